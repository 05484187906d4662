/* DeformKit: embedded deformation (dk_embedded.h), the public verbs; the files of this
 * folder in embedded_internal.h. */
#include "embedded_internal.h"

/* The phases of a bind and of a rebind (dk_progress.h), weighted by their cost in seconds
 * measured on the 692k-vertex armadillo (scripts/bench_scale.py's armadillo-wave, 2
 * subdivisions; defaults: 200 surface nodes, k = 4, Euclidean) on the shared 2-core
 * machine, timed between the callback's reports: 3.3 and 4.0 s in all, the longest stretch
 * without a report the edges' sort (~1 s). */
static const dk_progress_phase ed_bind_phases[] = {
    {"nodes", 0.43}, {"weights", 1.2}, {"edges", 1.7}, {"constraints", 0.25}, {"analyze", 0.03}};
static const dk_progress_phase ed_rebind_phases[] = {{"constraints", 0.25}, {"analyze", 0.03}};
dk_status ed_oom(dk_error *err, const char *what)
{
    return dk_error_set(err, DK_ERR_OUT_OF_MEMORY, "EmbeddedDeformation: out of memory (%s)",
                        what);
}

void dk_embedded_default_options(dk_embedded_options *o)
{
    memset(o, 0, sizeof *o);
    o->nodes = DK_ED_NODES_SURFACE;
    o->n_nodes = 200;
    o->radius = 0.0;
    o->k = 4;
    o->distance = DK_ED_DISTANCE_EUCLIDEAN;
    o->w_rot = 1.0;
    o->w_reg = 10.0;
    o->w_con = 2000.0;
    o->tolerance = 1e-6;
    o->max_iterations = 100;
    o->seed = 1;
    o->progress = NULL;
    o->progress_user = NULL;
}

static dk_status check_options(const dk_embedded_options *o, dk_error *err)
{
    const char *bad = NULL;
    if (o->nodes != DK_ED_NODES_SURFACE && o->nodes != DK_ED_NODES_VERTICES)
        bad = "nodes must be surface (0) or vertices (1)";
    else if (!(o->radius >= 0.0 && isfinite(o->radius)))
        bad = "radius must be finite and >= 0";
    else if (o->radius == 0.0 && (o->n_nodes < 1 || o->n_nodes > ED_MAX_NODES))
        bad = "n_nodes must be in 1..100000";
    else if (o->k < 1 || o->k > K_MAX)
        bad = "k must be in 1..16";
    else if (o->distance != DK_ED_DISTANCE_EUCLIDEAN && o->distance != DK_ED_DISTANCE_GEODESIC)
        bad = "distance must be euclidean (0) or geodesic (1)";
    else if (o->n_cut_a < 0 || o->n_cut_b < 0 || (o->n_cut_a > 0 && !o->cut_a) ||
             (o->n_cut_b > 0 && !o->cut_b))
        bad = "the cut groups must be index arrays with their counts";
    else if ((o->n_cut_a > 0) != (o->n_cut_b > 0))
        bad = "a cut needs both groups (cut_a and cut_b), or neither";
    else if (!(o->w_rot > 0 && o->w_reg > 0 && o->w_con > 0 && isfinite(o->w_rot) &&
               isfinite(o->w_reg) && isfinite(o->w_con)))
        bad = "the weights w_rot, w_reg and w_con must be finite and > 0";
    else if (!(o->tolerance > 0.0 && isfinite(o->tolerance)))
        bad = "tolerance must be finite and > 0";
    else if (o->max_iterations < 1)
        bad = "max_iterations must be >= 1";
    return bad ? dk_error_set(err, DK_ERR_INVALID_ARGUMENT, "EmbeddedDeformation: %s", bad)
               : DK_OK;
}

/* ------------------------------------------------------------------ bind, rebind ------- */

void dk_embedded_free(dk_embedded *ed)
{
    if (!ed)
        return;
    ed_system_free(&ed->sys);
    dk_team_free(ed->team); /* after the factor, which used it */
    free(ed->g);
    free(ed->nb);
    free(ed->w);
    free(ed->vside);
    free(ed->nside);
    free(ed->p);
    free(ed->node_vertex);
    free(ed->node_face);
    free(ed->node_bary);
    free(ed->edges);
    free(ed->adj_start);
    free(ed->adj);
    free(ed->x);
    free(ed);
}

dk_status dk_embedded_bind(const dk_mesh *mesh, const dk_constraint_desc *constraints,
                           const dk_embedded_options *options, dk_embedded **out,
                           dk_error *err)
{
    if (out)
        *out = NULL;
    if (!mesh || !constraints || !out)
        return dk_error_set(err, DK_ERR_INVALID_ARGUMENT,
                            "EmbeddedDeformation: mesh, constraints and output must not be "
                            "NULL");
    dk_embedded *ed = calloc(1, sizeof *ed);
    if (!ed)
        return ed_oom(err, "object");
    if (options)
        ed->opt = *options;
    else
        dk_embedded_default_options(&ed->opt);
    dk_progress prog;
    dk_progress_init(&prog, ed->opt.progress, ed->opt.progress_user, ed_bind_phases,
                     (int)(sizeof ed_bind_phases / sizeof ed_bind_phases[0]),
                     "EmbeddedDeformation bind");
    ed->opt.progress = NULL; /* the caller's callback is for this bind only */
    ed->opt.progress_user = NULL;
    ed->prog = &prog;
    ed->mesh = mesh;
    ed->n = mesh->n_vertices;
    ed->k = ed->opt.k;
    ed->team = dk_team_create(); /* NULL (no thread available) is fine */
    dk_status st = check_options(&ed->opt, err);
    if (st == DK_OK) { /* 0. the source's positions, the mesh's until updated */
        ed->p = malloc((3 * (size_t)ed->n + 1) * sizeof *ed->p);
        if (ed->p)
            memcpy(ed->p, mesh->positions, 3 * (size_t)ed->n * sizeof *ed->p);
        else
            st = ed_oom(err, "positions");
    }
    if (st == DK_OK) /* the unit of length of F (ed_evaluate()) */
        ed->L = ed_unit_length(mesh->positions, ed->n);
    if (st == DK_OK && (st = dk_progress_begin(&prog, 0, err)) == DK_OK) /* 1. the nodes */
        st = ed_sample_nodes(ed, err);
    if (st == DK_OK && (st = dk_progress_begin(&prog, 1, err)) == DK_OK) /* 2. eq. 4 */
        st = ed_weights(ed, err);
    if (st == DK_OK && (st = dk_progress_begin(&prog, 2, err)) == DK_OK) /* 3. the edges */
        st = ed_edges(ed, err);
    if (st == DK_OK) { /* 4. the transformations, identity */
        ed->x = malloc((12 * (size_t)ed->m + 1) * sizeof *ed->x);
        if (!ed->x)
            st = ed_oom(err, "transformations");
        else
            ed_identity(ed->x, ed->m);
    }
    if (st == DK_OK) /* 5. the constraints: fixed nodes, positional terms, J^T J's pattern */
        st = ed_system_build(ed, constraints, &ed->sys, 3, err);
    ed->prog = NULL;
    if (st != DK_OK) {
        dk_embedded_free(ed);
        return st;
    }
    ed->energy = 0.0;
    dk_progress_done(&prog);
    *out = ed;
    return DK_OK;
}

dk_status dk_embedded_rebind(dk_embedded *ed, const dk_constraint_desc *constraints,
                             dk_error *err)
{
    if (!ed || !constraints)
        return dk_error_set(err, DK_ERR_INVALID_ARGUMENT,
                            "EmbeddedDeformation rebind: object and constraints must not be "
                            "NULL");
    ed_system s;
    dk_progress prog;
    dk_progress_init(&prog, ed->opt.progress, ed->opt.progress_user, ed_rebind_phases,
                     (int)(sizeof ed_rebind_phases / sizeof ed_rebind_phases[0]),
                     "EmbeddedDeformation rebind");
    ed->prog = &prog;
    dk_status st = ed_system_build(ed, constraints, &s, 0, err);
    ed->prog = NULL;
    if (st != DK_OK)
        return st;
    dk_progress_done(&prog);
    ed_system_free(&ed->sys);
    ed->sys = s;
    /* nodes constant under the new constraints are the identity (the solver never moves
     * them): a warm solve must not blend the last solve's transforms of them */
    for (dk_index j = 0; j < ed->m; j++)
        if (ed->sys.node_unknown[j] < 0)
            ed_identity(ed->x + 12 * (size_t)j, 1);
    return DK_OK;
}

void dk_embedded_set_progress(dk_embedded *ed, dk_phase_progress_fn progress, void *user)
{
    if (!ed)
        return;
    ed->opt.progress = progress;
    ed->opt.progress_user = progress ? user : NULL;
}

/* ------------------------------------------------------------------ normals, points --- */

dk_status dk_embedded_update_source(dk_embedded *ed, const double *positions, dk_error *err)
{
    if (!ed || !positions)
        return dk_error_set(err, DK_ERR_INVALID_ARGUMENT,
                            "EmbeddedDeformation update_source: object and positions must not "
                            "be NULL");
    dk_status st = dk_check_positions(positions, ed->n, err);
    if (st != DK_OK)
        return dk_error_prefix(err, "EmbeddedDeformation update_source");
    memcpy(ed->p, positions, 3 * (size_t)ed->n * sizeof *ed->p);
    ed->sys.k_stale = 1; /* K's coefficients come from p and g */
    for (dk_index j = 0; j < ed->m; j++) {
        double *g = ed->g + 3 * (size_t)j;
        if (ed->node_vertex) { /* section 5: a node on a vertex rides along with it */
            memcpy(g, ed->p + 3 * (size_t)ed->node_vertex[j], 3 * sizeof *g);
            continue;
        }
        /* a surface sample keeps its place in its triangle: the paper's nodes on vertices,
         * generalised to its uniform samples, so that the default graph also follows */
        const dk_index *f = ed->mesh->faces + 3 * (size_t)ed->node_face[j];
        const double *a = ed->p + 3 * (size_t)f[0], *b = ed->p + 3 * (size_t)f[1];
        const double *c = ed->p + 3 * (size_t)f[2];
        const double s = ed->node_bary[2 * (size_t)j], t = ed->node_bary[2 * (size_t)j + 1];
        for (int d = 0; d < 3; d++)
            g[d] = a[d] + s * (b[d] - a[d]) + t * (c[d] - a[d]);
    }
    return DK_OK;
}

/* The state (dk_method_ops.state_size): the graph's transformations a warm start continues
 * from, their energy, the targets energy() reads, and the source a solve deforms with its
 * nodes (update_source). */
static int ed_state_spans(const dk_embedded *ed_const, dk_state_span *sp)
{
    dk_embedded *ed = (dk_embedded *)ed_const; /* save reads through the list restore writes */
    const size_t D = sizeof(double);
    int k = 0;
    sp[k++] = (dk_state_span){ed->x, 12 * (size_t)ed->m * D};
    sp[k++] = (dk_state_span){&ed->energy, D};
    sp[k++] = (dk_state_span){ed->sys.targets, 3 * (size_t)ed->sys.con->n_handle_vertices * D};
    sp[k++] = (dk_state_span){ed->p, 3 * (size_t)ed->n * D};
    sp[k++] = (dk_state_span){ed->g, 3 * (size_t)ed->m * D};
    return k;
}

static void ed_state_shape(const dk_embedded *ed, uint64_t shape[4])
{
    shape[0] = (uint64_t)ed->n;
    shape[1] = (uint64_t)ed->sys.con->n_handle_vertices;
    shape[2] = (uint64_t)ed->m;
    shape[3] = (uint64_t)ed->k;
}

size_t dk_embedded_state_size(const dk_embedded *ed)
{
    dk_state_span sp[5];
    return ed ? dk_state_size(sp, ed_state_spans(ed, sp)) : 0;
}

dk_status dk_embedded_save_state(const dk_embedded *ed, void *state, size_t size, dk_error *err)
{
    if (!ed)
        return dk_error_set(err, DK_ERR_INVALID_ARGUMENT,
                            "EmbeddedDeformation save_state: object is NULL");
    dk_state_span sp[5];
    uint64_t shape[4];
    ed_state_shape(ed, shape);
    return dk_state_save("EmbeddedDeformation", shape, sp, ed_state_spans(ed, sp), state, size,
                         err);
}

dk_status dk_embedded_restore_state(dk_embedded *ed, const void *state, size_t size,
                                    dk_error *err)
{
    if (!ed)
        return dk_error_set(err, DK_ERR_INVALID_ARGUMENT,
                            "EmbeddedDeformation restore_state: object is NULL");
    dk_state_span sp[5];
    uint64_t shape[4];
    ed_state_shape(ed, shape);
    const int k = ed_state_spans(ed, sp);
    const dk_status st = dk_state_check("EmbeddedDeformation", shape, sp, k, state, size, err);
    if (st == DK_OK) {
        dk_state_restore_spans(sp, k, state);
        ed->sys.k_stale = 1; /* the source (p, g) came back with it */
    }
    return st;
}

dk_status dk_embedded_deformed(const dk_embedded *ed, double *positions, dk_error *err)
{
    if (!ed || !positions)
        return dk_error_set(err, DK_ERR_INVALID_ARGUMENT,
                            "EmbeddedDeformation deformed: object and output must not be NULL");
    ed_apply(ed, ed->x, positions);
    return DK_OK;
}

/* The inverse transpose of a 3 x 3 (row-major) into it, or 0 when singular. */
static int inverse_transpose(const double *R, double *o)
{
    const double det = dk_mat3_cofactor(R, o); /* (R^-1)^T = cofactor matrix / det */
    if (!(fabs(det) > 1e-300) || !isfinite(det))
        return 0;
    for (int k = 0; k < 9; k++)
        o[k] /= det;
    return 1;
}

dk_status dk_embedded_normals(const dk_embedded *ed, const double *normals, double *out,
                              dk_error *err)
{
    if (!ed || !out)
        return dk_error_set(err, DK_ERR_INVALID_ARGUMENT,
                            "EmbeddedDeformation normals: object and output must not be NULL");
    const dk_index n = ed->n, k = ed->k;
    const dk_mesh *m = ed->mesh;
    double *rest = NULL;
    if (normals) /* NaN normals came back as zero vectors (the second hostile review) */
        for (size_t i = 0; i < 3 * (size_t)n; i++)
            if (!isfinite(normals[i]))
                return dk_error_set(err, DK_ERR_NONFINITE,
                                    "EmbeddedDeformation normals: the normal of vertex %lld "
                                    "is not finite",
                                    (long long)(i / 3));
    if (!normals) { /* area-weighted vertex normals: the sum of the faces' cross products */
        rest = calloc(3 * (size_t)n + 1, sizeof *rest);
        if (!rest)
            return ed_oom(err, "normals");
        for (dk_index f = 0; f < m->n_faces; f++) {
            const dk_index *t = m->faces + 3 * f;
            const double *a = ed->p + 3 * t[0], *b = ed->p + 3 * t[1];
            const double *c = ed->p + 3 * t[2];
            const double u[3] = {b[0] - a[0], b[1] - a[1], b[2] - a[2]};
            const double v[3] = {c[0] - a[0], c[1] - a[1], c[2] - a[2]};
            const double x[3] = {u[1] * v[2] - u[2] * v[1], u[2] * v[0] - u[0] * v[2],
                                 u[0] * v[1] - u[1] * v[0]};
            for (int q = 0; q < 3; q++)
                for (int d = 0; d < 3; d++)
                    rest[3 * t[q] + d] += x[d];
        }
        normals = rest;
    }
    double *itr = malloc((9 * (size_t)ed->m + 1) * sizeof *itr);
    unsigned char *ok = malloc((size_t)ed->m + 1);
    if (!itr || !ok) {
        free(rest);
        free(itr);
        free(ok);
        return ed_oom(err, "normals");
    }
    for (dk_index j = 0; j < ed->m; j++)
        ok[j] = (unsigned char)inverse_transpose(ed->x + 12 * (size_t)j, itr + 9 * (size_t)j);
    for (dk_index v = 0; v < n; v++) {
        const double *nv = normals + 3 * v;
        double o[3] = {0.0, 0.0, 0.0};
        const int held = ed->sys.con->held[v]; /* at rest: its normal is the rest normal */
        if (held)
            memcpy(o, nv, sizeof o);
        for (dk_index q = 0; q < k && !held; q++) {
            const dk_index j = ed->nb[(size_t)v * k + q];
            if (j < 0 || !ok[j])
                continue;
            const double w = ed->w[(size_t)v * k + q], *M = itr + 9 * (size_t)j;
            for (int d = 0; d < 3; d++)
                o[d] += w * (M[3 * d] * nv[0] + M[3 * d + 1] * nv[1] + M[3 * d + 2] * nv[2]);
        }
        const double len = sqrt(o[0] * o[0] + o[1] * o[1] + o[2] * o[2]);
        for (int d = 0; d < 3; d++)
            out[3 * v + d] = len > 0.0 ? o[d] / len : 0.0;
    }
    free(rest);
    free(itr);
    free(ok);
    return DK_OK;
}

dk_status dk_embedded_embed(const dk_embedded *ed, const double *points, dk_index n_points,
                            dk_index *nodes, double *weights, double *out, dk_error *err)
{
    if (!ed || !points || n_points < 0)
        return dk_error_set(err, DK_ERR_INVALID_ARGUMENT,
                            "EmbeddedDeformation embed: object and points must be given");
    for (size_t i = 0; i < 3 * (size_t)n_points; i++)
        if (!isfinite(points[i]))
            return dk_error_set(err, DK_ERR_NONFINITE,
                                "EmbeddedDeformation embed: point %d is not finite",
                                (int)(i / 3));
    const dk_index k = ed->k;
    if (ed->m < k + 1)
        return dk_error_set(err, DK_ERR_INVALID_ARGUMENT,
                            "EmbeddedDeformation embed: the graph has %d nodes, fewer than "
                            "k + 1 = %d", (int)ed->m, (int)k + 1);
    dk_index *nb = nodes ? nodes : malloc(((size_t)n_points * k + 1) * sizeof *nb);
    double *w = weights ? weights : malloc(((size_t)n_points * k + 1) * sizeof *w);
    dk_kdtree *tree = NULL;
    dk_status st = nb && w ? dk_kdtree_create(ed->g, ed->m, &tree, err) : ed_oom(err, "embed");
    if (st == DK_OK)
        st = ed_embed_points(tree, points, n_points, k, NULL, nb, w, NULL, err);
    for (dk_index p = 0; st == DK_OK && out && p < n_points; p++) {
        const double *x0 = points + 3 * p;
        double o[3] = {0.0, 0.0, 0.0};
        for (dk_index q = 0; q < k; q++) {
            const dk_index j = nb[(size_t)p * k + q];
            if (j < 0)
                continue;
            const double *R = ed->x + 12 * (size_t)j, *g = ed->g + 3 * j;
            const double d[3] = {x0[0] - g[0], x0[1] - g[1], x0[2] - g[2]};
            for (int c = 0; c < 3; c++)
                o[c] += w[(size_t)p * k + q] *
                        (R[3 * c] * d[0] + R[3 * c + 1] * d[1] + R[3 * c + 2] * d[2] + g[c] +
                         R[9 + c]);
        }
        memcpy(out + 3 * p, o, sizeof o);
    }
    dk_kdtree_free(tree);
    if (!nodes)
        free(nb);
    if (!weights)
        free(w);
    return st;
}

/* ------------------------------------------------------------------ accessors ---------- */

dk_status dk_embedded_energy(const dk_embedded *ed, const double *positions, double *energy,
                             dk_error *err)
{
    if (energy)
        *energy = NAN;
    if (!ed || !positions || !energy)
        return dk_error_set(err, DK_ERR_INVALID_ARGUMENT,
                            "EmbeddedDeformation energy: object, positions and energy must "
                            "not be NULL");
    const ed_system *s = &ed->sys;
    /* the graph terms: F of x without the positional terms */
    ed_system graph_only = *s;
    graph_only.n_pos = 0;
    double F = ed_evaluate(ed, NULL, &graph_only, ed->x, 0);
    for (dk_index l = 0; l < s->n_pos; l++) {
        const dk_index v = s->pos_vertex[l];
        const double *tg = s->pos_target_row[l] >= 0 ? s->targets + 3 * s->pos_target_row[l]
                                                     : ed->p + 3 * v;
        for (int d = 0; d < 3; d++) {
            const double r = (positions[3 * v + d] - tg[d]) / ed->L; /* as ed_evaluate() */
            F += ed->opt.w_con * r * r;
        }
    }
    *energy = F;
    return dk_energy_result_check(F, "EmbeddedDeformation energy", err);
}

void dk_embedded_stats(const dk_embedded *ed, dk_method_stats *st)
{
    if (!st)
        return;
    memset(st, 0, sizeof *st);
    if (!ed)
        return;
    st->n_vertices = ed->n;
    st->n_handles = ed->sys.con->n_handles;
    st->n_handle_vertices = ed->sys.con->n_handle_vertices;
    dk_constraints_held_stats(ed->sys.con, NULL, st);
    st->n_unknowns = 12 * ed->sys.n_free;
    st->n_graph_nodes = ed->m;
    st->analysis_count = ed->analysis_count;
    st->factorization_count = ed->factorization_count;
}

dk_index dk_embedded_n_nodes(const dk_embedded *ed)
{
    return ed ? ed->m : 0;
}

dk_index dk_embedded_k(const dk_embedded *ed)
{
    return ed ? ed->k : 0;
}

const double *dk_embedded_nodes(const dk_embedded *ed)
{
    return ed ? ed->g : NULL;
}

const double *dk_embedded_transforms(const dk_embedded *ed)
{
    return ed ? ed->x : NULL;
}

int dk_embedded_node_is_fixed(const dk_embedded *ed, dk_index node)
{
    return ed && node >= 0 && node < ed->m && ed->sys.node_unknown[node] < 0;
}

dk_index dk_embedded_n_edges(const dk_embedded *ed)
{
    return ed ? ed->n_edges : 0;
}

const dk_index *dk_embedded_edges(const dk_embedded *ed)
{
    return ed ? ed->edges : NULL;
}

/* ---------------------------------------------------------------- the method contract --- */

/* the contract's table (dk_method.h): the adapters cast to this method's types */
dk_status dk_embedded_estimate_memory(const dk_mesh *mesh, const dk_embedded_options *options,
                                      uint64_t *bytes, dk_error *err)
{
    if (!mesh || !bytes)
        return dk_error_set(err, DK_ERR_INVALID_ARGUMENT,
                            "EmbeddedDeformation estimate_memory: mesh and bytes must not be "
                            "NULL");
    dk_embedded_options o;
    if (options)
        o = *options;
    else
        dk_embedded_default_options(&o);
    dk_status st = check_options(&o, err); /* what bind refuses */
    if (st != DK_OK)
        return st;
    const double n = (double)mesh->n_vertices, k = o.k > 0 ? o.k : 4;
    /* the node count the bind will keep: n_nodes (at most the vertices), or for a radius r
     * the count a random disk packing leaves on the surface's area A, measured 0.51-0.65
     * A / r^2 on the arm and the armadillo (0.7 here), capped as sample_nodes caps it */
    double m = o.n_nodes > 0 ? o.n_nodes : 200.0;
    if (o.radius > 0.0) {
        double area = 0.0;
        for (dk_index f = 0; f < mesh->n_faces; f++) {
            const double *a = mesh->positions + 3 * (size_t)mesh->faces[3 * f];
            const double *b = mesh->positions + 3 * (size_t)mesh->faces[3 * f + 1];
            const double *c = mesh->positions + 3 * (size_t)mesh->faces[3 * f + 2];
            const double u[3] = {b[0] - a[0], b[1] - a[1], b[2] - a[2]};
            const double v[3] = {c[0] - a[0], c[1] - a[1], c[2] - a[2]};
            const double x = u[1] * v[2] - u[2] * v[1], y = u[2] * v[0] - u[0] * v[2],
                         z = u[0] * v[1] - u[1] * v[0];
            area += 0.5 * sqrt(x * x + y * y + z * z);
        }
        m = mesh->n_faces > 0 ? 0.7 * area / (o.radius * o.radius) : n;
        if (!(m <= ED_MAX_NODES + 1.0))
            m = ED_MAX_NODES + 1.0;
    }
    if (m > n)
        m = n;
    if (m < 1.0)
        m = 1.0;
    /* per vertex its k nodes and weights: measured 430 B at 43k; per node K's 4 x 4 blocks,
     * the reduced system over the graph's two rings and its factor (schur.c), growing with
     * k: measured 20-30 KB at k = 4 (2,000 nodes to nodes on every vertex of the arm and
     * the armadillo, two iterations) and 86 KB at k = 8; 16 MiB at any size: the factor's
     * first BLAS buffers. Handles spread over the whole graph keep every node's R in the
     * reduced system (up to 115 KB per node): the first factorization's own check, from its
     * symbolic analysis, refuses what this misses. */
    const double per_vertex = 500.0 + (k > 4 ? 24.0 * (k - 4) : 0.0);
    const double per_node = 36000.0 * pow(k / 4.0, 1.5);
    *bytes = dk_memory_model(per_vertex, n, per_node * m + 16.0 * 1048576.0);
    return DK_OK;
}

/* the options' fields (dk_option_desc): where each is, what values bind takes */
static const dk_option_desc embedded_fields[] = {
    {"nodes", DK_OPTION_ENUM, offsetof(dk_embedded_options, nodes), 0, 0, 1, 0, 1, 0},
    {"n_nodes", DK_OPTION_INT, offsetof(dk_embedded_options, n_nodes), 0, 1, ED_MAX_NODES, 200,
     40, 0},
    {"radius", DK_OPTION_DOUBLE, offsetof(dk_embedded_options, radius), 0, DBL_TRUE_MIN,
     DBL_MAX, 0.25, DBL_MAX, DK_OPTION_LENGTH | DK_OPTION_ZERO_AUTO},
    {"k", DK_OPTION_INT, offsetof(dk_embedded_options, k), 0, 1, K_MAX, 4, 8, 0},
    {"distance", DK_OPTION_ENUM, offsetof(dk_embedded_options, distance), 0, 0, 1, 0, 1, 0},
    {"cut_a", DK_OPTION_VERTICES, offsetof(dk_embedded_options, cut_a),
     offsetof(dk_embedded_options, n_cut_a), 0, 0, 0, 0, 0},
    {"cut_b", DK_OPTION_VERTICES, offsetof(dk_embedded_options, cut_b),
     offsetof(dk_embedded_options, n_cut_b), 0, 0, 0, 0, 0},
    {"w_rot", DK_OPTION_DOUBLE, offsetof(dk_embedded_options, w_rot), 0, DBL_TRUE_MIN, DBL_MAX,
     1.0, DBL_MAX, 0},
    {"w_reg", DK_OPTION_DOUBLE, offsetof(dk_embedded_options, w_reg), 0, DBL_TRUE_MIN, DBL_MAX,
     10.0, DBL_MAX, 0},
    {"w_con", DK_OPTION_DOUBLE, offsetof(dk_embedded_options, w_con), 0, DBL_TRUE_MIN, DBL_MAX,
     100.0, DBL_MAX, 0},
    {"tolerance", DK_OPTION_DOUBLE, offsetof(dk_embedded_options, tolerance), 0, DBL_TRUE_MIN,
     DBL_MAX, 1e-6, DBL_MAX, 0},
    {"max_iterations", DK_OPTION_INT, offsetof(dk_embedded_options, max_iterations), 0, 1,
     INT_MAX, 100, 20, 0},
    {"seed", DK_OPTION_SEED, offsetof(dk_embedded_options, seed), 0, 0, 0, 1, 0, 0},
};

DK_METHOD_OPS_STATEFUL(dk_embedded_ops, "EmbeddedDeformation",
              DK_METHOD_ITERATIVE | DK_METHOD_TRANSFORMS_AS_POSITIONS |
              DK_METHOD_TRANSLATION_INVARIANT | DK_METHOD_RIGID_INVARIANT |
              DK_METHOD_PENALTY_HANDLES | DK_METHOD_GRAPH, DK_CONTROL_VERTEX_GROUPS,
              dk_embedded, dk_embedded, dk_embedded_options, embedded_fields);

