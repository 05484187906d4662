"""Compute Weights: bounded biharmonic weights (deformkit.bounded_biharmonic_weights) of the
Skinning deformer's armature's deforming bones, written into vertex groups named after the
bones, as Blender's own "With Automatic Weights" writes them: an artist paints them further,
and Blender's Armature modifier reads them as well as the Skinning deformer does.

Each bone is held along its rest segment (head to tail) where the armature stands, in the
mesh's space; the weights live in the solid the mesh encloses (or on its surface when it
encloses none). Per vertex the `influences` largest weights are kept and renormalised, and
weights below 1/1000 dropped, as skinning wants few influences a vertex. The groups of the
bones are replaced whole; other groups are left alone. In the UI the computation runs in a
worker thread with its progress in the status bar, and Esc cancels it, changing nothing."""

import threading
import time

import bmesh
import bpy
import numpy as np
from bpy.props import EnumProperty, IntProperty

from . import native, solver
from .solver import control_objects
from .operators import _Base, _get_deformer, _get_object
from .text import plural

# weights below this are not written (a group entry an artist would see as noise)
SMALLEST = 1e-3


def bone_segments(obj, arm, depsgraph=None):
    """The deforming bones' names and rest segments (b x 2 x 3: head, tail) in obj's space."""
    names = [b.name for b in arm.data.bones if b.use_deform]
    if not names:
        raise solver.DeformKitError("armature '%s' has no deforming bone" % arm.name)
    M = control_objects.to_mesh_space(obj, arm, depsgraph)
    seg = np.empty((len(names), 2, 3))
    for j, n in enumerate(names):
        b = arm.data.bones[n]
        for k, p in enumerate((b.head_local, b.tail_local)):
            seg[j, k] = (M @ np.array([p[0], p[1], p[2], 1.0]))[:3]
    return names, seg


def limit_influences(W, influences):
    """Keeps each row's `influences` largest entries that are >= SMALLEST, renormalised (the
    largest one always)."""
    W = np.array(W, dtype=np.float64)
    if influences < W.shape[1]:
        cut = np.partition(W, -influences, axis=1)[:, -influences][:, None]
        W[W < cut] = 0.0
    top = W.max(axis=1, keepdims=True)
    W[(W < SMALLEST) & (W < top)] = 0.0
    return W / W.sum(axis=1, keepdims=True)


def write_groups(obj, names, W):
    """Replaces the groups `names` (created when missing) with the columns of W (entries > 0
    only), in one pass over the mesh through bmesh."""
    groups = [obj.vertex_groups.get(n) or obj.vertex_groups.new(name=n) for n in names]
    ids = [g.index for g in groups]
    me = obj.data
    bm = bmesh.new()
    try:
        bm.from_mesh(me)
        layer = bm.verts.layers.deform.verify()
        bm.verts.ensure_lookup_table()
        for v in bm.verts:
            dv = v[layer]
            row = W[v.index]
            for j, gid in enumerate(ids):
                w = row[j]
                if w > 0.0:
                    dv[gid] = float(w)
                elif gid in dv:
                    del dv[gid]
        bm.to_mesh(me)
    finally:
        bm.free()
    me.update()


class WeightsJob(solver.progress.Reporting):
    """Main thread: reads the mesh and the bones; run(): the native computation only (any
    thread); the main thread then writes the groups."""

    def __init__(self, context, obj, d, op):
        c = solver.controls.of(d)
        if c.KIND != "bones":
            raise solver.DeformKitError("%s is not driven by an armature: Compute Weights is "
                                        "for a Skinning deformer" % d.name)
        arm = control_objects.control_object(obj, d, "armature", "ARMATURE", make=False)
        dk = native.load()
        if dk is None:
            raise solver.DeformKitError(native.error)
        self.names, self.segments = bone_segments(obj, arm, context.evaluated_depsgraph_get())
        me = obj.data
        self.n_vertices = len(me.vertices)
        if self.n_vertices == 0:
            raise solver.DeformKitError("'%s' has no vertices" % obj.name)
        rest = solver.rest_positions(me)
        self.mesh = solver.calls._native_call("mesh", dk.Mesh, rest,
                                              solver.blender_data.triangles(me))
        self.fn = dk.bounded_biharmonic_weights
        self.kw = dict(domain=op.domain.lower(), resolution=op.resolution)
        self.influences = op.influences
        self.weights, self.error, self.report = None, None, None

    def run(self):
        try:
            self.weights, self.report = solver.calls._native_call(
                "compute weights", self.fn, self.mesh, bones=self.segments, report=True,
                progress=self._progress, **self.kw)
        except solver.DeformKitError as e:
            self.error = e

    def finish(self, obj):
        if self.error is not None:
            raise self.error
        W = limit_influences(self.weights, self.influences)
        write_groups(obj, self.names, W)
        return W


def _begin(op, context):
    obj = _get_object(op, context)
    d = _get_deformer(op, context, obj)
    if obj.mode == "EDIT":
        raise solver.DeformKitError("leave Edit Mode to compute weights (they are written into "
                                    "the mesh's vertex groups)")
    return obj, d, WeightsJob(context, obj, d, op)


def _report(op, obj, job, seconds):
    rep = job.report or {}
    op.report({"INFO"}, "Computed the weights of %s on '%s' in %.1f s (%s domain, %s): press "
              "Bind" % (plural(len(job.names), "bone"), obj.name, seconds,
                        rep.get("domain", "?"), plural(rep.get("domain_vertices", 0), "vertex")))


class DEFORMKIT_OT_compute_weights(_Base, bpy.types.Operator):
    """Compute bounded biharmonic weights of the armature's deforming bones into vertex
    groups named after them (replacing those groups), for this deformer and for Blender's
    Armature modifier alike"""
    bl_idname = "deformkit.compute_weights"
    bl_label = "Compute Weights"
    bl_options = {"REGISTER", "UNDO"}
    domain: EnumProperty(
        name="Domain", default="AUTO",
        items=[("AUTO", "Auto", "The solid the mesh encloses, or its surface when it "
                "encloses none"),
               ("VOLUME", "Volume", "The solid the mesh encloses (bones lie inside it)"),
               ("SURFACE", "Surface", "The mesh's own surface (open or flat meshes)")])
    resolution: IntProperty(name="Resolution", default=24, min=4, max=256,
                            description="Volume grid cells along the mesh's longest side: "
                                        "finer follows thin parts closer, and takes longer")
    influences: IntProperty(name="Influences", default=4, min=1, max=32,
                            description="Bones kept per vertex (the largest weights, "
                                        "renormalised)")

    def run(self, context):
        t0 = time.perf_counter()
        obj, d, job = _begin(self, context)
        wm = context.window_manager
        wm.progress_begin(0, 1)
        try:
            job.run()
        finally:
            wm.progress_end()
        job.finish(obj)
        _report(self, obj, job, time.perf_counter() - t0)

    def invoke(self, context, event):
        if bpy.app.background:
            return self.execute(context)
        try:
            self._obj, _, self._job = _begin(self, context)
        except solver.DeformKitError as ex:
            self.report({"ERROR"}, str(ex))
            return {"CANCELLED"}
        self._obj = self._obj.name
        self._t0 = time.perf_counter()
        self._thread = threading.Thread(target=self._job.run, name="DeformKit weights",
                                        daemon=True)
        self._thread.start()
        wm = context.window_manager
        self._timer = wm.event_timer_add(0.05, window=context.window)
        wm.progress_begin(0, 1)
        wm.modal_handler_add(self)
        return {"RUNNING_MODAL"}

    def _end(self, context):
        wm = context.window_manager
        wm.event_timer_remove(self._timer)
        wm.progress_end()
        context.workspace.status_text_set(None)

    def modal(self, context, event):
        if event.type == "ESC":
            self._job.cancelled = True
            self._end(context)
            self.report({"WARNING"}, "Compute Weights cancelled: the vertex groups are as they "
                        "were")
            return {"CANCELLED"}
        if event.type != "TIMER":
            return {"PASS_THROUGH"}
        if self._thread.is_alive():
            frac = self._job.fraction
            context.workspace.status_text_set(
                "DeformKit: computing weights (%s, %s) %.1f s%s, Esc to cancel"
                % (plural(self._job.n_vertices, "vertex"), plural(len(self._job.names), "bone"),
                   time.perf_counter() - self._t0,
                   " %.0f%%" % (100 * frac) if frac is not None else ""))
            if frac is not None:
                context.window_manager.progress_update(frac)
            return {"RUNNING_MODAL"}
        self._end(context)
        obj = bpy.data.objects.get(self._obj)
        try:
            if obj is None or len(obj.data.vertices) != self._job.n_vertices:
                raise solver.DeformKitError("Compute Weights: the mesh was removed or changed "
                                            "meanwhile: nothing written")
            self._job.finish(obj)
        except solver.DeformKitError as ex:
            self.report({"ERROR"}, str(ex))
            return {"CANCELLED"}
        _report(self, obj, self._job, time.perf_counter() - self._t0)
        return {"FINISHED"}


CLASSES = [DEFORMKIT_OT_compute_weights]


def register():
    for c in CLASSES:
        bpy.utils.register_class(c)


def unregister():
    for c in reversed(CLASSES):
        bpy.utils.unregister_class(c)
