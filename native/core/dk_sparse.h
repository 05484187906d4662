/* DeformKit: compressed sparse column matrices and their assembly from triplets.
 *
 * The layout matches CHOLMOD's "packed, sorted" cholmod_sparse so the numerics wrappers can
 * hand it to CHOLMOD without a copy. Symmetric matrices are always stored with BOTH
 * triangles; consumers that need only one (CHOLMOD with stype = 1 reads the upper one) say so.
 */
#ifndef DK_SPARSE_H
#define DK_SPARSE_H

#include <stdint.h>

#include "dk_mesh.h"
#include "dk_status.h"

#ifdef __cplusplus
extern "C" {
#endif

/** A CSC matrix: column j holds rows row_index[col_start[j] .. col_start[j+1]-1], sorted
 *  ascending and without duplicates, with values in `values`. */
typedef struct dk_sparse {
    dk_index n_rows, n_cols;
    dk_index *col_start;   /**< n_cols + 1              */
    dk_index *row_index;   /**< nnz = col_start[n_cols] */
    double *values;        /**< nnz                     */
} dk_sparse;

/** Number of stored entries. */
int64_t dk_sparse_nnz(const dk_sparse *a);

/** Allocates an n_rows x n_cols matrix with room for `nnz` entries; col_start zeroed. */
dk_status dk_sparse_alloc(dk_index n_rows, dk_index n_cols, int64_t nnz, dk_sparse **out,
                          dk_error *err);

/** Frees a matrix; NULL is allowed. */
void dk_sparse_free(dk_sparse *a);

/** Deep copy. */
dk_status dk_sparse_copy(const dk_sparse *a, dk_sparse **out, dk_error *err);

/** Builds a CSC matrix from `n` triplets (rows[k], cols[k], vals[k]); duplicates are summed,
 *  explicit zeros are kept (so a pattern stays fixed when values change). Indices are
 *  checked against the shape. */
dk_status dk_sparse_from_triplets(dk_index n_rows, dk_index n_cols, int64_t n,
                                  const dk_index *rows, const dk_index *cols,
                                  const double *vals, dk_sparse **out, dk_error *err);

/** Builds a CSC matrix from entries already bucketed by column: column j's entries are
 *  (rows[p], vals[p]) for p in [start[j], start[j+1]), in any order, duplicates summed,
 *  explicit zeros kept. `start` has n_cols + 1 entries (start[0] = 0, non-decreasing).
 *  Takes ownership of `rows` and `vals` (both malloc'ed, start[n_cols] entries; freed or
 *  moved into the result on every path, the error paths included): the columns are sorted
 *  and compacted in place, so a caller that can count its entries per column first needs
 *  12 bytes an entry, against dk_sparse_from_triplets's 16 for the triplets plus 12 for its
 *  copy. Row indices are checked against n_rows. */
dk_status dk_sparse_from_columns(dk_index n_rows, dk_index n_cols, const int64_t *start,
                                 dk_index *rows, double *vals, dk_sparse **out, dk_error *err);

/** y = A x (y has n_rows entries, x n_cols). */
void dk_sparse_matvec(const dk_sparse *a, const double *x, double *y);

/** Y = A X for `k` right-hand sides stored column after column (X is n_cols x k and Y is
 *  n_rows x k, both column-major). */
void dk_sparse_matmat(const dk_sparse *a, const double *x, double *y, int k);

/** Returns the value stored at (i, j), 0 when not stored. O(log column length). */
double dk_sparse_get(const dk_sparse *a, dk_index i, dk_index j);

/** Writes the diagonal (min(n_rows, n_cols) entries) into `diag`. */
void dk_sparse_diagonal(const dk_sparse *a, double *diag);

/** C = alpha A + beta B for matrices of the same shape (patterns are merged). */
dk_status dk_sparse_add(double alpha, const dk_sparse *a, double beta, const dk_sparse *b,
                        dk_sparse **out, dk_error *err);

/** Adds `d[i]` to the diagonal entries of a square matrix, inserting missing ones. */
dk_status dk_sparse_add_diagonal(const dk_sparse *a, const double *d, dk_sparse **out,
                                 dk_error *err);

/** C = A diag(d) B: A is n x k, d has k entries (NULL: the identity), B is k x m; C is
 *  n x m with only the entries the product can reach (sorted columns, no duplicates). The
 *  bilaplacian K M^-1 K of bounded biharmonic weights is one. */
dk_status dk_sparse_product(const dk_sparse *a, const double *d, const dk_sparse *b,
                            dk_sparse **out, dk_error *err);

/** Transpose. */
dk_status dk_sparse_transpose(const dk_sparse *a, dk_sparse **out, dk_error *err);

/** The submatrix A(rows, cols) where rows/cols are given as maps from old to new index
 *  (-1 drops the row/column), with n_rows_out / n_cols_out entries in the result.
 *  Used for eliminating constrained vertices. */
dk_status dk_sparse_submatrix(const dk_sparse *a, const dk_index *row_map, dk_index n_rows_out,
                              const dk_index *col_map, dk_index n_cols_out, dk_sparse **out,
                              dk_error *err);

/** Largest |A - A^T| entry (0 for an exactly symmetric matrix); square matrices only. */
double dk_sparse_asymmetry(const dk_sparse *a);

#ifdef __cplusplus
}
#endif
#endif
