/* DeformKit shape matching: the driver (dk_shape_matching.h). The steps of a bind: check the
 * options, the constraints (kinematic vertices), the per-vertex maps, the clusters, the rest
 * data of the bind's shape. A warm solve: the frame's goal shape and kinematic targets, then
 * `substeps` integration steps (integrators.c), each evaluating the goals (goals.c) of the
 * configuration and, with plasticity on, updating the clusters' plastic states. */
#include "sm_internal.h"

#include <float.h>
#include <math.h>
#include <stddef.h>
#include <stdlib.h>
#include <string.h>

#include "dk_memory.h"
#include "dk_operators.h"

struct dk_shape_matching {
    const dk_mesh *mesh;
    dk_shape_matching_options opt; /* the maps and given clusters not kept (copied below)  */
    dk_shape_matching_dynamics dyn;
    dk_constraints *con;
    unsigned char *kinematic;      /* n: 1 = follows its target or the input               */
    double *masses, *alpha_map, *beta_map, *damping_map; /* n each                         */
    double *attach_map;            /* n, or NULL: the painted attachments                  */
    sm_attach att;                 /* the attachments (attachments.c)                      */
    double *k, *d, *beta;          /* n: alpha_i / h^2 (h a substep), damping, beta        */
    double *ka, *ktot;             /* n: a_i / h^2, and k + ka (what the integrators use)   */
    int attached;                  /* some free vertex has an attachment                   */
    double tau;                    /* the fraction of the substep the goals are taken at   */
    sm_clusters cl;
    sm_rest rest;
    /* the state */
    double *x, *v;                 /* n x 3                                                */
    double *shape;                 /* n x 3: the goal shape of the last solve              */
    double *sp;                    /* 9 per cluster: plastic states                        */
    int64_t frame;
    /* scratch */
    double *goals, *member_goal, *work, *k0, *k1, *targets;
    double *u;                     /* n x 3: the input's velocity over this frame          */
    double *acc;                   /* 2 x n x 3: the goals summed per vertex, per half     */
    sm_fit *fits;
    unsigned char *changed;
    int want_fits;                 /* the next goal evaluation records the fits            */
    int substep, n_sub;            /* place(): the substep being taken                    */
    dk_team *team;
    unsigned char *backup;         /* a solve's own checkpoint: a failed solve puts it back */
    size_t backup_size;
    dk_phase_progress_fn rebind_progress; /* dk_shape_matching_set_progress                */
    void *rebind_progress_user;
};

static const dk_progress_phase bind_phases[] = {{"clusters", 1.0}};

/* The bytes of a state (dk_shape_matching_state_size) for n vertices and nc clusters: the
 * header, positions, velocities, goal shape, plastic states and the frame count (spans_of). */
static size_t state_bytes(dk_index n, dk_index nc)
{
    return sizeof(dk_state_header) + 3 * (3 * (size_t)n * sizeof(double)) +
           9 * (size_t)nc * sizeof(double) + sizeof(int64_t);
}

void dk_shape_matching_default_options(dk_shape_matching_options *o)
{
    memset(o, 0, sizeof *o);
    o->mode = DK_SHAPE_MATCHING_LINEAR;
    o->alpha = 0.3;
    o->beta = 0.3;
    o->damping = 4.0;
    o->time_step = 1.0 / 24.0;
    o->substeps = 2;
    o->integrator = DK_INTEGRATOR_SEMI_IMPLICIT_EULER;
    o->clusters = DK_CLUSTERS_CUBES;
    o->cluster_size = 0.0;
    o->plastic_yield = 0.1;
    o->plastic_creep = 0.0;
    o->plastic_max = 1.0;
}

static dk_status bad(dk_error *err, const char *what, double value, const char *range)
{
    return dk_error_set(err, DK_ERR_INVALID_ARGUMENT, "ShapeMatching: %s = %g, must be %s", what,
                        value, range);
}

static dk_status check_dynamics(const dk_shape_matching_dynamics *y, dk_error *err)
{
    if (!(y->alpha >= 0.0 && y->alpha <= 1.0))
        return bad(err, "alpha", y->alpha, "in [0, 1]");
    if (!(y->beta >= 0.0 && y->beta <= 1.0))
        return bad(err, "beta", y->beta, "in [0, 1]");
    if (!(y->damping >= 0.0 && y->damping <= DBL_MAX))
        return bad(err, "damping", y->damping, "finite and >= 0 (per second)");
    for (int c = 0; c < 3; c++)
        if (!isfinite(y->gravity[c]))
            return bad(err, c == 0 ? "gravity_x" : c == 1 ? "gravity_y" : "gravity_z",
                       y->gravity[c], "finite");
    if (!(y->time_step >= 1e-6 && y->time_step <= 3600.0))
        return bad(err, "time_step", y->time_step, "in [1e-6, 3600] seconds");
    if (!(y->plastic_yield >= 0.0 && y->plastic_yield <= DBL_MAX))
        return bad(err, "plastic_yield", y->plastic_yield, "finite and >= 0");
    if (!(y->plastic_creep >= 0.0 && y->plastic_creep <= DBL_MAX))
        return bad(err, "plastic_creep", y->plastic_creep, "finite and >= 0 (per second)");
    if (!(y->plastic_max >= 0.0 && y->plastic_max <= DBL_MAX))
        return bad(err, "plastic_max", y->plastic_max, "finite and >= 0");
    return DK_OK;
}

static dk_shape_matching_dynamics dynamics_of(const dk_shape_matching_options *o)
{
    return (dk_shape_matching_dynamics){.alpha = o->alpha,
                                        .beta = o->beta,
                                        .damping = o->damping,
                                        .gravity = {o->gravity_x, o->gravity_y, o->gravity_z},
                                        .time_step = o->time_step,
                                        .plastic_yield = o->plastic_yield,
                                        .plastic_creep = o->plastic_creep,
                                        .plastic_max = o->plastic_max};
}

/* A per-vertex array option: absent, or n values in [lo, hi]. */
static dk_status check_map(const dk_mesh *m, const char *name, const double *values,
                           dk_index count, double lo, double hi, dk_error *err)
{
    if (!values && count == 0)
        return DK_OK;
    if (!values || count != m->n_vertices)
        return dk_error_set(err, DK_ERR_INVALID_ARGUMENT,
                            "ShapeMatching: %s must have one value per vertex (%d), not %d",
                            name, (int)m->n_vertices, (int)count);
    for (dk_index v = 0; v < count; v++)
        if (!(values[v] >= lo && values[v] <= hi))
            return dk_error_set(err, DK_ERR_INVALID_ARGUMENT,
                                "ShapeMatching: %s of vertex %d is %g, must be in [%g, %g]",
                                name, (int)v, values[v], lo, hi);
    return DK_OK;
}

static dk_status check_options(const dk_mesh *m, const dk_shape_matching_options *o,
                               dk_error *err)
{
    if ((unsigned)o->mode > DK_SHAPE_MATCHING_QUADRATIC)
        return bad(err, "mode", (double)o->mode, "0 (rigid), 1 (linear) or 2 (quadratic)");
    if ((unsigned)o->integrator > DK_INTEGRATOR_RK4)
        return bad(err, "integrator", (double)o->integrator,
                   "0 (semi-implicit Euler), 1 (explicit Euler), 2 (implicit Euler) or 3 (RK4)");
    if ((unsigned)o->clusters > DK_CLUSTERS_PARTS)
        return bad(err, "clusters", (double)o->clusters, "0 (cubes) or 1 (parts)");
    if (o->substeps < 1 || o->substeps > 64)
        return bad(err, "substeps", o->substeps, "in [1, 64]");
    if (!(o->cluster_size >= 0.0 && o->cluster_size <= DBL_MAX))
        return bad(err, "cluster_size", o->cluster_size, "finite and >= 0 (0: automatic)");
    if (!(o->falloff >= 0.0 && o->falloff <= DBL_MAX))
        return bad(err, "falloff", o->falloff, "finite and >= 0 (0: automatic)");
    if (o->n_clusters < 0)
        return bad(err, "n_clusters", o->n_clusters, ">= 0");
    const dk_shape_matching_dynamics y = dynamics_of(o);
    dk_status st = check_dynamics(&y, err);
    if (st == DK_OK)
        st = check_map(m, "masses", o->masses, o->n_masses, DBL_MIN, 1e100, err);
    if (st == DK_OK)
        st = check_map(m, "alpha_map", o->alpha_map, o->n_alpha_map, 0.0, 1.0, err);
    if (st == DK_OK)
        st = check_map(m, "beta_map", o->beta_map, o->n_beta_map, 0.0, 1.0, err);
    if (st == DK_OK)
        st = check_map(m, "damping_map", o->damping_map, o->n_damping_map, 0.0, DBL_MAX, err);
    if (st == DK_OK)
        st = check_map(m, "attach_map", o->attach_map, o->n_attach_map, 0.0, 1.0, err);
    return st;
}

/* The per-vertex coefficients from the dynamics, the maps and the attachments. */
static void coefficients(dk_shape_matching *s)
{
    const double h = s->dyn.time_step / (double)s->opt.substeps;
    const double kf = s->dyn.alpha / (h * h);
    s->attached = 0;
    for (dk_index v = 0; v < s->mesh->n_vertices; v++) {
        s->k[v] = kf * s->alpha_map[v];
        s->d[v] = s->dyn.damping * s->damping_map[v];
        s->beta[v] = s->dyn.beta * s->beta_map[v];
        s->ka[v] = s->att.a[v] / (h * h);
        s->ktot[v] = s->k[v] + s->ka[v];
        s->attached |= s->att.a[v] > 0.0;
    }
}

/* ------------------------------------------------------------ passes over clusters ----- */

typedef struct pass {
    dk_shape_matching *s;
    const double *x, *y;
    double *goals;
} pass;

static void rest_part(void *ctx, dk_index begin, dk_index end, int part)
{
    (void)part;
    const pass *p = ctx;
    sm_rest_compute(&p->s->cl, p->y, p->s->mesh->positions, p->s->sp, &p->s->rest, begin, end);
}

/* The rest data of every cluster for goal shape y (whose content is s->shape's). */
static void rest_all(dk_shape_matching *s, const double *y)
{
    pass p = {.s = s, .y = y};
    dk_team_run_halves(s->team, rest_part, &p, s->cl.n_clusters, 64);
    s->rest.shape = s->shape;
}

/* Per membership goals (the energy's residual). */
static void member_part(void *ctx, dk_index begin, dk_index end, int part)
{
    (void)part;
    const pass *p = ctx;
    dk_shape_matching *s = p->s;
    sm_goals_clusters(&s->cl, &s->rest, s->opt.mode, s->beta, p->x, s->member_goal, NULL,
                      NULL, begin, end);
}

/* The goals summed per vertex, each half of the clusters into its own buffer (zeroed here:
 * the halves are the same whether or not the helper runs, so the sums are too). */
static void cluster_part(void *ctx, dk_index begin, dk_index end, int part)
{
    const pass *p = ctx;
    dk_shape_matching *s = p->s;
    double *acc = s->acc + 3 * (size_t)s->mesh->n_vertices * (size_t)part;
    memset(acc, 0, 3 * (size_t)s->mesh->n_vertices * sizeof *acc);
    sm_goals_clusters(&s->cl, &s->rest, s->opt.mode, s->beta, p->x, NULL, acc,
                      s->want_fits ? s->fits : NULL, begin, end);
}

static void vertex_part(void *ctx, dk_index begin, dk_index end, int part)
{
    (void)part;
    const pass *p = ctx;
    const size_t N = 3 * (size_t)p->s->mesh->n_vertices;
    sm_goals_from_sums(&p->s->cl, p->s->acc, p->s->acc + N, p->x, p->goals, begin, end);
}

/* sm_goals_fn: the blended goals of configuration x, each blended with where the input puts
 * its vertex at this time by its attachment: (k g + k_a y(t)) / (k + k_a). */
static void goals_of(void *ctx, const double *x, double *goals)
{
    dk_shape_matching *s = ctx;
    pass p = {.s = s, .x = x, .goals = goals};
    dk_team_run_halves(s->team, cluster_part, &p, s->cl.n_clusters, 64);
    dk_team_run_halves(s->team, vertex_part, &p, s->mesh->n_vertices, 4096);
    s->want_fits = 0;
    if (!s->attached)
        return;
    /* y(t) = y - u T (1 - f): the frame's input less what is left of its motion; a vertex
     * is attached to y(t) moved as its sources (attachments.c) are moved off their own y(t)
     * (by a handle; a fixed vertex follows the input: no move) */
    const double back = s->dyn.time_step * (1.0 - ((double)s->substep + s->tau) / s->n_sub);
    for (dk_index v = 0; v < s->mesh->n_vertices; v++) {
        if (!(s->ka[v] > 0.0))
            continue;
        const double inv = 1.0 / s->ktot[v];
        const dk_index t0 = s->att.start[v], t1 = s->att.start[v + 1];
        for (int c = 0; c < 3; c++) {
            const size_t j = 3 * (size_t)v + (size_t)c;
            double y = s->shape[j] - s->u[j] * back;
            for (dk_index t = t0; t < t1; t++) {
                const size_t i = 3 * (size_t)s->att.vertex[t] + (size_t)c;
                y += s->att.share[t] * (x[i] - (s->shape[i] - s->u[i] * back));
            }
            goals[j] = (s->k[v] * goals[j] + s->ka[v] * y) * inv;
        }
    }
}

/* sm_place_fn: the kinematic vertices at fraction tau of the current substep. */
static void place(void *ctx, double *x, double *v, double tau)
{
    dk_shape_matching *s = ctx;
    s->tau = tau;
    const double f = ((double)s->substep + tau) / (double)s->n_sub;
    const double inv_t = 1.0 / s->dyn.time_step;
    for (dk_index i = 0; i < s->mesh->n_vertices; i++) {
        if (!s->kinematic[i])
            continue;
        for (int c = 0; c < 3; c++) {
            const size_t j = 3 * (size_t)i + (size_t)c;
            const double a = s->k0[j], b = s->k1[j];
            x[j] = f == 1.0 ? b : a + f * (b - a);
            v[j] = (b - a) * inv_t;
        }
    }
}

/* ------------------------------------------------------------------------- bind ------- */

void dk_shape_matching_free(dk_shape_matching *s)
{
    if (!s)
        return;
    dk_team_free(s->team);
    dk_constraints_free(s->con);
    sm_clusters_free(&s->cl);
    sm_rest_free(&s->rest);
    free(s->kinematic);
    free(s->masses), free(s->alpha_map), free(s->beta_map), free(s->damping_map);
    free(s->attach_map);
    free(s->k), free(s->d), free(s->beta), free(s->ka), free(s->ktot);
    sm_attach_free(&s->att);
    free(s->backup);
    free(s->x), free(s->v), free(s->shape), free(s->sp);
    free(s->goals), free(s->member_goal), free(s->work), free(s->k0), free(s->k1), free(s->u);
    free(s->acc);
    free(s->targets), free(s->fits), free(s->changed);
    free(s);
}

static double *copy_or_fill(const double *src, dk_index n, double fill)
{
    double *a = malloc(((size_t)n + 1) * sizeof *a);
    if (!a)
        return NULL;
    for (dk_index i = 0; i < n; i++)
        a[i] = src ? src[i] : fill;
    return a;
}

/* The kinematic flags of constraints c. */
static void mark_kinematic(const dk_constraints *c, unsigned char *kin)
{
    for (dk_index v = 0; v < c->n_vertices; v++)
        kin[v] = c->role[v] != DK_VERTEX_FREE;
}

/* Rest: positions y everywhere, velocities 0, plastic states I, frame 0. */
static void reset(dk_shape_matching *s, const double *y)
{
    const size_t N = 3 * (size_t)s->mesh->n_vertices;
    memcpy(s->x, y, N * sizeof *s->x);
    memset(s->v, 0, N * sizeof *s->v);
    memcpy(s->shape, y, N * sizeof *s->shape);
    for (dk_index c = 0; c < s->cl.n_clusters; c++)
        for (int i = 0; i < 9; i++)
            s->sp[9 * (size_t)c + (size_t)i] = i % 4 == 0 ? 1.0 : 0.0;
    s->frame = 0;
    rest_all(s, y);
}

/* The scratch sized by the constraints (the handles' targets). */
static dk_status size_targets(dk_shape_matching *s, const dk_constraints *c, dk_error *err)
{
    double *t = malloc((3 * (size_t)c->n_handle_vertices + 1) * sizeof *t);
    if (!t)
        return dk_error_set(err, DK_ERR_OUT_OF_MEMORY, "ShapeMatching: out of memory (targets)");
    free(s->targets);
    s->targets = t;
    return DK_OK;
}

dk_status dk_shape_matching_bind(const dk_mesh *mesh, const dk_constraint_desc *desc,
                                 const dk_shape_matching_options *options,
                                 dk_shape_matching **out, dk_error *err)
{
    if (out)
        *out = NULL;
    if (!mesh || !desc || !out)
        return dk_error_set(err, DK_ERR_INVALID_ARGUMENT,
                            "ShapeMatching bind: mesh, constraints and output must not be NULL");
    dk_shape_matching_options o;
    if (options)
        o = *options;
    else
        dk_shape_matching_default_options(&o);
    dk_status st = check_options(mesh, &o, err);
    if (st != DK_OK)
        return st;
    dk_progress prog;
    dk_progress_init(&prog, o.progress, o.progress_user, bind_phases, 1, "ShapeMatching bind");
    dk_shape_matching *s = calloc(1, sizeof *s);
    if (!s)
        return dk_error_set(err, DK_ERR_OUT_OF_MEMORY, "ShapeMatching: out of memory (object)");
    const dk_index n = mesh->n_vertices;
    const size_t N = 3 * (size_t)n;
    s->mesh = mesh;
    s->opt = o;
    s->opt.masses = s->opt.alpha_map = s->opt.beta_map = s->opt.damping_map = NULL;
    s->opt.attach_map = NULL;
    s->opt.cluster_sizes = s->opt.cluster_vertices = NULL;
    s->opt.progress = NULL;
    s->opt.progress_user = NULL;
    s->dyn = dynamics_of(&o);
    st = dk_constraints_create_simulated(mesh, desc, &s->con, err);
    if (st == DK_OK)
        st = dk_progress_begin(&prog, 0, err);
    if (st != DK_OK) {
        dk_shape_matching_free(s);
        return st;
    }
    s->kinematic = malloc((size_t)n + 1);
    s->masses = copy_or_fill(o.masses, n, 1.0);
    s->alpha_map = copy_or_fill(o.alpha_map, n, 1.0);
    s->beta_map = copy_or_fill(o.beta_map, n, 1.0);
    s->damping_map = copy_or_fill(o.damping_map, n, 1.0);
    s->attach_map = o.attach_map ? copy_or_fill(o.attach_map, n, 0.0) : NULL;
    s->ka = malloc(((size_t)n + 1) * sizeof *s->ka);
    s->ktot = malloc(((size_t)n + 1) * sizeof *s->ktot);
    s->k = malloc(((size_t)n + 1) * sizeof *s->k);
    s->d = malloc(((size_t)n + 1) * sizeof *s->d);
    s->beta = malloc(((size_t)n + 1) * sizeof *s->beta);
    s->x = malloc((N + 1) * sizeof *s->x);
    s->v = malloc((N + 1) * sizeof *s->v);
    s->shape = malloc((N + 1) * sizeof *s->shape);
    s->goals = malloc((N + 1) * sizeof *s->goals);
    s->work = malloc((6 * N + 1) * sizeof *s->work);
    s->k0 = malloc((N + 1) * sizeof *s->k0);
    s->k1 = malloc((N + 1) * sizeof *s->k1);
    s->u = malloc((N + 1) * sizeof *s->u);
    s->acc = malloc((2 * N + 1) * sizeof *s->acc);
    if (!s->u || !s->acc || !s->ka || !s->ktot || (o.attach_map && !s->attach_map) ||
        !s->kinematic || !s->masses || !s->alpha_map || !s->beta_map || !s->damping_map ||
        !s->k || !s->d || !s->beta || !s->x || !s->v || !s->shape || !s->goals || !s->work ||
        !s->k0 || !s->k1) {
        dk_shape_matching_free(s);
        return dk_error_set(err, DK_ERR_OUT_OF_MEMORY, "ShapeMatching: out of memory (arrays)");
    }
    mark_kinematic(s->con, s->kinematic);
    st = size_targets(s, s->con, err);
    if (st == DK_OK)
        st = sm_attach_build(mesh, s->con, s->kinematic, s->opt.falloff,
                             sm_attach_cap(mesh, &s->opt), s->attach_map,
                             &s->att, err);
    if (st == DK_OK)
        st = sm_clusters_build(mesh, &o, s->masses, s->kinematic, &s->cl, err);
    if (st == DK_OK)
        st = sm_rest_alloc(&s->cl, o.mode == DK_SHAPE_MATCHING_QUADRATIC ? 9 : 3, &s->rest, err);
    if (st == DK_OK) {
        const size_t nm = (size_t)s->cl.start[s->cl.n_clusters], nc = (size_t)s->cl.n_clusters;
        s->member_goal = malloc((3 * nm + 1) * sizeof *s->member_goal);
        s->sp = malloc((9 * nc + 1) * sizeof *s->sp);
        s->fits = malloc((nc + 1) * sizeof *s->fits);
        s->changed = malloc(nc + 1);
        if (!s->member_goal || !s->sp || !s->fits || !s->changed)
            st = dk_error_set(err, DK_ERR_OUT_OF_MEMORY, "ShapeMatching: out of memory (clusters)");
    }
    if (st == DK_OK) {
        s->backup_size = state_bytes(n, s->cl.n_clusters);
        s->backup = malloc(s->backup_size);
        if (!s->backup)
            st = dk_error_set(err, DK_ERR_OUT_OF_MEMORY, "ShapeMatching: out of memory (backup)");
    }
    if (st == DK_OK)
        st = dk_progress_part(&prog, 1.0, err);
    if (st != DK_OK) {
        dk_shape_matching_free(s);
        return st;
    }
    s->team = dk_team_create(); /* NULL: passes run on this thread */
    coefficients(s);
    reset(s, mesh->positions);
    dk_progress_done(&prog);
    *out = s;
    return DK_OK;
}

/* What a rebind builds before it changes anything: freed whole on any failure. */
typedef struct sm_rebuilt {
    unsigned char *backup;
    size_t backup_size;
    dk_constraints *con;
    unsigned char *kinematic;
    sm_attach att;
    double *targets;
    int has_clusters; /* automatic clusters were rebuilt (given ones are kept)             */
    sm_clusters cl;
    sm_rest rest;
    double *member_goal, *sp;
    sm_fit *fits;
    unsigned char *changed;
} sm_rebuilt;

static void rebuilt_free(sm_rebuilt *r)
{
    dk_constraints_free(r->con);
    free(r->kinematic), free(r->targets), free(r->backup);
    sm_attach_free(&r->att);
    if (r->has_clusters) {
        sm_clusters_free(&r->cl);
        sm_rest_free(&r->rest);
    }
    free(r->member_goal), free(r->sp), free(r->fits), free(r->changed);
    memset(r, 0, sizeof *r);
}

/* The clusters' buffers of a rebuild (r->cl built). */
static dk_status cluster_buffers(sm_rebuilt *r, int dim, dk_error *err)
{
    dk_status st = sm_rest_alloc(&r->cl, dim, &r->rest, err);
    if (st != DK_OK)
        return st;
    const size_t nm = (size_t)r->cl.start[r->cl.n_clusters], nc = (size_t)r->cl.n_clusters;
    r->member_goal = malloc((3 * nm + 1) * sizeof *r->member_goal);
    r->sp = malloc((9 * nc + 1) * sizeof *r->sp);
    r->fits = malloc((nc + 1) * sizeof *r->fits);
    r->changed = malloc(nc + 1);
    if (!r->member_goal || !r->sp || !r->fits || !r->changed)
        return dk_error_set(err, DK_ERR_OUT_OF_MEMORY, "ShapeMatching: out of memory (rebind)");
    return DK_OK;
}

/* The solves' backup of a rebuild with nc clusters (on failure the caller frees r). */
static dk_status backup_for(sm_rebuilt *r, dk_index n, dk_index nc, dk_error *err)
{
    r->backup_size = state_bytes(n, nc);
    r->backup = malloc(r->backup_size);
    if (!r->backup)
        return dk_error_set(err, DK_ERR_OUT_OF_MEMORY, "ShapeMatching: out of memory (backup)");
    return DK_OK;
}

/* Builds everything a rebind for `desc` needs (r zeroed; on failure r is freed). */
static dk_status rebuild(const dk_shape_matching *s, const dk_constraint_desc *desc,
                         sm_rebuilt *r, dk_error *err)
{
    const dk_index n = s->mesh->n_vertices;
    dk_status st = dk_constraints_create_simulated(s->mesh, desc, &r->con, err);
    if (st != DK_OK)
        return st;
    r->kinematic = malloc((size_t)n + 1);
    r->targets = malloc((3 * (size_t)r->con->n_handle_vertices + 1) * sizeof *r->targets);
    if (!r->kinematic || !r->targets) {
        rebuilt_free(r);
        return dk_error_set(err, DK_ERR_OUT_OF_MEMORY, "ShapeMatching: out of memory (rebind)");
    }
    mark_kinematic(r->con, r->kinematic);
    st = sm_attach_build(s->mesh, r->con, r->kinematic, s->opt.falloff,
                         sm_attach_cap(s->mesh, &s->opt), s->attach_map,
                         &r->att, err);
    if (st != DK_OK) {
        rebuilt_free(r);
        return st;
    }
    if (s->opt.n_clusters > 0) { /* given clusters are kept: they must cover what is free */
        for (dk_index v = 0; v < n; v++)
            if (!r->kinematic[v] && s->cl.vm_start[v] == s->cl.vm_start[v + 1]) {
                rebuilt_free(r);
                return dk_error_set(err, DK_ERR_INVALID_ARGUMENT,
                                    "ShapeMatching rebind: vertex %d is simulated but lies in "
                                    "no given cluster",
                                    (int)v);
            }
        st = backup_for(r, n, s->cl.n_clusters, err); /* the kept clusters' */
        if (st != DK_OK)
            rebuilt_free(r);
        return st;
    }
    st = sm_clusters_build(s->mesh, &s->opt, s->masses, r->kinematic, &r->cl, err);
    if (st == DK_OK) {
        r->has_clusters = 1;
        st = cluster_buffers(r, s->rest.dim, err);
    }
    if (st == DK_OK)
        st = backup_for(r, n, r->cl.n_clusters, err);
    if (st != DK_OK)
        rebuilt_free(r);
    return st;
}

dk_status dk_shape_matching_rebind(dk_shape_matching *s, const dk_constraint_desc *desc,
                                   dk_error *err)
{
    if (!s || !desc)
        return dk_error_set(err, DK_ERR_INVALID_ARGUMENT,
                            "ShapeMatching rebind: object and constraints must not be NULL");
    dk_progress prog;
    dk_progress_init(&prog, s->rebind_progress, s->rebind_progress_user, bind_phases, 1,
                     "ShapeMatching rebind");
    sm_rebuilt r;
    memset(&r, 0, sizeof r);
    dk_status st = dk_progress_begin(&prog, 0, err);
    if (st == DK_OK)
        st = rebuild(s, desc, &r, err);
    if (st == DK_OK) {
        st = dk_progress_part(&prog, 1.0, err); /* a cancel here keeps the old binding */
        if (st != DK_OK)
            rebuilt_free(&r);
    }
    if (st != DK_OK)
        return st;
    /* install: swap the new parts in, free the old ones through r */
    dk_constraints *oc = s->con;
    unsigned char *ok = s->kinematic;
    double *ot = s->targets;
    const sm_attach oa = s->att;
    s->con = r.con, s->kinematic = r.kinematic, s->targets = r.targets, s->att = r.att;
    r.con = oc, r.kinematic = ok, r.targets = ot, r.att = oa;
    unsigned char *ob = s->backup;
    const size_t obs = s->backup_size;
    s->backup = r.backup, s->backup_size = r.backup_size;
    r.backup = ob, r.backup_size = obs;
    if (r.has_clusters) {
        sm_clusters tc = s->cl;
        sm_rest tr = s->rest;
        double *tg = s->member_goal, *tsp = s->sp;
        sm_fit *tf = s->fits;
        unsigned char *tch = s->changed;
        s->cl = r.cl, s->rest = r.rest, s->member_goal = r.member_goal, s->sp = r.sp;
        s->fits = r.fits, s->changed = r.changed;
        r.cl = tc, r.rest = tr, r.member_goal = tg, r.sp = tsp, r.fits = tf, r.changed = tch;
    }
    rebuilt_free(&r);
    coefficients(s);
    reset(s, s->mesh->positions);
    dk_progress_done(&prog);
    return DK_OK;
}

void dk_shape_matching_set_progress(dk_shape_matching *s, dk_phase_progress_fn fn, void *user)
{
    s->rebind_progress = fn;
    s->rebind_progress_user = user;
}

/* ------------------------------------------------------------------------ solve ------- */

/* This frame's kinematic positions (k1) for goal shape y and the request's targets (already
 * expanded into s->targets). */
static void kinematic_targets(dk_shape_matching *s, const double *y)
{
    const dk_constraints *c = s->con;
    const size_t N = 3 * (size_t)s->mesh->n_vertices;
    memcpy(s->k1, y, N * sizeof *s->k1);
    for (dk_index k = 0; k < c->n_handle_vertices; k++) {
        const dk_index v = c->handle_vertices[k];
        const double w = c->handle_weights[k];
        for (int d = 0; d < 3; d++) {
            const double a = y[3 * (size_t)v + d], t = s->targets[3 * (size_t)k + d];
            s->k1[3 * (size_t)v + d] = w == 1.0 ? t : a + w * (t - a);
        }
    }
}

static double residual(const dk_shape_matching *s, const double *x, const double *member_goal)
{
    double e = 0.0;
    for (dk_index k = 0; k < s->cl.start[s->cl.n_clusters]; k++) {
        const double *g = member_goal + 3 * (size_t)k;
        const double *p = x + 3 * (size_t)s->cl.member_vertex[k];
        const double dx = g[0] - p[0], dy = g[1] - p[1], dz = g[2] - p[2];
        e += s->cl.member_mass[k] * (dx * dx + dy * dy + dz * dz);
    }
    return e;
}

dk_status dk_shape_matching_solve(dk_shape_matching *s, const dk_solve_request *rq,
                                  double *positions, dk_solve_info *info, dk_error *err)
{
    if (!s || !positions)
        return dk_error_set(err, DK_ERR_INVALID_ARGUMENT,
                            "ShapeMatching solve: object and positions must not be NULL");
    const dk_index n = s->mesh->n_vertices;
    dk_status st = dk_solve_request_check_input(rq, n, "ShapeMatching solve", err);
    if (st != DK_OK)
        return st;
    if (rq->start == DK_START_GIVEN) {
        st = dk_start_positions_check(rq->start_positions, n, "ShapeMatching solve", err);
        if (st != DK_OK)
            return st;
    }
    const double *y = rq->input_positions ? rq->input_positions : s->mesh->positions;
    /* the targets, checked before anything changes */
    st = dk_constraints_targets(s->con, y, rq->targets, (int)rq->target_kind, s->targets, err);
    if (st != DK_OK)
        return st;
    const size_t N = 3 * (size_t)n;
    kinematic_targets(s, y);
    /* the object as it was, put back if this solve fails (a non-finite result): a refused
     * or failed solve changes nothing */
    st = dk_shape_matching_save_state(s, s->backup, s->backup_size, err);
    if (st != DK_OK)
        return st;
    int frames = 0;
    if (rq->start == DK_START_COLD || rq->start == DK_START_GIVEN) {
        reset(s, y);
        if (rq->start == DK_START_GIVEN) /* released from these positions, at rest */
            memcpy(s->x, rq->start_positions, N * sizeof *s->x);
        for (dk_index i = 0; i < n; i++)
            if (s->kinematic[i])
                memcpy(s->x + 3 * (size_t)i, s->k1 + 3 * (size_t)i, 3 * sizeof(double));
    } else {
        /* the input's velocity over the frame: the damping is relative to it, so that a
         * part carried by the animation is not dragged behind it */
        const double inv_t = 1.0 / s->dyn.time_step;
        for (size_t j = 0; j < N; j++)
            s->u[j] = (y[j] - s->shape[j]) * inv_t;
        if (y != s->shape && memcmp(y, s->shape, N * sizeof *y) != 0) {
            memcpy(s->shape, y, N * sizeof *y);
            rest_all(s, s->shape);
        }
        memcpy(s->k0, s->x, N * sizeof *s->k0);
        const sm_step step = {.n = n,
                              .kinematic = s->kinematic,
                              .k = s->ktot,
                              .d = s->d,
                              .u = s->u,
                              .gravity = {s->dyn.gravity[0], s->dyn.gravity[1], s->dyn.gravity[2]},
                              .h = s->dyn.time_step / (double)s->opt.substeps};
        const int plastic = s->dyn.plastic_creep > 0.0;
        s->n_sub = s->opt.substeps;
        for (s->substep = 0; s->substep < s->n_sub; s->substep++) {
            s->want_fits = plastic;
            s->tau = 0.0;
            sm_integrate(&step, s->opt.integrator, s->x, s->v, s->goals, goals_of, place, s,
                         s->work);
            if (plastic && sm_plastic_update(&s->cl, &s->rest, s->fits, step.h, &s->dyn,
                                             s->shape, s->mesh->positions, s->sp,
                                             s->changed) > 0)
                for (dk_index c = 0; c < s->cl.n_clusters; c++)
                    if (s->changed[c])
                        sm_rest_compute(&s->cl, s->shape, s->mesh->positions, s->sp, &s->rest,
                                        c, c + 1);
        }
        s->frame++;
        frames = 1;
    }
    memcpy(positions, s->x, N * sizeof *positions);
    double energy = NAN;
    if (!rq->skip_energy) {
        pass p = {.s = s, .x = s->x, .goals = s->goals};
        dk_team_run_halves(s->team, member_part, &p, s->cl.n_clusters, 64);
        energy = residual(s, s->x, s->member_goal);
    }
    if (info) {
        memset(info, 0, sizeof *info);
        info->energy = energy;
        info->iterations = frames * s->opt.substeps;
        info->converged = 1;
    }
    st = dk_solve_result_check(positions, n, energy, !rq->skip_energy, "ShapeMatching solve",
                               err);
    if (st != DK_OK)
        (void)dk_shape_matching_restore_state(s, s->backup, s->backup_size, NULL);
    dk_team_park(s->team);
    return st;
}

/* ------------------------------------------------------------ queries and state ------- */

/* The per-membership goals of `positions` (checked: finite, within DK_COORD_MAX) in a new
 * array (*out, 3 per membership; the caller frees it), for the const queries below. `who`
 * names the query in the messages. */
static dk_status member_goals(const dk_shape_matching *s, const double *positions,
                              double **out, const char *who, dk_error *err)
{
    *out = NULL;
    dk_status st = dk_check_positions(positions, s->mesh->n_vertices, err);
    if (st != DK_OK)
        return st;
    const size_t nm = (size_t)s->cl.start[s->cl.n_clusters];
    double *mg = malloc((3 * nm + 1) * sizeof *mg);
    if (!mg)
        return dk_error_set(err, DK_ERR_OUT_OF_MEMORY, "ShapeMatching %s: out of memory", who);
    sm_goals_clusters(&s->cl, &s->rest, s->opt.mode, s->beta, positions, mg, NULL, NULL, 0,
                      s->cl.n_clusters);
    *out = mg;
    return DK_OK;
}

dk_status dk_shape_matching_energy(const dk_shape_matching *s, const double *positions,
                                   double *energy, dk_error *err)
{
    if (!s || !positions || !energy)
        return dk_error_set(err, DK_ERR_INVALID_ARGUMENT,
                            "ShapeMatching energy: object, positions and energy must not be NULL");
    double *mg;
    dk_status st = member_goals(s, positions, &mg, "energy", err);
    if (st != DK_OK)
        return st;
    *energy = residual(s, positions, mg);
    free(mg);
    return dk_energy_result_check(*energy, "ShapeMatching energy", err);
}

dk_status dk_shape_matching_goals(const dk_shape_matching *s, const double *positions,
                                  double *goals, dk_error *err)
{
    if (!s || !positions || !goals)
        return dk_error_set(err, DK_ERR_INVALID_ARGUMENT,
                            "ShapeMatching goals: object, positions and goals must not be NULL");
    double *mg;
    dk_status st = member_goals(s, positions, &mg, "goals", err);
    if (st != DK_OK)
        return st;
    sm_goals_vertices(&s->cl, mg, positions, goals, 0, s->mesh->n_vertices);
    free(mg);
    return DK_OK;
}

void dk_shape_matching_velocities(const dk_shape_matching *s, double *out)
{
    memcpy(out, s->v, 3 * (size_t)s->mesh->n_vertices * sizeof *out);
}

dk_status dk_shape_matching_set_velocities(dk_shape_matching *s, const double *velocities,
                                           dk_error *err)
{
    if (!s || !velocities)
        return dk_error_set(err, DK_ERR_INVALID_ARGUMENT,
                            "ShapeMatching set_velocities: object and velocities must not be "
                            "NULL");
    for (size_t j = 0; j < 3 * (size_t)s->mesh->n_vertices; j++)
        if (!isfinite(velocities[j]))
            return dk_error_set(err, DK_ERR_NONFINITE,
                                "ShapeMatching set_velocities: vertex %d's velocity is not "
                                "finite",
                                (int)(j / 3));
    memcpy(s->v, velocities, 3 * (size_t)s->mesh->n_vertices * sizeof *s->v);
    return DK_OK;
}

int64_t dk_shape_matching_frame(const dk_shape_matching *s)
{
    return s->frame;
}

dk_index dk_shape_matching_clusters(const dk_shape_matching *s, const dk_index **start,
                                    const dk_index **vertices, const double **shares)
{
    if (shares)
        *shares = s->cl.member_share;
    if (start)
        *start = s->cl.start;
    if (vertices)
        *vertices = s->cl.member_vertex;
    return s->cl.n_clusters;
}

dk_status dk_shape_matching_set_dynamics(dk_shape_matching *s,
                                         const dk_shape_matching_dynamics *dyn, dk_error *err)
{
    if (!s || !dyn)
        return dk_error_set(err, DK_ERR_INVALID_ARGUMENT,
                            "ShapeMatching set_dynamics: object and dynamics must not be NULL");
    dk_status st = check_dynamics(dyn, err);
    if (st != DK_OK)
        return st;
    s->dyn = *dyn;
    coefficients(s);
    return DK_OK;
}

dk_status dk_shape_matching_check_dynamics(const dk_shape_matching_dynamics *dyn, dk_error *err)
{
    if (!dyn)
        return dk_error_set(err, DK_ERR_INVALID_ARGUMENT,
                            "ShapeMatching check_dynamics: dynamics must not be NULL");
    return check_dynamics(dyn, err);
}

void dk_shape_matching_get_dynamics(const dk_shape_matching *s, dk_shape_matching_dynamics *dyn)
{
    *dyn = s->dyn;
}

void dk_shape_matching_stats(const dk_shape_matching *s, dk_method_stats *stats)
{
    memset(stats, 0, sizeof *stats);
    stats->n_vertices = s->mesh->n_vertices;
    stats->n_handles = s->con->n_handles;
    stats->n_handle_vertices = s->con->n_handle_vertices;
    stats->first_held = -1;
}

enum { N_SPANS = 5 };

static void spans_of(const dk_shape_matching *s_const, dk_state_span *sp, uint64_t shape[4])
{
    dk_shape_matching *s = (dk_shape_matching *)s_const; /* save reads what restore writes */
    const size_t N = 3 * (size_t)s->mesh->n_vertices * sizeof(double);
    sp[0] = (dk_state_span){s->x, N};
    sp[1] = (dk_state_span){s->v, N};
    sp[2] = (dk_state_span){s->shape, N};
    sp[3] = (dk_state_span){s->sp, 9 * (size_t)s->cl.n_clusters * sizeof(double)};
    sp[4] = (dk_state_span){&s->frame, sizeof s->frame};
    shape[0] = (uint64_t)s->mesh->n_vertices;
    shape[1] = (uint64_t)s->cl.n_clusters;
    shape[2] = (uint64_t)s->cl.start[s->cl.n_clusters];
    shape[3] = (uint64_t)s->con->n_handle_vertices;
}

size_t dk_shape_matching_state_size(const dk_shape_matching *s)
{
    dk_state_span sp[N_SPANS];
    uint64_t shape[4];
    spans_of(s, sp, shape);
    return dk_state_size(sp, N_SPANS);
}

dk_status dk_shape_matching_save_state(const dk_shape_matching *s, void *state, size_t size,
                                       dk_error *err)
{
    dk_state_span sp[N_SPANS];
    uint64_t shape[4];
    spans_of(s, sp, shape);
    return dk_state_save("ShapeMatching", shape, sp, N_SPANS, state, size, err);
}

dk_status dk_shape_matching_restore_state(dk_shape_matching *s, const void *state, size_t size,
                                          dk_error *err)
{
    dk_state_span sp[N_SPANS];
    uint64_t shape[4];
    spans_of(s, sp, shape);
    dk_status st = dk_state_check("ShapeMatching", shape, sp, N_SPANS, state, size, err);
    if (st != DK_OK)
        return st;
    dk_state_restore_spans(sp, N_SPANS, state);
    rest_all(s, s->shape); /* the rest data of the restored goal shape and plastic states */
    return DK_OK;
}

dk_status dk_shape_matching_estimate_memory(const dk_mesh *mesh,
                                            const dk_shape_matching_options *options,
                                            uint64_t *bytes, dk_error *err)
{
    if (!mesh || !bytes)
        return dk_error_set(err, DK_ERR_INVALID_ARGUMENT,
                            "ShapeMatching estimate_memory: mesh and bytes must not be NULL");
    dk_status st = options ? check_options(mesh, options, err) : DK_OK;
    if (st != DK_OK)
        return st;
    const int quad = options && options->mode == DK_SHAPE_MATCHING_QUADRATIC;
    /* 8 memberships a vertex: offsets (3 or 9), goals (3), mass, share, two indices; the
     * bind's sort of 8 (key, vertex) pairs; the vertex arrays (x, v, shape, goals, 6 of
     * RK4's stages, two kinematic ends: 14 x 3 doubles; 7 per-vertex doubles); the
     * attachments (strength, row start, about two sources of index and share, and the
     * build's nearest-vertex queries: ~80 B) */
    const double per_vertex = 8.0 * (8.0 * (quad ? 9 : 3) + 24.0 + 8.0 + 8.0 + 8.0) +
                              8.0 * 16.0 + 14.0 * 24.0 + 7.0 * 8.0 + 80.0;
    *bytes = dk_memory_model(per_vertex, (double)mesh->n_vertices, 0.0);
    return DK_OK;
}

/* the options' fields (dk_option_desc): where each is, what values bind takes */
static const dk_option_desc shape_matching_fields[] = {
    {"mode", DK_OPTION_ENUM, offsetof(dk_shape_matching_options, mode), 0, 0, 2, 1, 2, 0},
    {"alpha", DK_OPTION_DOUBLE, offsetof(dk_shape_matching_options, alpha), 0, 0.0, 1.0, 0.3,
     1.0, 0},
    {"beta", DK_OPTION_DOUBLE, offsetof(dk_shape_matching_options, beta), 0, 0.0, 1.0, 0.3, 1.0,
     0},
    {"damping", DK_OPTION_DOUBLE, offsetof(dk_shape_matching_options, damping), 0, 0.0, DBL_MAX,
     4.0, DBL_MAX, 0},
    {"gravity_x", DK_OPTION_DOUBLE, offsetof(dk_shape_matching_options, gravity_x), 0, -DBL_MAX,
     DBL_MAX, 0.0, DBL_MAX, 0},
    {"gravity_y", DK_OPTION_DOUBLE, offsetof(dk_shape_matching_options, gravity_y), 0, -DBL_MAX,
     DBL_MAX, 0.0, DBL_MAX, 0},
    {"gravity_z", DK_OPTION_DOUBLE, offsetof(dk_shape_matching_options, gravity_z), 0, -DBL_MAX,
     DBL_MAX, -9.81, DBL_MAX, 0},
    {"time_step", DK_OPTION_DOUBLE, offsetof(dk_shape_matching_options, time_step), 0, 1e-6,
     3600.0, 1.0 / 24.0, 3600.0, 0},
    {"substeps", DK_OPTION_INT, offsetof(dk_shape_matching_options, substeps), 0, 1, 64, 2, 8, 0},
    {"integrator", DK_OPTION_ENUM, offsetof(dk_shape_matching_options, integrator), 0, 0, 3, 0, 3,
     0},
    {"clusters", DK_OPTION_ENUM, offsetof(dk_shape_matching_options, clusters), 0, 0, 1, 0, 1, 0},
    {"cluster_size", DK_OPTION_DOUBLE, offsetof(dk_shape_matching_options, cluster_size), 0,
     DBL_TRUE_MIN, DBL_MAX, 0.25, DBL_MAX, DK_OPTION_LENGTH | DK_OPTION_ZERO_AUTO},
    {"falloff", DK_OPTION_DOUBLE, offsetof(dk_shape_matching_options, falloff), 0, DBL_TRUE_MIN,
     DBL_MAX, 0.1, DBL_MAX, DK_OPTION_LENGTH | DK_OPTION_ZERO_AUTO},
    {"plastic_yield", DK_OPTION_DOUBLE, offsetof(dk_shape_matching_options, plastic_yield), 0,
     0.0, DBL_MAX, 0.1, DBL_MAX, 0},
    {"plastic_creep", DK_OPTION_DOUBLE, offsetof(dk_shape_matching_options, plastic_creep), 0,
     0.0, DBL_MAX, 1.0, DBL_MAX, 0},
    {"plastic_max", DK_OPTION_DOUBLE, offsetof(dk_shape_matching_options, plastic_max), 0, 0.0,
     DBL_MAX, 1.0, DBL_MAX, 0},
    {"masses", DK_OPTION_VERTEX_VALUES, offsetof(dk_shape_matching_options, masses),
     offsetof(dk_shape_matching_options, n_masses), DBL_MIN, 1e100, 1.0, 1e100, 0},
    {"alpha_map", DK_OPTION_VERTEX_VALUES, offsetof(dk_shape_matching_options, alpha_map),
     offsetof(dk_shape_matching_options, n_alpha_map), 0.0, 1.0, 1.0, 1.0, 0},
    {"beta_map", DK_OPTION_VERTEX_VALUES, offsetof(dk_shape_matching_options, beta_map),
     offsetof(dk_shape_matching_options, n_beta_map), 0.0, 1.0, 1.0, 1.0, 0},
    {"damping_map", DK_OPTION_VERTEX_VALUES, offsetof(dk_shape_matching_options, damping_map),
     offsetof(dk_shape_matching_options, n_damping_map), 0.0, DBL_MAX, 1.0, DBL_MAX, 0},
    {"attach_map", DK_OPTION_VERTEX_VALUES, offsetof(dk_shape_matching_options, attach_map),
     offsetof(dk_shape_matching_options, n_attach_map), 0.0, 1.0, 0.5, 1.0, 0},
};

DK_METHOD_OPS_STATEFUL(dk_shape_matching_ops, "ShapeMatching",
                       DK_METHOD_ITERATIVE | DK_METHOD_GIVEN_START | DK_METHOD_EDITS_INPUT |
                           DK_METHOD_DYNAMIC,
                       DK_CONTROL_VERTEX_GROUPS, dk_shape_matching, dk_shape_matching,
                       dk_shape_matching_options, shape_matching_fields);
