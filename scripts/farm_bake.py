"""A DeformKit bake split in chunks across machines: Dask distributed, or job files for a farm.

  build/venvs/farm/bin/python scripts/farm_bake.py --blend scene.blend --object NAME \\
      [--scene NAME] [--deformer NAME] [--frames A-B] --out FILE.pc2 [--chunk N] \\
      [--scheduler tcp://HOST:8786 | --workers N] [--retries N] [--blender PROGRAM]
  ... --jobs openjd,flamenco,slurm --jobs-dir DIR    (write job files instead of baking)

Each chunk of --chunk frames is one task: a headless Blender (the `bpy` module of the Python
running the worker, or --blender PROGRAM) opens the .blend and bakes the chunk's frames with
scripts/batch_bake.py. Without --scheduler, a local cluster of --workers processes is started
for the run (loopback only). The chunks come back as bytes and are joined into --out, a point
cache byte-identical to one `batch_bake.py` bake of the whole range; a simulation's chunks run
in order, each continuing from the checkpoint of the frame before it, and join the same way.
A chunk whose worker dies is rerun by the scheduler; one whose Blender fails is retried
--retries times, then the bake stops, naming the chunk's frames and the Blender's message.
Progress (chunks, frames per second, the slowest worker) goes to stderr; exit status 1 on
any failure, and --out is then left as it was.

Paths are as the workers see them: on several machines the .blend must be at the same path on
each (shared storage); --out is written by this process. The workers need Dask, a Blender
and the add-on; the chunk code travels with the tasks. See docs/farm.md.
"""

import argparse
import json
import logging
import os
import shutil
import sys
import tempfile

HERE = os.path.dirname(os.path.abspath(__file__))
ROOT = os.path.dirname(HERE)
if HERE not in sys.path:
    sys.path.insert(0, HERE)

from deformkit_farm import chunk as chunk_mod  # noqa: E402
from deformkit_farm import plan as plan_mod  # noqa: E402

JOB_KINDS = ("openjd", "flamenco", "slurm")
DEFAULT_CHUNK = 12


def log(msg):
    sys.stderr.write("farm_bake: %s\n" % msg)
    sys.stderr.flush()


def fail(msg, code=1):
    log("error: " + msg)
    sys.stderr.flush()
    sys.stdout.flush()
    # the bpy module is not loaded here, but Dask's threads may still be winding down
    os._exit(code)


def default_workers():
    """One local worker per two CPUs this process may use: a solve runs its passes on two
    threads, faster than two one-thread solves side by side on a 2-core machine
    (docs/farm.md, "Chunk size and speed")."""
    n = len(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity") else os.cpu_count()
    return max(1, (n or 1) // 2)


class Fail(Exception):
    """Stops the run with this message once everything started is shut down."""


class _Parser(argparse.ArgumentParser):
    def error(self, message):
        self.print_usage(sys.stderr)
        fail(message)


def parse(argv):
    p = _Parser(prog="farm_bake.py", description=__doc__.split("\n")[0])
    p.add_argument("--blend", required=True, help="the .blend to bake (the same path on "
                                                  "every worker)")
    p.add_argument("--scene", help="the scene to bake in (default: the file's)")
    p.add_argument("--object", required=True, help="name of the deformed mesh object")
    p.add_argument("--deformer", help="deformer name (default: the object's active one)")
    p.add_argument("--frames", help="frame range A-B (inclusive; default: the scene's; from "
                                    "below zero: --frames=-5-10)")
    p.add_argument("--out", required=True,
                   help="the joined .pc2 cache (its folder must exist; an existing file is "
                        "only replaced if it is a point cache)")
    p.add_argument("--chunk", type=int, default=DEFAULT_CHUNK,
                   help="frames per chunk (default %(default)s; each chunk pays a Blender "
                        "start, the file's load and the bind: docs/farm.md)")
    p.add_argument("--scheduler", metavar="ADDRESS",
                   help="a running Dask scheduler (tcp://host:8786); default: a local "
                        "cluster started for this run")
    p.add_argument("--workers", type=int, default=default_workers(),
                   help="without --scheduler: worker processes of the local cluster, each "
                        "keeping its Blender to an equal share of the cores (default: one "
                        "per two cores, as DeformKit's solvers use two threads: %(default)s "
                        "here)")
    p.add_argument("--retries", type=int, default=1,
                   help="times a chunk whose Blender failed is run again (default "
                        "%(default)s); a worker that dies is the scheduler's to retry")
    p.add_argument("--blender", metavar="PROGRAM",
                   help="run each chunk in this `blender` program (default: Blender as a "
                        "Python module, in the Python running the worker)")
    p.add_argument("--python", metavar="PROGRAM",
                   help="without --blender: a Python with the bpy module to run each chunk "
                        "(default: the worker's own)")
    p.add_argument("--batch-script", default=chunk_mod.BATCH_SCRIPT, metavar="PATH",
                   help="scripts/batch_bake.py as the workers see it (default: this "
                        "checkout's)")
    p.add_argument("--summary", metavar="JSON",
                   help="also write the run's figures here (seconds, frames per second, "
                        "each worker's frames and busy time)")
    p.add_argument("--jobs", metavar="KINDS",
                   help="instead of baking: write job files for %s (comma-separated) into "
                        "--jobs-dir" % ", ".join(JOB_KINDS))
    p.add_argument("--jobs-dir", metavar="DIR", help="with --jobs: the folder to write into")
    a = p.parse_args(argv)
    if a.chunk < 1:
        fail("--chunk must be at least 1 frame, got %d" % a.chunk)
    if a.workers < 1:
        fail("--workers must be at least 1, got %d" % a.workers)
    if a.retries < 0:
        fail("--retries must be 0 or more, got %d" % a.retries)
    if a.frames:
        try:
            plan_mod.parse_range(a.frames)
        except plan_mod.PlanError as e:
            fail("--frames: %s" % e)
    if a.jobs:
        kinds = [k.strip() for k in a.jobs.split(",") if k.strip()]
        bad = [k for k in kinds if k not in JOB_KINDS]
        if bad or not kinds:
            fail("--jobs: unknown kind %s (known: %s)" % (", ".join(bad) or "(none)",
                                                          ", ".join(JOB_KINDS)))
        if not a.jobs_dir:
            fail("--jobs needs --jobs-dir DIR")
        a.jobs = kinds
    return a


def load_pc2():
    """addon/pc2.py without the add-on package (no bpy here), as batch_bake.py loads it."""
    import batch_bake
    return batch_bake.load_pc2_module()


def program(path):
    """A program given as a path (it has a folder in it) made absolute: the chunks' Blenders
    start in folders of their own. A bare name is looked up on the worker's PATH."""
    return os.path.abspath(path) if path and os.sep in path else path


def make_spec(args):
    return chunk_mod.BakeSpec(blend=os.path.abspath(args.blend), object=args.object,
                              deformer=args.deformer, scene=args.scene,
                              blender=program(args.blender), python=program(args.python),
                              batch_script=os.path.abspath(args.batch_script))


def check_folder(path, what):
    """Fails unless the folder `path` would be written into exists and is writable."""
    folder = os.path.dirname(os.path.abspath(path))
    if not os.path.isdir(folder):
        raise Fail("%s: the folder %s does not exist: create it first" % (what, folder))
    if not os.access(folder, os.W_OK | os.X_OK):
        raise Fail("%s: cannot write in the folder %s (permission denied)" % (what, folder))


def check_out(pc2, out, described):
    """The real path of --out, or fail: as a bake checks it (the .blend, its libraries and
    the caches other objects play are never replaced; an existing file only if a cache)."""
    try:
        return pc2.check_target(out, protected(described))
    except pc2.PC2Error as e:
        raise Fail("--out: %s" % e)


def protected(described):
    """(path, why) of the files the joined cache must never replace."""
    return [(described["blend"], "the .blend being baked")] \
        + [tuple(p) for p in described.get("protected", [])]


def write_jobs(args, spec):
    from deformkit_farm import jobfiles
    check_folder(args.out, "--out")
    try:   # --out checked by the Blender as a bake checks it (the .blend, other caches)
        described = chunk_mod.describe(spec, args.frames, os.path.abspath(args.out))
    except chunk_mod.ChunkFailed as e:
        raise Fail(str(e))
    plan = plan_mod.plan_of(described, args.chunk)
    try:
        os.makedirs(args.jobs_dir, exist_ok=True)
    except OSError as e:
        raise Fail("--jobs-dir %s: %s" % (args.jobs_dir, e.strerror or e)) from None
    for kind in args.jobs:
        try:
            for path in jobfiles.write(kind, args, spec, described, plan, args.jobs_dir):
                log("wrote %s" % path)
        except (OSError, ValueError) as e:
            raise Fail("--jobs %s: %s" % (kind, e)) from None


def start_client(args):
    import dask
    from distributed import Client, LocalCluster
    if args.scheduler:
        log("connecting to the scheduler at %s" % args.scheduler)
        try:
            return Client(args.scheduler, timeout="30s"), None
        except (OSError, TimeoutError, ValueError) as e:
            raise Fail("cannot reach the scheduler %s: %s" % (args.scheduler, e))
    cluster = LocalCluster(n_workers=args.workers, threads_per_worker=1, processes=True,
                           host="127.0.0.1", dashboard_address=None,
                           silence_logs=logging.CRITICAL)   # failures are reported here
    log("started a local cluster of %d worker%s at %s"
        % (args.workers, "" if args.workers == 1 else "s", cluster.scheduler_address))
    return Client(cluster), cluster


def farm(args, spec):
    from deformkit_farm import dask_bake
    pc2 = load_pc2()
    out_folder = os.path.dirname(os.path.abspath(args.out))
    check_folder(args.out, "--out")
    if args.summary:
        check_folder(args.summary, "--summary")
        mine = os.path.realpath(args.summary)   # a typo must not put it over these
        for path, why in ((args.out, "--out"), (args.blend, "the .blend being baked")):
            if mine == os.path.realpath(path):
                raise Fail("--summary %s is %s: choose another file" % (args.summary, why))
    client, cluster = start_client(args)
    work = None
    try:
        dask_bake.upload_package(client)
        try:
            described = dask_bake.describe(client, spec, args.frames)
        except dask_bake.FarmError as e:
            raise Fail(str(e))
        out = check_out(pc2, args.out, described)
        if args.summary:   # nor over a library or a cache another object plays
            mine = os.path.realpath(args.summary)
            for path, why in protected(described):
                if mine == os.path.realpath(path):
                    raise Fail("--summary %s is %s: choose another file" % (args.summary, why))
        spec = chunk_mod.BakeSpec(**{**spec.__dict__, "simulation": described["simulation"],
                                     "local_workers": 0 if args.scheduler else args.workers})
        plan = plan_mod.plan_of(described, args.chunk)
        log("%s of %r (%s, %d vertices): frames %d-%d in %d chunk%s of up to %d%s"
            % (described["deformer"], described["object"], described["method"],
               described["vertices"], plan[0].first, plan[-1].last, len(plan),
               "" if len(plan) == 1 else "s", args.chunk,
               "; a simulation: chunks in order, each from the checkpoint before it"
               if described["simulation"] else ""))
        work = tempfile.mkdtemp(prefix=".farm-", dir=out_folder)
        paths = {}

        def on_chunk(c, result):
            path = os.path.join(work, "chunk-%05d.pc2" % c.index)
            try:
                with open(path, "wb") as f:
                    f.write(result["pc2"])
            except OSError as e:
                raise Fail("keeping chunk %d (frames %s) in %s: %s"
                           % (c.index, c.label, work, e.strerror or e)) from None
            paths[c.index] = path

        try:
            summary = dask_bake.bake(client, spec, plan, on_chunk, args.retries, say=log)
        except dask_bake.FarmError as e:
            raise Fail(str(e))
        if args.summary:      # before the join: a failure here leaves --out as it was
            summary.update(chunks=len(plan), chunk=args.chunk,
                           workers_started=None if args.scheduler else args.workers)
            try:
                with open(args.summary, "w") as f:
                    json.dump(summary, f, indent=1)
            except OSError as e:
                raise Fail("--summary %s: %s" % (args.summary, e.strerror or e)) from None
        try:   # protected again: the bake may have taken hours, and files move
            info = pc2.join([paths[c.index] for c in plan], out, protected(described))
        except (pc2.PC2Error, OSError) as e:
            raise Fail("joining the chunks into %s: %s" % (out, e))
        log("wrote %s: %d frames x %d points from %d chunks in %.1f s (%.2f frames/s)"
            % (out, info["samples"], info["points"], len(plan), summary["seconds"],
               summary["frames_per_second"]))
    finally:
        if work:
            shutil.rmtree(work, ignore_errors=True)
        client.close()
        if cluster is not None:
            cluster.close()


def _interrupt(signum, frame):
    raise KeyboardInterrupt


def main():
    import signal
    # a farm's job control stops a submission with SIGTERM (or SIGHUP): clean up as for ^C
    for sig in (signal.SIGTERM, signal.SIGHUP):
        signal.signal(sig, _interrupt)
    args = parse(sys.argv[1:])
    # each chunk's Blender (and the --describe run) starts in a folder of its own: a
    # relative PYTHONPATH (build/python, as the docs' examples give it) would name nothing
    # there
    from deformkit_farm import loopback
    loopback.absolute_pythonpath()
    # "//" as in Blender (and batch_bake.py): next to the .blend
    for name in ("out", "summary"):
        value = getattr(args, name, None)
        if value and value.startswith("//"):
            setattr(args, name, os.path.join(os.path.dirname(os.path.abspath(args.blend)),
                                             value[2:]))
    spec = make_spec(args)
    if not os.path.isfile(spec.blend):
        fail("no such .blend file: %s" % args.blend)
    try:
        if args.jobs:
            write_jobs(args, spec)
        else:
            farm(args, spec)
    except Fail as e:
        fail(str(e))
    except KeyboardInterrupt:
        fail("interrupted: nothing written to %s" % args.out, 130)
    except SystemExit:
        raise
    except Exception as e:  # anything unexpected: non-zero exit with the message
        import traceback
        traceback.print_exc()
        fail("%s: %s" % (type(e).__name__, e))
    sys.stdout.flush()
    sys.stderr.flush()
    os._exit(0)


if __name__ == "__main__":
    main()
