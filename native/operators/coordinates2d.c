/* DeformKit: generalized barycentric coordinates in the plane (dk_coordinates.h). */
#include "dk_coordinates.h"

#include <math.h>

/* Twice the signed area of triangle (a, b, c). */
static double area2(const double *a, const double *b, const double *c)
{
    return (b[0] - a[0]) * (c[1] - a[1]) - (b[1] - a[1]) * (c[0] - a[0]);
}

static int finite_all(const double *v, int count)
{
    for (int k = 0; k < count; k++)
        if (!isfinite(v[k]))
            return 0;
    return 1;
}

/* The polygon's size (its bounding box's diagonal) and twice its signed area; 0 on a
 * repeated consecutive vertex. */
static int polygon_measure(const double *poly, int n, double *size, double *twice_area)
{
    double lo[2] = {poly[0], poly[1]}, hi[2] = {poly[0], poly[1]}, a = 0.0;
    for (int i = 0; i < n; i++) {
        const double *p = poly + 2 * i, *q = poly + 2 * ((i + 1) % n);
        if (p[0] == q[0] && p[1] == q[1])
            return 0;
        for (int d = 0; d < 2; d++) {
            lo[d] = fmin(lo[d], p[d]);
            hi[d] = fmax(hi[d], p[d]);
        }
        a += p[0] * q[1] - p[1] * q[0];
    }
    *size = hypot(hi[0] - lo[0], hi[1] - lo[1]);
    *twice_area = a;
    return 1;
}

/* A point on the boundary: on a vertex, or within tol of an edge (between its ends). Writes
 * the edge's linear interpolation (or the vertex's unit vector) and returns 1. */
static int on_boundary(const double *poly, int n, const double *x, double tol, double *lambda)
{
    for (int i = 0; i < n; i++) {
        const double *a = poly + 2 * i, *b = poly + 2 * ((i + 1) % n);
        const double e[2] = {b[0] - a[0], b[1] - a[1]}, d[2] = {x[0] - a[0], x[1] - a[1]};
        const double ee = e[0] * e[0] + e[1] * e[1];
        const double t = (d[0] * e[0] + d[1] * e[1]) / ee;
        if (t < -tol / sqrt(ee) || t > 1.0 + tol / sqrt(ee))
            continue;
        if (fabs(d[0] * e[1] - d[1] * e[0]) / sqrt(ee) > tol)
            continue;
        const double s = t < 0.0 ? 0.0 : t > 1.0 ? 1.0 : t;
        for (int k = 0; k < n; k++)
            lambda[k] = 0.0;
        lambda[i] = 1.0 - s;
        lambda[(i + 1) % n] += s;
        return 1;
    }
    return 0;
}

dk_status dk_barycentric_2d(const double *t, const double *x, double *lambda, dk_error *err)
{
    if (!t || !x || !lambda)
        return dk_error_set(err, DK_ERR_INVALID_ARGUMENT,
                            "barycentric coordinates: arguments must not be NULL");
    if (!finite_all(t, 6) || !finite_all(x, 2))
        return dk_error_set(err, DK_ERR_NONFINITE,
                            "barycentric coordinates: the triangle or the point is not finite");
    const double A = area2(t, t + 2, t + 4);
    double longest = 0.0;
    for (int i = 0; i < 3; i++) {
        const double *a = t + 2 * i, *b = t + 2 * ((i + 1) % 3);
        longest = fmax(longest, (b[0] - a[0]) * (b[0] - a[0]) + (b[1] - a[1]) * (b[1] - a[1]));
    }
    if (!(fabs(A) > 1e-14 * longest))
        return dk_error_set(err, DK_ERR_INVALID_ARGUMENT,
                            "barycentric coordinates: the triangle is degenerate (area %g)",
                            0.5 * A);
    lambda[0] = area2(x, t + 2, t + 4) / A;
    lambda[1] = area2(t, x, t + 4) / A;
    lambda[2] = 1.0 - lambda[0] - lambda[1];
    return DK_OK;
}

static dk_status check_polygon(const char *who, const double *poly, int n, const double *x,
                               const double *lambda, double *size, double *twice_area,
                               dk_error *err)
{
    if (!poly || !x || !lambda)
        return dk_error_set(err, DK_ERR_INVALID_ARGUMENT, "%s: arguments must not be NULL",
                            who);
    if (n < 3)
        return dk_error_set(err, DK_ERR_INVALID_ARGUMENT,
                            "%s: a polygon has at least 3 vertices, not %d", who, n);
    if (!finite_all(poly, 2 * n) || !finite_all(x, 2))
        return dk_error_set(err, DK_ERR_NONFINITE, "%s: the polygon or the point is not finite",
                            who);
    if (!polygon_measure(poly, n, size, twice_area))
        return dk_error_set(err, DK_ERR_INVALID_ARGUMENT,
                            "%s: the polygon repeats a vertex (two consecutive ones equal)",
                            who);
    if (!(fabs(*twice_area) > 1e-14 * *size * *size))
        return dk_error_set(err, DK_ERR_INVALID_ARGUMENT, "%s: the polygon has no area", who);
    return DK_OK;
}

dk_status dk_wachspress_2d(const double *poly, int n, const double *x, double *lambda,
                           dk_error *err)
{
    double size, A2;
    dk_status st = check_polygon("Wachspress coordinates", poly, n, x, lambda, &size, &A2, err);
    if (st != DK_OK)
        return st;
    const double sgn = A2 > 0.0 ? 1.0 : -1.0; /* either way round */
    const double tol = 1e-12 * size;
    for (int i = 0; i < n; i++) { /* strictly convex: every corner turns the same way */
        const double *a = poly + 2 * ((i + n - 1) % n), *b = poly + 2 * i,
                     *c = poly + 2 * ((i + 1) % n);
        if (!(sgn * area2(a, b, c) > 1e-14 * size * size))
            return dk_error_set(err, DK_ERR_INVALID_ARGUMENT,
                                "Wachspress coordinates: the polygon is not strictly convex at "
                                "vertex %d (mean value coordinates take any polygon)",
                                i);
    }
    if (on_boundary(poly, n, x, tol, lambda))
        return DK_OK;
    for (int i = 0; i < n; i++)
        if (!(sgn * area2(x, poly + 2 * i, poly + 2 * ((i + 1) % n)) > 0.0))
            return dk_error_set(err, DK_ERR_INVALID_ARGUMENT,
                                "Wachspress coordinates: the point (%g, %g) is outside the "
                                "polygon (beyond edge %d)",
                                x[0], x[1], i);
    double sum = 0.0;
    for (int i = 0; i < n; i++) {
        const double *prev = poly + 2 * ((i + n - 1) % n), *v = poly + 2 * i,
                     *next = poly + 2 * ((i + 1) % n);
        const double Ai = sgn * area2(prev, v, next);
        const double Bprev = sgn * area2(x, prev, v), Bi = sgn * area2(x, v, next);
        lambda[i] = Ai / (Bprev * Bi);
        sum += lambda[i];
    }
    for (int i = 0; i < n; i++)
        lambda[i] /= sum;
    return DK_OK;
}

dk_status dk_mean_value_2d(const double *poly, int n, const double *x, double *lambda,
                           dk_error *err)
{
    double size, A2;
    dk_status st = check_polygon("mean value coordinates", poly, n, x, lambda, &size, &A2, err);
    if (st != DK_OK)
        return st;
    if (on_boundary(poly, n, x, 1e-12 * size, lambda))
        return DK_OK;
    /* t_i = tan(alpha_i / 2) for the angle at x from v_i to v_i+1, signed */
    double sum = 0.0, t_prev = 0.0;
    for (int k = 0; k <= n; k++) {
        const int i = k % n, j = (k + 1) % n;
        const double di[2] = {poly[2 * i] - x[0], poly[2 * i + 1] - x[1]};
        const double dj[2] = {poly[2 * j] - x[0], poly[2 * j + 1] - x[1]};
        const double ri = hypot(di[0], di[1]), rj = hypot(dj[0], dj[1]);
        const double cross = di[0] * dj[1] - di[1] * dj[0], dot = di[0] * dj[0] + di[1] * dj[1];
        /* tan(alpha/2) = sin / (1 + cos) = (1 - cos) / sin, each form where it does not
         * cancel: the first for angles below pi/2 (near an edge's line beyond its ends), the
         * second above (near the edge itself, where the weights grow as 1 / distance) */
        const double t = dot >= 0.0 ? cross / (ri * rj + dot) : (ri * rj - dot) / cross;
        if (k > 0) { /* vertex i: (t_i-1 + t_i) / r_i */
            lambda[i] = (t_prev + t) / ri;
            sum += lambda[i];
        }
        t_prev = t;
    }
    for (int i = 0; i < n; i++)
        lambda[i] /= sum;
    return DK_OK;
}
