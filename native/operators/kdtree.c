/* DeformKit: static k-d tree and exact k-nearest-neighbour queries (dk_kdtree_*).
 *
 * The tree is implicit: points are permuted so that every range [lo, hi) of the build
 * recursion stores its median (on the axis of largest extent) at mid = (lo + hi) / 2, the
 * smaller-or-equal coordinates in [lo, mid) and the greater-or-equal ones in (mid, hi).
 * The split axis of each node is kept per position. Points are stored in tree order for
 * locality, with their original indices.
 *
 * A query keeps its k best candidates in a bounded max-heap ordered by (squared distance,
 * index), so ties are broken by the smaller index exactly like a sort of all points would.
 * A side of a split is visited when its cell's lower bound (the squared distance to the
 * cell's box, accumulated from the splitting planes down from the points' bounding box) is
 * <= the current k-th best, so equal distances with smaller indices are never pruned. Queries only read the tree; each call to dk_kdtree_knn allocates its own heap.
 */
#include <math.h>
#include <stdlib.h>
#include <string.h>

#include "dk_operators.h"

struct dk_kdtree {
    dk_index n;
    double *pts;          /* n x 3 in tree order        */
    dk_index *index;      /* original index per slot    */
    unsigned char *axis;  /* split axis per slot        */
};

/* --------------------------------------------------------------------------- build ---- */

static void swap_slots(double *pts, dk_index *idx, dk_index a, dk_index b)
{
    for (int d = 0; d < 3; d++) {
        double t = pts[3 * a + d];
        pts[3 * a + d] = pts[3 * b + d];
        pts[3 * b + d] = t;
    }
    dk_index t = idx[a];
    idx[a] = idx[b];
    idx[b] = t;
}

/* Quickselect: puts the element of rank k (in [lo, hi)) at k on axis d, with <= before it
 * and >= after it. Median-of-three pivots; iterative. */
static void select_kth(double *pts, dk_index *idx, dk_index lo, dk_index hi, dk_index k, int d)
{
    hi--; /* inclusive */
    while (hi > lo) {
        dk_index mid = lo + (hi - lo) / 2;
        /* median of three into position hi as pivot */
        if (pts[3 * mid + d] < pts[3 * lo + d]) swap_slots(pts, idx, mid, lo);
        if (pts[3 * hi + d] < pts[3 * lo + d]) swap_slots(pts, idx, hi, lo);
        if (pts[3 * mid + d] < pts[3 * hi + d]) swap_slots(pts, idx, mid, hi);
        double pivot = pts[3 * hi + d];
        /* Hoare-style partition that splits runs of equal keys evenly. */
        dk_index i = lo - 1, j = hi;
        for (;;) {
            do i++; while (pts[3 * i + d] < pivot);
            do j--; while (j > lo && pts[3 * j + d] > pivot);
            if (i >= j) break;
            swap_slots(pts, idx, i, j);
        }
        swap_slots(pts, idx, i, hi); /* pivot to its final place i */
        if (i == k) return;
        if (k < i) hi = i - 1;
        else lo = i + 1;
    }
}

static void build(dk_kdtree *t, dk_index lo, dk_index hi)
{
    while (hi - lo > 1) {
        double mn[3] = {INFINITY, INFINITY, INFINITY}, mx[3] = {-INFINITY, -INFINITY, -INFINITY};
        for (dk_index i = lo; i < hi; i++)
            for (int d = 0; d < 3; d++) {
                double v = t->pts[3 * i + d];
                if (v < mn[d]) mn[d] = v;
                if (v > mx[d]) mx[d] = v;
            }
        int axis = 0;
        for (int d = 1; d < 3; d++)
            if (mx[d] - mn[d] > mx[axis] - mn[axis]) axis = d;
        dk_index mid = lo + (hi - lo) / 2;
        select_kth(t->pts, t->index, lo, hi, mid, axis);
        t->axis[mid] = (unsigned char)axis;
        /* recurse on the smaller side, loop on the larger (bounded stack depth) */
        if (mid - lo < hi - mid - 1) {
            build(t, lo, mid);
            lo = mid + 1;
        } else {
            build(t, mid + 1, hi);
            hi = mid;
        }
    }
    if (hi - lo == 1) t->axis[lo] = 0;
}

dk_status dk_kdtree_create(const double *points, dk_index n, dk_kdtree **out, dk_error *err)
{
    if (!out) return dk_error_set(err, DK_ERR_INVALID_ARGUMENT, "kdtree: out is NULL");
    *out = NULL;
    if (n < 1)
        return dk_error_set(err, DK_ERR_INVALID_ARGUMENT, "kdtree: needs at least one point, got %d",
                            (int)n);
    if (!points) return dk_error_set(err, DK_ERR_INVALID_ARGUMENT, "kdtree: points is NULL");
    for (dk_index i = 0; i < n; i++)
        for (int d = 0; d < 3; d++)
            if (!isfinite(points[3 * i + d]))
                return dk_error_set(err, DK_ERR_NONFINITE,
                                    "kdtree: point %d coordinate %d is not finite", (int)i, d);
    dk_kdtree *t = calloc(1, sizeof *t);
    if (!t) return dk_error_set(err, DK_ERR_OUT_OF_MEMORY, "kdtree: out of memory");
    t->n = n;
    t->pts = malloc((size_t)n * 3 * sizeof *t->pts);
    t->index = malloc((size_t)n * sizeof *t->index);
    t->axis = malloc((size_t)n);
    if (!t->pts || !t->index || !t->axis) {
        dk_kdtree_free(t);
        return dk_error_set(err, DK_ERR_OUT_OF_MEMORY, "kdtree: out of memory for %d points",
                            (int)n);
    }
    memcpy(t->pts, points, (size_t)n * 3 * sizeof *t->pts);
    for (dk_index i = 0; i < n; i++) t->index[i] = i;
    build(t, 0, n);
    *out = t;
    return DK_OK;
}

void dk_kdtree_free(dk_kdtree *tree)
{
    if (!tree) return;
    free(tree->pts);
    free(tree->index);
    free(tree->axis);
    free(tree);
}

/* --------------------------------------------------------------------------- query ---- */

typedef struct knn_heap {
    dk_index k, size;
    double *d2;
    dk_index *id;
} knn_heap;

/* (da, ia) ranks after (db, ib)? */
static inline int worse(double da, dk_index ia, double db, dk_index ib)
{
    return da > db || (da == db && ia > ib);
}

static void heap_offer(knn_heap *h, double d2, dk_index id)
{
    dk_index i;
    if (h->size < h->k) {
        i = h->size++;
        while (i > 0) { /* sift up */
            dk_index p = (i - 1) / 2;
            if (!worse(d2, id, h->d2[p], h->id[p])) break;
            h->d2[i] = h->d2[p];
            h->id[i] = h->id[p];
            i = p;
        }
    } else {
        if (!worse(h->d2[0], h->id[0], d2, id)) return; /* not better than the worst */
        i = 0;
        for (;;) { /* sift down from the root */
            dk_index c = 2 * i + 1;
            if (c >= h->size) break;
            if (c + 1 < h->size && worse(h->d2[c + 1], h->id[c + 1], h->d2[c], h->id[c])) c++;
            if (!worse(h->d2[c], h->id[c], d2, id)) break;
            h->d2[i] = h->d2[c];
            h->id[i] = h->id[c];
            i = c;
        }
    }
    h->d2[i] = d2;
    h->id[i] = id;
}

/* The lower bound of the squared distance from the query to a cell, from the query's
 * offsets to the cell along each axis (0 where the query is within the cell's extent).
 * Evaluated in the order the point distances are, so that, rounding being monotone, a
 * point of the cell never computes closer than its cell's bound: the pruning stays exact. */
static double cell_bound(const double *off)
{
    return off[0] * off[0] + off[1] * off[1] + off[2] * off[2];
}

/* Descends [lo, hi) whose cell is `off` away from q (per axis). A side is skipped when its
 * cell's bound exceeds the current k-th best. The bound counts every axis (the offsets
 * accumulate down the tree, as in Arya and Mount's incremental distance): with the plane
 * distance alone, a query far from all points (most of a mesh, for a small handle set)
 * visited nearly the whole tree -- 82% of Falloff's bind at 173k vertices. */
static void search(const dk_kdtree *t, const double *q, dk_index lo, dk_index hi,
                   const double *cell_off, knn_heap *h)
{
    double off[3] = {cell_off[0], cell_off[1], cell_off[2]};
    while (hi > lo) {
        if (h->size == h->k && cell_bound(off) > h->d2[0]) return;
        dk_index mid = lo + (hi - lo) / 2;
        const double *p = t->pts + 3 * mid;
        double dx = q[0] - p[0], dy = q[1] - p[1], dz = q[2] - p[2];
        heap_offer(h, dx * dx + dy * dy + dz * dz, t->index[mid]);
        if (hi - lo == 1) return;
        int ax = t->axis[mid];
        double diff = q[ax] - p[ax];
        dk_index nlo, nhi, flo, fhi;
        if (diff < 0) nlo = lo, nhi = mid, flo = mid + 1, fhi = hi;
        else nlo = mid + 1, nhi = hi, flo = lo, fhi = mid;
        search(t, q, nlo, nhi, off, h);
        /* the far side lies beyond the splitting plane: |diff| away along ax, at least */
        if (fabs(diff) > off[ax]) off[ax] = fabs(diff);
        lo = flo, hi = fhi; /* tail: the far side, its bound tested at the loop's top */
    }
}

dk_status dk_kdtree_knn(const dk_kdtree *tree, const double *queries, dk_index n_queries,
                        dk_index k, dk_index *indices, double *sq_distances, dk_error *err)
{
    if (!tree) return dk_error_set(err, DK_ERR_INVALID_ARGUMENT, "kdtree knn: tree is NULL");
    if (n_queries < 0)
        return dk_error_set(err, DK_ERR_INVALID_ARGUMENT, "kdtree knn: n_queries is %d",
                            (int)n_queries);
    if (n_queries > 0 && !queries)
        return dk_error_set(err, DK_ERR_INVALID_ARGUMENT, "kdtree knn: queries is NULL");
    if (k < 1 || k > tree->n)
        return dk_error_set(err, DK_ERR_INVALID_ARGUMENT,
                            "kdtree knn: k = %d is outside [1, %d] (number of tree points)",
                            (int)k, (int)tree->n);
    for (dk_index i = 0; i < n_queries; i++)
        for (int d = 0; d < 3; d++)
            if (!isfinite(queries[3 * i + d]))
                return dk_error_set(err, DK_ERR_NONFINITE,
                                    "kdtree knn: query %d coordinate %d is not finite", (int)i, d);
    knn_heap h;
    h.k = k;
    h.d2 = malloc((size_t)k * sizeof *h.d2);
    h.id = malloc((size_t)k * sizeof *h.id);
    if (!h.d2 || !h.id) {
        free(h.d2);
        free(h.id);
        return dk_error_set(err, DK_ERR_OUT_OF_MEMORY, "kdtree knn: out of memory for k = %d",
                            (int)k);
    }
    /* the root cell: the points' bounding box */
    double box_lo[3] = {INFINITY, INFINITY, INFINITY}, box_hi[3] = {-INFINITY, -INFINITY, -INFINITY};
    for (dk_index i = 0; i < tree->n; i++)
        for (int d = 0; d < 3; d++) {
            if (tree->pts[3 * i + d] < box_lo[d]) box_lo[d] = tree->pts[3 * i + d];
            if (tree->pts[3 * i + d] > box_hi[d]) box_hi[d] = tree->pts[3 * i + d];
        }
    for (dk_index qi = 0; qi < n_queries; qi++) {
        const double *q = queries + 3 * qi;
        double off[3];
        for (int d = 0; d < 3; d++)
            off[d] = q[d] < box_lo[d] ? box_lo[d] - q[d] : q[d] > box_hi[d] ? q[d] - box_hi[d] : 0.0;
        h.size = 0;
        search(tree, q, 0, tree->n, off, &h);
        /* pop the heap from the worst: fills the outputs back to front */
        for (dk_index s = k - 1; s >= 0; s--) {
            double d2 = h.d2[0];
            dk_index id = h.id[0];
            if (indices) indices[(int64_t)qi * k + s] = id;
            if (sq_distances) sq_distances[(int64_t)qi * k + s] = d2;
            /* remove the root: move the last element down */
            h.size--;
            double ld = h.d2[h.size];
            dk_index li = h.id[h.size];
            dk_index i = 0;
            for (;;) {
                dk_index c = 2 * i + 1;
                if (c >= h.size) break;
                if (c + 1 < h.size && worse(h.d2[c + 1], h.id[c + 1], h.d2[c], h.id[c])) c++;
                if (!worse(h.d2[c], h.id[c], ld, li)) break;
                h.d2[i] = h.d2[c];
                h.id[i] = h.id[c];
                i = c;
            }
            if (h.size > 0) {
                h.d2[i] = ld;
                h.id[i] = li;
            }
        }
    }
    free(h.d2);
    free(h.id);
    return DK_OK;
}
