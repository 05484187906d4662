/* Lattice FFD (dk_lattice.h): properties that a wrong basis, registration or border rule
 * would break. The mesh is a point set in and around a sheared, rotated box (a lattice is a
 * space deformation: faces play no part):
 *   - points left in place give the input back, bit for bit (every basis, every outside);
 *   - an affine map of the points moves every vertex by it (linear precision), inside and,
 *     with OUTSIDE_EXTEND, outside the box;
 *   - translations move every vertex by them (partition of unity);
 *   - the slides' bilinear example; a vertex on a lattice point follows it (linear), on a
 *     corner (every basis);
 *   - Bernstein and B-spline against independent evaluations (de Casteljau on the
 *     control net; the B-spline's extended control polygon and its basis matrix);
 *   - outside: CLAMP is the motion of the box's nearest point, STILL fades to none one cell
 *     beyond; input_positions registers the pose; rebind; refusals change nothing. */
#include <math.h>
#include <stdlib.h>
#include <string.h>

#include "dk_lattice.h"
#include "dk_test.h"

enum { NI = 120, NO = 24, N = NI + NO };

/* The box: unit cube -> scaled, sheared, rotated, moved (row-major 4 x 4). */
static void make_frame(double F[16])
{
    const double a = 0.3, c = cos(a), s = sin(a);
    const double S[9] = {2.0, 0.3, 0.0, 0.0, 1.5, 0.2, 0.0, 0.0, 0.8}; /* scale and shear */
    const double R[9] = {c, -s, 0.0, s, c, 0.0, 0.0, 0.0, 1.0};
    memset(F, 0, 16 * sizeof(double));
    for (int i = 0; i < 3; i++)
        for (int j = 0; j < 3; j++)
            for (int k = 0; k < 3; k++)
                F[4 * i + j] += R[3 * i + k] * S[3 * k + j];
    F[3] = 0.4, F[7] = -1.2, F[11] = 3.0, F[15] = 1.0;
}

static void apply_frame(const double F[16], const double u[3], double *x)
{
    for (int d = 0; d < 3; d++)
        x[d] = F[4 * d] * u[0] + F[4 * d + 1] * u[1] + F[4 * d + 2] * u[2] + F[4 * d + 3];
}

static double rnd(unsigned *state)
{
    *state = *state * 1664525u + 1013904223u;
    return (double)(*state >> 8) / 16777216.0;
}

/* NI points inside the box, NO outside (up to 0.6 of the box beyond a face). */
static dk_mesh *make_points(const double F[16], double *unit_out)
{
    double p[3 * N];
    unsigned st = 7;
    for (int v = 0; v < N; v++) {
        double u[3];
        for (int d = 0; d < 3; d++)
            u[d] = v < NI ? rnd(&st) : -0.6 + 2.2 * rnd(&st);
        if (v >= NI && u[0] >= 0 && u[0] <= 1 && u[1] >= 0 && u[1] <= 1 && u[2] >= 0 &&
            u[2] <= 1)
            u[v % 3] = 1.3; /* make sure it is outside */
        memcpy(unit_out + 3 * v, u, sizeof u);
        apply_frame(F, u, p + 3 * v);
    }
    dk_mesh *m = NULL;
    dk_error e = {0};
    return dk_mesh_create(p, N, NULL, 0, &m, &e) == DK_OK ? m : NULL;
}

typedef struct fixture {
    double F[16];
    double unit[3 * N];
    dk_mesh *mesh;
    dk_control_desc control;
    dk_constraint_desc desc;
} fixture;

static int fixture_make(fixture *f, int l, int m, int n)
{
    memset(f, 0, sizeof *f);
    make_frame(f->F);
    f->mesh = make_points(f->F, f->unit);
    f->control = (dk_control_desc){.kind = DK_CONTROL_LATTICE,
                                   .n_controls = l * m * n,
                                   .rest = f->F,
                                   .resolution = {l, m, n}};
    f->desc.control = &f->control;
    return f->mesh ? 0 : -1;
}

/* The rest lattice points, x fastest. */
static double *rest_points(const fixture *f)
{
    const dk_index *r = f->control.resolution;
    double *P = malloc(3 * sizeof(double) * (size_t)f->control.n_controls);
    for (int k = 0; P && k < r[2]; k++)
        for (int j = 0; j < r[1]; j++)
            for (int i = 0; i < r[0]; i++) {
                const double u[3] = {(double)i / (r[0] - 1), (double)j / (r[1] - 1),
                                     (double)k / (r[2] - 1)};
                apply_frame(f->F, u, P + 3 * (i + r[0] * (j + r[1] * k)));
            }
    return P;
}

static dk_lattice *bind(fixture *f, int interp, int outside)
{
    dk_lattice_options o;
    dk_lattice_default_options(&o);
    o.interpolation = (dk_lattice_interpolation)interp;
    o.outside = (dk_lattice_outside)outside;
    dk_lattice *lt = NULL;
    dk_error e = {0};
    CHECK_MSG(dk_lattice_bind(f->mesh, &f->desc, &o, &lt, &e) == DK_OK, "bind: %s", e.message);
    return lt;
}

static int solve(dk_lattice *lt, const double *P, const double *input, double *x)
{
    dk_solve_request rq = {.targets = P, .input_positions = input};
    dk_error e = {0};
    const dk_status st = dk_lattice_solve(lt, &rq, x, NULL, &e);
    CHECK_MSG(st == DK_OK, "solve: %s", e.message);
    return st == DK_OK;
}

static void test_zero_drag_affine_and_translation(void)
{
    fixture f;
    CHECK(fixture_make(&f, 4, 3, 5) == 0);
    double *R = rest_points(&f), *P = rest_points(&f), x[3 * N];
    const double A[12] = {1.1, 0.2, -0.3, 0.5, -0.1, 0.9, 0.25, -2.0, 0.3, 0.1, 1.2, 0.7};
    for (int interp = 0; interp <= 2; interp++)
        for (int outside = 0; outside <= 2; outside++) {
            dk_lattice *lt = bind(&f, interp, outside);
            if (!lt)
                continue;
            CHECK(solve(lt, R, NULL, x) &&
                  memcmp(x, f.mesh->positions, sizeof x) == 0); /* bit for bit */
            for (int k = 0; k < f.control.n_controls; k++) /* an affine map of the points */
                for (int d = 0; d < 3; d++)
                    P[3 * k + d] = A[4 * d] * R[3 * k] + A[4 * d + 1] * R[3 * k + 1] +
                                   A[4 * d + 2] * R[3 * k + 2] + A[4 * d + 3];
            double worst = 0.0;
            if (solve(lt, P, NULL, x))
                for (int v = 0; v < (outside == DK_LATTICE_OUTSIDE_EXTEND ? N : NI); v++)
                    for (int d = 0; d < 3; d++) {
                        const double *p = f.mesh->positions + 3 * v;
                        const double want = A[4 * d] * p[0] + A[4 * d + 1] * p[1] +
                                            A[4 * d + 2] * p[2] + A[4 * d + 3];
                        worst = fmax(worst, fabs(x[3 * v + d] - want));
                    }
            CHECK_MSG(worst < 1e-10, "interpolation %d outside %d: affine map off by %g",
                      interp, outside, worst);
            for (int k = 0; k < 3 * f.control.n_controls; k++) /* a translation */
                P[k] = R[k] + (k % 3 == 0 ? 0.25 : k % 3 == 1 ? -0.5 : 1.0);
            worst = 0.0;
            if (solve(lt, P, NULL, x))
                for (int v = 0; v < N; v++) {
                    const double t[3] = {0.25, -0.5, 1.0};
                    /* STILL: beyond one cell the motion has faded */
                    double fade = 1.0;
                    if (outside == DK_LATTICE_OUTSIDE_STILL) {
                        double beyond = 0.0;
                        for (int d = 0; d < 3; d++) {
                            const double a = f.unit[3 * v + d] *
                                             (double)(f.control.resolution[d] - 1);
                            const double L = (double)(f.control.resolution[d] - 1);
                            beyond = fmax(beyond, a < 0 ? -a : a > L ? a - L : 0.0);
                        }
                        fade = beyond >= 1.0 ? 0.0 : 1.0 - beyond;
                    }
                    for (int d = 0; d < 3; d++)
                        worst = fmax(worst, fabs(x[3 * v + d] - f.mesh->positions[3 * v + d] -
                                                 fade * t[d]));
                }
            CHECK_MSG(worst < 1e-10, "interpolation %d outside %d: translation off by %g",
                      interp, outside, worst);
            dk_lattice_free(lt);
        }
    free(R);
    free(P);
    dk_mesh_free(f.mesh);
}

/* The slides' worked example: u = 0.6, v = 0.7 in a cell, bilinear (here w = 0). */
static void test_the_slides_bilinear_example(void)
{
    const double F[16] = {1, 0, 0, 0, 0, 1, 0, 0, 0, 0, 1, 0, 0, 0, 0, 1};
    const double p[3] = {0.6, 0.7, 0.0};
    dk_mesh *m = NULL;
    dk_error e = {0};
    CHECK(dk_mesh_create(p, 1, NULL, 0, &m, &e) == DK_OK);
    if (!m)
        return;
    dk_control_desc c = {.kind = DK_CONTROL_LATTICE, .n_controls = 8, .rest = F,
                         .resolution = {2, 2, 2}};
    dk_constraint_desc d = {.control = &c};
    dk_lattice_options o;
    dk_lattice_default_options(&o);
    o.interpolation = DK_LATTICE_LINEAR;
    dk_lattice *lt = NULL;
    CHECK(dk_lattice_bind(m, &d, &o, &lt, &e) == DK_OK);
    /* P00, P10, P01, P11 moved (z = 0 face; the z = 1 face weighs 0 at w = 0) */
    double P[24] = {0, 0, 0, 1, 0, 0, 0, 1, 0, 1, 1, 0, 0, 0, 1, 1, 0, 1, 0, 1, 1, 1, 1, 1};
    const double P00[3] = {0.1, -0.2, 0.3}, P10[3] = {1.4, 0.1, 0.0}, P01[3] = {-0.3, 1.2, 0.1},
                 P11[3] = {1.1, 0.9, -0.2};
    memcpy(P + 0, P00, sizeof P00);
    memcpy(P + 3, P10, sizeof P10);
    memcpy(P + 6, P01, sizeof P01);
    memcpy(P + 9, P11, sizeof P11);
    double x[3];
    if (lt && solve(lt, P, NULL, x))
        for (int k = 0; k < 3; k++) {
            /* the slides: P = (1-u)(1-v) P00 + u(1-v) P10 + (1-u) v P01 + u v P11 */
            const double want = 0.4 * 0.3 * P00[k] + 0.6 * 0.3 * P10[k] + 0.4 * 0.7 * P01[k] +
                                0.6 * 0.7 * P11[k];
            CHECK_NEAR(x[k], want, 1e-14);
        }
    dk_lattice_free(lt);
    dk_mesh_free(m);
}

/* de Casteljau along one axis: the Bezier curve of `cnt` 3-vectors at t (independent of
 * the method's Bernstein weights). */
static void casteljau(double *pts, int cnt, double t, double *out)
{
    for (int r = cnt - 1; r > 0; r--)
        for (int i = 0; i < r; i++)
            for (int d = 0; d < 3; d++)
                pts[3 * i + d] = (1 - t) * pts[3 * i + d] + t * pts[3 * (i + 1) + d];
    memcpy(out, pts, 3 * sizeof(double));
}

/* The uniform cubic B-spline of the control polygon extended linearly at both ends, at
 * parameter a in [0, cnt - 1] (its basis matrix, independent of the method's folding). */
static void bspline(const double *pts, int cnt, double a, double *out)
{
    double ext[3 * 40];
    for (int i = 0; i < cnt; i++)
        memcpy(ext + 3 * (i + 1), pts + 3 * i, 3 * sizeof(double));
    for (int d = 0; d < 3; d++) {
        ext[d] = 2 * pts[d] - pts[3 + d];
        ext[3 * (cnt + 1) + d] = 2 * pts[3 * (cnt - 1) + d] - pts[3 * (cnt - 2) + d];
    }
    int i0 = (int)floor(a);
    if (i0 > cnt - 2)
        i0 = cnt - 2;
    const double t = a - i0, t2 = t * t, t3 = t2 * t;
    const double M[4] = {-t3 + 3 * t2 - 3 * t + 1, 3 * t3 - 6 * t2 + 4, -3 * t3 + 3 * t2 + 3 * t + 1,
                         t3};
    for (int d = 0; d < 3; d++) {
        out[d] = 0.0;
        for (int j = 0; j < 4; j++)
            out[d] += M[j] / 6.0 * ext[3 * (i0 + j) + d];
    }
}

/* A smooth bend of every lattice point, then each inside vertex against a tensor-product
 * evaluation by the independent curves above (x, then y, then z). */
static void test_smooth_bases_against_independent_evaluations(void)
{
    fixture f;
    CHECK(fixture_make(&f, 4, 3, 5) == 0);
    const dk_index *r = f.control.resolution;
    double *P = rest_points(&f), x[3 * N];
    for (int k = 0; k < f.control.n_controls; k++) {
        double *p = P + 3 * k;
        p[2] += 0.3 * sin(1.3 * p[0]) + 0.1 * p[1] * p[1];
        p[0] += 0.2 * cos(p[2]);
    }
    for (int interp = DK_LATTICE_BERNSTEIN; interp <= DK_LATTICE_BSPLINE; interp++) {
        dk_lattice *lt = bind(&f, interp, DK_LATTICE_OUTSIDE_EXTEND);
        if (!lt || !solve(lt, P, NULL, x)) {
            dk_lattice_free(lt);
            continue;
        }
        double worst = 0.0;
        for (int v = 0; v < NI; v++) {
            const double *u = f.unit + 3 * v;
            double zs[3 * 8], ys[3 * 8], row[3 * 8], out[3];
            for (int k = 0; k < r[2]; k++) {
                for (int j = 0; j < r[1]; j++) {
                    for (int i = 0; i < r[0]; i++)
                        memcpy(row + 3 * i, P + 3 * (i + r[0] * (j + r[1] * k)),
                               3 * sizeof(double));
                    if (interp == DK_LATTICE_BERNSTEIN)
                        casteljau(row, r[0], u[0], ys + 3 * j);
                    else
                        bspline(row, r[0], u[0] * (r[0] - 1), ys + 3 * j);
                }
                if (interp == DK_LATTICE_BERNSTEIN)
                    casteljau(ys, r[1], u[1], zs + 3 * k);
                else
                    bspline(ys, r[1], u[1] * (r[1] - 1), zs + 3 * k);
            }
            if (interp == DK_LATTICE_BERNSTEIN)
                casteljau(zs, r[2], u[2], out);
            else
                bspline(zs, r[2], u[2] * (r[2] - 1), out);
            for (int d = 0; d < 3; d++)
                worst = fmax(worst, fabs(x[3 * v + d] - out[d]));
        }
        CHECK_MSG(worst < 1e-12, "interpolation %d: %g from the independent evaluation",
                  interp, worst);
        dk_lattice_free(lt);
    }
    free(P);
    dk_mesh_free(f.mesh);
}

/* A vertex on a lattice point follows it (linear: every point; every basis: the corners). */
static void test_vertices_on_points_follow_them(void)
{
    double F[16];
    make_frame(F);
    const int l = 3, m = 4, n = 3, np = l * m * n;
    double pts[3 * 36], u[3];
    for (int k = 0, q = 0; k < n; k++)
        for (int j = 0; j < m; j++)
            for (int i = 0; i < l; i++, q++) {
                u[0] = (double)i / (l - 1), u[1] = (double)j / (m - 1), u[2] = (double)k / (n - 1);
                apply_frame(F, u, pts + 3 * q);
            }
    dk_mesh *mesh = NULL;
    dk_error e = {0};
    CHECK(dk_mesh_create(pts, np, NULL, 0, &mesh, &e) == DK_OK);
    if (!mesh)
        return;
    dk_control_desc c = {.kind = DK_CONTROL_LATTICE, .n_controls = np, .rest = F,
                         .resolution = {l, m, n}};
    dk_constraint_desc d = {.control = &c};
    double P[3 * 36], x[3 * 36];
    unsigned st = 3;
    for (int k = 0; k < 3 * np; k++)
        P[k] = pts[k] + 0.4 * (rnd(&st) - 0.5);
    for (int interp = 0; interp <= 2; interp++) {
        dk_lattice_options o;
        dk_lattice_default_options(&o);
        o.interpolation = (dk_lattice_interpolation)interp;
        dk_lattice *lt = NULL;
        CHECK(dk_lattice_bind(mesh, &d, &o, &lt, &e) == DK_OK);
        if (!lt || !solve(lt, P, NULL, x)) {
            dk_lattice_free(lt);
            continue;
        }
        double worst = 0.0;
        for (int k = 0, q = 0; k < n; k++)
            for (int j = 0; j < m; j++)
                for (int i = 0; i < l; i++, q++) {
                    const int corner = (i == 0 || i == l - 1) && (j == 0 || j == m - 1) &&
                                       (k == 0 || k == n - 1);
                    if (interp == DK_LATTICE_LINEAR || corner)
                        for (int dd = 0; dd < 3; dd++)
                            worst = fmax(worst, fabs(x[3 * q + dd] - P[3 * q + dd]));
                }
        CHECK_MSG(worst < 1e-12, "interpolation %d: a vertex on its point off by %g", interp,
                  worst);
        dk_lattice_free(lt);
    }
    dk_mesh_free(mesh);
}

/* CLAMP: an outside vertex moves as the box's nearest point; the input pose registers
 * anew; rebind; refusals. */
static void test_outside_input_rebind_and_refusals(void)
{
    fixture f;
    CHECK(fixture_make(&f, 3, 3, 3) == 0);
    double *R = rest_points(&f), *P = rest_points(&f), x[3 * N], y[3 * N];
    unsigned st = 11;
    for (int k = 0; k < 3 * f.control.n_controls; k++)
        P[k] += 0.3 * (rnd(&st) - 0.5);
    /* CLAMP: the vertex clamped into the box, deformed, minus the clamp's own offset */
    dk_lattice *lt = bind(&f, DK_LATTICE_LINEAR, DK_LATTICE_OUTSIDE_CLAMP);
    double clamped[3 * N];
    for (int v = 0; v < N; v++) {
        double u[3];
        for (int d = 0; d < 3; d++)
            u[d] = fmin(1.0, fmax(0.0, f.unit[3 * v + d]));
        apply_frame(f.F, u, clamped + 3 * v);
    }
    dk_mesh *cm = NULL;
    dk_error e = {0};
    CHECK(dk_mesh_create(clamped, N, NULL, 0, &cm, &e) == DK_OK);
    fixture g = f;
    g.mesh = cm;
    g.desc.control = &g.control;
    dk_lattice *lc = cm ? bind(&g, DK_LATTICE_LINEAR, DK_LATTICE_OUTSIDE_CLAMP) : NULL;
    if (lt && lc && solve(lt, P, NULL, x) && solve(lc, P, NULL, y)) {
        double worst = 0.0;
        for (int k = 0; k < 3 * N; k++)
            worst = fmax(worst, fabs((x[k] - f.mesh->positions[k]) - (y[k] - clamped[k])));
        CHECK_MSG(worst < 1e-12, "CLAMP: %g from the box's nearest point's motion", worst);
    }
    /* the input pose: the vertices registered where it puts them (a translated input, the
     * lattice translated with it, is the same motion translated) */
    if (lt && lc) {
        double in[3 * N], Pt[3 * 27], z[3 * N];
        for (int k = 0; k < 3 * N; k++)
            in[k] = f.mesh->positions[k] + 0.01 * (k % 7);
        CHECK(solve(lt, R, in, z) && memcmp(z, in, sizeof z) == 0); /* zero drag: the input */
        memcpy(Pt, P, sizeof Pt);
        if (solve(lt, P, in, z) && solve(lt, P, NULL, y)) {
            /* with an input, a different registration from the rest's */
            double differ = 0.0;
            for (int k = 0; k < 3 * N; k++)
                differ = fmax(differ, fabs((z[k] - in[k]) - (y[k] - f.mesh->positions[k])));
            CHECK(differ > 1e-6);
            CHECK(memcmp(y, x, sizeof y) == 0); /* back on the rest: as before, bit for bit */
        }
    }
    /* refusals, nothing changed after them */
    if (lt) {
        double bad[3 * 27];
        memcpy(bad, P, sizeof bad);
        bad[5] = NAN;
        dk_solve_request rq = {.targets = bad};
        CHECK(dk_lattice_solve(lt, &rq, y, NULL, &e) == DK_ERR_NONFINITE);
        rq = (dk_solve_request){.targets = P, .target_kind = DK_TARGETS_TRANSFORMS};
        CHECK(dk_lattice_solve(lt, &rq, y, NULL, &e) == DK_ERR_INVALID_ARGUMENT &&
              strstr(e.message, "not transforms"));
        CHECK(solve(lt, P, NULL, y) && memcmp(x, y, sizeof x) == 0);
        /* rebind: a finer lattice, the same box: the same affine precision */
        dk_control_desc c2 = f.control;
        c2.resolution[0] = 5;
        c2.n_controls = 5 * 3 * 3;
        dk_constraint_desc d2 = {.control = &c2};
        CHECK(dk_lattice_rebind(lt, &d2, &e) == DK_OK);
        dk_method_stats ms;
        dk_lattice_stats(lt, &ms);
        CHECK(ms.n_controls == 45 && ms.n_vertices == N);
        c2.resolution[0] = 1; /* refused: the old lattice stays */
        CHECK(dk_lattice_rebind(lt, &d2, &e) == DK_ERR_INVALID_ARGUMENT);
        dk_lattice_stats(lt, &ms);
        CHECK(ms.n_controls == 45);
    }
    /* binds refused by name */
    dk_lattice *none = NULL;
    dk_constraint_desc nodesc = {0};
    CHECK(dk_lattice_bind(f.mesh, &nodesc, NULL, &none, &e) == DK_ERR_INVALID_ARGUMENT &&
          !none && strstr(e.message, "binds to a lattice"));
    dk_index hv[1] = {0}, sz[1] = {1};
    dk_constraint_desc with_handles = f.desc;
    with_handles.n_handles = 1, with_handles.handle_sizes = sz, with_handles.handle_vertices = hv;
    CHECK(dk_lattice_bind(f.mesh, &with_handles, NULL, &none, &e) == DK_ERR_INVALID_ARGUMENT &&
          !none && strstr(e.message, "takes no handles"));
    dk_control_desc big = f.control;
    big.resolution[0] = 40, big.n_controls = 40 * 9;
    dk_constraint_desc bigd = {.control = &big};
    dk_lattice_options o;
    dk_lattice_default_options(&o);
    o.interpolation = DK_LATTICE_BERNSTEIN;
    CHECK(dk_lattice_bind(f.mesh, &bigd, &o, &none, &e) == DK_ERR_INVALID_ARGUMENT && !none &&
          strstr(e.message, "Bernstein"));
    dk_lattice_free(lt);
    dk_lattice_free(lc);
    dk_mesh_free(cm);
    free(R);
    free(P);
    dk_mesh_free(f.mesh);
}

DK_TEST_MAIN(test_zero_drag_affine_and_translation, test_the_slides_bilinear_example,
             test_smooth_bases_against_independent_evaluations,
             test_vertices_on_points_follow_them, test_outside_input_rebind_and_refusals)
