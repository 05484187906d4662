"""Input conversion (buffers of every dtype and layout, sequences), output arrays, the status
to exception mapping and SolveResult, checked through the module's private helpers and Mesh."""

import array
import subprocess
import sys
import textwrap

import numpy as np
import pytest

import deformkit
from deformkit import _native

REF = np.arange(12, dtype=np.float64).reshape(4, 3) * 0.5 - 1.0


@pytest.mark.parametrize("dtype", [np.float32, np.float64, ">f8", "<f4"])
def test_doubles_from_every_floating_dtype(dtype):
    src = (np.arange(12).reshape(4, 3) * 2).astype(dtype)
    out = _native._read_doubles(src, -1, 3)
    assert isinstance(out, np.ndarray) and out.dtype == np.float64 and out.shape == (4, 3)
    np.testing.assert_array_equal(out, src.astype(np.float64))


@pytest.mark.parametrize("dtype", [np.int8, np.int16, np.int32, np.int64, np.uint8,
                                   np.uint16, np.uint32, np.uint64, np.bool_])
def test_real_inputs_refuse_integer_buffers(dtype):
    """Issue 18, class 9: coordinates are floating-point. An integer (or raw byte) buffer was
    read value by value as if it were coordinates; now it is a TypeError naming the argument
    and the format found."""
    src = (np.arange(12).reshape(4, 3) % 2).astype(dtype)
    with pytest.raises(TypeError, match=r"obj(:| must hold floating-point).*buffer format '.+'"):
        _native._read_doubles(src, -1, 3)


def test_float32_values_are_exact_conversions():
    src = np.array([[0.1, 1e-30, -3.5]], dtype=np.float32)
    out = _native._read_doubles(src, 1, 3)
    np.testing.assert_array_equal(out, src.astype(np.float64))


@pytest.mark.parametrize("dtype", [np.int32, np.int64, np.int16, np.uint8, np.uint32,
                                   np.uint64])
def test_indices_from_integer_dtypes(dtype):
    src = np.arange(9, dtype=dtype).reshape(3, 3)
    out = _native._read_indices(src, -1, 3)
    assert out.dtype == np.int32
    np.testing.assert_array_equal(out, src.astype(np.int64))


@pytest.mark.parametrize("make", [
    lambda a: a[:, ::-1],                       # negative column stride
    lambda a: a[::-1],                          # negative row stride
    lambda a: a[::2],                           # row step
    lambda a: np.asfortranarray(a),             # column-major
    lambda a: a.T.copy().T,                     # transposed view of a transpose
    lambda a: np.repeat(a, 2, axis=1)[:, ::2],  # column step
])
def test_non_contiguous_views(make):
    base = np.arange(30, dtype=np.float64).reshape(10, 3) * 1.25
    view = make(base)
    np.testing.assert_array_equal(_native._read_doubles(view, -1, 3), np.ascontiguousarray(view))
    iview = make(np.arange(30, dtype=np.int64).reshape(10, 3))
    np.testing.assert_array_equal(_native._read_indices(iview, -1, 3), iview)


def test_column_slice_of_wider_array():
    wide = np.arange(40, dtype=np.float32).reshape(8, 5)
    np.testing.assert_array_equal(_native._read_doubles(wide[:, 1:4], -1, 3), wide[:, 1:4])


def test_byte_swapped_arrays():
    big = np.arange(6, dtype=">f8").reshape(2, 3) + 0.25
    np.testing.assert_array_equal(_native._read_doubles(big, -1, 3), big.astype("<f8"))
    bigi = np.arange(6, dtype=">i4").reshape(2, 3) - 2
    np.testing.assert_array_equal(_native._read_indices(bigi, -1, 3), bigi.astype("<i4"))


def test_memoryview_array_array_and_bytes():
    flat = array.array("d", REF.ravel())
    np.testing.assert_array_equal(_native._read_doubles(memoryview(flat), -1, 3), REF)
    np.testing.assert_array_equal(_native._read_doubles(flat, -1, 3), REF)
    f32 = array.array("f", REF.ravel())
    np.testing.assert_array_equal(_native._read_doubles(memoryview(f32), 4, 3), REF)
    shaped = memoryview(flat).cast("B").cast("d", (4, 3))
    np.testing.assert_array_equal(_native._read_doubles(shaped, -1, 3), REF)
    ints = array.array("i", range(9))
    np.testing.assert_array_equal(_native._read_indices(ints, -1, 3),
                                  np.arange(9).reshape(3, 3))
    longs = array.array("q", range(6))
    np.testing.assert_array_equal(_native._read_indices(memoryview(longs), 2, 3),
                                  np.arange(6).reshape(2, 3))
    # bytes export unsigned bytes: each byte is one value
    np.testing.assert_array_equal(_native._read_indices(bytes([1, 2, 250]), 1, 3), [[1, 2, 250]])


def test_nested_sequences():
    rows = [[float(x) for x in r] for r in REF]
    np.testing.assert_array_equal(_native._read_doubles(rows, -1, 3), REF)
    np.testing.assert_array_equal(_native._read_doubles(tuple(map(tuple, rows)), -1, 3), REF)
    np.testing.assert_array_equal(_native._read_doubles(list(REF), -1, 3), REF)  # numpy rows
    np.testing.assert_array_equal(_native._read_doubles(REF.ravel().tolist(), -1, 3), REF)
    np.testing.assert_array_equal(_native._read_indices([[0, 1, 2], (3, 4, 5)], -1, 3),
                                  [[0, 1, 2], [3, 4, 5]])
    np.testing.assert_array_equal(_native._read_indices([np.int64(4), True, 7], -1, 0), [4, 1, 7])
    assert _native._read_doubles([], -1, 3).shape == (0, 3)


def test_one_dimensional_requests():
    np.testing.assert_array_equal(_native._read_doubles(np.arange(5.0), -1, 0), np.arange(5))
    np.testing.assert_array_equal(_native._read_doubles(list(range(5)), -1, 0), np.arange(5))
    np.testing.assert_array_equal(_native._read_indices(np.arange(5).reshape(5, 1), -1, 0),
                                  np.arange(5))
    with pytest.raises(ValueError, match=r"must be 1-D"):
        _native._read_indices(np.zeros((2, 2), dtype=np.int32), -1, 0)


@pytest.mark.parametrize("obj, rows, cols, exc, pattern", [
    (np.zeros((4, 2)), -1, 3, ValueError, r"must have 3 columns, got 2"),
    (np.zeros(7), -1, 3, ValueError, r"multiple of 3 values, got 7"),
    (np.zeros((4, 3)), 5, 3, ValueError, r"must have 5 rows, got 4"),
    (np.zeros((2, 2, 3)), -1, 3, ValueError, r"1-D or 2-D"),
    (np.float64(3.0), -1, 3, (ValueError, TypeError), r"scalar|array|sequence"),
    ([[1, 2, 3], [4, 5]], -1, 3, ValueError, r"row 1 has 2 values, expected 3"),
    (np.array([["a", "b", "c"]]), -1, 3, TypeError, r"obj: unsupported element type"),
    (np.array([[1, 2, 3]], dtype=object).astype(str).astype(object), -1, 3, TypeError,
     r"obj\[0, 0\] must be a number, got str"),
    ([["x", 1, 2]], -1, 3, TypeError, r"obj\[0, 0\] must be a number, got str"),
    ("abc", -1, 3, TypeError, r"got str"),
    (None, -1, 3, TypeError, r"got None"),
    (42, -1, 3, TypeError, r"array or a sequence, got int"),
    ({"a": 1}, -1, 3, TypeError, r"array or a sequence, got dict"),
])
def test_double_reading_errors(obj, rows, cols, exc, pattern):
    with pytest.raises(exc, match=pattern):
        _native._read_doubles(obj, rows, cols)


@pytest.mark.parametrize("obj, exc, pattern", [
    (np.zeros((2, 3)), TypeError, r"must hold integers, got floating-point"),
    (np.zeros((2, 3), dtype=np.float32), TypeError, r"floating-point"),
    ([[0, 1, 2.5]], TypeError, r"obj\[0, 2\] must be an integer, got a float"),
    ([[0, 1, "2"]], TypeError, r"obj\[0, 2\] must be an integer, got str"),
    (np.array([[0, 1, 2**40]]), OverflowError, r"obj\[0, 2\] = 1099511627776 is outside"),
    (np.array([[0, 1, 2**64 - 1]], dtype=np.uint64), OverflowError, r"outside the int32"),
    ([[0, 1, -2**31 - 1]], OverflowError, r"outside the int32"),
    (array.array("d", [0, 1, 2]), TypeError, r"floating-point"),
])
def test_index_reading_errors(obj, exc, pattern):
    with pytest.raises(exc, match=pattern):
        _native._read_indices(obj, -1, 3)


def test_reading_does_not_leak_references_or_buffers():
    a = np.arange(30, dtype=np.float64).reshape(10, 3)
    before = sys.getrefcount(a)
    for _ in range(100):
        _native._read_doubles(a, -1, 3)
        with pytest.raises(ValueError):
            _native._read_doubles(a, 11, 3)
    assert sys.getrefcount(a) == before
    # Every buffer export was released: numpy lets us resize only then.
    b = bytearray(b"\x00" * 24)
    _native._read_doubles(memoryview(b).cast("d"), -1, 3)
    b.extend(b"\x00" * 24)  # would raise BufferError if a view were still held
    assert len(b) == 48


def test_outputs_are_independent_writable_numpy_arrays():
    v = np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0]], dtype=float)
    mesh = deformkit.Mesh(v, [[0, 1, 2]])
    out = mesh.vertices
    assert isinstance(out, np.ndarray) and out.flags.writeable and out.dtype == np.float64
    out[:] = 99.0
    np.testing.assert_array_equal(mesh.vertices, v)
    v[:] = -1.0  # the mesh copied its input too
    assert mesh.vertices[1, 0] == 1.0


def test_memoryview_outputs_without_numpy(tmp_path):
    """With numpy unimportable the module still works and returns shaped memoryviews."""
    script = textwrap.dedent("""
        import sys
        sys.modules['numpy'] = None          # makes 'import numpy' raise ImportError
        import deformkit
        m = deformkit.Mesh([[0, 0, 0], [1, 0, 0], [0, 1, 0], [0, 0, 1]],
                           [[0, 1, 2], [0, 3, 1], [0, 2, 3], [1, 3, 2]])
        v = m.vertices
        assert isinstance(v, memoryview), type(v)
        assert v.shape == (4, 3) and v.format == 'd', (v.shape, v.format)
        assert v.tolist()[1] == [1.0, 0.0, 0.0]
        t = m.triangles
        assert t.shape == (4, 3) and t.format == 'i' and t.tolist()[3] == [1, 3, 2]
        e = m.edges
        assert e.shape == (6, 2)
        b = m.boundary_vertices
        assert b.ndim == 1 and len(b) == 0
        print('ok')
    """)
    res = subprocess.run([sys.executable, "-c", script], capture_output=True, text=True,
                         timeout=60)
    assert res.returncode == 0, res.stderr
    assert res.stdout.strip() == "ok"


@pytest.mark.parametrize("status, exc", [
    (1, ValueError), (2, MemoryError), (3, IndexError), (4, ValueError), (5, ValueError),
    (6, ValueError), (7, RuntimeError), (8, RuntimeError), (9, RuntimeError),
    (10, RuntimeError), (11, RuntimeError),
])
def test_status_mapping(status, exc):
    with pytest.raises(exc) as info:
        _native._raise_status(status, "the message", "Context")
    assert type(info.value) is exc  # not a subclass such as KeyboardInterrupt
    assert str(info.value) == "Context: the message"


def test_status_mapping_without_context():
    with pytest.raises(IndexError, match=r"^face 3 corner 1$"):
        _native._raise_status(3, "face 3 corner 1")
    assert issubclass(IndexError, LookupError)


def test_solve_result_struct_sequence():
    pos = np.zeros((2, 3))
    r = deformkit.SolveResult((pos, 1.5, 7, True))
    assert r.positions is pos and r.energy == 1.5 and r.iterations == 7 and r.converged is True
    positions, energy, iterations, converged = r
    assert (energy, iterations, converged) == (1.5, 7, True)
    assert len(r) == 4 and isinstance(r, tuple)


def test_package_exports():
    assert deformkit.__version__
    for name in ("Mesh", "SolveResult", "load_mesh_file", "read_mesh", "cotangent_laplacian",
                 "uniform_laplacian", "cotangent_weights", "mass_matrix", "geodesic_distance",
                 "HeatGeodesic", "laplacian_eigenpairs", "knn", "KDTree", "closest_rotation"):
        assert name in deformkit.__all__, name
        assert getattr(deformkit, name).__doc__, name
    assert not any(n.startswith("_") for n in deformkit.__all__ if n != "__version__")
    assert deformkit.__doc__ and deformkit._native.__doc__
