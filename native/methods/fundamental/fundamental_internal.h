/* DeformKit linear reconstruction from discrete fundamental forms, internal: the object and
 * the functions the files of native/methods/fundamental/ share. Not part of the public API
 * (dk_fundamental.h is; docs/methods/fundamental.md has the choices).
 *
 * Files, one idea each:
 *   forms.c        the fundamental forms: each face's frame and cotangents, each interior
 *                  edge's rotation between its faces' frames, the fins of non-manifold
 *                  edges, and the pieces the frame equations join (with their bridges)
 *   residuals.c    the energy's residuals, visited one by one: the matrices assembled from
 *                  them, and the energy of positions
 *   elimination.c  the constraints: the unknowns' numbering, the pieces' check, the
 *                  factorization and the transform basis
 *   fundamental.c  the public verbs (bind, rebind, solve, ...) and the bind's phases
 */
#ifndef DK_FUNDAMENTAL_INTERNAL_H
#define DK_FUNDAMENTAL_INTERNAL_H

#include "dk_fundamental.h"

#include "dk_cholesky.h"
#include "dk_progress.h"
#include "dk_sparse.h"

/* The phases of a bind and of a rebind (dk_progress.h), weighted by their cost in seconds
 * measured on the ogre subdivided once (248,324 vertices, 1.56M unknowns; bench_scale.py's
 * ogre scenario: the lowest 10% fixed, one handle, so a 7-column transform basis) on the
 * shared 2-core machine (load ~1.4), timed between the callback's reports: 17.7 s in all.
 * On the 692k armadillo (load ~6, no basis: it would pass 256 MB) the same phases took
 * 4.8, 0.25, 18.0, 42.0 and 114.4 s of 179 s, about the same shares; the factorization is
 * the longest stretch without a report. Within "forms": the faces ~0.2 of it, the edge
 * rotations ~0.7 (asked every few thousand edges), the pieces ~0.1. The rebind's phases
 * are the bind's from FR_PHASE_CONSTRAINTS on, in the same order. */
enum {
    FR_PHASE_CONSTRAINTS = 0, /* the constraints, the numbering, the pieces' check          */
    FR_PHASE_ASSEMBLE = 1,    /* the energy's matrices, two passes over the residuals       */
    FR_PHASE_ANALYZE = 2,     /* CHOLMOD's symbolic analysis (uninterruptible)             */
    FR_PHASE_FACTORIZE = 3,   /* CHOLMOD's numeric factorization (uninterruptible)         */
    FR_PHASE_BASIS = 4        /* the transform basis: its right-hand sides and solves      */
};

/* The weight, relative to w, that draws the frames of an under-constrained component to
 * their rest frames (see fr_eliminate, elimination.c). */
#define REGULARIZATION 1e-8

/* What depends on the constraints, replaced as a whole by rebind. */
typedef struct elim {
    dk_constraints *con;
    dk_index n_unk, n_con;     /* per coordinate                                             */
    int any_anchor;            /* some face is regularized (fa >= 0)                         */
    dk_index *vu, *vc;         /* n: free / constrained index of each vertex, or -1          */
    dk_index *fu, *fc;         /* F: first of the frame's 3 free / constrained indices, or -1 */
    dk_index *face_handle;     /* F: the handle prescribing the frame, -2 fixed, -1 none     */
    dk_index *fa;              /* F: first of the 3 constrained slots holding the anchor
                                  frame row a regularized face is drawn to, or -1            */
    dk_sparse *A, *B;          /* n_unk x n_unk (upper triangle; freed once factored);
                                  n_unk x n_con                                               */
    dk_cholesky *chol;
    double *zc, *rhs, *lin, *tgt; /* solve buffers                                           */
    /* The transform basis (NULL when not built): the solution is affine in the handles'
     * transforms, z_d = S_d + sum_{h,j} T_h[d][j] G_{4h+j} for coordinate d, so a solve
     * with transforms is one small dense product instead of two triangular solves.
     * basis: n_unk x (4 n_handles + 3) column-major, G then S; coef: (4 n_handles) x 3. */
    double *basis, *coef;
} elim;

struct dk_fundamental {
    const dk_mesh *mesh;
    dk_fundamental_options opt;
    double *material;          /* n_edges                                                    */
    /* the fundamental forms, per face and per interior edge */
    unsigned char *degenerate; /* F                                                          */
    double *coord;             /* F x 6: the corners' 2-D coordinates in the face's frame    */
    double *cot;               /* F x 3: clamped cot of the angle at corner k                */
    double *rest_frame;        /* F x 9                                                      */
    double *R;                 /* n_edges x 9                                                */
    unsigned char *has_R;      /* n_edges                                                    */
    /* Pieces and bridges (see fr_pieces_and_bridges): the frame equations join faces across
     * interior edges only, so faces meeting at a vertex alone (a part pinched on at its
     * corners) or across a degenerate triangle are not joined by them. */
    dk_index *piece;           /* n_vertices: the piece (vertices joined through faces that
                                  have a frame), 0..n_pieces-1                               */
    dk_index n_pieces;
    dk_index *piece_rep;       /* n_pieces: a vertex of each, for messages                   */
    /* Fins (see fr_fin_pairs): a non-manifold edge's faces, joined by frame equations between
     * neighbours in their order around the edge. */
    dk_index n_fins;
    dk_index *fin;             /* n_fins x 3: faces i, j and their edge                      */
    double *fin_R;             /* n_fins x 9: f_i^T f_j of the rest frames                   */
    dk_index n_bridges;
    dk_index *bridge;          /* n_bridges x 2: faces i, j whose frames are tied weakly     */
    double *bridge_R;          /* n_bridges x 9: f_i^T f_j of the rest frames              */
    elim el;                   /* the elimination of the current constraints             */
    double *frames;            /* F x 9: the last solve's frames                          */
    double *comp_fit;          /* n_pieces x 25: per piece, the sums for the
                                  rotation that best fits its constrained vertices (count,
                                  rest sum 3, target sum 3, cross moments 9) and R (9)       */
    double w_scaled;           /* w times the mean edge length squared: E_f is dimensionless
                                  and E_x a squared length, so this keeps w scale-free      */
    /* during a bind or rebind only (NULL otherwise): its progress reporter, and the index
     * of FR_PHASE_CONSTRAINTS in its phase table */
    dk_progress *prog;
    int prog_base;
};

/* fundamental.c: starts phase k (FR_PHASE_*) of the running bind or rebind. */
dk_status fr_phase(const dk_fundamental *f, int k, dk_error *err);
/* fundamental.c: the out-of-memory error naming `what`. */
dk_status fr_oom(dk_error *err, const char *what);

/* forms.c: o = a b (3 x 3, row-major; o may be a or b). */
void fr_mat_mul(const double a[9], const double b[9], double o[9]);
/* forms.c: the corner (0..2) of face t at vertex v, or -1. */
int fr_corner_of(const dk_mesh *m, dk_index t, dk_index v);
/* forms.c: each face's frame, 2-D corner coordinates and clamped cotangents. */
void fr_faces(dk_fundamental *f);
/* forms.c: each interior edge's rotation between its faces' frames. */
dk_status fr_edge_rotations(dk_fundamental *f, dk_error *err);
/* forms.c: the fins of the non-manifold edges. */
dk_status fr_fin_pairs(dk_fundamental *f, dk_error *err);
/* forms.c: the pieces the frame equations join, and the bridges that tie them. */
dk_status fr_pieces_and_bridges(dk_fundamental *f, dk_error *err);

/* residuals.c: A (nu x nu, upper triangle) and B (nu x ncon) of the energy under the
 * numbering of `view` (its el). */
dk_status fr_assemble(const dk_fundamental *view, dk_index nu, dk_index ncon, dk_sparse **A,
                      dk_sparse **B, dk_error *err);
/* residuals.c: the energy of the positions (n_vertices x 3) with the last solve's frames. */
double fr_energy(const dk_fundamental *f, const double *positions);

/* elimination.c: the elimination of the constraints `desc` into s (zeroed; freed on
 * failure). */
dk_status fr_eliminate(const dk_fundamental *f, const dk_constraint_desc *desc, elim *s,
                       dk_error *err);
/* elimination.c: frees s's arrays. */
void fr_elim_free(elim *s);
/* elimination.c: makes s f's elimination (the old one freed). */
void fr_elim_install(dk_fundamental *f, elim *s);

#endif
