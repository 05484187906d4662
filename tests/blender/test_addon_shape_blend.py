"""Issue 43: the Shape Blend deformer (deformkit.ShapeInterpolation) blends the mesh's shape
keys keeping the shape. On a still tube with a 360-degree Twist key and a Bend key: it binds
without handles; a key's slider at 0.5 shows the API's in-between (where Blender's own blend
halves the volume); at 0 the mesh is untouched; a key it does not own stays Blender's linear
blend under it; a muted key weighs nothing; a keyed slider plays frame by frame as the API
computes it, and a bake writes what played. After an Armature (the keys below it), each frame
is the API's edit of the Armature's pose less the keys' linear blend. The settings survive
saving and reopening."""
import os
import sys
sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
import _setup as S  # noqa: E402
import bpy  # noqa: E402
import numpy as np  # noqa: E402
from addon import animated_input  # noqa: E402

R = S.Results("test_addon_shape_blend")
twist, bend, volume = S.shapes.twist, S.shapes.bend, S.shapes.volume   # tests/python/shapes.py
TOL = 2e-5   # float32 storage of the mesh, the keys and the result


def keyed_tube(rig=None):
    """A capped tube along x with shape keys Basis, Twist (360 degrees) and Bend (100
    degrees), a Shape Blend deformer on it (below the Armature `rig` makes, if any), bound."""
    S.reset_scene()
    V, F = S.tube(n_len=33)
    obj = S.triangle_mesh_object(V, F, name="Tube")
    rest = S.rest_positions(obj)
    obj.shape_key_add(name="Basis")
    for name, P in (("Twist", twist(rest, 2 * np.pi)), ("Bend", bend(rest, np.radians(100)))):
        kb = obj.shape_key_add(name=name, from_mix=False)
        kb.data.foreach_set("co", P.astype(np.float32).ravel())
        kb.value = 0.0   # (a new key starts at 1 in some releases)
    ao = rig(obj) if rig is not None else None
    bpy.context.view_layer.objects.active = obj
    bpy.ops.deformkit.add_deformer(method="SHAPE_BLEND")
    d = obj.deformkit.deformers[0]
    sc = bpy.context.scene
    sc.frame_start, sc.frame_end = 1, 12
    sc.frame_set(1)
    bpy.ops.deformkit.bind()
    R.check("binds without a handle", d.bound and not d.status_is_error, d.status)
    return obj, d, ao


def key_positions(obj, name):
    kb = obj.data.shape_keys.key_blocks[name]
    co = np.empty(len(kb.data) * 3, dtype=np.float32)
    kb.data.foreach_get("co", co)
    return co.reshape(-1, 3).astype(np.float64)


def api(obj, names):
    """The Python API bound as the add-on binds: the rest and the named keys as poses."""
    rest = S.rest_positions(obj)
    mesh = S.dk.Mesh(rest, S.solver.triangles(obj.data))
    return S.dk.ShapeInterpolation(mesh, poses=[key_positions(obj, n) for n in names]), rest


def shown(obj):
    return S.evaluated_positions(obj)


def linear_only(obj, d):
    """Blender's own blend: the stack with DeformKit's modifier off."""
    return S.armature_input(obj, d)


def test_still_mesh():
    obj, d, _ = keyed_tube()
    si, rest = api(obj, ["Twist", "Bend"])
    F = S.solver.triangles(obj.data)
    keys = obj.data.shape_keys.key_blocks
    R.check("at 0 the mesh is untouched", np.array_equal(shown(obj), rest))
    keys["Twist"].value = 0.5
    got = shown(obj)
    want = np.asarray(si.solve(weights=[0.5, 0.0]).positions)
    diff = float(np.abs(got - want).max())
    R.check("Twist at 0.5 = the API's in-between (max %.2e)" % diff, diff < TOL, diff)
    v0 = volume(rest, F)
    ours, theirs = volume(got, F) / v0, volume(linear_only(obj, d), F) / v0
    R.check("half way the volume stays (%.3f) where Blender's blend halves it (%.3f)"
            % (ours, theirs), abs(ours - 1) < 0.03 and theirs < 0.6, (ours, theirs))
    keys["Bend"].value = 0.7
    want = np.asarray(si.solve(weights=[0.5, 0.7]).positions)
    diff = float(np.abs(shown(obj) - want).max())
    R.check("two keys blend together as the API's (max %.2e)" % diff, diff < TOL, diff)
    keys["Twist"].mute = True
    want = np.asarray(si.solve(weights=[0.0, 0.7]).positions)
    diff = float(np.abs(shown(obj) - want).max())
    R.check("a muted key weighs nothing (max %.2e)" % diff, diff < TOL, diff)
    keys["Twist"].mute = False
    # a key masked by a vertex group: its pose is masked as Blender masks it; a group name
    # the object lacks leaves the key unmasked, in Blender and in the pose
    S.group(obj, "tip", np.flatnonzero(rest[:, 0] > 0.3), np.clip(rest[rest[:, 0] > 0.3, 0], 0, 1))
    keys["Bend"].vertex_group = "tip"
    mask = np.zeros(len(rest))
    vg = obj.vertex_groups["tip"]
    for v in obj.data.vertices:
        for g in v.groups:
            if g.group == vg.index:
                mask[v.index] = g.weight
    masked = rest + mask[:, None] * (key_positions(obj, "Bend") - rest)
    mesh = S.dk.Mesh(rest, S.solver.triangles(obj.data))
    sm = S.dk.ShapeInterpolation(mesh, poses=[key_positions(obj, "Twist"), masked])
    want = np.asarray(sm.solve(weights=[0.5, 0.7]).positions)
    diff = float(np.abs(shown(obj) - want).max())
    R.check("a key masked by a group blends its masked shape (max %.2e)" % diff, diff < TOL, diff)
    keys["Bend"].vertex_group = "no such group"
    want = np.asarray(si.solve(weights=[0.5, 0.7]).positions)
    diff = float(np.abs(shown(obj) - want).max())
    R.check("a key's missing group leaves it unmasked, as in Blender (max %.2e)" % diff,
            diff < TOL, diff)
    keys["Bend"].vertex_group = ""
    # a key the deformer does not own stays Blender's linear blend under it
    d.options_shape_blend.key_names = "Twist"
    one, _ = api(obj, ["Twist"])
    lin = 0.7 * (key_positions(obj, "Bend") - rest)
    want = np.asarray(one.solve(weights=[0.5], input_positions=rest + lin).positions)
    diff = float(np.abs(shown(obj) - want).max())
    R.check("Shape Keys 'Twist': Bend stays linear under it (max %.2e)" % diff,
            diff < TOL and not d.status_is_error, (diff, d.status))
    d.options_shape_blend.key_names = "Twist, Nope"
    shown(obj)
    R.check("a key name the mesh lacks is named in the status",
            d.status_is_error and "Nope" in d.status, d.status)
    d.options_shape_blend.key_names = ""
    shown(obj)
    R.check("and clears with the name", not d.status_is_error, d.status)


def test_keyed_playback_and_bake():
    obj, d, _ = keyed_tube()
    si, rest = api(obj, ["Twist", "Bend"])
    kb = obj.data.shape_keys.key_blocks["Twist"]
    for f, v in ((1, 0.0), (12, 1.0)):
        kb.value = v
        kb.keyframe_insert("value", frame=f)
    frames = list(range(1, 13))
    got = {}
    for f in frames:
        bpy.context.scene.frame_set(f)
        got[f] = shown(obj)
    worst = 0.0
    for f in frames:
        bpy.context.scene.frame_set(f)
        want = np.asarray(si.solve(weights=[kb.value, 0.0]).positions)
        worst = max(worst, float(np.abs(got[f] - want).max()))
    R.check("a keyed slider plays as the API computes each frame (max %.2e)" % worst,
            worst < TOL, worst)
    diff = S.bake_differs_from(obj, d, {f: got[f] for f in frames}, "shape_blend.pc2")
    R.check("the bake = playback (max %.2e)" % diff, diff < TOL, diff)
    # the settings survive saving and reopening
    d.options_shape_blend.key_names = "Twist"
    blend = os.path.join(S.OUTPUT, "shape_blend.blend")
    bpy.ops.wm.save_as_mainfile(filepath=blend)
    bpy.ops.wm.open_mainfile(filepath=blend)
    obj = bpy.data.objects["Tube"]
    d = obj.deformkit.deformers[0]
    R.check("Shape Keys survives a reload", d.options_shape_blend.key_names == "Twist",
            d.options_shape_blend.key_names)


def test_a_pinned_blend():
    """A handle on the bar's +x cap (its empty left where it was bound) and the -x end fixed:
    both are placed on the input less the keys' blend, so zero weights give the mesh back and
    half way is the API's in-between pinned there."""
    obj, d, _ = keyed_tube()
    rest = S.rest_positions(obj)
    tip = np.flatnonzero(rest[:, 0] > 0.95)
    root = np.flatnonzero(rest[:, 0] < -0.95)
    S.group(obj, "tip", tip)
    S.group(obj, "root", root)
    e = S.empty("Tip", tuple(rest[tip].mean(0)))
    bpy.ops.deformkit.add_handle(vertex_group="tip", target=e.name)
    d.fixed_group = "root"
    bpy.ops.deformkit.bind()
    R.check("binds with a handle and a fixed group", d.bound and not d.status_is_error, d.status)
    R.check("zero weights with the handle at rest: the mesh", np.array_equal(shown(obj), rest))
    obj.data.shape_keys.key_blocks["Bend"].value = 0.5   # the tip moves with the Bend key
    mesh = S.dk.Mesh(rest, S.solver.triangles(obj.data))
    si = S.dk.ShapeInterpolation(mesh, [tip], fixed=root,
                                 poses=[key_positions(obj, "Twist"), key_positions(obj, "Bend")])
    want = np.asarray(si.solve(weights=[0.0, 0.5], targets=rest[tip],
                               input_positions=rest).positions)
    got = shown(obj)
    diff = float(np.abs(got - want).max())
    R.check("half way, pinned at both ends: the API's in-between (max %.2e)" % diff,
            diff < TOL, diff)
    R.check("the pinned ends stay", float(np.abs(got[tip] - rest[tip]).max()) < TOL and
            float(np.abs(got[root] - rest[root]).max()) < TOL)


def rig(obj):
    """A two-bone Armature first in the stack, the lower bone turned by 0.6 about z."""
    return S.arm_rig(obj, {"lower": ((1, (0, 0, 0.6)),)})


def posed_copy(obj, positions):
    """A copy of obj with `positions` as its mesh and only its Armature modifier: what the
    Armature makes of those positions."""
    me = obj.data.copy()
    c = bpy.data.objects.new(obj.name + "_ref", me)
    bpy.context.scene.collection.objects.link(c)
    c.shape_key_clear()
    c.data.vertices.foreach_set("co", positions.astype(np.float32).ravel())
    for vg in obj.vertex_groups:
        c.vertex_groups.new(name=vg.name)
    for name in ("upper", "lower"):
        src = obj.vertex_groups[name]
        for v in obj.data.vertices:
            for g in v.groups:
                if g.group == src.index:
                    c.vertex_groups[name].add([v.index], g.weight, "REPLACE")
    am = c.modifiers.new("Armature", "ARMATURE")
    am.object = bpy.data.objects["Rig"]
    return c


def test_after_an_armature():
    """Added to a rigged mesh, Shape Blend goes first in the stack, above the Armature, which
    then poses the blend: each frame is the Armature applied to the API's in-between. Moved
    below the Armature it edits the pose less the keys' linear blend (the panel says so)."""
    obj, d, ao = keyed_tube(rig)
    mods = [m.type for m in obj.modifiers]
    R.check("added first in the stack, above the Armature", mods == ["NODES", "ARMATURE"], mods)
    si, rest = api(obj, ["Twist", "Bend"])
    keys = obj.data.shape_keys.key_blocks
    keys["Twist"].value = 0.5
    keys["Bend"].value = 0.3
    got = shown(obj)
    ref = posed_copy(obj, np.asarray(si.solve(weights=[0.5, 0.3]).positions))
    want = S.evaluated_positions(ref)
    diff = float(np.abs(got - want).max())
    R.check("the Armature poses the API's in-between (max %.2e)" % diff, diff < TOL, diff)
    F = S.solver.triangles(obj.data)
    v0 = volume(rest, F)
    inp = linear_only(obj, d)
    ours, theirs = volume(got, F) / v0, volume(inp, F) / v0
    R.check("the posed in-between keeps its volume (%.3f; Blender's blend %.3f)"
            % (ours, theirs), abs(ours - 1) < 0.05 and theirs < 0.7, (ours, theirs))
    R.check("no placement note first in the stack", animated_input.pose_note(obj, d) is None)
    # below the Armature: the API's edit of the pose less the keys' linear blend
    with bpy.context.temp_override(object=obj):
        bpy.ops.object.modifier_move_to_index(modifier=obj.modifiers[0].name, index=1)
    inp = linear_only(obj, d)
    lin = 0.5 * (key_positions(obj, "Twist") - rest) + 0.3 * (key_positions(obj, "Bend") - rest)
    want = np.asarray(si.solve(weights=[0.5, 0.3], input_positions=inp - lin).positions)
    got = shown(obj)
    diff = float(np.abs(got - want).max())
    R.check("below an Armature: the API's edit of the pose less the keys' blend (max %.2e)"
            % diff, diff < TOL, diff)
    ours = volume(got, F) / v0
    R.check("there still closer to the volume (%.3f) than Blender's blend (%.3f)"
            % (ours, volume(inp, F) / v0), ours > volume(inp, F) / v0 + 0.2, ours)
    note = animated_input.pose_note(obj, d)
    R.check("the panel says to move it to the top", note and "top of the stack" in note, note)


for t in (test_still_mesh, test_keyed_playback_and_bake, test_a_pinned_blend,
          test_after_an_armature):
    R.run(t)
R.finish()
