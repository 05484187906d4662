"""The mesh's shape keys as the poses of a Shape Blend deformer (deformkit.ShapeInterpolation).

Blender blends relative shape keys linearly before the modifier stack: the input a deformer
receives is basis + sum_k value_k (key_k - relative_k) (each key's delta masked by its vertex
group). A Shape Blend deformer takes the keys it owns (Shape Keys: the names given, or every
key but the reference one) as poses, each pose being the basis plus that key's delta, and
their values (keyed, driven, dragged: the keys' own sliders) as weights. It edits the input
less the owned keys' linear blend -- what the stack gives without them: the basis, the other
keys, and the modifiers above -- so that the owned keys' linear blend is replaced by the
in-between that keeps the shape. Exactly so where the deformer sits directly below the shape
keys (the top of the stack); below an Armature the keys' deltas are taken off in the rest's
directions, as Blender adds them. Muted keys weigh 0; "Shape Key Lock" (the pin: the active
key alone, at 1) is followed."""

import numpy as np

from .errors import DeformKitError


def _key(obj):
    key = obj.data.shape_keys
    if key is None or len(key.key_blocks) < 2:
        return None
    if not key.use_relative:
        raise DeformKitError("the mesh's shape keys are absolute (Relative is off): Shape "
                             "Blend blends relative shape keys")
    return key


def owned(obj, opts):
    """The key blocks the deformer blends, in the mesh's order ([] without shape keys)."""
    key = _key(obj)
    if key is None:
        return []
    names = [n.strip() for n in opts.key_names.split(",") if n.strip()]
    for n in names:
        if key.key_blocks.get(n) is None:
            raise DeformKitError("Shape Keys: the mesh has no shape key '%s'" % n)
    ref = key.reference_key
    blocks = [kb for kb in key.key_blocks if kb != ref and (not names or kb.name in names)]
    for kb in blocks:
        if kb.relative_key == kb:
            raise DeformKitError("shape key '%s' is relative to itself: it adds nothing to "
                                 "blend" % kb.name)
    return blocks


def _co(kb, n):
    co = np.empty(n * 3, dtype=np.float32)
    kb.data.foreach_get("co", co)
    return co.reshape(-1, 3).astype(np.float64)


def _mask(obj, kb, n):
    """The key's vertex-group weights (n; 1 everywhere without a group, 0 off it)."""
    if not kb.vertex_group:
        return None
    vg = obj.vertex_groups.get(kb.vertex_group)
    m = np.zeros(n)
    if vg is None:
        return m  # Blender applies nothing of a key whose group is missing
    for v in obj.data.vertices:
        for g in v.groups:
            if g.group == vg.index:
                m[v.index] = g.weight
    return m


def deltas(obj, opts):
    """Each owned key's delta from its relative key (P x n x 3), masked as Blender masks it."""
    n = len(obj.data.vertices)
    out = []
    for kb in owned(obj, opts):
        dlt = _co(kb, n) - _co(kb.relative_key, n)
        m = _mask(obj, kb, n)
        out.append(dlt if m is None else dlt * m[:, None])
    return np.array(out).reshape(-1, n, 3)


def poses(obj, opts, rest):
    """The bind's poses (P x n x 3): the rest plus each owned key's delta; None without keys."""
    D = deltas(obj, opts)
    return None if len(D) == 0 else rest[None, :, :] + D


def weights(obj, opts):
    """The owned keys' weights on this frame: their values (muted ones 0; with the shape key
    lock on, the active key 1 and the others 0)."""
    blocks = owned(obj, opts)
    if obj.show_only_shape_key:
        active = obj.active_shape_key
        return [0.0 if kb.mute else float(kb == active) for kb in blocks]
    return [0.0 if kb.mute else float(kb.value) for kb in blocks]


def solve_args(obj, opts, scene):
    """The solve's weights (Method.solve_args)."""
    return {"weights": weights(obj, opts)}


def edit_input(obj, opts, source):
    """What the native solve edits: the input less the owned keys' linear blend."""
    w = np.asarray(weights(obj, opts))
    if not w.any():
        return source
    return source - np.tensordot(w, deltas(obj, opts), axes=1)


def signature(obj, opts):
    """What of the keys a binding depends on besides their shapes (their names, relative keys
    and groups): a change binds again."""
    return tuple((kb.name, kb.relative_key.name, kb.vertex_group) for kb in owned(obj, opts))
