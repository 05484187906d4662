/* Tests for dk_mesh: validation messages, topology invariants on generated meshes, report
 * counts on crafted defects, polygon triangulation, and topology speed. */
#include <stdlib.h>
#include <string.h>
#include <time.h>

#include "dk_mesh.h"
#include "dk_test.h"
#include "dk_test_meshes.h"

#ifndef M_PI
#define M_PI 3.14159265358979323846
#endif

#if defined(__SANITIZE_ADDRESS__)
#define SANITIZED 1
#elif defined(__has_feature)
#if __has_feature(address_sanitizer)
#define SANITIZED 1
#endif
#endif
#ifndef SANITIZED
#define SANITIZED 0
#endif

/* Checks every topology invariant stated in dk_mesh.h against brute force where cheap. */
static void check_invariants(const dk_mesh *m)
{
    int ok = 1;
    /* edges sorted, a < b, face_edges consistent */
    for (dk_index e = 0; e < m->n_edges; e++) {
        if (m->edges[2 * e] >= m->edges[2 * e + 1]) ok = 0;
        if (e > 0 && (m->edges[2 * e - 2] > m->edges[2 * e] ||
                      (m->edges[2 * e - 2] == m->edges[2 * e] &&
                       m->edges[2 * e - 1] >= m->edges[2 * e + 1])))
            ok = 0;
    }
    CHECK_MSG(ok, "edges not sorted/unique");
    ok = 1;
    dk_index *count = calloc((size_t)m->n_edges + 1, sizeof(dk_index));
    for (dk_index f = 0; f < m->n_faces; f++)
        for (int k = 0; k < 3; k++) {
            dk_index e = m->face_edges[3 * f + k];
            dk_index a = m->faces[3 * f + (k + 1) % 3], b = m->faces[3 * f + (k + 2) % 3];
            dk_index lo = a < b ? a : b, hi = a < b ? b : a;
            if (e < 0 || e >= m->n_edges || m->edges[2 * e] != lo || m->edges[2 * e + 1] != hi)
                ok = 0;
            else {
                if (count[e] < 2 && m->edge_faces[2 * e + count[e]] != f) ok = 0;
                count[e]++;
            }
        }
    for (dk_index e = 0; e < m->n_edges; e++) {
        if (count[e] != m->edge_face_count[e]) ok = 0;
        if (count[e] < 2 && m->edge_faces[2 * e + 1] != -1) ok = 0;
    }
    free(count);
    CHECK_MSG(ok, "face_edges / edge_faces inconsistent (%ld faces)", (long)m->n_faces);
    /* rings sorted, symmetric, edge ids match */
    ok = 1;
    CHECK(m->ring_start[m->n_vertices] == 2 * m->n_edges);
    for (dk_index v = 0; v < m->n_vertices; v++)
        for (dk_index p = m->ring_start[v]; p < m->ring_start[v + 1]; p++) {
            dk_index w = m->ring_index[p], e = m->ring_edge[p];
            if (p > m->ring_start[v] && m->ring_index[p - 1] >= w) ok = 0;
            dk_index lo = v < w ? v : w, hi = v < w ? w : v;
            if (m->edges[2 * e] != lo || m->edges[2 * e + 1] != hi) ok = 0;
            if (dk_mesh_find_edge(m, w, v) != e || dk_mesh_find_edge(m, v, w) != e) ok = 0;
        }
    CHECK_MSG(ok, "rings wrong");
    /* vertex-face incidence */
    ok = 1;
    CHECK(m->vf_start[m->n_vertices] == 3 * m->n_faces);
    for (dk_index v = 0; v < m->n_vertices; v++)
        for (dk_index p = m->vf_start[v]; p < m->vf_start[v + 1]; p++) {
            dk_index f = m->vf_index[p];
            if (m->faces[3 * f] != v && m->faces[3 * f + 1] != v && m->faces[3 * f + 2] != v)
                ok = 0;
        }
    CHECK_MSG(ok, "vertex-face incidence wrong");
    /* components: endpoints of every edge agree; ids are 0..n_components-1 */
    ok = 1;
    for (dk_index e = 0; e < m->n_edges; e++)
        if (m->component[m->edges[2 * e]] != m->component[m->edges[2 * e + 1]]) ok = 0;
    for (dk_index v = 0; v < m->n_vertices; v++)
        if (m->component[v] < 0 || m->component[v] >= m->report.n_components) ok = 0;
    CHECK_MSG(ok, "components wrong");
}

static double signed_volume(const dk_mesh *m)
{
    double vol = 0;
    for (dk_index f = 0; f < m->n_faces; f++) {
        const double *a = m->positions + 3 * m->faces[3 * f],
                     *b = m->positions + 3 * m->faces[3 * f + 1],
                     *c = m->positions + 3 * m->faces[3 * f + 2];
        vol += (a[0] * (b[1] * c[2] - b[2] * c[1]) - a[1] * (b[0] * c[2] - b[2] * c[0]) +
                a[2] * (b[0] * c[1] - b[1] * c[0])) /
               6.0;
    }
    return vol;
}

static void test_icosphere(void)
{
    for (int level = 0; level <= 3; level++) {
        dk_test_mesh g;
        CHECK(dk_test_icosphere(level, 2.0, &g) == 0);
        dk_mesh *m = dk_test_mesh_build(&g);
        CHECK(m != NULL);
        if (m) {
            check_invariants(m);
            CHECK(m->n_vertices - m->n_edges + m->n_faces == 2);
            CHECK(m->n_faces == 20 << (2 * level));
            CHECK(m->report.n_boundary_edges == 0 && m->report.n_nonmanifold_edges == 0);
            CHECK(m->report.n_components == 1 && m->report.n_isolated_vertices == 0);
            CHECK(m->report.n_degenerate_faces == 0 && m->report.first_degenerate_face == -1);
            double worst = 0;
            for (dk_index v = 0; v < m->n_vertices; v++) {
                const double *p = m->positions + 3 * v;
                double r = sqrt(p[0] * p[0] + p[1] * p[1] + p[2] * p[2]);
                if (fabs(r - 2.0) > worst) worst = fabs(r - 2.0);
            }
            CHECK(worst < 1e-14);
            CHECK(signed_volume(m) > 0); /* outward orientation */
            if (level == 3) CHECK_NEAR(signed_volume(m), 4.0 / 3.0 * M_PI * 8, 1.0);
            CHECK(m->bbox_max[0] <= 2.0 && m->bbox_max[0] > 1.7 && m->bbox_min[2] >= -2.0);
            CHECK(m->bbox_diagonal <= sqrt(48.0) && m->bbox_diagonal > 5.8);
            double *areas = malloc(sizeof(double) * m->n_faces), total = 0;
            dk_mesh_face_areas(m, NULL, areas);
            for (dk_index f = 0; f < m->n_faces; f++) total += areas[f];
            CHECK(total < 4 * M_PI * 4 && total > (level == 3 ? 0.99 : 0.6) * 4 * M_PI * 4);
            free(areas);
        }
        dk_mesh_free(m);
        dk_test_mesh_free(&g);
    }
}

static void test_grid_and_others(void)
{
    dk_test_mesh g;
    CHECK(dk_test_grid(6, 1.0, 0.25, &g) == 0);
    dk_mesh *m = dk_test_mesh_build(&g);
    if (m) {
        check_invariants(m);
        CHECK(m->n_vertices == 49 && m->n_faces == 72);
        CHECK(m->report.n_boundary_edges == 24);
        CHECK(m->n_vertices - m->n_edges + m->n_faces == 1); /* a disc */
        int ok = 1, nb = 0;
        for (dk_index v = 0; v < m->n_vertices; v++) {
            int i = v % 7, j = v / 7;
            int on = i == 0 || j == 0 || i == 6 || j == 6;
            nb += m->is_boundary_vertex[v];
            if (on != m->is_boundary_vertex[v]) ok = 0;
        }
        CHECK(ok && nb == 24);
        CHECK_NEAR(m->bbox_max[0], 1.0, 0);
        CHECK_NEAR(m->bbox_min[1], 0.0, 0);
        double *areas = malloc(sizeof(double) * m->n_faces), total = 0;
        dk_mesh_face_areas(m, NULL, areas);
        for (dk_index f = 0; f < m->n_faces; f++) total += areas[f];
        CHECK_NEAR(total, 1.0, 1e-12); /* jitter keeps the square tiled */
        free(areas);
        CHECK(m->mean_edge_length > 0.1 && m->mean_edge_length < 0.3);
    }
    dk_mesh_free(m);
    dk_test_mesh_free(&g);

    /* closed bar and capped cylinder: sphere topology; open bar: a tube with 2 boundaries */
    CHECK(dk_test_closed_bar(5, 2, 0.5, 4.0, &g) == 0);
    m = dk_test_mesh_build(&g);
    if (m) {
        check_invariants(m);
        CHECK(m->n_vertices - m->n_edges + m->n_faces == 2);
        CHECK(m->report.n_boundary_edges == 0);
        CHECK_NEAR(signed_volume(m), 4.0, 1e-12);
    }
    dk_mesh_free(m);
    dk_test_mesh_free(&g);
    CHECK(dk_test_bar(5, 2, 0.5, 4.0, &g) == 0);
    m = dk_test_mesh_build(&g);
    if (m) {
        check_invariants(m);
        CHECK(m->n_vertices - m->n_edges + m->n_faces == 0);
        CHECK(m->report.n_boundary_edges == 16);
    }
    dk_mesh_free(m);
    dk_test_mesh_free(&g);
    CHECK(dk_test_cylinder(12, 8, 1.0, 5.0, 1, &g) == 0);
    m = dk_test_mesh_build(&g);
    if (m) {
        check_invariants(m);
        CHECK(m->n_vertices - m->n_edges + m->n_faces == 2);
        CHECK(signed_volume(m) > 0);
    }
    dk_mesh_free(m);
    dk_test_mesh_free(&g);
    CHECK(dk_test_uv_sphere(10, 6, 1.0, &g) == 0);
    m = dk_test_mesh_build(&g);
    if (m) {
        check_invariants(m);
        CHECK(m->n_vertices - m->n_edges + m->n_faces == 2);
        CHECK(m->report.n_boundary_edges == 0 && m->report.n_nonmanifold_edges == 0);
        CHECK(signed_volume(m) > 0);
    }
    dk_mesh_free(m);
    dk_test_mesh_free(&g);
    CHECK(dk_test_bumpy_plane(10, 0.3, &g) == 0);
    m = dk_test_mesh_build(&g);
    if (m) {
        check_invariants(m);
        CHECK(m->bbox_max[2] > 0.1);
    }
    dk_mesh_free(m);
    dk_test_mesh_free(&g);
}

static void test_defects(void)
{
    /* two disjoint triangles + an isolated vertex (index 3) + a degenerate triangle */
    const double p[] = {0, 0, 0, 1, 0, 0, 0, 1, 0, 9, 9, 9,
                        5, 0, 0, 6, 0, 0, 5, 1, 0, 7, 0, 0, 8, 0, 0};
    const dk_index f[] = {0, 1, 2, 4, 5, 6, 4, 7, 8};
    dk_mesh *m = NULL;
    dk_error err = {0};
    CHECK(dk_mesh_create(p, 9, f, 3, &m, &err) == DK_OK);
    if (m) {
        check_invariants(m);
        CHECK(m->report.n_isolated_vertices == 1 && m->report.first_isolated_vertex == 3);
        CHECK(m->report.n_components == 3);
        CHECK(m->component[0] == 0 && m->component[3] == 1 && m->component[4] == 2 &&
              m->component[8] == 2);
        CHECK(m->report.n_degenerate_faces == 1 && m->report.first_degenerate_face == 2);
        double areas[3];
        dk_mesh_face_areas(m, NULL, areas);
        CHECK(areas[2] == 0.0 && fabs(areas[0] - 0.5) < 1e-15);
        CHECK(dk_mesh_find_edge(m, 0, 3) == -1 && dk_mesh_find_edge(m, 0, 99) == -1);
    }
    dk_mesh_free(m);

    /* non-manifold fan: three triangles on edge (0, 1) */
    const double q[] = {0, 0, 0, 1, 0, 0, 0.5, 1, 0, 0.5, -1, 0, 0.5, 0, 1};
    const dk_index g[] = {0, 1, 2, 1, 0, 3, 0, 1, 4};
    CHECK(dk_mesh_create(q, 5, g, 3, &m, &err) == DK_OK);
    if (m) {
        check_invariants(m);
        dk_index e = dk_mesh_find_edge(m, 1, 0);
        CHECK(e >= 0 && m->edge_face_count[e] == 3);
        CHECK(m->report.n_nonmanifold_edges == 1 && m->report.first_nonmanifold_edge == e);
        CHECK(m->report.n_boundary_edges == 6);
        CHECK(m->report.n_components == 1);
    }
    dk_mesh_free(m);

    /* an empty mesh */
    CHECK(dk_mesh_create(NULL, 0, NULL, 0, &m, &err) == DK_OK);
    if (m) CHECK(m->n_edges == 0 && m->report.n_components == 0 && m->ring_start[0] == 0);
    dk_mesh_free(m);

    /* a point cloud */
    CHECK(dk_mesh_create(q, 5, NULL, 0, &m, &err) == DK_OK);
    if (m) {
        CHECK(m->n_edges == 0 && m->report.n_isolated_vertices == 5);
        CHECK(m->report.n_components == 5 && m->mean_edge_length == 0.0);
    }
    dk_mesh_free(m);
}

static void test_errors(void)
{
    const double p[] = {0, 0, 0, 1, 0, 0, 0, 1, 0, 1, 1, 0};
    dk_mesh *m = (dk_mesh *)&p;
    dk_error err = {0};
    const dk_index bad[] = {0, 1, 2, 2, 1, 4};
    CHECK(dk_mesh_create(p, 4, bad, 2, &m, &err) == DK_ERR_INDEX);
    CHECK(m == NULL);
    CHECK_MSG(strstr(err.message, "face 1 index 2 is 4, out of range [0, 3]"), "%s",
              err.message);
    const dk_index neg[] = {0, -1, 2};
    CHECK(dk_mesh_create(p, 4, neg, 1, &m, &err) == DK_ERR_INDEX);
    CHECK_MSG(strstr(err.message, "face 0 index 1 is -1"), "%s", err.message);
    const dk_index rep[] = {0, 1, 2, 3, 1, 3};
    CHECK(dk_mesh_create(p, 4, rep, 2, &m, &err) == DK_ERR_TOPOLOGY);
    CHECK_MSG(strstr(err.message, "face 1 repeats vertex 3 (corners 0 and 2)"), "%s",
              err.message);
    double pn[12];
    memcpy(pn, p, sizeof pn);
    pn[7] = NAN;
    CHECK(dk_mesh_create(pn, 4, bad, 1, &m, &err) == DK_ERR_NONFINITE);
    CHECK_MSG(strstr(err.message, "vertex 2 coordinate y is nan"), "%s", err.message);
    pn[7] = 0;
    pn[9] = -INFINITY;
    CHECK(dk_check_positions(pn, 4, &err) == DK_ERR_NONFINITE);
    CHECK_MSG(strstr(err.message, "vertex 3 coordinate x is -inf"), "%s", err.message);
    CHECK(dk_check_positions(p, 4, &err) == DK_OK);
    CHECK(dk_check_indices(bad, 6, 4, "handle 2 vertex", &err) == DK_ERR_INDEX);
    CHECK_MSG(strstr(err.message, "handle 2 vertex 5 is 4, out of range [0, 4)"), "%s",
              err.message);
    CHECK(dk_check_indices(bad, 5, 4, "x", NULL) == DK_OK);
    /* polygons */
    const dk_index sizes[] = {4, 2};
    const dk_index idx[] = {0, 1, 3, 2, 0, 1};
    CHECK(dk_mesh_from_polygons(p, 4, sizes, 2, idx, 6, &m, &err) == DK_ERR_TOPOLOGY);
    CHECK_MSG(strstr(err.message, "polygon 1 has 2 corners"), "%s", err.message);
    const dk_index sizes2[] = {3, 3};
    const dk_index idx2[] = {0, 1, 3, 0, 7, 1};
    CHECK(dk_mesh_from_polygons(p, 4, sizes2, 2, idx2, 6, &m, &err) == DK_ERR_INDEX);
    CHECK_MSG(strstr(err.message, "polygon 1 corner 1 is 7, out of range [0, 3]"), "%s",
              err.message);
    const dk_index sizes3[] = {4};
    const dk_index idx3[] = {0, 1, 2, 1}, q4[] = {0, 1, 3, 2, 0};
    CHECK(dk_mesh_from_polygons(p, 4, sizes3, 1, idx3, 4, &m, &err) == DK_ERR_TOPOLOGY);
    CHECK_MSG(strstr(err.message, "polygon 0 repeats vertex 1 (corners 1 and 3)"), "%s",
              err.message);
    CHECK(dk_mesh_from_polygons(p, 4, sizes3, 1, q4, 5, &m, &err) == DK_ERR_INVALID_ARGUMENT);
    CHECK_MSG(strstr(err.message, "add up to 4 but 5 indices"), "%s", err.message);
    CHECK(dk_mesh_create(p, 4, bad, 1, NULL, &err) == DK_ERR_INVALID_ARGUMENT);
    CHECK(m == NULL);
}

static double polygon_mesh_area(const dk_mesh *m)
{
    double *a = malloc(sizeof(double) * (m->n_faces + 1)), t = 0;
    dk_mesh_face_areas(m, NULL, a);
    for (dk_index f = 0; f < m->n_faces; f++) t += a[f];
    free(a);
    return t;
}

static void test_polygons(void)
{
    /* quad with a short diagonal 1-3: a kite, long along 0-2 */
    const double kite[] = {0, 0, 0, 2, -0.5, 0, 4, 0, 0, 2, 0.5, 0};
    const dk_index s4[] = {4}, q[] = {0, 1, 2, 3};
    dk_mesh *m = NULL;
    dk_error err = {0};
    CHECK(dk_mesh_from_polygons(kite, 4, s4, 1, q, 4, &m, &err) == DK_OK);
    if (m) {
        CHECK(m->n_faces == 2 && m->n_polygons == 1);
        CHECK(m->face_polygon[0] == 0 && m->face_polygon[1] == 0);
        CHECK(dk_mesh_find_edge(m, 1, 3) >= 0 && dk_mesh_find_edge(m, 0, 2) == -1);
        CHECK_NEAR(polygon_mesh_area(m), 2.0, 1e-14);
        check_invariants(m);
    }
    dk_mesh_free(m);

    /* L-shaped hexagon (non-convex), in a tilted plane, plus a triangle: area preserved,
     * every triangle keeps the polygon's orientation (no fold-over) */
    const double l2[6][2] = {{0, 0}, {2, 0}, {2, 1}, {1, 1}, {1, 2}, {0, 2}};
    double pos[3 * 7];
    for (int i = 0; i < 6; i++) { /* plane spanned by (1,0,1)/sqrt2 and (0,1,0) */
        pos[3 * i] = l2[i][0] / sqrt(2.0);
        pos[3 * i + 1] = l2[i][1];
        pos[3 * i + 2] = l2[i][0] / sqrt(2.0) + 3.0;
    }
    pos[18] = 5;
    pos[19] = 5;
    pos[20] = 5;
    /* start the hexagon at corner (2, 1): a naive fan from there folds over at (1, 1) */
    const dk_index sizes[] = {6, 3}, idx[] = {2, 3, 4, 5, 0, 1, 0, 1, 6};
    CHECK(dk_mesh_from_polygons(pos, 7, sizes, 2, idx, 9, &m, &err) == DK_OK);
    if (m) {
        CHECK(m->n_faces == 5 && m->n_polygons == 2);
        CHECK(m->face_polygon[4] == 1 && m->face_polygon[0] == 0 && m->face_polygon[3] == 0);
        double a[5];
        dk_mesh_face_areas(m, NULL, a);
        CHECK_NEAR(a[0] + a[1] + a[2] + a[3], 3.0, 1e-12);
        /* normal of each triangle of the hexagon points along the polygon normal */
        double n0[3] = {-1 / sqrt(2.0), 0, 1 / sqrt(2.0)}; /* u x v for u=(1,0,1)/r2, v=y */
        int ok = 1;
        for (int f = 0; f < 4; f++) {
            const double *A = pos + 3 * m->faces[3 * f], *B = pos + 3 * m->faces[3 * f + 1],
                         *C = pos + 3 * m->faces[3 * f + 2];
            double u[3] = {B[0] - A[0], B[1] - A[1], B[2] - A[2]};
            double v[3] = {C[0] - A[0], C[1] - A[1], C[2] - A[2]};
            double n[3] = {u[1] * v[2] - u[2] * v[1], u[2] * v[0] - u[0] * v[2],
                           u[0] * v[1] - u[1] * v[0]};
            if (n[0] * n0[0] + n[1] * n0[1] + n[2] * n0[2] <= 1e-12) ok = 0;
        }
        CHECK_MSG(ok, "an ear-clipped triangle is flipped or degenerate");
        check_invariants(m);
    }
    dk_mesh_free(m);

    /* a star-shaped 10-gon (5 reflex corners) */
    double star[3 * 10];
    dk_index sidx[10];
    const dk_index s10[] = {10};
    double exact = 0;
    for (int i = 0; i < 10; i++) {
        double r = i % 2 ? 0.4 : 1.0, t = M_PI * i / 5;
        star[3 * i] = r * cos(t);
        star[3 * i + 1] = r * sin(t);
        star[3 * i + 2] = 0;
        sidx[i] = i;
    }
    for (int i = 0; i < 10; i++) {
        const double *a = star + 3 * i, *b = star + 3 * ((i + 1) % 10);
        exact += 0.5 * (a[0] * b[1] - a[1] * b[0]);
    }
    CHECK(dk_mesh_from_polygons(star, 10, s10, 1, sidx, 10, &m, &err) == DK_OK);
    if (m) {
        CHECK(m->n_faces == 8);
        CHECK_NEAR(polygon_mesh_area(m), exact, 1e-12);
        CHECK(m->report.n_boundary_edges == 10 && m->report.n_nonmanifold_edges == 0);
    }
    dk_mesh_free(m);
}

static void test_speed(void)
{
    dk_test_mesh g;
    int n = SANITIZED ? 150 : 1000; /* 1M vertices, 2M triangles when not sanitized */
    CHECK(dk_test_grid(n, 1.0, 0.2, &g) == 0);
    dk_mesh *m = NULL;
    struct timespec t0, t1;
    timespec_get(&t0, TIME_UTC);
    CHECK(dk_mesh_create(g.positions, g.n_vertices, g.faces, g.n_faces, &m, NULL) == DK_OK);
    timespec_get(&t1, TIME_UTC);
    double secs = (t1.tv_sec - t0.tv_sec) + 1e-9 * (t1.tv_nsec - t0.tv_nsec);
    printf("mesh topology: %ld vertices, %ld triangles in %.3f s\n", (long)g.n_vertices,
           (long)g.n_faces, secs);
    if (m) {
        CHECK(m->n_vertices - m->n_edges + m->n_faces == 1);
        CHECK(m->report.n_boundary_edges == 4 * n);
        if (SANITIZED) check_invariants(m);
        /* speed is the benchmarks' (scripts/bench_core.py), not a test's: the time is printed only */
    }
    dk_mesh_free(m);
    dk_test_mesh_free(&g);
}

DK_TEST_MAIN(test_icosphere, test_grid_and_others, test_defects, test_errors, test_polygons,
             test_speed)
