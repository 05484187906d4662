/* DeformKit: embedded deformation with a deformation graph (Sumner, Schmid & Pauly,
 * "Embedded Deformation for Shape Manipulation", SIGGRAPH 2007). See
 * docs/methods/embedded.md.
 *
 * The graph. m nodes g_j, each with an affine transformation (R_j, t_j) that maps a point p
 * to R_j (p - g_j) + g_j + t_j (eq. 1). A point v of the embedded shape moves by the blend of
 * its k nearest nodes (eq. 2),
 *     v' = sum_j w_j(v) [R_j (v - g_j) + g_j + t_j],
 *     w_j(v) = (1 - |v - g_j| / d_max)^2, normalised, d_max = distance to the (k+1)-th node
 * (eq. 4). Two nodes are joined by an edge when they influence a common point.
 * Geodesic influence (DK_ED_DISTANCE_GEODESIC, section 7's remedy for a hand node that
 * influences the leg): the k + 1 nearest nodes and the distances of eq. 4 are measured along
 * the mesh's edges instead, by one Dijkstra that carries k + 1 labels per vertex. Each node
 * enters at its nearest vertex, at the straight distance to it. The paper does not say how
 * to measure geodesics; edge paths overestimate them by a few % (metrication) but rank the
 * nodes the same way on any sensible mesh and, unlike the heat method, cost one pass rather
 * than one solve per node. A vertex that reaches fewer than k + 1 nodes along the surface (a
 * small component with too few nodes) falls back to Euclidean distance. Points given to
 * dk_embedded_embed are not on the mesh and always use Euclidean distance.
 * The cut (options cut_a, cut_b; section 7 leaves the "simple user interface" open): the
 * user gives the two sides as vertex sets; each node takes the side of its nearest vertex;
 * vertices of one side ignore the other side's nodes (in Euclidean distance their nearest
 * nodes come from a k-d tree without them; in geodesic distance labels do not enter the
 * other side), and edges between the two sides' nodes are dropped.
 * Nodes (DK_ED_NODES_SURFACE): uniform samples of the surface, as the paper does: dense
 * random points on the triangles (area-weighted), then, in a random order, a point is kept
 * when no kept point lies within the radius r (keep one at random, remove all others within
 * r, again and again); r is given, or found by bisection for the requested node count. Or
 * (DK_ED_NODES_VERTICES) the same elimination run over the mesh vertices, so that nodes are
 * vertices and ride along an animated mesh; a point set (a mesh without faces) always takes
 * its nodes from its points. Seeded: the same options give the same graph.
 *
 * The energy (eq. 9), over the free nodes' 12 unknowns each:
 *     F = w_rot E_rot + w_reg E_reg + w_con E_con
 *     E_rot = sum_j Rot(R_j), Rot = the squared deviations of R's columns from orthonormal
 *             (eqs. 5-6);
 *     E_reg = sum_j sum_{k in N(j)} |R_j (g_k - g_j) + g_j + t_j - (g_k + t_k)|^2 (eq. 7,
 *             alpha_jk = 1);
 *     E_con = sum over handle vertices |v'_l - q_l|^2 (eq. 8): handles are penalty terms,
 *             met to the solver's tolerance, not exactly (DK_METHOD_PENALTY_HANDLES).
 * Fixed constraints, as the paper has them: every node that influences a fixed vertex is a
 * constant (R = I, t = 0) and leaves the unknowns, so fixed vertices stay exactly at rest.
 * (Issue 14 words it as the nodes that influence only fixed points; that would leave the
 * fixed vertices next to the free region to a penalty and let them drift, so the paper's
 * rule it is.) Nodes that influence no vertex at all are dropped.
 * The solve: Gauss-Newton (eqs. 10-11) on the normal equations J^T J d = -J^T f, the pattern
 * of J^T J analysed once per bind (CHOLMOD) and refactored per iteration, with
 * Levenberg-Marquardt damping (mu I added, Nielsen's update: raised by a doubling factor
 * until F decreases, lowered by the gain ratio after an accepted step) so that big drags
 * never diverge. Stopping (eq. 12, after Gill et al.), after two accepted steps, all of:
 *     |F_k - F_{k-1}| / (1 - r) < eps (1 + F_k), 2 |grad F_k|_inf < cbrt(eps) (1 + F_k),
 *     |d_k|_inf / (1 - r) < sqrt(eps) (1 + |x_k|_inf)   (r: the last rate of each)
 * (the paper prints the last factor of the step test as 1 + |d_k|; Gill et al.'s is the
 * iterate's norm, which we use). A warm start begins from the previous solution, a cold one
 * from the identity.
 */
#ifndef DK_EMBEDDED_H
#define DK_EMBEDDED_H

#include <stdint.h>

#include "dk_constraints.h"
#include "dk_mesh.h"
#include "dk_method.h"
#include "dk_progress.h"
#include "dk_status.h"

#ifdef __cplusplus
extern "C" {
#endif

/** Where the graph's nodes come from. */
typedef enum dk_ed_node_source {
    DK_ED_NODES_SURFACE = 0,  /**< uniform samples of the triangles (the paper's)           */
    DK_ED_NODES_VERTICES = 1  /**< mesh vertices (a graph that rides an animated mesh)      */
} dk_ed_node_source;

/** Which distance ranks a point's nearest nodes and enters the weights of eq. 4. */
typedef enum dk_ed_distance {
    DK_ED_DISTANCE_EUCLIDEAN = 0, /**< straight-line distance in space (the paper's)       */
    DK_ED_DISTANCE_GEODESIC = 1   /**< shortest paths along the mesh's edges (the paper's
                                       remedy for a hand node influencing the leg); needs
                                       faces                                              */
} dk_ed_distance;

typedef struct dk_embedded_options {
    dk_ed_node_source nodes;  /**< default DK_ED_NODES_SURFACE                             */
    int n_nodes;              /**< the node count wanted (the bisection meets it within
                                   a few %), 1..100000; default 200; at most the vertex
                                   count is used (a graph denser than its mesh is floppy);
                                   ignored when radius > 0                                */
    double radius;            /**< > 0: the sampling radius itself (mesh units); a radius
                                   below 1e-12 of the mesh's extent, or one that keeps more
                                   than 100000 nodes (n_nodes' bound), is refused         */
    int k;                    /**< nearest nodes per point, 1..16 (k+1 <= nodes); default 4 */
    dk_ed_distance distance;  /**< default DK_ED_DISTANCE_EUCLIDEAN                        */
    /** The cut (section 7's stroke between the leg and the hand): two disjoint vertex sets,
     *  n_cut_a and n_cut_b indices (read during bind only; both empty = no cut). A node is
     *  on side A or B when its nearest vertex is in that set; no vertex of A is influenced
     *  by a node of side B nor the other way round, along the surface no path crosses from
     *  one set into the other, and no graph edge joins a node of side A to one of side B. */
    const dk_index *cut_a, *cut_b;
    dk_index n_cut_a, n_cut_b;
    double w_rot, w_reg, w_con; /**< > 0; defaults 1, 10, 2000. The paper's w_con is 100,
                                     in units it does not give; in ours (lengths over L,
                                     see embedded/energy.c's ed_evaluate) it left the armadillo's
                                     hand 3% of the drag off its target, 2000 0.8%        */
    double tolerance;         /**< eps of the stopping tests, > 0; default 1e-6            */
    int max_iterations;       /**< Gauss-Newton iterations per solve, >= 1; default 100    */
    uint64_t seed;            /**< the sampling's random seed; default 1                   */
    dk_phase_progress_fn progress; /**< bind progress (dk_progress.h), NULL by default: the
                                        phases nodes, weights (asked every 65536 vertices'
                                        queries, or 8192 steps of the geodesic search),
                                        edges, constraints, analyze, then "done" at 1; a
                                        non-zero return cancels the bind (DK_ERR_CANCELLED,
                                        nothing leaked). For the bind only                 */
    void *progress_user;      /**< passed to progress                                      */
} dk_embedded_options;

typedef struct dk_embedded dk_embedded;

/** Fills the defaults above. */
void dk_embedded_default_options(dk_embedded_options *options);

/** Builds the graph (nodes, per-vertex weights, edges), the fixed nodes and the pattern of
 *  J^T J, and analyses it. Refuses invalid options, a surface without area, fewer than
 *  k + 1 nodes, and constraints that leave no free node.
 *  The mesh must outlive the object; `options` may be NULL (defaults). */
dk_status dk_embedded_bind(const dk_mesh *mesh, const dk_constraint_desc *constraints,
                           const dk_embedded_options *options, dk_embedded **out,
                           dk_error *err);

/** New constraints, same graph: the fixed nodes and the pattern are recomputed. On failure
 *  the object keeps its previous constraints. */
dk_status dk_embedded_rebind(dk_embedded *ed, const dk_constraint_desc *constraints,
                             dk_error *err);

/** The progress callback of the following rebinds (NULL: none, as after bind): the phases
 *  constraints and analyze, then "done" at 1. A non-zero return cancels the rebind with
 *  DK_ERR_CANCELLED, and the object keeps its previous constraints. */
void dk_embedded_set_progress(dk_embedded *ed, dk_phase_progress_fn progress, void *user);

/** Solves for the handle targets of `request` (dk_method.h: positions or one transform per
 *  handle; DK_START_WARM / RESUME from the previous node transformations, COLD from the
 *  identity, GIVEN refused with DK_ERR_INVALID_ARGUMENT: positions do not determine the
 *  nodes' affine maps; max_iterations > 0 overrides the option). Writes the deformed vertices
 *  (n_vertices x 3, eq. 2) and info: energy F, iterations, converged (eq. 12).
 *  Allocation-free. */
dk_status dk_embedded_solve(dk_embedded *ed, const dk_solve_request *request,
                            double *positions, dk_solve_info *info, dk_error *err);

/** F is a function of the node transformations; as the contract's energy of positions
 *  (n_vertices x 3) this is w_rot E_rot + w_reg E_reg of the current transformations plus
 *  w_con times the positional terms evaluated at `positions` (handle vertices against the
 *  last targets, held fixed vertices against rest). For a solve's own result it equals the
 *  F that the solve reported. */
dk_status dk_embedded_energy(const dk_embedded *ed, const double *positions, double *energy,
                             dk_error *err);

/** The contract's counters; n_unknowns = 12 x the free nodes. */
void dk_embedded_stats(const dk_embedded *ed, dk_method_stats *stats);

/** The graph: node count, node positions (n_nodes x 3), each node's current transformation
 *  (n_nodes x 12: R row-major, then t; identity before any solve), whether it is a constant
 *  (fixed), and the edges (n_edges x 2, each once with i < j). Pointers stay valid until the
 *  next rebind or free. */
dk_index dk_embedded_n_nodes(const dk_embedded *ed);
dk_index dk_embedded_k(const dk_embedded *ed); /**< nodes per point */
const double *dk_embedded_nodes(const dk_embedded *ed);
const double *dk_embedded_transforms(const dk_embedded *ed);
int dk_embedded_node_is_fixed(const dk_embedded *ed, dk_index node);
dk_index dk_embedded_n_edges(const dk_embedded *ed);
const dk_index *dk_embedded_edges(const dk_embedded *ed);

/** Section 5, an animated source: the source's new positions (n_vertices x 3, finite).
 *  The nodes move with the source: a node on a vertex (DK_ED_NODES_VERTICES, or a point
 *  set) with its vertex, as in the paper; a surface sample keeps its triangle and its
 *  barycentric coordinates there (our generalisation, so that the paper's uniform graph
 *  follows too). The graph's structure, the weights, the constraints and J^T J's pattern
 *  stay as bound (the paper: "the graph structure and weighting remains fixed throughout the
 *  animation"), and the node transformations stay as a warm start. From then on solve,
 *  deformed, normals (NULL: from these positions), energy, transform targets and held fixed
 *  vertices use these positions as the rest. On failure nothing changes. Allocation-free. */
dk_status dk_embedded_update_source(dk_embedded *ed, const double *positions, dk_error *err);

/** The vertices (n_vertices x 3) under the current node transformations (eq. 2): what the
 *  last solve returned, computed again (allocation-free). */
dk_status dk_embedded_deformed(const dk_embedded *ed, double *positions, dk_error *err);

/** Normals deformed by the current transformations (eq. 3): for vertex v,
 *  n' = sum_j w_j(v) R_j^-T n_v, renormalised. `normals` (n_vertices x 3) are the rest
 *  normals, or NULL for the mesh's area-weighted vertex normals. A node whose R is singular
 *  is left out of the sum (its inverse transpose does not exist). Writes `out`
 *  (n_vertices x 3; a zero vector where nothing is left). DK_ERR_NONFINITE, naming the
 *  vertex, for a normal that is not finite. */
dk_status dk_embedded_normals(const dk_embedded *ed, const double *normals, double *out,
                              dk_error *err);

/** The deformation at arbitrary points (n_points x 3, any points in space: the embedded
 *  points need not be the graph's source): each point's k nearest nodes and weights
 *  (eq. 4) are computed as for the vertices, then eq. 2 with the current transformations.
 *  `nodes` (n_points x k) and `weights` (n_points x k) receive the embedding when not NULL;
 *  `out` (n_points x 3) the deformed points when not NULL. */
dk_status dk_embedded_embed(const dk_embedded *ed, const double *points, dk_index n_points,
                            dk_index *nodes, double *weights, double *out, dk_error *err);

/** Frees; NULL allowed. */
void dk_embedded_free(dk_embedded *ed);

/** State (dk_method_ops.state_size, dk_method.h): the bytes save_state writes -- the graph's
 *  transformations a warm start continues from, their energy, the last targets and the
 *  source (update_source) -- so that a restored object, this one or another bound the same
 *  way, continues bit for bit as this one would. */
size_t dk_embedded_state_size(const dk_embedded *ed);

/** Writes the state into `state` (exactly dk_embedded_state_size bytes). */
dk_status dk_embedded_save_state(const dk_embedded *ed, void *state, size_t size, dk_error *err);

/** Puts back a state dk_embedded_save_state wrote; another method's, or one of another
 *  shape (vertices, handle vertices, nodes, k) is DK_ERR_INVALID_ARGUMENT and changes
 *  nothing. A state of another object of the same shape (other fixed vertices, another
 *  seed) is not told apart: restore a state into the object that saved it, or its twin. */
dk_status dk_embedded_restore_state(dk_embedded *ed, const void *state, size_t size,
                                    dk_error *err);

/** The bytes a bind needs at its peak, its first solve included (dk_method.h,
 *  dk_method_estimate_memory): per vertex its k weights and neighbours, and per node of the
 *  graph J^T J's blocks and their Cholesky factor, which grow with k. The node count is
 *  n_nodes, or, with a radius, the count a disk packing of that radius leaves on the
 *  surface (capped by the vertices for nodes on vertices). `options` may be NULL (the
 *  defaults). DK_ERR_INVALID_ARGUMENT for a NULL mesh or bytes. */
dk_status dk_embedded_estimate_memory(const dk_mesh *mesh, const dk_embedded_options *options,
                                      uint64_t *bytes, dk_error *err);

/** Embedded deformation's table of the method contract; options are a
 *  dk_embedded_options. */
extern const dk_method_ops dk_embedded_ops;

#ifdef __cplusplus
}
#endif
#endif
