"""One chunk of a farm bake, run where a worker is: a headless Blender baking the chunk's frames
with scripts/batch_bake.py, in a folder of its own.

Everything a chunk makes travels back as bytes (the point cache and, for a simulation, the
checkpoint of its last frame), so a worker needs only the .blend and the Blender (with the
add-on); nothing is written to shared storage, and a killed attempt leaves nothing that a
retry could mistake for its own. The Blender is a child process that dies with the thread
waiting for it (Linux PR_SET_PDEATHSIG): a worker that is killed takes its Blender with it.
Plain Python: no Dask here (scripts/deformkit_farm/dask_bake.py schedules these functions).
"""

import ctypes
import glob
import json
import os
import shutil
import signal
import socket
import subprocess
import sys
import tempfile
import time
from dataclasses import dataclass, field

HERE = os.path.dirname(os.path.abspath(__file__))
BATCH_SCRIPT = os.path.join(os.path.dirname(HERE), "batch_bake.py")
SHIPPED_SCRIPT = "batch_bake_shipped.py"   # its copy in the package uploaded to a cluster
LOG_TAIL = 12        # lines of the Blender's output quoted when a chunk fails


class ChunkFailed(Exception):
    """A chunk's Blender exited non-zero (or could not start): the message names the frames,
    the machine and the Blender's last lines."""


@dataclass(frozen=True)
class BakeSpec:
    """What every chunk of one bake shares. Paths are as the workers see them."""
    blend: str                      # the .blend (the same path on every machine)
    object: str                     # the deformed mesh object
    deformer: str = None            # None: the object's active deformer
    scene: str = None               # None: the file's scene
    blender: str = None             # the `blender` program; None: Blender as a Python module
    python: str = None              # with blender None: a Python with the bpy module
                                    # (None: the interpreter running the task)
    batch_script: str = BATCH_SCRIPT    # where it is missing, the copy shipped with the package
    simulation: bool = False        # chunks continue from checkpoints (describe() says)
    local_workers: int = 0          # > 0: the workers of a local cluster of this many, each
                                    # keeping its Blender to its share of the CPUs (cpu_share)
    env: dict = field(default_factory=dict)   # added to the Blender's environment

    def command(self, batch_args, script=None):
        """The command line running batch_bake.py (`script`, default batch_script) with
        `batch_args` in this spec's Blender."""
        script = script or self.batch_script
        if self.blender:
            cmd = [self.blender, "-b", self.blend]
            if self.scene:
                cmd += ["--scene", self.scene]
            return cmd + ["--python-exit-code", "1", "--python", script, "--"] \
                + self._target_args() + batch_args
        cmd = [self.python or sys.executable, script, "--blend", self.blend]
        if self.scene:
            cmd += ["--scene", self.scene]
        return cmd + self._target_args() + batch_args

    def _target_args(self):
        return ["--object", self.object] + (["--deformer", self.deformer] if self.deformer else [])


def _child_setup(cpus):
    """What the Blender's process does before exec: die with the thread that started it
    (SIGKILL when the worker is killed: no orphaned Blender goes on baking; Linux
    PR_SET_PDEATHSIG), and keep to `cpus` when given (a share of this machine's CPUs).
    prctl is looked up here, in the parent: the child, forked from a process with threads,
    only calls it."""
    try:
        prctl = ctypes.CDLL(None, use_errno=True).prctl
    except (OSError, AttributeError):          # not Linux: the orphan finishes on its own
        prctl = None

    def setup():
        if prctl is not None:
            prctl(1, signal.SIGKILL)           # PR_SET_PDEATHSIG
        if cpus and hasattr(os, "sched_setaffinity"):
            try:
                os.sched_setaffinity(0, cpus)
            except OSError:
                pass
    return setup


def cpu_share(index, count):
    """The CPUs the index-th of `count` workers on this machine keeps to: an equal share of
    the CPUs this process may use (None when there are fewer CPUs than workers, or no
    affinity on this system). Bound so, two chunks do not each start two threads on the
    same two cores (DeformKit's solvers then run their passes on one thread)."""
    if not hasattr(os, "sched_getaffinity") or count < 1:
        return None
    cpus = sorted(os.sched_getaffinity(0))
    k = len(cpus) // count
    if k < 1:
        return None
    return cpus[index * k:(index + 1) * k] if 0 <= index < count else None


def _script(spec, folder):
    """batch_bake.py: spec.batch_script where this machine has it (a checkout at the same
    path: its add-on folder is then the fallback when Blender has none installed), else the
    copy shipped inside this package, written into `folder`."""
    if os.path.isfile(spec.batch_script):
        return spec.batch_script
    import pkgutil
    data = pkgutil.get_data(__package__ or "deformkit_farm", SHIPPED_SCRIPT)
    if data is None:
        raise ChunkFailed("no %s on %s, and none shipped with the package"
                          % (spec.batch_script, socket.gethostname()))
    path = os.path.join(folder, "batch_bake.py")
    with open(path, "wb") as f:
        f.write(data)
    return path


def _run(spec, batch_args, folder, what, cpus=None):
    """Runs batch_bake.py: (wall time, its own progress lines). ChunkFailed with the output's
    tail (its error line when it said one) when it exits non-zero."""
    log_path = os.path.join(folder, "blender.log")
    env = dict(os.environ)
    env.update(spec.env)
    try:
        script = _script(spec, folder)
    except OSError as e:
        raise ChunkFailed("%s on %s: no batch_bake.py: %s" % (what, socket.gethostname(), e))
    cmd = spec.command(batch_args, script)
    t0 = time.perf_counter()
    try:
        with open(log_path, "wb") as log:
            proc = subprocess.Popen(cmd, stdin=subprocess.DEVNULL, stdout=log, stderr=log,
                                    env=env, cwd=folder,
                                    preexec_fn=_child_setup(cpus) if os.name == "posix" else None)
            rc = proc.wait()
    except OSError as e:
        raise ChunkFailed("%s on %s: cannot start %s: %s"
                          % (what, socket.gethostname(), cmd[0], e.strerror or e)) from None
    if rc != 0:
        with open(log_path, "rb") as f:
            lines = f.read().decode("utf-8", "replace").splitlines()
        said = [ln for ln in lines if ln.startswith("batch_bake: error")]
        tail = "\n".join(said[-1:] or lines[-LOG_TAIL:])
        how = "killed by signal %d" % -rc if rc < 0 else "exit status %d" % rc
        raise ChunkFailed("%s failed on %s (%s):\n%s" % (what, socket.gethostname(), how, tail))
    with open(log_path, "rb") as f:
        said = [ln for ln in f.read().decode("utf-8", "replace").splitlines()
                if ln.startswith("batch_bake: ")]
    return time.perf_counter() - t0, said


def describe(spec, frames=None, out=None):
    """What a bake of `spec` would do (batch_bake.py --describe): a dict with frame_start,
    frame_end (`frames` "A-B" or the scene's range), method, simulation, vertices, ... and
    `out` checked as a bake would check it."""
    folder = tempfile.mkdtemp(prefix="deformkit-farm-")
    try:
        path = os.path.join(folder, "describe.json")
        args = ["--describe", path] + (["--frames=" + frames] if frames else []) \
            + (["--out", out] if out else [])
        _run(spec, args, folder, "reading %s in Blender" % spec.blend)
        with open(path) as f:
            return json.load(f)
    finally:
        shutil.rmtree(folder, ignore_errors=True)


def bake_chunk(spec, chunk, checkpoint=None, cpus=None, scratch=None):
    """Bakes `chunk` (scripts/deformkit_farm/plan.Chunk). `checkpoint`: (file name, bytes) the chunk
    before it left, for a simulation. Returns a dict: index, first, last, pc2 (the cache's
    bytes), checkpoint ((name, bytes) of the last frame's, or None), seconds, host,
    cpus (those the Blender was bound to: `cpus`, None for all),
    continued (True when it started from `checkpoint` rather than playing the frames before
    it). `scratch`: the folder to work in (default: the system's temporary folder)."""
    folder = tempfile.mkdtemp(prefix="deformkit-farm-", dir=scratch)
    try:
        out = os.path.join(folder, "chunk.pc2")
        args = ["--frames=" + chunk.label, "--out", out]   # one word: "-5-6" is no option
        states = os.path.join(folder, "checkpoints")
        os.mkdir(states)
        if spec.simulation:
            args += ["--checkpoints", states]
        if checkpoint is not None:
            name, data = checkpoint
            with open(os.path.join(states, os.path.basename(name)), "wb") as f:
                f.write(data)
        seconds, said = _run(spec, args, folder, "its Blender", cpus)
        with open(out, "rb") as f:
            pc2 = f.read()
        left = None
        mine = glob.glob(os.path.join(glob.escape(states), "*.%d.dkstate" % chunk.last))
        if mine:
            with open(mine[0], "rb") as f:
                left = (os.path.basename(mine[0]), f.read())
        return {"index": chunk.index, "first": chunk.first, "last": chunk.last, "pc2": pc2,
                "checkpoint": left, "seconds": seconds, "host": socket.gethostname(),
                "cpus": list(cpus) if cpus else None,
                "continued": any("continuing from the checkpoint" in ln for ln in said)}
    finally:
        shutil.rmtree(folder, ignore_errors=True)
