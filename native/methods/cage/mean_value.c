/* DeformKit cage FFD: 3D mean value coordinates of one point (dk_cage.h, Ju, Schaefer and
 * Warren 2005, their pseudo-code's robust form). */
#include "dk_cage.h"

#include <math.h>
#include <stdint.h>
#include <stdlib.h>
#include <string.h>

/* pi - h below this: the point is on the triangle; |s_i| below it: on the triangle's plane,
 * outside it (the paper's epsilon) */
#define MVC_EPS 1e-10
#define MVC_PI 3.14159265358979323846
/* the smallest |s_i| of a triangle below which its weights are computed again in extended
 * precision: near its plane (x beside a triangle seen edge-on) the three weights grow as
 * 1/s and cancel, and double rounding in them cost linear precision up to 3e-9 of the size
 * on three real meshes */
#define MVC_NEAR_PLANE 1e-3

/* One triangle's contributions (corners p[0..2]) to the weights of x, in long double from
 * the positions up (triangle_weights' formula); w[i] for corner i; 0, or 1 when x is on the
 * triangle's plane outside it (no contribution). */
static int triangle_weights_long(const double *x, const double *const p[3], double w[3])
{
    long double d[3], u[3][3];
    for (int i = 0; i < 3; i++) {
        long double v[3], r2 = 0.0L;
        for (int k = 0; k < 3; k++) {
            v[k] = (long double)p[i][k] - (long double)x[k];
            r2 += v[k] * v[k];
        }
        d[i] = sqrtl(r2);
        for (int k = 0; k < 3; k++)
            u[i][k] = v[k] / d[i];
    }
    long double theta[3], co[3], si[3];
    for (int i = 0; i < 3; i++) {
        const long double *a = u[(i + 1) % 3], *b = u[(i + 2) % 3];
        const long double cx = a[1] * b[2] - a[2] * b[1], cy = a[2] * b[0] - a[0] * b[2],
                          cz = a[0] * b[1] - a[1] * b[0];
        co[i] = a[0] * b[0] + a[1] * b[1] + a[2] * b[2];
        si[i] = sqrtl(cx * cx + cy * cy + cz * cz);
        theta[i] = atan2l(si[i], co[i]);
    }
    const long double det = u[0][0] * (u[1][1] * u[2][2] - u[1][2] * u[2][1]) -
                            u[0][1] * (u[1][0] * u[2][2] - u[1][2] * u[2][0]) +
                            u[0][2] * (u[1][0] * u[2][1] - u[1][1] * u[2][0]);
    const long double sign = det < 0.0L ? -1.0L : 1.0L;
    long double c[3], sv[3];
    for (int i = 0; i < 3; i++) {
        const int ip = (i + 1) % 3, im = (i + 2) % 3;
        c[i] = (co[i] - co[ip] * co[im]) / (si[ip] * si[im]);
        const long double q = 1.0L - c[i] * c[i];
        sv[i] = sign * sqrtl(q > 0.0L ? q : 0.0L);
        if (fabsl(sv[i]) <= MVC_EPS)
            return 1;
    }
    for (int i = 0; i < 3; i++) {
        const int ip = (i + 1) % 3, im = (i + 2) % 3;
        w[i] = (double)((theta[i] - c[ip] * theta[im] - c[im] * theta[ip]) /
                        (d[i] * si[ip] * sv[im]));
    }
    return 0;
}

static double det3(const double *a, const double *b, const double *c)
{
    return a[0] * (b[1] * c[2] - b[2] * c[1]) - a[1] * (b[0] * c[2] - b[2] * c[0]) +
           a[2] * (b[0] * c[1] - b[1] * c[0]);
}

typedef struct edge_key {
    int64_t key; /* min * 2^31 + max */
    int64_t slot; /* 3 t + the opposite corner */
} edge_key;

static int key_less(const void *a, const void *b)
{
    const int64_t x = ((const edge_key *)a)->key, y = ((const edge_key *)b)->key;
    return (x > y) - (x < y);
}

dk_status dk_cage_edges(const dk_index *tris, dk_index nt, dk_index **edges_out,
                        dk_index *n_edges, dk_index **opposite_out, dk_error *err)
{
    const size_t ns = 3 * (size_t)nt;
    edge_key *k = malloc((ns + 1) * sizeof *k);
    dk_index *edges = malloc((2 * ns + 1) * sizeof *edges);
    dk_index *opposite = malloc((ns + 1) * sizeof *opposite);
    if (!k || !edges || !opposite) {
        free(k);
        free(edges);
        free(opposite);
        return dk_error_set(err, DK_ERR_OUT_OF_MEMORY, "Cage: out of memory (cage edges)");
    }
    for (dk_index t = 0; t < nt; t++)
        for (int i = 0; i < 3; i++) {
            const int64_t a = tris[3 * t + (i + 1) % 3], b = tris[3 * t + (i + 2) % 3];
            k[3 * (size_t)t + i].key = a < b ? a * INT64_C(2147483648) + b
                                             : b * INT64_C(2147483648) + a;
            k[3 * (size_t)t + i].slot = 3 * (int64_t)t + i;
        }
    qsort(k, ns, sizeof *k, key_less);
    dk_index ne = 0;
    for (size_t i = 0; i < ns; i++) {
        if (i == 0 || k[i].key != k[i - 1].key) {
            edges[2 * (size_t)ne] = (dk_index)(k[i].key / INT64_C(2147483648));
            edges[2 * (size_t)ne + 1] = (dk_index)(k[i].key % INT64_C(2147483648));
            ne++;
        }
        opposite[k[i].slot] = ne - 1;
    }
    free(k);
    *edges_out = edges;
    *n_edges = ne;
    *opposite_out = opposite;
    return DK_OK;
}

int dk_cage_mean_value(const double *x, const double *cage, dk_index nc,
                       const dk_index *tris, dk_index nt, const dk_index *edges, dk_index ne,
                       const dk_index *opposite, double *lambda, double *scratch)
{
    double *d = scratch, *u = scratch + nc; /* u: nc x 3 */
    double *eth = scratch + 4 * (size_t)nc, *eco = eth + ne, *esi = eco + ne;
    double size2 = 0.0;
    for (dk_index j = 0; j < nc; j++) {
        const double *p = cage + 3 * (size_t)j;
        double v[3] = {p[0] - x[0], p[1] - x[1], p[2] - x[2]};
        const double r2 = v[0] * v[0] + v[1] * v[1] + v[2] * v[2];
        size2 = r2 > size2 ? r2 : size2;
        d[j] = sqrt(r2);
        for (int k = 0; k < 3; k++)
            u[3 * (size_t)j + k] = d[j] > 0.0 ? v[k] / d[j] : 0.0;
    }
    const double on_vertex = 1e-12 * sqrt(size2);
    for (dk_index j = 0; j < nc; j++)
        if (d[j] <= on_vertex) { /* on a cage vertex: that vertex */
            memset(lambda, 0, (size_t)nc * sizeof *lambda);
            lambda[j] = 1.0;
            return 0;
        }
    memset(lambda, 0, (size_t)nc * sizeof *lambda);
    /* per edge, the angle at x it subtends: its cosine (a dot product), sine (a cross
     * product's length) and value (atan2), once for its two triangles */
    for (dk_index e = 0; e < ne; e++) {
        const double *a = u + 3 * (size_t)edges[2 * e], *b = u + 3 * (size_t)edges[2 * e + 1];
        const double cx = a[1] * b[2] - a[2] * b[1], cy = a[2] * b[0] - a[0] * b[2],
                     cz = a[0] * b[1] - a[1] * b[0];
        eco[e] = a[0] * b[0] + a[1] * b[1] + a[2] * b[2];
        esi[e] = sqrt(cx * cx + cy * cy + cz * cz);
        eth[e] = atan2(esi[e], eco[e]);
    }
    for (dk_index t = 0; t < nt; t++) {
        const dk_index *f = tris + 3 * (size_t)t;
        const double *uf[3] = {u + 3 * (size_t)f[0], u + 3 * (size_t)f[1], u + 3 * (size_t)f[2]};
        /* per corner i, the angle theta_i at x subtended by the opposite edge */
        double theta[3], co[3], si[3];
        for (int i = 0; i < 3; i++) {
            const dk_index e = opposite[3 * (size_t)t + i];
            theta[i] = eth[e];
            co[i] = eco[e];
            si[i] = esi[e];
        }
        const double h = 0.5 * (theta[0] + theta[1] + theta[2]);
        if (MVC_PI - h < MVC_EPS) { /* on this triangle: its barycentric coordinates */
            memset(lambda, 0, (size_t)nc * sizeof *lambda);
            double sum = 0.0;
            for (int i = 0; i < 3; i++) {
                const double w = si[i] * d[f[(i + 2) % 3]] * d[f[(i + 1) % 3]];
                lambda[f[i]] += w;
                sum += w;
            }
            for (int i = 0; i < 3; i++)
                lambda[f[i]] /= sum;
            return 0;
        }
        /* c_i = 2 sin(h) sin(h - theta_i) / (sin theta_i+1 sin theta_i-1) - 1, written with
         * 2 sin h sin(h - theta_i) = cos theta_i - cos(theta_i+1 + theta_i-1): no trigonometry */
        double c[3], s[3];
        const double sign = det3(uf[0], uf[1], uf[2]) < 0.0 ? -1.0 : 1.0;
        int skip = 0;
        for (int i = 0; i < 3; i++) {
            const int ip = (i + 1) % 3, im = (i + 2) % 3;
            c[i] = (co[i] - co[ip] * co[im]) / (si[ip] * si[im]);
            const double q = 1.0 - c[i] * c[i];
            s[i] = sign * sqrt(q > 0.0 ? q : 0.0);
            if (fabs(s[i]) <= MVC_EPS)
                skip = 1; /* on the triangle's plane, outside it: no contribution */
        }
        if (skip)
            continue;
        if (fabs(s[0]) < MVC_NEAR_PLANE || fabs(s[1]) < MVC_NEAR_PLANE ||
            fabs(s[2]) < MVC_NEAR_PLANE) {
            const double *pc[3] = {cage + 3 * (size_t)f[0], cage + 3 * (size_t)f[1],
                                   cage + 3 * (size_t)f[2]};
            double wl[3];
            if (triangle_weights_long(x, pc, wl) == 0)
                for (int i = 0; i < 3; i++)
                    lambda[f[i]] += wl[i];
            continue;
        }
        for (int i = 0; i < 3; i++) {
            const int ip = (i + 1) % 3, im = (i + 2) % 3;
            lambda[f[i]] += (theta[i] - c[ip] * theta[im] - c[im] * theta[ip]) /
                            (d[f[i]] * si[ip] * s[im]);
        }
    }
    double sum = 0.0;
    for (dk_index j = 0; j < nc; j++)
        sum += lambda[j];
    if (!(fabs(sum) > 0.0) || !isfinite(sum))
        return -1;
    for (dk_index j = 0; j < nc; j++)
        lambda[j] /= sum;
    return 0;
}
