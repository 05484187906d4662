/* DeformKit: where points lie in a tetrahedral mesh (dk_locate_in_tetrahedra in
 * dk_operators.h): a cell list of the tetrahedra (each in every cell its box meets), and per
 * point the tetrahedron of its cell with the largest smallest barycentric coordinate (>= 0:
 * the point is inside it); failing that the same over the 26 neighbouring cells (and, when
 * extrapolating, one more ring); what is found is clamped or extrapolated by the mode, and
 * failing everything the nearest mesh point takes the whole weight. */
#include <math.h>
#include <stdint.h>
#include <stdlib.h>
#include <string.h>

#include "dk_operators.h"

double dk_tetrahedron_frame(const double *x0, const double *x1, const double *x2,
                            const double *x3, double grad[12])
{
    double e[9], c[9];
    for (int k = 0; k < 3; k++) {
        e[k] = x1[k] - x0[k];
        e[3 + k] = x2[k] - x0[k];
        e[6 + k] = x3[k] - x0[k];
    }
    double det = dk_mat3_cofactor(e, c);
    if (det == 0.0) return 0.0;
    for (int r = 0; r < 3; r++)
        for (int k = 0; k < 3; k++) grad[3 * (r + 1) + k] = c[3 * r + k] / det;
    for (int k = 0; k < 3; k++) grad[k] = -(grad[3 + k] + grad[6 + k] + grad[9 + k]);
    return det;
}

/* A dense grid of cells of size h with a linked list of tetrahedra per cell. */
typedef struct grid {
    double origin[3], h;
    dk_index dim[3];
    dk_index *head; /* cells, -1 empty */
} grid;

static dk_index coord(const grid *g, double x, int k)
{
    const double c = floor((x - g->origin[k]) / g->h);
    if (!(c >= 0.0)) return 0;
    if (c >= (double)g->dim[k]) return g->dim[k] - 1;
    return (dk_index)c;
}

static size_t cell_of(const grid *g, dk_index x, dk_index y, dk_index z)
{
    return ((size_t)z * (size_t)g->dim[1] + (size_t)y) * (size_t)g->dim[0] + (size_t)x;
}

/* Whether cell (x, y, z) is at Chebyshev distance `ring` from c (not inside it). */
static int shell(const dk_index c[3], dk_index x, dk_index y, dk_index z, dk_index ring)
{
    const dk_index dx = x > c[0] ? x - c[0] : c[0] - x, dy = y > c[1] ? y - c[1] : c[1] - y;
    const dk_index dz = z > c[2] ? z - c[2] : c[2] - z;
    return dx == ring || dy == ring || dz == ring;
}

/* The cells a tetrahedron's box meets. */
static void tet_cells(const grid *g, const double *points, const dk_index *tet, dk_index c0[3],
                      dk_index c1[3])
{
    for (int a = 0; a < 3; a++) {
        double mn = INFINITY, mx = -INFINITY;
        for (int c = 0; c < 4; c++) {
            const double x = points[3 * (size_t)tet[c] + a];
            mn = fmin(mn, x);
            mx = fmax(mx, x);
        }
        c0[a] = coord(g, mn, a);
        c1[a] = coord(g, mx, a);
    }
}

/* The grid's cell size when none is given: the tetrahedra's mean box size (its longest
 * side), so that a cell near the surface, where a scan's tetrahedra are small, holds a few
 * of them, and a big one inside spans a few cells; at least 1/256 of the box's longest side
 * (at most about 2^24 cells). */
static double auto_cell(const double *points, const dk_index *tets, dk_index n_tets,
                        const double *lo, const double *hi)
{
    double sum = 0.0;
    for (dk_index t = 0; t < n_tets; t++) {
        double side = 0.0;
        for (int a = 0; a < 3; a++) {
            double mn = INFINITY, mx = -INFINITY;
            for (int c = 0; c < 4; c++) {
                const double x = points[3 * (size_t)tets[4 * (size_t)t + c] + a];
                mn = fmin(mn, x);
                mx = fmax(mx, x);
            }
            side = fmax(side, mx - mn);
        }
        sum += side;
    }
    double ext = 0.0;
    for (int k = 0; k < 3; k++)
        ext = fmax(ext, hi[k] - lo[k]);
    const double h = sum / (double)n_tets;
    return h > ext / 256.0 ? h : ext > 0.0 ? ext / 256.0 : 1.0;
}

dk_status dk_locate_in_tetrahedra(const double *points, dk_index n_points,
                                  const dk_index *tets, const double *frames, dk_index n_tets,
                                  double cell, dk_locate_mode mode, const double *queries,
                                  dk_index n_queries, dk_index *corners, double *weights,
                                  dk_error *err)
{
    static const char who[] = "locating points in tetrahedra";
    grid g;
    memset(&g, 0, sizeof g);
    double lo[3] = {INFINITY, INFINITY, INFINITY}, hi[3] = {-INFINITY, -INFINITY, -INFINITY};
    for (dk_index i = 0; i < n_points; i++)
        for (int k = 0; k < 3; k++) {
            lo[k] = fmin(lo[k], points[3 * (size_t)i + k]);
            hi[k] = fmax(hi[k], points[3 * (size_t)i + k]);
        }
    if (n_points <= 0 || n_tets <= 0)
        return dk_error_set(err, DK_ERR_INVALID_ARGUMENT, "%s: no point or no tetrahedron",
                            who);
    if (!points || !tets || !frames || n_queries < 0 || (n_queries > 0 && (!queries || !corners ||
                                                                           !weights)))
        return dk_error_set(err, DK_ERR_INVALID_ARGUMENT,
                            "%s: an array is NULL or n_queries is negative", who);
    for (size_t k = 0; k < 4 * (size_t)n_tets; k++)
        if (tets[k] < 0 || tets[k] >= n_points)
            return dk_error_set(err, DK_ERR_INVALID_ARGUMENT,
                                "%s: tetrahedron %zu has corner %ld, out of range [0, %ld)",
                                who, k / 4, (long)tets[k], (long)n_points);
    for (int k = 0; k < 3; k++)
        if (!isfinite(lo[k]) || !isfinite(hi[k]))
            return dk_error_set(err, DK_ERR_INVALID_ARGUMENT, "%s: a point is not finite", who);
    g.h = cell > 0.0 ? cell : auto_cell(points, tets, n_tets, lo, hi);
    double cells = 1.0;
    for (int k = 0; k < 3; k++)
        cells *= floor((hi[k] - lo[k]) / g.h) + 1.0;
    if (!(cells <= 0x1p28)) /* a cell size given too small for the points' box */
        return dk_error_set(err, DK_ERR_INVALID_ARGUMENT,
                            "%s: cells of %g make %.3g cells over the points' box (at most "
                            "2^28)", who, g.h, cells);
    size_t n_cells = 1;
    for (int k = 0; k < 3; k++) {
        g.origin[k] = lo[k];
        g.dim[k] = (dk_index)floor((hi[k] - lo[k]) / g.h) + 1;
        n_cells *= (size_t)g.dim[k];
    }
    size_t n_items = 0;
    for (dk_index t = 0; t < n_tets; t++) {
        dk_index c0[3], c1[3];
        tet_cells(&g, points, tets + 4 * (size_t)t, c0, c1);
        n_items += (size_t)(c1[0] - c0[0] + 1) * (size_t)(c1[1] - c0[1] + 1) *
                   (size_t)(c1[2] - c0[2] + 1);
    }
    if (n_items >= (size_t)INT32_MAX) /* dk_index */
        return dk_error_set(err, DK_ERR_INVALID_ARGUMENT,
                            "%s: the tetrahedra meet %zu cells, too many for the cell size %g",
                            who, n_items, g.h);
    g.head = malloc(n_cells * sizeof *g.head);
    dk_index *next = malloc((n_items + 1) * sizeof *next);
    dk_index *item_tet = malloc((n_items + 1) * sizeof *item_tet);
    dk_kdtree *tree = NULL;
    dk_status st = DK_OK;
    if (!g.head || !next || !item_tet) {
        st = dk_error_set(err, DK_ERR_OUT_OF_MEMORY, "%s: out of memory", who);
        goto done;
    }
    for (size_t c = 0; c < n_cells; c++) g.head[c] = -1;
    dk_index item = 0;
    for (dk_index t = 0; t < n_tets; t++) {
        dk_index c0[3], c1[3];
        tet_cells(&g, points, tets + 4 * (size_t)t, c0, c1);
        for (dk_index z = c0[2]; z <= c1[2]; z++)
            for (dk_index y = c0[1]; y <= c1[1]; y++)
                for (dk_index x = c0[0]; x <= c1[0]; x++) {
                    const size_t c = cell_of(&g, x, y, z);
                    item_tet[item] = t;
                    next[item] = g.head[c];
                    g.head[c] = item++;
                }
    }
    const int extrapolate = mode == DK_LOCATE_EXTRAPOLATE;
    const dk_index max_ring = extrapolate ? 2 : 1;
    for (dk_index v = 0; v < n_queries; v++) {
        dk_index *e = corners + 4 * (size_t)v;
        double *ew = weights + 4 * (size_t)v;
        const double *p = queries + 3 * (size_t)v;
        dk_index c[3], best = -1;
        double best_min = -INFINITY, best_l[4] = {0, 0, 0, 0};
        for (int a = 0; a < 3; a++) c[a] = coord(&g, p[a], a);
        /* each ring looks at the cells at that Chebyshev distance (ring 0 its own): the
         * next one while the point is outside the best tetrahedron so far (the second, when
         * extrapolating, only while it is farther than half that tetrahedron away) */
        for (dk_index ring = 0;
             ring <= max_ring && best_min < (ring < 2 ? -1e-9 : -0.5); ring++)
            for (dk_index z = c[2] > ring ? c[2] - ring : 0; z <= c[2] + ring && z < g.dim[2]; z++)
                for (dk_index y = c[1] > ring ? c[1] - ring : 0; y <= c[1] + ring && y < g.dim[1]; y++)
                    for (dk_index x = c[0] > ring ? c[0] - ring : 0; x <= c[0] + ring && x < g.dim[0]; x++)
                        for (dk_index it = g.head[cell_of(&g, x, y, z)];
                             it >= 0 && (ring < 2 || shell(c, x, y, z, ring)); it = next[it]) {
                            const double *f = frames + 12 * (size_t)item_tet[it];
                            double r[3] = {p[0] - f[0], p[1] - f[1], p[2] - f[2]}, l[4];
                            l[0] = 1.0;
                            for (int q = 1; q < 4; q++) {
                                l[q] = f[3 * q] * r[0] + f[3 * q + 1] * r[1] + f[3 * q + 2] * r[2];
                                l[0] -= l[q];
                            }
                            double mn = fmin(fmin(l[0], l[1]), fmin(l[2], l[3]));
                            if (mn > best_min) {
                                best_min = mn;
                                best = item_tet[it];
                                memcpy(best_l, l, sizeof l);
                            }
                        }
        if (best >= 0 && (extrapolate || best_min > -0.5)) {
            double sum = 0.0;
            for (int q = 0; q < 4; q++) sum += extrapolate ? best_l[q] : fmax(0.0, best_l[q]);
            for (int q = 0; q < 4; q++) {
                e[q] = tets[4 * (size_t)best + q];
                ew[q] = (extrapolate ? best_l[q] : fmax(0.0, best_l[q])) / sum;
            }
            continue;
        }
        if (!tree) {
            st = dk_kdtree_create(points, n_points, &tree, err);
            if (st != DK_OK) goto done;
        }
        st = dk_kdtree_knn(tree, p, 1, 1, &e[0], NULL, err);
        if (st != DK_OK) goto done;
        e[1] = e[2] = e[3] = -1;
        ew[0] = 1.0;
        ew[1] = ew[2] = ew[3] = 0.0;
    }
done:
    dk_kdtree_free(tree);
    free(g.head);
    free(next);
    free(item_tet);
    return st;
}
