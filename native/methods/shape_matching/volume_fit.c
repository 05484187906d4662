/* Shape matching's volume-preserving fit (sm_internal.h): the linear mode's goal map.
 *
 * The paper (4.2) takes the best linear fit A* and divides it by det(A*)^(1/3). That map is
 * not the minimiser of anything the points move down, so its goals are not the gradient of
 * an energy: undamped at alpha = 1 the simulation gained energy, and with the cubes' hat
 * shares (clusters.c) a tube blew up at beta = 1 even with the default damping. Here the
 * goal map is the best fit among the maps that keep the volume,
 *     A = argmin_{det A = 1} sum m |A q - p|^2 + lambda |A - R|^2
 *       = argmin_{det A = 1} |(A - A*) M^(1/2)|_F^2,   M = A_qq + L,
 * so that, as in the rigid mode (the best fit among rotations), each cluster's pull is the
 * gradient of its own least-squares energy. With B = A M^(1/2) this is the matrix nearest
 * to B* = A* M^(1/2) in the Frobenius norm with det B = det M^(1/2): B shares B*'s polar
 * rotation and the eigenvectors of its stretch S*, and each eigenvalue sigma_i becomes
 * s_i = (sigma_i + sqrt(sigma_i^2 + 4 mu)) / 2 (from s_i (s_i - sigma_i) = mu, the Lagrange
 * condition), mu the root of sum log s_i = log det M^(1/2), found by safeguarded Newton.
 * That root need not exist, nor be the cheapest, where the fit's volume is much too large
 * (s_i >= sigma_i / 2 on it: a thin cluster, whose smallest sigma is small, can lose little
 * volume so; or a nearly isotropic one shrunk to about 1/8): there the smallest stretch may
 * take the other root, s_0 = (sigma_0 - sqrt(sigma_0^2 + 4 mu)) / 2 for mu in
 * (-sigma_0^2 / 4, 0), and the fit gives up volume across the cluster, where its points say
 * least. Every stationary point found on both branches is compared by its cost, the
 * cheapest kept. (Nearest matrices of a given determinant take at most the smallest stretch
 * on its other root.)
 *
 * Thin clusters: the metric M weighs the directions by the cluster's extent, so a flat
 * cluster of a surface keeps its volume mostly by its normal, where it has no points: it
 * then resists a stretch in its own plane little beyond its rigid part (1 - beta), where the
 * paper's division shrinks the plane back (measured by a review: a flat patch stretched by
 * 1.05-1.5 at beta = 1 pulls back 1e-4 of the stretch here, 0.7 there; closed models still
 * come back to their volume). A careful reading of "keep the volume": a flat cluster has
 * none to keep.
 *
 * Where sm_volume_fit returns 0 (a singular metric, no stretch with det > 0) the caller
 * divides by det^(1/3), the paper's map. */
#include "sm_internal.h"

#include <math.h>
#include <string.h>

#include "dk_operators.h"

/* The eigenvalues w (ascending) and eigenvectors (columns of v, row-major) of the symmetric
 * 3 x 3 a, by cyclic Jacobi rotations. */
static void sym3_eigen(const double a[9], double w[3], double v[9])
{
    double m[3][3];
    for (int i = 0; i < 3; i++)
        for (int j = 0; j < 3; j++) {
            m[i][j] = 0.5 * (a[3 * i + j] + a[3 * j + i]);
            v[3 * i + j] = i == j ? 1.0 : 0.0;
        }
    for (int sweep = 0; sweep < 50; sweep++) {
        const double off = m[0][1] * m[0][1] + m[0][2] * m[0][2] + m[1][2] * m[1][2];
        const double diag = m[0][0] * m[0][0] + m[1][1] * m[1][1] + m[2][2] * m[2][2];
        if (!(off > 1e-30 * diag))
            break;
        for (int p = 0; p < 2; p++)
            for (int q = p + 1; q < 3; q++) {
                if (m[p][q] == 0.0)
                    continue;
                const double theta = (m[q][q] - m[p][p]) / (2.0 * m[p][q]);
                const double t = (theta >= 0.0 ? 1.0 : -1.0) /
                                 (fabs(theta) + sqrt(theta * theta + 1.0));
                const double c = 1.0 / sqrt(t * t + 1.0), s = t * c;
                for (int k = 0; k < 3; k++) { /* m <- J^T m J */
                    const double mkp = m[k][p], mkq = m[k][q];
                    m[k][p] = c * mkp - s * mkq;
                    m[k][q] = s * mkp + c * mkq;
                }
                for (int k = 0; k < 3; k++) {
                    const double mpk = m[p][k], mqk = m[q][k];
                    m[p][k] = c * mpk - s * mqk;
                    m[q][k] = s * mpk + c * mqk;
                }
                for (int k = 0; k < 3; k++) {
                    const double vkp = v[3 * k + p], vkq = v[3 * k + q];
                    v[3 * k + p] = c * vkp - s * vkq;
                    v[3 * k + q] = s * vkp + c * vkq;
                }
            }
    }
    int order[3] = {0, 1, 2};
    for (int i = 0; i < 3; i++)
        for (int j = i + 1; j < 3; j++)
            if (m[order[j]][order[j]] < m[order[i]][order[i]]) {
                const int t = order[i];
                order[i] = order[j];
                order[j] = t;
            }
    double vs[9];
    for (int j = 0; j < 3; j++) {
        w[j] = m[order[j]][order[j]];
        for (int i = 0; i < 3; i++)
            vs[3 * i + j] = v[3 * i + order[j]];
    }
    memcpy(v, vs, sizeof vs);
}

/* out = V diag(d) V^T. */
static void from_eigen(const double v[9], const double d[3], double out[9])
{
    for (int i = 0; i < 3; i++)
        for (int j = 0; j < 3; j++)
            out[3 * i + j] = v[3 * i] * d[0] * v[3 * j] + v[3 * i + 1] * d[1] * v[3 * j + 1] +
                             v[3 * i + 2] * d[2] * v[3 * j + 2];
}

static void mul3(const double a[9], const double b[9], double o[9])
{
    double t[9];
    for (int i = 0; i < 3; i++)
        for (int j = 0; j < 3; j++)
            t[3 * i + j] = a[3 * i] * b[j] + a[3 * i + 1] * b[3 + j] + a[3 * i + 2] * b[6 + j];
    memcpy(o, t, sizeof t);
}

void sm_volume_metric(const double m[9], double half[9], double ihalf[9], double *log_det)
{
    double w[3], v[9], d[3], id[3];
    sym3_eigen(m, w, v);
    *log_det = 0.0;
    for (int i = 0; i < 3; i++) {
        d[i] = w[i] > 0.0 ? sqrt(w[i]) : 0.0;
        id[i] = d[i] > 0.0 ? 1.0 / d[i] : 0.0;
        *log_det += d[i] > 0.0 ? log(d[i]) : -INFINITY;
    }
    from_eigen(v, d, half);
    from_eigen(v, id, ihalf);
}

/* s_i(mu): the larger root of s (s - sigma) = mu, or for i = 0 with `minus` the smaller
 * (written -2 mu / (sigma + r), which keeps its digits where |mu| << sigma^2). */
static double root_of(double sigma, double mu, int minus)
{
    const double r = sqrt(fmax(sigma * sigma + 4.0 * mu, 0.0));
    return minus ? -2.0 * mu / (sigma + r) : 0.5 * (sigma + r);
}

/* sum log s_i(mu) - target and, on the larger roots, its derivative. */
static double volume_gap(const double sigma[3], double mu, double target, int minus,
                         double *slope)
{
    double f = -target, g = 0.0;
    for (int i = 0; i < 3; i++) {
        const double r = sqrt(fmax(sigma[i] * sigma[i] + 4.0 * mu, 0.0));
        const double s = root_of(sigma[i], mu, minus && i == 0);
        f += log(s);
        g += r > 0.0 ? 1.0 / (s * r) : INFINITY;
    }
    *slope = g;
    return f;
}

/* The cost sum (s_i - sigma_i)^2 of the stretches at mu. */
static double cost_at(const double sigma[3], double mu, int minus, double s[3])
{
    double c = 0.0;
    for (int i = 0; i < 3; i++) {
        s[i] = root_of(sigma[i], mu, minus && i == 0);
        c += (s[i] - sigma[i]) * (s[i] - sigma[i]);
    }
    return c;
}

/* Bisection of the gap on (lo, hi), its sign at lo `at_lo`, until the interval stops
 * shrinking in doubles. */
static double bisect(const double sigma[3], double lo, double hi, double target, int minus,
                     int at_lo)
{
    double slope;
    for (int it = 0; it < 200; it++) {
        const double mid = 0.5 * (lo + hi);
        if (mid <= lo || mid >= hi)
            break;
        if ((volume_gap(sigma, mid, target, minus, &slope) > 0.0) == (at_lo > 0))
            lo = mid;
        else
            hi = mid;
    }
    return 0.5 * (lo + hi);
}

/* samples of the smaller root's branch, where its gap may turn more than once */
#define MINUS_SAMPLES 48

int sm_volume_fit(double A[9], const double half[9], const double ihalf[9], double log_det)
{
    if (!isfinite(log_det))
        return 0;
    double B[9], Rb[9], S[9], Rt[9];
    mul3(A, half, B);
    dk_closest_rotation(B, Rb);
    for (int i = 0; i < 3; i++)
        for (int j = 0; j < 3; j++)
            Rt[3 * i + j] = Rb[3 * j + i];
    mul3(Rt, B, S); /* the stretch S* = Rb^T B* (symmetric where det B* > 0) */
    double sigma[3], v[9];
    sym3_eigen(S, sigma, v);
    if (!(sigma[0] > 0.0))
        return 0;
    /* The stationary points: s_i (s_i - sigma_i) = mu for one mu. On the larger roots,
     * mu in [lo, inf) with lo = -sigma_min^2 / 4, sum log s_i rises: one root when the gap
     * at lo is <= 0. On the smallest's smaller root, mu in (lo, 0), the gap falls to -inf
     * at 0 but near isotropy may turn (up to three roots): sampled, each sign change
     * bisected. The cheapest stationary point is the fit; the smaller root is only tried
     * where the larger's cost passes sigma_min^2 / 4, which any smaller root costs. */
    const double lo = -0.25 * sigma[0] * sigma[0];
    double slope, best = INFINITY, s[3], t[3];
    if (volume_gap(sigma, lo, log_det, 0, &slope) <= 0.0) {
        double a = lo, b = fmax(1.0, sigma[2] * sigma[2]);
        for (int k = 0; k < 200 && volume_gap(sigma, b, log_det, 0, &slope) < 0.0; k++)
            b *= 2.0;
        double mu = 0.0;
        if (!(mu > a && mu < b))
            mu = 0.5 * (a + b);
        for (int it = 0; it < 100; it++) { /* safeguarded Newton */
            const double f = volume_gap(sigma, mu, log_det, 0, &slope);
            if (f > 0.0)
                b = mu;
            else
                a = mu;
            if (fabs(f) < 1e-14)
                break;
            double next = mu - f / slope;
            if (!(next > a && next < b))
                next = 0.5 * (a + b);
            if (next == mu)
                break;
            mu = next;
        }
        best = cost_at(sigma, mu, 0, s);
    }
    if (best > 0.25 * sigma[0] * sigma[0]) {
        double prev_mu = lo, prev = volume_gap(sigma, lo, log_det, 1, &slope);
        for (int k = 1; k <= MINUS_SAMPLES; k++) {
            const double mu = k < MINUS_SAMPLES ? lo * (1.0 - (double)k / MINUS_SAMPLES)
                                                : -1e-300;
            const double g = volume_gap(sigma, mu, log_det, 1, &slope);
            if ((prev > 0.0) != (g > 0.0)) {
                const double root = bisect(sigma, prev_mu, mu, log_det, 1, prev > 0.0 ? 1 : -1);
                const double c = cost_at(sigma, root, 1, t);
                if (c < best) {
                    best = c;
                    memcpy(s, t, sizeof t);
                }
            }
            prev_mu = mu;
            prev = g;
        }
    }
    if (!isfinite(best))
        return 0;
    from_eigen(v, s, S);
    mul3(Rb, S, B);
    mul3(B, ihalf, A);
    return 1;
}
