/* DeformKit: the k smallest eigenpairs of L x = lambda M x with ARPACK.
 *
 * L symmetric positive semidefinite (sparse), M diagonal positive. Shift-invert mode (ARPACK
 * mode 3, B = M) with dk_cholesky solving (L - sigma M) y = M x. Eigenvectors are returned
 * M-orthonormal (x_i^T M x_j = delta_ij), sorted by increasing eigenvalue.
 *
 * Many eigenpairs: when k exceeds `band_size`, the spectrum is computed band by band with a
 * new shift per band (Vallet and Levy 2008, "Spectral geometry processing with manifold
 * harmonics"), each band a small ARPACK run, so hundreds of eigenpairs stay practical.
 *
 * Completeness: every band is certified by the inertia of an LDL' factorization of
 * L - tau M (tau in a spectral gap at the band's top: Sylvester's law counts the eigenvalues
 * below tau), and copies of multiple eigenvalues that Lanczos missed are recovered by a
 * deflated run, so no eigenvalue below the k-th is skipped or duplicated.
 *
 * Disconnected L (several components in its graph, e.g. a mesh of many parts): the spectrum
 * is the union of the components' spectra, with eigenvalue 0 once per component and every
 * eigenvalue of a part repeated once per identical copy, multiplicities that Lanczos (one
 * vector per eigenspace) cannot be relied on to find. Each component is then solved on its
 * own (densely when small), the number of pairs each contributes read from the inertia of
 * LDL' of L_c - tau M_c at a tau below which exactly k eigenvalues lie; the vectors are zero
 * outside their component. A connected L takes the band search alone, as before. Results are
 * deterministic (fixed start vectors). Measured on the 43k-vertex armadillo (2 cores):
 * 50 pairs ~0.6-1.0 s, 300 pairs ~4.8-6.5 s with the default band_size
 * (scripts/bench_core.py, scripts/bench_eigen.py). A block Lanczos method of our own was
 * measured against ARPACK here and lost (docs/methods/eigen.md): ARPACK it stays.
 *
 * ARPACK keeps internal SAVE variables: calls are not reentrant across threads. Callers that
 * may run concurrently (the Python module) serialise eigen computations themselves.
 */
#ifndef DK_EIGS_H
#define DK_EIGS_H

#include "dk_sparse.h"
#include "dk_status.h"

#ifdef __cplusplus
extern "C" {
#endif

/** Options; zero-initialise then set what you need (dk_eigs_options_default fills defaults). */
typedef struct dk_eigs_options {
    double tolerance;    /**< ARPACK relative tolerance (default 1e-10)                   */
    int max_iterations;  /**< ARPACK restarts per band (default 1000)                      */
    int band_size;       /**< eigenpairs per band (default 50; values below 16 are raised
                              to 16); k <= band_size: one band                            */
    dk_progress_fn progress; /**< may be NULL. Called after each band with the fraction of
                                  the k pairs found, and again with the same fraction every
                                  16 operator applications within a band, so that a non-zero
                                  return (cancel) takes effect within a few solves (a
                                  disconnected L: also with 0 at each inertia count, and
                                  after each component)                                     */
    void *progress_user;
} dk_eigs_options;

/** Fills the defaults. */
void dk_eigs_options_default(dk_eigs_options *opt);

/** Computes the `k` smallest eigenpairs. `eigenvalues` has k entries, `eigenvectors` is
 *  n x k column-major (eigenvector j at eigenvectors + j*n). `*n_converged` (may be NULL) gets
 *  how many pairs converged; when fewer than k did, the call fails with
 *  DK_ERR_NO_CONVERGENCE saying how many, and the converged ones are in the outputs (a
 *  disconnected L, solved by component, reports 0 on any failure; its message names the
 *  component).
 *  `mass` must be positive everywhere (an error names the first vertex where it is not).
 *  Memory (issue 19): the accepted vectors are built in `eigenvectors` itself, which is
 *  therefore written also by a call that fails. Beyond it the call holds about
 *  2 min(k, band_size) + 1 Krylov vectors (the Ritz vectors overwrite them), the band's
 *  results (about band_size + band_size / 8 vectors touched), 16 vectors of margin past the
 *  k-th pair when a cluster straddles it, and one sparse factor of L - sigma M. */
dk_status dk_eigs_smallest(const dk_sparse *l, const double *mass, int k,
                           const dk_eigs_options *opt, double *eigenvalues,
                           double *eigenvectors, int *n_converged, dk_error *err);

#ifdef __cplusplus
}
#endif
#endif
