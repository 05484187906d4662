"""deformkit.SparseCholesky against dense and scipy solves: residuals, reuse of the analysis,
one and many right-hand sides, and every refusal (not positive definite, not symmetric,
non-finite values, indices out of range, wrong shapes)."""

import numpy as np
import pytest

import deformkit


def laplacian_plus_diagonal(mesh, d):
    """Cotangent Laplacian + d*I as triplets (both triangles), SPD for d > 0."""
    r, c, v = deformkit.cotangent_laplacian(mesh)
    n = mesh.n_vertices
    return (np.concatenate([r, np.arange(n)]), np.concatenate([c, np.arange(n)]),
            np.concatenate([v, np.full(n, d)]))


def dense(rows, cols, vals, n):
    a = np.zeros((n, n))
    np.add.at(a, (rows, cols), vals)
    return a


def test_small_matrix_equals_dense_solve(grid):
    v, f = grid(6, 5, bump=0.2, jitter=0.3)
    mesh = deformkit.Mesh(v, f)
    r, c, w = laplacian_plus_diagonal(mesh, 0.05)
    n = mesh.n_vertices
    chol = deformkit.SparseCholesky(r, c, w, n)
    a = dense(r, c, w, n)
    b = np.random.default_rng(1).standard_normal((n, 4))
    x = chol.solve(b)
    assert x.shape == (n, 4)
    np.testing.assert_allclose(x, np.linalg.solve(a, b), rtol=1e-10, atol=1e-12)
    x1 = chol.solve(b[:, 2])
    assert x1.shape == (n,)
    np.testing.assert_allclose(x1, x[:, 2], rtol=1e-12, atol=1e-14)
    # memoryview (no numpy on the way in) and a plain list give the same answer
    np.testing.assert_allclose(chol.solve(memoryview(np.ascontiguousarray(b))), x)
    np.testing.assert_allclose(chol.solve(list(b[:, 0])), x[:, 0])


def test_duplicates_are_summed(grid):
    v, f = grid(4, 4)
    mesh = deformkit.Mesh(v, f)
    r, c, w = laplacian_plus_diagonal(mesh, 1.0)
    n = mesh.n_vertices
    # the same matrix with every value split into two halves
    chol = deformkit.SparseCholesky(np.r_[r, r], np.r_[c, c], np.r_[w, w] / 2, n)
    b = np.arange(n, dtype=float)
    np.testing.assert_allclose(chol.solve(b), np.linalg.solve(dense(r, c, w, n), b),
                               rtol=1e-10)


def test_armadillo_residual_and_reused_analysis(shared_mesh):
    v, fs, idx = deformkit.load_mesh_file(str(shared_mesh("armadillo.obj")))
    mesh = deformkit.Mesh.from_polygons(v, fs, idx)
    n = mesh.n_vertices
    r, c, w = deformkit.cotangent_laplacian(mesh)
    # constraint diagonal: a few hundred "fixed" vertices with a large weight, a small
    # regulariser elsewhere (the shape of a soft-constrained Laplacian editing system)
    diag = np.full(n, 1e-6)
    diag[::150] = 1e3
    rows, cols, vals = np.r_[r, np.arange(n)], np.r_[c, np.arange(n)], np.r_[w, diag]
    chol = deformkit.SparseCholesky(rows, cols, vals, n)
    assert chol.n == n
    assert chol.stats["analysis_count"] == 1 and chol.stats["factorization_count"] == 1
    assert chol.stats["factor_bytes"] > 0
    import scipy.sparse as sp
    b = np.random.default_rng(0).standard_normal((n, 3))
    for scale in (1.0, 3.0):
        if scale != 1.0:
            chol.refactorize(vals * scale)
        a = sp.csr_matrix((vals * scale, (rows, cols)), shape=(n, n))
        x = chol.solve(b)
        res = np.linalg.norm(a @ x - b) / np.linalg.norm(b)
        assert res < 1e-10, res
    assert chol.stats["analysis_count"] == 1, "refactorize must reuse the analysis"
    assert chol.stats["factorization_count"] == 2


def test_not_positive_definite_names_column(grid):
    v, f = grid(4, 4)
    mesh = deformkit.Mesh(v, f)
    r, c, w = deformkit.cotangent_laplacian(mesh)  # singular (constants in the kernel)
    n = mesh.n_vertices
    with pytest.raises(RuntimeError, match="positive definite"):
        deformkit.SparseCholesky(r, c, -w - np.where(r == c, 0.1, 0.0), n)
    rr, cc, ww = laplacian_plus_diagonal(mesh, 0.1)
    chol = deformkit.SparseCholesky(rr, cc, ww, n)
    with pytest.raises(RuntimeError, match="positive definite"):
        chol.refactorize(-ww)
    assert chol.stats["analysis_count"] == 1


def test_refusals(grid):
    v, f = grid(3, 3)
    mesh = deformkit.Mesh(v, f)
    r, c, w = laplacian_plus_diagonal(mesh, 0.1)
    n = mesh.n_vertices
    asym = w.copy()
    off = np.flatnonzero(r != c)[0]
    asym[off] += 0.5
    with pytest.raises(ValueError, match="not symmetric"):
        deformkit.SparseCholesky(r, c, asym, n)
    bad = w.copy()
    bad[3] = np.nan
    with pytest.raises(ValueError, match="value 3 is not finite"):
        deformkit.SparseCholesky(r, c, bad, n)
    with pytest.raises(IndexError):
        deformkit.SparseCholesky(np.r_[r, n], np.r_[c, 0], np.r_[w, 1.0], n)
    with pytest.raises(ValueError, match="cols must have"):
        deformkit.SparseCholesky(r, c[:-1], w, n)
    with pytest.raises(ValueError, match="n is 0"):
        deformkit.SparseCholesky(r, c, w, 0)
    with pytest.raises(TypeError):
        deformkit.SparseCholesky(r.astype(float), c, w, n)
    chol = deformkit.SparseCholesky(r, c, w, n)
    with pytest.raises(ValueError, match="rows"):
        chol.solve(np.zeros(n + 1))
    with pytest.raises(ValueError, match="not finite"):
        chol.solve(np.full(n, np.inf))
    # a factor that is fine, a solution that overflows: an error, not inf
    tiny = deformkit.SparseCholesky([0], [0], [1e-300], 1)
    with pytest.raises(RuntimeError, match=r"x\[0, 0\] is not finite"):
        tiny.solve([1e300])
    assert tiny.solve([1e-10])[0] == pytest.approx(1e290)
    with pytest.raises(ValueError, match="values must have"):
        chol.refactorize(w[:-1])
    # a refused call leaves the factor usable
    b = np.ones(n)
    np.testing.assert_allclose(chol.solve(b), np.linalg.solve(dense(r, c, w, n), b),
                               rtol=1e-10)
