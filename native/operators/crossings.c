/* DeformKit: triangles of a surface that clearly cross each other (dk_surface_crossings in
 * dk_operators.h).
 *
 * A quick refusal before TetGen's own intersection check, which takes seconds on a scanned
 * surface (13 s at 62k vertices, 3 s at 48k: it builds the points' Delaunay tetrahedralization
 * first). Conservative: a pair is reported only when each triangle has a corner clearly on
 * either side of the other's plane and their segments on the planes' common line overlap by
 * more than a tolerance, so a surface reported here certainly crosses itself; pairs sharing a
 * corner, touching, coplanar or nearly so are left to TetGen's exact check.
 *
 * Pairs come from a sweep along the axis of largest extent: triangles sorted by the low end
 * of their extent there, each compared with the following ones until their low end passes its
 * high end, and only when the boxes overlap in the other two axes. */
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

static void sub3(const double *a, const double *b, double *o)
{
    o[0] = a[0] - b[0], o[1] = a[1] - b[1], o[2] = a[2] - b[2];
}

static void cross3(const double *a, const double *b, double *o)
{
    o[0] = a[1] * b[2] - a[2] * b[1];
    o[1] = a[2] * b[0] - a[0] * b[2];
    o[2] = a[0] * b[1] - a[1] * b[0];
}

static double dot3(const double *a, const double *b)
{
    return a[0] * b[0] + a[1] * b[1] + a[2] * b[2];
}

/* The segment where triangle p meets the plane (normal n, through q) projected on the
 * direction d: [*lo, *hi]. 0 when a corner is within tol (times |n|) of the plane, or all
 * corners are on one side: no clear crossing. */
static int segment(const double *const p[3], const double *n, const double *q, const double *d,
                   double tol, double *lo, double *hi)
{
    double s[3];
    const double nn = sqrt(dot3(n, n));
    if (!(nn > 0.0))
        return 0;
    for (int k = 0; k < 3; k++) {
        double r[3];
        sub3(p[k], q, r);
        s[k] = dot3(n, r) / nn;
        if (!(fabs(s[k]) > tol))
            return 0;
    }
    int iso = -1; /* the corner alone on its side */
    if ((s[0] > 0) == (s[1] > 0) && (s[0] > 0) == (s[2] > 0))
        return 0;
    if ((s[1] > 0) == (s[2] > 0))
        iso = 0;
    else if ((s[0] > 0) == (s[2] > 0))
        iso = 1;
    else
        iso = 2;
    double t[2];
    for (int e = 0, k = 0; k < 3; k++) {
        if (k == iso)
            continue;
        const double w = s[iso] / (s[iso] - s[k]); /* in (0, 1): the signs differ */
        double x[3];
        for (int c = 0; c < 3; c++)
            x[c] = p[iso][c] + w * (p[k][c] - p[iso][c]);
        t[e++] = dot3(x, d);
    }
    *lo = fmin(t[0], t[1]);
    *hi = fmax(t[0], t[1]);
    return 1;
}

/* Whether triangles a and b (corners pa, pb) clearly cross (see the file's comment). */
static int clearly_cross(const double *const pa[3], const double *const pb[3], double tol)
{
    double u[3], v[3], na[3], nb[3], d[3];
    sub3(pa[1], pa[0], u);
    sub3(pa[2], pa[0], v);
    cross3(u, v, na);
    sub3(pb[1], pb[0], u);
    sub3(pb[2], pb[0], v);
    cross3(u, v, nb);
    cross3(na, nb, d);
    const double dn = sqrt(dot3(d, d));
    if (!(dn > 0.0))
        return 0; /* parallel planes */
    for (int c = 0; c < 3; c++)
        d[c] /= dn;
    double alo, ahi, blo, bhi;
    if (!segment(pa, nb, pb[0], d, tol, &alo, &ahi) || !segment(pb, na, pa[0], d, tol, &blo, &bhi))
        return 0;
    return fmin(ahi, bhi) - fmax(alo, blo) > tol;
}

dk_status dk_surface_crossings(const double *positions, dk_index n_vertices,
                               const dk_index *triangles, dk_index n_triangles,
                               dk_index *n_crossing, dk_error *err)
{
    if (!n_crossing)
        return dk_error_set(err, DK_ERR_INVALID_ARGUMENT, "surface crossings: out is NULL");
    *n_crossing = 0;
    if (n_triangles <= 0)
        return DK_OK;
    if (!positions || !triangles || n_vertices <= 0)
        return dk_error_set(err, DK_ERR_INVALID_ARGUMENT, "surface crossings: no positions "
                            "or triangles");
    for (size_t i = 0; i < 3 * (size_t)n_triangles; i++)
        if (triangles[i] < 0 || triangles[i] >= n_vertices)
            return dk_error_set(err, DK_ERR_INVALID_ARGUMENT, "surface crossings: triangle %ld "
                                "has corner %ld, out of [0, %ld)", (long)(i / 3),
                                (long)triangles[i], (long)n_vertices);
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
    const double diag = sqrt((hi[0] - lo[0]) * (hi[0] - lo[0]) + (hi[1] - lo[1]) * (hi[1] - lo[1]) +
                             (hi[2] - lo[2]) * (hi[2] - lo[2]));
    if (!isfinite(diag))
        return dk_error_set(err, DK_ERR_NONFINITE, "surface crossings: non-finite positions");
    const double tol = 1e-9 * diag;
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
            if (clearly_cross(pa, pb, tol)) {
                count += !hit[a] + !hit[b];
                hit[a] = hit[b] = 1;
            }
        }
    }
    free(sp);
    free(box);
    free(hit);
    *n_crossing = count;
    return DK_OK;
}
