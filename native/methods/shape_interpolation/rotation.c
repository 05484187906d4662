/* Shape interpolation: rotation vectors (the exponential and logarithm of SO(3)) and the
 * 3 x 3 products the blend takes. Row-major matrices; a rotation vector is the angle (radians)
 * times the unit axis, turning counter-clockwise about it (R x = exp([w]_x) x). */
#include "si_internal.h"

#include "dk_operators.h"

#include <math.h>

void si_rotation_exp(const double w[3], double R[9])
{
    const double t2 = w[0] * w[0] + w[1] * w[1] + w[2] * w[2];
    const double t = sqrt(t2);
    double a, b; /* R = I + a K + b K^2, K = [w]_x */
    if (t < 1e-4) { /* the series: the closed forms lose digits to cancellation here */
        a = 1.0 - t2 / 6.0;
        b = 0.5 - t2 / 24.0;
    } else {
        a = sin(t) / t;
        b = (1.0 - cos(t)) / t2;
    }
    const double x = w[0], y = w[1], z = w[2];
    /* K^2 = w w^T - t2 I */
    R[0] = 1.0 + b * (x * x - t2);
    R[1] = -a * z + b * x * y;
    R[2] = a * y + b * x * z;
    R[3] = a * z + b * x * y;
    R[4] = 1.0 + b * (y * y - t2);
    R[5] = -a * x + b * y * z;
    R[6] = -a * y + b * x * z;
    R[7] = a * x + b * y * z;
    R[8] = 1.0 + b * (z * z - t2);
}

double si_rotation_log(const double R[9], double w[3])
{
    double q[4]; /* unit, q[0] >= 0: w = 2 atan2(|v|, q0) v / |v| */
    dk_rotation_quaternion(R, q);
    const double sv = sqrt(q[1] * q[1] + q[2] * q[2] + q[3] * q[3]);
    if (!(sv > 0.0)) {
        w[0] = w[1] = w[2] = 0.0;
        return 0.0;
    }
    const double angle = 2.0 * atan2(sv, q[0]);
    const double f = sv < 1e-12 ? 2.0 / q[0] : angle / sv;
    for (int k = 0; k < 3; k++)
        w[k] = f * q[k + 1];
    return angle;
}

void si_mat3_mul(const double a[9], const double b[9], double c[9])
{
    for (int r = 0; r < 3; r++)
        for (int k = 0; k < 3; k++)
            c[3 * r + k] = a[3 * r] * b[k] + a[3 * r + 1] * b[3 + k] + a[3 * r + 2] * b[6 + k];
}

void si_mat3_tmul(const double a[9], const double b[9], double c[9])
{
    for (int r = 0; r < 3; r++)
        for (int k = 0; k < 3; k++)
            c[3 * r + k] = a[r] * b[k] + a[3 + r] * b[3 + k] + a[6 + r] * b[6 + k];
}
