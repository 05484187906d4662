#!/usr/bin/python3
"""Core operator benchmark: DeformKit vs scipy on the armadillo (and ~1M vertices with --big).

usage: PYTHONPATH=build/python /usr/bin/python3 scripts/bench_core.py [--big] [--scipy-timeout S]
The module exposes no direct Cholesky: "factorize" is timed as HeatGeodesic construction
(cotangent Laplacian + mass + Cholesky analyze/factorize of M + tL); "solve" as one
HeatGeodesic.distance call (two back-substitutions + gradient/divergence).
"""
import argparse, os, resource, sys, time, multiprocessing as mp
import numpy as np
sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
import bench_common as bc
import deformkit


def t(f, *a, **k):
    t0 = time.perf_counter(); r = f(*a, **k); return time.perf_counter() - t0, r


def _eigsh(q, V, F, k):
    import scipy.sparse as sp, scipy.sparse.linalg as sla
    L, M = bc.cotangent_laplacian(V, F)
    t0 = time.perf_counter()
    sla.eigsh(L, k, sp.diags(M).tocsc(), sigma=-1e-8, which="LM")
    q.put(time.perf_counter() - t0)


def scipy_eigsh(V, F, k, timeout):
    q = mp.Queue(); p = mp.Process(target=_eigsh, args=(q, V, F, k)); p.start(); p.join(timeout)
    if p.is_alive():
        p.kill(); p.join(); return None
    return q.get()


def row(name, dk, sp_=None, target=None):
    f = lambda x: "-" if x is None else ("> cap" if x == "cap" else f"{x:.4f}")
    ratio = "-" if (sp_ is None or dk is None or sp_ == "cap") else f"{sp_ / dk:.1f}x"
    print(f"{name:<34}{f(dk):>10}{f(sp_):>12}{ratio:>9}  {target or ''}")


def bench(V, F, label, eig=True, timeout=120):
    import scipy.sparse as sp, scipy.sparse.linalg as sla
    print(f"\n== {label}: {len(V)} vertices, {len(F)} faces ==")
    print(f"{'job':<34}{'DK s':>10}{'scipy s':>12}{'ratio':>9}  target")
    tt, mesh = t(deformkit.Mesh, V, F.astype(np.int32))
    row("topology (Mesh)", tt, None, "(1M: topo+Lap < 2 s)")
    tl, _ = t(deformkit.cotangent_laplacian, mesh)
    ts, (L, M) = t(bc.cotangent_laplacian, V, F)
    row("cotangent assembly", tl, ts)
    th, heat = t(deformkit.HeatGeodesic, mesh)
    h = np.mean(np.linalg.norm(V[F[:, 0]] - V[F[:, 1]], axis=1)) ** 2
    A = (sp.diags(M) + h * L).tocsc()
    tf, lu = t(sla.splu, A)
    row("factorize (HeatGeodesic / splu)", th, tf, "armadillo < 0.15 s")
    B = np.random.rand(len(V), 3)
    td, _ = t(heat.distance, [0])
    tss, _ = t(lu.solve, B)
    row("solve (1 heat query / splu 3-RHS)", td, tss, "3-RHS < 8 ms")
    src = np.random.default_rng(0).choice(len(V), 100, replace=False)
    tg, _ = t(lambda: [heat.distance([int(s)]) for s in src])
    row("heat geodesics, 100 sources", tg, None)
    if eig:
        for k, tgt in ((50, "< 1.5 s"), (300, "< 10 s, >= 5x scipy")):
            te, _ = t(deformkit.laplacian_eigenpairs, mesh, k)
            tsp = scipy_eigsh(V, F, k, timeout)
            row(f"{k} eigenpairs", te, "cap" if tsp is None else tsp, tgt + (f" (scipy cap {timeout} s)" if tsp is None else ""))
    print(f"peak RSS of this process: {resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024:.0f} MB")


def _factor_peak(q, V, F):
    m = deformkit.Mesh(V, F.astype(np.int32)); deformkit.HeatGeodesic(m)
    q.put(resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024)


def main():
    ap = argparse.ArgumentParser(); ap.add_argument("--big", action="store_true")
    ap.add_argument("--scipy-timeout", type=float, default=120)
    a = ap.parse_args()
    V, F = bc.load_obj(os.path.join(bc.SHARED, "meshes", "armadillo.obj"))
    bench(V, F, "armadillo", timeout=a.scipy_timeout)
    if a.big:
        while len(V) < 500_000:  # 43k -> 173k -> 692k
            V, F = bc.midpoint_subdivide(V, F)
        bench(V, F, "subdivided armadillo", eig=False, timeout=a.scipy_timeout)
        ctx = mp.get_context("spawn")  # fresh process: peak RSS of the factorization alone, no fork-after-threads hang
        q = ctx.Queue(); p = ctx.Process(target=_factor_peak, args=(q, V, F)); p.start(); p.join()
        print(f"1M factorization subprocess peak RSS: {q.get():.0f} MB (target < 2048 MB)")


if __name__ == "__main__":
    main()
