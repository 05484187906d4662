/* DeformKit ARAP: local/global iterations, plain or Anderson-accelerated (Peng et al.
 * 2018), with the energy safeguard (see arap_internal.h). */
#include "arap_internal.h"

/* Solves the m x m SPD system g theta = h in place (Cholesky, regularised); 0 on success. */
static int small_spd_solve(double *g, double *h, int m)
{
    double tr = 0.0;
    for (int i = 0; i < m; i++)
        tr += g[i * m + i];
    if (!(tr > 0.0) || !isfinite(tr))
        return -1;
    for (int i = 0; i < m; i++)
        g[i * m + i] += 1e-10 * tr / m;
    for (int j = 0; j < m; j++) {
        double d = g[j * m + j];
        for (int k = 0; k < j; k++)
            d -= g[j * m + k] * g[j * m + k];
        if (!(d > 0.0))
            return -1;
        d = sqrt(d);
        g[j * m + j] = d;
        for (int i = j + 1; i < m; i++) {
            double v = g[i * m + j];
            for (int k = 0; k < j; k++)
                v -= g[i * m + k] * g[j * m + k];
            g[i * m + j] = v / d;
        }
    }
    for (int i = 0; i < m; i++) {
        double v = h[i];
        for (int k = 0; k < i; k++)
            v -= g[i * m + k] * h[k];
        h[i] = v / g[i * m + i];
    }
    for (int i = m - 1; i >= 0; i--) {
        double v = h[i];
        for (int k = i + 1; k < m; k++)
            v -= g[k * m + i] * h[k];
        h[i] = v / g[i * m + i];
    }
    for (int i = 0; i < m; i++)
        if (!isfinite(h[i]))
            return -1;
    return 0;
}

/* Anderson's mix of the last `depth` (x, g) pairs into s->xu, from the global step's g in
 * s->gu and the current iterate in s->xu; updates the history (*hist pairs, the next slot
 * *head). Returns 1 when it mixed, 0 when the plain step stays (no history yet, or a
 * singular least-squares system). */
static int anderson_mix(const dk_arap *ar, arap_system *s, int *hist_io, int *head_io,
                        int *have_prev_pair_io)
{
    const size_t N = 3 * (size_t)s->nu;
    const int depth = ar->opt.anderson_depth;
    /* Gram matrix of the df slots, gram[i * MAX_ANDERSON_DEPTH + j] = df_i . df_j: only the
     * row of the slot written in an iteration changes */
    double *gram = s->aa_gram;
    int hist = *hist_io, head = *head_io, have_prev_pair = *have_prev_pair_io;
    int used_accel = 0;
    /* The vector passes are fused (each was memory-bound on its own): the residual,
     * the new difference pair and the saved pair in one pass; each slot's Gram entry
     * and its projection of the residual in one pass over the slot; the mix in one
     * pass (the same subtraction order as one pass per slot). */
    double h[MAX_ANDERSON_DEPTH];
    if (have_prev_pair) {
        double *dgc = s->dg + (size_t)head * N, *dfc = s->df + (size_t)head * N;
        for (size_t k = 0; k < N; k++) {
            const double gk = s->gu[k], fk = gk - s->xu[k];
            s->fu[k] = fk;
            dgc[k] = gk - s->gprev[k];
            dfc[k] = fk - s->fprev[k];
            s->gprev[k] = gk;
            s->fprev[k] = fk;
        }
        if (hist < depth)
            hist++;
        for (int j = 0; j < hist; j++)
            gram[head * MAX_ANDERSON_DEPTH + j] = gram[j * MAX_ANDERSON_DEPTH + head] =
                dot2(s->df + (size_t)j * N, dfc, s->fu, N, &h[j]);
        head = (head + 1) % depth;
    } else {
        for (size_t k = 0; k < N; k++) {
            const double gk = s->gu[k], fk = gk - s->xu[k];
            s->fu[k] = fk;
            s->gprev[k] = gk;
            s->fprev[k] = fk;
        }
        for (int j = 0; j < hist; j++) /* (hist is 0 here in practice) */
            (void)dot2(s->df + (size_t)j * N, s->fu, s->fu, N, &h[j]);
    }
    have_prev_pair = 1;
    if (hist > 0) {
        double g[MAX_ANDERSON_DEPTH * MAX_ANDERSON_DEPTH];
        for (int i = 0; i < hist; i++)
            for (int j = 0; j < hist; j++)
                g[i * hist + j] = gram[i * MAX_ANDERSON_DEPTH + j];
        if (small_spd_solve(g, h, hist) == 0) {
            const double *dgs[MAX_ANDERSON_DEPTH];
            for (int i = 0; i < hist; i++)
                dgs[i] = s->dg + (size_t)i * N;
            for (size_t k = 0; k < N; k++) {
                double xk = s->gu[k];
                for (int i = 0; i < hist; i++)
                    xk -= h[i] * dgs[i][k];
                s->xu[k] = xk;
            }
            used_accel = 1;
        }
    }
    *hist_io = hist;
    *head_io = head;
    *have_prev_pair_io = have_prev_pair;
    return used_accel;
}

dk_status arap_iterate_local_global(dk_arap *ar, arap_system *s, int maxit, arap_progress *p,
                                    dk_error *err)
{
    const size_t N = 3 * (size_t)s->nu;
    const int accel = ar->opt.acceleration == DK_ARAP_ACCEL_ANDERSON;
    const double tiny = p->tiny;
    double energy = p->energy;
    int it = p->iterations, converged = p->converged, rejected = p->rejected;
    int hist = s->aa_hist, head = s->aa_head, have_prev_pair = s->aa_have_pair;
    dk_status st;
    while (!converged && it < maxit) {
        it++;
        /* s->rhs: from the last local step, the one at the current iterate */
        st = dk_cholesky_solve(s->chol, s->rhs, 3, s->gu, err);
        if (st != DK_OK)
            return dk_error_prefix(err, "ARAP solve");
        int used_accel = accel && anderson_mix(ar, s, &hist, &head, &have_prev_pair);
        double e_new;
        if (used_accel) {
            arap_scatter(s, s->xu, ar->x);
            e_new = arap_local_energy(ar, s, ar->x, ar->rot);
            if (!(e_new <= energy)) { /* safeguard: plain step, forget the history */
                rejected++;
                hist = 0;
                head = 0;
                used_accel = 0;
            }
        }
        if (!used_accel) {
            memcpy(s->xu, s->gu, N * sizeof(double));
            arap_scatter(s, s->xu, ar->x);
            e_new = arap_local_energy(ar, s, ar->x, ar->rot);
        }
        arap_rotations_rhs(ar, s, ar->rot); /* the next global step's, at the kept iterate */
        converged = e_new <= tiny || (energy - e_new) <= ar->opt.tolerance * energy;
        energy = e_new;
        if (ar->opt.on_iteration && ar->opt.on_iteration(ar->opt.user, it, energy))
            return dk_error_set(err, DK_ERR_CANCELLED, "ARAP solve: cancelled by the observer");
    }
    s->aa_hist = hist;
    s->aa_head = head;
    s->aa_have_pair = have_prev_pair;
    p->energy = energy;
    p->iterations = it;
    p->converged = converged;
    p->rejected = rejected;
    return DK_OK;
}
