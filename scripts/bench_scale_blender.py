"""Issue 19, item 3: does Blender freeze while a 692k-vertex mesh is dragged? The add-on in
Blender, on the armadillo midpoint-subdivided twice (scripts/bench_scale.py's scenario):

    PYTHONPATH=build/python build/venvs/bpy-5.3/bin/python scripts/bench_scale_blender.py \\
        [--levels 2] [--methods ARAP,LAPLACIAN,FALLOFF] [--steps 8]

(or `blender -b --factory-startup --python scripts/bench_scale_blender.py -- ...` for
Debian's Blender). Per method: the Bind operator's time, then a drag of --steps handle moves,
each a depsgraph update as the UI makes it (interactive solves), measured two ways:
  sync     the solve in the handler (solver.threaded_solves off): the update's time is
           the time Blender is frozen
  threaded the add-on's UI behaviour (solver.threaded_solves "auto"): a solve slower than
           solver.workers.ASYNC_MS, or any on a mesh of ASYNC_MIN_VERTICES, runs in a worker
           thread and the update returns at once; the refine timer (called here as
           Blender's timer would, every 5 ms) installs the worker's result
Each drag starts from the handle at rest, settled.
and prints, per way, the update's median / max time, the time from the last move to the
first installed result of its targets, and to the settled result, and (ARAP) the energy of
what the last move showed (threaded: the response-basis preview from the last finished
result) over the settled result's. A script, not a test.
"""
import os
import statistics
import sys
import time

import bpy
import numpy as np

HERE = os.path.dirname(os.path.abspath(__file__))
sys.path.insert(0, HERE)
sys.path.insert(0, os.path.join(HERE, "..", "tests", "blender"))
import _setup as S  # noqa: E402  (the add-on, registered from addon/)
import bench_scale as bs  # noqa: E402


def args():
    import argparse
    argv = sys.argv[sys.argv.index("--") + 1:] if "--" in sys.argv else sys.argv[1:]
    ap = argparse.ArgumentParser()
    ap.add_argument("--levels", type=int, default=2)
    ap.add_argument("--methods", default="ARAP,LAPLACIAN,FALLOFF")
    ap.add_argument("--steps", type=int, default=8)
    return ap.parse_args(argv)


def settle(obj, d, limit_s=600.0):
    """Calls the refine timer until it stops; returns the time to the first shown result
    for the handle's final placement and to the end (s)."""
    key = (obj.name, d.uid)
    ent = S.solver.cache._cache[key]
    final = S.solver.solving._solve_inputs(obj, d, ent, bpy.context.evaluated_depsgraph_get())[2]
    t0 = time.perf_counter()
    first = 0.0 if ent.last_inputs == final else None
    while time.perf_counter() - t0 < limit_s:
        nxt = S.handlers.refine()
        ent = S.solver.cache._cache.get(key)
        if first is None and ent is not None and ent.last_inputs == final:
            first = time.perf_counter() - t0
        if nxt is None:
            break
        time.sleep(min(nxt, 0.005))
    return first, time.perf_counter() - t0


def drag(obj, d, e, rest, t, steps, threaded):
    # at rest first, settled, then the drag from there
    S.solver.threaded_solves[0] = False
    e.location = rest
    bpy.context.view_layer.update()
    settle(obj, d)
    S.solver.threaded_solves[0] = "auto" if threaded else False
    S.handlers.force_interactive[0] = True
    start = np.array(e.location)
    times = []
    for k in range(1, steps + 1):
        e.location = start + t * k / steps
        t0 = time.perf_counter()
        bpy.context.view_layer.update()
        times.append((time.perf_counter() - t0) * 1000.0)
        if threaded:  # a timer tick between drag events, as in the UI
            S.handlers.refine()
    shown = shown_positions(obj, d)  # what the last move showed (ARAP: a basis preview)
    first, end = settle(obj, d)
    S.solver.threaded_solves[0] = None
    S.handlers.force_interactive[0] = False
    ratio = None
    ent = S.solver.cache._cache.get((obj.name, d.uid))
    if d.method == "ARAP" and ent is not None:  # its energy over the settled result's
        ratio = float(ent.native.energy(shown)) / float(ent.native.energy(
            shown_positions(obj, d)))
    return times, first, end, ratio


def shown_positions(obj, d):
    me = obj.data
    off = np.empty(len(me.vertices) * 3, dtype=np.float32)
    me.attributes[d.attribute_name].data.foreach_get("vector", off)
    return S.rest_positions(obj) + off.reshape(-1, 3)


def main():
    a = args()
    V, F, fixed, hand, t = bs.scenario("armadillo", a.levels)
    print("armadillo x%d: %d vertices, %d fixed, handle %d" % (a.levels, len(V), len(fixed),
                                                              len(hand)), flush=True)
    print("Blender %s" % bpy.app.version_string)
    for method in a.methods.split(","):
        S.reset_scene()
        obj = S.triangle_mesh_object(V, F)
        S.group(obj, "fixed", fixed)
        S.group(obj, "hand", hand)
        rest = tuple(V[hand].mean(0))
        e = S.empty("Hand", rest)
        bpy.ops.deformkit.add_deformer(method=method)
        d = obj.deformkit.deformers[0]
        d.fixed_group = "fixed"
        bpy.ops.deformkit.add_handle(vertex_group="hand", target=e.name)
        t0 = time.perf_counter()
        bpy.ops.deformkit.bind()
        print("%s: bind %.1f s (%s)" % (method, time.perf_counter() - t0, d.status), flush=True)
        for threaded in (False, True):
            times, first, end, ratio = drag(obj, d, e, rest, np.asarray(t), a.steps,
                                            threaded)
            print("  %-8s update median %.0f ms, max %.0f ms; after the last move: first "
                  "result %s, settled %.1f s (%s)%s"
                  % ("threaded" if threaded else "sync", statistics.median(times), max(times),
                     "-" if first is None else "%.2f s" % first, end,
                     S.solver.solve_summary(obj, d),
                     "" if ratio is None else "; shown at the last move: %.3fx the settled "
                     "energy" % ratio), flush=True)
        S.solver.clear_cache()


main()
os._exit(0)
