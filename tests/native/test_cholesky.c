/* Tests of the CHOLMOD wrapper (dk_cholesky.h): dense LAPACK reference solves, not positive
 * definite detection, refactorization reuse, several right-hand sides, big-matrix residuals,
 * LDL' inertia, argument checking. */
#define _POSIX_C_SOURCE 199309L /* clock_gettime */
#include <dlfcn.h>
#include <lapacke.h>
#include <math.h>
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <time.h>

#include "dk_cholesky.h"
#include "dk_test.h"


#if defined(__SANITIZE_ADDRESS__)
#define SANITIZED 1
#elif defined(__has_feature)
#if __has_feature(address_sanitizer)
#define SANITIZED 1
#endif
#endif
#ifndef SANITIZED
#define SANITIZED 0
#endif

/* ------------------------------------------------------------------ test-local helpers -- */

static uint64_t rng_state = 88172645463325252ull;
static double rnd(void) /* uniform in [-1, 1) */
{
    rng_state ^= rng_state << 13;
    rng_state ^= rng_state >> 7;
    rng_state ^= rng_state << 17;
    return (double)(rng_state >> 11) / 9007199254740992.0 * 2.0 - 1.0;
}

static double now(void)
{
    struct timespec t;
    clock_gettime(CLOCK_MONOTONIC, &t);
    return (double)t.tv_sec + 1e-9 * (double)t.tv_nsec;
}

/* A CSC matrix owned by the test (independent of the core's dk_sparse functions). */
static dk_sparse *csc_new(dk_index n, int64_t nnz)
{
    dk_sparse *a = calloc(1, sizeof *a);
    if (!a) return NULL;
    a->n_rows = a->n_cols = n;
    a->col_start = calloc((size_t)n + 1, sizeof(dk_index));
    a->row_index = malloc((size_t)(nnz ? nnz : 1) * sizeof(dk_index));
    a->values = malloc((size_t)(nnz ? nnz : 1) * sizeof(double));
    if (!a->col_start || !a->row_index || !a->values) {
        free(a->col_start); free(a->row_index); free(a->values); free(a);
        return NULL;
    }
    return a;
}

static void csc_free(dk_sparse *a)
{
    if (!a) return;
    free(a->col_start); free(a->row_index); free(a->values); free(a);
}

/* CSC of the non-zeros of a dense column-major n x n matrix. */
static dk_sparse *csc_from_dense(const double *d, dk_index n)
{
    int64_t nnz = 0;
    for (int64_t k = 0; k < (int64_t)n * n; k++) nnz += d[k] != 0.0;
    dk_sparse *a = csc_new(n, nnz);
    if (!a) return NULL;
    dk_index p = 0;
    for (dk_index j = 0; j < n; j++) {
        a->col_start[j] = p;
        for (dk_index i = 0; i < n; i++)
            if (d[(size_t)j * n + i] != 0.0) {
                a->row_index[p] = i;
                a->values[p++] = d[(size_t)j * n + i];
            }
    }
    a->col_start[n] = p;
    return a;
}

/* y = A x with both triangles stored. */
static void csc_matvec(const dk_sparse *a, const double *x, double *y)
{
    memset(y, 0, (size_t)a->n_rows * sizeof(double));
    for (dk_index j = 0; j < a->n_cols; j++)
        for (dk_index p = a->col_start[j]; p < a->col_start[j + 1]; p++)
            y[a->row_index[p]] += a->values[p] * x[j];
}

/* Graph Laplacian of an nx x ny x nz grid (7-point stencil; nz = 1 gives the 2D 5-point
 * one) plus `diag[i]` on the diagonal: symmetric, both triangles, rows sorted. */
static dk_sparse *grid_laplacian(int nx, int ny, int nz, const double *diag)
{
    const dk_index n = (dk_index)nx * ny * nz;
    dk_sparse *a = csc_new(n, (int64_t)n * 7);
    if (!a) return NULL;
    dk_index p = 0;
    for (int z = 0; z < nz; z++)
        for (int y = 0; y < ny; y++)
            for (int x = 0; x < nx; x++) {
                const dk_index j = (dk_index)((z * ny + y) * nx + x);
                a->col_start[j] = p;
                dk_index nb[6];
                int m = 0;
                /* in ascending index order */
                if (z > 0) nb[m++] = j - nx * ny;
                if (y > 0) nb[m++] = j - nx;
                if (x > 0) nb[m++] = j - 1;
                const int below = m;
                if (x < nx - 1) nb[m++] = j + 1;
                if (y < ny - 1) nb[m++] = j + nx;
                if (z < nz - 1) nb[m++] = j + nx * ny;
                for (int k = 0; k < below; k++) { a->row_index[p] = nb[k]; a->values[p++] = -1.0; }
                a->row_index[p] = j;
                a->values[p++] = (double)m + (diag ? diag[j] : 0.0);
                for (int k = below; k < m; k++) { a->row_index[p] = nb[k]; a->values[p++] = -1.0; }
            }
    a->col_start[n] = p;
    return a;
}

/* ||A x - b||_2 / ||b||_2 for column `c` of multi-RHS arrays. */
static double rel_residual(const dk_sparse *a, const double *x, const double *b)
{
    const dk_index n = a->n_rows;
    double *r = malloc((size_t)n * sizeof(double));
    if (!r) return INFINITY;
    csc_matvec(a, x, r);
    double num = 0, den = 0;
    for (dk_index i = 0; i < n; i++) {
        num += (r[i] - b[i]) * (r[i] - b[i]);
        den += b[i] * b[i];
    }
    free(r);
    return sqrt(num) / sqrt(den);
}

/* A random sparse SPD matrix (dense column-major storage): random symmetric sparse
 * off-diagonals, diagonal = row sum of |off-diagonals| + 0.5 (strictly diagonally dominant). */
static void random_spd_dense(double *d, int n, double density)
{
    memset(d, 0, sizeof(double) * (size_t)n * n);
    for (int j = 0; j < n; j++)
        for (int i = j + 1; i < n; i++)
            if (fabs(rnd()) < density) {
                const double v = rnd();
                d[(size_t)j * n + i] = v;
                d[(size_t)i * n + j] = v;
            }
    for (int i = 0; i < n; i++) {
        double s = 0;
        for (int j = 0; j < n; j++) s += fabs(d[(size_t)j * n + i]);
        d[(size_t)i * n + i] = s + 0.5 + 0.5 * fabs(rnd());
    }
}

/* -------------------------------------------------------------------------- the tests -- */

static void test_small_against_lapack(void)
{
    enum { N = 40, NRHS = 3 };
    double *d = malloc(sizeof(double) * N * N), *f = malloc(sizeof(double) * N * N);
    double b[N * NRHS], xr[N * NRHS], x[N * NRHS];
    CHECK(d && f);
    if (!d || !f) { free(d); free(f); return; }
    random_spd_dense(d, N, 0.15);
    memcpy(f, d, sizeof(double) * N * N);
    for (int k = 0; k < N * NRHS; k++) b[k] = rnd();
    memcpy(xr, b, sizeof b);
    CHECK(LAPACKE_dpotrf(LAPACK_COL_MAJOR, 'L', N, f, N) == 0);
    CHECK(LAPACKE_dpotrs(LAPACK_COL_MAJOR, 'L', N, NRHS, f, N, xr, N) == 0);

    dk_sparse *a = csc_from_dense(d, N);
    CHECK(a != NULL);
    dk_error err = {0};
    dk_cholesky *ch = NULL;
    CHECK(dk_cholesky_analyze(a, &ch, &err) == DK_OK);
    CHECK(ch && dk_cholesky_size(ch) == N);
    CHECK(dk_cholesky_analysis_count(ch) == 1 && dk_cholesky_factorization_count(ch) == 0);
    /* solving before any factorization is refused */
    CHECK(dk_cholesky_solve(ch, b, 1, x, &err) == DK_ERR_INVALID_ARGUMENT);
    CHECK_MSG(dk_cholesky_factorize(ch, a, &err) == DK_OK, "%s", err.message);
    CHECK(dk_cholesky_solve(ch, b, NRHS, x, &err) == DK_OK);
    double maxdiff = 0, maxref = 0;
    for (int k = 0; k < N * NRHS; k++) {
        maxdiff = fmax(maxdiff, fabs(x[k] - xr[k]));
        maxref = fmax(maxref, fabs(xr[k]));
    }
    CHECK_MSG(maxdiff <= 1e-12 * maxref, "max diff %g (max |x| %g)", maxdiff, maxref);
    CHECK(dk_cholesky_memory(ch) > sizeof(double) * N);
    dk_cholesky_free(ch);
    csc_free(a);
    free(d);
    free(f);
}

static void test_not_positive_definite(void)
{
    /* 1D Laplacian plus identity, with column 7 made negative and decoupled: Cholesky must
     * fail there and the message must name the column. */
    enum { N = 12 };
    double d[N * N] = {0};
    for (int i = 0; i < N; i++) {
        d[i * N + i] = 3.0;
        if (i + 1 < N && i != 6 && i != 7) { d[i * N + i + 1] = -1; d[(i + 1) * N + i] = -1; }
    }
    d[7 * N + 7] = -2.0;
    dk_sparse *a = csc_from_dense(d, N);
    dk_error err = {0};
    dk_cholesky *ch = NULL;
    CHECK(dk_cholesky_analyze(a, &ch, &err) == DK_OK);
    dk_status st = dk_cholesky_factorize(ch, a, &err);
    CHECK(st == DK_ERR_NOT_POSITIVE_DEFINITE);
    CHECK(err.status == DK_ERR_NOT_POSITIVE_DEFINITE);
    CHECK_MSG(strstr(err.message, "not positive definite") != NULL, "%s", err.message);
    CHECK_MSG(strstr(err.message, "column 7)") != NULL, "%s", err.message);
    double b[N], x[N];
    for (int i = 0; i < N; i++) b[i] = 1.0;
    /* no solve after a failed factorization */
    CHECK(dk_cholesky_solve(ch, b, 1, x, &err) == DK_ERR_INVALID_ARGUMENT);

    /* the same object recovers with positive values on the same pattern */
    a->values[a->col_start[7]] = 2.0;
    err = (dk_error){0};
    CHECK_MSG(dk_cholesky_factorize(ch, a, &err) == DK_OK, "%s", err.message);
    CHECK(dk_cholesky_solve(ch, b, 1, x, &err) == DK_OK);
    CHECK(rel_residual(a, x, b) < 1e-14);
    CHECK(dk_cholesky_analysis_count(ch) == 1 && dk_cholesky_factorization_count(ch) == 2);
    dk_cholesky_free(ch);

    /* negative definite from the start: the first pivot column is named */
    for (int p = 0; p < a->col_start[N]; p++) a->values[p] = -a->values[p];
    CHECK(dk_cholesky_analyze(a, &ch, &err) == DK_OK);
    CHECK(dk_cholesky_factorize(ch, a, &err) == DK_ERR_NOT_POSITIVE_DEFINITE);
    CHECK(strstr(err.message, "matrix column") != NULL);
    dk_cholesky_free(ch);
    csc_free(a);
}

static void test_not_positive_definite_supernodal(void)
{
    /* A 3D grid has enough fill for CHOLMOD's supernodal path: an indefinite shift must be
     * reported there too, and the object must recover on the next factorization. */
    const int m = SANITIZED ? 16 : 24;
    const dk_index n = m * m * m;
    double *diag = malloc(sizeof(double) * n), *b = malloc(sizeof(double) * n);
    double *x = malloc(sizeof(double) * n);
    CHECK(diag && b && x);
    if (diag && b && x) {
        for (dk_index i = 0; i < n; i++) { diag[i] = -0.5; b[i] = rnd(); }
        dk_sparse *a = grid_laplacian(m, m, m, diag);
        dk_error err = {0};
        dk_cholesky *ch = NULL;
        /* the factorization's serial OpenMP scope (dk_openmp_serial_begin) restores the
         * thread's setting on every path, the failing one too */
        int (*get_levels)(void) = NULL;
        void (*set_levels)(int) = NULL;
        void *gomp = dlopen("libgomp.so.1", RTLD_NOW);
        void *gs = gomp ? dlsym(gomp, "omp_get_max_active_levels") : NULL;
        void *ss = gomp ? dlsym(gomp, "omp_set_max_active_levels") : NULL;
        CHECK_MSG(gs && ss, "libgomp.so.1 (CHOLMOD's OpenMP runtime) not found");
        int levels_before = 0;
        if (gs && ss) {
            memcpy(&get_levels, &gs, sizeof get_levels);
            memcpy(&set_levels, &ss, sizeof set_levels);
            levels_before = get_levels();
            set_levels(3);
        }
        CHECK(dk_cholesky_analyze(a, &ch, &err) == DK_OK);
        CHECK(dk_cholesky_is_supernodal(ch));
        CHECK(dk_cholesky_factorize(ch, a, &err) == DK_ERR_NOT_POSITIVE_DEFINITE);
        if (get_levels)
            CHECK_MSG(get_levels() == 3, "levels %d after a failed factorization", get_levels());
        CHECK_MSG(strstr(err.message, "not positive definite") != NULL, "%s", err.message);
        CHECK(dk_cholesky_solve(ch, b, 1, x, &err) == DK_ERR_INVALID_ARGUMENT);
        for (dk_index j = 0; j < n; j++)
            for (dk_index p = a->col_start[j]; p < a->col_start[j + 1]; p++)
                if (a->row_index[p] == j) a->values[p] += 0.75;
        CHECK_MSG(dk_cholesky_factorize(ch, a, &err) == DK_OK, "%s", err.message);
        if (get_levels) {
            CHECK_MSG(get_levels() == 3, "levels %d after a factorization", get_levels());
            set_levels(levels_before);
        }
        if (gomp)
            dlclose(gomp);
        CHECK(dk_cholesky_solve(ch, b, 1, x, &err) == DK_OK);
        CHECK(rel_residual(a, x, b) < 1e-12);
        dk_cholesky_free(ch);
        csc_free(a);
    }
    free(diag); free(b); free(x);
}

static void test_refactorize_and_multi_rhs(void)
{
    const int nx = 30, ny = 20;
    const dk_index n = nx * ny;
    double *diag = malloc(sizeof(double) * n);
    double *b = malloc(sizeof(double) * n * 4), *x = malloc(sizeof(double) * n * 4);
    double *x1 = malloc(sizeof(double) * n);
    CHECK(diag && b && x && x1);
    if (!diag || !b || !x || !x1) { free(diag); free(b); free(x); free(x1); return; }
    for (dk_index i = 0; i < n; i++) diag[i] = 0.01;
    dk_sparse *a = grid_laplacian(nx, ny, 1, diag);
    dk_error err = {0};
    dk_cholesky *ch = NULL;
    CHECK(dk_cholesky_analyze(a, &ch, &err) == DK_OK);
    CHECK(dk_cholesky_factorize(ch, a, &err) == DK_OK);
    for (dk_index k = 0; k < n * 4; k++) b[k] = rnd();

    /* 3 right-hand sides at once == 3 single solves, each with a tiny residual */
    CHECK(dk_cholesky_solve(ch, b, 3, x, &err) == DK_OK);
    for (int c = 0; c < 3; c++) {
        CHECK(rel_residual(a, x + (size_t)c * n, b + (size_t)c * n) < 1e-12);
        CHECK(dk_cholesky_solve(ch, b + (size_t)c * n, 1, x1, &err) == DK_OK);
        double md = 0;
        for (dk_index i = 0; i < n; i++) md = fmax(md, fabs(x1[i] - x[(size_t)c * n + i]));
        CHECK_MSG(md < 1e-12, "multi vs single RHS differ by %g", md);
    }
    /* 4 then 3 again (workspace re-shaped both ways) */
    CHECK(dk_cholesky_solve(ch, b, 4, x, &err) == DK_OK);
    CHECK(rel_residual(a, x + 3 * (size_t)n, b + 3 * (size_t)n) < 1e-12);
    /* x aliasing b */
    double *bb = malloc(sizeof(double) * n * 3);
    CHECK(bb != NULL);
    if (bb) {
        memcpy(bb, b, sizeof(double) * n * 3);
        CHECK(dk_cholesky_solve(ch, bb, 3, bb, &err) == DK_OK);
        for (int c = 0; c < 3; c++)
            CHECK(rel_residual(a, bb + (size_t)c * n, b + (size_t)c * n) < 1e-12);
        free(bb);
    }

    /* new values, same pattern: a stiffer diagonal and scaled off-diagonals */
    for (dk_index j = 0; j < n; j++)
        for (dk_index p = a->col_start[j]; p < a->col_start[j + 1]; p++)
            a->values[p] = a->row_index[p] == j ? a->values[p] * 2.0 + (double)(j % 7)
                                                : a->values[p] * 1.5;
    CHECK(dk_cholesky_factorize(ch, a, &err) == DK_OK);
    CHECK(dk_cholesky_analysis_count(ch) == 1);
    CHECK(dk_cholesky_factorization_count(ch) == 2);
    CHECK(dk_cholesky_solve(ch, b, 3, x, &err) == DK_OK);
    for (int c = 0; c < 3; c++)
        CHECK(rel_residual(a, x + (size_t)c * n, b + (size_t)c * n) < 1e-12);

    /* a different pattern is refused (would otherwise factor garbage) */
    dk_sparse *other = grid_laplacian(ny, nx, 1, diag);
    CHECK(dk_cholesky_factorize(ch, other, &err) == DK_ERR_INVALID_ARGUMENT);
    CHECK(strstr(err.message, "pattern") != NULL);
    dk_sparse *small = grid_laplacian(5, 5, 1, diag);
    CHECK(dk_cholesky_factorize(ch, small, &err) == DK_ERR_INVALID_ARGUMENT);
    csc_free(other);
    csc_free(small);
    dk_cholesky_free(ch);
    csc_free(a);
    free(diag); free(b); free(x); free(x1);
}

static void test_bad_arguments(void)
{
    dk_error err = {0};
    dk_cholesky *ch = (dk_cholesky *)&err; /* must be reset to NULL on failure */
    CHECK(dk_cholesky_analyze(NULL, &ch, &err) == DK_ERR_INVALID_ARGUMENT);
    CHECK(ch == NULL);
    double d[9] = {2, -1, 0, -1, 2, -1, 0, -1, 2};
    dk_sparse *a = csc_from_dense(d, 3);
    a->n_rows = 2;
    CHECK(dk_cholesky_analyze(a, &ch, &err) == DK_ERR_INVALID_ARGUMENT);
    a->n_rows = 3;
    a->row_index[1] = 7; /* out of range */
    CHECK(dk_cholesky_analyze(a, &ch, &err) == DK_ERR_INDEX);
    a->row_index[1] = 1;
    a->values[4] = NAN;
    CHECK(dk_cholesky_analyze(a, &ch, &err) == DK_ERR_NONFINITE);
    a->values[4] = 2;
    const dk_index r0 = a->row_index[0];
    a->row_index[0] = a->row_index[1];
    a->row_index[1] = r0; /* unsorted column */
    CHECK(dk_cholesky_analyze(a, &ch, &err) == DK_ERR_INVALID_ARGUMENT);
    a->row_index[1] = a->row_index[0];
    a->row_index[0] = r0;
    CHECK(dk_cholesky_analyze(a, &ch, &err) == DK_OK);
    CHECK(dk_cholesky_factorize(ch, a, &err) == DK_OK);
    double b[3] = {1, 2, 3}, x[3];
    CHECK(dk_cholesky_solve(ch, b, 0, x, &err) == DK_ERR_INVALID_ARGUMENT);
    CHECK(dk_cholesky_solve(ch, NULL, 1, x, &err) == DK_ERR_INVALID_ARGUMENT);
    CHECK(dk_cholesky_factorize(NULL, a, &err) == DK_ERR_INVALID_ARGUMENT);
    /* a NaN in a later factorization is caught before CHOLMOD sees it */
    a->values[0] = INFINITY;
    CHECK(dk_cholesky_factorize(ch, a, &err) == DK_ERR_NONFINITE);
    CHECK(dk_cholesky_solve(ch, b, 1, x, &err) == DK_ERR_INVALID_ARGUMENT);
    dk_cholesky_free(ch);
    dk_cholesky_free(NULL);
    csc_free(a);
}

static void test_indefinite_inertia(void)
{
    /* L - sigma I for a 2D grid Laplacian: LDL' solves accurately and the negative pivots
     * count the eigenvalues below sigma (compared with a dense LAPACK eigen solve). */
    const int nx = 12, ny = 9;
    const dk_index n = nx * ny;
    const double sigma = 1.2345;
    double *diag = malloc(sizeof(double) * n), *dense = calloc((size_t)n * n, sizeof(double));
    double *w = malloc(sizeof(double) * n), *b = malloc(sizeof(double) * n * 2);
    double *x = malloc(sizeof(double) * n * 2);
    CHECK(diag && dense && w && b && x);
    if (!diag || !dense || !w || !b || !x) goto done;
    for (dk_index i = 0; i < n; i++) diag[i] = -sigma;
    dk_sparse *a = grid_laplacian(nx, ny, 1, diag);
    for (dk_index j = 0; j < n; j++)
        for (dk_index p = a->col_start[j]; p < a->col_start[j + 1]; p++)
            dense[(size_t)j * n + a->row_index[p]] = a->values[p];
    CHECK(LAPACKE_dsyev(LAPACK_COL_MAJOR, 'N', 'U', n, dense, n, w) == 0);
    dk_index expected = 0;
    for (dk_index i = 0; i < n; i++) expected += w[i] < 0;
    CHECK(expected > 3 && expected < n - 3);

    dk_error err = {0};
    dk_cholesky *ch = NULL, *spd = NULL;
    CHECK(dk_cholesky_analyze_indefinite(a, &ch, &err) == DK_OK);
    CHECK_MSG(dk_cholesky_factorize(ch, a, &err) == DK_OK, "%s", err.message);
    dk_index neg = -1;
    CHECK(dk_cholesky_negative_pivots(ch, &neg, &err) == DK_OK);
    CHECK_MSG(neg == expected, "negative pivots %d, eigenvalues below sigma %d", (int)neg,
              (int)expected);
    for (dk_index k = 0; k < 2 * n; k++) b[k] = rnd();
    CHECK(dk_cholesky_solve(ch, b, 2, x, &err) == DK_OK);
    CHECK(rel_residual(a, x, b) < 1e-10);
    CHECK(rel_residual(a, x + n, b + n) < 1e-10);
    /* the SPD wrapper refuses the same matrix */
    CHECK(dk_cholesky_analyze(a, &spd, &err) == DK_OK);
    CHECK(dk_cholesky_factorize(spd, a, &err) == DK_ERR_NOT_POSITIVE_DEFINITE);
    /* an SPD factor has no negative pivots */
    for (dk_index j = 0; j < n; j++)
        for (dk_index p = a->col_start[j]; p < a->col_start[j + 1]; p++)
            if (a->row_index[p] == j) a->values[p] += sigma + 0.5;
    CHECK(dk_cholesky_factorize(spd, a, &err) == DK_OK);
    CHECK(dk_cholesky_negative_pivots(spd, &neg, &err) == DK_OK && neg == 0);
    CHECK(dk_cholesky_factorize(ch, a, &err) == DK_OK);
    CHECK(dk_cholesky_negative_pivots(ch, &neg, &err) == DK_OK && neg == 0);
    dk_cholesky_free(spd);
    dk_cholesky_free(ch);
    csc_free(a);
done:
    free(diag); free(dense); free(w); free(b); free(x);
}

/* A big constrained Laplacian: L + diag(1e3 on every 97th vertex, 1e-8 * mean diag
 * elsewhere); random right-hand sides must have relative residual below 1e-10. */
static void check_big_constrained(dk_sparse *l, const char *name)
{
    const dk_index n = l->n_rows;
    double mean = 0;
    for (dk_index j = 0; j < n; j++)
        for (dk_index p = l->col_start[j]; p < l->col_start[j + 1]; p++)
            if (l->row_index[p] == j) mean += l->values[p] / n;
    for (dk_index j = 0; j < n; j++)
        for (dk_index p = l->col_start[j]; p < l->col_start[j + 1]; p++)
            if (l->row_index[p] == j) l->values[p] += (j % 97 == 0) ? 1e3 : 1e-8 * mean;
    double *b = malloc(sizeof(double) * n * 3), *x = malloc(sizeof(double) * n * 3);
    CHECK(b && x);
    if (b && x) {
        for (dk_index k = 0; k < 3 * n; k++) b[k] = rnd();
        dk_error err = {0};
        dk_cholesky *ch = NULL;
        const double t0 = now();
        CHECK(dk_cholesky_analyze(l, &ch, &err) == DK_OK);
        const double t1 = now();
        CHECK_MSG(dk_cholesky_factorize(ch, l, &err) == DK_OK, "%s", err.message);
        const double t2 = now();
        CHECK(dk_cholesky_solve(ch, b, 3, x, &err) == DK_OK);
        const double t3 = now();
        double worst = 0;
        for (int c = 0; c < 3; c++)
            worst = fmax(worst, rel_residual(l, x + (size_t)c * n, b + (size_t)c * n));
        CHECK_MSG(worst < 1e-10, "%s: relative residual %g", name, worst);
        printf("%s: n=%d analyze %.3f s, factorize %.3f s, 3-RHS solve %.2f ms, residual %.2e, "
               "memory %.1f MB\n", name, (int)n, t1 - t0, t2 - t1, 1e3 * (t3 - t2), worst,
               (double)dk_cholesky_memory(ch) / 1048576.0);
        dk_cholesky_free(ch);
    }
    free(b);
    free(x);
}

static void test_big_grid(void)
{
    /* 3D grids fill in much more than surface meshes: a hard case for the supernodal code */
    dk_sparse *l = SANITIZED ? grid_laplacian(14, 14, 14, NULL) : grid_laplacian(30, 30, 30, NULL);
    CHECK(l != NULL);
    if (l) check_big_constrained(l, "3D grid Laplacian");
    csc_free(l);
    l = SANITIZED ? grid_laplacian(60, 60, 1, NULL) : grid_laplacian(200, 200, 1, NULL);
    if (l) check_big_constrained(l, "2D grid Laplacian");
    csc_free(l);
}

/* Two-thread substitutions (dk_trisolve) against cholmod_solve2 on the same factor: an SPD
 * 2D grid (simplicial LL'), a 3D grid (supernodal LL') and an indefinite shifted 2D grid
 * (simplicial LDL'), for 1..6 right-hand sides (the specialised and the generic kernels),
 * 7, 11 and 16 (solved in blocks of at most 6), 17 (beyond the plan: cholmod_solve2), and in
 * place (x aliasing b; 3 and 11 columns). */
static void check_parallel(dk_sparse *a, int indefinite, const char *name)
{
    const dk_index n = a->n_rows;
    dk_error err = {0};
    dk_cholesky *ch = NULL;
    const int ok = (indefinite ? dk_cholesky_analyze_indefinite(a, &ch, &err)
                               : dk_cholesky_analyze(a, &ch, &err)) == DK_OK &&
                   dk_cholesky_factorize(ch, a, &err) == DK_OK;
    CHECK_MSG(ok, "%s: %s", name, err.message);
    if (!ok) {
        dk_cholesky_free(ch);
        return;
    }
    const double speedup = dk_cholesky_parallel_speedup(ch);
    CHECK_MSG(speedup >= 1.25, "%s: no two-thread plan (estimated speed-up %.2f)", name, speedup);
    static const int counts[] = {1, 2, 3, 4, 5, 6, 7, 11, 16, 17};
    double *b = malloc(sizeof(double) * (size_t)n * 17), *x = malloc(sizeof(double) * (size_t)n * 17),
           *y = malloc(sizeof(double) * (size_t)n * 17);
    CHECK(b && x && y);
    for (size_t q = 0; b && x && y && q < sizeof counts / sizeof counts[0]; q++) {
        const int k = counts[q];
        for (size_t i = 0; i < (size_t)n * (size_t)k; i++)
            b[i] = rnd();
        dk_cholesky_set_parallel(ch, 0);
        CHECK(dk_cholesky_solve(ch, b, k, x, &err) == DK_OK);
        dk_cholesky_set_parallel(ch, 1);
        double t0 = now();
        CHECK(dk_cholesky_solve(ch, b, k, y, &err) == DK_OK);
        double t1 = now();
        double diff = 0.0, big = 0.0;
        for (size_t i = 0; i < (size_t)n * (size_t)k; i++) {
            diff = fmax(diff, fabs(x[i] - y[i]));
            big = fmax(big, fabs(x[i]));
        }
        CHECK_MSG(diff <= 1e-11 * big, "%s, %d right-hand sides: differs by %.3g (of %.3g)",
                  name, k, diff, big);
        {   /* on a team's helper thread: the same operations, so the same bits */
            dk_team *team = dk_team_create();
            double *z = malloc(sizeof(double) * (size_t)n * (size_t)k);
            CHECK(team != NULL && z != NULL);
            dk_cholesky_set_team(ch, team);
            for (int rep = 0; z && rep < 2; rep++) { /* helper woken, then spinning */
                CHECK(dk_cholesky_solve(ch, b, k, z, &err) == DK_OK);
                CHECK_MSG(memcmp(z, y, sizeof(double) * (size_t)n * (size_t)k) == 0,
                          "%s, %d right-hand sides: the team's solve differs", name, k);
            }
            dk_cholesky_set_team(ch, NULL);
            dk_team_free(team);
            free(z);
        }
        if (k == 3)
            printf("%s: n=%d, estimated speed-up %.2f, 3-RHS two-thread solve %.2f ms\n", name,
                   (int)n, speedup, 1e3 * (t1 - t0));
        if (k == 3 || k == 11) {
            memcpy(y, b, sizeof(double) * (size_t)n * (size_t)k); /* in place */
            CHECK(dk_cholesky_solve(ch, y, k, y, &err) == DK_OK);
            diff = 0.0;
            for (size_t i = 0; i < (size_t)n * (size_t)k; i++)
                diff = fmax(diff, fabs(x[i] - y[i]));
            CHECK_MSG(diff <= 1e-11 * big, "%s in place, %d columns: differs by %.3g", name, k,
                      diff);
        }
    }
    free(b);
    free(x);
    free(y);
    dk_cholesky_free(ch);
}

static void test_parallel_solve(void)
{
    double *shift = malloc(sizeof(double) * 150 * 150);
    CHECK(shift != NULL);
    if (!shift)
        return;
    for (int i = 0; i < 150 * 150; i++)
        shift[i] = 1e-3;
    dk_sparse *a = grid_laplacian(150, 150, 1, shift);
    if (a) check_parallel(a, 0, "2D grid, simplicial LL'");
    csc_free(a);
    a = SANITIZED ? grid_laplacian(18, 18, 18, NULL) : grid_laplacian(26, 26, 26, NULL);
    if (a) {
        for (dk_index j = 0; j < a->n_cols; j++)
            for (dk_index p = a->col_start[j]; p < a->col_start[j + 1]; p++)
                if (a->row_index[p] == j) a->values[p] += 1e-3;
        check_parallel(a, 0, "3D grid, supernodal LL'");
    }
    csc_free(a);
    /* 2D grid Laplacian eigenvalues 4 sin^2(pi i / 300) + 4 sin^2(pi j / 300): a shift of
     * -0.05 lies between two of them (checked: the factorization would fail on a zero pivot
     * otherwise, and the solves are compared, not the inertia) */
    for (int i = 0; i < 150 * 150; i++)
        shift[i] = -0.0503;
    a = grid_laplacian(150, 150, 1, shift);
    if (a) check_parallel(a, 1, "2D grid - sigma I, simplicial LDL'");
    csc_free(a);
    free(shift);
}

/* The schedule on trees of every shape, with plans forced on small and unbalanced factors
 * (dk_cholesky_set_parallel 2): a path (the elimination tree is one chain: everything is
 * "top"), a star (one root with thousands of leaf children, merged into chunks), a forest of
 * 37 random components (many roots), a random sparse graph, and the latter shifted to be
 * indefinite (LDL'). Each against cholmod_solve2 for 1, 3 and 5 right-hand sides. */
static dk_sparse *from_edges(dk_index n, const dk_index *ea, const dk_index *eb, int64_t m,
                             double shift)
{
    const int64_t nt = 2 * m + n;
    dk_index *r = malloc(sizeof(dk_index) * (size_t)nt), *c = malloc(sizeof(dk_index) * (size_t)nt);
    double *v = malloc(sizeof(double) * (size_t)nt);
    dk_sparse *a = NULL;
    dk_error err = {0};
    if (r && c && v) {
        int64_t k = 0;
        for (dk_index i = 0; i < n; i++) {
            r[k] = c[k] = i;
            v[k++] = shift;
        }
        for (int64_t e = 0; e < m; e++) {
            const double w = 0.5 + 0.5 * (rnd() + 1.0);
            r[k] = ea[e]; c[k] = eb[e]; v[k++] = -w;
            r[k] = eb[e]; c[k] = ea[e]; v[k++] = -w;
        }
        dk_sparse *t = NULL;
        if (dk_sparse_from_triplets(n, n, k, r, c, v, &t, &err) == DK_OK) {
            /* add the degrees to the diagonal (a weighted graph Laplacian + shift) */
            for (dk_index j = 0; j < n; j++) {
                double deg = 0.0;
                dk_index dpos = -1;
                for (dk_index q = t->col_start[j]; q < t->col_start[j + 1]; q++) {
                    if (t->row_index[q] == j)
                        dpos = q;
                    else
                        deg -= t->values[q];
                }
                if (dpos >= 0)
                    t->values[dpos] += deg;
            }
            a = t;
        }
    }
    free(r);
    free(c);
    free(v);
    return a;
}

static void check_forced(dk_sparse *a, int indefinite, const char *name)
{
    const dk_index n = a->n_rows;
    dk_error err = {0};
    dk_cholesky *ch = NULL;
    int ok = (indefinite ? dk_cholesky_analyze_indefinite(a, &ch, &err)
                         : dk_cholesky_analyze(a, &ch, &err)) == DK_OK;
    if (ok) {
        dk_cholesky_set_parallel(ch, 2);
        ok = dk_cholesky_factorize(ch, a, &err) == DK_OK;
    }
    CHECK_MSG(ok, "%s: %s", name, err.message);
    if (!ok) {
        dk_cholesky_free(ch);
        return;
    }
    CHECK_MSG(dk_cholesky_parallel_speedup(ch) > 0.0, "%s: no plan", name);
    double *b = malloc(sizeof(double) * (size_t)n * 5), *x = malloc(sizeof(double) * (size_t)n * 5),
           *y = malloc(sizeof(double) * (size_t)n * 5);
    for (int k = 1; b && x && y && k <= 5; k += 2) {
        for (size_t i = 0; i < (size_t)n * (size_t)k; i++)
            b[i] = rnd();
        dk_cholesky_set_parallel(ch, 0);
        CHECK(dk_cholesky_solve(ch, b, k, x, &err) == DK_OK);
        dk_cholesky_set_parallel(ch, 2);
        CHECK(dk_cholesky_solve(ch, b, k, y, &err) == DK_OK);
        double diff = 0.0, big = 0.0;
        for (size_t i = 0; i < (size_t)n * (size_t)k; i++) {
            diff = fmax(diff, fabs(x[i] - y[i]));
            big = fmax(big, fabs(x[i]));
        }
        CHECK_MSG(diff <= 1e-10 * big, "%s, %d right-hand sides: differs by %.3g (of %.3g)", name,
                  k, diff, big);
    }
    printf("%s: n=%d, forced plan, estimated speed-up %.2f\n", name, (int)n,
           dk_cholesky_parallel_speedup(ch));
    free(b);
    free(x);
    free(y);
    dk_cholesky_free(ch);
}

static void test_parallel_schedule_shapes(void)
{
    enum { NMAX = 6000, MMAX = 6 * NMAX };
    dk_index *ea = malloc(sizeof(dk_index) * MMAX), *eb = malloc(sizeof(dk_index) * MMAX);
    CHECK(ea && eb);
    if (!ea || !eb) {
        free(ea);
        free(eb);
        return;
    }
    int64_t m = 0;
    dk_sparse *a;
    /* path */
    for (dk_index i = 0; i + 1 < 3000; i++, m++) {
        ea[m] = i;
        eb[m] = i + 1;
    }
    a = from_edges(3000, ea, eb, m, 1e-3);
    if (a) check_forced(a, 0, "path");
    dk_sparse_free(a);
    /* star */
    m = 0;
    for (dk_index i = 1; i < 2500; i++, m++) {
        ea[m] = 0;
        eb[m] = i;
    }
    a = from_edges(2500, ea, eb, m, 1e-3);
    if (a) check_forced(a, 0, "star");
    dk_sparse_free(a);
    /* forest of 37 random components */
    m = 0;
    dk_index start = 0;
    for (int comp = 0; comp < 37; comp++) {
        const dk_index size = 20 + (dk_index)((rnd() + 1.0) * 60.0);
        for (dk_index i = 1; i < size; i++) { /* a random tree plus extra edges */
            ea[m] = start + i;
            eb[m++] = start + (dk_index)((rnd() + 1.0) * 0.5 * i) % i;
            const dk_index j = (dk_index)((rnd() + 1.0) * 0.5 * size) % size;
            if (j != i) {
                ea[m] = start + i;
                eb[m++] = start + j;
            }
        }
        start += size;
    }
    a = from_edges(start, ea, eb, m, 1e-3);
    if (a) check_forced(a, 0, "forest of 37 components");
    dk_sparse_free(a);
    /* random sparse graph, SPD and shifted indefinite */
    m = 0;
    for (dk_index i = 0; i < NMAX; i++)
        for (int k = 0; k < 2; k++) {
            const dk_index j = (dk_index)((rnd() + 1.0) * 0.5 * NMAX) % NMAX;
            if (j != i) {
                ea[m] = i;
                eb[m++] = j;
            }
        }
    a = from_edges(NMAX, ea, eb, m, 1e-3);
    if (a) check_forced(a, 0, "random graph");
    dk_sparse_free(a);
    a = from_edges(NMAX, ea, eb, m, -0.37);
    if (a) check_forced(a, 1, "random graph - 0.37 I (LDL')");
    dk_sparse_free(a);
    free(ea);
    free(eb);
}

/* Minimal OBJ reading ("v x y z" and "f a b c ..." with a/b/c corner forms, polygons fanned)
 * and cotangent Laplacian, local to this test so that it depends on the numerics layer only
 * (the library's own reader and operators are tested in their own suites). */
typedef struct obj_mesh {
    int nv, nf;
    double *pos;
    int *tri;
} obj_mesh;

static int read_obj(const char *path, obj_mesh *m)
{
    FILE *f = fopen(path, "r");
    if (!f) return 0;
    int capv = 1024, capf = 2048, ok = 1;
    m->nv = m->nf = 0;
    m->pos = malloc(sizeof(double) * 3 * (size_t)capv);
    m->tri = malloc(sizeof(int) * 3 * (size_t)capf);
    char line[4096];
    while (ok && m->pos && m->tri && fgets(line, sizeof line, f)) {
        if (line[0] == 'v' && line[1] == ' ') {
            if (m->nv == capv) {
                capv *= 2;
                double *np = realloc(m->pos, sizeof(double) * 3 * (size_t)capv);
                if (!np) { ok = 0; break; }
                m->pos = np;
            }
            double *p = m->pos + 3 * (size_t)m->nv;
            if (sscanf(line + 2, "%lf %lf %lf", p, p + 1, p + 2) != 3) ok = 0;
            m->nv++;
        } else if (line[0] == 'f' && line[1] == ' ') {
            int idx[64], c = 0;
            char *s = line + 2, *end;
            for (;;) {
                long v = strtol(s, &end, 10);
                if (end == s) break;
                if (c < 64) idx[c++] = (int)(v > 0 ? v - 1 : m->nv + v);
                s = end;
                while (*s && *s != ' ' && *s != '\t') s++; /* skip /vt/vn */
            }
            for (int t = 1; t + 1 < c; t++) {
                if (m->nf == capf) {
                    capf *= 2;
                    int *nt = realloc(m->tri, sizeof(int) * 3 * (size_t)capf);
                    if (!nt) { ok = 0; break; }
                    m->tri = nt;
                }
                m->tri[3 * m->nf] = idx[0];
                m->tri[3 * m->nf + 1] = idx[t];
                m->tri[3 * m->nf + 2] = idx[t + 1];
                m->nf++;
            }
        }
    }
    fclose(f);
    for (int k = 0; ok && k < 3 * m->nf; k++) ok = m->tri[k] >= 0 && m->tri[k] < m->nv;
    if (!ok || !m->pos || !m->tri) {
        free(m->pos); free(m->tri);
        m->pos = NULL; m->tri = NULL;
        return 0;
    }
    return 1;
}

typedef struct trip {
    int64_t key; /* col * n + row */
    double v;
} trip;

static int cmp_trip(const void *a, const void *b)
{
    const int64_t x = ((const trip *)a)->key, y = ((const trip *)b)->key;
    return (x > y) - (x < y);
}

/* Cotangent Laplacian, PSD sign convention, both triangles stored. */
static dk_sparse *cotan_laplacian(const obj_mesh *m)
{
    const int n = m->nv;
    trip *t = malloc(sizeof *t * 12 * (size_t)m->nf);
    if (!t) return NULL;
    size_t q = 0;
    for (int f = 0; f < m->nf; f++) {
        const int *v = m->tri + 3 * f;
        double e[3][3];
        for (int c = 0; c < 3; c++)
            for (int d = 0; d < 3; d++)
                e[c][d] = m->pos[3 * v[(c + 2) % 3] + d] - m->pos[3 * v[(c + 1) % 3] + d];
        const double cr[3] = {e[0][1] * e[1][2] - e[0][2] * e[1][1],
                              e[0][2] * e[1][0] - e[0][0] * e[1][2],
                              e[0][0] * e[1][1] - e[0][1] * e[1][0]};
        const double a2 = sqrt(cr[0] * cr[0] + cr[1] * cr[1] + cr[2] * cr[2]);
        for (int c = 0; c < 3; c++) {
            const double *p = e[(c + 1) % 3], *r = e[(c + 2) % 3];
            const double w = a2 > 0 ? -0.5 * (p[0] * r[0] + p[1] * r[1] + p[2] * r[2]) / a2 : 0;
            const int i = v[(c + 1) % 3], j = v[(c + 2) % 3];
            t[q++] = (trip){(int64_t)j * n + i, -w};
            t[q++] = (trip){(int64_t)i * n + j, -w};
            t[q++] = (trip){(int64_t)i * n + i, w};
            t[q++] = (trip){(int64_t)j * n + j, w};
        }
    }
    qsort(t, q, sizeof *t, cmp_trip);
    size_t uniq = 0;
    for (size_t r = 0; r < q; r++) uniq += r == 0 || t[r].key != t[r - 1].key;
    dk_sparse *a = csc_new(n, (int64_t)uniq);
    if (!a) { free(t); return NULL; }
    size_t nz = 0;
    for (size_t r = 0; r < q; r++) {
        if (r > 0 && t[r].key == t[r - 1].key) {
            a->values[nz - 1] += t[r].v;
            continue;
        }
        a->row_index[nz] = (dk_index)(t[r].key % n);
        a->values[nz++] = t[r].v;
        a->col_start[t[r].key / n + 1]++;
    }
    for (int j = 0; j < n; j++) a->col_start[j + 1] += a->col_start[j];
    free(t);
    return a;
}

static void test_armadillo(void)
{
    const char *path = DK_SHARED_DIR "/meshes/armadillo.obj";
    obj_mesh m;
    if (!read_obj(path, &m)) {
        printf("note: %s missing or unreadable, armadillo case skipped\n", path);
        return;
    }
    CHECK(m.nv == 43243);
    dk_sparse *l = cotan_laplacian(&m);
    CHECK(l != NULL);
    if (l) check_big_constrained(l, "armadillo cotangent Laplacian");
    csc_free(l);
    free(m.pos);
    free(m.tri);
}

/* The upper triangle alone is enough, and dk_cholesky_analyze_compact gives the solution
 * dk_cholesky_analyze gives, in a supernodal factor that stores fewer entries (no
 * amalgamation zeros). */
static void test_compact_upper(void)
{
    const int m = SANITIZED ? 14 : 22;
    const dk_index n = m * m * m;
    double *diag = malloc(sizeof(double) * n), *b = malloc(sizeof(double) * n);
    double *x1 = malloc(sizeof(double) * n), *x2 = malloc(sizeof(double) * n);
    dk_sparse *a = NULL, *u = NULL;
    CHECK(diag && b && x1 && x2);
    if (diag && b && x1 && x2) {
        for (dk_index i = 0; i < n; i++) { diag[i] = 0.1; b[i] = rnd(); }
        a = grid_laplacian(m, m, m, diag);
        u = a ? csc_new(n, a->col_start[n]) : NULL;
    }
    CHECK(u != NULL);
    if (u) {
        int64_t q = 0; /* u: the upper triangle of a */
        for (dk_index j = 0; j < n; j++) {
            u->col_start[j] = (dk_index)q;
            for (dk_index p = a->col_start[j]; p < a->col_start[j + 1]; p++)
                if (a->row_index[p] <= j) {
                    u->row_index[q] = a->row_index[p];
                    u->values[q++] = a->values[p];
                }
        }
        u->col_start[n] = (dk_index)q;
        CHECK(q < a->col_start[n]);
        dk_error err = {0};
        dk_cholesky *full = NULL, *small = NULL;
        CHECK_MSG(dk_cholesky_analyze(u, &full, &err) == DK_OK, "%s", err.message);
        CHECK_MSG(dk_cholesky_analyze_compact(u, &small, &err) == DK_OK, "%s", err.message);
        CHECK(full && small && dk_cholesky_factorize(full, u, &err) == DK_OK &&
              dk_cholesky_factorize(small, u, &err) == DK_OK);
        if (full && small) {
            CHECK(dk_cholesky_solve(full, b, 1, x1, &err) == DK_OK);
            CHECK(dk_cholesky_solve(small, b, 1, x2, &err) == DK_OK);
            double worst = 0.0, scale = 0.0;
            for (dk_index i = 0; i < n; i++) {
                worst = fmax(worst, fabs(x1[i] - x2[i]));
                scale = fmax(scale, fabs(x1[i]));
            }
            CHECK_MSG(worst <= 1e-12 * scale, "compact solution differs by %g", worst / scale);
            CHECK(rel_residual(a, x1, b) < 1e-12); /* against both triangles */
            CHECK(rel_residual(a, x2, b) < 1e-12);
            const size_t m_full = dk_cholesky_memory(full), m_small = dk_cholesky_memory(small);
            CHECK_MSG(m_small < m_full, "compact factor %zu bytes, default %zu", m_small, m_full);
        }
        dk_cholesky_free(full);
        dk_cholesky_free(small);
    }
    csc_free(u);
    csc_free(a);
    free(diag); free(b); free(x1); free(x2);
}

/* dk_cholesky_min_pivot_ratio on a grid Laplacian shifted by s (every diagonal entry
 * degree + s, degree 3..6): every pivot L_jj^2 lies between the matrix's smallest
 * eigenvalue s and its own diagonal entry, so the ratio is in [s / (6 + s), 1]; and the last
 * pivot is at most n s (the constant vector's Rayleigh quotient bounds 1 / (A^-1)_nn), so
 * near singularity the ratio is at most n s / 3. Supernodal and simplicial factors. */
static void test_min_pivot_ratio(void)
{
    const int m = SANITIZED ? 14 : 24;
    const dk_index n = m * m * m;
    double *shift = malloc(sizeof(double) * n);
    CHECK(shift != NULL);
    if (!shift) return;
    for (int simplicial = 0; simplicial < 2; simplicial++)
        for (int k = 0; k < 2; k++) {
            const double s = k == 0 ? 1.0 : 1e-9;
            for (dk_index i = 0; i < n; i++) shift[i] = s;
            dk_sparse *a = grid_laplacian(m, m, m, shift);
            dk_error err = {0};
            dk_cholesky *ch = NULL;
            CHECK(a != NULL);
            if (!a) continue;
            CHECK((simplicial ? dk_cholesky_analyze_simplicial(a, &ch, &err)
                              : dk_cholesky_analyze(a, &ch, &err)) == DK_OK);
            CHECK(dk_cholesky_min_pivot_ratio(ch, a) == 0.0); /* not factored yet */
            CHECK(dk_cholesky_is_supernodal(ch) == !simplicial);
            CHECK_MSG(dk_cholesky_factorize(ch, a, &err) == DK_OK, "%s", err.message);
            const double r = dk_cholesky_min_pivot_ratio(ch, a);
            if (k == 0)
                CHECK_MSG(r >= s / (6.0 + s) * (1.0 - 1e-12) && r <= 1.0 + 1e-12,
                          "ratio %g outside [%g, 1]", r, s / (6.0 + s));
            else
                CHECK_MSG(r > 0.0 && r <= (double)n * s / 3.0, "ratio %g above %g", r,
                          (double)n * s / 3.0);
            dk_cholesky_free(ch);
            csc_free(a);
        }
    free(shift);
}

DK_TEST_MAIN(test_small_against_lapack, test_min_pivot_ratio, test_compact_upper, test_parallel_solve, test_parallel_schedule_shapes, test_not_positive_definite,
             test_not_positive_definite_supernodal,
             test_refactorize_and_multi_rhs, test_bad_arguments, test_indefinite_inertia,
             test_big_grid, test_armadillo)
