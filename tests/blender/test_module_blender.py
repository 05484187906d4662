"""deformkit inside real Blender (headless).

Run:
    PYTHONPATH=build/python blender -b --factory-startup --python-exit-code 1 \
        --python tests/blender/test_module_blender.py

Builds a Mesh from a bpy primitive's foreach_get buffers (array.array memoryviews and numpy),
computes a cotangent Laplacian, eigenpairs and a geodesic, checks them, prints
'N passed, N failed' and exits non-zero on any failure.
"""

import array
import math
import sys
import traceback

import bpy

RESULTS = {"passed": 0, "failed": 0}


def check(name, fn):
    """Runs one check, recording and printing its outcome."""
    try:
        fn()
    except Exception:  # noqa: BLE001 - every failure is reported
        RESULTS["failed"] += 1
        print("FAIL", name)
        traceback.print_exc()
    else:
        RESULTS["passed"] += 1
        print("ok  ", name)


def sphere_buffers():
    """Vertices (flat float32) and triangle indices (flat int32) of a triangulated UV sphere."""
    bpy.ops.mesh.primitive_uv_sphere_add(segments=32, ring_count=16, radius=1.0)
    me = bpy.context.active_object.data
    me.calc_loop_triangles()
    co = array.array("f", [0.0]) * (3 * len(me.vertices))
    me.vertices.foreach_get("co", co)
    tris = array.array("i", [0]) * (3 * len(me.loop_triangles))
    me.loop_triangles.foreach_get("vertices", tris)
    return co, tris, len(me.vertices), len(me.loop_triangles)


def main():
    import deformkit

    co, tris, nv, nt = sphere_buffers()
    state = {}

    def build_from_memoryview():
        mesh = deformkit.Mesh(memoryview(co), memoryview(tris))
        assert (mesh.n_vertices, mesh.n_faces) == (nv, nt)
        assert mesh.n_vertices - mesh.n_edges + mesh.n_faces == 2
        state["mesh"] = mesh

    def build_from_numpy():
        import numpy as np
        mesh = deformkit.Mesh(np.frombuffer(co, dtype=np.float32).reshape(-1, 3),
                              np.frombuffer(tris, dtype=np.int32).reshape(-1, 3))
        assert np.array_equal(mesh.triangles, state["mesh"].triangles)

    def laplacian():
        rows, cols, vals = deformkit.cotangent_laplacian(state["mesh"])
        sums = [0.0] * nv
        for r, v in zip(rows, vals):
            sums[r] += v
        assert max(abs(s) for s in sums) < 1e-9  # rows sum to zero
        assert all(v > 0 for r, c, v in zip(rows, cols, vals) if r == c)

    def eigenpairs():
        evals, evecs = deformkit.laplacian_eigenpairs(state["mesh"], 4)
        assert abs(evals[0]) < 1e-8
        for lam in evals[1:]:  # first non-constant band of the unit sphere: l(l+1) = 2
            assert abs(lam - 2.0) < 0.1, lam
        assert len(evecs) == nv

    def geodesic():
        mesh = state["mesh"]
        d = deformkit.geodesic_distance(mesh, [0])
        pts = mesh.vertices
        p0 = pts[0]
        errs = []
        for i in range(nv):
            exact = math.acos(max(-1.0, min(1.0, sum(a * b for a, b in zip(pts[i], p0)))))
            if exact > 0.3:
                errs.append(abs(d[i] - exact) / exact)
        assert sum(errs) / len(errs) < 0.05, sum(errs) / len(errs)

    def errors():
        bad = array.array("i", tris)
        bad[5] = nv + 10
        try:
            deformkit.Mesh(memoryview(co), memoryview(bad))
        except IndexError:
            pass
        else:
            raise AssertionError("out-of-range index accepted")

    for name, fn in [("mesh from foreach_get memoryviews", build_from_memoryview),
                     ("mesh from numpy views", build_from_numpy),
                     ("cotangent laplacian", laplacian), ("eigenpairs", eigenpairs),
                     ("heat geodesic", geodesic), ("index error", errors)]:
        if name != "mesh from foreach_get memoryviews" and "mesh" not in state:
            RESULTS["failed"] += 1
            print("SKIP(FAIL)", name, "- no mesh")
            continue
        check(name, fn)


try:
    main()
except Exception:  # noqa: BLE001
    traceback.print_exc()
    RESULTS["failed"] += 1
print("{} passed, {} failed".format(RESULTS["passed"], RESULTS["failed"]))
if RESULTS["failed"]:
    sys.exit(1)
