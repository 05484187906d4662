/* DeformKit ARAP: the warm start's response basis (see arap_internal.h).
 *
 * A warm start spreads the move of the eliminated vertices over the unknowns by one global
 * step with the previous rotations held (warm_start.c):
 *     w_d = A^-1 r_d,   r_d[u] = sum over the border terms t (u, k), k eliminated, of
 *                                tws_t dx_{k,d},
 * with dx the move of k from the start's base. That is linear in dx. When each hard handle
 * moved by an affine map of its rest positions, dx_k = T_h [p_k; 1] (a drag by translation,
 * rotation or scale: what the add-on sends, and what a caller's per-vertex targets of such a
 * drag are), and the fixed vertices did not move, then
 *     w_d = sum_h sum_{j<4} T_h[d][j] Z_{h,j},   Z_{h,j} = A^-1 r_{h,j},
 *     r_{h,j}[u] = sum over the border terms t (u, k), k a hard vertex of handle h, of
 *                  tws_t q_j(k),   q = (x, y, z, 1) of k's rest position,
 * so bind solves the 4 columns per handle once and a warm start combines them in O(n)
 * instead of back-substituting 3 or 6 columns through the factor (at 692k vertices ~0.7 s
 * against a few ms). This is ours, the same idea as Laplacian editing's affine basis
 * (docs/methods/laplacian_edit.md) applied to ARAP's global step. Starts that do not fit
 * (non-affine per-vertex targets, a fixed vertex moved by a rebind, more handles or columns
 * than the limits) back-substitute as before; a fitted start differs from the substituted one
 * by the response to the fit's misfit (1e-13 of the coordinates), and the iterations that
 * follow do not depend on it beyond rounding. */
#include "arap_internal.h"

/* At most this many handles (4 columns each) and this many doubles (128 MB) in the basis. */
enum { ARAP_MAX_BASIS_HANDLES = 16 };
#define ARAP_MAX_BASIS_DOUBLES 16.0e6
/* An affine map per handle must reproduce the moves to this fraction of the coordinates. */
#define ARAP_FIT_TOLERANCE 1e-13

void arap_response_basis_free(arap_system *s)
{
    free(s->zb);
    free(s->zverts);
    free(s->zstart);
    free(s->zdx);
    free(s->zfit);
    s->zb = s->zdx = s->zfit = NULL;
    s->zverts = s->zstart = NULL;
    s->zcols = 0;
}

void arap_response_basis_build(dk_arap *ar, arap_system *s)
{
    const dk_constraints *c = s->con;
    const dk_index n = ar->n, nu = s->nu, H = c->n_handles;
    const double *rest = ar->mesh->positions;
    dk_error ignored = {0};

    arap_response_basis_free(s);
    if (ar->opt.basis == DK_ARAP_BASIS_OFF || nu == 0 || H == 0 ||
        H > ARAP_MAX_BASIS_HANDLES || 4.0 * (double)H * (double)nu > ARAP_MAX_BASIS_DOUBLES)
        return;
    const size_t ncol = 4 * (size_t)H;
    s->zb = calloc(ncol * (size_t)nu, sizeof(double));
    s->zverts = malloc(((size_t)c->n_handle_vertices + 1) * sizeof *s->zverts);
    s->zstart = malloc(((size_t)H + 1) * sizeof *s->zstart);
    s->zdx = malloc((3 * (size_t)c->n_handle_vertices + 1) * sizeof(double));
    s->zfit = malloc(2 * 16 * (size_t)H * sizeof(double));
    if (!s->zb || !s->zverts || !s->zstart || !s->zdx || !s->zfit) {
        arap_response_basis_free(s); /* the basis is only a speed-up: starts substitute */
        return;
    }
    /* the hard (eliminated) vertices of each handle, in handle order */
    dk_index m = 0;
    for (dk_index h = 0; h < H; h++) {
        s->zstart[h] = m;
        for (dk_index k = c->handle_start[h]; k < c->handle_start[h + 1]; k++)
            if (s->unk[c->handle_vertices[k]] < 0)
                s->zverts[m++] = c->handle_vertices[k];
    }
    s->zstart[H] = m;
    /* r_{h,j}: the border terms whose eliminated end is a hard handle vertex */
    for (int64_t bt = 0; bt < s->n_bterms; bt++) {
        const int64_t t = s->bterms[bt];
        const dk_index a = ar->ta[t], b = ar->tb[t];
        const dk_index ua = s->unk[a], ub = s->unk[b];
        const dk_index u = ua >= 0 ? ua : ub, known = ua >= 0 ? b : a;
        const dk_index h = c->role[known];
        if (h < 0)
            continue; /* fixed: its move must be zero for the basis to apply */
        double *col = s->zb + 4 * (size_t)h * (size_t)nu;
        for (int j = 0; j < 3; j++)
            col[(size_t)j * nu + (size_t)u] += s->tws[t] * rest[3 * (size_t)known + (size_t)j];
        col[3 * (size_t)nu + (size_t)u] += s->tws[t];
    }
    if (dk_cholesky_solve(s->chol, s->zb, (int)ncol, s->zb, &ignored) != DK_OK) {
        arap_response_basis_free(s);
        return;
    }
    s->zcols = (int)ncol;
    (void)n;
}

/* Whether the move of the eliminated vertices from the base `b0 + alpha (b0 - b1)` (b1 may be
 * NULL: alpha unused) to ar->x is one affine map per handle (into fit, 16 per handle) with the
 * fixed vertices unmoved. */
static int fit_moves(const dk_arap *ar, arap_system *s, const double *b0, const double *b1,
                     double alpha, double *fit)
{
    const dk_constraints *c = s->con;
    const double *x = ar->x;
#define BASE(k) (b1 ? b0[k] + alpha * (b0[k] - b1[k]) : b0[k])
    for (int64_t bt = 0; bt < s->n_bterms; bt++) {
        const int64_t t = s->bterms[bt];
        const dk_index a = ar->ta[t], b = ar->tb[t];
        const dk_index known = s->unk[a] >= 0 ? b : a;
        if (c->role[known] >= 0)
            continue;
        for (int d = 0; d < 3; d++) {
            const size_t k = 3 * (size_t)known + (size_t)d;
            if (x[k] - BASE(k) != 0.0)
                return 0;
        }
    }
    /* fitted as images p + dx of the rest positions p, so that a translation is found
     * exactly however few or flat the handle's vertices (dk_affine_fit tries it first); the
     * columns combine the move's map, T - I */
    const double *rest = ar->mesh->positions;
    for (dk_index i = 0; i < s->zstart[c->n_handles]; i++)
        for (int d = 0; d < 3; d++) {
            const size_t k = 3 * (size_t)s->zverts[i] + (size_t)d;
            s->zdx[3 * (size_t)i + (size_t)d] = rest[k] + (x[k] - BASE(k));
        }
#undef BASE
    for (dk_index h = 0; h < c->n_handles; h++) {
        const dk_index k0 = s->zstart[h], k1 = s->zstart[h + 1];
        double *T = fit + 16 * (size_t)h;
        if (!dk_affine_fit(rest, s->zverts + k0, k1 - k0, s->zdx + 3 * (size_t)k0,
                           ARAP_FIT_TOLERANCE, T))
            return 0;
        if (k1 > k0) /* (an all-soft handle: the zero map, and no columns to combine) */
            T[0] -= 1.0, T[5] -= 1.0, T[10] -= 1.0;
    }
    return 1;
}

typedef struct combine_job {
    const arap_system *s;
    const double *fit[2]; /* per start: n_handles x 16, or NULL */
    double *w;            /* 6 nu: the two responses (as warm_start.c's s->warm)           */
} combine_job;

/* Unknowns [u0, u1): w_d = sum_{h,j} T_h[d][j] Z_{h,j} for each fitted start (a dk_range_fn). */
static void combine_range(void *ctx, dk_index u0, dk_index u1, int part)
{
    const combine_job *job = ctx;
    const arap_system *s = job->s;
    const size_t nu = (size_t)s->nu, N3 = 3 * nu;
    const dk_index H = s->con->n_handles;
    (void)part;
    for (int which = 0; which < 2; which++) {
        const double *fit = job->fit[which];
        if (!fit)
            continue;
        for (int d = 0; d < 3; d++) {
            double *w = job->w + (size_t)which * N3 + (size_t)d * nu;
            for (dk_index u = u0; u < u1; u++)
                w[u] = 0.0;
            for (dk_index h = 0; h < H; h++)
                for (int j = 0; j < 4; j++) {
                    const double coef = fit[16 * (size_t)h + 4 * (size_t)d + (size_t)j];
                    const double *z = s->zb + (4 * (size_t)h + (size_t)j) * nu;
                    if (coef == 0.0)
                        continue;
                    for (dk_index u = u0; u < u1; u++)
                        w[u] += coef * z[u];
                }
        }
    }
}

int arap_response_basis_apply(dk_arap *ar, arap_system *s, const double *x1, const double *x2,
                              double alpha, int predict, double *w)
{
    if (!s->zb)
        return 0;
    double *fit_plain = s->zfit, *fit_pred = s->zfit + 16 * (size_t)s->con->n_handles;
    if (!fit_moves(ar, s, x1, NULL, 0.0, fit_plain) ||
        (predict && !fit_moves(ar, s, x1, x2, alpha, fit_pred)))
        return 0;
    combine_job job = {s, {fit_plain, predict ? fit_pred : NULL}, w};
    dk_team_run_halves(ar->team, combine_range, &job, s->nu, PARALLEL_TERMS);
    ar->basis_starts++;
    return 1;
}
