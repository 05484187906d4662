#!/usr/bin/env python3
"""Issue 19 item 4: each method's memory estimate against the measured peak.

    PYTHONPATH=build/python /usr/bin/python3 scripts/bench_memory.py \\
        [--meshes arm,armadillo] [--levels 0] [--methods ARAP,LaplacianEdit,...]

For every mesh and method, in a fresh process (spawn, so that the peak is its own): the
growth of the peak resident set (VmHWM) over the resident set before the bind, through the
bind and its first solve, next to `<Method>.estimate_memory(mesh)`; the ratio peak /
estimate must stay below 1 (the estimate is what a bind is refused by). --levels
midpoint-subdivides the meshes (bench_scale.py's scenario: the armadillo at 2 levels is
692k vertices; the ogre, 992,608, wants --drop-degenerate). A script, not a test: tests/python/test_memory.py checks the bound on the
arm.
"""
import argparse
import json
import multiprocessing as mp
import os
import sys
import time

import numpy as np

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
import bench_scale as bs  # noqa: E402


def status(key):
    with open("/proc/self/status") as f:
        for line in f:
            if line.startswith(key + ":"):
                return int(line.split()[1]) * 1024
    return 0


def measure(q, method, V, F, fixed, hand, t, options):
    try:
        import deformkit as dk
        mesh = dk.Mesh(V, F)
        cls = getattr(dk, method)
        est = cls.estimate_memory(mesh, **options)
        before = status("VmRSS")
        t0 = time.perf_counter()
        obj = cls(mesh, handles=[hand], fixed=fixed, **options)
        bind_s = time.perf_counter() - t0
        obj.solve(V[hand] + t, energy=False)
        q.put({"peak": status("VmHWM") - before, "estimate": est, "bind_s": bind_s})
    except Exception as ex:  # the parent waits on the queue: always answer
        q.put({"error": "%s: %s" % (type(ex).__name__, ex)})


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--meshes", default="arm,armadillo")
    ap.add_argument("--levels", type=int, default=0)
    ap.add_argument("--options", default="{}",
                    help='JSON keyword arguments for every method, e.g. '
                         '\'{"n_eigenvectors": 50, "refine": 0}\'')
    ap.add_argument("--drop-degenerate", action="store_true",
                    help="remove zero-area triangles before subdividing (the ogre has 4: "
                         "subdivided twice, they leave vertices on degenerate triangles "
                         "only, which EigenDeformation refuses)")
    ap.add_argument("--methods", default="ARAP,LaplacianEdit,Falloff,EmbeddedDeformation,"
                                         "EigenDeformation,LinearReconstruction")
    a = ap.parse_args()
    ctx = mp.get_context("spawn")
    print("| mesh | vertices | method | peak MiB | estimate MiB | peak / estimate | bind s |")
    print("| --- | --- | --- | --- | --- | --- | --- |")
    for name in a.meshes.split(","):
        if a.drop_degenerate:
            V, F, fixed, hand, t = bs.scenario(name, 0)
            area2 = np.linalg.norm(np.cross(V[F[:, 1]] - V[F[:, 0]], V[F[:, 2]] - V[F[:, 0]]), axis=1)
            F = F[area2 > 0.0]
            for _ in range(a.levels):
                V, F, (fixed, hand) = bs.subdivide_with_sets(V, F, (fixed, hand))
            F = F.astype(np.int32)
        else:
            V, F, fixed, hand, t = bs.scenario(name, a.levels)
        for method in a.methods.split(","):
            q = ctx.Queue()
            p = ctx.Process(target=measure, args=(q, method, V, F, fixed, hand, t,
                                                  json.loads(a.options)))
            p.start()
            r = q.get()
            p.join()
            if "error" in r:
                print("| %s | %d | %s | %s | | | |" % (name, len(V), method, r["error"]))
                continue
            print("| %s | %d | %s | %.0f | %.0f | %.2f | %.1f |" % (
                name, len(V), method, r["peak"] / 2**20, r["estimate"] / 2**20,
                r["peak"] / r["estimate"], r["bind_s"]), flush=True)


if __name__ == "__main__":
    main()
