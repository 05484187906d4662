"""VolumetricARAP (native/methods/dk_volumetric_arap.h): ARAP on the tetrahedra of the solid
a closed mesh bounds, the slides' volume-based deformation. Checked against properties that
a wrong implementation breaks: each tetrahedron's term is vol |F - R|^2 (F = Ds Dm^-1), the
volume a bent or twisted tube keeps against surface ARAP, rigid motions and exact handles,
the harmonic extension's linear precision, and the parts that bound no volume."""
import numpy as np
import pytest

import deformkit as dk
from conftest import make_grid, make_icosphere
from shapes import bend, capped_tube, twist, volume


def tube():
    v, f = capped_tube(n_ring=20, n_len=41, radius=0.2, length=2.0)
    return v, f, [np.flatnonzero(v[:, 0] <= -0.9), np.flatnonzero(v[:, 0] >= 0.9)]


def solve_to(m, v, handles, shape):
    return m.solve(targets=np.vstack([shape[h] for h in handles]), warm_start=False)


def tetrahedra_energy(points, tets, X):
    """sum over the tetrahedra of vol |F - R|^2, F = Ds Dm^-1, R its closest rotation (SVD),
    the volume's points moved from `points` to X: the slides' energy, in numpy."""
    Dm = np.stack([points[tets[:, k]] - points[tets[:, 0]] for k in (1, 2, 3)], axis=2)
    Ds = np.stack([X[tets[:, k]] - X[tets[:, 0]] for k in (1, 2, 3)], axis=2)
    vol = np.linalg.det(Dm) / 6.0
    assert (vol > 0).all()                      # positively oriented at rest
    F = Ds @ np.linalg.inv(Dm)
    U, _, Vt = np.linalg.svd(F)
    D = np.ones((len(F), 3))
    D[:, 2] = np.sign(np.linalg.det(U @ Vt))
    R = (U * D[:, None, :]) @ Vt
    return float((vol * ((F - R) ** 2).sum(axis=(1, 2))).sum())


def test_the_energy_is_the_tetrahedra_sum_of_vol_f_minus_r():
    """A solve's reported energy, and energy() of its result, equal sum over the tetrahedra of
    vol |F - R|^2 (F = Ds Dm^-1, R its closest rotation) computed in numpy over tetrahedra()
    at the rest and at the result: a bend, where every tetrahedron has its own F and R."""
    v, f, handles = tube()
    m = dk.VolumetricARAP(dk.Mesh(v, f), handles=handles)
    rest_points, tets = m.tetrahedra()
    assert m.n_points == len(rest_points) > len(v) and np.array_equal(rest_points[: len(v)], v)
    r = solve_to(m, v, handles, bend(v, 2.0, -0.5, 1.0))
    points, same = m.tetrahedra()
    assert np.array_equal(same, tets) and np.array_equal(points[: len(v)], r.positions)
    want = tetrahedra_energy(rest_points, tets, points)
    assert want > 1e-4
    assert r.energy == pytest.approx(want, rel=1e-9)
    assert m.energy(r.positions) == pytest.approx(want, rel=1e-9)


def test_a_bent_and_a_twisted_tube_keep_their_volume():
    """The issue's figures: a tube bent by its end handles (to 90 and 180 degrees) and twisted
    (180): volumetric ARAP keeps the volume within 6%, where surface ARAP loses 7-15%."""
    v, f, handles = tube()
    mesh = dk.Mesh(v, f)
    v0 = volume(v, f)
    vol, surf = dk.VolumetricARAP(mesh, handles=handles), dk.ARAP(mesh, handles=handles)
    for shape, vol_tol, surf_below in [(bend(v, np.pi / 2, -0.5, 1.0), 0.045, 0.93),
                                      (bend(v, np.pi, -0.5, 1.0), 0.06, 0.87),
                                      (twist(v, np.pi), 0.04, 0.90)]:
        a, b = solve_to(vol, v, handles, shape), solve_to(surf, v, handles, shape)
        assert a.converged and b.converged
        ra, rb = volume(a.positions, f) / v0, volume(b.positions, f) / v0
        assert abs(ra - 1.0) <= vol_tol, ra
        assert rb <= surf_below, rb
        assert abs(ra - 1.0) < abs(rb - 1.0) / 2


def test_rigid_motions_and_exact_handles():
    v, f, handles = tube()
    m = dk.VolumetricARAP(dk.Mesh(v, f), handles=handles)
    c, s = np.cos(0.7), np.sin(0.7)
    T = np.eye(4)
    T[:3, :3] = [[c, -s, 0], [s, c, 0], [0, 0, 1]]
    T[:3, 3] = [0.3, -1.0, 2.0]
    r = m.solve(transforms=[T, T], warm_start=False)
    want = v @ T[:3, :3].T + T[:3, 3]
    np.testing.assert_allclose(r.positions, want, atol=1e-6)
    assert r.energy <= 1e-12 * volume(v, f)
    shape = bend(v, 2.0, -0.5, 1.0)
    r = solve_to(m, v, handles, shape)
    for h in handles:
        np.testing.assert_allclose(r.positions[h], shape[h], atol=1e-12)
    # the energy decreases along the solve: from the cold start (a preview: the start
    # alone), slice by slice, strictly until converged
    targets = np.vstack([shape[h] for h in handles])
    start = m.solve(targets=targets, warm_start=False, preview=True)
    assert start.iterations == 0
    energies = [start.energy]
    for _ in range(4):
        r = m.solve(targets=targets, resume=True, max_iterations=1)
        energies.append(r.energy)
    assert energies[1] < 0.9 * energies[0]
    assert all(b < a for a, b in zip(energies, energies[1:])), energies


def test_an_affine_input_pose_is_edited_exactly():
    """The harmonic extension has linear precision: an input pose that is an affine map of
    the rest moves the interior by the same map, so handles at the input's own positions
    give the input back, interior and all, at zero energy."""
    v, f, handles = tube()
    m = dk.VolumetricARAP(dk.Mesh(v, f), handles=handles)
    A = np.array([[1.0, 0.3, 0.0], [0.0, 1.0, 0.0], [0.1, 0.0, 1.0]])
    pose = v @ A.T + [0.5, 0.0, -0.2]
    r = m.solve(targets=np.vstack([pose[h] for h in handles]), input_positions=pose)
    np.testing.assert_allclose(r.positions, pose, atol=1e-9)
    assert r.energy <= 1e-12
    points, _ = m.tetrahedra()
    rest, _ = dk.VolumetricARAP(dk.Mesh(v, f), handles=handles).tetrahedra()
    np.testing.assert_allclose(points, rest @ A.T + [0.5, 0.0, -0.2], atol=1e-9)


def test_parts_that_bound_no_volume_deform_as_surfaces():
    """A grid (open) bounds no volume: the method is surface ARAP there, result for result;
    a mesh with a closed and an open part tetrahedralizes the closed one only."""
    v, f = make_grid(10, 8, bump=0.1)
    cols = np.arange(len(v)) % 10
    handles = [np.flatnonzero(cols <= 1), np.flatnonzero(cols >= 8)]
    mesh = dk.Mesh(v, f)
    m, a = dk.VolumetricARAP(mesh, handles=handles), dk.ARAP(mesh, handles=handles)
    assert m.n_tetrahedra == 0 and m.n_points == len(v) and "no closed part" in m.volume_note
    T = np.eye(4)
    T[:3, 3] = [0.0, 0.0, 0.3]
    np.testing.assert_allclose(m.solve(transforms=[np.eye(4), T]).positions,
                               a.solve(transforms=[np.eye(4), T]).positions, atol=1e-9)
    s, sf = make_icosphere(2)
    both_v = np.vstack([s, v + [3.0, 0, 0]])
    both_f = np.vstack([sf, f + len(s)])
    mixed = dk.VolumetricARAP(dk.Mesh(both_v, both_f),
                              handles=[np.flatnonzero(s[:, 2] < -0.8),
                                       handles[1] + len(s)],
                              fixed=np.concatenate([np.flatnonzero(s[:, 2] > 0.8),
                                                    handles[0] + len(s)]))
    assert mixed.n_tetrahedra > 0 and "deform as surfaces" in mixed.volume_note
    r = mixed.solve(transforms=[np.eye(4), T])
    assert r.converged and np.isfinite(r.positions).all()
    # the open part, a component of its own, deforms as surface ARAP does it alone
    alone = dk.ARAP(mesh, handles=[handles[1]], fixed=handles[0], tolerance=1e-12)
    mixed = dk.VolumetricARAP(dk.Mesh(both_v, both_f),
                              handles=[np.flatnonzero(s[:, 2] < -0.8), handles[1] + len(s)],
                              fixed=np.concatenate([np.flatnonzero(s[:, 2] > 0.8),
                                                    handles[0] + len(s)]), tolerance=1e-12)
    lift = np.eye(4)
    lift[:3, 3] = [0.1, 0.0, 0.2]
    r = mixed.solve(transforms=[lift, T])
    np.testing.assert_allclose(r.positions[len(s):] - [3.0, 0, 0],
                               alone.solve(transforms=[T]).positions,
                               atol=1e-6)
    assert np.abs(r.positions[: len(s)] - s).max() > 0.05   # and the sphere moved


def test_a_closed_mesh_tetgen_refuses_deforms_as_a_surface():
    """Two overlapping spheres cross each other: TetGen refuses, the mesh deforms as a surface
    and volume_note says why."""
    s, sf = make_icosphere(2)
    v = np.vstack([s, s + [0.5, 0, 0]])
    f = np.vstack([sf, sf + len(s)])
    m = dk.VolumetricARAP(dk.Mesh(v, f), handles=[np.flatnonzero(v[:, 0] > 1.3)],
                          fixed=np.flatnonzero(v[:, 0] < -0.8))
    assert m.n_tetrahedra == 0 and "intersects itself" in m.volume_note
    T = np.eye(4)
    T[:3, 3] = [0.2, 0, 0]
    assert m.solve(transforms=[T]).converged


@pytest.mark.heavy
def test_the_arm_bends_keeping_its_volume(shared_mesh):
    """The shared arm (a closed scan): the hand turned 90 degrees about the elbow's axis with
    the shoulder fixed; volumetric ARAP keeps the volume closer than surface ARAP."""
    mesh = dk.read_mesh(str(shared_mesh("arm.obj")))
    v, f = np.asarray(mesh.vertices), np.asarray(mesh.triangles)
    axis = int(np.argmax(np.ptp(v, axis=0)))
    lo, hi = v[:, axis].min(), v[:, axis].max()
    t = (v[:, axis] - lo) / (hi - lo)
    hand, shoulder = np.flatnonzero(t > 0.9), np.flatnonzero(t < 0.1)
    centre = v[(t > 0.45) & (t < 0.55)].mean(axis=0)
    other = (axis + 1) % 3
    ang = np.pi / 2
    R = np.eye(3)
    a, b = axis, other
    R[a, a], R[a, b], R[b, a], R[b, b] = np.cos(ang), -np.sin(ang), np.sin(ang), np.cos(ang)
    T = np.eye(4)
    T[:3, :3] = R
    T[:3, 3] = centre - R @ centre
    v0 = volume(v, f)
    out = {}
    for cls in (dk.VolumetricARAP, dk.ARAP):
        m = cls(mesh, handles=[hand], fixed=shoulder)
        r = m.solve(transforms=[T], warm_start=False)
        assert r.converged
        out[cls.__name__] = volume(r.positions, f) / v0
    assert abs(out["VolumetricARAP"] - 1) < abs(out["ARAP"] - 1), out


def test_the_result_does_not_depend_on_placement_or_scale():
    """TetGen's choices depend on the coordinates: the method meshes in a frame that moves
    with the mesh, so the same tube turned, moved far away and scaled by 1000 gets the same
    tetrahedra and the same result, moved and scaled."""
    v, f, handles = tube()
    c, s = np.cos(2.1), np.sin(2.1)
    R = np.array([[c, -s, 0], [s, c, 0], [0, 0, 1.0]]) @ np.array(
        [[1, 0, 0], [0, np.cos(0.7), -np.sin(0.7)], [0, np.sin(0.7), np.cos(0.7)]])
    k, t = 1000.0, np.array([3e4, -7e4, 5e4])
    a = dk.VolumetricARAP(dk.Mesh(v, f), handles=handles)
    b = dk.VolumetricARAP(dk.Mesh(k * v @ R.T + t, f), handles=handles)
    pa, ta = a.tetrahedra()
    pb, tb = b.tetrahedra()
    assert np.array_equal(ta, tb)
    np.testing.assert_allclose(k * pa @ R.T + t, pb, atol=1e-9 * k)
    shape = bend(v, 2.0, -0.5, 1.0)
    ra = solve_to(a, v, handles, shape)
    rb = b.solve(targets=np.vstack([k * shape[h] @ R.T + t for h in handles]), warm_start=False)
    np.testing.assert_allclose(k * ra.positions @ R.T + t, rb.positions, atol=1e-6 * k)


def test_the_response_basis_is_the_solvers_rows_for_the_vertices():
    """response_basis(): the global step's response to each handle's affine motion, the mesh's
    vertices' rows of the solver's on the tetrahedra: a handle vertex's row is its own affine
    coordinates, a fixed one's zero, and a preview from a converged result for a moved handle
    lands where the basis moves it, the handle exactly."""
    v, f, handles = tube()
    fixed = handles[0]
    m = dk.VolumetricARAP(dk.Mesh(v, f), handles=[handles[1]], fixed=fixed)
    B = m.response_basis()
    assert B.shape == (len(v), 4)
    np.testing.assert_allclose(B[handles[1]], np.c_[v[handles[1]], np.ones(len(handles[1]))],
                               atol=1e-12)
    assert np.abs(B[fixed]).max() == 0.0
    free = np.setdiff1d(np.arange(len(v)), np.concatenate(handles))
    assert np.abs(B[free]).max() > 0.1
    T = np.eye(4)
    T[:3, 3] = [0.0, 0.2, 0.0]
    x0 = m.solve(transforms=[np.eye(4)], warm_start=False).positions
    C = (T - np.eye(4))[:3, :].T          # C[j, d] = (T - T0)[d, j]
    moved = x0 + B @ C
    np.testing.assert_allclose(moved[handles[1]], v[handles[1]] + [0.0, 0.2, 0.0], atol=1e-12)
    assert dk.VolumetricARAP(dk.Mesh(*make_grid(6, 5)), handles=[[0, 1]]).response_basis() \
        is not None                       # no volume: ARAP's own rows
