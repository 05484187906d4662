#!/usr/bin/python3
"""Issue 43: ShapeInterpolation on real meshes (docs/methods/shape_interpolation.md).

  PYTHONPATH=build/python /usr/bin/python3 scripts/bench_shape_interpolation.py [--meshes ...]
      [--levels L]

For each mesh, two poses: the mesh turned about its longest axis by up to 270 degrees along
it (a twist) and bent by 120 degrees about a perpendicular axis past its middle. Prints the
bind (the poses' rotations and stretches, the rotation lift, the factor), one in-between of
both poses (best of --repeat: a blend plays at the scene's rate when it is well under a
frame), the same with an input pose (input_positions), and the linear blend's time in numpy
for scale; then the half-way quality against the half twist: mean edge-length change, volume
and the rms distance after the best rigid fit (over the diagonal), for the consistent and
principal rotations, the stretches blended in the logarithm, and the linear blend. --levels
L subdivides each mesh L times first (midpoints; 2: the armadillo's 692k vertices) and
prints the peak RSS after the bind (the quality figures are skipped there). A script, not a test: compare within one run (the
machines' speed swings by tens of percent)."""
import argparse
import os
import time

import resource
import sys

import numpy as np

import deformkit as dk

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
sys.path.insert(0, os.path.join(os.path.dirname(os.path.abspath(__file__)), "..", "tests",
                                "python"))
import shapes  # noqa: E402  (tests/python/shapes.py: the twist, volume and rigid fit)
from bench_common import best as best_of, midpoint_subdivide  # noqa: E402


def best(fn, repeat):
    """fn's best wall time in seconds over `repeat` calls (bench_common.best)."""
    return best_of(fn, repeat)[1]

HERE = os.path.dirname(os.path.abspath(__file__))
SHARED = os.path.join(HERE, "..", "..", "shared", "meshes")


def turned(V, axis, degrees):
    """V twisted about its centre line along `axis` by up to `degrees` from one end."""
    return shapes.twist(V, np.radians(degrees), axis, V.mean(0))


def bent(V, axis, degrees):
    """V bent past its middle along `axis` about a perpendicular axis, smoothly over a
    fifth of its length."""
    lo, ext = V[:, axis].min(), np.ptp(V[:, axis])
    s = np.clip((V[:, axis] - lo - 0.4 * ext) / (0.2 * ext), 0, 1)
    th = np.radians(degrees) * s * s * (3 - 2 * s)
    a = [k for k in range(3) if k != axis][0]
    pivot = V.mean(0)
    P = V.copy()
    x, y = V[:, axis] - pivot[axis], V[:, a] - pivot[a]
    P[:, axis] = pivot[axis] + np.cos(th) * x - np.sin(th) * y
    P[:, a] = pivot[a] + np.sin(th) * x + np.cos(th) * y
    return P


volume = shapes.volume


def rigid_rms(X, Y):
    return shapes.rigid_fit(X, Y)[0]


def run(name, repeat, levels):
    V, sizes, idx = dk.load_mesh_file(os.path.join(SHARED, name))
    V = np.asarray(V, dtype=float)
    mesh = dk.Mesh.from_polygons(V, sizes, idx)
    F = np.asarray(mesh.triangles)
    for _ in range(levels):
        V, F = midpoint_subdivide(V, F)
        mesh = dk.Mesh(V, F)
    axis = int(np.argmax(np.ptp(V, axis=0)))
    diag = float(np.linalg.norm(np.ptp(V, axis=0)))
    twist, bend = turned(V, axis, 270.0), bent(V, axis, 120.0)
    print("%s: %d vertices, %d triangles" % (name, len(V), len(F)))
    t0 = time.perf_counter()
    si = dk.ShapeInterpolation(mesh, poses=[twist, bend])
    t_bind = time.perf_counter() - t0
    si_log = dk.ShapeInterpolation(mesh, poses=[twist, bend], stretches="log")
    w = np.array([0.5, 0.3])
    t_solve = best(lambda: si.solve(weights=w, energy=False), repeat)
    inp = V + 0.01 * diag * np.sin(V[:, [1, 2, 0]] / diag * 7)
    t_input = best(lambda: si.solve(weights=w, input_positions=inp, energy=False), repeat)
    t_lin = best(lambda: V + w[0] * (twist - V) + w[1] * (bend - V), repeat)
    t_log = best(lambda: si_log.solve(weights=w, energy=False), repeat)
    print("  peak RSS after the binds %.0f MB" % (
        resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024.0))
    print("  bind %.2f s; one in-between %.1f ms (with an input pose %.1f ms; stretches='log' "
          "%.1f ms); numpy's linear blend %.2f ms" % (t_bind, 1e3 * t_solve, 1e3 * t_input,
                                                      1e3 * t_log, 1e3 * t_lin))
    if levels:
        return
    ideal = turned(V, axis, 135.0)
    E = np.unique(np.sort(np.concatenate([F[:, [0, 1]], F[:, [1, 2]], F[:, [2, 0]]]), 1), axis=0)
    L = np.linalg.norm(ideal[E[:, 0]] - ideal[E[:, 1]], axis=1)
    v0 = volume(V, F)
    rows = []
    for label, kw in (("consistent", {}), ("log", {"stretches": "log"}),
                      ("principal", {"rotations": "principal"})):
        X = np.asarray(dk.ShapeInterpolation(mesh, poses=[twist], **kw).solve(
            weights=[0.5]).positions)
        rows.append((label, X))
    rows.append(("linear", 0.5 * (V + twist)))
    for label, X in rows:
        e = np.abs(np.linalg.norm(X[E[:, 0]] - X[E[:, 1]], axis=1) / L - 1).mean()
        print("  half of the 270-degree twist, %-10s: edges %5.1f%%, volume %.3f, %.3f of the "
              "diagonal off the half twist" % (label, 100 * e, volume(X, F) / v0,
                                               rigid_rms(ideal, X) / diag))


def main():
    p = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    p.add_argument("--meshes", nargs="*", default=["armadillo.obj", "ogre.obj"])
    p.add_argument("--repeat", type=int, default=7)
    p.add_argument("--levels", type=int, default=0)
    a = p.parse_args()
    for name in a.meshes:
        run(name, a.repeat, a.levels)


if __name__ == "__main__":
    main()
