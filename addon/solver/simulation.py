"""A simulation's frames (a method whose native table says `dynamic`: shape matching).

Each frame follows from the one before it, so the add-on plays the simulation from the scene's
first frame and keeps every frame it computed: the positions it showed, the native object's
state after it (a checkpoint: positions, velocities, the frame's goal shape, plastic states)
and a key of what it was computed from (the handles' placement, the animated input, the
keyed settings). On a frame:
- the scene's first frame (or one before it) resets the simulation to that frame's input,
  at rest;
- a frame whose key matches the one kept shows the kept result, with no solve;
- otherwise, when the frame before it is kept, its checkpoint is restored and one frame is
  simulated: the frames after it are dropped (they followed from the old one), so a change
  anywhere invalidates the cache from the first frame it changes, found as playback reaches
  it; an edit at the frame shown (moving a handle there) re-simulates that frame at once;
- a frame with no kept frame before it (a jump ahead of the cache, or a frame before it
  whose checkpoint was dropped for memory) cannot be simulated: it shows the input, the
  kept frames after the last checkpoint before it are dropped, and the panel says from
  which frame to play (a bake plays the frames before its range itself). The exception:
  the frame whose result the deformer's offset attribute holds, with the same key (saved
  with the file, the kept frames are not: a reopened file, or another scene shown after
  a load), shows that result instead of the input until playback simulates it again.
A bake therefore writes what playback showed, bit for bit, and a bake split into chunks
starts each chunk from the checkpoint of the frame before it (export_checkpoint /
import_checkpoint, scripts/batch_bake.py --checkpoints)."""

import hashlib
import struct

import numpy as np

from .. import native

# Checkpoints kept per deformer, in bytes; beyond it the oldest frames' checkpoints are
# dropped (their results stay, to play back) except every CHECKPOINT_STRIDE-th
MEMORY_BUDGET = [2 << 30]
CHECKPOINT_STRIDE = 10


def is_dynamic(method):
    """Whether `method` (an addon.methods.Method) simulates in time (its native table)."""
    return bool(native.method_info(method.native_class).get("dynamic", False))


class Frames:
    """The frames of one binding's simulation (kept on its cache entry, solver.cache)."""

    def __init__(self):
        self.start = None   # the scene frame the simulation starts at
        self.items = {}     # frame -> [key, state bytes or None, positions n x 3 float64,
                            #           chain: the history's hash, chain(previous, key)]
        self.at = None      # the frame whose state the native object holds now, or None
        self.gap_from = None  # the frame playback must start from to reach the shown one
        self.shown = None     # the key of the frame shown (None: the input, no frame)
        self.rest_of = None   # the rest shape whose digest rest_digest is (solving._sim_key)
        self.rest_digest = b""

    def drop_after(self, frame):
        for f in [f for f in self.items if f > frame]:
            del self.items[f]
        if self.at is not None and self.at > frame:
            self.at = None

    def cached_range(self):
        """(first, last) of the frames kept in one run from the start, or None."""
        if self.start is None or self.start not in self.items:
            return None
        last = self.start
        while last + 1 in self.items:
            last += 1
        return self.start, last

    def _trim(self):
        sizes = [(f, len(r[1])) for f, r in self.items.items() if r[1] is not None]
        total = sum(s for _, s in sizes)
        for f, s in sorted(sizes):
            if total <= MEMORY_BUDGET[0]:
                break
            if (f - (self.start or 0)) % CHECKPOINT_STRIDE and f != max(self.items):
                self.items[f][1] = None
                total -= s


def frame_key(plan, frame):
    """What a frame's result depends on besides the frames before it (bytes)."""
    h = hashlib.blake2b(digest_size=20)
    h.update(struct.pack("<q", frame))
    h.update(plan["inputs"])
    h.update(repr(sorted((k, v) for k, v in plan["kw"].items()   # arrays: in the inputs
                         if k not in ("energy", "warm_start") and not hasattr(v, "shape"))
                  ).encode())
    return h.digest()


def chain(previous, key):
    """The hash of a frame's history: its key after its previous frame's chain (b"" before
    the first frame)."""
    return hashlib.blake2b(previous + key, digest_size=20).digest()


class _Result:
    """A kept frame's result in the shape of a native SolveResult."""

    def __init__(self, positions):
        self.positions = positions
        self.iterations = 0
        self.converged = True
        self.energy = float("nan")


def solve(e, plan, call, frame, start, stored=None):
    """The positions of `frame` (scene frame) for the solve `plan` (solving._plan_solve) of
    the cache entry `e`: a kept frame, or one simulated from the frame before it, or a reset
    at the start. `call(label, fn, **kw)` runs a native call (solver.calls); `stored(key)`
    gives the positions the deformer's attribute holds when they are the frame of `key`,
    else None. Returns a SolveResult-like object; e.sim.shown says which frame it is."""
    sim = getattr(e, "sim", None)
    if sim is None or sim.start != start:
        sim = e.sim = Frames()
        sim.start = start
    key = frame_key(plan, frame)
    kw = dict(plan["kw"])
    kw.pop("warm_start", None)
    kw.pop("resume", None)
    kw.pop("max_iterations", None)
    label = plan["label"]
    rec = sim.items.get(frame)
    sim.shown = None
    if frame >= start and rec is not None and rec[0] == key:   # kept: no solve
        sim.gap_from = None
        sim.shown = key
        return _Result(rec[2])
    if frame <= start:
        # the start (kept for the frames after it), or a frame before it: a reset there,
        # not kept (it is no frame of the simulation)
        sim.at = None   # the native object is reset whatever follows
        res = call(label + " solve", e.native.solve, warm_start=False, **plan["goal"], **kw)
        sim.gap_from = None
        if frame < start:
            return res
    else:
        prev = sim.items.get(frame - 1)
        if prev is None or (prev[1] is None and sim.at != frame - 1):
            # ahead of what can be simulated from here: the input as it arrives, at rest.
            # Playback must go back to the last frame with a checkpoint and simulate on: the
            # kept frames after it are dropped so that they are simulated again (a kept frame
            # shows with no solve and would not advance the native object)
            c = max((f for f, r in sim.items.items() if f < frame and r[1] is not None),
                    default=None)
            if c is not None and c + 1 in sim.items:
                sim.drop_after(c)
            sim.gap_from = c + 1 if c is not None else start
            sim.at = None
            kept = stored(key) if stored is not None else None
            if kept is not None:   # this very frame, as saved: shown until played again
                sim.shown = key
                return _Result(kept)
            return call(label + " solve", e.native.solve, warm_start=False, **plan["goal"],
                        **kw)
        if sim.at != frame - 1:
            sim.at = None
            call(label + " restore", e.native.restore_state, prev[1])
        sim.at = None   # until the step below succeeds
        res = call(label + " solve", e.native.solve, warm_start=True, **plan["goal"], **kw)
    positions = np.asarray(res.positions, dtype=np.float64).reshape(-1, 3)
    sim.drop_after(frame)
    history = chain(b"" if frame == start else sim.items[frame - 1][3], key)
    sim.items[frame] = [key, call(label + " checkpoint", e.native.save_state), positions,
                        history]
    sim.at = frame
    sim.gap_from = None
    sim.shown = key
    sim._trim()
    return res


def export_checkpoint(e, frame):
    """(the checkpoint kept after `frame`, the hash of its history: chain()), or None: for a
    chunk that starts after it."""
    sim = getattr(e, "sim", None)
    rec = sim.items.get(frame) if sim is not None else None
    return None if rec is None or rec[1] is None else (rec[1], rec[3])


def import_checkpoint(e, frame, state, start, history):
    """Makes `state` (export_checkpoint's, from another process, whose history the caller
    checked) the frame `frame` of this binding's simulation, as if it had been simulated
    here: the next frame continues from it. The native object checks that the state fits
    (ValueError otherwise)."""
    sim = getattr(e, "sim", None)
    if sim is None or sim.start != start:
        sim = e.sim = Frames()
        sim.start = start
    e.native.restore_state(state)
    sim.drop_after(frame - 1)
    # a key no frame has: never shown as kept; its history continues the chain
    sim.items[frame] = [b"", bytes(state), None, history]
    sim.at = frame


def summary(e):
    """(first, last, gap_from) for the panel: the frames kept from the start, and where
    playback must start to reach a frame ahead of them (None when none is wanted)."""
    sim = getattr(e, "sim", None)
    if sim is None:
        return None
    r = sim.cached_range()
    return (r[0], r[1], sim.gap_from) if r else (None, None, sim.gap_from)
