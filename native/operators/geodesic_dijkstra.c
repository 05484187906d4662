/* DeformKit: graph distances along mesh edges (dk_geodesic_dijkstra, dk_hop_distance).
 *
 * Dijkstra with an indexed binary min-heap (decrease-key through a position array), so each
 * vertex enters the heap once: O((V + E) log V). Edge lengths are Euclidean at the mesh's
 * positions. Several sources all start at 0. Hop distance is a breadth-first search.
 */
#include <math.h>
#include <stdlib.h>

#include "dk_operators.h"

static dk_status check_sources(const dk_mesh *mesh, const dk_index *sources, dk_index n_sources,
                               const void *out, const char *what, dk_error *err)
{
    if (!mesh) return dk_error_set(err, DK_ERR_INVALID_ARGUMENT, "%s: mesh is NULL", what);
    if (!out) return dk_error_set(err, DK_ERR_INVALID_ARGUMENT, "%s: output is NULL", what);
    if (n_sources < 0)
        return dk_error_set(err, DK_ERR_INVALID_ARGUMENT, "%s: n_sources is %d", what,
                            (int)n_sources);
    if (n_sources > 0 && !sources)
        return dk_error_set(err, DK_ERR_INVALID_ARGUMENT, "%s: sources is NULL", what);
    dk_status st = dk_check_indices(sources, n_sources, mesh->n_vertices, "source", err);
    if (st != DK_OK) {
        dk_error_prefix(err, "%s", what);
        return st;
    }
    return DK_OK;
}

/* Indexed min-heap on key[]. */
typedef struct vheap {
    dk_index size;
    dk_index *items; /* heap of vertices       */
    dk_index *pos;   /* vertex -> slot, or -1  */
    const double *key;
} vheap;

static void heap_place(vheap *h, dk_index slot, dk_index v)
{
    h->items[slot] = v;
    h->pos[v] = slot;
}

static void sift_up(vheap *h, dk_index slot)
{
    dk_index v = h->items[slot];
    double k = h->key[v];
    while (slot > 0) {
        dk_index parent = (slot - 1) / 2;
        dk_index pv = h->items[parent];
        if (!(k < h->key[pv])) break;
        heap_place(h, slot, pv);
        slot = parent;
    }
    heap_place(h, slot, v);
}

static dk_index pop_min(vheap *h)
{
    dk_index top = h->items[0];
    h->pos[top] = -1;
    h->size--;
    if (h->size > 0) {
        dk_index v = h->items[h->size];
        double k = h->key[v];
        dk_index slot = 0;
        for (;;) {
            dk_index c = 2 * slot + 1;
            if (c >= h->size) break;
            if (c + 1 < h->size && h->key[h->items[c + 1]] < h->key[h->items[c]]) c++;
            if (!(h->key[h->items[c]] < k)) break;
            heap_place(h, slot, h->items[c]);
            slot = c;
        }
        heap_place(h, slot, v);
    }
    return top;
}

dk_status dk_geodesic_dijkstra(const dk_mesh *mesh, const dk_index *sources, dk_index n_sources,
                               double *distance, dk_error *err)
{
    dk_status st = check_sources(mesh, sources, n_sources, distance, "Dijkstra", err);
    if (st != DK_OK) return st;
    dk_index n = mesh->n_vertices;
    vheap h;
    h.size = 0;
    h.key = distance;
    h.items = malloc((size_t)(n > 0 ? n : 1) * sizeof *h.items);
    h.pos = malloc((size_t)(n > 0 ? n : 1) * sizeof *h.pos);
    if (!h.items || !h.pos) {
        free(h.items);
        free(h.pos);
        return dk_error_set(err, DK_ERR_OUT_OF_MEMORY, "Dijkstra: out of memory (%d vertices)",
                            (int)n);
    }
    for (dk_index v = 0; v < n; v++) {
        distance[v] = INFINITY;
        h.pos[v] = -1;
    }
    for (dk_index s = 0; s < n_sources; s++) {
        dk_index v = sources[s];
        if (distance[v] == 0.0) continue; /* repeated source */
        distance[v] = 0.0;
        heap_place(&h, h.size, v);
        h.size++;
    }
    /* all keys are 0: already a heap */
    const double *x = mesh->positions;
    while (h.size > 0) {
        dk_index v = pop_min(&h);
        double dv = distance[v];
        for (dk_index r = mesh->ring_start[v]; r < mesh->ring_start[v + 1]; r++) {
            dk_index j = mesh->ring_index[r];
            double dx = x[3 * j] - x[3 * v], dy = x[3 * j + 1] - x[3 * v + 1],
                   dz = x[3 * j + 2] - x[3 * v + 2];
            double nd = dv + sqrt(dx * dx + dy * dy + dz * dz);
            if (nd < distance[j]) {
                int fresh = distance[j] == INFINITY;
                distance[j] = nd;
                if (fresh) {
                    heap_place(&h, h.size, j);
                    h.size++;
                }
                if (h.pos[j] >= 0) sift_up(&h, h.pos[j]);
            }
        }
    }
    free(h.items);
    free(h.pos);
    return DK_OK;
}

dk_status dk_hop_distance(const dk_mesh *mesh, const dk_index *sources, dk_index n_sources,
                          dk_index *hops, dk_error *err)
{
    dk_status st = check_sources(mesh, sources, n_sources, hops, "hop distance", err);
    if (st != DK_OK) return st;
    dk_index n = mesh->n_vertices;
    dk_index *queue = malloc((size_t)(n > 0 ? n : 1) * sizeof *queue);
    if (!queue)
        return dk_error_set(err, DK_ERR_OUT_OF_MEMORY, "hop distance: out of memory (%d vertices)",
                            (int)n);
    for (dk_index v = 0; v < n; v++) hops[v] = -1;
    dk_index head = 0, tail = 0;
    for (dk_index s = 0; s < n_sources; s++)
        if (hops[sources[s]] < 0) {
            hops[sources[s]] = 0;
            queue[tail++] = sources[s];
        }
    while (head < tail) {
        dk_index v = queue[head++];
        for (dk_index r = mesh->ring_start[v]; r < mesh->ring_start[v + 1]; r++) {
            dk_index j = mesh->ring_index[r];
            if (hops[j] < 0) {
                hops[j] = hops[v] + 1;
                queue[tail++] = j;
            }
        }
    }
    free(queue);
    return DK_OK;
}
