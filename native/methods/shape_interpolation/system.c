/* Shape interpolation: the edge weights and the least-squares system of the positions
 * (dk_shape_interpolation.h): E(x) = sum_edges c_ij |x_i - x_j - d_ij|^2 over the unknowns,
 * every other vertex eliminated at its value (fixed, handle, or the pinned vertex of a part
 * without either, which the driver places by its mean afterwards). */
#include "si_internal.h"

#include <math.h>
#include <stdlib.h>
#include <string.h>

#include "dk_operators.h"

/* The smallest weight, as a part of the mean: every edge keeps its two vertices tied, so a
 * vertex whose triangles are all degenerate or obtuse still has a place. */
#define WEIGHT_FLOOR 1e-6

dk_status si_edge_weights(const dk_mesh *mesh, dk_shape_interpolation_weights kind,
                          double *weights, dk_error *err)
{
    const dk_index ne = mesh->n_edges;
    if (kind == DK_SI_WEIGHTS_UNIFORM) {
        for (dk_index e = 0; e < ne; e++)
            weights[e] = 1.0;
        return DK_OK;
    }
    dk_cotangent_weights(mesh, mesh->positions, weights);
    double sum = 0.0;
    dk_index count = 0;
    for (dk_index e = 0; e < ne; e++)
        if (weights[e] > 0.0) {
            sum += weights[e];
            count++;
        }
    if (count == 0 && ne > 0)
        return dk_error_set(err, DK_ERR_DEGENERATE,
                            "ShapeInterpolation: no edge has a positive cotangent weight (every "
                            "triangle is degenerate); use edge_weights='uniform'");
    const double floor_w = count ? WEIGHT_FLOOR * sum / (double)count : 0.0;
    for (dk_index e = 0; e < ne; e++) {
        if (kind == DK_SI_WEIGHTS_CLAMPED_COTANGENT)
            weights[e] = fmax(weights[e], floor_w);
        else if (fabs(weights[e]) < floor_w)
            weights[e] = floor_w;
    }
    return DK_OK;
}

void si_system_free(si_system *s)
{
    if (!s)
        return;
    dk_constraints_free(s->con);
    free(s->unk);
    free(s->unknowns);
    free(s->target_of);
    free(s->free_part);
    dk_sparse_free(s->a);
    dk_cholesky_free(s->chol);
    memset(s, 0, sizeof *s);
}

/* The reduced matrix: for each unknown its weighted degree on the diagonal, -c_ij for each
 * edge between two unknowns (upper triangle). */
static dk_status assemble(const dk_mesh *m, const double *w, const si_system *s, dk_sparse **out,
                          dk_error *err)
{
    int64_t count = s->nu;
    for (dk_index e = 0; e < m->n_edges; e++)
        count += s->unk[m->edges[2 * (size_t)e]] >= 0 && s->unk[m->edges[2 * (size_t)e + 1]] >= 0;
    dk_index *rows = malloc((size_t)count * sizeof *rows + 1);
    dk_index *cols = malloc((size_t)count * sizeof *cols + 1);
    double *vals = malloc((size_t)count * sizeof *vals + 1);
    if (!rows || !cols || !vals) {
        free(rows);
        free(cols);
        free(vals);
        return dk_error_set(err, DK_ERR_OUT_OF_MEMORY, "ShapeInterpolation: out of memory "
                            "(system of %d unknowns)", (int)s->nu);
    }
    for (dk_index u = 0; u < s->nu; u++) {
        rows[u] = cols[u] = u;
        vals[u] = 0.0;
    }
    int64_t k = s->nu;
    for (dk_index e = 0; e < m->n_edges; e++) {
        const dk_index ua = s->unk[m->edges[2 * (size_t)e]], ub = s->unk[m->edges[2 * (size_t)e + 1]];
        if (ua >= 0)
            vals[ua] += w[e];
        if (ub >= 0)
            vals[ub] += w[e];
        if (ua >= 0 && ub >= 0) {
            rows[k] = ua < ub ? ua : ub;
            cols[k] = ua < ub ? ub : ua;
            vals[k++] = -w[e];
        }
    }
    const dk_status st = dk_sparse_from_triplets(s->nu, s->nu, count, rows, cols, vals, out, err);
    free(rows);
    free(cols);
    free(vals);
    return st;
}

static int same_unknowns(const si_system *a, const si_system *b, dk_index n)
{
    return a->nu == b->nu && memcmp(a->unk, b->unk, (size_t)n * sizeof *a->unk) == 0;
}

dk_status si_system_build(const dk_mesh *mesh, const double *edge_weights, dk_constraints *con,
                          si_system *old, dk_team *team, dk_csys_counts *counts,
                          dk_progress *progress, int phase, si_system *out, dk_error *err)
{
    memset(out, 0, sizeof *out);
    out->con = con;
    const dk_index n = mesh->n_vertices, nc = mesh->report.n_components;
    out->unk = malloc((size_t)n * sizeof *out->unk + 1);
    out->unknowns = malloc((size_t)n * sizeof *out->unknowns + 1);
    out->target_of = malloc((size_t)n * sizeof *out->target_of + 1);
    out->free_part = malloc((size_t)nc + 1);
    unsigned char *pinned = calloc((size_t)nc + 1, 1);
    if (!out->unk || !out->unknowns || !out->target_of || !out->free_part || !pinned) {
        free(pinned);
        si_system_free(out);
        return dk_error_set(err, DK_ERR_OUT_OF_MEMORY, "ShapeInterpolation: out of memory "
                            "(constraint system)");
    }
    dk_csys_target_rows(con, out->target_of);
    memset(out->free_part, 1, (size_t)nc);
    for (dk_index v = 0; v < n; v++)
        if (con->role[v] != DK_VERTEX_FREE)
            out->free_part[mesh->component[v]] = 0;
    out->nu = 0;
    for (dk_index v = 0; v < n; v++) {
        const dk_index c = mesh->component[v];
        if (con->role[v] != DK_VERTEX_FREE || (out->free_part[c] && !pinned[c])) {
            pinned[c] = 1; /* the first vertex of a free part is pinned */
            out->unk[v] = -1;
        } else {
            out->unknowns[out->nu] = v;
            out->unk[v] = out->nu++;
        }
    }
    free(pinned);
    dk_status st = DK_OK;
    if (out->nu > 0) {
        st = assemble(mesh, edge_weights, out, &out->a, err);
        if (st == DK_OK) {
            const int same = old && old->chol && same_unknowns(old, out, n);
            st = dk_csys_factor(out->a, &out->chol, old ? &old->chol : NULL, old ? old->a : NULL,
                                same, DK_CSYS_REFACTOR_IF_CHANGED, team, counts, progress, phase,
                                err);
        }
    }
    if (st != DK_OK)
        si_system_free(out); /* `con` with it: taken over */
    return st;
}
