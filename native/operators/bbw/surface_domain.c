/* DeformKit: bounded biharmonic weights on the mesh's own triangles (bbw_internal.h): the
 * cotangent Laplacian and the barycentric lumped mass, each handle sample held at its
 * nearest vertex (a vertex two handles reach goes to the nearer sample). The handles are
 * sampled at the mesh's mean edge length, so a bone that runs along the surface holds the
 * vertices along it. */
#include <math.h>
#include <stdlib.h>
#include <string.h>

#include "bbw_internal.h"
#include "dk_operators.h"

dk_status bbw_surface_domain(const dk_mesh *mesh, const dk_bbw_handles *h, bbw_domain *d,
                             dk_error *err)
{
    const dk_index n = mesh->n_vertices;
    memset(d, 0, sizeof *d);
    d->kind = DK_BBW_SURFACE;
    if (h->n_cage_triangles > 0 || h->n_cage_vertices > 0)
        return dk_error_set(err, DK_ERR_INVALID_ARGUMENT, "bounded biharmonic weights: a cage's "
                            "weights live in the volume it encloses: use the volume domain");
    double step = mesh->mean_edge_length > 0.0 ? mesh->mean_edge_length
                                               : 1e-3 * (mesh->bbox_diagonal > 0.0 ? mesh->bbox_diagonal : 1.0);
    dk_status st = bbw_sample_handles(h, step, &d->samples, &d->n_samples, err);
    if (st != DK_OK) return st;
    d->n = n;
    d->n_elements = mesh->n_faces;
    d->positions = malloc(((size_t)n + 1) * 3 * sizeof *d->positions);
    d->mass = malloc(((size_t)n + 1) * sizeof *d->mass);
    d->embed = malloc(((size_t)n + 1) * 4 * sizeof *d->embed);
    d->embed_weight = calloc(((size_t)n + 1) * 4, sizeof *d->embed_weight);
    dk_index *nearest = malloc(((size_t)d->n_samples + 1) * sizeof *nearest);
    double *d2 = malloc(((size_t)d->n_samples + 1) * sizeof *d2);
    dk_index *claim = malloc(((size_t)n + 1) * sizeof *claim);
    dk_kdtree *tree = NULL;
    if (!d->positions || !d->mass || !d->embed || !d->embed_weight || !nearest || !d2 || !claim) {
        st = dk_error_set(err, DK_ERR_OUT_OF_MEMORY, "bounded biharmonic weights: out of memory");
        goto done;
    }
    memcpy(d->positions, mesh->positions, (size_t)n * 3 * sizeof(double));
    for (dk_index i = 0; i < n; i++) {
        d->embed[4 * (size_t)i] = i;
        d->embed[4 * (size_t)i + 1] = d->embed[4 * (size_t)i + 2] = d->embed[4 * (size_t)i + 3] = -1;
        d->embed_weight[4 * (size_t)i] = 1.0;
    }
    st = dk_laplacian_cotangent(mesh, &d->stiffness, err);
    if (st == DK_OK) st = dk_mass_matrix(mesh, DK_MASS_BARYCENTRIC, d->mass, err);
    if (st == DK_OK) st = dk_kdtree_create(mesh->positions, n, &tree, err);
    if (st != DK_OK) goto done;
    /* the samples are structs: query them one at a time */
    for (dk_index s = 0; s < d->n_samples && st == DK_OK; s++)
        st = dk_kdtree_knn(tree, d->samples[s].p, 1, 1, &nearest[s], &d2[s], err);
    if (st != DK_OK) goto done;
    for (dk_index i = 0; i < n; i++) claim[i] = -1;
    for (dk_index s = 0; s < d->n_samples; s++) {
        dk_index v = nearest[s];
        if (claim[v] < 0 || d2[s] < d2[claim[v]]) claim[v] = s;
    }
    d->held = malloc(((size_t)n + 1) * sizeof *d->held);
    d->held_sample = malloc(((size_t)n + 1) * sizeof *d->held_sample);
    if (!d->held || !d->held_sample) {
        st = dk_error_set(err, DK_ERR_OUT_OF_MEMORY, "bounded biharmonic weights: out of memory");
        goto done;
    }
    for (dk_index v = 0; v < n; v++)
        if (claim[v] >= 0) {
            d->held[d->n_held] = v;
            d->held_sample[d->n_held++] = claim[v];
        }
    st = bbw_check_held(d, h, err);
done:
    dk_kdtree_free(tree);
    free(nearest);
    free(d2);
    free(claim);
    if (st != DK_OK) bbw_domain_free(d);
    return st;
}
