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
import math
import sys

import numpy as np

import deformkit as dk
from posed_armadillo import PosedArmadillo


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
    arm = PosedArmadillo()
    V, F, hand, fixed, diag = arm.V, arm.F, arm.hand, arm.fixed, arm.diag
    on_rest = cls(dk.Mesh(V, F), [hand], fixed=fixed)
    T = np.eye(4)
    T[2, 3] = 0.05 * diag
    for deg in (20, 60, 90):
        P = arm.pose(math.radians(deg))
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
