/* Generalized barycentric coordinates in the plane (dk_coordinates.h): what every kind owes
 * (partition of unity, linear precision, the vertices' unit vectors, the edges' linear
 * interpolation), each kind's own (Wachspress and mean value positive inside convex
 * polygons, mean value also on non-convex ones and outside), agreement with the slides'
 * formula evaluated independently (angles by atan2), and what is refused. */
#include <math.h>
#include <string.h>

#include "dk_coordinates.h"
#include "dk_test.h"

#define PI 3.14159265358979323846

static double rnd(unsigned *s)
{
    *s = *s * 1664525u + 1013904223u;
    return (double)(*s >> 8) / 16777216.0;
}

/* sum lambda = 1 and sum lambda v = p, the worse of the two errors */
static double precision(const double *poly, int n, const double *p, const double *lambda)
{
    double s = 0.0, x = 0.0, y = 0.0;
    for (int i = 0; i < n; i++) {
        s += lambda[i];
        x += lambda[i] * poly[2 * i];
        y += lambda[i] * poly[2 * i + 1];
    }
    return fmax(fabs(s - 1.0), fmax(fabs(x - p[0]), fabs(y - p[1])));
}

/* A regular n-gon of radius 1 around (0.3, -0.2), counter-clockwise (or clockwise). */
static void ngon(int n, int clockwise, double *poly)
{
    for (int i = 0; i < n; i++) {
        const double a = (clockwise ? -1.0 : 1.0) * 2.0 * PI * i / n + 0.1;
        poly[2 * i] = 0.3 + cos(a);
        poly[2 * i + 1] = -0.2 + sin(a);
    }
}

typedef dk_status (*coords_fn)(const double *, int, const double *, double *, dk_error *);

static void check_convex(const char *name, coords_fn f)
{
    unsigned st = 5;
    for (int n = 3; n <= 8; n++)
        for (int cw = 0; cw < 2; cw++) {
            double poly[16], lambda[8], p[2];
            ngon(n, cw, poly);
            dk_error e = {0};
            double worst = 0.0, least = 1.0;
            for (int k = 0; k < 200; k++) { /* random points inside (r < cos(pi/n)) */
                const double r = 0.999 * cos(PI / n) * sqrt(rnd(&st)), a = 2 * PI * rnd(&st);
                p[0] = 0.3 + r * cos(a), p[1] = -0.2 + r * sin(a);
                if (f(poly, n, p, lambda, &e) != DK_OK) {
                    CHECK_MSG(0, "%s: %s", name, e.message);
                    break;
                }
                worst = fmax(worst, precision(poly, n, p, lambda));
                for (int i = 0; i < n; i++)
                    least = fmin(least, lambda[i]);
            }
            CHECK_MSG(worst < 1e-13, "%s, %d-gon: linear precision off by %g", name, n, worst);
            CHECK_MSG(least > 0.0, "%s, %d-gon: a negative weight %g inside", name, n, least);
            /* a vertex: its unit vector; an edge's midpoint: half and half */
            CHECK(f(poly, n, poly + 2, lambda, &e) == DK_OK && lambda[1] == 1.0 && lambda[0] == 0.0);
            const double mid[2] = {0.5 * (poly[2] + poly[4]), 0.5 * (poly[3] + poly[5])};
            CHECK(f(poly, n, mid, lambda, &e) == DK_OK && fabs(lambda[1] - 0.5) < 1e-12 &&
                  fabs(lambda[2] - 0.5) < 1e-12);
            /* near the boundary: continuous with the edge's interpolation */
            const double near[2] = {mid[0] + 1e-9 * (0.3 - mid[0]), mid[1] + 1e-9 * (-0.2 - mid[1])};
            CHECK(f(poly, n, near, lambda, &e) == DK_OK && fabs(lambda[1] - 0.5) < 1e-6 &&
                  fabs(lambda[2] - 0.5) < 1e-6 && precision(poly, n, near, lambda) < 1e-12);
        }
}

static void test_barycentric(void)
{
    const double t[6] = {0.1, 0.2, 2.0, -0.3, 0.7, 1.9};
    double l[3], p[2];
    unsigned st = 1;
    dk_error e = {0};
    double worst = 0.0;
    for (int k = 0; k < 100; k++) {
        p[0] = -1 + 4 * rnd(&st), p[1] = -1 + 4 * rnd(&st); /* in and out */
        CHECK(dk_barycentric_2d(t, p, l, &e) == DK_OK);
        worst = fmax(worst, precision(t, 3, p, l));
    }
    CHECK(worst < 1e-13);
    CHECK(dk_barycentric_2d(t, t + 4, l, &e) == DK_OK && fabs(l[2] - 1.0) < 1e-15);
    const double flat[6] = {0, 0, 1, 1, 2, 2};
    CHECK(dk_barycentric_2d(flat, p, l, &e) == DK_ERR_INVALID_ARGUMENT &&
          strstr(e.message, "degenerate"));
    /* Wachspress and mean value on a triangle are its barycentric coordinates */
    double w[3], m[3];
    p[0] = 0.8, p[1] = 0.5;
    CHECK(dk_barycentric_2d(t, p, l, &e) == DK_OK && dk_wachspress_2d(t, 3, p, w, &e) == DK_OK &&
          dk_mean_value_2d(t, 3, p, m, &e) == DK_OK);
    for (int i = 0; i < 3; i++)
        CHECK(fabs(w[i] - l[i]) < 1e-13 && fabs(m[i] - l[i]) < 1e-13);
}

static void test_wachspress(void)
{
    check_convex("Wachspress", dk_wachspress_2d);
    double poly[12], l[6];
    ngon(6, 0, poly);
    dk_error e = {0};
    const double out[2] = {3.0, 0.0};
    CHECK(dk_wachspress_2d(poly, 6, out, l, &e) == DK_ERR_INVALID_ARGUMENT &&
          strstr(e.message, "outside"));
    const double dent[12] = {0, 0, 2, 0, 2, 2, 1, 0.5, 0, 2, -0.5, 1};
    const double in[2] = {0.5, 0.3};
    CHECK(dk_wachspress_2d(dent, 6, in, l, &e) == DK_ERR_INVALID_ARGUMENT &&
          strstr(e.message, "convex"));
    /* the square's Wachspress coordinates are bilinear: the slides' worked example */
    const double sq[8] = {0, 0, 1, 0, 1, 1, 0, 1};
    const double uv[2] = {0.6, 0.7};
    CHECK(dk_wachspress_2d(sq, 4, uv, l, &e) == DK_OK);
    CHECK_NEAR(l[0], 0.4 * 0.3, 1e-14);
    CHECK_NEAR(l[1], 0.6 * 0.3, 1e-14);
    CHECK_NEAR(l[2], 0.6 * 0.7, 1e-14);
    CHECK_NEAR(l[3], 0.4 * 0.7, 1e-14);
}

/* The slides' formula with the angles from atan2: w_i = (tan(a_i-1/2) + tan(a_i/2)) / r_i. */
static void slides_mean_value(const double *poly, int n, const double *p, double *l)
{
    double sum = 0.0;
    for (int i = 0; i < n; i++) {
        const int h = (i + n - 1) % n, j = (i + 1) % n;
        const double ai = atan2(poly[2 * j + 1] - p[1], poly[2 * j] - p[0]) -
                          atan2(poly[2 * i + 1] - p[1], poly[2 * i] - p[0]);
        const double ah = atan2(poly[2 * i + 1] - p[1], poly[2 * i] - p[0]) -
                          atan2(poly[2 * h + 1] - p[1], poly[2 * h] - p[0]);
        /* angles into (-pi, pi] */
        const double a1 = atan2(sin(ai), cos(ai)), a0 = atan2(sin(ah), cos(ah));
        l[i] = (tan(a0 / 2) + tan(a1 / 2)) / hypot(poly[2 * i] - p[0], poly[2 * i + 1] - p[1]);
        sum += l[i];
    }
    for (int i = 0; i < n; i++)
        l[i] /= sum;
}

static void test_mean_value(void)
{
    check_convex("mean value", dk_mean_value_2d);
    /* a non-convex star, inside and outside: linear precision, and the slides' formula */
    double star[20], l[10], s[10], p[2];
    for (int i = 0; i < 10; i++) {
        const double r = i % 2 ? 0.4 : 1.0, a = PI * i / 5;
        star[2 * i] = r * cos(a), star[2 * i + 1] = r * sin(a);
    }
    unsigned st = 9;
    dk_error e = {0};
    double worst = 0.0, diff = 0.0;
    int negative = 0;
    for (int k = 0; k < 400; k++) {
        p[0] = -1.5 + 3 * rnd(&st), p[1] = -1.5 + 3 * rnd(&st);
        if (dk_mean_value_2d(star, 10, p, l, &e) != DK_OK) {
            CHECK_MSG(0, "%s", e.message);
            break;
        }
        worst = fmax(worst, precision(star, 10, p, l));
        slides_mean_value(star, 10, p, s);
        for (int i = 0; i < 10; i++) {
            diff = fmax(diff, fabs(l[i] - s[i]));
            negative |= l[i] < 0;
        }
    }
    CHECK_MSG(worst < 1e-11, "mean value, star: linear precision off by %g", worst);
    CHECK_MSG(diff < 1e-9, "mean value, star: %g from the slides' formula", diff);
    CHECK(negative); /* outside the kernel some weights are negative: they may be */
    /* on an edge's line beyond its ends: finite, exact */
    const double sq[8] = {0, 0, 1, 0, 1, 1, 0, 1}, beyond[2] = {2.5, 0.0};
    CHECK(dk_mean_value_2d(sq, 4, beyond, l, &e) == DK_OK &&
          precision(sq, 4, beyond, l) < 1e-13);
    /* refusals */
    const double rep[8] = {0, 0, 1, 0, 1, 0, 0, 1};
    CHECK(dk_mean_value_2d(rep, 4, p, l, &e) == DK_ERR_INVALID_ARGUMENT &&
          strstr(e.message, "repeats"));
    const double line[6] = {0, 0, 1, 1, 2, 2};
    CHECK(dk_mean_value_2d(line, 3, p, l, &e) == DK_ERR_INVALID_ARGUMENT &&
          strstr(e.message, "no area"));
    CHECK(dk_mean_value_2d(sq, 2, p, l, &e) == DK_ERR_INVALID_ARGUMENT);
    const double nan_p[2] = {NAN, 0.0};
    CHECK(dk_mean_value_2d(sq, 4, nan_p, l, &e) == DK_ERR_NONFINITE);
}

DK_TEST_MAIN(test_barycentric, test_wachspress, test_mean_value)
