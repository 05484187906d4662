/* DeformKit skinning: the public verbs and the method table (see dk_skinning.h). */
#include "dk_skinning.h"

#include <math.h>
#include <stddef.h>
#include <stdint.h>
#include <stdlib.h>
#include <string.h>

#include "dk_operators.h"
#include "skinning_internal.h"

/* The bones and weights of one bind: each vertex's non-zero weights (CSR), heaviest first. */
typedef struct skin_data {
    dk_index nb;
    double *rest;     /* nb x 16: the rest frames B_j                                       */
    double *rest_inv; /* nb x 16: B_j^-1                                                     */
    dk_index *start;  /* n + 1                                                               */
    dk_index *bone;   /* start[n]                                                            */
    double *w;        /* start[n]                                                            */
    skin_bone *b;     /* nb: a solve's motions (scratch)                                     */
} skin_data;

struct dk_skinning {
    const dk_mesh *mesh;
    dk_skinning_options opt;
    skin_data sd;
};

/* a bind that computes its weights spends nearly all its time there */
static const dk_progress_phase weight_phases[] = {{"computed weights", 20.0}, {"weights", 1.0}};

void dk_skinning_default_options(dk_skinning_options *o)
{
    memset(o, 0, sizeof *o);
    o->blend = DK_SKINNING_LINEAR;
    dk_bbw_default_options(&o->computed);
}

/* The computation's progress as the bind's phase "computed weights". */
static int computed_progress(void *user, const char *phase, double fraction)
{
    (void)phase;
    dk_error ignored;
    return dk_progress_part((dk_progress *)user, fraction, &ignored) != DK_OK;
}

static void data_free(skin_data *sd)
{
    free(sd->rest);
    free(sd->rest_inv);
    free(sd->start);
    free(sd->bone);
    free(sd->w);
    free(sd->b);
    memset(sd, 0, sizeof *sd);
}

static dk_status take_control(const dk_constraint_desc *c, dk_index n, dk_error *err)
{
    dk_status st = dk_control_taken(c->control, DK_CONTROL_BONES, "Skinning", err);
    if (st != DK_OK)
        return st;
    if (c->n_handles != 0 || c->n_fixed != 0 || c->n_roi != 0 || c->stiffness)
        return dk_error_set(err, DK_ERR_INVALID_ARGUMENT,
                            "Skinning: takes no handles, fixed vertices, region or stiffness "
                            "(its bones move the whole mesh)");
    return dk_control_check(c->control, n, err);
}

static dk_status build_weights(dk_skinning *s, const dk_control_desc *c, dk_progress *prog,
                               skin_data *sd, dk_error *err);

/* The weights given, or computed from the bones' segments first. */
static dk_status build(dk_skinning *s, const dk_control_desc *c, dk_progress *prog,
                       skin_data *sd, dk_error *err)
{
    dk_status st = dk_progress_begin(prog, c->weights ? 1 : 0, err);
    if (st != DK_OK || c->weights)
        return st == DK_OK ? build_weights(s, c, prog, sd, err) : st;
    const dk_index n = s->mesh->n_vertices, nb = c->n_controls;
    double *w = malloc(((size_t)n * (size_t)nb + 1) * sizeof *w);
    if (!w)
        return dk_error_set(err, DK_ERR_OUT_OF_MEMORY, "Skinning: out of memory (weights)");
    dk_bbw_options o = s->opt.computed;
    o.progress = computed_progress;
    o.progress_user = prog;
    dk_bbw_handles h = {.n_bones = nb, .bones = c->segments};
    st = dk_bounded_biharmonic_weights(s->mesh, &h, &o, w, NULL, err);
    if (st == DK_ERR_CANCELLED)
        st = dk_error_set(err, DK_ERR_CANCELLED, "Skinning bind: cancelled in phase computed "
                          "weights");
    dk_control_desc given = *c;
    given.weights = w;
    given.segments = NULL;
    if (st == DK_OK) st = dk_progress_begin(prog, 1, err);
    if (st == DK_OK) st = build_weights(s, &given, prog, sd, err);
    free(w);
    return st;
}

static dk_status build_weights(dk_skinning *s, const dk_control_desc *c, dk_progress *prog,
                               skin_data *sd, dk_error *err)
{
    const dk_index n = s->mesh->n_vertices, nb = c->n_controls;
    memset(sd, 0, sizeof *sd);
    sd->nb = nb;
    size_t nnz = 0;
    for (size_t k = 0; k < (size_t)n * (size_t)nb; k++)
        nnz += c->weights[k] > 0.0;
    sd->rest = malloc(16 * (size_t)nb * sizeof *sd->rest);
    sd->rest_inv = malloc(16 * (size_t)nb * sizeof *sd->rest_inv);
    sd->start = malloc(((size_t)n + 1) * sizeof *sd->start);
    sd->bone = malloc((nnz + 1) * sizeof *sd->bone);
    sd->w = malloc((nnz + 1) * sizeof *sd->w);
    sd->b = malloc((size_t)nb * sizeof *sd->b);
    if (!sd->rest || !sd->rest_inv || !sd->start || !sd->bone || !sd->w || !sd->b) {
        data_free(sd);
        return dk_error_set(err, DK_ERR_OUT_OF_MEMORY, "Skinning: out of memory (weights)");
    }
    memcpy(sd->rest, c->rest, 16 * (size_t)nb * sizeof *sd->rest);
    for (dk_index j = 0; j < nb; j++)
        if (dk_affine_inverse(sd->rest + 16 * (size_t)j, sd->rest_inv + 16 * (size_t)j) != 0) {
            data_free(sd);
            return dk_error_set(err, DK_ERR_INVALID_ARGUMENT,
                                "Skinning: bone %d's rest frame is singular", (int)j);
        }
    size_t at = 0;
    dk_status st = DK_OK;
    for (dk_index v = 0; v < n; v++) {
        if ((v & 16383) == 0 && (st = dk_progress_part(prog, (double)v / n, err)) != DK_OK) {
            data_free(sd);
            return st;
        }
        sd->start[v] = (dk_index)at;
        const double *row = c->weights + (size_t)v * (size_t)nb;
        const size_t first = at;
        for (dk_index j = 0; j < nb; j++)
            if (row[j] > 0.0) {
                /* insertion by weight, heaviest first (the pivot of dual quaternions) */
                size_t k = at++;
                while (k > first && sd->w[k - 1] < row[j]) {
                    sd->w[k] = sd->w[k - 1];
                    sd->bone[k] = sd->bone[k - 1];
                    k--;
                }
                sd->w[k] = row[j];
                sd->bone[k] = j;
            }
    }
    sd->start[n] = (dk_index)at;
    return DK_OK;
}

dk_status dk_skinning_bind(const dk_mesh *mesh, const dk_constraint_desc *constraints,
                           const dk_skinning_options *options, dk_skinning **out,
                           dk_error *err)
{
    if (out)
        *out = NULL;
    if (!mesh || !constraints || !out)
        return dk_error_set(err, DK_ERR_INVALID_ARGUMENT,
                            "Skinning bind: mesh, constraints and output must not be NULL");
    dk_skinning_options opt;
    if (options)
        opt = *options;
    else
        dk_skinning_default_options(&opt);
    if (opt.blend != DK_SKINNING_LINEAR && opt.blend != DK_SKINNING_DUAL_QUATERNION)
        return dk_error_set(err, DK_ERR_INVALID_ARGUMENT,
                            "Skinning: blend %d is not linear (0) or dual quaternion (1)",
                            (int)opt.blend);
    if (opt.computed.domain < DK_BBW_AUTO || opt.computed.domain > DK_BBW_SURFACE ||
        opt.computed.resolution < 4 || opt.computed.resolution > 256 ||
        opt.computed.max_iterations < 1)
        return dk_error_set(err, DK_ERR_INVALID_ARGUMENT,
                            "Skinning: the computed weights' options are out of range (domain "
                            "%d in [0, 2], resolution %d in [4, 256], max_iterations %d >= 1)",
                            (int)opt.computed.domain, opt.computed.resolution,
                            opt.computed.max_iterations);
    dk_status st = take_control(constraints, mesh->n_vertices, err);
    if (st != DK_OK)
        return st;
    dk_progress prog;
    dk_progress_init(&prog, opt.progress, opt.progress_user, weight_phases, 2,
                     "Skinning bind");
    opt.progress = NULL;
    opt.progress_user = NULL;
    dk_skinning *s = calloc(1, sizeof *s);
    if (!s)
        return dk_error_set(err, DK_ERR_OUT_OF_MEMORY, "Skinning: out of memory");
    s->mesh = mesh;
    s->opt = opt;
    if ((st = build(s, constraints->control, &prog, &s->sd, err)) != DK_OK) {
        free(s);
        return st;
    }
    dk_progress_done(&prog);
    *out = s;
    return DK_OK;
}

dk_status dk_skinning_rebind(dk_skinning *s, const dk_constraint_desc *constraints,
                             dk_error *err)
{
    if (!s || !constraints)
        return dk_error_set(err, DK_ERR_INVALID_ARGUMENT,
                            "Skinning rebind: object and constraints must not be NULL");
    dk_status st = take_control(constraints, s->mesh->n_vertices, err);
    if (st != DK_OK)
        return st;
    dk_progress prog;
    dk_progress_init(&prog, NULL, NULL, weight_phases, 2, "Skinning rebind");
    skin_data fresh;
    if ((st = build(s, constraints->control, &prog, &fresh, err)) != DK_OK)
        return st;
    data_free(&s->sd);
    s->sd = fresh;
    return DK_OK;
}

/* Each bone's motion M_j = T_j B_j^-1 for the frames T (nb x 16), and for dual quaternions
 * its polar parts and dual quaternion; a frame equal to the rest is the identity exactly. */
static dk_status bone_motions(dk_skinning *s, const double *T, dk_error *err)
{
    skin_data *sd = &s->sd;
    for (dk_index j = 0; j < sd->nb; j++) {
        const double *t = T + 16 * (size_t)j, *bi = sd->rest_inv + 16 * (size_t)j;
        if (t[12] != 0.0 || t[13] != 0.0 || t[14] != 0.0 || t[15] != 1.0)
            return dk_error_set(err, DK_ERR_INVALID_ARGUMENT,
                                "Skinning solve: bone %d's frame is not affine (its bottom row "
                                "must be 0 0 0 1)", (int)j);
        skin_bone *b = sd->b + j;
        double M[16];
        if (memcmp(t, sd->rest + 16 * (size_t)j, 16 * sizeof *t) == 0) {
            memset(M, 0, sizeof M);
            M[0] = M[5] = M[10] = M[15] = 1.0;
        } else {
            for (int r = 0; r < 4; r++)
                for (int c = 0; c < 4; c++)
                    M[4 * r + c] = t[4 * r] * bi[c] + t[4 * r + 1] * bi[4 + c] +
                                   t[4 * r + 2] * bi[8 + c] + t[4 * r + 3] * bi[12 + c];
        }
        for (int r = 0; r < 3; r++) {
            for (int c = 0; c < 3; c++)
                b->A[3 * r + c] = M[4 * r + c];
            b->t[r] = M[4 * r + 3];
        }
        if (s->opt.blend == DK_SKINNING_DUAL_QUATERNION) {
            double R[9];
            dk_closest_rotation(b->A, R);
            for (int r = 0; r < 3; r++) /* S = R^T A */
                for (int c = 0; c < 3; c++)
                    b->S[3 * r + c] = R[r] * b->A[c] + R[3 + r] * b->A[3 + c] +
                                      R[6 + r] * b->A[6 + c];
            skin_dq_from_rigid(R, b->t, b->r, b->d);
        }
    }
    return DK_OK;
}

dk_status dk_skinning_solve(dk_skinning *s, const dk_solve_request *rq, double *positions,
                            dk_solve_info *info, dk_error *err)
{
    if (info)
        memset(info, 0, sizeof *info);
    if (!s || !positions)
        return dk_error_set(err, DK_ERR_INVALID_ARGUMENT,
                            "Skinning solve: object and positions must not be NULL");
    dk_status st = dk_solve_request_check_input(rq, s->mesh->n_vertices, "Skinning solve", err);
    if (st != DK_OK)
        return st;
    const skin_data *sd = &s->sd;
    if (rq->target_kind != DK_TARGETS_TRANSFORMS)
        return dk_error_set(err, DK_ERR_INVALID_ARGUMENT,
                            "Skinning solve: takes the bones' frames (%d 4 x 4 transforms), "
                            "not positions", (int)sd->nb);
    for (size_t k = 0; k < 16 * (size_t)sd->nb; k++)
        if (!isfinite(rq->targets[k]) || fabs(rq->targets[k]) > DK_COORD_MAX)
            return dk_error_set(err, DK_ERR_NONFINITE,
                                "Skinning solve: bone %d's frame is not finite or too large",
                                (int)(k / 16));
    if ((st = bone_motions(s, rq->targets, err)) != DK_OK)
        return st;
    const dk_index n = s->mesh->n_vertices;
    const double *base = rq->input_positions ? rq->input_positions : s->mesh->positions;
    const int dq = s->opt.blend == DK_SKINNING_DUAL_QUATERNION;
    for (dk_index v = 0; v < n; v++) {
        const double *p = base + 3 * (size_t)v;
        double *o = positions + 3 * (size_t)v;
        const dk_index e0 = sd->start[v], e1 = sd->start[v + 1];
        if (!dq) {
            /* p + sum_j w_j (M_j p - p): the weights' sum rounded off 1 moves nothing, and
             * bones at rest give p back bit for bit */
            double acc[3] = {0.0, 0.0, 0.0};
            for (dk_index e = e0; e < e1; e++) {
                const skin_bone *b = sd->b + sd->bone[e];
                const double w = sd->w[e];
                for (int r = 0; r < 3; r++)
                    acc[r] += w * (b->A[3 * r] * p[0] + b->A[3 * r + 1] * p[1] +
                                   b->A[3 * r + 2] * p[2] + b->t[r] - p[r]);
            }
            for (int r = 0; r < 3; r++)
                o[r] = p[r] + acc[r];
            continue;
        }
        /* dual quaternions on the heaviest bone's side, stretch blended linearly */
        const double *pivot = sd->b[sd->bone[e0]].r;
        double r[4] = {0, 0, 0, 0}, d[4] = {0, 0, 0, 0}, S[9] = {0};
        for (dk_index e = e0; e < e1; e++) {
            const skin_bone *b = sd->b + sd->bone[e];
            const double dot = b->r[0] * pivot[0] + b->r[1] * pivot[1] + b->r[2] * pivot[2] +
                               b->r[3] * pivot[3];
            const double w = dot < 0.0 ? -sd->w[e] : sd->w[e];
            for (int k = 0; k < 4; k++) {
                r[k] += w * b->r[k];
                d[k] += w * b->d[k];
            }
            for (int k = 0; k < 9; k++)
                S[k] += sd->w[e] * b->S[k];
        }
        const double sp[3] = {S[0] * p[0] + S[1] * p[1] + S[2] * p[2],
                              S[3] * p[0] + S[4] * p[1] + S[5] * p[2],
                              S[6] * p[0] + S[7] * p[1] + S[8] * p[2]};
        skin_dq_apply(r, d, sp, o);
    }
    return dk_direct_solve_finish(positions, base, n, rq, "Skinning solve", info, err);
}

dk_status dk_skinning_energy(const dk_skinning *s, const double *positions, double *energy,
                             dk_error *err)
{
    if (!s)
        return dk_error_set(err, DK_ERR_INVALID_ARGUMENT,
                            "Skinning energy: arguments must not be NULL");
    return dk_displacement_energy_result(positions, s->mesh->positions, s->mesh->n_vertices,
                                         "Skinning energy", energy, err);
}

void dk_skinning_stats(const dk_skinning *s, dk_method_stats *st)
{
    if (!st)
        return;
    memset(st, 0, sizeof *st);
    st->first_held = -1;
    if (!s)
        return;
    st->n_vertices = s->mesh->n_vertices;
    st->n_controls = s->sd.nb;
}

const double *dk_skinning_rest_frames(const dk_skinning *s)
{
    return s ? s->sd.rest : NULL;
}

void dk_skinning_free(dk_skinning *s)
{
    if (!s)
        return;
    data_free(&s->sd);
    free(s);
}

dk_status dk_skinning_estimate_memory(const dk_mesh *mesh, const dk_skinning_options *options,
                                      uint64_t *bytes, dk_error *err)
{
    if (!mesh || !bytes)
        return dk_error_set(err, DK_ERR_INVALID_ARGUMENT,
                            "Skinning estimate_memory: mesh and bytes must not be NULL");
    (void)options;
    /* four influences a vertex (index and weight), the CSR start, a result */
    *bytes = dk_memory_model(4.0 * 12.0 + 8.0 + 48.0, (double)mesh->n_vertices, 0.0);
    return DK_OK;
}

static const dk_option_desc skinning_fields[] = {
    {"blend", DK_OPTION_ENUM, offsetof(dk_skinning_options, blend), 0, DK_SKINNING_LINEAR,
     DK_SKINNING_DUAL_QUATERNION, DK_SKINNING_LINEAR, DK_SKINNING_DUAL_QUATERNION, 0},
    /* the computed weights' (bones given as segments) */
    {"domain", DK_OPTION_ENUM, offsetof(dk_skinning_options, computed.domain), 0, DK_BBW_AUTO,
     DK_BBW_SURFACE, DK_BBW_AUTO, DK_BBW_SURFACE, 0},
    {"resolution", DK_OPTION_INT, offsetof(dk_skinning_options, computed.resolution), 0, 4, 256,
     24, 12, 0},
};

DK_METHOD_OPS(dk_skinning_ops, "Skinning", DK_METHOD_EDITS_INPUT, DK_CONTROL_BONES,
              dk_skinning, dk_skinning, dk_skinning_options, skinning_fields);
