/* DeformKit embedded deformation: the graph's nodes (embedded_internal.h). */
#include "embedded_internal.h"

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
        return ed_oom(err, "surface samples");
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
dk_status ed_sample_nodes(dk_embedded *ed, dk_error *err)
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
        st = ed_oom(err, "node sampling");
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
        st = ed_oom(err, "node sampling");
        goto done;
    }
    ed->g = malloc(3 * ((size_t)count + 1) * sizeof *ed->g);
    if (!ed->g) {
        st = ed_oom(err, "nodes");
        goto done;
    }
    for (dk_index i = 0; i < count; i++)
        memcpy(ed->g + 3 * i, cand + 3 * kept[i], 3 * sizeof(double));
    if (from_vertices) { /* candidates are the vertices: remember which */
        if (!(ed->node_vertex = malloc(((size_t)count + 1) * sizeof *ed->node_vertex))) {
            st = ed_oom(err, "nodes");
            goto done;
        }
        memcpy(ed->node_vertex, kept, (size_t)count * sizeof *kept);
    } else { /* surface samples: remember where, so that they ride along a moving mesh */
        ed->node_face = malloc(((size_t)count + 1) * sizeof *ed->node_face);
        ed->node_bary = malloc(2 * ((size_t)count + 1) * sizeof *ed->node_bary);
        if (!ed->node_face || !ed->node_bary) {
            st = ed_oom(err, "nodes");
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
