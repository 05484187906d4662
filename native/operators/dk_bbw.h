/* DeformKit: bounded biharmonic weights (Jacobson, Baran, Popovic, Sorkine 2011).
 *
 * One weight function w_j per handle over the shape: the minimiser of the biharmonic energy
 * 1/2 sum_j integral (Laplacian w_j)^2, discretised as 1/2 sum_j w_j^T K M^-1 K w_j (K the
 * cotangent stiffness, M the lumped mass), subject to
 *   - interpolation: w_j = 1 on handle j and 0 on every other handle (a bone along its whole
 *     segment; a cage's faces take the linear blend of their corners' weights: the paper's
 *     "cage edges linear");
 *   - bounds: 0 <= w_j <= 1;
 *   - partition of unity: sum_j w_j = 1.
 * As the paper does (its section 3, "we optimise each weight function separately, dropping
 * the partition of unity, and normalise"), each w_j is its own quadratic program with the
 * bounds as inequality constraints, solved exactly by a primal-dual active-set method on the
 * sparse system (every iteration solves the equality-constrained problem of its active set
 * with a sparse Cholesky factorization; it stops when the active set repeats, with the KKT
 * conditions then met to rounding), and the weights are divided by their sum at the end. The
 * bounds and the interpolation survive the division exactly; the report gives how far the
 * undivided sums were from 1.
 *
 * Where the weights live (the domain):
 *   VOLUME   the solid the mesh encloses (bones lie inside it, not on the surface), as a
 *            tetrahedral mesh: a Delaunay tetrahedralization (TetGen) of the grid points
 *            inside (generalized winding number >= 1/2: robust to holes, several parts,
 *            non-manifold edges and self-intersections), samples of the mesh's own vertices
 *            (so thin parts are there), and the handles' samples (so the handles are domain
 *            vertices and the interpolation is exact); the tetrahedra whose centroid is inside
 *            are kept. The mesh's vertices take the weights of the tetrahedron they lie in,
 *            linearly (bounded and summing to 1 as the domain's). With a cage among the
 *            handles the solid is the cage's inside instead.
 *   SURFACE  the mesh's own triangles; each handle sample is held at its nearest vertex. For
 *            handles on the surface, and for open or flat meshes that enclose no volume.
 *   AUTO     VOLUME when the mesh encloses one (grid points inside), else SURFACE.
 * Parts of the domain no handle reaches take the weights of the nearest point that one does.
 * Everything is relative to the shape's size: the same weights at any unit scale and place.
 */
#ifndef DK_BBW_H
#define DK_BBW_H

#include "dk_mesh.h"
#include "dk_progress.h"
#include "dk_sparse.h"
#include "dk_status.h"

#ifdef __cplusplus
extern "C" {
#endif

typedef enum dk_bbw_domain {
    DK_BBW_AUTO = 0,    /**< VOLUME when the mesh encloses one, else SURFACE (default)  */
    DK_BBW_VOLUME = 1,  /**< the solid inside the mesh (or the cage), tetrahedralized    */
    DK_BBW_SURFACE = 2  /**< the mesh's triangles                                        */
} dk_bbw_domain;

/** The handles, in this order in the weights' columns: points, then bones, then the cage's
 *  vertices. At least one handle in all; every coordinate finite. */
typedef struct dk_bbw_handles {
    dk_index n_points;
    const double *points;          /**< n_points x 3                                     */
    dk_index n_bones;
    const double *bones;           /**< n_bones x 2 x 3: each bone's head, then its tail
                                        (a zero-length bone is a point)                  */
    dk_index n_cage_vertices;
    const double *cage_vertices;   /**< n_cage_vertices x 3                              */
    dk_index n_cage_triangles;
    const dk_index *cage_triangles;/**< n_cage_triangles x 3, a closed cage around the
                                        mesh (VOLUME only)                               */
} dk_bbw_handles;

typedef struct dk_bbw_options {
    dk_bbw_domain domain;          /**< default AUTO                                      */
    int resolution;                /**< VOLUME: grid cells along the shape's longest side;
                                        default 24, in [4, 256]                           */
    int max_iterations;            /**< active-set iterations per handle; default 200    */
    dk_phase_progress_fn progress; /**< phases "domain", "operator", "weights"; NULL none */
    void *progress_user;
} dk_bbw_options;

/** What a computation did. */
typedef struct dk_bbw_report {
    dk_bbw_domain domain;          /**< the domain used (VOLUME or SURFACE)               */
    dk_index domain_vertices;      /**< unknowns per weight function plus held ones       */
    dk_index domain_elements;      /**< tetrahedra or triangles                           */
    int max_iterations;            /**< the most active-set iterations a handle took      */
    int total_iterations;          /**< over all handles                                  */
    double kkt_residual;           /**< worst KKT violation at the end, relative          */
    double sum_deviation;          /**< max |sum_j w_j - 1| before the division           */
    dk_index unreached;            /**< domain vertices in parts without a handle          */
} dk_bbw_report;

void dk_bbw_default_options(dk_bbw_options *options);

/** Total number of handles (weights' columns). */
dk_index dk_bbw_handle_count(const dk_bbw_handles *handles);

/** Computes the weights of every vertex of `mesh`: `weights` n_vertices x n_handles,
 *  row-major, each in [0, 1], each row summing to 1. `report` may be NULL. Fails with
 *  DK_ERR_INVALID_ARGUMENT naming the handle when two handles fall on one domain vertex or a
 *  handle lies outside the domain, DK_ERR_CANCELLED when progress asks to stop (weights then
 *  untouched), DK_ERR_NO_CONVERGENCE when a handle's active set has not settled within
 *  max_iterations. */
dk_status dk_bounded_biharmonic_weights(const dk_mesh *mesh, const dk_bbw_handles *handles,
                                        const dk_bbw_options *options, double *weights,
                                        dk_bbw_report *report, dk_error *err);

/** The quadratic program of one weight function, for tests and other discretizations:
 *  minimise 1/2 x^T A x - b^T x subject to lo <= x <= hi (lo < hi, both finite), with A
 *  (m x m, both triangles) symmetric positive definite. `x` holds a start on entry (any
 *  values: it only seeds the active set) and the minimiser on return; `iterations` and
 *  `kkt_residual` may be NULL. */
dk_status dk_box_qp(const dk_sparse *a, const double *b, double lo, double hi, double *x,
                    int max_iterations, int *iterations, double *kkt_residual, dk_error *err);

#ifdef __cplusplus
}
#endif

#endif
