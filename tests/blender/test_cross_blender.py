"""The same scenes in every Blender: records what this Blender shows, and reopens the files
that older Blenders saved, without the add-on.

Run in each Blender by tests/blender/run_all.sh (DEFORMKIT_BLENDER_LABEL names it: debian,
bpy-4.5, bpy-5.2, bpy-5.3). It builds a few scenes (a bumpy grid with each method and a
rotated and moved handle, and the shared arm with ARAP and Laplacian editing when ../shared
is there), binds and solves them cold through the add-on, keys each deformer's Factor (1 on
frame 1, 0.5 on frame 11), and writes into tests/blender/output/cross/:
  <label>.npz    every object's evaluated positions on frames 1 and 11, the mesh diagonals,
                 the Blender version
  <label>.blend  the scenes, saved with their bound, keyframed deformers
Then, for every <other>.blend saved there by an older Blender, it opens that file in this
Blender with no add-on and no native module (a subprocess) and checks that the evaluated
meshes on both frames equal what the older Blender recorded (so the keyed Factor still
animates: from 5.2 its F-curve has a new data path, which Blender versions on load), writing
the figures to <label>.reloads.json.
tests/blender/compare_blenders.py compares the .npz files of all Blenders afterwards.
"""
import json
import os
import subprocess
import sys
sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
import _setup as S  # noqa: E402
import bpy  # noqa: E402
import numpy as np  # noqa: E402
from mathutils import Euler  # noqa: E402

R = S.Results("test_cross_blender")
CROSS = os.path.join(S.OUTPUT, "cross")
os.makedirs(CROSS, exist_ok=True)
LABEL = os.environ.get("DEFORMKIT_BLENDER_LABEL") or (
    "%s-%s" % ("bpy" if S.AS_MODULE else "blender", bpy.app.version_string.split()[0]))
REL_TOL = 1e-6   # of the mesh diagonal (the bound), on float32 positions
FRAMES = {"pos": (1, 1.0), "half": (11, 0.5)}   # record prefix: (frame, keyed Factor)


def grid_scene(mid, name):
    obj, d, e, fixed, handle = S.grid_setup(mid, nx=16, ny=8)
    obj.name = name
    e.name = name + " handle"
    return obj, d, [(e, (1.1, 0.2, 0.35), (0.3, -0.1, 0.5))]


def arm_scene(mid, name):
    path = os.path.join(S.ROOT, "..", "shared", "scenarios", "arm-lift.json")
    with open(path) as f:
        sc = json.load(f)
    verts, sizes, idx = S.dk.load_mesh_file(os.path.join(os.path.dirname(path), sc["mesh"]))
    verts, sizes, idx = np.asarray(verts), np.asarray(sizes), np.asarray(idx)
    starts = np.r_[0, np.cumsum(sizes)[:-1]]
    faces = [idx[s:s + n].tolist() for s, n in zip(starts, sizes)]
    me = bpy.data.meshes.new(name)
    me.from_pydata(verts.tolist(), [], faces)
    me.update()
    obj = bpy.data.objects.new(name, me)
    bpy.context.scene.collection.objects.link(obj)
    bpy.context.view_layer.objects.active = obj
    S.group(obj, "fixed", sc["fixed"])
    h = sc["handles"][0]
    S.group(obj, "hand", h["vertices"])
    centre = verts[h["vertices"]].mean(axis=0)
    e = S.empty(name + " handle", tuple(centre))
    bpy.ops.deformkit.add_deformer(method=mid)
    d = obj.deformkit.deformers[0]
    d.fixed_group = "fixed"
    bpy.ops.deformkit.add_handle(vertex_group="hand", target=e.name)
    return obj, d, [(e, tuple(centre + h["translate"]), (0.0, 0.4, 0.2))]


def build_scenes():
    S.reset_scene()
    scenes = [(grid_scene, m, "Grid " + m) for m in ("ARAP", "LAPLACIAN", "FALLOFF")]
    if os.path.isdir(os.path.join(S.ROOT, "..", "shared", "meshes")):
        scenes += [(arm_scene, m, "Arm " + m) for m in ("ARAP", "LAPLACIAN")]
    else:
        print("note: no ../shared beside the repository: grid scenes only")
    out = {}
    for make, mid, name in scenes:
        for o in bpy.context.view_layer.objects:
            o.select_set(False)
        obj, d, moves = make(mid, name)
        bpy.context.view_layer.objects.active = obj
        bpy.ops.deformkit.bind()
        R.check("%s: bound" % name, d.bound and not d.status_is_error, d.status)
        for e, loc, rot in moves:
            e.location = loc
            e.rotation_euler = Euler(rot)
        bpy.context.view_layer.update()
        # a cold solve, as frames and renders do: the result depends only on these inputs
        S.solver.solve(obj, d, bpy.context.evaluated_depsgraph_get(), cold=True, force=True)
        mod = S.geonodes.find_modifier(obj, d)
        owner, prop = S.geonodes.factor_prop(mod)
        for frame, value in FRAMES.values():
            S.geonodes.set_factor(mod, value)
            owner.keyframe_insert(prop, frame=frame)
    out = {}
    for prefix, (frame, value) in FRAMES.items():
        bpy.context.scene.frame_set(frame)
        for o in bpy.context.view_layer.objects:
            if o.type == "MESH" and len(o.deformkit.deformers):
                out["%s:%s" % (prefix, o.name)] = S.evaluated_positions(o)
    for o in bpy.context.view_layer.objects:
        if o.type == "MESH" and len(o.deformkit.deformers):
            rest, full = S.rest_positions(o), out["pos:" + o.name]
            R.check("%s: deformed" % o.name, np.abs(full - rest).max() > 0.05)
            half = out["half:" + o.name]
            R.check("%s: the keyed Factor animates (0.5 on frame 11 halves the offset)"
                    % o.name, np.abs(half - (rest + 0.5 * (full - rest))).max() < 1e-5,
                    np.abs(half - (rest + 0.5 * (full - rest))).max())
    return out


def test_record():
    rec = build_scenes()
    names = sorted(k[len("pos:"):] for k in rec if k.startswith("pos:"))
    diag = [float(np.linalg.norm(rec["pos:" + k].max(axis=0) - rec["pos:" + k].min(axis=0)))
            for k in names]
    bpy.context.scene.frame_set(1)
    blend = os.path.join(CROSS, LABEL + ".blend")
    bpy.ops.wm.save_as_mainfile(filepath=blend)
    np.savez(os.path.join(CROSS, LABEL + ".npz"), names=np.array(names),
             version=np.array(bpy.app.version), diag=np.array(diag),
             **{k: v.astype(np.float32) for k, v in rec.items()})
    R.check("recorded %d scenes in %s" % (len(names), LABEL), len(names) >= 3)


EVAL_NO_ADDON = """
import bpy, numpy as np, sys
assert not hasattr(bpy.types.Object, "deformkit"), "the add-on is loaded"
assert "deformkit" not in sys.modules, "the native module is loaded"
out = {}
for prefix, frame in %r:
    bpy.context.scene.frame_set(frame)
    dg = bpy.context.evaluated_depsgraph_get()
    for o in bpy.data.objects:
        if o.type == "MESH":
            me = o.evaluated_get(dg).to_mesh()
            co = np.empty(len(me.vertices) * 3, np.float32)
            me.vertices.foreach_get("co", co)
            out[prefix + ":" + o.name] = co.reshape(-1, 3)
np.savez(%r, **out)
"""


def test_reload_older_files():
    """Every file an older Blender saved here opens in this one, without the add-on, showing
    the mesh that Blender showed."""
    mine = tuple(bpy.app.version)
    report = {}
    env = {k: v for k, v in os.environ.items() if k != "PYTHONPATH"}
    for f in sorted(os.listdir(CROSS)):
        other = f[:-len(".npz")] if f.endswith(".npz") else None
        if other is None or other == LABEL:
            continue
        rec = np.load(os.path.join(CROSS, f))
        if tuple(int(x) for x in rec["version"]) >= mine:
            continue
        os.makedirs(os.path.join(CROSS, "reloaded"), exist_ok=True)
        out = os.path.join(CROSS, "reloaded", "%s-in-%s.npz" % (other, LABEL))
        if os.path.exists(out):
            os.remove(out)
        cmd = S.blender_command(blend=os.path.join(CROSS, other + ".blend"),
                                expr=EVAL_NO_ADDON % (
                                    [(p, f) for p, (f, _) in FRAMES.items()], out))
        r = subprocess.run(cmd, env=env, capture_output=True, text=True, timeout=300)
        if not R.check("%s's file opens in %s without the add-on" % (other, LABEL),
                       r.returncode == 0 and os.path.exists(out),
                       (r.stdout[-800:] + r.stderr[-800:])):
            continue
        got = np.load(out)
        worst = 0.0
        for name, d in zip(rec["names"], rec["diag"]):
            for prefix in FRAMES:
                key = "%s:%s" % (prefix, name)
                if key not in got.files or key not in rec.files:
                    R.check("%s: %s present in the reloaded file" % (other, key), False)
                    continue
                worst = max(worst, float(np.abs(got[key] - rec[key]).max() / d))
        report[other] = worst
        R.check("%s's file in %s without the add-on: same evaluated meshes on frames %s, the "
                "keyed Factor animating (max %.1e of the diagonal)"
                % (other, LABEL, sorted(f for f, _ in FRAMES.values()), worst),
                worst <= REL_TOL, worst)
    with open(os.path.join(CROSS, LABEL + ".reloads.json"), "w") as f:
        json.dump({"blender": list(mine), "reloaded": report}, f, indent=1)
    if not report:
        print("note: no file of an older Blender in %s yet" % CROSS)


for t in (test_record, test_reload_older_files):
    R.run(t)
R.finish()
