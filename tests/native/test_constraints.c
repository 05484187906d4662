/* Tests of the shared constraint description (native/methods/constraints.c): roles, free
 * index maps, ROI, overlap refusals naming the vertex and both groups, range and weight
 * checks, and target expansion from positions and 4x4 transforms. Only n_vertices of the
 * mesh is read by dk_constraints_create, so a stack mesh stands in for a real one. */
#include <math.h>
#include <string.h>

#include "dk_constraints.h"
#include "dk_test.h"

static dk_mesh fake_mesh(dk_index n)
{
    dk_mesh m;
    memset(&m, 0, sizeof m);
    m.n_vertices = n;
    return m;
}

static void test_roles_and_maps(void)
{
    dk_mesh m = fake_mesh(10);
    dk_index sizes[2] = {2, 1};
    dk_index hv[3] = {7, 3, 5};
    dk_index fixed[2] = {0, 9};
    dk_constraint_desc d = {2, sizes, hv, NULL, 2, fixed, 0, NULL, NULL, NULL};
    dk_constraints *c = NULL;
    dk_error e = {0};
    CHECK_MSG(dk_constraints_create(&m, &d, &c, &e) == DK_OK, "%s", e.message);
    if (!c)
        return;
    CHECK(c->n_handles == 2 && c->n_handle_vertices == 3);
    CHECK(c->handle_start[0] == 0 && c->handle_start[1] == 2 && c->handle_start[2] == 3);
    CHECK(c->role[7] == 0 && c->role[3] == 0 && c->role[5] == 1);
    CHECK(c->role[0] == DK_VERTEX_FIXED && c->role[9] == DK_VERTEX_FIXED);
    CHECK(c->n_free == 5);
    for (dk_index k = 0; k < c->n_free; k++)
        CHECK(c->free_index[c->free_vertices[k]] == k && c->role[c->free_vertices[k]] ==
              DK_VERTEX_FREE);
    CHECK(c->free_index[7] == -1 && c->free_index[0] == -1);
    for (dk_index k = 0; k < 3; k++)
        CHECK(c->handle_weights[k] == 1.0);
    for (dk_index v = 0; v < 10; v++)
        CHECK(c->stiffness[v] == 1.0);
    dk_constraints_free(c);
}

static void test_roi(void)
{
    dk_mesh m = fake_mesh(8);
    dk_index sizes[1] = {1};
    dk_index hv[1] = {6}; /* outside the ROI: stays a handle */
    dk_index roi[3] = {1, 2, 2};
    double stiff[8] = {1, 2, 3, 4, 5, 6, 7, 8};
    double w[1] = {0.5};
    dk_constraint_desc d = {1, sizes, hv, w, 0, NULL, 3, roi, stiff, NULL};
    dk_constraints *c = NULL;
    dk_error e = {0};
    CHECK_MSG(dk_constraints_create(&m, &d, &c, &e) == DK_OK, "%s", e.message);
    if (!c)
        return;
    CHECK(c->n_free == 2 && c->free_vertices[0] == 1 && c->free_vertices[1] == 2);
    CHECK(c->role[6] == 0 && c->role[0] == DK_VERTEX_FIXED && c->role[7] == DK_VERTEX_FIXED);
    CHECK(c->handle_weights[0] == 0.5 && c->stiffness[4] == 5.0);
    dk_constraints_free(c);
}

static void expect_error(const dk_constraint_desc *d, dk_index n, dk_status want,
                         const char *s1, const char *s2)
{
    dk_mesh m = fake_mesh(n);
    dk_constraints *c = (dk_constraints *)1;
    dk_error e = {0};
    dk_status st = dk_constraints_create(&m, d, &c, &e);
    CHECK_MSG(st == want, "status %d, want %d: %s", (int)st, (int)want, e.message);
    CHECK(c == NULL);
    if (s1)
        CHECK_MSG(strstr(e.message, s1) != NULL, "'%s' not in '%s'", s1, e.message);
    if (s2)
        CHECK_MSG(strstr(e.message, s2) != NULL, "'%s' not in '%s'", s2, e.message);
}

static void test_errors(void)
{
    dk_index sizes[2] = {2, 2};
    dk_index hv[4] = {1, 2, 3, 2};
    dk_constraint_desc d = {2, sizes, hv, NULL, 0, NULL, 0, NULL, NULL, NULL};
    expect_error(&d, 10, DK_ERR_INVALID_ARGUMENT, "vertex 2", "handle 0 and in handle 1");

    dk_index hv_same[4] = {1, 1, 3, 4};
    d.handle_vertices = hv_same;
    expect_error(&d, 10, DK_ERR_INVALID_ARGUMENT, "vertex 1", "twice in handle 0");

    dk_index hv_ok[4] = {1, 2, 3, 4};
    dk_index fixed[2] = {8, 4};
    d.handle_vertices = hv_ok;
    d.n_fixed = 2;
    d.fixed_vertices = fixed;
    expect_error(&d, 10, DK_ERR_INVALID_ARGUMENT, "vertex 4", "handle 1 and in the fixed");

    fixed[1] = 12;
    expect_error(&d, 10, DK_ERR_INDEX, "12", "[0, 10)");
    fixed[1] = 0;

    dk_index hv_bad[4] = {1, 2, 3, 999};
    d.handle_vertices = hv_bad;
    expect_error(&d, 10, DK_ERR_INDEX, "handle 1", "999");
    d.handle_vertices = hv_ok;

    dk_index sizes0[2] = {2, 0};
    d.handle_sizes = sizes0;
    expect_error(&d, 10, DK_ERR_INVALID_ARGUMENT, "handle 1 is empty", NULL);
    d.handle_sizes = sizes;

    double w[4] = {1, 0.5, 0.0, 1};
    d.handle_weights = w;
    expect_error(&d, 10, DK_ERR_INVALID_ARGUMENT, "weight", "vertex 3");
    w[2] = NAN;
    expect_error(&d, 10, DK_ERR_NONFINITE, "weight", NULL);
    d.handle_weights = NULL;

    double stiff[10] = {1, 1, 1, 1, 1, 1, -1, 1, 1, 1};
    d.stiffness = stiff;
    expect_error(&d, 10, DK_ERR_INVALID_ARGUMENT, "stiffness of vertex 6", NULL);
    d.stiffness = NULL;

    dk_index roi[1] = {-1};
    d.n_roi = 1;
    d.roi_vertices = roi;
    expect_error(&d, 10, DK_ERR_INDEX, "ROI", "-1");
    d.n_roi = 0;

    d.n_handles = 0;
    expect_error(&d, 10, DK_ERR_INVALID_ARGUMENT, "at least one handle", NULL);
}

static void test_targets(void)
{
    dk_mesh m = fake_mesh(4);
    double rest[12] = {0, 0, 0, 1, 0, 0, 0, 1, 0, 0, 0, 1};
    dk_index sizes[2] = {2, 1};
    dk_index hv[3] = {1, 3, 2};
    dk_constraint_desc d = {2, sizes, hv, NULL, 0, NULL, 0, NULL, NULL, NULL};
    dk_constraints *c = NULL;
    dk_error e = {0};
    if (dk_constraints_create(&m, &d, &c, &e) != DK_OK) {
        CHECK_MSG(0, "%s", e.message);
        return;
    }
    double pos[9] = {1, 2, 3, 4, 5, 6, 7, 8, 9}, out[9];
    CHECK(dk_constraints_targets(c, rest, pos, 0, out, &e) == DK_OK);
    CHECK(memcmp(pos, out, sizeof out) == 0);
    pos[4] = NAN;
    CHECK(dk_constraints_targets(c, rest, pos, 0, out, &e) == DK_ERR_NONFINITE);
    CHECK_MSG(strstr(e.message, "handle 0 vertex 3") != NULL, "%s", e.message);

    /* Handle 0: rotation by 90 degrees about z plus translation (1, 2, 3); handle 1: scale 2. */
    double t[32] = {0, -1, 0, 1, 1, 0, 0, 2, 0, 0, 1, 3, 0, 0, 0, 1,
                    2, 0, 0, 0, 0, 2, 0, 0, 0, 0, 2, 0, 0, 0, 0, 1};
    CHECK_MSG(dk_constraints_targets(c, rest, t, 1, out, &e) == DK_OK, "%s", e.message);
    double want[9] = {1, 3, 3, 1, 2, 4, 0, 2, 0};
    for (int k = 0; k < 9; k++)
        CHECK_NEAR(out[k], want[k], 1e-15);
    t[31] = 2.0;
    CHECK(dk_constraints_targets(c, rest, t, 1, out, &e) == DK_ERR_INVALID_ARGUMENT);
    CHECK_MSG(strstr(e.message, "handle 1") != NULL, "%s", e.message);
    t[31] = 1.0;
    t[5] = INFINITY;
    CHECK(dk_constraints_targets(c, rest, t, 1, out, &e) == DK_ERR_NONFINITE);
    CHECK_MSG(strstr(e.message, "handle 0") != NULL, "%s", e.message);
    CHECK(dk_constraints_targets(c, rest, t, 2, out, &e) == DK_ERR_INVALID_ARGUMENT);

    /* Issue 18, class 8: a refused request writes nothing (the method's current targets
     * live in `out`); class 10: targets beyond DK_COORD_MAX are refused, naming them. */
    double keep[9];
    CHECK(dk_constraints_targets(c, rest, pos, 0, out, &e) == DK_ERR_NONFINITE); /* pos[4] NaN */
    pos[4] = 5;
    CHECK(dk_constraints_targets(c, rest, pos, 0, out, &e) == DK_OK);
    memcpy(keep, out, sizeof keep);
    double bad[9] = {-1, -2, -3, -4, -5, -6, -7, -8, NAN};
    CHECK(dk_constraints_targets(c, rest, bad, 0, out, &e) == DK_ERR_NONFINITE);
    CHECK(memcmp(keep, out, sizeof keep) == 0);
    bad[8] = 1e300;
    CHECK(dk_constraints_targets(c, rest, bad, 0, out, &e) == DK_ERR_NONFINITE);
    CHECK_MSG(strstr(e.message, "beyond") != NULL, "%s", e.message);
    CHECK(memcmp(keep, out, sizeof keep) == 0);
    dk_constraints_free(c);
    dk_constraints_free(NULL);
}

DK_TEST_MAIN(test_roles_and_maps, test_roi, test_errors, test_targets)
