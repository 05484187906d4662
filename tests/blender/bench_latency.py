"""Per-drag latency inside Blender: handle moved -> evaluated mesh updated, for DeformKit ARAP
and Laplacian editing against Blender's built-in Laplacian Deform modifier (+ a Hook moving its
anchors) on the same mesh, anchors and drag, in the same run.

  PYTHONPATH=build/python blender -b --factory-startup --python-exit-code 1 \
      --python tests/blender/bench_latency.py -- [--scenario PATH] [--steps N] [--json OUT] \
      [--methods ...] [--paired] [--load] [--timer]

Default scenario: ../shared/scenarios/armadillo-wave.json (43k vertices). The drag moves the
handle target along the scenario's translation in N steps; each step's time covers the depsgraph
update that runs the add-on's handler (solve + attribute write) and the re-evaluation of the
modifier stack that shows it (two updates for DeformKit, one for the built-in modifier).
--paired adds, per DeformKit variant (the interactive ones too, without timer ticks), a drag
alternating step by step with a built-in Laplacian Deform object of its own, for a ratio that
machine-speed drift between the variants' runs cannot skew (the add-on's handler also runs,
and returns at once, on the built-in's updates: ~0.05 ms of its ~100).
--load keeps one core busy for the whole run with a second process (a plain Python busy
loop, killed at the end, also on an error, and ending by itself if this process dies), as
when the artist's machine renders or compiles meanwhile; it reports the CPU share the loop
got. --timer: the :interactive variants also run one tick of the refine timer between drag
steps (timed apart), as the UI's timer gets one between mouse moves.
The run ends with a table per variant: median and 90th percentile (numpy's linear
interpolation) of the per-drag times, and the built-in's median / ours and p90 / ours.
"""
import argparse
import json
import os
import statistics
import subprocess
import sys
import time

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
import _setup as S  # noqa: E402
import bpy  # noqa: E402
import numpy as np  # noqa: E402


def args():
    a = sys.argv[sys.argv.index("--") + 1:] if "--" in sys.argv else []
    p = argparse.ArgumentParser()
    p.add_argument("--scenario", default=os.path.join(S.ROOT, "..", "shared", "scenarios",
                                                      "armadillo-wave.json"))
    p.add_argument("--steps", type=int, default=20)
    p.add_argument("--json", default=os.path.join(S.OUTPUT, "bench_latency.json"))
    p.add_argument("--methods", default="ARAP,ARAP:interactive,LAPLACIAN,LAPLACIAN:detail=fixed",
                   help="registry ids, each optionally with :option=value settings, or "
                        ":interactive (the UI's time-budgeted solve plus the refine steps that "
                        "finish it after the drag, timed separately)")
    p.add_argument("--profile", action="store_true",
                   help="print the cProfile of each DeformKit drag (where Python time goes)")
    p.add_argument("--load", action="store_true",
                   help="keep one core busy with a second process (a Python busy loop) for "
                        "the whole run")
    p.add_argument("--timer", action="store_true",
                   help=":interactive variants: one refine-timer tick between drag steps, as "
                        "the UI's timer gets between mouse moves (timed apart)")
    p.add_argument("--paired", action="store_true",
                   help="also drag a built-in Laplacian Deform object step by step alternating "
                        "with each DeformKit variant (its own copy of the mesh), so that the "
                        "ratio compares steps taken within milliseconds of each other: the "
                        "VM's speed can drift by tens of percent between the variants' runs")
    return p.parse_args(a)


# The busy loop of --load: checks now and then that its parent still runs, so that it ends
# even if this Blender is killed before its finally clause.
_BUSY = """
import os
parent = os.getppid()
while True:
    for _ in range(200000):
        pass
    if os.getppid() != parent:
        break
"""


def start_load():
    py = "/usr/bin/python3" if os.path.exists("/usr/bin/python3") else sys.executable
    return subprocess.Popen([py, "-c", _BUSY], stdin=subprocess.DEVNULL,
                            stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)


def cpu_seconds(pid):
    """User + system CPU time of a process (Linux /proc), or None."""
    try:
        with open("/proc/%d/stat" % pid) as f:
            fields = f.read().rsplit(")", 1)[1].split()
        return (int(fields[11]) + int(fields[12])) / os.sysconf("SC_CLK_TCK")
    except (OSError, ValueError, IndexError):
        return None


def stop_load(proc):
    if proc is not None and proc.poll() is None:
        proc.kill()
        proc.wait()


def p90(times):
    return float(np.percentile(np.asarray(times, dtype=np.float64), 90))


def load_obj(path):
    vs, fs = [], []
    with open(path) as f:
        for ln in f:
            if ln.startswith("v "):
                vs.append(tuple(map(float, ln.split()[1:4])))
            elif ln.startswith("f "):
                fs.append(tuple(int(t.split("/")[0]) - 1 for t in ln.split()[1:]))
    return vs, fs


def make_object(name, vs, fs, fixed, handle):
    me = bpy.data.meshes.new(name)
    me.from_pydata(vs, [], fs)
    me.update()
    obj = bpy.data.objects.new(name, me)
    bpy.context.scene.collection.objects.link(obj)
    S.group(obj, "fixed", fixed)
    S.group(obj, "handle", handle)
    S.group(obj, "anchors", list(fixed) + list(handle))
    bpy.context.view_layer.objects.active = obj
    centre = np.asarray(vs)[handle].mean(axis=0)
    e = S.empty(name + " target", tuple(centre))
    return obj, e


def make_builtin(name, vs, fs, fixed, handle):
    """Blender's Laplacian Deform on the anchors (fixed + handle), with a Hook moving the
    handle vertices by the target empty; bound. Returns (object, empty, modifier, bind ms)."""
    obj, e = make_object(name, vs, fs, fixed, handle)
    # the new empty's matrix_world is only valid after an update (else identity, and the Hook
    # would add the empty's whole location to the handle)
    bpy.context.view_layer.update()
    hook = obj.modifiers.new("Hook", "HOOK")
    hook.object = e
    hook.vertex_group = "handle"
    hook.center = e.location
    hook.matrix_inverse = e.matrix_world.inverted()
    lap = obj.modifiers.new("LaplacianDeform", "LAPLACIANDEFORM")
    lap.vertex_group = "anchors"
    lap.iterations = 1
    t0 = time.perf_counter()
    with bpy.context.temp_override(object=obj, active_object=obj):
        bpy.ops.object.laplaciandeform_bind(modifier=lap.name)
    bpy.context.evaluated_depsgraph_get().update()
    return obj, e, lap, (time.perf_counter() - t0) * 1000


def drag_paired(obj, e, bobj, be, steps, translate, check_idx, rest):
    """Steps of the DeformKit drag (two updates each) and of the built-in one (one update)
    alternating, the order swapped every step. Returns (DeformKit ms, built-in ms, errors)."""
    start, bstart = np.array(e.location), np.array(be.location)
    dk, bi = [], []
    dg = bpy.context.evaluated_depsgraph_get()
    for i in range(1, steps + 1):
        for which in ((0, 1) if i % 2 else (1, 0)):
            target, base, n_updates, out, o = ((e, start, 2, dk, obj) if which == 0
                                                else (be, bstart, 1, bi, bobj))
            target.location = tuple(base + np.asarray(translate) * i / steps)
            t0 = time.perf_counter()
            for _ in range(n_updates):
                dg.update()
            v = o.evaluated_get(dg).data.vertices[check_idx].co
            out.append((time.perf_counter() - t0) * 1000.0)
    want = rest[check_idx] + np.asarray(translate)
    errs = [float(np.abs(np.array(o.evaluated_get(dg).data.vertices[check_idx].co) - want).max())
            for o in (obj, bobj)]
    return dk, bi, errs


def drag(obj, e, steps, translate, n_updates, check_idx, rest, ticks=None):
    """Per-step times of a drag; `ticks` (a list): one refine-timer tick before every step
    after the first, its time appended there."""
    start = np.array(e.location)
    times = []
    dg = bpy.context.evaluated_depsgraph_get()
    for i in range(1, steps + 1):
        if ticks is not None and i > 1:
            t0 = time.perf_counter()
            if S.solver.pending():
                S.handlers.refine()
                dg.update()
            ticks.append((time.perf_counter() - t0) * 1000.0)
        e.location = tuple(start + np.asarray(translate) * i / steps)
        t0 = time.perf_counter()
        for _ in range(n_updates):
            dg.update()
        ev = obj.evaluated_get(dg)
        v = ev.data.vertices[check_idx].co  # the evaluated mesh is there
        times.append((time.perf_counter() - t0) * 1000.0)
    got = np.array(v)
    want = rest[check_idx] + np.asarray(translate)
    err = float(np.abs(got - want).max())
    return times, err


def main():
    a = args()
    load = start_load() if a.load else None
    t_start = time.perf_counter()
    cpu0 = cpu_seconds(load.pid) if load is not None else None
    try:
        results = run(a)
        if load is not None:
            cpu1 = cpu_seconds(load.pid)
            wall = time.perf_counter() - t_start
            share = (cpu1 - cpu0) / wall if cpu0 is not None and cpu1 is not None else None
            results["load_cpu_share"] = share
            print("load: the busy loop had %s of a core over the run (%.0f s)"
                  % ("n/a" if share is None else "%.0f%%" % (100 * share), wall))
    finally:
        stop_load(load)
    summary(results)
    with open(a.json, "w") as f:
        json.dump(results, f, indent=1)
    print("bench_latency: wrote %s" % a.json)


def summary(results):
    """The table: per variant the median and p90 per-drag time and the built-in's over ours."""
    b = results.get("BUILTIN_LAPLACIAN_DEFORM")
    if b is None:
        return
    bm, bp = b["drag_ms_median"], b["drag_ms_p90"]
    print("\nper drag (ms), %d steps, %s, %s:" % (results["steps"], results["mesh"],
                                              "one core kept busy" if results["load"]
                                              else "no added load"))
    print("| variant | median | p90 | built-in / ours, median | built-in / ours, p90 |")
    print("|---|---|---|---|---|")
    print("| built-in Laplacian Deform | %.1f | %.1f | 1 | 1 |" % (bm, bp))
    for k, r in results.items():
        if not isinstance(r, dict) or k == "BUILTIN_LAPLACIAN_DEFORM" or k.endswith(":paired"):
            continue
        extra = ""
        if r.get("tick_ms_median") is not None:
            extra = " (timer ticks between steps: median %.1f, p90 %.1f)" % (
                r["tick_ms_median"], r["tick_ms_p90"])
        print("| %s%s | %.1f | %.1f | %.1fx | %.1fx |" % (
            k, extra, r["drag_ms_median"], r["drag_ms_p90"], bm / r["drag_ms_median"],
            bp / r["drag_ms_p90"]))
    for k, r in results.items():
        if isinstance(r, dict) and k.endswith(":paired"):
            print("| %s (paired, its own built-in %.1f / %.1f) | %.1f | %.1f | %.1fx | %.1fx |"
                  % (k[:-len(":paired")], r["builtin_drag_ms_median"], r["builtin_drag_ms_p90"],
                     r["drag_ms_median"], r["drag_ms_p90"], r["ratio_of_medians"],
                     r["builtin_drag_ms_p90"] / r["drag_ms_p90"]))


def run(a):
    with open(a.scenario) as f:
        sc = json.load(f)
    mesh_path = os.path.normpath(os.path.join(os.path.dirname(a.scenario), sc["mesh"]))
    vs, fs = load_obj(mesh_path)
    fixed = sc["fixed"]
    handle = sc["handles"][0]["vertices"]
    translate = sc["handles"][0]["translate"]
    rest = np.asarray(vs)
    results = {"mesh": os.path.basename(mesh_path), "vertices": len(vs), "faces": len(fs),
               "fixed": len(fixed), "handle": len(handle), "steps": a.steps,
               "blender": bpy.app.version_string, "load": bool(a.load),
               "date": time.strftime("%Y-%m-%d %H:%M")}
    S.reset_scene()
    for spec in a.methods.split(","):
        mid, *mods = spec.split(":")
        m = S.methods.get(mid)
        if not S.native.has_class(m.native_class):
            print("skip %s: no deformkit.%s" % (mid, m.native_class))
            continue
        obj, e = make_object("DK_" + mid, vs, fs, fixed, handle)
        bpy.ops.deformkit.add_deformer(method=mid)
        d = obj.deformkit.deformers[0]
        d.fixed_group = "fixed"
        interactive = "interactive" in mods
        for mod in mods:
            if "=" in mod:
                k, v = mod.split("=", 1)
                cur = getattr(d.options, k)
                setattr(d.options, k, type(cur)(v) if not isinstance(cur, str) else v)
        bpy.ops.deformkit.add_handle(vertex_group="handle", target=e.name)
        t0 = time.perf_counter()
        bpy.ops.deformkit.bind()
        bind_ms = (time.perf_counter() - t0) * 1000
        S.handlers.force_interactive[0] = interactive
        if a.paired:
            bobj, be, _, bbind = make_builtin("Builtin_" + mid, vs, fs, fixed, handle)
            dk, bi, errs = drag_paired(obj, e, bobj, be, a.steps, translate, handle[0], rest)
            ratio = statistics.median(bi) / statistics.median(dk)
            per_step = [b / d for b, d in zip(bi, dk)]
            results[spec + ":paired"] = dict(drag_ms_median=statistics.median(dk),
                                             drag_ms_p90=p90(dk), builtin_drag_ms_p90=p90(bi),
                                             builtin_drag_ms_median=statistics.median(bi),
                                             ratio_of_medians=ratio,
                                             step_ratio_median=statistics.median(per_step),
                                             drag_ms_all=dk, builtin_drag_ms_all=bi,
                                             handle_errors=errs, builtin_bind_ms=bbind)
            print("%s paired with the built-in: drag median %.1f ms against %.1f ms: %.1fx "
                  "(median of the per-step ratios %.1fx), handle errors %.1e / %.1e"
                  % (spec, statistics.median(dk), statistics.median(bi), ratio,
                     statistics.median(per_step), errs[0], errs[1]))
            bpy.data.objects.remove(bobj)
            bpy.data.objects.remove(be)
            # back to the start for the unpaired drag below (not timed)
            e.location = tuple(np.array(e.location) - np.asarray(translate))
            bpy.context.evaluated_depsgraph_get().update()
            bpy.context.evaluated_depsgraph_get().update()
        if a.profile:
            import cProfile
            import pstats
            prof = cProfile.Profile()
            prof.enable()
        tick_times = [] if interactive and a.timer else None
        times, err = drag(obj, e, a.steps, translate, 2, handle[0], rest, tick_times)
        if a.profile:
            prof.disable()
            pstats.Stats(prof).sort_stats("tottime").print_stats(12)
        solve = S.solver.runtime.get((obj.name, d.uid), {})
        settle_ms, ticks = 0.0, 0
        if interactive:  # what the timer does once the handle stops
            t0 = time.perf_counter()
            while S.solver.pending() and ticks < 10000 and time.perf_counter() - t0 < 120:
                if all(S.solver.settling(k) for k in S.solver.pending()):
                    time.sleep(0.005)  # a preview waits for the handles to settle
                    continue
                S.handlers.refine()
                bpy.context.evaluated_depsgraph_get().update()
                ticks += 1
            settle_ms = (time.perf_counter() - t0) * 1000
            v = obj.evaluated_get(bpy.context.evaluated_depsgraph_get()).data.vertices
            err = float(np.abs(np.array(v[handle[0]].co) - (rest[handle[0]] + translate)).max())
            solve = S.solver.runtime.get((obj.name, d.uid), {})
        S.handlers.force_interactive[0] = False
        results[spec] = dict(bind_ms=bind_ms, drag_ms_median=statistics.median(times),
                             drag_ms_p90=p90(times), drag_ms_max=max(times), drag_ms_all=times,
                             tick_ms_median=(statistics.median(tick_times) if tick_times
                                             else None),
                             tick_ms_p90=p90(tick_times) if tick_times else None,
                             tick_ms_all=tick_times,
                             last_solve_ms=solve.get("ms"), iterations=solve.get("iterations"),
                             converged=solve.get("converged"), handle_error=err,
                             settle_ms=settle_ms, settle_ticks=ticks)
        obj.hide_viewport = True
        S.handlers.enabled[0] = False  # keep the next measurements free of this object
        print("%s: bind %.0f ms, drag median %.1f ms (p90 %.1f, max %.1f), last solve %.1f ms, "
              "%s it%s" % (spec, bind_ms, statistics.median(times), p90(times), max(times),
                           solve.get("ms", -1),
                 solve.get("iterations"), ", converged %.0f ms after release (%d refine steps)"
                 % (settle_ms, ticks) if interactive else ""))
        bpy.data.objects.remove(obj)
        bpy.data.objects.remove(e)
        S.handlers.enabled[0] = True
    # built-in: Hook (handle vertices to the target) then Laplacian Deform (anchors)
    S.handlers.enabled[0] = False
    obj, e, lap, bind_ms = make_builtin("Builtin", vs, fs, fixed, handle)
    times, err = drag(obj, e, a.steps, translate, 1, handle[0], rest)
    results["BUILTIN_LAPLACIAN_DEFORM"] = dict(bind_ms=bind_ms, drag_ms_median=statistics.median(times),
                                               drag_ms_p90=p90(times), drag_ms_max=max(times),
                                               drag_ms_all=times, handle_error=err,
                                               is_bound=lap.is_bind)
    print("built-in Laplacian Deform: bind %.0f ms, drag median %.1f ms (p90 %.1f, max %.1f), "
          "bound %s" % (bind_ms, statistics.median(times), p90(times), max(times), lap.is_bind))
    return results


main()
