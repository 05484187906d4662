#!/usr/bin/python3
"""Sparse factorizations as the methods use them: binds that factor once, and
EmbeddedDeformation's Gauss-Newton iterations, which factor a matrix every time.

    PYTHONPATH=build/python /usr/bin/python3 scripts/bench_factorize.py [--subdivide 0,1,2]

On the armadillo-wave scenario (scripts/bench_scale.py; the armadillo midpoint-subdivided 0,
1 or 2 times: 43k, 173k, 692k vertices): the bind of ARAP (one level), LinearReconstruction and
LaplacianEdit (ARAP alone at 692k), best of 3 at 43k and of 1 above; and at 43k the time of
one EmbeddedDeformation iteration with 220 and 1,000 nodes, (t(n iterations) - t(1)) / (n - 1),
best of 3. To compare two builds, run it once with each on PYTHONPATH, one after the other in
the same quiet hour (the machines' speed swings by tens of percent). docs/benchmarks.md,
"CHOLMOD's OpenMP regions", has the figures.
"""
import argparse
import os
import sys

import numpy as np

import deformkit as dk

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
from bench_common import best  # noqa: E402
from bench_scale import scenario  # noqa: E402


def binds(sub):
    V, F, fixed, hand, _ = scenario("armadillo", sub)
    mesh = dk.Mesh(V, F)
    repeat = 3 if sub == 0 else 1
    for name in ("ARAP", "LinearReconstruction", "LaplacianEdit"):
        if sub >= 2 and name != "ARAP":
            continue
        kw = {"levels": 1} if name == "ARAP" else {}
        _, t = best(lambda: getattr(dk, name)(mesh, handles=[hand], fixed=fixed, **kw), repeat)
        print("  %-21s %7d vertices: bind %.3f s" % (name, len(V), t), flush=True)


def embedded_iterations():
    V, F, fixed, hand, _ = scenario("armadillo", 0)
    mesh = dk.Mesh(V, F)
    diag = float(np.linalg.norm(V.max(0) - V.min(0)))
    handle = np.setdiff1d(hand, fixed)
    target = V[handle] + [0.0, 0.05 * diag, 0.0]
    for n_nodes in (220, 1000):
        ed = dk.EmbeddedDeformation(mesh, handles=[handle], fixed=fixed, n_nodes=n_nodes)
        full, tn = best(lambda: ed.solve(target, warm_start=False), 3)
        _, t1 = best(lambda: ed.solve(target, warm_start=False, max_iterations=1), 3)
        its = max(full.iterations, 2)
        print("  EmbeddedDeformation %5d nodes: %.2f ms an iteration (%d iterations)" % (
            len(ed.nodes), (tn - t1) / (its - 1) * 1e3, full.iterations), flush=True)


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--subdivide", default="0,1,2")
    a = ap.parse_args()
    for sub in [int(s) for s in a.subdivide.split(",")]:
        print("armadillo x%d" % sub, flush=True)
        binds(sub)
        if sub == 0:
            embedded_iterations()


if __name__ == "__main__":
    main()
