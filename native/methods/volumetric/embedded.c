/* DeformKit volumetric ARAP: the embedded domain (the option embed; volumetric_internal.h).
 * A coarse volume carries the surface, for meshes whose own volume would not fit (the 3D
 * factor fills in: about 12 KB a vertex, so 3 GB is passed from about 250,000 vertices):
 *   1. the surface simplified to a sixteenth of its vertices, each vertex's handle, fixed or
 *      free role kept, tetrahedralized and bound as a VolumetricARAP of its own with the
 *      constraints restricted (multiscale.c's coarse volume, volumetric_coarse_build: its
 *      TetGen run retried with more vertices where the simplified surface crosses itself);
 *   2. each vertex of the surface located in the coarse tetrahedra at rest (a kept vertex is
 *      its coarse point), its barycentric coordinates extrapolated outside them (between
 *      kept vertices the surface bulges past the coarse one): the map P moves every vertex
 *      by an affine map of the coarse points exactly;
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
    /* any simplification will do (a small mesh may keep most of its vertices), and where
     * TetGen refuses the simplified surfaces, the mesh's own */
    dk_status st = volumetric_coarse_build(va, va->n, va->opt.levels,
                                           progress ? forward : NULL, progress, &e->level,
                                           &hv_fine, err);
    if (st == DK_OK && !e->level)
        st = dk_error_set(err, DK_ERR_TOPOLOGY,
                          "VolumetricARAP embed: no volume carries this surface: TetGen "
                          "refused it and its simplifications (its triangles cross, or its "
                          "closed parts cross each other); embed=1 deforms it as a surface");
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
            /* P: a kept vertex is its coarse point, the others located in the tetrahedra */
            for (dk_index v = 0; v < n; v++)
                order[v] = e->level->dec->coarse_of[v];
            st = volumetric_map_rows(volume_points(in), in->np, in->tets, in->nt,
                                     m->positions, order, n, e->p_start, e->p_col, e->p_w,
                                     err);
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
    return DK_OK;
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
    if (st == DK_OK) /* rows of the coarse points, carried to the surface by P */
        for (dk_index v = 0; v < va->n; v++) {
            double *row = out + cols * (size_t)v;
            memset(row, 0, cols * sizeof *row);
            for (dk_index t = e->p_start[v]; t < e->p_start[v + 1]; t++) {
                const double *src = all + cols * (size_t)e->p_col[t];
                for (size_t j = 0; j < cols; j++)
                    row[j] += e->p_w[t] * src[j];
            }
        }
    free(all);
    return st;
}
