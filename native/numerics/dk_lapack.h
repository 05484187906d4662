/* DeformKit: LAPACK's dense symmetric eigensolvers without LAPACKE's own allocations.
 *
 * LAPACKE's high-level drivers allocate their work arrays and, when that fails, print a
 * message to stdout (LAPACKE_xerbla). The library never prints: these call the _work
 * drivers with work arrays allocated here, and report a failed allocation as LAPACKE
 * does (LAPACK_WORK_MEMORY_ERROR) without a word. Column-major only (no transposed copy).
 */
#ifndef DK_LAPACK_H
#define DK_LAPACK_H

/** Eigenvalues (ascending, into w: n) and, with jobz 'V', eigenvectors (overwriting a) of
 *  the symmetric n x n column-major matrix a (leading dimension n; its upper triangle is
 *  read). Returns LAPACK's info: 0, > 0 (no convergence), < 0 (an illegal argument), or
 *  LAPACK_WORK_MEMORY_ERROR when the work arrays could not be allocated. */
int dk_lapack_dsyev(char jobz, int n, double *a, double *w);

/** As dk_lapack_dsyev, by divide and conquer (LAPACK dsyevd). */
int dk_lapack_dsyevd(char jobz, int n, double *a, double *w);

/** Eigenvalues (into d: n, ascending) and, with jobz 'V', eigenvectors (z: n x n,
 *  column-major, leading dimension ldz >= n) of the symmetric tridiagonal matrix with
 *  diagonal d (n) and off-diagonal e (n - 1 used; overwritten). Returns as dk_lapack_dsyev. */
int dk_lapack_dstev(char jobz, int n, double *d, double *e, double *z, int ldz);

#endif
