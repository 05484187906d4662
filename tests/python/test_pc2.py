"""PC2 read/write/join of the add-on (addon/pc2.py), without Blender."""
import importlib.util
import os
import struct

import pytest

ROOT = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
spec = importlib.util.spec_from_file_location("dk_pc2", os.path.join(ROOT, "addon", "pc2.py"))
pc2 = importlib.util.module_from_spec(spec)
spec.loader.exec_module(pc2)


def frames(n_points, start, count):
    return [[float(start + s) + 0.001 * i for i in range(n_points * 3)] for s in range(count)]


def test_roundtrip(tmp_path):
    p = str(tmp_path / "a.pc2")
    fr = frames(4, 10, 3)
    pc2.write(p, fr, 4, start=10)
    h, got = pc2.read(p)
    assert h == dict(version=1, points=4, start=10.0, rate=1.0, samples=3)
    assert [list(x) for x in got] == [pytest.approx(x, rel=1e-6) for x in fr]
    raw = open(p, "rb").read()
    assert raw[:12] == b"POINTCACHE2\0" and struct.unpack("<i", raw[12:16])[0] == 1
    assert len(raw) == 32 + 3 * 4 * 12


def test_join_any_order(tmp_path):
    a, b, c, out = (str(tmp_path / n) for n in ("a.pc2", "b.pc2", "c.pc2", "o.pc2"))
    pc2.write(a, frames(5, 1, 4), 5, start=1)
    pc2.write(b, frames(5, 5, 2), 5, start=5)
    pc2.write(c, frames(5, 7, 3), 5, start=7)
    info = pc2.join([c, a, b], out)
    assert info["samples"] == 9 and info["start"] == 1.0
    single = str(tmp_path / "s.pc2")
    pc2.write(single, frames(5, 1, 9), 5, start=1)
    assert open(single, "rb").read() == open(out, "rb").read()


def test_join_errors(tmp_path):
    a, b, out = str(tmp_path / "a.pc2"), str(tmp_path / "b.pc2"), str(tmp_path / "o.pc2")
    pc2.write(a, frames(5, 1, 4), 5, start=1)
    pc2.write(b, frames(5, 6, 2), 5, start=6)
    with pytest.raises(pc2.PC2Error, match="gap"):
        pc2.join([a, b], out)
    pc2.write(b, frames(5, 4, 2), 5, start=4)
    with pytest.raises(pc2.PC2Error, match="overlap"):
        pc2.join([a, b], out)
    pc2.write(b, frames(6, 5, 2), 6, start=5)
    with pytest.raises(pc2.PC2Error, match="points"):
        pc2.join([a, b], out)


def test_bad_files(tmp_path):
    p = str(tmp_path / "x.pc2")
    open(p, "wb").write(b"NOTACACHE")
    with pytest.raises(pc2.PC2Error):
        pc2.read(p)
    w = pc2.Writer(p, 3)
    with pytest.raises(pc2.PC2Error, match="expected 9"):
        w.add([0.0] * 8)
    w.close()
