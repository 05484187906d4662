"""Issue 43: the Shape Blend deformer in Blender, against Blender's own shape-key blend:

    PYTHONPATH=build/python build/venvs/bpy-5.3/bin/python scripts/bench_shape_blend_blender.py
    ... scripts/bench_shape_blend_blender.py -- --render docs/images/shape_blend_compare.png

The armadillo (43,243 vertices) with a shape key Twist (turned about its vertical axis by up
to 270 degrees with its height) and a capped bar with a key twisted by 360 degrees, each with
a Shape Blend deformer (the add-on's defaults). Measured: playback of the key's slider keyed
from 0 to 1 over 48 frames (frame_set through the range: one in-between a frame), against
the scene's frame time (24 fps: 41.7 ms) and the same playback with the deformer's modifier
off (Blender's linear blend alone); the volume half way with each. With --render: a Workbench
picture, for each model the Basis, Blender's blend at 0.5, Shape Blend at 0.5 and the key at
1 (looked at; docs/methods/shape_interpolation.md). A script, not a test.
"""
import argparse
import os
import sys
import time

import bpy
import numpy as np

HERE = os.path.dirname(os.path.abspath(__file__))
sys.path.insert(0, os.path.join(HERE, "..", "tests", "blender"))
import _setup as S  # noqa: E402  (the add-on, registered from addon/)
sys.path.insert(0, HERE)
from bench_shape_interpolation import turned, volume  # noqa: E402
from render_tiles import render  # noqa: E402

SHARED = os.path.join(HERE, "..", "..", "shared", "meshes")


def args():
    argv = sys.argv[sys.argv.index("--") + 1:] if "--" in sys.argv else []
    p = argparse.ArgumentParser()
    p.add_argument("--frames", type=int, default=48)
    p.add_argument("--render", default="", help="write the comparison here (PNG)")
    return p.parse_args(argv)


def keyed(name, V, F, axis, degrees):
    """An object of V, F with keys Basis and Twist, a Shape Blend deformer, bound."""
    obj = S.triangle_mesh_object(V, F, name=name)
    obj.shape_key_add(name="Basis")
    kb = obj.shape_key_add(name="Twist", from_mix=False)
    kb.data.foreach_set("co", turned(V, axis, degrees).astype(np.float32).ravel())
    kb.value = 0.0
    bpy.ops.deformkit.add_deformer(method="SHAPE_BLEND")
    d = obj.deformkit.deformers[0]
    bpy.ops.deformkit.bind()
    assert d.bound and not d.status_is_error, d.status
    return obj, d, kb


def playback(obj, d, kb, frames):
    sc = bpy.context.scene
    sc.frame_start, sc.frame_end = 1, frames
    kb.keyframe_insert("value", frame=1)
    kb.value = 1.0
    kb.keyframe_insert("value", frame=frames)
    mod = S.geonodes.find_modifier(obj, d)
    out = {}
    for on in (True, False):
        mod.show_viewport = on
        S.handlers.enabled[0] = on
        sc.frame_set(1)
        t0 = time.perf_counter()
        for f in range(1, frames + 1):
            sc.frame_set(f)
            bpy.context.evaluated_depsgraph_get()
        out[on] = 1e3 * (time.perf_counter() - t0) / frames
    mod.show_viewport = True
    S.handlers.enabled[0] = True
    return out


def main():
    a = args()
    S.reset_scene()
    verts, sizes, idx = S.dk.load_mesh_file(os.path.join(SHARED, "armadillo.obj"))
    mesh = S.dk.Mesh.from_polygons(verts, sizes, idx)
    V, F = np.asarray(verts, dtype=float), np.asarray(mesh.triangles)
    up = int(np.argmax(np.ptp(V, axis=0)))
    rows = []
    Vb, Fb = S.tube(n_len=41)
    Vb[:, 1:] *= 1.5   # a bar a little stouter than the test tube
    for name, (V0, F0, axis, deg) in (("Armadillo", (V, F, up, 270.0)),
                                      ("Bar", (np.asarray(Vb), np.asarray(Fb), 0, 360.0))):
        obj, d, kb = keyed(name, V0, F0, axis, deg)
        n = len(V0)
        kb.value = 0.5
        ours = S.evaluated_positions(obj)
        theirs = S.armature_input(obj, d)   # the stack with DeformKit's modifier off
        kb.value = 1.0
        pose = S.evaluated_positions(obj)
        kb.value = 0.0
        v0 = volume(V0, F0)
        print("%s: %d vertices; half way the volume is %.3f with Shape Blend, %.3f with "
              "Blender's blend" % (name, n, volume(ours, F0) / v0, volume(theirs, F0) / v0))
        ms = playback(obj, d, kb, a.frames)
        print("  playback of the keyed slider: %.1f ms a frame with Shape Blend (%.2fx of 24 "
              "fps), %.1f ms with Blender's blend alone" % (ms[True], 41.7 / ms[True], ms[False]))
        ext = np.ptp(V0, axis=0)
        size = 1.15 * float(np.max(ext))
        centre = V0.mean(0)
        # look along the axis that is neither the twist's nor the longest other one's
        others = [k for k in range(3) if k != axis]
        depth = others[int(np.argmin(ext[others]))]
        side = [k for k in others if k != depth][0]
        M = np.eye(4)
        # camera frame: x = the long axis or the side, y = up, z = towards the camera
        xa = side if name == "Armadillo" else axis
        ya = axis if name == "Armadillo" else side
        M[:3, 0] = np.eye(3)[xa]
        M[:3, 1] = np.eye(3)[ya]
        M[:3, 2] = np.cross(M[:3, 0], M[:3, 1])
        view = (centre, size, M.tolist())
        rows.append([(V0, F0, view), (theirs, F0, view), (ours, F0, view), (pose, F0, view)])
        obj.hide_viewport = True
    if a.render:
        render(rows, a.render)
        print("wrote %s (each row: the Basis, Blender's blend at 0.5, Shape Blend at 0.5, the "
              "key at 1)" % a.render)
    S.exit_now(0)


main()
