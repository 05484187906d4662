/* DeformKit: harmonic interpolation of painted values (dk_operators.h). */
#include <math.h>
#include <stdlib.h>
#include <string.h>

#include "dk_cholesky.h"
#include "dk_operators.h"
#include "dk_sparse.h"

dk_status dk_harmonic_interpolation(const dk_mesh *mesh, const dk_index *painted,
                                    const double *values, dk_index n_painted, double fallback,
                                    double *u, double *u_edge, dk_error *err)
{
    dk_status st = dk_harmonic_interpolation_columns(mesh, painted, values, n_painted, 1,
                                                     fallback, u, err);
    if (st != DK_OK || !u_edge)
        return st;
    for (dk_index e = 0; e < mesh->n_edges; e++)
        u_edge[e] = 0.5 * (u[mesh->edges[2 * (size_t)e]] + u[mesh->edges[2 * (size_t)e + 1]]);
    return DK_OK;
}

dk_status dk_harmonic_interpolation_columns(const dk_mesh *mesh, const dk_index *painted,
                                            const double *values, dk_index n_painted,
                                            int n_columns, double fallback, double *u,
                                            dk_error *err)
{
    if (!mesh || !u || (n_painted > 0 && (!painted || !values)) || n_painted < 0 ||
        n_columns < 1)
        return dk_error_set(err, DK_ERR_INVALID_ARGUMENT,
                            "harmonic_interpolation: arguments must not be NULL, and there "
                            "must be at least one column");
    const size_t k = (size_t)n_columns;
    const dk_index n = mesh->n_vertices, E = mesh->n_edges;
    dk_status st = dk_check_indices(painted, n_painted, n, "painted vertices", err);
    if (st != DK_OK)
        return st;
    for (size_t i = 0; i < (size_t)n_painted * k; i++)
        if (!isfinite(values[i]))
            return dk_error_set(err, DK_ERR_NONFINITE,
                                "harmonic_interpolation: the value of painted vertex %d is not "
                                "finite", (int)painted[i % (size_t)n_painted]);
    if (!isfinite(fallback))
        return dk_error_set(err, DK_ERR_NONFINITE, "harmonic_interpolation: fallback is not finite");
    const dk_index nc = mesh->report.n_components > 0 ? mesh->report.n_components : 1;
    dk_index *idx = malloc(((size_t)n + 1) * sizeof *idx);
    unsigned char *fixed = calloc((size_t)n + 1, 1), *has = calloc((size_t)nc, 1);
    double *w = malloc(((size_t)E + 1) * sizeof *w);
    dk_index *ri = NULL, *ci = NULL;
    double *vv = NULL, *b = NULL;
    dk_sparse *A = NULL;
    dk_cholesky *chol = NULL;
    if (!idx || !fixed || !has || !w) {
        st = dk_error_set(err, DK_ERR_OUT_OF_MEMORY, "harmonic_interpolation: out of memory");
        goto done;
    }
    for (dk_index i = 0; i < n_painted; i++) {
        if (fixed[painted[i]]) {
            st = dk_error_set(err, DK_ERR_INVALID_ARGUMENT,
                              "harmonic_interpolation: vertex %d is painted twice",
                              (int)painted[i]);
            goto done;
        }
        fixed[painted[i]] = 1;
        for (size_t j = 0; j < k; j++)
            u[(size_t)n * j + painted[i]] = values[(size_t)n_painted * j + i];
        has[mesh->component[painted[i]]] = 1;
    }
    for (dk_index v = 0; v < n; v++) /* unpainted components: the fallback, held */
        if (!has[mesh->component[v]]) {
            fixed[v] = 1;
            for (size_t j = 0; j < k; j++)
                u[(size_t)n * j + v] = fallback;
        }
    dk_cotangent_weights(mesh, mesh->positions, w);
    double mean = 0.0;
    for (dk_index e = 0; e < E; e++)
        mean += fabs(w[e]) / (double)(E > 0 ? E : 1);
    for (dk_index e = 0; e < E; e++)
        w[e] = fmax(w[e], 1e-2 * (mean > 0.0 ? mean : 1.0));
    dk_index nf = 0;
    for (dk_index v = 0; v < n; v++)
        idx[v] = fixed[v] ? -1 : nf++;
    if (nf > 0) { /* L_ff u_f = -L_fc u_c */
        const int64_t cap = 4 * (int64_t)E + n;
        ri = malloc((size_t)cap * sizeof *ri), ci = malloc((size_t)cap * sizeof *ci);
        vv = malloc((size_t)cap * sizeof *vv), b = calloc((size_t)nf * k, sizeof *b);
        if (!ri || !ci || !vv || !b) {
            st = dk_error_set(err, DK_ERR_OUT_OF_MEMORY, "harmonic_interpolation: out of memory");
            goto done;
        }
        int64_t t = 0;
        for (dk_index e = 0; e < E; e++) {
            const dk_index a = mesh->edges[2 * (size_t)e], c = mesh->edges[2 * (size_t)e + 1];
            const dk_index ia = idx[a], ic = idx[c];
            if (ia >= 0)
                ri[t] = ia, ci[t] = ia, vv[t++] = w[e];
            if (ic >= 0)
                ri[t] = ic, ci[t] = ic, vv[t++] = w[e];
            if (ia >= 0 && ic >= 0) {
                ri[t] = ia, ci[t] = ic, vv[t++] = -w[e];
                ri[t] = ic, ci[t] = ia, vv[t++] = -w[e];
            } else if (ia >= 0) {
                for (size_t j = 0; j < k; j++)
                    b[(size_t)nf * j + ia] += w[e] * u[(size_t)n * j + c];
            } else if (ic >= 0) {
                for (size_t j = 0; j < k; j++)
                    b[(size_t)nf * j + ic] += w[e] * u[(size_t)n * j + a];
            }
        }
        st = dk_sparse_from_triplets(nf, nf, t, ri, ci, vv, &A, err);
        if (st == DK_OK)
            st = dk_cholesky_analyze(A, &chol, err);
        if (st == DK_OK)
            st = dk_cholesky_factorize(chol, A, err);
        if (st == DK_OK)
            st = dk_cholesky_solve(chol, b, n_columns, b, err);
        if (st != DK_OK) {
            dk_error_prefix(err, "harmonic_interpolation");
            goto done;
        }
        for (dk_index v = 0; v < n; v++)
            if (idx[v] >= 0)
                for (size_t j = 0; j < k; j++)
                    u[(size_t)n * j + v] = b[(size_t)nf * j + idx[v]];
    }
done:
    dk_cholesky_free(chol);
    dk_sparse_free(A);
    free(idx);
    free(fixed);
    free(has);
    free(w);
    free(ri);
    free(ci);
    free(vv);
    free(b);
    return st;
}
