/* Shape interpolation's pieces (dk_shape_interpolation.h): rotation vectors (rotation.c),
 * triangle frames and each pose's rotations and stretches (poses.c), rotation vectors
 * lifted across the mesh (lift.c), the least-squares system of the positions (system.c)
 * and the driver (shape_interpolation.c). Not installed. */
#ifndef DK_SI_INTERNAL_H
#define DK_SI_INTERNAL_H

#include "dk_cholesky.h"
#include "dk_constraints.h"
#include "dk_csys.h"
#include "dk_parallel.h"
#include "dk_shape_interpolation.h"

/* ---- rotation.c: 3 x 3 matrices are row-major, rotation vectors angle x unit axis ---- */

/* exp: the rotation of the vector w (Rodrigues; its series near 0). */
void si_rotation_exp(const double w[3], double R[9]);

/* log: a rotation vector of R (a rotation matrix) with angle in [0, pi]; returns the angle. */
double si_rotation_log(const double R[9], double w[3]);

/* c = a b and c = a^T b (3 x 3; c must not overlap a or b). */
void si_mat3_mul(const double a[9], const double b[9], double c[9]);
void si_mat3_tmul(const double a[9], const double b[9], double c[9]);

/* ---- stretch.c: symmetric 3 x 3 as 6 entries (xx, xy, xz, yy, yz, zz) ---- */

/* log of a symmetric positive definite matrix (eigenvalues below 1e-8 taken as 1e-8). */
void si_sym_log(const double s[6], double out[6]);

/* exp of a symmetric matrix, as a full row-major 3 x 3. */
void si_sym_exp(const double s[6], double out[9]);

/* ---- poses.c ---- */

/* The frame of the triangle p0, p1, p2 (columns p1 - p0, p2 - p0, n / sqrt|n|), row-major. */
void si_frame(const double *p0, const double *p1, const double *p2, double V[9]);

/* Every triangle's inverse rest frame V^-1 (n_faces x 9) and whether it is degenerate
 * (dk_triangle_degenerate; its inverse is then 0). */
void si_rest_frames(const dk_mesh *mesh, double *vinv, unsigned char *degenerate);

/* What the bind keeps of the poses, per pose k and triangle t: the rotation vector omega
 * (lift.c), its residual eps, the stretch. */
typedef struct si_poses {
    dk_index n_poses;
    double *positions;        /* P x n x 3: the poses as given (a rebind builds again)     */
    double *omega;            /* P x F x 3                                                 */
    double *eps;              /* P x F x 3: log(exp(omega)^T R)                             */
    double *stretch;          /* P x F x 6: S - I, or log S (stretches LOG: stretch.c)     */
    double *shift;            /* P x n_components x 3: the mean displacement of each part  */
} si_poses;

/* Copies the poses (n_poses x n x 3) and computes each pose's rotation vectors (lifted
 * across the mesh from roots touching a vertex with `seed_vertex` set, else the least
 * turned triangles; principal ones for rotations PRINCIPAL), residuals, stretches and part
 * shifts. `progress` gets phase `phase`. */
dk_status si_poses_build(const dk_mesh *mesh, const double *vinv, const unsigned char *degenerate,
                         const double *poses, dk_index n_poses,
                         const dk_shape_interpolation_options *options,
                         const unsigned char *seed_vertex, si_poses *out, dk_progress *progress,
                         int phase, dk_error *err);
void si_poses_free(si_poses *p);

/* ---- lift.c ---- */

/* The least-squares lift of rotations: the triangles' adjacency (across edges shared by two
 * non-degenerate triangles), one root per connected group, and the factored graph
 * Laplacian over the other triangles. */
typedef struct si_lift {
    dk_index *unk;            /* F: unknown index, -1 at roots and degenerate triangles    */
    dk_index nu;
    dk_sparse *a;
    dk_cholesky *chol;
    double *rhs;              /* nu x 3, column-major                                      */
} si_lift;

/* Builds the lift; `by_key` (F) lists the triangles in the order roots are taken. */
dk_status si_lift_build(const dk_mesh *mesh, const unsigned char *degenerate,
                        const dk_index *by_key, si_lift *out, dk_error *err);
void si_lift_free(si_lift *l);

/* One pose: R (F x 9) its rotations; writes omega and eps (F x 3 each). */
dk_status si_lift_pose(si_lift *l, const dk_mesh *mesh, const unsigned char *degenerate,
                       const double *R, double *omega, double *eps, dk_error *err);

/* ---- system.c ---- */

/* The edge weights c_ij (n_edges) of `kind` at the rest, each at least 1e-6 of their mean
 * (clamped and uniform; the cotangent ones keep their sign). */
dk_status si_edge_weights(const dk_mesh *mesh, dk_shape_interpolation_weights kind,
                          double *weights, dk_error *err);

/* The positions' system for one set of constraints: the unknowns are the free vertices less
 * one per part of the mesh without a constrained vertex (pinned, placed by its mean). */
typedef struct si_system {
    dk_constraints *con;
    dk_index nu;              /* unknowns                                                 */
    dk_index *unk;            /* n: unknown index, or -1                                  */
    dk_index *unknowns;       /* nu: their vertices                                       */
    dk_index *target_of;      /* n: row of the expanded handle targets, or -1             */
    unsigned char *free_part; /* n_components: 1 = no constrained vertex (placed by mean) */
    dk_sparse *a;             /* nu x nu                                                  */
    dk_cholesky *chol;
} si_system;

/* Builds and factors the system for `con` (taken over: freed with the system, also on
 * failure) and the edge weights. `old` (may be NULL): the previous system, whose analysis is
 * reused when the unknowns are the same. Counts into `counts`; progress phases
 * `phase` (analysis) and `phase` + 1 (factorization). */
dk_status si_system_build(const dk_mesh *mesh, const double *edge_weights, dk_constraints *con,
                          si_system *old, dk_team *team, dk_csys_counts *counts,
                          dk_progress *progress, int phase, si_system *out, dk_error *err);
void si_system_free(si_system *s);

#endif
