/* DeformKit: the memory a bind needs (dk_method.h, dk_method_estimate_memory): each method's
 * own model (its ops' estimate_memory, next to the method), and the margin they share.
 *
 * The models are fitted to measured peak RSS of the bind plus one solve
 * (scripts/bench_memory.py, docs/benchmarks.md "Memory"): linear in the vertex count, with a
 * log term for the methods whose cost is a sparse Cholesky factor (its fill grows like
 * n log n on surface meshes). Constants carry a 25% margin over the measurements, so that a
 * bind refused before allocating would really not have fit, and one admitted does not meet
 * the limit inside OpenBLAS. The factorization itself is checked again, exactly, from
 * CHOLMOD's symbolic analysis before the numeric factorization (dk_cholesky_factorize). */
#include "dk_method.h"

#define MIB (1024.0 * 1024.0)

uint64_t dk_memory_model(double per_vertex, double n_vertices, double extra)
{
    const double fixed = 8.0 * MIB; /* small per-object tables, the helper thread */
    return (uint64_t)(1.25 * (per_vertex * n_vertices + extra) + fixed);
}

dk_status dk_method_estimate_memory(const dk_method_ops *ops, const dk_mesh *mesh,
                                    const void *options, uint64_t *bytes, dk_error *err)
{
    if (!ops || !mesh || !bytes || !ops->estimate_memory)
        return dk_error_set(err, DK_ERR_INVALID_ARGUMENT,
                            "estimate_memory: ops (with a model), mesh and bytes must not be "
                            "NULL");
    return ops->estimate_memory(mesh, options, bytes, err);
}
