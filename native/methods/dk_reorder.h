/* DeformKit: an internal vertex numbering with locality, for the methods' per-vertex passes.
 *
 * Scanned meshes often come in an order in which neighbours are far apart (the armadillo:
 * median index distance of an edge's ends 1026, a quarter over 4096). Every per-iteration
 * pass of a method gathers neighbour data (positions, rotations, right-hand sides), so that
 * order costs cache misses: on the armadillo an ARAP iteration took 7.5 ms against 4.4-5.0
 * with a breadth-first numbering, measured in the same run. A method binds on the renumbered
 * copy made here and maps at its API boundary: constraints in, positions in and out, vertex
 * numbers in its error messages. Callers never see the internal numbering.
 *
 * The order: breadth-first search per connected component, in the order of the caller's
 * smallest vertex of each component, from a pseudo-peripheral start (the last vertex reached
 * by a first search from that smallest vertex), neighbours in ascending caller order; i.e.
 * Cuthill-McKee without the degree sort, which only matters for bandwidth, not for
 * locality. Faces keep the caller's order (relabelled), so that sums over a vertex's faces
 * (normals, areas) run in the same order as on the caller's mesh, unless the method asks
 * for DK_REORDER_SORT_FACES: then faces are sorted by their smallest internal corner (stably,
 * so ties keep the caller's order), which keeps the faces of neighbouring vertices close in
 * memory for methods that gather per-face data on every solve (Laplacian editing's local
 * frames: per-vertex sums of face cross products), at the price of summing a vertex's faces
 * in another order (rounding-level differences). Methods that pick among
 * neighbours break exact ties by the caller's vertex order (ro->perm), so results do not
 * depend on the internal numbering beyond rounding. Deterministic: depends only on the
 * mesh's connectivity and the caller's numbering.
 */
#ifndef DK_REORDER_H
#define DK_REORDER_H

#include "dk_constraints.h"
#include "dk_mesh.h"
#include "dk_status.h"

#ifdef __cplusplus
extern "C" {
#endif

/** A renumbering of a mesh and the renumbered mesh. */
typedef struct dk_reorder {
    dk_index n;
    dk_index *perm;  /**< n: internal vertex i is the caller's vertex perm[i]               */
    dk_index *iperm; /**< n: the caller's vertex v is internal vertex iperm[v]              */
    dk_mesh *mesh;   /**< owned: the caller's mesh with vertices and faces renumbered       */
    dk_index *face_perm; /**< n_faces: internal face f is the caller's face face_perm[f]      */
} dk_reorder;

/** Flags of dk_reorder_create. */
enum { DK_REORDER_SORT_FACES = 1 /**< faces sorted by their smallest internal corner */ };

/** Computes the order for `mesh` and builds the renumbered mesh (same positions, rows
 *  permuted; same triangles, relabelled, in the caller's order or, with
 *  DK_REORDER_SORT_FACES in `flags`, sorted). DK_ERR_OUT_OF_MEMORY on allocation failure,
 *  DK_ERR_INVALID_ARGUMENT for unknown flags. */
dk_status dk_reorder_create(const dk_mesh *mesh, unsigned flags, dk_reorder **out,
                            dk_error *err);

/** Frees; NULL allowed. */
void dk_reorder_free(dk_reorder *r);

/** internal[i] = caller[perm[i]] for n rows of 3 doubles (row-major). */
void dk_reorder_rows_in(const dk_reorder *r, const double *caller, double *internal);

/** caller[perm[i]] = internal[i] for n rows of 3 doubles (row-major). */
void dk_reorder_rows_out(const dk_reorder *r, const double *internal, double *caller);

/** A constraint description renumbered into the internal numbering (owns its arrays). */
typedef struct dk_reorder_desc {
    dk_constraint_desc desc; /**< what to pass to the method's internals                    */
    dk_index *indices;       /**< owned: handle, fixed and ROI vertices, concatenated         */
    double *stiffness;       /**< owned: permuted stiffness, or NULL                          */
} dk_reorder_desc;

/** Validates `in` against the caller's mesh (dk_constraints_create, so that errors name the
 *  caller's vertices), then writes its renumbered copy into `out` (handle groups, the order
 *  of vertices inside each group, and weights unchanged, so solve-time targets keep their
 *  order). On failure `out` holds nothing to free. */
dk_status dk_reorder_desc_create(const dk_reorder *r, const dk_mesh *caller_mesh,
                                 const dk_constraint_desc *in, dk_reorder_desc *out,
                                 dk_error *err);

/** Frees the arrays of `d` (not `d` itself); safe on a zeroed struct. */
void dk_reorder_desc_free(dk_reorder_desc *d);

#ifdef __cplusplus
}
#endif
#endif
