/* Compressed sparse column matrices: see dk_sparse.h.
 *
 * Triplet assembly is a counting sort by column (one pass to count, one to scatter), then
 * each column is sorted by row (insertion sort for the short columns of mesh operators,
 * heap sort beyond that, both in place) and duplicates are summed while compacting. Linear
 * in the number of triplets for mesh matrices, with 12 bytes of scratch per triplet.
 */
#include "dk_sparse.h"

#include <math.h>
#include <stdlib.h>
#include <string.h>

int64_t dk_sparse_nnz(const dk_sparse *a)
{
    return a ? (int64_t)a->col_start[a->n_cols] : 0;
}

dk_status dk_sparse_alloc(dk_index n_rows, dk_index n_cols, int64_t nnz, dk_sparse **out,
                          dk_error *err)
{
    if (!out) return dk_error_set(err, DK_ERR_INVALID_ARGUMENT, "sparse alloc: out is NULL");
    *out = NULL;
    if (n_rows < 0 || n_cols < 0 || nnz < 0)
        return dk_error_set(err, DK_ERR_INVALID_ARGUMENT,
                            "sparse alloc: negative size (%ld x %ld, nnz %lld)", (long)n_rows,
                            (long)n_cols, (long long)nnz);
    if (nnz > INT32_MAX)
        return dk_error_set(err, DK_ERR_INVALID_ARGUMENT,
                            "sparse alloc: %lld entries exceed the 32-bit index range",
                            (long long)nnz);
    dk_sparse *a = calloc(1, sizeof *a);
    if (!a) return dk_error_set(err, DK_ERR_OUT_OF_MEMORY, "sparse alloc: out of memory");
    a->n_rows = n_rows;
    a->n_cols = n_cols;
    a->col_start = calloc((size_t)n_cols + 1, sizeof(dk_index));
    a->row_index = malloc(sizeof(dk_index) * (size_t)(nnz ? nnz : 1));
    a->values = malloc(sizeof(double) * (size_t)(nnz ? nnz : 1));
    if (!a->col_start || !a->row_index || !a->values) {
        dk_sparse_free(a);
        return dk_error_set(err, DK_ERR_OUT_OF_MEMORY,
                            "sparse alloc: out of memory for %ld x %ld with %lld entries",
                            (long)n_rows, (long)n_cols, (long long)nnz);
    }
    *out = a;
    return DK_OK;
}

void dk_sparse_free(dk_sparse *a)
{
    if (!a) return;
    free(a->col_start);
    free(a->row_index);
    free(a->values);
    free(a);
}

dk_status dk_sparse_copy(const dk_sparse *a, dk_sparse **out, dk_error *err)
{
    if (!a || !out) {
        if (out) *out = NULL;
        return dk_error_set(err, DK_ERR_INVALID_ARGUMENT, "sparse copy: NULL argument");
    }
    int64_t nnz = dk_sparse_nnz(a);
    dk_status st = dk_sparse_alloc(a->n_rows, a->n_cols, nnz, out, err);
    if (st) return st;
    memcpy((*out)->col_start, a->col_start, sizeof(dk_index) * ((size_t)a->n_cols + 1));
    if (nnz) {
        memcpy((*out)->row_index, a->row_index, sizeof(dk_index) * (size_t)nnz);
        memcpy((*out)->values, a->values, sizeof(double) * (size_t)nnz);
    }
    return DK_OK;
}

/* ------------------------------------------------------------ column sorting ------------ */

static void sift_down(dk_index *r, double *v, int64_t root, int64_t n)
{
    for (;;) {
        int64_t child = 2 * root + 1;
        if (child >= n) return;
        if (child + 1 < n && r[child + 1] > r[child]) child++;
        if (r[root] >= r[child]) return;
        dk_index tr = r[root];
        r[root] = r[child];
        r[child] = tr;
        double tv = v[root];
        v[root] = v[child];
        v[child] = tv;
        root = child;
    }
}

/* Sorts the parallel arrays (r, v) of length n by r, in place. */
static void sort_column(dk_index *r, double *v, int64_t n)
{
    if (n <= 24) {
        for (int64_t i = 1; i < n; i++) {
            dk_index kr = r[i];
            double kv = v[i];
            int64_t j = i;
            while (j > 0 && r[j - 1] > kr) {
                r[j] = r[j - 1];
                v[j] = v[j - 1];
                j--;
            }
            r[j] = kr;
            v[j] = kv;
        }
        return;
    }
    for (int64_t i = n / 2 - 1; i >= 0; i--) sift_down(r, v, i, n);
    for (int64_t end = n - 1; end > 0; end--) {
        dk_index tr = r[0];
        r[0] = r[end];
        r[end] = tr;
        double tv = v[0];
        v[0] = v[end];
        v[end] = tv;
        sift_down(r, v, 0, end);
    }
}

/* Given columns stored at [start[j], start[j+1]) of (rows, vals) in any order, sorts each,
 * sums duplicates and builds a compact matrix. Takes ownership of rows and vals (freed or
 * moved into the result on every path). */
static dk_status finish_columns(dk_index n_rows, dk_index n_cols, const int64_t *start,
                                dk_index *rows, double *vals, const char *who,
                                dk_sparse **out, dk_error *err)
{
    int64_t w = 0;
    dk_sparse *a = calloc(1, sizeof *a);
    dk_index *cs = calloc((size_t)n_cols + 1, sizeof(dk_index));
    if (!a || !cs) {
        free(a);
        free(cs);
        free(rows);
        free(vals);
        return dk_error_set(err, DK_ERR_OUT_OF_MEMORY, "%s: out of memory", who);
    }
    for (dk_index j = 0; j < n_cols; j++) {
        int64_t b = start[j], e = start[j + 1];
        sort_column(rows + b, vals + b, e - b);
        for (int64_t p = b; p < e; p++) {
            if ((int64_t)cs[j] < w && rows[w - 1] == rows[p]) {
                vals[w - 1] += vals[p];
            } else {
                if (w >= INT32_MAX) {
                    free(a);
                    free(cs);
                    free(rows);
                    free(vals);
                    return dk_error_set(err, DK_ERR_INVALID_ARGUMENT,
                                        "%s: more than %ld distinct entries", who,
                                        (long)INT32_MAX);
                }
                rows[w] = rows[p];
                vals[w] = vals[p];
                w++;
            }
        }
        cs[j + 1] = (dk_index)w; /* also the first slot of column j + 1 */
    }
    /* shrink (never fails in practice; keep the larger block if it does) */
    dk_index *r2 = realloc(rows, sizeof(dk_index) * (size_t)(w ? w : 1));
    double *v2 = realloc(vals, sizeof(double) * (size_t)(w ? w : 1));
    a->n_rows = n_rows;
    a->n_cols = n_cols;
    a->col_start = cs;
    a->row_index = r2 ? r2 : rows;
    a->values = v2 ? v2 : vals;
    *out = a;
    return DK_OK;
}

dk_status dk_sparse_from_triplets(dk_index n_rows, dk_index n_cols, int64_t n,
                                  const dk_index *rows, const dk_index *cols,
                                  const double *vals, dk_sparse **out, dk_error *err)
{
    static const char who[] = "sparse from triplets";
    if (!out) return dk_error_set(err, DK_ERR_INVALID_ARGUMENT, "%s: out is NULL", who);
    *out = NULL;
    if (n_rows < 0 || n_cols < 0 || n < 0)
        return dk_error_set(err, DK_ERR_INVALID_ARGUMENT,
                            "%s: negative size (%ld x %ld, %lld triplets)", who, (long)n_rows,
                            (long)n_cols, (long long)n);
    if (n > 0 && (!rows || !cols || !vals))
        return dk_error_set(err, DK_ERR_INVALID_ARGUMENT, "%s: NULL triplet array", who);
    for (int64_t k = 0; k < n; k++) {
        if (rows[k] < 0 || rows[k] >= n_rows || cols[k] < 0 || cols[k] >= n_cols)
            return dk_error_set(err, DK_ERR_INDEX,
                                "%s: triplet %lld is (%ld, %ld), out of range for a %ld x %ld "
                                "matrix",
                                who, (long long)k, (long)rows[k], (long)cols[k], (long)n_rows,
                                (long)n_cols);
    }
    int64_t *start = calloc((size_t)n_cols + 2, sizeof(int64_t));
    dk_index *r = malloc(sizeof(dk_index) * (size_t)(n ? n : 1));
    double *v = malloc(sizeof(double) * (size_t)(n ? n : 1));
    if (!start || !r || !v) {
        free(start);
        free(r);
        free(v);
        return dk_error_set(err, DK_ERR_OUT_OF_MEMORY, "%s: out of memory for %lld triplets",
                            who, (long long)n);
    }
    /* counting sort by column: start[j + 2] counts, then prefix sums shifted by one */
    for (int64_t k = 0; k < n; k++) start[cols[k] + 2]++;
    for (dk_index j = 0; j < n_cols; j++) start[j + 2] += start[j + 1];
    for (int64_t k = 0; k < n; k++) {
        int64_t p = start[cols[k] + 1]++;
        r[p] = rows[k];
        v[p] = vals[k];
    }
    /* now start[j] .. start[j+1] is column j */
    dk_status st = finish_columns(n_rows, n_cols, start, r, v, who, out, err);
    free(start);
    return st;
}

dk_status dk_sparse_from_columns(dk_index n_rows, dk_index n_cols, const int64_t *start,
                                 dk_index *rows, double *vals, dk_sparse **out, dk_error *err)
{
    static const char who[] = "sparse from columns";
    dk_status st = DK_OK;
    if (!out) {
        st = dk_error_set(err, DK_ERR_INVALID_ARGUMENT, "%s: out is NULL", who);
    } else {
        *out = NULL;
        if (n_rows < 0 || n_cols < 0 || !start)
            st = dk_error_set(err, DK_ERR_INVALID_ARGUMENT, "%s: negative size (%ld x %ld) or "
                              "no column starts", who, (long)n_rows, (long)n_cols);
        else if (start[0] != 0)
            st = dk_error_set(err, DK_ERR_INVALID_ARGUMENT, "%s: start[0] is %lld, not 0", who,
                              (long long)start[0]);
        else if (start[n_cols] > 0 && (!rows || !vals))
            st = dk_error_set(err, DK_ERR_INVALID_ARGUMENT, "%s: NULL entry array", who);
    }
    for (dk_index j = 0; st == DK_OK && j < n_cols; j++) {
        if (start[j + 1] < start[j]) {
            st = dk_error_set(err, DK_ERR_INVALID_ARGUMENT, "%s: start decreases at column %ld",
                              who, (long)j);
            break;
        }
        for (int64_t p = start[j]; p < start[j + 1]; p++)
            if (rows[p] < 0 || rows[p] >= n_rows) {
                st = dk_error_set(err, DK_ERR_INDEX, "%s: entry %lld of column %ld has row %ld, "
                                  "out of range for a %ld x %ld matrix", who, (long long)p,
                                  (long)j, (long)rows[p], (long)n_rows, (long)n_cols);
                break;
            }
    }
    if (st != DK_OK) {
        free(rows);
        free(vals);
        return st;
    }
    if (start[n_cols] == 0) { /* finish_columns shrinks to at least one slot */
        free(rows);
        free(vals);
        rows = malloc(sizeof(dk_index));
        vals = malloc(sizeof(double));
        if (!rows || !vals) {
            free(rows);
            free(vals);
            return dk_error_set(err, DK_ERR_OUT_OF_MEMORY, "%s: out of memory", who);
        }
    }
    return finish_columns(n_rows, n_cols, start, rows, vals, who, out, err);
}

/* ------------------------------------------------------------ products ------------------ */

void dk_sparse_matvec(const dk_sparse *a, const double *x, double *y)
{
    for (dk_index i = 0; i < a->n_rows; i++) y[i] = 0.0;
    for (dk_index j = 0; j < a->n_cols; j++) {
        double xj = x[j];
        for (dk_index p = a->col_start[j]; p < a->col_start[j + 1]; p++)
            y[a->row_index[p]] += a->values[p] * xj;
    }
}

void dk_sparse_matmat(const dk_sparse *a, const double *x, double *y, int k)
{
    for (int c = 0; c < k; c++)
        dk_sparse_matvec(a, x + (size_t)c * (size_t)a->n_cols, y + (size_t)c * (size_t)a->n_rows);
}

double dk_sparse_get(const dk_sparse *a, dk_index i, dk_index j)
{
    if (!a || j < 0 || j >= a->n_cols || i < 0 || i >= a->n_rows) return 0.0;
    dk_index lo = a->col_start[j], hi = a->col_start[j + 1];
    while (lo < hi) {
        dk_index mid = lo + (hi - lo) / 2;
        if (a->row_index[mid] < i)
            lo = mid + 1;
        else
            hi = mid;
    }
    return (lo < a->col_start[j + 1] && a->row_index[lo] == i) ? a->values[lo] : 0.0;
}

void dk_sparse_diagonal(const dk_sparse *a, double *diag)
{
    dk_index n = a->n_rows < a->n_cols ? a->n_rows : a->n_cols;
    for (dk_index j = 0; j < n; j++) diag[j] = dk_sparse_get(a, j, j);
}

/* ------------------------------------------------------------ sums ---------------------- */

/* Merges alpha * column j of a with beta * column j of b (b may be NULL: then `d` gives a
 * single diagonal entry d[j] to merge). With `write` == 0 only counts. */
static int64_t merge_column(double alpha, const dk_sparse *a, double beta, const dk_sparse *b,
                            const double *d, dk_index j, dk_index *ro, double *vo, int write)
{
    dk_index pa = a->col_start[j], ea = a->col_start[j + 1];
    dk_index pb = 0, eb = 0;
    dk_index diag_row = j;
    if (b) {
        pb = b->col_start[j];
        eb = b->col_start[j + 1];
    } else {
        eb = 1; /* one virtual entry: (j, d[j]) */
    }
    int64_t w = 0;
    while (pa < ea || pb < eb) {
        dk_index rb = pb < eb ? (b ? b->row_index[pb] : diag_row) : INT32_MAX;
        dk_index ra = pa < ea ? a->row_index[pa] : INT32_MAX;
        dk_index r = ra < rb ? ra : rb;
        double val = 0.0;
        if (ra == r) val += alpha * a->values[pa++];
        if (rb == r) {
            val += b ? beta * b->values[pb] : d[j];
            pb++;
        }
        if (write) {
            ro[w] = r;
            vo[w] = val;
        }
        w++;
    }
    return w;
}

static dk_status merge(double alpha, const dk_sparse *a, double beta, const dk_sparse *b,
                       const double *d, const char *who, dk_sparse **out, dk_error *err)
{
    int64_t total = 0;
    for (dk_index j = 0; j < a->n_cols; j++)
        total += merge_column(alpha, a, beta, b, d, j, NULL, NULL, 0);
    dk_status st = dk_sparse_alloc(a->n_rows, a->n_cols, total, out, err);
    if (st) return dk_error_prefix(err, "%s", who);
    dk_sparse *c = *out;
    int64_t w = 0;
    for (dk_index j = 0; j < a->n_cols; j++) {
        w += merge_column(alpha, a, beta, b, d, j, c->row_index + w, c->values + w, 1);
        c->col_start[j + 1] = (dk_index)w;
    }
    return DK_OK;
}

dk_status dk_sparse_add(double alpha, const dk_sparse *a, double beta, const dk_sparse *b,
                        dk_sparse **out, dk_error *err)
{
    if (!out) return dk_error_set(err, DK_ERR_INVALID_ARGUMENT, "sparse add: out is NULL");
    *out = NULL;
    if (!a || !b) return dk_error_set(err, DK_ERR_INVALID_ARGUMENT, "sparse add: NULL matrix");
    if (a->n_rows != b->n_rows || a->n_cols != b->n_cols)
        return dk_error_set(err, DK_ERR_INVALID_ARGUMENT,
                            "sparse add: shapes differ (%ld x %ld vs %ld x %ld)",
                            (long)a->n_rows, (long)a->n_cols, (long)b->n_rows,
                            (long)b->n_cols);
    return merge(alpha, a, beta, b, NULL, "sparse add", out, err);
}

dk_status dk_sparse_add_diagonal(const dk_sparse *a, const double *d, dk_sparse **out,
                                 dk_error *err)
{
    if (!out)
        return dk_error_set(err, DK_ERR_INVALID_ARGUMENT, "sparse add diagonal: out is NULL");
    *out = NULL;
    if (!a || !d)
        return dk_error_set(err, DK_ERR_INVALID_ARGUMENT, "sparse add diagonal: NULL argument");
    if (a->n_rows != a->n_cols)
        return dk_error_set(err, DK_ERR_INVALID_ARGUMENT,
                            "sparse add diagonal: matrix is %ld x %ld, not square",
                            (long)a->n_rows, (long)a->n_cols);
    return merge(1.0, a, 0.0, NULL, d, "sparse add diagonal", out, err);
}

dk_status dk_sparse_transpose(const dk_sparse *a, dk_sparse **out, dk_error *err)
{
    if (!out) return dk_error_set(err, DK_ERR_INVALID_ARGUMENT, "sparse transpose: out is NULL");
    *out = NULL;
    if (!a) return dk_error_set(err, DK_ERR_INVALID_ARGUMENT, "sparse transpose: NULL matrix");
    int64_t nnz = dk_sparse_nnz(a);
    dk_status st = dk_sparse_alloc(a->n_cols, a->n_rows, nnz, out, err);
    if (st) return dk_error_prefix(err, "sparse transpose");
    dk_sparse *t = *out;
    dk_index *next = malloc(sizeof(dk_index) * ((size_t)a->n_rows + 1));
    if (!next) {
        dk_sparse_free(t);
        *out = NULL;
        return dk_error_set(err, DK_ERR_OUT_OF_MEMORY, "sparse transpose: out of memory");
    }
    for (int64_t p = 0; p < nnz; p++) t->col_start[a->row_index[p] + 1]++;
    for (dk_index i = 0; i < a->n_rows; i++) t->col_start[i + 1] += t->col_start[i];
    memcpy(next, t->col_start, sizeof(dk_index) * (size_t)a->n_rows);
    /* visiting columns in order keeps rows sorted in the result */
    for (dk_index j = 0; j < a->n_cols; j++) {
        for (dk_index p = a->col_start[j]; p < a->col_start[j + 1]; p++) {
            dk_index q = next[a->row_index[p]]++;
            t->row_index[q] = j;
            t->values[q] = a->values[p];
        }
    }
    free(next);
    return DK_OK;
}

dk_status dk_sparse_submatrix(const dk_sparse *a, const dk_index *row_map, dk_index n_rows_out,
                              const dk_index *col_map, dk_index n_cols_out, dk_sparse **out,
                              dk_error *err)
{
    static const char who[] = "sparse submatrix";
    if (!out) return dk_error_set(err, DK_ERR_INVALID_ARGUMENT, "%s: out is NULL", who);
    *out = NULL;
    if (!a || !row_map || !col_map)
        return dk_error_set(err, DK_ERR_INVALID_ARGUMENT, "%s: NULL argument", who);
    if (n_rows_out < 0 || n_cols_out < 0)
        return dk_error_set(err, DK_ERR_INVALID_ARGUMENT, "%s: negative output size", who);
    for (dk_index i = 0; i < a->n_rows; i++)
        if (row_map[i] < -1 || row_map[i] >= n_rows_out)
            return dk_error_set(err, DK_ERR_INDEX,
                                "%s: row_map[%ld] is %ld, out of range [-1, %ld)", who, (long)i,
                                (long)row_map[i], (long)n_rows_out);
    for (dk_index j = 0; j < a->n_cols; j++)
        if (col_map[j] < -1 || col_map[j] >= n_cols_out)
            return dk_error_set(err, DK_ERR_INDEX,
                                "%s: col_map[%ld] is %ld, out of range [-1, %ld)", who, (long)j,
                                (long)col_map[j], (long)n_cols_out);
    int64_t *start = calloc((size_t)n_cols_out + 2, sizeof(int64_t));
    if (!start) return dk_error_set(err, DK_ERR_OUT_OF_MEMORY, "%s: out of memory", who);
    int64_t total = 0;
    for (dk_index j = 0; j < a->n_cols; j++) {
        if (col_map[j] < 0) continue;
        for (dk_index p = a->col_start[j]; p < a->col_start[j + 1]; p++)
            if (row_map[a->row_index[p]] >= 0) {
                start[col_map[j] + 2]++;
                total++;
            }
    }
    dk_index *r = malloc(sizeof(dk_index) * (size_t)(total ? total : 1));
    double *v = malloc(sizeof(double) * (size_t)(total ? total : 1));
    if (!r || !v) {
        free(start);
        free(r);
        free(v);
        return dk_error_set(err, DK_ERR_OUT_OF_MEMORY, "%s: out of memory", who);
    }
    for (dk_index j = 0; j < n_cols_out; j++) start[j + 2] += start[j + 1];
    for (dk_index j = 0; j < a->n_cols; j++) {
        if (col_map[j] < 0) continue;
        for (dk_index p = a->col_start[j]; p < a->col_start[j + 1]; p++) {
            dk_index ni = row_map[a->row_index[p]];
            if (ni < 0) continue;
            int64_t q = start[col_map[j] + 1]++;
            r[q] = ni;
            v[q] = a->values[p];
        }
    }
    /* maps that are not monotone (or not injective) are handled by sorting and summing */
    dk_status st = finish_columns(n_rows_out, n_cols_out, start, r, v, who, out, err);
    free(start);
    return st;
}

dk_status dk_sparse_product(const dk_sparse *a, const double *d, const dk_sparse *b,
                            dk_sparse **out, dk_error *err)
{
    static const char who[] = "sparse product";
    if (!out) return dk_error_set(err, DK_ERR_INVALID_ARGUMENT, "%s: out is NULL", who);
    *out = NULL;
    if (!a || !b) return dk_error_set(err, DK_ERR_INVALID_ARGUMENT, "%s: NULL argument", who);
    if (a->n_cols != b->n_rows)
        return dk_error_set(err, DK_ERR_INVALID_ARGUMENT, "%s: %ld columns times %ld rows", who,
                            (long)a->n_cols, (long)b->n_rows);
    const dk_index n = a->n_rows, m = b->n_cols;
    /* column j of C is the sum over b's entries (k, j) of b_kj d_k a(:, k): first count the
     * distinct rows each column reaches (a marker per row), then fill a dense accumulator */
    dk_index *mark = malloc(((size_t)n + 1) * sizeof *mark);
    double *acc = malloc(((size_t)n + 1) * sizeof *acc);
    int64_t *start = calloc((size_t)m + 1, sizeof *start);
    dk_index *rows = NULL;
    double *vals = NULL;
    if (!mark || !acc || !start) goto oom;
    for (dk_index i = 0; i < n; i++) mark[i] = -1;
    for (dk_index j = 0; j < m; j++) {
        int64_t count = 0;
        for (dk_index p = b->col_start[j]; p < b->col_start[j + 1]; p++) {
            dk_index k = b->row_index[p];
            for (dk_index q = a->col_start[k]; q < a->col_start[k + 1]; q++)
                if (mark[a->row_index[q]] != j) {
                    mark[a->row_index[q]] = j;
                    count++;
                }
        }
        start[j + 1] = start[j] + count;
        if (start[j + 1] >= INT32_MAX) {
            free(mark);
            free(acc);
            free(start);
            return dk_error_set(err, DK_ERR_INVALID_ARGUMENT, "%s: more than %ld entries", who,
                                (long)INT32_MAX);
        }
    }
    rows = malloc(((size_t)start[m] + 1) * sizeof *rows);
    vals = malloc(((size_t)start[m] + 1) * sizeof *vals);
    if (!rows || !vals) goto oom;
    for (dk_index i = 0; i < n; i++) mark[i] = -1;
    for (dk_index j = 0; j < m; j++) {
        int64_t w = start[j];
        for (dk_index p = b->col_start[j]; p < b->col_start[j + 1]; p++) {
            dk_index k = b->row_index[p];
            double f = b->values[p] * (d ? d[k] : 1.0);
            for (dk_index q = a->col_start[k]; q < a->col_start[k + 1]; q++) {
                dk_index i = a->row_index[q];
                if (mark[i] != j) {
                    mark[i] = j;
                    acc[i] = 0.0;
                    rows[w++] = i;
                }
                acc[i] += f * a->values[q];
            }
        }
        for (int64_t p = start[j]; p < w; p++) vals[p] = acc[rows[p]];
    }
    free(mark);
    free(acc);
    dk_status st = finish_columns(n, m, start, rows, vals, who, out, err);
    free(start);
    return st;
oom:
    free(mark);
    free(acc);
    free(start);
    free(rows);
    free(vals);
    return dk_error_set(err, DK_ERR_OUT_OF_MEMORY, "%s: out of memory", who);
}

double dk_sparse_asymmetry(const dk_sparse *a)
{
    double worst = 0.0;
    if (!a || a->n_rows != a->n_cols) return 0.0;
    for (dk_index j = 0; j < a->n_cols; j++) {
        for (dk_index p = a->col_start[j]; p < a->col_start[j + 1]; p++) {
            double d = fabs(a->values[p] - dk_sparse_get(a, j, a->row_index[p]));
            if (d > worst || d != d) worst = d;
        }
    }
    return worst;
}
