/* DeformKit EigenDeformation: eq. 1, the skeletons and Steps 1-2 (eigen_internal.h). */
#include "eigen_internal.h"

#include <math.h>

#include <cblas.h>
#include <lapacke.h>
#include <stdlib.h>
#include <string.h>

/* b (m x 3, column-major) = U_m^T x, for x n x 3 row-major: x is first copied into
 * column-major scratch, so that both operands are read along their columns. */
void eigen_project(const dk_eigen *e, int m, const double *x, double *b)
{
    const dk_index n = e->n;
    for (dk_index i = 0; i < n; i++)
        for (int r = 0; r < 3; r++)
            e->cm[(size_t)r * n + i] = x[3 * (size_t)i + r];
    cblas_dgemm(CblasColMajor, CblasTrans, CblasNoTrans, m, 3, (int)n, 1.0, e->U, (int)n, e->cm,
                (int)n, 0.0, b, m);
}

/* Step 2: A = Phi_m^-1 b in place (b m x 3), then out = U_m A (n x 3 row-major), computed
 * column-major (U_m read along its columns) and transposed. The factor of Phi_m is the
 * leading block of Phi_K's. */
void eigen_fit(const dk_eigen *e, int m, double *b, double *out)
{
    const dk_index n = e->n;
    LAPACKE_dpotrs(LAPACK_COL_MAJOR, 'U', m, 3, e->chol, e->K, b, m);
    cblas_dgemm(CblasColMajor, CblasNoTrans, CblasNoTrans, (int)n, 3, m, 1.0, e->U, (int)n, b, m,
                0.0, e->cm, (int)n);
    for (dk_index i = 0; i < n; i++)
        for (int r = 0; r < 3; r++)
            out[3 * (size_t)i + r] = e->cm[(size_t)r * n + i];
}

void eigen_level_free(level *L)
{
    free(L->p);
    free(L->b0);
    free(L->detail);
    free(L->coord);
    free(L->frame_nb);
    memset(L, 0, sizeof *L);
}

static dk_status level_alloc(level *L, int m, dk_index n)
{
    L->m = m;
    L->p = malloc(3 * (size_t)n * sizeof *L->p);
    L->b0 = malloc(3 * (size_t)m * sizeof *L->b0);
    L->detail = malloc(3 * (size_t)n * sizeof *L->detail);
    L->coord = malloc(3 * (size_t)n * sizeof *L->coord);
    L->frame_nb = malloc((size_t)n * sizeof *L->frame_nb);
    return (L->p && L->b0 && L->detail && L->coord && L->frame_nb) ? DK_OK
                                                                   : DK_ERR_OUT_OF_MEMORY;
}

/* eigen_internal.h. Two eigenvalues are one when they differ by under 1e-8 of the larger
 * (a symmetric mesh's repeated eigenvalues agree to ~1e-13; a scan's nearest distinct ones
 * differ by far more), or both are zeros (below 1e-12 of the largest computed). */
static int same_eigenvalue(const dk_eigen *e, double a, double b)
{
    const double zero = 1e-12 * fabs(e->evals[e->K - 1]);
    return fabs(a - b) <= 1e-8 * fmax(fabs(a), fabs(b)) || (fabs(a) <= zero && fabs(b) <= zero);
}

int eigen_whole_count(const dk_eigen *e, int m)
{
    if (m <= 0 || m >= e->K || !same_eigenvalue(e, e->evals[m - 1], e->evals[m]))
        return m;
    int up = m;
    while (up < e->K && same_eigenvalue(e, e->evals[up - 1], e->evals[up]))
        up++;
    if (up < e->K)
        return up; /* the eigenspace ends within the computed ones */
    int down = m;
    while (down > 1 && same_eigenvalue(e, e->evals[down - 1], e->evals[down]))
        down--;
    return down;
}

/* 3. the skeletons of the levels for m (and n'), their details and frames. m is taken to
 * the end of the eigenspace it cuts (eigen_whole_count), so that the fit is the mesh's,
 * not the eigensolver's choice of basis inside that eigenspace. */
dk_status eigen_skeletons(dk_eigen *e, int m, dk_error *err)
{
    const dk_index n = e->n;
    m = eigen_whole_count(e, m);
    const int n2 = eigen_whole_count(e, e->n_prime); /* n', its eigenspace whole too */
    const int two = e->opt.refine > m && n2 > m;
    eigen_level_free(&e->lv[0]);
    eigen_level_free(&e->lv[1]);
    e->m = m;
    e->n_levels = two ? 2 : 1;
    for (int k = 0; k < e->n_levels; k++)
        if (level_alloc(&e->lv[k], k == 0 ? m : n2, n) != DK_OK)
            return eigen_oom(err, "skeletons");
    for (int k = 0; k < e->n_levels; k++) { /* eq. 1 fitted to the mesh: K_m */
        level *L = &e->lv[k];
        eigen_project(e, L->m, e->mesh->positions, e->b);
        eigen_fit(e, L->m, e->b, L->p);
        eigen_project(e, L->m, L->p, L->b0);
    }
    for (int k = 0; k < e->n_levels; k++) { /* details to the next level, in frames */
        level *L = &e->lv[k];
        const double *next = k + 1 < e->n_levels ? e->lv[k + 1].p : e->mesh->positions;
        for (size_t i = 0; i < 3 * (size_t)n; i++)
            L->detail[i] = next[i] - L->p[i];
        eigen_record_frames(e, L, e->normals);
    }
    return DK_OK;
}

/* Step 1 on level L's skeleton into e->ptil, and Step 2's right-hand side from R's rows
 * alone: b = b0 + U_m^T (p~ - p), the change being zero outside R. A vertex v of group h
 * with target t and linear part A moves its skeleton point p to t - A (v - p): for a
 * transform T, T p; for a position (A = I), p + (t - v). */
void eigen_step1_step2_rhs(dk_eigen *e, const level *L)
{
    const dk_constraints *c = e->r.con;
    const dk_index n = e->n;
    memcpy(e->ptil, L->p, 3 * (size_t)n * sizeof(double));
    memcpy(e->b, L->b0, 3 * (size_t)L->m * sizeof(double));
    for (dk_index h = 0; h < c->n_handles; h++)
        for (dk_index q = c->handle_start[h]; q < c->handle_start[h + 1]; q++) {
            const dk_index i = c->handle_vertices[q];
            const double *p = L->p + 3 * (size_t)i, *v = e->mesh->positions + 3 * (size_t)i;
            const double *tg = e->r.target + 3 * (size_t)q, *A = e->r.lin + 9 * (size_t)h;
            double *pt = e->ptil + 3 * (size_t)i;
            for (int r = 0; r < 3; r++)
                pt[r] = tg[r] - (A[3 * r] * (v[0] - p[0]) + A[3 * r + 1] * (v[1] - p[1]) +
                                 A[3 * r + 2] * (v[2] - p[2]));
            for (int r = 0; r < 3; r++) {
                const double dp = pt[r] - p[r];
                if (dp != 0.0)
                    cblas_daxpy(L->m, dp, e->U + i, (int)n, e->b + (size_t)r * L->m, 1);
            }
        }
}
