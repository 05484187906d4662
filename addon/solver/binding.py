"""Bind: the native precomputation (BindJob, off the main thread in the UI), installing its
result, and the binding a solve uses (checked against the mesh first)."""

import time

import numpy as np

from .. import geonodes, methods
from ..animated_input import depends_on_input
from ..errors import DeformKitError
from ..handles import bind_matrix, pose_bind, rig_bind
from ..text import plural
from . import (blender_data, cache, calls, controls, identity, material, progress, rebind, solving,
               status)


class BindJob(progress.Reporting):
    """One full bind, split so that the native precomputation (factorizations: seconds on big
    meshes) can run off the main thread while the UI stays live:
      job = BindJob(obj, d, kw, key)   main thread: reads Blender data, builds the Mesh
      job.run()                        any thread: native work only, no bpy access
      job.entry(obj, d)                main thread: caches the result (raises its error)
    """

    def __init__(self, obj, d, kw, groups_key):
        m = methods.get(d.method)
        dk, self._cls = calls._native_class(m)
        me = obj.data
        self.label = m.label
        self.method_id, self.groups = d.method, groups_key
        self.settings = controls.settings_key(d)
        self.rest = blender_data.rest_positions(me)
        self.n_vertices, self.n_faces = len(me.vertices), len(me.polygons)
        self.topology = identity.topology_fingerprint(me)
        self.dkmesh = calls._native_call("mesh", dk.Mesh, self.rest, blender_data.triangles(me))
        args = dict(kw)
        paint = args.pop("material_paint", None)
        self.material = None
        if paint is not None:
            args["material"] = self.material = material.material_map(
                dk, self.dkmesh, paint, kw, d.options)
        args.update(methods.bind_kwargs(m, d.options, self.rest, kw, self.dkmesh))
        # a blend of poses: the poses' displacements, kept for its solves (edit_input)
        self.pose_deltas = kw["poses"] - self.rest[None] if "poses" in kw else None
        self.fraction, self.phase, self.cancelled = None, None, False
        if m.bind_progress:  # called from the worker thread: plain attribute writes only
            args["progress"] = self._progress
        for k in ("fixed", "roi"):
            if args.get(k) is None:
                args.pop(k, None)
        self._args = args
        self.handles = list(kw.get("handles", ()))   # a control object's method: none
        self.captured = None   # what Bind keeps of a control object (bind_begin, bind_end)
        self.native, self.error, self.seconds = None, None, 0.0

    def run(self):
        t0 = time.perf_counter()
        try:
            self.native = calls._native_call(self.label + " bind", self._cls, self.dkmesh,
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
        if identity.topology_fingerprint(me) != self.topology or not np.array_equal(
                blender_data.rest_positions(me), self.rest):
            raise DeformKitError("mesh was edited during the bind: bind again")
        if not explicit:
            if not d.bind_topology:
                d.bind_topology = self.topology
            elif d.bind_topology != self.topology:
                raise DeformKitError(identity.TOPOLOGY_CHANGED)
        e = cache._Entry()
        e.native, e.dkmesh, e.rest = self.native, self.dkmesh, self.rest
        e.extent = float(np.linalg.norm(self.rest.max(axis=0) - self.rest.min(axis=0)))
        e.n_vertices, e.n_faces = self.n_vertices, self.n_faces
        e.settings, e.groups, e.method_id = self.settings, self.groups, self.method_id
        e.last_inputs, e.verified, e.pending, e.pending_its = None, True, False, 0
        e.handles, e.source, e.preview_at = self.handles, self.rest, 0.0
        e.native_source = self.rest   # what a follower's native object solves from
        e.material, e.material_shown = self.material, None
        e.slice_cost, e.moved_at = {}, 0.0
        e.quick = identity.quick_topology(me)
        e.worker, e.slice_ms, e.graph_shown = None, None, None
        e.basis, e.result_pos, e.result_T, e.preview_inputs = None, None, None, None
        e.warned = None  # bind_warnings
        e.last_cold = False  # whether the shown result is a cold solve's (solve())
        e.last_T = None      # the handle transforms of the last written solve
        e.fit_for, e.fit_text = None, None   # fit_warning's cache
        e.sim = None   # a simulation's kept frames (solver.simulation)
        e.pose_deltas = self.pose_deltas   # a blend of poses' displacements (BindJob)
        # what this native object made (every new one: a Bind, a re-build for other
        # settings or a reopened file), for the status line
        summary = methods.get(d.method).bind_summary
        text = summary(e.native) if summary else ""
        if d.bind_summary != text:
            d.bind_summary = text
        cache._cache[(obj.name, d.uid)] = e
        return e


def _install_groups(entry, d, kw, groups_key):
    """The entry after its native object was re-bound for new constraint groups."""
    entry.groups = groups_key
    entry.handles = list(kw.get("handles", ()))
    # a follower's native source after a rebind: pushed again by the next solve
    entry.source = None if depends_on_input(methods.get(d.method), d) else entry.rest
    entry.native_source = None
    entry.verified = True
    entry.last_inputs = None
    # other handles: another basis, and no result to move by it
    entry.basis, entry.result_pos, entry.result_T = None, None, None
    entry.preview_inputs = None
    entry.warned = None  # new constraints: other loose parts
    entry.sim = None     # the native rebind restarted a simulation: its frames are gone
    return entry


def _build(obj, d, kw, groups_key, entry=None, threaded=False, groups_threaded=False):
    # Only the constraint groups changed: the native rebind is the fast path (in a worker
    # thread for big meshes in the UI: GroupsRebindJob).
    if (entry is not None and entry.method_id == d.method
            and entry.settings == controls.settings_key(d)
            and hasattr(entry.native, "rebind") and set(kw) <= {"handles", "fixed", "roi"}):
        if groups_threaded and entry.n_vertices >= rebind.REBIND_ASYNC_MIN_VERTICES[0]:
            rebind._groups_rebind_in_thread(obj, d, entry, kw, groups_key)  # raises RebindPending
        try:
            entry.native.rebind(handles=kw["handles"], fixed=kw["fixed"], roi=kw["roi"])
            return _install_groups(entry, d, kw, groups_key)
        except calls.NATIVE_ERRORS:
            pass  # fall back to a full bind, which reports the error properly
    if threaded:
        rebind._rebind_in_thread(obj, d, kw, groups_key)  # raises RebindPending
    job = BindJob(obj, d, kw, groups_key)
    job.run()
    return job.entry(obj, d)


def bind_begin(obj, d, depsgraph=None):
    """Explicit bind, first half (main thread): validates the set-up and reads the groups and
    the targets' current placement (which becomes the handles' rest pose at bind_end).
    Returns (job, bind matrices); nothing is changed until bind_end."""
    blender_data.check_object(obj, d)
    identity.ensure_own_uid(obj, d)
    cache._cancel_rebinds((obj.name, d.uid))  # this bind replaces an automatic re-bind
    captured = controls.capture(obj, d, depsgraph)   # a control object's rest, taken now
    kw, key = controls.collect(obj, d, captured)
    mats = []
    if controls.uses_handles(d):
        poses = pose_bind(blender_data.rest_positions(obj.data), kw["handles"],
                          solving._input_or_none(obj, d, depsgraph))
        mats = [(bind_matrix(obj, h, depsgraph), rig_bind(obj, d, h, depsgraph), pose)
                for h, pose in zip(d.handles, poses + [None] * (len(d.handles) - len(poses)))]
    job = BindJob(obj, d, kw, key)
    job.captured = captured
    return job, mats


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
    handles = controls.uses_handles(d)
    if handles and len(d.handles) != len(mats):
        raise DeformKitError("handles were added or removed during the bind: bind again")
    e = job.entry(obj, d, explicit=True)
    d.bind_topology = job.topology
    if not handles:
        controls.store(d, job.captured)
        # the binding's settings include what was kept (settings_key): the entry is the
        # one for it
        e.settings = controls.settings_key(d)
    for h, (mat, rig, pose) in zip(d.handles if handles else (), mats):
        h.bind_matrix = mat
        h.rig_matrix = rig
        h.pose_matrix = pose if pose is not None else (0.0,) * 16
        h.is_bound = True
    d.bind_n_vertices = e.n_vertices
    d.bind_n_faces = e.n_faces
    d.bound = True
    d.sim_frame_key = ""   # the attribute holds no simulated frame of this binding yet
    cache.runtime.pop((obj.name, d.uid), None)
    geonodes.ensure_modifier(obj, d)
    geonodes.ensure_attribute(obj.data, d.attribute_name)
    solving.solve(obj, d, depsgraph, force=True)
    status.reset_status(d)
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
    e = cache._cache.get((obj.name, d.uid))
    if e is None or e.native is None:
        return ()
    if e.warned is None:
        try:
            e.warned = tuple(getattr(e.native, "warnings", ()))
        except RuntimeError:  # in use by a worker thread: ask again at the next redraw
            return ()
    return e.warned


def unbind(obj, d):
    cache.drop(obj.name, d.uid)
    d.bound = False
    d.sim_frame_key = ""
    for h in d.handles:
        h.is_bound = False
    a = obj.data.attributes.get(d.attribute_name)
    if a is not None:
        a.data.foreach_set("vector", np.zeros(len(a.data) * 3, dtype=np.float32))
        obj.data.update_tag()
    status.reset_status(d)


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
    e = cache._cache.get((obj.name, d.uid))
    rest_same = e is not None and np.array_equal(blender_data.rest_positions(me), e.rest)
    identity.check_topology(obj, d, e,
                            full=full_check or e is None or not e.verified or not rest_same)
    settings = controls.settings_key(d)
    same = e is not None and e.method_id == d.method and e.settings == settings
    if same and e.verified and rest_same and not check_groups and controls.exist(obj, d):
        return e
    kw, key = controls.collect(obj, d)
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
