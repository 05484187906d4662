/* DeformKit volumetric ARAP: the interior's harmonic extension (volumetric_internal.h).
 *
 * With L the linear elements' Laplacian of the rest tetrahedra (edge weights
 * dk_tetrahedron_stiffness summed over the tetrahedra), a move d of the surface moves the
 * interior by the harmonic u with L_II u = -L_IB d, i.e. u_i = L_II^-1 (sum_b w_ib d_b): the
 * interior points' Dirichlet problem, positive definite when every interior point is in a
 * tetrahedron that is not degenerate (TetGen's are not; the factorization says so otherwise),
 * with linear precision (an affine move of the surface moves the interior by the
 * same map, exactly). */
#include "volumetric_internal.h"

#include "dk_operators.h"

void volumetric_extension_free(dk_volumetric_arap *va)
{
    free(va->ib_start);
    free(va->ib_col);
    free(va->ib_w);
    dk_sparse_free(va->lii);
    dk_cholesky_free(va->chol);
    free(va->rhs);
    va->ib_start = va->ib_col = NULL;
    va->ib_w = va->rhs = NULL;
    va->lii = NULL;
    va->chol = NULL;
}

static dk_status oom(dk_error *err)
{
    return dk_error_set(err, DK_ERR_OUT_OF_MEMORY, "VolumetricARAP bind: out of memory "
                                                   "(the interior's extension)");
}

dk_status volumetric_extension_build(dk_volumetric_arap *va, dk_error *err)
{
    const dk_index n = va->n, ni = va->np - va->n;
    if (ni == 0)
        return DK_OK;
    const double *p = va->volume->positions;
    /* triplets: per tetrahedron edge with an interior end, the II part (upper triangle and
     * diagonal) or the IB coupling */
    const size_t cap = 6 * 3 * (size_t)va->nt;
    dk_index *rows = malloc(cap * sizeof *rows + 1), *cols = malloc(cap * sizeof *cols + 1);
    double *vals = malloc(cap * sizeof *vals + 1);
    dk_index *ib_count = calloc((size_t)ni + 1, sizeof *ib_count);
    va->ib_start = calloc((size_t)ni + 1, sizeof *va->ib_start);
    va->rhs = malloc(3 * (size_t)ni * sizeof *va->rhs);
    if (!rows || !cols || !vals || !ib_count || !va->ib_start || !va->rhs) {
        free(rows);
        free(cols);
        free(vals);
        free(ib_count);
        return oom(err);
    }
    size_t k = 0, nib = 0;
    static const int ea[6] = {0, 0, 0, 1, 1, 2}, eb[6] = {1, 2, 3, 2, 3, 3};
    for (int pass = 0; pass < 2; pass++) {
        for (dk_index t = 0; t < va->nt; t++) {
            const dk_index *q = va->tets + 4 * (size_t)t;
            double w[6];
            dk_tetrahedron_stiffness(p + 3 * q[0], p + 3 * q[1], p + 3 * q[2], p + 3 * q[3], w);
            for (int e = 0; e < 6; e++) {
                dk_index a = q[ea[e]], b = q[eb[e]];
                if (a < n && b < n)
                    continue;
                if (a >= n && b >= n) { /* both interior: II entries */
                    if (pass == 1)
                        continue;
                    const dk_index i = a - n, j = b - n;
                    rows[k] = i < j ? i : j, cols[k] = i < j ? j : i, vals[k++] = -w[e];
                    rows[k] = i, cols[k] = i, vals[k++] = w[e];
                    rows[k] = j, cols[k] = j, vals[k++] = w[e];
                    continue;
                }
                if (a < n) { /* b interior, a on the surface */
                    const dk_index s = a;
                    a = b;
                    b = s;
                }
                const dk_index i = a - n;
                if (pass == 0) {
                    rows[k] = i, cols[k] = i, vals[k++] = w[e];
                    ib_count[i]++;
                    nib++;
                } else {
                    const dk_index at = va->ib_start[i] + ib_count[i]++;
                    va->ib_col[at] = b;
                    va->ib_w[at] = w[e];
                }
            }
        }
        if (pass == 0) {
            for (dk_index i = 0; i < ni; i++) {
                va->ib_start[i + 1] = va->ib_start[i] + ib_count[i];
                ib_count[i] = 0;
            }
            va->ib_col = malloc(nib * sizeof *va->ib_col + 1);
            va->ib_w = malloc(nib * sizeof *va->ib_w + 1);
            if (!va->ib_col || !va->ib_w) {
                free(rows);
                free(cols);
                free(vals);
                free(ib_count);
                return oom(err);
            }
        }
    }
    free(ib_count);
    dk_status st = dk_sparse_from_triplets(ni, ni, (int64_t)k, rows, cols, vals, &va->lii, err);
    free(rows);
    free(cols);
    free(vals);
    if (st == DK_OK)
        st = dk_cholesky_analyze(va->lii, &va->chol, err);
    if (st == DK_OK)
        st = dk_cholesky_factorize(va->chol, va->lii, err);
    if (st == DK_ERR_NOT_POSITIVE_DEFINITE)
        return dk_error_set(err, DK_ERR_DEGENERATE,
                            "VolumetricARAP bind: the interior's Laplacian is not positive "
                            "definite (degenerate tetrahedra)");
    return st == DK_OK ? DK_OK : dk_error_prefix(err, "VolumetricARAP bind: the interior");
}

dk_status volumetric_extend(const dk_volumetric_arap *va, const double *from,
                            const double *surface, double *out, double *rhs, dk_error *err)
{
    const dk_index n = va->n, ni = va->np - va->n;
    for (dk_index i = 0; i < ni; i++) {
        double b[3] = {0.0, 0.0, 0.0};
        for (dk_index k = va->ib_start[i]; k < va->ib_start[i + 1]; k++) {
            const dk_index s = va->ib_col[k];
            for (int d = 0; d < 3; d++)
                b[d] += va->ib_w[k] * (surface[3 * (size_t)s + d] - from[3 * (size_t)s + d]);
        }
        for (int d = 0; d < 3; d++)
            rhs[(size_t)d * ni + i] = b[d];
    }
    if (ni > 0) {
        const dk_status st = dk_cholesky_solve(va->chol, rhs, 3, rhs, err);
        if (st != DK_OK)
            return dk_error_prefix(err, "VolumetricARAP: the interior's extension");
    }
    for (dk_index i = 0; i < ni; i++)
        for (int d = 0; d < 3; d++)
            out[3 * ((size_t)n + i) + d] = from[3 * ((size_t)n + i) + d] + rhs[(size_t)d * ni + i];
    if (out != surface)
        memcpy(out, surface, 3 * (size_t)n * sizeof *out);
    return DK_OK;
}
