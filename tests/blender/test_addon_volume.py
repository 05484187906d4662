"""Issue 44: the Volume ARAP deformer (deformkit.VolumetricARAP) deforms the solid inside a
closed mesh. On a still capped tube, its far end a handle and its near end fixed: bound, the
status counts the tetrahedra; the handle moved as a 90-degree bend moves the tube's end bends it as the API does
(warm, from the bind pose), keeping its volume where ARAP's loses it. On an open grid it
binds too and says that it deforms as a surface. After an Armature bending the tube (keyed),
each frame is the API's edit of the Armature's pose, its handle at the pose's place; a bake
writes what played; the settings survive saving and reopening. With Coarse Level 2 (the
multi-scale solve): the status names the level, the bend is the API's with levels=2, the
setting survives saving, and after the Armature each frame is the API's edit of the pose.
With Coarse Solid 2 (a coarse volume carries the mesh) likewise: the status says so, the bend
is the API's with embed=2, the setting survives saving, the Armature's pose is edited as the
API edits it."""
import os
import sys
sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
import _setup as S  # noqa: E402
import bpy  # noqa: E402
import numpy as np  # noqa: E402

R = S.Results("test_addon_volume")
volume = S.shapes.volume   # tests/python/shapes.py
TOL = 2e-4   # float32 storage, and two converged Newton solves (tolerance 1e-6) of one edit


def tube_setup(rig=None):
    """S.tube_deformer's tube with a Volume ARAP deformer, in a fresh scene."""
    S.reset_scene()
    return S.tube_deformer("VOLUME_ARAP", rig=rig)


def api(obj, d, fixed, tip, cls="VolumetricARAP"):
    rest = S.rest_positions(obj)
    mesh = S.dk.Mesh(rest, S.solver.triangles(obj.data))
    o = d.options_volume_arap
    kw = {"levels": o.levels, "embed": o.embed} if cls == "VolumetricARAP" else {}
    return getattr(S.dk, cls)(mesh, handles=[tip], fixed=fixed, tolerance=o.tolerance,
                              max_iterations=o.max_iterations, **kw), rest


def test_still_mesh():
    obj, d, e, fixed, tip = tube_setup()
    bind_world = e.matrix_world.copy()
    bpy.ops.deformkit.bind()
    R.check("binds", d.bound and not d.status_is_error, d.status)
    R.check("the status counts the tetrahedra", "tetrahedra inside" in S.solver.status_text(d),
            S.solver.status_text(d))
    first = d.bind_summary
    e.matrix_world = S.bend_end(np.pi / 2) @ bind_world
    bpy.context.view_layer.update()
    got = S.evaluated_positions(obj)
    T = np.array(e.matrix_world @ bind_world.inverted())
    va, rest = api(obj, d, fixed, tip)
    va.solve(transforms=[np.eye(4)], warm_start=False)
    want = np.asarray(va.solve(transforms=[T], warm_start=True).positions)
    diff = float(np.abs(got - want).max())
    R.check("the bend is the API's (max %.2e)" % diff, diff < TOL, diff)
    F = S.solver.triangles(obj.data)
    ar, _ = api(obj, d, fixed, tip, "ARAP")
    surf = np.asarray(ar.solve(transforms=[T], warm_start=False).positions)
    v0 = volume(rest, F)
    ours, arap = volume(got, F) / v0, volume(surf, F) / v0
    R.check("keeps the volume (%.3f) closer than ARAP (%.3f)" % (ours, arap),
            abs(ours - 1) < abs(arap - 1), (ours, arap))
    # saved and reopened: the settings and the binding's summary
    d.options_volume_arap.quality = 2.0
    path = os.path.join(S.OUTPUT, "volume_arap.blend")
    bpy.ops.wm.save_as_mainfile(filepath=path)
    bpy.ops.wm.open_mainfile(filepath=path)
    d = bpy.data.objects["Tube"].deformkit.deformers[0]
    R.check("settings survive saving", d.method == "VOLUME_ARAP" and
            abs(d.options_volume_arap.quality - 2.0) < 1e-9, d.method)
    # the quality change re-built the binding: the summary counts its tetrahedra
    obj = bpy.data.objects["Tube"]
    bpy.data.objects["Tip"].location.z += 0.05   # a drag re-builds the solver on demand
    bpy.context.view_layer.update()
    S.evaluated_positions(obj)
    e = S.solver.cache._cache.get((obj.name, d.uid))
    n = e.native.n_tetrahedra if e is not None else -1
    R.check("the summary follows the re-built binding (%s, at bind %s)"
            % (d.bind_summary, first),
            n > 0 and d.bind_summary.startswith("%d tetrahedra" % n) and d.bind_summary != first,
            (n, d.bind_summary))


def test_open_mesh_deforms_as_a_surface():
    S.reset_scene()
    obj, d, e, fixed, handle = S.grid_setup("VOLUME_ARAP")
    bpy.ops.deformkit.bind()
    R.check("an open grid binds", d.bound and not d.status_is_error, d.status)
    R.check("and says it deforms as a surface", "deformed as a surface" in S.solver.status_text(d),
            S.solver.status_text(d))
    e.location.z += 0.3
    bpy.context.view_layer.update()
    got = S.evaluated_positions(obj)
    R.check("its handle follows", abs(got[handle, 2].mean() - 0.3) < 0.02, got[handle, 2].mean())


def check_option(option, status_words, stats_key, stats_value, name):
    """Volume ARAP with `option` = 2 on the still tube: the status says `status_words`, the
    API's stats[stats_key] is stats_value, the bend is the API's with the option and the
    handle where it was moved, the setting survives saving, and after the Armature each
    frame is the API's edit of the pose."""
    S.reset_scene()
    obj, d, e, fixed, tip = S.tube_deformer("VOLUME_ARAP", **{option: 2})
    bind_world = e.matrix_world.copy()
    bpy.ops.deformkit.bind()
    text = S.solver.status_text(d)
    R.check("the status names the %s" % name, d.bound and status_words in text, text)
    e.matrix_world = S.bend_end(np.pi / 2) @ bind_world
    bpy.context.view_layer.update()
    got = S.evaluated_positions(obj)
    T = np.array(e.matrix_world @ bind_world.inverted())
    va, rest = api(obj, d, fixed, tip)
    R.check("the API has the %s too" % name, va.stats[stats_key] == stats_value, va.stats)
    va.solve(transforms=[np.eye(4)], warm_start=False)
    want = np.asarray(va.solve(transforms=[T], warm_start=True).positions)
    diff = float(np.abs(got - want).max())
    R.check("the bend is the API's with the %s (max %.2e)" % (name, diff), diff < TOL, diff)
    R.check("the handle is where it was moved",
            float(np.abs(got[tip] - (rest[tip] @ T[:3, :3].T + T[:3, 3])).max()) < 1e-5)
    path = os.path.join(S.OUTPUT, "volume_arap_%s.blend" % option)
    bpy.ops.wm.save_as_mainfile(filepath=path)
    bpy.ops.wm.open_mainfile(filepath=path)
    d = bpy.data.objects["Tube"].deformkit.deformers[0]
    value = getattr(d.options_volume_arap, option)
    R.check("the setting survives saving", value == 2, value)
    S.reset_scene()
    obj, d, e, fixed, tip = S.tube_deformer("VOLUME_ARAP", rig=S.lower_bone_rig,
                                            **{option: 2})
    S.check_edit_after_armature(R, obj, d, e, fixed, tip, TOL, "volume_arap_%s.pc2" % option)


def test_coarse_level():
    check_option("levels", "coarse level of", "levels", 2, "coarse level")


def test_coarse_solid():
    check_option("embed", "coarse solid", "embedded", 1, "coarse solid")


def test_after_an_armature():
    obj, d, e, fixed, tip = tube_setup(S.lower_bone_rig)
    got, inp = S.check_edit_after_armature(R, obj, d, e, fixed, tip, TOL, "volume_arap.pc2")
    moved = float(np.abs(got - inp).max())
    R.check("the deformer edits the pose (moved %.3f)" % moved, 0.05 < moved < 1.0, moved)
    F = S.solver.triangles(obj.data)
    v_in, v_out = volume(inp, F), volume(got, F)
    R.check("keeps the pose's volume (%.3f)" % (v_out / v_in), abs(v_out / v_in - 1) < 0.05,
            v_out / v_in)


for t in (test_still_mesh, test_open_mesh_deforms_as_a_surface, test_coarse_level, test_coarse_solid,
          test_after_an_armature):
    R.run(t)
R.finish()
