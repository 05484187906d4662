/* Fuzzes mesh construction: dk_mesh_from_polygons (triangulation of polygons of any size)
 * and dk_mesh_create (triangles) on decoded positions and polygons.
 *
 * Input: byte 0 picks the vertex count (1..64) and byte 1 how coordinates are drawn (small
 * lattice points, which make coincident and collinear corners, or raw doubles, which make
 * NaN, Inf and huge values); then polygons: a corner count (3..8, sometimes 0..2) and that
 * many vertex indices (sometimes out of range), until the input ends.
 *
 * Checked besides the sanitizers, on success: the documented topology (each triangle's
 * polygon, edges sorted and unique with a < b, face_edges opposite their corner, one-rings
 * sorted and symmetric, vertex-face incidence, component ids, the report's counts
 * recomputed) and, for dk_mesh_create on the triangles it produced, the same mesh. */
#include <stddef.h>
#include <stdint.h>

#include "dk_mesh.h"
#include "fuzz_input.h"

int LLVMFuzzerTestOneInput(const uint8_t *data, size_t size);

static void check_topology(const dk_mesh *m, dk_index n_polygons)
{
    const dk_index n = m->n_vertices, F = m->n_faces, E = m->n_edges;
    for (dk_index f = 0; f < F; f++) {
        dk_fuzz_check(m->face_polygon[f] >= 0 && m->face_polygon[f] < n_polygons,
                      "triangle %d from polygon %d", (int)f, (int)m->face_polygon[f]);
        for (int k = 0; k < 3; k++) {
            const dk_index a = m->faces[3 * f + (k + 1) % 3], b = m->faces[3 * f + (k + 2) % 3];
            dk_fuzz_check(m->faces[3 * f + k] >= 0 && m->faces[3 * f + k] < n, "face index");
            const dk_index e = m->face_edges[3 * f + k];
            dk_fuzz_check(e >= 0 && e < E, "face_edges out of range");
            dk_fuzz_check((m->edges[2 * e] == a && m->edges[2 * e + 1] == b) ||
                              (m->edges[2 * e] == b && m->edges[2 * e + 1] == a),
                          "face %d edge %d is not opposite corner %d", (int)f, (int)e, k);
            dk_fuzz_check(dk_mesh_find_edge(m, a, b) == e && dk_mesh_find_edge(m, b, a) == e,
                          "find_edge");
        }
    }
    dk_index boundary = 0, nonmanifold = 0;
    for (dk_index e = 0; e < E; e++) {
        dk_fuzz_check(m->edges[2 * e] < m->edges[2 * e + 1], "edge %d not a < b", (int)e);
        if (e > 0)
            dk_fuzz_check(m->edges[2 * e - 2] < m->edges[2 * e] ||
                              (m->edges[2 * e - 2] == m->edges[2 * e] &&
                               m->edges[2 * e - 1] < m->edges[2 * e + 1]),
                          "edges not sorted and unique at %d", (int)e);
        dk_fuzz_check(m->edge_face_count[e] >= 1, "edge %d in no face", (int)e);
        boundary += m->edge_face_count[e] == 1;
        nonmanifold += m->edge_face_count[e] > 2;
    }
    dk_fuzz_check(boundary == m->report.n_boundary_edges, "boundary edges %d, report %d",
                  (int)boundary, (int)m->report.n_boundary_edges);
    dk_fuzz_check(nonmanifold == m->report.n_nonmanifold_edges, "non-manifold edges");
    dk_fuzz_check(m->ring_start[0] == 0 && m->ring_start[n] == 2 * E, "ring_start ends");
    dk_fuzz_check(m->vf_start[0] == 0 && m->vf_start[n] == 3 * F, "vf_start ends");
    dk_index isolated = 0, max_component = -1;
    for (dk_index v = 0; v < n; v++) {
        for (dk_index r = m->ring_start[v]; r < m->ring_start[v + 1]; r++) {
            const dk_index w = m->ring_index[r];
            dk_fuzz_check(w >= 0 && w < n && w != v, "ring of %d holds %d", (int)v, (int)w);
            if (r > m->ring_start[v])
                dk_fuzz_check(m->ring_index[r - 1] < w, "ring of %d not sorted", (int)v);
            dk_fuzz_check(m->ring_edge[r] == dk_mesh_find_edge(m, v, w), "ring_edge");
            dk_fuzz_check(m->component[w] == m->component[v], "neighbours in two components");
        }
        for (dk_index r = m->vf_start[v]; r < m->vf_start[v + 1]; r++) {
            const dk_index f = m->vf_index[r];
            dk_fuzz_check(f >= 0 && f < F &&
                              (m->faces[3 * f] == v || m->faces[3 * f + 1] == v ||
                               m->faces[3 * f + 2] == v),
                          "vertex %d lists face %d", (int)v, (int)f);
        }
        isolated += m->vf_start[v + 1] == m->vf_start[v];
        dk_fuzz_check(m->component[v] >= 0 && m->component[v] < n, "component id");
        if (m->component[v] > max_component) max_component = m->component[v];
    }
    dk_fuzz_check(isolated == m->report.n_isolated_vertices, "isolated %d, report %d",
                  (int)isolated, (int)m->report.n_isolated_vertices);
    dk_fuzz_check(max_component + 1 == m->report.n_components, "components %d, report %d",
                  (int)max_component + 1, (int)m->report.n_components);
    dk_fuzz_check(m->bbox_diagonal >= 0 && isfinite(m->bbox_diagonal), "bbox diagonal");
    dk_fuzz_check(m->mean_edge_length >= 0 && isfinite(m->mean_edge_length), "mean edge");
}

int LLVMFuzzerTestOneInput(const uint8_t *data, size_t size)
{
    enum { MAX_V = 64, MAX_P = 256, MAX_CORNERS = 8 };
    dk_fuzz_input in = dk_fuzz_begin(data, size);
    const dk_index n = 1 + dk_fuzz_below(&in, MAX_V);
    const int raw = dk_fuzz_u8(&in) % 8 == 0;
    double pos[3 * MAX_V];
    for (int i = 0; i < 3 * n; i++)
        pos[i] = raw ? dk_fuzz_raw_double(&in) : (double)(dk_fuzz_u8(&in) % 5) - 2.0;
    dk_index sizes[MAX_P], idx[MAX_P * MAX_CORNERS];
    dk_index np = 0;
    int64_t ni = 0;
    while (dk_fuzz_left(&in) > 0 && np < MAX_P) {
        const uint8_t c = dk_fuzz_u8(&in);
        const dk_index k = c % 16 == 0 ? (dk_index)(c >> 4) % 3 : 3 + (c % 6);
        sizes[np++] = k;
        for (dk_index j = 0; j < k; j++) {
            const uint8_t b = dk_fuzz_u8(&in);
            idx[ni++] = b == 255 ? -1 : b == 254 ? n : (dk_index)(b % n);
        }
    }
    dk_mesh *m = NULL;
    dk_error err = {0};
    dk_status st = dk_mesh_from_polygons(pos, n, sizes, np, idx, ni, &m, &err);
    dk_fuzz_check((st == DK_OK) == (m != NULL), "status %d, mesh %p", (int)st, (void *)m);
    if (st != DK_OK) {
        dk_fuzz_check(err.message[0] != '\0', "status %d without a message", (int)st);
        return 0;
    }
    check_topology(m, np);
    /* the triangles it made, through the other constructor */
    dk_mesh *t = NULL;
    st = dk_mesh_create(m->positions, m->n_vertices, m->faces, m->n_faces, &t, &err);
    dk_fuzz_check(st == DK_OK, "dk_mesh_create refused dk_mesh_from_polygons' triangles: %s",
                  err.message);
    check_topology(t, t->n_faces);
    dk_fuzz_check(t->n_edges == m->n_edges && t->report.n_components == m->report.n_components,
                  "the two constructors disagree");
    dk_mesh_free(t);
    dk_mesh_free(m);
    return 0;
}
