/* Tests of dk_closest_rotation against LAPACK's SVD: R = U diag(1, 1, det(U V^T)) V^T is
 * the reference maximiser of trace(R^T A), with maximum s1 + s2 + d s3. Random, rank-1,
 * rank-2, zero, reflected, near-identity and exact-rotation matrices; orthonormality and
 * det = +1; timing of 10^6 calls. */
#define _POSIX_C_SOURCE 199309L /* clock_gettime */
#include <lapacke.h>
#include <math.h>
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <time.h>

#include "dk_operators.h"
#include "dk_test.h"

static uint64_t rng_state = 0x9E3779B97F4A7C15ull;
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

static void matmul(const double *a, const double *b, double *c) /* c = a b, 3x3 */
{
    for (int i = 0; i < 3; i++)
        for (int j = 0; j < 3; j++) {
            double s = 0;
            for (int k = 0; k < 3; k++) s += a[3 * i + k] * b[3 * k + j];
            c[3 * i + j] = s;
        }
}

static double det3(const double *m)
{
    return m[0] * (m[4] * m[8] - m[5] * m[7]) - m[1] * (m[3] * m[8] - m[5] * m[6]) +
           m[2] * (m[3] * m[7] - m[4] * m[6]);
}

static double frob(const double *m)
{
    double s = 0;
    for (int i = 0; i < 9; i++) s += m[i] * m[i];
    return sqrt(s);
}

/* Reference: the SVD maximiser (rref) and the maximum; *gap = s2 + d s3 (0 when the
 * maximiser is not unique). Returns 0 on LAPACK failure. */
static int svd_reference(const double *a, double *rref, double *best, double *gap, double *s1)
{
    double tmp[9], s[3], u[9], vt[9], superb[2];
    memcpy(tmp, a, sizeof tmp);
    if (LAPACKE_dgesvd(LAPACK_ROW_MAJOR, 'A', 'A', 3, 3, tmp, 3, s, u, 3, vt, 3, superb) != 0)
        return 0;
    double uvt[9];
    matmul(u, vt, uvt);
    double d = det3(uvt) < 0 ? -1.0 : 1.0;
    double ud[9];
    memcpy(ud, u, sizeof ud);
    for (int i = 0; i < 3; i++) ud[3 * i + 2] *= d;
    matmul(ud, vt, rref);
    *best = s[0] + s[1] + d * s[2];
    *gap = s[1] + d * s[2];
    *s1 = s[0];
    return 1;
}

static void random_rotation(double *r)
{
    double q[4], n = 0;
    for (int i = 0; i < 4; i++) q[i] = rnd(), n += q[i] * q[i];
    n = sqrt(n);
    double w = q[0] / n, x = q[1] / n, y = q[2] / n, z = q[3] / n;
    r[0] = 1 - 2 * (y * y + z * z), r[1] = 2 * (x * y - w * z), r[2] = 2 * (x * z + w * y);
    r[3] = 2 * (x * y + w * z), r[4] = 1 - 2 * (x * x + z * z), r[5] = 2 * (y * z - w * x);
    r[6] = 2 * (x * z - w * y), r[7] = 2 * (y * z + w * x), r[8] = 1 - 2 * (x * x + y * y);
}

/* Statistics over a family of matrices. */
static int n_checked, n_compared;
static double worst_trace, worst_orth, worst_det, worst_r;

static void check_one(const double *a, const char *family)
{
    double r[9], rref[9], best, gap, s1;
    double tr = dk_closest_rotation(a, r);
    if (!svd_reference(a, rref, &best, &gap, &s1)) {
        CHECK_MSG(0, "LAPACK failed on a %s matrix", family);
        return;
    }
    n_checked++;
    double scale = frob(a) > 1 ? frob(a) : 1;
    /* Proper rotation. */
    double rtr[9], rt[9];
    for (int i = 0; i < 3; i++)
        for (int j = 0; j < 3; j++) rt[3 * i + j] = r[3 * j + i];
    matmul(rt, r, rtr);
    double orth = 0;
    for (int i = 0; i < 9; i++) {
        double e = fabs(rtr[i] - ((i % 4) == 0 ? 1.0 : 0.0));
        if (e > orth) orth = e;
    }
    double dt = fabs(det3(r) - 1.0);
    /* Returned value is trace(R^T A) and it is the maximum. */
    double direct = 0;
    for (int i = 0; i < 9; i++) direct += r[i] * a[i];
    double terr = fabs(tr - best) / scale;
    if (orth > worst_orth) worst_orth = orth;
    if (dt > worst_det) worst_det = dt;
    if (terr > worst_trace) worst_trace = terr;
    CHECK_MSG(orth <= 1e-12, "%s: |R^T R - I| = %g", family, orth);
    CHECK_MSG(dt <= 1e-12, "%s: |det R - 1| = %g", family, dt);
    CHECK_MSG(fabs(direct - tr) <= 1e-12 * scale, "%s: returned %.17g, trace %.17g", family,
              tr, direct);
    CHECK_MSG(terr <= 1e-12, "%s: trace %.17g vs SVD maximum %.17g", family, tr, best);
    /* Where the maximiser is unique and well separated, it must be the SVD one. */
    if (gap > 1e-3 * s1) {
        n_compared++;
        double e = 0;
        for (int i = 0; i < 9; i++)
            if (fabs(r[i] - rref[i]) > e) e = fabs(r[i] - rref[i]);
        if (e > worst_r) worst_r = e;
        CHECK_MSG(e <= 1e-9, "%s: |R - R_svd| = %g (gap %g)", family, e, gap / s1);
    }
}

static void test_random_families(void)
{
    double a[9], q[9], d[9], tmp[9];
    for (int it = 0; it < 3000; it++) { /* general */
        for (int i = 0; i < 9; i++) a[i] = rnd() * 10;
        check_one(a, "random");
    }
    for (int it = 0; it < 1000; it++) { /* rank 1: u v^T */
        double u[3], v[3];
        for (int i = 0; i < 3; i++) u[i] = rnd(), v[i] = rnd();
        for (int i = 0; i < 3; i++)
            for (int j = 0; j < 3; j++) a[3 * i + j] = u[i] * v[j];
        check_one(a, "rank-1");
    }
    for (int it = 0; it < 1000; it++) { /* rank 2: u1 v1^T + u2 v2^T */
        double u[6], v[6];
        for (int i = 0; i < 6; i++) u[i] = rnd(), v[i] = rnd();
        for (int i = 0; i < 3; i++)
            for (int j = 0; j < 3; j++) a[3 * i + j] = u[i] * v[j] + u[3 + i] * v[3 + j];
        check_one(a, "rank-2");
    }
    for (int it = 0; it < 1000; it++) { /* reflections: Q diag(s1, s2, -s3) with s > 0 */
        random_rotation(q);
        memset(d, 0, sizeof d);
        d[0] = 0.5 + fabs(rnd()), d[4] = 0.5 + fabs(rnd()), d[8] = -(0.1 + fabs(rnd()));
        matmul(q, d, tmp);
        random_rotation(q);
        matmul(tmp, q, a);
        check_one(a, "reflection");
    }
    for (int it = 0; it < 1000; it++) { /* near identity */
        for (int i = 0; i < 9; i++) a[i] = ((i % 4) == 0 ? 1.0 : 0.0) + 1e-8 * rnd();
        check_one(a, "near-identity");
    }
    for (int it = 0; it < 1000; it++) { /* exact rotations, scaled: R itself is the answer */
        random_rotation(q);
        double s = 0.01 + fabs(rnd()) * 100;
        for (int i = 0; i < 9; i++) a[i] = s * q[i];
        double r[9];
        double tr = dk_closest_rotation(a, r);
        double e = 0;
        for (int i = 0; i < 9; i++)
            if (fabs(r[i] - q[i]) > e) e = fabs(r[i] - q[i]);
        CHECK_MSG(e <= 1e-12, "rotation recovered to %g", e);
        CHECK_NEAR(tr, 3 * s, 1e-12 * s * 3);
        check_one(a, "scaled rotation");
    }
    for (int it = 0; it < 500; it++) { /* tiny and huge magnitudes */
        double s = (it % 2) ? 1e-300 : 1e300;
        for (int i = 0; i < 9; i++) a[i] = rnd() * s;
        double r[9];
        dk_closest_rotation(a, r);
        int finite = 1;
        for (int i = 0; i < 9; i++) finite &= isfinite(r[i]);
        CHECK(finite);
        CHECK_NEAR(det3(r), 1.0, 1e-12);
        double b[9], rref[9], best, gap, s1;
        for (int i = 0; i < 9; i++) b[i] = a[i] / s;
        if (svd_reference(b, rref, &best, &gap, &s1) && gap > 1e-3 * s1)
            for (int i = 0; i < 9; i++) CHECK_NEAR(r[i], rref[i], 1e-9);
    }
    printf("rotation: %d matrices, %d compared entrywise; worst trace err %.2e, orth %.2e, "
           "det %.2e, |R-Rsvd| %.2e\n",
           n_checked, n_compared, worst_trace, worst_orth, worst_det, worst_r);
}

static void test_special(void)
{
    double r[9];
    const double zero[9] = {0};
    double tr = dk_closest_rotation(zero, r);
    CHECK(tr == 0.0);
    for (int i = 0; i < 9; i++) CHECK(r[i] == ((i % 4) == 0 ? 1.0 : 0.0));

    /* Identity and a pure reflection diag(1, 1, -1): best is the identity, value 1. */
    const double id[9] = {1, 0, 0, 0, 1, 0, 0, 0, 1};
    tr = dk_closest_rotation(id, r);
    CHECK_NEAR(tr, 3.0, 1e-15);
    for (int i = 0; i < 9; i++) CHECK_NEAR(r[i], id[i], 1e-15);
    const double refl[9] = {2, 0, 0, 0, 3, 0, 0, 0, -1};
    tr = dk_closest_rotation(refl, r);
    CHECK_NEAR(tr, 4.0, 1e-14); /* 2 + 3 - 1 */
    for (int i = 0; i < 9; i++) CHECK_NEAR(r[i], id[i], 1e-14);
    check_one(refl, "diag reflection");

    /* -I: every half-turn is optimal with value 1. */
    const double mid[9] = {-1, 0, 0, 0, -1, 0, 0, 0, -1};
    tr = dk_closest_rotation(mid, r);
    CHECK_NEAR(tr, 1.0, 1e-14);
    check_one(mid, "-identity");

    /* A 90 degree turn about z, and a known rank-1 matrix e_x e_y^T: maximum 1. */
    const double rz[9] = {0, -1, 0, 1, 0, 0, 0, 0, 1};
    tr = dk_closest_rotation(rz, r);
    CHECK_NEAR(tr, 3.0, 1e-14);
    for (int i = 0; i < 9; i++) CHECK_NEAR(r[i], rz[i], 1e-14);
    const double r1[9] = {0, 1, 0, 0, 0, 0, 0, 0, 0};
    tr = dk_closest_rotation(r1, r);
    CHECK_NEAR(tr, 1.0, 1e-14);
    CHECK_NEAR(r[1], 1.0, 1e-14);
}

static void test_timing(void)
{
    enum { NM = 1024, CALLS = 1000000 };
    static double mats[NM][9];
    for (int m = 0; m < NM; m++) {
        double q[9];
        random_rotation(q);
        /* ARAP-like covariance: near a rotation with noise. */
        for (int i = 0; i < 9; i++) mats[m][i] = q[i] * 3 + 0.3 * rnd();
    }
    double r[9], acc = 0;
    double t0 = now();
    for (int c = 0; c < CALLS; c++) acc += dk_closest_rotation(mats[c & (NM - 1)], r);
    double t1 = now();
    double random_acc = 0;
    for (int m = 0; m < NM; m++)
        for (int i = 0; i < 9; i++) mats[m][i] = rnd();
    double t2 = now();
    for (int c = 0; c < CALLS; c++) random_acc += dk_closest_rotation(mats[c & (NM - 1)], r);
    double t3 = now();
    /* Flat one-rings: rank-2 covariances (the cofactor trick keeps them on the fast path)
     * and rank-1 ones (Jacobi fallback). */
    for (int m = 0; m < NM; m++) {
        double u[6], v[6];
        for (int i = 0; i < 6; i++) u[i] = rnd(), v[i] = rnd();
        for (int i = 0; i < 3; i++)
            for (int j = 0; j < 3; j++)
                mats[m][3 * i + j] = u[i] * v[j] + ((m & 1) ? u[3 + i] * v[3 + j] : 0.0);
    }
    double flat_acc = 0;
    double t4 = now();
    for (int c = 0; c < CALLS; c++) flat_acc += dk_closest_rotation(mats[c & (NM - 1)], r);
    double t5 = now();
    printf("dk_closest_rotation: %.1f ns/call (ARAP-like), %.1f ns/call (random), "
           "%.1f ns/call (half rank-2, half rank-1) [checksum %.3f %.3f %.3f]\n",
           (t1 - t0) / CALLS * 1e9, (t3 - t2) / CALLS * 1e9, (t5 - t4) / CALLS * 1e9, acc,
           random_acc, flat_acc);
    CHECK(isfinite(acc) && isfinite(random_acc) && isfinite(flat_acc));
}

/* dk_rotation_quaternion and dk_quaternion_rotation are inverses: R -> q -> R to rounding
 * (half turns and the identity included), and q -> R -> q up to the sign (w >= 0). */
static void test_quaternion_round_trip(void)
{
    const double axes[4][3] = {{1, 0, 0}, {0, 0.6, 0.8}, {0.48, 0.6, 0.64}, {-0.36, 0.48, 0.8}};
    const double angles[5] = {0.0, 0.3, 1.7, 3.14159265358979, -2.5};
    for (int a = 0; a < 4; a++)
        for (int k = 0; k < 5; k++) {
            const double *u = axes[a], th = angles[k], c = cos(th), s = sin(th);
            double R[9], q[4], back[9];
            for (int i = 0; i < 3; i++)
                for (int j = 0; j < 3; j++)
                    R[3 * i + j] = (i == j ? c : 0.0) + (1 - c) * u[i] * u[j];
            R[1] -= s * u[2], R[2] += s * u[1], R[3] += s * u[2];
            R[5] -= s * u[0], R[6] -= s * u[1], R[7] += s * u[0];
            dk_rotation_quaternion(R, q);
            dk_quaternion_rotation(q, back);
            double err = 0.0;
            for (int i = 0; i < 9; i++)
                err = fmax(err, fabs(back[i] - R[i]));
            CHECK_MSG(err < 1e-14, "axis %d angle %g: %g", a, th, err);
            CHECK(q[0] >= 0.0);
        }
}

DK_TEST_MAIN(test_special, test_random_families, test_timing, test_quaternion_round_trip)
