/* DeformKit cage FFD: the public verbs and the method table (see dk_cage.h). */
#include "dk_cage.h"

#include <cblas.h>
#include <math.h>
#include <stddef.h>
#include <stdint.h>
#include <stdlib.h>
#include <stdio.h>
#include <string.h>

#include "dk_memory.h"
#include "dk_parallel.h"

struct dk_cage {
    const dk_mesh *mesh;
    dk_cage_options opt;
    dk_index n, nc;
    double *rest;     /* nc x 3: the cage at rest                                       */
    double *W;        /* n x nc row-major (weights DOUBLE), else NULL                    */
    float *Wf;        /* n x nc row-major (weights SINGLE), else NULL                    */
    double *disp;     /* nc x 3: the cage's motion of a solve (scratch)                  */
    float *dispf;     /* nc x 3, and n x 3 products (SINGLE only)                        */
    float *outf;
};

/* The vertices of a bind per progress report (and cancellation check). */
enum { CAGE_CHUNK = 4096 };

static dk_status oom(dk_error *err, const char *what)
{
    return dk_error_set(err, DK_ERR_OUT_OF_MEMORY, "Cage: out of memory (%s)", what);
}

void dk_cage_default_options(dk_cage_options *o)
{
    memset(o, 0, sizeof *o);
    o->weights = DK_CAGE_DOUBLE;
}

static int edge_less(const void *a, const void *b)
{
    const int64_t x = *(const int64_t *)a, y = *(const int64_t *)b;
    return (x > y) - (x < y);
}

/* A closed cage: every edge in exactly two triangles. */
static dk_status check_closed(const dk_control_desc *c, dk_error *err)
{
    const size_t ne = 3 * (size_t)c->n_triangles;
    int64_t *e = malloc((ne + 1) * sizeof *e);
    if (!e)
        return oom(err, "cage edges");
    for (dk_index t = 0; t < c->n_triangles; t++)
        for (int k = 0; k < 3; k++) {
            const int64_t a = c->triangles[3 * t + k], b = c->triangles[3 * t + (k + 1) % 3];
            e[3 * (size_t)t + k] = a < b ? a * INT64_C(2147483648) + b : b * INT64_C(2147483648) + a;
        }
    qsort(e, ne, sizeof *e, edge_less);
    dk_status st = DK_OK;
    for (size_t i = 0; i < ne && st == DK_OK;) {
        size_t j = i;
        while (j < ne && e[j] == e[i])
            j++;
        if (j - i != 2)
            st = dk_error_set(err, DK_ERR_INVALID_ARGUMENT,
                              "Cage: the cage is not closed: its edge %lld-%lld is in %zu "
                              "triangle%s, not 2 (a cage must enclose a volume)",
                              (long long)(e[i] / INT64_C(2147483648)),
                              (long long)(e[i] % INT64_C(2147483648)), j - i,
                              j - i == 1 ? "" : "s");
        i = j;
    }
    free(e);
    return st;
}

static dk_status take_control(const dk_constraint_desc *c, dk_index n, dk_error *err)
{
    dk_status st = dk_control_taken(c->control, DK_CONTROL_CAGE, "Cage", err);
    if (st != DK_OK)
        return st;
    if (c->n_handles != 0 || c->n_fixed != 0 || c->n_roi != 0 || c->stiffness)
        return dk_error_set(err, DK_ERR_INVALID_ARGUMENT,
                            "Cage: takes no handles, fixed vertices, region or stiffness (its "
                            "vertices move the whole mesh)");
    st = dk_control_check(c->control, n, err);
    return st == DK_OK ? check_closed(c->control, err) : st;
}

typedef struct rows_job {
    const dk_mesh *mesh;
    const dk_control_desc *c;
    const dk_index *edges, *opposite;
    dk_index n_edges;
    double *W;
    float *Wf;
    double *scratch; /* 2 parts x (5 nc + 3 n_edges): lambda and the kernel's scratch */
    dk_index first_bad[2];
} rows_job;

static void rows_range(void *ctx, dk_index v0, dk_index v1, int part)
{
    rows_job *job = ctx;
    const dk_index nc = job->c->n_controls;
    double *lambda = job->scratch + (size_t)part * (5 * (size_t)nc + 3 * (size_t)job->n_edges);
    double *k = lambda + nc;
    for (dk_index v = v0; v < v1; v++) {
        if (dk_cage_mean_value(job->mesh->positions + 3 * (size_t)v, job->c->rest, nc,
                               job->c->triangles, job->c->n_triangles, job->edges,
                               job->n_edges, job->opposite, lambda, k) != 0 &&
            job->first_bad[part] < 0)
            job->first_bad[part] = v;
        if (job->W)
            memcpy(job->W + (size_t)v * (size_t)nc, lambda, (size_t)nc * sizeof *lambda);
        else
            for (dk_index j = 0; j < nc; j++)
                job->Wf[(size_t)v * (size_t)nc + j] = (float)lambda[j];
    }
}

static void cage_free_arrays(dk_cage *cg)
{
    free(cg->rest);
    free(cg->W);
    free(cg->Wf);
    free(cg->disp);
    free(cg->dispf);
    free(cg->outf);
    cg->rest = cg->W = cg->disp = NULL;
    cg->Wf = cg->dispf = cg->outf = NULL;
}

void dk_cage_free(dk_cage *cg)
{
    if (!cg)
        return;
    cage_free_arrays(cg);
    free(cg);
}

/* The coordinates of every vertex for the control into `cg` (whose arrays it allocates). */
static dk_status build(dk_cage *cg, const dk_control_desc *c, dk_progress *prog, dk_error *err)
{
    const size_t n = (size_t)cg->n, nc = (size_t)c->n_controls;
    const int single = cg->opt.weights == DK_CAGE_SINGLE;
    char what[96];
    snprintf(what, sizeof what, "coordinates of %zu vertices for %zu cage vertices", n, nc);
    dk_status st = dk_memory_check((uint64_t)n * nc * (single ? 4u : 8u), "Cage", what, err);
    if (st != DK_OK)
        return st;
    cg->nc = c->n_controls;
    cg->rest = malloc(3 * nc * sizeof *cg->rest);
    cg->disp = malloc(3 * nc * sizeof *cg->disp);
    if (single) {
        cg->Wf = malloc(n * nc * sizeof *cg->Wf + 1);
        cg->dispf = malloc(3 * nc * sizeof *cg->dispf);
        cg->outf = malloc(3 * n * sizeof *cg->outf + 1);
    } else {
        cg->W = malloc(n * nc * sizeof *cg->W + 1);
    }
    dk_index *edges = NULL, *opposite = NULL, ne = 0;
    st = dk_cage_edges(c->triangles, c->n_triangles, &edges, &ne, &opposite, err);
    if (st != DK_OK)
        return st;
    rows_job job = {cg->mesh, c, edges, opposite, ne, cg->W, cg->Wf,
                    malloc(2 * (5 * nc + 3 * (size_t)ne) * sizeof(double)), {-1, -1}};
    if (!cg->rest || !cg->disp || (single ? !cg->Wf || !cg->dispf || !cg->outf : !cg->W) ||
        !job.scratch) {
        free(job.scratch);
        free(edges);
        free(opposite);
        return oom(err, "coordinates");
    }
    memcpy(cg->rest, c->rest, 3 * nc * sizeof *cg->rest);
    for (size_t v0 = 0; v0 < n && st == DK_OK; v0 += CAGE_CHUNK) {
        const size_t v1 = v0 + CAGE_CHUNK < n ? v0 + CAGE_CHUNK : n;
        if (prog && (st = dk_progress_part(prog, (double)v0 / (double)n, err)) != DK_OK)
            break;
        /* the chunk's two halves on two threads, on a view of the chunk's rows */
        dk_mesh view = *cg->mesh;
        view.positions = cg->mesh->positions + 3 * v0;
        rows_job part = job;
        part.mesh = &view;
        part.W = cg->W ? cg->W + v0 * nc : NULL;
        part.Wf = cg->Wf ? cg->Wf + v0 * nc : NULL;
        part.first_bad[0] = part.first_bad[1] = -1;
        dk_run_halves(rows_range, &part, (dk_index)(v1 - v0), 512);
        for (int k = 0; k < 2; k++)
            if (part.first_bad[k] >= 0 && job.first_bad[0] < 0)
                job.first_bad[0] = (dk_index)v0 + part.first_bad[k];
    }
    free(job.scratch);
    free(edges);
    free(opposite);
    if (st == DK_OK && job.first_bad[0] >= 0)
        st = dk_error_set(err, DK_ERR_INVALID_ARGUMENT,
                          "Cage: vertex %d has no mean value coordinates (its weights sum to "
                          "zero: a degenerate cage, or the vertex on it where it folds)",
                          (int)job.first_bad[0]);
    return st;
}

dk_status dk_cage_bind(const dk_mesh *mesh, const dk_constraint_desc *constraints,
                       const dk_cage_options *options, dk_cage **out, dk_error *err)
{
    if (out)
        *out = NULL;
    if (!mesh || !constraints || !out)
        return dk_error_set(err, DK_ERR_INVALID_ARGUMENT,
                            "Cage bind: mesh, constraints and output must not be NULL");
    dk_cage_options opt;
    if (options)
        opt = *options;
    else
        dk_cage_default_options(&opt);
    if (opt.weights != DK_CAGE_DOUBLE && opt.weights != DK_CAGE_SINGLE)
        return dk_error_set(err, DK_ERR_INVALID_ARGUMENT,
                            "Cage: weights %d is not double (0) or single (1)", (int)opt.weights);
    dk_status st = take_control(constraints, mesh->n_vertices, err);
    if (st != DK_OK)
        return st;
    dk_progress prog;
    static const dk_progress_phase phases[] = {{"coordinates", 1.0}};
    dk_progress_init(&prog, opt.progress, opt.progress_user, phases, 1, "Cage bind");
    opt.progress = NULL;
    opt.progress_user = NULL;
    if ((st = dk_progress_begin(&prog, 0, err)) != DK_OK)
        return st;
    dk_cage *cg = calloc(1, sizeof *cg);
    if (!cg)
        return oom(err, "object");
    cg->mesh = mesh;
    cg->opt = opt;
    cg->n = mesh->n_vertices;
    st = build(cg, constraints->control, &prog, err);
    if (st != DK_OK) {
        dk_cage_free(cg);
        return st;
    }
    dk_progress_done(&prog);
    *out = cg;
    return DK_OK;
}

dk_status dk_cage_rebind(dk_cage *cg, const dk_constraint_desc *constraints, dk_error *err)
{
    if (!cg || !constraints)
        return dk_error_set(err, DK_ERR_INVALID_ARGUMENT,
                            "Cage rebind: object and constraints must not be NULL");
    dk_status st = take_control(constraints, cg->n, err);
    if (st != DK_OK)
        return st;
    dk_cage fresh = *cg;
    fresh.rest = fresh.W = fresh.disp = NULL;
    fresh.Wf = fresh.dispf = fresh.outf = NULL;
    st = build(&fresh, constraints->control, NULL, err);
    if (st != DK_OK) {
        cage_free_arrays(&fresh);
        return st;
    }
    cage_free_arrays(cg);
    *cg = fresh;
    return DK_OK;
}

dk_status dk_cage_solve(dk_cage *cg, const dk_solve_request *rq, double *positions,
                        dk_solve_info *info, dk_error *err)
{
    if (info)
        memset(info, 0, sizeof *info);
    if (!cg || !positions)
        return dk_error_set(err, DK_ERR_INVALID_ARGUMENT,
                            "Cage solve: object and positions must not be NULL");
    dk_status st = dk_solve_request_check(rq, "Cage solve", err);
    if (st != DK_OK)
        return st;
    if (rq->target_kind != DK_TARGETS_POSITIONS)
        return dk_error_set(err, DK_ERR_INVALID_ARGUMENT,
                            "Cage solve: takes the cage vertices' positions (%d x 3), not "
                            "transforms",
                            (int)cg->nc);
    st = dk_check_positions(rq->targets, cg->nc, err);
    if (st != DK_OK)
        return dk_error_prefix(err, "Cage solve: the cage vertices");
    const size_t nc3 = 3 * (size_t)cg->nc, n3 = 3 * (size_t)cg->n;
    const double *x = cg->mesh->positions;
    if (cg->W) {
        for (size_t k = 0; k < nc3; k++)
            cg->disp[k] = rq->targets[k] - cg->rest[k];
        memcpy(positions, x, n3 * sizeof *positions);
        cblas_dgemm(CblasRowMajor, CblasNoTrans, CblasNoTrans, (int)cg->n, 3, (int)cg->nc, 1.0,
                    cg->W, (int)cg->nc, cg->disp, 3, 1.0, positions, 3);
    } else {
        for (size_t k = 0; k < nc3; k++)
            cg->dispf[k] = (float)(rq->targets[k] - cg->rest[k]);
        cblas_sgemm(CblasRowMajor, CblasNoTrans, CblasNoTrans, (int)cg->n, 3, (int)cg->nc, 1.0f,
                    cg->Wf, (int)cg->nc, cg->dispf, 3, 0.0f, cg->outf, 3);
        for (size_t k = 0; k < n3; k++)
            positions[k] = x[k] + (double)cg->outf[k];
    }
    return dk_direct_solve_finish(positions, x, cg->n, rq, "Cage solve", info, err);
}

dk_status dk_cage_energy(const dk_cage *cg, const double *positions, double *energy,
                         dk_error *err)
{
    if (!cg || !positions || !energy)
        return dk_error_set(err, DK_ERR_INVALID_ARGUMENT, "Cage energy: arguments must not be NULL");
    const double e = dk_displacement_energy(positions, cg->mesh->positions, cg->n);
    const dk_status st = dk_energy_result_check(e, "Cage energy", err);
    if (st == DK_OK)
        *energy = e;
    return st;
}

void dk_cage_stats(const dk_cage *cg, dk_method_stats *st)
{
    if (!st)
        return;
    memset(st, 0, sizeof *st);
    st->first_held = -1;
    if (!cg)
        return;
    st->n_vertices = cg->n;
    st->n_controls = cg->nc;
}

const double *dk_cage_rest_points(const dk_cage *cg)
{
    return cg ? cg->rest : NULL;
}

dk_status dk_cage_estimate_memory(const dk_mesh *mesh, const dk_cage_options *options,
                                  uint64_t *bytes, dk_error *err)
{
    if (!mesh || !bytes)
        return dk_error_set(err, DK_ERR_INVALID_ARGUMENT,
                            "Cage estimate_memory: mesh and bytes must not be NULL");
    (void)options;
    /* W's rows for a cage of 64 vertices (the bind checks its own cage's size) */
    *bytes = dk_memory_model(64.0 * 8.0 + 48.0, (double)mesh->n_vertices, 0.0);
    return DK_OK;
}

static const dk_option_desc cage_fields[] = {
    {"weights", DK_OPTION_ENUM, offsetof(dk_cage_options, weights), 0, DK_CAGE_DOUBLE,
     DK_CAGE_SINGLE, DK_CAGE_DOUBLE, DK_CAGE_SINGLE, 0},
};

DK_METHOD_OPS(dk_cage_ops, "Cage", DK_METHOD_LINEAR_PRECISION, DK_CONTROL_CAGE, dk_cage,
              dk_cage, dk_cage_options, cage_fields);
