"""Issue 41: Shepard's bind and per-frame solve on the armadillo of armadillo-wave (43,243
vertices; the scenario's handles and fixed group) and on the armadillo midpoint-subdivided
twice (692k), for each neighbourhood and what it interpolates. Plain Python:

    PYTHONPATH=build/python /usr/bin/python3 scripts/bench_shepard.py

A script, not a test: compare within one run (median of 10 solves).
"""
import statistics
import sys
import time

import numpy as np

import deformkit as dk

sys.path.insert(0, __file__.rsplit("/", 1)[0])


def run(name, mesh, handles, fixed, t):
    T = np.repeat(np.eye(4)[None], len(handles), axis=0)
    T[:, :3, 3] = t
    for nb in ("all", "nearest"):
        for interp in ("transforms", "displacements"):
            t0 = time.perf_counter()
            s = dk.Shepard(mesh, handles=handles, fixed=fixed, neighbourhood=nb,
                           interpolate=interp)
            bind = time.perf_counter() - t0
            ts = []
            for _ in range(10):
                t0 = time.perf_counter()
                s.solve(transforms=T, energy=False)
                ts.append((time.perf_counter() - t0) * 1e3)
            print("%s: %d vertices, %d handle(s), neighbourhood %s, %s: bind %.0f ms, solve "
                  "median %.1f ms" % (name, mesh.n_vertices, len(handles), nb, interp,
                                      bind * 1e3, statistics.median(ts)), flush=True)


def main():
    import bench_scale as bs
    for levels in (0, 2):
        V, F, fixed, hand, t = bs.scenario("armadillo", levels)
        run("armadillo" if levels == 0 else "armadillo subdivided twice", dk.Mesh(V, F),
            [hand], fixed, t)


if __name__ == "__main__":
    main()
