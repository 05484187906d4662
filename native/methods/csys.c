/* DeformKit: the shared constrained-system steps (dk_csys.h). */
#include "dk_csys.h"

#include <stdlib.h>
#include <string.h>

void dk_csys_target_rows(const dk_constraints *c, dk_index *target_of)
{
    for (dk_index v = 0; v < c->n_vertices; v++)
        target_of[v] = -1;
    for (dk_index k = 0; k < c->n_handle_vertices; k++)
        target_of[c->handle_vertices[k]] = k;
}

dk_index dk_csys_number_unknowns(dk_index n, dk_csys_classify_fn classify, const void *ctx,
                                 dk_index *unknown_index, dk_index *unknowns, double *soft,
                                 dk_index *n_soft)
{
    dk_index nu = 0, ns = 0;
    for (dk_index v = 0; v < n; v++) {
        double w = 0.0;
        const int unknown = classify(ctx, v, &w);
        if (soft)
            soft[v] = w;
        ns += w > 0.0;
        unknown_index[v] = unknown ? nu : -1;
        if (unknown) {
            if (unknowns)
                unknowns[nu] = v;
            nu++;
        }
    }
    if (n_soft)
        *n_soft = ns;
    return nu;
}

dk_status dk_csys_check_components(const dk_mesh *mesh, const dk_index *unknown_index,
                                   dk_csys_anchor_fn anchored, const void *ctx,
                                   const dk_index *iperm, const dk_mesh *caller_mesh,
                                   const char *who, const char *hint, dk_error *err)
{
    const dk_index n = mesh->n_vertices;
    const dk_index nc = mesh->report.n_components > 0 ? mesh->report.n_components : 1;
    unsigned char *pinned = calloc((size_t)nc, 1);
    if (!pinned)
        return dk_error_set(err, DK_ERR_OUT_OF_MEMORY, "%s: out of memory (component check)",
                            who);
    for (dk_index i = 0; i < n; i++)
        if (unknown_index[i] < 0 || anchored(ctx, i))
            pinned[mesh->component[i]] = 1;
    dk_status st = DK_OK;
    /* in the caller's order, so that the message names the caller's first such vertex */
    for (dk_index v = 0; v < n && st == DK_OK; v++) {
        const dk_index i = iperm ? iperm[v] : v;
        if (unknown_index[i] >= 0 && !pinned[mesh->component[i]]) {
            const dk_mesh *cm = caller_mesh ? caller_mesh : mesh;
            st = dk_error_set(err, DK_ERR_DEGENERATE,
                              "%s: connected component %d (the component of vertex %d) has "
                              "free vertices but no handle or fixed vertex, so its position "
                              "is undetermined; %s",
                              who, (int)cm->component[v], (int)v, hint);
        }
    }
    free(pinned);
    return st;
}

int dk_csys_same_pattern(const dk_sparse *a, const dk_sparse *b)
{
    if (a->n_rows != b->n_rows || a->n_cols != b->n_cols)
        return 0;
    if (memcmp(a->col_start, b->col_start, sizeof(dk_index) * ((size_t)a->n_cols + 1)) != 0)
        return 0;
    return memcmp(a->row_index, b->row_index,
                  sizeof(dk_index) * (size_t)a->col_start[a->n_cols]) == 0;
}

static int same_values(const dk_sparse *a, const dk_sparse *b)
{
    return memcmp(a->values, b->values, sizeof(double) * (size_t)a->col_start[a->n_cols]) == 0;
}

dk_status dk_csys_factor(const dk_sparse *a, dk_cholesky **chol, dk_cholesky **old_chol,
                         const dk_sparse *old_a, int same_pattern, dk_csys_refactor policy,
                         dk_team *team, dk_csys_counts *counts, dk_progress *progress,
                         int analyze_phase, dk_error *err)
{
    dk_status st;
    *chol = NULL;
    if (old_chol && *old_chol && same_pattern) {
        /* the same pattern: keep the symbolic analysis */
        if (!(policy == DK_CSYS_REFACTOR_IF_CHANGED && same_values(a, old_a)) &&
            (st = dk_progress_begin(progress, analyze_phase + 1, err)) != DK_OK)
            return st; /* before anything moved: old_chol is untouched */
        *chol = *old_chol;
        *old_chol = NULL;
        if (policy == DK_CSYS_REFACTOR_IF_CHANGED && same_values(a, old_a))
            return DK_OK;
        st = dk_cholesky_factorize(*chol, a, err);
        if (st == DK_OK) {
            counts->factorization_count++;
            return DK_OK;
        }
        /* give the analysis back, with the old values, so the object stays usable */
        *old_chol = *chol;
        *chol = NULL;
        dk_error ignored = {0};
        if (dk_cholesky_factorize(*old_chol, old_a, &ignored) != DK_OK) {
            dk_cholesky_free(*old_chol);
            *old_chol = NULL;
        }
        return st;
    }
    if ((st = dk_progress_begin(progress, analyze_phase, err)) != DK_OK)
        return st;
    st = dk_cholesky_analyze(a, chol, err);
    if (st != DK_OK)
        return st;
    dk_cholesky_set_team(*chol, team);
    counts->analysis_count++;
    if ((st = dk_progress_begin(progress, analyze_phase + 1, err)) != DK_OK) {
        dk_cholesky_free(*chol);
        *chol = NULL;
        return st;
    }
    st = dk_cholesky_factorize(*chol, a, err);
    if (st == DK_OK) {
        counts->factorization_count++;
        return DK_OK;
    }
    dk_cholesky_free(*chol);
    *chol = NULL;
    return st;
}
