/* DeformKit ARAP, internal: the object, its constraint system and the functions the files of
 * native/methods/arap/ share. Not part of the public API (dk_arap.h is).
 *
 * Layout. The bind builds the cells once: for cell i (vertex i on a surface; see nc for a
 * volume), terms cell_start[i] .. cell_start[i+1]-1, each an edge (ta, tb) with a base weight tw and its rest vector
 * te = p_a - p_b. Everything that depends on the constraints lives in an arap_system (the
 * validated constraints, the unknown map, the reduced matrix and its factor, the
 * per-iteration buffers) that rebind replaces atomically.
 *
 * One iteration from positions x with rotations R (optimal for x) and energy E:
 *   g = G(x): solve A g = rhs(R)                      (global step, 3 right-hand sides)
 *   candidate = g, or the Anderson mix of the last m (x, g) pairs
 *   R', E', rhs(R') = local step, energy and next right-hand side at the candidate (one
 *                     pass over the cells; each R' refined from the previous rotation)
 *   if accelerated and E' > E: candidate = g (plain step, E' <= E is guaranteed), history
 *   is cleared; stop when E - E' <= tolerance * E.
 * A warm solve starts from the previous solution with the move of the constrained vertices
 * spread by one global step (previous rotations held); a cold one from the global step with
 * identity rotations. Acceleration NEWTON replaces the iteration by inexact Newton steps on
 * the same energy (newton_step), from the same starts.
 *
 * Files, one idea each:
 *   arap.c        the public verbs: options, bind, rebind, solve (a driver naming its
 *                 steps), energy, stats, the method-contract table
 *   cells.c       the cells: each vertex's weighted rest edges, or each tetrahedron's
 *   system.c      the constraint system: unknowns, component check, reduced matrix, its
 *                 factor (analysis reused by rebind), the right-hand-side map
 *   local_step.c  rotations (refined by Newton steps on SO(3)), energies, right-hand sides
 *   warm_start.c  where a solve starts (cold, warm, predicted along the drag) and the
 *                 history the predictor keeps
 *   anderson.c    local/global iterations, plain or Anderson-accelerated
 *   newton.c      inexact Newton steps with matrix-free Hessian products
 *   state.c       the state a solve leaves for the next call, saved and restored
 *   multiscale.c  the coarse level a cold start is solved on first, then prolonged
 */
#ifndef DK_ARAP_INTERNAL_H
#define DK_ARAP_INTERNAL_H

#include "dk_arap.h"

#include <math.h>
#include <stdint.h>
#include <stdlib.h>
#include <string.h>

#include "dk_cholesky.h"
#include "dk_csys.h"
#include "dk_operators.h"
#include "dk_parallel.h"
#include "dk_progress.h"
#include "dk_reorder.h"
#include "dk_sparse.h"

#define MAX_ANDERSON_DEPTH 20
/* Below this many cell terms the local step runs on the calling thread only. */
#define PARALLEL_TERMS 50000
/* Newton takes a plain local/global step while that step's predicted decrease (at least
 * r0.z0, see newton_step) exceeds this fraction of E. Far from a minimum (cold starts of big
 * deformations: the naive start) the Hessian is indefinite, damped Newton steps can jump into
 * another basin, and local/global steps, descending a majorizer, follow the energy downhill
 * into the basin the local/global solvers find. Chosen on 8 cold solves (bumpy-plane bends of
 * 1.2-2.4 rad, the three scenarios): pure Newton ended 23% above the local/global minimum on
 * the 1.5 rad bend; 0.5, 0.3 and 0.1 fixed that but sent arm-lift 2e-3 higher; 0.03 and 0.01
 * kept all eight in the local/global basin, 0.003 ran into max_iterations. Checked on 16
 * other cold solves (other bends, tube twists with and without a lift, the scenarios at half
 * and 1.5 times their translation): worst 2.3e-4 above Anderson's minimum with 0.03 (pure
 * Newton: 0.19 and 3e-3 on two of them), and 10% less time in all. Warm drag starts are at
 * ~5e-4, so drags are unaffected. */
#define NEWTON_FAR 0.03
/* A preview compares its two starts (plain, predicted) on about this many cells. */
#define PREVIEW_SAMPLE 16384

/* The multi-scale solve's coarse level (multiscale.c): the mesh simplified (dk_decimate,
 * internal numbering, each vertex's role kept) and an ARAP object bound on it for the
 * restricted constraints; buffers for its targets, pose, result and rotations, and the
 * prolonged start (fine: internal numbering, also the corrections' scratch). */
typedef struct arap_coarse {
    dk_decimation *dec;
    dk_mesh *mesh;
    dk_arap *arap;
    dk_index n_handle_vertices;
    dk_index *target_row; /* per coarse handle vertex: its row of the system's targets */
    double *targets, *pose, *y, *rot, *fine, *scratch;
    int starts;           /* cold starts it gave since it was built                     */
    /* the corrections (arap_coarse_correct): the coarse vectors in its vertex order (n_kept
     * x 3), its unknowns' blocks (3 of its nu), and the fine direction and product (3 nu) */
    double *cr, *cb, *cd, *fd, *fq;
    int corrections;      /* corrections taken since it was built                        */
    /* A level its owner attached (dk_arap_attach_coarse_level: a volume's coarse
     * tetrahedra) has no decimation (dec and mesh NULL) and borrows its object; its linear
     * maps instead, fine vertices in the internal numbering, coarse points in the coarse
     * object's caller numbering. Prolongation: fine vertex i = sum over q in
     * ps[i] .. ps[i+1]-1 of pw[q] times coarse point pc[q]; restriction of an iterate: coarse
     * point j = sum over q in rs[j] .. rs[j+1]-1 of rw[q] times fine vertex rc[q]. */
    int borrowed;
    int no_corrections;   /* its owner asked for the cold start only                      */
    dk_index cnu;         /* the coarse object's unknowns when attached: a rebind of it since
                             (its owner's misuse) makes the level unusable, not unsafe      */
    dk_index n_fine;      /* the mesh's vertices (rows of the prolongation)              */
    dk_index *ps, *pc, *rs, *rc;
    double *pw, *rw;
    double *cacc;         /* a coarse vector (n_coarse x 3): the restricted residual, then
                             the coarse direction                                         */
    double *cpose;        /* the rest or the input pose restricted (n_coarse x 3): attached
                             levels prolong the coarse result's move from it              */
} arap_coarse;

typedef struct arap_system {
    dk_constraints *con;
    dk_index nu;          /* unknowns: free vertices and soft handle vertices            */
    dk_index *unk;        /* n: unknown index or -1 (eliminated)                         */
    dk_index *unknowns;   /* nu: the vertices                                            */
    dk_index *target_of;  /* n: row into the expanded targets, or -1                     */
    double *soft_k;       /* n: penalty k_v of a soft handle vertex, 0 otherwise         */
    double *tws;          /* n_terms: stiffness x base weight                            */
    int64_t *bterms;      /* the terms with one eliminated and one unknown end, ascending
                             (the warm start's response reads only these)                */
    int64_t n_bterms;
    double escale;        /* sum over terms of tws |te|^2: the energy's natural scale    */
    double lambda;        /* mean diagonal of the ARAP part of A                         */
    dk_sparse a;          /* reduced matrix (both triangles), arrays owned               */
    dk_cholesky *chol;
    /* The global step's right-hand side is linear in the rotations: for unknown u (vertex
     * v), b_u = rhs_const_u + sum over the cells c with a term touching v of R_c g_{v,c},
     * g_{v,c} = sum of tws_t e_t over c's terms with ta = v minus those with tb = v. The
     * entries of u are rg[rg_start[u] .. rg_start[u+1]-1] (the cells are v and its
     * one-ring). A gather per unknown: each half of the pass writes its own rows, where
     * scattering each term's R_c e_t to both ends had needed a second buffer for the helper
     * thread and cost ~0.8 ms an iteration on the armadillo. */
    int64_t *rg_start;    /* nu + 1                                                       */
    struct rhs_entry { double g[3]; dk_index cell; } *rg;
    /* per-solve / per-iteration buffers, N = 3 nu, column-major n x 3 layouts */
    double *rhs_const, *rhs, *xu, *gu, *fu, *gprev, *fprev, *dg, *df;
    double *targets;      /* n_handle_vertices x 3: last expanded targets                */
    int have_targets;
    /* where the last solve stopped, for a resumed solve (DK_START_RESUME, same targets) */
    double *targets_prev; /* n_handle_vertices x 3: the targets it solved for            */
    double *targets_prev2; /* n_handle_vertices x 3: the targets of dk_arap's prev2      */
    double *warm;         /* 6 nu: the two warm-start responses (plain, predicted)       */
    int resumable, aa_hist, aa_head, aa_have_pair;
    int predicted;        /* the last warm start used the secant predictor                */
    int start_pending;    /* the iterate is a lazy start (a preview): its rotations, energy
                             and right-hand side are not computed yet (arap_start_complete) */
    double last_energy;
    double aa_gram[MAX_ANDERSON_DEPTH * MAX_ANDERSON_DEPTH];
    /* Newton (acceleration NEWTON) only, see newton_step: per cell K_c^-1 at the current
     * iterate (6: 00 01 02 11 12 22, zero where K_c is not safely positive definite) and
     * omega_c (3); the PCG direction in the mesh layout (n x 3, zero on eliminated
     * vertices); per right-hand-side entry R_c g_{v,c} (written with the right-hand side)
     * and the cell terms packed for the Hessian products, both in single precision: the
     * products only steer conjugate gradients (truncated far above that rounding), the
     * gradient, energies and line search stay in double, and halving these streams made a
     * product ~25% faster (memory-bound); the PCG vectors (N each) */
    double *kinv, *omega, *vfull;
    /* the current iterate comes from a Newton step cut to fewer CG iterations than bound
     * (dk_arap_set_cg_iterations) with no whole step since: the stopping test then waits
     * for a whole step (cut steps, like local/global ones, leave the slow bending modes
     * where the test's local/global prediction is small while the minimum is still away).
     * Cleared by a whole step and by a cold start; kept across warm starts. */
    int cut;
    /* the CG schedule's level (dk_arap_cg_schedule GROWING): whole Newton steps run
     * cg_iterations << cg_level iterations; set after each step from its relative decrease
     * (newton.c, cg_level_after), 0 at every start that is not a resume */
    int cg_level;
    /* the extrapolated-gap stopping test (newton.c, gap_small): the last Newton step's
     * decrease of E and the last two ratios of consecutive decreases ([0] the newer; 0:
     * not measured), all since the last start that was not a resume (arap_gap_restart);
     * and the rate the solve before ended with (0: none since the last cold start) */
    double nt_decrease, nt_ratio[2], nt_ratio_before;
    /* the last Newton step's CG met a clearly negative curvature (newton.c,
     * NEGATIVE_CURVATURE): E is not locally convex at the iterate, a saddle-like region where
     * steps can shrink for a while before they grow again, so the stopping test waits for
     * a step that did not (measured: 692k vertices, growing CG counts, a plateau of five
     * short steps whose decreases made the gap extrapolation stop 1.1e-4 of E above the
     * minimum). 0 at every start that is not a resume (arap_gap_restart) */
    int nt_indefinite;
    dk_index *a_vrow; /* per entry of a: the vertex of its row (products in the mesh layout) */
    struct nt_entry { float h[3]; dk_index cell; } *nt;
    struct nt_term { float e[3], w; dk_index a, b; } *ntt; /* the cell terms, packed */
    double *nt_r, *nt_z, *nt_p, *nt_q, *nt_d, *nt_z0;
    /* The warm start's response basis (response_basis.c; NULL when not built): per handle h
     * and j < 4, the column Z_{h,j} = A^-1 r_{h,j} (nu each, column (4h + j) of zb), the
     * global step's response to the hard vertices of h moved by their rest coordinate j
     * (x, y, z, or 1); zverts/zstart: those hard vertices per handle; zdx (3 per vertex) and
     * zfit (2 x 16 per handle): the fits' scratch. */
    double *zb, *zdx, *zfit;
    dk_index *zverts, *zstart;
    int zcols;
    arap_coarse *coarse;  /* the multi-scale solve's coarse level, NULL: none            */
    /* the Newton steps of this solve are followed by coarse corrections: set by a cold or
     * given start, cleared by a warm one, kept by a resume (arap.c, solve_rest) */
    int coarse_active;
} arap_system;

struct dk_arap {
    /* The mesh in the internal numbering (dk_reorder.h: breadth-first, for cache
     * locality); every array below uses it. The API maps at its boundary: constraints in
     * (rebind too), positions in and out, vertex numbers in messages (ro->perm). */
    const dk_mesh *mesh;
    const dk_mesh *caller_mesh;
    dk_reorder *ro;
    dk_arap_options opt;
    int cg;               /* CG iterations per Newton step of the next solves
                             (dk_arap_set_cg_iterations; opt.cg_iterations as bound)       */
    int cg_scheduled;     /* 1: the bound count, scaled by opt.cg_schedule (newton.c); 0: a
                             count given to dk_arap_set_cg_iterations, run as given          */
    dk_index n;
    /* The cells: one per vertex (nc == n) on a surface; on a volume (dk_arap_bind_tetrahedra)
     * a surface cell per vertex in no tetrahedron, then one per tetrahedron, whose corners
     * are cc[cc_start[c] .. cc_start[c + 1] - 1] (its vertex, or its four; both NULL on a
     * surface): a cell's stiffness is its corners' mean. rot (allocated for n + tetrahedra)
     * and Newton's kinv and omega are per cell. */
    dk_index nc;
    dk_index *cc_start, *cc;
    int64_t n_terms;
    dk_index *cell_start, *ta, *tb;
    double *tw, *te;
    /* The pose the solves edit (dk_solve_request.input_positions), internal numbering:
     * mesh->positions (the rest) or `input`; te and the system's vectors made from it
     * follow it (arap_cells_set_edges, arap_system_edges_changed), the weights tw and the
     * factor stay the bind's. input_next: the next request's pose, read before anything
     * changes. Both NULL until a request gives one. */
    const double *base;
    double *input, *input_next;
    arap_system sys;
    double *x;            /* n x 3 row-major current positions                           */
    double *rot;          /* nc x 9 rotations, one per cell                              */
    double *prev;         /* n x 3 previous solution (warm start)                        */
    int have_prev;
    /* secant predictor of a warm start: prev2 (n x 3) is the end of the last call before
     * the previous one with other targets; n_hist counts how many of prev (with
     * sys.targets_prev) and prev2 (with sys.targets_prev2) hold ends of calls under the
     * current constraints */
    double *prev2;
    int n_hist;
    int analysis_count, factorization_count;
    int basis_starts;     /* warm starts that combined the response basis                 */
    dk_team *team;        /* the passes' and the factor's helper thread (NULL: per pass)  */
    /* during a bind or rebind only (NULL otherwise): its progress reporter, and the index
     * of ARAP_PHASE_CONSTRAINTS in its phase table (the system's phases follow it) */
    dk_progress *prog;
    int prog_base;
};

/* The phases of a bind and a rebind, relative to ARAP_PHASE_CONSTRAINTS (arap.c has the
 * tables and their measured weights). */
enum {
    ARAP_PHASE_CONSTRAINTS = 0, /* validating the constraints, the unknowns, the weights    */
    ARAP_PHASE_SYSTEM = 1,      /* solve buffers, right-hand-side map, component check      */
    ARAP_PHASE_ASSEMBLE = 2,    /* the reduced matrix                                      */
    ARAP_PHASE_ANALYZE = 3,     /* CHOLMOD's symbolic analysis (uninterruptible)            */
    ARAP_PHASE_FACTORIZE = 4,   /* CHOLMOD's numeric factorization (uninterruptible)        */
    ARAP_PHASE_BASIS = 5,       /* the warm start's response basis: one solve of 4 columns
                                   per handle (uninterruptible)                            */
    ARAP_PHASE_COARSE = 6       /* the multi-scale solve's coarse level: simplification and
                                   its bind (uninterruptible)                              */
};

/* dk_progress_begin / dk_progress_tick for a system phase of the running bind or rebind */
static inline dk_status arap_phase(const dk_arap *ar, int k, dk_error *err)
{
    return dk_progress_begin(ar->prog, ar->prog_base + k, err);
}
static inline dk_status arap_tick(const dk_arap *ar, double done, double total, dk_error *err)
{
    return dk_progress_tick(ar->prog, done, total, err);
}

/* The progress of one solve's iterations, handed from the start to the iteration loop. */
typedef struct arap_progress {
    double energy;  /* of the current iterate                                             */
    double tiny;    /* an energy at or below this is a rigid motion: converged             */
    int iterations, converged, rejected, cg_total;
} arap_progress;

static inline dk_status oom(dk_error *err, const char *what)
{
    return dk_error_set(err, DK_ERR_OUT_OF_MEMORY, "ARAP: out of memory (%s)", what);
}

/* a . b (returned) and a . c (into *ac) in one pass over a, each with four partial sums: a
 * single running sum is one floating-point add latency per element (~4 cycles), which made
 * Anderson's dot products cost ~1 ms an iteration on the armadillo; four chains run at the
 * loads' speed. The order of summation is fixed, so the results stay reproducible. */
static inline double dot2(const double *a, const double *b, const double *c, size_t n, double *ac)
{
    double s0 = 0.0, s1 = 0.0, s2 = 0.0, s3 = 0.0, t0 = 0.0, t1 = 0.0, t2 = 0.0, t3 = 0.0;
    size_t k = 0;
    for (; k + 4 <= n; k += 4) {
        s0 += a[k] * b[k];
        s1 += a[k + 1] * b[k + 1];
        s2 += a[k + 2] * b[k + 2];
        s3 += a[k + 3] * b[k + 3];
        t0 += a[k] * c[k];
        t1 += a[k + 1] * c[k + 1];
        t2 += a[k + 2] * c[k + 2];
        t3 += a[k + 3] * c[k + 3];
    }
    for (; k < n; k++) {
        s0 += a[k] * b[k];
        t0 += a[k] * c[k];
    }
    *ac = (t0 + t1) + (t2 + t3);
    return (s0 + s1) + (s2 + s3);
}


static inline double dist2(const double *p, const double *q)
{
    double d0 = p[0] - q[0], d1 = p[1] - q[1], d2 = p[2] - q[2];
    return d0 * d0 + d1 * d1 + d2 * d2;
}

/* cells.c; arap_cells_set_edges: te from the positions p (n x 3, internal numbering);
 * arap_build_volume_cells: the cells of a volume, `tets` (nt x 4, internal numbering) and
 * the surface of what no tetrahedron holds (see dk_arap_bind_tetrahedra) */
dk_status arap_build_cells(dk_arap *ar, dk_error *err);
dk_status arap_build_volume_cells(dk_arap *ar, const dk_index *tets, dk_index nt,
                                  dk_error *err);
void arap_cells_set_edges(dk_arap *ar, const double *p);

/* system.c: builds a complete system for `desc`; `old` (may be NULL) lends its symbolic
 * analysis when the unknown set is the same (it is then moved into the new system). */
dk_status arap_system_build(dk_arap *ar, const dk_constraint_desc *desc, arap_system *old,
                            arap_system *s, dk_error *err);
void arap_system_free(arap_system *s);
/* system.c: after ar->te changed (a new base): the parts of s made from it, the energy's
 * scale, the right-hand-side map's vectors and Newton's packed terms */
void arap_system_edges_changed(const dk_arap *ar, arap_system *s);

/* local_step.c: the rotations optimal for x (refined from `rot`), into rot, and the energy
 * at x (arap_local_energy; rot may be NULL: energy only); the right-hand side of the next
 * global step from the rotations (arap_rotations_rhs); its part from the eliminated
 * vertices (arap_build_rhs_const); unknowns <-> mesh layout (arap_scatter, arap_gather) */
double arap_local_energy(const dk_arap *ar, const arap_system *s, const double *x,
                         double *rot);
void arap_rotations_rhs(const dk_arap *ar, arap_system *s, const double *rot);
/* the energy of one block of 64 consecutive cells in every `stride` (rotations refined from
 * ar->rot, which is left as it is) plus every soft penalty: the preview's cheap comparison
 * of two starts (warm_start.c) */
double arap_sampled_energy(const dk_arap *ar, const arap_system *s, const double *x,
                           dk_index stride);
void arap_build_rhs_const(const dk_arap *ar, arap_system *s, const double *x);
void arap_scatter(const arap_system *s, const double *xu, double *x);
void arap_gather(const arap_system *s, const double *x, double *xu);

/* warm_start.c: sets the iterate where a solve starts (ar->x, ar->rot, s->xu, s->rhs) and
 * its energy; `given` (DK_START_GIVEN, n x 3 in the caller's vertex order, checked finite;
 * with `given_internal`, in the internal order: the coarse level's prolonged start):
 * from those positions, `warm` and `lazy` ignored; `warm`: from the previous solution (there
 * must be one). `lazy` (a preview):
 * positions only (ar->x, s->xu), the predictor taken whenever the drag goes on, energy NaN,
 * s->start_pending set; arap_start_complete then does the rest (rotations, energy,
 * right-hand side) before any iteration. After the solve, arap_keep_history records its end
 * for the next warm start's predictor. */
dk_status arap_start(dk_arap *ar, arap_system *s, const double *given, int given_internal,
                     int warm, int lazy, double *energy, dk_error *err);
dk_status arap_start_complete(dk_arap *ar, arap_system *s, double *energy, dk_error *err);
void arap_keep_history(dk_arap *ar, arap_system *s, int warm_start);

/* response_basis.c: builds the basis after the factorization (skipped, zb NULL, when off,
 * over the limits or out of memory: it is only a speed-up); frees it; and, when the moves
 * of the eliminated vertices from the base x1 (plain) and from x1 + alpha (x1 - x2)
 * (predict) to ar->x are one affine map per handle with the fixed ones unmoved, writes the
 * responses into w (3 nu each, column-major, plain then predicted) and returns 1; else 0
 * (nothing written: back-substitute). */
void arap_response_basis_build(dk_arap *ar, arap_system *s);
void arap_response_basis_free(arap_system *s);
int arap_response_basis_apply(dk_arap *ar, arap_system *s, const double *x1, const double *x2,
                              double alpha, int predict, double *w);

/* anderson.c, newton.c: iterate from p until converged or max_iterations in all */
dk_status arap_iterate_local_global(dk_arap *ar, arap_system *s, int max_iterations,
                                    arap_progress *p, dk_error *err);
/* A start that is not a resume: the stopping test's decreases start again, the rate the
 * last solve ended with is kept for the new one's first steps (cold: forgotten too). */
void arap_gap_restart(arap_system *s, int cold);
dk_status arap_iterate_newton(dk_arap *ar, arap_system *s, int max_iterations,
                              arap_progress *p, dk_error *err);

/* multiscale.c: the coarse level for the constraints of `s` (*out NULL: none, by the
 * levels option, the mesh's size, or a coarse mesh that would not bind); the cold start it
 * gives (*start: n x 3 in the internal order, owned by the level and valid until its next
 * correction; NULL: none this time) */
dk_status arap_coarse_build(dk_arap *ar, const arap_system *s, arap_coarse **out, dk_error *err);
dk_status arap_coarse_start(dk_arap *ar, arap_system *s, const double **start, dk_error *err);
void arap_coarse_free(arap_coarse *c);
/* multiscale.c: after a Newton step (the iterate's rotations, K^-1 and right-hand side in
 * place), the coarse level's correction of the slow modes: the gradient restricted, the
 * coarse Hessian's Newton direction at the restricted iterate, prolonged, a line search on
 * E; *energy lowered when it is taken (the iterate's data with it), unchanged when not */
dk_status arap_coarse_correct(dk_arap *ar, arap_system *s, double *energy, int *products,
                              dk_error *err);
/* newton.c: out = rhs - A x at the iterate (minus half the gradient over the unknowns, 3
 * blocks of nu); out = H v (returns v . H v); the Newton direction out ~ H^-1 rhs by at
 * most maxit conjugate-gradient products preconditioned by A^-1, from 0, ending at
 * non-positive curvature (the first: out = A^-1 rhs). Use s->nt_r, nt_z, nt_p, nt_q, vfull. */
dk_status arap_minus_gradient(dk_arap *ar, arap_system *s, double *out);
double arap_hessian_product(dk_arap *ar, arap_system *s, const double *v, double *out);
dk_status arap_newton_direction(dk_arap *ar, arap_system *s, const double *rhs, double *out,
                                int maxit, int *products, dk_error *err);

#endif
