"""deformkit inside real Blender (headless).

Run:
    PYTHONPATH=build/python blender -b --factory-startup --python-exit-code 1 \
        --python tests/blender/test_module_blender.py

Builds a Mesh from a bpy primitive's foreach_get buffers (array.array memoryviews and numpy),
computes a cotangent Laplacian, eigenpairs and a geodesic, checks them; and deformkit.Lattice
with the linear basis against this Blender's own Lattice modifier, vertex for vertex (issue
40). Prints 'N passed, N failed' and exits non-zero on any failure.
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

    def lattice_matches_blenders():
        """A sphere, moved, turned and scaled, under a Lattice modifier whose lattice (3 x 4 x
        2 points, linear interpolation, turned, moved and smaller than the sphere in places,
        so that some vertices lie outside it) has every point moved: deformkit.Lattice on the
        same box, linear with outside='clamp', gives Blender's result to float32 rounding,
        inside the box and out (docs/methods/lattice.md)."""
        import numpy as np
        from mathutils import Vector
        bpy.ops.mesh.primitive_ico_sphere_add(subdivisions=3, radius=1.0,
                                              location=(0.3, -0.2, 0.5))
        obj = bpy.context.active_object
        obj.rotation_euler = (0.3, 0.1, -0.4)
        obj.scale = (1.2, 0.8, 1.0)
        lt = bpy.data.lattices.new("DK test lattice")
        lat = bpy.data.objects.new("DK test lattice", lt)
        bpy.context.collection.objects.link(lat)
        lt.points_u, lt.points_v, lt.points_w = 3, 4, 2
        lt.interpolation_type_u = lt.interpolation_type_v = "KEY_LINEAR"
        lt.interpolation_type_w = "KEY_LINEAR"
        lat.location = (0.5, 0.0, 0.4)
        lat.rotation_euler = (0.2, -0.3, 0.5)
        lat.scale = (2.0, 1.6, 1.3)
        rng = np.random.default_rng(3)
        for p in lt.points:
            p.co_deform = p.co + Vector(rng.normal(scale=0.15, size=3))
        mod = obj.modifiers.new("Lattice", "LATTICE")
        mod.object = lat
        bpy.context.view_layer.update()
        dg = bpy.context.evaluated_depsgraph_get()
        ev = obj.evaluated_get(dg)
        em = ev.to_mesh()
        got = np.empty(3 * len(em.vertices), dtype=np.float32)
        em.vertices.foreach_get("co", got)
        ev.to_mesh_clear()
        me = obj.data
        rest = np.empty(3 * len(me.vertices), dtype=np.float32)
        me.vertices.foreach_get("co", rest)
        me.calc_loop_triangles()
        tri = np.empty(3 * len(me.loop_triangles), dtype=np.int32)
        me.loop_triangles.foreach_get("vertices", tri)
        rest, got = rest.reshape(-1, 3).astype(float), got.reshape(-1, 3).astype(float)
        # the lattice in the mesh's object space: its box from its first and last rest point
        M = np.array(obj.matrix_world.inverted() @ lat.matrix_world)
        lo, hi = np.array(lt.points[0].co), np.array(lt.points[len(lt.points) - 1].co)
        box = np.eye(4)
        box[:3, :3] = np.diag(hi - lo)
        box[:3, 3] = lo
        to_obj = lambda p: (M @ np.append(np.array(p), 1.0))[:3]  # noqa: E731
        L = deformkit.Lattice(deformkit.Mesh(rest, tri.reshape(-1, 3)), resolution=(3, 4, 2),
                              frame=M @ box, interpolation="linear", outside="clamp")
        diag = float(np.linalg.norm(np.ptp(rest, axis=0)))
        grid = np.array([to_obj(p.co) for p in lt.points])
        assert np.abs(np.asarray(L.rest_points) - grid).max() < 1e-5 * diag
        x = np.asarray(L.solve(np.array([to_obj(p.co_deform) for p in lt.points])).positions)
        u = (rest - (M @ box)[:3, 3]) @ np.linalg.inv((M @ box)[:3, :3]).T
        outside = ((u < 0) | (u > 1)).any(axis=1)
        assert 0 < outside.sum() < len(rest), outside.sum()   # both kinds are compared
        err = np.abs(x - got).max() / diag
        assert err < 2e-6, err
        assert np.abs(got - rest).max() > 0.05 * diag   # the lattice did deform

    for name, fn in [("lattice matches Blender's Lattice modifier", lattice_matches_blenders),
                     ("mesh from foreach_get memoryviews", build_from_memoryview),
                     ("mesh from numpy views", build_from_numpy),
                     ("cotangent laplacian", laplacian), ("eigenpairs", eigenpairs),
                     ("heat geodesic", geodesic), ("index error", errors)]:
        if name not in ("mesh from foreach_get memoryviews",
                        "lattice matches Blender's Lattice modifier") and "mesh" not in state:
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
