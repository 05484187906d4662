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

/* The cells of the triangles `faces` (nf x 3): one per vertex (empty for a vertex in none). */
static dk_status build_surface_cells(dk_arap *ar, const dk_index *faces, dk_index nf,
                                     dk_error *err)
{
    const dk_mesh *m = ar->mesh;
    const dk_index n = m->n_vertices;
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
            start[faces[3 * f + k] + 1] += per_corner;
    for (dk_index v = 0; v < n; v++)
        start[v + 1] += start[v];
    memcpy(fill, start, (size_t)n * sizeof *fill);
    const double work = (double)nf + (double)n; /* the two loops below, for progress */
    for (dk_index f = 0; f < nf; f++) {
        if ((st = arap_tick(ar, f, work, err)) != DK_OK)
            goto done;
        const dk_index *t = faces + 3 * f;
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

dk_status arap_build_cells(dk_arap *ar, dk_error *err)
{
    return build_surface_cells(ar, ar->mesh->faces, ar->mesh->n_faces, err);
}

void arap_cells_set_edges(dk_arap *ar, const double *p)
{
    for (int64_t t = 0; t < ar->n_terms; t++)
        for (int d = 0; d < 3; d++)
            ar->te[3 * t + d] = p[3 * ar->ta[t] + d] - p[3 * ar->tb[t] + d];
}

/* A tetrahedron's cell: its six edges weighted by the linear element's stiffness
 * (dk_tetrahedron_stiffness), so that the cell's sum over its edges of
 * w_ab |(x_a - x_b) - R (p_a - p_b)|^2 = vol |F - R|^2 for every x and R, F = D_s D_m^-1
 * the element's deformation gradient: the slides' volumetric ARAP term with lambda = vol,
 * whatever the signs of the w (an obtuse dihedral angle makes one negative; the sum stays
 * vol |F - R|^2 >= 0, so nothing is clamped).
 *
 * The layout: first one surface cell per vertex in no tetrahedron (the parts that bound no
 * volume), built from the triangles among them, then one cell per tetrahedron; a cell's
 * corners (cc) are its vertex, or its tetrahedron's four. */
dk_status arap_build_volume_cells(dk_arap *ar, const dk_index *tets, dk_index nt,
                                  dk_error *err)
{
    const dk_mesh *m = ar->mesh;
    const dk_index n = ar->n;
    const double *p = m->positions;
    unsigned char *in_tet = calloc((size_t)n + 1, 1);
    dk_index *faces = malloc(3 * (size_t)m->n_faces * sizeof *faces + sizeof *faces);
    if (!in_tet || !faces) {
        free(in_tet);
        free(faces);
        return oom(err, "cells");
    }
    for (size_t k = 0; k < 4 * (size_t)nt; k++)
        in_tet[tets[k]] = 1;
    dk_index nf = 0;
    for (dk_index f = 0; f < m->n_faces; f++) {
        const dk_index *t = m->faces + 3 * (size_t)f;
        if (!in_tet[t[0]] && !in_tet[t[1]] && !in_tet[t[2]])
            memcpy(faces + 3 * (size_t)nf++, t, 3 * sizeof *t);
    }
    dk_status st = build_surface_cells(ar, faces, nf, err);
    free(faces);
    if (st != DK_OK) {
        free(in_tet);
        return st;
    }
    /* the surface cells of the vertices in no tetrahedron, in vertex order (those of the
     * others are empty: dropping them keeps the terms contiguous), so the two threads'
     * halves of the cells hold comparable work */
    dk_index ncs = 0;
    for (dk_index v = 0; v < n; v++)
        ncs += !in_tet[v];
    ar->cc_start = malloc(((size_t)ncs + (size_t)nt + 1) * sizeof *ar->cc_start);
    ar->cc = malloc(((size_t)ncs + 4 * (size_t)nt + 1) * sizeof *ar->cc);
    if (!ar->cc_start || !ar->cc) {
        free(in_tet);
        return oom(err, "cells"); /* freed with the object */
    }
    for (dk_index v = 0, k = 0; v < n; v++)
        if (!in_tet[v]) {
            ar->cell_start[k] = ar->cell_start[v]; /* k <= v: read before written */
            ar->cc_start[k] = k;
            ar->cc[k++] = v;
        }
    free(in_tet);
    const int64_t ns = ar->n_terms, nterms = ns + 6 * (int64_t)nt;
    if (nterms > INT32_MAX)
        return dk_error_set(err, DK_ERR_INVALID_ARGUMENT,
                            "ARAP bind: %lld cell terms, at most %ld", (long long)nterms,
                            (long)INT32_MAX);
    dk_index *cs = realloc(ar->cell_start, ((size_t)ncs + (size_t)nt + 1) * sizeof *cs);
    if (cs)
        ar->cell_start = cs;
    dk_index *ta = realloc(ar->ta, ((size_t)nterms + 1) * sizeof *ta);
    if (ta)
        ar->ta = ta;
    dk_index *tb = realloc(ar->tb, ((size_t)nterms + 1) * sizeof *tb);
    if (tb)
        ar->tb = tb;
    double *tw = realloc(ar->tw, ((size_t)nterms + 1) * sizeof *tw);
    if (tw)
        ar->tw = tw;
    double *te = realloc(ar->te, ((size_t)nterms * 3 + 1) * sizeof *te);
    if (te)
        ar->te = te;
    if (!cs || !ta || !tb || !tw || !te)
        return oom(err, "cell terms"); /* freed with the object */
    ar->cc_start[ncs] = ncs;
    for (dk_index c = 0; c < nt; c++) {
        if ((c & 4095) == 0 && (st = arap_tick(ar, c, nt, err)) != DK_OK)
            return st;
        const dk_index *q = tets + 4 * (size_t)c;
        double w[6];
        dk_tetrahedron_stiffness(p + 3 * q[0], p + 3 * q[1], p + 3 * q[2], p + 3 * q[3], w);
        ar->cell_start[ncs + c] = (dk_index)(ns + 6 * (int64_t)c);
        ar->cc_start[ncs + c + 1] = ncs + 4 * (c + 1);
        memcpy(ar->cc + ncs + 4 * (size_t)c, q, 4 * sizeof *q);
        int e = 0;
        for (int a = 0; a < 4; a++)
            for (int b = a + 1; b < 4; b++, e++) {
                const int64_t t = ns + 6 * (int64_t)c + e;
                ar->ta[t] = q[a] < q[b] ? q[a] : q[b];
                ar->tb[t] = q[a] < q[b] ? q[b] : q[a];
                ar->tw[t] = w[e];
                for (int k = 0; k < 3; k++)
                    ar->te[3 * t + k] = p[3 * ar->ta[t] + k] - p[3 * ar->tb[t] + k];
            }
    }
    ar->cell_start[ncs + nt] = (dk_index)nterms;
    ar->n_terms = nterms;
    ar->nc = ncs + nt;
    return DK_OK;
}
