/* DeformKit: what a method's handles are -- its control kind -- declared in its table
 * (dk_method_ops.controls) and bound with the mesh.
 *
 * The methods so far are driven by VERTEX_GROUPS of the mesh they deform (dk_constraints.h):
 * each handle is a set of its vertices, moved at solve time by positions or transforms. The
 * slides' other families are driven by something bound beside the mesh, which a solve then
 * moves:
 *   POINTS   free points in space (Shepard interpolation): their rest positions; a solve gives
 *            each point's position (targets: n_controls x 3).
 *   BONES    bone frames (skinning): each bone's rest frame B_j (a 4x4 affine, row-major)
 *            and a weight per vertex and bone (given, or computed at bind from each bone's
 *            segment); a solve gives each bone's current frame T_j
 *            (targets: n_controls 4x4 row-major, as transforms), and the bone moves the
 *            mesh by T_j B_j^-1 (the slides' skinning), so the rest frames give it back.
 *   CAGE     a closed triangle control mesh around the mesh (mean value and Wachspress
 *            coordinates): its rest vertices and triangles; a solve gives each cage vertex's
 *            position (targets: n_controls x 3).
 *   LATTICE  a box lattice (free-form deformation): its points along x, y and z and the box's
 *            frame (the affine map of the unit cube [0,1]^3 onto the box); a solve gives each
 *            lattice point's position, x fastest, then y, then z (targets: n_controls x 3).
 *   POSES    example shapes of the mesh, same vertices (shape interpolation): their positions;
 *            a solve gives a weight per pose (targets: n_controls values).
 * A method declares the kinds it takes as a bit set (dk_method_ops.controls); a bind given a
 * control whose kind the method does not take is refused by name, and one given none takes
 * the vertex groups of its dk_constraint_desc. dk_control_check validates a description the
 * same way for every method that takes it, before the method reads it.
 */
#ifndef DK_CONTROLS_H
#define DK_CONTROLS_H

#include "dk_mesh.h"
#include "dk_status.h"
#include <stddef.h>

#ifdef __cplusplus
extern "C" {
#endif

/** One control kind, a bit of dk_method_ops.controls. */
typedef enum dk_control_kind {
    DK_CONTROL_VERTEX_GROUPS = 1, /**< handles are groups of the mesh's vertices            */
    DK_CONTROL_POINTS = 2,        /**< free points in space                                  */
    DK_CONTROL_BONES = 4,         /**< bone frames with per-vertex weights                   */
    DK_CONTROL_CAGE = 8,          /**< a closed triangle control mesh                        */
    DK_CONTROL_LATTICE = 16,      /**< a box lattice                                         */
    DK_CONTROL_POSES = 32         /**< example shapes of the mesh                            */
} dk_control_kind;

/** Every kind's bit. */
#define DK_CONTROL_ALL 63u

/** A control bound with the mesh (borrowed pointers, nothing owned). Zero-initialise, then
 *  set the fields of its kind; the others must stay 0 / NULL. */
typedef struct dk_control_desc {
    dk_control_kind kind;       /**< one kind, not VERTEX_GROUPS (those are the handles of
                                     dk_constraint_desc)                                  */
    dk_index n_controls;        /**< POINTS: points; BONES: bones; CAGE: cage vertices;
                                     LATTICE: the product of resolution; POSES: poses. > 0  */
    const double *rest;         /**< POINTS, CAGE: n_controls x 3 positions; BONES:
                                     n_controls 4x4 row-major rest frames (bottom row 0 0 0
                                     1, invertible); LATTICE: one 4x4 row-major affine map of
                                     the unit cube onto the box (invertible); POSES:
                                     n_controls x n_vertices x 3. Finite, within
                                     DK_COORD_MAX                                          */
    dk_index n_triangles;       /**< CAGE: > 0                                             */
    const dk_index *triangles;  /**< CAGE: n_triangles x 3 indices into the cage's vertices,
                                     three distinct each                                   */
    dk_index resolution[3];     /**< LATTICE: points along x, y, z, each >= 2              */
    const double *weights;      /**< BONES: n_vertices x n_controls, row-major, each >= 0
                                     and each row summing to 1 within 1e-6; or NULL with
                                     `segments` given: the bind computes them (bounded
                                     biharmonic weights, dk_bbw.h)                         */
    const double *segments;     /**< BONES without weights: n_controls x 2 x 3, each bone's
                                     head and tail in the mesh's space                     */
} dk_control_desc;

/** The kind's name as messages and the Python module say it ("lattice"); "unknown" for a
 *  value that is not one kind. */
const char *dk_control_kind_name(dk_control_kind kind);

/** The kind's identifier as the Python module lists it ("vertex_groups", "lattice"), NULL
 *  for a value that is not one kind. */
const char *dk_control_kind_id(dk_control_kind kind);

/** Validates `control` for a mesh of `n_vertices` vertices: a known kind other than
 *  VERTEX_GROUPS; n_controls > 0 (LATTICE: the product of resolution, each >= 2); `rest`
 *  given, finite and within DK_COORD_MAX, frames affine and invertible; CAGE's triangles in
 *  range with distinct corners; BONES' weights non-negative with rows summing to 1; the
 *  fields of other kinds 0 / NULL. DK_ERR_INVALID_ARGUMENT or DK_ERR_NONFINITE naming the
 *  field and the first bad entry. */
dk_status dk_control_check(const dk_control_desc *control, dk_index n_vertices,
                           dk_error *err);

/** The number of doubles a solve's targets hold for `control` (a checked description):
 *  3 n_controls for points, cage and lattice, 16 n_controls for bones, n_controls for
 *  poses. */
size_t dk_control_target_count(const dk_control_desc *control);

/** Refuses `control` (DK_ERR_INVALID_ARGUMENT) unless its kind is one of `taken` (a method's
 *  dk_method_ops.controls): "<who> binds to vertex groups, not a lattice". NULL `control`
 *  is the vertex groups. For a method's bind, before it reads anything else. */
dk_status dk_control_taken(const dk_control_desc *control, unsigned taken, const char *who,
                           dk_error *err);

#ifdef __cplusplus
}
#endif

#endif
