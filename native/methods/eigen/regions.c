/* DeformKit EigenDeformation: the region R and its distances (eigen_internal.h). */
#include "eigen_internal.h"

#include <math.h>
#include <stdlib.h>
#include <string.h>

#include "dk_operators.h"

/* What the method does not use, refused rather than ignored. */
static dk_status refuse_unused(const dk_constraint_desc *desc, dk_error *err)
{
    if (desc->n_roi > 0)
        return dk_error_set(err, DK_ERR_INVALID_ARGUMENT,
                            "EigenDeformation: no region of interest (roi) is used: the region "
                            "R is what the handles move");
    if (desc->handle_weights)
        for (int64_t i = 0, tot = 0; i < desc->n_handles; tot += desc->handle_sizes[i], i++)
            for (dk_index k = 0; k < desc->handle_sizes[i]; k++)
                if (desc->handle_weights[tot + k] != 1.0)
                    return dk_error_set(err, DK_ERR_INVALID_ARGUMENT,
                                        "EigenDeformation: handle weights are not used (a "
                                        "region moves as a whole): leave them at 1");
    return DK_OK;
}

/* g, w and delta3 of R (the vertices with region >= 0). */
static dk_status distances(const dk_mesh *mesh, eigen_regions *R, dk_error *err)
{
    const dk_index n = mesh->n_vertices;
    const dk_index *region = R->region;
    double *g = R->g, *w = R->w;
    dk_index *src = malloc(((size_t)n + 1) * sizeof *src), ns = 0;
    if (!src)
        return eigen_oom(err, "regions");
    for (dk_index v = 0; v < n; v++) { /* in R, with a neighbour outside: the boundary */
        if (region[v] < 0)
            continue;
        for (dk_index q = mesh->ring_start[v]; q < mesh->ring_start[v + 1]; q++)
            if (region[mesh->ring_index[q]] < 0) {
                src[ns++] = v;
                break;
            }
    }
    dk_status st = DK_OK;
    if (ns > 0) {
        st = dk_geodesic_dijkstra(mesh, src, ns, g, err);
    } else {
        for (dk_index v = 0; v < n; v++)
            g[v] = INFINITY;
    }
    free(src);
    if (st != DK_OK)
        return dk_error_prefix(err, "EigenDeformation: distances to the boundary of R");
    double diam_r = 0.0, diam_out = 0.0;
    for (dk_index v = 0; v < n; v++)
        if (isfinite(g[v])) {
            if (region[v] >= 0)
                diam_r = fmax(diam_r, g[v]);
            else
                diam_out = fmax(diam_out, g[v]);
        }
    /* section 4.1: w = 1 within diam R / 8 of the boundary, 0 beyond diam R / 4 */
    const double d1 = diam_r / 8.0, d2 = diam_r / 4.0;
    for (dk_index v = 0; v < n; v++) {
        if (!isfinite(g[v]) || !(diam_r > 0.0))
            w[v] = 0.0;
        else if (g[v] < d1)
            w[v] = 1.0;
        else if (g[v] > d2)
            w[v] = 0.0;
        else
            w[v] = (d2 - g[v]) / (d2 - d1);
    }
    R->delta3 = diam_out > 0.0 ? diam_r / diam_out : INFINITY;
    return DK_OK;
}

/* What the constraints give; frees what `R` holds */
void eigen_regions_free(eigen_regions *R)
{
    dk_constraints_free(R->user);
    eigen_parts_free(&R->parts);
    dk_constraints_free(R->con);
    free(R->region);
    free(R->g);
    free(R->w);
    free(R->lin);
    free(R->target);
    free(R->utarget);
    free(R->uT);
    free(R->gT);
    memset(R, 0, sizeof *R);
}

/* The caller's constraints as the groups of R (region PART: each handle's part and the
 * handle; HANDLES: the handle groups), their distances and weights, and the request
 * buffers, with every target at rest. On failure `R` is empty. */
dk_status eigen_regions_build(dk_eigen *e, const dk_constraint_desc *desc, eigen_regions *R,
                         dk_error *err)
{
    const dk_mesh *mesh = e->mesh;
    const dk_index n = e->n;
    memset(R, 0, sizeof *R);
    dk_status st = refuse_unused(desc, err);
    if (st != DK_OK)
        return st;
    const dk_constraint_desc *groups = desc;
    if (e->opt.region == DK_EIGEN_REGION_PART) {
        st = dk_constraints_create(mesh, desc, &R->user, err);
        if (st != DK_OK)
            return dk_error_prefix(err, "EigenDeformation");
        st = eigen_parts_build(mesh, R->user, desc->fixed_vertices, desc->n_fixed, &R->parts,
                               err);
        if (st != DK_OK) {
            eigen_regions_free(R);
            return st;
        }
        groups = &R->parts.desc;
    }
    st = dk_constraints_create(mesh, groups, &R->con, err);
    if (st != DK_OK) {
        eigen_regions_free(R);
        return dk_error_prefix(err, "EigenDeformation");
    }
    const dk_constraints *c = R->con, *u = R->user;
    R->region = malloc(((size_t)n + 1) * sizeof *R->region);
    R->g = malloc(((size_t)n + 1) * sizeof *R->g);
    R->w = malloc(((size_t)n + 1) * sizeof *R->w);
    R->lin = malloc(9 * ((size_t)c->n_handles + 1) * sizeof *R->lin);
    R->target = malloc(3 * ((size_t)c->n_handle_vertices + 1) * sizeof *R->target);
    if (u) {
        R->utarget = malloc(3 * ((size_t)u->n_handle_vertices + 1) * sizeof *R->utarget);
        R->uT = malloc(16 * ((size_t)u->n_handles + 1) * sizeof *R->uT);
        R->gT = malloc(16 * ((size_t)c->n_handles + 1) * sizeof *R->gT);
    }
    if (!R->region || !R->g || !R->w || !R->lin || !R->target ||
        (u && (!R->utarget || !R->uT || !R->gT))) {
        eigen_regions_free(R);
        return eigen_oom(err, "regions");
    }
    for (dk_index v = 0; v < n; v++)
        R->region[v] = c->role[v] >= 0 ? c->role[v] : -1;
    st = distances(mesh, R, err);
    if (st != DK_OK) {
        eigen_regions_free(R);
        return st;
    }
    for (dk_index i = 0; i < c->n_handle_vertices; i++) /* before any solve: the rest */
        memcpy(R->target + 3 * (size_t)i, mesh->positions + 3 * (size_t)c->handle_vertices[i],
               3 * sizeof(double));
    for (dk_index h = 0; h < c->n_handles; h++)
        for (int k = 0; k < 9; k++)
            R->lin[9 * (size_t)h + k] = k % 4 == 0 ? 1.0 : 0.0;
    return DK_OK;
}
