"""Workbench pictures of meshes side by side, for the benchmarks' comparisons (run inside
Blender, or with a `bpy` wheel's Python): the scripts that show a method against another
(bench_shape_blend_blender.py, render_volume_compare.py) build rows of tiles and call render."""
import os
import sys

import bpy
import numpy as np
from mathutils import Matrix

HERE = os.path.dirname(os.path.abspath(__file__))
sys.path.insert(0, os.path.join(HERE, "..", "tests", "blender"))
import _setup as S  # noqa: E402  (its OUTPUT folder)


def render(cells, path):
    """cells: rows of (positions, triangles) tiles, rendered side by side from the front."""
    sc = bpy.context.scene
    for ob in list(bpy.data.objects):
        ob.hide_render = True
    cam = bpy.data.objects.new("Cam", bpy.data.cameras.new("Cam"))
    sc.collection.objects.link(cam)
    sc.camera = cam
    cam.data.type = "ORTHO"
    sc.render.engine = "BLENDER_WORKBENCH"
    sc.render.resolution_x, sc.render.resolution_y = 320, 320
    sc.display.shading.light = "STUDIO"
    sc.display.shading.color_type = "SINGLE"
    sc.display.shading.single_color = (0.8, 0.75, 0.65)
    tmp = os.path.join(S.OUTPUT, "render_tile.png")
    rows = []
    for row_cells in cells:
        tiles = []
        for P, F, view in row_cells:
            centre, size, m = view
            cam.data.ortho_scale = size
            cam.matrix_world = Matrix(m) @ Matrix.Translation(tuple(centre))
            me = bpy.data.meshes.new("tile")
            me.from_pydata(P.tolist(), [], F.tolist())
            ob = bpy.data.objects.new("tile", me)
            sc.collection.objects.link(ob)
            cam.location = tuple(np.asarray(centre) + 4 * size * np.asarray(view[2])[:3, 2])
            sc.render.filepath = tmp
            bpy.ops.render.render(write_still=True)
            img = bpy.data.images.load(tmp, check_existing=False)
            px = np.array(img.pixels[:], dtype=np.float32).reshape(img.size[1], img.size[0], 4)
            bpy.data.images.remove(img)
            tiles.append(px)
            bpy.data.objects.remove(ob)
            bpy.data.meshes.remove(me)
        row = np.concatenate(tiles, axis=1)
        # the row's empty margins cut off: the pixel rows its models project to (orthographic:
        # the image's height spans ortho_scale along the camera's y), a little kept around
        res = sc.render.resolution_y
        lo, hi = res, 0
        for P, F, (centre, size, m) in row_cells:
            y = (P - np.asarray(centre)) @ np.asarray(m)[:3, 1]
            lo = min(lo, int(res / 2 - y.max() / size * res) - 12)
            hi = max(hi, int(res / 2 - y.min() / size * res) + 12)
        row = row[::-1][max(lo, 0):min(hi, res)][::-1]   # (pixels run bottom-up)
        rows.append(row)
    pic = np.concatenate(rows[::-1], axis=0)
    out = bpy.data.images.new("compare", pic.shape[1], pic.shape[0], alpha=True)
    out.pixels[:] = pic.ravel()
    out.filepath_raw = os.path.abspath(path)
    out.file_format = "PNG"
    out.save()
