/* Shape matching's attachments (sm_internal.h): how strongly each free vertex is also pulled
 * to where the input puts it, and which kinematic vertices' moves off the input move that
 * place.
 *
 * The strength: a_i = smoothstep(1 - d_i / F), d_i the distance at rest from the nearest
 * kinematic vertex, F the falloff, combined with a painted map as 1 - (1 - a)(1 - map).
 * The automatic falloff (0) is half the depth of the simulated region (its farthest vertex
 * from the kinematic ones), so that its core swings freely whatever its size, and at most
 * `cap`: with the automatic cubes, half a cube's edge. What the attachment hides is the
 * crease where the clusters that straddle the border meet what does not move with them, a
 * cube's width; reaching deeper, it pulled a whole body simulated between a dragged hand
 * and its held feet along with the hand (the thighs stretched by 50% where the hand's and
 * the feet's pulls met, on the armadillo).
 *
 * The place moves with the kinematic vertices nearby. Kinematic vertices form groups: each
 * handle, and everything that follows the input (fixed, outside the region). Within a group
 * the nearest vertex's move is taken (its neighbours move alike); across groups the moves
 * are blended by each group's own falloff weight smoothstep(1 - d_ig / F). Taking the
 * nearest kinematic vertex of all would make the place jump where the nearest group changes
 * (half-way between a dragged hand and the held feet) and tear the mesh there; the blend
 * varies continuously. A vertex beyond F of every group (attached by the map alone) follows
 * its nearest kinematic vertex.
 *
 * Cost: a k-d tree and a pass over the free vertices per group (each handle, and the
 * input's), so a bind with thousands of handles pays for them (measured by the review: 0.6 s
 * at 4,000 handles on 40k vertices, 0.06 s with one). */
#include "sm_internal.h"

#include <math.h>
#include <stdint.h>
#include <stdlib.h>
#include <string.h>

#include "dk_operators.h"

void sm_attach_free(sm_attach *a)
{
    if (!a)
        return;
    free(a->a);
    free(a->start);
    free(a->vertex);
    free(a->share);
    memset(a, 0, sizeof *a);
}

static dk_status oom(dk_error *err)
{
    return dk_error_set(err, DK_ERR_OUT_OF_MEMORY, "ShapeMatching: out of memory (attachments)");
}

static double smoothstep_of(double d, double F)
{
    const double t = F > 0.0 ? 1.0 - d / F : 0.0;
    return t > 0.0 ? t * t * (3.0 - 2.0 * t) : 0.0;
}

/* For the `nq` free vertices `query` (indices), the nearest of the kinematic vertices
 * `members` (nm): its index into `hit` and the distance into `dist`. */
static dk_status nearest(const dk_mesh *m, const dk_index *members, dk_index nm,
                         const dk_index *query, dk_index nq, dk_index *hit, double *dist,
                         dk_error *err)
{
    double *pts = malloc(3 * (size_t)(nm > nq ? nm : nq) * sizeof *pts + 1);
    if (!pts)
        return oom(err);
    for (dk_index j = 0; j < nm; j++)
        memcpy(pts + 3 * (size_t)j, m->positions + 3 * (size_t)members[j], 3 * sizeof *pts);
    dk_kdtree *tree = NULL;
    dk_status st = dk_kdtree_create(pts, nm, &tree, err);
    if (st == DK_OK) {
        for (dk_index j = 0; j < nq; j++)
            memcpy(pts + 3 * (size_t)j, m->positions + 3 * (size_t)query[j], 3 * sizeof *pts);
        st = dk_kdtree_knn(tree, pts, nq, 1, hit, dist, err);
    }
    dk_kdtree_free(tree);
    free(pts);
    if (st == DK_OK)
        for (dk_index j = 0; j < nq; j++) {
            hit[j] = members[hit[j]];
            dist[j] = sqrt(dist[j]);
        }
    return st;
}

typedef struct source {
    dk_index v, w; /* free vertex v follows kinematic vertex w's move ...                  */
    double a;      /* ... with this weight                                                */
} source;

/* The groups' sources of the free vertices (pass 2 of the build); `list` grows. */
static dk_status group_sources(const dk_mesh *m, const dk_constraints *con,
                               const unsigned char *kin, double F, source **list,
                               size_t *count, dk_error *err)
{
    const dk_index n = m->n_vertices, ng = con->n_handles + 1;
    dk_index *gstart = calloc((size_t)ng + 2, sizeof *gstart);
    dk_index *gvert = malloc(((size_t)n + 1) * sizeof *gvert);
    dk_index *query = malloc(((size_t)n + 1) * sizeof *query);
    dk_index *hit = malloc(((size_t)n + 1) * sizeof *hit);
    double *dist = malloc(((size_t)n + 1) * sizeof *dist);
    size_t cap = 0;
    dk_status st = DK_OK;
    if (!gstart || !gvert || !query || !hit || !dist)
        st = oom(err);
    if (st == DK_OK) {
        for (dk_index v = 0; v < n; v++)
            if (kin[v])
                gstart[(con->role[v] >= 0 ? con->role[v] + 1 : 0) + 1]++;
        for (dk_index g = 0; g < ng; g++)
            gstart[g + 1] += gstart[g];
        for (dk_index v = 0; v < n; v++)
            if (kin[v])
                gvert[gstart[con->role[v] >= 0 ? con->role[v] + 1 : 0]++] = v;
        for (dk_index g = ng; g > 0; g--) /* back to the starts */
            gstart[g] = gstart[g - 1];
        gstart[0] = 0;
    }
    for (dk_index g = 0; g < ng && st == DK_OK; g++) {
        const dk_index *mem = gvert + gstart[g], nm = gstart[g + 1] - gstart[g];
        if (nm == 0)
            continue;
        double lo[3] = {INFINITY, INFINITY, INFINITY}, hi[3] = {-INFINITY, -INFINITY, -INFINITY};
        for (dk_index j = 0; j < nm; j++)
            for (int d = 0; d < 3; d++) {
                const double p = m->positions[3 * (size_t)mem[j] + (size_t)d];
                lo[d] = fmin(lo[d], p), hi[d] = fmax(hi[d], p);
            }
        dk_index nq = 0; /* the free vertices within F of the group's box */
        for (dk_index v = 0; v < n; v++) {
            if (kin[v])
                continue;
            double d2 = 0.0;
            for (int d = 0; d < 3; d++) {
                const double p = m->positions[3 * (size_t)v + (size_t)d];
                const double e = p < lo[d] ? lo[d] - p : p > hi[d] ? p - hi[d] : 0.0;
                d2 += e * e;
            }
            if (d2 < F * F)
                query[nq++] = v;
        }
        if (nq == 0)
            continue;
        st = nearest(m, mem, nm, query, nq, hit, dist, err);
        for (dk_index j = 0; j < nq && st == DK_OK; j++) {
            const double a = smoothstep_of(dist[j], F);
            if (!(a > 0.0))
                continue;
            if (*count == cap) {
                cap = 2 * cap + 1024;
                source *p = realloc(*list, cap * sizeof *p);
                if (!p) {
                    st = oom(err);
                    break;
                }
                *list = p;
            }
            (*list)[(*count)++] = (source){query[j], hit[j], a};
        }
    }
    free(gstart), free(gvert), free(query), free(hit), free(dist);
    return st;
}

dk_status sm_attach_build(const dk_mesh *m, const dk_constraints *con, const unsigned char *kin,
                          double falloff, double cap, const double *attach_map, sm_attach *out,
                          dk_error *err)
{
    memset(out, 0, sizeof *out);
    const dk_index n = m->n_vertices;
    out->a = calloc((size_t)n + 1, sizeof *out->a);
    out->start = calloc((size_t)n + 2, sizeof *out->start);
    dk_index *near = malloc(((size_t)n + 1) * sizeof *near);
    dk_index *freev = malloc(((size_t)n + 1) * sizeof *freev);
    dk_index *kinv = malloc(((size_t)n + 1) * sizeof *kinv);
    source *list = NULL;
    size_t count = 0;
    dk_status st = DK_OK;
    if (!out->a || !out->start || !near || !freev || !kinv)
        st = oom(err);
    dk_index nf = 0, nk = 0;
    if (st == DK_OK)
        for (dk_index v = 0; v < n; v++) {
            near[v] = -1;
            if (kin[v])
                kinv[nk++] = v;
            else
                freev[nf++] = v;
        }
    /* pass 1: the nearest kinematic vertex of all, the strength and the falloff */
    double F = falloff;
    if (st == DK_OK && nk > 0 && nf > 0) {
        dk_index *hit = malloc(((size_t)nf + 1) * sizeof *hit);
        double *dist = malloc(((size_t)nf + 1) * sizeof *dist);
        st = hit && dist ? nearest(m, kinv, nk, freev, nf, hit, dist, err) : oom(err);
        if (st == DK_OK) {
            double depth = 0.0;
            for (dk_index j = 0; j < nf; j++) {
                near[freev[j]] = hit[j];
                depth = fmax(depth, dist[j]);
            }
            if (F == 0.0)
                F = fmin(0.5 * depth, cap);
            for (dk_index j = 0; j < nf; j++)
                out->a[freev[j]] = smoothstep_of(dist[j], F);
        }
        free(hit), free(dist);
        /* pass 2: each group's nearest vertex and weight */
        if (st == DK_OK && F > 0.0)
            st = group_sources(m, con, kin, F, &list, &count, err);
    }
    if (st == DK_OK && attach_map)
        for (dk_index v = 0; v < n; v++)
            if (!kin[v])
                out->a[v] = 1.0 - (1.0 - out->a[v]) * (1.0 - attach_map[v]);
    /* the sources in rows by vertex: the groups' (in group order), or the nearest vertex
     * for one attached by the map alone */
    if (st == DK_OK) {
        for (size_t e = 0; e < count; e++)
            out->start[list[e].v + 1]++;
        for (dk_index v = 0; v < n; v++)
            if (out->a[v] > 0.0 && out->start[v + 1] == 0 && near[v] >= 0)
                out->start[v + 1] = 1;
        int64_t total = 0; /* at most a source per group and vertex: checked for dk_index */
        for (dk_index v = 0; v < n && total <= INT32_MAX; v++) {
            total += out->start[v + 1];
            out->start[v + 1] = (dk_index)(total <= INT32_MAX ? total : 0);
        }
        if (total > INT32_MAX)
            st = dk_error_set(err, DK_ERR_OUT_OF_MEMORY,
                              "ShapeMatching: more attachment sources than an index holds");
    }
    if (st == DK_OK) {
        const size_t total = (size_t)out->start[n];
        out->vertex = malloc((total + 1) * sizeof *out->vertex);
        out->share = malloc((total + 1) * sizeof *out->share);
        dk_index *fill = malloc(((size_t)n + 1) * sizeof *fill);
        if (!out->vertex || !out->share || !fill)
            st = oom(err);
        else {
            memcpy(fill, out->start, (size_t)n * sizeof *fill);
            for (size_t e = 0; e < count; e++) {
                out->vertex[fill[list[e].v]] = list[e].w;
                out->share[fill[list[e].v]++] = list[e].a;
            }
            for (dk_index v = 0; v < n; v++) {
                const dk_index a = out->start[v], b = out->start[v + 1];
                if (b > a && fill[v] == a) { /* the map's: the nearest */
                    out->vertex[a] = near[v];
                    out->share[a] = 1.0;
                    continue;
                }
                double sum = 0.0;
                for (dk_index t = a; t < b; t++)
                    sum += out->share[t];
                for (dk_index t = a; t < b; t++)
                    out->share[t] /= sum;
            }
        }
        free(fill);
    }
    free(near), free(freev), free(kinv), free(list);
    if (st != DK_OK)
        sm_attach_free(out);
    return st;
}
