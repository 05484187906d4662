"""Issue 39: the per-frame cost of each method on an animated input, in Blender. The armadillo
of the armadillo-wave scenario (43,243 vertices) is rigged with two bones, the raised arm's
bone keyed from 0 to 60 degrees over frames 1-24; a DeformKit deformer after the Armature
modifier holds the feet (the scenario's fixed set) and lifts the hand (its handle) by 5% of
the model's size, edited once on frame 1. Playback is then stepped frame by frame as Blender
plays it (scene.frame_set: the frame handler solves each frame cold, as a bake does):

    PYTHONPATH=build/python build/venvs/bpy-5.3/bin/python scripts/bench_animated.py \\
        [--methods ARAP,LAPLACIAN,FALLOFF,EMBEDDED,EIGEN,LINEAR_RECONSTRUCTION] [--frames 24]

(or `blender -b --factory-startup --python scripts/bench_animated.py -- ...`). Per method:
the bind, then the median and largest time of a frame (frame_set, the Armature and the
solve together), the frames per second that makes, and the time of the same frames with the
deformer off (the rig alone). A script, not a test: compare methods within one run.
"""
import json
import math
import os
import statistics
import sys
import time

import bpy
import numpy as np

HERE = os.path.dirname(os.path.abspath(__file__))
sys.path.insert(0, os.path.join(HERE, "..", "tests", "blender"))
import _setup as S  # noqa: E402  (the add-on, registered from addon/)

SHARED = os.environ.get("DEFORMKIT_SHARED", os.path.join(HERE, "..", "..", "shared"))


def args():
    import argparse
    argv = sys.argv[sys.argv.index("--") + 1:] if "--" in sys.argv else sys.argv[1:]
    ap = argparse.ArgumentParser()
    ap.add_argument("--methods", default="ARAP,LAPLACIAN,FALLOFF,EMBEDDED,EIGEN,"
                                         "LINEAR_RECONSTRUCTION")
    ap.add_argument("--frames", type=int, default=24)
    return ap.parse_args(argv)


def armadillo():
    """The scenario's mesh as an object, its handle and fixed vertex indices."""
    sc = json.load(open(os.path.join(SHARED, "scenarios", "armadillo-wave.json")))
    mesh = S.dk.read_mesh(os.path.join(SHARED, "scenarios", sc["mesh"]))
    V, F = np.asarray(mesh.vertices), np.asarray(mesh.triangles)
    obj = S.triangle_mesh_object(V, F, "armadillo")
    return obj, V, np.array(sc["handles"][0]["vertices"]), np.array(sc["fixed"])


def rig(obj, V, hand, frames):
    """Two bones: 'body' holds everything, 'arm' the vertices within a third of the way from
    the hand to the body's centre (blended over the next sixth), turned 60 degrees about the
    shoulder by the last frame."""
    c, h = V.mean(axis=0), V[hand].mean(axis=0)
    d = np.linalg.norm(V - h, axis=1) / np.linalg.norm(h - c)
    w = np.clip((0.5 - d) / (1.0 / 6.0), 0.0, 1.0)
    S.group(obj, "arm", range(len(V)), w)
    S.group(obj, "body", range(len(V)), 1.0 - w)
    arm, ao = S.armature_in_edit_mode("Rig")
    body = arm.edit_bones.new("body")
    body.head, body.tail = tuple(c), tuple(c + [0, 0, 0.1 * np.ptp(V[:, 2])])
    shoulder = h + 0.5 * (c - h)
    b = arm.edit_bones.new("arm")
    b.head, b.tail = tuple(shoulder), tuple(h)
    b.parent = body
    bpy.ops.object.mode_set(mode="OBJECT")
    pb = ao.pose.bones["arm"]
    pb.rotation_mode = "XYZ"
    for f, a in ((1, 0.0), (frames, math.radians(60))):
        pb.rotation_euler = (a, 0.0, 0.0)
        pb.keyframe_insert("rotation_euler", frame=f)
    mod = obj.modifiers.new("Armature", "ARMATURE")
    mod.object = ao
    bpy.context.view_layer.objects.active = obj
    return ao


def frame_times(frames):
    sc = bpy.context.scene
    out = []
    for f in range(2, frames + 1):
        t0 = time.perf_counter()
        sc.frame_set(f)
        out.append((time.perf_counter() - t0) * 1000.0)
    sc.frame_set(1)
    return out


def main():
    a = args()
    S.handlers.enabled[0] = True
    print("bench_animated: Blender %s, armadillo-wave rigged, %d frames"
          % (bpy.app.version_string, a.frames))
    for mid in a.methods.split(","):
        S.reset_scene()
        sc = bpy.context.scene
        sc.frame_start, sc.frame_end = 1, a.frames
        sc.frame_set(1)
        obj, V, hand, fixed = armadillo()
        rig(obj, V, hand, a.frames)
        S.group(obj, "fixed", fixed)
        S.group(obj, "hand", hand)
        e = S.empty("Hand", tuple(V[hand].mean(axis=0)))
        bpy.context.view_layer.objects.active = obj
        bpy.ops.deformkit.add_deformer(method=mid)
        d = obj.deformkit.deformers[0]
        d.fixed_group = "fixed"
        bpy.ops.deformkit.add_handle(vertex_group="hand", target=e.name)
        t0 = time.perf_counter()
        bpy.ops.deformkit.bind()
        bind_ms = (time.perf_counter() - t0) * 1000.0
        e.location.z += 0.05 * float(np.linalg.norm(np.ptp(V, axis=0)))
        bpy.context.view_layer.update()
        with_dk = frame_times(a.frames)
        mod = S.geonodes.find_modifier(obj, d)
        mod.show_viewport = False
        S.handlers.enabled[0] = False
        rig_only = frame_times(a.frames)
        S.handlers.enabled[0] = True
        mod.show_viewport = True
        med = statistics.median(with_dk)
        print("  %-22s bind %7.0f ms  frame median %7.1f ms  max %7.1f ms  (%5.1f fps); "
              "the rig alone %5.1f ms" % (S.methods.get(mid).label, bind_ms, med, max(with_dk),
                                          1000.0 / med, statistics.median(rig_only)))
        sys.stdout.flush()


main()
S.exit_now(0)
