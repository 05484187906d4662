"""Interactive (time-budgeted) solves without a window: the budget's arithmetic, a drag
update of ARAP's Newton solver cut to one step of few CG iterations that the refine steps
still bring to the minimum of one uninterrupted solve, the "refining" flag the panel shows,
and undo/redo converging before they show. The UI path (timer, window) is in
test_addon_modal.py and test_addon_undo.py; no timing is asserted here: the budget is set so
small that no machine fits a full Newton step in it."""
import os
import time
import sys
sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
import _setup as S  # noqa: E402
import bpy  # noqa: E402
import numpy as np  # noqa: E402
from mathutils import Euler  # noqa: E402

R = S.Results("test_addon_interactive")


def arap_grid(nx=40, ny=20):
    S.reset_scene()
    obj, d, e, fixed, handle = S.grid_setup("ARAP", nx=nx, ny=ny)
    bpy.ops.deformkit.bind()
    return obj, d, e, fixed, handle, (obj.name, d.uid)


class budget:
    """INTERACTIVE_BUDGET_MS set for a block, and UI-style solves under blender -b."""

    def __init__(self, ms):
        self.ms = ms

    def __enter__(self):
        self.old = S.solver.budget.INTERACTIVE_BUDGET_MS
        S.solver.budget.INTERACTIVE_BUDGET_MS = self.ms
        S.handlers.force_interactive[0] = True

    def __exit__(self, *exc):
        S.solver.budget.INTERACTIVE_BUDGET_MS = self.old
        S.handlers.force_interactive[0] = False


def refine_all():
    n = 0
    while S.handlers.refine() is not None and n < 100000:
        n += 1
    return n



def test_a_frame_after_a_drag_shows_what_a_bake_writes():
    """Playback and bakes agree: after UI-style drag updates (warm, time-budgeted, previews),
    a frame change shows exactly the cold solve a bake writes for that frame, for every
    method. The frame handler's "inputs unchanged" shortcut kept the drag's result (the
    second hostile review: ARAP 2.6e-5 of the diagonal off, EmbeddedDeformation 1e-3,
    EigenDeformation its Steps 1-2 preview)."""
    for m in S.handle_methods():
        S.reset_scene()
        obj, d, e, fixed, handle = S.grid_setup(m.id, nx=24, ny=10)
        bpy.ops.deformkit.bind()
        with budget(1e-6):   # drag updates: budgeted slices, previews, warm starts
            for k in range(4):
                e.location.z += 0.08
                e.rotation_euler = Euler((0.1 * k, 0.0, 0.0))
                bpy.context.view_layer.update()
        sc = bpy.context.scene
        sc.frame_set(sc.frame_current)       # a frame change (playback, scrubbing, a render)
        shown = S.evaluated_positions(obj)
        bake = S.solver.deformed_positions(obj, d, bpy.context.evaluated_depsgraph_get())
        rest = S.rest_positions(obj)
        size = np.linalg.norm(rest.max(0) - rest.min(0))
        err = np.abs(shown - bake).max() / size
        R.check("%s: the frame after a drag shows the bake's cold solve (%.1e of the size)"
                % (m.id, err), err < 1e-6, err)


def test_a_weight_paint_stroke_rebinds_once_and_keeps_the_surface():
    """Painting a group a bound deformer reads: every sample of a stroke is a group change,
    and each re-bound and re-solved (8 re-binds and 41 ARAP solves for one 12-move stroke,
    the surface moving under the brush: the second hostile review). Now the stroke's changes
    leave the binding and the surface as they are; once the stroke has settled
    (handlers.settle_paint, a timer) the groups are read again: one re-bind."""
    obj, d, e, fixed, handle, key = arap_grid(24, 12)
    e.location = (1.0, 0.1, 0.3)
    bpy.context.view_layer.update()
    S.solver.finish(obj, d)
    calls = {"rebind": 0}
    real_build = S.solver.binding._build

    def counting_build(*a, **kw):
        calls["rebind"] += 1
        return real_build(*a, **kw)
    S.solver.binding._build = counting_build
    try:
        with budget(S.solver.budget.INTERACTIVE_BUDGET_MS):
            bpy.ops.object.mode_set(mode="WEIGHT_PAINT")
            before = S.evaluated_positions(obj)
            vg = obj.vertex_groups[d.fixed_group]
            extra = [j * 24 + 2 for j in range(12)]   # the column next to the fixed ones
            moved = 0.0
            for i in range(12):                       # a stroke of 12 samples
                vg.add([extra[i]], 1.0, "REPLACE")
                bpy.context.view_layer.update()
                moved = max(moved, float(np.abs(S.evaluated_positions(obj) - before).max()))
            R.check("a stroke of 12 samples: no re-bind while it runs", calls["rebind"] == 0,
                    calls)
            R.check("... and the surface does not move under the brush (%.1e)" % moved,
                    moved == 0.0)
            time.sleep(S.handlers.PAINT_SETTLE_S + 0.05)
            while S.handlers.settle_paint() is not None:
                time.sleep(S.handlers.PAINT_SETTLE_S / 3)
            for _ in range(200):                      # the re-bind's worker thread
                if not S.solver.rebinding():
                    break
                time.sleep(0.02)
            S.solver.finish_rebinds()
            bpy.ops.object.mode_set(mode="OBJECT")
            S.solver.finish(obj, d)
        R.check("the stroke settled: one re-bind", calls["rebind"] == 1, calls)
        T = S.handles.transforms(obj, d, bpy.context.evaluated_depsgraph_get())
        rest = S.rest_positions(obj)
        want = S.dk.ARAP(S.dk.Mesh(rest, S.solver.triangles(obj.data)), [handle],
                         fixed=np.r_[fixed, extra], tolerance=d.options.tolerance,
                         max_iterations=d.options.max_iterations)
        want = np.asarray(want.solve(transforms=T, warm_start=False).positions)
        err = np.abs(S.evaluated_positions(obj) - want).max()
        R.check("... and the result is the new groups' (%.1e)" % err, err < 1e-3)
    finally:
        S.solver.binding._build = real_build

def test_budget_arithmetic():
    """_budget: units that fit = budget / (a slice's time / its units), per kind of slice;
    an iteration with an inner count that does not fit whole is cut to fewer inner
    iterations; with room for several whole ones, several."""
    obj, d, e, fixed, handle, key = arap_grid(12, 6)
    ent = S.solver.cache._cache[key]
    B = S.solver.budget.INTERACTIVE_BUDGET_MS
    ent.slice_cost = {False: (B * 2.0, 1, 12)}  # a unit costs B/6
    R.check("a step that does not fit is cut to the inner iterations that do",
            S.solver.budget._budget(key, 100, 12, False) == (1, 6), S.solver.budget._budget(key, 100, 12, False))
    ent.slice_cost = {False: (B * 2.0, 1, 12), True: (B / 3.0, 1, 12)}  # a unit: B/36
    R.check("resumed slices use their own cost (3 whole steps fit)",
            S.solver.budget._budget(key, 100, 12, True) == (3, None), S.solver.budget._budget(key, 100, 12, True))
    R.check("... and the cap holds", S.solver.budget._budget(key, 2, 12, True) == (2, None))
    ent.slice_cost = {False: (B * 2.0, 1, 12)}
    R.check("settled refine steps (cut=False) take whole iterations",
            S.solver.budget._budget(key, 100, 12, True, cut=False) == (1, None))
    ent.slice_cost = {False: (B * 100.0, 1, 12)}
    R.check("at least one inner iteration", S.solver.budget._budget(key, 100, 12, False) == (1, 1))
    ent.slice_cost = {False: (B / 2.0, 3, 1)}
    R.check("methods without an inner count: whole iterations (6 fit)",
            S.solver.budget._budget(key, 100, 0, False) == (6, None), S.solver.budget._budget(key, 100, 0, False))
    m = S.methods.get("ARAP")
    R.check("ARAP Newton's inner count is its CG iterations",
            S.solver.inner_cap(m, d.options) == d.options.cg_iterations == 12)
    d.options.acceleration = "anderson"
    R.check("... and Anderson's iterations have none", S.solver.inner_cap(m, d.options) == 0)


def test_cheap_drag_step_converges_to_the_minimum():
    """A drag update whose budget fits no full Newton step takes one step of a single CG
    iteration and is left pending ("refining"); refine steps with the normal budget end
    converged at the minimum one uninterrupted solve reaches, to the solver's tolerance."""
    obj, d, e, fixed, handle, key = arap_grid()
    dg = bpy.context.evaluated_depsgraph_get()
    bind_T = S.handles.transforms(obj, d, dg)
    with budget(1e-6):
        e.location = (1.0, 0.1, 0.4)
        e.rotation_euler = Euler((0.0, -0.3, 0.0))
        bpy.context.view_layer.update()
        first = dict(S.solver.runtime.get(key, {}))
        R.check("the drag update is one Newton step of 1 CG iteration, unconverged",
                first.get("budgeted") and first.get("iterations") == 1
                and first.get("inner") == 1 and not first.get("converged"), first)
        R.check("it is pending and the panel's flag says refining",
                key in S.solver.pending() and S.solver.refining(obj, d))
    with budget(S.solver.budget.INTERACTIVE_BUDGET_MS):
        ticks = refine_all()
    last = S.solver.runtime.get(key, {})
    R.check("refine steps converge it (%d ticks)" % ticks,
            last.get("converged") and key not in S.solver.pending(), last)
    R.check("the flag is cleared once converged", not S.solver.refining(obj, d))
    got = S.evaluated_positions(obj)
    rest = S.rest_positions(obj)
    T = S.handles.transforms(obj, d, bpy.context.evaluated_depsgraph_get())
    ref = S.dk.ARAP(S.dk.Mesh(rest, S.solver.triangles(obj.data)), [handle], fixed=fixed,
                    tolerance=d.options.tolerance, max_iterations=d.options.max_iterations)
    ref.solve(transforms=bind_T, warm_start=False)
    r = ref.solve(transforms=T, warm_start=True)
    bbox = np.linalg.norm(rest.max(0) - rest.min(0))
    # the add-on skips the energy of its solves: the shown result's, evaluated here
    gap = abs(float(ref.energy(got)) - r.energy) / r.energy
    R.check("the same minimum as one uninterrupted solve: energy within 1e-5 (%.1e)" % gap,
            r.converged and gap <= 1e-5, (last.get("energy"), r.energy))
    err = np.abs(got - r.positions).max() / bbox
    R.check("... positions within 1e-3 of the bbox diagonal (%.1e)" % err, err < 1e-3)


def test_undo_converges_before_showing():
    """After on_undo (undo_post / redo_post) the next solve of a deformer is a full one even
    when UI updates are budgeted; the one after is a budgeted slice again."""
    obj, d, e, fixed, handle, key = arap_grid()
    with budget(1e-6):
        e.location = (1.0, 0.1, 0.4)
        bpy.context.view_layer.update()
        R.check("before: a budgeted slice, pending",
                S.solver.runtime[key]["budgeted"] and key in S.solver.pending())
        S.handlers.on_undo()
        R.check("on_undo: the deformer converges next", S.solver.converges_next(key))
        e.location = (1.0, 0.1, 0.45)
        bpy.context.view_layer.update()
        rt = dict(S.solver.runtime[key])
        R.check("the first solve after undo is full and converged",
                not rt["budgeted"] and rt["converged"] and key not in S.solver.pending()
                and not S.solver.refining(obj, d), rt)
        R.check("... once", not S.solver.converges_next(key))
        e.location = (1.0, 0.1, 0.5)
        bpy.context.view_layer.update()
        R.check("the next drag update is budgeted again", S.solver.runtime[key]["budgeted"]
                and key in S.solver.pending())
        # the same through evaluate_object directly, as the handler calls it, with nothing
        # moved since the undo (its check of the inputs is reset)
        S.handlers.on_undo()
        S.solver.evaluate_object(obj, bpy.context.evaluated_depsgraph_get(), interactive=True)
        rt = dict(S.solver.runtime[key])
        R.check("evaluate_object after on_undo re-solves in full", not rt["budgeted"]
                and rt["converged"] and key not in S.solver.pending(), rt)
    S.solver.clear_cache()


class counting_group_reads:
    """Counts solver.blender_data.read_groups calls (the O(n) vertex-group pass) within a block."""

    def __enter__(self):
        self.n, self.orig = 0, S.solver.blender_data.read_groups

        def counted(*a, **kw):
            self.n += 1
            return self.orig(*a, **kw)
        S.solver.blender_data.read_groups = counted
        return self

    def __exit__(self, *exc):
        S.solver.blender_data.read_groups = self.orig


def test_refine_ticks_do_not_reread_groups_but_see_edits():
    """A refine tick's own attribute write is evaluated within the tick, so the main loop's
    next update does not re-read the vertex groups for it (it did: ~30 ms a tick at 43k);
    a group edit made just before a tick, not yet evaluated, is still seen by the tick."""
    obj, d, e, fixed, handle, key = arap_grid()
    with budget(1e-6):
        e.location = (1.0, 0.1, 0.4)
        bpy.context.view_layer.update()
        R.check("a drag leaves the solve pending", key in S.solver.pending())
    with budget(S.solver.budget.INTERACTIVE_BUDGET_MS), counting_group_reads() as c:
        S.handlers.refine()
        bpy.context.view_layer.update()  # what the main loop evaluates after the tick
        R.check("a refine tick and the update after it read no vertex group (%d reads)" % c.n,
                c.n == 0, c.n)
        refine_all()
        R.check("... nor do the ticks to convergence (%d reads)" % c.n, c.n == 0, c.n)
    # a group edit right before a tick (tagged, not evaluated): a free vertex joins Fixed
    free = next(i for i in range(len(obj.data.vertices)) if i not in set(fixed) | set(handle))
    with budget(1e-6):
        e.location = (1.0, 0.1, 0.45)
        bpy.context.view_layer.update()
    with budget(S.solver.budget.INTERACTIVE_BUDGET_MS), counting_group_reads() as c:
        obj.vertex_groups["fixed"].add([free], 1.0, "REPLACE")
        obj.data.update_tag()
        S.handlers.refine()
        R.check("an edit pending before the tick is read by it (%d reads)" % c.n, c.n >= 1, c.n)
        refine_all()
    got = S.evaluated_positions(obj)
    rest = S.rest_positions(obj)
    R.check("... and the vertex that joined Fixed stays at rest",
            np.abs(got[free] - rest[free]).max() < 1e-6, got[free] - rest[free])
    S.solver.clear_cache()


class threaded_solves:
    """Interactive solves in worker threads (solver.workers._Worker) for a block, under blender -b."""

    def __enter__(self):
        S.solver.threaded_solves[0] = True
        S.handlers.force_interactive[0] = True

    def __exit__(self, *exc):
        S.solver.threaded_solves[0] = None
        S.handlers.force_interactive[0] = False


def refine_until_settled(limit_s=60.0):
    """handlers.refine() as the timer calls it, sleeping while solves run in threads."""
    import time
    t0 = time.monotonic()
    while time.monotonic() - t0 < limit_s:
        nxt = S.handlers.refine()
        if nxt is None:
            return True
        time.sleep(min(nxt, 0.005))
    return False


def shown_offset(obj, d):
    a = obj.data.attributes[d.attribute_name]
    off = np.empty(len(obj.data.vertices) * 3, dtype=np.float32)
    a.data.foreach_get("vector", off)
    return off.reshape(-1, 3)


def test_slow_solves_run_in_a_worker_thread():
    """With solves in worker threads (what the UI does for a solve slower than ASYNC_MS or a
    mesh of ASYNC_MIN_VERTICES), a drag update returns at once: ARAP's shows the last result
    moved by the response basis, Laplacian editing's writes nothing (the shown result
    stays); the refine timer installs the worker's result, and the end is the same minimum
    as one uninterrupted solve; a frame's cold solve while a worker runs waits for it."""
    for method in ("ARAP", "LAPLACIAN"):
        S.reset_scene()
        obj, d, e, fixed, handle = S.grid_setup(method, nx=60, ny=30)
        bpy.ops.deformkit.bind()
        key = (obj.name, d.uid)
        bind_T = S.handles.transforms(obj, d, bpy.context.evaluated_depsgraph_get())
        before = shown_offset(obj, d).copy()
        with threaded_solves():
            e.location = (1.0, 0.1, 0.4)
            e.rotation_euler = Euler((0.0, -0.3, 0.0))
            bpy.context.view_layer.update()
            ent = S.solver.cache._cache[key]
            if method == "ARAP":
                # the update shows the bind result moved by the response basis: the plain
                # warm start, which an independent object's preview gives
                T = S.handles.transforms(obj, d, bpy.context.evaluated_depsgraph_get())
                ref = S.dk.ARAP(S.dk.Mesh(S.rest_positions(obj), S.solver.triangles(obj.data)),
                                [handle], fixed=fixed, predict=False)
                ref.solve(transforms=bind_T, warm_start=False)
                want = np.asarray(ref.solve(transforms=T, preview=True, energy=False).positions)
                got = S.rest_positions(obj) + shown_offset(obj, d)
                err = np.abs(got - want).max()
                R.check("ARAP: the drag update started a worker and shows the basis preview "
                        "(%.1e from the native preview)" % err,
                        ent.worker is not None and err < 1e-5
                        and np.abs(got - S.rest_positions(obj)).max() > 0.05)
                # a second move while the worker runs: the preview follows the handle
                e.location = (1.1, 0.1, 0.45)
                bpy.context.view_layer.update()
                T2 = S.handles.transforms(obj, d, bpy.context.evaluated_depsgraph_get())
                busy = ent.worker is not None and ent.worker.thread.is_alive()
                ref.solve(transforms=bind_T, warm_start=False)
                want2 = np.asarray(ref.solve(transforms=T2, preview=True, energy=False).positions)
                got2 = S.rest_positions(obj) + shown_offset(obj, d)
                R.check("ARAP: ... and a move while it runs shows the preview for that move "
                        "(busy %s, %.1e)" % (busy, np.abs(got2 - want2).max()),
                        not busy or np.abs(got2 - want2).max() < 1e-5)
            else:
                R.check("%s: the drag update started a worker and wrote nothing yet" % method,
                        ent.worker is not None and np.array_equal(shown_offset(obj, d), before))
            R.check("%s: ... and the solve is pending (the panel says refining)" % method,
                    key in S.solver.pending() and S.solver.refining(obj, d))
            R.check("%s: the refine timer settles it" % method, refine_until_settled())
            R.check("%s: the worker's result is shown and recorded" % method,
                    not np.array_equal(shown_offset(obj, d), before)
                    and ent.slice_ms is not None and key not in S.solver.pending(),
                    S.solver.runtime.get(key))
        got = S.evaluated_positions(obj)
        rest = S.rest_positions(obj)
        T = S.handles.transforms(obj, d, bpy.context.evaluated_depsgraph_get())
        bbox = np.linalg.norm(rest.max(0) - rest.min(0))
        if method == "ARAP":
            ref, r = S.arap_reference(obj, d, handle, fixed, bind_T, T)
            gap = abs(float(ref.energy(got)) - r.energy) / r.energy
            R.check("ARAP: the same minimum as one uninterrupted solve (energy gap %.1e)" % gap,
                    r.converged and gap <= 1e-5)
        else:
            ref = S.solver.deformed_positions(obj, d)
            err = np.abs(got - ref).max() / bbox
            R.check("LAPLACIAN: the worker's result is the direct solve's (%.1e)" % err,
                    err < 1e-6)
        # a frame's cold solve while a worker is running: it waits, then solves in full
        with threaded_solves():
            e.location = (1.0, 0.2, 0.5)
            bpy.context.view_layer.update()
            started = S.solver.cache._cache[key].worker is not None
            try:
                cold = S.solver.deformed_positions(obj, d)
                err = None
            except S.solver.DeformKitError as ex:
                cold, err = None, ex
            R.check("%s: a cold solve during a worker's waits for it (no 'in use')" % method,
                    started and err is None, err)
            refine_until_settled()
        S.solver.clear_cache()
        S.handlers.enabled[0] = True
        ref_cold = S.solver.deformed_positions(obj, d)
        R.check("%s: ... and gives the cold result" % method,
                cold is not None and np.abs(cold - ref_cold).max() / bbox < 1e-6)
    S.solver.clear_cache()


# the stand-in module (DEFORMKIT_MOCK=1) converges every solve at once: the arithmetic only
MOCK = os.environ.get("DEFORMKIT_MOCK") == "1"
for t in (test_budget_arithmetic,) + (() if MOCK else (
        test_cheap_drag_step_converges_to_the_minimum, test_undo_converges_before_showing,
        test_refine_ticks_do_not_reread_groups_but_see_edits,
        test_slow_solves_run_in_a_worker_thread,
        test_a_frame_after_a_drag_shows_what_a_bake_writes,
        test_a_weight_paint_stroke_rebinds_once_and_keeps_the_surface)):
    R.run(t)
R.finish()
