"""Corrective shape keys (issue 39, item 7): the deformer's edit at the current pose, stored as
a shape key under the Armature and driven by a bone's rotation, the rigging pattern that
plays without DeformKit and blends in between poses.

A shape key moves the rest before the Armature, so the key holds the edit carried back
through the Armature's deformation: at each vertex the Armature (linear or dual-quaternion
blend of its bones, Preserve Volume or not) maps rest positions affinely, p -> J p + c, and
the key's offset is J^-1 times the edit seen on the pose. J is measured, not assumed: the
object is evaluated with the rest moved by eps along x, y and z in turn (a temporary shape
key), the deformer off; the differences over eps are J's columns, exact for an affine map up
to float32 rounding.
"""

import bpy
import numpy as np

from . import animated_input, geonodes, handlers, solver
from .errors import DeformKitError


def _evaluated(obj):
    return solver.evaluated_positions(obj)


def armature_jacobians(obj, d, eps):
    """Per vertex the 3 x 3 derivative (n x 3 x 3) of the input d's modifier receives with
    respect to the rest, at the current frame: finite differences of step `eps` through a
    temporary shape key (removed after), with every DeformKit modifier at and below d's off.
    Also returns the input itself (n x 3)."""
    mods = [m for m in obj.modifiers]
    mod = geonodes.find_modifier(obj, d)
    below = mods[mods.index(mod):] if mod is not None else []
    shown = [(m, m.show_viewport) for m in below]
    keys_before = obj.data.shape_keys is not None
    active_before = obj.active_shape_key_index
    rest = solver.rest_positions(obj.data)
    n = len(rest)
    J = np.empty((n, 3, 3))
    handlers_were = handlers.enabled[0]
    handlers.enabled[0] = False  # no deformer re-solves on the probe's evaluations
    try:
        for m in below:
            m.show_viewport = False
        if not keys_before:
            obj.shape_key_add(name="Basis", from_mix=False)
        base = _evaluated(obj)
        probe = obj.shape_key_add(name="DeformKit probe", from_mix=False)
        probe.value = 1.0
        for k in range(3):
            moved = rest.copy()
            moved[:, k] += eps
            probe.data.foreach_set("co", moved.astype(np.float32).ravel())
            obj.data.update()
            J[:, :, k] = (_evaluated(obj) - base) / eps
    finally:
        keys = obj.data.shape_keys
        if keys is not None:
            p = keys.key_blocks.get("DeformKit probe")
            if p is not None:
                obj.shape_key_remove(p)
            if not keys_before and len(keys.key_blocks) == 1:
                obj.shape_key_remove(keys.key_blocks[0])
        obj.active_shape_key_index = active_before
        for m, v in shown:
            m.show_viewport = v
        obj.data.update()
        handlers.enabled[0] = handlers_were
    return J, base


def driving_bone(obj, d):
    """(armature object, bone name) whose rotation drives the key by default: the bone that
    carries the most weight of the handles' vertices, among the deforming bones of the
    Armature modifiers above d."""
    arms = [m.object for m in animated_input.modifiers_above(obj, d)
            if m.type == "ARMATURE" and m.object is not None]
    if not arms:
        raise DeformKitError("%s has no Armature above it: a corrective shape key is driven "
                             "by a bone of the rig that deforms the mesh" % d.name)
    groups = solver.blender_data.read_groups(
        obj, {h.vertex_group for h in d.handles if h.vertex_group})
    handle = np.unique(np.concatenate([g[0] for g in groups.values()] or [np.zeros(0, int)]))
    best, best_w = None, -1.0
    bones = {b.name: a for a in arms for b in a.data.bones if b.use_deform}
    if not bones:
        raise DeformKitError("the rig above %s has no deforming bone" % d.name)
    weights = solver.blender_data.read_groups(obj, set(bones))
    for name, (idx, w) in weights.items():
        total = float(w[np.isin(idx, handle)].sum())
        if total > best_w:
            best, best_w = name, total
    if best is None:
        raise DeformKitError("no vertex group of %s is named after a deforming bone of the "
                             "rig above %s" % (obj.name, d.name))
    return bones[best], best


def bone_turn(arm, bone):
    """The bone's rotation from its rest, in its own space: (axis letter, angle in radians)
    of the largest of its X, Y and Z Euler angles (the driver's variable). These are the
    bone's own channels (the driver's Local Space), without constraints: a limb posed by IK
    drives no key through its deform bones; bake on the bone the animator keys."""
    pb = arm.pose.bones[bone]
    e = pb.matrix_basis.to_euler("XYZ")
    k = int(np.argmax(np.abs(e)))
    return "XYZ"[k], float(e[k])


def bake_corrective(obj, d, name=None, bone=None):
    """Stores the deformer's edit at the current frame as a shape key under the Armature,
    driven to 1 at this pose's rotation of the driving bone (0 at its rest, in between
    linearly). Returns (the key, the bone's name). The deformer stays: mute or remove it to
    play the key."""
    if obj.data.users > 1:
        raise DeformKitError("mesh '%s' is shared: a shape key would change every user"
                             % obj.data.name)
    arm, bone = (bone if bone is not None else driving_bone(obj, d))
    axis, angle = bone_turn(arm, bone)
    if abs(angle) < 1e-3:
        raise DeformKitError("bone '%s' is at its rest here: pose it (the key is driven by "
                             "its rotation), then bake the corrective" % bone)
    dg = bpy.context.evaluated_depsgraph_get()
    solver.finish(obj, d, dg)
    # the edit as d's modifier adds it to its input: factor * its offset attribute
    a = obj.data.attributes.get(d.attribute_name)
    if a is None or len(a.data) != len(obj.data.vertices):
        raise DeformKitError("%s has no result here: bind it first" % d.name)
    edit = np.empty(len(a.data) * 3, dtype=np.float32)
    a.data.foreach_get("vector", edit)
    edit = geonodes.factor(obj, d) * edit.reshape(-1, 3).astype(np.float64)
    diag = float(np.linalg.norm(np.ptp(solver.rest_positions(obj.data), axis=0))) or 1.0
    J, _ = armature_jacobians(obj, d, 1e-2 * diag)
    try:
        offset = np.linalg.solve(J, edit[:, :, None])[:, :, 0]
    except np.linalg.LinAlgError:
        raise DeformKitError("the Armature collapses some vertices here (a zero scale?): no "
                             "corrective can be carried back to the rest") from None
    rest = solver.rest_positions(obj.data)
    if obj.data.shape_keys is None:
        obj.shape_key_add(name="Basis", from_mix=False)
    key = obj.shape_key_add(name=name or "%s %s %.0f" % (d.name, bone, np.degrees(angle)),
                            from_mix=False)
    key.data.foreach_set("co", (rest + offset).astype(np.float32).ravel())
    key.slider_min, key.slider_max = 0.0, 1.0
    fc = key.driver_add("value")
    drv = fc.driver
    drv.type = "SCRIPTED"
    var = drv.variables.new()
    var.name = "turn"
    var.type = "TRANSFORMS"
    t = var.targets[0]
    t.id = arm
    t.bone_target = bone
    t.transform_type = "ROT_" + axis
    t.rotation_mode = "XYZ"
    t.transform_space = "LOCAL_SPACE"
    drv.expression = "turn / %r" % angle
    obj.data.update()
    return key, bone
