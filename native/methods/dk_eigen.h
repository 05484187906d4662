/* DeformKit: eigen deformation with Laplace-Beltrami eigenvectors (Dey, Ranjan & Wang,
 * "Eigen Deformation of 3D Models", ../shared/papers/000_*.txt; docs/methods/eigen.md).
 *
 * Bind (precompute):
 *   - the first K eigenvectors U (n x K) of the cotangent Laplacian with the mixed-Voronoi
 *     mass matrix, L phi = lambda M phi (dk_eigs; a dense solve on small meshes);
 *   - Phi = U^T U (the Gram matrix of eq. 1's normal equations: the paper's <phi_i, phi_j>
 *     is the sum over the vertices, as eq. 1 is) and its Cholesky factor; the factor of the
 *     leading m x m block of Phi is the leading block of Phi's factor, so one factor serves
 *     every eigenvector count up to K;
 *   - the eigen-skeletons K_m (and K_n' for the two-iteration scheme): eq. 1 fitted to the
 *     mesh itself, p = U_m Phi_m^-1 U_m^T V;
 *   - the detail vectors and their coordinates in each skeleton vertex's local frame
 *     (normal, projected incident edge, their cross product; section 3.3);
 *   - g, the distance along edges to the boundary of R (one multi-source Dijkstra), the
 *     interpolation weights w (section 4.1) and the automatic eigenvector count (4.2).
 * Solve (per drag), allocation-free:
 *   Step 1 the coarse target: R's skeleton points transformed, the rest kept;
 *   Step 2 eq. 1: b updated from R's rows only, two triangular solves, p* = U_m A;
 *   Step 3 detail recovery: local-frame and transformation-based details blended by w; for
 *          m < n' the two-iteration scheme of section 4.3 (interpolation-based recovery to
 *          K~_n', a re-fit with n' eigenvectors, local-frame recovery).
 *
 * Constraints (the method contract): R, the region that moves, is made of groups, each with
 * its own motion: per handle, the part of the mesh it drags (turned about the part's border
 * so that the handle reaches its target) and the handle group itself (region
 * DK_EIGEN_REGION_PART, the default; eigen/part.h), or the handle groups alone
 * (DK_EIGEN_REGION_HANDLES). Every other vertex keeps its skeleton position in eq. 1 (the
 * paper has no fixed set: the fixed vertices are simply outside R). Handle weights and a
 * region of interest are refused (a region moves as a whole). Targets given as transforms
 * are the paper's rotation-type motion (T applied to the group's skeleton points and, in the
 * transformation-based details, T's linear part to the detail vectors); targets given as
 * positions move each skeleton point by its vertex's displacement (translation-type, per
 * vertex). The least-squares fit meets neither exactly: the flag DK_METHOD_SOFT_REGIONS.
 *
 * The energy a solve reports: sum_i |x_i - x~_i|^2, the distance of the result x to the
 * Step-1 target of the mesh itself (R's vertices at their targets, the rest at rest).
 */
#ifndef DK_EIGEN_H
#define DK_EIGEN_H

#include "dk_constraints.h"
#include "dk_mesh.h"
#include "dk_progress.h"
#include "dk_method.h"
#include "dk_status.h"

#ifdef __cplusplus
extern "C" {
#endif

/** Which Laplacian's eigenvectors. */
typedef enum dk_eigen_laplacian {
    DK_EIGEN_COTANGENT = 0,       /**< cotangent weights, mixed-Voronoi mass (Meyer et al.) */
    DK_EIGEN_BELKIN_SUN_WANG = 1  /**< the mesh-Laplacian of Belkin, Sun & Wang 2008, the
                                       paper's: (L f)(w) = 1 / (4 pi h^2) sum_p a_p
                                       exp(-|p - w|^2 / 4h) (f(p) - f(w)), a_p a third of the
                                       areas around p; solved as the symmetric generalized
                                       problem with stiffness a_w a_p exp(..) / (4 pi h^2)
                                       and mass a. The kernel is cut where it falls below
                                       e^-9 (|p - w| > 6 sqrt(h)), over each vertex's 64
                                       nearest vertices in space                            */
} dk_eigen_laplacian;

/** What each handle moves (the region R of the paper). */
typedef enum dk_eigen_region {
    DK_EIGEN_REGION_PART = 0,    /**< the part the handle drags: the free vertices whose
                                      harmonic field (1 on the handle, 0 on the other handles
                                      and the fixed vertices) is the handle's and above one
                                      half, turned about the border of the part so that the
                                      handle's centroid reaches its target, the handle
                                      following its own targets (eigen/part.h). Default      */
    DK_EIGEN_REGION_HANDLES = 1  /**< the handle groups alone, moved to their targets: the
                                      paper's R when the user selects it as a handle group  */
} dk_eigen_region;

/** Options; fill with dk_eigen_default_options. */
typedef struct dk_eigen_options {
    int n_eigenvectors;      /**< m; 0 = automatic (section 4.2: 8, 50 or 300 from
                                  delta_3 = diam R / diam(V \ R), plus one per connected
                                  surface beyond the first). Default 0                    */
    int refine;              /**< n' of the two-iteration scheme (section 4.3), used when
                                  m < n'; 0 = one iteration always. Default 300           */
    dk_eigen_laplacian laplacian; /**< default DK_EIGEN_COTANGENT                         */
    dk_eigen_region region;  /**< what each handle moves; default DK_EIGEN_REGION_PART       */
    double bsw_width;        /**< Belkin-Sun-Wang: sqrt(4h), the kernel's width, in mean edge
                                  lengths (> 0; default 1)                                */
    dk_phase_progress_fn progress; /**< bind progress in named phases (dk_progress.h):
                                  "regions", "operator", "eigenvectors" (the fraction of
                                  the eigenpairs found), "skeletons", then "done"; may be
                                  NULL; a non-zero return cancels the bind
                                  (DK_ERR_CANCELLED, nothing kept)                        */
    void *progress_user;
} dk_eigen_options;

typedef struct dk_eigen dk_eigen;

/** Writes the defaults into `options`. */
void dk_eigen_default_options(dk_eigen_options *options);

/** Binds: the precomputation above. `mesh` (n_vertices >= 4, with faces, no isolated
 *  vertices) is borrowed and must outlive the object; `options` may be NULL. */
dk_status dk_eigen_bind(const dk_mesh *mesh, const dk_constraint_desc *constraints,
                        const dk_eigen_options *options, dk_eigen **out, dk_error *err);

/** New regions, same mesh and options: the eigenvectors and Phi's factor are kept; the
 *  distances, weights, m (when automatic) and skeleton right-hand sides are recomputed. On
 *  failure nothing changes. */
dk_status dk_eigen_rebind(dk_eigen *e, const dk_constraint_desc *constraints, dk_error *err);

/** Steps 1-3: deformed positions (n_vertices x 3) for `request` (a direct method: start and
 *  max_iterations change nothing). `info` (may be NULL): the energy above, iterations 1 or
 *  2 (the scheme's iterations), converged 1. Allocation-free. */
dk_status dk_eigen_solve(dk_eigen *e, const dk_solve_request *request, double *positions,
                         dk_solve_info *info, dk_error *err);

/** The fast preview while dragging (1) or the full result (0, the default) for the next
 *  solves (a request's `preview` asks the same for one solve). The preview is Steps 1-2 only, shown on the mesh as v + (p* - p): the skeleton's
 *  motion carried to every vertex with its detail vector unrotated (the skeleton itself, at
 *  m = 8, is a blob, not a preview an artist can read). A preview solve reports
 *  iterations 0. */
void dk_eigen_set_preview(dk_eigen *e, int preview);

/** Whether the next solve is a preview (dk_eigen_set_preview); 0 for NULL. */
int dk_eigen_preview(const dk_eigen *e);

/** sum_i |positions_i - x~_i|^2 for the last solve's Step-1 target (before any solve: the
 *  rest). */
dk_status dk_eigen_energy(const dk_eigen *e, const double *positions, double *energy,
                          dk_error *err);

/** The eigen-skeleton K_m of the rest mesh (n_vertices x 3) for the m in use. */
const double *dk_eigen_skeleton(const dk_eigen *e);

/** m in use, and K (eigenvectors computed: max(m, n') or m). */
int dk_eigen_m(const dk_eigen *e);
int dk_eigen_k(const dk_eigen *e);

/** The K eigenvalues (ascending) and eigenvectors (n_vertices x K, column-major,
 *  M-orthonormal). */
const double *dk_eigen_eigenvalues(const dk_eigen *e);
const double *dk_eigen_eigenvectors(const dk_eigen *e);

/** delta_3 of section 4.2 for the current regions (INFINITY when V \ R is empty or
 *  unreachable from R's boundary), and the interpolation weight w of every vertex
 *  (n_vertices; section 4.1). */
double dk_eigen_delta3(const dk_eigen *e);
const double *dk_eigen_weights(const dk_eigen *e);

/** The contract's counters (dk_method.h); zeros for NULL. */
void dk_eigen_stats(const dk_eigen *e, dk_method_stats *stats);

/** Frees; NULL allowed. */
void dk_eigen_free(dk_eigen *e);

/** The bytes a bind needs at its peak, its first solve included (dk_method.h,
 *  dk_method_estimate_memory): the K basis vectors (K the larger of n_eigenvectors, 300 when
 *  automatic, and refine), the eigensolver's Krylov vectors and the Laplacian's factor.
 *  `options` may be NULL (the defaults). DK_ERR_INVALID_ARGUMENT for a NULL mesh or bytes. */
dk_status dk_eigen_estimate_memory(const dk_mesh *mesh, const dk_eigen_options *options,
                                   uint64_t *bytes, dk_error *err);

/** Eigen deformation's table of the method contract; options are a dk_eigen_options. */
extern const dk_method_ops dk_eigen_ops;

#ifdef __cplusplus
}
#endif
#endif
