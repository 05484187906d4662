/* DeformKit: skinning (the lecture slides' "Skinning": skeletal subspace deformation, linear
 * blend skinning), with dual quaternion skinning as the option that does not collapse.
 *
 * The control (dk_controls.h, DK_CONTROL_BONES): each bone's rest frame B_j (4x4 affine)
 * and the weights w_ij (n_vertices x n_bones, >= 0, rows summing to 1). A solve gives each
 * bone's current frame T_j (request targets, transforms: n_bones 4x4); bone j moves the
 * mesh by M_j = T_j B_j^-1, and
 *   LINEAR           p'_i = sum_j w_ij M_j p_i                        (the slides' formula)
 *   DUAL_QUATERNION  each M_j = [R_j S_j | t_j] (polar: R_j the rotation closest to its
 *                    linear part, S_j = R_j^T A_j the stretch); the rigid parts blended as
 *                    unit dual quaternions (Kavan, Collins, Zara, O'Sullivan 2008: each
 *                    bone's sign taken on the side of the vertex's heaviest bone, the blend
 *                    normalised), the stretches blended linearly and applied first:
 *                    p'_i = DQ(sum_j w_ij q_j) (sum_j w_ij S_j) p_i. A bone twisted half a
 *                    turn against its neighbour keeps the limb's girth where LINEAR
 *                    collapses it to its axis (the candy wrapper).
 * Both give M p exactly where every bone of a vertex moves alike, and a bone's own motion
 * where its weight is 1; the rest frames as targets give the mesh back bit for bit. The
 * weights are stored sparsely (the non-zero ones of each vertex); a solve is one pass over
 * them, allocation-free. It edits the pose it is given (input_positions: that pose is
 * skinned instead of the rest). Direct: iterations 1; the energy reported is the squared
 * displacement.
 */
#ifndef DK_SKINNING_H
#define DK_SKINNING_H

#include "dk_bbw.h"
#include "dk_constraints.h"
#include "dk_controls.h"
#include "dk_mesh.h"
#include "dk_method.h"
#include "dk_progress.h"
#include "dk_status.h"

#ifdef __cplusplus
extern "C" {
#endif

typedef enum dk_skinning_blend {
    DK_SKINNING_LINEAR = 0,         /**< linear blend skinning (default)                    */
    DK_SKINNING_DUAL_QUATERNION = 1 /**< dual quaternion skinning, stretch blended linearly */
} dk_skinning_blend;

typedef struct dk_skinning_options {
    dk_skinning_blend blend;       /**< default LINEAR                                     */
    dk_bbw_options computed;       /**< weights computed from the bones' segments (no
                                        weights given): bounded biharmonic weights, these
                                        options (dk_bbw_default_options; its progress
                                        fields are ignored: the bind reports)             */
    dk_phase_progress_fn progress; /**< bind progress (phase "weights"), NULL: none        */
    void *progress_user;
} dk_skinning_options;

typedef struct dk_skinning dk_skinning;

void dk_skinning_default_options(dk_skinning_options *options);

/** Binds `mesh` (borrowed) to the bones `constraints->control` (DK_CONTROL_BONES, checked by
 *  dk_control_check: invertible rest frames, non-negative weights summing to 1 per vertex,
 *  or instead of weights each bone's segment, from which the bind computes bounded
 *  biharmonic weights (phase "computed weights", options->computed); no handles, fixed
 *  vertices or region). */
dk_status dk_skinning_bind(const dk_mesh *mesh, const dk_constraint_desc *constraints,
                           const dk_skinning_options *options, dk_skinning **out,
                           dk_error *err);

/** Other bones (frames and weights) for the same mesh and options; on failure nothing
 *  changes. */
dk_status dk_skinning_rebind(dk_skinning *s, const dk_constraint_desc *constraints,
                             dk_error *err);

/** `request->targets`: the bones' current frames (n_bones 4x4 row-major, target_kind
 *  transforms; affine, finite). Writes n_vertices x 3 positions; allocation-free. */
dk_status dk_skinning_solve(dk_skinning *s, const dk_solve_request *request,
                            double *positions, dk_solve_info *info, dk_error *err);

/** The sum over the vertices of |positions - rest|^2. */
dk_status dk_skinning_energy(const dk_skinning *s, const double *positions, double *energy,
                             dk_error *err);

void dk_skinning_stats(const dk_skinning *s, dk_method_stats *stats);

/** The bones' rest frames (n_bones 4x4 row-major), owned by the object. */
const double *dk_skinning_rest_frames(const dk_skinning *s);

void dk_skinning_free(dk_skinning *s);

/** Peak bytes of a bind: four influences a vertex (the bind checks its own). */
dk_status dk_skinning_estimate_memory(const dk_mesh *mesh, const dk_skinning_options *options,
                                      uint64_t *bytes, dk_error *err);

extern const dk_method_ops dk_skinning_ops;

#ifdef __cplusplus
}
#endif

#endif
