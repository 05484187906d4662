"""Previews while a worker thread solves: the last result moved by the response basis."""

import numpy as np

from . import blender_data, calls


def _has_basis(e):
    return e.basis is not None and e.basis is not False


def _fetch_basis(e, m):
    """The native response basis (methods.Method.response_basis), fetched once per binding,
    while the object is idle (False: it has none)."""
    if m.response_basis and e.basis is None:
        b = calls._native_call(m.label + " response basis", e.native.response_basis)
        e.basis = False if b is None else b


def _basis_preview(obj, d, e, T, inputs):
    """While a worker thread solves (issue 19): the last finished result moved by the
    response basis to the handles' current transforms T -- the plain warm start's positions,
    x0 + B (T - T0), no solve: ~10 ms at 692k vertices -- written as the shown result, so
    that the mesh follows the handle between the worker's results. Returns the positions,
    or None (no basis, no result yet, or nothing moved since the last preview)."""
    if not _has_basis(e) or e.result_pos is None or inputs == e.preview_inputs:
        return None
    if e.source is not e.rest:  # a posed input (a rig): the basis is the rest's response,
        return None             # and would put the handles off their targets on the pose
    T0 = e.result_T
    if T0 is None or T0.shape != T.shape or e.basis.shape[1] != 4 * len(T):
        return None
    C = (T - T0)[:, :3, :].transpose(0, 2, 1).reshape(-1, 3)
    pos = e.result_pos + e.basis @ C
    off = np.empty(pos.shape, dtype=np.float32)
    np.subtract(pos, e.source, out=off, casting="unsafe")
    blender_data.write_offset(obj, d, off, retime=False)
    e.preview_inputs = inputs
    # what shows is no solve's result now: any later solve, a frame's included, writes again
    e.last_inputs, e.last_cold = None, False
    return pos
