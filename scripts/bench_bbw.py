"""Bounded biharmonic weights (deformkit.bounded_biharmonic_weights): the volume domain at
several resolutions against the surface domain, on the armadillo (43,243 vertices), with 10
handles: points on the surface (both domains take them) and a chain of bones inside.

    PYTHONPATH=build/python /usr/bin/python3 scripts/bench_bbw.py [--repeat 3]

Prints per case the median seconds, the domain's size, the active-set iterations (the most a
handle took, and all handles') and how far the undivided sums were from 1. A script, not a
test: compare within one run.
"""
import argparse
import os
import statistics
import time

import numpy as np

import deformkit as dk

HERE = os.path.dirname(os.path.abspath(__file__))
MESH = os.path.join(HERE, "..", "..", "shared", "meshes", "armadillo.obj")


def chain(V, n):
    c = V.mean(axis=0)
    _, _, vt = np.linalg.svd(V - c, full_matrices=False)
    t = (V - c) @ vt[0]
    ts = np.linspace(np.quantile(t, 0.1), np.quantile(t, 0.9), n + 1)
    J = np.array([c + s * vt[0] for s in ts])
    return np.stack([J[:-1], J[1:]], axis=1)


def main():
    p = argparse.ArgumentParser()
    p.add_argument("--repeat", type=int, default=3)
    a = p.parse_args()
    m = dk.read_mesh(MESH)
    V = np.asarray(m.vertices)
    points = V[np.random.default_rng(1).choice(len(V), 10, replace=False)]
    bones = chain(V, 10)
    cases = [("points", "surface", 32, dict(points=points))]
    for r in (16, 24, 32, 48):
        cases.append(("points", "volume", r, dict(points=points)))
    for r in (16, 24, 32, 48):
        cases.append(("bones", "volume", r, dict(bones=bones)))
    print("armadillo, %d vertices, 10 handles" % len(V))
    print("| handles | domain | resolution | seconds | domain vertices | iterations (max, all) "
          "| sum before division |")
    print("| --- | --- | --- | --- | --- | --- | --- |")
    for handles, domain, res, kw in cases:
        times = []
        try:
            for _ in range(a.repeat):
                t0 = time.perf_counter()
                W, rep = dk.bounded_biharmonic_weights(m, domain=domain, resolution=res,
                                                       report=True, **kw)
                times.append(time.perf_counter() - t0)
        except RuntimeError as e:  # the surface's active sets may not settle
            print("| %s | %s | %s | %.2f | - | %s | - |" % (
                handles, domain, res if domain == "volume" else "-",
                time.perf_counter() - t0, str(e).split(": ")[-1]), flush=True)
            continue
        print("| %s | %s | %s | %.2f | %d | %d, %d | %.2g |"
              % (handles, domain, res if domain == "volume" else "-", statistics.median(times),
                 rep["domain_vertices"], rep["max_iterations"], rep["total_iterations"],
                 rep["sum_deviation"]), flush=True)


if __name__ == "__main__":
    main()
