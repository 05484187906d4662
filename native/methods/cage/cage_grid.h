/* DeformKit cage FFD, internal: the grid a cage's coordinates are computed on when they are
 * interpolated (grid.c; dk_cage.h, DK_CAGE_GRID). */
#ifndef DK_CAGE_GRID_H
#define DK_CAGE_GRID_H

#include <stdint.h>

#include "dk_mesh.h"
#include "dk_status.h"

typedef struct dk_cage_grid {
    dk_index n;        /* the mesh's vertices                                              */
    dk_index n_nodes;  /* the grid nodes at the corners of the cells holding a vertex      */
    int64_t *corner;   /* n x 8: each vertex's cell's corners (node indices)               */
    double *w;         /* n x 8: their trilinear weights (summing to 1)                    */
    double *node_pos;  /* n_nodes x 3: the nodes' positions (freed after the bind)         */
} dk_cage_grid;

/** The grid for the points `pos` (n x 3): cubic cells, `resolution` along the bounding
 *  box's longest side (a positive count); fills `g` (dk_cage_grid_free frees it). */
dk_status dk_cage_grid_plan(const double *pos, dk_index n, int resolution, dk_cage_grid *g,
                            dk_error *err);

/** out (n x 3) = x (n x 3) + each vertex's blend of its corners' rows of node_disp (n_nodes
 *  x 3 doubles), or of node_dispf (floats) when node_disp is NULL. */
void dk_cage_grid_blend(const dk_cage_grid *g, const double *x, const double *node_disp,
                        const float *node_dispf, double *out);

void dk_cage_grid_free(dk_cage_grid *g);

#endif
