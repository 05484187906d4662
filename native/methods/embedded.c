/* DeformKit: embedded deformation (dk_embedded.h).
 *
 * Layout of the unknowns: free node u owns columns 12 u + a, a = 3 d + e for R[d][e] (row
 * major) and a = 9 + d for t[d]. J^T J is stored as dense 12 x 12 blocks, one per ordered
 * pair of free nodes that share a residual (an edge, or a constrained vertex both
 * influence); block (u, v) sits at position rank_u(v) among u's sorted block list, so the
 * CSC matrix handed to CHOLMOD has, in column 12 u + a, the rows 12 v + b of every v in u's
 * list: value index col_start[12 u + a] + 12 rank + b. Its pattern depends on the graph and
 * the constrained vertices only, so it is analysed once per bind or rebind.
 */
#include "dk_embedded.h"

#include <float.h>
#include <limits.h>
#include <math.h>
#include <stdlib.h>
#include <string.h>

#include "dk_cholesky.h"
#include "dk_operators.h"
#include "dk_parallel.h"
#include "dk_sparse.h"

#define K_MAX 16

typedef struct ed_system {
    dk_constraints *con;
    dk_index n_free;            /* free nodes                                               */
    dk_index *node_unknown;     /* m: free index or -1 (a constant node)                    */
    dk_index *free_nodes;       /* n_free: the nodes                                        */
    /* the positional terms: handle vertices (targets from the request) and held fixed
     * vertices (target: rest) */
    dk_index n_pos;
    dk_index *pos_vertex;       /* n_pos                                                    */
    dk_index *pos_target_row;   /* n_pos: row in the expanded handle targets, or -1 (rest)  */
    double *targets;            /* n_handle_vertices x 3                                    */
    /* J^T J blocks: per free node u, blk_start[u] .. blk_start[u+1]-1 into blk_node (sorted
     * free indices v) */
    dk_index *blk_start, *blk_node;
    int64_t n_blocks;
    double *blocks;             /* n_blocks x 144, block b's entry (a, c) at 144 b + 12 a + c */
    /* per ordered edge (j -> k, both free or not): the block indices (j,j), (j,k), (k,j),
     * (k,k), -1 where a node is constant */
    int64_t *edge_blk;          /* 4 per directed edge                                       */
    /* per positional term, per pair (p, q) of its nodes: the block index, -1 if constant  */
    int64_t *pos_blk;           /* n_pos x k x k                                             */
    dk_sparse *a;               /* the CSC matrix, 12 n_free square                          */
    int64_t *diag_pos;          /* 12 n_free: where each diagonal entry is                   */
    dk_cholesky *chol;
    double *grad, *step, *x_try; /* 12 n_free each; x_try: 12 m                             */
} ed_system;

struct dk_embedded {
    const dk_mesh *mesh;
    dk_embedded_options opt;
    dk_index n, m, k;
    double *g;                  /* m x 3 node positions                                     */
    double *p;                  /* n x 3 the source's positions: the mesh's at bind, then
                                   what dk_embedded_update_source gave                      */
    dk_index *node_vertex;      /* m: the vertex each node sits on; NULL for surface samples */
    dk_index *node_face;        /* m: surface samples: the triangle each node lies on       */
    double *node_bary;          /* m x 2: and its coordinates (s, t): a + s(b - a) + t(c - a)  */
    dk_index *nb;               /* n x k: each vertex's nodes                               */
    unsigned char *vside;       /* n: 0, 1 (cut group A) or 2 (B); NULL without a cut       */
    unsigned char *nside;       /* m: the side of each node's nearest vertex                */
    double *w;                  /* n x k: their weights                                     */
    dk_index n_edges;
    dk_index *edges;            /* n_edges x 2, i < j                                       */
    dk_index *adj_start, *adj;  /* directed adjacency (both directions), sorted              */
    double *x;                  /* m x 12: the current transformations                      */
    double L;                   /* the unit of length of F: unit_length() of the bind mesh;
                                   see evaluate()                                            */
    double energy;              /* F of x for the last solve's targets                      */
    ed_system sys;
    int analysis_count, factorization_count;
    dk_team *team;              /* the factor's two-thread substitutions' helper (NULL: per
                                   sweep)                                                   */
    dk_progress *prog;          /* during a bind or rebind only (NULL otherwise)             */
};

/* The phases of a bind and of a rebind (dk_progress.h), weighted by their cost in seconds
 * measured on the 692k-vertex armadillo (scripts/bench_scale.py's armadillo-wave, 2
 * subdivisions; defaults: 200 surface nodes, k = 4, Euclidean) on the shared 2-core
 * machine, timed between the callback's reports: 3.3 and 4.0 s in all, the longest stretch
 * without a report the edges' sort (~1 s). */
static const dk_progress_phase ed_bind_phases[] = {
    {"nodes", 0.43}, {"weights", 1.2}, {"edges", 1.7}, {"constraints", 0.25}, {"analyze", 0.03}};
static const dk_progress_phase ed_rebind_phases[] = {{"constraints", 0.25}, {"analyze", 0.03}};
/* the vertices one k-d tree query of the weights takes between two progress reports */
enum { ED_QUERY_CHUNK = 65536 };

static dk_status oom(dk_error *err, const char *what)
{
    return dk_error_set(err, DK_ERR_OUT_OF_MEMORY, "EmbeddedDeformation: out of memory (%s)",
                        what);
}

void dk_embedded_default_options(dk_embedded_options *o)
{
    memset(o, 0, sizeof *o);
    o->nodes = DK_ED_NODES_SURFACE;
    o->n_nodes = 200;
    o->radius = 0.0;
    o->k = 4;
    o->distance = DK_ED_DISTANCE_EUCLIDEAN;
    o->w_rot = 1.0;
    o->w_reg = 10.0;
    o->w_con = 2000.0;
    o->tolerance = 1e-6;
    o->max_iterations = 100;
    o->seed = 1;
    o->progress = NULL;
    o->progress_user = NULL;
}

/* The largest graph: n_nodes' bound, and what a radius may keep. */
enum { ED_MAX_NODES = 100000 };
/* The smallest radius, relative to the extent of the samples: below it the sampling grid's
 * cell numbers would not fit an int64 (and no graph that small could be bound anyway). */
#define ED_MIN_RADIUS 1e-12

static dk_status check_options(const dk_embedded_options *o, dk_error *err)
{
    const char *bad = NULL;
    if (o->nodes != DK_ED_NODES_SURFACE && o->nodes != DK_ED_NODES_VERTICES)
        bad = "nodes must be surface (0) or vertices (1)";
    else if (!(o->radius >= 0.0 && isfinite(o->radius)))
        bad = "radius must be finite and >= 0";
    else if (o->radius == 0.0 && (o->n_nodes < 1 || o->n_nodes > ED_MAX_NODES))
        bad = "n_nodes must be in 1..100000";
    else if (o->k < 1 || o->k > K_MAX)
        bad = "k must be in 1..16";
    else if (o->distance != DK_ED_DISTANCE_EUCLIDEAN && o->distance != DK_ED_DISTANCE_GEODESIC)
        bad = "distance must be euclidean (0) or geodesic (1)";
    else if (o->n_cut_a < 0 || o->n_cut_b < 0 || (o->n_cut_a > 0 && !o->cut_a) ||
             (o->n_cut_b > 0 && !o->cut_b))
        bad = "the cut groups must be index arrays with their counts";
    else if ((o->n_cut_a > 0) != (o->n_cut_b > 0))
        bad = "a cut needs both groups (cut_a and cut_b), or neither";
    else if (!(o->w_rot > 0 && o->w_reg > 0 && o->w_con > 0 && isfinite(o->w_rot) &&
               isfinite(o->w_reg) && isfinite(o->w_con)))
        bad = "the weights w_rot, w_reg and w_con must be finite and > 0";
    else if (!(o->tolerance > 0.0 && isfinite(o->tolerance)))
        bad = "tolerance must be finite and > 0";
    else if (o->max_iterations < 1)
        bad = "max_iterations must be >= 1";
    return bad ? dk_error_set(err, DK_ERR_INVALID_ARGUMENT, "EmbeddedDeformation: %s", bad)
               : DK_OK;
}

/* ------------------------------------------------------------------ sampling ----------- */

/* splitmix64: the object's own generator state (no global state) */
static uint64_t next_u64(uint64_t *s)
{
    uint64_t z = (*s += 0x9E3779B97F4A7C15ull);
    z = (z ^ (z >> 30)) * 0xBF58476D1CE4E5B9ull;
    z = (z ^ (z >> 27)) * 0x94D049BB133111EBull;
    return z ^ (z >> 31);
}

static double next_unit(uint64_t *s)
{
    return (double)(next_u64(s) >> 11) * (1.0 / 9007199254740992.0);
}

/* Dense candidate points: `count` area-weighted uniform samples of the triangles, with each
 * one's triangle (`face`, count) and coordinates (`bary`, count x 2) in it. */
static dk_status surface_samples(const dk_mesh *m, dk_index count, uint64_t *rng, double *out,
                                 dk_index *face, double *bary, dk_error *err)
{
    double *cdf = malloc(((size_t)m->n_faces + 1) * sizeof *cdf);
    if (!cdf)
        return oom(err, "surface samples");
    double total = 0.0;
    for (dk_index f = 0; f < m->n_faces; f++) {
        const double *a = m->positions + 3 * m->faces[3 * f];
        const double *b = m->positions + 3 * m->faces[3 * f + 1];
        const double *c = m->positions + 3 * m->faces[3 * f + 2];
        const double u[3] = {b[0] - a[0], b[1] - a[1], b[2] - a[2]};
        const double v[3] = {c[0] - a[0], c[1] - a[1], c[2] - a[2]};
        const double n[3] = {u[1] * v[2] - u[2] * v[1], u[2] * v[0] - u[0] * v[2],
                             u[0] * v[1] - u[1] * v[0]};
        total += 0.5 * sqrt(n[0] * n[0] + n[1] * n[1] + n[2] * n[2]);
        cdf[f] = total;
    }
    if (!(total > 0.0)) {
        free(cdf);
        return dk_error_set(err, DK_ERR_DEGENERATE,
                            "EmbeddedDeformation: the mesh has no area to sample nodes on");
    }
    for (dk_index i = 0; i < count; i++) {
        const double r = next_unit(rng) * total;
        dk_index lo = 0, hi = m->n_faces - 1;
        while (lo < hi) { /* the first face whose cumulative area exceeds r */
            const dk_index mid = lo + (hi - lo) / 2;
            if (cdf[mid] > r)
                hi = mid;
            else
                lo = mid + 1;
        }
        double s = next_unit(rng), t = next_unit(rng);
        if (s + t > 1.0) {
            s = 1.0 - s;
            t = 1.0 - t;
        }
        const double *a = m->positions + 3 * m->faces[3 * lo];
        const double *b = m->positions + 3 * m->faces[3 * lo + 1];
        const double *c = m->positions + 3 * m->faces[3 * lo + 2];
        for (int d = 0; d < 3; d++)
            out[3 * i + d] = a[d] + s * (b[d] - a[d]) + t * (c[d] - a[d]);
        face[i] = lo;
        bary[2 * i] = s;
        bary[2 * i + 1] = t;
    }
    free(cdf);
    return DK_OK;
}

/* Random sequential elimination over `pts` in the order `order`: keeps a point when no kept
 * one lies within r (a uniform grid of cell r finds the candidates). Writes the kept
 * indices into `kept` (room for n) and returns their count, or -1 when out of memory. */
static dk_index eliminate(const double *pts, dk_index n, const dk_index *order, double r,
                          const double lo[3], dk_index *kept, dk_index cap)
{
    /* hashed grid: cell id -> linked list of kept points */
    const size_t nb = 1u << 16;
    dk_index *head = malloc(nb * sizeof *head), *next = malloc(((size_t)n + 1) * sizeof *next);
    if (!head || !next) {
        free(head);
        free(next);
        return -1;
    }
    for (size_t i = 0; i < nb; i++)
        head[i] = -1;
    dk_index count = 0;
    const double r2 = r * r;
    for (dk_index o = 0; o < n && count < cap; o++) {
        const dk_index i = order[o];
        const double *p = pts + 3 * i;
        int64_t c[3];
        /* r >= ED_MIN_RADIUS x the extent (sample_nodes): the cell numbers fit an int64 */
        for (int d = 0; d < 3; d++)
            c[d] = (int64_t)floor((p[d] - lo[d]) / r);
        int ok = 1;
        for (int dx = -1; dx <= 1 && ok; dx++)
            for (int dy = -1; dy <= 1 && ok; dy++)
                for (int dz = -1; dz <= 1 && ok; dz++) {
                    const uint64_t h = ((uint64_t)(c[0] + dx) * 73856093u) ^
                                       ((uint64_t)(c[1] + dy) * 19349663u) ^
                                       ((uint64_t)(c[2] + dz) * 83492791u);
                    for (dk_index q = head[h & (nb - 1)]; q >= 0 && ok; q = next[q]) {
                        const double *pq = pts + 3 * kept[q];
                        const double e0 = pq[0] - p[0], e1 = pq[1] - p[1], e2 = pq[2] - p[2];
                        if (e0 * e0 + e1 * e1 + e2 * e2 < r2)
                            ok = 0;
                    }
                }
        if (!ok)
            continue;
        const uint64_t h = ((uint64_t)c[0] * 73856093u) ^ ((uint64_t)c[1] * 19349663u) ^
                           ((uint64_t)c[2] * 83492791u);
        kept[count] = i;
        next[count] = head[h & (nb - 1)];
        head[h & (nb - 1)] = count;
        count++;
    }
    free(head);
    free(next);
    return count;
}

/* The nodes: candidates (surface samples or the vertices) thinned to radius r, r from the
 * options or by bisection on the count. */
static dk_status sample_nodes(dk_embedded *ed, dk_error *err)
{
    const dk_mesh *m = ed->mesh;
    const dk_embedded_options *o = &ed->opt;
    uint64_t rng = o->seed;
    dk_index nc;
    /* a point set (no faces) is its own surface sample: its points are the candidates */
    const int from_vertices = o->nodes == DK_ED_NODES_VERTICES || m->n_faces == 0;
    if (from_vertices) {
        nc = m->n_vertices;
    } else {
        const int64_t want = o->radius > 0.0 ? 200000 : (int64_t)o->n_nodes * 40 + 2000;
        nc = (dk_index)(want < 2000000 ? want : 2000000);
    }
    double *cand = malloc(3 * ((size_t)nc + 1) * sizeof *cand);
    dk_index *order = malloc(((size_t)nc + 1) * sizeof *order);
    dk_index *kept = malloc(((size_t)nc + 1) * sizeof *kept);
    dk_index *cface = from_vertices ? NULL : malloc(((size_t)nc + 1) * sizeof *cface);
    double *cbary = from_vertices ? NULL : malloc(2 * ((size_t)nc + 1) * sizeof *cbary);
    dk_status st = DK_OK;
    if (!cand || !order || !kept || (!from_vertices && (!cface || !cbary))) {
        st = oom(err, "node sampling");
        goto done;
    }
    if (from_vertices)
        memcpy(cand, m->positions, 3 * (size_t)nc * sizeof *cand);
    else if ((st = surface_samples(m, nc, &rng, cand, cface, cbary, err)) != DK_OK)
        goto done;
    for (dk_index i = 0; i < nc; i++) /* a random order (Fisher-Yates) */
        order[i] = i;
    for (dk_index i = nc - 1; i > 0; i--) {
        const dk_index j = (dk_index)(next_u64(&rng) % (uint64_t)(i + 1));
        const dk_index t = order[i];
        order[i] = order[j];
        order[j] = t;
    }
    double lo[3] = {INFINITY, INFINITY, INFINITY}, hi[3] = {-INFINITY, -INFINITY, -INFINITY};
    for (dk_index i = 0; i < nc; i++)
        for (int d = 0; d < 3; d++) {
            lo[d] = fmin(lo[d], cand[3 * i + d]);
            hi[d] = fmax(hi[d], cand[3 * i + d]);
        }
    const double diag = sqrt((hi[0] - lo[0]) * (hi[0] - lo[0]) + (hi[1] - lo[1]) * (hi[1] - lo[1]) +
                             (hi[2] - lo[2]) * (hi[2] - lo[2]));
    dk_index count;
    if (o->radius > 0.0 && o->radius < ED_MIN_RADIUS * diag) {
        /* found by fuzz_method: radius 1e-300 made the grid's cell numbers overflow int64
         * (undefined behaviour), and clamping them put every sample into one cell, a
         * quadratic elimination of 200,000 samples */
        st = dk_error_set(err, DK_ERR_INVALID_ARGUMENT,
                          "EmbeddedDeformation bind: radius %g is below %g of the surface's "
                          "extent (%g); raise it", o->radius, ED_MIN_RADIUS, diag);
        goto done;
    }
    if (o->radius > 0.0) {
        /* at most one node more than n_nodes allows, so that a radius far below the
         * mesh's extent is refused here instead of binding a graph of up to 200,000 nodes
         * for minutes (fuzz_method: radius 1e-300 on a 20-vertex grid) */
        count = eliminate(cand, nc, order, o->radius, lo, kept,
                          nc < ED_MAX_NODES + 1 ? nc : ED_MAX_NODES + 1);
        if (count > ED_MAX_NODES) {
            st = dk_error_set(err, DK_ERR_INVALID_ARGUMENT,
                              "EmbeddedDeformation bind: radius %g keeps more than %d nodes "
                              "(the most n_nodes allows) on a surface %g across; raise it",
                              o->radius, ED_MAX_NODES, diag);
            goto done;
        }
    } else { /* the smallest radius whose count does not exceed the request */
        /* all candidates on one point (coincident vertices): any radius keeps one; a zero
         * one made every cell number 0 / 0, NaN into an int64 (fuzz_method, UBSan) */
        const double extent = diag > 0 ? diag : 1.0;
        /* at most one node per vertex: a graph denser than its mesh only adds freedom the
         * vertices cannot hold (the paper's graphs are far coarser than their meshes); the
         * add-on's default 200 nodes on a 50-vertex grid bulged 13% past the handle */
        const dk_index wanted = o->n_nodes < m->n_vertices ? o->n_nodes : m->n_vertices;
        double a = extent * 1e-4, b = extent;
        for (int it = 0; it < 40; it++) {
            const double r = 0.5 * (a + b);
            const dk_index c = eliminate(cand, nc, order, r, lo, kept, nc);
            if (c < 0)
                break;
            if (c > wanted)
                a = r;
            else
                b = r;
        }
        count = eliminate(cand, nc, order, b, lo, kept, nc);
    }
    if (count < 0) {
        st = oom(err, "node sampling");
        goto done;
    }
    ed->g = malloc(3 * ((size_t)count + 1) * sizeof *ed->g);
    if (!ed->g) {
        st = oom(err, "nodes");
        goto done;
    }
    for (dk_index i = 0; i < count; i++)
        memcpy(ed->g + 3 * i, cand + 3 * kept[i], 3 * sizeof(double));
    if (from_vertices) { /* candidates are the vertices: remember which */
        if (!(ed->node_vertex = malloc(((size_t)count + 1) * sizeof *ed->node_vertex))) {
            st = oom(err, "nodes");
            goto done;
        }
        memcpy(ed->node_vertex, kept, (size_t)count * sizeof *kept);
    } else { /* surface samples: remember where, so that they ride along a moving mesh */
        ed->node_face = malloc(((size_t)count + 1) * sizeof *ed->node_face);
        ed->node_bary = malloc(2 * ((size_t)count + 1) * sizeof *ed->node_bary);
        if (!ed->node_face || !ed->node_bary) {
            st = oom(err, "nodes");
            goto done;
        }
        for (dk_index i = 0; i < count; i++) {
            ed->node_face[i] = cface[kept[i]];
            memcpy(ed->node_bary + 2 * i, cbary + 2 * (size_t)kept[i], 2 * sizeof(double));
        }
    }
    ed->m = count;
done:
    free(cand);
    free(order);
    free(kept);
    free(cface);
    free(cbary);
    return st;
}

/* ------------------------------------------------------------------ weights, edges ----- */

static int cmp_index(const void *a, const void *b)
{
    const dk_index x = *(const dk_index *)a, y = *(const dk_index *)b;
    return (x > y) - (x < y);
}

static int cmp_i64(const void *a, const void *b)
{
    const int64_t x = *(const int64_t *)a, y = *(const int64_t *)b;
    return (x > y) - (x < y);
}

/* Eq. 4 for one point from its k + 1 nearest nodes `idx` at distances `dist` (ascending):
 * the k weights, normalised (equal weights when the k-th and (k+1)-th nodes tie), into nb
 * and w (k each; a node with weight 0 gets -1). */
static void eq4(const dk_index *idx, const double *dist, dk_index k, dk_index *nb, double *w)
{
    const double dmax = dist[k];
    double sum = 0.0;
    for (dk_index q = 0; q < k; q++) {
        const double s = dmax > 0.0 ? 1.0 - dist[q] / dmax : 0.0;
        w[q] = s * s;
        nb[q] = idx[q];
        sum += s * s;
    }
    for (dk_index q = 0; q < k; q++) {
        w[q] = sum > 0.0 ? w[q] / sum : 1.0 / (double)k;
        if (!(w[q] > 0.0))
            nb[q] = -1;
    }
}

/* The k nearest of the tree's nodes for `n` points, with the weights of eq. 4, into nb and w
 * (n x k each). Needs k + 1 <= the tree's nodes. `only` (n, or NULL for all) skips the
 * points where it is 0. */
/* `prog` (may be NULL): the queries run in chunks of ED_QUERY_CHUNK points with a report
 * of the phase's part (the fraction of the points done) between them; the results are
 * those of one query (each point's neighbours do not depend on the others). */
static dk_status embed_points(const dk_kdtree *tree, const double *points, dk_index n,
                              dk_index k, const unsigned char *only, dk_index *nb, double *w,
                              dk_progress *prog, dk_error *err)
{
    const size_t k1 = (size_t)k + 1;
    dk_index *idx = malloc(((size_t)n * k1 + 1) * sizeof *idx);
    double *d2 = malloc(((size_t)n * k1 + 1) * sizeof *d2);
    dk_status st = idx && d2 ? DK_OK : oom(err, "weights");
    for (dk_index v0 = 0; st == DK_OK && v0 < n; v0 += ED_QUERY_CHUNK) {
        const dk_index c = n - v0 < ED_QUERY_CHUNK ? n - v0 : ED_QUERY_CHUNK;
        st = dk_progress_part(prog, (double)v0 / n, err);
        if (st == DK_OK)
            st = dk_kdtree_knn(tree, points + 3 * (size_t)v0, c, k + 1, idx + (size_t)v0 * k1,
                               d2 + (size_t)v0 * k1, err);
    }
    for (dk_index v = 0; st == DK_OK && v < n; v++) {
        if (only && !only[v])
            continue;
        double dist[K_MAX + 1];
        for (size_t q = 0; q < k1; q++)
            dist[q] = sqrt(d2[(size_t)v * k1 + q]);
        eq4(idx + (size_t)v * k1, dist, k, nb + (size_t)v * k, w + (size_t)v * k);
    }
    free(idx);
    free(d2);
    return st;
}

/* A label of the multi-source Dijkstra: node `node` reaches vertex `v` at distance d. */
typedef struct ed_label {
    double d;
    dk_index v, node;
} ed_label;

static void label_push(ed_label *h, size_t *size, ed_label x)
{
    size_t i = (*size)++;
    while (i > 0) {
        const size_t p = (i - 1) / 2;
        if (!(x.d < h[p].d))
            break;
        h[i] = h[p];
        i = p;
    }
    h[i] = x;
}

static ed_label label_pop(ed_label *h, size_t *size)
{
    const ed_label top = h[0], last = h[--*size];
    size_t i = 0;
    for (;;) {
        size_t c = 2 * i + 1;
        if (c >= *size)
            break;
        if (c + 1 < *size && h[c + 1].d < h[c].d)
            c++;
        if (!(h[c].d < last.d))
            break;
        h[i] = h[c];
        i = c;
    }
    if (*size > 0)
        h[i] = last;
    return top;
}

/* Sides of a cut: 0 none, 1 group A, 2 group B; two sides are across when both are set
 * and differ. */
static int across(unsigned char a, unsigned char b)
{
    return a && b && a != b;
}

/* Geodesic influence: each vertex's k + 1 nearest nodes along the mesh's edges, by one
 * Dijkstra whose labels are (vertex, node) pairs; a vertex settles at most k + 1 distinct
 * nodes, the first ones to reach it, so they are its nearest in edge-path distance. Node j
 * starts at its nearest vertex `anchor[j]`, at the straight distance `anchor_d[j]` to it.
 * With a cut, a label does not enter a vertex of the other side (and so does not pass
 * through it). Fills nb and w for the vertices that settle k + 1 nodes and sets short[v]
 * for the others (to be done in Euclidean distance). Labels pushed: at most k + 1 per vertex
 * and edge end. */
static dk_status geodesic_weights(dk_embedded *ed, const dk_index *anchor,
                                  const double *anchor_d, unsigned char *short_, dk_error *err)
{
    const dk_mesh *mesh = ed->mesh;
    const dk_index n = ed->n, k = ed->k, m = ed->m;
    const size_t k1 = (size_t)k + 1;
    const size_t cap = (size_t)m + k1 * 2 * (size_t)mesh->n_edges + 1;
    ed_label *heap = malloc(cap * sizeof *heap);
    dk_index *cnt = calloc((size_t)n + 1, sizeof *cnt);
    dk_index *lab = malloc(((size_t)n * k1 + 1) * sizeof *lab);
    double *dist = malloc(((size_t)n * k1 + 1) * sizeof *dist);
    dk_status st = heap && cnt && lab && dist ? DK_OK : oom(err, "geodesic influence");
    size_t size = 0;
    for (dk_index j = 0; st == DK_OK && j < m; j++)
        label_push(heap, &size, (ed_label){anchor_d[j], anchor[j], j});
    int64_t pops = 0; /* ~(k + 1) n labels settle: the progress of the search */
    while (st == DK_OK && size > 0) {
        if ((st = dk_progress_tick(ed->prog, (double)++pops, (double)n * k1, err)) != DK_OK)
            break;
        const ed_label x = label_pop(heap, &size);
        dk_index *mine = lab + (size_t)x.v * k1;
        int seen = cnt[x.v] == (dk_index)k1;
        for (dk_index c = 0; !seen && c < cnt[x.v]; c++)
            seen = mine[c] == x.node;
        if (seen)
            continue;
        mine[cnt[x.v]] = x.node;
        dist[(size_t)x.v * k1 + (size_t)cnt[x.v]] = x.d;
        cnt[x.v]++;
        const double *p = mesh->positions + 3 * (size_t)x.v;
        for (dk_index r = mesh->ring_start[x.v]; r < mesh->ring_start[x.v + 1]; r++) {
            const dk_index u = mesh->ring_index[r];
            if (cnt[u] == (dk_index)k1 || size == cap ||
                (ed->vside && across(ed->nside[x.node], ed->vside[u])))
                continue;
            const double *q = mesh->positions + 3 * (size_t)u;
            const double e = sqrt((p[0] - q[0]) * (p[0] - q[0]) + (p[1] - q[1]) * (p[1] - q[1]) +
                                  (p[2] - q[2]) * (p[2] - q[2]));
            label_push(heap, &size, (ed_label){x.d + e, u, x.node});
        }
    }
    for (dk_index v = 0; st == DK_OK && v < n; v++) {
        short_[v] = cnt[v] < (dk_index)k1;
        if (!short_[v])
            eq4(lab + (size_t)v * k1, dist + (size_t)v * k1, k, ed->nb + (size_t)v * k,
                ed->w + (size_t)v * k);
    }
    free(heap);
    free(cnt);
    free(lab);
    free(dist);
    return st;
}

/* The cut's sides: vside from the two groups (disjoint), nside from each node's nearest
 * vertex. */
static dk_status cut_sides(dk_embedded *ed, const dk_index *anchor, dk_error *err)
{
    const dk_embedded_options *o = &ed->opt;
    dk_status st = dk_check_indices(o->cut_a, o->n_cut_a, ed->n, "cut group A vertex", err);
    if (st == DK_OK)
        st = dk_check_indices(o->cut_b, o->n_cut_b, ed->n, "cut group B vertex", err);
    if (st != DK_OK) {
        dk_error_prefix(err, "EmbeddedDeformation");
        return st;
    }
    ed->vside = calloc((size_t)ed->n + 1, 1);
    ed->nside = malloc((size_t)ed->m + 1);
    if (!ed->vside || !ed->nside)
        return oom(err, "the cut");
    for (dk_index i = 0; i < o->n_cut_a; i++)
        ed->vside[o->cut_a[i]] = 1;
    for (dk_index i = 0; i < o->n_cut_b; i++) {
        if (ed->vside[o->cut_b[i]] == 1)
            return dk_error_set(err, DK_ERR_INVALID_ARGUMENT,
                                "EmbeddedDeformation: vertex %d is in both cut groups; the "
                                "two sides of a cut must not overlap",
                                (int)o->cut_b[i]);
        ed->vside[o->cut_b[i]] = 2;
    }
    for (dk_index j = 0; j < ed->m; j++)
        ed->nside[j] = ed->vside[anchor[j]];
    return DK_OK;
}

/* Eq. 4 in Euclidean distance for the vertices of side `side` (0: those of no side) that
 * `todo` marks (NULL: all): their nearest nodes among those not across the cut. */
static dk_status euclidean_weights(dk_embedded *ed, const unsigned char *todo,
                                   unsigned char side, dk_error *err)
{
    const dk_index n = ed->n, m = ed->m, k = ed->k;
    unsigned char *only = NULL;
    double *sub = NULL;
    dk_index *glob = NULL, ns = 0;
    dk_kdtree *tree = NULL;
    dk_status st = DK_OK;
    if (ed->vside) { /* the nodes allowed, and the vertices to do */
        only = malloc((size_t)n + 1);
        sub = malloc(3 * ((size_t)m + 1) * sizeof *sub);
        glob = malloc(((size_t)m + 1) * sizeof *glob);
        if (!only || !sub || !glob) {
            st = oom(err, "weights");
            goto done;
        }
        for (dk_index j = 0; j < m; j++)
            if (!across(ed->nside[j], side)) {
                memcpy(sub + 3 * (size_t)ns, ed->g + 3 * (size_t)j, 3 * sizeof *sub);
                glob[ns++] = j;
            }
        dk_index count = 0;
        for (dk_index v = 0; v < n; v++) {
            only[v] = ed->vside[v] == side && (!todo || todo[v]);
            count += only[v];
        }
        if (count == 0)
            goto done;
        if (ns < k + 1) {
            st = dk_error_set(err, DK_ERR_INVALID_ARGUMENT,
                              "EmbeddedDeformation: the cut leaves %d nodes to the vertices of "
                              "group %c, but k = %d needs at least %d (raise n_nodes, widen "
                              "the groups, or lower k to %d or less)",
                              (int)ns, side == 1 ? 'A' : 'B', (int)k, (int)k + 1,
                              (int)(ns > 1 ? ns - 1 : 1));
            goto done;
        }
    }
    st = dk_kdtree_create(sub ? sub : ed->g, sub ? ns : m, &tree, err);
    if (st == DK_OK)
        st = embed_points(tree, ed->mesh->positions, n, k, only ? only : todo, ed->nb, ed->w,
                          ed->prog, err);
    for (dk_index v = 0; st == DK_OK && glob && v < n; v++)
        if (only[v])
            for (dk_index q = 0; q < k; q++) {
                dk_index *c = ed->nb + (size_t)v * (size_t)k + (size_t)q;
                *c = *c >= 0 ? glob[*c] : -1;
            }
done:
    dk_kdtree_free(tree);
    free(only);
    free(sub);
    free(glob);
    return st;
}

/* Each vertex's k nearest nodes and weights (eq. 4), in Euclidean or geodesic distance and
 * across no cut; nodes that influence no vertex are dropped (renumbering the rest, in their
 * order). */
static dk_status weights(dk_embedded *ed, dk_error *err)
{
    const dk_index n = ed->n, k = ed->k;
    const dk_embedded_options *o = &ed->opt;
    if (ed->m < k + 1) {
        /* more nodes help only where the sampling can give them: n_nodes is capped by the
         * vertices, so on a small mesh k is what to change (the second hostile review: the
         * hint said "raise n_nodes", which could not help) */
        const int more = o->radius > 0.0 ? 1 : o->n_nodes < n && ed->m < n;
        if (ed->m < 2)
            return dk_error_set(err, DK_ERR_INVALID_ARGUMENT,
                                "EmbeddedDeformation: %d node, but k = %d needs at least %d "
                                "(%s)",
                                (int)ed->m, (int)k, (int)k + 1,
                                more ? "raise n_nodes or lower the radius"
                                     : "this mesh is too small for a graph");
        return dk_error_set(err, DK_ERR_INVALID_ARGUMENT,
                            "EmbeddedDeformation: %d nodes, but k = %d needs at least %d "
                            "(%slower k to %d or less)",
                            (int)ed->m, (int)k, (int)k + 1,
                            more ? "raise n_nodes or lower the radius, or " : "",
                            (int)ed->m - 1);
    }
    const int geodesic = o->distance == DK_ED_DISTANCE_GEODESIC, cut = o->n_cut_a > 0;
    if (geodesic && ed->mesh->n_faces == 0)
        return dk_error_set(err, DK_ERR_INVALID_ARGUMENT,
                            "EmbeddedDeformation: distance=geodesic needs a mesh with faces "
                            "(paths along its edges); this one has none (a point set): use "
                            "distance=euclidean");
    dk_kdtree *vtree = NULL;
    dk_index *anchor = NULL;    /* m: each node's nearest vertex (geodesic or cut)     */
    double *anchor_d = NULL;    /* m: the distance to it                               */
    unsigned char *euclid = NULL; /* n: the vertices still to weigh in Euclidean distance */
    ed->nb = malloc(((size_t)n * (size_t)k + 1) * sizeof *ed->nb);
    ed->w = malloc(((size_t)n * (size_t)k + 1) * sizeof *ed->w);
    dk_index *map = malloc(((size_t)ed->m + 1) * sizeof *map);
    dk_status st = ed->nb && ed->w && map ? DK_OK : oom(err, "weights");
    if (st == DK_OK && (geodesic || cut)) { /* 1. the nodes' nearest vertices */
        anchor = malloc(((size_t)ed->m + 1) * sizeof *anchor);
        anchor_d = malloc(((size_t)ed->m + 1) * sizeof *anchor_d);
        st = anchor && anchor_d ? dk_kdtree_create(ed->mesh->positions, n, &vtree, err)
                                : oom(err, "weights");
        if (st == DK_OK)
            st = dk_kdtree_knn(vtree, ed->g, ed->m, 1, anchor, anchor_d, err);
        for (dk_index j = 0; st == DK_OK && j < ed->m; j++)
            anchor_d[j] = sqrt(anchor_d[j]);
    }
    if (st == DK_OK && cut) /* 2. the cut's sides */
        st = cut_sides(ed, anchor, err);
    if (st == DK_OK && geodesic) { /* 3. along the surface */
        euclid = malloc((size_t)n + 1);
        st = euclid ? geodesic_weights(ed, anchor, anchor_d, euclid, err) : oom(err, "weights");
    }
    /* 4. in space: every vertex, or those the surface left short; per side of a cut */
    for (unsigned char side = 0; st == DK_OK && side <= (cut ? 2 : 0); side++)
        st = euclidean_weights(ed, euclid, side, err);
    if (st != DK_OK)
        goto done;
    for (dk_index j = 0; j < ed->m; j++) /* 5. drop the nodes that influence nothing */
        map[j] = -1;
    for (size_t q = 0; q < (size_t)n * (size_t)k; q++)
        if (ed->nb[q] >= 0)
            map[ed->nb[q]] = 0;
    dk_index kept = 0;
    for (dk_index j = 0; j < ed->m; j++)
        if (map[j] == 0) {
            map[j] = kept;
            memmove(ed->g + 3 * kept, ed->g + 3 * j, 3 * sizeof(double));
            if (ed->nside)
                ed->nside[kept] = ed->nside[j];
            if (ed->node_vertex)
                ed->node_vertex[kept] = ed->node_vertex[j];
            if (ed->node_face) {
                ed->node_face[kept] = ed->node_face[j];
                memmove(ed->node_bary + 2 * kept, ed->node_bary + 2 * j, 2 * sizeof(double));
            }
            kept++;
        }
    for (size_t q = 0; q < (size_t)n * (size_t)k; q++)
        ed->nb[q] = ed->nb[q] >= 0 ? map[ed->nb[q]] : -1;
    ed->m = kept;
done:
    dk_kdtree_free(vtree);
    free(anchor);
    free(anchor_d);
    free(map);
    free(euclid);
    return st;
}

static dk_index uf_find(dk_index *parent, dk_index a)
{
    while (parent[a] != a) {
        parent[a] = parent[parent[a]];
        a = parent[a];
    }
    return a;
}

/* Edges between every two nodes influencing a common vertex; the directed adjacency.
 *
 * A graph dense for its mesh (n_nodes near or above the vertex count) can fall apart into
 * pieces that influence neighbouring vertices but share none: a piece that reaches no
 * handle then stays at the identity, and its vertices at rest while the surface around them
 * moves (found by tests/python/test_properties.py: translating both ends of a 30-vertex grid
 * left its 20 inner vertices behind, "converged" at F = 2e-9). So wherever a mesh edge joins
 * two vertices whose nodes lie in different pieces, their first nodes are joined too (not
 * across a cut), in mesh-edge order; a graph that is connected along the surface -- every
 * graph of the paper's density -- gets no extra edge. */
static dk_status edges(dk_embedded *ed, dk_error *err)
{
    const dk_index n = ed->n, k = ed->k, m = ed->m;
    const dk_mesh *mesh = ed->mesh;
    const int64_t cap = (int64_t)n * k * (k - 1) / 2 + (int64_t)mesh->n_edges + 1;
    int64_t *pairs = malloc((size_t)cap * sizeof *pairs), np = 0;
    dk_index *parent = malloc(((size_t)m + 1) * sizeof *parent);
    if (!pairs || !parent) {
        free(pairs);
        free(parent);
        return oom(err, "graph edges");
    }
    for (dk_index j = 0; j < m; j++)
        parent[j] = j;
    /* progress: the two loops are the first half of the phase, the sort (uninterruptible,
     * ~1 s of the 1.7 at 692k) the second */
    const double work = 2.0 * ((double)n + (double)mesh->n_edges);
    dk_status st = DK_OK;
    for (dk_index v = 0; v < n && st == DK_OK; v++) {
        st = dk_progress_tick(ed->prog, v, work, err);
        for (dk_index p = 0; p < k; p++)
            for (dk_index q = p + 1; q < k; q++) {
                dk_index a = ed->nb[(size_t)v * k + p], b = ed->nb[(size_t)v * k + q];
                if (a < 0 || b < 0 || a == b || (ed->nside && across(ed->nside[a], ed->nside[b])))
                    continue;
                if (a > b) {
                    const dk_index t = a;
                    a = b;
                    b = t;
                }
                pairs[np++] = (int64_t)a * m + b;
                parent[uf_find(parent, a)] = uf_find(parent, b);
            }
    }
    for (dk_index e = 0; e < mesh->n_edges && st == DK_OK; e++) {
        if ((st = dk_progress_tick(ed->prog, (double)n + e, work, err)) != DK_OK)
            break;
        dk_index a = ed->nb[(size_t)mesh->edges[2 * e] * k];
        dk_index b = ed->nb[(size_t)mesh->edges[2 * e + 1] * k];
        if (a < 0 || b < 0 || (ed->nside && across(ed->nside[a], ed->nside[b])))
            continue;
        const dk_index ra = uf_find(parent, a), rb = uf_find(parent, b);
        if (ra == rb)
            continue;
        parent[ra] = rb;
        if (a > b) {
            const dk_index t = a;
            a = b;
            b = t;
        }
        pairs[np++] = (int64_t)a * m + b;
    }
    free(parent);
    if (st == DK_OK)
        st = dk_progress_part(ed->prog, 0.5, err);
    if (st != DK_OK) {
        free(pairs);
        return st;
    }
    qsort(pairs, (size_t)np, sizeof *pairs, cmp_i64);
    int64_t ne = 0;
    for (int64_t i = 0; i < np; i++)
        if (i == 0 || pairs[i] != pairs[i - 1])
            pairs[ne++] = pairs[i];
    ed->n_edges = (dk_index)ne;
    ed->edges = malloc(2 * ((size_t)ne + 1) * sizeof *ed->edges);
    ed->adj_start = calloc((size_t)m + 1, sizeof *ed->adj_start);
    ed->adj = malloc(2 * ((size_t)ne + 1) * sizeof *ed->adj);
    if (!ed->edges || !ed->adj_start || !ed->adj) {
        free(pairs);
        return oom(err, "graph edges");
    }
    for (int64_t i = 0; i < ne; i++) {
        ed->edges[2 * i] = (dk_index)(pairs[i] / m);
        ed->edges[2 * i + 1] = (dk_index)(pairs[i] % m);
        ed->adj_start[ed->edges[2 * i] + 1]++;
        ed->adj_start[ed->edges[2 * i + 1] + 1]++;
    }
    for (dk_index j = 0; j < m; j++)
        ed->adj_start[j + 1] += ed->adj_start[j];
    dk_index *fill = malloc(((size_t)m + 1) * sizeof *fill);
    if (!fill) {
        free(pairs);
        return oom(err, "graph edges");
    }
    memcpy(fill, ed->adj_start, (size_t)m * sizeof *fill);
    for (int64_t i = 0; i < ne; i++) {
        const dk_index a = ed->edges[2 * i], b = ed->edges[2 * i + 1];
        ed->adj[fill[a]++] = b;
        ed->adj[fill[b]++] = a;
    }
    for (dk_index j = 0; j < m; j++)
        qsort(ed->adj + ed->adj_start[j], (size_t)(ed->adj_start[j + 1] - ed->adj_start[j]),
              sizeof *ed->adj, cmp_index);
    free(fill);
    free(pairs);
    return DK_OK;
}

/* ------------------------------------------------------------------ the system --------- */

static void system_free(ed_system *s)
{
    dk_constraints_free(s->con);
    free(s->node_unknown);
    free(s->free_nodes);
    free(s->pos_vertex);
    free(s->pos_target_row);
    free(s->targets);
    free(s->blk_start);
    free(s->blk_node);
    free(s->blocks);
    free(s->edge_blk);
    free(s->pos_blk);
    dk_sparse_free(s->a);
    free(s->diag_pos);
    dk_cholesky_free(s->chol);
    free(s->grad);
    free(s->step);
    free(s->x_try);
    memset(s, 0, sizeof *s);
}

/* A slot's coordinate d (R[d][e] at 3 d + e, t[d] at 9 + d), and the c-th slot (0..3, in
 * ascending order) of coordinate d. The regularization and positional residuals of
 * coordinate d involve only those slots, so blocks between different nodes are nonzero only
 * between slots of the same coordinate; the rotation residuals couple the coordinates, but
 * within one node. */
static int slot_coord(int a)
{
    return a < 9 ? a / 3 : a - 9;
}

static int coord_slot(int d, int c)
{
    return c < 3 ? 3 * d + c : 9 + d;
}

/* The block of free nodes (u, v), or -1 when either is constant or they share no residual. */
static int64_t block_of(const ed_system *s, dk_index u, dk_index v)
{
    if (u < 0 || v < 0)
        return -1;
    dk_index lo = s->blk_start[u], hi = s->blk_start[u + 1] - 1;
    while (lo <= hi) {
        const dk_index mid = lo + (hi - lo) / 2;
        if (s->blk_node[mid] == v)
            return mid;
        if (s->blk_node[mid] < v)
            lo = mid + 1;
        else
            hi = mid - 1;
    }
    return -1;
}

/* Which nodes are constants, the free numbering, and the positional terms. */
static dk_status classify(const dk_embedded *ed, ed_system *s, dk_error *err)
{
    const dk_index n = ed->n, m = ed->m, k = ed->k;
    const dk_constraints *c = s->con;
    unsigned char *moves = calloc((size_t)m + 1, 1);
    dk_index *target_of = malloc(((size_t)n + 1) * sizeof *target_of);
    s->node_unknown = malloc(((size_t)m + 1) * sizeof *s->node_unknown);
    s->free_nodes = malloc(((size_t)m + 1) * sizeof *s->free_nodes);
    s->pos_vertex = malloc(((size_t)n + 1) * sizeof *s->pos_vertex);
    s->pos_target_row = malloc(((size_t)n + 1) * sizeof *s->pos_target_row);
    s->targets = malloc((3 * (size_t)c->n_handle_vertices + 1) * sizeof *s->targets);
    dk_status st = DK_OK;
    if (!moves || !target_of || !s->node_unknown || !s->free_nodes || !s->pos_vertex ||
        !s->pos_target_row || !s->targets) {
        st = oom(err, "constraint system");
        goto done;
    }
    /* the paper's rule: a node that influences a fixed vertex is a constant, so fixed
     * vertices stay exactly at rest (all their nodes are the identity). Not for held
     * vertices (loose geometry nothing constrains, dk_constraints.h): they are put at rest
     * in apply(), and freezing their nodes would freeze the surface around them. */
    unsigned char *held = moves; /* reused: 1 = influences a fixed vertex */
    for (dk_index v = 0; v < n; v++)
        if (c->role[v] == DK_VERTEX_FIXED && !c->held[v])
            for (dk_index q = 0; q < k; q++)
                if (ed->nb[(size_t)v * k + q] >= 0)
                    held[ed->nb[(size_t)v * k + q]] = 1;
    s->n_free = 0;
    for (dk_index j = 0; j < m; j++) {
        s->node_unknown[j] = !held[j] ? s->n_free : -1;
        if (!held[j])
            s->free_nodes[s->n_free++] = j;
    }
    if (s->n_free == 0) {
        st = dk_error_set(err, DK_ERR_INVALID_ARGUMENT,
                          "EmbeddedDeformation: every node influences a fixed vertex, so "
                          "every node is a constant and nothing can move (fix fewer "
                          "vertices or use more nodes)");
        goto done;
    }
    for (dk_index v = 0; v < n; v++)
        target_of[v] = -1;
    for (dk_index i = 0; i < c->n_handle_vertices; i++)
        target_of[c->handle_vertices[i]] = i;
    s->n_pos = 0;
    for (dk_index v = 0; v < n; v++) {
        if (c->role[v] >= 0) {
            s->pos_vertex[s->n_pos] = v;
            s->pos_target_row[s->n_pos] = target_of[v];
            s->n_pos++;
        }
    }
done:
    free(moves);
    free(target_of);
    return st;
}

/* The blocks of J^T J: every free node with itself, its free graph neighbours, and the free
 * nodes it shares a positional term with. */
static dk_status block_pattern(const dk_embedded *ed, ed_system *s, dk_error *err)
{
    const dk_index k = ed->k, nf = s->n_free;
    int64_t cap = nf + 2 * (int64_t)ed->n_edges + (int64_t)s->n_pos * k * k + 1;
    int64_t *pairs = malloc((size_t)cap * sizeof *pairs), np = 0;
    if (!pairs)
        return oom(err, "matrix pattern");
    for (dk_index u = 0; u < nf; u++)
        pairs[np++] = (int64_t)u * nf + u;
    for (dk_index e = 0; e < ed->n_edges; e++) {
        const dk_index a = s->node_unknown[ed->edges[2 * e]];
        const dk_index b = s->node_unknown[ed->edges[2 * e + 1]];
        if (a >= 0 && b >= 0) {
            pairs[np++] = (int64_t)a * nf + b;
            pairs[np++] = (int64_t)b * nf + a;
        }
    }
    for (dk_index l = 0; l < s->n_pos; l++) {
        const dk_index *nb = ed->nb + (size_t)s->pos_vertex[l] * k;
        for (dk_index p = 0; p < k; p++)
            for (dk_index q = 0; q < k; q++) {
                const dk_index a = nb[p] >= 0 ? s->node_unknown[nb[p]] : -1;
                const dk_index b = nb[q] >= 0 ? s->node_unknown[nb[q]] : -1;
                if (a >= 0 && b >= 0)
                    pairs[np++] = (int64_t)a * nf + b;
            }
    }
    qsort(pairs, (size_t)np, sizeof *pairs, cmp_i64);
    int64_t nb = 0;
    for (int64_t i = 0; i < np; i++)
        if (i == 0 || pairs[i] != pairs[i - 1])
            pairs[nb++] = pairs[i];
    s->n_blocks = nb;
    s->blk_start = calloc((size_t)nf + 1, sizeof *s->blk_start);
    s->blk_node = malloc(((size_t)nb + 1) * sizeof *s->blk_node);
    s->blocks = malloc(((size_t)nb * 144 + 1) * sizeof *s->blocks);
    if (!s->blk_start || !s->blk_node || !s->blocks) {
        free(pairs);
        return oom(err, "matrix pattern");
    }
    for (int64_t i = 0; i < nb; i++) {
        s->blk_node[i] = (dk_index)(pairs[i] % nf);
        s->blk_start[pairs[i] / nf + 1]++;
    }
    for (dk_index u = 0; u < nf; u++)
        s->blk_start[u + 1] += s->blk_start[u];
    free(pairs);
    return DK_OK;
}

/* The CSC matrix over the blocks (rows of each column: the blocks' rows in order), the
 * diagonal positions, the per-residual block indices, and the analysis. */
static dk_status matrix(dk_embedded *ed, ed_system *s, dk_error *err)
{
    const dk_index nf = s->n_free, N = 12 * nf, k = ed->k;
    /* entries: a dense block per node, 3 x 16 for each pair of different nodes */
    const int64_t nnz = 144 * (int64_t)nf + 48 * (s->n_blocks - nf);
    dk_status st = dk_sparse_alloc(N, N, nnz, &s->a, err);
    if (st != DK_OK)
        return st;
    s->diag_pos = malloc(((size_t)N + 1) * sizeof *s->diag_pos);
    s->edge_blk = malloc((4 * 2 * (size_t)ed->n_edges + 1) * sizeof *s->edge_blk);
    s->pos_blk = malloc(((size_t)s->n_pos * k * k + 1) * sizeof *s->pos_blk);
    s->grad = malloc(((size_t)N + 1) * sizeof *s->grad);
    s->step = malloc(((size_t)N + 1) * sizeof *s->step);
    s->x_try = malloc((12 * (size_t)ed->m + 1) * sizeof *s->x_try);
    if (!s->diag_pos || !s->edge_blk || !s->pos_blk || !s->grad || !s->step || !s->x_try)
        return oom(err, "matrix");
    int64_t at = 0;
    for (dk_index u = 0; u < nf; u++)
        for (int a = 0; a < 12; a++) {
            const int d = slot_coord(a);
            s->a->col_start[12 * u + a] = (dk_index)at;
            for (dk_index b = s->blk_start[u]; b < s->blk_start[u + 1]; b++) {
                const dk_index v = s->blk_node[b];
                if (v == u) { /* the node's own block: dense (the rotation term) */
                    s->diag_pos[12 * u + a] = at + a;
                    for (int c = 0; c < 12; c++)
                        s->a->row_index[at++] = 12 * v + c;
                } else { /* between nodes: the same coordinate only (R[d][.], t[d]) */
                    for (int c = 0; c < 4; c++)
                        s->a->row_index[at++] = 12 * v + coord_slot(d, c);
                }
            }
        }
    s->a->col_start[N] = (dk_index)at;
    memset(s->a->values, 0, (size_t)at * sizeof(double));
    for (dk_index u = 0; u < nf; u++) /* a definite placeholder for the analysis */
        for (int a = 0; a < 12; a++)
            s->a->values[s->diag_pos[12 * u + a]] = 1.0;
    for (dk_index e = 0; e < ed->n_edges; e++)
        for (int dir = 0; dir < 2; dir++) {
            const dk_index j = s->node_unknown[ed->edges[2 * e + dir]];
            const dk_index q = s->node_unknown[ed->edges[2 * e + 1 - dir]];
            int64_t *b = s->edge_blk + 8 * (size_t)e + 4 * dir;
            b[0] = block_of(s, j, j);
            b[1] = block_of(s, j, q);
            b[2] = block_of(s, q, j);
            b[3] = block_of(s, q, q);
        }
    for (dk_index l = 0; l < s->n_pos; l++) {
        const dk_index *nb = ed->nb + (size_t)s->pos_vertex[l] * k;
        for (dk_index p = 0; p < k; p++)
            for (dk_index q = 0; q < k; q++)
                s->pos_blk[((size_t)l * k + p) * k + q] =
                    block_of(s, nb[p] >= 0 ? s->node_unknown[nb[p]] : -1,
                             nb[q] >= 0 ? s->node_unknown[nb[q]] : -1);
    }
    st = dk_cholesky_analyze(s->a, &s->chol, err);
    if (st != DK_OK)
        return dk_error_prefix(err, "EmbeddedDeformation: analysis");
    dk_cholesky_set_team(s->chol, ed->team);
    ed->analysis_count++;
    return DK_OK;
}

/* `phase`: the index of "constraints" in the running bind's or rebind's phase table (the
 * analysis follows it). */
static dk_status system_build(dk_embedded *ed, const dk_constraint_desc *desc, ed_system *s,
                              int phase, dk_error *err)
{
    memset(s, 0, sizeof *s);
    dk_status st = dk_progress_begin(ed->prog, phase, err);
    if (st != DK_OK)
        return st;
    st = dk_constraints_create(ed->mesh, desc, &s->con, err);
    if (st != DK_OK)
        return dk_error_prefix(err, "EmbeddedDeformation");
    st = classify(ed, s, err);
    if (st == DK_OK)
        st = block_pattern(ed, s, err);
    if (st == DK_OK)
        st = dk_progress_begin(ed->prog, phase + 1, err);
    if (st == DK_OK)
        st = matrix(ed, s, err);
    if (st != DK_OK)
        system_free(s);
    return st;
}

/* ------------------------------------------------------------------ energy, J^T J ------ */

/* One residual's Jacobian row: up to 2 K_MAX nodes' entries, each a free index u (-1: a
 * constant node, no unknowns), its 4 slots of coordinate d (R[d][0..2], t[d]) or 6 of a
 * rotation residual, and their coefficients. */
typedef struct jrow {
    int n;
    dk_index u[2 * K_MAX];
    int64_t blk[2 * K_MAX][2 * K_MAX];
    int ns;
    int slot[2 * K_MAX][6];
    double coef[2 * K_MAX][6];
} jrow;

/* Adds r^2 to *F, and, when `s` is given, the row's part of J^T f (into grad) and J^T J
 * (into the blocks). */
static void add_row(ed_system *s, const jrow *j, double r, double *F)
{
    *F += r * r;
    if (!s)
        return;
    for (int p = 0; p < j->n; p++) {
        if (j->u[p] < 0)
            continue;
        for (int i = 0; i < j->ns; i++)
            s->grad[12 * j->u[p] + j->slot[p][i]] += j->coef[p][i] * r;
        for (int q = 0; q < j->n; q++) {
            const int64_t b = j->blk[p][q];
            if (b < 0)
                continue;
            double *B = s->blocks + 144 * (size_t)b;
            for (int i = 0; i < j->ns; i++)
                for (int c = 0; c < j->ns; c++)
                    B[12 * j->slot[p][i] + j->slot[q][c]] += j->coef[p][i] * j->coef[q][c];
        }
    }
}

/* The unit of length of F: twice the root mean square distance of the points from their
 * centroid (a sphere's diameter, 0.82 for the unit square), so that it does not depend on
 * where the model is or how it is turned, as a bounding box would; 1 when the points
 * coincide. Our choice: the paper gives no unit. */
static double unit_length(const double *p, dk_index n)
{
    double c[3] = {0.0, 0.0, 0.0}, s = 0.0;
    for (dk_index i = 0; i < n; i++)
        for (int d = 0; d < 3; d++)
            c[d] += p[3 * (size_t)i + d] / (double)n;
    for (dk_index i = 0; i < n; i++)
        for (int d = 0; d < 3; d++) {
            const double e = p[3 * (size_t)i + d] - c[d];
            s += e * e / (double)n;
        }
    const double L = 2.0 * sqrt(s);
    return L > 0.0 && isfinite(L) ? L : 1.0;
}

/* F(x) (eq. 9); with `s`, also J^T f (s->grad) and J^T J (s->blocks, then s->a).
 *
 * Lengths are measured in units of ed->L (unit_length() of the bind mesh): E_reg and E_con are
 * divided by L^2, and the unknowns are R and t / L. The paper gives fixed weights (w_rot 1,
 * w_reg 10, w_con 100) and eq. 12's tests against 1, but E_rot is dimensionless while E_reg
 * and E_con scale with length squared: in the model's own units the same scene scaled by
 * 0.01 stopped 5% of its diagonal off, at 1e-6 after no iteration at all, and from about 20x
 * up a 45 degree handle turn returned the rest pose (the second hostile review). In units of
 * L, F, its gradient, the steps and the tests are the same at any scale. So the Jacobian's
 * columns are those of t / L (a t entry's coefficient is L times its length one: wg, wc w),
 * gn_step moves t by L times its step, and the step and iterate norms read t / L. ed->x
 * itself stays in the model's units. */
static double evaluate(const dk_embedded *ed, ed_system *s, const ed_system *sys,
                       const double *x)
{
    const dk_index k = ed->k, m = ed->m;
    const double wr = sqrt(ed->opt.w_rot), wg = sqrt(ed->opt.w_reg), wc = sqrt(ed->opt.w_con);
    const double wgL = wg / ed->L, wcL = wc / ed->L; /* per unit of length */
    double F = 0.0;
    jrow jr;
    if (s) {
        memset(s->grad, 0, 12 * (size_t)s->n_free * sizeof(double));
        memset(s->blocks, 0, 144 * (size_t)s->n_blocks * sizeof(double));
    }
    /* rotation (eqs. 5-6): six residuals per free node over its 9 R entries */
    static const int pairs[6][2] = {{0, 1}, {0, 2}, {1, 2}, {0, 0}, {1, 1}, {2, 2}};
    for (dk_index j = 0; j < m; j++) {
        const dk_index u = sys->node_unknown[j];
        if (u < 0)
            continue; /* R = I: Rot = 0 */
        const double *R = x + 12 * (size_t)j;
        for (int r = 0; r < 6; r++) {
            const int a = pairs[r][0], b = pairs[r][1];
            double dot = 0.0;
            for (int d = 0; d < 3; d++)
                dot += R[3 * d + a] * R[3 * d + b];
            if (a == b)
                dot -= 1.0;
            jr.n = 1;
            jr.u[0] = u;
            jr.blk[0][0] = s ? block_of(sys, u, u) : -1;
            jr.ns = 6;
            for (int d = 0; d < 3; d++) { /* d(c_a . c_b)/dR[d][a] = R[d][b] and vice versa */
                jr.slot[0][2 * d] = 3 * d + a;
                jr.slot[0][2 * d + 1] = 3 * d + b;
                jr.coef[0][2 * d] = wr * (a == b ? R[3 * d + a] : R[3 * d + b]);
                jr.coef[0][2 * d + 1] = wr * (a == b ? R[3 * d + a] : R[3 * d + a]);
            }
            add_row(s, &jr, wr * dot, &F);
        }
    }
    /* regularization (eq. 7), both directions of each edge, one residual per coordinate */
    for (dk_index e = 0; e < ed->n_edges; e++)
        for (int dir = 0; dir < 2; dir++) {
            const dk_index j = ed->edges[2 * e + dir], q = ed->edges[2 * e + 1 - dir];
            const double *Rj = x + 12 * (size_t)j, *tj = Rj + 9, *tq = x + 12 * (size_t)q + 9;
            const double *gj = ed->g + 3 * j, *gq = ed->g + 3 * q;
            const double dg[3] = {gq[0] - gj[0], gq[1] - gj[1], gq[2] - gj[2]};
            const int64_t *b = sys->edge_blk + 8 * (size_t)e + 4 * dir;
            for (int d = 0; d < 3; d++) {
                const double r = Rj[3 * d] * dg[0] + Rj[3 * d + 1] * dg[1] +
                                 Rj[3 * d + 2] * dg[2] + gj[d] + tj[d] - gq[d] - tq[d];
                jr.n = 2;
                jr.u[0] = sys->node_unknown[j];
                jr.u[1] = sys->node_unknown[q];
                jr.blk[0][0] = b[0];
                jr.blk[0][1] = b[1];
                jr.blk[1][0] = b[2];
                jr.blk[1][1] = b[3];
                jr.ns = 4;
                for (int c = 0; c < 3; c++) {
                    jr.slot[0][c] = 3 * d + c;
                    jr.coef[0][c] = wgL * dg[c];
                    jr.slot[1][c] = 3 * d + c;
                    jr.coef[1][c] = 0.0; /* t_q only: its R does not enter */
                }
                jr.slot[0][3] = 9 + d;
                jr.coef[0][3] = wg;
                jr.slot[1][3] = 9 + d;
                jr.coef[1][3] = -wg;
                add_row(s, &jr, wgL * r, &F);
            }
        }
    /* positional terms (eq. 8): handles to their targets, held fixed vertices to rest */
    for (dk_index l = 0; l < sys->n_pos; l++) {
        const dk_index v = sys->pos_vertex[l];
        const double *p = ed->p + 3 * v;
        const dk_index *nb = ed->nb + (size_t)v * k;
        const double *wv = ed->w + (size_t)v * k;
        const double *tg = sys->pos_target_row[l] >= 0 ? sys->targets + 3 * sys->pos_target_row[l]
                                                       : p;
        for (int d = 0; d < 3; d++) {
            double r = -tg[d];
            jr.n = 0;
            jr.ns = 4;
            for (dk_index q = 0; q < k; q++) {
                const dk_index j = nb[q];
                if (j < 0)
                    continue;
                const double *R = x + 12 * (size_t)j, *g = ed->g + 3 * j;
                const double dv[3] = {p[0] - g[0], p[1] - g[1], p[2] - g[2]};
                r += wv[q] * (R[3 * d] * dv[0] + R[3 * d + 1] * dv[1] + R[3 * d + 2] * dv[2] +
                              g[d] + R[9 + d]);
                const int c = jr.n++;
                jr.u[c] = sys->node_unknown[j];
                for (int e = 0; e < 3; e++) {
                    jr.slot[c][e] = 3 * d + e;
                    jr.coef[c][e] = wcL * wv[q] * dv[e];
                }
                jr.slot[c][3] = 9 + d;
                jr.coef[c][3] = wc * wv[q];
            }
            if (s) { /* the blocks of this vertex's node pairs (valid entries only) */
                int c = 0;
                int idx[K_MAX];
                for (dk_index q = 0; q < k; q++)
                    if (nb[q] >= 0)
                        idx[c++] = (int)q;
                for (int a = 0; a < jr.n; a++)
                    for (int b2 = 0; b2 < jr.n; b2++)
                        jr.blk[a][b2] = sys->pos_blk[((size_t)l * k + idx[a]) * k + idx[b2]];
            }
            add_row(s, &jr, wcL * r, &F);
        }
    }
    if (s) /* the blocks into the CSC values: block (u, v) entry (a, c) = row 12v+c, col 12u+a;
            * between different nodes only the entries of one coordinate exist (matrix()) */
        for (dk_index u = 0; u < s->n_free; u++)
            for (int a = 0; a < 12; a++) {
                const int d = slot_coord(a);
                int64_t at = s->a->col_start[12 * u + a];
                for (dk_index b = s->blk_start[u]; b < s->blk_start[u + 1]; b++) {
                    const double *B = s->blocks + 144 * (size_t)b + 12 * a;
                    if (s->blk_node[b] == u)
                        for (int c = 0; c < 12; c++)
                            s->a->values[at++] = B[c];
                    else
                        for (int c = 0; c < 4; c++)
                            s->a->values[at++] = B[coord_slot(d, c)];
                }
            }
    return F;
}

/* ------------------------------------------------------------------ solve -------------- */

static void identity(double *x, dk_index m)
{
    static const double id[12] = {1, 0, 0, 0, 1, 0, 0, 0, 1, 0, 0, 0};
    for (dk_index j = 0; j < m; j++)
        memcpy(x + 12 * (size_t)j, id, sizeof id);
}

/* eq. 2 for every vertex; a vertex whose nodes are all constants is copied (the blend of
 * identities would give it back only to rounding) */
static void apply(const dk_embedded *ed, const double *x, double *out)
{
    const dk_index k = ed->k;
    const unsigned char *held_at_rest = ed->sys.con->held;
    for (dk_index v = 0; v < ed->n; v++) {
        const double *p = ed->p + 3 * v;
        int moving = 0;
        if (held_at_rest[v]) { /* loose geometry nothing constrains: at rest */
            memcpy(out + 3 * v, p, 3 * sizeof(double));
            continue;
        }
        for (dk_index q = 0; q < k; q++) {
            const dk_index j = ed->nb[(size_t)v * k + q];
            moving |= j >= 0 && ed->sys.node_unknown[j] >= 0;
        }
        if (!moving) {
            memcpy(out + 3 * v, p, 3 * sizeof(double));
            continue;
        }
        double o[3] = {0.0, 0.0, 0.0};
        for (dk_index q = 0; q < k; q++) {
            const dk_index j = ed->nb[(size_t)v * k + q];
            if (j < 0)
                continue;
            const double w = ed->w[(size_t)v * k + q], *R = x + 12 * (size_t)j;
            const double *g = ed->g + 3 * j;
            const double d[3] = {p[0] - g[0], p[1] - g[1], p[2] - g[2]};
            for (int c = 0; c < 3; c++)
                o[c] += w * (R[3 * c] * d[0] + R[3 * c + 1] * d[1] + R[3 * c + 2] * d[2] +
                             g[c] + R[9 + c]);
        }
        memcpy(out + 3 * v, o, sizeof o);
    }
}

static double inf_norm(const double *a, size_t n)
{
    double m = 0.0;
    for (size_t i = 0; i < n; i++)
        m = fmax(m, fabs(a[i]));
    return m;
}

/* |x|_inf of the transformations with t in units of ed->L (the unknowns of evaluate()) */
static double x_norm(const dk_embedded *ed, const double *x)
{
    double m = 0.0;
    for (size_t i = 0; i < 12 * (size_t)ed->m; i++)
        m = fmax(m, fabs(x[i]) / (i % 12 >= 9 ? ed->L : 1.0));
    return m;
}

/* One damped Gauss-Newton step (Levenberg-Marquardt with Nielsen's damping update, Madsen,
 * Nielsen & Tingleff 2004, the reference the paper gives): solves (J^T J + mu I) d = -J^T f
 * and compares the decrease of F with the one the linear model predicts,
 * rho = (F - F(x + d)) / (d . (mu d - J^T f)). A step with rho > 0 is taken and mu scaled by
 * max(1/3, 1 - (2 rho - 1)^3); otherwise mu grows by nu, which doubles on every refusal (at
 * most 30). mu starts at 0 (the plain Gauss-Newton step of eq. 11) and, at the first
 * refusal, at 1e-6 of J^T J's mean diagonal. *accepted: whether a step was taken. */
static dk_status gn_step(dk_embedded *ed, double F, double *mu, double *nu, double *F_new,
                         double *dnorm, int *accepted, dk_error *err)
{
    ed_system *s = &ed->sys;
    const size_t N = 12 * (size_t)s->n_free;
    double trace = 0.0;
    for (size_t i = 0; i < N; i++)
        trace += s->a->values[s->diag_pos[i]];
    *accepted = 0;
    for (int attempt = 0; attempt < 30 && !*accepted; attempt++) {
        for (size_t i = 0; i < N; i++)
            s->a->values[s->diag_pos[i]] += *mu;
        dk_status st = dk_cholesky_factorize(s->chol, s->a, err);
        for (size_t i = 0; i < N; i++)
            s->a->values[s->diag_pos[i]] -= *mu;
        if (st == DK_OK) {
            ed->factorization_count++;
            for (size_t i = 0; i < N; i++)
                s->step[i] = -s->grad[i];
            st = dk_cholesky_solve(s->chol, s->step, 1, s->step, err);
            if (st != DK_OK)
                return dk_error_prefix(err, "EmbeddedDeformation solve");
            memcpy(s->x_try, ed->x, 12 * (size_t)ed->m * sizeof(double));
            double pred = 0.0;
            for (dk_index u = 0; u < s->n_free; u++)
                for (int a = 0; a < 12; a++) { /* the step of t is in units of L */
                    const double d = s->step[12 * u + a];
                    s->x_try[12 * (size_t)s->free_nodes[u] + a] += a >= 9 ? ed->L * d : d;
                    pred += d * (*mu * d - s->grad[12 * u + a]);
                }
            const double Ft = evaluate(ed, NULL, s, s->x_try);
            const double rho = pred > 0.0 ? (F - Ft) / pred : (Ft < F ? 1.0 : -1.0);
            if (rho > 0.0 || (Ft == F && inf_norm(s->step, N) == 0.0)) {
                memcpy(ed->x, s->x_try, 12 * (size_t)ed->m * sizeof(double));
                *F_new = Ft;
                *dnorm = inf_norm(s->step, N);
                *accepted = 1;
                const double c = 2.0 * rho - 1.0;
                *mu *= fmax(1.0 / 3.0, 1.0 - c * c * c);
                *nu = 2.0;
                return DK_OK;
            }
        } else if (st != DK_ERR_NOT_POSITIVE_DEFINITE) {
            return dk_error_prefix(err, "EmbeddedDeformation solve");
        }
        if (*mu > 0.0) {
            *mu *= *nu;
            *nu *= 2.0;
        } else {
            *mu = fmax(1e-6 * trace / (double)N, 1e-300);
        }
    }
    *F_new = F;
    *dnorm = 0.0;
    return DK_OK;
}

dk_status dk_embedded_solve(dk_embedded *ed, const dk_solve_request *rq, double *positions,
                            dk_solve_info *info, dk_error *err)
{
    if (info)
        memset(info, 0, sizeof *info);
    if (!ed || !positions)
        return dk_error_set(err, DK_ERR_INVALID_ARGUMENT,
                            "EmbeddedDeformation solve: object and positions must not be NULL");
    dk_status st = dk_solve_request_check(rq, "EmbeddedDeformation solve", err);
    if (st != DK_OK)
        return st;
    if (rq->start == DK_START_GIVEN) /* positions do not determine the graph's affine maps */
        return dk_error_set(err, DK_ERR_INVALID_ARGUMENT,
                            "EmbeddedDeformation solve: it cannot start from given positions "
                            "(its iterate is the graph's node transformations); use a cold or "
                            "warm start");
    ed_system *s = &ed->sys;
    st = dk_constraints_targets(s->con, ed->p, rq->targets, (int)rq->target_kind,
                                s->targets, err);
    if (st != DK_OK)
        return dk_error_prefix(err, "EmbeddedDeformation solve");
    if (rq->start == DK_START_COLD)
        identity(ed->x, ed->m);
    const int maxit = rq->max_iterations > 0 ? rq->max_iterations : ed->opt.max_iterations;
    const double eps = ed->opt.tolerance;
    const size_t N = 12 * (size_t)s->n_free;
    double F = evaluate(ed, s, s, ed->x), mu = 0.0, nu = 2.0;
    int it = 0;
    /* Eq. 12 as Gill, Murray & Wright give it (the paper's reference): converged when the
     * change of F, the gradient (grad F = 2 J^T f) and the step are all small, each against
     * 1 + its scale; or, before any step, when the gradient is already negligible in absolute
     * terms (their U4; eps^2 of the dimensionless F: a zero drag). The gradient test alone,
     * as an alternative, let a large F stop after 0 or 1 steps. */
    int converged = 2.0 * inf_norm(s->grad, N) <= eps * eps;
    double prev_dnorm = 0.0, prev_change = 0.0;
    while (!converged && it < maxit) {
        double F_new, dnorm;
        int accepted;
        st = gn_step(ed, F, &mu, &nu, &F_new, &dnorm, &accepted, err);
        if (st != DK_OK)
            return st;
        if (!accepted)
            break; /* no descent even with heavy damping: a stationary point for all we see */
        it++;
        const double change = fabs(F - F_new);
        F = evaluate(ed, s, s, ed->x);
        /* Gauss-Newton converges linearly here (a non-zero residual), often slowly where
         * the constraints conflict: a step and a decrease below the tests can leave many
         * more of about the same size to come (1.5e-3 of the model's size on the contract
         * grid, whose handles pull against its fixed row). So the tests read what remains,
         * extrapolated from the rate of the last two: x d / (1 - r), r the ratio of the step
         * norms (and of the decreases); a rate of 1 or more never passes. Our choice, in
         * the spirit of Gill et al.'s tests, which assume a step near the solution says how
         * near it is. */
        const double rate_d = prev_dnorm > 0.0 ? dnorm / prev_dnorm : 0.0;
        const double rate_f = prev_change > 0.0 ? change / prev_change : 0.0;
        const double left_d = rate_d < 1.0 ? dnorm / (1.0 - rate_d) : INFINITY;
        const double left_f = rate_f < 1.0 ? change / (1.0 - rate_f) : INFINITY;
        prev_dnorm = dnorm;
        prev_change = change;
        if (it >= 2 && left_f < eps * (1.0 + F) &&
            2.0 * inf_norm(s->grad, N) < cbrt(eps) * (1.0 + F) &&
            left_d < sqrt(eps) * (1.0 + x_norm(ed, ed->x)))
            converged = 1;
    }
    dk_team_park(ed->team); /* the helper sleeps until the next solve */
    apply(ed, ed->x, positions);
    st = dk_solve_result_check(positions, ed->n, F, !rq->skip_energy,
                               "EmbeddedDeformation solve", err);
    if (st != DK_OK) { /* a non-finite end is no start: the next solve starts from rest */
        identity(ed->x, ed->m);
        return st;
    }
    ed->energy = F;
    if (info) {
        info->energy = rq->skip_energy ? NAN : F; /* skipped: NaN, as the contract says */
        info->iterations = it;
        info->converged = converged;
    }
    return DK_OK;
}

/* ------------------------------------------------------------------ bind, rebind ------- */

void dk_embedded_free(dk_embedded *ed)
{
    if (!ed)
        return;
    system_free(&ed->sys);
    dk_team_free(ed->team); /* after the factor, which used it */
    free(ed->g);
    free(ed->nb);
    free(ed->w);
    free(ed->vside);
    free(ed->nside);
    free(ed->p);
    free(ed->node_vertex);
    free(ed->node_face);
    free(ed->node_bary);
    free(ed->edges);
    free(ed->adj_start);
    free(ed->adj);
    free(ed->x);
    free(ed);
}

dk_status dk_embedded_bind(const dk_mesh *mesh, const dk_constraint_desc *constraints,
                           const dk_embedded_options *options, dk_embedded **out,
                           dk_error *err)
{
    if (out)
        *out = NULL;
    if (!mesh || !constraints || !out)
        return dk_error_set(err, DK_ERR_INVALID_ARGUMENT,
                            "EmbeddedDeformation: mesh, constraints and output must not be "
                            "NULL");
    dk_embedded *ed = calloc(1, sizeof *ed);
    if (!ed)
        return oom(err, "object");
    if (options)
        ed->opt = *options;
    else
        dk_embedded_default_options(&ed->opt);
    dk_progress prog;
    dk_progress_init(&prog, ed->opt.progress, ed->opt.progress_user, ed_bind_phases,
                     (int)(sizeof ed_bind_phases / sizeof ed_bind_phases[0]),
                     "EmbeddedDeformation bind");
    ed->opt.progress = NULL; /* the caller's callback is for this bind only */
    ed->opt.progress_user = NULL;
    ed->prog = &prog;
    ed->mesh = mesh;
    ed->n = mesh->n_vertices;
    ed->k = ed->opt.k;
    ed->team = dk_team_create(); /* NULL (no thread available) is fine */
    dk_status st = check_options(&ed->opt, err);
    if (st == DK_OK) { /* 0. the source's positions, the mesh's until updated */
        ed->p = malloc((3 * (size_t)ed->n + 1) * sizeof *ed->p);
        if (ed->p)
            memcpy(ed->p, mesh->positions, 3 * (size_t)ed->n * sizeof *ed->p);
        else
            st = oom(err, "positions");
    }
    if (st == DK_OK) /* the unit of length of F (evaluate()) */
        ed->L = unit_length(mesh->positions, ed->n);
    if (st == DK_OK && (st = dk_progress_begin(&prog, 0, err)) == DK_OK) /* 1. the nodes */
        st = sample_nodes(ed, err);
    if (st == DK_OK && (st = dk_progress_begin(&prog, 1, err)) == DK_OK) /* 2. eq. 4 */
        st = weights(ed, err);
    if (st == DK_OK && (st = dk_progress_begin(&prog, 2, err)) == DK_OK) /* 3. the edges */
        st = edges(ed, err);
    if (st == DK_OK) { /* 4. the transformations, identity */
        ed->x = malloc((12 * (size_t)ed->m + 1) * sizeof *ed->x);
        if (!ed->x)
            st = oom(err, "transformations");
        else
            identity(ed->x, ed->m);
    }
    if (st == DK_OK) /* 5. the constraints: fixed nodes, positional terms, J^T J's pattern */
        st = system_build(ed, constraints, &ed->sys, 3, err);
    ed->prog = NULL;
    if (st != DK_OK) {
        dk_embedded_free(ed);
        return st;
    }
    ed->energy = 0.0;
    dk_progress_done(&prog);
    *out = ed;
    return DK_OK;
}

dk_status dk_embedded_rebind(dk_embedded *ed, const dk_constraint_desc *constraints,
                             dk_error *err)
{
    if (!ed || !constraints)
        return dk_error_set(err, DK_ERR_INVALID_ARGUMENT,
                            "EmbeddedDeformation rebind: object and constraints must not be "
                            "NULL");
    ed_system s;
    dk_progress prog;
    dk_progress_init(&prog, ed->opt.progress, ed->opt.progress_user, ed_rebind_phases,
                     (int)(sizeof ed_rebind_phases / sizeof ed_rebind_phases[0]),
                     "EmbeddedDeformation rebind");
    ed->prog = &prog;
    dk_status st = system_build(ed, constraints, &s, 0, err);
    ed->prog = NULL;
    if (st != DK_OK)
        return st;
    dk_progress_done(&prog);
    system_free(&ed->sys);
    ed->sys = s;
    return DK_OK;
}

void dk_embedded_set_progress(dk_embedded *ed, dk_phase_progress_fn progress, void *user)
{
    if (!ed)
        return;
    ed->opt.progress = progress;
    ed->opt.progress_user = progress ? user : NULL;
}

/* ------------------------------------------------------------------ normals, points --- */

dk_status dk_embedded_update_source(dk_embedded *ed, const double *positions, dk_error *err)
{
    if (!ed || !positions)
        return dk_error_set(err, DK_ERR_INVALID_ARGUMENT,
                            "EmbeddedDeformation update_source: object and positions must not "
                            "be NULL");
    dk_status st = dk_check_positions(positions, ed->n, err);
    if (st != DK_OK)
        return dk_error_prefix(err, "EmbeddedDeformation update_source");
    memcpy(ed->p, positions, 3 * (size_t)ed->n * sizeof *ed->p);
    for (dk_index j = 0; j < ed->m; j++) {
        double *g = ed->g + 3 * (size_t)j;
        if (ed->node_vertex) { /* section 5: a node on a vertex rides along with it */
            memcpy(g, ed->p + 3 * (size_t)ed->node_vertex[j], 3 * sizeof *g);
            continue;
        }
        /* a surface sample keeps its place in its triangle: the paper's nodes on vertices,
         * generalised to its uniform samples, so that the default graph also follows */
        const dk_index *f = ed->mesh->faces + 3 * (size_t)ed->node_face[j];
        const double *a = ed->p + 3 * (size_t)f[0], *b = ed->p + 3 * (size_t)f[1];
        const double *c = ed->p + 3 * (size_t)f[2];
        const double s = ed->node_bary[2 * (size_t)j], t = ed->node_bary[2 * (size_t)j + 1];
        for (int d = 0; d < 3; d++)
            g[d] = a[d] + s * (b[d] - a[d]) + t * (c[d] - a[d]);
    }
    return DK_OK;
}

/* The state (dk_method_ops.state_size): the graph's transformations a warm start continues
 * from, their energy, the targets energy() reads, and the source a solve deforms with its
 * nodes (update_source). */
static int ed_state_spans(const dk_embedded *ed_const, dk_state_span *sp)
{
    dk_embedded *ed = (dk_embedded *)ed_const; /* save reads through the list restore writes */
    const size_t D = sizeof(double);
    int k = 0;
    sp[k++] = (dk_state_span){ed->x, 12 * (size_t)ed->m * D};
    sp[k++] = (dk_state_span){&ed->energy, D};
    sp[k++] = (dk_state_span){ed->sys.targets, 3 * (size_t)ed->sys.con->n_handle_vertices * D};
    sp[k++] = (dk_state_span){ed->p, 3 * (size_t)ed->n * D};
    sp[k++] = (dk_state_span){ed->g, 3 * (size_t)ed->m * D};
    return k;
}

static void ed_state_shape(const dk_embedded *ed, uint64_t shape[4])
{
    shape[0] = (uint64_t)ed->n;
    shape[1] = (uint64_t)ed->sys.con->n_handle_vertices;
    shape[2] = (uint64_t)ed->m;
    shape[3] = (uint64_t)ed->k;
}

size_t dk_embedded_state_size(const dk_embedded *ed)
{
    dk_state_span sp[5];
    return ed ? dk_state_size(sp, ed_state_spans(ed, sp)) : 0;
}

dk_status dk_embedded_save_state(const dk_embedded *ed, void *state, size_t size, dk_error *err)
{
    if (!ed)
        return dk_error_set(err, DK_ERR_INVALID_ARGUMENT,
                            "EmbeddedDeformation save_state: object is NULL");
    dk_state_span sp[5];
    uint64_t shape[4];
    ed_state_shape(ed, shape);
    return dk_state_save("EmbeddedDeformation", shape, sp, ed_state_spans(ed, sp), state, size,
                         err);
}

dk_status dk_embedded_restore_state(dk_embedded *ed, const void *state, size_t size,
                                    dk_error *err)
{
    if (!ed)
        return dk_error_set(err, DK_ERR_INVALID_ARGUMENT,
                            "EmbeddedDeformation restore_state: object is NULL");
    dk_state_span sp[5];
    uint64_t shape[4];
    ed_state_shape(ed, shape);
    const int k = ed_state_spans(ed, sp);
    const dk_status st = dk_state_check("EmbeddedDeformation", shape, sp, k, state, size, err);
    if (st == DK_OK)
        dk_state_restore_spans(sp, k, state);
    return st;
}

dk_status dk_embedded_deformed(const dk_embedded *ed, double *positions, dk_error *err)
{
    if (!ed || !positions)
        return dk_error_set(err, DK_ERR_INVALID_ARGUMENT,
                            "EmbeddedDeformation deformed: object and output must not be NULL");
    apply(ed, ed->x, positions);
    return DK_OK;
}

/* The inverse transpose of a 3 x 3 (row-major) into it, or 0 when singular. */
static int inverse_transpose(const double *R, double *o)
{
    const double det = dk_mat3_cofactor(R, o); /* (R^-1)^T = cofactor matrix / det */
    if (!(fabs(det) > 1e-300) || !isfinite(det))
        return 0;
    for (int k = 0; k < 9; k++)
        o[k] /= det;
    return 1;
}

dk_status dk_embedded_normals(const dk_embedded *ed, const double *normals, double *out,
                              dk_error *err)
{
    if (!ed || !out)
        return dk_error_set(err, DK_ERR_INVALID_ARGUMENT,
                            "EmbeddedDeformation normals: object and output must not be NULL");
    const dk_index n = ed->n, k = ed->k;
    const dk_mesh *m = ed->mesh;
    double *rest = NULL;
    if (normals) /* NaN normals came back as zero vectors (the second hostile review) */
        for (size_t i = 0; i < 3 * (size_t)n; i++)
            if (!isfinite(normals[i]))
                return dk_error_set(err, DK_ERR_NONFINITE,
                                    "EmbeddedDeformation normals: the normal of vertex %lld "
                                    "is not finite",
                                    (long long)(i / 3));
    if (!normals) { /* area-weighted vertex normals: the sum of the faces' cross products */
        rest = calloc(3 * (size_t)n + 1, sizeof *rest);
        if (!rest)
            return oom(err, "normals");
        for (dk_index f = 0; f < m->n_faces; f++) {
            const dk_index *t = m->faces + 3 * f;
            const double *a = ed->p + 3 * t[0], *b = ed->p + 3 * t[1];
            const double *c = ed->p + 3 * t[2];
            const double u[3] = {b[0] - a[0], b[1] - a[1], b[2] - a[2]};
            const double v[3] = {c[0] - a[0], c[1] - a[1], c[2] - a[2]};
            const double x[3] = {u[1] * v[2] - u[2] * v[1], u[2] * v[0] - u[0] * v[2],
                                 u[0] * v[1] - u[1] * v[0]};
            for (int q = 0; q < 3; q++)
                for (int d = 0; d < 3; d++)
                    rest[3 * t[q] + d] += x[d];
        }
        normals = rest;
    }
    double *itr = malloc((9 * (size_t)ed->m + 1) * sizeof *itr);
    unsigned char *ok = malloc((size_t)ed->m + 1);
    if (!itr || !ok) {
        free(rest);
        free(itr);
        free(ok);
        return oom(err, "normals");
    }
    for (dk_index j = 0; j < ed->m; j++)
        ok[j] = (unsigned char)inverse_transpose(ed->x + 12 * (size_t)j, itr + 9 * (size_t)j);
    for (dk_index v = 0; v < n; v++) {
        const double *nv = normals + 3 * v;
        double o[3] = {0.0, 0.0, 0.0};
        const int held = ed->sys.con->held[v]; /* at rest: its normal is the rest normal */
        if (held)
            memcpy(o, nv, sizeof o);
        for (dk_index q = 0; q < k && !held; q++) {
            const dk_index j = ed->nb[(size_t)v * k + q];
            if (j < 0 || !ok[j])
                continue;
            const double w = ed->w[(size_t)v * k + q], *M = itr + 9 * (size_t)j;
            for (int d = 0; d < 3; d++)
                o[d] += w * (M[3 * d] * nv[0] + M[3 * d + 1] * nv[1] + M[3 * d + 2] * nv[2]);
        }
        const double len = sqrt(o[0] * o[0] + o[1] * o[1] + o[2] * o[2]);
        for (int d = 0; d < 3; d++)
            out[3 * v + d] = len > 0.0 ? o[d] / len : 0.0;
    }
    free(rest);
    free(itr);
    free(ok);
    return DK_OK;
}

dk_status dk_embedded_embed(const dk_embedded *ed, const double *points, dk_index n_points,
                            dk_index *nodes, double *weights, double *out, dk_error *err)
{
    if (!ed || !points || n_points < 0)
        return dk_error_set(err, DK_ERR_INVALID_ARGUMENT,
                            "EmbeddedDeformation embed: object and points must be given");
    for (size_t i = 0; i < 3 * (size_t)n_points; i++)
        if (!isfinite(points[i]))
            return dk_error_set(err, DK_ERR_NONFINITE,
                                "EmbeddedDeformation embed: point %d is not finite",
                                (int)(i / 3));
    const dk_index k = ed->k;
    if (ed->m < k + 1)
        return dk_error_set(err, DK_ERR_INVALID_ARGUMENT,
                            "EmbeddedDeformation embed: the graph has %d nodes, fewer than "
                            "k + 1 = %d", (int)ed->m, (int)k + 1);
    dk_index *nb = nodes ? nodes : malloc(((size_t)n_points * k + 1) * sizeof *nb);
    double *w = weights ? weights : malloc(((size_t)n_points * k + 1) * sizeof *w);
    dk_kdtree *tree = NULL;
    dk_status st = nb && w ? dk_kdtree_create(ed->g, ed->m, &tree, err) : oom(err, "embed");
    if (st == DK_OK)
        st = embed_points(tree, points, n_points, k, NULL, nb, w, NULL, err);
    for (dk_index p = 0; st == DK_OK && out && p < n_points; p++) {
        const double *x0 = points + 3 * p;
        double o[3] = {0.0, 0.0, 0.0};
        for (dk_index q = 0; q < k; q++) {
            const dk_index j = nb[(size_t)p * k + q];
            if (j < 0)
                continue;
            const double *R = ed->x + 12 * (size_t)j, *g = ed->g + 3 * j;
            const double d[3] = {x0[0] - g[0], x0[1] - g[1], x0[2] - g[2]};
            for (int c = 0; c < 3; c++)
                o[c] += w[(size_t)p * k + q] *
                        (R[3 * c] * d[0] + R[3 * c + 1] * d[1] + R[3 * c + 2] * d[2] + g[c] +
                         R[9 + c]);
        }
        memcpy(out + 3 * p, o, sizeof o);
    }
    dk_kdtree_free(tree);
    if (!nodes)
        free(nb);
    if (!weights)
        free(w);
    return st;
}

/* ------------------------------------------------------------------ accessors ---------- */

dk_status dk_embedded_energy(const dk_embedded *ed, const double *positions, double *energy,
                             dk_error *err)
{
    if (energy)
        *energy = NAN;
    if (!ed || !positions || !energy)
        return dk_error_set(err, DK_ERR_INVALID_ARGUMENT,
                            "EmbeddedDeformation energy: object, positions and energy must "
                            "not be NULL");
    const ed_system *s = &ed->sys;
    /* the graph terms: F of x without the positional terms */
    ed_system graph_only = *s;
    graph_only.n_pos = 0;
    double F = evaluate(ed, NULL, &graph_only, ed->x);
    for (dk_index l = 0; l < s->n_pos; l++) {
        const dk_index v = s->pos_vertex[l];
        const double *tg = s->pos_target_row[l] >= 0 ? s->targets + 3 * s->pos_target_row[l]
                                                     : ed->p + 3 * v;
        for (int d = 0; d < 3; d++) {
            const double r = (positions[3 * v + d] - tg[d]) / ed->L; /* as evaluate() */
            F += ed->opt.w_con * r * r;
        }
    }
    *energy = F;
    return dk_energy_result_check(F, "EmbeddedDeformation energy", err);
}

void dk_embedded_stats(const dk_embedded *ed, dk_method_stats *st)
{
    if (!st)
        return;
    memset(st, 0, sizeof *st);
    if (!ed)
        return;
    st->n_vertices = ed->n;
    st->n_handles = ed->sys.con->n_handles;
    st->n_handle_vertices = ed->sys.con->n_handle_vertices;
    dk_constraints_held_stats(ed->sys.con, NULL, st);
    st->n_unknowns = 12 * ed->sys.n_free;
    st->n_graph_nodes = ed->m;
    st->analysis_count = ed->analysis_count;
    st->factorization_count = ed->factorization_count;
}

dk_index dk_embedded_n_nodes(const dk_embedded *ed)
{
    return ed ? ed->m : 0;
}

dk_index dk_embedded_k(const dk_embedded *ed)
{
    return ed ? ed->k : 0;
}

const double *dk_embedded_nodes(const dk_embedded *ed)
{
    return ed ? ed->g : NULL;
}

const double *dk_embedded_transforms(const dk_embedded *ed)
{
    return ed ? ed->x : NULL;
}

int dk_embedded_node_is_fixed(const dk_embedded *ed, dk_index node)
{
    return ed && node >= 0 && node < ed->m && ed->sys.node_unknown[node] < 0;
}

dk_index dk_embedded_n_edges(const dk_embedded *ed)
{
    return ed ? ed->n_edges : 0;
}

const dk_index *dk_embedded_edges(const dk_embedded *ed)
{
    return ed ? ed->edges : NULL;
}

/* ---------------------------------------------------------------- the method contract --- */

/* the contract's table (dk_method.h): the adapters cast to this method's types */
dk_status dk_embedded_estimate_memory(const dk_mesh *mesh, const dk_embedded_options *options,
                                      uint64_t *bytes, dk_error *err)
{
    if (!mesh || !bytes)
        return dk_error_set(err, DK_ERR_INVALID_ARGUMENT,
                            "EmbeddedDeformation estimate_memory: mesh and bytes must not be "
                            "NULL");
    dk_embedded_options o;
    if (options)
        o = *options;
    else
        dk_embedded_default_options(&o);
    dk_status st = check_options(&o, err); /* what bind refuses */
    if (st != DK_OK)
        return st;
    const double n = (double)mesh->n_vertices, k = o.k > 0 ? o.k : 4;
    /* the node count the bind will keep: n_nodes (at most the vertices), or for a radius r
     * the count a random disk packing leaves on the surface's area A, measured 0.51-0.65
     * A / r^2 on the arm and the armadillo (0.7 here), capped as sample_nodes caps it */
    double m = o.n_nodes > 0 ? o.n_nodes : 200.0;
    if (o.radius > 0.0) {
        double area = 0.0;
        for (dk_index f = 0; f < mesh->n_faces; f++) {
            const double *a = mesh->positions + 3 * (size_t)mesh->faces[3 * f];
            const double *b = mesh->positions + 3 * (size_t)mesh->faces[3 * f + 1];
            const double *c = mesh->positions + 3 * (size_t)mesh->faces[3 * f + 2];
            const double u[3] = {b[0] - a[0], b[1] - a[1], b[2] - a[2]};
            const double v[3] = {c[0] - a[0], c[1] - a[1], c[2] - a[2]};
            const double x = u[1] * v[2] - u[2] * v[1], y = u[2] * v[0] - u[0] * v[2],
                         z = u[0] * v[1] - u[1] * v[0];
            area += 0.5 * sqrt(x * x + y * y + z * z);
        }
        m = mesh->n_faces > 0 ? 0.7 * area / (o.radius * o.radius) : n;
        if (!(m <= ED_MAX_NODES + 1.0))
            m = ED_MAX_NODES + 1.0;
    }
    if (m > n)
        m = n;
    if (m < 1.0)
        m = 1.0;
    /* per vertex its k nodes and weights: measured 430 B at 43k; per node J^T J's 12 x 12
     * blocks and their factor, whose edges grow with k: measured 41-112 KB at k = 4 (200 to
     * 20,000 nodes on the arm and the armadillo, nodes on every vertex included) and 193-244
     * KB at k = 8 (2.2x); 16 MiB at any size: the factor's first BLAS buffers */
    const double per_vertex = 500.0 + (k > 4 ? 24.0 * (k - 4) : 0.0);
    const double per_node = 115000.0 * pow(k / 4.0, 1.25);
    *bytes = dk_memory_model(per_vertex, n, per_node * m + 16.0 * 1048576.0);
    return DK_OK;
}

/* the options' fields (dk_option_desc): where each is, what values bind takes */
static const dk_option_desc embedded_fields[] = {
    {"nodes", DK_OPTION_ENUM, offsetof(dk_embedded_options, nodes), 0, 0, 1, 0, 1, 0},
    {"n_nodes", DK_OPTION_INT, offsetof(dk_embedded_options, n_nodes), 0, 1, ED_MAX_NODES, 200,
     40, 0},
    {"radius", DK_OPTION_DOUBLE, offsetof(dk_embedded_options, radius), 0, DBL_TRUE_MIN,
     DBL_MAX, 0.25, DBL_MAX, DK_OPTION_LENGTH | DK_OPTION_ZERO_AUTO},
    {"k", DK_OPTION_INT, offsetof(dk_embedded_options, k), 0, 1, K_MAX, 4, 8, 0},
    {"distance", DK_OPTION_ENUM, offsetof(dk_embedded_options, distance), 0, 0, 1, 0, 1, 0},
    {"cut_a", DK_OPTION_VERTICES, offsetof(dk_embedded_options, cut_a),
     offsetof(dk_embedded_options, n_cut_a), 0, 0, 0, 0, 0},
    {"cut_b", DK_OPTION_VERTICES, offsetof(dk_embedded_options, cut_b),
     offsetof(dk_embedded_options, n_cut_b), 0, 0, 0, 0, 0},
    {"w_rot", DK_OPTION_DOUBLE, offsetof(dk_embedded_options, w_rot), 0, DBL_TRUE_MIN, DBL_MAX,
     1.0, DBL_MAX, 0},
    {"w_reg", DK_OPTION_DOUBLE, offsetof(dk_embedded_options, w_reg), 0, DBL_TRUE_MIN, DBL_MAX,
     10.0, DBL_MAX, 0},
    {"w_con", DK_OPTION_DOUBLE, offsetof(dk_embedded_options, w_con), 0, DBL_TRUE_MIN, DBL_MAX,
     100.0, DBL_MAX, 0},
    {"tolerance", DK_OPTION_DOUBLE, offsetof(dk_embedded_options, tolerance), 0, DBL_TRUE_MIN,
     DBL_MAX, 1e-6, DBL_MAX, 0},
    {"max_iterations", DK_OPTION_INT, offsetof(dk_embedded_options, max_iterations), 0, 1,
     INT_MAX, 100, 20, 0},
    {"seed", DK_OPTION_SEED, offsetof(dk_embedded_options, seed), 0, 0, 0, 1, 0, 0},
};

DK_METHOD_OPS_STATEFUL(dk_embedded_ops, "EmbeddedDeformation",
              DK_METHOD_ITERATIVE | DK_METHOD_TRANSFORMS_AS_POSITIONS |
              DK_METHOD_TRANSLATION_INVARIANT | DK_METHOD_RIGID_INVARIANT |
              DK_METHOD_PENALTY_HANDLES | DK_METHOD_GRAPH, DK_CONTROL_VERTEX_GROUPS,
              dk_embedded, dk_embedded, dk_embedded_options, embedded_fields);
