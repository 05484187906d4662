"""Issue 39, item 8: the elbow case beside Blender's own answers. A capped tube (an arm, 2 units
long, radius 0.25) with two bones and automatic weights (Armature Deform with Automatic
Weights); the forearm bent 90 degrees. Compared, each on its own copy:

  LBS                 the Armature modifier as it comes (linear blend skinning)
  Preserve Volume     the Armature's Preserve Volume (dual quaternions)
  Corrective Smooth   LBS, then Blender's Corrective Smooth modifier (its defaults, rest from
                      the original coordinates)
  DeformKit ARAP      LBS, then a DeformKit ARAP deformer with Solve From: Rest Shape: the
                      upper arm and the forearm (beyond 0.4 of the elbow) handles riding
                      their bones, the elbow between them solved as rigidly as possible
                      from the rest shape

and for each the enclosed volume against the rest's, the RMS and the largest relative
change of the edge lengths, and the time of a frame. With --render DIR it also renders the
four side by side (Workbench) into DIR/elbow_compare.png.

    PYTHONPATH=build/python build/venvs/bpy-5.3/bin/python scripts/bench_elbow.py \\
        [--render docs/images]

A script, not a test (tests/blender/test_addon_animation.py holds the checks).
"""
import math
import os
import sys
import time

import bpy
import numpy as np

HERE = os.path.dirname(os.path.abspath(__file__))
sys.path.insert(0, os.path.join(HERE, "..", "tests", "blender"))
import _setup as S  # noqa: E402  (the add-on, registered from addon/)

# the handles: the tube beyond this distance from the elbow, on either side
REACH = float(os.environ.get("DEFORMKIT_ELBOW_REACH", "0.4"))


def args():
    import argparse
    argv = sys.argv[sys.argv.index("--") + 1:] if "--" in sys.argv else sys.argv[1:]
    ap = argparse.ArgumentParser()
    ap.add_argument("--render", default="")
    ap.add_argument("--angle", type=float, default=90.0)
    return ap.parse_args(argv)


def tube(name, x0, rings=48, around=24):
    """A capped tube along x from x0 - 1 to x0 + 1 (local coordinates -1 to 1), `rings`
    segments of `around` quads, a fan at each end."""
    t = np.linspace(0.0, 2.0 * np.pi, around, endpoint=False)
    xs = np.linspace(-1.0, 1.0, rings + 1)
    V = [(x, 0.25 * np.cos(a), 0.25 * np.sin(a)) for x in xs for a in t]
    V += [(-1.0, 0.0, 0.0), (1.0, 0.0, 0.0)]
    F = []
    for r in range(rings):
        for k in range(around):
            a0, a1 = r * around + k, r * around + (k + 1) % around
            F.append((a0, a1, a1 + around, a0 + around))
    c0, c1, top = len(V) - 2, len(V) - 1, rings * around
    F += [(c0, (k + 1) % around, k) for k in range(around)]
    F += [(c1, top + k, top + (k + 1) % around) for k in range(around)]
    me = bpy.data.meshes.new(name)
    me.from_pydata([tuple(v) for v in V], [], F)
    me.update()
    obj = S.linked_object(name, me)
    obj.location = (x0, 0.0, 0.0)
    return obj


def rig(obj, x0, angle):
    arm, ao = S.armature_in_edit_mode(obj.name + " rig")
    up = arm.edit_bones.new("upper")
    up.head, up.tail = (x0 - 1.0, 0, 0), (x0, 0, 0)
    lo = arm.edit_bones.new("lower")
    lo.head, lo.tail = (x0, 0, 0), (x0 + 1.0, 0, 0)
    lo.parent, lo.use_connect = up, True
    bpy.ops.object.mode_set(mode="OBJECT")
    bpy.ops.object.select_all(action="DESELECT")
    obj.select_set(True)
    ao.select_set(True)
    bpy.context.view_layer.objects.active = ao
    bpy.ops.object.parent_set(type="ARMATURE_AUTO")
    pb = ao.pose.bones["lower"]
    pb.rotation_mode = "XYZ"
    pb.rotation_euler = (0.0, 0.0, math.radians(angle))
    bpy.context.view_layer.objects.active = obj
    return ao


def volume_and_edges(obj, rest):
    """(volume, RMS and largest relative edge change) of the evaluated mesh."""
    x = S.evaluated_positions(obj)
    me = obj.data
    tri = S.solver.triangles(me)
    a, b, c = x[tri[:, 0]], x[tri[:, 1]], x[tri[:, 2]]
    vol = float(np.einsum("ij,ij->i", a, np.cross(b, c)).sum() / 6.0)
    e = np.empty(len(me.edges) * 2, dtype=np.int32)
    me.edges.foreach_get("vertices", e)
    e = e.reshape(-1, 2)
    l0 = np.linalg.norm(rest[e[:, 0]] - rest[e[:, 1]], axis=1)
    l1 = np.linalg.norm(x[e[:, 0]] - x[e[:, 1]], axis=1)
    r = (l1 - l0) / l0
    return vol, float(np.sqrt((r * r).mean())), float(np.abs(r).max())


def rest_volume(obj):
    x = S.rest_positions(obj)
    tri = S.solver.triangles(obj.data)
    a, b, c = x[tri[:, 0]], x[tri[:, 1]], x[tri[:, 2]]
    return float(np.einsum("ij,ij->i", a, np.cross(b, c)).sum() / 6.0)


def main():
    a = args()
    S.reset_scene()
    rows = []
    variants = ("LBS", "Preserve Volume", "Corrective Smooth", "DeformKit ARAP")
    objs = []
    for i, name in enumerate(variants):
        x0 = 3.0 * i
        obj = tube(name, x0)
        ao = rig(obj, x0, a.angle)
        arm_mod = next(m for m in obj.modifiers if m.type == "ARMATURE")
        if name == "Preserve Volume":
            arm_mod.use_deform_preserve_volume = True
        if name == "Corrective Smooth":
            obj.modifiers.new("Corrective Smooth", "CORRECTIVE_SMOOTH")
        if name == "DeformKit ARAP":
            rest = S.rest_positions(obj)
            S.group(obj, "dk upper", np.where(rest[:, 0] < -REACH)[0])
            S.group(obj, "dk lower", np.where(rest[:, 0] > REACH)[0])
            bpy.context.view_layer.objects.active = obj
            bpy.ops.deformkit.add_deformer(method="ARAP")
            d = obj.deformkit.deformers[0]
            d.solve_from = "REST"
            bpy.ops.deformkit.add_handle(vertex_group="dk upper", target=ao.name,
                                         subtarget="upper")
            bpy.ops.deformkit.add_handle(vertex_group="dk lower", target=ao.name,
                                         subtarget="lower")
            pb = ao.pose.bones["lower"]
            turned = tuple(pb.rotation_euler)
            pb.rotation_euler = (0.0, 0.0, 0.0)    # bind on the rig's rest
            bpy.context.view_layer.update()
            bpy.ops.deformkit.bind()
            pb.rotation_euler = turned
            bpy.context.view_layer.update()
        objs.append(obj)
    bpy.context.view_layer.update()
    dg = bpy.context.evaluated_depsgraph_get()
    for obj in objs:
        rest = S.rest_positions(obj)
        ms = None
        if obj.deformkit.deformers:   # the deformer's cold solve, as a frame or a bake has it
            t0 = time.perf_counter()
            S.solver.evaluate_object(obj, dg, cold=True)
            ms = (time.perf_counter() - t0) * 1000.0
        vol, rms, worst = volume_and_edges(obj, rest)
        rows.append((obj.name, vol / rest_volume(obj), rms, worst, ms))
    print("bench_elbow: Blender %s, a capped tube of %d vertices bent %.0f degrees"
          % (bpy.app.version_string, len(objs[0].data.vertices), a.angle))
    print("  %-18s %9s %13s %13s %9s" % ("variant", "volume", "RMS edge chg", "max edge chg",
                                          "solve ms"))
    for name, v, rms, worst, ms in rows:
        print("  %-18s %8.1f%% %12.2f%% %12.1f%% %9s" % (name, 100 * v, 100 * rms, 100 * worst,
                                                           "-" if ms is None else "%.1f" % ms))
    if a.render:
        sc = bpy.context.scene
        cam = bpy.data.objects.new("Cam", bpy.data.cameras.new("Cam"))
        sc.collection.objects.link(cam)
        sc.camera = cam
        cam.data.type = "ORTHO"
        cam.data.ortho_scale = 11.5
        cam.location = (4.0, 0.5, 10.0)
        sc.render.engine = "BLENDER_WORKBENCH"
        sc.display.shading.light = "STUDIO"
        sc.render.resolution_x, sc.render.resolution_y = 1200, 300
        for ob in bpy.data.objects:
            if ob.type == "ARMATURE":
                ob.hide_render = True
        os.makedirs(a.render, exist_ok=True)
        sc.render.filepath = os.path.join(os.path.abspath(a.render), "elbow_compare.png")
        bpy.ops.render.render(write_still=True)
        print("bench_elbow: rendered %s" % sc.render.filepath)
    sys.stdout.flush()


main()
S.exit_now(0)
