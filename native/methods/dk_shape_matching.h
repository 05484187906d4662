/* DeformKit: physically based deformation by meshless shape matching (Mueller, Heidelberger,
 * Teschner, Gross 2005; the lecture slides' "Physically-based Deformation"), integrated in
 * time with the slides' integrators. A dynamic method: it carries positions and velocities
 * from frame to frame (dk_method_ops.state_size), and each warm solve advances one frame.
 *
 * The points are the mesh's vertices (faces are not needed: meshless). Each vertex has a mass
 * m_i (1, or `masses`). The vertices are grouped into overlapping clusters; vertex i has the
 * share phi_iC of cluster C (its shares sum to 1) and counts with the mass m_i phi_iC in it,
 * so that the clusters' forces add up to no net force and no net torque. The paper's share
 * is 1 / n_i (n_i the clusters of i); that of the automatic cubes is the cube's trilinear hat
 * (1 at its centre, 0 on its faces), so that goals vary continuously across the cubes' faces
 * instead of jumping there (given clusters and whole parts: 1 / n_i). For a cluster C with
 * rest offsets q_i (its vertices in the goal shape, less their mass centre) and current
 * offsets p_i = x_i - x_cm:
 *   RIGID      A_pq = sum m p q^T, R its closest rotation (polar decomposition; for a flat
 *              or straight cluster the rotation that keeps orientation, det R = +1: the
 *              paper's A_pq S^-1 would reflect or be undefined there), goal g_i = R q_i + x_cm;
 *   LINEAR     A the best linear map of det 1 (it keeps the volume): argmin over det A = 1
 *              of sum m |A q - p|^2 (+ the regulariser below); the paper's A_pq A_qq^-1
 *              divided by det^(1/3) keeps it too but is not a minimiser, and its goals
 *              gained energy (volume_fit.c); where the best linear map has det <= 0 the
 *              cluster is inverted and R is used; goal (beta A + (1 - beta) R) q_i + x_cm;
 *   QUADRATIC  q~ = [q, qx^2, qy^2, qz^2, qx qy, qy qz, qz qx] (9; the quadratic terms
 *              less their mass-weighted mean, so that the goals keep x_cm), A~ = A~_pq A~_qq^-1
 *              (3 x 9), R~ = [R 0 0], goal (beta A~ + (1 - beta) R~) q~_i + x_cm: bends and
 *              twists the linear mode cannot.
 * The fits are regularised towards the rotation (a choice the paper leaves open, as it
 * assumes volumetric clusters): A = argmin sum m |A q - p|^2 + lambda |A - R|^2 with lambda =
 * 1e-4 of the mean squared extent per mode (rotation-invariant, scale-free), so that a flat
 * cluster of a surface keeps R across its normal instead of dividing by zero; elsewhere it
 * changes the fit by about 1e-4. A vertex's goal g_i is sum_C phi_iC g_iC.
 *
 * Dynamics, per vertex (k_i = alpha_i / h^2 with h = time_step / substeps the integration
 * step: alpha is the paper's stiffness per step, so that alpha = 1 reaches the goals in one
 * step and more substeps make the same alpha stiffer):
 *   dx/dt = v,   dv/dt = k_i (g_i(x) - x_i) + gravity - d_i (v_i - u_i),
 * u_i the input's velocity over the frame (this frame's goal shape less the last one's, over
 * time_step; 0 on a still mesh, where this is the slides' damping): a part the animation
 * carries is damped against the animation, not dragged behind it through still air.
 * Integrators, for a substep h (dk_shape_matching_integrator):
 *   SEMI_IMPLICIT_EULER (default; the paper's scheme, unconditionally stable for alpha <= 1):
 *       v' = (v + h k (g - x) + h gravity + h d u) / (1 + h d),  x' = x + h v'
 *     (the paper's v + alpha (g - x) / h + h f/m for one step a frame; the damping at the new
 *     velocity, so that no rate flips its sign, where the slides' v_t form does for h d > 1);
 *   EXPLICIT_EULER (the slides' code as written): x' = x + h v, v' = v + h (k (g - x) +
 *     gravity - d (v - u)): gains energy; kept to compare;
 *   IMPLICIT_EULER (backward): v' = v + h (k (g(x') - x') + gravity - d v'), x' = x + h v',
 *     solved by v' (1 + h d + h^2 k) = v + h k (g(x + h v'_old) - x) + h (gravity + d u),
 *     iterated to its fixed point (each pass contracts by at most alpha / (1 + alpha) <=
 *     1/2): damps vibrations, keeps rigid motions, stable for any alpha;
 *   RK4: the classical Runge-Kutta of order 4, the goals evaluated at each stage.
 * Attachment (for secondary motion; not in the paper): a free vertex i with attachment a_i
 * in [0, 1] (the falloff near the kinematic vertices, and a painted map) is also pulled
 * towards y_i(t), where the input puts it at that time (interpolated over the frame), moved
 * as the kinematic vertices near it (at the rest) are moved off the input (by a handle): of
 * each group (a handle, or what follows the input) its nearest vertex, the groups blended by
 * their own falloff weights, so that the place varies continuously; with
 * the stiffness a_i / h^2: its goal becomes (k g + k_a y) / (k + k_a), its stiffness k + k_a,
 * so every integrator treats it alike. A region that follows the rig at its border and
 * jiggles inside then has no crease where the two meet.
 * Kinematic vertices (handles: their targets; fixed vertices and those outside the region:
 * the input) are not integrated: over a frame's substeps they move linearly from where the
 * last frame left them to where this frame puts them, and drive the clusters they share.
 * Plasticity (per cluster, when plastic_creep > 0): with A = R S, where |S - I|_F exceeds
 * plastic_yield the plastic state S_p <- (I + h creep (S - I)) S_p, |S_p - I|_F is clamped to
 * plastic_max, S_p keeps det 1, and the rest offsets become S_p q (the Frobenius norm where
 * the paper writes the 2-norm: smooth, and it bounds it).
 *
 * Solves (the contract's starts): COLD resets the simulation to this request: every vertex at
 * rest in the goal shape (the input, or the bind's rest), kinematic vertices where the
 * request puts them, all velocities zero, plastic states I; it returns those positions.
 * GIVEN does the same from request->start_positions (a shape released at rest: the kinematic
 * vertices still where the request puts them). WARM and RESUME advance one frame (time_step,
 * in `substeps` steps) towards this request's input (the goal shape of the frame: secondary
 * motion on an animation) and targets. Energy: the shape-matching residual
 * sum_C sum_i m_i phi_iC |g_iC - x_i|^2 of the positions against the last solve's goal shape.
 */
#ifndef DK_SHAPE_MATCHING_H
#define DK_SHAPE_MATCHING_H

#include "dk_constraints.h"
#include "dk_mesh.h"
#include "dk_method.h"
#include "dk_progress.h"
#include "dk_status.h"

#ifdef __cplusplus
extern "C" {
#endif

typedef enum dk_shape_matching_mode {
    DK_SHAPE_MATCHING_RIGID = 0,
    DK_SHAPE_MATCHING_LINEAR = 1, /**< default                                              */
    DK_SHAPE_MATCHING_QUADRATIC = 2
} dk_shape_matching_mode;

typedef enum dk_shape_matching_integrator {
    DK_INTEGRATOR_SEMI_IMPLICIT_EULER = 0, /**< default: the paper's scheme                */
    DK_INTEGRATOR_EXPLICIT_EULER = 1,
    DK_INTEGRATOR_IMPLICIT_EULER = 2,
    DK_INTEGRATOR_RK4 = 3
} dk_shape_matching_integrator;

typedef enum dk_shape_matching_cluster_kind {
    DK_CLUSTERS_CUBES = 0, /**< overlapping cubes of cluster_size, split into the pieces the
                                mesh's edges connect (default): detailed shapes wobble
                                locally                                                   */
    DK_CLUSTERS_PARTS = 1  /**< one cluster per connected part: the paper's basic method,
                                each part keeps its shape as a whole                      */
} dk_shape_matching_cluster_kind;

typedef struct dk_shape_matching_options {
    dk_shape_matching_mode mode;             /**< default LINEAR                           */
    double alpha;        /**< stiffness in [0, 1] per integration step; default 0.3         */
    double beta;         /**< LINEAR, QUADRATIC: in [0, 1], how far the fit goes from the
                              rotation to the best linear / quadratic map; default 0.3      */
    double damping;      /**< velocity damping rate d >= 0, per second; default 4           */
    double gravity_x, gravity_y, gravity_z; /**< acceleration, mesh units / s^2; default 0  */
    double time_step;    /**< seconds a warm solve advances (a frame); default 1/24         */
    int substeps;        /**< integration steps a frame, 1 .. 64; default 2                 */
    dk_shape_matching_integrator integrator; /**< default SEMI_IMPLICIT_EULER              */
    dk_shape_matching_cluster_kind clusters; /**< default CUBES                              */
    double cluster_size; /**< CUBES: the cubes' edge, mesh units (overlapping by half: each
                              vertex lies in 8); 0 (default): a quarter of the bounding
                              box's diagonal                                                */
    double falloff;       /**< attachment near the kinematic vertices: a free vertex at
                               distance d from the nearest one (at the bind's rest) gets the
                               attachment s(1 - d / falloff) (s the smoothstep: 1 at a
                               kinematic vertex, 0 from falloff on), so that a jiggling region
                               blends into what follows the rig instead of tearing from it;
                               mesh units, 0 (default): half the simulated region's depth
                               (its farthest vertex from the kinematic ones), at most half
                               the automatic cubes' edge                                  */
    double plastic_yield; /**< |S - I|_F above which a cluster creeps; default 0.1          */
    double plastic_creep; /**< creep rate per second, >= 0; 0 (default): elastic only      */
    double plastic_max;   /**< the largest |S_p - I|_F; default 1                           */
    const double *masses; /**< n_vertices masses in (0, 1e100], or NULL: all 1              */
    dk_index n_masses;
    const double *alpha_map;   /**< n_vertices factors in [0, 1] on alpha (painted), or NULL */
    dk_index n_alpha_map;
    const double *beta_map;    /**< n_vertices factors in [0, 1] on beta, or NULL            */
    dk_index n_beta_map;
    const double *damping_map; /**< n_vertices factors >= 0 on damping, or NULL              */
    dk_index n_damping_map;
    const double *attach_map;  /**< n_vertices attachments in [0, 1] to the input's positions
                                    (painted: 1 held to the rig's pose, 0 free), combined with
                                    the falloff's a as 1 - (1 - a)(1 - map); or NULL          */
    dk_index n_attach_map;
    /** Clusters given instead of the automatic ones (regions of the surface): n_clusters
     *  lists of vertices, cluster_sizes[c] each, concatenated in cluster_vertices; every
     *  vertex that is not kinematic must lie in one. Not in the option table (Python's
     *  clusters=). n_clusters 0: automatic. */
    dk_index n_clusters;
    const dk_index *cluster_sizes;
    const dk_index *cluster_vertices;
    dk_phase_progress_fn progress; /**< bind progress (phase "clusters"), NULL: none         */
    void *progress_user;
} dk_shape_matching_options;

/** What can change between solves without a bind (keyed by an animator): written by
 *  dk_shape_matching_set_dynamics, read by dk_shape_matching_dynamics. */
typedef struct dk_shape_matching_dynamics {
    double alpha, beta, damping;
    double gravity[3];
    double time_step; /**< a frame's length (the scene's frame rate)                      */
    double plastic_yield, plastic_creep, plastic_max;
} dk_shape_matching_dynamics;

typedef struct dk_shape_matching dk_shape_matching;

void dk_shape_matching_default_options(dk_shape_matching_options *options);

/** Binds `mesh` (borrowed; faces optional). Constraints: handles (kinematic: follow their
 *  targets), fixed vertices and a region (outside it, kinematic: follow the input); handles
 *  are optional here (n_handles 0: every vertex outside the fixed set is simulated), and a
 *  part that nothing holds is simulated, not held. Builds the clusters (phase "clusters")
 *  and the rest state; the simulation starts at rest. */
dk_status dk_shape_matching_bind(const dk_mesh *mesh, const dk_constraint_desc *constraints,
                                 const dk_shape_matching_options *options,
                                 dk_shape_matching **out, dk_error *err);

/** Other constraints, same mesh and options; the simulation restarts at rest. On failure
 *  nothing changes. */
dk_status dk_shape_matching_rebind(dk_shape_matching *s, const dk_constraint_desc *constraints,
                                   dk_error *err);

/** The progress hook of later rebinds (phase "clusters"; NULL: none); a cancel there keeps
 *  the object as it was. */
void dk_shape_matching_set_progress(dk_shape_matching *s, dk_phase_progress_fn fn, void *user);

/** One frame (see the header's "Solves"): `request->targets` the handles' targets
 *  (positions or transforms of the input's handle vertices; a request for a bind without
 *  handles passes any non-NULL pointer), `request->input_positions` this frame's goal shape
 *  (n_vertices x 3) or NULL for the rest. Writes n_vertices x 3 positions. Allocation-free. */
dk_status dk_shape_matching_solve(dk_shape_matching *s, const dk_solve_request *request,
                                  double *positions, dk_solve_info *info, dk_error *err);

/** The shape-matching residual of `positions` (n_vertices x 3) against the last solve's goal
 *  shape (the rest before any). */
dk_status dk_shape_matching_energy(const dk_shape_matching *s, const double *positions,
                                   double *energy, dk_error *err);

/** The blended goal g_i of every vertex (n_vertices x 3) for `positions` (n_vertices x 3)
 *  against the last solve's goal shape and the current plastic states: what the clusters
 *  pull each vertex towards (kinematic vertices included; the attachment's blend with the
 *  input, which the integrators add, is not). */
dk_status dk_shape_matching_goals(const dk_shape_matching *s, const double *positions,
                                  double *goals, dk_error *err);

/** The current velocities (n_vertices x 3, copied into `out`). */
void dk_shape_matching_velocities(const dk_shape_matching *s, double *out);

/** Sets the velocities (n_vertices x 3, finite; DK_ERR_NONFINITE naming the vertex, nothing
 *  changed): an initial condition (a throw, a spin). Kinematic vertices get theirs from
 *  their motion at the next frame. */
dk_status dk_shape_matching_set_velocities(dk_shape_matching *s, const double *velocities,
                                           dk_error *err);

/** Frames advanced since the last cold solve (or restore: the saved count). */
int64_t dk_shape_matching_frame(const dk_shape_matching *s);

/** The clusters: their count, and for cluster c its vertices cluster_vertices[start[c] ..
 *  start[c+1]-1] (arrays owned by the object) and each one's share of it (`shares`, the
 *  same shape, or NULL: a vertex's shares sum to 1; the automatic cubes' trilinear hats). */
dk_index dk_shape_matching_clusters(const dk_shape_matching *s, const dk_index **start,
                                    const dk_index **vertices, const double **shares);

/** Sets the keyable parameters (checked: alpha, beta in [0, 1], damping, creep, yield, max
 *  >= 0, gravity finite, time_step in [1e-6, 3600]); on failure nothing changes. */
dk_status dk_shape_matching_set_dynamics(dk_shape_matching *s,
                                         const dk_shape_matching_dynamics *dyn, dk_error *err);
/** The check of dk_shape_matching_set_dynamics alone. */
dk_status dk_shape_matching_check_dynamics(const dk_shape_matching_dynamics *dyn, dk_error *err);
void dk_shape_matching_get_dynamics(const dk_shape_matching *s, dk_shape_matching_dynamics *dyn);

void dk_shape_matching_stats(const dk_shape_matching *s, dk_method_stats *stats);
void dk_shape_matching_free(dk_shape_matching *s);

/** State: positions, velocities, the clusters' plastic states and the frame count. */
size_t dk_shape_matching_state_size(const dk_shape_matching *s);
dk_status dk_shape_matching_save_state(const dk_shape_matching *s, void *state, size_t size,
                                       dk_error *err);
dk_status dk_shape_matching_restore_state(dk_shape_matching *s, const void *state, size_t size,
                                          dk_error *err);

/** Peak bytes of a bind: 8 clusters a vertex. */
dk_status dk_shape_matching_estimate_memory(const dk_mesh *mesh,
                                            const dk_shape_matching_options *options,
                                            uint64_t *bytes, dk_error *err);

extern const dk_method_ops dk_shape_matching_ops;

#ifdef __cplusplus
}
#endif

#endif
