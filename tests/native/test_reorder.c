/* Tests of dk_reorder: the order is a permutation, breadth-first (every vertex after the
 * first of its component has an earlier neighbour), deterministic, and improves locality on
 * a scrambled grid; the renumbered mesh has the same positions and the same triangles
 * (relabelled, in the caller's order); rows map both ways; constraint descriptions are
 * validated against the caller's mesh and renumbered with their group structure kept. */
#include <stdlib.h>
#include <string.h>

#include "dk_reorder.h"
#include "dk_test.h"
#include "dk_test_meshes.h"

/* A grid with its vertices scrambled (a fixed pseudo-random permutation) and, as a second
 * component, a lone triangle. */
static dk_mesh *scrambled_grid(int n, dk_index **scramble_out)
{
    dk_test_mesh g;
    dk_mesh *m = NULL;
    if (dk_test_grid(n, 1.0, 0.1, &g) != 0)
        return NULL;
    const dk_index nv = g.n_vertices + 3, nf = g.n_faces + 1;
    dk_index *sc = malloc(sizeof *sc * (size_t)nv); /* old -> new */
    double *pos = malloc(sizeof *pos * 3 * (size_t)nv);
    dk_index *faces = malloc(sizeof *faces * 3 * (size_t)nf);
    if (sc && pos && faces) {
        for (dk_index i = 0; i < nv; i++)
            sc[i] = i;
        unsigned s = 12345u;
        for (dk_index i = nv - 1; i > 0; i--) { /* Fisher-Yates with an LCG */
            s = s * 1103515245u + 12345u;
            dk_index j = (dk_index)((s >> 8) % (unsigned)(i + 1)), t = sc[i];
            sc[i] = sc[j];
            sc[j] = t;
        }
        for (dk_index i = 0; i < g.n_vertices; i++)
            for (int d = 0; d < 3; d++)
                pos[3 * sc[i] + d] = g.positions[3 * i + d];
        for (int k = 0; k < 3; k++)
            for (int d = 0; d < 3; d++)
                pos[3 * sc[g.n_vertices + k] + d] = (d == 2 ? 5.0 : 0.0) + (d == k ? 1.0 : 0.0);
        for (dk_index f = 0; f < g.n_faces; f++)
            for (int k = 0; k < 3; k++)
                faces[3 * f + k] = sc[g.faces[3 * f + k]];
        for (int k = 0; k < 3; k++)
            faces[3 * g.n_faces + k] = sc[g.n_vertices + k];
        dk_error err;
        if (dk_mesh_create(pos, nv, faces, nf, &m, &err) != DK_OK)
            m = NULL;
    }
    free(pos);
    free(faces);
    dk_test_mesh_free(&g);
    *scramble_out = sc;
    return m;
}

/* Sum over faces of the largest index distance between corners. */
static double spread(const dk_mesh *m)
{
    double s = 0.0;
    for (dk_index f = 0; f < m->n_faces; f++) {
        const dk_index *t = m->faces + 3 * f;
        dk_index lo = t[0], hi = t[0];
        for (int k = 1; k < 3; k++) {
            lo = t[k] < lo ? t[k] : lo;
            hi = t[k] > hi ? t[k] : hi;
        }
        s += hi - lo;
    }
    return s;
}

static void test_order_and_mesh(void)
{
    dk_index *sc = NULL;
    dk_mesh *m = scrambled_grid(30, &sc);
    CHECK(m != NULL);
    if (!m) {
        free(sc);
        return;
    }
    dk_reorder *r = NULL, *r2 = NULL;
    dk_error err;
    CHECK(dk_reorder_create(m, 0, &r, &err) == DK_OK);
    CHECK(dk_reorder_create(m, 0, &r2, &err) == DK_OK);
    if (!r || !r2)
        goto done;
    const dk_index n = m->n_vertices;
    CHECK(r->n == n && r->mesh->n_vertices == n && r->mesh->n_faces == m->n_faces);
    CHECK(memcmp(r->perm, r2->perm, sizeof(dk_index) * (size_t)n) == 0); /* deterministic */
    unsigned char *hit = calloc((size_t)n, 1);
    CHECK(hit != NULL);
    if (hit) {
        for (dk_index i = 0; i < n; i++) {
            CHECK(r->perm[i] >= 0 && r->perm[i] < n && !hit[r->perm[i]]);
            hit[r->perm[i]] = 1;
            CHECK(r->iperm[r->perm[i]] == i);
        }
        free(hit);
    }
    /* breadth-first: each internal vertex except a component's first has an earlier
     * neighbour; components are contiguous (the big one is not interleaved with the lone
     * triangle) */
    int starts = 0;
    for (dk_index i = 0; i < n; i++) {
        int earlier = 0;
        for (dk_index k = r->mesh->ring_start[i]; k < r->mesh->ring_start[i + 1]; k++)
            earlier |= r->mesh->ring_index[k] < i;
        starts += !earlier;
        if (i > 0 && r->mesh->component[i] != r->mesh->component[i - 1])
            CHECK(!earlier);
    }
    CHECK(starts == 2);
    /* same positions and triangles, relabelled, in the caller's order */
    for (dk_index i = 0; i < n; i++)
        for (int d = 0; d < 3; d++)
            CHECK(r->mesh->positions[3 * i + d] == m->positions[3 * r->perm[i] + d]);
    for (dk_index f = 0; f < m->n_faces; f++)
        for (int k = 0; k < 3; k++)
            CHECK(r->perm[r->mesh->faces[3 * f + k]] == m->faces[3 * f + k]);
    /* locality: the scrambled grid's triangles span far more indices */
    CHECK_MSG(spread(r->mesh) * 10.0 < spread(m), "spread %g vs %g", spread(r->mesh), spread(m));
    /* rows both ways */
    double *a = malloc(sizeof *a * 3 * (size_t)n), *b = malloc(sizeof *b * 3 * (size_t)n);
    CHECK(a && b);
    if (a && b) {
        dk_reorder_rows_in(r, m->positions, a);
        CHECK(memcmp(a, r->mesh->positions, sizeof *a * 3 * (size_t)n) == 0);
        dk_reorder_rows_out(r, a, b);
        CHECK(memcmp(b, m->positions, sizeof *b * 3 * (size_t)n) == 0);
    }
    free(a);
    free(b);
done:
    dk_reorder_free(r);
    dk_reorder_free(r2);
    dk_mesh_free(m);
    free(sc);
}

static void test_constraint_descriptions(void)
{
    dk_index *sc = NULL;
    dk_mesh *m = scrambled_grid(8, &sc);
    dk_reorder *r = NULL;
    dk_error err;
    CHECK(m != NULL);
    if (!m || dk_reorder_create(m, 0, &r, &err) != DK_OK) {
        CHECK(0);
        dk_mesh_free(m);
        free(sc);
        return;
    }
    const dk_index n = m->n_vertices;
    const dk_index sizes[2] = {2, 1}, hv[3] = {5, 9, 17}, fixed[2] = {0, 3}, roi[4] = {0, 3, 5, 9};
    const double hw[3] = {1.0, 0.5, 1.0};
    double *stiff = malloc(sizeof *stiff * (size_t)n);
    CHECK(stiff != NULL);
    if (stiff) {
        for (dk_index i = 0; i < n; i++)
            stiff[i] = 1.0 + i;
        dk_constraint_desc d = {2, sizes, hv, hw, 2, fixed, 4, roi, stiff, NULL};
        dk_reorder_desc rd;
        CHECK(dk_reorder_desc_create(r, m, &d, &rd, &err) == DK_OK);
        CHECK(rd.desc.n_handles == 2 && rd.desc.handle_sizes == sizes && rd.desc.handle_weights == hw);
        for (int k = 0; k < 3; k++)
            CHECK(r->perm[rd.desc.handle_vertices[k]] == hv[k]); /* order inside groups kept */
        for (int k = 0; k < 2; k++)
            CHECK(r->perm[rd.desc.fixed_vertices[k]] == fixed[k]);
        for (int k = 0; k < 4; k++)
            CHECK(r->perm[rd.desc.roi_vertices[k]] == roi[k]);
        for (dk_index i = 0; i < n; i++)
            CHECK(rd.desc.stiffness[i] == stiff[r->perm[i]]);
        dk_reorder_desc_free(&rd);
        /* errors are about the caller's numbering, and leave nothing to free */
        const dk_index bad[3] = {5, 9, n};
        dk_constraint_desc e = {2, sizes, bad, NULL, 0, NULL, 0, NULL, NULL, NULL};
        CHECK(dk_reorder_desc_create(r, m, &e, &rd, &err) == DK_ERR_INDEX);
        CHECK(rd.indices == NULL && rd.stiffness == NULL);
        const dk_index overlap[2] = {9, 1};
        dk_constraint_desc o = {2, sizes, hv, NULL, 2, overlap, 0, NULL, NULL, NULL};
        CHECK(dk_reorder_desc_create(r, m, &o, &rd, &err) != DK_OK);
        CHECK_MSG(strstr(err.message, "9") != NULL, "%s", err.message);
        dk_reorder_desc_free(&rd); /* safe on what a failure left */
    }
    free(stiff);
    dk_reorder_free(r);
    dk_mesh_free(m);
    free(sc);
}

/* DK_REORDER_SORT_FACES: the same vertex order, the same triangles (face_perm says which),
 * sorted by their smallest internal corner, ties in the caller's order; unknown flags fail. */
static void test_sorted_faces(void)
{
    dk_index *sc = NULL;
    dk_mesh *m = scrambled_grid(30, &sc);
    dk_reorder *r = NULL, *plain = NULL;
    dk_error err;
    CHECK(m != NULL);
    if (!m || dk_reorder_create(m, DK_REORDER_SORT_FACES, &r, &err) != DK_OK ||
        dk_reorder_create(m, 0, &plain, &err) != DK_OK) {
        CHECK(0);
        goto done;
    }
    dk_reorder *bad = NULL;
    CHECK(dk_reorder_create(m, 2, &bad, &err) == DK_ERR_INVALID_ARGUMENT && bad == NULL);
    const dk_index n = m->n_vertices, nf = m->n_faces;
    CHECK(memcmp(r->perm, plain->perm, sizeof(dk_index) * (size_t)n) == 0);
    unsigned char *hit = calloc((size_t)nf, 1);
    CHECK(hit != NULL);
    dk_index prev_min = -1, prev_face = -1;
    for (dk_index f = 0; hit && f < nf; f++) {
        const dk_index src = r->face_perm[f];
        CHECK(src >= 0 && src < nf && !hit[src]);
        hit[src] = 1;
        dk_index lo = n;
        for (int k = 0; k < 3; k++) {
            CHECK(r->perm[r->mesh->faces[3 * f + k]] == m->faces[3 * src + k]);
            lo = r->mesh->faces[3 * f + k] < lo ? r->mesh->faces[3 * f + k] : lo;
        }
        CHECK(lo >= prev_min);
        if (lo == prev_min)
            CHECK(src > prev_face); /* stable */
        prev_min = lo;
        prev_face = src;
    }
    free(hit);
    for (dk_index f = 0; f < nf; f++)
        CHECK(plain->face_perm[f] == f);
done:
    dk_reorder_free(r);
    dk_reorder_free(plain);
    dk_mesh_free(m);
    free(sc);
}

DK_TEST_MAIN(test_order_and_mesh, test_constraint_descriptions, test_sorted_faces)
