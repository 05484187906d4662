/* DeformKit embedded deformation, internal: the object and the functions the files of
 * native/methods/embedded/ share. Not part of the public API (dk_embedded.h is).
 *
 * Files, one idea each:
 *   nodes.c     the deformation graph's nodes: surface samples thinned to a radius, or mesh
 *               vertices (section 3 of the paper)
 *   weights.c   each vertex's k nodes and their weights (eq. 4), Euclidean or along the
 *               surface, and the cut between two vertex groups
 *   graph.c     the graph's edges (nodes that influence a common vertex) and adjacency
 *   system.c    the fixed nodes, J^T J's block pattern
 *   energy.c    F (eq. 9) with J^T f and J^T J's parts
 *   schur.c     each step through the system reduced to the translations: the rotation
 *               parts eliminated node by node, the rest factorized
 *   solve.c     Gauss-Newton with Levenberg-Marquardt damping and eq. 12's tests; eq. 2
 *   embedded.c  options, bind, rebind, source updates, state, normals, points, the table
 *
 * Layout of the unknowns: free node u owns columns 12 u + a, a = 3 d + e for R[d][e] (row
 * major) and a = 9 + d for t[d]. J^T J = I_3 (x) K + D(x): K, the regularization's and
 * the positional terms' part for one coordinate, is kept as 4 x 4 blocks (slots R[d][0..2],
 * t[d]), one per ordered pair of free nodes that share a residual (an edge, or a
 * constrained vertex both influence), block (u, v) at position rank_u(v) among u's sorted
 * block list; D, E_rot's part, as one 9 x 9 block per free node. The reduced system's
 * pattern (schur.c) depends on the graph and the constrained vertices only, so it is
 * analysed once per bind or rebind.
 */
#ifndef DK_EMBEDDED_INTERNAL_H
#define DK_EMBEDDED_INTERNAL_H

#include "dk_embedded.h"

#include <float.h>
#include <limits.h>
#include <math.h>
#include <stdint.h>
#include <stdlib.h>
#include <string.h>

#include "dk_cholesky.h"
#include "dk_operators.h"
#include "dk_parallel.h"
#include "dk_sparse.h"

#define K_MAX 16

typedef struct ed_system {
    dk_constraints *con;
    dk_index n_free;            /* free nodes                                               */
    dk_index *node_unknown;     /* m: free index or -1 (a constant node)                    */
    dk_index *free_nodes;       /* n_free: the nodes                                        */
    /* the positional terms: handle vertices (targets from the request) and held fixed
     * vertices (target: rest) */
    dk_index n_pos, n_pos_moving; /* the first n_pos_moving involve a free node           */
    dk_index *pos_vertex;       /* n_pos                                                    */
    dk_index *pos_target_row;   /* n_pos: row in the expanded handle targets, or -1 (rest)  */
    double *targets;            /* n_handle_vertices x 3                                    */
    double f_constant;          /* F's terms of constant nodes only, for the solve's targets */
    /* J^T J blocks: per free node u, blk_start[u] .. blk_start[u+1]-1 into blk_node (sorted
     * free indices v) */
    dk_index *blk_start, *blk_node;
    int64_t n_blocks;
    double *kblk;               /* n_blocks x 16: K, block b's entry (a, c) at 16 b + 4 a + c
                                   (a, c: 0..2 R[d][.], 3 t[d]), for the source at hand      */
    int k_stale;                /* the source moved since kblk was made                      */
    double *rot;                /* n_free x 81: E_rot's J^T J over each node's R (row major) */
    unsigned char *kept;        /* n_free: a positional term couples its R with another free
                                   node's, so R stays in the reduced system                 */
    /* per ordered edge (j -> k, both free or not): the block indices (j,j), (j,k), (k,j),
     * (k,k), -1 where a node is constant */
    int64_t *edge_blk;          /* 4 per directed edge                                       */
    /* per positional term, per pair (p, q) of its nodes: the block index, -1 if constant  */
    int64_t *pos_blk;           /* n_pos x k x k                                             */
    /* the reduced system (schur.c) */
    dk_index n_red;             /* its unknowns                                             */
    dk_index *base;             /* n_free: each node's first reduced unknown                */
    dk_index *red;              /* 12 n_free: each unknown's reduced index, -1 eliminated   */
    dk_index *nl_start, *nl_node, *nl_off; /* per node w, the nodes v <= w its columns meet
                                   (sorted) and the rows before v in each of them           */
    dk_sparse *S;               /* the matrix, upper triangle                               */
    double *S_base;             /* its part that does not change with x or mu               */
    double *S_part;             /* the second half of the nodes' part (ed_reduced_factorize) */
    int64_t *S_diag;            /* n_red: where each diagonal entry is                      */
    int64_t *cl_start;          /* n_free + 1: each eliminated node's clique entries        */
    dk_index *cl_pos;           /* where each sits in S                                     */
    int64_t *w_start;           /* n_free + 1: each eliminated node's W = L^-1 C (9 x 3 nc) */
    double *W;
    double *lfac;               /* n_free x 81: each eliminated node's 9 x 9 factor         */
    double *rhs;                /* n_red                                                    */
    dk_cholesky *chol;
    double *grad, *step, *x_try; /* 12 n_free each; x_try: 12 m                             */
    double *grad_spare, *rot_spare; /* J^T f and rot at a trial point (solve.c)            */
} ed_system;

struct dk_embedded {
    const dk_mesh *mesh;
    dk_embedded_options opt;
    dk_index n, m, k;
    double *g;                  /* m x 3 node positions                                     */
    double *p;                  /* n x 3 the source's positions: the mesh's at bind, then
                                   what dk_embedded_update_source gave                      */
    dk_index *node_vertex;      /* m: the vertex each node sits on; NULL for surface samples */
    dk_index *node_face;        /* m: surface samples: the triangle each node lies on       */
    double *node_bary;          /* m x 2: and its coordinates (s, t): a + s(b - a) + t(c - a)  */
    dk_index *nb;               /* n x k: each vertex's nodes                               */
    unsigned char *vside;       /* n: 0, 1 (cut group A) or 2 (B); NULL without a cut       */
    unsigned char *nside;       /* m: the side of each node's nearest vertex                */
    double *w;                  /* n x k: their weights                                     */
    dk_index n_edges;
    dk_index *edges;            /* n_edges x 2, i < j                                       */
    dk_index *adj_start, *adj;  /* directed adjacency (both directions), sorted              */
    double *x;                  /* m x 12: the current transformations                      */
    double L;                   /* the unit of length of F: ed_unit_length() of the bind
                                   mesh; see ed_evaluate()                                  */
    double energy;              /* F of x for the last solve's targets                      */
    ed_system sys;
    int analysis_count, factorization_count;
    dk_team *team;              /* the factor's two-thread substitutions' helper (NULL: per
                                   sweep)                                                   */
    dk_progress *prog;          /* during a bind or rebind only (NULL otherwise)             */
};

/* The largest graph: n_nodes' bound, and what a radius may keep. */
enum { ED_MAX_NODES = 100000 };
/* The smallest radius, relative to the extent of the samples: below it the sampling grid's
 * cell numbers would not fit an int64 (and no graph that small could be bound anyway). */
#define ED_MIN_RADIUS 1e-12
/* the vertices one k-d tree query of the weights takes between two progress reports */
enum { ED_QUERY_CHUNK = 65536 };

static inline int slot_coord(int a)
{
    return a < 9 ? a / 3 : a - 9;
}

static inline int coord_slot(int d, int c)
{
    return c < 3 ? 3 * d + c : 9 + d;
}

static inline int cmp_index(const void *a, const void *b)
{
    const dk_index x = *(const dk_index *)a, y = *(const dk_index *)b;
    return (x > y) - (x < y);
}

static inline int cmp_i64(const void *a, const void *b)
{
    const int64_t x = *(const int64_t *)a, y = *(const int64_t *)b;
    return (x > y) - (x < y);
}

/* Sides of a cut: 0 none, 1 group A, 2 group B; two sides are across when both are set
 * and differ. */
static inline int across(unsigned char a, unsigned char b)
{
    return a && b && a != b;
}

/* embedded.c: an out-of-memory error naming what was being made. */
dk_status ed_oom(dk_error *err, const char *what);

/* nodes.c: the graph's nodes (ed->g, ed->m, and node_vertex or node_face + node_bary) for
 * ed->mesh and ed->opt. */
dk_status ed_sample_nodes(dk_embedded *ed, dk_error *err);

/* weights.c: each vertex's k nodes and weights (ed->nb, ed->w; the cut's sides). */
dk_status ed_weights(dk_embedded *ed, dk_error *err);

/* weights.c: the k nearest of the tree's nodes for `n` points (n x 3), with the weights of
 * eq. 4, into nb and w (n x k each); k + 1 <= the tree's nodes. `only` (n, or NULL for all)
 * skips the points where it is 0; `prog` (may be NULL) gets the phase's part done. */
dk_status ed_embed_points(const dk_kdtree *tree, const double *points, dk_index n,
                          dk_index k, const unsigned char *only, dk_index *nb, double *w,
                          dk_progress *prog, dk_error *err);

/* graph.c: the graph's edges and adjacency from the weights. */
dk_status ed_edges(dk_embedded *ed, dk_error *err);

/* system.c: the system for the constraints `desc` (phase: the index of "constraints" in the
 * running bind's or rebind's phase table), and its release. */
dk_status ed_system_build(dk_embedded *ed, const dk_constraint_desc *desc, ed_system *s,
                          int phase, dk_error *err);
void ed_system_free(ed_system *s);

/* system.c: the block of free nodes (u, v), or -1 when either is constant or they share no
 * residual. */
int64_t ed_block_of(const ed_system *s, dk_index u, dk_index v);

/* energy.c: the unit of length of F for the n points p (n x 3). */
double ed_unit_length(const double *p, dk_index n);

/* what ed_evaluate() also computes into `s`, and which terms it sums: ED_MOVING those some
 * free node enters, ED_CONSTANT the others (neither: all) */
enum { ED_GRADIENT = 1, ED_QUADRATIC = 2, ED_MOVING = 4, ED_CONSTANT = 8 };

/* energy.c: F(x) (eq. 9) for the transformations x (m x 12); with `s`, also J^T f and
 * E_rot's part of J^T J (ED_GRADIENT) or K (ED_QUADRATIC) into s. */
double ed_evaluate(const dk_embedded *ed, ed_system *s, const ed_system *sys, const double *x,
                   unsigned what);

/* schur.c: the reduced system's pattern, its analysis and K (after system.c's pattern). */
dk_status ed_reduced_build(dk_embedded *ed, ed_system *s, dk_error *err);

/* schur.c: K and the reduced system's constant part for the source at hand. */
void ed_reduced_refresh(const dk_embedded *ed, ed_system *s);

/* schur.c: factorizes J^T J + mu I reduced (s->grad's point: s->rot and K), the nodes'
 * eliminations split over `team` (may be NULL);
 * DK_ERR_NOT_POSITIVE_DEFINITE when it is not. */
dk_status ed_reduced_factorize(ed_system *s, double mu, dk_team *team, dk_error *err);

/* schur.c: the step (s->step, 12 n_free) solving (J^T J + mu I) step = -J^T f with the
 * last factorization. */
dk_status ed_reduced_solve(ed_system *s, dk_error *err);

/* schur.c: J^T J's trace. */
double ed_reduced_trace(const ed_system *s);

/* solve.c: every node the identity (x: m x 12). */
void ed_identity(double *x, dk_index m);

/* solve.c: eq. 2 for every vertex with the transformations x (m x 12) into out (n x 3). */
void ed_apply(const dk_embedded *ed, const double *x, double *out);

#endif
