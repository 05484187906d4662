"""PC2 read/write/join of the add-on (addon/pc2.py), without Blender."""
import importlib.util
import os
import stat
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
    w = pc2.Writer(str(tmp_path / "y.pc2"), 3)
    with pytest.raises(pc2.PC2Error, match="expected 9"):
        w.add([0.0] * 8)
    w.close()


# ---- writing never destroys what it was not asked to replace (pc2.check_target)

def leftovers(folder):
    """Hidden temporary files a writer left behind."""
    return [n for n in os.listdir(folder) if n.endswith(".part")]


def refused(path, match, protect=()):
    """Writing a cache to `path` is refused with a message matching `match`, before any
    frame, and again by pc2.write; nothing is left beside it."""
    with pytest.raises(pc2.PC2Error, match=match):
        pc2.Writer(path, 2, protect=protect)
    with pytest.raises(pc2.PC2Error, match=match):
        pc2.write(path, frames(2, 1, 2), 2, protect=protect)


def test_a_file_that_is_not_a_cache_is_never_overwritten(tmp_path):
    blend = tmp_path / "scene.blend"
    body = b"BLENDER-v405" + os.urandom(4096)
    blend.write_bytes(body)
    refused(str(blend), "exists and is not a point cache")
    assert blend.read_bytes() == body and leftovers(tmp_path) == []
    # through a symbolic link too: the file it points to is the one checked
    link = tmp_path / "link.pc2"
    link.symlink_to(blend)
    refused(str(link), "is not a point cache")
    assert blend.read_bytes() == body and link.is_symlink()
    # an empty file is not a cache either
    empty = tmp_path / "empty.pc2"
    empty.write_bytes(b"")
    refused(str(empty), "not a point cache")


def test_folders_devices_and_missing_folders_are_refused(tmp_path):
    refused(str(tmp_path), "is a folder")
    # a pipe stands for devices and sockets (never a real device: a wrong build would
    # replace it for the whole machine)
    fifo = tmp_path / "fifo.pc2"
    os.mkfifo(fifo)
    refused(str(fifo), "not a regular file")
    assert stat.S_ISFIFO(os.lstat(fifo).st_mode)
    refused(str(tmp_path / "no" / "such" / "x.pc2"), "folder .* does not exist")
    assert not (tmp_path / "no").exists()
    refused("", "no cache path")


@pytest.mark.skipif(os.geteuid() == 0, reason="root writes in a read-only folder")
def test_an_unwritable_folder_is_refused(tmp_path):
    ro = tmp_path / "ro"
    ro.mkdir()
    ro.chmod(0o555)
    try:
        refused(str(ro / "x.pc2"), "permission denied")
    finally:
        ro.chmod(0o755)


def test_protected_paths_are_refused_by_name(tmp_path):
    a = str(tmp_path / "a.pc2")
    pc2.write(a, frames(2, 1, 2), 2)
    before = open(a, "rb").read()
    refused(a, "the cache another object plays", protect=[(a, "the cache another object plays")])
    refused(a, "must not replace", protect=[a])
    assert open(a, "rb").read() == before


def test_a_cache_is_replaced_whole_or_not_at_all(tmp_path):
    p = str(tmp_path / "c.pc2")
    pc2.write(p, frames(3, 1, 2), 3, start=1)
    first = open(p, "rb").read()
    # baking again to a cache replaces it
    pc2.write(p, frames(3, 5, 4), 3, start=5)
    assert pc2.read_header(p)["samples"] == 4 and leftovers(tmp_path) == []
    second = open(p, "rb").read()
    assert second != first
    # an unfinished write leaves the old cache as it was, and no temporary file
    w = pc2.Writer(p, 3, start=9)
    w.add(frames(3, 9, 1)[0])
    assert open(p, "rb").read() == second and len(leftovers(tmp_path)) == 1
    w.abort()
    assert open(p, "rb").read() == second and leftovers(tmp_path) == []
    # an exception inside `with` drops the new frames too
    with pytest.raises(RuntimeError):
        with pc2.Writer(p, 3) as w:
            w.add(frames(3, 1, 1)[0])
            raise RuntimeError("cancelled")
    assert open(p, "rb").read() == second and leftovers(tmp_path) == []


def test_a_path_that_became_something_else_during_the_write_is_kept(tmp_path):
    """The target is checked again when the cache is complete: a long bake must not replace
    a file saved at that path meanwhile."""
    p = tmp_path / "late.pc2"
    w = pc2.Writer(str(p), 2)
    w.add(frames(2, 1, 1)[0])
    p.write_bytes(b"BLENDER saved here meanwhile")
    with pytest.raises(pc2.PC2Error, match="not a point cache"):
        w.close()
    assert p.read_bytes() == b"BLENDER saved here meanwhile" and leftovers(tmp_path) == []


def test_join_never_writes_over_its_inputs_or_other_files(tmp_path):
    a, b = str(tmp_path / "a.pc2"), str(tmp_path / "b.pc2")
    pc2.write(a, frames(5, 1, 4), 5, start=1)
    pc2.write(b, frames(5, 5, 2), 5, start=5)
    ab = open(a, "rb").read(), open(b, "rb").read()
    with pytest.raises(pc2.PC2Error, match="one of the caches being joined"):
        pc2.join([a, b], a)
    other = tmp_path / "notes.txt"
    other.write_text("keep me")
    with pytest.raises(pc2.PC2Error, match="not a point cache"):
        pc2.join([a, b], str(other))
    assert (open(a, "rb").read(), open(b, "rb").read()) == ab
    assert other.read_text() == "keep me" and leftovers(tmp_path) == []
