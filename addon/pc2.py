"""PC2 point caches (the format Blender's Mesh Cache modifier reads), pure Python.

Layout (little endian): char[12] "POINTCACHE2\\0", int32 version (1), int32 points,
float32 start frame, float32 sample rate, int32 samples; then samples x points x 3 float32.
No bpy import: usable (and tested) with any Python 3.

Writing never destroys what it was not asked to replace. A cache is written to a new hidden
file beside its target and moved over the target only once complete (check_target decides,
before the first frame and again at the end, that the target may be replaced): a path that
is missing in an existing folder, or a regular file that is already a PC2 cache. Anything
else (a folder, a device, a .blend or any other file, a path in `protect`) is refused with a
PC2Error that names it, and no partial file is left behind.
"""

import errno
import os
import stat
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


def _is_pc2(path):
    try:
        with open(path, "rb") as f:
            return f.read(len(MAGIC)) == MAGIC
    except OSError:
        return False


def _same(a, b):
    try:
        return os.path.samefile(a, b)
    except OSError:
        return False


def check_target(path, protect=()):
    """The real path a cache for `path` may be written to, or PC2Error saying why not.

    Allowed: a missing file in an existing folder, or an existing regular file that is a PC2
    cache (a bake done again). Refused: a folder, anything that is not a regular file (a
    device, a pipe), an existing file of any other kind (the .blend, an image...), a path
    whose folder is missing or not writable, and any path that is the same file as one of
    `protect` (each a path, or a (path, why) pair: why is said in the message). A symbolic
    link is followed: the file it points to is the one checked and written."""
    if not path:
        raise PC2Error("no cache path given")
    real = os.path.realpath(os.path.abspath(path))
    shown = path if os.path.abspath(path) == real else "%s (%s)" % (path, real)
    for item in protect:
        other, why = item if isinstance(item, tuple) else (item, None)
        if other and _same(other, real):
            raise PC2Error("%s is %s: refusing to overwrite it with a point cache"
                           % (shown, why or "a file this cache must not replace"))
    folder = os.path.dirname(real)
    if not os.path.isdir(folder):
        raise PC2Error("the folder %s does not exist: create it first, or choose another "
                       "path for the cache" % folder)
    try:
        st = os.stat(real)
    except FileNotFoundError:
        st = None
    except OSError as e:
        raise PC2Error("cannot write the cache %s: %s" % (shown, e.strerror or e)) from None
    if st is not None:
        if stat.S_ISDIR(st.st_mode):
            raise PC2Error("%s is a folder: give the cache a file name (for example %s)"
                           % (shown, os.path.join(path, "cache.pc2")))
        if not stat.S_ISREG(st.st_mode):
            raise PC2Error("%s is not a regular file (a device, pipe or socket): refusing to "
                           "write a cache there" % shown)
        if not _is_pc2(real):
            raise PC2Error("%s exists and is not a point cache: refusing to overwrite it "
                           "(choose another path, or delete the file first)" % shown)
    if not os.access(folder, os.W_OK | os.X_OK):
        raise PC2Error("cannot write in the folder %s (permission denied)" % folder)
    return real


def _new_temp(target):
    """A new hidden file beside `target`, opened for writing: (file, path). Made with the
    user's umask, never over an existing file."""
    folder, name = os.path.split(target)
    for i in range(100):
        tmp = os.path.join(folder, ".%s.%d.%d.part" % (name, os.getpid(), i))
        try:
            fd = os.open(tmp, os.O_WRONLY | os.O_CREAT | os.O_EXCL, 0o666)
        except FileExistsError:
            continue
        except OSError as e:
            raise PC2Error("cannot write in the folder %s: %s" % (folder, e.strerror or e)) \
                from None
        return os.fdopen(fd, "wb"), tmp
    raise PC2Error("cannot make a temporary file in %s" % folder)


class Writer:
    """Streams frames to disk: w = Writer(path, n_points, start); w.add(frame_xyz); w.close()
    puts the finished cache at `path`; w.abort() (or leaving a `with` block by an exception)
    drops it. Frames go to a hidden temporary file beside `path`; `path` itself is only
    replaced by close(), and only if check_target still allows it then. `protect`: see
    check_target. Raises PC2Error (never a bare OSError) with the path in the message."""

    def __init__(self, path, n_points, start=0.0, rate=1.0, protect=()):
        self.path, self.n_points, self.start, self.rate = path, int(n_points), start, rate
        self.protect = tuple(protect)
        self.samples = 0
        self.target = check_target(path, self.protect)
        self.f, self.tmp = _new_temp(self.target)
        try:
            self.f.write(HEADER.pack(MAGIC, 1, self.n_points, float(start), float(rate), 0))
        except OSError as e:
            self.abort()
            raise PC2Error("cannot write the cache %s: %s" % (path, e.strerror or e)) from None

    def add(self, xyz):
        """xyz: flat sequence / buffer of n_points*3 floats (or an n x 3 numpy array)."""
        try:
            data = xyz.astype("<f4").tobytes()          # numpy
        except AttributeError:
            a = array("f", xyz)
            data = _le(a).tobytes()
        if len(data) != self.n_points * 12:
            raise PC2Error("frame has %d values, expected %d" % (len(data) // 4, self.n_points * 3))
        try:
            self.f.write(data)
        except OSError as e:
            raise PC2Error("cannot write the cache %s: %s" % (self.path, e.strerror or e)) \
                from None
        self.samples += 1

    def close(self):
        """Finishes the cache and moves it to its path (PC2Error, and nothing changed at the
        path, if that is no longer allowed or the disk refuses)."""
        if self.f is None:
            return
        try:
            self.f.seek(0)
            self.f.write(HEADER.pack(MAGIC, 1, self.n_points, float(self.start),
                                     float(self.rate), self.samples))
            self.f.close()
            self.f = None
            # again: the path may have become something else during a long bake
            target = check_target(self.path, self.protect)
            os.replace(self.tmp, target)
        except OSError as e:
            self.abort()
            if e.errno == errno.ENOSPC:
                raise PC2Error("the disk is full: the cache %s was not written" % self.path) \
                    from None
            raise PC2Error("cannot write the cache %s: %s" % (self.path, e.strerror or e)) \
                from None
        except BaseException:
            self.abort()
            raise

    def abort(self):
        """Drops the unfinished cache; the path keeps whatever it held."""
        if self.f is not None:
            try:
                self.f.close()
            except OSError:
                pass
            self.f = None
        if self.tmp is not None:
            try:
                os.remove(self.tmp)
            except OSError:
                pass
            self.tmp = None

    def __enter__(self):
        return self

    def __exit__(self, exc_type, *exc):
        if exc_type is None:
            self.close()
        else:
            self.abort()


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


def write(path, frames, n_points, start=0.0, rate=1.0, protect=()):
    with Writer(path, n_points, start, rate, protect) as w:
        for fr in frames:
            w.add(fr)


def join(paths, out, protect=()):
    """Concatenates caches of consecutive frame ranges (given in any order) into `out`.
    They must have the same point count and rate, and no gap or overlap. `out` is never one
    of `paths`, nor any of `protect` (as in check_target)."""
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
    protect = tuple((p, "one of the caches being joined") for p in paths) + tuple(protect)
    w = Writer(out, h0["points"], h0["start"], h0["rate"], protect)
    try:
        for h, p in heads:
            with open(p, "rb") as src:
                src.seek(HEADER.size)
                size = h["samples"] * h["points"] * 12
                body = src.read(size)
                if len(body) != size:
                    raise PC2Error("%s is truncated" % p)
                w.f.write(body)
                w.samples += h["samples"]
    except OSError as e:
        w.abort()
        raise PC2Error("cannot join into %s: %s" % (out, e.strerror or e)) from None
    except BaseException:
        w.abort()
        raise
    w.close()
    return dict(points=h0["points"], start=h0["start"], rate=h0["rate"], samples=total)
