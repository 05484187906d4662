#!/usr/bin/python3
"""Core operator benchmark: DeformKit vs scipy on the armadillo (and ~1M vertices with --big).

usage: PYTHONPATH=build/python /usr/bin/python3 scripts/bench_core.py [--big] [--scipy-timeout S]

Jobs, each timed on DeformKit and, where scipy has the same job, on scipy in the same run:
  topology            deformkit.Mesh (validation, edges, one-rings, boundary, components)
  cotangent assembly  deformkit.cotangent_laplacian vs a numpy assembly
  Cholesky            deformkit.SparseCholesky of L + D (D: a constraint diagonal, 1e3 on every
                      100th vertex and 1e-6 elsewhere, the shape of a soft-constrained editing
                      system): analyze + factorize, refactorize (same pattern), a solve with
                      3 right-hand sides; scipy: splu of the same matrix (scipy has no sparse
                      Cholesky) and its 3-RHS solve
  heat geodesics      deformkit.HeatGeodesic (two factorizations kept), the distance from 100
                      source vertices (one query), and single-source queries
  eigenpairs          deformkit.laplacian_eigenpairs (cotangent L, Voronoi mass, tolerance
                      1e-10) vs scipy eigsh(L, k, M, sigma=-1e-8, which='LM') at its default
                      tol (machine precision) and at tol=1e-10, each in a subprocess capped
                      by --scipy-timeout
--big: the ogre (62k vertices) midpoint-subdivided twice, 992,608 vertices; no eigenpairs; the
peak memory of the factorization alone is measured in a fresh process.
"""
import argparse
import multiprocessing as mp
import os
import resource
import sys
import time

import numpy as np

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
import bench_common as bc  # noqa: E402
import deformkit  # noqa: E402


def timed(f, *a, **k):
    t0 = time.perf_counter()
    r = f(*a, **k)
    return time.perf_counter() - t0, r


def best_of(reps, f, *a, **k):
    best, r = None, None
    for _ in range(reps):
        t, r = timed(f, *a, **k)
        best = t if best is None else min(best, t)
    return best, r


def _eigsh(q, V, F, k, tol):
    import scipy.sparse as sp
    import scipy.sparse.linalg as sla
    L, M = bc.cotangent_laplacian(V, F)
    t0 = time.perf_counter()
    sla.eigsh(L, k, sp.diags(M).tocsc(), sigma=-1e-8, which="LM", tol=tol)
    q.put(time.perf_counter() - t0)


def scipy_eigsh(V, F, k, tol, timeout):
    q = mp.Queue()
    p = mp.Process(target=_eigsh, args=(q, V, F, k, tol))
    p.start()
    p.join(timeout)
    if p.is_alive():
        p.kill()
        p.join()
        return "cap"
    return q.get()


def row(name, dk, sp_=None, target=None):
    def f(x):
        return "-" if x is None else ("> cap" if x == "cap" else f"{x:.4f}")
    ratio = "-" if (sp_ is None or dk is None or sp_ == "cap") else f"{sp_ / dk:.1f}x"
    print(f"{name:<40}{f(dk):>10}{f(sp_):>12}{ratio:>9}  {target or ''}", flush=True)


def constraint_system(mesh):
    """Triplets of L + D (see the module docstring)."""
    r, c, v = deformkit.cotangent_laplacian(mesh)
    n = mesh.n_vertices
    d = np.full(n, 1e-6)
    d[::100] = 1e3
    return (np.concatenate([r, np.arange(n, dtype=r.dtype)]),
            np.concatenate([c, np.arange(n, dtype=c.dtype)]), np.concatenate([v, d]))


def bench(V, F, label, eig=True, timeout=120, reps=3):
    import scipy.sparse as sp
    import scipy.sparse.linalg as sla
    big = len(V) > 200_000
    print(f"\n== {label}: {len(V)} vertices, {len(F)} faces ==")
    print(f"{'job':<40}{'DK s':>10}{'scipy s':>12}{'ratio':>9}  target")
    F32 = F.astype(np.int32)
    tt, mesh = best_of(reps, deformkit.Mesh, V, F32)
    row("topology (Mesh)", tt, None, "1M: topology + Laplacian < 2 s" if big else "")
    tl, _ = best_of(reps, deformkit.cotangent_laplacian, mesh)
    ts, _ = timed(bc.cotangent_laplacian, V, F)
    row("cotangent assembly", tl, ts, f"topology + Laplacian = {tt + tl:.2f} s" if big else "")

    rows, cols, vals = constraint_system(mesh)
    n = len(V)
    A = sp.csc_matrix((vals, (rows, cols)), shape=(n, n))
    tf, chol = best_of(1 if big else reps, deformkit.SparseCholesky, rows, cols, vals, n)
    tsf, lu = timed(sla.splu, A)
    row("Cholesky analyze + factorize (L + D)", tf, tsf, "" if big else "< 0.15 s")
    tr, _ = best_of(1 if big else reps, chol.refactorize, vals * 1.5)
    row("  refactorize, same pattern", tr, None)
    chol.refactorize(vals)
    B = np.random.default_rng(0).standard_normal((n, 3))
    td, x = best_of(reps, chol.solve, B)
    tss, _ = timed(lu.solve, B)
    res = np.linalg.norm(A @ x - B) / np.linalg.norm(B)
    row("  solve, 3 right-hand sides", td, tss, ("" if big else "< 8 ms; ") +
        f"relative residual {res:.1e}")
    del lu

    th, heat = timed(deformkit.HeatGeodesic, mesh)
    row("heat geodesics: HeatGeodesic(mesh)", th, None)
    rng = np.random.default_rng(0)
    src = rng.choice(n, 100, replace=False)
    tg, _ = best_of(1 if big else reps, heat.distance, src)
    row("  distance from 100 sources (one query)", tg, None)
    one = rng.choice(n, 5, replace=False)
    tq, _ = timed(lambda: [heat.distance([int(s)]) for s in one])
    row("  single-source query (mean of 5)", tq / 5, None)
    del heat
    if eig:
        for k, tgt in ((50, "< 1.5 s"), (300, "< 10 s, >= 5x scipy")):
            te, _ = timed(deformkit.laplacian_eigenpairs, mesh, k)
            row(f"{k} eigenpairs (tol 1e-10)", te, scipy_eigsh(V, F, k, 0.0, timeout),
                tgt + " [scipy tol=0]")
            row(f"{k} eigenpairs, scipy at tol=1e-10", te,
                scipy_eigsh(V, F, k, 1e-10, timeout), "[same DeformKit run]")
    print(f"peak RSS of this process so far: "
          f"{resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024:.0f} MB")


def _vm_hwm_mb():
    """Peak resident set of this process image (VmHWM: reset by exec, unlike ru_maxrss,
    which a spawned child inherits from its parent)."""
    with open("/proc/self/status") as f:
        for line in f:
            if line.startswith("VmHWM:"):
                return int(line.split()[1]) / 1024.0
    return float("nan")


def _factor_peak(q, V, F):
    start = _vm_hwm_mb()
    mesh = deformkit.Mesh(V, F.astype(np.int32))
    rows, cols, vals = constraint_system(mesh)
    inputs = _vm_hwm_mb()
    chol = deformkit.SparseCholesky(rows, cols, vals, mesh.n_vertices)
    q.put((start, inputs, _vm_hwm_mb(), chol.stats["factor_bytes"] / 2**20))


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--big", action="store_true")
    ap.add_argument("--scipy-timeout", type=float, default=120)
    a = ap.parse_args()
    V, F = bc.load_obj(os.path.join(bc.SHARED, "meshes", "armadillo.obj"))
    bench(V, F, "armadillo", timeout=a.scipy_timeout)
    if a.big:
        V, F = bc.load_obj(os.path.join(bc.SHARED, "meshes", "ogre.obj"))
        for _ in range(2):  # 62k -> 248k -> 993k vertices
            V, F = bc.midpoint_subdivide(V, F)
        bench(V, F, "ogre subdivided twice", eig=False, timeout=a.scipy_timeout, reps=1)
        # a fresh process, so the peak is the factorization's (spawn: no fork after threads)
        ctx = mp.get_context("spawn")
        q = ctx.Queue()
        p = ctx.Process(target=_factor_peak, args=(q, V, F))
        p.start()
        start, inputs, peak, factor = q.get()
        p.join()
        print(f"factorization of L + D at {len(V)} vertices, fresh process: peak RSS "
              f"{peak:.0f} MB (interpreter + numpy {start:.0f} MB, with mesh and triplets "
              f"{inputs:.0f} MB; factor {factor:.0f} MB); target < 2048 MB")


if __name__ == "__main__":
    main()
