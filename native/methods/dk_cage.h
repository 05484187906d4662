/* DeformKit: cage-based free-form deformation with 3D mean value coordinates (the slides'
 * "arbitrary polyhedron cells"; Ju, Schaefer and Warren 2005, "Mean value coordinates for
 * closed triangular meshes"; Floater, Kos and Reimers 2005).
 *
 * The control (dk_controls.h, DK_CONTROL_CAGE): a closed triangle mesh around the mesh (its
 * rest vertices R, n_controls x 3, and triangles). Bind computes each vertex's coordinates
 * lambda (one per cage vertex: sum lambda_j R_j = x, sum lambda_j = 1) -- the dense n x
 * n_controls matrix W, the costly part, parallel over vertices. A solve moves the cage's
 * vertices to P (targets: n_controls x 3 positions) and every vertex by
 *     x' = x + sum_j lambda_j (P_j - R_j) = x + W (P - R),
 * one matrix product (BLAS), so that a cage at rest gives the mesh back bit for bit and an
 * affine map of the cage maps the mesh (linear precision).
 *
 * Mean value coordinates, as the paper evaluates them: per cage triangle, from the unit
 * vectors u_i towards its corners, the angles theta_i = 2 asin(|u_i+1 - u_i-1| / 2), h =
 * (theta_1 + theta_2 + theta_3) / 2, c_i = 2 sin(h) sin(h - theta_i) / (sin theta_i+1
 * sin theta_i-1) - 1, s_i = sign(det[u_1 u_2 u_3]) sqrt(1 - c_i^2), and
 *     w_i += (theta_i - c_i+1 theta_i-1 - c_i-1 theta_i+1) / (d_i sin theta_i+1 s_i-1),
 * normalised. Its special cases: a vertex on a cage vertex takes it (lambda its unit
 * vector); on a cage triangle (pi - h below 1e-10) the triangle's barycentric coordinates;
 * a triangle whose plane holds the vertex outside it (|s_i| below 1e-10) adds nothing. The
 * coordinates are defined inside and outside the cage, positive inside convex cages.
 *
 * Green coordinates instead (options.coordinates, green.c): x = sum phi_i R_i + sum psi_t
 * n_t over the cage's vertices and its faces' outward unit normals; a solve moves every
 * vertex by x' = x + Phi (P - R) + Psi (s n' - n), n' the moved faces' normals and s each
 * face's stretch (Lipman et al.'s sqrt(|u'|^2 |v|^2 - 2 (u'.v')(u.v) + |v'|^2 |u|^2) /
 * (sqrt(8) area), the scale of a face moved by a similarity): two products. Psi is n x
 * n_triangles more (about twice W).
 *
 * Memory: W is n x n_controls doubles (43k x 100: 35 MB), or floats with weights='single'
 * (a million vertices and a 500-vertex cage: 2 GB instead of 4), whose products keep the
 * motion to about 1e-7 of itself. It edits a pose only at bind (no input_positions): the
 * coordinates are the rest's. Direct: iterations 1; the energy reported is the squared
 * displacement sum |x' - x|^2. Rebind takes another cage for the same mesh.
 */
#ifndef DK_CAGE_H
#define DK_CAGE_H

#include "dk_constraints.h"
#include "dk_controls.h"
#include "dk_mesh.h"
#include "dk_method.h"
#include "dk_progress.h"
#include "dk_status.h"

#ifdef __cplusplus
extern "C" {
#endif

/** How W is stored. */
typedef enum dk_cage_weights {
    DK_CAGE_DOUBLE = 0, /**< doubles: affine maps to rounding (1e-13)                     */
    DK_CAGE_SINGLE = 1  /**< floats: half the memory, the motion to about 1e-7 of itself   */
} dk_cage_weights;

/** Which coordinates the vertices get. */
typedef enum dk_cage_coordinates {
    DK_CAGE_MEAN_VALUE = 0, /**< 3D mean value coordinates: affine maps of the cage map the
                                 mesh (linear precision)                                   */
    DK_CAGE_GREEN = 1       /**< Green coordinates (Lipman, Levin, Cohen-Or 2008): each
                                 vertex from the cage's vertices and its faces' normals,
                                 quasi-conformal, shape-preserving; similarities of the cage
                                 map the mesh by them, other affine maps do not (they keep
                                 the shape instead). Needs the cage's triangles oriented
                                 consistently (either way round)                           */
} dk_cage_coordinates;

/** Where the coordinates are computed. */
typedef enum dk_cage_evaluation {
    DK_CAGE_AUTO = 0,  /**< EXACT while the coordinates have at most DK_CAGE_AUTO_ENTRIES
                            entries (n x n_controls, plus n x n_triangles for Green), else
                            GRID                                                         */
    DK_CAGE_EXACT = 1, /**< at every vertex                                              */
    DK_CAGE_GRID = 2   /**< at the corners of a grid's cells that hold vertices, blended
                            trilinearly per vertex (cage/grid.c): linear precision and the
                            partition of unity kept exactly, the values between nodes to
                            the grid's h^2, memory and solves by the nodes, not the vertices */
} dk_cage_evaluation;

/** AUTO's limit: 64 M entries (512 MB of doubles). */
#define DK_CAGE_AUTO_ENTRIES 67108864.0

typedef struct dk_cage_options {
    dk_cage_coordinates coordinates; /**< default DK_CAGE_MEAN_VALUE                      */
    dk_cage_evaluation evaluation;   /**< default DK_CAGE_AUTO                            */
    int grid_resolution;             /**< GRID: cells along the mesh's box's longest side,
                                          4 .. 256; default 64 (the interpolation off the
                                          exact coordinates by about 3e-4 of the motion on
                                          the armadillo; 128: 8e-5)                       */
    dk_cage_weights weights;       /**< default DK_CAGE_DOUBLE                            */
    dk_phase_progress_fn progress; /**< bind progress (phase "coordinates"), NULL: none   */
    void *progress_user;
} dk_cage_options;

typedef struct dk_cage dk_cage;

void dk_cage_default_options(dk_cage_options *options);

/** Binds `mesh` (borrowed) to the cage `constraints->control` (DK_CONTROL_CAGE, checked by
 *  dk_control_check; no handles, fixed vertices or region). The progress hook may cancel
 *  (DK_ERR_CANCELLED, nothing returned). */
dk_status dk_cage_bind(const dk_mesh *mesh, const dk_constraint_desc *constraints,
                       const dk_cage_options *options, dk_cage **out, dk_error *err);

/** Another cage for the same mesh and options; on failure nothing changes. */
dk_status dk_cage_rebind(dk_cage *cage, const dk_constraint_desc *constraints, dk_error *err);

/** `request->targets`: the cage vertices' positions (n_controls x 3, positions only).
 *  Writes n_vertices x 3 positions; allocation-free. */
dk_status dk_cage_solve(dk_cage *cage, const dk_solve_request *request, double *positions,
                        dk_solve_info *info, dk_error *err);

/** The sum over the vertices of |positions - rest|^2. */
dk_status dk_cage_energy(const dk_cage *cage, const double *positions, double *energy,
                         dk_error *err);

void dk_cage_stats(const dk_cage *cage, dk_method_stats *stats);

/** The cage's vertices at rest (n_controls x 3), owned by the object. */
const double *dk_cage_rest_points(const dk_cage *cage);
void dk_cage_free(dk_cage *cage);

/** The edges of a cage's triangles, for dk_cage_mean_value: `edges` (n_edges x 2, each
 *  once) and, per triangle corner, the edge opposite it (`opposite`, n_triangles x 3).
 *  Allocates both (the caller frees them); DK_ERR_OUT_OF_MEMORY. */
dk_status dk_cage_edges(const dk_index *triangles, dk_index n_triangles, dk_index **edges,
                        dk_index *n_edges, dk_index **opposite, dk_error *err);

/** One vertex's mean value coordinates for a cage: `point` (3), the cage's `n_cage`
 *  vertices (n_cage x 3), `n_triangles` triangles (n_triangles x 3) and their edges
 *  (dk_cage_edges), into `lambda` (n_cage; `scratch`: 4 n_cage + 3 n_edges doubles). Each
 *  edge's angle is computed once for the two triangles that share it. Returns 0, or -1 when
 *  the weights sum to zero (a point the formula cannot place: a degenerate cage). */
int dk_cage_mean_value(const double *point, const double *cage, dk_index n_cage,
                       const dk_index *triangles, dk_index n_triangles, const dk_index *edges,
                       dk_index n_edges, const dk_index *opposite, double *lambda,
                       double *scratch);

/** One vertex's Green coordinates for a cage whose `n_triangles` triangles are oriented
 *  outwards, with their unit outward `normals` (n_triangles x 3) and edges (dk_cage_edges):
 *  `phi` (n_cage) and `psi` (n_triangles), so that point = sum phi_i cage_i + sum psi_t
 *  normal_t; outside the cage continued through the face it lies beyond (green.c).
 *  `scratch`: 4 n_cage + n_edges doubles. Returns 0, or -1 for a point the formula cannot
 *  place (a degenerate cage, or values not finite). */
int dk_cage_green(const double *point, const double *cage, dk_index n_cage,
                  const dk_index *triangles, dk_index n_triangles, const double *normals,
                  const dk_index *edges, dk_index n_edges, const dk_index *opposite,
                  double *phi, double *psi, double *scratch);

/** Peak bytes of a bind: the mesh's rows of W for a cage the model cannot know here (the
 *  Python binding and the bind check the control's own size: n x n_controls). */
dk_status dk_cage_estimate_memory(const dk_mesh *mesh, const dk_cage_options *options,
                                  uint64_t *bytes, dk_error *err);

extern const dk_method_ops dk_cage_ops;

#ifdef __cplusplus
}
#endif

#endif
