"""Farm bakes on a real Dask cluster on this machine (loopback only): a scheduler and two worker
processes started here, scripts/farm_bake.py submitting the demo's arm-lift scenario in chunks.

- split in chunks (uneven last one), the joined cache is byte-identical to one batch_bake.py
  bake of the whole range; so is a simulation's (Jiggle), whose chunks after the first start
  from the checkpoint the one before left (said by each chunk's Blender);
- a worker killed (SIGKILL) while its Blender is in the middle of a chunk: the scheduler
  reruns the chunk on a worker that lives, the result is still identical, and the killed
  worker's Blender died with it;
- a chunk that fails for good (a handle keyed to NaN in its frames) is reported with its
  frame range and the Blender's message, exit status 1, and --out is left as it was;
- bad arguments and a protected --out are refused before any chunk runs.

Run with the farm environment's Python (scripts/pins.txt [farm]; scripts/test.sh does):
  PYTHONPATH=build/python build/venvs/farm/bin/python -m pytest -q tests/farm
"""

import json
import os
import signal
import subprocess
import sys
import time

import psutil
import pytest
from distributed import Client

ROOT = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
FARM = os.path.join(ROOT, "scripts", "farm_bake.py")
BATCH = os.path.join(ROOT, "scripts", "batch_bake.py")
DEMO = os.path.join(ROOT, "scripts", "demo_blender.py")
PY = sys.executable
ARAP, JIGGLE = "arm-lift ARAP", "arm-lift Jiggle"
TIMEOUT = 300
# the subprocesses run in the test's folder: a relative PYTHONPATH (build/python) made absolute
os.environ["PYTHONPATH"] = os.pathsep.join(
    os.path.abspath(p) for p in os.environ.get("PYTHONPATH", "").split(os.pathsep) if p)


def run(cmd, cwd, **kw):
    return subprocess.run(cmd, cwd=cwd, stdin=subprocess.DEVNULL, capture_output=True,
                          text=True, timeout=TIMEOUT, **kw)


@pytest.fixture(scope="module")
def work(tmp_path_factory):
    return tmp_path_factory.mktemp("farm")


@pytest.fixture(scope="module")
def blend(work):
    """The demo's arm-lift scene (24 frames, its handle keyed from rest to the lift) with an
    ARAP and a Jiggle deformer, saved by this Blender."""
    r = run([PY, DEMO, "--", "--scenarios", "arm-lift", "--methods", "ARAP,SHAPE_MATCHING",
             "--no-render", "--out", str(work / "demo")], cwd=work)
    assert r.returncode == 0, r.stderr[-3000:]
    return str(work / "demo" / "deformkit_demo.blend")


MAKE_FAILING = r'''
import math, sys, bpy
bpy.ops.wm.open_mainfile(filepath=sys.argv[1])
sys.path.insert(0, sys.argv[3])
import addon
addon.register()
e = bpy.data.objects[sys.argv[4]].deformkit.deformers[0].handles[0].target
keep = tuple(e.location)
e.location = (math.nan, 0.0, 0.0)
e.keyframe_insert("location", frame=13)
e.location = keep
e.keyframe_insert("location", frame=19)
act = e.animation_data.action
curves = list(getattr(act, "fcurves", None) or
              [fc for ly in act.layers for st in ly.strips for cb in st.channelbags
               for fc in cb.fcurves])
for fc in curves:
    for k in fc.keyframe_points:
        k.interpolation = "CONSTANT"
bpy.ops.wm.save_as_mainfile(filepath=sys.argv[2])
'''


@pytest.fixture(scope="module")
def failing_blend(work, blend):
    """The same scene with the ARAP handle keyed to NaN on frames 13-18 only."""
    script = work / "make_failing.py"
    script.write_text(MAKE_FAILING)
    out = str(work / "failing.blend")
    r = run([PY, str(script), blend, out, ROOT, ARAP], cwd=work)
    assert r.returncode == 0 and os.path.isfile(out), r.stderr[-3000:]
    return out


@pytest.fixture(scope="module")
def cluster(work):
    """A scheduler and two single-thread workers (each with its nanny), loopback only:
    (address, client)."""
    dask = os.path.join(os.path.dirname(PY), "dask")
    sfile = str(work / "scheduler.json")
    logs = open(work / "cluster.log", "wb")
    procs = [subprocess.Popen([dask, "scheduler", "--host", "127.0.0.1", "--port", "0",
                               "--no-dashboard", "--scheduler-file", sfile],
                              stdout=logs, stderr=logs, cwd=work)]
    try:
        t0 = time.time()
        while not os.path.isfile(sfile) and time.time() - t0 < 60:
            time.sleep(0.1)
        for i in range(2):
            procs.append(subprocess.Popen(
                [dask, "worker", "--scheduler-file", sfile, "--nthreads", "1", "--host",
                 "127.0.0.1", "--no-dashboard", "--name", "worker-%d" % i],
                stdout=logs, stderr=logs, cwd=work))
        client = Client(scheduler_file=sfile, timeout="60s")
        client.wait_for_workers(2, timeout=120)
        yield client.scheduler.address, client
        client.close()
    finally:
        for p in procs[::-1]:
            p.terminate()
        for p in procs[::-1]:
            try:
                p.wait(timeout=30)
            except subprocess.TimeoutExpired:
                p.kill()
        logs.close()


def single_bake(work, blend, obj, name):
    """One batch_bake.py bake of the scene's whole range: the reference."""
    out = str(work / name)
    if not os.path.isfile(out):
        r = run([PY, BATCH, "--blend", blend, "--object", obj, "--out", out], cwd=work)
        assert r.returncode == 0, r.stderr[-3000:]
    return out


def farm(work, address, blend, obj, out, *extra):
    summary = str(work / (os.path.basename(out) + ".json"))
    r = run([PY, FARM, "--scheduler", address, "--blend", blend, "--object", obj,
             "--out", out, "--summary", summary] + list(extra), cwd=work)
    s = json.load(open(summary)) if r.returncode == 0 else None
    return r, s


def same_bytes(a, b):
    with open(a, "rb") as fa, open(b, "rb") as fb:
        return fa.read() == fb.read()


def test_chunks_join_to_the_single_bake(work, blend, cluster):
    ref = single_bake(work, blend, ARAP, "arap_single.pc2")
    out = str(work / "arap_farm.pc2")
    r, s = farm(work, cluster[0], blend, ARAP, out, "--chunk", "7")
    assert r.returncode == 0, r.stderr[-3000:]
    assert [c["frames"] for c in s["chunk_runs"]] == ["1-7", "8-14", "15-21", "22-24"]
    assert same_bytes(out, ref), "the joined cache differs from the single bake"
    assert len(s["workers"]) == 2, "both workers should have baked chunks: %s" % s["workers"]
    assert "24/24 frames" in r.stderr and "slowest worker" in r.stderr, r.stderr
    # the chunks' folders are gone
    assert not [n for n in os.listdir(work) if n.startswith(".farm-")]


def test_simulation_chunks_continue_from_checkpoints(work, blend, cluster):
    ref = single_bake(work, blend, JIGGLE, "jiggle_single.pc2")
    out = str(work / "jiggle_farm.pc2")
    r, s = farm(work, cluster[0], blend, JIGGLE, out, "--chunk", "5")
    assert r.returncode == 0, r.stderr[-3000:]
    runs = s["chunk_runs"]
    assert [c["frames"] for c in runs] == ["1-5", "6-10", "11-15", "16-20", "21-24"]
    assert [c["continued"] for c in runs] == [False, True, True, True, True], runs
    assert same_bytes(out, ref), "the simulation's joined cache differs from the single bake"


def test_worker_killed_in_the_middle_of_a_chunk(work, blend, cluster):
    address, client = cluster
    ref = single_bake(work, blend, ARAP, "arap_single.pc2")
    out = str(work / "arap_killed.pc2")
    summary = str(work / "arap_killed.json")
    proc = subprocess.Popen([PY, FARM, "--scheduler", address, "--blend", blend, "--object",
                             ARAP, "--out", out, "--chunk", "12", "--summary", summary],
                            cwd=work, stdin=subprocess.DEVNULL, stdout=subprocess.PIPE,
                            stderr=subprocess.PIPE, text=True)
    victim = blender = None
    t0 = time.time()
    while victim is None and time.time() - t0 < 120:
        for w, keys in client.processing().items():
            if any("deformkit-chunk" in str(k) for k in keys):
                pid = client.run(os.getpid, workers=[w])[w]
                kids = psutil.Process(pid).children(recursive=True)
                if kids:
                    victim, blender = (w, pid), kids
                    break
        time.sleep(0.05)
    assert victim is not None, "no chunk started"
    time.sleep(0.8)       # its Blender has opened the file and is solving frames
    assert all(k.is_running() for k in blender), "the chunk ended before the kill"
    os.kill(victim[1], signal.SIGKILL)
    stdout, stderr = proc.communicate(timeout=TIMEOUT)
    assert proc.returncode == 0, stderr[-3000:]
    assert same_bytes(out, ref), "the cache differs from the single bake after the retry"
    runs = json.load(open(summary))["chunk_runs"]
    assert victim[0] not in [c["worker"] for c in runs], (victim, runs)
    # the killed worker's Blender died with it (no orphan baking on)
    gone, alive = psutil.wait_procs(blender, timeout=10)
    assert not alive, "orphaned Blender processes: %s" % alive
    client.wait_for_workers(2, timeout=120)      # its nanny started a new worker


def test_chunk_failing_for_good(work, failing_blend, cluster):
    out = str(work / "failing.pc2")
    with open(out, "wb") as f:       # a previous cache there stays as it was
        f.write(b"POINTCACHE2\0" + bytes(20))
    before = open(out, "rb").read()
    r, _ = farm(work, cluster[0], failing_blend, ARAP, out, "--chunk", "6", "--retries", "1")
    assert r.returncode == 1
    err = r.stderr
    assert "chunk 2 (frames 13-18) failed for good after 2 attempts" in err, err[-3000:]
    assert "not finite" in err and "handle" in err, err[-3000:]
    assert open(out, "rb").read() == before
    assert not [n for n in os.listdir(work) if n.startswith(".farm-")]


def test_refusals_before_any_chunk(work, blend, cluster):
    address = cluster[0]
    r = run([PY, FARM, "--scheduler", address, "--blend", str(work / "missing.blend"),
             "--object", ARAP, "--out", str(work / "x.pc2")], cwd=work)
    assert r.returncode == 1 and "no such .blend file" in r.stderr, r.stderr
    r = run([PY, FARM, "--scheduler", address, "--blend", blend, "--object", ARAP,
             "--out", blend], cwd=work)
    assert r.returncode == 1 and "the .blend being baked" in r.stderr, r.stderr[-2000:]
    assert "chunk 0" not in r.stderr
    r = run([PY, FARM, "--scheduler", address, "--blend", blend, "--object", "nothing",
             "--out", str(work / "x.pc2")], cwd=work)
    assert r.returncode == 1 and "no object named 'nothing'" in r.stderr, r.stderr[-2000:]
    r = run([PY, FARM, "--blend", blend, "--object", ARAP, "--out", str(work / "x.pc2"),
             "--chunk", "0"], cwd=work)
    assert r.returncode == 1 and "--chunk must be at least 1" in r.stderr, r.stderr
    r = run([PY, FARM, "--blend", blend, "--object", ARAP, "--out", str(work / "x.pc2"),
             "--frames", "9-3"], cwd=work)
    assert r.returncode == 1 and "empty frame range 9-3" in r.stderr, r.stderr
    assert not os.path.exists(work / "x.pc2")
