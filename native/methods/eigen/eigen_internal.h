/* DeformKit EigenDeformation, internal: the object and the functions the files of
 * native/methods/eigen/ share. Not part of the public API (dk_eigen.h is).
 *
 * Files, one idea each:
 *   eigen.c     the public verbs: options, bind and rebind (a driver naming its steps:
 *               regions, eigenvectors, skeletons), solve (Steps 1-3), energy, queries,
 *               stats, the memory model, the method-contract table
 *   spectrum.c  the eigenpairs of the cotangent or Belkin-Sun-Wang Laplacian (dense on small
 *               meshes, ARPACK otherwise), the bind's progress phases, Phi's factor
 *   fit.c       eq. 1: the projection on U_m, the fit, the skeletons of the levels, and
 *               Step 1's coarse target with Step 2's right-hand side
 *   frames.c    the local frames of section 3.3 and Step 3's detail recovery (section 4.1's
 *               blend)
 *   regions.c   R from the constraints: its groups, the distance to its boundary, w and
 *               delta_3
 *   part.c      the part each handle drags (region PART; part.h)
 *   request.c   a solve's targets as each group's Step-1 motion
 */
#ifndef DK_EIGEN_INTERNAL_H
#define DK_EIGEN_INTERNAL_H

#include "dk_eigen.h"
#include "part.h"

/* One level of the scheme: a skeleton with m eigenvectors, and the detail vectors that lead
 * from it to the next level (the mesh, or K_n' in the two-iteration scheme). */
typedef struct level {
    int m;
    double *p;       /* n x 3: the rest skeleton K_m                                       */
    double *b0;      /* m x 3: U_m^T p, eq. 1's right-hand side when nothing moves         */
    double *detail;  /* n x 3: to the next level, in world coordinates (d = next - p)       */
    double *coord;   /* n x 3: d in the rest skeleton's local frame (edge, cross, normal)   */
    dk_index *frame_nb; /* n: the neighbour whose edge gives the frame, -1: no valid frame */
} level;

/* What the constraints give: replaced as a whole by rebind. */
typedef struct eigen_regions {
    dk_constraints *user;    /* the caller's constraints, for region PART (NULL: HANDLES,
                                where they are con)                                         */
    eigen_parts parts;       /* PART: the groups each handle drags (part.h)                 */
    dk_constraints *con;     /* the groups R is made of                                     */
    dk_index *region;        /* n: the group, or -1 outside R                               */
    double *g, *w;           /* n: distance to the boundary of R; interpolation weight     */
    double delta3;
    /* the last request: per group the linear part of its motion (identity for targets given
     * as positions: the paper's translation-type motion, per vertex), and the Step-1 targets
     * of R's vertices */
    double *lin;             /* con->n_handles x 9                                          */
    double *target;          /* con->n_handle_vertices x 3                                  */
    double *utarget;         /* PART: user->n_handle_vertices x 3, the caller's targets     */
    double *uT, *gT;         /* PART: the handles' and the groups' transforms (x 16)        */
} eigen_regions;

struct dk_eigen {
    const dk_mesh *mesh;
    dk_eigen_options opt;
    dk_progress prog;        /* the bind's reporter (eigen_phases)                         */
    dk_index n;
    int K, m, n_levels;      /* n_levels 1 (one iteration) or 2 (section 4.3)              */
    int n_prime;             /* section 4.3's n': refine (plus the components' constants
                              * when m is automatic), at most K                          */
    double *evals, *U;       /* K; n x K column-major                                      */
    double *chol;            /* K x K column-major, upper: Phi_K = R^T R                   */
    level lv[2];
    eigen_regions r;         /* the regions and the last request's targets                  */
    int preview;             /* dk_eigen_set_preview                                        */
    /* scratch, allocated at bind */
    double *ptil, *pstar, *normals, *b, *next;
    double *cm;              /* n x 3 column-major, for the products with U                 */
    double tiny;             /* a skeleton edge shorter than this defines no frame (FRAME_*) */
};

/* The bind's phases (dk_progress.h). Weights: seconds measured on the 43k armadillo
 * (the armadillo-wave handle, K = 300, cotangent; 2 cores at a load of ~2): the
 * eigenvectors dominate at every size (713 s of the 1M ogre's bind, docs/methods/eigen.md). */
enum { EIGEN_PHASE_REGIONS, EIGEN_PHASE_OPERATOR, EIGEN_PHASE_EIGENVECTORS,
       EIGEN_PHASE_SKELETONS, EIGEN_N_PHASES };
extern const dk_progress_phase eigen_phases[EIGEN_N_PHASES]; /* spectrum.c */


/* eigen.c */
/** DK_ERR_OUT_OF_MEMORY saying what could not be allocated. */
dk_status eigen_oom(dk_error *err, const char *what);

/* spectrum.c */
/** The K eigenpairs of the chosen Laplacian into e->evals / e->U, Phi = U^T U and its
 *  Cholesky factor into e->chol (e->K, e->b set; reports the operator and eigenvectors
 *  phases). */
dk_status eigen_eigenvectors(dk_eigen *e, dk_error *err);

/* fit.c */
/** b (m x 3, column-major) = U_m^T x for x (n x 3, row-major); uses e->cm. */
void eigen_project(const dk_eigen *e, int m, const double *x, double *b);
/** Step 2: A = Phi_m^-1 b in place (b m x 3), out (n x 3 row-major) = U_m A; uses e->cm. */
void eigen_fit(const dk_eigen *e, int m, double *b, double *out);
/** Frees a level's arrays (zeroes it). */
void eigen_level_free(level *L);
/** The eigenvector count to fit with for a requested m (1 <= m <= K): m, unless the
 *  eigenvalues m and m + 1 (1-based) are one repeated eigenvalue, which a symmetric mesh
 *  has: then the end of that eigenspace when it ends within the K computed, else its start.
 *  Eq. 1 with part of an eigenspace depends on which basis of it the eigensolver returned
 *  (LAPACK's threads or ARPACK's start pick one), the whole eigenspace does not. */
int eigen_whole_count(const dk_eigen *e, int m);
/** The levels for m (and n' = K when the two-iteration scheme applies): skeletons, their
 *  right-hand sides, details and frames; m is taken to a whole eigenspace first
 *  (eigen_whole_count). */
dk_status eigen_skeletons(dk_eigen *e, int m, dk_error *err);
/** Step 1 on level L's skeleton into e->ptil, and Step 2's right-hand side into e->b. */
void eigen_step1_step2_rhs(dk_eigen *e, const level *L);

/* frames.c */
/** The length below which a skeleton edge defines no frame, for `mesh`. */
double eigen_frame_threshold(const dk_mesh *mesh);
/** Each vertex's frame neighbour on L's rest skeleton and its detail in that frame
 *  (`nrm`: n x 3 scratch). */
void eigen_record_frames(const dk_eigen *e, level *L, double *nrm);
/** Step 3 on level L: out (n x 3) = p* + the recovered details, blended by w (blend = 1) or
 *  in local frames alone. */
void eigen_step3(dk_eigen *e, const level *L, const double *pstar, int blend, double *out);

/* regions.c */
/** R from the caller's constraints for e's region option, with the request buffers at
 *  rest. On failure `R` is empty. */
dk_status eigen_regions_build(dk_eigen *e, const dk_constraint_desc *desc, eigen_regions *R,
                              dk_error *err);
/** Frees what `R` holds (zeroes it). */
void eigen_regions_free(eigen_regions *R);

/* request.c */
/** A solve's targets as the groups' Step-1 targets and linear parts (e->r); checked before
 *  anything is written. */
dk_status eigen_read_request(dk_eigen *e, const dk_solve_request *rq, dk_error *err);

#endif
