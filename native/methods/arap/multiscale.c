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
 * and solves start as without it. */
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
    free(c);
}

/* the coarse level's size for levels (0: automatic, by the nu unknowns), or 0 for none */
static dk_index coarse_size(dk_index n, dk_index nu, int levels)
{
    if (levels == 1 || (levels == 0 && nu < AUTO_MIN_UNKNOWNS))
        return 0;
    const dk_index m = n / COARSE_RATIO;
    return m >= MIN_COARSE_VERTICES ? m : 0;
}

/* the coarse constraints: each handle's kept vertices in their order, the kept fixed
 * vertices (held ones and those outside the ROI included: role FIXED), the stiffness of
 * the kept vertices; target_row[k]: the row of the k-th coarse handle vertex among the
 * system's expanded targets */
static dk_status coarse_desc(const dk_arap *ar, const arap_system *s, arap_coarse *c,
                             dk_constraint_desc *desc, dk_index **buf, double **dbuf,
                             dk_error *err)
{
    const dk_constraints *con = s->con;
    const dk_decimation *d = c->dec;
    const dk_index nh = con->n_handles, m = d->n_kept;
    dk_index *sizes = calloc((size_t)nh + 1, sizeof *sizes);
    dk_index *hv = malloc(((size_t)m + 1) * sizeof *hv), *fixed = malloc(((size_t)m + 1) * sizeof *fixed);
    double *hw = malloc(((size_t)m + 1) * sizeof *hw), *stiff = malloc(((size_t)m + 1) * sizeof *stiff);
    c->target_row = malloc(((size_t)m + 1) * sizeof *c->target_row);
    if (!sizes || !hv || !fixed || !hw || !stiff || !c->target_row) {
        free(sizes), free(hv), free(fixed), free(hw), free(stiff);
        return oom(err, "coarse level");
    }
    dk_index nhv = 0, nfix = 0;
    for (dk_index h = 0; h < nh; h++)
        for (dk_index k = con->handle_start[h]; k < con->handle_start[h + 1]; k++) {
            const dk_index v = con->handle_vertices[k], cv = d->coarse_of[v];
            if (cv < 0)
                continue;
            sizes[h]++;
            hv[nhv] = cv;
            hw[nhv] = con->handle_weights[k];
            c->target_row[nhv++] = s->target_of[v];
        }
    for (dk_index cv = 0; cv < m; cv++) {
        const dk_index v = d->kept[cv];
        stiff[cv] = con->stiffness[v];
        if (con->role[v] == DK_VERTEX_FIXED)
            fixed[nfix++] = cv;
    }
    (void)ar;
    c->n_handle_vertices = nhv;
    memset(desc, 0, sizeof *desc);
    desc->n_handles = nh;
    desc->handle_sizes = sizes;
    desc->handle_vertices = hv;
    desc->handle_weights = hw;
    desc->n_fixed = nfix;
    desc->fixed_vertices = fixed;
    desc->stiffness = stiff;
    buf[0] = sizes, buf[1] = hv, buf[2] = fixed;
    dbuf[0] = hw, dbuf[1] = stiff;
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
    for (dk_index v = 0; v < ar->n; v++)
        cls[v] = con->role[v] == DK_VERTEX_FIXED ? 1 : con->role[v] < 0 ? 0
                 : 2 + 2 * (int)con->role[v] + (s->soft_k[v] > 0.0);
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
    dk_constraint_desc desc;
    dk_index *buf[3] = {NULL, NULL, NULL};
    double *dbuf[2] = {NULL, NULL};
    if (st == DK_OK)
        st = coarse_desc(ar, s, c, &desc, buf, dbuf, err);
    if (st == DK_OK) {
        dk_arap_options o = ar->opt;
        o.levels = ar->opt.levels == 0 ? 0 : ar->opt.levels - 1;
        o.basis = DK_ARAP_BASIS_OFF; /* it solves cold only: no warm start to combine */
        o.on_iteration = NULL;
        o.user = NULL;
        o.progress = NULL;
        o.progress_user = NULL;
        st = dk_arap_bind(c->mesh, &desc, &o, &c->arap, &ignored);
        if (st == DK_ERR_OUT_OF_MEMORY)
            dk_error_set(err, st, "ARAP: out of memory (coarse level)");
    }
    for (int k = 0; k < 3; k++)
        free(buf[k]);
    free(dbuf[0]);
    free(dbuf[1]);
    if (st == DK_OK) {
        const size_t n3 = 3 * (size_t)ar->n + 1;
        c->targets = malloc((3 * (size_t)c->n_handle_vertices + 1) * sizeof *c->targets);
        c->pose = malloc((3 * (size_t)mk + 1) * sizeof *c->pose);
        c->y = malloc((3 * (size_t)mk + 1) * sizeof *c->y);
        c->rot = malloc((9 * (size_t)mk + 1) * sizeof *c->rot);
        c->fine = malloc(n3 * sizeof *c->fine);
        c->scratch = malloc((4 * (size_t)ar->n + 1) * sizeof *c->scratch);
        const size_t cn = 3 * (size_t)c->arap->sys.nu + 1, fn = 3 * (size_t)s->nu + 1;
        c->cr = malloc((3 * (size_t)mk + 1) * sizeof *c->cr);
        c->cb = malloc(cn * sizeof *c->cb);
        c->cd = malloc(cn * sizeof *c->cd);
        c->fd = malloc(fn * sizeof *c->fd);
        c->fq = malloc(fn * sizeof *c->fq);
        if (!c->targets || !c->pose || !c->y || !c->rot || !c->fine ||
            !c->scratch || !c->cr || !c->cb || !c->cd || !c->fd || !c->fq)
            st = oom(err, "coarse level");
    }
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

dk_status arap_coarse_start(dk_arap *ar, arap_system *s, const double **start, dk_error *err)
{
    arap_coarse *c = s->coarse;
    const dk_decimation *d = c->dec;
    const dk_index mk = d->n_kept;
    for (dk_index k = 0; k < c->n_handle_vertices; k++)
        memcpy(c->targets + 3 * (size_t)k, s->targets + 3 * (size_t)c->target_row[k],
               3 * sizeof *c->targets);
    const int posed = ar->base != ar->mesh->positions;
    if (posed)
        for (dk_index k = 0; k < mk; k++)
            memcpy(c->pose + 3 * (size_t)k, ar->base + 3 * (size_t)d->kept[k],
                   3 * sizeof *c->pose);
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
    for (dk_index i = 0; i < mk; i++) /* the coarse rotations in the coarse vertex order */
        memcpy(c->rot + 9 * (size_t)ca->ro->perm[i], ca->rot + 9 * (size_t)i,
               9 * sizeof *c->rot);
    dk_decimation_prolong(d, ar->base, c->y, c->rot, c->fine, c->scratch);
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
    const dk_decimation *d = c->dec;
    dk_arap *ca = c->arap;
    arap_system *cs = &ca->sys;
    const dk_index mk = d->n_kept, nu = s->nu, cnu = cs->nu;
    const size_t N = 3 * (size_t)nu;
    if (ar->opt.acceleration != DK_ARAP_ACCEL_NEWTON || cnu == 0)
        return DK_OK;
    /* 1. the fine residual r = -g, restricted: scattered to the vertices (0 where
     * eliminated), each removed vertex's share handed to its carriers in removal order
     * (the transpose of the linear prolongation), read at the kept vertices */
    double *r = s->nt_r, *acc = c->fine;
    dk_status st = arap_minus_gradient(ar, s, r);
    if (st != DK_OK)
        return st;
    memset(acc, 0, 3 * (size_t)ar->n * sizeof *acc);
    for (dk_index u = 0; u < nu; u++)
        for (int k = 0; k < 3; k++)
            acc[3 * (size_t)s->unknowns[u] + k] = r[(size_t)k * nu + u];
    for (dk_index k = 0; k < d->n_removed; k++) {
        const double *ru = acc + 3 * (size_t)d->removed[k];
        for (int i = 0; i < 3; i++) {
            double *rc = acc + 3 * (size_t)d->carrier[3 * (size_t)k + i];
            const double w = d->weight[3 * (size_t)k + i];
            rc[0] += w * ru[0], rc[1] += w * ru[1], rc[2] += w * ru[2];
        }
    }
    /* 2. the coarse iterate: the fine one at the kept vertices, taken as a given start by
     * a preview (the targets and pose restricted: its rotations, K^-1, right-hand side) */
    for (dk_index k = 0; k < c->n_handle_vertices; k++)
        memcpy(c->targets + 3 * (size_t)k, s->targets + 3 * (size_t)c->target_row[k],
               3 * sizeof *c->targets);
    const int posed = ar->base != ar->mesh->positions;
    for (dk_index k = 0; k < mk; k++) {
        const size_t v = 3 * (size_t)d->kept[k];
        memcpy(c->y + 3 * (size_t)k, ar->x + v, 3 * sizeof *c->y);
        if (posed)
            memcpy(c->pose + 3 * (size_t)k, ar->base + v, 3 * sizeof *c->pose);
    }
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
                c->cb[(size_t)k * cnu + cu] = acc[3 * (size_t)d->kept[ca->ro->perm[i]] + k];
    }
    st = arap_newton_direction(ca, cs, c->cb, c->cd, CORRECTION_CG, products, err);
    dk_team_park(ca->team);
    if (st != DK_OK)
        return st;
    /* 4. prolonged linearly (kept vertices take it, removed ones their carriers' blend),
     * read at the fine unknowns */
    memset(acc, 0, 3 * (size_t)ar->n * sizeof *acc);
    for (dk_index i = 0; i < ca->n; i++) {
        const dk_index cu = cs->unk[i];
        if (cu >= 0)
            for (int k = 0; k < 3; k++)
                acc[3 * (size_t)d->kept[ca->ro->perm[i]] + k] = c->cd[(size_t)k * cnu + cu];
    }
    for (dk_index k = d->n_removed - 1; k >= 0; k--) {
        double *du = acc + 3 * (size_t)d->removed[k];
        du[0] = du[1] = du[2] = 0.0;
        for (int i = 0; i < 3; i++) {
            const double *dc = acc + 3 * (size_t)d->carrier[3 * (size_t)k + i];
            const double w = d->weight[3 * (size_t)k + i];
            du[0] += w * dc[0], du[1] += w * dc[1], du[2] += w * dc[2];
        }
    }
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
