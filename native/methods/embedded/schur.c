/* DeformKit embedded deformation: each Gauss-Newton step through the system reduced to the
 * translations (embedded_internal.h).
 *
 * J^T J = I_3 (x) K + D(x): the regularization and positional terms give, for each of the
 * three coordinates d, the same matrix K over the slots (R[d][0..2], t[d]) of every node
 * (their coefficients do not depend on d or on x), and E_rot gives D, one 9 x 9 block per
 * node over its R entries, coupling the coordinates. A node's R meets other nodes only
 * through t (an edge's residual R_j (g_k - g_j) + g_j + t_j - g_k - t_k), unless a
 * positional term also holds another free node: so each such R is eliminated exactly (a
 * 9 x 9 Cholesky factor), and the step solves the Schur complement over the translations
 * and the R of the nodes positional terms couple (the "kept" nodes):
 *
 *   S = A_kk - sum_u C_u^T A_u^-1 C_u,   A_u = I_3 (x) K_RR(u) + D_u + mu I,
 *
 * C_u the coupling of R_u with the translations of u's block list. Eliminating R_u joins
 * the translations of u's neighbours, so S's pattern is the graph's two rings over 3 x 3
 * blocks instead of its one ring over 12 x 12 ones: on the armadillo's 192 free nodes
 * 8-16x fewer operations to factorize. The step is exact, as the full factorization's.
 *
 * S's layout: free node u owns the reduced unknowns base[u] + l, l = 0..2 for t[0..2] and,
 * for a kept node, l = 3 + a for R slot a. S is stored as its upper triangle by node
 * blocks: the column of (w, l) holds, for each node v <= w in w's sorted node list, all of
 * v's unknowns when v < w, or w's own l + 1 first ones. K's values (kblk) change only with
 * the source (update_source, restore_state): ed_reduced_refresh() then remakes S's
 * constant part. */
#include "embedded_internal.h"

/* Where J^T J is singular (a mesh free to turn about a single handle vertex: rigid turns
 * cost nothing), its factorization can still succeed with a pivot whose size and sign are
 * rounding's, and the undamped step then depends on rounding: a translated copy of a scene
 * took another path to another of its minima. A pivot below this fraction of its own
 * diagonal entry (in S's factorization or a node's 9 x 9 block) refuses the step as not
 * positive definite, and Levenberg-Marquardt's damping takes over. Measured: ~1e-16 there,
 * 2.6e-3 or more on the armadillo and the ogre, 1e-8 on a 12,800-node tube pulled with
 * w_con = 1e11. Relative to each pivot's own diagonal, the test does not fall with the
 * weights' ratio or the graph's size, as a condition number does (CHOLMOD's rcond fell
 * below 1e-12 on that tube). Our choice. */
#define ED_SINGULAR 1e-12

static int node_size(const ed_system *s, dk_index u)
{
    return s->kept[u] ? 12 : 3;
}

/* the local index of slot a (0..11) of a node's reduced unknowns, -1 when eliminated */
static int local_of(const ed_system *s, dk_index u, int a)
{
    return a >= 9 ? a - 9 : s->kept[u] ? 3 + a : -1;
}

/* where S holds (row node v, its local r; column node w, its local l); v <= w, and r <= l
 * when v == w; -1 when absent */
static int64_t s_at(const ed_system *s, dk_index v, int r, dk_index w, int l)
{
    dk_index lo = s->nl_start[w], hi = s->nl_start[w + 1] - 1;
    while (lo <= hi) {
        const dk_index mid = lo + (hi - lo) / 2;
        if (s->nl_node[mid] == v)
            return (int64_t)s->S->col_start[s->base[w] + l] + s->nl_off[mid] + r;
        if (s->nl_node[mid] < v)
            lo = mid + 1;
        else
            hi = mid - 1;
    }
    return -1;
}

static int64_t blk_count(const ed_system *s, dk_index u)
{
    return (int64_t)s->blk_start[u + 1] - s->blk_start[u];
}

/* S's node-level pattern: per column node w, the sorted nodes v <= w it meets (itself, its
 * blocks, and the two rings an eliminated node joins) */
static dk_status node_pattern(ed_system *s, dk_error *err)
{
    const dk_index nf = s->n_free;
    int64_t cap = nf;
    for (dk_index u = 0; u < nf; u++) {
        const int64_t nc = blk_count(s, u);
        cap += s->kept[u] ? nc : nc * (nc + 1) / 2;
    }
    int64_t *keys = malloc(((size_t)cap + 1) * sizeof *keys), nk = 0;
    if (!keys)
        return ed_oom(err, "reduced system");
    for (dk_index u = 0; u < nf; u++) {
        keys[nk++] = (int64_t)u * nf + u;
        const dk_index b0 = s->blk_start[u], b1 = s->blk_start[u + 1];
        if (s->kept[u]) {
            for (dk_index b = b0; b < b1; b++) {
                const dk_index v = s->blk_node[b];
                keys[nk++] = v <= u ? (int64_t)u * nf + v : (int64_t)v * nf + u;
            }
        } else { /* the clique of its coupled translations (blk_node sorted) */
            for (dk_index j = b0; j < b1; j++)
                for (dk_index i = b0; i <= j; i++)
                    keys[nk++] = (int64_t)s->blk_node[j] * nf + s->blk_node[i];
        }
    }
    qsort(keys, (size_t)nk, sizeof *keys, cmp_i64);
    int64_t nu = 0;
    for (int64_t i = 0; i < nk; i++)
        if (i == 0 || keys[i] != keys[i - 1])
            keys[nu++] = keys[i];
    if (nu > INT32_MAX) {
        free(keys);
        return dk_error_set(err, DK_ERR_INVALID_ARGUMENT,
                            "EmbeddedDeformation: the reduced system has too many node pairs "
                            "(%lld); use fewer nodes", (long long)nu);
    }
    s->nl_start = calloc((size_t)nf + 1, sizeof *s->nl_start);
    s->nl_node = malloc(((size_t)nu + 1) * sizeof *s->nl_node);
    s->nl_off = malloc(((size_t)nu + 1) * sizeof *s->nl_off);
    if (!s->nl_start || !s->nl_node || !s->nl_off) {
        free(keys);
        return ed_oom(err, "reduced system");
    }
    for (int64_t i = 0; i < nu; i++) {
        s->nl_node[i] = (dk_index)(keys[i] % nf);
        s->nl_start[keys[i] / nf + 1]++;
    }
    free(keys);
    for (dk_index u = 0; u < nf; u++)
        s->nl_start[u + 1] += s->nl_start[u];
    return DK_OK;
}

/* S's CSC pattern from the node pattern, and the diagonal's positions */
static dk_status csc(ed_system *s, dk_error *err)
{
    const dk_index nf = s->n_free;
    int64_t nnz = 0;
    for (dk_index w = 0; w < nf; w++) {
        int64_t below = 0; /* rows of the nodes before w in its list */
        for (dk_index p = s->nl_start[w]; p < s->nl_start[w + 1]; p++) {
            s->nl_off[p] = (dk_index)below;
            if (s->nl_node[p] != w)
                below += node_size(s, s->nl_node[p]);
        }
        const int sz = node_size(s, w);
        nnz += sz * below + (int64_t)sz * (sz + 1) / 2;
        if (nnz > INT32_MAX)
            return dk_error_set(err, DK_ERR_INVALID_ARGUMENT,
                                "EmbeddedDeformation: the reduced system's matrix would hold "
                                "more than 2^31 entries; use fewer nodes");
    }
    dk_status st = dk_sparse_alloc(s->n_red, s->n_red, nnz, &s->S, err);
    if (st != DK_OK)
        return st;
    s->S_base = malloc(((size_t)nnz + 1) * sizeof *s->S_base);
    s->S_part = malloc(((size_t)nnz + 1) * sizeof *s->S_part);
    s->S_diag = malloc(((size_t)s->n_red + 1) * sizeof *s->S_diag);
    if (!s->S_base || !s->S_part || !s->S_diag)
        return ed_oom(err, "reduced system");
    int64_t at = 0;
    for (dk_index w = 0; w < nf; w++) {
        const int sz = node_size(s, w);
        for (int l = 0; l < sz; l++) {
            s->S->col_start[s->base[w] + l] = (dk_index)at;
            for (dk_index p = s->nl_start[w]; p < s->nl_start[w + 1]; p++) {
                const dk_index v = s->nl_node[p];
                const int rows = v == w ? l + 1 : node_size(s, v);
                for (int r = 0; r < rows; r++)
                    s->S->row_index[at++] = s->base[v] + r;
            }
            s->S_diag[s->base[w] + l] = at - 1; /* w is last in its own list */
        }
    }
    s->S->col_start[s->n_red] = (dk_index)at;
    return DK_OK;
}

/* per eliminated node: where each entry (a <= b) of its clique's 3 nc x 3 nc block sits
 * in S (a = 3 i + d: the translation t[d] of the i-th node of its block list), and room
 * for its W = L^-1 C (9 x 3 nc) */
static dk_status cliques(ed_system *s, dk_error *err)
{
    const dk_index nf = s->n_free;
    s->cl_start = malloc(((size_t)nf + 1) * sizeof *s->cl_start);
    s->w_start = malloc(((size_t)nf + 1) * sizeof *s->w_start);
    if (!s->cl_start || !s->w_start)
        return ed_oom(err, "reduced system");
    s->cl_start[0] = s->w_start[0] = 0;
    for (dk_index u = 0; u < nf; u++) {
        const int64_t c = s->kept[u] ? 0 : 3 * blk_count(s, u);
        s->cl_start[u + 1] = s->cl_start[u] + c * (c + 1) / 2;
        s->w_start[u + 1] = s->w_start[u] + 9 * c;
    }
    s->cl_pos = malloc(((size_t)s->cl_start[nf] + 1) * sizeof *s->cl_pos);
    s->W = malloc(((size_t)s->w_start[nf] + 1) * sizeof *s->W);
    if (!s->cl_pos || !s->W)
        return ed_oom(err, "reduced system");
    for (dk_index u = 0; u < nf; u++) {
        if (s->kept[u])
            continue;
        const dk_index *nb = s->blk_node + s->blk_start[u];
        const int c = (int)(3 * blk_count(s, u));
        dk_index *pos = s->cl_pos + s->cl_start[u];
        for (int b = 0; b < c; b++)
            for (int a = 0; a <= b; a++) {
                const int64_t at = s_at(s, nb[a / 3], a % 3, nb[b / 3], b % 3);
                if (at < 0)
                    return dk_error_set(err, DK_ERR_INTERNAL,
                                        "EmbeddedDeformation: reduced system pattern is "
                                        "missing a clique entry");
                *pos++ = (dk_index)at;
            }
    }
    return DK_OK;
}

dk_status ed_reduced_build(dk_embedded *ed, ed_system *s, dk_error *err)
{
    const dk_index nf = s->n_free;
    s->base = malloc(((size_t)nf + 1) * sizeof *s->base);
    s->red = malloc((12 * (size_t)nf + 1) * sizeof *s->red);
    s->lfac = malloc((81 * (size_t)nf + 1) * sizeof *s->lfac);
    if (!s->base || !s->red || !s->lfac)
        return ed_oom(err, "reduced system");
    int64_t r = 0;
    for (dk_index u = 0; u < nf; u++) {
        s->base[u] = (dk_index)r;
        for (int a = 0; a < 12; a++) {
            const int l = local_of(s, u, a);
            s->red[12 * (size_t)u + a] = l >= 0 ? (dk_index)(r + l) : -1;
        }
        r += node_size(s, u);
    }
    s->n_red = (dk_index)r;
    s->rhs = malloc(((size_t)r + 1) * sizeof *s->rhs);
    if (!s->rhs)
        return ed_oom(err, "reduced system");
    dk_status st = node_pattern(s, err);
    if (st == DK_OK)
        st = csc(s, err);
    if (st == DK_OK)
        st = cliques(s, err);
    if (st != DK_OK)
        return st;
    memset(s->S->values, 0, (size_t)s->S->col_start[s->n_red] * sizeof(double));
    for (dk_index i = 0; i < s->n_red; i++) /* a definite placeholder for the analysis */
        s->S->values[s->S_diag[i]] = 1.0;
    st = dk_cholesky_analyze(s->S, &s->chol, err);
    if (st != DK_OK)
        return dk_error_prefix(err, "EmbeddedDeformation: analysis");
    dk_cholesky_set_team(s->chol, ed->team);
    ed->analysis_count++;
    ed_reduced_refresh(ed, s);
    return DK_OK;
}

void ed_reduced_refresh(const dk_embedded *ed, ed_system *s)
{
    ed_evaluate(ed, s, s, ed->x, ED_QUADRATIC);
    const int64_t nnz = s->S->col_start[s->n_red];
    memset(s->S_base, 0, (size_t)nnz * sizeof *s->S_base);
    /* K among the reduced unknowns, for each coordinate: (slot a of u, slot c of v), stored
     * once, in the column of the later node (or of the later unknown within a node) */
    for (dk_index u = 0; u < s->n_free; u++)
        for (dk_index b = s->blk_start[u]; b < s->blk_start[u + 1]; b++) {
            const dk_index v = s->blk_node[b];
            if (v > u)
                continue;
            const double *B = s->kblk + 16 * (size_t)b;
            for (int d = 0; d < 3; d++)
                for (int a = 0; a < 4; a++)
                    for (int c = 0; c < 4; c++) {
                        const int l = local_of(s, u, coord_slot(d, a));
                        const int rr = local_of(s, v, coord_slot(d, c));
                        if (l < 0 || rr < 0 || (v == u && rr > l) || B[4 * a + c] == 0.0)
                            continue;
                        s->S_base[s_at(s, v, rr, u, l)] += B[4 * a + c];
                    }
        }
    s->k_stale = 0;
}

/* In-place Cholesky factor of the symmetric positive definite 9 x 9 matrix A (row major;
 * the lower triangle is used and becomes L, with 1 / L_ii on the diagonal: the
 * substitutions multiply). 0 when a pivot is not positive, or so small against its
 * column's diagonal (ED_SINGULAR) that its sign is rounding's. */
static int cholesky9(double *A)
{
    for (int j = 0; j < 9; j++) {
        double d = A[9 * j + j];
        const double diag = d;
        for (int k = 0; k < j; k++)
            d -= A[9 * j + k] * A[9 * j + k];
        if (!(d > ED_SINGULAR * diag))
            return 0;
        const double inv = 1.0 / sqrt(d);
        A[9 * j + j] = inv;
        for (int i = j + 1; i < 9; i++) {
            double v = A[9 * i + j];
            for (int k = 0; k < j; k++)
                v -= A[9 * i + k] * A[9 * j + k];
            A[9 * i + j] = v * inv;
        }
    }
    return 1;
}

/* y = L^-1 y for the 9 x 9 factor L (row major), starting at row `from` (y's rows before it
 * are zero) */
static void forward9(const double *L, double *y, int from)
{
    for (int i = from; i < 9; i++) {
        double v = y[i];
        for (int k = from; k < i; k++)
            v -= L[9 * i + k] * y[k];
        y[i] = v * L[9 * i + i];
    }
}

/* y = L^-T y */
static void backward9(const double *L, double *y)
{
    for (int i = 8; i >= 0; i--) {
        double v = y[i];
        for (int k = i + 1; k < 9; k++)
            v -= L[9 * k + i] * y[k];
        y[i] = v * L[9 * i + i];
    }
}

/* x . y over rows k0..8 of two of W's columns (k0 = 0, 3 or 6: a column of coordinate d is
 * zero above row 3 d), in three independent sums */
static inline double dot_from(const double *x, const double *y, int k0)
{
    const double c = x[6] * y[6] + x[7] * y[7] + x[8] * y[8];
    if (k0 == 6)
        return c;
    const double b = x[3] * y[3] + x[4] * y[4] + x[5] * y[5];
    if (k0 == 3)
        return b + c;
    return (x[0] * y[0] + x[1] * y[1] + x[2] * y[2]) + b + c;
}

/* The eliminated node u: A_u's factor into lfac, W = L^-1 C_u, and -W^T W into S's values.
 * 0 when A_u is not positive definite. */
static int eliminate(ed_system *s, dk_index u, double mu, double *val)
{
    const dk_index b0 = s->blk_start[u], nc = s->blk_start[u + 1] - b0;
    const double *D = s->rot + 81 * (size_t)u;
    const double *Kuu = s->kblk + 16 * (size_t)ed_block_of(s, u, u);
    double *L = s->lfac + 81 * (size_t)u;
    for (int i = 0; i < 9; i++)
        for (int j = 0; j <= i; j++)
            L[9 * i + j] = D[9 * i + j] + (i / 3 == j / 3 ? Kuu[4 * (i % 3) + j % 3] : 0.0) +
                           (i == j ? mu : 0.0);
    if (!cholesky9(L))
        return 0;
    double *W = s->W + s->w_start[u];
    for (dk_index i = 0; i < nc; i++) { /* C's column (i, d): K(R_u[d][e], t_v[d]) in rows 3 d + e */
        const double *B = s->kblk + 16 * (size_t)(b0 + i);
        for (int d = 0; d < 3; d++) {
            double *w = W + 9 * (3 * (size_t)i + d);
            memset(w, 0, 9 * sizeof *w);
            for (int e = 0; e < 3; e++)
                w[3 * d + e] = B[4 * e + 3];
            forward9(L, w, 3 * d);
        }
    }
    /* entry (a, b), a = 3 i + d <= b = 3 j + e, in cliques()'s order */
    const dk_index *pos = s->cl_pos + s->cl_start[u];
    for (dk_index j = 0; j < nc; j++)
        for (int e = 0; e < 3; e++) {
            const double *wb = W + 9 * (3 * (size_t)j + e);
            for (dk_index i = 0; i <= j; i++) {
                const double *wa = W + 27 * (size_t)i;
                const int dmax = i < j ? 2 : e;
                for (int d = 0; d <= dmax; d++)
                    val[*pos++] -= dot_from(wa + 9 * d, wb, 3 * (d > e ? d : e));
            }
        }
    return 1;
}

/* the nodes' parts of S for one half of them, into their own copy of the values */
typedef struct elim_pass {
    ed_system *s;
    double mu;
    double *val[2];
    dk_index failed[2]; /* the first node whose block is not positive definite, or -1 */
} elim_pass;

static void elim_range(void *ctx, dk_index begin, dk_index end, int part)
{
    elim_pass *e = ctx;
    ed_system *s = e->s;
    double *val = e->val[part];
    e->failed[part] = -1;
    for (dk_index u = begin; u < end; u++) {
        if (s->kept[u]) { /* D_u into its R block, upper triangle */
            const double *D = s->rot + 81 * (size_t)u;
            for (int j = 0; j < 9; j++)
                for (int i = 0; i <= j; i++)
                    val[s->S_diag[s->base[u] + 3 + j] - (j - i)] += D[9 * i + j];
        } else if (!eliminate(s, u, e->mu, val)) {
            e->failed[part] = u;
            return;
        }
    }
}

/* nodes below which one thread does the elimination */
enum { ED_PARALLEL_NODES = 64 };

dk_status ed_reduced_factorize(ed_system *s, double mu, dk_team *team, dk_error *err)
{
    const size_t nnz = (size_t)s->S->col_start[s->n_red];
    double *val = s->S->values;
    memcpy(val, s->S_base, nnz * sizeof *val);
    for (dk_index i = 0; i < s->n_red; i++)
        val[s->S_diag[i]] += mu;
    /* the second half's contributions go to S_part, added after in the same order whether
     * or not the helper ran: the same values either way */
    memset(s->S_part, 0, nnz * sizeof *s->S_part);
    elim_pass e = {s, mu, {val, s->S_part}, {-1, -1}};
    dk_team_run_halves(team, elim_range, &e, s->n_free, ED_PARALLEL_NODES);
    for (int part = 0; part < 2; part++)
        if (e.failed[part] >= 0)
            return dk_error_set(err, DK_ERR_NOT_POSITIVE_DEFINITE,
                                "EmbeddedDeformation: the rotation block of node %d is not "
                                "positive definite", (int)s->free_nodes[e.failed[part]]);
    for (size_t i = 0; i < nnz; i++)
        val[i] += s->S_part[i];
    dk_status st = dk_cholesky_factorize(s->chol, s->S, err);
    const double ratio = st == DK_OK ? dk_cholesky_min_pivot_ratio(s->chol, s->S) : 1.0;
    if (ratio < ED_SINGULAR)
        st = dk_error_set(err, DK_ERR_NOT_POSITIVE_DEFINITE,
                          "EmbeddedDeformation: J^T J is singular but for rounding (a pivot "
                          "%.3g of its diagonal)", ratio);
    return st;
}

dk_status ed_reduced_solve(ed_system *s, dk_error *err)
{
    const dk_index nf = s->n_free;
    double *y = s->rhs;
    for (dk_index u = 0; u < nf; u++)
        for (int a = 0; a < 12; a++) {
            const dk_index r = s->red[12 * (size_t)u + a];
            if (r >= 0)
                y[r] = -s->grad[12 * (size_t)u + a];
        }
    /* z_u = L^-1 b_R(u) (kept in step's R slots), and the right side minus W^T z_u */
    for (dk_index u = 0; u < nf; u++) {
        if (s->kept[u])
            continue;
        double *z = s->step + 12 * (size_t)u;
        for (int i = 0; i < 9; i++)
            z[i] = -s->grad[12 * (size_t)u + i];
        forward9(s->lfac + 81 * (size_t)u, z, 0);
        const dk_index *nb = s->blk_node + s->blk_start[u];
        const double *W = s->W + s->w_start[u];
        for (int a = 0; a < 3 * (int)blk_count(s, u); a++) {
            double v = 0.0;
            for (int k = 0; k < 9; k++)
                v += W[9 * a + k] * z[k];
            y[s->base[nb[a / 3]] + a % 3] -= v;
        }
    }
    dk_status st = dk_cholesky_solve(s->chol, y, 1, y, err);
    if (st != DK_OK)
        return st;
    for (dk_index u = 0; u < nf; u++) {
        double *step = s->step + 12 * (size_t)u;
        for (int a = 0; a < 12; a++) {
            const dk_index r = s->red[12 * (size_t)u + a];
            if (r >= 0)
                step[a] = y[r];
        }
        if (s->kept[u])
            continue;
        /* R_u = L^-T (z_u - W y) */
        const dk_index *nb = s->blk_node + s->blk_start[u];
        const double *W = s->W + s->w_start[u];
        for (int a = 0; a < 3 * (int)blk_count(s, u); a++) {
            const double ya = y[s->base[nb[a / 3]] + a % 3];
            for (int k = 0; k < 9; k++)
                step[k] -= W[9 * a + k] * ya;
        }
        backward9(s->lfac + 81 * (size_t)u, step);
    }
    return DK_OK;
}

double ed_reduced_trace(const ed_system *s)
{
    double t = 0.0;
    for (dk_index u = 0; u < s->n_free; u++) {
        const double *K = s->kblk + 16 * (size_t)ed_block_of(s, u, u);
        const double *D = s->rot + 81 * (size_t)u;
        for (int a = 0; a < 4; a++)
            t += 3.0 * K[5 * a];
        for (int i = 0; i < 9; i++)
            t += D[10 * i];
    }
    return t;
}
