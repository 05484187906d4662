/* DeformKit internal: two-thread triangular solves with a numeric CHOLMOD factor.
 *
 * cholmod_solve2 runs on one thread. The forward and backward substitutions of a sparse
 * factor are, however, independent in disjoint subtrees of the elimination tree: columns of
 * one subtree only update rows of that subtree and of its ancestors. A plan splits the tree
 * into a set of disjoint subtrees, assigned to two threads with balanced work (entries of
 * the factor), and the remaining "top" columns (the ancestors: on surface meshes the top
 * separators), done by one thread:
 *   forward:  both threads do their subtrees (the second on its own copy of the rows it
 *             writes outside its subtrees, added afterwards), then the top columns;
 *   backward: the top columns, then both threads their subtrees (read-only outside them).
 * In supernodal factors the big top supernodes are cut into blocks of 64 columns whose
 * triangle one thread does while the rows below each block are split between both (the
 * root separator of a surface mesh is a dense supernode of hundreds of columns).
 * The factor is read as columns (row list, values, length; diagonal first) for both of
 * CHOLMOD's layouts: simplicial LL' or LDL', and supernodal LL' (column c of a supernode is
 * its row list from c on, its dense column from the diagonal on). Results equal
 * cholmod_solve2's to rounding (the same operations, in another order of summation).
 * Used by dk_cholesky for factors big enough to gain from it.
 */
#ifndef DK_TRISOLVE_H
#define DK_TRISOLVE_H

#include "dk_parallel.h"

#include <cholmod.h>
#include <stddef.h>

typedef struct dk_trisolve dk_trisolve;

/** A plan for the numeric factor `L` (CHOLMOD_INT indices, real doubles, postordered
 *  elimination tree). Returns NULL when the factor does not qualify (symbolic, complex,
 *  not postordered, fewer than `min_entries` entries, an estimated speed-up below
 *  `min_speedup`, out of memory): the caller then uses cholmod_solve2. dk_cholesky passes
 *  200,000 entries (below, a solve takes < ~0.3 ms and the thread start and copies eat the
 *  gain) and 1.25; tests pass 0 and 0 to exercise any tree. The plan refers to L's arrays:
 *  rebuild it after every numeric factorization. */
dk_trisolve *dk_trisolve_plan(const cholmod_factor *L, double min_entries, double min_speedup);

/** Solves A X = B with the factor of A (P A P' = L L' or L D L'), B and X column-major
 *  n x nrhs (X may alias B), 1 <= nrhs <= 16. The second thread is `team`'s helper (NULL: a
 *  thread started for each of the two sweeps). Returns 0, or -1 when nrhs is out of that
 *  range or its workspace cannot be allocated
 *  (nothing written; the caller falls back). Allocates only when nrhs grows. More than 6
 *  columns are solved in balanced blocks of at most 6 (one pass over the factor each, with
 *  the register kernels), the largest first. */
int dk_trisolve_solve(dk_trisolve *plan, dk_team *team, const double *b, int nrhs,
                      double *x);

/** Estimated speed-up of the plan's split (serial work / critical path), for tests. */
double dk_trisolve_balance(const dk_trisolve *plan);

/** Bytes held by the plan and its workspace. */
size_t dk_trisolve_bytes(const dk_trisolve *plan);

/** Frees the plan (NULL is fine). */
void dk_trisolve_free(dk_trisolve *plan);

#endif
