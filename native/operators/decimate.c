/* DeformKit: simplification by half-edge collapses in quadric-error order, and the
 * prolongation back to the mesh (dk_operators.h: dk_decimate, dk_decimation_prolong).
 *
 * The working mesh is the input's triangles, rewritten in place as vertices go: each
 * vertex keeps the list of its triangles (dead ones dropped lazily), its quadric, and its
 * best collapse (target and cost), kept in an indexed heap (one entry per vertex that has
 * a collapse, moved when its cost changes). A collapse u -> v kills the triangles on the edge, moves u's others to
 * v, adds u's quadric to v's and recomputes the best collapse of v and its neighbours (the
 * only vertices whose neighbourhoods changed). Quadrics are taken in coordinates centred on
 * the bounding box and divided by its diagonal: costs are then free of the mesh's units and
 * placement except for rounding. Ties go to the lower vertex number: the result is
 * deterministic. */
#include "dk_operators.h"

#include <math.h>
#include <stdint.h>
#include <stdlib.h>
#include <string.h>

#define MAX_VALENCE 16
#define MAX_RING 64 /* neighbours a check looks at; a vertex with more is not collapsed */
/* a collapse may not leave a triangle less compact than this (4 sqrt(3) area / sum of
 * squared edges: 1 equilateral) unless it was already worse: slivers make poor cotangent
 * weights on the coarse level */
#define MIN_COMPACTNESS 0.05

typedef struct heap_entry {
    double cost;
    dk_index v;
} heap_entry;

typedef struct work {
    const double *p; /* the mesh's positions */
    dk_index n, nf;
    dk_index *f;     /* nf x 3, rewritten by collapses */
    unsigned char *face_alive, *alive, *locked, *bnd;
    const int *cls;
    /* per-vertex triangle lists in one pool: v's are pool[off[v] .. off[v] + cnt[v] - 1] */
    dk_index *pool;
    size_t pool_n, pool_cap, *off;
    dk_index *cnt, *cap;
    double *q;       /* n x 10: symmetric 4 x 4 quadrics, upper triangle */
    double *x;       /* n x 3: normalised coordinates for the quadrics */
    dk_index *best;  /* n: best collapse target, -1 none */
    double *best_cost; /* n: its cost */
    heap_entry *heap; /* the vertices with a collapse, a binary heap on (best_cost, vertex);
                        each entry holds its cost, so that a sift reads the heap alone */
    dk_index *pos;   /* n: a vertex's place in heap, -1 when not there */
    dk_index heap_n;
    dk_index alive_count;
} work;

static int entry_less(heap_entry a, heap_entry b)
{
    return a.cost < b.cost || (a.cost == b.cost && a.v < b.v);
}

static void heap_place(work *w, dk_index i, heap_entry e)
{
    w->heap[i] = e;
    w->pos[e.v] = i;
}

static void sift_up(work *w, dk_index i)
{
    const heap_entry e = w->heap[i];
    while (i > 0) {
        const dk_index parent = (i - 1) / 2;
        if (!entry_less(e, w->heap[parent]))
            break;
        heap_place(w, i, w->heap[parent]);
        i = parent;
    }
    heap_place(w, i, e);
}

static void sift_down(work *w, dk_index i)
{
    const heap_entry e = w->heap[i];
    const dk_index n = w->heap_n;
    for (;;) {
        dk_index c = 2 * i + 1;
        if (c >= n)
            break;
        if (c + 1 < n && entry_less(w->heap[c + 1], w->heap[c]))
            c++;
        if (!entry_less(w->heap[c], e))
            break;
        heap_place(w, i, w->heap[c]);
        i = c;
    }
    heap_place(w, i, e);
}

/* v's entry after its best collapse changed (best[v] < 0: none, taken out) */
static void heap_update(work *w, dk_index v)
{
    dk_index i = w->pos[v];
    if (w->best[v] < 0) {
        if (i < 0)
            return;
        w->pos[v] = -1;
        const heap_entry last = w->heap[--w->heap_n];
        if (i == w->heap_n)
            return;
        heap_place(w, i, last);
        sift_up(w, i);
        sift_down(w, w->pos[last.v]);
        return;
    }
    if (i < 0)
        i = w->heap_n++;
    heap_place(w, i, (heap_entry){w->best_cost[v], v});
    sift_up(w, i);
    sift_down(w, w->pos[v]);
}

/* appends triangle t to v's list, moving the list to the pool's end when it is full */
static int list_add(work *w, dk_index v, dk_index t)
{
    if (w->cnt[v] == w->cap[v]) {
        const size_t cap = 2 * (size_t)w->cap[v] + 4;
        if (w->pool_n + cap > w->pool_cap) {
            size_t pc = (w->pool_n + cap) * 2;
            dk_index *np = realloc(w->pool, pc * sizeof *np);
            if (!np)
                return -1;
            w->pool = np;
            w->pool_cap = pc;
        }
        memcpy(w->pool + w->pool_n, w->pool + w->off[v], (size_t)w->cnt[v] * sizeof *w->pool);
        w->off[v] = w->pool_n;
        w->pool_n += cap;
        w->cap[v] = (dk_index)cap;
    }
    w->pool[w->off[v] + (size_t)w->cnt[v]++] = t;
    return 0;
}

static void list_compact(work *w, dk_index v)
{
    dk_index *l = w->pool + w->off[v], k = 0;
    for (dk_index i = 0; i < w->cnt[v]; i++)
        if (w->face_alive[l[i]])
            l[k++] = l[i];
    w->cnt[v] = k;
}

static int has(const dk_index *t, dk_index v)
{
    return t[0] == v || t[1] == v || t[2] == v;
}

/* v's distinct neighbours over its live triangles into nb (at most MAX_RING); -1 when more */
static int neighbours(const work *w, dk_index v, dk_index *nb)
{
    int k = 0;
    const dk_index *l = w->pool + w->off[v];
    for (dk_index i = 0; i < w->cnt[v]; i++) {
        if (!w->face_alive[l[i]])
            continue;
        const dk_index *t = w->f + 3 * (size_t)l[i];
        for (int c = 0; c < 3; c++) {
            const dk_index a = t[c];
            if (a == v)
                continue;
            int seen = 0;
            for (int j = 0; j < k && !seen; j++)
                seen = nb[j] == a;
            if (!seen) {
                if (k == MAX_RING)
                    return -1;
                nb[k++] = a;
            }
        }
    }
    return k;
}

static void sub3(const double *a, const double *b, double *d)
{
    d[0] = a[0] - b[0];
    d[1] = a[1] - b[1];
    d[2] = a[2] - b[2];
}

static void cross3(const double *a, const double *b, double *c)
{
    c[0] = a[1] * b[2] - a[2] * b[1];
    c[1] = a[2] * b[0] - a[0] * b[2];
    c[2] = a[0] * b[1] - a[1] * b[0];
}

static double dot3(const double *a, const double *b)
{
    return a[0] * b[0] + a[1] * b[1] + a[2] * b[2];
}

/* twice the area vector of (a, b, c), its compactness and whether it is degenerate */
static int triangle_shape(const double *a, const double *b, const double *c, double *normal,
                          double *compact)
{
    double e0[3], e1[3], e2[3];
    sub3(b, a, e0);
    sub3(c, a, e1);
    sub3(c, b, e2);
    cross3(e0, e1, normal);
    const double l0 = dot3(e0, e0), l1 = dot3(e1, e1), l2 = dot3(e2, e2);
    const double twice_area = sqrt(dot3(normal, normal)), sum = l0 + l1 + l2;
    *compact = sum > 0.0 ? 2.0 * sqrt(3.0) * twice_area / sum : 0.0;
    return dk_triangle_degenerate(a, b, c, twice_area, fmax(l0, fmax(l1, l2)));
}

static dk_index lu_face(const work *w, dk_index v, dk_index i)
{
    return w->pool[w->off[v] + (size_t)i];
}

/* the live triangles with the edge (a, b) */
static int edge_triangles(const work *w, dk_index a, dk_index b)
{
    int k = 0;
    for (dk_index i = 0; i < w->cnt[a]; i++) {
        const dk_index f = lu_face(w, a, i);
        k += w->face_alive[f] && has(w->f + 3 * (size_t)f, b);
    }
    return k;
}

/* Whether collapsing u into v keeps the mesh what it was (dk_operators.h, dk_decimate). */
static int collapse_ok(const work *w, dk_index u, dk_index v, dk_index *nbu, int *ku_out)
{
    dk_index nbv[MAX_RING];
    const int ku = neighbours(w, u, nbu), kv = neighbours(w, v, nbv);
    *ku_out = ku;
    if (ku < 0 || kv < 0)
        return 0;
    int shared = 0;
    const dk_index *lu = w->pool + w->off[u];
    for (dk_index i = 0; i < w->cnt[u]; i++)
        if (w->face_alive[lu[i]] && has(w->f + 3 * (size_t)lu[i], v))
            shared++;
    if (shared < 1 || shared > 2)
        return 0;
    /* a boundary vertex moves along its boundary only; an edge between two boundary
     * vertices that is not itself a boundary edge would pinch */
    if ((w->bnd[u] && shared != 1) || (!w->bnd[u] && shared != 2))
        return 0;
    int common = 0, uni = ku;
    for (int j = 0; j < kv; j++) {
        int in = 0;
        for (int i = 0; i < ku && !in; i++)
            in = nbu[i] == nbv[j];
        common += in;
        uni += !in;
    }
    if (common != shared) /* the link condition */
        return 0;
    if (shared == 1) { /* on a boundary: not the part's last triangle (x's edges to u and v
                        * both on the boundary too: the collapse would leave no triangle) */
        dk_index x = -1;
        for (dk_index i = 0; i < w->cnt[u] && x < 0; i++) {
            const dk_index *t = w->f + 3 * (size_t)lu_face(w, u, i);
            if (w->face_alive[lu_face(w, u, i)] && has(t, v))
                x = t[0] != u && t[0] != v ? t[0] : t[1] != u && t[1] != v ? t[1] : t[2];
        }
        if (x >= 0 && edge_triangles(w, u, x) == 1 && edge_triangles(w, v, x) == 1)
            return 0;
    }
    if (uni - 2 > MAX_VALENCE)
        return 0;
    const double *pv = w->p + 3 * (size_t)v;
    const dk_index *lv = w->pool + w->off[v];
    for (dk_index i = 0; i < w->cnt[u]; i++) {
        if (!w->face_alive[lu[i]])
            continue;
        const dk_index *t = w->f + 3 * (size_t)lu[i];
        if (has(t, v))
            continue;
        const double *c[3], *c_new[3];
        dk_index a = -1, b = -1;
        for (int k = 0; k < 3; k++) {
            c[k] = w->p + 3 * (size_t)t[k];
            c_new[k] = t[k] == u ? pv : c[k];
            if (t[k] != u) {
                if (a < 0)
                    a = t[k];
                else
                    b = t[k];
            }
        }
        double n0[3], n1[3], q0, q1;
        const int degenerate_before = triangle_shape(c[0], c[1], c[2], n0, &q0);
        if (triangle_shape(c_new[0], c_new[1], c_new[2], n1, &q1))
            return 0;
        if (degenerate_before || dot3(n0, n1) <= 0.0)
            return 0; /* turned over (or its direction unknown) */
        if (q1 < MIN_COMPACTNESS && q1 < q0)
            return 0;
        for (dk_index j = 0; j < w->cnt[v]; j++) { /* would duplicate a triangle of v's */
            if (!w->face_alive[lv[j]])
                continue;
            const dk_index *g = w->f + 3 * (size_t)lv[j];
            if (has(g, a) && has(g, b))
                return 0;
        }
    }
    return 1;
}

static double quadric_at(const double *q, const double *x)
{
    const double a = x[0], b = x[1], c = x[2];
    return q[0] * a * a + 2.0 * q[1] * a * b + 2.0 * q[2] * a * c + 2.0 * q[3] * a +
           q[4] * b * b + 2.0 * q[5] * b * c + 2.0 * q[6] * b + q[7] * c * c +
           2.0 * q[8] * c + q[9];
}

static void quadric_add_plane(double *q, const double *nrm, double d, double weight)
{
    const double a = nrm[0], b = nrm[1], c = nrm[2];
    q[0] += weight * a * a;
    q[1] += weight * a * b;
    q[2] += weight * a * c;
    q[3] += weight * a * d;
    q[4] += weight * b * b;
    q[5] += weight * b * c;
    q[6] += weight * b * d;
    q[7] += weight * c * c;
    q[8] += weight * c * d;
    q[9] += weight * d * d;
}

/* The cost of collapsing u into v (INFINITY: other classes): the quadric error plus the
 * edge's length^4 (both in units of the diagonal^4). Where the surface is flat on the
 * edge's scale, as a cylinder is along its axis, the quadric is ~0 and the shortest edge
 * goes first, so that the coarse triangles stay about as long as wide -- a deformation
 * needs them to bend where the mesh does; the quadric alone strings a tube's triangles
 * along its whole length (measured: a coarse tube that bent 8% of the diagonal off). */
static double collapse_cost(const work *w, dk_index u, dk_index v)
{
    if ((w->cls ? w->cls[v] : 0) != (w->cls ? w->cls[u] : 0))
        return INFINITY;
    double qs[10], e[3];
    for (int j = 0; j < 10; j++)
        qs[j] = w->q[10 * (size_t)u + j] + w->q[10 * (size_t)v + j];
    sub3(w->x + 3 * (size_t)u, w->x + 3 * (size_t)v, e);
    const double l2 = dot3(e, e);
    return fmax(quadric_at(qs, w->x + 3 * (size_t)v), 0.0) + l2 * l2;
}

/* u's cheapest collapse, pushed on the heap (none: not pushed); -1 on exhausted memory.
 * checked: the cheapest that collapse_ok accepts; else the cheapest, checked when it is
 * popped (most are never popped: the checks are what costs) */
static int update_candidate_ring(work *w, dk_index u, const dk_index *nb, int k, int checked);

static int update_candidate(work *w, dk_index u, int checked)
{
    if (!w->alive[u] || w->locked[u]) {
        w->best[u] = -1;
        heap_update(w, u);
        return 0;
    }
    list_compact(w, u);
    dk_index nb[MAX_RING];
    return update_candidate_ring(w, u, nb, neighbours(w, u, nb), checked);
}

/* update_candidate for a live, unlocked u whose ring (k entries, -1: too many) is nb */
static int update_candidate_ring(work *w, dk_index u, const dk_index *nb, int k, int checked)
{
    double cost[MAX_RING];
    w->best[u] = -1;
    if (k <= 0) {
        heap_update(w, u);
        return 0;
    }
    for (int i = 0; i < k; i++)
        cost[i] = collapse_cost(w, u, nb[i]);
    for (;;) { /* the cheapest valid one */
        int bi = -1;
        for (int i = 0; i < k; i++)
            if (cost[i] < INFINITY && (bi < 0 || cost[i] < cost[bi] ||
                                       (cost[i] == cost[bi] && nb[i] < nb[bi])))
                bi = i;
        if (bi < 0) {
            heap_update(w, u);
            return 0;
        }
        dk_index ring[MAX_RING];
        int kr;
        if (!checked || collapse_ok(w, u, nb[bi], ring, &kr)) {
            w->best[u] = nb[bi];
            w->best_cost[u] = cost[bi];
            heap_update(w, u);
            return 0;
        }
        cost[bi] = INFINITY;
    }
}

/* the point of triangle (a, b, c) nearest to p, as barycentric weights (Ericson's regions) */
static void nearest_on_triangle(const double *p, const double *a, const double *b,
                                const double *c, double wt[3])
{
    double ab[3], ac[3], ap[3], bp[3], cp[3];
    sub3(b, a, ab);
    sub3(c, a, ac);
    sub3(p, a, ap);
    const double d1 = dot3(ab, ap), d2 = dot3(ac, ap);
    if (d1 <= 0.0 && d2 <= 0.0) {
        wt[0] = 1.0, wt[1] = 0.0, wt[2] = 0.0;
        return;
    }
    sub3(p, b, bp);
    const double d3 = dot3(ab, bp), d4 = dot3(ac, bp);
    if (d3 >= 0.0 && d4 <= d3) {
        wt[0] = 0.0, wt[1] = 1.0, wt[2] = 0.0;
        return;
    }
    const double vc = d1 * d4 - d3 * d2;
    if (vc <= 0.0 && d1 >= 0.0 && d3 <= 0.0) {
        const double t = d1 / (d1 - d3);
        wt[0] = 1.0 - t, wt[1] = t, wt[2] = 0.0;
        return;
    }
    sub3(p, c, cp);
    const double d5 = dot3(ab, cp), d6 = dot3(ac, cp);
    if (d6 >= 0.0 && d5 <= d6) {
        wt[0] = 0.0, wt[1] = 0.0, wt[2] = 1.0;
        return;
    }
    const double vb = d5 * d2 - d1 * d6;
    if (vb <= 0.0 && d2 >= 0.0 && d6 <= 0.0) {
        const double t = d2 / (d2 - d6);
        wt[0] = 1.0 - t, wt[1] = 0.0, wt[2] = t;
        return;
    }
    const double va = d3 * d6 - d5 * d4;
    if (va <= 0.0 && d4 - d3 >= 0.0 && d5 - d6 >= 0.0) {
        const double t = (d4 - d3) / ((d4 - d3) + (d5 - d6));
        wt[0] = 0.0, wt[1] = 1.0 - t, wt[2] = t;
        return;
    }
    const double den = va + vb + vc;
    if (!(den > 0.0)) { /* degenerate: the nearest corner */
        wt[0] = 1.0, wt[1] = 0.0, wt[2] = 0.0;
        return;
    }
    wt[1] = fmax(vb / den, 0.0);
    wt[2] = fmax(vc / den, 0.0);
    wt[0] = fmax(1.0 - wt[1] - wt[2], 0.0);
    const double sum = wt[0] + wt[1] + wt[2]; /* >= 1 - rounding: no division by ~0 */
    wt[0] /= sum, wt[1] /= sum, wt[2] /= sum;
}

/* Collapses u into v, recording u's carriers as removal k; -1 on exhausted memory. */
static int collapse(work *w, dk_decimation *d, dk_index u, dk_index v, const dk_index *nbu,
                    int ku)
{
    const dk_index k = d->n_removed++;
    d->removed[k] = u;
    dk_index *car = d->carrier + 3 * (size_t)k;
    double *wt = d->weight + 3 * (size_t)k, best = INFINITY;
    car[0] = car[1] = car[2] = v;
    wt[0] = 1.0, wt[1] = wt[2] = 0.0;
    const double *pu = w->p + 3 * (size_t)u;
    const dk_index *lu = w->pool + w->off[u];
    for (dk_index i = 0; i < w->cnt[u]; i++) { /* the nearest triangle u leaves to v */
        const dk_index *t = w->f + 3 * (size_t)lu[i];
        if (!w->face_alive[lu[i]] || has(t, v))
            continue;
        dk_index c[3];
        for (int j = 0; j < 3; j++)
            c[j] = t[j] == u ? v : t[j];
        double bw[3], near[3];
        nearest_on_triangle(pu, w->p + 3 * (size_t)c[0], w->p + 3 * (size_t)c[1],
                            w->p + 3 * (size_t)c[2], bw);
        for (int j = 0; j < 3; j++)
            near[j] = bw[0] * w->p[3 * (size_t)c[0] + j] + bw[1] * w->p[3 * (size_t)c[1] + j] +
                      bw[2] * w->p[3 * (size_t)c[2] + j];
        double dd[3];
        sub3(pu, near, dd);
        const double dist = dot3(dd, dd);
        if (dist < best) {
            best = dist;
            memcpy(car, c, sizeof c);
            memcpy(wt, bw, sizeof bw);
        }
    }
    const dk_index nu = w->cnt[u]; /* nbu: u's ring as collapse_ok read it (ku <= MAX_RING) */
    for (dk_index i = 0; i < nu; i++) {
        const dk_index t = w->pool[w->off[u] + (size_t)i];
        if (!w->face_alive[t])
            continue;
        dk_index *tri = w->f + 3 * (size_t)t;
        if (has(tri, v)) {
            w->face_alive[t] = 0;
            continue;
        }
        for (int j = 0; j < 3; j++)
            if (tri[j] == u)
                tri[j] = v;
        if (list_add(w, v, t) < 0)
            return -1;
    }
    w->cnt[u] = 0;
    for (int j = 0; j < 10; j++)
        w->q[10 * (size_t)v + j] += w->q[10 * (size_t)u + j];
    w->alive[u] = 0;
    w->alive_count--;
    w->best[u] = -1;
    heap_update(w, u);
    /* whose best collapse can have changed: v's (its quadric and ring); a neighbour's whose
     * best went to u or v (gone, or dearer: v's quadric only grows); u's former neighbours
     * gained v, one cost to compare. The others' costs and rings are as they were. */
    dk_index nb[MAX_RING];
    list_compact(w, v);
    const int kv = neighbours(w, v, nb);
    if (w->locked[v]) {
        w->best[v] = -1;
        heap_update(w, v);
    } else if (update_candidate_ring(w, v, nb, kv, 0) < 0) {
        return -1;
    }
    for (int i = 0; i < kv; i++) { /* kv <= MAX_VALENCE: collapse_ok checked it */
        const dk_index x = nb[i];
        if (w->best[x] == u || w->best[x] == v) {
            if (update_candidate(w, x, 0) < 0)
                return -1;
            continue;
        }
        int was_u = 0;
        for (int j = 0; j < ku && !was_u; j++)
            was_u = nbu[j] == x;
        if (!was_u || !w->alive[x] || w->locked[x])
            continue;
        const double c = collapse_cost(w, x, v);
        if (w->best[x] < 0 ? c < INFINITY
                           : c < w->best_cost[x] || (c == w->best_cost[x] && v < w->best[x])) {
            w->best[x] = v;
            w->best_cost[x] = c;
            heap_update(w, x);
        }
    }
    return 0;
}

/* Vertices on a non-manifold edge, with other than two boundary edges, or whose triangles
 * form more than one fan are never removed. */
/* How many fans v's triangles form: groups joined across the edges at v that two
 * triangles share (a manifold vertex has one; two cones tip to tip have two). More than
 * MAX_RING triangles: counted as many (such a vertex is never removed anyway: valence). */
static int fans(const dk_mesh *m, dk_index v)
{
    const dk_index t0 = m->vf_start[v], nt = m->vf_start[v + 1] - t0;
    if (nt > MAX_RING)
        return 2;
    int group[MAX_RING];
    for (int i = 0; i < nt; i++)
        group[i] = i;
    for (dk_index r = m->ring_start[v]; r < m->ring_start[v + 1]; r++) {
        const dk_index e = m->ring_edge[r];
        if (m->edge_face_count[e] != 2)
            continue;
        int a = -1, b = -1; /* the two triangles' places in v's list, their groups joined */
        for (int i = 0; i < nt; i++) {
            const dk_index f = m->vf_index[t0 + i];
            if (f == m->edge_faces[2 * (size_t)e])
                a = i;
            if (f == m->edge_faces[2 * (size_t)e + 1])
                b = i;
        }
        if (a < 0 || b < 0)
            continue;
        const int ga = group[a], gb = group[b];
        if (ga != gb)
            for (int i = 0; i < nt; i++)
                if (group[i] == gb)
                    group[i] = ga;
    }
    int count = 0;
    for (int i = 0; i < nt; i++)
        count += group[i] == i;
    return count;
}

static void lock_nonmanifold(const dk_mesh *m, work *w)
{
    for (dk_index v = 0; v < m->n_vertices; v++) {
        int boundary_edges = 0;
        for (dk_index r = m->ring_start[v]; r < m->ring_start[v + 1]; r++) {
            const dk_index c = m->edge_face_count[m->ring_edge[r]];
            if (c > 2)
                w->locked[v] = 1;
            boundary_edges += c == 1;
        }
        if (boundary_edges != 0 && boundary_edges != 2)
            w->locked[v] = 1;
        if (!w->locked[v] && fans(m, v) > 1)
            w->locked[v] = 1;
    }
}

void dk_decimation_free(dk_decimation *d)
{
    if (!d)
        return;
    free(d->kept);
    free(d->coarse_of);
    free(d->faces);
    free(d->removed);
    free(d->carrier);
    free(d->weight);
    free(d);
}

static void work_free(work *w)
{
    free(w->f);
    free(w->face_alive);
    free(w->alive);
    free(w->locked);
    free(w->bnd);
    free(w->pool);
    free(w->off);
    free(w->cnt);
    free(w->cap);
    free(w->q);
    free(w->x);
    free(w->best);
    free(w->best_cost);
    free(w->heap);
    free(w->pos);
}

static dk_status oom(dk_error *err)
{
    return dk_error_set(err, DK_ERR_OUT_OF_MEMORY, "decimate: out of memory");
}

dk_status dk_decimate(const dk_mesh *mesh, const int *vertex_class, dk_index target_vertices,
                      dk_decimation **out, dk_error *err)
{
    return dk_decimate_progress(mesh, vertex_class, target_vertices, NULL, NULL, out, err);
}

dk_status dk_decimate_progress(const dk_mesh *mesh, const int *vertex_class,
                               dk_index target_vertices,
                               int (*progress)(void *user, double done, double total),
                               void *user, dk_decimation **out, dk_error *err)
{
    if (out)
        *out = NULL;
    if (!mesh || !out)
        return dk_error_set(err, DK_ERR_INVALID_ARGUMENT,
                            "decimate: mesh and output must not be NULL");
    if (target_vertices < 1)
        return dk_error_set(err, DK_ERR_INVALID_ARGUMENT,
                            "decimate: target_vertices is %ld, must be >= 1",
                            (long)target_vertices);
    const dk_index n = mesh->n_vertices, nf = mesh->n_faces;
    work w;
    memset(&w, 0, sizeof w);
    w.p = mesh->positions;
    w.n = n;
    w.nf = nf;
    w.cls = vertex_class;
    w.alive_count = n;
    const size_t nn = (size_t)n + 1;
    w.f = malloc(3 * (size_t)nf * sizeof *w.f + 1);
    w.face_alive = malloc((size_t)nf + 1);
    w.alive = malloc(nn);
    w.locked = calloc(nn, 1);
    w.bnd = malloc(nn);
    w.pool_cap = 3 * (size_t)nf + 4 * nn;
    w.pool = malloc(w.pool_cap * sizeof *w.pool);
    w.off = malloc(nn * sizeof *w.off);
    w.cnt = malloc(nn * sizeof *w.cnt);
    w.cap = malloc(nn * sizeof *w.cap);
    w.q = calloc(10 * nn, sizeof *w.q);
    w.x = malloc(3 * nn * sizeof *w.x);
    w.best = malloc(nn * sizeof *w.best);
    w.best_cost = malloc(nn * sizeof *w.best_cost);
    w.heap = malloc(nn * sizeof *w.heap);
    w.pos = malloc(nn * sizeof *w.pos);
    dk_decimation *d = calloc(1, sizeof *d);
    if (d) {
        d->removed = malloc(nn * sizeof *d->removed);
        d->carrier = malloc(3 * nn * sizeof *d->carrier);
        d->weight = malloc(3 * nn * sizeof *d->weight);
        d->coarse_of = malloc(nn * sizeof *d->coarse_of);
    }
    if (!w.f || !w.face_alive || !w.alive || !w.locked || !w.bnd || !w.pool || !w.off ||
        !w.cnt || !w.cap || !w.q || !w.x || !w.best || !w.best_cost || !w.heap || !w.pos || !d || !d->removed ||
        !d->carrier || !d->weight || !d->coarse_of) {
        work_free(&w);
        dk_decimation_free(d);
        return oom(err);
    }
    d->n_vertices = n;
    memcpy(w.f, mesh->faces, 3 * (size_t)nf * sizeof *w.f);
    memset(w.face_alive, 1, (size_t)nf);
    memset(w.alive, 1, (size_t)n);
    memset(w.pos, 0xff, nn * sizeof *w.pos); /* -1: in no heap place */
    for (dk_index v = 0; v < n; v++) {
        w.bnd[v] = mesh->is_boundary_vertex[v];
        w.locked[v] = vertex_class && vertex_class[v] < 0;
    }
    lock_nonmanifold(mesh, &w);
    /* the lists, with room to grow: a vertex's list starts at its triangles of the mesh */
    size_t o = 0;
    for (dk_index v = 0; v < n; v++) {
        const dk_index c = mesh->vf_start[v + 1] - mesh->vf_start[v];
        w.off[v] = o;
        w.cnt[v] = c;
        w.cap[v] = c + 4;
        memcpy(w.pool + o, mesh->vf_index + mesh->vf_start[v], (size_t)c * sizeof *w.pool);
        o += (size_t)c + 4;
    }
    w.pool_n = o;
    /* normalised coordinates: centred on the bounding box, in units of its diagonal */
    double lo[3] = {INFINITY, INFINITY, INFINITY}, hi[3] = {-INFINITY, -INFINITY, -INFINITY};
    for (dk_index v = 0; v < n; v++)
        for (int j = 0; j < 3; j++) {
            lo[j] = fmin(lo[j], w.p[3 * (size_t)v + j]);
            hi[j] = fmax(hi[j], w.p[3 * (size_t)v + j]);
        }
    double diag = 0.0, mid[3];
    for (int j = 0; j < 3; j++) {
        mid[j] = 0.5 * (lo[j] + hi[j]);
        diag += (hi[j] - lo[j]) * (hi[j] - lo[j]);
    }
    diag = sqrt(diag);
    if (!(diag > 0.0) || !isfinite(diag))
        diag = 1.0;
    for (dk_index v = 0; v < n; v++)
        for (int j = 0; j < 3; j++)
            w.x[3 * (size_t)v + j] = (w.p[3 * (size_t)v + j] - mid[j]) / diag;
    for (dk_index f = 0; f < nf; f++) { /* face planes, weighted by area */
        const dk_index *t = mesh->faces + 3 * (size_t)f;
        const double *a = w.x + 3 * (size_t)t[0], *b = w.x + 3 * (size_t)t[1],
                     *c = w.x + 3 * (size_t)t[2];
        double e0[3], e1[3], nr[3];
        sub3(b, a, e0);
        sub3(c, a, e1);
        cross3(e0, e1, nr);
        const double len = sqrt(dot3(nr, nr));
        if (!(len > 0.0))
            continue;
        for (int j = 0; j < 3; j++)
            nr[j] /= len;
        const double dd = -dot3(nr, a);
        for (int k = 0; k < 3; k++)
            quadric_add_plane(w.q + 10 * (size_t)t[k], nr, dd, 0.5 * len);
        for (int k = 0; k < 3; k++) { /* a boundary edge's plane, perpendicular to f */
            const dk_index e = mesh->face_edges[3 * (size_t)f + (size_t)k];
            if (mesh->edge_face_count[e] != 1)
                continue;
            const dk_index i0 = t[(k + 1) % 3], i1 = t[(k + 2) % 3];
            double ed[3], m[3];
            sub3(w.x + 3 * (size_t)i1, w.x + 3 * (size_t)i0, ed);
            cross3(ed, nr, m);
            const double ml = sqrt(dot3(m, m));
            if (!(ml > 0.0))
                continue;
            for (int j = 0; j < 3; j++)
                m[j] /= ml;
            const double md = -dot3(m, w.x + 3 * (size_t)i0), weight = 10.0 * dot3(ed, ed);
            quadric_add_plane(w.q + 10 * (size_t)i0, m, md, weight);
            quadric_add_plane(w.q + 10 * (size_t)i1, m, md, weight);
        }
    }
    int failed = 0, cancelled = 0;
    /* the first candidates from the mesh's rings (in order in memory), the heap built at once */
    for (dk_index v = 0; v < n; v++) {
        w.best[v] = -1;
        if (w.locked[v])
            continue;
        for (dk_index r = mesh->ring_start[v]; r < mesh->ring_start[v + 1]; r++) {
            const dk_index x = mesh->ring_index[r];
            const double c = collapse_cost(&w, v, x);
            if (c < INFINITY && (w.best[v] < 0 || c < w.best_cost[v])) /* ring ascending */
                w.best[v] = x, w.best_cost[v] = c;
        }
        if (w.best[v] >= 0)
            heap_place(&w, w.heap_n++, (heap_entry){w.best_cost[v], v});
    }
    for (dk_index i = w.heap_n / 2 - 1; i >= 0; i--)
        sift_down(&w, i);
    const double total = (double)(n > target_vertices ? n - target_vertices : 0);
    while (!failed && w.alive_count > target_vertices && w.heap_n > 0) {
        if (progress && progress(user, (double)d->n_removed, total)) {
            cancelled = 1;
            break;
        }
        const dk_index u = w.heap[0].v, v = w.best[u];
        dk_index ring[MAX_RING];
        int kr = 0;
        if (!w.alive[v] || !collapse_ok(&w, u, v, ring, &kr)) { /* its cheapest valid one */
            failed = update_candidate(&w, u, 1) < 0;
            continue;
        }
        failed = collapse(&w, d, u, v, ring, kr) < 0;
    }
    if (!failed && !cancelled) { /* the coarse mesh */
        d->n_kept = w.alive_count;
        d->kept = malloc(((size_t)d->n_kept + 1) * sizeof *d->kept);
        dk_index nfc = 0;
        for (dk_index f = 0; f < nf; f++)
            nfc += w.face_alive[f];
        d->faces = malloc((3 * (size_t)nfc + 1) * sizeof *d->faces);
        failed = !d->kept || !d->faces;
        if (!failed) {
            dk_index c = 0;
            for (dk_index v = 0; v < n; v++) {
                d->coarse_of[v] = w.alive[v] ? c : -1;
                if (w.alive[v])
                    d->kept[c++] = v;
            }
            for (dk_index f = 0; f < nf; f++)
                if (w.face_alive[f]) {
                    for (int k = 0; k < 3; k++)
                        d->faces[3 * (size_t)d->n_faces + (size_t)k] =
                            d->coarse_of[w.f[3 * (size_t)f + (size_t)k]];
                    d->n_faces++;
                }
        }
    }
    work_free(&w);
    if (failed || cancelled) {
        dk_decimation_free(d);
        if (cancelled) /* the callback's own message (a bind's phase) stays */
            return err && err->message[0] ? (err->status = DK_ERR_CANCELLED)
                                          : dk_error_set(err, DK_ERR_CANCELLED,
                                                         "decimate: cancelled");
        return oom(err);
    }
    *out = d;
    return DK_OK;
}

void dk_decimation_prolong(const dk_decimation *d, const double *pose, const double *coarse,
                           const double *coarse_rotations, double *fine, double *scratch)
{
    const int rotate = coarse_rotations != NULL;
    for (dk_index c = 0; c < d->n_kept; c++) {
        const size_t v = (size_t)d->kept[c];
        memcpy(fine + 3 * v, coarse + 3 * (size_t)c, 3 * sizeof *fine);
        if (rotate)
            dk_rotation_quaternion(coarse_rotations + 9 * (size_t)c, scratch + 4 * v);
    }
    for (dk_index k = d->n_removed - 1; k >= 0; k--) {
        const size_t u = (size_t)d->removed[k];
        const dk_index *car = d->carrier + 3 * (size_t)k;
        const double *wt = d->weight + 3 * (size_t)k, *pu = pose + 3 * u;
        double x[3] = {0.0, 0.0, 0.0};
        if (rotate) { /* the carriers' rotations blended, signs aligned to the first's */
            double *qu = scratch + 4 * u;
            const double *q0 = scratch + 4 * (size_t)car[0];
            qu[0] = qu[1] = qu[2] = qu[3] = 0.0;
            for (int i = 0; i < 3; i++) {
                const double *qi = scratch + 4 * (size_t)car[i];
                const double s = (qi[0] * q0[0] + qi[1] * q0[1] + qi[2] * q0[2] +
                                  qi[3] * q0[3]) < 0.0 ? -wt[i] : wt[i];
                for (int j = 0; j < 4; j++)
                    qu[j] += s * qi[j];
            }
            const double len = sqrt(qu[0] * qu[0] + qu[1] * qu[1] + qu[2] * qu[2] + qu[3] * qu[3]);
            if (len > 1e-12)
                for (int j = 0; j < 4; j++)
                    qu[j] /= len;
            else
                memcpy(qu, q0, 4 * sizeof *qu);
        }
        for (int i = 0; i < 3; i++) {
            const size_t c = (size_t)car[i];
            if (wt[i] == 0.0)
                continue;
            double off[3];
            sub3(pu, pose + 3 * c, off);
            if (rotate) {
                double r[9], ro[3];
                dk_quaternion_rotation(scratch + 4 * c, r);
                ro[0] = r[0] * off[0] + r[1] * off[1] + r[2] * off[2];
                ro[1] = r[3] * off[0] + r[4] * off[1] + r[5] * off[2];
                ro[2] = r[6] * off[0] + r[7] * off[1] + r[8] * off[2];
                memcpy(off, ro, sizeof off);
            }
            for (int j = 0; j < 3; j++)
                x[j] += wt[i] * (fine[3 * c + (size_t)j] + off[j]);
        }
        memcpy(fine + 3 * u, x, sizeof x);
    }
}
