"""Operators (bpy.ops.deformkit.*). Each has a synchronous execute() that works under
blender -b and from scripts; errors are reported with the native message, never raised."""

import contextlib
import time

import bmesh
import bpy
import numpy as np
from bpy.props import BoolProperty, EnumProperty, IntProperty, StringProperty

from . import (animated_input, bake, compat, geonodes, handlers, handles, methods, native,
               properties, solver)
from .text import plural


def _get_object(op, context):
    name = getattr(op, "object_name", "")
    if name:
        obj = bpy.data.objects.get(name)
    else:
        obj = getattr(context, "object", None) or context.view_layer.objects.active
    if obj is None:
        raise solver.DeformKitError("no active object" if not name else
                                    "object '%s' not found" % name)
    solver.check_mesh_type(obj)
    solver.check_editable(obj)
    return obj


def _get_deformer(op, context, obj):
    dks = obj.deformkit
    if len(dks.deformers) == 0:
        raise solver.DeformKitError("'%s' has no DeformKit deformer: add one first" % obj.name)
    i = op.deformer_index if op.deformer_index >= 0 else dks.active_index
    if not 0 <= i < len(dks.deformers):
        raise solver.DeformKitError("no deformer at index %d" % i)
    d = dks.deformers[i]
    # a duplicate's copy gets its own uid before anything acts on its attribute (removing,
    # unbinding or applying a linked copy's would act on the original's)
    solver.ensure_own_uid(obj, d)
    return d


class _Base:
    object_name: StringProperty(name="Object", description="Object (default: the active one)",
                                options={"SKIP_SAVE"})
    deformer_index: IntProperty(name="Deformer", default=-1, options={"SKIP_SAVE"},
                                description="Deformer index (-1: the active one)")

    def execute(self, context):
        try:
            return self.run(context) or {"FINISHED"}
        except solver.DeformKitError as e:
            self.report({"ERROR"}, str(e))
            return {"CANCELLED"}


class DEFORMKIT_OT_add_deformer(_Base, bpy.types.Operator):
    """Add a DeformKit deformer (an owned Geometry Nodes modifier) to the object"""
    bl_idname = "deformkit.add_deformer"
    bl_label = "Add DeformKit Deformer"
    bl_options = {"REGISTER", "UNDO"}
    method: EnumProperty(name="Method", items=methods.enum_items())

    def run(self, context):
        obj = _get_object(self, context)
        if len(obj.data.polygons) == 0 and methods.get(self.method).needs_faces:
            raise solver.DeformKitError("mesh '%s' has no faces: %s needs a surface (Embedded "
                                        "Deformation also deforms vertex clouds)"
                                        % (obj.data.name, methods.get(self.method).label))
        d = properties.new_deformer(obj, self.method)
        mod = geonodes.ensure_modifier(obj, d)
        if (methods.get(self.method).stack_first and obj.data.shape_keys is not None
                and list(obj.modifiers).index(mod) > 0):
            with context.temp_override(object=obj):
                # Blender may refuse, or stop part way (above a modifier that needs the
                # original mesh): the deformer goes where its modifier went
                bpy.ops.object.modifier_move_to_index(modifier=mod.name, index=0)
            dks = obj.deformkit   # the deformers keep the stack's order
            rank = sum(1 for x in obj.modifiers[:list(obj.modifiers).index(mod)]
                       if geonodes.is_ours(x))
            if rank < len(dks.deformers) - 1:
                dks.deformers.move(len(dks.deformers) - 1, rank)
                dks.active_index = rank
                d = dks.deformers[rank]
        solver.reset_status(d)
        if not native.has_class(methods.get(self.method).native_class):
            self.report({"WARNING"}, "the native module lacks deformkit.%s: %s"
                        % (methods.get(self.method).native_class, native.error or "old build"))


class DEFORMKIT_OT_remove_deformer(_Base, bpy.types.Operator):
    """Remove the deformer, its modifier and its offset attribute"""
    bl_idname = "deformkit.remove_deformer"
    bl_label = "Remove DeformKit Deformer"
    bl_options = {"REGISTER", "UNDO"}

    def run(self, context):
        obj = _get_object(self, context)
        d = _get_deformer(self, context, obj)
        remove_deformer(obj, d)


def remove_deformer(obj, d):
    mod = geonodes.find_modifier(obj, d)
    if mod is not None:
        obj.modifiers.remove(mod)
    geonodes.remove_attribute(obj.data, d.attribute_name)
    solver.drop(obj.name, d.uid)
    dks = obj.deformkit
    i = list(dks.deformers).index(d)
    dks.deformers.remove(i)
    dks.active_index = min(max(0, dks.active_index), max(0, len(dks.deformers) - 1))


class DEFORMKIT_OT_move_deformer(_Base, bpy.types.Operator):
    """Move the active deformer (and its modifier) up or down"""
    bl_idname = "deformkit.move_deformer"
    bl_label = "Move DeformKit Deformer"
    bl_options = {"REGISTER", "UNDO"}
    direction: EnumProperty(items=(("UP", "Up", ""), ("DOWN", "Down", "")))

    def run(self, context):
        obj = _get_object(self, context)
        d = _get_deformer(self, context, obj)
        dks = obj.deformkit
        i = list(dks.deformers).index(d)
        j = i - 1 if self.direction == "UP" else i + 1
        if not 0 <= j < len(dks.deformers):
            return {"CANCELLED"}
        other = dks.deformers[j]
        m1, m2 = geonodes.find_modifier(obj, d), geonodes.find_modifier(obj, other)
        dks.deformers.move(i, j)
        dks.active_index = j
        if m1 is not None and m2 is not None:
            k = list(obj.modifiers).index(m2)
            with context.temp_override(object=obj):
                bpy.ops.object.modifier_move_to_index(modifier=m1.name, index=k)


def _handles_changed(d):
    """An unbound deformer's status after a handle came or went: the error of a bind tried
    before (e.g. "no handles") no longer holds. A bound one is re-checked by the handler."""
    if not d.bound:
        solver.reset_status(d)


class DEFORMKIT_OT_add_handle(_Base, bpy.types.Operator):
    """Add an empty handle entry (choose its vertex group and target)"""
    bl_idname = "deformkit.add_handle"
    bl_label = "Add Handle"
    bl_options = {"REGISTER", "UNDO"}
    vertex_group: StringProperty(name="Vertex Group")
    target: StringProperty(name="Target Object")
    subtarget: StringProperty(name="Bone")

    def run(self, context):
        obj = _get_object(self, context)
        d = _get_deformer(self, context, obj)
        h = d.handles.add()
        h.name = self.vertex_group or "Handle %d" % len(d.handles)
        h.vertex_group = self.vertex_group
        if self.target:
            t = bpy.data.objects.get(self.target)
            if t is None:
                raise solver.DeformKitError("target object '%s' not found" % self.target)
            h.target = t
        h.subtarget = self.subtarget
        d.active_handle = len(d.handles) - 1
        if d.bound and h.target is not None:
            handles.set_bind_matrix(obj, h, d=d)
        _handles_changed(d)


class DEFORMKIT_OT_add_handle_from_selection(_Base, bpy.types.Operator):
    """Make a vertex group from the selected vertices, an empty at their centre, and a handle
    entry targeting it (like Hook to New Object)"""
    bl_idname = "deformkit.add_handle_from_selection"
    bl_label = "Add Handle from Selection"
    bl_options = {"REGISTER", "UNDO"}
    method: EnumProperty(name="Method (new deformer)", items=methods.enum_items(),
                         description="Method of the deformer created if the object has none")

    def run(self, context):
        obj = _get_object(self, context)
        if obj.mode != "EDIT":
            raise solver.DeformKitError("select the handle's vertices in Edit Mode first")
        bm = bmesh.from_edit_mesh(obj.data)
        sel = [v.index for v in bm.verts if v.select]
        if not sel:
            raise solver.DeformKitError("no vertices selected")
        co = np.array([tuple(v.co) for v in bm.verts if v.select])
        bpy.ops.object.mode_set(mode="OBJECT")
        try:
            # the empty goes where the selection is shown: on a posed mesh, where the
            # Armature (and the other modifiers) put it, not at its rest place
            shown = solver.evaluated_positions(obj)
            if len(shown) == len(obj.data.vertices):
                co = shown[sel]
            centre_local = co.mean(axis=0)
            dks = obj.deformkit
            if len(dks.deformers) == 0:
                d = properties.new_deformer(obj, self.method)
                geonodes.ensure_modifier(obj, d)
            else:
                d = _get_deformer(self, context, obj)
            n = len(d.handles) + 1
            base = "DK Handle"
            name = "%s %d" % (base, n)
            while obj.vertex_groups.get(name) is not None or bpy.data.objects.get(name):
                n += 1
                name = "%s %d" % (base, n)
            vg = obj.vertex_groups.new(name=name)
            vg.add(sel, 1.0, "REPLACE")
            from mathutils import Vector
            empty = bpy.data.objects.new(name, None)
            empty.empty_display_type = "SPHERE"
            ext = co.max(axis=0) - co.min(axis=0)
            size = float(max(ext.max() * 0.6, obj.dimensions.length * 0.03, 0.01))
            empty.empty_display_size = size / max(max(obj.scale), 1e-9)
            colls = obj.users_collection or (context.scene.collection,)
            colls[0].objects.link(empty)
            empty.matrix_world = obj.matrix_world.copy()
            empty.location = obj.matrix_world @ Vector(centre_local)
            h = d.handles.add()
            h.name = name
            h.vertex_group = name
            h.target = empty
            d.active_handle = len(d.handles) - 1
            if d.bound:
                context.view_layer.update()
                handles.set_bind_matrix(obj, h, d=d)
            _handles_changed(d)
        finally:
            bpy.ops.object.mode_set(mode="EDIT")
        self.report({"INFO"}, "handle '%s': %s" % (name, plural(len(sel), "vertex")))


class DEFORMKIT_OT_remove_handle(_Base, bpy.types.Operator):
    """Remove the active handle (its vertex group and target are kept)"""
    bl_idname = "deformkit.remove_handle"
    bl_label = "Remove Handle"
    bl_options = {"REGISTER", "UNDO"}
    handle_index: IntProperty(default=-1, options={"SKIP_SAVE"})

    def run(self, context):
        obj = _get_object(self, context)
        d = _get_deformer(self, context, obj)
        i = self.handle_index if self.handle_index >= 0 else d.active_handle
        if not 0 <= i < len(d.handles):
            raise solver.DeformKitError("no handle at index %d" % i)
        d.handles.remove(i)
        d.active_handle = min(d.active_handle, max(0, len(d.handles) - 1))
        _handles_changed(d)



def _report_bound(op, obj, d, ms, rest_frame=None):
    """The bind's report: a warning when nothing can show the result, or when the native
    object warns (loose geometry held at rest, a floppy deformation graph). It names the rest
    frame when that is not the frame shown."""
    msg = "%s %s (%.0f ms)" % (d.name, solver.idle_status(d), ms)
    if rest_frame is not None and rest_frame != bpy.context.scene.frame_current:
        msg += ", the rest taken on frame %d (%s)" % (
            rest_frame, "the scene's start" if d.rest_frame_from == "START" else "Rest Frame")
    hidden = bake.hidden_reason(obj, d)
    baked = bake.state(obj, d)
    buts = ([hidden or baked["text"]] if hidden or baked else []) + list(
        solver.bind_warnings(obj, d))
    if buts:
        op.report({"WARNING"}, "%s, but %s" % (msg, "; ".join(buts)))
    else:
        op.report({"INFO"}, msg)


@contextlib.contextmanager
def _at_rest_frame(context, d):
    """Shows the deformer's rest frame (solver.rest_frame) while the body runs, then the
    frame that was shown, without solving any deformer on the way (the handlers are off:
    what shows is unchanged). Yields the rest frame."""
    scene = context.scene
    f, now = solver.rest_frame(scene, d), scene.frame_current
    if f == now:
        yield f
        return
    was = handlers.enabled[0]
    handlers.enabled[0] = False
    try:
        scene.frame_set(f)
        yield f
    finally:
        scene.frame_set(now)
        handlers.enabled[0] = was


def _bind_begin(context, obj, d):
    """solver.bind_begin on the deformer's rest frame: (job, bind matrices, rest frame)."""
    with _at_rest_frame(context, d) as f:
        job, mats = solver.bind_begin(obj, d, context.evaluated_depsgraph_get())
    return job, mats, f


class DEFORMKIT_OT_bind(_Base, bpy.types.Operator):
    """Bind: precompute the solver for the current mesh and groups, with the handles' placement
    and the pose of the rest frame (the scene's start unless the deformer's Rest Frame says
    otherwise)"""
    bl_idname = "deformkit.bind"
    bl_label = "Bind"
    bl_options = {"REGISTER", "UNDO"}

    def run(self, context):
        obj = _get_object(self, context)
        d = _get_deformer(self, context, obj)
        t0 = time.perf_counter()
        wm = context.window_manager
        wm.progress_begin(0, 1)  # a busy cursor while the factorizations run
        try:
            job, mats, f = _bind_begin(context, obj, d)
            job.run()
            solver.bind_end(obj, d, job, mats, context.evaluated_depsgraph_get())
        except solver.DeformKitError as ex:
            solver.set_status(d, ex, True)
            raise
        finally:
            wm.progress_end()
        ms = (time.perf_counter() - t0) * 1000
        _report_bound(self, obj, d, ms, f)

    # ---- UI version: the native precomputation runs in a worker thread (it releases the
    # GIL), the window stays live with the elapsed time in the status bar, Esc cancels and
    # keeps the previous binding. Scripts and blender -b use the synchronous execute().
    def invoke(self, context, event):
        if bpy.app.background:
            return self.execute(context)
        import threading
        try:
            obj = _get_object(self, context)
            d = _get_deformer(self, context, obj)
            # running from invoke until its modal part ends (not only while the worker
            # thread lives: a small mesh's bind is done before the next event)
            if (obj.name, d.uid) in solver.running_binds:
                raise solver.DeformKitError("a bind of %s is already running" % d.name)
            self._job, self._mats, self._rest_frame = _bind_begin(context, obj, d)
        except solver.DeformKitError as ex:
            if "d" in locals():
                solver.set_status(d, ex, True)
            self.report({"ERROR"}, str(ex))
            return {"CANCELLED"}
        self._obj, self._uid, self._name = obj.name, d.uid, d.name
        self._t0 = time.perf_counter()
        self._thread = threading.Thread(target=self._job.run, name="DeformKit bind",
                                        daemon=True)
        self._thread.start()
        solver.running_binds[(obj.name, d.uid)] = self._thread
        wm = context.window_manager
        self._timer = wm.event_timer_add(0.05, window=context.window)
        wm.progress_begin(0, 1)
        wm.modal_handler_add(self)
        return {"RUNNING_MODAL"}

    def _end(self, context):
        solver.running_binds.pop((self._obj, self._uid), None)
        wm = context.window_manager
        wm.event_timer_remove(self._timer)
        wm.progress_end()
        context.workspace.status_text_set(None)

    def modal(self, context, event):
        if event.type == "ESC":
            self._job.cancelled = True  # methods with bind progress stop their native work
            self._end(context)  # the worker finishes on its own; its result is dropped
            self.report({"WARNING"}, "bind of %s cancelled: the previous state is kept"
                        % self._name)
            return {"CANCELLED"}
        if event.type != "TIMER":
            return {"PASS_THROUGH"}
        if self._thread.is_alive():
            frac, phase = self._job.fraction, self._job.progress_text()
            context.workspace.status_text_set(
                "DeformKit: binding %s (%s) %.1f s%s, Esc to cancel"
                % (self._name, plural(self._job.n_vertices, "vertex"),
                   time.perf_counter() - self._t0, ", " + phase if phase else ""))
            if frac is not None:
                context.window_manager.progress_update(frac)
            return {"RUNNING_MODAL"}
        self._end(context)
        obj = bpy.data.objects.get(self._obj)
        d = None if obj is None else next(
            (x for x in obj.deformkit.deformers if x.uid == self._uid), None)
        if d is None:
            self.report({"ERROR"}, "bind of %s: the object or deformer was removed meanwhile"
                        % self._name)
            return {"CANCELLED"}
        try:
            solver.bind_end(obj, d, self._job, self._mats, context.evaluated_depsgraph_get())
        except solver.DeformKitError as ex:
            solver.set_status(d, ex, True)
            self.report({"ERROR"}, str(ex))
            return {"CANCELLED"}
        _report_bound(self, obj, d, (time.perf_counter() - self._t0) * 1000, self._rest_frame)
        return {"FINISHED"}


class DEFORMKIT_OT_unbind(_Base, bpy.types.Operator):
    """Unbind: drop the solver state and show the rest shape"""
    bl_idname = "deformkit.unbind"
    bl_label = "Unbind"
    bl_options = {"REGISTER", "UNDO"}

    def run(self, context):
        obj = _get_object(self, context)
        d = _get_deformer(self, context, obj)
        solver.unbind(obj, d)


class DEFORMKIT_OT_bake_corrective(_Base, bpy.types.Operator):
    """Store the deformer's edit at this pose as a corrective shape key under the Armature,
    driven by the bone that carries the handles: it plays without DeformKit, at full
    strength on this pose and blended in between"""
    bl_idname = "deformkit.bake_corrective"
    bl_label = "Bake Corrective Shape Key"
    bl_options = {"REGISTER", "UNDO"}
    bone: StringProperty(name="Bone", description="The bone whose rotation drives the key "
                                                  "(empty: the one carrying the handles)")

    def run(self, context):
        from . import corrective
        obj = _get_object(self, context)
        d = _get_deformer(self, context, obj)
        solver.check_editable(obj)
        if obj.mode != "OBJECT":
            raise solver.DeformKitError("leave %s Mode to bake a corrective" % obj.mode.title())
        if not d.bound:
            raise solver.DeformKitError("'%s' is not bound: press Bind first" % d.name)
        rig = None
        if self.bone:
            arms = [m.object for m in animated_input.modifiers_above(obj, d)
                    if m.type == "ARMATURE" and m.object is not None
                    and self.bone in m.object.data.bones]
            if not arms:
                raise solver.DeformKitError("no Armature above %s has a bone '%s'"
                                            % (d.name, self.bone))
            rig = (arms[0], self.bone)
        key, bone = corrective.bake_corrective(obj, d, bone=rig)
        self.report({"INFO"}, "corrective shape key '%s', driven by bone '%s'; hide %s's "
                    "modifier to play it alone" % (key.name, bone, d.name))


class DEFORMKIT_OT_apply(_Base, bpy.types.Operator):
    """Bake the deformer's current result into the mesh or into a new shape key"""
    bl_idname = "deformkit.apply"
    bl_label = "Apply DeformKit Deformer"
    bl_options = {"REGISTER", "UNDO"}
    mode: EnumProperty(name="Into", items=(
        ("MESH", "Mesh", "Write the result into the mesh and remove the deformer"),
        ("SHAPE_KEY", "New Shape Key", "Store the result as a new shape key")))
    keep: BoolProperty(name="Keep Deformer", default=False,
                       description="Keep the deformer after applying as a shape key; the key "
                                   "is then stored at value 0, as Blender's Save as Shape Key "
                                   "does (at 1 the deformer would add its offset to it again)")

    def run(self, context):
        obj = _get_object(self, context)
        d = _get_deformer(self, context, obj)
        if obj.mode == "EDIT":
            raise solver.DeformKitError("leave Edit Mode to apply")
        me = obj.data
        solver.check_single_user(obj, "apply %s" % d.name)
        if self.mode == "MESH" and me.shape_keys is not None:
            raise solver.DeformKitError("mesh '%s' has shape keys: apply as a new shape key "
                                        "instead" % me.name)
        # what the artist sees: the shown result, brought up to date first
        dg = context.evaluated_depsgraph_get()
        # under an Armature the written shape would be moved again: for every method (the
        # edits turn with the pose; Bake Corrective Shape Key carries them back instead)
        animated_input.check_input_is_rest(obj, d, "apply", dg, every_method=True)
        solver.finish(obj, d, dg)
        pos = solver.shown_positions(obj, d)
        flat = np.ascontiguousarray(pos, dtype=np.float32).ravel()
        mod = geonodes.find_modifier(obj, d)
        first = mod is None or list(obj.modifiers).index(mod) == 0
        name = d.name
        if self.mode == "MESH":
            me.vertices.foreach_set("co", flat)
            me.update()
            remove_deformer(obj, d)
        else:
            if me.shape_keys is None:
                obj.shape_key_add(name="Basis", from_mix=False)
            sk = obj.shape_key_add(name=name, from_mix=False)
            sk.data.foreach_set("co", flat)
            # kept, the deformer still shows the result: the key waits at 0 (a key at 1 would
            # be the deformer's input, and its offset would be added to it a second time)
            sk.value = 0.0 if self.keep else 1.0
            me.update()
            if not self.keep:
                remove_deformer(obj, d)
        if not first:
            self.report({"WARNING"}, "applied '%s', which was not first in the modifier stack"
                        % name)
        elif self.mode == "SHAPE_KEY" and self.keep:
            self.report({"INFO"}, "saved '%s' as the shape key '%s' (value 0: the deformer "
                        "still shows the result; raise the key after removing it)"
                        % (name, sk.name))
        else:
            self.report({"INFO"}, "applied '%s'" % name)


class DEFORMKIT_OT_bake(_Base, bpy.types.Operator):
    """Bake a frame range to a PC2 point cache (+ Mesh Cache modifier) or to shape keys, so
    renders need neither the add-on nor its handlers. Esc cancels in the UI"""
    bl_idname = "deformkit.bake"
    bl_label = "Bake DeformKit Animation"
    bl_options = {"REGISTER", "UNDO"}
    mode: EnumProperty(name="Bake To", items=(
        ("PC2", "Point Cache", "PC2 file next to the .blend, read by a Mesh Cache modifier"),
        ("SHAPE_KEYS", "Shape Keys", "One shape key per frame (short ranges)")))
    frame_start: IntProperty(name="Start", default=-1, description="-1: the scene's start")
    frame_end: IntProperty(name="End", default=-1, description="-1: the scene's end")
    filepath: StringProperty(name="File", subtype="FILE_PATH",
                             options=compat.BLEND_RELATIVE_PATH,
                             description="PC2 path (default: //<object>_<deformer>.pc2)")

    def _range(self, context):
        s = self.frame_start if self.frame_start >= 0 else context.scene.frame_start
        e = self.frame_end if self.frame_end >= 0 else context.scene.frame_end
        return s, e

    def run(self, context):
        obj = _get_object(self, context)
        d = _get_deformer(self, context, obj)
        s, e = self._range(context)
        wm = context.window_manager
        wm.progress_begin(0, e - s + 1)
        try:
            def prog(i, n, f):
                wm.progress_update(i)
            if self.mode == "PC2":
                path = bake.resolve_path(self.filepath or d.bake_file, obj, d)
                bake.bake_pc2(context, obj, d, s, e, path, prog, add_cache=True)
                self.report({"INFO"}, "baked frames %d-%d to %s" % (s, e, path))
            else:
                n = bake.bake_shape_keys(context, obj, d, s, e, prog)
                self.report({"INFO"}, "baked %s to shape keys" % plural(n, "frame"))
        finally:
            wm.progress_end()

    # ---- modal version for the UI: one frame per timer tick (the window stays live, the
    # status bar shows the progress), Esc cancels and drops the partial bake
    def invoke(self, context, event):
        if bpy.app.background:
            return self.execute(context)
        try:
            obj = _get_object(self, context)
            d = _get_deformer(self, context, obj)
            s, e = self._range(context)
            if self.mode == "PC2":
                path = bake.resolve_path(self.filepath or d.bake_file, obj, d)
                self._job = bake.PC2Bake(context, obj, d, s, e, path)
            else:
                self._job = bake.ShapeKeyBake(context, obj, d, s, e)
        except solver.DeformKitError as ex:
            self.report({"ERROR"}, str(ex))
            return {"CANCELLED"}
        wm = context.window_manager
        self._timer = wm.event_timer_add(0.001, window=context.window)
        wm.progress_begin(0, len(self._job.fb.frames))
        wm.modal_handler_add(self)
        return {"RUNNING_MODAL"}

    def _end(self, context, ok, msg=None):
        wm = context.window_manager
        wm.event_timer_remove(self._timer)
        wm.progress_end()
        if context.area:
            context.area.header_text_set(None)
        context.workspace.status_text_set(None)
        try:
            done = self._job.finish(ok)
        except Exception as ex:  # said in the report bar; the earlier bake is put back
            ok, msg = False, str(ex)
        if ok:
            self.report({"INFO"}, done)
            return {"FINISHED"}
        self.report({"WARNING"} if msg == "bake cancelled" else {"ERROR"}, msg)
        return {"CANCELLED"}

    def modal(self, context, event):
        if event.type == "ESC":
            return self._end(context, False, "bake cancelled")
        if event.type != "TIMER":
            return {"PASS_THROUGH"}
        try:
            f = self._job.step_async()  # the frame's solve runs in a worker thread
        except Exception as ex:  # any error ends the bake through finish(False): the
            # partial file dropped, the earlier bake put back, the handlers on again
            return self._end(context, False, str(ex))
        fb = self._job.fb
        if f is None:  # still solving: the window stays live, Esc answers
            busy = fb.solving()
            if busy is None:  # a simulation playing the frames before the range, one a tick
                context.workspace.status_text_set(
                    "DeformKit bake: playing frame %d before the range, Esc to cancel"
                    % fb.prerolled)
                return {"RUNNING_MODAL"}
            f, secs = busy
            context.workspace.status_text_set(
                "DeformKit bake: frame %d (%d/%d), solving %.1f s, Esc to cancel"
                % (f, fb.i + 1, len(fb.frames), secs))
            return {"RUNNING_MODAL"}
        context.window_manager.progress_update(fb.i)
        context.workspace.status_text_set("DeformKit bake: frame %d (%d/%d), Esc to cancel"
                                          % (f, fb.i, len(fb.frames)))
        if self._job.done:
            return self._end(context, True)
        return {"RUNNING_MODAL"}


class DEFORMKIT_OT_free_bake(_Base, bpy.types.Operator):
    """Remove the deformer's bake (its Mesh Cache modifier, or its baked shape keys) and show
    the live result again; a cache file on disk is kept"""
    bl_idname = "deformkit.free_bake"
    bl_label = "Free Bake"
    bl_options = {"REGISTER", "UNDO"}

    def run(self, context):
        obj = _get_object(self, context)
        d = _get_deformer(self, context, obj)
        if bake.state(obj, d) is None:
            raise solver.DeformKitError("'%s' has no bake to free" % d.name)
        kind = bake.free(obj, d)
        self.report({"INFO"}, "%s: %s bake freed, the live result shows again"
                    % (d.name, "point cache" if kind == "PC2" else "shape key"))


class DEFORMKIT_OT_rebake(_Base, bpy.types.Operator):
    """Bake again, to the same kind, frame range and file as the last bake"""
    bl_idname = "deformkit.rebake"
    bl_label = "Re-bake"
    bl_options = {"REGISTER", "UNDO"}

    def _args(self, context):
        obj = _get_object(self, context)
        d = _get_deformer(self, context, obj)
        st = bake.state(obj, d)
        if st is None:
            raise solver.DeformKitError("'%s' has no bake to redo: use Bake" % d.name)
        i = list(obj.deformkit.deformers).index(d)
        kw = dict(mode=st["kind"], object_name=obj.name, deformer_index=i)
        if d.bake_kind != "NONE":
            kw.update(frame_start=d.bake_start, frame_end=d.bake_end)
        if st["kind"] == "PC2":
            mc = obj.modifiers.get(d.bake_target or "%s Cache" % d.name)
            if mc is not None and mc.type == "MESH_CACHE" and mc.filepath:
                kw["filepath"] = mc.filepath
        return kw

    def _bake(self, context, *how):
        try:
            return bpy.ops.deformkit.bake(*how, **self._args(context))
        except RuntimeError as e:  # the bake reported its error: pass it on as ours
            raise solver.DeformKitError(str(e).replace("Error:", "").strip()) from e

    def run(self, context):
        return self._bake(context)

    def invoke(self, context, event):
        try:
            return self._bake(context, "INVOKE_DEFAULT")
        except solver.DeformKitError as e:
            self.report({"ERROR"}, str(e))
            return {"CANCELLED"}


class DEFORMKIT_OT_restore_modifier(_Base, bpy.types.Operator):
    """Give the deformer a Geometry Nodes modifier again (it was deleted), at the end of the
    stack, keeping its handles and options"""
    bl_idname = "deformkit.restore_modifier"
    bl_label = "Restore Modifier"
    bl_options = {"REGISTER", "UNDO"}

    def run(self, context):
        obj = _get_object(self, context)
        d = _get_deformer(self, context, obj)
        if geonodes.find_modifier(obj, d) is not None:
            raise solver.DeformKitError("%s already has its modifier" % d.name)
        mod = geonodes.ensure_modifier(obj, d)
        if d.bound:
            geonodes.ensure_attribute(obj.data, d.attribute_name)
            solver.mark_all_dirty()
        self.report({"INFO"}, "%s: modifier '%s' restored" % (d.name, mod.name))


class DEFORMKIT_OT_overlap(_Base, bpy.types.Operator):
    """Select the vertices two of the deformer's groups share (in Edit Mode), or remove them
    from one of the groups"""
    bl_idname = "deformkit.overlap"
    bl_label = "Shared Vertices"
    bl_options = {"REGISTER", "UNDO"}
    action: EnumProperty(items=(("SELECT", "Select Shared", "Select the shared vertices in "
                                 "Edit Mode"),
                                ("REMOVE", "Remove", "Remove the shared vertices from "
                                 "`group`")))
    group: StringProperty(name="Group", description="The group to remove them from")
    other: StringProperty(name="Other Group")

    def run(self, context):
        obj = _get_object(self, context)
        _get_deformer(self, context, obj)
        names = (self.group, self.other)
        vgs = [obj.vertex_groups.get(n) for n in names]
        for n, vg in zip(names, vgs):
            if vg is None:
                raise solver.DeformKitError("vertex group '%s' does not exist" % n)
        groups = solver.blender_data.read_groups(obj, names)
        shared = np.intersect1d(groups[names[0]][0], groups[names[1]][0])
        if len(shared) == 0:
            raise solver.DeformKitError("'%s' and '%s' share no vertices" % names)
        if self.action == "REMOVE":
            if obj.mode == "EDIT":
                bpy.ops.object.mode_set(mode="OBJECT")
            vgs[0].remove([int(i) for i in shared])
            self.report({"INFO"}, "removed %s from '%s'" % (plural(len(shared), "vertex"),
                                                            names[0]))
            return
        if context.view_layer.objects.active != obj:
            context.view_layer.objects.active = obj
        if obj.mode != "EDIT":
            bpy.ops.object.mode_set(mode="EDIT")
        # through bmesh in Edit Mode (writing the mesh's edge selection with foreach_set
        # crashed Blender 5.0 as a module)
        bm = bmesh.from_edit_mesh(obj.data)
        want = set(int(i) for i in shared)
        for seq in (bm.faces, bm.edges):
            for x in seq:
                x.select = False
        for v in bm.verts:
            v.select = v.index in want
        bm.select_flush(False)
        bmesh.update_edit_mesh(obj.data)
        self.report({"INFO"}, "%s selected" % plural(len(shared), "shared vertex",
                                                       "shared vertices"))


CLASSES = [
    DEFORMKIT_OT_add_deformer, DEFORMKIT_OT_remove_deformer, DEFORMKIT_OT_move_deformer,
    DEFORMKIT_OT_add_handle, DEFORMKIT_OT_add_handle_from_selection, DEFORMKIT_OT_remove_handle,
    DEFORMKIT_OT_bind, DEFORMKIT_OT_unbind, DEFORMKIT_OT_apply, DEFORMKIT_OT_bake_corrective,
    DEFORMKIT_OT_bake,
    DEFORMKIT_OT_free_bake, DEFORMKIT_OT_rebake, DEFORMKIT_OT_restore_modifier,
    DEFORMKIT_OT_overlap,
]


def register():
    for c in CLASSES:
        bpy.utils.register_class(c)


def unregister():
    for c in reversed(CLASSES):
        bpy.utils.unregister_class(c)
