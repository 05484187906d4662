#!/usr/bin/env python3
"""Linear reconstruction timings (issue 16's benchmark):

    OPENBLAS_NUM_THREADS=2 PYTHONPATH=build/python /usr/bin/python3 scripts/bench_fundamental.py \\
        [--shared DIR] [--repeat 10]

On the shared arm (8k) and the armadillo (43k): the lowest 10% of the vertices fixed, the
vertices within 10% of the diagonal of the highest point a handle moved by 5% of the
diagonal. Prints bind (assembly, analysis, factorization and the transform basis) and the
solve per drag (best of --repeat), with and without orientation constraints, for the drag
given as a transform (what the add-on sends: the combination of the transform basis) and
as positions (two triangular solves). A script, not a test.
"""
import argparse
import os
import sys
import time

import numpy as np

import deformkit as dk

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
from bench_common import best  # noqa: E402

HERE = os.path.dirname(os.path.abspath(__file__))




def run(label, path, repeat):
    v, sizes, idx = dk.load_mesh_file(path)
    v = np.asarray(v)
    mesh = dk.Mesh.from_polygons(v, sizes, idx)
    diag = float(np.linalg.norm(v.max(0) - v.min(0)))
    fixed = np.where(v[:, 1] < np.percentile(v[:, 1], 10))[0]
    top = int(np.argmax(v[:, 1]))
    hand = np.setdiff1d(np.where(np.linalg.norm(v - v[top], axis=1) < 0.1 * diag)[0], fixed)
    tg = v[hand] + [0.0, 0.05 * diag, 0.0]
    T = np.eye(4)
    T[1, 3] = 0.05 * diag
    print("%s: %d vertices, %d faces, %d fixed, %d handle" % (label, len(v), mesh.n_faces,
                                                             len(fixed), len(hand)))
    for ori in (False, True):
        t0 = time.perf_counter()
        lr = dk.LinearReconstruction(mesh, handles=[hand], fixed=fixed, orientation=ori)
        tb = time.perf_counter() - t0
        _, ts = best(lambda: lr.solve(tg, energy=False), repeat)
        _, tt = best(lambda: lr.solve(transforms=[T], energy=False), repeat)
        print("  orientation %-5s bind %7.1f ms   solve: transform %6.2f ms, positions %6.2f ms"
              "   unknowns %d%s" % (ori, tb * 1e3, tt * 1e3, ts * 1e3, lr.stats["n_unknowns"],
                                    "" if lr.transform_basis else " (no transform basis)"))


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--shared", default=os.path.join(HERE, "..", "..", "shared"))
    ap.add_argument("--repeat", type=int, default=10)
    a = ap.parse_args()
    for label, name in (("arm", "arm.obj"), ("armadillo", "armadillo.obj")):
        run(label, os.path.join(a.shared, "meshes", name), a.repeat)


if __name__ == "__main__":
    main()
