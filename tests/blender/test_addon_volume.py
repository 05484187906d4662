"""Issue 44: the Volume ARAP deformer (deformkit.VolumetricARAP) deforms the solid inside a
closed mesh. On a still capped tube, its far end a handle and its near end fixed: bound, the
status counts the tetrahedra; the handle moved as a 90-degree bend moves the tube's end bends it as the API does
(warm, from the bind pose), keeping its volume where ARAP's loses it. On an open grid it
binds too and says that it deforms as a surface. After an Armature bending the tube (keyed),
each frame is the API's edit of the Armature's pose, its handle at the pose's place; a bake
writes what played; the settings survive saving and reopening."""
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
    """A capped tube along x (S.tube), 'fixed' its x < -0.9 end, 'tip' its x > 0.9 end on an
    empty at (1, 0, 0), a Volume ARAP deformer (below the Armature `rig` makes, if any)."""
    S.reset_scene()
    V, F = S.tube(n_len=33)
    obj = S.triangle_mesh_object(V, F, name="Tube")
    ao = rig(obj) if rig is not None else None
    fixed, tip = np.flatnonzero(V[:, 0] < -0.9), np.flatnonzero(V[:, 0] > 0.9)
    S.group(obj, "fixed", fixed)
    S.group(obj, "tip", tip)
    e = S.empty("Tip", (1.0, 0.0, 0.0))
    bpy.context.view_layer.objects.active = obj
    bpy.ops.deformkit.add_deformer(method="VOLUME_ARAP")
    d = obj.deformkit.deformers[-1]
    d.fixed_group = "fixed"
    bpy.ops.deformkit.add_handle(vertex_group="tip", target=e.name)
    return obj, d, e, fixed, tip, ao


def api(obj, d, fixed, tip, cls="VolumetricARAP"):
    rest = S.rest_positions(obj)
    mesh = S.dk.Mesh(rest, S.solver.triangles(obj.data))
    o = d.options_volume_arap
    return getattr(S.dk, cls)(mesh, handles=[tip], fixed=fixed, tolerance=o.tolerance,
                              max_iterations=o.max_iterations), rest


def test_still_mesh():
    obj, d, e, fixed, tip, _ = tube_setup()
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


def rig(obj):
    """A two-bone Armature first in the stack, its lower bone turned about z by 0 at frame 1
    and 0.8 at frame 5."""
    return S.arm_rig(obj, {"lower": ((1, (0, 0, 0.0)), (5, (0, 0, 0.8)))})


def test_after_an_armature():
    obj, d, e, fixed, tip, ao = tube_setup(rig)
    sc = bpy.context.scene
    sc.frame_start, sc.frame_end = 1, 5
    sc.frame_set(1)
    bind_world = e.matrix_world.copy()
    bpy.ops.deformkit.bind()
    R.check("binds after an Armature", d.bound and not d.status_is_error, d.status)
    # the handle (parented to nothing) lifted: at each frame the deformer edits the pose
    e.location.z += 0.2
    sc.frame_set(5)
    got = S.evaluated_positions(obj)
    inp = S.armature_input(obj, d)
    R.check("the Armature bends the input", np.abs(inp - S.rest_positions(obj)).max() > 0.3,
            np.abs(inp - S.rest_positions(obj)).max())
    moved = float(np.abs(got - inp).max())
    R.check("the deformer edits the pose (moved %.3f)" % moved, 0.05 < moved < 1.0, moved)
    R.check("its fixed end stays where the Armature puts it",
            float(np.abs(got[fixed] - inp[fixed]).max()) < TOL,
            float(np.abs(got[fixed] - inp[fixed]).max()))
    # the API on the pose: the handle where the edit (a lift), turned with the lower bone,
    # puts it (tests/blender/test_addon_animation.py, for every method that edits its input)
    m = S.methods.get(d.method)
    rest = S.rest_positions(obj)
    mesh = S.dk.Mesh(rest, S.solver.triangles(obj.data))
    kw = dict(handles=[tip], fixed=fixed)
    native = S.dk.VolumetricARAP(mesh, **kw, **S.methods.bind_kwargs(m, d.options, rest, kw,
                                                                       mesh))
    T = np.array(e.matrix_world @ bind_world.inverted())
    edit = rest[tip] @ T[:3, :3].T + T[:3, 3] - rest[tip]
    B = S.bone_turn(obj, "lower")
    want = np.asarray(native.solve(inp[tip] + edit @ B.T, input_positions=inp,
                                   **S.methods.solve_kwargs(m, d.options, True)).positions)
    diff = float(np.abs(got - want).max())
    R.check("frame 5 is the API's edit of the pose (max %.2e)" % diff, diff < TOL, diff)
    F = S.solver.triangles(obj.data)
    v_in, v_out = volume(inp, F), volume(got, F)
    R.check("keeps the pose's volume (%.3f)" % (v_out / v_in), abs(v_out / v_in - 1) < 0.05,
            v_out / v_in)
    # a bake writes what played
    shown = {}
    for f in range(1, 6):
        sc.frame_set(f)
        shown[f] = S.evaluated_positions(obj)
    diff = S.bake_differs_from(obj, d, shown, "volume_arap.pc2")
    R.check("the bake = playback (max %.2e)" % diff, diff < TOL, diff)

for t in (test_still_mesh, test_open_mesh_deforms_as_a_surface, test_after_an_armature):
    R.run(t)
R.finish()
