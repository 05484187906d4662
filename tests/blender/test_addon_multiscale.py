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


def tube_setup(levels, rig=None):
    """S.tube_deformer's tube (61 rings) with an ARAP deformer of `levels`, in a fresh
    scene."""
    S.reset_scene()
    return S.tube_deformer("ARAP", n_len=61, rig=rig, levels=levels)


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
    obj, d, e, fixed, tip = tube_setup(2, S.lower_bone_rig)
    S.check_edit_after_armature(R, obj, d, e, fixed, tip, TOL, "arap_levels.pc2")


for t in (test_still_mesh, test_automatic_on_a_small_mesh, test_after_an_armature):
    R.run(t)
R.finish()
