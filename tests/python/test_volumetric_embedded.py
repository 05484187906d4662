"""VolumetricARAP with embed=2 (docs/methods/volumetric_arap.md, "Big meshes"): a coarse
volume (the surface simplified to a sixteenth, its own tetrahedra) carries the surface by
each vertex's barycentric coordinates in it. Checked: handles and fixed vertices exact,
rigid motions and affine input poses carried exactly (the coordinates sum to 1, also where
extrapolated), the volume kept in a bend where surface ARAP loses it, the result near the
full volume's, energy() and state as the coarse volume's, rebinds, refusals."""
import numpy as np
import pytest

import deformkit as dk
from conftest import make_grid
from shapes import bend, capped_tube, twist, volume


def tube():
    v, f = capped_tube(n_ring=40, n_len=81, radius=0.2, length=2.0)
    return v, f, [np.flatnonzero(v[:, 0] <= -0.9), np.flatnonzero(v[:, 0] >= 0.9)]


def targets_of(handles, shape):
    return np.vstack([shape[h] for h in handles])


def test_the_coarse_volume_carries_the_surface():
    v, f, handles = tube()
    m = dk.VolumetricARAP(dk.Mesh(v, f), handles=handles, embed=2)
    points, tets = m.tetrahedra()
    # the coarse volume: about a sixteenth of the surface, its own interior
    assert len(v) / 32 < m.stats["n_points"] - m.stats["n_interior_points"] < len(v) / 4
    assert m.n_points == len(points) and m.n_tetrahedra == len(tets) > 0
    assert m.volume_note == ""
    shape = bend(v, np.pi / 2, -0.5, 1.0)
    r = m.solve(targets=targets_of(handles, shape), warm_start=False)
    assert r.converged
    for h in handles:  # exact, though most handle vertices are not coarse points
        np.testing.assert_allclose(r.positions[h], shape[h], atol=1e-12)
    # energy() is the coarse volume's of the result, as reported
    assert m.energy(r.positions) == pytest.approx(r.energy, rel=1e-9)


def test_rigid_motions_and_affine_poses_are_carried_exactly():
    v, f, handles = tube()
    m = dk.VolumetricARAP(dk.Mesh(v, f), handles=handles, embed=2)
    c, s = np.cos(0.7), np.sin(0.7)
    T = np.eye(4)
    T[:3, :3] = [[c, -s, 0], [s, c, 0], [0, 0, 1]]
    T[:3, 3] = [0.3, -1.0, 2.0]
    r = m.solve(transforms=[T, T], warm_start=False)
    np.testing.assert_allclose(r.positions, v @ T[:3, :3].T + T[:3, 3], atol=1e-6)
    A = np.array([[1.0, 0.3, 0.0], [0.0, 1.0, 0.0], [0.1, 0.0, 1.0]])
    pose = v @ A.T + [0.5, 0.0, -0.2]
    r = m.solve(targets=targets_of(handles, pose), input_positions=pose)
    np.testing.assert_allclose(r.positions, pose, atol=1e-9)
    assert r.energy <= 1e-12


def test_a_bend_keeps_its_volume_near_the_full_volumes_result():
    """A 90-degree bend and a half twist: the volume within 5% (surface ARAP loses 8% and
    11%), and every vertex within 3% of the tube's length of the full volume's result."""
    v, f, handles = tube()
    mesh = dk.Mesh(v, f)
    v0 = volume(v, f)
    emb = dk.VolumetricARAP(mesh, handles=handles, embed=2)
    full = dk.VolumetricARAP(mesh, handles=handles, embed=1)
    surf = dk.ARAP(mesh, handles=handles)
    for shape in (bend(v, np.pi / 2, -0.5, 1.0), twist(v, np.pi)):
        t = targets_of(handles, shape)
        a = emb.solve(targets=t, warm_start=False)
        b = full.solve(targets=t, warm_start=False)
        c = surf.solve(targets=t, warm_start=False)
        ra, rc = volume(a.positions, f) / v0, volume(c.positions, f) / v0
        assert abs(ra - 1) < 0.05 and abs(ra - 1) < abs(rc - 1) / 2, (ra, rc)
        assert np.abs(a.positions - b.positions).max() < 0.03 * 2.0


def test_state_rebind_and_warm_solves():
    v, f, handles = tube()
    mesh = dk.Mesh(v, f)
    m = dk.VolumetricARAP(mesh, handles=handles, embed=2)
    t = targets_of(handles, bend(v, 1.0, -0.5, 1.0))
    m.solve(targets=t, warm_start=False)
    saved = m.save_state()
    t2 = targets_of(handles, bend(v, 1.3, -0.5, 1.0))
    a = m.solve(targets=t2, max_iterations=2)
    m.restore_state(saved)
    b = m.solve(targets=t2, max_iterations=2)
    assert np.array_equal(a.positions, b.positions)
    fresh = dk.VolumetricARAP(mesh, handles=handles, embed=2)
    fresh.restore_state(saved)
    c = fresh.solve(targets=t2, max_iterations=2)
    assert np.array_equal(a.positions, c.positions)
    # a rebind to one handle (the other end now fixed) builds a coarse volume for it
    m.rebind(handles=[handles[1]], fixed=handles[0])
    shape = bend(v, np.pi / 2, -0.5, 1.0)
    r = m.solve(targets=shape[handles[1]], warm_start=False)
    np.testing.assert_allclose(r.positions[handles[1]], shape[handles[1]], atol=1e-12)
    np.testing.assert_allclose(r.positions[handles[0]], v[handles[0]], atol=0)


def test_parts_close_together_ride_on_their_own_volumes():
    """Two closed tubes 0.01 apart, one's end lifted, the other fixed: each vertex rides on
    the coarse tetrahedra near its own place on the surface. Located among all of them, the
    vertices facing the other tube followed it and the lifted tube tore (edges 11.8-fold;
    1.17 with its own volume)."""
    v, f = capped_tube(n_ring=40, n_len=81, radius=0.2, length=2.0)
    n = len(v)
    V, F = np.vstack([v, v + [0, 0.41, 0]]), np.vstack([f, f + n])
    hand, left = np.flatnonzero(v[:, 0] >= 0.9), np.flatnonzero(v[:, 0] <= -0.9)
    m = dk.VolumetricARAP(dk.Mesh(V, F), handles=[hand], fixed=np.r_[left, n + np.arange(n)],
                          embed=2)
    T = np.eye(4)
    T[2, 3] = 0.3
    X = np.asarray(m.solve(transforms=[T], warm_start=False).positions)
    E = np.vstack([f[:, [0, 1]], f[:, [1, 2]], f[:, [2, 0]]])
    stretch = np.linalg.norm(X[E[:, 0]] - X[E[:, 1]], axis=1) / np.linalg.norm(
        V[E[:, 0]] - V[E[:, 1]], axis=1)
    assert stretch.max() < 1.5, stretch.max()
    np.testing.assert_allclose(X[n:], V[n:], atol=0)


def test_the_response_basis_and_the_pose():
    """The response basis's rows are the solve's: a fixed vertex's are 0, a hard handle
    vertex's its rest position and 1 in its handle's columns, so a preview through them puts
    the handle on its transform and leaves the fixed part; and with an input pose the fixed
    vertices stay where the pose puts them."""
    v, f, handles = tube()
    m = dk.VolumetricARAP(dk.Mesh(v, f), handles=[handles[1]], fixed=handles[0], embed=2)
    B = np.asarray(m.response_basis())
    assert B.shape == (len(v), 4)
    assert np.abs(B[handles[0]]).max() == 0.0
    np.testing.assert_array_equal(B[handles[1]], np.c_[v[handles[1]], np.ones(len(handles[1]))])
    T = np.eye(4)
    T[:3, 3] = [0.1, 0.3, -0.2]
    np.testing.assert_allclose(B[handles[1]] @ T[:3].T, v[handles[1]] + T[:3, 3], atol=1e-12)
    pose = bend(v, 0.6, -0.5, 1.0)
    r = m.solve(transforms=[np.eye(4)], input_positions=pose, warm_start=False)
    np.testing.assert_array_equal(r.positions[handles[0]], pose[handles[0]])
    np.testing.assert_allclose(r.positions[handles[1]], pose[handles[1]], atol=1e-12)


def test_the_automatic_choice_by_size():
    """From 250,000 vertices of a closed mesh a coarse volume carries it: the estimate (the
    coarse volume at its largest retry, an eighth of the surface) fits 3 GB where the mesh's
    own volume would need about 5 times as much."""
    v, f = capped_tube(n_ring=500, n_len=500)
    mesh = dk.Mesh(v, f)
    assert len(v) > 250000
    auto, own = (dk.VolumetricARAP.estimate_memory(mesh),
                 dk.VolumetricARAP.estimate_memory(mesh, embed=1))
    assert auto == dk.VolumetricARAP.estimate_memory(mesh, embed=2)
    assert auto < 3 * 2 ** 30 and own > 3 * auto, (auto, own)
    small_v, small_f = capped_tube(n_ring=40, n_len=81)
    small = dk.Mesh(small_v, small_f)
    assert dk.VolumetricARAP.estimate_memory(small) == dk.VolumetricARAP.estimate_memory(
        small, embed=1)


def test_refusals():
    g_v, g_f = make_grid(8, 8)
    with pytest.raises(ValueError, match="every part is closed"):
        dk.VolumetricARAP(dk.Mesh(g_v, g_f), handles=[[0]], embed=2)
    v, f, handles = tube()
    with pytest.raises(ValueError, match="embed"):
        dk.VolumetricARAP(dk.Mesh(v, f), handles=handles, embed=3)
    # automatic: a small mesh keeps its own volume (the coarse one from 250,000 vertices)
    m = dk.VolumetricARAP(dk.Mesh(v, f), handles=handles)
    assert m.n_points > len(v)
