"""What the add-on's mesh checks before each write cost (issue 18, class 6), on the 43k
armadillo: the full topology fingerprint (solver.topology_fingerprint: the corners' vertices
and each face's corner count, hashed), the quick check of Blender 3.6+ (solver.quick_topology,
three hidden attributes compared with the cached copy) and the rest-position comparison.
    PYTHONPATH=build/python blender -b --factory-startup --python tests/blender/bench_topology.py
    PYTHONPATH=build/python build/venvs/bpy-5.3/bin/python tests/blender/bench_topology.py
Prints the median of 30 runs of each, in ms."""
import os
import sys
import time
sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
import _setup as S  # noqa: E402
import bpy  # noqa: E402
import numpy as np  # noqa: E402

MESH = os.path.join(S.ROOT, "..", "shared", "meshes", "armadillo.obj")


def median_ms(fn, n=30):
    fn()
    t = []
    for _ in range(n):
        t0 = time.perf_counter()
        fn()
        t.append((time.perf_counter() - t0) * 1000.0)
    return float(np.median(t))


def main():
    S.reset_scene()
    m = S.dk.read_mesh(MESH)
    me = bpy.data.meshes.new("armadillo")
    me.from_pydata(np.asarray(m.vertices).tolist(), [], np.asarray(m.triangles).tolist())
    me.update()
    sv = S.solver
    q0 = sv.quick_topology(me)
    rest0 = sv.rest_positions(me)
    rows = [("full fingerprint (topology_fingerprint)", lambda: sv.topology_fingerprint(me))]
    if q0 is not None:
        rows.append(("quick check (quick_topology + compare)",
                     lambda: all(np.array_equal(a, b) for a, b in
                                 zip(sv.quick_topology(me), q0))))
    rows.append(("rest positions (read + compare)",
                 lambda: np.array_equal(sv.rest_positions(me), rest0)))
    print("Blender %s, %d vertices, %d faces, %d corners"
          % (bpy.app.version_string, len(me.vertices), len(me.polygons), len(me.loops)))
    for name, fn in rows:
        print("  %-42s %7.2f ms" % (name, median_ms(fn)))
    if q0 is None:
        print("  %-42s %7s" % ("quick check", "n/a (before 3.6)"))


main()
S.exit_now(0)
