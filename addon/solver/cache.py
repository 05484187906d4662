"""What the add-on keeps of each deformer's binding between updates, keyed by (object name,
deformer uid): the native objects, the last solve's figures, the serials that say what to
solve again, the running re-binds. Nothing here holds a bpy reference."""

import time

from . import budget


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
                 "fit_for", "fit_text", "native_source", "sim", "pose_deltas")


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


# (object name, deformer uid) -> dict(job, thread, t0, sig) of a re-bind running in a worker
# thread. An option or method change in the UI re-binds this way (0.4-0.75 s at 43k
# vertices, seconds on big meshes, used to freeze the handler); the last result stays shown
# meanwhile and the panel says "re-binding". Frames, bakes, scripts and blender -b bind
# synchronously: their result must be this frame's.
_rebinds = {}


def _cancel_rebinds(key=None):
    """Forgets the running re-binds (of `key`, or all): their results are dropped."""
    for k in [key] if key is not None else list(_rebinds):
        r = _rebinds.pop(k, None)
        if r is not None:
            r["job"].cancelled = True


def pending():
    """(object name, deformer uid) of the interactive solves left unconverged."""
    return [k for k, e in _cache.items() if e.pending]


def settling(key):
    """True while `key` shows a preview younger than PREVIEW_SETTLE_S (the handles may still
    be moving: its full result waits)."""
    e = _cache.get(key)
    return e is not None and e.preview_at > 0.0 and\
        time.monotonic() - e.preview_at < budget.PREVIEW_SETTLE_S


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


def working():
    """The keys whose solve is running in a worker thread."""
    return [k for k, e in _cache.items() if e.worker is not None and e.worker.thread.is_alive()]
