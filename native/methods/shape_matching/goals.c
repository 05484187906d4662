/* Shape matching's goals (sm_internal.h): per cluster the rotation and the fit of the rest
 * offsets onto the current ones, each member's goal, and each vertex's blended goal; and the
 * clusters' plasticity. The formulas are the header's (dk_shape_matching.h). */
#include "sm_internal.h"

#include <math.h>
#include <string.h>

#include "dk_operators.h"

/* The rest offset y_v - cm of vertex v (into `out`), as rest_shape.c computed it: the linear
 * modes read it from the goal shape (cached with the positions) instead of streaming q. */
static inline const double *offset(const double *y, const double *cm, dk_index v, double out[3])
{
    const double *p = y + 3 * (size_t)v;
    out[0] = p[0] - cm[0], out[1] = p[1] - cm[1], out[2] = p[2] - cm[2];
    return out;
}

/* One cluster's sums in one pass over its members, relative to its first member's position
 * x0 (so that a model far from the origin loses no precision): cm = x0 + sum m (x - x0) / M
 * and A_pq = sum m (x - x0) q^T - (sum m (x - x0) / M) (sum m q)^T, the second term the
 * rounding of sum m q = 0. DIM is 3 or 9: a constant, so that the loops unroll. */
#define SM_CLUSTER_SUMS(DIM)                                                                  \
    static void sums##DIM(const sm_clusters *c, const sm_rest *r, const double *x,            \
                          dk_index cl, double cm[3], double apq[3 * DIM])                     \
    {                                                                                         \
        const dk_index k0 = c->start[cl], k1 = c->start[cl + 1];                              \
        const double *x0 = x + 3 * (size_t)c->member_vertex[k0];                              \
        double sx[3] = {0, 0, 0}, sq[DIM];                                                    \
        for (int j = 0; j < 3 * DIM; j++)                                                     \
            apq[j] = 0.0;                                                                     \
        for (int j = 0; j < DIM; j++)                                                         \
            sq[j] = 0.0;                                                                      \
        const int from_shape = DIM == 3 && !r->plastic[cl];                                   \
        const double *cy = r->cm + 3 * (size_t)cl;                                            \
        for (dk_index k = k0; k < k1; k++) {                                                  \
            const double m = c->member_mass[k];                                               \
            const dk_index v = c->member_vertex[k];                                           \
            const double *p = x + 3 * (size_t)v;                                              \
            double qy[3];                                                                     \
            const double *q = from_shape ? offset(r->shape, cy, v, qy)                        \
                                         : r->q + (size_t)DIM * (size_t)k;                    \
            const double d[3] = {m * (p[0] - x0[0]), m * (p[1] - x0[1]), m * (p[2] - x0[2])}; \
            for (int i = 0; i < 3; i++) {                                                     \
                sx[i] += d[i];                                                                \
                for (int j = 0; j < DIM; j++)                                                 \
                    apq[i * DIM + j] += d[i] * q[j];                                          \
            }                                                                                 \
            for (int j = 0; j < DIM; j++)                                                     \
                sq[j] += m * q[j];                                                            \
        }                                                                                     \
        const double M = r->mass[cl];                                                         \
        for (int i = 0; i < 3; i++) {                                                         \
            const double off = sx[i] / M;                                                     \
            cm[i] = x0[i] + off;                                                              \
            for (int j = 0; j < DIM; j++)                                                     \
                apq[i * DIM + j] -= off * sq[j];                                              \
        }                                                                                     \
    }
SM_CLUSTER_SUMS(3)
SM_CLUSTER_SUMS(9)
#undef SM_CLUSTER_SUMS

/* The fit A = (A_pq + R~ L) (A_qq + L)^-1 (3 x dim). */
static void fit(int dim, const double *apq, const double R[9], const double *lam,
                const double *inv, double *A)
{
    double rhs[27];
    memcpy(rhs, apq, sizeof(double) * 3 * (size_t)dim);
    for (int i = 0; i < 3; i++)
        for (int j = 0; j < 3; j++)
            rhs[i * dim + j] += R[3 * i + j] * lam[j];
    for (int i = 0; i < 3; i++)
        for (int j = 0; j < dim; j++) {
            double t = 0.0;
            for (int k = 0; k < dim; k++)
                t += rhs[i * dim + k] * inv[k * dim + j];
            A[i * dim + j] = t;
        }
}

/* Where a member's goal goes: its own row of member_goal, or added, times the member's
 * share, to its vertex's row of acc (the blend over the vertex's clusters). */
static inline double *goal_row(const sm_clusters *c, double *member_goal, double *acc,
                               dk_index k, double g[3])
{
    double *row = acc ? acc + 3 * (size_t)c->member_vertex[k] : member_goal + 3 * (size_t)k;
    if (acc) {
        const double phi = c->member_share[k];
        row[0] += phi * g[0], row[1] += phi * g[1], row[2] += phi * g[2];
    } else {
        row[0] = g[0], row[1] = g[1], row[2] = g[2];
    }
    return row;
}

void sm_goals_clusters(const sm_clusters *c, const sm_rest *r, dk_shape_matching_mode mode,
                       const double *beta, const double *x, double *member_goal, double *acc,
                       sm_fit *fits, dk_index begin, dk_index end)
{
    const int dim = r->dim;
    for (dk_index cl = begin; cl < end; cl++) {
        const dk_index k0 = c->start[cl], k1 = c->start[cl + 1];
        double cm[3], apq[27], lin[9], R[9], A[27];
        if (dim == 9)
            sums9(c, r, x, cl, cm, apq);
        else
            sums3(c, r, x, cl, cm, apq);
        for (int i = 0; i < 3; i++)
            for (int j = 0; j < 3; j++)
                lin[3 * i + j] = apq[i * dim + j];
        dk_closest_rotation(lin, R);
        int use_fit = mode != DK_SHAPE_MATCHING_RIGID;
        if (use_fit)
            fit(dim, apq, R, r->lambda + (size_t)dim * (size_t)cl,
                r->inv + (size_t)(dim * dim) * (size_t)cl, A);
        if (fits) {
            memcpy(fits[cl].R, R, sizeof R);
            if (use_fit)
                for (int i = 0; i < 3; i++)
                    for (int j = 0; j < 3; j++)
                        fits[cl].A[3 * i + j] = A[i * dim + j];
            else
                memcpy(fits[cl].A, R, sizeof R);
        }
        if (mode == DK_SHAPE_MATCHING_LINEAR) { /* the best fit with det 1 (volume_fit.c) */
            const double det = A[0] * (A[4] * A[8] - A[5] * A[7]) -
                               A[1] * (A[3] * A[8] - A[5] * A[6]) +
                               A[2] * (A[3] * A[7] - A[4] * A[6]);
            if (det > 0.0 && isfinite(det)) {
                if (!sm_volume_fit(A, r->half + 9 * (size_t)cl, r->ihalf + 9 * (size_t)cl,
                                   r->log_det[cl])) {
                    const double s = 1.0 / cbrt(det);
                    for (int i = 0; i < 9; i++)
                        A[i] *= s;
                }
            } else {
                use_fit = 0; /* inverted: the rotation */
            }
        }
        const int from_shape = dim == 3 && !r->plastic[cl];
        const double *cy = r->cm + 3 * (size_t)cl;
        if (!use_fit) { /* g = R q + cm */
            for (dk_index k = k0; k < k1; k++) {
                double qy[3];
                const double *q = from_shape ? offset(r->shape, cy, c->member_vertex[k], qy)
                                             : r->q + (size_t)dim * (size_t)k;
                double g[3];
                for (int i = 0; i < 3; i++)
                    g[i] = R[3 * i] * q[0] + R[3 * i + 1] * q[1] + R[3 * i + 2] * q[2] + cm[i];
                goal_row(c, member_goal, acc, k, g);
            }
            continue;
        }
        /* g = R q + beta (A q~ - R q) + cm, with D = A - R~ */
        for (int i = 0; i < 3; i++)
            for (int j = 0; j < 3; j++)
                A[i * dim + j] -= R[3 * i + j];
        for (dk_index k = k0; k < k1; k++) {
            double qy[3];
            const double *q = from_shape ? offset(r->shape, cy, c->member_vertex[k], qy)
                                         : r->q + (size_t)dim * (size_t)k;
            const double b = beta[c->member_vertex[k]];
            double g[3];
            for (int i = 0; i < 3; i++) {
                double dq = 0.0;
                for (int j = 0; j < dim; j++)
                    dq += A[i * dim + j] * q[j];
                g[i] = R[3 * i] * q[0] + R[3 * i + 1] * q[1] + R[3 * i + 2] * q[2] + b * dq +
                       cm[i];
            }
            goal_row(c, member_goal, acc, k, g);
        }
    }
}

void sm_goals_vertices(const sm_clusters *c, const double *member_goal, const double *x,
                       double *goals, dk_index begin, dk_index end)
{
    for (dk_index v = begin; v < end; v++) {
        const dk_index a = c->vm_start[v], b = c->vm_start[v + 1];
        double *g = goals + 3 * (size_t)v;
        if (a == b) {
            memcpy(g, x + 3 * (size_t)v, 3 * sizeof(double));
            continue;
        }
        double s[3] = {0, 0, 0};
        for (dk_index t = a; t < b; t++) {
            const dk_index k = c->vm_index[t];
            const double *mg = member_goal + 3 * (size_t)k, phi = c->member_share[k];
            s[0] += phi * mg[0], s[1] += phi * mg[1], s[2] += phi * mg[2];
        }
        g[0] = s[0], g[1] = s[1], g[2] = s[2];
    }
}

void sm_goals_from_sums(const sm_clusters *c, const double *acc0, const double *acc1,
                        const double *x, double *goals, dk_index begin, dk_index end)
{
    for (dk_index v = begin; v < end; v++) {
        const dk_index n = c->vm_start[v + 1] - c->vm_start[v];
        const size_t j = 3 * (size_t)v;
        if (n == 0) {
            memcpy(goals + j, x + j, 3 * sizeof(double));
            continue;
        }
        for (int d = 0; d < 3; d++)
            goals[j + (size_t)d] = acc0[j + (size_t)d] + acc1[j + (size_t)d];
    }
}

static double frobenius_from_identity(const double *m)
{
    double s = 0.0;
    for (int i = 0; i < 9; i++) {
        const double d = m[i] - (i % 4 == 0 ? 1.0 : 0.0);
        s += d * d;
    }
    return sqrt(s);
}

void sm_rest_to_goal(const sm_clusters *c, const sm_rest *r, const double *y,
                     const double *rest, dk_index cl, double Q[9])
{
    const dk_index k0 = c->start[cl], k1 = c->start[cl + 1];
    const double *cy = r->cm + 3 * (size_t)cl;
    double cr[3] = {0, 0, 0}, cov[9] = {0};
    for (dk_index k = k0; k < k1; k++) {
        const double *p = rest + 3 * (size_t)c->member_vertex[k];
        for (int d = 0; d < 3; d++)
            cr[d] += c->member_mass[k] * p[d];
    }
    for (int d = 0; d < 3; d++)
        cr[d] /= r->mass[cl];
    for (dk_index k = k0; k < k1; k++) {
        const double m = c->member_mass[k];
        const double *a = y + 3 * (size_t)c->member_vertex[k];
        const double *b = rest + 3 * (size_t)c->member_vertex[k];
        for (int i = 0; i < 3; i++)
            for (int j = 0; j < 3; j++)
                cov[3 * i + j] += m * (a[i] - cy[i]) * (b[j] - cr[j]);
    }
    dk_closest_rotation(cov, Q);
}

dk_index sm_plastic_update(const sm_clusters *c, const sm_rest *r, const sm_fit *fits, double h,
                           const dk_shape_matching_dynamics *dyn, const double *y,
                           const double *rest, double *sp, unsigned char *changed)
{
    dk_index n_changed = 0;
    for (dk_index cl = 0; cl < c->n_clusters; cl++) {
        changed[cl] = 0;
        const double *R = fits[cl].R, *A = fits[cl].A;
        double S[9];
        for (int i = 0; i < 3; i++) /* S = R^T A, symmetrised */
            for (int j = 0; j < 3; j++)
                S[3 * i + j] = R[i] * A[j] + R[3 + i] * A[3 + j] + R[6 + i] * A[6 + j];
        for (int i = 0; i < 3; i++)
            for (int j = 0; j < i; j++)
                S[3 * i + j] = S[3 * j + i] = 0.5 * (S[3 * i + j] + S[3 * j + i]);
        if (!(frobenius_from_identity(S) > dyn->plastic_yield))
            continue;
        double *P = sp + 9 * (size_t)cl, G[9], F[9], N[9], Q[9], T[9];
        for (int i = 0; i < 9; i++)
            G[i] = (i % 4 == 0 ? 1.0 : 0.0) + h * dyn->plastic_creep * (S[i] - (i % 4 == 0));
        sm_rest_to_goal(c, r, y, rest, cl, Q); /* F = Q^T G Q: the step in the rest's frame */
        for (int i = 0; i < 3; i++)
            for (int j = 0; j < 3; j++)
                T[3 * i + j] = G[3 * i] * Q[j] + G[3 * i + 1] * Q[3 + j] + G[3 * i + 2] * Q[6 + j];
        for (int i = 0; i < 3; i++)
            for (int j = 0; j < 3; j++)
                F[3 * i + j] = Q[i] * T[j] + Q[3 + i] * T[3 + j] + Q[6 + i] * T[6 + j];
        for (int i = 0; i < 3; i++)
            for (int j = 0; j < 3; j++)
                N[3 * i + j] = F[3 * i] * P[j] + F[3 * i + 1] * P[3 + j] + F[3 * i + 2] * P[6 + j];
        const double dev = frobenius_from_identity(N);
        if (dev > dyn->plastic_max) {
            const double s = dyn->plastic_max / dev;
            for (int i = 0; i < 9; i++)
                N[i] = (i % 4 == 0 ? 1.0 : 0.0) + s * (N[i] - (i % 4 == 0));
        }
        const double det = N[0] * (N[4] * N[8] - N[5] * N[7]) - N[1] * (N[3] * N[8] - N[5] * N[6]) +
                           N[2] * (N[3] * N[7] - N[4] * N[6]);
        if (!(det > 0.0) || !isfinite(det))
            continue; /* no volume-keeping state from it: keep the last */
        const double s = 1.0 / cbrt(det);
        for (int i = 0; i < 9; i++)
            P[i] = N[i] * s;
        changed[cl] = 1;
        n_changed++;
    }
    return n_changed;
}
