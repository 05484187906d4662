"""What a binding depends on besides the positions (the topology fingerprint), and which object
owns a deformer (its uid, copies, shared meshes)."""

import hashlib
import uuid

import bpy
import numpy as np

from .. import compat, geonodes
from ..errors import DeformKitError
from . import cache


TOPOLOGY_CHANGED = ("mesh topology changed since bind (faces or vertex order): bind again")


def topology_fingerprint(me):
    """What a binding depends on besides the positions, as a short string: the vertex count,
    each face's corner count and its corners' vertex indices, in order (Mesh.loops'
    vertex_index, Mesh.polygons' loop_total). Any edit of the connectivity or of the
    vertex order changes it (a sort, an edge rotate, a merge and a split that keep the
    counts); the same in every Blender version, so a file bound in one opens in another."""
    totals = np.empty(len(me.polygons), dtype=np.int32)
    me.polygons.foreach_get("loop_total", totals)
    corners = _corner_verts(me)
    h = hashlib.blake2b(digest_size=16)
    h.update(np.array([len(me.vertices), len(totals), len(corners)], dtype=np.int64).tobytes())
    h.update(totals.tobytes())
    h.update(corners.tobytes())
    return "v1:" + h.hexdigest()


def _corner_verts(me):
    a = me.attributes.get(".corner_vert") if compat.CORNER_ATTRIBUTES else None
    out = np.empty(len(me.loops), dtype=np.int32)
    if a is not None:
        a.data.foreach_get("value", out)
    else:
        me.loops.foreach_get("vertex_index", out)
    return out


def quick_topology(me):
    """Blender 3.6+ only (else None): the mesh's corner vertices, corner edges and edge
    vertices, read straight from its attributes (0.2-0.3 ms together at 43k vertices, where
    the full fingerprint takes 5-9 ms). Equal arrays mean an equal fingerprint: a corner's edge
    joins its vertex to the next corner's, so the corners' vertices and edges fix where
    each face ends (a face may not repeat a vertex)."""
    if not compat.CORNER_ATTRIBUTES:
        return None
    out = []
    for name, n in ((".corner_vert", len(me.loops)), (".corner_edge", len(me.loops)),
                    (".edge_verts", 2 * len(me.edges))):
        a = me.attributes.get(name)
        if a is None:
            return None
        buf = np.empty(n, dtype=np.int32)
        a.data.foreach_get("value", buf)
        out.append(buf)
    return out


def check_topology(obj, d, e=None, full=True):
    """Raises DeformKitError(TOPOLOGY_CHANGED) when the mesh's connectivity or vertex order
    is not the one `d` was bound on (d.bind_topology). With a cache entry `e`: from 3.6 the
    quick check against the arrays `e` took when its mesh matched (exact; a mismatch, such as
    edges merely re-ordered, goes on to the fingerprint); before 3.6 the fingerprint when
    `full`, else nothing. A deformer bound before fingerprints were stored takes the
    mesh's."""
    me = obj.data
    if e is not None and e.quick is not None:
        q = quick_topology(me)
        if q is not None and len(q) == len(e.quick) and all(
                np.array_equal(a, b) for a, b in zip(q, e.quick)):
            return
    elif e is not None and not full:
        return
    fp = topology_fingerprint(me)
    if not d.bind_topology:
        d.bind_topology = fp
    elif fp != d.bind_topology:
        raise DeformKitError(TOPOLOGY_CHANGED)
    if e is not None:
        e.quick = quick_topology(me)


def _holds_uid(o, uid):
    if o.type != "MESH":
        return None
    dks = getattr(o, "deformkit", None)
    if dks is None:
        return None
    return next((x for x in dks.deformers if x.uid == uid), None)


def ensure_own_uid(obj, d):
    """Makes d's uid (its attribute, modifier link and cache key) its object's own. A
    duplicate (Shift+D copies the deformer, Alt+D copies it onto the same mesh) keeps the
    original's uid and still names the original as its owner: it gets a fresh uid, its own
    attribute and its own cache (built from its mesh on its next solve), so that each object
    shows its own result. O(1) when d names obj as its owner; otherwise (a copy, a renamed
    object, a file from before owners were recorded) one pass over the objects. Returns
    True when d got a fresh uid."""
    if d.owner == obj.name:
        return False
    others = [o for o in bpy.data.objects if o != obj and _holds_uid(o, d.uid) is not None]
    claimed = any(_holds_uid(o, d.uid).owner == o.name for o in others)
    if not claimed:  # renamed, or the first of unclaimed holders: this one keeps it
        d.owner = obj.name
        return False
    me = obj.data
    old_uid, old_attr, old_mat = d.uid, d.attribute_name, "dk_%s_material" % d.uid
    mod = geonodes.find_modifier(obj, d)  # found by the old attribute name: before the change
    cache.drop(obj.name, old_uid)
    d.uid = new_uid()
    d.owner = obj.name
    d.sim_frame_key = ""   # the copy's attribute is a new one: no simulated frame yet
    if not any(o.data == me for o in others):  # its own mesh (Shift+D): the old data goes
        geonodes.remove_attribute(me, old_attr)
        old = me.color_attributes.get(old_mat) if hasattr(me, "color_attributes") else None
        if old is not None:
            me.color_attributes.remove(old)
    if mod is not None:
        compat.set_modifier_input(mod, geonodes.attribute_key(mod.node_group), d.attribute_name)
        geonodes.ensure_input_name(mod, d)
        geonodes.repair(mod, d)
    if d.bound:
        geonodes.ensure_attribute(me, d.attribute_name)
    obj.update_tag()
    return True


def new_uid():
    """A fresh deformer uid: the stable id of its attribute, modifier link and cache key."""
    return uuid.uuid4().hex[:10]


def mesh_users(me):
    """The objects whose data is `me`."""
    return [o for o in bpy.data.objects if o.data == me]


def check_single_user(obj, what):
    """Refuses writing into a mesh that other objects share (a linked duplicate, Alt+D):
    `what` ("apply", "bake to shape keys") would change them too."""
    users = mesh_users(obj.data)
    if len(users) > 1:
        raise DeformKitError("cannot %s: mesh '%s' is shared by %d objects (a linked "
                             "duplicate), which would all change; make it single-user first "
                             "(Object > Relations > Make Single User > Object & Data)"
                             % (what, obj.data.name, len(users)))
