/* Locating points in tetrahedra (dk_locate_in_tetrahedra, dk_tetrahedron_frame): on a cube
 * cut into six tetrahedra, a point inside gets coordinates >= 0 that rebuild it exactly; a
 * point outside gets, extrapolated, coordinates that rebuild it and move it by any affine map
 * of the corners exactly (what the multi-scale prolongation relies on), clamped, weights in
 * [0, 1]; a point far away, clamped, its nearest corner; bad input is refused. */
#include <math.h>
#include <stdlib.h>
#include <string.h>

#include "dk_operators.h"
#include "dk_test.h"

/* the unit cube's corners (bit k of the index: coordinate k) and its six tetrahedra along
 * the diagonal 0 -> 7, one per order of the three axes */
static void cube(double p[24], dk_index t[24])
{
    for (int i = 0; i < 8; i++)
        for (int k = 0; k < 3; k++)
            p[3 * i + k] = (double)((i >> k) & 1);
    static const int order[6][3] = {{0, 1, 2}, {0, 2, 1}, {1, 0, 2},
                                    {1, 2, 0}, {2, 0, 1}, {2, 1, 0}};
    for (int s = 0; s < 6; s++) {
        int v = 0;
        t[4 * s] = 0;
        for (int k = 0; k < 3; k++) {
            v |= 1 << order[s][k];
            t[4 * s + k + 1] = v;
        }
    }
}

static void frames_of(const double *p, const dk_index *t, int nt, double *f)
{
    for (int s = 0; s < nt; s++) {
        double g[12];
        CHECK(fabs(dk_tetrahedron_frame(p + 3 * t[4 * s], p + 3 * t[4 * s + 1],
                                        p + 3 * t[4 * s + 2], p + 3 * t[4 * s + 3], g)) ==
              1.0); /* six times each one's volume, 1/6 */
        memcpy(f + 12 * s, p + 3 * t[4 * s], 3 * sizeof *f);
        memcpy(f + 12 * s + 3, g + 3, 9 * sizeof *f);
    }
}

static double lcg(unsigned *s)
{
    *s = *s * 1103515245u + 12345u;
    return (double)((*s >> 8) & 0xffffff) / 16777216.0;
}

/* sum_k w_k f(x_k) for an affine f(x) = A x + b, against f(q) */
static double affine_error(const double *p, const dk_index *c, const double *w, const double *q)
{
    static const double A[9] = {1.3, -0.4, 2.0, 0.7, 0.9, -1.1, 0.2, 3.0, 0.5};
    static const double b[3] = {5.0, -2.0, 0.25};
    double err = 0.0;
    for (int i = 0; i < 3; i++) {
        double want = b[i], got = 0.0;
        for (int k = 0; k < 3; k++)
            want += A[3 * i + k] * q[k];
        for (int j = 0; j < 4; j++)
            if (c[j] >= 0) {
                double v = b[i];
                for (int k = 0; k < 3; k++)
                    v += A[3 * i + k] * p[3 * c[j] + k];
                got += w[j] * v;
            }
        err = fmax(err, fabs(got - want));
    }
    return err;
}

static void test_frame(void)
{
    const double x[12] = {0.1, 0.2, 0.3, 1.5, 0.1, 0.0, 0.2, 1.1, 0.4, 0.3, 0.1, 2.0};
    double g[12];
    const double det = dk_tetrahedron_frame(x, x + 3, x + 6, x + 9, g);
    CHECK(det > 0.0);
    for (int k = 0; k < 4; k++) /* coordinate k is 1 at corner k, 0 at the others */
        for (int j = 0; j < 4; j++) {
            double l = k == 0 ? 1.0 : 0.0;
            for (int d = 0; d < 3; d++)
                l += g[3 * k + d] * (x[3 * j + d] - x[d]);
            CHECK_NEAR(l, j == k ? 1.0 : 0.0, 1e-12);
        }
    const double flat[12] = {0, 0, 0, 1, 0, 0, 0, 1, 0, 1, 1, 0};
    CHECK(dk_tetrahedron_frame(flat, flat + 3, flat + 6, flat + 9, g) == 0.0);
}

static void test_cube(void)
{
    double p[24], f[72];
    dk_index t[24];
    cube(p, t);
    frames_of(p, t, 6, f);
    enum { N = 400 };
    double *q = malloc(3 * N * sizeof *q), *w = malloc(4 * N * sizeof *w);
    dk_index *c = malloc(4 * N * sizeof *c);
    CHECK(q && w && c);
    unsigned seed = 7;
    for (int mode = 0; mode < 2; mode++) {
        /* half inside, half outside within 0.3 of the cube (but not inside it) */
        for (int i = 0; i < N; i++)
            for (int k = 0; k < 3; k++)
                q[3 * i + k] = i < N / 2 ? lcg(&seed) : -0.3 + 1.6 * lcg(&seed);
        for (int i = N / 2; i < N; i++)
            if (q[3 * i] >= 0 && q[3 * i] <= 1 && q[3 * i + 1] >= 0 && q[3 * i + 1] <= 1 &&
                q[3 * i + 2] >= 0 && q[3 * i + 2] <= 1)
                q[3 * i] = 1.1;
        dk_error err = {0};
        CHECK(dk_locate_in_tetrahedra(p, 8, t, f, 6, 0.0, (dk_locate_mode)mode, q, N, c, w,
                                      &err) == DK_OK);
        for (int i = 0; i < N; i++) {
            const double *wi = w + 4 * i;
            CHECK(c[4 * i] >= 0 && c[4 * i + 3] >= 0); /* a tetrahedron, not a corner alone */
            CHECK_NEAR(wi[0] + wi[1] + wi[2] + wi[3], 1.0, 1e-12);
            if (i < N / 2 || mode == DK_LOCATE_EXTRAPOLATE)
                CHECK_MSG(affine_error(p, c + 4 * i, wi, q + 3 * i) < 1e-12,
                          "point %d (mode %d) not rebuilt", i, mode);
            if (i < N / 2 || mode == DK_LOCATE_CLAMP)
                for (int k = 0; k < 4; k++)
                    CHECK(wi[k] >= -1e-12 && wi[k] <= 1.0 + 1e-12);
            if (i >= N / 2 && mode == DK_LOCATE_EXTRAPOLATE)
                CHECK(fmin(fmin(wi[0], wi[1]), fmin(wi[2], wi[3])) < 0.0);
        }
    }
    /* far away: extrapolated, still exact for affine maps; clamped, its nearest corner */
    const double far[3] = {40.0, 41.0, -0.2};
    dk_error err = {0};
    CHECK(dk_locate_in_tetrahedra(p, 8, t, f, 6, 0.0, DK_LOCATE_EXTRAPOLATE, far, 1, c, w,
                                  &err) == DK_OK);
    CHECK(c[3] >= 0 && affine_error(p, c, w, far) < 1e-10);
    CHECK(dk_locate_in_tetrahedra(p, 8, t, f, 6, 0.0, DK_LOCATE_CLAMP, far, 1, c, w, &err) ==
          DK_OK);
    CHECK(c[0] == 3 && c[1] == -1 && w[0] == 1.0 && w[1] == 0.0);
    /* nothing to locate in */
    CHECK(dk_locate_in_tetrahedra(p, 8, t, f, 0, 0.0, DK_LOCATE_CLAMP, far, 1, c, w, &err) ==
          DK_ERR_INVALID_ARGUMENT);
    CHECK(strstr(err.message, "no tetrahedron") != NULL);
    t[5] = 8; /* a corner out of range */
    CHECK(dk_locate_in_tetrahedra(p, 8, t, f, 6, 0.0, DK_LOCATE_CLAMP, far, 1, c, w, &err) ==
          DK_ERR_INVALID_ARGUMENT);
    CHECK(strstr(err.message, "out of range") != NULL);
    t[5] = 1;
    CHECK(dk_locate_in_tetrahedra(p, 8, t, f, 6, 1e-4, DK_LOCATE_CLAMP, far, 1, c, w, &err) ==
          DK_ERR_INVALID_ARGUMENT); /* 10^12 cells */
    CHECK(strstr(err.message, "2^28") != NULL);
    free(q);
    free(w);
    free(c);
}

DK_TEST_MAIN(test_frame, test_cube)
