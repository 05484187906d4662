"""Operator bindings checked against independent numpy/scipy computations."""

import threading
import time

import numpy as np
import pytest
import scipy.linalg
import scipy.sparse
import scipy.sparse.csgraph

import deformkit
from conftest import make_grid, make_icosphere, numpy_edges


def dense(coo, n):
    r, c, v = coo
    return scipy.sparse.csc_matrix((v, (r, c)), shape=(n, n)).toarray()


def numpy_cotangent_laplacian(v, f):
    """Independent assembly: for each triangle corner, cot of its angle goes to the opposite
    edge with weight 1/2."""
    n = len(v)
    L = np.zeros((n, n))
    for tri in f:
        for k in range(3):
            i, j, o = tri[(k + 1) % 3], tri[(k + 2) % 3], tri[k]
            a, b = v[i] - v[o], v[j] - v[o]
            w = 0.5 * np.dot(a, b) / np.linalg.norm(np.cross(a, b))
            L[i, j] -= w
            L[j, i] -= w
            L[i, i] += w
            L[j, j] += w
    return L


def area(v, f):
    return 0.5 * np.linalg.norm(np.cross(v[f[:, 1]] - v[f[:, 0]], v[f[:, 2]] - v[f[:, 0]]),
                                axis=1)


def test_uniform_laplacian():
    v, f = make_grid(4, 3)
    m = deformkit.Mesh(v, f)
    L = dense(deformkit.uniform_laplacian(m), m.n_vertices)
    A = np.zeros_like(L)
    e = numpy_edges(f)
    A[e[:, 0], e[:, 1]] = A[e[:, 1], e[:, 0]] = 1
    np.testing.assert_array_equal(L, np.diag(A.sum(1)) - A)


@pytest.mark.parametrize("mesh", ["grid", "sphere"])
def test_cotangent_laplacian_against_numpy(mesh):
    v, f = make_grid(5, 4, bump=0.3, jitter=0.3) if mesh == "grid" else make_icosphere(1)
    m = deformkit.Mesh(v, f)
    rows, cols, vals = deformkit.cotangent_laplacian(m)
    assert rows.dtype == np.int32 and vals.dtype == np.float64
    L = dense((rows, cols, vals), m.n_vertices)
    np.testing.assert_allclose(L, numpy_cotangent_laplacian(v, f), atol=1e-12)
    w = deformkit.cotangent_weights(m)
    np.testing.assert_allclose(w, -L[m.edges[:, 0], m.edges[:, 1]], atol=1e-12)


def test_cotangent_weights_at_other_positions():
    v, f = make_grid(4, 4, bump=0.2)
    m = deformkit.Mesh(v, f)
    p = v * [1.0, 2.0, 0.5] + 0.1 * np.sin(7 * v[:, [1, 2, 0]])
    Lp = numpy_cotangent_laplacian(p, f)
    np.testing.assert_allclose(deformkit.cotangent_weights(m, p.astype(np.float32)),
                               -Lp[m.edges[:, 0], m.edges[:, 1]], atol=1e-5)
    with pytest.raises(ValueError):
        deformkit.cotangent_weights(m, p[:-1])
    p[3, 2] = np.nan
    with pytest.raises(ValueError, match=r"\b3\b"):
        deformkit.cotangent_weights(m, p)


def test_mass_matrices_sum_to_area():
    v, f = make_grid(6, 5, bump=0.4, jitter=0.4)
    m = deformkit.Mesh(v, f)
    a = area(v, f)
    bary = deformkit.mass_matrix(m, "barycentric")
    expected = np.zeros(len(v))
    for k in range(3):
        np.add.at(expected, f[:, k], a / 3)
    np.testing.assert_allclose(bary, expected, rtol=1e-12)
    vor = deformkit.mass_matrix(m)
    assert vor.sum() == pytest.approx(a.sum(), rel=1e-12) and (vor > 0).all()
    with pytest.raises(ValueError, match="voronoi"):
        deformkit.mass_matrix(m, "lumped")


def test_eigenpairs_on_sphere():
    R = 2.0
    v, f = make_icosphere(3, R)
    m = deformkit.Mesh(v, f)
    evals, evecs = deformkit.laplacian_eigenpairs(m, 16)
    assert evals.shape == (16,) and evecs.shape == (m.n_vertices, 16)
    assert abs(evals[0]) < 1e-8
    expected = np.repeat([l * (l + 1) / R ** 2 for l in range(4)], [1, 3, 5, 7])
    np.testing.assert_allclose(evals[1:], expected[1:], rtol=0.03)
    M = deformkit.mass_matrix(m)
    np.testing.assert_allclose(evecs.T @ (M[:, None] * evecs), np.eye(16), atol=1e-8)
    L = dense(deformkit.cotangent_laplacian(m), m.n_vertices)
    np.testing.assert_allclose(L @ evecs, M[:, None] * evecs * evals, atol=1e-7)


def test_eigenpairs_match_dense_scipy():
    v, f = make_grid(6, 5, bump=0.3, jitter=0.4, seed=3)
    m = deformkit.Mesh(v, f)
    L = dense(deformkit.cotangent_laplacian(m), m.n_vertices)
    M = deformkit.mass_matrix(m, "barycentric")
    ref_vals, ref_vecs = scipy.linalg.eigh(L, np.diag(M))
    evals, evecs = deformkit.laplacian_eigenpairs(m, 10, mass="barycentric", band_size=4)
    np.testing.assert_allclose(evals, ref_vals[:10], atol=1e-8)
    overlap = np.abs(np.sum(evecs * (M[:, None] * ref_vecs[:, :10]), axis=0))
    np.testing.assert_allclose(overlap, 1.0, atol=1e-8)
    with pytest.raises(ValueError, match=r"k must be"):
        deformkit.laplacian_eigenpairs(m, m.n_vertices)


def test_eigen_solve_releases_the_gil():
    m = deformkit.Mesh(*make_icosphere(5))
    out = {}

    def work():
        t0 = time.perf_counter()
        out["pairs"] = deformkit.laplacian_eigenpairs(m, 30)
        out["duration"] = time.perf_counter() - t0

    t = threading.Thread(target=work)
    stamps = [time.perf_counter()]
    t.start()
    while t.is_alive():
        stamps.append(time.perf_counter())
    t.join()
    assert out["duration"] > 0.05
    assert np.diff(stamps).max() < 0.5 * out["duration"]
    assert len(stamps) > 1000


def test_concurrent_eigen_calls_are_serialised_and_correct():
    m = deformkit.Mesh(*make_grid(10, 8, bump=0.2, jitter=0.3))
    ref = deformkit.laplacian_eigenpairs(m, 8)[0]
    results = []
    threads = [threading.Thread(target=lambda: results.append(
        deformkit.laplacian_eigenpairs(m, 8)[0])) for _ in range(3)]
    for t in threads:
        t.start()
    for t in threads:
        t.join()
    assert len(results) == 3
    for r in results:
        np.testing.assert_allclose(r, ref, atol=1e-9)


def test_heat_geodesic_against_great_circle():
    v, f = make_icosphere(4)
    m = deformkit.Mesh(v, f)
    d = deformkit.geodesic_distance(m, [0])
    exact = np.arccos(np.clip(v @ v[0], -1, 1))
    far = exact > 0.2
    assert np.mean(np.abs(d[far] - exact[far]) / exact[far]) < 0.03
    heat = deformkit.HeatGeodesic(m, 1.0)
    np.testing.assert_allclose(heat.distance(0), d, atol=1e-10)
    assert heat.mesh is m
    d2 = heat.distance([0, 5])
    assert d2[5] == pytest.approx(0, abs=1e-9) or d2[5] < 0.05


def test_dijkstra_and_hops_match_scipy():
    v, f = make_grid(7, 5, bump=0.3, jitter=0.3)
    m = deformkit.Mesh(v, f)
    e = m.edges
    w = np.linalg.norm(v[e[:, 0]] - v[e[:, 1]], axis=1)
    G = scipy.sparse.coo_matrix((w, (e[:, 0], e[:, 1])), shape=(len(v),) * 2)
    ref = scipy.sparse.csgraph.dijkstra(G, directed=False, indices=[0, 9]).min(axis=0)
    np.testing.assert_allclose(deformkit.geodesic_distance(m, [0, 9], method="dijkstra"), ref,
                               rtol=1e-14)
    hops = scipy.sparse.csgraph.dijkstra(G, directed=False, indices=3, unweighted=True)
    np.testing.assert_array_equal(deformkit.geodesic_distance(m, 3, method="hops"), hops)


def test_geodesic_errors():
    m = deformkit.Mesh(*make_grid(2, 2))
    with pytest.raises(IndexError, match=r"sources"):
        deformkit.geodesic_distance(m, [100])
    with pytest.raises(ValueError, match=r"empty"):
        deformkit.geodesic_distance(m, [], method="dijkstra")
    with pytest.raises(ValueError, match=r"method"):
        deformkit.geodesic_distance(m, [0], method="exact")
    with pytest.raises(ValueError):
        deformkit.HeatGeodesic(m, -1.0)


def test_knn_against_brute_force():
    rng = np.random.default_rng(5)
    pts, q = rng.normal(size=(300, 3)), rng.normal(size=(40, 3)).astype(np.float32)
    idx, d2 = deformkit.knn(pts, q, 5)
    full = ((q.astype(float)[:, None, :] - pts[None]) ** 2).sum(-1)
    ref = np.argsort(full, axis=1, kind="stable")[:, :5]
    np.testing.assert_array_equal(idx, ref)
    np.testing.assert_allclose(d2, np.take_along_axis(full, ref, 1), rtol=1e-12)
    tree = deformkit.KDTree(pts)
    assert tree.n_points == 300
    i2, _ = tree.query(q, 5)
    np.testing.assert_array_equal(i2, idx)
    with pytest.raises(ValueError, match=r"k must be"):
        tree.query(q, 301)
    with pytest.raises(ValueError):
        deformkit.knn(pts, q, 0)


def test_closest_rotation_against_svd():
    rng = np.random.default_rng(7)
    for A in list(rng.normal(size=(20, 3, 3))) + [np.diag([1.0, 1.0, -1.0]), np.zeros((3, 3))]:
        R = deformkit.closest_rotation(A)
        np.testing.assert_allclose(R @ R.T, np.eye(3), atol=1e-10)
        assert np.linalg.det(R) == pytest.approx(1.0, abs=1e-10)
        U, S, Vt = np.linalg.svd(A)
        D = np.diag([1, 1, np.sign(np.linalg.det(U @ Vt)) or 1])
        ref = U @ D @ Vt
        assert np.trace(R.T @ A) == pytest.approx(np.trace(ref.T @ A), abs=1e-9)
        if S[1] > 1e-6 and S[2] > 1e-6 and abs(S[1] - S[2]) > 1e-6:
            np.testing.assert_allclose(R, ref, atol=1e-8)
    np.testing.assert_allclose(deformkit.closest_rotation(np.zeros(9)), np.eye(3))
    with pytest.raises(ValueError):
        deformkit.closest_rotation(np.full((3, 3), np.nan))
