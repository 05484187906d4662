"""Issue 44: ARAP's multi-scale solve from the add-on (the ARAP deformer's Coarse Levels,
deformkit.ARAP's levels=). On a still capped tube, its far end a handle and its near end
fixed, with 2 levels: the status says how many vertices the coarse level has; the handle
moved as a 90-degree bend moves the tube's end bends it as the API does with the same
levels; the setting survives saving and reopening. After an Armature bending the tube
(keyed), each frame is the API's edit of the Armature's pose, and a bake writes what played.
With the default (automatic) the small tube gets no coarse level, and the status says
nothing of one."""
import os
import sys
sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
import _setup as S  # noqa: E402
import bpy  # noqa: E402
import numpy as np  # noqa: E402

R = S.Results("test_addon_multiscale")
TOL = 2e-4   # float32 storage, and two converged Newton solves (tolerance 1e-6) of one edit


def rig(obj):
    """A two-bone Armature first in the stack, its lower bone turned about z by 0 at frame 1
    and 0.8 at frame 5."""
    return S.arm_rig(obj, {"lower": ((1, (0, 0, 0.0)), (5, (0, 0, 0.8)))})


def tube_setup(levels, rig=None):
    """A capped tube along x (S.tube, 61 rings), 'fixed' its x < -0.9 end, 'tip' its
    x > 0.9 end on an empty at (1, 0, 0), an ARAP deformer with `levels` (below the Armature
    `rig` makes, if any)."""
    S.reset_scene()
    V, F = S.tube(n_len=61)
    obj = S.triangle_mesh_object(V, F, name="Tube")
    if rig is not None:
        rig(obj)
    fixed, tip = np.flatnonzero(V[:, 0] < -0.9), np.flatnonzero(V[:, 0] > 0.9)
    S.group(obj, "fixed", fixed)
    S.group(obj, "tip", tip)
    e = S.empty("Tip", (1.0, 0.0, 0.0))
    bpy.context.view_layer.objects.active = obj
    bpy.ops.deformkit.add_deformer(method="ARAP")
    d = obj.deformkit.deformers[-1]
    d.fixed_group = "fixed"
    d.options_arap.levels = levels
    bpy.ops.deformkit.add_handle(vertex_group="tip", target=e.name)
    return obj, d, e, fixed, tip


def api(obj, d, fixed, tip):
    rest = S.rest_positions(obj)
    m = S.methods.get(d.method)
    mesh = S.dk.Mesh(rest, S.solver.triangles(obj.data))
    kw = dict(handles=[tip], fixed=fixed)
    return S.dk.ARAP(mesh, **kw, **S.methods.bind_kwargs(m, d.options, rest, kw, mesh)), m


def test_still_mesh():
    obj, d, e, fixed, tip = tube_setup(2)
    bind_world = e.matrix_world.copy()
    bpy.ops.deformkit.bind()
    R.check("binds", d.bound and not d.status_is_error, d.status)
    native, m = api(obj, d, fixed, tip)
    coarse = native.stats["coarse_vertices"]
    R.check("the API binds a coarse level with the add-on's options", len(coarse) == 1, coarse)
    text = S.solver.status_text(d)
    R.check("the status names it", ("coarse level of %d vertices" % coarse[0]) in text, text)
    e.matrix_world = S.bend_end(np.pi / 2) @ bind_world
    bpy.context.view_layer.update()
    got = S.evaluated_positions(obj)
    T = np.array(e.matrix_world @ bind_world.inverted())
    native.solve(transforms=[np.eye(4)], warm_start=False)
    want = np.asarray(native.solve(transforms=[T], warm_start=True).positions)
    diff = float(np.abs(got - want).max())
    R.check("the bend is the API's (max %.2e)" % diff, diff < TOL, diff)
    moved = float(np.abs(got - S.rest_positions(obj)).max())
    R.check("the tube bends (its end moved %.2f)" % moved, moved > 0.5, moved)
    path = os.path.join(S.OUTPUT, "arap_levels.blend")
    bpy.ops.wm.save_as_mainfile(filepath=path)
    bpy.ops.wm.open_mainfile(filepath=path)
    d = bpy.data.objects["Tube"].deformkit.deformers[0]
    R.check("the levels survive saving", d.options_arap.levels == 2, d.options_arap.levels)


def test_automatic_on_a_small_mesh():
    obj, d, e, fixed, tip = tube_setup(0)
    bpy.ops.deformkit.bind()
    R.check("binds", d.bound and not d.status_is_error, d.status)
    native, _ = api(obj, d, fixed, tip)
    R.check("no coarse level below 100,000 vertices", native.stats["levels"] == 1,
            native.stats)
    R.check("and the status says none", "coarse level" not in S.solver.status_text(d),
            S.solver.status_text(d))


def test_after_an_armature():
    obj, d, e, fixed, tip = tube_setup(2, rig)
    sc = bpy.context.scene
    sc.frame_start, sc.frame_end = 1, 5
    sc.frame_set(1)
    bind_world = e.matrix_world.copy()
    bpy.ops.deformkit.bind()
    R.check("binds after an Armature", d.bound and not d.status_is_error, d.status)
    e.location.z += 0.2
    sc.frame_set(5)
    got = S.evaluated_positions(obj)
    inp = S.armature_input(obj, d)
    R.check("the Armature bends the input", np.abs(inp - S.rest_positions(obj)).max() > 0.3,
            np.abs(inp - S.rest_positions(obj)).max())
    R.check("its fixed end stays where the Armature puts it",
            float(np.abs(got[fixed] - inp[fixed]).max()) < TOL,
            float(np.abs(got[fixed] - inp[fixed]).max()))
    native, m = api(obj, d, fixed, tip)
    rest = S.rest_positions(obj)
    T = np.array(e.matrix_world @ bind_world.inverted())
    edit = rest[tip] @ T[:3, :3].T + T[:3, 3] - rest[tip]
    B = S.bone_turn(obj, "lower")
    want = np.asarray(native.solve(inp[tip] + edit @ B.T, input_positions=inp,
                                   **S.methods.solve_kwargs(m, d.options, True)).positions)
    diff = float(np.abs(got - want).max())
    R.check("frame 5 is the API's edit of the pose (max %.2e)" % diff, diff < TOL, diff)
    shown = {}
    for f in range(1, 6):
        sc.frame_set(f)
        shown[f] = S.evaluated_positions(obj)
    diff = S.bake_differs_from(obj, d, shown, "arap_levels.pc2")
    R.check("the bake = playback (max %.2e)" % diff, diff < TOL, diff)


for t in (test_still_mesh, test_automatic_on_a_small_mesh, test_after_an_armature):
    R.run(t)
R.finish()
