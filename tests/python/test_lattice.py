"""deformkit.Lattice (docs/methods/lattice.md) from Python, on every real mesh of
../shared/meshes at its own scale and placement and far from the origin: the default box
holds the whole mesh, the points at rest return it bit for bit, an affine map of the points
maps it, a bend of the lattice bends it smoothly (each interpolation's own character), and
a pose is registered where it lies. The native properties (independent evaluations of each
basis, the outside rules) are in tests/native/test_lattice.c."""
import math

import numpy as np
import pytest

import deformkit as dk
from conftest import SHARED_MESHES

MESH_FILES = sorted(p.name for p in SHARED_MESHES.glob("*")
                    if p.suffix in (".obj", ".off", ".ply")) if SHARED_MESHES.is_dir() else []


def load(name):
    verts, sizes, idx = dk.load_mesh_file(str(SHARED_MESHES / name))
    return np.asarray(verts, dtype=float), dk.Mesh.from_polygons(verts, sizes, idx)


def bend(rest, amount):
    """The lattice bent about its x axis: each point turned by `amount` times its height in
    the box (a smooth, non-affine motion)."""
    lo, hi = rest.min(axis=0), rest.max(axis=0)
    c = 0.5 * (lo + hi)
    out = rest.copy()
    for k, p in enumerate(rest):
        a = amount * (p[2] - lo[2]) / (hi[2] - lo[2])
        R = np.array([[1, 0, 0], [0, math.cos(a), -math.sin(a)], [0, math.sin(a), math.cos(a)]])
        out[k] = R @ (p - c) + c
    return out


@pytest.mark.skipif(not MESH_FILES, reason="../shared/meshes not present")
@pytest.mark.parametrize("mesh_file", MESH_FILES)
def test_every_real_mesh(mesh_file):
    v, mesh = load(mesh_file)
    diag = float(np.linalg.norm(np.ptp(v, axis=0)))
    lat = dk.Lattice(mesh, resolution=(4, 3, 5))
    rest = np.asarray(lat.rest_points)
    F = np.asarray(lat.frame)
    u = (v - F[:3, 3]) @ np.linalg.inv(F[:3, :3]).T   # the vertices in the unit cube
    assert u.min() > 0 and u.max() < 1, "the default box holds the mesh"
    assert np.array_equal(lat.solve(rest).positions, v)
    A = np.array([[1.1, 0.2, 0.0], [-0.1, 0.9, 0.3], [0.05, 0.0, 1.2]])
    t = np.array([0.3, -0.1, 0.2]) * diag
    got = lat.solve(rest @ A.T + t).positions
    assert np.abs(got - (v @ A.T + t)).max() < 1e-9 * diag
    bent = bend(rest, 0.8)
    for interp in ("linear", "bernstein", "bspline"):
        lat = dk.Lattice(mesh, resolution=(4, 3, 5), interpolation=interp)
        x = lat.solve(bent).positions
        assert np.isfinite(x).all() and 0.01 * diag < np.abs(x - v).max() < diag


@pytest.mark.skipif(not MESH_FILES, reason="../shared/meshes not present")
def test_scale_and_placement_do_not_matter():
    """The same lattice edit on the armadillo at 1e-3 of its size, far from the origin,
    and at 1e3: the same result in the mesh's own units."""
    v, _ = load("armadillo.obj")
    F0 = None
    results = []
    for scale, shift in ((1.0, 0.0), (1e-3, 2e4), (1e3, -5.0)):
        vs = v * scale + shift
        lat = dk.Lattice(dk.Mesh(vs, np.asarray(load("armadillo.obj")[1].triangles)),
                         resolution=(3, 3, 3))
        rest = np.asarray(lat.rest_points)
        if F0 is None:
            F0 = rest
        bent = bend(rest, 0.6)
        results.append((lat.solve(bent).positions - shift) / scale)
    for r in results[1:]:
        assert np.abs(r - results[0]).max() < 1e-8 * float(np.linalg.norm(np.ptp(v, axis=0)))


def test_bspline_is_smoother_than_linear_across_cells():
    """A point moved in the middle of the lattice: the linear basis bends the mesh at the
    cell borders (a kink: the second difference along x jumps), the cubic B-spline does not
    (C2 across the cell borders)."""
    xs = np.linspace(0.0, 1.0, 401)
    v = np.stack([xs, np.full_like(xs, 0.5), np.full_like(xs, 0.5)], axis=1)
    mesh = dk.Mesh(v, np.zeros((0, 3), dtype=np.int32))
    frame = np.eye(4)
    kinks = {}
    for interp in ("linear", "bspline"):
        lat = dk.Lattice(mesh, resolution=(5, 3, 3), frame=frame, interpolation=interp)
        P = np.asarray(lat.rest_points).copy()
        P[2 + 5 * (1 + 3 * 1), 2] += 0.2   # the middle point, up
        z = np.asarray(lat.solve(P).positions)[:, 2]
        kinks[interp] = np.abs(np.diff(z, 2)).max()
    assert kinks["bspline"] < 0.05 * kinks["linear"]


def test_keywords_and_refusals():
    v = np.random.RandomState(1).rand(50, 3)
    mesh = dk.Mesh(v, np.array([[0, 1, 2]]))
    lat = dk.Lattice(mesh)
    assert lat.resolution == (3, 3, 3) and np.asarray(lat.rest_points).shape == (27, 3)
    assert lat.stats["n_controls"] == 27
    lat.rebind(resolution=(2, 4, 3))
    assert lat.resolution == (2, 4, 3)
    F = np.asarray(lat.frame)
    lat.rebind(frame=np.eye(4) * 2 + np.diag([0, 0, 0, -1.0]))   # keeps the resolution
    assert lat.resolution == (2, 4, 3) and not np.array_equal(np.asarray(lat.frame), F)
    with pytest.raises(ValueError, match="at least 2"):
        dk.Lattice(mesh, resolution=(1, 3, 3))
    with pytest.raises(ValueError, match="invertible"):
        dk.Lattice(mesh, frame=np.diag([1.0, 1.0, 0.0, 1.0]))
    with pytest.raises(ValueError, match="Bernstein"):
        dk.Lattice(mesh, resolution=(40, 2, 2), interpolation="bernstein")
    with pytest.raises(ValueError, match="interpolation"):
        dk.Lattice(mesh, interpolation="cubic")
    with pytest.raises(TypeError, match="not transforms"):
        lat.solve(transforms=[np.eye(4)])
    with pytest.raises(TypeError):
        dk.Lattice(mesh, handles=[[0]])
    with pytest.raises(TypeError, match="carries no state"):
        lat.save_state()
    # a refused rebind keeps the lattice
    with pytest.raises(ValueError):
        lat.rebind(resolution=(2, 0, 2))
    assert lat.resolution == (2, 4, 3)
