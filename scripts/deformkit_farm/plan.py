"""The chunk plan of a farm bake: which frames each chunk bakes and which chunk waits for which.

One plan feeds every way of running the bake (Dask in scripts/farm_bake.py, and the job files
for Open Job Description, Flamenco and Slurm), so that they all bake the same chunks. Plain
Python: no Blender, no Dask.

A bake of frames A-B in chunks of N frames is ceil((B - A + 1) / N) chunks of consecutive
frames, the last one possibly shorter. Each frame is solved from its own inputs, so the
chunks are independent and can run anywhere in any order; a simulation (a method whose frame
follows from the one before it, e.g. Jiggle) is the exception: chunk k continues from the
state checkpoint chunk k - 1 left at its last frame, so it waits for it (`after`).
"""

from dataclasses import dataclass


class PlanError(ValueError):
    """A frame range or chunk size that gives no plan."""


@dataclass(frozen=True)
class Chunk:
    index: int        # 0, 1, ...: the chunk's place in the range
    first: int        # first frame (inclusive)
    last: int         # last frame (inclusive)
    after: int        # index of the chunk whose checkpoint this one starts from, or -1

    @property
    def frames(self):
        return self.last - self.first + 1

    @property
    def label(self):
        return "%d-%d" % (self.first, self.last)


def parse_range(text):
    """(A, B) from "A-B" or "A" (negative frames allowed: "-5-10"); PlanError otherwise."""
    try:
        cut = text.index("-", 1) if "-" in text[1:] else -1
        a, b = (text[:cut], text[cut + 1:]) if cut > 0 else (text, text)
        a, b = int(a), int(b)
    except (ValueError, AttributeError):
        raise PlanError("a frame range looks like A-B, got %r" % (text,)) from None
    if b < a:
        raise PlanError("empty frame range %d-%d" % (a, b))
    return a, b


def make_plan(first, last, chunk_frames, simulation=False):
    """The chunks of frames first..last (inclusive), chunk_frames each (the last one what is
    left); with `simulation`, each chunk after the first waits for the one before it."""
    if not isinstance(chunk_frames, int) or chunk_frames < 1:
        raise PlanError("a chunk is at least 1 frame, got %r" % (chunk_frames,))
    if last < first:
        raise PlanError("empty frame range %d-%d" % (first, last))
    chunks = []
    for i, a in enumerate(range(first, last + 1, chunk_frames)):
        chunks.append(Chunk(i, a, min(a + chunk_frames - 1, last),
                            i - 1 if simulation and i > 0 else -1))
    return chunks


def plan_of(described, chunk_frames):
    """The plan of a bake batch_bake.py --describe described (its frame range, simulation or
    not) in chunks of chunk_frames."""
    return make_plan(described["frame_start"], described["frame_end"], chunk_frames,
                     described["simulation"])
