"""Issue 39, item 5: where an ARAP frame of an animated input could start, and what it costs
to converge tightly enough that the start does not show. Plain Python, no Blender: the
armadillo of armadillo-wave (43,243 vertices) posed as scripts/bench_animated.py rigs it
(the raised arm's vertices turned about the shoulder, blended by the same weights, 0 to 60
degrees over the shot), its feet fixed and its hand lifted by 5% of the model's size. Each
frame is solved twice on its pose (input_positions):
  cold    from the pose alone (what playback and bakes do: the result depends on the frame
          alone, so a bake equals playback);
  given   from the previous frame's cold result carried onto this pose
          (start_positions = pose + previous result - previous pose);
with the difference between the two results against the bounding-box diagonal.

    PYTHONPATH=build/python /usr/bin/python3 scripts/bench_arap_playback.py \\
        [--frames 12] [--tolerance 1e-6]

A script, not a test: compare the two starts within one run.
"""
import argparse
import json
import math
import os
import statistics
import time

import numpy as np

import deformkit as dk

HERE = os.path.dirname(os.path.abspath(__file__))
SHARED = os.environ.get("DEFORMKIT_SHARED", os.path.join(HERE, "..", "..", "shared"))


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--frames", type=int, default=12)
    ap.add_argument("--tolerance", type=float, default=1e-6)
    a = ap.parse_args()
    sc = json.load(open(os.path.join(SHARED, "scenarios", "armadillo-wave.json")))
    mesh = dk.read_mesh(os.path.join(SHARED, "scenarios", sc["mesh"]))
    V, F = np.asarray(mesh.vertices), np.asarray(mesh.triangles)
    hand, fixed = np.array(sc["handles"][0]["vertices"]), np.array(sc["fixed"])
    c, h = V.mean(axis=0), V[hand].mean(axis=0)
    w = np.clip((0.5 - np.linalg.norm(V - h, axis=1) / np.linalg.norm(h - c)) * 6.0,
                0.0, 1.0)[:, None]
    shoulder = h + 0.5 * (c - h)
    diag = float(np.linalg.norm(np.ptp(V, axis=0)))

    def pose(angle):
        co, si = math.cos(angle), math.sin(angle)
        R = np.array([[1.0, 0.0, 0.0], [0.0, co, -si], [0.0, si, co]])
        return (1.0 - w) * V + w * ((V - shoulder) @ R.T + shoulder)

    ar = dk.ARAP(dk.Mesh(V, F), [hand], fixed=fixed, tolerance=a.tolerance)
    T = np.eye(4)[None].copy()
    T[0, 2, 3] = 0.05 * diag
    print("bench_arap_playback: %d vertices, %d frames of 0-60 degrees, tolerance %g"
          % (len(V), a.frames, a.tolerance))
    rows, prev = [], None
    for f in range(a.frames):
        inp = pose(math.radians(60.0) * f / max(a.frames - 1, 1))
        t0 = time.perf_counter()
        rc = ar.solve(transforms=T, input_positions=inp, warm_start=False)
        cold_ms = (time.perf_counter() - t0) * 1000.0
        xc = np.asarray(rc.positions).reshape(-1, 3)
        if prev is not None:
            t0 = time.perf_counter()
            rg = ar.solve(transforms=T, input_positions=inp,
                          start_positions=inp + prev[0] - prev[1])
            given_ms = (time.perf_counter() - t0) * 1000.0
            diff = float(np.abs(np.asarray(rg.positions).reshape(-1, 3) - xc).max()) / diag
            rows.append((cold_ms, rc.iterations, given_ms, rg.iterations, diff))
            print("  frame %2d  cold %6.0f ms %3d its  given %6.0f ms %3d its  "
                  "differ by %.1e of the diagonal" % (f, cold_ms, rc.iterations, given_ms,
                                                      rg.iterations, diff), flush=True)
        prev = (xc, inp)
    med = [statistics.median(r[k] for r in rows) for k in range(4)]
    print("median: cold %.0f ms (%d its), given %.0f ms (%d its), %.2fx; largest difference "
          "%.1e of the diagonal" % (med[0], med[1], med[2], med[3], med[0] / med[2],
                                    max(r[4] for r in rows)))


main()
