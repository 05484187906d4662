/* DeformKit EigenDeformation: a solve's targets as the groups' motions
 * (eigen_internal.h). */
#include "eigen_internal.h"

#include <math.h>
#include <stdlib.h>
#include <string.h>

#include "dk_operators.h"

/* PART: the handles' transforms from the caller's targets (R->utarget), for the parts they
 * turn: the given transforms, or for positions the affine map that gives them when there is
 * one, else the translation of the handle's centroid. */
static void handle_transforms(const dk_eigen *e, const dk_solve_request *rq)
{
    const eigen_regions *R = &e->r;
    const dk_constraints *u = R->user;
    for (dk_index h = 0; h < u->n_handles; h++) {
        double *T = R->uT + 16 * (size_t)h;
        if (rq->target_kind == DK_TARGETS_TRANSFORMS) {
            memcpy(T, rq->targets + 16 * (size_t)h, 16 * sizeof(double));
            continue;
        }
        const dk_index s = u->handle_start[h], cnt = u->handle_start[h + 1] - s;
        if (dk_affine_fit(e->mesh->positions, u->handle_vertices + s, cnt,
                          R->utarget + 3 * (size_t)s, 1e-9, T))
            continue;
        double d[3] = {0.0, 0.0, 0.0};
        for (dk_index q = s; q < s + cnt; q++)
            for (int r = 0; r < 3; r++)
                d[r] += (R->utarget[3 * (size_t)q + r] -
                         e->mesh->positions[3 * (size_t)u->handle_vertices[q] + r]) /
                        (double)cnt;
        for (int k = 0; k < 16; k++)
            T[k] = k % 5 == 0 ? 1.0 : 0.0;
        for (int r = 0; r < 3; r++)
            T[4 * r + 3] = d[r];
    }
}

/* PART: the groups' targets and linear parts. A handle group takes the caller's targets
 * (and linear part: the transform's, or the identity for positions); a turning part the
 * turn eigen_parts_transforms gives it. */
static void part_targets(eigen_regions *R, const dk_mesh *mesh, int per_vertex)
{
    const eigen_parts *P = &R->parts;
    const dk_constraints *c = R->con, *u = R->user;
    eigen_parts_transforms(P, R->uT, R->gT);
    for (dk_index h = 0; h < u->n_handles; h++) {
        const dk_index f = P->follow[h], t = P->turn[h];
        memcpy(R->target + 3 * (size_t)c->handle_start[f],
               R->utarget + 3 * (size_t)u->handle_start[h],
               3 * (size_t)(u->handle_start[h + 1] - u->handle_start[h]) * sizeof(double));
        for (int r = 0; r < 3; r++)
            for (int q = 0; q < 3; q++)
                R->lin[9 * (size_t)f + 3 * r + q] =
                    per_vertex ? (r == q) : R->uT[16 * (size_t)h + 4 * r + q];
        if (t < 0)
            continue;
        const double *M = R->gT + 16 * (size_t)t;
        for (int r = 0; r < 3; r++)
            for (int q = 0; q < 3; q++)
                R->lin[9 * (size_t)t + 3 * r + q] = M[4 * r + q];
        for (dk_index q = c->handle_start[t]; q < c->handle_start[t + 1]; q++) {
            const double *v = mesh->positions + 3 * (size_t)c->handle_vertices[q];
            for (int r = 0; r < 3; r++)
                R->target[3 * (size_t)q + r] =
                    M[4 * r] * v[0] + M[4 * r + 1] * v[1] + M[4 * r + 2] * v[2] + M[4 * r + 3];
        }
    }
}

/* Reads the request: the Step-1 targets of R's vertices (for the energy), and per group the
 * linear part of its motion (identity for positions) into R->lin. Checked before anything
 * is written: a refused request leaves the last one's targets. */
dk_status eigen_read_request(dk_eigen *e, const dk_solve_request *rq, dk_error *err)
{
    dk_status st = dk_solve_request_check(rq, "EigenDeformation solve", err);
    if (st != DK_OK)
        return st;
    eigen_regions *R = &e->r;
    const int per_vertex = rq->target_kind == DK_TARGETS_POSITIONS;
    if (R->user) {
        st = dk_constraints_targets(R->user, e->mesh->positions, rq->targets,
                                    (int)rq->target_kind, R->utarget, err);
        if (st != DK_OK)
            return dk_error_prefix(err, "EigenDeformation solve");
        handle_transforms(e, rq);
        part_targets(R, e->mesh, per_vertex);
        return DK_OK;
    }
    const dk_constraints *c = R->con;
    st = dk_constraints_targets(c, e->mesh->positions, rq->targets, (int)rq->target_kind,
                                R->target, err);
    if (st != DK_OK)
        return dk_error_prefix(err, "EigenDeformation solve");
    for (dk_index h = 0; h < c->n_handles; h++)
        for (int r = 0; r < 3; r++)
            for (int q = 0; q < 3; q++)
                R->lin[9 * (size_t)h + 3 * r + q] =
                    per_vertex ? (r == q) : rq->targets[16 * (size_t)h + 4 * r + q];
    return DK_OK;
}
