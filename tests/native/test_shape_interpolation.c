/* Shape interpolation (dk_shape_interpolation.h) through its poses, in C so that the poses'
 * path runs under ASan and the leak checker too (tests/python/test_shape_interpolation.py
 * has the figures): a closed bar twisted by 360 degrees as the pose;
 *   - zero weights give the rest bit for bit, weight 1 the pose (1e-10);
 *   - half way the far cap is turned by half a turn (rotations CONSISTENT) and not at all
 *     (PRINCIPAL: each triangle's rotation alone cannot see a whole turn);
 *   - a rigid motion as the pose is a rigid motion half way (edge lengths kept);
 *   - fixed vertices stay exactly, handles meet their targets, the targets follow the
 *     weights; an input pose with zero weights is returned as is;
 *   - rebind keeps or replaces the poses; a control of another kind, bad weights and bad
 *     poses are refused by name and change nothing. */
#include <math.h>
#include <stdlib.h>
#include <string.h>

#include "dk_shape_interpolation.h"
#include "dk_test.h"
#include "dk_test_meshes.h"

#define PI 3.14159265358979323846

typedef struct bar {
    dk_test_mesh m;
    dk_mesh *mesh;
    dk_index ring, n_rings, cap0, cap1;
} bar;

static void bar_make(bar *b)
{
    memset(b, 0, sizeof *b);
    CHECK(dk_test_closed_bar(24, 3, 0.2, 2.0, &b->m) == 0);
    dk_error e = {0};
    CHECK(dk_mesh_create(b->m.positions, b->m.n_vertices, b->m.faces, b->m.n_faces, &b->mesh,
                         &e) == DK_OK);
    b->ring = 12;
    b->n_rings = 25;
    b->cap0 = b->n_rings * b->ring;
    b->cap1 = b->cap0 + 1;
}

static void bar_free(bar *b)
{
    dk_mesh_free(b->mesh);
    dk_test_mesh_free(&b->m);
}

/* The bar twisted about z by `turn` from z = 0 to z = 2 (n x 3 into out). */
static void twist(const bar *b, double turn, double *out)
{
    for (dk_index v = 0; v < b->m.n_vertices; v++) {
        const double *p = b->m.positions + 3 * v;
        const double a = turn * p[2] / 2.0, c = cos(a), s = sin(a);
        out[3 * v] = c * p[0] - s * p[1];
        out[3 * v + 1] = s * p[0] + c * p[1];
        out[3 * v + 2] = p[2];
    }
}

/* The turn about z of the last ring (mean over its vertices of the angle change). */
static double far_turn(const bar *b, const double *x)
{
    double cs = 0.0, sn = 0.0;
    for (dk_index k = 0; k < b->ring; k++) {
        const dk_index v = (b->n_rings - 1) * b->ring + k;
        const double *p = b->m.positions + 3 * v, *q = x + 3 * v;
        const double d = atan2(q[1], q[0]) - atan2(p[1], p[0]);
        cs += cos(d);
        sn += sin(d);
    }
    return fabs(atan2(sn, cs));
}

static double max_diff(const double *a, const double *b, dk_index n)
{
    double m = 0.0;
    for (dk_index k = 0; k < 3 * n; k++)
        m = fmax(m, fabs(a[k] - b[k]));
    return m;
}

static void test_a_twisted_bar(void)
{
    bar b;
    bar_make(&b);
    const dk_index n = b.m.n_vertices;
    double *pose = malloc(sizeof(double) * 3 * (size_t)n), *x = malloc(sizeof(double) * 3 * (size_t)n);
    if (!pose || !x)
        abort();
    twist(&b, 2.0 * PI, pose);
    const dk_control_desc control = {.kind = DK_CONTROL_POSES, .n_controls = 1, .rest = pose};
    const dk_constraint_desc desc = {.control = &control};
    for (int mode = 0; mode < 2; mode++) {
        dk_shape_interpolation_options o;
        dk_shape_interpolation_default_options(&o);
        o.rotations = mode ? DK_SI_ROTATIONS_PRINCIPAL : DK_SI_ROTATIONS_CONSISTENT;
        dk_shape_interpolation *s = NULL;
        dk_error e = {0};
        CHECK_MSG(dk_shape_interpolation_bind(b.mesh, &desc, &o, &s, &e) == DK_OK, "%s", e.message);
        if (!s)
            continue;
        double w = 0.0;
        dk_solve_request rq = {.targets = &w};
        CHECK(dk_shape_interpolation_solve(s, &rq, x, NULL, &e) == DK_OK);
        CHECK(memcmp(x, b.m.positions, sizeof(double) * 3 * (size_t)n) == 0);
        w = 1.0;
        CHECK(dk_shape_interpolation_solve(s, &rq, x, NULL, &e) == DK_OK);
        CHECK_MSG(max_diff(x, pose, n) < 1e-10, "pose off by %g", max_diff(x, pose, n));
        w = 0.5;
        CHECK(dk_shape_interpolation_solve(s, &rq, x, NULL, &e) == DK_OK);
        const double turn = far_turn(&b, x);
        CHECK_MSG(mode ? turn < 0.3 : fabs(turn - PI) < 0.15, "mode %d: far ring turned %g", mode,
                  turn);
        dk_method_stats st;
        dk_shape_interpolation_stats(s, &st);
        CHECK(st.n_controls == 1 && st.n_handles == 0 && st.n_held == 0);
        dk_shape_interpolation_free(s);
    }
    free(pose);
    free(x);
    bar_free(&b);
}

static void test_rigid_handles_input_rebind_refusals(void)
{
    bar b;
    bar_make(&b);
    const dk_index n = b.m.n_vertices;
    const size_t bytes = sizeof(double) * 3 * (size_t)n;
    double *pose = malloc(bytes), *x = malloc(bytes), *y = malloc(bytes), *in = malloc(bytes);
    if (!pose || !x || !y || !in)
        abort();
    /* a rigid turn by 2 radians about an oblique axis, and a shift */
    const double ax[3] = {0.48, 0.6, 0.64}, a = 2.0, c = cos(a), s = sin(a);
    for (dk_index v = 0; v < n; v++) {
        const double *p = b.m.positions + 3 * v;
        const double d = ax[0] * p[0] + ax[1] * p[1] + ax[2] * p[2];
        const double cr[3] = {ax[1] * p[2] - ax[2] * p[1], ax[2] * p[0] - ax[0] * p[2],
                              ax[0] * p[1] - ax[1] * p[0]};
        for (int k = 0; k < 3; k++)
            pose[3 * v + k] = p[k] * c + cr[k] * s + ax[k] * d * (1.0 - c) + 0.3 * k;
    }
    dk_control_desc control = {.kind = DK_CONTROL_POSES, .n_controls = 1, .rest = pose};
    dk_constraint_desc desc = {.control = &control};
    dk_shape_interpolation *si = NULL;
    dk_error e = {0};
    CHECK(dk_shape_interpolation_bind(b.mesh, &desc, NULL, &si, &e) == DK_OK);
    if (!si)
        abort();
    double w[1 + 3 * 12] = {0.5};
    dk_solve_request rq = {.targets = w};
    CHECK(dk_shape_interpolation_solve(si, &rq, x, NULL, &e) == DK_OK);
    double worst = 0.0; /* the edge lengths of the rest, half way */
    for (dk_index e2 = 0; e2 < b.mesh->n_edges; e2++) {
        const dk_index i = b.mesh->edges[2 * e2], j = b.mesh->edges[2 * e2 + 1];
        double l0 = 0.0, l1 = 0.0;
        for (int k = 0; k < 3; k++) {
            l0 += pow(b.m.positions[3 * i + k] - b.m.positions[3 * j + k], 2);
            l1 += pow(x[3 * i + k] - x[3 * j + k], 2);
        }
        worst = fmax(worst, fabs(sqrt(l1 / l0) - 1.0));
    }
    CHECK_MSG(worst < 1e-10, "a rigid motion half way changes an edge by %g", worst);
    /* fixed: the first ring; a handle: the cap centre at z = 2 */
    dk_index fixed[12], handle[1] = {b.cap1}, size[1] = {1};
    for (int k = 0; k < 12; k++)
        fixed[k] = k;
    desc = (dk_constraint_desc){.n_handles = 1, .handle_sizes = size, .handle_vertices = handle,
                                .n_fixed = 12, .fixed_vertices = fixed};
    CHECK(dk_shape_interpolation_rebind(si, &desc, &e) == DK_OK); /* poses kept */
    CHECK(dk_shape_interpolation_n_poses(si) == 1);
    for (int k = 0; k < 3; k++)
        w[1 + k] = b.m.positions[3 * b.cap1 + k] + (k == 0 ? 0.25 : 0.0);
    CHECK(dk_shape_interpolation_solve(si, &rq, x, NULL, &e) == DK_OK);
    CHECK(memcmp(x, b.m.positions, sizeof(double) * 36) == 0);
    CHECK(memcmp(x + 3 * b.cap1, w + 1, sizeof(double) * 3) == 0);
    /* an input pose with zero weights and the handle where it puts it: the input */
    for (size_t k = 0; k < 3 * (size_t)n; k++)
        in[k] = b.m.positions[k] + 0.01 * sin((double)k);
    w[0] = 0.0;
    memcpy(w + 1, in + 3 * b.cap1, sizeof(double) * 3);
    rq.input_positions = in;
    CHECK(dk_shape_interpolation_solve(si, &rq, y, NULL, &e) == DK_OK);
    CHECK(memcmp(y, in, bytes) == 0);
    rq.input_positions = NULL;
    /* refusals change nothing */
    w[0] = NAN;
    CHECK(dk_shape_interpolation_solve(si, &rq, y, NULL, &e) == DK_ERR_NONFINITE);
    CHECK(strstr(e.message, "pose 0") != NULL);
    const double box[16] = {1, 0, 0, 0, 0, 1, 0, 0, 0, 0, 1, 0, 0, 0, 0, 1};
    const dk_control_desc lattice = {.kind = DK_CONTROL_LATTICE, .n_controls = 8, .rest = box,
                                     .resolution = {2, 2, 2}};
    dk_constraint_desc bad = {.control = &lattice};
    CHECK(dk_shape_interpolation_rebind(si, &bad, &e) == DK_ERR_INVALID_ARGUMENT);
    CHECK(strstr(e.message, "lattice") != NULL);
    pose[7] = INFINITY;
    bad.control = &control;
    CHECK(dk_shape_interpolation_rebind(si, &bad, &e) != DK_OK);
    CHECK(dk_shape_interpolation_n_poses(si) == 1);
    /* two poses now: the rest twice (zero motion whatever the weights) */
    double *two = malloc(2 * bytes);
    if (!two)
        abort();
    memcpy(two, b.m.positions, bytes);
    memcpy(two + 3 * (size_t)n, b.m.positions, bytes);
    control = (dk_control_desc){.kind = DK_CONTROL_POSES, .n_controls = 2, .rest = two};
    dk_constraint_desc again = {.control = &control};
    CHECK(dk_shape_interpolation_rebind(si, &again, &e) == DK_OK);
    CHECK(dk_shape_interpolation_n_poses(si) == 2);
    const double w2[2] = {0.7, -2.0};
    dk_solve_request rq2 = {.targets = w2};
    CHECK(dk_shape_interpolation_solve(si, &rq2, y, NULL, &e) == DK_OK);
    CHECK(max_diff(y, b.m.positions, n) < 1e-10);
    dk_shape_interpolation_free(si);
    free(two);
    free(pose);
    free(x);
    free(y);
    free(in);
    bar_free(&b);
}

DK_TEST_MAIN(test_a_twisted_bar, test_rigid_handles_input_rebind_refusals)
