"""Animation: keyframed handle targets re-solve per frame (compared with direct solves); bake to
PC2 (operator and headless batch), chunked bakes joined equal one bake, the Mesh Cache modifier
plays the cache back; bake to shape keys; batch failures exit non-zero; Embedded Deformation
on a mesh animated by an Armature modifier above it (section 5 of Sumner et al.)."""
import concurrent.futures
import os
import shutil
import subprocess
import sys
sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
import _setup as S  # noqa: E402
import bpy  # noqa: E402
import numpy as np  # noqa: E402
from mathutils import Euler, Vector  # noqa: E402
from addon import pc2  # noqa: E402

R = S.Results("test_addon_animation")
TOL = 2e-5
MID = next((m.id for m in S.methods.METHODS if S.native.has_class(m.native_class)), "ARAP")
BLEND = os.path.join(S.OUTPUT, "anim.blend")
BATCH = os.path.join(S.ROOT, "scripts", "batch_bake.py")
FRAMES = (1, 4, 10, 13, 20)


def build(method=MID):
    S.reset_scene()
    obj, d, e, fixed, handle = S.grid_setup(method)
    sc = bpy.context.scene
    sc.frame_start, sc.frame_end = 1, 20
    sc.frame_set(1)
    bpy.ops.deformkit.bind()
    for f, loc, rot in ((1, (1, 0, 0), (0, 0, 0)), (10, (1.0, 0.2, 0.5), (0.4, 0, 0)),
                        (20, (0.9, -0.1, 0.2), (0, 0.3, 0.6))):
        e.location, e.rotation_euler = loc, Euler(rot)
        e.keyframe_insert("location", frame=f)
        e.keyframe_insert("rotation_euler", frame=f)
    mod = S.geonodes.find_modifier(obj, d)
    owner, key = S.geonodes.factor_prop(mod)
    S.geonodes.set_factor(mod, 1.0)
    owner.keyframe_insert(key, frame=1)
    S.geonodes.set_factor(mod, 0.5)
    owner.keyframe_insert(key, frame=20)
    sc.frame_set(1)
    return obj, d, e, fixed, handle


def direct_bind(obj, d, fixed, handle):
    """(the registry's method, the native object bound as the add-on binds d)."""
    m = S.methods.get(d.method)
    rest = S.rest_positions(obj)
    mesh = S.dk.Mesh(rest, S.solver.triangles(obj.data))
    kw = dict(handles=[handle], fixed=fixed)
    return m, getattr(S.dk, m.native_class)(mesh, **kw, **S.methods.bind_kwargs(
        m, d.options, rest, kw, mesh))


def direct_cold(obj, d, e, fixed, handle, bind_world):
    m, meth = direct_bind(obj, d, fixed, handle)
    T = np.array(e.matrix_world @ bind_world.inverted())[None]
    return np.asarray(meth.solve(transforms=T, **S.methods.solve_kwargs(m, d.options, True)).positions)


def test_playback():
    obj, d, e, fixed, handle = build()
    bind_world = S.empty  # placeholder to keep names short
    sc = bpy.context.scene
    sc.frame_set(1)
    bind_world = e.matrix_world.copy()  # the target at frame 1 = at bind
    rest = S.rest_positions(obj)
    for f in FRAMES:
        sc.frame_set(f)
        got = S.evaluated_positions(obj)
        fac = S.geonodes.factor(obj, d)
        want = direct_cold(obj, d, e, fixed, handle, bind_world)
        want = rest + fac * (want - rest)
        R.check("frame %d (factor %.2f): playback = direct solve" % (f, fac),
                np.abs(got - want).max() < TOL, np.abs(got - want).max())
    bpy.ops.wm.save_as_mainfile(filepath=BLEND)


def test_render_sees_each_frame():
    """An animation render (its own depsgraph) shows each frame's solve, not the previous one:
    a frame_change_post probe registered after the add-on reads the render depsgraph."""
    bpy.ops.wm.open_mainfile(filepath=BLEND)
    sc = bpy.context.scene
    obj = bpy.data.objects["Grid"]
    want = {}
    for f in (4, 13):
        sc.frame_set(f)
        want[f] = S.evaluated_positions(obj)
    seen = {}
    probe = S.evaluated_frames_probe(seen)
    S.tiny_workbench_render(sc, 16, os.path.join(S.OUTPUT, "render_", "f"))
    sc.frame_set(1)
    bpy.app.handlers.frame_change_post.append(probe)
    try:
        for f in (4, 13):
            sc.frame_start = sc.frame_end = f
            bpy.ops.render.render(animation=True)
    finally:
        bpy.app.handlers.frame_change_post.remove(probe)
    for f in (4, 13):
        ok = f in seen and np.abs(seen[f] - want[f]).max() < TOL
        R.check("render of frame %d sees that frame's solve" % f, ok,
                np.abs(seen[f] - want[f]).max() if f in seen else "not rendered")


def run_batch(*args, blend=BLEND):
    if S.AS_MODULE:   # as a pipeline runs it with the bpy module: the script opens the file
        cmd = [sys.executable, BATCH] + (["--blend", blend] if blend else []) + list(args)
    else:
        cmd = S.blender_command(blend=blend, script=BATCH, args=args)
    r = subprocess.run(cmd, capture_output=True, text=True, timeout=600)
    return r


def run_batches(*calls):
    """run_batch for each (args, blend) of `calls`, three processes at a time (as a farm runs
    its chunks side by side; each one's start-up is most of its time here), results in order."""
    with concurrent.futures.ThreadPoolExecutor(max_workers=3) as pool:
        futures = [pool.submit(run_batch, *args, blend=blend) for args, blend in calls]
        return [f.result() for f in futures]


def direct_simulation(obj, d, fixed, handle):
    """A simulation through the API (a dynamic method): sim(T, frame) gives the frame's
    positions for the handle transform T, frame 1 a reset and each later one a step."""
    m, meth = direct_bind(obj, d, fixed, handle)
    skw = S.methods.solve_kwargs(m, d.options, True)
    skw.update(m.solve_args(obj, d.options, bpy.context.scene))

    def sim(T, frame):
        return np.asarray(meth.solve(transforms=T, warm_start=frame > 1, **skw).positions)
    return sim


def test_chunked_bake_equals_single():
    out = {k: os.path.join(S.OUTPUT, "anim_%s.pc2" % k) for k in ("all", "a", "b", "joined")}
    for p in out.values():
        if os.path.exists(p):
            os.remove(p)
    r, r1, r2 = run_batches(*[(("--object", "Grid", "--frames", fr, "--out", out[k]), BLEND)
                              for fr, k in (("1-20", "all"), ("1-8", "a"), ("9-20", "b"))])
    R.check("single batch bake exits 0", r.returncode == 0, r.stderr[-1500:])
    R.check("progress lines on stderr", "frame 20 (20/20, 100%)" in r.stderr, r.stderr[-500:])
    R.check("chunk bakes exit 0", r1.returncode == 0 and r2.returncode == 0, r1.stderr[-800:] + r2.stderr[-800:])
    R.check("a successful batch bake prints no traceback and no add-on load failure",
            not any(w in x.stdout + x.stderr for x in (r, r1, r2)
                    for w in ("Traceback", "Add-on not loaded")),
            (r.stdout + r.stderr)[-1200:])
    r3 = run_batch("--join", out["b"], out["a"], "--out", out["joined"], blend=None)
    R.check("join exits 0", r3.returncode == 0, r3.stderr[-800:])
    h1, f1 = pc2.read(out["all"])
    h2, f2 = pc2.read(out["joined"])
    R.check("joined header = single header", h1 == h2, (h1, h2))
    diff = max(float(np.abs(np.array(a) - np.array(b)).max()) for a, b in zip(f1, f2))
    R.check("chunked bake equals single bake (max diff %g)" % diff, len(f1) == len(f2) == 20 and diff == 0.0)
    # the cache holds what playback shows
    bpy.ops.wm.open_mainfile(filepath=BLEND)
    obj = bpy.data.objects["Grid"]
    for f in (4, 13, 20):
        bpy.context.scene.frame_set(f)
        got = S.evaluated_positions(obj)
        cache = np.array(f1[f - 1]).reshape(-1, 3)
        R.check("cache frame %d = playback" % f, np.abs(got - cache).max() < TOL, np.abs(got - cache).max())
    # a gap is refused
    r4 = run_batch("--join", out["all"], out["b"], "--out", out["joined"], blend=None)
    R.check("join refuses overlapping chunks", r4.returncode != 0 and "overlap" in r4.stderr, r4.stderr[-300:])
    # plain python3 can join too (no Blender needed)
    if os.path.exists("/usr/bin/python3"):
        r5 = subprocess.run(["/usr/bin/python3", BATCH, "--join", out["a"], out["b"], "--out", out["joined"]],
                            capture_output=True, text=True)
        R.check("join under plain python3", r5.returncode == 0, r5.stderr[-300:])


def test_batch_failures():
    x = [os.path.join(S.OUTPUT, "x%d.pc2" % i) for i in range(3)]
    bad = run_batches((("--object", "Nope", "--frames", "1-3", "--out", x[0]), BLEND),
                      (("--object", "Tip", "--frames", "1-3", "--out", x[1]), BLEND),
                      (("--object", "Grid", "--frames", "5-1", "--out", x[2]), BLEND))
    r = bad[0]
    R.check("unknown object: non-zero exit + message", r.returncode != 0 and "no object named" in r.stderr, r.stderr[-300:])
    r = bad[1]
    R.check("non-mesh object: non-zero exit", r.returncode != 0 and "not a mesh" in r.stderr, r.stderr[-300:])
    r = bad[2]
    R.check("empty range: non-zero exit", r.returncode != 0, r.stderr[-300:])
    # the output path: "//" as in Blender, and nothing destroyed or made up
    folder = os.path.dirname(BLEND)
    rel = os.path.join(folder, "anim_rel.pc2")
    missing = os.path.join(folder, "anim_no_such_folder")
    for p in (rel,):
        if os.path.exists(p):
            os.remove(p)
    shutil.rmtree(missing, ignore_errors=True)
    body = open(BLEND, "rb").read()
    r_rel, r_blend, r_missing = run_batches(
        (("--object", "Grid", "--frames", "1-2", "--out", "//anim_rel.pc2"), BLEND),
        (("--object", "Grid", "--frames", "1-2", "--out", BLEND), BLEND),
        (("--object", "Grid", "--frames", "1-2", "--out", os.path.join(missing, "x.pc2")),
         BLEND))
    R.check("--out //name.pc2 writes next to the .blend, as the panel does",
            r_rel.returncode == 0 and os.path.isfile(rel), r_rel.stderr[-600:])
    R.check("--out naming the open .blend: exit 1, refused by name, the .blend untouched",
            r_blend.returncode == 1 and "the open .blend file" in r_blend.stderr
            and open(BLEND, "rb").read() == body, r_blend.stderr[-600:])
    R.check("--out in a missing folder: exit 1, said, no folder made",
            r_missing.returncode == 1 and "does not exist" in r_missing.stderr
            and not os.path.exists(missing), r_missing.stderr[-600:])
    r_usage = run_batch("--object", "Grid", "--frames", "1-2")
    R.check("a missing argument: exit 1 (as every failure) with batch_bake: error",
            r_usage.returncode == 1 and "batch_bake: error:" in r_usage.stderr
            and "--out" in r_usage.stderr, (r_usage.returncode, r_usage.stderr[-600:]))
    if os.path.exists(rel):
        r_join = run_batch("--join", rel, "--out", rel, blend=None)
        R.check("join into one of its inputs: exit 1, the input kept",
                r_join.returncode == 1 and "one of the caches being joined" in r_join.stderr
                and pc2.read_header(rel)["samples"] == 2, r_join.stderr[-600:])


def test_mesh_cache_modifier():
    bpy.ops.wm.open_mainfile(filepath=BLEND)
    obj = bpy.data.objects["Grid"]
    bpy.context.view_layer.objects.active = obj
    sc = bpy.context.scene
    want = {}
    for f in (3, 12, 20):
        sc.frame_set(f)
        want[f] = S.evaluated_positions(obj)
    path = os.path.join(S.OUTPUT, "anim_op.pc2")
    bpy.ops.deformkit.bake(mode="PC2", frame_start=2, frame_end=20, filepath=path)
    mc = [m for m in obj.modifiers if m.type == "MESH_CACHE"]
    R.check("operator bake adds a Mesh Cache modifier", len(mc) == 1)
    gn = S.geonodes.find_modifier(obj, obj.deformkit.deformers[0])
    R.check("GN modifier hidden after bake", not gn.show_viewport and not gn.show_render)
    S.handlers.enabled[0] = False  # playback from the cache alone
    for f in (3, 12, 20):
        sc.frame_set(f)
        got = S.evaluated_positions(obj)
        R.check("Mesh Cache plays frame %d" % f, np.abs(got - want[f]).max() < TOL, np.abs(got - want[f]).max())
    S.handlers.enabled[0] = True
    h = pc2.read_header(path)
    R.check("operator cache header", h["samples"] == 19 and h["start"] == 2.0, h)


def test_shape_key_bake():
    bpy.ops.wm.open_mainfile(filepath=BLEND)
    obj = bpy.data.objects["Grid"]
    bpy.context.view_layer.objects.active = obj
    sc = bpy.context.scene
    want = {}
    for f in (5, 6):
        sc.frame_set(f)
        want[f] = S.evaluated_positions(obj)
    bpy.ops.deformkit.bake(mode="SHAPE_KEYS", frame_start=4, frame_end=7)
    kb = obj.data.shape_keys.key_blocks
    R.check("4 frame shape keys + basis", len(kb) == 5, [k.name for k in kb])
    S.handlers.enabled[0] = False
    for f in (5, 6):
        sc.frame_set(f)
        got = S.evaluated_positions(obj)
        R.check("shape keys play frame %d" % f, np.abs(got - want[f]).max() < 1e-4, np.abs(got - want[f]).max())
    S.handlers.enabled[0] = True


def test_every_method_plays_and_bakes_in_chunks():
    """The other registered methods (the suite above uses the first): playback equals the
    direct cold solve, and two chunked batch bakes joined equal one bake, bit for bit. The
    scenes are saved first, then every method's bakes run side by side (run_batches)."""
    outs = {}
    for m in S.handle_methods():
        if m.id == MID or not S.native.has_class(m.native_class):
            continue
        obj, d, e, fixed, handle = build(m.id)
        sc = bpy.context.scene
        sc.frame_set(1)
        bind_world = e.matrix_world.copy()
        rest = S.rest_positions(obj)
        if S.solver.simulation.is_dynamic(m):
            # a simulation: played in order from frame 1, against the API simulating the
            # same handle motion frame by frame
            sim = direct_simulation(obj, d, fixed, handle)
            for f in range(1, 14):
                sc.frame_set(f)
                T = np.array(e.matrix_world @ bind_world.inverted())[None]
                x = sim(T, f)
                if f in (4, 13):
                    got = S.evaluated_positions(obj)
                    want = rest + S.geonodes.factor(obj, d) * (x - rest)
                    R.check("%s frame %d: playback = the simulation" % (m.id, f),
                            np.abs(got - want).max() < TOL, np.abs(got - want).max())
        for f in (4, 13) if not S.solver.simulation.is_dynamic(m) else ():
            sc.frame_set(f)
            got = S.evaluated_positions(obj)
            fac = S.geonodes.factor(obj, d)
            want = rest + fac * (direct_cold(obj, d, e, fixed, handle, bind_world) - rest)
            R.check("%s frame %d: playback = direct solve" % (m.id, f),
                    np.abs(got - want).max() < TOL, np.abs(got - want).max())
        blend = os.path.join(S.OUTPUT, "anim_%s.blend" % m.id.lower())
        bpy.ops.wm.save_as_mainfile(filepath=blend)
        out = {k: os.path.join(S.OUTPUT, "anim_%s_%s.pc2" % (m.id.lower(), k))
               for k in ("all", "a", "b", "joined")}
        for p in out.values():
            if os.path.exists(p):
                os.remove(p)
        outs[m.id] = (blend, out)
    chunks = (("1-20", "all"), ("1-8", "a"), ("9-20", "b"))
    bakes = run_batches(*[(("--object", "Grid", "--frames", fr, "--out", out[k]), blend)
                          for blend, out in outs.values() for fr, k in chunks])
    joins = run_batches(*[(("--join", out["a"], out["b"], "--out", out["joined"]), None)
                          for blend, out in outs.values()])
    for i, (mid, (blend, out)) in enumerate(outs.items()):
        rs = bakes[3 * i:3 * i + 3] + [joins[i]]
        R.check("%s batch bakes and join exit 0" % mid, all(r.returncode == 0 for r in rs),
                " | ".join(r.stderr[-400:] for r in rs if r.returncode))
        if all(r.returncode == 0 for r in rs):
            _, f1 = pc2.read(out["all"])
            _, f2 = pc2.read(out["joined"])
            diff = max(float(np.abs(np.array(a) - np.array(b)).max()) for a, b in zip(f1, f2))
            R.check("%s chunked bake equals single bake" % mid,
                    len(f1) == len(f2) == 20 and diff == 0.0, diff)


def test_embedded_follows_an_armature():
    """Section 5: the graph rides along the armature's output, and the artist's edit (the
    handle's displacement at the bind pose) is kept on every frame. Each frame's playback
    equals the direct API on that frame's evaluated input: update_source(input), then a cold
    solve with targets input[handle] + edit. For both node sources (surface samples keep
    their places in their triangles; vertex nodes ride with their vertices)."""
    for nodes in ("surface", "vertices"):
        obj, d, e, fixed, handle, bind_world = S.rigged_arm(nodes)
        m = S.methods.get("EMBEDDED")
        rest = S.rest_positions(obj)
        mesh = S.dk.Mesh(rest, S.solver.triangles(obj.data))
        kw = dict(handles=[handle], fixed=fixed)
        native = S.dk.EmbeddedDeformation(mesh, **kw, **S.methods.bind_kwargs(m, d.options,
                                                                             rest, kw, mesh))
        T = np.array(e.matrix_world @ bind_world.inverted())
        edit = rest[handle] @ T[:3, :3].T + T[:3, 3] - rest[handle]
        sc = bpy.context.scene
        for f in (1, 7, 10, 16, 20):
            sc.frame_set(f)
            got = S.evaluated_positions(obj)
            inp = S.armature_input(obj, d)
            native.update_source(inp)
            # the edit follows the pose (the tip rides the lower bone alone: its fit is the
            # bone's turn)
            turned = edit @ S.bone_turn(obj, "lower").T
            want = np.asarray(native.solve(inp[handle] + turned,
                                           **S.methods.solve_kwargs(m, d.options, True)).positions)
            R.check("%s nodes, frame %d: playback = direct API on the armature's output"
                    % (nodes, f), np.abs(got - want).max() < TOL, np.abs(got - want).max())
            R.check("%s nodes, frame %d: fixed vertices stay where the armature puts them"
                    % (nodes, f), np.abs(got[fixed] - inp[fixed]).max() < TOL,
                    np.abs(got[fixed] - inp[fixed]).max())
            kept = np.linalg.norm((got[handle] - inp[handle]).mean(0) - turned.mean(0))
            R.check("%s nodes, frame %d: the edit is kept (tip off by %.2g%% of the drag)"
                    % (nodes, f, 100 * kept / np.linalg.norm(edit.mean(0))),
                    kept < 0.03 * np.linalg.norm(edit.mean(0)))
            if f == 16:
                R.check("frame 16: the armature moves the arm (the test means something)",
                        np.abs(inp - rest).max() > 0.3, np.abs(inp - rest).max())
    # writing the result into the mesh would let the armature move it again: refused
    for op, kw in ((bpy.ops.deformkit.apply, dict(mode="SHAPE_KEY")),
                   (bpy.ops.deformkit.bake, dict(mode="SHAPE_KEYS", frame_start=1, frame_end=2))):
        try:
            op(**kw)
            msg = ""
        except RuntimeError as ex:
            msg = str(ex)
        R.check("%s refused with a reason" % op.idname_py(),
                "by 'Armature' above it" in msg and "Point Cache" in msg, msg)
    R.check("nothing written into the mesh", obj.data.shape_keys is None)
    # a Point Cache bake holds what playback shows
    want = {}
    for f in (5, 12, 20):
        sc.frame_set(f)
        want[f] = S.evaluated_positions(obj)
    path = os.path.join(S.OUTPUT, "anim_armature.pc2")
    bpy.ops.deformkit.bake(mode="PC2", frame_start=1, frame_end=20, filepath=path)
    S.handlers.enabled[0] = False
    try:
        for f in (5, 12, 20):
            sc.frame_set(f)
            got = S.evaluated_positions(obj)
            R.check("Point Cache of the armature-driven edit plays frame %d" % f,
                    np.abs(got - want[f]).max() < TOL, np.abs(got - want[f]).max())
    finally:
        S.handlers.enabled[0] = True


def test_bakes_keep_the_rig():
    """Issue 39: a deformer after an Armature, every method. The point cache holds what
    playback shows on every frame: the armature's pose with the deformer's edit on it. It
    held the rest shape plus the edit, and the Mesh Cache (Overwrite) after the Armature
    threw the pose away (a straight arm at the bent frames). Shape keys, which the Armature
    would move again, are refused with a message naming the Point Cache."""
    for m in S.handle_methods():
        if not S.native.has_class(m.native_class):
            continue
        obj, d, e, fixed, handle, bind_world = S.rigged_arm("surface", m.id)
        sc = bpy.context.scene
        want = {}
        # a simulation shows a frame after the frames before it: played in order
        dynamic = S.solver.simulation.is_dynamic(m)
        for f in range(1, 21) if dynamic else (1, 8, 16, 20):
            sc.frame_set(f)
            if f in (1, 8, 16, 20):
                want[f] = S.evaluated_positions(obj)
        inp = S.armature_input(obj, d)
        R.check("%s: the armature bends the arm at frame 20 (the test means something)"
                % m.id, np.abs(inp - S.rest_positions(obj)).max() > 0.3)
        sc.frame_set(20)
        R.check("%s: the edit shows on the pose at frame 20" % m.id,
                np.abs(want[20][handle] - inp[handle]).max() > 0.05)
        try:
            bpy.ops.deformkit.bake(mode="SHAPE_KEYS", frame_start=1, frame_end=2)
            msg = ""
        except RuntimeError as ex:
            msg = str(ex)
        R.check("%s: bake to shape keys under the Armature refused, naming what to use"
                % m.id, "'Armature' above it" in msg and "Point Cache" in msg, msg)
        R.check("%s: nothing written into the mesh" % m.id, obj.data.shape_keys is None)
        path = os.path.join(S.OUTPUT, "anim_rig_%s.pc2" % m.id.lower())
        bpy.ops.deformkit.bake(mode="PC2", frame_start=1, frame_end=20, filepath=path)
        S.handlers.enabled[0] = False
        try:
            for f in want:
                sc.frame_set(f)
                got = S.evaluated_positions(obj)
                R.check("%s: the point cache plays frame %d as playback showed it" % (m.id, f),
                        np.abs(got - want[f]).max() < TOL, np.abs(got - want[f]).max())
        finally:
            S.handlers.enabled[0] = True
        if m.id == "ARAP":  # baked again (Re-bake): its hidden modifier still reads the pose
            first = pc2.read(path)[1]
            try:
                bpy.ops.deformkit.rebake()
                msg = ""
            except RuntimeError as ex:
                msg = str(ex)
            again = pc2.read(path)[1]
            R.check("%s: Re-bake on the rig writes the same cache" % m.id, not msg and
                    len(again) == len(first) and all(np.array_equal(np.asarray(a),
                                                                    np.asarray(b))
                                                     for a, b in zip(first, again)), msg)


def test_a_handle_on_the_rig_moves_its_vertices_once():
    """Issue 39: a handle whose target is the bone that bends the arm, or an empty parented
    to that bone, every method. The rig already moved its vertices in the deformer's input:
    the handle adds only the artist's deviation from the bone. It added the bone's motion
    again (the forearm swung twice as far). With the target on the bone the result is the
    armature's pose; with the empty moved along the bone, the tip moves by that much more."""
    for m in S.handle_methods():
        if not S.native.has_class(m.native_class):
            continue
        obj, d, e, fixed, handle, bind_world = S.rigged_arm("surface", m.id)
        rig = bpy.data.objects["Rig"]
        sc = bpy.context.scene
        sc.frame_set(1)
        h = d.handles[0]
        h.target, h.subtarget = rig, "lower"
        bpy.ops.deformkit.bind()
        for f in (10, 20):
            sc.frame_set(f)
            got, inp = S.evaluated_positions(obj), S.armature_input(obj, d)
            R.check("%s frame %d: the handle on the bone shows the rig's pose" % (m.id, f),
                    np.abs(got - inp).max() < TOL, np.abs(got - inp).max())
        if m.fit_check == "handles":
            continue  # the deviation below is met exactly by the hard-handle methods only
        sc.frame_set(1)
        h.target, h.subtarget = e, ""
        e.parent, e.parent_type, e.parent_bone = rig, "BONE", "lower"
        e.matrix_world = bind_world  # the bind-time placement, now under the bone
        bpy.context.view_layer.update()
        bpy.ops.deformkit.bind()
        for f in (10, 20):
            sc.frame_set(f)
            before = np.array(e.matrix_world.translation)
            e.location = e.location + Vector((0, 0.1, 0))
            bpy.context.view_layer.update()
            dev = np.array(e.matrix_world.translation) - before
            got, inp = S.evaluated_positions(obj), S.armature_input(obj, d)
            off = np.abs(got[handle] - inp[handle] - dev).max()
            R.check("%s frame %d: an empty on the bone adds its own move once" % (m.id, f),
                    off < TOL and np.linalg.norm(dev) > 0.05, (off, dev))
            e.location = e.location - Vector((0, 0.1, 0))
            bpy.context.view_layer.update()
            # turned about itself: the vertices turn about the empty, from where the rig
            # puts them (the deviation applied in the bone's frame, not about the origin)
            Ew = np.array(e.matrix_world)
            was = e.rotation_euler.copy()
            e.rotation_euler.z += 0.3
            bpy.context.view_layer.update()
            P = np.array(e.matrix_world) @ np.linalg.inv(Ew)
            got, inp = S.evaluated_positions(obj), S.armature_input(obj, d)
            want = inp[handle] @ P[:3, :3].T + P[:3, 3]
            off = np.abs(got[handle] - want).max()
            R.check("%s frame %d: an empty on the bone turned about itself turns its vertices"
                    " there" % (m.id, f), off < TOL, off)
            e.rotation_euler = was
            bpy.context.view_layer.update()


def test_rebind_takes_the_rest_frame():
    """Issue 39: Rebind on frame 20 of a shot whose handle is keyed (rest on frame 1, lifted
    on 20) took frame 20's placement as the rest: the lift vanished there and showed
    inverted on frame 1. It takes the scene's start by default and says so; Current Frame
    keeps the old behaviour for those who want it, and Frame a chosen one."""
    obj, d, e, fixed, handle = build("LAPLACIAN")
    sc = bpy.context.scene
    rest = S.rest_positions(obj)
    sc.frame_set(20)
    lifted = S.evaluated_positions(obj)
    R.check("the keyed lift shows on frame 20", np.abs(lifted - rest).max() > 0.1)
    bpy.ops.deformkit.bind()
    R.check("after Rebind on frame 20 the frame is still 20", sc.frame_current == 20)
    R.check("Rebind keeps the keyed lift on frame 20",
            np.abs(S.evaluated_positions(obj) - lifted).max() < TOL,
            np.abs(S.evaluated_positions(obj) - lifted).max())
    sc.frame_set(1)
    R.check("... and the rest on frame 1", np.abs(S.evaluated_positions(obj) - rest).max() < TOL,
            np.abs(S.evaluated_positions(obj) - rest).max())
    d.rest_frame_from = "FRAME"
    d.rest_frame = 20
    bpy.ops.deformkit.bind()
    R.check("Rest Frame 20: frame 20 is the rest", np.abs(S.evaluated_positions(obj) -
                                                           rest).max() > 0.1)
    sc.frame_set(20)
    R.check("... there", np.abs(S.evaluated_positions(obj) - rest).max() < TOL,
            np.abs(S.evaluated_positions(obj) - rest).max())
    d.rest_frame_from = "CURRENT"
    sc.frame_set(10)
    bpy.ops.deformkit.bind()
    R.check("Current Frame: the shown frame is the rest",
            np.abs(S.evaluated_positions(obj) - rest).max() < TOL)


def test_an_edit_turns_with_the_pose():
    """Issue 39: the tip lifted at the bind pose (frame 1), the forearm then bent by the
    rig. By default the edit follows the pose: the tip's offset from the posed input, seen
    from the forearm (its bone's turn undone), is the same on every frame, with every
    method (to float32 rounding where handles are exact, 3% of the edit where they are
    met approximately). It was pasted in the rest's directions, so a correction keyed
    outward on a straight arm pointed elsewhere on the bent one. With Stays in Place the
    tip keeps the place the edit gave it, wherever the rig takes the forearm."""
    for m in S.handle_methods():
        if not S.native.has_class(m.native_class):
            continue
        obj, d, e, fixed, handle, bind_world = S.rigged_arm("surface", m.id)
        sc = bpy.context.scene
        exact = m.fit_check != "handles"
        tol = lambda edit: TOL if exact else 0.03 * np.linalg.norm(edit.mean(0))  # noqa: E731
        sc.frame_set(1)
        edit = S.evaluated_positions(obj)[handle] - S.armature_input(obj, d)[handle]
        R.check("%s: the edit shows at the bind frame" % m.id,
                np.linalg.norm(edit.mean(0)) > 0.2, edit.mean(0))
        for f in (10, 20):
            sc.frame_set(f)
            got, inp = S.evaluated_positions(obj), S.armature_input(obj, d)
            seen = (got[handle] - inp[handle]) @ S.bone_turn(obj, "lower")
            off = np.abs(seen - edit).max() if exact else np.linalg.norm((seen - edit).mean(0))
            R.check("%s frame %d: the edit, seen from the forearm, is the bind frame's"
                    % (m.id, f), off < tol(edit), off)
        if not exact:
            continue
        d.handles[0].follow = "WORLD"
        sc.frame_set(1)
        placed = S.evaluated_positions(obj)[handle]
        for f in (10, 20):
            sc.frame_set(f)
            got, inp = S.evaluated_positions(obj), S.armature_input(obj, d)
            R.check("%s frame %d: Stays in Place keeps the tip where the edit put it"
                    % (m.id, f), np.abs(got[handle] - placed).max() < TOL
                    and np.abs(inp[handle] - placed).max() > 0.3,
                    np.abs(got[handle] - placed).max())


def test_a_method_that_edits_its_input_solves_on_the_pose():
    """Issue 39: a method that edits its input (the native edits_input: ARAP, Falloff)
    solves on the pose the Armature gives it, each frame: playback equals the direct API
    given that pose as input_positions and the handle where the edit, turned with the
    forearm, puts it. Its offset was solved on the rest and pasted on the pose, so the
    surface sheared instead of turning with the bone; the forearm's vertices near the tip
    now keep their offset from the pose, seen from the bone, within 10% of the edit (they
    were pasted in the rest's directions)."""
    done = 0
    for m in S.handle_methods():
        if not (S.native.has_class(m.native_class) and
                S.native.method_info(m.native_class).get("edits_input")) or \
                S.solver.simulation.is_dynamic(m):   # test_addon_simulation.py plays those
            continue
        done += 1
        obj, d, e, fixed, handle, bind_world = S.rigged_arm("surface", m.id)
        rest = S.rest_positions(obj)
        mesh = S.dk.Mesh(rest, S.solver.triangles(obj.data))
        kw = dict(handles=[handle], fixed=fixed)
        native = getattr(S.dk, m.native_class)(mesh, **kw, **S.methods.bind_kwargs(
            m, d.options, rest, kw, mesh))
        T = np.array(e.matrix_world @ bind_world.inverted())
        edit = rest[handle] @ T[:3, :3].T + T[:3, 3] - rest[handle]
        sc = bpy.context.scene
        sc.frame_set(1)
        near = np.where(rest[:, 0] > 0.6)[0]   # the forearm by the tip, its weight all 'lower'
        at_bind = S.evaluated_positions(obj)[near] - S.armature_input(obj, d)[near]
        for f in (10, 20):
            sc.frame_set(f)
            got, inp = S.evaluated_positions(obj), S.armature_input(obj, d)
            B = S.bone_turn(obj, "lower")
            want = np.asarray(native.solve(inp[handle] + edit @ B.T, input_positions=inp,
                                           **S.methods.solve_kwargs(m, d.options, True)).positions)
            R.check("%s frame %d: playback = the direct API on the pose" % (m.id, f),
                    np.abs(got - want).max() < TOL, np.abs(got - want).max())
            seen = (got[near] - inp[near]) @ B
            off = np.abs(seen - at_bind).max() / np.abs(edit).max()
            R.check("%s frame %d: the forearm's offset turns with it (%.2g of the edit)"
                    % (m.id, f, off), off < 0.1, off)
    R.check("some method edits its input", done > 0, done)


def test_a_corrective_shape_key_plays_without_deformkit():
    """Issue 39, item 7: the deformer's edit on the bent pose of frame 20, baked as a shape
    key under the Armature, driven by the forearm's rotation. With DeformKit's modifier off
    (and the add-on's handlers), frame 20 shows what playback showed with it; frame 1, at
    the rig's rest, the rig alone (the key at 0); frame 16 something in between."""
    obj, d, e, fixed, handle, bind_world = S.rigged_arm("surface", MID)
    sc = bpy.context.scene
    sc.frame_set(20)
    want = S.evaluated_positions(obj)
    bpy.ops.deformkit.bake_corrective()
    keys = obj.data.shape_keys
    R.check("one corrective key besides the basis", keys is not None and
            len(keys.key_blocks) == 2, keys and [k.name for k in keys.key_blocks])
    key = keys.key_blocks[-1]
    fc = keys.animation_data.drivers.find('key_blocks["%s"].value' % key.name)
    R.check("driven by the forearm's rotation", fc is not None and
            fc.driver.variables[0].targets[0].bone_target == "lower",
            fc and fc.driver.variables[0].targets[0].bone_target)
    mod = S.geonodes.find_modifier(obj, d)
    mod.show_viewport = False
    S.handlers.enabled[0] = False
    try:
        sc.frame_set(1)
        sc.frame_set(20)
        got = S.evaluated_positions(obj)
        R.check("frame 20 without DeformKit shows the edit (%.1e)" % np.abs(got - want).max(),
                np.abs(got - want).max() < 1e-4 and abs(key.value - 1.0) < 1e-6,
                (np.abs(got - want).max(), key.value))
        sc.frame_set(1)   # the rig at its rest: the mesh's rest
        R.check("frame 1: the key at 0, the rig alone", abs(key.value) < 1e-6 and
                np.abs(S.evaluated_positions(obj) - S.rest_positions(obj)).max() < 1e-5,
                key.value)
        sc.frame_set(16)
        R.check("frame 16: the key in between", 0.05 < key.value < 0.95, key.value)
    finally:
        mod.show_viewport = True
        S.handlers.enabled[0] = True


def test_solve_from_the_rest_shape_between_the_bones():
    """Solve From: Rest Shape: the arm's two ends are handles riding the rig's two bones; the
    method places them where the rig does and solves what lies between from the rest shape,
    in place of the rig's blend: the ends sit exactly on the rig's pose (no edit was made),
    the elbow is ARAP's, whose edges keep their lengths better than the blend's."""
    obj, d, e, fixed, handle, bind_world = S.rigged_arm("surface", "ARAP")
    rig = bpy.data.objects["Rig"]
    sc = bpy.context.scene
    sc.frame_set(1)
    d.fixed_group = ""
    d.handles[0].target, d.handles[0].subtarget = rig, "lower"
    bpy.ops.deformkit.add_handle(vertex_group="fixed", target=rig.name, subtarget="upper")
    d.solve_from = "REST"
    bpy.ops.deformkit.bind()
    sc.frame_set(20)
    got, inp = S.evaluated_positions(obj), S.armature_input(obj, d)
    ends = np.concatenate([handle, fixed])
    R.check("the ends where the rig puts them", np.abs(got[ends] - inp[ends]).max() < TOL,
            np.abs(got[ends] - inp[ends]).max())
    rest = S.rest_positions(obj)
    E = np.array([(j * 24 + i, j * 24 + i + 1) for j in range(6) for i in range(23)])
    change = lambda x: np.abs(np.linalg.norm(x[E[:, 0]] - x[E[:, 1]], axis=1) /  # noqa: E731
                              np.linalg.norm(rest[E[:, 0]] - rest[E[:, 1]], axis=1) - 1).max()
    R.check("the elbow is solved, not the blend (edge change %.3f against %.3f)"
            % (change(got), change(inp)), change(got) < 0.8 * change(inp)
            and np.abs(got - inp).max() > 1e-3)


def test_a_handle_from_selection_sits_where_the_selection_is_shown():
    """Issue 39: Add Handle from Selection on a posed mesh put the empty at the selection's
    rest place, far from the bent arm the artist was looking at."""
    obj, d, e, fixed, handle, bind_world = S.rigged_arm("surface", MID)
    bpy.context.scene.frame_set(20)
    shown = S.evaluated_positions(obj)
    bpy.context.view_layer.objects.active = obj
    bpy.ops.object.mode_set(mode="EDIT")
    bpy.ops.mesh.select_all(action="DESELECT")
    bpy.ops.object.mode_set(mode="OBJECT")
    for i in fixed[:4]:
        obj.data.vertices[int(i)].select = True
    bpy.ops.object.mode_set(mode="EDIT")
    bpy.ops.deformkit.add_handle_from_selection()
    bpy.ops.object.mode_set(mode="OBJECT")
    new = d.handles[-1].target
    want = np.array(obj.matrix_world) @ np.append(shown[fixed[:4]].mean(0), 1.0)
    R.check("the empty is at the selection's shown centre",
            np.abs(np.array(new.matrix_world.translation) - want[:3]).max() < 1e-5,
            (tuple(new.matrix_world.translation), want))
    sel = [j * 24 + 23 for j in range(6)]
    shown = S.evaluated_positions(obj)  # the new handle changed the deformer's result
    bpy.ops.object.mode_set(mode="EDIT")
    bpy.ops.mesh.select_all(action="DESELECT")
    bpy.ops.object.mode_set(mode="OBJECT")
    for i in sel:
        obj.data.vertices[i].select = True
    bpy.ops.object.mode_set(mode="EDIT")
    bpy.ops.deformkit.add_handle_from_selection()
    bpy.ops.object.mode_set(mode="OBJECT")
    new = d.handles[-1].target
    rest = S.rest_positions(obj)
    R.check("on the bent tip, not at its rest place",
            np.abs(np.array(new.matrix_world.translation) - shown[sel].mean(0)).max() < 1e-5
            and np.linalg.norm(rest[sel].mean(0) - shown[sel].mean(0)) > 0.3,
            (tuple(new.matrix_world.translation), shown[sel].mean(0), rest[sel].mean(0)))


def test_the_panel_says_which_methods_edit_the_pose():
    """Issue 39: a method that solves on the rest pastes its edit on the posed mesh in the
    rest's directions (2-6% of the model from a bind on the pose, measured for Linear
    Reconstruction). Under an Armature the panel says so and names the methods that edit
    the pose (from the native table's edits_input, not from names); not for those methods,
    not with Solve From: Rest Shape, not without a rig."""
    followers = [m for m in S.handle_methods() if S.native.has_class(m.native_class)
                 and S.addon.animated_input.follows(m)]
    listed = [m for m in followers if m.poses is None]  # a blend of poses is not suggested
    for m in S.handle_methods():
        if not S.native.has_class(m.native_class):
            continue
        obj, d, e, fixed, handle, bind_world = S.rigged_arm("surface", m.id)
        note = S.addon.animated_input.pose_note(obj, d)
        if m in followers:
            R.check("%s edits the pose: no note" % m.id, note is None, note)
            continue
        R.check("%s: the note names it and the methods that edit the pose" % m.id,
                note is not None and m.label in note and all(
                    f.label in note for f in listed), note)
        d.solve_from = "REST"
        R.check("%s, Solve From: Rest Shape: no note" % m.id,
                S.addon.animated_input.pose_note(obj, d) is None)
        d.solve_from = "POSE"
        arm = next(mm for mm in obj.modifiers if mm.type == "ARMATURE")
        obj.modifiers.remove(arm)
        R.check("%s without a rig: no note" % m.id,
                S.addon.animated_input.pose_note(obj, d) is None)


for t in (test_playback, test_render_sees_each_frame, test_chunked_bake_equals_single, test_batch_failures, test_mesh_cache_modifier,
          test_shape_key_bake, test_every_method_plays_and_bakes_in_chunks,
          test_embedded_follows_an_armature, test_bakes_keep_the_rig,
          test_a_handle_on_the_rig_moves_its_vertices_once, test_an_edit_turns_with_the_pose,
          test_rebind_takes_the_rest_frame, test_a_method_that_edits_its_input_solves_on_the_pose,
          test_a_corrective_shape_key_plays_without_deformkit,
          test_solve_from_the_rest_shape_between_the_bones,
          test_a_handle_from_selection_sits_where_the_selection_is_shown,
          test_the_panel_says_which_methods_edit_the_pose):
    R.run(t)
R.finish()
