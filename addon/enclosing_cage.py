"""A coarse closed cage around a point set, for Make Cage: a geodesic sphere about the points'
box centre whose vertices are pushed out along their rays until every point is inside.

The cage is star-shaped about the centre (every ray from it crosses the cage once), so it is
closed, manifold and free of self-intersections by construction, whatever the model: the
careful engineer's choice for a one-click cage that always works, not the tightest one. A
point p on the ray u = sum_i mu_i a_i (mu >= 0) through the cone of a cage triangle with
unit directions a_i and radii R_i meets the triangle at distance 1 / sum_i (mu_i / R_i):
raising any R_i only pushes the triangle out, so one pass over the triangles, each scaled
to clear its own points, encloses them all. No bpy: tests run it in plain Python."""

import numpy as np


def icosphere(subdivisions):
    """Unit geodesic sphere: (vertices v x 3, triangles t x 3, outward, counter-clockwise).
    Subdivisions 0-4: 12, 42, 162, 642, 2562 vertices."""
    g = (1.0 + 5.0 ** 0.5) / 2.0
    V = [(-1, g, 0), (1, g, 0), (-1, -g, 0), (1, -g, 0), (0, -1, g), (0, 1, g), (0, -1, -g),
         (0, 1, -g), (g, 0, -1), (g, 0, 1), (-g, 0, -1), (-g, 0, 1)]
    V = [np.array(v, dtype=np.float64) / np.linalg.norm(v) for v in V]
    F = [(0, 11, 5), (0, 5, 1), (0, 1, 7), (0, 7, 10), (0, 10, 11), (1, 5, 9), (5, 11, 4),
         (11, 10, 2), (10, 7, 6), (7, 1, 8), (3, 9, 4), (3, 4, 2), (3, 2, 6), (3, 6, 8),
         (3, 8, 9), (4, 9, 5), (2, 4, 11), (6, 2, 10), (8, 6, 7), (9, 8, 1)]
    for _ in range(subdivisions):
        mid = {}

        def middle(a, b):
            k = (min(a, b), max(a, b))
            if k not in mid:
                m = V[a] + V[b]
                V.append(m / np.linalg.norm(m))
                mid[k] = len(V) - 1
            return mid[k]

        out = []
        for a, b, c in F:
            ab, bc, ca = middle(a, b), middle(b, c), middle(c, a)
            out += [(a, ab, ca), (b, bc, ab), (c, ca, bc), (ab, bc, ca)]
        F = out
    return np.array(V), np.array(F, dtype=np.int64)


def enclosing_cage(points, subdivisions=2, margin=0.05):
    """A closed triangle cage around `points` (n x 3, n >= 1): (vertices v x 3, triangles
    t x 3, outward). Every point lies inside it, at least `margin` (a part of its distance
    from the centre) from it along its ray; the centre is the points' box centre."""
    P = np.asarray(points, dtype=np.float64).reshape(-1, 3)
    if len(P) == 0 or not np.isfinite(P).all():
        raise ValueError("enclosing_cage: points must be a non-empty n x 3 finite array")
    lo, hi = P.min(axis=0), P.max(axis=0)
    c = 0.5 * (lo + hi)
    A, F = icosphere(subdivisions)
    D = P - c
    r = np.linalg.norm(D, axis=1)
    # the radius of a cage vertex whose triangles hold no point (a flat set's sides): a
    # tenth of the farthest point's, so that the cage keeps a thickness
    floor = 0.1 * float(r.max()) if r.max() > 0 else 1e-3 * max(float(np.abs(c).max()), 1.0)
    keep = r > 1e-9 * floor
    U = D[keep] / r[keep, None]
    rk = r[keep] * (1.0 + margin)
    # each point's triangle (the cone holding its ray) and its weights mu in that cone
    Minv = np.linalg.inv(np.stack([A[F[:, 0]], A[F[:, 1]], A[F[:, 2]]], axis=2))
    tri = np.empty(len(U), dtype=np.int64)
    mu = np.empty((len(U), 3))
    chunk = max(256, 4000000 // (3 * len(F)))   # about 32 MB of weights at a time
    for s in range(0, len(U), chunk):
        u = U[s:s + chunk]
        W = np.einsum("tij,nj->nti", Minv, u)          # weights of u in every cone
        best = W.min(axis=2).argmax(axis=1)            # the cone it lies in (all >= 0)
        tri[s:s + chunk] = best
        mu[s:s + chunk] = W[np.arange(len(u)), best]
    mu = np.maximum(mu, 0.0)
    R = np.full(len(A), floor * (1.0 + margin))
    # start: each vertex at the farthest point of the triangles around it
    np.maximum.at(R, F[tri].ravel(), np.repeat(rk, 3))
    # one pass: scale each triangle's radii to clear its points (raising radii only pushes
    # every other triangle out)
    order = np.argsort(tri, kind="stable")
    bounds = np.searchsorted(tri[order], np.arange(len(F) + 1))
    for t in range(len(F)):
        sel = order[bounds[t]:bounds[t + 1]]
        if len(sel) == 0:
            continue
        hit = 1.0 / (mu[sel] / R[F[t]]).sum(axis=1)
        need = float((rk[sel] / hit).max())
        if need > 1.0:
            R[F[t]] *= need * (1.0 + 1e-9)
    return c + A * R[:, None], F
