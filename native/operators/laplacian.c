/* DeformKit: uniform and cotangent Laplacians (dk_laplacian_*, dk_cotangent_weights).
 *
 * Every Laplacian is assembled straight into CSC from the one-ring CSR of the mesh: column
 * v holds v's neighbours (already sorted) with the diagonal inserted in order, so the
 * pattern is the same for every weighting (n + 2 * n_edges entries, full diagonal even on
 * isolated vertices) and no triplet sort is needed. Sign convention: dk_operators.h.
 */
#include <float.h>
#include <math.h>
#include <stdlib.h>

#include "dk_operators.h"

/* Degenerate triangles (dk_triangle_degenerate): area below DEGENERATE_RATIO times the
 * longest edge squared, or height below ROUNDING_UNITS * DBL_EPSILON times the largest
 * absolute coordinate (the coordinates' own rounding, with room for the few operations that
 * computed them: a turn, a shift, a file's decimal digits). */
#define DEGENERATE_RATIO 1e-14
#define ROUNDING_UNITS 64.0

int dk_triangle_degenerate(const double *p0, const double *p1, const double *p2,
                           double twice_area, double longest2)
{
    if (!(0.5 * twice_area > DEGENERATE_RATIO * longest2))
        return 1; /* also NaN */
    double scale = 0.0;
    for (int d = 0; d < 3; d++)
        scale = fmax(scale, fmax(fabs(p0[d]), fmax(fabs(p1[d]), fabs(p2[d]))));
    /* height = twice_area / longest edge */
    return !(twice_area > ROUNDING_UNITS * DBL_EPSILON * scale * sqrt(longest2)) ||
           !isfinite(scale);
}

void dk_cotangent_weights(const dk_mesh *mesh, const double *positions, double *weights)
{
    for (dk_index e = 0; e < mesh->n_edges; e++) weights[e] = 0.0;
    for (dk_index f = 0; f < mesh->n_faces; f++) {
        const dk_index *t = mesh->faces + 3 * f;
        const double *p[3] = {positions + 3 * t[0], positions + 3 * t[1], positions + 3 * t[2]};
        /* e[k] = p[k+2] - p[k+1]: the edge opposite corner k */
        double e[3][3], len2[3];
        for (int k = 0; k < 3; k++) {
            const double *a = p[(k + 1) % 3], *b = p[(k + 2) % 3];
            for (int d = 0; d < 3; d++) e[k][d] = b[d] - a[d];
            len2[k] = e[k][0] * e[k][0] + e[k][1] * e[k][1] + e[k][2] * e[k][2];
        }
        double cx = e[0][1] * e[1][2] - e[0][2] * e[1][1];
        double cy = e[0][2] * e[1][0] - e[0][0] * e[1][2];
        double cz = e[0][0] * e[1][1] - e[0][1] * e[1][0];
        double twice_area = sqrt(cx * cx + cy * cy + cz * cz);
        double longest = fmax(len2[0], fmax(len2[1], len2[2]));
        if (dk_triangle_degenerate(p[0], p[1], p[2], twice_area, longest)) continue;
        for (int k = 0; k < 3; k++) {
            /* angle at corner k, between the edges to corners k+1 and k+2:
             * cot = (u . v) / |u x v| with u = p[k+1]-p[k] = e[k+2], v = p[k+2]-p[k] = -e[k+1] */
            const double *u = e[(k + 2) % 3], *v = e[(k + 1) % 3];
            double dot = -(u[0] * v[0] + u[1] * v[1] + u[2] * v[2]);
            weights[mesh->face_edges[3 * f + k]] += 0.5 * dot / twice_area;
        }
    }
}

dk_status dk_laplacian_from_edge_weights(const dk_mesh *mesh, const double *weights,
                                         dk_sparse **out, dk_error *err)
{
    if (!out) return dk_error_set(err, DK_ERR_INVALID_ARGUMENT, "Laplacian: out is NULL");
    *out = NULL;
    if (!mesh) return dk_error_set(err, DK_ERR_INVALID_ARGUMENT, "Laplacian: mesh is NULL");
    if (!weights && mesh->n_edges > 0)
        return dk_error_set(err, DK_ERR_INVALID_ARGUMENT, "Laplacian: weights is NULL");
    for (dk_index e = 0; e < mesh->n_edges; e++)
        if (!isfinite(weights[e]))
            return dk_error_set(err, DK_ERR_NONFINITE, "Laplacian: weight of edge %d (%d-%d) is %g",
                                (int)e, (int)mesh->edges[2 * e], (int)mesh->edges[2 * e + 1],
                                weights[e]);
    dk_index n = mesh->n_vertices;
    dk_sparse *a = NULL;
    dk_status st = dk_sparse_alloc(n, n, (int64_t)n + 2 * (int64_t)mesh->n_edges, &a, err);
    if (st != DK_OK) {
        dk_error_prefix(err, "Laplacian");
        return st;
    }
    int64_t pos = 0;
    for (dk_index v = 0; v < n; v++) {
        a->col_start[v] = (dk_index)pos;
        double diag = 0.0;
        int64_t diag_pos = -1;
        for (dk_index r = mesh->ring_start[v]; r < mesh->ring_start[v + 1]; r++) {
            dk_index j = mesh->ring_index[r];
            if (diag_pos < 0 && j > v) {
                diag_pos = pos;
                a->row_index[pos++] = v;
            }
            double w = weights[mesh->ring_edge[r]];
            a->row_index[pos] = j;
            a->values[pos++] = -w;
            diag += w;
        }
        if (diag_pos < 0) {
            diag_pos = pos;
            a->row_index[pos++] = v;
        }
        a->values[diag_pos] = diag;
    }
    a->col_start[n] = (dk_index)pos;
    *out = a;
    return DK_OK;
}

dk_status dk_laplacian_uniform(const dk_mesh *mesh, dk_sparse **out, dk_error *err)
{
    if (!out) return dk_error_set(err, DK_ERR_INVALID_ARGUMENT, "uniform Laplacian: out is NULL");
    *out = NULL;
    if (!mesh) return dk_error_set(err, DK_ERR_INVALID_ARGUMENT, "uniform Laplacian: mesh is NULL");
    double *w = malloc((size_t)(mesh->n_edges > 0 ? mesh->n_edges : 1) * sizeof *w);
    if (!w)
        return dk_error_set(err, DK_ERR_OUT_OF_MEMORY, "uniform Laplacian: out of memory (%d edges)",
                            (int)mesh->n_edges);
    for (dk_index e = 0; e < mesh->n_edges; e++) w[e] = 1.0;
    dk_status st = dk_laplacian_from_edge_weights(mesh, w, out, err);
    free(w);
    return st;
}

dk_status dk_laplacian_cotangent(const dk_mesh *mesh, dk_sparse **out, dk_error *err)
{
    if (!out)
        return dk_error_set(err, DK_ERR_INVALID_ARGUMENT, "cotangent Laplacian: out is NULL");
    *out = NULL;
    if (!mesh)
        return dk_error_set(err, DK_ERR_INVALID_ARGUMENT, "cotangent Laplacian: mesh is NULL");
    double *w = malloc((size_t)(mesh->n_edges > 0 ? mesh->n_edges : 1) * sizeof *w);
    if (!w)
        return dk_error_set(err, DK_ERR_OUT_OF_MEMORY,
                            "cotangent Laplacian: out of memory (%d edges)", (int)mesh->n_edges);
    dk_cotangent_weights(mesh, mesh->positions, w);
    dk_status st = dk_laplacian_from_edge_weights(mesh, w, out, err);
    free(w);
    return st;
}
