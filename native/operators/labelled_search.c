/* DeformKit: the nearest source along the edges (dk_labelled_search, dk_operators.h).
 *
 * Multi-source Dijkstra along edges (unit weights for hops) that records, for each vertex,
 * the source it is nearest to. Ties in the distance (frequent with hops) go to the source
 * that is closer in straight line, then to the lower position in the source list. Keys are
 * (distance, straight-line distance, label) triples in a growable binary heap with lazy
 * deletion. Used by Falloff (the handle vertex a free vertex takes its displacement from)
 * and Shepard (a group's nearest vertex along the surface). */
#include <math.h>
#include <stdint.h>
#include <stdlib.h>

#include "dk_operators.h"
#include "dk_progress.h"

typedef struct heap_item {
    double d, e;
    dk_index label, v;
} heap_item;

typedef struct heap {
    heap_item *h;
    int64_t size, cap;
} heap;

static int item_less(const heap_item *a, const heap_item *b)
{
    if (a->d != b->d)
        return a->d < b->d;
    if (a->e != b->e)
        return a->e < b->e;
    return a->label < b->label;
}

static int heap_push(heap *hp, heap_item it)
{
    int64_t i;
    if (hp->size == hp->cap) {
        int64_t nc = hp->cap ? 2 * hp->cap : 64;
        heap_item *nh = realloc(hp->h, sizeof(heap_item) * (size_t)nc);
        if (!nh)
            return -1;
        hp->h = nh;
        hp->cap = nc;
    }
    i = hp->size++;
    while (i > 0) {
        int64_t p = (i - 1) / 2;
        if (!item_less(&it, &hp->h[p]))
            break;
        hp->h[i] = hp->h[p];
        i = p;
    }
    hp->h[i] = it;
    return 0;
}

static heap_item heap_pop(heap *hp)
{
    heap_item top = hp->h[0], last = hp->h[--hp->size];
    int64_t i = 0;
    for (;;) {
        int64_t c = 2 * i + 1;
        if (c >= hp->size)
            break;
        if (c + 1 < hp->size && item_less(&hp->h[c + 1], &hp->h[c]))
            c++;
        if (!item_less(&hp->h[c], &last))
            break;
        hp->h[i] = hp->h[c];
        i = c;
    }
    hp->h[i] = last;
    return top;
}

static double dist3(const double *a, const double *b)
{
    return sqrt((a[0] - b[0]) * (a[0] - b[0]) + (a[1] - b[1]) * (a[1] - b[1]) +
                (a[2] - b[2]) * (a[2] - b[2]));
}

dk_status dk_labelled_search(const dk_mesh *m, const dk_index *sources, dk_index n_sources,
                                 dk_index first_label, int unit_weights, double *dist,
                                 double *eu, dk_index *label, dk_progress *prog, dk_index g,
                                 dk_index n_groups, dk_error *err)
{
    const dk_index n = m->n_vertices;
    heap hp = {NULL, 0, 0};
    int64_t pops = 0;
    dk_status st = DK_OK;
    for (dk_index i = 0; i < n; i++) {
        dist[i] = eu[i] = INFINITY;
        label[i] = -1;
    }
    for (dk_index s = 0; s < n_sources; s++) {
        heap_item it = {0.0, 0.0, first_label + s, sources[s]};
        if (label[it.v] >= 0)
            continue;
        dist[it.v] = eu[it.v] = 0.0;
        label[it.v] = it.label;
        if (heap_push(&hp, it) < 0)
            goto oom;
    }
    while (hp.size > 0) {
        if ((st = dk_progress_tick(prog, (double)g + 0.5 * (double)++pops / (double)n,
                                   (double)n_groups, err)) != DK_OK) {
            free(hp.h);
            return st;
        }
        heap_item it = heap_pop(&hp);
        const double *ps = m->positions + 3 * sources[it.label - first_label];
        if (it.d != dist[it.v] || it.e != eu[it.v] || it.label != label[it.v])
            continue;
        for (dk_index k = m->ring_start[it.v]; k < m->ring_start[it.v + 1]; k++) {
            const dk_index j = m->ring_index[k];
            heap_item nx;
            nx.d = it.d + (unit_weights ? 1.0
                                        : dist3(m->positions + 3 * it.v, m->positions + 3 * j));
            nx.e = dist3(ps, m->positions + 3 * j);
            nx.label = it.label;
            nx.v = j;
            if (nx.d < dist[j] ||
                (nx.d == dist[j] && (nx.e < eu[j] || (nx.e == eu[j] && nx.label < label[j])))) {
                dist[j] = nx.d;
                eu[j] = nx.e;
                label[j] = nx.label;
                if (heap_push(&hp, nx) < 0)
                    goto oom;
            }
        }
    }
    free(hp.h);
    return DK_OK;
oom:
    free(hp.h);
    return dk_error_set(err, DK_ERR_OUT_OF_MEMORY, "labelled search: out of memory (its heap)");
}

