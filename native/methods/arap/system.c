/* DeformKit ARAP: the constraint system: unknowns, component check, reduced matrix and
 * factor, right-hand-side map (see arap_internal.h). */
#include "arap_internal.h"

#include <stdio.h>

static void sparse_release(dk_sparse *a)
{
    free(a->col_start);
    free(a->row_index);
    free(a->values);
    memset(a, 0, sizeof *a);
}

void arap_system_free(arap_system *s)
{
    arap_coarse_free(s->coarse);
    s->coarse = NULL;
    dk_constraints_free(s->con);
    free(s->unk);
    free(s->unknowns);
    free(s->target_of);
    free(s->soft_k);
    free(s->tws);
    free(s->bterms);
    sparse_release(&s->a);
    dk_cholesky_free(s->chol);
    free(s->rhs_const);
    free(s->rhs);
    free(s->rg_start);
    free(s->rg);
    free(s->xu);
    free(s->gu);
    free(s->fu);
    free(s->gprev);
    free(s->fprev);
    free(s->dg);
    free(s->df);
    free(s->targets);
    free(s->targets_prev);
    free(s->targets_prev2);
    free(s->warm);
    free(s->kinv);
    free(s->omega);
    free(s->vfull);
    free(s->nt);
    free(s->ntt);
    free(s->a_vrow);
    free(s->nt_r);
    free(s->nt_z);
    free(s->nt_p);
    free(s->nt_q);
    free(s->nt_d);
    free(s->nt_z0);
    arap_response_basis_free(s);
    memset(s, 0, sizeof *s);
}

/* A component is anchored by an eliminated vertex (dk_csys_check_components looks at those
 * itself) or a soft handle vertex. */
static int soft_anchor(const void *ctx, dk_index v)
{
    return ((const arap_system *)ctx)->soft_k[v] > 0.0;
}

static dk_status check_components(const dk_arap *ar, const arap_system *s, dk_error *err)
{
    return dk_csys_check_components(ar->mesh, s->unk, soft_anchor, s, ar->ro->iperm,
                                    ar->caller_mesh, "ARAP",
                                    "constrain a vertex there or exclude it from the region "
                                    "of interest",
                                    err);
}

typedef struct entry {
    dk_index row;
    double val;
} entry;

/* Assembles the reduced matrix A (unknowns x unknowns, both triangles, every diagonal
 * present, explicit zeros kept so that the pattern depends only on the unknown set). */
static dk_status assemble(const dk_arap *ar, arap_system *s, dk_error *err)
{
    const dk_index nu = s->nu;
    dk_index *count = calloc((size_t)nu + 1, sizeof *count);
    if (!count)
        return oom(err, "matrix assembly");
    const double work = 2.0 * (double)ar->n_terms + (double)nu; /* the three loops below */
    for (int64_t t = 0; t < ar->n_terms; t++) {
        dk_index ua = s->unk[ar->ta[t]], ub = s->unk[ar->tb[t]];
        if (ua >= 0)
            count[ua + 1] += 1 + (ub >= 0);
        if (ub >= 0)
            count[ub + 1] += 1 + (ua >= 0);
        const dk_status cs = arap_tick(ar, (double)t, work, err);
        if (cs != DK_OK) {
            free(count);
            return cs;
        }
    }
    for (dk_index u = 0; u < nu; u++)
        count[u + 1] += count[u] + 1; /* + the diagonal */
    int64_t total = count[nu];
    entry *ent = malloc(((size_t)total + 1) * sizeof *ent);
    dk_index *fill = malloc(((size_t)nu + 1) * sizeof *fill);
    if (!ent || !fill) {
        free(count);
        free(ent);
        free(fill);
        return oom(err, "matrix assembly");
    }
    for (dk_index u = 0; u < nu; u++) {
        fill[u] = count[u] + 1;
        ent[count[u]].row = u;
        ent[count[u]].val = s->soft_k[s->unknowns[u]];
    }
    dk_status st = DK_OK;
    for (int64_t t = 0; t < ar->n_terms && st == DK_OK; t++) {
        st = arap_tick(ar, (double)ar->n_terms + (double)t, work, err);
        dk_index ua = s->unk[ar->ta[t]], ub = s->unk[ar->tb[t]];
        double w = s->tws[t];
        if (ua >= 0) {
            ent[fill[ua]++] = (entry){ua, w};
            if (ub >= 0)
                ent[fill[ua]++] = (entry){ub, -w};
        }
        if (ub >= 0) {
            ent[fill[ub]++] = (entry){ub, w};
            if (ua >= 0)
                ent[fill[ub]++] = (entry){ua, -w};
        }
    }
    free(fill);
    /* Sort and merge each column in place. */
    int64_t nnz = 0;
    for (dk_index u = 0; u < nu && st == DK_OK; u++) {
        st = arap_tick(ar, 2.0 * (double)ar->n_terms + (double)u, work, err);
        entry *c = ent + count[u];
        dk_index len = count[u + 1] - count[u];
        for (dk_index i = 1; i < len; i++) {
            entry key = c[i];
            dk_index j = i - 1;
            while (j >= 0 && c[j].row > key.row) {
                c[j + 1] = c[j];
                j--;
            }
            c[j + 1] = key;
        }
        int64_t col_start = nnz;
        for (dk_index i = 0; i < len;) {
            entry e = c[i++];
            while (i < len && c[i].row == e.row)
                e.val += c[i++].val;
            ent[nnz++] = e;
        }
        count[u] = (dk_index)col_start;
    }
    if (st != DK_OK) { /* cancelled */
        free(count);
        free(ent);
        return st;
    }
    count[nu] = (dk_index)nnz;
    s->a.n_rows = s->a.n_cols = nu;
    s->a.col_start = count;
    s->a.row_index = malloc(((size_t)nnz + 1) * sizeof *s->a.row_index);
    s->a.values = malloc(((size_t)nnz + 1) * sizeof *s->a.values);
    if (!s->a.row_index || !s->a.values) {
        free(ent);
        sparse_release(&s->a);
        return oom(err, "reduced matrix");
    }
    for (int64_t k = 0; k < nnz; k++) {
        s->a.row_index[k] = ent[k].row;
        s->a.values[k] = ent[k].val;
    }
    free(ent);
    return DK_OK;
}

static int same_unknowns(const arap_system *x, const arap_system *y, dk_index n)
{
    if (!x->unk || x->nu != y->nu)
        return 0;
    return memcmp(x->unk, y->unk, (size_t)n * sizeof *x->unk) == 0;
}

/* arap_internal.h */
/* g_{v,c} of cell c for vertex v (see arap_system.rg); returns whether a term touches v. */
static int cell_gather_vector(const dk_arap *ar, const arap_system *s, dk_index c, dk_index v,
                              double g[3])
{
    int touches = 0;
    g[0] = g[1] = g[2] = 0.0;
    for (dk_index t = ar->cell_start[c]; t < ar->cell_start[c + 1]; t++) {
        const double sign = ar->ta[t] == v ? 1.0 : ar->tb[t] == v ? -1.0 : 0.0;
        if (sign == 0.0)
            continue;
        touches = 1;
        for (int d = 0; d < 3; d++)
            g[d] += sign * s->tws[t] * ar->te[3 * t + d];
    }
    return touches;
}

/* The cells that may touch vertex v: on a surface v's own and its one-ring's (a spoke
 * (c, v), or a rim of a triangle (c, v, k)); on a volume those with a term touching v, from
 * the incidence `vt` (vt_start[v] .. vt_start[v + 1] - 1). Entry q of first .. end - 1
 * (candidate_cell). */
static void candidates(const dk_arap *ar, const dk_index *vt_start, dk_index v, dk_index *first,
                       dk_index *end)
{
    if (vt_start) {
        *first = vt_start[v];
        *end = vt_start[v + 1];
    } else {
        *first = ar->mesh->ring_start[v] - 1;
        *end = ar->mesh->ring_start[v + 1];
    }
}
static dk_index candidate_cell(const dk_arap *ar, const dk_index *vt, dk_index v, dk_index q)
{
    if (vt)
        return vt[q];
    return q < ar->mesh->ring_start[v] ? v : ar->mesh->ring_index[q];
}

/* A volume's vertex-to-cell incidence: the cells with a term touching each vertex
 * (*vt_start: n + 1 offsets, *vt: the cells, ascending per vertex); both NULL on a
 * surface. */
static dk_status tet_incidence(const dk_arap *ar, dk_index **vt_start, dk_index **vt,
                               dk_error *err)
{
    *vt_start = *vt = NULL;
    if (!ar->cc_start)
        return DK_OK;
    const dk_index n = ar->n, nc = ar->nc;
    dk_index *start = calloc((size_t)n + 2, sizeof *start);
    dk_index *seen = malloc(((size_t)n + 1) * sizeof *seen);
    dk_index *cells = NULL;
    if (!start || !seen)
        goto oom;
    for (int pass = 0; pass < 2; pass++) {
        for (dk_index v = 0; v < n; v++)
            seen[v] = -1;
        for (dk_index c = 0; c < nc; c++)
            for (dk_index t = ar->cell_start[c]; t < ar->cell_start[c + 1]; t++) {
                const dk_index ends[2] = {ar->ta[t], ar->tb[t]};
                for (int k = 0; k < 2; k++)
                    if (seen[ends[k]] != c) {
                        seen[ends[k]] = c;
                        if (pass == 0)
                            start[ends[k] + 2]++;
                        else
                            cells[start[ends[k] + 1]++] = c;
                    }
            }
        if (pass == 0) {
            for (dk_index v = 0; v < n; v++)
                start[v + 2] += start[v + 1];
            if (!(cells = malloc(((size_t)start[n + 1] + 1) * sizeof *cells)))
                goto oom;
        }
    }
    free(seen);
    *vt_start = start; /* start[v] .. start[v + 1] - 1 after the fill shifted it */
    *vt = cells;
    return DK_OK;
oom:
    free(start);
    free(seen);
    free(cells);
    return oom(err, "right-hand-side map");
}

/* The rotations-to-right-hand-side map s->rg (needs s->unknowns, s->tws). Every cell with a
 * term touching v is among candidates(): O(sum of their sizes). */
static dk_status build_rhs_map(const dk_arap *ar, arap_system *s, dk_error *err)
{
    const dk_index nu = s->nu;
    double g[3];
    dk_index *vt_start, *vt;
    s->rg_start = malloc(((size_t)nu + 1) * sizeof *s->rg_start);
    if (!s->rg_start)
        return oom(err, "right-hand-side map");
    dk_status st = tet_incidence(ar, &vt_start, &vt, err);
    if (st != DK_OK)
        return st;
    int64_t k = 0;
    for (int pass = 0; pass < 2 && st == DK_OK; pass++) {
        k = 0;
        for (dk_index u = 0; u < nu; u++) {
            if ((st = arap_tick(ar, (double)pass * nu + u, 2.0 * nu, err)) != DK_OK)
                break; /* rg_start, rg: freed with the system */
            const dk_index v = s->unknowns[u];
            if (pass == 0)
                s->rg_start[u] = k;
            dk_index first, end;
            candidates(ar, vt_start, v, &first, &end);
            for (dk_index q = first; q < end; q++) {
                const dk_index c = candidate_cell(ar, vt, v, q);
                if (!cell_gather_vector(ar, s, c, v, g))
                    continue;
                if (pass == 1) {
                    memcpy(s->rg[k].g, g, sizeof g);
                    s->rg[k].cell = c;
                }
                k++;
            }
        }
        if (pass == 0 && st == DK_OK) {
            s->rg_start[nu] = k;
            s->rg = malloc(((size_t)k + 1) * sizeof *s->rg);
            if (!s->rg)
                st = oom(err, "right-hand-side map");
        }
    }
    free(vt_start);
    free(vt);
    return st;
}

/* ARAP's unknowns: free vertices, and handle vertices of weight w < 1, pulled to their
 * target by the penalty k = lambda w / (1 - w) (in the units of the ARAP energy). */
static int classify_vertex(const void *ctx, dk_index v, double *soft)
{
    const arap_system *s = ctx;
    const dk_constraints *c = s->con;
    if (c->role[v] >= 0) {
        const double w = c->handle_weights[s->target_of[v]];
        if (w < 1.0) {
            *soft = s->lambda * w / (1.0 - w);
            return 1;
        }
    }
    return c->role[v] == DK_VERTEX_FREE;
}

/* The unknowns: free vertices and soft handle vertices (their penalty k_v into soft_k);
 * each term's weight with the stiffness; the terms across the constraints' border. */
static dk_status classify(const dk_arap *ar, arap_system *s, dk_error *err)
{
    const dk_index n = ar->n;
    const dk_constraints *c = s->con;
    dk_csys_target_rows(c, s->target_of);
    /* Weights with stiffness, the ARAP diagonal, then the soft penalties. */
    double diag = 0.0, escale = 0.0;
    for (dk_index i = 0; i < ar->nc; i++) {
        const dk_status st = arap_tick(ar, i, ar->nc, err);
        if (st != DK_OK)
            return st;
        double stiffness = 0.0; /* vertex i's; on a volume the cell's corners' mean */
        if (ar->cc_start) {
            for (dk_index k = ar->cc_start[i]; k < ar->cc_start[i + 1]; k++)
                stiffness += c->stiffness[ar->cc[k]];
            stiffness /= (double)(ar->cc_start[i + 1] - ar->cc_start[i]);
        } else {
            stiffness = c->stiffness[i];
        }
        for (dk_index t = ar->cell_start[i]; t < ar->cell_start[i + 1]; t++) {
            s->tws[t] = stiffness * ar->tw[t];
            diag += 2.0 * s->tws[t];
            const double *e = ar->te + 3 * t;
            escale += s->tws[t] * (e[0] * e[0] + e[1] * e[1] + e[2] * e[2]);
        }
    }
    s->lambda = n > 0 ? diag / n : 0.0;
    s->escale = escale;
    const dk_index nu = dk_csys_number_unknowns(n, classify_vertex, s, s->unk, NULL, s->soft_k,
                                                NULL);
    s->nu = nu;
    s->n_bterms = 0;
    for (int64_t t = 0; t < ar->n_terms; t++)
        s->n_bterms += (s->unk[ar->ta[t]] >= 0) != (s->unk[ar->tb[t]] >= 0);
    s->bterms = malloc(((size_t)s->n_bterms + 1) * sizeof *s->bterms);
    if (!s->bterms)
        return oom(err, "constraint system");
    s->n_bterms = 0;
    for (int64_t t = 0; t < ar->n_terms; t++)
        if ((s->unk[ar->ta[t]] >= 0) != (s->unk[ar->tb[t]] >= 0))
            s->bterms[s->n_bterms++] = t;
    return DK_OK; /* nu == 0: every vertex constrained, solves give the constrained motion */
}

/* The per-solve buffers of the chosen solver (N = 3 nu each, column-major). */
static dk_status solve_buffers(const dk_arap *ar, arap_system *s, dk_error *err)
{
    const dk_index n = ar->n, nu = s->nu;
    s->unknowns = malloc((size_t)nu * sizeof *s->unknowns);
    size_t N = 3 * (size_t)nu, m = (size_t)ar->opt.anderson_depth;
    int accel = ar->opt.acceleration == DK_ARAP_ACCEL_ANDERSON;
    s->rhs_const = malloc(N * sizeof(double));
    s->rhs = malloc(N * sizeof(double));
    s->xu = malloc(N * sizeof(double));
    s->gu = malloc(N * sizeof(double));
    s->warm = malloc(2 * N * sizeof(double) + sizeof(double));
    if (accel) {
        s->fu = malloc(N * sizeof(double));
        s->gprev = malloc(N * sizeof(double));
        s->fprev = malloc(N * sizeof(double));
        s->dg = malloc(N * m * sizeof(double));
        s->df = malloc(N * m * sizeof(double));
    }
    const int newton = ar->opt.acceleration == DK_ARAP_ACCEL_NEWTON;
    if (newton) {
        s->kinv = malloc(6 * (size_t)ar->nc * sizeof(double) + sizeof(double));
        s->omega = malloc(3 * (size_t)ar->nc * sizeof(double) + sizeof(double));
        s->vfull = calloc(3 * (size_t)n + 1, sizeof(double));
        s->nt_r = malloc(N * sizeof(double));
        s->nt_z = malloc(N * sizeof(double));
        s->nt_p = malloc(N * sizeof(double));
        s->nt_q = malloc(N * sizeof(double));
        s->nt_d = malloc(N * sizeof(double));
        s->nt_z0 = malloc(N * sizeof(double));
    }
    if (!s->unknowns || !s->rhs_const || !s->rhs || !s->xu || !s->gu || !s->warm ||
        (accel && (!s->fu || !s->gprev || !s->fprev || !s->dg || !s->df)) ||
        (newton && (!s->kinv || !s->omega || !s->vfull || !s->nt_r || !s->nt_z || !s->nt_p ||
                    !s->nt_q || !s->nt_d || !s->nt_z0)))
        return oom(err, "solve buffers");
    for (dk_index v = 0; v < n; v++)
        if (s->unk[v] >= 0)
            s->unknowns[s->unk[v]] = v;
    return DK_OK;
}

/* Newton: the right-hand-side entries' cells and the cell terms, packed in single
 * precision for the Hessian products (see arap_system). */
static dk_status newton_terms(const dk_arap *ar, arap_system *s, dk_error *err)
{
    const int64_t ne = s->rg_start[s->nu];
    s->nt = malloc(((size_t)ne + 1) * sizeof *s->nt);
    s->ntt = malloc(((size_t)ar->n_terms + 1) * sizeof *s->ntt);
    if (!s->nt || !s->ntt)
        return oom(err, "Newton buffers");
    for (int64_t k = 0; k < ne; k++)
        s->nt[k].cell = s->rg[k].cell;
    for (int64_t t = 0; t < ar->n_terms; t++) {
        struct nt_term *q = s->ntt + t;
        for (int d = 0; d < 3; d++)
            q->e[d] = (float)ar->te[3 * t + d];
        q->w = (float)ar->tw[t];
        q->a = ar->ta[t];
        q->b = ar->tb[t];
    }
    return DK_OK;
}

/* Newton: the vertex of each matrix entry's row (the products run in the mesh layout). */
static dk_status newton_rows(arap_system *s, dk_error *err)
{
    const dk_index nnz = s->a.col_start[s->nu];
    s->a_vrow = malloc(((size_t)nnz + 1) * sizeof *s->a_vrow);
    if (!s->a_vrow)
        return oom(err, "Newton buffers");
    for (dk_index k = 0; k < nnz; k++)
        s->a_vrow[k] = s->unknowns[s->a.row_index[k]];
    return DK_OK;
}

/* Factors s->a, taking the symbolic analysis from `old` when the unknown set is the same;
 * when that numeric factorization fails, the analysis goes back to `old`, refactored with
 * its own values, so that the object keeps working with its previous constraints. Frees
 * s on failure. */
static dk_status factor(dk_arap *ar, arap_system *old, arap_system *s, dk_error *err)
{
    dk_csys_counts counts = {ar->analysis_count, ar->factorization_count};
    const int same = old && same_unknowns(old, s, ar->n); /* explicit zeros: same pattern */
    dk_status st = dk_csys_factor(&s->a, &s->chol, old ? &old->chol : NULL,
                                  old ? &old->a : NULL, same, DK_CSYS_REFACTOR_ALWAYS,
                                  ar->team, &counts, ar->prog,
                                  ar->prog_base + ARAP_PHASE_ANALYZE, err);
    if (st != DK_ERR_CANCELLED) { /* a cancelled rebind changes nothing, its counters too */
        ar->analysis_count = counts.analysis_count;
        ar->factorization_count = counts.factorization_count;
    }
    if (st == DK_OK)
        return DK_OK;
    /* the caller's vertex of the failing column, not the internal matrix column */
    long vertex = -1;
    if (st == DK_ERR_NOT_POSITIVE_DEFINITE && err && err->column > 0 && err->column <= s->nu)
        vertex = (long)ar->ro->perm[s->unknowns[err->column - 1]];
    arap_system_free(s);
    if (st == DK_ERR_CANCELLED)
        return st;
    if (st == DK_ERR_NOT_POSITIVE_DEFINITE) {
        const int clamped = ar->opt.weights != DK_ARAP_WEIGHTS_COTANGENT;
        char at[48] = "";
        if (vertex >= 0)
            snprintf(at, sizeof at, " at vertex %ld", vertex);
        dk_error_set(err, DK_ERR_DEGENERATE,
                     "ARAP: the reduced matrix is not positive definite%s (%s)", at,
                     ar->cc_start ? "degenerate tetrahedra or triangles around it, or a part "
                                    "held only along a line"
                     : clamped    ? "degenerate triangles around it, or a part held only "
                                    "along a line"
                                  : "degenerate triangles or negative cotangent weights; try "
                                    "weights='clamped_cotangent'");
        return DK_ERR_DEGENERATE;
    }
    return dk_error_prefix(err, "ARAP: factorization");
}

dk_status arap_system_build(dk_arap *ar, const dk_constraint_desc *desc, arap_system *old,
                            arap_system *s, dk_error *err)
{
    const dk_index n = ar->n;
    memset(s, 0, sizeof *s);
    dk_status st = arap_phase(ar, ARAP_PHASE_CONSTRAINTS, err);
    if (st != DK_OK)
        return st;
    st = dk_constraints_create(ar->mesh, desc, &s->con, err);
    if (st != DK_OK)
        return dk_error_prefix(err, "ARAP");
    const dk_constraints *c = s->con;
    s->unk = malloc(((size_t)n + 1) * sizeof *s->unk);
    s->target_of = malloc(((size_t)n + 1) * sizeof *s->target_of);
    s->soft_k = calloc((size_t)n + 1, sizeof *s->soft_k);
    s->tws = malloc(((size_t)ar->n_terms + 1) * sizeof *s->tws);
    s->targets = malloc(((size_t)c->n_handle_vertices * 3 + 1) * sizeof *s->targets);
    s->targets_prev = malloc(((size_t)c->n_handle_vertices * 3 + 1) * sizeof *s->targets_prev);
    s->targets_prev2 = malloc(((size_t)c->n_handle_vertices * 3 + 1) * sizeof *s->targets_prev2);
    if (!s->unk || !s->target_of || !s->soft_k || !s->tws || !s->targets || !s->targets_prev ||
        !s->targets_prev2)
        st = oom(err, "constraint system");
    const int newton = ar->opt.acceleration == DK_ARAP_ACCEL_NEWTON;
    if (st == DK_OK)
        st = classify(ar, s, err);
    if (st == DK_OK && s->nu == 0)
        return DK_OK; /* nothing to solve: no system, no factor (solve_impl) */
    if (st == DK_OK)
        st = arap_phase(ar, ARAP_PHASE_SYSTEM, err);
    if (st == DK_OK)
        st = solve_buffers(ar, s, err);
    if (st == DK_OK)
        st = build_rhs_map(ar, s, err);
    if (st == DK_OK && newton)
        st = newton_terms(ar, s, err);
    if (st == DK_OK)
        st = check_components(ar, s, err);
    if (st == DK_OK)
        st = arap_phase(ar, ARAP_PHASE_ASSEMBLE, err);
    if (st == DK_OK)
        st = assemble(ar, s, err);
    if (st == DK_OK && newton)
        st = newton_rows(s, err);
    if (st != DK_OK) {
        arap_system_free(s);
        return st;
    }
    const dk_csys_counts before = {ar->analysis_count, ar->factorization_count};
    if (old && old->nu == 0)
        old = NULL;
    const int had_factor = old && old->chol;
    st = factor(ar, old, s, err);
    if (st != DK_OK)
        return st;
    if ((st = arap_phase(ar, ARAP_PHASE_BASIS, err)) == DK_OK) {
        arap_response_basis_build(ar, s);
        if ((st = arap_phase(ar, ARAP_PHASE_COARSE, err)) == DK_OK)
            st = arap_coarse_build(ar, s, &s->coarse, err);
    }
    if (st != DK_OK) {
        /* cancelled after the factor (or out of memory at the coarse level): a rebind that
         * took over the old analysis (the same unknowns) gives it back, refactored with the
         * old values -- that stop costs the factorization -- and its counters stay as they
         * were */
        if (had_factor && !old->chol && s->chol) {
            old->chol = s->chol;
            s->chol = NULL;
            dk_error ignored = {0};
            if (dk_cholesky_factorize(old->chol, &old->a, &ignored) != DK_OK) {
                dk_cholesky_free(old->chol); /* cannot happen: it factored before */
                old->chol = NULL;
            }
        }
        ar->analysis_count = before.analysis_count;
        ar->factorization_count = before.factorization_count;
        arap_system_free(s);
        return st;
    }
    return DK_OK;
}

void arap_system_edges_changed(const dk_arap *ar, arap_system *s)
{
    double escale = 0.0; /* classify's sum, in its order */
    for (int64_t t = 0; t < ar->n_terms; t++) {
        const double *e = ar->te + 3 * t;
        escale += s->tws[t] * (e[0] * e[0] + e[1] * e[1] + e[2] * e[2]);
    }
    s->escale = escale;
    if (s->rg)
        for (dk_index u = 0; u < s->nu; u++)
            for (int64_t k = s->rg_start[u]; k < s->rg_start[u + 1]; k++)
                cell_gather_vector(ar, s, s->rg[k].cell, s->unknowns[u], s->rg[k].g);
    if (s->ntt)
        for (int64_t t = 0; t < ar->n_terms; t++)
            for (int d = 0; d < 3; d++)
                s->ntt[t].e[d] = (float)ar->te[3 * t + d];
}
