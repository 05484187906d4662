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
key alone) is followed as the active key at weight 1 (what Blender shows then, the key's own
shape, is that when the key is relative to the Basis)."""

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
    # (a key relative to itself adds nothing, in Blender and as a pose equal to the Basis)
    return [kb for kb in key.key_blocks if kb != ref and (not names or kb.name in names)]


def _co(kb, n):
    co = np.empty(n * 3, dtype=np.float32)
    kb.data.foreach_get("co", co)
    return co.reshape(-1, 3).astype(np.float64)


def _mask(obj, kb, n):
    """The key's vertex-group weights (n, 0 off the group), or None where Blender applies the
    key unmasked: no group named, a group name the object lacks, or a mesh whose vertices
    carry no group at all (Blender's key.cc, get_weights_array)."""
    if not kb.vertex_group:
        return None
    vg = obj.vertex_groups.get(kb.vertex_group)
    if vg is None:
        return None
    m = np.zeros(n)
    any_group = False
    for v in obj.data.vertices:
        for g in v.groups:
            any_group = True
            if g.group == vg.index:
                m[v.index] = g.weight
    return m if any_group else None


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


def edit_input(obj, opts, source, bound_deltas=None):
    """What the native solve edits: the input less the owned keys' linear blend. `bound_deltas`
    (P x n x 3): the keys' deltas the binding was made with (the binding is made again when
    they change), read from the keys when None."""
    w = np.asarray(weights(obj, opts))
    if not w.any():
        return source
    D = deltas(obj, opts) if bound_deltas is None or len(bound_deltas) != len(w) else bound_deltas
    return source - np.tensordot(w, D, axes=1)


def signature(obj, opts):
    """What of the keys a binding depends on besides their shapes (their names, relative keys
    and groups): a change binds again."""
    return tuple((kb.name, kb.relative_key.name, kb.vertex_group) for kb in owned(obj, opts))
