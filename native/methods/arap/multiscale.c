/* DeformKit ARAP: the coarse level of the multi-scale solve (see arap_internal.h,
 * arap_coarse). A cold start (a solve with no previous solution to start from, or asked
 * cold) on a system with a coarse level:
 *   1. the targets and the pose restricted to the coarse vertices (a subset of the mesh's,
 *      dk_decimate: each kept vertex keeps its handle, fixed or free role);
 *   2. the coarse ARAP object solves them, cold (itself multi-scale when it has a level);
 *   3. its positions and rotations prolonged to the mesh (dk_decimation_prolong: each
 *      removed vertex carried by its nearest coarse triangle, its offset turned by the
 *      carriers' blended rotation);
 *   4. the full-mesh solve starts there, as from a given start (DK_START_GIVEN), so its
 *      converged answer is still the full mesh's minimum for the targets.
 * The level is built with the system (arap_system_build) for its constraints, so a rebind
 * replaces it with the rest. It is an accelerator, not a result: when the coarse mesh does
 * not bind (a coarse triangle fan that is not positive definite, say) the system has none
 * and solves start as without it.
 *
 * A level can also be attached by the object's owner (dk_arap_attach_coarse_level: a
 * volume's coarse tetrahedra, native/methods/volumetric/multiscale.c): no decimation, its
 * own ARAP object (borrowed) and two linear maps given as sparse rows, the prolongation of
 * the coarse points to the mesh's and the restriction of the mesh's iterate to the coarse
 * points. Its cold start prolongs the coarse result's move from the restricted pose, and
 * its corrections (when its owner asks for them) use the maps where a decimation uses its
 * carriers. */
#include "arap_internal.h"

/* how many times fewer vertices each coarse level has: the armadillo scenario's measured
 * levels (docs/methods/arap.md, "A million vertices": 692k from 43k) */
#define COARSE_RATIO 16
/* levels 0 (automatic) adds a coarse level from this many unknowns on */
#define AUTO_MIN_UNKNOWNS 100000
/* no coarse level of fewer vertices (a level asked for on a small mesh: tests) */
#define MIN_COARSE_VERTICES 16

void arap_coarse_free(arap_coarse *c)
{
    if (!c)
        return;
    if (!c->borrowed)
        dk_arap_free(c->arap);
    dk_mesh_free(c->mesh);
    dk_decimation_free(c->dec);
    free(c->target_row);
    free(c->targets);
    free(c->pose);
    free(c->y);
    free(c->rot);
    free(c->fine);
    free(c->scratch);
    free(c->cr);
    free(c->cb);
    free(c->cd);
    free(c->fd);
    free(c->fq);
    free(c->ps);
    free(c->pc);
    free(c->pw);
    free(c->rs);
    free(c->rc);
    free(c->rw);
    free(c->cacc);
    free(c->cpose);
    free(c);
}

/* The level's coarse points (a decimation's kept vertices, or an attached object's). */
static dk_index n_coarse(const arap_coarse *c)
{
    return c->dec ? c->dec->n_kept : c->arap->n;
}

/* A fine vector (n x 3, internal numbering) at the coarse points (n_coarse x 3): a kept
 * vertex's own, or an attached level's restriction. */
static void restrict_iterate(const arap_coarse *c, const double *fine, double *coarse)
{
    const dk_index mk = n_coarse(c);
    for (dk_index k = 0; k < mk; k++) {
        double *y = coarse + 3 * (size_t)k;
        if (c->dec) {
            memcpy(y, fine + 3 * (size_t)c->dec->kept[k], 3 * sizeof *y);
            continue;
        }
        y[0] = y[1] = y[2] = 0.0;
        for (dk_index q = c->rs[k]; q < c->rs[k + 1]; q++) {
            const double *f = fine + 3 * (size_t)c->rc[q], w = c->rw[q];
            y[0] += w * f[0], y[1] += w * f[1], y[2] += w * f[2];
        }
    }
}

/* The transpose of the linear prolongation: the fine vector acc (n x 3, internal numbering;
 * a decimation's accumulates in place) handed to the coarse points, into coarse
 * (n_coarse x 3). */
static void restrict_dual(const arap_coarse *c, double *acc, double *coarse)
{
    const dk_index mk = n_coarse(c);
    const dk_decimation *d = c->dec;
    if (d) { /* each removed vertex's share handed to its carriers in removal order */
        for (dk_index k = 0; k < d->n_removed; k++) {
            const double *ru = acc + 3 * (size_t)d->removed[k];
            for (int i = 0; i < 3; i++) {
                double *rc = acc + 3 * (size_t)d->carrier[3 * (size_t)k + i];
                const double w = d->weight[3 * (size_t)k + i];
                rc[0] += w * ru[0], rc[1] += w * ru[1], rc[2] += w * ru[2];
            }
        }
        for (dk_index k = 0; k < mk; k++)
            memcpy(coarse + 3 * (size_t)k, acc + 3 * (size_t)d->kept[k], 3 * sizeof *coarse);
        return;
    }
    memset(coarse, 0, 3 * (size_t)mk * sizeof *coarse);
    for (dk_index i = 0; i < c->n_fine; i++) {
        const double *f = acc + 3 * (size_t)i;
        for (dk_index q = c->ps[i]; q < c->ps[i + 1]; q++) {
            double *y = coarse + 3 * (size_t)c->pc[q];
            const double w = c->pw[q];
            y[0] += w * f[0], y[1] += w * f[1], y[2] += w * f[2];
        }
    }
}

/* The linear prolongation: coarse (n_coarse x 3) to fine (n x 3, internal numbering): a
 * kept vertex takes its coarse value, a removed one its carriers' blend in reverse removal
 * order; an attached level's rows. */
static void prolong_linear(const arap_coarse *c, const double *coarse, double *fine)
{
    const dk_decimation *d = c->dec;
    if (d) {
        memset(fine, 0, 3 * (size_t)d->n_vertices * sizeof *fine);
        for (dk_index k = 0; k < d->n_kept; k++)
            memcpy(fine + 3 * (size_t)d->kept[k], coarse + 3 * (size_t)k, 3 * sizeof *fine);
        for (dk_index k = d->n_removed - 1; k >= 0; k--) {
            double *du = fine + 3 * (size_t)d->removed[k];
            du[0] = du[1] = du[2] = 0.0;
            for (int i = 0; i < 3; i++) {
                const double *dc = fine + 3 * (size_t)d->carrier[3 * (size_t)k + i];
                const double w = d->weight[3 * (size_t)k + i];
                du[0] += w * dc[0], du[1] += w * dc[1], du[2] += w * dc[2];
            }
        }
        return;
    }
    for (dk_index i = 0; i < c->n_fine; i++) {
        double *f = fine + 3 * (size_t)i;
        f[0] = f[1] = f[2] = 0.0;
        for (dk_index q = c->ps[i]; q < c->ps[i + 1]; q++) {
            const double *y = coarse + 3 * (size_t)c->pc[q], w = c->pw[q];
            f[0] += w * y[0], f[1] += w * y[1], f[2] += w * y[2];
        }
    }
}

/* the coarse level's size for levels (0: automatic, by the nu unknowns), or 0 for none */
static dk_index coarse_size(dk_index n, dk_index nu, int levels)
{
    if (levels == 1 || (levels == 0 && nu < AUTO_MIN_UNKNOWNS))
        return 0;
    const dk_index m = n / COARSE_RATIO;
    return m >= MIN_COARSE_VERTICES ? m : 0;
}

/* The level's solve and correction buffers (c->arap and c->n_handle_vertices set). */
static dk_status alloc_buffers(const dk_arap *ar, const arap_system *s, arap_coarse *c,
                               dk_error *err)
{
    const size_t mk3 = 3 * (size_t)n_coarse(c) + 1, n3 = 3 * (size_t)ar->n + 1;
    const size_t cn = 3 * (size_t)c->arap->sys.nu + 1, fn = 3 * (size_t)s->nu + 1;
    c->targets = malloc((3 * (size_t)c->n_handle_vertices + 1) * sizeof *c->targets);
    c->pose = malloc(mk3 * sizeof *c->pose);
    c->y = malloc(mk3 * sizeof *c->y);
    c->rot = malloc((9 * (size_t)n_coarse(c) + 1) * sizeof *c->rot);
    c->fine = malloc(n3 * sizeof *c->fine);
    c->scratch = malloc((4 * (size_t)ar->n + 1) * sizeof *c->scratch);
    c->cr = malloc(mk3 * sizeof *c->cr);
    c->cacc = malloc(mk3 * sizeof *c->cacc);
    c->cb = malloc(cn * sizeof *c->cb);
    c->cd = malloc(cn * sizeof *c->cd);
    c->fd = malloc(fn * sizeof *c->fd);
    c->fq = malloc(fn * sizeof *c->fq);
    if (!c->dec)
        c->cpose = malloc(mk3 * sizeof *c->cpose);
    if (!c->targets || !c->pose || !c->y || !c->rot || !c->fine || !c->scratch || !c->cr ||
        !c->cacc || !c->cb || !c->cd || !c->fd || !c->fq || (!c->dec && !c->cpose))
        return oom(err, "coarse level");
    return DK_OK;
}

/* the simplification's progress, as ticks of the bind's coarse phase */
typedef struct tick_ctx {
    const dk_arap *ar;
    dk_error *err;
} tick_ctx;

static int tick(void *user, double done, double total)
{
    const tick_ctx *t = user;
    return arap_tick(t->ar, done, total, t->err) != DK_OK;
}

dk_status arap_coarse_build(dk_arap *ar, const arap_system *s, arap_coarse **out, dk_error *err)
{
    *out = NULL;
    const dk_index m = coarse_size(ar->n, s->nu, ar->opt.levels);
    if (m == 0 || s->nu == 0)
        return DK_OK;
    const dk_constraints *con = s->con;
    /* classes: the fixed or free role, or a handle's id and whether its vertex is hard or
     * soft (weight < 1), so that every region of one role keeps vertices (a handle that lost
     * them all would be missing at the coarse level, one that kept only soft ones would
     * pull by penalties alone where the mesh's hard ones are exact) */
    int *cls = malloc(((size_t)ar->n + 1) * sizeof *cls);
    arap_coarse *c = calloc(1, sizeof *c);
    if (!cls || !c) {
        free(cls);
        free(c);
        return oom(err, "coarse level");
    }
    dk_constraints_classes(con, cls);
    tick_ctx tc = {ar, err};
    dk_status st = dk_decimate_progress(ar->mesh, cls, m, tick, &tc, &c->dec, err);
    free(cls);
    if (st != DK_OK) {
        arap_coarse_free(c);
        return st;
    }
    const dk_decimation *d = c->dec;
    const dk_index mk = d->n_kept;
    if (mk > ar->n / 4 || d->n_faces == 0) { /* blocked collapses (a triangle soup, high
                                               * valences): a level would not pay its solve */
        arap_coarse_free(c);
        return DK_OK;
    }
    double *cp = malloc((3 * (size_t)mk + 1) * sizeof *cp);
    if (!cp) {
        arap_coarse_free(c);
        return oom(err, "coarse level");
    }
    for (dk_index k = 0; k < mk; k++)
        memcpy(cp + 3 * (size_t)k, ar->mesh->positions + 3 * (size_t)d->kept[k], 3 * sizeof *cp);
    dk_error ignored = {0};
    st = dk_mesh_create(cp, mk, d->faces, d->n_faces, &c->mesh, &ignored);
    free(cp);
    if (st == DK_ERR_OUT_OF_MEMORY)
        dk_error_set(err, st, "ARAP: out of memory (coarse level)");
    dk_coarse_constraints cc;
    memset(&cc, 0, sizeof cc);
    if (st == DK_OK && (st = dk_coarse_constraints_create(con, d, &cc, err)) != DK_OK)
        dk_error_prefix(err, "ARAP");
    if (st == DK_OK) {
        c->n_handle_vertices = cc.n_handle_vertices;
        if (!(c->target_row = malloc(((size_t)cc.n_handle_vertices + 1) *
                                     sizeof *c->target_row)))
            st = oom(err, "coarse level");
        for (dk_index k = 0; st == DK_OK && k < cc.n_handle_vertices; k++)
            c->target_row[k] = s->target_of[cc.fine_vertex[k]];
    }
    if (st == DK_OK) {
        dk_arap_options o = ar->opt;
        o.levels = ar->opt.levels == 0 ? 0 : ar->opt.levels - 1;
        o.basis = DK_ARAP_BASIS_OFF; /* it solves cold only: no warm start to combine */
        o.on_iteration = NULL;
        o.user = NULL;
        o.progress = NULL;
        o.progress_user = NULL;
        st = dk_arap_bind(c->mesh, &cc.desc, &o, &c->arap, &ignored);
        if (st == DK_ERR_OUT_OF_MEMORY)
            dk_error_set(err, st, "ARAP: out of memory (coarse level)");
    }
    dk_coarse_constraints_free(&cc);
    if (st == DK_OK)
        st = alloc_buffers(ar, s, c, err);
    if (st == DK_ERR_OUT_OF_MEMORY) {
        arap_coarse_free(c);
        return st;
    }
    if (st != DK_OK) { /* the coarse mesh would not bind: solves start without it */
        arap_coarse_free(c);
        return DK_OK;
    }
    *out = c;
    return DK_OK;
}

/* An attached level whose object was rebound since (other unknowns or handle vertices: the
 * buffers were sized for the old ones) is skipped. */
static int usable(const arap_coarse *c)
{
    return c->dec || (c->arap->sys.nu == c->cnu &&
                      c->arap->sys.con->n_handle_vertices == c->n_handle_vertices);
}

/* the coarse level's targets from the system's expanded ones */
static void restrict_targets(arap_coarse *c, const arap_system *s)
{
    for (dk_index k = 0; k < c->n_handle_vertices; k++)
        memcpy(c->targets + 3 * (size_t)k, s->targets + 3 * (size_t)c->target_row[k],
               3 * sizeof *c->targets);
}

dk_status arap_coarse_start(dk_arap *ar, arap_system *s, const double **start, dk_error *err)
{
    arap_coarse *c = s->coarse;
    const dk_decimation *d = c->dec;
    const dk_index mk = n_coarse(c);
    *start = NULL;
    if (!usable(c))
        return DK_OK;
    restrict_targets(c, s);
    const int posed = ar->base != ar->mesh->positions;
    if (posed)
        restrict_iterate(c, ar->base, c->pose);
    /* the tolerance the mesh solves to now (dk_arap_set_tolerance), down every level */
    c->arap->opt.tolerance = ar->opt.tolerance;
    dk_solve_request rq;
    memset(&rq, 0, sizeof rq);
    rq.targets = c->targets;
    rq.target_kind = DK_TARGETS_POSITIONS;
    rq.start = DK_START_COLD;
    rq.skip_energy = 1;
    rq.input_positions = posed ? c->pose : NULL;
    dk_error cerr = {0};
    dk_status st = dk_arap_solve(c->arap, &rq, c->y, NULL, &cerr);
    if (st == DK_ERR_OUT_OF_MEMORY)
        return dk_error_set(err, st, "ARAP: out of memory (coarse level's solve)");
    if (st != DK_OK) { /* not finite (cannot happen for finite targets): start without it */
        *start = NULL;
        return DK_OK;
    }
    const dk_arap *ca = c->arap;
    if (d) {
        for (dk_index i = 0; i < mk; i++) /* the coarse rotations in the coarse vertex order */
            memcpy(c->rot + 9 * (size_t)ca->ro->perm[i], ca->rot + 9 * (size_t)i,
                   9 * sizeof *c->rot);
        dk_decimation_prolong(d, ar->base, c->y, c->rot, c->fine, c->scratch);
    } else { /* the move from the restricted pose, prolonged: base + P (y - R base) */
        restrict_iterate(c, ar->base, c->cpose);
        for (size_t k = 0; k < 3 * (size_t)mk; k++)
            c->cacc[k] = c->y[k] - c->cpose[k];
        prolong_linear(c, c->cacc, c->fine);
        for (size_t k = 0; k < 3 * (size_t)ar->n; k++)
            c->fine[k] += ar->base[k];
    }
    c->starts++;
    *start = c->fine;
    return DK_OK;
}

/* CG products of the coarse Newton direction: the coarse solve is a sixteenth of a fine
 * product each, so it can afford more than a fine step's 12 */
#define CORRECTION_CG 30

dk_status arap_coarse_correct(dk_arap *ar, arap_system *s, double *energy, int *products,
                              dk_error *err)
{
    arap_coarse *c = s->coarse;
    dk_arap *ca = c->arap;
    arap_system *cs = &ca->sys;
    const dk_index nu = s->nu, cnu = cs->nu;
    const size_t N = 3 * (size_t)nu;
    if (ar->opt.acceleration != DK_ARAP_ACCEL_NEWTON || cnu == 0 || c->no_corrections ||
        !usable(c))
        return DK_OK;
    /* 1. the fine residual r = -g, restricted: scattered to the vertices (0 where
     * eliminated), handed to the coarse points by the transpose of the linear
     * prolongation */
    double *r = s->nt_r, *acc = c->fine;
    dk_status st = arap_minus_gradient(ar, s, r);
    if (st != DK_OK)
        return st;
    memset(acc, 0, 3 * (size_t)ar->n * sizeof *acc);
    for (dk_index u = 0; u < nu; u++)
        for (int k = 0; k < 3; k++)
            acc[3 * (size_t)s->unknowns[u] + k] = r[(size_t)k * nu + u];
    restrict_dual(c, acc, c->cacc);
    /* 2. the coarse iterate: the fine one at the coarse points (kept vertices, or
     * restricted), taken as a given start by a preview (the targets and pose restricted:
     * its rotations, K^-1, right-hand side) */
    restrict_targets(c, s);
    const int posed = ar->base != ar->mesh->positions;
    restrict_iterate(c, ar->x, c->y);
    if (posed)
        restrict_iterate(c, ar->base, c->pose);
    dk_solve_request rq;
    memset(&rq, 0, sizeof rq);
    rq.targets = c->targets;
    rq.target_kind = DK_TARGETS_POSITIONS;
    rq.start = DK_START_GIVEN;
    rq.start_positions = c->y;
    rq.preview = 1;
    rq.skip_energy = 1;
    rq.input_positions = posed ? c->pose : NULL;
    dk_error cerr = {0};
    st = dk_arap_solve(ca, &rq, c->cr, NULL, &cerr);
    if (st == DK_ERR_OUT_OF_MEMORY)
        return dk_error_set(err, st, "ARAP: out of memory (coarse level's correction)");
    if (st != DK_OK)
        return DK_OK; /* (not finite: cannot happen for a finite iterate) no correction */
    /* 3. the coarse Newton direction for the restricted residual */
    for (dk_index i = 0; i < ca->n; i++) {
        const dk_index cu = cs->unk[i];
        if (cu >= 0)
            for (int k = 0; k < 3; k++)
                c->cb[(size_t)k * cnu + cu] = c->cacc[3 * (size_t)ca->ro->perm[i] + k];
    }
    st = arap_newton_direction(ca, cs, c->cb, c->cd, CORRECTION_CG, products, err);
    dk_team_park(ca->team);
    if (st != DK_OK)
        return st;
    /* 4. prolonged linearly, read at the fine unknowns */
    for (dk_index i = 0; i < ca->n; i++) {
        const dk_index cu = cs->unk[i];
        double *ci = c->cacc + 3 * (size_t)ca->ro->perm[i];
        for (int k = 0; k < 3; k++)
            ci[k] = cu >= 0 ? c->cd[(size_t)k * cnu + cu] : 0.0;
    }
    prolong_linear(c, c->cacc, acc);
    double *dir = c->fd, rd = 0.0;
    for (dk_index u = 0; u < nu; u++)
        for (int k = 0; k < 3; k++) {
            const double v = acc[3 * (size_t)s->unknowns[u] + k];
            dir[(size_t)k * nu + u] = v;
            rd += v * r[(size_t)k * nu + u];
        }
    /* 5. its length from the fine quadratic model, then a line search on E */
    const double dhd = arap_hessian_product(ar, s, dir, c->fq);
    (*products)++;
    if (!(rd > 0.0) || !(dhd > 0.0))
        return DK_OK; /* not a descent direction of the model: no correction */
    double t = rd / dhd, e = NAN;
    for (int ls = 0; ls < 4; ls++, t *= 0.5) {
        for (size_t i = 0; i < N; i++)
            s->gu[i] = s->xu[i] + t * dir[i];
        arap_scatter(s, s->gu, ar->x);
        e = arap_local_energy(ar, s, ar->x, ar->rot);
        if (e < *energy) {
            memcpy(s->xu, s->gu, N * sizeof(double));
            arap_rotations_rhs(ar, s, ar->rot);
            *energy = e;
            c->corrections++;
            return DK_OK;
        }
    }
    /* none lowered E: the iterate back, with its rotations and K^-1 */
    arap_scatter(s, s->xu, ar->x);
    (void)arap_local_energy(ar, s, ar->x, ar->rot);
    arap_rotations_rhs(ar, s, ar->rot);
    return DK_OK;
}

/* Sparse rows (start: rows + 1, col, weight) checked: ascending starts from 0, columns in
 * [0, cols), finite weights. */
static int rows_ok(const dk_index *start, const dk_index *col, const double *w, dk_index rows,
                   dk_index cols)
{
    if (!start || start[0] != 0)
        return 0;
    for (dk_index i = 0; i < rows; i++)
        if (start[i + 1] < start[i])
            return 0;
    if (start[rows] > 0 && (!col || !w))
        return 0;
    for (dk_index q = 0; q < start[rows]; q++)
        if (col[q] < 0 || col[q] >= cols || !isfinite(w[q]))
            return 0;
    return 1;
}

dk_status dk_arap_attach_coarse_level(dk_arap *ar, dk_arap *coarse,
                                      const dk_index *handle_vertex,
                                      dk_index n_handle_vertices, const dk_index *p_start,
                                      const dk_index *p_col, const double *p_weight,
                                      const dk_index *r_start, const dk_index *r_col,
                                      const double *r_weight, int correct, dk_error *err)
{
    static const char who[] = "ARAP attach_coarse_level";
    if (!ar || !coarse || coarse == ar)
        return dk_error_set(err, DK_ERR_INVALID_ARGUMENT,
                            "%s: the object and another coarse object must not be NULL", who);
    for (const dk_arap *a = coarse; a; a = a->sys.coarse ? a->sys.coarse->arap : NULL)
        if (a == ar)
            return dk_error_set(err, DK_ERR_INVALID_ARGUMENT,
                                "%s: the coarse object has this one as a level of its own",
                                who);
    arap_system *s = &ar->sys;
    const dk_index n = ar->n, mc = coarse->n;
    if (n_handle_vertices != coarse->sys.con->n_handle_vertices ||
        (n_handle_vertices > 0 && !handle_vertex))
        return dk_error_set(err, DK_ERR_INVALID_ARGUMENT,
                            "%s: %ld handle vertices given for the coarse object's %ld", who,
                            (long)n_handle_vertices, (long)coarse->sys.con->n_handle_vertices);
    for (dk_index k = 0; k < n_handle_vertices; k++)
        if (handle_vertex[k] < 0 || handle_vertex[k] >= n ||
            s->target_of[ar->ro->iperm[handle_vertex[k]]] < 0)
            return dk_error_set(err, DK_ERR_INVALID_ARGUMENT,
                                "%s: the coarse handle vertex %ld stands for vertex %ld, which "
                                "is not a handle vertex", who, (long)k, (long)handle_vertex[k]);
    if (!rows_ok(p_start, p_col, p_weight, n, mc) || !rows_ok(r_start, r_col, r_weight, mc, n))
        return dk_error_set(err, DK_ERR_INVALID_ARGUMENT,
                            "%s: the prolongation (%ld rows over %ld coarse points) or the "
                            "restriction (%ld rows over %ld vertices) is not valid sparse rows",
                            who, (long)n, (long)mc, (long)mc, (long)n);
    arap_coarse *c = calloc(1, sizeof *c);
    if (!c)
        return oom(err, "coarse level");
    c->arap = coarse;
    c->borrowed = 1;
    c->no_corrections = !correct;
    c->cnu = coarse->sys.nu;
    c->n_fine = n;
    c->n_handle_vertices = n_handle_vertices;
    const size_t np = (size_t)p_start[n], nr = (size_t)r_start[mc];
    c->ps = malloc(((size_t)n + 1) * sizeof *c->ps);
    c->pc = malloc((np + 1) * sizeof *c->pc);
    c->pw = malloc((np + 1) * sizeof *c->pw);
    c->rs = malloc(((size_t)mc + 1) * sizeof *c->rs);
    c->rc = malloc((nr + 1) * sizeof *c->rc);
    c->rw = malloc((nr + 1) * sizeof *c->rw);
    c->target_row = malloc(((size_t)n_handle_vertices + 1) * sizeof *c->target_row);
    dk_status st = DK_OK;
    if (!c->ps || !c->pc || !c->pw || !c->rs || !c->rc || !c->rw || !c->target_row)
        st = oom(err, "coarse level");
    else
        st = alloc_buffers(ar, s, c, err);
    if (st != DK_OK) {
        arap_coarse_free(c);
        return st;
    }
    /* the prolongation's rows in the internal order, the restriction's columns too */
    c->ps[0] = 0;
    for (dk_index i = 0; i < n; i++) {
        const dk_index v = ar->ro->perm[i], len = p_start[v + 1] - p_start[v];
        memcpy(c->pc + c->ps[i], p_col + p_start[v], (size_t)len * sizeof *c->pc);
        memcpy(c->pw + c->ps[i], p_weight + p_start[v], (size_t)len * sizeof *c->pw);
        c->ps[i + 1] = c->ps[i] + len;
    }
    memcpy(c->rs, r_start, ((size_t)mc + 1) * sizeof *c->rs);
    for (size_t q = 0; q < nr; q++)
        c->rc[q] = ar->ro->iperm[r_col[q]];
    memcpy(c->rw, r_weight, nr * sizeof *c->rw);
    for (dk_index k = 0; k < n_handle_vertices; k++)
        c->target_row[k] = s->target_of[ar->ro->iperm[handle_vertex[k]]];
    arap_coarse_free(s->coarse);
    s->coarse = c;
    return DK_OK;
}
