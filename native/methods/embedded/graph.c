/* DeformKit embedded deformation: the graph's edges (embedded_internal.h). */
#include "embedded_internal.h"

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
dk_status ed_edges(dk_embedded *ed, dk_error *err)
{
    const dk_index n = ed->n, k = ed->k, m = ed->m;
    const dk_mesh *mesh = ed->mesh;
    const int64_t cap = (int64_t)n * k * (k - 1) / 2 + (int64_t)mesh->n_edges + 1;
    int64_t *pairs = malloc((size_t)cap * sizeof *pairs), np = 0;
    dk_index *parent = malloc(((size_t)m + 1) * sizeof *parent);
    if (!pairs || !parent) {
        free(pairs);
        free(parent);
        return ed_oom(err, "graph edges");
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
        return ed_oom(err, "graph edges");
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
        return ed_oom(err, "graph edges");
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
