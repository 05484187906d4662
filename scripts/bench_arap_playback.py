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
import math
import statistics
import time

import numpy as np

import deformkit as dk
from posed_armadillo import PosedArmadillo


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--frames", type=int, default=12)
    ap.add_argument("--tolerance", type=float, default=1e-6)
    a = ap.parse_args()
    arm = PosedArmadillo()
    V, F, hand, fixed, diag, pose = arm.V, arm.F, arm.hand, arm.fixed, arm.diag, arm.pose

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
