/* DeformKit embedded deformation: the Gauss-Newton solve (embedded_internal.h). */
#include "embedded_internal.h"

void ed_identity(double *x, dk_index m)
{
    static const double id[12] = {1, 0, 0, 0, 1, 0, 0, 0, 1, 0, 0, 0};
    for (dk_index j = 0; j < m; j++)
        memcpy(x + 12 * (size_t)j, id, sizeof id);
}

/* eq. 2 for every vertex; a vertex whose nodes are all constants is copied (the blend of
 * identities would give it back only to rounding) */
void ed_apply(const dk_embedded *ed, const double *x, double *out)
{
    const dk_index k = ed->k;
    const unsigned char *held_at_rest = ed->sys.con->held;
    for (dk_index v = 0; v < ed->n; v++) {
        const double *p = ed->p + 3 * v;
        int moving = 0;
        if (held_at_rest[v]) { /* loose geometry nothing constrains: at rest */
            memcpy(out + 3 * v, p, 3 * sizeof(double));
            continue;
        }
        for (dk_index q = 0; q < k; q++) {
            const dk_index j = ed->nb[(size_t)v * k + q];
            moving |= j >= 0 && ed->sys.node_unknown[j] >= 0;
        }
        if (!moving) {
            memcpy(out + 3 * v, p, 3 * sizeof(double));
            continue;
        }
        double o[3] = {0.0, 0.0, 0.0};
        for (dk_index q = 0; q < k; q++) {
            const dk_index j = ed->nb[(size_t)v * k + q];
            if (j < 0)
                continue;
            const double w = ed->w[(size_t)v * k + q], *R = x + 12 * (size_t)j;
            const double *g = ed->g + 3 * j;
            const double d[3] = {p[0] - g[0], p[1] - g[1], p[2] - g[2]};
            for (int c = 0; c < 3; c++)
                o[c] += w * (R[3 * c] * d[0] + R[3 * c + 1] * d[1] + R[3 * c + 2] * d[2] +
                             g[c] + R[9 + c]);
        }
        memcpy(out + 3 * v, o, sizeof o);
    }
}

static double inf_norm(const double *a, size_t n)
{
    double m = 0.0;
    for (size_t i = 0; i < n; i++)
        m = fmax(m, fabs(a[i]));
    return m;
}

/* |x|_inf of the transformations with t in units of ed->L (the unknowns of ed_evaluate()) */
static double x_norm(const dk_embedded *ed, const double *x)
{
    double m = 0.0;
    for (size_t i = 0; i < 12 * (size_t)ed->m; i++)
        m = fmax(m, fabs(x[i]) / (i % 12 >= 9 ? ed->L : 1.0));
    return m;
}

/* J^T f and E_rot's blocks with their spares */
static void swap_buffers(ed_system *s)
{
    double *g = s->grad, *r = s->rot;
    s->grad = s->grad_spare;
    s->rot = s->rot_spare;
    s->grad_spare = g;
    s->rot_spare = r;
}

/* One damped Gauss-Newton step (Levenberg-Marquardt with Nielsen's damping update, Madsen,
 * Nielsen & Tingleff 2004, the reference the paper gives): solves (J^T J + mu I) d = -J^T f
 * and compares the decrease of F with the one the linear model predicts,
 * rho = (F - F(x + d)) / (d . (mu d - J^T f)). A step with rho > 0 is taken and mu scaled by
 * max(1/3, 1 - (2 rho - 1)^3); otherwise mu grows by nu, which doubles on every refusal (at
 * most 30). mu starts at 0 (the plain Gauss-Newton step of eq. 11) and, at the first
 * refusal, at 1e-6 of J^T J's mean diagonal. *accepted: whether a step was taken. */
static dk_status gn_step(dk_embedded *ed, double F, double *mu, double *nu, double *F_new,
                         double *dnorm, int *accepted, dk_error *err)
{
    ed_system *s = &ed->sys;
    const size_t N = 12 * (size_t)s->n_free;
    const double trace = ed_reduced_trace(s);
    *accepted = 0;
    for (int attempt = 0; attempt < 30 && !*accepted; attempt++) {
        dk_status st = ed_reduced_factorize(s, *mu, ed->team, err);
        if (st == DK_OK) {
            ed->factorization_count++;
            st = ed_reduced_solve(s, err);
            if (st != DK_OK)
                return dk_error_prefix(err, "EmbeddedDeformation solve");
            memcpy(s->x_try, ed->x, 12 * (size_t)ed->m * sizeof(double));
            double pred = 0.0;
            for (dk_index u = 0; u < s->n_free; u++)
                for (int a = 0; a < 12; a++) { /* the step of t is in units of L */
                    const double d = s->step[12 * u + a];
                    s->x_try[12 * (size_t)s->free_nodes[u] + a] += a >= 9 ? ed->L * d : d;
                    pred += d * (*mu * d - s->grad[12 * u + a]);
                }
            /* F, J^T f and E_rot's blocks at the trial point, into the spare buffers: the
             * next step's if this one is taken */
            swap_buffers(s);
            const double Ft =
                ed_evaluate(ed, s, s, s->x_try, ED_GRADIENT | ED_MOVING) + s->f_constant;
            swap_buffers(s);
            const double rho = pred > 0.0 ? (F - Ft) / pred : (Ft < F ? 1.0 : -1.0);
            if (rho > 0.0 || (Ft == F && inf_norm(s->step, N) == 0.0)) {
                memcpy(ed->x, s->x_try, 12 * (size_t)ed->m * sizeof(double));
                swap_buffers(s);
                *F_new = Ft;
                *dnorm = inf_norm(s->step, N);
                *accepted = 1;
                const double c = 2.0 * rho - 1.0;
                *mu *= fmax(1.0 / 3.0, 1.0 - c * c * c);
                *nu = 2.0;
                return DK_OK;
            }
        } else if (st != DK_ERR_NOT_POSITIVE_DEFINITE) {
            return dk_error_prefix(err, "EmbeddedDeformation solve");
        }
        if (*mu > 0.0) {
            *mu *= *nu;
            *nu *= 2.0;
        } else {
            *mu = fmax(1e-6 * trace / (double)N, 1e-300);
        }
    }
    *F_new = F;
    *dnorm = 0.0;
    return DK_OK;
}

dk_status dk_embedded_solve(dk_embedded *ed, const dk_solve_request *rq, double *positions,
                            dk_solve_info *info, dk_error *err)
{
    if (info)
        memset(info, 0, sizeof *info);
    if (!ed || !positions)
        return dk_error_set(err, DK_ERR_INVALID_ARGUMENT,
                            "EmbeddedDeformation solve: object and positions must not be NULL");
    dk_status st = dk_solve_request_check(rq, "EmbeddedDeformation solve", err);
    if (st != DK_OK)
        return st;
    if (rq->start == DK_START_GIVEN) /* positions do not determine the graph's affine maps */
        return dk_error_set(err, DK_ERR_INVALID_ARGUMENT,
                            "EmbeddedDeformation solve: it cannot start from given positions "
                            "(its iterate is the graph's node transformations); use a cold or "
                            "warm start");
    ed_system *s = &ed->sys;
    st = dk_constraints_targets(s->con, ed->p, rq->targets, (int)rq->target_kind,
                                s->targets, err);
    if (st != DK_OK)
        return dk_error_prefix(err, "EmbeddedDeformation solve");
    if (rq->start == DK_START_COLD)
        ed_identity(ed->x, ed->m);
    if (s->k_stale) /* the source moved: K with it */
        ed_reduced_refresh(ed, s);
    const int maxit = rq->max_iterations > 0 ? rq->max_iterations : ed->opt.max_iterations;
    const double eps = ed->opt.tolerance;
    const size_t N = 12 * (size_t)s->n_free;
    /* the terms no free node enters do not change during the solve */
    s->f_constant = ed_evaluate(ed, NULL, s, ed->x, ED_CONSTANT);
    double F = ed_evaluate(ed, s, s, ed->x, ED_GRADIENT | ED_MOVING) + s->f_constant;
    double mu = 0.0, nu = 2.0;
    int it = 0;
    /* Eq. 12 as Gill, Murray & Wright give it (the paper's reference): converged when the
     * change of F, the gradient (grad F = 2 J^T f) and the step are all small, each against
     * 1 + its scale; or, before any step, when the gradient is already negligible in absolute
     * terms (their U4; eps^2 of the dimensionless F: a zero drag). The gradient test alone,
     * as an alternative, let a large F stop after 0 or 1 steps. */
    int converged = 2.0 * inf_norm(s->grad, N) <= eps * eps;
    double prev_dnorm = 0.0, prev_change = 0.0;
    while (!converged && it < maxit) {
        double F_new, dnorm;
        int accepted;
        st = gn_step(ed, F, &mu, &nu, &F_new, &dnorm, &accepted, err);
        if (st != DK_OK)
            return st;
        if (!accepted)
            break; /* no descent even with heavy damping: a stationary point for all we see */
        it++;
        const double change = fabs(F - F_new);
        F = F_new; /* gn_step left J^T f and E_rot's blocks at the new point */
        /* Gauss-Newton converges linearly here (a non-zero residual), often slowly where
         * the constraints conflict: a step and a decrease below the tests can leave many
         * more of about the same size to come (1.5e-3 of the model's size on the contract
         * grid, whose handles pull against its fixed row). So the tests read what remains,
         * extrapolated from the rate of the last two: x d / (1 - r), r the ratio of the step
         * norms (and of the decreases); a rate of 1 or more never passes. Our choice, in
         * the spirit of Gill et al.'s tests, which assume a step near the solution says how
         * near it is. */
        const double rate_d = prev_dnorm > 0.0 ? dnorm / prev_dnorm : 0.0;
        const double rate_f = prev_change > 0.0 ? change / prev_change : 0.0;
        const double left_d = rate_d < 1.0 ? dnorm / (1.0 - rate_d) : INFINITY;
        const double left_f = rate_f < 1.0 ? change / (1.0 - rate_f) : INFINITY;
        prev_dnorm = dnorm;
        prev_change = change;
        if (it >= 2 && left_f < eps * (1.0 + F) &&
            2.0 * inf_norm(s->grad, N) < cbrt(eps) * (1.0 + F) &&
            left_d < sqrt(eps) * (1.0 + x_norm(ed, ed->x)))
            converged = 1;
    }
    dk_team_park(ed->team); /* the helper sleeps until the next solve */
    ed_apply(ed, ed->x, positions);
    st = dk_solve_result_check(positions, ed->n, F, !rq->skip_energy,
                               "EmbeddedDeformation solve", err);
    if (st != DK_OK) { /* a non-finite end is no start: the next solve starts from rest */
        ed_identity(ed->x, ed->m);
        return st;
    }
    ed->energy = F;
    if (info) {
        info->energy = rq->skip_energy ? NAN : F; /* skipped: NaN, as the contract says */
        info->iterations = it;
        info->converged = converged;
    }
    return DK_OK;
}
