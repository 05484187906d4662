/* DeformKit: surface deformation by linear reconstruction from discrete fundamental forms,
 * with a per-edge material map (Li, after Wang, Liu & Tong 2012; ../shared/papers/004_*.txt;
 * docs/methods/fundamental.md).
 *
 * Bind, from the rest mesh's discrete fundamental forms:
 *   - per triangle: inner angles from the edge lengths (law of cosines), the vertices' 2-D
 *     coordinates in the triangle's frame (first edge, normal x first edge, normal) and so
 *     the edge coordinates a^1, a^2 (eq. 4);
 *   - per interior edge: R_ij, the rotation from frame i to frame j as the paper's product
 *     of three rotations: about i's normal to align e_1 with the shared edge, about the edge
 *     by the dihedral angle, about j's normal back to j's e_1;
 *   - the quadratic energy E = w E_f + E_x (eqs. 5-7) in positions x and frames f together,
 *     with cotangent weights times the material map m_e: E_x's weight of edge e in
 *     triangle T is m_e cot(angle opposite e in T), E_f's weight of an interior edge is
 *     1 / (m_e (cot alpha + cot beta)); each cotangent clamped to [1e-2, 1e2] (see the docs).
 *     m_e > 1 stretches less easily and bends more easily: a fold gathers there (the
 *     add-on's Softness). The paper calls m_e < 1 soft, but measured, that spreads a fold
 *     away from the paint (docs/methods/fundamental.md, "Measured");
 *   - handle and fixed vertices are hard constraints and leave the unknowns; with
 *     orientation constraints, so are the frames of the faces whose three vertices belong to
 *     one handle (or are all fixed). The system is the same for the three coordinates: it is
 *     factored once (CHOLMOD) and solved with three right-hand sides.
 * Solve: the right-hand side from the constraint values (one sparse product), two
 * triangular solves; with transforms, a combination of solutions precomputed at bind (see
 * dk_fundamental_has_transform_basis). Allocation-free.
 *
 * Frames of faces the user prescribes (orientation constraints): a handle's transform
 * gives its linear part; positions give the rotation that best fits the handle's rest
 * vertices to the targets (Kabsch). Fixed faces keep their rest frames.
 *
 * Degenerate triangles (dk_triangle_degenerate, dk_operators.h) have no frame: they
 * take no part in either energy. Boundary edges have one triangle's E_x term and no E_f.
 * A non-manifold edge joins each of its faces to the next in their order about it by a
 * frame equation with the rest frames' relative rotation (fundamental/forms.c, fr_fin_pairs), so it
 * keeps its bending stiffness. A component without any constraint is held at rest
 * (dk_constraints.h). Faces that meet at a vertex only (a part pinched onto the surface at
 * its corners) or across a degenerate triangle are joined by no frame equation: at each
 * such vertex a weak "bridge" ties their frames to the rest frames' relative rotation, so
 * the part turns with its neighbours instead of leaving the system singular (zero at rest
 * and for affine motions of the whole; see fundamental/forms.c, fr_pieces_and_bridges). A part that
 * only degenerate triangles join to the rest needs a constraint of its own: the error names
 * a vertex of it and the triangle. A part held by fewer than four vertices spanning space
 * and no prescribed frame has its free shear regularized (see the docs).
 *
 * The energy a solve reports is w E_f + E_x at the returned positions and frames;
 * dk_fundamental_energy evaluates it for given positions with the last solve's frames.
 */
#ifndef DK_FUNDAMENTAL_H
#define DK_FUNDAMENTAL_H

#include "dk_constraints.h"
#include "dk_mesh.h"
#include "dk_method.h"
#include "dk_progress.h"
#include "dk_status.h"

#ifdef __cplusplus
extern "C" {
#endif

/** Options; fill with dk_fundamental_default_options. */
typedef struct dk_fundamental_options {
    double w;                  /**< weight of the frame energy E_f (eq. 7), > 0, in units of
                                    the mean edge length squared (E_f is dimensionless, E_x
                                    a squared length: the product keeps results independent
                                    of the model's scale); default 1                       */
    int orientation;           /**< 1: handles (and the fixed set) prescribe the frames of
                                    their faces (Wang, Liu & Tong's orientation
                                    constraints); default 0                               */
    const double *material;    /**< n_material = n_edges (the mesh's edge order), each > 0 and
                                    finite: the material map m_e (1 = as built; > 1 folds
                                    more easily there, < 1 resists folding);
                                    NULL = all 1. Copied at bind                           */
    dk_index n_material;       /**< entries of `material` (must be the mesh's edge count)   */
    dk_phase_progress_fn progress; /**< bind progress (dk_progress.h), NULL by default: the
                                    phases forms, constraints, assemble, analyze,
                                    factorize, basis, and "done" at 1; a non-zero return
                                    cancels the bind (DK_ERR_CANCELLED, nothing leaked).
                                    Asked between phases, every few thousand residuals of
                                    the assembly's two passes and between the transform
                                    basis' solves (the fixed values' 3 columns, then 4 per
                                    handle); not during CHOLMOD's analysis and
                                    factorization, which cannot be interrupted. For the
                                    bind only: the object does not keep it              */
    void *progress_user;       /**< passed to progress                                      */
} dk_fundamental_options;

typedef struct dk_fundamental dk_fundamental;

/** Writes the defaults into `options`. */
void dk_fundamental_default_options(dk_fundamental_options *options);

/** Binds (see above). `mesh` is borrowed and must outlive the object; `options` may be
 *  NULL. */
dk_status dk_fundamental_bind(const dk_mesh *mesh, const dk_constraint_desc *constraints,
                              const dk_fundamental_options *options, dk_fundamental **out,
                              dk_error *err);

/** New constraints, same mesh and options: a new elimination, so a new factorization. On
 *  failure nothing changes. */
dk_status dk_fundamental_rebind(dk_fundamental *f, const dk_constraint_desc *constraints,
                                dk_error *err);

/** The progress callback of the following rebinds (NULL: none, as after bind): the phases
 *  constraints, assemble, analyze, factorize, basis (each rebind is a new elimination, so
 *  all of them), then "done" at 1. A non-zero return cancels the rebind with
 *  DK_ERR_CANCELLED and the object keeps its previous constraints, factor and transform
 *  basis exactly (the new ones are built aside and dropped). */
void dk_fundamental_set_progress(dk_fundamental *f, dk_phase_progress_fn progress, void *user);

/** Deformed positions (n_vertices x 3) for `request` (a direct method). `info` (may be
 *  NULL): energy w E_f + E_x, iterations = converged = 1. Allocation-free. */
dk_status dk_fundamental_solve(dk_fundamental *f, const dk_solve_request *request,
                               double *positions, dk_solve_info *info, dk_error *err);

/** w E_f + E_x of `positions` (n_vertices x 3) with the last solve's frames (before any
 *  solve: the rest frames). */
dk_status dk_fundamental_energy(const dk_fundamental *f, const double *positions,
                                double *energy, dk_error *err);

/** The last solve's frames (n_faces x 9, row-major 3 x 3 with columns e_1, e_2, normal;
 *  zero for degenerate faces); before any solve, the rest frames. */
const double *dk_fundamental_frames(const dk_fundamental *f);

/** The rotation R_ij (row-major 3 x 3) of interior edge `edge` (the mesh's numbering) as
 *  built from the fundamental forms, into `r`; 0 if the edge is a boundary edge or touches
 *  a degenerate face. For tests: on the rest mesh R_ij = f_i^T f_j. */
int dk_fundamental_edge_rotation(const dk_fundamental *f, dk_index edge, double r[9]);

/** The contract's counters (dk_method.h); zeros for NULL. */
void dk_fundamental_stats(const dk_fundamental *f, dk_method_stats *stats);

/** Frees; NULL allowed. */
void dk_fundamental_free(dk_fundamental *f);

/** The bytes a bind needs at its peak, its first solve included (dk_method.h,
 *  dk_method_estimate_memory): the factor of the 7n-unknown system (fill ~ n log n).
 *  `options` (may be NULL) changes nothing. DK_ERR_INVALID_ARGUMENT for a NULL mesh or
 *  bytes. */
dk_status dk_fundamental_estimate_memory(const dk_mesh *mesh,
                                         const dk_fundamental_options *options,
                                         uint64_t *bytes, dk_error *err);

/** 1 when solves with transforms combine precomputed solutions (the transform basis: the
 *  result is affine in the transforms' entries, so bind solves once per entry and a solve
 *  is one n_unknowns x 4 n_handles x 3 product). Built at bind and rebind unless a
 *  component is regularized (not affine), or it would take more than 256 MB. Solves with
 *  positions, and without the basis, take the two triangular solves. */
int dk_fundamental_has_transform_basis(const dk_fundamental *f);

/** The method's table of the contract; options are a dk_fundamental_options. */
extern const dk_method_ops dk_fundamental_ops;

#ifdef __cplusplus
}
#endif
#endif
