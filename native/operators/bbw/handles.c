/* DeformKit: the handles of bounded biharmonic weights as samples (bbw_internal.h): the
 * points where the weights are given. A bone is held along its whole segment (the paper's
 * bones), a cage along its edges and faces at the linear blend of its corners (the paper's
 * "cage edges linear", over a 3D cage's faces). */
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "bbw_internal.h"

const char *bbw_handle_name(const dk_bbw_handles *h, dk_index handle, char *buf)
{
    if (handle < h->n_points)
        snprintf(buf, 48, "point %ld", (long)handle);
    else if (handle < h->n_points + h->n_bones)
        snprintf(buf, 48, "bone %ld", (long)(handle - h->n_points));
    else
        snprintf(buf, 48, "cage vertex %ld", (long)(handle - h->n_points - h->n_bones));
    return buf;
}

static double dist3(const double *a, const double *b)
{
    return sqrt((a[0] - b[0]) * (a[0] - b[0]) + (a[1] - b[1]) * (a[1] - b[1]) +
                (a[2] - b[2]) * (a[2] - b[2]));
}

static dk_index divisions(double length, double step)
{
    double k = ceil(length / step);
    return k < 1.0 ? 1 : k > 1e6 ? 1000000 : (dk_index)k;
}

/* Appends a sample blending up to three handles at the given weights. */
static void put(bbw_sample *s, dk_index *n, const double *p, const dk_index *hs, const double *ws,
                int k)
{
    bbw_sample *o = &s[(*n)++];
    memcpy(o->p, p, sizeof o->p);
    for (int i = 0; i < BBW_SAMPLE_HANDLES; i++) {
        o->handle[i] = i < k ? hs[i] : -1;
        o->weight[i] = i < k ? ws[i] : 0.0;
    }
    o->owner = hs[0];
}

static const bbw_sample *sort_base;

static int by_x(const void *a, const void *b)
{
    double xa = sort_base[*(const dk_index *)a].p[0], xb = sort_base[*(const dk_index *)b].p[0];
    return xa < xb ? -1 : xa > xb ? 1 : 0;
}

/* Merges samples within `tol` of each other into the first: where each is one handle's
 * (points, bones, cage vertices) the merged one holds all their handles equally (bones
 * meeting at a joint); a cage's blended samples coincide only with samples of the same
 * cage, which give the same weights there, and the first is kept. */
static dk_status merge_coincident(bbw_sample *s, dk_index *n_io, double tol, dk_error *err)
{
    dk_index n = *n_io;
    dk_index *order = malloc(((size_t)n + 1) * sizeof *order);
    unsigned char *gone = calloc((size_t)n + 1, 1);
    if (!order || !gone) {
        free(order);
        free(gone);
        return dk_error_set(err, DK_ERR_OUT_OF_MEMORY, "bounded biharmonic weights: out of memory");
    }
    for (dk_index i = 0; i < n; i++) order[i] = i;
    sort_base = s;
    qsort(order, (size_t)n, sizeof *order, by_x);
    sort_base = NULL;
    for (dk_index a = 0; a < n; a++) {
        bbw_sample *keep = &s[order[a]];
        if (gone[order[a]]) continue;
        int k = 1; /* handles of the group when every member is a single handle's */
        int single = keep->handle[1] < 0 && keep->weight[0] == 1.0;
        for (dk_index b = a + 1; b < n && s[order[b]].p[0] - keep->p[0] <= tol; b++) {
            const bbw_sample *o = &s[order[b]];
            if (gone[order[b]] || dist3(keep->p, o->p) > tol) continue;
            gone[order[b]] = 1;
            if (!single || o->handle[1] >= 0 || o->weight[0] != 1.0) continue;
            int known = 0;
            for (int r = 0; r < k; r++) known |= keep->handle[r] == o->handle[0];
            if (!known && k < BBW_SAMPLE_HANDLES) keep->handle[k++] = o->handle[0];
        }
        if (single && k > 1)
            for (int r = 0; r < k; r++) keep->weight[r] = 1.0 / (double)k;
    }
    dk_index w = 0;
    for (dk_index i = 0; i < n; i++)
        if (!gone[i]) s[w++] = s[i];
    *n_io = w;
    free(order);
    free(gone);
    return DK_OK;
}

dk_status bbw_sample_handles(const dk_bbw_handles *h, double step, bbw_sample **out,
                             dk_index *n_out, dk_error *err)
{
    *out = NULL;
    *n_out = 0;
    if (!(step > 0.0) || !isfinite(step))
        return dk_error_set(err, DK_ERR_DEGENERATE, "bounded biharmonic weights: the shape has "
                            "no size to sample its handles at");
    const dk_index first_bone = h->n_points, first_cage = h->n_points + h->n_bones;
    const dk_index *ct = h->cage_triangles;
    /* count first */
    size_t total = (size_t)h->n_points + (size_t)h->n_cage_vertices;
    for (dk_index b = 0; b < h->n_bones; b++)
        total += (size_t)divisions(dist3(h->bones + 6 * (size_t)b, h->bones + 6 * (size_t)b + 3),
                                   step) + 2;
    for (dk_index t = 0; t < h->n_cage_triangles; t++) {
        double longest = 0.0;
        for (int e = 0; e < 3; e++) {
            double l = dist3(h->cage_vertices + 3 * (size_t)ct[3 * (size_t)t + e],
                             h->cage_vertices + 3 * (size_t)ct[3 * (size_t)t + (e + 1) % 3]);
            longest = fmax(longest, l);
            total += (size_t)divisions(l, step); /* an edge is in two faces: counted twice */
        }
        size_t k = (size_t)divisions(longest, 2.0 * step);
        total += k * k / 2 + 1;
    }
    if (total > (size_t)INT32_MAX / 2)
        return dk_error_set(err, DK_ERR_INVALID_ARGUMENT, "bounded biharmonic weights: the "
                            "handles are too long for the resolution (%zu samples)", total);
    bbw_sample *s = malloc((total + 1) * sizeof *s);
    if (!s)
        return dk_error_set(err, DK_ERR_OUT_OF_MEMORY, "bounded biharmonic weights: out of memory");
    dk_index n = 0;
    for (dk_index i = 0; i < h->n_points; i++) {
        double one = 1.0;
        put(s, &n, h->points + 3 * (size_t)i, &i, &one, 1);
    }
    for (dk_index b = 0; b < h->n_bones; b++) {
        const double *a = h->bones + 6 * (size_t)b, *c = a + 3;
        dk_index k = dist3(a, c) > 0.0 ? divisions(dist3(a, c), step) : 0, id = first_bone + b;
        if (k == 1) k = 2; /* a midpoint of its own even where both ends are joints */
        double one = 1.0;
        for (dk_index i = 0; i <= k; i++) {
            double t = k > 0 ? (double)i / (double)k : 0.0, p[3];
            for (int x = 0; x < 3; x++) p[x] = (1.0 - t) * a[x] + t * c[x];
            put(s, &n, p, &id, &one, 1);
        }
    }
    for (dk_index v = 0; v < h->n_cage_vertices; v++) {
        dk_index id = first_cage + v;
        double one = 1.0;
        put(s, &n, h->cage_vertices + 3 * (size_t)v, &id, &one, 1);
    }
    for (dk_index t = 0; t < h->n_cage_triangles; t++) {
        const dk_index *tri = ct + 3 * (size_t)t;
        const double *P[3];
        double longest = 0.0;
        for (int e = 0; e < 3; e++) P[e] = h->cage_vertices + 3 * (size_t)tri[e];
        for (int e = 0; e < 3; e++) {
            /* each edge once: from the face where it runs from the lower to the higher index
             * (a closed cage has both directions; an edge seen only one way is kept too) */
            dk_index a = tri[e], b = tri[(e + 1) % 3];
            double l = dist3(P[e], P[(e + 1) % 3]);
            longest = fmax(longest, l);
            if (a > b) continue;
            dk_index k = divisions(l, step), hs[2] = {first_cage + a, first_cage + b};
            for (dk_index i = 1; i < k; i++) {
                double u = (double)i / (double)k, ws[2] = {1.0 - u, u}, p[3];
                for (int x = 0; x < 3; x++) p[x] = ws[0] * P[e][x] + u * P[(e + 1) % 3][x];
                put(s, &n, p, hs, ws, 2);
            }
        }
        /* a face's inside at twice the step: the edges bound it, and the points of a big
         * cage's faces would otherwise outnumber its inside's */
        dk_index k = divisions(longest, 2.0 * step);
        dk_index hs[3] = {first_cage + tri[0], first_cage + tri[1], first_cage + tri[2]};
        for (dk_index i = 1; i < k; i++)
            for (dk_index j = 1; i + j < k; j++) {
                double ws[3] = {(double)(k - i - j) / (double)k, (double)i / (double)k,
                                (double)j / (double)k}, p[3];
                for (int x = 0; x < 3; x++)
                    p[x] = ws[0] * P[0][x] + ws[1] * P[1][x] + ws[2] * P[2][x];
                put(s, &n, p, hs, ws, 3);
            }
    }
    dk_status st = merge_coincident(s, &n, 1e-6 * step, err);
    if (st != DK_OK) {
        free(s);
        return st;
    }
    *out = s;
    *n_out = n;
    return DK_OK;
}

dk_status bbw_check_held(const bbw_domain *d, const dk_bbw_handles *h, dk_error *err)
{
    dk_index nh = dk_bbw_handle_count(h);
    unsigned char *has = calloc((size_t)nh + 1, 1);
    if (!has)
        return dk_error_set(err, DK_ERR_OUT_OF_MEMORY, "bounded biharmonic weights: out of memory");
    for (dk_index i = 0; i < d->n_held; i++) {
        const bbw_sample *s = &d->samples[d->held_sample[i]];
        for (int k = 0; k < BBW_SAMPLE_HANDLES; k++)
            if (s->handle[k] >= 0 && s->weight[k] == 1.0) has[s->handle[k]] = 1;
    }
    dk_status st = DK_OK;
    for (dk_index j = 0; j < nh && st == DK_OK; j++)
        if (!has[j]) {
            char name[48];
            st = dk_error_set(err, DK_ERR_INVALID_ARGUMENT, "bounded biharmonic weights: %s has "
                              "no place of its own in the %s: it lies outside the shape, or "
                              "nearer another handle than the %s's resolution tells apart",
                              bbw_handle_name(h, j, name), d->kind == DK_BBW_VOLUME ? "volume" : "surface",
                              d->kind == DK_BBW_VOLUME ? "volume" : "mesh");
        }
    free(has);
    return st;
}

void bbw_domain_free(bbw_domain *d)
{
    if (!d) return;
    free(d->positions);
    dk_sparse_free(d->stiffness);
    free(d->mass);
    free(d->samples);
    free(d->held);
    free(d->held_sample);
    free(d->tets);
    free(d->frames);
    free(d->embed);
    free(d->embed_weight);
    memset(d, 0, sizeof *d);
}
