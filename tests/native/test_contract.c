/* The method contract (dk_method.h), checked for every method of dk_methods(): a method
 * registered there gets these tests without writing any. Each runs on a bumpy plane with two
 * handles (the left and the right column of vertices) and a fixed row, and on a closed
 * icosphere with one handle cap and a fixed cap, with the method's default options:
 *   - zero drag (the handles' rest positions as targets) returns the rest mesh;
 *   - positions and transforms describing the same targets give the same result (for a
 *     method without DK_METHOD_TRANSFORMS_AS_POSITIONS: translations);
 *   - a rebind with the same constraints equals a fresh bind, and the counters follow;
 *   - two cold solves of one request are bit-identical, whatever was solved in between;
 *   - energy(positions returned) equals the energy the solve reported;
 *   - with nothing fixed, a rigid motion of every handle moves the whole mesh rigidly
 *     (DK_METHOD_RIGID_INVARIANT), or a translation translates it
 *     (DK_METHOD_TRANSLATION_INVARIANT);
 *   - every malformed request is refused with the same status by every method, and a
 *     refused solve leaves the object as it was;
 *   - loose geometry (issue 18, class 12): the bumpy plane with loose vertices and an
 *     unconstrained floating triangle binds with every method, every held vertex stays
 *     exactly at rest, the counters say how many were held (none for a DK_METHOD_DYNAMIC
 *     method, which simulates them: a cold solve leaves them at rest), and a mesh whose every vertex
 *     is constrained gives the constrained motion instead of a refusal;
 *   - a method bound to a control (dk_controls.h: a lattice here) instead of vertex groups:
 *     zero motion returns the rest bit for bit, a translation of the control translates
 *     the mesh, an affine map moves it by that map (DK_METHOD_LINEAR_PRECISION), cold solves
 *     repeat, the energy matches, a refused request changes nothing, an input pose is
 *     returned when the control stays, a rebind equals a fresh bind;
 *   - every method declares the controls it binds to (dk_controls.h), and a bind given a
 *     control of another kind is refused by name, nothing returned;
 *   - every iterative method carries state (dk_method_ops.state_size): after a save, other
 *     solves and a restore -- into the same object or a fresh one -- the next solves
 *     (a resumed one, a warm one, one on a pose) equal bit for bit those of an object that
 *     was never interrupted; states that do not fit are refused and change nothing. */
#include <limits.h>
#include <math.h>
#include <stdlib.h>
#include <string.h>

#include "dk_method.h"
#include "dk_test.h"
#include "dk_test_meshes.h"

typedef struct scene {
    const char *name;
    dk_mesh *mesh;
    dk_index sizes[2], *hv, n_hv, *fixed, n_fixed;
    dk_constraint_desc desc;
    double diag;
} scene;

static void scene_free(scene *s)
{
    dk_mesh_free(s->mesh);
    free(s->hv);
    free(s->fixed);
    memset(s, 0, sizeof *s);
}

/* vertices by a coordinate: handle 0 where coord[axis] <= lo, handle 1 where >= hi (if two
 * handles), fixed where |coord[faxis] - fval| <= ftol and not in a handle */
static int scene_make(scene *s, const char *name, dk_test_mesh *tm, int axis, double lo,
                      double hi, int two_handles, int faxis, double fval, double ftol)
{
    memset(s, 0, sizeof *s);
    s->name = name;
    s->mesh = dk_test_mesh_build(tm);
    const dk_index n = tm->n_vertices;
    s->hv = malloc(sizeof(dk_index) * (size_t)n);
    s->fixed = malloc(sizeof(dk_index) * (size_t)n);
    if (!s->mesh || !s->hv || !s->fixed)
        return -1;
    for (int h = 0; h < 1 + two_handles; h++)
        for (dk_index v = 0; v < n; v++) {
            const double c = tm->positions[3 * v + axis];
            if (h == 0 ? c <= lo : c >= hi) {
                s->hv[s->n_hv++] = v;
                s->sizes[h]++;
            }
        }
    for (dk_index v = 0; v < n; v++) {
        const double c = tm->positions[3 * v + axis];
        const int in_handle = c <= lo || (two_handles && c >= hi);
        if (!in_handle && fabs(tm->positions[3 * v + faxis] - fval) <= ftol)
            s->fixed[s->n_fixed++] = v;
    }
    s->desc.n_handles = 1 + two_handles;
    s->desc.handle_sizes = s->sizes;
    s->desc.handle_vertices = s->hv;
    s->desc.n_fixed = s->n_fixed;
    s->desc.fixed_vertices = s->fixed;
    s->diag = s->mesh->bbox_diagonal;
    return 0;
}

/* The bumpy plane of n x n cells with the two handle columns and the fixed row of
 * test_every_method; 1 on success (else a failed check, nothing to free). */
static int small_plane(scene *s, dk_test_mesh *plane, int n)
{
    const int ok = dk_test_bumpy_plane(n, 0.1, plane) == 0 &&
                   scene_make(s, "bumpy plane", plane, 0, -0.99, 0.99, 1, 1, -1.0, 1e-9) == 0;
    CHECK(ok);
    return ok;
}

/* small_plane's scene; for a DK_METHOD_INTERIOR method (whose interior a plane does not
 * have) the icosphere of `level` with the same roles: a handle at each pole (z <= -0.8,
 * z >= 0.8) and a fixed cap (x >= 0.8 between them). 1 on success. */
static int small_scene(const dk_method_ops *o, scene *s, dk_test_mesh *tm, int n, int level)
{
    if (!(o->flags & DK_METHOD_INTERIOR))
        return small_plane(s, tm, n);
    const int ok = dk_test_icosphere(level, 1.0, tm) == 0 &&
                   scene_make(s, "icosphere", tm, 2, -0.8, 0.8, 1, 0, 1.0, 0.2) == 0;
    CHECK(ok);
    return ok;
}

static double max_diff(const double *a, const double *b, size_t n)
{
    double m = 0;
    for (size_t i = 0; i < n; i++)
        m = fmax(m, fabs(a[i] - b[i]));
    return m;
}

/* a rotation of 0.4 rad about (1, 2, 2)/3 and a translation, row-major 4x4 */
static void some_transform(double T[16], double shift)
{
    const double ax[3] = {1.0 / 3, 2.0 / 3, 2.0 / 3}, a = 0.4, c = cos(a), s = sin(a);
    memset(T, 0, 16 * sizeof(double));
    for (int i = 0; i < 3; i++)
        for (int j = 0; j < 3; j++)
            T[4 * i + j] = (i == j ? c : 0) + (1 - c) * ax[i] * ax[j];
    T[1] -= s * ax[2], T[2] += s * ax[1], T[4] += s * ax[2];
    T[6] -= s * ax[0], T[8] -= s * ax[1], T[9] += s * ax[0];
    T[3] = 0.1 + shift, T[7] = -0.05, T[11] = 0.2, T[15] = 1;
}

static void apply(const double T[16], const double *p, double *out)
{
    for (int d = 0; d < 3; d++)
        out[d] = T[4 * d] * p[0] + T[4 * d + 1] * p[1] + T[4 * d + 2] * p[2] + T[4 * d + 3];
}

/* What a method bound to a control (not to vertex groups) binds with on a scene: the
 * control around the scene's mesh and its points at rest (the targets of no motion). */
typedef struct control_scene {
    dk_control_desc control;
    dk_constraint_desc desc;
    double frame[16];
    double *rest;    /* the targets at rest: n_controls x stride                           */
    int stride;      /* 3 (points, cage, lattice: positions) or 16 (bones: frames)         */
    dk_index tris[36];
    double *weights; /* bones: n_vertices x 2                                             */
} control_scene;

static void control_scene_free(control_scene *c)
{
    free(c->rest);
    free(c->weights);
    memset(c, 0, sizeof *c);
}

/* Moves the targets `in` (n controls of c's stride) by the translation T[3], T[7], T[11]
 * into `out`: positions translated, frames translated. */
static void translate_targets(const control_scene *c, const double *T, const double *in,
                              double *out)
{
    const size_t nt = (size_t)c->stride * (size_t)c->control.n_controls;
    memcpy(out, in, nt * sizeof *out);
    for (dk_index q = 0; q < c->control.n_controls; q++)
        for (int d = 0; d < 3; d++)
            out[(size_t)c->stride * (size_t)q + (c->stride == 16 ? 4 * (size_t)d + 3 : (size_t)d)] +=
                T[4 * d + 3];
}

/* A lattice of 3 x 4 x 3 points, or a box cage (8 vertices, 12 triangles facing out), over
 * the mesh's bounding box grown by a tenth of it (the kinds a method may take, first
 * match). 0 on success; -1 for a kind this test has no scene for: a new kind needs its
 * scene here. */
static int control_scene_make(const dk_method_ops *o, const scene *s, control_scene *c)
{
    memset(c, 0, sizeof *c);
    c->stride = 3;
    if (!(o->controls & (DK_CONTROL_LATTICE | DK_CONTROL_CAGE | DK_CONTROL_BONES)))
        return -1;
    const double *lo = s->mesh->bbox_min, *hi = s->mesh->bbox_max;
    if (o->controls & DK_CONTROL_BONES) {
        /* two bones: one at the origin, one at the box's centre turned about z; each
         * vertex's weights a ramp along x */
        const dk_index n = s->mesh->n_vertices;
        c->stride = 16;
        c->rest = calloc(32, sizeof(double));
        c->weights = malloc(2 * (size_t)n * sizeof(double));
        if (!c->rest || !c->weights)
            return -1;
        c->rest[0] = c->rest[5] = c->rest[10] = c->rest[15] = 1.0;
        double *b = c->rest + 16;
        b[0] = cos(0.3);
        b[1] = -sin(0.3);
        b[4] = sin(0.3);
        b[5] = cos(0.3);
        b[10] = b[15] = 1.0;
        for (int d = 0; d < 3; d++)
            b[4 * d + 3] = 0.5 * (lo[d] + hi[d]);
        for (dk_index v = 0; v < n; v++) {
            const double x = s->mesh->positions[3 * v];
            const double w = hi[0] > lo[0] ? (x - lo[0]) / (hi[0] - lo[0]) : 0.5;
            c->weights[2 * v] = 1.0 - w;
            c->weights[2 * v + 1] = w;
        }
        c->control = (dk_control_desc){.kind = DK_CONTROL_BONES, .n_controls = 2,
                                       .rest = c->rest, .weights = c->weights};
        c->desc.control = &c->control;
        return 0;
    }
    for (int d = 0; d < 3; d++) {
        const double pad = 0.1 * (hi[d] - lo[d]) + 1e-3 * s->diag;
        c->frame[5 * d] = hi[d] - lo[d] + 2 * pad;
        c->frame[4 * d + 3] = lo[d] - pad;
    }
    c->frame[15] = 1.0;
    if (!(o->controls & DK_CONTROL_LATTICE)) { /* the box as a cage, corners x fastest */
        static const dk_index box[36] = {0, 2, 1, 1, 2, 3, 4, 5, 6, 5, 7, 6, 0, 1, 4, 1, 5, 4,
                                         2, 6, 3, 3, 6, 7, 0, 4, 2, 2, 4, 6, 1, 3, 5, 3, 7, 5};
        memcpy(c->tris, box, sizeof box);
        c->rest = malloc(3 * 8 * sizeof(double));
        if (!c->rest)
            return -1;
        for (int q = 0; q < 8; q++)
            for (int d = 0; d < 3; d++)
                c->rest[3 * q + d] = c->frame[5 * d] * (double)((q >> d) & 1) + c->frame[4 * d + 3];
        c->control = (dk_control_desc){.kind = DK_CONTROL_CAGE, .n_controls = 8, .rest = c->rest,
                                       .n_triangles = 12, .triangles = c->tris};
        c->desc.control = &c->control;
        return 0;
    }
    const dk_index res[3] = {3, 4, 3};
    c->control = (dk_control_desc){.kind = DK_CONTROL_LATTICE, .n_controls = 36, .rest = c->frame,
                                   .resolution = {res[0], res[1], res[2]}};
    c->rest = malloc(3 * 36 * sizeof(double));
    if (!c->rest)
        return -1;
    for (int k = 0, q = 0; k < res[2]; k++)
        for (int j = 0; j < res[1]; j++)
            for (int i = 0; i < res[0]; i++, q++) {
                const double u[3] = {(double)i / (res[0] - 1), (double)j / (res[1] - 1),
                                     (double)k / (res[2] - 1)};
                for (int d = 0; d < 3; d++)
                    c->rest[3 * q + d] = c->frame[5 * d] * u[d] + c->frame[4 * d + 3];
            }
    c->desc.control = &c->control;
    return 0;
}

/* The contract for a method bound to a control (see the file's comment). */
static void check_control_method(const dk_method_ops *ops, scene *s)
{
    const dk_index n = s->mesh->n_vertices;
    const size_t N = 3 * (size_t)n;
    control_scene c;
    if (control_scene_make(ops, s, &c) != 0) {
        CHECK_MSG(0, "%s: no contract scene for its controls %#x", ops->name, ops->controls);
        return;
    }
    const size_t nt = (size_t)c.stride * (size_t)c.control.n_controls;
    const dk_target_kind kind = c.stride == 16 ? DK_TARGETS_TRANSFORMS : DK_TARGETS_POSITIONS;
    double *x = malloc(sizeof(double) * N), *y = malloc(sizeof(double) * N);
    double *t = malloc(sizeof(double) * nt);
    void *m = NULL, *fresh = NULL;
    dk_error e = {0};
    dk_solve_info info;
    if (!x || !y || !t || ops->bind(s->mesh, &c.desc, NULL, &m, &e) != DK_OK) {
        CHECK_MSG(0, "%s on %s: bind: %s", ops->name, s->name, e.message);
        goto out;
    }
    dk_method_stats st;
    ops->stats(m, &st);
    CHECK_MSG(st.n_vertices == n && st.n_controls == c.control.n_controls,
              "%s: stats %d vertices, %d controls", ops->name, (int)st.n_vertices,
              (int)st.n_controls);
    /* no motion: the rest, bit for bit */
    dk_solve_request rq = {.targets = c.rest, .target_kind = kind};
    CHECK_MSG(ops->solve(m, &rq, x, &info, &e) == DK_OK && memcmp(x, s->mesh->positions,
                                                                  N * sizeof(double)) == 0,
              "%s on %s: the control at rest moves the mesh (%s)", ops->name, s->name,
              e.message);
    /* a translation translates; an affine map maps (linear precision) */
    double T[16];
    some_transform(T, 0.0);
    for (int affine = 0; affine < 2; affine++) {
        if (affine && !(ops->flags & DK_METHOD_LINEAR_PRECISION))
            continue;
        if (affine)
            for (size_t k = 0; k < nt; k += 3)
                apply(T, c.rest + k, t + k);
        else
            translate_targets(&c, T, c.rest, t);
        rq.targets = t;
        double worst = INFINITY;
        if (ops->solve(m, &rq, x, &info, &e) == DK_OK) {
            worst = 0.0;
            for (dk_index v = 0; v < n; v++) {
                double want[3];
                if (affine)
                    apply(T, s->mesh->positions + 3 * v, want);
                else
                    for (int d = 0; d < 3; d++)
                        want[d] = s->mesh->positions[3 * v + d] + T[4 * d + 3];
                for (int d = 0; d < 3; d++)
                    worst = fmax(worst, fabs(x[3 * v + d] - want[d]));
            }
            double en = NAN;
            CHECK(ops->energy(m, x, &en, &e) == DK_OK &&
                  fabs(en - info.energy) <= 1e-9 * fmax(1.0, fabs(info.energy)));
        }
        CHECK_MSG(worst <= 1e-9 * s->diag, "%s on %s: the control %s moves the mesh %g off",
                  ops->name, s->name, affine ? "mapped affinely" : "translated", worst);
    }
    /* cold solves repeat, whatever came between; a refused request changes nothing */
    for (size_t k = 0; k < nt; k++) /* frames keep their bottom row */
        t[k] = c.rest[k] + (c.stride == 16 && k % 16 >= 12
                                ? 0.0 : 0.05 * sin(3.0 * (double)k) * s->diag);
    rq.targets = t;
    CHECK(ops->solve(m, &rq, x, NULL, &e) == DK_OK);
    double *bad = malloc(sizeof(double) * nt);
    if (bad) {
        memcpy(bad, t, sizeof(double) * nt);
        bad[nt / 2] = NAN;
        dk_solve_request brq = {.targets = bad, .target_kind = kind};
        CHECK(ops->solve(m, &brq, y, NULL, &e) != DK_OK && e.message[0]);
        free(bad);
    }
    CHECK(ops->solve(m, &rq, y, NULL, &e) == DK_OK && memcmp(x, y, N * sizeof(double)) == 0);
    /* an input pose with the control at rest: the input */
    if (ops->flags & DK_METHOD_EDITS_INPUT) {
        for (size_t k = 0; k < N; k++)
            y[k] = s->mesh->positions[k] + 0.02 * cos((double)k) * s->diag;
        dk_solve_request irq = {.targets = c.rest, .target_kind = kind, .input_positions = y};
        double *z = malloc(sizeof(double) * N);
        CHECK(z && ops->solve(m, &irq, z, NULL, &e) == DK_OK && memcmp(z, y, N * sizeof(double)) == 0);
        free(z);
    }
    /* a rebind with the same control equals a fresh bind */
    CHECK(ops->rebind(m, &c.desc, &e) == DK_OK && ops->solve(m, &rq, x, NULL, &e) == DK_OK);
    if (ops->bind(s->mesh, &c.desc, NULL, &fresh, &e) == DK_OK &&
        ops->solve(fresh, &rq, y, NULL, &e) == DK_OK)
        CHECK_MSG(memcmp(x, y, N * sizeof(double)) == 0, "%s: rebind differs from a bind",
                  ops->name);
out:
    if (m)
        ops->free(m);
    if (fresh)
        ops->free(fresh);
    free(x);
    free(y);
    free(t);
    control_scene_free(&c);
}

static void check_method(const dk_method_ops *ops, scene *s)
{
    if (!(ops->controls & DK_CONTROL_VERTEX_GROUPS)) {
        check_control_method(ops, s);
        return;
    }
    const dk_index n = s->mesh->n_vertices;
    const size_t N = 3 * (size_t)n;
    const double tol = 1e-9 * s->diag;
    double *x = malloc(sizeof(double) * N), *y = malloc(sizeof(double) * N);
    double *t = malloc(sizeof(double) * 3 * (size_t)s->n_hv);
    double T[32];
    void *m = NULL, *fresh = NULL;
    dk_error e = {0};
    dk_solve_info info, info2;
    dk_method_stats st;
    if (!x || !y || !t)
        goto out;
    if (ops->bind(s->mesh, &s->desc, NULL, &m, &e) != DK_OK) {
        CHECK_MSG(0, "%s on %s: bind: %s", ops->name, s->name, e.message);
        goto out;
    }
    ops->stats(m, &st);
    CHECK_MSG(st.n_vertices == n && st.n_handles == s->desc.n_handles &&
                  st.n_handle_vertices == s->n_hv,
              "%s on %s: stats %d %d %d", ops->name, s->name, (int)st.n_vertices,
              (int)st.n_handles, (int)st.n_handle_vertices);
    /* a deformation graph's node count: the methods with a graph only (py warnings read it) */
    CHECK_MSG(((ops->flags & DK_METHOD_GRAPH) != 0) == (st.n_graph_nodes > 0),
              "%s on %s: n_graph_nodes %d", ops->name, s->name, (int)st.n_graph_nodes);

    /* zero drag, cold and warm */
    for (dk_index k = 0; k < s->n_hv; k++)
        memcpy(t + 3 * k, s->mesh->positions + 3 * s->hv[k], 3 * sizeof(double));
    for (int start = DK_START_COLD; start <= DK_START_WARM; start++) {
        const dk_solve_request rq = {.targets = t, .start = (dk_start)start};
        CHECK_MSG(ops->solve(m, &rq, x, &info, &e) == DK_OK, "%s: %s", ops->name, e.message);
        const double d = max_diff(x, s->mesh->positions, N);
        CHECK_MSG(d <= tol, "%s on %s: zero drag (start %d) moved the mesh by %g", ops->name,
                  s->name, start, d);
    }

    /* positions and transforms of the same targets: rotated and moved handles, or for a
     * method whose transforms are not positions (Falloff) moved ones */
    const int affine = (ops->flags & DK_METHOD_TRANSFORMS_AS_POSITIONS) != 0;
    for (dk_index h = 0; h < s->desc.n_handles; h++) {
        some_transform(T + 16 * h, 0.05 * (double)h);
        if (!affine)
            for (int i = 0; i < 3; i++)
                for (int j = 0; j < 3; j++)
                    T[16 * h + 4 * i + j] = i == j;
    }
    for (dk_index k = 0, h = 0, end = s->sizes[0]; k < s->n_hv; k++) {
        while (k >= end)
            end += s->sizes[++h];
        apply(T + 16 * h, s->mesh->positions + 3 * s->hv[k], t + 3 * k);
    }
    const dk_solve_request by_pos = {.targets = t};
    const dk_solve_request by_tf = {.targets = T, .target_kind = DK_TARGETS_TRANSFORMS};
    CHECK(ops->solve(m, &by_pos, x, &info, &e) == DK_OK);
    CHECK(ops->solve(m, &by_tf, y, &info2, &e) == DK_OK);
    double d = max_diff(x, y, N);
    CHECK_MSG(d <= 1e-7 * s->diag, "%s on %s: positions vs transforms differ by %g", ops->name,
              s->name, d);
    /* handles of weight 1 are met exactly; penalty handles (embedded deformation) only go
     * most of the way, how far depending on the graph and the weights: on average within a
     * quarter of the move here (the method's own tests hold it to the paper's figures) */
    const int penalty = (ops->flags & DK_METHOD_PENALTY_HANDLES) != 0;
    /* soft regions (eigen deformation): a least-squares fit with a few eigenvectors (a
     * quarter of these small meshes' spectrum at most), so the handles go at least half of
     * the way and the fixed vertices, held like every vertex outside the regions, stay
     * within half of the move */
    const int soft = (ops->flags & DK_METHOD_SOFT_REGIONS) != 0;
    double move = 0.0, herr = 0.0, hsum = 0.0;
    for (dk_index k = 0; k < s->n_hv; k++) {
        move = fmax(move, max_diff(t + 3 * k, s->mesh->positions + 3 * s->hv[k], 3));
        herr = fmax(herr, max_diff(x + 3 * s->hv[k], t + 3 * k, 3));
        hsum += max_diff(x + 3 * s->hv[k], t + 3 * k, 3);
    }
    if (penalty || soft)
        CHECK_MSG(hsum / (double)s->n_hv <= (soft ? 0.5 : 0.25) * move,
                  "%s on %s: handles off by %g on average (move %g)", ops->name, s->name,
                  hsum / (double)s->n_hv, move);
    else
        CHECK_MSG(herr <= tol, "%s on %s: handles off by %g", ops->name, s->name, herr);
    double fsum = 0.0;
    for (dk_index k = 0; k < s->n_fixed; k++) {
        const double fd = max_diff(x + 3 * s->fixed[k], s->mesh->positions + 3 * s->fixed[k], 3);
        fsum += fd;
        if (!soft)
            CHECK(fd <= tol);
    }
    if (soft && s->n_fixed > 0)
        CHECK_MSG(fsum / (double)s->n_fixed <= 0.5 * move,
                  "%s on %s: fixed vertices off by %g on average (move %g)", ops->name, s->name,
                  fsum / (double)s->n_fixed, move);

    /* energy of the returned positions = the reported energy */
    double energy = NAN;
    CHECK(ops->energy(m, x, &energy, &e) == DK_OK);
    CHECK_MSG(fabs(energy - info.energy) <= 1e-9 * fmax(fabs(info.energy), 1e-300),
              "%s on %s: energy %.17g, solve reported %.17g", ops->name, s->name, energy,
              info.energy);

    /* determinism: a cold solve after other solves = the first cold solve, bit for bit */
    CHECK(ops->solve(m, &by_pos, y, &info2, &e) == DK_OK);
    CHECK_MSG(memcmp(x, y, N * sizeof(double)) == 0 && info.iterations == info2.iterations,
              "%s on %s: two cold solves differ", ops->name, s->name);

    /* a given start from the cold result: a method that starts from positions returns it
     * (one step, the same minimum), other iterative ones refuse, direct ones ignore it */
    {
        const dk_solve_request given = {.targets = t, .start = DK_START_GIVEN,
                                        .start_positions = x};
        const dk_status got = ops->solve(m, &given, y, &info2, &e);
        if (ops->flags & DK_METHOD_GIVEN_START) {
            CHECK_MSG(got == DK_OK && (ops->flags & DK_METHOD_ITERATIVE), "%s: %s", ops->name,
                      e.message);
            /* a volume's interior is not in the positions: rebuilt from them, it relaxes
             * in a few more steps (dk_volumetric_arap.h) */
            const int steps = ops->flags & DK_METHOD_INTERIOR ? 5 : 2;
            CHECK_MSG(max_diff(x, y, N) <= 1e-6 * s->diag && info2.iterations <= steps,
                      "%s on %s: a start at its own result moved %g in %d iterations",
                      ops->name, s->name, max_diff(x, y, N), info2.iterations);
        } else if (ops->flags & DK_METHOD_ITERATIVE) {
            CHECK_MSG(got == DK_ERR_INVALID_ARGUMENT, "%s: a given start gave status %d",
                      ops->name, (int)got);
        } else {
            CHECK_MSG(got == DK_OK && memcmp(x, y, N * sizeof(double)) == 0,
                      "%s on %s: a direct method's given start changed the result", ops->name,
                      s->name);
        }
    }

    /* rebind with the same constraints = a fresh bind */
    CHECK_MSG(ops->rebind(m, &s->desc, &e) == DK_OK, "%s: rebind: %s", ops->name, e.message);
    CHECK(ops->bind(s->mesh, &s->desc, NULL, &fresh, &e) == DK_OK);
    if (fresh) {
        CHECK(ops->solve(m, &by_pos, x, &info, &e) == DK_OK);
        CHECK(ops->solve(fresh, &by_pos, y, &info2, &e) == DK_OK);
        d = max_diff(x, y, N);
        CHECK_MSG(d <= 1e-12 * s->diag, "%s on %s: rebind vs fresh bind differ by %g",
                  ops->name, s->name, d);
    }

    /* a rigid motion (or, for a translation-invariant method, a translation) of every
     * constraint, with nothing fixed, moves the whole mesh so */
    if (ops->flags & (DK_METHOD_TRANSLATION_INVARIANT | DK_METHOD_RIGID_INVARIANT)) {
        const int rigid = (ops->flags & DK_METHOD_RIGID_INVARIANT) != 0;
        dk_constraint_desc free_desc = s->desc;
        free_desc.n_fixed = 0;
        void *r = NULL;
        double R[16];
        some_transform(R, 0.0);
        if (!rigid)
            for (int i = 0; i < 3; i++)
                for (int j = 0; j < 3; j++)
                    R[4 * i + j] = i == j;
        for (dk_index h = 0; h < s->desc.n_handles; h++)
            memcpy(T + 16 * h, R, sizeof R);
        if (ops->bind(s->mesh, &free_desc, NULL, &r, &e) != DK_OK) {
            CHECK_MSG(0, "%s on %s: bind without fixed: %s", ops->name, s->name, e.message);
        } else {
            /* a cap well above the default: from a cold start, ARAP's Newton solver needs
             * 536 steps for this rotation of the icosphere (Anderson: 55; see
             * docs/methods/arap.md) */
            const dk_solve_request rq = {.targets = T, .target_kind = DK_TARGETS_TRANSFORMS,
                                         .max_iterations = 2000};
            CHECK(ops->solve(r, &rq, x, &info, &e) == DK_OK);
            for (dk_index v = 0; v < n; v++)
                apply(R, s->mesh->positions + 3 * v, y + 3 * v);
            d = max_diff(x, y, N);
            CHECK_MSG(d <= (penalty ? 1e-4 : rigid ? 1e-6 : 1e-9) * s->diag,
                      "%s on %s: a %s of every constraint is off by %g", ops->name, s->name,
                      rigid ? "rigid motion" : "translation", d);
            ops->free(r);
        }
    }

    /* malformed requests: the same status from every method, and nothing changes */
    const double nan_t[3] = {NAN, 0, 0};
    double *tn = malloc(sizeof(double) * 3 * (size_t)s->n_hv);
    struct {
        const char *what;
        dk_solve_request rq;
        dk_status want;
    } bad[] = {
        {"NULL targets", {.targets = NULL}, DK_ERR_INVALID_ARGUMENT},
        {"unknown target kind", {.targets = t, .target_kind = (dk_target_kind)7},
         DK_ERR_INVALID_ARGUMENT},
        {"unknown start", {.targets = t, .start = (dk_start)9}, DK_ERR_INVALID_ARGUMENT},
        {"negative max_iterations", {.targets = t, .max_iterations = -1},
         DK_ERR_INVALID_ARGUMENT},
        {"skip_energy not 0/1", {.targets = t, .skip_energy = 3}, DK_ERR_INVALID_ARGUMENT},
        {"start_positions without the given start", {.targets = t, .start_positions = x},
         DK_ERR_INVALID_ARGUMENT},
        {"the given start without start_positions", {.targets = t, .start = DK_START_GIVEN},
         DK_ERR_INVALID_ARGUMENT},
        {"NaN target", {.targets = tn}, DK_ERR_NONFINITE},
    };
    if (tn) {
        memcpy(tn, t, sizeof(double) * 3 * (size_t)s->n_hv);
        memcpy(tn + 3 * (s->n_hv - 1), nan_t, sizeof nan_t);
    }
    CHECK(ops->solve(m, &by_pos, x, &info, &e) == DK_OK);
    for (size_t b = 0; tn && b < sizeof bad / sizeof bad[0]; b++) {
        const dk_status got = ops->solve(m, &bad[b].rq, y, &info2, &e);
        CHECK_MSG(got == bad[b].want, "%s: %s gave status %d, want %d (%s)", ops->name,
                  bad[b].what, (int)got, (int)bad[b].want, e.message);
    }
    CHECK(ops->solve(m, NULL, y, &info2, &e) == DK_ERR_INVALID_ARGUMENT);
    CHECK(ops->solve(m, &by_pos, y, &info2, &e) == DK_OK);
    CHECK_MSG(memcmp(x, y, N * sizeof(double)) == 0,
              "%s on %s: a refused request changed the next cold solve", ops->name, s->name);
    free(tn);
out:
    if (m)
        ops->free(m);
    if (fresh)
        ops->free(fresh);
    free(x);
    free(y);
    free(t);
}

static void test_registry(void)
{
    const dk_method_ops *const *all = dk_methods();
    int count = 0;
    for (const dk_method_ops *const *m = all; *m; m++, count++) {
        const dk_method_ops *o = *m;
        CHECK_MSG(o->name && o->bind && o->rebind && o->solve && o->energy && o->stats &&
                      o->free,
                  "method %d has an empty entry", count);
        CHECK(dk_method_find(o->name) == o);
    }
    CHECK(count >= 3);
    CHECK(dk_method_find("no such method") == NULL && dk_method_find(NULL) == NULL);
}

static void test_every_method(void)
{
    dk_test_mesh plane = {0}, sphere = {0};
    scene scenes[2];
    int ok = dk_test_bumpy_plane(16, 0.1, &plane) == 0 && dk_test_icosphere(2, 1.0, &sphere) == 0;
    CHECK(ok);
    if (!ok)
        return;
    /* plane: handles at x <= -0.99 and x >= 0.99, fixed row y = -1 */
    ok = scene_make(&scenes[0], "bumpy plane", &plane, 0, -0.99, 0.99, 1, 1, -1.0, 1e-9) == 0;
    /* sphere: one handle cap z <= -0.8, fixed cap z >= 0.8 (a band around z = 1) */
    ok = ok && scene_make(&scenes[1], "icosphere", &sphere, 2, -0.8, 2.0, 0, 2, 1.0, 0.2) == 0;
    CHECK(ok);
    for (int k = 0; ok && k < 2; k++)
        for (const dk_method_ops *const *m = dk_methods(); *m; m++)
            check_method(*m, &scenes[k]);
    for (int k = 0; k < 2; k++)
        scene_free(&scenes[k]);
    dk_test_mesh_free(&plane);
    dk_test_mesh_free(&sphere);
}

/* The loose-geometry tests' solve: the handles lifted by 0.2 (targets t, rest p) move the
 * handle vertices up by more than `min_move`, and the n_held vertices from n0 on, which
 * nothing constrains, stay exactly at rest. x: the positions' buffer. */
static void solve_beside_held(const dk_method_ops *o, void *obj, const scene *s,
                              const double *p, const double *t, dk_index n0, dk_index n_held,
                              double min_move, double *x)
{
    dk_error e = {0};
    const dk_solve_request rq = {.targets = t};
    const dk_status st = o->solve(obj, &rq, x, NULL, &e);
    CHECK_MSG(st == DK_OK, "%s: %s", o->name, e.message);
    if (st != DK_OK)
        return;
    CHECK_MSG(memcmp(x + 3 * (size_t)n0, p + 3 * (size_t)n0,
                     sizeof(double) * 3 * (size_t)n_held) == 0,
              "%s: a held vertex moved", o->name);
    double moved = 0.0;
    for (dk_index k = 0; k < s->n_hv; k++)
        moved = fmax(moved, x[3 * s->hv[k] + 2] - p[3 * s->hv[k] + 2]);
    CHECK_MSG(moved > min_move, "%s: the handles did not move (%g)", o->name, moved);
}

/* The plane of test_every_method plus three loose vertices and a floating triangle, with
 * the plane's handles and fixed row: nothing constrains the four extra components. */
static void test_loose_geometry(void)
{
    dk_test_mesh plane = {0};
    CHECK(dk_test_bumpy_plane(12, 0.1, &plane) == 0);
    const dk_index n0 = plane.n_vertices, n = n0 + 6, nf = plane.n_faces + 1;
    double *p = malloc(sizeof(double) * 3 * (size_t)n);
    dk_index *f = malloc(sizeof(dk_index) * 3 * (size_t)nf);
    if (!p || !f)
        abort();
    memcpy(p, plane.positions, sizeof(double) * 3 * (size_t)n0);
    const double extra[18] = {0, 0, 3, 0.1, 0, 4, 0.2, 0.1, 5, 0, 0.5, 2, 0.5, 0.5, 2, 0, 0.9, 2.5};
    memcpy(p + 3 * (size_t)n0, extra, sizeof extra);
    memcpy(f, plane.faces, sizeof(dk_index) * 3 * (size_t)plane.n_faces);
    f[3 * plane.n_faces] = n0 + 3, f[3 * plane.n_faces + 1] = n0 + 4;
    f[3 * plane.n_faces + 2] = n0 + 5;
    dk_test_mesh loose = {p, f, n, nf};
    scene s;
    CHECK(scene_make(&s, "plane with loose geometry", &loose, 0, -0.99, 0.99, 1, 1, -1.0,
                     1e-9) == 0);
    double *t = malloc(sizeof(double) * 3 * (size_t)s.n_hv), *x = malloc(sizeof(double) * 3 * (size_t)n);
    if (!t || !x)
        abort();
    for (dk_index k = 0; k < s.n_hv; k++)
        for (int c = 0; c < 3; c++)
            t[3 * k + c] = p[3 * s.hv[k] + c] + (c == 2 ? 0.2 : 0.0);
    for (const dk_method_ops *const *m = dk_methods(); *m; m++) {
        const dk_method_ops *o = *m;
        if (!(o->controls & DK_CONTROL_VERTEX_GROUPS))
            continue; /* a control moves every vertex: nothing is loose */
        void *obj = NULL;
        dk_error e = {0};
        dk_status st = o->bind(s.mesh, &s.desc, NULL, &obj, &e);
        CHECK_MSG(st == DK_OK, "%s: %s", o->name, e.message);
        if (st != DK_OK)
            continue;
        dk_method_stats ms;
        o->stats(obj, &ms);
        /* a dynamic method simulates loose parts (they move by their dynamics, which at
         * rest and without gravity keeps them there): nothing is held */
        const int dynamic = (o->flags & DK_METHOD_DYNAMIC) != 0;
        CHECK_MSG(dynamic ? ms.n_held == 0 && ms.n_held_components == 0 && ms.first_held == -1
                          : ms.n_held == 6 && ms.n_held_components == 4 && ms.first_held == n0,
                  "%s: held %d in %d, first %d", o->name, (int)ms.n_held,
                  (int)ms.n_held_components, (int)ms.first_held);
        solve_beside_held(o, obj, &s, p, t, n0, n - n0, 0.05, x);
        o->free(obj);
    }
    /* every vertex constrained (handles, and fixed everything else): the constrained
     * motion for the methods whose handles are exact */
    dk_index *rest = malloc(sizeof(dk_index) * (size_t)n), nr = 0;
    unsigned char *is_h = calloc((size_t)n, 1);
    if (!rest || !is_h)
        abort();
    for (dk_index k = 0; k < s.n_hv; k++)
        is_h[s.hv[k]] = 1;
    for (dk_index v = 0; v < n; v++)
        if (!is_h[v])
            rest[nr++] = v;
    dk_constraint_desc all = s.desc;
    all.n_fixed = nr;
    all.fixed_vertices = rest;
    for (const dk_method_ops *const *m = dk_methods(); *m; m++) {
        const dk_method_ops *o = *m;
        if (!(o->controls & DK_CONTROL_VERTEX_GROUPS))
            continue; /* no vertex is constrained by a control */
        void *obj = NULL;
        dk_error e = {0};
        dk_status st = o->bind(s.mesh, &all, NULL, &obj, &e);
        CHECK_MSG(st == DK_OK, "%s, every vertex constrained: %s", o->name, e.message);
        if (st != DK_OK)
            continue;
        const dk_solve_request rq = {.targets = t};
        st = o->solve(obj, &rq, x, NULL, &e);
        CHECK_MSG(st == DK_OK, "%s, every vertex constrained: %s", o->name, e.message);
        if (st == DK_OK && !(o->flags & (DK_METHOD_PENALTY_HANDLES | DK_METHOD_SOFT_REGIONS))) {
            double err_h = 0.0, err_f = 0.0;
            for (dk_index k = 0; k < s.n_hv; k++)
                for (int c = 0; c < 3; c++)
                    err_h = fmax(err_h, fabs(x[3 * s.hv[k] + c] - t[3 * k + c]));
            for (dk_index k = 0; k < nr; k++)
                for (int c = 0; c < 3; c++)
                    err_f = fmax(err_f, fabs(x[3 * rest[k] + c] - p[3 * rest[k] + c]));
            CHECK_MSG(err_h <= 1e-12 && err_f <= 1e-12, "%s: handles off by %g, fixed by %g",
                      o->name, err_h, err_f);
        }
        o->free(obj);
    }
    free(rest);
    free(is_h);
    free(t);
    free(x);
    scene_free(&s);
    free(p);
    free(f);
    dk_test_mesh_free(&plane);
}

/* test_loose_geometry with volumes, for the DK_METHOD_INTERIOR methods: small_scene's
 * icosphere and a second, smaller one beside it that nothing constrains: that one is held
 * at rest, the first deforms. */
static void test_loose_volumes(void)
{
    for (const dk_method_ops *const *m = dk_methods(); *m; m++) {
        const dk_method_ops *o = *m;
        if (!(o->flags & DK_METHOD_INTERIOR))
            continue;
        dk_test_mesh a = {0}, b = {0};
        CHECK(dk_test_icosphere(2, 1.0, &a) == 0 && dk_test_icosphere(1, 0.3, &b) == 0);
        const dk_index n0 = a.n_vertices, n = n0 + b.n_vertices, nf = a.n_faces + b.n_faces;
        double *p = malloc(sizeof(double) * 3 * (size_t)n);
        dk_index *f = malloc(sizeof(dk_index) * 3 * (size_t)nf);
        if (!p || !f)
            abort();
        memcpy(p, a.positions, sizeof(double) * 3 * (size_t)n0);
        for (dk_index v = 0; v < b.n_vertices; v++)
            for (int c = 0; c < 3; c++)
                p[3 * (n0 + v) + c] = b.positions[3 * v + c] + (c == 0 ? 3.0 : 0.0);
        memcpy(f, a.faces, sizeof(dk_index) * 3 * (size_t)a.n_faces);
        for (dk_index k = 0; k < 3 * b.n_faces; k++)
            f[3 * a.n_faces + k] = b.faces[k] + n0;
        dk_test_mesh two = {p, f, n, nf};
        scene s;
        /* handles at the first sphere's poles only (x < 2), fixed cap at x = 1 */
        CHECK(scene_make(&s, "two spheres", &two, 2, -0.8, 0.8, 1, 0, 1.0, 0.2) == 0);
        dk_index kept = 0, sizes[2] = {0, 0};
        for (dk_index k = 0, h = 0; h < 2; h++)
            for (dk_index j = 0; j < s.sizes[h]; j++, k++)
                if (s.hv[k] < n0) {
                    s.hv[kept++] = s.hv[k];
                    sizes[h]++;
                }
        s.n_hv = kept;
        memcpy(s.sizes, sizes, sizeof sizes);
        double *t = malloc(sizeof(double) * 3 * (size_t)s.n_hv), *x = malloc(sizeof(double) * 3 * (size_t)n);
        if (!t || !x)
            abort();
        for (dk_index k = 0; k < s.n_hv; k++)
            for (int c = 0; c < 3; c++)
                t[3 * k + c] = p[3 * s.hv[k] + c] + (c == 2 ? 0.2 : 0.0);
        void *obj = NULL;
        dk_error e = {0};
        dk_status st = o->bind(s.mesh, &s.desc, NULL, &obj, &e);
        CHECK_MSG(st == DK_OK, "%s: %s", o->name, e.message);
        if (st == DK_OK) {
            dk_method_stats ms;
            o->stats(obj, &ms);
            CHECK_MSG(ms.n_held == b.n_vertices && ms.n_held_components == 1 &&
                          ms.first_held == n0,
                      "%s: held %d in %d, first %d", o->name, (int)ms.n_held,
                      (int)ms.n_held_components, (int)ms.first_held);
            solve_beside_held(o, obj, &s, p, t, n0, b.n_vertices, 0.15, x);
            o->free(obj);
        }
        free(t);
        free(x);
        scene_free(&s);
        free(p);
        free(f);
        dk_test_mesh_free(&a);
        dk_test_mesh_free(&b);
    }
}

/* Sets field f of options o to v (INT, ENUM, DOUBLE). */
static void set_field(void *o, const dk_option_desc *f, double v)
{
    unsigned char *p = (unsigned char *)o + f->offset;
    if (f->type == DK_OPTION_DOUBLE) {
        memcpy(p, &v, sizeof v);
    } else {
        const int i = (int)v;
        memcpy(p, &i, sizeof i);
    }
}

/* Binds with the defaults but field f set to v; returns the status (the object freed). */
static dk_status bind_with(const dk_method_ops *o, const scene *s, const dk_option_desc *f,
                           double v, dk_error *e)
{
    union {
        max_align_t align;
        unsigned char bytes[1024];
    } opt;
    void *obj = NULL;
    if (o->options_size > sizeof opt.bytes)
        return dk_error_set(e, DK_ERR_INTERNAL, "options struct over 1 KiB");
    o->default_options(opt.bytes);
    set_field(opt.bytes, f, v);
    control_scene c;
    const int controlled = !(o->controls & DK_CONTROL_VERTEX_GROUPS);
    if (controlled && control_scene_make(o, s, &c) != 0)
        return dk_error_set(e, DK_ERR_INTERNAL, "no contract scene for %s's controls", o->name);
    const dk_status st = o->bind(s->mesh, controlled ? &c.desc : &s->desc, opt.bytes, &obj, e);
    if (controlled)
        control_scene_free(&c);
    if (st == DK_OK)
        o->free(obj);
    return st;
}

/* The ops table's option fields (dk_option_desc) tell the truth, for every method: each
 * default lies in its field's range; a bind takes the field's usual value, its least and
 * its quick largest; and it refuses what lies outside: one below the least and one above
 * the largest integer, NaN, and a real below its least (0 or -1). So code written against
 * the contract (the fuzzer) fills options it does not know, and every field is checked
 * ("a call that cannot work says so"). */
static void test_option_fields(void)
{
    for (const dk_method_ops *const *m = dk_methods(); *m; m++) {
        const dk_method_ops *o = *m;
        dk_test_mesh plane = {0};
        scene s;
        if (!small_scene(o, &s, &plane, 8, 1))
            return;
        CHECK_MSG(o->options_size > 0 && o->default_options && o->n_option_fields > 0 &&
                      o->progress_offset != o->progress_user_offset,
                  "%s: the table lacks its options", o->name);
        union {
            max_align_t align;
            unsigned char bytes[1024];
        } def;
        o->default_options(def.bytes);
        for (int i = 0; i < o->n_option_fields; i++) {
            const dk_option_desc *f = &o->option_fields[i];
            dk_error e = {0};
            CHECK_MSG(f->offset < o->options_size && f->count_offset < o->options_size,
                      "%s.%s: offset past the struct", o->name, f->name);
            if (f->type == DK_OPTION_VERTICES || f->type == DK_OPTION_EDGE_VALUES ||
                f->type == DK_OPTION_VERTEX_VALUES || f->type == DK_OPTION_SEED)
                continue;
            double d;
            if (f->type == DK_OPTION_DOUBLE)
                memcpy(&d, def.bytes + f->offset, sizeof d);
            else {
                int iv;
                memcpy(&iv, def.bytes + f->offset, sizeof iv);
                d = iv;
            }
            CHECK_MSG((d >= f->min && d <= f->max) || (d == 0 && (f->flags & DK_OPTION_ZERO_AUTO)),
                      "%s.%s: the default %g is outside [%g, %g]", o->name, f->name, d, f->min,
                      f->max);
            const double usual = f->flags & DK_OPTION_LENGTH ? f->usual * s.diag : f->usual;
            /* the least valid value alone: n_nodes = 1 needs k = 0, a radius or w of
             * 1e-323 scale the mesh away; the integers' least is taken where the defaults
             * allow it (below), the reals' usual value */
            const double good[2] = {usual, f->type == DK_OPTION_DOUBLE ? usual : f->quick_max};
            for (int k = 0; k < 2; k++)
                CHECK_MSG(bind_with(o, &s, f, good[k], &e) == DK_OK, "%s.%s = %g refused: %s",
                          o->name, f->name, good[k], e.message);
            if (f->type == DK_OPTION_DOUBLE) {
                CHECK_MSG(bind_with(o, &s, f, NAN, &e) != DK_OK && e.message[0],
                          "%s.%s = NaN taken", o->name, f->name);
                if (f->min >= 0.0) {
                    const double below = f->min > 0.0 && !(f->flags & DK_OPTION_ZERO_AUTO)
                                             ? 0.0
                                             : -1.0;
                    CHECK_MSG(bind_with(o, &s, f, below, &e) != DK_OK && e.message[0],
                              "%s.%s = %g taken", o->name, f->name, below);
                }
            } else {
                const int below = (int)f->min - 1;
                if (f->min > INT_MIN && !(below == 0 && (f->flags & DK_OPTION_ZERO_AUTO)))
                    CHECK_MSG(bind_with(o, &s, f, below, &e) != DK_OK && e.message[0],
                              "%s.%s = %d taken", o->name, f->name, below);
                if (f->max < INT_MAX)
                    CHECK_MSG(bind_with(o, &s, f, f->max + 1, &e) != DK_OK && e.message[0],
                              "%s.%s = %g taken", o->name, f->name, f->max + 1);
            }
        }
        scene_free(&s);
        dk_test_mesh_free(&plane);
    }
}

/* Each method declares its control kinds; a control of a kind it does not take is refused
 * with a message naming both, and no object comes back. */
static void test_controls_declared(void)
{
    dk_test_mesh plane = {0};
    scene s;
    if (!small_plane(&s, &plane, 8))
        return;
    const double box[16] = {2, 0, 0, -1, 0, 2, 0, -1, 0, 0, 1, -0.5, 0, 0, 0, 1};
    const double points[6] = {0, 0, 0, 1, 1, 1};
    const dk_control_desc controls[2] = {
        {.kind = DK_CONTROL_LATTICE, .n_controls = 8, .rest = box, .resolution = {2, 2, 2}},
        {.kind = DK_CONTROL_POINTS, .n_controls = 2, .rest = points}};
    for (const dk_method_ops *const *m = dk_methods(); *m; m++) {
        const dk_method_ops *o = *m;
        CHECK_MSG(o->controls != 0 && (o->controls & ~DK_CONTROL_ALL) == 0,
                  "%s declares controls %#x", o->name, o->controls);
        for (int k = 0; k < 2; k++) {
            const dk_control_desc *c = &controls[k];
            dk_error e = {0};
            CHECK(dk_control_check(c, s.mesh->n_vertices, &e) == DK_OK);
            if (o->controls & (unsigned)c->kind)
                continue; /* a method that takes it has tests of its own */
            dk_constraint_desc d = s.desc;
            d.control = c;
            void *obj = (void *)1;
            const dk_status st = o->bind(s.mesh, &d, NULL, &obj, &e);
            CHECK_MSG(st == DK_ERR_INVALID_ARGUMENT && obj == NULL &&
                          strstr(e.message, dk_control_kind_name(c->kind)) &&
                          strstr(e.message, "binds to"),
                      "%s given %s: status %d, '%s'", o->name, dk_control_kind_name(c->kind),
                      (int)st, e.message);
            if (st == DK_OK && obj)
                o->free(obj);
        }
    }
    scene_free(&s);
    dk_test_mesh_free(&plane);
}

/* One step of a shot: transforms of both handles (a shift along x and a turn), the start,
 * an iteration cap (0: as bound) and, for methods that edit their input, whether the
 * request carries a pose (the rest bent along y). */
typedef struct shot_step {
    double shift;
    dk_start start;
    int max_iterations, posed;
} shot_step;

static dk_status shot_solve(const dk_method_ops *ops, void *obj, const scene *s,
                            const shot_step *k, const double *pose, double *x,
                            dk_solve_info *info, dk_error *e)
{
    double T[32];
    some_transform(T, k->shift);
    memcpy(T + 16, T, 16 * sizeof(double));
    T[16 + 3] -= 2.0 * k->shift;
    dk_solve_request rq = {.targets = T,
                           .target_kind = DK_TARGETS_TRANSFORMS,
                           .start = k->start,
                           .max_iterations = k->max_iterations};
    if (k->posed && (ops->flags & DK_METHOD_EDITS_INPUT))
        rq.input_positions = pose;
    (void)s;
    return ops->solve(obj, &rq, x, info, e);
}

/* Runs steps [from, to) of `shot` on obj; the last solve's positions in x, its info in
 * *info. 0 on success. */
static int shot_run(const dk_method_ops *ops, void *obj, const scene *s, const shot_step *shot,
                    int from, int to, const double *pose, double *x, dk_solve_info *info)
{
    for (int k = from; k < to; k++) {
        dk_error e = {0};
        if (shot_solve(ops, obj, s, &shot[k], pose, x, info, &e) != DK_OK) {
            CHECK_MSG(0, "%s: shot step %d: %s", ops->name, k, e.message);
            return -1;
        }
    }
    return 0;
}

static int same_solve(const double *x, const dk_solve_info *a, const double *y,
                      const dk_solve_info *b, size_t n)
{
    return memcmp(x, y, n * sizeof(double)) == 0 && a->iterations == b->iterations &&
           a->converged == b->converged &&
           memcmp(&a->energy, &b->energy, sizeof a->energy) == 0;
}

static void check_state(const dk_method_ops *ops, scene *s)
{
    const size_t N = 3 * (size_t)s->mesh->n_vertices;
    /* cold, a warm slice of three iterations (a resumable place), a turn on the pose, then
     * what must continue exactly: a resume of that slice (three iterations in: Newton
     * steps, whose resumed products read what the slice left), warm solves on a pose */
    static const shot_step shot[] = {{0.0, DK_START_COLD, 0, 0}, {0.3, DK_START_WARM, 3, 0},
                                     {0.3, DK_START_RESUME, 0, 0}, {0.5, DK_START_WARM, 0, 1},
                                     {0.6, DK_START_WARM, 0, 1}, {0.6, DK_START_RESUME, 0, 1}};
    const int saved_at = 2, n_steps = (int)(sizeof shot / sizeof shot[0]);
    double *pose = malloc(N * sizeof(double)), *x = malloc(N * sizeof(double));
    double *y = malloc(N * sizeof(double));
    void *a = NULL, *b = NULL, *c = NULL;
    unsigned char *state = NULL;
    dk_error e = {0};
    dk_solve_info ia, ib;
    if (!pose || !x || !y)
        goto out;
    for (size_t i = 0; i < N; i += 3) { /* the rest, bent: y lifted by x^2 / 4 */
        memcpy(pose + i, s->mesh->positions + i, 3 * sizeof(double));
        pose[i + 1] += 0.25 * pose[i] * pose[i];
    }
    if (ops->bind(s->mesh, &s->desc, NULL, &a, &e) != DK_OK ||
        ops->bind(s->mesh, &s->desc, NULL, &b, &e) != DK_OK ||
        ops->bind(s->mesh, &s->desc, NULL, &c, &e) != DK_OK) {
        CHECK_MSG(0, "%s: bind: %s", ops->name, e.message);
        goto out;
    }
    /* a: never interrupted, the reference */
    if (shot_run(ops, a, s, shot, 0, n_steps, pose, x, &ia) != 0)
        goto out;
    /* b: saved after the first two steps, driven elsewhere, restored, finished */
    if (shot_run(ops, b, s, shot, 0, saved_at, pose, y, &ib) != 0)
        goto out;
    const size_t size = ops->state_size(b);
    state = malloc(size + 1);
    if (!state || ops->save_state(b, state, size, &e) != DK_OK) {
        CHECK_MSG(0, "%s: save_state: %s", ops->name, e.message);
        goto out;
    }
    CHECK(ops->save_state(b, state, size - 1, &e) == DK_ERR_INVALID_ARGUMENT);
    if (shot_run(ops, b, s, shot, saved_at + 1, n_steps, pose, y, &ib) != 0)
        goto out;
    if (ops->restore_state(b, state, size, &e) != DK_OK) {
        CHECK_MSG(0, "%s: restore_state: %s", ops->name, e.message);
        goto out;
    }
    if (shot_run(ops, b, s, shot, saved_at, n_steps, pose, y, &ib) != 0)
        goto out;
    CHECK_MSG(same_solve(x, &ia, y, &ib, N),
              "%s on %s: restored into itself, the shot ends %g away (%d vs %d iterations)",
              ops->name, s->name, max_diff(x, y, N), ia.iterations, ib.iterations);
    /* c: a fresh object given the state (a chunk starting mid-shot); first what must not
     * fit, which changes nothing */
    unsigned char *bad = malloc(size);
    if (bad) {
        memcpy(bad, state, size);
        bad[0] ^= 1;
        CHECK(ops->restore_state(c, bad, size, &e) == DK_ERR_INVALID_ARGUMENT &&
              strstr(e.message, "not a saved state"));
        memcpy(bad, state, size);
        bad[8] = 'Z'; /* the method's name */
        CHECK(ops->restore_state(c, bad, size, &e) == DK_ERR_INVALID_ARGUMENT &&
              strstr(e.message, "saved by"));
        CHECK(ops->restore_state(c, state, size - 1, &e) == DK_ERR_INVALID_ARGUMENT);
        free(bad);
    }
    if (ops->restore_state(c, state, size, &e) != DK_OK) {
        CHECK_MSG(0, "%s: restore_state into a fresh object: %s", ops->name, e.message);
        goto out;
    }
    if (shot_run(ops, c, s, shot, saved_at, n_steps, pose, y, &ib) != 0)
        goto out;
    CHECK_MSG(same_solve(x, &ia, y, &ib, N),
              "%s on %s: restored into a fresh object, the shot ends %g away (%d vs %d "
              "iterations)",
              ops->name, s->name, max_diff(x, y, N), ia.iterations, ib.iterations);
    /* other constraints (one handle): refused, and the object goes on as before */
    dk_constraint_desc one = s->desc;
    one.n_handles = 1;
    if (ops->rebind(c, &one, &e) == DK_OK) {
        CHECK_MSG(ops->restore_state(c, state, ops->state_size(c), &e) ==
                          DK_ERR_INVALID_ARGUMENT &&
                      strstr(e.message, "bound otherwise"),
                  "%s: a state of two handles restored into one: '%s'", ops->name, e.message);
    }
out:
    if (a)
        ops->free(a);
    if (b)
        ops->free(b);
    if (c)
        ops->free(c);
    free(state);
    free(pose);
    free(x);
    free(y);
}

static void test_state(void)
{
    dk_test_mesh plane = {0};
    scene s;
    if (!small_plane(&s, &plane, 12))
        return;
    int stateful = 0;
    for (const dk_method_ops *const *m = dk_methods(); *m; m++) {
        const dk_method_ops *o = *m;
        const int has = o->state_size != NULL;
        CHECK_MSG(has == (o->save_state != NULL) && has == (o->restore_state != NULL),
                  "%s: state entries partly set", o->name);
        /* a warm start reads what the last solve left: every iterative method carries it */
        CHECK_MSG(!(o->flags & DK_METHOD_ITERATIVE) || has, "%s: iterative without state",
                  o->name);
        if (has && (o->flags & DK_METHOD_INTERIOR)) {
            dk_test_mesh sphere = {0};
            scene c;
            if (small_scene(o, &c, &sphere, 0, 2)) {
                stateful++;
                check_state(o, &c);
                scene_free(&c);
            }
            dk_test_mesh_free(&sphere);
        } else if (has) {
            stateful++;
            check_state(o, &s);
        }
    }
    CHECK(stateful >= 2);
    scene_free(&s);
    dk_test_mesh_free(&plane);
}

DK_TEST_MAIN(test_registry, test_every_method, test_loose_geometry, test_loose_volumes,
             test_option_fields,
             test_controls_declared, test_state)
