"""Benchmark of farm bakes (issue 45): a 96-frame ARAP bake of the demo's 43k armadillo
(armadillo-wave, its handle keyed from rest on frame 1 to the wave on the last frame) with
scripts/farm_bake.py on a loopback Dask cluster of separate processes:

  one1   one worker bound to one CPU             (a one-core machine)
  two1   two workers, each bound to its own CPU   (two one-core machines: the farm's scaling)
  one2   one worker, both CPUs                   (DeformKit's own two threads)
  two2   two workers, both CPUs each             (one 2-core machine split in two, unbound)
  batch  no farm: one batch_bake.py process over the whole range, both CPUs
  local  farm_bake.py's own local cluster (no --scheduler): one worker per two CPUs, each
         chunk's Blender bound to its worker's CPUs (what a user of this machine gets)

and the per-chunk overhead: a one-frame chunk at rest (Blender start, the file's load, the
bind) against the frames' solve time. Ratios are within this one run.

  PYTHONPATH=build/python build/venvs/farm/bin/python scripts/bench_farm.py \\
      [--frames 96] [--chunk 12] [--cases one1,two1,batch,local] [--json out.json]
"""

import argparse
import json
import os
import shutil
import subprocess
import sys
import tempfile
import time

HERE = os.path.dirname(os.path.abspath(__file__))
ROOT = os.path.dirname(HERE)
sys.path.insert(0, HERE)
from deformkit_farm.loopback import Loopback, absolute_pythonpath  # noqa: E402

PY = sys.executable
OBJECT = "armadillo-wave ARAP"
CASES = {"one1": (1, ["0"]), "two1": (2, ["0", "1"]), "one2": (1, None), "two2": (2, None),
         "batch": (0, None), "local": (os.cpu_count(), "own")}

RETIME = r'''
import sys, bpy
bpy.ops.wm.open_mainfile(filepath=sys.argv[1])
sys.path.insert(0, sys.argv[3])
import addon
addon.register()
last = int(sys.argv[4])
sc = bpy.context.scene
d = bpy.data.objects[sys.argv[5]].deformkit.deformers[0]
for h in d.handles:
    e = h.target
    sc.frame_set(sc.frame_start)
    rest = [tuple(getattr(e, p)) for p in ("location", "rotation_euler", "scale")]
    sc.frame_set(sc.frame_end)
    moved = [tuple(getattr(e, p)) for p in ("location", "rotation_euler", "scale")]
    e.animation_data_clear()
    for f, vals in ((sc.frame_start, rest), (last, moved)):
        for p, v in zip(("location", "rotation_euler", "scale"), vals):
            setattr(e, p, v)
            e.keyframe_insert(p, frame=f)
sc.frame_end = last
sc.frame_set(sc.frame_start)
bpy.ops.wm.save_as_mainfile(filepath=sys.argv[2])
'''


def run(cmd, cwd):
    r = subprocess.run(cmd, cwd=cwd, capture_output=True, text=True)
    if r.returncode != 0:
        sys.exit("bench_farm: %s failed:\n%s" % (" ".join(cmd[:3]), r.stderr[-3000:]))
    return r


def scene(work, frames):
    run([PY, os.path.join(HERE, "demo_blender.py"), "--", "--scenarios", "armadillo-wave",
         "--methods", "ARAP", "--no-render", "--out", os.path.join(work, "demo")], work)
    script = os.path.join(work, "retime.py")
    with open(script, "w") as f:
        f.write(RETIME)
    blend = os.path.join(work, "bench.blend")
    run([PY, script, os.path.join(work, "demo", "deformkit_demo.blend"), blend, ROOT,
         str(frames), OBJECT], work)
    return blend


def overhead(work, blend, cpus):
    """Wall time of a one-frame chunk at rest (start, load, bind; a trivial solve)."""
    cmd = [PY, os.path.join(HERE, "batch_bake.py"), "--blend", blend, "--object", OBJECT,
           "--frames", "1-1", "--out", os.path.join(work, "one.pc2")]
    t0 = time.perf_counter()
    run(["taskset", "-c", cpus] + cmd, work)
    return time.perf_counter() - t0


def single(work, blend):
    out = os.path.join(work, "batch.pc2")
    t0 = time.perf_counter()
    run([PY, os.path.join(HERE, "batch_bake.py"), "--blend", blend, "--object", OBJECT,
         "--out", out], work)
    t = time.perf_counter() - t0
    return {"wall_seconds": t, "bake_seconds": t, "out": out}


def local(work, blend, chunk):
    out = os.path.join(work, "local.pc2")
    summary = os.path.join(work, "local.json")
    t0 = time.perf_counter()
    run([PY, os.path.join(HERE, "farm_bake.py"), "--blend", blend, "--object", OBJECT,
         "--out", out, "--chunk", str(chunk), "--summary", summary], work)
    s = json.load(open(summary))
    return {"wall_seconds": time.perf_counter() - t0, "bake_seconds": s["seconds"],
            "frames_per_second": s["frames_per_second"], "workers": s["workers"],
            "chunk_runs": s["chunk_runs"], "out": out}


def case(work, blend, name, chunk):
    if name == "batch":
        return single(work, blend)
    if name == "local":
        return local(work, blend, chunk)
    workers, cpus = CASES[name]
    c = Loopback(work, workers, cpus).start()
    try:
        out = os.path.join(work, "%s.pc2" % name)
        summary = os.path.join(work, "%s.json" % name)
        t0 = time.perf_counter()
        run([PY, os.path.join(HERE, "farm_bake.py"), "--scheduler", c.address, "--blend", blend,
             "--object", OBJECT, "--out", out, "--chunk", str(chunk), "--summary", summary],
            work)
        wall = time.perf_counter() - t0
    finally:
        c.stop()
    s = json.load(open(summary))
    return {"wall_seconds": wall, "bake_seconds": s["seconds"],
            "frames_per_second": s["frames_per_second"], "workers": s["workers"],
            "chunk_runs": s["chunk_runs"], "out": out}


def main():
    p = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    p.add_argument("--frames", type=int, default=96)
    p.add_argument("--chunk", type=int, default=12)
    p.add_argument("--cases", default="one1,two1,batch,local")
    p.add_argument("--json")
    a = p.parse_args()
    absolute_pythonpath()
    names = a.cases.split(",")
    work = tempfile.mkdtemp(prefix="bench-farm-")
    try:
        blend = scene(work, a.frames)
        res = {"frames": a.frames, "chunk": a.chunk, "object": OBJECT,
               "chunk_overhead_one_cpu_s": overhead(work, blend, "0"), "cases": {}}
        print("one-frame chunk at rest (start + load + bind), one CPU: %.2f s"
              % res["chunk_overhead_one_cpu_s"], flush=True)
        for n in names:
            r = case(work, blend, n, a.chunk)
            res["cases"][n] = r
            how = {"batch": "batch_bake.py, no farm", "local": "farm_bake.py's local cluster"}
            print("%-5s %s: %.1f s (%.2f frames/s; %.1f s wall with the cluster's start)"
                  % (n, how.get(n, "%d worker(s), %s" % (
                      CASES[n][0], "one CPU each" if CASES[n][1] else "all CPUs")),
                     r["bake_seconds"], a.frames / r["bake_seconds"], r["wall_seconds"]),
                  flush=True)
        outs = [r.pop("out") for r in res["cases"].values()]
        res["identical_caches"] = all(open(o, "rb").read() == open(outs[0], "rb").read()
                                      for o in outs)
        c = res["cases"]
        for a_, b_ in (("one1", "two1"), ("one2", "two2"), ("one1", "one2"),
                       ("batch", "local")):
            if a_ in c and b_ in c:
                res["speedup_%s_over_%s" % (b_, a_)] = c[a_]["bake_seconds"] / c[b_]["bake_seconds"]
                print("%s over %s: %.2fx" % (b_, a_, res["speedup_%s_over_%s" % (b_, a_)]))
        print("caches identical across cases: %s" % res["identical_caches"])
        if a.json:
            with open(a.json, "w") as f:
                json.dump(res, f, indent=1)
    finally:
        shutil.rmtree(work, ignore_errors=True)


if __name__ == "__main__":
    main()
