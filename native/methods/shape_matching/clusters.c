/* Shape matching's clusters (sm_internal.h). The paper divides the volume into overlapping
 * cubes and makes a cluster of the points in each; on a surface a cube can hold pieces of
 * two parts that only pass near each other (two fingers), which would then move as one, so
 * each cube's points are split into the pieces the mesh's edges connect (a point set, with no
 * edges, keeps the paper's cubes). A piece of fewer than 4 points has no well-defined fit and
 * is dropped; a vertex left in no cluster gets the cluster of the 8 vertices nearest to it
 * along the edges (or in space, for a point set), so that every vertex is matched.
 *
 * Each membership has a weight: in a cube, the trilinear hat of the cube (1 at its centre, 0
 * on its faces); elsewhere 1. A vertex's share of a cluster is its weight there over the sum
 * of its weights (the cubes' hats already sum to 1 where no piece was dropped). Equal shares,
 * the paper's m_i / n_i, make a vertex's goal jump where it crosses a cube's face (4 of its 8
 * cubes change at once): under a large drag the clusters' goals differ and the mesh tears
 * along the cubes' faces. With the hats the goals vary continuously. Memberships of weight
 * below HAT_MIN (a vertex on a cube's face) are left out. */
#include "sm_internal.h"

#include <math.h>
#include <stdint.h>
#include <stdlib.h>
#include <string.h>

#include "dk_operators.h"

enum { MIN_PIECE = 4, FALLBACK_SIZE = 8 };
static const double HAT_MIN = 1e-9;

void sm_clusters_free(sm_clusters *c)
{
    if (!c)
        return;
    free(c->start);
    free(c->member_vertex);
    free(c->member_mass);
    free(c->member_share);
    free(c->vm_start);
    free(c->vm_index);
    memset(c, 0, sizeof *c);
}

static dk_status oom(dk_error *err, const char *what)
{
    return dk_error_set(err, DK_ERR_OUT_OF_MEMORY, "ShapeMatching: out of memory (%s)", what);
}

/* A growing list of clusters (members appended cluster by cluster). */
typedef struct builder {
    dk_index n_clusters, cap_clusters;
    int64_t n_members, cap_members;
    dk_index *start, *members;
    double *weights; /* per member                                                           */
} builder;

static int reserve(builder *b, dk_index more_clusters, int64_t more_members)
{
    if (b->n_clusters + more_clusters + 1 > b->cap_clusters) {
        dk_index cap = 2 * (b->cap_clusters + more_clusters + 16);
        dk_index *p = realloc(b->start, (size_t)cap * sizeof *p);
        if (!p)
            return 0;
        b->start = p;
        b->cap_clusters = cap;
    }
    if (b->n_members + more_members > b->cap_members) {
        int64_t cap = 2 * (b->cap_members + more_members + 64);
        dk_index *p = realloc(b->members, (size_t)cap * sizeof *p);
        if (!p)
            return 0;
        b->members = p;
        double *w = realloc(b->weights, (size_t)cap * sizeof *w);
        if (!w)
            return 0;
        b->weights = w;
        b->cap_members = cap;
    }
    return 1;
}

/* Appends a cluster of `count` vertices with their weights (NULL: 1 each). */
static int add_cluster(builder *b, const dk_index *verts, const double *weights, dk_index count)
{
    if (b->n_members + count > INT32_MAX || !reserve(b, 1, count))
        return 0;
    if (b->n_clusters == 0)
        b->start[0] = 0;
    memcpy(b->members + b->n_members, verts, (size_t)count * sizeof *verts);
    for (dk_index k = 0; k < count; k++)
        b->weights[b->n_members + k] = weights ? weights[k] : 1.0;
    b->n_members += count;
    b->start[++b->n_clusters] = (dk_index)b->n_members;
    return 1;
}

/* (cube key, vertex) pairs, sorted by key then vertex. */
typedef struct pair {
    uint64_t key;
    dk_index v;
} pair;

static int pair_cmp(const void *a, const void *b)
{
    const pair *p = a, *q = b;
    if (p->key != q->key)
        return p->key < q->key ? -1 : 1;
    return (p->v > q->v) - (p->v < q->v);
}

static dk_index find(dk_index *parent, dk_index i)
{
    while (parent[i] != i) {
        parent[i] = parent[parent[i]];
        i = parent[i];
    }
    return i;
}

/* The automatic cubes: cells of edge cluster_size / 2, a cube of 2 x 2 x 2 cells at every
 * cell, so that each vertex lies in 8 cubes. In cell units u = (p - bbox_min) / h, cube
 * (X, Y, Z) spans [X - 1, X + 1) along x (and so on): its hat is the product over the axes
 * of 1 - |u - X|, and a point's 8 hats sum to 1. */
static dk_status cubes(const dk_mesh *m, double size, builder *b, dk_error *err)
{
    const dk_index n = m->n_vertices;
    double h = 0.5 * size, ext = 0.0;
    for (int d = 0; d < 3; d++)
        ext = fmax(ext, m->bbox_max[d] - m->bbox_min[d]);
    if (ext / h > (double)(1 << 20))
        h = ext / (double)(1 << 20); /* keys of 21 bits an axis */
    pair *pairs = malloc(8 * (size_t)n * sizeof *pairs + 1);
    dk_index *stamp = malloc(((size_t)n + 1) * sizeof *stamp);
    dk_index *local = malloc(((size_t)n + 1) * sizeof *local);
    dk_index *parent = malloc(((size_t)n + 1) * sizeof *parent);
    dk_index *piece = malloc(((size_t)n + 1) * sizeof *piece);
    dk_index *count = malloc(((size_t)n + 1) * sizeof *count);
    double *hat = malloc(((size_t)n + 1) * sizeof *hat);
    if (!pairs || !stamp || !local || !parent || !piece || !count || !hat) {
        free(pairs), free(stamp), free(local), free(parent), free(piece), free(count),
            free(hat);
        return oom(err, "cluster cubes");
    }
    for (dk_index v = 0; v < n; v++) {
        uint64_t c[3];
        for (int d = 0; d < 3; d++)
            c[d] = (uint64_t)floor((m->positions[3 * (size_t)v + d] - m->bbox_min[d]) / h) + 1;
        for (int k = 0; k < 8; k++) {
            const uint64_t x = c[0] - (k & 1), y = c[1] - ((k >> 1) & 1),
                           z = c[2] - ((k >> 2) & 1);
            pairs[8 * (size_t)v + k] = (pair){(x << 42) | (y << 21) | z, v};
        }
    }
    qsort(pairs, 8 * (size_t)n, sizeof *pairs, pair_cmp);
    for (dk_index v = 0; v < n; v++)
        stamp[v] = -1;
    dk_status st = DK_OK;
    const int split = m->n_edges > 0;
    size_t i = 0, total = 8 * (size_t)n;
    dk_index cube = 0;
    while (i < total && st == DK_OK) {
        size_t j = i;
        while (j < total && pairs[j].key == pairs[i].key)
            j++;
        const dk_index size_c = (dk_index)(j - i);
        for (dk_index a = 0; a < size_c; a++) {
            const dk_index v = pairs[i + (size_t)a].v;
            stamp[v] = cube;
            local[v] = a;
            parent[a] = a;
        }
        if (split)
            for (dk_index a = 0; a < size_c; a++) {
                const dk_index v = pairs[i + (size_t)a].v;
                for (dk_index r = m->ring_start[v]; r < m->ring_start[v + 1]; r++) {
                    const dk_index u = m->ring_index[r];
                    if (stamp[u] == cube) {
                        const dk_index ra = find(parent, a), rb = find(parent, local[u]);
                        if (ra != rb)
                            parent[ra > rb ? ra : rb] = ra > rb ? rb : ra;
                    }
                }
            }
        else
            for (dk_index a = 0; a < size_c; a++)
                parent[a] = 0;
        /* the pieces, each listed in vertex order, in the order of their least vertex */
        for (dk_index a = 0; a < size_c; a++)
            count[a] = 0;
        for (dk_index a = 0; a < size_c; a++)
            count[find(parent, a)]++;
        const uint64_t key = pairs[i].key, mask = (UINT64_C(1) << 21) - 1;
        const double centre[3] = {(double)(key >> 42), (double)((key >> 21) & mask),
                                  (double)(key & mask)};
        for (dk_index a = 0; a < size_c && st == DK_OK; a++) {
            if (find(parent, a) != a || count[a] < MIN_PIECE)
                continue;
            dk_index np = 0;
            for (dk_index q = a; q < size_c; q++) {
                if (find(parent, q) != a)
                    continue;
                const dk_index v = pairs[i + (size_t)q].v;
                double w = 1.0;
                for (int d = 0; d < 3; d++) {
                    const double u = (m->positions[3 * (size_t)v + d] - m->bbox_min[d]) / h;
                    w *= fmax(0.0, 1.0 - fabs(u - centre[d]));
                }
                if (w >= HAT_MIN) {
                    hat[np] = w;
                    piece[np++] = v;
                }
            }
            if (np >= MIN_PIECE && !add_cluster(b, piece, hat, np))
                st = oom(err, "clusters");
        }
        cube++;
        i = j;
    }
    free(pairs), free(stamp), free(local), free(parent), free(piece), free(count), free(hat);
    return st;
}

/* One cluster per connected part (a point set: one). */
static dk_status parts(const dk_mesh *m, builder *b, dk_error *err)
{
    const dk_index n = m->n_vertices;
    const dk_index nc = m->n_edges > 0 && m->component ? m->report.n_components : 1;
    dk_index *order = malloc(((size_t)n + 1) * sizeof *order);
    dk_index *at = calloc((size_t)nc + 1, sizeof *at);
    if (!order || !at) {
        free(order), free(at);
        return oom(err, "clusters");
    }
    for (dk_index v = 0; v < n; v++)
        at[(nc > 1 ? m->component[v] : 0) + 1]++;
    for (dk_index k = 0; k < nc; k++)
        at[k + 1] += at[k];
    dk_index *fill = malloc(((size_t)nc + 1) * sizeof *fill);
    if (!fill) {
        free(order), free(at);
        return oom(err, "clusters");
    }
    memcpy(fill, at, (size_t)nc * sizeof *fill);
    for (dk_index v = 0; v < n; v++)
        order[fill[nc > 1 ? m->component[v] : 0]++] = v;
    dk_status st = DK_OK;
    for (dk_index k = 0; k < nc && st == DK_OK; k++)
        if (!add_cluster(b, order + at[k], NULL, at[k + 1] - at[k]))
            st = oom(err, "clusters");
    free(order), free(at), free(fill);
    return st;
}

/* The clusters the caller gave, checked. */
static dk_status given(const dk_mesh *m, const dk_shape_matching_options *o, builder *b,
                       dk_error *err)
{
    if (!o->cluster_sizes || !o->cluster_vertices)
        return dk_error_set(err, DK_ERR_INVALID_ARGUMENT,
                            "ShapeMatching: %d clusters announced but their lists are NULL",
                            (int)o->n_clusters);
    int64_t at = 0;
    for (dk_index c = 0; c < o->n_clusters; c++) {
        const dk_index size = o->cluster_sizes[c];
        if (size <= 0)
            return dk_error_set(err, DK_ERR_INVALID_ARGUMENT,
                                "ShapeMatching: cluster %d is empty", (int)c);
        for (dk_index k = 0; k < size; k++) {
            const dk_index v = o->cluster_vertices[at + k];
            if (v < 0 || v >= m->n_vertices)
                return dk_error_set(err, DK_ERR_INVALID_ARGUMENT,
                                    "ShapeMatching: cluster %d lists vertex %d, outside [0, %d)",
                                    (int)c, (int)v, (int)m->n_vertices);
        }
        if (!add_cluster(b, o->cluster_vertices + at, NULL, size))
            return oom(err, "clusters");
        at += size;
    }
    return DK_OK;
}

/* For every vertex that must be covered and is in no cluster: the cluster of the nearest
 * FALLBACK_SIZE vertices (by edge hops, breadth first; a point set: in space), the vertex's
 * weight 1 and its neighbours' 1 / FALLBACK_SIZE, so that a neighbour already in its cubes
 * (hats summing to about 1) gives this small cluster about the share it had with equal
 * shares, not half of its goal. */
static dk_status cover(const dk_mesh *m, const unsigned char *kinematic, int must_all,
                       builder *b, dk_error *err)
{
    const dk_index n = m->n_vertices;
    unsigned char *in = calloc((size_t)n + 1, 1);
    if (!in)
        return oom(err, "coverage");
    for (int64_t k = 0; k < (b->n_clusters ? b->start[b->n_clusters] : 0); k++)
        in[b->members[k]] = 1;
    dk_status st = DK_OK;
    dk_index missing = 0, first = -1;
    for (dk_index v = 0; v < n; v++)
        if (!in[v] && !kinematic[v] && missing++ == 0)
            first = v;
    if (missing && must_all) {
        free(in);
        return dk_error_set(err, DK_ERR_INVALID_ARGUMENT,
                            "ShapeMatching: %d simulated vertices lie in no given cluster "
                            "(vertex %d first): add them to a cluster, or make them fixed",
                            (int)missing, (int)first);
    }
    if (!missing) {
        free(in);
        return DK_OK;
    }
    dk_index list[FALLBACK_SIZE];
    dk_kdtree *tree = NULL;
    dk_index *mark = NULL, *queue = NULL;
    if (m->n_edges == 0)
        st = dk_kdtree_create(m->positions, n, &tree, err);
    else {
        mark = malloc(((size_t)n + 1) * sizeof *mark);
        queue = malloc(((size_t)n + 1) * sizeof *queue);
        if (!mark || !queue)
            st = oom(err, "coverage");
        else
            for (dk_index v = 0; v < n; v++)
                mark[v] = -1;
    }
    for (dk_index v = 0; v < n && st == DK_OK; v++) {
        if (in[v] || kinematic[v])
            continue;
        dk_index got = 0;
        if (tree) {
            const dk_index k = n < FALLBACK_SIZE ? n : FALLBACK_SIZE;
            double dist[FALLBACK_SIZE];
            st = dk_kdtree_knn(tree, m->positions + 3 * (size_t)v, 1, k, list, dist, err);
            got = k;
        } else {
            dk_index head = 0, tail = 0;
            queue[tail++] = v;
            mark[v] = v;
            while (head < tail && got < FALLBACK_SIZE) {
                const dk_index u = queue[head++];
                list[got++] = u;
                for (dk_index r = m->ring_start[u]; r < m->ring_start[u + 1]; r++) {
                    const dk_index w = m->ring_index[r];
                    if (mark[w] != v) {
                        mark[w] = v;
                        queue[tail++] = w;
                    }
                }
            }
        }
        if (st != DK_OK)
            break;
        double weights[FALLBACK_SIZE];
        for (dk_index k = 0; k < got; k++)
            weights[k] = list[k] == v ? 1.0 : 1.0 / FALLBACK_SIZE;
        if (!add_cluster(b, list, weights, got))
            st = oom(err, "clusters");
    }
    dk_kdtree_free(tree);
    free(mark), free(queue), free(in);
    return st;
}

/* The automatic cubes' edge. */
static double cube_edge(const dk_mesh *mesh, const dk_shape_matching_options *o)
{
    return o->cluster_size > 0.0 ? o->cluster_size : 0.25 * mesh->bbox_diagonal;
}

double sm_attach_cap(const dk_mesh *mesh, const dk_shape_matching_options *o)
{
    const int cubes = o->n_clusters == 0 && o->clusters != DK_CLUSTERS_PARTS;
    return cubes && cube_edge(mesh, o) > 0.0 ? 0.5 * cube_edge(mesh, o) : INFINITY;
}

dk_status sm_clusters_build(const dk_mesh *mesh, const dk_shape_matching_options *o,
                            const double *masses, const unsigned char *kinematic,
                            sm_clusters *out, dk_error *err)
{
    memset(out, 0, sizeof *out);
    builder b = {0};
    dk_status st;
    if (o->n_clusters > 0)
        st = given(mesh, o, &b, err);
    else if (o->clusters == DK_CLUSTERS_PARTS)
        st = parts(mesh, &b, err);
    else {
        const double size = cube_edge(mesh, o);
        st = size > 0.0 ? cubes(mesh, size, &b, err) : parts(mesh, &b, err); /* one point */
    }
    if (st == DK_OK)
        st = cover(mesh, kinematic, o->n_clusters > 0, &b, err);
    if (st == DK_OK && !reserve(&b, 1, 1))
        st = oom(err, "clusters");
    if (st != DK_OK) {
        free(b.start), free(b.members), free(b.weights);
        return st;
    }
    if (b.n_clusters == 0)
        b.start[0] = 0;
    const dk_index n = mesh->n_vertices, nm = b.start[b.n_clusters];
    out->n_clusters = b.n_clusters;
    out->start = b.start;
    out->member_vertex = b.members;
    out->member_share = b.weights; /* the weights, made shares below */
    out->member_mass = malloc(((size_t)nm + 1) * sizeof *out->member_mass);
    out->vm_start = calloc((size_t)n + 2, sizeof *out->vm_start);
    out->vm_index = malloc(((size_t)nm + 1) * sizeof *out->vm_index);
    if (!out->member_share || !out->member_mass || !out->vm_start || !out->vm_index) {
        sm_clusters_free(out);
        return oom(err, "cluster memberships");
    }
    for (dk_index k = 0; k < nm; k++)
        out->vm_start[out->member_vertex[k] + 1]++;
    for (dk_index v = 0; v < n; v++)
        out->vm_start[v + 1] += out->vm_start[v];
    dk_index *fill = malloc(((size_t)n + 1) * sizeof *fill);
    if (!fill) {
        sm_clusters_free(out);
        return oom(err, "cluster memberships");
    }
    memcpy(fill, out->vm_start, (size_t)n * sizeof *fill);
    for (dk_index k = 0; k < nm; k++)
        out->vm_index[fill[out->member_vertex[k]]++] = k;
    free(fill);
    for (dk_index v = 0; v < n; v++) {
        double sum = 0.0;
        for (dk_index t = out->vm_start[v]; t < out->vm_start[v + 1]; t++)
            sum += out->member_share[out->vm_index[t]];
        const double mv = masses ? masses[v] : 1.0;
        for (dk_index t = out->vm_start[v]; t < out->vm_start[v + 1]; t++) {
            const dk_index k = out->vm_index[t];
            out->member_share[k] /= sum;
            out->member_mass[k] = mv * out->member_share[k];
        }
    }
    return DK_OK;
}
