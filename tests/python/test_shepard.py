"""deformkit.Shepard (docs/methods/shepard.md): the weights against an independent numpy
evaluation of the slides' formula (all points) and of Franke and Little's (nearest), a
partition of unity; interpolation at the data points and the bound by the data; the flat
spots of the slides' formula (its profile quadratic at a data point for p = 2, linear for
p = 1) and their fix (the handle's own slope there with transforms); scale and placement;
the shared meshes. The contract suites (test_contract.py, the fuzzer) take it as every
method."""
import numpy as np
import pytest

import deformkit as dk
from conftest import SHARED_MESHES


def plane(n=31, size=2.0):
    xs = np.linspace(-size / 2, size / 2, n)
    X, Y = np.meshgrid(xs, xs)
    V = np.c_[X.ravel(), Y.ravel(), np.zeros(n * n)]
    F = []
    for j in range(n - 1):
        for i in range(n - 1):
            a = j * n + i
            F += [[a, a + 1, a + n + 1], [a, a + n + 1, a + n]]
    return V, np.array(F)


def ring_and_centre(V, n):
    """The boundary ring (fixed) and the centre vertex (a one-vertex handle) of plane(n)."""
    ring = np.flatnonzero((np.abs(V[:, 0]) > V[:, 0].max() - 1e-9)
                          | (np.abs(V[:, 1]) > V[:, 1].max() - 1e-9))
    centre = (n // 2) * n + n // 2
    return ring, centre


def test_weights_are_the_formulas():
    """Each group (two handles and the fixed ring) is a data point at its nearest vertex's
    distance: 'all' weighs them d^-p (the slides), 'nearest' with Franke and Little's
    ((R - d)_+ / (R d))^p, R the next group's distance; against numpy's brute force."""
    V, F = plane(15)
    mesh = dk.Mesh(V, F)
    ring, centre = ring_and_centre(V, 15)
    h1 = np.array([centre, centre + 1, centre + 15])
    h2 = np.array([centre - 4, centre - 4 + 15])
    groups = [h1, h2, ring]
    data = np.concatenate(groups)
    free = np.setdiff1d(np.arange(len(V)), data)
    for p in (1.0, 2.0, 3.5):
        for nb, k in (("all", 4), ("nearest", 1), ("nearest", 2)):
            s = dk.Shepard(mesh, handles=[h1, h2], fixed=ring, neighbourhood=nb, k=k, power=p)
            for v in free[::7]:
                w, d = s.weights(int(v))
                dd = np.array([np.linalg.norm(V[g] - V[v], axis=1).min() for g in groups])
                assert np.abs(d - dd).max() < 1e-12
                if nb == "all":
                    want = dd ** -p
                else:
                    order = np.argsort(dd, kind="stable")
                    R = dd[order[k]]
                    want = np.zeros(3)
                    near = order[:k]
                    want[near] = (np.maximum(R - dd[near], 0.0) / (R * dd[near])) ** p
                want /= want.sum()
                assert abs(w.sum() - 1.0) < 1e-12 and (w >= 0).all()
                assert np.abs(w - want).max() < 1e-12, (nb, k, p, w, want)


@pytest.mark.parametrize("neighbourhood", ["nearest", "all", "radius"])
def test_interpolates_and_is_bounded(neighbourhood):
    V, F = plane(25)
    mesh = dk.Mesh(V, F)
    ring, centre = ring_and_centre(V, 25)
    handle = np.flatnonzero(np.linalg.norm(V[:, :2] - (0.3, 0.2), axis=1) < 0.25)
    rng = np.random.default_rng(4)
    targets = V[handle] + rng.normal(scale=0.2, size=(len(handle), 3))
    s = dk.Shepard(mesh, handles=[handle], fixed=ring, interpolate="displacements",
                   neighbourhood=neighbourhood, radius=0.8)
    x = np.asarray(s.solve(targets=targets).positions)
    assert np.abs(x[handle] - targets).max() < 1e-14
    assert np.array_equal(x[ring], V[ring])
    disp = x - V
    data_disp = np.vstack([targets - V[handle], np.zeros((1, 3))])
    lo, hi = data_disp.min(axis=0), data_disp.max(axis=0)
    assert (disp >= lo - 1e-14).all() and (disp <= hi + 1e-14).all()


def test_flat_spots_and_their_fix():
    """A one-vertex handle: the slides' formula is flat there (its fall from the data value
    is quadratic in the distance for p = 2, linear for p = 1); with transforms the slope at
    the data point is the handle's own (R - I), not 0."""
    n = 61
    V, F = plane(n)
    mesh = dk.Mesh(V, F)
    ring, centre = ring_and_centre(V, n)
    h = V[1, 0] - V[0, 0]
    for p, ratio in ((2.0, 0.25), (1.0, 0.5)):
        s = dk.Shepard(mesh, handles=[[centre]], fixed=ring, interpolate="displacements",
                       neighbourhood="all", power=p)
        x = np.asarray(s.solve(targets=V[[centre]] + (0.0, 0.0, 1.0)).positions)
        fall1, fall2 = 1.0 - x[centre + 1, 2], 1.0 - x[centre + 2, 2]
        assert abs(fall1 / fall2 - ratio) < 0.05, (p, fall1 / fall2)
    th = 0.4
    T = np.eye(4)
    T[:2, :2] = [[np.cos(th), -np.sin(th)], [np.sin(th), np.cos(th)]]
    T[:3, 3] = (0.3, -0.2, 0.5)
    slope_want = (T[:3, :3] - np.eye(3)) @ np.array([1.0, 0.0, 0.0])
    for interp, near_want in (("transforms", True), ("displacements", False)):
        s = dk.Shepard(mesh, handles=[[centre]], fixed=ring, interpolate=interp,
                       neighbourhood="all")
        x = np.asarray(s.solve(transforms=T[None]).positions)
        d = x - V
        slope = (d[centre + 1] - d[centre]) / h
        err = np.linalg.norm(slope - slope_want)
        assert (err < 0.05) == near_want, (interp, slope, slope_want)


def test_scale_and_placement():
    V, F = plane(21)
    ring, centre = ring_and_centre(V, 21)
    handle = np.flatnonzero(np.linalg.norm(V[:, :2], axis=1) < 0.2)
    T = np.eye(4)
    T[:3, 3] = (0.0, 0.1, 0.4)
    T[:2, :2] = [[np.cos(0.3), -np.sin(0.3)], [np.sin(0.3), np.cos(0.3)]]
    out = {}
    for scale, off in ((1.0, np.zeros(3)), (1000.0, np.array([5e3, -2e3, 1e4]))):
        mesh = dk.Mesh(V * scale + off, F)
        Ts = np.eye(4)
        Ts[:3, :3] = T[:3, :3]
        Ts[:3, 3] = scale * T[:3, 3] + off - T[:3, :3] @ off
        for nb in ("nearest", "radius", "all"):
            s = dk.Shepard(mesh, handles=[handle], fixed=ring, neighbourhood=nb)
            out[(scale, nb)] = (np.asarray(s.solve(transforms=Ts[None]).positions) - off) / scale
    for nb in ("nearest", "radius", "all"):
        assert np.abs(out[(1.0, nb)] - out[(1000.0, nb)]).max() < 1e-9


@pytest.mark.parametrize("mesh_file", ["armadillo.obj", "beast.obj", "horse.ply"])
def test_shared_meshes(mesh_file):
    path = SHARED_MESHES / mesh_file
    if not path.exists():
        pytest.skip("%s not present" % mesh_file)
    verts, sizes, idx = dk.load_mesh_file(str(path))
    v = np.asarray(verts, dtype=float)
    mesh = dk.Mesh.from_polygons(verts, sizes, idx)
    diag = float(np.linalg.norm(np.ptp(v, axis=0)))
    top = np.flatnonzero(v[:, 2] > v[:, 2].max() - 0.1 * np.ptp(v[:, 2]))
    bottom = np.flatnonzero(v[:, 2] < v[:, 2].min() + 0.1 * np.ptp(v[:, 2]))
    T = np.eye(4)
    T[:3, 3] = (0.0, 0.0, 0.2 * diag)
    for interp in ("transforms", "displacements"):
        s = dk.Shepard(mesh, handles=[top], fixed=bottom, interpolate=interp)
        x = np.asarray(s.solve(transforms=T[None]).positions)
        dz = (x - v)[:, 2]
        assert np.abs(dz[top] - 0.2 * diag).max() < 1e-9 * diag
        assert np.abs(x[bottom] - v[bottom]).max() == 0.0
        assert dz.min() > -1e-9 * diag and dz.max() < 0.2 * diag * (1 + 1e-12)
        mid = np.flatnonzero(np.abs(v[:, 2] - np.median(v[:, 2])) < 0.05 * np.ptp(v[:, 2]))
        assert 0.01 * diag < np.median(dz[mid]) < 0.19 * diag


def u_strip(n=40, w=4, L=1.0, gap=0.1):
    """A strip folded back on itself: the bottom sheet from x = 0 to L (z = 0), a half turn of
    radius gap/2, the top sheet back to x = 0 (z = gap). Returns V, F and the path parameter
    of each vertex's column."""
    half = np.pi * gap / 2
    total = 2 * L + half
    s = np.linspace(0.0, total, n)
    cols = []
    for t in s:
        if t <= L:
            cols.append((t, 0.0))
        elif t <= L + half:
            a = (t - L) / (gap / 2)
            cols.append((L + gap / 2 * np.sin(a), gap / 2 - gap / 2 * np.cos(a)))
        else:
            cols.append((L - (t - L - half), gap))
    V = np.array([(x, y, z) for (x, z) in cols for y in np.linspace(0, 0.2, w)])
    F = []
    for i in range(n - 1):
        for j in range(w - 1):
            a = i * w + j
            F += [[a, a + w, a + w + 1], [a, a + w + 1, a + 1]]
    return V, np.array(F), np.repeat(s, w)


def test_geodesic_distance_follows_the_surface():
    """On a strip folded back on itself, the bottom sheet's tip lies a fold's gap below the
    handle on the top sheet's tip, but two sheets away along the surface: straight-line
    distances pull it nearly as far as the handle, distances along the surface hardly."""
    V, F, s = u_strip()
    mesh = dk.Mesh(V, F)
    total = s.max()
    handle = np.flatnonzero(s > total - 0.06)          # the top sheet's tip
    fixed = np.flatnonzero(np.abs(s - 0.5 * total) < 0.06)   # the fold
    probe = np.flatnonzero(s < 0.03)                   # the bottom sheet's tip, below the handle
    T = np.eye(4)
    T[1, 3] = 0.5
    moved = {}
    for distance in ("euclidean", "geodesic"):
        sh = dk.Shepard(mesh, handles=[handle], fixed=fixed, distance=distance)
        x = np.asarray(sh.solve(transforms=T[None]).positions)
        assert np.allclose(x[handle], V[handle] + (0, 0.5, 0)) and np.array_equal(x[fixed],
                                                                                  V[fixed])
        moved[distance] = float((x[probe, 1] - V[probe, 1]).mean())
    assert moved["euclidean"] > 0.3 and moved["geodesic"] < 0.5 * moved["euclidean"], moved
    with pytest.raises(ValueError, match="geodesic distance needs triangles"):
        dk.Shepard(dk.Mesh(V, np.zeros((0, 3), int)), handles=[handle], fixed=fixed,
                   distance="geodesic")
