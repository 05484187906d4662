/* DeformKit lattice FFD: the public verbs and the method table (see dk_lattice.h). */
#include "lattice_internal.h"

#include <stddef.h>

static dk_status oom(dk_error *err, const char *what)
{
    return dk_error_set(err, DK_ERR_OUT_OF_MEMORY, "Lattice: out of memory (%s)", what);
}

void dk_lattice_default_options(dk_lattice_options *o)
{
    memset(o, 0, sizeof *o);
    o->interpolation = DK_LATTICE_BSPLINE;
    o->outside = DK_LATTICE_OUTSIDE_EXTEND;
}

static dk_status check_options(const dk_lattice_options *o, dk_error *err)
{
    if (o->interpolation < DK_LATTICE_LINEAR || o->interpolation > DK_LATTICE_BSPLINE)
        return dk_error_set(err, DK_ERR_INVALID_ARGUMENT,
                            "Lattice: interpolation %d is not linear (0), bernstein (1) or "
                            "bspline (2)",
                            (int)o->interpolation);
    if (o->outside < DK_LATTICE_OUTSIDE_EXTEND || o->outside > DK_LATTICE_OUTSIDE_STILL)
        return dk_error_set(err, DK_ERR_INVALID_ARGUMENT,
                            "Lattice: outside %d is not extend (0), clamp (1) or still (2)",
                            (int)o->outside);
    return DK_OK;
}

/* A lattice moves everything: vertex groups have no part in it. */
static dk_status check_groups(const dk_constraint_desc *c, dk_error *err)
{
    if (c->n_handles != 0 || c->n_fixed != 0 || c->n_roi != 0 || c->stiffness)
        return dk_error_set(err, DK_ERR_INVALID_ARGUMENT,
                            "Lattice: takes no handles, fixed vertices, region or stiffness "
                            "(its points move the whole mesh)");
    return DK_OK;
}

void dk_lattice_free(dk_lattice *lt)
{
    if (!lt)
        return;
    lattice_grid_free(&lt->grid);
    free(lt->pose);
    dk_team_free(lt->team);
    free(lt);
}

dk_status dk_lattice_bind(const dk_mesh *mesh, const dk_constraint_desc *constraints,
                          const dk_lattice_options *options, dk_lattice **out, dk_error *err)
{
    if (out)
        *out = NULL;
    if (!mesh || !constraints || !out)
        return dk_error_set(err, DK_ERR_INVALID_ARGUMENT,
                            "Lattice bind: mesh, constraints and output must not be NULL");
    dk_lattice_options opt;
    if (options)
        opt = *options;
    else
        dk_lattice_default_options(&opt);
    dk_status st = dk_control_taken(constraints->control, DK_CONTROL_LATTICE, "Lattice", err);
    if (st == DK_OK)
        st = check_options(&opt, err);
    if (st == DK_OK)
        st = check_groups(constraints, err);
    if (st != DK_OK)
        return st;
    dk_progress prog;
    static const dk_progress_phase phases[] = {{"register", 1.0}};
    dk_progress_init(&prog, opt.progress, opt.progress_user, phases, 1, "Lattice bind");
    opt.progress = NULL; /* the caller's callback is for this bind only */
    opt.progress_user = NULL;
    if ((st = dk_progress_begin(&prog, 0, err)) != DK_OK)
        return st;
    dk_lattice *lt = calloc(1, sizeof *lt);
    if (!lt)
        return oom(err, "object");
    lt->mesh = mesh;
    lt->team = dk_team_create(); /* NULL (no thread available) is fine: passes start threads */
    lt->opt = opt;
    lt->n = mesh->n_vertices;
    lt->pose = malloc((3 * (size_t)lt->n + 1) * sizeof *lt->pose);
    if (!lt->pose) {
        dk_lattice_free(lt);
        return oom(err, "positions");
    }
    memcpy(lt->pose, mesh->positions, 3 * (size_t)lt->n * sizeof *lt->pose);
    st = lattice_grid_create(constraints->control, &lt->opt, lt->n, &lt->grid, err);
    if (st != DK_OK) {
        dk_lattice_free(lt);
        return st;
    }
    lattice_register(&lt->opt, &lt->grid, lt->pose, lt->n);
    dk_progress_done(&prog);
    *out = lt;
    return DK_OK;
}

dk_status dk_lattice_rebind(dk_lattice *lt, const dk_constraint_desc *constraints,
                            dk_error *err)
{
    if (!lt || !constraints)
        return dk_error_set(err, DK_ERR_INVALID_ARGUMENT,
                            "Lattice rebind: object and constraints must not be NULL");
    dk_status st = dk_control_taken(constraints->control, DK_CONTROL_LATTICE, "Lattice", err);
    if (st == DK_OK)
        st = check_groups(constraints, err);
    if (st != DK_OK)
        return st;
    lattice_grid g;
    st = lattice_grid_create(constraints->control, &lt->opt, lt->n, &g, err);
    if (st != DK_OK)
        return st;
    lattice_register(&lt->opt, &g, lt->pose, lt->n);
    lattice_grid_free(&lt->grid);
    lt->grid = g;
    return DK_OK;
}

typedef struct deform_job {
    const dk_lattice *lt;
    double *out;
} deform_job;

/* x' = x + sum_ijk w_i w_j w_k (P_ijk - R_ijk) for vertices [v0, v1), into `out`. */
static void deform_range(void *ctx, dk_index v0, dk_index v1, int part)
{
    const deform_job *job = ctx;
    const dk_lattice *lt = job->lt;
    double *out = job->out;
    const lattice_grid *g = &lt->grid;
    const int kx = g->k[0], ky = g->k[1], kz = g->k[2], kt = kx + ky + kz;
    const size_t rx = (size_t)g->res[0], rxy = rx * (size_t)g->res[1];
    (void)part;
    for (dk_index v = v0; v < v1; v++) {
        const dk_index *first = g->first + 3 * (size_t)v;
        const double *wx = g->w + (size_t)kt * (size_t)v, *wy = wx + kx, *wz = wy + ky;
        double acc[3] = {0.0, 0.0, 0.0};
        for (int c = 0; c < kz; c++) {
            const size_t zoff = rxy * (size_t)(first[2] + c);
            for (int b = 0; b < ky; b++) {
                const double wyz = wy[b] * wz[c];
                if (wyz == 0.0)
                    continue;
                const double *d = g->disp + 3 * (zoff + rx * (size_t)(first[1] + b) +
                                                 (size_t)first[0]);
                for (int a = 0; a < kx; a++) {
                    const double f = wx[a] * wyz;
                    acc[0] += f * d[3 * a];
                    acc[1] += f * d[3 * a + 1];
                    acc[2] += f * d[3 * a + 2];
                }
            }
        }
        const double *x = lt->pose + 3 * (size_t)v;
        for (int d = 0; d < 3; d++)
            out[3 * (size_t)v + d] = x[d] + acc[d];
    }
}

/* Every vertex, on two threads for big meshes (each vertex is its own). */
static void deform(dk_lattice *lt, double *out)
{
    deform_job job = {lt, out};
    dk_team_run_halves(lt->team, deform_range, &job, lt->n, LATTICE_PARALLEL_MIN);
    dk_team_park(lt->team);
}

dk_status dk_lattice_solve(dk_lattice *lt, const dk_solve_request *rq, double *positions,
                           dk_solve_info *info, dk_error *err)
{
    if (info)
        memset(info, 0, sizeof *info);
    if (!lt || !positions)
        return dk_error_set(err, DK_ERR_INVALID_ARGUMENT,
                            "Lattice solve: object and positions must not be NULL");
    dk_status st = dk_solve_request_check_input(rq, lt->n, "Lattice solve", err);
    if (st != DK_OK)
        return st;
    lattice_grid *g = &lt->grid;
    if (rq->target_kind != DK_TARGETS_POSITIONS)
        return dk_error_set(err, DK_ERR_INVALID_ARGUMENT,
                            "Lattice solve: takes the lattice points' positions (%d x 3), not "
                            "transforms",
                            (int)g->n_points);
    st = dk_check_positions(rq->targets, g->n_points, err);
    if (st != DK_OK)
        return dk_error_prefix(err, "Lattice solve: the lattice points");
    /* the pose: a new input is registered (O(n)); back to the rest likewise */
    const size_t bytes = 3 * (size_t)lt->n * sizeof(double);
    const double *want = rq->input_positions ? rq->input_positions : lt->mesh->positions;
    if ((rq->input_positions != NULL) != lt->pose_is_input || memcmp(want, lt->pose, bytes) != 0) {
        memcpy(lt->pose, want, bytes);
        lt->pose_is_input = rq->input_positions != NULL;
        lattice_register(&lt->opt, g, lt->pose, lt->n);
    }
    for (size_t k = 0; k < 3 * (size_t)g->n_points; k++)
        g->disp[k] = rq->targets[k] - g->rest[k];
    deform(lt, positions);
    return dk_direct_solve_finish(positions, lt->pose, lt->n, rq, "Lattice solve", info, err);
}

dk_status dk_lattice_energy(const dk_lattice *lt, const double *positions, double *energy,
                            dk_error *err)
{
    if (!lt)
        return dk_error_set(err, DK_ERR_INVALID_ARGUMENT,
                            "Lattice energy: arguments must not be NULL");
    return dk_displacement_energy_result(positions, lt->pose, lt->n, "Lattice energy", energy,
                                         err);
}

void dk_lattice_stats(const dk_lattice *lt, dk_method_stats *st)
{
    if (!st)
        return;
    memset(st, 0, sizeof *st);
    st->first_held = -1;
    if (!lt)
        return;
    st->n_vertices = lt->n;
    st->n_controls = lt->grid.n_points;
}

void dk_lattice_get(const dk_lattice *lt, dk_index *resolution, double *frame, double *rest)
{
    if (!lt)
        return;
    if (resolution)
        memcpy(resolution, lt->grid.res, sizeof lt->grid.res);
    if (frame)
        memcpy(frame, lt->grid.frame, sizeof lt->grid.frame);
    if (rest)
        memcpy(rest, lt->grid.rest, 3 * (size_t)lt->grid.n_points * sizeof *rest);
}

dk_status dk_lattice_estimate_memory(const dk_mesh *mesh, const dk_lattice_options *options,
                                     uint64_t *bytes, dk_error *err)
{
    if (!mesh || !bytes)
        return dk_error_set(err, DK_ERR_INVALID_ARGUMENT,
                            "Lattice estimate_memory: mesh and bytes must not be NULL");
    (void)options;
    /* the pose (24 bytes), three first indices (12) and up to 12 weights (96) a vertex */
    *bytes = dk_memory_model(132.0, (double)mesh->n_vertices, 0.0);
    return DK_OK;
}

static const dk_option_desc lattice_fields[] = {
    {"interpolation", DK_OPTION_ENUM, offsetof(dk_lattice_options, interpolation), 0,
     DK_LATTICE_LINEAR, DK_LATTICE_BSPLINE, DK_LATTICE_BSPLINE, DK_LATTICE_BSPLINE, 0},
    {"outside", DK_OPTION_ENUM, offsetof(dk_lattice_options, outside), 0,
     DK_LATTICE_OUTSIDE_EXTEND, DK_LATTICE_OUTSIDE_STILL, DK_LATTICE_OUTSIDE_EXTEND,
     DK_LATTICE_OUTSIDE_STILL, 0},
};

DK_METHOD_OPS(dk_lattice_ops, "Lattice", DK_METHOD_EDITS_INPUT | DK_METHOD_LINEAR_PRECISION,
              DK_CONTROL_LATTICE, dk_lattice, dk_lattice, dk_lattice_options, lattice_fields);
