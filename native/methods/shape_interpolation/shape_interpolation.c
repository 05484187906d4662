/* DeformKit shape interpolation: the driver (dk_shape_interpolation.h). A bind: check the
 * options and the mesh, the rest frames, the edge weights, the constraints, the poses'
 * rotations and stretches (poses.c, lift.c, stretch.c), the factored system (system.c). A
 * solve:
 * the blended gradient of every triangle, each edge's target, the right-hand side, one
 * back-substitution, the constrained vertices, the parts placed by their means. */
#include "si_internal.h"

#include <float.h>
#include <math.h>
#include <stddef.h>
#include <stdlib.h>
#include <string.h>

#include "dk_memory.h"
#include "dk_operators.h"

/* The largest weight a solve takes: far beyond any extrapolation an artist means, and small
 * enough that the blended rotation vectors and stretches stay finite. */
#define MAX_WEIGHT 1e6
/* Below this many items a pass runs on the calling thread only. */
#define PARALLEL_ITEMS 20000

struct dk_shape_interpolation {
    const dk_mesh *mesh;
    dk_shape_interpolation_options opt;
    double *vinv;               /* F x 9: inverse rest frames                             */
    unsigned char *degenerate;  /* F                                                      */
    double *ew;                 /* n_edges: c_ij                                          */
    unsigned char *edge_faces;  /* n_edges: its non-degenerate triangles (0, 1 or 2)      */
    si_poses poses;
    si_system sys;
    dk_csys_counts counts;
    /* scratch and the last solve */
    double *J;                  /* F x 9: blended gradients                               */
    double *Pt;                 /* F x 6: their stretches, kept by the refining iterations */
    double *d;                  /* n_edges x 3: edge targets of the last solve            */
    double *rhs;                /* nu x 3, column-major                                   */
    double *tgt;                /* n_handle_vertices x 3                                  */
    double *part_sum;           /* n_components x 4: a part's sum of positions, count      */
    double *part_turn;          /* n_components x 15: a part's sums of input and rest, and
                                 * their covariance: the input's turn of the part          */
    dk_team *team;
    dk_phase_progress_fn rebind_progress;
    void *rebind_progress_user;
};

enum { PHASE_POSES = 0, PHASE_ANALYZE = 1, PHASE_FACTORIZE = 2 };
static const dk_progress_phase phases[] = {{"poses", 1.0}, {"analyze", 0.5}, {"factorize", 1.0}};

void dk_shape_interpolation_default_options(dk_shape_interpolation_options *o)
{
    memset(o, 0, sizeof *o);
    o->rotations = DK_SI_ROTATIONS_CONSISTENT;
    o->stretches = DK_SI_STRETCHES_LINEAR;
    o->refine = 0;
    o->edge_weights = DK_SI_WEIGHTS_CLAMPED_COTANGENT;
}

static dk_status check_options(const dk_shape_interpolation_options *o, dk_error *err)
{
    if ((unsigned)o->rotations > DK_SI_ROTATIONS_PRINCIPAL)
        return dk_error_set(err, DK_ERR_INVALID_ARGUMENT, "ShapeInterpolation: rotations = %d, "
                            "must be 0 (consistent) or 1 (principal)", (int)o->rotations);
    if ((unsigned)o->stretches > DK_SI_STRETCHES_LOG)
        return dk_error_set(err, DK_ERR_INVALID_ARGUMENT, "ShapeInterpolation: stretches = %d, "
                            "must be 0 (linear) or 1 (log)", (int)o->stretches);
    if (o->refine < 0 || o->refine > DK_SI_MAX_REFINE)
        return dk_error_set(err, DK_ERR_INVALID_ARGUMENT, "ShapeInterpolation: refine = %d, "
                            "must be in [0, %d]", o->refine, DK_SI_MAX_REFINE);
    if ((unsigned)o->edge_weights > DK_SI_WEIGHTS_UNIFORM)
        return dk_error_set(err, DK_ERR_INVALID_ARGUMENT, "ShapeInterpolation: edge_weights = "
                            "%d, must be 0 (clamped cotangent), 1 (cotangent) or 2 (uniform)",
                            (int)o->edge_weights);
    return DK_OK;
}

/* The poses of a constraint description: none (NULL control) or checked POSES. */
static dk_status poses_of(const dk_mesh *m, const dk_constraint_desc *desc, const double **poses,
                          dk_index *n_poses, dk_error *err)
{
    *poses = NULL;
    *n_poses = 0;
    if (!desc->control)
        return DK_OK;
    dk_status st = dk_control_taken(desc->control, DK_CONTROL_VERTEX_GROUPS | DK_CONTROL_POSES,
                                    "ShapeInterpolation", err);
    if (st == DK_OK)
        st = dk_control_check(desc->control, m->n_vertices, err);
    if (st != DK_OK)
        return st;
    *poses = desc->control->rest;
    *n_poses = desc->control->n_controls;
    return DK_OK;
}

/* The bytes the poses take: a copy, and per triangle a rotation vector, a residual and a
 * stretch; the scratch of their build. */
static uint64_t pose_bytes(const dk_mesh *m, dk_index n_poses)
{
    const double P = (double)n_poses, F = (double)m->n_faces, n = (double)m->n_vertices;
    return (uint64_t)(P * (24.0 * n + 96.0 * F) + (n_poses ? 120.0 * F : 0.0));
}

/* Which vertices seed the branch trees: the constrained ones. */
static unsigned char *seed_vertices(const dk_constraints *con, dk_index n)
{
    unsigned char *seed = malloc((size_t)n + 1);
    if (seed)
        for (dk_index v = 0; v < n; v++)
            seed[v] = con->role[v] != DK_VERTEX_FREE;
    return seed;
}

/* New constraints (and poses, when `poses` is not NULL; else the bound ones, chosen again
 * from the new seeds) into fresh parts; the object takes them only when all succeed. */
static dk_status build(dk_shape_interpolation *s, const dk_constraint_desc *desc,
                       const double *poses, dk_index n_poses, dk_progress *prog, dk_error *err)
{
    const dk_mesh *m = s->mesh;
    dk_constraint_desc groups = *desc;
    groups.control = NULL;
    if (!poses) {
        poses = s->poses.positions;
        n_poses = s->poses.n_poses;
    }
    /* with poses every part is driven (a part no handle or fixed vertex holds follows the
     * blend); without, a loose part is held at rest as by every method */
    dk_constraints *con = NULL;
    dk_status st = n_poses > 0 ? dk_constraints_create_simulated(m, &groups, &con, err)
                               : dk_constraints_create(m, &groups, &con, err);
    if (st != DK_OK)
        return st;
    st = dk_memory_check(pose_bytes(m, n_poses), "ShapeInterpolation", "keeping the poses", err);
    unsigned char *seed = st == DK_OK ? seed_vertices(con, m->n_vertices) : NULL;
    if (st == DK_OK && !seed)
        st = dk_error_set(err, DK_ERR_OUT_OF_MEMORY, "ShapeInterpolation: out of memory (seeds)");
    si_poses np;
    memset(&np, 0, sizeof np);
    if (st == DK_OK)
        st = si_poses_build(m, s->vinv, s->degenerate, poses, n_poses, &s->opt, seed, &np, prog,
                            PHASE_POSES, err);
    free(seed);
    double *tgt = st == DK_OK ? malloc(3 * (size_t)con->n_handle_vertices * sizeof(double) + 1)
                              : NULL;
    if (st == DK_OK && !tgt)
        st = dk_error_set(err, DK_ERR_OUT_OF_MEMORY, "ShapeInterpolation: out of memory (targets)");
    if (st != DK_OK) {
        dk_constraints_free(con);
        si_poses_free(&np);
        return st;
    }
    /* the right-hand side's room first (the unknowns are at most the vertices): once the new
     * system has taken the old one's factor over, nothing may fail */
    double *rhs = malloc(3 * (size_t)m->n_vertices * sizeof(double) + 1);
    if (!rhs) {
        dk_constraints_free(con);
        si_poses_free(&np);
        free(tgt);
        return dk_error_set(err, DK_ERR_OUT_OF_MEMORY, "ShapeInterpolation: out of memory (rhs)");
    }
    si_system sys;
    dk_csys_counts counts = s->counts;
    st = si_system_build(m, s->ew, con, s->sys.con ? &s->sys : NULL, s->team, &counts, prog,
                         PHASE_ANALYZE, &sys, err); /* takes con */
    if (st != DK_OK) {
        free(rhs);
        si_poses_free(&np);
        free(tgt);
        if (st != DK_ERR_CANCELLED)
            s->counts = counts;
        return st;
    }
    s->counts = counts;
    si_system_free(&s->sys);
    s->sys = sys;
    si_poses_free(&s->poses);
    s->poses = np;
    free(s->tgt);
    s->tgt = tgt;
    free(s->rhs);
    s->rhs = rhs;
    return DK_OK;
}

/* Every edge's target at the rest: its own vector (the energy before any solve). */
static void rest_edges(const dk_mesh *m, const double *x, double *d)
{
    for (dk_index e = 0; e < m->n_edges; e++) {
        const dk_index a = m->edges[2 * (size_t)e], b = m->edges[2 * (size_t)e + 1];
        for (int k = 0; k < 3; k++)
            d[3 * (size_t)e + k] = x[3 * (size_t)a + k] - x[3 * (size_t)b + k];
    }
}

dk_status dk_shape_interpolation_bind(const dk_mesh *mesh, const dk_constraint_desc *desc,
                                      const dk_shape_interpolation_options *options,
                                      dk_shape_interpolation **out, dk_error *err)
{
    if (out)
        *out = NULL;
    if (!mesh || !desc || !out)
        return dk_error_set(err, DK_ERR_INVALID_ARGUMENT, "ShapeInterpolation bind: mesh, "
                            "constraints and output must not be NULL");
    dk_shape_interpolation_options o;
    if (options)
        o = *options;
    else
        dk_shape_interpolation_default_options(&o);
    dk_status st = check_options(&o, err);
    if (st != DK_OK)
        return st;
    if (mesh->n_faces == 0)
        return dk_error_set(err, DK_ERR_INVALID_ARGUMENT, "ShapeInterpolation: the mesh has no "
                            "faces: the in-betweens blend its triangles");
    const double *poses;
    dk_index n_poses;
    st = poses_of(mesh, desc, &poses, &n_poses, err);
    if (st != DK_OK)
        return st;
    dk_progress prog;
    dk_progress_init(&prog, o.progress, o.progress_user, phases, 3, "ShapeInterpolation bind");
    dk_shape_interpolation *s = calloc(1, sizeof *s);
    if (!s)
        return dk_error_set(err, DK_ERR_OUT_OF_MEMORY, "ShapeInterpolation: out of memory");
    s->mesh = mesh;
    s->opt = o;
    s->opt.progress = NULL;
    s->opt.progress_user = NULL;
    const size_t F = (size_t)mesh->n_faces, E = (size_t)mesh->n_edges;
    const size_t nc = (size_t)mesh->report.n_components;
    s->vinv = malloc(9 * F * sizeof(double));
    s->degenerate = malloc(F);
    s->ew = malloc(E * sizeof(double) + 1);
    s->edge_faces = malloc(E + 1);
    s->J = malloc(9 * F * sizeof(double));
    s->Pt = malloc(6 * F * sizeof(double));
    s->d = malloc(3 * E * sizeof(double) + 1);
    s->part_sum = malloc(4 * nc * sizeof(double) + 1);
    s->part_turn = malloc(15 * nc * sizeof(double) + 1);
    if (!s->vinv || !s->degenerate || !s->ew || !s->edge_faces || !s->J || !s->Pt || !s->d || !s->part_sum ||
        !s->part_turn) {
        dk_shape_interpolation_free(s);
        return dk_error_set(err, DK_ERR_OUT_OF_MEMORY, "ShapeInterpolation: out of memory "
                            "(%d triangles)", (int)F);
    }
    si_rest_frames(mesh, s->vinv, s->degenerate);
    for (size_t e = 0; e < E; e++) {
        const dk_index nf = mesh->edge_face_count[e] < 2 ? mesh->edge_face_count[e] : 2;
        s->edge_faces[e] = 0;
        for (dk_index j = 0; j < nf; j++) {
            const dk_index t = mesh->edge_faces[2 * e + (size_t)j];
            s->edge_faces[e] += (unsigned char)(t >= 0 && !s->degenerate[t]);
        }
    }
    rest_edges(mesh, mesh->positions, s->d);
    s->team = dk_team_create(); /* NULL: passes run on this thread */
    st = si_edge_weights(mesh, o.edge_weights, s->ew, err);
    if (st == DK_OK)
        st = build(s, desc, poses, n_poses, &prog, err);
    if (st != DK_OK) {
        dk_shape_interpolation_free(s);
        return st;
    }
    dk_progress_done(&prog);
    *out = s;
    return DK_OK;
}

dk_status dk_shape_interpolation_rebind(dk_shape_interpolation *s, const dk_constraint_desc *desc,
                                        dk_error *err)
{
    if (!s || !desc)
        return dk_error_set(err, DK_ERR_INVALID_ARGUMENT, "ShapeInterpolation rebind: object "
                            "and constraints must not be NULL");
    const double *poses;
    dk_index n_poses;
    dk_status st = poses_of(s->mesh, desc, &poses, &n_poses, err);
    if (st != DK_OK)
        return st;
    dk_progress prog;
    dk_progress_init(&prog, s->rebind_progress, s->rebind_progress_user, phases, 3,
                     "ShapeInterpolation rebind");
    /* a poses' copy of the object's own: the build frees the old one when it succeeds */
    st = build(s, desc, desc->control ? poses : NULL, n_poses, &prog, err);
    if (st == DK_OK)
        dk_progress_done(&prog);
    return st;
}

void dk_shape_interpolation_set_progress(dk_shape_interpolation *s, dk_phase_progress_fn progress,
                                         void *user)
{
    if (!s)
        return;
    s->rebind_progress = progress;
    s->rebind_progress_user = user;
}

/* ------------------------------------------------------------------ solve ------------- */

typedef struct pass {
    dk_shape_interpolation *s;
    const double *w;     /* the weights                                                  */
    const double *base;  /* the input, or the rest                                       */
    int has_input;
    double part_energy[2];
    const double *x;     /* energy: the positions                                        */
} pass;

/* J_t = [A_t] R_t(w) S_t(w), R_t(w) = exp(sum w_k omega_k) exp(sum w_k eps_k), for triangles
 * [begin, end). */
static void gradients(void *ctx, dk_index begin, dk_index end, int part)
{
    (void)part;
    const pass *p = ctx;
    const dk_shape_interpolation *s = p->s;
    const dk_mesh *m = s->mesh;
    const size_t F = (size_t)m->n_faces;
    const dk_index P = s->poses.n_poses;
    for (dk_index t = begin; t < end; t++) {
        double *J = s->J + 9 * (size_t)t;
        if (s->degenerate[t])
            continue;
        double om[3] = {0.0, 0.0, 0.0}, ep[3] = {0.0, 0.0, 0.0};
        double S[6] = {0.0, 0.0, 0.0, 0.0, 0.0, 0.0};
        for (dk_index k = 0; k < P; k++) {
            const double wk = p->w[k];
            const size_t kt = (size_t)k * F + (size_t)t;
            const double *o = s->poses.omega + 3 * kt, *e = s->poses.eps + 3 * kt;
            const double *st = s->poses.stretch + 6 * kt;
            for (int c = 0; c < 3; c++) {
                om[c] += wk * o[c];
                ep[c] += wk * e[c];
            }
            for (int c = 0; c < 6; c++)
                S[c] += wk * st[c];
        }
        double R[9];
        si_rotation_exp(om, R);
        if (ep[0] != 0.0 || ep[1] != 0.0 || ep[2] != 0.0) {
            double E[9], RE[9];
            si_rotation_exp(ep, E);
            si_mat3_mul(R, E, RE);
            memcpy(R, RE, sizeof R);
        }
        double Sm[9], G[9];
        if (s->opt.stretches == DK_SI_STRETCHES_LOG) {
            si_sym_exp(S, Sm);
        } else {
            Sm[0] = 1.0 + S[0], Sm[1] = S[1], Sm[2] = S[2];
            Sm[3] = S[1], Sm[4] = 1.0 + S[3], Sm[5] = S[4];
            Sm[6] = S[2], Sm[7] = S[4], Sm[8] = 1.0 + S[5];
        }
        si_mat3_mul(R, Sm, G);
        if (s->opt.refine > 0 && !p->has_input) { /* J = R S: the refinement keeps S */
            double *Pt = s->Pt + 6 * (size_t)t;
            Pt[0] = Sm[0], Pt[1] = Sm[1], Pt[2] = Sm[2];
            Pt[3] = Sm[4], Pt[4] = Sm[5], Pt[5] = Sm[8];
        }
        if (p->has_input) {
            const dk_index *f = m->faces + 3 * (size_t)t;
            double V[9], A[9];
            si_frame(p->base + 3 * (size_t)f[0], p->base + 3 * (size_t)f[1],
                     p->base + 3 * (size_t)f[2], V);
            si_mat3_mul(V, s->vinv + 9 * (size_t)t, A);
            si_mat3_mul(A, G, J);
        } else {
            memcpy(J, G, sizeof G);
        }
    }
}

/* d_e: the mean of the edge's non-degenerate triangles' J applied to its rest vector (its
 * input vector when it has none), for edges [begin, end). */
static void edge_targets(void *ctx, dk_index begin, dk_index end, int part)
{
    (void)part;
    const pass *p = ctx;
    const dk_shape_interpolation *s = p->s;
    const dk_mesh *m = s->mesh;
    const double *rest = m->positions;
    for (dk_index e = begin; e < end; e++) {
        const dk_index a = m->edges[2 * (size_t)e], b = m->edges[2 * (size_t)e + 1];
        double *d = s->d + 3 * (size_t)e;
        if (s->edge_faces[e] == 0) {
            for (int k = 0; k < 3; k++)
                d[k] = p->base[3 * (size_t)a + k] - p->base[3 * (size_t)b + k];
            continue;
        }
        const double r[3] = {rest[3 * (size_t)a] - rest[3 * (size_t)b],
                             rest[3 * (size_t)a + 1] - rest[3 * (size_t)b + 1],
                             rest[3 * (size_t)a + 2] - rest[3 * (size_t)b + 2]};
        double sum[3] = {0.0, 0.0, 0.0};
        const dk_index nf = m->edge_face_count[e] < 2 ? m->edge_face_count[e] : 2;
        for (dk_index j = 0; j < nf; j++) {
            const dk_index t = m->edge_faces[2 * (size_t)e + (size_t)j];
            if (t < 0 || s->degenerate[t])
                continue;
            const double *J = s->J + 9 * (size_t)t;
            for (int k = 0; k < 3; k++)
                sum[k] += J[3 * k] * r[0] + J[3 * k + 1] * r[1] + J[3 * k + 2] * r[2];
        }
        const double inv = 1.0 / (double)s->edge_faces[e];
        for (int k = 0; k < 3; k++)
            d[k] = sum[k] * inv;
    }
}

/* Each triangle's stretch P (J = U P, U its closest rotation), for triangles [begin, end):
 * what the refining iterations keep of the blend. */
static void target_stretches(void *ctx, dk_index begin, dk_index end, int part)
{
    (void)part;
    const pass *p = ctx;
    const dk_shape_interpolation *s = p->s;
    for (dk_index t = begin; t < end; t++) {
        if (s->degenerate[t])
            continue;
        const double *J = s->J + 9 * (size_t)t;
        double U[9], UJ[9];
        dk_closest_rotation(J, U);
        si_mat3_tmul(U, J, UJ);
        double *P = s->Pt + 6 * (size_t)t;
        P[0] = UJ[0];
        P[1] = 0.5 * (UJ[1] + UJ[3]);
        P[2] = 0.5 * (UJ[2] + UJ[6]);
        P[3] = UJ[4];
        P[4] = 0.5 * (UJ[5] + UJ[7]);
        P[5] = UJ[8];
    }
}

/* A refining iteration's local step, for triangles [begin, end): the rotation U that best
 * takes the triangle's stretched rest edges P r onto its edges in p->x (weighted by the
 * edges' weights: Procrustes), and J = U P. */
static void local_rotations(void *ctx, dk_index begin, dk_index end, int part)
{
    (void)part;
    const pass *p = ctx;
    const dk_shape_interpolation *s = p->s;
    const dk_mesh *m = s->mesh;
    const double *rest = m->positions, *x = p->x;
    for (dk_index t = begin; t < end; t++) {
        if (s->degenerate[t])
            continue;
        const double *P = s->Pt + 6 * (size_t)t;
        const double Pm[9] = {P[0], P[1], P[2], P[1], P[3], P[4], P[2], P[4], P[5]};
        const dk_index *f = m->faces + 3 * (size_t)t;
        double C[9] = {0};
        for (int k = 0; k < 3; k++) {
            const dk_index a = f[k], b = f[(k + 1) % 3];
            const double c = s->ew[m->face_edges[3 * (size_t)t + (size_t)((k + 2) % 3)]];
            double r[3], q[3], e[3];
            for (int d = 0; d < 3; d++) {
                r[d] = rest[3 * (size_t)a + d] - rest[3 * (size_t)b + d];
                e[d] = x[3 * (size_t)a + d] - x[3 * (size_t)b + d];
            }
            for (int d = 0; d < 3; d++)
                q[d] = Pm[3 * d] * r[0] + Pm[3 * d + 1] * r[1] + Pm[3 * d + 2] * r[2];
            for (int i = 0; i < 3; i++)
                for (int j = 0; j < 3; j++)
                    C[3 * i + j] += c * e[i] * q[j];
        }
        double U[9];
        dk_closest_rotation(C, U);
        si_mat3_mul(U, Pm, s->J + 9 * (size_t)t);
    }
}

/* Where an eliminated vertex v sits: a handle vertex at input + weight (target - input),
 * any other (fixed, pinned) at the input. */
static void eliminated_at(const dk_shape_interpolation *s, const double *base, dk_index v,
                          double x[3])
{
    const dk_index r = s->sys.target_of[v];
    const double *b = base + 3 * (size_t)v;
    if (r < 0) {
        x[0] = b[0];
        x[1] = b[1];
        x[2] = b[2];
        return;
    }
    const double hw = s->sys.con->handle_weights[r];
    const double *t = s->tgt + 3 * (size_t)r;
    for (int k = 0; k < 3; k++)
        x[k] = hw == 1.0 ? t[k] : b[k] + hw * (t[k] - b[k]);
}

/* The right-hand side of unknowns [begin, end): sum over v's edges of c (d_{v->j} + x_j for an
 * eliminated j). */
static void right_hand_side(void *ctx, dk_index begin, dk_index end, int part)
{
    (void)part;
    const pass *p = ctx;
    const dk_shape_interpolation *s = p->s;
    const dk_mesh *m = s->mesh;
    const size_t nu = (size_t)s->sys.nu;
    for (dk_index u = begin; u < end; u++) {
        const dk_index v = s->sys.unknowns[u];
        double b[3] = {0.0, 0.0, 0.0};
        for (dk_index r = m->ring_start[v]; r < m->ring_start[v + 1]; r++) {
            const dk_index j = m->ring_index[r], e = m->ring_edge[r];
            const double c = s->ew[e];
            const double sign = m->edges[2 * (size_t)e] == v ? 1.0 : -1.0;
            const double *d = s->d + 3 * (size_t)e;
            for (int k = 0; k < 3; k++)
                b[k] += c * sign * d[k];
            if (s->sys.unk[j] < 0) {
                double x[3];
                eliminated_at(s, p->base, j, x);
                for (int k = 0; k < 3; k++)
                    b[k] += c * x[k];
            }
        }
        for (int k = 0; k < 3; k++)
            s->rhs[(size_t)k * nu + (size_t)u] = b[k];
    }
}

static void energy_pass(void *ctx, dk_index begin, dk_index end, int part)
{
    pass *p = ctx;
    const dk_shape_interpolation *s = p->s;
    const dk_mesh *m = s->mesh;
    double sum = 0.0;
    for (dk_index e = begin; e < end; e++) {
        const dk_index a = m->edges[2 * (size_t)e], b = m->edges[2 * (size_t)e + 1];
        const double *d = s->d + 3 * (size_t)e;
        double r2 = 0.0;
        for (int k = 0; k < 3; k++) {
            const double r = p->x[3 * (size_t)a + k] - p->x[3 * (size_t)b + k] - d[k];
            r2 += r * r;
        }
        sum += s->ew[e] * r2;
    }
    p->part_energy[part] = sum;
}

static double energy_of(dk_shape_interpolation *s, const double *x)
{
    pass p = {.s = s, .x = x};
    dk_team_run_halves(s->team, energy_pass, &p, s->mesh->n_edges, PARALLEL_ITEMS);
    return p.part_energy[0] + p.part_energy[1];
}

/* The input's turn of each free part (rows of R, row-major, into part_turn + 15 c + 6): the
 * rotation of the best rigid fit of the part's rest onto the input (identity without an
 * input). */
static void free_part_turns(dk_shape_interpolation *s, const double *base)
{
    const dk_mesh *m = s->mesh;
    const dk_index nc = m->report.n_components;
    double *pt = s->part_turn;
    memset(pt, 0, 15 * (size_t)nc * sizeof(double));
    for (dk_index c = 0; c < nc; c++)
        if (base == m->positions)
            pt[15 * (size_t)c + 6] = pt[15 * (size_t)c + 10] = pt[15 * (size_t)c + 14] = 1.0;
    if (base == m->positions)
        return;
    for (dk_index v = 0; v < m->n_vertices; v++) {
        const dk_index c = m->component[v];
        if (!s->sys.free_part[c])
            continue;
        for (int k = 0; k < 3; k++) {
            pt[15 * (size_t)c + (size_t)k] += base[3 * (size_t)v + k];
            pt[15 * (size_t)c + 3 + (size_t)k] += m->positions[3 * (size_t)v + k];
        }
    }
    for (dk_index c = 0; c < nc; c++) { /* the sums become means (count in part_sum) */
        const double n = s->part_sum[4 * (size_t)c + 3];
        for (int k = 0; k < 6; k++)
            pt[15 * (size_t)c + (size_t)k] /= n > 0.0 ? n : 1.0;
    }
    for (dk_index v = 0; v < m->n_vertices; v++) {
        const dk_index c = m->component[v];
        if (!s->sys.free_part[c])
            continue;
        double *q = pt + 15 * (size_t)c;
        for (int i = 0; i < 3; i++)
            for (int j = 0; j < 3; j++)
                q[6 + 3 * i + j] += (base[3 * (size_t)v + i] - q[i]) *
                                    (m->positions[3 * (size_t)v + j] - q[3 + j]);
    }
    for (dk_index c = 0; c < nc; c++)
        if (s->sys.free_part[c]) {
            double *q = pt + 15 * (size_t)c, r[9];
            dk_closest_rotation(q + 6, r); /* argmax trace(R^T sum (b - b0)(r - r0)^T) */
            memcpy(q + 6, r, sizeof r);
        }
}

/* The parts without a constrained vertex, moved so that their means are the linear blend's,
 * the poses' shifts (in the rest's directions) turned as the input turns the part. */
static void place_free_parts(dk_shape_interpolation *s, const double *base, const double *w,
                             double *x)
{
    const dk_mesh *m = s->mesh;
    const dk_index nc = m->report.n_components, P = s->poses.n_poses;
    int any = 0;
    for (dk_index c = 0; c < nc; c++)
        any |= s->sys.free_part[c];
    if (!any)
        return;
    double *ps = s->part_sum; /* per part: sum of (base - x), count */
    memset(ps, 0, 4 * (size_t)nc * sizeof(double));
    for (dk_index v = 0; v < m->n_vertices; v++) {
        const dk_index c = m->component[v];
        if (!s->sys.free_part[c])
            continue;
        for (int k = 0; k < 3; k++)
            ps[4 * (size_t)c + k] += base[3 * (size_t)v + k] - x[3 * (size_t)v + k];
        ps[4 * (size_t)c + 3] += 1.0;
    }
    free_part_turns(s, base);
    for (dk_index c = 0; c < nc; c++) {
        if (!s->sys.free_part[c])
            continue;
        double *q = ps + 4 * (size_t)c, blend[3] = {0.0, 0.0, 0.0};
        const double *R = s->part_turn + 15 * (size_t)c + 6;
        for (int k = 0; k < 3; k++)
            for (dk_index i = 0; i < P; i++)
                blend[k] += w[i] * s->poses.shift[3 * ((size_t)i * (size_t)nc + (size_t)c) + (size_t)k];
        for (int k = 0; k < 3; k++)
            q[k] = q[k] / q[3] + R[3 * k] * blend[0] + R[3 * k + 1] * blend[1] + R[3 * k + 2] * blend[2];
    }
    for (dk_index v = 0; v < m->n_vertices; v++) {
        const dk_index c = m->component[v];
        if (s->sys.free_part[c])
            for (int k = 0; k < 3; k++)
                x[3 * (size_t)v + k] += ps[4 * (size_t)c + k];
    }
}

/* The positions whose edges best fit the gradients in s->J: the edges' targets, the
 * right-hand side, one back-substitution, the constrained vertices, the free parts placed. */
static dk_status positions_for_gradients(dk_shape_interpolation *s, pass *p, double *positions,
                                         dk_error *err)
{
    const dk_mesh *m = s->mesh;
    dk_team_run_halves(s->team, edge_targets, p, m->n_edges, PARALLEL_ITEMS);
    const dk_index nu = s->sys.nu;
    if (nu > 0) {
        dk_team_run_halves(s->team, right_hand_side, p, nu, PARALLEL_ITEMS);
        const dk_status st = dk_cholesky_solve(s->sys.chol, s->rhs, 3, s->rhs, err);
        if (st != DK_OK)
            return st;
    }
    for (dk_index v = 0; v < m->n_vertices; v++) {
        const dk_index u = s->sys.unk[v];
        if (u >= 0)
            for (int k = 0; k < 3; k++)
                positions[3 * (size_t)v + k] = s->rhs[(size_t)k * (size_t)nu + (size_t)u];
        else
            eliminated_at(s, p->base, v, positions + 3 * (size_t)v);
    }
    place_free_parts(s, p->base, p->w, positions);
    return DK_OK;
}

/* Zero weights and every handle where the input puts it: the input itself. */
static int is_identity(const dk_shape_interpolation *s, const double *w, const double *base)
{
    for (dk_index k = 0; k < s->poses.n_poses; k++)
        if (w[k] != 0.0)
            return 0;
    const dk_constraints *c = s->sys.con;
    for (dk_index r = 0; r < c->n_handle_vertices; r++) {
        const dk_index v = c->handle_vertices[r];
        for (int k = 0; k < 3; k++)
            if (s->tgt[3 * (size_t)r + k] != base[3 * (size_t)v + k])
                return 0;
    }
    return 1;
}

dk_status dk_shape_interpolation_solve(dk_shape_interpolation *s, const dk_solve_request *rq,
                                       double *positions, dk_solve_info *info, dk_error *err)
{
    static const char who[] = "ShapeInterpolation solve";
    if (!s || !positions)
        return dk_error_set(err, DK_ERR_INVALID_ARGUMENT, "%s: object and positions must not "
                            "be NULL", who);
    const dk_mesh *m = s->mesh;
    dk_status st = dk_solve_request_check_input(rq, m->n_vertices, who, err);
    if (st != DK_OK)
        return st;
    const dk_index P = s->poses.n_poses;
    const double *w = rq->targets;
    for (dk_index k = 0; k < P; k++)
        if (!(fabs(w[k]) <= MAX_WEIGHT))
            return dk_error_set(err, isfinite(w[k]) ? DK_ERR_INVALID_ARGUMENT : DK_ERR_NONFINITE,
                                "%s: the weight of pose %d is %g, must be finite and within "
                                "[-%g, %g]", who, (int)k, w[k], MAX_WEIGHT, MAX_WEIGHT);
    const double *base = rq->input_positions ? rq->input_positions : m->positions;
    if (s->sys.con->n_handles > 0) {
        st = dk_constraints_targets(s->sys.con, base, rq->targets + P, (int)rq->target_kind,
                                    s->tgt, err);
        if (st != DK_OK)
            return st;
    }
    pass p = {.s = s, .w = w, .base = base, .has_input = rq->input_positions != NULL};
    if (is_identity(s, w, base)) {
        memcpy(positions, base, 3 * (size_t)m->n_vertices * sizeof(double));
        rest_edges(m, base, s->d);
    } else {
        dk_team_run_halves(s->team, gradients, &p, m->n_faces, PARALLEL_ITEMS);
        if (s->opt.refine > 0 && p.has_input) /* J = A R S: its own polar stretch */
            dk_team_run_halves(s->team, target_stretches, &p, m->n_faces, PARALLEL_ITEMS);
        st = positions_for_gradients(s, &p, positions, err);
        for (int it = 0; it < s->opt.refine && st == DK_OK; it++) {
            p.x = positions;
            dk_team_run_halves(s->team, local_rotations, &p, m->n_faces, PARALLEL_ITEMS);
            st = positions_for_gradients(s, &p, positions, err);
        }
        if (st != DK_OK) {
            dk_team_park(s->team);
            return st;
        }
    }
    const double e = rq->skip_energy ? NAN : energy_of(s, positions);
    dk_team_park(s->team);
    if (info) {
        memset(info, 0, sizeof *info);
        info->energy = e;
        info->iterations = 1;
        info->converged = 1;
    }
    return dk_solve_result_check(positions, m->n_vertices, e, !rq->skip_energy, who, err);
}

dk_status dk_shape_interpolation_energy(const dk_shape_interpolation *s, const double *positions,
                                        double *energy, dk_error *err)
{
    if (!s || !positions || !energy)
        return dk_error_set(err, DK_ERR_INVALID_ARGUMENT, "ShapeInterpolation energy: object, "
                            "positions and energy must not be NULL");
    dk_status st = dk_check_positions(positions, s->mesh->n_vertices, err);
    if (st != DK_OK)
        return st;
    /* the passes write only their own sums: the object is not changed */
    *energy = energy_of((dk_shape_interpolation *)s, positions);
    dk_team_park(s->team);
    return dk_energy_result_check(*energy, "ShapeInterpolation energy", err);
}

void dk_shape_interpolation_stats(const dk_shape_interpolation *s, dk_method_stats *st)
{
    memset(st, 0, sizeof *st);
    if (!s)
        return;
    st->n_vertices = s->mesh->n_vertices;
    st->n_handles = s->sys.con->n_handles;
    st->n_handle_vertices = s->sys.con->n_handle_vertices;
    st->n_unknowns = s->sys.nu;
    st->analysis_count = s->counts.analysis_count;
    st->factorization_count = s->counts.factorization_count;
    st->n_controls = s->poses.n_poses;
    dk_constraints_held_stats(s->sys.con, NULL, st);
}

dk_index dk_shape_interpolation_n_poses(const dk_shape_interpolation *s)
{
    return s ? s->poses.n_poses : 0;
}

void dk_shape_interpolation_free(dk_shape_interpolation *s)
{
    if (!s)
        return;
    dk_team_free(s->team);
    free(s->vinv);
    free(s->degenerate);
    free(s->ew);
    free(s->edge_faces);
    si_poses_free(&s->poses);
    si_system_free(&s->sys);
    free(s->J);
    free(s->Pt);
    free(s->d);
    free(s->rhs);
    free(s->tgt);
    free(s->part_sum);
    free(s->part_turn);
    free(s);
}

dk_status dk_shape_interpolation_estimate_memory(const dk_mesh *mesh,
                                                 const dk_shape_interpolation_options *options,
                                                 uint64_t *bytes, dk_error *err)
{
    if (!mesh || !bytes)
        return dk_error_set(err, DK_ERR_INVALID_ARGUMENT, "ShapeInterpolation estimate_memory: "
                            "mesh and bytes must not be NULL");
    dk_status st = options ? check_options(options, err) : DK_OK;
    if (st != DK_OK)
        return st;
    const double n = (double)mesh->n_vertices, lg = n > 2.0 ? log2(n) : 1.0;
    /* frames, gradients, edge data and the factor (as Laplacian editing's), and four poses */
    *bytes = dk_memory_model(900.0 + 40.0 * lg, n, (double)pose_bytes(mesh, 4));
    return DK_OK;
}

static const dk_option_desc si_fields[] = {
    {"rotations", DK_OPTION_ENUM, offsetof(dk_shape_interpolation_options, rotations), 0, 0, 1, 0,
     1, 0},
    {"stretches", DK_OPTION_ENUM, offsetof(dk_shape_interpolation_options, stretches), 0, 0, 1, 0,
     1, 0},
    {"edge_weights", DK_OPTION_ENUM, offsetof(dk_shape_interpolation_options, edge_weights), 0, 0,
     2, 0, 2, 0},
    {"refine", DK_OPTION_INT, offsetof(dk_shape_interpolation_options, refine), 0, 0,
     DK_SI_MAX_REFINE, 2, 4, 0},
};

DK_METHOD_OPS(dk_shape_interpolation_ops, "ShapeInterpolation",
              DK_METHOD_TRANSFORMS_AS_POSITIONS | DK_METHOD_TRANSLATION_INVARIANT |
                  DK_METHOD_EDITS_INPUT,
              DK_CONTROL_VERTEX_GROUPS | DK_CONTROL_POSES, dk_shape_interpolation,
              dk_shape_interpolation, dk_shape_interpolation_options, si_fields);
