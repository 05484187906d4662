"""The collector for a cage control: any closed mesh object drives deformkit.Cage.

Bind takes the cage as evaluated now (its modifiers, shape keys and rig applied), where its
object puts it, as the cage's rest (d.control_bind: k x 3 floats, the mesh's space); its
triangles are its mesh's (modifiers that change its vertex count are refused). A solve's
cage is the evaluated cage where its object is now: edit it, key it, hook it or rig it, and
the mesh follows. An edit that changes its vertex count asks for Bind."""

import numpy as np

from ..errors import DeformKitError
from ..text import plural
from . import blender_data, control_objects

KIND = "cage"
LABEL = "Cage"
OBJECT_TYPE = "MESH"
MAKE_OPERATOR = "deformkit.make_cage"
SOLVE_KEYWORD = "targets"   # the solve takes the control's points as positions
uses_handles = False


def _cage(obj, d):
    return control_objects.control_object(obj, d, KIND, OBJECT_TYPE)


def _evaluated(c, depsgraph):
    """The cage's evaluated mesh: (positions k x 3 in its object's space, triangles)."""
    me = (c.evaluated_get(depsgraph) if depsgraph is not None else c).data
    co = np.empty(len(me.vertices) * 3, dtype=np.float32)
    me.vertices.foreach_get("co", co)
    return co.reshape(-1, 3).astype(np.float64), me


def capture(obj, d, depsgraph=None):
    """The cage's vertices now, in the deformed mesh's space (Bind keeps them)."""
    c = _cage(obj, d)
    co, me = _evaluated(c, depsgraph)
    if len(co) != len(c.data.vertices):
        raise DeformKitError("cage '%s': its modifiers change its vertex count (%d to %d); "
                             "apply them, or pick another cage" % (c.name, len(c.data.vertices),
                                                                   len(co)))
    if len(co) < 4 or len(me.polygons) == 0:
        raise DeformKitError("cage '%s' has %s and %s: a cage is a closed mesh around the "
                             "deformed one" % (c.name, plural(len(co), "vertex"),
                                               plural(len(me.polygons), "face")))
    return control_objects.transform(control_objects.to_mesh_space(obj, c, depsgraph), co).ravel()


def collect(obj, d, captured=None):
    """The bind's keywords (cage_vertices, cage_triangles) and the bytes that change when
    they do. The triangles are read from the cage now; their vertex count must be Bind's."""
    c = _cage(obj, d)
    blob = captured if captured is not None else control_objects.decode(d.control_bind)
    if captured is None:
        control_objects.check_bound_object(obj, d, KIND)
    if len(blob) == 0 or len(blob) % 3:
        raise DeformKitError("not bound to a cage: press Bind")
    rest = blob.reshape(-1, 3)
    # the triangles of the cage's own mesh (its modifiers keep its vertices: capture)
    me = c.data
    if len(me.vertices) != len(rest):
        raise DeformKitError("cage '%s' has %s, bound with %d: press Bind"
                             % (c.name, plural(len(me.vertices), "vertex"), len(rest)))
    tris = blender_data.triangles(me)
    return dict(cage_vertices=rest, cage_triangles=tris), blob.tobytes() + tris.tobytes()


store = control_objects.store
settings_key = control_objects.settings_key


def exist(obj, d):
    return control_objects.exists(d, OBJECT_TYPE)


def targets(obj, d, e, depsgraph=None):
    """The cage's vertices on this frame (k x 3, the deformed mesh's space)."""
    c = _cage(obj, d)
    control_objects.check_bound_object(obj, d, KIND)
    co, _me = _evaluated(c, depsgraph)
    k = len(control_objects.decode(d.control_bind)) // 3
    if len(co) != k:
        raise DeformKitError("cage '%s' has %s, bound with %d: press Bind"
                             % (c.name, plural(len(co), "vertex"), k))
    P = control_objects.transform(control_objects.to_mesh_space(obj, c, depsgraph), co)
    if not np.isfinite(P).all():
        raise DeformKitError("cage '%s' has vertices at infinity or NaN" % c.name)
    return P


def summary(d):
    c = d.control_object
    return "cage '%s'" % c.name if c is not None else None


def missing(d):
    """What the idle status asks for before Bind, or None when the control is set."""
    return None if d.control_object is not None else "pick a cage mesh (or Make Cage)"
