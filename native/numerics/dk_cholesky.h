/* DeformKit: sparse Cholesky (CHOLMOD) and symmetric eigenproblems (ARPACK).
 *
 * dk_cholesky wraps one CHOLMOD context (no global state): analyze once, factorize
 * numerically as often as the values change (same pattern), solve many right-hand sides at
 * once. CHOLMOD's printing is switched off; its failures come back as dk_status codes.
 * Ordering AMD; simplicial or supernodal LL' chosen by CHOLMOD from the flops per factor entry
 * (switch at 100: simplicial on surface meshes up to ~10^5 vertices, where it is 2-3x
 * faster; supernodal beyond). Solves of factors with >= 200,000 entries run on two threads
 * (dk_trisolve.h), others through cholmod_solve2. Armadillo (43k vertices, 2 cores): analyze
 * 0.03 s, factorize 0.04 s, 3-RHS solve ~1-2 ms.
 */
#ifndef DK_CHOLESKY_H
#define DK_CHOLESKY_H

#include "dk_parallel.h"
#include "dk_sparse.h"
#include "dk_status.h"

#ifdef __cplusplus
extern "C" {
#endif

typedef struct dk_cholesky dk_cholesky;

/** Symbolic analysis (fill-reducing ordering) of the symmetric matrix `a` (n x n; only its
 *  upper triangle, diagonal included, is read, so the lower one may be left out). `*out` is
 *  a new factor object without numeric values. */
dk_status dk_cholesky_analyze(const dk_sparse *a, dk_cholesky **out, dk_error *err);

/** Like dk_cholesky_analyze, for a factor that must be small rather than fast to compute:
 *  a supernodal factor's supernodes are amalgamated without explicit zeros (CHOLMOD's
 *  zrelax all 0). LinearReconstruction's system on the 62k ogre: 18.7M stored entries
 *  instead of 23.2M, the factorization as fast (issue 19, memory). Solves are the same. */
dk_status dk_cholesky_analyze_compact(const dk_sparse *a, dk_cholesky **out, dk_error *err);

/** Like dk_cholesky_analyze, always simplicial LL': no BLAS calls, so that two
 *  factorizations can run at once, one per core, without the BLAS's own threads fighting
 *  them (bounded biharmonic weights factor a system per handle and iteration, two handles
 *  at a time: 2.7 s against 4.9 s with supernodal factors on the 43k armadillo). */
dk_status dk_cholesky_analyze_simplicial(const dk_sparse *a, dk_cholesky **out, dk_error *err);

/** Whether the analysis chose a supernodal factor (dense fronts, BLAS calls): 1, else 0. */
int dk_cholesky_is_supernodal(const dk_cholesky *chol);

/** Numeric factorization of `a`, which must have the pattern given to analyze. Fails with
 *  DK_ERR_NOT_POSITIVE_DEFINITE naming the column where positivity was lost. */
dk_status dk_cholesky_factorize(dk_cholesky *chol, const dk_sparse *a, dk_error *err);

/** Solves A X = B for `nrhs` right-hand sides stored column-major (n x nrhs) in `b`,
 *  writing `x` (may alias `b`). Workspace is kept in the object, so repeated solves with the
 *  same nrhs do not allocate. Not thread-safe on the same object. */
dk_status dk_cholesky_solve(dk_cholesky *chol, const double *b, int nrhs, double *x,
                            dk_error *err);

/** Solves of big factors (>= 200,000 entries) run their forward and backward substitutions
 *  on two threads, over disjoint subtrees of the elimination tree (dk_trisolve.h), when the
 *  split promises a speed-up of at least 1.25; results equal cholmod_solve2's to rounding.
 *  `on` = 0 makes this object always use cholmod_solve2 (tests and benchmarks compare); 1 is
 *  the default; 2 plans two-thread solves for every later factorization whatever its size
 *  and balance (tests of the scheduling on small and degenerate trees). */
void dk_cholesky_set_parallel(dk_cholesky *chol, int on);

/** Two-thread solves use `team`'s helper thread (dk_parallel.h) instead of starting a thread
 *  per sweep. The team is not owned: it must outlive the solves (a method object owns both
 *  and sets its team on every factor object it makes). NULL (the default) starts threads. */
void dk_cholesky_set_team(dk_cholesky *chol, dk_team *team);

/** Estimated speed-up (serial work / critical path) of the two-thread solve planned for the
 *  current factorization, or 0 when solves use cholmod_solve2. */
double dk_cholesky_parallel_speedup(const dk_cholesky *chol);

/** Matrix dimension. */
dk_index dk_cholesky_size(const dk_cholesky *chol);

/** How many numeric factorizations this object has done since analyze (to verify reuse). */
int dk_cholesky_factorization_count(const dk_cholesky *chol);

/** How many symbolic analyses this object has done (1 after analyze). */
int dk_cholesky_analysis_count(const dk_cholesky *chol);

/** Bytes held by the factor (for memory reports). */
size_t dk_cholesky_memory(const dk_cholesky *chol);

/** The smallest pivot of the last factorization against its own diagonal entry:
 *  min_j L_jj^2 / A_pp (LDL': D_jj / A_pp), p the row pivot j eliminated, for the matrix `a`
 *  (n x n, the one factored). Near DBL_EPSILON when `a` is singular but for rounding, which
 *  lets a factorization "succeed" with a pivot of rounding's size and sign; unlike a
 *  condition number it does not fall with the scale of some rows against others. 0 when
 *  not factored or a diagonal entry is not positive. */
double dk_cholesky_min_pivot_ratio(const dk_cholesky *chol, const dk_sparse *a);

/** Like dk_cholesky_analyze, for symmetric INDEFINITE nonsingular matrices (the shifted
 *  operators L - sigma M of the band-by-band eigensolver): simplicial LDL' without pivoting
 *  (CHOLMOD has no pivoting), so it is only as stable as the matrix allows. Factorize then
 *  fails with DK_ERR_NOT_POSITIVE_DEFINITE only on a zero or NaN pivot (singular matrix).
 *  Slower than the supernodal LL' of dk_cholesky_analyze; use that one for SPD matrices. */
dk_status dk_cholesky_analyze_indefinite(const dk_sparse *a, dk_cholesky **out,
                                         dk_error *err);

/** Inertia after a successful factorization: `*count` gets the number of negative pivots
 *  of D in LDL' (objects from dk_cholesky_analyze_indefinite), which by Sylvester's law of
 *  inertia is the number of negative eigenvalues of the matrix (for L - sigma M with M
 *  positive definite: the number of eigenvalues of L x = lambda M x below sigma).
 *  Always 0 for an LL' factor (the matrix is positive definite). */
dk_status dk_cholesky_negative_pivots(const dk_cholesky *chol, dk_index *count, dk_error *err);

/** Frees; NULL allowed. */
void dk_cholesky_free(dk_cholesky *chol);

#ifdef __cplusplus
}
#endif
#endif
