/* DeformKit: internal vertex numbering with locality (see dk_reorder.h). */
#include "dk_reorder.h"

#include <stdlib.h>
#include <string.h>

/* Breadth-first search from `start` over unvisited vertices, appending to order[*len...];
 * marks them in `seen` with `mark`. Returns the last vertex reached. */
static dk_index bfs(const dk_mesh *m, dk_index start, dk_index *order, dk_index *len,
                    int *seen, int mark)
{
    dk_index head = *len, last = start;
    order[(*len)++] = start;
    seen[start] = mark;
    while (head < *len) {
        const dk_index v = order[head++];
        last = v;
        for (dk_index k = m->ring_start[v]; k < m->ring_start[v + 1]; k++) {
            const dk_index w = m->ring_index[k];
            if (seen[w] != mark) {
                seen[w] = mark;
                order[(*len)++] = w;
            }
        }
    }
    return last;
}

/* The smallest internal index among the caller's triangle t's corners. */
static dk_index min_corner(const dk_reorder *r, const dk_index *t)
{
    dk_index a = r->iperm[t[0]], b = r->iperm[t[1]], c = r->iperm[t[2]];
    a = b < a ? b : a;
    return c < a ? c : a;
}

dk_status dk_reorder_create(const dk_mesh *mesh, unsigned flags, dk_reorder **out,
                            dk_error *err)
{
    if (!mesh || !out)
        return dk_error_set(err, DK_ERR_INVALID_ARGUMENT, "reorder: NULL mesh or output");
    *out = NULL;
    if (flags & ~(unsigned)DK_REORDER_SORT_FACES)
        return dk_error_set(err, DK_ERR_INVALID_ARGUMENT, "reorder: unknown flags %#x", flags);
    const dk_index n = mesh->n_vertices, nf = mesh->n_faces;
    dk_reorder *r = calloc(1, sizeof *r);
    int *seen = malloc(((size_t)n + 1) * sizeof *seen);
    double *pos = malloc(((size_t)n * 3 + 1) * sizeof *pos);
    dk_index *faces = malloc(((size_t)nf * 3 + 1) * sizeof *faces);
    if (r) {
        r->n = n;
        r->perm = malloc(((size_t)n + 1) * sizeof *r->perm);
        r->iperm = malloc(((size_t)n + 1) * sizeof *r->iperm);
        r->face_perm = malloc(((size_t)nf + 1) * sizeof *r->face_perm);
    }
    dk_status st = DK_OK;
    if (!r || !seen || !pos || !faces || !r->perm || !r->iperm || !r->face_perm) {
        st = dk_error_set(err, DK_ERR_OUT_OF_MEMORY, "reorder: out of memory");
        goto done;
    }
    /* seen: 0 unvisited, 1 reached by the probing search, 2 placed */
    memset(seen, 0, (size_t)n * sizeof *seen);
    dk_index len = 0;
    for (dk_index v = 0; v < n; v++) {
        if (seen[v] == 2)
            continue;
        /* probe from v (its component's smallest vertex) into the tail of perm, which the
         * real search then overwrites: it covers the same component */
        dk_index probe_len = len;
        const dk_index far = bfs(mesh, v, r->perm, &probe_len, seen, 1);
        bfs(mesh, far, r->perm, &len, seen, 2);
    }
    for (dk_index i = 0; i < n; i++)
        r->iperm[r->perm[i]] = i;
    for (dk_index i = 0; i < n; i++)
        memcpy(pos + 3 * (size_t)i, mesh->positions + 3 * (size_t)r->perm[i], 3 * sizeof(double));
    /* faces in the caller's order, corners relabelled: per-vertex sums over incident faces
     * (normals) then run in the same order as on the caller's mesh, bit for bit; or, sorted,
     * a stable counting sort by the smallest internal corner (seen[] reused as counts) */
    for (dk_index f = 0; f < nf; f++)
        r->face_perm[f] = f;
    if (flags & DK_REORDER_SORT_FACES) {
        memset(seen, 0, ((size_t)n + 1) * sizeof *seen);
        for (dk_index f = 0; f < nf; f++)
            seen[min_corner(r, mesh->faces + 3 * (size_t)f) + 1]++;
        for (dk_index i = 0; i < n; i++)
            seen[i + 1] += seen[i];
        for (dk_index f = 0; f < nf; f++)
            r->face_perm[seen[min_corner(r, mesh->faces + 3 * (size_t)f)]++] = f;
    }
    for (dk_index f = 0; f < nf; f++)
        for (int k = 0; k < 3; k++)
            faces[3 * (size_t)f + k] = r->iperm[mesh->faces[3 * (size_t)r->face_perm[f] + k]];
    st = dk_mesh_create(pos, n, faces, nf, &r->mesh, err);
    if (st != DK_OK)
        dk_error_prefix(err, "reorder");
done:
    free(seen);
    free(pos);
    free(faces);
    if (st != DK_OK) {
        dk_reorder_free(r);
        return st;
    }
    *out = r;
    return DK_OK;
}

void dk_reorder_free(dk_reorder *r)
{
    if (!r)
        return;
    free(r->perm);
    free(r->iperm);
    free(r->face_perm);
    dk_mesh_free(r->mesh);
    free(r);
}

void dk_reorder_rows_in(const dk_reorder *r, const double *caller, double *internal)
{
    for (dk_index i = 0; i < r->n; i++)
        memcpy(internal + 3 * (size_t)i, caller + 3 * (size_t)r->perm[i], 3 * sizeof(double));
}

void dk_reorder_rows_out(const dk_reorder *r, const double *internal, double *caller)
{
    for (dk_index i = 0; i < r->n; i++)
        memcpy(caller + 3 * (size_t)r->perm[i], internal + 3 * (size_t)i, 3 * sizeof(double));
}

dk_status dk_reorder_desc_create(const dk_reorder *r, const dk_mesh *caller_mesh,
                                 const dk_constraint_desc *in, dk_reorder_desc *out,
                                 dk_error *err)
{
    dk_constraints *check = NULL;
    memset(out, 0, sizeof *out);
    if (!r || !caller_mesh || !in)
        return dk_error_set(err, DK_ERR_INVALID_ARGUMENT, "reorder: NULL argument");
    dk_status st = dk_constraints_create(caller_mesh, in, &check, err);
    if (st != DK_OK)
        return st;
    dk_constraints_free(check);
    /* valid: handle sizes >= 0 summing to the handle vertex count, indices in range */
    int64_t nh = 0;
    for (dk_index h = 0; h < in->n_handles; h++)
        nh += in->handle_sizes[h];
    const int64_t total = nh + in->n_fixed + in->n_roi;
    out->indices = malloc(((size_t)total + 1) * sizeof *out->indices);
    if (in->stiffness)
        out->stiffness = malloc(((size_t)r->n + 1) * sizeof *out->stiffness);
    if (!out->indices || (in->stiffness && !out->stiffness)) {
        dk_reorder_desc_free(out);
        return dk_error_set(err, DK_ERR_OUT_OF_MEMORY, "reorder: out of memory (constraints)");
    }
    dk_index *p = out->indices;
    for (int64_t k = 0; k < nh; k++)
        p[k] = r->iperm[in->handle_vertices[k]];
    for (dk_index k = 0; k < in->n_fixed; k++)
        p[nh + k] = r->iperm[in->fixed_vertices[k]];
    for (dk_index k = 0; k < in->n_roi; k++)
        p[nh + in->n_fixed + k] = r->iperm[in->roi_vertices[k]];
    if (in->stiffness)
        for (dk_index i = 0; i < r->n; i++)
            out->stiffness[i] = in->stiffness[r->perm[i]];
    out->desc = *in;
    out->desc.handle_vertices = p;
    out->desc.fixed_vertices = p + nh;
    out->desc.roi_vertices = p + nh + in->n_fixed;
    out->desc.stiffness = out->stiffness;
    return DK_OK;
}

void dk_reorder_desc_free(dk_reorder_desc *d)
{
    if (!d)
        return;
    free(d->indices);
    free(d->stiffness);
    d->indices = NULL;
    d->stiffness = NULL;
}
