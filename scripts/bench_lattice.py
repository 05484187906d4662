"""Issue 40: the Lattice method's bind and per-frame solve, per interpolation, on the
armadillo of armadillo-wave (43,243 vertices), the ogre of ../shared/meshes (62,194) and a
million points (the armadillo's, repeated and jittered), with a 4 x 4 x 4 lattice (the points bent about x, a smooth non-affine edit), and
the bind's peak memory against the estimate. Plain Python, no Blender:

    PYTHONPATH=build/python /usr/bin/python3 scripts/bench_lattice.py [--meshes armadillo,ogre,million]

A script, not a test: compare within one run (median of 10 solves).
"""
import argparse
import json
import math
import os
import resource
import statistics
import time

import numpy as np

import deformkit as dk

HERE = os.path.dirname(os.path.abspath(__file__))
SHARED = os.environ.get("DEFORMKIT_SHARED", os.path.join(HERE, "..", "..", "shared"))


def load(which):
    if which == "million":   # the armadillo's vertices repeated, jittered: a million points
        v = np.asarray(load("armadillo").vertices)
        rng = np.random.default_rng(1)
        reps = -(-1_000_000 // len(v))
        pts = np.concatenate([v + rng.normal(scale=2e-3, size=v.shape) for _ in range(reps)])
        return dk.Mesh(pts[:1_000_000], np.zeros((0, 3), dtype=np.int32))
    if which == "armadillo":
        sc = json.load(open(os.path.join(SHARED, "scenarios", "armadillo-wave.json")))
        return dk.read_mesh(os.path.join(SHARED, "scenarios", sc["mesh"]))
    verts, sizes, idx = dk.load_mesh_file(os.path.join(SHARED, "meshes", which + ".obj"))
    return dk.Mesh.from_polygons(verts, sizes, idx)


def bend(rest, amount):
    lo, hi = rest.min(axis=0), rest.max(axis=0)
    c = 0.5 * (lo + hi)
    a = amount * (rest[:, 2] - lo[2]) / (hi[2] - lo[2])
    out = rest.copy()
    out[:, 1] = c[1] + np.cos(a) * (rest[:, 1] - c[1]) - np.sin(a) * (rest[:, 2] - c[2])
    out[:, 2] = c[2] + np.sin(a) * (rest[:, 1] - c[1]) + np.cos(a) * (rest[:, 2] - c[2])
    return out


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--meshes", default="armadillo,ogre,million")
    a = ap.parse_args()
    for which in a.meshes.split(","):
        mesh = load(which)
        n = mesh.n_vertices
        print("%s: %d vertices" % (which, n), flush=True)
        for interp in ("linear", "bspline", "bernstein"):
            est = dk.Lattice.estimate_memory(mesh, interpolation=interp)
            rss0 = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss
            t0 = time.perf_counter()
            lat = dk.Lattice(mesh, resolution=(4, 4, 4), interpolation=interp)
            bind_ms = (time.perf_counter() - t0) * 1e3
            P = bend(np.asarray(lat.rest_points), math.radians(40))
            times = []
            for _ in range(10):
                t0 = time.perf_counter()
                lat.solve(P, energy=False)
                times.append((time.perf_counter() - t0) * 1e3)
            rss = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss
            print("  %-9s bind %7.1f ms, solve median %7.2f ms (%d vertices/ms); estimate "
                  "%.0f MB, peak RSS grew %.0f MB" % (
                      interp, bind_ms, statistics.median(times), n / statistics.median(times),
                      est / 2**20, max(rss - rss0, 0) / 1024.0), flush=True)
            del lat


main()
