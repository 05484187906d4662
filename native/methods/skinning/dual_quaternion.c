/* DeformKit skinning: the unit dual quaternions of dual quaternion skinning (Kavan, Collins,
 * Zara, O'Sullivan 2008): a rigid motion as (r, d), blended linearly by the caller and
 * applied here after normalisation. */
#include <math.h>

#include "dk_operators.h"
#include "skinning_internal.h"

/* a b (Hamilton product, w x y z) */
static void qmul(const double a[4], const double b[4], double c[4])
{
    c[0] = a[0] * b[0] - a[1] * b[1] - a[2] * b[2] - a[3] * b[3];
    c[1] = a[0] * b[1] + a[1] * b[0] + a[2] * b[3] - a[3] * b[2];
    c[2] = a[0] * b[2] - a[1] * b[3] + a[2] * b[0] + a[3] * b[1];
    c[3] = a[0] * b[3] + a[1] * b[2] - a[2] * b[1] + a[3] * b[0];
}

void skin_dq_from_rigid(const double R[9], const double t[3], double r[4], double d[4])
{
    dk_rotation_quaternion(R, r);
    const double tq[4] = {0.0, t[0], t[1], t[2]};
    qmul(tq, r, d);
    for (int k = 0; k < 4; k++)
        d[k] *= 0.5;
}

void skin_dq_apply(const double r[4], const double d[4], const double x[3], double out[3])
{
    const double len = sqrt(r[0] * r[0] + r[1] * r[1] + r[2] * r[2] + r[3] * r[3]);
    if (!(len > 0.0)) {
        out[0] = x[0];
        out[1] = x[1];
        out[2] = x[2];
        return;
    }
    const double w = r[0] / len, v[3] = {r[1] / len, r[2] / len, r[3] / len};
    const double we = d[0] / len, ve[3] = {d[1] / len, d[2] / len, d[3] / len};
    /* the rotation: x + 2 v x (v x x + w x) */
    const double c1[3] = {v[1] * x[2] - v[2] * x[1] + w * x[0],
                          v[2] * x[0] - v[0] * x[2] + w * x[1],
                          v[0] * x[1] - v[1] * x[0] + w * x[2]};
    const double c2[3] = {v[1] * c1[2] - v[2] * c1[1], v[2] * c1[0] - v[0] * c1[2],
                          v[0] * c1[1] - v[1] * c1[0]};
    /* the translation: 2 (w ve - we v + v x ve) */
    const double cx[3] = {v[1] * ve[2] - v[2] * ve[1], v[2] * ve[0] - v[0] * ve[2],
                          v[0] * ve[1] - v[1] * ve[0]};
    for (int k = 0; k < 3; k++)
        out[k] = x[k] + 2.0 * c2[k] + 2.0 * (w * ve[k] - we * v[k] + cx[k]);
}
