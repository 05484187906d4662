"""Native solves off the main thread: a slow interactive solve (_Worker) and a bake's frame
(FrameSolve, in resumable slices so that Esc stops it)."""

import time

import bpy

from ..errors import DeformKitError
from . import cache, calls, solving


# An interactive solve that takes longer than ASYNC_MS (its last run, or a mesh of at least
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
            self.result = calls._native_call(label + " solve", native_solve, **goal, **kw)
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
        # the solve's own cap, else the method's option (the native default it solves with)
        cap = int(kw.get("max_iterations") or plan.get("cap") or 0)

        def run():
            if not iterative or cap <= 0:
                self.result_ = calls._native_call(label + " solve", native_solve, **goal, **kw)
            else:
                done, its, first = 0, 1, True
                while True:
                    k = max(1, min(its, cap - done))
                    t1 = time.perf_counter()
                    res = calls._native_call(label + " solve", native_solve, **goal,
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
        if cache._cache.get(self.key) is not e:
            raise DeformKitError("'%s' was re-bound during the bake: bake again" % d.name)
        pos = solving._finish_solve(obj, d, e, self.key, self.plan, self.result_, self.ms)
        return solving.as_shown(obj, d, e, pos)


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


def _wait_for_worker(key):
    """Joins the key's worker (a frame, bake, Apply or re-check needs the native object):
    its result is installed by the solve that follows when still wanted."""
    e = cache._cache.get(key)
    if e is not None and e.worker is not None:
        e.worker.thread.join()
