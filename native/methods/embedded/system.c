/* DeformKit embedded deformation: the fixed nodes and J^T J's block pattern
 * (embedded_internal.h). */
#include "embedded_internal.h"

void ed_system_free(ed_system *s)
{
    dk_constraints_free(s->con);
    free(s->node_unknown);
    free(s->free_nodes);
    free(s->pos_vertex);
    free(s->pos_target_row);
    free(s->targets);
    free(s->blk_start);
    free(s->blk_node);
    free(s->kblk);
    free(s->rot);
    free(s->rot_spare);
    free(s->grad_spare);
    free(s->kept);
    free(s->edge_blk);
    free(s->pos_blk);
    free(s->base);
    free(s->red);
    free(s->nl_start);
    free(s->nl_node);
    free(s->nl_off);
    dk_sparse_free(s->S);
    free(s->S_base);
    free(s->S_part);
    free(s->S_diag);
    free(s->cl_start);
    free(s->cl_pos);
    free(s->w_start);
    free(s->W);
    free(s->lfac);
    free(s->rhs);
    dk_cholesky_free(s->chol);
    free(s->grad);
    free(s->step);
    free(s->x_try);
    memset(s, 0, sizeof *s);
}

/* A slot's coordinate d (R[d][e] at 3 d + e, t[d] at 9 + d), and the c-th slot (0..3, in
 * ascending order) of coordinate d. The regularization and positional residuals of
 * coordinate d involve only those slots, so blocks between different nodes are nonzero only
 * between slots of the same coordinate; the rotation residuals couple the coordinates, but
 * within one node. */

/* The block of free nodes (u, v), or -1 when either is constant or they share no residual. */
int64_t ed_block_of(const ed_system *s, dk_index u, dk_index v)
{
    if (u < 0 || v < 0)
        return -1;
    dk_index lo = s->blk_start[u], hi = s->blk_start[u + 1] - 1;
    while (lo <= hi) {
        const dk_index mid = lo + (hi - lo) / 2;
        if (s->blk_node[mid] == v)
            return mid;
        if (s->blk_node[mid] < v)
            lo = mid + 1;
        else
            hi = mid - 1;
    }
    return -1;
}

/* Which nodes are constants, the free numbering, and the positional terms. */
static dk_status classify(const dk_embedded *ed, ed_system *s, dk_error *err)
{
    const dk_index n = ed->n, m = ed->m, k = ed->k;
    const dk_constraints *c = s->con;
    unsigned char *moves = calloc((size_t)m + 1, 1);
    dk_index *target_of = malloc(((size_t)n + 1) * sizeof *target_of);
    s->node_unknown = malloc(((size_t)m + 1) * sizeof *s->node_unknown);
    s->free_nodes = malloc(((size_t)m + 1) * sizeof *s->free_nodes);
    s->pos_vertex = malloc(((size_t)n + 1) * sizeof *s->pos_vertex);
    s->pos_target_row = malloc(((size_t)n + 1) * sizeof *s->pos_target_row);
    s->targets = calloc(3 * (size_t)c->n_handle_vertices + 1, sizeof *s->targets);
    dk_status st = DK_OK;
    if (!moves || !target_of || !s->node_unknown || !s->free_nodes || !s->pos_vertex ||
        !s->pos_target_row || !s->targets) {
        st = ed_oom(err, "constraint system");
        goto done;
    }
    /* the paper's rule: a node that influences a fixed vertex is a constant, so fixed
     * vertices stay exactly at rest (all their nodes are the identity). Not for held
     * vertices (loose geometry nothing constrains, dk_constraints.h): they are put at rest
     * in ed_apply(), and freezing their nodes would freeze the surface around them. */
    unsigned char *held = moves; /* reused: 1 = influences a fixed vertex */
    for (dk_index v = 0; v < n; v++)
        if (c->role[v] == DK_VERTEX_FIXED && !c->held[v])
            for (dk_index q = 0; q < k; q++)
                if (ed->nb[(size_t)v * k + q] >= 0)
                    held[ed->nb[(size_t)v * k + q]] = 1;
    s->n_free = 0;
    for (dk_index j = 0; j < m; j++) {
        s->node_unknown[j] = !held[j] ? s->n_free : -1;
        if (!held[j])
            s->free_nodes[s->n_free++] = j;
    }
    if (s->n_free == 0) {
        st = dk_error_set(err, DK_ERR_INVALID_ARGUMENT,
                          "EmbeddedDeformation: every node influences a fixed vertex, so "
                          "every node is a constant and nothing can move (fix fewer "
                          "vertices or use more nodes)");
        goto done;
    }
    for (dk_index v = 0; v < n; v++)
        target_of[v] = -1;
    for (dk_index i = 0; i < c->n_handle_vertices; i++)
        target_of[c->handle_vertices[i]] = i;
    /* the terms some free node moves first, then those of constant nodes only (a fixed
     * vertex's: their residuals do not depend on the unknowns, ed_evaluate()) */
    s->n_pos = 0;
    for (int moving = 1; moving >= 0; moving--) {
        for (dk_index v = 0; v < n; v++) {
            if (c->role[v] < 0)
                continue;
            int any = 0;
            for (dk_index q = 0; q < k; q++) {
                const dk_index j = ed->nb[(size_t)v * k + q];
                any |= j >= 0 && s->node_unknown[j] >= 0;
            }
            if (any != moving)
                continue;
            s->pos_vertex[s->n_pos] = v;
            s->pos_target_row[s->n_pos] = target_of[v];
            s->n_pos++;
        }
        if (moving)
            s->n_pos_moving = s->n_pos;
    }
done:
    free(moves);
    free(target_of);
    return st;
}

/* The blocks of J^T J: every free node with itself, its free graph neighbours, and the free
 * nodes it shares a positional term with (which makes both "kept", schur.c). */
static dk_status block_pattern(const dk_embedded *ed, ed_system *s, dk_error *err)
{
    const dk_index k = ed->k, nf = s->n_free;
    int64_t cap = nf + 2 * (int64_t)ed->n_edges + (int64_t)s->n_pos * k * k + 1;
    int64_t *pairs = malloc((size_t)cap * sizeof *pairs), np = 0;
    s->kept = calloc((size_t)nf + 1, 1);
    if (!pairs || !s->kept) {
        free(pairs);
        return ed_oom(err, "matrix pattern");
    }
    for (dk_index u = 0; u < nf; u++)
        pairs[np++] = (int64_t)u * nf + u;
    for (dk_index e = 0; e < ed->n_edges; e++) {
        const dk_index a = s->node_unknown[ed->edges[2 * e]];
        const dk_index b = s->node_unknown[ed->edges[2 * e + 1]];
        if (a >= 0 && b >= 0) {
            pairs[np++] = (int64_t)a * nf + b;
            pairs[np++] = (int64_t)b * nf + a;
        }
    }
    for (dk_index l = 0; l < s->n_pos; l++) {
        const dk_index *nb = ed->nb + (size_t)s->pos_vertex[l] * k;
        for (dk_index p = 0; p < k; p++)
            for (dk_index q = 0; q < k; q++) {
                const dk_index a = nb[p] >= 0 ? s->node_unknown[nb[p]] : -1;
                const dk_index b = nb[q] >= 0 ? s->node_unknown[nb[q]] : -1;
                if (a >= 0 && b >= 0) {
                    pairs[np++] = (int64_t)a * nf + b;
                    if (a != b)
                        s->kept[a] = s->kept[b] = 1;
                }
            }
    }
    qsort(pairs, (size_t)np, sizeof *pairs, cmp_i64);
    int64_t nb = 0;
    for (int64_t i = 0; i < np; i++)
        if (i == 0 || pairs[i] != pairs[i - 1])
            pairs[nb++] = pairs[i];
    s->n_blocks = nb;
    s->blk_start = calloc((size_t)nf + 1, sizeof *s->blk_start);
    s->blk_node = malloc(((size_t)nb + 1) * sizeof *s->blk_node);
    s->kblk = malloc(((size_t)nb * 16 + 1) * sizeof *s->kblk);
    s->rot = calloc(81 * (size_t)nf + 1, sizeof *s->rot);
    if (!s->blk_start || !s->blk_node || !s->kblk || !s->rot) {
        free(pairs);
        return ed_oom(err, "matrix pattern");
    }
    for (int64_t i = 0; i < nb; i++) {
        s->blk_node[i] = (dk_index)(pairs[i] % nf);
        s->blk_start[pairs[i] / nf + 1]++;
    }
    for (dk_index u = 0; u < nf; u++)
        s->blk_start[u + 1] += s->blk_start[u];
    free(pairs);
    return DK_OK;
}

/* The per-residual block indices, the step's buffers, and the reduced system. */
static dk_status matrix(dk_embedded *ed, ed_system *s, dk_error *err)
{
    const dk_index nf = s->n_free, k = ed->k;
    s->edge_blk = malloc((4 * 2 * (size_t)ed->n_edges + 1) * sizeof *s->edge_blk);
    s->pos_blk = malloc(((size_t)s->n_pos * k * k + 1) * sizeof *s->pos_blk);
    s->grad = malloc((12 * (size_t)nf + 1) * sizeof *s->grad);
    s->grad_spare = malloc((12 * (size_t)nf + 1) * sizeof *s->grad_spare);
    s->rot_spare = malloc((81 * (size_t)nf + 1) * sizeof *s->rot_spare);
    s->step = malloc((12 * (size_t)nf + 1) * sizeof *s->step);
    s->x_try = malloc((12 * (size_t)ed->m + 1) * sizeof *s->x_try);
    if (!s->edge_blk || !s->pos_blk || !s->grad || !s->grad_spare || !s->rot_spare ||
        !s->step || !s->x_try)
        return ed_oom(err, "matrix");
    for (dk_index e = 0; e < ed->n_edges; e++)
        for (int dir = 0; dir < 2; dir++) {
            const dk_index j = s->node_unknown[ed->edges[2 * e + dir]];
            const dk_index q = s->node_unknown[ed->edges[2 * e + 1 - dir]];
            int64_t *b = s->edge_blk + 8 * (size_t)e + 4 * dir;
            b[0] = ed_block_of(s, j, j);
            b[1] = ed_block_of(s, j, q);
            b[2] = ed_block_of(s, q, j);
            b[3] = ed_block_of(s, q, q);
        }
    for (dk_index l = 0; l < s->n_pos; l++) {
        const dk_index *nb = ed->nb + (size_t)s->pos_vertex[l] * k;
        for (dk_index p = 0; p < k; p++)
            for (dk_index q = 0; q < k; q++)
                s->pos_blk[((size_t)l * k + p) * k + q] =
                    ed_block_of(s, nb[p] >= 0 ? s->node_unknown[nb[p]] : -1,
                             nb[q] >= 0 ? s->node_unknown[nb[q]] : -1);
    }
    return ed_reduced_build(ed, s, err);
}

/* `phase`: the index of "constraints" in the running bind's or rebind's phase table (the
 * analysis follows it). */
dk_status ed_system_build(dk_embedded *ed, const dk_constraint_desc *desc, ed_system *s,
                              int phase, dk_error *err)
{
    memset(s, 0, sizeof *s);
    dk_status st = dk_progress_begin(ed->prog, phase, err);
    if (st != DK_OK)
        return st;
    st = dk_constraints_create(ed->mesh, desc, &s->con, err);
    if (st != DK_OK)
        return dk_error_prefix(err, "EmbeddedDeformation");
    st = classify(ed, s, err);
    if (st == DK_OK)
        st = block_pattern(ed, s, err);
    if (st == DK_OK)
        st = dk_progress_begin(ed->prog, phase + 1, err);
    if (st == DK_OK)
        st = matrix(ed, s, err);
    if (st != DK_OK)
        ed_system_free(s);
    return st;
}
