"""The slides' generalized barycentric coordinates from Python (deformkit.barycentric_
coordinates, wachspress_coordinates, mean_value_coordinates; native/operators/
dk_coordinates.h): the bilinear worked example, linear precision over many points at once,
the mean value formula of the slides evaluated here with numpy's angles, any buffer, and
the refusals. The native properties are in tests/native/test_coordinates.c."""
import numpy as np
import pytest

import deformkit as dk


def star(k=5, inner=0.4):
    a = np.pi * np.arange(2 * k) / k
    r = np.where(np.arange(2 * k) % 2, inner, 1.0)
    return np.stack([r * np.cos(a), r * np.sin(a)], axis=1)


def slides_mean_value(poly, p):
    d = poly - p
    r = np.linalg.norm(d, axis=1)
    ang = np.arctan2(d[:, 1], d[:, 0])
    alpha = np.angle(np.exp(1j * (np.roll(ang, -1) - ang)))   # v_i -> v_i+1, in (-pi, pi]
    w = (np.tan(np.roll(alpha, 1) / 2) + np.tan(alpha / 2)) / r
    return w / w.sum()


def test_the_slides_bilinear_example():
    sq = np.array([[0, 0], [1, 0], [1, 1], [0, 1]], dtype=np.float32)  # float32 accepted
    lam = dk.wachspress_coordinates(sq, [0.6, 0.7])
    np.testing.assert_allclose(lam, [0.4 * 0.3, 0.6 * 0.3, 0.6 * 0.7, 0.4 * 0.7], atol=1e-14)


def test_linear_precision_and_the_slides_formula():
    rng = np.random.default_rng(0)
    poly = star()
    pts = rng.uniform(-1.5, 1.5, size=(500, 2))
    lam = dk.mean_value_coordinates(poly, pts)
    assert lam.shape == (500, 10)
    np.testing.assert_allclose(lam.sum(axis=1), 1.0, atol=1e-12)
    np.testing.assert_allclose(lam @ poly, pts, atol=1e-11)
    want = np.array([slides_mean_value(poly, p) for p in pts])
    np.testing.assert_allclose(lam, want, atol=1e-9)
    hexagon = np.stack([np.cos(np.arange(6) * np.pi / 3), np.sin(np.arange(6) * np.pi / 3)], 1)
    inside = rng.uniform(-0.8, 0.8, size=(300, 2))
    inside = inside[np.linalg.norm(inside, axis=1) < 0.85]
    for fn in (dk.wachspress_coordinates, dk.mean_value_coordinates):
        lam = fn(hexagon[::-1], inside)   # clockwise too
        assert (lam > 0).all()
        np.testing.assert_allclose(lam @ hexagon[::-1], inside, atol=1e-13)
    tri = np.array([[0.1, 0.2], [2.0, -0.3], [0.7, 1.9]])
    np.testing.assert_allclose(dk.barycentric_coordinates(tri, inside) @ tri, inside, atol=1e-13)
    np.testing.assert_allclose(dk.mean_value_coordinates(tri, [0.8, 0.5]),
                               dk.barycentric_coordinates(tri, [0.8, 0.5]), atol=1e-13)


def test_refusals_name_the_point():
    sq = [[0, 0], [1, 0], [1, 1], [0, 1]]
    with pytest.raises(ValueError, match="point 1.*outside"):
        dk.wachspress_coordinates(sq, [[0.5, 0.5], [3.0, 3.0]])
    with pytest.raises(ValueError, match="convex"):
        dk.wachspress_coordinates(star(), [0.0, 0.0])
    with pytest.raises(ValueError, match="repeats"):
        dk.mean_value_coordinates([[0, 0], [1, 0], [1, 0], [0, 1]], [0.2, 0.2])
    with pytest.raises(ValueError, match="degenerate"):
        dk.barycentric_coordinates([[0, 0], [1, 1], [2, 2]], [0.2, 0.2])
    with pytest.raises(ValueError):
        dk.mean_value_coordinates(sq, [[0.2, 0.2, 0.0]])
    with pytest.raises(ValueError, match="not finite"):
        dk.mean_value_coordinates(sq, [np.nan, 0.0])
