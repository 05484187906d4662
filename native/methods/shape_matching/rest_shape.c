/* Shape matching's rest data for a goal shape (sm_internal.h): per cluster its mass centre,
 * the offsets q (or q~ for the quadratic mode) and the regularised inverse (A_qq + L)^-1.
 *
 * The regulariser L (dk_shape_matching.h): lambda = 1e-4 of the mean of the squared extents
 * per mode, isotropic in the linear block (sum m |q|^2 / 3) and in the quadratic block
 * measured in an orthonormal basis of the quadratic forms (sum m |q|^4 / 6): the goal is a
 * linear map L of q q^T, and |L|_F over the forms (E_ii, (E_ij + E_ji) / sqrt 2) weighs the
 * columns of x^2, y^2, z^2 by 1 and those of xy, yz, zx (L((E_ij + E_ji) / sqrt 2) = their
 * column / sqrt 2) by 1/2, so they take lambda_q and lambda_q / 2. Both are invariant under
 * rotations (S -> R S R^T keeps the Frobenius norm), so the goals
 * turn with the shape, and scale with it, so they do not depend on the units. The quadratic
 * terms are taken less their mass-weighted mean over the cluster (the paper's q~ plus a
 * constant, which the fit absorbs): sum m q~ = 0, so the goals keep the mass centre and the
 * clusters exert no net force, in the quadratic mode as in the others. */
#include "sm_internal.h"

#include <math.h>
#include <stdlib.h>
#include <string.h>

#include "dk_operators.h"

#define SM_REGULARISER 1e-4

dk_status sm_rest_alloc(const sm_clusters *c, int dim, sm_rest *r, dk_error *err)
{
    memset(r, 0, sizeof *r);
    r->dim = dim;
    const size_t nm = (size_t)c->start[c->n_clusters], nc = (size_t)c->n_clusters;
    r->q = malloc((nm * (size_t)dim + 1) * sizeof *r->q);
    r->inv = malloc((nc * (size_t)(dim * dim) + 1) * sizeof *r->inv);
    r->lambda = malloc((nc * (size_t)dim + 1) * sizeof *r->lambda);
    r->mass = malloc((nc + 1) * sizeof *r->mass);
    r->cm = malloc((3 * nc + 1) * sizeof *r->cm);
    r->plastic = malloc(nc + 1);
    if (dim == 3) {
        r->half = malloc((9 * nc + 1) * sizeof *r->half);
        r->ihalf = malloc((9 * nc + 1) * sizeof *r->ihalf);
        r->log_det = malloc((nc + 1) * sizeof *r->log_det);
    }
    if (!r->q || !r->inv || !r->lambda || !r->mass || !r->cm || !r->plastic ||
        (dim == 3 && (!r->half || !r->ihalf || !r->log_det))) {
        sm_rest_free(r);
        return dk_error_set(err, DK_ERR_OUT_OF_MEMORY,
                            "ShapeMatching: out of memory (rest offsets)");
    }
    return DK_OK;
}

void sm_rest_free(sm_rest *r)
{
    if (!r)
        return;
    free(r->q);
    free(r->inv);
    free(r->lambda);
    free(r->mass);
    free(r->cm);
    free(r->plastic);
    free(r->half);
    free(r->ihalf);
    free(r->log_det);
    memset(r, 0, sizeof *r);
}

/* The inverse of the symmetric positive definite n x n `a` (n <= 9) by Cholesky; 0 where
 * it is not positive definite (an empty cluster). */
static void spd_inverse(int n, const double *a, double *inv)
{
    double l[81], y[9];
    for (int i = 0; i < n; i++)
        for (int j = 0; j <= i; j++) {
            double s = a[i * n + j];
            for (int k = 0; k < j; k++)
                s -= l[i * 9 + k] * l[j * 9 + k];
            if (i == j) {
                if (!(s > 0.0)) {
                    memset(inv, 0, (size_t)(n * n) * sizeof *inv);
                    return;
                }
                l[i * 9 + i] = sqrt(s);
            } else {
                l[i * 9 + j] = s / l[j * 9 + j];
            }
        }
    for (int col = 0; col < n; col++) { /* solve L L^T x = e_col */
        for (int i = 0; i < n; i++) {
            double s = i == col ? 1.0 : 0.0;
            for (int k = 0; k < i; k++)
                s -= l[i * 9 + k] * y[k];
            y[i] = s / l[i * 9 + i];
        }
        for (int i = n - 1; i >= 0; i--) {
            double s = y[i];
            for (int k = i + 1; k < n; k++)
                s -= l[k * 9 + i] * inv[k * n + col];
            inv[i * n + col] = s / l[i * 9 + i];
        }
    }
}

/* q~ of offset q (9 values). */
static void quadratic_terms(const double q[3], double out[9])
{
    out[0] = q[0], out[1] = q[1], out[2] = q[2];
    out[3] = q[0] * q[0], out[4] = q[1] * q[1], out[5] = q[2] * q[2];
    out[6] = q[0] * q[1], out[7] = q[1] * q[2], out[8] = q[2] * q[0];
}

static int is_identity(const double *m)
{
    for (int i = 0; i < 9; i++)
        if (m[i] != (i % 4 == 0 ? 1.0 : 0.0))
            return 0;
    return 1;
}

void sm_rest_compute(const sm_clusters *c, const double *y, const double *rest,
                     const double *sp, sm_rest *r, dk_index begin, dk_index end)
{
    const int dim = r->dim;
    for (dk_index cl = begin; cl < end; cl++) {
        const dk_index k0 = c->start[cl], k1 = c->start[cl + 1];
        double M = 0.0, cm[3] = {0, 0, 0};
        for (dk_index k = k0; k < k1; k++) {
            const double m = c->member_mass[k];
            const double *p = y + 3 * (size_t)c->member_vertex[k];
            M += m;
            for (int d = 0; d < 3; d++)
                cm[d] += m * p[d];
        }
        for (int d = 0; d < 3; d++)
            cm[d] /= M;
        r->mass[cl] = M;
        memcpy(r->cm + 3 * (size_t)cl, cm, sizeof cm);
        /* the plastic state in the goal shape's frame: S = Q S_p Q^T, Q the rotation from
         * the cluster at the bind rest to the goal shape */
        double S[9] = {1, 0, 0, 0, 1, 0, 0, 0, 1};
        int plastic = sp && !is_identity(sp + 9 * (size_t)cl);
        r->plastic[cl] = (unsigned char)plastic;
        if (plastic) {
            const double *P = sp + 9 * (size_t)cl;
            memcpy(S, P, sizeof S);
            if (rest != y) {
                double Q[9], T[9];
                sm_rest_to_goal(c, r, y, rest, cl, Q);
                for (int i = 0; i < 3; i++) /* T = Q P */
                    for (int j = 0; j < 3; j++)
                        T[3 * i + j] = Q[3 * i] * P[j] + Q[3 * i + 1] * P[3 + j] +
                                       Q[3 * i + 2] * P[6 + j];
                for (int i = 0; i < 3; i++) /* S = T Q^T */
                    for (int j = 0; j < 3; j++)
                        S[3 * i + j] = T[3 * i] * Q[3 * j] + T[3 * i + 1] * Q[3 * j + 1] +
                                       T[3 * i + 2] * Q[3 * j + 2];
            }
        }
        double aqq[81] = {0}, s2 = 0.0, s4 = 0.0, mean[9] = {0};
        for (dk_index k = k0; k < k1; k++) {
            const double m = c->member_mass[k];
            const double *p = y + 3 * (size_t)c->member_vertex[k];
            double q0[3] = {p[0] - cm[0], p[1] - cm[1], p[2] - cm[2]}, q[3], qt[9];
            if (plastic)
                for (int i = 0; i < 3; i++)
                    q[i] = S[3 * i] * q0[0] + S[3 * i + 1] * q0[1] + S[3 * i + 2] * q0[2];
            else
                memcpy(q, q0, sizeof q);
            const double qq = q[0] * q[0] + q[1] * q[1] + q[2] * q[2];
            s2 += m * qq;
            s4 += m * qq * qq;
            double *dst = r->q + (size_t)dim * (size_t)k;
            if (dim == 9) {
                quadratic_terms(q, qt);
                memcpy(dst, qt, sizeof qt);
            } else {
                memcpy(dst, q, sizeof q);
            }
            for (int i = 3; i < dim; i++)
                mean[i] += m * dst[i];
        }
        /* the quadratic terms less their mean: sum m q~ = 0, so that the goals keep the
         * cluster's mass centre (no net force, as in the linear modes) */
        for (int i = 3; i < dim; i++)
            mean[i] /= M;
        for (dk_index k = k0; k < k1; k++) {
            const double m = c->member_mass[k];
            double *dst = r->q + (size_t)dim * (size_t)k;
            for (int i = 3; i < dim; i++)
                dst[i] -= mean[i];
            for (int i = 0; i < dim; i++)
                for (int j = 0; j <= i; j++)
                    aqq[i * dim + j] += m * dst[i] * dst[j];
        }
        for (int i = 0; i < dim; i++)
            for (int j = 0; j < i; j++)
                aqq[j * dim + i] = aqq[i * dim + j];
        double *lam = r->lambda + (size_t)dim * (size_t)cl;
        const double ll = SM_REGULARISER * s2 / 3.0, lq = SM_REGULARISER * s4 / 6.0;
        for (int i = 0; i < dim; i++) {
            lam[i] = i < 3 ? ll : i < 6 ? lq : 0.5 * lq;
            aqq[i * dim + i] += lam[i];
        }
        spd_inverse(dim, aqq, r->inv + (size_t)(dim * dim) * (size_t)cl);
        if (dim == 3)
            sm_volume_metric(aqq, r->half + 9 * (size_t)cl, r->ihalf + 9 * (size_t)cl,
                             r->log_det + cl);
    }
}
