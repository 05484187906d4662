#!/usr/bin/python3
"""Issue 44: VolumetricARAP against surface ARAP (docs/methods/volumetric_arap.md).

  PYTHONPATH=build/python /usr/bin/python3 scripts/bench_volumetric_arap.py [--meshes ...]
      [--subdivide S] [--levels 1,2] [--embed 0,1,2] [--quality Q] [--no-surface]

For each mesh (its longest axis its length): the far tenth a handle, the near tenth fixed,
the handle turned by 90 degrees about the middle's centre (a bend) and, separately, by 180
degrees about the axis (a twist). Prints the bind (VolumetricARAP: TetGen, the points and
tetrahedra it made, the extension's factor, ARAP's on the tetrahedra; ARAP's for scale), a
cold converged solve of each edit (time, Newton steps), a drag step (the bend's handle moved
by 1% of the length: a warm solve and a preview), and the enclosed volume after each edit
against the rest's, for both methods. --subdivide S subdivides each mesh S times first
(midpoints); --levels lists VolumetricARAP's `levels` to run (1: the volume alone, 2: with
its coarse level; the coarse points and the cold starts it gave are printed), and the
largest difference of each cold result from the first's (in units of the length) with its
energy's; --embed lists `embed` values to run with each (0 automatic: a coarse volume carries
the surface from 250,000 closed vertices on; 1 the surface is the volume's boundary; 2 the
coarse volume carries it; the default 1); --no-surface skips surface ARAP. A script, not a test: compare within one run (the machines' speed swings by
tens of percent)."""
import argparse
import os
import sys
import time

import numpy as np

import deformkit as dk

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
sys.path.insert(0, os.path.join(os.path.dirname(os.path.abspath(__file__)), "..", "tests",
                                "python"))
import shapes  # noqa: E402  (tests/python/shapes.py: the volume)
from bench_common import SHARED, midpoint_subdivide  # noqa: E402


def turn(angle, axis, centre):
    """A 4x4 rotation by `angle` about the line through `centre` along coordinate `axis`."""
    a, b = [k for k in range(3) if k != axis]
    R = np.eye(3)
    R[a, a], R[a, b], R[b, a], R[b, b] = np.cos(angle), -np.sin(angle), np.sin(angle), np.cos(angle)
    T = np.eye(4)
    T[:3, :3] = R
    T[:3, 3] = centre - R @ centre
    return T


def run(name, V, F, quality, levels, surface, embeds=(1,)):
    mesh = dk.Mesh(V, F)
    axis = int(np.argmax(np.ptp(V, axis=0)))
    t = (V[:, axis] - V[:, axis].min()) / np.ptp(V[:, axis])
    hand, base = np.flatnonzero(t > 0.9), np.flatnonzero(t < 0.1)
    centre = V[(t > 0.45) & (t < 0.55)].mean(axis=0)
    side = (axis + 1) % 3
    edits = {"bend 90": turn(np.pi / 2, 3 - axis - side, centre),
             "twist 180": turn(np.pi, axis, V[hand].mean(axis=0))}
    v0 = shapes.volume(V, F)
    print("%s: %d vertices, %d triangles" % (name, len(V), len(F)))
    runs = [(dk.VolumetricARAP, {"quality": quality, "levels": L, "embed": E})
            for L in levels for E in embeds]
    runs += [(dk.ARAP, {})] if surface else []
    first = {}
    length = np.ptp(V[:, axis])
    for cls, kw in runs:
        t0 = time.perf_counter()
        m = cls(mesh, handles=[hand], fixed=base, **kw)
        bind = time.perf_counter() - t0
        extra = ""
        if cls is dk.VolumetricARAP:
            extra = ", levels=%d, embed=%d%s: %d points (%d inside), %d tetrahedra%s%s" % (
                kw["levels"], kw["embed"],
                " (a coarse volume carries the surface)" if m.stats["embedded"] else "",
                m.n_points, m.n_interior_points, m.n_tetrahedra,
                ", coarse level of %d points" % m.stats["coarse_points"]
                if m.stats["levels"] > 1 else "",
                ", " + m.volume_note if m.volume_note else "")
        print("  %-15s bind %.2f s%s" % (cls.__name__, bind, extra))
        for what, T in edits.items():
            t0 = time.perf_counter()
            r = m.solve(transforms=[T], warm_start=False)
            dt = time.perf_counter() - t0
            agree = ""
            if cls is dk.VolumetricARAP:
                if what not in first:
                    first[what] = r
                else:
                    agree = ", off the first by %.1e (energy %+.1e)" % (
                        np.abs(r.positions - first[what].positions).max() / length,
                        r.energy / first[what].energy - 1.0)
            print("  %-15s %-9s cold %.3f s, %d steps%s, volume %.4f%s" % (
                cls.__name__, what, dt, r.iterations, "" if r.converged else " (not converged)",
                shapes.volume(r.positions, F) / v0, agree))
        m.solve(transforms=[edits["bend 90"]], warm_start=False)
        step = edits["bend 90"].copy()
        step[:3, 3] += 0.01 * np.ptp(V[:, axis]) * np.eye(3)[side]
        t0 = time.perf_counter()
        p = m.solve(transforms=[step], preview=True)
        tp = time.perf_counter() - t0
        t0 = time.perf_counter()
        r = m.solve(transforms=[step], resume=True)
        dt = time.perf_counter() - t0
        print("  %-15s drag step: preview %.4f s, then converged %.3f s (%d steps)" % (
            cls.__name__, tp, dt, r.iterations))
        del p, m


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--meshes", nargs="*", default=["arm.obj", "armadillo.obj"])
    ap.add_argument("--subdivide", type=int, default=0)
    ap.add_argument("--levels", default="1")
    ap.add_argument("--embed", default="1")
    ap.add_argument("--quality", type=float, default=1.5)
    ap.add_argument("--no-surface", action="store_true")
    a = ap.parse_args()
    for name in a.meshes:
        mesh = dk.read_mesh(os.path.join(SHARED, "meshes", name))
        V, F = np.asarray(mesh.vertices), np.asarray(mesh.triangles)
        for _ in range(a.subdivide):
            V, F = midpoint_subdivide(V, F)
        run(name, V, F, a.quality, [int(x) for x in a.levels.split(",")], not a.no_surface,
            [int(x) for x in a.embed.split(",")])


if __name__ == "__main__":
    main()
