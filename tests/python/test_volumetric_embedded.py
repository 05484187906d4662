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
