/* DeformKit: smallest eigenpairs of L x = lambda M x with ARPACK (see dk_eigs.h).
 *
 * One band: ARPACK dsaupd in shift-invert mode 3 with bmat = 'G' (B = M), which = "LM":
 * OP = (L - sigma M)^-1 M, whose eigenvalues nu = 1 / (lambda - sigma) are largest in
 * magnitude for the lambda nearest sigma. The linear solves use dk_cholesky.
 *
 * First shift. L is PSD with eigenvalue 0 (constants), so sigma must be negative for
 * L - sigma M to be positive definite. The generalized spectrum lies in [0, lmax] with
 * lmax <= 2 max_i L_ii / m_i (Gershgorin) and mean eigenvalue trace(M^-1 L) / n, of the order
 * of 1/h^2 (h the edge length); the first non-zero eigenvalue is of the order of
 * 1/diameter^2, i.e. about 1/n of the mean on a mesh of n vertices. sigma = -1e-6 * mean
 * is then far below lambda_1 for meshes up to ~1e5-1e6 vertices (so the wanted nu are well
 * separated and the constant mode converges immediately), while the condition number of
 * L - sigma M, about lmax / |sigma| ~ 1e6, costs at most ~6 digits in directions of the
 * near-null space, which the Rayleigh quotients computed afterwards do not inherit.
 *
 * Certification (every band, the single band included). Lanczos finds one vector per
 * eigenspace from its start vector; further copies of a multiple eigenvalue only appear through
 * rounding, and can be missed. So after each run tau is put in the highest spectral gap
 * (relative width > 1e-6) of the run's results and L - tau M is factored as LDL'
 * (dk_cholesky_analyze_indefinite; one symbolic analysis shared by every shift): by
 * Sylvester's law of inertia its negative pivots count the eigenvalues below tau exactly.
 * When the accepted pairs fall short, an ARPACK run around the same shift with OP deflated
 * against the pairs already found (P OP, P the M-orthogonal projector off them) returns the
 * missing copies; a surplus (a duplicate) is an error. Pairs above tau are dropped (the next
 * band finds them again), so everything accepted is certified complete below its tau.
 *
 * A disconnected L is split by component first, each solved as below ("disconnected L",
 * near the end of this file).
 *
 * Many eigenpairs (Vallet and Levy 2008): when k > band_size, later bands use a shift
 * sigma_b placed beyond the last accepted eigenvalue lambda_top, from the local spacing delta
 * of the accepted ones, so that the window of the nev eigenvalues nearest sigma_b reaches
 * back about nev/8 eigenvalues below lambda_top (overlap). L - sigma_b M is indefinite and
 * factored as LDL'. The window must reach below lambda_top and hold a gap above it, else the
 * shift is moved down and the band widened by half (a cluster larger than the band) and
 * redone. Merging a certified band:
 *  - results below lambda_top - zeta (zeta = delta / 10) are known already: dropped;
 *  - results within zeta of lambda_top are M-projected against the accepted vectors of that
 *    cluster; directions with an M-norm^2 above 1/2 after projection are new (the rest
 *    duplicates), and a Rayleigh-Ritz step on the union re-M-orthogonalises the cluster;
 *  - results above lambda_top + zeta are new.
 * At the end the k vectors are M-orthonormalised together (Cholesky QR), which removes the
 * small cross-band inner products left by the per-band accuracy.
 *
 * ARPACK's Fortran SAVE variables make these calls non-reentrant (see the header); ARPACK's
 * random start vector (another SAVEd state) is avoided by passing our own deterministic
 * start vector, so results are reproducible.
 */
#include "dk_eigs.h"
#include "dk_lapack.h"

#include <arpack.h>
#include <cblas.h>
#include <lapacke.h>
#include <float.h>
#include <math.h>
#include <stdint.h>
#include <stdlib.h>
#include <string.h>

#include "dk_cholesky.h"

#define DEFAULT_TOLERANCE 1e-10
#define DEFAULT_MAX_ITERATIONS 1000
#define DEFAULT_BAND_SIZE 50
#define MIN_BAND_SIZE 16
#define PI 3.14159265358979323846

void dk_eigs_options_default(dk_eigs_options *opt)
{
    if (!opt) return;
    memset(opt, 0, sizeof *opt);
    opt->tolerance = DEFAULT_TOLERANCE;
    opt->max_iterations = DEFAULT_MAX_ITERATIONS;
    opt->band_size = DEFAULT_BAND_SIZE;
}

/* ------------------------------------------------------------------ working context ---- */

typedef struct eig_ctx {
    const dk_sparse *l;
    const double *mass;
    dk_index n;
    double tol;
    int max_iterations;
    dk_sparse shifted;      /* upper triangle of L - sigma M, diagonal always stored */
    dk_index *diag_pos;     /* position of (j, j) in `shifted`                        */
    double *l_diag;         /* L_jj                                                   */
    dk_cholesky *spd;       /* LL' for sigma < 0                                      */
    dk_cholesky *ldl;       /* LDL' for interior shifts                               */
    uint64_t seed;
    /* ARPACK workspace, sized for the largest ncv used so far. The Ritz vectors of a run
     * overwrite the first columns of the Krylov basis v (ritz_vectors): z is v. */
    double *resid, *v, *workd, *workl, *d;
    double *ritz;           /* Ritz step: theta, e, S (ncv x ncv), selected S columns   */
    int *order;             /* ncv                                                       */
    int ws_ncv, ws_nev;
    /* cancellation inside a band: the progress callback is asked again every
     * CANCEL_CHECK_OPS operator applications, with the fraction of the last report */
    dk_progress_fn progress;
    void *progress_user;
    double fraction;
    long ops;
} eig_ctx;

#define CANCEL_CHECK_OPS 16

static void ctx_free(eig_ctx *c)
{
    free(c->shifted.col_start);
    free(c->shifted.row_index);
    free(c->shifted.values);
    free(c->diag_pos);
    free(c->l_diag);
    dk_cholesky_free(c->spd);
    dk_cholesky_free(c->ldl);
    free(c->resid); free(c->v); free(c->workd); free(c->workl); free(c->d);
    free(c->ritz); free(c->order);
}

/* Builds the upper-triangular pattern of L with every diagonal entry present. */
static dk_status ctx_build_shifted(eig_ctx *c, dk_error *err)
{
    const dk_sparse *l = c->l;
    const dk_index n = c->n;
    int64_t cnt = 0;
    for (dk_index j = 0; j < n; j++) {
        for (dk_index p = l->col_start[j]; p < l->col_start[j + 1]; p++)
            cnt += l->row_index[p] < j;
        cnt++; /* the diagonal, stored even where L has none (an isolated vertex) */
    }
    if (cnt > INT32_MAX)
        return dk_error_set(err, DK_ERR_OUT_OF_MEMORY, "eigs: matrix too large (%lld entries)",
                            (long long)cnt);
    dk_sparse *s = &c->shifted;
    s->n_rows = s->n_cols = n;
    s->col_start = malloc(((size_t)n + 1) * sizeof(dk_index));
    s->row_index = malloc((size_t)cnt * sizeof(dk_index));
    s->values = malloc((size_t)cnt * sizeof(double));
    c->diag_pos = malloc((size_t)n * sizeof(dk_index));
    c->l_diag = malloc((size_t)n * sizeof(double));
    if (!s->col_start || !s->row_index || !s->values || !c->diag_pos || !c->l_diag)
        return dk_error_set(err, DK_ERR_OUT_OF_MEMORY, "eigs: out of memory");
    dk_index q = 0;
    for (dk_index j = 0; j < n; j++) {
        s->col_start[j] = q;
        c->l_diag[j] = 0.0;
        for (dk_index p = l->col_start[j]; p < l->col_start[j + 1]; p++) {
            const dk_index i = l->row_index[p];
            if (i < j) {
                s->row_index[q] = i;
                s->values[q++] = l->values[p];
            } else if (i == j) {
                c->l_diag[j] = l->values[p];
            }
        }
        c->diag_pos[j] = q;
        s->row_index[q] = j;
        s->values[q++] = c->l_diag[j];
    }
    s->col_start[n] = q;
    return DK_OK;
}

static void ctx_set_shift(eig_ctx *c, double sigma)
{
    for (dk_index j = 0; j < c->n; j++)
        c->shifted.values[c->diag_pos[j]] = c->l_diag[j] - sigma * c->mass[j];
}

/* Factors L - sigma M: LL' (must be PD) or LDL' (`*neg` gets the inertia). */
static dk_status ctx_factor(eig_ctx *c, double sigma, int indefinite, dk_index *neg,
                            dk_error *err)
{
    ctx_set_shift(c, sigma);
    dk_cholesky **obj = indefinite ? &c->ldl : &c->spd;
    dk_status st;
    if (!*obj) {
        st = indefinite ? dk_cholesky_analyze_indefinite(&c->shifted, obj, err)
                        : dk_cholesky_analyze(&c->shifted, obj, err);
        if (st != DK_OK) return st;
    }
    st = dk_cholesky_factorize(*obj, &c->shifted, err);
    if (st != DK_OK) {
        if (st == DK_ERR_NOT_POSITIVE_DEFINITE && !indefinite)
            return dk_error_prefix(err, "eigs: L - sigma M with sigma = %g < 0 (is L positive "
                                   "semidefinite?)", sigma);
        return dk_error_prefix(err, "eigs: factorizing L - sigma M at sigma = %g", sigma);
    }
    if (neg) {
        *neg = 0;
        st = dk_cholesky_negative_pivots(*obj, neg, err);
    }
    return st;
}

/* y = L x (both triangles of L stored). */
static void l_matvec(const dk_sparse *l, const double *x, double *y)
{
    memset(y, 0, (size_t)l->n_rows * sizeof(double));
    for (dk_index j = 0; j < l->n_cols; j++) {
        const double xj = x[j];
        for (dk_index p = l->col_start[j]; p < l->col_start[j + 1]; p++)
            y[l->row_index[p]] += l->values[p] * xj;
    }
}

static double m_dot(const double *mass, const double *x, const double *y, dk_index n)
{
    double s = 0.0;
    for (dk_index i = 0; i < n; i++) s += mass[i] * x[i] * y[i];
    return s;
}

static double next_random(uint64_t *s) /* xorshift64, uniform in [-1, 1) */
{
    *s ^= *s << 13;
    *s ^= *s >> 7;
    *s ^= *s << 17;
    return (double)(*s >> 11) / 9007199254740992.0 * 2.0 - 1.0;
}

/* ---------------------------------------------------------------- one ARPACK run -------- */

static dk_status ensure_workspace(eig_ctx *c, int nev, int ncv, dk_error *err)
{
    const size_t n = (size_t)c->n;
    if (ncv > c->ws_ncv) {
        free(c->v); free(c->workl); free(c->ritz); free(c->order);
        c->v = malloc(n * (size_t)ncv * sizeof(double));
        c->workl = malloc((size_t)ncv * ((size_t)ncv + 8) * sizeof(double));
        c->ritz = malloc((size_t)ncv * (2 * (size_t)ncv + 2) * sizeof(double));
        c->order = malloc((size_t)ncv * sizeof(int));
        c->ws_ncv = ncv;
        if (!c->v || !c->workl || !c->ritz || !c->order) {
            c->ws_ncv = 0;
            return dk_error_set(err, DK_ERR_OUT_OF_MEMORY, "eigs: out of memory (Krylov basis "
                                "%zu x %d)", n, ncv);
        }
    }
    if (nev > c->ws_nev) {
        free(c->d);
        c->d = malloc((size_t)nev * sizeof(double));
        c->ws_nev = nev;
        if (!c->d) {
            c->ws_nev = 0;
            return dk_error_set(err, DK_ERR_OUT_OF_MEMORY, "eigs: out of memory");
        }
    }
    if (!c->resid) {
        c->resid = malloc(n * sizeof(double));
        c->workd = malloc(3 * n * sizeof(double));
        if (!c->resid || !c->workd)
            return dk_error_set(err, DK_ERR_OUT_OF_MEMORY, "eigs: out of memory");
    }
    return DK_OK;
}

/* The `nev` eigenpairs nearest `sigma`, with the factorization of L - sigma M in `chol`.
 * On return c->d[0..*nconv-1] holds the eigenvalues (Rayleigh quotients) ascending and
 * the first nconv columns of c->v the matching M-orthonormal eigenvectors (column-major
 * n x nconv; they overwrite the Krylov basis). Fails with DK_ERR_NO_CONVERGENCE (the
 * converged pairs still in c->d, c->v) or DK_ERR_NUMERIC. */
static void deflate(const double *mass, const double *basis, int nb, dk_index n, double *y)
{
    for (int pass = 0; pass < 2; pass++)
        for (int a = 0; a < nb; a++) {
            const double *x = basis + (size_t)a * n;
            const double t = m_dot(mass, x, y, n);
            for (dk_index i = 0; i < n; i++) y[i] -= t * x[i];
        }
}

/* Ritz vectors of the final Lanczos factorization OP V = V H + f e_ncv^T that dsaupd leaves
 * (V: n x ncv, M-orthonormal; H tridiagonal in workl at ipntr[4]: first column rnorm then
 * the subdiagonal, second column the diagonal; f in resid). This does dseupd's job for
 * "all wanted vectors" with one dgemm: dseupd forms V Q with an unblocked QR (dgeqr2 +
 * dorm2r), several times slower on big bases (armadillo, ncv 101: ~70 ms a band vs ~10 ms).
 * The `want` converged pairs of largest |theta| are kept, the convergence test being
 * dsaupd's (Ritz estimate rnorm |s_ncv| <= tol max(eps^(2/3), |theta|)); each vector gets
 * the purification step z = V s + (s_ncv / theta) f = OP (V s) / theta (one step of inverse
 * iteration, as dseupd does in shift-invert mode). On return the first `*got` columns of
 * c->v hold the vectors, in no particular order (the caller sorts by Rayleigh quotient).
 * V Q is formed in place, a block of rows at a time (row r of V Q needs row r of V only),
 * so that the Ritz vectors need no n x nev array of their own (issue 19: 0.4 KB a vertex
 * with 50-pair bands). */
#define RITZ_ROWS 256
static dk_status ritz_vectors(eig_ctx *c, int ncv, int want, const a_int *ipntr, int *got,
                              dk_error *err)
{
    const dk_index n = c->n;
    const double *h = c->workl + ipntr[4] - 1;
    double *theta = c->ritz, *e = theta + ncv, *s = e + ncv, *q = s + (size_t)ncv * ncv;
    int *ord = c->order;
    const double rnorm = h[0];
    for (int i = 0; i < ncv; i++) theta[i] = h[ncv + i];
    for (int i = 0; i + 1 < ncv; i++) e[i] = h[1 + i];
    e[ncv - 1] = 0.0;
    const int info = dk_lapack_dstev('V', ncv, theta, e, s, ncv);
    if (info != 0)
        return dk_error_set(err, DK_ERR_NUMERIC, "eigs: tridiagonal eigensolver failed "
                            "(info %d, ncv %d)", (int)info, ncv);
    for (int i = 0; i < ncv; i++) ord[i] = i;
    for (int j = 1; j < ncv; j++) /* by |theta| descending (the wanted end of "LM") */
        for (int i = j; i > 0 && fabs(theta[ord[i]]) > fabs(theta[ord[i - 1]]); i--) {
            const int t = ord[i]; ord[i] = ord[i - 1]; ord[i - 1] = t;
        }
    const double eps23 = pow(DBL_EPSILON, 2.0 / 3.0);
    int m = 0;
    for (int r = 0; r < ncv && m < want; r++) {
        const int j = ord[r];
        const double *sj = s + (size_t)j * ncv;
        if (!(fabs(rnorm * sj[ncv - 1]) <= c->tol * fmax(eps23, fabs(theta[j])))) continue;
        if (theta[j] == 0.0) continue; /* OP is nonsingular: cannot be a converged pair */
        memcpy(q + (size_t)m * ncv, sj, (size_t)ncv * sizeof(double));
        c->d[m++] = theta[j];
    }
    /* Order the selection by the eigenvalue estimate sigma + 1/theta, so that the caller's
     * sort by Rayleigh quotient finds the vectors (nearly) sorted: swapping columns of
     * length n there cost ~0.4 s on 300 armadillo pairs, where these columns have ncv. */
    for (int j = 1; j < m; j++)
        for (int i = j; i > 0 && 1.0 / c->d[i] < 1.0 / c->d[i - 1]; i--) {
            const double t = c->d[i]; c->d[i] = c->d[i - 1]; c->d[i - 1] = t;
            double *qa = q + (size_t)i * ncv, *qb = q + (size_t)(i - 1) * ncv;
            for (int r = 0; r < ncv; r++) { const double u = qa[r]; qa[r] = qb[r]; qb[r] = u; }
        }
    if (m > 0) {
        double *blk = malloc((size_t)RITZ_ROWS * (size_t)m * sizeof(double));
        if (!blk)
            return dk_error_set(err, DK_ERR_OUT_OF_MEMORY, "eigs: out of memory (Ritz vectors)");
        for (dk_index r0 = 0; r0 < n; r0 += RITZ_ROWS) {
            const int rows = n - r0 < RITZ_ROWS ? (int)(n - r0) : RITZ_ROWS;
            cblas_dgemm(CblasColMajor, CblasNoTrans, CblasNoTrans, rows, m, ncv, 1.0,
                        c->v + r0, (int)n, q, ncv, 0.0, blk, rows);
            for (int k = 0; k < m; k++)
                memcpy(c->v + (size_t)k * n + r0, blk + (size_t)k * rows,
                       (size_t)rows * sizeof(double));
        }
        free(blk);
        for (int k = 0; k < m; k++)
            cblas_daxpy((int)n, q[(size_t)k * ncv + ncv - 1] / c->d[k], c->resid, 1,
                        c->v + (size_t)k * n, 1);
    }
    *got = m;
    return DK_OK;
}

static dk_status arpack_run(eig_ctx *c, dk_cholesky *chol, double sigma, int nev, int ncv,
                            const double *defl, int ndefl, int *nconv, double *scratch,
                            dk_error *err)
{
    *nconv = 0;
    dk_status st = ensure_workspace(c, nev, ncv, err);
    if (st != DK_OK) return st;
    const a_int n = c->n;
    for (a_int i = 0; i < n; i++) c->resid[i] = next_random(&c->seed);
    /* Deflation: OP is replaced by P OP with P = I - X X^T M, the M-orthogonal projector off
     * the already found eigenvectors X, so that copies of a multiple eigenvalue that the
     * first run missed (Lanczos finds one vector per eigenspace, others only by rounding)
     * become the dominant ones. */
    if (ndefl > 0) deflate(c->mass, defl, ndefl, n, c->resid);
    a_int iparam[11] = {0}, ipntr[14] = {0};
    iparam[0] = 1;                 /* exact shifts */
    iparam[2] = c->max_iterations; /* restarts */
    iparam[6] = 3;                 /* shift-invert mode */
    const a_int lworkl = (a_int)ncv * (ncv + 8);
    a_int ido = 0, info = 1;       /* info = 1: resid holds our start vector */
    const double *mass = c->mass;
    for (;;) {
        dsaupd_c(&ido, "G", n, "LM", nev, c->tol, c->resid, ncv, c->v, n, iparam, ipntr,
                 c->workd, c->workl, lworkl, &info);
        if (ido == -1 || ido == 1) {
            double *x = c->workd + ipntr[0] - 1, *y = c->workd + ipntr[1] - 1;
            if (ido == -1) {
                for (a_int i = 0; i < n; i++) scratch[i] = mass[i] * x[i];
            } else {
                memcpy(scratch, c->workd + ipntr[2] - 1, (size_t)n * sizeof(double));
            }
            st = dk_cholesky_solve(chol, scratch, 1, y, err);
            if (st != DK_OK) return dk_error_prefix(err, "eigs");
            if (c->progress && ++c->ops % CANCEL_CHECK_OPS == 0 &&
                c->progress(c->progress_user, c->fraction))
                return dk_error_set(err, DK_ERR_CANCELLED, "eigs: cancelled during a band");
            if (ndefl > 0) deflate(c->mass, defl, ndefl, n, y);
        } else if (ido == 2) {
            double *x = c->workd + ipntr[0] - 1, *y = c->workd + ipntr[1] - 1;
            for (a_int i = 0; i < n; i++) y[i] = mass[i] * x[i];
        } else {
            break;
        }
    }
    if (info < 0)
        return dk_error_set(err, DK_ERR_NUMERIC, "eigs: ARPACK dsaupd failed with info %d "
                            "(n %d, nev %d, ncv %d)", (int)info, (int)n, nev, ncv);
    if (info == 3)
        return dk_error_set(err, DK_ERR_NO_CONVERGENCE, "eigs: ARPACK could not apply shifts "
                            "(nev %d, ncv %d)", nev, ncv);
    const int converged = (int)iparam[4];
    int got = converged < nev ? converged : nev;
    if (got > 0) {
        st = ritz_vectors(c, ncv, got, ipntr, &got, err);
        if (st != DK_OK) return st;
    }
    /* Rayleigh quotients (accurate to the square of the vector error), then sort. */
    for (int j = 0; j < got; j++) {
        double *x = c->v + (size_t)j * n;
        const double xm = m_dot(mass, x, x, n);
        l_matvec(c->l, x, scratch);
        double xl = 0.0;
        for (a_int i = 0; i < n; i++) xl += x[i] * scratch[i];
        const double inv = 1.0 / sqrt(xm);
        for (a_int i = 0; i < n; i++) x[i] *= inv;
        c->d[j] = xl / xm;
    }
    for (int j = 1; j < got; j++) { /* insertion sort with column swaps: nev is small */
        for (int i = j; i > 0 && c->d[i] < c->d[i - 1]; i--) {
            const double t = c->d[i]; c->d[i] = c->d[i - 1]; c->d[i - 1] = t;
            double *a = c->v + (size_t)i * n, *b = c->v + (size_t)(i - 1) * n;
            for (a_int r = 0; r < n; r++) { const double u = a[r]; a[r] = b[r]; b[r] = u; }
        }
    }
    *nconv = got;
    /* info = 1 (restart limit) with every wanted pair converged is a success */
    if (got < nev)
        return dk_error_set(err, DK_ERR_NO_CONVERGENCE, "eigs: ARPACK converged %d of %d "
                            "eigenpairs near sigma = %g in %d restarts", got, nev, sigma,
                            c->max_iterations);
    return DK_OK;
}

/* ------------------------------------------------------------------ accepted store ------ */

typedef struct store {
    double *val;   /* ascending */
    double *vec;   /* n x split: columns [0, split)                                  */
    double *extra; /* n x (cap - split): columns [split, cap), or NULL (split == cap) */
    size_t n;
    int m, cap, split;
} store;

/* Column j of a store. The accepted store keeps its first k columns in the caller's output
 * (no n x k copy at the end: 2.4 KB a vertex for 300 pairs, issue 19) and the margin
 * beyond k in `extra`; a band store is one block. */
static double *scol(const store *s, int j)
{
    return j < s->split ? s->vec + (size_t)j * s->n : s->extra + (size_t)(j - s->split) * s->n;
}

static int count_below(const double *v, int m, double t)
{
    int c = 0;
    for (int i = 0; i < m; i++) c += v[i] < t;
    return c;
}

/* Merges band results (bd: nb pairs, ascending) above lambda_top - zeta into the
 * store (see the file comment). With `commit` = 0 only counts: `*n_below` gets how many
 * eigenvalues below `sigma` the merged store would hold. */
static dk_status merge_band(eig_ctx *c, store *s, const store *bd, double zeta,
                            double sigma, int commit, int *n_below, dk_error *err)
{
    const int nb = bd->m;
    const dk_index n = c->n;
    const double top = s->val[s->m - 1];
    int p0 = s->m; /* first accepted in the top cluster */
    while (p0 > 0 && s->val[p0 - 1] >= top - zeta) p0--;
    const int p = s->m - p0;
    int j0 = 0, j1 = 0; /* zone candidates [j0, j1) */
    while (j0 < nb && bd->val[j0] < top - zeta) j0++;
    j1 = j0;
    while (j1 < nb && bd->val[j1] <= top + zeta) j1++;
    const int q = j1 - j0;
    dk_status st = DK_OK;
    double *zz = NULL, *g = NULL, *gw = NULL, *sv = NULL, *ls = NULL, *h = NULL, *hw = NULL;
    int r = 0;
    if (q > 0) {
        /* Z = Y - C (C^T M Y), G = Z^T M Z, new directions: eigenvalues of G above 1/2 */
        zz = malloc((size_t)n * q * sizeof(double));
        g = malloc((size_t)q * q * sizeof(double));
        gw = malloc((size_t)q * sizeof(double));
        if (!zz || !g || !gw) {
            st = dk_error_set(err, DK_ERR_OUT_OF_MEMORY, "eigs: out of memory (band merge)");
            goto done;
        }
        memcpy(zz, bd->vec + (size_t)j0 * n, (size_t)n * q * sizeof(double));
        for (int pass = 0; pass < 2; pass++) /* twice: Gram-Schmidt loses orthogonality */
            for (int b = 0; b < q; b++) {
                double *y = zz + (size_t)b * n;
                for (int a = 0; a < p; a++) {
                    const double *x = scol(s, p0 + a);
                    const double t = m_dot(c->mass, x, y, n);
                    for (dk_index i = 0; i < n; i++) y[i] -= t * x[i];
                }
            }
        for (int a = 0; a < q; a++)
            for (int b = 0; b <= a; b++)
                g[(size_t)a * q + b] = g[(size_t)b * q + a] =
                    m_dot(c->mass, zz + (size_t)a * n, zz + (size_t)b * n, n);
        if (dk_lapack_dsyev('V', q, g, gw) != 0) {
            st = dk_error_set(err, DK_ERR_NUMERIC, "eigs: LAPACK dsyev failed (band merge)");
            goto done;
        }
        for (int a = 0; a < q; a++) r += gw[a] > 0.5;
    }
    if (!commit) {
        int below = count_below(s->val, p0, sigma) + p + r;
        for (int j = j1; j < nb; j++) below += bd->val[j] < sigma;
        *n_below = below;
        goto done;
    }
    if (s->m + r > s->cap) {
        st = dk_error_set(err, DK_ERR_INTERNAL, "eigs: accepted store overflow");
        goto done;
    }
    if (r > 0) {
        /* S = [C, new directions], M-orthonormal; Rayleigh-Ritz with H = S^T L S. */
        const int w = p + r;
        sv = malloc((size_t)n * w * sizeof(double));
        ls = malloc((size_t)n * sizeof(double));
        h = malloc((size_t)w * w * sizeof(double));
        hw = malloc((size_t)w * sizeof(double));
        if (!sv || !ls || !h || !hw) {
            st = dk_error_set(err, DK_ERR_OUT_OF_MEMORY, "eigs: out of memory (Rayleigh-Ritz)");
            goto done;
        }
        for (int a = 0; a < p; a++)
            memcpy(sv + (size_t)a * n, scol(s, p0 + a), (size_t)n * sizeof(double));
        int col = p;
        for (int a = 0; a < q; a++) {
            if (gw[a] <= 0.5) continue;
            double *x = sv + (size_t)col * n;
            memset(x, 0, (size_t)n * sizeof(double));
            for (int b = 0; b < q; b++) {
                const double coef = g[(size_t)a * q + b];
                const double *y = zz + (size_t)b * n;
                for (dk_index i = 0; i < n; i++) x[i] += coef * y[i];
            }
            for (int pass = 0; pass < 2; pass++)
                for (int b = 0; b < col; b++) {
                    const double *y = sv + (size_t)b * n;
                    const double t = m_dot(c->mass, y, x, n);
                    for (dk_index i = 0; i < n; i++) x[i] -= t * y[i];
                }
            const double nm = sqrt(m_dot(c->mass, x, x, n));
            for (dk_index i = 0; i < n; i++) x[i] /= nm;
            col++;
        }
        for (int a = 0; a < w; a++) {
            l_matvec(c->l, sv + (size_t)a * n, ls);
            for (int b = 0; b <= a; b++) {
                double t = 0.0;
                const double *y = sv + (size_t)b * n;
                for (dk_index i = 0; i < n; i++) t += y[i] * ls[i];
                h[(size_t)a * w + b] = h[(size_t)b * w + a] = t;
            }
        }
        if (dk_lapack_dsyev('V', w, h, hw) != 0) {
            st = dk_error_set(err, DK_ERR_NUMERIC, "eigs: LAPACK dsyev failed (Rayleigh-Ritz)");
            goto done;
        }
        for (int a = 0; a < w; a++) {
            double *x = scol(s, p0 + a);
            memset(x, 0, (size_t)n * sizeof(double));
            for (int b = 0; b < w; b++) {
                const double coef = h[(size_t)a * w + b];
                const double *y = sv + (size_t)b * n;
                for (dk_index i = 0; i < n; i++) x[i] += coef * y[i];
            }
            s->val[p0 + a] = hw[a];
        }
        s->m = p0 + w;
    }
    /* new pairs beyond the store's room are not needed (the store holds k + margin) */
    for (int j = j1; j < nb && s->m < s->cap; j++) {
        memcpy(scol(s, s->m), bd->vec + (size_t)j * n, (size_t)n * sizeof(double));
        s->val[s->m++] = bd->val[j];
    }
done:
    free(zz); free(g); free(gw); free(sv); free(ls); free(h); free(hw);
    return st;
}

/* M-orthonormalises the k columns of x (Cholesky QR on M^(1/2) X) when they are not already
 * orthonormal to 1e-12. */
static dk_status m_orthonormalise(const double *mass, dk_index n, int k, double *x,
                                  dk_error *err)
{
    double *g = malloc((size_t)k * k * sizeof(double));
    double *sq = malloc((size_t)n * sizeof(double));
    if (!g || !sq) {
        free(g); free(sq);
        return dk_error_set(err, DK_ERR_OUT_OF_MEMORY, "eigs: out of memory");
    }
    for (dk_index i = 0; i < n; i++) sq[i] = sqrt(mass[i]);
    for (int j = 0; j < k; j++)
        for (dk_index i = 0; i < n; i++) x[(size_t)j * n + i] *= sq[i];
    cblas_dsyrk(CblasColMajor, CblasUpper, CblasTrans, k, n, 1.0, x, n, 0.0, g, k);
    double off = 0.0;
    for (int j = 0; j < k; j++)
        for (int i = 0; i <= j; i++) off = fmax(off, fabs(g[(size_t)j * k + i] - (i == j)));
    dk_status st = DK_OK;
    if (off > 1e-12) {
        if (LAPACKE_dpotrf(LAPACK_COL_MAJOR, 'U', k, g, k) != 0)
            st = dk_error_set(err, DK_ERR_INTERNAL, "eigs: eigenvectors are linearly dependent "
                              "(a duplicate slipped through)");
        else
            cblas_dtrsm(CblasColMajor, CblasRight, CblasUpper, CblasNoTrans, CblasNonUnit, n, k,
                        1.0, g, k, x, n);
    }
    for (int j = 0; j < k; j++)
        for (dk_index i = 0; i < n; i++) x[(size_t)j * n + i] /= sq[i];
    free(g);
    free(sq);
    return st;
}

/* Local mean spacing of the top accepted eigenvalues. */
static double spacing(const store *s, int window, double floor)
{
    const int m = s->m;
    const int q = m - 1 < window ? m - 1 : window;
    double d = q > 0 ? (s->val[m - 1] - s->val[m - 1 - q]) / q : 0.0;
    const double avg = s->val[m - 1] / m;
    if (!(d > 0.25 * avg)) d = fmax(d, avg);
    return fmax(d, floor);
}

/* ------------------------------------------------------------------ entry point --------- */

static dk_status check_inputs(const dk_sparse *l, const double *mass, int k,
                              const double *eigenvalues, const double *eigenvectors,
                              dk_error *err)
{
    if (!l || !l->col_start || !mass || !eigenvalues || !eigenvectors)
        return dk_error_set(err, DK_ERR_INVALID_ARGUMENT, "eigs: NULL argument");
    if (l->n_rows != l->n_cols)
        return dk_error_set(err, DK_ERR_INVALID_ARGUMENT, "eigs: L must be square, got %d x %d",
                            (int)l->n_rows, (int)l->n_cols);
    const dk_index n = l->n_rows;
    if (n < 2)
        return dk_error_set(err, DK_ERR_INVALID_ARGUMENT, "eigs: L is %d x %d, need n >= 2",
                            (int)n, (int)n);
    if (k < 1 || k >= n)
        return dk_error_set(err, DK_ERR_INVALID_ARGUMENT,
                            "eigs: k is %d, must be in [1, %d] (n - 1)", k, (int)n - 1);
    for (dk_index i = 0; i < n; i++)
        if (!(mass[i] > 0.0) || !isfinite(mass[i]))
            return dk_error_set(err, DK_ERR_INVALID_ARGUMENT,
                                "eigs: mass of vertex %d is %g, must be positive and finite",
                                (int)i, mass[i]);
    for (dk_index j = 0; j < n; j++)
        for (dk_index p = l->col_start[j]; p < l->col_start[j + 1]; p++) {
            const dk_index i = l->row_index[p];
            if (i < 0 || i >= n)
                return dk_error_set(err, DK_ERR_INDEX,
                                    "eigs: L column %d has row %d, out of range [0, %d)", (int)j,
                                    (int)i, (int)n);
            if (!isfinite(l->values[p]))
                return dk_error_set(err, DK_ERR_NONFINITE, "eigs: L(%d, %d) is not finite",
                                    (int)i, (int)j);
        }
    return DK_OK;
}

static int ncv_for(int nev, dk_index n, int attempt)
{
    int ncv = 2 * nev + 1;
    if (ncv < 20) ncv = 20;
    if (attempt > 0) ncv = 3 * nev + 10;
    if (ncv > n) ncv = (int)n;
    return ncv;
}

/* Appends pair j of the last ARPACK run (c->d, c->v) to the band store `s` (one block),
 * keeping it sorted. */
static void store_insert(store *s, const eig_ctx *c, int j)
{
    const size_t n = (size_t)c->n;
    int at = s->m;
    while (at > 0 && s->val[at - 1] > c->d[j]) at--;
    memmove(s->vec + (size_t)(at + 1) * n, s->vec + (size_t)at * n,
            (size_t)(s->m - at) * n * sizeof(double));
    memmove(s->val + at + 1, s->val + at, (size_t)(s->m - at) * sizeof(double));
    memcpy(s->vec + (size_t)at * n, c->v + (size_t)j * n, n * sizeof(double));
    s->val[at] = c->d[j];
    s->m++;
}

/* One ARPACK run around sigma; the converged pairs replace the contents of `bd`. */
static dk_status run_band(eig_ctx *c, dk_cholesky *chol, double sigma, int nev, int ncv,
                          store *bd, double *scratch, dk_error *err)
{
    int got = 0;
    dk_status st = arpack_run(c, chol, sigma, nev, ncv, NULL, 0, &got, scratch, err);
    bd->m = 0;
    for (int j = 0; j < got && bd->m < bd->cap; j++) store_insert(bd, c, j);
    return st;
}

/* Looks for eigenpairs that the run which filled `bd` missed (inertia said so): an ARPACK
 * run deflated against bd's vectors asks for `want` more pairs near sigma and those with an
 * eigenvalue in (lo, hi) are inserted. `*added` gets how many. */
static dk_status find_missing(eig_ctx *c, dk_cholesky *chol, double sigma, int want,
                              store *bd, double lo, double hi, int *added, double *scratch,
                              dk_error *err)
{
    *added = 0;
    if (want > bd->cap - bd->m) want = bd->cap - bd->m;
    if (want > c->n - 1 - bd->m) want = (int)c->n - 1 - bd->m;
    if (want < 1) return DK_OK;
    int got = 0;
    const int ncv = ncv_for(want, c->n - bd->m, 0);
    if (ncv <= want) return DK_OK;
    dk_status st = arpack_run(c, chol, sigma, want, ncv, bd->vec, bd->m, &got, scratch, err);
    if (st != DK_OK && st != DK_ERR_NO_CONVERGENCE) return st;
    for (int j = 0; j < got; j++)
        if (c->d[j] > lo && c->d[j] < hi && bd->m < bd->cap) {
            store_insert(bd, c, j);
            (*added)++;
        }
    return DK_OK;
}

/* Index j >= 1 (searching down from `from`) with val[j] - val[j-1] > gap_tol, or 0. */
static int gap_below(const double *val, int from, double gap_tol)
{
    int j = from;
    while (j > 0 && !(val[j] - val[j - 1] > gap_tol)) j--;
    return j;
}

/* Certifies a band: tau is put in the highest spectral gap (wider than gap_tol) of the
 * band's results `bd`, and an LDL' factorization of L - tau M counts the eigenvalues below
 * tau (inertia); the accepted pairs `s` merged with the band must hold exactly that many
 * below tau. Missing ones (copies of a multiple eigenvalue) are searched by deflated runs
 * around sigma (the band's shift, factor `chol`, refactored first when it is the LDL' one
 * that tau used). `*j_out` gets how many of bd's pairs lie below tau (those are certified),
 * or 0 when tau cannot be put above the accepted ones plus `min_above` (no progress).
 * Without a gap in the window, tau goes just above the window's top. */
static dk_status certify_band(eig_ctx *c, dk_cholesky *chol, double sigma, const store *s,
                              store *bd, double zeta, double gap_tol, double min_above,
                              int *j_out, double *scratch, dk_error *err)
{
    *j_out = 0;
    double lo_win = INFINITY, hi_win = -INFINITY;
    for (int i = 0; i < bd->m; i++) {
        lo_win = fmin(lo_win, bd->val[i]);
        hi_win = fmax(hi_win, bd->val[i]);
    }
    const double radius = fmax(fabs(sigma - lo_win), fabs(hi_win - sigma));
    for (int rep = 0;; rep++) {
        int j = gap_below(bd->val, bd->m - 1, gap_tol);
        double tau;
        if (j > 0 && bd->val[j - 1] > min_above) {
            tau = 0.5 * (bd->val[j] + bd->val[j - 1]);
        } else {
            /* No gap above the accepted ones inside the window (one cluster, or the top of
             * the spectrum): certify the whole window with tau just above its top; an
             * eigenvalue in between shows up as missing and is searched for. */
            j = bd->m;
            if (!(bd->val[j - 1] > min_above)) return DK_OK; /* no progress possible */
            tau = hi_win + fmax(gap_tol, 1e-8 * fabs(hi_win));
        }
        dk_index neg = 0;
        dk_status st = ctx_factor(c, tau, 1, &neg, err);
        if (st != DK_OK) return st;
        int below = 0;
        if (s->m > 0) {
            /* count with the band's pairs below tau only (those above are dropped) */
            const int m_full = bd->m;
            bd->m = j;
            st = merge_band(c, (store *)s, bd, zeta, tau, 0, &below, err);
            bd->m = m_full;
            if (st != DK_OK) return st;
        } else {
            below = j;
        }
        if (below == neg) {
            *j_out = j;
            return DK_OK;
        }
        if (below > neg || rep >= 2)
            return dk_error_set(err, DK_ERR_NO_CONVERGENCE,
                                "eigs: inertia check failed: %d eigenvalues below %g, %d found",
                                (int)neg, tau, below);
        if (chol == c->ldl) {
            st = ctx_factor(c, sigma, 1, NULL, err);
            if (st != DK_OK) return st;
        }
        int added = 0;
        st = find_missing(c, chol, sigma, (int)neg - below + 2, bd, sigma - radius * 1.0000001,
                          tau, &added, scratch, err);
        if (st != DK_OK) return st;
        if (added == 0)
            return dk_error_set(err, DK_ERR_NO_CONVERGENCE,
                                "eigs: inertia says %d eigenvalues below %g but only %d were "
                                "found, also with deflation", (int)neg, tau, below);
    }
}

/* The k smallest pairs of a connected L (or one whose components the caller could not
 * split off): the band-by-band search of the file comment. Inputs are checked. */
static dk_status smallest_connected(const dk_sparse *l, const double *mass, int k,
                                    const dk_eigs_options *opt, double *eigenvalues,
                                    double *eigenvectors, int *n_converged, dk_error *err)
{
    if (n_converged) *n_converged = 0;
    dk_status st = DK_OK;
    dk_eigs_options o;
    dk_eigs_options_default(&o);
    if (opt) {
        if (opt->tolerance > 0) o.tolerance = opt->tolerance;
        if (opt->max_iterations > 0) o.max_iterations = opt->max_iterations;
        if (opt->band_size > 0) o.band_size = opt->band_size;
        o.progress = opt->progress;
        o.progress_user = opt->progress_user;
    }
    if (o.band_size < MIN_BAND_SIZE) o.band_size = MIN_BAND_SIZE;

    const dk_index n = l->n_rows;
    eig_ctx c;
    memset(&c, 0, sizeof c);
    c.l = l;
    c.mass = mass;
    c.n = n;
    c.tol = o.tolerance;
    c.max_iterations = o.max_iterations;
    c.seed = 0x9E3779B97F4A7C15ull;
    c.progress = o.progress;
    c.progress_user = o.progress_user;
    store s = {0}, bd = {0};
    double *scratch = NULL;
    st = ctx_build_shifted(&c, err);
    if (st != DK_OK) goto done;

    /* spectrum scale: mean eigenvalue trace(M^-1 L) / n */
    double mean = 0.0;
    for (dk_index i = 0; i < n; i++) mean += c.l_diag[i] / mass[i];
    mean /= n;
    double total_mass = 0.0;
    for (dk_index i = 0; i < n; i++) total_mass += mass[i];
    if (!(mean > 0.0)) {
        st = dk_error_set(err, DK_ERR_INVALID_ARGUMENT, "eigs: L has no positive diagonal "
                          "(trace(M^-1 L) = %g): not a Laplacian", mean * n);
        goto done;
    }
    const double sigma0 = -1e-6 * mean;

    const int single = k <= o.band_size;
    const int nev0 = single ? (k + 1 < n ? k + 1 : k) : o.band_size;
    /* room for bands grown up to twice band_size (big clusters) plus deflated extras */
    bd.cap = (nev0 > 2 * o.band_size ? nev0 : 2 * o.band_size) + 32;
    if (bd.cap > n) bd.cap = (int)n;
    /* accepted pairs: bands stop adding new ones once k are there (plus a cluster's RR) */
    s.cap = single ? bd.cap : (k + 16 > bd.cap ? k + 16 : bd.cap);
    if (s.cap > n) s.cap = (int)n;
    /* the accepted store's first k columns are the output itself */
    s.n = bd.n = (size_t)n;
    s.split = s.cap < k ? s.cap : k;
    bd.split = bd.cap;
    s.val = malloc((size_t)s.cap * sizeof(double));
    s.vec = eigenvectors;
    s.extra = s.cap > s.split ? malloc((size_t)n * (size_t)(s.cap - s.split) * sizeof(double))
                              : NULL;
    bd.val = malloc((size_t)bd.cap * sizeof(double));
    bd.vec = malloc((size_t)n * bd.cap * sizeof(double));
    scratch = malloc((size_t)n * sizeof(double));
    if (!s.val || (s.cap > s.split && !s.extra) || !bd.val || !bd.vec || !scratch) {
        st = dk_error_set(err, DK_ERR_OUT_OF_MEMORY, "eigs: out of memory (%d vectors of %d)",
                          s.cap + bd.cap, (int)n);
        goto done;
    }

    /* ---- band 0: the smallest, with the positive definite shift */
    st = ctx_factor(&c, sigma0, 0, NULL, err);
    if (st != DK_OK) goto done;
    for (int attempt = 0;; attempt++) {
        st = run_band(&c, c.spd, sigma0, nev0, ncv_for(nev0, n, attempt), &bd, scratch, err);
        if (st == DK_ERR_NO_CONVERGENCE && attempt == 0) continue;
        break;
    }
    if (st == DK_OK) {
        int j = 0;
        st = certify_band(&c, c.spd, sigma0, &s, &bd, 0.0,
                          1e-6 * fmax(bd.m ? bd.val[bd.m - 1] : 0.0, 1e-6 * mean), -INFINITY,
                          &j, scratch, err);
        /* band mode keeps only the certified part; the next band overlaps the rest */
        if (st == DK_OK && !single && j > 0) bd.m = j;
    }
    memcpy(s.val, bd.val, (size_t)bd.m * sizeof(double));
    for (int j = 0; j < bd.m; j++)
        memcpy(scol(&s, j), bd.vec + (size_t)j * n, (size_t)n * sizeof(double));
    s.m = bd.m;
    /* band 0's positive definite factor is not used again (later shifts are LDL') */
    dk_cholesky_free(c.spd);
    c.spd = NULL;
    if (st != DK_OK) goto partial;
    c.fraction = fmin(1.0, (double)s.m / k);
    if (o.progress && o.progress(o.progress_user, c.fraction)) {
        st = dk_error_set(err, DK_ERR_CANCELLED, "eigs: cancelled after %d of %d eigenpairs",
                          s.m < k ? s.m : k, k);
        goto partial;
    }

    /* ---- later bands around interior shifts */
    for (int band = 1; s.m < k; band++) {
        const int need = k - s.m;
        int nev = o.band_size;
        const int ov = nev / 8 > 3 ? nev / 8 : 3; /* overlap (nev/5 measured ~10% slower) */
        if (need + ov + 4 < nev) nev = need + ov + 4;
        if (nev < 2 * ov + 4) nev = 2 * ov + 4;
        if (nev > o.band_size) nev = o.band_size;
        if (nev > n - 1) nev = (int)n - 1;
        const double top = s.val[s.m - 1];
        /* floor, for a degenerate start (a cluster of equal eigenvalues): half the spacing
         * Weyl's law gives for a surface of area A = sum(M), lambda_k ~ 4 pi k / A. (It was
         * trace(M^-1 L) / n^2, the mean spacing of the whole discrete spectrum, which a few
         * tiny triangles inflate: 4x the true spacing on the camelhead, whose every band
         * then started beyond its window and was redone with 2.3x the basis, 5 s for 300
         * pairs instead of ~2.) */
        const double delta = spacing(&s, nev / 2, 2.0 * PI / total_mass);
        const double zeta = 0.1 * delta + 100.0 * c.tol * fabs(top);
        double sigma = top + fmax(1.0, 0.5 * nev - ov) * delta;
        int accepted = 0;
        for (int attempt = 0; attempt < 8 && !accepted; attempt++) {
            st = ctx_factor(&c, sigma, 1, NULL, err);
            if (st != DK_OK) goto partial;
            st = run_band(&c, c.ldl, sigma, nev, ncv_for(nev, n, attempt > 0), &bd, scratch,
                          err);
            if (st == DK_ERR_NO_CONVERGENCE && attempt < 7) continue;
            if (st != DK_OK) goto partial;
            int j = 0;
            if (bd.val[0] < top - zeta) {
                /* progress: tau must lie above an eigenvalue distinct from lambda_top by
                 * more than the accuracy (duplicates of lambda_top agree to ~1e-10) */
                const double gap_tol = 1e-6 * fmax(bd.val[bd.m - 1], 1e-6 * mean);
                st = certify_band(&c, c.ldl, sigma, &s, &bd, zeta, gap_tol,
                                  top + 1e-3 * gap_tol, &j, scratch, err);
                if (st != DK_OK && st != DK_ERR_NO_CONVERGENCE) goto partial;
            }
            if (j == 0 || st != DK_OK) {
                /* The window does not reach back below lambda_top, holds no spectral gap
                 * above it (a dense cluster), or failed its inertia check: move the shift
                 * down next to lambda_top and widen the band, which must hold the whole
                 * cluster plus the overlap. */
                const double lo_win = bd.val[0], hi_win = bd.val[bd.m - 1];
                if (lo_win < top - zeta && hi_win <= top + 1e-9 * fmax(fabs(top), mean)) {
                    /* Nothing above lambda_top within the window's radius: a wide spectral
                     * gap (or the top of the spectrum). Jump the shift over the empty part;
                     * the next window then holds eigenvalues on both sides of the gap. */
                    sigma += fmax(sigma - lo_win, hi_win - sigma);
                    st = DK_OK;
                    continue;
                }
                if (lo_win >= top - zeta) sigma -= (lo_win - top) + ov * delta;
                if (sigma <= top) sigma = top + 0.5 * delta;
                nev += nev / 2;
                if (nev > bd.cap - 8) nev = bd.cap - 8;
                if (nev > n - 1) nev = (int)n - 1;
                if (st == DK_OK)
                    st = dk_error_set(err, DK_ERR_NO_CONVERGENCE, "eigs: band %d near lambda "
                                      "%g found no certifiable new eigenvalue", band, top);
                continue;
            }
            bd.m = j; /* keep the certified pairs, below tau */
            int below = 0;
            const int m_before = s.m;
            st = merge_band(&c, &s, &bd, zeta, 0.0, 1, &below, err);
            if (st != DK_OK) goto partial;
            if (s.m == m_before) { /* nothing new (cannot happen with a certified band) */
                nev += nev / 2;
                if (nev > bd.cap - 8) nev = bd.cap - 8;
                if (nev > n - 1) nev = (int)n - 1;
                st = dk_error_set(err, DK_ERR_NO_CONVERGENCE, "eigs: band %d near lambda %g "
                                  "added no eigenvalue", band, top);
                continue;
            }
            accepted = 1;
        }
        if (!accepted) {
            if (st == DK_OK)
                st = dk_error_set(err, DK_ERR_INTERNAL, "eigs: band %d not accepted", band);
            goto partial;
        }
        c.fraction = fmin(1.0, (double)s.m / k);
        if (o.progress && o.progress(o.progress_user, c.fraction)) {
            st = dk_error_set(err, DK_ERR_CANCELLED, "eigs: cancelled after %d of %d eigenpairs",
                              s.m < k ? s.m : k, k);
            goto partial;
        }
    }
    memcpy(eigenvalues, s.val, (size_t)k * sizeof(double));
    /* (the vectors are in place) */
    if (!single) {
        st = m_orthonormalise(mass, n, k, eigenvectors, err);
        if (st != DK_OK) goto done;
    }
    if (n_converged) *n_converged = k;
    dk_error_clear(err); /* drop messages of retried attempts */
    goto done;

partial: {
        /* Hand back what there is: the accepted pairs, ascending. */
        const int m = s.m < k ? s.m : k;
        if (m > 0) /* (the vectors are in place) */
            memcpy(eigenvalues, s.val, (size_t)m * sizeof(double));
        if (n_converged) *n_converged = m;
        if (st == DK_ERR_NO_CONVERGENCE)
            dk_error_prefix(err, "%d of %d eigenpairs converged", m, k);
    }
done:
    free(scratch);
    free(s.val);
    free(s.extra);
    free(bd.val);
    free(bd.vec);
    ctx_free(&c);
    return st;
}

/* ------------------------------------------------------------ disconnected L ----------- */

/* A disconnected mesh (the ogre: 44 components, 18 of them identical) has a block-diagonal
 * problem whose spectrum is the union of its components' spectra: eigenvalue 0 once per
 * component, and every eigenvalue of a component repeated once per identical copy. Lanczos
 * finds one vector per eigenspace (the rest only through rounding), so the band search
 * above, which relies on deflated reruns to pick up the missing copies, was left short:
 * the ogre subdivided twice failed its first band ("82 eigenvalues below 0.311", 33 of
 * them missing after the first run: the 44-fold eigenvalue 0, with a shift -1e-6 mean
 * that is only ~9 lambda_1 below it at that size; two deflated runs found 20 and 8, and
 * the check gave up after its third count), and 40 copies of a sphere failed a later band
 * at a 40-fold cluster. These multiplicities are the structure of the problem, not a
 * numerical accident, so the problem is split along it: each component is solved on its
 * own by the band search (which still handles a component's own multiple eigenvalues, a
 * sphere's for instance, as before), and how many of the k pairs each component holds is
 * read off the inertia: per component, the negative pivots of LDL' of L_c - tau M_c count
 * its eigenvalues below tau, and tau is moved (regula falsi on the counts, every third
 * step a bisection) until the counts sum to k. When the k-th eigenvalue is a copy shared
 * by several components (the counts jump past k over an interval narrower than 1e-10
 * relative), the copies are given to the components in order: which copies are taken is
 * arbitrary, as a basis inside an eigenspace cut by k is anyway. Components of at most
 * COMPONENT_DENSE_MAX vertices (or asked for more than half their spectrum) are solved
 * densely. The vectors are zero outside their component, hence exactly M-orthogonal
 * across components. Cost: one LDL' of every component per count (a few counts; one when a
 * single component holds every eigenvalue below the first guess, as with the loose
 * vertices' decoupled modes of docs/methods/eigen.md), then the components' own searches. */
#define COMPONENT_DENSE_MAX 400

typedef struct component {
    dk_index n, first;  /* vertices: order[first .. first + n), ascending               */
    dk_sparse l;        /* its block of L in local indices (sparse components)          */
    double *mass;
    double *dense_val;  /* all n eigenvalues (dense components)                         */
    eig_ctx ctx;        /* the counting factorizations (sparse components)              */
    int ctx_ready, cnt, cnt_lo, cnt_hi, k;
} component;

static int component_dense(const component *cp)
{
    return cp->n <= COMPONENT_DENSE_MAX;
}

/* All eigenpairs of a component densely (C = M^-1/2 L M^-1/2, x = M^-1/2 y): `val` gets
 * n ascending eigenvalues, `vec` (may be NULL: values only) n x n vectors. */
static dk_status component_dense_solve(const component *cp, double *val, double *vec,
                                       dk_error *err)
{
    const dk_index n = cp->n;
    double *a = calloc((size_t)n * (size_t)n, sizeof *a);
    if (!a) return dk_error_set(err, DK_ERR_OUT_OF_MEMORY, "eigs: out of memory (dense "
                                "component of %d vertices)", (int)n);
    for (dk_index j = 0; j < n; j++)
        for (dk_index p = cp->l.col_start[j]; p < cp->l.col_start[j + 1]; p++) {
            const dk_index i = cp->l.row_index[p];
            a[(size_t)j * n + i] = cp->l.values[p] / sqrt(cp->mass[i] * cp->mass[j]);
        }
    const int info = dk_lapack_dsyevd(vec ? 'V' : 'N', n, a, val);
    if (info != 0) {
        free(a);
        return dk_error_set(err, DK_ERR_NUMERIC, "eigs: dense eigensolver failed on a "
                            "component of %d vertices (LAPACK dsyevd info %d)", (int)n,
                            (int)info);
    }
    if (vec)
        for (dk_index j = 0; j < n; j++)
            for (dk_index i = 0; i < n; i++)
                vec[(size_t)j * n + i] = a[(size_t)j * n + i] / sqrt(cp->mass[i]);
    free(a);
    return DK_OK;
}

/* Each component's count of eigenvalues below tau (cp->cnt); `*total` their sum. */
static dk_status count_below_tau(component *cp, int nc, double tau, int *total, dk_error *err)
{
    *total = 0;
    for (int c = 0; c < nc; c++) {
        component *q = cp + c;
        if (q->dense_val) {
            q->cnt = count_below(q->dense_val, (int)q->n, tau);
        } else {
            if (!q->ctx_ready) {
                q->ctx.l = &q->l;
                q->ctx.mass = q->mass;
                q->ctx.n = q->n;
                q->ctx_ready = 1;
                dk_status st = ctx_build_shifted(&q->ctx, err);
                if (st != DK_OK) return st;
            }
            dk_index neg = 0;
            dk_status st = ctx_factor(&q->ctx, tau, 1, &neg, err);
            if (st != DK_OK)
                return dk_error_prefix(err, "eigs: counting the eigenvalues of a component of "
                                       "%d vertices below %g", (int)q->n, tau);
            q->cnt = (int)neg;
        }
        *total += q->cnt;
    }
    return DK_OK;
}

typedef struct sub_progress {
    dk_progress_fn fn;
    void *user;
    double done, share;
} sub_progress;

static int sub_progress_cb(void *user, double fraction)
{
    const sub_progress *p = user;
    return p->fn(p->user, p->done + p->share * fraction);
}

typedef struct val_index {
    double v;
    int i;
} val_index;

static int cmp_val_index(const void *a, const void *b)
{
    const val_index *x = a, *y = b;
    if (x->v != y->v) return x->v < y->v ? -1 : 1;
    return (x->i > y->i) - (x->i < y->i);
}

static dk_status smallest_by_components(const dk_sparse *l, const double *mass, int k,
                                        const dk_eigs_options *opt, const dk_index *label,
                                        int nc, double *eigenvalues, double *eigenvectors,
                                        dk_error *err)
{
    const dk_index n = l->n_rows;
    dk_status st = DK_OK;
    component *cp = calloc((size_t)nc, sizeof *cp);
    dk_index *order = malloc((size_t)n * sizeof *order);
    dk_index *loc = malloc((size_t)n * sizeof *loc);
    double *tmp = NULL;
    val_index *perm = NULL;
    if (!cp || !order || !loc) {
        st = dk_error_set(err, DK_ERR_OUT_OF_MEMORY, "eigs: out of memory (%d components)", nc);
        goto done;
    }
    /* the vertices of each component, ascending (counting sort by label) */
    for (dk_index v = 0; v < n; v++) cp[label[v]].n++;
    for (int c = 1; c < nc; c++) cp[c].first = cp[c - 1].first + cp[c - 1].n;
    for (int c = 0; c < nc; c++) cp[c].k = 0; /* (used as a fill counter below) */
    for (dk_index v = 0; v < n; v++) {
        component *q = cp + label[v];
        loc[v] = q->k;
        order[q->first + q->k++] = v;
    }
    double area = 0.0, gersh = 0.0;
    for (dk_index v = 0; v < n; v++) area += mass[v];
    for (int c = 0; c < nc; c++) {
        component *q = cp + c;
        q->k = 0;
        int64_t nnz = 0;
        for (dk_index a = 0; a < q->n; a++) {
            const dk_index j = order[q->first + a];
            nnz += l->col_start[j + 1] - l->col_start[j];
        }
        q->l.n_rows = q->l.n_cols = q->n;
        q->l.col_start = malloc(((size_t)q->n + 1) * sizeof(dk_index));
        q->l.row_index = malloc((size_t)(nnz > 0 ? nnz : 1) * sizeof(dk_index));
        q->l.values = malloc((size_t)(nnz > 0 ? nnz : 1) * sizeof(double));
        q->mass = malloc((size_t)q->n * sizeof(double));
        if (!q->l.col_start || !q->l.row_index || !q->l.values || !q->mass) {
            st = dk_error_set(err, DK_ERR_OUT_OF_MEMORY, "eigs: out of memory (components)");
            goto done;
        }
        dk_index w = 0;
        for (dk_index a = 0; a < q->n; a++) {
            const dk_index j = order[q->first + a];
            q->l.col_start[a] = w;
            q->mass[a] = mass[j];
            for (dk_index p = l->col_start[j]; p < l->col_start[j + 1]; p++) {
                q->l.row_index[w] = loc[l->row_index[p]];
                q->l.values[w++] = l->values[p];
                if (l->row_index[p] == j) gersh = fmax(gersh, 2.0 * fabs(l->values[p]) / mass[j]);
            }
        }
        q->l.col_start[q->n] = w;
        if (component_dense(q)) {
            q->dense_val = malloc((size_t)q->n * sizeof(double));
            if (!q->dense_val) {
                st = dk_error_set(err, DK_ERR_OUT_OF_MEMORY, "eigs: out of memory");
                goto done;
            }
            st = component_dense_solve(q, q->dense_val, NULL, err);
            if (st != DK_OK) goto done;
        }
    }

    /* ---- tau with k eigenvalues below it: the share of each component */
    {
        int clo = 0, chi = 0;
        double lo = 0.0; /* L is positive semidefinite: nothing below 0 */
        double hi = 8.0 * PI * k / area; /* twice Weyl's lambda_k ~ 4 pi k / area */
        const double top = 1.01 * gersh + DBL_MIN;
        if (hi > top) hi = top;
        for (int it = 0;; it++) {
            if (opt->progress && opt->progress(opt->progress_user, 0.0)) {
                st = dk_error_set(err, DK_ERR_CANCELLED, "eigs: cancelled");
                goto done;
            }
            st = count_below_tau(cp, nc, hi, &chi, err);
            if (st != DK_OK) goto done;
            for (int c = 0; c < nc; c++) cp[c].cnt_hi = cp[c].cnt;
            if (chi >= k) break;
            if (hi >= top || it > 64) {
                st = dk_error_set(err, DK_ERR_INTERNAL, "eigs: only %d eigenvalues below the "
                                  "Gershgorin bound %g, k is %d", chi, hi, k);
                goto done;
            }
            lo = hi;
            clo = chi;
            for (int c = 0; c < nc; c++) cp[c].cnt_lo = cp[c].cnt_hi;
            hi = fmin(2.0 * hi, top);
        }
        /* One component holding every eigenvalue below hi (the loose vertices' modes of
         * docs/methods/eigen.md sit above a Gershgorin bound): it alone holds the k
         * smallest, no need to pin tau down */
        int holders = 0;
        for (int c = 0; c < nc; c++) holders += cp[c].cnt_hi > 0;
        if (holders == 1)
            for (int c = 0; c < nc; c++)
                if (cp[c].cnt_hi > 0) {
                    cp[c].cnt_hi = k;
                    chi = k;
                }
        for (int it = 0; chi != k && hi - lo > 1e-10 * hi; it++) {
            if (opt->progress && opt->progress(opt->progress_user, 0.0)) {
                st = dk_error_set(err, DK_ERR_CANCELLED, "eigs: cancelled");
                goto done;
            }
            double t = 0.5 * (lo + hi);
            if (it % 3 != 2) { /* regula falsi on the counts, kept inside, every third bisection */
                t = lo + (hi - lo) * ((k + 0.5 - clo) / (double)(chi - clo));
                t = fmin(fmax(t, lo + 0.02 * (hi - lo)), hi - 0.02 * (hi - lo));
            }
            int ct = 0;
            st = count_below_tau(cp, nc, t, &ct, err);
            if (st != DK_OK) goto done;
            if (ct >= k) {
                hi = t;
                chi = ct;
                for (int c = 0; c < nc; c++) cp[c].cnt_hi = cp[c].cnt;
            } else {
                lo = t;
                clo = ct;
                for (int c = 0; c < nc; c++) cp[c].cnt_lo = cp[c].cnt;
            }
        }
        /* the factors were for counting only */
        for (int c = 0; c < nc; c++)
            if (cp[c].ctx_ready) {
                ctx_free(&cp[c].ctx);
                memset(&cp[c].ctx, 0, sizeof cp[c].ctx);
                cp[c].ctx_ready = 0;
            }
        if (chi == k) {
            for (int c = 0; c < nc; c++) cp[c].k = cp[c].cnt_hi;
        } else { /* the k-th eigenvalue is shared: its copies go to components in order */
            int rem = k - clo;
            for (int c = 0; c < nc; c++) {
                const int extra = cp[c].cnt_hi - cp[c].cnt_lo;
                const int add = extra < rem ? extra : rem;
                cp[c].k = cp[c].cnt_lo + add;
                rem -= add;
            }
        }
    }

    /* ---- each component's pairs, in the output columns [off, off + k_c): computed compact
     * (n_c x k_c, at the start of that region) then spread to full columns in place */
    int off = 0;
    for (int c = 0; c < nc; c++) {
        component *q = cp + c;
        if (q->k == 0) continue;
        const dk_index m = q->n;
        double *base = eigenvectors + (size_t)off * n;
        if (q->dense_val || q->k > m / 2) {
            tmp = malloc((size_t)m * (size_t)m * sizeof(double));
            double *val = q->dense_val ? q->dense_val : malloc((size_t)m * sizeof(double));
            if (!tmp || !val) {
                if (val != q->dense_val) free(val);
                st = dk_error_set(err, DK_ERR_OUT_OF_MEMORY, "eigs: out of memory (dense "
                                  "component of %d vertices)", (int)m);
                goto done;
            }
            st = component_dense_solve(q, val, tmp, err);
            if (st == DK_OK) {
                memcpy(eigenvalues + off, val, (size_t)q->k * sizeof(double));
                memcpy(base, tmp, (size_t)m * (size_t)q->k * sizeof(double));
            }
            if (val != q->dense_val) free(val);
            free(tmp);
            tmp = NULL;
            if (st != DK_OK) goto done;
        } else {
            dk_eigs_options o = *opt;
            sub_progress sp = {opt->progress, opt->progress_user, (double)off / k,
                               (double)q->k / k};
            if (opt->progress) {
                o.progress = sub_progress_cb;
                o.progress_user = &sp;
            }
            st = smallest_connected(&q->l, q->mass, q->k, &o, eigenvalues + off, base, NULL,
                                    err);
            if (st != DK_OK) {
                dk_error_prefix(err, "eigs: component %d of %d (%d vertices, %d pairs)", c + 1,
                                nc, (int)m, q->k);
                goto done;
            }
        }
        /* Spread: column j moves from base + j m to base + j n, row a to row order[..]. Done
         * from the last entry backwards, every write lands at or beyond the entries still
         * to be read (j n + r >= j m + a for the row r of local a, as r >= a). */
        for (int j = q->k - 1; j >= 0; j--) {
            const double *src = base + (size_t)j * m;
            double *dst = base + (size_t)j * n;
            dk_index a = m - 1;
            for (dk_index r = n - 1; r >= 0; r--) {
                if (a >= 0 && order[q->first + a] == r) {
                    const double x = src[a--];
                    dst[r] = x;
                } else {
                    dst[r] = 0.0;
                }
            }
        }
        off += q->k;
        if (opt->progress && opt->progress(opt->progress_user, (double)off / k)) {
            st = dk_error_set(err, DK_ERR_CANCELLED, "eigs: cancelled after %d of %d "
                              "eigenpairs", off, k);
            goto done;
        }
    }
    if (off != k) {
        st = dk_error_set(err, DK_ERR_INTERNAL, "eigs: components hold %d pairs, not %d", off, k);
        goto done;
    }

    /* ---- ascending overall: a permutation of the columns, applied cycle by cycle */
    perm = malloc((size_t)k * sizeof *perm);
    tmp = malloc((size_t)n * sizeof(double));
    if (!perm || !tmp) {
        st = dk_error_set(err, DK_ERR_OUT_OF_MEMORY, "eigs: out of memory");
        goto done;
    }
    for (int j = 0; j < k; j++) {
        perm[j].v = eigenvalues[j];
        perm[j].i = j;
    }
    qsort(perm, (size_t)k, sizeof *perm, cmp_val_index);
    for (int j = 0; j < k; j++) eigenvalues[j] = perm[j].v;
    for (int s0 = 0; s0 < k; s0++) {
        if (perm[s0].i < 0 || perm[s0].i == s0) continue;
        memcpy(tmp, eigenvectors + (size_t)s0 * n, (size_t)n * sizeof(double));
        int j = s0;
        for (;;) {
            const int from = perm[j].i;
            perm[j].i = -1;
            if (from == s0) {
                memcpy(eigenvectors + (size_t)j * n, tmp, (size_t)n * sizeof(double));
                break;
            }
            memcpy(eigenvectors + (size_t)j * n, eigenvectors + (size_t)from * n,
                   (size_t)n * sizeof(double));
            j = from;
        }
    }
done:
    if (cp)
        for (int c = 0; c < nc; c++) {
            free(cp[c].l.col_start);
            free(cp[c].l.row_index);
            free(cp[c].l.values);
            free(cp[c].mass);
            free(cp[c].dense_val);
            if (cp[c].ctx_ready) ctx_free(&cp[c].ctx);
        }
    free(cp);
    free(order);
    free(loc);
    free(tmp);
    free(perm);
    return st;
}

/* Connected components of L's graph: `label` (n) gets each vertex's, `*nc` their number. */
static dk_status components_of(const dk_sparse *l, dk_index *label, int *nc, dk_error *err)
{
    const dk_index n = l->n_rows;
    dk_index *queue = malloc((size_t)n * sizeof *queue);
    if (!queue) return dk_error_set(err, DK_ERR_OUT_OF_MEMORY, "eigs: out of memory");
    for (dk_index v = 0; v < n; v++) label[v] = -1;
    int c = 0;
    for (dk_index s = 0; s < n; s++) {
        if (label[s] >= 0) continue;
        dk_index head = 0, tail = 0;
        queue[tail++] = s;
        label[s] = c;
        while (head < tail) {
            const dk_index j = queue[head++];
            for (dk_index p = l->col_start[j]; p < l->col_start[j + 1]; p++) {
                const dk_index i = l->row_index[p];
                if (label[i] < 0) {
                    label[i] = c;
                    queue[tail++] = i;
                }
            }
        }
        c++;
    }
    free(queue);
    *nc = c;
    return DK_OK;
}

dk_status dk_eigs_smallest(const dk_sparse *l, const double *mass, int k,
                           const dk_eigs_options *opt, double *eigenvalues,
                           double *eigenvectors, int *n_converged, dk_error *err)
{
    if (n_converged) *n_converged = 0;
    dk_status st = check_inputs(l, mass, k, eigenvalues, eigenvectors, err);
    if (st != DK_OK) return st;
    dk_index *label = malloc((size_t)l->n_rows * sizeof *label);
    if (!label) return dk_error_set(err, DK_ERR_OUT_OF_MEMORY, "eigs: out of memory");
    int nc = 1;
    st = components_of(l, label, &nc, err);
    if (st == DK_OK && nc == 1) {
        free(label);
        return smallest_connected(l, mass, k, opt, eigenvalues, eigenvectors, n_converged, err);
    }
    if (st == DK_OK) {
        dk_eigs_options o;
        dk_eigs_options_default(&o);
        if (opt) o = *opt;
        st = smallest_by_components(l, mass, k, &o, label, nc, eigenvalues, eigenvectors, err);
        if (st == DK_OK && n_converged) *n_converged = k;
    }
    free(label);
    return st;
}
