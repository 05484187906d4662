"""What reaches a deformer on this frame: the modifiers and shape keys above it in the stack
(an Armature's pose), read from the evaluated object where its Geometry Nodes modifier stores
its input, and what may and may not be written back into the mesh under them."""

import bpy
import numpy as np

from . import geonodes, methods, native
from .errors import DeformKitError
from .text import plural


_edits_input = {}


def follows(m):
    """Whether method `m` edits the animated input it receives (its result depends on it):
    through update_source (m.follows_input) or the native contract's input_positions
    (edits_input). The others solve on the rest, and their offset lands on the input."""
    if m.follows_input:
        return True
    if m.native_class not in _edits_input:
        _edits_input[m.native_class] = bool(native.method_info(m.native_class).get(
            "edits_input", False))
    return _edits_input[m.native_class]


def depends_on_input(m, d):
    """Whether d's result depends on its input: its method follows the input, or d solves
    from the rest with its handles where the input puts them (Solve From: Rest Shape; a
    method driven by a control object has no handles, and no such choice)."""
    return follows(m) or (d.solve_from == "REST"
                          and "vertex_groups" in native.control_kinds(m.native_class))


def pose_note(obj, d):
    """What the panel says when d's method solves on the rest while an Armature above it
    poses the mesh (and d does not solve from the rest shape between handles where the
    input puts them): its edit is pasted on the pose in the rest's directions away from the
    handles (2-6% of the model from a bind on the pose, docs/methods/fundamental.md), with
    the methods that edit the pose. None otherwise."""
    m = methods.get(d.method)
    if m.stack_first:  # a blend of shape keys: exact first in the stack
        above = [mm.name for mm in modifiers_above(obj, d)]
        if above and obj.data.shape_keys is not None:
            return ("%s sits below %s: the keys' straight blend it replaces is taken off in "
                    "the rest's directions, which a pose turns; move it to the top of the "
                    "stack for the exact blend" % (m.label, ", ".join(above)))
        return None
    if depends_on_input(m, d) or not any(mm.type == "ARMATURE"
                                         for mm in modifiers_above(obj, d)):
        return None
    kinds = native.control_kinds(m.native_class)
    # (a blend of poses is not suggested for a handle's edit)
    editors = [x.label for x in methods.METHODS if x.id != m.id and follows(x) and x.poses is None
               and native.has_class(x.native_class)
               and native.control_kinds(x.native_class) == kinds]
    names = (", ".join(editors[:-1]) + " and " + editors[-1]) if len(editors) > 1 else \
        "".join(editors)
    where = ("away from the handles" if "vertex_groups" in kinds
             else "wherever the pose turns the mesh")
    return ("%s solves on the rest pose: on the posed mesh its edit keeps the rest's "
            "directions %s%s" % (m.label, where,
                                 ". %s edit%s the pose" % (names, "" if len(editors) > 1 else "s")
                                 if editors else ""))


def modifiers_above(obj, d, depsgraph=None):
    """The modifiers above d's own in the stack that are enabled for the depsgraph's mode
    (viewport or render)."""
    mod = geonodes.find_modifier(obj, d)
    render = depsgraph is not None and depsgraph.mode == "RENDER"
    out = []
    for mm in obj.modifiers:
        if mm == mod:
            break
        if mm.show_render if render else mm.show_viewport:
            out.append(mm)
    return out


def input_movers(obj, d, depsgraph=None):
    """What may move the mesh before d's modifier sees it, for messages ("'Armature'",
    "shape keys"), or None when its input is the base mesh."""
    above = modifiers_above(obj, d, depsgraph)
    keys = obj.data.shape_keys
    if not above and (keys is None or len(keys.key_blocks) < 2):
        return None
    return ", ".join("'%s'" % mm.name for mm in above) or "shape keys"


def moved_input(obj, d, depsgraph=None):
    """What reaches d's modifier (n x 3, object space) when shape keys or modifiers above it
    can move the base mesh, or None when the input is the base mesh itself. Read from the
    evaluated object, where the modifier stores its input (geonodes, version 2)."""
    what = input_movers(obj, d, depsgraph)
    if what is None:
        return None
    mod = geonodes.find_modifier(obj, d)
    if mod is None or not geonodes.ensure_input_name(mod, d):
        raise DeformKitError("%s: its Geometry Nodes modifier is missing or not DeformKit's: "
                             "bind again" % d.name)
    dg = depsgraph if depsgraph is not None else bpy.context.evaluated_depsgraph_get()
    a = obj.evaluated_get(dg).data.attributes.get(d.input_attribute_name)
    if a is None:  # the Input name was just set (bind): evaluate the stack with it
        dg.update()
        a = obj.evaluated_get(dg).data.attributes.get(d.input_attribute_name)
    if a is None:
        raise DeformKitError("%s cannot read what %s gives it: its modifier is disabled or a "
                             "modifier below it drops attributes" % (d.name, what))
    n = len(obj.data.vertices)
    if len(a.data) != n:
        raise DeformKitError("%s follows %s, but the final mesh has %s, not %d: a "
                             "modifier below it (Subdivision?) changes the vertex count; "
                             "disable it while editing, or move it above %s"
                             % (d.name, what, plural(len(a.data), "vertex"), n, d.name))
    co = np.empty(n * 3, dtype=np.float32)
    a.data.foreach_get("vector", co)
    return co.reshape(-1, 3).astype(np.float64)


def check_input_is_rest(obj, d, what, depsgraph=None, every_method=False):
    """Refuses writing a follower's result into the mesh or its shape keys (`what`: "apply",
    "bake to shape keys") while something above moves its input: the modifiers and keys
    that moved it would move the written shape again. `every_method`: also for a method
    that solves from the rest, while modifiers above move its input (shape keys hold
    positions before modifiers: a rig would move each frame's baked shape again; shape keys
    alone add up, the baked key's offset on top of the others')."""
    if not depends_on_input(methods.get(d.method), d):
        above = modifiers_above(obj, d, depsgraph) if every_method else []
        if above:
            raise DeformKitError("cannot %s %s: its input is moved by %s above it, which "
                                 "would move the baked shapes again; bake to Point Cache "
                                 "instead" % (what, d.name,
                                              ", ".join("'%s'" % m.name for m in above)))
        return
    by = input_movers(obj, d, depsgraph)
    if by is not None:
        raise DeformKitError("cannot %s %s: its input is moved by %s above it, which would "
                             "move the written shape again; bake to Point Cache instead"
                             % (what, d.name, by))


def input_transforms(e, T, source):
    """Transforms that act on the input `source` as T (n_handles x 4 x 4) acts on the rest:
    each handle's vertices move by the offset T gives them at rest, turned into the input by
    the rigid fit G of the handle's vertices from the rest to the input: I + (T - I) G^-1
    (exact where the input moves them rigidly). For a method that edits its input and whose
    transforms are not positions (Falloff blends them per vertex)."""
    from .handles import rigid_fit
    out = np.empty_like(T)
    for i, (h, t) in enumerate(zip(e.handles, T)):
        out[i] = np.eye(4) + (t - np.eye(4)) @ np.linalg.inv(rigid_fit(e.rest[h], source[h]))
    return out


def edit_targets(e, T, source):
    """Section 5 of Sumner et al.: each handle vertex's edit (its displacement by the handle's
    transform T at its bind-time rest position) added to where `source` (the animated input)
    puts it. Equal to T applied to the rest when the input is the rest."""
    out = []
    for h, t in zip(e.handles, T):
        r = e.rest[h]
        out.append(source[h] + (r @ t[:3, :3].T + t[:3, 3] - r))
    return np.concatenate(out) if out else np.zeros((0, 3))   # no handles (a blend of poses)
