"""deformkit.tetrahedralize (dk_tetrahedralize_surface, TetGen): the interior of a closed
surface in tetrahedra, its vertices the first points bit for bit, the tetrahedra filling
exactly the enclosed volume with the surface as their boundary, quality and size bounds
honoured; a real scan; open, non-manifold, degenerate and self-intersecting surfaces refused
by name (TetGen itself crashes on a self-intersecting surface: its own check runs first)."""
import numpy as np
import pytest

import deformkit as dk
from conftest import SHARED_MESHES, make_icosphere


def tet_volumes(P, T):
    a, b, c, d = (P[T[:, k]] for k in range(4))
    return np.einsum("ij,ij->i", b - a, np.cross(c - a, d - a)) / 6.0


def enclosed(V, F):
    a, b, c = V[F[:, 0]], V[F[:, 1]], V[F[:, 2]]
    return abs(np.einsum("ij,ij->i", a, np.cross(b, c)).sum() / 6.0)


def boundary_faces(T):
    faces = np.concatenate([T[:, [1, 2, 3]], T[:, [0, 2, 3]], T[:, [0, 1, 3]], T[:, [0, 1, 2]]])
    faces = np.sort(faces, axis=1)
    u, counts = np.unique(faces, axis=0, return_counts=True)
    return u[counts == 1]


@pytest.mark.parametrize("quality, max_volume", [(0.0, 0.0), (1.5, 0.0), (1.5, 0.02)])
def test_a_closed_surface(quality, max_volume):
    V, F = make_icosphere(3, radius=1.0)
    V = np.asarray(V, float) * [1.0, 0.6, 0.8] + [3.0, -1.0, 2.0]
    P, T = dk.tetrahedralize(V, F, quality=quality, max_volume=max_volume)
    assert np.array_equal(P[:len(V)], V) and T.dtype == np.int32 and T.shape[1] == 4
    vol = np.abs(tet_volumes(P, T))
    assert abs(vol.sum() - enclosed(V, np.asarray(F))) < 1e-9 * vol.sum()
    assert np.array_equal(boundary_faces(T), np.unique(np.sort(np.asarray(F), axis=1), axis=0))
    if max_volume:
        assert vol.max() <= max_volume * (1 + 1e-9) and len(P) > len(V)


def test_refusals():
    V, F = make_icosphere(2)
    V, F = np.asarray(V, float), np.asarray(F)
    with pytest.raises(ValueError, match="closed and manifold"):
        dk.tetrahedralize(V, F[1:])  # a hole
    two = np.vstack([V, V + [0.7, 0.01, 0.02]])
    with pytest.raises(ValueError, match="intersects itself"):
        dk.tetrahedralize(two, np.vstack([F, F + len(V)]))
    flat = V.copy()
    flat[F[0, 1]] = flat[F[0, 0]]
    with pytest.raises(ValueError, match="degenerate"):
        dk.tetrahedralize(flat, F)
    with pytest.raises(ValueError, match="quality"):
        dk.tetrahedralize(V, F, quality=0.5)
    with pytest.raises(ValueError, match="out of"):
        dk.tetrahedralize(V, np.where(F == 3, len(V) + 2, F))


def test_a_real_scan():
    """The arm of ../shared/meshes (8,311 vertices): closed; measured 4,032 interior points
    and 50,383 tetrahedra at quality 1.5."""
    path = SHARED_MESHES / "arm.obj"
    if not path.exists():
        pytest.skip("arm.obj not present")
    verts, sizes, idx = dk.load_mesh_file(str(path))
    mesh = dk.Mesh.from_polygons(verts, sizes, idx)
    V, F = np.asarray(verts, float), np.asarray(mesh.triangles)
    P, T = dk.tetrahedralize(V, F, quality=1.5)
    assert np.array_equal(P[:len(V)], V) and len(P) > len(V)
    vol = np.abs(tet_volumes(P, T))
    assert abs(vol.sum() - enclosed(V, F)) < 1e-9 * vol.sum() and vol.min() > 0
