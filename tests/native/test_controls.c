/* dk_control_check, dk_control_taken and dk_control_target_count (dk_controls.h): every kind
 * accepted when well formed, and each malformed field refused with a message naming it. */
#include <math.h>
#include <string.h>

#include "dk_controls.h"
#include "dk_test.h"

#define NV 4 /* vertices of the mesh the controls are checked against */

static const double unit_box[16] = {1, 0, 0, 0, 0, 1, 0, 0, 0, 0, 1, 0, 0, 0, 0, 1};
static const double tetra[12] = {0, 0, 0, 1, 0, 0, 0, 1, 0, 0, 0, 1};
static const dk_index tetra_faces[12] = {0, 2, 1, 0, 1, 3, 0, 3, 2, 1, 2, 3};

/* Checks that `c` is refused with `status` and a message containing `word`. */
static void refused(const dk_control_desc *c, dk_status status, const char *word)
{
    dk_error e = {0};
    const dk_status st = dk_control_check(c, NV, &e);
    CHECK_MSG(st == status && strstr(e.message, word), "status %d (want %d), '%s' (want '%s')",
              (int)st, (int)status, e.message, word);
}

static void accepted(const dk_control_desc *c)
{
    dk_error e = {0};
    CHECK_MSG(dk_control_check(c, NV, &e) == DK_OK, "%s refused: %s",
              dk_control_kind_name(c->kind), e.message);
}

static void test_points_and_cage(void)
{
    dk_control_desc p = {.kind = DK_CONTROL_POINTS, .n_controls = 4, .rest = tetra};
    accepted(&p);
    CHECK(dk_control_target_count(&p) == 12);
    double bad[12];
    memcpy(bad, tetra, sizeof bad);
    bad[7] = NAN;
    p.rest = bad;
    refused(&p, DK_ERR_NONFINITE, "rest[7]");
    bad[7] = 1e80;
    refused(&p, DK_ERR_INVALID_ARGUMENT, "rest[7]");
    p.rest = NULL;
    refused(&p, DK_ERR_INVALID_ARGUMENT, "needs rest");
    p.rest = tetra;
    p.n_controls = 0;
    refused(&p, DK_ERR_INVALID_ARGUMENT, "n_controls");
    p.n_controls = 4;
    p.n_triangles = 4;
    p.triangles = tetra_faces;
    refused(&p, DK_ERR_INVALID_ARGUMENT, "only a cage");

    dk_control_desc c = {.kind = DK_CONTROL_CAGE, .n_controls = 4, .rest = tetra,
                         .n_triangles = 4, .triangles = tetra_faces};
    accepted(&c);
    CHECK(dk_control_target_count(&c) == 12);
    dk_index faces[12];
    memcpy(faces, tetra_faces, sizeof faces);
    faces[5] = 4;
    c.triangles = faces;
    refused(&c, DK_ERR_INDEX, "cage triangle 1");
    faces[5] = 1;
    refused(&c, DK_ERR_INVALID_ARGUMENT, "repeats a corner");
    c.triangles = NULL;
    refused(&c, DK_ERR_INVALID_ARGUMENT, "needs triangles");
}

static void test_lattice(void)
{
    dk_control_desc l = {.kind = DK_CONTROL_LATTICE, .n_controls = 12, .rest = unit_box,
                         .resolution = {2, 3, 2}};
    accepted(&l);
    CHECK(dk_control_target_count(&l) == 36);
    l.n_controls = 8;
    refused(&l, DK_ERR_INVALID_ARGUMENT, "has 12 points, not 8");
    l.n_controls = 12;
    l.resolution[1] = 1;
    refused(&l, DK_ERR_INVALID_ARGUMENT, "at least 2 points");
    l.resolution[1] = 3;
    double flat[16];
    memcpy(flat, unit_box, sizeof flat);
    flat[10] = 0.0; /* the box squashed to a plane */
    l.rest = flat;
    refused(&l, DK_ERR_INVALID_ARGUMENT, "not invertible");
    flat[10] = 1.0;
    flat[14] = 0.5;
    refused(&l, DK_ERR_INVALID_ARGUMENT, "not affine");
    /* a tiny box is a box: invertibility is relative to its size */
    double tiny[16];
    memcpy(tiny, unit_box, sizeof tiny);
    tiny[0] = tiny[5] = tiny[10] = 1e-9;
    l.rest = tiny;
    accepted(&l);
}

static void test_bones_and_poses(void)
{
    double frames[32];
    memcpy(frames, unit_box, sizeof unit_box);
    memcpy(frames + 16, unit_box, sizeof unit_box);
    frames[16 + 3] = 1.0; /* the second bone one unit along x */
    double w[2 * NV] = {1, 0, 0.5, 0.5, 0.25, 0.75, 0, 1};
    dk_control_desc b = {.kind = DK_CONTROL_BONES, .n_controls = 2, .rest = frames,
                         .weights = w};
    accepted(&b);
    CHECK(dk_control_target_count(&b) == 32);
    w[3] = 0.6;
    refused(&b, DK_ERR_INVALID_ARGUMENT, "vertex 1's bone weights sum to");
    w[3] = 0.5;
    w[4] = -0.25;
    w[5] = 1.25;
    refused(&b, DK_ERR_INVALID_ARGUMENT, "negative");
    w[4] = 0.25;
    w[5] = 0.75;
    b.weights = NULL;
    refused(&b, DK_ERR_INVALID_ARGUMENT, "need weights");
    b.weights = w;
    frames[16 + 15] = 2.0;
    refused(&b, DK_ERR_INVALID_ARGUMENT, "bone frame 1");

    double poses[2 * NV * 3] = {0};
    poses[13] = 1.0;
    dk_control_desc s = {.kind = DK_CONTROL_POSES, .n_controls = 2, .rest = poses};
    accepted(&s);
    CHECK(dk_control_target_count(&s) == 2);
    s.weights = w;
    refused(&s, DK_ERR_INVALID_ARGUMENT, "only bones");
}

static void test_kinds_and_taken(void)
{
    dk_control_desc g = {.kind = DK_CONTROL_VERTEX_GROUPS, .n_controls = 1, .rest = tetra};
    refused(&g, DK_ERR_INVALID_ARGUMENT, "not a control");
    g.kind = (dk_control_kind)7;
    refused(&g, DK_ERR_INVALID_ARGUMENT, "unknown kind 7");
    dk_error e = {0};
    CHECK(dk_control_check(NULL, NV, &e) == DK_ERR_INVALID_ARGUMENT);
    CHECK(strcmp(dk_control_kind_name(DK_CONTROL_LATTICE), "a lattice") == 0);
    CHECK(strcmp(dk_control_kind_name((dk_control_kind)3), "unknown") == 0);

    const dk_control_desc l = {.kind = DK_CONTROL_LATTICE, .n_controls = 8, .rest = unit_box,
                               .resolution = {2, 2, 2}};
    CHECK(dk_control_taken(NULL, DK_CONTROL_VERTEX_GROUPS, "X", &e) == DK_OK);
    CHECK(dk_control_taken(&l, DK_CONTROL_VERTEX_GROUPS | DK_CONTROL_LATTICE, "X", &e) == DK_OK);
    CHECK(dk_control_taken(&l, DK_CONTROL_VERTEX_GROUPS | DK_CONTROL_POINTS, "X", &e) ==
          DK_ERR_INVALID_ARGUMENT);
    CHECK_MSG(strcmp(e.message, "X binds to vertex groups or points, not a lattice") == 0, "%s",
              e.message);
    CHECK(dk_control_taken(NULL, DK_CONTROL_CAGE, "Y", &e) == DK_ERR_INVALID_ARGUMENT);
    CHECK_MSG(strcmp(e.message, "Y binds to a cage, not vertex groups") == 0, "%s", e.message);
}

DK_TEST_MAIN(test_points_and_cage, test_lattice, test_bones_and_poses, test_kinds_and_taken)
