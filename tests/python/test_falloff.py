"""deformkit.Falloff: the slide-7 profile at sampled distances for k < 0, k = 0, k > 0 and
every distance kind, checked against distances computed here independently (BFS, numpy,
scipy's Dijkstra); the displacement rule; fixed/ROI/weights; errors; a shared scenario."""

import collections
import json
import math
import pathlib

import numpy as np
import pytest
import scipy.sparse as sp
from scipy.sparse.csgraph import dijkstra

import deformkit

SHARED = pathlib.Path(__file__).resolve().parents[2] / ".." / "shared"


def grid(nx, ny):
    v = np.array([(i / nx, j / nx, 0.0) for j in range(ny + 1) for i in range(nx + 1)])
    f = []
    for j in range(ny):
        for i in range(nx):
            a = j * (nx + 1) + i
            b, c, d = a + 1, a + nx + 1, a + nx + 2
            f += [(a, b, d), (a, d, c)] if (i + j) % 2 else [(a, b, c), (b, d, c)]
    return v, np.array(f, dtype=np.int64)


def edges_of(f):
    return np.unique(np.sort(np.r_[f[:, [0, 1]], f[:, [1, 2]], f[:, [2, 0]]], axis=1), axis=0)


def formula(i, n, k):
    """S(i) of the slides; 0 beyond the range."""
    i = np.asarray(i, dtype=float)
    t = np.minimum(i / (n + 1), 1.0)  # beyond the range S is 0 anyway
    s = 1 - t ** (k + 1) if k >= 0 else (1 - t) ** (1 - k)
    return np.where(i <= n, s, 0.0)


def hops_bfs(n, edges, sources):
    nb = collections.defaultdict(list)
    for a, b in edges:
        nb[a].append(b)
        nb[b].append(a)
    d = np.full(n, np.inf)
    q = collections.deque(sources)
    d[list(sources)] = 0
    while q:
        a = q.popleft()
        for b in nb[a]:
            if d[b] == np.inf:
                d[b] = d[a] + 1
                q.append(b)
    return d


def test_profile_formula_sampled():
    v, f = grid(20, 20)
    mesh = deformkit.Mesh(v, f)
    centre = 10 * 21 + 10
    hops = hops_bfs(len(v), edges_of(f), [centre])
    for k in (-2.0, -0.5, 0.0, 0.5, 3.0):
        fo = deformkit.Falloff(mesh, [[centre]], distance="hops", range=7, k=k)
        d, s = fo.weights(0)
        free = np.arange(len(v)) != centre
        assert np.array_equal(d, hops)
        np.testing.assert_allclose(s[free], formula(hops[free], 7, k), atol=1e-15)
        assert (s[hops > 7] == 0).all() and (s[(hops <= 7) & free] > 0).all()


@pytest.mark.parametrize("distance", ["hops", "euclidean", "dijkstra", "geodesic"])
@pytest.mark.parametrize("k", [-1.5, 0.0, 2.0])
def test_distance_kinds_and_displacement(distance, k):
    v, f = grid(20, 20)
    mesh = deformkit.Mesh(v, f)
    centre = 10 * 21 + 10
    E = edges_of(f)
    L = np.linalg.norm(v[E[:, 0]] - v[E[:, 1]], axis=1)
    h = L.mean()
    rng = 6 if distance == "hops" else 0.3
    fo = deformkit.Falloff(mesh, [[centre]], distance=distance, range=rng, k=k)
    d, s = fo.weights(0)
    eu = np.linalg.norm(v - v[centre], axis=1)
    if distance == "hops":
        ref = hops_bfs(len(v), E, [centre])
        np.testing.assert_array_equal(d, ref)
    elif distance == "euclidean":
        np.testing.assert_allclose(d, eu, atol=1e-12)
    elif distance == "dijkstra":
        G = sp.coo_matrix((L, (E[:, 0], E[:, 1])), shape=(len(v), len(v)))
        np.testing.assert_allclose(d, dijkstra(G, directed=False, indices=centre), atol=1e-12)
    else:  # heat method: close to Euclidean on a flat grid away from the source
        far = eu > 3 * h
        assert np.all(np.abs(d[far] - eu[far]) < 0.15 * eu[far])
    unit = 1.0 if distance == "hops" else h
    free = np.arange(len(v)) != centre
    np.testing.assert_allclose(s[free], formula(d[free] / unit, rng / unit, k), atol=1e-12)
    # displacement: S times the handle's displacement; energy = sum of squared displacements
    t = v[[centre]] + [0.0, 0.0, 1.0]
    r = fo.solve(t)
    disp = r.positions - v
    np.testing.assert_allclose(disp[free, 2], s[free], atol=1e-12)
    assert np.abs(disp[:, :2]).max() == 0
    assert r.energy == pytest.approx(float(np.sum(disp ** 2)), rel=1e-12)
    assert r.iterations == 1 and r.converged


def test_groups_fixed_roi_weights_transforms():
    v, f = grid(20, 4)
    mesh = deformkit.Mesh(v, f)
    W = 21
    g0 = np.arange(5) * W
    g1 = np.arange(5) * W + 20
    fixed = [10]
    w1 = np.ones(5)
    w1[2] = 0.5
    fo = deformkit.Falloff(mesh, [g0, g1], fixed=fixed, handle_weights=[1.0, w1], range=12)
    t = np.vstack([v[g0] + [0, 0, 0.3], v[g1] + [0, 0, -1.0]])
    x = fo.solve(t).positions
    d0, s0 = fo.weights(0)
    d1, s1 = fo.weights(1)
    cols = np.arange(len(v)) % W
    rows = np.arange(len(v)) // W
    free = (cols > 0) & (cols < 20) & (np.arange(len(v)) != 10)
    # the nearest vertex of group 1 is in the same row: its weight scales the displacement
    expect = 0.3 * s0 - 1.0 * s1 * np.where(rows == 2, 0.5, 1.0)
    np.testing.assert_allclose(x[free, 2], expect[free], atol=1e-12)
    assert x[10, 2] == 0.0                              # fixed stays
    np.testing.assert_allclose(x[g1, 2], -w1)           # soft handle: w * displacement
    # transforms: pure translations equal translated targets
    T = np.tile(np.eye(4), (2, 1, 1))
    T[0, 2, 3], T[1, 2, 3] = 0.3, -1.0
    np.testing.assert_allclose(fo.solve(transforms=T).positions, x, atol=1e-14)
    # nested lists work too, and a rotation is blended: p + S (R p - p)
    R = np.eye(4)
    R[:2, :2] = [[0, -1], [1, 0]]
    xr = fo.solve(transforms=[R.tolist(), np.eye(4).tolist()]).positions
    p = v[free]
    np.testing.assert_allclose(xr[free], p + s0[free, None] * (p @ R[:3, :3].T - p), atol=1e-14)
    # ROI: rebind with the right half outside; it stays
    roi = np.flatnonzero(cols <= 10)
    fo.rebind(handles=[[2 * W]], fixed=None, roi=roi, handle_weights=None)
    x = fo.solve([v[2 * W] + [0, 0, 2.0]]).positions
    assert (x[cols > 10] == v[cols > 10]).all()
    assert (x[(cols <= 10) & (cols > 0)][:, 2] > 0).any()


def test_bad_input():
    v, f = grid(4, 4)
    mesh = deformkit.Mesh(v, f)
    with pytest.raises(ValueError):
        deformkit.Falloff(mesh, [[0, 1], []])
    with pytest.raises(IndexError, match="999"):
        deformkit.Falloff(mesh, [[0, 999]])
    with pytest.raises(ValueError, match=r"\b1\b"):
        deformkit.Falloff(mesh, [[0, 1]], fixed=[1])
    with pytest.raises(ValueError):
        deformkit.Falloff(mesh, [[0]], distance="manhattan")
    with pytest.raises(ValueError):
        deformkit.Falloff(mesh, [[0]], range=-2)
    with pytest.raises(ValueError):
        deformkit.Falloff(mesh, [[0]], k=float("nan"))
    fo = deformkit.Falloff(mesh, [[0]])
    with pytest.raises(ValueError):
        fo.solve([[0.0, float("nan"), 0.0]])
    with pytest.raises(ValueError):
        fo.solve([[0.0, 0.0, 0.0], [1.0, 1.0, 1.0]])
    with pytest.raises(IndexError):
        fo.weights(3)
    # every vertex constrained is accepted: the result is the targets
    fo = deformkit.Falloff(mesh, [np.arange(len(v))])
    np.testing.assert_allclose(fo.solve(v + 1).positions, v + 1)


@pytest.mark.skipif(not (SHARED / "scenarios" / "arm-lift.json").exists(),
                    reason="shared scenarios not available")
def test_arm_lift_geodesic():
    sc = json.loads((SHARED / "scenarios" / "arm-lift.json").read_text())
    verts, faces = [], []
    with open(SHARED / "scenarios" / sc["mesh"]) as fh:
        for line in fh:
            if line.startswith("v "):
                verts.append([float(t) for t in line.split()[1:4]])
            elif line.startswith("f "):
                idx = [int(t.split("/")[0]) - 1 for t in line.split()[1:]]
                faces += [(idx[0], idx[k], idx[k + 1]) for k in range(1, len(idx) - 1)]
    v, f = np.array(verts), np.array(faces, dtype=np.int64)
    mesh = deformkit.Mesh(v, f)
    h = np.array(sc["handles"][0]["vertices"])
    tr = np.array(sc["handles"][0]["translate"])
    fo = deformkit.Falloff(mesh, [h], fixed=sc["fixed"], distance="geodesic",
                           range=0.25 * np.linalg.norm(v.max(0) - v.min(0)), k=0.0)
    r = fo.solve(v[h] + tr)
    disp = r.positions - v
    np.testing.assert_allclose(disp[h], np.tile(tr, (len(h), 1)), atol=1e-12)
    assert (disp[sc["fixed"]] == 0).all()
    # every displacement is S times the handle translation, 0 <= S <= 1
    s = disp @ tr / (tr @ tr)
    assert s.min() >= -1e-12 and s.max() <= 1 + 1e-12
    np.testing.assert_allclose(np.cross(disp, tr), 0, atol=1e-12)


def test_reach_fixed_fades_out_where_the_fixed_part_begins():
    """reach='fixed': each group's range is its distance to the nearest fixed vertex, in the
    chosen kind, so the weights reach 0 at the fixed part and are independent of the model's
    scale; a group that reaches no fixed vertex keeps `range`."""
    nx, ny = 30, 6
    xs, ys = np.meshgrid(np.linspace(0, 3, nx), np.linspace(0, 0.5, ny))
    v = np.c_[xs.ravel(), ys.ravel(), np.zeros(nx * ny)]
    f = []
    for j in range(ny - 1):
        for i in range(nx - 1):
            a = j * nx + i
            f += [[a, a + 1, a + nx + 1], [a, a + nx + 1, a + nx]]
    f = np.array(f, np.int32)
    x = v[:, 0]
    fixed, hand = np.where(x < 0.2)[0], np.where(x > 2.8)[0]
    for distance in ("hops", "euclidean", "dijkstra", "geodesic"):
        ranges = []
        for scale in (1.0, 100.0):
            mesh = deformkit.Mesh(v * scale, f)
            fo = deformkit.Falloff(mesh, handles=[hand], fixed=fixed, distance=distance, reach="fixed",
                            range=1.0)
            d, S = fo.weights(0)
            r = float(np.asarray(fo.ranges)[0])
            assert abs(r - np.asarray(d)[fixed].min()) < 1e-12 * max(r, 1.0), distance
            ranges.append(r / (1.0 if distance == "hops" else scale))
            S = np.asarray(S)
            free = np.setdiff1d(np.arange(len(v)), np.r_[fixed, hand])
            beside = free[np.argmin(np.abs(x[free] - 0.3))]
            assert S[beside] < 0.15, (distance, S[beside])   # nearly nothing next to fixed
            mid = free[np.argmin(np.abs(x[free] - 1.5))]
            assert 0.3 < S[mid] < 0.7, (distance, S[mid])     # half way: half the pull
        assert abs(ranges[0] - ranges[1]) < 1e-6 * ranges[0], (distance, ranges)
    # reach="range": the given range for every group; no fixed vertex reached: `range`
    mesh = deformkit.Mesh(v, f)
    assert np.asarray(deformkit.Falloff(mesh, handles=[hand], fixed=fixed, range=7.0,
                                        reach="range").ranges)[0] == 7.0
    fo = deformkit.Falloff(mesh, handles=[hand], reach="fixed", range=5.0)
    assert np.asarray(fo.ranges)[0] == 5.0
    # the defaults (the add-on's too): euclidean, reach="fixed", and without a fixed group a
    # quarter of the bounding-box diagonal
    d = np.asarray(deformkit.Falloff(mesh, handles=[hand], fixed=fixed).ranges)[0]
    assert abs(d - np.asarray(deformkit.Falloff(mesh, handles=[hand], fixed=fixed, distance="euclidean", reach="fixed").ranges)[0]) == 0
    assert abs(np.asarray(deformkit.Falloff(mesh, handles=[hand]).ranges)[0]
               - 0.25 * mesh.bbox_diagonal) < 1e-12
    with pytest.raises(ValueError):
        deformkit.Falloff(mesh, handles=[hand], reach="nowhere")


def test_weights_are_not_read_while_a_rebind_runs():
    """weights() reads the native object a rebind replaces: from the rebind's progress
    callback (and from another thread meanwhile) it says the object is in use instead of
    reading freed memory."""
    v, f = grid(12, 12)
    fo = deformkit.Falloff(deformkit.Mesh(v, f), [[60]], range=5)
    seen = []

    def progress(fraction):
        try:
            fo.weights(0)
            seen.append("read")
        except RuntimeError as e:
            seen.append(str(e))
        return False
    fo.rebind(handles=[[61]], progress=progress)
    assert seen and all("in use by a call on this same thread" in m for m in seen), seen
    d, s = fo.weights(0)
    assert d[61] == 0.0


def test_loose_geometry_does_not_set_the_automatic_range():
    """The automatic range is the distance to the nearest fixed vertex the caller gave; loose
    geometry the constraints hold at rest (an eyeball near the handle) is not one: with the
    default euclidean distance it became the handle's range."""
    v, f = grid(12, 12)
    n = len(v)
    island = np.array([[0.55, 0.55, 0.02], [0.6, 0.55, 0.02], [0.55, 0.6, 0.02]])
    mesh = deformkit.Mesh(np.vstack([v, island]), np.vstack([f, [[n, n + 1, n + 2]]]))
    fo = deformkit.Falloff(mesh, [[84]])
    quarter = 0.25 * np.linalg.norm(np.ptp(np.asarray(mesh.vertices), axis=0))
    assert fo.ranges[0] == pytest.approx(quarter)   # no fixed group: a quarter diagonal
    T = np.eye(4)
    T[2, 3] = 0.1
    p = np.asarray(fo.solve(transforms=[T]).positions)
    assert np.array_equal(p[n:], island)   # the island held at rest
