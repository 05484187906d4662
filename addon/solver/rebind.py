"""Re-binds in a worker thread after an option, method or vertex-group change in the UI: the
last result stays shown meanwhile, and finish_rebinds installs the new binding."""

import time

import bpy

from .. import methods
from ..errors import DeformKitError
from . import binding, blender_data, cache, calls, controls, progress, status


threaded_rebinds = [None]  # None: in the UI only; True / False force it (tests)


class RebindPending(Exception):
    """The deformer's re-bind runs in a worker thread: nothing to solve yet."""


def _use_threads(interactive):
    force = threaded_rebinds[0]
    return force if force is not None else (interactive and not bpy.app.background)


def _rebind_in_thread(obj, d, kw, groups_key):
    import threading
    key = (obj.name, d.uid)
    sig = (d.method, controls.settings_key(d), groups_key)
    r = cache._rebinds.get(key)
    if r is not None and r["sig"] == sig:
        raise RebindPending()
    if r is not None:
        r["job"].cancelled = True  # settings changed again: its result will be dropped
    job = binding.BindJob(obj, d, kw, groups_key)  # main thread: reads Blender data
    th = threading.Thread(target=job.run, name="DeformKit re-bind", daemon=True)
    th.start()
    cache._rebinds[key] = dict(job=job, thread=th, t0=time.perf_counter(), sig=sig)
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


class GroupsRebindJob(progress.Reporting):
    """The native rebind of a bound entry for new constraint groups (same interface as
    BindJob: run() in any thread, entry(obj, d) on the main thread, progress_text())."""
    inplace = True

    def __init__(self, entry, m, kw, groups_key):
        self._entry, self.kw, self.groups = entry, kw, groups_key
        self.label = m.label
        self._with_progress = m.rebind_progress
        self.fraction, self.phase, self.cancelled = None, None, False
        self.error, self.seconds = None, 0.0

    def run(self):
        t0 = time.perf_counter()
        args = dict(handles=self.kw["handles"], fixed=self.kw["fixed"], roi=self.kw["roi"])
        if self._with_progress:
            args["progress"] = self._progress
        try:
            calls._native_call(self.label + " rebind", self._entry.native.rebind, **args)
        except DeformKitError as ex:
            self.error = ex
        except Exception as ex:  # a worker must not die silently
            self.error = DeformKitError("%s rebind: %s: %s" % (self.label, type(ex).__name__,
                                                                ex))
        self.seconds = time.perf_counter() - t0

    def entry(self, obj, d):
        if self.error is not None:
            raise self.error
        return binding._install_groups(self._entry, d, self.kw, self.groups)


def _groups_rebind_in_thread(obj, d, entry, kw, groups_key):
    import threading
    key = (obj.name, d.uid)
    sig = (d.method, controls.settings_key(d), groups_key)
    r = cache._rebinds.get(key)
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
    cache._rebinds[key] = dict(job=job, thread=th, t0=time.perf_counter(), sig=sig)
    raise RebindPending()


def _in_place_rebind(key):
    r = cache._rebinds.get(key)
    return r if r is not None and getattr(r["job"], "inplace", False) else None


def rebinding(obj=None, d=None):
    """Seconds since the running re-bind of (obj, d) started, or None; without arguments,
    whether any re-bind runs."""
    if obj is None:
        return bool(cache._rebinds)
    r = cache._rebinds.get((obj.name, d.uid))
    return None if r is None else time.perf_counter() - r["t0"]


def rebind_text(obj, d):
    """What the panel says about the running re-bind of (obj, d), or None."""
    r = cache._rebinds.get((obj.name, d.uid))
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
    for key, r in list(cache._rebinds.items()):
        if r["thread"].is_alive():
            continue
        del cache._rebinds[key]
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
                e = cache._cache.get(key)
                if e is not None:
                    # its native rebind may have run to the end: the entry's groups no longer
                    # say what the native object holds (a change back would not re-bind), and
                    # a simulation restarted there
                    e.verified, e.last_inputs, e.groups, e.sim = False, None, None, None
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
            blender_data.zero_offset(obj, d)
            status.set_status(d, ex, True)
            continue
        e.last_inputs = None
        status.reset_status(d)
        obj.update_tag()
    return done
