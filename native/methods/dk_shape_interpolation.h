/* DeformKit: shape interpolation that keeps the shape (the lecture slides' "Deformation
 * Types": creating the in-betweens of poses is a deformation, and shape space is not linear).
 * In-betweens of example poses of one mesh (same vertices and triangles): each triangle's
 * deformation gradient from the rest to each pose is split into a rotation and a stretch
 * (Alexa, Cohen-Or, Levin 2000, for simplices), those are blended separately, and the
 * positions follow from the blended gradients in the least-squares sense (the gradient-domain
 * or Poisson form of Xu, Zhou, Wang, Ding, Guo 2005, as for surfaces).
 *
 * Per triangle t with rest corners p0, p1, p2 (frame V = [p1 - p0, p2 - p0, n / sqrt|n|],
 * n = (p1 - p0) x (p2 - p0), the normal scaled so that the frame scales like the triangle)
 * and its frame V_k in pose k, the gradient J_k = V_k V^-1 maps the rest edges onto the
 * pose's, and J_k = R_k S_k (polar: R_k the closest rotation, S_k = sym(R_k^T J_k)). For
 * weights w (one per pose; the rest has weight 1 - sum w, as Blender's relative shape keys):
 *     R(w) = exp(sum_k w_k omega_k) exp(sum_k w_k eps_k),    S(w) = I + sum_k w_k (S_k - I),
 *     J(w) = R(w) S(w),
 * (stretches LOG: S(w) = exp(sum_k w_k log S_k), which keeps det S(w) = prod det(S_k)^w_k:
 * a shear that keeps a triangle's area keeps it half way, where the linear blend of the
 * paper inflates it -- by 6% for a shear of 45 degrees -- but a bend, whose stretches are
 * linear in its angle, is exact only with the linear blend)
 * omega_k a rotation vector of R_k (angle times axis, the angle not limited to pi: see
 * rotations) and eps_k = log(exp(omega_k)^T R_k) its residual (0 where omega_k represents R_k
 * exactly), so that J(e_k) = J_k exactly and J(0) = I, and w -> J(w) is smooth: extrapolation
 * (weights outside [0, 1]) and several poses at once (a blend) follow the same formula (the
 * "linear combination of transformations" of Alexa 2002). A rigid motion R x + t between the
 * rest and a pose gives every triangle the same R and S = I: each in-between is the rigid
 * motion exp(w log R) (the shape is kept), where the linear blend shrinks it.
 *
 * Rotations beyond 180 degrees (rotations CONSISTENT, the default): the rotation vectors are
 * lifted across the mesh (lift.c): between neighbouring triangles p, c the relative rotation
 * R_c R_p^T is small, its vector delta_pc counts the turn without ambiguity, and omega_k is
 * the field closest to those steps in the least-squares sense (a graph Laplacian on the
 * triangles, factored once per bind), fixed at one root per connected group of triangles to
 * the root's own vector: a triangle touching a handle or fixed vertex if there is one (a part
 * pinned there does not turn), else the least turned one. eps carries what omega does not
 * represent exactly. A bar twisted by 360 degrees then keeps its twist half way (180 degrees
 * at its end) instead of untwisting. PRINCIPAL takes each rotation's own angle in [0, pi] (a
 * part turned by more than 180 degrees unwinds the short way, and a twist of 360 degrees has
 * no interpolation at all): for comparison.
 *
 * Positions: the least-squares fit of every edge (i, j) to its blended gradient,
 *     E(x) = sum_edges c_ij |x_i - x_j - Jbar_ij (p_i - p_j)|^2,
 * Jbar_ij the mean gradient of the edge's non-degenerate triangles, c_ij the edge weights
 * (clamped cotangent by default: the discrete Poisson equation L x = div J of Xu et al.; each
 * weight at least 1e-6 of the mean, so that every edge connects). The normal equations are
 * one prefactored sparse system over the unconstrained vertices (a Cholesky factor from the
 * bind), so an in-between is one pass over the triangles and one back-substitution. At a pose
 * every edge's target is its own edge in the pose: the pose is the exact minimiser.
 * The blended rotations of neighbouring triangles need not be those of any one shape (where
 * a turn beyond pi meets a tilt: a bar twisted by 360 degrees); the least-squares positions
 * then lose some size there (the stout bar of the tests narrows to 0.89 of its radius half
 * way). `refine` local/global iterations (as-rigid-as-possible, with each triangle's blended
 * stretch P kept: J = U P, U the rotation that best takes the triangle's stretched rest
 * edges P r onto its edges in the positions, then the positions again from the same factor)
 * even that out (4 iterations: within 3% along the bar); the poses, the rest and rigid
 * motions stay exact, since their gradients are already those of their positions. With an
 * input, P is the stretch of A R(w) S(w). Each iteration costs about twice the blend.
 * Handles and fixed vertices (optional vertex groups beside the poses) are kept exactly
 * (fixed at the input, handles at their targets), so an in-between can be pinned. A part of
 * the mesh without any is placed by its vertices' mean: the linear blend's (the input's mean
 * plus sum_k w_k times pose k's mean displacement).
 *
 * An input pose (request->input_positions, an Armature's pose: DK_METHOD_EDITS_INPUT) is
 * edited as if it were the rest: each triangle's blended gradient is applied after the
 * input's own, J = A J(w) with A = V_in V^-1 the input's gradient, so zero weights return the
 * input and an input that turns a part turns its in-betweens with it. The poses stay the
 * bind's (example shapes of the rest).
 *
 * Bound without poses the method is gradient-domain editing of the rest by its handles (the
 * rest's gradients kept, not turned; at least one handle vertex, and loose parts held at
 * rest as by every method, dk_constraints.h). Targets of a solve: one weight per pose, then the
 * handles' targets (positions or transforms, dk_method.h) when there are handles. Zero
 * weights with every handle at its input return the input bit for bit. Direct: iterations 1;
 * the energy reported is E at the returned positions.
 */
#ifndef DK_SHAPE_INTERPOLATION_H
#define DK_SHAPE_INTERPOLATION_H

#include "dk_constraints.h"
#include "dk_mesh.h"
#include "dk_method.h"
#include "dk_progress.h"
#include "dk_status.h"

#ifdef __cplusplus
extern "C" {
#endif

/** How each pose's rotations are represented (see above). */
typedef enum dk_shape_interpolation_rotations {
    DK_SI_ROTATIONS_CONSISTENT = 0, /**< branches chosen across the mesh (default)          */
    DK_SI_ROTATIONS_PRINCIPAL = 1   /**< each rotation's angle in [0, pi]                   */
} dk_shape_interpolation_rotations;

/** The edge weights c_ij of the fit. */
typedef enum dk_shape_interpolation_weights {
    DK_SI_WEIGHTS_CLAMPED_COTANGENT = 0, /**< cotangent, negative ones set to 0 (default)   */
    DK_SI_WEIGHTS_COTANGENT = 1,         /**< cotangent as they are (a mesh with many obtuse
                                              angles may have no factor: refused by name)  */
    DK_SI_WEIGHTS_UNIFORM = 2            /**< 1 for every edge                             */
} dk_shape_interpolation_weights;

/** How each pose's stretches are blended (see above). */
typedef enum dk_shape_interpolation_stretches {
    DK_SI_STRETCHES_LINEAR = 0, /**< I + sum w_k (S_k - I), Alexa et al.'s (default): exact
                                     for a bend (a limb's inside and outside stretch
                                     linearly with its angle)                              */
    DK_SI_STRETCHES_LOG = 1     /**< exp(sum w_k log S_k): keeps a triangle's area under a
                                     shear that keeps it (a wide body twisted), where the
                                     linear blend inflates it                              */
} dk_shape_interpolation_stretches;

/** The most refining iterations a bind takes. */
#define DK_SI_MAX_REFINE 100

typedef struct dk_shape_interpolation_options {
    dk_shape_interpolation_rotations rotations;  /**< default CONSISTENT                    */
    dk_shape_interpolation_stretches stretches;  /**< default LINEAR                        */
    int refine;                    /**< local/global iterations after the blend's solve, 0 ..
                                        DK_SI_MAX_REFINE (see above); default 0           */
    dk_shape_interpolation_weights edge_weights; /**< default CLAMPED_COTANGENT             */
    dk_phase_progress_fn progress; /**< bind progress (phases "poses", "analyze",
                                        "factorize"), NULL: none                 */
    void *progress_user;
} dk_shape_interpolation_options;

typedef struct dk_shape_interpolation dk_shape_interpolation;

void dk_shape_interpolation_default_options(dk_shape_interpolation_options *options);

/** Binds the mesh (triangles needed; borrowed), its optional handles and fixed vertices
 *  (`constraints`: handles may be none) and, in constraints->control, the poses
 *  (DK_CONTROL_POSES: n_controls poses, rest n_controls x n_vertices x 3; or no control:
 *  none). Precomputes each pose's rotations and stretches and factors the system. `options`
 *  may be NULL (defaults). Refuses invalid options, a control of another kind and a mesh
 *  without triangles by name. */
dk_status dk_shape_interpolation_bind(const dk_mesh *mesh, const dk_constraint_desc *constraints,
                                      const dk_shape_interpolation_options *options,
                                      dk_shape_interpolation **out, dk_error *err);

/** New handles and fixed vertices, same mesh and options; new poses when constraints->control
 *  gives them (else the bound poses stay). On failure nothing changes. */
dk_status dk_shape_interpolation_rebind(dk_shape_interpolation *s,
                                        const dk_constraint_desc *constraints, dk_error *err);

/** The progress callback of the following rebinds (NULL: none, as after bind); a non-zero
 *  return cancels the rebind (DK_ERR_CANCELLED), the object unchanged. */
void dk_shape_interpolation_set_progress(dk_shape_interpolation *s, dk_phase_progress_fn progress,
                                         void *user);

/** The in-between (n x 3) for request->targets: n_poses weights (finite, |w| <= 1e6), then
 *  the handles' targets (request->target_kind) when there are handles. With
 *  input_positions, the edit of that pose. Allocation-free. */
dk_status dk_shape_interpolation_solve(dk_shape_interpolation *s, const dk_solve_request *request,
                                       double *positions, dk_solve_info *info, dk_error *err);

/** E (above) of `positions` (n x 3) for the last solve's blended gradients (before any
 *  solve: the rest's, so that the rest has energy 0). */
dk_status dk_shape_interpolation_energy(const dk_shape_interpolation *s, const double *positions,
                                        double *energy, dk_error *err);

void dk_shape_interpolation_stats(const dk_shape_interpolation *s, dk_method_stats *stats);

/** The poses bound (n_controls of the stats). */
dk_index dk_shape_interpolation_n_poses(const dk_shape_interpolation *s);

void dk_shape_interpolation_free(dk_shape_interpolation *s);

/** Peak bytes of a bind with four poses and its first solve (the poses add about 200 bytes
 *  per vertex each; a bind with more checks their size before allocating them). */
dk_status dk_shape_interpolation_estimate_memory(const dk_mesh *mesh,
                                                 const dk_shape_interpolation_options *options,
                                                 uint64_t *bytes, dk_error *err);

extern const dk_method_ops dk_shape_interpolation_ops;

#ifdef __cplusplus
}
#endif

#endif
