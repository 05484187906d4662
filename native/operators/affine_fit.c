/* DeformKit: the affine map that reproduces a point set's images (see dk_operators.h). Shared
 * by the methods whose solution is affine in the handle transforms (Laplacian editing's
 * affine basis, ARAP's warm-start response basis): targets given as positions take the fast
 * path when some affine map of the rest positions reproduces them. */
#include "dk_operators.h"

#include <math.h>
#include <string.h>

/* The largest |r| of q_k - T [p_k; 1] over the points, and the largest coordinate magnitude
 * seen (rest or image) into *scale. */
static double misfit_of(const double *rest, const dk_index *verts, dk_index count,
                        const double *q, const double T[16], double *scale)
{
    double misfit = 0.0, sc = 0.0;
    for (dk_index k = 0; k < count; k++) {
        const double *p = rest + 3 * (size_t)verts[k];
        const double *qk = q + 3 * (size_t)k;
        for (int d = 0; d < 3; d++) {
            const double r = fabs(T[4 * d] * p[0] + T[4 * d + 1] * p[1] + T[4 * d + 2] * p[2] +
                                  T[4 * d + 3] - qk[d]);
            misfit = r > misfit ? r : misfit;
            sc = fmax(sc, fmax(fabs(p[d]), fabs(qk[d])));
        }
    }
    *scale = sc;
    return misfit;
}

/* The pseudo-inverse of the symmetric 3x3 matrix m (row-major) into p, eigenvalues at or
 * below rel * the largest |eigenvalue| dropped, by cyclic Jacobi rotations. 0 when m is not
 * finite or is zero. */
static int sym3_pseudo_inverse(const double m[9], double rel, double p[9])
{
    double a[3][3], v[3][3] = {{1, 0, 0}, {0, 1, 0}, {0, 0, 1}};
    for (int i = 0; i < 9; i++) {
        if (!isfinite(m[i]))
            return 0;
        a[i / 3][i % 3] = m[i];
    }
    for (int sweep = 0; sweep < 50; sweep++) {
        const double off = a[0][1] * a[0][1] + a[0][2] * a[0][2] + a[1][2] * a[1][2];
        const double on = a[0][0] * a[0][0] + a[1][1] * a[1][1] + a[2][2] * a[2][2];
        if (off <= 1e-32 * on)
            break;
        for (int pi = 0; pi < 2; pi++)
            for (int qi = pi + 1; qi < 3; qi++) {
                if (a[pi][qi] == 0.0)
                    continue;
                /* the rotation that zeroes a[pi][qi] (Golub & Van Loan, Algorithm 8.4.1) */
                const double tau = (a[qi][qi] - a[pi][pi]) / (2.0 * a[pi][qi]);
                const double t = (tau >= 0.0 ? 1.0 : -1.0) / (fabs(tau) + sqrt(1.0 + tau * tau));
                const double c = 1.0 / sqrt(1.0 + t * t), sn = t * c;
                for (int k = 0; k < 3; k++) { /* a := a J */
                    const double x = a[k][pi], y = a[k][qi];
                    a[k][pi] = c * x - sn * y;
                    a[k][qi] = sn * x + c * y;
                }
                for (int k = 0; k < 3; k++) { /* a := J^T a */
                    const double x = a[pi][k], y = a[qi][k];
                    a[pi][k] = c * x - sn * y;
                    a[qi][k] = sn * x + c * y;
                }
                for (int k = 0; k < 3; k++) { /* v := v J */
                    const double x = v[k][pi], y = v[k][qi];
                    v[k][pi] = c * x - sn * y;
                    v[k][qi] = sn * x + c * y;
                }
            }
    }
    const double top = fmax(fabs(a[0][0]), fmax(fabs(a[1][1]), fabs(a[2][2])));
    if (!(top > 0.0))
        return 0;
    double inv[3];
    for (int k = 0; k < 3; k++)
        inv[k] = a[k][k] > rel * top ? 1.0 / a[k][k] : 0.0;
    for (int i = 0; i < 3; i++)
        for (int j = 0; j < 3; j++)
            p[3 * i + j] = v[i][0] * inv[0] * v[j][0] + v[i][1] * inv[1] * v[j][1] +
                           v[i][2] * inv[2] * v[j][2];
    return 1;
}

int dk_affine_fit(const double *rest, const dk_index *verts, dk_index count, const double *q,
                  double rel_tol, double T[16])
{
    double scale = 0.0;
    memset(T, 0, sizeof(double) * 16);
    T[15] = 1.0;
    if (count <= 0)
        return 1; /* nothing to reproduce: the zero map does */
    /* first the translation of the first point (the identity plus q_0 - p_0), which is
     * exact for a drag by translation, however few or flat the points */
    const double *p0 = rest + 3 * (size_t)verts[0];
    T[0] = T[5] = T[10] = 1.0;
    for (int d = 0; d < 3; d++)
        T[4 * d + 3] = q[d] - p0[d];
    double misfit = misfit_of(rest, verts, count, q, T, &scale);
    if (misfit <= rel_tol * scale)
        return 1;
    /* else the least-squares affine map: L M = B with M = sum (p - pm)(p - pm)^T,
     * B = sum (q - qm)(p - pm)^T, t = qm - L pm */
    double pm[3] = {0, 0, 0}, qm[3] = {0, 0, 0}, M[9] = {0}, B[9] = {0};
    for (dk_index k = 0; k < count; k++) {
        const double *p = rest + 3 * (size_t)verts[k];
        for (int d = 0; d < 3; d++) {
            pm[d] += p[d];
            qm[d] += q[3 * (size_t)k + d];
        }
    }
    for (int d = 0; d < 3; d++) {
        pm[d] /= (double)count;
        qm[d] /= (double)count;
    }
    for (dk_index k = 0; k < count; k++) {
        const double *p = rest + 3 * (size_t)verts[k];
        const double *qk = q + 3 * (size_t)k;
        for (int a = 0; a < 3; a++)
            for (int b = 0; b < 3; b++) {
                M[3 * a + b] += (p[a] - pm[a]) * (p[b] - pm[b]);
                B[3 * a + b] += (qk[a] - qm[a]) * (p[b] - pm[b]);
            }
    }
    /* L = B M^+, the pseudo-inverse over M's eigenvalues above 1e-12 of the largest: a
     * planar or collinear set (a flat cap, a row of vertices) keeps the map on its own span,
     * which is all that the images determine; the misfit test below decides */
    double Mp[9];
    if (!sym3_pseudo_inverse(M, 1e-12, Mp))
        return 0;
    for (int a = 0; a < 3; a++) {
        double tt = qm[a];
        for (int b = 0; b < 3; b++) {
            double v = 0.0;
            for (int e = 0; e < 3; e++)
                v += B[3 * a + e] * Mp[3 * e + b];
            T[4 * a + b] = v;
        }
        for (int b = 0; b < 3; b++)
            tt -= T[4 * a + b] * pm[b];
        T[4 * a + 3] = tt;
    }
    misfit = misfit_of(rest, verts, count, q, T, &scale);
    return misfit <= rel_tol * scale;
}
