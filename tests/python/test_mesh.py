"""deformkit.Mesh: construction from every input kind, validation errors, topology checked
against numpy computations, memory/reference sanity, and the real meshes when present."""

import array
import gc
import sys
import tracemalloc

import numpy as np
import pytest

import deformkit
from conftest import make_grid, make_icosphere, measures_rss, numpy_edges

TET_V = np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0], [0, 0, 1]], dtype=float)
TET_F = np.array([[0, 2, 1], [0, 1, 3], [0, 3, 2], [1, 2, 3]])


# ---------------------------------------------------------------- construction -----------

@pytest.mark.parametrize("vdtype", [np.float32, np.float64])
@pytest.mark.parametrize("fdtype", [np.int32, np.int64])
def test_construct_from_numpy_dtypes(vdtype, fdtype):
    v, f = make_icosphere(1)
    m = deformkit.Mesh(v.astype(vdtype), f.astype(fdtype))
    assert (m.n_vertices, m.n_faces) == (len(v), len(f))
    np.testing.assert_array_equal(m.vertices, v.astype(vdtype).astype(np.float64))
    np.testing.assert_array_equal(m.triangles, f)


def test_construct_from_non_contiguous_slices():
    v, f = make_icosphere(1)
    wide = np.zeros((len(v), 7))
    wide[:, 2:5] = v
    ff = np.zeros((len(f), 6), dtype=np.int64)
    ff[:, ::2] = f
    m = deformkit.Mesh(wide[:, 2:5], ff[:, ::2])
    np.testing.assert_array_equal(m.vertices, v)
    np.testing.assert_array_equal(m.triangles, f)
    rev = deformkit.Mesh(v[::-1], (len(v) - 1 - f)[:, ::-1])
    np.testing.assert_array_equal(rev.vertices, v[::-1])


def test_construct_from_memoryview_array_and_lists():
    v = array.array("f", TET_V.ravel())       # the layout foreach_get fills: flat float32
    f = array.array("i", TET_F.ravel())
    m1 = deformkit.Mesh(memoryview(v), memoryview(f))
    m2 = deformkit.Mesh(v, f)
    m3 = deformkit.Mesh(TET_V.tolist(), TET_F.tolist())
    m4 = deformkit.Mesh(vertices=[tuple(p) for p in TET_V], triangles=[tuple(t) for t in TET_F])
    for m in (m1, m2, m3, m4):
        np.testing.assert_array_equal(m.vertices, TET_V)
        np.testing.assert_array_equal(m.triangles, TET_F)
        assert m.n_edges == 6


def test_point_cloud_without_faces():
    m = deformkit.Mesh(np.random.default_rng(1).normal(size=(5, 3)), np.zeros((0, 3), int))
    assert m.n_faces == 0 and m.n_edges == 0 and m.n_components == 5
    assert m.report["n_isolated_vertices"] == 5


# ---------------------------------------------------------------- validation -------------

def test_index_out_of_range_names_face_and_corner():
    f = TET_F.copy()
    f[2, 1] = 17
    with pytest.raises(IndexError) as info:
        deformkit.Mesh(TET_V, f)
    msg = str(info.value)
    assert "2" in msg and "17" in msg and "face" in msg.lower()


def test_negative_index_is_refused():
    f = TET_F.copy()
    f[3, 0] = -1
    with pytest.raises(IndexError, match=r"-1"):
        deformkit.Mesh(TET_V, f)


@pytest.mark.parametrize("bad", [np.nan, np.inf, -np.inf])
def test_nonfinite_vertex_is_named(bad):
    v = TET_V.copy()
    v[3, 1] = bad
    with pytest.raises(ValueError, match=r"\b3\b"):
        deformkit.Mesh(v, TET_F)


def test_repeated_vertex_in_face():
    f = TET_F.copy()
    f[1] = [0, 1, 0]
    with pytest.raises(ValueError) as info:
        deformkit.Mesh(TET_V, f)
    assert "1" in str(info.value)


@pytest.mark.parametrize("v, f, exc", [
    (np.zeros((4, 2)), TET_F, ValueError),
    (TET_V, TET_F[:, :2], ValueError),
    (TET_V, TET_F.ravel()[:-1], ValueError),
    (TET_V, TET_F.astype(float), TypeError),
    (np.array([["a", "b", "c"]] * 4), TET_F, TypeError),
    ("vertices", TET_F, TypeError),
    (TET_V, None, TypeError),
])
def test_shape_and_type_errors(v, f, exc):
    with pytest.raises(exc):
        deformkit.Mesh(v, f)


def test_wrong_argument_count():
    with pytest.raises(TypeError):
        deformkit.Mesh(TET_V)


def test_polygon_errors():
    quad = np.array([[0, 0, 0], [1, 0, 0], [1, 1, 0], [0, 1, 0]], float)
    with pytest.raises(ValueError):  # fewer than 3 corners
        deformkit.Mesh.from_polygons(quad, [4, 2], [0, 1, 2, 3, 0, 1])
    with pytest.raises((ValueError, IndexError)):  # sizes do not match the index count
        deformkit.Mesh.from_polygons(quad, [4, 4], [0, 1, 2, 3])
    with pytest.raises(IndexError):
        deformkit.Mesh.from_polygons(quad, [4], [0, 1, 2, 9])


# ---------------------------------------------------------------- topology ---------------

def test_icosphere_topology_against_numpy():
    v, f = make_icosphere(2)
    m = deformkit.Mesh(v, f)
    edges = numpy_edges(f)
    assert m.n_edges == len(edges)
    assert m.n_vertices - m.n_edges + m.n_faces == 2  # Euler characteristic of a sphere
    np.testing.assert_array_equal(m.edges, edges)
    assert m.n_components == 1 and len(m.boundary_vertices) == 0
    np.testing.assert_array_equal(m.components, np.zeros(m.n_vertices))
    # edge_faces: both faces on each edge contain both of its vertices
    ef = m.edge_faces
    assert (ef >= 0).all()
    tri = m.triangles
    for k in range(2):
        faces = tri[ef[:, k]]
        for end in range(2):
            assert (faces == m.edges[:, end:end + 1]).any(axis=1).all()
    assert (ef[:, 0] != ef[:, 1]).all()
    lengths = np.linalg.norm(v[edges[:, 0]] - v[edges[:, 1]], axis=1)
    assert m.mean_edge_length == pytest.approx(lengths.mean(), rel=1e-12)
    np.testing.assert_allclose(m.bbox, [v.min(axis=0), v.max(axis=0)], rtol=0, atol=0)
    assert m.bbox_diagonal == pytest.approx(np.linalg.norm(v.max(0) - v.min(0)))
    assert m.report == {"n_degenerate_faces": 0, "n_nonmanifold_edges": 0,
                        "n_isolated_vertices": 0, "n_boundary_edges": 0, "n_components": 1,
                        "first_degenerate_face": -1, "first_nonmanifold_edge": -1,
                        "first_isolated_vertex": -1}


def test_one_rings_against_numpy():
    v, f = make_grid(5, 4)
    m = deformkit.Mesh(v, f)
    edges = numpy_edges(f)
    for vert in range(m.n_vertices):
        expected = np.sort(np.concatenate([edges[edges[:, 0] == vert, 1],
                                           edges[edges[:, 1] == vert, 0]]))
        ring = m.one_ring(vert)
        assert ring.dtype == np.int32
        np.testing.assert_array_equal(ring, expected)
    with pytest.raises(IndexError, match=r"vertex 30 "):
        m.one_ring(30)
    with pytest.raises(IndexError, match=r"vertex -1 "):
        m.one_ring(-1)
    with pytest.raises(TypeError):
        m.one_ring("a")


def test_boundary_and_components_of_two_grids():
    v1, f1 = make_grid(4, 3)
    v2, f2 = make_grid(2, 2)
    v = np.concatenate([v1, v2 + [3, 0, 0]])
    f = np.concatenate([f1, f2 + len(v1)])
    m = deformkit.Mesh(v, f)
    x, y = v[:, 0] % 3, v[:, 1]
    on_border = np.isclose(x, 0) | np.isclose(x, 1) | np.isclose(y, 0) | np.isclose(y, 1)
    np.testing.assert_array_equal(m.boundary_vertices, np.flatnonzero(on_border))
    assert m.n_components == 2
    comp = m.components
    assert len(set(comp[: len(v1)])) == 1 and len(set(comp[len(v1):])) == 1
    assert comp[0] != comp[-1]
    # boundary edges: edges used by exactly one triangle
    e = np.concatenate([f[:, [0, 1]], f[:, [1, 2]], f[:, [2, 0]]])
    e.sort(axis=1)
    _, counts = np.unique(e, axis=0, return_counts=True)
    assert m.report["n_boundary_edges"] == int((counts == 1).sum())
    assert m.report["n_components"] == 2


def test_report_counts_isolated_and_nonmanifold():
    v = np.concatenate([TET_V, [[5, 5, 5], [0.3, 0.3, -1]]])
    f = np.concatenate([TET_F, [[0, 1, 5]]])  # a third face on edge (0, 1)
    m = deformkit.Mesh(v, f)
    assert m.report["n_isolated_vertices"] == 1 and m.report["first_isolated_vertex"] == 4
    assert m.report["n_nonmanifold_edges"] == 1
    nm = m.report["first_nonmanifold_edge"]
    np.testing.assert_array_equal(m.edges[nm], [0, 1])


def test_degenerate_face_reported_not_refused():
    v = np.concatenate([TET_V, [[2, 0, 0]]])
    f = np.concatenate([TET_F, [[0, 1, 4]]])  # collinear corners
    m = deformkit.Mesh(v, f)
    assert m.report["n_degenerate_faces"] == 1 and m.report["first_degenerate_face"] == 4


def test_from_polygons_quads_and_ngons():
    v, _ = make_grid(3, 2)
    quads = []
    for i in range(3):
        for j in range(2):
            quads.append([i * 3 + j, (i + 1) * 3 + j, (i + 1) * 3 + j + 1, i * 3 + j + 1])
    m = deformkit.Mesh.from_polygons(v, [4] * 6, np.array(quads).ravel())
    assert m.n_polygons == 6 and m.n_faces == 12
    fp = m.face_polygon
    np.testing.assert_array_equal(np.bincount(fp), [2] * 6)
    for t, p in zip(m.triangles, fp):
        assert set(t) <= set(quads[p])
    # a regular hexagon fan-free: 4 triangles covering its area
    ang = np.arange(6) * np.pi / 3
    hexv = np.stack([np.cos(ang), np.sin(ang), np.zeros(6)], axis=1)
    h = deformkit.Mesh.from_polygons(hexv, [6], range(6))
    assert h.n_faces == 4 and h.n_polygons == 1
    area = sum(0.5 * np.linalg.norm(np.cross(hexv[b] - hexv[a], hexv[c] - hexv[a]))
               for a, b, c in h.triangles)
    assert area == pytest.approx(3 * np.sqrt(3) / 2)
    assert "n_faces=4" in repr(h) and repr(h).startswith("deformkit.Mesh(")


def test_mesh_get_rejects_non_mesh():
    with pytest.raises(TypeError, match=r"mesh must be a deformkit.Mesh, got list"):
        deformkit.cotangent_laplacian([1, 2, 3])


# ---------------------------------------------------------------- memory -----------------

def _rss_bytes():
    with open("/proc/self/statm") as fh:
        return int(fh.read().split()[1]) * 4096


@measures_rss
def test_repeated_construction_does_not_grow_memory():
    v, f = make_icosphere(3)  # 642 vertices: a leaked mesh is ~100 kB
    bad = f.copy()
    bad[-1, -1] = 10 ** 6
    vref, fref = sys.getrefcount(v), sys.getrefcount(f)
    for _ in range(50):
        deformkit.Mesh(v, f).edges
    gc.collect()
    rss0 = _rss_bytes()
    tracemalloc.start()
    snap0 = tracemalloc.take_snapshot()
    for _ in range(1000):
        m = deformkit.Mesh(v, f)
        m.edges, m.vertices, m.report, m.one_ring(3)
        with pytest.raises(IndexError):
            deformkit.Mesh(v, bad)
    del m
    gc.collect()
    snap1 = tracemalloc.take_snapshot()
    tracemalloc.stop()
    grown = sum(s.size_diff for s in snap1.compare_to(snap0, "filename"))
    assert grown < 200_000, grown  # PyMem buffers (inputs) all released
    assert _rss_bytes() - rss0 < 30_000_000  # native meshes freed (a leak would be ~100 MB)
    assert (sys.getrefcount(v), sys.getrefcount(f)) == (vref, fref)


# ---------------------------------------------------------------- real meshes ------------

def test_beast_ngons_via_from_polygons(shared_mesh):
    path = shared_mesh("beast.obj")
    verts, sizes, idx = deformkit.load_mesh_file(str(path))
    assert verts.shape[1] == 3 and sizes.sum() == len(idx)
    m = deformkit.Mesh.from_polygons(verts, sizes, idx)
    assert m.n_polygons == len(sizes)
    assert m.n_faces == int((sizes - 2).sum())  # every k-gon becomes k - 2 triangles
    np.testing.assert_array_equal(np.bincount(m.face_polygon, minlength=len(sizes)), sizes - 2)


def test_armadillo_vertex_count(shared_mesh):
    m = deformkit.read_mesh(shared_mesh("armadillo.obj"))
    assert m.n_vertices == 43243
    assert m.n_faces > 80000 and m.report["n_nonmanifold_edges"] == 0


def test_load_mesh_file_errors(tmp_path):
    with pytest.raises((ValueError, OSError, RuntimeError)):
        deformkit.load_mesh_file(str(tmp_path / "missing.obj"))
    bad = tmp_path / "bad.obj"
    bad.write_text("v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 7\n")
    with pytest.raises((IndexError, ValueError)):
        deformkit.read_mesh(bad)
