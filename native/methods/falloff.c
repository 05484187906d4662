/* DeformKit: attenuated handle displacement. See dk_falloff.h for what is computed. Per
 * handle group g the bind stores, for every vertex, its distance from g, its nearest vertex
 * of g (position in the concatenated handle list) and its weight S; a solve is one pass. */
#include "dk_falloff.h"

#include <float.h>
#include <limits.h>
#include <math.h>
#include <stdlib.h>
#include <string.h>

#include "dk_operators.h"

typedef struct falloff_state {
    dk_constraints *con;
    double *dist;    /* n_handles x n: distance (INFINITY = unreachable)               */
    double *weight;  /* n_handles x n: S, 0 where unaffected                           */
    dk_index *label; /* n_handles x n: nearest handle-vertex position, -1 if none      */
    double *targets; /* n_handle_vertices x 3                                         */
    dk_index *hpos;  /* n: position of a handle vertex in the handle list, or -1       */
    double *range;   /* n_handles: the range each group uses (units of the distance)   */
} falloff_state;

struct dk_falloff {
    const dk_mesh *mesh;
    dk_falloff_options opt;
    double unit;     /* 1 for hops, the mean edge length otherwise                    */
    dk_heat_geodesic *heat;
    falloff_state st;
    dk_progress *prog; /* during a bind or rebind only (NULL otherwise) */
};

/* The phases of a bind (dk_progress.h), weighted by their cost measured on the 692k-vertex
 * armadillo (scripts/bench_scale.py's armadillo-wave, 2 subdivisions, one handle) on the
 * shared 2-core machine, in seconds: geodesic binds 42 s, of which the heat method's
 * factorization (dk_heat_create, uninterruptible) all but the 3.3 s its rebind takes; the
 * other distances have the distances phase only (hops 1.1 s, euclidean 5-9 s). Within it,
 * each handle group has an equal share, half of it the labelled search (asked every 8192
 * vertices it settles), the rest its distance (one call of the operator, uninterruptible)
 * and weights. */
static const dk_progress_phase geodesic_phases[] = {{"heat", 39.0}, {"distances", 3.3}};
static const dk_progress_phase distance_phases[] = {{"distances", 1.0}};

static void state_free(falloff_state *s)
{
    dk_constraints_free(s->con);
    free(s->dist);
    free(s->weight);
    free(s->label);
    free(s->targets);
    free(s->hpos);
    free(s->range);
    memset(s, 0, sizeof *s);
}

void dk_falloff_default_options(dk_falloff_options *o)
{
    if (!o)
        return;
    o->distance = DK_FALLOFF_EUCLIDEAN;
    o->range = 0.0;
    o->reach = DK_FALLOFF_REACH_FIXED;
    o->k = 0.0;
    o->heat_time_factor = 0.0;
    o->progress = NULL;
    o->progress_user = NULL;
}

double dk_falloff_profile(double i, double n, double k)
{
    double t;
    if (!isfinite(i) || i > n)
        return 0.0;
    if (i < 0.0)
        i = 0.0;
    t = i / (n + 1.0);
    if (k >= 0.0)
        return 1.0 - pow(t, k + 1.0);
    return pow(1.0 - t, 1.0 - k);
}

/* ------------------------------------------------------------------ bind ---------------- */

static dk_status group_distances(dk_falloff *f, falloff_state *s, dk_index g, double *dist,
                                 dk_index *label, dk_index *scratch_i, double *scratch_d,
                                 double *scratch_e, dk_error *err)
{
    const dk_mesh *m = f->mesh;
    const dk_index n = m->n_vertices;
    const dk_index b = s->con->handle_start[g], e = s->con->handle_start[g + 1];
    const dk_index *src = s->con->handle_vertices + b;
    const dk_index G = s->con->n_handles;
    dk_status st;

    switch (f->opt.distance) {
    case DK_FALLOFF_HOPS:
        st = dk_labelled_search(m, src, e - b, b, 1, scratch_d, scratch_e, label, f->prog, g, G,
                                err);
        if (st == DK_OK)
            st = dk_progress_part(f->prog, (g + 0.5) / G, err);
        if (st != DK_OK)
            return st;
        st = dk_hop_distance(m, src, e - b, scratch_i, err);
        if (st != DK_OK)
            return dk_error_prefix(err, "Falloff hop distance");
        for (dk_index v = 0; v < n; v++)
            dist[v] = scratch_i[v] < 0 ? INFINITY : (double)scratch_i[v];
        return DK_OK;
    case DK_FALLOFF_DIJKSTRA:
    case DK_FALLOFF_GEODESIC:
        st = dk_labelled_search(m, src, e - b, b, 0, scratch_d, scratch_e, label, f->prog, g, G,
                                err);
        if (st == DK_OK)
            st = dk_progress_part(f->prog, (g + 0.5) / G, err);
        if (st != DK_OK)
            return st;
        if (f->opt.distance == DK_FALLOFF_DIJKSTRA)
            st = dk_geodesic_dijkstra(m, src, e - b, dist, err);
        else
            st = dk_heat_distance(f->heat, src, e - b, dist, err);
        if (st != DK_OK)
            return dk_error_prefix(err, "Falloff geodesic distance");
        return DK_OK;
    case DK_FALLOFF_EUCLIDEAN: {
        dk_kdtree *tree = NULL;
        double *pts = malloc(sizeof(double) * 3 * (size_t)(e - b));
        if (!pts)
            return dk_error_set(err, DK_ERR_OUT_OF_MEMORY, "Falloff: out of memory (points)");
        for (dk_index k = b; k < e; k++)
            memcpy(pts + 3 * (k - b), m->positions + 3 * s->con->handle_vertices[k],
                   sizeof(double) * 3);
        st = dk_kdtree_create(pts, e - b, &tree, err);
        free(pts);
        if (st != DK_OK)
            return dk_error_prefix(err, "Falloff k-d tree");
        st = dk_kdtree_knn(tree, m->positions, n, 1, scratch_i, dist, err);
        dk_kdtree_free(tree);
        if (st != DK_OK)
            return dk_error_prefix(err, "Falloff nearest handle vertex");
        for (dk_index v = 0; v < n; v++) {
            dist[v] = sqrt(dist[v]);
            label[v] = b + scratch_i[v];
        }
        return DK_OK;
    }
    }
    return dk_error_set(err, DK_ERR_INTERNAL, "Falloff: unknown distance kind");
}

/* The range of one group with distances `dist`: `range`, or (REACH_FIXED) the distance to
 * its nearest fixed vertex when it reaches one at a positive distance. */
static double group_reach(const dk_falloff *f, const falloff_state *s, const double *dist)
{
    if (f->opt.reach != DK_FALLOFF_REACH_FIXED)
        return f->opt.range;
    /* the fixed vertices the caller gave (and the region's outside), not loose geometry the
     * constraints hold at rest: an eyeball near the handle must not become its range */
    double r = INFINITY;
    const unsigned char *held = s->con->held;
    for (dk_index v = 0; v < f->mesh->n_vertices; v++)
        if (s->con->role[v] == DK_VERTEX_FIXED && !(held && held[v]) && dist[v] < r)
            r = dist[v];
    return isfinite(r) && r > 0.0 ? r : f->opt.range;
}

static dk_status build_state(dk_falloff *f, const dk_constraint_desc *desc, falloff_state *s,
                             dk_error *err)
{
    const dk_mesh *m = f->mesh;
    const dk_index n = m->n_vertices;
    dk_index *scratch_i = NULL;
    double *scratch_d = NULL, *scratch_e = NULL;
    size_t gn;
    dk_status st;

    memset(s, 0, sizeof *s);
    if (!desc)
        return dk_error_set(err, DK_ERR_INVALID_ARGUMENT, "Falloff: constraints are NULL");
    st = dk_constraints_create(m, desc, &s->con, err);
    if (st != DK_OK)
        return dk_error_prefix(err, "Falloff");
    gn = (size_t)s->con->n_handles * (size_t)n;
    s->dist = malloc(sizeof(double) * gn);
    s->weight = malloc(sizeof(double) * gn);
    s->label = malloc(sizeof(dk_index) * gn);
    s->targets = malloc(sizeof(double) * 3 * ((size_t)s->con->n_handle_vertices + 1));
    s->hpos = malloc(sizeof(dk_index) * ((size_t)n + 1));
    s->range = malloc(sizeof(double) * ((size_t)s->con->n_handles + 1));
    scratch_i = malloc(sizeof(dk_index) * ((size_t)n + 1));
    scratch_d = malloc(sizeof(double) * ((size_t)n + 1));
    scratch_e = malloc(sizeof(double) * ((size_t)n + 1));
    if (!s->dist || !s->weight || !s->label || !s->targets || !s->hpos || !s->range ||
        !scratch_i || !scratch_d || !scratch_e) {
        st = dk_error_set(err, DK_ERR_OUT_OF_MEMORY, "Falloff: out of memory (weights)");
        goto done;
    }
    for (dk_index v = 0; v < n; v++)
        s->hpos[v] = -1;
    for (dk_index k = 0; k < s->con->n_handle_vertices; k++)
        s->hpos[s->con->handle_vertices[k]] = k;
    for (dk_index g = 0; g < s->con->n_handles; g++) {
        double *dist = s->dist + (size_t)g * n, *w = s->weight + (size_t)g * n;
        st = dk_progress_part(f->prog, (double)g / s->con->n_handles, err);
        if (st == DK_OK)
            st = group_distances(f, s, g, dist, s->label + (size_t)g * n, scratch_i, scratch_d,
                                 scratch_e, err);
        if (st == DK_OK)
            st = dk_progress_part(f->prog, (g + 0.9) / s->con->n_handles, err);
        if (st != DK_OK)
            goto done;
        s->range[g] = group_reach(f, s, dist);
        for (dk_index v = 0; v < n; v++)
            w[v] = s->con->role[v] == DK_VERTEX_FREE
                       ? dk_falloff_profile(dist[v] / f->unit, s->range[g] / f->unit, f->opt.k)
                       : 0.0;
    }
    st = DK_OK;
done:
    free(scratch_i);
    free(scratch_d);
    free(scratch_e);
    if (st != DK_OK)
        state_free(s);
    return st;
}

/* The options a bind accepts (the estimate refuses the same). */
static dk_status check_options(const dk_falloff_options *o, dk_error *err)
{
    if (o->distance != DK_FALLOFF_HOPS && o->distance != DK_FALLOFF_EUCLIDEAN &&
        o->distance != DK_FALLOFF_GEODESIC && o->distance != DK_FALLOFF_DIJKSTRA)
        return dk_error_set(err, DK_ERR_INVALID_ARGUMENT,
                            "Falloff bind: unknown distance kind %d (hops = 0, euclidean = 1, "
                            "geodesic = 2, dijkstra = 3)", (int)o->distance);
    if (!(isfinite(o->range) && o->range >= 0.0))
        return dk_error_set(err, DK_ERR_INVALID_ARGUMENT,
                            "Falloff bind: range must be finite and > 0 (0 = default), got %g",
                            o->range);
    if (o->reach != DK_FALLOFF_REACH_RANGE && o->reach != DK_FALLOFF_REACH_FIXED)
        return dk_error_set(err, DK_ERR_INVALID_ARGUMENT,
                            "Falloff bind: unknown reach %d (range = 0, fixed = 1)",
                            (int)o->reach);
    if (!isfinite(o->k))
        return dk_error_set(err, DK_ERR_INVALID_ARGUMENT,
                            "Falloff bind: k must be finite, got %g", o->k);
    if (!isfinite(o->heat_time_factor)) /* whatever the distance: a value that cannot work */
        return dk_error_set(err, DK_ERR_INVALID_ARGUMENT,
                            "Falloff bind: heat_time_factor must be finite (<= 0: the "
                            "default), got %g", o->heat_time_factor);
    return DK_OK;
}

dk_status dk_falloff_bind(const dk_mesh *mesh, const dk_constraint_desc *desc,
                          const dk_falloff_options *options, dk_falloff **out, dk_error *err)
{
    dk_falloff *f;
    dk_status st;
    dk_progress prog;

    if (!out)
        return dk_error_set(err, DK_ERR_INVALID_ARGUMENT, "Falloff bind: out is NULL");
    *out = NULL;
    if (!mesh || !desc)
        return dk_error_set(err, DK_ERR_INVALID_ARGUMENT,
                            "Falloff bind: mesh or constraints are NULL");
    f = calloc(1, sizeof *f);
    if (!f)
        return dk_error_set(err, DK_ERR_OUT_OF_MEMORY, "Falloff bind: out of memory");
    f->mesh = mesh;
    if (options)
        f->opt = *options;
    else
        dk_falloff_default_options(&f->opt);
    if ((st = check_options(&f->opt, err)) != DK_OK)
        goto fail;
    f->unit = 1.0;
    if (f->opt.distance != DK_FALLOFF_HOPS) {
        if (!(mesh->mean_edge_length > 0.0)) {
            st = dk_error_set(err, DK_ERR_DEGENERATE,
                              "Falloff bind: metric distances need edges of non-zero length "
                              "(the mesh's mean edge length is %g)", mesh->mean_edge_length);
            goto fail;
        }
        f->unit = mesh->mean_edge_length;
    }
    if (f->opt.range == 0.0) { /* a quarter of the model's size (hops: in mean edge lengths) */
        const double len = DK_FALLOFF_AUTO_RANGE * mesh->bbox_diagonal;
        f->opt.range = f->opt.distance == DK_FALLOFF_HOPS
                           ? fmax(1.0, round(len / fmax(mesh->mean_edge_length, 1e-300)))
                           : (len > 0.0 ? len : 10.0 * f->unit);
    }
    {
        const int geo = f->opt.distance == DK_FALLOFF_GEODESIC;
        dk_progress_init(&prog, f->opt.progress, f->opt.progress_user,
                         geo ? geodesic_phases : distance_phases, geo ? 2 : 1, "Falloff bind");
        f->opt.progress = NULL; /* the caller's callback is for this bind only */
        f->opt.progress_user = NULL;
        f->prog = &prog;
        st = dk_progress_begin(&prog, 0, err);
        if (st != DK_OK)
            goto fail;
    }
    if (f->opt.distance == DK_FALLOFF_GEODESIC) {
        if (mesh->n_faces == 0) {
            st = dk_error_set(err, DK_ERR_DEGENERATE,
                              "Falloff bind: geodesic (heat) distance needs triangles");
            goto fail;
        }
        st = dk_heat_create(mesh, f->opt.heat_time_factor, &f->heat, err);
        if (st != DK_OK) {
            dk_error_prefix(err, "Falloff bind");
            goto fail;
        }
        st = dk_progress_begin(&prog, 1, err); /* distances */
        if (st != DK_OK)
            goto fail;
    }
    st = build_state(f, desc, &f->st, err);
    if (st != DK_OK)
        goto fail;
    f->prog = NULL;
    dk_progress_done(&prog);
    *out = f;
    return DK_OK;
fail:
    dk_falloff_free(f);
    return st;
}

dk_status dk_falloff_rebind(dk_falloff *f, const dk_constraint_desc *desc, dk_error *err)
{
    falloff_state s;
    dk_status st;
    if (!f)
        return dk_error_set(err, DK_ERR_INVALID_ARGUMENT, "Falloff rebind: object is NULL");
    dk_progress prog;
    dk_progress_init(&prog, f->opt.progress, f->opt.progress_user, distance_phases, 1,
                     "Falloff rebind");
    f->prog = &prog;
    st = dk_progress_begin(&prog, 0, err);
    if (st == DK_OK)
        st = build_state(f, desc, &s, err);
    f->prog = NULL;
    if (st != DK_OK)
        return st;
    dk_progress_done(&prog);
    state_free(&f->st);
    f->st = s;
    return DK_OK;
}

void dk_falloff_set_progress(dk_falloff *f, dk_phase_progress_fn progress, void *user)
{
    if (!f)
        return;
    f->opt.progress = progress;
    f->opt.progress_user = progress ? user : NULL;
}

/* ------------------------------------------------------------------ solve --------------- */

dk_status dk_falloff_solve(dk_falloff *f, const dk_solve_request *rq, double *positions,
                           dk_solve_info *info, dk_error *err)
{
    const dk_mesh *m;
    const falloff_state *s;
    dk_index n;
    double e = 0.0;
    dk_status st;

    if (info)
        memset(info, 0, sizeof *info);
    if (!f || !positions)
        return dk_error_set(err, DK_ERR_INVALID_ARGUMENT,
                            "Falloff solve: NULL object or positions");
    st = dk_solve_request_check_input(rq, f->mesh->n_vertices, "Falloff solve", err);
    if (st != DK_OK)
        return st;
    const double *targets = rq->targets;
    const int mode = (int)rq->target_kind;
    m = f->mesh;
    s = &f->st;
    n = m->n_vertices;
    /* the pose this solve edits: the request's input, or the rest */
    const double *base = rq->input_positions ? rq->input_positions : m->positions;
    /* validates (finiteness, affine bottom row) and expands to per-vertex targets */
    st = dk_constraints_targets(s->con, base, targets, mode, s->targets, err);
    if (st != DK_OK)
        return dk_error_prefix(err, "Falloff solve");
    for (dk_index v = 0; v < n; v++) {
        const double *p = base + 3 * v;
        const dk_index role = s->con->role[v];
        double dsp[3] = {0.0, 0.0, 0.0};
        if (role >= 0) {
            /* a handle vertex: its own (weighted) displacement */
            const dk_index k = s->hpos[v];
            if (k >= 0)
                for (int d = 0; d < 3; d++)
                    dsp[d] = s->con->handle_weights[k] * (s->targets[3 * k + d] - p[d]);
        } else if (role == DK_VERTEX_FREE) {
            for (dk_index g = 0; g < s->con->n_handles; g++) {
                const double w = s->weight[(size_t)g * n + v];
                if (w == 0.0)
                    continue;
                if (mode == 0) {
                    const dk_index l = s->label[(size_t)g * n + v];
                    const double *pl;
                    if (l < 0)
                        continue;
                    pl = base + 3 * s->con->handle_vertices[l];
                    for (int d = 0; d < 3; d++)
                        dsp[d] += w * s->con->handle_weights[l] * (s->targets[3 * l + d] - pl[d]);
                } else {
                    const double *t = targets + 16 * (size_t)g;
                    const dk_index l = s->label[(size_t)g * n + v];
                    const double ww = w * (l >= 0 ? s->con->handle_weights[l] : 1.0);
                    for (int d = 0; d < 3; d++)
                        dsp[d] += ww * (t[4 * d] * p[0] + t[4 * d + 1] * p[1] +
                                       t[4 * d + 2] * p[2] + t[4 * d + 3] - p[d]);
                }
            }
        }
        for (int d = 0; d < 3; d++) {
            positions[3 * v + d] = p[d] + dsp[d];
            e += dsp[d] * dsp[d];
        }
    }
    st = dk_solve_result_check(positions, n, e, !rq->skip_energy, "Falloff solve", err);
    if (st != DK_OK)
        return st;
    if (info) {
        info->energy = rq->skip_energy ? NAN : e;
        info->iterations = 1;
        info->converged = 1;
    }
    return DK_OK;
}

dk_status dk_falloff_energy(const dk_falloff *f, const double *positions, double *energy,
                            dk_error *err)
{
    if (energy)
        *energy = NAN;
    if (!f || !positions || !energy)
        return dk_error_set(err, DK_ERR_INVALID_ARGUMENT,
                            "Falloff energy: object, positions and energy must not be NULL");
    const double *rest = f->mesh->positions;
    double e = 0.0;
    for (size_t i = 0; i < 3 * (size_t)f->mesh->n_vertices; i++) {
        const double d = positions[i] - rest[i];
        e += d * d;
    }
    *energy = e;
    return dk_energy_result_check(e, "Falloff energy", err);
}

/* ------------------------------------------------------------------ accessors ----------- */

void dk_falloff_vertex_weight(const dk_falloff *f, dk_index g, dk_index v, double *distance,
                              double *weight)
{
    double d = INFINITY, w = 0.0;
    if (f && f->st.con && g >= 0 && g < f->st.con->n_handles && v >= 0 &&
        v < f->mesh->n_vertices) {
        d = f->st.dist[(size_t)g * f->mesh->n_vertices + v];
        w = f->st.weight[(size_t)g * f->mesh->n_vertices + v];
    }
    if (distance)
        *distance = d;
    if (weight)
        *weight = w;
}

double dk_falloff_group_range(const dk_falloff *f, dk_index g)
{
    if (!f || g < 0 || g >= f->st.con->n_handles)
        return NAN;
    return f->st.range[g];
}

void dk_falloff_stats(const dk_falloff *f, dk_method_stats *st)
{
    if (!st)
        return;
    memset(st, 0, sizeof *st);
    if (!f)
        return;
    st->n_vertices = f->mesh->n_vertices;
    st->n_handles = f->st.con ? f->st.con->n_handles : 0;
    st->n_handle_vertices = f->st.con ? f->st.con->n_handle_vertices : 0;
    dk_constraints_held_stats(f->st.con, NULL, st);
    st->factorization_count = f->heat ? dk_heat_factorization_count(f->heat) : 0;
}

void dk_falloff_free(dk_falloff *f)
{
    if (!f)
        return;
    state_free(&f->st);
    dk_heat_free(f->heat);
    free(f);
}

/* ---------------------------------------------------------------- the method contract --- */

/* the contract's table (dk_method.h): the adapters cast to this method's types */
dk_status dk_falloff_estimate_memory(const dk_mesh *mesh, const dk_falloff_options *options,
                                     uint64_t *bytes, dk_error *err)
{
    if (!mesh || !bytes)
        return dk_error_set(err, DK_ERR_INVALID_ARGUMENT,
                            "Falloff estimate_memory: mesh and bytes must not be NULL");
    dk_status st = options ? check_options(options, err) : DK_OK; /* what bind refuses */
    if (st != DK_OK)
        return st;
    /* measured 34 B/vertex at 43k, 70 at 692k */
    *bytes = dk_memory_model(80.0, (double)mesh->n_vertices, 0.0);
    return DK_OK;
}

/* the options' fields (dk_option_desc): where each is, what values bind takes */
static const dk_option_desc falloff_fields[] = {
    {"distance", DK_OPTION_ENUM, offsetof(dk_falloff_options, distance), 0, 0, 3, 1, 3, 0},
    {"range", DK_OPTION_DOUBLE, offsetof(dk_falloff_options, range), 0, DBL_TRUE_MIN, DBL_MAX,
     0.3, DBL_MAX, DK_OPTION_LENGTH | DK_OPTION_ZERO_AUTO},
    {"reach", DK_OPTION_ENUM, offsetof(dk_falloff_options, reach), 0, 0, 1, 1, 1, 0},
    {"k", DK_OPTION_DOUBLE, offsetof(dk_falloff_options, k), 0, -DBL_MAX, DBL_MAX, 1.0, DBL_MAX,
     0},
    {"heat_time_factor", DK_OPTION_DOUBLE, offsetof(dk_falloff_options, heat_time_factor), 0,
     -DBL_MAX, DBL_MAX, 1.0, DBL_MAX, 0},
};

DK_METHOD_OPS(dk_falloff_ops, "Falloff",
              DK_METHOD_EDITS_INPUT,
              DK_CONTROL_VERTEX_GROUPS, dk_falloff, dk_falloff, dk_falloff_options,
              falloff_fields);
