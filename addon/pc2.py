"""PC2 point caches (the format Blender's Mesh Cache modifier reads), pure Python.

Layout (little endian): char[12] "POINTCACHE2\\0", int32 version (1), int32 points,
float32 start frame, float32 sample rate, int32 samples; then samples x points x 3 float32.
No bpy import: usable (and tested) with any Python 3.
"""

import struct
import sys
from array import array

MAGIC = b"POINTCACHE2\0"
HEADER = struct.Struct("<12siiffi")


class PC2Error(ValueError):
    pass


def _le(a):
    if sys.byteorder != "little":
        a = array("f", a)
        a.byteswap()
    return a


class Writer:
    """Streams frames to disk: w = Writer(path, n_points, start); w.add(frame_xyz); w.close()."""

    def __init__(self, path, n_points, start=0.0, rate=1.0):
        self.path, self.n_points, self.start, self.rate = path, int(n_points), start, rate
        self.samples = 0
        self.f = open(path, "wb")
        self.f.write(HEADER.pack(MAGIC, 1, self.n_points, float(start), float(rate), 0))

    def add(self, xyz):
        """xyz: flat sequence / buffer of n_points*3 floats (or an n x 3 numpy array)."""
        try:
            data = xyz.astype("<f4").tobytes()          # numpy
        except AttributeError:
            a = array("f", xyz)
            data = _le(a).tobytes()
        if len(data) != self.n_points * 12:
            raise PC2Error("frame has %d values, expected %d" % (len(data) // 4, self.n_points * 3))
        self.f.write(data)
        self.samples += 1

    def close(self):
        if self.f is None:
            return
        self.f.seek(0)
        self.f.write(HEADER.pack(MAGIC, 1, self.n_points, float(self.start), float(self.rate),
                                 self.samples))
        self.f.close()
        self.f = None

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        self.close()


def read_header(path):
    with open(path, "rb") as f:
        raw = f.read(HEADER.size)
    if len(raw) < HEADER.size:
        raise PC2Error("%s: too short for a PC2 header" % path)
    magic, version, points, start, rate, samples = HEADER.unpack(raw)
    if magic != MAGIC:
        raise PC2Error("%s: not a PC2 file (bad magic %r)" % (path, magic))
    return dict(version=version, points=points, start=start, rate=rate, samples=samples)


def read(path):
    """(header dict, list of frames, each an array('f') of points*3)."""
    h = read_header(path)
    n = h["points"] * 3
    with open(path, "rb") as f:
        f.seek(HEADER.size)
        body = f.read()
    if len(body) != h["samples"] * n * 4:
        raise PC2Error("%s: header says %d samples of %d points but the file holds %d bytes"
                       % (path, h["samples"], h["points"], len(body)))
    frames = []
    for s in range(h["samples"]):
        a = array("f")
        a.frombytes(body[s * n * 4:(s + 1) * n * 4])
        frames.append(_le(a))
    return h, frames


def write(path, frames, n_points, start=0.0, rate=1.0):
    with Writer(path, n_points, start, rate) as w:
        for fr in frames:
            w.add(fr)


def join(paths, out):
    """Concatenates caches of consecutive frame ranges (given in any order) into `out`.
    They must have the same point count and rate, and no gap or overlap."""
    if not paths:
        raise PC2Error("nothing to join")
    heads = sorted(((read_header(p), p) for p in paths), key=lambda x: x[0]["start"])
    h0 = heads[0][0]
    for h, p in heads[1:]:
        if h["points"] != h0["points"]:
            raise PC2Error("%s has %d points, %s has %d" % (p, h["points"], heads[0][1], h0["points"]))
        if abs(h["rate"] - h0["rate"]) > 1e-6:
            raise PC2Error("%s has sample rate %g, %s has %g" % (p, h["rate"], heads[0][1], h0["rate"]))
    expect = h0["start"]
    for h, p in heads:
        if abs(h["start"] - expect) > 1e-4:
            what = "gap" if h["start"] > expect else "overlap"
            raise PC2Error("%s starts at frame %g but frame %g was expected (%s between chunks)"
                           % (p, h["start"], expect, what))
        expect = h["start"] + h["samples"] * h["rate"]
    total = sum(h["samples"] for h, _ in heads)
    with open(out, "wb") as f:
        f.write(HEADER.pack(MAGIC, 1, h0["points"], h0["start"], h0["rate"], total))
        for h, p in heads:
            with open(p, "rb") as src:
                src.seek(HEADER.size)
                size = h["samples"] * h["points"] * 12
                body = src.read(size)
                if len(body) != size:
                    raise PC2Error("%s is truncated" % p)
                f.write(body)
    return dict(points=h0["points"], start=h0["start"], rate=h0["rate"], samples=total)
