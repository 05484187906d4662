/* DeformKit: Shepard interpolation of the handles' motion (the lecture slides'
 * "Interpolation": scattered data by inverse distance weighting, Shepard 1968).
 *
 * The data are the constraint groups: each handle group (its value: its motion) and the
 * fixed vertices as one more (no motion). Each is a data point at the distance of its
 * nearest vertex, d_g(x) = min over its vertices |x - v| (Euclidean, on the rest; or along
 * the surface with distance GEODESIC: the heat method's distance from the group, its
 * nearest vertex the one nearest along the edges, dk_labelled_search), and a free vertex x
 * moves by
 *     f(x) = sum_g phi_g(x) f_g(x),   phi_g(x) = w_g(x) / sum_j w_j(x),
 * over its neighbourhood of groups:
 *   ALL      every group, w_g = d_g^-p (the slides' formula; the default);
 *   NEAREST  its k nearest groups, w_g = ((R - d_g)_+ / (R d_g))^p with R the distance to
 *            the (k+1)-th (Franke and Little's weights: they reach 0 at R, so the result
 *            stays continuous where the neighbours change; with k or fewer groups, d^-p);
 *   RADIUS   the groups within `radius` (at most k), w_g = ((R - d_g)_+ / (R d_g))^p,
 *            R = radius; a vertex farther than that from every group stays.
 * Where the sources leave room, the careful engineer's choices: groups, not their single
 * vertices, are the data points (with vertex data points every free vertex takes its k
 * nearest vertices, all of one big group but in a thin band between groups: the result is a
 * step, not a blend), and the cut-off is smooth (a hard cut shows as a seam).
 *
 * What is interpolated (`interpolate`), with l the group's vertex nearest to x and w_l its
 * handle weight:
 *   TRANSFORMS     f_g(x) = w_l (T_g x - x), T_g the handle's transform: Shepard's method
 *                  with linear nodal functions in place of constants, the usual fix for its
 *                  flat spots (each handle's motion continues with its own slope around it;
 *                  a turned handle turns its surroundings). The default. Given positions
 *                  instead of transforms, the solve interpolates displacements.
 *   DISPLACEMENTS  f_g = w_l (target_l - x_l), l's displacement: the slides' formula. For
 *                  p > 1 it is flat at every data point (zero gradient): plateaus around the
 *                  handles, and a bend is not carried.
 * Both interpolate (d_g = 0 gives group g's own value), every weight is >= 0 and they sum
 * to 1, so DISPLACEMENTS stays within the data's displacements. Handle vertices move to their
 * (weighted) targets and fixed ones stay, as in Falloff. Bind computes each free vertex's
 * nearest vertex of every group (a k-d tree per group) and its weights; a solve is a
 * weighted sum, allocation-free. Direct: iterations 1; the energy reported is the sum of
 * squared displacements. Loose geometry is held at rest, as by every method.
 */
#ifndef DK_SHEPARD_H
#define DK_SHEPARD_H

#include "dk_constraints.h"
#include "dk_mesh.h"
#include "dk_method.h"
#include "dk_progress.h"
#include "dk_status.h"

#ifdef __cplusplus
extern "C" {
#endif

typedef enum dk_shepard_neighbourhood {
    DK_SHEPARD_ALL = 0,     /**< every group (default)                                      */
    DK_SHEPARD_NEAREST = 1, /**< the k nearest groups, smooth cut-off                       */
    DK_SHEPARD_RADIUS = 2   /**< the groups within `radius` (at most k)                     */
} dk_shepard_neighbourhood;

typedef enum dk_shepard_distance {
    DK_SHEPARD_EUCLIDEAN = 0, /**< straight through space (default)                         */
    DK_SHEPARD_GEODESIC = 1   /**< along the surface (the heat method; needs triangles): a
                                   part that touches another in space but not along the
                                   surface is not pulled by it                            */
} dk_shepard_distance;

typedef enum dk_shepard_interpolate {
    DK_SHEPARD_TRANSFORMS = 0,    /**< the handles' transforms: no flat spots (default)     */
    DK_SHEPARD_DISPLACEMENTS = 1  /**< the data points' displacements (the slides)          */
} dk_shepard_interpolate;

/** The radius a bind takes for `radius` = 0: this part of the bounding-box diagonal. */
#define DK_SHEPARD_AUTO_RADIUS 0.25

typedef struct dk_shepard_options {
    double power;                          /**< p > 0, at most 64; default 2               */
    dk_shepard_neighbourhood neighbourhood; /**< default ALL                               */
    int k;                                 /**< NEAREST, RADIUS: 1 .. 1024; default 4      */
    double radius;                         /**< RADIUS: a length > 0, 0 = auto
                                                (DK_SHEPARD_AUTO_RADIUS of the diagonal)   */
    dk_shepard_interpolate interpolate;    /**< default TRANSFORMS                         */
    dk_shepard_distance distance;          /**< default EUCLIDEAN                          */
    dk_phase_progress_fn progress;         /**< bind progress (phase "weights"), NULL: none */
    void *progress_user;
} dk_shepard_options;

typedef struct dk_shepard dk_shepard;

void dk_shepard_default_options(dk_shepard_options *options);

/** Computes each free vertex's nearest vertex of every group and its weights. `mesh` is
 *  borrowed; `options` may be NULL (defaults). Refuses invalid options by name. */
dk_status dk_shepard_bind(const dk_mesh *mesh, const dk_constraint_desc *constraints,
                          const dk_shepard_options *options, dk_shepard **out, dk_error *err);

/** New constraints, same mesh and options; on failure nothing changes. */
dk_status dk_shepard_rebind(dk_shepard *s, const dk_constraint_desc *constraints,
                            dk_error *err);

/** The progress callback of the following rebinds (NULL: none, as after bind): the phase
 *  weights; a non-zero return cancels the rebind (DK_ERR_CANCELLED), the object unchanged. */
void dk_shepard_set_progress(dk_shepard *s, dk_phase_progress_fn progress, void *user);

/** Deformed positions (n x 3) for the request's targets (positions, n_handle_vertices x 3,
 *  or transforms, n_handles x 4 x 4); with input_positions the motion is applied to that
 *  pose. Allocation-free. */
dk_status dk_shepard_solve(dk_shepard *s, const dk_solve_request *request, double *positions,
                           dk_solve_info *info, dk_error *err);

/** The sum over the vertices of |positions - rest|^2. */
dk_status dk_shepard_energy(const dk_shepard *s, const double *positions, double *energy,
                            dk_error *err);

void dk_shepard_stats(const dk_shepard *s, dk_method_stats *stats);

/** The groups of the bind: n_handles, plus one for the fixed vertices when there are any
 *  (its index n_handles). */
dk_index dk_shepard_n_groups(const dk_shepard *s);

/** Vertex v's weight of every group (n_groups: handles in order, then the fixed vertices)
 *  and the distance to each group's nearest vertex, as bound; zeros and INFINITY for a
 *  constrained vertex or v out of range. Either output may be NULL. */
void dk_shepard_vertex_weights(const dk_shepard *s, dk_index v, double *weights,
                               double *distances);

void dk_shepard_free(dk_shepard *s);

/** Peak bytes of a bind (a weight, a distance and a nearest vertex per vertex and group,
 *  for a few groups). */
dk_status dk_shepard_estimate_memory(const dk_mesh *mesh, const dk_shepard_options *options,
                                     uint64_t *bytes, dk_error *err);

extern const dk_method_ops dk_shepard_ops;

#ifdef __cplusplus
}
#endif

#endif
