/* DeformKit: where points lie in a tetrahedral domain of bounded biharmonic weights
 * (bbw_locate in bbw_internal.h): a cell list of the tetrahedra (each in every cell its box
 * meets, cells of the domain's grid size), and per point the tetrahedron of its cell with
 * the largest smallest barycentric coordinate (>= 0: the point is inside it); failing that
 * the same over the 26 neighbouring cells, clamped; failing that the nearest vertex. */
#include <math.h>
#include <stdlib.h>
#include <string.h>

#include "bbw_internal.h"
#include "dk_operators.h"

/* The cells a tetrahedron's box meets. */
static void tet_cells(const cell_grid *g, const bbw_domain *d, dk_index t, dk_index c0[3],
                      dk_index c1[3])
{
    for (int a = 0; a < 3; a++) {
        double mn = INFINITY, mx = -INFINITY;
        for (int c = 0; c < 4; c++) {
            double x = d->positions[3 * (size_t)d->tets[4 * (size_t)t + c] + a];
            mn = fmin(mn, x);
            mx = fmax(mx, x);
        }
        double pmn[3] = {0, 0, 0}, pmx[3] = {0, 0, 0};
        pmn[a] = mn;
        pmx[a] = mx;
        c0[a] = cell_coord(g, pmn, a);
        c1[a] = cell_coord(g, pmx, a);
    }
}

dk_status bbw_locate(const bbw_domain *d, const double *points, dk_index n, dk_index *embed,
                     double *w, dk_error *err)
{
    static const char who[] = "bounded biharmonic weights";
    cell_grid g;
    memset(&g, 0, sizeof g);
    g.h = d->cell;
    double lo[3] = {INFINITY, INFINITY, INFINITY}, hi[3] = {-INFINITY, -INFINITY, -INFINITY};
    for (dk_index i = 0; i < d->n; i++)
        for (int k = 0; k < 3; k++) {
            lo[k] = fmin(lo[k], d->positions[3 * (size_t)i + k]);
            hi[k] = fmax(hi[k], d->positions[3 * (size_t)i + k]);
        }
    size_t n_cells = 1;
    for (int k = 0; k < 3; k++) {
        g.origin[k] = lo[k];
        g.dim[k] = (dk_index)floor((hi[k] - lo[k]) / g.h) + 1;
        n_cells *= (size_t)g.dim[k];
    }
    size_t n_items = 0;
    for (dk_index t = 0; t < d->n_elements; t++) {
        dk_index c0[3], c1[3];
        tet_cells(&g, d, t, c0, c1);
        n_items += (size_t)(c1[0] - c0[0] + 1) * (size_t)(c1[1] - c0[1] + 1) *
                   (size_t)(c1[2] - c0[2] + 1);
    }
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
    for (dk_index t = 0; t < d->n_elements; t++) {
        dk_index c0[3], c1[3];
        tet_cells(&g, d, t, c0, c1);
        for (dk_index z = c0[2]; z <= c1[2]; z++)
            for (dk_index y = c0[1]; y <= c1[1]; y++)
                for (dk_index x = c0[0]; x <= c1[0]; x++) {
                    size_t c = cell_index(&g, x, y, z);
                    item_tet[item] = t;
                    next[item] = g.head[c];
                    g.head[c] = item++;
                }
    }
    for (dk_index v = 0; v < n; v++) {
        dk_index *e = embed + 4 * (size_t)v;
        double *ew = w + 4 * (size_t)v;
        const double *p = points + 3 * (size_t)v;
        dk_index c[3], best = -1;
        double best_min = -INFINITY, best_l[4] = {0, 0, 0, 0};
        for (int a = 0; a < 3; a++) c[a] = cell_coord(&g, p, a);
        for (dk_index ring = 0; ring <= 1 && best_min < -1e-9; ring++)
            for (dk_index z = c[2] > ring ? c[2] - ring : 0; z <= c[2] + ring && z < g.dim[2]; z++)
                for (dk_index y = c[1] > ring ? c[1] - ring : 0; y <= c[1] + ring && y < g.dim[1]; y++)
                    for (dk_index x = c[0] > ring ? c[0] - ring : 0; x <= c[0] + ring && x < g.dim[0]; x++)
                        for (dk_index it = g.head[cell_index(&g, x, y, z)]; it >= 0; it = next[it]) {
                            const double *f = d->frames + 12 * (size_t)item_tet[it];
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
        if (best >= 0 && best_min > -0.5) {
            double sum = 0.0;
            for (int q = 0; q < 4; q++) sum += fmax(0.0, best_l[q]);
            for (int q = 0; q < 4; q++) {
                e[q] = d->tets[4 * (size_t)best + q];
                ew[q] = fmax(0.0, best_l[q]) / sum;
            }
            continue;
        }
        if (!tree) {
            st = dk_kdtree_create(d->positions, d->n, &tree, err);
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
