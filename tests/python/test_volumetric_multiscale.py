"""VolumetricARAP's multi-scale solve (levels=2; docs/methods/volumetric_arap.md,
"Multi-scale"): the surface simplified, its own tetrahedra and VolumetricARAP, the maps
between the two volumes. Checked against what a wrong level would break: the converged
answer is the single level's minimum, reached in fewer Newton steps; a rigid motion and an
affine input pose come back exactly (the prolongation reproduces affine maps, outside the
coarse volume too); the handles hold exactly; a cold solve depends on the request alone and
slices equal one solve; rebinds, soft handles and stiffness; no level where nothing bounds a
volume; bad levels refused by name."""
import numpy as np
import pytest

import deformkit as dk
from conftest import make_grid
from shapes import bend, capped_tube, twist


def tube(n_ring=20, n_len=41):
    v, f = capped_tube(n_ring=n_ring, n_len=n_len, radius=0.2, length=2.0)
    return v, f, [np.flatnonzero(v[:, 0] <= -0.9), np.flatnonzero(v[:, 0] >= 0.9)]


def targets(shape, handles):
    return np.vstack([shape[h] for h in handles])


def rigid(angle, move):
    c, s = np.cos(angle), np.sin(angle)
    T = np.eye(4)
    T[:3, :3] = [[c, 0, s], [0, 1, 0], [-s, 0, c]]
    T[:3, 3] = move
    return T


@pytest.mark.parametrize("edit", ["bend", "twist"])
def test_the_level_reaches_the_single_level_minimum_in_fewer_steps(edit):
    v, f, handles = tube()
    mesh = dk.Mesh(v, f)
    shape = bend(v, np.pi / 2, -0.5, 1.0) if edit == "bend" else twist(v, np.pi)
    one = dk.VolumetricARAP(mesh, handles=handles, levels=1, tolerance=1e-10)
    two = dk.VolumetricARAP(mesh, handles=handles, levels=2, tolerance=1e-10)
    assert one.stats["levels"] == 1 and one.stats["coarse_points"] == 0
    assert two.stats["levels"] == 2 and 0 < two.stats["coarse_points"] < two.n_points
    a = one.solve(targets=targets(shape, handles), warm_start=False)
    b = two.solve(targets=targets(shape, handles), warm_start=False)
    assert a.converged and b.converged
    assert two.stats["coarse_starts"] == 1
    assert b.energy == pytest.approx(a.energy, rel=1e-8)
    assert np.abs(b.positions - a.positions).max() < 1e-5
    assert b.iterations * 2 < a.iterations, (b.iterations, a.iterations)
    # the handles hold exactly, with or without the level
    for h, want in zip(handles, (shape[handles[0]], shape[handles[1]])):
        assert np.abs(b.positions[h] - want).max() < 1e-12


def test_a_rigid_motion_comes_back_exactly_and_at_once():
    """Both handles moved by one rigid motion: the coarse level's solve is that motion, and
    its prolongation (each point's barycentric coordinates in the coarse tetrahedra,
    extrapolated where the surface bulges past the coarse one) carries every point of the
    volume by it exactly: the cold preview is already the answer."""
    v, f, handles = tube()
    m = dk.VolumetricARAP(dk.Mesh(v, f), handles=handles, levels=2)
    T = rigid(2.0, [0.4, -3.0, 1.5])
    want = v @ T[:3, :3].T + T[:3, 3]
    p = m.solve(transforms=[T, T], warm_start=False, preview=True)
    assert np.abs(p.positions - want).max() < 1e-9
    r = m.solve(transforms=[T, T], warm_start=False)
    assert r.converged and r.iterations <= 1
    assert np.abs(r.positions - want).max() < 1e-9 and r.energy < 1e-16
    points, tets = m.tetrahedra()
    rest, _ = dk.VolumetricARAP(dk.Mesh(v, f), handles=handles, levels=1).tetrahedra()
    assert np.abs(points - (rest @ T[:3, :3].T + T[:3, 3])).max() < 1e-9


def test_an_affine_input_pose_is_returned_as_it_is():
    """Editing an input pose (an Armature's) that is an affine map of the rest, with the
    handles where the pose puts them: the answer is the pose, interior and all, with the
    level as without."""
    v, f, handles = tube()
    A = np.array([[1.2, 0.3, 0.0], [0.0, 0.9, 0.1], [0.2, 0.0, 1.1]])
    pose = v @ A.T + [0.5, 0.0, -1.0]
    m = dk.VolumetricARAP(dk.Mesh(v, f), handles=handles, levels=2)
    r = m.solve(targets=targets(pose, handles), input_positions=pose, warm_start=False)
    assert r.converged and m.stats["coarse_starts"] == 1
    assert np.abs(r.positions - pose).max() < 1e-9


def test_cold_solves_depend_on_the_request_alone_and_slices_equal_one_solve():
    v, f, handles = tube()
    mesh = dk.Mesh(v, f)
    t = targets(twist(v, np.pi), handles)
    fresh = dk.VolumetricARAP(mesh, handles=handles, levels=2)
    whole = fresh.solve(targets=t, warm_start=False)
    assert whole.iterations >= 3
    used = dk.VolumetricARAP(mesh, handles=handles, levels=2)
    used.solve(targets=targets(bend(v, 1.0, -0.5, 1.0), handles), warm_start=False)
    used.solve(targets=targets(bend(v, 1.2, -0.5, 1.0), handles))
    again = used.solve(targets=t, warm_start=False)
    assert np.array_equal(again.positions, whole.positions)
    cut = dk.VolumetricARAP(mesh, handles=handles, levels=2)
    r = cut.solve(targets=t, warm_start=False, max_iterations=1)
    state, steps = cut.save_state(), r.iterations
    while not r.converged:
        r = cut.solve(targets=t, resume=True, max_iterations=1)
        steps += r.iterations
    assert steps == whole.iterations
    assert np.array_equal(r.positions, whole.positions)
    other = dk.VolumetricARAP(mesh, handles=handles, levels=2)
    other.restore_state(state)
    assert np.array_equal(other.solve(targets=t, resume=True).positions, whole.positions)


def test_rebind_soft_handles_and_stiffness():
    """A rebind builds the level for the new constraints; soft handle vertices and painted
    stiffness end at the single level's minimum."""
    v, f, handles = tube()
    mesh = dk.Mesh(v, f)
    weights = [np.ones(len(handles[0])), np.where(v[handles[1], 1] > 0, 1.0, 0.4)]
    stiffness = 1.0 + 4.0 * (np.abs(v[:, 0]) < 0.3)
    one = dk.VolumetricARAP(mesh, handles=[handles[1]], fixed=handles[0], levels=1)
    two = dk.VolumetricARAP(mesh, handles=[handles[1]], fixed=handles[0], levels=2)
    for m in (one, two):
        m.rebind(handles=handles, fixed=np.zeros(0, np.int64), handle_weights=weights,
                 stiffness=stiffness)
    assert two.stats["levels"] == 2 and two.stats["coarse_starts"] == 0
    t = targets(bend(v, np.pi / 2, -0.5, 1.0), handles)
    a = one.solve(targets=t, warm_start=False, tolerance=1e-10)
    b = two.solve(targets=t, warm_start=False, tolerance=1e-10)
    assert a.converged and b.converged
    assert b.energy == pytest.approx(a.energy, rel=1e-8)
    assert np.abs(b.positions - a.positions).max() < 1e-5
    hard = handles[1][weights[1] == 1.0]
    assert np.abs(b.positions[hard] - bend(v, np.pi / 2, -0.5, 1.0)[hard]).max() < 1e-12


def test_automatic_level_from_ten_thousand_points():
    small_v, small_f, small_h = tube()
    assert dk.VolumetricARAP(dk.Mesh(small_v, small_f), handles=small_h).stats["levels"] == 1
    v, f, handles = tube(n_ring=40, n_len=161)
    m = dk.VolumetricARAP(dk.Mesh(v, f), handles=handles)
    assert m.n_points >= 10000 and m.stats["levels"] == 2


def test_no_level_where_nothing_bounds_a_volume():
    v, f = make_grid(24, 24)
    m = dk.VolumetricARAP(dk.Mesh(v, f), handles=[np.flatnonzero(v[:, 0] > 0.99)],
                          fixed=np.flatnonzero(v[:, 0] < 0.01), levels=2)
    assert m.n_tetrahedra == 0 and m.stats["levels"] == 1


@pytest.mark.parametrize("levels", [-1, 3, 8])
def test_bad_levels_refused(levels):
    v, f, handles = tube()
    with pytest.raises(ValueError, match="levels"):
        dk.VolumetricARAP(dk.Mesh(v, f), handles=handles, levels=levels)
