/* The triangle mesh: validation and topology. See dk_mesh.h.
 *
 * Topology is built without any per-vertex allocation: the 3F half-edges are bucketed by
 * their smaller vertex with a counting sort, each (short) bucket is sorted by the larger
 * vertex, and one walk over the buckets numbers the unique edges in lexicographic order.
 * Walking the sorted edges then fills the one-ring CSR already sorted (neighbours below v
 * come from earlier buckets in ascending order, neighbours above v from v's own bucket).
 * Components use union-find with path halving. Everything is O(F) apart from the bucket
 * sorts, which are tiny for meshes (average bucket size 3).
 */
#include "dk_mesh.h"

#include <math.h>
#include <stdlib.h>
#include <string.h>

#include "dk_mesh_internal.h"

void dk_mesh_free(dk_mesh *m)
{
    if (!m) return;
    free(m->positions);
    free(m->faces);
    free(m->face_polygon);
    free(m->edges);
    free(m->edge_faces);
    free(m->edge_face_count);
    free(m->face_edges);
    free(m->ring_start);
    free(m->ring_index);
    free(m->ring_edge);
    free(m->vf_start);
    free(m->vf_index);
    free(m->is_boundary_vertex);
    free(m->component);
    free(m);
}

dk_status dk_check_positions(const double *positions, dk_index n, dk_error *err)
{
    static const char axis[3] = {'x', 'y', 'z'};
    if (n < 0)
        return dk_error_set(err, DK_ERR_INVALID_ARGUMENT, "negative vertex count %ld", (long)n);
    if (n > 0 && !positions)
        return dk_error_set(err, DK_ERR_INVALID_ARGUMENT, "positions are NULL");
    for (int64_t i = 0; i < 3 * (int64_t)n; i++) {
        if (!isfinite(positions[i]))
            return dk_error_set(err, DK_ERR_NONFINITE, "vertex %lld coordinate %c is %g",
                                (long long)(i / 3), axis[i % 3], positions[i]);
        if (fabs(positions[i]) > DK_COORD_MAX)
            return dk_error_set(err, DK_ERR_NONFINITE,
                                "vertex %lld coordinate %c is %g, beyond +-%g (the "
                                "operators would overflow double precision)",
                                (long long)(i / 3), axis[i % 3], positions[i], DK_COORD_MAX);
    }
    return DK_OK;
}

dk_status dk_check_indices(const dk_index *indices, int64_t n, dk_index limit,
                           const char *what, dk_error *err)
{
    if (!what) what = "index";
    if (n < 0)
        return dk_error_set(err, DK_ERR_INVALID_ARGUMENT, "%s: negative count %lld", what,
                            (long long)n);
    if (n > 0 && !indices)
        return dk_error_set(err, DK_ERR_INVALID_ARGUMENT, "%s: NULL array", what);
    for (int64_t i = 0; i < n; i++) {
        if (indices[i] < 0 || indices[i] >= limit)
            return dk_error_set(err, DK_ERR_INDEX, "%s %lld is %ld, out of range [0, %ld)",
                                what, (long long)i, (long)indices[i], (long)limit);
    }
    return DK_OK;
}

/* Sorts the pairs (k[i], v[i]) of length n lexicographically (insertion sort: buckets are
 * short; a heap sort for long ones keeps the worst case n log n). Sorting by v too keeps the
 * incident faces of an edge in face order. */
static void sift(dk_index *k, dk_index *v, int64_t root, int64_t n)
{
    for (;;) {
        int64_t c = 2 * root + 1;
        if (c >= n) return;
        if (c + 1 < n && (k[c + 1] > k[c] || (k[c + 1] == k[c] && v[c + 1] > v[c]))) c++;
        if (k[root] > k[c] || (k[root] == k[c] && v[root] >= v[c])) return;
        dk_index t = k[root];
        k[root] = k[c];
        k[c] = t;
        t = v[root];
        v[root] = v[c];
        v[c] = t;
        root = c;
    }
}

static void sort_pairs(dk_index *k, dk_index *v, int64_t n)
{
    if (n <= 16) {
        for (int64_t i = 1; i < n; i++) {
            dk_index kk = k[i], vv = v[i];
            int64_t j = i;
            while (j > 0 && (k[j - 1] > kk || (k[j - 1] == kk && v[j - 1] > vv))) {
                k[j] = k[j - 1];
                v[j] = v[j - 1];
                j--;
            }
            k[j] = kk;
            v[j] = vv;
        }
        return;
    }
    for (int64_t i = n / 2 - 1; i >= 0; i--) sift(k, v, i, n);
    for (int64_t e = n - 1; e > 0; e--) {
        dk_index t = k[0];
        k[0] = k[e];
        k[e] = t;
        t = v[0];
        v[0] = v[e];
        v[e] = t;
        sift(k, v, 0, e);
    }
}

static dk_index uf_find(dk_index *parent, dk_index x)
{
    while (parent[x] != x) {
        parent[x] = parent[parent[x]];
        x = parent[x];
    }
    return x;
}

static double tri_area(const double *p, const dk_index *t)
{
    const double *a = p + 3 * (int64_t)t[0], *b = p + 3 * (int64_t)t[1],
                 *c = p + 3 * (int64_t)t[2];
    double u[3] = {b[0] - a[0], b[1] - a[1], b[2] - a[2]};
    double v[3] = {c[0] - a[0], c[1] - a[1], c[2] - a[2]};
    double n0 = u[1] * v[2] - u[2] * v[1], n1 = u[2] * v[0] - u[0] * v[2],
           n2 = u[0] * v[1] - u[1] * v[0];
    return 0.5 * sqrt(n0 * n0 + n1 * n1 + n2 * n2);
}

void dk_mesh_face_areas(const dk_mesh *mesh, const double *positions, double *areas)
{
    if (!mesh || !areas) return;
    if (!positions) positions = mesh->positions;
    for (dk_index f = 0; f < mesh->n_faces; f++) {
        double a = tri_area(positions, mesh->faces + 3 * (int64_t)f);
        areas[f] = a < 1e-14 * mesh->bbox_diagonal * mesh->bbox_diagonal ? 0.0 : a;
    }
}

dk_index dk_mesh_find_edge(const dk_mesh *mesh, dk_index a, dk_index b)
{
    if (!mesh || a < 0 || b < 0 || a >= mesh->n_vertices || b >= mesh->n_vertices) return -1;
    dk_index lo = mesh->ring_start[a], hi = mesh->ring_start[a + 1];
    while (lo < hi) {
        dk_index mid = lo + (hi - lo) / 2;
        if (mesh->ring_index[mid] < b)
            lo = mid + 1;
        else
            hi = mid;
    }
    if (lo < mesh->ring_start[a + 1] && mesh->ring_index[lo] == b) return mesh->ring_edge[lo];
    return -1;
}

/* Validates triangle indices (range, repeats). */
static dk_status check_triangles(const dk_index *faces, dk_index n_faces, dk_index nv,
                                 dk_error *err)
{
    for (int64_t f = 0; f < n_faces; f++) {
        const dk_index *t = faces + 3 * f;
        for (int k = 0; k < 3; k++)
            if (t[k] < 0 || t[k] >= nv)
                return dk_error_set(err, DK_ERR_INDEX,
                                    "face %lld index %d is %ld, out of range [0, %ld]",
                                    (long long)f, k, (long)t[k], (long)nv - 1);
        if (t[0] == t[1] || t[0] == t[2] || t[1] == t[2]) {
            int i = t[0] == t[1] ? 0 : (t[0] == t[2] ? 0 : 1);
            int j = t[0] == t[1] ? 1 : 2;
            return dk_error_set(err, DK_ERR_TOPOLOGY,
                                "face %lld repeats vertex %ld (corners %d and %d)",
                                (long long)f, (long)t[i], i, j);
        }
    }
    return DK_OK;
}

#define ALLOC(ptr, count)                                                                  \
    do {                                                                                   \
        (ptr) = malloc(sizeof *(ptr) * (size_t)((count) > 0 ? (count) : 1));              \
        if (!(ptr)) goto oom;                                                              \
    } while (0)

dk_status dk_mesh_build_owned(double *positions, dk_index nv, dk_index *faces, dk_index nf,
                              dk_index *face_polygon, dk_index n_polygons, dk_mesh **out,
                              dk_error *err)
{
    dk_index *cnt = NULL, *he_hi = NULL, *he_id = NULL, *parent = NULL;
    dk_mesh *m = calloc(1, sizeof *m);
    if (!m) {
        free(positions);
        free(faces);
        free(face_polygon);
        return dk_error_set(err, DK_ERR_OUT_OF_MEMORY, "mesh: out of memory");
    }
    m->positions = positions;
    m->faces = faces;
    m->face_polygon = face_polygon;
    m->n_vertices = nv;
    m->n_faces = nf;
    m->n_polygons = n_polygons;
    int64_t nh = 3 * (int64_t)nf;

    /* --- bucket half-edges by smaller vertex */
    cnt = calloc((size_t)nv + 2, sizeof(dk_index));
    if (!cnt) goto oom;
    ALLOC(he_hi, nh);
    ALLOC(he_id, nh);
    ALLOC(m->face_edges, nh);
    for (int64_t h = 0; h < nh; h++) {
        int64_t f = h / 3;
        int k = (int)(h % 3);
        dk_index a = faces[3 * f + (k + 1) % 3], b = faces[3 * f + (k + 2) % 3];
        cnt[(a < b ? a : b) + 2]++;
    }
    for (dk_index v = 0; v < nv; v++) cnt[v + 2] += cnt[v + 1];
    for (int64_t h = 0; h < nh; h++) {
        int64_t f = h / 3;
        int k = (int)(h % 3);
        dk_index a = faces[3 * f + (k + 1) % 3], b = faces[3 * f + (k + 2) % 3];
        dk_index lo = a < b ? a : b, hi = a < b ? b : a;
        dk_index p = cnt[lo + 1]++;
        he_hi[p] = hi;
        he_id[p] = (dk_index)h;
    }
    /* bucket v is [cnt[v], cnt[v+1]) */
    int64_t ne = 0;
    for (dk_index v = 0; v < nv; v++) {
        dk_index b = cnt[v], e = cnt[v + 1];
        sort_pairs(he_hi + b, he_id + b, e - b);
        for (dk_index p = b; p < e; p++)
            if (p == b || he_hi[p] != he_hi[p - 1]) ne++;
    }
    if (ne > INT32_MAX / 2) {
        dk_mesh_free(m);
        free(cnt);
        free(he_hi);
        free(he_id);
        return dk_error_set(err, DK_ERR_INVALID_ARGUMENT, "mesh: too many edges (%lld)",
                            (long long)ne);
    }
    m->n_edges = (dk_index)ne;
    ALLOC(m->edges, 2 * ne);
    ALLOC(m->edge_faces, 2 * ne);
    ALLOC(m->edge_face_count, ne);
    {
        dk_index e = -1;
        for (dk_index v = 0; v < nv; v++) {
            for (dk_index p = cnt[v]; p < cnt[v + 1]; p++) {
                if (p == cnt[v] || he_hi[p] != he_hi[p - 1]) {
                    e++;
                    m->edges[2 * e] = v;
                    m->edges[2 * e + 1] = he_hi[p];
                    m->edge_faces[2 * e] = m->edge_faces[2 * e + 1] = -1;
                    m->edge_face_count[e] = 0;
                }
                dk_index f = he_id[p] / 3;
                m->face_edges[he_id[p]] = e;
                if (m->edge_face_count[e] < 2) m->edge_faces[2 * e + m->edge_face_count[e]] = f;
                m->edge_face_count[e]++;
            }
        }
    }
    free(he_hi);
    free(he_id);
    he_hi = he_id = NULL;

    /* --- one-rings, sorted by construction */
    ALLOC(m->ring_start, (int64_t)nv + 1);
    ALLOC(m->ring_index, 2 * ne);
    ALLOC(m->ring_edge, 2 * ne);
    memset(m->ring_start, 0, sizeof(dk_index) * ((size_t)nv + 1));
    for (int64_t e = 0; e < ne; e++) {
        m->ring_start[m->edges[2 * e] + 1]++;
        m->ring_start[m->edges[2 * e + 1] + 1]++;
    }
    for (dk_index v = 0; v < nv; v++) m->ring_start[v + 1] += m->ring_start[v];
    memcpy(cnt, m->ring_start, sizeof(dk_index) * (size_t)nv);
    for (int64_t e = 0; e < ne; e++) {
        dk_index a = m->edges[2 * e], b = m->edges[2 * e + 1];
        dk_index pa = cnt[a]++, pb = cnt[b]++;
        m->ring_index[pa] = b;
        m->ring_edge[pa] = (dk_index)e;
        m->ring_index[pb] = a;
        m->ring_edge[pb] = (dk_index)e;
    }

    /* --- vertex-face incidence */
    ALLOC(m->vf_start, (int64_t)nv + 1);
    ALLOC(m->vf_index, nh);
    memset(m->vf_start, 0, sizeof(dk_index) * ((size_t)nv + 1));
    for (int64_t h = 0; h < nh; h++) m->vf_start[faces[h] + 1]++;
    for (dk_index v = 0; v < nv; v++) m->vf_start[v + 1] += m->vf_start[v];
    memcpy(cnt, m->vf_start, sizeof(dk_index) * (size_t)nv);
    for (int64_t h = 0; h < nh; h++) m->vf_index[cnt[faces[h]]++] = (dk_index)(h / 3);
    free(cnt);
    cnt = NULL;

    /* --- bbox, edge lengths, boundary, counts */
    dk_mesh_report *r = &m->report;
    r->first_degenerate_face = r->first_nonmanifold_edge = r->first_isolated_vertex = -1;
    for (int i = 0; i < 3; i++) {
        m->bbox_min[i] = nv ? positions[i] : 0.0;
        m->bbox_max[i] = nv ? positions[i] : 0.0;
    }
    for (int64_t v = 0; v < nv; v++)
        for (int i = 0; i < 3; i++) {
            double x = positions[3 * v + i];
            if (x < m->bbox_min[i]) m->bbox_min[i] = x;
            if (x > m->bbox_max[i]) m->bbox_max[i] = x;
        }
    {
        double d0 = m->bbox_max[0] - m->bbox_min[0], d1 = m->bbox_max[1] - m->bbox_min[1],
               d2 = m->bbox_max[2] - m->bbox_min[2];
        m->bbox_diagonal = sqrt(d0 * d0 + d1 * d1 + d2 * d2);
    }
    ALLOC(m->is_boundary_vertex, nv);
    memset(m->is_boundary_vertex, 0, (size_t)(nv > 0 ? nv : 1));
    double len_sum = 0.0;
    for (int64_t e = 0; e < ne; e++) {
        const double *a = positions + 3 * (int64_t)m->edges[2 * e],
                     *b = positions + 3 * (int64_t)m->edges[2 * e + 1];
        double dx = a[0] - b[0], dy = a[1] - b[1], dz = a[2] - b[2];
        len_sum += sqrt(dx * dx + dy * dy + dz * dz);
        if (m->edge_face_count[e] == 1) {
            r->n_boundary_edges++;
            m->is_boundary_vertex[m->edges[2 * e]] = 1;
            m->is_boundary_vertex[m->edges[2 * e + 1]] = 1;
        } else if (m->edge_face_count[e] > 2) {
            if (r->first_nonmanifold_edge < 0) r->first_nonmanifold_edge = (dk_index)e;
            r->n_nonmanifold_edges++;
        }
    }
    m->mean_edge_length = ne ? len_sum / (double)ne : 0.0;
    double tiny = 1e-14 * m->bbox_diagonal * m->bbox_diagonal;
    for (int64_t f = 0; f < nf; f++) {
        if (tri_area(positions, faces + 3 * f) < tiny || m->bbox_diagonal == 0.0) {
            if (r->first_degenerate_face < 0) r->first_degenerate_face = (dk_index)f;
            r->n_degenerate_faces++;
        }
    }
    for (dk_index v = 0; v < nv; v++)
        if (m->vf_start[v + 1] == m->vf_start[v]) {
            if (r->first_isolated_vertex < 0) r->first_isolated_vertex = v;
            r->n_isolated_vertices++;
        }

    /* --- components */
    ALLOC(m->component, nv);
    ALLOC(parent, nv);
    for (dk_index v = 0; v < nv; v++) parent[v] = v;
    for (int64_t e = 0; e < ne; e++) {
        dk_index a = uf_find(parent, m->edges[2 * e]), b = uf_find(parent, m->edges[2 * e + 1]);
        if (a != b) {
            if (a < b)
                parent[b] = a;
            else
                parent[a] = b;
        }
    }
    /* roots are the smallest vertex of their set, so ids follow first appearance */
    for (dk_index v = 0; v < nv; v++) {
        dk_index root = uf_find(parent, v);
        if (root == v)
            m->component[v] = r->n_components++;
        else
            m->component[v] = m->component[root];
    }
    free(parent);
    *out = m;
    return DK_OK;

oom:
    free(cnt);
    free(he_hi);
    free(he_id);
    free(parent);
    dk_mesh_free(m);
    return dk_error_set(err, DK_ERR_OUT_OF_MEMORY,
                        "mesh: out of memory building topology (%ld vertices, %ld faces)",
                        (long)nv, (long)nf);
}

dk_status dk_mesh_create(const double *positions, dk_index n_vertices, const dk_index *faces,
                         dk_index n_faces, dk_mesh **out, dk_error *err)
{
    if (!out) return dk_error_set(err, DK_ERR_INVALID_ARGUMENT, "mesh: out is NULL");
    *out = NULL;
    if (n_faces < 0 || n_faces > INT32_MAX / 3)
        return dk_error_set(err, DK_ERR_INVALID_ARGUMENT, "mesh: invalid face count %ld",
                            (long)n_faces);
    if (n_faces > 0 && !faces)
        return dk_error_set(err, DK_ERR_INVALID_ARGUMENT, "mesh: faces are NULL");
    dk_status st = dk_check_positions(positions, n_vertices, err);
    if (st) return st;
    st = check_triangles(faces, n_faces, n_vertices, err);
    if (st) return st;
    double *p = malloc(sizeof(double) * 3 * (size_t)(n_vertices ? n_vertices : 1));
    dk_index *f = malloc(sizeof(dk_index) * 3 * (size_t)(n_faces ? n_faces : 1));
    dk_index *fp = malloc(sizeof(dk_index) * (size_t)(n_faces ? n_faces : 1));
    if (!p || !f || !fp) {
        free(p);
        free(f);
        free(fp);
        return dk_error_set(err, DK_ERR_OUT_OF_MEMORY, "mesh: out of memory copying input");
    }
    if (n_vertices) memcpy(p, positions, sizeof(double) * 3 * (size_t)n_vertices);
    if (n_faces) memcpy(f, faces, sizeof(dk_index) * 3 * (size_t)n_faces);
    for (dk_index i = 0; i < n_faces; i++) fp[i] = i;
    return dk_mesh_build_owned(p, n_vertices, f, n_faces, fp, n_faces, out, err);
}
