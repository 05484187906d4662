/* DeformKit: triangles of a surface that certainly cross each other (dk_surface_crossings in
 * dk_operators.h).
 *
 * A quick refusal before TetGen's own intersection check, which takes seconds on a scanned
 * surface (13 s at 62k vertices, 3 s at 48k: it builds the points' Delaunay tetrahedralization
 * first). Conservative: a pair of triangles without a common corner is reported only when an
 * edge of one certainly passes through the other's interior, every orientation it rests on
 * certified by floating-point error bounds; touching, coplanar and undecidable pairs are left
 * to TetGen's exact check, so a surface reported here certainly intersects itself.
 *
 * Pairs come from a sweep along the axis of largest extent: triangles sorted by the low end
 * of their extent there, each compared with the following ones until their low end passes its
 * high end, and only when the boxes overlap in the other two axes. Long triangles across that
 * axis make the sweep quadratic: past a budget of box tests it gives up (reports none found),
 * and TetGen's check decides. */
#include <math.h>
#include <stdlib.h>
#include <string.h>

#include "dk_operators.h"

typedef struct span {
    double lo, hi; /* extent along the sweep axis */
    dk_index t;
} span;

static int by_lo(const void *a, const void *b)
{
    const span *x = a, *y = b;
    if (x->lo != y->lo)
        return (x->lo > y->lo) - (x->lo < y->lo);
    return (x->t > y->t) - (x->t < y->t); /* deterministic order */
}

/* The sign of the orientation det[b - a; c - a; d - a] (positive when d is on the side of
 * plane abc that (b - a) x (c - a) points to), or 0 when floating point cannot certify it:
 * the determinant computed from differences, and trusted only beyond the static error bound
 * of Shewchuk's orient3d (1997), (7 + 56 eps) eps times the permanent of the absolute
 * products, eps = 2^-53, plus an absolute slack for products that underflow (coordinates
 * within DK_COORD_MAX, checked by the caller). NaN gives 0. */
static int orient(const double *a, const double *b, const double *c, const double *d)
{
    const double bx = b[0] - a[0], by = b[1] - a[1], bz = b[2] - a[2];
    const double cx = c[0] - a[0], cy = c[1] - a[1], cz = c[2] - a[2];
    const double dx = d[0] - a[0], dy = d[1] - a[1], dz = d[2] - a[2];
    const double cy_dz = cy * dz, cz_dy = cz * dy, cz_dx = cz * dx, cx_dz = cx * dz,
                 cx_dy = cx * dy, cy_dx = cy * dx;
    const double det = bx * (cy_dz - cz_dy) + by * (cz_dx - cx_dz) + bz * (cx_dy - cy_dx);
    const double perm = fabs(bx) * (fabs(cy_dz) + fabs(cz_dy)) +
                        fabs(by) * (fabs(cz_dx) + fabs(cx_dz)) +
                        fabs(bz) * (fabs(cx_dy) + fabs(cy_dx));
    const double eps = 0x1p-53;
    const double bound = (7.0 + 56.0 * eps) * eps * perm + 1e-240;
    return det > bound ? 1 : -det > bound ? -1 : 0;
}

/* Whether the segment uv certainly passes through the interior of triangle abc: u and v
 * certainly on opposite sides of its plane, and the line uv certainly on the same side of
 * each of its three edges (the three orientations of u, v with an edge share one certified
 * sign). Touching, grazing and anything floating point cannot decide: 0. */
static int pierces(const double *u, const double *v, const double *a, const double *b,
                   const double *c)
{
    const int su = orient(a, b, c, u), sv = orient(a, b, c, v);
    if (su == 0 || sv == 0 || su == sv)
        return 0;
    const int e0 = orient(u, v, a, b);
    return e0 != 0 && orient(u, v, b, c) == e0 && orient(u, v, c, a) == e0;
}

/* Whether triangles a and b (corners pa, pb; no corner in common) certainly cross: one edge
 * of either certainly passes through the other's interior. Two triangles whose interiors
 * cross in general position always have such an edge (each end of their common segment is
 * where an edge of one meets the other); the cases without one (touching, coplanar, edges
 * through edges) are left to TetGen's exact check. */
static int clearly_cross(const double *const pa[3], const double *const pb[3])
{
    for (int k = 0; k < 3; k++)
        if (pierces(pa[k], pa[(k + 1) % 3], pb[0], pb[1], pb[2]) ||
            pierces(pb[k], pb[(k + 1) % 3], pa[0], pa[1], pa[2]))
            return 1;
    return 0;
}

dk_status dk_surface_crossings(const double *positions, dk_index n_vertices,
                               const dk_index *triangles, dk_index n_triangles,
                               dk_index *n_crossing, dk_error *err)
{
    if (!n_crossing)
        return dk_error_set(err, DK_ERR_INVALID_ARGUMENT, "surface crossings: out is NULL");
    *n_crossing = 0;
    if (n_triangles < 0)
        return dk_error_set(err, DK_ERR_INVALID_ARGUMENT, "surface crossings: %ld triangles",
                            (long)n_triangles);
    if (n_triangles == 0)
        return DK_OK;
    if (!positions || !triangles || n_vertices <= 0)
        return dk_error_set(err, DK_ERR_INVALID_ARGUMENT, "surface crossings: no positions "
                            "or triangles");
    for (size_t i = 0; i < 3 * (size_t)n_triangles; i++)
        if (triangles[i] < 0 || triangles[i] >= n_vertices)
            return dk_error_set(err, DK_ERR_INVALID_ARGUMENT, "surface crossings: triangle %ld "
                                "has corner %ld, out of [0, %ld)", (long)(i / 3),
                                (long)triangles[i], (long)n_vertices);
    dk_status st = dk_check_positions(positions, n_vertices, err); /* finite, bounded */
    if (st != DK_OK)
        return st;
    double lo[3] = {INFINITY, INFINITY, INFINITY}, hi[3] = {-INFINITY, -INFINITY, -INFINITY};
    for (dk_index v = 0; v < n_vertices; v++)
        for (int c = 0; c < 3; c++) {
            lo[c] = fmin(lo[c], positions[3 * (size_t)v + c]);
            hi[c] = fmax(hi[c], positions[3 * (size_t)v + c]);
        }
    int axis = 0;
    for (int c = 1; c < 3; c++)
        if (hi[c] - lo[c] > hi[axis] - lo[axis])
            axis = c;
    /* the sweep's budget of box tests: scans need a few hundred per triangle */
    const double budget = 1024.0 * (double)n_triangles + 1e6;
    double tests = 0.0;
    span *sp = malloc(sizeof *sp * (size_t)n_triangles + 1);
    double *box = malloc(sizeof *box * 6 * (size_t)n_triangles + 1); /* lo xyz, hi xyz */
    unsigned char *hit = calloc((size_t)n_triangles + 1, 1);
    if (!sp || !box || !hit) {
        free(sp);
        free(box);
        free(hit);
        return dk_error_set(err, DK_ERR_OUT_OF_MEMORY, "surface crossings: out of memory");
    }
    for (dk_index t = 0; t < n_triangles; t++) {
        double *b = box + 6 * (size_t)t;
        for (int c = 0; c < 3; c++) {
            b[c] = INFINITY;
            b[3 + c] = -INFINITY;
        }
        for (int k = 0; k < 3; k++) {
            const double *p = positions + 3 * (size_t)triangles[3 * (size_t)t + k];
            for (int c = 0; c < 3; c++) {
                b[c] = fmin(b[c], p[c]);
                b[3 + c] = fmax(b[3 + c], p[c]);
            }
        }
        sp[t].lo = b[axis];
        sp[t].hi = b[3 + axis];
        sp[t].t = t;
    }
    qsort(sp, (size_t)n_triangles, sizeof *sp, by_lo);
    const int o1 = (axis + 1) % 3, o2 = (axis + 2) % 3;
    dk_index count = 0;
    for (dk_index i = 0; i < n_triangles; i++) {
        const dk_index a = sp[i].t;
        const dk_index *fa = triangles + 3 * (size_t)a;
        const double *ba = box + 6 * (size_t)a;
        const double *pa[3] = {positions + 3 * (size_t)fa[0], positions + 3 * (size_t)fa[1],
                               positions + 3 * (size_t)fa[2]};
        for (dk_index j = i + 1; j < n_triangles && sp[j].lo <= sp[i].hi; j++) {
            if (++tests > budget) { /* quadratic here: none found, TetGen decides */
                count = 0;
                goto out;
            }
            const dk_index b = sp[j].t;
            const double *bb = box + 6 * (size_t)b;
            if (bb[o1] > ba[3 + o1] || ba[o1] > bb[3 + o1] || bb[o2] > ba[3 + o2] ||
                ba[o2] > bb[3 + o2])
                continue;
            const dk_index *fb = triangles + 3 * (size_t)b;
            int shared = 0;
            for (int x = 0; x < 3; x++)
                for (int y = 0; y < 3; y++)
                    shared |= fa[x] == fb[y];
            if (shared)
                continue;
            const double *pb[3] = {positions + 3 * (size_t)fb[0], positions + 3 * (size_t)fb[1],
                                   positions + 3 * (size_t)fb[2]};
            if (clearly_cross(pa, pb)) {
                count += !hit[a] + !hit[b];
                hit[a] = hit[b] = 1;
            }
        }
    }
out:
    free(sp);
    free(box);
    free(hit);
    *n_crossing = count;
    return DK_OK;
}
