/* dk_box_qp (dk_bbw.h), the quadratic program of every bounded biharmonic weight function,
 * against an exhaustive reference: on small bilaplacians of a chain with masses spread over
 * four orders of magnitude (rows of very different sizes, as small and big tetrahedra give),
 * every partition of the variables into free / at lo / at hi is solved densely and the one
 * meeting the KKT conditions is the minimiser; dk_box_qp must find it from any start. */
#include <math.h>
#include <stdlib.h>
#include <string.h>

#include "dk_bbw.h"
#include "dk_test.h"

#define M 7

/* Dense Gaussian elimination with partial pivoting on the k x k system (row-major). */
static int dense_solve(double *a, double *b, int k)
{
    for (int c = 0; c < k; c++) {
        int p = c;
        for (int r = c + 1; r < k; r++)
            if (fabs(a[r * k + c]) > fabs(a[p * k + c])) p = r;
        if (fabs(a[p * k + c]) < 1e-300) return -1;
        for (int j = 0; j < k; j++) {
            double t = a[c * k + j];
            a[c * k + j] = a[p * k + j];
            a[p * k + j] = t;
        }
        double t = b[c];
        b[c] = b[p];
        b[p] = t;
        for (int r = c + 1; r < k; r++) {
            double f = a[r * k + c] / a[c * k + c];
            for (int j = c; j < k; j++) a[r * k + j] -= f * a[c * k + j];
            b[r] -= f * b[c];
        }
    }
    for (int c = k - 1; c >= 0; c--) {
        for (int j = c + 1; j < k; j++) b[c] -= a[c * k + j] * b[j];
        b[c] /= a[c * k + c];
    }
    return 0;
}

/* The minimiser by trying all 3^M partitions. */
static void reference(const double *A, const double *b, double lo, double hi, double *x)
{
    int total = 1;
    for (int i = 0; i < M; i++) total *= 3;
    double best = INFINITY;
    for (int code = 0; code < total; code++) {
        int state[M], c = code, map[M], k = 0;
        for (int i = 0; i < M; i++, c /= 3) state[i] = c % 3;
        double y[M], sub[M * M], rhs[M];
        for (int i = 0; i < M; i++) {
            y[i] = state[i] == 1 ? lo : state[i] == 2 ? hi : 0.0;
            map[i] = state[i] == 0 ? k++ : -1;
        }
        for (int i = 0; i < M; i++) {
            if (map[i] < 0) continue;
            rhs[map[i]] = b[i];
            for (int j = 0; j < M; j++) {
                if (map[j] >= 0) sub[map[i] * k + map[j]] = A[i * M + j];
                else rhs[map[i]] -= A[i * M + j] * y[j];
            }
        }
        if (k > 0 && dense_solve(sub, rhs, k) != 0) continue;
        int ok = 1;
        for (int i = 0; i < M; i++)
            if (map[i] >= 0) {
                y[i] = rhs[map[i]];
                ok &= y[i] >= lo - 1e-12 && y[i] <= hi + 1e-12;
            }
        if (!ok) continue;
        double e = 0.0;
        for (int i = 0; i < M; i++) {
            double ay = 0.0;
            for (int j = 0; j < M; j++) ay += A[i * M + j] * y[j];
            e += 0.5 * y[i] * ay - b[i] * y[i];
        }
        if (e < best) {
            best = e;
            memcpy(x, y, sizeof y);
        }
    }
}

static void test_against_every_partition(void)
{
    unsigned seed = 12345u;
    for (int trial = 0; trial < 40; trial++) {
        /* a chain's Laplacian K, masses 1e-4..1, A = K diag(1/m) K + a small shift */
        double K[M * M] = {0}, mass[M], A[M * M] = {0}, b[M];
        for (int i = 0; i + 1 < M; i++) {
            seed = seed * 1103515245u + 12345u;
            double w = 0.1 + (double)(seed >> 16 & 1023) / 1024.0;
            K[i * M + i] += w;
            K[(i + 1) * M + i + 1] += w;
            K[i * M + i + 1] -= w;
            K[(i + 1) * M + i] -= w;
        }
        for (int i = 0; i < M; i++) {
            seed = seed * 1103515245u + 12345u;
            mass[i] = pow(10.0, -4.0 * (double)(seed >> 16 & 1023) / 1024.0);
            seed = seed * 1103515245u + 12345u;
            b[i] = ((double)(seed >> 16 & 1023) / 512.0 - 1.0) * (trial % 2 ? 1e3 : 1.0);
        }
        for (int i = 0; i < M; i++)
            for (int j = 0; j < M; j++) {
                for (int k = 0; k < M; k++) A[i * M + j] += K[i * M + k] * K[k * M + j] / mass[k];
                if (i == j) A[i * M + j] += 1e-3;
            }
        dk_index rows[M * M], cols[M * M];
        for (int p = 0; p < M * M; p++) rows[p] = p / M, cols[p] = p % M;
        dk_sparse *S = NULL;
        dk_error e = {0};
        CHECK(dk_sparse_from_triplets(M, M, M * M, rows, cols, A, &S, &e) == DK_OK);
        double want[M];
        reference(A, b, 0.0, 1.0, want);
        for (int start = 0; start < 3; start++) {
            double x[M];
            for (int i = 0; i < M; i++) x[i] = start == 0 ? 0.0 : start == 1 ? 1.0 : 0.5;
            int it = 0;
            double kkt = 0.0;
            CHECK_MSG(dk_box_qp(S, b, 0.0, 1.0, x, 100, &it, &kkt, &e) == DK_OK, "%s", e.message);
            double worst = 0.0;
            for (int i = 0; i < M; i++) worst = fmax(worst, fabs(x[i] - want[i]));
            CHECK_MSG(worst < 1e-6, "trial %d start %d: %g from the minimiser (%d iterations)",
                      trial, start, worst, it);
        }
        dk_sparse_free(S);
    }
}

static void test_refusals(void)
{
    dk_error e = {0};
    double x[1] = {0}, b[1] = {0};
    dk_index r = 0;
    double v = 1.0;
    dk_sparse *S = NULL;
    CHECK(dk_sparse_from_triplets(1, 1, 1, &r, &r, &v, &S, &e) == DK_OK);
    CHECK(dk_box_qp(S, b, 1.0, 0.0, x, 10, NULL, NULL, &e) == DK_ERR_INVALID_ARGUMENT);
    CHECK(dk_box_qp(S, b, 0.0, 1.0, x, 0, NULL, NULL, &e) == DK_ERR_INVALID_ARGUMENT);
    b[0] = NAN;
    CHECK(dk_box_qp(S, b, 0.0, 1.0, x, 10, NULL, NULL, &e) == DK_ERR_NONFINITE);
    dk_sparse_free(S);
}

DK_TEST_MAIN(test_against_every_partition, test_refusals)
