/* DeformKit: Laplacian editing / least-squares meshes (Sorkine et al., "Laplacian Surface
 * Editing" 2004; Sorkine & Cohen-Or, "Least-squares Meshes" 2004; Lipman et al.,
 * "Differential Coordinates for Interactive Mesh Editing" 2004 for the local frames).
 *
 * The differential operator. Row i of the n x n operator A is the normalised "umbrella" of
 * the lecture (slide 45):   A_ii = 1,  A_ij = -w_ij / sum_k w_ik  (j in the one-ring of i),
 * so (A x)_i = x_i - (weighted mean of the neighbours). Weights are 1 (uniform) or the
 * cotangent weights of dk_cotangent_weights at rest. Cotangent fallback: a vertex whose
 * cotangent weight sum is not > 1e-12 * degree (only degenerate or strongly obtuse incident
 * triangles) gets the uniform row instead; dk_laplacian_edit_counters counts those vertices.
 * An isolated vertex (no neighbour) gets the row A_ii = 1 and therefore stays at rest.
 * A is not symmetric; only A^T A is used.
 *
 * The energy minimised (x: n x 3 positions, each coordinate separately; c: handle targets):
 *     E(x) = ||A x - delta||^2 + sum_{soft rows i} (lambda w_i)^2 |x_i - c_i|^2
 *            + mu^2 sum_{unknown i} |x_i - x0_i|^2
 * with delta = A x0 ("fixed": detail preserving), delta = 0 ("membrane", slide 61), or the
 * rest differential coordinates rotated into local frames of the current solution
 * ("local_frame", slide 69). Norms are squared Euclidean over all n rows and 3 columns.
 *
 * Constraints (dk_constraints.h). Vertices outside the ROI always stay at rest (eliminated).
 *   hard: fixed vertices and handle vertices of weight 1 are eliminated (x_i given); handle
 *         vertices of weight w < 1 become unknowns with a soft row of weight lambda * w.
 *         The unknowns ("free" here) minimise E via the normal equations
 *         (A_f^T A_f + S + mu^2 I) x_f = A_f^T (delta - A_c x_c) + S c + mu^2 x0_f,
 *         S = diag((lambda w_i)^2) on soft rows.
 *   soft: every vertex inside the ROI is unknown; each handle vertex gets a soft row of
 *         weight lambda * w_i (target c_i), each fixed vertex one of weight lambda (target:
 *         its rest position) -- the [A; lambda I_c] x = [delta; lambda c] system of slide 51.
 * The matrix is factored (CHOLMOD, analysed once) at bind; a solve from targets is a
 * 3-column back-substitution (per local-frame iteration) and no allocation. Because the
 * solution is affine in the entries of the handle transforms, bind also precomputes (for up
 * to 16 handles and 128 MB) x = g0 + sum_{h,a} T_h[d][a] G_{h,a} (3 + 4 H columns, one multi-RHS
 * solve), so a solve from transforms (mode 1) needs no back-substitution at all (the
 * local-frame updates after it still do). A solve from positions (mode 0) takes the basis too
 * when one affine map per handle reproduces its targets to 1e-13 of their magnitude (a drag
 * the caller computed per vertex; the maps are fitted in O(handle vertices)); other
 * positions back-substitute. If that basis cannot be allocated, or options.basis is OFF,
 * every solve back-substitutes.
 *
 * Local frames (slide 69, as Blender's Laplacian Deform): at every vertex an orthonormal
 * frame (n, u, n x u): n the area-weighted normal of the incident triangles, u the
 * projection onto the tangent plane of the edge to one fixed neighbour (chosen at rest as
 * the one whose edge is most orthogonal to n; cosines within 1e-9 tie, ties go to the
 * longest edge, then to the smaller vertex number). The rest delta_i is stored as coordinates in
 * the rest frame. A solve first uses the rest deltas (= "fixed"), then repeats
 * `local_frame_iterations` times: rebuild the frames on the current solution, rotate the
 * stored coordinates into them (|delta_i| is preserved exactly), solve again. Blender does
 * one such extra solve (the default here). It stops early when no vertex moved more than
 * local_frame_tolerance * bbox diagonal in an iteration; `converged` reports exactly that
 * test on the last iteration. A vertex whose frame is degenerate (zero normal or tangent, at
 * rest or deformed) keeps its unrotated rest delta.
 *
 * The reported energy is E(x) at the returned positions, with the delta of the last linear
 * solve (for local_frame: the rotated deltas that the returned positions minimise over).
 */
#ifndef DK_LAPLACIAN_EDIT_H
#define DK_LAPLACIAN_EDIT_H

#include "dk_constraints.h"
#include "dk_mesh.h"
#include "dk_method.h"
#include "dk_progress.h"
#include "dk_status.h"

#ifdef __cplusplus
extern "C" {
#endif

/** Edge weights of the differential operator. */
typedef enum dk_le_weights {
    DK_LE_WEIGHTS_UNIFORM = 0,  /**< w_ij = 1                                             */
    DK_LE_WEIGHTS_COTANGENT = 1 /**< rest cotangent weights, uniform fallback (see above)  */
} dk_le_weights;

/** Right-hand side of the differential part. */
typedef enum dk_le_detail {
    DK_LE_DETAIL_FIXED = 0,      /**< delta = A x0: preserves rest details, not rotated     */
    DK_LE_DETAIL_MEMBRANE = 1,   /**< delta = 0: smooth membrane, details flattened         */
    DK_LE_DETAIL_LOCAL_FRAME = 2 /**< rest deltas in local frames, iterated (see above)     */
} dk_le_detail;

/** How handle and fixed vertices enter the system. */
typedef enum dk_le_constraint_mode {
    DK_LE_CONSTRAINTS_HARD = 0, /**< eliminated, met exactly (weight-1 handles and fixed)  */
    DK_LE_CONSTRAINTS_SOFT = 1  /**< least-squares rows of weight lambda * handle weight   */
} dk_le_constraint_mode;

/** Whether bind precomputes the affine basis (see the file comment). */
typedef enum dk_le_basis {
    DK_LE_BASIS_AUTO = 0, /**< built when it fits the limits (16 handles, 128 MB)           */
    DK_LE_BASIS_OFF = 1   /**< never: every solve back-substitutes (tests, memory)          */
} dk_le_basis;

/** Options of one bind. Fill with dk_laplacian_edit_default_options, then change fields. */
typedef struct dk_laplacian_edit_options {
    dk_le_weights weights;            /**< default COTANGENT                                */
    dk_le_detail detail;              /**< default LOCAL_FRAME (the add-on's too: details
                                           turn with the surface)                           */
    dk_le_constraint_mode constraints;/**< default HARD                                     */
    double constraint_weight;         /**< lambda > 0, finite; default 1                    */
    double tikhonov;                  /**< mu >= 0, finite; default 0                       */
    int local_frame_iterations;       /**< frame updates after the first solve, 0..1000;
                                           default 1 (Blender)                               */
    double local_frame_tolerance;     /**< >= 0, relative to the bbox diagonal; default 1e-6 */
    dk_le_basis basis;                /**< default AUTO                                     */
    dk_phase_progress_fn progress;    /**< bind progress (dk_progress.h), NULL by default:
                                           the phases renumber, operator, constraints,
                                           assemble, analyze, factorize, basis, and "done"
                                           at 1; a non-zero return cancels the bind
                                           (DK_ERR_CANCELLED, nothing leaked). Asked between
                                           phases, every few thousand unknowns of the
                                           assembly and between the basis' solves (g0's 3
                                           columns, then 4 per handle); not during CHOLMOD's
                                           analysis and factorization, which cannot be
                                           interrupted. For the bind only: the object does
                                           not keep it                                      */
    void *progress_user;              /**< passed to progress                               */
} dk_laplacian_edit_options;

/** Counters for tests and reports. */
typedef struct dk_laplacian_edit_counters {
    dk_index n_unknowns;          /**< size of the factored system                          */
    dk_index n_soft_rows;         /**< vertices with a soft constraint row                   */
    dk_index n_cotangent_fallback;/**< rows that fell back to uniform weights                */
    dk_index n_degenerate_frames; /**< vertices without a rest frame (local_frame only)      */
    int analysis_count;           /**< symbolic analyses done so far (bind + rebinds)        */
    int factorization_count;      /**< numeric factorizations done so far                    */
    int basis_columns;            /**< columns of the affine basis (3 + 4 n_handles), 0 when
                                       it was not built                                     */
    int basis_solves;             /**< solves since bind that combined the basis instead of
                                       back-substituting (from transforms, or from positions
                                       that an affine map per handle reproduces)            */
} dk_laplacian_edit_counters;

typedef struct dk_laplacian_edit dk_laplacian_edit;

/** Writes the defaults into `options`. */
void dk_laplacian_edit_default_options(dk_laplacian_edit_options *options);

/** Builds the operator, the rest deltas (and frames), validates the constraints
 *  (dk_constraints_create) and factors the system. Refuses (naming the problem): a mesh
 *  without triangles or with a zero bounding box (DK_ERR_DEGENERATE), invalid options
 *  (DK_ERR_INVALID_ARGUMENT), a connected
 *  component of unknowns that touches no constraint while tikhonov = 0 (the system would be
 *  singular; DK_ERR_DEGENERATE naming a vertex of it). `mesh` is borrowed and must outlive
 *  the object. `options` may be NULL (defaults). */
dk_status dk_laplacian_edit_bind(const dk_mesh *mesh, const dk_constraint_desc *desc,
                                 const dk_laplacian_edit_options *options,
                                 dk_laplacian_edit **out, dk_error *err);

/** Replaces the constraints (same mesh and options). The operator and rest deltas are kept;
 *  when the set of unknowns is unchanged the symbolic analysis is reused (and the numeric
 *  factorization too when the matrix values are unchanged). On failure the object keeps its
 *  previous constraints and stays usable. */
dk_status dk_laplacian_edit_rebind(dk_laplacian_edit *le, const dk_constraint_desc *desc,
                                   dk_error *err);

/** The progress callback of the following rebinds (NULL: none, as after bind): the phases
 *  constraints, assemble, analyze (skipped when the analysis is reused), factorize (skipped
 *  when the values are unchanged too), basis, then "done" at 1. A non-zero return cancels
 *  the rebind with DK_ERR_CANCELLED and the object keeps its previous constraints, factor,
 *  basis and last solve's deltas exactly; a cancellation in the basis after the analysis was
 *  reused refactors the previous values (the factorization's time) to give the analysis
 *  back. */
void dk_laplacian_edit_set_progress(dk_laplacian_edit *le, dk_phase_progress_fn progress,
                                    void *user);

/** Deformed positions (n x 3, row-major) for the handle targets of `request`
 *  (dk_method.h): a direct method, so request->start and max_iterations change nothing;
 *  request->skip_energy saves one pass over the operator (~0.4 ms of a 6 ms local-frame
 *  solve on 43k vertices; info.energy is then NaN). `info` (may be NULL): energy E(x) at the
 *  returned positions (see the file comment), iterations (linear solves done: 1 unless
 *  local_frame), converged (1 for fixed/membrane; local_frame: the last change <= tolerance),
 *  last_change (local_frame: the max vertex move of the last iteration / bbox diagonal).
 *  request->input_positions (DK_METHOD_EDITS_INPUT): the pose to edit in place of the rest
 *  (its deltas through the bind's operator, its frames; fixed vertices stay at it; the
 *  bind's factor, the affine basis left aside while a pose is edited).
 *  Not thread-safe on the same object (uses buffers held in it). */
dk_status dk_laplacian_edit_solve(dk_laplacian_edit *le, const dk_solve_request *request,
                                  double *positions, dk_solve_info *info, dk_error *err);

/** E(x) for arbitrary positions (n x 3) with the handle targets and deltas of the most
 *  recent solve (before any solve: rest deltas and rest handle positions). */
dk_status dk_laplacian_edit_energy(const dk_laplacian_edit *le, const double *positions,
                                   double *energy, dk_error *err);

/** The contract's counters (dk_method.h); zeros for NULL. */
void dk_laplacian_edit_stats(const dk_laplacian_edit *le, dk_method_stats *stats);

/** Laplacian editing's own counters (see dk_laplacian_edit_counters). */
void dk_laplacian_edit_get_counters(const dk_laplacian_edit *le, dk_laplacian_edit_counters *stats);

/** Frees; NULL allowed. */
void dk_laplacian_edit_free(dk_laplacian_edit *le);

/** The bytes a bind needs at its peak, its first solve included (dk_method.h,
 *  dk_method_estimate_memory): as ARAP's, the factor of the n-unknown system. `options`
 *  (may be NULL) changes nothing. DK_ERR_INVALID_ARGUMENT for a NULL mesh or bytes. */
dk_status dk_laplacian_edit_estimate_memory(const dk_mesh *mesh,
                                            const dk_laplacian_edit_options *options,
                                            uint64_t *bytes, dk_error *err);

/** Laplacian editing's table of the method contract (dk_method.h); options are a
 *  dk_laplacian_edit_options. */
extern const dk_method_ops dk_laplacian_edit_ops;

#ifdef __cplusplus
}
#endif
#endif
