"""Baking a frame range: shared by the bake operator (sync and modal) and scripts/batch_bake.py.

Each frame is solved cold (its result depends only on that frame's inputs), so frame ranges
baked on different machines and joined give the same cache as one bake.
"""

import os

import bpy
import numpy as np

from . import geonodes, handlers, pc2, solver


def resolve_path(path, obj, d):
    if not path:
        path = "//%s_%s.pc2" % (bpy.path.clean_name(obj.name), bpy.path.clean_name(d.name))
    if path.startswith("//") and not bpy.data.filepath:
        raise solver.DeformKitError("save the .blend first (the cache goes next to it) or give "
                                    "an absolute path")
    return bpy.path.abspath(path)


class FrameBaker:
    """Steps through frames one at a time (so a modal operator can interleave UI events)."""

    def __init__(self, context, obj, d, frame_start, frame_end):
        if frame_end < frame_start:
            raise solver.DeformKitError("frame range %d-%d is empty" % (frame_start, frame_end))
        if not d.bound:
            raise solver.DeformKitError("'%s' is not bound: press Bind first" % d.name)
        self.scene = context.scene
        self.context = context
        self.obj_name, self.uid = obj.name, d.uid
        self.frames = list(range(frame_start, frame_end + 1))
        self.i = 0
        self.saved_frame = self.scene.frame_current
        self.handlers_were = handlers.enabled[0]
        handlers.enabled[0] = False  # the bake solves itself, cold; no double work per frame

    def _objects(self):
        obj = bpy.data.objects.get(self.obj_name)
        if obj is None:
            raise solver.DeformKitError("object '%s' was deleted during the bake" % self.obj_name)
        for d in obj.deformkit.deformers:
            if d.uid == self.uid:
                return obj, d
        raise solver.DeformKitError("deformer was removed during the bake")

    @property
    def done(self):
        return self.i >= len(self.frames)

    def step(self):
        """Solves the next frame; returns (frame, positions n x 3 float64)."""
        f = self.frames[self.i]
        self.scene.frame_set(f)
        obj, d = self._objects()
        dg = self.context.evaluated_depsgraph_get()
        pos = solver.deformed_positions(obj, d, dg, cold=True)
        self.i += 1
        return f, pos

    def finish(self):
        handlers.enabled[0] = self.handlers_were
        if self.scene.frame_current != self.saved_frame:
            self.scene.frame_set(self.saved_frame)


def add_mesh_cache(obj, d, path, frame_start):
    """Adds (or updates) a Mesh Cache modifier reading `path`, in place of the deformer's GN
    modifier, which is hidden (kept for re-baking)."""
    name = "%s Cache" % d.name
    mc = obj.modifiers.get(name)
    if mc is None or mc.type != "MESH_CACHE":
        mc = obj.modifiers.new(name, "MESH_CACHE")
    mc.cache_format = "PC2"
    try:
        mc.filepath = bpy.path.relpath(path) if bpy.data.filepath else path
    except ValueError:  # different drive
        mc.filepath = path
    mc.deform_mode = "OVERWRITE"
    mc.play_mode = "SCENE"
    mc.time_mode = "FRAME"
    mc.frame_start = frame_start
    mc.frame_scale = 1.0
    mc.interpolation = "LINEAR"
    gn = geonodes.find_modifier(obj, d)
    if gn is not None:
        gn.show_viewport = False
        gn.show_render = False
        gi = list(obj.modifiers).index(gn)
        mi = list(obj.modifiers).index(mc)
        if mi != gi + 1:
            try:
                with bpy.context.temp_override(object=obj):
                    bpy.ops.object.modifier_move_to_index(modifier=mc.name, index=gi + 1 if mi > gi else gi)
            except Exception:
                pass
    return mc


def bake_pc2(context, obj, d, frame_start, frame_end, path, progress=None):
    """Synchronous bake of frames [start, end] to `path`; progress(i, n, frame) per frame."""
    fb = FrameBaker(context, obj, d, frame_start, frame_end)
    n_points = len(obj.data.vertices)
    os.makedirs(os.path.dirname(os.path.abspath(path)) or ".", exist_ok=True)
    tmp = path + ".part"
    try:
        with pc2.Writer(tmp, n_points, start=frame_start) as w:
            while not fb.done:
                f, pos = fb.step()
                w.add(np.asarray(pos, dtype=np.float32))
                if progress is not None:
                    progress(fb.i, len(fb.frames), f)
        os.replace(tmp, path)
    finally:
        fb.finish()
        if os.path.exists(tmp):
            os.remove(tmp)
    return path


def bake_shape_keys(context, obj, d, frame_start, frame_end, progress=None):
    """One shape key per frame, keyed to 1 on its frame and 0 on the neighbours."""
    solver.check_input_is_rest(obj, d, "bake to shape keys")
    fb = FrameBaker(context, obj, d, frame_start, frame_end)
    results = []
    try:
        while not fb.done:
            f, pos = fb.step()
            results.append((f, np.asarray(pos, dtype=np.float32)))
            if progress is not None:
                progress(fb.i, len(fb.frames), f)
    finally:
        fb.finish()
    obj, d = fb._objects()
    if obj.data.shape_keys is None:
        obj.shape_key_add(name="Basis", from_mix=False)
    for f, pos in results:
        kname = "%s f%04d" % (d.name, f)
        old = obj.data.shape_keys.key_blocks.get(kname)
        if old is not None:
            obj.shape_key_remove(old)
        sk = obj.shape_key_add(name=kname, from_mix=False)
        sk.data.foreach_set("co", pos.ravel())
        for ff, v in ((f - 1, 0.0), (f, 1.0), (f + 1, 0.0)):
            sk.value = v
            sk.keyframe_insert("value", frame=ff)
    gn = geonodes.find_modifier(obj, d)
    if gn is not None:
        gn.show_viewport = False
        gn.show_render = False
    return len(results)
