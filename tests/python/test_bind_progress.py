"""Bind progress and cancellation (issue 19, item 3): progress=callable(fraction) on the
constructors of ARAP, LaplacianEdit, Falloff, EmbeddedDeformation, LinearReconstruction and
EigenDeformation and on rebind of all but the last. The callable gets a deformkit.BindProgress (a float with `.phase`); a true
return stops the bind (RuntimeError), an exception stops it and propagates, and a rebind
that stopped leaves the object solving its old constraints exactly as before."""

import numpy as np
import pytest

import deformkit as dk


def grid(n, bump=0.05):
    """(n+1)^2 vertices on the unit square, sine bumps, alternating diagonals."""
    x, y = np.meshgrid(np.linspace(0, 1, n + 1), np.linspace(0, 1, n + 1))
    z = bump * np.sin(5 * np.pi * x) * np.sin(3 * np.pi * y)
    v = np.column_stack([x.ravel(), y.ravel(), z.ravel()])
    f = []
    for j in range(n):
        for i in range(n):
            a = j * (n + 1) + i
            b, c, d = a + 1, a + n + 1, a + n + 2
            f += [(a, b, d), (a, d, c)] if (i + j) % 2 else [(a, b, c), (b, d, c)]
    return v, np.array(f, dtype=np.int64)


N = 90  # 8,281 vertices: the native loops report a few times in between their phases
V, F = grid(N)
COLS = np.arange(len(V)) % (N + 1)
FIXED = np.flatnonzero(COLS <= 1)
HANDLE = np.flatnonzero(COLS >= N - 1)
OTHER = np.flatnonzero((COLS >= N // 2) & (COLS <= N // 2 + 1))  # a handle in the middle
MESH = dk.Mesh(V, F)
TARGETS = V[HANDLE] + [0.05, 0.0, 0.25]

PHASES = {
    "ARAP": {"renumber", "cells", "constraints", "system", "assemble", "analyze",
             "factorize", "basis", "coarse"},
    "LaplacianEdit": {"renumber", "operator", "constraints", "assemble", "analyze",
                      "factorize", "basis"},
    "Falloff": {"distances"},  # distance="hops"; "geodesic" adds "heat" (below)
    "EmbeddedDeformation": {"nodes", "weights", "edges", "constraints", "analyze"},
    "LinearReconstruction": {"forms", "constraints", "assemble", "analyze", "factorize",
                             "basis"},
}
METHODS = sorted(PHASES)


class Recorder:
    def __init__(self, stop_at=None, raise_at=None):
        self.seen, self.stop_at, self.raise_at = [], stop_at, raise_at

    def __call__(self, fraction):
        self.seen.append(fraction)
        k = len(self.seen) - 1
        if k == self.raise_at:
            raise ZeroDivisionError("raised by the callback at %d" % k)
        return k == self.stop_at


def stops(seen):
    """The reports a test stops at: each phase's first and the one after it (inside its
    loop, when it has one); never the last ("done": the bind is whole by then)."""
    ph = [x.phase for x in seen]
    return [k for k in range(len(seen) - 1)
            if k <= 1 or ph[k] != ph[k - 1] or ph[k - 1] != ph[k - 2]]


def check_sequence(seen):
    fr = [float(x) for x in seen]
    assert all(isinstance(x, dk.BindProgress) and isinstance(x, float) for x in seen)
    assert all(0.0 <= x <= 1.0 for x in fr)
    assert all(a <= b for a, b in zip(fr, fr[1:])), fr
    assert fr[-1] == 1.0


def bind(name, **kw):
    return getattr(dk, name)(MESH, handles=[HANDLE], fixed=FIXED, **kw)


@pytest.mark.parametrize("name", METHODS)
def test_bind_reports_named_phases(name):
    rec = Recorder()
    obj = bind(name, progress=rec)
    check_sequence(rec.seen)
    phases = [x.phase for x in rec.seen]
    assert set(phases) == PHASES[name] | {"done"}
    assert phases[-1] == "done" and phases.count("done") == 1
    # the phases come in one order, each once (a block of reports)
    blocks = [p for i, p in enumerate(phases) if i == 0 or p != phases[i - 1]]
    assert len(blocks) == len(set(blocks))
    assert len(rec.seen) > len(blocks)  # reports inside the long loops too
    # the same result as without a callback
    plain = bind(name)
    a, b = obj.solve(TARGETS), plain.solve(TARGETS)
    assert np.array_equal(np.asarray(a.positions), np.asarray(b.positions))


@pytest.mark.parametrize("name", METHODS)
def test_bind_stops_at_every_report(name):
    whole = _whole_bind(name)
    calls = len(whole)
    for k in stops(whole):
        rec = Recorder(stop_at=k)
        with pytest.raises(RuntimeError, match="cancelled"):
            bind(name, progress=rec)
        assert len(rec.seen) == k + 1  # asked no more after the stop
    # a stop at the last report ("done": the bind is whole) changes nothing
    obj = bind(name, progress=Recorder(stop_at=calls - 1))
    assert obj.n_vertices == len(V)


def _whole_bind(name):
    rec = Recorder()
    bind(name, progress=rec)
    return rec.seen


@pytest.mark.parametrize("name", METHODS)
def test_exception_in_callback_propagates(name):
    calls = len(_whole_bind(name))
    for k in (0, calls // 2, calls - 2):
        rec = Recorder(raise_at=k)
        with pytest.raises(ZeroDivisionError, match="raised by the callback at %d" % k):
            bind(name, progress=rec)
        assert len(rec.seen) == k + 1  # not called again after it raised


def test_falloff_geodesic_reports_the_heat_factorization():
    rec = Recorder()
    bind("Falloff", distance="geodesic", progress=rec)
    check_sequence(rec.seen)
    phases = [x.phase for x in rec.seen]
    assert phases[0] == "heat" and phases[-1] == "done" and "distances" in phases
    with pytest.raises(RuntimeError, match="cancelled in phase heat"):
        bind("Falloff", distance="geodesic", progress=Recorder(stop_at=0))


def test_eigen_reports_through_the_same_callback():
    v, f = grid(24)
    region = np.flatnonzero(np.arange(len(v)) % 25 >= 23)
    rec = Recorder()
    dk.EigenDeformation(dk.Mesh(v, f), handles=[region], n_eigenvectors=8, refine=0,
                        progress=rec)
    check_sequence(rec.seen)
    phases = [x.phase for x in rec.seen]
    assert [p for i, p in enumerate(phases) if i == 0 or phases[i - 1] != p] == [
        "regions", "operator", "eigenvectors", "skeletons", "done"]
    assert sum(p == "eigenvectors" for p in phases) > 2  # the eigensolver's bands report
    with pytest.raises(ZeroDivisionError):
        dk.EigenDeformation(dk.Mesh(v, f), handles=[region], n_eigenvectors=8, refine=0,
                            progress=Recorder(raise_at=0))
    for k, name in ((0, "regions"), (phases.index("eigenvectors") + 1, "eigenvectors"),
                    (phases.index("skeletons"), "skeletons")):
        with pytest.raises(RuntimeError, match="EigenDeformation: cancelled in phase " + name):
            dk.EigenDeformation(dk.Mesh(v, f), handles=[region], n_eigenvectors=8, refine=0,
                                progress=Recorder(stop_at=k))


@pytest.mark.parametrize("name", METHODS)
@pytest.mark.parametrize("change", ["new unknowns", "same unknowns"])
def test_cancelled_rebind_keeps_the_old_constraints(name, change):
    obj = bind(name, handle_weights=[np.full(len(HANDLE), 0.9)])
    before = np.asarray(obj.solve(TARGETS, warm_start=False).positions).copy()
    def counters():  # the bound state's counters (basis_solves counts solves, not binds)
        return {k: v for k, v in obj.stats.items() if k != "basis_solves"}

    stats = counters()
    if change == "new unknowns":
        kw = dict(handles=[OTHER])
    else:  # the same unknown vertices, other values (soft handle weights)
        kw = dict(handles=[HANDLE], handle_weights=[np.full(len(HANDLE), 0.6)])
    twin = bind(name, handle_weights=[np.full(len(HANDLE), 0.9)])
    rec = Recorder()
    twin.rebind(progress=rec, **kw)
    check_sequence(rec.seen)
    assert rec.seen[-1].phase == "done"
    for k in stops(rec.seen):
        stop = Recorder(stop_at=k) if k % 2 else Recorder(raise_at=k)
        stats = counters()  # just before (a solve may count too: Gauss-Newton factors)
        with pytest.raises(RuntimeError if k % 2 else ZeroDivisionError):
            obj.rebind(progress=stop, **kw)
        assert counters() == stats
        after = np.asarray(obj.solve(TARGETS, warm_start=False).positions)
        assert np.array_equal(before, after), (k, stop.seen[-1].phase)
    obj.rebind(progress=Recorder(), **kw)  # not stopped: the new constraints
    if change == "new unknowns":  # the new handle holds (a cold solve: a warm one from the
        # old handle's move swings the free end back over hundreds of ARAP iterations)
        lifted = V[OTHER] + [0.0, 0.0, 0.1]
        got = np.asarray(obj.solve(lifted, warm_start=False).positions)[OTHER]
        # (EmbeddedDeformation's handles are penalties: within 3e-3 here)
        assert np.abs(got - lifted).max() < (1e-2 if name == "EmbeddedDeformation" else 1e-12)
    elif name not in ("EmbeddedDeformation", "LinearReconstruction"):
        # (EmbeddedDeformation's handles are penalties of fixed weight; LinearReconstruction's
        # are hard constraints, whatever their weight)
        assert not np.array_equal(before, np.asarray(obj.solve(TARGETS).positions))


def test_bad_progress_is_refused():
    for name in METHODS:
        with pytest.raises(TypeError, match="progress must be callable"):
            bind(name, progress=3)
        obj = bind(name, progress=None)
        with pytest.raises(TypeError, match="progress must be callable"):
            obj.rebind(progress="no")
    eig = dk.EigenDeformation(MESH, handles=[HANDLE], n_eigenvectors=8, refine=0)
    with pytest.raises(TypeError):
        eig.rebind(progress=lambda f: False)  # its rebind does not report
    # estimate_memory takes the bind's keywords, progress= included (not called)
    rec = Recorder()
    assert dk.ARAP.estimate_memory(MESH, progress=rec) > 0 and rec.seen == []


# ---- the second hostile review: what a callback does at the end, and calls from inside it

def _raise_at_done(fraction):
    if fraction.phase == "done":
        raise ZeroDivisionError("raised at done")
    return False


@pytest.mark.parametrize("name", METHODS + ["EigenDeformation"])
def test_an_exception_at_done_propagates(name):
    """The final report ("done") comes when the work is whole: a stop request there is
    ignored, but an exception still propagates from the constructor (no object) and from
    rebind (whose new constraints then stay bound, as the docs say)."""
    if name == "EigenDeformation":
        v, f = grid(24)
        region = np.flatnonzero(np.arange(len(v)) % 25 >= 23)
        with pytest.raises(ZeroDivisionError, match="raised at done"):
            dk.EigenDeformation(dk.Mesh(v, f), handles=[region], n_eigenvectors=8, refine=0,
                                progress=_raise_at_done)
        return
    with pytest.raises(ZeroDivisionError, match="raised at done"):
        bind(name, progress=_raise_at_done)
    obj = bind(name)
    with pytest.raises(ZeroDivisionError, match="raised at done"):
        obj.rebind(handles=[OTHER], progress=_raise_at_done)
    lifted = V[OTHER] + [0.0, 0.0, 0.1]
    got = np.asarray(obj.solve(lifted, warm_start=False).positions)[OTHER]
    assert np.abs(got - lifted).max() < (1e-2 if name == "EmbeddedDeformation" else 1e-12)


@pytest.mark.parametrize("name", METHODS)
def test_a_call_on_the_same_object_from_its_rebind_callback_says_so(name):
    obj = bind(name)
    seen = []

    def cb(fraction):
        if not seen:
            with pytest.raises(RuntimeError, match="in use by a call on this same thread"):
                obj.solve(TARGETS)
            seen.append(fraction.phase)
        return False

    obj.rebind(handles=[OTHER], progress=cb)
    assert seen


ISOLATED = """
import numpy as np, deformkit as dk, json, sys
x, y = np.meshgrid(np.linspace(0, 1, 25), np.linspace(0, 1, 25))
v = np.column_stack([x.ravel(), y.ravel(), 0.05 * np.sin(5 * x.ravel()) * np.cos(3 * y.ravel())])
f = []
for j in range(24):
    for i in range(24):
        a = j * 25 + i
        f += [(a, a + 1, a + 26), (a, a + 26, a + 25)]
mesh = dk.Mesh(v, np.array(f))
region = np.flatnonzero(np.arange(len(v)) % 25 >= 23)
"""


def run_isolated(code, timeout=120):
    """Runs `code` (after ISOLATED's set-up) in a fresh interpreter; a hang fails the test
    after `timeout` s instead of hanging the suite. Returns its stdout."""
    import subprocess
    import sys
    try:
        r = subprocess.run([sys.executable, "-c", ISOLATED + code], capture_output=True,
                           text=True, timeout=timeout)
    except subprocess.TimeoutExpired:
        pytest.fail("hung: no answer within %d s" % timeout)
    assert r.returncode == 0, r.stdout[-2000:] + r.stderr[-2000:]
    return r.stdout


@pytest.mark.parametrize("second", ["laplacian_eigenpairs", "EigenDeformation"])
def test_an_eigen_computation_from_an_eigen_callback_is_refused_not_hung(second):
    """ARPACK runs one eigensolve at a time: a second one started from the progress callback
    of an EigenDeformation bind, on its thread, waited forever for the lock its own thread
    held. It is refused with a RuntimeError, which propagates from the outer bind."""
    out = run_isolated("""
def cb(fraction):
    if fraction.phase == "eigenvectors":
        if %r == "laplacian_eigenpairs":
            dk.laplacian_eigenpairs(mesh, 4)
        else:
            dk.EigenDeformation(mesh, handles=[region], n_eigenvectors=4, refine=0)
    return False
try:
    dk.EigenDeformation(mesh, handles=[region], n_eigenvectors=8, refine=0, progress=cb)
    print("no error")
except RuntimeError as e:
    print("refused:", e)
# and afterwards both work again
dk.laplacian_eigenpairs(mesh, 4)
dk.EigenDeformation(mesh, handles=[region], n_eigenvectors=8, refine=0)
print("then fine")
""" % second)
    assert "refused:" in out and "already running on this thread" in out, out
    assert "then fine" in out, out
