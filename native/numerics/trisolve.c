/* DeformKit: two-thread triangular solves with a CHOLMOD factor (see dk_trisolve.h).
 *
 * Plan. Every column j of L is a node of the elimination tree, parent(j) = the smallest
 * off-diagonal row of column j. CHOLMOD postorders the tree (dk_cholesky asks for it), so the
 * subtree of j is the column range [first(j), j]; the plan checks this and gives up
 * otherwise. The split is searched greedily: start from the roots (consecutive small ones
 * merged into one item), repeatedly replace the heaviest item by the children of its subtree
 * root (the root and any single-child chain below it move to the top part), and after each
 * step assign the items to two threads by decreasing work (longest processing time first);
 * keep the split with the shortest critical path max(thread work) + top work. Work = factor
 * entries, which is what both substitutions stream through.
 */
#include "dk_trisolve.h"
#include "dk_parallel.h"

#include <stdint.h>
#include <stdlib.h>
#include <string.h>

#define MAX_ITEMS 512
#define MAX_EXPANSIONS 256

/* Columns [j0, j1) of one top supernode whose first column is k1 (its row count is
 * len[k1]): the substitutions split the rows below the block between the threads. */
typedef struct top_panel {
    int j0, j1, k1;
} top_panel;

/* Top supernodes are cut into blocks of PANEL_COLS columns; a block goes to two threads when
 * the entries below it are at least PANEL_MIN_WORK (a hand-off costs a few microseconds,
 * ~2,000 entries' worth). */
#define PANEL_COLS 64
#define PANEL_MIN_WORK 16384.0

struct dk_trisolve {
    int n;
    int ll;                 /* 1: L L'; 0: L D L' (unit L, D_j stored as the diagonal)   */
    const int **rows;       /* n: row list of column j, rows[j][0] == j                   */
    const double **vals;    /* n: values of column j, vals[j][0] = L_jj or D_j            */
    int *len;               /* n: entries of column j                                     */
    const int *perm;        /* n or NULL: row k of L is row perm[k] of A                  */
    int *ranges;            /* [start, end) pairs: thread 0's, then thread 1's, ascending  */
    int n_ranges[2];
    int *top;               /* the other columns, ascending                               */
    int n_top;
    double total_work, critical_work;
    double *wa, *wb;        /* n x cap row-major work of thread 0 and thread 1            */
    int cap;
    top_panel *panels;      /* blocks of big top supernodes done on two threads, ascending */
    int n_panels;
};

typedef struct item {
    int start, end; /* column range [start, end) */
    int node;       /* the subtree root (end - 1) when expandable, else -1 */
    double work;
} item;

void dk_trisolve_free(dk_trisolve *p)
{
    if (!p)
        return;
    free(p->rows);
    free(p->vals);
    free(p->len);
    free(p->ranges);
    free(p->top);
    free(p->panels);
    free(p->wa);
    free(p->wb);
    free(p);
}

size_t dk_trisolve_bytes(const dk_trisolve *p)
{
    if (!p)
        return 0;
    const size_t n = (size_t)p->n;
    return sizeof *p + n * (sizeof(*p->rows) + sizeof(*p->vals) + sizeof(int)) +
           sizeof(int) * (2 * (size_t)(p->n_ranges[0] + p->n_ranges[1]) + n) +
           2 * n * (size_t)p->cap * sizeof(double) + sizeof(top_panel) * (size_t)p->n_panels;
}

double dk_trisolve_balance(const dk_trisolve *p)
{
    return p && p->critical_work > 0.0 ? p->total_work / p->critical_work : 0.0;
}

static int item_heavier(const void *a, const void *b)
{
    const item *x = a, *y = b;
    return (x->work < y->work) - (x->work > y->work);
}

static int item_earlier(const void *a, const void *b)
{
    const item *x = a, *y = b;
    return (x->start > y->start) - (x->start < y->start);
}

/* Appends the subtrees rooted at the consecutive nodes kids[0..nk-1] (ascending, each a
 * contiguous range, together contiguous) as items, merging consecutive light ones. Returns
 * the new item count, or -1 when it would exceed MAX_ITEMS. */
static int add_items(item *it, int count, const int *kids, int nk, const int *first,
                     const double *subwork, double light)
{
    item chunk = {0, 0, -1, 0.0};
    int open = 0;
    for (int q = 0; q < nk; q++) {
        const int v = kids[q];
        if (subwork[v] >= light) {
            if (open) {
                if (count >= MAX_ITEMS)
                    return -1;
                it[count++] = chunk;
                open = 0;
            }
            if (count >= MAX_ITEMS)
                return -1;
            it[count++] = (item){first[v], v + 1, v, subwork[v]};
        } else {
            if (!open) {
                chunk = (item){first[v], first[v], -1, 0.0};
                open = 1;
            }
            if (chunk.end != first[v]) { /* not adjacent (cannot happen when postordered) */
                if (count >= MAX_ITEMS)
                    return -1;
                it[count++] = chunk;
                chunk = (item){first[v], v + 1, -1, 0.0};
            }
            chunk.end = v + 1;
            chunk.work += subwork[v];
            if (chunk.work >= light) {
                if (count >= MAX_ITEMS)
                    return -1;
                it[count++] = chunk;
                open = 0;
            }
        }
    }
    if (open) {
        if (count >= MAX_ITEMS)
            return -1;
        it[count++] = chunk;
    }
    return count;
}

/* LPT assignment of the items (sorted heaviest first on return) to two threads; returns
 * the larger thread's work, and the thread of each item in `who`. */
static double assign(item *it, int count, unsigned char *who)
{
    double bin[2] = {0.0, 0.0};
    qsort(it, (size_t)count, sizeof *it, item_heavier);
    for (int q = 0; q < count; q++) {
        const int t = bin[1] < bin[0];
        who[q] = (unsigned char)t;
        bin[t] += it[q].work;
    }
    return bin[0] > bin[1] ? bin[0] : bin[1];
}

static int build_schedule(dk_trisolve *p, const int *parent, double min_speedup)
{
    const int n = p->n;
    int ok = 0;
    int *first = malloc(sizeof(int) * (size_t)n), *cnt = malloc(sizeof(int) * (size_t)n);
    int *kid_start = calloc((size_t)n + 2, sizeof(int)), *kids = malloc(sizeof(int) * (size_t)n);
    double *subwork = malloc(sizeof(double) * (size_t)n);
    item *it = malloc(sizeof(item) * MAX_ITEMS), *best = malloc(sizeof(item) * MAX_ITEMS);
    unsigned char *who = malloc(MAX_ITEMS), *best_who = malloc(MAX_ITEMS);
    unsigned char *covered = NULL;
    if (!first || !cnt || !kid_start || !kids || !subwork || !it || !best || !who || !best_who)
        goto out;
    double total = 0.0;
    for (int j = 0; j < n; j++) {
        first[j] = j;
        cnt[j] = 1;
        subwork[j] = (double)p->len[j];
        total += (double)p->len[j];
    }
    /* children lists (ascending), roots listed under the virtual node n */
    for (int j = 0; j < n; j++)
        kid_start[(parent[j] >= 0 ? parent[j] : n) + 1]++;
    for (int j = 0; j <= n; j++)
        kid_start[j + 1] += kid_start[j];
    {
        int *fill = malloc(sizeof(int) * ((size_t)n + 1));
        if (!fill)
            goto out;
        memcpy(fill, kid_start, sizeof(int) * ((size_t)n + 1));
        for (int j = 0; j < n; j++)
            kids[fill[parent[j] >= 0 ? parent[j] : n]++] = j;
        free(fill);
    }
    for (int j = 0; j < n; j++) {
        if (cnt[j] != j - first[j] + 1)
            goto out; /* not postordered: subtrees are not column ranges */
        const int q = parent[j];
        if (q >= 0) {
            if (first[j] < first[q])
                first[q] = first[j];
            cnt[q] += cnt[j];
            subwork[q] += subwork[j];
        }
    }
    const double light = total / 64.0;
    int count = add_items(it, 0, kids + kid_start[n], kid_start[n + 1] - kid_start[n], first,
                          subwork, light);
    if (count < 0)
        goto out;
    double top_work = 0.0;
    double best_est = -1.0;
    int best_count = 0;
    for (int step = 0; step <= MAX_EXPANSIONS; step++) {
        const double est = assign(it, count, who) + top_work;
        if (best_est < 0.0 || est < best_est) {
            best_est = est;
            best_count = count;
            memcpy(best, it, sizeof(item) * (size_t)count);
            memcpy(best_who, who, (size_t)count);
        }
        /* it[] is sorted heaviest first: expand the heaviest expandable item */
        int e = -1;
        for (int q = 0; q < count; q++)
            if (it[q].node >= 0 && kid_start[it[q].node + 1] > kid_start[it[q].node]) {
                e = q;
                break;
            }
        if (e < 0 || it[e].work < 2.0 * light / 64.0)
            break;
        int v = it[e].node;
        it[e] = it[--count];
        top_work += (double)p->len[v];
        while (kid_start[v + 1] - kid_start[v] == 1) { /* single-child chain: to the top */
            v = kids[kid_start[v]];
            top_work += (double)p->len[v];
        }
        /* merge light children into chunks of at least light / 64, and of 1/128 of their
         * total so that a node with thousands of children (a star) still fits MAX_ITEMS */
        double kids_work = 0.0;
        for (int q = kid_start[v]; q < kid_start[v + 1]; q++)
            kids_work += subwork[kids[q]];
        const double chunk = kids_work / 128.0 > light / 64.0 ? kids_work / 128.0 : light / 64.0;
        const int c2 = add_items(it, count, kids + kid_start[v], kid_start[v + 1] - kid_start[v],
                                 first, subwork, chunk);
        if (c2 < 0)
            break;
        count = c2;
    }
    p->total_work = total;
    p->critical_work = best_est;
    if (!(total >= min_speedup * best_est))
        goto out;
    /* ranges per thread, ascending; the top = the columns no range covers */
    p->ranges = malloc(sizeof(int) * (2 * (size_t)best_count + 2));
    p->top = malloc(sizeof(int) * (size_t)n);
    covered = calloc((size_t)n, 1);
    if (!p->ranges || !p->top || !covered)
        goto out;
    {
        item *sorted = it; /* reuse: items of thread 0, then of thread 1, each by start */
        int k = 0;
        for (int t = 0; t < 2; t++) {
            const int k0 = k;
            for (int q = 0; q < best_count; q++)
                if (best_who[q] == t)
                    sorted[k++] = best[q];
            qsort(sorted + k0, (size_t)(k - k0), sizeof *sorted, item_earlier);
            p->n_ranges[t] = k - k0;
        }
        for (int q = 0; q < best_count; q++) {
            p->ranges[2 * q] = sorted[q].start;
            p->ranges[2 * q + 1] = sorted[q].end;
            memset(covered + sorted[q].start, 1, (size_t)(sorted[q].end - sorted[q].start));
        }
    }
    p->n_top = 0;
    for (int j = 0; j < n; j++)
        if (!covered[j])
            p->top[p->n_top++] = j;
    ok = 1;
out:
    free(first);
    free(cnt);
    free(kid_start);
    free(kids);
    free(subwork);
    free(it);
    free(best);
    free(who);
    free(best_who);
    free(covered);
    return ok;
}

/* The blocks of big supernodes in the top (see top_panel). On the armadillo's bi-Laplacian the
 * top is two supernodes, 100 and 589 columns (6% of the entries), which one thread did in
 * ~0.5 ms of a 3.3 ms solve. Without the list (out of memory) the top stays serial. */
static void plan_panels(dk_trisolve *p, const cholmod_factor *L)
{
    const int *super = L->super;
    unsigned char *in_top = calloc((size_t)p->n + 1, 1);
    int count = 0, cap = 0;
    top_panel *list = NULL;
    if (!in_top)
        return;
    for (int t = 0; t < p->n_top; t++)
        in_top[p->top[t]] = 1;
    for (size_t sn = 0; sn < L->nsuper; sn++) {
        const int k1 = super[sn], k2 = super[sn + 1], nsrow = p->len[k1];
        int all = 1;
        for (int j = k1; j < k2 && all; j++)
            all = in_top[j];
        if (!all)
            continue;
        for (int j0 = k1; j0 < k2; j0 += PANEL_COLS) {
            const int j1 = k2 - j0 > PANEL_COLS ? j0 + PANEL_COLS : k2;
            const double below = (double)(nsrow - (j1 - k1)) * (double)(j1 - j0);
            if (below < PANEL_MIN_WORK)
                continue;
            if (count == cap) {
                cap = cap ? 2 * cap : 16;
                top_panel *grown = realloc(list, sizeof *list * (size_t)cap);
                if (!grown) {
                    free(list);
                    free(in_top);
                    return;
                }
                list = grown;
            }
            list[count++] = (top_panel){j0, j1, k1};
        }
    }
    free(in_top);
    p->panels = list;
    p->n_panels = count;
}

dk_trisolve *dk_trisolve_plan(const cholmod_factor *L, double min_entries, double min_speedup)
{
    if (!L || L->xtype != CHOLMOD_REAL || L->itype != CHOLMOD_INT ||
        L->dtype != CHOLMOD_DOUBLE || !L->x || L->n < 2 || L->n > (size_t)INT32_MAX)
        return NULL;
    if (L->is_super && !L->is_ll)
        return NULL;
    dk_trisolve *p = calloc(1, sizeof *p);
    int *parent = NULL;
    if (!p)
        return NULL;
    const int n = (int)L->n;
    p->n = n;
    p->perm = L->Perm;
    p->rows = malloc(sizeof(*p->rows) * (size_t)n);
    p->vals = malloc(sizeof(*p->vals) * (size_t)n);
    p->len = malloc(sizeof(int) * (size_t)n);
    parent = malloc(sizeof(int) * (size_t)n);
    if (!p->rows || !p->vals || !p->len || !parent)
        goto fail;
    const double *lx = L->x;
    double entries = 0.0;
    if (L->is_super) {
        const int *super = L->super, *pi = L->pi, *px = L->px, *ls = L->s;
        if (!super || !pi || !px || !ls)
            goto fail;
        for (size_t s = 0; s < L->nsuper; s++) {
            const int k1 = super[s], k2 = super[s + 1], psi = pi[s], nsrow = pi[s + 1] - psi;
            const int nscol = k2 - k1;
            if (nscol < 1 || nsrow < nscol || k2 > n)
                goto fail;
            for (int c = 0; c < nscol; c++) {
                const int j = k1 + c;
                if (ls[psi + c] != j)
                    goto fail;
                p->rows[j] = ls + psi + c;
                p->vals[j] = lx + (size_t)px[s] + (size_t)c * (size_t)nsrow + (size_t)c;
                p->len[j] = nsrow - c;
            }
        }
        p->ll = 1;
    } else {
        const int *lp = L->p, *li = L->i, *lnz = L->nz;
        if (!lp || !li || !lnz)
            goto fail;
        for (int j = 0; j < n; j++) {
            p->rows[j] = li + lp[j];
            p->vals[j] = lx + lp[j];
            p->len[j] = lnz[j];
            if (lnz[j] < 1 || li[lp[j]] != j)
                goto fail;
        }
        p->ll = L->is_ll;
    }
    /* parent(j) = the smallest row below the diagonal. Inside a supernode the tree is a
     * chain (parent = the next column) and only the last column's list is scanned: O(|Ls|)
     * per factor instead of O(entries), which matters at 10^6 vertices. */
    for (size_t sn = 0; sn < (L->is_super ? L->nsuper : (size_t)n); sn++) {
        const int j0 = L->is_super ? ((const int *)L->super)[sn] : (int)sn;
        const int tail = L->is_super ? ((const int *)L->super)[sn + 1] - 1 : (int)sn;
        int q = -1;
        for (int k = 1; k < p->len[tail]; k++) {
            const int r = p->rows[tail][k];
            if (r <= tail || r >= n)
                goto fail;
            if (q < 0 || r < q)
                q = r;
        }
        for (int c = j0; c < tail; c++)
            parent[c] = c + 1;
        parent[tail] = q;
        for (int c = j0; c <= tail; c++)
            entries += (double)p->len[c];
    }
    if (entries < min_entries || !build_schedule(p, parent, min_speedup))
        goto fail;
    if (L->is_super)
        plan_panels(p, L);
    free(parent);
    return p;
fail:
    free(parent);
    dk_trisolve_free(p);
    return NULL;
}

/* ------------------------------------------------------------------ substitutions ------ */

/* Forward substitution of columns j0 .. j1-1 on the row-major n x K work w, and backward
 * substitution of columns j1-1 down to j0. For K = 1..6 the row's values are named scalars
 * (y0..y5, the unused ones dead code), which keeps them in registers: a loop over a local
 * array, even of constant length, was left in memory by GCC -O2 and ran ~3x slower than
 * cholmod_solve2. Any other K (up to 16) uses the loop version. */
#define DK_SWEEPS6(K)                                                                        \
    static void forward_##K(const dk_trisolve *p, double *w, int kk, int j0, int j1)         \
    {                                                                                        \
        (void)kk;                                                                            \
        for (int j = j0; j < j1; j++) {                                                      \
            const int *r = p->rows[j];                                                       \
            const double *v = p->vals[j];                                                    \
            const int m = p->len[j];                                                         \
            double *xj = w + (size_t)j * K;                                                  \
            const double d = p->ll ? 1.0 / v[0] : 1.0;                                       \
            const double y0 = xj[0] * d;                                                     \
            const double y1 = K > 1 ? xj[K > 1 ? 1 : 0] * d : 0.0;                           \
            const double y2 = K > 2 ? xj[K > 2 ? 2 : 0] * d : 0.0;                           \
            const double y3 = K > 3 ? xj[K > 3 ? 3 : 0] * d : 0.0;                           \
            const double y4 = K > 4 ? xj[K > 4 ? 4 : 0] * d : 0.0;                           \
            const double y5 = K > 5 ? xj[K > 5 ? 5 : 0] * d : 0.0;                           \
            xj[0] = y0;                                                                      \
            if (K > 1) xj[K > 1 ? 1 : 0] = y1;                                               \
            if (K > 2) xj[K > 2 ? 2 : 0] = y2;                                               \
            if (K > 3) xj[K > 3 ? 3 : 0] = y3;                                               \
            if (K > 4) xj[K > 4 ? 4 : 0] = y4;                                               \
            if (K > 5) xj[K > 5 ? 5 : 0] = y5;                                               \
            for (int q = 1; q < m; q++) {                                                    \
                double *xi = w + (size_t)r[q] * K;                                           \
                const double a = v[q];                                                       \
                xi[0] -= a * y0;                                                             \
                if (K > 1) xi[K > 1 ? 1 : 0] -= a * y1;                                      \
                if (K > 2) xi[K > 2 ? 2 : 0] -= a * y2;                                      \
                if (K > 3) xi[K > 3 ? 3 : 0] -= a * y3;                                      \
                if (K > 4) xi[K > 4 ? 4 : 0] -= a * y4;                                      \
                if (K > 5) xi[K > 5 ? 5 : 0] -= a * y5;                                      \
            }                                                                                \
        }                                                                                    \
    }                                                                                        \
    static void backward_##K(const dk_trisolve *p, double *w, int kk, int j0, int j1)        \
    {                                                                                        \
        (void)kk;                                                                            \
        for (int j = j1 - 1; j >= j0; j--) {                                                 \
            const int *r = p->rows[j];                                                       \
            const double *v = p->vals[j];                                                    \
            const int m = p->len[j];                                                         \
            double *xj = w + (size_t)j * K;                                                  \
            /* two sets of accumulators (even and odd entries): halves the dependency chain. \
             * The entries are read from the last to the first, so that with the columns  \
             * also taken last to first the factor is streamed in one descending sweep;   \
             * ascending runs inside descending columns defeated the hardware prefetch   \
             * (bi-Laplacian, 3 RHS: 2.0 ms -> 0.9 ms for the parallel part). */         \
            double y0 = xj[0], y1 = 0.0, y2 = 0.0, y3 = 0.0, y4 = 0.0, y5 = 0.0;             \
            double z0 = 0.0, z1 = 0.0, z2 = 0.0, z3 = 0.0, z4 = 0.0, z5 = 0.0;               \
            if (K > 1) y1 = xj[K > 1 ? 1 : 0];                                               \
            if (K > 2) y2 = xj[K > 2 ? 2 : 0];                                               \
            if (K > 3) y3 = xj[K > 3 ? 3 : 0];                                               \
            if (K > 4) y4 = xj[K > 4 ? 4 : 0];                                               \
            if (K > 5) y5 = xj[K > 5 ? 5 : 0];                                               \
            int q = m - 1;                                                                   \
            for (; q >= 2; q -= 2) {                                                         \
                const double *xi = w + (size_t)r[q] * K, *xh = w + (size_t)r[q - 1] * K;     \
                const double a = v[q], b = v[q - 1];                                         \
                y0 -= a * xi[0];                                                             \
                z0 -= b * xh[0];                                                             \
                if (K > 1) y1 -= a * xi[K > 1 ? 1 : 0];                                      \
                if (K > 1) z1 -= b * xh[K > 1 ? 1 : 0];                                      \
                if (K > 2) y2 -= a * xi[K > 2 ? 2 : 0];                                      \
                if (K > 2) z2 -= b * xh[K > 2 ? 2 : 0];                                      \
                if (K > 3) y3 -= a * xi[K > 3 ? 3 : 0];                                      \
                if (K > 4) y4 -= a * xi[K > 4 ? 4 : 0];                                      \
                if (K > 5) y5 -= a * xi[K > 5 ? 5 : 0];                                      \
                if (K > 3) z3 -= b * xh[K > 3 ? 3 : 0];                                      \
                if (K > 4) z4 -= b * xh[K > 4 ? 4 : 0];                                      \
                if (K > 5) z5 -= b * xh[K > 5 ? 5 : 0];                                      \
            }                                                                                \
            if (q == 1) {                                                                    \
                const double *xi = w + (size_t)r[1] * K;                                     \
                const double a = v[1];                                                       \
                y0 -= a * xi[0];                                                             \
                if (K > 1) y1 -= a * xi[K > 1 ? 1 : 0];                                      \
                if (K > 2) y2 -= a * xi[K > 2 ? 2 : 0];                                      \
                if (K > 3) y3 -= a * xi[K > 3 ? 3 : 0];                                      \
                if (K > 4) y4 -= a * xi[K > 4 ? 4 : 0];                                      \
                if (K > 5) y5 -= a * xi[K > 5 ? 5 : 0];                                      \
            }                                                                                \
            y0 += z0;                                                                        \
            y1 += z1;                                                                        \
            y2 += z2;                                                                        \
            y3 += z3;                                                                        \
            y4 += z4;                                                                        \
            y5 += z5;                                                                        \
            const double d = p->ll ? 1.0 / v[0] : 1.0;                                       \
            xj[0] = y0 * d;                                                                  \
            if (K > 1) xj[K > 1 ? 1 : 0] = y1 * d;                                           \
            if (K > 2) xj[K > 2 ? 2 : 0] = y2 * d;                                           \
            if (K > 3) xj[K > 3 ? 3 : 0] = y3 * d;                                           \
            if (K > 4) xj[K > 4 ? 4 : 0] = y4 * d;                                           \
            if (K > 5) xj[K > 5 ? 5 : 0] = y5 * d;                                           \
        }                                                                                    \
    }

DK_SWEEPS6(1)
DK_SWEEPS6(2)
DK_SWEEPS6(3)
DK_SWEEPS6(4)
DK_SWEEPS6(5)
DK_SWEEPS6(6)

static void forward_k(const dk_trisolve *p, double *w, int k, int j0, int j1)
{
    for (int j = j0; j < j1; j++) {
        const int *r = p->rows[j];
        const double *v = p->vals[j];
        const int m = p->len[j];
        double *xj = w + (size_t)j * (size_t)k;
        if (p->ll)
            for (int c = 0; c < k; c++)
                xj[c] /= v[0];
        for (int q = 1; q < m; q++) {
            double *xi = w + (size_t)r[q] * (size_t)k;
            const double a = v[q];
            for (int c = 0; c < k; c++)
                xi[c] -= a * xj[c];
        }
    }
}

static void backward_k(const dk_trisolve *p, double *w, int k, int j0, int j1)
{
    for (int j = j1 - 1; j >= j0; j--) {
        const int *r = p->rows[j];
        const double *v = p->vals[j];
        const int m = p->len[j];
        double *xj = w + (size_t)j * (size_t)k;
        for (int q = m - 1; q >= 1; q--) {
            const double *xi = w + (size_t)r[q] * (size_t)k;
            const double a = v[q];
            for (int c = 0; c < k; c++)
                xj[c] -= a * xi[c];
        }
        if (p->ll)
            for (int c = 0; c < k; c++)
                xj[c] /= v[0];
    }
}

typedef void (*sweep_fn)(const dk_trisolve *, double *, int, int, int);

static void forward(const dk_trisolve *p, double *w, int k, int j0, int j1)
{
    static const sweep_fn f[7] = {forward_k, forward_1, forward_2, forward_3,
                                  forward_4, forward_5, forward_6};
    f[k <= 6 ? k : 0](p, w, k, j0, j1);
}

static void backward(const dk_trisolve *p, double *w, int k, int j0, int j1)
{
    static const sweep_fn f[7] = {backward_k, backward_1, backward_2, backward_3,
                                  backward_4, backward_5, backward_6};
    f[k <= 6 ? k : 0](p, w, k, j0, j1);
}

typedef struct sweep {
    const dk_trisolve *p;
    double *w;        /* the thread's work array: wa (thread 0, and thread 1 backward), wb */
    double *wa;       /* thread 0's array (where thread 1's rows go after the forward)      */
    const double *b;  /* forward: the right-hand sides (column-major n x k)                 */
    double *x;        /* backward: the solution (column-major n x k, may alias b)           */
    int k, thread, back;
} sweep;

/* Rows [j0, j1) of the work array w from the right-hand sides (permuted), or zero. */
static void rows_in(const dk_trisolve *p, const double *b, int k, double *w, int j0, int j1)
{
    const size_t n = (size_t)p->n;
    for (int i = j0; i < j1; i++) {
        const size_t src = p->perm ? (size_t)p->perm[i] : (size_t)i;
        for (int c = 0; c < k; c++)
            w[(size_t)i * (size_t)k + (size_t)c] = b ? b[(size_t)c * n + src] : 0.0;
    }
}

/* Rows [j0, j1) of the solution x from the work array w (permuted back). */
static void rows_out(const dk_trisolve *p, const double *w, int k, double *x, int j0, int j1)
{
    const size_t n = (size_t)p->n;
    for (int i = j0; i < j1; i++) {
        const size_t dst = p->perm ? (size_t)p->perm[i] : (size_t)i;
        for (int c = 0; c < k; c++)
            x[(size_t)c * n + dst] = w[(size_t)i * (size_t)k + (size_t)c];
    }
}

/* One thread's part of a sweep. The copies in and out of the work arrays are done here by
 * the thread that owns the rows, in parallel, instead of serially around the sweeps: the
 * rows of a thread's ranges are read and written only by that thread (subtrees update only
 * themselves and the top); the top rows start in wa (thread 0) and as zeros in wb (thread
 * 1, added in afterwards). */
static void run_sweep(const sweep *s)
{
    const dk_trisolve *p = s->p;
    const int *rg = p->ranges + (s->thread ? 2 * p->n_ranges[0] : 0);
    const int nr = p->n_ranges[s->thread], k = s->k;
    if (!s->back) {
        for (int q = 0; q < nr; q++)
            rows_in(p, s->b, k, s->w, rg[2 * q], rg[2 * q + 1]);
        for (int t = 0; t < p->n_top; t++)
            rows_in(p, s->thread ? NULL : s->b, k, s->w, p->top[t], p->top[t] + 1);
        for (int q = 0; q < nr; q++)
            forward(p, s->w, k, rg[2 * q], rg[2 * q + 1]);
        if (s->thread) /* thread 1's rows into wa, for the top columns and the backward */
            for (int q = 0; q < nr; q++)
                memcpy(s->wa + (size_t)rg[2 * q] * (size_t)k, s->w + (size_t)rg[2 * q] * (size_t)k,
                       sizeof(double) * (size_t)(rg[2 * q + 1] - rg[2 * q]) * (size_t)k);
    } else {
        for (int q = nr - 1; q >= 0; q--)
            backward(p, s->w, k, rg[2 * q], rg[2 * q + 1]);
        for (int q = 0; q < nr; q++)
            rows_out(p, s->w, k, s->x, rg[2 * q], rg[2 * q + 1]);
        if (!s->thread) /* the top rows, final before the parallel backward began */
            for (int t = 0; t < p->n_top; t++)
                rows_out(p, s->w, k, s->x, p->top[t], p->top[t] + 1);
    }
}

static void sweep_part(void *ctx, dk_index begin, dk_index end, int part)
{
    (void)begin;
    (void)end;
    run_sweep((sweep *)ctx + part);
}

/* Thread 1's sweep on a helper thread (the team's, or a new one) while the caller does
 * thread 0's (dk_team_run_halves over the two sweeps); without a helper the caller does
 * both, part 0 first (each writes only its own rows). */
static void both(dk_team *team, sweep *s0, sweep *s1)
{
    sweep pair[2] = {*s0, *s1};
    dk_team_run_halves(team, sweep_part, pair, 2, 2);
}

/* ------------------------------------------------------------------ top blocks -------- */

/* Entry q of column j of a supernode with first column k1 is the supernode's local row
 * (j - k1) + q; a block [j0, j1) ends at local row c1 = j1 - k1. The rows below the block,
 * local [c1, nsrow), are split at their middle between the two parts. */
typedef struct panel_job {
    const dk_trisolve *p;
    const top_panel *b;
    double *w;
    int k;
    int back;                        /* 0: forward, 1: backward                            */
    double sums[2][PANEL_COLS * 16]; /* backward: each part's sums, column-major k x cols */
} panel_job;

static void panel_rows(const panel_job *j, int part, int col, int *q0, int *q1)
{
    const int k1 = j->b->k1, nsrow = j->p->len[k1], c1 = j->b->j1 - k1;
    const int mid = c1 + (nsrow - c1) / 2, c = col - k1;
    *q0 = (part ? mid : c1) - c;
    *q1 = (part ? nsrow : mid) - c;
}

/* The rows below the block, one part's half (a dk_range_fn). Forward (job->back 0):
 * w_r -= L_rj y_j for the block's columns in ascending order, each row by one part: the same
 * operations in the same order as column by column. Backward: the part's sums of L_rj x_r. */
static void panel_part(void *ctx, dk_index begin, dk_index end, int part)
{
    panel_job *j = ctx;
    const dk_trisolve *p = j->p;
    const int k = j->k;
    (void)begin;
    (void)end;
    for (int col = j->b->j0; col < j->b->j1; col++) {
        int q0, q1;
        panel_rows(j, part, col, &q0, &q1);
        const int *r = p->rows[col];
        const double *v = p->vals[col];
        if (!j->back) {
            const double *y = j->w + (size_t)col * (size_t)k;
            for (int q = q0; q < q1; q++) {
                double *xi = j->w + (size_t)r[q] * (size_t)k;
                if (k == 3) { /* named scalars: the common case stays in registers */
                    xi[0] -= v[q] * y[0];
                    xi[1] -= v[q] * y[1];
                    xi[2] -= v[q] * y[2];
                } else {
                    for (int c = 0; c < k; c++)
                        xi[c] -= v[q] * y[c];
                }
            }
        } else {
            double *sum = j->sums[part] + (size_t)(col - j->b->j0) * (size_t)k;
            double s0 = 0.0, s1 = 0.0, s2 = 0.0;
            for (int c = 0; c < k; c++)
                sum[c] = 0.0;
            for (int q = q1 - 1; q >= q0; q--) {
                const double *xi = j->w + (size_t)r[q] * (size_t)k;
                if (k == 3) {
                    s0 += v[q] * xi[0];
                    s1 += v[q] * xi[1];
                    s2 += v[q] * xi[2];
                } else {
                    for (int c = 0; c < k; c++)
                        sum[c] += v[q] * xi[c];
                }
            }
            if (k == 3) {
                sum[0] = s0;
                sum[1] = s1;
                sum[2] = s2;
            }
        }
    }
}

/* The rows below block b on the two threads of `team`, forward or backward. */
static void run_panel(const dk_trisolve *p, dk_team *team, double *w, int k,
                      const top_panel *b, panel_job *job, int back)
{
    job->p = p;
    job->b = b;
    job->w = w;
    job->k = k;
    job->back = back;
    dk_team_run_halves(team, panel_part, job, 2, 2);
}

/* Forward substitution of a block: its triangle on the calling thread (each column's
 * entries inside the block), then the rows below on two. Supernodal factors are LL'. */
static void panel_forward(const dk_trisolve *p, dk_team *team, double *w, int k,
                          const top_panel *b, panel_job *job)
{
    for (int col = b->j0; col < b->j1; col++) {
        const int *r = p->rows[col];
        const double *v = p->vals[col];
        double *y = w + (size_t)col * (size_t)k;
        const double d = 1.0 / v[0];
        for (int c = 0; c < k; c++)
            y[c] *= d;
        for (int q = 1; q < b->j1 - col; q++) {
            double *xi = w + (size_t)r[q] * (size_t)k;
            for (int c = 0; c < k; c++)
                xi[c] -= v[q] * y[c];
        }
    }
    run_panel(p, team, w, k, b, job, 0);
}

/* Backward substitution of a block: the sums over the rows below on two threads, then the
 * triangle from its last column to its first on the calling thread. */
static void panel_backward(const dk_trisolve *p, dk_team *team, double *w, int k,
                           const top_panel *b, panel_job *job)
{
    run_panel(p, team, w, k, b, job, 1);
    for (int col = b->j1 - 1; col >= b->j0; col--) {
        const int *r = p->rows[col];
        const double *v = p->vals[col];
        double *x = w + (size_t)col * (size_t)k;
        const double *s0 = job->sums[0] + (size_t)(col - b->j0) * (size_t)k;
        const double *s1 = job->sums[1] + (size_t)(col - b->j0) * (size_t)k;
        for (int c = 0; c < k; c++) {
            double acc = x[c] - s0[c] - s1[c];
            for (int q = b->j1 - col - 1; q >= 1; q--)
                acc -= v[q] * w[(size_t)r[q] * (size_t)k + (size_t)c];
            x[c] = acc / v[0];
        }
    }
}

/* The solve of dk_trisolve_solve for 1 <= nrhs <= 16 columns at once. */
static int solve_block(dk_trisolve *p, dk_team *team, const double *b, int nrhs, double *x)
{
    const int n = p->n, k = nrhs;
    const size_t nk = (size_t)n * (size_t)k;
    if (k > p->cap) {
        double *wa = malloc(sizeof(double) * nk), *wb = malloc(sizeof(double) * nk);
        if (!wa || !wb) {
            free(wa);
            free(wb);
            return -1;
        }
        free(p->wa);
        free(p->wb);
        p->wa = wa;
        p->wb = wb;
        p->cap = k;
    }
    double *wa = p->wa, *wb = p->wb;
    /* forward: both threads copy their rows in and sweep their subtrees */
    sweep s0 = {p, wa, wa, b, x, k, 0, 0}, s1 = {p, wb, wa, b, x, k, 1, 0};
    both(team, &s0, &s1);
    for (int t = 0; t < p->n_top; t++) {
        double *xa = wa + (size_t)p->top[t] * k;
        const double *xb = wb + (size_t)p->top[t] * k;
        for (int c = 0; c < k; c++)
            xa[c] += xb[c];
    }
    panel_job panel_work, *job = &panel_work; /* 16 KB of sums */
    for (int t = 0, pc = 0; t < p->n_top;) {
        if (pc < p->n_panels && p->panels[pc].j0 == p->top[t]) {
            panel_forward(p, team, wa, k, &p->panels[pc], job);
            t += p->panels[pc].j1 - p->panels[pc].j0;
            pc++;
        } else {
            forward(p, wa, k, p->top[t], p->top[t] + 1);
            t++;
        }
    }
    if (!p->ll)
        for (int j = 0; j < n; j++) {
            const double d = p->vals[j][0];
            for (int c = 0; c < k; c++)
                wa[(size_t)j * k + c] /= d;
        }
    for (int t = p->n_top - 1, pc = p->n_panels - 1; t >= 0;) {
        if (pc >= 0 && p->panels[pc].j1 - 1 == p->top[t]) {
            panel_backward(p, team, wa, k, &p->panels[pc], job);
            t -= p->panels[pc].j1 - p->panels[pc].j0;
            pc--;
        } else {
            backward(p, wa, k, p->top[t], p->top[t] + 1);
            t--;
        }
    }
    /* backward: both threads on wa, each copying its rows out (b is no longer read) */
    s0.back = s1.back = 1;
    s1.w = wa;
    both(team, &s0, &s1);
    return 0;
}

/* Right-hand sides beyond the register kernels' 6 are solved in blocks of at most
 * KERNEL_MAX columns: the generic loop of a 7-column solve took 2.5x the time of a 6-column
 * one (1.22 s against 0.49 s through a 403 MB factor at 576k unknowns), so two passes over
 * the factor with the kernels (4 + 3 columns: 0.70 s) beat one without. */
#define KERNEL_MAX 6

int dk_trisolve_solve(dk_trisolve *p, dk_team *team, const double *b, int nrhs, double *x)
{
    if (!p || !b || !x || nrhs < 1 || nrhs > 16) /* more: cholmod_solve2 */
        return -1;
    if (nrhs <= KERNEL_MAX)
        return solve_block(p, team, b, nrhs, x);
    /* balanced blocks, the largest first: only the first can need to grow the work arrays
     * (the only failure), so a failure leaves x untouched (x may alias b). Columns are
     * contiguous (column-major), so the blocks are independent solves. */
    const int blocks = (nrhs + KERNEL_MAX - 1) / KERNEL_MAX;
    const size_t n = (size_t)p->n;
    for (int q = 0, done = 0; q < blocks; q++) {
        const int cols = (nrhs - done + (blocks - q) - 1) / (blocks - q);
        if (solve_block(p, team, b + n * (size_t)done, cols, x + n * (size_t)done) != 0)
            return -1; /* q == 0: nothing written */
        done += cols;
    }
    return 0;
}
