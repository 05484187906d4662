"""Issue 42: a jiggle on the armadillo's belly, driven by a keyed armature, in Blender:

    PYTHONPATH=build/python build/venvs/bpy-5.3/bin/python scripts/bench_jiggle_blender.py
    PYTHONPATH=build/python blender -b --factory-startup --python scripts/bench_jiggle_blender.py
    ... scripts/bench_jiggle_blender.py -- --frames 250 --render docs/images/jiggle_armadillo.png

The armadillo (43,243 vertices) on one bone that hops: up a tenth of its height over 5 frames
and down over 5, ten times, then stands still until --frames. A Jiggle deformer (ShapeMatching,
the add-on's defaults) after the Armature, its Region a sphere about the belly: the rest
follows the rig. Measured in one run: the playback that simulates each frame (frame_set
through the range, each frame from the one before), playing it again from the kept frames,
the bake to a point cache, and the cache played by Blender's Mesh Cache modifier without
DeformKit; each as milliseconds a frame against the scene's frame time (24 fps: 41.7 ms).
With --render: a Workbench strip of frames around a landing, the rig's pose above and the
jiggle below (looked at; docs/methods/shape_matching.md). A script, not a test.
"""
import argparse
import os
import sys
import time

import bpy
import numpy as np
from mathutils import Matrix

HERE = os.path.dirname(os.path.abspath(__file__))
sys.path.insert(0, os.path.join(HERE, "..", "tests", "blender"))
import _setup as S  # noqa: E402  (the add-on, registered from addon/)
from addon import bake  # noqa: E402

SHARED = os.path.join(HERE, "..", "..", "shared", "meshes")


def args():
    argv = sys.argv[sys.argv.index("--") + 1:] if "--" in sys.argv else []
    p = argparse.ArgumentParser()
    p.add_argument("--mesh", default="armadillo.obj")
    p.add_argument("--frames", type=int, default=250)
    p.add_argument("--render", default="", help="write the strip of frames here (PNG)")
    p.add_argument("--strip", type=int, nargs="*", default=[46, 49, 51, 53, 56, 60])
    return p.parse_args(argv)


def scene(a):
    S.reset_scene()
    v, sizes, idx = S.dk.load_mesh_file(os.path.join(SHARED, a.mesh))
    V, F = np.asarray(v, dtype=np.float64), np.asarray(idx).reshape(-1, 3)
    obj = S.triangle_mesh_object(V, F, "Armadillo")
    lo, hi = V.min(0), V.max(0)
    height = hi[1] - lo[1]
    # the belly: a sphere in front of the torso (the armadillo stands along +y, faces +z)
    centre = np.array([0.0, lo[1] + 0.52 * height, 0.06])
    belly = np.flatnonzero(np.linalg.norm(V - centre, axis=1) < 0.2 * height)
    S.group(obj, "belly", belly)
    S.group(obj, "body", range(len(V)))
    arm, ao = S.bone_chain([(0.0, lo[1], 0.0), (0.0, hi[1], 0.0)], ["body"], "Rig")
    pb = ao.pose.bones["body"]
    for k in range(10):   # hops: up over 5 frames, down over 5 (pose space: along the bone)
        for f, up in ((1 + 10 * k, 0.0), (6 + 10 * k, 0.1 * height), (11 + 10 * k, 0.0)):
            pb.location = (0.0, up, 0.0)
            pb.keyframe_insert("location", frame=f)
    mod = obj.modifiers.new("Armature", "ARMATURE")
    mod.object = ao
    bpy.context.view_layer.objects.active = obj
    bpy.ops.deformkit.add_deformer(method="SHAPE_MATCHING")
    d = obj.deformkit.deformers[0]
    d.roi_group = "belly"
    sc = bpy.context.scene
    sc.frame_start, sc.frame_end = 1, a.frames
    sc.render.fps, sc.render.fps_base = 24, 1.0
    sc.frame_set(1)
    bpy.ops.deformkit.bind()
    return obj, d, belly, height, centre


def per_frame(fn, frames):
    t0 = time.perf_counter()
    for f in frames:
        fn(f)
    return 1000.0 * (time.perf_counter() - t0) / len(frames)


def frame_object(name, P, F, heat):
    """A still object of positions P (n x 3) and triangles F, coloured by `heat` in [0, 1]
    (white to orange to red, per vertex)."""
    obj = S.triangle_mesh_object(P, F, name)
    h = np.clip(heat, 0.0, 1.0)[:, None]
    white, orange, red = np.array([0.85, 0.85, 0.87]), np.array([1.0, 0.55, 0.1]), \
        np.array([0.8, 0.05, 0.05])
    rgb = np.where(h < 0.5, white + 2 * h * (orange - white), orange + (2 * h - 1) * (red - orange))
    me = obj.data
    col = me.color_attributes.new("offset", "FLOAT_COLOR", "POINT")
    col.data.foreach_set("color", np.c_[rgb, np.ones(len(P))].astype(np.float32).ravel())
    me.color_attributes.active_color = col
    return obj


def render_strip(obj, d, frames, path, height, centre):
    """Per frame of `frames`: the rig's pose (top) and the jiggle coloured by how far each
    vertex is from the pose (bottom: white 0, red a tenth of the height or more), rendered
    from the side."""
    sc = bpy.context.scene
    F = np.asarray(S.solver.triangles(obj.data)).reshape(-1, 3)
    shots = []
    for f in frames:
        sc.frame_set(f)
        shots.append((S.armature_input(obj, d), S.evaluated_positions(obj)))
    obj.hide_render = True
    for ob in bpy.data.objects:
        if ob.type == "ARMATURE":
            ob.hide_render = True
    cam = bpy.data.objects.new("Cam", bpy.data.cameras.new("Cam"))
    sc.collection.objects.link(cam)
    sc.camera = cam
    cam.data.type = "ORTHO"
    cam.data.ortho_scale = 0.8 * height
    # from the side (+x), the model's up (+y) up in the image, on the torso: the belly's
    # profile (the armadillo faces +z: left in the image)
    cam.matrix_world = Matrix(((0, 0, 1, 2.0 * height), (0, 1, 0, float(centre[1])),
                               (-1, 0, 0, float(centre[2]) - 0.1 * height), (0, 0, 0, 1)))
    sc.render.engine = "BLENDER_WORKBENCH"
    sc.render.resolution_x, sc.render.resolution_y = 300, 380
    sc.display.shading.light = "STUDIO"
    sc.display.shading.color_type = "VERTEX"
    tmp = os.path.join(S.OUTPUT, "jiggle_tile.png")
    rows = [[], []]
    for pose, got in shots:
        off = np.linalg.norm(got - pose, axis=1) / (0.1 * height)
        for row, (P, heat) in enumerate(((pose, np.zeros(len(pose))), (got, off))):
            tile = frame_object("tile", P, F, heat)
            sc.render.filepath = tmp
            bpy.ops.render.render(write_still=True)
            img = bpy.data.images.load(tmp, check_existing=False)
            px = np.array(img.pixels[:], dtype=np.float32).reshape(img.size[1], img.size[0], 4)
            bpy.data.images.remove(img)
            rows[row].append(px)
            me = tile.data
            bpy.data.objects.remove(tile)
            bpy.data.meshes.remove(me)
    strip = np.concatenate([np.concatenate(r, axis=1) for r in rows[::-1]], axis=0)
    out = bpy.data.images.new("strip", strip.shape[1], strip.shape[0], alpha=True)
    out.pixels[:] = strip.ravel()
    out.filepath_raw = os.path.abspath(path)
    out.file_format = "PNG"
    out.save()
    obj.hide_render = False
    print("wrote %s (top: the rig's pose; bottom: the jiggle, red where it is a tenth of the "
          "height off the pose; frames %s)" % (path, ", ".join(map(str, frames))))


def main():
    a = args()
    obj, d, belly, height, centre = scene(a)
    sc = bpy.context.scene
    frames = list(range(1, a.frames + 1))

    def show(f):
        sc.frame_set(f)

    simulate = per_frame(show, frames)
    replay = per_frame(show, frames)
    key = (obj.name, d.uid)
    sim = S.solver.cache._cache[key].sim
    kept = sum(len(r[1] or b"") for r in sim.items.values())
    # how far the belly swings from the rig's pose, in the hops and after them
    swing = []
    for f in (49, 51, 53, 110, a.frames):
        sc.frame_set(f)
        got = S.evaluated_positions(obj)[belly]
        pose = S.armature_input(obj, d)[belly]
        swing.append((f, float(np.abs(got - pose).max()) / height))
    path = os.path.join(S.OUTPUT, "jiggle_bench.pc2")
    if os.path.exists(path):
        os.remove(path)
    t0 = time.perf_counter()
    bake.bake_pc2(bpy.context, obj, d, 1, a.frames, path, add_cache=False)
    baked = 1000.0 * (time.perf_counter() - t0) / a.frames
    S.solver.cache._cache[key].sim = None   # a bake from nothing kept
    t0 = time.perf_counter()
    bake.bake_pc2(bpy.context, obj, d, 1, a.frames, path, add_cache=False)
    baked_cold = 1000.0 * (time.perf_counter() - t0) / a.frames
    mc = obj.modifiers.new("MeshCache", "MESH_CACHE")
    mc.cache_format, mc.filepath = "PC2", path
    mc.frame_start = 1
    S.geonodes.find_modifier(obj, d).show_viewport = False
    obj.modifiers["Armature"].show_viewport = False
    S.handlers.enabled[0] = False

    def show_cache(f):
        sc.frame_set(f)
        S.evaluated_positions(obj)
    cached = per_frame(show_cache, frames)
    obj.modifiers.remove(mc)
    S.geonodes.find_modifier(obj, d).show_viewport = True
    obj.modifiers["Armature"].show_viewport = True
    S.handlers.enabled[0] = True
    frame_ms = 1000.0 / 24
    print("%s, %d vertices, belly %d, %d frames (24 fps: %.1f ms a frame), Blender %s"
          % (a.mesh, len(obj.data.vertices), len(belly), a.frames, frame_ms,
             bpy.app.version_string))
    print("  playback simulating each frame  %6.1f ms a frame (%.2fx the frame time)"
          % (simulate, simulate / frame_ms))
    print("  playback of the kept frames     %6.1f ms a frame (%.2fx)" % (replay, replay / frame_ms))
    print("  bake (frames kept)              %6.1f ms a frame" % baked)
    print("  bake (nothing kept)             %6.1f ms a frame, %.1f s in all"
          % (baked_cold, baked_cold * a.frames / 1000))
    print("  Mesh Cache of the bake          %6.1f ms a frame" % cached)
    print("  checkpoints kept: %.0f MB" % (kept / 2 ** 20))
    print("  belly off the rig's pose (of the height): %s"
          % ", ".join("frame %d %.3f" % s for s in swing))
    if a.render:
        render_strip(obj, d, a.strip, a.render, height, centre)


main()
