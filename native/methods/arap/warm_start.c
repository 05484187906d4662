/* DeformKit ARAP: where a solve starts, and the history its drag predictor keeps (see
 * arap_internal.h). */
#include "arap_internal.h"

/* Eliminated vertices at their targets (hard handles) or the base (the rest, or the
 * request's input); the unknowns at `from`. */
static void place_known(dk_arap *ar, arap_system *s, const double *from)
{
    const dk_index n = ar->n;
    const double *rest = ar->base;
    if (from != ar->x)
        memcpy(ar->x, from, 3 * (size_t)n * sizeof(double));
    for (dk_index v = 0; v < n; v++)
        if (s->unk[v] < 0)
            for (int d = 0; d < 3; d++)
                ar->x[3 * v + d] =
                    s->target_of[v] >= 0 ? s->targets[3 * s->target_of[v] + d] : rest[3 * v + d];
}

/* Identity rotations. They also start the local steps' refinement (cells_energy), so that
 * a cold or given solve depends on its input only, bit for bit, whatever was solved before. */
static void identity_rotations(dk_arap *ar)
{
    static const double id[9] = {1, 0, 0, 0, 1, 0, 0, 0, 1};
    for (dk_index v = 0; v < ar->nc; v++)
        memcpy(ar->rot + 9 * (size_t)v, id, sizeof id);
}

/* The cold start: the global step with identity rotations (naive Laplacian editing). */
static dk_status start_cold(dk_arap *ar, arap_system *s, dk_error *err)
{
    identity_rotations(ar);
    arap_rotations_rhs(ar, s, ar->rot);
    dk_status st = dk_cholesky_solve(s->chol, s->rhs, 3, s->gu, err);
    if (st != DK_OK)
        return dk_error_prefix(err, "ARAP solve");
    arap_scatter(s, s->gu, ar->x);
    return DK_OK;
}

/* The predictor's step along the drag: alpha = the projection of the new targets' step
 * t - t1 onto the last step t1 - t2, clamped to [0, 2]; 0 without two ends to go by. */
static double drag_alpha(const dk_arap *ar, const arap_system *s)
{
    const size_t nhv3 = 3 * (size_t)s->con->n_handle_vertices;
    double alpha = 0.0;
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
    return alpha;
}

/* The warm start's responses by back-substitution: the border terms' moves, then one solve
 * of 3 (plain) or 6 (and predicted) columns into s->warm (zeroed by the caller). */
static dk_status substituted_response(dk_arap *ar, arap_system *s, double alpha, int predict,
                                      int *moved_out, dk_error *err)
{
    const dk_index nu = s->nu;
    const size_t N3 = 3 * (size_t)nu;
    const double *x1 = ar->prev, *x2 = ar->prev2;
    double *w = s->warm;
    int moved = 0;
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
        const dk_status st = dk_cholesky_solve(s->chol, w, predict ? 6 : 3, w, err);
        if (st != DK_OK)
            return dk_error_prefix(err, "ARAP solve");
    }
    *moved_out = moved;
    return DK_OK;
}

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
static dk_status start_warm(dk_arap *ar, arap_system *s, int lazy, double *energy,
                            int *have_energy, dk_error *err)
{
    dk_status st;
    const dk_index nu = s->nu;
    const double *x1 = ar->prev, *x2 = ar->prev2;
    const double alpha = drag_alpha(ar, s);
    int moved = 0;
    const int predict = alpha > 0.0;
    const size_t N3 = 3 * (size_t)nu;
    double *w = s->warm; /* columns 0-2: plain response; 3-5: predicted one */
    if (arap_response_basis_apply(ar, s, x1, x2, alpha, predict, w)) {
        moved = 1; /* combined from the bind's columns: no back-substitution */
    } else {
        memset(w, 0, (predict ? 2 : 1) * N3 * sizeof(double));
        st = substituted_response(ar, s, alpha, predict, &moved, err);
        if (st != DK_OK)
            return st;
    }
    /* the plain start (ar->x holds the previous solution on the unknowns) */
    if (moved)
        for (dk_index u = 0; u < nu; u++)
            for (int d = 0; d < 3; d++)
                ar->x[3 * s->unknowns[u] + d] += w[(size_t)d * nu + u];
    if (predict && lazy) {
        /* a preview: the two starts compared on a fixed sample of ~PREVIEW_SAMPLE cells
         * (all of them on small meshes; on two threads) instead of two passes over every
         * cell (~0.2 s at 692k vertices, five times the rest of the start): on the
         * 692k armadillo's first drag step after a converged solve, taking the predictor
         * unchecked gave 1.10x the step's minimum (docs/methods/arap.md, "Preview"). */
        const dk_index stride = ar->nc > PREVIEW_SAMPLE ? ar->nc / PREVIEW_SAMPLE : 1;
        const double e_plain = arap_sampled_energy(ar, s, ar->x, stride);
        arap_gather(s, ar->x, s->xu); /* keep the plain start */
        for (dk_index u = 0; u < nu; u++)
            for (int d = 0; d < 3; d++) {
                const size_t k = 3 * (size_t)s->unknowns[u] + (size_t)d;
                ar->x[k] = x1[k] + alpha * (x1[k] - x2[k]) + w[N3 + (size_t)d * nu + u];
            }
        if (arap_sampled_energy(ar, s, ar->x, stride) <= e_plain)
            s->predicted = 1;
        else
            arap_scatter(s, s->xu, ar->x);
    } else if (predict) {
        const double e_plain = arap_local_energy(ar, s, ar->x, ar->rot);
        arap_gather(s, ar->x, s->xu); /* keep the plain start */
        for (dk_index u = 0; u < nu; u++)
            for (int d = 0; d < 3; d++) {
                const size_t k = 3 * (size_t)s->unknowns[u] + (size_t)d;
                ar->x[k] = x1[k] + alpha * (x1[k] - x2[k]) + w[N3 + (size_t)d * nu + u];
            }
        const double e_pred = arap_local_energy(ar, s, ar->x, ar->rot);
        if (e_pred <= e_plain) {
            s->predicted = 1;
            *energy = e_pred;
        } else {
            arap_scatter(s, s->xu, ar->x);
            *energy = arap_local_energy(ar, s, ar->x, ar->rot);
        }
        *have_energy = 1;
    }
    return DK_OK;
}

dk_status arap_start(dk_arap *ar, arap_system *s, const double *given, int given_internal,
                     int warm, int lazy, double *energy_out, dk_error *err)
{
    double energy = 0.0;
    int have_energy = 0;
    dk_status st = DK_OK;
    s->predicted = 0;
    if (given) /* the caller's iterate: no previous solution, no preview of one */
        warm = lazy = 0;
    if (!warm) { /* a cold start remembers nothing of the cut steps or ratios (newton.c) */
        s->cut = 0;
        arap_gap_restart(s, 1);
    }
    if (given) { /* the given positions, constrained vertices in place, their rotations */
        if (given_internal)
            memcpy(ar->x, given, 3 * (size_t)ar->n * sizeof *ar->x);
        else
            dk_reorder_rows_in(ar->ro, given, ar->x);
        identity_rotations(ar);
    }
    place_known(ar, s, given ? ar->x : warm ? ar->prev : ar->base);
    if (!(lazy && warm)) /* a lazy warm start needs it only in arap_start_complete */
        arap_build_rhs_const(ar, s, ar->x);
    if (warm)
        st = start_warm(ar, s, lazy, &energy, &have_energy, err);
    else if (!given)
        st = start_cold(ar, s, err);
    if (st != DK_OK)
        return st;
    s->aa_hist = s->aa_head = s->aa_have_pair = 0;
    if (lazy) { /* the local step waits for the iterations (arap_start_complete) */
        arap_gather(s, ar->x, s->xu);
        s->start_pending = 1;
        *energy_out = NAN;
        return DK_OK;
    }
    s->start_pending = 0;
    if (!have_energy)
        energy = arap_local_energy(ar, s, ar->x, ar->rot);
    arap_rotations_rhs(ar, s, ar->rot);
    if (ar->opt.on_iteration && ar->opt.on_iteration(ar->opt.user, 0, energy))
        return dk_error_set(err, DK_ERR_CANCELLED, "ARAP solve: cancelled by the observer");
    arap_gather(s, ar->x, s->xu);
    *energy_out = energy;
    return DK_OK;
}

dk_status arap_start_complete(dk_arap *ar, arap_system *s, double *energy_out, dk_error *err)
{
    arap_build_rhs_const(ar, s, ar->x); /* from the eliminated vertices, which are in place */
    const double energy = arap_local_energy(ar, s, ar->x, ar->rot);
    arap_rotations_rhs(ar, s, ar->rot);
    s->start_pending = 0;
    *energy_out = energy;
    if (ar->opt.on_iteration && ar->opt.on_iteration(ar->opt.user, 0, energy))
        return dk_error_set(err, DK_ERR_CANCELLED, "ARAP solve: cancelled by the observer");
    return DK_OK;
}

void arap_keep_history(dk_arap *ar, arap_system *s, int warm_start)
{
    const size_t nhv3 = 3 * (size_t)s->con->n_handle_vertices;
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
    memcpy(ar->prev, ar->x, 3 * (size_t)ar->n * sizeof(double));
    ar->have_prev = 1;
    memcpy(s->targets_prev, s->targets, nhv3 * sizeof(double));
}
