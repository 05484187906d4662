"""Make Cage's cage (addon/enclosing_cage.py), without Blender: closed and manifold, every
vertex of real meshes inside it (winding number 1: inside is what Make Cage promises), the
same cage for a moved and scaled mesh moved and scaled, and bad input refused."""
import numpy as np
import pytest

import deformkit as dk
from conftest import SHARED_MESHES
from conftest import _enclosing_cage as ec


def winding(C, T, P):
    """The winding number of the closed triangle mesh (C, T) about each point of P (solid
    angles, Van Oosterom and Strackee), an independent test of inside."""
    out = np.empty(len(P))
    for s in range(0, len(P), 2000):
        p = P[s:s + 2000, None, :]
        a, b, c = C[T[:, 0]] - p, C[T[:, 1]] - p, C[T[:, 2]] - p
        la, lb, lc = (np.linalg.norm(x, axis=2) for x in (a, b, c))
        num = np.einsum("nti,nti->nt", a, np.cross(b, c))
        den = (la * lb * lc + np.einsum("nti,nti->nt", a, b) * lc
               + np.einsum("nti,nti->nt", b, c) * la + np.einsum("nti,nti->nt", c, a) * lb)
        out[s:s + 2000] = 2.0 * np.arctan2(num, den).sum(axis=1) / (4.0 * np.pi)
    return out


def closed_manifold(T):
    e = np.sort(np.concatenate([T[:, [0, 1]], T[:, [1, 2]], T[:, [2, 0]]]), axis=1)
    _, counts = np.unique(e, axis=0, return_counts=True)
    return bool((counts == 2).all())


@pytest.mark.parametrize("subdivisions,count", [(0, 12), (1, 42), (2, 162), (3, 642)])
def test_icosphere_counts_and_closed(subdivisions, count):
    V, F = ec.icosphere(subdivisions)
    assert len(V) == count and len(F) == 2 * count - 4
    assert np.allclose(np.linalg.norm(V, axis=1), 1.0)
    assert closed_manifold(F)
    # outward: positive volume
    vol = np.einsum("ti,ti->t", V[F[:, 0]], np.cross(V[F[:, 1]], V[F[:, 2]])).sum() / 6.0
    assert vol > 0


@pytest.mark.parametrize("name", ["armadillo.obj", "beast.obj", "elephant.obj", "spot.obj",
                                  "horse.ply"])
def test_real_meshes_are_inside(name):
    path = SHARED_MESHES / name
    if not path.exists():
        pytest.skip("%s not present" % path)
    V = np.asarray(dk.load_mesh_file(str(path))[0], dtype=np.float64).reshape(-1, 3)
    C, T = ec.enclosing_cage(V)
    assert len(C) == 162 and closed_manifold(T)
    w = winding(C, T, V[::max(1, len(V) // 3000)])
    assert np.abs(w - 1.0).max() < 1e-6, w.min()


def test_moved_and_scaled_mesh_gives_the_cage_moved_and_scaled():
    rng = np.random.default_rng(1)
    P = rng.normal(size=(2000, 3)) * (1.0, 0.4, 0.2)
    C, T = ec.enclosing_cage(P)
    C2, T2 = ec.enclosing_cage(P * 1000.0 + (5e4, -3e4, 1e4))
    assert np.array_equal(T, T2)
    assert np.allclose(C2, C * 1000.0 + (5e4, -3e4, 1e4), rtol=1e-9, atol=1e-6)


def test_flat_and_single_point_sets_get_a_closed_cage():
    flat = np.c_[np.random.default_rng(2).uniform(-1, 1, (500, 2)), np.zeros(500)]
    for P in (flat, np.array([[1.0, 2.0, 3.0]])):
        C, T = ec.enclosing_cage(P, subdivisions=1)
        assert closed_manifold(T) and np.isfinite(C).all()
        w = winding(C, T, P)
        assert np.abs(w - 1.0).max() < 1e-6


def test_bad_input_is_refused():
    for bad in (np.zeros((0, 3)), np.array([[0.0, np.nan, 0.0]])):
        with pytest.raises(ValueError, match="non-empty n x 3 finite"):
            ec.enclosing_cage(bad)
