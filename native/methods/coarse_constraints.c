/* DeformKit: the constraints of a simplified mesh (dk_constraints.h, "a simplified mesh's"):
 * the classes a simplification keeps apart, and the constraints restricted to the vertices
 * it kept. ARAP's coarse level and VolumetricARAP's bind their coarse meshes with them. */
#include "dk_constraints.h"

#include <stdlib.h>
#include <string.h>

#include "dk_operators.h"

void dk_constraints_classes(const dk_constraints *c, int *cls)
{
    for (dk_index v = 0; v < c->n_vertices; v++)
        cls[v] = c->role[v] == DK_VERTEX_FIXED ? 1 : c->role[v] < 0 ? 0 : 2 + 2 * (int)c->role[v];
    for (dk_index k = 0; k < c->n_handle_vertices; k++)
        if (c->handle_weights[k] < 1.0)
            cls[c->handle_vertices[k]] |= 1;
}

void dk_coarse_constraints_free(dk_coarse_constraints *cc)
{
    if (!cc)
        return;
    free(cc->fine_vertex);
    free(cc->sizes);
    free(cc->handle_vertices);
    free(cc->fixed);
    free(cc->weights);
    free(cc->stiffness);
    memset(cc, 0, sizeof *cc);
}

dk_status dk_coarse_constraints_create(const dk_constraints *c, const dk_decimation *d,
                                       dk_coarse_constraints *out, dk_error *err)
{
    memset(out, 0, sizeof *out);
    const dk_index nh = c->n_handles, m = d->n_kept;
    const size_t mm = (size_t)m + 1;
    out->sizes = calloc((size_t)nh + 1, sizeof *out->sizes);
    out->handle_vertices = malloc(mm * sizeof *out->handle_vertices);
    out->fixed = malloc(mm * sizeof *out->fixed);
    out->weights = malloc(mm * sizeof *out->weights);
    out->stiffness = malloc(mm * sizeof *out->stiffness);
    out->fine_vertex = malloc(mm * sizeof *out->fine_vertex);
    if (!out->sizes || !out->handle_vertices || !out->fixed || !out->weights ||
        !out->stiffness || !out->fine_vertex)
        return dk_error_set(err, DK_ERR_OUT_OF_MEMORY, "out of memory (the coarse level's "
                            "constraints)");
    dk_index nhv = 0, nfix = 0;
    for (dk_index h = 0; h < nh; h++)
        for (dk_index k = c->handle_start[h]; k < c->handle_start[h + 1]; k++) {
            const dk_index v = c->handle_vertices[k], cv = d->coarse_of[v];
            if (cv < 0)
                continue;
            out->sizes[h]++;
            out->handle_vertices[nhv] = cv;
            out->weights[nhv] = c->handle_weights[k];
            out->fine_vertex[nhv++] = v;
        }
    for (dk_index cv = 0; cv < m; cv++) {
        const dk_index v = d->kept[cv];
        out->stiffness[cv] = c->stiffness[v];
        if (c->role[v] == DK_VERTEX_FIXED)
            out->fixed[nfix++] = cv;
    }
    out->n_handle_vertices = nhv;
    dk_constraint_desc *desc = &out->desc;
    desc->n_handles = nh;
    desc->handle_sizes = out->sizes;
    desc->handle_vertices = out->handle_vertices;
    desc->handle_weights = out->weights;
    desc->n_fixed = nfix;
    desc->fixed_vertices = out->fixed;
    desc->stiffness = out->stiffness;
    return DK_OK;
}
