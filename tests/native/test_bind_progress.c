/* DeformKit: bind progress and cancellation (dk_progress.h) of ARAP, LaplacianEdit,
 * Falloff (geodesic: its heat factorization and its distances), EmbeddedDeformation and
 * LinearReconstruction.
 *
 * - the reporter itself: fractions from the phase weights, non-decreasing, in [0, 1], "done"
 *   at 1, a stop request turned into DK_ERR_CANCELLED, phases out of order refused;
 * - each method's bind and rebind report non-decreasing fractions in [0, 1] ending at
 *   exactly 1 ("done"), through several phases, with reports inside the long loops;
 * - a bind cancelled at each of its reports (every one, in turn) fails with
 *   DK_ERR_CANCELLED and no object (the ASan build checks that nothing leaks);
 * - a rebind cancelled at each of its reports leaves the object solving its old
 *   constraints exactly as before (bit for bit, the same counters), for a rebind that
 *   needs a new analysis and one that reuses it (LaplacianEdit: with new values, so that a
 *   cancellation in the basis refactors the old ones).
 * The meshes are generated (a bumpy grid, large enough for the loops to report). */
#include "dk_arap.h"
#include "dk_eigen.h"
#include "dk_embedded.h"
#include "dk_falloff.h"
#include "dk_fundamental.h"
#include "dk_laplacian_edit.h"
#include "dk_progress.h"
#include "dk_test.h"
#include "dk_test_meshes.h"

#include <stdlib.h>
#include <string.h>

/* ------------------------------------------------------------------ a recording callback */

#define MAX_CALLS 4096

typedef struct recorder {
    int calls;
    int stop_at;            /* ask to stop at this call (0-based), -1: never            */
    double fraction[MAX_CALLS];
    const char *phase[MAX_CALLS]; /* the method's names are static strings             */
} recorder;

static int record(void *user, const char *phase, double fraction)
{
    recorder *r = user;
    if (r->calls < MAX_CALLS) {
        r->fraction[r->calls] = fraction;
        r->phase[r->calls] = phase;
    }
    return r->calls++ == r->stop_at;
}

static void recorder_reset(recorder *r, int stop_at)
{
    r->calls = 0;
    r->stop_at = stop_at;
}

/* fractions non-decreasing in [0, 1], the last exactly 1 named "done"; returns the number
 * of distinct phases seen */
static int check_sequence(const recorder *r, const char *what)
{
    CHECK_MSG(r->calls >= 2 && r->calls <= MAX_CALLS, "%s: %d calls", what, r->calls);
    if (r->calls < 2 || r->calls > MAX_CALLS)
        return 0;
    int phases = 1, ordered = 1, inside = 1;
    for (int i = 0; i < r->calls; i++) {
        inside &= r->fraction[i] >= 0.0 && r->fraction[i] <= 1.0;
        if (i > 0) {
            ordered &= r->fraction[i] >= r->fraction[i - 1];
            phases += strcmp(r->phase[i], r->phase[i - 1]) != 0;
        }
    }
    CHECK_MSG(inside, "%s: a fraction outside [0, 1]", what);
    CHECK_MSG(ordered, "%s: the fractions decrease somewhere", what);
    CHECK_MSG(r->fraction[r->calls - 1] == 1.0 && strcmp(r->phase[r->calls - 1], "done") == 0,
              "%s: ends at %g in %s", what, r->fraction[r->calls - 1], r->phase[r->calls - 1]);
    return phases;
}

/* Whether a test stops at report k of the whole sequence r: the first report of a phase
 * or the one after it (inside the phase's loop, when it has one). */
static int stop_here(const recorder *r, int k)
{
    if (k >= MAX_CALLS)
        return 0;
    return k <= 1 || strcmp(r->phase[k], r->phase[k - 1]) != 0 ||
           strcmp(r->phase[k - 1], r->phase[k - 2]) != 0;
}

static int count_phase(const recorder *r, const char *phase)
{
    int k = 0;
    for (int i = 0; i < r->calls && i < MAX_CALLS; i++)
        k += strcmp(r->phase[i], phase) == 0;
    return k;
}

/* ------------------------------------------------------------------ the reporter -------- */

static void test_reporter(void)
{
    static const dk_progress_phase phases[] = {{"one", 1.0}, {"two", 3.0}, {"three", 4.0}};
    recorder r;
    recorder_reset(&r, -1);
    dk_progress p;
    dk_error e = {0};
    dk_progress_init(&p, record, &r, phases, 3, "test");
    CHECK(dk_progress_begin(&p, 0, &e) == DK_OK);
    CHECK(dk_progress_part(&p, 0.5, &e) == DK_OK);
    CHECK(dk_progress_begin(&p, 2, &e) == DK_OK); /* phase two skipped */
    CHECK(dk_progress_part(&p, NAN, &e) == DK_OK); /* NaN: no step back */
    CHECK(dk_progress_part(&p, 7.0, &e) == DK_OK); /* clamped to the phase's end */
    CHECK(dk_progress_begin(&p, 1, &e) == DK_ERR_INTERNAL); /* never revisited */
    for (int i = 0; i < DK_PROGRESS_TICK; i++) /* one question per DK_PROGRESS_TICK ticks */
        CHECK(dk_progress_tick(&p, i, DK_PROGRESS_TICK, &e) == DK_OK);
    dk_progress_done(&p);
    CHECK(r.calls == 7);
    const double want[] = {0.0, 0.0625, 0.5, 0.5, 1.0, 1.0, 1.0};
    for (int i = 0; i < 7 && i < r.calls; i++)
        CHECK_NEAR(r.fraction[i], want[i], 1e-15);
    CHECK(strcmp(r.phase[1], "one") == 0 && strcmp(r.phase[2], "three") == 0);
    CHECK(strcmp(r.phase[6], "done") == 0);
    /* a stop request: DK_ERR_CANCELLED naming the phase */
    recorder_reset(&r, 1);
    dk_progress_init(&p, record, &r, phases, 3, "test");
    CHECK(dk_progress_begin(&p, 0, &e) == DK_OK);
    CHECK(dk_progress_begin(&p, 1, &e) == DK_ERR_CANCELLED);
    CHECK(e.status == DK_ERR_CANCELLED && strstr(e.message, "two") != NULL);
    /* no callback, or no reporter: nothing happens, nothing cancels */
    dk_progress_init(&p, NULL, NULL, phases, 3, "test");
    CHECK(dk_progress_begin(&p, 0, &e) == DK_OK);
    CHECK(dk_progress_begin(NULL, 0, &e) == DK_OK);
    CHECK(dk_progress_tick(NULL, 1, 2, &e) == DK_OK);
    dk_progress_done(NULL);
}

/* ------------------------------------------------------------------ the set-up ---------- */

#define CELLS 70 /* (CELLS + 1)^2 = 5041 vertices: the long loops report inside */

typedef struct setup {
    dk_test_mesh tm;
    dk_mesh *mesh;
    dk_index nv;
    /* A: handle = the top rows, fixed = the bottom rows; B: a handle elsewhere (a new
     * unknown set); C: A's vertices with other weights (the same unknowns, new values) */
    dk_index *handle_a, *handle_b, *fixed;
    dk_index n_handle_a, n_handle_b, n_fixed;
    double *weights_a, *weights_c;
    dk_constraint_desc a, b, c;
    double *targets_a;
    double transform[16];
} setup;

static int setup_make(setup *s)
{
    memset(s, 0, sizeof *s);
    if (dk_test_bumpy_plane(CELLS, 0.15, &s->tm) != 0)
        return -1;
    s->mesh = dk_test_mesh_build(&s->tm);
    if (!s->mesh)
        return -1;
    const int side = CELLS + 1;
    s->nv = s->tm.n_vertices;
    s->handle_a = malloc(sizeof(dk_index) * 3 * side);
    s->handle_b = malloc(sizeof(dk_index) * 3 * side);
    s->fixed = malloc(sizeof(dk_index) * 2 * side);
    s->weights_a = malloc(sizeof(double) * 3 * side);
    s->weights_c = malloc(sizeof(double) * 3 * side);
    s->targets_a = malloc(sizeof(double) * 9 * side);
    if (!s->handle_a || !s->handle_b || !s->fixed || !s->weights_a || !s->weights_c ||
        !s->targets_a)
        return -1;
    for (int i = 0; i < 2 * side; i++)
        s->fixed[s->n_fixed++] = i; /* rows 0, 1 */
    for (int i = 0; i < 3 * side; i++) {
        s->handle_a[s->n_handle_a++] = s->nv - 1 - i; /* the three top rows */
        s->weights_a[i] = 0.9;
        s->weights_c[i] = 0.6;
        const int col = i % side, row = side / 2 - 1 + i / side; /* three middle rows */
        s->handle_b[s->n_handle_b++] = row * side + col;
    }
    static dk_index size_a, size_b;
    size_a = s->n_handle_a;
    size_b = s->n_handle_b;
    s->a = (dk_constraint_desc){.n_handles = 1, .handle_sizes = &size_a,
                                .handle_vertices = s->handle_a, .handle_weights = s->weights_a,
                                .n_fixed = s->n_fixed, .fixed_vertices = s->fixed};
    s->b = s->a;
    s->b.handle_sizes = &size_b;
    s->b.handle_vertices = s->handle_b;
    s->b.handle_weights = NULL;
    s->c = s->a;
    s->c.handle_weights = s->weights_c;
    /* the handle lifted and moved sideways */
    for (dk_index k = 0; k < s->n_handle_a; k++)
        for (int d = 0; d < 3; d++)
            s->targets_a[3 * k + d] = s->tm.positions[3 * s->handle_a[k] + d] +
                                      (d == 2 ? 0.3 : d == 0 ? 0.1 : 0.0);
    const double t[16] = {1, 0, 0, 0.1, 0, 1, 0, 0, 0, 0, 1, 0.3, 0, 0, 0, 1};
    memcpy(s->transform, t, sizeof t);
    return 0;
}

static void setup_free(setup *s)
{
    dk_mesh_free(s->mesh);
    dk_test_mesh_free(&s->tm);
    free(s->handle_a);
    free(s->handle_b);
    free(s->fixed);
    free(s->weights_a);
    free(s->weights_c);
    free(s->targets_a);
}

/* ------------------------------------------------------------------ the methods -------- */

/* The contract's table plus the two functions the test needs of each method. */
typedef struct method {
    const char *name;
    const dk_method_ops *ops;
    void (*options)(void *opt, dk_phase_progress_fn fn, void *user); /* defaults + callback */
    void (*set_progress)(void *self, dk_phase_progress_fn fn, void *user);
    const char *loop_phase; /* a phase with reports inside its loop at CELLS */
    int min_phases;         /* of a bind, "done" included */
} method;

static void arap_options(void *o, dk_phase_progress_fn fn, void *user)
{
    dk_arap_default_options(o);
    /* a few Newton steps: the test compares solves bit for bit, not converged ones (the
     * lifted handle takes hundreds of steps to converge here, most of this test's time) */
    ((dk_arap_options *)o)->max_iterations = 10;
    ((dk_arap_options *)o)->progress = fn;
    ((dk_arap_options *)o)->progress_user = user;
}
static void arap_set(void *self, dk_phase_progress_fn fn, void *user)
{
    dk_arap_set_progress(self, fn, user);
}
static void le_options(void *o, dk_phase_progress_fn fn, void *user)
{
    dk_laplacian_edit_default_options(o);
    ((dk_laplacian_edit_options *)o)->progress = fn;
    ((dk_laplacian_edit_options *)o)->progress_user = user;
}
static void le_set(void *self, dk_phase_progress_fn fn, void *user)
{
    dk_laplacian_edit_set_progress(self, fn, user);
}

static void falloff_options(void *o, dk_phase_progress_fn fn, void *user)
{
    dk_falloff_default_options(o);
    ((dk_falloff_options *)o)->distance = DK_FALLOFF_GEODESIC; /* both phases */
    ((dk_falloff_options *)o)->progress = fn;
    ((dk_falloff_options *)o)->progress_user = user;
}
static void falloff_set(void *self, dk_phase_progress_fn fn, void *user)
{
    dk_falloff_set_progress(self, fn, user);
}

static void ed_options(void *o, dk_phase_progress_fn fn, void *user)
{
    dk_embedded_default_options(o);
    ((dk_embedded_options *)o)->progress = fn;
    ((dk_embedded_options *)o)->progress_user = user;
}
static void ed_set(void *self, dk_phase_progress_fn fn, void *user)
{
    dk_embedded_set_progress(self, fn, user);
}

static void fr_options(void *o, dk_phase_progress_fn fn, void *user)
{
    dk_fundamental_default_options(o);
    ((dk_fundamental_options *)o)->progress = fn;
    ((dk_fundamental_options *)o)->progress_user = user;
}
static void fr_set(void *self, dk_phase_progress_fn fn, void *user)
{
    dk_fundamental_set_progress(self, fn, user);
}

/* EigenDeformation: its bind only (its rebind does not report), on set-up B (it refuses
 * handle weights), with few eigenvectors so that the test stays quick */
static void eig_options(void *o, dk_phase_progress_fn fn, void *user)
{
    dk_eigen_default_options(o);
    ((dk_eigen_options *)o)->n_eigenvectors = 8;
    ((dk_eigen_options *)o)->refine = 0;
    ((dk_eigen_options *)o)->progress = fn;
    ((dk_eigen_options *)o)->progress_user = user;
}
static const method eigen_method = {"EigenDeformation", &dk_eigen_ops, eig_options, NULL,
                                    "eigenvectors", 5};

static const method methods[] = {
    {"ARAP", &dk_arap_ops, arap_options, arap_set, "cells", 8},
    {"LaplacianEdit", &dk_laplacian_edit_ops, le_options, le_set, "basis", 8},
    {"Falloff", &dk_falloff_ops, falloff_options, falloff_set, "distances", 3},
    {"EmbeddedDeformation", &dk_embedded_ops, ed_options, ed_set, "weights", 6},
    {"LinearReconstruction", &dk_fundamental_ops, fr_options, fr_set, "assemble", 7}};

typedef union options {
    dk_arap_options arap;
    dk_laplacian_edit_options le;
    dk_falloff_options falloff;
    dk_embedded_options ed;
    dk_fundamental_options fr;
    dk_eigen_options eig;
} options;

/* Two cold solves of the A set-up (positions and a transform) into out (2 x nv x 3), with
 * their infos; returns the status. */
static dk_status solve_pair(const method *m, void *obj, const setup *s, double *out,
                            dk_solve_info info[2])
{
    dk_error e = {0};
    dk_solve_request rq = {.targets = s->targets_a};
    dk_status st = m->ops->solve(obj, &rq, out, &info[0], &e);
    if (st != DK_OK)
        return st;
    rq = (dk_solve_request){.targets = s->transform, .target_kind = DK_TARGETS_TRANSFORMS};
    return m->ops->solve(obj, &rq, out + 3 * (size_t)s->nv, &info[1], &e);
}

static void test_bind(const method *m, const setup *s, const dk_constraint_desc *desc)
{
    recorder *r = malloc(sizeof *r);
    if (!r) {
        CHECK(0);
        return;
    }
    options opt;
    dk_error e = {0};
    void *obj = NULL;
    /* a whole bind: the sequence, and how many reports it made */
    recorder_reset(r, -1);
    m->options(&opt, record, r);
    CHECK(m->ops->bind(s->mesh, desc, &opt, &obj, &e) == DK_OK);
    const int phases = check_sequence(r, m->name);
    CHECK_MSG(phases >= m->min_phases, "%s: %d phases", m->name, phases);
    CHECK_MSG(count_phase(r, m->loop_phase) >= 2, "%s: %d reports in %s", m->name,
              count_phase(r, m->loop_phase), m->loop_phase);
    const int calls = r->calls;
    recorder whole = *r;
    m->ops->free(obj);
    /* cancelled at each report but the last ("done": the bind is whole by then) that starts
     * a phase or is the first inside one (the loops' reports: the others are alike) */
    for (int k = 0; k < calls - 1; k++) {
        if (!stop_here(&whole, k))
            continue;
        recorder_reset(r, k);
        m->options(&opt, record, r);
        obj = (void *)1;
        dk_error_clear(&e);
        const dk_status st = m->ops->bind(s->mesh, desc, &opt, &obj, &e);
        CHECK_MSG(st == DK_ERR_CANCELLED && obj == NULL && r->calls == k + 1,
                  "%s bind stopped at report %d (%s): status %d, %d reports, %s", m->name, k,
                  r->phase[k], (int)st, r->calls, e.message);
        if (st == DK_OK)
            m->ops->free(obj);
    }
    /* stopping at "done" changes nothing: the bind succeeded */
    recorder_reset(r, calls - 1);
    m->options(&opt, record, r);
    CHECK(m->ops->bind(s->mesh, desc, &opt, &obj, &e) == DK_OK && obj != NULL);
    m->ops->free(obj);
    free(r);
}

static void test_rebind(const method *m, const setup *s, const dk_constraint_desc *next,
                        const char *what)
{
    const size_t n3 = 3 * (size_t)s->nv;
    recorder *r = malloc(sizeof *r);
    double *before = malloc(sizeof(double) * 2 * n3), *after = malloc(sizeof(double) * 2 * n3);
    if (!r || !before || !after) {
        CHECK(0);
        free(r);
        free(before);
        free(after);
        return;
    }
    options opt;
    dk_error e = {0};
    void *obj = NULL;
    m->options(&opt, NULL, NULL);
    if (m->ops->bind(s->mesh, &s->a, &opt, &obj, &e) != DK_OK) {
        CHECK_MSG(0, "%s bind: %s", m->name, e.message);
        goto out;
    }
    dk_solve_info ib[2], ia[2];
    CHECK(solve_pair(m, obj, s, before, ib) == DK_OK);
    dk_method_stats sb, sa;
    m->ops->stats(obj, &sb);
    /* the whole rebind's reports, then one cancelled at each of them */
    recorder_reset(r, -1);
    void *twin = NULL;
    CHECK(m->ops->bind(s->mesh, &s->a, &opt, &twin, &e) == DK_OK);
    m->set_progress(twin, record, r);
    CHECK(m->ops->rebind(twin, next, &e) == DK_OK);
    m->ops->free(twin);
    char label[96];
    snprintf(label, sizeof label, "%s rebind (%s)", m->name, what);
    const int phases = check_sequence(r, label);
    CHECK_MSG(phases >= 2, "%s: %d phases", label, phases);
    const int calls = r->calls;
    recorder whole = *r;
    for (int k = 0; k < calls - 1; k++) {
        if (!stop_here(&whole, k))
            continue;
        recorder_reset(r, k);
        m->ops->stats(obj, &sb); /* the counters just before (solves may count too) */
        m->set_progress(obj, record, r);
        dk_error_clear(&e);
        const dk_status st = m->ops->rebind(obj, next, &e);
        m->set_progress(obj, NULL, NULL);
        CHECK_MSG(st == DK_ERR_CANCELLED, "%s stopped at report %d (%s): status %d, %s", label,
                  k, r->phase[k], (int)st, e.message);
        /* the old constraints, solved exactly as before */
        m->ops->stats(obj, &sa);
        CHECK_MSG(sa.n_handle_vertices == sb.n_handle_vertices && sa.n_unknowns == sb.n_unknowns &&
                      sa.analysis_count == sb.analysis_count &&
                      sa.factorization_count == sb.factorization_count,
                  "%s at %d (%s): the constraints or counters changed", label, k, r->phase[k]);
        CHECK(solve_pair(m, obj, s, after, ia) == DK_OK);
        CHECK_MSG(memcmp(before, after, sizeof(double) * 2 * n3) == 0,
                  "%s at report %d (%s): the solves differ", label, k, r->phase[k]);
        CHECK(ia[0].energy == ib[0].energy && ia[1].energy == ib[1].energy &&
              ia[0].iterations == ib[0].iterations);
    }
    /* and a rebind that is not cancelled changes the result */
    CHECK(m->ops->rebind(obj, next, &e) == DK_OK);
    CHECK(solve_pair(m, obj, s, after, ia) == DK_OK);
    CHECK_MSG(next != &s->b || memcmp(before, after, sizeof(double) * 2 * n3) != 0,
              "%s: no change", label); /* (EmbeddedDeformation ignores handle weights) */
out:
    m->ops->free(obj);
    free(r);
    free(before);
    free(after);
}

static void test_methods(void)
{
    setup s;
    if (setup_make(&s) != 0) {
        CHECK(0);
        setup_free(&s);
        return;
    }
    for (size_t i = 0; i < sizeof methods / sizeof methods[0]; i++) {
        test_bind(&methods[i], &s, &s.a);
        test_rebind(&methods[i], &s, &s.b, "new unknowns");
        test_rebind(&methods[i], &s, &s.c, "same unknowns, new values");
    }
    test_bind(&eigen_method, &s, &s.b);
    setup_free(&s);
}

DK_TEST_MAIN(test_reporter, test_methods)
