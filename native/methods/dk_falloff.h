/* DeformKit: attenuated handle displacement ("falloff", lecture slides 5-7).
 *
 * The handle's displacement is propagated to nearby vertices, attenuated by
 *     S(i) = 1 - (i / (n + 1))^(k + 1)        for k >= 0   (k = 0: linear; k > 0: "rigid")
 *     S(i) = (1 - i / (n + 1))^(1 - k)        for k < 0    ("elastic")
 * with i the distance of the vertex from the handle and n the range; vertices with i > n are
 * not affected (S = 0 there, as in the slides: the range is "the vertices within n edges").
 *
 * Distances (the slides leave the units of i and n to the distance kind):
 *   HOPS       edge hops (dk_hop_distance); i and n are counted in edges.
 *   EUCLIDEAN  straight-line distance to the nearest handle vertex of the group (k-d tree);
 *   GEODESIC   heat-method distance (dk_heat_distance);
 *   DIJKSTRA   shortest path along edges (dk_geodesic_dijkstra).
 *   For the three metric kinds `range` is a length and the formula is applied in units of
 *   the mesh's mean edge length h ("one hop"): i = d / h, n = range / h, so that
 *   S(d) = 1 - (d / (range + h))^(k+1) etc. This keeps the slides' "+1" meaningful and the
 *   profile independent of the model's scale.
 *
 * Which displacement is attenuated (the slides have one seed vertex; with a handle group of
 * several vertices there is a choice). Per handle group g:
 *   targets (mode 0): vertex v moves by S(d_g(v)) * D_g(l), where D_g(l) = w_l (c_l - p_l)
 *     is the (weighted) displacement of l, v's nearest vertex of group g. "Nearest" is in
 *     the chosen distance, except for GEODESIC where the heat method yields distances only:
 *     l is then the nearest vertex along edges (Dijkstra) and d the heat distance. Ties in
 *     the distance (frequent with hops) go to the handle vertex closer in straight line,
 *     then to the lower position in the handle list.
 *   transforms (mode 1): vertex v moves by S(d_g(v)) * w_l * (T_g p_v - p_v), i.e. the
 *     transform is blended into the identity by S (p' = p + S (T p - p)), the natural
 *     generalisation; w_l is the handle weight of the same nearest vertex l, so that for a
 *     pure translation both modes agree exactly.
 *   Several groups: their displacements are summed (each group's influence is its own
 *   falloff; overlapping ranges add up, as stacked Blender hooks do).
 * Handle vertices move by w (c - p) (per-vertex handle weight w in (0,1], as Blender's hook
 * weights); they receive no falloff from other groups. Fixed vertices and vertices outside
 * the region of interest stay at rest. Vertices unreachable from a group (another
 * component) are not affected by it. A mesh where every vertex is constrained is accepted
 * (the result is the handle targets).
 *
 * It is a direct method: iterations = 1, converged = 1, and the reported energy is the sum
 * over all vertices of the squared displacement |p'_v - p_v|^2.
 */
#ifndef DK_FALLOFF_H
#define DK_FALLOFF_H

#include "dk_constraints.h"
#include "dk_mesh.h"
#include "dk_method.h"
#include "dk_progress.h"
#include "dk_status.h"

#ifdef __cplusplus
extern "C" {
#endif

/** Distance used for the attenuation. */
typedef enum dk_falloff_distance {
    DK_FALLOFF_HOPS = 0,
    DK_FALLOFF_EUCLIDEAN = 1,
    DK_FALLOFF_GEODESIC = 2, /**< heat method                                              */
    DK_FALLOFF_DIJKSTRA = 3  /**< exact shortest paths along edges                         */
} dk_falloff_distance;

/** How far each handle group's pull reaches. */
typedef enum dk_falloff_reach {
    DK_FALLOFF_REACH_RANGE = 0, /**< `range`, for every group                               */
    DK_FALLOFF_REACH_FIXED = 1  /**< per group, its distance (in the chosen kind) to the
                                     nearest fixed vertex: the pull fades out exactly where
                                     the fixed part begins, whatever the model's size and
                                     edge density. A group that reaches no fixed vertex
                                     uses `range`                                         */
} dk_falloff_reach;

/** Options; fill with dk_falloff_default_options. */
/** The range a bind takes for `range` = 0, as a fraction of the mesh's bounding-box diagonal:
 *  10 hops, the earlier default, were ~7 cm on a 1 m model of 43k vertices, and the arm of
 *  the README's image became a stretched tube. */
#define DK_FALLOFF_AUTO_RANGE 0.25

typedef struct dk_falloff_options {
    dk_falloff_distance distance; /**< default EUCLIDEAN                                    */
    double range;                 /**< n: > 0 (hops: edges; else a length). Default 0, which
                                       means DK_FALLOFF_AUTO_RANGE of the bounding-box
                                       diagonal (hops: that over the mean edge length, at
                                       least 1)                                           */
    dk_falloff_reach reach;       /**< default FIXED (a group that reaches no fixed vertex,
                                       or a bind without one, uses `range`)               */
    double k;                     /**< exponent parameter, finite; default 0 (linear)      */
    double heat_time_factor;      /**< GEODESIC: dk_heat_create's factor (<= 0: default)    */
    dk_phase_progress_fn progress; /**< bind progress (dk_progress.h), NULL by default: the
                                        phases heat (GEODESIC only: the heat method's
                                        factorization, uninterruptible) and distances
                                        (asked between handle groups and every 8192
                                        vertices of each group's labelled search), then
                                        "done" at 1; a non-zero return cancels the bind
                                        (DK_ERR_CANCELLED, nothing leaked). For the bind
                                        only: the object does not keep it              */
    void *progress_user;          /**< passed to progress                                  */
} dk_falloff_options;

typedef struct dk_falloff dk_falloff;

/** Writes the defaults into `options`. */
void dk_falloff_default_options(dk_falloff_options *options);

/** The profile S(i) for distance i >= 0 and range n >= 0 (both in hop units), exponent k:
 *  the formula above, 0 for i > n or a non-finite i. */
double dk_falloff_profile(double i, double n, double k);

/** Computes the distances from every handle group and the weights S. `mesh` is borrowed and
 *  must outlive the object; `options` may be NULL (defaults). Refuses invalid options
 *  (naming them) and invalid constraints (dk_constraints_create's messages). */
dk_status dk_falloff_bind(const dk_mesh *mesh, const dk_constraint_desc *desc,
                          const dk_falloff_options *options, dk_falloff **out, dk_error *err);

/** New constraints, same mesh and options (the heat-method factorization is reused). On
 *  failure the object keeps its previous constraints. */
dk_status dk_falloff_rebind(dk_falloff *f, const dk_constraint_desc *desc, dk_error *err);

/** The progress callback of the following rebinds (NULL: none, as after bind): the phase
 *  distances, then "done" at 1. A non-zero return cancels the rebind with DK_ERR_CANCELLED,
 *  and the object keeps its previous constraints and weights. */
void dk_falloff_set_progress(dk_falloff *f, dk_phase_progress_fn progress, void *user);

/** Deformed positions (n x 3) for the handle targets of `request` (dk_method.h; a direct
 *  method: start and max_iterations change nothing). With request->input_positions the
 *  displacements are taken from that pose and added to it: the falloff weights stay the
 *  bind's (distances on the rest). `info` (may be NULL): energy = the sum of squared
 *  displacements, iterations = converged = 1. Allocation-free. */
dk_status dk_falloff_solve(dk_falloff *f, const dk_solve_request *request, double *positions,
                           dk_solve_info *info, dk_error *err);

/** The sum over all vertices of |positions - rest|^2 (n_vertices x 3), into `energy`: the
 *  energy a solve reports. */
dk_status dk_falloff_energy(const dk_falloff *f, const double *positions, double *energy,
                            dk_error *err);

/** The distance (in the chosen kind's units; INFINITY when unreachable) and weight S of
 *  vertex v from handle group g, as computed at bind; for tests. Out-of-range arguments
 *  give INFINITY and 0. */
void dk_falloff_vertex_weight(const dk_falloff *f, dk_index g, dk_index v, double *distance,
                              double *weight);

/** The range handle group g uses (the distance kind's units: edges for hops), as chosen
 *  at bind (`range`, or with REACH_FIXED its distance to the fixed part); NaN for an
 *  out-of-range g. */
double dk_falloff_group_range(const dk_falloff *f, dk_index g);

/** The contract's counters (dk_method.h); zeros for NULL. */
void dk_falloff_stats(const dk_falloff *f, dk_method_stats *stats);

/** Frees; NULL allowed. */
void dk_falloff_free(dk_falloff *f);

/** The bytes a bind needs at its peak, its first solve included (dk_method.h,
 *  dk_method_estimate_memory): a few arrays per vertex. `options` (may be NULL) changes
 *  nothing. DK_ERR_INVALID_ARGUMENT for a NULL mesh or bytes. */
dk_status dk_falloff_estimate_memory(const dk_mesh *mesh, const dk_falloff_options *options,
                                     uint64_t *bytes, dk_error *err);

/** Falloff's table of the method contract (dk_method.h); options are a dk_falloff_options. */
extern const dk_method_ops dk_falloff_ops;

#ifdef __cplusplus
}
#endif
#endif
