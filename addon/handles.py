"""Where each handle's target puts its vertices on this frame, in the deformed object's space:
the hook transform of its target since the bind, less the rig's own motion of the bone the
target rides (the rig moved those vertices already), and turned with the pose of the
handle's vertices (an edit keyed once rides the animated part)."""

import numpy as np
from mathutils import Matrix

from . import native
from .animated_input import modifiers_above
from .errors import DeformKitError


def target_world(h, depsgraph=None):
    """World matrix of a handle's target (object, or bone of an armature); raises if missing."""
    t = h.target
    if t is None:
        raise DeformKitError("handle '%s' has no target: pick an object or bone" % h.name)
    if not t.users_scene:
        raise DeformKitError("handle '%s': target '%s' was deleted" % (h.name, t.name))
    te = t.evaluated_get(depsgraph) if depsgraph is not None else t
    if h.subtarget:
        if t.type != "ARMATURE":
            raise DeformKitError("handle '%s': bone '%s' set but target '%s' is not an armature"
                                 % (h.name, h.subtarget, t.name))
        pb = te.pose.bones.get(h.subtarget)
        if pb is None:
            raise DeformKitError("handle '%s': bone '%s' not found in '%s'"
                                 % (h.name, h.subtarget, t.name))
        return te.matrix_world @ pb.matrix
    return te.matrix_world.copy()


def _flat(m):
    return [m[r][c] for r in range(4) for c in range(4)]


def _mat(v):
    return Matrix((v[0:4], v[4:8], v[8:12], v[12:16]))


def bind_matrix(obj, h, depsgraph=None):
    """inverse(target world) @ object world, flat (16 floats): the handle's rest placement."""
    tw = target_world(h, depsgraph)
    try:
        inv = tw.inverted()
    except ValueError:
        raise DeformKitError("handle '%s': target '%s' has a singular transform (zero scale?)"
                             % (h.name, h.target.name))
    ow = obj.evaluated_get(depsgraph).matrix_world if depsgraph is not None else obj.matrix_world
    return _flat(inv @ ow)


def rig_bone(obj, d, h, depsgraph=None):
    """(armature object, bone name) when the handle's target rides a bone of an armature
    that deforms d's input (an Armature modifier above d's, enabled): the target is that
    bone, or an object parented to it (through other objects too), and the bone deforms
    (use_deform, and the mesh has its vertex group). Else None."""
    t, bone = h.target, h.subtarget
    if t is None:
        return None
    if not (t.type == "ARMATURE" and bone):
        bone = None
        while t is not None and bone is None:
            if t.parent is not None and t.parent_type == "BONE" and t.parent_bone:
                bone = t.parent_bone
            t = t.parent
        if bone is None:
            return None
    b = t.data.bones.get(bone) if t.type == "ARMATURE" else None
    if b is None or not b.use_deform or obj.vertex_groups.get(bone) is None:
        return None  # a control bone, or one that deforms nothing here: the rig moved nothing
    for m in modifiers_above(obj, d, depsgraph):
        if m.type == "ARMATURE" and m.object is not None and m.object.name == t.name:
            return t, bone
    return None


def rig_motion(obj, d, h, depsgraph=None):
    """How the rig moves the vertices the handle's bone carries, in obj's space: obj^-1 @
    armature @ pose bone @ inverse(bone rest) @ armature^-1 @ obj, as the Armature modifier
    deforms them (a Matrix); None when the target rides no such bone (rig_bone)."""
    rb = rig_bone(obj, d, h, depsgraph)
    if rb is None:
        return None
    arm, bone = rb
    ae = arm.evaluated_get(depsgraph) if depsgraph is not None else arm
    pb = ae.pose.bones.get(bone)
    if pb is None:
        return None
    ow = obj.evaluated_get(depsgraph).matrix_world if depsgraph is not None else obj.matrix_world
    try:
        return (ow.inverted() @ ae.matrix_world @ pb.matrix @ pb.bone.matrix_local.inverted()
                @ ae.matrix_world.inverted() @ ow)
    except ValueError:
        raise DeformKitError("handle '%s': the rig '%s' or '%s' has a singular transform"
                             % (h.name, arm.name, obj.name))


def rig_bind(obj, d, h, depsgraph=None):
    """rig_motion at bind, flat (16 floats), or all 0 when there is none."""
    m = rig_motion(obj, d, h, depsgraph) if d is not None else None
    return (0.0,) * 16 if m is None else _flat(m)


def set_bind_matrix(obj, h, depsgraph=None, d=None):
    h.bind_matrix = bind_matrix(obj, h, depsgraph)
    h.rig_matrix = rig_bind(obj, d, h, depsgraph)
    h.is_bound = True


def transforms(obj, d, depsgraph=None):
    """n_handles x 4 x 4 transforms (object space) of the rest pose. A handle whose target
    rides a bone of the rig that deforms the input (rig_bone) gives only the artist's
    deviation from the rig: the target's motion since bind T, less the rig's motion of that
    bone since bind R, as T @ R^-1. The rig already moved those vertices in the input, and
    the deformer adds its offset there: T alone moved them twice (issue 39: a forearm keyed
    90 degrees swung 180). With M the rig's deformation now and M_b at bind, the target's
    motion is T M_b = M K (K: the artist's own move, in the bone's rest frame), the vertices
    belong at M K r, and the offset added to the rig's M r is (T M_b - M) r:
    T' = I + T M_b - M. A target that follows its bone exactly gives the identity, and the
    vertices stay where the rig shows them."""
    ow = obj.evaluated_get(depsgraph).matrix_world if depsgraph is not None else obj.matrix_world
    try:
        owi = ow.inverted()
    except ValueError:
        raise DeformKitError("'%s' has a singular transform (zero scale?)" % obj.name)
    out = np.empty((len(d.handles), 4, 4), dtype=np.float64)
    for i, h in enumerate(d.handles):
        tw = target_world(h, depsgraph)
        if not h.is_bound:
            set_bind_matrix(obj, h, depsgraph, d)
        T = owi @ tw @ _mat(h.bind_matrix)
        M = rig_motion(obj, d, h, depsgraph)
        if M is not None:
            if not any(h.rig_matrix):  # the rig came after the bind: its pose now is the rest
                h.rig_matrix = _flat(M)
            T = Matrix.Identity(4) + T @ _mat(h.rig_matrix) - M
        out[i] = np.array(T)
    return out


def rigid_fit(rest, moved):
    """The rigid motion (4 x 4) that best maps the points `rest` (k x 3) onto `moved`: the
    rotation of the centred cross-covariance (deformkit.closest_rotation), then the
    centroids' shift. Fewer than three points, or points on a line, define no rotation:
    the shift alone."""
    cr, cm = rest.mean(axis=0), moved.mean(axis=0)
    A = (moved - cm).T @ (rest - cr)
    R = np.eye(3)
    if len(rest) >= 3:
        sv = np.linalg.svd(A, compute_uv=False)
        if sv[1] > 1e-9 * sv[0]:
            R = np.asarray(native.get().closest_rotation(A), dtype=np.float64)
    G = np.eye(4)
    G[:3, :3], G[:3, 3] = R, cm - R @ cr
    return G


def pose_bind(rest, handles, inp):
    """At bind: each handle's rigid fit from the rest to the input (`inp`, None: the rest),
    flat (16 floats each), for its pose_matrix: the pose the edit is made on."""
    return [tuple((np.eye(4) if inp is None else rigid_fit(rest[idx], inp[idx])).ravel())
            for idx in handles]


def turn_with_the_pose(d, rest, handles, T, inp):
    """The transforms (n_handles x 4 x 4) that give each handle's vertices, solved from the
    rest and added to the input `inp` as the deformer's offset, the place its `follow`
    asks for. G is the rigid fit of the handle's vertices from the rest to this frame's
    input, G_b the same at bind (pose_matrix; the pose the edit was made on):
      POSE:  the edit T - I, made on the bind pose, turned with the vertices since:
             T' = I + R (T - I) G_b, R the rotation of G G_b^-1 (the same offset, seen
             from the handle's vertices, on every frame);
      WORLD: the vertices where T puts them on the bind pose, wherever the input went:
             T' = I + T G_b - G (exact where the input moves them rigidly).
    Unchanged where the input is the rest (`inp` None), and for a handle that rides the
    rig (its transform is the deviation from its bone already, transforms())."""
    if inp is None:
        return T
    out = T.copy()
    eye = np.eye(4)
    for i, (h, idx) in enumerate(zip(d.handles, handles)):
        if i >= len(T) or any(h.rig_matrix):
            continue
        Gb = np.array(h.pose_matrix, dtype=np.float64).reshape(4, 4)
        G = rigid_fit(rest[idx], inp[idx])
        if not Gb.any():  # bound before the pose was recorded: this frame's pose is the bind's
            Gb = G
            h.pose_matrix = tuple(G.ravel())
        if h.follow == "WORLD":
            out[i] = eye + T[i] @ Gb - G
        else:
            Rm = eye.copy()
            Rm[:3, :3] = G[:3, :3] @ Gb[:3, :3].T
            out[i] = eye + Rm @ (T[i] - eye) @ Gb
    return out
