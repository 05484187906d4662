"""Baking a frame range: shared by the bake operator (sync and modal) and scripts/batch_bake.py.

Each frame is solved cold (its result depends only on that frame's inputs), so frame ranges
baked on different machines and joined give the same cache as one bake.
"""

import os
import weakref

import bpy
import numpy as np

from . import animated_input, compat, geonodes, handlers, methods, pc2, solver
from .text import plural


def resolve_path(path, obj, d):
    if not path:
        path = "//%s_%s.pc2" % (bpy.path.clean_name(obj.name), bpy.path.clean_name(d.name))
    if path.startswith("//") and not bpy.data.filepath:
        raise solver.DeformKitError("save the .blend first (the cache goes next to it) or give "
                                    "an absolute path")
    return bpy.path.abspath(path)


# How long a modal bake's tick waits for the frame it started (FrameBaker.step_async).
QUICK_FRAME_S = 0.03


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
        # a simulation plays the frames before the range first (kept ones cost no solve),
        # unless the frame before it was imported as a checkpoint (a chunk of a split bake)
        self.dynamic = solver.simulation.is_dynamic(methods.get(d.method))
        e = solver.cache._cache.get((obj.name, d.uid))
        sim = getattr(e, "sim", None) if e is not None else None
        rec = sim.items.get(frame_start - 1) if sim is not None else None
        # only a checkpoint imported for this bake (its key is b""): a kept frame before the
        # range may follow from frames an edit has changed since, which the preroll checks
        have = rec is not None and rec[0] == b"" and rec[1] is not None
        self.preroll = [] if not self.dynamic or have else \
            list(range(min(self.scene.frame_start, frame_start), frame_start))
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

    def _preroll(self):
        while self.preroll:
            f = self.preroll.pop(0)
            self.scene.frame_set(f)
            obj, d = self._objects()
            solver.deformed_positions(obj, d, self.context.evaluated_depsgraph_get(), cold=True,
                                      check_groups=False)

    def step(self):
        """Solves the next frame; returns (frame, positions n x 3 float64)."""
        self._preroll()
        f = self.frames[self.i]
        self.scene.frame_set(f)
        obj, d = self._objects()
        dg = self.context.evaluated_depsgraph_get()
        # the first frame reads the vertex groups again (a script may have edited them
        # without an update that said so)
        pos = solver.deformed_positions(obj, d, dg, cold=True, check_groups=self.i == 0)
        if self.dynamic:
            self._check_followed(obj, d, f)
        self.i += 1
        return f, pos

    def _check_followed(self, obj, d, f):
        """A simulation's frame must have followed from the frame before it (never the
        input shown ahead of what was simulated, which playback may show)."""
        s = solver.simulation.summary(solver.binding_of(obj, d))
        if s is None or s[2] is not None:
            raise solver.DeformKitError(
                "simulation: frame %d could not follow from frame %d (its checkpoint is "
                "gone): bake again from frame %d" % (f, f - 1, self.scene.frame_start))

    # ---- the modal bake's steps: the frame's native solve in a worker thread
    # (solver.FrameSolve), so that the window stays live and Esc answers while a big mesh's
    # frame solves (ARAP at 692k vertices: tens of seconds a frame)
    pending = None  # (frame, solver.FrameSolve, start time) of the frame being solved
    prerolled = None  # a simulation's last frame played before the range (modal bake)

    def step_begin(self):
        """Starts solving the next frame in a worker thread."""
        import time
        f = self.frames[self.i]
        self.scene.frame_set(f)
        obj, d = self._objects()
        dg = self.context.evaluated_depsgraph_get()
        job = solver.solve(obj, d, dg, cold=True, write=False, force=True, defer=True,
                           check_groups=self.i == 0)
        self.pending = (f, job, time.perf_counter())

    def step_poll(self):
        """(frame, positions) once the frame started by step_begin is solved, else None."""
        f, job, _ = self.pending
        if not job.done():
            return None
        self.pending = None
        # the window stayed live while the frame solved: had the user changed the frame,
        # what reached the modifier (read for the shown result) would be another frame's
        if self.scene.frame_current != f:
            self.scene.frame_set(f)
        obj, d = self._objects()
        pos = job.result(obj, d)
        self.i += 1
        return f, pos

    def solving(self):
        """(frame, seconds) of the frame being solved, or None."""
        import time
        if self.pending is None:
            return None
        return self.pending[0], time.perf_counter() - self.pending[2]

    def step_async(self):
        """One tick of a modal bake: starts the next frame's solve, or returns (frame,
        positions) when it is done (None meanwhile)."""
        if self.dynamic:  # each frame follows from the last: in order, milliseconds each
            if self.preroll:  # the frames before the range one a tick, so that Esc answers
                f = self.preroll.pop(0)
                self.scene.frame_set(f)
                obj, d = self._objects()
                solver.deformed_positions(obj, d, self.context.evaluated_depsgraph_get(),
                                          cold=True, check_groups=False)
                self.prerolled = f
                return None
            return self.step()
        if self.pending is None:
            self.step_begin()
            # a small mesh's frame is solved within this: one tick a frame, as before (a
            # tick of the window costs far more than the wait)
            self.pending[1].thread.join(QUICK_FRAME_S)
        return self.step_poll()

    def finish(self):
        if self.pending is not None:  # cancelled while a frame solved: stop its slices
            self.pending[1].cancel()
            self.pending = None
        handlers.enabled[0] = self.handlers_were
        if self.scene.frame_current != self.saved_frame:
            self.scene.frame_set(self.saved_frame)


# ---- a simulation's checkpoints between the chunks of a split bake (solver.simulation): the
# chunk that ends at frame B leaves the native state after B in a file; the chunk that starts
# at B + 1 continues from it instead of playing frames 1..B again. The file begins with a
# line of JSON naming the binding (method, settings, groups, topology, first frame) and the
# hash of the history of frames 1..B (each frame's key: what it was computed from), checked
# before the state is used (the loader evaluates those frames, without simulating them): a
# file left by another binding or another animation is refused by name.
CHECKPOINT_MAGIC = b"DKCHECKPOINT1\n"


def checkpoint_path(folder, obj, d, frame):
    return os.path.join(folder, "%s_%s.%d.dkstate" % (bpy.path.clean_name(obj.name),
                                                      bpy.path.clean_name(d.name), frame))


def _binding_id(obj, d, e):
    import hashlib
    h = hashlib.sha256()
    h.update(repr(methods.signature(methods.get(d.method), d.options)).encode())
    g = e.groups
    h.update(g if isinstance(g, bytes) else repr(g).encode())
    h.update(repr(d.bind_topology).encode())
    h.update(repr(bpy.context.scene.frame_start).encode())
    return h.hexdigest()


def load_checkpoint(obj, d, folder, frame_start):
    """Imports the checkpoint of the frame before `frame_start` from `folder` when there is
    one; returns its path, or None (the bake then plays the frames before its range). A file
    made by another binding (method, settings, groups, mesh) or from another animation of
    the frames before it is refused with a DeformKitError naming it."""
    import json
    if not solver.simulation.is_dynamic(methods.get(d.method)):
        return None
    scene = bpy.context.scene
    if frame_start <= scene.frame_start:
        return None
    path = checkpoint_path(folder, obj, d, frame_start - 1)
    if not os.path.isfile(path):
        return None
    with open(path, "rb") as f:
        data = f.read()
    head, _, state = data[len(CHECKPOINT_MAGIC):].partition(b"\n")
    try:
        meta = json.loads(head) if data.startswith(CHECKPOINT_MAGIC) else None
    except ValueError:
        meta = None
    if not isinstance(meta, dict):
        raise solver.DeformKitError("%s is not a DeformKit checkpoint" % path)
    e = solver.binding_of(obj, d)
    if meta.get("binding") != _binding_id(obj, d, e) or meta.get("frame") != frame_start - 1:
        raise solver.DeformKitError(
            "checkpoint %s was made by another binding of '%s' (its settings, groups, mesh or "
            "first frame differ): delete it, or bake from frame %d"
            % (path, d.name, scene.frame_start))
    was = handlers.enabled[0]
    handlers.enabled[0] = False   # the history of the frames up to it, without solving them
    history = b""
    try:
        for f in range(scene.frame_start, frame_start):
            scene.frame_set(f)
            history = solver.simulation.chain(
                history, solver.frame_key(obj, d, bpy.context.evaluated_depsgraph_get()))
    finally:
        handlers.enabled[0] = was
    if meta.get("history") != history.hex():
        raise solver.DeformKitError(
            "checkpoint %s was made from another animation of frames %d-%d (their input, "
            "handles or keyed settings differ): delete it, or bake from frame %d"
            % (path, scene.frame_start, frame_start - 1, scene.frame_start))
    try:
        solver.simulation.import_checkpoint(e, frame_start - 1, state, scene.frame_start,
                                            history)
    except (ValueError, TypeError) as ex:
        raise solver.DeformKitError("checkpoint %s does not fit '%s': %s" % (path, d.name, ex))
    return path


def save_checkpoint(obj, d, folder, frame):
    """Writes the checkpoint kept after `frame` into `folder` (a hidden file moved into
    place: a reader never sees half of it); returns its path, or None when the method keeps
    none."""
    import json
    if not solver.simulation.is_dynamic(methods.get(d.method)):
        return None
    e = solver.binding_of(obj, d)
    got = solver.simulation.export_checkpoint(e, frame)
    if got is None:
        raise solver.DeformKitError("no checkpoint of frame %d was kept" % frame)
    state, history = got
    meta = {"binding": _binding_id(obj, d, e), "frame": frame, "history": history.hex()}
    path = checkpoint_path(folder, obj, d, frame)
    part = os.path.join(folder, ".%s.%d.part" % (os.path.basename(path), os.getpid()))
    with open(part, "wb") as f:
        f.write(CHECKPOINT_MAGIC + json.dumps(meta).encode() + b"\n" + state)
    os.replace(part, path)
    return path


def add_mesh_cache(obj, d, path, frame_start, frame_end=None):
    """Adds (or updates) a Mesh Cache modifier reading `path`, in place of the deformer's GN
    modifier, which is hidden (kept for re-baking), and records the bake on `d`."""
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
    _record(d, "PC2", mc.name, frame_start, frame_end if frame_end is not None else frame_start,
            mc.filepath)
    return mc


def _record(d, kind, target, start, end, path=""):
    d.bake_kind = kind
    d.bake_target = target
    d.bake_start, d.bake_end = start, end
    if path:
        d.bake_file = path


def _key_name(d, prefix, f):
    return "%s f%04d" % (prefix or d.name, f)


def state(obj, d):
    """What shows in place of the live result: None when nothing is baked, else a dict
    kind ('PC2' or 'SHAPE_KEYS'), text (a sentence for the panel) and broken (the bake's
    modifier or keys were deleted by hand: Free Bake brings the live result back). Files
    saved before bakes were recorded are recognised by their Mesh Cache modifier's name."""
    kind, target = d.bake_kind, d.bake_target
    if kind == "NONE":
        legacy = obj.modifiers.get("%s Cache" % d.name)
        if legacy is None or legacy.type != "MESH_CACHE":
            return None
        kind, target = "PC2", legacy.name
    frames = "frames %d-%d" % (d.bake_start, d.bake_end) if d.bake_kind != "NONE" else "frames"
    if kind == "PC2":
        mc = obj.modifiers.get(target)
        if mc is None or mc.type != "MESH_CACHE":
            return dict(kind=kind, broken=True,
                        text="its Mesh Cache modifier '%s' was removed" % target)
        return dict(kind=kind, broken=False,
                    text="baked to %s (%s): edits don't show until you free the bake"
                    % (mc.filepath or "a point cache", frames))
    keys = obj.data.shape_keys
    n = 0 if keys is None else sum(1 for k in keys.key_blocks
                                   if k.name.startswith(target + " f"))
    if n == 0:
        return dict(kind=kind, broken=True, text="its baked shape keys were removed")
    return dict(kind=kind, broken=False,
                text="baked to %s (%s): edits don't show until you free the bake"
                % (plural(n, "shape key"), frames))


def free(obj, d):
    """Removes the bake (the Mesh Cache modifier, or the baked shape keys and their keyframes;
    a cache file on disk is kept) and shows the live result again. Returns what was freed."""
    st = state(obj, d)
    kind = st["kind"] if st else "NONE"
    target = d.bake_target or ("%s Cache" % d.name if kind == "PC2" else d.name)
    if kind == "PC2":
        mc = obj.modifiers.get(target)
        if mc is not None and mc.type == "MESH_CACHE":
            obj.modifiers.remove(mc)
    elif kind == "SHAPE_KEYS":
        keys = obj.data.shape_keys
        if keys is not None:
            names = [k.name for k in keys.key_blocks if k.name.startswith(target + " f")]
            for name in names:
                kb = keys.key_blocks[name]
                # its keyframes first (f-1, f, f+1, as bake_shape_keys keyed them): a removed
                # key block would leave its value curve behind; the last one deleted takes
                # the curve with it
                try:
                    f = int(name.rsplit(" f", 1)[1])
                except ValueError:
                    f = None
                for ff in (() if f is None else (f - 1, f, f + 1)):
                    try:
                        kb.keyframe_delete("value", frame=ff)
                    except RuntimeError:  # no keyframe there (edited by hand)
                        pass
                obj.shape_key_remove(kb)
            keys = obj.data.shape_keys
            if keys is not None and len(keys.key_blocks) == 1:
                obj.shape_key_clear()  # only the Basis the bake added is left
    gn = geonodes.find_modifier(obj, d)
    if gn is not None:
        gn.show_viewport = True
        gn.show_render = True
    d.bake_kind, d.bake_target = "NONE", ""
    solver.mark_settings_changed()
    return kind


def _animated(idd):
    """True when the ID has an action or drivers, or (objects) a parent that does."""
    seen = 0
    while idd is not None and seen < 64:
        ad = getattr(idd, "animation_data", None)
        if ad is not None and (ad.action is not None or len(ad.drivers)):
            return True
        idd = getattr(idd, "parent", None)
        seen += 1
    return False


def _moved_by_others(c):
    """Whether a modifier of `c` (a lattice's or cage's Hook or Armature) takes an object that
    is animated."""
    for m in getattr(c, "modifiers", ()):
        o = getattr(m, "object", None)
        if o is not None and _animated(o):
            return True
    return False


def animated_reason(obj, d):
    """Why the deformer's result changes over time without a bake, or None: a keyed (or
    driven) handle target, the object itself, or its Factor. A file opened without the
    add-on shows one frozen pose then (the last solve stays in its attribute), so the panel
    asks for a bake before the file goes to a render farm."""
    for h in d.handles:
        if h.target is not None and _animated(h.target):
            return "handle '%s' follows the animated '%s'" % (h.name, h.target.name)
    c = d.control_object
    if c is not None and (_animated(c) or _animated(c.data) or _animated(
            getattr(c.data, "shape_keys", None)) or _moved_by_others(c)):
        return "its control '%s' is animated" % c.name
    mod = geonodes.find_modifier(obj, d)
    ad = obj.animation_data
    if mod is not None and ad is not None:
        path = geonodes.factor_data_path(mod)
        if any(fc.data_path == path for fc in ad.drivers):
            return "its Factor is driven"
        try:
            if ad.action is not None and compat.action_animates(ad.action, path):
                return "its Factor is keyed"
        except (AttributeError, TypeError):  # an action layout this code does not know
            pass
    if _animated(obj):
        return "'%s' itself is animated" % obj.name
    return None


def hidden_reason(obj, d):
    """Why nothing shows the deformer's live result although no bake replaced it, or None:
    its modifier is missing, or off in both the viewport and renders."""
    mod = geonodes.find_modifier(obj, d)
    if mod is None:
        return "its Geometry Nodes modifier was removed: press Restore Modifier"
    if not (mod.show_viewport or mod.show_render) and state(obj, d) is None:
        return "its modifier '%s' is off in the viewport and in renders" % mod.name
    return None


# The bakes under way, by deformer uid (their SetAside; weak: a bake Blender dropped, with
# its modal operator, at a file load, does not hold its deformer).
_under_way = weakref.WeakValueDictionary()


def check_not_baking(d):
    """Refuses a bake of `d` while another bake of it runs (the window stays live during a
    modal bake): the second would set aside what the first set aside, and put it back over
    the first one's result."""
    a = _under_way.get(d.uid)
    if a is not None and not a.done:
        raise solver.DeformKitError("'%s' is being baked: wait for that bake, or press Esc "
                                    "to cancel it" % d.name)


class SetAside:
    """An earlier bake of `d`, set aside while a new bake runs (after its checks): the
    deformer's own modifier shown (the bake reads its input there: a rig's pose), and when
    the new bake replaces it by another kind (or it is broken), its shape keys muted (they
    would shape the deformer's input) and its Mesh Cache hidden (it would hide new shape
    keys). commit() frees such a bake for good once the new one is written (a point cache
    baked again to a point cache keeps its modifier, which the new file then replaces, and
    its hidden modifier); restore() puts everything back when the bake is cancelled or
    fails, so that neither loses the earlier bake."""

    def __init__(self, obj, d, kind, register=True):
        self.obj_name, self.uid, self.saved, self.done = obj.name, d.uid, [], False
        if register:  # what check_not_baking looks for
            _under_way[d.uid] = self
        st = state(obj, d)
        self.frees = st is not None and not (st["kind"] == "PC2" and kind == "PC2"
                                             and not st["broken"])
        if st is None:
            return
        if self.frees:
            target = d.bake_target or ("%s Cache" % d.name if st["kind"] == "PC2" else d.name)
            keys = obj.data.shape_keys
            if st["kind"] == "SHAPE_KEYS" and keys is not None:
                for kb in keys.key_blocks:
                    if kb.name.startswith(target + " f"):
                        self._set(("key", kb.name), "mute", True)
            if st["kind"] == "PC2":
                mc = obj.modifiers.get(target)
                if mc is not None and mc.type == "MESH_CACHE":
                    self._set(("modifier", mc.name), "show_viewport", False)
                    self._set(("modifier", mc.name), "show_render", False)
        gn = geonodes.find_modifier(obj, d)
        if gn is not None:
            self._set(("modifier", gn.name), "show_viewport", True)
            self._set(("modifier", gn.name), "show_render", True)

    def _lookup(self, obj, where):
        kind, name = where
        if kind == "key":
            keys = obj.data.shape_keys
            return None if keys is None else keys.key_blocks.get(name)
        return obj.modifiers.get(name)

    def _set(self, where, attr, value):
        item = self._lookup(self._objects()[0], where)
        self.saved.append((where, attr, getattr(item, attr)))
        setattr(item, attr, value)

    def _objects(self):
        """The object and deformer, by name, else by the deformer's uid (renamed meanwhile:
        the modal bake then stops, and this restores it all the same)."""
        named = bpy.data.objects.get(self.obj_name)
        for obj in [named] + [o for o in bpy.data.objects if o != named]:
            for d in (getattr(obj, "deformkit", None).deformers
                      if obj is not None and obj.type == "MESH" else ()):
                if d.uid == self.uid:
                    return obj, d
        return named, None

    def commit(self):
        """The new bake is written: frees the earlier one (its keys, its Mesh Cache), or
        puts back what a point cache baked again keeps."""
        obj, d = self._objects()
        if self.frees and d is not None:
            free(obj, d)
            self.saved = []
        self.restore()

    def restore(self):
        """The new bake was cancelled or failed: the earlier bake as it was."""
        obj, _ = self._objects()
        for where, attr, value in reversed(self.saved if obj is not None else []):
            item = self._lookup(obj, where)
            if item is not None:
                setattr(item, attr, value)
        self.frees, self.saved, self.done = False, [], True


def protected_files(obj, d):
    """(path, why) of the files a bake of `d` must never replace: the open .blend, its linked
    libraries, and the caches that other Mesh Cache modifiers play (the one of `d`'s own
    point-cache bake excepted: baking again replaces it). A cache path outside these is
    still only replaced when it is a PC2 file (pc2.check_target)."""
    out = []
    if bpy.data.filepath:
        out.append((bpy.data.filepath, "the open .blend file"))
    for lib in bpy.data.libraries:
        out.append((bpy.path.abspath(lib.filepath), "the linked library '%s'" % lib.name))
    st = state(obj, d)
    own = obj.modifiers.get(d.bake_target or "%s Cache" % d.name) \
        if st is not None and st["kind"] == "PC2" and not st["broken"] else None
    for o in bpy.data.objects:
        for m in getattr(o, "modifiers", ()):
            if m.type == "MESH_CACHE" and m.filepath and not (own is not None and m == own):
                out.append((bpy.path.abspath(m.filepath, library=o.library),
                            "the cache that '%s' plays (its modifier '%s')" % (o.name, m.name)))
    return out


def check_cache_path(obj, d, path):
    """The real path a point-cache bake of `d` writes to, or DeformKitError saying why `path`
    cannot take it (pc2.check_target with protected_files). Changes nothing."""
    try:
        return pc2.check_target(path, protected_files(obj, d))
    except pc2.PC2Error as e:
        raise solver.DeformKitError(str(e)) from None


class PC2Bake:
    """A bake to a PC2 file, frame by frame (the synchronous bake and the modal operator
    share it): step() solves and writes the next frame (into a hidden file beside `path`,
    pc2.Writer); finish(True) puts the file in place (and with `add_cache` adds the Mesh
    Cache that plays it), finish(False) drops it. finish runs once. The path is checked
    before anything changes: a path that is not a point cache (the .blend, a folder, a
    device, another object's cache) is refused with a DeformKitError, leaving the scene,
    any earlier bake and the file as they were."""
    kind = "PC2"

    def __init__(self, context, obj, d, frame_start, frame_end, path, add_cache=True):
        check_not_baking(d)
        protect = protected_files(obj, d)
        check_cache_path(obj, d, path)
        self.add_cache = add_cache
        self.path, self.protect = path, protect
        self.start, self.end = frame_start, frame_end
        self.fb = FrameBaker(context, obj, d, frame_start, frame_end)
        try:
            self.w = pc2.Writer(path, len(obj.data.vertices), start=frame_start,
                                protect=protect)
        except pc2.PC2Error as e:
            self.fb.finish()
            raise solver.DeformKitError(str(e)) from None
        except BaseException:
            self.fb.finish()
            raise
        self.aside = SetAside(obj, d, "PC2")

    @property
    def done(self):
        return self.fb.done

    def _add(self, pos):
        try:
            self.w.add(np.asarray(pos, dtype=np.float32))
        except pc2.PC2Error as e:
            raise solver.DeformKitError(str(e)) from None

    def step(self):
        f, pos = self.fb.step()
        self._add(pos)
        return f

    def step_async(self):
        """The modal bake's tick (FrameBaker.step_async): the frame baked, or None."""
        r = self.fb.step_async()
        if r is None:
            return None
        self._add(r[1])
        return r[0]

    def finish(self, ok):
        self.fb.finish()
        if not ok:
            self.w.abort()
            self.aside.restore()
            return None
        try:
            self.w.close()
        except pc2.PC2Error as e:
            self.aside.restore()
            raise solver.DeformKitError(str(e)) from None
        self.aside.commit()
        if self.add_cache:
            obj, d = self.fb._objects()
            add_mesh_cache(obj, d, self.path, self.start, self.end)
        return "baked %s to %s" % (plural(len(self.fb.frames), "frame"), self.path)


class ShapeKeyBake:
    """A bake to shape keys, frame by frame: step() solves the next frame; finish(True) adds
    one shape key per frame, keyed to 1 on its frame and 0 on the neighbours."""
    kind = "SHAPE_KEYS"

    def __init__(self, context, obj, d, frame_start, frame_end):
        solver.check_single_user(obj, "bake %s to shape keys" % d.name)
        check_not_baking(d)
        keys = obj.data.shape_keys
        if keys is not None and not keys.use_relative:
            raise solver.DeformKitError(
                "cannot bake %s to shape keys: the mesh's shape keys are absolute (Relative "
                "is off), which would play the baked keys as a sequence, not by frame; bake "
                "to Point Cache instead" % d.name)
        above = animated_input.modifiers_above(obj, d)
        if above:
            raise solver.DeformKitError(
                "cannot bake %s to shape keys: its input is moved by %s above it, which "
                "would move the baked shapes again; bake to Point Cache instead"
                % (d.name, ", ".join("'%s'" % m.name for m in above)))
        self.context, self.start, self.end = context, frame_start, frame_end
        self.fb = FrameBaker(context, obj, d, frame_start, frame_end)
        self.results, self.basis = [], None
        self.aside = SetAside(obj, d, "SHAPE_KEYS")

    @property
    def done(self):
        return self.fb.done

    def _keep(self, f, pos):
        """Keeps frame f's key: what the modifier showed less what reached it, on the Basis.
        Other shape keys above the deformer add up with the baked one on playback, so the
        key holds the deformer's offset alone (shown - input), not their mix again."""
        obj, d = self.fb._objects()
        inp = animated_input.moved_input(obj, d)
        pos = np.asarray(pos, dtype=np.float64)
        if inp is not None:
            if self.basis is None:  # read once: no frame of the bake changes it
                basis = np.empty(3 * len(obj.data.vertices), dtype=np.float32)
                keys = obj.data.shape_keys
                (keys.reference_key.data if keys is not None else obj.data.vertices).foreach_get(
                    "co", basis)
                self.basis = basis.reshape(-1, 3)
            pos = self.basis + (pos - inp)
        self.results.append((f, pos.astype(np.float32)))

    def step(self):
        f, pos = self.fb.step()
        self._keep(f, pos)
        return f

    def step_async(self):
        """The modal bake's tick (FrameBaker.step_async): the frame baked, or None."""
        r = self.fb.step_async()
        if r is None:
            return None
        self._keep(*r)
        return r[0]

    def finish(self, ok):
        self.fb.finish()
        if not ok:
            self.aside.restore()
            return None
        self.aside.commit()
        obj, d = self.fb._objects()
        prefix = d.name
        if obj.data.shape_keys is None:
            obj.shape_key_add(name="Basis", from_mix=False)
        for f, pos in self.results:
            kname = _key_name(d, prefix, f)
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
        _record(d, "SHAPE_KEYS", prefix, self.start, self.end)
        # the keyframes were inserted after this frame was evaluated: evaluate it again, or
        # the mesh shows no key (the rest shape) until the frame changes, as if the bake had
        # failed
        self.context.scene.frame_set(self.context.scene.frame_current)
        return "baked %s to shape keys" % plural(len(self.results), "frame")


def run(job, progress=None):
    """Runs a PC2Bake or ShapeKeyBake to the end (progress(i, n, frame) per frame); on any
    error the partial bake is dropped and the error raised. Returns the finish message."""
    try:
        while not job.done:
            f = job.step()
            if progress is not None:
                progress(job.fb.i, len(job.fb.frames), f)
    except BaseException:
        job.finish(False)
        raise
    return job.finish(True)


def bake_pc2(context, obj, d, frame_start, frame_end, path, progress=None, add_cache=False):
    """Synchronous bake of frames [start, end] to `path` (with `add_cache`, and its Mesh
    Cache modifier); progress(i, n, frame) per frame. Returns `path`."""
    run(PC2Bake(context, obj, d, frame_start, frame_end, path, add_cache), progress)
    return path


def bake_shape_keys(context, obj, d, frame_start, frame_end, progress=None):
    """One shape key per frame, keyed to 1 on its frame and 0 on the neighbours. Returns the
    number of frames."""
    job = ShapeKeyBake(context, obj, d, frame_start, frame_end)
    run(job, progress)
    return len(job.results)
