/* DeformKit: a tetrahedron's linear-element stiffness per edge (dk_operators.h). */
#include "dk_operators.h"

#include <math.h>

double dk_tetrahedron_stiffness(const double *p0, const double *p1, const double *p2,
                                const double *p3, double w[6])
{
    const double *p[4] = {p0, p1, p2, p3};
    double d[3][3]; /* columns p1 - p0, p2 - p0, p3 - p0 */
    double longest2 = 0.0;
    for (int j = 0; j < 3; j++)
        for (int k = 0; k < 3; k++)
            d[k][j] = p[j + 1][k] - p0[k];
    for (int a = 0; a < 4; a++)
        for (int b = a + 1; b < 4; b++) {
            const double e0 = p[a][0] - p[b][0], e1 = p[a][1] - p[b][1], e2 = p[a][2] - p[b][2];
            longest2 = fmax(longest2, e0 * e0 + e1 * e1 + e2 * e2);
        }
    /* cofactors: D_m^-1 = cof^T / det, whose rows are the gradients of phi_1..3 */
    double c[3][3];
    c[0][0] = d[1][1] * d[2][2] - d[1][2] * d[2][1];
    c[0][1] = d[1][2] * d[2][0] - d[1][0] * d[2][2];
    c[0][2] = d[1][0] * d[2][1] - d[1][1] * d[2][0];
    c[1][0] = d[0][2] * d[2][1] - d[0][1] * d[2][2];
    c[1][1] = d[0][0] * d[2][2] - d[0][2] * d[2][0];
    c[1][2] = d[0][1] * d[2][0] - d[0][0] * d[2][1];
    c[2][0] = d[0][1] * d[1][2] - d[0][2] * d[1][1];
    c[2][1] = d[0][2] * d[1][0] - d[0][0] * d[1][2];
    c[2][2] = d[0][0] * d[1][1] - d[0][1] * d[1][0];
    const double det = d[0][0] * c[0][0] + d[0][1] * c[0][1] + d[0][2] * c[0][2];
    for (int k = 0; k < 6; k++)
        w[k] = 0.0;
    if (!(fabs(det) > 1e-12 * longest2 * sqrt(longest2)))
        return 0.0;
    double g[4][3]; /* grad phi_j = column j of cof / det (j = 1..3), grad phi_0 = -sum */
    for (int j = 0; j < 3; j++)
        for (int k = 0; k < 3; k++)
            g[j + 1][k] = c[k][j] / det;
    for (int k = 0; k < 3; k++)
        g[0][k] = -(g[1][k] + g[2][k] + g[3][k]);
    const double vol = fabs(det) / 6.0;
    int e = 0;
    for (int a = 0; a < 4; a++)
        for (int b = a + 1; b < 4; b++)
            w[e++] = -vol * (g[a][0] * g[b][0] + g[a][1] * g[b][1] + g[a][2] * g[b][2]);
    return det / 6.0;
}
