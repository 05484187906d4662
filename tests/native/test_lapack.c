/* The dense symmetric eigensolvers without LAPACKE's allocations (dk_lapack.h): on a
 * matrix with known eigenpairs, dsyev and dsyevd give its eigenvalues in ascending order and
 * orthonormal eigenvectors that diagonalise it; dstev does on a tridiagonal one. */
#include <math.h>

#include "dk_lapack.h"
#include "dk_test.h"

/* Q diag(1, 2, 5) Q^T for the orthonormal Q of a turn, column-major (symmetric). */
static void known(double a[9])
{
    const double c = cos(0.7), s = sin(0.7), lam[3] = {5.0, 1.0, 2.0};
    const double q[9] = {c, s, 0.0, -s, c, 0.0, 0.0, 0.0, 1.0}; /* columns: the vectors */
    for (int i = 0; i < 3; i++)
        for (int j = 0; j < 3; j++) {
            double t = 0.0;
            for (int k = 0; k < 3; k++)
                t += q[3 * k + i] * lam[k] * q[3 * k + j];
            a[3 * j + i] = t;
        }
}

static void check_pairs(const double a[9], const double v[9], const double w[3])
{
    CHECK(fabs(w[0] - 1.0) < 1e-12 && fabs(w[1] - 2.0) < 1e-12 && fabs(w[2] - 5.0) < 1e-12);
    for (int k = 0; k < 3; k++)
        for (int i = 0; i < 3; i++) {
            double av = 0.0;
            for (int j = 0; j < 3; j++)
                av += a[3 * j + i] * v[3 * k + j];
            CHECK(fabs(av - w[k] * v[3 * k + i]) < 1e-12); /* A v = w v */
        }
    for (int k = 0; k < 3; k++)
        for (int l = 0; l < 3; l++) {
            double d = 0.0;
            for (int i = 0; i < 3; i++)
                d += v[3 * k + i] * v[3 * l + i];
            CHECK(fabs(d - (k == l)) < 1e-12);
        }
}

static void test_dense(void)
{
    double a[9], v[9], w[3];
    known(a);
    for (int i = 0; i < 9; i++) v[i] = a[i];
    CHECK(dk_lapack_dsyev('V', 3, v, w) == 0);
    check_pairs(a, v, w);
    for (int i = 0; i < 9; i++) v[i] = a[i];
    CHECK(dk_lapack_dsyevd('V', 3, v, w) == 0);
    check_pairs(a, v, w);
    for (int i = 0; i < 9; i++) v[i] = a[i];
    CHECK(dk_lapack_dsyev('N', 3, v, w) == 0);
    CHECK(fabs(w[0] - 1.0) < 1e-12 && fabs(w[2] - 5.0) < 1e-12);
}

static void test_tridiagonal(void)
{
    /* tridiag(-1, 2, -1) of order 4: eigenvalues 2 - 2 cos(k pi / 5) */
    double d[4] = {2, 2, 2, 2}, e[4] = {-1, -1, -1, 0}, z[16];
    CHECK(dk_lapack_dstev('V', 4, d, e, z, 4) == 0);
    for (int k = 0; k < 4; k++)
        CHECK(fabs(d[k] - (2.0 - 2.0 * cos((k + 1) * 3.14159265358979323846 / 5.0))) < 1e-12);
    for (int k = 0; k < 4; k++) {
        double n = 0.0;
        for (int i = 0; i < 4; i++) n += z[4 * k + i] * z[4 * k + i];
        CHECK(fabs(n - 1.0) < 1e-12);
    }
}

DK_TEST_MAIN(test_dense, test_tridiagonal)
