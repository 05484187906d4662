/* Embedded deformation's own native checks beyond the contract (test_contract.c), so that
 * the sanitized build walks them too: geodesic influence on a closed surface and on a mesh
 * whose small second component reaches too few nodes along its surface (the Euclidean
 * fallback), and its refusal on a point set. The behaviour itself (a hand that stops moving
 * the leg) is tested from Python, tests/python/test_embedded.py. */
#include <math.h>
#include <stdlib.h>
#include <string.h>

#include "dk_embedded.h"
#include "dk_test.h"
#include "dk_test_meshes.h"

/* an icosphere and, when `island`, one far small triangle as a second component */
static dk_mesh *sphere(int island, int with_faces)
{
    dk_test_mesh t;
    if (dk_test_icosphere(3, 1.0, &t) != 0)
        return NULL;
    const dk_index n = t.n_vertices + (island ? 3 : 0), nf = t.n_faces + (island ? 1 : 0);
    double *p = malloc(3 * (size_t)n * sizeof *p);
    dk_index *f = malloc(3 * (size_t)nf * sizeof *f);
    dk_mesh *m = NULL;
    dk_error e;
    if (p && f) {
        memcpy(p, t.positions, 3 * (size_t)t.n_vertices * sizeof *p);
        memcpy(f, t.faces, 3 * (size_t)t.n_faces * sizeof *f);
        if (island) {
            const double tri[9] = {3, 0, 0, 3.05, 0, 0, 3, 0.05, 0};
            memcpy(p + 3 * (size_t)t.n_vertices, tri, sizeof tri);
            for (int c = 0; c < 3; c++)
                f[3 * (size_t)t.n_faces + (size_t)c] = t.n_vertices + c;
        }
        if (dk_mesh_create(p, n, f, with_faces ? nf : 0, &m, &e) != DK_OK)
            m = NULL;
    }
    free(p);
    free(f);
    dk_test_mesh_free(&t);
    return m;
}

/* binds with geodesic influence, checks the weights through embed's rows being sane, solves
 * a zero drag and a real one */
static void check_geodesic(dk_mesh *m)
{
    dk_index handle = 0, size = 1;
    dk_constraint_desc d = {.n_handles = 1, .handle_sizes = &size, .handle_vertices = &handle};
    dk_embedded_options o;
    dk_embedded_default_options(&o);
    o.n_nodes = 60;
    o.distance = DK_ED_DISTANCE_GEODESIC;
    dk_embedded *ed = NULL;
    dk_error e;
    CHECK_MSG(dk_embedded_bind(m, &d, &o, &ed, &e) == DK_OK, "bind: %s", e.message);
    if (!ed)
        return;
    const dk_index n = m->n_vertices;
    double *x = malloc(3 * (size_t)n * sizeof *x);
    if (!x)
        abort();
    dk_solve_info info;
    double t[3] = {m->positions[0], m->positions[1], m->positions[2]};
    CHECK(dk_embedded_solve(ed, &(dk_solve_request){.targets = t}, x, &info, &e) == DK_OK);
    double dev = 0.0;
    for (size_t i = 0; i < 3 * (size_t)n; i++)
        dev = fmax(dev, fabs(x[i] - m->positions[i]));
    CHECK_MSG(dev <= 1e-12, "zero drag moved the mesh by %g", dev);
    t[0] += 0.3;
    CHECK(dk_embedded_solve(ed, &(dk_solve_request){.targets = t}, x, &info, &e) == DK_OK);
    CHECK_MSG(fabs(x[0] - t[0]) < 0.05 * 0.3, "handle at %g, target %g", x[0], t[0]);
    for (size_t i = 0; i < 3 * (size_t)n; i++)
        CHECK(isfinite(x[i]));
    free(x);
    dk_embedded_free(ed);
}

static void test_geodesic_influence(void)
{
    dk_mesh *closed = sphere(0, 1), *islands = sphere(1, 1), *points = sphere(0, 0);
    CHECK(closed && islands && points);
    if (closed)
        check_geodesic(closed);
    if (islands) /* the triangle reaches no node along its surface: Euclidean for it */
        check_geodesic(islands);
    if (points) {
        dk_index handle = 0, size = 1;
        dk_constraint_desc d = {.n_handles = 1, .handle_sizes = &size,
                                .handle_vertices = &handle};
        dk_embedded_options o;
        dk_embedded_default_options(&o);
        o.distance = DK_ED_DISTANCE_GEODESIC;
        dk_embedded *ed = NULL;
        dk_error e;
        CHECK(dk_embedded_bind(points, &d, &o, &ed, &e) == DK_ERR_INVALID_ARGUMENT);
        CHECK(ed == NULL && strstr(e.message, "geodesic") != NULL);
        o.distance = (dk_ed_distance)7;
        CHECK(dk_embedded_bind(points, &d, &o, &ed, &e) == DK_ERR_INVALID_ARGUMENT);
    }
    dk_mesh_free(closed);
    dk_mesh_free(islands);
    dk_mesh_free(points);
}

/* a cut between the upper and the lower cap of a sphere, in both distances: binds, solves,
 * and no vertex of one side is influenced by a node that the other side's vertices use */
static void test_cut(void)
{
    dk_mesh *m = sphere(0, 1);
    CHECK(m != NULL);
    if (!m)
        return;
    const dk_index n = m->n_vertices;
    dk_index *a = malloc((size_t)n * sizeof *a), *b = malloc((size_t)n * sizeof *b);
    unsigned char *side = calloc((size_t)n, 1);
    double *x = malloc(3 * (size_t)n * sizeof *x);
    if (!a || !b || !side || !x)
        abort();
    dk_index na = 0, nb = 0;
    for (dk_index v = 0; v < n; v++) {
        if (m->positions[3 * v + 2] > 0.2) {
            a[na++] = v;
            side[v] = 1;
        } else if (m->positions[3 * v + 2] < -0.2) {
            b[nb++] = v;
            side[v] = 2;
        }
    }
    dk_index handle = a[0], size = 1;
    dk_constraint_desc d = {.n_handles = 1, .handle_sizes = &size, .handle_vertices = &handle};
    for (int dist = 0; dist < 2; dist++) {
        dk_embedded_options o;
        dk_embedded_default_options(&o);
        o.n_nodes = 60;
        o.distance = dist ? DK_ED_DISTANCE_GEODESIC : DK_ED_DISTANCE_EUCLIDEAN;
        o.cut_a = a;
        o.n_cut_a = na;
        o.cut_b = b;
        o.n_cut_b = nb;
        dk_embedded *ed = NULL;
        dk_error e;
        CHECK_MSG(dk_embedded_bind(m, &d, &o, &ed, &e) == DK_OK, "bind: %s", e.message);
        if (!ed)
            continue;
        /* no edge joins a node nearest to side A with one nearest to side B */
        const dk_index mm = dk_embedded_n_nodes(ed), ne = dk_embedded_n_edges(ed);
        const double *g = dk_embedded_nodes(ed);
        const dk_index *edges = dk_embedded_edges(ed);
        unsigned char *ns = malloc((size_t)mm + 1);
        if (!ns)
            abort();
        for (dk_index j = 0; j < mm; j++) {
            double best = INFINITY;
            for (dk_index v = 0; v < n; v++) {
                const double *p = m->positions + 3 * v, *q = g + 3 * j;
                const double dd = (p[0] - q[0]) * (p[0] - q[0]) + (p[1] - q[1]) * (p[1] - q[1]) +
                                  (p[2] - q[2]) * (p[2] - q[2]);
                if (dd < best) {
                    best = dd;
                    ns[j] = side[v];
                }
            }
        }
        int crossing = 0;
        for (dk_index i = 0; i < ne; i++)
            crossing += ns[edges[2 * i]] * ns[edges[2 * i + 1]] == 2;
        CHECK_MSG(crossing == 0, "%d edges cross the cut (distance %d)", crossing, dist);
        double t[3] = {m->positions[3 * handle], m->positions[3 * handle + 1],
                       m->positions[3 * handle + 2] + 0.2};
        dk_solve_info info;
        CHECK(dk_embedded_solve(ed, &(dk_solve_request){.targets = t}, x, &info, &e) == DK_OK);
        free(ns);
        dk_embedded_free(ed);
        /* the refusals: overlapping sides, one side only */
        o.n_cut_b = nb + 1;
        b[nb] = a[0];
        CHECK(dk_embedded_bind(m, &d, &o, &ed, &e) == DK_ERR_INVALID_ARGUMENT);
        CHECK(strstr(e.message, "both cut groups") != NULL);
        o.n_cut_b = 0;
        CHECK(dk_embedded_bind(m, &d, &o, &ed, &e) == DK_ERR_INVALID_ARGUMENT);
        CHECK(ed == NULL);
    }
    free(a);
    free(b);
    free(side);
    free(x);
    dk_mesh_free(m);
}

/* section 5: a translated source with translated targets gives the translated result, for
 * nodes on vertices and for surface samples (which keep their place in their triangles);
 * a refused update changes nothing */
static void test_update_source(void)
{
    dk_mesh *m = sphere(0, 1);
    CHECK(m != NULL);
    if (!m)
        return;
    const dk_index n = m->n_vertices;
    double *p = malloc(3 * (size_t)n * sizeof *p), *x = malloc(3 * (size_t)n * sizeof *x),
           *y = malloc(3 * (size_t)n * sizeof *y);
    if (!p || !x || !y)
        abort();
    dk_index handle = 0, size = 1;
    dk_constraint_desc d = {.n_handles = 1, .handle_sizes = &size, .handle_vertices = &handle};
    dk_embedded_options o;
    dk_embedded_default_options(&o);
    o.n_nodes = 60;
    o.nodes = DK_ED_NODES_VERTICES;
    dk_embedded *ed = NULL, *surf = NULL;
    dk_error e;
    CHECK(dk_embedded_bind(m, &d, &o, &ed, &e) == DK_OK);
    o.nodes = DK_ED_NODES_SURFACE;
    CHECK(dk_embedded_bind(m, &d, &o, &surf, &e) == DK_OK);
    if (ed && surf) {
        dk_solve_info info;
        double t[3] = {m->positions[0] + 0.3, m->positions[1], m->positions[2]};
        CHECK(dk_embedded_solve(ed, &(dk_solve_request){.targets = t}, x, &info, &e) == DK_OK);
        for (size_t i = 0; i < 3 * (size_t)n; i++)
            p[i] = m->positions[i] + (i % 3 == 2 ? 2.0 : 0.0);
        CHECK(dk_embedded_update_source(ed, p, &e) == DK_OK);
        t[2] += 2.0;
        CHECK(dk_embedded_solve(ed, &(dk_solve_request){.targets = t}, y, &info, &e) == DK_OK);
        double dev = 0.0;
        for (size_t i = 0; i < 3 * (size_t)n; i++)
            dev = fmax(dev, fabs(y[i] - x[i] - (i % 3 == 2 ? 2.0 : 0.0)));
        CHECK_MSG(dev < 1e-8, "translated source: off by %g", dev);
        p[4] = NAN;
        CHECK(dk_embedded_update_source(ed, p, &e) != DK_OK);
        CHECK(dk_embedded_deformed(ed, x, &e) == DK_OK);
        dev = 0.0;
        for (size_t i = 0; i < 3 * (size_t)n; i++)
            dev = fmax(dev, fabs(x[i] - y[i]));
        CHECK_MSG(dev == 0.0, "a refused update changed the result by %g", dev);
        t[2] -= 2.0;
        p[4] = m->positions[4];
        CHECK(dk_embedded_solve(surf, &(dk_solve_request){.targets = t}, x, &info, &e) == DK_OK);
        const dk_index ms = dk_embedded_n_nodes(surf);
        double *g0 = malloc(3 * (size_t)ms * sizeof *g0);
        if (!g0)
            abort();
        memcpy(g0, dk_embedded_nodes(surf), 3 * (size_t)ms * sizeof *g0);
        CHECK(dk_embedded_update_source(surf, p, &e) == DK_OK);
        dev = 0.0;
        for (size_t i = 0; i < 3 * (size_t)ms; i++)
            dev = fmax(dev, fabs(dk_embedded_nodes(surf)[i] - g0[i] - (i % 3 == 2 ? 2.0 : 0.0)));
        CHECK_MSG(dev < 1e-12, "surface nodes did not ride along: off by %g", dev);
        free(g0);
        t[2] += 2.0;
        CHECK(dk_embedded_solve(surf, &(dk_solve_request){.targets = t}, y, &info, &e) == DK_OK);
        dev = 0.0;
        for (size_t i = 0; i < 3 * (size_t)n; i++)
            dev = fmax(dev, fabs(y[i] - x[i] - (i % 3 == 2 ? 2.0 : 0.0)));
        CHECK_MSG(dev < 1e-8, "translated source, surface nodes: off by %g", dev);
    }
    dk_embedded_free(ed);
    dk_embedded_free(surf);
    free(p);
    free(x);
    free(y);
    dk_mesh_free(m);
}

/* What fuzz_method found (tests/fuzz/corpus/method/crash-embedded-*): a radius of 1e-300
 * overflowed the sampling grid's int64 cell numbers (UBSan: undefined behaviour); clamping
 * them instead made one cell of 200,000 samples, minutes of elimination. A radius below
 * 1e-12 of the extent is refused, so is one that keeps more than 100000 nodes, and a tiny
 * but meaningful radius on a vertex graph still binds (every vertex a node). */
static void test_radius_bounds(void)
{
    dk_test_mesh t;
    if (dk_test_grid(4, 1.0, 0.0, &t) != 0) return;
    dk_mesh *m = dk_test_mesh_build(&t);
    dk_test_mesh_free(&t);
    if (!m) return;
    const dk_index hv[2] = {0, 1}, sizes[1] = {2};
    dk_constraint_desc c = {.n_handles = 1, .handle_sizes = sizes, .handle_vertices = hv};
    dk_embedded_options o;
    dk_embedded *ed = NULL;
    dk_error e = {0};
    const double tiny[3] = {1e-300, 4.9e-324, 1e-13};
    for (int i = 0; i < 3; i++) {
        dk_embedded_default_options(&o);
        o.radius = tiny[i];
        CHECK(dk_embedded_bind(m, &c, &o, &ed, &e) == DK_ERR_INVALID_ARGUMENT && !ed);
        CHECK_MSG(strstr(e.message, "below 1e-12 of the surface's extent"), "%s", e.message);
    }
    dk_embedded_default_options(&o);
    o.radius = 1e-10; /* surface samples: nearly all 200,000 would be nodes */
    CHECK(dk_embedded_bind(m, &c, &o, &ed, &e) == DK_ERR_INVALID_ARGUMENT && !ed);
    CHECK_MSG(strstr(e.message, "keeps more than 100000 nodes"), "%s", e.message);
    o.nodes = DK_ED_NODES_VERTICES; /* 25 vertices: 25 nodes */
    CHECK_MSG(dk_embedded_bind(m, &c, &o, &ed, &e) == DK_OK, "%s", e.message);
    CHECK(dk_embedded_n_nodes(ed) == 25);
    dk_embedded_free(ed);
    dk_mesh_free(m);
    /* a point set whose points coincide: the node bisection's radius was 0, every cell
     * number 0 / 0 (NaN into an int64; crash-embedded-coincident-vertices-nan-cell). One
     * node, so refused for having fewer than k + 1 */
    const double same[15] = {0};
    CHECK(dk_mesh_create(same, 5, NULL, 0, &m, &e) == DK_OK);
    dk_embedded_default_options(&o);
    o.k = 1;
    CHECK(dk_embedded_bind(m, &c, &o, &ed, &e) != DK_OK && !ed);
    CHECK_MSG(strstr(e.message, "node"), "%s", e.message);
    dk_mesh_free(m);
}

/* Found by tests/python/test_properties.py: the default 200 nodes on a 5 x 5-cell grid make a
 * graph whose pieces influence neighbouring vertices but share none; translating both ends
 * left the inner vertices exactly at rest ("converged", F = 2e-9). The pieces are now
 * joined along the mesh's edges, so every vertex follows (most of the way: a graph that
 * much denser than its mesh is floppy, docs/reliability.md). */
static void test_dense_graph_is_connected_along_the_surface(void)
{
    dk_test_mesh t;
    if (dk_test_grid(5, 1.0, 0.2, &t) != 0) return;
    dk_mesh *m = dk_test_mesh_build(&t);
    if (!m) { dk_test_mesh_free(&t); return; }
    dk_index hv[12], sizes[2] = {6, 6};
    for (int j = 0; j < 6; j++) {
        hv[j] = j * 6;          /* x = 0 column */
        hv[6 + j] = j * 6 + 5;  /* x = 1 column */
    }
    dk_constraint_desc c = {.n_handles = 2, .handle_sizes = sizes, .handle_vertices = hv};
    dk_embedded *ed = NULL;
    dk_error e = {0};
    double T[32] = {0}, *x = malloc(3 * (size_t)m->n_vertices * sizeof *x);
    for (int h = 0; h < 2; h++) {
        T[16 * h] = T[16 * h + 5] = T[16 * h + 10] = T[16 * h + 15] = 1;
        T[16 * h + 11] = 1.0; /* up by 1 */
    }
    /* the default 200 nodes are capped at the vertex count now; a small radius still
     * makes a graph denser than the mesh */
    CHECK_MSG(dk_embedded_bind(m, &c, NULL, &ed, &e) == DK_OK, "%s", e.message);
    if (ed)
        CHECK(dk_embedded_n_nodes(ed) <= m->n_vertices);
    dk_embedded_free(ed);
    ed = NULL;
    dk_embedded_options o;
    dk_embedded_default_options(&o);
    o.radius = 0.03;
    CHECK_MSG(x && dk_embedded_bind(m, &c, &o, &ed, &e) == DK_OK, "%s", e.message);
    if (ed && x) {
        CHECK_MSG(dk_embedded_n_nodes(ed) > m->n_vertices, "%d nodes", (int)dk_embedded_n_nodes(ed)); /* the dense case */
        dk_solve_request rq = {.targets = T, .target_kind = DK_TARGETS_TRANSFORMS};
        CHECK_MSG(dk_embedded_solve(ed, &rq, x, NULL, &e) == DK_OK, "%s", e.message);
        double least = INFINITY;
        for (dk_index v = 0; v < m->n_vertices; v++)
            least = fmin(least, x[3 * v + 2] - t.positions[3 * v + 2]);
        CHECK_MSG(least > 0.5, "a vertex moved up by only %g of 1", least);
    }
    dk_embedded_free(ed);
    free(x);
    dk_mesh_free(m);
    dk_test_mesh_free(&t);
}

DK_TEST_MAIN(test_geodesic_influence, test_cut, test_update_source, test_radius_bounds,
             test_dense_graph_is_connected_along_the_surface)
