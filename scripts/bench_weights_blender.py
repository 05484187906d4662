"""Issue 41: computed skinning weights, DeformKit's Compute Weights (bounded biharmonic
weights) against Blender's automatic weights (bone heat: Parent > With Automatic Weights), in
the same Blender and the same run, on the meshes of ../shared/meshes:

    PYTHONPATH=build/python build/venvs/bpy-5.3/bin/python scripts/bench_weights_blender.py
    PYTHONPATH=build/python blender -b --factory-startup --python scripts/bench_weights_blender.py
    ... scripts/bench_weights_blender.py -- --meshes armadillo.obj --bones 10 --scales 1

Each mesh gets a chain of --bones bones along its longest principal axis through its centroid
(10% to 90% of its extent), placed with the mesh at each --scales (the mesh and the bones
scaled about the origin, the mesh moved off it by its own size). For each: Blender's automatic
weights (the seconds, whether it warned "Bone Heat Weighting: failed", how many vertices it
weighted at all) and DeformKit's Compute Weights (the seconds, the domain, how many vertices
weighted). A script, not a test: compare within one run.
"""
import argparse
import os
import sys
import tempfile
import time

import bpy
import numpy as np

HERE = os.path.dirname(os.path.abspath(__file__))
sys.path.insert(0, os.path.join(HERE, "..", "tests", "blender"))
import _setup as S  # noqa: E402  (the add-on, registered from addon/)
import deformkit as dk  # noqa: E402

SHARED = os.path.join(HERE, "..", "..", "shared", "meshes")


def args():
    argv = sys.argv[sys.argv.index("--") + 1:] if "--" in sys.argv else []
    p = argparse.ArgumentParser()
    p.add_argument("--meshes", nargs="*", default=sorted(
        f for f in os.listdir(SHARED) if f.endswith((".obj", ".off", ".ply"))))
    p.add_argument("--bones", type=int, default=10)
    p.add_argument("--scales", type=float, nargs="*", default=[0.001, 1.0, 1000.0])
    return p.parse_args(argv)


def captured(fn):
    """fn()'s result and what it printed to the process's stdout and stderr (C prints too)."""
    with tempfile.TemporaryFile(mode="w+b") as tmp:
        sys.stdout.flush()
        sys.stderr.flush()
        saved = os.dup(1), os.dup(2)
        os.dup2(tmp.fileno(), 1)
        os.dup2(tmp.fileno(), 2)
        try:
            out = fn()
        finally:
            sys.stdout.flush()
            sys.stderr.flush()
            os.dup2(saved[0], 1)
            os.dup2(saved[1], 2)
            os.close(saved[0])
            os.close(saved[1])
        tmp.seek(0)
        return out, tmp.read().decode("utf-8", "replace")


def chain(V, n):
    c = V.mean(axis=0)
    _, _, vt = np.linalg.svd(V - c, full_matrices=False)
    axis = vt[0]
    t = (V - c) @ axis
    ts = np.linspace(np.quantile(t, 0.1), np.quantile(t, 0.9), n + 1)
    return [c + s * axis for s in ts]


def setup(V, F, joints):
    S.reset_scene()
    obj = S.triangle_mesh_object(V, F, "Scan")
    arm, ao = S.bone_chain(joints, ["b%02d" % j for j in range(len(joints) - 1)])
    return obj, ao


def weighted(obj):
    return sum(1 for v in obj.data.vertices if any(g.weight > 0 for g in v.groups))


def blender_auto(V, F, joints):
    obj, ao = setup(V, F, joints)
    bpy.ops.object.select_all(action="DESELECT")
    obj.select_set(True)
    ao.select_set(True)
    bpy.context.view_layer.objects.active = ao
    t0 = time.perf_counter()
    _, said = captured(lambda: bpy.ops.object.parent_set(type="ARMATURE_AUTO"))
    sec = time.perf_counter() - t0
    return sec, "failed" in said.lower(), weighted(obj)


def deformkit_weights(V, F, joints):
    obj, ao = setup(V, F, joints)
    bpy.context.view_layer.objects.active = obj
    obj.select_set(True)
    bpy.ops.deformkit.add_deformer(method="SKINNING")
    obj.deformkit.deformers[0].control_object = ao
    t0 = time.perf_counter()
    err = ""
    try:
        bpy.ops.deformkit.compute_weights()
    except RuntimeError as e:
        err = str(e).strip()
    sec = time.perf_counter() - t0
    return sec, err, weighted(obj)


def main():
    a = args()
    print("Blender %s; %d bones a chain" % (bpy.app.version_string, a.bones))
    print("| mesh | vertices | scale | Blender auto weights | DeformKit Compute Weights |")
    print("| --- | --- | --- | --- | --- |")
    for name in a.meshes:
        m = dk.read_mesh(os.path.join(SHARED, name))
        V0 = np.asarray(m.vertices, dtype=np.float64)
        F = np.asarray(m.triangles, dtype=np.int64)
        size = float(np.linalg.norm(V0.max(0) - V0.min(0)))
        for s in a.scales:
            V = (V0 - V0.mean(0)) / size * s + [s, 0.5 * s, 0.0]
            joints = chain(V, a.bones)
            bs, failed, bw = blender_auto(V, F, joints)
            ds, err, dw = deformkit_weights(V, F, joints)
            b = "%.2f s, %s%d weighted" % (bs, "**failed**, " if failed else "", bw)
            d = ("%.2f s, %d weighted" % (ds, dw)) if not err else "**error** " + err
            print("| %s | %d | %g | %s | %s |" % (name, len(V), s, b, d), flush=True)


main()
