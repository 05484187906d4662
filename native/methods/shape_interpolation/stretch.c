/* Shape interpolation: stretches blended in the logarithm (dk_shape_interpolation.h).
 *
 * A stretch S (symmetric positive definite 3 x 3, the polar part of a triangle's gradient)
 * is blended as S(w) = exp(sum_k w_k log S_k): its determinant is prod_k det(S_k)^w_k, so a
 * shear that keeps a triangle's area keeps it at every weight, where the straight blend
 * (1 - w) I + w S inflates it (a shear of 45 degrees by 6% half way: the twisted armadillo
 * gained 8% volume half way with it). Symmetric matrices are stored as their 6 upper entries
 * (xx, xy, xz, yy, yz, zz). */
#include "si_internal.h"

#include <math.h>
#include <string.h>

/* The smallest eigenvalue a stretch is taken with: a triangle collapsed in a pose (an
 * eigenvalue 0) blends from a finite logarithm. */
#define MIN_STRETCH 1e-8

static void to_full(const double s[6], double a[9])
{
    a[0] = s[0], a[1] = s[1], a[2] = s[2];
    a[3] = s[1], a[4] = s[3], a[5] = s[4];
    a[6] = s[2], a[7] = s[4], a[8] = s[5];
}

void si_sym_log(const double s[6], double out[6])
{
    /* cyclic Jacobi: A = Q diag(l) Q^T, then log A = Q diag(log l) Q^T */
    double a[9], q[9] = {1, 0, 0, 0, 1, 0, 0, 0, 1};
    to_full(s, a);
    for (int sweep = 0; sweep < 32; sweep++) {
        const double off = a[1] * a[1] + a[2] * a[2] + a[5] * a[5];
        const double diag = a[0] * a[0] + a[4] * a[4] + a[8] * a[8];
        if (!(off > 1e-32 * diag))
            break;
        for (int p = 0; p < 2; p++)
            for (int r = p + 1; r < 3; r++) {
                const double apr = a[3 * p + r];
                if (apr == 0.0)
                    continue;
                const double theta = (a[3 * r + r] - a[3 * p + p]) / (2.0 * apr);
                const double t = (theta >= 0.0 ? 1.0 : -1.0) /
                                 (fabs(theta) + sqrt(theta * theta + 1.0));
                const double c = 1.0 / sqrt(t * t + 1.0), sn = t * c;
                for (int k = 0; k < 3; k++) { /* a <- J^T a J, q <- q J */
                    const double akp = a[3 * k + p], akr = a[3 * k + r];
                    a[3 * k + p] = c * akp - sn * akr;
                    a[3 * k + r] = sn * akp + c * akr;
                }
                for (int k = 0; k < 3; k++) {
                    const double apk = a[3 * p + k], ark = a[3 * r + k];
                    a[3 * p + k] = c * apk - sn * ark;
                    a[3 * r + k] = sn * apk + c * ark;
                }
                for (int k = 0; k < 3; k++) {
                    const double qkp = q[3 * k + p], qkr = q[3 * k + r];
                    q[3 * k + p] = c * qkp - sn * qkr;
                    q[3 * k + r] = sn * qkp + c * qkr;
                }
            }
    }
    double l[3];
    for (int k = 0; k < 3; k++)
        l[k] = log(fmax(a[4 * k], MIN_STRETCH));
    int n = 0;
    for (int r = 0; r < 3; r++)
        for (int c = r; c < 3; c++)
            out[n++] = q[3 * r] * l[0] * q[3 * c] + q[3 * r + 1] * l[1] * q[3 * c + 1] +
                       q[3 * r + 2] * l[2] * q[3 * c + 2];
}

/* c = a b for symmetric a, b that commute (c is then symmetric): its 6 entries. */
static void sym_mul(const double a[6], const double b[6], double c[6])
{
    c[0] = a[0] * b[0] + a[1] * b[1] + a[2] * b[2];
    c[1] = a[0] * b[1] + a[1] * b[3] + a[2] * b[4];
    c[2] = a[0] * b[2] + a[1] * b[4] + a[2] * b[5];
    c[3] = a[1] * b[1] + a[3] * b[3] + a[4] * b[4];
    c[4] = a[1] * b[2] + a[3] * b[4] + a[4] * b[5];
    c[5] = a[2] * b[2] + a[4] * b[4] + a[5] * b[5];
}

void si_sym_exp(const double s[6], double out[9])
{
    /* scaling and squaring: |L / 2^m| <= 1/8, then Taylor to order 10 (remainder below
     * 1e-16 of the result) by Horner's scheme, squared m times */
    double norm = 0.0;
    for (int r = 0; r < 3; r++) {
        static const int row[3][3] = {{0, 1, 2}, {1, 3, 4}, {2, 4, 5}};
        double sum = 0.0;
        for (int c = 0; c < 3; c++)
            sum += fabs(s[row[r][c]]);
        norm = fmax(norm, sum);
    }
    int m = 0;
    double scale = 1.0;
    while (norm * scale > 0.125 && m < 60) {
        scale *= 0.5;
        m++;
    }
    double x[6], e[6] = {1, 0, 0, 1, 0, 1}, t[6];
    for (int k = 0; k < 6; k++)
        x[k] = s[k] * scale;
    for (int order = 10; order >= 1; order--) { /* e <- I + x e / order */
        sym_mul(x, e, t);
        for (int k = 0; k < 6; k++)
            e[k] = t[k] / (double)order;
        e[0] += 1.0, e[3] += 1.0, e[5] += 1.0;
    }
    for (int k = 0; k < m; k++) {
        sym_mul(e, e, t);
        memcpy(e, t, sizeof t);
    }
    to_full(e, out);
}
