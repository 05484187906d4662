/* DeformKit cage FFD: the public verbs and the method table (see dk_cage.h). */
#include "dk_cage.h"

#include <cblas.h>
#include <math.h>
#include <stddef.h>
#include <stdint.h>
#include <stdlib.h>
#include <stdio.h>
#include <string.h>

#include "cage_grid.h"
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
    /* Green coordinates only (else NULL, nt 0): */
    dk_index nt;
    dk_index *tris;   /* nt x 3: the cage's triangles, oriented outwards                 */
    double *nrm;      /* nt x 3: their unit normals at rest                              */
    double *Psi;      /* n x nt row-major (DOUBLE), else NULL                            */
    float *Psif;      /* n x nt row-major (SINGLE), else NULL                            */
    double *dn;       /* nt x 3: s n' - n of a solve (scratch)                           */
    float *dnf;       /* nt x 3 (SINGLE)                                                 */
    /* evaluation on a grid (else use_grid 0): W and Psi are the nodes' rows */
    int use_grid;
    dk_cage_grid grid;
    double *node_disp; /* n_nodes x 3: the nodes' motion of a solve (DOUBLE)             */
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
    o->coordinates = DK_CAGE_MEAN_VALUE;
    o->evaluation = DK_CAGE_AUTO;
    o->grid_resolution = 64;
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

/* Green coordinates: the cage's triangles oriented consistently (each edge used once each
 * way), copied into `out` facing outwards (the enclosed volume positive), and their unit
 * normals. */
static dk_status orient_outwards(const dk_control_desc *c, dk_index *out, double *nrm,
                                 dk_error *err)
{
    const size_t ne = 3 * (size_t)c->n_triangles;
    int64_t *e = malloc((ne + 1) * sizeof *e);
    if (!e)
        return oom(err, "cage edges");
    for (dk_index t = 0; t < c->n_triangles; t++)
        for (int k = 0; k < 3; k++)
            e[3 * (size_t)t + k] = (int64_t)c->triangles[3 * t + k] * INT64_C(2147483648) +
                                   c->triangles[3 * t + (k + 1) % 3];
    qsort(e, ne, sizeof *e, edge_less);
    dk_status st = DK_OK;
    for (size_t i = 1; i < ne && st == DK_OK; i++)
        if (e[i] == e[i - 1])
            st = dk_error_set(err, DK_ERR_INVALID_ARGUMENT,
                              "Cage: Green coordinates need the cage's triangles oriented "
                              "consistently, but two triangles run along edge %lld-%lld the "
                              "same way (recalculate the cage's normals)",
                              (long long)(e[i] / INT64_C(2147483648)),
                              (long long)(e[i] % INT64_C(2147483648)));
    free(e);
    if (st != DK_OK)
        return st;
    double vol = 0.0;
    const double *R = c->rest;
    for (dk_index t = 0; t < c->n_triangles; t++) {
        const double *a = R + 3 * (size_t)c->triangles[3 * t],
                     *b = R + 3 * (size_t)c->triangles[3 * t + 1],
                     *d = R + 3 * (size_t)c->triangles[3 * t + 2];
        vol += a[0] * (b[1] * d[2] - b[2] * d[1]) - a[1] * (b[0] * d[2] - b[2] * d[0]) +
               a[2] * (b[0] * d[1] - b[1] * d[0]);
    }
    const int flip = vol < 0.0;
    for (dk_index t = 0; t < c->n_triangles; t++) {
        const dk_index *f = c->triangles + 3 * (size_t)t;
        dk_index *g = out + 3 * (size_t)t;
        g[0] = f[0];
        g[1] = flip ? f[2] : f[1];
        g[2] = flip ? f[1] : f[2];
        const double *a = R + 3 * (size_t)g[0], *b = R + 3 * (size_t)g[1],
                     *d = R + 3 * (size_t)g[2];
        double u[3] = {b[0] - a[0], b[1] - a[1], b[2] - a[2]};
        double v[3] = {d[0] - a[0], d[1] - a[1], d[2] - a[2]};
        double *n = nrm + 3 * (size_t)t;
        n[0] = u[1] * v[2] - u[2] * v[1];
        n[1] = u[2] * v[0] - u[0] * v[2];
        n[2] = u[0] * v[1] - u[1] * v[0];
        const double len = sqrt(n[0] * n[0] + n[1] * n[1] + n[2] * n[2]);
        if (!(len > 0.0))
            return dk_error_set(err, DK_ERR_INVALID_ARGUMENT,
                                "Cage: Green coordinates need cage triangles with an area; "
                                "triangle %d has none", (int)t);
        for (int k = 0; k < 3; k++)
            n[k] /= len;
    }
    return DK_OK;
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
    const double *points; /* the rows' points (x 3): vertices, or grid nodes */
    const dk_control_desc *c;
    const dk_index *edges, *opposite;
    dk_index n_edges;
    const dk_index *tris; /* Green: the oriented triangles and their normals, else NULL */
    const double *nrm;
    double *W, *Psi;
    float *Wf, *Psif;
    double *scratch; /* 2 parts x rows_scratch() doubles */
    dk_index first_bad[2];
    double reach; /* the cage's bounding-box diagonal: the scale of the precision check */
} rows_job;

/* Linear precision (the coordinates' defining property): the weights sum to 1 and rebuild
 * the point, sum_j lambda_j v_j (+ sum_t psi_t n_t for Green) = x. A point on the cage where
 * a formula has no case for it (Green at a cage vertex: weights summing to 1/8), or a cage
 * flat or folded there, gives finite weights that fail it: refused, not bound. */
static int reproduces(const double *x, const double *cage, dk_index nc, const double *lambda,
                      const double *nrm, dk_index nt, const double *psi, double reach)
{
    double sum = 0.0, p[3] = {0.0, 0.0, 0.0};
    for (dk_index j = 0; j < nc; j++) {
        sum += lambda[j];
        for (int k = 0; k < 3; k++)
            p[k] += lambda[j] * cage[3 * (size_t)j + (size_t)k];
    }
    for (dk_index t = 0; nrm && t < nt; t++)
        for (int k = 0; k < 3; k++)
            p[k] += psi[t] * nrm[3 * (size_t)t + (size_t)k];
    const double tol = 1e-6;
    return fabs(sum - 1.0) <= tol && fabs(p[0] - x[0]) <= tol * reach &&
           fabs(p[1] - x[1]) <= tol * reach && fabs(p[2] - x[2]) <= tol * reach;
}

/* Doubles of one part's scratch: the coordinates and the kernel's scratch. */
static size_t rows_scratch(size_t nc, size_t nt, size_t ne)
{
    const size_t mv = 5 * nc + 3 * ne, gc = 5 * nc + nt + ne;
    return mv > gc ? mv : gc;
}

static void store_row(double *Wd, float *Wf, size_t v, size_t width, const double *row)
{
    if (Wd)
        memcpy(Wd + v * width, row, width * sizeof *row);
    else
        for (size_t j = 0; j < width; j++)
            Wf[v * width + j] = (float)row[j];
}

static void rows_range(void *ctx, dk_index v0, dk_index v1, int part)
{
    rows_job *job = ctx;
    const dk_index nc = job->c->n_controls, nt = job->c->n_triangles;
    double *lambda = job->scratch + (size_t)part * rows_scratch((size_t)nc, (size_t)nt,
                                                                (size_t)job->n_edges);
    double *psi = lambda + nc, *k = job->tris ? psi + nt : lambda + nc;
    for (dk_index v = v0; v < v1; v++) {
        const double *x = job->points + 3 * (size_t)v;
        const int bad = job->tris
            ? dk_cage_green(x, job->c->rest, nc, job->tris, nt, job->nrm, job->edges,
                            job->n_edges, job->opposite, lambda, psi, k)
            : dk_cage_mean_value(x, job->c->rest, nc, job->c->triangles, nt, job->edges,
                                 job->n_edges, job->opposite, lambda, k);
        if ((bad != 0 || !reproduces(x, job->c->rest, nc, lambda, job->tris ? job->nrm : NULL,
                                     nt, psi, job->reach)) &&
            job->first_bad[part] < 0)
            job->first_bad[part] = v;
        store_row(job->W, job->Wf, (size_t)v, (size_t)nc, lambda);
        if (job->tris)
            store_row(job->Psi, job->Psif, (size_t)v, (size_t)nt, psi);
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
    free(cg->tris);
    free(cg->nrm);
    free(cg->Psi);
    free(cg->Psif);
    free(cg->dn);
    free(cg->dnf);
    free(cg->node_disp);
    dk_cage_grid_free(&cg->grid);
    cg->node_disp = NULL;
    cg->use_grid = 0;
    cg->rest = cg->W = cg->disp = cg->nrm = cg->Psi = cg->dn = NULL;
    cg->Wf = cg->dispf = cg->outf = cg->Psif = cg->dnf = NULL;
    cg->tris = NULL;
    cg->nt = 0;
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
    const size_t nc = (size_t)c->n_controls;
    const int single = cg->opt.weights == DK_CAGE_SINGLE;
    const int green = cg->opt.coordinates == DK_CAGE_GREEN;
    const size_t nt = green ? (size_t)c->n_triangles : 0;
    cg->use_grid = cg->opt.evaluation == DK_CAGE_GRID ||
                   (cg->opt.evaluation == DK_CAGE_AUTO &&
                    (double)cg->n * (double)(nc + nt) > DK_CAGE_AUTO_ENTRIES);
    dk_status st;
    if (cg->use_grid &&
        (st = dk_cage_grid_plan(cg->mesh->positions, cg->n, cg->opt.grid_resolution, &cg->grid,
                                err)) != DK_OK)
        return st;
    /* the points whose coordinates are computed: the vertices, or the grid's nodes */
    const double *pts = cg->use_grid ? cg->grid.node_pos : cg->mesh->positions;
    const size_t n = cg->use_grid ? (size_t)cg->grid.n_nodes : (size_t)cg->n;
    char what[160];
    snprintf(what, sizeof what, "%s coordinates of %zu %s for %zu cage vertices%s",
             green ? "Green" : "mean value", n, cg->use_grid ? "grid nodes" : "vertices", nc,
             green ? " and their faces" : "");
    st = dk_memory_check((uint64_t)n * (nc + nt) * (single ? 4u : 8u) +
                         (cg->use_grid ? 128u * (uint64_t)cg->n : 0u), "Cage", what, err);
    if (st != DK_OK)
        return st;
    cg->nc = c->n_controls;
    cg->nt = (dk_index)nt;
    cg->rest = malloc(3 * nc * sizeof *cg->rest);
    cg->disp = malloc(3 * nc * sizeof *cg->disp);
    if (single) {
        cg->Wf = malloc(n * nc * sizeof *cg->Wf + 1);
        cg->dispf = malloc(3 * nc * sizeof *cg->dispf);
        cg->outf = malloc(3 * n * sizeof *cg->outf + 1);
    } else {
        cg->W = malloc(n * nc * sizeof *cg->W + 1);
    }
    if (cg->use_grid && !single && !(cg->node_disp = malloc(3 * n * sizeof *cg->node_disp + 1)))
        return oom(err, "the grid");
    int green_ok = 1;
    if (green) {
        cg->tris = malloc(3 * nt * sizeof *cg->tris + 1);
        cg->nrm = malloc(3 * nt * sizeof *cg->nrm + 1);
        if (single) {
            cg->Psif = malloc(n * nt * sizeof *cg->Psif + 1);
            cg->dnf = malloc(3 * nt * sizeof *cg->dnf + 1);
            green_ok = cg->Psif && cg->dnf;
        } else {
            cg->Psi = malloc(n * nt * sizeof *cg->Psi + 1);
            cg->dn = malloc(3 * nt * sizeof *cg->dn + 1);
            green_ok = cg->Psi && cg->dn;
        }
        green_ok = green_ok && cg->tris && cg->nrm;
    }
    if (!cg->rest || !cg->disp || (single ? !cg->Wf || !cg->dispf || !cg->outf : !cg->W) ||
        !green_ok)
        return oom(err, "coordinates");
    if (green && (st = orient_outwards(c, cg->tris, cg->nrm, err)) != DK_OK)
        return st;
    dk_index *edges = NULL, *opposite = NULL, ne = 0;
    st = dk_cage_edges(green ? cg->tris : c->triangles, c->n_triangles, &edges, &ne, &opposite,
                       err);
    if (st != DK_OK)
        return st;
    rows_job job = {pts, c, edges, opposite, ne, cg->tris, cg->nrm, cg->W, cg->Psi, cg->Wf,
                    cg->Psif, malloc(2 * rows_scratch(nc, (size_t)c->n_triangles, (size_t)ne) *
                                     sizeof(double)), {-1, -1}, 0.0};
    {
        double lo[3], hi[3];
        for (int k = 0; k < 3; k++)
            lo[k] = hi[k] = c->rest[k];
        for (size_t j = 1; j < nc; j++)
            for (int k = 0; k < 3; k++) {
                const double q = c->rest[3 * j + (size_t)k];
                lo[k] = q < lo[k] ? q : lo[k];
                hi[k] = q > hi[k] ? q : hi[k];
            }
        job.reach = sqrt((hi[0] - lo[0]) * (hi[0] - lo[0]) + (hi[1] - lo[1]) * (hi[1] - lo[1]) +
                         (hi[2] - lo[2]) * (hi[2] - lo[2]));
    }
    if (!job.scratch) {
        free(edges);
        free(opposite);
        return oom(err, "coordinates");
    }
    memcpy(cg->rest, c->rest, 3 * nc * sizeof *cg->rest);
    for (size_t v0 = 0; v0 < n && st == DK_OK; v0 += CAGE_CHUNK) {
        const size_t v1 = v0 + CAGE_CHUNK < n ? v0 + CAGE_CHUNK : n;
        if (prog && (st = dk_progress_part(prog, (double)v0 / (double)n, err)) != DK_OK)
            break;
        /* the chunk's two halves on two threads, on the chunk's rows */
        rows_job part = job;
        part.points = pts + 3 * v0;
        part.W = cg->W ? cg->W + v0 * nc : NULL;
        part.Wf = cg->Wf ? cg->Wf + v0 * nc : NULL;
        part.Psi = cg->Psi ? cg->Psi + v0 * nt : NULL;
        part.Psif = cg->Psif ? cg->Psif + v0 * nt : NULL;
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
                          green ? "Cage: %s %d has no Green coordinates (a degenerate "
                                  "cage, or the point on it)"
                                : "Cage: %s %d has no mean value coordinates (its weights "
                                  "sum to zero: a degenerate cage, or the point on it where "
                                  "it folds)",
                          cg->use_grid ? "grid node" : "vertex", (int)job.first_bad[0]);
    if (cg->use_grid) { /* the nodes' positions served their purpose */
        free(cg->grid.node_pos);
        cg->grid.node_pos = NULL;
    }
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
    if (opt.coordinates != DK_CAGE_MEAN_VALUE && opt.coordinates != DK_CAGE_GREEN)
        return dk_error_set(err, DK_ERR_INVALID_ARGUMENT,
                            "Cage: coordinates %d is not mean value (0) or Green (1)",
                            (int)opt.coordinates);
    if (opt.evaluation != DK_CAGE_AUTO && opt.evaluation != DK_CAGE_EXACT &&
        opt.evaluation != DK_CAGE_GRID)
        return dk_error_set(err, DK_ERR_INVALID_ARGUMENT,
                            "Cage: evaluation %d is not auto (0), exact (1) or grid (2)",
                            (int)opt.evaluation);
    if (opt.grid_resolution < 4 || opt.grid_resolution > 256)
        return dk_error_set(err, DK_ERR_INVALID_ARGUMENT,
                            "Cage: grid_resolution %d is outside 4 .. 256 (cells along the "
                            "mesh's longest side)", opt.grid_resolution);
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
    fresh.rest = fresh.W = fresh.disp = fresh.nrm = fresh.Psi = fresh.dn = NULL;
    fresh.Wf = fresh.dispf = fresh.outf = fresh.Psif = fresh.dnf = NULL;
    fresh.tris = NULL;
    fresh.nt = 0;
    fresh.node_disp = NULL;
    fresh.use_grid = 0;
    memset(&fresh.grid, 0, sizeof fresh.grid);
    st = build(&fresh, constraints->control, NULL, err);
    if (st != DK_OK) {
        cage_free_arrays(&fresh);
        return st;
    }
    cage_free_arrays(cg);
    *cg = fresh;
    return DK_OK;
}

/* Green coordinates: each face's s n' - n for the cage at `P` (dn, or dnf), s its stretch
 * (dk_cage.h); a face moved to no area gets s n' = 0. */
static void normal_motion(dk_cage *cg, const double *P)
{
    for (dk_index t = 0; t < cg->nt; t++) {
        const dk_index *f = cg->tris + 3 * (size_t)t;
        const double *a = cg->rest + 3 * (size_t)f[0], *b = cg->rest + 3 * (size_t)f[1],
                     *d = cg->rest + 3 * (size_t)f[2];
        const double *a2 = P + 3 * (size_t)f[0], *b2 = P + 3 * (size_t)f[1],
                     *d2 = P + 3 * (size_t)f[2];
        if (memcmp(a, a2, 3 * sizeof *a) == 0 && memcmp(b, b2, 3 * sizeof *b) == 0 &&
            memcmp(d, d2, 3 * sizeof *d) == 0) { /* at rest: no motion, bit for bit */
            for (int k = 0; k < 3; k++) {
                if (cg->dn)
                    cg->dn[3 * (size_t)t + k] = 0.0;
                else
                    cg->dnf[3 * (size_t)t + k] = 0.0f;
            }
            continue;
        }
        double u[3], v[3], u2[3], v2[3], n2[3];
        for (int k = 0; k < 3; k++) {
            u[k] = b[k] - a[k];
            v[k] = d[k] - a[k];
            u2[k] = b2[k] - a2[k];
            v2[k] = d2[k] - a2[k];
        }
        n2[0] = u2[1] * v2[2] - u2[2] * v2[1];
        n2[1] = u2[2] * v2[0] - u2[0] * v2[2];
        n2[2] = u2[0] * v2[1] - u2[1] * v2[0];
        const double len2 = sqrt(n2[0] * n2[0] + n2[1] * n2[1] + n2[2] * n2[2]);
        const double uu = u[0] * u[0] + u[1] * u[1] + u[2] * u[2];
        const double vv = v[0] * v[0] + v[1] * v[1] + v[2] * v[2];
        const double uv = u[0] * v[0] + u[1] * v[1] + u[2] * v[2];
        const double uu2 = u2[0] * u2[0] + u2[1] * u2[1] + u2[2] * u2[2];
        const double vv2 = v2[0] * v2[0] + v2[1] * v2[1] + v2[2] * v2[2];
        const double uv2 = u2[0] * v2[0] + u2[1] * v2[1] + u2[2] * v2[2];
        /* twice the rest area: |u x v| = sqrt(|u|^2 |v|^2 - (u.v)^2) */
        const double area2 = sqrt(fmax(uu * vv - uv * uv, 0.0));
        const double q = uu2 * vv - 2.0 * uv2 * uv + vv2 * uu;
        /* s = sqrt(q) / (sqrt(8) area) = sqrt(q) / (sqrt(2) * 2 area) */
        const double sc = area2 > 0.0 ? sqrt(fmax(q, 0.0)) / (sqrt(2.0) * area2) : 0.0;
        const double *n = cg->nrm + 3 * (size_t)t;
        for (int k = 0; k < 3; k++) {
            const double want = len2 > 0.0 ? sc * n2[k] / len2 : 0.0;
            if (cg->dn)
                cg->dn[3 * (size_t)t + k] = want - n[k];
            else
                cg->dnf[3 * (size_t)t + k] = (float)(want - n[k]);
        }
    }
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
    /* the rows of W (and Psi): the vertices', or the grid nodes' */
    const int rows = cg->use_grid ? (int)cg->grid.n_nodes : (int)cg->n;
    if (cg->tris)
        normal_motion(cg, rq->targets);
    if (cg->W) {
        for (size_t k = 0; k < nc3; k++)
            cg->disp[k] = rq->targets[k] - cg->rest[k];
        double *out = cg->use_grid ? cg->node_disp : positions;
        if (!cg->use_grid)
            memcpy(positions, x, n3 * sizeof *positions);
        cblas_dgemm(CblasRowMajor, CblasNoTrans, CblasNoTrans, rows, 3, (int)cg->nc, 1.0,
                    cg->W, (int)cg->nc, cg->disp, 3, cg->use_grid ? 0.0 : 1.0, out, 3);
        if (cg->Psi)
            cblas_dgemm(CblasRowMajor, CblasNoTrans, CblasNoTrans, rows, 3, (int)cg->nt,
                        1.0, cg->Psi, (int)cg->nt, cg->dn, 3, 1.0, out, 3);
        if (cg->use_grid)
            dk_cage_grid_blend(&cg->grid, x, cg->node_disp, NULL, positions);
    } else {
        for (size_t k = 0; k < nc3; k++)
            cg->dispf[k] = (float)(rq->targets[k] - cg->rest[k]);
        cblas_sgemm(CblasRowMajor, CblasNoTrans, CblasNoTrans, rows, 3, (int)cg->nc, 1.0f,
                    cg->Wf, (int)cg->nc, cg->dispf, 3, 0.0f, cg->outf, 3);
        if (cg->Psif)
            cblas_sgemm(CblasRowMajor, CblasNoTrans, CblasNoTrans, rows, 3, (int)cg->nt,
                        1.0f, cg->Psif, (int)cg->nt, cg->dnf, 3, 1.0f, cg->outf, 3);
        if (cg->use_grid)
            dk_cage_grid_blend(&cg->grid, x, NULL, cg->outf, positions);
        else
            for (size_t k = 0; k < n3; k++)
                positions[k] = x[k] + (double)cg->outf[k];
    }
    return dk_direct_solve_finish(positions, x, cg->n, rq, "Cage solve", info, err);
}

dk_status dk_cage_energy(const dk_cage *cg, const double *positions, double *energy,
                         dk_error *err)
{
    if (!cg)
        return dk_error_set(err, DK_ERR_INVALID_ARGUMENT, "Cage energy: arguments must not be NULL");
    return dk_displacement_energy_result(positions, cg->mesh->positions, cg->n, "Cage energy",
                                         energy, err);
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
    /* W's rows for a cage of 64 vertices, and Green's Psi for its 124 triangles (the bind
     * checks its own cage's size) */
    const int green = options && options->coordinates == DK_CAGE_GREEN;
    const double per = (options && options->weights == DK_CAGE_SINGLE) ? 4.0 : 8.0;
    *bytes = dk_memory_model((64.0 + (green ? 124.0 : 0.0)) * per + 48.0,
                             (double)mesh->n_vertices, 0.0);
    return DK_OK;
}

static const dk_option_desc cage_fields[] = {
    {"coordinates", DK_OPTION_ENUM, offsetof(dk_cage_options, coordinates), 0,
     DK_CAGE_MEAN_VALUE, DK_CAGE_GREEN, DK_CAGE_MEAN_VALUE, DK_CAGE_GREEN, 0},
    {"evaluation", DK_OPTION_ENUM, offsetof(dk_cage_options, evaluation), 0, DK_CAGE_AUTO,
     DK_CAGE_GRID, DK_CAGE_AUTO, DK_CAGE_GRID, 0},
    {"grid_resolution", DK_OPTION_INT, offsetof(dk_cage_options, grid_resolution), 0, 4, 256,
     64, 32, 0},
    {"weights", DK_OPTION_ENUM, offsetof(dk_cage_options, weights), 0, DK_CAGE_DOUBLE,
     DK_CAGE_SINGLE, DK_CAGE_DOUBLE, DK_CAGE_SINGLE, 0},
};

DK_METHOD_OPS(dk_cage_ops, "Cage", DK_METHOD_LINEAR_PRECISION, DK_CONTROL_CAGE, dk_cage,
              dk_cage, dk_cage_options, cage_fields);
