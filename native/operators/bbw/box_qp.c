/* DeformKit: the quadratic program of one bounded biharmonic weight function (dk_box_qp in
 * dk_bbw.h): minimise 1/2 x^T A x - b^T x subject to lo <= x <= hi, by the primal-dual
 * active-set method (Bergounioux, Ito, Kunisch 1999; Hintermueller, Ito, Kunisch 2002).
 *
 * Each variable is free, held at lo or held at hi. An iteration solves the equality-
 * constrained problem of that partition (the free variables' block A_FF, a sparse Cholesky
 * factorization, the held ones moved to the right-hand side), then reads the multipliers of
 * the held ones from the gradient g = A x - b (at lo the multiplier is g_i, at hi it is -g_i)
 * and repartitions: a free variable that left the box is held at the bound it crossed, a
 * held variable whose multiplier is negative (the energy wants it inside) is freed. When the
 * partition repeats, x is the minimiser: feasible, free gradients zero, multipliers
 * non-negative (the KKT conditions of a convex problem). On matrices that are not M-matrices
 * (the bilaplacian is not one) the method can cycle between partitions; a repeated
 * partition other than the last one switches it to the primal active-set method, which
 * cannot cycle: from the box's nearest point to the current iterate, each iteration moves
 * towards the minimiser on the working set as far as the box allows (holding the variable
 * that stops it), or, when it gets there, frees the held variables whose multipliers are
 * negative; the energy falls at every step (a variable freed that stops the very next step
 * at once had a multiplier of rounding and stays held). Thresholds are relative:
 * a variable past a bound by 1e-9 of the box, a multiplier negative by 1e-7 of its row of
 * the gradient (sum_j |A_ij| (hi - lo) + |b_i|).
 */
#include <math.h>
#include <stdint.h>
#include <stdlib.h>
#include <string.h>

#include "bbw_internal.h"
#include "dk_cholesky.h"

enum { QP_FREE = 0, QP_LOW = 1, QP_HIGH = 2 };


/* A 64-bit fingerprint of a partition, to notice a cycle. */
static uint64_t partition_hash(const unsigned char *state, dk_index m)
{
    uint64_t h = 1469598103934665603ull;
    for (dk_index i = 0; i < m; i++) {
        h ^= (uint64_t)state[i] + 1u;
        h *= 1099511628211ull;
    }
    return h;
}

/* Solves the equality-constrained problem of `state`: x held at lo / hi, the free block
 * A_FF x_F = b_F - A_F,held x_held. */
static dk_status solve_partition(const dk_sparse *a, const double *b, double lo, double hi,
                                 const unsigned char *state, double *x, dk_index *map,
                                 double *rhs, int simplicial, dk_error *err)
{
    const dk_index m = a->n_rows;
    dk_index nf = 0;
    for (dk_index i = 0; i < m; i++) {
        map[i] = state[i] == QP_FREE ? nf++ : -1;
        if (state[i] == QP_LOW) x[i] = lo;
        else if (state[i] == QP_HIGH) x[i] = hi;
    }
    if (nf == 0)
        return DK_OK;
    for (dk_index i = 0; i < m; i++)
        if (map[i] >= 0) rhs[map[i]] = b[i];
    for (dk_index j = 0; j < m; j++) {
        if (map[j] >= 0 || x[j] == 0.0) continue;
        for (dk_index p = a->col_start[j]; p < a->col_start[j + 1]; p++) {
            dk_index i = map[a->row_index[p]];
            if (i >= 0) rhs[i] -= a->values[p] * x[j];
        }
    }
    dk_sparse *sub = NULL;
    dk_cholesky *chol = NULL;
    dk_status st = dk_sparse_submatrix(a, map, nf, map, nf, &sub, err);
    if (st == DK_OK)
        st = simplicial ? dk_cholesky_analyze_simplicial(sub, &chol, err)
                        : dk_cholesky_analyze(sub, &chol, err);
    if (st == DK_OK) st = dk_cholesky_factorize(chol, sub, err);
    if (st == DK_OK) st = dk_cholesky_solve(chol, rhs, 1, rhs, err);
    if (st == DK_OK)
        for (dk_index i = 0; i < m; i++)
            if (map[i] >= 0) x[i] = rhs[map[i]];
    dk_cholesky_free(chol);
    dk_sparse_free(sub);
    return st;
}

dk_status dk_box_qp(const dk_sparse *a, const double *b, double lo, double hi, double *x,
                    int max_iterations, int *iterations, double *kkt_residual, dk_error *err)
{
    return bbw_box_qp(a, b, lo, hi, x, 0, 0, max_iterations, iterations, kkt_residual, err);
}

dk_status bbw_box_qp(const dk_sparse *a, const double *b, double lo, double hi, double *x,
                     int start_solves, int simplicial, int max_iterations, int *iterations,
                     double *kkt_residual, dk_error *err)
{
    static const char who[] = "bounded quadratic program";
    if (iterations) *iterations = 0;
    if (kkt_residual) *kkt_residual = 0.0;
    if (!a || !b || !x || a->n_rows != a->n_cols || max_iterations < 1)
        return dk_error_set(err, DK_ERR_INVALID_ARGUMENT,
                            "%s: needs a square matrix, b, x and max_iterations >= 1", who);
    if (!(isfinite(lo) && isfinite(hi) && lo < hi))
        return dk_error_set(err, DK_ERR_INVALID_ARGUMENT, "%s: bounds [%g, %g] are not an "
                            "interval", who, lo, hi);
    const dk_index m = a->n_rows;
    if (m == 0)
        return DK_OK;
    unsigned char *state = malloc((size_t)m), *next = malloc((size_t)m);
    dk_index *map = malloc((size_t)m * sizeof *map);
    double *rhs = malloc((size_t)m * sizeof *rhs), *g = malloc((size_t)m * sizeof *g);
    double *diag = malloc((size_t)m * sizeof *diag); /* each row's scale */
    double *xf = malloc((size_t)m * sizeof *xf); /* the primal method's feasible point */
    unsigned char *keep_held = calloc((size_t)m, 1), *just_freed = calloc((size_t)m, 1);
    uint64_t *seen = malloc((size_t)(max_iterations + 1) * sizeof *seen);
    dk_status st = DK_OK;
    if (!state || !next || !map || !rhs || !g || !diag || !xf || !keep_held || !just_freed || !seen) {
        st = dk_error_set(err, DK_ERR_OUT_OF_MEMORY, "%s: out of memory", who);
        goto done;
    }
    /* scales: a variable is past a bound by more than rounding; a multiplier is negative
     * by more than the rounding of its row of the gradient A x - b, whose size is
     * row[i] = sum_j |A_ij| (hi - lo) + |b_i| (per row: the bilaplacian's rows differ by
     * orders of magnitude between big and small elements, and one scale for all let small
     * rows keep multipliers that were really negative: a different, wrong minimiser) */
    for (dk_index i = 0; i < m; i++) {
        if (!isfinite(b[i]) || !isfinite(x[i])) {
            st = dk_error_set(err, DK_ERR_NONFINITE, "%s: entry %ld of b or x is not finite",
                              who, (long)i);
            goto done;
        }
        diag[i] = fabs(b[i]);
    }
    for (dk_index j = 0; j < m; j++)
        for (dk_index p = a->col_start[j]; p < a->col_start[j + 1]; p++)
            diag[a->row_index[p]] += fabs(a->values[p]) * (hi - lo);
    for (dk_index i = 0; i < m; i++)
        if (!(diag[i] > 0.0)) diag[i] = 1.0;
    double *row = diag;
    const double xtol = 1e-9 * (hi - lo), gtol = 1e-7;
    for (dk_index i = 0; i < m; i++)
        state[i] = x[i] <= lo + xtol ? QP_LOW : x[i] >= hi - xtol ? QP_HIGH : QP_FREE;
    int it = 0, primal = 0, settled = 0, all_free = 1;
    for (dk_index i = 0; i < m; i++) all_free &= state[i] == QP_FREE;
    while (it < max_iterations) {
        seen[it] = partition_hash(state, m);
        /* a start that solves the all-free problem and stays in the box is its own first
         * iteration (the weights of a cage, usually: no factorization per handle) */
        if (!(it == 0 && start_solves && all_free))
            st = solve_partition(a, b, lo, hi, state, x, map, rhs, simplicial, err);
        it++;
        if (st != DK_OK) goto done;
        if (primal) {
            /* from the feasible xf towards x, the minimiser on the working set, as far as
             * the box allows; a variable that stops the step is held where it stopped */
            double step = 1.0;
            dk_index block = -1;
            for (dk_index i = 0; i < m; i++) {
                if (state[i] != QP_FREE) continue;
                double t = x[i] < lo ? (xf[i] - lo) / (xf[i] - x[i])
                           : x[i] > hi ? (hi - xf[i]) / (x[i] - xf[i]) : 1.0;
                if (t < step) step = t, block = i;
            }
            for (dk_index i = 0; i < m; i++) xf[i] += step * (x[i] - xf[i]);
            if (block >= 0) {
                /* a variable just freed that stops the step at once: its multiplier was
                 * rounding (the bilaplacian's solves carry errors of ~1e-5 of a row on
                 * fine volumes), not a descent; it stays held from now on */
                if (step == 0.0 && just_freed[block]) keep_held[block] = 1;
                state[block] = x[block] < lo ? QP_LOW : QP_HIGH;
                xf[block] = x[block] < lo ? lo : hi;
                memset(just_freed, 0, (size_t)m);
                continue;
            }
            memset(just_freed, 0, (size_t)m);
            memcpy(x, xf, (size_t)m * sizeof *x);
        }
        dk_sparse_matvec(a, x, g);
        dk_index changes = 0;
        for (dk_index i = 0; i < m; i++) {
            g[i] -= b[i];
            next[i] = state[i];
            if (state[i] == QP_FREE) {
                if (x[i] < lo - xtol) next[i] = QP_LOW;
                else if (x[i] > hi + xtol) next[i] = QP_HIGH;
            } else {
                /* the held variable's multiplier, negative: the energy wants it inside */
                double v = (state[i] == QP_LOW ? -g[i] : g[i]) / row[i];
                if (v > gtol && !keep_held[i]) next[i] = QP_FREE;
            }
            changes += next[i] != state[i];
        }
        if (changes == 0) {
            settled = 1;
            break;
        }
        if (primal) { /* the held variables with negative multipliers freed: the step
                       * towards the larger face's minimiser lowers the energy */
            for (dk_index i = 0; i < m; i++)
                if (state[i] != QP_FREE && next[i] == QP_FREE) {
                    state[i] = QP_FREE;
                    just_freed[i] = 1;
                }
            continue;
        }
        uint64_t h = partition_hash(next, m);
        for (int k = 0; k + 1 < it && !primal; k++)
            primal = seen[k] == h;
        if (!primal) {
            memcpy(state, next, (size_t)m);
            continue;
        }
        /* a cycle: the primal method from the box's nearest point to x, holding the
         * variables it puts on a bound */
        for (dk_index i = 0; i < m; i++) {
            xf[i] = fmin(hi, fmax(lo, x[i]));
            state[i] = xf[i] <= lo ? QP_LOW : xf[i] >= hi ? QP_HIGH : QP_FREE;
        }
    }
    if (!settled) {
        st = dk_error_set(err, DK_ERR_NO_CONVERGENCE, "%s: the active set of %ld variables has "
                          "not settled in %d iterations", who, (long)m, max_iterations);
        goto done;
    }
    double worst = 0.0;
    for (dk_index i = 0; i < m; i++) {
        double r = state[i] == QP_FREE ? fmax(fabs(g[i]) / row[i],
                                              fmax(lo - x[i], x[i] - hi) / (hi - lo))
                   : state[i] == QP_LOW ? fmax(0.0, -g[i]) / row[i]
                                        : fmax(0.0, g[i]) / row[i];
        worst = fmax(worst, r);
        x[i] = fmin(hi, fmax(lo, x[i]));
    }
    if (iterations) *iterations = it;
    if (kkt_residual) *kkt_residual = worst;
done:
    free(state);
    free(next);
    free(map);
    free(rhs);
    free(g);
    free(diag);
    free(xf);
    free(keep_held);
    free(just_freed);
    free(seen);
    return st;
}
