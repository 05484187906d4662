"""A farm bake's chunks as tasks on a Dask distributed scheduler.

Each chunk is one task (scripts/deformkit_farm/chunk.bake_chunk: a headless Blender). A
simulation's chunk k is submitted once chunk k - 1's result is here, with its checkpoint's
bytes as an argument: the chunks run in order anyway, and a worker lost later costs only its
own chunk (were the checkpoint a result left on a worker, losing that worker would have the
scheduler recompute the whole chain before it). Retries: a worker that dies (killed, out of
memory, its machine lost) is Dask's to handle: the scheduler reruns its task elsewhere up to
its `distributed.scheduler.allowed-failures` (3 by default), then gives up with KilledWorker;
a chunk whose Blender fails is retried `retries` times. The code of this package travels to
the scheduler and the workers as an uploaded zip (upload_package), so a worker needs Dask and
a Blender with the add-on, not this checkout.
"""

import os
import sys
import time

from distributed import as_completed, get_worker

HERE = os.path.dirname(os.path.abspath(__file__))
if os.path.dirname(HERE) not in sys.path:
    sys.path.insert(0, os.path.dirname(HERE))

from deformkit_farm import chunk as chunk_mod  # noqa: E402
from deformkit_farm import plan as plan_mod  # noqa: E402, F401  (the chunks' class)

UPLOAD_NAME = "deformkit-farm-package"


def upload_package(client):
    """Sends this package (deformkit_farm) to the scheduler and every worker, those that join
    later included (Dask's upload plugins, registered under one name, so that a run replaces
    the previous run's plugin instead of adding one), so that the tasks' functions and
    arguments unpickle there, with scripts/batch_bake.py inside: the scheduler and workers
    need Dask and a Blender with the add-on installed, not this checkout. Dask reloads only
    the package's top module on a worker that imported an earlier upload: after updating
    DeformKit, restart long-lived workers (docs/farm.md)."""
    import tempfile
    import zipfile
    folder = tempfile.mkdtemp(prefix="deformkit-farm-upload-")
    path = os.path.join(folder, "deformkit_farm.zip")
    with zipfile.ZipFile(path, "w") as z:
        for name in sorted(os.listdir(HERE)):
            if name.endswith(".py"):
                z.write(os.path.join(HERE, name), "deformkit_farm/" + name)
        z.write(chunk_mod.BATCH_SCRIPT, "deformkit_farm/" + chunk_mod.SHIPPED_SCRIPT)
    try:
        from distributed.diagnostics.plugin import SchedulerUploadFile, UploadFile
        client.register_plugin(SchedulerUploadFile(path, load=True), name=UPLOAD_NAME)
        client.register_plugin(UploadFile(path, load=True), name=UPLOAD_NAME)
    finally:
        import shutil
        shutil.rmtree(folder, ignore_errors=True)


class FarmError(Exception):
    """A chunk failed for good: the message names its frames, its worker and why."""


def _worker_address():
    try:
        return get_worker().address
    except ValueError:          # not inside a worker (a test calling the task directly)
        return "local"


def _bake_task(spec, chunk, checkpoint):
    cpus = None
    if spec.local_workers:        # a local cluster's workers are named 0, 1, ...
        try:
            cpus = chunk_mod.cpu_share(int(get_worker().name), spec.local_workers)
        except (ValueError, TypeError):
            cpus = None
    try:    # the worker's own folder: a worker that is killed has it cleaned after it
        scratch = get_worker().local_directory
    except (ValueError, AttributeError):
        scratch = None
    result = chunk_mod.bake_chunk(spec, chunk, checkpoint, cpus, scratch)
    result["worker"] = _worker_address()
    return result


def _describe_task(spec, frames):
    return chunk_mod.describe(spec, frames)


def describe(client, spec, frames=None):
    """batch_bake.py --describe run on one of the workers (they are the ones with Blender)."""
    fut = client.submit(_describe_task, spec, frames, pure=False)
    try:
        return fut.result()
    except Exception as e:
        if _is_chunk_failure(e):
            raise FarmError(str(e)) from None
        raise FarmError("reading %s on a worker failed: %s: %s"
                        % (spec.blend, type(e).__name__, e)) from None


def _is_chunk_failure(exc):
    """A ChunkFailed raised on a worker (recognised by name: a worker that imported an older
    upload of this package raises its own copy of the class)."""
    return type(exc).__name__ == chunk_mod.ChunkFailed.__name__


class Progress:
    """Chunks and frames done, the frame rate so far, and each worker's rate (frames per
    second of its own busy time): the slowest one is the bake's straggler."""

    def __init__(self, plan, say):
        self.chunks, self.frames = len(plan), sum(c.frames for c in plan)
        self.say = say
        self.t0 = time.perf_counter()
        self.done_chunks = self.done_frames = 0
        self.per_worker = {}            # address: [frames, seconds]
        self.done = []                  # per chunk: index, frames, worker, seconds, continued

    def chunk_done(self, c, result):
        self.done_chunks += 1
        self.done_frames += c.frames
        w = self.per_worker.setdefault(result["worker"], [0, 0.0])
        w[0] += c.frames
        w[1] += result["seconds"]
        self.done.append({"index": c.index, "frames": c.label, "worker": result["worker"],
                          "seconds": result["seconds"], "continued": result["continued"],
                          "cpus": result["cpus"]})
        elapsed = time.perf_counter() - self.t0
        slow = min(self.per_worker.items(), key=lambda kv: kv[1][0] / max(kv[1][1], 1e-9))
        self.say("chunk %d (frames %s) done on %s in %.1f s; %d/%d chunks, %d/%d frames, "
                 "%.2f frames/s; slowest worker %s at %.2f frames/s"
                 % (c.index, c.label, result["worker"], result["seconds"], self.done_chunks,
                    self.chunks, self.done_frames, self.frames,
                    self.done_frames / max(elapsed, 1e-9), slow[0],
                    slow[1][0] / max(slow[1][1], 1e-9)))

    def summary(self):
        elapsed = time.perf_counter() - self.t0
        return {"seconds": elapsed, "frames": self.done_frames, "chunks": self.done_chunks,
                "frames_per_second": self.done_frames / max(elapsed, 1e-9),
                "workers": {w: {"frames": f, "busy_seconds": s}
                            for w, (f, s) in self.per_worker.items()},
                "chunk_runs": sorted(self.done, key=lambda r: r["index"])}


def bake(client, spec, plan, on_chunk, retries=1, say=print):
    """Runs every chunk of `plan` on `client`'s cluster. on_chunk(chunk, result) is called in
    the caller's thread as each chunk finishes (in any order; result["pc2"] holds the cache's
    bytes). Returns Progress.summary(). FarmError when a chunk fails for good: the chunks not
    started are cancelled (those running finish their chunk, their results dropped)."""
    progress = Progress(plan, say)
    futures, by_key = [], {}

    def submit(c, checkpoint):
        fut = client.submit(_bake_task, spec, c, checkpoint, retries=retries, pure=False,
                            key="deformkit-chunk-%d-%s-%s" % (c.index, c.label,
                                                              os.urandom(4).hex()))
        futures.append(fut)
        by_key[fut.key] = c
        return fut

    def finished(fut):
        c = by_key[fut.key]
        if fut.status == "cancelled":
            raise FarmError("chunk %d (frames %s) was cancelled by the cluster (its scheduler "
                            "restarted, or lost this run)" % (c.index, c.label))
        if fut.status != "finished":
            raise FarmError(_failure(c, fut.exception(), retries))
        result = fut.result()
        fut.release()
        on_chunk(c, result)
        progress.chunk_done(c, result)
        return result

    try:
        if spec.simulation:     # in order, each from the checkpoint the one before left
            checkpoint = None
            for c in plan:
                fut = submit(c, checkpoint if c.after >= 0 else None)
                for done in as_completed([fut]):
                    checkpoint = finished(done)["checkpoint"]
        else:
            for c in plan:
                submit(c, None)
            for fut in as_completed(list(futures)):
                finished(fut)
    except BaseException:
        client.cancel(futures)
        raise
    return progress.summary()


def _failure(c, exc, retries):
    name = type(exc).__name__
    if name == "KilledWorker":
        return ("chunk %d (frames %s) failed for good: every worker that ran it died (the "
                "scheduler's distributed.scheduler.allowed-failures was reached): %s"
                % (c.index, c.label, exc))
    if _is_chunk_failure(exc):
        return ("chunk %d (frames %s) failed for good after %d attempt%s: %s"
                % (c.index, c.label, retries + 1, "" if retries == 0 else "s", exc))
    return "chunk %d (frames %s) failed for good: %s: %s" % (c.index, c.label, name, exc)
