/* DeformKit: the constraint description shared by every deformation method.
 *
 * Each vertex is FREE, FIXED (stays at its rest position) or belongs to exactly one HANDLE
 * group (moves to a target given at solve time). A region of interest (ROI) may restrict the
 * solve: vertices outside it are treated as fixed. Per-vertex handle weights in (0, 1] make a
 * handle soft where a method supports it (weight 1 = fully attached, as Blender's hook
 * weights); per-vertex stiffness (> 0, default 1) scales a method's regulariser where it
 * supports it.
 *
 * Overlaps are refused, not resolved silently: a vertex in two handles, or in a handle and the
 * fixed set, is a DK_ERR_INVALID_ARGUMENT naming the vertex and both groups.
 *
 * Loose geometry (issue 18, class 12): a connected component of the mesh in which no vertex
 * is a handle or fixed (or outside the ROI) -- a loose vertex, a loose edge, a floating
 * island -- is nothing any method can place: its position is undetermined for some, a
 * guess for others. Every such component is HELD: its vertices get the role FIXED (so every
 * method keeps them at rest, as it keeps fixed vertices), `held` marks them, and n_held /
 * n_held_components / first_held count them for the methods' reports. A mesh without faces
 * (a point set, which EmbeddedDeformation deforms through its graph) has no loose geometry
 * and nothing is held there. This is decided once,
 * here, so that every method treats loose geometry the same way; a method whose fixed
 * vertices act on their surroundings (EmbeddedDeformation's constant nodes) ignores held
 * ones there, and every method writes the rest position of held vertices into its result
 * (dk_constraints_hold).
 */
#ifndef DK_CONSTRAINTS_H
#define DK_CONSTRAINTS_H

#include "dk_controls.h"
#include "dk_mesh.h"
#include "dk_status.h"

#ifdef __cplusplus
extern "C" {
#endif

enum { DK_VERTEX_FREE = -1, DK_VERTEX_FIXED = -2 };

/** Caller-side description (borrowed pointers, nothing owned). */
typedef struct dk_constraint_desc {
    dk_index n_handles;
    const dk_index *handle_sizes;     /**< n_handles                                        */
    const dk_index *handle_vertices;  /**< concatenated, sum(handle_sizes)                  */
    const double *handle_weights;     /**< same length, in (0, 1]; NULL = all 1             */
    dk_index n_fixed;
    const dk_index *fixed_vertices;   /**< n_fixed                                          */
    dk_index n_roi;                   /**< 0 = the whole mesh is the region of interest     */
    const dk_index *roi_vertices;     /**< n_roi                                            */
    const double *stiffness;          /**< n_vertices, > 0; NULL = all 1                    */
    const dk_control_desc *control;   /**< NULL: the handles above drive the method. Else
                                           the control it binds to (dk_controls.h), for a
                                           method whose table takes its kind; the vertex-
                                           group constraints refuse it                  */
} dk_constraint_desc;

/** Validated, owned constraints of one bind. */
typedef struct dk_constraints {
    dk_index n_vertices;
    dk_index n_handles;
    dk_index n_handle_vertices;       /**< total over handles                               */
    dk_index *handle_start;           /**< n_handles + 1 offsets into handle_vertices       */
    dk_index *handle_vertices;        /**< concatenated, in the caller's order              */
    double *handle_weights;           /**< per handle vertex, in (0, 1]                     */
    dk_index *role;                   /**< n_vertices: handle id >= 0, or FREE / FIXED      */
    dk_index n_free;                  /**< vertices with role FREE                          */
    dk_index *free_index;             /**< n_vertices: position among free vertices or -1   */
    dk_index *free_vertices;          /**< n_free: the inverse map                          */
    double *stiffness;                /**< n_vertices                                       */
    unsigned char *held;              /**< n_vertices: 1 = in a component nothing constrains,
                                           held at rest (role FIXED)                      */
    dk_index n_held;                  /**< vertices held                                    */
    dk_index n_held_components;       /**< components held                                  */
    dk_index first_held;              /**< the smallest held vertex, -1 when none           */
} dk_constraints;

/** Validates `desc` against the mesh (indices in range, no overlaps, weights in (0,1],
 *  stiffness finite and > 0, no empty handle, at least one handle vertex, no `control`:
 *  "this method binds to vertex groups, not a lattice") and builds the
 *  owned form. Vertices outside a non-empty ROI become FIXED, and so do the vertices of
 *  every connected component without a handle or fixed vertex (held, see above). */
dk_status dk_constraints_create(const dk_mesh *mesh, const dk_constraint_desc *desc,
                                dk_constraints **out, dk_error *err);

/** dk_constraints_create for a method that simulates what nothing constrains (shape
 *  matching: a part no handle holds moves by its dynamics): handles are optional (n_handles
 *  0) and no component is held (n_held 0). */
dk_status dk_constraints_create_simulated(const dk_mesh *mesh, const dk_constraint_desc *desc,
                                          dk_constraints **out, dk_error *err);

/** Frees; NULL allowed. */
void dk_constraints_free(dk_constraints *c);

/** Expands solve-time handle targets into per-handle-vertex target positions.
 *  mode 0: `targets` holds n_handle_vertices x 3 positions (concatenated in handle order).
 *  mode 1: `targets` holds n_handles 4x4 row-major affine transforms applied to the rest
 *          positions of each handle's vertices (bottom row must be 0 0 0 1).
 *  Checks finiteness and the DK_COORD_MAX bound of every expanded target (naming the
 *  handle and vertex) before writing anything: on failure `out` is unchanged, so a
 *  method whose current targets live there keeps them. `out` is n_handle_vertices x 3. */
dk_status dk_constraints_targets(const dk_constraints *c, const double *rest_positions,
                                 const double *targets, int mode, double *out, dk_error *err);

/** Writes the rest position of every held vertex into `positions` (n_vertices x 3): the
 *  last step of every method's solve, so that loose geometry is held exactly at rest. */
void dk_constraints_hold(const dk_constraints *c, const double *rest_positions,
                         double *positions);

/** Writes the constrained motion into `positions` (n_vertices x 3) when no vertex is free:
 *  each handle vertex at rest + weight (target - rest) (its target when the weight is 1),
 *  every other vertex at rest. `targets` are the expanded per-handle-vertex targets. For
 *  methods whose bind finds nothing to solve. */
void dk_constraints_constrained_motion(const dk_constraints *c, const double *rest_positions,
                                       const double *targets, double *positions);

/* ---------------------------------------------------------------- a simplified mesh's --- */

struct dk_decimation; /* dk_operators.h */

/** Each vertex's class for dk_decimate, so that a simplification keeps every role and never
 *  joins two (cls, n_vertices): 0 free, 1 fixed (held and outside the region of interest
 *  included), 2 + 2h + s for handle h, s = 1 on a soft vertex (weight < 1), so that a handle
 *  keeps hard vertices where it has any (the multi-scale solves' coarse levels). */
void dk_constraints_classes(const dk_constraints *c, int *cls);

/** The constraints restricted to a simplification's kept vertices (its coarse mesh's
 *  numbering): each handle's kept vertices in order with their weights, the kept fixed ones,
 *  their stiffness; no region of interest (the vertices outside it are fixed). */
typedef struct dk_coarse_constraints {
    dk_constraint_desc desc;  /**< for binding the coarse mesh; arrays owned below          */
    dk_index *fine_vertex;    /**< per coarse handle vertex (desc's order): its mesh vertex */
    dk_index n_handle_vertices;
    dk_index *sizes, *handle_vertices, *fixed;
    double *weights, *stiffness;
} dk_coarse_constraints;

/** Fills `out` (zeroed first; free it with dk_coarse_constraints_free, also after a
 *  failure). Only DK_ERR_OUT_OF_MEMORY. */
dk_status dk_coarse_constraints_create(const dk_constraints *c, const struct dk_decimation *d,
                                       dk_coarse_constraints *out, dk_error *err);
void dk_coarse_constraints_free(dk_coarse_constraints *cc);

#ifdef __cplusplus
}
#endif
#endif
