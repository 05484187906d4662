/* dk_mesh_from_polygons: validation of polygon lists and their triangulation.
 *
 * Triangles are kept; quads are split along the shorter diagonal; larger polygons are
 * projected to the plane of their Newell normal and ear-clipped (an ear is a convex corner
 * whose triangle contains no other remaining corner); if no ear is found (self-intersecting
 * or degenerate polygon) the rest is fanned from one corner. A k-gon always gives k - 2
 * triangles, so the triangle count is known before triangulating.
 */
#include <math.h>
#include <stdlib.h>
#include <string.h>

#include "dk_mesh.h"
#include "dk_mesh_internal.h"

typedef struct ear_scratch {
    double *xy;    /* 2 * k projected corners */
    int *next, *prev;
} ear_scratch;

static double cross2(const double *a, const double *b, const double *c)
{
    return (b[0] - a[0]) * (c[1] - a[1]) - (b[1] - a[1]) * (c[0] - a[0]);
}

/* Is p inside or on the triangle (a, b, c) (counter-clockwise)? */
static int in_triangle(const double *p, const double *a, const double *b, const double *c)
{
    return cross2(a, b, p) >= 0 && cross2(b, c, p) >= 0 && cross2(c, a, p) >= 0;
}

/* Triangulates polygon `idx` (k >= 3 corners) into `tris` (3 * (k - 2) entries). */
static void triangulate(const double *pos, const dk_index *idx, int k, ear_scratch *s,
                        dk_index *tris)
{
    int t = 0;
    if (k == 3) {
        memcpy(tris, idx, sizeof(dk_index) * 3);
        return;
    }
    if (k == 4) {
        const double *p0 = pos + 3 * (int64_t)idx[0], *p1 = pos + 3 * (int64_t)idx[1],
                     *p2 = pos + 3 * (int64_t)idx[2], *p3 = pos + 3 * (int64_t)idx[3];
        double d02 = 0, d13 = 0;
        for (int i = 0; i < 3; i++) {
            d02 += (p0[i] - p2[i]) * (p0[i] - p2[i]);
            d13 += (p1[i] - p3[i]) * (p1[i] - p3[i]);
        }
        int o = d02 <= d13 ? 0 : 1;
        for (int i = 0; i < 2; i++) {
            tris[3 * i] = idx[o];
            tris[3 * i + 1] = idx[(o + 1 + i) % 4];
            tris[3 * i + 2] = idx[(o + 2 + i) % 4];
        }
        return;
    }
    /* Newell normal */
    double n[3] = {0, 0, 0}, c[3] = {0, 0, 0};
    for (int i = 0; i < k; i++) {
        const double *a = pos + 3 * (int64_t)idx[i], *b = pos + 3 * (int64_t)idx[(i + 1) % k];
        n[0] += (a[1] - b[1]) * (a[2] + b[2]);
        n[1] += (a[2] - b[2]) * (a[0] + b[0]);
        n[2] += (a[0] - b[0]) * (a[1] + b[1]);
        for (int j = 0; j < 3; j++) c[j] += a[j] / k;
    }
    double nl = sqrt(n[0] * n[0] + n[1] * n[1] + n[2] * n[2]);
    int start = 0, remaining = k;
    for (int i = 0; i < k; i++) {
        s->next[i] = (i + 1) % k;
        s->prev[i] = (i + k - 1) % k;
    }
    if (nl > 0 && isfinite(nl)) {
        for (int j = 0; j < 3; j++) n[j] /= nl;
        /* u: perpendicular to n, v = n x u, so that (u, v, n) is right-handed */
        double u[3];
        if (fabs(n[0]) < 0.9) {
            u[0] = 0; u[1] = n[2]; u[2] = -n[1]; /* n x e_x */
        } else {
            u[0] = -n[2]; u[1] = 0; u[2] = n[0]; /* e_y x n */
        }
        double ul = sqrt(u[0] * u[0] + u[1] * u[1] + u[2] * u[2]);
        for (int j = 0; j < 3; j++) u[j] /= ul;
        double v[3] = {n[1] * u[2] - n[2] * u[1], n[2] * u[0] - n[0] * u[2],
                       n[0] * u[1] - n[1] * u[0]};
        for (int i = 0; i < k; i++) {
            const double *p = pos + 3 * (int64_t)idx[i];
            double d[3] = {p[0] - c[0], p[1] - c[1], p[2] - c[2]};
            s->xy[2 * i] = d[0] * u[0] + d[1] * u[1] + d[2] * u[2];
            s->xy[2 * i + 1] = d[0] * v[0] + d[1] * v[1] + d[2] * v[2];
        }
        int cur = 0, tried = 0;
        while (remaining > 3 && tried < remaining) {
            int a = s->prev[cur], b = cur, cc = s->next[cur];
            const double *pa = s->xy + 2 * a, *pb = s->xy + 2 * b, *pc = s->xy + 2 * cc;
            int ear = cross2(pa, pb, pc) > 0;
            for (int q = s->next[cc]; ear && q != a; q = s->next[q])
                if (in_triangle(s->xy + 2 * q, pa, pb, pc)) ear = 0;
            if (ear) {
                tris[3 * t] = idx[a];
                tris[3 * t + 1] = idx[b];
                tris[3 * t + 2] = idx[cc];
                t++;
                s->next[a] = cc;
                s->prev[cc] = a;
                remaining--;
                cur = a; /* the corner before may have become an ear */
                tried = 0;
            } else {
                cur = cc;
                tried++;
            }
        }
        start = cur;
    }
    /* the last triangle, or a fan over what is left when no ear was found */
    int a = start, b = s->next[a];
    while (remaining > 2) {
        int cc = s->next[b];
        tris[3 * t] = idx[a];
        tris[3 * t + 1] = idx[b];
        tris[3 * t + 2] = idx[cc];
        t++;
        b = cc;
        remaining--;
    }
}

dk_status dk_mesh_from_polygons(const double *positions, dk_index n_vertices,
                                const dk_index *face_sizes, dk_index n_polygons,
                                const dk_index *indices, int64_t n_indices, dk_mesh **out,
                                dk_error *err)
{
    if (!out) return dk_error_set(err, DK_ERR_INVALID_ARGUMENT, "mesh: out is NULL");
    *out = NULL;
    if (n_polygons < 0 || n_indices < 0)
        return dk_error_set(err, DK_ERR_INVALID_ARGUMENT,
                            "mesh: negative polygon (%ld) or index (%lld) count",
                            (long)n_polygons, (long long)n_indices);
    if ((n_polygons > 0 && !face_sizes) || (n_indices > 0 && !indices))
        return dk_error_set(err, DK_ERR_INVALID_ARGUMENT, "mesh: polygon arrays are NULL");
    dk_status st = dk_check_positions(positions, n_vertices, err);
    if (st) return st;
    int64_t off = 0, n_tris = 0;
    int max_k = 3;
    for (int64_t p = 0; p < n_polygons; p++) {
        dk_index k = face_sizes[p];
        if (k < 3)
            return dk_error_set(err, DK_ERR_TOPOLOGY,
                                "polygon %lld has %ld corners; at least 3 are needed",
                                (long long)p, (long)k);
        if (off + k > n_indices)
            return dk_error_set(err, DK_ERR_INVALID_ARGUMENT,
                                "polygon %lld needs indices up to %lld but only %lld are given",
                                (long long)p, (long long)(off + k), (long long)n_indices);
        const dk_index *c = indices + off;
        for (dk_index i = 0; i < k; i++) {
            if (c[i] < 0 || c[i] >= n_vertices)
                return dk_error_set(err, DK_ERR_INDEX,
                                    "polygon %lld corner %ld is %ld, out of range [0, %ld]",
                                    (long long)p, (long)i, (long)c[i], (long)n_vertices - 1);
            for (dk_index j = 0; j < i; j++)
                if (c[j] == c[i])
                    return dk_error_set(err, DK_ERR_TOPOLOGY,
                                        "polygon %lld repeats vertex %ld (corners %ld and %ld)",
                                        (long long)p, (long)c[i], (long)j, (long)i);
        }
        if (k > max_k) max_k = k;
        off += k;
        n_tris += k - 2;
    }
    if (off != n_indices)
        return dk_error_set(err, DK_ERR_INVALID_ARGUMENT,
                            "mesh: polygon sizes add up to %lld but %lld indices are given",
                            (long long)off, (long long)n_indices);
    if (n_tris > INT32_MAX / 3)
        return dk_error_set(err, DK_ERR_INVALID_ARGUMENT, "mesh: too many triangles (%lld)",
                            (long long)n_tris);

    double *pos = malloc(sizeof(double) * 3 * (size_t)(n_vertices ? n_vertices : 1));
    dk_index *tris = malloc(sizeof(dk_index) * 3 * (size_t)(n_tris ? n_tris : 1));
    dk_index *fp = malloc(sizeof(dk_index) * (size_t)(n_tris ? n_tris : 1));
    ear_scratch s = {malloc(sizeof(double) * 2 * (size_t)max_k),
                     malloc(sizeof(int) * (size_t)max_k), malloc(sizeof(int) * (size_t)max_k)};
    if (!pos || !tris || !fp || !s.xy || !s.next || !s.prev) {
        free(pos);
        free(tris);
        free(fp);
        free(s.xy);
        free(s.next);
        free(s.prev);
        return dk_error_set(err, DK_ERR_OUT_OF_MEMORY,
                            "mesh: out of memory triangulating %ld polygons", (long)n_polygons);
    }
    if (n_vertices) memcpy(pos, positions, sizeof(double) * 3 * (size_t)n_vertices);
    off = 0;
    int64_t t = 0;
    for (int64_t p = 0; p < n_polygons; p++) {
        int k = (int)face_sizes[p];
        triangulate(pos, indices + off, k, &s, tris + 3 * t);
        for (int i = 0; i < k - 2; i++) fp[t + i] = (dk_index)p;
        t += k - 2;
        off += k;
    }
    free(s.xy);
    free(s.next);
    free(s.prev);
    return dk_mesh_build_owned(pos, n_vertices, tris, (dk_index)n_tris, fp, n_polygons, out,
                               err);
}
