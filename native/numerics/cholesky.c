/* DeformKit: sparse Cholesky with CHOLMOD (see dk_cholesky.h).
 *
 * One cholmod_common per object, so objects are independent of one another (no global
 * state). The input dk_sparse is handed to CHOLMOD as a cholmod_sparse *view* (no copy):
 * dk_sparse is CSC, packed, sorted, int indices, real doubles, which is exactly CHOLMOD's
 * layout; stype = 1 makes CHOLMOD read only the upper triangle. The pattern given to analyze
 * is kept so that factorize can refuse a matrix whose pattern differs (a silent mismatch
 * would factor garbage). Solves go through cholmod_solve2 with the workspaces Y and E and
 * the result X owned by the object, so repeated solves with the same nrhs do not allocate.
 */
#include "dk_cholesky.h"

#include <cholmod.h>
#include <math.h>
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "dk_memory.h"
#include "dk_trisolve.h"

_Static_assert(sizeof(dk_index) == sizeof(int), "dk_index must match CHOLMOD_INT (int)");

struct dk_cholesky {
    cholmod_common common;
    int common_started;
    int indefinite;          /* simplicial LDL' for symmetric indefinite matrices */
    cholmod_factor *factor;  /* symbolic after analyze, numeric after factorize    */
    int factored;            /* the last factorize succeeded                       */
    cholmod_dense *x;        /* solve result (n x nrhs), kept between solves        */
    cholmod_dense *y;        /* cholmod_solve2 workspaces                          */
    cholmod_dense *e;
    dk_index n;
    dk_index *pattern_start; /* copy of the analysed pattern (n + 1)                */
    dk_index *pattern_index; /* nnz                                               */
    int n_factorizations;
    int n_analyses;
    dk_trisolve *plan;       /* two-thread substitutions for big factors, or NULL       */
    dk_team *team;           /* helper thread for the plan's solves (not owned), or NULL */
    int use_plan;            /* 0: always cholmod_solve2; 1: plans when worthwhile;
                                2: plans for any factor (tests)                        */
};

/* A read-only CHOLMOD view of `a` (CHOLMOD does not write through it). */
static cholmod_sparse sparse_view(const dk_sparse *a)
{
    cholmod_sparse v;
    memset(&v, 0, sizeof v);
    v.nrow = (size_t)a->n_rows;
    v.ncol = (size_t)a->n_cols;
    v.nzmax = (size_t)a->col_start[a->n_cols];
    v.p = (void *)a->col_start;
    v.i = (void *)a->row_index;
    v.nz = NULL;
    v.x = (void *)a->values;
    v.z = NULL;
    v.stype = 1;
    v.itype = CHOLMOD_INT;
    v.xtype = CHOLMOD_REAL;
    v.dtype = CHOLMOD_DOUBLE;
    v.sorted = 1;
    v.packed = 1;
    return v;
}

/* Maps CHOLMOD's status after a failed call to a dk_status with context. */
static dk_status cholmod_failure(const cholmod_common *c, const char *what, dk_error *err)
{
    if (c->status == CHOLMOD_OUT_OF_MEMORY)
        return dk_error_set(err, DK_ERR_OUT_OF_MEMORY, "%s: CHOLMOD ran out of memory", what);
    if (c->status == CHOLMOD_TOO_LARGE)
        return dk_error_set(err, DK_ERR_OUT_OF_MEMORY, "%s: problem too large for CHOLMOD",
                            what);
    return dk_error_set(err, DK_ERR_NUMERIC, "%s: CHOLMOD failed with status %d", what,
                        c->status);
}

/* Checks shape, CSC invariants that CHOLMOD relies on, and finiteness. */
static dk_status check_matrix(const dk_sparse *a, const char *what, dk_error *err)
{
    if (!a || !a->col_start)
        return dk_error_set(err, DK_ERR_INVALID_ARGUMENT, "%s: matrix is NULL", what);
    if (a->n_rows != a->n_cols || a->n_rows < 1)
        return dk_error_set(err, DK_ERR_INVALID_ARGUMENT,
                            "%s: matrix must be square and non-empty, got %d x %d", what,
                            (int)a->n_rows, (int)a->n_cols);
    const dk_index n = a->n_cols;
    if (a->col_start[0] != 0)
        return dk_error_set(err, DK_ERR_INVALID_ARGUMENT, "%s: col_start[0] is %d, not 0",
                            what, (int)a->col_start[0]);
    for (dk_index j = 0; j < n; j++) {
        const dk_index p0 = a->col_start[j], p1 = a->col_start[j + 1];
        if (p1 < p0)
            return dk_error_set(err, DK_ERR_INVALID_ARGUMENT,
                                "%s: col_start decreases at column %d", what, (int)j);
        for (dk_index p = p0; p < p1; p++) {
            const dk_index i = a->row_index[p];
            if (i < 0 || i >= n)
                return dk_error_set(err, DK_ERR_INDEX,
                                    "%s: column %d has row index %d, out of range [0, %d)",
                                    what, (int)j, (int)i, (int)n);
            if (p > p0 && i <= a->row_index[p - 1])
                return dk_error_set(err, DK_ERR_INVALID_ARGUMENT,
                                    "%s: column %d rows are not sorted/unique at row %d", what,
                                    (int)j, (int)i);
            if (a->values && !isfinite(a->values[p]))
                return dk_error_set(err, DK_ERR_NONFINITE,
                                    "%s: entry (%d, %d) is not finite", what, (int)i, (int)j);
        }
    }
    if (!a->values && a->col_start[n] > 0)
        return dk_error_set(err, DK_ERR_INVALID_ARGUMENT, "%s: matrix has no values", what);
    return DK_OK;
}

/* `compact`: supernodes amalgamated without explicit zeros (see dk_cholesky_analyze_compact) */
static dk_status analyze(const dk_sparse *a, int indefinite, int compact, int simplicial,
                         dk_cholesky **out, dk_error *err)
{
    if (!out) return dk_error_set(err, DK_ERR_INVALID_ARGUMENT, "Cholesky analyze: out is NULL");
    *out = NULL;
    dk_status st = check_matrix(a, "Cholesky analyze", err);
    if (st != DK_OK) return st;

    dk_cholesky *ch = calloc(1, sizeof *ch);
    if (!ch) return dk_error_set(err, DK_ERR_OUT_OF_MEMORY, "Cholesky analyze: out of memory");
    const dk_index n = a->n_cols;
    const size_t nnz = (size_t)a->col_start[n];
    ch->n = n;
    ch->indefinite = indefinite;
    ch->use_plan = 1;
    ch->pattern_start = malloc(((size_t)n + 1) * sizeof(dk_index));
    ch->pattern_index = malloc((nnz ? nnz : 1) * sizeof(dk_index));
    if (!ch->pattern_start || !ch->pattern_index) {
        dk_cholesky_free(ch);
        return dk_error_set(err, DK_ERR_OUT_OF_MEMORY, "Cholesky analyze: out of memory");
    }
    memcpy(ch->pattern_start, a->col_start, ((size_t)n + 1) * sizeof(dk_index));
    memcpy(ch->pattern_index, a->row_index, nnz * sizeof(dk_index));

    cholmod_common *c = &ch->common;
    if (!cholmod_start(c)) {
        dk_cholesky_free(ch);
        return dk_error_set(err, DK_ERR_INTERNAL, "Cholesky analyze: cholmod_start failed");
    }
    ch->common_started = 1;
    c->print = 0;             /* never print */
    c->error_handler = NULL;  /* failures come back through c->status */
    if (indefinite) {
        /* Supernodal factorization is LL' only; LDL' (no pivoting) needs the simplicial
         * path. Keep the factor as LDL' so that D carries the inertia. */
        c->supernodal = CHOLMOD_SIMPLICIAL;
        c->final_ll = 0;
    } else {
        /* Simplicial or supernodal by the flop count per factor entry. Measured (2 cores,
         * AMD ordering): on surface meshes up to ~60k vertices (armadillo 43k: fl/lnz = 71,
         * ogre 62k: 45) simplicial LL' factorizes ~2x faster (0.038 s vs 0.075 s) and
         * solves ~3x faster (3-RHS 3.3 ms vs 12 ms) than supernodal, whose small fronts
         * waste the BLAS calls; from a 160k-vertex grid on (fl/lnz = 216) supernodal is 2x
         * faster to factorize and 4x on 640k. CHOLMOD's own switch is 40; 100 fits meshes. */
        c->supernodal = simplicial ? CHOLMOD_SIMPLICIAL : CHOLMOD_AUTO;
        c->supernodal_switch = 100.0;
        c->final_ll = 1;
    }
    /* Ordering: a single AMD run. On mesh Laplacians METIS/NESDIS give a similar factor
     * (armadillo: lnz 0.99M vs 0.98M with AMD) but analyse 5-8x slower (0.2 s vs 0.03 s);
     * only past ~500k vertices does METIS's smaller factor pay for its analysis. */
    c->nmethods = 1;
    c->method[0].ordering = CHOLMOD_AMD;
    c->postorder = 1;
    if (compact) {
        /* CHOLMOD's relaxed amalgamation merges supernodes while the zeros it adds stay
         * under zrelax = 0.8 / 0.1 / 0.05 of a supernode of up to 4 / 16 / 48 columns. On
         * LinearReconstruction's system (62k ogre) that stores 23.2M entries for the 16.4M
         * of L (+41%); with no zeros allowed beyond the unconditional merges of up to
         * nrelax[0] = 4 columns, 18.7M (+14%), in the same factorization time. */
        c->zrelax[0] = c->zrelax[1] = c->zrelax[2] = 0.0;
    }

    cholmod_sparse view = sparse_view(a);
    ch->factor = cholmod_analyze(&view, c);
    if (!ch->factor) {
        st = cholmod_failure(c, "Cholesky analyze", err);
        dk_cholesky_free(ch);
        return st;
    }
    ch->n_analyses = 1;
    *out = ch;
    return DK_OK;
}

dk_status dk_cholesky_analyze(const dk_sparse *a, dk_cholesky **out, dk_error *err)
{
    return analyze(a, 0, 0, 0, out, err);
}

dk_status dk_cholesky_analyze_compact(const dk_sparse *a, dk_cholesky **out, dk_error *err)
{
    return analyze(a, 0, 1, 0, out, err);
}

dk_status dk_cholesky_analyze_indefinite(const dk_sparse *a, dk_cholesky **out,
                                         dk_error *err)
{
    return analyze(a, 1, 0, 0, out, err);
}

int dk_cholesky_is_supernodal(const dk_cholesky *chol)
{
    return chol && chol->factor && chol->factor->is_super;
}

dk_status dk_cholesky_analyze_simplicial(const dk_sparse *a, dk_cholesky **out, dk_error *err)
{
    return analyze(a, 0, 0, 1, out, err);
}

dk_status dk_cholesky_factorize(dk_cholesky *chol, const dk_sparse *a, dk_error *err)
{
    if (!chol)
        return dk_error_set(err, DK_ERR_INVALID_ARGUMENT, "Cholesky factorize: object is NULL");
    chol->factored = 0;
    dk_status st = check_matrix(a, "Cholesky factorize", err);
    if (st != DK_OK) return st;
    const dk_index n = chol->n;
    if (a->n_cols != n)
        return dk_error_set(err, DK_ERR_INVALID_ARGUMENT,
                            "Cholesky factorize: matrix is %d x %d but %d x %d was analysed",
                            (int)a->n_rows, (int)a->n_cols, (int)n, (int)n);
    if (memcmp(a->col_start, chol->pattern_start, ((size_t)n + 1) * sizeof(dk_index)) != 0 ||
        memcmp(a->row_index, chol->pattern_index,
               (size_t)a->col_start[n] * sizeof(dk_index)) != 0)
        return dk_error_set(err, DK_ERR_INVALID_ARGUMENT,
                            "Cholesky factorize: sparsity pattern differs from the one analysed");

    cholmod_common *c = &chol->common;
    if (chol->factor->xtype == CHOLMOD_PATTERN) {
        /* The first numeric factorization allocates the factor (known from the symbolic
         * analysis: nnz(L) entries, or xsize for a supernodal one) and the BLAS's buffers:
         * refused here, before allocating, when it cannot fit (issue 18, class 4; under
         * RLIMIT_AS OpenBLAS's allocator would retry forever). Later factorizations reuse
         * the factor's memory. */
        const cholmod_factor *L = chol->factor;
        const double entries = L->is_super ? (double)L->xsize : c->lnz;
        const double need = entries * (sizeof(double) + sizeof(dk_index)) * 2.0 /* the
                            factor and the two-thread solve plan's copy */
                            + (L->is_super ? (double)L->maxcsize * sizeof(double) : 0.0) +
                            (double)n * 64.0;
        char what[96];
        snprintf(what, sizeof what, "the factorization (n = %d, nnz(L) = %.0f)", (int)n,
                 entries);
        st = dk_memory_check((uint64_t)need, "Cholesky factorize", what, err);
        if (st != DK_OK) return st;
    }
    cholmod_sparse view = sparse_view(a);
    dk_trisolve_free(chol->plan); /* it points into the factor's arrays */
    chol->plan = NULL;
    dk_openmp_serial omp;
    dk_openmp_serial_begin(&omp); /* CHOLMOD's small OpenMP regions, on few CPUs */
    const int ok = cholmod_factorize(&view, chol->factor, c);
    dk_openmp_serial_end(&omp);
    chol->n_factorizations++;
    if (!ok || c->status < CHOLMOD_OK) return cholmod_failure(c, "Cholesky factorize", err);
    if (c->status == CHOLMOD_NOT_POSDEF || chol->factor->minor < (size_t)n) {
        const size_t k = chol->factor->minor;
        const int *perm = chol->factor->Perm;
        const long col = (perm && k < (size_t)n) ? (long)perm[k] : (long)k;
        /* Entries so large that the elimination overflows are no loss of positivity: say
         * what it is (the inputs beyond what double precision carries), not "not positive
         * definite", which sends the caller looking for degenerate triangles. */
        double largest = 0.0;
        for (int64_t p = 0; p < (int64_t)a->col_start[n]; p++)
            if (fabs(a->values[p]) > largest)
                largest = fabs(a->values[p]);
        if (largest > 1e150)
            return dk_error_set(err, DK_ERR_NONFINITE,
                                "Cholesky factorize: the elimination overflowed (matrix entries "
                                "up to %g): coordinates, weights or stiffness too large for "
                                "double precision", largest);
        if (chol->indefinite)
            dk_error_set(err, DK_ERR_NOT_POSITIVE_DEFINITE,
                         "Cholesky factorize: zero or NaN pivot %zu of %d in LDL' "
                         "(matrix column %ld): the matrix is singular", k, (int)n, col);
        else
            dk_error_set(err, DK_ERR_NOT_POSITIVE_DEFINITE,
                         "Cholesky factorize: matrix is not positive definite: positivity "
                         "lost at pivot %zu of %d (matrix column %ld)", k, (int)n, col);
        if (err)
            err->column = col + 1; /* for the caller to name its own vertex */
        return DK_ERR_NOT_POSITIVE_DEFINITE;
    }
    chol->factored = 1;
    /* NULL (small factor, no gain, no memory): solves use cholmod_solve2 */
    chol->plan = chol->use_plan == 2 ? dk_trisolve_plan(chol->factor, 0.0, 0.0)
                                     : dk_trisolve_plan(chol->factor, 200000.0, 1.25);
    return DK_OK;
}

/* Makes sure `*d` is an n x ncol dense real matrix, reallocating only when the shape
 * changes. */
static int ensure_dense(cholmod_dense **d, size_t n, size_t ncol, cholmod_common *c)
{
    if (*d && (*d)->nrow == n && (*d)->ncol == ncol && (*d)->d == n) return 1;
    if (*d) cholmod_free_dense(d, c);
    *d = cholmod_allocate_dense(n, ncol, n, CHOLMOD_REAL, c);
    return *d != NULL;
}

dk_status dk_cholesky_solve(dk_cholesky *chol, const double *b, int nrhs, double *x,
                            dk_error *err)
{
    if (!chol || !b || !x)
        return dk_error_set(err, DK_ERR_INVALID_ARGUMENT, "Cholesky solve: NULL argument");
    if (nrhs < 1)
        return dk_error_set(err, DK_ERR_INVALID_ARGUMENT,
                            "Cholesky solve: nrhs is %d, must be >= 1", nrhs);
    if (!chol->factored)
        return dk_error_set(err, DK_ERR_INVALID_ARGUMENT,
                            "Cholesky solve: no successful numeric factorization");
    if (chol->plan && chol->use_plan && dk_trisolve_solve(chol->plan, chol->team, b, nrhs, x) == 0)
        return DK_OK;
    cholmod_common *c = &chol->common;
    const size_t n = (size_t)chol->n;
    /* X is kept with the shape of the last solve so cholmod_solve2 reuses it. */
    if (!ensure_dense(&chol->x, n, (size_t)nrhs, c))
        return cholmod_failure(c, "Cholesky solve", err);

    cholmod_dense bview;
    memset(&bview, 0, sizeof bview);
    bview.nrow = n;
    bview.ncol = (size_t)nrhs;
    bview.nzmax = n * (size_t)nrhs;
    bview.d = n;
    bview.x = (void *)b;
    bview.z = NULL;
    bview.xtype = CHOLMOD_REAL;
    bview.dtype = CHOLMOD_DOUBLE;

    cholmod_dense *xd = chol->x;
    if (!cholmod_solve2(CHOLMOD_A, chol->factor, &bview, NULL, &xd, NULL, &chol->y, &chol->e,
                        c)) {
        chol->x = xd;
        return cholmod_failure(c, "Cholesky solve", err);
    }
    chol->x = xd;
    /* Copy out (this is what lets x alias b: b has been fully read by now). */
    memcpy(x, xd->x, n * (size_t)nrhs * sizeof(double));
    return DK_OK;
}

dk_index dk_cholesky_size(const dk_cholesky *chol)
{
    return chol ? chol->n : 0;
}

int dk_cholesky_factorization_count(const dk_cholesky *chol)
{
    return chol ? chol->n_factorizations : 0;
}

int dk_cholesky_analysis_count(const dk_cholesky *chol)
{
    return chol ? chol->n_analyses : 0;
}

void dk_cholesky_set_parallel(dk_cholesky *chol, int on)
{
    if (chol) chol->use_plan = on == 2 ? 2 : on != 0;
}

void dk_cholesky_set_team(dk_cholesky *chol, dk_team *team)
{
    if (chol) chol->team = team;
}

double dk_cholesky_parallel_speedup(const dk_cholesky *chol)
{
    return chol && chol->plan ? dk_trisolve_balance(chol->plan) : 0.0;
}

size_t dk_cholesky_memory(const dk_cholesky *chol)
{
    if (!chol) return 0;
    size_t bytes = sizeof *chol;
    bytes += ((size_t)chol->n + 1) * sizeof(dk_index);
    bytes += (size_t)chol->pattern_start[chol->n] * sizeof(dk_index);
    if (chol->common_started) bytes += chol->common.memory_inuse;
    bytes += dk_trisolve_bytes(chol->plan);
    return bytes;
}

/* a's diagonal entry (i, i), 0 when not stored */
static double diagonal_entry(const dk_sparse *a, dk_index i)
{
    dk_index lo = a->col_start[i], hi = a->col_start[i + 1] - 1;
    while (lo <= hi) {
        const dk_index mid = lo + (hi - lo) / 2;
        if (a->row_index[mid] == i) return a->values[mid];
        if (a->row_index[mid] < i) lo = mid + 1;
        else hi = mid - 1;
    }
    return 0.0;
}

double dk_cholesky_min_pivot_ratio(const dk_cholesky *chol, const dk_sparse *a)
{
    if (!chol || !chol->factored || !a || a->n_cols != chol->n) return 0.0;
    const cholmod_factor *L = chol->factor;
    const int *perm = L->Perm;
    const double *x = L->x;
    double worst = INFINITY;
    for (dk_index j = 0; j < chol->n; j++) {
        double pivot;
        if (L->is_super) { /* column j of its supernode s: the diagonal of the dense block */
            const int *super = L->super, *pi = L->pi, *px = L->px;
            size_t lo = 0, hi = L->nsuper - 1;
            while (lo < hi) { /* the supernode holding column j */
                const size_t mid = (lo + hi + 1) / 2;
                if (super[mid] <= j) lo = mid;
                else hi = mid - 1;
            }
            const int k = j - super[lo];
            pivot = x[px[lo] + (size_t)k * (size_t)(pi[lo + 1] - pi[lo]) + k];
            pivot *= pivot; /* supernodal factors are LL' */
        } else {
            pivot = x[((const int *)L->p)[j]];
            if (L->is_ll) pivot *= pivot;
        }
        const double d = diagonal_entry(a, perm ? (dk_index)perm[j] : j);
        if (!(d > 0.0)) return 0.0;
        worst = fmin(worst, pivot / d);
    }
    return worst == INFINITY ? 0.0 : worst;
}

dk_status dk_cholesky_negative_pivots(const dk_cholesky *chol, dk_index *count, dk_error *err)
{
    if (!chol || !count)
        return dk_error_set(err, DK_ERR_INVALID_ARGUMENT, "Cholesky inertia: NULL argument");
    *count = 0;
    if (!chol->factored)
        return dk_error_set(err, DK_ERR_INVALID_ARGUMENT,
                            "Cholesky inertia: no successful numeric factorization");
    const cholmod_factor *f = chol->factor;
    if (!chol->indefinite || f->is_ll) return DK_OK; /* LL' exists: positive definite */
    if (f->is_super)
        return dk_error_set(err, DK_ERR_INTERNAL, "Cholesky inertia: unexpected supernodal LDL'");
    const int *p = f->p;
    const double *lx = f->x;
    dk_index neg = 0;
    for (size_t j = 0; j < f->n; j++)
        if (lx[p[j]] < 0) neg++; /* D(j,j) is stored first in column j of a simplicial LDL' */
    *count = neg;
    return DK_OK;
}

void dk_cholesky_free(dk_cholesky *chol)
{
    if (!chol) return;
    dk_trisolve_free(chol->plan);
    if (chol->common_started) {
        cholmod_common *c = &chol->common;
        if (chol->factor) cholmod_free_factor(&chol->factor, c);
        if (chol->x) cholmod_free_dense(&chol->x, c);
        if (chol->y) cholmod_free_dense(&chol->y, c);
        if (chol->e) cholmod_free_dense(&chol->e, c);
        cholmod_finish(c);
    }
    free(chol->pattern_start);
    free(chol->pattern_index);
    free(chol);
}
