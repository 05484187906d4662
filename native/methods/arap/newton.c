/* DeformKit ARAP: inexact Newton steps with matrix-free exact Hessian products and
 * local/global-preconditioned conjugate gradients (see arap_internal.h). */
#include "arap_internal.h"

/* acceleration NEWTON. With R(x) the optimal rotations, E(x) = E(x, R(x)) and (envelope
 * theorem) half its gradient over the unknowns is g = A x - b(R(x)), the global step being
 * x - A^-1 g. Half its Hessian is H = A - db/dx with db(v) = sum_c dR_c g_{v,c} (the
 * right-hand-side map, linear in the rotations) and dR_c = R_c [w_c]x the first-order
 * response of cell c's rotation to the direction v: differentiating its optimality condition
 * skew(R^T S) = 0 gives w_c = -K_c^-1 skew(R_c^T dS_c), dS_c = the covariance of v, K_c as in
 * refine_rotation. With omega_c = R_c w_c, dR_c g = omega_c x (R_c g): the products read 3 + 3
 * numbers per map entry (R_c g is stored with each right-hand side). A Newton step solves
 * H d = -g approximately by preconditioned conjugate gradients, preconditioner A^-1 (the
 * bound factor), from d = 0: its first iterate is the local/global step; at most
 * cg_iterations Hessian products (ar->cg: as bound, scaled by the schedule, cg_level_after;
 * or as given to dk_arap_set_cg_iterations); a direction of non-positive curvature ends it (the first
 * one: the local/global step is used). Then a line search on E (t = 1, 1/2, 1/4, 1/8;
 * accept when E does not increase), and if it fails, the local/global step (which never
 * increases E). Far from a minimum (the local/global step promises more than NEWTON_FAR of
 * E) the local/global step is taken instead. Stopping test: at the first conjugate-gradient
 * iterate, the quadratic
 * model's decrease for the best step along the local/global direction (alpha_0 r_0.z_0) is
 * at most tolerance * E: the local/global test, predicted instead of taken; and the gap to
 * the minimum extrapolated from the last steps' decreases is too (gap_small), and the last
 * step's CG met no clearly negative curvature (nt_indefinite: E is not locally convex
 * there, and the decreases of such steps say nothing of the gap). Cells
 * whose K is not safely positive definite (degenerate) have their rotation held in H (a
 * positive semi-definite simplification, like Gauss-Newton). */

typedef struct hv_job {
    const dk_arap *ar;
    arap_system *s;
    const double *v;   /* rows: the vector, in the mesh layout (n x 3; only unknowns read)  */
    double *out;       /* rows: the result                                                   */
    const double *rhs; /* rows: non-NULL: out = rhs - A v (minus the gradient), else H v    */
    double dot[2];     /* rows: per half, v . out                                           */
} hv_job;

/* Cells [v0, v1) (a dk_range_fn): omega_c for the direction in s->vfull. */
static void hv_cells_part(void *ctx, dk_index v0, dk_index v1, int part)
{
    const hv_job *j = ctx;
    const dk_arap *ar = j->ar;
    const arap_system *s = j->s;
    (void)part;
    const double *x = s->vfull;
    for (dk_index i = v0; i < v1; i++) {
        double a[9] = {0, 0, 0, 0, 0, 0, 0, 0, 0};
        for (dk_index t = ar->cell_start[i]; t < ar->cell_start[i + 1]; t++) {
            const struct nt_term *q = s->ntt + t;
            const double *pa = x + 3 * (size_t)q->a, *pb = x + 3 * (size_t)q->b;
            const double w = q->w, e0 = q->e[0], e1 = q->e[1], e2 = q->e[2];
            const double d0 = w * (pa[0] - pb[0]), d1 = w * (pa[1] - pb[1]),
                         d2 = w * (pa[2] - pb[2]);
            a[0] += d0 * e0; a[1] += d0 * e1; a[2] += d0 * e2;
            a[3] += d1 * e0; a[4] += d1 * e1; a[5] += d1 * e2;
            a[6] += d2 * e0; a[7] += d2 * e1; a[8] += d2 * e2;
        }
        const double *r = ar->rot + 9 * (size_t)i, *k = s->kinv + 6 * (size_t)i;
        /* the skew part of M = r^T a, as in DK_NEWTON_STEP */
        const double m1 = r[0] * a[1] + r[3] * a[4] + r[6] * a[7];
        const double m2 = r[0] * a[2] + r[3] * a[5] + r[6] * a[8];
        const double m3 = r[1] * a[0] + r[4] * a[3] + r[7] * a[6];
        const double m5 = r[1] * a[2] + r[4] * a[5] + r[7] * a[8];
        const double m6 = r[2] * a[0] + r[5] * a[3] + r[8] * a[6];
        const double m7 = r[2] * a[1] + r[5] * a[4] + r[8] * a[7];
        const double g0 = m5 - m7, g1 = m6 - m2, g2 = m1 - m3;
        const double w0 = -(k[0] * g0 + k[1] * g1 + k[2] * g2);
        const double w1 = -(k[1] * g0 + k[3] * g1 + k[4] * g2);
        const double w2 = -(k[2] * g0 + k[4] * g1 + k[5] * g2);
        double *o = s->omega + 3 * (size_t)i;
        o[0] = r[0] * w0 + r[1] * w1 + r[2] * w2;
        o[1] = r[3] * w0 + r[4] * w1 + r[5] * w2;
        o[2] = r[6] * w0 + r[7] * w1 + r[8] * w2;
    }
}

/* Unknowns [u0, u1) (a dk_range_fn): out = rhs - A v, or H v = A v - sum omega_c x R_c g. */
static void hv_rows_part(void *ctx, dk_index u0, dk_index u1, int part)
{
    hv_job *j = ctx;
    const arap_system *s = j->s;
    const size_t nu = (size_t)s->nu;
    const double *v = j->v;
    double dot = 0.0;
    for (dk_index u = u0; u < u1; u++) {
        double b0 = 0.0, b1 = 0.0, b2 = 0.0;
        for (dk_index k = s->a.col_start[u]; k < s->a.col_start[u + 1]; k++) {
            const double av = s->a.values[k], *y = v + 3 * (size_t)s->a_vrow[k];
            b0 += av * y[0];
            b1 += av * y[1];
            b2 += av * y[2];
        }
        if (j->rhs) {
            b0 = j->rhs[u] - b0;
            b1 = j->rhs[nu + u] - b1;
            b2 = j->rhs[2 * nu + u] - b2;
        } else {
            for (int64_t k = s->rg_start[u]; k < s->rg_start[u + 1]; k++) {
                const float *h = s->nt[k].h;
                const double *o = s->omega + 3 * (size_t)s->nt[k].cell;
                b0 -= o[1] * h[2] - o[2] * h[1];
                b1 -= o[2] * h[0] - o[0] * h[2];
                b2 -= o[0] * h[1] - o[1] * h[0];
            }
        }
        j->out[u] = b0;
        j->out[nu + u] = b1;
        j->out[2 * nu + u] = b2;
        const double *y = v + 3 * (size_t)s->unknowns[u];
        dot += y[0] * b0 + y[1] * b1 + y[2] * b2;
    }
    j->dot[part] = dot;
}

/* The local/global step from the current iterate, x + A^-1 (b - A x) with z0 = that
 * correction (E cannot increase): moves s->xu and ar->x, returns the new energy (rotations
 * and K^-1 with it; the caller forms the right-hand side). */
static double local_global_step(const dk_arap *ar, arap_system *s, const double *z0)
{
    const size_t N = 3 * (size_t)s->nu;
    for (size_t i = 0; i < N; i++)
        s->xu[i] += z0[i];
    arap_scatter(s, s->xu, ar->x);
    return arap_local_energy(ar, s, ar->x, ar->rot);
}

/* One Newton step from the current iterate (s->xu = ar->x on the unknowns, with its
 * rotations, K^-1, right-hand side and R_c g; energy `energy`), or the finding that it has
 * converged (*newton_converged = 1, nothing moves). Else the new iterate with all of those,
 * its energy in *e_new. Counters: *rejected (line search failed), *cg_total (products). */
/* Element-wise CG vector updates over the unknowns [u0, u1) of all three coordinate blocks
 * (a dk_range_fn), so that they run on the team like the products: each is a pass over
 * 3 nu doubles that left the helper idle. Element-wise, so the split changes nothing. */
typedef struct vec_job {
    const arap_system *s;
    int op;           /* VEC_STEP, VEC_DIRECTION or VEC_TRIAL                            */
    double a;         /* alpha, beta or t                                                */
    double *y, *w;    /* STEP: d, r;  DIRECTION: p;  TRIAL: gu                           */
    const double *u, *v; /* STEP: p, q;  DIRECTION: z;  TRIAL: xu, d                     */
    double *full;     /* DIRECTION, TRIAL: n x 3 row-major, receives the scattered result */
} vec_job;

enum { VEC_STEP, VEC_DIRECTION, VEC_TRIAL };

static void vec_part(void *ctx, dk_index u0, dk_index u1, int part)
{
    const vec_job *j = ctx;
    const arap_system *s = j->s;
    const size_t nu = (size_t)s->nu;
    const double a = j->a;
    (void)part;
    for (int c = 0; c < 3; c++) {
        const size_t o = (size_t)c * nu;
        if (j->op == VEC_STEP) { /* d += alpha p, r -= alpha q */
            for (size_t i = o + (size_t)u0; i < o + (size_t)u1; i++) {
                j->y[i] += a * j->u[i];
                j->w[i] -= a * j->v[i];
            }
        } else if (j->op == VEC_DIRECTION) { /* p = z + beta p, scattered */
            for (dk_index u = u0; u < u1; u++) {
                const double v = j->u[o + (size_t)u] + a * j->y[o + (size_t)u];
                j->y[o + (size_t)u] = v;
                j->full[3 * (size_t)s->unknowns[u] + (size_t)c] = v;
            }
        } else { /* gu = xu + t d, scattered */
            for (dk_index u = u0; u < u1; u++) {
                const double v = j->u[o + (size_t)u] + a * j->v[o + (size_t)u];
                j->y[o + (size_t)u] = v;
                j->full[3 * (size_t)s->unknowns[u] + (size_t)c] = v;
            }
        }
    }
}

/* The second half of the stopping test: the gap to the minimum extrapolated from the last
 * step's decrease, at most `bound`. Near the minimum of a large mesh the steps shrink
 * linearly (the slow bending modes: ratio 0.80-0.88 per step at 173k vertices), and the
 * first-iterate test alone then stops 10-100x the tolerance above the minimum (measured:
 * docs/methods/arap.md, "Where the stopping test stops"). With decreases shrinking by rho
 * per step, what is left after a step of decrease d is d (rho + rho^2 + ...) =
 * d rho / (1 - rho). The paper has no stopping test; our choices, each from the 43k/173k
 * step-by-step traces of that section: the rate is the geometric mean of the last two
 * measured ratios, the per-step rate over two steps (truncated-CG Newton steps alternate
 * long and short ones at 43k: 2.5, then 0.03, where the larger alone would call a fast
 * solve stalled), rho the larger of it and of the rate the solve before ended with (a
 * drag's first steps shrink fast, 0.01 then 0.13, before the slow modes set the rate again:
 * that rate is the mesh's, not the drag's); capped at RATIO_CAP so that decreases that do
 * not shrink still stop once d is small. Nothing measured (a cold start's first two
 * steps): the first-iterate test alone. */
#define RATIO_CAP 0.99
static double rate(const arap_system *s)
{
    return s->nt_ratio[1] > 0.0 ? sqrt(s->nt_ratio[0] * s->nt_ratio[1]) : s->nt_ratio[0];
}

static int gap_small(const arap_system *s, double bound)
{
    double rho = rate(s);
    if (s->nt_ratio_before > rho)
        rho = s->nt_ratio_before;
    if (!(s->nt_decrease > 0.0 && rho > 0.0))
        return 1;
    if (rho > RATIO_CAP)
        rho = RATIO_CAP;
    return s->nt_decrease * rho / (1.0 - rho) <= bound;
}

/* After a step that took E from `energy` to `e_new`: the decreases gap_small extrapolates. */
static void record_decrease(arap_system *s, double energy, double e_new)
{
    const double d = energy - e_new;
    if (!(d > 0.0))
        return;
    if (s->nt_decrease > 0.0) {
        s->nt_ratio[1] = s->nt_ratio[0];
        s->nt_ratio[0] = d / s->nt_decrease;
    }
    s->nt_decrease = d;
}

void arap_gap_restart(arap_system *s, int cold)
{
    const double r = rate(s);
    if (cold)
        s->nt_ratio_before = 0.0;
    else if (r > 0.0)
        s->nt_ratio_before = r;
    s->nt_decrease = s->nt_ratio[0] = s->nt_ratio[1] = 0.0;
    s->nt_indefinite = 0;
}

/* A CG iteration whose curvature p.Hp is below -NEGATIVE_CURVATURE times r.z (the
 * preconditioned residual's norm, so the ratio is of the order of a Rayleigh quotient of
 * A^-1 H, in (0, 1] where E is convex) sets s->nt_indefinite. Far below rounding: the
 * products read the cell data in float (~1e-7 relative), and a closed mesh with nothing
 * fixed has an exactly flat direction (its rigid rotation) that must not count. The
 * measured ones are -5e-3 to -3.4 (the 692k armadillo). */
#define NEGATIVE_CURVATURE 1e-6

static dk_status newton_step(dk_arap *ar, arap_system *s, double energy, double *e_new,
                             int *newton_converged, int *far, int *rejected, int *cg_total,
                             dk_error *err)
{
    const dk_index nu = s->nu;
    const size_t N = 3 * (size_t)nu;
    const int par = ar->n_terms >= PARALLEL_TERMS;
    const dk_index cells_min = par ? 0 : ar->nc + 1, rows_min = par ? 0 : nu + 1;
    double *r = s->nt_r, *z = s->nt_z, *p = s->nt_p, *q = s->nt_q, *d = s->nt_d;
    double *z0 = s->nt_z0, ignored;
    const int whole = ar->cg >= ar->opt.cg_iterations;
    const int cg = ar->cg_scheduled && ar->opt.cg_schedule == DK_ARAP_CG_GROWING
                       ? ar->cg << s->cg_level
                       : ar->cg;
    *newton_converged = 0;
    *far = 0;
    hv_job job = {ar, s, ar->x, r, s->rhs, {0.0, 0.0}};
    dk_team_run_halves(ar->team, hv_rows_part, &job, nu, rows_min); /* r = -g */
    dk_status st = dk_cholesky_solve(s->chol, r, 3, z0, err);
    if (st != DK_OK)
        return st;
    double rz = dot2(r, z0, z0, N, &ignored);
    const double rz0 = rz;
    if (rz0 > NEWTON_FAR * energy) { /* far from a minimum: the local/global step */
        *far = 1;
        *e_new = local_global_step(ar, s, z0);
        arap_rotations_rhs(ar, s, ar->rot);
        s->nt_indefinite = 0;
        return DK_OK;
    }
    int indefinite = 0;
    memcpy(p, z0, N * sizeof(double));
    memset(d, 0, N * sizeof(double));
    arap_scatter(s, p, s->vfull);
    job.v = s->vfull;
    job.out = q;
    job.rhs = NULL;
    for (int k = 0; k < cg; k++) {
        dk_team_run_halves(ar->team, hv_cells_part, &job, ar->nc, cells_min);
        dk_team_run_halves(ar->team, hv_rows_part, &job, nu, rows_min);
        (*cg_total)++;
        const double pq = job.dot[0] + job.dot[1];
        if (!(pq > 0.0) || !(rz > 0.0)) {
            indefinite = pq < -NEGATIVE_CURVATURE * rz;
            if (k == 0) /* non-positive curvature at once: the local/global step */
                memcpy(d, p, N * sizeof(double));
            break;
        }
        const double alpha = rz / pq;
        /* The stopping test, on the first iterate: alpha rz0 is the decrease of the
         * quadratic model for the best step along the local/global direction, which is at
         * least what a local/global step would achieve; at most tolerance * E: converged,
         * the local/global test predicted instead of taken, when the extrapolated gap is
         * small too (gap_small: what makes tolerance bound the energy left above the
         * minimum, which the local/global solvers' per-step test does not), and when the
         * last step met no clear negative curvature (nt_indefinite). Nothing moves. */
        if (k == 0 && alpha * rz <= ar->opt.tolerance * energy && !s->cut &&
            !s->nt_indefinite && gap_small(s, ar->opt.tolerance * energy)) {
            *newton_converged = 1;
            *e_new = energy;
            return DK_OK;
        } /* (after cut steps the step is taken: the test counts again after a whole one) */
        {
            vec_job vj = {s, VEC_STEP, alpha, d, r, p, q, NULL};
            dk_team_run_halves(ar->team, vec_part, &vj, nu, rows_min);
        }
        if (k + 1 == cg)
            break;
        st = dk_cholesky_solve(s->chol, r, 3, z, err);
        if (st != DK_OK)
            return st;
        const double rzn = dot2(r, z, z, N, &ignored);
        if (!(rzn > 1e-24 * rz0))
            break; /* solved to rounding */
        const double beta = rzn / rz;
        {
            vec_job vj = {s, VEC_DIRECTION, beta, p, NULL, z, NULL, s->vfull};
            dk_team_run_halves(ar->team, vec_part, &vj, nu, rows_min);
        }
        rz = rzn;
    }
    /* line search on E; its last evaluation is the kept iterate's local step */
    double t = 1.0, e = NAN;
    int accepted = 0;
    for (int ls = 0; ls < 4 && !accepted; ls++) {
        if (ls > 0)
            t *= 0.5;
        {
            vec_job vj = {s, VEC_TRIAL, t, s->gu, NULL, s->xu, d, ar->x};
            dk_team_run_halves(ar->team, vec_part, &vj, nu, rows_min);
        }
        e = arap_local_energy(ar, s, ar->x, ar->rot);
        accepted = e <= energy;
    }
    if (accepted) {
        memcpy(s->xu, s->gu, N * sizeof(double));
    } else { /* the line search failed: the local/global step */
        (*rejected)++;
        e = local_global_step(ar, s, z0);
    }
    arap_rotations_rhs(ar, s, ar->rot);
    s->cut = !whole;
    s->nt_indefinite = indefinite;
    *e_new = e;
    return DK_OK;
}


dk_status arap_minus_gradient(dk_arap *ar, arap_system *s, double *out)
{
    const int par = ar->n_terms >= PARALLEL_TERMS;
    hv_job job = {ar, s, ar->x, out, s->rhs, {0.0, 0.0}};
    dk_team_run_halves(ar->team, hv_rows_part, &job, s->nu, par ? 0 : s->nu + 1);
    return DK_OK;
}

double arap_hessian_product(dk_arap *ar, arap_system *s, const double *v, double *out)
{
    const int par = ar->n_terms >= PARALLEL_TERMS;
    arap_scatter(s, v, s->vfull);
    hv_job job = {ar, s, s->vfull, out, NULL, {0.0, 0.0}};
    dk_team_run_halves(ar->team, hv_cells_part, &job, ar->nc, par ? 0 : ar->nc + 1);
    dk_team_run_halves(ar->team, hv_rows_part, &job, s->nu, par ? 0 : s->nu + 1);
    return job.dot[0] + job.dot[1];
}

dk_status arap_newton_direction(dk_arap *ar, arap_system *s, const double *rhs, double *out,
                                int maxit, int *products, dk_error *err)
{
    const size_t N = 3 * (size_t)s->nu;
    double *r = s->nt_r, *z = s->nt_z, *p = s->nt_p, *q = s->nt_q, ignored;
    memcpy(r, rhs, N * sizeof(double));
    memset(out, 0, N * sizeof(double));
    dk_status st = dk_cholesky_solve(s->chol, r, 3, z, err);
    if (st != DK_OK)
        return st;
    double rz = dot2(r, z, z, N, &ignored);
    const double rz0 = rz;
    memcpy(p, z, N * sizeof(double));
    for (int k = 0; k < maxit && rz > 1e-24 * rz0 && rz > 0.0; k++) {
        const double pq = arap_hessian_product(ar, s, p, q);
        (*products)++;
        if (!(pq > 0.0)) {
            if (k == 0) /* non-positive curvature at once: the preconditioned direction */
                memcpy(out, p, N * sizeof(double));
            break;
        }
        const double alpha = rz / pq;
        for (size_t i = 0; i < N; i++) {
            out[i] += alpha * p[i];
            r[i] -= alpha * q[i];
        }
        if (k + 1 == maxit)
            break;
        if ((st = dk_cholesky_solve(s->chol, r, 3, z, err)) != DK_OK)
            return st;
        const double rzn = dot2(r, z, z, N, &ignored), beta = rzn / rz;
        for (size_t i = 0; i < N; i++)
            p[i] = z[i] + beta * p[i];
        rz = rzn;
    }
    return DK_OK;
}

/* The CG schedule (dk_arap_cg_schedule GROWING) after a step that took E from `energy` to
 * `e_new`: level 0 (cg_iterations) while a step gains more than 1e-3 of E, 1 (twice) down to
 * 1e-5, 2 (four times) below. The thresholds are the tenth session's (173k armadillo); the
 * eleventh's measurements, why it is opt-in: docs/methods/arap.md, "A CG count that grows". */
static int cg_level_after(double energy, double e_new)
{
    const double gain = energy > 0.0 ? (energy - e_new) / energy : 0.0;
    return gain > 1e-3 ? 0 : gain > 1e-5 ? 1 : 2;
}

dk_status arap_iterate_newton(dk_arap *ar, arap_system *s, int maxit, arap_progress *p,
                              dk_error *err)
{
    const double tiny = p->tiny;
    double energy = p->energy;
    int it = p->iterations, converged = p->converged, rejected = p->rejected;
    int cg_total = p->cg_total;
    dk_status st;
    while (!converged && it < maxit) {
        it++;
        double e_new;
        int newton_converged, far;
        st = newton_step(ar, s, energy, &e_new, &newton_converged, &far, &rejected, &cg_total,
                         err);
        /* near a minimum only, where Newton steps are taken: far from one, the local/global
         * steps keep to the basin they descend into (NEWTON_FAR), and a long correction
         * there can leave it (measured: a tube bent by 90 degrees, 91 coarse vertices, a
         * minimum 0.2% higher and 8% of the diagonal away) */
        if (st == DK_OK && !newton_converged && !far && s->coarse && s->coarse_active)
            st = arap_coarse_correct(ar, s, &e_new, &cg_total, err);
        if (st != DK_OK)
            return dk_error_prefix(err, "ARAP solve");
        /* or a step that did not lower E at all (rounding level: stagnation) */
        converged = e_new <= tiny || newton_converged || (energy - e_new) <= 0.0;
        if (!newton_converged) {
            s->cg_level = cg_level_after(energy, e_new);
            record_decrease(s, energy, e_new);
        }
        energy = e_new;
        if (ar->opt.on_iteration && ar->opt.on_iteration(ar->opt.user, it, energy))
            return dk_error_set(err, DK_ERR_CANCELLED, "ARAP solve: cancelled by the observer");
    }
    p->energy = energy;
    p->iterations = it;
    p->converged = converged;
    p->rejected = rejected;
    p->cg_total = cg_total;
    return DK_OK;
}
