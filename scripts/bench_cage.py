"""Issue 40: the Cage method's bind and per-frame solve on the armadillo of armadillo-wave
(43,243 vertices) with a box cage of 98 vertices (5 points along each edge, the issue's
measure against Blender's Mesh Deform), and on a million points (the armadillo's, repeated
and jittered) with a 488-vertex box cage; mean value and Green coordinates, evaluated
exactly or on a grid (evaluation='auto' picks the grid at a million), double and single
weights; the whole process's peak RSS after each bind (the mesh's own arrays included;
its growth says little after a bigger run before it). Plain Python:

    PYTHONPATH=build/python /usr/bin/python3 scripts/bench_cage.py [--meshes armadillo,million]

A script, not a test: compare within one run (median of 10 solves).
"""
import argparse
import json
import os
import resource
import statistics
import time

import numpy as np

import deformkit as dk

HERE = os.path.dirname(os.path.abspath(__file__))
SHARED = os.environ.get("DEFORMKIT_SHARED", os.path.join(HERE, "..", "..", "shared"))


def armadillo():
    sc = json.load(open(os.path.join(SHARED, "scenarios", "armadillo-wave.json")))
    return dk.read_mesh(os.path.join(SHARED, "scenarios", sc["mesh"]))


def box_cage(v, n):
    """The surface of an n x n x n grid over the points' bounding box grown by a tenth: its
    n^3 - (n-2)^3 vertices and 12 (n-1)^2 triangles facing out."""
    lo, hi = v.min(axis=0), v.max(axis=0)
    pad = 0.1 * (hi - lo)
    lo, hi = lo - pad, hi + pad
    index, pts = {}, []
    for i in range(n):
        for j in range(n):
            for k in range(n):
                if 0 in (i, j, k) or n - 1 in (i, j, k):
                    index[(i, j, k)] = len(pts)
                    pts.append(lo + (hi - lo) * np.array([i, j, k]) / (n - 1))
    tris = []
    for axis in range(3):
        a, b = [d for d in range(3) if d != axis]
        for side in (0, n - 1):
            for s in range(n - 1):
                for t in range(n - 1):
                    def at(ds, dt):
                        key = [0, 0, 0]
                        key[axis], key[a], key[b] = side, s + ds, t + dt
                        return index[tuple(key)]
                    q = [at(0, 0), at(1, 0), at(1, 1), at(0, 1)]
                    tris += [[q[0], q[1], q[2]], [q[0], q[2], q[3]]]
    P, T = np.array(pts), np.array(tris)
    c = 0.5 * (lo + hi)
    nrm = np.cross(P[T[:, 1]] - P[T[:, 0]], P[T[:, 2]] - P[T[:, 0]])
    inward = np.einsum("ij,ij->i", nrm, P[T[:, 0]] - c) < 0
    T[inward] = T[inward][:, ::-1]
    return P, T


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--meshes", default="armadillo,million")
    ap.add_argument("--coordinates", default="mean_value,green")
    a = ap.parse_args()
    for which in a.meshes.split(","):
        if which == "armadillo":
            mesh, n_edge = armadillo(), 5
            runs = [("auto", "double"), ("grid", "double")]
        else:
            v = np.asarray(armadillo().vertices)
            rng = np.random.default_rng(1)
            pts = np.concatenate([v + rng.normal(scale=2e-3, size=v.shape)
                                  for _ in range(-(-1_000_000 // len(v)))])[:1_000_000]
            mesh, n_edge = dk.Mesh(pts, np.zeros((0, 3), np.int32)), 10
            runs = [("auto", "single"), ("auto", "double")]
        v = np.asarray(mesh.vertices)
        P, T = box_cage(v, n_edge)
        pulled = P.copy()
        pulled[:, 2] += 0.1 * np.ptp(v[:, 2]) * np.sin(3 * P[:, 0] / np.ptp(v[:, 0]))
        for coordinates in a.coordinates.split(","):
            for evaluation, weights in runs:
                rss0 = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss
                t0 = time.perf_counter()
                cage = dk.Cage(mesh, cage_vertices=P, cage_triangles=T, weights=weights,
                               coordinates=coordinates, evaluation=evaluation)
                bind_s = time.perf_counter() - t0
                rss = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss
                times = []
                for _ in range(10):
                    t0 = time.perf_counter()
                    cage.solve(pulled, energy=False)
                    times.append((time.perf_counter() - t0) * 1e3)
                print("%s: %d vertices, cage of %d vertices (%d triangles), %s, evaluation "
                      "%s, %s weights: bind %.2f s, solve median %.1f ms; the process's "
                      "peak RSS %.0f MB (grew %.0f MB)"
                      % (which, len(v), len(P), len(T), coordinates, evaluation, weights,
                         bind_s, statistics.median(times), rss / 1024.0, (rss - rss0) / 1024.0),
                      flush=True)
                del cage


if __name__ == "__main__":
    main()
