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
- bad arguments and a protected --out are refused before any chunk runs;
- farm_bake.py's own local cluster binds each chunk's Blender to its worker's CPUs;
- the job files: `openjd check` and `openjd run` of the template (the cache equals one bake),
  the Flamenco job type's compileJob under Node against the Python plan, the Slurm scripts
  run under bash with their array index, submitted through a stand-in sbatch, and submitted
  to a real single-node Slurm (slurm_node.py; skipped where slurmctld, slurmd, munge or root
  are missing).

Run with the farm environment's Python (scripts/pins.txt [farm]; scripts/test.sh does):
  PYTHONPATH=build/python build/venvs/farm/bin/python -m pytest -q tests/farm
"""

import json
import os
import shutil
import signal
import subprocess
import sys
import time

import psutil
import pytest

ROOT = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
sys.path.insert(0, os.path.join(ROOT, "scripts"))
from deformkit_farm import chunk as chunk_mod  # noqa: E402
from deformkit_farm import jobfiles  # noqa: E402
from deformkit_farm.loopback import Loopback, absolute_pythonpath  # noqa: E402
from deformkit_farm.plan import make_plan  # noqa: E402
sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
import slurm_node  # noqa: E402
FARM = os.path.join(ROOT, "scripts", "farm_bake.py")
BATCH = os.path.join(ROOT, "scripts", "batch_bake.py")
DEMO = os.path.join(ROOT, "scripts", "demo_blender.py")
PY = sys.executable
ARAP, JIGGLE = "arm-lift ARAP", "arm-lift Jiggle"
TIMEOUT = 300
absolute_pythonpath()       # the subprocesses run in the test's folder


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
    c = Loopback(work, workers=2).start()
    try:
        yield c.address, c.client
    finally:
        c.stop()


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


def test_local_cluster_shares_the_cpus(work, blend):
    """Without --scheduler: a local cluster of one worker per CPU (at most 2 here), each
    chunk's Blender bound to its worker's share of the CPUs (disjoint shares), and the
    same bytes as the single bake."""
    ref = single_bake(work, blend, ARAP, "arap_single.pc2")
    out = str(work / "arap_local.pc2")
    summary = str(work / "arap_local.json")
    workers = min(2, len(os.sched_getaffinity(0)))
    r = run([PY, FARM, "--blend", blend, "--object", ARAP, "--out", out, "--chunk", "6",
             "--workers", str(workers), "--summary", summary], cwd=work)
    assert r.returncode == 0, r.stderr[-3000:]
    assert same_bytes(out, ref)
    runs = json.load(open(summary))["chunk_runs"]
    shares = {}
    for c in runs:
        assert c["cpus"], runs
        shares.setdefault(c["worker"], set()).add(tuple(c["cpus"]))
    assert all(len(v) == 1 for v in shares.values()), shares      # one share per worker
    seen = [set(next(iter(v))) for v in shares.values()]
    assert all(not (a & b) for i, a in enumerate(seen) for b in seen[i + 1:]), shares


def test_cpu_share():
    cpus = sorted(os.sched_getaffinity(0))
    assert chunk_mod.cpu_share(0, 1) == cpus
    if len(cpus) >= 2:
        assert chunk_mod.cpu_share(0, 2) + chunk_mod.cpu_share(1, 2) == cpus[:len(cpus) // 2 * 2]
    assert chunk_mod.cpu_share(0, len(cpus) + 1) is None     # fewer CPUs than workers
    assert chunk_mod.cpu_share(5, 2) is None


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
    for summary, why in ((work / "x.pc2", "is --out"), (blend, "the .blend being baked")):
        r = run([PY, FARM, "--scheduler", address, "--blend", blend, "--object", ARAP,
                 "--out", str(work / "x.pc2"), "--summary", str(summary)], cwd=work)
        assert r.returncode == 1 and why in r.stderr, r.stderr[-2000:]
    assert not os.path.exists(work / "x.pc2")


def test_relative_pythonpath_and_an_out_next_to_the_blend(work, blend):
    """The docs' `export PYTHONPATH=build/python`, relative: each chunk's Blender and the
    describe run start in folders of their own, where it named nothing. And `--out //x.pc2`
    is next to the .blend, as in Blender and batch_bake.py (it was the filesystem's root)."""
    folder = work / "jobs_relative"
    env = {**os.environ, "PYTHONPATH": os.path.relpath(os.path.join(ROOT, "build", "python"),
                                                       ROOT)}
    r = run([PY, FARM, "--blend", blend, "--object", ARAP, "--out", "//relative.pc2",
             "--chunk", "10", "--jobs", "slurm", "--jobs-dir", str(folder)], cwd=ROOT,
            env=env)
    assert r.returncode == 0, r.stderr[-3000:]
    want = os.path.join(os.path.dirname(os.path.abspath(blend)), "relative.pc2")
    assert want in (folder / "slurm_join.sh").read_text()


# ------------------------------------------------------------------ job files for farms ---

OPENJD = os.path.join(os.path.dirname(PY), "openjd")


def write_jobs(work, blend, obj, name, chunk):
    folder = work / ("jobs_" + name)
    out = str(work / ("%s.pc2" % name))
    r = run([PY, FARM, "--blend", blend, "--object", obj, "--out", out, "--chunk", str(chunk),
             "--jobs", "openjd,flamenco,slurm", "--jobs-dir", str(folder)], cwd=work)
    assert r.returncode == 0, r.stderr[-3000:]
    return folder, out


@pytest.mark.parametrize("obj,name", [(ARAP, "arap"), (JIGGLE, "jiggle")])
def test_openjd_template_checked_and_run(work, blend, obj, name):
    """`openjd check` accepts the template; `openjd run` of its Join step with its
    dependencies (the chunks: a simulation's chained step by step) writes the single bake."""
    ref = single_bake(work, blend, obj, "%s_single.pc2" % name)
    folder, out = write_jobs(work, blend, obj, "openjd_" + name, 10)
    template = str(folder / "deformkit_bake.openjd.json")
    r = run([OPENJD, "check", template], cwd=work)
    assert r.returncode == 0, r.stdout + r.stderr
    t = json.load(open(template))
    steps = [s["name"] for s in t["steps"]]
    if name == "jiggle":
        assert steps == ["Bake 1-10", "Bake 11-20", "Bake 21-24", "Join"], steps
        assert t["steps"][2]["dependencies"] == [{"dependsOn": "Bake 11-20"}]
    else:
        assert steps == ["Bake", "Join"], steps
        space = t["steps"][0]["parameterSpace"]["taskParameterDefinitions"]
        assert [d["range"] for d in space] == [[1, 11, 21], [10, 20, 24]]
    values = "file://%s" % (folder / "deformkit_bake.openjd_values.json")
    r = run([OPENJD, "run", template, "-p", values, "--step", "Join", "--run-dependencies"],
            cwd=work)
    assert r.returncode == 0, (r.stdout + r.stderr)[-4000:]
    assert same_bytes(out, ref), "openjd run's joined cache differs from the single bake"


def flamenco_tasks(folder):
    r = run(["node", os.path.join(ROOT, "tests", "farm", "flamenco_harness.js"),
             str(folder / "deformkit_bake.js"), str(folder / "flamenco_job.json")], cwd=folder)
    assert r.returncode == 0, r.stderr
    return json.loads(r.stdout)


@pytest.mark.parametrize("obj,name,sim", [(ARAP, "arap", False), (JIGGLE, "jiggle", True)])
def test_flamenco_job_type_compiles_the_same_plan(work, blend, obj, name, sim):
    """The job type's compileJob (Node, the Manager's API stood in for) makes one task per
    chunk of the Python plan, with the command line BakeSpec.command gives the blender
    program, a simulation's tasks chained, and a join after all of them."""
    folder, out = write_jobs(work, blend, obj, "flamenco_" + name, 7)
    got = flamenco_tasks(folder)
    job = json.load(open(folder / "flamenco_job.json"))
    s = job["settings"]
    assert job["type"] == "deformkit-bake" and set(s) <= set(got["settings"]), (s, got)
    plan = make_plan(1, 24, 7, sim)
    spec = chunk_mod.BakeSpec(blend=s["blendfile"], object=obj, deformer=s["deformer"],
                              scene=s["scene"], blender="{blender}",
                              batch_script=s["batch_script"], simulation=sim)
    tasks = got["tasks"]
    assert [t["name"] for t in tasks] == ["bake-%s" % c.label for c in plan] + ["join"]
    for c, t in zip(plan, tasks):
        cmd = spec.command(jobfiles.chunk_args(s["chunk_folder"], c.first, c.last, sim))
        p = t["commands"][0]["parameters"]
        assert t["commands"][0]["name"] == "blender-render" and p["exe"] == "{blender}"
        assert cmd[1:3] == ["-b", p["blendfile"]], cmd
        assert p["args"] == cmd[3:], (p["args"], cmd)
        assert t["dependencies"] == (["bake-%s" % plan[c.after].label] if c.after >= 0 else [])
    join = tasks[-1]
    caches = [jobfiles.chunk_cache(s["chunk_folder"], c.first, c.last) for c in plan]
    assert join["commands"][0]["parameters"]["args"] == \
        jobfiles.join_command(spec, caches, s["output_cache"])[2:]
    assert join["dependencies"] == ["bake-%s" % c.label for c in plan]


def test_slurm_scripts(work, blend):
    """Each array element's script (run by bash with its index, as Slurm would) and the join
    script write the single bake; slurm_submit.sh, with an sbatch that records its calls,
    submits the array and the join after it (afterok), a simulation as a chain."""
    ref = single_bake(work, blend, ARAP, "arap_single.pc2")
    folder, out = write_jobs(work, blend, ARAP, "slurm_arap", 10)
    for i in range(3):
        r = run(["bash", str(folder / "slurm_chunk.sh")], cwd=work,
                env={**os.environ, "SLURM_ARRAY_TASK_ID": str(i)})
        assert r.returncode == 0, r.stderr[-3000:]
    r = run(["bash", str(folder / "slurm_chunk.sh"), "3"], cwd=work)
    assert r.returncode == 2 and "no chunk 3 (0-2)" in r.stderr, r.stderr
    r = run(["bash", str(folder / "slurm_join.sh")], cwd=work)
    assert r.returncode == 0, r.stderr[-3000:]
    assert same_bytes(out, ref), "the Slurm scripts' cache differs from the single bake"
    # submission, with a stand-in sbatch on PATH
    bin_dir = work / "fake_bin"
    bin_dir.mkdir(exist_ok=True)
    log = work / "sbatch.log"
    (bin_dir / "sbatch").write_text(
        '#!/bin/bash\necho "$*" >> %s\nn=$(wc -l < %s)\necho "$((100 + n))"\n' % (log, log))
    os.chmod(bin_dir / "sbatch", 0o755)
    env = {**os.environ, "PATH": "%s:%s" % (bin_dir, os.environ["PATH"])}
    r = run(["bash", str(folder / "slurm_submit.sh")], cwd=work, env=env)
    assert r.returncode == 0, r.stderr
    calls = log.read_text().splitlines()
    assert calls == ["--parsable --array=0-2 %s" % (folder / "slurm_chunk.sh"),
                     "--parsable --dependency=afterok:101 --kill-on-invalid-dep=yes %s"
                     % (folder / "slurm_join.sh")], calls
    log.unlink()
    sim_folder, _ = write_jobs(work, blend, JIGGLE, "slurm_jiggle", 10)
    r = run(["bash", str(sim_folder / "slurm_submit.sh")], cwd=work, env=env)
    assert r.returncode == 0, r.stderr
    chunk = sim_folder / "slurm_chunk.sh"
    after = "--kill-on-invalid-dep=yes"
    assert log.read_text().splitlines() == [
        "--parsable %s 0" % chunk, "--parsable --dependency=afterok:101 %s %s 1" % (after, chunk),
        "--parsable --dependency=afterok:102 %s %s 2" % (after, chunk),
        "--parsable --dependency=afterok:103 %s %s" % (after, sim_folder / "slurm_join.sh")]


@pytest.mark.skipif(bool(slurm_node.missing_tools()),
                    reason="no single-node Slurm here: %s" % ", ".join(slurm_node.missing_tools()))
@pytest.mark.parametrize("obj,name", [(ARAP, "arap"), (JIGGLE, "jiggle")])
def test_slurm_single_node(work, blend, obj, name):
    """slurm_submit.sh on a real Slurm (slurmctld and slurmd on this machine, a MUNGE of
    their own): the chunks (an array; a simulation: a chain) and the join run as Slurm
    jobs, and the cache equals one bake."""
    ref = single_bake(work, blend, obj, "%s_single.pc2" % name)
    folder, out = write_jobs(work, blend, obj, "slurm_real_" + name, 10)
    with slurm_node.SlurmNode(work / ("slurm_" + name)) as node:
        r = run(["bash", str(folder / "slurm_submit.sh")], cwd=folder, env=node.env)
        assert r.returncode == 0, r.stdout + r.stderr
        assert node.wait_idle(TIMEOUT), "the Slurm jobs did not finish"
    job_logs = [f for f in sorted(os.listdir(folder))
                if f.startswith("slurm-") and f.endswith(".out")]
    logs = "".join(open(folder / f).read() for f in job_logs)
    assert os.path.isfile(out), "no joined cache; the jobs said:\n" + logs[-4000:]
    assert len(job_logs) == 4, job_logs        # three chunks and the join ran as jobs
    assert same_bytes(out, ref), "the Slurm bake's cache differs from the single bake"


ECHO_ARGS = r'''#!/usr/bin/env python3
import json, sys
with open(sys.argv[0] + ".calls", "a") as f:
    f.write(json.dumps(sys.argv[1:]) + "\n")
'''


def test_slurm_quoting_of_hostile_names(work):
    """Paths and names with spaces, quotes, $, backquotes and a negative frame range reach
    the program exactly as BakeSpec.command gives them: nothing expands, nothing breaks."""
    folder = work / "it's $HOME `id` \"q\""
    folder.mkdir(exist_ok=True)
    fake = folder / "py $x"
    fake.write_text(ECHO_ARGS)
    os.chmod(fake, 0o755)
    spec = chunk_mod.BakeSpec(blend=str(folder / "a $b.blend"), object='Bo"dy $x `id`',
                              python=str(fake), batch_script=str(folder / "bb's.py"))
    described = {"scene": "Sc'ene", "object": spec.object, "deformer": "De $(id)",
                 "simulation": True, "method": "SHAPE_MATCHING"}
    plan = make_plan(-5, 3, 4, True)
    out = str(folder / "out $(id).pc2")
    files = jobfiles.slurm_files(spec, described, plan, out, str(folder / "chunks"))
    for name, text in files.items():
        (folder / name).write_text(text)
        assert run(["bash", "-n", str(folder / name)], cwd=work).returncode == 0, name
    for c in plan:
        r = run(["bash", str(folder / "slurm_chunk.sh"), str(c.index)], cwd=work)
        assert r.returncode == 0, r.stderr
    r = run(["bash", str(folder / "slurm_join.sh")], cwd=work)
    assert r.returncode == 0, r.stderr
    calls = [json.loads(ln) for ln in open(str(fake) + ".calls")]
    tspec = chunk_mod.BakeSpec(**{**spec.__dict__, "scene": "Sc'ene", "deformer": "De $(id)",
                                  "simulation": True})
    want = [tspec.command(jobfiles.chunk_args(str(folder / "chunks"), c.first, c.last, True))[1:]
            for c in plan]
    caches = [jobfiles.chunk_cache(str(folder / "chunks"), c.first, c.last) for c in plan]
    want.append(jobfiles.join_command(tspec, caches, out)[1:])
    assert calls == want, (calls, want)
    assert [c.label for c in plan] == ["-5--2", "-1-2", "3-3"]
    assert "--frames=-5--2" in calls[0]


def test_negative_frame_ranges_parse():
    import importlib.util
    spec = importlib.util.spec_from_file_location("batch_bake_for_test", BATCH)
    bb = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(bb)
    assert bb.parse_frames("-5-10", None) == (-5, 10)
    assert bb.parse_frames("-5--2", None) == (-5, -2)
    assert bb.parse_frames("7", None) == (7, 7)
    args = bb.parse(["x", "--object", "o", "--frames=-5-10", "--out", "a.pc2"])
    assert args.frames == "-5-10"


def test_jobs_refuse_a_protected_out(work, blend):
    folder = work / "jobs_refused"
    r = run([PY, FARM, "--blend", blend, "--object", ARAP, "--out", blend, "--jobs", "slurm",
             "--jobs-dir", str(folder)], cwd=work)
    assert r.returncode == 1 and "the open .blend file" in r.stderr, r.stderr[-2000:]
    assert not folder.exists()
    r = run([PY, FARM, "--blend", blend, "--object", ARAP, "--out",
             str(work / "no_such_folder" / "x.pc2"), "--jobs", "slurm", "--jobs-dir",
             str(folder)], cwd=work)
    assert r.returncode == 1 and "does not exist" in r.stderr, r.stderr[-2000:]
    assert not (work / "no_such_folder").exists()


@pytest.mark.skipif(shutil.which("blender") is None, reason="no blender program on PATH")
def test_chunks_in_the_blender_program(work, cluster):
    """--blender PROGRAM: each chunk runs in the `blender` program (Debian's) instead of the
    bpy module, on a scene that program saved; the join equals its own single bake."""
    demo = work / "demo_program"
    r = run(["blender", "-b", "--factory-startup", "--python-exit-code", "1", "--python", DEMO,
             "--", "--scenarios", "arm-lift", "--methods", "ARAP", "--no-render",
             "--out", str(demo)], cwd=work)
    assert r.returncode == 0, r.stderr[-3000:]
    blend = str(demo / "deformkit_demo.blend")
    ref = str(work / "program_single.pc2")
    r = run(["blender", "-b", blend, "--python-exit-code", "1", "--python", BATCH, "--",
             "--object", ARAP, "--out", ref], cwd=work)
    assert r.returncode == 0, r.stderr[-3000:]
    out = str(work / "program_farm.pc2")
    r, s = farm(work, cluster[0], blend, ARAP, out, "--chunk", "8", "--blender", "blender")
    assert r.returncode == 0, r.stderr[-3000:]
    assert len(s["chunk_runs"]) == 3
    assert same_bytes(out, ref), "the blender program's chunks differ from its single bake"
