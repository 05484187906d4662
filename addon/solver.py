"""Bridges Blender data and the native solvers; no numerics here.

Blender -> arrays: vertex groups become index arrays (and weight arrays), handle targets become
4x4 transforms in the deformed object's space, exactly like a Hook modifier:
    T = inverse(object world) @ target world @ bind_matrix,
    bind_matrix = inverse(target world at bind) @ object world at bind.
Arrays -> Blender: offset = solved - rest is written into the deformer's point attribute, read by
its Geometry Nodes modifier. The base mesh positions are never written here.

Solver state (native objects) is cached by (object name, deformer uid) and holds no bpy
references; it is rebuilt on demand (after file load, undo, settings or group changes).
"""

import hashlib
import math
import time

import bpy
import numpy as np

from . import compat, geonodes, methods, native
from .animated_input import (check_input_is_rest, depends_on_input, edit_targets,  # noqa: F401
                             follows, input_movers, input_transforms, modifiers_above,
                             moved_input)
from .errors import DeformKitError, OverlapError  # noqa: F401
from .handles import (bind_matrix, pose_bind, rig_bind, set_bind_matrix,  # noqa: F401
                      target_world, transforms, turn_with_the_pose)
from .text import article, plural


NATIVE_ERRORS = (ValueError, IndexError, TypeError, RuntimeError, MemoryError, OverflowError)

_cache = {}            # (object name, deformer uid) -> _Entry
# (object name, deformer uid) -> the last solve: dict(ms=..., iterations=..., converged=...,
# energy=..., slices=...); the slices of one interactive solve add up (solve(), resume)
runtime = {}
_settings_serial = [0]
# Undo and redo converge before they show: on_undo bumps the serial, and the next solve of
# each deformer that writes its result is a full one (not a budgeted slice or a preview)
# until it has been solved since (key -> the serial of its last written solve).
_undo_serial = [0]
_written_at_undo = {}
# (object name, deformer uid) -> worker thread of a UI bind (operators.DEFORMKIT_OT_bind),
# from its invoke until its modal part ends. A file load drops modal handlers without ending
# them: clear_cache (on load_post) forgets those.
running_binds = {}


class _Entry:
    __slots__ = ("native", "dkmesh", "rest", "extent", "n_vertices", "n_faces", "settings",
                 "groups", "last_inputs", "method_id", "verified", "pending", "pending_its",
                 "handles", "source", "preview_at", "material", "material_shown", "slice_cost",
                 "moved_at", "quick", "worker", "slice_ms", "graph_shown", "basis",
                 "result_pos", "result_T", "preview_inputs", "warned", "last_cold", "last_T",
                 "fit_for", "fit_text", "native_source")


def mark_settings_changed():
    _settings_serial[0] += 1


def clear_cache():
    _cache.clear()
    runtime.clear()
    _written_at_undo.clear()
    running_binds.clear()
    _cancel_rebinds()


def mark_unverified(obj):
    """The object is in Edit or Sculpt Mode, where its topology may change: its deformers'
    next solve checks the mesh in full."""
    for (name, _uid), e in _cache.items():
        if name == obj.name:
            e.verified = False


def mark_all_dirty():
    """After undo/redo: the attribute may hold an older result; re-check everything, and
    solve every deformer in full before showing it again (an undone Apply would otherwise
    show a budgeted slice of a solve from the naive start: 14 cm off on the armadillo for
    the seconds the refine timer takes)."""
    for e in _cache.values():
        e.last_inputs = None
        e.verified = False
    _undo_serial[0] += 1


def converges_next(key):
    """True when the next solve of `key` is a full one because of an undo or redo since its
    last written solve."""
    return _written_at_undo.get(key, 0) != _undo_serial[0]


def drop(obj_name, uid):
    _cache.pop((obj_name, uid), None)
    runtime.pop((obj_name, uid), None)
    _cancel_rebinds((obj_name, uid))


# ------------------------------------------------------------------ reading Blender data ----

def check_mesh_type(obj):
    if obj.type != "MESH":
        raise DeformKitError("DeformKit deforms mesh objects; '%s' is %s"
                             % (obj.name, article(obj.type.lower().replace("_", " "))))


def check_object(obj, d=None):
    if obj is None:
        raise DeformKitError("no active object")
    check_mesh_type(obj)
    me = obj.data
    if len(me.vertices) == 0:
        raise DeformKitError("mesh '%s' has no vertices" % me.name)
    needs_faces = d is None or methods.get(d.method).needs_faces
    if len(me.polygons) == 0 and needs_faces:
        raise DeformKitError("mesh '%s' has no faces: this method needs a surface (Embedded "
                             "Deformation also deforms vertex clouds)" % me.name)
    if obj.mode == "EDIT":
        raise DeformKitError("'%s' is in Edit Mode: leave it to bind or solve" % obj.name)


def evaluated_positions(obj):
    """The object's evaluated (modifier stack applied) vertex positions, object space."""
    dg = bpy.context.evaluated_depsgraph_get()
    dg.update()
    ev = obj.evaluated_get(dg)
    me = ev.to_mesh()
    co = np.empty(len(me.vertices) * 3, dtype=np.float32)
    me.vertices.foreach_get("co", co)
    ev.to_mesh_clear()
    return co.reshape(-1, 3).astype(np.float64)


def rest_positions(me):
    """The base mesh's positions (n x 3 float64). From 3.6 through the "position" attribute:
    0.04 ms at 43k vertices where MeshVertex.co takes 1-4 ms in 4.2-5.0, and every solve
    compares them with the binding's."""
    co = np.empty(len(me.vertices) * 3, dtype=np.float32)
    a = me.attributes.get("position") if compat.CORNER_ATTRIBUTES else None
    if a is not None and a.domain == "POINT" and a.data_type == "FLOAT_VECTOR":
        a.data.foreach_get("vector", co)
    else:
        me.vertices.foreach_get("co", co)
    return co.reshape(-1, 3).astype(np.float64)


def triangles(me):
    me.calc_loop_triangles()
    tri = np.empty(len(me.loop_triangles) * 3, dtype=np.int32)
    me.loop_triangles.foreach_get("vertices", tri)
    return tri.reshape(-1, 3)


def read_groups(obj, names):
    """{group name: (indices int32, weights float64)} for the existing groups in `names`;
    members are vertices with weight > 0. One pass over the vertices."""
    by_index = {}
    for n in names:
        vg = obj.vertex_groups.get(n)
        if vg is not None:
            by_index[vg.index] = n
    idx = {n: [] for n in by_index.values()}
    wts = {n: [] for n in by_index.values()}
    if by_index:
        for v in obj.data.vertices:
            for g in v.groups:
                n = by_index.get(g.group)
                if n is not None and g.weight > 0.0:
                    idx[n].append(v.index)
                    wts[n].append(g.weight)
    return {n: (np.array(idx[n], dtype=np.int32), np.array(wts[n], dtype=np.float64))
            for n in idx}


def _settings_key(d):
    m = methods.get(d.method)
    return (methods.signature(m, d.options), d.roi_group, d.fixed_group, d.material_group,
            tuple((h.vertex_group, h.use_weights) for h in d.handles))


def check_editable(obj):
    """DeformKitError when `obj` or its mesh is linked from a library: nothing the add-on
    writes (the deformer's settings, its result attribute, an applied mesh) can be stored
    there, and Bind and Apply reported success having written nothing, Apply even removing
    the deformer (the second hostile review)."""
    lib = obj.library
    if lib is not None:
        raise DeformKitError("'%s' is linked from the library '%s': DeformKit cannot change it "
                             "here (make it local: Object > Relations > Make Local)"
                             % (obj.name, lib.name))
    lib = getattr(obj.data, "library", None)
    if lib is not None:
        raise DeformKitError("the mesh '%s' of '%s' is linked from the library '%s': DeformKit "
                             "cannot change it here (make it local: Object > Relations > Make "
                             "Local > Object and Data)" % (obj.data.name, obj.name, lib.name))


def group_names(obj, d):
    """The names of the vertex groups `d` reads (handles, region, fixed, material, cut)."""
    m = methods.get(d.method)
    names = {h.vertex_group for h in d.handles if h.vertex_group}
    names.update(g for g in (d.roi_group, d.fixed_group, d.material_group) if g)
    if "cut" in m.maps:
        names.update(g for g in (getattr(d.options, o) for o in m.cut_options) if g)
    return names


def groups_exist(obj, d):
    """Whether every vertex group `d` reads is still there: a name lookup each, cheap enough
    for every solve. A group removed by a script (obj.vertex_groups.remove) tags no update,
    so the binding's copy of it went on being used, and Apply wrote its result (the second
    hostile review); the next solve now re-reads the groups, and collect names the missing
    one."""
    vgs = obj.vertex_groups
    return all(vgs.get(n) is not None for n in group_names(obj, d))


def collect(obj, d):
    """Validated constraint arrays from the deformer's vertex groups (raises DeformKitError)."""
    check_object(obj, d)
    m = methods.get(d.method)
    if len(d.handles) == 0:
        raise DeformKitError("no handles: add one (Add Handle from Selection in Edit Mode)")
    names = set()
    for h in d.handles:
        if not h.vertex_group:
            raise DeformKitError("handle '%s' has no vertex group" % h.name)
        if obj.vertex_groups.get(h.vertex_group) is None:
            raise DeformKitError("handle '%s': vertex group '%s' does not exist"
                                 % (h.name, h.vertex_group))
        names.add(h.vertex_group)
        target_world(h)  # raises for a missing/deleted target or bone
    for label, g in (("region", d.roi_group), ("fixed", d.fixed_group),
                     (m.material_label.lower(), d.material_group)):
        if g:
            if obj.vertex_groups.get(g) is None:
                raise DeformKitError("%s vertex group '%s' does not exist" % (label, g))
            names.add(g)
    cut = [getattr(d.options, o) for o in m.cut_options] if "cut" in m.maps else []
    if any(cut):
        labels = [next(o.label for o in m.options if o.name == n) for n in m.cut_options]
        for label, g in zip(labels, cut):
            if not g:
                raise DeformKitError("%s is set but %s is not: a cut needs both vertex groups"
                                     % (labels[1 - labels.index(label)], label))
            if obj.vertex_groups.get(g) is None:
                raise DeformKitError("%s: vertex group '%s' does not exist" % (label, g))
        if cut[0] == cut[1]:
            raise DeformKitError("%s and %s are the same vertex group '%s'"
                                 % (labels[0], labels[1], cut[0]))
        names.update(cut)
    groups = read_groups(obj, names)
    handles, weights = [], []
    seen = {}
    for h in d.handles:
        idx, w = groups[h.vertex_group]
        if len(idx) == 0:
            raise DeformKitError("handle '%s': vertex group '%s' is empty"
                                 % (h.name, h.vertex_group))
        if h.vertex_group in seen:
            raise DeformKitError("handles '%s' and '%s' use the same vertex group '%s'"
                                 % (seen[h.vertex_group], h.name, h.vertex_group))
        seen[h.vertex_group] = h.name
        handles.append(idx)
        weights.append(w if h.use_weights else np.ones(len(idx)))
    if len(handles) > 1:
        allh = np.concatenate(handles)
        u, c = np.unique(allh, return_counts=True)
        if (c > 1).any():
            v = int(u[c > 1][0])
            owners = [h for h, idx in zip(d.handles, handles) if v in idx]
            raise OverlapError("handles '%s' and '%s' share %s: a vertex can follow one "
                               "handle only" % (owners[0].name, owners[1].name,
                                                plural(int((c > 1).sum()), "vertex")),
                               owners[0].vertex_group, owners[1].vertex_group)
    fixed = roi = None
    if d.fixed_group:
        fixed = groups[d.fixed_group][0]
        if len(fixed) == 0:
            raise DeformKitError("fixed vertex group '%s' is empty" % d.fixed_group)
        for h, idx in zip(d.handles, handles):
            both = np.intersect1d(idx, fixed)
            if len(both):
                raise OverlapError("handle '%s' overlaps the fixed group '%s' in %s: remove "
                                   "them from one group"
                                   % (h.name, d.fixed_group, plural(len(both), "vertex")),
                                   h.vertex_group, d.fixed_group)
    if d.roi_group:
        roi = groups[d.roi_group][0]
        if len(roi) == 0:
            raise DeformKitError("region vertex group '%s' is empty" % d.roi_group)
    if m.region_is_handle and roi is not None:
        # the Region group is the region that moves (eigen deformation's R), with the
        # first handle's motion
        if len(d.handles) > 1:
            raise DeformKitError("%s moves the Region group with one handle: remove the "
                                 "other handles or clear the Region group" % m.label)
        both = np.intersect1d(roi, fixed) if fixed is not None else ()
        if len(both):
            raise OverlapError("the Region group '%s' overlaps the fixed group '%s' in %d "
                               "vertices: remove them from one group"
                               % (d.roi_group, d.fixed_group, len(both)),
                               d.roi_group, d.fixed_group)
        handles, roi = [roi], None
        kw = dict(m.region_kw)
    else:
        kw = {}
    kw.update(handles=handles, fixed=fixed, roi=roi)
    if "stiffness" in m.maps and d.material_group:
        idx, w = groups[d.material_group]
        s = np.ones(len(obj.data.vertices))
        s[idx] = 1.0 + (getattr(d.options, m.stiffness_option) - 1.0) * w
        kw["stiffness"] = s
    if "material" in m.maps and d.material_group:
        idx, w = groups[d.material_group]
        kw["material_paint"] = (idx, w)
    if "handle_weights" in m.maps and any(h.use_weights for h in d.handles):
        kw["handle_weights"] = weights
    if any(cut):
        kw["cut"] = tuple(groups[g][0] for g in cut)
        for label, g, idx in zip(labels, cut, kw["cut"]):
            if len(idx) == 0:
                raise DeformKitError("%s: vertex group '%s' is empty" % (label, g))
    key = b"".join(np.ascontiguousarray(a).tobytes() for a in handles) + b"|" + b"|".join(
        b"" if x is None else np.ascontiguousarray(x).tobytes()
        for x in (fixed, roi, kw.get("stiffness")) + kw.get("cut", ())
        + kw.get("material_paint", ()))
    key += b"|" + b"".join(w.tobytes() for w in kw.get("handle_weights", []))
    key += b"|" + repr(sorted((k, x) for k, x in kw.items() if isinstance(x, str))).encode()
    return kw, key


# ------------------------------------------------------- topology and deformer identity ----

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
    drop(obj.name, old_uid)
    d.uid = _fresh_uid()
    d.owner = obj.name
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


def _fresh_uid():
    from . import properties
    return properties._new_uid()


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


# ------------------------------------------------------------------ binding and solving ----

def _native_call(what, fn, *a, **kw):
    try:
        return fn(*a, **kw)
    except DeformKitError:
        raise
    except NATIVE_ERRORS as e:
        raise DeformKitError("%s: %s" % (what, e)) from e


def _native_class(m):
    dk = native.load()
    if dk is None:
        raise DeformKitError(native.error)
    cls = getattr(dk, m.native_class, None)
    if cls is None:
        raise DeformKitError("this build of the native module has no deformkit.%s (%s)"
                             % (m.native_class, m.label))
    return dk, cls


# Softness 1 multiplies the painted edges' weights by this (the material map of
# docs/methods/fundamental.md): E_x's by MATERIAL_SOFTEST, E_f's by its inverse.
MATERIAL_SOFTEST = 20.0


def material_map(dk, dkmesh, paint, kw, opts):
    """The per-edge material of linear reconstruction from the Material group's paint
    (vertex indices, weights in (0, 1]): each painted vertex's value is
    MATERIAL_SOFTEST ** (softness * weight). Interpolate: a harmonic map through the painted
    vertices, the handles and fixed vertices held at 1 (as built); Smooth: the raw values
    (1 where unpainted) averaged `smooth_iterations` times over the edges. The direction
    (soft = a higher stretching and a lower bending weight) is the one measured to
    concentrate a fold at the paint (docs/methods/fundamental.md, "Measured")."""
    idx, w = paint
    n = dkmesh.n_vertices
    val = MATERIAL_SOFTEST ** (float(opts.softness) * np.asarray(w, dtype=np.float64))
    edges = np.asarray(dkmesh.edges)
    if opts.material_mode == "interpolate":
        held = [np.asarray(h) for h in kw["handles"]]
        if kw.get("fixed") is not None:
            held.append(np.asarray(kw["fixed"]))
        held = np.setdiff1d(np.concatenate(held) if held else np.zeros(0, np.int64), idx)
        painted = np.concatenate([np.asarray(idx, dtype=np.int64), held.astype(np.int64)])
        values = np.concatenate([val, np.ones(len(held))])
        return np.asarray(_native_call("material", dk.harmonic_material, dkmesh, painted, values))
    u = np.ones(n)
    u[idx] = val
    for _ in range(int(opts.smooth_iterations)):  # Jacobi averaging over the neighbours
        acc = np.zeros(n)
        deg = np.zeros(n)
        np.add.at(acc, edges[:, 0], u[edges[:, 1]])
        np.add.at(acc, edges[:, 1], u[edges[:, 0]])
        np.add.at(deg, edges[:, 0], 1.0)
        np.add.at(deg, edges[:, 1], 1.0)
        u = np.where(deg > 0, 0.5 * u + 0.5 * acc / np.maximum(deg, 1.0), u)
    return 0.5 * (u[edges[:, 0]] + u[edges[:, 1]])


# What the status bar calls the native binds' phases (deformkit.BindProgress.phase).
BIND_PHASES = {
    "renumber": "renumbering", "cells": "building cells", "operator": "building the operator",
    "constraints": "reading constraints", "system": "building the system",
    "assemble": "assembling", "analyze": "analysing", "factorize": "factorizing",
    "basis": "handle basis", "heat": "heat method", "distances": "distances",
    "nodes": "placing nodes", "weights": "node weights", "edges": "graph edges",
    "eigenvectors": "eigenvectors", "forms": "fundamental forms", "regions": "regions",
    "skeletons": "skeletons", "done": "finishing",
}


class BindJob:
    """One full bind, split so that the native precomputation (factorizations: seconds on big
    meshes) can run off the main thread while the UI stays live:
      job = BindJob(obj, d, kw, key)   main thread: reads Blender data, builds the Mesh
      job.run()                        any thread: native work only, no bpy access
      job.entry(obj, d)                main thread: caches the result (raises its error)
    """

    def __init__(self, obj, d, kw, groups_key):
        m = methods.get(d.method)
        dk, self._cls = _native_class(m)
        me = obj.data
        self.label = m.label
        self.method_id, self.settings, self.groups = d.method, _settings_key(d), groups_key
        self.rest = rest_positions(me)
        self.n_vertices, self.n_faces = len(me.vertices), len(me.polygons)
        self.topology = topology_fingerprint(me)
        self.dkmesh = _native_call("mesh", dk.Mesh, self.rest, triangles(me))
        args = dict(kw)
        paint = args.pop("material_paint", None)
        self.material = None
        if paint is not None:
            args["material"] = self.material = material_map(dk, self.dkmesh, paint, kw,
                                                            d.options)
        args.update(methods.bind_kwargs(m, d.options, self.rest, kw, self.dkmesh))
        self.fraction, self.phase, self.cancelled = None, None, False
        if m.bind_progress:  # called from the worker thread: plain attribute writes only
            args["progress"] = self._progress
        for k in ("fixed", "roi"):
            if args.get(k) is None:
                args.pop(k, None)
        self._args = args
        self.handles = list(kw["handles"])
        self.native, self.error, self.seconds = None, None, 0.0

    def _progress(self, fraction):
        # the phase first: the main thread reads fraction, then phase (progress_text)
        self.phase = getattr(fraction, "phase", None)
        self.fraction = float(fraction)
        return self.cancelled

    def progress_text(self):
        """The bind's phase and fraction for the status bar ("factorizing 62%"), "" before
        the first report or for a method without bind progress."""
        frac = self.fraction
        if frac is None:
            return ""
        phase = self.phase
        return "%s %.0f%%" % (BIND_PHASES.get(phase, phase or "bind"), 100 * frac)

    def run(self):
        t0 = time.perf_counter()
        try:
            self.native = _native_call(self.label + " bind", self._cls, self.dkmesh,
                                       **self._args)
        except DeformKitError as ex:
            self.error = ex
        except Exception as ex:  # e.g. a KeyboardInterrupt-free failure in a thread
            self.error = DeformKitError("%s bind: %s: %s" % (self.label, type(ex).__name__, ex))
        self.seconds = time.perf_counter() - t0

    def entry(self, obj, d, explicit=False):
        """`explicit`: a Bind, whose mesh becomes the bound one; otherwise a re-build of
        the binding, refused when the mesh is not the one bound (d.bind_topology)."""
        if self.error is not None:
            raise self.error
        me = obj.data
        if (len(me.vertices), len(me.polygons)) != (self.n_vertices, self.n_faces):
            raise DeformKitError("mesh changed from %d to %s during the bind: bind "
                                 "again" % (self.n_vertices, plural(len(me.vertices), "vertex")))
        if topology_fingerprint(me) != self.topology or not np.array_equal(
                rest_positions(me), self.rest):
            raise DeformKitError("mesh was edited during the bind: bind again")
        if not explicit:
            if not d.bind_topology:
                d.bind_topology = self.topology
            elif d.bind_topology != self.topology:
                raise DeformKitError(TOPOLOGY_CHANGED)
        e = _Entry()
        e.native, e.dkmesh, e.rest = self.native, self.dkmesh, self.rest
        e.extent = float(np.linalg.norm(self.rest.max(axis=0) - self.rest.min(axis=0)))
        e.n_vertices, e.n_faces = self.n_vertices, self.n_faces
        e.settings, e.groups, e.method_id = self.settings, self.groups, self.method_id
        e.last_inputs, e.verified, e.pending, e.pending_its = None, True, False, 0
        e.handles, e.source, e.preview_at = self.handles, self.rest, 0.0
        e.native_source = self.rest   # what a follower's native object solves from
        e.material, e.material_shown = self.material, None
        e.slice_cost, e.moved_at = {}, 0.0
        e.quick = quick_topology(me)
        e.worker, e.slice_ms, e.graph_shown = None, None, None
        e.basis, e.result_pos, e.result_T, e.preview_inputs = None, None, None, None
        e.warned = None  # bind_warnings
        e.last_cold = False  # whether the shown result is a cold solve's (solve())
        e.last_T = None      # the handle transforms of the last written solve
        e.fit_for, e.fit_text = None, None   # fit_warning's cache
        _cache[(obj.name, d.uid)] = e
        return e


def _install_groups(entry, d, kw, groups_key):
    """The entry after its native object was re-bound for new constraint groups."""
    entry.groups = groups_key
    entry.handles = list(kw["handles"])
    # a follower's native source after a rebind: pushed again by the next solve
    entry.source = None if depends_on_input(methods.get(d.method), d) else entry.rest
    entry.native_source = None
    entry.verified = True
    entry.last_inputs = None
    # other handles: another basis, and no result to move by it
    entry.basis, entry.result_pos, entry.result_T = None, None, None
    entry.preview_inputs = None
    entry.warned = None  # new constraints: other loose parts
    return entry


def _build(obj, d, kw, groups_key, entry=None, threaded=False, groups_threaded=False):
    # Only the constraint groups changed: the native rebind is the fast path (in a worker
    # thread for big meshes in the UI: GroupsRebindJob).
    if (entry is not None and entry.method_id == d.method and entry.settings == _settings_key(d)
            and hasattr(entry.native, "rebind") and set(kw) <= {"handles", "fixed", "roi"}):
        if groups_threaded and entry.n_vertices >= REBIND_ASYNC_MIN_VERTICES[0]:
            _groups_rebind_in_thread(obj, d, entry, kw, groups_key)  # raises RebindPending
        try:
            entry.native.rebind(handles=kw["handles"], fixed=kw["fixed"], roi=kw["roi"])
            return _install_groups(entry, d, kw, groups_key)
        except NATIVE_ERRORS:
            pass  # fall back to a full bind, which reports the error properly
    if threaded:
        _rebind_in_thread(obj, d, kw, groups_key)  # raises RebindPending
    job = BindJob(obj, d, kw, groups_key)
    job.run()
    return job.entry(obj, d)


# ---- re-binds after an option or method change, off the main thread in the UI ----------

# (object name, deformer uid) -> dict(job, thread, t0, sig) of a re-bind running in a worker
# thread. An option or method change in the UI re-binds this way (0.4-0.75 s at 43k
# vertices, seconds on big meshes, used to freeze the handler); the last result stays shown
# meanwhile and the panel says "re-binding". Frames, bakes, scripts and blender -b bind
# synchronously: their result must be this frame's.
_rebinds = {}
threaded_rebinds = [None]  # None: in the UI only; True / False force it (tests)


class RebindPending(Exception):
    """The deformer's re-bind runs in a worker thread: nothing to solve yet."""


def _use_threads(interactive):
    force = threaded_rebinds[0]
    return force if force is not None else (interactive and not bpy.app.background)


def _rebind_in_thread(obj, d, kw, groups_key):
    import threading
    key = (obj.name, d.uid)
    sig = (d.method, _settings_key(d), groups_key)
    r = _rebinds.get(key)
    if r is not None and r["sig"] == sig:
        raise RebindPending()
    if r is not None:
        r["job"].cancelled = True  # settings changed again: its result will be dropped
    job = BindJob(obj, d, kw, groups_key)  # main thread: reads Blender data
    th = threading.Thread(target=job.run, name="DeformKit re-bind", daemon=True)
    th.start()
    _rebinds[key] = dict(job=job, thread=th, t0=time.perf_counter(), sig=sig)
    raise RebindPending()


# A groups-only re-bind (a vertex group's membership or name changed) re-binds the bound
# native object in place (its rebind keeps what does not depend on the groups). On a mesh
# this big it runs in a worker thread in the UI, with the native progress: at 692k vertices
# Laplacian editing's rebind re-factors for ~14 s and ARAP's for ~5 s when the unknowns change,
# which froze the handler that long. Meanwhile the object is the worker's alone: the
# deformer's interactive solves raise RebindPending (the last result stays shown) and the
# others (frames, bakes, Apply) wait for it. Below, the rebind takes milliseconds to a
# second and stays synchronous, so that the next update already shows the new groups.
REBIND_ASYNC_MIN_VERTICES = [200_000]  # a list: tests lower it


class GroupsRebindJob:
    """The native rebind of a bound entry for new constraint groups (same interface as
    BindJob: run() in any thread, entry(obj, d) on the main thread, progress_text())."""
    inplace = True

    def __init__(self, entry, m, kw, groups_key):
        self._entry, self.kw, self.groups = entry, kw, groups_key
        self.label = m.label
        self._with_progress = m.rebind_progress
        self.fraction, self.phase, self.cancelled = None, None, False
        self.error, self.seconds = None, 0.0

    _progress = BindJob._progress
    progress_text = BindJob.progress_text

    def run(self):
        t0 = time.perf_counter()
        args = dict(handles=self.kw["handles"], fixed=self.kw["fixed"], roi=self.kw["roi"])
        if self._with_progress:
            args["progress"] = self._progress
        try:
            _native_call(self.label + " rebind", self._entry.native.rebind, **args)
        except DeformKitError as ex:
            self.error = ex
        except Exception as ex:  # a worker must not die silently
            self.error = DeformKitError("%s rebind: %s: %s" % (self.label, type(ex).__name__,
                                                                ex))
        self.seconds = time.perf_counter() - t0

    def entry(self, obj, d):
        if self.error is not None:
            raise self.error
        return _install_groups(self._entry, d, self.kw, self.groups)


def _groups_rebind_in_thread(obj, d, entry, kw, groups_key):
    import threading
    key = (obj.name, d.uid)
    sig = (d.method, _settings_key(d), groups_key)
    r = _rebinds.get(key)
    if r is not None:
        if r["sig"] != sig:
            # the groups changed again: this one's result is dropped, and the update after it
            # ends (finish_rebinds) starts the re-bind for the groups as they are then (the
            # object cannot take two rebinds at once)
            r["job"].cancelled = True
        raise RebindPending()
    job = GroupsRebindJob(entry, methods.get(d.method), kw, groups_key)
    th = threading.Thread(target=job.run, name="DeformKit groups re-bind", daemon=True)
    th.start()
    _rebinds[key] = dict(job=job, thread=th, t0=time.perf_counter(), sig=sig)
    raise RebindPending()


def _in_place_rebind(key):
    r = _rebinds.get(key)
    return r if r is not None and getattr(r["job"], "inplace", False) else None


def _cancel_rebinds(key=None):
    """Forgets the running re-binds (of `key`, or all): their results are dropped."""
    for k in [key] if key is not None else list(_rebinds):
        r = _rebinds.pop(k, None)
        if r is not None:
            r["job"].cancelled = True


def rebinding(obj=None, d=None):
    """Seconds since the running re-bind of (obj, d) started, or None; without arguments,
    whether any re-bind runs."""
    if obj is None:
        return bool(_rebinds)
    r = _rebinds.get((obj.name, d.uid))
    return None if r is None else time.perf_counter() - r["t0"]


def rebind_text(obj, d):
    """What the panel says about the running re-bind of (obj, d), or None."""
    r = _rebinds.get((obj.name, d.uid))
    if r is None:
        return None
    what = "the new groups" if getattr(r["job"], "inplace", False) else "the new settings"
    phase = r["job"].progress_text()
    return "re-binding for %s: %.1f s%s (the last result shows)" % (
        what, time.perf_counter() - r["t0"], ", " + phase if phase else "")


def finish_rebinds():
    """Installs the re-binds whose worker finished (main thread; handlers.poll_rebinds calls
    it from a timer): the result becomes the deformer's binding and its object is tagged so
    that the next update solves with it; a failure becomes the deformer's status. Returns
    the keys finished."""
    done = []
    for key, r in list(_rebinds.items()):
        if r["thread"].is_alive():
            continue
        del _rebinds[key]
        done.append(key)
        obj = bpy.data.objects.get(key[0])
        d = None if obj is None else next(
            (x for x in obj.deformkit.deformers if x.uid == key[1]), None)
        job = r["job"]
        if d is None:
            continue
        if job.cancelled:
            if getattr(job, "inplace", False) and obj is not None:
                # superseded by a later groups change: re-read the groups on the next update
                e = _cache.get(key)
                if e is not None:
                    e.verified, e.last_inputs = False, None
                obj.update_tag()
            continue
        if getattr(job, "inplace", False) and job.error is not None:
            # the native rebind refused (its previous binding stays): a full re-bind reports
            # the error as a bind would, or succeeds where the rebind's shortcut could not
            try:
                _rebind_in_thread(obj, d, job.kw, job.groups)
            except RebindPending:
                pass
            continue
        try:
            e = job.entry(obj, d)
        except DeformKitError as ex:
            zero_offset(obj, d)
            set_status(d, ex, True)
            continue
        e.last_inputs = None
        reset_status(d)
        obj.update_tag()
    return done


def bind_begin(obj, d, depsgraph=None):
    """Explicit bind, first half (main thread): validates the set-up and reads the groups and
    the targets' current placement (which becomes the handles' rest pose at bind_end).
    Returns (job, bind matrices); nothing is changed until bind_end."""
    check_object(obj, d)
    ensure_own_uid(obj, d)
    _cancel_rebinds((obj.name, d.uid))  # this bind replaces an automatic re-bind
    kw, key = collect(obj, d)
    poses = pose_bind(rest_positions(obj.data), kw["handles"],
                      _input_or_none(obj, d, depsgraph))
    mats = [(bind_matrix(obj, h, depsgraph), rig_bind(obj, d, h, depsgraph), pose)
            for h, pose in zip(d.handles, poses + [None] * (len(d.handles) - len(poses)))]
    return BindJob(obj, d, kw, key), mats


def rest_frame(scene, d):
    """The frame Bind takes the handles' placement and the pose from (d.rest_frame_from)."""
    if d.rest_frame_from == "START":
        return scene.frame_start
    if d.rest_frame_from == "FRAME":
        return d.rest_frame
    return scene.frame_current


def bind_end(obj, d, job, mats, depsgraph=None):
    """Explicit bind, second half (main thread, after job.run()): installs the result. On the
    native bind's error, or a mesh or handle list changed meanwhile, it raises before touching
    anything, so the previous binding stays."""
    if len(d.handles) != len(mats):
        raise DeformKitError("handles were added or removed during the bind: bind again")
    e = job.entry(obj, d, explicit=True)
    d.bind_topology = job.topology
    for h, (mat, rig, pose) in zip(d.handles, mats):
        h.bind_matrix = mat
        h.rig_matrix = rig
        h.pose_matrix = pose if pose is not None else (0.0,) * 16
        h.is_bound = True
    d.bind_n_vertices = e.n_vertices
    d.bind_n_faces = e.n_faces
    d.bound = True
    runtime.pop((obj.name, d.uid), None)
    geonodes.ensure_modifier(obj, d)
    geonodes.ensure_attribute(obj.data, d.attribute_name)
    solve(obj, d, depsgraph, force=True)
    reset_status(d)
    return e


def bind(obj, d, depsgraph=None):
    """Explicit bind (synchronous): the targets' current placement becomes the rest pose of
    the handles."""
    job, mats = bind_begin(obj, d, depsgraph)
    job.run()
    return bind_end(obj, d, job, mats, depsgraph)


def bind_warnings(obj, d):
    """What the bound native object says the artist should know (loose geometry held at rest,
    a deformation graph denser than its mesh): a tuple of str, empty when unbound. Read once
    per native object (the panel asks on every redraw; a worker thread may be solving)."""
    e = _cache.get((obj.name, d.uid))
    if e is None or e.native is None:
        return ()
    if e.warned is None:
        try:
            e.warned = tuple(getattr(e.native, "warnings", ()))
        except RuntimeError:  # in use by a worker thread: ask again at the next redraw
            return ()
    return e.warned


def unbind(obj, d):
    drop(obj.name, d.uid)
    d.bound = False
    for h in d.handles:
        h.is_bound = False
    a = obj.data.attributes.get(d.attribute_name)
    if a is not None:
        a.data.foreach_set("vector", np.zeros(len(a.data) * 3, dtype=np.float32))
        obj.data.update_tag()
    reset_status(d)


def set_status(d, msg, is_error):
    """The deformer's status line; an OverlapError also records its two groups (the panel
    offers to select or remove the shared vertices), any other status clears them."""
    text = str(msg)
    if d.status != text:
        d.status = text
    if d.status_is_error != is_error:
        d.status_is_error = is_error
    groups = "\t".join(msg.groups) if isinstance(msg, OverlapError) else ""
    if d.status_overlap != groups:
        d.status_overlap = groups


def idle_status(d):
    """A deformer's status when nothing is wrong, composed from its state now (bound or not,
    its handles): the one place that words it. The panel draws it at draw time, so it follows
    handles added or removed since it was stored."""
    if d.bound:
        return "bound: %s, %s" % (plural(d.bind_n_vertices, "vertex"),
                                  plural(len(d.handles), "handle"))
    if len(d.handles) == 0:
        return "not bound: add a handle, then Bind"
    return "not bound: press Bind"


def reset_status(d):
    """Stores the idle status, clearing an error."""
    set_status(d, idle_status(d), False)


def status_text(d):
    """What the panel shows: the stored error, else the idle status of the state now."""
    return d.status if d.status_is_error else idle_status(d)


def _entry_for(obj, d, check_groups, threaded=False, full_check=True):
    """The binding to solve with, checked against the mesh first: counts, the topology
    (check_topology: in full when `full_check`, after an undo, a mode that edits meshes or
    a rest edit; else the quick check) and the rest positions (every call: an edited rest
    shape with the bound topology re-binds from it)."""
    me = obj.data
    n, f = len(me.vertices), len(me.polygons)
    if n != d.bind_n_vertices:
        raise DeformKitError("mesh changed from %d to %s: bind again"
                             % (d.bind_n_vertices, plural(n, "vertex")))
    if f != d.bind_n_faces:
        raise DeformKitError("mesh changed from %d to %s: bind again"
                             % (d.bind_n_faces, plural(f, "face")))
    e = _cache.get((obj.name, d.uid))
    rest_same = e is not None and np.array_equal(rest_positions(me), e.rest)
    check_topology(obj, d, e, full=full_check or e is None or not e.verified or not rest_same)
    settings = _settings_key(d)
    same = e is not None and e.method_id == d.method and e.settings == settings
    if same and e.verified and rest_same and not check_groups and groups_exist(obj, d):
        return e
    kw, key = collect(obj, d)
    if same and e.groups == key:
        if rest_same:
            e.verified = True
            return e
        e = None  # rest shape edited (same topology): full rebuild
    # in a worker thread: a re-bind for changed options or method (the last result then
    # stays shown); a binding the cache lacks (after a file load, an undone Apply) is built
    # here, so that the first update after it shows the deformer's result
    return _build(obj, d, kw, key, e, threaded and e is not None and not same,
                  groups_threaded=threaded and e is not None)


# A handle transform this close to the identity is the identity seen through Blender's float32
# matrix products (the bind pose re-computed, a target keyed back to where it was bound).
_SNAP_LINEAR = 1e-6   # on the 3x3 part
_SNAP_SHIFT = 1e-6    # on the translation, times the mesh's bounding-box diagonal


def _within_rounding(T, U, extent):
    """Whether handle transforms T and U differ by no more than float32 rounding: 1e-6 on the
    3x3 parts, 1e-6 of the mesh's bounding-box diagonal on the translations (as
    snap_identity)."""
    dlt = np.abs(T - U)
    return (dlt[:, :3, :3].max(initial=0.0) <= _SNAP_LINEAR
            and dlt[:, :3, 3].max(initial=0.0) <= _SNAP_SHIFT * max(extent, 1e-30)
            and not dlt[:, 3].any())


def snap_identity(T, extent):
    """Replaces transforms within float32 rounding of the identity by the exact identity.
    The solvers then return the rest shape at once; fed the rounding, an iterative method
    would chase an energy that is itself ~0 (ARAP ran to its iteration cap at the bind pose of
    a rotated object). A real move or rotation is thousands of times larger."""
    eye = np.eye(4)
    for i in range(len(T)):
        dlt = T[i] - eye
        if (np.abs(dlt[:3, :3]).max() <= _SNAP_LINEAR
                and np.abs(dlt[:3, 3]).max() <= _SNAP_SHIFT * max(extent, 1e-30)
                and not dlt[3].any()):
            T[i] = eye
    return T


# Interactive updates of iterative methods (ARAP) get this much solve time; the rest of the
# solve runs from a timer once the handles stop moving (handlers.refine).
INTERACTIVE_BUDGET_MS = 30.0


def inner_cap(m, opts):
    """The bound inner count of m's iterations (ARAP Newton steps: CG iterations), or 0 when
    its iterations have none (for ARAP: another solver)."""
    if m.inner_iterations is None:
        return 0
    if m.inner_when is not None and getattr(opts, m.inner_when[0]) != m.inner_when[1]:
        return 0
    return int(getattr(opts, m.inner_iterations))


def _budget(key, cap, inner=0, resume=False, cut=True):
    """(iterations, inner count or None for the bound one) of a slice that fits
    INTERACTIVE_BUDGET_MS: at most `cap` iterations, and for methods whose iterations have an
    inner count (`inner`, ARAP Newton: 12 CG iterations a step) one iteration with fewer when
    a full one does not fit (a Newton step is ~50 ms on the armadillo, 100-250 ms on a loaded
    machine; a CG iteration ~4 / ~8 ms). The cost of a unit (an iteration, or an inner
    iteration) comes from the last unconverged slice of the same kind (a drag update starts
    warm, a refine tick resumes: their fixed costs differ), else from the last solve (the
    bind's), else ~0.15 us per vertex (the armadillo's 6.5 ms at 43k). Dividing a slice's
    time, fixed cost included, by its units converges within a few slices to the count that
    fills the budget: (budget - fixed) / unit. `cut` False: whole iterations only (at least
    one), for the refine steps once the handles have settled: after cut Newton steps the
    solver's stopping test waits for a whole one (docs/methods/arap.md)."""
    e = _cache.get(key)
    last = None
    if e is not None:
        last = e.slice_cost.get(bool(resume)) or e.slice_cost.get(not resume)
    if last is None:
        rt = runtime.get(key)
        if rt and rt.get("iterations", 0) >= 1:
            last = (rt["ms"], rt["iterations"], inner or 1)
    if last is not None:
        ms, its, per_it = last
        per_unit = ms / max(its * per_it, 1)
    else:
        per_unit = 1.5e-4 * (e.n_vertices if e is not None else 1e5)
    units = int(INTERACTIVE_BUDGET_MS / max(per_unit, 1e-3))
    if inner and units < inner and cut:
        # one iteration cut short: the smallest unit is an inner iteration
        return 1, max(1, units)
    # at least one: an iteration can take most of the budget on its own
    return max(1, min(cap, units // max(inner, 1))), None


# A preview (methods.Method.preview) is replaced by the full result once the handles have
# not moved for this long; and the refine steps of a budgeted solve cut its iterations to
# the budget (ARAP: Newton steps of fewer CG iterations) until then, so that the ticks the
# timer gets between the updates of a drag stay within the budget too, and take whole
# iterations once the handles have stopped, which is how the solve converges.
PREVIEW_SETTLE_S = 0.15


def pending():
    """(object name, deformer uid) of the interactive solves left unconverged."""
    return [k for k, e in _cache.items() if e.pending]


def settling(key):
    """True while `key` shows a preview younger than PREVIEW_SETTLE_S (the handles may still
    be moving: its full result waits)."""
    e = _cache.get(key)
    return e is not None and e.preview_at > 0.0 and \
        time.monotonic() - e.preview_at < PREVIEW_SETTLE_S


def refining(obj, d):
    """True while d's shown result is still being refined: an interactive solve stopped at
    its time budget (or a preview shown) and the refine timer has not converged it yet."""
    e = _cache.get((obj.name, d.uid))
    return e is not None and e.pending and bool(d.bound)


def previewing(obj, d):
    """True while d shows a preview (Method.preview) that its full result will replace."""
    e = _cache.get((obj.name, d.uid))
    return e is not None and e.pending and e.preview_at > 0.0 and bool(d.bound)


def drop_pending(key):
    e = _cache.get(key)
    if e is not None:
        e.pending = False


# ASYNC_MIN_VERTICES before any) runs in a worker thread: the update returns at once, the
# shown result stays until the worker's is ready (the refine timer installs it), so that
# dragging a million-vertex mesh never freezes Blender (issue 19). The native solve releases
# the GIL; the object is used by the worker alone meanwhile.
ASYNC_MS = 50.0
ASYNC_MIN_VERTICES = 200_000
# None: in the UI only, above the thresholds; "auto": the thresholds also under blender -b
# (benchmarks); True / False force it (tests)
threaded_solves = [None]


def _start_thread(owner, name, what, work):
    """Runs work() in a daemon thread `owner.thread`: a failure becomes `owner.error` (a
    DeformKitError naming `what`; a worker must not die silently), its time `owner.ms`."""
    import threading

    def guarded():
        t0 = time.perf_counter()
        try:
            work()
        except DeformKitError as ex:
            owner.error = ex
        except Exception as ex:
            owner.error = DeformKitError("%s: %s: %s" % (what, type(ex).__name__, ex))
        owner.ms = (time.perf_counter() - t0) * 1000.0
    owner.thread = threading.Thread(target=guarded, name=name, daemon=True)
    owner.thread.start()


class _Worker:
    """One native solve off the main thread: its plan (what solve() prepared) and outcome."""
    __slots__ = ("plan", "thread", "result", "error", "ms")

    def __init__(self, e, plan):
        self.plan, self.result, self.error, self.ms = plan, None, None, 0.0
        native_solve, label, goal, kw = e.native.solve, plan["label"], plan["goal"], plan["kw"]

        def run():
            self.result = _native_call(label + " solve", native_solve, **goal, **kw)
        _start_thread(self, "DeformKit solve", label + " solve", run)


# A bake's frame solve in a worker thread (solve(defer=True)): iterative methods run in
# slices of about this long, resumed (a resumed slice continues exactly where the last one
# stopped: the same result as one solve), so that Esc stops a frame within about a slice
# (a Newton step of ARAP at 692k vertices is 1.5-3 s: one per slice there).
BAKE_SLICE_MS = 250.0


class _Sliced:
    """The native result of a sliced solve: the last slice's positions and convergence, the
    slices' iterations added up."""
    __slots__ = ("positions", "iterations", "converged", "energy")

    def __init__(self, res, iterations):
        self.positions, self.converged = res.positions, res.converged
        self.energy, self.iterations = res.energy, iterations


class FrameSolve:
    """A non-interactive solve (a bake's frame) running in a worker thread: done() polls it,
    result(obj, d) (main thread, once done) gives what deformed_positions gives, cancel()
    stops an iterative method's solve after its current slice (the object stays busy until
    then: other solves of it wait for or skip the worker as for an interactive one)."""

    def __init__(self, key, e, plan, iterative):
        self.key, self.e, self.plan, self.cancelled = key, e, plan, False
        self.result_, self.error, self.ms = None, None, 0.0
        native_solve, label = e.native.solve, plan["label"]
        goal, kw = plan["goal"], dict(plan["kw"])
        cap = int(kw.get("max_iterations") or 0)

        def run():
            if not iterative or cap <= 0:
                self.result_ = _native_call(label + " solve", native_solve, **goal, **kw)
            else:
                done, its, first = 0, 1, True
                while True:
                    k = max(1, min(its, cap - done))
                    t1 = time.perf_counter()
                    res = _native_call(label + " solve", native_solve, **goal,
                                       **dict(kw, max_iterations=k, resume=not first))
                    ms = (time.perf_counter() - t1) * 1000.0
                    first, done = False, done + int(res.iterations)
                    if res.converged or done >= cap or self.cancelled:
                        break
                    its = max(1, int(k * BAKE_SLICE_MS / max(ms, 1e-3)))
                self.result_ = _Sliced(res, done)
        _start_thread(self, "DeformKit frame solve", label + " solve", run)

    def done(self):
        return not self.thread.is_alive()

    def cancel(self):
        self.cancelled = True

    def result(self, obj, d):
        self.thread.join()
        e = self.e
        if e.worker is self:
            e.worker = None
        if self.error is not None:
            raise self.error
        if self.cancelled:
            raise DeformKitError("bake cancelled")
        if _cache.get(self.key) is not e:
            raise DeformKitError("'%s' was re-bound during the bake: bake again" % d.name)
        pos = _finish_solve(obj, d, e, self.key, self.plan, self.result_, self.ms)
        return as_shown(obj, d, e, pos)


def _async_wanted(e, interactive, cold, write):
    if not (interactive and write and not cold):
        return False
    force = threaded_solves[0]
    if force is True or force is False:
        return force
    if force is None and bpy.app.background:
        return False
    if e.slice_ms is not None:
        return e.slice_ms > ASYNC_MS
    return e.n_vertices >= ASYNC_MIN_VERTICES


def working():
    """The keys whose solve is running in a worker thread."""
    return [k for k, e in _cache.items() if e.worker is not None and e.worker.thread.is_alive()]


def _wait_for_worker(key):
    """Joins the key's worker (a frame, bake, Apply or re-check needs the native object):
    its result is installed by the solve that follows when still wanted."""
    e = _cache.get(key)
    if e is not None and e.worker is not None:
        e.worker.thread.join()


def solve(obj, d, depsgraph=None, cold=False, write=True, force=False, check_groups=False,
          interactive=False, resume=False, check_topology=None, defer=False):
    """Solves `d` for the targets' current placement. Returns the n x 3 positions, or None when
    nothing changed since the last solve (unless `force`). Raises DeformKitError.
    `interactive` (UI updates): an iterative method stops at the time budget and is marked
    pending; the timer in handlers.py continues it (`resume`: from where it stopped, as one
    long solve would) with further interactive solves. A slow interactive solve runs in a
    worker thread (_async_wanted): the call returns None at once, and a later call (the
    refine timer's) installs its result. `defer` (non-interactive solves: bakes): the native
    solve starts in a worker thread and a FrameSolve is returned instead of positions."""
    if not d.bound:
        raise DeformKitError("not bound: press Bind")
    check_object(obj, d)
    ensure_own_uid(obj, d)
    key = (obj.name, d.uid)
    r = _in_place_rebind(key)
    if r is not None:  # a groups re-bind has the native object (GroupsRebindJob)
        if interactive and not cold:
            raise RebindPending()
        r["thread"].join()  # a frame, bake or Apply: its result must be this frame's
        finish_rebinds()
    ce = _cache.get(key)
    if ce is not None and ce.worker is not None and ce.worker.thread.is_alive():
        if interactive and write and not cold and not check_groups:
            ce.pending = True  # the timer polls it
            T, _, inputs = _solve_inputs(obj, d, ce, depsgraph)
            return _basis_preview(obj, d, ce, T, inputs)
        _wait_for_worker(key)
    # the topology in full (check_topology) for Apply, bakes, scripts and blender -b (None:
    # all but interactive solves); the UI's handler asks for it after a geometry update the
    # add-on did not make, an Edit or Sculpt Mode session or an undo (handlers._run)
    full = (not interactive) if check_topology is None else check_topology
    e = _entry_for(obj, d, check_groups, threaded=not cold and _use_threads(interactive),
                   full_check=full)
    w, e.worker = e.worker, None
    if isinstance(w, FrameSolve):
        w = None  # a bake's frame (finished): its owner takes the result (FrameSolve.result)
    shown = None
    T, source, inputs = _solve_inputs(obj, d, e, depsgraph)
    if w is not None:  # a worker's solve ended: its result shows now (if still wanted)
        if w.error is not None:
            e.pending = False
            raise w.error
        if interactive and write and not cold:
            plan_w = w.plan
            if inputs != w.plan["inputs"] and _has_basis(e):
                # the handles moved on: the preview from this result is what shows (below)
                plan_w = dict(w.plan, write=False)
            shown = _finish_solve(obj, d, e, key, plan_w, w.result, w.ms)
    if shown is not None and inputs == w.plan["inputs"]:
        return shown  # the worker's result is for the targets as they are
    if write:
        # Show Material follows its checkbox at once, not at the next solve (it showed
        # nothing until the handle moved, and stayed after unticking: the second hostile
        # review); show_material writes only on a change
        show_material(obj, d, e)
    # unchanged inputs keep the shown result, except that a frame (cold) must show what a bake
    # of it writes: a cold solve's result, not a drag's warm, budgeted or preview one (the
    # second hostile review: ARAP 2.6e-5 of the diagonal off, EmbeddedDeformation 1e-3,
    # EigenDeformation its Steps 1-2 preview)
    if not force and e.last_inputs == inputs and (e.last_cold or not cold):
        return shown
    plan = _plan_solve(obj, d, e, key, T, source, inputs, cold, write, interactive,
                       resume and shown is None)
    if _async_wanted(e, interactive, cold, write):
        _fetch_basis(e, methods.get(d.method))  # the object is idle now
        e.worker = _Worker(e, plan)
        e.pending = True
        preview = _basis_preview(obj, d, e, T, inputs)
        return shown if preview is None else preview
    if defer:
        job = FrameSolve(key, e, plan, methods.get(d.method).iterative)
        e.worker = job
        return job
    t0 = time.perf_counter()
    res = _native_call(plan["label"] + " solve", e.native.solve, **plan["goal"], **plan["kw"])
    ms = (time.perf_counter() - t0) * 1000.0
    return _finish_solve(obj, d, e, key, plan, res, ms)


def _has_basis(e):
    return e.basis is not None and e.basis is not False


def _fetch_basis(e, m):
    """The native response basis (methods.Method.response_basis), fetched once per binding,
    while the object is idle (False: it has none)."""
    if m.response_basis and e.basis is None:
        b = _native_call(m.label + " response basis", e.native.response_basis)
        e.basis = False if b is None else b


def _basis_preview(obj, d, e, T, inputs):
    """While a worker thread solves (issue 19): the last finished result moved by the
    response basis to the handles' current transforms T -- the plain warm start's positions,
    x0 + B (T - T0), no solve: ~10 ms at 692k vertices -- written as the shown result, so
    that the mesh follows the handle between the worker's results. Returns the positions,
    or None (no basis, no result yet, or nothing moved since the last preview)."""
    if not _has_basis(e) or e.result_pos is None or inputs == e.preview_inputs:
        return None
    T0 = e.result_T
    if T0 is None or T0.shape != T.shape or e.basis.shape[1] != 4 * len(T):
        return None
    C = (T - T0)[:, :3, :].transpose(0, 2, 1).reshape(-1, 3)
    pos = e.result_pos + e.basis @ C
    off = np.empty(pos.shape, dtype=np.float32)
    np.subtract(pos, e.source, out=off, casting="unsafe")
    write_offset(obj, d, off, retime=False)
    e.preview_inputs = inputs
    # what shows is no solve's result now: any later solve, a frame's included, writes again
    e.last_inputs, e.last_cold = None, False
    return pos


def _input_or_none(obj, d, depsgraph):
    """The deformer's input for a method that solves from the rest (where its handles' edits
    turn with the pose), or None when it is the rest, or cannot be read (a modifier below
    changes the vertex count): the edits then keep their direction, as they did."""
    try:
        return moved_input(obj, d, depsgraph)
    except DeformKitError:
        return None


def _solve_inputs(obj, d, e, depsgraph):
    """The handle transforms, the animated input (methods that follow one, else None) and
    the bytes they make, which say whether anything changed since the last solve."""
    m = methods.get(d.method)
    source = moved_input(obj, d, depsgraph) if depends_on_input(m, d) else None
    inp = source if depends_on_input(m, d) else _input_or_none(obj, d, depsgraph)
    T = snap_identity(turn_with_the_pose(d, e.rest, e.handles, transforms(obj, d, depsgraph),
                                         inp), e.extent)
    last = e.last_T
    if last is not None and last.shape == T.shape and _within_rounding(T, last, e.extent):
        # the same placement seen through other float32 products (the object and its
        # child target moved together): the last solve's, so that nothing is solved again
        # (a warm iterative solve from its own result moves it by up to its tolerance)
        T = last
    if len(T) > len(e.handles):  # region_is_handle: the Region group moves with the first
        T = T[:len(e.handles)]
    return T, source, T.tobytes() + (b"" if source is None else source.tobytes())


def _plan_solve(obj, d, e, key, T, source, inputs, cold, write, interactive, resume):
    """What a solve of `d` asks the native object for now: the goal (targets), the solve
    keywords (the budget's slice when interactive) and the inputs they come from."""
    m = methods.get(d.method)
    goal = dict(transforms=T)
    kw = methods.solve_kwargs(m, d.options, cold)
    if depends_on_input(m, d):
        want = e.rest if source is None else source
        from_rest = d.solve_from == "REST"
        solve_on = e.rest if from_rest else want   # what the native object deforms
        ns = getattr(e, "native_source", None)
        if m.follows_input and (ns is None or not np.array_equal(ns, solve_on)):
            _native_call(m.label + " input", e.native.update_source, solve_on)
            e.native_source = solve_on
        e.source = want   # the offset written is the result less the input
        if source is not None and from_rest:
            # Solve From: Rest Shape: the handles where the input puts them (plus the
            # edit), the rest between them solved from the rest shape
            goal = dict(targets=edit_targets(e, T, source))
        elif source is not None:
            # the edit where the input puts the handle vertices: positions where they are
            # the transforms' equal, else transforms turned into the input
            positions = m.follows_input or native.method_info(m.native_class).get(
                "transforms_as_positions", False)
            goal = (dict(targets=edit_targets(e, T, source)) if positions
                    else dict(transforms=input_transforms(e, T, source)))
            if not m.follows_input:
                kw["input_positions"] = source
    else:
        e.source = e.rest   # solved on the rest, its offset lands on the input as it is
    # after an undo or redo: a full solve before showing (mark_all_dirty)
    full = write and converges_next(key)
    budgeted = interactive and m.iterative and not cold and not full
    previewing = interactive and bool(m.preview) and not cold and not resume and not full
    if previewing:
        kw.update(m.preview)
    cap = int(getattr(d.options, m.iteration_cap)) if m.iteration_cap else 0
    n_inner = inner_cap(m, d.options) if budgeted else 0
    inner = None
    if budgeted:
        # slices of one solve: together at most the method's Max Iterations (counted in full
        # iterations: a Newton step of 3 CG iterations out of 12 is a quarter). A slice of
        # whole iterations resumed by another of whole iterations is exactly what one
        # uninterrupted solve would give; slices cut to fewer inner iterations take another
        # path to a point the same stopping test accepts (docs/methods/arap.md)
        now = time.monotonic()
        if not resume:
            e.pending_its, e.moved_at = 0, now
        its, inner = _budget(key, cap or 100, n_inner, resume,
                             cut=not resume or now - e.moved_at < PREVIEW_SETTLE_S)
        left = cap - e.pending_its if cap else 1 << 30
        kw["max_iterations"] = max(1, min(its, int(math.ceil(left))))
        if inner is not None:
            kw[m.inner_iterations] = inner
        if resume:
            kw["resume"] = True
    return dict(label=m.label, goal=goal, kw=kw, inputs=inputs, T=T, budgeted=budgeted,
                previewing=previewing, resume=resume, cap=cap, n_inner=n_inner, inner=inner,
                write=write, cold=cold)


def _finish_solve(obj, d, e, key, plan, res, ms):
    """Records a native solve's figures and pending state, and writes its result (when the
    plan says so). Returns the n x 3 positions."""
    budgeted, resume, inner = plan["budgeted"], plan["resume"], plan["inner"]
    cap, n_inner = plan["cap"], plan["n_inner"]
    e.slice_ms = ms
    pos = np.asarray(res.positions, dtype=np.float64).reshape(-1, 3)
    # the base of the response-basis previews (_basis_preview): the object's own last result
    Tg = plan["goal"].get("transforms")
    e.result_pos = pos if Tg is not None else None
    e.result_T = None if Tg is None else np.asarray(Tg, dtype=np.float64)
    # inner: the inner count of a slice's iterations when cut below the bound one (ARAP: CG
    # iterations per Newton step), else None
    rt = dict(ms=ms, iterations=int(res.iterations), converged=bool(res.converged),
              energy=float(res.energy), slices=1, inner=inner, budgeted=budgeted)
    last = runtime.get(key)
    if budgeted and resume and e.pending and last is not None:
        # a further slice of the interactive solve left pending: the figures are the whole
        # solve's (its time and iterations so far), not this slice's
        rt["ms"] += last["ms"]
        rt["iterations"] += last["iterations"]
        rt["slices"] += last["slices"]
    runtime[key] = rt
    # unconverged only because of the budget: finish from the timer
    if budgeted:
        per_it = inner if inner is not None else (n_inner or 1)
        e.pending_its += int(res.iterations) * per_it / (n_inner or 1)
        if not (n_inner and res.converged):
            # (a converged Newton slice ended at its stopping test, one product into a step:
            # its time says nothing of a full unit's)
            e.slice_cost[bool(resume)] = (ms, max(int(res.iterations), 1), per_it)
    e.pending = bool(budgeted and not res.converged and (not cap or e.pending_its < cap))
    if plan["previewing"]:  # the full result follows from the timer once the handles stop
        e.pending, e.preview_at = True, time.monotonic()
    else:
        e.preview_at = 0.0
    if plan["write"]:
        show_material(obj, d, e)
        # the offset computed in float64 and rounded once, straight into float32 (one pass)
        off = np.empty(pos.shape, dtype=np.float32)
        np.subtract(pos, e.source, out=off, casting="unsafe")
        write_offset(obj, d, off, retime=plan["cold"])
        e.last_inputs = plan["inputs"]
        e.last_cold = plan["cold"]
        e.last_T = plan["T"]
        e.preview_inputs = None
        _written_at_undo[key] = _undo_serial[0]
    return pos


# fit_warning's thresholds: handles off by more than this part of their move, or more than
# this part of the edges stretched (or shrunk) by more than half
FIT_HANDLE_PART = 0.02
FIT_STRETCH_PART = 0.01


def fit_warning(obj, d):
    """What the panel says when the method cannot do this edit well, with the method that
    can (Method.fit_check, better_method), or None. Read from the last settled result (none
    while refining or previewing), computed once per result: "handles" how far the handle
    vertices are from their targets against the move, "stretch" how many edges changed
    length by more than half. The second hostile review: Eigen Deformation's spike, the
    linear methods' swelling, shown as if they were fine."""
    m = methods.get(d.method)
    e = _cache.get((obj.name, d.uid))
    if (not m.fit_check or e is None or e.result_pos is None or e.result_T is None
            or e.pending or not d.bound):
        return None
    if e.fit_for is e.result_pos:
        return e.fit_text
    pos, T, src = e.result_pos, e.result_T, e.rest
    text = None
    if m.fit_check == "handles":
        worst = move = 0.0
        for idx, Ti in zip(e.handles, T):
            want = src[idx] @ Ti[:3, :3].T + Ti[:3, 3]
            worst = max(worst, float(np.linalg.norm(pos[idx] - want, axis=1).max()))
            move = max(move, float(np.linalg.norm(want - src[idx], axis=1).max()))
        if move > 1e-3 * max(e.extent, 1e-30) and worst > FIT_HANDLE_PART * move:
            text = ("%s meets its handles approximately: here %.0f%% of the move off the "
                    "target. %s meets them exactly" % (m.label, 100.0 * worst / move,
                                                        m.better_method))
    else:
        ed = np.asarray(e.dkmesh.edges)
        a = np.linalg.norm(src[ed[:, 0]] - src[ed[:, 1]], axis=1)
        b = np.linalg.norm(pos[ed[:, 0]] - pos[ed[:, 1]], axis=1)
        ok = a > 0
        bad = int((np.abs(b[ok] / a[ok] - 1.0) > 0.5).sum())
        if bad > FIT_STRETCH_PART * max(int(ok.sum()), 1):
            text = ("%s changes %s by more than half for this move: it moves the surface "
                    "without turning it, and stretches what should turn. %s keeps the "
                    "shape" % (m.label, plural(bad, "edge length"), m.better_method))
    e.fit_for, e.fit_text = pos, text
    return text


def solve_summary(obj, d):
    """The panel's line about the last solve, or None before one (or while the status is an
    error). Iterative methods: the time and iterations of the whole solve, its interactive
    slices summed, and "(not converged)" when it stopped at Max Iterations short of its
    tolerance (not while the timer is still refining it). Direct methods: the time only;
    they never say "not converged" (Laplacian editing's local-frame passes are a fixed
    count, not an iteration to convergence)."""
    key = (obj.name, d.uid)
    rt = runtime.get(key)
    if not rt or not d.bound or d.status_is_error:
        return None
    m = methods.get(d.method)
    if not m.iterative:
        return "last solve %.1f ms" % rt["ms"]
    e = _cache.get(key)
    refining = e is not None and e.pending
    return "last solve %.1f ms, %s%s" % (
        rt["ms"], plural(rt["iterations"], "iteration"),
        "" if rt["converged"] or refining else " (not converged)")


def show_material(obj, d, e):
    """Show Material (methods with a 'material' map): the map as the colour attribute
    "dk_<uid>_material" (grey where as built, yellow where softest; the viewport shows it
    in Solid mode with Attribute colouring), made the active colour; removed when off or
    when nothing is painted. Writes only on a change."""
    m = methods.get(d.method)
    if "material" not in m.maps:
        return
    want = bool(getattr(d.options, "show_material", False)) and e.material is not None
    key = (want, id(e.material))
    if e.material_shown == key:
        return
    me = obj.data
    name = "dk_%s_material" % d.uid
    old = me.color_attributes.get(name) if hasattr(me, "color_attributes") else None
    if not want:
        if old is not None:
            me.color_attributes.remove(old)
        e.material_shown = key
        return
    edges = np.asarray(e.dkmesh.edges)
    acc = np.zeros(e.n_vertices)
    deg = np.zeros(e.n_vertices)
    np.add.at(acc, edges.ravel(), np.repeat(e.material, 2))
    np.add.at(deg, edges.ravel(), 1.0)
    u = np.where(deg > 0, acc / np.maximum(deg, 1.0), 1.0)
    t = np.clip(np.log(np.maximum(u, 1e-12)) / np.log(MATERIAL_SOFTEST), 0.0, 1.0)[:, None]
    rgba = (1.0 - t) * np.array([0.5, 0.5, 0.5, 1.0]) + t * np.array([1.0, 0.85, 0.1, 1.0])
    if old is None or old.domain != "POINT" or old.data_type != "FLOAT_COLOR":
        if old is not None:
            me.color_attributes.remove(old)
        old = me.color_attributes.new(name, "FLOAT_COLOR", "POINT")
    old.data.foreach_set("color", np.ascontiguousarray(rgba, dtype=np.float32).ravel())
    me.color_attributes.active_color = old
    e.material_shown = key


def write_offset(obj, d, offset, retime=False):
    me = obj.data
    a = geonodes.ensure_attribute(me, d.attribute_name)
    a.data.foreach_set("vector", np.ascontiguousarray(offset, dtype=np.float32).ravel())
    me.update_tag()
    if retime:
        # Frame change: a depsgraph re-evaluated after this tag (a render's, see handlers.py)
        # re-copies the object from the original, whose animated values (the modifier's
        # Factor) are not flushed there; re-run the object's animation with it.
        obj.update_tag(refresh={"TIME"})


def zero_offset(obj, d):
    me = obj.data
    a = me.attributes.get(d.attribute_name)
    if a is not None and len(a.data) == len(me.vertices):
        a.data.foreach_set("vector", np.zeros(len(me.vertices) * 3, dtype=np.float32))
        me.update_tag()


def finish(obj, d, depsgraph=None):
    """Brings the shown result up to date: solves when the inputs changed since the last
    solve, and completes an interactive solve left pending (as the timer would). The vertex
    groups are read again first: Apply must not write a result of groups a script has edited
    without an update that said so."""
    solve(obj, d, depsgraph, check_groups=True)
    key = (obj.name, d.uid)
    if key in _cache:
        _cache[key].moved_at = 0.0  # settled: whole iterations
    while key in _cache and _cache[key].pending:
        _wait_for_worker(key)  # a slice in a worker thread: its result installs next
        solve(obj, d, depsgraph, interactive=True, resume=True, force=True)


def shown_positions(obj, d):
    """rest + factor * the offset attribute: exactly what the modifier shows (for a method
    following an animated input: that input + factor * the offset)."""
    e = _cache.get((obj.name, d.uid))
    me = obj.data
    a = me.attributes.get(d.attribute_name)
    if e is None or a is None or len(a.data) != len(me.vertices):
        raise DeformKitError("%s has no result to apply: bind it first" % d.name)
    off = np.empty(len(me.vertices) * 3, dtype=np.float32)
    a.data.foreach_get("vector", off)
    src = e.rest if e.source is None else e.source
    return src + geonodes.factor(obj, d) * off.reshape(-1, 3).astype(np.float64)


def as_shown(obj, d, e, pos, depsgraph=None):
    """What the modifier shows for the solved positions `pos` of this frame: the input it
    gets + factor * (pos - the positions the method solved from). The input is what reaches
    the modifier (an Armature's pose, shape keys), not the rest: a method that does not
    follow its input solved from the rest, and its offset lands on the input as the
    modifier adds it. A bake writes this, so that its cache, played after the Armature in
    place of the modifier, shows what playback showed (issue 39: it held rest + offset, and
    the rig was thrown away)."""
    inp = moved_input(obj, d, depsgraph)
    base = e.source if inp is None else inp
    return base + geonodes.factor(obj, d) * (pos - e.source)


def deformed_positions(obj, d, depsgraph=None, cold=True, check_groups=False):
    """What the modifier shows on the current frame (as_shown), solved cold as a bake
    solves. `check_groups`: re-read the vertex groups first (a bake's first frame)."""
    pos = solve(obj, d, depsgraph, cold=cold, write=False, force=True,
                check_groups=check_groups)
    return as_shown(obj, d, _cache[(obj.name, d.uid)], pos, depsgraph)


def evaluate_object(obj, depsgraph=None, check_groups=False, cold=False, interactive=False,
                    refine=False, only=None, check_topology=None):
    """Handler entry: solves every bound deformer of `obj` whose inputs changed; errors go to
    the deformer's status (and its offset is zeroed), never raised. `refine`: only the
    deformers with a pending interactive solve, continued for another budget (or, for a
    preview, solved in full); `only`: a set of deformer uids to consider."""
    for d in obj.deformkit.deformers:
        if not d.bound or (only is not None and d.uid not in only):
            continue
        try:
            ensure_own_uid(obj, d)  # a duplicate's copy: its own uid before its modifier
        except Exception as ex:  # never let a handler raise
            set_status(d, "internal error: %s: %s" % (type(ex).__name__, ex), True)
            continue
        mod = geonodes.find_modifier(obj, d)
        if mod is None or not (mod.show_viewport or mod.show_render):
            continue  # nothing would show it (e.g. replaced by a baked cache)
        geonodes.repair(mod, d)  # an Attribute input edited in the modifier's panel
        key = (obj.name, d.uid)
        if refine and not (key in _cache and _cache[key].pending):
            continue
        try:
            if solve(obj, d, depsgraph, cold=cold, check_groups=check_groups,
                     interactive=interactive, force=refine, resume=refine,
                     check_topology=check_topology) is not None:
                reset_status(d)
        except RebindPending:
            pass  # the last result stays shown; finish_rebinds installs the new binding
        except DeformKitError as ex:
            if d.status != str(ex):
                zero_offset(obj, d)
                drop(obj.name, d.uid)
            set_status(d, ex, True)
        except Exception as ex:  # never let a handler raise
            set_status(d, "internal error: %s: %s" % (type(ex).__name__, ex), True)
