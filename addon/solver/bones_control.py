"""The collector for bones: a Blender Armature object drives deformkit.Skinning.

The bones are the armature's deforming bones that have a vertex group of their name on the
mesh (as Blender's Armature modifier reads them), in the armature's order. Bind takes each
bone's rest frame (bone.matrix_local) where the armature object stands, in the mesh's space,
and keeps them with their names (d.control_bind, JSON). The weights are the vertex groups',
normalised per vertex as the Armature modifier does; a vertex no bone weighs stays at rest,
through one more bone that never moves. On each frame each bone moves the mesh as the
Armature modifier moves it: its pose against its rest (pose_bone.matrix times the inverse of
bone.matrix_local), seen from where the armature object stands now; moving the armature
object alone moves nothing (parent the mesh to it, as for the Armature modifier)."""

import base64
import json

import numpy as np

from ..errors import DeformKitError
from . import blender_data, control_objects

KIND = "bones"
LABEL = "Armature"
OBJECT_TYPE = "ARMATURE"
MAKE_OPERATOR = "deformkit.compute_weights"  # the weights, into the bones' groups
SOLVE_KEYWORD = "transforms"   # the solve takes the bones' frames as transforms
uses_handles = False


def _armature(obj, d):
    return control_objects.control_object(obj, d, "armature", OBJECT_TYPE, make=False)


def _bone_names(obj, arm):
    """The deforming bones with a vertex group of their name on `obj`, in armature order."""
    return [b.name for b in arm.data.bones
            if b.use_deform and obj.vertex_groups.get(b.name) is not None]


def capture(obj, d, depsgraph=None):
    """The bones' names and rest frames in the mesh's space (Bind keeps them)."""
    arm = _armature(obj, d)
    names = _bone_names(obj, arm)
    if not names:
        raise DeformKitError("armature '%s' has no deforming bone with a vertex group of its "
                             "name on '%s': name vertex groups after the bones"
                             % (arm.name, obj.name))
    M = control_objects.to_mesh_space(obj, arm, depsgraph)
    frames = np.array([M @ np.array(arm.data.bones[n].matrix_local, dtype=np.float64)
                       for n in names])
    return {"names": names, "frames": frames}


def _encode(captured):
    return json.dumps({"names": captured["names"], "frames": base64.b64encode(
        np.ascontiguousarray(captured["frames"], dtype="<f8").tobytes()).decode("ascii")})


def _decode(text):
    try:
        c = json.loads(text)
        frames = np.frombuffer(base64.b64decode(c["frames"]), dtype="<f8").reshape(-1, 4, 4)
        names = [str(n) for n in c["names"]]
    except (ValueError, KeyError, TypeError):
        raise DeformKitError("not bound to an armature: press Bind")
    if len(names) != len(frames):
        raise DeformKitError("the armature's bind data is damaged: press Bind")
    return {"names": names, "frames": frames.astype(np.float64)}


def weights(obj, names):
    """n x (len(names) + 1): the groups' weights normalised per vertex; the last column the
    unmoving bone's (1 where no bone weighs the vertex)."""
    groups = blender_data.read_groups(obj, set(names))
    n = len(obj.data.vertices)
    W = np.zeros((n, len(names) + 1))
    for j, name in enumerate(names):
        idx, w = groups.get(name, (np.zeros(0, np.int64), np.zeros(0)))
        W[idx, j] = w
    total = W[:, :-1].sum(axis=1)
    some = total > 0.0
    W[some, :-1] /= total[some, None]
    W[~some, -1] = 1.0
    return W


def collect(obj, d, captured=None):
    """The bind's keywords (bone_frames with the unmoving bone last, weights) and the bytes
    that change when they do."""
    _armature(obj, d)
    c = captured if captured is not None else _decode(d.control_bind)
    if captured is None:
        control_objects.check_bound_object(obj, d, "armature")
    for n in c["names"]:
        if obj.vertex_groups.get(n) is None:
            raise DeformKitError("bone '%s' has no vertex group on '%s' any more: press Bind"
                                 % (n, obj.name))
    frames = np.concatenate([c["frames"], np.eye(4)[None]])
    W = weights(obj, c["names"])
    return (dict(bone_frames=frames, weights=W),
            frames.tobytes() + b"|" + W.tobytes())


def store(d, captured):
    d.control_bind = _encode(captured)
    d.control_bound_object = d.control_object


settings_key = control_objects.settings_key


def exist(obj, d):
    return control_objects.exists(d, OBJECT_TYPE)


def targets(obj, d, e, depsgraph=None):
    """The bones' current frames (n_bones + 1 frames, the unmoving bone last) in the mesh's
    space on this frame."""
    arm = _armature(obj, d)
    control_objects.check_bound_object(obj, d, "armature")
    c = _decode(d.control_bind)
    ae = arm.evaluated_get(depsgraph) if depsgraph is not None else arm
    M = control_objects.to_mesh_space(obj, arm, depsgraph)
    Minv = np.linalg.inv(M)
    out = np.empty((len(c["names"]) + 1, 4, 4))
    for j, name in enumerate(c["names"]):
        pb = ae.pose.bones.get(name)
        if pb is None:
            raise DeformKitError("armature '%s' has no bone '%s' any more: press Bind"
                                 % (arm.name, name))
        # the bone's motion in the armature's space, pose times the inverse of its rest,
        # seen from where the armature stands now (as the Armature modifier sees it), as
        # the frame that gives that motion against the bound rest frame
        motion = np.array(pb.matrix, dtype=np.float64) @ np.linalg.inv(
            np.array(pb.bone.matrix_local, dtype=np.float64))
        out[j] = M @ motion @ Minv @ c["frames"][j]
    out[-1] = np.eye(4)
    if not np.isfinite(out).all():
        raise DeformKitError("armature '%s' has a bone at infinity or NaN" % arm.name)
    return out


def summary(d):
    c = d.control_object
    return "armature '%s'" % c.name if c is not None else None


def missing(d):
    """What the idle status asks for before Bind, or None when the control is set."""
    return None if d.control_object is not None else "pick an armature"
