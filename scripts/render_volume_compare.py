"""Issue 44: Volume ARAP against surface ARAP, in a picture:

    PYTHONPATH=build/python build/venvs/bpy-5.3/bin/python scripts/render_volume_compare.py \
        -- docs/images/volume_arap_compare.png

Each row: the rest, surface ARAP and volumetric ARAP (the API, defaults, cold solves to the
default tolerance) for one edit of scripts/bench_volumetric_arap.py's: the armadillo's far
tenth turned by 180 degrees about its long axis (its near tenth fixed), and the arm's hand
turned by 90 degrees about the middle (a bend). Prints each result's volume against the
rest's. Rendered by Workbench (scripts/render_tiles.py). A script, not a test: look at it.
"""
import os
import sys

import numpy as np

HERE = os.path.dirname(os.path.abspath(__file__))
sys.path.insert(0, HERE)
sys.path.insert(0, os.path.join(HERE, "..", "tests", "python"))
from render_tiles import S, render  # noqa: E402  (tests/blender/_setup.py)
from bench_volumetric_arap import turn  # noqa: E402
import shapes  # noqa: E402

SHARED = os.path.join(HERE, "..", "..", "shared", "meshes")


def edit(name, what):
    mesh = S.dk.read_mesh(os.path.join(SHARED, name))
    V, F = np.asarray(mesh.vertices), np.asarray(mesh.triangles)
    axis = int(np.argmax(np.ptp(V, axis=0)))
    t = (V[:, axis] - V[:, axis].min()) / np.ptp(V[:, axis])
    hand, base = np.flatnonzero(t > 0.9), np.flatnonzero(t < 0.1)
    side = (axis + 1) % 3
    T = (turn(np.pi, axis, V[hand].mean(axis=0)) if what == "twist" else
         turn(np.pi / 2, 3 - axis - side, V[(t > 0.45) & (t < 0.55)].mean(axis=0)))
    out = [V]
    for cls in (S.dk.ARAP, S.dk.VolumetricARAP):
        r = cls(mesh, handles=[hand], fixed=base).solve(transforms=[T], warm_start=False)
        out.append(np.asarray(r.positions))
        print("%s %s, %s: volume %.3f of the rest's" % (name, what, cls.__name__,
                                                     shapes.volume(out[-1], F) /
                                                     shapes.volume(V, F)))
    # the camera looks along the axis that is neither the long one nor the bend's plane's
    M = np.eye(4)
    M[:3, 0] = np.eye(3)[side if what == "twist" else axis]
    M[:3, 1] = np.eye(3)[axis if what == "twist" else side]
    M[:3, 2] = np.cross(M[:3, 0], M[:3, 1])
    P = np.vstack(out)
    view = (P.mean(axis=0), 1.1 * float(np.max(np.ptp(P, axis=0))), M.tolist())
    return [(X, F, view) for X in out]


def main():
    argv = sys.argv[sys.argv.index("--") + 1:] if "--" in sys.argv else []
    path = argv[0] if argv else os.path.join(S.OUTPUT, "volume_arap_compare.png")
    S.reset_scene()
    rows = [edit("armadillo.obj", "twist"), edit("arm.obj", "bend")]
    render(rows, path)
    print("wrote %s (each row: the rest, surface ARAP, Volume ARAP)" % path)
    S.exit_now(0)


main()
