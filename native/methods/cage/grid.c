/* DeformKit cage FFD: coordinates on a grid, interpolated (dk_cage.h, evaluation GRID).
 *
 * The mesh's bounding box is cut into cubic cells, `resolution` along its longest side; the
 * coordinates are computed at the corners of the cells that hold a vertex (the grid's
 * nodes), and each vertex takes the trilinear blend of its cell's eight corners' rows. Since
 * trilinear interpolation reproduces affine functions, and the nodes' coordinates reproduce
 * the node positions, the blended coordinates keep linear precision (and a partition of
 * unity) exactly; what they lose is the exact value between nodes (an error of order h^2
 * times the coordinates' curvature, small inside the cage) and smoothness across cells (C0).
 * A solve moves the nodes (one product over the nodes) and blends their motion per vertex:
 * the coordinates' memory and the product scale with the nodes, not the vertices. */
#include "cage_grid.h"

#include "dk_parallel.h"

#include <math.h>
#include <stdint.h>
#include <stdlib.h>
#include <string.h>

void dk_cage_grid_free(dk_cage_grid *g)
{
    free(g->corner);
    free(g->w);
    free(g->node_pos);
    memset(g, 0, sizeof *g);
}

dk_status dk_cage_grid_plan(const double *pos, dk_index n, int resolution, dk_cage_grid *g,
                            dk_error *err)
{
    memset(g, 0, sizeof *g);
    if (n <= 0)
        return dk_error_set(err, DK_ERR_INVALID_ARGUMENT, "Cage grid: no vertices");
    double lo[3], hi[3];
    for (int d = 0; d < 3; d++)
        lo[d] = hi[d] = pos[d];
    for (dk_index v = 1; v < n; v++)
        for (int d = 0; d < 3; d++) {
            const double x = pos[3 * (size_t)v + d];
            lo[d] = x < lo[d] ? x : lo[d];
            hi[d] = x > hi[d] ? x : hi[d];
        }
    double side = 0.0;
    for (int d = 0; d < 3; d++)
        side = hi[d] - lo[d] > side ? hi[d] - lo[d] : side;
    if (!(side > 0.0)) /* one point: a cell around it */
        side = fabs(lo[0]) + fabs(lo[1]) + fabs(lo[2]) + 1.0;
    const double h = side / resolution;
    int64_t dims[3];
    for (int d = 0; d < 3; d++) {
        dims[d] = (int64_t)ceil((hi[d] - lo[d]) / h);
        dims[d] = dims[d] < 1 ? 1 : dims[d] > resolution ? resolution : dims[d];
    }
    const int64_t nx = dims[0] + 1, ny = dims[1] + 1, nz = dims[2] + 1;
    const size_t n_all = (size_t)(nx * ny * nz);
    int32_t *index = malloc(n_all * sizeof *index);
    g->corner = malloc(8 * (size_t)n * sizeof *g->corner);
    g->w = malloc(8 * (size_t)n * sizeof *g->w);
    if (!index || !g->corner || !g->w) {
        free(index);
        dk_cage_grid_free(g);
        return dk_error_set(err, DK_ERR_OUT_OF_MEMORY, "Cage: out of memory (the grid)");
    }
    for (size_t k = 0; k < n_all; k++)
        index[k] = -1;
    /* each vertex's cell and its trilinear weights; the cell's corners marked */
    for (dk_index v = 0; v < n; v++) {
        const double *x = pos + 3 * (size_t)v;
        int64_t c[3];
        double t[3];
        for (int d = 0; d < 3; d++) {
            const double s = (x[d] - lo[d]) / h;
            c[d] = (int64_t)floor(s);
            c[d] = c[d] < 0 ? 0 : c[d] >= dims[d] ? dims[d] - 1 : c[d];
            t[d] = s - (double)c[d];
        }
        for (int k = 0; k < 8; k++) {
            const int bx = k & 1, by = (k >> 1) & 1, bz = (k >> 2) & 1;
            const int64_t id = (c[0] + bx) + nx * ((c[1] + by) + ny * (c[2] + bz));
            g->corner[8 * (size_t)v + k] = id; /* the full grid's id for now */
            index[id] = 0;
            g->w[8 * (size_t)v + k] = (bx ? t[0] : 1.0 - t[0]) * (by ? t[1] : 1.0 - t[1]) *
                                      (bz ? t[2] : 1.0 - t[2]);
        }
    }
    /* the marked nodes, numbered in grid order; their positions */
    dk_index m = 0;
    for (size_t k = 0; k < n_all; k++)
        if (index[k] == 0)
            index[k] = m++ + 1; /* 1-based while counting */
    g->node_pos = malloc(3 * (size_t)m * sizeof *g->node_pos + 1);
    if (!g->node_pos) {
        free(index);
        dk_cage_grid_free(g);
        return dk_error_set(err, DK_ERR_OUT_OF_MEMORY, "Cage: out of memory (the grid)");
    }
    for (int64_t k = 0; k < (int64_t)n_all; k++)
        if (index[k] > 0) {
            double *p = g->node_pos + 3 * (size_t)(index[k] - 1);
            const int64_t i = k % nx, j = (k / nx) % ny, l = k / (nx * ny);
            p[0] = lo[0] + h * (double)i;
            p[1] = lo[1] + h * (double)j;
            p[2] = lo[2] + h * (double)l;
        }
    for (size_t k = 0; k < 8 * (size_t)n; k++)
        g->corner[k] = index[g->corner[k]] - 1;
    free(index);
    g->n_nodes = m;
    g->n = n;
    return DK_OK;
}

typedef struct blend_job {
    const dk_cage_grid *g;
    const double *x, *node_disp;
    const float *node_dispf;
    double *out;
} blend_job;

static void blend_range(void *ctx, dk_index v0, dk_index v1, int part)
{
    const blend_job *job = ctx;
    (void)part;
    for (dk_index v = v0; v < v1; v++) {
        const int64_t *c = job->g->corner + 8 * (size_t)v;
        const double *w = job->g->w + 8 * (size_t)v;
        double acc[3] = {0.0, 0.0, 0.0};
        for (int k = 0; k < 8; k++)
            for (int d = 0; d < 3; d++)
                acc[d] += w[k] * (job->node_disp ? job->node_disp[3 * (size_t)c[k] + d]
                                                 : (double)job->node_dispf[3 * (size_t)c[k] + d]);
        for (int d = 0; d < 3; d++)
            job->out[3 * (size_t)v + d] = job->x[3 * (size_t)v + d] + acc[d];
    }
}

void dk_cage_grid_blend(const dk_cage_grid *g, const double *x, const double *node_disp,
                        const float *node_dispf, double *out)
{
    blend_job job = {g, x, node_disp, node_dispf, out};
    dk_run_halves(blend_range, &job, g->n, 65536); /* two threads for big meshes */
}
