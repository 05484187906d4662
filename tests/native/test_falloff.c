/* Tests for the attenuated handle displacement (native/methods/falloff.c): the profile
 * against the slide-7 formula, every distance kind against an independent distance, the
 * displacement rule (nearest handle vertex, transforms blended by S, groups summed), fixed /
 * ROI / handle weights, rebind, bad input. */
#include <math.h>
#include <stdlib.h>
#include <string.h>

#include "dk_falloff.h"
#include "dk_test.h"

/* (nx+1) x (ny+1) grid on [0,1] x [0, ny/nx] with alternating diagonals */
static dk_mesh *make_grid(int nx, int ny)
{
    const dk_index nv = (nx + 1) * (ny + 1), nf = 2 * nx * ny;
    double *p = malloc(sizeof(double) * 3 * (size_t)nv);
    dk_index *f = malloc(sizeof(dk_index) * 3 * (size_t)nf), t = 0;
    dk_mesh *m = NULL;
    if (!p || !f)
        abort();
    for (int j = 0; j <= ny; j++)
        for (int i = 0; i <= nx; i++) {
            double *q = p + 3 * (j * (nx + 1) + i);
            q[0] = (double)i / nx;
            q[1] = (double)j / nx;
            q[2] = 0.0;
        }
    for (int j = 0; j < ny; j++)
        for (int i = 0; i < nx; i++) {
            dk_index a = j * (nx + 1) + i, b = a + 1, c = a + nx + 1, d = c + 1;
            dk_index q1[6] = {a, b, d, a, d, c}, q2[6] = {a, b, c, b, d, c};
            memcpy(f + 3 * t, (i + j) % 2 ? q1 : q2, sizeof q1);
            t += 2;
        }
    if (dk_mesh_create(p, nv, f, nf, &m, NULL) != DK_OK)
        m = NULL;
    free(p);
    free(f);
    return m;
}

/* breadth-first hops, independent of the library */
static void bfs(const dk_mesh *m, const dk_index *src, dk_index ns, int *hops)
{
    dk_index *q = malloc(sizeof(dk_index) * (size_t)m->n_vertices), head = 0, tail = 0;
    if (!q)
        abort();
    for (dk_index v = 0; v < m->n_vertices; v++)
        hops[v] = -1;
    for (dk_index k = 0; k < ns; k++) {
        hops[src[k]] = 0;
        q[tail++] = src[k];
    }
    while (head < tail) {
        dk_index v = q[head++];
        for (dk_index k = m->ring_start[v]; k < m->ring_start[v + 1]; k++)
            if (hops[m->ring_index[k]] < 0) {
                hops[m->ring_index[k]] = hops[v] + 1;
                q[tail++] = m->ring_index[k];
            }
    }
    free(q);
}

static double formula(double i, double n, double k)
{
    if (i > n)
        return 0.0;
    return k >= 0 ? 1.0 - pow(i / (n + 1), k + 1) : pow(1.0 - i / (n + 1), 1 - k);
}

static void test_profile(void)
{
    const double ks[5] = {-2.0, -0.5, 0.0, 0.5, 3.0};
    for (int a = 0; a < 5; a++)
        for (int i = 0; i <= 12; i++) {
            double s = dk_falloff_profile(i, 10, ks[a]);
            CHECK_NEAR(s, formula(i, 10, ks[a]), 1e-15);
            CHECK(s >= 0.0 && s <= 1.0);
        }
    CHECK(dk_falloff_profile(0, 5, 0) == 1.0);
    CHECK(dk_falloff_profile(0, 5, -3) == 1.0);
    CHECK_NEAR(dk_falloff_profile(5, 5, 0), 1.0 / 6.0, 1e-15); /* linear: 1 - 5/6 */
    CHECK(dk_falloff_profile(5.5, 5, 0) == 0.0);
    CHECK(dk_falloff_profile(INFINITY, 5, 0) == 0.0);
    /* k > 0 is "rigid" (above linear), k < 0 "elastic" (below) */
    CHECK(dk_falloff_profile(3, 5, 2) > dk_falloff_profile(3, 5, 0));
    CHECK(dk_falloff_profile(3, 5, -2) < dk_falloff_profile(3, 5, 0));
}

/* One handle vertex at the grid centre moved up by 1: every free vertex moves up by S(d)
 * with d its distance in the chosen kind, checked against independent distances. */
static void test_distance_kinds(void)
{
    dk_mesh *m = make_grid(20, 20);
    if (!m) {
        CHECK(0);
        return;
    }
    const dk_index n = m->n_vertices, centre = 10 * 21 + 10;
    int *hops = malloc(sizeof(int) * (size_t)n);
    double *x = malloc(sizeof(double) * 3 * (size_t)n);
    if (!hops || !x)
        abort();
    bfs(m, &centre, 1, hops);
    const double h = m->mean_edge_length;
    const double ks[3] = {-1.5, 0.0, 2.0};
    for (int kind = 0; kind < 4; kind++)
        for (int a = 0; a < 3; a++) {
            dk_falloff_options o;
            dk_falloff *f = NULL;
            dk_index one = 1;
            dk_constraint_desc d = {0};
            dk_error e;
            dk_error_clear(&e);
            d.n_handles = 1;
            d.handle_sizes = &one;
            d.handle_vertices = &centre;
            dk_falloff_default_options(&o);
            o.reach = DK_FALLOFF_REACH_RANGE;
            o.distance = (dk_falloff_distance)kind;
            o.k = ks[a];
            o.range = kind == DK_FALLOFF_HOPS ? 6.0 : 0.3;
            if (dk_falloff_bind(m, &d, &o, &f, &e) != DK_OK) {
                CHECK_MSG(0, "kind %d: %s", kind, e.message);
                continue;
            }
            double t[3] = {m->positions[3 * centre], m->positions[3 * centre + 1], 1.0};
            double esum = 0;
            dk_solve_info info = {.energy = -1};
            CHECK(dk_falloff_solve(f, &(dk_solve_request){.targets = t}, x, &info, &e) == DK_OK);
            const double energy = info.energy;
            int bad_formula = 0, bad_dist = 0, bad_xy = 0;
            for (dk_index v = 0; v < n; v++) {
                double dist, w;
                dk_falloff_vertex_weight(f, 0, v, &dist, &w);
                const double *p = m->positions + 3 * v;
                const double eu = hypot(p[0] - 0.5, p[1] - 0.5);
                if (v == centre) {
                    bad_formula += fabs(x[3 * v + 2] - 1.0) > 1e-15;
                    continue;
                }
                /* the distance itself */
                if (kind == DK_FALLOFF_HOPS)
                    bad_dist += dist != hops[v];
                else if (kind == DK_FALLOFF_EUCLIDEAN)
                    bad_dist += fabs(dist - eu) > 1e-12;
                else if (kind == DK_FALLOFF_DIJKSTRA)
                    bad_dist += dist < eu - 1e-12 || dist > 1.5 * eu + 1e-12;
                else /* heat: close to Euclidean on a flat grid away from the source */
                    bad_dist += eu > 3 * h && fabs(dist - eu) > 0.15 * eu;
                /* the weight and the displacement: S(d / unit) with range / unit */
                const double unit = kind == DK_FALLOFF_HOPS ? 1.0 : h;
                const double s = formula(dist / unit, o.range / unit, o.k);
                bad_formula += fabs(w - s) > 1e-12 || fabs(x[3 * v + 2] - s) > 1e-12;
                bad_xy += x[3 * v] != p[0] || x[3 * v + 1] != p[1];
                esum += x[3 * v + 2] * x[3 * v + 2];
            }
            esum += 1.0;
            CHECK_MSG(bad_dist == 0, "kind %d: %d distances off", kind, bad_dist);
            CHECK_MSG(bad_formula == 0, "kind %d k %g: %d weights off the formula", kind, o.k,
                      bad_formula);
            CHECK(bad_xy == 0);
            CHECK_NEAR(energy, esum, 1e-12 * esum);
            dk_falloff_free(f);
        }
    free(hops);
    free(x);
    dk_mesh_free(m);
}

/* Two groups, fixed vertices, ROI, weights, transforms, nearest-vertex rule. */
static void test_groups_and_constraints(void)
{
    dk_mesh *m = make_grid(20, 4);
    if (!m) {
        CHECK(0);
        return;
    }
    const dk_index n = m->n_vertices, W = 21;
    /* group 0: column 0 (rows 0..4), group 1: column 20; fixed: vertex at column 10 row 0 */
    dk_index hv[10], sizes[2] = {5, 5}, fixed = 10;
    double hw[10];
    for (int j = 0; j < 5; j++) {
        hv[j] = j * W;
        hv[5 + j] = j * W + 20;
        hw[j] = hw[5 + j] = 1.0;
    }
    hw[7] = 0.5;
    dk_constraint_desc d = {0};
    d.n_handles = 2;
    d.handle_sizes = sizes;
    d.handle_vertices = hv;
    d.handle_weights = hw;
    d.n_fixed = 1;
    d.fixed_vertices = &fixed;
    dk_falloff_options o;
    dk_falloff_default_options(&o);
    o.distance = DK_FALLOFF_HOPS;
    o.reach = DK_FALLOFF_REACH_RANGE;
    o.range = 12; /* hops: columns 1..12 from each side, overlap in the middle */
    dk_falloff *f = NULL;
    dk_error e;
    dk_error_clear(&e);
    double *x = malloc(sizeof(double) * 3 * (size_t)n), *y = malloc(sizeof(double) * 3 * (size_t)n);
    if (!x || !y)
        abort();
    CHECK(dk_falloff_bind(m, &d, &o, &f, &e) == DK_OK);
    if (!f)
        goto out;
    /* targets: group 0 up by row index (so the nearest vertex matters), group 1 down by 1 */
    double t[30];
    for (int k = 0; k < 10; k++) {
        memcpy(t + 3 * k, m->positions + 3 * hv[k], sizeof(double) * 3);
        t[3 * k + 2] += k < 5 ? 0.1 * (k + 1) : -1.0;
    }
    CHECK(dk_falloff_solve(f, &(dk_solve_request){.targets = t}, x, NULL, &e) == DK_OK);
    int bad = 0;
    for (int j = 0; j < 5; j++)
        for (int i = 0; i <= 20; i++) {
            const dk_index v = j * W + i;
            double expect;
            if (v == fixed)
                expect = 0.0;
            else if (i == 0)
                expect = 0.1 * (j + 1);
            else if (i == 20)
                expect = (v == hv[7] ? 0.5 : 1.0) * -1.0;
            else {
                /* group 0: several column-0 vertices are i hops away (diagonals); the
                 * tie goes to the straight-line closest one, row j itself. */
                double d0, w0, d1, w1;
                dk_falloff_vertex_weight(f, 0, v, &d0, &w0);
                dk_falloff_vertex_weight(f, 1, v, &d1, &w1);
                CHECK(d0 == i && d1 == 20 - i);
                double g1 = -1.0 * (j * W + 20 == hv[7] ? 0.5 : 1.0);
                expect = w0 * 0.1 * (j + 1) + w1 * g1;
                CHECK_NEAR(w0, formula(i, 12, 0), 1e-15);
            }
            bad += fabs(x[3 * v + 2] - expect) > 1e-12;
        }
    CHECK_MSG(bad == 0, "%d vertices off", bad);
    /* transforms: pure translations give the same result as translated targets */
    {
        double T[32] = {0};
        double t2[30];
        for (int g = 0; g < 2; g++) {
            T[16 * g + 0] = T[16 * g + 5] = T[16 * g + 10] = T[16 * g + 15] = 1.0;
            T[16 * g + 11] = g ? -1.0 : 0.3;
        }
        for (int k = 0; k < 10; k++) {
            memcpy(t2 + 3 * k, m->positions + 3 * hv[k], sizeof(double) * 3);
            t2[3 * k + 2] += k < 5 ? 0.3 : -1.0;
        }
        CHECK(dk_falloff_solve(f,
                               &(dk_solve_request){.targets = T,
                                                   .target_kind = DK_TARGETS_TRANSFORMS},
                               x, NULL, &e) == DK_OK);
        CHECK(dk_falloff_solve(f, &(dk_solve_request){.targets = t2}, y, NULL, &e) == DK_OK);
        double md = 0;
        for (dk_index i = 0; i < 3 * n; i++)
            md = fmax(md, fabs(x[i] - y[i]));
        CHECK(md < 1e-14);
        /* a rotation: p' = p + S (T p - p) at a free vertex */
        memset(T, 0, sizeof T);
        T[1] = -1; T[4] = 1; T[10] = 1; T[15] = 1; /* 90 deg about z */
        T[16] = T[21] = T[26] = T[31] = 1;
        CHECK(dk_falloff_solve(f,
                               &(dk_solve_request){.targets = T,
                                                   .target_kind = DK_TARGETS_TRANSFORMS},
                               x, NULL, &e) == DK_OK);
        const dk_index v = 2 * W + 3;
        double d0, w0;
        dk_falloff_vertex_weight(f, 0, v, &d0, &w0);
        const double *p = m->positions + 3 * v;
        CHECK_NEAR(x[3 * v], p[0] + w0 * (-p[1] - p[0]), 1e-14);
        CHECK_NEAR(x[3 * v + 1], p[1] + w0 * (p[0] - p[1]), 1e-14);
    }
    /* rebind with a ROI that excludes the right half: those vertices stay */
    {
        dk_index *roi = malloc(sizeof(dk_index) * (size_t)n), nr = 0;
        dk_index one = 1, h0 = 2 * W;
        if (!roi)
            abort();
        for (dk_index v = 0; v < n; v++)
            if (v % W <= 10)
                roi[nr++] = v;
        dk_constraint_desc d2 = {0};
        d2.n_handles = 1;
        d2.handle_sizes = &one;
        d2.handle_vertices = &h0;
        d2.n_roi = nr;
        d2.roi_vertices = roi;
        CHECK(dk_falloff_rebind(f, &d2, &e) == DK_OK);
        dk_method_stats ms;
        dk_falloff_stats(f, &ms);
        CHECK(ms.n_handles == 1 && ms.n_handle_vertices == 1);
        double t1[3] = {m->positions[3 * h0], m->positions[3 * h0 + 1], 2.0};
        CHECK(dk_falloff_solve(f, &(dk_solve_request){.targets = t1}, x, NULL, &e) == DK_OK);
        int moved_out = 0, moved_in = 0;
        for (dk_index v = 0; v < n; v++) {
            if (v % W > 10)
                moved_out += x[3 * v + 2] != 0.0;
            else if (v % W <= 10 && v != h0)
                moved_in += x[3 * v + 2] > 0.0;
        }
        CHECK(moved_out == 0);
        CHECK(moved_in > 0);
        free(roi);
    }
out:
    dk_falloff_free(f);
    free(x);
    free(y);
    dk_mesh_free(m);
}

static void test_bad_input(void)
{
    dk_mesh *m = make_grid(4, 4);
    if (!m) {
        CHECK(0);
        return;
    }
    dk_falloff *f = NULL;
    dk_falloff_options o;
    dk_error e;
    dk_error_clear(&e);
    dk_index hv[2] = {0, 1}, sizes[2] = {2, 0};
    dk_constraint_desc d = {0};
    d.n_handles = 2;
    d.handle_sizes = sizes;
    d.handle_vertices = hv;
    CHECK(dk_falloff_bind(m, &d, NULL, &f, &e) != DK_OK && f == NULL); /* empty group */
    d.n_handles = 1;
    hv[1] = 999;
    CHECK(dk_falloff_bind(m, &d, NULL, &f, &e) == DK_ERR_INDEX);
    CHECK(strstr(e.message, "999") != NULL);
    hv[1] = 1;
    d.n_fixed = 1;
    d.fixed_vertices = hv + 1;
    CHECK(dk_falloff_bind(m, &d, NULL, &f, &e) == DK_ERR_INVALID_ARGUMENT);
    CHECK(strstr(e.message, "1") != NULL);
    d.n_fixed = 0;
    dk_falloff_default_options(&o);
    o.range = -1;
    CHECK(dk_falloff_bind(m, &d, &o, &f, &e) == DK_ERR_INVALID_ARGUMENT);
    o.range = 3;
    o.k = NAN;
    CHECK(dk_falloff_bind(m, &d, &o, &f, &e) == DK_ERR_INVALID_ARGUMENT);
    o.k = 0;
    o.distance = (dk_falloff_distance)9;
    CHECK(dk_falloff_bind(m, &d, &o, &f, &e) == DK_ERR_INVALID_ARGUMENT);
    CHECK(dk_falloff_bind(m, &d, NULL, &f, &e) == DK_OK);
    {
        double t[6] = {0, 0, NAN, 0, 0, 0}, *x = malloc(sizeof(double) * 3 * (size_t)m->n_vertices);
        if (!x)
            abort();
        CHECK(dk_falloff_solve(f, &(dk_solve_request){.targets = t}, x, NULL,
                               &e) == DK_ERR_NONFINITE);
        t[2] = 0;
        CHECK(dk_falloff_solve(f, &(dk_solve_request){.targets = t}, x, NULL, &e) == DK_OK);
        CHECK(dk_falloff_solve(f,
                               &(dk_solve_request){.targets = t,
                                                   .target_kind = (dk_target_kind)(2)},
                               x, NULL, &e) == DK_ERR_INVALID_ARGUMENT);
        free(x);
    }
    dk_falloff_free(f);
    dk_mesh_free(m);
}

DK_TEST_MAIN(test_profile, test_distance_kinds, test_groups_and_constraints, test_bad_input)
