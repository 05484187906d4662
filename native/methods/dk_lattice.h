/* DeformKit: lattice free-form deformation (the lecture's FFD: "deform the ambient space
 * and thus implicitly the embedded object"; Sederberg & Parry 1986 for the Bernstein form).
 *
 * The control (dk_controls.h, DK_CONTROL_LATTICE): a box -- the affine image F of the unit
 * cube, F = control->rest -- carrying l x m x n points R_ijk = F (i/(l-1), j/(m-1),
 * k/(n-1)), x fastest, then y, then z (index i + l (j + m k)). Bind registers each vertex
 * to the lattice: its coordinates in index space, a = F^-1 x scaled by (l-1, m-1, n-1), and
 * from them a weight per lattice point. A solve moves the points to P (targets:
 * n_controls x 3 positions) and each vertex by the weighted motion of the points:
 *     x' = x + sum_ijk w_i(a_x) w_j(a_y) w_k(a_z) (P_ijk - R_ijk),
 * the displacement form, so that points left where they are give the input back exactly,
 * bit for bit, everywhere. The weights, per axis (the tensor product of three 1D bases):
 *   LINEAR     the slides' trilinear interpolation in the cell holding the vertex: two
 *              weights per axis, (1 - f, f) at the cell's corners.
 *   BERNSTEIN  Sederberg-Parry: B_i^L(s) = C(L, i) s^i (1 - s)^(L - i), L = l - 1, s in the
 *              box's [0, 1]: every point moves every vertex (l weights per axis, smooth
 *              everywhere; costs l m n per vertex and solve).
 *   BSPLINE    uniform cubic B-spline over the points, as Blender's default lattice: four
 *              weights per axis. Its two missing end points are the lattice extended
 *              linearly (P_-1 = 2 P_0 - P_1, and at the far end likewise), folded into the
 *              real ones, so the border points are interpolated (a vertex on a border
 *              point follows it exactly) and a straight lattice gives straight lines.
 * Every interpolation reproduces affine maps: moving the points by an affine map A moves
 * every vertex in the box by A (to rounding) -- the linear precision the tests check.
 * Outside the box a vertex takes the nearest border cell's polynomial, continued
 * (OUTSIDE_EXTEND, the default: affine precision everywhere), the motion of the box's
 * nearest point (OUTSIDE_CLAMP: what Blender's Lattice does with its linear basis), or that
 * motion fading to none within one cell of the box (OUTSIDE_STILL; cells measured per
 * axis). Blender's B-spline repeats its border points instead of extending the lattice:
 * near the border its shape differs from BSPLINE here, which keeps linear precision and
 * interpolates the border points (a careful engineer's choice where the two disagree).
 *
 * The method edits the pose it is given (DK_METHOD_EDITS_INPUT): with input_positions the
 * vertices are registered where the input puts them (O(n) per new pose, no allocation), as
 * Blender's Lattice modifier registers what reaches it. It is direct: iterations 1,
 * converged 1; the energy reported is the sum over the vertices of |x' - x|^2, the squared
 * displacement (as Falloff's). Rebind takes a new lattice (resolution, box) for the same
 * mesh and options.
 */
#ifndef DK_LATTICE_H
#define DK_LATTICE_H

#include "dk_constraints.h"
#include "dk_controls.h"
#include "dk_mesh.h"
#include "dk_method.h"
#include "dk_progress.h"
#include "dk_status.h"

#ifdef __cplusplus
extern "C" {
#endif

/** The 1D basis of each axis. */
typedef enum dk_lattice_interpolation {
    DK_LATTICE_LINEAR = 0,    /**< trilinear in the vertex's cell (the slides)               */
    DK_LATTICE_BERNSTEIN = 1, /**< Sederberg-Parry: Bernstein polynomials over the box       */
    DK_LATTICE_BSPLINE = 2    /**< uniform cubic B-spline, ends extended linearly            */
} dk_lattice_interpolation;

/** What moves a vertex outside the lattice's box. */
typedef enum dk_lattice_outside {
    DK_LATTICE_OUTSIDE_EXTEND = 0, /**< the nearest border cell's map, continued: affine
                                        maps of the lattice move every vertex exactly       */
    DK_LATTICE_OUTSIDE_CLAMP = 1,  /**< the motion at the nearest point of the box, as
                                        Blender's Lattice modifier carries its border on   */
    DK_LATTICE_OUTSIDE_STILL = 2   /**< CLAMP fading to no motion one cell beyond the box   */
} dk_lattice_outside;

typedef struct dk_lattice_options {
    dk_lattice_interpolation interpolation; /**< default DK_LATTICE_BSPLINE (as Blender's)   */
    dk_lattice_outside outside;             /**< default DK_LATTICE_OUTSIDE_EXTEND           */
    dk_phase_progress_fn progress;          /**< bind progress (phase "register"), NULL: none */
    void *progress_user;
} dk_lattice_options;

typedef struct dk_lattice dk_lattice;

/** The defaults above. */
void dk_lattice_default_options(dk_lattice_options *options);

/** Binds `mesh` (borrowed, must outlive the object) to the lattice `constraints->control`
 *  (kind DK_CONTROL_LATTICE, checked by dk_control_check; its handles, fixed and ROI must be
 *  empty: the lattice moves everything). `options` NULL: the defaults. */
dk_status dk_lattice_bind(const dk_mesh *mesh, const dk_constraint_desc *constraints,
                          const dk_lattice_options *options, dk_lattice **out, dk_error *err);

/** Another lattice for the same mesh and options; on failure nothing changes. */
dk_status dk_lattice_rebind(dk_lattice *lattice, const dk_constraint_desc *constraints,
                            dk_error *err);

/** `request->targets`: the lattice points' positions, n_controls x 3, row-major, in the
 *  control's order (DK_TARGETS_POSITIONS only: a lattice has no handles to transform;
 *  transforms are refused). `request->input_positions` (n_vertices x 3, optional): the pose
 *  to deform instead of the rest. Writes n_vertices x 3 positions. Allocation-free. */
dk_status dk_lattice_solve(dk_lattice *lattice, const dk_solve_request *request,
                           double *positions, dk_solve_info *info, dk_error *err);

/** The sum over the vertices of |positions - x|^2, x the pose the last solve deformed
 *  (before any solve: the rest): the squared displacement a solve reports. */
dk_status dk_lattice_energy(const dk_lattice *lattice, const double *positions, double *energy,
                            dk_error *err);

void dk_lattice_stats(const dk_lattice *lattice, dk_method_stats *stats);

/** The bound lattice: its points along x, y, z (`resolution`, 3), its box (`frame`, 16:
 *  the unit cube onto the box, row-major) and its points at rest (`rest`, n_controls x 3,
 *  x fastest), each NULL when not wanted. */
void dk_lattice_get(const dk_lattice *lattice, dk_index *resolution, double *frame,
                    double *rest);
void dk_lattice_free(dk_lattice *lattice);

/** Peak bytes of a bind (dk_method_ops.estimate_memory): the registration's weights, per
 *  vertex 3 indices and 6, 12 or l + m + n doubles (the lattice's size is the control's,
 *  unknown here: the model takes 12 and the Bernstein case checks its own at bind). */
dk_status dk_lattice_estimate_memory(const dk_mesh *mesh, const dk_lattice_options *options,
                                     uint64_t *bytes, dk_error *err);

extern const dk_method_ops dk_lattice_ops;

#ifdef __cplusplus
}
#endif

#endif
