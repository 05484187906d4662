#!/usr/bin/python3
"""Deformation benchmark: DeformKit's methods vs CGAL 5.5's Surface_mesh_deformation.

    PYTHONPATH=build/python /usr/bin/python3 scripts/bench_arap.py [scenario ...]
        [--repeat 3] [--ref-iterations 3000] [--energy spokes|spokes_and_rims]
        [--no-cgal] [--rebuild-cgal] [--cgal-weights deformkit|cgal]
        [--cgal-max-iterations 2000] [--markdown FILE]

Scenarios: names or JSON paths (default: every scenario in ../shared/scenarios). Each handle
moves rigidly by its "translate"; fixed vertices stay. The ROI is every vertex that lies in a
triangle plus the constrained ones (a free vertex in no triangle, as in the Stanford bunny,
stays at rest: it has no ARAP cell and would make CGAL's matrix singular); for meshes without
such vertices that is all vertices.

Rows (DeformKit): deformkit.ARAP with default options (acceleration="newton": Newton steps),
ARAP Anderson (acceleration="anderson": accelerated local/global iterations), ARAP plain
(acceleration="none"), both of the first run to their own tolerance (1e-6), LaplacianEdit
with detail="local_frame" and with the default detail="fixed", Falloff (defaults). Columns:
  bind        constructor time (cells, constraints, assembly, CHOLMOD analysis and
              factorization), best of --repeat; for CGAL: preprocess() (region of solution,
              assembly, SparseLU factorization), best of --repeat fresh objects
  per it      time per iteration: ARAP from cold fixed-count solves (t(1 + K) - t(1)) / K,
              K = 30 (Newton: K = 10, its steps cost as much as many local/global
              iterations); direct methods: the solve time divided by the iterations they report;
              CGAL: median deform(1, 0) call
  its, time   ARAP / CGAL: iterations and wall time (solve only, no bind / preprocess) to come
              within 1% of the converged energy E*, found by bisection on max_iterations
              (cold solves; the energy of accepted iterates never increases); DeformKit's count
              excludes the cold start's initial identity-rotation global step (its cost is in
              the time), CGAL's first iteration is that step. Direct methods: one solve
              (iterations as reported: LaplacianEdit local_frame reports 2 linear solves).
  E/E*        ARAP energy (deformkit.ARAP.energy of the positions: spokes cells, clamped
              cotangent weights, rotations recomputed) relative to E*, at the 1% point for the
              iterative rows, of the result for the direct methods
  con. err    max distance of a handle or fixed vertex from its target, / bbox diagonal
  edge RMS    relative RMS edge-length change (Dey et al.): sqrt(mean(((|e'| - |e|)/|e|)^2))
              over the unique edges of the mesh
E* comes from a long plain run (tolerance 1e-12, --ref-iterations), checked against an
Anderson run to tolerance 1e-12 (the lower of the two is E*; both are printed).

CGAL reference: scripts/cgal_arap/cgal_arap.cpp (ORIGINAL_ARAP, every ROI vertex, fixed and
handle vertices as control vertices, CGAL's default solver Eigen SparseLU: CGAL keeps the
constrained vertices as identity rows, so its matrix is not symmetric and CGAL's Cholesky
option would need the constrained columns moved to the right-hand side first). Built with g++
into build/cgal_arap/ and rebuilt only when the source is newer (or --rebuild-cgal). CGAL's
ORIGINAL_ARAP weight (CGAL::Weights::Cotangent_weight) clamps each triangle's cot/2 at 0
before summing, DeformKit's clamped_cotangent clamps the sum: they differ on edges opposite an
obtuse angle (12.5% of the armadillo's edges). So by default the program passes DeformKit's
weight through CGAL's weight-calculator template parameter and both minimise the same energy;
--cgal-weights cgal runs CGAL's own weights instead (same cost per iteration, different
minimiser: its E/E* then stays above 1). The program streams its positions after every
deform(1, 0) call and waits, so the energy evaluation here never overlaps CGAL's timed work;
the reported CGAL timings come from unstreamed runs of the same number of iterations (best of
--repeat, each with preprocess() best of --repeat).
Without g++ or the CGAL / Eigen / Boost headers a note is printed and only DeformKit rows are
shown.

Targets (stated for the armadillo, checked on every scenario): bind <= CGAL preprocess; a
local/global iteration (Anderson, the kind CGAL does) <= 1/3 of CGAL's; within 1% of E* (default options) in <= 1/10 of CGAL's time to
the same point; a warm-started re-solve after a small handle move (0.2% of the bbox diagonal
further along the drag, from the default-options solution), run to convergence (the default
tolerance), under 50 ms; the table also shows the same size of move along +y, and the printed
warm lines re-solves capped at 2 iterations and from a converged (1e-10) solution.

Converged drag (--drag-steps N, default 20; 0 skips it): the handles move from rest to their
translation in N equal steps, each solved warm to the default tolerance, as the add-on does
while an artist drags; per acceleration: the median time of steps 2..N, the iterations in all,
and how far each step's result is from that step's true minimum (a cold Anderson solve to
tolerance 1e-13): energy gap (E - E_min) / E_min and max vertex distance / bbox diagonal,
median and max over the steps. Both solvers stop on their tolerance, not on these numbers.

OPENBLAS_NUM_THREADS defaults to 1 (set before deformkit is imported), as for the other
measurements in docs/; the machine's load moves wall times, so re-run before quoting.
"""
import argparse
import glob
import os
import shutil
import subprocess
import sys
import time

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")

import numpy as np  # noqa: E402

HERE = os.path.dirname(os.path.abspath(__file__))
ROOT = os.path.dirname(HERE)
sys.path.insert(0, HERE)
import bench_common as bc  # noqa: E402
import deformkit  # noqa: E402

CGAL_SOURCE = os.path.join(HERE, "cgal_arap", "cgal_arap.cpp")
WITHIN = 0.01           # "within 1% of the converged energy"
MOVE = 0.002            # warm re-solve: handle moved by this fraction of the bbox diagonal
PER_IT_COUNT = 30       # K of the per-iteration timing


# ------------------------------------------------------------------------- scenario -------

class Case:
    def __init__(self, spec):
        path = spec if spec.endswith(".json") else os.path.join(bc.SHARED, "scenarios",
                                                                  spec + ".json")
        self.path = os.path.abspath(path)
        sc, self.V, self.F = bc.load_scenario(self.path)
        self.name = sc.get("name", os.path.basename(path)[:-5])
        self.mesh = deformkit.Mesh(self.V, self.F)
        self.handles = [np.asarray(h["vertices"], np.int64) for h in sc["handles"]]
        self.translate = [np.asarray(h["translate"], float) for h in sc["handles"]]
        self.fixed = np.asarray(sc["fixed"], np.int64)
        self.targets = np.vstack([self.V[h] + t for h, t in zip(self.handles, self.translate)])
        in_tri = np.zeros(len(self.V), bool)
        in_tri[self.F.ravel()] = True
        in_tri[self.fixed] = True
        for h in self.handles:
            in_tri[h] = True
        self.roi = None if in_tri.all() else np.flatnonzero(in_tri)
        self.n_outside = int((~in_tri).sum())
        self.bbox = float(np.linalg.norm(self.V.max(0) - self.V.min(0)))
        self.edges = np.asarray(self.mesh.edges, np.int64)
        self.l0 = np.linalg.norm(self.V[self.edges[:, 0]] - self.V[self.edges[:, 1]], axis=1)
        self.con_idx = np.concatenate([self.fixed] + self.handles)
        self.con_tgt = np.vstack([self.V[self.fixed], self.targets])
        # The small move of the warm re-solve: further along each handle's drag.
        self.moved = np.vstack([self.V[h] + t * (1.0 + MOVE * self.bbox / np.linalg.norm(t))
                                for h, t in zip(self.handles, self.translate)])
        # ... and one of the same size along +y, which is not the drag direction
        self.moved_y = self.targets + np.array([0.0, MOVE * self.bbox, 0.0])

    def kw(self):
        return dict(fixed=self.fixed, roi=self.roi)

    def constraint_error(self, x):
        return float(np.linalg.norm(x[self.con_idx] - self.con_tgt, axis=1).max() / self.bbox)

    def edge_change(self, x):
        l1 = np.linalg.norm(x[self.edges[:, 0]] - x[self.edges[:, 1]], axis=1)
        ok = self.l0 > 0
        return float(np.sqrt(np.mean(((l1[ok] - self.l0[ok]) / self.l0[ok]) ** 2)))


def timed(f, *a, **k):
    t0 = time.perf_counter()
    r = f(*a, **k)
    return time.perf_counter() - t0, r


def best_of(n, f):
    """Best wall time of n calls of f() and the last result."""
    best, r = float("inf"), None
    for _ in range(n):
        t, r = timed(f)
        best = min(best, t)
    return best, r


class Row:
    def __init__(self, method, **kw):
        self.method = method
        self.bind = self.per_it = self.its = self.time = None
        self.e_ratio = self.con_err = self.edge = None
        self.note = ""
        self.__dict__.update(kw)

    def quality(self, case, x, energy_fn, e_star):
        self.e_ratio = energy_fn(x) / e_star
        self.con_err = case.constraint_error(x)
        self.edge = case.edge_change(x)


# ------------------------------------------------------------------------- DeformKit ------

def arap(case, energy, **kw):
    return deformkit.ARAP(case.mesh, case.handles, energy=energy, **case.kw(), **kw)


def converged_energy(case, args):
    t, r = timed(lambda: arap(case, args.energy, acceleration="none", tolerance=1e-12,
                              max_iterations=args.ref_iterations).solve(case.targets,
                                                                         warm_start=False))
    ta, ra = timed(lambda: arap(case, args.energy, tolerance=1e-12, acceleration="anderson",
                                max_iterations=args.ref_iterations).solve(case.targets,
                                                                          warm_start=False))
    print(f"  E*: plain {r.energy:.10g} ({r.iterations} iterations, converged={r.converged}, "
          f"{t:.1f} s); Anderson {ra.energy:.10g} ({ra.iterations} iterations, {ta:.1f} s); "
          f"relative difference {(r.energy - ra.energy) / ra.energy:.1e}")
    return min(r.energy, ra.energy)


def first_within(solve, goal, kmax):
    """Smallest k <= kmax with solve(k).energy <= goal (energies non-increasing in k), by
    doubling then bisection; None if solve(kmax) is still above."""
    lo, hi = 0, 1
    while solve(hi).energy > goal:
        if hi >= kmax:
            return None
        lo, hi = hi, min(2 * hi, kmax)
    while hi - lo > 1:
        mid = (lo + hi) // 2
        if solve(mid).energy <= goal:
            hi = mid
        else:
            lo = mid
    return hi


def arap_iterative_row(case, label, e_star, energy_fn, args, **kw):
    row = Row(label)
    row.bind, _ = best_of(args.repeat, lambda: arap(case, args.energy, **kw))
    obj = arap(case, args.energy, tolerance=0.0, max_iterations=10 ** 6, **kw)

    def solve(k):
        return obj.solve(case.targets, warm_start=False, max_iterations=k)

    count = PER_IT_COUNT if kw.get("acceleration", "newton") != "newton" else 10
    t1, _ = best_of(args.repeat, lambda: solve(1))
    tk, _ = best_of(args.repeat, lambda: solve(1 + count))
    row.per_it = (tk - t1) / count
    k = first_within(solve, (1 + WITHIN) * e_star, args.ref_iterations)
    if k is None:
        row.note = f"not within 1% after {args.ref_iterations} iterations"
        r = solve(args.ref_iterations)
    else:
        row.its = k
        row.time, r = best_of(args.repeat, lambda: solve(k))
    row.quality(case, r.positions, energy_fn, e_star)
    return row


def arap_default_rows(case, e_star, energy_fn, args, label, **kw):
    """Options `kw` run to their own tolerance, and the warm re-solves after a small move
    (folded in from the former scripts/measure_arap.py, now removed)."""
    row = Row(label)
    obj = arap(case, args.energy, **kw)
    row.time, r = best_of(args.repeat, lambda: obj.solve(case.targets, warm_start=False))
    row.its = r.iterations
    row.per_it = row.time / max(r.iterations, 1)
    row.quality(case, r.positions, energy_fn, e_star)
    row.note = "" if r.converged else "not converged within max_iterations=100"

    # Reference minima for the moved targets.
    ref = arap(case, args.energy, tolerance=1e-12, max_iterations=args.ref_iterations,
               acceleration="anderson")
    ref.solve(case.targets, warm_start=False)
    e_moved = ref.solve(case.moved, warm_start=True).energy
    ref.solve(case.targets, warm_start=False)
    e_moved_y = ref.solve(case.moved_y, warm_start=True).energy

    def warm_after(prepare, moved=case.moved, **solve_kw):
        best, res = float("inf"), None
        for _ in range(args.repeat):
            prepare()
            t, res = timed(lambda: obj.solve(moved, warm_start=True, **solve_kw))
            best = min(best, t)
        return best, res

    from_default = lambda: obj.solve(case.targets, warm_start=False, tolerance=1e-6)
    from_tight = lambda: obj.solve(case.targets, warm_start=False, tolerance=1e-10,
                                   max_iterations=1000)
    warm = {}
    warm["default"] = warm_after(from_default, tolerance=1e-6)
    warm["capped2"] = warm_after(from_default, tolerance=1e-6, max_iterations=2)
    warm["y"] = warm_after(from_default, moved=case.moved_y, tolerance=1e-6)
    for tol in (1e-6, 1e-5, 1e-4):
        warm[f"tight{tol:g}"] = warm_after(from_tight, tolerance=tol)
    obj.solve(case.targets, warm_start=False, tolerance=1e-6)  # leave the default tolerance
    lines = []
    for key, label in (("default", "from the default-options solution, to tolerance 1e-6"),
                       ("capped2", "same, capped at 2 iterations"),
                       ("y", "the same size of move along +y instead, to tolerance 1e-6"),
                       ("tight1e-06", "from a converged (1e-10) solution, to tolerance 1e-6"),
                       ("tight1e-05", "same, to tolerance 1e-5"),
                       ("tight0.0001", "same, to tolerance 1e-4")):
        t, res = warm[key]
        e_min = e_moved_y if key == "y" else e_moved
        lines.append(f"    {label}: {res.iterations} it, {t * 1e3:.1f} ms, converged="
                     f"{res.converged}, energy {res.energy / e_min - 1:.1e} above the moved "
                     f"minimum")
    return row, (warm["default"], warm["y"]), lines


def drag_rows(case, args):
    """The converged drag (see the module docstring): {acceleration: dict of figures}."""
    n = args.drag_steps
    steps = [np.vstack([case.V[h] + t * k / n for h, t in zip(case.handles, case.translate)])
             for k in range(1, n + 1)]
    ref = arap(case, args.energy, acceleration="anderson", tolerance=1e-13,
               max_iterations=args.ref_iterations)
    refs = [ref.solve(t, warm_start=False) for t in steps]
    out = {}
    for acc in ("newton", "anderson"):
        obj = arap(case, args.energy, acceleration=acc, max_iterations=1000)
        obj.solve(case.V[np.concatenate(case.handles)], warm_start=False)  # bound at rest
        times, its, gaps, errs, conv = [], 0, [], [], True
        for t, r0 in zip(steps, refs):
            dt, r = timed(lambda: obj.solve(t, warm_start=True))
            times.append(dt)
            its += r.iterations
            conv &= r.converged
            gaps.append((r.energy - r0.energy) / r0.energy)
            errs.append(float(np.abs(np.asarray(r.positions) - r0.positions).max()) / case.bbox)
        out[acc] = dict(median_ms=1e3 * float(np.median(times[1:])), max_ms=1e3 * max(times[1:]),
                        iterations=its, gap_median=float(np.median(gaps)), gap_max=max(gaps),
                        err_median=float(np.median(errs)), err_max=max(errs), converged=conv)
    return out


def drag_table(results, args):
    out = [f"Converged drag ({args.drag_steps} steps, each warm to tolerance 1e-6; gap and "
           "error against each step's true minimum, median / max over the steps):", "",
           "| scenario | solver | step median ms (max) | iterations | energy gap | "
           "max vertex error / bbox |", "| --- | --- | --- | --- | --- | --- |"]
    for case, _, _, drag in results:
        for acc, d in (drag or {}).items():
            out.append(f"| {case.name} | {acc} | {d['median_ms']:.1f} ({d['max_ms']:.0f}) | "
                       f"{d['iterations']}{'' if d['converged'] else ' (not all converged)'} | "
                       f"{d['gap_median']:.1e} / {d['gap_max']:.1e} | "
                       f"{d['err_median']:.1e} / {d['err_max']:.1e} |")
    return out


def direct_row(case, label, cls, e_star, energy_fn, args, **kw):
    row = Row(label)
    row.bind, obj = best_of(args.repeat, lambda: cls(case.mesh, case.handles, **case.kw(), **kw))
    row.time, r = best_of(max(args.repeat, 5), lambda: obj.solve(case.targets))
    row.its = r.iterations
    row.per_it = row.time / max(r.iterations, 1)
    row.quality(case, r.positions, energy_fn, e_star)
    return row


# ------------------------------------------------------------------------- CGAL -----------

def cgal_binary(args):
    """Path of the CGAL reference program, building it when needed; (None, reason) when it
    cannot be built."""
    out_dir = os.path.join(args.build_dir, "cgal_arap")
    exe = os.path.join(out_dir, "cgal_arap")
    if (os.path.exists(exe) and not args.rebuild_cgal
            and os.path.getmtime(exe) >= os.path.getmtime(CGAL_SOURCE)):
        return exe, None
    cxx = shutil.which(os.environ.get("CXX", "g++"))
    if not cxx:
        return None, "no C++ compiler (g++) found"
    eigen = next((d for d in ("/usr/include/eigen3", "/usr/local/include/eigen3")
                  if os.path.exists(os.path.join(d, "Eigen", "SparseLU"))), None)
    cflags = []
    if shutil.which("pkg-config"):
        p = subprocess.run(["pkg-config", "--cflags", "eigen3"], capture_output=True, text=True)
        if p.returncode == 0:
            cflags = p.stdout.split()
    if not cflags and eigen:
        cflags = ["-I" + eigen]
    os.makedirs(out_dir, exist_ok=True)
    tmp = exe + ".tmp"
    cmd = [cxx, "-std=c++17", "-O3", "-DNDEBUG", "-DCGAL_EIGEN3_ENABLED", *cflags,
           CGAL_SOURCE, "-o", tmp]
    print("building the CGAL reference (slow, cached afterwards): " + " ".join(cmd),
          flush=True)
    t, p = timed(subprocess.run, cmd, capture_output=True, text=True)
    if p.returncode != 0:
        lines = p.stderr.splitlines()
        shown = [l for l in lines if "error" in l][:4] or lines[-4:]
        return None, ("building the CGAL reference failed (exit status "
                      f"{p.returncode}; are the CGAL, Eigen 3 and Boost headers installed?)"
                      + "".join("\n    " + l[:200] for l in shown))
    os.replace(tmp, exe)
    print(f"  built in {t:.0f} s: {exe}")
    return exe, None


def _cgal_process(exe, case, args, iterations, stream):
    cmd = [exe, case.path, "--weights", args.cgal_weights, "--max-iterations", str(iterations),
           "--preprocess-repeats", str(args.repeat if not stream else 1)]
    return subprocess.Popen(cmd + (["--stream"] if stream else []), stdin=subprocess.PIPE,
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE)


def _cgal_lines(p, case, on_positions=None):
    """Parses the program's output; returns (preprocess seconds, iteration times)."""
    pre, times = None, []
    while True:
        line = p.stdout.readline().decode()
        if not line:
            break
        tok = line.split()
        if tok[0] == "mesh" and (int(tok[1]), int(tok[2])) != (len(case.V), len(case.F)):
            raise RuntimeError(f"CGAL read {tok[1]} vertices / {tok[2]} triangles, "
                               f"expected {len(case.V)} / {len(case.F)}")
        elif tok[0] == "preprocess":
            pre = float(tok[1])
            if tok[2] != "1":
                raise RuntimeError("CGAL preprocess() failed")
        elif tok[0] == "iteration":
            times.append(float(tok[2]))
        elif tok[0] == "positions":
            nbytes = int(tok[1])
            buf = p.stdout.read(nbytes)
            if len(buf) != nbytes:
                raise RuntimeError("CGAL output truncated")
            go_on = on_positions(np.frombuffer(buf, np.float64).reshape(-1, 3))
            p.stdin.write(b"c\n" if go_on else b"q\n")
            p.stdin.flush()
            if not go_on:
                break
    return pre, times


def _cgal_finish(p, got_output):
    try:
        p.stdin.close()
    except BrokenPipeError:
        pass
    err = p.stderr.read().decode().strip()
    p.wait()
    if p.returncode != 0 or not got_output:
        raise RuntimeError(f"cgal_arap exited with {p.returncode}: {err}")


def run_cgal(exe, case, e_star, energy_fn, args):
    """CGAL row. Two runs of the program: a streamed one whose positions after every
    deform(1, 0) are evaluated here (finds the first iteration within 1% of E*), then a plain
    one of that many iterations whose timings are reported, so that CGAL's timed loop runs
    back to back as DeformKit's does (the evaluation between streamed iterations evicts its
    data from the caches)."""
    row = Row("CGAL ORIGINAL_ARAP" + (" (CGAL weights)" if args.cgal_weights == "cgal" else ""))
    goal = (1 + WITHIN) * e_star
    state = {"k": 0, "hit": None, "x": None}

    def on_positions(x):
        state["k"] += 1
        state["x"] = x
        if energy_fn(x) <= goal:
            state["hit"] = state["k"]
            return False
        return state["k"] < args.cgal_max_iterations

    p = _cgal_process(exe, case, args, args.cgal_max_iterations, True)
    try:
        _, times = _cgal_lines(p, case, on_positions)
    finally:
        _cgal_finish(p, True)
    if not times:
        raise RuntimeError("cgal_arap produced no iteration")
    row.quality(case, state["x"], energy_fn, e_star)
    k = state["hit"]
    best = None
    for _ in range(args.repeat):  # best of --repeat timed runs, as for DeformKit's solves
        p = _cgal_process(exe, case, args, k if k else min(len(times), 50), False)
        try:
            pre, times = _cgal_lines(p, case)
        finally:
            _cgal_finish(p, True)
        row.bind = pre if row.bind is None else min(row.bind, pre)
        if best is None or sum(times) < sum(best):
            best = times
    times = best
    row.per_it = float(np.median(times))
    if k:
        row.its, row.time = k, float(sum(times))
    else:
        row.note = f"not within 1% after {state['k']} iterations"
    return row


# ------------------------------------------------------------------------- output ---------

def fmt(v, kind):
    if v is None:
        return "-"
    if kind == "ms":
        return f"{v * 1e3:.2f}" if v < 0.01 else (f"{v * 1e3:.1f}" if v < 1 else f"{v * 1e3:.0f}")
    if kind == "s":
        return f"{v:.3f}" if v < 10 else f"{v:.1f}"
    if kind == "ratio":
        return f"{v:.4f}"
    if kind == "sci":
        return f"{v:.1e}"
    return str(v)


def scenario_table(case, rows):
    out = [f"### {case.name} ({len(case.V)} vertices, {len(case.F)} triangles, "
           f"{len(case.fixed)} fixed, {sum(len(h) for h in case.handles)} handle vertices)",
           "",
           "| method | bind ms | per it ms | its | time s | E/E* | con. err | edge RMS | note |",
           "| --- | --- | --- | --- | --- | --- | --- | --- | --- |"]
    for r in rows:
        out.append(f"| {r.method} | {fmt(r.bind, 'ms')} | {fmt(r.per_it, 'ms')} | "
                   f"{fmt(r.its, '')} | {fmt(r.time, 's')} | {fmt(r.e_ratio, 'ratio')} | "
                   f"{fmt(r.con_err, 'sci')} | {fmt(r.edge, 'ratio')} | {r.note} |")
    return out


def ratio_text(a, b):
    return "-" if a is None or b is None or b == 0 else f"{a / b:.3f}"


def targets_table(results):
    out = ["| scenario | target | DeformKit | CGAL | DK / CGAL | goal | met |",
           "| --- | --- | --- | --- | --- | --- | --- |"]
    for case, rows, warm, _ in results:
        dk = rows[0]
        lg = rows[1]  # Anderson: local/global iterations, the kind CGAL's are
        cg = next((r for r in rows if r.method.startswith("CGAL")), None)

        def line(target, a, b, goal, limit, unit):
            r = None if (a is None or b is None) else a / b
            met = "n/a (no CGAL)" if cg is None else (
                "n/a" if r is None else ("yes" if r <= limit else "**no**"))
            out.append(f"| {case.name} | {target} | {fmt(a, unit)} {unit} | "
                       f"{fmt(b, unit) + ' ' + unit if b is not None else '-'} | "
                       f"{ratio_text(a, b)} | {goal} | {met} |")

        line("bind vs preprocess", dk.bind, cg.bind if cg else None, "<= 1", 1.0, "ms")
        line("time per local/global iteration (Anderson)", lg.per_it,
             cg.per_it if cg else None, "<= 1/3", 1 / 3, "ms")
        line("time to within 1% of E* (defaults)", dk.time, cg.time if cg else None,
             "<= 1/10", 0.1, "s")
        for (t, res), how in zip(warm, ("further along the drag", "along +y")):
            ok = res.converged and t < 0.050
            out.append(f"| {case.name} | warm re-solve, {MOVE * 100:.1f}% move {how}, converged | "
                       f"{t * 1e3:.1f} ms ({res.iterations} it"
                       f"{'' if res.converged else ', not converged'}) | - | - | < 50 ms | "
                       f"{'yes' if ok else '**no**'} |")
    return out


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("scenarios", nargs="*")
    ap.add_argument("--repeat", type=int, default=3, help="timings: best of N (default 3)")
    ap.add_argument("--ref-iterations", type=int, default=3000,
                    help="iterations of the converged-energy runs (default 3000)")
    ap.add_argument("--energy", default="spokes", choices=("spokes", "spokes_and_rims"),
                    help="DeformKit ARAP energy; CGAL (ORIGINAL_ARAP) only runs for spokes")
    ap.add_argument("--no-cgal", action="store_true")
    ap.add_argument("--rebuild-cgal", action="store_true")
    ap.add_argument("--cgal-weights", default="deformkit", choices=("deformkit", "cgal"))
    ap.add_argument("--cgal-max-iterations", type=int, default=2000)
    ap.add_argument("--build-dir", default=os.path.join(ROOT, "build"))
    ap.add_argument("--markdown", help="also write the tables to this file")
    ap.add_argument("--drag-steps", type=int, default=20,
                    help="steps of the converged drag (0: skip it)")
    args = ap.parse_args()
    specs = args.scenarios or sorted(
        os.path.basename(p)[:-5] for p in glob.glob(os.path.join(bc.SHARED, "scenarios",
                                                                 "*.json")))
    print(f"deformkit {deformkit.__version__}, OPENBLAS_NUM_THREADS="
          f"{os.environ.get('OPENBLAS_NUM_THREADS')}, {os.cpu_count()} CPUs, load average "
          f"{' '.join(f'{x:.2f}' for x in os.getloadavg())}", flush=True)
    exe, why = None, "--no-cgal"
    if args.energy != "spokes":
        why = "CGAL's ORIGINAL_ARAP is the spokes energy; not compared for " + args.energy
    elif not args.no_cgal:
        exe, why = cgal_binary(args)
    if exe is None:
        print(f"NOTE: no CGAL reference ({why}); DeformKit rows only.", flush=True)

    results = []
    for spec in specs:
        case = Case(spec)
        print(f"\n== {case.name}: {len(case.V)} vertices, {len(case.F)} triangles, "
              f"{len(case.fixed)} fixed, {len(case.handles)} handle(s) of "
              f"{[len(h) for h in case.handles]} vertices"
              + (f", {case.n_outside} free vertices in no triangle left out of the ROI"
                 if case.n_outside else ""), flush=True)
        e_star = converged_energy(case, args)
        energy_fn = arap(case, args.energy).energy
        rows = [arap_iterative_row(case, "ARAP (defaults: Newton)", e_star, energy_fn, args),
                arap_iterative_row(case, "ARAP Anderson", e_star, energy_fn, args,
                                   acceleration="anderson"),
                arap_iterative_row(case, "ARAP plain", e_star, energy_fn, args,
                                   acceleration="none")]
        row, warm, warm_lines = arap_default_rows(case, e_star, energy_fn, args,
                                                  "ARAP defaults (Newton), to tolerance 1e-6")
        rows.append(row)
        row, _, warm_lines_a = arap_default_rows(case, e_star, energy_fn, args,
                                                 "ARAP Anderson, to tolerance 1e-6",
                                                 acceleration="anderson")
        rows.append(row)
        rows.append(direct_row(case, "LaplacianEdit local_frame", deformkit.LaplacianEdit,
                               e_star, energy_fn, args, detail="local_frame"))
        rows.append(direct_row(case, "LaplacianEdit (default: fixed)", deformkit.LaplacianEdit,
                               e_star, energy_fn, args))
        rows.append(direct_row(case, "Falloff (defaults)", deformkit.Falloff, e_star,
                               energy_fn, args))
        if exe:
            try:
                rows.append(run_cgal(exe, case, e_star, energy_fn, args))
            except (RuntimeError, OSError) as e:
                print(f"NOTE: CGAL failed on {case.name}: {e}", flush=True)
        print("\n".join(scenario_table(case, rows)[2:]))
        print(f"  warm re-solves after moving the handles {MOVE * 100:.1f}% of the bbox "
              f"diagonal further (default options: Newton):")
        print("\n".join(warm_lines), flush=True)
        print("  the same with Anderson:")
        print("\n".join(warm_lines_a), flush=True)
        drag = drag_rows(case, args) if args.drag_steps > 0 else None
        results.append((case, rows, warm, drag))
        if drag:
            print("\n".join(drag_table([results[-1]], args)[2:]), flush=True)

    cmd = " ".join(["PYTHONPATH=build/python /usr/bin/python3 scripts/bench_arap.py"]
                   + sys.argv[1:])
    md = [f"Command: `{cmd}`", ""]
    for case, rows, _, _ in results:
        md += scenario_table(case, rows) + [""]
    md += ["### Targets", ""] + targets_table(results)
    if args.drag_steps > 0:
        md += ["", "### Converged drag", ""] + drag_table(results, args)
    print("\n" + "\n".join(md))
    if args.markdown:
        with open(args.markdown, "w") as f:
            f.write("\n".join(md) + "\n")


if __name__ == "__main__":
    main()
