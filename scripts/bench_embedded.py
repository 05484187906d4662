#!/usr/bin/env python3
"""Embedded deformation timings in the shape of the paper's Table 1 (Sumner et al. 2007).

    OPENBLAS_NUM_THREADS=1 PYTHONPATH=build/python /usr/bin/python3 scripts/bench_embedded.py \\
        [--shared DIR] [--repeat 3]

On the armadillo (43k vertices) and the ogre (62k), with about 220 and about 1,000 nodes and
10 to 5,000 handle constraints (the vertices nearest the scenario's hand, or the ogre's
highest vertex; the armadillo's feet, the ogre's lowest 5% fixed), a drag of 5% of the
bounding-box diagonal, solved cold to the eq. 12 tests. Columns:
  Bind   the constructor: node sampling, weights (eq. 4), edges, fixed nodes, J^T J's pattern
         and its analysis
  Solve  time per Gauss-Newton iteration: (t(n iterations) - t(1)) / (n - 1), best of --repeat
  Its    iterations to converge
  Def    eq. 2 for every vertex with the solved transformations (EmbeddedDeformation.deformed,
         best of --repeat)
Prints the paper's rows beside ours. A script, not a test: timings swing with the machine.
"""
import argparse
import json
import os
import sys
import time

import numpy as np

import deformkit as dk

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
from bench_common import best  # noqa: E402

HERE = os.path.dirname(os.path.abspath(__file__))
PAPER = """paper (2.4 GHz Core 2 Duo, 2007):
  Raptor  85,792 vertices  226 nodes    27 csts  Solve  20 ms  Def 22 ms
  Giraffe 79,226 vertices  221 nodes 5,000 csts  Solve  38 ms  Def 20 ms
  Dino    10,002 vertices  222 nodes   540 csts  Solve  19 ms  Def  3 ms
  Dino    10,002 vertices 1048 nodes   540 csts  Solve 148 ms  Def  3 ms"""


def load(shared, name):
    v, sizes, idx = dk.load_mesh_file(os.path.join(shared, "meshes", name))
    return np.asarray(v), dk.Mesh.from_polygons(v, sizes, idx)




def run(label, v, mesh, fixed, centre, nodes_list, csts_list, repeat, distance):
    diag = float(np.linalg.norm(v.max(0) - v.min(0)))
    order = np.argsort(np.linalg.norm(v - centre, axis=1))
    print("%s: %d vertices, %d fixed, %s influence" % (label, len(v), len(fixed), distance))
    print("  %6s %6s %9s %10s %5s %9s %12s" % ("nodes", "csts", "Bind ms", "Solve ms", "Its",
                                              "Def ms", "handle err"))
    for n_nodes in nodes_list:
        for csts in csts_list:
            handle = np.setdiff1d(order[:csts], fixed)
            ed, tb = best(lambda: dk.EmbeddedDeformation(mesh, handles=[handle], fixed=fixed,
                                                         n_nodes=n_nodes, distance=distance), 1)
            tg = v[handle] + [0.0, 0.05 * diag, 0.0]
            full, tn = best(lambda: ed.solve(tg, warm_start=False), repeat)
            _, t1 = best(lambda: ed.solve(tg, warm_start=False, max_iterations=1), repeat)
            its = full.iterations
            per_it = (tn - t1) / (its - 1) if its > 1 else t1
            _, tdef = best(ed.deformed, repeat)
            err = float(np.linalg.norm(np.asarray(full.positions)[handle] - tg, axis=1).max())
            print("  %6d %6d %9.1f %10.2f %5d %9.2f %11.2f%%" % (
                len(ed.nodes), len(handle), tb * 1e3, per_it * 1e3, its, tdef * 1e3,
                100 * err / (0.05 * diag)))


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--shared", default=os.path.join(HERE, "..", "..", "shared"))
    ap.add_argument("--repeat", type=int, default=3)
    ap.add_argument("--distance", choices=("euclidean", "geodesic"), default="euclidean",
                    help="how vertices find their nodes (geodesic: along the surface)")
    a = ap.parse_args()
    print(PAPER)
    print()
    with open(os.path.join(a.shared, "scenarios", "armadillo-wave.json")) as f:
        sc = json.load(f)
    v, mesh = load(a.shared, "armadillo.obj")
    hand = v[sc["handles"][0]["vertices"]].mean(axis=0)
    run("armadillo", v, mesh, np.asarray(sc["fixed"]), hand, (220, 1000),
        (10, 100, 1000, 5000), a.repeat, a.distance)
    v, mesh = load(a.shared, "ogre.obj")
    low = np.where(v[:, 1] <= np.quantile(v[:, 1], 0.05))[0]
    top = v[np.argmax(v[:, 1])]
    run("ogre", v, mesh, low, top, (220, 1000), (10, 100, 1000, 5000), a.repeat, a.distance)


if __name__ == "__main__":
    main()
