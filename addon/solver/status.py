"""What the panel says about a deformer: its status line, the last solve's figures and the
warning when the method cannot do this edit well."""

import numpy as np

from .. import methods
from ..errors import OverlapError
from ..text import plural
from . import cache, controls, simulation


def set_status(d, msg, is_error):
    """The deformer's status line; an OverlapError also records its two groups (the panel
    offers to select or remove the shared vertices), any other status clears them."""
    text = str(msg)
    if d.status != text:
        d.status = text
    if d.status_is_error != is_error:
        d.status_is_error = is_error
    groups = "\t".join(msg.groups) if isinstance(msg, OverlapError) else ""
    if d.status_overlap != groups:
        d.status_overlap = groups


def idle_status(d):
    """A deformer's status when nothing is wrong, composed from its state now (bound or not,
    its handles): the one place that words it. The panel draws it at draw time, so it follows
    handles added or removed since it was stored."""
    c = controls.of(d) if not controls.uses_handles(d) else None
    if c is not None:
        if d.bound:
            return "bound: %s to %s" % (plural(d.bind_n_vertices, "vertex"), c.summary(d))
        want = c.missing(d)
        return "not bound: %s, then Bind" % want if want else "not bound: press Bind"
    m = methods.get(d.method)
    if d.bound and m.poses is not None:   # a blend of poses: what it blends
        try:
            names = [kb.name for kb in methods.poses_reader(m).owned(d.id_data, d.options)]
        except Exception:  # a wrong key name: the solve reports it
            names = []
        what = ("blending %s" % ", ".join(names[:3]) + (" and %d more" % (len(names) - 3)
                                                         if len(names) > 3 else "")
                if names else "no shape key to blend")
        return "bound: %s, %s%s" % (plural(d.bind_n_vertices, "vertex"), what,
                                    ", %s" % plural(len(d.handles), "handle")
                                    if len(d.handles) else "")
    if d.bound:
        return "bound: %s, %s%s" % (plural(d.bind_n_vertices, "vertex"),
                                    plural(len(d.handles), "handle"),
                                    "; " + d.bind_summary if d.bind_summary else "")
    if len(d.handles) == 0 and m.needs_handles:
        return "not bound: add a handle, then Bind"
    return "not bound: press Bind"


def reset_status(d):
    """Stores the idle status, clearing an error."""
    set_status(d, idle_status(d), False)


def status_text(d):
    """What the panel shows: the stored error, else the idle status of the state now."""
    return d.status if d.status_is_error else idle_status(d)


# fit_warning's thresholds: handles off by more than this part of their move, or more than
# this part of the edges stretched (or shrunk) by more than half
FIT_HANDLE_PART = 0.02


FIT_STRETCH_PART = 0.01


def fit_warning(obj, d):
    """What the panel says when the method cannot do this edit well, with the method that
    can (Method.fit_check, better_method), or None. Read from the last settled result (none
    while refining or previewing), computed once per result: "handles" how far the handle
    vertices are from their targets against the move, "stretch" how many edges changed
    length by more than half. The second hostile review: Eigen Deformation's spike, the
    linear methods' swelling, shown as if they were fine."""
    m = methods.get(d.method)
    e = cache._cache.get((obj.name, d.uid))
    if (not m.fit_check or e is None or e.result_pos is None or e.result_T is None
            or e.pending or not d.bound):
        return None
    if e.fit_for is e.result_pos:
        return e.fit_text
    pos, T, src = e.result_pos, e.result_T, e.rest
    text = None
    if m.fit_check == "handles":
        worst = move = 0.0
        for idx, Ti in zip(e.handles, T):
            want = src[idx] @ Ti[:3, :3].T + Ti[:3, 3]
            worst = max(worst, float(np.linalg.norm(pos[idx] - want, axis=1).max()))
            move = max(move, float(np.linalg.norm(want - src[idx], axis=1).max()))
        if move > 1e-3 * max(e.extent, 1e-30) and worst > FIT_HANDLE_PART * move:
            text = ("%s meets its handles approximately: here %.0f%% of the move off the "
                    "target. %s meets them exactly" % (m.label, 100.0 * worst / move,
                                                        m.better_method))
    else:
        ed = np.asarray(e.dkmesh.edges)
        a = np.linalg.norm(src[ed[:, 0]] - src[ed[:, 1]], axis=1)
        b = np.linalg.norm(pos[ed[:, 0]] - pos[ed[:, 1]], axis=1)
        ok = a > 0
        bad = int((np.abs(b[ok] / a[ok] - 1.0) > 0.5).sum())
        if bad > FIT_STRETCH_PART * max(int(ok.sum()), 1):
            text = ("%s changes %s by more than half for this move: it moves the surface "
                    "without turning it, and stretches what should turn. %s keeps the "
                    "shape" % (m.label, plural(bad, "edge length"), m.better_method))
    e.fit_for, e.fit_text = pos, text
    return text


def solve_summary(obj, d):
    """The panel's line about the last solve, or None before one (or while the status is an
    error). Iterative methods: the time and iterations of the whole solve, its interactive
    slices summed, and "(not converged)" when it stopped at Max Iterations short of its
    tolerance (not while the timer is still refining it). Direct methods: the time only;
    they never say "not converged" (Laplacian editing's local-frame passes are a fixed
    count, not an iteration to convergence)."""
    key = (obj.name, d.uid)
    rt = cache.runtime.get(key)
    if not rt or not d.bound or d.status_is_error:
        return None
    m = methods.get(d.method)
    if not m.iterative:
        return "last solve %.1f ms" % rt["ms"]
    e = cache._cache.get(key)
    refining = e is not None and e.pending
    return "last solve %.1f ms, %s%s" % (
        rt["ms"], plural(rt["iterations"], "iteration"),
        "" if rt["converged"] or refining else " (not converged)")


def simulation_text(obj, d):
    """A simulation's panel line (the native table's `dynamic`), or None for other methods:
    the frames kept, and when the frame shown is ahead of them, where to play from."""
    if not d.bound or not simulation.is_dynamic(methods.get(d.method)):
        return None
    e = cache._cache.get((obj.name, d.uid))
    s = simulation.summary(e) if e is not None else None
    sim = getattr(e, "sim", None) if e is not None else None
    # a frame ahead of the kept ones shows the input, or its result as saved with the file
    saved = sim is not None and sim.gap_from is not None and sim.shown is not None
    if s is None or s[0] is None:
        if saved:
            return ("simulation: this frame shows its result as saved; play from frame %d "
                    "to simulate on" % sim.gap_from)
        return "simulation: plays from the scene's first frame"
    first, last, gap = s
    text = "simulated frames %d-%d" % (first, last)
    if gap is not None:
        text += ("; this frame is ahead of them and shows %s: play from frame %d"
                 % ("its result as saved" if saved else "the input", gap))
    return text
