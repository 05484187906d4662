/* DeformKit Shepard interpolation of the handles' motion (see dk_shepard.h). */
#include "dk_shepard.h"

#include <float.h>
#include <math.h>
#include <stddef.h>
#include <stdint.h>
#include <stdlib.h>
#include <string.h>

#include "dk_memory.h"
#include "dk_operators.h"

/* The weights of one bind: per vertex and group (handles, then the fixed vertices) the
 * normalised weight, the distance and the group's nearest vertex (dense: groups are few;
 * constrained vertices have weights 0). */
typedef struct shepard_weights {
    dk_constraints *con;
    dk_index n_groups;
    int has_fixed;    /* the last group is the fixed vertices                              */
    double *w;        /* n x n_groups                                                       */
    double *dist;     /* n x n_groups                                                       */
    dk_index *label;  /* n x n_groups: the group's nearest vertex's place among the handle
                         vertices (handle groups), -1 for the fixed group                    */
    dk_index *hpos;   /* n_vertices: place among the handle vertices, or -1                 */
    double *targets;  /* n_handle_vertices x 3: a solve's expanded targets (scratch)        */
} shepard_weights;

struct dk_shepard {
    const dk_mesh *mesh;
    dk_shepard_options opt;
    double radius;          /* RADIUS: the bind's radius (auto resolved)                   */
    dk_heat_geodesic *heat; /* GEODESIC: the heat method's factors (kept for rebinds)      */
    shepard_weights sw;
};

static const dk_progress_phase weight_phases[] = {{"weights", 1.0}};

void dk_shepard_default_options(dk_shepard_options *o)
{
    memset(o, 0, sizeof *o);
    o->power = 2.0;
    o->neighbourhood = DK_SHEPARD_ALL;
    o->k = 4;
    o->radius = 0.0;
    o->interpolate = DK_SHEPARD_TRANSFORMS;
    o->distance = DK_SHEPARD_EUCLIDEAN;
}

static void weights_free(shepard_weights *sw)
{
    dk_constraints_free(sw->con);
    free(sw->w);
    free(sw->dist);
    free(sw->label);
    free(sw->hpos);
    free(sw->targets);
    memset(sw, 0, sizeof *sw);
}

static dk_status check_options(const dk_shepard_options *o, dk_error *err)
{
    if (!(isfinite(o->power) && o->power > 0.0 && o->power <= 64.0))
        return dk_error_set(err, DK_ERR_INVALID_ARGUMENT,
                            "Shepard: power must be in (0, 64], got %g", o->power);
    if (o->neighbourhood != DK_SHEPARD_NEAREST && o->neighbourhood != DK_SHEPARD_ALL &&
        o->neighbourhood != DK_SHEPARD_RADIUS)
        return dk_error_set(err, DK_ERR_INVALID_ARGUMENT,
                            "Shepard: neighbourhood %d is not all (0), nearest (1) or radius "
                            "(2)", (int)o->neighbourhood);
    if (o->k < 1 || o->k > 1024)
        return dk_error_set(err, DK_ERR_INVALID_ARGUMENT,
                            "Shepard: k must be in 1 .. 1024, got %d", o->k);
    if (!(isfinite(o->radius) && o->radius >= 0.0))
        return dk_error_set(err, DK_ERR_INVALID_ARGUMENT,
                            "Shepard: radius must be finite and > 0 (0 = auto), got %g",
                            o->radius);
    if (o->distance != DK_SHEPARD_EUCLIDEAN && o->distance != DK_SHEPARD_GEODESIC)
        return dk_error_set(err, DK_ERR_INVALID_ARGUMENT,
                            "Shepard: distance %d is not euclidean (0) or geodesic (1)",
                            (int)o->distance);
    if (o->interpolate != DK_SHEPARD_TRANSFORMS && o->interpolate != DK_SHEPARD_DISPLACEMENTS)
        return dk_error_set(err, DK_ERR_INVALID_ARGUMENT,
                            "Shepard: interpolate %d is not transforms (0) or displacements "
                            "(1)", (int)o->interpolate);
    return DK_OK;
}

/* One vertex's weights from its distances d to the groups (g groups): the neighbourhood's
 * rule, normalised into w (zeros outside it). Each weight is scaled by the nearest
 * distance's d_0^p so that no power overflows; a vertex on a group takes it alone (the
 * first such). `order`: scratch of g indices. */
static void vertex_weights(const dk_shepard *s, const double *d, dk_index g, double *w,
                           dk_index *order)
{
    for (dk_index i = 0; i < g; i++) { /* insertion sort by distance: groups are few */
        dk_index j = i;
        while (j > 0 && d[order[j - 1]] > d[i]) {
            order[j] = order[j - 1];
            j--;
        }
        order[j] = i;
    }
    memset(w, 0, (size_t)g * sizeof *w);
    if (g == 0 || !isfinite(d[order[0]]))
        return;
    if (d[order[0]] == 0.0) {
        w[order[0]] = 1.0;
        return;
    }
    const double p = s->opt.power, d0 = d[order[0]];
    dk_index m = g;
    double R = INFINITY;
    if (s->opt.neighbourhood == DK_SHEPARD_NEAREST) {
        m = s->opt.k < g ? s->opt.k : g;
        if (m < g)
            R = d[order[m]];
    } else if (s->opt.neighbourhood == DK_SHEPARD_RADIUS) {
        m = s->opt.k < g ? s->opt.k : g;
        R = s->radius;
    }
    double sum = 0.0;
    for (int pass = 0; pass < 2 && !(sum > 0.0); pass++) {
        /* a second pass without the cut-off when every one sat at it (ties at R) */
        const double Rp = pass ? INFINITY : R;
        if (pass && s->opt.neighbourhood == DK_SHEPARD_RADIUS)
            break; /* beyond the radius of every group: it stays */
        for (dk_index i = 0; i < m; i++) {
            const dk_index k = order[i];
            double wi = pow(d0 / d[k], p);
            if (isfinite(Rp))
                wi *= pow(fmax(Rp - d[k], 0.0) / Rp, p);
            w[k] = wi;
            sum += wi;
        }
    }
    if (!(sum > 0.0)) {
        memset(w, 0, (size_t)g * sizeof *w);
        return;
    }
    for (dk_index i = 0; i < g; i++)
        w[i] /= sum;
}

static dk_status build(dk_shepard *s, const dk_constraint_desc *desc, dk_progress *prog,
                       shepard_weights *sw, dk_error *err)
{
    const dk_mesh *m = s->mesh;
    const dk_index n = m->n_vertices;
    const double *X = m->positions;
    memset(sw, 0, sizeof *sw);
    dk_status st = dk_constraints_create(m, desc, &sw->con, err);
    if (st != DK_OK)
        return dk_error_prefix(err, "Shepard");
    const dk_constraints *c = sw->con;
    dk_index n_fixed = 0;
    for (dk_index v = 0; v < n; v++)
        n_fixed += c->role[v] == DK_VERTEX_FIXED && !c->held[v];
    sw->has_fixed = n_fixed > 0;
    const dk_index g = c->n_handles + (sw->has_fixed ? 1 : 0);
    sw->n_groups = g;
    const size_t ng = (size_t)n * (size_t)g;
    st = dk_memory_check((uint64_t)ng * (2 * sizeof(double) + sizeof(dk_index)), "Shepard",
                         "each vertex's weight and distance for every group", err);
    if (st != DK_OK) {
        weights_free(sw);
        return st;
    }
    sw->w = calloc(ng + 1, sizeof *sw->w);
    sw->dist = malloc((ng + 1) * sizeof *sw->dist);
    sw->label = malloc((ng + 1) * sizeof *sw->label);
    sw->hpos = malloc(((size_t)n + 1) * sizeof *sw->hpos);
    sw->targets = malloc(3 * ((size_t)c->n_handle_vertices + 1) * sizeof *sw->targets);
    const dk_index biggest = c->n_handle_vertices > n_fixed ? c->n_handle_vertices : n_fixed;
    double *pts = malloc(3 * ((size_t)biggest + 1) * sizeof *pts);
    dk_index *ids = malloc(((size_t)biggest + 1) * sizeof *ids);
    dk_index *order = malloc(((size_t)g + 1) * sizeof *order);
    double *q = malloc(3 * ((size_t)c->n_free + 1) * sizeof *q);  /* the free vertices */
    /* GEODESIC: the sources, and per vertex a distance, a straight-line distance, a label */
    dk_index *src = malloc(((size_t)biggest + 1) * sizeof *src);
    double *gd = s->heat ? malloc(((size_t)n + 1) * sizeof *gd) : NULL;
    double *ge = s->heat ? malloc(((size_t)n + 1) * sizeof *ge) : NULL;
    dk_index *gl = s->heat ? malloc(((size_t)n + 1) * sizeof *gl) : NULL;
    double *qd = malloc(((size_t)c->n_free + 1) * sizeof *qd);
    dk_index *qi = malloc(((size_t)c->n_free + 1) * sizeof *qi);
    if (!sw->w || !sw->dist || !sw->label || !sw->hpos || !sw->targets || !pts || !ids ||
        !order || !q || !qd || !qi || !src || (s->heat && (!gd || !ge || !gl))) {
        st = dk_error_set(err, DK_ERR_OUT_OF_MEMORY, "Shepard: out of memory (weights)");
        goto done;
    }
    for (dk_index v = 0; v < n; v++)
        sw->hpos[v] = -1;
    for (dk_index k = 0; k < c->n_handle_vertices; k++)
        sw->hpos[c->handle_vertices[k]] = k;
    for (size_t i = 0; i < ng; i++) {
        sw->dist[i] = INFINITY;
        sw->label[i] = -1;
    }
    /* each group's nearest vertex and distance, for every free vertex: a tree per group,
     * queried once for all of them */
    for (dk_index f = 0; f < c->n_free; f++)
        memcpy(q + 3 * (size_t)f, X + 3 * (size_t)c->free_vertices[f], 3 * sizeof *q);
    for (dk_index grp = 0; grp < g && st == DK_OK; grp++) {
        if ((st = dk_progress_part(prog, (double)grp / g, err)) != DK_OK)
            break;
        dk_index cnt = 0;
        if (grp < c->n_handles) {
            for (dk_index k = c->handle_start[grp]; k < c->handle_start[grp + 1]; k++)
                ids[cnt++] = k; /* places among the handle vertices */
        } else {
            for (dk_index v = 0; v < n; v++)
                if (c->role[v] == DK_VERTEX_FIXED && !c->held[v])
                    ids[cnt++] = v;
        }
        for (dk_index i = 0; i < cnt; i++) {
            const dk_index v = grp < c->n_handles ? c->handle_vertices[ids[i]] : ids[i];
            memcpy(pts + 3 * (size_t)i, X + 3 * (size_t)v, 3 * sizeof *pts);
            src[i] = v;
        }
        if (s->heat) { /* along the surface: the heat distance, the nearest along edges */
            st = dk_labelled_search(m, src, cnt, 0, 0, gd, ge, gl, prog, grp, g, err);
            if (st == DK_OK)
                st = dk_heat_distance(s->heat, src, cnt, gd, err);
            for (dk_index f = 0; f < c->n_free && st == DK_OK; f++) {
                const dk_index v = c->free_vertices[f];
                const size_t at = (size_t)v * g + (size_t)grp;
                sw->dist[at] = gl[v] >= 0 ? fmax(gd[v], 0.0) : INFINITY;
                sw->label[at] = grp < c->n_handles && gl[v] >= 0 ? ids[gl[v]] : -1;
            }
            continue;
        }
        dk_kdtree *tree = NULL;
        if ((st = dk_kdtree_create(pts, cnt, &tree, err)) != DK_OK)
            break;
        if (c->n_free > 0)
            st = dk_kdtree_knn(tree, q, c->n_free, 1, qi, qd, err);
        dk_kdtree_free(tree);
        for (dk_index f = 0; f < c->n_free && st == DK_OK; f++) {
            const size_t at = (size_t)c->free_vertices[f] * g + (size_t)grp;
            sw->dist[at] = sqrt(qd[f]);
            sw->label[at] = grp < c->n_handles ? ids[qi[f]] : -1;
        }
    }
    for (dk_index v = 0; v < n && st == DK_OK; v++)
        if (c->role[v] == DK_VERTEX_FREE)
            vertex_weights(s, sw->dist + (size_t)v * g, g, sw->w + (size_t)v * g, order);
done:
    free(pts);
    free(ids);
    free(order);
    free(q);
    free(qd);
    free(qi);
    free(src);
    free(gd);
    free(ge);
    free(gl);
    if (st != DK_OK)
        weights_free(sw);
    return st;
}

dk_status dk_shepard_bind(const dk_mesh *mesh, const dk_constraint_desc *constraints,
                          const dk_shepard_options *options, dk_shepard **out, dk_error *err)
{
    if (out)
        *out = NULL;
    if (!mesh || !constraints || !out)
        return dk_error_set(err, DK_ERR_INVALID_ARGUMENT,
                            "Shepard bind: mesh, constraints and output must not be NULL");
    dk_shepard_options opt;
    if (options)
        opt = *options;
    else
        dk_shepard_default_options(&opt);
    dk_status st = check_options(&opt, err);
    if (st != DK_OK)
        return st;
    dk_progress prog;
    dk_progress_init(&prog, opt.progress, opt.progress_user, weight_phases, 1, "Shepard bind");
    opt.progress = NULL;
    opt.progress_user = NULL;
    if ((st = dk_progress_begin(&prog, 0, err)) != DK_OK)
        return st;
    dk_shepard *s = calloc(1, sizeof *s);
    if (!s)
        return dk_error_set(err, DK_ERR_OUT_OF_MEMORY, "Shepard: out of memory");
    s->mesh = mesh;
    s->opt = opt;
    s->radius = opt.radius > 0.0 ? opt.radius : DK_SHEPARD_AUTO_RADIUS * mesh->bbox_diagonal;
    if (!(s->radius > 0.0))
        s->radius = 1.0; /* a mesh of one point: any radius */
    if (opt.distance == DK_SHEPARD_GEODESIC) {
        if (mesh->n_faces == 0) {
            free(s);
            return dk_error_set(err, DK_ERR_DEGENERATE,
                                "Shepard: geodesic distance needs triangles (a vertex cloud "
                                "has only straight-line distances)");
        }
        if ((st = dk_heat_create(mesh, 0.0, &s->heat, err)) != DK_OK) {
            free(s);
            return dk_error_prefix(err, "Shepard bind");
        }
    }
    st = build(s, constraints, &prog, &s->sw, err);
    if (st != DK_OK) {
        dk_heat_free(s->heat);
        free(s);
        return st;
    }
    dk_progress_done(&prog);
    *out = s;
    return DK_OK;
}

dk_status dk_shepard_rebind(dk_shepard *s, const dk_constraint_desc *constraints,
                            dk_error *err)
{
    if (!s || !constraints)
        return dk_error_set(err, DK_ERR_INVALID_ARGUMENT,
                            "Shepard rebind: object and constraints must not be NULL");
    dk_progress prog;
    dk_progress_init(&prog, s->opt.progress, s->opt.progress_user, weight_phases, 1,
                     "Shepard rebind");
    shepard_weights fresh;
    dk_status st = dk_progress_begin(&prog, 0, err);
    if (st == DK_OK)
        st = build(s, constraints, &prog, &fresh, err);
    if (st != DK_OK)
        return st;
    dk_progress_done(&prog);
    weights_free(&s->sw);
    s->sw = fresh;
    return DK_OK;
}

void dk_shepard_set_progress(dk_shepard *s, dk_phase_progress_fn progress, void *user)
{
    if (!s)
        return;
    s->opt.progress = progress;
    s->opt.progress_user = progress ? user : NULL;
}

dk_status dk_shepard_solve(dk_shepard *s, const dk_solve_request *rq, double *positions,
                           dk_solve_info *info, dk_error *err)
{
    if (info)
        memset(info, 0, sizeof *info);
    if (!s || !positions)
        return dk_error_set(err, DK_ERR_INVALID_ARGUMENT,
                            "Shepard solve: object and positions must not be NULL");
    dk_status st = dk_solve_request_check_input(rq, s->mesh->n_vertices, "Shepard solve", err);
    if (st != DK_OK)
        return st;
    const shepard_weights *sw = &s->sw;
    const dk_constraints *c = sw->con;
    const dk_index n = s->mesh->n_vertices;
    const double *base = rq->input_positions ? rq->input_positions : s->mesh->positions;
    const int mode = (int)rq->target_kind;
    st = dk_constraints_targets(c, base, rq->targets, mode, sw->targets, err);
    if (st != DK_OK)
        return dk_error_prefix(err, "Shepard solve");
    /* the handles' linear nodal functions need transforms; positions give displacements */
    const int transforms = mode == 1 && s->opt.interpolate == DK_SHEPARD_TRANSFORMS;
    for (dk_index v = 0; v < n; v++) {
        const double *p = base + 3 * (size_t)v;
        double dsp[3] = {0.0, 0.0, 0.0};
        const dk_index role = c->role[v];
        if (role >= 0) { /* a handle vertex: its own (weighted) motion */
            const dk_index k = sw->hpos[v];
            for (int d = 0; d < 3; d++)
                dsp[d] = c->handle_weights[k] * (sw->targets[3 * (size_t)k + d] - p[d]);
        } else if (role == DK_VERTEX_FREE) {
            const double *w = sw->w + (size_t)v * sw->n_groups;
            const dk_index *lab = sw->label + (size_t)v * sw->n_groups;
            for (dk_index g = 0; g < c->n_handles; g++) { /* the fixed group adds nothing */
                const dk_index k = lab[g];
                if (w[g] == 0.0 || k < 0)
                    continue;
                const double wk = w[g] * c->handle_weights[k];
                if (transforms) {
                    const double *t = rq->targets + 16 * (size_t)g;
                    for (int d = 0; d < 3; d++)
                        dsp[d] += wk * (t[4 * d] * p[0] + t[4 * d + 1] * p[1] +
                                        t[4 * d + 2] * p[2] + t[4 * d + 3] - p[d]);
                } else {
                    const double *q = base + 3 * (size_t)c->handle_vertices[k];
                    for (int d = 0; d < 3; d++)
                        dsp[d] += wk * (sw->targets[3 * (size_t)k + d] - q[d]);
                }
            }
        }
        for (int d = 0; d < 3; d++)
            positions[3 * (size_t)v + d] = p[d] + dsp[d];
    }
    dk_constraints_hold(c, base, positions);
    return dk_direct_solve_finish(positions, base, n, rq, "Shepard solve", info, err);
}

dk_status dk_shepard_energy(const dk_shepard *s, const double *positions, double *energy,
                            dk_error *err)
{
    if (!s)
        return dk_error_set(err, DK_ERR_INVALID_ARGUMENT,
                            "Shepard energy: arguments must not be NULL");
    return dk_displacement_energy_result(positions, s->mesh->positions, s->mesh->n_vertices,
                                         "Shepard energy", energy, err);
}

void dk_shepard_stats(const dk_shepard *s, dk_method_stats *st)
{
    if (!st)
        return;
    memset(st, 0, sizeof *st);
    st->first_held = -1;
    if (!s)
        return;
    st->n_vertices = s->mesh->n_vertices;
    st->n_handles = s->sw.con ? s->sw.con->n_handles : 0;
    st->n_handle_vertices = s->sw.con ? s->sw.con->n_handle_vertices : 0;
    dk_constraints_held_stats(s->sw.con, NULL, st);
}

dk_index dk_shepard_n_groups(const dk_shepard *s)
{
    return s ? s->sw.n_groups : 0;
}

void dk_shepard_vertex_weights(const dk_shepard *s, dk_index v, double *weights,
                               double *distances)
{
    const dk_index g = s ? s->sw.n_groups : 0;
    const int ok = s && v >= 0 && v < s->mesh->n_vertices;
    for (dk_index i = 0; i < g; i++) {
        if (weights)
            weights[i] = ok ? s->sw.w[(size_t)v * g + i] : 0.0;
        if (distances)
            distances[i] = ok ? s->sw.dist[(size_t)v * g + i] : INFINITY;
    }
}

void dk_shepard_free(dk_shepard *s)
{
    if (!s)
        return;
    weights_free(&s->sw);
    dk_heat_free(s->heat);
    free(s);
}

dk_status dk_shepard_estimate_memory(const dk_mesh *mesh, const dk_shepard_options *options,
                                     uint64_t *bytes, dk_error *err)
{
    if (!mesh || !bytes)
        return dk_error_set(err, DK_ERR_INVALID_ARGUMENT,
                            "Shepard estimate_memory: mesh and bytes must not be NULL");
    dk_shepard_options o;
    if (options)
        o = *options;
    else
        dk_shepard_default_options(&o);
    dk_status st = check_options(&o, err);
    if (st != DK_OK)
        return st;
    /* per vertex: for a few groups a weight, a distance and a label; the role tables, a
     * result */
    *bytes = dk_memory_model(4.0 * 20.0 + 120.0, (double)mesh->n_vertices, 0.0);
    return DK_OK;
}

static const dk_option_desc shepard_fields[] = {
    {"power", DK_OPTION_DOUBLE, offsetof(dk_shepard_options, power), 0, DBL_TRUE_MIN, 64.0, 2.0,
     64.0, 0},
    {"neighbourhood", DK_OPTION_ENUM, offsetof(dk_shepard_options, neighbourhood), 0,
     DK_SHEPARD_ALL, DK_SHEPARD_RADIUS, DK_SHEPARD_ALL, DK_SHEPARD_RADIUS, 0},
    {"k", DK_OPTION_INT, offsetof(dk_shepard_options, k), 0, 1, 1024, 4, 64, 0},
    {"radius", DK_OPTION_DOUBLE, offsetof(dk_shepard_options, radius), 0, DBL_TRUE_MIN, DBL_MAX,
     0.3, DBL_MAX, DK_OPTION_LENGTH | DK_OPTION_ZERO_AUTO},
    {"interpolate", DK_OPTION_ENUM, offsetof(dk_shepard_options, interpolate), 0,
     DK_SHEPARD_TRANSFORMS, DK_SHEPARD_DISPLACEMENTS, DK_SHEPARD_TRANSFORMS,
     DK_SHEPARD_DISPLACEMENTS, 0},
    {"distance", DK_OPTION_ENUM, offsetof(dk_shepard_options, distance), 0,
     DK_SHEPARD_EUCLIDEAN, DK_SHEPARD_GEODESIC, DK_SHEPARD_EUCLIDEAN, DK_SHEPARD_GEODESIC, 0},
};

DK_METHOD_OPS(dk_shepard_ops, "Shepard", DK_METHOD_EDITS_INPUT, DK_CONTROL_VERTEX_GROUPS,
              dk_shepard, dk_shepard, dk_shepard_options, shepard_fields);
