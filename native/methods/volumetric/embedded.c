/* DeformKit volumetric ARAP: the embedded domain (the option embed; volumetric_internal.h).
 * A coarse volume carries the surface, for meshes whose own volume would not fit (the 3D
 * factor fills in: about 12 KB a vertex, so 3 GB is passed from about 250,000 vertices):
 *   1. the surface simplified to a sixteenth of its vertices, each vertex's handle, fixed or
 *      free role kept, tetrahedralized and bound as a VolumetricARAP of its own with the
 *      constraints restricted (multiscale.c's coarse volume, volumetric_coarse_build: its
 *      TetGen run retried with more vertices where the simplified surface crosses itself);
 *   2. each vertex of the surface located in the coarse tetrahedra at rest near its own
 *      place on the surface (a kept vertex is its coarse point; any other is located among
 *      the tetrahedra around the kept vertex its simplification's carriers lead to, one
 *      ring of them, two where it lies outside those): its barycentric coordinates there,
 *      extrapolated outside them (between kept vertices the surface bulges past the coarse
 *      one), so that P moves every vertex by an affine map of the coarse points exactly. A
 *      search among all the tetrahedra put vertices facing a nearby part or fold into that
 *      part's tetrahedra (two tubes 0.01 apart: edges stretched 12-fold, found by a review);
 *   3. a solve edits the coarse volume (the input pose and a given start restricted to the
 *      kept vertices, position targets to the kept handle vertices, transforms as they are)
 *      and moves each vertex from the pose it edits by the coarse volume's move at its
 *      coordinates, x = p + P (y - y_p), y_p the coarse pose (the input extended into the
 *      coarse volume, or its rest): a zero edit gives the pose back, a rigid motion moves
 *      it rigidly; then each hard handle vertex is put at its target and each fixed (and
 *      held) vertex at the pose, exactly, as every vertex-group method does.
 * What is minimised is the coarse volume's energy; the surface's details ride on it. */
#include "volumetric_internal.h"

#include <math.h>

#include "dk_operators.h"

/* from this many vertices on, embed 0 (automatic) carries a closed surface by a coarse
 * volume: the full volume's estimate passes 3 GB there (docs/methods/volumetric_arap.md) */
#define EMBED_AUTO_VERTICES 250000
/* the coarse surface's most vertices: an eighth of the mesh, or up to this many (a small mesh
 * may keep most of its vertices and costs little) */
#define EMBED_SMALL 8192

struct volumetric_embedding {
    volumetric_level *level; /* the simplification, its mesh and the coarse VolumetricARAP  */
    dk_index *hv;            /* per coarse handle vertex: its index among the surface's
                                handle vertices (for position targets)                    */
    dk_index *p_start, *p_col; /* P: n + 1 row starts, 4 n columns (coarse points)          */
    double *p_w;             /* 4 n weights                                                */
    double *pose_c, *start_c; /* n_c x 3 each: the input and a given start, restricted     */
    double *targets_c;       /* coarse handle vertices x 3                                 */
    double *surface_c;       /* n_c x 3: the coarse solve's surface                        */
    double *targets;         /* the surface's handle vertices x 3, expanded                */
    double *scratch_c;       /* n_c x 3: energy's restriction                              */
};

dk_index volumetric_embed_most(dk_index n)
{
    const dk_index small = n < EMBED_SMALL ? n : EMBED_SMALL;
    return n / 8 > small ? n / 8 : small;
}

int volumetric_embed_wanted(const dk_mesh *mesh, const dk_volumetric_arap_options *o)
{
    if (o->embed == 2)
        return 1;
    if (o->embed == 1 || mesh->n_vertices < EMBED_AUTO_VERTICES)
        return 0;
    const dk_mesh_report *r = &mesh->report;
    return r->n_boundary_edges == 0 && r->n_nonmanifold_edges == 0 &&
           r->n_isolated_vertices == 0;
}

void volumetric_embedding_free(volumetric_embedding *e)
{
    if (!e)
        return;
    volumetric_level_free(e->level);
    free(e->hv);
    free(e->p_start);
    free(e->p_col);
    free(e->p_w);
    free(e->pose_c);
    free(e->start_c);
    free(e->targets_c);
    free(e->surface_c);
    free(e->targets);
    free(e->scratch_c);
    free(e);
}

dk_volumetric_arap *volumetric_embedding_inner(const volumetric_embedding *e)
{
    return e->level->coarse;
}

uint64_t volumetric_embedding_bytes(double n, uint64_t coarse_bytes)
{
    /* the simplification's working arrays (~300 B a vertex, freed after; ARAP's measure),
     * P (4 columns and weights a vertex and the row starts: 52 B), the solve's buffers (a
     * handle vertex's target: at most 24 B a vertex) and the locator's (~100 B) */
    return coarse_bytes + dk_memory_model(300.0 + 52.0 + 24.0 + 100.0, n, 0.0);
}

/* The kept vertex (its coarse point) each vertex is carried from: itself when kept, else
 * the anchor of its heaviest carrier, those removed after it first (reverse order). */
static void anchors(const dk_decimation *d, dk_index *anchor)
{
    for (dk_index v = 0; v < d->n_vertices; v++)
        anchor[v] = d->coarse_of[v];
    for (dk_index k = d->n_removed - 1; k >= 0; k--) {
        const dk_index *c = d->carrier + 3 * (size_t)k;
        const double *w = d->weight + 3 * (size_t)k;
        const int j = w[1] > w[0] ? (w[2] > w[1] ? 2 : 1) : (w[2] > w[0] ? 2 : 0);
        anchor[d->removed[k]] = anchor[c[j]];
    }
}

/* The smallest barycentric coordinate of q in tetrahedron t (its frame f: corner 0 and the
 * gradients of corners 1..3), the coordinates into l. */
static double coordinates(const double *f, const double *q, double l[4])
{
    const double dx[3] = {q[0] - f[0], q[1] - f[1], q[2] - f[2]};
    l[0] = 1.0;
    for (int k = 1; k < 4; k++) {
        const double *g = f + 3 * (size_t)k;
        l[k] = g[0] * dx[0] + g[1] * dx[1] + g[2] * dx[2];
        l[0] -= l[k];
    }
    return fmin(fmin(l[0], l[1]), fmin(l[2], l[3]));
}

/* P: per vertex its coarse point (kept) or the best tetrahedron among those around its
 * anchor (one ring, two where it lies outside them all). */
static dk_status carrier_map(const dk_mesh *m, const dk_decimation *d,
                             const dk_volumetric_arap *in, volumetric_embedding *e,
                             dk_error *err)
{
    const dk_index n = m->n_vertices, np = in->np, nt = in->nt;
    const double *p = volume_points(in);
    dk_index *anchor = malloc(((size_t)n + 1) * sizeof *anchor);
    dk_index *ps = calloc((size_t)np + 2, sizeof *ps);
    dk_index *pt = malloc((4 * (size_t)nt + 1) * sizeof *pt);
    double *frames = malloc((12 * (size_t)nt + 1) * sizeof *frames);
    unsigned char *flat = calloc((size_t)nt + 1, 1);
    dk_index *seen = malloc(((size_t)nt + 1) * sizeof *seen);
    dk_index *cand = malloc(((size_t)nt + 1) * sizeof *cand);
    dk_status st = DK_OK;
    if (!anchor || !ps || !pt || !frames || !flat || !seen || !cand) {
        st = dk_error_set(err, DK_ERR_OUT_OF_MEMORY, "VolumetricARAP embed: out of memory");
        goto done;
    }
    anchors(d, anchor);
    for (dk_index t = 0; t < nt; t++) { /* the tetrahedra around each point, and frames */
        const dk_index *q = in->tets + 4 * (size_t)t;
        for (int k = 0; k < 4; k++)
            ps[q[k] + 1]++;
        double g[12];
        flat[t] = dk_tetrahedron_frame(p + 3 * (size_t)q[0], p + 3 * (size_t)q[1],
                                       p + 3 * (size_t)q[2], p + 3 * (size_t)q[3], g) == 0.0;
        memcpy(frames + 12 * (size_t)t, p + 3 * (size_t)q[0], 3 * sizeof *frames);
        memcpy(frames + 12 * (size_t)t + 3, g + 3, 9 * sizeof *frames);
        seen[t] = -1;
    }
    for (dk_index i = 0; i < np; i++)
        ps[i + 1] += ps[i];
    {
        dk_index *fill = malloc(((size_t)np + 1) * sizeof *fill);
        if (!fill) {
            st = dk_error_set(err, DK_ERR_OUT_OF_MEMORY, "VolumetricARAP embed: out of memory");
            goto done;
        }
        memcpy(fill, ps, (size_t)np * sizeof *fill);
        for (dk_index t = 0; t < nt; t++)
            for (int k = 0; k < 4; k++)
                pt[fill[in->tets[4 * (size_t)t + (size_t)k]]++] = t;
        free(fill);
    }
    e->p_start[0] = 0;
    for (dk_index v = 0; v < n; v++) {
        dk_index at = e->p_start[v];
        if (d->coarse_of[v] >= 0) {
            e->p_col[at] = d->coarse_of[v];
            e->p_w[at++] = 1.0;
            e->p_start[v + 1] = at;
            continue;
        }
        const double *q = m->positions + 3 * (size_t)v;
        const dk_index a = anchor[v];
        dk_index nc = 0, best = -1;
        double best_min = -INFINITY, l[4], bl[4] = {1, 0, 0, 0};
        for (int ring = 0; ring < 2 && !(best_min >= -1e-12); ring++) {
            const dk_index from = nc;
            if (ring == 0) {
                for (dk_index r = ps[a]; r < ps[a + 1]; r++)
                    if (seen[pt[r]] != v) {
                        seen[pt[r]] = v;
                        cand[nc++] = pt[r];
                    }
            } else {
                for (dk_index c = 0; c < from; c++)
                    for (int k = 0; k < 4; k++) {
                        const dk_index u = in->tets[4 * (size_t)cand[c] + (size_t)k];
                        for (dk_index r = ps[u]; r < ps[u + 1]; r++)
                            if (seen[pt[r]] != v) {
                                seen[pt[r]] = v;
                                cand[nc++] = pt[r];
                            }
                    }
            }
            for (dk_index c = ring == 0 ? 0 : from; c < nc; c++) {
                if (flat[cand[c]])
                    continue;
                const double mn = coordinates(frames + 12 * (size_t)cand[c], q, l);
                if (mn > best_min) {
                    best_min = mn;
                    best = cand[c];
                    memcpy(bl, l, sizeof l);
                }
            }
        }
        if (best < 0) { /* no tetrahedron around it with a volume: its anchor */
            e->p_col[at] = a;
            e->p_w[at++] = 1.0;
        } else {
            for (int k = 0; k < 4; k++) {
                e->p_col[at] = in->tets[4 * (size_t)best + (size_t)k];
                e->p_w[at++] = bl[k];
            }
        }
        e->p_start[v + 1] = at;
    }
done:
    free(anchor), free(ps), free(pt), free(frames), free(flat), free(seen), free(cand);
    return st;
}

/* Forwards the coarse bind's progress as the part done of the running phase. */
static int forward(void *user, const char *phase, double fraction)
{
    dk_error ignored = {0};
    (void)phase;
    return dk_progress_part(user, fraction, &ignored) != DK_OK;
}

dk_status volumetric_embedding_build(const dk_volumetric_arap *va, dk_progress *progress,
                                     volumetric_embedding **out, dk_error *err)
{
    *out = NULL;
    const dk_mesh *m = va->mesh;
    const dk_mesh_report *r = &m->report;
    if (r->n_boundary_edges || r->n_nonmanifold_edges || r->n_isolated_vertices)
        return dk_error_set(err, DK_ERR_TOPOLOGY,
                            "VolumetricARAP embed: a coarse volume carries only a surface "
                            "whose every part is closed (%d boundary edges, %d non-manifold "
                            "edges, %d loose vertices here); embed=1 deforms the open parts "
                            "as surfaces",
                            (int)r->n_boundary_edges, (int)r->n_nonmanifold_edges,
                            (int)r->n_isolated_vertices);
    volumetric_embedding *e = calloc(1, sizeof *e);
    if (!e)
        return dk_error_set(err, DK_ERR_OUT_OF_MEMORY, "VolumetricARAP embed: out of memory");
    dk_index *hv_fine = NULL;
    /* the simplification, twice as fine where TetGen refuses it, up to an eighth of the
     * mesh (what estimate_memory charges; a small mesh, up to all of it) */
    dk_status st = volumetric_coarse_build(va, volumetric_embed_most(va->n), va->opt.levels,
                                           progress ? forward : NULL, progress, &e->level,
                                           &hv_fine, err);
    if (st == DK_OK && !e->level)
        st = dk_error_set(err, DK_ERR_TOPOLOGY,
                          "VolumetricARAP embed: no coarse volume carries this surface: its "
                          "simplification stopped above an eighth of it, or TetGen refused "
                          "the simplified surfaces (their triangles cross: the mesh's closed "
                          "parts may cross each other); embed=1 deforms such a mesh as a "
                          "surface");
    const dk_index n = va->n;
    const dk_constraints *con = va->con;
    if (st == DK_OK) {
        const dk_volumetric_arap *in = e->level->coarse;
        const dk_index nc = in->n, nhc = in->con->n_handle_vertices;
        const size_t nh = (size_t)con->n_handle_vertices;
        e->hv = malloc(((size_t)nhc + 1) * sizeof *e->hv);
        e->p_start = malloc(((size_t)n + 1) * sizeof *e->p_start);
        e->p_col = malloc((4 * (size_t)n + 1) * sizeof *e->p_col);
        e->p_w = malloc((4 * (size_t)n + 1) * sizeof *e->p_w);
        e->pose_c = malloc((3 * (size_t)nc + 1) * sizeof *e->pose_c);
        e->start_c = malloc((3 * (size_t)nc + 1) * sizeof *e->start_c);
        e->targets_c = malloc((3 * (size_t)nhc + 1) * sizeof *e->targets_c);
        e->surface_c = malloc((3 * (size_t)nc + 1) * sizeof *e->surface_c);
        e->targets = malloc((3 * nh + 1) * sizeof *e->targets);
        e->scratch_c = malloc((3 * (size_t)nc + 1) * sizeof *e->scratch_c);
        dk_index *order = malloc(((size_t)n + 1) * sizeof *order);
        if (!e->hv || !e->p_start || !e->p_col || !e->p_w || !e->pose_c || !e->start_c ||
            !e->targets_c || !e->surface_c || !e->targets || !e->scratch_c || !order) {
            st = dk_error_set(err, DK_ERR_OUT_OF_MEMORY, "VolumetricARAP embed: out of memory");
        } else {
            /* each coarse handle vertex's place among the surface's handle vertices */
            for (dk_index k = 0; k < con->n_handle_vertices; k++)
                order[con->handle_vertices[k]] = k;
            for (dk_index j = 0; j < nhc; j++)
                e->hv[j] = order[hv_fine[j]];
            st = carrier_map(m, e->level->dec, in, e, err);
        }
        free(order);
    }
    free(hv_fine);
    if (st != DK_OK) {
        volumetric_embedding_free(e);
        return st == DK_ERR_CANCELLED || st == DK_ERR_OUT_OF_MEMORY || st == DK_ERR_TOPOLOGY
                   ? st
                   : dk_error_prefix(err, "VolumetricARAP embed");
    }
    *out = e;
    return DK_OK;
}

/* Restricts rows (n x 3) to the kept vertices (n_c x 3). */
static void restrict_rows(const dk_decimation *d, const double *rows, double *out)
{
    for (dk_index k = 0; k < d->n_kept; k++)
        memcpy(out + 3 * (size_t)k, rows + 3 * (size_t)d->kept[k], 3 * sizeof *out);
}

dk_status volumetric_embedding_solve(dk_volumetric_arap *va, const dk_solve_request *rq,
                                     double *positions, dk_solve_info *info, dk_error *err)
{
    volumetric_embedding *e = va->emb;
    dk_volumetric_arap *in = e->level->coarse;
    const dk_decimation *d = e->level->dec;
    const dk_constraints *con = va->con;
    const double *pose = rq->input_positions ? rq->input_positions : va->mesh->positions;
    /* the surface's targets, expanded and checked before anything changes */
    dk_status st = dk_constraints_targets(con, pose, rq->targets,
                                          rq->target_kind == DK_TARGETS_TRANSFORMS, e->targets,
                                          err);
    if (st != DK_OK)
        return dk_error_prefix(err, "VolumetricARAP solve");
    dk_solve_request inner = *rq;
    if (rq->input_positions) {
        restrict_rows(d, rq->input_positions, e->pose_c);
        inner.input_positions = e->pose_c;
    }
    if (rq->start == DK_START_GIVEN) {
        restrict_rows(d, rq->start_positions, e->start_c);
        inner.start_positions = e->start_c;
    }
    if (rq->target_kind != DK_TARGETS_TRANSFORMS) {
        const dk_index nhc = in->con->n_handle_vertices;
        for (dk_index j = 0; j < nhc; j++)
            memcpy(e->targets_c + 3 * (size_t)j, rq->targets + 3 * (size_t)e->hv[j],
                   3 * sizeof(double));
        inner.targets = e->targets_c;
    }
    st = dk_volumetric_arap_solve(in, &inner, e->surface_c, info, err);
    if (st != DK_OK)
        return st;
    /* x = p + P (y - y_p): the coarse volume's move at each vertex's coordinates */
    const double *y = in->last, *yp = rq->input_positions ? in->input_full : volume_points(in);
    for (dk_index v = 0; v < va->n; v++) {
        double dx[3] = {0, 0, 0};
        for (dk_index t = e->p_start[v]; t < e->p_start[v + 1]; t++) {
            const size_t c = 3 * (size_t)e->p_col[t];
            for (int k = 0; k < 3; k++)
                dx[k] += e->p_w[t] * (y[c + (size_t)k] - yp[c + (size_t)k]);
        }
        for (int k = 0; k < 3; k++)
            positions[3 * (size_t)v + (size_t)k] = pose[3 * (size_t)v + (size_t)k] + dx[k];
    }
    /* the constraints exactly: hard handle vertices at their targets, fixed and held ones
     * where the pose puts them (soft handle vertices are where the volume took them) */
    for (dk_index v = 0; v < va->n; v++)
        if (con->role[v] == DK_VERTEX_FIXED)
            memcpy(positions + 3 * (size_t)v, pose + 3 * (size_t)v, 3 * sizeof(double));
    for (dk_index k = 0; k < con->n_handle_vertices; k++)
        if (con->handle_weights[k] == 1.0)
            memcpy(positions + 3 * (size_t)con->handle_vertices[k], e->targets + 3 * (size_t)k,
                   3 * sizeof(double));
    /* the coarse solve checked its own result; the carried one is checked here (the
     * energy is the coarse solve's, checked there) */
    return dk_solve_result_check(positions, va->n, 0.0, 0, "VolumetricARAP solve", err);
}

dk_status volumetric_embedding_energy(const dk_volumetric_arap *va, const double *positions,
                                      double *energy, dk_error *err)
{
    const volumetric_embedding *e = va->emb;
    dk_status st = dk_check_positions(positions, va->n, err);
    if (st != DK_OK)
        return dk_error_prefix(err, "VolumetricARAP energy");
    restrict_rows(e->level->dec, positions, e->scratch_c);
    return dk_volumetric_arap_energy(e->level->coarse, e->scratch_c, energy, err);
}

dk_status volumetric_embedding_response_basis(const dk_volumetric_arap *va, double *out,
                                              dk_error *err)
{
    const volumetric_embedding *e = va->emb;
    const dk_volumetric_arap *in = e->level->coarse;
    dk_arap_counters c;
    dk_arap_get_counters(in->arap, &c);
    const size_t cols = (size_t)c.basis_columns;
    double *all = malloc(((size_t)in->np * cols + 1) * sizeof *all);
    if (!all)
        return dk_error_set(err, DK_ERR_OUT_OF_MEMORY,
                            "VolumetricARAP response basis: out of memory");
    dk_status st = dk_arap_response_basis(in->arap, all, err);
    const dk_constraints *con = va->con;
    if (st == DK_OK) { /* rows of the coarse points, carried to the surface by P */
        for (dk_index v = 0; v < va->n; v++) {
            double *row = out + cols * (size_t)v;
            memset(row, 0, cols * sizeof *row);
            if (con->role[v] == DK_VERTEX_FIXED) /* where the pose puts it, as the solve */
                continue;
            for (dk_index t = e->p_start[v]; t < e->p_start[v + 1]; t++) {
                const double *src = all + cols * (size_t)e->p_col[t];
                for (size_t j = 0; j < cols; j++)
                    row[j] += e->p_w[t] * src[j];
            }
        }
        /* a hard handle vertex moves with its handle's transform, exactly: its rest
         * position and 1 in the handle's four columns (ARAP's rows for it) */
        for (dk_index h = 0; h < con->n_handles && 4 * (size_t)h + 3 < cols; h++)
            for (dk_index k = con->handle_start[h]; k < con->handle_start[h + 1]; k++) {
                if (con->handle_weights[k] != 1.0)
                    continue;
                const dk_index v = con->handle_vertices[k];
                double *row = out + cols * (size_t)v;
                memset(row, 0, cols * sizeof *row);
                memcpy(row + 4 * (size_t)h, va->mesh->positions + 3 * (size_t)v,
                       3 * sizeof *row);
                row[4 * (size_t)h + 3] = 1.0;
            }
    }
    free(all);
    return st;
}
