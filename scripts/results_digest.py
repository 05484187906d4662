#!/usr/bin/env python3
"""Digests of what each method computes on the shared scenarios, to prove that a refactor
changed no result: run it before and after, and diff the two outputs.

    PYTHONPATH=build/python /usr/bin/python3 scripts/results_digest.py [--shared DIR] > a.txt

For each scenario (../shared/scenarios/*.json) and each method variant it prints the SHA-256
of the positions (float64 bytes), the iteration count and the energy of: a cold solve for the
scenario's full translation (targets as transforms), the same targets as positions, and a
warm-started drag in 5 steps (each step from the previous one, as the add-on drags). Equal
lines mean bit-identical results. Not a test: the suite's assertions are the tests.
"""
import argparse
import hashlib
import json
import os
import sys

import numpy as np

import deformkit as dk

HERE = os.path.dirname(os.path.abspath(__file__))
VARIANTS = [
    ("ARAP", dk.ARAP, {}, {"warm_start": True}),
    ("ARAP anderson", dk.ARAP, {"acceleration": "anderson"}, {"warm_start": True}),
    ("ARAP rims", dk.ARAP, {"energy": "spokes_and_rims", "max_iterations": 30},
     {"warm_start": True}),
    ("LaplacianEdit", dk.LaplacianEdit, {}, {}),
    ("LaplacianEdit local_frame", dk.LaplacianEdit, {"detail": "local_frame"}, {}),
    ("LaplacianEdit soft", dk.LaplacianEdit, {"constraints": "soft", "detail": "membrane"}, {}),
    ("Falloff", dk.Falloff, {}, {}),
    ("Falloff geodesic", dk.Falloff, {"distance": "geodesic", "range": 0.0}, {}),
]


def digest(a):
    return hashlib.sha256(np.ascontiguousarray(np.asarray(a, dtype=np.float64)).tobytes()
                          ).hexdigest()[:16]


def line(name, res):
    return "%-28s %s its=%-4d E=%.17g" % (name, digest(res.positions), res.iterations,
                                           float(res.energy))


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--shared", default=os.path.join(HERE, "..", "..", "shared"))
    args = ap.parse_args()
    sdir = os.path.join(args.shared, "scenarios")
    if not os.path.isdir(sdir):
        sys.exit("no scenarios in %s" % sdir)
    for fname in sorted(os.listdir(sdir)):
        if not fname.endswith(".json"):
            continue
        with open(os.path.join(sdir, fname)) as f:
            sc = json.load(f)
        verts, sizes, idx = dk.load_mesh_file(os.path.join(sdir, sc["mesh"]))
        verts = np.asarray(verts)
        mesh = dk.Mesh.from_polygons(verts, sizes, idx)
        handles = [np.asarray(h["vertices"]) for h in sc["handles"]]
        moves = [np.asarray(h["translate"], dtype=float) for h in sc["handles"]]
        print("# %s (%d vertices)" % (sc["name"], len(verts)))
        for name, cls, kw, warm in VARIANTS:
            try:
                m = cls(mesh, handles=handles, fixed=sc["fixed"], **kw)
            except (ValueError, RuntimeError) as ex:   # a refusal is a result too
                print("%-28s refused: %s: %s" % (name, type(ex).__name__, ex))
                continue
            T = np.tile(np.eye(4), (len(handles), 1, 1))
            T[:, :3, 3] = moves
            print(line(name + " transforms", m.solve(transforms=T)))
            m = cls(mesh, handles=handles, fixed=sc["fixed"], **kw)
            tg = np.concatenate([verts[h] + t for h, t in zip(handles, moves)])
            print(line(name + " targets", m.solve(tg)))
            for step in range(1, 6):
                T[:, :3, 3] = [t * step / 5 for t in moves]
                r = m.solve(transforms=T, **warm)
            print(line(name + " drag", r))


if __name__ == "__main__":
    main()
