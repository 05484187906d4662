/* DeformKit cage FFD: 3D Green coordinates of one point (dk_cage.h; Lipman, Levin and
 * Cohen-Or 2008), from Green's third identity written for the cage, each face's integrals in
 * closed form.
 *
 * For a point x and a harmonic u, u(x) = sum_t int_t (u dG/dn - G du/dn), G = -1/(4 pi r),
 * r = |xi - x|, n the face's outward normal. With u the coordinates themselves (linear on
 * each face, du/dn = n):
 *     x = sum_i phi_i v_i + sum_t psi_t n_t,
 *     phi_i = sum_{t at i} 1/(4 pi) int_t Gamma_i h / r^3,   psi_t = 1/(4 pi) int_t 1 / r,
 * h = n . (v - x) the face's height above x (positive inside), Gamma_i the face's barycentric
 * function of corner i. Per face, with the projection p of x on its plane, each edge k's
 * outward in-plane normal m_k, length L_k and signed distance d_k = m_k . (edge - p), and
 * per edge the line integral J = int_edge 1/r = log((r_a + r_b + L) / (r_a + r_b - L)) (once
 * for the two faces sharing it):
 *     int_t 1/r          = sum_k d_k J_k - |h| |Omega|,
 *     int_t Gamma_l h/r^3 = a_l Omega + h L_l / (2 A) sum_k (m_l . m_k) J_k,
 * Omega the face's signed solid angle at x (positive seen from inside; Van Oosterom and
 * Strackee's atan2), A its area, a_l = d_l L_l / (2 A) the barycentric coordinate of p (the
 * first from the divergence theorem on the plane with the field (xi - p)(r - |h|)/|xi - p|^2,
 * the second from Gamma_l = a_l + g_l . (xi - x), g_l = -m_l L_l / (2 A), and the tangential
 * part of int_t (xi - x)/r^3 = -sum_k m_k J_k). This is the paper's GCTriInt in another
 * arrangement (one log per edge and one atan2 per face); its values are checked against a
 * numerical integration of the definition (tests/native/test_cage.c).
 *
 * Outside the cage (the faces' solid angles sum to 0, not 4 pi) the identity gives 0; the
 * paper continues the coordinates analytically through the face x lies beyond: phi of that
 * face's corners += a_l, its psi += -h. The face chosen here, where the paper leaves it to
 * the region: among the faces x lies beyond (h < 0) whose triangle holds x's projection, the
 * nearest; if none holds it (x beyond an edge or a corner), the nearest of those faces. */
#include "dk_cage.h"

#include <math.h>
#include <string.h>

#define GC_PI 3.14159265358979323846

static double dot3(const double *a, const double *b)
{
    return a[0] * b[0] + a[1] * b[1] + a[2] * b[2];
}

static void cross3(const double *a, const double *b, double *c)
{
    c[0] = a[1] * b[2] - a[2] * b[1];
    c[1] = a[2] * b[0] - a[0] * b[2];
    c[2] = a[0] * b[1] - a[1] * b[0];
}

int dk_cage_green(const double *x, const double *cage, dk_index nc, const dk_index *tris,
                  dk_index nt, const double *normals, const dk_index *edges, dk_index ne,
                  const dk_index *opposite, double *phi, double *psi, double *scratch)
{
    double *r = scratch, *a = scratch + nc, *J = scratch + 4 * (size_t)nc;
    double size = 0.0;
    for (dk_index j = 0; j < nc; j++) {
        const double *p = cage + 3 * (size_t)j;
        double *aj = a + 3 * (size_t)j;
        for (int k = 0; k < 3; k++)
            aj[k] = p[k] - x[k];
        r[j] = sqrt(dot3(aj, aj));
        size = r[j] > size ? r[j] : size;
    }
    if (!(size > 0.0) || !isfinite(size))
        return -1;
    /* per edge, int_edge 1/r; on the edge's line the log is infinite, and it is multiplied
     * by a distance that vanishes there: kept finite */
    for (dk_index e = 0; e < ne; e++) {
        const dk_index i = edges[2 * e], j = edges[2 * e + 1];
        double d[3];
        for (int k = 0; k < 3; k++)
            d[k] = cage[3 * (size_t)j + k] - cage[3 * (size_t)i + k];
        const double L = sqrt(dot3(d, d)), s = r[i] + r[j];
        const double den = s - L > 1e-300 ? s - L : 1e-300;
        J[e] = log((s + L) / den);
    }
    memset(phi, 0, (size_t)nc * sizeof *phi);
    double winding = 0.0;
    int beyond = -1, beyond_inside = 0;
    double beyond_dist = 0.0;
    for (dk_index t = 0; t < nt; t++) {
        const dk_index *f = tris + 3 * (size_t)t;
        const double *n = normals + 3 * (size_t)t;
        const double *ac[3] = {a + 3 * (size_t)f[0], a + 3 * (size_t)f[1], a + 3 * (size_t)f[2]};
        const double h = dot3(n, ac[0]);
        double bc[3];
        cross3(ac[1], ac[2], bc);
        const double num = dot3(ac[0], bc);
        const double den = r[f[0]] * r[f[1]] * r[f[2]] + dot3(ac[0], ac[1]) * r[f[2]] +
                           dot3(ac[1], ac[2]) * r[f[0]] + dot3(ac[2], ac[0]) * r[f[1]];
        const double omega = 2.0 * atan2(num, den);
        winding += omega;
        /* the edges opposite each corner: outward in-plane normals, lengths, distances */
        double m[3][3], L[3], d[3], Jk[3];
        for (int k = 0; k < 3; k++) {
            const double *p1 = cage + 3 * (size_t)f[(k + 1) % 3];
            const double *p2 = cage + 3 * (size_t)f[(k + 2) % 3];
            double ed[3] = {p2[0] - p1[0], p2[1] - p1[1], p2[2] - p1[2]};
            L[k] = sqrt(dot3(ed, ed));
            cross3(ed, n, m[k]);
            for (int c = 0; c < 3; c++)
                m[k][c] /= L[k] > 0.0 ? L[k] : 1.0;
            d[k] = dot3(m[k], ac[(k + 1) % 3]);
            Jk[k] = J[opposite[3 * (size_t)t + k]];
        }
        double nn[3];
        {
            double e1[3], e2[3];
            for (int c = 0; c < 3; c++) {
                e1[c] = ac[1][c] - ac[0][c];
                e2[c] = ac[2][c] - ac[0][c];
            }
            cross3(e1, e2, nn);
        }
        const double A2 = sqrt(dot3(nn, nn)); /* twice the area */
        if (!(A2 > 0.0))
            return -1;
        psi[t] = (d[0] * Jk[0] + d[1] * Jk[1] + d[2] * Jk[2] - fabs(h) * fabs(omega)) /
                 (4.0 * GC_PI);
        for (int l = 0; l < 3; l++) {
            const double al = d[l] * L[l] / A2;
            double mj = 0.0;
            for (int k = 0; k < 3; k++)
                mj += dot3(m[l], m[k]) * Jk[k];
            phi[f[l]] += (al * omega + h * L[l] / A2 * mj) / (4.0 * GC_PI);
        }
        if (h < 0.0) { /* x beyond this face: a candidate for the continuation */
            const int inside = d[0] >= 0.0 && d[1] >= 0.0 && d[2] >= 0.0;
            double dist = -h;
            if (!inside) { /* the distance to the triangle: to its nearest edge point */
                dist = 1e300;
                for (int k = 0; k < 3; k++) {
                    const double *p1 = ac[(k + 1) % 3], *p2 = ac[(k + 2) % 3];
                    double ed[3] = {p2[0] - p1[0], p2[1] - p1[1], p2[2] - p1[2]};
                    double s = -dot3(p1, ed) / (L[k] * L[k] > 0.0 ? L[k] * L[k] : 1.0);
                    s = s < 0.0 ? 0.0 : s > 1.0 ? 1.0 : s;
                    double q[3] = {p1[0] + s * ed[0], p1[1] + s * ed[1], p1[2] + s * ed[2]};
                    const double dq = sqrt(dot3(q, q));
                    dist = dq < dist ? dq : dist;
                }
            }
            if (beyond < 0 || (inside && !beyond_inside) ||
                (inside == beyond_inside && dist < beyond_dist)) {
                beyond = (int)t;
                beyond_inside = inside;
                beyond_dist = dist;
            }
        }
    }
    if (!isfinite(winding))
        return -1;
    if (winding < 2.0 * GC_PI && beyond >= 0) {
        /* outside: the analytic continuation through the face x lies beyond */
        const dk_index *f = tris + 3 * (size_t)beyond;
        const double *n = normals + 3 * (size_t)beyond;
        const double *ac[3] = {a + 3 * (size_t)f[0], a + 3 * (size_t)f[1], a + 3 * (size_t)f[2]};
        const double h = dot3(n, ac[0]);
        /* the barycentric coordinates of x's projection: sub-areas over the area */
        double e1[3], e2[3], nn[3];
        for (int c = 0; c < 3; c++) {
            e1[c] = ac[1][c] - ac[0][c];
            e2[c] = ac[2][c] - ac[0][c];
        }
        cross3(e1, e2, nn);
        const double A2 = dot3(nn, n);
        for (int l = 0; l < 3; l++) {
            double s[3];
            cross3(ac[(l + 1) % 3], ac[(l + 2) % 3], s);
            /* twice the sub-triangle (p, corner l+1, corner l+2)'s area: with p = x + h n
             * the corners' offsets from p are those from x less h n, which changes the
             * cross product only by vectors normal to n */
            phi[f[l]] += dot3(s, n) / A2;
        }
        psi[beyond] += -h;
    }
    for (dk_index j = 0; j < nc; j++)
        if (!isfinite(phi[j]))
            return -1;
    for (dk_index t = 0; t < nt; t++)
        if (!isfinite(psi[t]))
            return -1;
    return 0;
}
