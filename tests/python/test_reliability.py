"""Issue 18: hostile inputs and the guarantees of docs/reliability.md, class by class.

Each test names the defect class it covers. Run them also under AddressSanitizer (see
docs/reliability.md): a heap overrun in the binding is then a crash, not a silent pass.
"""
import gc
import math
import re
import os
import stat
import threading
import weakref

import numpy as np
import pytest

import deformkit as dk
from deformkit import _native
from conftest import GROUP_METHODS, make_grid, make_icosphere


def info(name):
    return _native._method_info(name)


def cold(name):
    return {"warm_start": False} if info(name)["iterative"] else {}


def grid_scene():
    v, f = make_grid(8, 6, bump=0.1, jitter=0.2)
    left, right = np.where(v[:, 0] <= 1e-9)[0], np.where(v[:, 0] >= 1 - 1e-9)[0]
    row = np.where((v[:, 1] <= 1e-9) & (v[:, 0] > 1e-9) & (v[:, 0] < 1 - 1e-9))[0]
    return v, f, [left, right], row


def lift(v, handles, dz=0.2):
    return np.concatenate([v[h] + [0.0, 0.0, dz * (k + 1)] for k, h in enumerate(handles)])


# ------------------------------------------------------------------------------------------
# Class 1: every Python input read exactly once, into memory the binding owns.

@pytest.mark.parametrize("name", GROUP_METHODS)
def test_rebind_keeps_what_was_bound_not_what_the_caller_changed_since(name):
    """The arguments a rebind leaves out keep their bound values: the caller's arrays,
    changed in place after the bind, change nothing (the object kept the objects and read
    them again at every rebind)."""
    v, f, handles, fixed = grid_scene()
    mesh = dk.Mesh(v, f)
    cold = {"warm_start": False} if dk._native._method_info(name)["iterative"] else {}
    mine = [h.copy() for h in handles]
    fix = fixed.copy()
    m = getattr(dk, name)(mesh, handles=mine, fixed=fix)
    want = np.asarray(m.solve(lift(v, handles), **cold).positions)
    fix[:] = fix[0]           # in place, after the bind
    mine[0][:] = mine[0][0]
    m.rebind(handles=[h.copy() for h in handles])   # the fixed set left out
    got = np.asarray(m.solve(lift(v, handles), **cold).positions)
    np.testing.assert_allclose(got, want, atol=1e-9)
    m.rebind(fixed=fixed.copy())                       # the handles left out
    got = np.asarray(m.solve(lift(v, handles), **cold).positions)
    np.testing.assert_allclose(got, want, atol=1e-9)


class CountingIndex:
    """An int-like whose __index__ runs Python code: on every call after the first it calls
    `mutate` (which changes the caller's containers while the binding is reading them)."""

    def __init__(self, value, mutate):
        self.value, self.mutate, self.calls = value, mutate, 0

    def __index__(self):
        self.calls += 1
        if self.calls > 1:
            self.mutate()
        return self.value


@pytest.mark.parametrize("name", GROUP_METHODS)
@pytest.mark.parametrize("how", ["grow", "shrink"])
def test_handle_groups_read_once_while_python_mutates_them(name, how):
    """The handle-group reader summed the groups' sizes in one pass and copied them in a
    second: an __index__ that grows a later group between the passes overran the heap
    buffer (ASan: heap-buffer-overflow), one that shrinks it passed uninitialised memory as
    vertex indices. Now each group is read once: __index__ runs once, and the bind sees the
    groups as they were when read."""
    v, f, (left, right), row = grid_scene()
    g1 = [int(i) for i in right]
    extra = [int(i) for i in row]

    def mutate():
        if how == "grow":
            g1.extend(extra * 50)
        else:
            del g1[:]

    hostile = CountingIndex(int(left[0]), mutate)
    g0 = [hostile] + [int(i) for i in left[1:]]
    m = getattr(dk, name)(dk.Mesh(v, f), handles=[g0, g1], fixed=row)
    assert hostile.calls == 1
    assert m.n_handle_vertices == len(left) + len(right)
    r = m.solve(lift(v, [left, right]), **cold(name))
    assert np.isfinite(r.positions).all()


class MutatingList(list):
    """A list whose __len__ mutates `victim` (the outer handle list) each time it is asked."""

    def __init__(self, items, victim_box):
        super().__init__(items)
        self.victim_box = victim_box
        self.len_calls = 0

    def __len__(self):
        self.len_calls += 1
        victim = self.victim_box[0]
        if victim is not None:
            if self.len_calls % 2:
                victim.append(list(range(5)))
            elif len(victim) > 1:
                victim.pop()
        return super().__len__()


@pytest.mark.parametrize("name", GROUP_METHODS)
def test_len_that_mutates_the_outer_handle_list(name):
    v, f, (left, right), row = grid_scene()
    box = [None]
    outer = [MutatingList([int(i) for i in left], box), [int(i) for i in right]]
    box[0] = outer
    m = getattr(dk, name)(dk.Mesh(v, f), handles=outer, fixed=row)
    assert m.n_handles == 2
    assert m.n_handle_vertices == len(left) + len(right)


def test_handle_weights_and_fixed_read_once():
    v, f, (left, right), row = grid_scene()
    g1 = [int(i) for i in right]
    weights = [1.0, None]

    class Weight(float):
        calls = 0

        def __float__(self):
            Weight.calls += 1
            g1.extend([int(i) for i in row])   # changes a group already read
            weights.append(0.5)                # and the weight list being read
            return 0.75

    weights[1] = Weight(0.75)
    m = dk.ARAP(dk.Mesh(v, f), handles=[list(left), g1], fixed=row, handle_weights=weights)
    assert m.n_handle_vertices == len(left) + len(right)
    m.solve(lift(v, [left, right]))


@pytest.mark.parametrize("how", ["grow", "shrink"])
def test_coordinate_rows_read_once(how):
    """Nested coordinate sequences: every row is copied before the shape is decided, so a
    __float__ that changes the rows cannot make the shape and the data disagree."""
    v, f = make_grid(3, 3)
    rows = [list(map(float, p)) for p in v]

    class Coord(float):
        def __float__(self):
            if how == "grow":
                for r in rows:
                    r.append(1.0)
                rows.append([0.0, 0.0, 0.0])
            else:
                for r in rows[1:]:
                    del r[:]
                del rows[2:]
            return 0.0

    rows[0][0] = Coord(0.0)
    mesh = dk.Mesh(rows, f)
    np.testing.assert_array_equal(mesh.vertices[1:], v[1:])


def test_cholesky_b_read_once():
    n = 4
    r = np.arange(n, dtype=np.int32)
    chol = dk.SparseCholesky(r, r, np.full(n, 2.0), n)
    np.testing.assert_allclose(chol.solve(np.ones(n)), np.full(n, 0.5))
    np.testing.assert_allclose(chol.solve(np.ones((n, 2))), np.full((n, 2), 0.5))
    np.testing.assert_allclose(chol.solve([[1.0], [1.0], [1.0], [1.0]]), np.full((n, 1), 0.5))


def test_embedded_cut_read_once():
    """cut=(a, b) is copied once; a pair whose length changes as it is asked is read as it
    was at that one read (here: a third group appeared, which is refused)."""
    v, f, (left, right), row = grid_scene()

    class Pair(list):
        def __len__(self):
            self.append([0])
            return super().__len__()

    mesh = dk.Mesh(v, f)
    with pytest.raises(ValueError, match="cut must be a pair"):
        dk.EmbeddedDeformation(mesh, handles=[left, right], n_nodes=20,
                               cut=Pair([list(left), list(right)]))
    m = dk.EmbeddedDeformation(mesh, handles=[left], n_nodes=20,
                               cut=(list(left), list(right)))
    assert m.n_handles == 1


# ------------------------------------------------------------------------------------------
# Class 9: real inputs must be floating-point, indices integers; a TypeError names the
# argument and the format found.

def _raw_bytes(a):
    return memoryview(np.ascontiguousarray(a, dtype=np.float64).tobytes())


def _entries():
    """(label, argument name, call(bad_value)) for every public entry that takes a real
    buffer; each call gives the good value for every argument but the one tested."""
    v, f, (left, right), row = grid_scene()
    mesh = dk.Mesh(v, f)
    hv = len(left) + len(right)
    out = [
        ("Mesh vertices", "vertices", lambda x: dk.Mesh(x, f)),
        ("Mesh.from_polygons vertices", "vertices",
         lambda x: dk.Mesh.from_polygons(x, np.full(len(f), 3), f.ravel())),
        ("knn points", "points", lambda x: dk.knn(x, v[:3], 1)),
        ("KDTree points", "points", lambda x: dk.KDTree(x)),
        ("closest_rotation", "A", lambda x: dk.closest_rotation(x)),
        ("SparseCholesky values", "values",
         lambda x: dk.SparseCholesky(np.arange(3), np.arange(3), x, 3)),
    ]
    tree = dk.KDTree(v)
    out.append(("KDTree.query queries", "queries", lambda x: tree.query(x, 1)))
    out.append(("cotangent_weights positions", "positions",
                lambda x: dk.cotangent_weights(mesh, x)))
    out.append(("harmonic_material values", "values",
                lambda x: dk.harmonic_material(mesh, [0, 1, 2], x)))
    chol = dk.SparseCholesky(np.arange(3), np.arange(3), np.full(3, 2.0), 3)
    out.append(("SparseCholesky.solve b", "b", lambda x: chol.solve(x)))
    out.append(("SparseCholesky.refactorize values", "values", lambda x: chol.refactorize(x)))
    out.append(("ARAP stiffness", "stiffness",
                lambda x: dk.ARAP(mesh, handles=[left, right], stiffness=x)))
    out.append(("LinearReconstruction material", "material",
                lambda x: dk.LinearReconstruction(mesh, handles=[left, right], material=x)))
    ed = dk.EmbeddedDeformation(mesh, handles=[left, right], n_nodes=20)
    out.append(("EmbeddedDeformation.normals", "normals", lambda x: ed.normals(x)))
    out.append(("EmbeddedDeformation.update_source", "positions",
                lambda x: ed.update_source(x)))
    out.append(("EmbeddedDeformation.embed", "points", lambda x: ed.embed(x)))
    eig = dk.EigenDeformation(mesh, handles=[left, right])
    out.append(("EigenDeformation translation", "translation",
                lambda x: eig.solve(translation=x)))
    out.append(("EigenDeformation rotation", "rotation", lambda x: eig.solve(rotation=x)))
    for name in GROUP_METHODS:
        cls = getattr(dk, name)
        m = cls(mesh, handles=[left, right], fixed=row)
        out += [
            ("%s targets" % name, "targets", lambda x, m=m: m.solve(x)),
            ("%s transforms" % name, "transforms", lambda x, m=m: m.solve(transforms=x)),
            ("%s energy" % name, "positions", lambda x, m=m: m.energy(x)),
            ("%s handle_weights" % name, "handle_weights",
             lambda x, cls=cls: cls(mesh, handles=[left], handle_weights=x)),
        ]
    return out, v, hv


ENTRIES, _V, _HV = _entries()


def _good_shape(label):
    if "material" in label:
        return (len(dk.Mesh(_V, grid_scene()[1]).edges),)
    if "harmonic" in label or "SparseCholesky" in label:
        return (3,)
    if "stiffness" in label:
        return (len(_V),)
    if "translation" in label:
        return (3,)
    if "rotation" in label:
        return (3, 3)
    if "embed" in label and "update" not in label:
        return (4, 3)
    if "targets" in label:
        return (_HV, 3)
    if "transforms" in label:
        return (2, 4, 4)
    if "closest_rotation" in label:
        return (3, 3)
    if "SparseCholesky" in label:
        return (3,)
    if "handle_weights" in label:
        return (int((_V[:, 0] <= 1e-9).sum()),)
    if "query" in label or "knn" in label or "KDTree" in label:
        return (4, 3)
    return _V.shape


@pytest.mark.parametrize("label,arg,call", ENTRIES, ids=[e[0] for e in ENTRIES])
@pytest.mark.parametrize("kind", ["raw bytes", "int64", "complex"])
def test_real_inputs_refuse_other_formats(label, arg, call, kind):
    shape = _good_shape(label)
    good = np.ones(shape)
    if kind == "raw bytes":
        bad = _raw_bytes(good)            # format 'B', 8 values per float
        pattern = r"buffer format 'B'"
    elif kind == "int64":
        bad = good.astype(np.int64)
        pattern = r"buffer format '[lq]'"
    else:
        bad = good.astype(np.complex128) + 0.5j
        pattern = r"complex"
    with pytest.raises(TypeError, match=r"%s.*%s" % (arg, pattern)):
        call(bad)


def test_complex_scalars_in_sequences_are_refused():
    with pytest.raises(TypeError, match=r"obj\[0, 1\] must be a real number, got complex"):
        _native._read_doubles([[0.0, 1j, 0.0]], -1, 3)
    with pytest.raises(TypeError, match=r"obj\[0, 0\] must be a real number, got complex"):
        _native._read_doubles([np.complex128(1.0), 0.0, 0.0], -1, 3)
    with pytest.raises(TypeError, match=r"obj\[0, 0\] must be a float.*'[lq]'"):
        _native._read_doubles([np.int64(1), 0.0, 0.0], -1, 3)
    # Python ints and floats, numpy float scalars: accepted and read exactly
    np.testing.assert_array_equal(
        _native._read_doubles([1, np.float32(0.5), np.float64(0.25)], -1, 3), [[1, 0.5, 0.25]])


def test_indices_refuse_float_and_complex_buffers():
    v, f, (left, right), row = grid_scene()
    mesh = dk.Mesh(v, f)
    for bad, pattern in [(left.astype(np.float64), "floating-point"),
                         (left.astype(np.complex128), "complex")]:
        with pytest.raises(TypeError, match=r"handle 0.*%s" % pattern):
            dk.ARAP(mesh, handles=[bad])
        with pytest.raises(TypeError, match=r"fixed.*%s" % pattern):
            dk.ARAP(mesh, handles=[left], fixed=bad)
    with pytest.raises(TypeError, match=r"triangles.*floating-point"):
        dk.Mesh(v, f.astype(np.float64))


# ------------------------------------------------------------------------------------------
# Class 2: mesh files are read only when they are regular files, up to a stated size.

@pytest.mark.parametrize("kind", ["dev-zero symlink", "fifo", "directory"])
@pytest.mark.parametrize("reader", ["load_mesh_file", "read_mesh"])
def test_mesh_readers_refuse_non_regular_files(tmp_path, kind, reader):
    """An .obj symlink to /dev/zero was read until memory ran out (the process killed), a
    FIFO blocked forever; each is now a ValueError before anything is read. The test runs
    in a thread with a timeout, so that a regression fails instead of hanging."""
    path = tmp_path / "x.obj"
    if kind == "dev-zero symlink":
        os.symlink("/dev/zero", path)
        want = "character device"
    elif kind == "fifo":
        os.mkfifo(path)
        want = "FIFO"
    else:
        path.mkdir()
        want = "directory"
    result = {}

    def run():
        try:
            getattr(dk, reader)(str(path))
            result["value"] = "returned"
        except BaseException as exc:   # noqa: BLE001 - reported below
            result["value"] = exc

    t = threading.Thread(target=run, daemon=True)
    t.start()
    t.join(10)
    if t.is_alive():
        if kind == "fifo":   # unblock the reader so the process can exit
            with open(path, "w"):
                pass
        pytest.fail("%s(%s) did not return within 10 s" % (reader, kind))
    exc = result["value"]
    assert isinstance(exc, ValueError), exc
    assert want in str(exc) and "only regular mesh files" in str(exc)


def test_mesh_file_symlink_to_a_regular_file_is_followed(tmp_path):
    real = tmp_path / "real.obj"
    real.write_text("v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\n")
    link = tmp_path / "link.obj"
    os.symlink(real, link)
    assert dk.read_mesh(str(link)).n_vertices == 3


def test_obj_index_error_names_the_file_vertex_count(tmp_path):
    bad = tmp_path / "bad.obj"
    bad.write_text("v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 7\n")
    with pytest.raises(IndexError, match=r"line 4: face index 7 is out of range \[1, 3\] "
                                         r"\(the file has 3 vertices\)"):
        dk.read_mesh(str(bad))


# ------------------------------------------------------------------------------------------
# Class 5: objects in reference cycles are collected, with their native resources.

def _threads():
    return len(os.listdir("/proc/self/task"))


class _Holder:
    pass


@pytest.mark.parametrize("name", GROUP_METHODS)
def test_cycles_free_the_object_and_its_helper_thread(name):
    """A method object in a cycle (its remembered handle list holds an object that holds
    it) is collected by gc, and its native part with it: the helper thread some methods
    keep for their two-thread passes ends (the process's thread count returns)."""
    v, f = make_grid(24, 24)         # big enough for the methods' helper threads
    left, right = np.where(v[:, 0] <= 1e-9)[0], np.where(v[:, 0] >= 1 - 1e-9)[0]
    mesh = dk.Mesh(v, f)
    # a first object, freed by reference counting: the BLAS / OpenMP pools the numerics
    # start once per process are running before the count is taken
    getattr(dk, name)(mesh, handles=[left, right]).solve(lift(v, [left, right]), **cold(name))
    gc.collect()
    before = _threads()
    alive = []
    for _ in range(3):
        h = [left, right]
        m = getattr(dk, name)(mesh, handles=h)
        m.solve(lift(v, [left, right]), **cold(name))
        s = _Holder()
        s.method = m
        h.append(s)              # m -> its handles h -> s -> m
        alive.append(weakref.ref(s))
        del m, h, s
    gc.collect()
    assert all(a() is None for a in alive)
    for _ in range(50):          # joined threads leave /proc/self/task promptly
        if _threads() <= before:
            break
        threading.Event().wait(0.02)
    assert _threads() <= before


def test_heat_geodesic_is_tracked_by_the_collector():
    """HeatGeodesic holds its Mesh: it supports the collector (traverse/clear) like every
    type that holds Python references."""
    v, f = make_icosphere(1)
    mesh = dk.Mesh(v, f)
    h = dk.HeatGeodesic(mesh)
    assert gc.is_tracked(h)
    assert any(r is mesh for r in gc.get_referents(h))
    d = h.distance([0])
    assert d[0] == 0 and np.isfinite(d).all()


# ------------------------------------------------------------------------------------------
# Class 8: a call that raised changed nothing.

def _observable(m):
    """Every attribute the object shows (its getters), plus its energy of a fixed pose."""
    out = {}
    for name in dir(type(m)):
        if name.startswith("_"):
            continue
        attr = getattr(type(m), name)
        if callable(attr) and not type(attr).__name__ == "getset_descriptor":
            continue
        value = getattr(m, name)
        out[name] = (np.array(value).copy() if not isinstance(value, (dict, dk.Mesh, str))
                     else value)
    return out


def _same(a, b):
    assert a.keys() == b.keys()
    for k in a:
        if isinstance(a[k], np.ndarray):
            assert a[k].shape == b[k].shape and np.array_equal(a[k], b[k], equal_nan=True), k
        else:
            assert a[k] == b[k] if not isinstance(a[k], dk.Mesh) else a[k] is b[k], k


def _bad_calls(name, v, handles, fixed, hv):
    good = lift(v, handles)
    nh = len(handles)
    extra = {"ARAP": {"tolerance": 0.5}, "VolumetricARAP": {"tolerance": 0.5},
             "EigenDeformation": {"preview": True}}.get(name, {})
    calls = [
        ("NaN targets", lambda m: m.solve(np.full((hv, 3), np.nan), **extra)),
        ("wrong target rows", lambda m: m.solve(np.zeros((hv + 1, 3)), **extra)),
        ("raw-byte targets", lambda m: m.solve(memoryview(good.tobytes()), **extra)),
        ("huge targets", lambda m: m.solve(good * 1e300, **extra)),
        ("non-affine transforms", lambda m: m.solve(transforms=[np.ones((4, 4))] * nh, **extra)),
        ("both inputs", lambda m: m.solve(good, transforms=[np.eye(4)] * nh, **extra)),
        ("unknown keyword", lambda m: m.solve(good, no_such_keyword=1, **extra)),
        ("max_iterations 0", lambda m: m.solve(good, max_iterations=0, **extra)),
        ("rebind: handle out of range", lambda m: m.rebind(handles=[[len(v)]])),
        ("rebind: overlap", lambda m: m.rebind(handles=handles, fixed=handles[0][:1])),
        ("rebind: bad weights", lambda m: m.rebind(handle_weights=[np.full(len(h), 2.0)
                                                                   for h in handles])),
        ("rebind: float indices", lambda m: m.rebind(fixed=np.asarray(fixed, dtype=float))),
        ("energy: wrong shape", lambda m: m.energy(np.zeros((3, 3)))),
        ("energy: NaN", lambda m: m.energy(np.full(v.shape, np.nan))),
    ]
    if name == "ARAP":
        calls.append(("negative tolerance", lambda m: m.solve(good, tolerance=-1.0)))
        calls.append(("NaN tolerance", lambda m: m.solve(good, tolerance=float("nan"))))
    if name == "EigenDeformation":
        calls.append(("bad pivot", lambda m: m.solve(pivot=[0, 0, 0], preview=True)))
    return calls


@pytest.mark.parametrize("name", GROUP_METHODS)
def test_a_call_that_raised_changed_nothing(name):
    """For each method and each way a call can be refused: every getter shows what it
    showed before, energy() of a fixed pose is the same, and the next (warm) solve returns
    bit for bit what it returns on an object that never saw the refused call. Before the
    fix, solve(bad_targets, tolerance=...) kept the tolerance and solve(..., preview=True)
    kept the preview, and ARAP forgot its targets (energy changed)."""
    v, f, handles, fixed = grid_scene()
    hv = sum(len(h) for h in handles)
    mesh = dk.Mesh(v, f)
    first, second = lift(v, handles, 0.1), lift(v, handles, 0.25)
    pose = v + 0.01 * np.sin(np.arange(v.size)).reshape(v.shape)

    def fresh():
        m = getattr(dk, name)(mesh, handles=handles, fixed=fixed)
        m.solve(first)
        return m

    reference = fresh()
    want_energy = reference.energy(pose)
    want_obs = _observable(reference)
    want_next = reference.solve(second)
    for what, call in _bad_calls(name, v, handles, fixed, hv):
        m = fresh()
        with pytest.raises((TypeError, ValueError, IndexError, OverflowError)):
            call(m)
        _same(_observable(m), want_obs)
        assert m.energy(pose) == want_energy, what
        got = m.solve(second)
        assert np.array_equal(got.positions, want_next.positions), what
        assert got.iterations == want_next.iterations, what
        assert got.energy == want_energy or got.energy == want_next.energy, what


# ------------------------------------------------------------------------------------------
# Class 10: no solve or energy returns NaN or Inf without an error.

@pytest.mark.parametrize("name", GROUP_METHODS)
def test_overflowing_targets_fail_clearly_and_the_object_stays_usable(name):
    """Targets of 1e300 were solved into Inf/NaN positions or an infinite energy, returned
    as a result. They are now refused before anything changes (beyond the +-1e75 the
    library computes with); targets just inside that bound either solve to finite
    positions and energy, or fail with an error that says what overflowed. Either way the
    object answers the next ordinary solve as a fresh one does."""
    v, f, handles, fixed = grid_scene()
    mesh = dk.Mesh(v, f)
    m = getattr(dk, name)(mesh, handles=handles, fixed=fixed)
    nh = len(handles)
    with pytest.raises(ValueError, match=r"beyond \+-1e\+75"):
        m.solve(lift(v, handles) * 1e300)
    with pytest.raises(ValueError, match=r"beyond \+-1e\+75|not finite"):
        m.solve(transforms=[np.diag([1e300, 1e300, 1e300, 1.0])] * nh)
    for scale in (1e75, 1e74, 1e60):
        for energy in (True, False):
            try:
                r = m.solve(lift(v, handles) * scale, energy=energy, **cold(name))
            except (ValueError, RuntimeError) as exc:
                assert re.search(r"not finite|energy is (inf|nan)|overflow", str(exc)), exc
            else:
                assert np.isfinite(r.positions).all()
                assert math.isfinite(r.energy) if energy else math.isnan(r.energy)
    good = lift(v, handles, 0.2)
    want = getattr(dk, name)(mesh, handles=handles, fixed=fixed).solve(good, **cold(name))
    got = m.solve(good, **cold(name))
    np.testing.assert_allclose(got.positions, want.positions, atol=1e-12)


@pytest.mark.parametrize("name", GROUP_METHODS)
def test_energy_of_huge_positions_is_an_error_not_inf(name):
    v, f, handles, fixed = grid_scene()
    m = getattr(dk, name)(dk.Mesh(v, f), handles=handles, fixed=fixed)
    m.solve(lift(v, handles))
    try:
        e = m.energy(v * 1e300)
    except ValueError as exc:
        assert "energy is inf" in str(exc) or "overflow" in str(exc)
    else:
        assert math.isfinite(e)


def test_mesh_coordinates_beyond_the_bound_are_refused():
    v, f = make_grid(3, 3)
    big = v.copy()
    big[5, 1] = 1e300
    with pytest.raises(ValueError, match=r"vertex 5 coordinate y is 1e\+300, beyond"):
        dk.Mesh(big, f)


@pytest.mark.parametrize("name", GROUP_METHODS)
def test_huge_meshes_bind_and_solve_finite_or_say_overflow(name):
    """A mesh at the edge of the coordinate bound: the bind's matrices stay finite (no
    'not positive definite' caused by overflow); a result is finite or an error says why."""
    v, f, handles, fixed = grid_scene()
    mesh = dk.Mesh(v * 1e74, f)
    try:
        m = getattr(dk, name)(mesh, handles=handles, fixed=fixed)
        r = m.solve(lift(v, handles) * 1e74, **cold(name))
    except (ValueError, RuntimeError) as exc:
        assert "positive definite" not in str(exc), exc
        assert re.search(r"not finite|energy is (inf|nan)|overflow", str(exc)), exc
    else:
        assert np.isfinite(r.positions).all() and math.isfinite(r.energy)


# ------------------------------------------------------------------------------------------
# Item 11: a conversion error names the argument.

@pytest.mark.parametrize("kw, exc, pattern", [
    (dict(max_iterations=2 ** 80), OverflowError, r"max_iterations is 1208925819614629174706176"),
    (dict(tolerance="x"), TypeError, r"tolerance must be a float, got str"),
    (dict(tolerance=10 ** 400), OverflowError, r"tolerance is 1000.*out of the range of a float"),
])
def test_option_conversion_errors_name_the_argument(kw, exc, pattern):
    v, f, handles, fixed = grid_scene()
    with pytest.raises(exc, match=pattern):
        dk.ARAP(dk.Mesh(v, f), handles=handles, **kw)


def test_solve_max_iterations_overflow_names_the_argument():
    v, f, handles, fixed = grid_scene()
    m = dk.ARAP(dk.Mesh(v, f), handles=handles)
    with pytest.raises(OverflowError, match=r"max_iterations is"):
        m.solve(lift(v, handles), max_iterations=2 ** 80)


def test_singular_systems_name_the_callers_vertex_not_a_matrix_column():
    """Item 11: 'positivity lost at pivot 0 (matrix column 41)' named the solver's internal
    column; the message now names the caller's vertex, and suggests clamped weights only
    when they are not already in use."""
    vd = np.array([[0, 0, 0], [1, 0, 0], [2, 0, 0], [3, 0, 0.0], [9, 9, 9]])
    fd = np.array([[0, 1, 2], [1, 2, 3]])
    for order in ([0, 1, 2, 3, 4], [4, 3, 2, 1, 0], [2, 4, 0, 3, 1]):
        p = np.asarray(order)          # new vertex k is old vertex p[k]
        ip = np.argsort(p)
        mesh = dk.Mesh(vd[p], ip[fd])
        free = {int(ip[1]), int(ip[2])}
        with pytest.raises(ValueError) as info:
            dk.ARAP(mesh, [[int(ip[0])]], fixed=[int(ip[3])])
        msg = str(info.value)
        assert "matrix column" not in msg and "clamped_cotangent" not in msg, msg
        assert int(re.search(r"at vertex (\d+)", msg).group(1)) in free, msg
        with pytest.raises(ValueError, match=r"try weights='clamped_cotangent'"):
            dk.ARAP(mesh, [[int(ip[0])]], fixed=[int(ip[3])], weights="cotangent")


# ---- getters while another call has the object --------------------------------------------

def _busy_readers(name):
    """The getters of `name` that read the native object."""
    own = {"ARAP": ["handle_sizes"], "Falloff": ["ranges"],
           "EmbeddedDeformation": ["nodes", "transforms", "edges", "fixed_nodes"],
           "LinearReconstruction": ["frames", "transform_basis"]}
    return ["stats", "n_handles", "n_handle_vertices", "warnings"] + own.get(name, [])


@pytest.mark.parametrize("name", ["ARAP", "LaplacianEdit", "Falloff", "EmbeddedDeformation",
                                  "LinearReconstruction"])
def test_getters_refuse_while_a_rebind_runs(name):
    """A rebind (or solve) in another thread releases the GIL and frees and rebuilds what the
    getters read (the constraint sets, the deformation graph): a getter then read freed
    memory. Now it raises "in use by another thread". The rebind's progress callback runs
    while the object is in use, which makes the situation deterministic here (the callback
    runs on the rebind's own thread, which the message says)."""
    v, f = make_grid(24)
    mesh = dk.Mesh(v, f)
    cols = np.arange(len(v)) % 25
    fixed, handle, other = (np.flatnonzero(cols <= 1), np.flatnonzero(cols >= 23),
                            np.flatnonzero(cols == 12))
    kw = {} if name == "Falloff" else dict(fixed=fixed)
    obj = getattr(dk, name)(mesh, handles=[handle], **kw)
    readers = _busy_readers(name)
    before = {r: repr(getattr(obj, r)) for r in readers}
    seen = []

    def progress(fraction):
        for r in readers:
            with pytest.raises(RuntimeError, match="in use by a call on this same thread"):
                getattr(obj, r)
        seen.append(fraction.phase)
        return False

    obj.rebind(handles=[other], progress=progress)
    assert seen
    after = {r: repr(getattr(obj, r)) for r in readers}  # readable again, and rebound
    assert after["n_handle_vertices"] == repr(len(other)) != before["n_handle_vertices"]


# ---- the second hostile review: arguments that cannot work say so -------------------------

@pytest.mark.parametrize("name", list(GROUP_METHODS))
@pytest.mark.parametrize("flag", ["preview", "warm_start", "resume", "energy"])
def test_a_flag_takes_a_bool_not_any_truthy_object(name, flag):
    """solve's flags took any object by its truth: preview="no" previewed. True/False,
    numpy bools and 0/1 are flags; a string, None or 2 is a TypeError naming the flag."""
    v, f = make_grid(8)
    cols = np.arange(len(v)) % 9
    handle, fixed = np.flatnonzero(cols >= 7), np.flatnonzero(cols <= 1)
    kw = {"n_eigenvectors": 8, "refine": 0} if name == "EigenDeformation" else {}
    if name != "EigenDeformation":
        kw["fixed"] = fixed
    m = getattr(dk, name)(dk.Mesh(v, f), handles=[handle], **kw)
    for bad in ("no", None, 2, "False"):
        with pytest.raises(TypeError, match="%s must be True or False" % flag):
            m.solve(v[handle], **{flag: bad})
    for good in (False, np.bool_(False), 0):
        m.solve(v[handle], **{flag: good})


def test_nan_normals_are_refused():
    """EmbeddedDeformation.normals(NaN) returned zero vectors; now a ValueError names the
    vertex."""
    v, f = make_grid(8)
    cols = np.arange(len(v)) % 9
    m = dk.EmbeddedDeformation(dk.Mesh(v, f), handles=[np.flatnonzero(cols >= 7)], n_nodes=10)
    n = np.tile([0.0, 0.0, 1.0], (len(v), 1))
    assert np.isfinite(np.asarray(m.normals(n))).all()
    n[5, 1] = np.nan
    with pytest.raises(ValueError, match="normal of vertex 5 is not finite"):
        m.normals(n)


BAD_OPTIONS = {
    "ARAP": [{"tolerance": float("nan")}, {"tolerance": -1.0}, {"max_iterations": -5}],
    "LaplacianEdit": [{"constraint_weight": -1.0}, {"tikhonov": float("nan")}],
    "Falloff": [{"range": -1.0}, {"range": float("nan")}, {"k": float("inf")}],
    "EmbeddedDeformation": [{"n_nodes": -1}, {"tolerance": float("nan")}, {"k": 0},
                            {"w_reg": -1.0}, {"radius": float("nan")}],
    "EigenDeformation": [{"n_eigenvectors": -1}, {"bsw_width": 0.0}, {"refine": -3}],
    "LinearReconstruction": [{"w": -1.0}, {"w": float("nan")}],
    "Shepard": [{"power": 0.0}, {"power": float("nan")}, {"k": 0}, {"radius": -1.0}],
    "ShapeMatching": [{"alpha": float("nan")}, {"substeps": 0}, {"cluster_size": -1.0},
                      {"damping": -1.0}, {"time_step": 0.0}],
    "ShapeInterpolation": [{"rotations": "spiral"}, {"edge_weights": "heat"}],
    "VolumetricARAP": [{"quality": 0.5}, {"quality": float("nan")}, {"max_volume": -1.0},
                       {"tolerance": float("nan")}, {"cg_iterations": 0}],
}


@pytest.mark.parametrize("name", list(GROUP_METHODS))
def test_estimate_memory_refuses_what_the_constructor_refuses(name):
    """estimate_memory accepted options the constructor refused (n_nodes=-1, tolerance=nan,
    ...) and estimated them (the second hostile review). For each bad option the estimate now
    raises what the bind raises."""
    v, f = make_grid(8)
    mesh = dk.Mesh(v, f)
    cols = np.arange(len(v)) % 9
    handle = np.flatnonzero(cols >= 7)
    cls = getattr(dk, name)
    for bad in BAD_OPTIONS[name]:
        with pytest.raises(ValueError):
            cls(mesh, handles=[handle], **bad)
        with pytest.raises(ValueError):
            cls.estimate_memory(mesh, **bad)


def test_a_singular_linear_reconstruction_names_its_cause():
    """LinearReconstruction blamed "constrained vertices on a line, or degenerate triangles"
    when the material map's or w's magnitude made the system singular (the second hostile
    review). The message now names the cause it can see."""
    v, f = make_grid(12, 12, bump=0.1)
    mesh = dk.Mesh(v, f)
    cols = np.arange(len(v)) % 13
    kw = dict(handles=[np.flatnonzero(cols >= 11)], fixed=np.flatnonzero(cols <= 1))
    mat = np.ones(mesh.n_edges)
    mat[: len(mat) // 2] = 1e-14
    with pytest.raises(RuntimeError, match="material map spans 1e-14 to 1.*keep it within"):
        dk.LinearReconstruction(mesh, material=mat, **kw)
    with pytest.raises(RuntimeError, match="w = 1e-20 is too small"):
        dk.LinearReconstruction(mesh, w=1e-20, **kw)
    dk.LinearReconstruction(mesh, material=np.where(mat < 1, 1e-6, 1.0), **kw)  # within range


def test_too_few_nodes_names_what_can_help():
    """EmbeddedDeformation with fewer nodes than k + 1 said "raise n_nodes", which cannot
    help where the nodes are already capped by the mesh's vertices (the second hostile
    review): there it says to lower k."""
    v = np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0], [0, 0, 1]], float)
    f = np.array([[0, 2, 1], [0, 1, 3], [0, 3, 2], [1, 2, 3]])
    mesh = dk.Mesh(v, f)
    with pytest.raises(ValueError, match=r"4 nodes, but k = 4 needs at least 5 \(lower k to 3"):
        dk.EmbeddedDeformation(mesh, handles=[[0]], n_nodes=50)
    dk.EmbeddedDeformation(mesh, handles=[[0]], n_nodes=50, k=3)
    big, bf = make_grid(8)
    with pytest.raises(ValueError, match="raise n_nodes or lower the radius, or lower k to 2"):
        dk.EmbeddedDeformation(dk.Mesh(big, bf), handles=[[0]], n_nodes=3)
