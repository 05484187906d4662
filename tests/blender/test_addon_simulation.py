"""Issue 42: the Jiggle deformer (deformkit.ShapeMatching, a simulation) after an Armature:
playback from the scene's first frame equals the Python API simulating the same input frame
by frame; kept frames show again with no solve; an edit re-simulates from the first frame it
changes; a frame ahead of the simulation shows the input and the panel says where to play
from; a keyed Stiffness reaches each frame; a bake writes what playback showed, a bake of a
later range plays the frames before it, and a batch bake split into chunks with checkpoints
equals one bake, bit for bit."""
import os
import shutil
import subprocess
import sys
sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
import _setup as S  # noqa: E402
import bpy  # noqa: E402
import numpy as np  # noqa: E402
from addon import bake, pc2  # noqa: E402

R = S.Results("test_addon_simulation")
TOL = 2e-5
LAST = 40
BATCH = os.path.join(S.ROOT, "scripts", "batch_bake.py")


def run_batch(*args, blend=None):
    """scripts/batch_bake.py as a pipeline runs it (tests/blender/test_addon_animation.py)."""
    if S.AS_MODULE:
        cmd = [sys.executable, BATCH] + (["--blend", blend] if blend else []) + list(args)
    else:
        cmd = S.blender_command(blend=blend, script=BATCH, args=args)
    return subprocess.run(cmd, capture_output=True, text=True, timeout=600)


def jiggle_arm():
    """A 24 x 6 grid bent by a two-bone Armature (keyed over frames 1-20, still after), a
    Jiggle deformer after it with no handle: the upper arm (x < -0.4) follows the rig, the
    rest jiggles after it."""
    S.reset_scene()
    nx, ny = 24, 6
    obj = S.make_grid(nx=nx, ny=ny)
    rest = S.rest_positions(obj)
    S.group(obj, "held", np.where(rest[:, 0] < -0.4)[0])
    ao = S.arm_rig(obj, {"upper": ((1, (0, 0, 0)), (10, (0, 0, 0.5)), (20, (0.2, 0, 0.1))),
                         "lower": ((1, (0, 0, 0)), (10, (0.8, 0, 0)), (20, (0.3, 0.2, -0.6)))})
    bpy.context.view_layer.objects.active = obj
    bpy.ops.deformkit.add_deformer(method="SHAPE_MATCHING")
    d = obj.deformkit.deformers[0]
    d.fixed_group = "held"
    sc = bpy.context.scene
    sc.frame_start, sc.frame_end = 1, LAST
    sc.frame_set(1)
    bpy.ops.deformkit.bind()
    R.check("binds without a handle", d.bound and not d.status_is_error, d.status)
    return obj, d, ao


def inputs(obj, d, frames):
    """The Armature's output on each frame (what the deformer receives)."""
    out = {}
    for f in frames:
        bpy.context.scene.frame_set(f)
        out[f] = S.armature_input(obj, d)
    return out


def direct(obj, d, inp, frames, alpha=None, **extra):
    """The Python API simulating the same inputs frame by frame (the add-on's keywords)."""
    m = S.methods.get(d.method)
    rest = S.rest_positions(obj)
    mesh = S.dk.Mesh(rest, S.solver.triangles(obj.data))
    fixed = np.where(rest[:, 0] < -0.4)[0]
    kw = dict(fixed=fixed, **extra)
    sm = S.dk.ShapeMatching(mesh, **kw, **S.methods.bind_kwargs(m, d.options, rest, kw, mesh))
    skw = S.methods.solve_kwargs(m, d.options, True)
    skw.update(m.solve_args(obj, d.options, bpy.context.scene))
    out = {}
    for f in frames:
        if alpha is not None:
            skw["alpha"] = alpha[f]
        out[f] = np.asarray(sm.solve(input_positions=inp[f], warm_start=f > frames[0],
                                     **skw).positions)
    return out


def play(obj, frames):
    got = {}
    for f in frames:
        bpy.context.scene.frame_set(f)
        got[f] = S.evaluated_positions(obj)
    return got


def worst(a, b):
    return max(float(np.abs(a[f] - b[f]).max()) for f in a)


def test_playback_is_the_simulation():
    obj, d, ao = jiggle_arm()
    frames = list(range(1, LAST + 1))
    inp = inputs(obj, d, frames)
    want = direct(obj, d, inp, frames)
    got = play(obj, frames)
    R.check("playback = the API simulating the same input (max %.2e)" % worst(got, want),
            worst(got, want) < TOL, worst(got, want))
    lag = max(float(np.abs(got[f] - inp[f]).max()) for f in frames)
    late = float(np.abs(got[LAST] - inp[LAST]).max())
    R.check("the forearm lags and swings (%.3f) and settles once the rig stops (%.4f)"
            % (lag, late), lag > 0.02 and late < 0.2 * lag, (lag, late))
    key = (obj.name, d.uid)
    # scrubbing back: the kept frames, no native solve
    calls = []
    native = S.solver.cache._cache[key].native
    real = native.solve

    class Spy:
        def __getattr__(self, k):
            return getattr(native, k)

        def solve(self, *a, **kw):
            calls.append(1)
            return real(*a, **kw)
    S.solver.cache._cache[key].native = Spy()
    again = play(obj, (12, 5, 30))
    S.solver.cache._cache[key].native = native
    R.check("kept frames show again without a solve", not calls and all(
        np.array_equal(again[f], got[f]) for f in again), len(calls))
    first, last, gap = S.solver.simulation.summary(S.solver.cache._cache[key])
    R.check("the panel's range: frames 1-%d kept" % LAST, (first, last, gap) == (1, LAST, None),
            (first, last, gap))
    text = S.solver.status.simulation_text(obj, d)
    R.check("the panel says what is simulated", "1-%d" % LAST in text, text)


def test_an_edit_resimulates_from_the_frame_it_changes():
    obj, d, ao = jiggle_arm()
    frames = list(range(1, LAST + 1))
    play(obj, frames)
    # a key of the forearm at frame 10 changed while frame 30 is shown
    bpy.context.scene.frame_set(30)
    pb = ao.pose.bones["lower"]
    pb.rotation_euler = (0.2, 0.5, 0.0)
    pb.keyframe_insert("rotation_euler", frame=10)
    bpy.context.view_layer.update()
    inp = inputs(obj, d, frames)
    want = direct(obj, d, inp, frames)
    got = play(obj, frames)
    R.check("after an edit, playback from frame 1 = the new simulation (max %.2e)"
            % worst(got, want), worst(got, want) < TOL, worst(got, want))


def test_the_hold_paint_reaches_each_vertex():
    """The Hold group's weights are the native attach_map: painted 0.8 over the forearm, the
    jiggle shrinks, and playback is still the API's simulation given that map."""
    obj, d, ao = jiggle_arm()
    frames = list(range(1, 25))
    inp = inputs(obj, d, frames)
    free = play(obj, frames)
    rest = S.rest_positions(obj)
    held = np.where(rest[:, 0] > 0.0)[0]
    S.group(obj, "hold", held, np.full(len(held), 0.8))
    d.material_group = "hold"
    bpy.context.view_layer.update()
    attach = np.where(rest[:, 0] > 0.0, 0.8, 0.0)
    want = direct(obj, d, inp, frames, attach_map=attach)
    got = play(obj, frames)
    R.check("held: playback = the API given the paint (max %.2e)" % worst(got, want),
            worst(got, want) < TOL, worst(got, want))
    lag = {k: max(float(np.abs(r[f] - inp[f]).max()) for f in frames)
           for k, r in (("free", free), ("held", got))}
    R.check("the Hold paint shrinks the jiggle (%.3f -> %.3f)" % (lag["free"], lag["held"]),
            lag["held"] < 0.5 * lag["free"], lag)


def test_painted_stiffness_damping_and_squash_reach_each_vertex():
    """The Advanced section's paints: each group's weights are the native per-vertex factor
    (1 where the group has none)."""
    obj, d, ao = jiggle_arm()
    rest = S.rest_positions(obj)
    fore = np.where(rest[:, 0] > 0.3)[0]
    o = d.options_shape_matching
    maps = {}
    for opt, keyword, weight in (("stiffness_group", "alpha_map", 0.2),
                                 ("damping_group", "damping_map", 0.5),
                                 ("squash_group", "beta_map", 0.7)):
        S.group(obj, opt, fore, np.full(len(fore), weight))
        setattr(o, opt, opt)
        m = np.ones(len(rest))
        m[fore] = weight
        maps[keyword] = m
    bpy.context.view_layer.update()
    frames = list(range(1, 21))
    inp = inputs(obj, d, frames)
    want = direct(obj, d, inp, frames, **maps)
    got = play(obj, frames)
    plain = direct(obj, d, inp, frames)
    R.check("painted factors: playback = the API given them (max %.2e; %.3f from unpainted)"
            % (worst(got, want), worst(got, plain)),
            worst(got, want) < TOL and worst(got, plain) > 0.01, worst(got, want))


def test_a_frame_ahead_of_the_simulation():
    obj, d, ao = jiggle_arm()
    play(obj, range(1, 6))   # frames 1-5 simulated: the next to simulate is 6
    bpy.context.scene.frame_set(25)
    got = S.evaluated_positions(obj)
    inp = S.armature_input(obj, d)
    R.check("a frame ahead of the kept ones shows the input", np.abs(got - inp).max() < TOL,
            np.abs(got - inp).max())
    text = S.solver.status.simulation_text(obj, d)
    R.check("the panel says to play from frame 6", "play from frame 6" in text, text)


def test_a_reopened_file_shows_the_frame_it_saved():
    """The frames played are kept in memory, not in the file: on a reopened file the frame
    saved is ahead of what can be simulated. It shows what was saved (not the input), also
    after an update re-solves the deformer, with the panel saying where to play from; an
    edit of that frame, or another frame, shows the input as before."""
    obj, d, ao = jiggle_arm()
    got = play(obj, range(1, 13))
    blend = os.path.join(S.OUTPUT, "jiggle_saved.blend")
    name = obj.name
    bpy.ops.wm.save_as_mainfile(filepath=blend)
    bpy.ops.wm.open_mainfile(filepath=blend)
    obj = bpy.data.objects[name]
    d = obj.deformkit.deformers[0]
    R.check("the file opens at the frame it saved", bpy.context.scene.frame_current == 12,
            bpy.context.scene.frame_current)
    obj.update_tag()                       # an update: the add-on solves the deformer again
    bpy.context.view_layer.update()
    key = (obj.name, d.uid)
    R.check("the add-on solved it after the load", key in S.solver.cache._cache)
    shown = S.evaluated_positions(obj)
    R.check("the saved frame shows as saved (%.1e)" % np.abs(shown - got[12]).max(),
            np.abs(shown - got[12]).max() < TOL, np.abs(shown - got[12]).max())
    R.check("and differs from the input", np.abs(shown - S.armature_input(obj, d)).max() > 0.01)
    text = S.solver.status.simulation_text(obj, d)
    R.check("the panel says it is the saved result, and to play from frame 1",
            "as saved" in text and "play from frame 1" in text, text)
    # a bind setting changed: another simulation, whose frame this is not (the key names the
    # binding too)
    m = S.methods.get(d.method)
    o = next(o for o in m.options if o.bind_time and o.type == "INT")
    before = getattr(d.options_shape_matching, o.name)
    setattr(d.options_shape_matching, o.name, before + 1)
    bpy.context.view_layer.update()
    inp = S.armature_input(obj, d)
    R.check("a changed bind setting (%s) shows the input" % o.name,
            np.abs(S.evaluated_positions(obj) - inp).max() < TOL)
    setattr(d.options_shape_matching, o.name, before)   # back: the saved frame's binding
    bpy.context.view_layer.update()
    R.check("the input still (the attribute holds it now, not the saved frame)",
            np.abs(S.evaluated_positions(obj) - inp).max() < TOL)
    d.options_shape_matching.alpha = 0.5 * d.options_shape_matching.alpha   # an edit here
    bpy.context.view_layer.update()
    R.check("an edit of the frame shows the input",
            np.abs(S.evaluated_positions(obj) - inp).max() < TOL)
    bpy.context.scene.frame_set(13)
    inp = S.armature_input(obj, d)
    R.check("another frame ahead shows the input",
            np.abs(S.evaluated_positions(obj) - inp).max() < TOL)


def test_a_keyed_stiffness_reaches_each_frame():
    obj, d, ao = jiggle_arm()
    d.options_shape_matching.alpha = 0.1
    d.options_shape_matching.keyframe_insert("alpha", frame=1)
    d.options_shape_matching.alpha = 0.9
    d.options_shape_matching.keyframe_insert("alpha", frame=20)
    frames = list(range(1, 31))
    alpha = {}
    for f in frames:
        bpy.context.scene.frame_set(f)
        alpha[f] = d.options_shape_matching.alpha
    inp = inputs(obj, d, frames)
    want = direct(obj, d, inp, frames, alpha=alpha)
    got = play(obj, frames)
    R.check("keyed Stiffness: playback = the API given each frame's (max %.2e)"
            % worst(got, want), worst(got, want) < TOL and alpha[1] != alpha[20],
            worst(got, want))


def test_bakes_write_what_played():
    obj, d, ao = jiggle_arm()
    frames = list(range(1, LAST + 1))
    got = play(obj, frames)
    path = os.path.join(S.OUTPUT, "jiggle_all.pc2")
    later = os.path.join(S.OUTPUT, "jiggle_later.pc2")
    for p in (path, later):
        if os.path.exists(p):
            os.remove(p)
    bake.bake_pc2(bpy.context, obj, d, 1, LAST, path)
    _, all_frames = pc2.read(path)
    diff = max(float(np.abs(np.array(all_frames[f - 1]).reshape(-1, 3) - got[f]).max())
               for f in frames)
    R.check("the bake = playback (max %.2e)" % diff, diff < TOL, diff)
    # a bake of a later range, the simulation's kept frames dropped first (a rebind)
    S.solver.cache._cache[(obj.name, d.uid)].sim = None
    bake.bake_pc2(bpy.context, obj, d, 21, LAST, later)
    _, tail = pc2.read(later)
    same = all(np.array_equal(np.array(a), np.array(b)) for a, b in zip(tail, all_frames[20:]))
    R.check("a bake of frames 21-%d plays the frames before it: the same, bit for bit" % LAST,
            len(tail) == LAST - 20 and same)
    # the modal bake's ticks: the frames before the range one a tick (Esc answers between);
    # it adds its Mesh Cache, so the chunks below bake a file whose deformer is baked (its
    # own modifier hidden: they failed to read the rig's pose there)
    S.solver.cache._cache[(obj.name, d.uid)].sim = None
    job = bake.PC2Bake(bpy.context, obj, d, 21, LAST, later)
    played = []
    try:
        while not job.done:
            f = job.step_async()
            if f is None:
                played.append(job.fb.prerolled)
    finally:
        job.finish(True)
    _, tail = pc2.read(later)
    same = all(np.array_equal(np.array(a), np.array(b)) for a, b in zip(tail, all_frames[20:]))
    R.check("the modal bake plays frames 1-20 one a tick, then bakes the same",
            played == list(range(1, 21)) and len(tail) == LAST - 20 and same, played)
    blend = os.path.join(S.OUTPUT, "jiggle.blend")
    bpy.ops.wm.save_as_mainfile(filepath=blend)
    folder = os.path.join(S.OUTPUT, "jiggle_checkpoints")
    shutil.rmtree(folder, ignore_errors=True)
    os.makedirs(folder)
    outs = [os.path.join(S.OUTPUT, "jiggle_%s.pc2" % k) for k in ("a", "b", "joined")]
    for p in outs:
        if os.path.exists(p):
            os.remove(p)
    logs = []
    for fr, out in (("1-20", outs[0]), ("21-%d" % LAST, outs[1])):   # in order: a chain
        r = run_batch("--object", obj.name, "--frames", fr, "--out", out, "--checkpoints",
                      folder, blend=blend)
        logs.append(r)
        R.check("chunk %s exits 0" % fr, r.returncode == 0, r.stderr[-1500:])
    R.check("the second chunk continues from the first's checkpoint",
            "continuing from the checkpoint of frame 20" in logs[1].stderr,
            logs[1].stderr[-800:])
    r = run_batch("--join", outs[0], outs[1], "--out", outs[2], blend=None)
    R.check("join exits 0", r.returncode == 0, r.stderr[-500:])
    if r.returncode == 0:
        _, joined = pc2.read(outs[2])
        same = len(joined) == LAST and all(
            np.array_equal(np.array(a), np.array(b)) for a, b in zip(joined, all_frames))
        R.check("chunks with checkpoints = one bake, bit for bit", same)
    # a checkpoint of another animation (a key at 15: frames 11-19 change, 20 does not) is
    # refused by name, nothing written
    obj = bpy.data.objects[obj.name]
    ao = bpy.data.objects["Rig"]
    S.key_rotations(ao, {"lower": ((15, (0.1, 0.6, 0.0)),)})
    other = os.path.join(S.OUTPUT, "jiggle_other.blend")
    bpy.ops.wm.save_as_mainfile(filepath=other)
    os.remove(outs[1])
    r = run_batch("--object", obj.name, "--frames", "21-%d" % LAST, "--out", outs[1],
                  "--checkpoints", folder, blend=other)
    R.check("a checkpoint from another animation is refused by name",
            r.returncode != 0 and "another animation of frames 1-20" in r.stderr
            and not os.path.exists(outs[1]), r.stderr[-600:])


def test_a_dropped_checkpoint_sends_playback_back():
    """Beyond the memory budget old checkpoints are dropped (every tenth kept); an edit
    that reaches a frame whose previous checkpoint was dropped names the frame after the
    last checkpoint before it, and playing from there gives the new simulation."""
    obj, d, ao = jiggle_arm()
    budget = S.solver.simulation.MEMORY_BUDGET[0]
    e = None
    try:
        frames = list(range(1, 31))
        play(obj, frames[:1])
        e = S.solver.cache._cache[(obj.name, d.uid)]
        per = len(e.sim.items[1][1])
        S.solver.simulation.MEMORY_BUDGET[0] = 4 * per
        play(obj, frames)
        kept = sorted(f for f, r in e.sim.items.items() if r[1] is not None)
        R.check("checkpoints thinned to every tenth and the newest (%s)" % kept,
                len(kept) <= 5 and 11 in kept and 30 in kept, kept)
        bpy.context.scene.frame_set(25)
        S.key_rotations(ao, {"lower": ((15, (0.1, 0.6, 0.0)),)})
        bpy.context.view_layer.update()
        play(obj, frames)
        # the key at 15 changes frames 11-19; frame 10's checkpoint was dropped, frame 1's
        # is the last before it
        text = S.solver.status.simulation_text(obj, d)
        R.check("the panel sends playback back to frame 2", "play from frame 2" in text, text)
        inp = inputs(obj, d, frames)
        want = direct(obj, d, inp, frames)
        got = play(obj, frames)
        R.check("played on from there: the new simulation (max %.2e)" % worst(got, want),
                worst(got, want) < TOL, worst(got, want))
    finally:
        S.solver.simulation.MEMORY_BUDGET[0] = budget


for t in (test_playback_is_the_simulation, test_an_edit_resimulates_from_the_frame_it_changes,
          test_the_hold_paint_reaches_each_vertex,
          test_painted_stiffness_damping_and_squash_reach_each_vertex,
          test_a_frame_ahead_of_the_simulation, test_a_reopened_file_shows_the_frame_it_saved,
          test_a_keyed_stiffness_reaches_each_frame,
          test_bakes_write_what_played, test_a_dropped_checkpoint_sends_playback_back):
    R.run(t)
R.finish()
