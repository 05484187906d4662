"""How much of a solve an interactive update gets (its time budget), and the float32
rounding below which a handle transform is the identity or the last one."""

import numpy as np

from . import cache


# A handle transform this close to the identity is the identity seen through Blender's float32
# matrix products (the bind pose re-computed, a target keyed back to where it was bound).
_SNAP_LINEAR = 1e-6   # on the 3x3 part


_SNAP_SHIFT = 1e-6    # on the translation, times the mesh's bounding-box diagonal


def _within_rounding(T, U, extent):
    """Whether handle transforms T and U differ by no more than float32 rounding: 1e-6 on the
    3x3 parts, 1e-6 of the mesh's bounding-box diagonal on the translations (as
    snap_identity)."""
    dlt = np.abs(T - U)
    return (dlt[:, :3, :3].max(initial=0.0) <= _SNAP_LINEAR
            and dlt[:, :3, 3].max(initial=0.0) <= _SNAP_SHIFT * max(extent, 1e-30)
            and not dlt[:, 3].any())


def snap_identity(T, extent):
    """Replaces transforms within float32 rounding of the identity by the exact identity.
    The solvers then return the rest shape at once; fed the rounding, an iterative method
    would chase an energy that is itself ~0 (ARAP ran to its iteration cap at the bind pose of
    a rotated object). A real move or rotation is thousands of times larger."""
    eye = np.eye(4)
    for i in range(len(T)):
        dlt = T[i] - eye
        if (np.abs(dlt[:3, :3]).max() <= _SNAP_LINEAR
                and np.abs(dlt[:3, 3]).max() <= _SNAP_SHIFT * max(extent, 1e-30)
                and not dlt[3].any()):
            T[i] = eye
    return T


# Interactive updates of iterative methods (ARAP) get this much solve time; the rest of the
# solve runs from a timer once the handles stop moving (handlers.refine).
INTERACTIVE_BUDGET_MS = 30.0


def inner_cap(m, opts):
    """The bound inner count of m's iterations (ARAP Newton steps: CG iterations), or 0 when
    its iterations have none (for ARAP: another solver)."""
    if m.inner_iterations is None:
        return 0
    if m.inner_when is not None and getattr(opts, m.inner_when[0]) != m.inner_when[1]:
        return 0
    return int(getattr(opts, m.inner_iterations))


def _budget(key, cap, inner=0, resume=False, cut=True):
    """(iterations, inner count or None for the bound one) of a slice that fits
    INTERACTIVE_BUDGET_MS: at most `cap` iterations, and for methods whose iterations have an
    inner count (`inner`, ARAP Newton: 12 CG iterations a step) one iteration with fewer when
    a full one does not fit (a Newton step is ~50 ms on the armadillo, 100-250 ms on a loaded
    machine; a CG iteration ~4 / ~8 ms). The cost of a unit (an iteration, or an inner
    iteration) comes from the last unconverged slice of the same kind (a drag update starts
    warm, a refine tick resumes: their fixed costs differ), else from the last solve (the
    bind's), else ~0.15 us per vertex (the armadillo's 6.5 ms at 43k). Dividing a slice's
    time, fixed cost included, by its units converges within a few slices to the count that
    fills the budget: (budget - fixed) / unit. `cut` False: whole iterations only (at least
    one), for the refine steps once the handles have settled: after cut Newton steps the
    solver's stopping test waits for a whole one (docs/methods/arap.md)."""
    e = cache._cache.get(key)
    last = None
    if e is not None:
        last = e.slice_cost.get(bool(resume)) or e.slice_cost.get(not resume)
    if last is None:
        rt = cache.runtime.get(key)
        if rt and rt.get("iterations", 0) >= 1:
            last = (rt["ms"], rt["iterations"], inner or 1)
    if last is not None:
        ms, its, per_it = last
        per_unit = ms / max(its * per_it, 1)
    else:
        per_unit = 1.5e-4 * (e.n_vertices if e is not None else 1e5)
    units = int(INTERACTIVE_BUDGET_MS / max(per_unit, 1e-3))
    if inner and units < inner and cut:
        # one iteration cut short: the smallest unit is an inner iteration
        return 1, max(1, units)
    # at least one: an iteration can take most of the budget on its own
    return max(1, min(cap, units // max(inner, 1))), None


# A preview (methods.Method.preview) is replaced by the full result once the handles have
# not moved for this long; and the refine steps of a budgeted solve cut its iterations to
# the budget (ARAP: Newton steps of fewer CG iterations) until then, so that the ticks the
# timer gets between the updates of a drag stay within the budget too, and take whole
# iterations once the handles have stopped, which is how the solve converges.
PREVIEW_SETTLE_S = 0.15
