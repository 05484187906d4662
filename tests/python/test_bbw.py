"""deformkit.bounded_biharmonic_weights (docs/methods/skinning.md, "Computed weights"):
each handle's quadratic program against an independent bounded least-squares solve in scipy
(the surface domain, where the discretization is the public cotangent Laplacian and mass);
the paper's properties on the volume domain (bounds, partition of unity, interpolation at the
handles, a bone held along its whole segment, smoothness as the biharmonic energy's
optimality); scale and placement; broken meshes (several parts, non-manifold, open); the
Skinning bind that computes them; refusals."""
import numpy as np
import pytest
import scipy.optimize
import scipy.sparse as sp

import deformkit as dk
from conftest import SHARED_MESHES, make_book, make_icosphere
from shapes import capped_tube as capped_cylinder


def check_partition(W, tol=1e-12):
    assert W.min() >= 0.0 and W.max() <= 1.0 + tol
    assert np.abs(W.sum(1) - 1.0).max() < 1e-12


def test_surface_weights_solve_the_papers_program():
    """On the surface the weights are the paper's: for each handle, minimise the discrete
    biharmonic energy x^T L M^-1 L x with x = 1 on the handle, 0 on the others, 0 <= x <= 1,
    then divide by the sum. scipy's bounded least squares (BVLS, an exact active-set method
    of its own) on M^-1/2 L gives the same minimisers."""
    V, F = make_icosphere(2)
    V = V * np.array([1.0, 0.7, 0.5])  # not a sphere: no symmetry to hide an error
    m = dk.Mesh(V, F)
    handles = np.array([0, 50, 100, 150])
    W, rep = dk.bounded_biharmonic_weights(m, points=V[handles], domain="surface", report=True)
    assert rep["domain"] == "surface" and rep["kkt_residual"] < 1e-7
    r, c, v = dk.cotangent_laplacian(m)
    n = len(V)
    L = sp.csr_matrix((v, (r, c)), shape=(n, n))
    mass = np.asarray(dk.mass_matrix(m, "barycentric"))
    R = sp.diags(1.0 / np.sqrt(mass)) @ L
    free = np.setdiff1d(np.arange(n), handles)
    raw = np.zeros((n, len(handles)))
    for j, hv in enumerate(handles):
        held = np.zeros(n)
        held[hv] = 1.0
        res = scipy.optimize.lsq_linear(R[:, free].toarray(), -R @ held, bounds=(0.0, 1.0),
                                        method="bvls", tol=1e-14)
        raw[:, j] = held
        raw[free, j] = res.x
    ref = raw / raw.sum(1, keepdims=True)
    assert np.abs(W - ref).max() < 1e-6
    check_partition(W)
    np.testing.assert_allclose(W[handles], np.eye(len(handles)), atol=1e-12)


def test_volume_weights_are_bounded_interpolating_and_smooth():
    V, F = capped_cylinder()
    m = dk.Mesh(V, F)
    pts = np.array([[-0.9, 0, 0], [0.0, 0, 0], [0.9, 0, 0]])
    W, rep = dk.bounded_biharmonic_weights(m, points=pts, report=True)
    assert rep["domain"] == "volume" and rep["kkt_residual"] < 1e-6
    check_partition(W)
    # each handle's weight falls off along the tube, the nearest handle dominating
    x = V[:, 0]
    assert np.all(W[x < -0.8, 0] > 0.9) and np.all(W[x > 0.8, 2] > 0.9)
    assert np.all(W[np.abs(x) < 0.05, 1] > 0.9)
    # along the tube (one ring angle) the middle weight rises then falls: no wiggles
    ring = np.arange(0, len(V) - 2, 16)
    w1 = W[ring, 1]
    top = np.argmax(w1)
    assert np.all(np.diff(w1[:top + 1]) >= -1e-9) and np.all(np.diff(w1[top:]) <= 1e-9)


def test_a_bone_holds_its_whole_segment_and_joints_are_shared():
    V, F = capped_cylinder(n_len=41)
    m = dk.Mesh(V, F)
    bones = np.array([[[-1.0, 0, 0], [0.0, 0, 0]], [[0.0, 0, 0], [1.0, 0, 0]]])
    # vertices placed on the bones' axis: the caps' centres lie on the bones' outer ends
    W = dk.bounded_biharmonic_weights(m, bones=bones)
    check_partition(W)
    assert W[len(V) - 2, 0] == pytest.approx(1.0, abs=1e-9)
    assert W[len(V) - 1, 1] == pytest.approx(1.0, abs=1e-9)
    x = V[:, 0]
    assert np.all(W[x < -0.5, 0] > 0.9) and np.all(W[x > 0.5, 1] > 0.9)
    # the joint is shared: the ring around it weighs both bones about equally
    mid = np.abs(x) < 1e-9
    assert np.all(np.abs(W[mid, 0] - 0.5) < 0.1)


def test_a_mesh_facing_inwards_still_has_its_volume():
    V, F = capped_cylinder()
    pts = np.array([[-0.9, 0, 0], [0.3, 0, 0]])
    W, rep = dk.bounded_biharmonic_weights(dk.Mesh(V, F), points=pts, report=True)
    Wi, repi = dk.bounded_biharmonic_weights(dk.Mesh(V, F[:, ::-1]), points=pts, report=True)
    assert rep["domain"] == repi["domain"] == "volume"
    assert np.abs(Wi - W).max() < 1e-9


def test_same_weights_at_any_scale_and_place():
    V, F = capped_cylinder()
    pts = np.array([[-0.9, 0, 0], [0.3, 0, 0]])
    W = dk.bounded_biharmonic_weights(dk.Mesh(V, F), points=pts)
    for s, t in ((1e-3, (5.0, -2.0, 1.0)), (1e3, (-4e3, 1e3, 7.0))):
        Ws = dk.bounded_biharmonic_weights(dk.Mesh(V * s + t, F), points=pts * s + t)
        assert np.abs(Ws - W).max() < 1e-3


def test_open_and_flat_meshes_take_the_surface():
    n = 12
    xs, ys = np.meshgrid(np.linspace(0, 1, n), np.linspace(0, 1, n), indexing="ij")
    V = np.stack([xs.ravel(), ys.ravel(), np.zeros(n * n)], 1)
    F = []
    for i in range(n - 1):
        for j in range(n - 1):
            a, b, c, d = i * n + j, (i + 1) * n + j, (i + 1) * n + j + 1, i * n + j + 1
            F += [[a, b, c], [a, c, d]]
    m = dk.Mesh(V, np.array(F))
    W, rep = dk.bounded_biharmonic_weights(m, points=V[[0, n * n - 1]], report=True)
    assert rep["domain"] == "surface"
    check_partition(W)
    with pytest.raises(ValueError, match="encloses no volume"):
        dk.bounded_biharmonic_weights(m, points=V[[0, 5]], domain="volume")


def test_several_parts_and_non_manifold_edges():
    # two spheres, one with no handle: it takes the weights of the nearest reached point
    V1, F1 = make_icosphere(2)
    V2, F2 = make_icosphere(2, radius=0.5)
    V = np.vstack([V1, V2 + [3.0, 0, 0]])
    F = np.vstack([F1, F2 + len(V1)])
    W, rep = dk.bounded_biharmonic_weights(dk.Mesh(V, F), points=[[-0.5, 0, 0], [0.5, 0, 0]],
                                           report=True)
    check_partition(W)
    assert rep["unreached"] > 0
    far = W[len(V1):]
    assert np.all(far[:, 1] > 0.9)
    # a book of pages glued along a spine (non-manifold edges, no volume): the surface
    bv, bf, page = make_book(pages=3)
    W = dk.bounded_biharmonic_weights(dk.Mesh(bv, bf), points=bv[[10, 40]])
    check_partition(W)


@pytest.mark.parametrize("name", ["beast.obj", "ogre.obj"])
def test_broken_scans(name):
    """Several parts, holes and non-manifold edges, where Blender's bone heat reports that it
    failed to find a solution: weights everywhere, bounded, summing to 1."""
    path = SHARED_MESHES / name
    if not path.exists():
        pytest.skip("shared meshes not present")
    m = dk.read_mesh(str(path))
    V = np.asarray(m.vertices)
    lo, hi = V.min(0), V.max(0)
    c = 0.5 * (lo + hi)
    axis = np.argmax(hi - lo)
    a, b = c.copy(), c.copy()
    a[axis] = lo[axis] + 0.3 * (hi[axis] - lo[axis])
    b[axis] = lo[axis] + 0.7 * (hi[axis] - lo[axis])
    # the handles on the surface, nearest those points (the axis may run through air)
    at = [int(np.argmin(((V - p) ** 2).sum(1))) for p in (a, b)]
    W, rep = dk.bounded_biharmonic_weights(m, points=V[at], report=True)
    check_partition(W)
    assert rep["domain"] == "volume"
    # each handle interpolated, and weighing most around itself
    diag = np.linalg.norm(hi - lo)
    for j, v in enumerate(at):
        assert W[v, j] == pytest.approx(1.0, abs=1e-9)
        near = np.linalg.norm(V - V[v], axis=1) < 0.03 * diag
        assert W[near, j].mean() > 0.8


def test_skinning_computes_its_weights_from_the_bones():
    V, F = capped_cylinder(n_len=41)
    m = dk.Mesh(V, F)
    bones = np.array([[[-1.0, 0, 0], [0.0, 0, 0]], [[0.0, 0, 0], [1.0, 0, 0]]])
    frames = np.tile(np.eye(4), (2, 1, 1))
    frames[:, :3, 3] = bones[:, 0]
    s = dk.Skinning(m, bone_frames=frames, bones=bones)
    W = dk.bounded_biharmonic_weights(m, bones=bones)
    assert np.array_equal(np.asarray(s.solve(transforms=frames).positions), V)
    # bend the second bone 90 degrees about z at the joint
    R = np.array([[0.0, -1, 0], [1, 0, 0], [0, 0, 1]])
    T = frames.copy()
    T[1, :3, :3] = R
    P = np.asarray(s.solve(transforms=T).positions)
    expect = (1 - W[:, 1:2]) * V + W[:, 1:2] * (V @ R.T)
    np.testing.assert_allclose(P, expect, atol=1e-12)
    full = W[:, 1] == 1.0
    assert full.sum() > 0
    np.testing.assert_allclose(P[full], V[full] @ R.T, atol=1e-12)


def test_skinning_bind_reports_and_cancels():
    V, F = capped_cylinder()
    bones = np.array([[[-1.0, 0, 0], [0.0, 0, 0]], [[0.0, 0, 0], [1.0, 0, 0]]])
    frames = np.tile(np.eye(4), (2, 1, 1))
    seen = []
    dk.Skinning(dk.Mesh(V, F), bone_frames=frames, bones=bones,
                progress=lambda f: seen.append((f.phase, float(f))) and False)
    assert seen[-1][1] == 1.0 and any(p == "computed weights" for p, _ in seen)
    assert all(b >= a for (_, a), (_, b) in zip(seen, seen[1:]))
    with pytest.raises(RuntimeError, match="cancelled"):
        dk.Skinning(dk.Mesh(V, F), bone_frames=frames, bones=bones,
                    progress=lambda f: f.phase == "computed weights" and float(f) > 0.3)


def test_refusals():
    V, F = capped_cylinder()
    m = dk.Mesh(V, F)
    with pytest.raises(ValueError, match="at least one handle"):
        dk.bounded_biharmonic_weights(m)
    with pytest.raises(ValueError, match="domain"):
        dk.bounded_biharmonic_weights(m, points=[[0, 0, 0]], domain="tets")
    with pytest.raises(ValueError, match="resolution"):
        dk.bounded_biharmonic_weights(m, points=[[0, 0, 0]], resolution=2)
    with pytest.raises(ValueError, match="not a finite"):
        dk.bounded_biharmonic_weights(m, points=[[0, np.nan, 0]])
    with pytest.raises(ValueError, match="point [01] has no place"):
        dk.bounded_biharmonic_weights(m, points=[[0, 0, 0], [0, 0, 0]])
    with pytest.raises(ValueError, match="volume"):
        cage_v, cage_f = make_icosphere(1, radius=3.0)
        dk.bounded_biharmonic_weights(m, cage=(cage_v, cage_f), domain="surface")
    frames = np.tile(np.eye(4), (2, 1, 1))
    with pytest.raises(TypeError, match="bones"):
        dk.Skinning(m, bone_frames=frames)
    with pytest.raises(ValueError, match="2 rows|rows"):
        dk.Skinning(m, bone_frames=frames, bones=np.zeros((3, 2, 3)))


def test_cage_handles_blend_linearly_on_the_cage():
    V, F = capped_cylinder()
    cage_v, cage_f = make_icosphere(0, radius=1.6)
    W, rep = dk.bounded_biharmonic_weights(dk.Mesh(V, F), cage=(cage_v, cage_f), resolution=16,
                                           report=True)
    assert W.shape == (len(V), len(cage_v)) and rep["domain"] == "volume"
    check_partition(W)
    # a cage's weights reproduce nothing exactly inside (they are not coordinates), but the
    # nearest cage vertices weigh most: the tube's ends lean to the cage's +-x vertices
    ends = cage_v[:, 0].argmin(), cage_v[:, 0].argmax()
    assert W[V[:, 0] < -0.9].argmax(1).tolist().count(ends[0]) > 0
    assert W[V[:, 0] > 0.9].argmax(1).tolist().count(ends[1]) > 0


def random_rotation(rng):
    q = rng.normal(size=4)
    q /= np.linalg.norm(q)
    w, x, y, z = q
    return np.array([[1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)],
                     [2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)],
                     [2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)]])


def example_poses(V, W, n_poses, rng, noise=0.0):
    """Bone frames (rest and posed) and the poses linear blend skinning makes of V with W."""
    b = W.shape[1]
    B = np.tile(np.eye(4), (b, 1, 1))
    B[:, :3, 3] = rng.normal(size=(b, 3))
    T = np.tile(np.eye(4), (n_poses, b, 1, 1))
    X = np.empty((n_poses, len(V), 3))
    for p in range(n_poses):
        for j in range(b):
            T[p, j, :3, :3] = random_rotation(rng)
            T[p, j, :3, 3] = rng.normal(size=3)
        M = T[p] @ np.linalg.inv(B)
        Vh = np.c_[V, np.ones(len(V))]
        X[p] = np.einsum("vj,jrc,vc->vr", W, M[:, :3, :], Vh)
    return B, T, X + noise * rng.normal(size=X.shape)


def test_weights_fitted_from_example_poses_recover_the_weights():
    """Poses made by linear blend skinning with known sparse weights: the fit recovers them
    (the slides' "weights by using example poses & skins")."""
    rng = np.random.default_rng(3)
    V, _ = make_icosphere(2)
    b = 5
    W = np.zeros((len(V), b))
    for i in range(len(V)):  # two or three bones a vertex, summing to 1
        k = rng.choice(b, size=rng.integers(1, 4), replace=False)
        W[i, k] = rng.dirichlet(np.ones(len(k)))
    B, T, X = example_poses(V, W, 4, rng)
    F = dk.fit_skinning_weights(V, B, T, X)
    assert F.shape == W.shape
    assert F.min() >= 0.0 and np.abs(F.sum(1) - 1).max() < 1e-12
    assert np.abs(F - W).max() < 1e-8
    # with noise the fit is still the nearest (bounded, summing to 1, close)
    B, T, X = example_poses(V, W, 6, rng, noise=1e-3)
    F = dk.fit_skinning_weights(V, B, T, X)
    assert F.min() >= 0.0 and np.abs(F.sum(1) - 1).max() < 1e-12
    assert np.abs(F - W).max() < 0.05


def test_fitted_weights_are_the_constrained_least_squares_minimisers():
    """Against scipy's SLSQP on single vertices with inconsistent poses: same minimum."""
    rng = np.random.default_rng(5)
    V = rng.normal(size=(6, 3))
    b = 4
    W = rng.dirichlet(np.ones(b), size=len(V))
    B, T, X = example_poses(V, W, 3, rng, noise=0.3)
    F = dk.fit_skinning_weights(V, B, T, X)
    M = T @ np.linalg.inv(B)[None]
    for v in range(len(V)):
        A = np.concatenate([np.stack([M[p, j, :3, :] @ np.r_[V[v], 1.0] for j in range(b)], 1)
                            for p in range(len(T))])
        x = X[:, v].ravel()
        res = scipy.optimize.minimize(
            lambda w: 0.5 * np.sum((A @ w - x) ** 2), np.full(b, 1.0 / b),
            jac=lambda w: A.T @ (A @ w - x), method="SLSQP", bounds=[(0, 1)] * b,
            constraints=[{"type": "eq", "fun": lambda w: w.sum() - 1}],
            options={"ftol": 1e-15, "maxiter": 500})
        ours = 0.5 * np.sum((A @ F[v] - x) ** 2)
        assert ours <= res.fun + 1e-9 * (1 + res.fun)
        assert np.abs(F[v] - res.x).max() < 1e-5


def test_fit_refusals():
    V, _ = make_icosphere(1)
    B = np.tile(np.eye(4), (2, 1, 1))
    T = np.tile(np.eye(4), (1, 2, 1, 1))
    X = V[None]
    with pytest.raises(ValueError, match="pose_frames"):
        dk.fit_skinning_weights(V, B, np.tile(np.eye(4), (3, 1, 1)), X)
    with pytest.raises(ValueError, match="pose_positions"):
        dk.fit_skinning_weights(V, B, T, X[:, :5])
    bad = B.copy()
    bad[1, :3, :3] = 0.0
    with pytest.raises(ValueError, match="bone 1's rest frame"):
        dk.fit_skinning_weights(V, bad, T, X)
    Xn = X.copy()
    Xn[0, 3, 1] = np.nan
    with pytest.raises(ValueError, match="vertex 3"):
        dk.fit_skinning_weights(V, B, T, Xn)
    # bones that move alike in every pose cannot be told apart: any split reproduces them
    F = dk.fit_skinning_weights(V, B, T, X)
    assert np.abs(F.sum(1) - 1).max() < 1e-12 and F.min() >= 0.0
