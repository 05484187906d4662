/* DeformKit: As-Rigid-As-Possible surface deformation (Sorkine & Alexa 2007), with the
 * spokes-and-rims variant (Chao et al. 2010), per-vertex stiffness, soft handles and
 * Anderson acceleration (Peng et al. 2018). See docs/methods/arap.md.
 *
 * Energy. Every vertex i owns a cell: a list of weighted rest edges (a, b, w), and
 *     E(p') = sum_i s_i sum_{(a,b,w) in cell i} w ||(p'_a - p'_b) - R_i (p_a - p_b)||^2
 *           + sum_{soft handle vertices v} k_v ||p'_v - t_v||^2
 * with R_i the rotation minimising cell i's term (so E is a function of positions only),
 * s_i the per-vertex stiffness and k_v = lambda * w_v / (1 - w_v) for a handle weight
 * w_v < 1, lambda = mean diagonal entry of the ARAP matrix (puts the penalty in the units of
 * the ARAP energy).
 *   spokes:          cell i = the edges (i, j) of its one-ring, w = w_ij
 *   spokes_and_rims: cell i = every edge of every triangle incident to i, each with its
 *                    triangle's half weight cot(opposite angle) / 2 (the same edge appearing
 *                    in two incident triangles gets the sum of both halves)
 * Weights: per triangle edge a half weight h = cot(opposite angle) / 2 (cotangent; 0 for a
 * degenerate triangle, dk_triangle_degenerate) or 1/2 (uniform); each cell's entries for the
 * same edge are summed (so a spoke weighs w_ij = (cot alpha + cot beta) / 2), and the
 * clamped kind replaces every summed weight w by max(w, 0). DEFAULT: clamped cotangent, since
 * a negative weight makes its cell's term concave in that edge: the local/global iteration is
 * then no longer guaranteed to decrease the energy and the global matrix can lose positive
 * definiteness on poor (non-Delaunay) meshes; on Delaunay meshes both kinds are identical.
 *
 * Constraints: fixed vertices, vertices outside the ROI and handle vertices of weight 1 are
 * eliminated exactly; handle vertices of weight < 1 are unknowns pulled by the penalty above.
 * Global step: A x_u = rhs with A = the ARAP matrix restricted to the unknowns (+ soft
 * penalties on its diagonal), factored (CHOLMOD) once per bind / rebind, 3 right-hand sides
 * per iteration.
 */
#ifndef DK_ARAP_H
#define DK_ARAP_H

#include "dk_constraints.h"
#include "dk_mesh.h"
#include "dk_method.h"
#include "dk_progress.h"
#include "dk_status.h"

#ifdef __cplusplus
extern "C" {
#endif

typedef enum dk_arap_energy_kind {
    DK_ARAP_SPOKES = 0,
    DK_ARAP_SPOKES_AND_RIMS = 1
} dk_arap_energy_kind;

typedef enum dk_arap_weight_kind {
    DK_ARAP_WEIGHTS_COTANGENT = 0,         /**< raw cotangent weights, may be negative   */
    DK_ARAP_WEIGHTS_CLAMPED_COTANGENT = 1, /**< max(w, 0): the default                   */
    DK_ARAP_WEIGHTS_UNIFORM = 2            /**< 1 per spoke                              */
} dk_arap_weight_kind;

/** How the solve iterates. NONE: the paper's local/global iteration. ANDERSON: the same,
 *  with Anderson acceleration and an energy safeguard (Peng et al. 2018). NEWTON: inexact
 *  Newton steps on E(x) (rotations optimal for x): the exact Hessian applied by matrix-free
 *  products, inverted approximately by `cg_iterations` preconditioned conjugate-gradient
 *  iterations with the bound factor as preconditioner (so the first iterate is the
 *  local/global step), an energy line search with the local/global step as fallback (E never
 *  increases). Ours; docs/methods/arap.md. Fewer, costlier iterations that reach the
 *  minimum's slow (bending) modes, which local/global iterations barely move. */
typedef enum dk_arap_acceleration {
    DK_ARAP_ACCEL_NONE = 0,
    DK_ARAP_ACCEL_ANDERSON = 1,
    DK_ARAP_ACCEL_NEWTON = 2
} dk_arap_acceleration;

/** Whether bind precomputes the warm start's response basis: 4 columns per handle (up to
 *  16 handles and 128 MB), the global step's response to each handle moved by an affine
 *  map, so that warm starts after such a move (a drag by translation, rotation or scale,
 *  given as transforms or as the positions such a map gives) combine columns in O(n)
 *  instead of back-substituting through the factor. Costs one solve of 4 columns per
 *  handle at bind and rebind. Results equal the substituted starts' to rounding. */
typedef enum dk_arap_basis {
    DK_ARAP_BASIS_AUTO = 0, /**< built when it fits the limits (the default)               */
    DK_ARAP_BASIS_OFF = 1   /**< never: warm starts back-substitute (tests, memory)         */
} dk_arap_basis;

/** How many conjugate-gradient iterations a Newton step runs (acceleration NEWTON). FIXED
 *  (the default): cg_iterations for every step. GROWING: cg_iterations while the last step
 *  lowered E by more than 1e-3 of it, twice as many while it lowered E by more than 1e-5,
 *  four times as many below (an Eisenstat-Walker-like forcing: near the minimum the slow
 *  bending modes are what is left). The count starts at cg_iterations in every solve that is
 *  not resumed; a resumed solve continues the schedule, so slices still equal one long solve
 *  bit for bit. A count given to dk_arap_set_cg_iterations is run as given, never scaled
 *  (time-budgeted slices need a step's cost to be predictable). Measured (docs/methods/
 *  arap.md, "A CG count that grows"): GROWING gets closer to the minimum (to 1e-6 of E in
 *  8.7 s against 11.1 s on the 173k armadillo), but to the stopping test at the default
 *  tolerance it is 20-70% slower on the 173k and 692k armadillo, hence not the default. */
typedef enum dk_arap_cg_schedule {
    DK_ARAP_CG_FIXED = 0,  /**< the default                                                */
    DK_ARAP_CG_GROWING = 1
} dk_arap_cg_schedule;

/** Per-iteration observer: called after every iteration (and once with iteration 0 for the
 *  initial guess) with the energy of the accepted iterate. Returning non-zero stops the
 *  solve with DK_ERR_CANCELLED. Must not call back into the same object. */
typedef int (*dk_arap_iteration_fn)(void *user, int iteration, double energy);

typedef struct dk_arap_options {
    dk_arap_energy_kind energy;        /**< default DK_ARAP_SPOKES                        */
    dk_arap_weight_kind weights;       /**< default DK_ARAP_WEIGHTS_CLAMPED_COTANGENT     */
    int max_iterations;                /**< >= 1, default 1000                            */
    double tolerance;                  /**< >= 0, default 1e-6. NONE / ANDERSON: stop when
                                            the last iteration lowered E by at most
                                            tolerance * E_prev. NEWTON: stop when the best
                                            step along the local/global direction would
                                            lower E by at most tolerance * E (predicted by
                                            the quadratic model, before any step is taken)
                                            and the gap to the minimum extrapolated from
                                            the last steps' decreases is at most
                                            tolerance * E too, after a step that met no
                                            negative curvature (docs/methods/arap.md)  */
    dk_arap_acceleration acceleration; /**< default DK_ARAP_ACCEL_NEWTON                  */
    int anderson_depth;                /**< 1..20, default 5                              */
    int cg_iterations;                 /**< NEWTON: conjugate-gradient iterations (Hessian
                                            products) per Newton step, 1..100, default 12
                                            (the first step's; see cg_schedule)          */
    dk_arap_cg_schedule cg_schedule;   /**< NEWTON: default DK_ARAP_CG_FIXED              */
    int predict;                       /**< warm starts may extrapolate along the drag
                                            (the secant of the last two solutions, see
                                            dk_arap_solve); 0 or 1, default 1             */
    dk_arap_basis basis;               /**< default DK_ARAP_BASIS_AUTO                    */
    int levels;                        /**< the multi-scale solve (docs/methods/arap.md,
                                            "Multi-scale"): 1 the mesh alone; L > 1 adds
                                            L - 1 coarse levels, each with 1/16 of the
                                            vertices of the one above (dk_decimate, every
                                            vertex's handle, fixed or free role kept), of at
                                            least 16 vertices; 0 (the default): automatic,
                                            a coarse level from 100,000 unknowns on. A cold
                                            start (no previous solution, or asked cold)
                                            solves the coarsest level first and starts each
                                            finer one from the prolonged result; in cold
                                            and given solves (NEWTON) each Newton step near
                                            the minimum is followed by the coarse level's
                                            correction (its Newton direction for the
                                            restricted gradient, prolonged, line-searched);
                                            warm solves take none. The answer is still the
                                            mesh's minimum. Not used by
                                            dk_arap_bind_tetrahedra (a volume's cells: its
                                            caller attaches a level of its own,
                                            dk_arap_attach_coarse_level). 0..8 */
    dk_arap_iteration_fn on_iteration; /**< optional, NULL by default                     */
    void *user;                        /**< passed to on_iteration                        */
    dk_phase_progress_fn progress;     /**< bind progress (dk_progress.h), NULL by default:
                                            called with the phases renumber, cells,
                                            constraints, system, assemble, analyze,
                                            factorize, basis (the response basis), and
                                            "done" at 1; a non-zero return
                                            cancels the bind (DK_ERR_CANCELLED, nothing
                                            leaked). Asked between phases and every few
                                            thousand steps of the long loops; not during
                                            CHOLMOD's analysis and factorization, which
                                            cannot be interrupted. For the bind only: the
                                            object does not keep it                       */
    void *progress_user;               /**< passed to progress                            */
} dk_arap_options;

typedef struct dk_arap dk_arap;

/** Fills the defaults above. */
void dk_arap_default_options(dk_arap_options *options);

/** Binds: validates the constraints (dk_constraints_create), builds the cells, assembles the
 *  reduced matrix and factors it. Refuses a reduced matrix that is not positive definite
 *  (DK_ERR_DEGENERATE: degenerate triangles or negative cotangent weights) and bad
 *  constraints or options (naming the vertex, group or option). Accepts: non-manifold edges
 *  (a spoke sums the half-cotangents of all its triangles), a connected component or
 *  isolated vertex without any constraint (held at rest, counted in the stats), no free
 *  vertex at all (a solve returns the constrained motion). `options` may be NULL
 *  (defaults). The mesh must outlive the object. */
dk_status dk_arap_bind(const dk_mesh *mesh, const dk_constraint_desc *constraints,
                       const dk_arap_options *options, dk_arap **out, dk_error *err);

/** dk_arap_bind for a volume (the slides' volume-based deformation): one cell per
 *  tetrahedron, the energy sum_t s_t vol_t |F_t - R_t|^2 (F_t = D_s D_m^-1 the element's
 *  deformation gradient, s_t the mean stiffness of its corners) plus the soft penalties.
 *  Each cell holds the tetrahedron's six edges weighted by the linear element's stiffness
 *  (|e| cot(dihedral angle at the opposite edge) / 6), exactly (nothing is clamped: a
 *  cell's sum is >= 0 whatever its signs). mesh: its vertices are the points (the
 *  surface's and the interior's), its triangles the tetrahedra's faces and any others: the
 *  triangles none of whose corners is in a tetrahedron (a part of the mesh that bounds no
 *  volume) give their vertices surface cells as dk_arap_bind does, with options.energy and
 *  options.weights, in the same solve; all of them give the locality order and the
 *  connected components (dk_constraints.h). tetrahedra: n_tetrahedra x 4 vertex indices,
 *  four distinct per row, in either orientation; a degenerate one weighs nothing.
 *  Everything else -- constraints, solves, starts, state -- as for a surface. */
dk_status dk_arap_bind_tetrahedra(const dk_mesh *mesh, const dk_index *tetrahedra,
                                  dk_index n_tetrahedra, const dk_constraint_desc *constraints,
                                  const dk_arap_options *options, dk_arap **out, dk_error *err);

/** Replaces the constraints. The cells are kept; the reduced matrix is reassembled and
 *  refactored, reusing the symbolic analysis when the set of unknown vertices is unchanged
 *  (for example only the handle groups, their weights or the stiffness changed). On failure
 *  the object keeps its previous constraints. The previous solution stays as warm start. */
dk_status dk_arap_rebind(dk_arap *arap, const dk_constraint_desc *constraints, dk_error *err);

/** The progress callback of the following rebinds (NULL: none, as after bind): the phases
 *  constraints, system, assemble, analyze (skipped when the analysis is reused), factorize,
 *  basis, then "done" at 1. A non-zero return cancels the rebind with DK_ERR_CANCELLED, and
 *  the object keeps its previous constraints, factor, basis, counters and warm start
 *  exactly; a cancellation at the basis after the analysis was reused refactors the
 *  previous values (the factorization's time) to give the analysis back. */
void dk_arap_set_progress(dk_arap *arap, dk_phase_progress_fn progress, void *user);

/** Solves for the handle targets of `request` (dk_method.h). Starts (request->start):
 *  DK_START_WARM from the previous solution when there is one, plus the global step's
 *  response (previous rotations held) to how far the constrained vertices moved since. With
 *  the `predict` option, when the ends of the last two calls for different targets (x1 = the
 *  previous solution for t1, x2 for t2; converged or not) show a drag direction, a second
 *  start is built from the base x1 + alpha (x1 - x2), alpha = the projection of t - t1 on
 *  t1 - t2 clamped to [0, 2] (<= 0, a reversed drag: no second start), and the start with
 *  the lower energy is used (info.predicted says which). DK_START_COLD, and WARM without a
 *  previous solution: from the global step with all rotations = identity, i.e. naive
 *  Laplacian editing. DK_START_RESUME: when the targets equal the previous call's and that
 *  call ended normally, iterations continue exactly where it stopped (Anderson history
 *  included), so a solve cut into slices by `max_iterations` gives the same result as one
 *  long solve; otherwise as WARM. DK_START_GIVEN: from request->start_positions (checked
 *  finite before anything changes), eliminated vertices put at their targets (hard
 *  handles) or rest (fixed), the local step's rotations from identities: the result
 *  depends on the request alone, and the drag history starts again, as after COLD (the
 *  use: a coarse level's converged result prolonged to this mesh, a cached frame's result;
 *  docs/methods/arap.md, "A given start"). request->input_positions (DK_METHOD_EDITS_INPUT):
 *  the pose to edit, in place of the rest: its edges are the cells' rest edges (and the
 *  right-hand side's vectors), fixed and held vertices stay at it, and transforms act on it;
 *  the bind's weights and factor are kept, so a new pose costs one pass over the cells and
 *  no factorization (the result's energy, measured by an ARAP bound on the pose, is within
 *  0.1-5.5% of that bind's minimum on a tube bent 20-90 degrees by a two-part blend: the
 *  blend's sheared triangles have other cotangent weights). A request without it edits the
 *  rest again. request->preview: the start alone, no iterations
 *  (info.iterations 0): with the response basis (dk_arap_basis) an O(n) combination, the
 *  predicted start chosen over the plain one by the energies of a fixed sample of cells
 *  (~16k), and the start's local step left to the solve that resumes it (or done when the
 *  energy is asked for). request->max_iterations > 0 overrides the option for this
 *  call; the energy is always reported (it costs nothing extra). Writes `positions`
 *  (n_vertices x 3, row-major) and `info` (may be NULL): energy E of the returned positions
 *  (with their optimal rotations), iterations (local/global iterations or Newton steps),
 *  converged (the stopping test of dk_arap_options.tolerance held), rejected (accelerated
 *  steps rejected by the safeguard; Newton: steps whose line search failed, replaced by a
 *  local/global step), predicted, cg_iterations (Newton: Hessian products in all).
 *  Allocation-free. */
dk_status dk_arap_solve(dk_arap *arap, const dk_solve_request *request, double *positions,
                        dk_solve_info *info, dk_error *err);

/** Changes the stopping tolerance (>= 0, see dk_arap_options) for the following solves, e.g.
 *  a loose one while dragging and a tight one when the user lets go; the warm start is kept. */
dk_status dk_arap_set_tolerance(dk_arap *arap, double tolerance, dk_error *err);

/** Attaches a coarse level its caller built (VolumetricARAP's coarse tetrahedra, see
 *  docs/methods/volumetric_arap.md "Multi-scale"), used as options.levels' own are: a cold
 *  start solves it first and starts from its result prolonged (the move from the pose
 *  restricted: x = pose + P (y - R pose)), and, when `correct` is non-zero, cold and given
 *  Newton solves follow each Newton step near the minimum by its correction (the gradient
 *  restricted by P^T, the coarse Newton direction, prolonged by P, line-searched); the
 *  answer is still this object's minimum. coarse: an ARAP object bound on the coarse points (n_c of them) with
 *  this object's constraints restricted; borrowed (it must outlive the attachment, which
 *  lasts until the next rebind or free; no other object may use it meanwhile; rebound
 *  meanwhile, the level is skipped; one that has this object as its own level is refused).
 *  handle_vertex (n_handle_vertices, the coarse object's handle vertices in its handle
 *  groups' order): the vertex of this object each stands for (same handle; its target is
 *  that vertex's). P: n_vertices rows (p_start n_vertices + 1, p_col and p_weight
 *  p_start[n_vertices]) over the coarse points; R, the restriction of positions: n_c rows
 *  (r_start, r_col, r_weight) over this object's vertices. All in caller numbering, copied.
 *  Refuses (nothing changed) counts that differ, a vertex that is not a handle vertex, rows
 *  out of range or weights not finite. Replaces a level options.levels built. */
dk_status dk_arap_attach_coarse_level(dk_arap *arap, dk_arap *coarse,
                                      const dk_index *handle_vertex,
                                      dk_index n_handle_vertices, const dk_index *p_start,
                                      const dk_index *p_col, const double *p_weight,
                                      const dk_index *r_start, const dk_index *r_col,
                                      const double *r_weight, int correct, dk_error *err);

/** The stopping tolerance the next solve uses (NaN for NULL). */
double dk_arap_tolerance(const dk_arap *arap);

/** Conjugate-gradient iterations (Hessian products) per Newton step for the following
 *  solves: 1..100, or 0 for the bound options.cg_iterations again (the other accelerations
 *  ignore it). Fewer make a step cheaper and less complete (still a descent step with the
 *  same line search, and the same stopping test, which looks only at the first CG iterate).
 *  The add-on fits its interactive slices to a time budget with it: one step of a few
 *  products where a full step (12) would take ~50 ms on the armadillo, 100-250 ms on a
 *  loaded machine (docs/methods/arap.md, "Interactive slices"). After a cut step (fewer
 *  than the bound count) the stopping test does not end the solve until a whole step has
 *  been taken: cut steps, like local/global ones, leave the slow bending modes, where the
 *  test's local/global prediction is small while the minimum is still away (measured:
 *  1.3e-4 of E above it on a bent grid), so a solve of cut steps only reports converged
 *  only for a rigid motion or when E stops decreasing. A solve resumed (DK_START_RESUME)
 *  with another count continues from where the previous call stopped, so slices of
 *  different counts end, converged, at a point the same test accepts after a whole step,
 *  not bit for bit where one uninterrupted solve would. A count given here is run as given
 *  (options.cg_schedule scales only the bound count, 0). The warm start is kept. */
dk_status dk_arap_set_cg_iterations(dk_arap *arap, int cg_iterations, dk_error *err);

/** The ARAP energy E of arbitrary positions (n_vertices x 3) with their optimal rotations,
 *  including the soft-handle penalties for the targets of the last solve (none before the
 *  first solve), into `energy` (NaN on failure). Independent of the solver state otherwise.
 *  Allocates an n x 3 scratch copy. */
dk_status dk_arap_energy(const dk_arap *arap, const double *positions, double *energy,
                         dk_error *err);

/** The constraints, in the object's internal vertex numbering (a locality order, see
 *  dk_reorder.h): read their counts, not their vertex lists. */
const dk_constraints *dk_arap_constraints(const dk_arap *arap);

/** The contract's counters (dk_method.h); zeros for NULL. */
void dk_arap_stats(const dk_arap *arap, dk_method_stats *stats);

/** ARAP's own counters. */
typedef struct dk_arap_counters {
    int basis_columns; /**< columns of the response basis (4 per handle), 0 when not built */
    int basis_starts;  /**< warm starts since bind that combined it instead of substituting */
    int levels;        /**< levels of the multi-scale solve: 1 (the mesh alone) or more    */
    dk_index coarse_vertices[7]; /**< vertices of each coarse level, finest first (levels-1) */
    int coarse_starts; /**< cold starts from the coarse level since the last bind/rebind  */
    int coarse_corrections; /**< coarse corrections taken since the last bind/rebind     */
} dk_arap_counters;

/** Fills `counters` (zeros for NULL). */
void dk_arap_get_counters(const dk_arap *arap, dk_arap_counters *counters);

/** The response basis (dk_arap_basis) as the linear map it is, in the caller's vertex
 *  numbering, into `out` (n_vertices x 4 n_handles, row-major): column 4h + j of vertex v is
 *  the move of v in the global step (rotations held) per unit of handle h's affine
 *  coordinate j (x, y, z of the rest position, or 1), so that for handles moved from
 *  transforms T0_h to T_h (4x4 each)
 *      x_v = x0_v + sum_{h,j} out[v][4h + j] (T_h - T0_h)[0..2][j]
 *  is a warm start from x0 without its rotations (the plain one, dk_arap_solve). Hard handle
 *  vertices get their own coordinates (so they land on their targets exactly), fixed ones 0.
 *  Read-only and cheap next to a solve: a caller can show such an update while another
 *  thread solves (the add-on does, on meshes whose solves outlast a drag event).
 *  DK_ERR_INVALID_ARGUMENT when the basis was not built (stats: basis_columns 0). */
dk_status dk_arap_response_basis(const dk_arap *arap, double *out, dk_error *err);

/** Frees; NULL allowed. */
void dk_arap_free(dk_arap *arap);

/** State (dk_method_ops.state_size, dk_method.h): the bytes save_state writes, what the
 *  solves leave behind (the iterate, its rotations, the drag history, a resumable solve's
 *  place, the pose and targets last solved), so that a restored object -- this one or
 *  another bound on the same mesh with the same constraints and options -- continues bit
 *  for bit as this one would. About 50 doubles per vertex. */
size_t dk_arap_state_size(const dk_arap *arap);

/** Writes the state into `state` (exactly dk_arap_state_size bytes). */
dk_status dk_arap_save_state(const dk_arap *arap, void *state, size_t size, dk_error *err);

/** Puts back a state dk_arap_save_state wrote (`size` bytes); a state of another method,
 *  mesh size, constraints or acceleration is DK_ERR_INVALID_ARGUMENT and changes nothing. */
dk_status dk_arap_restore_state(dk_arap *arap, const void *state, size_t size, dk_error *err);

/** The bytes a bind needs at its peak, its first solve included (dk_method.h,
 *  dk_method_estimate_memory): the factor of the n-unknown system (fill ~ n log n). `options`
 *  (may be NULL) changes nothing. DK_ERR_INVALID_ARGUMENT for a NULL mesh or bytes. */
dk_status dk_arap_estimate_memory(const dk_mesh *mesh, const dk_arap_options *options,
                                  uint64_t *bytes, dk_error *err);

/** ARAP's table of the method contract (dk_method.h); options are a dk_arap_options. */
extern const dk_method_ops dk_arap_ops;

#ifdef __cplusplus
}
#endif
#endif
