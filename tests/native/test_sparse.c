/* Tests for dk_sparse: every operation against a dense reference on random matrices with
 * duplicates, error messages, and the speed of assembling a large cotangent-like pattern. */
#include <stdlib.h>
#include <string.h>
#include <time.h>

#include "dk_sparse.h"
#include "dk_test.h"

#if defined(__has_feature)
#if __has_feature(address_sanitizer)
#define SANITIZED 1
#endif
#endif
#if !defined(SANITIZED) && defined(__SANITIZE_ADDRESS__)
#define SANITIZED 1
#endif
#ifndef SANITIZED
#define SANITIZED 0
#endif

static uint64_t rng_state = 12345;
static uint32_t rnd(void)
{
    rng_state = rng_state * 6364136223846793005ull + 1442695040888963407ull;
    return (uint32_t)(rng_state >> 33);
}
static double rndu(void) { return (rnd() % 2000001) / 1000000.0 - 1.0; }

/* Checks structural invariants: sorted, unique, in range. */
static int well_formed(const dk_sparse *a)
{
    if (a->col_start[0] != 0) return 0;
    for (dk_index j = 0; j < a->n_cols; j++) {
        if (a->col_start[j + 1] < a->col_start[j]) return 0;
        for (dk_index p = a->col_start[j]; p < a->col_start[j + 1]; p++) {
            if (a->row_index[p] < 0 || a->row_index[p] >= a->n_rows) return 0;
            if (p > a->col_start[j] && a->row_index[p] <= a->row_index[p - 1]) return 0;
        }
    }
    return 1;
}

typedef struct trip {
    dk_index *r, *c;
    double *v;
    int64_t n;
} trip;

static trip random_triplets(dk_index m, dk_index n, int64_t count)
{
    trip t = {malloc(sizeof(dk_index) * count), malloc(sizeof(dk_index) * count),
              malloc(sizeof(double) * count), count};
    for (int64_t k = 0; k < count; k++) {
        t.r[k] = (dk_index)(rnd() % (uint32_t)m);
        t.c[k] = (dk_index)(rnd() % (uint32_t)n);
        t.v[k] = rndu();
    }
    return t;
}
static void trip_free(trip *t)
{
    free(t->r);
    free(t->c);
    free(t->v);
}

static dk_sparse *from(trip t, dk_index m, dk_index n)
{
    dk_sparse *a = NULL;
    dk_error err = {0};
    dk_status st = dk_sparse_from_triplets(m, n, t.n, t.r, t.c, t.v, &a, &err);
    CHECK_MSG(st == DK_OK, "%s", err.message);
    return a;
}

static void test_triplets_vs_dense(void)
{
    /* several shapes, including long columns (heap sort path) and duplicates */
    const dk_index shapes[][3] = {{7, 5, 60}, {40, 3, 500}, {1, 1, 10}, {30, 30, 400},
                                  {5, 9, 0}, {200, 4, 3000}};
    for (size_t s = 0; s < sizeof shapes / sizeof shapes[0]; s++) {
        dk_index m = shapes[s][0], n = shapes[s][1];
        trip t = random_triplets(m, n, shapes[s][2]);
        double *ref = calloc((size_t)m * n, sizeof(double));
        unsigned char *present = calloc((size_t)m * n, 1);
        for (int64_t k = 0; k < t.n; k++) {
            ref[(size_t)t.c[k] * m + t.r[k]] += t.v[k];
            present[(size_t)t.c[k] * m + t.r[k]] = 1;
        }
        dk_sparse *a = from(t, m, n);
        if (a) {
            CHECK(well_formed(a));
            int64_t expected_nnz = 0;
            for (size_t i = 0; i < (size_t)m * n; i++) expected_nnz += present[i];
            CHECK_MSG(dk_sparse_nnz(a) == expected_nnz, "nnz %lld vs %lld",
                      (long long)dk_sparse_nnz(a), (long long)expected_nnz);
            double worst = 0;
            for (dk_index j = 0; j < n; j++)
                for (dk_index i = 0; i < m; i++) {
                    double d = fabs(dk_sparse_get(a, i, j) - ref[(size_t)j * m + i]);
                    if (d > worst) worst = d;
                }
            CHECK(worst < 1e-12);
            /* matvec and matmat */
            double *x = malloc(sizeof(double) * n * 3), *y = malloc(sizeof(double) * m * 3);
            for (dk_index j = 0; j < n * 3; j++) x[j] = rndu();
            dk_sparse_matmat(a, x, y, 3);
            worst = 0;
            for (int c = 0; c < 3; c++)
                for (dk_index i = 0; i < m; i++) {
                    double s2 = 0;
                    for (dk_index j = 0; j < n; j++)
                        s2 += ref[(size_t)j * m + i] * x[(size_t)c * n + j];
                    double d = fabs(s2 - y[(size_t)c * m + i]);
                    if (d > worst) worst = d;
                }
            CHECK(worst < 1e-12);
            dk_sparse_matvec(a, x + n, y);
            double s1 = 0;
            for (dk_index j = 0; j < n; j++) s1 += ref[j * (size_t)m] * x[n + j];
            CHECK_NEAR(y[0], s1, 1e-12);
            /* transpose */
            dk_sparse *at = NULL;
            CHECK(dk_sparse_transpose(a, &at, NULL) == DK_OK);
            if (at) {
                CHECK(well_formed(at));
                CHECK(at->n_rows == n && at->n_cols == m);
                int same = 1;
                for (dk_index j = 0; j < n; j++)
                    for (dk_index i = 0; i < m; i++)
                        if (dk_sparse_get(at, j, i) != dk_sparse_get(a, i, j)) same = 0;
                CHECK(same);
                CHECK(dk_sparse_nnz(at) == dk_sparse_nnz(a));
            }
            dk_sparse_free(at);
            free(x);
            free(y);
        }
        dk_sparse_free(a);
        free(ref);
        free(present);
        trip_free(&t);
    }
}

static void test_explicit_zero_kept(void)
{
    dk_index r[] = {0, 1, 1, 0}, c[] = {0, 0, 0, 1};
    double v[] = {2.0, 3.0, -3.0, 0.0};
    dk_sparse *a = NULL;
    CHECK(dk_sparse_from_triplets(2, 2, 4, r, c, v, &a, NULL) == DK_OK);
    if (!a) return;
    CHECK(dk_sparse_nnz(a) == 3); /* (0,0), (1,0) summed to zero, explicit (0,1) */
    CHECK(dk_sparse_get(a, 1, 0) == 0.0);
    CHECK(a->row_index[1] == 1 && a->col_start[1] == 2);
    dk_sparse_free(a);
}

static void test_errors(void)
{
    dk_index r[] = {0, 5}, c[] = {0, 1};
    double v[] = {1, 1};
    dk_sparse *a = (dk_sparse *)&v; /* must be reset to NULL on failure */
    dk_error err = {0};
    CHECK(dk_sparse_from_triplets(3, 3, 2, r, c, v, &a, &err) == DK_ERR_INDEX);
    CHECK(a == NULL);
    CHECK_MSG(strstr(err.message, "triplet 1") && strstr(err.message, "(5, 1)") &&
                  strstr(err.message, "3 x 3"),
              "%s", err.message);
    CHECK(dk_sparse_from_triplets(-1, 3, 0, r, c, v, &a, &err) == DK_ERR_INVALID_ARGUMENT);
    CHECK(dk_sparse_from_triplets(3, 3, 2, NULL, c, v, &a, NULL) == DK_ERR_INVALID_ARGUMENT);
    /* shape mismatch in add, non-square add_diagonal */
    dk_sparse *b = NULL, *d = NULL, *o = NULL;
    CHECK(dk_sparse_from_triplets(3, 3, 1, r, c, v, &b, NULL) == DK_OK);
    CHECK(dk_sparse_from_triplets(3, 2, 1, r, c, v, &d, NULL) == DK_OK);
    CHECK(dk_sparse_add(1, b, 1, d, &o, &err) == DK_ERR_INVALID_ARGUMENT && !o);
    CHECK_MSG(strstr(err.message, "3 x 3 vs 3 x 2") != NULL, "%s", err.message);
    double diag[3] = {1, 1, 1};
    CHECK(dk_sparse_add_diagonal(d, diag, &o, &err) == DK_ERR_INVALID_ARGUMENT && !o);
    CHECK(strstr(err.message, "not square") != NULL);
    dk_index rm[3] = {0, 1, 7}, cm[3] = {0, 1, 2};
    CHECK(dk_sparse_submatrix(b, rm, 3, cm, 3, &o, &err) == DK_ERR_INDEX && !o);
    CHECK_MSG(strstr(err.message, "row_map[2] is 7") != NULL, "%s", err.message);
    CHECK(dk_sparse_alloc(2, 2, -1, &o, &err) == DK_ERR_INVALID_ARGUMENT);
    dk_sparse_free(b);
    dk_sparse_free(d);
    dk_sparse_free(NULL);
}

static void test_add_diagonal_submatrix_asymmetry(void)
{
    dk_index m = 25;
    trip t = random_triplets(m, m, 120);
    trip u = random_triplets(m, m, 90);
    dk_sparse *a = from(t, m, m), *b = from(u, m, m), *c = NULL, *d = NULL, *s = NULL,
              *cp = NULL;
    if (!a || !b) goto done;
    CHECK(dk_sparse_add(2.0, a, -0.5, b, &c, NULL) == DK_OK);
    if (c) {
        CHECK(well_formed(c));
        double worst = 0;
        for (dk_index j = 0; j < m; j++)
            for (dk_index i = 0; i < m; i++) {
                double e = 2.0 * dk_sparse_get(a, i, j) - 0.5 * dk_sparse_get(b, i, j);
                double dd = fabs(e - dk_sparse_get(c, i, j));
                if (dd > worst) worst = dd;
            }
        CHECK(worst < 1e-14);
    }
    double diag[25], got[25];
    for (int i = 0; i < 25; i++) diag[i] = i + 1;
    CHECK(dk_sparse_add_diagonal(a, diag, &d, NULL) == DK_OK);
    if (d) {
        CHECK(well_formed(d));
        dk_sparse_diagonal(d, got);
        int ok = 1;
        for (dk_index i = 0; i < m; i++) {
            if (fabs(got[i] - (dk_sparse_get(a, i, i) + diag[i])) > 1e-14) ok = 0;
            for (dk_index j = 0; j < m; j++)
                if (i != j && dk_sparse_get(d, i, j) != dk_sparse_get(a, i, j)) ok = 0;
        }
        CHECK(ok);
    }
    /* reversed, dropping every third row/column: non-monotone maps */
    dk_index rmap[25], cmap[25], nk = 0;
    for (dk_index i = 0; i < m; i++) rmap[i] = cmap[i] = -1;
    for (dk_index i = 0; i < m; i++)
        if (i % 3) nk++;
    dk_index k = nk;
    for (dk_index i = 0; i < m; i++)
        if (i % 3) rmap[i] = cmap[i] = --k;
    CHECK(dk_sparse_submatrix(a, rmap, nk, cmap, nk, &s, NULL) == DK_OK);
    if (s) {
        CHECK(well_formed(s));
        CHECK(s->n_rows == nk && s->n_cols == nk);
        int ok = 1;
        for (dk_index j = 0; j < m; j++)
            for (dk_index i = 0; i < m; i++)
                if (rmap[i] >= 0 && cmap[j] >= 0 &&
                    dk_sparse_get(s, rmap[i], cmap[j]) != dk_sparse_get(a, i, j))
                    ok = 0;
        CHECK(ok);
    }
    /* asymmetry: A + A^T is symmetric; A is not */
    dk_sparse *at = NULL, *sym = NULL;
    CHECK(dk_sparse_transpose(a, &at, NULL) == DK_OK);
    CHECK(dk_sparse_add(1, a, 1, at, &sym, NULL) == DK_OK);
    if (sym) CHECK(dk_sparse_asymmetry(sym) == 0.0);
    CHECK(dk_sparse_asymmetry(a) > 0.01);
    dk_sparse_free(at);
    dk_sparse_free(sym);
    CHECK(dk_sparse_copy(a, &cp, NULL) == DK_OK);
    if (cp) {
        CHECK(dk_sparse_nnz(cp) == dk_sparse_nnz(a) && cp->values != a->values &&
              memcmp(cp->values, a->values, sizeof(double) * dk_sparse_nnz(a)) == 0);
    }
done:
    dk_sparse_free(a);
    dk_sparse_free(b);
    dk_sparse_free(c);
    dk_sparse_free(d);
    dk_sparse_free(s);
    dk_sparse_free(cp);
    trip_free(&t);
    trip_free(&u);
}

/* Cotangent-Laplacian-like assembly on an n x n grid: two triplets per triangle edge (edges
 * inside the grid come twice, so duplicates are summed) plus one diagonal triplet per vertex,
 * about 13M triplets for a 1M-vertex mesh. Checks the pattern, zero row sums and time. */
static void test_large_assembly(void)
{
    int n = SANITIZED ? 200 : 1000;
    dk_index nv = (dk_index)((n + 1) * (n + 1));
    int64_t nt = 2 * (int64_t)n * n, count = nt * 6 + nv;
    dk_index *r = malloc(sizeof(dk_index) * count), *c = malloc(sizeof(dk_index) * count);
    double *v = malloc(sizeof(double) * count), *diag = calloc((size_t)nv, sizeof(double));
    if (!r || !c || !v || !diag) {
        CHECK(!"out of memory in test");
        free(r);
        free(c);
        free(v);
        free(diag);
        return;
    }
    int64_t k = 0;
    for (int j = 0; j < n; j++)
        for (int i = 0; i < n; i++) {
            dk_index a = j * (n + 1) + i, b = a + 1, cc = a + n + 2, d = a + n + 1;
            dk_index tri[2][3] = {{a, b, cc}, {a, cc, d}};
            for (int t = 0; t < 2; t++)
                for (int e = 0; e < 3; e++) {
                    dk_index p = tri[t][e], q = tri[t][(e + 1) % 3];
                    double w = 0.5 + 0.25 * e;
                    r[k] = p; c[k] = q; v[k++] = w;
                    r[k] = q; c[k] = p; v[k++] = w;
                    diag[p] -= w;
                    diag[q] -= w;
                }
        }
    for (dk_index i = 0; i < nv; i++) {
        r[k] = i; c[k] = i; v[k++] = diag[i];
    }
    free(diag);
    count = k;
    dk_sparse *l = NULL;
    struct timespec t0, t1;
    timespec_get(&t0, TIME_UTC);
    dk_status st = dk_sparse_from_triplets(nv, nv, count, r, c, v, &l, NULL);
    timespec_get(&t1, TIME_UTC);
    double secs = (t1.tv_sec - t0.tv_sec) + 1e-9 * (t1.tv_nsec - t0.tv_nsec);
    printf("assembled %lld triplets (%ld vertices) in %.3f s\n", (long long)count, (long)nv,
           secs);
    CHECK(st == DK_OK);
    if (l) {
        CHECK(well_formed(l));
        /* 7 entries per interior column of this triangulation */
        CHECK(dk_sparse_nnz(l) == (int64_t)nv + 2 * (3 * (int64_t)n * n + 2 * n));
        double *ones = malloc(sizeof(double) * nv), *y = malloc(sizeof(double) * nv);
        for (dk_index i = 0; i < nv; i++) ones[i] = 1.0;
        dk_sparse_matvec(l, ones, y);
        double worst = 0;
        for (dk_index i = 0; i < nv; i++)
            if (fabs(y[i]) > worst) worst = fabs(y[i]);
        CHECK(worst < 1e-12);
        CHECK(dk_sparse_asymmetry(l) == 0.0);
        free(ones);
        free(y);
        /* speed is the benchmarks' (scripts/bench_core.py), not a test's: the time is printed only */
    }
    dk_sparse_free(l);
    free(r);
    free(c);
    free(v);
}

/* dk_sparse_from_columns gives the matrix dk_sparse_from_triplets gives for the same
 * entries, bucketed by column in a shuffled order; it takes its arrays on every path. */
static void test_from_columns(void)
{
    const dk_index m = 37, n = 23;
    const int64_t count = 900;
    trip t = random_triplets(m, n, count);
    dk_sparse *ref = from(t, m, n);
    int64_t *start = calloc((size_t)n + 1, sizeof *start), *next = calloc((size_t)n + 1, sizeof *next);
    dk_index *rows = malloc(sizeof(dk_index) * count);
    double *vals = malloc(sizeof(double) * count);
    CHECK(ref && start && next && rows && vals);
    if (ref && start && next && rows && vals) {
        for (int64_t k = 0; k < count; k++) start[t.c[k] + 1]++;
        for (dk_index j = 0; j < n; j++) start[j + 1] += start[j];
        memcpy(next, start, sizeof(int64_t) * ((size_t)n + 1));
        for (int64_t k = count - 1; k >= 0; k--) { /* reversed: the order must not matter */
            const int64_t p = next[t.c[k]]++;
            rows[p] = t.r[k];
            vals[p] = t.v[k];
        }
        dk_sparse *a = NULL;
        dk_error err = {0};
        CHECK_MSG(dk_sparse_from_columns(m, n, start, rows, vals, &a, &err) == DK_OK, "%s",
                  err.message);
        rows = NULL, vals = NULL; /* taken */
        CHECK(a && well_formed(a));
        if (a) {
            CHECK(dk_sparse_nnz(a) == dk_sparse_nnz(ref));
            double worst = 0.0;
            for (dk_index j = 0; j < n; j++)
                for (dk_index i = 0; i < m; i++)
                    worst = fmax(worst, fabs(dk_sparse_get(a, i, j) - dk_sparse_get(ref, i, j)));
            CHECK_MSG(worst < 1e-13, "from_columns differs from from_triplets by %g", worst);
        }
        dk_sparse_free(a);
        /* a row out of range is refused (and the arrays still taken: ASan sees a leak else) */
        dk_index *r2 = malloc(sizeof(dk_index) * 2);
        double *v2 = malloc(sizeof(double) * 2);
        int64_t st2[3] = {0, 1, 2};
        CHECK(r2 && v2);
        if (r2 && v2) {
            r2[0] = 0, r2[1] = 5, v2[0] = v2[1] = 1.0;
            a = NULL;
            CHECK(dk_sparse_from_columns(3, 2, st2, r2, v2, &a, &err) == DK_ERR_INDEX);
            CHECK(a == NULL && strstr(err.message, "row 5") != NULL);
        } else {
            free(r2), free(v2);
        }
        /* an empty matrix */
        int64_t st0[4] = {0, 0, 0, 0};
        CHECK(dk_sparse_from_columns(3, 3, st0, malloc(sizeof(dk_index)), malloc(sizeof(double)),
                                     &a, &err) == DK_OK);
        CHECK(a && dk_sparse_nnz(a) == 0 && well_formed(a));
        dk_sparse_free(a);
    }
    free(rows), free(vals), free(start), free(next);
    dk_sparse_free(ref);
    trip_free(&t);
}

DK_TEST_MAIN(test_triplets_vs_dense, test_explicit_zero_kept, test_errors,
             test_add_diagonal_submatrix_asymmetry, test_large_assembly, test_from_columns)
