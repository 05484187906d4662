/* DeformKit: the memory a bind needs, per method (dk_method.h, dk_method_estimate_memory).
 *
 * A model, fitted to measured peak RSS of the bind plus one solve (scripts/bench_memory.py,
 * docs/benchmarks.md "Memory"): linear in the vertex count, with a log term for the methods
 * whose cost is a sparse Cholesky factor (its fill grows like n log n on surface meshes) and
 * EigenDeformation's dense basis (K eigenvectors of n entries and ARPACK's ~2K-vector
 * workspace). Constants carry a 25% margin over the measurements, so that a bind refused
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
        /* K basis vectors (n doubles each) and ARPACK's workspace of about 2K more; K is the
         * larger of the requested m (automatic: up to 300) and the refinement n' */
        const dk_eigen_options *o = options;
        double k = o && o->n_eigenvectors > 0 ? o->n_eigenvectors : 300.0;
        if (!o || o->refine > k)
            k = o ? o->refine : 300.0;
        if (k > n)
            k = n;
        per_vertex = 1300.0 + 26.0 * k;  /* measured 7600-8000 B/vertex for K = 300 */
    } else if (strcmp(ops->name, "LinearReconstruction") == 0) {
        per_vertex = 8700.0 + 40.0 * lg; /* measured 8800-9000 B/vertex at 8k and 43k */
    } else {
        return dk_error_set(err, DK_ERR_INVALID_ARGUMENT,
                            "estimate_memory: no memory model for method %s", ops->name);
    }
    *bytes = (uint64_t)(1.25 * per_vertex * n + fixed);
    return DK_OK;
}
