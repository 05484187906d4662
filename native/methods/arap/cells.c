/* DeformKit ARAP: the cells, each vertex's weighted rest edges (see arap_internal.h). */
#include "arap_internal.h"

typedef struct raw_term {
    dk_index a, b;
    double w;
} raw_term;

/* cot(angle at corner p0 of triangle p0 p1 p2) / 2, 0 for a degenerate triangle. */
static double half_cot(const double *p0, const double *p1, const double *p2, double longest2)
{
    double u[3] = {p1[0] - p0[0], p1[1] - p0[1], p1[2] - p0[2]};
    double v[3] = {p2[0] - p0[0], p2[1] - p0[1], p2[2] - p0[2]};
    double c[3] = {u[1] * v[2] - u[2] * v[1], u[2] * v[0] - u[0] * v[2],
                   u[0] * v[1] - u[1] * v[0]};
    double twice_area = sqrt(c[0] * c[0] + c[1] * c[1] + c[2] * c[2]);
    if (dk_triangle_degenerate(p0, p1, p2, twice_area, longest2))
        return 0.0;
    return 0.5 * (u[0] * v[0] + u[1] * v[1] + u[2] * v[2]) / twice_area;
}

static int term_less(const raw_term *x, const raw_term *y)
{
    return x->a < y->a || (x->a == y->a && x->b < y->b);
}

dk_status arap_build_cells(dk_arap *ar, dk_error *err)
{
    const dk_mesh *m = ar->mesh;
    const dk_index n = m->n_vertices, nf = m->n_faces;
    const int rims = ar->opt.energy == DK_ARAP_SPOKES_AND_RIMS;
    const int per_corner = rims ? 3 : 2;
    const double *p = m->positions;
    dk_status st = DK_OK;
    dk_index *start = calloc((size_t)n + 1, sizeof *start);
    dk_index *fill = malloc(((size_t)n + 1) * sizeof *fill);
    raw_term *raw = malloc(((size_t)nf * 3 * per_corner + 1) * sizeof *raw);
    if (!start || !fill || !raw) {
        st = oom(err, "cells");
        goto done;
    }
    for (dk_index f = 0; f < nf; f++)
        for (int k = 0; k < 3; k++)
            start[m->faces[3 * f + k] + 1] += per_corner;
    for (dk_index v = 0; v < n; v++)
        start[v + 1] += start[v];
    memcpy(fill, start, (size_t)n * sizeof *fill);
    const double work = (double)nf + (double)n; /* the two loops below, for progress */
    for (dk_index f = 0; f < nf; f++) {
        if ((st = arap_tick(ar, f, work, err)) != DK_OK)
            goto done;
        const dk_index *t = m->faces + 3 * f;
        double l0 = dist2(p + 3 * t[1], p + 3 * t[2]), l1 = dist2(p + 3 * t[2], p + 3 * t[0]),
               l2 = dist2(p + 3 * t[0], p + 3 * t[1]);
        double longest2 = fmax(l0, fmax(l1, l2));
        double h[3]; /* h[k]: half weight of the edge opposite corner k */
        for (int k = 0; k < 3; k++)
            h[k] = ar->opt.weights == DK_ARAP_WEIGHTS_UNIFORM
                       ? 0.5
                       : half_cot(p + 3 * t[k], p + 3 * t[(k + 1) % 3], p + 3 * t[(k + 2) % 3],
                                  longest2);
        for (int k = 0; k < 3; k++) {
            dk_index i = t[k];
            for (int e = 0; e < 3; e++) {
                if (!rims && e == k)
                    continue; /* the edge opposite i is a rim */
                dk_index a = t[(e + 1) % 3], b = t[(e + 2) % 3];
                raw_term r = {a < b ? a : b, a < b ? b : a, h[e]};
                raw[fill[i]++] = r;
            }
        }
    }
    /* Sort each cell by edge, merge duplicates, clamp. A spoke on a non-manifold edge (more
     * than two triangles) sums the half-cotangents of all of them: the energy is a sum over
     * triangles, which needs no manifold (scanned meshes carry such edges; the beast of
     * ../shared/meshes has one). */
    int64_t out = 0;
    for (dk_index i = 0; i < n; i++) {
        if ((st = arap_tick(ar, (double)nf + i, work, err)) != DK_OK)
            goto done;
        raw_term *c = raw + start[i];
        dk_index len = start[i + 1] - start[i];
        for (dk_index s = 1; s < len; s++) {
            raw_term key = c[s];
            dk_index j = s - 1;
            while (j >= 0 && term_less(&key, &c[j])) {
                c[j + 1] = c[j];
                j--;
            }
            c[j + 1] = key;
        }
        dk_index new_start = (dk_index)out;
        for (dk_index s = 0; s < len;) {
            raw_term merged = c[s];
            dk_index e = s + 1;
            while (e < len && c[e].a == merged.a && c[e].b == merged.b)
                merged.w += c[e++].w;
            if (ar->opt.weights == DK_ARAP_WEIGHTS_CLAMPED_COTANGENT && merged.w < 0.0)
                merged.w = 0.0;
            raw[out++] = merged; /* out <= start[i] + s: never overwrites unread terms */
            s = e;
        }
        start[i] = new_start;
    }
    start[n] = (dk_index)out;
    ar->n_terms = out;
    ar->cell_start = start;
    start = NULL;
    ar->ta = malloc(((size_t)out + 1) * sizeof *ar->ta);
    ar->tb = malloc(((size_t)out + 1) * sizeof *ar->tb);
    ar->tw = malloc(((size_t)out + 1) * sizeof *ar->tw);
    ar->te = malloc(((size_t)out * 3 + 1) * sizeof *ar->te);
    if (!ar->ta || !ar->tb || !ar->tw || !ar->te) {
        st = oom(err, "cell terms");
        goto done;
    }
    for (int64_t t = 0; t < out; t++) {
        ar->ta[t] = raw[t].a;
        ar->tb[t] = raw[t].b;
        ar->tw[t] = raw[t].w;
        for (int d = 0; d < 3; d++)
            ar->te[3 * t + d] = p[3 * raw[t].a + d] - p[3 * raw[t].b + d];
    }
done:
    free(start);
    free(fill);
    free(raw);
    return st;
}

void arap_cells_set_edges(dk_arap *ar, const double *p)
{
    for (int64_t t = 0; t < ar->n_terms; t++)
        for (int d = 0; d < 3; d++)
            ar->te[3 * t + d] = p[3 * ar->ta[t] + d] - p[3 * ar->tb[t] + d];
}
