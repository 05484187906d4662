#!/usr/bin/env python3
"""The Softness calibration of linear reconstruction, measured on the shared arm (the
libigl tutorial's arm.obj: the scene of Li's Figures 6-10).

    OPENBLAS_NUM_THREADS=2 PYTHONPATH=build/python /usr/bin/python3 scripts/calibrate_material.py \\
        [--shared DIR] [--angle 90]

The shoulder (x < -0.78) is fixed; the hand (x > 0.5) is the handle, turned by --angle
degrees about the elbow (the axis point at x = -0.2, the forearm's thinnest section before
the upper arm widens) around z, inward. A ring at the elbow (|x + 0.2| < 0.06) is painted
with weight 1 and becomes the material map exactly as the add-on makes it
(addon/solver.material_map, mode Interpolate: a harmonic map through the painted vertices,
the handle and the fixed part held at 1; value MATERIAL_SOFTEST ** (Softness * weight)).
For each Softness and balance w it prints:
  elbow share   the share of the turning that happens within 0.12 of the elbow (each of
                40 slices of the rest arm along x gets its rotation about z by a Kabsch
                fit; the share is the rise of that angle across the elbow zone)
  widening      the slices within 0.05 of the elbow: mean radius deformed / rest - 1
                (Figure 10's complaint)
  edge RMS      the relative RMS change of edge lengths, whole mesh
and the paper's direction (material 20 ** -Softness: lower stretching, higher bending
weight) for comparison. A script, not a test.
"""
import argparse
import os

import numpy as np

import deformkit as dk

HERE = os.path.dirname(os.path.abspath(__file__))
MATERIAL_SOFTEST = 20.0  # addon/solver/material.py
ELBOW_X, RING, SHARE_RADIUS = -0.2, 0.06, 0.12


def rot_z(a):
    c, s = np.cos(a), np.sin(a)
    return np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])


def slice_angles(v, r, slices):
    """Each slice's rotation about z, rest to deformed (degrees): the Kabsch fit of its
    vertices (the arm's cross-sections turn as wholes, their centroids zigzag)."""
    out = []
    for s in slices:
        p, q = v[s] - v[s].mean(0), r[s] - r[s].mean(0)
        u, _, vt = np.linalg.svd(q.T @ p)
        d = np.sign(np.linalg.det(u @ vt))
        rot = u @ np.diag([1.0, 1.0, d]) @ vt
        out.append(np.degrees(np.arctan2(rot[1, 0], rot[0, 0])))
    return np.unwrap(np.radians(out)) * 180.0 / np.pi


def measure(v, r, slices, mids, edges):
    ang = slice_angles(v, r, slices)
    lo = np.interp(ELBOW_X - SHARE_RADIUS, mids, ang)
    hi = np.interp(ELBOW_X + SHARE_RADIUS, mids, ang)
    share = (hi - lo) / (ang[-1] - ang[0])
    near = [i for i in range(len(slices)) if abs(mids[i] - ELBOW_X) < 0.05]
    rad0 = np.mean([np.linalg.norm(v[slices[i]] - v[slices[i]].mean(0), axis=1).mean()
                    for i in near])
    rad = np.mean([np.linalg.norm(r[slices[i]] - r[slices[i]].mean(0), axis=1).mean()
                   for i in near])
    l0 = np.linalg.norm(v[edges[:, 0]] - v[edges[:, 1]], axis=1)
    l1 = np.linalg.norm(r[edges[:, 0]] - r[edges[:, 1]], axis=1)
    return share, rad / rad0 - 1.0, np.sqrt(np.mean(((l1 - l0) / l0) ** 2)), ang[-1] - ang[0]


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--shared", default=os.path.join(HERE, "..", "..", "shared"))
    ap.add_argument("--angle", type=float, default=90.0)
    a = ap.parse_args()
    v, sizes, idx = dk.load_mesh_file(os.path.join(a.shared, "meshes", "arm.obj"))
    v = np.asarray(v)
    mesh = dk.Mesh.from_polygons(v, sizes, idx)
    edges = np.asarray(mesh.edges)
    x = v[:, 0]
    fixed, hand = np.where(x < -0.78)[0], np.where(x > 0.5)[0]
    ring = np.where(np.abs(x - ELBOW_X) < RING)[0]
    pivot = v[np.abs(x - ELBOW_X) < 0.03].mean(0)
    T = np.eye(4)
    T[:3, :3] = rot_z(np.radians(a.angle))
    T[:3, 3] = pivot - T[:3, :3] @ pivot
    cuts = np.linspace(-0.78, 0.5, 41)
    slices = [np.where((x >= lo) & (x < hi))[0] for lo, hi in zip(cuts[:-1], cuts[1:])]
    mids = 0.5 * (cuts[:-1] + cuts[1:])
    held = np.setdiff1d(np.concatenate([hand, fixed]), ring)
    print("arm: %d vertices; fixed %d, hand %d, painted ring %d; fold %.0f degrees about z"
          % (len(v), len(fixed), len(hand), len(ring), a.angle))
    print("%-22s %6s %5s %11s %9s %8s %7s" % ("map", "Soft.", "w", "elbow share", "widening",
                                              "edge RMS", "turn"))
    for w in (0.1, 1.0, 10.0):
        for direction in ("add-on", "paper"):
            for soft in (0.0, 0.25, 0.5, 0.75, 1.0):
                if direction == "paper" and soft == 0.0:
                    continue
                m = MATERIAL_SOFTEST ** (soft if direction == "add-on" else -soft)
                mat = dk.harmonic_material(mesh, np.concatenate([ring, held]),
                                           np.concatenate([np.full(len(ring), m),
                                                           np.ones(len(held))]))
                lr = dk.LinearReconstruction(mesh, handles=[hand], fixed=fixed, w=w,
                                             material=np.asarray(mat))
                r = np.asarray(lr.solve(transforms=[T]).positions)
                assert np.abs(r[fixed] - v[fixed]).max() == 0.0
                share, widen, erms, turn = measure(v, r, slices, mids, edges)
                print("%-22s %6.2f %5.1f %10.1f%% %+8.1f%% %7.1f%% %7.1f"
                      % (direction + (" (m = %.3g)" % m), soft, w, 100 * share, 100 * widen,
                         100 * erms, turn))


if __name__ == "__main__":
    main()
