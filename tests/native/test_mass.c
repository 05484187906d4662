/* Tests of the lumped mass matrices (dk_mass_matrix): totals equal the surface area (icosphere
 * vs the sum of triangle areas and vs 4 pi r^2), Voronoi = barycentric inside an equilateral
 * lattice, the acute case against an independent circumcentre construction, the obtuse and
 * right-angle rules, degenerate and isolated vertices, errors. */
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "dk_operators.h"
#include "dk_test.h"
#include "dk_test_meshes.h"

static double tri_area(const double *a, const double *b, const double *c)
{
    double u[3], v[3];
    for (int d = 0; d < 3; d++) u[d] = b[d] - a[d], v[d] = c[d] - a[d];
    double x = u[1] * v[2] - u[2] * v[1], y = u[2] * v[0] - u[0] * v[2],
           z = u[0] * v[1] - u[1] * v[0];
    return 0.5 * sqrt(x * x + y * y + z * z);
}

static void test_sphere_totals(void)
{
    const double r = 2.0;
    dk_test_mesh g;
    if (dk_test_icosphere(3, r, &g) != 0) {
        CHECK(0);
        return;
    }
    dk_mesh *m = dk_test_mesh_build(&g);
    if (!m) {
        CHECK(0);
        dk_test_mesh_free(&g);
        return;
    }
    dk_index n = m->n_vertices;
    double *mb = malloc((size_t)n * sizeof *mb), *mv = malloc((size_t)n * sizeof *mv);
    dk_error err = {0};
    if (mb && mv && dk_mass_matrix(m, DK_MASS_BARYCENTRIC, mb, &err) == DK_OK &&
        dk_mass_matrix(m, DK_MASS_VORONOI, mv, &err) == DK_OK) {
        double area = 0, sb = 0, sv = 0;
        for (dk_index f = 0; f < m->n_faces; f++) {
            const dk_index *t = m->faces + 3 * f;
            area += tri_area(m->positions + 3 * t[0], m->positions + 3 * t[1],
                             m->positions + 3 * t[2]);
        }
        int positive = 1;
        for (dk_index v = 0; v < n; v++) {
            sb += mb[v], sv += mv[v];
            positive &= mb[v] > 0 && mv[v] > 0;
        }
        CHECK(positive);
        CHECK_NEAR(sb, area, 1e-12 * area);
        CHECK_NEAR(sv, area, 1e-12 * area);
        double exact = 4 * 3.14159265358979323846 * r * r;
        printf("icosphere level 3: area %.6f, 4 pi r^2 %.6f\n", area, exact);
        CHECK(fabs(area - exact) < 0.02 * exact);
        CHECK(area < exact); /* inscribed polyhedron */
        /* the two kinds differ on this irregular mesh (they would coincide everywhere on a
         * perfectly regular one) */
        double diff = 0;
        for (dk_index v = 0; v < n; v++) diff = fmax(diff, fabs(mb[v] - mv[v]));
        CHECK(diff > 1e-6);
    } else {
        CHECK_MSG(0, "%s", err.message);
    }
    free(mb);
    free(mv);
    dk_mesh_free(m);
    dk_test_mesh_free(&g);
}

static void test_equilateral_lattice(void)
{
    /* rows of 8 vertices, odd rows shifted by 1/2, all triangles equilateral with side 1 */
    enum { W = 8, H = 7 };
    double p[W * H * 3];
    dk_index f[(W - 1) * (H - 1) * 2 * 3];
    const double hgt = sqrt(3.0) / 2;
    for (int j = 0; j < H; j++)
        for (int i = 0; i < W; i++) {
            p[3 * (j * W + i)] = i + ((j & 1) ? 0.5 : 0.0);
            p[3 * (j * W + i) + 1] = j * hgt;
            p[3 * (j * W + i) + 2] = 0;
        }
    int nf = 0;
    for (int j = 0; j + 1 < H; j++)
        for (int i = 0; i + 1 < W; i++) {
            dk_index a = j * W + i, b = a + 1, c = a + W, d = c + 1;
            if (j & 1) { /* row shifted right: triangles a-b-d, a-d-c */
                f[3 * nf] = a, f[3 * nf + 1] = b, f[3 * nf + 2] = d, nf++;
                f[3 * nf] = a, f[3 * nf + 1] = d, f[3 * nf + 2] = c, nf++;
            } else {
                f[3 * nf] = a, f[3 * nf + 1] = b, f[3 * nf + 2] = c, nf++;
                f[3 * nf] = b, f[3 * nf + 1] = d, f[3 * nf + 2] = c, nf++;
            }
        }
    dk_mesh *m = NULL;
    dk_error err = {0};
    CHECK(dk_mesh_create(p, W * H, f, nf, &m, &err) == DK_OK);
    if (!m) return;
    double mb[W * H], mv[W * H];
    CHECK(dk_mass_matrix(m, DK_MASS_BARYCENTRIC, mb, &err) == DK_OK);
    CHECK(dk_mass_matrix(m, DK_MASS_VORONOI, mv, &err) == DK_OK);
    const double tri = sqrt(3.0) / 4;
    int interior = 0, ok = 1;
    for (int v = 0; v < W * H; v++) {
        if (m->is_boundary_vertex[v]) continue;
        interior++;
        if (m->ring_start[v + 1] - m->ring_start[v] != 6) ok = 0;
        if (fabs(mb[v] - 2 * tri) > 1e-14 || fabs(mv[v] - 2 * tri) > 1e-14) ok = 0;
    }
    CHECK(interior == (W - 2) * (H - 2));
    CHECK_MSG(ok, "interior masses are 2 * sqrt(3)/4 for both kinds");
    dk_mesh_free(m);
}

static void test_single_triangles(void)
{
    dk_error err = {0};
    dk_mesh *m = NULL;
    double mass[3];
    /* acute: independent construction with the circumcentre O: the Voronoi part of P is
     * area(P, mid PQ, O) + area(P, O, mid PR). */
    const double a[] = {0, 0, 0, 4, 0, 0, 1.5, 3, 0};
    const dk_index f[] = {0, 1, 2};
    CHECK(dk_mesh_create(a, 3, f, 1, &m, &err) == DK_OK);
    if (m) {
        CHECK(dk_mass_matrix(m, DK_MASS_VORONOI, mass, &err) == DK_OK);
        /* circumcentre of (0,0), (4,0), (1.5,3): x = 2, y from |O-P0| = |O-P2| */
        double ox = 2, oy = (1.5 * 1.5 + 9 - 2 * ox * 1.5) / 6.0;
        double o[3] = {ox, oy, 0};
        for (int k = 0; k < 3; k++) {
            const double *pp = a + 3 * k, *q = a + 3 * ((k + 1) % 3), *r = a + 3 * ((k + 2) % 3);
            double mq[3], mr[3];
            for (int d = 0; d < 3; d++) mq[d] = 0.5 * (pp[d] + q[d]), mr[d] = 0.5 * (pp[d] + r[d]);
            double ref = tri_area(pp, mq, o) + tri_area(pp, o, mr);
            CHECK_NEAR(mass[k], ref, 1e-13);
        }
        CHECK_NEAR(mass[0] + mass[1] + mass[2], 6.0, 1e-13);
        dk_mesh_free(m);
    }
    /* obtuse at vertex 2: area / 2 there, area / 4 at the others */
    const double b[] = {0, 0, 0, 4, 0, 0, 2, 0.5, 0};
    CHECK(dk_mesh_create(b, 3, f, 1, &m, &err) == DK_OK);
    if (m) {
        CHECK(dk_mass_matrix(m, DK_MASS_VORONOI, mass, &err) == DK_OK);
        CHECK_NEAR(mass[2], 0.5, 1e-15);
        CHECK_NEAR(mass[0], 0.25, 1e-15);
        CHECK_NEAR(mass[1], 0.25, 1e-15);
        CHECK(dk_mass_matrix(m, DK_MASS_BARYCENTRIC, mass, &err) == DK_OK);
        CHECK_NEAR(mass[2], 1.0 / 3, 1e-15);
        dk_mesh_free(m);
    }
    /* right angle at 0: not obtuse, Voronoi gives 1/4, 1/8, 1/8 */
    const double c[] = {0, 0, 0, 1, 0, 0, 0, 1, 0};
    CHECK(dk_mesh_create(c, 3, f, 1, &m, &err) == DK_OK);
    if (m) {
        CHECK(dk_mass_matrix(m, DK_MASS_VORONOI, mass, &err) == DK_OK);
        CHECK_NEAR(mass[0], 0.25, 1e-15);
        CHECK_NEAR(mass[1], 0.125, 1e-15);
        CHECK_NEAR(mass[2], 0.125, 1e-15);
        CHECK(dk_mass_matrix(m, (dk_mass_kind)7, mass, &err) == DK_ERR_INVALID_ARGUMENT);
        CHECK(strstr(err.message, "7") != NULL);
        CHECK(dk_mass_matrix(m, DK_MASS_VORONOI, NULL, &err) == DK_ERR_INVALID_ARGUMENT);
        dk_mesh_free(m);
    }
}

static void test_degenerate(void)
{
    /* vertex 3 only on a zero-area triangle (collinear 0, 1, 3 ... here 1, 2, 3 with 3 on the
     * segment's line), vertex 4 isolated */
    const double p[] = {0, 0, 0, 1, 0, 0, 0, 1, 0, 3, 0, 0, 9, 9, 9};
    const dk_index f[] = {0, 1, 2, 0, 1, 3};
    dk_mesh *m = NULL;
    dk_error err = {0};
    CHECK(dk_mesh_create(p, 5, f, 2, &m, &err) == DK_OK);
    if (!m) return;
    for (int kind = 0; kind < 2; kind++) {
        double mass[5];
        CHECK(dk_mass_matrix(m, (dk_mass_kind)kind, mass, &err) == DK_OK);
        int finite = 1;
        for (int v = 0; v < 5; v++) finite &= isfinite(mass[v]);
        CHECK(finite);
        CHECK(mass[3] == 0.0);
        CHECK(mass[4] == 0.0);
        CHECK_NEAR(mass[0] + mass[1] + mass[2], 0.5, 1e-15);
    }
    dk_mesh_free(m);
}

DK_TEST_MAIN(test_sphere_totals, test_equilateral_lattice, test_single_triangles,
             test_degenerate)
