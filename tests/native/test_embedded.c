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

DK_TEST_MAIN(test_geodesic_influence)
