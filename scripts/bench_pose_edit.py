"""Issue 39, item 2: a method that does not edit its input (it solves on the rest, and the
add-on pastes its offset on the pose, each handle's edit turned by the rigid fit of its
vertices) against the same method bound on the pose itself. The armadillo of armadillo-wave
(43,243 vertices) posed as scripts/bench_arap_playback.py poses it (the raised arm turned by
a blend), the feet fixed, the hand lifted by 5% of the model in the pose. Per angle: the
pose-bound method's energy of the pasted result against its minimum, and how far apart the
two are at the farthest vertex.

    PYTHONPATH=build/python /usr/bin/python3 scripts/bench_pose_edit.py [METHOD]

A script, not a test (METHOD: a deformkit class, default LinearReconstruction).
"""
import json
import math
import os
import sys

import numpy as np

import deformkit as dk

HERE = os.path.dirname(os.path.abspath(__file__))
SHARED = os.environ.get("DEFORMKIT_SHARED", os.path.join(HERE, "..", "..", "shared"))


def rigid_fit(A, B):
    """The rigid map (4 x 4) that best takes points A onto B (Kabsch)."""
    ca, cb = A.mean(axis=0), B.mean(axis=0)
    U, _, Wt = np.linalg.svd((A - ca).T @ (B - cb))
    D = np.diag([1.0, 1.0, np.sign(np.linalg.det(Wt.T @ U.T))])
    G = np.eye(4)
    G[:3, :3] = Wt.T @ D @ U.T
    G[:3, 3] = cb - G[:3, :3] @ ca
    return G


def main():
    name = sys.argv[1] if len(sys.argv) > 1 else "LinearReconstruction"
    cls = getattr(dk, name)
    sc = json.load(open(os.path.join(SHARED, "scenarios", "armadillo-wave.json")))
    mesh = dk.read_mesh(os.path.join(SHARED, "scenarios", sc["mesh"]))
    V, F = np.asarray(mesh.vertices), np.asarray(mesh.triangles)
    hand, fixed = np.array(sc["handles"][0]["vertices"]), np.array(sc["fixed"])
    c, h = V.mean(axis=0), V[hand].mean(axis=0)
    w = np.clip((0.5 - np.linalg.norm(V - h, axis=1) / np.linalg.norm(h - c)) * 6.0,
                0.0, 1.0)[:, None]
    shoulder = h + 0.5 * (c - h)
    diag = float(np.linalg.norm(np.ptp(V, axis=0)))
    on_rest = cls(dk.Mesh(V, F), [hand], fixed=fixed)
    T = np.eye(4)
    T[2, 3] = 0.05 * diag
    for deg in (20, 60, 90):
        a = math.radians(deg)
        R = np.array([[1.0, 0.0, 0.0], [0.0, math.cos(a), -math.sin(a)],
                      [0.0, math.sin(a), math.cos(a)]])
        P = (1.0 - w) * V + w * ((V - shoulder) @ R.T + shoulder)
        G = rigid_fit(V[hand], P[hand])
        at_rest = np.linalg.inv(G) @ T @ G   # the edit as it reads at the rest
        pasted = P + (np.asarray(on_rest.solve(transforms=at_rest[None]).positions) - V)
        on_pose = cls(dk.Mesh(P, F), [hand], fixed=fixed)
        best = on_pose.solve(transforms=T[None])
        e = on_pose.energy(pasted)
        print("%s, arm at %2d degrees: pasted edit %.4g, bind on the pose %.4g (%.4gx); "
              "%.2f%% of the diagonal apart" % (name, deg, e, best.energy, e / best.energy,
                                               100.0 * np.abs(pasted - best.positions).max()
                                               / diag), flush=True)


main()
