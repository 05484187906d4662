/* Tests of the geodesic distances: Dijkstra exact against Bellman-Ford on the edge graph,
 * hop counts against unit-weight Bellman-Ford, unreachable vertices, argument errors; the
 * heat method against Euclidean distance on an irregular flat grid (with boundary) and
 * great-circle distance on an icosphere, factorizations reused across calls, several
 * components, a source on the boundary. */
#define _POSIX_C_SOURCE 199309L /* clock_gettime */
#include <math.h>
#include <stdio.h>
#include <time.h>
#include <stdlib.h>
#include <string.h>

#include "dk_io.h"
#include "dk_operators.h"
#include "dk_test.h"
#include "dk_test_meshes.h"

static double edge_len(const dk_mesh *m, dk_index e)
{
    const double *a = m->positions + 3 * m->edges[2 * e], *b = m->positions + 3 * m->edges[2 * e + 1];
    double dx = a[0] - b[0], dy = a[1] - b[1], dz = a[2] - b[2];
    return sqrt(dx * dx + dy * dy + dz * dz);
}

/* Bellman-Ford over the unique edges; unit = 1 counts hops. */
static void bellman_ford(const dk_mesh *m, const dk_index *src, int ns, int unit, double *d)
{
    for (dk_index v = 0; v < m->n_vertices; v++) d[v] = INFINITY;
    for (int s = 0; s < ns; s++) d[src[s]] = 0;
    for (int changed = 1; changed;) {
        changed = 0;
        for (dk_index e = 0; e < m->n_edges; e++) {
            dk_index a = m->edges[2 * e], b = m->edges[2 * e + 1];
            double w = unit ? 1.0 : edge_len(m, e);
            if (d[a] + w < d[b]) d[b] = d[a] + w, changed = 1;
            if (d[b] + w < d[a]) d[a] = d[b] + w, changed = 1;
        }
    }
}

static dk_mesh *two_component_mesh(void)
{
    /* an irregular grid plus a separate translated copy of the same grid */
    dk_test_mesh g;
    if (dk_test_grid(6, 1.0, 0.25, &g) != 0) return NULL;
    dk_index n = g.n_vertices, nf = g.n_faces;
    double *p = malloc((size_t)n * 6 * sizeof *p);
    dk_index *f = malloc((size_t)nf * 6 * sizeof *f);
    dk_mesh *m = NULL;
    if (p && f) {
        for (dk_index v = 0; v < n; v++)
            for (int d = 0; d < 3; d++) {
                p[3 * v + d] = g.positions[3 * v + d];
                p[3 * (n + v) + d] = g.positions[3 * v + d] + (d == 0 ? 5.0 : 0.0);
            }
        for (dk_index k = 0; k < 3 * nf; k++) f[k] = g.faces[k], f[3 * nf + k] = g.faces[k] + n;
        dk_error err = {0};
        if (dk_mesh_create(p, 2 * n, f, 2 * nf, &m, &err) != DK_OK)
            fprintf(stderr, "two components: %s\n", err.message);
    }
    free(p);
    free(f);
    dk_test_mesh_free(&g);
    return m;
}

static void test_dijkstra_and_hops(void)
{
    dk_test_mesh g;
    if (dk_test_icosphere(2, 1.0, &g) != 0) {
        CHECK(0);
        return;
    }
    dk_mesh *m = dk_test_mesh_build(&g);
    dk_test_mesh_free(&g);
    if (!m) {
        CHECK(0);
        return;
    }
    dk_index n = m->n_vertices;
    double *d = malloc((size_t)n * sizeof *d), *ref = malloc((size_t)n * sizeof *ref);
    dk_index *hops = malloc((size_t)n * sizeof *hops);
    dk_error err = {0};
    if (d && ref && hops) {
        const dk_index sets[3][3] = {{0, 0, 0}, {5, 77, 140}, {17, 17, 3}};
        const int counts[3] = {1, 3, 3};
        for (int s = 0; s < 3; s++) {
            CHECK(dk_geodesic_dijkstra(m, sets[s], counts[s], d, &err) == DK_OK);
            bellman_ford(m, sets[s], counts[s], 0, ref);
            double worst = 0;
            for (dk_index v = 0; v < n; v++) worst = fmax(worst, fabs(d[v] - ref[v]));
            CHECK_MSG(worst < 1e-12, "Dijkstra vs Bellman-Ford: %g", worst);
            CHECK(dk_hop_distance(m, sets[s], counts[s], hops, &err) == DK_OK);
            bellman_ford(m, sets[s], counts[s], 1, ref);
            int same = 1;
            for (dk_index v = 0; v < n; v++) same &= hops[v] == (dk_index)ref[v];
            CHECK(same);
        }
        /* edge paths are at least the straight chord and at most a bit above the arc */
        dk_index src = 0;
        CHECK(dk_geodesic_dijkstra(m, &src, 1, d, &err) == DK_OK);
        int above = 1;
        for (dk_index v = 0; v < n; v++) {
            double c = 0;
            for (int k = 0; k < 3; k++) c += m->positions[3 * v + k] * m->positions[k];
            double gc = acos(fmax(-1.0, fmin(1.0, c)));
            double chord = sqrt(fmax(0.0, 2.0 - 2.0 * c));
            above &= d[v] >= chord * (1 - 1e-9) - 1e-12 && d[v] <= 1.3 * gc + 1e-12;
        }
        CHECK(above);
        /* errors */
        dk_index bad = n;
        CHECK(dk_geodesic_dijkstra(m, &bad, 1, d, &err) == DK_ERR_INDEX);
        CHECK(strstr(err.message, "Dijkstra") != NULL);
        CHECK(dk_hop_distance(m, &bad, 1, hops, &err) == DK_ERR_INDEX);
        CHECK(dk_geodesic_dijkstra(m, NULL, 2, d, &err) == DK_ERR_INVALID_ARGUMENT);
        CHECK(dk_geodesic_dijkstra(m, &src, 1, NULL, &err) == DK_ERR_INVALID_ARGUMENT);
        /* no sources: everything unreachable */
        CHECK(dk_geodesic_dijkstra(m, NULL, 0, d, &err) == DK_OK);
        CHECK(isinf(d[0]) && isinf(d[n - 1]));
    }
    free(d);
    free(ref);
    free(hops);
    dk_mesh_free(m);

    /* unreachable component */
    m = two_component_mesh();
    CHECK(m != NULL);
    if (m) {
        n = m->n_vertices;
        double *dd = malloc((size_t)n * sizeof *dd);
        dk_index *hh = malloc((size_t)n * sizeof *hh);
        if (dd && hh) {
            dk_index src = 3;
            CHECK(dk_geodesic_dijkstra(m, &src, 1, dd, &err) == DK_OK);
            CHECK(dk_hop_distance(m, &src, 1, hh, &err) == DK_OK);
            int ok = 1;
            for (dk_index v = 0; v < n; v++) {
                int second = v >= n / 2;
                ok &= second ? (isinf(dd[v]) && hh[v] == -1) : (isfinite(dd[v]) && hh[v] >= 0);
            }
            CHECK(ok);
        }
        free(dd);
        free(hh);
        dk_mesh_free(m);
    }
}

/* Mean relative error of `d` against `ref` over vertices with ref in [lo, hi]. */
static double mean_rel_error(const double *d, const double *ref, dk_index n, double lo, double hi,
                             const unsigned char *skip, int *count)
{
    double s = 0;
    int c = 0;
    for (dk_index v = 0; v < n; v++) {
        if (ref[v] < lo || ref[v] > hi || (skip && skip[v])) continue;
        s += fabs(d[v] - ref[v]) / ref[v];
        c++;
    }
    *count = c;
    return c ? s / c : INFINITY;
}

static void test_heat_flat_grid(void)
{
    dk_test_mesh g;
    if (dk_test_grid(40, 2.0, 0.25, &g) != 0) {
        CHECK(0);
        return;
    }
    dk_mesh *m = dk_test_mesh_build(&g);
    dk_test_mesh_free(&g);
    if (!m) {
        CHECK(0);
        return;
    }
    dk_index n = m->n_vertices;
    dk_heat_geodesic *heat = NULL;
    dk_error err = {0};
    double *d = malloc((size_t)n * sizeof *d), *ref = malloc((size_t)n * sizeof *ref);
    CHECK(dk_heat_create(m, 0.0, &heat, &err) == DK_OK);
    if (heat && d && ref) {
        int f0 = dk_heat_factorization_count(heat);
        CHECK(f0 == 3); /* Neumann heat, Dirichlet heat, Poisson */
        /* centre source (vertex (20, 20)) */
        dk_index src = 20 * 41 + 20;
        CHECK(dk_heat_distance(heat, &src, 1, d, &err) == DK_OK);
        const double *c = m->positions + 3 * src;
        for (dk_index v = 0; v < n; v++) {
            double dx = m->positions[3 * v] - c[0], dy = m->positions[3 * v + 1] - c[1];
            ref[v] = sqrt(dx * dx + dy * dy);
        }
        int cnt;
        double e = mean_rel_error(d, ref, n, 0.2, 0.8, m->is_boundary_vertex, &cnt);
        printf("heat, flat irregular grid, centre source: mean rel error %.4f over %d vertices\n",
               e, cnt);
        CHECK(cnt > 500);
        CHECK_MSG(e < 0.03, "mean relative error %g", e);
        CHECK(d[src] == 0.0);
        int finite = 1;
        for (dk_index v = 0; v < n; v++) finite &= isfinite(d[v]);
        CHECK(finite);

        /* second source set: a corner (on the boundary) and another interior vertex */
        dk_index src2[2] = {0, 30 * 41 + 33};
        CHECK(dk_heat_distance(heat, src2, 2, d, &err) == DK_OK);
        for (dk_index v = 0; v < n; v++) {
            double best = INFINITY;
            for (int s = 0; s < 2; s++) {
                const double *q = m->positions + 3 * src2[s];
                double dx = m->positions[3 * v] - q[0], dy = m->positions[3 * v + 1] - q[1];
                best = fmin(best, sqrt(dx * dx + dy * dy));
            }
            ref[v] = best;
        }
        e = mean_rel_error(d, ref, n, 0.2, 1.5, NULL, &cnt);
        printf("heat, two sources incl. a boundary corner: mean rel error %.4f over %d vertices\n",
               e, cnt);
        CHECK_MSG(e < 0.05, "mean relative error %g", e);
        CHECK(fmin(d[src2[0]], d[src2[1]]) == 0.0);
        CHECK(dk_heat_factorization_count(heat) == f0); /* only back-substitutions */
        /* errors */
        dk_index bad = -1;
        CHECK(dk_heat_distance(heat, &bad, 1, d, &err) == DK_ERR_INDEX);
        CHECK(dk_heat_distance(heat, NULL, 1, d, &err) == DK_ERR_INVALID_ARGUMENT);
    } else {
        CHECK_MSG(0, "%s", err.message);
    }
    free(d);
    free(ref);
    dk_heat_free(heat);
    dk_mesh_free(m);
    CHECK(dk_heat_create(NULL, 1.0, &heat, &err) == DK_ERR_INVALID_ARGUMENT);
    dk_heat_free(NULL);
}

static void test_heat_sphere(void)
{
    dk_test_mesh g;
    if (dk_test_icosphere(4, 1.0, &g) != 0) {
        CHECK(0);
        return;
    }
    dk_mesh *m = dk_test_mesh_build(&g);
    dk_test_mesh_free(&g);
    if (!m) {
        CHECK(0);
        return;
    }
    dk_index n = m->n_vertices;
    dk_heat_geodesic *heat = NULL;
    dk_error err = {0};
    double *d = malloc((size_t)n * sizeof *d), *ref = malloc((size_t)n * sizeof *ref);
    CHECK(dk_heat_create(m, 1.0, &heat, &err) == DK_OK);
    if (heat && d && ref) {
        CHECK(dk_heat_factorization_count(heat) == 2); /* closed: no Dirichlet system */
        const dk_index sources[2] = {0, 1000};
        for (int s = 0; s < 2; s++) {
            CHECK(dk_heat_distance(heat, sources + s, 1, d, &err) == DK_OK);
            const double *c = m->positions + 3 * sources[s];
            for (dk_index v = 0; v < n; v++) {
                const double *p = m->positions + 3 * v;
                double dot = p[0] * c[0] + p[1] * c[1] + p[2] * c[2];
                ref[v] = acos(fmax(-1.0, fmin(1.0, dot)));
            }
            int cnt;
            double e = mean_rel_error(d, ref, n, 0.2, 2.8, NULL, &cnt);
            printf("heat, icosphere (%d vertices), source %d: mean rel error %.4f over %d\n",
                   (int)n, (int)sources[s], e, cnt);
            CHECK(cnt > n / 2);
            CHECK_MSG(e < 0.03, "mean relative error %g", e);
        }
        CHECK(dk_heat_factorization_count(heat) == 2);
    } else {
        CHECK_MSG(0, "%s", err.message);
    }
    free(d);
    free(ref);
    dk_heat_free(heat);
    dk_mesh_free(m);
}

static void test_heat_components(void)
{
    dk_mesh *m = two_component_mesh();
    CHECK(m != NULL);
    if (!m) return;
    dk_index n = m->n_vertices, half = n / 2;
    dk_heat_geodesic *heat = NULL;
    dk_error err = {0};
    double *d = malloc((size_t)n * sizeof *d);
    CHECK(dk_heat_create(m, 0.0, &heat, &err) == DK_OK);
    if (heat && d) {
        dk_index src = 24; /* interior vertex (3, 3) of the first grid */
        CHECK(dk_heat_distance(heat, &src, 1, d, &err) == DK_OK);
        int ok = 1;
        for (dk_index v = 0; v < n; v++) ok &= (v < half) ? isfinite(d[v]) : isinf(d[v]);
        CHECK(ok);
        CHECK(d[src] == 0.0);
        /* sources in both: each component shifted to 0 at its own source, and the two
         * components give the same distances (same geometry, same relative source) */
        double *d1 = malloc((size_t)n * sizeof *d1);
        dk_index both[2] = {24, 24 + half};
        if (d1 && dk_heat_distance(heat, both, 2, d1, &err) == DK_OK) {
            CHECK(d1[24] == 0.0 && d1[24 + half] == 0.0);
            double worst = 0;
            for (dk_index v = 0; v < half; v++) {
                worst = fmax(worst, fabs(d1[v] - d1[v + half]));
                worst = fmax(worst, fabs(d1[v] - d[v]));
            }
            CHECK_MSG(worst < 1e-9, "components differ by %g", worst);
        } else {
            CHECK(0);
        }
        free(d1);
    } else {
        CHECK_MSG(0, "%s", err.message);
    }
    free(d);
    dk_heat_free(heat);
    dk_mesh_free(m);
}

static void test_heat_degenerate(void)
{
    /* a grid plus a zero-area sliver hanging off a corner and an isolated vertex */
    dk_test_mesh g;
    if (dk_test_grid(8, 1.0, 0.2, &g) != 0) {
        CHECK(0);
        return;
    }
    dk_index n = g.n_vertices, nf = g.n_faces;
    double *p = malloc((size_t)(n + 2) * 3 * sizeof *p);
    dk_index *f = malloc((size_t)(nf + 1) * 3 * sizeof *f);
    dk_mesh *m = NULL;
    dk_error err = {0};
    if (p && f) {
        memcpy(p, g.positions, (size_t)n * 3 * sizeof *p);
        memcpy(f, g.faces, (size_t)nf * 3 * sizeof *f);
        /* vertex n on the line through corners 0 and 1, beyond 1; triangle (0, 1, n) */
        p[3 * n] = 2 * g.positions[3] - g.positions[0];
        p[3 * n + 1] = 2 * g.positions[4] - g.positions[1];
        p[3 * n + 2] = 0;
        p[3 * n + 3] = 7, p[3 * n + 4] = 7, p[3 * n + 5] = 7;
        f[3 * nf] = 0, f[3 * nf + 1] = 1, f[3 * nf + 2] = n;
        CHECK(dk_mesh_create(p, n + 2, f, nf + 1, &m, &err) == DK_OK);
    }
    free(p);
    free(f);
    dk_test_mesh_free(&g);
    if (!m) return;
    dk_heat_geodesic *heat = NULL;
    double d[200];
    CHECK(m->n_vertices <= 200);
    CHECK(dk_heat_create(m, 0.0, &heat, &err) == DK_OK);
    if (heat) {
        dk_index src = 40;
        CHECK(dk_heat_distance(heat, &src, 1, d, &err) == DK_OK);
        int finite = 1;
        for (dk_index v = 0; v < n + 1; v++) finite &= isfinite(d[v]) && d[v] >= -1e-9;
        CHECK(finite);
        CHECK(isinf(d[n + 1])); /* isolated, no source there */
        /* the sliver vertex: through its neighbour 1 (or 0) plus the edge length */
        double e1 = fabs(m->positions[3 * n] - m->positions[3]) +
                    fabs(m->positions[3 * n + 1] - m->positions[4]);
        CHECK(d[n] <= d[1] + e1 * 1.0000001 && d[n] > d[1]);
        dk_index iso = n + 1;
        CHECK(dk_heat_distance(heat, &iso, 1, d, &err) == DK_OK);
        CHECK(d[iso] == 0.0 && isinf(d[0]));
    } else {
        CHECK_MSG(0, "%s", err.message);
    }
    dk_heat_free(heat);
    dk_mesh_free(m);
}

/* Two grids joined only through a zero-area triangle: one mesh component, but L splits in
 * two blocks. The far grid has no source: it is reached along edges through the sliver. */
static void test_heat_sliver_bridge(void)
{
    dk_test_mesh g;
    if (dk_test_grid(4, 1.0, 0.0, &g) != 0) {
        CHECK(0);
        return;
    }
    dk_index n = g.n_vertices, nf = g.n_faces; /* 25 vertices, corner (4,4) is vertex 24 */
    double *p = malloc((size_t)(2 * n + 1) * 3 * sizeof *p);
    dk_index *f = malloc((size_t)(2 * nf + 1) * 3 * sizeof *f);
    dk_mesh *m = NULL;
    dk_error err = {0};
    if (p && f) {
        for (dk_index v = 0; v < n; v++)
            for (int d = 0; d < 3; d++) {
                p[3 * v + d] = g.positions[3 * v + d];
                p[3 * (n + v) + d] = g.positions[3 * v + d] + 2.0; /* corner 0 at (2,2,2) */
            }
        /* c: midpoint of corner 24 = (1,1,0) and corner n = (2,2,2) */
        p[6 * n] = 1.5, p[6 * n + 1] = 1.5, p[6 * n + 2] = 1.0;
        for (dk_index k = 0; k < 3 * nf; k++) f[k] = g.faces[k], f[3 * nf + k] = g.faces[k] + n;
        f[6 * nf] = 24, f[6 * nf + 1] = 2 * n, f[6 * nf + 2] = n;
        CHECK(dk_mesh_create(p, 2 * n + 1, f, 2 * nf + 1, &m, &err) == DK_OK);
    }
    free(p);
    free(f);
    dk_test_mesh_free(&g);
    if (!m) return;
    dk_heat_geodesic *heat = NULL;
    double d[64], dj[64];
    CHECK(dk_heat_create(m, 0.0, &heat, &err) == DK_OK);
    if (heat) {
        dk_index src = 6;
        CHECK(dk_heat_distance(heat, &src, 1, d, &err) == DK_OK);
        CHECK(dk_geodesic_dijkstra(m, &src, 1, dj, &err) == DK_OK);
        int ok = 1;
        for (dk_index v = 0; v <= 2 * n; v++) ok &= isfinite(d[v]) && d[v] >= -1e-9;
        CHECK(ok);
        /* the far grid and the sliver vertex continue from corner 24 along edges */
        double bridge = sqrt(6.0); /* |corner n - corner 24| = |(1, 1, 2)| */
        CHECK_NEAR(d[n], d[24] + bridge, 1e-12);
        CHECK_NEAR(d[2 * n], d[24] + 0.5 * bridge, 1e-12);
        for (dk_index v = n; v < 2 * n; v++)
            CHECK_NEAR(d[v] - d[24], dj[v] - dj[24], 1e-12); /* edge paths from corner n */
        /* heat part still accurate: first grid vs straight lines from vertex 6 = (0.25,0.25) */
        CHECK(d[src] == 0.0);
    } else {
        CHECK_MSG(0, "%s", err.message);
    }
    dk_heat_free(heat);
    dk_mesh_free(m);
}

static double now(void)
{
    struct timespec t;
    clock_gettime(CLOCK_MONOTONIC, &t);
    return (double)t.tv_sec + 1e-9 * (double)t.tv_nsec;
}

/* Armadillo-sized sphere (40962 vertices): timings, and the accuracy still holds. */
static void test_heat_timing(void)
{
    dk_test_mesh g;
    if (dk_test_icosphere(6, 1.0, &g) != 0) {
        CHECK(0);
        return;
    }
    dk_mesh *m = dk_test_mesh_build(&g);
    dk_test_mesh_free(&g);
    if (!m) {
        CHECK(0);
        return;
    }
    dk_index n = m->n_vertices;
    double *d = malloc((size_t)n * sizeof *d);
    dk_heat_geodesic *heat = NULL;
    dk_error err = {0};
    double t0 = now();
    dk_status st = dk_heat_create(m, 0.0, &heat, &err);
    double t1 = now();
    CHECK_MSG(st == DK_OK, "%s", err.message);
    if (st == DK_OK && d) {
        dk_index src = 7;
        double t2 = now();
        CHECK(dk_heat_distance(heat, &src, 1, d, &err) == DK_OK);
        double t3 = now();
        double sum = 0;
        int cnt = 0;
        const double *c = m->positions + 3 * src;
        for (dk_index v = 0; v < n; v++) {
            const double *p = m->positions + 3 * v;
            double gc = acos(fmax(-1.0, fmin(1.0, p[0] * c[0] + p[1] * c[1] + p[2] * c[2])));
            if (gc < 0.2 || gc > 2.8) continue;
            sum += fabs(d[v] - gc) / gc;
            cnt++;
        }
        double t4 = now();
        CHECK(dk_geodesic_dijkstra(m, &src, 1, d, &err) == DK_OK);
        double t5 = now();
        printf("icosphere %d vertices: heat create %.1f ms, heat distance %.1f ms (mean rel "
               "error %.4f), Dijkstra %.1f ms\n",
               (int)n, (t1 - t0) * 1e3, (t3 - t2) * 1e3, sum / cnt, (t5 - t4) * 1e3);
        CHECK(sum / cnt < 0.03);
    }
    free(d);
    dk_heat_free(heat);
    dk_mesh_free(m);
}

/* The armadillo (when the shared meshes are present): timings, and the heat distance is a
 * plausible geodesic distance: below the edge-graph (Dijkstra) distance, which overestimates
 * the geodesic, and not far below it. */
static void test_heat_armadillo(void)
{
    char path[1024];
    if (!dk_test_shared_mesh_path(DK_SHARED_DIR, "armadillo.obj", path, sizeof path)) return;
    dk_mesh_file file = {0};
    dk_error err = {0};
    if (dk_read_mesh_file(path, &file, &err) != DK_OK) {
        printf("armadillo not readable (%s), skipping\n", err.message);
        return;
    }
    dk_mesh *m = NULL;
    CHECK(dk_mesh_from_polygons(file.positions, file.n_vertices, file.face_sizes,
                                file.n_polygons, file.indices, file.n_indices, &m, &err) == DK_OK);
    dk_mesh_file_free(&file);
    if (!m) return;
    dk_index n = m->n_vertices;
    double *d = malloc((size_t)n * sizeof *d), *dj = malloc((size_t)n * sizeof *dj);
    dk_heat_geodesic *heat = NULL;
    double t0 = now();
    dk_status st = dk_heat_create(m, 0.0, &heat, &err);
    double t1 = now();
    CHECK_MSG(st == DK_OK, "%s", err.message);
    if (st == DK_OK && d && dj) {
        dk_index src = 0;
        double t2 = now();
        CHECK(dk_heat_distance(heat, &src, 1, d, &err) == DK_OK);
        double t3 = now();
        CHECK(dk_geodesic_dijkstra(m, &src, 1, dj, &err) == DK_OK);
        double ratio = 0, maxd = 0;
        int cnt = 0, finite = 1;
        for (dk_index v = 0; v < n; v++) {
            finite &= isfinite(d[v]) == isfinite(dj[v]);
            if (isfinite(dj[v])) maxd = fmax(maxd, dj[v]);
        }
        for (dk_index v = 0; v < n; v++)
            if (isfinite(dj[v]) && dj[v] > 0.1 * maxd) ratio += d[v] / dj[v], cnt++;
        ratio /= cnt;
        printf("armadillo (%d vertices): heat create %.0f ms, distance %.1f ms; mean "
               "heat/Dijkstra %.3f\n", (int)n, (t1 - t0) * 1e3, (t3 - t2) * 1e3, ratio);
        CHECK(finite);
        CHECK(ratio > 0.85 && ratio < 1.0);
    }
    free(d);
    free(dj);
    dk_heat_free(heat);
    dk_mesh_free(m);
}

DK_TEST_MAIN(test_dijkstra_and_hops, test_heat_armadillo, test_heat_timing, test_heat_sliver_bridge, test_heat_flat_grid, test_heat_sphere, test_heat_components,
             test_heat_degenerate)
