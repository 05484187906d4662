"""Issue 18, class 3: binds and solves in a child process forked from a parent that uses
DeformKit (docs/reliability.md).

The parent binds and solves every method on a real mesh first, so that the thread pools the
numerics keep per process (CHOLMOD's OpenMP team, OpenBLAS's threads, the methods' helper
threads) are running; then, while one thread per method is inside a solve on its own
object, the main thread forks. In the child every method must bind and solve the real mesh
to the parent's answer, and each object that was mid-solve in another thread must solve
too (not answer "in use" forever). A child that hangs is killed after a timeout and the test
fails; so does one that crashes.

Before the fix the child's first supernodal factorization crashed (SIGSEGV in libgomp's
GOMP_parallel: the forking thread's OpenMP team refers to threads that exist only in the
parent), and every object that was busy at the fork raised RuntimeError in the child.
"""
import faulthandler
import json
import multiprocessing
import os
import signal
import threading
import time

import numpy as np
import pytest

import deformkit as dk
from conftest import GROUP_METHODS, SHARED_MESHES

MESH = SHARED_MESHES / "arm.obj"
CHILD_TIMEOUT = 180.0   # s; a child binds all six methods on these 8k vertices in ~5 s

# heavy: every method bound and solved on a real mesh, in the parent and in each child (the
# sanitized run leaves them out: four times slower there, over a minute, on paths the
# other tests take)
pytestmark = [pytest.mark.skipif(not MESH.exists(), reason="shared meshes not available"),
              pytest.mark.heavy]


def _iterative(name):
    return dk._native._method_info(name)["iterative"]


def _solve_kw(name):
    return {"warm_start": False} if _iterative(name) else {}


class Scene:
    """The real mesh, a fixed strip and a handle strip, and the parent's reference solves."""

    def __init__(self):
        self.mesh = dk.read_mesh(str(MESH))
        v = np.asarray(self.mesh.vertices)
        y = v[:, 1]
        lo, hi = np.quantile(y, [0.05, 0.95])
        self.fixed = np.where(y <= lo)[0]
        self.handle = np.where(y >= hi)[0]
        self.targets = v[self.handle] + [0.0, 0.05 * (hi - lo), 0.0]
        self.scale = float(np.ptp(v, axis=0).max())
        self.reference = {}
        self.objects = {}
        for name in GROUP_METHODS:
            m = self.bind(name)
            self.reference[name] = np.asarray(m.solve(self.targets, **_solve_kw(name)).positions)
            self.objects[name] = m       # solved: its pools and helper thread are live

    def bind(self, name):
        return getattr(dk, name)(self.mesh, handles=[self.handle], fixed=self.fixed)

    def error(self, name, positions):
        return float(np.abs(np.asarray(positions) - self.reference[name]).max()) / self.scale


@pytest.fixture(scope="module")
def scene():
    return Scene()


class BusySolvers:
    """One thread per method, each solving its method's bound object in a loop (the native
    solve runs with the GIL released, so at any moment most of them are inside it)."""

    def __init__(self, scene):
        self.stop = threading.Event()
        self.in_solve = {name: threading.Event() for name in GROUP_METHODS}
        self.threads = [threading.Thread(target=self._loop, args=(scene, name), daemon=True)
                        for name in GROUP_METHODS]

    def _loop(self, scene, name):
        m = scene.objects[name]
        while not self.stop.is_set():
            self.in_solve[name].set()
            m.solve(scene.targets, **_solve_kw(name))

    def __enter__(self):
        for t in self.threads:
            t.start()
        for e in self.in_solve.values():
            e.wait(30)
        time.sleep(0.05)
        return self

    def __exit__(self, *exc):
        self.stop.set()
        for t in self.threads:
            t.join(60)


def child_work(scene, out_fd):
    """In the child: bind and solve every method, and solve every inherited object (some of
    them were mid-solve in a thread that does not exist here). Writes a JSON report."""
    report = {}
    for name in GROUP_METHODS:
        entry = {}
        try:
            m = scene.bind(name)
            entry["fresh"] = scene.error(name, m.solve(scene.targets, **_solve_kw(name)).positions)
            # a second solve: the object's helper thread and the child's pools keep working
            entry["fresh_again"] = scene.error(
                name, m.solve(scene.targets, **_solve_kw(name)).positions)
        except Exception as exc:   # noqa: BLE001 - reported to the parent
            entry["fresh"] = "%s: %s" % (type(exc).__name__, exc)
        try:
            r = scene.objects[name].solve(scene.targets, **_solve_kw(name))
            entry["inherited"] = scene.error(name, r.positions)
        except Exception as exc:   # noqa: BLE001
            entry["inherited"] = "%s: %s" % (type(exc).__name__, exc)
        report[name] = entry
    os.write(out_fd, json.dumps(report).encode())
    os.close(out_fd)


def _read_all(fd):
    chunks = []
    while True:
        b = os.read(fd, 65536)
        if not b:
            break
        chunks.append(b)
    os.close(fd)
    return b"".join(chunks).decode()


def _check(report_text, how):
    assert report_text, "%s: the child wrote no report" % how
    report = json.loads(report_text)
    for name in GROUP_METHODS:
        for key in ("fresh", "fresh_again", "inherited"):
            got = report[name][key]
            assert not isinstance(got, str), "%s child, %s %s: %s" % (how, name, key, got)
            assert got < 1e-6, "%s child, %s %s: off the parent's answer by %g of the " \
                               "bbox" % (how, name, key, got)


def _fork_with_os(scene):
    """Forks; returns a function that waits for the child and returns its report."""
    r, w = os.pipe()
    pid = os.fork()
    if pid == 0:   # the child: never return into pytest
        code = 1
        try:
            os.close(r)
            signal.alarm(int(CHILD_TIMEOUT) + 30)   # belt and braces if the parent died
            child_work(scene, w)
            code = 0
        finally:
            os._exit(code)
    os.close(w)
    return lambda: _wait_os_child(pid, r)


def _wait_os_child(pid, r):
    deadline = time.monotonic() + CHILD_TIMEOUT
    status = None
    while time.monotonic() < deadline:
        done, status = os.waitpid(pid, os.WNOHANG)
        if done:
            break
        time.sleep(0.05)
    else:
        os.kill(pid, signal.SIGKILL)
        os.waitpid(pid, 0)
        os.close(r)
        pytest.fail("the os.fork child did not finish within %.0f s (hung)" % CHILD_TIMEOUT)
    text = _read_all(r)
    assert os.WIFEXITED(status) and os.WEXITSTATUS(status) == 0, \
        "the os.fork child died: %s (report: %r)" % (
            "signal %d" % os.WTERMSIG(status) if os.WIFSIGNALED(status)
            else "exit %d" % os.WEXITSTATUS(status), text)
    return text


_MP_SCENE = {}


def _mp_target(w):
    child_work(_MP_SCENE["scene"], w)


def _fork_with_multiprocessing(scene):
    ctx = multiprocessing.get_context("fork")
    r, w = os.pipe()
    _MP_SCENE["scene"] = scene      # inherited by the forked child, not pickled
    try:
        p = ctx.Process(target=_mp_target, args=(w,))
        p.start()
    finally:
        _MP_SCENE.clear()
    os.close(w)
    return lambda: _wait_mp_child(p, r)


def _wait_mp_child(p, r):
    p.join(CHILD_TIMEOUT)
    if p.is_alive():
        p.kill()
        p.join()
        os.close(r)
        pytest.fail("the multiprocessing 'fork' child did not finish within %.0f s (hung)"
                    % CHILD_TIMEOUT)
    text = _read_all(r)
    assert p.exitcode == 0, "the multiprocessing child died with exit code %s (report: %r)" % (
        p.exitcode, text)
    return text


@pytest.mark.filterwarnings("ignore::DeprecationWarning")   # 3.12+: fork with threads
@pytest.mark.parametrize("how", ["os.fork", "multiprocessing"])
def test_child_binds_and_solves_after_fork_during_solves(scene, how):
    fork = _fork_with_os if how == "os.fork" else _fork_with_multiprocessing
    # the fork itself hung in the parent before the fix (OpenBLAS's fork handler waiting for
    # a worker busy with another thread's job): a watchdog ends the test run then
    faulthandler.dump_traceback_later(CHILD_TIMEOUT, exit=True)
    try:
        with BusySolvers(scene):
            wait = fork(scene)
    finally:
        faulthandler.cancel_dump_traceback_later()
    text = wait()    # the parent's solver threads have stopped: the child runs alone
    _check(text, how)
    # and the parent's objects are unaffected by the fork
    for name in GROUP_METHODS:
        r = scene.objects[name].solve(scene.targets, **_solve_kw(name))
        assert scene.error(name, r.positions) < 1e-6


@pytest.mark.filterwarnings("ignore::DeprecationWarning")
def test_child_of_an_idle_parent_keeps_its_objects(scene):
    """No thread is inside a call at the fork: the inherited objects solve in the child to
    the parent's answer, and so do new binds."""
    r, w = os.pipe()
    pid = os.fork()
    if pid == 0:
        code = 1
        try:
            os.close(r)
            signal.alarm(int(CHILD_TIMEOUT))
            out = {}
            for name in GROUP_METHODS:
                m = scene.objects[name]
                res = m.solve(scene.targets, **_solve_kw(name))
                fresh = scene.bind(name).solve(scene.targets, **_solve_kw(name))
                out[name] = [scene.error(name, res.positions),
                             scene.error(name, fresh.positions)]
            os.write(w, json.dumps(out).encode())
            code = 0
        finally:
            os._exit(code)
    os.close(w)
    out = json.loads(_wait_os_child(pid, r))  # asserts the child exited with status 0
    for name in GROUP_METHODS:
        inherited, fresh = out[name]
        assert inherited < 1e-6 and fresh < 1e-6, (name, inherited, fresh)


# ---- forks while a bind stands at its progress callback (the second hostile review) -------
# A progress callback runs while its native call is at a phase boundary. Before, that call
# still counted as "in flight" for the fork gate: os.fork() from the callback waited for the
# very call that ran it, and a thread forking while another thread's callback made a
# DeformKit call deadlocked both. Each scenario runs in a fresh interpreter with a timeout.

ISOLATED = """
import json, os, signal, sys, threading, time
import numpy as np, deformkit as dk
x, y = np.meshgrid(np.linspace(0, 1, 31), np.linspace(0, 1, 31))
v = np.column_stack([x.ravel(), y.ravel(), 0.05 * np.sin(5 * x.ravel()) * np.cos(3 * y.ravel())])
f = []
for j in range(30):
    for i in range(30):
        a = j * 31 + i
        f += [(a, a + 1, a + 32), (a, a + 32, a + 31)]
mesh = dk.Mesh(v, np.array(f))
cols = np.arange(len(v)) % 31
fixed, handle, other = (np.flatnonzero(cols <= 1), np.flatnonzero(cols >= 29),
                        np.flatnonzero((cols >= 15) & (cols <= 16)))
targets = v[handle] + [0.05, 0.0, 0.2]

def bind(name, **kw):
    kw.setdefault("handles", [handle])
    if name == "EigenDeformation":
        return dk.EigenDeformation(mesh, n_eigenvectors=8, refine=0, **kw)
    return getattr(dk, name)(mesh, fixed=fixed, **kw)

def solve(m):
    return np.asarray(m.solve(targets).positions)

def wait_child(pid, timeout=60):
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        done, status = os.waitpid(pid, os.WNOHANG)
        if done:
            return os.WEXITSTATUS(status) if os.WIFEXITED(status) else -1
        time.sleep(0.02)
    os.kill(pid, signal.SIGKILL)
    os.waitpid(pid, 0)
    return "hung"
"""


def run_isolated(code, timeout=150):
    import subprocess
    import sys
    try:
        r = subprocess.run([sys.executable, "-W", "ignore::DeprecationWarning", "-c",
                            ISOLATED + code], capture_output=True, text=True, timeout=timeout)
    except subprocess.TimeoutExpired:
        pytest.fail("hung: no answer within %d s" % timeout)
    assert r.returncode == 0, r.stdout[-2000:] + r.stderr[-2000:]
    return json.loads(r.stdout.strip().splitlines()[-1])


@pytest.mark.parametrize("name", sorted(GROUP_METHODS))
@pytest.mark.parametrize("call", ["bind", "rebind"])
def test_fork_from_a_progress_callback(name, call):
    """os.fork() inside a bind's (or rebind's) progress callback returns in both processes;
    each finishes the bind and solves to the same answer as an undisturbed object."""
    if call == "rebind" and name == "EigenDeformation":
        pytest.skip("EigenDeformation's rebind takes no progress callback")
    out = run_isolated("""
name, call = %r, %r
pids = []
def cb(fraction):
    if not pids and fraction > 0:
        pids.append(os.fork())
    return False
want = solve(bind(name))
if call == "bind":
    m = bind(name, progress=cb)
else:
    m = bind(name, handles=[other]) if name != "EigenDeformation" else None
    m.rebind(handles=[handle], progress=cb)
err = float(np.abs(solve(m) - want).max())
if pids and pids[0] == 0:          # the child: report through the exit status
    os._exit(0 if err < 1e-9 else 3)
child = wait_child(pids[0]) if pids else "no fork"
print(json.dumps({"parent": err, "child": child}))
""" % (name, call))
    assert out["child"] == 0, out
    assert out["parent"] < 1e-9, out


def test_a_fork_while_another_threads_callback_calls_deformkit():
    """Thread A's bind stands at its progress callback, which makes a DeformKit call (a solve
    on another object) while thread B forks: neither waits for the other."""
    out = run_isolated("""
ready, forked = threading.Event(), threading.Event()
other_obj = bind("LaplacianEdit")
result = {}
def cb(fraction):
    if not ready.is_set():
        ready.set()
        forked.wait(30)     # B has forked (or is forking): now call in
        result["solve"] = float(np.abs(solve(other_obj)).max())
    return False
def a():
    result["bind"] = bind("ARAP", progress=cb) is not None
def b():
    ready.wait(30)
    pid = os.fork()
    if pid == 0:
        os._exit(0 if float(np.abs(solve(other_obj)).max()) > 0 else 3)
    forked.set()
    result["child"] = wait_child(pid)
ta, tb = threading.Thread(target=a), threading.Thread(target=b)
ta.start(); tb.start(); ta.join(60); tb.join(60)
print(json.dumps({"alive": ta.is_alive() or tb.is_alive(), **result}))
""")
    assert not out["alive"] and out.get("bind") and out.get("solve", 0) > 0, out
    assert out.get("child") == 0, out


def test_a_rebind_copied_half_way_by_a_fork_is_refused_in_the_child():
    """Thread B forks while thread A's rebind of an object stands at its progress callback:
    in the child that object is half-way through a rebind that will never finish there, so
    every call on it is refused, saying why; other objects work, and in the parent the
    rebind completes."""
    out = run_isolated("""
obj, spare = bind("ARAP"), bind("ARAP")
at_callback, forked = threading.Event(), threading.Event()
result = {}
def cb(fraction):
    if not at_callback.is_set():
        at_callback.set()
        forked.wait(30)
    return False
def a():
    obj.rebind(handles=[other], progress=cb)
    result["parent_rebind"] = "done"
def b():
    at_callback.wait(30)
    pid = os.fork()
    if pid == 0:
        try:
            obj.solve(v[other])
            code = 3
        except RuntimeError as e:
            code = 0 if "half-way through that rebind" in str(e) else 4
        if code == 0 and float(np.abs(solve(spare)).max()) <= 0:
            code = 5
        os._exit(code)
    forked.set()
    result["child"] = wait_child(pid)
ta, tb = threading.Thread(target=a), threading.Thread(target=b)
ta.start(); tb.start(); ta.join(60); tb.join(60)
lifted = v[other] + [0.0, 0.0, 0.1]
result["parent_err"] = float(np.abs(np.asarray(obj.solve(lifted, warm_start=False).positions)[other] - lifted).max())
print(json.dumps(result))
""")
    assert out.get("child") == 0, out
    assert out.get("parent_rebind") == "done" and out["parent_err"] < 1e-9, out


@pytest.mark.filterwarnings("ignore::DeprecationWarning")
def test_fork_from_a_callback_while_another_eigensolve_waits():
    """An EigenDeformation bind holds the ARPACK lock while its progress callback runs
    (outside the fork gate); another thread's eigensolve waits for that lock. A fork from
    the callback then waited for the waiting thread to leave the gate, which waited for the
    lock, which waited for the fork: the process hung. The waiting thread now waits outside
    the gate."""
    from conftest import make_icosphere
    mesh = dk.Mesh(*make_icosphere(3))
    in_callback, forked, out = threading.Event(), [], {}

    def progress(fraction):
        if not in_callback.is_set():
            in_callback.set()
            time.sleep(0.5)           # the other thread is now waiting for the lock
            pid = os.fork()
            if pid == 0:
                os._exit(0)
            forked.append(os.waitpid(pid, 0)[1])
        return False

    def other():
        in_callback.wait(30)
        out["pairs"] = dk.laplacian_eigenpairs(mesh, 5)

    faulthandler.dump_traceback_later(120, exit=True)
    try:
        t = threading.Thread(target=other)
        t.start()
        dk.EigenDeformation(mesh, [[0, 1, 2]], n_eigenvectors=10, progress=progress)
        t.join(60)
    finally:
        faulthandler.cancel_dump_traceback_later()
    assert forked == [0] and not t.is_alive() and len(out["pairs"][0]) == 5
