"""Issue 40: the add-on's Lattice and Cage deformers against Blender's Lattice and Mesh Deform
modifiers, in the same Blender and the same run, on the armadillo of armadillo-wave (43,243
vertices):

    PYTHONPATH=build/python build/venvs/bpy-5.3/bin/python scripts/bench_controls_blender.py
    PYTHONPATH=build/python blender -b --factory-startup --python scripts/bench_controls_blender.py

- lattice: a 4 x 4 x 4 lattice (Make Lattice), B-spline; a frame = one point moved and the
  view layer updated (the control re-evaluated, the deformer or modifier, the mesh);
- cage: the 98-vertex box cage of bench_cage.py; Mesh Deform bound at precision 4 and 5
  (bpy.ops.object.meshdeform_bind, the bind runs in the next evaluation), DeformKit's Cage
  bound with its Bind operator; a frame = one cage vertex moved and the view layer updated.
- skinning: a chain of 8 bones along the armadillo, 4 influences a vertex; the Skinning
  deformer (linear, dual quaternion) against the Armature modifier (Preserve Volume off, on);
  a frame = the middle bone turned and the view layer updated.
Each frame figure is the median of --frames updates; "no modifier" is the same update with
the mesh's deformer disabled (what the control's own re-evaluation and the update cost).
A script, not a test: compare the ratios within one run.
"""
import os
import statistics
import sys
import time

import bpy
import numpy as np

HERE = os.path.dirname(os.path.abspath(__file__))
sys.path.insert(0, HERE)
sys.path.insert(0, os.path.join(HERE, "..", "tests", "blender"))
import _setup as S  # noqa: E402  (the add-on, registered from addon/)
import bench_cage as bc  # noqa: E402

FRAMES = 15


def armadillo_object(name):
    mesh = bc.armadillo()
    V = np.asarray(mesh.vertices, dtype=np.float64)
    F = np.asarray(mesh.triangles, dtype=np.int64)
    return S.triangle_mesh_object(V, F, name)


def frames(move, shown, n=FRAMES):
    """The median and max ms of n updates, each after move(i), and how far the object
    `shown` moved between the first and the last (that the frames deformed it)."""
    out = []
    first = None
    for i in range(n):
        move(i)
        t0 = time.perf_counter()
        bpy.context.view_layer.update()
        out.append((time.perf_counter() - t0) * 1e3)
        if first is None:
            first = S.evaluated_positions(shown)
    moved = float(np.abs(S.evaluated_positions(shown) - first).max())
    return statistics.median(out), max(out), moved


def only(objs, keep):
    """Only `keep` of `objs` in the view layer's evaluation (the others hidden)."""
    for o in objs:
        o.hide_viewport = o is not keep
    bpy.context.view_layer.update()


def lattice_bench():
    S.reset_scene()
    obj = armadillo_object("Armadillo")
    bpy.ops.deformkit.add_deformer(method="LATTICE")
    d = obj.deformkit.deformers[0]
    bpy.ops.deformkit.make_lattice(resolution=(4, 4, 4))
    lat = d.control_object
    t0 = time.perf_counter()
    bpy.ops.deformkit.bind()
    bind_ms = (time.perf_counter() - t0) * 1e3
    twin = bpy.data.objects.new("Twin", obj.data.copy())
    bpy.context.scene.collection.objects.link(twin)
    for a in list(twin.data.attributes):
        if a.name.startswith("dk_"):
            twin.data.attributes.remove(a)
    lm = twin.modifiers.new("Lattice", "LATTICE")
    lm.object = lat
    gn = S.geonodes.find_modifier(obj, d)
    pt = lat.data.points[21]
    base = pt.co_deform.copy()
    size = max(obj.dimensions)

    def move(i):
        pt.co_deform = base + type(base)((0.0, 0.0, 0.02 * size * (1 + i % 5)))
        lat.data.update_tag()

    rows = []
    for label, shown, on in (("no modifier", obj, False), ("DeformKit Lattice", obj, True),
                             ("Blender Lattice", twin, True)):
        only((obj, twin), shown)
        # both flags: a deformer hidden in the viewport but rendered still solves
        gn.show_viewport = gn.show_render = on if shown is obj else False
        lm.show_viewport = on if shown is twin else False
        bpy.context.view_layer.update()
        rows.append((label,) + frames(move, shown))
    print("lattice 4 x 4 x 4 on %d vertices: DeformKit bind %.1f ms" % (len(obj.data.vertices),
                                                                      bind_ms))
    for label, med, mx, moved in rows:
        print("  %-18s a frame: median %.1f ms, max %.1f ms (moved %.3g)" % (label, med, mx,
                                                                           moved))
    sys.stdout.flush()


def cage_bench():
    S.reset_scene()
    obj = armadillo_object("Armadillo")
    V = S.rest_positions(obj)
    P, T = bc.box_cage(V, 5)
    cme = bpy.data.meshes.new("Cage")
    cme.from_pydata([tuple(p) for p in P], [], [tuple(int(i) for i in t) for t in T])
    cme.update()
    cage = bpy.data.objects.new("Cage", cme)
    bpy.context.scene.collection.objects.link(cage)
    cage.display_type = "WIRE"
    bpy.context.view_layer.objects.active = obj
    bpy.ops.deformkit.add_deformer(method="CAGE")
    d = obj.deformkit.deformers[0]
    d.control_object = cage
    t0 = time.perf_counter()
    bpy.ops.deformkit.bind()
    ours_bind = time.perf_counter() - t0
    gn = S.geonodes.find_modifier(obj, d)
    twin = bpy.data.objects.new("Twin", obj.data.copy())
    bpy.context.scene.collection.objects.link(twin)
    for a in list(twin.data.attributes):
        if a.name.startswith("dk_"):
            twin.data.attributes.remove(a)
    md = twin.modifiers.new("MeshDeform", "MESH_DEFORM")
    md.object = cage
    binds = {}
    bpy.context.view_layer.objects.active = twin
    for prec in (4, 5):
        if md.is_bound:
            with bpy.context.temp_override(object=twin, active_object=twin):
                bpy.ops.object.meshdeform_bind(modifier=md.name)   # unbinds
        md.precision = prec
        t0 = time.perf_counter()
        with bpy.context.temp_override(object=twin, active_object=twin):
            bpy.ops.object.meshdeform_bind(modifier=md.name)
        bpy.context.view_layer.update()
        binds[prec] = time.perf_counter() - t0
    co = cage.data.vertices[7].co
    base = co.copy()
    size = max(obj.dimensions)

    def move(i):
        cage.data.vertices[7].co = base + type(base)((0.0, 0.0, 0.02 * size * (1 + i % 5)))
        cage.data.update()

    rows = []
    for label, shown, on in (("no modifier", obj, False), ("DeformKit Cage", obj, True),
                             ("Mesh Deform (5)", twin, True)):
        only((obj, twin), shown)
        gn.show_viewport = gn.show_render = on if shown is obj else False
        md.show_viewport = on if shown is twin else False
        bpy.context.view_layer.update()
        rows.append((label,) + frames(move, shown))
    print("cage of %d vertices on %d vertices: DeformKit bind %.2f s; Mesh Deform bind "
          "%.2f s at precision 4, %.2f s at 5 (bound: %s); ratio at 5: %.1fx"
          % (len(P), len(V), ours_bind, binds[4], binds[5], md.is_bound,
             binds[5] / max(ours_bind, 1e-9)))
    for label, med, mx, moved in rows:
        print("  %-18s a frame: median %.1f ms, max %.1f ms (moved %.3g)" % (label, med, mx,
                                                                           moved))
    print("  (DeformKit's last native solve: %.1f ms)"
          % S.solver.runtime[(obj.name, d.uid)]["ms"])
    sys.stdout.flush()


def skinning_bench(n_bones=8, influences=4):
    """A chain of n_bones along the armadillo's height, each vertex weighted to its
    `influences` nearest bones (inverse distance): the Skinning deformer (both blends) and
    Blender's Armature modifier (Preserve Volume off and on) on a copy."""
    S.reset_scene()
    obj = armadillo_object("Armadillo")
    V = S.rest_positions(obj)
    lo, hi = V.min(axis=0), V.max(axis=0)
    heads = [lo + (hi - lo) * np.array([0.5, 0.5, k / n_bones]) for k in range(n_bones + 1)]
    arm, ao = S.bone_chain(heads, ["b%d" % k for k in range(n_bones)])
    mid = np.array([(heads[k] + heads[k + 1]) / 2 for k in range(n_bones)])
    dist = np.linalg.norm(V[:, None, :] - mid[None], axis=2)
    near = np.argsort(dist, axis=1)[:, :influences]
    w = 1.0 / np.maximum(np.take_along_axis(dist, near, axis=1), 1e-9) ** 2
    w /= w.sum(axis=1, keepdims=True)
    twin = bpy.data.objects.new("Twin", obj.data.copy())
    bpy.context.scene.collection.objects.link(twin)
    for o in (obj, twin):
        for k in range(n_bones):
            vg = o.vertex_groups.new(name="b%d" % k)
            for j in range(influences):
                sel = np.flatnonzero(near[:, j] == k)
                for v in sel:
                    vg.add([int(v)], float(w[v, j]), "REPLACE")
    am = twin.modifiers.new("Armature", "ARMATURE")
    am.object = ao
    bpy.context.view_layer.objects.active = obj
    bpy.ops.deformkit.add_deformer(method="SKINNING")
    d = obj.deformkit.deformers[0]
    d.control_object = ao
    t0 = time.perf_counter()
    bpy.ops.deformkit.bind()
    bind_ms = (time.perf_counter() - t0) * 1e3
    gn = S.geonodes.find_modifier(obj, d)
    pb = ao.pose.bones["b%d" % (n_bones // 2)]
    pb.rotation_mode = "XYZ"

    def move(i):
        pb.rotation_euler = (0.1 * (1 + i % 5), 0.0, 0.05 * (i % 3))

    rows = []
    for label, shown, blend in (("no modifier", obj, None),
                                ("DeformKit Skinning, linear", obj, "linear"),
                                ("DeformKit Skinning, dual quaternion", obj, "dual_quaternion"),
                                ("Blender Armature", twin, False),
                                ("Blender Armature, Preserve Volume", twin, True)):
        only((obj, twin), shown)
        if shown is obj:
            gn.show_viewport = gn.show_render = blend is not None
            if blend is not None:
                d.options.blend = blend
        else:
            am.use_deform_preserve_volume = blend
        bpy.context.view_layer.update()
        rows.append((label,) + frames(move, shown))
    print("skinning, %d bones, %d influences a vertex, %d vertices: DeformKit bind %.0f ms"
          % (n_bones, influences, len(V), bind_ms))
    for label, med, mx, moved in rows:
        print("  %-36s a frame: median %.1f ms, max %.1f ms (moved %.3g)" % (label, med, mx,
                                                                             moved))
    sys.stdout.flush()


def main():
    print("Blender %s" % bpy.app.version_string)
    lattice_bench()
    cage_bench()
    skinning_bench()


# the UI's path (quick topology checks, interactive solves), solved in the handler
S.handlers.force_interactive[0] = True
S.solver.threaded_solves[0] = False
if __name__ == "__main__":
    main()
    S.exit_now(0)
