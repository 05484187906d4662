#!/usr/bin/python3
"""Mesh/scenario loading and timing helpers for the DeformKit benchmarks (numpy only)."""
import json
import os
import time

import numpy as np

HERE = os.path.dirname(os.path.abspath(__file__))
SHARED = os.path.normpath(os.path.join(HERE, "..", "..", "shared"))


def best(fn, repeat):
    """(fn()'s last result, its best wall time in seconds over `repeat` calls)."""
    out, t = None, float("inf")
    for _ in range(repeat):
        t0 = time.perf_counter()
        out = fn()
        t = min(t, time.perf_counter() - t0)
    return out, t


def load_obj(path):
    """Vertices and triangles in file order (faces fan-triangulated)."""
    V, F = [], []
    with open(path) as f:
        for line in f:
            if line.startswith("v "):
                V.append([float(x) for x in line.split()[1:4]])
            elif line.startswith("f "):
                idx = [int(t.split("/")[0]) for t in line.split()[1:]]
                idx = [i - 1 if i > 0 else len(V) + i for i in idx]
                for k in range(1, len(idx) - 1):
                    F.append([idx[0], idx[k], idx[k + 1]])
    return np.array(V, float), np.array(F, np.int64)


def load_scenario(name):
    """A scenario of ../shared/scenarios by name (without .json), or a path to a JSON file."""
    path = name if name.endswith(".json") else os.path.join(SHARED, "scenarios", name + ".json")
    with open(path) as f:
        s = json.load(f)
    V, F = load_obj(os.path.normpath(os.path.join(os.path.dirname(path), s["mesh"])))
    return s, V, F


def midpoint_subdivide(V, F):
    """1-to-4 midpoint subdivision: n -> n + edges vertices, m -> 4m faces."""
    E = np.sort(np.concatenate([F[:, [0, 1]], F[:, [1, 2]], F[:, [2, 0]]]), axis=1)
    uE, inv = np.unique(E, axis=0, return_inverse=True)
    inv = inv.reshape(-1)
    m = len(F)
    mid = len(V) + inv
    a, b, c = mid[:m], mid[m:2 * m], mid[2 * m:]
    V2 = np.vstack([V, 0.5 * (V[uE[:, 0]] + V[uE[:, 1]])])
    F2 = np.vstack([np.c_[F[:, 0], a, c], np.c_[F[:, 1], b, a],
                    np.c_[F[:, 2], c, b], np.c_[a, b, c]])
    return V2, F2.astype(np.int64)


def cotangent_laplacian(V, F):
    """PSD cotangent Laplacian (scipy.sparse csc) and Voronoi-ish (barycentric) mass."""
    import scipy.sparse as sp
    n = len(V)
    L_rows, L_cols, L_vals = [], [], []
    for k in range(3):
        i, j, o = F[:, (k + 1) % 3], F[:, (k + 2) % 3], F[:, k]
        u, v = V[i] - V[o], V[j] - V[o]
        cot = np.einsum("ij,ij->i", u, v) / np.linalg.norm(np.cross(u, v), axis=1)
        w = 0.5 * cot
        L_rows += [i, j, i, j]; L_cols += [j, i, i, j]; L_vals += [-w, -w, w, w]
    L = sp.csc_matrix((np.concatenate(L_vals), (np.concatenate(L_rows), np.concatenate(L_cols))), shape=(n, n))
    area = 0.5 * np.linalg.norm(np.cross(V[F[:, 1]] - V[F[:, 0]], V[F[:, 2]] - V[F[:, 0]]), axis=1)
    M = np.bincount(F.ravel(), np.repeat(area / 3, 3), minlength=n)
    return L, M
