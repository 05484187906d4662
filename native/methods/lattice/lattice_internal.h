/* DeformKit lattice FFD, internal: the object and the registration of vertices to the
 * lattice (see dk_lattice.h). Not part of the public API.
 *
 * Files, one idea each:
 *   lattice.c   the public verbs: options, bind, rebind, solve, energy, stats, the table
 *   basis.c     the 1D bases (linear, Bernstein, cubic B-spline with extended ends) and the
 *               registration of a pose: per vertex and axis a first index and its weights
 */
#ifndef DK_LATTICE_INTERNAL_H
#define DK_LATTICE_INTERNAL_H

#include "dk_lattice.h"
#include "dk_parallel.h"

#include <math.h>
#include <stdlib.h>
#include <string.h>

/* The largest resolution along an axis: any basis (a lattice is a coarse control), and the
 * Bernstein one, whose every point weighs on every vertex (l m n products a vertex). */
#define LATTICE_MAX_RESOLUTION 256
#define LATTICE_MAX_BERNSTEIN 32

/* One lattice: its resolution, its box (the control's frame and its inverse) and its rest
 * points. Replaced whole by rebind. */
typedef struct lattice_grid {
    dk_index res[3];      /* points along x, y, z                                         */
    dk_index n_points;    /* res[0] res[1] res[2]                                         */
    int k[3];             /* weights per vertex along each axis (2, 4, or res[axis])       */
    double frame[16];     /* the unit cube onto the box, row-major 4 x 4                  */
    double inv[12];       /* the box onto the unit cube, rows of a 3 x 4 affine map        */
    double *rest;         /* n_points x 3: the points at rest                             */
    /* the registration of the pose (n vertices): per vertex the first index along each
     * axis (3) and the weights (k[0] + k[1] + k[2]), x's scaled by the fade outside */
    dk_index *first;
    double *w;
    double *disp;         /* n_points x 3: the points' motion of a solve (scratch)        */
} lattice_grid;

struct dk_lattice {
    const dk_mesh *mesh;
    dk_lattice_options opt;
    dk_index n;
    lattice_grid grid;
    double *pose;         /* n x 3: the positions registered (the rest, or an input)       */
    int pose_is_input;    /* pose holds a request's input_positions, not the rest          */
    dk_team *team;        /* the deformation pass's helper thread (NULL: per pass)         */
};

/* Below this many vertices a pass runs on the calling thread only (waking the helper cost
 * more than it saved at 43k: scripts/bench_lattice.py). */
#define LATTICE_PARALLEL_MIN 100000

/* basis.c: checks the control for this method (resolution and basis limits) and fills the
 * grid's box, rest points and buffers (allocates; on failure the grid is freed) */
dk_status lattice_grid_create(const dk_control_desc *control, const dk_lattice_options *opt,
                              dk_index n_vertices, lattice_grid *g, dk_error *err);
void lattice_grid_free(lattice_grid *g);

/* basis.c: registers positions p (n x 3, row-major) to the grid: first and w */
void lattice_register(const dk_lattice_options *opt, lattice_grid *g, const double *p,
                      dk_index n);

#endif
