/* DeformKit: the memory a bind needs, per method (dk_method.h, dk_method_estimate_memory).
 *
 * A model, fitted to measured peak RSS of the bind plus one solve (scripts/bench_memory.py,
 * docs/benchmarks.md "Memory"): linear in the vertex count, with a log term for the methods
 * whose cost is a sparse Cholesky factor (its fill grows like n log n on surface meshes) and
 * EigenDeformation's dense basis (K eigenvectors of n entries and ARPACK's workspace of
 * about 3 min(K, 50) vectors). Constants carry a 25% margin over the measurements, so that a bind refused
 * before allocating would really not have fit, and one admitted does not meet the limit
 * inside OpenBLAS. The factorization itself is checked again, exactly, from CHOLMOD's
 * symbolic analysis before the numeric factorization (dk_cholesky_factorize). */
#include "dk_method.h"

#include <math.h>
#include <string.h>

#include "dk_eigen.h"
#include "dk_embedded.h"

#define MIB (1024.0 * 1024.0)

dk_status dk_method_estimate_memory(const dk_method_ops *ops, const dk_mesh *mesh,
                                    const void *options, uint64_t *bytes, dk_error *err)
{
    if (!ops || !mesh || !bytes)
        return dk_error_set(err, DK_ERR_INVALID_ARGUMENT,
                            "estimate_memory: ops, mesh and bytes must not be NULL");
    const double n = (double)mesh->n_vertices;
    const double lg = n > 2.0 ? log2(n) : 1.0;
    const double fixed = 8.0 * MIB; /* small per-object tables, the helper thread */
    double per_vertex;
    if (strcmp(ops->name, "ARAP") == 0 || strcmp(ops->name, "LaplacianEdit") == 0) {
        /* measured 1950 B/vertex at 8k and 43k vertices, 2180-2450 at 692k */
        per_vertex = 1700.0 + 40.0 * lg;
    } else if (strcmp(ops->name, "Falloff") == 0) {
        per_vertex = 80.0;               /* measured 34 at 43k, 70 at 692k */
    } else if (strcmp(ops->name, "EmbeddedDeformation") == 0) {
        /* measured 430 B/vertex at 43k (+ ~16 MiB at any size: the node graph's factor
         * and the BLAS buffers it touches first) */
        const dk_embedded_options *o = options;
        per_vertex = 500.0 + (o && o->k > 4 ? 24.0 * (o->k - 4) : 0.0);
        per_vertex += 16.0 * MIB / (n > 1.0 ? n : 1.0);
    } else if (strcmp(ops->name, "EigenDeformation") == 0) {
        /* The K basis vectors (n doubles each; the eigensolver builds them in place), the
         * band's Krylov basis of 2 min(K, 50) + 1 vectors and its results of about
         * min(K, 50) more (eigs.c), and the Laplacian's LDL' factor (the log term). K is the
         * larger of the requested m (automatic: up to 300) and the refinement n'. Measured
         * (2026-12-02): 4600 / 4700 B/vertex for K = 300 at 62k / 248k vertices (7650 / 7870
         * before the basis was built in place), 2660 for K = 50 at 62k. */
        const dk_eigen_options *o = options;
        double k = o && o->n_eigenvectors > 0 ? o->n_eigenvectors : 300.0;
        if (!o || o->refine > k)
            k = o ? o->refine : 300.0;
        if (k > n)
            k = n;
        per_vertex = 350.0 + 40.0 * lg + 8.0 * k + 26.0 * (k < 50.0 ? k : 50.0);
        if (n <= 600.0 || k > n / 4.0) /* eigen.c's dense path: the n x n matrix, dsyevd's
                                          workspace of 2 n^2 + 6n + 1 more */
            per_vertex += 24.0 * n;
    } else if (strcmp(ops->name, "LinearReconstruction") == 0) {
        /* the factor of the 7n-unknown system dominates, and its fill grows ~n log n.
         * Measured (2026-12-02, after the column assembly and the compact factor): 6560 /
         * 6890 / 8220 / 9720 B/vertex on the arm 8k, the armadillo 43k and subdivided once
         * and twice (173k, 692k); 8700-9700 before at 8k-173k */
        per_vertex = 1500.0 + 450.0 * lg;
    } else {
        return dk_error_set(err, DK_ERR_INVALID_ARGUMENT,
                            "estimate_memory: no memory model for method %s", ops->name);
    }
    *bytes = (uint64_t)(1.25 * per_vertex * n + fixed);
    return DK_OK;
}
