#!/usr/bin/python3
"""Issue 42: ShapeMatching's time step on real meshes (docs/methods/shape_matching.md).

  PYTHONPATH=build/python /usr/bin/python3 scripts/bench_shape_matching.py [--meshes ...]

For each mesh: the bind (clusters) and, for every mode and integrator, one frame of two
substeps on a still input and on a moving one (an animated input: the clusters' rest data
are computed again each frame), best of --repeat; the time of one step is the still frame's
over its substeps. The lowest 40% along the longest axis follows the input, the rest is
simulated (the default cubes: each vertex in 8 clusters). A script, not a test: compare
within one run (the machines' speed swings by tens of percent).
"""
import argparse
import os
import time

import numpy as np

import deformkit as dk

HERE = os.path.dirname(os.path.abspath(__file__))
SHARED = os.path.join(HERE, "..", "..", "shared", "meshes")


def best(fn, repeat):
    t = []
    for _ in range(repeat):
        t0 = time.perf_counter()
        fn()
        t.append(time.perf_counter() - t0)
    return min(t)


def run(name, repeat, modes, integrators):
    v, sizes, idx = dk.load_mesh_file(os.path.join(SHARED, name))
    v = np.asarray(v)
    mesh = dk.Mesh.from_polygons(v, sizes, idx)
    axis = int(np.argmax(v.max(0) - v.min(0)))
    cut = np.quantile(v[:, axis], 0.4)
    fixed = np.flatnonzero(v[:, axis] < cut)
    diag = float(np.linalg.norm(v.max(0) - v.min(0)))
    print("%s: %d vertices" % (name, len(v)))
    for mode in modes:
        for integ in integrators:
            t0 = time.perf_counter()
            sm = dk.ShapeMatching(mesh, fixed=fixed, mode=mode, integrator=integ)
            t_bind = time.perf_counter() - t0
            n_cl = len(sm.clusters())
            sm.solve(warm_start=False)
            state = sm.save_state()
            f = [0]

            def moving():
                f[0] += 1
                sm.solve(input_positions=v + [0.01 * diag * np.sin(f[0]), 0, 0], energy=False)

            def still():
                sm.solve(energy=False)
            t_move = best(moving, repeat)
            sm.restore_state(state)
            t_still = best(still, repeat)
            print("  %-9s %-19s bind %5.3f s (%d clusters)  frame: still %6.1f ms, moving "
                  "input %6.1f ms;  one step %5.1f ms"
                  % (mode, integ, t_bind, n_cl, 1e3 * t_still, 1e3 * t_move,
                     1e3 * t_still / 2))


def main():
    p = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    p.add_argument("--meshes", nargs="*", default=["armadillo.obj", "ogre.obj"])
    p.add_argument("--repeat", type=int, default=7)
    p.add_argument("--modes", nargs="*", default=["rigid", "linear", "quadratic"])
    p.add_argument("--integrators", nargs="*", default=["semi_implicit_euler", "rk4"])
    a = p.parse_args()
    for name in a.meshes:
        run(name, a.repeat, a.modes, a.integrators)


if __name__ == "__main__":
    main()
