"""Persistent handlers: re-solve when inputs change, on frame change; reset on load/undo.

- Re-entrancy guarded (our attribute writes trigger another depsgraph update, which re-enters
  here; the guard plus "inputs unchanged -> skip" in solver.solve means it never loops).
- Vertex groups are re-read only when the deformed object's geometry was updated (weight
  paint, edit mode exit, group assignment), since that read is O(n). Our own attribute writes
  never reach the handler as such an update: Blender evaluates a depsgraph callback's tags
  in a second pass without callbacks, and the refine timer evaluates its writes itself,
  guarded, right after evaluating whatever was pending before them (see refine()); the same
  holds for the topology check below.
- No bpy references are kept: objects are looked up by name each time.
- Before solving, a deformer id seen on two objects (a Shift+D or Alt+D copy) is made the
  copy's own (solver.ensure_own_uid). The mesh topology is checked in full (the fingerprint
  stored at bind) headless, and in the UI on every geometry update of the object (the
  add-on's own attribute writes bring none: measured, test_addon_probe), after Edit or
  Sculpt Mode and after undo; Blender 3.6+ also compares the mesh's corner attributes on
  every solve (solver.check_topology).
- UI updates of iterative methods (ARAP) solve within a time budget; the `refine` timer
  finishes them once the handles stop, so dragging stays interactive and the result still
  converges. Frame changes, bakes, scripts and blender -b always solve to convergence, and so
  does the first solve of each deformer after an undo or redo (solver.mark_all_dirty).
- The panel says "refining..." while a shown result is pending (solver.refining): the
  Properties editor is redrawn whenever the set of pending solves changes.
"""

import time

import bpy
from bpy.app.handlers import persistent

from . import compat, geonodes, solver

_busy = [False]
enabled = [True]   # tests and the benchmark may switch automatic solving off
# Weight Paint: every sample of a stroke changes a group, and re-binding on each (8 re-binds
# and 41 ARAP solves for one 12-move stroke, the surface moving under the brush: the second
# hostile review) is replaced by one re-bind once the stroke has settled: the objects whose
# groups changed while painting, with the time of the last change (settle_paint)
PAINT_SETTLE_S = 0.3
_painted = {}
# UI-style (time-budgeted) solves also under blender -b, where no timer runs: for the latency
# benchmark, which then calls refine() itself
force_interactive = [False]


def _deformed_objects(scene):
    for obj in scene.objects:
        if obj.type == "MESH":
            dks = getattr(obj, "deformkit", None)
            if dks is not None and len(dks.deformers):
                yield obj


def _redraw_if_changed(before):
    """Redraws the Properties editor when the pending solves changed (the panel's
    "refining..." line); a no-op without windows (blender -b)."""
    if set(solver.pending()) == before:
        return
    wm = getattr(bpy.context, "window_manager", None)
    for win in (wm.windows if wm is not None else ()):
        for area in win.screen.areas:
            if area.type == "PROPERTIES":
                area.tag_redraw()


def _run(scene, depsgraph, cold=False):
    if _busy[0] or not enabled[0]:
        return
    _busy[0] = True
    before = set(solver.pending())
    try:
        geometry = set()
        if depsgraph is not None:
            for u in depsgraph.updates:
                if u.is_updated_geometry:
                    idd = u.id
                    if isinstance(idd, bpy.types.Object):
                        geometry.add(idd.name)
                    elif isinstance(idd, bpy.types.Mesh):
                        geometry.add(("mesh", idd.name))
        ui = force_interactive[0] or not bpy.app.background
        objs = list(_deformed_objects(scene))
        _claim_duplicates(objs)
        any_deformed = bool(objs)
        for obj in objs:
            if obj.mode in ("EDIT", "SCULPT"):
                # modes that may change the topology: checked in full once out of them
                solver.mark_unverified(obj)
                if obj.mode == "EDIT":
                    continue
            changed = (obj.name in geometry or ("mesh", obj.data.name) in geometry)
            if changed and obj.mode == "WEIGHT_PAINT" and ui:
                # a stroke's weights: keep the binding (and the surface) as it is until the
                # stroke has settled, then re-bind once (settle_paint)
                _painted[obj.name] = time.monotonic()
                if not bpy.app.timers.is_registered(settle_paint):
                    bpy.app.timers.register(settle_paint, first_interval=PAINT_SETTLE_S)
                continue
            # re-read groups on every geometry update of the object, ours included: skipping
            # our own writes could hide a group edit made in the same update. Not on a frame
            # change: an Armature (any animation above the deformer) updates the object's
            # and the mesh's geometry on every frame, and the read, O(group memberships) in
            # Python, took 111 ms of a 125 ms frame on the rigged armadillo
            # (scripts/bench_animated.py); a group edit has its own update, the names are
            # checked on every solve, and a bake's first frame re-reads them
            check = changed and not cold
            # the topology: headless always, in the UI (drags, playback) on every geometry
            # update of the object (solver.check_topology: Blender 3.6+ compare three
            # attributes on every solve anyway, 3.4-3.5 read every corner)
            solver.evaluate_object(obj, depsgraph, check_groups=check, cold=cold,
                                   interactive=not cold and ui,
                                   check_topology=not ui or changed)
        if cold and depsgraph is not None and any_deformed:
            # Frame change: this depsgraph (the viewport's or a render's) may have been
            # evaluated before the offsets were written (here, or by the handler call of
            # another depsgraph for the same frame); re-evaluate what is tagged so this frame
            # shows this frame's solve. A no-op when nothing is tagged.
            depsgraph.update()
        if not cold and solver.pending() and not bpy.app.timers.is_registered(refine):
            bpy.app.timers.register(refine, first_interval=0.001)
        if solver.rebinding() and not bpy.app.timers.is_registered(poll_rebinds):
            bpy.app.timers.register(poll_rebinds, first_interval=0.05)
        _redraw_if_changed(before)
    except Exception as ex:  # a handler must never raise
        print("DeformKit handler error: %s: %s" % (type(ex).__name__, ex))
    finally:
        _busy[0] = False


def _flush_updates():
    """Evaluates the context's view layer (a no-op when nothing is tagged)."""
    view_layer = getattr(bpy.context, "view_layer", None)
    if view_layer is None:
        return
    try:
        view_layer.update()
    except Exception as ex:  # a timer must never raise
        print("DeformKit refine error: %s: %s" % (type(ex).__name__, ex))


def _claim_duplicates(objs):
    """A deformer id seen on two objects of the scene (Shift+D, Alt+D): the copy gets its
    own (solver.ensure_own_uid), also when its modifier is hidden and it is not solved."""
    seen = {}
    for obj in objs:
        for d in obj.deformkit.deformers:
            seen.setdefault(d.uid, []).append((obj, d))
    for holders in seen.values():
        if len(holders) > 1:
            for obj, d in holders:
                solver.ensure_own_uid(obj, d)


def settle_paint():
    """Timer: once no group of a painted object has changed for PAINT_SETTLE_S and no paint
    stroke is running (4.2+ can tell), its deformers read their groups again: one re-bind
    per stroke, in a worker thread as any group change. Returns the next interval, or None
    when nothing is left."""
    if not _painted:
        return None
    if compat.painting():
        return PAINT_SETTLE_S / 3.0
    now = time.monotonic()
    due = [n for n, t in _painted.items() if now - t >= PAINT_SETTLE_S]
    if not due:
        return PAINT_SETTLE_S / 3.0
    # as refine(): what is pending first with the handler live, then our writes guarded
    _flush_updates()
    _busy[0] = True
    try:
        depsgraph = bpy.context.evaluated_depsgraph_get()
        for name in due:
            _painted.pop(name, None)
            obj = bpy.data.objects.get(name)
            if obj is None or obj.type != "MESH":
                continue
            solver.evaluate_object(obj, depsgraph, check_groups=True, interactive=True,
                                   check_topology=False)
        _flush_updates()  # our writes only: the handler is guarded (_busy)
    except Exception as ex:  # a timer must never raise
        print("DeformKit paint error: %s: %s" % (type(ex).__name__, ex))
    finally:
        _busy[0] = False
    if solver.rebinding() and not bpy.app.timers.is_registered(poll_rebinds):
        bpy.app.timers.register(poll_rebinds, first_interval=0.05)
    if solver.pending() and not bpy.app.timers.is_registered(refine):
        bpy.app.timers.register(refine, first_interval=0.001)
    return PAINT_SETTLE_S / 3.0 if _painted else None


def refine():
    """Timer: continues the interactive solves that stopped at their time budget (ARAP while
    dragging), one budget per tick, until they converge; a new drag just updates the targets
    they converge to. The UI stays live between ticks. Returns the next interval, or None."""
    if not enabled[0]:
        return None
    if _busy[0]:
        return 0.05
    keys = solver.pending()
    if not keys:
        return None
    working = set(solver.working())
    if all(k in working or solver.settling(k) for k in keys):
        # solves running in worker threads (polled), or previews while the handles still
        # move (their full results wait)
        return 0.02 if working else 0.05
    keys = [k for k in keys if not solver.settling(k) and k not in working]
    # Our own attribute writes must not cost a vertex-group re-read (a Python pass over every
    # vertex: ~30 ms at 43k, ~0.5 s at 692k). A write from the depsgraph handler never does:
    # Blender evaluates what a depsgraph_update_post callback tagged at once, in a second pass
    # without callbacks. A write from this timer would reach the handler with the next main
    # loop's update, merged with whatever the artist did meanwhile, so the handler cannot
    # tell it apart and re-reads. Hence here: (1) evaluate what is pending *before* the
    # write, with the handler live (anyone else's group or mesh edit is handled as always),
    # (2) solve and write, (3) evaluate again with the handler guarded, in this same call,
    # where nothing but our write can have happened since (1).
    _flush_updates()
    _busy[0] = True
    before = set(solver.pending())
    try:
        try:
            depsgraph = bpy.context.evaluated_depsgraph_get()
        except Exception:
            depsgraph = None
        for name in {k[0] for k in keys}:
            obj = bpy.data.objects.get(name)
            if obj is None or obj.mode == "EDIT":
                for k in keys:
                    if k[0] == name:
                        solver.drop_pending(k)
                continue
            solver.evaluate_object(obj, depsgraph, interactive=True, refine=True,
                                   only={k[1] for k in keys if k[0] == name})
        _flush_updates()  # our writes only: the handler is guarded (_busy)
        _redraw_if_changed(before)
    except Exception as ex:  # a timer must never raise either
        print("DeformKit refine error: %s: %s" % (type(ex).__name__, ex))
        return None
    finally:
        _busy[0] = False
    return 0.001 if solver.pending() else None


def poll_rebinds():
    """Timer: installs the option and method re-binds that finished in their worker threads
    (solver.finish_rebinds; their objects then re-solve on the next update), and redraws the
    panels meanwhile so that the elapsed time shows. Returns the next interval, or None."""
    try:
        solver.finish_rebinds()
        now = time.monotonic()
        if now - _panels_redrawn[0] >= PANEL_REDRAW_S or not solver.rebinding():
            _panels_redrawn[0] = now
            _redraw_panels()
    except Exception as ex:  # a timer must never raise
        print("DeformKit re-bind error: %s: %s" % (type(ex).__name__, ex))
        return None
    return 0.1 if solver.rebinding() else None


# How often the panels showing a running re-bind's time and phase are redrawn. Only the
# panels' regions are: redrawing the whole 3D View every 0.1 s (as before) drew the mesh ten
# times a second for the re-bind's whole length, taking a core from it (EigenDeformation's
# re-bind at 43k vertices took about a minute in the UI, 7 s without it: the second hostile
# review)
PANEL_REDRAW_S = 0.25
_panels_redrawn = [0.0]


def _redraw_panels():
    """Tags the regions the DeformKit panels live in: the Properties editor, and the 3D View's
    sidebar (not its viewport)."""
    wm = getattr(bpy.context, "window_manager", None)
    for win in (wm.windows if wm is not None else ()):
        for area in win.screen.areas:
            if area.type == "PROPERTIES":
                area.tag_redraw()
            elif area.type == "VIEW_3D":
                for region in area.regions:
                    if region.type == "UI":
                        region.tag_redraw()


@persistent
def on_depsgraph_update(scene, depsgraph=None):
    _run(scene, depsgraph)


@persistent
def on_frame_change(scene, depsgraph=None):
    # cold solves: a frame shows exactly what a bake or a render farm chunk computes for it
    _run(scene, depsgraph, cold=True)


@persistent
def on_load(*_args):
    solver.clear_cache()
    geonodes.watch_factor_edits()


@persistent
def on_undo(*_args):
    # re-check everything, and solve each deformer in full before it shows again
    solver.mark_all_dirty()
    geonodes.watch_factor_edits()


def _watch_after_register():
    # registration runs where bpy.data is not readable yet: the first timer tick can
    geonodes.watch_factor_edits()
    return None


_HANDLERS = (
    (bpy.app.handlers.depsgraph_update_post, on_depsgraph_update),
    (bpy.app.handlers.frame_change_post, on_frame_change),
    (bpy.app.handlers.load_post, on_load),
    (bpy.app.handlers.undo_post, on_undo),
    (bpy.app.handlers.redo_post, on_undo),
)


def register():
    for lst, fn in _HANDLERS:
        # remove stale copies (re-registration during development reloads the module)
        for old in [f for f in lst if getattr(f, "__name__", "") == fn.__name__
                    and getattr(f, "__module__", "") == fn.__module__]:
            lst.remove(old)
        lst.append(fn)
    bpy.app.timers.register(_watch_after_register, first_interval=0.0)


def unregister():
    for lst, fn in _HANDLERS:
        for old in [f for f in lst if getattr(f, "__name__", "") == fn.__name__
                    and getattr(f, "__module__", "") == fn.__module__]:
            lst.remove(old)
    bpy.msgbus.clear_by_owner(geonodes._WATCH_OWNER)
    _painted.clear()
    for timer in (refine, poll_rebinds, _watch_after_register, settle_paint):
        if bpy.app.timers.is_registered(timer):
            bpy.app.timers.unregister(timer)
    solver.clear_cache()
