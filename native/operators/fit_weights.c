/* DeformKit: skinning weights fitted from example poses (dk_fit_skinning_weights in
 * dk_operators.h), the slides' "weights ... by using example poses & skins".
 *
 * Each vertex is its own problem: with M_pj = T_pj B_j^-1 bone j's motion in pose p, the
 * weights w (b of them) that make linear blend skinning reproduce the example positions best,
 *     minimise  sum_p | sum_j w_j M_pj p - x_p |^2   subject to  w >= 0,  sum_j w_j = 1,
 * a least-squares problem over 3 P rows: min 1/2 w^T H w - c^T w with H = A^T A, c = A^T x,
 * A's column j the stacked M_pj p. Solved exactly by a primal active-set method (as Lawson
 * and Hanson's NNLS, with the equality kept in the KKT system of the free weights): start at
 * the single best bone, solve the free weights' equality-constrained problem; when that
 * leaves the simplex, step to its boundary and drop the weights that reach 0; when it stays
 * inside, add the bone whose multiplier says the energy falls fastest, or stop when none
 * does (the KKT conditions of a convex problem). Bones that move alike in every pose make H
 * singular (any split of the weight between them reproduces the examples alike): a ridge of
 * 1e-12 of H's mean diagonal keeps the free weights' system solvable, and the method keeps
 * the first of them it took. Vertices run on two threads. */
#include <math.h>
#include <stdlib.h>
#include <string.h>

#include <lapacke.h>

#include "dk_operators.h"
#include "dk_parallel.h"

typedef struct fit_pass {
    dk_index n, nb, np;
    const double *rest, *motion, *x; /* motion: np x nb x 12 (rows 0..2 of M_pj)        */
    double *w;
    int *iterations;                 /* per part: the most a vertex took                 */
    int failed[2];
    char *scratch[2];
} fit_pass;

/* The minimiser over the free set F (f of them) of 1/2 z^T H z - c^T z with sum z = 1: the
 * KKT system [H_FF 1; 1^T 0] [z; mu] = [c_F; 1]. */
static int free_solve(const double *H, const double *c, int nb, const int *F, int f, double *z,
                      double *kkt, lapack_int *pivots)
{
    const int k = f + 1;
    for (int r = 0; r < f; r++) {
        for (int q = 0; q < f; q++) kkt[r * k + q] = H[F[r] * nb + F[q]];
        kkt[r * k + f] = 1.0;
        kkt[f * k + r] = 1.0;
        z[r] = c[F[r]];
    }
    kkt[f * k + f] = 0.0;
    z[f] = 1.0;
    /* symmetric: its layout does not matter; LU with partial pivoting (the zero corner
     * rules Cholesky out), the _work form allocates nothing */
    return LAPACKE_dgesv_work(LAPACK_COL_MAJOR, k, 1, kkt, k, pivots, z, k) == 0 ? 0 : -1;
}

static void fit_range(void *ctx, dk_index begin, dk_index end, int part)
{
    fit_pass *p = (fit_pass *)ctx;
    const int nb = (int)p->nb; /* 1..1024, checked */
    if (nb < 1) return;
    double *A = (double *)p->scratch[part];           /* 3 np x nb                         */
    double *H = A + 3 * (size_t)p->np * (size_t)nb;   /* nb x nb                           */
    double *c = H + (size_t)nb * (size_t)nb;          /* nb                                */
    double *w = c + nb, *g = w + nb, *z = g + nb;     /* nb, nb, nb + 1                    */
    double *kkt = z + nb + 1;                         /* (nb + 1)^2                        */
    lapack_int *pivots = (lapack_int *)(kkt + (size_t)(nb + 1) * (size_t)(nb + 1));
    int *F = (int *)(pivots + nb + 1);
    unsigned char *in = (unsigned char *)(F + nb);
    for (dk_index v = begin; v < end; v++) {
        const double *q = p->rest + 3 * (size_t)v;
        const size_t rows = 3 * (size_t)p->np;
        double xx = 0.0;
        for (dk_index s = 0; s < p->np; s++)
            for (int j = 0; j < nb; j++) {
                const double *M = p->motion + ((size_t)s * (size_t)nb + (size_t)j) * 12;
                for (int r = 0; r < 3; r++)
                    A[(3 * (size_t)s + (size_t)r) * (size_t)nb + (size_t)j] =
                        M[4 * r] * q[0] + M[4 * r + 1] * q[1] + M[4 * r + 2] * q[2] + M[4 * r + 3];
            }
        const double *x = p->x;
        double mean = 0.0;
        for (int i = 0; i < nb; i++) {
            for (int j = i; j < nb; j++) {
                double s = 0.0;
                for (size_t r = 0; r < rows; r++) s += A[r * (size_t)nb + (size_t)i] * A[r * (size_t)nb + (size_t)j];
                H[i * nb + j] = H[j * nb + i] = s;
            }
            double s = 0.0;
            for (dk_index t = 0; t < p->np; t++)
                for (int r = 0; r < 3; r++)
                    s += A[(3 * (size_t)t + (size_t)r) * (size_t)nb + (size_t)i] *
                         x[((size_t)t * (size_t)p->n + (size_t)v) * 3 + (size_t)r];
            c[i] = s;
            mean += H[i * nb + i] / nb;
        }
        for (dk_index t = 0; t < p->np; t++)
            for (int r = 0; r < 3; r++) {
                double e = x[((size_t)t * (size_t)p->n + (size_t)v) * 3 + (size_t)r];
                xx += e * e;
            }
        const double ridge = 1e-12 * (mean > 0.0 ? mean : 1.0);
        for (int i = 0; i < nb; i++) H[i * nb + i] += ridge;
        /* start: the single bone that fits best (energy 1/2 H_jj - c_j) */
        int best = 0;
        for (int j = 1; j < nb; j++)
            if (0.5 * H[j * nb + j] - c[j] < 0.5 * H[best * nb + best] - c[best]) best = j;
        memset(w, 0, (size_t)nb * sizeof *w);
        memset(in, 0, (size_t)nb);
        w[best] = 1.0;
        in[best] = 1;
        int f = 1, it = 0;
        F[0] = best;
        const double tol = 1e-12 * (mean > 0.0 ? mean : 1.0) + 1e-14 * sqrt(xx * mean);
        for (; it < 4 * nb + 20; it++) {
            if (free_solve(H, c, nb, F, f, z, kkt, pivots) != 0) {
                p->failed[part] = 1;
                return;
            }
            /* z feasible (>= 0)? else step from w towards z to the first weight at 0 */
            double step = 1.0;
            int hit = -1;
            for (int r = 0; r < f; r++)
                if (z[r] < 0.0) {
                    double t = w[F[r]] / (w[F[r]] - z[r]);
                    if (t < step) step = t, hit = r;
                }
            for (int r = 0; r < f; r++) w[F[r]] += step * (z[r] - w[F[r]]);
            if (hit >= 0) {
                /* drop every free weight at (or, by rounding, below) 0 */
                int k = 0;
                for (int r = 0; r < f; r++) {
                    if (r == hit || w[F[r]] <= 0.0) {
                        w[F[r]] = 0.0;
                        in[F[r]] = 0;
                    } else {
                        F[k++] = F[r];
                    }
                }
                f = k;
                continue;
            }
            /* optimal on F: the multiplier of each held weight, g_j - mu with g = H w - c,
             * mu the equality's (the free weights' common gradient) */
            double mu = 0.0;
            for (int j = 0; j < nb; j++) {
                double s = -c[j];
                for (int q = 0; q < nb; q++) s += H[j * nb + q] * w[q];
                g[j] = s;
            }
            for (int r = 0; r < f; r++) mu += g[F[r]] / f;
            int enter = -1;
            double most = -tol;
            for (int j = 0; j < nb; j++)
                if (!in[j] && g[j] - mu < most) most = g[j] - mu, enter = j;
            if (enter < 0) break;
            in[enter] = 1;
            F[f++] = enter;
        }
        if (it == 4 * nb + 20) { /* cannot happen for a convex problem: say so if it does */
            p->failed[part] = 2;
            return;
        }
        if (it > p->iterations[part]) p->iterations[part] = it;
        double sum = 0.0;
        for (int j = 0; j < nb; j++) sum += w[j] = fmax(0.0, w[j]);
        for (int j = 0; j < nb; j++) p->w[(size_t)v * (size_t)nb + (size_t)j] = w[j] / sum;
    }
}

dk_status dk_fit_skinning_weights(const double *rest, dk_index n, const double *rest_frames,
                                  dk_index n_bones, const double *pose_frames,
                                  const double *pose_positions, dk_index n_poses,
                                  double *weights, dk_error *err)
{
    static const char who[] = "fit skinning weights";
    if (!rest || !rest_frames || !pose_frames || !pose_positions || !weights || n < 0 ||
        n_bones < 1 || n_poses < 1)
        return dk_error_set(err, DK_ERR_INVALID_ARGUMENT, "%s: needs the rest positions, at "
                            "least one bone and one pose", who);
    if (n_bones > 1024)
        return dk_error_set(err, DK_ERR_INVALID_ARGUMENT, "%s: %ld bones (at most 1024)", who,
                            (long)n_bones);
    const size_t nb = (size_t)n_bones, np = (size_t)n_poses;
    for (size_t i = 0; i < 3 * (size_t)n; i++)
        if (!isfinite(rest[i]))
            return dk_error_set(err, DK_ERR_NONFINITE, "%s: rest position of vertex %zu is not "
                                "finite", who, i / 3);
    for (size_t i = 0; i < 3 * (size_t)n * np; i++)
        if (!isfinite(pose_positions[i]))
            return dk_error_set(err, DK_ERR_NONFINITE, "%s: pose %zu's position of vertex %zu is "
                                "not finite", who, i / (3 * (size_t)n), (i / 3) % (size_t)n);
    double *motion = malloc(np * nb * 12 * sizeof *motion);
    if (!motion) return dk_error_set(err, DK_ERR_OUT_OF_MEMORY, "%s: out of memory", who);
    for (size_t j = 0; j < nb; j++) {
        const double *B = rest_frames + 16 * j;
        double inv[16]; /* B^-1 */
        int bad = !(B[12] == 0.0 && B[13] == 0.0 && B[14] == 0.0 && B[15] == 1.0);
        for (int k = 0; k < 16; k++) bad |= !isfinite(B[k]);
        if (bad || dk_affine_inverse(B, inv) != 0) {
            free(motion);
            return dk_error_set(err, DK_ERR_INVALID_ARGUMENT, "%s: bone %zu's rest frame is not "
                                "an invertible affine frame", who, j);
        }
        for (size_t s = 0; s < np; s++) {
            const double *T = pose_frames + 16 * (s * nb + j);
            for (int k = 0; k < 16; k++)
                if (!isfinite(T[k])) {
                    free(motion);
                    return dk_error_set(err, DK_ERR_NONFINITE, "%s: pose %zu's frame of bone %zu "
                                        "is not finite", who, s, j);
                }
            double *M = motion + (s * nb + j) * 12;
            for (int r = 0; r < 3; r++)
                for (int k = 0; k < 4; k++)
                    M[4 * r + k] = T[4 * r] * inv[k] + T[4 * r + 1] * inv[4 + k] +
                                   T[4 * r + 2] * inv[8 + k] + (k == 3 ? T[4 * r + 3] : 0.0);
        }
    }
    /* per part: A (3 np x nb), H, c, w, g, z, kkt, F, in */
    size_t bytes = (3 * np * nb + nb * nb + 4 * nb + 1 + (nb + 1) * (nb + 1)) * sizeof(double) +
                   (nb + 1) * sizeof(lapack_int) + nb * sizeof(int) + nb + 16;
    fit_pass pass = {.n = n, .nb = n_bones, .np = n_poses, .rest = rest, .motion = motion,
                     .x = pose_positions, .w = weights};
    int iters[2] = {0, 0};
    pass.iterations = iters;
    pass.scratch[0] = malloc(bytes);
    pass.scratch[1] = malloc(bytes);
    dk_status st = DK_OK;
    if (!pass.scratch[0] || !pass.scratch[1]) {
        st = dk_error_set(err, DK_ERR_OUT_OF_MEMORY, "%s: out of memory", who);
    } else {
        dk_run_halves(fit_range, &pass, n, 256);
        if (pass.failed[0] == 1 || pass.failed[1] == 1)
            st = dk_error_set(err, DK_ERR_NUMERIC, "%s: a vertex's system is singular", who);
        else if (pass.failed[0] || pass.failed[1])
            st = dk_error_set(err, DK_ERR_NO_CONVERGENCE, "%s: a vertex's active set did not "
                              "settle", who);
    }
    free(pass.scratch[0]);
    free(pass.scratch[1]);
    free(motion);
    return st;
}
