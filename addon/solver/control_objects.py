"""What the collectors of control objects share (a Lattice object for a lattice, a mesh for a
cage): finding the deformer's control object, its placement in the deformed object's space,
and what Bind keeps of it in the file.

The control's rest is taken at Bind and kept in the deformer (d.control_bind, float64 as
base64 text, so a saved file opens without the add-on; d.control_bound_object, the object it
was taken from). From then on the mesh follows the control wherever it goes: its points'
edits, its hooks, its rig, and its object's own motion relative to the mesh, as Blender's
Mesh Deform follows its cage. Parent the control to the mesh (Make Lattice and Make Cage
do) and moving the mesh moves both."""

import base64

import numpy as np

from .. import methods
from ..errors import DeformKitError
from ..text import article


def encode(a):
    """float64 array -> the text d.control_bind keeps."""
    return base64.b64encode(np.ascontiguousarray(a, dtype="<f8").tobytes()).decode("ascii")


def decode(text):
    """d.control_bind's text -> a flat float64 array (empty for an empty text)."""
    if not text:
        return np.zeros(0)
    try:
        raw = base64.b64decode(text.encode("ascii"), validate=True)
    except (ValueError, UnicodeEncodeError):
        raise DeformKitError("the control's bind data is damaged: press Bind")
    if len(raw) % 8:
        raise DeformKitError("the control's bind data is damaged: press Bind")
    return np.frombuffer(raw, dtype="<f8").astype(np.float64)


def control_object(obj, d, kind, object_type, make=True):
    """d's control object, checked: set, in a scene, of `object_type` ("LATTICE", "MESH",
    "ARMATURE"), not the deformed object itself. `kind` names it in messages ("lattice",
    "cage"); `make`: the panel has Make <Kind> for it."""
    c = d.control_object
    if c is None:
        raise DeformKitError("no %s: pick one in the panel%s" % (
            kind, " (or Make %s)" % kind.title() if make else ""))
    if not c.users_scene:
        raise DeformKitError("%s '%s' was deleted" % (kind, c.name))
    if c.type != object_type:
        raise DeformKitError("%s '%s' is %s object, not %s" % (
            kind, c.name, article(c.type.lower()), article(object_type.lower())))
    if c.name == obj.name:
        raise DeformKitError("%s '%s' is the deformed mesh itself: pick another object"
                             % (kind, c.name))
    return c


def check_bound_object(obj, d, kind):
    """Raises when the control object is not the one Bind took the rest from."""
    b = d.control_bound_object
    if b is None or d.control_object is None or b.name != d.control_object.name:
        raise DeformKitError("%s is now '%s', bound to '%s': press Bind" % (
            kind, d.control_object.name if d.control_object else "none",
            b.name if b is not None else "none"))


def to_mesh_space(obj, c, depsgraph=None):
    """4 x 4: the control object's space -> the deformed object's space, as evaluated (its
    parents, constraints, drivers and keys on this frame)."""
    oe = obj.evaluated_get(depsgraph) if depsgraph is not None else obj
    ce = c.evaluated_get(depsgraph) if depsgraph is not None else c
    M = np.array(oe.matrix_world, dtype=np.float64)
    C = np.array(ce.matrix_world, dtype=np.float64)
    try:
        return np.linalg.solve(M, C)
    except np.linalg.LinAlgError:
        raise DeformKitError("'%s' has a singular transform (zero scale?)" % obj.name)


def transform(M, P):
    """Points P (n x 3) mapped by the 4 x 4 affine M."""
    return P @ M[:3, :3].T + M[:3, 3]


def store(d, captured):
    """Keeps what Bind took of the control (its collector's capture) in the deformer, with
    the object it was taken from (Bind's end, on success)."""
    d.control_bind = encode(captured)
    d.control_bound_object = d.control_object


def settings_key(d):
    """What the binding depends on besides the control's motion: the method's bind options
    and what Bind kept."""
    m = methods.get(d.method)
    return (methods.signature(m, d.options), d.control_bind)


def exists(d, object_type):
    """Whether d's control object is set, of `object_type` and in a scene (every solve)."""
    c = d.control_object
    return c is not None and c.type == object_type and bool(c.users_scene)

