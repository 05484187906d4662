"""The posed armadillo the playback benchmarks share (scripts/bench_arap_playback.py,
scripts/bench_pose_edit.py): the armadillo of armadillo-wave (43,243 vertices), its feet
(the scenario's fixed set) and hand (its handle), and a pose that turns the raised arm about
the shoulder by a blend, as scripts/bench_animated.py rigs it in Blender: the vertices
within a third of the way from the hand to the body's centre follow the arm, blended over
the next sixth."""
import json
import math
import os

import numpy as np

import deformkit as dk

HERE = os.path.dirname(os.path.abspath(__file__))
SHARED = os.environ.get("DEFORMKIT_SHARED", os.path.join(HERE, "..", "..", "shared"))


class PosedArmadillo:
    """V, F (rest and triangles), hand and fixed (index arrays), diag (the bounding box's
    diagonal) and pose(angle), the rest with the arm turned by `angle` radians."""

    def __init__(self):
        sc = json.load(open(os.path.join(SHARED, "scenarios", "armadillo-wave.json")))
        mesh = dk.read_mesh(os.path.join(SHARED, "scenarios", sc["mesh"]))
        self.V, self.F = np.asarray(mesh.vertices), np.asarray(mesh.triangles)
        self.hand, self.fixed = np.array(sc["handles"][0]["vertices"]), np.array(sc["fixed"])
        c, h = self.V.mean(axis=0), self.V[self.hand].mean(axis=0)
        d = np.linalg.norm(self.V - h, axis=1) / np.linalg.norm(h - c)
        self.weight = np.clip((0.5 - d) * 6.0, 0.0, 1.0)[:, None]
        self.shoulder = h + 0.5 * (c - h)
        self.diag = float(np.linalg.norm(np.ptp(self.V, axis=0)))

    def pose(self, angle):
        co, si = math.cos(angle), math.sin(angle)
        R = np.array([[1.0, 0.0, 0.0], [0.0, co, -si], [0.0, si, co]])
        V, w, s = self.V, self.weight, self.shoulder
        return (1.0 - w) * V + w * ((V - s) @ R.T + s)
