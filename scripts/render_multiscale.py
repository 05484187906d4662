"""Issue 44: ARAP's multi-scale solve, in a picture:

    PYTHONPATH=build/python build/venvs/bpy-5.3/bin/python scripts/render_multiscale.py \\
        -- docs/images/arap_multiscale.png

The armadillo-wave drag (../shared/scenarios, 43,243 vertices: the right hand pulled, the
feet fixed) solved cold with `levels=2`: the coarse level (deformkit.decimate, 2,702
vertices, each vertex's role kept) at rest and solved, the start prolonged from it to the
full mesh (`preview=True`: the details turned with the coarse rotations), and the converged
full-mesh minimum; a last tile, the naive cold start of the single level (Laplacian editing,
identity rotations) that the coarse level replaces. Prints each start's energy against the
minimum's. Rendered by Workbench (scripts/render_tiles.py). A script, not a test: look at it.
"""
import os
import sys

import numpy as np

HERE = os.path.dirname(os.path.abspath(__file__))
sys.path.insert(0, HERE)
from render_tiles import S, render  # noqa: E402  (tests/blender/_setup.py)
import bench_common as bc  # noqa: E402


def main():
    argv = sys.argv[sys.argv.index("--") + 1:] if "--" in sys.argv else []
    path = argv[0] if argv else os.path.join(S.OUTPUT, "arap_multiscale.png")
    s, V, F = bc.load_scenario("armadillo-wave")
    fixed = np.array(s["fixed"])
    hand = np.array(s["handles"][0]["vertices"])
    target = V[hand] + np.array(s["handles"][0]["translate"], float)
    F = np.asarray(F, np.int32)
    mesh = S.dk.Mesh(V, F)
    classes = np.zeros(len(V), np.int32)
    classes[fixed], classes[hand] = 1, 2
    d = S.dk.decimate(mesh, len(V) // 16, classes=classes)
    kept, T = np.asarray(d["kept"]), np.asarray(d["triangles"])
    coarse_mesh = S.dk.Mesh(V[kept], T)
    row = {v: i for i, v in enumerate(hand)}   # a handle vertex's target row
    cf = np.flatnonzero(classes[kept] == 1)
    ch = np.flatnonzero(classes[kept] == 2)
    coarse = np.asarray(S.dk.ARAP(coarse_mesh, [ch], fixed=cf, levels=1)
                        .solve(target[[row[v] for v in kept[ch]]], warm_start=False)
                        .positions)
    arap = S.dk.ARAP(mesh, [hand], fixed=fixed, levels=2)
    start = np.asarray(arap.solve(target, warm_start=False, preview=True).positions)
    done = arap.solve(target, warm_start=False)
    single = S.dk.ARAP(mesh, [hand], fixed=fixed, levels=1)
    naive = np.asarray(single.solve(target, warm_start=False, preview=True).positions)
    for name, X in (("prolonged start", start), ("naive cold start", naive)):
        print("%s: %.3fx the minimum's energy" % (name, arap.energy(X) / done.energy))
    print("converged in %d Newton steps (levels=1: %d)"
          % (done.iterations, single.solve(target, warm_start=False).iterations))
    tiles = [(V[kept], T), (coarse, T), (start, F), (np.asarray(done.positions), F), (naive, F)]
    P = np.vstack([X for X, _ in tiles])
    view = (P.mean(axis=0), 1.05 * float(np.max(np.ptp(P, axis=0))), np.eye(4).tolist())
    S.reset_scene()
    render([[(X, Fx, view) for X, Fx in tiles]], path)
    print("wrote %s (the coarse level at rest and solved, the prolonged start, the converged "
          "minimum, the naive start)" % path)
    S.exit_now(0)


main()
