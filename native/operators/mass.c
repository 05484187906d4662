/* DeformKit: lumped mass matrices (dk_mass_matrix).
 *
 * Barycentric: a third of each triangle's area to each corner. Mixed Voronoi (Meyer, Desbrun,
 * Schroeder, Barr 2003): in a non-obtuse triangle corner P gets its Voronoi part
 * (|PR|^2 cot Q + |PQ|^2 cot R) / 8; in an obtuse triangle the obtuse corner gets area / 2
 * and the two others area / 4. The cotangents are computed as dot / (2 * area), so a right
 * angle gives exactly 0 and the three parts of a non-obtuse triangle sum to its area.
 * A degenerate triangle (dk_triangle_degenerate: the same rule as the cotangent
 * weights) contributes nothing, so every mass is finite and vertices only on degenerate
 * triangles (and isolated vertices) get 0.
 */
#include <math.h>

#include "dk_operators.h"

dk_status dk_mass_matrix(const dk_mesh *mesh, dk_mass_kind kind, double *mass, dk_error *err)
{
    if (!mesh) return dk_error_set(err, DK_ERR_INVALID_ARGUMENT, "mass matrix: mesh is NULL");
    if (!mass) return dk_error_set(err, DK_ERR_INVALID_ARGUMENT, "mass matrix: mass is NULL");
    if (kind != DK_MASS_BARYCENTRIC && kind != DK_MASS_VORONOI)
        return dk_error_set(err, DK_ERR_INVALID_ARGUMENT,
                            "mass matrix: unknown kind %d (0 barycentric, 1 Voronoi)", (int)kind);
    for (dk_index v = 0; v < mesh->n_vertices; v++) mass[v] = 0.0;
    const double *x = mesh->positions;
    for (dk_index f = 0; f < mesh->n_faces; f++) {
        const dk_index *t = mesh->faces + 3 * f;
        /* e[k] = p[k+2] - p[k+1], opposite corner k */
        double e[3][3], len2[3];
        for (int k = 0; k < 3; k++) {
            const double *a = x + 3 * t[(k + 1) % 3], *b = x + 3 * t[(k + 2) % 3];
            for (int d = 0; d < 3; d++) e[k][d] = b[d] - a[d];
            len2[k] = e[k][0] * e[k][0] + e[k][1] * e[k][1] + e[k][2] * e[k][2];
        }
        double cx = e[0][1] * e[1][2] - e[0][2] * e[1][1];
        double cy = e[0][2] * e[1][0] - e[0][0] * e[1][2];
        double cz = e[0][0] * e[1][1] - e[0][1] * e[1][0];
        double area = 0.5 * sqrt(cx * cx + cy * cy + cz * cz);
        double longest = fmax(len2[0], fmax(len2[1], len2[2]));
        if (dk_triangle_degenerate(x + 3 * t[0], x + 3 * t[1], x + 3 * t[2], 2.0 * area, longest))
            continue;
        if (kind == DK_MASS_BARYCENTRIC) {
            for (int k = 0; k < 3; k++) mass[t[k]] += area / 3.0;
            continue;
        }
        /* dot[k]: dot product of the two edges leaving corner k (its cosine's sign) */
        double dot[3];
        for (int k = 0; k < 3; k++) {
            const double *u = e[(k + 2) % 3], *v = e[(k + 1) % 3];
            dot[k] = -(u[0] * v[0] + u[1] * v[1] + u[2] * v[2]);
        }
        int obtuse = -1;
        for (int k = 0; k < 3; k++)
            if (dot[k] < 0.0) obtuse = k;
        if (obtuse >= 0) {
            for (int k = 0; k < 3; k++) mass[t[k]] += (k == obtuse) ? area / 2.0 : area / 4.0;
            continue;
        }
        /* Voronoi: corner k gets (|e[k+1]|^2 cot(k+1) + |e[k+2]|^2 cot(k+2)) / 8, where the
         * edge e[k+1] (from k+2 to k, length |PR|) is opposite corner k+1. */
        double cot[3];
        for (int k = 0; k < 3; k++) cot[k] = dot[k] / (2.0 * area);
        for (int k = 0; k < 3; k++) {
            int k1 = (k + 1) % 3, k2 = (k + 2) % 3;
            mass[t[k]] += (len2[k1] * cot[k1] + len2[k2] * cot[k2]) / 8.0;
        }
    }
    return DK_OK;
}
