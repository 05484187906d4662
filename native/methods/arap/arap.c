/* DeformKit: As-Rigid-As-Possible deformation, the public verbs (dk_arap.h). See
 * arap_internal.h for the layout and the files of this folder, docs/methods/arap.md for the
 * choices and measurements. */
#include "arap_internal.h"

#include <float.h>
#include <limits.h>

void dk_arap_default_options(dk_arap_options *o)
{
    if (!o)
        return;
    o->energy = DK_ARAP_SPOKES;
    o->weights = DK_ARAP_WEIGHTS_CLAMPED_COTANGENT;
    /* 1000, not 100: an honest 1e-6 takes 88-268 Newton steps at 692k vertices and
     * 536 for a closed mesh's rigid motion from a cold start (docs/methods/arap.md);
     * a cap is a guard against stalls, not a speed setting */
    o->max_iterations = 1000;
    o->tolerance = 1e-6;
    o->acceleration = DK_ARAP_ACCEL_NEWTON;
    o->anderson_depth = 5;
    o->cg_iterations = 12;
    o->cg_schedule = DK_ARAP_CG_FIXED;
    o->predict = 1;
    o->basis = DK_ARAP_BASIS_AUTO;
    o->levels = 0;
    o->on_iteration = NULL;
    o->user = NULL;
    o->progress = NULL;
    o->progress_user = NULL;
}

/* The phases of a bind and of a rebind (dk_progress.h), weighted by their measured cost in
 * seconds: binds of the 692k-vertex armadillo (scripts/bench_scale.py's armadillo-wave, 2
 * subdivisions, one handle; defaults: spokes, clamped cotangent, Newton, the response
 * basis) on the shared 2-core machine, timed between the callback's reports (issue 19 item
 * 3): 4.6 and 4.8 s in all, the factorization 1.7-1.9 s (2.6-3.8 s at load ~6), the
 * longest stretch without a report. The system's phases follow ARAP_PHASE_CONSTRAINTS in
 * the same order in both tables. */
static const dk_progress_phase bind_phases[] = {
    {"renumber", 0.54},    /* dk_reorder_create: the locality order, the renumbered mesh */
    {"cells", 0.65},       /* cotangent weights and the cells' terms                       */
    {"constraints", 0.06}, /* ARAP_PHASE_CONSTRAINTS ...                                  */
    {"system", 0.35},
    {"assemble", 0.32},
    {"analyze", 0.83},
    {"factorize", 1.80},
    {"basis", 0.10},       /* the response basis: 4 columns per handle                     */
    {"coarse", 0.40}};     /* the multi-scale solve's coarse level (none below 100k vertices
                              by default: then the phase is empty)                         */
static const dk_progress_phase rebind_phases[] = {
    {"constraints", 0.06}, {"system", 0.35}, {"assemble", 0.32}, {"analyze", 0.83},
    {"factorize", 1.80}, {"basis", 0.10}, {"coarse", 0.40}};
#define BIND_PHASE_BASE 2 /* ARAP_PHASE_CONSTRAINTS in bind_phases */

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
    if (o->cg_schedule != DK_ARAP_CG_GROWING && o->cg_schedule != DK_ARAP_CG_FIXED)
        return dk_error_set(err, DK_ERR_INVALID_ARGUMENT,
                            "ARAP: unknown cg_schedule %d (fixed = 0, growing = 1)",
                            (int)o->cg_schedule);
    if (o->levels < 0 || o->levels > 8)
        return dk_error_set(err, DK_ERR_INVALID_ARGUMENT,
                            "ARAP: levels is %d, must be in [1, 8] (0: automatic)", o->levels);
    if (o->predict != 0 && o->predict != 1)
        return dk_error_set(err, DK_ERR_INVALID_ARGUMENT, "ARAP: predict is %d, must be 0 or 1",
                            o->predict);
    if (o->basis != DK_ARAP_BASIS_AUTO && o->basis != DK_ARAP_BASIS_OFF)
        return dk_error_set(err, DK_ERR_INVALID_ARGUMENT,
                            "ARAP: unknown basis mode %d (auto = 0, off = 1)", (int)o->basis);
    if (o->anderson_depth < 1 || o->anderson_depth > MAX_ANDERSON_DEPTH)
        return dk_error_set(err, DK_ERR_INVALID_ARGUMENT,
                            "ARAP: anderson_depth is %d, must be in [1, %d]", o->anderson_depth,
                            MAX_ANDERSON_DEPTH);
    return DK_OK;
}

/* ------------------------------------------------------------------ bind / free -------- */

void dk_arap_free(dk_arap *ar)
{
    if (!ar)
        return;
    arap_system_free(&ar->sys);
    free(ar->cell_start);
    free(ar->cc_start);
    free(ar->cc);
    free(ar->ta);
    free(ar->tb);
    free(ar->tw);
    free(ar->te);
    free(ar->input);
    free(ar->input_next);
    free(ar->x);
    free(ar->rot);
    free(ar->prev);
    free(ar->prev2);
    dk_reorder_free(ar->ro);
    dk_team_free(ar->team); /* after the factor, which used it */
    free(ar);
}

/* Every corner a vertex of the mesh, four distinct ones per tetrahedron, every edge one of
 * the mesh's (its triangles give the components: a tetrahedron's edge missing there would
 * leave its interior corner a part of its own, held at rest), and few enough tetrahedra that
 * their six terms each are numbered by a dk_index. */
static dk_status check_tetrahedra(const dk_mesh *mesh, const dk_index *tets, dk_index n_tets,
                                  dk_error *err)
{
    const dk_index n = mesh->n_vertices;
    if (n_tets > (INT32_MAX - n) / 6)
        return dk_error_set(err, DK_ERR_INVALID_ARGUMENT,
                            "ARAP bind: %ld tetrahedra, at most %ld", (long)n_tets,
                            (long)((INT32_MAX - n) / 6));
    for (dk_index t = 0; t < n_tets; t++) {
        const dk_index *q = tets + 4 * (size_t)t;
        for (int a = 0; a < 4; a++) {
            if (q[a] < 0 || q[a] >= n)
                return dk_error_set(err, DK_ERR_INVALID_ARGUMENT,
                                    "ARAP bind: tetrahedron %ld has corner %ld, the mesh has "
                                    "%ld vertices", (long)t, (long)q[a], (long)n);
            for (int b = 0; b < a; b++)
                if (q[a] == q[b])
                    return dk_error_set(err, DK_ERR_INVALID_ARGUMENT,
                                        "ARAP bind: tetrahedron %ld has vertex %ld twice",
                                        (long)t, (long)q[a]);
        }
        for (int a = 0; a < 4; a++)
            for (int b = a + 1; b < 4; b++)
                if (dk_mesh_find_edge(mesh, q[a], q[b]) < 0)
                    return dk_error_set(err, DK_ERR_INVALID_ARGUMENT,
                                        "ARAP bind: tetrahedron %ld's edge (%ld, %ld) is no "
                                        "edge of the mesh's triangles (give the tetrahedra's "
                                        "faces)", (long)t, (long)q[a], (long)q[b]);
    }
    return DK_OK;
}

/* dk_arap_bind (tets NULL) and dk_arap_bind_tetrahedra. */
static dk_status bind(const dk_mesh *mesh, const dk_index *tets, dk_index n_tets,
                      const dk_constraint_desc *constraints, const dk_arap_options *options,
                      dk_arap **out, dk_error *err)
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
    if (tets && (st = check_tetrahedra(mesh, tets, n_tets, err)) != DK_OK)
        return st;
    dk_arap *ar = calloc(1, sizeof *ar);
    if (!ar)
        return oom(err, "object");
    ar->caller_mesh = mesh;
    ar->team = dk_team_create(); /* NULL (no thread available) is fine: passes start threads */
    ar->opt = opt;
    if (tets) /* a volume's cells: no simplified surface stands for them */
        ar->opt.levels = 1;
    dk_progress prog;
    dk_progress_init(&prog, opt.progress, opt.progress_user, bind_phases,
                     (int)(sizeof bind_phases / sizeof bind_phases[0]), "ARAP bind");
    ar->prog = &prog;
    ar->prog_base = BIND_PHASE_BASE;
    ar->cg = opt.cg_iterations;
    ar->cg_scheduled = 1;
    ar->n = mesh->n_vertices;
    ar->nc = tets ? ar->n + n_tets : ar->n;
    st = dk_progress_begin(&prog, 0, err); /* renumber */
    if (st == DK_OK)
        st = dk_reorder_create(mesh, 0, &ar->ro, err);
    if (st != DK_OK) {
        dk_arap_free(ar);
        return st == DK_ERR_CANCELLED ? st : dk_error_prefix(err, "ARAP bind");
    }
    ar->mesh = ar->ro->mesh;
    ar->base = ar->mesh->positions;
    ar->opt.progress = NULL; /* the caller's callback is for this bind only */
    ar->opt.progress_user = NULL;
    ar->x = malloc(((size_t)ar->n * 3 + 1) * sizeof *ar->x);
    ar->rot = malloc(((size_t)ar->nc * 9 + 1) * sizeof *ar->rot);
    dk_index *itets = tets ? malloc(4 * (size_t)n_tets * sizeof *tets + 1) : NULL;
    if (itets) /* in the internal numbering */
        for (size_t k = 0; k < 4 * (size_t)n_tets; k++)
            itets[k] = ar->ro->iperm[tets[k]];
    ar->prev = malloc(((size_t)ar->n * 3 + 1) * sizeof *ar->prev);
    ar->prev2 = malloc(((size_t)ar->n * 3 + 1) * sizeof *ar->prev2);
    if (!ar->x || !ar->rot || !ar->prev || !ar->prev2 || (tets && !itets)) {
        free(itets);
        dk_arap_free(ar);
        return oom(err, "positions");
    }
    for (dk_index v = 0; v < ar->nc; v++) /* rotations are always valid guesses */
        for (int k = 0; k < 9; k++)
            ar->rot[9 * (size_t)v + k] = k % 4 == 0 ? 1.0 : 0.0;
    dk_reorder_desc rd;
    st = dk_reorder_desc_create(ar->ro, mesh, constraints, &rd, err);
    if (st != DK_OK) {
        free(itets);
        dk_arap_free(ar);
        return dk_error_prefix(err, "ARAP");
    }
    st = dk_progress_begin(&prog, 1, err); /* cells */
    if (st == DK_OK)
        st = tets ? arap_build_volume_cells(ar, itets, n_tets, err) : arap_build_cells(ar, err);
    free(itets);
    if (st == DK_OK)
        st = arap_system_build(ar, &rd.desc, NULL, &ar->sys, err);
    dk_reorder_desc_free(&rd);
    ar->prog = NULL;
    if (st != DK_OK) {
        dk_arap_free(ar);
        return st;
    }
    dk_progress_done(&prog);
    *out = ar;
    return DK_OK;
}

dk_status dk_arap_bind(const dk_mesh *mesh, const dk_constraint_desc *constraints,
                       const dk_arap_options *options, dk_arap **out, dk_error *err)
{
    return bind(mesh, NULL, 0, constraints, options, out, err);
}

dk_status dk_arap_bind_tetrahedra(const dk_mesh *mesh, const dk_index *tetrahedra,
                                  dk_index n_tetrahedra, const dk_constraint_desc *constraints,
                                  const dk_arap_options *options, dk_arap **out, dk_error *err)
{
    if (out)
        *out = NULL;
    if (!tetrahedra || n_tetrahedra < 1)
        return dk_error_set(err, DK_ERR_INVALID_ARGUMENT,
                            "ARAP bind: no tetrahedra (tetrahedra NULL or n_tetrahedra %ld)",
                            (long)n_tetrahedra);
    return bind(mesh, tetrahedra, n_tetrahedra, constraints, options, out, err);
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
    dk_progress prog;
    dk_progress_init(&prog, ar->opt.progress, ar->opt.progress_user, rebind_phases,
                     (int)(sizeof rebind_phases / sizeof rebind_phases[0]), "ARAP rebind");
    ar->prog = &prog;
    ar->prog_base = 0;
    st = arap_system_build(ar, &rd.desc, &ar->sys, &s, err);
    ar->prog = NULL;
    dk_reorder_desc_free(&rd);
    if (st != DK_OK)
        return st;
    dk_progress_done(&prog);
    arap_system_free(&ar->sys);
    ar->sys = s;
    ar->n_hist = 0; /* other constraints: the drag history no longer predicts */
    return DK_OK;
}

/* One solve: the targets, where to start, the iterations, the end kept for the next one. */
/* 1. The pose this solve edits (read aside: nothing changes before the targets pass), and
 * the targets, expanded per handle vertex; then the pose taken: its edges, and what the
 * system made of them. *swapped: the request's input became ar->input, the old one is in
 * ar->input_next (restore_base puts it back). */
static dk_status take_pose(dk_arap *ar, const dk_solve_request *rq, int *swapped,
                           dk_error *err)
{
    arap_system *s = &ar->sys;
    const double *base = ar->mesh->positions;
    *swapped = 0;
    if (rq->input_positions) {
        const size_t bytes = 3 * (size_t)ar->n * sizeof(double);
        if (!ar->input_next && !(ar->input_next = malloc(bytes + sizeof(double))))
            return oom(err, "input positions");
        dk_reorder_rows_in(ar->ro, rq->input_positions, ar->input_next);
        base = ar->base == ar->input && memcmp(ar->input, ar->input_next, bytes) == 0
                   ? ar->input
                   : ar->input_next;
    }
    const dk_status st = dk_constraints_targets(s->con, base, rq->targets,
                                                (int)rq->target_kind, s->targets, err);
    if (st != DK_OK) /* refused: the targets of the last solve are still in place */
        return dk_error_prefix(err, "ARAP solve");
    s->have_targets = 1;
    if (base != ar->base) {
        if (base == ar->input_next) { /* it becomes the input; the old one the scratch */
            double *old = ar->input;
            ar->input = ar->input_next;
            ar->input_next = old;
            *swapped = 1;
        }
        ar->base = base;
        arap_cells_set_edges(ar, base);
        arap_system_edges_changed(ar, s);
        ar->n_hist = 0;     /* the drag predictor's ends were solved on another pose */
        s->resumable = 0;
    }
    return DK_OK;
}

/* After a solve that failed having taken another pose: the pose before it again (`was`),
 * so that a failed call leaves energy() as it was. */
static void restore_base(dk_arap *ar, const double *was, int swapped)
{
    if (ar->base == was)
        return;
    if (swapped) {
        double *cur = ar->input;
        ar->input = ar->input_next;
        ar->input_next = cur;
    }
    ar->base = was;
    arap_cells_set_edges(ar, was);
    arap_system_edges_changed(ar, &ar->sys);
}

static dk_status solve_rest(dk_arap *ar, const dk_solve_request *rq, double *positions,
                            dk_solve_info *info, dk_error *err);

static dk_status solve_impl(dk_arap *ar, const dk_solve_request *rq, double *positions,
                            dk_solve_info *info, dk_error *err)
{
    if (info)
        memset(info, 0, sizeof *info);
    if (!ar || !positions)
        return dk_error_set(err, DK_ERR_INVALID_ARGUMENT,
                            "ARAP solve: object and positions must not be NULL");
    dk_status st = dk_solve_request_check_input(rq, ar->n, "ARAP solve", err);
    if (st != DK_OK)
        return st;
    const double *given = rq->start == DK_START_GIVEN ? rq->start_positions : NULL;
    if (given && (st = dk_start_positions_check(given, ar->n, "ARAP solve", err)) != DK_OK)
        return st; /* before anything changes */
    const double *was = ar->base;
    int swapped = 0;
    st = take_pose(ar, rq, &swapped, err);
    if (st != DK_OK)
        return st;
    st = solve_rest(ar, rq, positions, info, err);
    if (st != DK_OK)
        restore_base(ar, was, swapped);
    return st;
}

/* 2-4: the start, the iterations and the result, on the pose and targets take_pose set. */
static dk_status solve_rest(dk_arap *ar, const dk_solve_request *rq, double *positions,
                            dk_solve_info *info, dk_error *err)
{
    arap_system *s = &ar->sys;
    dk_status st;
    /* a preview is the start alone: no iterations */
    const int maxit = rq->preview ? 0
                      : rq->max_iterations > 0 ? rq->max_iterations
                                               : ar->opt.max_iterations;
    /* warm: from the previous solution; a given start, like a cold one, depends on the
     * request alone and starts the drag history again */
    const int warm_start = rq->start == DK_START_WARM || rq->start == DK_START_RESUME;
    const double *given = rq->start == DK_START_GIVEN ? rq->start_positions : NULL;

    if (s->nu == 0) { /* every vertex constrained: the constrained motion, exactly */
        dk_constraints_constrained_motion(s->con, ar->base, s->targets, ar->x);
        const double e = arap_local_energy(ar, s, ar->x, NULL);
        dk_reorder_rows_out(ar->ro, ar->x, positions);
        st = dk_solve_result_check(positions, ar->n, e, !rq->skip_energy, "ARAP solve", err);
        if (st != DK_OK)
            return st;
        ar->have_prev = 0;
        if (info) {
            info->energy = rq->skip_energy ? NAN : e;
            info->iterations = 0;
            info->converged = 1;
        }
        return DK_OK;
    }

    /* 2. the start. Resume: the previous call's targets again, and nothing changed since:
     * continue exactly where it stopped, acceleration history included, so that solves
     * resumed in slices (the add-on's interactive time budget) equal one longer solve. */
    const size_t nhv3 = 3 * (size_t)s->con->n_handle_vertices;
    const int resume = rq->start == DK_START_RESUME && ar->have_prev && s->resumable &&
                       memcmp(s->targets, s->targets_prev, nhv3 * sizeof(double)) == 0;
    /* a cold start on a system with a coarse level: from its solve, prolonged (multiscale.c,
     * in the internal order) */
    int given_internal = 0;
    if (!resume && !given && !(warm_start && ar->have_prev) && s->coarse) {
        if ((st = arap_coarse_start(ar, s, &given, err)) != DK_OK)
            return st;
        given_internal = given != NULL;
    }
    arap_progress p = {0};
    if (!resume) {
        s->cg_level = 0;       /* the CG schedule starts again (newton.c) */
        /* coarse corrections in cold and given solves only: their error is in the slow
         * bending modes, which the coarse level carries (the 692k armadillo from the bind
         * pose: 194 -> 83 Newton steps); a drag step's small error mostly is not (measured
         * with them at 692k: 32 -> 39 steps to the same minimum for a 2% drag step; 84 ->
         * 340 for the next, ending lower where the single level stopped on a plateau:
         * docs/methods/arap.md, "Multi-scale"), and drags keep their time */
        s->coarse_active = !(warm_start && ar->have_prev);
        arap_gap_restart(s, 0); /* and the decreases the stopping test extrapolates */
    }
    if (resume)
        p.energy = s->last_energy; /* ar->x, s->xu, s->rhs, ar->rot: as the last call left them */
    else if ((st = arap_start(ar, s, given, given_internal, warm_start && ar->have_prev,
                              rq->preview, &p.energy, err)) != DK_OK)
        return st;
    /* a preview's local step is done when the energy is asked for, or by the first
     * iteration of the solve that refines it */
    if (s->start_pending && (!rq->skip_energy || maxit > 0) &&
        (st = arap_start_complete(ar, s, &p.energy, err)) != DK_OK)
        return st;

    /* 3. the iterations */
    p.tiny = 1e-26 * s->escale;
    p.converged = p.energy <= p.tiny;
    s->resumable = 0; /* until this call ends normally */
    st = ar->opt.acceleration == DK_ARAP_ACCEL_NEWTON
             ? arap_iterate_newton(ar, s, maxit, &p, err)
             : arap_iterate_local_global(ar, s, maxit, &p, err);
    if (st != DK_OK)
        return st;

    /* 4. the result, and its end kept for the next warm start */
    arap_keep_history(ar, s, warm_start);
    dk_reorder_rows_out(ar->ro, ar->x, positions);
    st = dk_solve_result_check(positions, ar->n, p.energy, !rq->skip_energy, "ARAP solve", err);
    if (st != DK_OK) { /* a non-finite end is no start: the next solve starts cold */
        ar->have_prev = 0;
        ar->n_hist = 0;
        return st;
    }
    s->last_energy = p.energy;
    s->resumable = 1;
    if (info) {
        info->energy = rq->skip_energy ? NAN : p.energy; /* skipped: NaN, as the contract says */
        info->iterations = p.iterations;
        info->converged = p.converged;
        info->rejected = p.rejected;
        info->predicted = !resume && s->predicted;
        info->cg_iterations = p.cg_total;
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

void dk_arap_set_progress(dk_arap *ar, dk_phase_progress_fn progress, void *user)
{
    if (!ar)
        return;
    ar->opt.progress = progress;
    ar->opt.progress_user = progress ? user : NULL;
}

double dk_arap_tolerance(const dk_arap *ar)
{
    return ar ? ar->opt.tolerance : NAN;
}

dk_status dk_arap_set_cg_iterations(dk_arap *ar, int cg_iterations, dk_error *err)
{
    if (!ar)
        return dk_error_set(err, DK_ERR_INVALID_ARGUMENT, "ARAP: object is NULL");
    if (cg_iterations < 0 || cg_iterations > 100)
        return dk_error_set(err, DK_ERR_INVALID_ARGUMENT,
                            "ARAP: cg_iterations is %d, must be in [1, 100] (0: as bound)",
                            cg_iterations);
    ar->cg = cg_iterations > 0 ? cg_iterations : ar->opt.cg_iterations;
    ar->cg_scheduled = cg_iterations == 0; /* a count asked for is run as asked */
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
    *energy = arap_local_energy(ar, &ar->sys, x, NULL);
    free(x);
    return dk_energy_result_check(*energy, "ARAP energy", err);
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
    dk_constraints_held_stats(ar->sys.con, ar->ro->perm, stats);
    stats->n_unknowns = ar->sys.nu;
    stats->analysis_count = ar->analysis_count;
    stats->factorization_count = ar->factorization_count;
}

void dk_arap_get_counters(const dk_arap *ar, dk_arap_counters *counters)
{
    if (!counters)
        return;
    memset(counters, 0, sizeof *counters);
    if (!ar)
        return;
    counters->basis_columns = ar->sys.zcols;
    counters->basis_starts = ar->basis_starts;
    for (const dk_arap *a = ar; a->sys.coarse; a = a->sys.coarse->arap) {
        counters->coarse_vertices[counters->levels] = a->sys.coarse->arap->n;
        if (counters->levels++ == 0) {
            counters->coarse_starts = a->sys.coarse->starts;
            counters->coarse_corrections = a->sys.coarse->corrections;
        }
        if (counters->levels == 7)
            break;
    }
    counters->levels++; /* the mesh itself */
}

dk_status dk_arap_response_basis(const dk_arap *ar, double *out, dk_error *err)
{
    if (!ar || !out)
        return dk_error_set(err, DK_ERR_INVALID_ARGUMENT,
                            "ARAP response basis: object and out must not be NULL");
    const arap_system *s = &ar->sys;
    if (!s->zb)
        return dk_error_set(err, DK_ERR_INVALID_ARGUMENT,
                            "ARAP response basis: not built (basis='off', more than 16 "
                            "handles, over 128 MB, or nothing to solve)");
    const dk_constraints *c = s->con;
    const size_t ncol = (size_t)s->zcols, nu = (size_t)s->nu;
    const double *rest = ar->mesh->positions;
    for (dk_index v = 0; v < ar->n; v++) {
        double *row = out + ncol * (size_t)ar->ro->perm[v];
        const dk_index u = s->unk[v], h = c->role[v];
        memset(row, 0, ncol * sizeof(double));
        if (u >= 0) {
            for (size_t k = 0; k < ncol; k++)
                row[k] = s->zb[k * nu + (size_t)u];
        } else if (h >= 0) {
            for (int j = 0; j < 3; j++)
                row[4 * (size_t)h + (size_t)j] = rest[3 * (size_t)v + (size_t)j];
            row[4 * (size_t)h + 3] = 1.0;
        }
    }
    return DK_OK;
}

dk_status dk_arap_estimate_memory(const dk_mesh *mesh, const dk_arap_options *options,
                                  uint64_t *bytes, dk_error *err)
{
    if (!mesh || !bytes)
        return dk_error_set(err, DK_ERR_INVALID_ARGUMENT,
                            "ARAP estimate_memory: mesh and bytes must not be NULL");
    dk_status st = options ? check_options(options, err) : DK_OK; /* what bind refuses */
    if (st != DK_OK)
        return st;
    const double n = (double)mesh->n_vertices, lg = n > 2.0 ? log2(n) : 1.0;
    /* measured 1950 B/vertex at 8k and 43k vertices, 2180-2450 at 692k */
    *bytes = dk_memory_model(1700.0 + 40.0 * lg, n, 0.0);
    /* the coarse levels (multiscale.c): each a sixteenth of the one above, and the
     * simplification's working arrays (~300 B a vertex of the finer level, freed after);
     * automatic levels counted by vertices, an upper bound of the unknowns that decide */
    const int levels = options ? options->levels : 0;
    double m = n;
    for (int k = 1; levels == 0 ? m >= 100000.0 : k < levels; k++) {
        const double c = floor(m / 16.0);
        if (c < 16.0)
            break;
        const double lc = c > 2.0 ? log2(c) : 1.0;
        *bytes += dk_memory_model(1700.0 + 40.0 * lc, c, 0.0) + (uint64_t)(300.0 * m);
        m = c;
    }
    return DK_OK;
}

/* ---------------------------------------------------------------- the method contract --- */

/* the contract's table (dk_method.h): the adapters cast to this method's types */
/* the options' fields (dk_option_desc): where each is, what values bind takes */
static const dk_option_desc arap_fields[] = {
    {"energy", DK_OPTION_ENUM, offsetof(dk_arap_options, energy), 0, 0, 1, 0, 1, 0},
    {"weights", DK_OPTION_ENUM, offsetof(dk_arap_options, weights), 0, 0, 2, 1, 2, 0},
    {"max_iterations", DK_OPTION_INT, offsetof(dk_arap_options, max_iterations), 0, 1, INT_MAX,
     100, 40, 0},
    {"tolerance", DK_OPTION_DOUBLE, offsetof(dk_arap_options, tolerance), 0, 0, DBL_MAX, 1e-6,
     DBL_MAX, 0},
    {"acceleration", DK_OPTION_ENUM, offsetof(dk_arap_options, acceleration), 0, 0, 2, 2, 2, 0},
    {"anderson_depth", DK_OPTION_INT, offsetof(dk_arap_options, anderson_depth), 0, 1,
     MAX_ANDERSON_DEPTH, 5, MAX_ANDERSON_DEPTH, 0},
    {"cg_iterations", DK_OPTION_INT, offsetof(dk_arap_options, cg_iterations), 0, 1, 100, 12,
     100, 0},
    {"cg_schedule", DK_OPTION_ENUM, offsetof(dk_arap_options, cg_schedule), 0, 0, 1, 0, 1, 0},
    {"predict", DK_OPTION_INT, offsetof(dk_arap_options, predict), 0, 0, 1, 1, 1, 0},
    {"basis", DK_OPTION_ENUM, offsetof(dk_arap_options, basis), 0, 0, 1, 0, 1, 0},
    {"levels", DK_OPTION_INT, offsetof(dk_arap_options, levels), 0, 1, 8, 2, 2,
     DK_OPTION_ZERO_AUTO},
};

DK_METHOD_OPS_STATEFUL(dk_arap_ops, "ARAP",
              DK_METHOD_ITERATIVE | DK_METHOD_TRANSFORMS_AS_POSITIONS |
              DK_METHOD_TRANSLATION_INVARIANT | DK_METHOD_RIGID_INVARIANT |
              DK_METHOD_GIVEN_START | DK_METHOD_EDITS_INPUT, DK_CONTROL_VERTEX_GROUPS,
              dk_arap, dk_arap, dk_arap_options, arap_fields);

