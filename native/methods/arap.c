/* DeformKit: As-Rigid-As-Possible deformation. See dk_arap.h for the energy, weights and
 * constraints; docs/methods/arap.md for the choices and measurements.
 *
 * Layout. The bind builds the cells once: for vertex i, terms cell_start[i] ..
 * cell_start[i+1]-1, each an edge (ta, tb) with a base weight tw and its rest vector
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
 */
#include "dk_arap.h"

#include <math.h>
#include <stdlib.h>
#include <string.h>

#include "dk_cholesky.h"
#include "dk_operators.h"
#include "dk_parallel.h"
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
    dk_index *a_vrow; /* per entry of a: the vertex of its row (products in the mesh layout) */
    struct nt_entry { float h[3]; dk_index cell; } *nt;
    struct nt_term { float e[3], w; dk_index a, b; } *ntt; /* the cell terms, packed */
    double *nt_r, *nt_z, *nt_p, *nt_q, *nt_d, *nt_z0;
} arap_system;

struct dk_arap {
    /* The mesh in the internal numbering (dk_reorder.h: breadth-first, for cache
     * locality); every array below uses it. The API maps at its boundary: constraints in
     * (rebind too), positions in and out, vertex numbers in messages (ro->perm). */
    const dk_mesh *mesh;
    const dk_mesh *caller_mesh;
    dk_reorder *ro;
    dk_arap_options opt;
    dk_index n;
    int64_t n_terms;
    dk_index *cell_start, *ta, *tb;
    double *tw, *te;
    arap_system sys;
    double *x;            /* n x 3 row-major current positions                           */
    double *rot;          /* n x 9 rotations                                             */
    double *prev;         /* n x 3 previous solution (warm start)                        */
    int have_prev;
    /* secant predictor of a warm start: prev2 (n x 3) is the end of the last call before
     * the previous one with other targets; n_hist counts how many of prev (with
     * sys.targets_prev) and prev2 (with sys.targets_prev2) hold ends of calls under the
     * current constraints */
    double *prev2;
    int n_hist;
    int analysis_count, factorization_count;
    dk_team *team;        /* the passes' and the factor's helper thread (NULL: per pass)  */
};

static dk_status oom(dk_error *err, const char *what)
{
    return dk_error_set(err, DK_ERR_OUT_OF_MEMORY, "ARAP: out of memory (%s)", what);
}

void dk_arap_default_options(dk_arap_options *o)
{
    if (!o)
        return;
    o->energy = DK_ARAP_SPOKES;
    o->weights = DK_ARAP_WEIGHTS_CLAMPED_COTANGENT;
    o->max_iterations = 100;
    o->tolerance = 1e-6;
    o->acceleration = DK_ARAP_ACCEL_NEWTON;
    o->anderson_depth = 5;
    o->cg_iterations = 12;
    o->predict = 1;
    o->on_iteration = NULL;
    o->user = NULL;
}

static dk_status check_options(const dk_arap_options *o, dk_error *err)
{
    if (o->energy != DK_ARAP_SPOKES && o->energy != DK_ARAP_SPOKES_AND_RIMS)
        return dk_error_set(err, DK_ERR_INVALID_ARGUMENT,
                            "ARAP: unknown energy %d (spokes = 0, spokes_and_rims = 1)",
                            (int)o->energy);
    if (o->weights != DK_ARAP_WEIGHTS_COTANGENT &&
        o->weights != DK_ARAP_WEIGHTS_CLAMPED_COTANGENT && o->weights != DK_ARAP_WEIGHTS_UNIFORM)
        return dk_error_set(err, DK_ERR_INVALID_ARGUMENT,
                            "ARAP: unknown weights %d (cotangent = 0, clamped_cotangent = 1, "
                            "uniform = 2)", (int)o->weights);
    if (o->max_iterations < 1)
        return dk_error_set(err, DK_ERR_INVALID_ARGUMENT,
                            "ARAP: max_iterations is %d, must be >= 1", o->max_iterations);
    if (!(isfinite(o->tolerance) && o->tolerance >= 0.0))
        return dk_error_set(err, DK_ERR_INVALID_ARGUMENT,
                            "ARAP: tolerance is %g, must be finite and >= 0", o->tolerance);
    if (o->acceleration != DK_ARAP_ACCEL_NONE && o->acceleration != DK_ARAP_ACCEL_ANDERSON &&
        o->acceleration != DK_ARAP_ACCEL_NEWTON)
        return dk_error_set(err, DK_ERR_INVALID_ARGUMENT,
                            "ARAP: unknown acceleration %d (none = 0, anderson = 1, newton = 2)",
                            (int)o->acceleration);
    if (o->cg_iterations < 1 || o->cg_iterations > 100)
        return dk_error_set(err, DK_ERR_INVALID_ARGUMENT,
                            "ARAP: cg_iterations is %d, must be in [1, 100]", o->cg_iterations);
    if (o->predict != 0 && o->predict != 1)
        return dk_error_set(err, DK_ERR_INVALID_ARGUMENT, "ARAP: predict is %d, must be 0 or 1",
                            o->predict);
    if (o->anderson_depth < 1 || o->anderson_depth > MAX_ANDERSON_DEPTH)
        return dk_error_set(err, DK_ERR_INVALID_ARGUMENT,
                            "ARAP: anderson_depth is %d, must be in [1, %d]", o->anderson_depth,
                            MAX_ANDERSON_DEPTH);
    return DK_OK;
}

/* ------------------------------------------------------------------ cells -------------- */

typedef struct raw_term {
    dk_index a, b;
    double w;
} raw_term;

/* cot(angle at corner p0 of triangle p0 p1 p2) / 2, 0 for a degenerate triangle. */
static double half_cot(const double *p0, const double *p1, const double *p2, double longest2)
{
    double u[3] = {p1[0] - p0[0], p1[1] - p0[1], p1[2] - p0[2]};
    double v[3] = {p2[0] - p0[0], p2[1] - p0[1], p2[2] - p0[2]};
    double c[3] = {u[1] * v[2] - u[2] * v[1], u[2] * v[0] - u[0] * v[2],
                   u[0] * v[1] - u[1] * v[0]};
    double twice_area = sqrt(c[0] * c[0] + c[1] * c[1] + c[2] * c[2]);
    if (!(0.5 * twice_area >= 1e-14 * longest2))
        return 0.0;
    return 0.5 * (u[0] * v[0] + u[1] * v[1] + u[2] * v[2]) / twice_area;
}

static double dist2(const double *p, const double *q)
{
    double d0 = p[0] - q[0], d1 = p[1] - q[1], d2 = p[2] - q[2];
    return d0 * d0 + d1 * d1 + d2 * d2;
}

static int term_less(const raw_term *x, const raw_term *y)
{
    return x->a < y->a || (x->a == y->a && x->b < y->b);
}

static dk_status build_cells(dk_arap *ar, dk_error *err)
{
    const dk_mesh *m = ar->mesh;
    const dk_index n = m->n_vertices, nf = m->n_faces;
    const int rims = ar->opt.energy == DK_ARAP_SPOKES_AND_RIMS;
    const int per_corner = rims ? 3 : 2;
    const double *p = m->positions;
    dk_status st = DK_OK;
    dk_index *start = calloc((size_t)n + 1, sizeof *start);
    dk_index *fill = malloc(((size_t)n + 1) * sizeof *fill);
    raw_term *raw = malloc(((size_t)nf * 3 * per_corner + 1) * sizeof *raw);
    if (!start || !fill || !raw) {
        st = oom(err, "cells");
        goto done;
    }
    for (dk_index f = 0; f < nf; f++)
        for (int k = 0; k < 3; k++)
            start[m->faces[3 * f + k] + 1] += per_corner;
    for (dk_index v = 0; v < n; v++)
        start[v + 1] += start[v];
    memcpy(fill, start, (size_t)n * sizeof *fill);
    for (dk_index f = 0; f < nf; f++) {
        const dk_index *t = m->faces + 3 * f;
        double l0 = dist2(p + 3 * t[1], p + 3 * t[2]), l1 = dist2(p + 3 * t[2], p + 3 * t[0]),
               l2 = dist2(p + 3 * t[0], p + 3 * t[1]);
        double longest2 = fmax(l0, fmax(l1, l2));
        double h[3]; /* h[k]: half weight of the edge opposite corner k */
        for (int k = 0; k < 3; k++)
            h[k] = ar->opt.weights == DK_ARAP_WEIGHTS_UNIFORM
                       ? 0.5
                       : half_cot(p + 3 * t[k], p + 3 * t[(k + 1) % 3], p + 3 * t[(k + 2) % 3],
                                  longest2);
        for (int k = 0; k < 3; k++) {
            dk_index i = t[k];
            for (int e = 0; e < 3; e++) {
                if (!rims && e == k)
                    continue; /* the edge opposite i is a rim */
                dk_index a = t[(e + 1) % 3], b = t[(e + 2) % 3];
                raw_term r = {a < b ? a : b, a < b ? b : a, h[e]};
                raw[fill[i]++] = r;
            }
        }
    }
    /* Sort each cell by edge, merge duplicates, detect non-manifold spokes, clamp. */
    int64_t out = 0;
    for (dk_index i = 0; i < n; i++) {
        raw_term *c = raw + start[i];
        dk_index len = start[i + 1] - start[i];
        for (dk_index s = 1; s < len; s++) {
            raw_term key = c[s];
            dk_index j = s - 1;
            while (j >= 0 && term_less(&key, &c[j])) {
                c[j + 1] = c[j];
                j--;
            }
            c[j + 1] = key;
        }
        dk_index new_start = (dk_index)out;
        for (dk_index s = 0; s < len;) {
            raw_term merged = c[s];
            dk_index e = s + 1;
            while (e < len && c[e].a == merged.a && c[e].b == merged.b)
                merged.w += c[e++].w;
            if ((merged.a == i || merged.b == i) && e - s > 2) {
                const dk_index ca = ar->ro->perm[merged.a], cb = ar->ro->perm[merged.b];
                st = dk_error_set(err, DK_ERR_TOPOLOGY,
                                  "ARAP: edge (%d, %d) is non-manifold (%d incident "
                                  "triangles)", (int)(ca < cb ? ca : cb), (int)(ca < cb ? cb : ca),
                                  (int)(e - s));
                goto done;
            }
            if (ar->opt.weights == DK_ARAP_WEIGHTS_CLAMPED_COTANGENT && merged.w < 0.0)
                merged.w = 0.0;
            raw[out++] = merged; /* out <= start[i] + s: never overwrites unread terms */
            s = e;
        }
        start[i] = new_start;
    }
    start[n] = (dk_index)out;
    ar->n_terms = out;
    ar->cell_start = start;
    start = NULL;
    ar->ta = malloc(((size_t)out + 1) * sizeof *ar->ta);
    ar->tb = malloc(((size_t)out + 1) * sizeof *ar->tb);
    ar->tw = malloc(((size_t)out + 1) * sizeof *ar->tw);
    ar->te = malloc(((size_t)out * 3 + 1) * sizeof *ar->te);
    if (!ar->ta || !ar->tb || !ar->tw || !ar->te) {
        st = oom(err, "cell terms");
        goto done;
    }
    for (int64_t t = 0; t < out; t++) {
        ar->ta[t] = raw[t].a;
        ar->tb[t] = raw[t].b;
        ar->tw[t] = raw[t].w;
        for (int d = 0; d < 3; d++)
            ar->te[3 * t + d] = p[3 * raw[t].a + d] - p[3 * raw[t].b + d];
    }
done:
    free(start);
    free(fill);
    free(raw);
    return st;
}

/* ------------------------------------------------------------------ system ------------- */

static void sparse_release(dk_sparse *a)
{
    free(a->col_start);
    free(a->row_index);
    free(a->values);
    memset(a, 0, sizeof *a);
}

static void system_free(arap_system *s)
{
    dk_constraints_free(s->con);
    free(s->unk);
    free(s->unknowns);
    free(s->target_of);
    free(s->soft_k);
    free(s->tws);
    free(s->bterms);
    sparse_release(&s->a);
    dk_cholesky_free(s->chol);
    free(s->rhs_const);
    free(s->rhs);
    free(s->rg_start);
    free(s->rg);
    free(s->xu);
    free(s->gu);
    free(s->fu);
    free(s->gprev);
    free(s->fprev);
    free(s->dg);
    free(s->df);
    free(s->targets);
    free(s->targets_prev);
    free(s->targets_prev2);
    free(s->warm);
    free(s->kinv);
    free(s->omega);
    free(s->vfull);
    free(s->nt);
    free(s->ntt);
    free(s->a_vrow);
    free(s->nt_r);
    free(s->nt_z);
    free(s->nt_p);
    free(s->nt_q);
    free(s->nt_d);
    free(s->nt_z0);
    memset(s, 0, sizeof *s);
}

static dk_index uf_find(dk_index *parent, dk_index v)
{
    while (parent[v] != v) {
        parent[v] = parent[parent[v]];
        v = parent[v];
    }
    return v;
}

/* Every connected component (and isolated vertex) holding an unknown must hold an anchor:
 * an eliminated vertex or a soft handle vertex. */
static dk_status check_components(const dk_arap *ar, const arap_system *s, dk_error *err)
{
    const dk_mesh *m = ar->mesh;
    const dk_index n = ar->n;
    dk_index *parent = malloc(((size_t)n + 1) * sizeof *parent);
    unsigned char *anchored = calloc((size_t)n + 1, 1);
    if (!parent || !anchored) {
        free(parent);
        free(anchored);
        return oom(err, "component check");
    }
    for (dk_index v = 0; v < n; v++)
        parent[v] = v;
    for (dk_index f = 0; f < m->n_faces; f++)
        for (int k = 1; k < 3; k++) {
            dk_index a = uf_find(parent, m->faces[3 * f]);
            dk_index b = uf_find(parent, m->faces[3 * f + k]);
            if (a != b)
                parent[a < b ? b : a] = a < b ? a : b;
        }
    for (dk_index v = 0; v < n; v++)
        if (s->unk[v] < 0 || s->soft_k[v] > 0.0)
            anchored[uf_find(parent, v)] = 1;
    dk_status st = DK_OK;
    /* in the caller's order, so that the message names the component's smallest vertex */
    for (dk_index cv = 0; cv < n && st == DK_OK; cv++) {
        const dk_index v = ar->ro->iperm[cv];
        if (s->unk[v] >= 0 && !anchored[uf_find(parent, v)])
            st = dk_error_set(err, DK_ERR_DEGENERATE,
                              "ARAP: the connected component of vertex %d has free vertices "
                              "but no handle or fixed vertex, so its position is undetermined",
                              (int)cv);
    }
    free(parent);
    free(anchored);
    return st;
}

typedef struct entry {
    dk_index row;
    double val;
} entry;

/* Assembles the reduced matrix A (unknowns x unknowns, both triangles, every diagonal
 * present, explicit zeros kept so that the pattern depends only on the unknown set). */
static dk_status assemble(const dk_arap *ar, arap_system *s, dk_error *err)
{
    const dk_index nu = s->nu;
    dk_index *count = calloc((size_t)nu + 1, sizeof *count);
    if (!count)
        return oom(err, "matrix assembly");
    for (int64_t t = 0; t < ar->n_terms; t++) {
        dk_index ua = s->unk[ar->ta[t]], ub = s->unk[ar->tb[t]];
        if (ua >= 0)
            count[ua + 1] += 1 + (ub >= 0);
        if (ub >= 0)
            count[ub + 1] += 1 + (ua >= 0);
    }
    for (dk_index u = 0; u < nu; u++)
        count[u + 1] += count[u] + 1; /* + the diagonal */
    int64_t total = count[nu];
    entry *ent = malloc(((size_t)total + 1) * sizeof *ent);
    dk_index *fill = malloc(((size_t)nu + 1) * sizeof *fill);
    if (!ent || !fill) {
        free(count);
        free(ent);
        free(fill);
        return oom(err, "matrix assembly");
    }
    for (dk_index u = 0; u < nu; u++) {
        fill[u] = count[u] + 1;
        ent[count[u]].row = u;
        ent[count[u]].val = s->soft_k[s->unknowns[u]];
    }
    for (int64_t t = 0; t < ar->n_terms; t++) {
        dk_index ua = s->unk[ar->ta[t]], ub = s->unk[ar->tb[t]];
        double w = s->tws[t];
        if (ua >= 0) {
            ent[fill[ua]++] = (entry){ua, w};
            if (ub >= 0)
                ent[fill[ua]++] = (entry){ub, -w};
        }
        if (ub >= 0) {
            ent[fill[ub]++] = (entry){ub, w};
            if (ua >= 0)
                ent[fill[ub]++] = (entry){ua, -w};
        }
    }
    free(fill);
    /* Sort and merge each column in place. */
    int64_t nnz = 0;
    for (dk_index u = 0; u < nu; u++) {
        entry *c = ent + count[u];
        dk_index len = count[u + 1] - count[u];
        for (dk_index i = 1; i < len; i++) {
            entry key = c[i];
            dk_index j = i - 1;
            while (j >= 0 && c[j].row > key.row) {
                c[j + 1] = c[j];
                j--;
            }
            c[j + 1] = key;
        }
        int64_t col_start = nnz;
        for (dk_index i = 0; i < len;) {
            entry e = c[i++];
            while (i < len && c[i].row == e.row)
                e.val += c[i++].val;
            ent[nnz++] = e;
        }
        count[u] = (dk_index)col_start;
    }
    count[nu] = (dk_index)nnz;
    s->a.n_rows = s->a.n_cols = nu;
    s->a.col_start = count;
    s->a.row_index = malloc(((size_t)nnz + 1) * sizeof *s->a.row_index);
    s->a.values = malloc(((size_t)nnz + 1) * sizeof *s->a.values);
    if (!s->a.row_index || !s->a.values) {
        free(ent);
        sparse_release(&s->a);
        return oom(err, "reduced matrix");
    }
    for (int64_t k = 0; k < nnz; k++) {
        s->a.row_index[k] = ent[k].row;
        s->a.values[k] = ent[k].val;
    }
    free(ent);
    return DK_OK;
}

static int same_unknowns(const arap_system *x, const arap_system *y, dk_index n)
{
    if (!x->unk || x->nu != y->nu)
        return 0;
    return memcmp(x->unk, y->unk, (size_t)n * sizeof *x->unk) == 0;
}

/* Builds a complete system for `desc`; `old` (may be NULL) lends its symbolic analysis when
 * the unknown set is the same (it is then moved into the new system). */
/* g_{v,c} of cell c for vertex v (see arap_system.rg); returns whether a term touches v. */
static int cell_gather_vector(const dk_arap *ar, const arap_system *s, dk_index c, dk_index v,
                              double g[3])
{
    int touches = 0;
    g[0] = g[1] = g[2] = 0.0;
    for (dk_index t = ar->cell_start[c]; t < ar->cell_start[c + 1]; t++) {
        const double sign = ar->ta[t] == v ? 1.0 : ar->tb[t] == v ? -1.0 : 0.0;
        if (sign == 0.0)
            continue;
        touches = 1;
        for (int d = 0; d < 3; d++)
            g[d] += sign * s->tws[t] * ar->te[3 * t + d];
    }
    return touches;
}

/* The rotations-to-right-hand-side map s->rg (needs s->unknowns, s->tws). Every cell with a
 * term touching v is v's own or one of its one-ring's (a spoke (c, v), or a rim of a
 * triangle (c, v, k)), so candidates are scanned there: O(sum of one-ring cell sizes). */
static dk_status build_rhs_map(const dk_arap *ar, arap_system *s, dk_error *err)
{
    const dk_mesh *m = ar->mesh;
    const dk_index nu = s->nu;
    double g[3];
    s->rg_start = malloc(((size_t)nu + 1) * sizeof *s->rg_start);
    if (!s->rg_start)
        return oom(err, "right-hand-side map");
    int64_t k = 0;
    for (int pass = 0; pass < 2; pass++) {
        k = 0;
        for (dk_index u = 0; u < nu; u++) {
            const dk_index v = s->unknowns[u];
            if (pass == 0)
                s->rg_start[u] = k;
            for (dk_index q = m->ring_start[v] - 1; q < m->ring_start[v + 1]; q++) {
                const dk_index c = q < m->ring_start[v] ? v : m->ring_index[q];
                if (!cell_gather_vector(ar, s, c, v, g))
                    continue;
                if (pass == 1) {
                    memcpy(s->rg[k].g, g, sizeof g);
                    s->rg[k].cell = c;
                }
                k++;
            }
        }
        if (pass == 0) {
            s->rg_start[nu] = k;
            s->rg = malloc(((size_t)k + 1) * sizeof *s->rg);
            if (!s->rg)
                return oom(err, "right-hand-side map");
        }
    }
    return DK_OK;
}

static dk_status system_build(dk_arap *ar, const dk_constraint_desc *desc, arap_system *old,
                              arap_system *s, dk_error *err)
{
    const dk_index n = ar->n;
    memset(s, 0, sizeof *s);
    dk_status st = dk_constraints_create(ar->mesh, desc, &s->con, err);
    if (st != DK_OK)
        return dk_error_prefix(err, "ARAP");
    const dk_constraints *c = s->con;
    s->unk = malloc(((size_t)n + 1) * sizeof *s->unk);
    s->target_of = malloc(((size_t)n + 1) * sizeof *s->target_of);
    s->soft_k = calloc((size_t)n + 1, sizeof *s->soft_k);
    s->tws = malloc(((size_t)ar->n_terms + 1) * sizeof *s->tws);
    s->targets = malloc(((size_t)c->n_handle_vertices * 3 + 1) * sizeof *s->targets);
    s->targets_prev = malloc(((size_t)c->n_handle_vertices * 3 + 1) * sizeof *s->targets_prev);
    s->targets_prev2 = malloc(((size_t)c->n_handle_vertices * 3 + 1) * sizeof *s->targets_prev2);
    if (!s->unk || !s->target_of || !s->soft_k || !s->tws || !s->targets || !s->targets_prev ||
        !s->targets_prev2) {
        system_free(s);
        return oom(err, "constraint system");
    }
    for (dk_index v = 0; v < n; v++)
        s->target_of[v] = -1;
    for (dk_index k = 0; k < c->n_handle_vertices; k++)
        s->target_of[c->handle_vertices[k]] = k;
    /* Weights with stiffness, the ARAP diagonal, then the soft penalties. */
    double diag = 0.0, escale = 0.0;
    for (dk_index i = 0; i < n; i++)
        for (dk_index t = ar->cell_start[i]; t < ar->cell_start[i + 1]; t++) {
            s->tws[t] = c->stiffness[i] * ar->tw[t];
            diag += 2.0 * s->tws[t];
            const double *e = ar->te + 3 * t;
            escale += s->tws[t] * (e[0] * e[0] + e[1] * e[1] + e[2] * e[2]);
        }
    s->lambda = n > 0 ? diag / n : 0.0;
    s->escale = escale;
    dk_index nu = 0;
    for (dk_index v = 0; v < n; v++) {
        int soft = 0;
        if (c->role[v] >= 0) {
            double w = c->handle_weights[s->target_of[v]];
            if (w < 1.0) {
                soft = 1;
                s->soft_k[v] = s->lambda * w / (1.0 - w);
            }
        }
        s->unk[v] = (c->role[v] == DK_VERTEX_FREE || soft) ? nu++ : -1;
    }
    s->nu = nu;
    s->n_bterms = 0;
    for (int64_t t = 0; t < ar->n_terms; t++)
        s->n_bterms += (s->unk[ar->ta[t]] >= 0) != (s->unk[ar->tb[t]] >= 0);
    s->bterms = malloc(((size_t)s->n_bterms + 1) * sizeof *s->bterms);
    if (!s->bterms) {
        system_free(s);
        return oom(err, "constraint system");
    }
    s->n_bterms = 0;
    for (int64_t t = 0; t < ar->n_terms; t++)
        if ((s->unk[ar->ta[t]] >= 0) != (s->unk[ar->tb[t]] >= 0))
            s->bterms[s->n_bterms++] = t;
    if (nu == 0) {
        system_free(s);
        return dk_error_set(err, DK_ERR_INVALID_ARGUMENT,
                            "ARAP: no free vertex: every vertex is fixed, outside the ROI or "
                            "a hard handle, so there is nothing to solve");
    }
    s->unknowns = malloc((size_t)nu * sizeof *s->unknowns);
    size_t N = 3 * (size_t)nu, m = (size_t)ar->opt.anderson_depth;
    int accel = ar->opt.acceleration == DK_ARAP_ACCEL_ANDERSON;
    s->rhs_const = malloc(N * sizeof(double));
    s->rhs = malloc(N * sizeof(double));
    s->xu = malloc(N * sizeof(double));
    s->gu = malloc(N * sizeof(double));
    s->warm = malloc(2 * N * sizeof(double) + sizeof(double));
    if (accel) {
        s->fu = malloc(N * sizeof(double));
        s->gprev = malloc(N * sizeof(double));
        s->fprev = malloc(N * sizeof(double));
        s->dg = malloc(N * m * sizeof(double));
        s->df = malloc(N * m * sizeof(double));
    }
    const int newton = ar->opt.acceleration == DK_ARAP_ACCEL_NEWTON;
    if (newton) {
        s->kinv = malloc(6 * (size_t)n * sizeof(double) + sizeof(double));
        s->omega = malloc(3 * (size_t)n * sizeof(double) + sizeof(double));
        s->vfull = calloc(3 * (size_t)n + 1, sizeof(double));
        s->nt_r = malloc(N * sizeof(double));
        s->nt_z = malloc(N * sizeof(double));
        s->nt_p = malloc(N * sizeof(double));
        s->nt_q = malloc(N * sizeof(double));
        s->nt_d = malloc(N * sizeof(double));
        s->nt_z0 = malloc(N * sizeof(double));
    }
    if (!s->unknowns || !s->rhs_const || !s->rhs || !s->xu || !s->gu || !s->warm ||
        (accel && (!s->fu || !s->gprev || !s->fprev || !s->dg || !s->df)) ||
        (newton && (!s->kinv || !s->omega || !s->vfull || !s->nt_r || !s->nt_z || !s->nt_p ||
                    !s->nt_q || !s->nt_d || !s->nt_z0))) {
        system_free(s);
        return oom(err, "solve buffers");
    }
    for (dk_index v = 0; v < n; v++)
        if (s->unk[v] >= 0)
            s->unknowns[s->unk[v]] = v;
    st = build_rhs_map(ar, s, err);
    if (st == DK_OK && newton) {
        const int64_t ne = s->rg_start[nu];
        s->nt = malloc(((size_t)ne + 1) * sizeof *s->nt);
        s->ntt = malloc(((size_t)ar->n_terms + 1) * sizeof *s->ntt);
        if (!s->nt || !s->ntt) {
            st = oom(err, "Newton buffers");
        } else {
            for (int64_t k = 0; k < ne; k++)
                s->nt[k].cell = s->rg[k].cell;
            for (int64_t t = 0; t < ar->n_terms; t++) {
                struct nt_term *q = s->ntt + t;
                for (int d = 0; d < 3; d++)
                    q->e[d] = (float)ar->te[3 * t + d];
                q->w = (float)ar->tw[t];
                q->a = ar->ta[t];
                q->b = ar->tb[t];
            }
        }
    }
    if (st == DK_OK)
        st = check_components(ar, s, err);
    if (st == DK_OK)
        st = assemble(ar, s, err);
    if (st == DK_OK && newton) {
        const dk_index nnz = s->a.col_start[nu];
        s->a_vrow = malloc(((size_t)nnz + 1) * sizeof *s->a_vrow);
        if (!s->a_vrow)
            st = oom(err, "Newton buffers");
        else
            for (dk_index k = 0; k < nnz; k++)
                s->a_vrow[k] = s->unknowns[s->a.row_index[k]];
    }
    if (st != DK_OK) {
        system_free(s);
        return st;
    }
    int reused = 0;
    if (old && old->chol && same_unknowns(old, s, n)) {
        s->chol = old->chol; /* same pattern: keep the symbolic analysis */
        old->chol = NULL;
        reused = 1;
    } else {
        st = dk_cholesky_analyze(&s->a, &s->chol, err);
        if (st != DK_OK) {
            system_free(s);
            return dk_error_prefix(err, "ARAP: analysis of the reduced matrix");
        }
        dk_cholesky_set_team(s->chol, ar->team);
        ar->analysis_count++;
    }
    st = dk_cholesky_factorize(s->chol, &s->a, err);
    if (st == DK_OK) {
        ar->factorization_count++;
        return DK_OK;
    }
    if (reused) { /* give the analysis back, with the old values */
        old->chol = s->chol;
        s->chol = NULL;
        dk_error ignored = {0};
        if (dk_cholesky_factorize(old->chol, &old->a, &ignored) != DK_OK) {
            dk_cholesky_free(old->chol);
            old->chol = NULL;
        }
    }
    system_free(s);
    if (st == DK_ERR_NOT_POSITIVE_DEFINITE) {
        dk_error_prefix(err, "ARAP: the reduced matrix is not positive definite (degenerate "
                             "triangles or negative cotangent weights; try "
                             "weights=clamped_cotangent)");
        if (err)
            err->status = DK_ERR_DEGENERATE;
        return DK_ERR_DEGENERATE;
    }
    return dk_error_prefix(err, "ARAP: factorization");
}

/* ------------------------------------------------------------------ bind / free -------- */

void dk_arap_free(dk_arap *ar)
{
    if (!ar)
        return;
    system_free(&ar->sys);
    free(ar->cell_start);
    free(ar->ta);
    free(ar->tb);
    free(ar->tw);
    free(ar->te);
    free(ar->x);
    free(ar->rot);
    free(ar->prev);
    free(ar->prev2);
    dk_reorder_free(ar->ro);
    dk_team_free(ar->team); /* after the factor, which used it */
    free(ar);
}

dk_status dk_arap_bind(const dk_mesh *mesh, const dk_constraint_desc *constraints,
                       const dk_arap_options *options, dk_arap **out, dk_error *err)
{
    if (out)
        *out = NULL;
    if (!mesh || !constraints || !out)
        return dk_error_set(err, DK_ERR_INVALID_ARGUMENT,
                            "ARAP bind: mesh, constraints and output must not be NULL");
    dk_arap_options opt;
    if (options)
        opt = *options;
    else
        dk_arap_default_options(&opt);
    dk_status st = check_options(&opt, err);
    if (st != DK_OK)
        return st;
    if (mesh->n_faces == 0)
        return dk_error_set(err, DK_ERR_TOPOLOGY, "ARAP bind: the mesh has no triangle");
    dk_arap *ar = calloc(1, sizeof *ar);
    if (!ar)
        return oom(err, "object");
    ar->caller_mesh = mesh;
    ar->team = dk_team_create(); /* NULL (no thread available) is fine: passes start threads */
    ar->opt = opt;
    ar->n = mesh->n_vertices;
    st = dk_reorder_create(mesh, 0, &ar->ro, err);
    if (st != DK_OK) {
        dk_arap_free(ar);
        return dk_error_prefix(err, "ARAP bind");
    }
    ar->mesh = ar->ro->mesh;
    ar->x = malloc(((size_t)ar->n * 3 + 1) * sizeof *ar->x);
    ar->rot = malloc(((size_t)ar->n * 9 + 1) * sizeof *ar->rot);
    ar->prev = malloc(((size_t)ar->n * 3 + 1) * sizeof *ar->prev);
    ar->prev2 = malloc(((size_t)ar->n * 3 + 1) * sizeof *ar->prev2);
    if (!ar->x || !ar->rot || !ar->prev || !ar->prev2) {
        dk_arap_free(ar);
        return oom(err, "positions");
    }
    for (dk_index v = 0; v < ar->n; v++) /* rotations are always valid guesses */
        for (int k = 0; k < 9; k++)
            ar->rot[9 * (size_t)v + k] = k % 4 == 0 ? 1.0 : 0.0;
    dk_reorder_desc rd;
    st = dk_reorder_desc_create(ar->ro, mesh, constraints, &rd, err);
    if (st != DK_OK) {
        dk_arap_free(ar);
        return dk_error_prefix(err, "ARAP");
    }
    st = build_cells(ar, err);
    if (st == DK_OK)
        st = system_build(ar, &rd.desc, NULL, &ar->sys, err);
    dk_reorder_desc_free(&rd);
    if (st != DK_OK) {
        dk_arap_free(ar);
        return st;
    }
    *out = ar;
    return DK_OK;
}

dk_status dk_arap_rebind(dk_arap *ar, const dk_constraint_desc *constraints, dk_error *err)
{
    if (!ar || !constraints)
        return dk_error_set(err, DK_ERR_INVALID_ARGUMENT,
                            "ARAP rebind: object and constraints must not be NULL");
    arap_system s;
    dk_reorder_desc rd;
    dk_status st = dk_reorder_desc_create(ar->ro, ar->caller_mesh, constraints, &rd, err);
    if (st != DK_OK)
        return dk_error_prefix(err, "ARAP");
    st = system_build(ar, &rd.desc, &ar->sys, &s, err);
    dk_reorder_desc_free(&rd);
    if (st != DK_OK)
        return st;
    system_free(&ar->sys);
    ar->sys = s;
    ar->n_hist = 0; /* other constraints: the drag history no longer predicts */
    return DK_OK;
}

/* ------------------------------------------------------------------ iteration ---------- */

/* One Newton step of refine_rotation for element type T (double, or a GCC vector of
 * doubles lane by lane): declares M = r^T a, its skew part g, K = tr(M) I - sym(M), K's
 * adjugate c.., det, the margin s, the step w = -K^-1 g with t2 = |w|^2, and the Cayley
 * factors q0..q8 of the rotation update. Computed before the caller's tests of K and t2
 * (pure arithmetic: a failed test discards them), in one text for the scalar and the
 * four-lane code, so that both round every lane identically. */
#define DK_NEWTON_STEP(T, a, r)                                                            \
    T m0 = r[0] * a[0] + r[3] * a[3] + r[6] * a[6];                                        \
    T m1 = r[0] * a[1] + r[3] * a[4] + r[6] * a[7];                                        \
    T m2 = r[0] * a[2] + r[3] * a[5] + r[6] * a[8];                                        \
    T m3 = r[1] * a[0] + r[4] * a[3] + r[7] * a[6];                                        \
    T m4 = r[1] * a[1] + r[4] * a[4] + r[7] * a[7];                                        \
    T m5 = r[1] * a[2] + r[4] * a[5] + r[7] * a[8];                                        \
    T m6 = r[2] * a[0] + r[5] * a[3] + r[8] * a[6];                                        \
    T m7 = r[2] * a[1] + r[5] * a[4] + r[8] * a[7];                                        \
    T m8 = r[2] * a[2] + r[5] * a[5] + r[8] * a[8];                                        \
    T g0 = m5 - m7, g1 = m6 - m2, g2 = m1 - m3;                                            \
    T tr = m0 + m4 + m8;                                                                   \
    T k00 = tr - m0, k11 = tr - m4, k22 = tr - m8;                                         \
    T k01 = -0.5 * (m1 + m3), k02 = -0.5 * (m2 + m6), k12 = -0.5 * (m5 + m7);              \
    /* adjugate of K; Sylvester's criterion (the caller) with margins relative to tr K */ \
    T c00 = k11 * k22 - k12 * k12, c01 = k02 * k12 - k01 * k22,                            \
      c02 = k01 * k12 - k02 * k11, c11 = k00 * k22 - k02 * k02,                            \
      c12 = k01 * k02 - k00 * k12, c22 = k00 * k11 - k01 * k01;                            \
    T det = k00 * c00 + k01 * c01 + k02 * c02;                                             \
    T s = 1e-3 * (k00 + k11 + k22);                                                        \
    T inv = -1.0 / det;                                                                    \
    T w0 = inv * (c00 * g0 + c01 * g1 + c02 * g2);                                         \
    T w1 = inv * (c01 * g0 + c11 * g1 + c12 * g2);                                         \
    T w2 = inv * (c02 * g0 + c12 * g1 + c22 * g2);                                         \
    T t2 = w0 * w0 + w1 * w1 + w2 * w2;                                                    \
    /* Cayley retraction Q = I + f ([v]x + [v]x^2), v = w / 2, f = 2 / (1 + |v|^2):       \
     * orthogonal, agrees with exp([w]x) to second order */                               \
    T v0 = 0.5 * w0, v1 = 0.5 * w1, v2 = 0.5 * w2, vv = 0.25 * t2;                         \
    T f = 2.0 / (1.0 + vv);                                                                \
    T q0 = 1.0 + f * (v0 * v0 - vv), q4 = 1.0 + f * (v1 * v1 - vv),                        \
      q8 = 1.0 + f * (v2 * v2 - vv);                                                       \
    T q1 = f * (v0 * v1 - v2), q3 = f * (v0 * v1 + v2);                                    \
    T q2 = f * (v0 * v2 + v1), q6 = f * (v0 * v2 - v1);                                    \
    T q5 = f * (v1 * v2 - v0), q7 = f * (v1 * v2 + v0);

/* The rotation maximising trace(R^T a), refined from the guess r (in/out; a rotation on
 * entry) by Newton steps on SO(3). For R = r exp([w]x) and M = r^T a,
 *     trace(R^T a) = tr M - w.g - w^T K w / 2 + O(|w|^3),
 *     g = (M12 - M21, M20 - M02, M01 - M10),  K = tr(M) I - (M + M^T) / 2,
 * so a Newton step is w = -K^-1 g, applied with the Cayley rotation (exactly orthogonal,
 * equal to exp([w]x) to second order, so the convergence stays quadratic). At a stationary
 * point (M symmetric) K positive definite means a strict local maximum, and on SO(3) every
 * strict local maximum of trace(R^T a) is the global one (at the other stationary points
 * U diag(+-1) V^T some pair of signed singular values has a sum <= 0, an eigenvalue of K).
 * Returns 1 once a step of at most 1e-8 rad has been taken (the remaining error is then of
 * order 1e-16) with K positive definite by a margin; 0 when the guess is too far (a step
 * over 1 rad, or not converged in 4 steps) or a is degenerate (rank <= 1, equal singular
 * values at a reflection): the caller then uses dk_closest_rotation, whose result is the
 * same maximiser. In a local/global iteration a cell's rotation moves little from one
 * iteration to the next: two steps from the previous rotation cost about half of
 * dk_closest_rotation from scratch (61 vs 132 ns on near-rotations; on the armadillo a plain
 * iteration went from 9.0 to 5.4 ms). */
static int refine_rotation(const double a[9], double r[9])
{
    for (int step = 0; step < 4; step++) {
        DK_NEWTON_STEP(double, a, r)
        if (!(k00 > s && c22 > s * s && det > s * s * s))
            return 0;
        if (!(t2 <= 1.0))
            return 0; /* not finite, or too far for a Newton step */
        for (int i = 0; i < 3; i++) {
            double x = r[3 * i], y = r[3 * i + 1], z = r[3 * i + 2];
            r[3 * i] = x * q0 + y * q3 + z * q6;
            r[3 * i + 1] = x * q1 + y * q4 + z * q7;
            r[3 * i + 2] = x * q2 + y * q5 + z * q8;
        }
        if (t2 <= 1e-16) {
            /* one Newton-Schulz step R (3 I - R^T R) / 2: the products above add ~1e-16 of
             * non-orthogonality each, which would otherwise accumulate over many calls */
            double c[9];
            for (int i = 0; i < 3; i++)
                for (int j = i; j < 3; j++)
                    c[3 * i + j] = c[3 * j + i] =
                        (i == j ? 1.5 : 0.0) -
                        0.5 * (r[i] * r[j] + r[3 + i] * r[3 + j] + r[6 + i] * r[6 + j]);
            for (int i = 0; i < 3; i++) {
                double x = r[3 * i], y = r[3 * i + 1], z = r[3 * i + 2];
                r[3 * i] = x * c[0] + y * c[3] + z * c[6];
                r[3 * i + 1] = x * c[1] + y * c[4] + z * c[7];
                r[3 * i + 2] = x * c[2] + y * c[5] + z * c[8];
            }
            return 1;
        }
    }
    return 0;
}

#if defined(__GNUC__)
/* Four cells' refine_rotation at once, lane by lane the same operations in the same order
 * (no contraction: the results equal refine_rotation's bit for bit), on GCC/Clang generic
 * vectors: SSE2 / NEON pairs or one AVX register. refine_rotation is about half of a local
 * step's instructions, all of it arithmetic on a few registers: in lock step the four
 * dependency chains overlap. a: 9 x 4 (entry-major, lane-minor); r: 9 x 4 in/out. Returns
 * a bit mask of the lanes that converged (bit l); the other lanes' r are unspecified and the
 * caller redoes them with dk_closest_rotation. */
typedef double v4d __attribute__((vector_size(32)));
typedef long long v4l __attribute__((vector_size(32)));

/* On x86-64 Linux (ifunc) an AVX2 clone runs the four lanes in one register where the CPU
 * has it; without FMA, so every lane rounds exactly as the baseline SSE2 code does. */
#if defined(__x86_64__) && defined(__linux__) && !defined(__clang__)
#define DK_VEC_CLONES __attribute__((target_clones("avx2", "default")))
#else
#define DK_VEC_CLONES
#endif
#define V4SEL(m, x, y) ((v4d)(((v4l)(x) & (m)) | ((v4l)(y) & ~(m))))

DK_VEC_CLONES static int refine_rotation4(const v4d a[9], v4d r[9])
{
    const v4d half = {0.5, 0.5, 0.5, 0.5};
    v4l done = {0, 0, 0, 0}, failed = {0, 0, 0, 0};
    for (int step = 0; step < 4; step++) {
        const v4l active = ~(done | failed);
        DK_NEWTON_STEP(v4d, a, r)
        v4l spd = (k00 > s) & (c22 > s * s) & (det > s * s * s);
        const v4l ok = spd & (t2 <= 1.0); /* false for NaN */
        failed |= active & ~ok;
        const v4l go = active & ok;
        for (int i = 0; i < 3; i++) {
            v4d x = r[3 * i], y = r[3 * i + 1], z = r[3 * i + 2];
            r[3 * i] = V4SEL(go, x * q0 + y * q3 + z * q6, x);
            r[3 * i + 1] = V4SEL(go, x * q1 + y * q4 + z * q7, y);
            r[3 * i + 2] = V4SEL(go, x * q2 + y * q5 + z * q8, z);
        }
        const v4l fin = go & (t2 <= 1e-16);
        if (fin[0] | fin[1] | fin[2] | fin[3]) {
            v4d c[9];
            for (int i = 0; i < 3; i++)
                for (int j = i; j < 3; j++)
                    c[3 * i + j] = c[3 * j + i] =
                        (i == j ? 1.5 : 0.0) -
                        half * (r[i] * r[j] + r[3 + i] * r[3 + j] + r[6 + i] * r[6 + j]);
            for (int i = 0; i < 3; i++) {
                v4d x = r[3 * i], y = r[3 * i + 1], z = r[3 * i + 2];
                r[3 * i] = V4SEL(fin, x * c[0] + y * c[3] + z * c[6], x);
                r[3 * i + 1] = V4SEL(fin, x * c[1] + y * c[4] + z * c[7], y);
                r[3 * i + 2] = V4SEL(fin, x * c[2] + y * c[5] + z * c[8], z);
            }
            done |= fin;
        }
        const v4l left = ~(done | failed);
        if (!(left[0] | left[1] | left[2] | left[3]))
            break;
    }
    return (done[0] ? 1 : 0) | (done[1] ? 2 : 0) | (done[2] ? 4 : 0) | (done[3] ? 8 : 0);
}
#endif

/* Cell i's covariance a = sum_t w_t (x_a - x_b) e_t^T (the local step's input). */
static inline void cell_covariance(const dk_arap *ar, const double *x, dk_index i, double a[9])
{
    for (int k = 0; k < 9; k++)
        a[k] = 0.0;
    for (dk_index t = ar->cell_start[i]; t < ar->cell_start[i + 1]; t++) {
        const double *pa = x + 3 * ar->ta[t], *pb = x + 3 * ar->tb[t];
        const double *e = ar->te + 3 * t;
        double w = ar->tw[t];
        double d0 = w * (pa[0] - pb[0]), d1 = w * (pa[1] - pb[1]), d2 = w * (pa[2] - pb[2]);
        a[0] += d0 * e[0]; a[1] += d0 * e[1]; a[2] += d0 * e[2];
        a[3] += d1 * e[0]; a[4] += d1 * e[1]; a[5] += d1 * e[2];
        a[6] += d2 * e[0]; a[7] += d2 * e[1]; a[8] += d2 * e[2];
    }
}

/* K^-1 for the optimal rotation r of covariance a, K = tr(M) I - sym(M), M = r^T a: the
 * Hessian of -trace(R^T a) in R = r exp([w]x) at w = 0 (see refine_rotation), whose inverse
 * maps a change of a to the rotation's response (newton_step). Stored as 00 01 02 11 12
 * 22; all zero (the rotation held in the Hessian, a positive semi-definite simplification)
 * where K is not positive definite by refine_rotation's margins (a degenerate cell). */
static inline void cell_kinv(const double a[9], const double r[9], double o[6])
{
    DK_NEWTON_STEP(double, a, r)
    (void)g0, (void)g1, (void)g2, (void)inv, (void)w0, (void)w1, (void)w2, (void)q0, (void)q1,
        (void)q2, (void)q3, (void)q4, (void)q5, (void)q6, (void)q7, (void)q8;
    if (k00 > s && c22 > s * s && det > s * s * s && isfinite(det)) {
        const double id = 1.0 / det;
        o[0] = c00 * id;
        o[1] = c01 * id;
        o[2] = c02 * id;
        o[3] = c11 * id;
        o[4] = c12 * id;
        o[5] = c22 * id;
    } else {
        o[0] = o[1] = o[2] = o[3] = o[4] = o[5] = 0.0;
    }
}

/* Cell i's energy with rotation r. */
static inline double cell_energy(const dk_arap *ar, const arap_system *s, const double *x,
                                 dk_index i, const double r[9])
{
    double ce = 0.0;
    for (dk_index t = ar->cell_start[i]; t < ar->cell_start[i + 1]; t++) {
        const double *pa = x + 3 * ar->ta[t], *pb = x + 3 * ar->tb[t];
        const double *e = ar->te + 3 * t;
        double re0 = r[0] * e[0] + r[1] * e[1] + r[2] * e[2];
        double re1 = r[3] * e[0] + r[4] * e[1] + r[5] * e[2];
        double re2 = r[6] * e[0] + r[7] * e[1] + r[8] * e[2];
        double q0 = pa[0] - pb[0] - re0, q1 = pa[1] - pb[1] - re1, q2 = pa[2] - pb[2] - re2;
        ce += s->tws[t] * (q0 * q0 + q1 * q1 + q2 * q2);
    }
    return ce;
}

/* Local step and energy of the cells v0 .. v1-1 at positions x: rotations into rot (may be
 * NULL: then only the energy, with rotations from scratch); returns their energy. When rot
 * is given it holds rotations on entry (the previous local step's, or identities at a cold
 * start) from which each cell's rotation is refined (refine_rotation, else
 * dk_closest_rotation): both give the maximiser to rounding. The refinements run four cells
 * at a time (refine_rotation4, the same result); the energies are summed in cell order
 * either way. */
static double cells_energy(const dk_arap *ar, const arap_system *s, const double *x,
                           double *rot, dk_index v0, dk_index v1)
{
    double energy = 0.0;
    dk_index i = v0;
#if defined(__GNUC__)
    if (rot)
        for (; i + 4 <= v1; i += 4) {
            double a4[4][9];
            v4d av[9], rv[9];
            for (int l = 0; l < 4; l++)
                cell_covariance(ar, x, i + l, a4[l]);
            const double *r0 = rot + 9 * (size_t)i;
            for (int k = 0; k < 9; k++) {
                av[k] = (v4d){a4[0][k], a4[1][k], a4[2][k], a4[3][k]};
                rv[k] = (v4d){r0[k], r0[9 + k], r0[18 + k], r0[27 + k]};
            }
            const int okmask = refine_rotation4(av, rv);
            for (int l = 0; l < 4; l++) {
                double r[9];
                if (okmask & (1 << l))
                    for (int k = 0; k < 9; k++)
                        r[k] = rv[k][l];
                else
                    dk_closest_rotation(a4[l], r);
                if (s->kinv)
                    cell_kinv(a4[l], r, s->kinv + 6 * (size_t)(i + l));
                energy += cell_energy(ar, s, x, i + l, r);
                memcpy(rot + 9 * (size_t)(i + l), r, sizeof r);
            }
        }
#endif
    for (; i < v1; i++) {
        double a[9], r[9];
        cell_covariance(ar, x, i, a);
        if (rot) {
            memcpy(r, rot + 9 * (size_t)i, sizeof r);
            if (!refine_rotation(a, r))
                dk_closest_rotation(a, r);
        } else {
            dk_closest_rotation(a, r);
        }
        energy += cell_energy(ar, s, x, i, r);
        if (rot) {
            memcpy(rot + 9 * (size_t)i, r, sizeof r);
            if (s->kinv)
                cell_kinv(a, r, s->kinv + 6 * (size_t)i);
        }
    }
    return energy;
}

typedef struct cells_job {
    const dk_arap *ar;
    const arap_system *s;
    const double *x;
    double *rot;
    double energy[2];
} cells_job;

/* One half of the cells (a dk_range_fn). */
static void cells_part(void *ctx, dk_index v0, dk_index v1, int part)
{
    cells_job *j = ctx;
    j->energy[part] = cells_energy(j->ar, j->s, j->x, j->rot, v0, v1);
}

typedef struct rhs_job {
    const arap_system *s;
    const double *rot;
} rhs_job;

/* Rows [u0, u1) of the right-hand side for the rotations (a dk_range_fn; see
 * arap_system.rg). */
static void rhs_part(void *ctx, dk_index u0, dk_index u1, int part)
{
    const rhs_job *j = ctx;
    const arap_system *s = j->s;
    const size_t nu = (size_t)s->nu;
    (void)part;
    for (dk_index u = u0; u < u1; u++) {
        double b0 = s->rhs_const[u], b1 = s->rhs_const[nu + u], b2 = s->rhs_const[2 * nu + u];
        for (int64_t k = s->rg_start[u]; k < s->rg_start[u + 1]; k++) {
            const double *g = s->rg[k].g, *r = j->rot + 9 * (size_t)s->rg[k].cell;
            const double h0 = r[0] * g[0] + r[1] * g[1] + r[2] * g[2];
            const double h1 = r[3] * g[0] + r[4] * g[1] + r[5] * g[2];
            const double h2 = r[6] * g[0] + r[7] * g[1] + r[8] * g[2];
            b0 += h0;
            b1 += h1;
            b2 += h2;
            if (s->nt) { /* Newton: R_c g_{v,c}, for the Hessian products */
                s->nt[k].h[0] = (float)h0;
                s->nt[k].h[1] = (float)h1;
                s->nt[k].h[2] = (float)h2;
            }
        }
        s->rhs[u] = b0;
        s->rhs[nu + u] = b1;
        s->rhs[2 * nu + u] = b2;
    }
}

/* s->rhs := the global step's right-hand side for the rotations rot. */
static void rotations_rhs(const dk_arap *ar, arap_system *s, const double *rot)
{
    rhs_job job = {s, rot};
    dk_team_run_halves(ar->team, rhs_part, &job, s->nu,
                       ar->n_terms >= PARALLEL_TERMS ? 0 : s->nu + 1);
}

/* Local step and energy at positions x: rotations into rot (may be NULL: then only the
 * energy), returns E(x) including soft penalties (when targets are known); the caller gets
 * the next global step's right-hand side from rotations_rhs, once it keeps the iterate. On
 * big meshes the cells are split in two halves, the second on the object's helper thread
 * (the target machines have two cores); without one the calling thread does both halves.
 * The split point depends only on the mesh, so results are reproducible. */
static double local_energy(const dk_arap *ar, const arap_system *s, const double *x,
                           double *rot)
{
    double energy;
    if (ar->n_terms >= PARALLEL_TERMS) {
        cells_job job = {ar, s, x, rot, {0.0, 0.0}};
        dk_team_run_halves(ar->team, cells_part, &job, ar->n, 0);
        energy = job.energy[0] + job.energy[1];
    } else {
        energy = cells_energy(ar, s, x, rot, 0, ar->n);
    }
    if (s->have_targets)
        for (dk_index u = 0; u < s->nu; u++) {
            dk_index v = s->unknowns[u];
            if (s->soft_k[v] > 0.0)
                energy += s->soft_k[v] * dist2(x + 3 * v, s->targets + 3 * s->target_of[v]);
        }
    return energy;
}

/* Constant part of the right-hand side: couplings to eliminated vertices at positions x,
 * and the soft targets. */
static void build_rhs_const(const dk_arap *ar, arap_system *s, const double *x)
{
    const dk_index nu = s->nu;
    memset(s->rhs_const, 0, 3 * (size_t)nu * sizeof(double));
    for (int64_t t = 0; t < ar->n_terms; t++) {
        dk_index a = ar->ta[t], b = ar->tb[t];
        dk_index ua = s->unk[a], ub = s->unk[b];
        if ((ua >= 0) == (ub >= 0))
            continue;
        dk_index u = ua >= 0 ? ua : ub, known = ua >= 0 ? b : a;
        for (int d = 0; d < 3; d++)
            s->rhs_const[(size_t)d * nu + u] += s->tws[t] * x[3 * known + d];
    }
    for (dk_index u = 0; u < nu; u++) {
        dk_index v = s->unknowns[u];
        if (s->soft_k[v] > 0.0)
            for (int d = 0; d < 3; d++)
                s->rhs_const[(size_t)d * nu + u] +=
                    s->soft_k[v] * s->targets[3 * s->target_of[v] + d];
    }
}

static void scatter(const arap_system *s, const double *xu, double *x)
{
    const dk_index nu = s->nu;
    for (dk_index u = 0; u < nu; u++)
        for (int d = 0; d < 3; d++)
            x[3 * s->unknowns[u] + d] = xu[(size_t)d * nu + u];
}

static void gather(const arap_system *s, const double *x, double *xu)
{
    const dk_index nu = s->nu;
    for (dk_index u = 0; u < nu; u++)
        for (int d = 0; d < 3; d++)
            xu[(size_t)d * nu + u] = x[3 * s->unknowns[u] + d];
}

/* a . b (returned) and a . c (into *ac) in one pass over a, each with four partial sums: a
 * single running sum is one floating-point add latency per element (~4 cycles), which made
 * Anderson's dot products cost ~1 ms an iteration on the armadillo; four chains run at the
 * loads' speed. The order of summation is fixed, so the results stay reproducible. */
static double dot2(const double *a, const double *b, const double *c, size_t n, double *ac)
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

/* Solves the m x m SPD system g theta = h in place (Cholesky, regularised); 0 on success. */
static int small_spd_solve(double *g, double *h, int m)
{
    double tr = 0.0;
    for (int i = 0; i < m; i++)
        tr += g[i * m + i];
    if (!(tr > 0.0) || !isfinite(tr))
        return -1;
    for (int i = 0; i < m; i++)
        g[i * m + i] += 1e-10 * tr / m;
    for (int j = 0; j < m; j++) {
        double d = g[j * m + j];
        for (int k = 0; k < j; k++)
            d -= g[j * m + k] * g[j * m + k];
        if (!(d > 0.0))
            return -1;
        d = sqrt(d);
        g[j * m + j] = d;
        for (int i = j + 1; i < m; i++) {
            double v = g[i * m + j];
            for (int k = 0; k < j; k++)
                v -= g[i * m + k] * g[j * m + k];
            g[i * m + j] = v / d;
        }
    }
    for (int i = 0; i < m; i++) {
        double v = h[i];
        for (int k = 0; k < i; k++)
            v -= g[i * m + k] * h[k];
        h[i] = v / g[i * m + i];
    }
    for (int i = m - 1; i >= 0; i--) {
        double v = h[i];
        for (int k = i + 1; k < m; k++)
            v -= g[k * m + i] * h[k];
        h[i] = v / g[i * m + i];
    }
    for (int i = 0; i < m; i++)
        if (!isfinite(h[i]))
            return -1;
    return 0;
}

/* ------------------------------------------------------------------ Newton ------------- */
/* acceleration NEWTON. With R(x) the optimal rotations, E(x) = E(x, R(x)) and (envelope
 * theorem) half its gradient over the unknowns is g = A x - b(R(x)), the global step being
 * x - A^-1 g. Half its Hessian is H = A - db/dx with db(v) = sum_c dR_c g_{v,c} (the
 * right-hand-side map, linear in the rotations) and dR_c = R_c [w_c]x the first-order
 * response of cell c's rotation to the direction v: differentiating its optimality condition
 * skew(R^T S) = 0 gives w_c = -K_c^-1 skew(R_c^T dS_c), dS_c = the covariance of v, K_c as in
 * refine_rotation. With omega_c = R_c w_c, dR_c g = omega_c x (R_c g): the products read 3 + 3
 * numbers per map entry (R_c g is stored with each right-hand side). A Newton step solves
 * H d = -g approximately by preconditioned conjugate gradients, preconditioner A^-1 (the
 * bound factor), from d = 0: its first iterate is the local/global step; at most
 * cg_iterations Hessian products; a direction of non-positive curvature ends it (the first
 * one: the local/global step is used). Then a line search on E (t = 1, 1/2, 1/4, 1/8;
 * accept when E does not increase), and if it fails, the local/global step (which never
 * increases E). Far from a minimum (the local/global step promises more than NEWTON_FAR of
 * E) the local/global step is taken instead. Stopping test: at the first conjugate-gradient
 * iterate, the quadratic
 * model's decrease for the best step along the local/global direction (alpha_0 r_0.z_0) is
 * at most tolerance * E: the local/global test, predicted instead of taken. Cells
 * whose K is not safely positive definite (degenerate) have their rotation held in H (a
 * positive semi-definite simplification, like Gauss-Newton). */

typedef struct hv_job {
    const dk_arap *ar;
    arap_system *s;
    const double *v;   /* rows: the vector, in the mesh layout (n x 3; only unknowns read)  */
    double *out;       /* rows: the result                                                   */
    const double *rhs; /* rows: non-NULL: out = rhs - A v (minus the gradient), else H v    */
    double dot[2];     /* rows: per half, v . out                                           */
} hv_job;

/* Cells [v0, v1) (a dk_range_fn): omega_c for the direction in s->vfull. */
static void hv_cells_part(void *ctx, dk_index v0, dk_index v1, int part)
{
    const hv_job *j = ctx;
    const dk_arap *ar = j->ar;
    const arap_system *s = j->s;
    (void)part;
    const double *x = s->vfull;
    for (dk_index i = v0; i < v1; i++) {
        double a[9] = {0, 0, 0, 0, 0, 0, 0, 0, 0};
        for (dk_index t = ar->cell_start[i]; t < ar->cell_start[i + 1]; t++) {
            const struct nt_term *q = s->ntt + t;
            const double *pa = x + 3 * (size_t)q->a, *pb = x + 3 * (size_t)q->b;
            const double w = q->w, e0 = q->e[0], e1 = q->e[1], e2 = q->e[2];
            const double d0 = w * (pa[0] - pb[0]), d1 = w * (pa[1] - pb[1]),
                         d2 = w * (pa[2] - pb[2]);
            a[0] += d0 * e0; a[1] += d0 * e1; a[2] += d0 * e2;
            a[3] += d1 * e0; a[4] += d1 * e1; a[5] += d1 * e2;
            a[6] += d2 * e0; a[7] += d2 * e1; a[8] += d2 * e2;
        }
        const double *r = ar->rot + 9 * (size_t)i, *k = s->kinv + 6 * (size_t)i;
        /* the skew part of M = r^T a, as in DK_NEWTON_STEP */
        const double m1 = r[0] * a[1] + r[3] * a[4] + r[6] * a[7];
        const double m2 = r[0] * a[2] + r[3] * a[5] + r[6] * a[8];
        const double m3 = r[1] * a[0] + r[4] * a[3] + r[7] * a[6];
        const double m5 = r[1] * a[2] + r[4] * a[5] + r[7] * a[8];
        const double m6 = r[2] * a[0] + r[5] * a[3] + r[8] * a[6];
        const double m7 = r[2] * a[1] + r[5] * a[4] + r[8] * a[7];
        const double g0 = m5 - m7, g1 = m6 - m2, g2 = m1 - m3;
        const double w0 = -(k[0] * g0 + k[1] * g1 + k[2] * g2);
        const double w1 = -(k[1] * g0 + k[3] * g1 + k[4] * g2);
        const double w2 = -(k[2] * g0 + k[4] * g1 + k[5] * g2);
        double *o = s->omega + 3 * (size_t)i;
        o[0] = r[0] * w0 + r[1] * w1 + r[2] * w2;
        o[1] = r[3] * w0 + r[4] * w1 + r[5] * w2;
        o[2] = r[6] * w0 + r[7] * w1 + r[8] * w2;
    }
}

/* Unknowns [u0, u1) (a dk_range_fn): out = rhs - A v, or H v = A v - sum omega_c x R_c g. */
static void hv_rows_part(void *ctx, dk_index u0, dk_index u1, int part)
{
    hv_job *j = ctx;
    const arap_system *s = j->s;
    const size_t nu = (size_t)s->nu;
    const double *v = j->v;
    double dot = 0.0;
    for (dk_index u = u0; u < u1; u++) {
        double b0 = 0.0, b1 = 0.0, b2 = 0.0;
        for (dk_index k = s->a.col_start[u]; k < s->a.col_start[u + 1]; k++) {
            const double av = s->a.values[k], *y = v + 3 * (size_t)s->a_vrow[k];
            b0 += av * y[0];
            b1 += av * y[1];
            b2 += av * y[2];
        }
        if (j->rhs) {
            b0 = j->rhs[u] - b0;
            b1 = j->rhs[nu + u] - b1;
            b2 = j->rhs[2 * nu + u] - b2;
        } else {
            for (int64_t k = s->rg_start[u]; k < s->rg_start[u + 1]; k++) {
                const float *h = s->nt[k].h;
                const double *o = s->omega + 3 * (size_t)s->nt[k].cell;
                b0 -= o[1] * h[2] - o[2] * h[1];
                b1 -= o[2] * h[0] - o[0] * h[2];
                b2 -= o[0] * h[1] - o[1] * h[0];
            }
        }
        j->out[u] = b0;
        j->out[nu + u] = b1;
        j->out[2 * nu + u] = b2;
        const double *y = v + 3 * (size_t)s->unknowns[u];
        dot += y[0] * b0 + y[1] * b1 + y[2] * b2;
    }
    j->dot[part] = dot;
}

/* The local/global step from the current iterate, x + A^-1 (b - A x) with z0 = that
 * correction (E cannot increase): moves s->xu and ar->x, returns the new energy (rotations
 * and K^-1 with it; the caller forms the right-hand side). */
static double local_global_step(const dk_arap *ar, arap_system *s, const double *z0)
{
    const size_t N = 3 * (size_t)s->nu;
    for (size_t i = 0; i < N; i++)
        s->xu[i] += z0[i];
    scatter(s, s->xu, ar->x);
    return local_energy(ar, s, ar->x, ar->rot);
}

/* One Newton step from the current iterate (s->xu = ar->x on the unknowns, with its
 * rotations, K^-1, right-hand side and R_c g; energy `energy`), or the finding that it has
 * converged (*newton_converged = 1, nothing moves). Else the new iterate with all of those,
 * its energy in *e_new. Counters: *rejected (line search failed), *cg_total (products). */
/* Element-wise CG vector updates over the unknowns [u0, u1) of all three coordinate blocks
 * (a dk_range_fn), so that they run on the team like the products: each is a pass over
 * 3 nu doubles that left the helper idle. Element-wise, so the split changes nothing. */
typedef struct vec_job {
    const arap_system *s;
    int op;           /* VEC_STEP, VEC_DIRECTION or VEC_TRIAL                            */
    double a;         /* alpha, beta or t                                                */
    double *y, *w;    /* STEP: d, r;  DIRECTION: p;  TRIAL: gu                           */
    const double *u, *v; /* STEP: p, q;  DIRECTION: z;  TRIAL: xu, d                     */
    double *full;     /* DIRECTION, TRIAL: n x 3 row-major, receives the scattered result */
} vec_job;

enum { VEC_STEP, VEC_DIRECTION, VEC_TRIAL };

static void vec_part(void *ctx, dk_index u0, dk_index u1, int part)
{
    const vec_job *j = ctx;
    const arap_system *s = j->s;
    const size_t nu = (size_t)s->nu;
    const double a = j->a;
    (void)part;
    for (int c = 0; c < 3; c++) {
        const size_t o = (size_t)c * nu;
        if (j->op == VEC_STEP) { /* d += alpha p, r -= alpha q */
            for (size_t i = o + (size_t)u0; i < o + (size_t)u1; i++) {
                j->y[i] += a * j->u[i];
                j->w[i] -= a * j->v[i];
            }
        } else if (j->op == VEC_DIRECTION) { /* p = z + beta p, scattered */
            for (dk_index u = u0; u < u1; u++) {
                const double v = j->u[o + (size_t)u] + a * j->y[o + (size_t)u];
                j->y[o + (size_t)u] = v;
                j->full[3 * (size_t)s->unknowns[u] + (size_t)c] = v;
            }
        } else { /* gu = xu + t d, scattered */
            for (dk_index u = u0; u < u1; u++) {
                const double v = j->u[o + (size_t)u] + a * j->v[o + (size_t)u];
                j->y[o + (size_t)u] = v;
                j->full[3 * (size_t)s->unknowns[u] + (size_t)c] = v;
            }
        }
    }
}

static dk_status newton_step(dk_arap *ar, arap_system *s, double energy, double *e_new,
                             int *newton_converged, int *rejected, int *cg_total, dk_error *err)
{
    const dk_index nu = s->nu;
    const size_t N = 3 * (size_t)nu;
    const int par = ar->n_terms >= PARALLEL_TERMS;
    const dk_index cells_min = par ? 0 : ar->n + 1, rows_min = par ? 0 : nu + 1;
    double *r = s->nt_r, *z = s->nt_z, *p = s->nt_p, *q = s->nt_q, *d = s->nt_d;
    double *z0 = s->nt_z0, ignored;
    *newton_converged = 0;
    hv_job job = {ar, s, ar->x, r, s->rhs, {0.0, 0.0}};
    dk_team_run_halves(ar->team, hv_rows_part, &job, nu, rows_min); /* r = -g */
    dk_status st = dk_cholesky_solve(s->chol, r, 3, z0, err);
    if (st != DK_OK)
        return st;
    double rz = dot2(r, z0, z0, N, &ignored);
    const double rz0 = rz;
    if (rz0 > NEWTON_FAR * energy) { /* far from a minimum: the local/global step */
        *e_new = local_global_step(ar, s, z0);
        rotations_rhs(ar, s, ar->rot);
        return DK_OK;
    }
    memcpy(p, z0, N * sizeof(double));
    memset(d, 0, N * sizeof(double));
    scatter(s, p, s->vfull);
    job.v = s->vfull;
    job.out = q;
    job.rhs = NULL;
    for (int k = 0; k < ar->opt.cg_iterations; k++) {
        dk_team_run_halves(ar->team, hv_cells_part, &job, ar->n, cells_min);
        dk_team_run_halves(ar->team, hv_rows_part, &job, nu, rows_min);
        (*cg_total)++;
        const double pq = job.dot[0] + job.dot[1];
        if (!(pq > 0.0) || !(rz > 0.0)) {
            if (k == 0) /* non-positive curvature at once: the local/global step */
                memcpy(d, p, N * sizeof(double));
            break;
        }
        const double alpha = rz / pq;
        /* The stopping test, on the first iterate: alpha rz0 is the decrease of the
         * quadratic model for the best step along the local/global direction, which is at
         * least what a local/global step would achieve; at most tolerance * E: converged,
         * the local/global test predicted instead of taken (so that one tolerance means the
         * same for every acceleration). Nothing moves. */
        if (k == 0 && alpha * rz <= ar->opt.tolerance * energy) {
            *newton_converged = 1;
            *e_new = energy;
            return DK_OK;
        }
        {
            vec_job vj = {s, VEC_STEP, alpha, d, r, p, q, NULL};
            dk_team_run_halves(ar->team, vec_part, &vj, nu, rows_min);
        }
        if (k + 1 == ar->opt.cg_iterations)
            break;
        st = dk_cholesky_solve(s->chol, r, 3, z, err);
        if (st != DK_OK)
            return st;
        const double rzn = dot2(r, z, z, N, &ignored);
        if (!(rzn > 1e-24 * rz0))
            break; /* solved to rounding */
        const double beta = rzn / rz;
        {
            vec_job vj = {s, VEC_DIRECTION, beta, p, NULL, z, NULL, s->vfull};
            dk_team_run_halves(ar->team, vec_part, &vj, nu, rows_min);
        }
        rz = rzn;
    }
    /* line search on E; its last evaluation is the kept iterate's local step */
    double t = 1.0, e = NAN;
    int accepted = 0;
    for (int ls = 0; ls < 4 && !accepted; ls++) {
        if (ls > 0)
            t *= 0.5;
        {
            vec_job vj = {s, VEC_TRIAL, t, s->gu, NULL, s->xu, d, ar->x};
            dk_team_run_halves(ar->team, vec_part, &vj, nu, rows_min);
        }
        e = local_energy(ar, s, ar->x, ar->rot);
        accepted = e <= energy;
    }
    if (accepted) {
        memcpy(s->xu, s->gu, N * sizeof(double));
    } else { /* the line search failed: the local/global step */
        (*rejected)++;
        e = local_global_step(ar, s, z0);
    }
    rotations_rhs(ar, s, ar->rot);
    *e_new = e;
    return DK_OK;
}

static dk_status solve_impl(dk_arap *ar, const dk_solve_request *rq, double *positions,
                            dk_solve_info *info, dk_error *err)
{
    if (info)
        memset(info, 0, sizeof *info);
    if (!ar || !positions)
        return dk_error_set(err, DK_ERR_INVALID_ARGUMENT,
                            "ARAP solve: object and positions must not be NULL");
    dk_status st = dk_solve_request_check(rq, "ARAP solve", err);
    if (st != DK_OK)
        return st;
    const double *targets = rq->targets;
    const int warm_start = rq->start != DK_START_COLD;
    const int max_iterations = rq->max_iterations;
    arap_system *s = &ar->sys;
    const dk_constraints *c = s->con;
    const dk_index n = ar->n, nu = s->nu;
    const size_t N = 3 * (size_t)nu;
    const double *rest = ar->mesh->positions;
    st = dk_constraints_targets(c, rest, targets, (int)rq->target_kind, s->targets, err);
    if (st != DK_OK) {
        s->have_targets = 0;
        return dk_error_prefix(err, "ARAP solve");
    }
    s->have_targets = 1;
    const int maxit = max_iterations > 0 ? max_iterations : ar->opt.max_iterations;
    const int accel = ar->opt.acceleration == DK_ARAP_ACCEL_ANDERSON;
    const int newton = ar->opt.acceleration == DK_ARAP_ACCEL_NEWTON;
    const int depth = ar->opt.anderson_depth;

    /* Resume: the previous call's targets again, and nothing changed since:
     * continue exactly where it stopped, acceleration history included, so that solves
     * resumed in slices (the add-on's interactive time budget) equal one longer solve. */
    const size_t nhv3 = 3 * (size_t)s->con->n_handle_vertices;
    const int resume = rq->start == DK_START_RESUME && ar->have_prev && s->resumable &&
                       memcmp(s->targets, s->targets_prev, nhv3 * sizeof(double)) == 0;
    /* Gram matrix of the df slots, gram[i * MAX_ANDERSON_DEPTH + j] = df_i . df_j: only the
     * row of the slot written in an iteration changes */
    double *gram = s->aa_gram;
    double energy;
    if (resume) {
        energy = s->last_energy; /* ar->x, s->xu, s->rhs, ar->rot: as the last call left them */
    } else {
        /* Eliminated vertices: hard targets or rest; unknowns: previous solution or rest. */
        const int warm = warm_start && ar->have_prev;
        int have_energy = 0;
        s->predicted = 0;
        memcpy(ar->x, warm ? ar->prev : rest, 3 * (size_t)n * sizeof(double));
        for (dk_index v = 0; v < n; v++)
            if (s->unk[v] < 0)
                for (int d = 0; d < 3; d++)
                    ar->x[3 * v + d] =
                        s->target_of[v] >= 0 ? s->targets[3 * s->target_of[v] + d] : rest[3 * v + d];
        build_rhs_const(ar, s, ar->x);
        if (!warm) { /* initial guess: global step with identity rotations */
            /* identities also start the local steps' refinement (cells_energy), so that a cold
             * solve depends on its input only, bit for bit, whatever was solved before */
            static const double id[9] = {1, 0, 0, 0, 1, 0, 0, 0, 1};
            for (dk_index v = 0; v < n; v++)
                memcpy(ar->rot + 9 * (size_t)v, id, sizeof id);
            rotations_rhs(ar, s, ar->rot);
            st = dk_cholesky_solve(s->chol, s->rhs, 3, s->gu, err);
            if (st != DK_OK)
                return dk_error_prefix(err, "ARAP solve");
            scatter(s, s->gu, ar->x);
        } else {
            /* Warm start after a handle move: a base plus the response of the global step
             * (previous rotations held) to how far the constrained vertices are from the
             * base, x0 = base + A^-1 (b(new known) - b(base known)). This spreads a handle's
             * jump smoothly over the free vertices instead of leaving it at the handle's
             * border. The plain base is the previous solution. The predicted one (option
             * predict) continues the drag: with the ends x1, x2 of the last two calls for
             * different targets t1, t2 (x1 = the previous solution; converged or cut by
             * max_iterations, as the add-on's time-budgeted updates are), alpha = the
             * projection of the new targets' step t - t1 onto the last step t1 - t2, clamped
             * to [0, 2], and base = x1 + alpha (x1 - x2): a predictor-corrector continuation,
             * the response covering what of the move is not along the last step. Both starts
             * come from one 6-column solve and the one with the lower ARAP energy is taken,
             * so a drag that turns or stops cannot start worse than the plain warm start.
             * The choice is ours (the paper restarts from the previous solution); measured on
             * the armadillo-wave drag in 20 straight steps of 1.6% of the bbox, converged
             * (1e-6) re-solves take 7-29 iterations (median 12.5) instead of 19-65 (median
             * 35) and stop closer to the true minimum (1e-5..7e-5 above it instead of up to
             * 2.3e-4); on a curved drag 5-42 (median 13) instead of 12-64 (median 27.5); with
             * 4 iterations per step (an interactive budget) the energy after each step is
             * 5-14x closer to the step's minimum. Soft handles' own target changes are not in
             * the response: this is only a starting point, and the iterations do the rest. */
            const dk_index nu = s->nu;
            const double *x1 = ar->prev, *x2 = ar->prev2;
            double alpha = 0.0;
            int moved = 0;
            if (ar->opt.predict && ar->n_hist == 2) {
                double dd = 0.0, dt = 0.0;
                for (size_t k = 0; k < nhv3; k++) {
                    const double a = s->targets_prev[k] - s->targets_prev2[k];
                    dd += a * a;
                    dt += a * (s->targets[k] - s->targets_prev[k]);
                }
                if (dd > 0.0 && dt > 0.0)
                    alpha = dt / dd < 2.0 ? dt / dd : 2.0;
            }
            const int predict = alpha > 0.0;
            const size_t N3 = 3 * (size_t)nu;
            double *w = s->warm; /* columns 0-2: plain response; 3-5: predicted one */
            memset(w, 0, (predict ? 2 : 1) * N3 * sizeof(double));
            /* only the terms across the constraints' borders (a few % of all), in order */
            for (int64_t bt = 0; bt < s->n_bterms; bt++) {
                const int64_t t = s->bterms[bt];
                const dk_index a = ar->ta[t], b = ar->tb[t];
                const dk_index ua = s->unk[a], ub = s->unk[b];
                const dk_index u = ua >= 0 ? ua : ub, known = ua >= 0 ? b : a;
                for (int d = 0; d < 3; d++) {
                    const size_t k = 3 * (size_t)known + (size_t)d;
                    const double dx = ar->x[k] - ar->prev[k];
                    if (dx != 0.0) {
                        w[(size_t)d * nu + u] += s->tws[t] * dx;
                        moved = 1;
                    }
                    if (predict)
                        w[N3 + (size_t)d * nu + u] +=
                            s->tws[t] * (ar->x[k] - (x1[k] + alpha * (x1[k] - x2[k])));
                }
            }
            if (moved || predict) {
                st = dk_cholesky_solve(s->chol, w, predict ? 6 : 3, w, err);
                if (st != DK_OK)
                    return dk_error_prefix(err, "ARAP solve");
            }
            /* the plain start (ar->x holds the previous solution on the unknowns) */
            if (moved)
                for (dk_index u = 0; u < nu; u++)
                    for (int d = 0; d < 3; d++)
                        ar->x[3 * s->unknowns[u] + d] += w[(size_t)d * nu + u];
            if (predict) {
                const double e_plain = local_energy(ar, s, ar->x, ar->rot);
                gather(s, ar->x, s->xu); /* keep the plain start */
                for (dk_index u = 0; u < nu; u++)
                    for (int d = 0; d < 3; d++) {
                        const size_t k = 3 * (size_t)s->unknowns[u] + (size_t)d;
                        ar->x[k] = x1[k] + alpha * (x1[k] - x2[k]) + w[N3 + (size_t)d * nu + u];
                    }
                const double e_pred = local_energy(ar, s, ar->x, ar->rot);
                if (e_pred <= e_plain) {
                    s->predicted = 1;
                    energy = e_pred;
                } else {
                    scatter(s, s->xu, ar->x);
                    energy = local_energy(ar, s, ar->x, ar->rot);
                }
                have_energy = 1;
            }
        }
        if (!have_energy)
            energy = local_energy(ar, s, ar->x, ar->rot);
        rotations_rhs(ar, s, ar->rot);
        if (ar->opt.on_iteration && ar->opt.on_iteration(ar->opt.user, 0, energy))
            return dk_error_set(err, DK_ERR_CANCELLED, "ARAP solve: cancelled by the observer");
        s->aa_hist = s->aa_head = s->aa_have_pair = 0;
        gather(s, ar->x, s->xu);
    }
    const double tiny = 1e-26 * s->escale;
    int it = 0, converged = energy <= tiny, rejected = 0, cg_total = 0;
    int hist = s->aa_hist, head = s->aa_head, have_prev_pair = s->aa_have_pair;
    s->resumable = 0; /* until this call ends normally */
    while (newton && !converged && it < maxit) {
        it++;
        double e_new;
        int newton_converged;
        st = newton_step(ar, s, energy, &e_new, &newton_converged, &rejected, &cg_total, err);
        if (st != DK_OK)
            return dk_error_prefix(err, "ARAP solve");
        /* or a step that did not lower E at all (rounding level: stagnation) */
        converged = e_new <= tiny || newton_converged || (energy - e_new) <= 0.0;
        energy = e_new;
        if (ar->opt.on_iteration && ar->opt.on_iteration(ar->opt.user, it, energy))
            return dk_error_set(err, DK_ERR_CANCELLED, "ARAP solve: cancelled by the observer");
    }
    while (!newton && !converged && it < maxit) {
        it++;
        /* s->rhs: from the last local step, the one at the current iterate */
        st = dk_cholesky_solve(s->chol, s->rhs, 3, s->gu, err);
        if (st != DK_OK)
            return dk_error_prefix(err, "ARAP solve");
        int used_accel = 0;
        if (accel) {
            /* The vector passes are fused (each was memory-bound on its own): the residual,
             * the new difference pair and the saved pair in one pass; each slot's Gram entry
             * and its projection of the residual in one pass over the slot; the mix in one
             * pass (the same subtraction order as one pass per slot). */
            double h[MAX_ANDERSON_DEPTH];
            if (have_prev_pair) {
                double *dgc = s->dg + (size_t)head * N, *dfc = s->df + (size_t)head * N;
                for (size_t k = 0; k < N; k++) {
                    const double gk = s->gu[k], fk = gk - s->xu[k];
                    s->fu[k] = fk;
                    dgc[k] = gk - s->gprev[k];
                    dfc[k] = fk - s->fprev[k];
                    s->gprev[k] = gk;
                    s->fprev[k] = fk;
                }
                if (hist < depth)
                    hist++;
                for (int j = 0; j < hist; j++)
                    gram[head * MAX_ANDERSON_DEPTH + j] = gram[j * MAX_ANDERSON_DEPTH + head] =
                        dot2(s->df + (size_t)j * N, dfc, s->fu, N, &h[j]);
                head = (head + 1) % depth;
            } else {
                for (size_t k = 0; k < N; k++) {
                    const double gk = s->gu[k], fk = gk - s->xu[k];
                    s->fu[k] = fk;
                    s->gprev[k] = gk;
                    s->fprev[k] = fk;
                }
                for (int j = 0; j < hist; j++) /* (hist is 0 here in practice) */
                    (void)dot2(s->df + (size_t)j * N, s->fu, s->fu, N, &h[j]);
            }
            have_prev_pair = 1;
            if (hist > 0) {
                double g[MAX_ANDERSON_DEPTH * MAX_ANDERSON_DEPTH];
                for (int i = 0; i < hist; i++)
                    for (int j = 0; j < hist; j++)
                        g[i * hist + j] = gram[i * MAX_ANDERSON_DEPTH + j];
                if (small_spd_solve(g, h, hist) == 0) {
                    const double *dgs[MAX_ANDERSON_DEPTH];
                    for (int i = 0; i < hist; i++)
                        dgs[i] = s->dg + (size_t)i * N;
                    for (size_t k = 0; k < N; k++) {
                        double xk = s->gu[k];
                        for (int i = 0; i < hist; i++)
                            xk -= h[i] * dgs[i][k];
                        s->xu[k] = xk;
                    }
                    used_accel = 1;
                }
            }
        }
        double e_new;
        if (used_accel) {
            scatter(s, s->xu, ar->x);
            e_new = local_energy(ar, s, ar->x, ar->rot);
            if (!(e_new <= energy)) { /* safeguard: plain step, forget the history */
                rejected++;
                hist = 0;
                head = 0;
                used_accel = 0;
            }
        }
        if (!used_accel) {
            memcpy(s->xu, s->gu, N * sizeof(double));
            scatter(s, s->xu, ar->x);
            e_new = local_energy(ar, s, ar->x, ar->rot);
        }
        rotations_rhs(ar, s, ar->rot); /* the next global step's, at the kept iterate */
        converged = e_new <= tiny || (energy - e_new) <= ar->opt.tolerance * energy;
        energy = e_new;
        if (ar->opt.on_iteration && ar->opt.on_iteration(ar->opt.user, it, energy))
            return dk_error_set(err, DK_ERR_CANCELLED, "ARAP solve: cancelled by the observer");
    }
    /* the predictor's history: with other targets than the previous call's, that call's end
     * moves to prev2 (a pointer swap); with the same ones (a resumed slice) it is replaced */
    if (!warm_start)
        ar->n_hist = 0;
    if (ar->n_hist > 0 && memcmp(s->targets_prev, s->targets, nhv3 * sizeof(double)) != 0) {
        double *t = ar->prev2;
        ar->prev2 = ar->prev;
        ar->prev = t;
        t = s->targets_prev2;
        s->targets_prev2 = s->targets_prev;
        s->targets_prev = t;
        ar->n_hist = 2;
    } else if (ar->n_hist == 0) {
        ar->n_hist = 1;
    }
    dk_reorder_rows_out(ar->ro, ar->x, positions);
    memcpy(ar->prev, ar->x, 3 * (size_t)n * sizeof(double));
    ar->have_prev = 1;
    memcpy(s->targets_prev, s->targets, nhv3 * sizeof(double));
    s->aa_hist = hist;
    s->aa_head = head;
    s->aa_have_pair = have_prev_pair;
    s->last_energy = energy;
    s->resumable = 1;
    if (info) {
        info->energy = energy;
        info->iterations = it;
        info->converged = converged;
        info->rejected = rejected;
        info->predicted = !resume && s->predicted;
        info->cg_iterations = cg_total;
    }
    return DK_OK;
}

dk_status dk_arap_solve(dk_arap *ar, const dk_solve_request *request, double *positions,
                        dk_solve_info *info, dk_error *err)
{
    const dk_status st = solve_impl(ar, request, positions, info, err);
    if (ar)
        dk_team_park(ar->team); /* the helper sleeps until the next solve */
    return st;
}

dk_status dk_arap_set_tolerance(dk_arap *ar, double tolerance, dk_error *err)
{
    if (!ar)
        return dk_error_set(err, DK_ERR_INVALID_ARGUMENT, "ARAP: object is NULL");
    if (!(isfinite(tolerance) && tolerance >= 0.0))
        return dk_error_set(err, DK_ERR_INVALID_ARGUMENT,
                            "ARAP: tolerance is %g, must be finite and >= 0", tolerance);
    ar->opt.tolerance = tolerance;
    return DK_OK;
}

dk_status dk_arap_energy(const dk_arap *ar, const double *positions, double *energy,
                         dk_error *err)
{
    if (energy)
        *energy = NAN;
    if (!ar || !positions || !energy)
        return dk_error_set(err, DK_ERR_INVALID_ARGUMENT,
                            "ARAP energy: object, positions and energy must not be NULL");
    double *x = malloc(((size_t)ar->n * 3 + 1) * sizeof *x);
    if (!x)
        return oom(err, "ARAP energy");
    dk_reorder_rows_in(ar->ro, positions, x);
    *energy = local_energy(ar, &ar->sys, x, NULL);
    free(x);
    return DK_OK;
}

const dk_constraints *dk_arap_constraints(const dk_arap *ar)
{
    return ar ? ar->sys.con : NULL;
}

void dk_arap_stats(const dk_arap *ar, dk_method_stats *stats)
{
    if (!stats)
        return;
    memset(stats, 0, sizeof *stats);
    if (!ar)
        return;
    stats->n_vertices = ar->n;
    stats->n_handles = ar->sys.con->n_handles;
    stats->n_handle_vertices = ar->sys.con->n_handle_vertices;
    stats->n_unknowns = ar->sys.nu;
    stats->analysis_count = ar->analysis_count;
    stats->factorization_count = ar->factorization_count;
}

/* ---------------------------------------------------------------- the method contract --- */

static dk_status ops_bind(const dk_mesh *mesh, const dk_constraint_desc *c,
                          const void *options, void **out, dk_error *err)
{
    return dk_arap_bind(mesh, c, (const dk_arap_options *)options, (dk_arap **)out, err);
}

static dk_status ops_rebind(void *self, const dk_constraint_desc *c, dk_error *err)
{
    return dk_arap_rebind((dk_arap *)self, c, err);
}

static dk_status ops_solve(void *self, const dk_solve_request *rq, double *positions,
                           dk_solve_info *info, dk_error *err)
{
    return dk_arap_solve((dk_arap *)self, rq, positions, info, err);
}

static dk_status ops_energy(const void *self, const double *positions, double *energy,
                            dk_error *err)
{
    return dk_arap_energy((const dk_arap *)self, positions, energy, err);
}

static void ops_stats(const void *self, dk_method_stats *stats)
{
    dk_arap_stats((const dk_arap *)self, stats);
}

static void ops_free(void *self)
{
    dk_arap_free((dk_arap *)self);
}

const dk_method_ops dk_arap_ops = {
    .name = "ARAP",
    .flags = DK_METHOD_ITERATIVE | DK_METHOD_TRANSFORMS_AS_POSITIONS |
             DK_METHOD_TRANSLATION_INVARIANT | DK_METHOD_RIGID_INVARIANT,
    .bind = ops_bind,
    .rebind = ops_rebind,
    .solve = ops_solve,
    .energy = ops_energy,
    .stats = ops_stats,
    .free = ops_free,
};
