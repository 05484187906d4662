/* Tests of the k-d tree (dk_kdtree_*) against brute force: random points, exact ties on a
 * lattice (ties broken by index), duplicated points, k = n, NULL outputs, bad arguments. */
#define _POSIX_C_SOURCE 199309L /* clock_gettime */
#include <math.h>
#include <stdint.h>
#include <time.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "dk_operators.h"
#include "dk_test.h"

static uint64_t rng_state = 1234567891234567ull;
static double rnd(void) /* uniform in [-1, 1) */
{
    rng_state ^= rng_state << 13;
    rng_state ^= rng_state >> 7;
    rng_state ^= rng_state << 17;
    return (double)(rng_state >> 11) / 9007199254740992.0 * 2.0 - 1.0;
}

typedef struct cand {
    double d2;
    dk_index id;
} cand;

static int cand_cmp(const void *a, const void *b)
{
    const cand *x = a, *y = b;
    if (x->d2 != y->d2) return x->d2 < y->d2 ? -1 : 1;
    return (x->id > y->id) - (x->id < y->id);
}

/* Builds a tree over pts, queries every query and compares with a full sort. */
static int compare_with_brute(const double *pts, dk_index n, const double *q, dk_index nq,
                              dk_index k, const char *what)
{
    dk_kdtree *t = NULL;
    dk_error err = {0};
    if (dk_kdtree_create(pts, n, &t, &err) != DK_OK) {
        CHECK_MSG(0, "%s: create failed: %s", what, err.message);
        return 0;
    }
    dk_index *idx = malloc((size_t)nq * k * sizeof *idx);
    double *d2 = malloc((size_t)nq * k * sizeof *d2);
    cand *all = malloc((size_t)n * sizeof *all);
    int bad = 0;
    if (!idx || !d2 || !all) {
        CHECK_MSG(0, "test out of memory");
        bad = 1;
    } else if (dk_kdtree_knn(t, q, nq, k, idx, d2, &err) != DK_OK) {
        CHECK_MSG(0, "%s: knn failed: %s", what, err.message);
        bad = 1;
    } else {
        for (dk_index i = 0; i < nq && !bad; i++) {
            for (dk_index j = 0; j < n; j++) {
                double dx = q[3 * i] - pts[3 * j], dy = q[3 * i + 1] - pts[3 * j + 1],
                       dz = q[3 * i + 2] - pts[3 * j + 2];
                all[j].d2 = dx * dx + dy * dy + dz * dz;
                all[j].id = j;
            }
            qsort(all, (size_t)n, sizeof *all, cand_cmp);
            for (dk_index j = 0; j < k; j++) {
                if (idx[(size_t)i * k + j] != all[j].id || d2[(size_t)i * k + j] != all[j].d2) {
                    CHECK_MSG(0, "%s: query %d rank %d: tree (%d, %.17g) vs brute (%d, %.17g)",
                              what, (int)i, (int)j, (int)idx[(size_t)i * k + j],
                              d2[(size_t)i * k + j], (int)all[j].id, all[j].d2);
                    bad = 1;
                    break;
                }
            }
        }
        CHECK_MSG(!bad, "%s: all %d queries match brute force", what, (int)nq);
    }
    free(idx);
    free(d2);
    free(all);
    dk_kdtree_free(t);
    return !bad;
}

static void test_random(void)
{
    enum { N = 3000, NQ = 300 };
    double *p = malloc(N * 3 * sizeof *p), *q = malloc(NQ * 3 * sizeof *q);
    if (!p || !q) {
        CHECK(0);
        free(p);
        free(q);
        return;
    }
    for (int i = 0; i < 3 * N; i++) p[i] = rnd();
    /* flatten a third of the points onto z = 0.25 (many equal split keys) */
    for (int i = 0; i < N / 3; i++) p[3 * i + 2] = 0.25;
    for (int i = 0; i < 3 * NQ; i++) q[i] = 1.3 * rnd();
    const dk_index ks[] = {1, 2, 7, 32};
    for (size_t j = 0; j < sizeof ks / sizeof ks[0]; j++) compare_with_brute(p, N, q, NQ, ks[j], "random");
    /* queries that are tree points: the nearest is the point itself at distance 0 */
    compare_with_brute(p, N, p, 200, 5, "self queries");
    free(p);
    free(q);
}

static void test_ties(void)
{
    /* 6x6x6 integer lattice queried at lattice points, cell centres and face centres:
     * many exactly equal distances; each point duplicated once (same coordinates). */
    enum { S = 6, N = 2 * S * S * S };
    static double p[N * 3];
    int c = 0;
    for (int rep = 0; rep < 2; rep++)
        for (int x = 0; x < S; x++)
            for (int y = 0; y < S; y++)
                for (int z = 0; z < S; z++) {
                    p[3 * c] = x, p[3 * c + 1] = y, p[3 * c + 2] = z;
                    c++;
                }
    double q[3 * 30];
    for (int i = 0; i < 30; i++) {
        q[3 * i] = (i % 6) + ((i % 3) ? 0.5 : 0.0);
        q[3 * i + 1] = ((i / 6) % 6) + ((i % 2) ? 0.5 : 0.0);
        q[3 * i + 2] = (i % 5) + ((i % 4 == 1) ? 0.5 : 0.0);
    }
    compare_with_brute(p, N, q, 30, 1, "lattice k=1");
    compare_with_brute(p, N, q, 30, 9, "lattice k=9");
    compare_with_brute(p, N, q, 30, 27, "lattice k=27");
}

/* Queries far outside the points' box, in every direction, and around a flat patch: the
 * case the per-axis cell bound prunes (a handle's few vertices queried from the whole mesh).
 * The lattice far queries have many exactly equal distances, which must not be pruned. */
static void test_far_queries(void)
{
    enum { S = 8, N = S * S * S, NQ = 64 };
    static double p[3 * N], flat[3 * N], q[3 * NQ];
    int c = 0;
    for (int x = 0; x < S; x++)
        for (int y = 0; y < S; y++)
            for (int z = 0; z < S; z++, c++) {
                p[3 * c] = x, p[3 * c + 1] = y, p[3 * c + 2] = z;
                flat[3 * c] = x + 0.1 * rnd(), flat[3 * c + 1] = y * S + z, flat[3 * c + 2] = 0.0;
            }
    for (int i = 0; i < NQ; i++) {
        /* a direction from the 26 around the box, at 3 to 300 box sizes */
        int dir = i % 26, scale = 3 * (1 + (i % 4) * 33);
        int d[3] = {dir % 3 - 1, (dir / 3) % 3 - 1, (dir / 9) % 3 - 1};
        if (!d[0] && !d[1] && !d[2]) d[2] = 1;
        for (int k = 0; k < 3; k++)
            q[3 * i + k] = 3.5 + d[k] * scale * S + ((i % 5 == 0) ? 0.0 : rnd());
    }
    compare_with_brute(p, N, q, NQ, 1, "far lattice k=1");
    compare_with_brute(p, N, q, NQ, 8, "far lattice k=8");
    compare_with_brute(flat, N, q, NQ, 1, "far flat patch k=1");
    compare_with_brute(flat, N, q, NQ, 5, "far flat patch k=5");
}

static void test_k_equals_n_and_small(void)
{
    double p[3 * 17], q[3 * 4];
    for (int i = 0; i < 3 * 17; i++) p[i] = rnd();
    for (int i = 0; i < 12; i++) q[i] = rnd();
    compare_with_brute(p, 17, q, 4, 17, "k = n");
    compare_with_brute(p, 1, q, 4, 1, "one point");
    const double same[12] = {1, 2, 3, 1, 2, 3, 1, 2, 3, 1, 2, 3};
    compare_with_brute(same, 4, q, 4, 4, "all points equal");

    /* NULL outputs are allowed */
    dk_kdtree *t = NULL;
    dk_error err = {0};
    CHECK(dk_kdtree_create(p, 17, &t, &err) == DK_OK);
    double d2[3];
    dk_index idx[3];
    CHECK(dk_kdtree_knn(t, q, 1, 3, NULL, d2, &err) == DK_OK);
    CHECK(dk_kdtree_knn(t, q, 1, 3, idx, NULL, &err) == DK_OK);
    CHECK(d2[0] <= d2[1] && d2[1] <= d2[2]);
    CHECK(dk_kdtree_knn(t, q, 0, 3, idx, d2, &err) == DK_OK);

    /* bad k */
    CHECK(dk_kdtree_knn(t, q, 1, 0, idx, d2, &err) == DK_ERR_INVALID_ARGUMENT);
    CHECK(strstr(err.message, "k = 0") != NULL);
    CHECK(dk_kdtree_knn(t, q, 1, 18, idx, d2, &err) == DK_ERR_INVALID_ARGUMENT);
    CHECK(strstr(err.message, "[1, 17]") != NULL);
    CHECK(dk_kdtree_knn(t, q, 1, -3, idx, d2, &err) == DK_ERR_INVALID_ARGUMENT);
    double bad_q[3] = {0, NAN, 0};
    CHECK(dk_kdtree_knn(t, bad_q, 1, 1, idx, d2, &err) == DK_ERR_NONFINITE);
    dk_kdtree_free(t);
    dk_kdtree_free(NULL);

    /* bad create arguments */
    t = (dk_kdtree *)&err; /* must be reset to NULL on failure */
    CHECK(dk_kdtree_create(p, 0, &t, &err) == DK_ERR_INVALID_ARGUMENT);
    CHECK(t == NULL);
    double bad_p[6] = {0, 0, 0, INFINITY, 0, 0};
    CHECK(dk_kdtree_create(bad_p, 2, &t, &err) == DK_ERR_NONFINITE);
    CHECK(strstr(err.message, "point 1") != NULL);
    CHECK(dk_kdtree_create(NULL, 2, &t, &err) == DK_ERR_INVALID_ARGUMENT);
}

static double now(void)
{
    struct timespec t;
    clock_gettime(CLOCK_MONOTONIC, &t);
    return (double)t.tv_sec + 1e-9 * (double)t.tv_nsec;
}

/* Armadillo-sized cloud: build and all-points 8-NN timings; spot-check against brute force. */
static void test_timing(void)
{
    enum { N = 43243, K = 8 };
    double *p = malloc((size_t)N * 3 * sizeof *p), *d2 = malloc((size_t)N * K * sizeof *d2);
    dk_index *idx = malloc((size_t)N * K * sizeof *idx);
    dk_kdtree *t = NULL;
    dk_error err = {0};
    if (p && d2 && idx) {
        for (int i = 0; i < 3 * N; i++) p[i] = rnd();
        double t0 = now();
        CHECK(dk_kdtree_create(p, N, &t, &err) == DK_OK);
        double t1 = now();
        CHECK(t && dk_kdtree_knn(t, p, N, K, idx, d2, &err) == DK_OK);
        double t2 = now();
        printf("kdtree: %d points built in %.1f ms, %d-NN of every point in %.1f ms\n", N,
               (t1 - t0) * 1e3, K, (t2 - t1) * 1e3);
        int ok = 1;
        for (int q = 0; q < N; q += 4321) { /* brute-force k-th distance */
            double kth[K];
            for (int j = 0; j < K; j++) kth[j] = INFINITY;
            for (int j = 0; j < N; j++) {
                double dx = p[3 * q] - p[3 * j], dy = p[3 * q + 1] - p[3 * j + 1],
                       dz = p[3 * q + 2] - p[3 * j + 2], dd = dx * dx + dy * dy + dz * dz;
                for (int r = 0; r < K; r++)
                    if (dd < kth[r]) {
                        for (int s = K - 1; s > r; s--) kth[s] = kth[s - 1];
                        kth[r] = dd;
                        break;
                    }
            }
            for (int r = 0; r < K; r++) ok &= d2[(size_t)q * K + r] == kth[r];
            ok &= idx[(size_t)q * K] == q;
        }
        CHECK(ok);
    } else {
        CHECK(0);
    }
    dk_kdtree_free(t);
    free(p);
    free(d2);
    free(idx);
}

DK_TEST_MAIN(test_random, test_ties, test_far_queries, test_k_equals_n_and_small, test_timing)
