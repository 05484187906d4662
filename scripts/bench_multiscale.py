#!/usr/bin/python3
"""Issue 44: ARAP's multi-scale solve against the single level (docs/methods/arap.md,
"Multi-scale"; docs/benchmarks.md).

  OPENBLAS_NUM_THREADS=2 PYTHONPATH=build/python /usr/bin/python3 scripts/bench_multiscale.py \\
      [--subdivide 0,1,2] [--levels 1,0] [--trace]

The armadillo-wave drag (scripts/bench_scale.py's scenario: the armadillo midpoint-subdivided
0, 1 or 2 times, 43k / 173k / 692k vertices), solved cold from the bind pose to the default
tolerance, for each `levels` (1: the mesh alone; 0: automatic, a coarse level from 100k
vertices; 2: a coarse level at any size): the bind (and its coarse phase), the preview from
cold (time, energy over the minimum), the converged solve (time, Newton steps, energy), and
the largest distance between the levels' results. --trace prints the energy every 5 steps
(slices resumed with resume=True, which equal one solve). A script, not a test: compare
within one run (the machines' speed swings by tens of percent)."""
import argparse
import os
import resource
import sys
import time

import numpy as np

import deformkit as dk

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
from bench_scale import scenario  # noqa: E402


def bind(mesh, hand, fixed, levels):
    phases, last = {}, [time.perf_counter(), None]

    def progress(f):
        now = time.perf_counter()
        if last[1] is not None:
            phases[last[1]] = phases.get(last[1], 0.0) + now - last[0]
        last[0], last[1] = now, f.phase
        return False
    t0 = time.perf_counter()
    a = dk.ARAP(mesh, [hand], fixed=fixed, levels=levels, progress=progress)
    return a, time.perf_counter() - t0, phases.get("coarse", 0.0)


def solve(a, targets, trace):
    t0 = time.perf_counter()
    if not trace:
        r = a.solve(targets, warm_start=False)
        return r, time.perf_counter() - t0, r.iterations, []
    r = a.solve(targets, warm_start=False, max_iterations=5)
    steps, points = r.iterations, [(r.iterations, time.perf_counter() - t0, r.energy)]
    while not r.converged and steps < 1000:
        r = a.solve(targets, resume=True, max_iterations=5)
        steps += r.iterations
        points.append((steps, time.perf_counter() - t0, r.energy))
    return r, time.perf_counter() - t0, steps, points


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--subdivide", default="0,1,2")
    ap.add_argument("--levels", default="1,0")
    ap.add_argument("--trace", action="store_true")
    args = ap.parse_args()
    for sub in [int(s) for s in args.subdivide.split(",")]:
        V, F, fixed, hand, t = scenario("armadillo", sub)
        mesh = dk.Mesh(V, F)
        targets = V[hand] + t
        print("armadillo x%d: %d vertices" % (sub, len(V)), flush=True)
        results = {}
        for levels in [int(s) for s in args.levels.split(",")]:
            a, tb, tc = bind(mesh, hand, fixed, levels)
            coarse = a.stats["coarse_vertices"]
            t0 = time.perf_counter()
            p = a.solve(targets, warm_start=False, preview=True, energy=False)
            tp = time.perf_counter() - t0
            ep = a.energy(p.positions)
            r, ts, steps, points = solve(a, targets, args.trace)
            results[levels] = np.asarray(r.positions)
            peak = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024
            print("  levels=%d (coarse %s): bind %.2f s (coarse phase %.2f s); preview from "
                  "cold %.3f s at %.3fx; converged %.1f s, %d Newton steps, E %.10e%s; peak "
                  "%.0f MB" % (levels, coarse or "none", tb, tc, tp, ep / r.energy, ts, steps,
                               r.energy, "" if r.converged else " (not converged)", peak),
                  flush=True)
            if points:
                print("    trace (steps: s, E/E_end - 1): " + "  ".join(
                    "%d: %.0f s %.1e" % (k, tt, e / r.energy - 1) for k, tt, e in points),
                    flush=True)
            del a
        if len(results) > 1:
            X = list(results.values())
            diag = float(np.linalg.norm(np.ptp(V, axis=0)))
            print("  largest distance between the results: %.2e of the diagonal"
                  % (max(float(np.abs(x - X[0]).max()) for x in X[1:]) / diag), flush=True)


main()
