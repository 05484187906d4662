"""The collector for a lattice control: a Blender Lattice object drives deformkit.Lattice.

Bind takes the lattice's rest grid (its points' `co`) where its object puts it, as the
native lattice's box (`frame`: the unit cube's map into the mesh's space); a solve's points
are the evaluated lattice's `co_deform` (edits, shape keys, hooks, an Armature on the
lattice) where its object is now. An axis with one point (a flat lattice) becomes two
layers that move together, spanning the mesh: Blender weighs that layer on every vertex
along the axis, and so do they.

Kept at Bind (d.control_bind, 35 floats): the frame (mesh space, 16), the map B of the unit
cube onto the lattice's own box (lattice space, 16) and the lattice's point counts (3)."""

import numpy as np

from ..errors import DeformKitError
from . import blender_data, control_objects

KIND = "lattice"
LABEL = "Lattice"
OBJECT_TYPE = "LATTICE"
MAKE_OPERATOR = "deformkit.make_lattice"
SOLVE_KEYWORD = "targets"   # the solve takes the control's points as positions
uses_handles = False

# a one-point axis: its two layers span the mesh along it, this much beyond it
ONE_LAYER_MARGIN = 0.05


def _lattice(obj, d):
    return control_objects.control_object(obj, d, KIND, OBJECT_TYPE)


def _points(lt, attr):
    a = np.empty(len(lt.points) * 3, dtype=np.float32)
    lt.points.foreach_get(attr, a)
    return a.reshape(-1, 3).astype(np.float64)


def _counts(lt):
    return (int(lt.points_u), int(lt.points_v), int(lt.points_w))


def _grid(res):
    """The unit-cube coordinates of a res[0] x res[1] x res[2] grid, x fastest."""
    axes = [np.linspace(0.0, 1.0, n) for n in res]
    z, y, x = np.meshgrid(axes[2], axes[1], axes[0], indexing="ij")
    return np.stack([x.ravel(), y.ravel(), z.ravel()], axis=1)


def _native_res(counts):
    return tuple(max(2, n) for n in counts)


def _blender_index(counts):
    """For each native point (x fastest), the Blender point it moves with: a one-point axis'
    two layers both follow its one point."""
    nr = _native_res(counts)
    idx = [np.minimum(np.arange(n), c - 1) for n, c in zip(nr, counts)]
    k, j, i = np.meshgrid(idx[2], idx[1], idx[0], indexing="ij")
    return (i + counts[0] * (j + counts[1] * k)).ravel()


def capture(obj, d, depsgraph=None):
    """What Bind keeps of the lattice now (control_objects.encode's input)."""
    c = _lattice(obj, d)
    lt = c.data
    counts = _counts(lt)
    co = _points(lt, "co")
    M = control_objects.to_mesh_space(obj, c, depsgraph)
    lo, hi = co.min(axis=0), co.max(axis=0)
    # the rest points must be the grid their box says (Blender keeps them regular)
    B0 = np.eye(4)
    B0[:3, :3] = np.diag(hi - lo)
    B0[:3, 3] = lo
    size = max(float(np.abs(hi - lo).max()), 1e-30)
    if np.abs(control_objects.transform(B0, _grid(counts)) - co).max() > 1e-5 * size:
        raise DeformKitError("lattice '%s': its rest points are not a regular grid" % c.name)
    # a one-point axis: the layers span the mesh along it (in the lattice's space)
    try:
        inv = np.linalg.inv(M)
    except np.linalg.LinAlgError:
        raise DeformKitError("lattice '%s' has a singular transform (zero scale?)" % c.name)
    local = control_objects.transform(inv, blender_data.rest_positions(obj.data))
    for a, n in enumerate(counts):
        if n == 1:
            reach = float(np.abs(local[:, a] - lo[a]).max()) if len(local) else 0.0
            h = reach * (1.0 + ONE_LAYER_MARGIN) + 1e-3 * size
            lo[a], hi[a] = lo[a] - h, hi[a] + h
    B = np.eye(4)
    B[:3, :3] = np.diag(hi - lo)
    B[:3, 3] = lo
    return np.concatenate([(M @ B).ravel(), B.ravel(), np.array(counts, dtype=np.float64)])


def _unpack(blob):
    if len(blob) != 35:
        raise DeformKitError("not bound to a lattice: press Bind")
    frame, B = blob[:16].reshape(4, 4), blob[16:32].reshape(4, 4)
    return frame, B, tuple(int(round(x)) for x in blob[32:35])


def collect(obj, d, captured=None):
    """The bind's keywords (resolution, frame) from what Bind took (`captured`, else what
    the deformer keeps), and the bytes that change when they do."""
    _lattice(obj, d)
    blob = captured if captured is not None else control_objects.decode(d.control_bind)
    frame, _B, counts = _unpack(blob)
    if captured is None:
        control_objects.check_bound_object(obj, d, KIND)
    return dict(resolution=_native_res(counts), frame=frame), blob.tobytes()


store = control_objects.store
settings_key = control_objects.settings_key


def exist(obj, d):
    return control_objects.exists(d, OBJECT_TYPE)


def targets(obj, d, e, depsgraph=None):
    """The native lattice's points (n_controls x 3, the deformed mesh's space) on this
    frame: the evaluated lattice's points where its object is now."""
    c = _lattice(obj, d)
    control_objects.check_bound_object(obj, d, KIND)
    _frame, B, counts = _unpack(control_objects.decode(d.control_bind))
    lt = (c.evaluated_get(depsgraph) if depsgraph is not None else c).data
    if _counts(lt) != counts:
        raise DeformKitError("lattice '%s' has points %d x %d x %d, bound with %d x %d x %d: "
                             "press Bind" % ((c.name,) + _counts(lt) + counts))
    bi = _blender_index(counts)
    co, cd = _points(lt, "co"), _points(lt, "co_deform")
    # each native point moves as its Blender point does: the point's edit, at the native
    # point's rest place in the lattice's space
    rest_local = control_objects.transform(B, _grid(_native_res(counts)))
    local = cd[bi] + (rest_local - co[bi])
    P = control_objects.transform(control_objects.to_mesh_space(obj, c, depsgraph), local)
    if not np.isfinite(P).all():
        raise DeformKitError("lattice '%s' has points at infinity or NaN" % c.name)
    return P


def summary(d):
    c = d.control_object
    return "lattice '%s'" % c.name if c is not None else None


def missing(d):
    """What the idle status asks for before Bind, or None when the control is set."""
    return None if d.control_object is not None else "pick a lattice (or Make Lattice)"
