/* DeformKit volumetric ARAP: the coarse level of the multi-scale solve (volumetric_internal.h,
 * volumetric_level_build). Built for each set of constraints, after ARAP's bind or rebind on
 * the tetrahedra:
 *   1. the surface simplified to a sixteenth of its vertices (dk_decimate, each vertex's
 *      handle, soft-handle, fixed or free role kept, so the coarse handles are mesh vertices
 *      and hold exactly where the mesh's do);
 *   2. a VolumetricARAP bound on it with the constraints restricted (its own TetGen run:
 *      coarse tetrahedra whose boundary is the coarse surface);
 *   3. the prolongation P: each point of the volume at the coarse point it is (a kept
 *      vertex), or located in the coarse tetrahedra at rest, its barycentric coordinates
 *      extrapolated where it lies outside them (the fine surface bulges past the coarse one
 *      between kept vertices): P then moves every point by an affine map of the coarse
 *      points exactly; the restriction R of an iterate likewise the other way, each coarse
 *      interior point located in the fine tetrahedra;
 *   4. attached to the fine ARAP object (dk_arap_attach_coarse_level), which solves a cold
 *      start there first (its corrections of the Newton steps are not asked for: they did
 *      not pay on volumes, below).
 * It is an accelerator: where a step fails for the mesh's reasons (the simplification blocked,
 * TetGen refusing the coarse surface, a part that bounds no volume) there is no level and
 * solves run as without it; running out of memory is reported to the caller (the bind and
 * rebind go on without a level then too). */
#include "volumetric_internal.h"

#include "dk_operators.h"

/* how many times fewer surface vertices the coarse level has (ARAP's ratio) */
#define COARSE_RATIO 16
/* the level gives cold starts only: its corrections of the Newton steps did not pay on
 * volumes (measured, 90-degree bend and 180-degree twist of the armadillo: 43k vertices,
 * 5 and 29 steps with them, 5 and 31 without, 1.4 / 7.3 s against 1.2 / 6.9 s; subdivided
 * to 173k, the bend 100 steps in 149 s with them, 99 in 112 s without: both cross the same
 * plateau, docs/methods/volumetric_arap.md "Multi-scale") */
#define NO_CORRECTIONS 0
/* levels 0 (automatic) adds the level from this many points (surface and interior) on:
 * the level costs its bind (the 43k armadillo: 0.7 s on 5.5 s) and makes cold solves 3-4x
 * faster (the 8k arm too: 0.47 -> 0.17 s for a 90-degree bend; docs/methods/
 * volumetric_arap.md, "Multi-scale") */
#define AUTO_MIN_POINTS 10000
/* the coarse surface's fewest vertices (unless that is more than a quarter of the mesh's):
 * a coarser one cannot follow a big edit, and its solve sends the mesh's into another
 * basin (measured: a capped tube of 822 vertices twisted by 180 degrees, a coarse level of
 * 51 surface vertices: a minimum 42% higher than the single level's; with 205 the same) */
#define MIN_COARSE_VERTICES 256

void volumetric_level_free(volumetric_level *l)
{
    if (!l)
        return;
    dk_volumetric_arap_free(l->coarse);
    dk_mesh_free(l->mesh);
    dk_decimation_free(l->dec);
    free(l);
}

/* The tetrahedra with a volume (into kept, *n_kept of them; a flat one has no coordinates)
 * and per kept one its corner 0 and the gradients of corners 1..3 (into f: the frames
 * dk_locate_in_tetrahedra takes). */
static void tet_frames(const double *p, const dk_index *tets, dk_index nt, dk_index *kept,
                       dk_index *n_kept, double *f)
{
    dk_index m = 0;
    for (dk_index t = 0; t < nt; t++) {
        const dk_index *q = tets + 4 * (size_t)t;
        double g[12];
        if (dk_tetrahedron_frame(p + 3 * (size_t)q[0], p + 3 * (size_t)q[1],
                                 p + 3 * (size_t)q[2], p + 3 * (size_t)q[3], g) == 0.0)
            continue;
        memcpy(kept + 4 * (size_t)m, q, 4 * sizeof *kept);
        memcpy(f + 12 * (size_t)m, p + 3 * (size_t)q[0], 3 * sizeof *f);
        memcpy(f + 12 * (size_t)m + 3, g + 3, 9 * sizeof *f);
        m++;
    }
    *n_kept = m;
}

dk_status volumetric_map_rows(const double *p, dk_index np, const dk_index *tets, dk_index nt,
                          const double *queries, const dk_index *same, dk_index rows,
                          dk_index *start, dk_index *col, double *w, dk_error *err)
{
    dk_index nq = 0;
    for (dk_index i = 0; i < rows; i++)
        nq += same[i] < 0;
    double *frames = malloc((12 * (size_t)nt + 1) * sizeof *frames);
    dk_index *kept = malloc((4 * (size_t)nt + 1) * sizeof *kept), n_kept = 0;
    double *qp = malloc((3 * (size_t)nq + 1) * sizeof *qp);
    dk_index *qc = malloc((4 * (size_t)nq + 1) * sizeof *qc);
    double *qw = malloc((4 * (size_t)nq + 1) * sizeof *qw);
    dk_status st = DK_OK;
    if (!frames || !kept || !qp || !qc || !qw) {
        st = dk_error_set(err, DK_ERR_OUT_OF_MEMORY, "VolumetricARAP: out of memory (coarse "
                          "level)");
        goto done;
    }
    tet_frames(p, tets, nt, kept, &n_kept, frames);
    for (dk_index i = 0, k = 0; i < rows; i++)
        if (same[i] < 0)
            memcpy(qp + 3 * (size_t)k++, queries + 3 * (size_t)i, 3 * sizeof *qp);
    if (nq > 0 && (st = dk_locate_in_tetrahedra(p, np, kept, frames, n_kept, 0.0,
                                                 DK_LOCATE_EXTRAPOLATE, qp, nq, qc, qw,
                                                 err)) != DK_OK)
        goto done;
    start[0] = 0;
    for (dk_index i = 0, k = 0; i < rows; i++) {
        dk_index e = start[i];
        if (same[i] >= 0) {
            col[e] = same[i];
            w[e++] = 1.0;
        } else {
            for (int c = 0; c < 4; c++)
                if (qc[4 * (size_t)k + c] >= 0) {
                    col[e] = qc[4 * (size_t)k + c];
                    w[e++] = qw[4 * (size_t)k + c];
                }
            k++;
        }
        start[i + 1] = e;
    }
done:
    free(frames);
    free(kept);
    free(qp);
    free(qc);
    free(qw);
    return st;
}

/* Steps 1 and 2 for a coarse surface of at most m vertices: the simplified surface and its
 * VolumetricARAP (*out NULL: none, *refused set when TetGen refused the coarse surface). */
static dk_status coarse_object(const dk_volumetric_arap *va, dk_index m, dk_index most,
                               int levels, dk_phase_progress_fn progress, void *user,
                               volumetric_level **out, dk_index **hv_fine, int *refused,
                               dk_error *err)
{
    *out = NULL;
    *refused = 0;
    const dk_constraints *con = va->con;
    const dk_index n = va->n;
    volumetric_level *l = calloc(1, sizeof *l);
    int *cls = malloc(((size_t)n + 1) * sizeof *cls);
    if (!l || !cls) {
        free(l);
        free(cls);
        return dk_error_set(err, DK_ERR_OUT_OF_MEMORY, "VolumetricARAP: out of memory "
                            "(coarse level)");
    }
    dk_constraints_classes(con, cls); /* every role kept, hard and soft handles apart */
    dk_error ignored = {0};
    dk_status st = dk_decimate(va->mesh, cls, m, &l->dec, &ignored);
    free(cls);
    if (st != DK_OK || l->dec->n_kept > most || l->dec->n_faces == 0)
        goto none; /* blocked collapses: a level would not pay its solve */
    const dk_decimation *d = l->dec;
    double *cp = malloc((3 * (size_t)d->n_kept + 1) * sizeof *cp);
    if (!cp) {
        st = DK_ERR_OUT_OF_MEMORY;
        goto none;
    }
    for (dk_index k = 0; k < d->n_kept; k++)
        memcpy(cp + 3 * (size_t)k, va->mesh->positions + 3 * (size_t)d->kept[k],
               3 * sizeof *cp);
    st = dk_mesh_create(cp, d->n_kept, d->faces, d->n_faces, &l->mesh, &ignored);
    free(cp);
    if (st != DK_OK)
        goto none;
    dk_coarse_constraints cc;
    st = dk_coarse_constraints_create(con, d, &cc, err);
    if (st == DK_OK) {
        dk_volumetric_arap_options o = va->opt;
        o.levels = levels;
        o.embed = 1;
        o.max_volume = 0.0; /* a size bound is the mesh's: the coarse level grows its own */
        o.progress = progress;
        o.progress_user = user;
        dk_error inner = {0};
        st = dk_volumetric_arap_bind(l->mesh, &cc.desc, &o, &l->coarse, &inner);
        if (st == DK_ERR_CANCELLED)
            dk_error_set(err, st, "%s", inner.message);
    }
    *hv_fine = cc.fine_vertex; /* the attachment's handle vertices: kept from cc */
    cc.fine_vertex = NULL;
    dk_coarse_constraints_free(&cc);
    if (st == DK_OK && (l->coarse->nt == 0 || l->coarse->note[0])) {
        *refused = 1; /* TetGen refused the coarse surface (its triangles cross) */
        st = DK_ERR_TOPOLOGY;
    }
    if (st != DK_OK)
        goto none;
    *out = l;
    return DK_OK;
none:
    volumetric_level_free(l);
    free(*hv_fine);
    *hv_fine = NULL;
    if (st == DK_ERR_CANCELLED)
        return st;
    return st == DK_ERR_OUT_OF_MEMORY ? dk_error_set(err, st, "VolumetricARAP: out of memory "
                                                     "(coarse level)")
                                      : DK_OK;
}

dk_status volumetric_coarse_build(const dk_volumetric_arap *va, dk_index most, int levels,
                                  dk_phase_progress_fn progress, void *user,
                                  volumetric_level **out, dk_index **hv_fine, dk_error *err)
{
    *out = NULL;
    *hv_fine = NULL;
    dk_status st = DK_OK;
    /* a simplified surface can cross itself where the mesh is thin (a tube of 40 around
     * decimated to 10); TetGen refuses it, and a less simplified one is tried, up to `most`
     * vertices */
    dk_index m = va->n / COARSE_RATIO > MIN_COARSE_VERTICES ? va->n / COARSE_RATIO
                                                            : MIN_COARSE_VERTICES;
    if (m > most)
        m = most;
    for (int last = 0; m >= 1 && !last && !*out && st == DK_OK; m *= 2) {
        if (m >= most) {
            m = most;
            last = 1;
        }
        int refused = 0;
        st = coarse_object(va, m, most, levels, progress, user, out, hv_fine, &refused, err);
        if (!refused)
            break;
    }
    return st;
}

dk_status volumetric_level_build(dk_volumetric_arap *va, volumetric_level **out, dk_error *err)
{
    *out = NULL;
    const int levels = va->opt.levels;
    if (levels == 1 || va->nt == 0 || va->note[0] ||
        (levels == 0 && va->np < AUTO_MIN_POINTS) || va->n / 4 < 16)
        return DK_OK;
    dk_index *hv_fine = NULL;
    volumetric_level *l = NULL;
    dk_status st = volumetric_coarse_build(va, va->n / 4, 1, NULL, NULL, &l, &hv_fine, err);
    if (st != DK_OK || !l)
        return st;
    /* 3. the maps: P over the coarse points (np rows), R over the fine ones (cnp rows) */
    const dk_volumetric_arap *cva = l->coarse;
    const dk_decimation *d = l->dec;
    const dk_index np = va->np, cnp = cva->np, mk = d->n_kept;
    dk_index *same = malloc(((size_t)(np > cnp ? np : cnp) + 1) * sizeof *same);
    dk_index *ps = malloc(((size_t)np + 1) * sizeof *ps), *pc = malloc((4 * (size_t)np + 1) * sizeof *pc);
    dk_index *rs = malloc(((size_t)cnp + 1) * sizeof *rs), *rc = malloc((4 * (size_t)cnp + 1) * sizeof *rc);
    double *pw = malloc((4 * (size_t)np + 1) * sizeof *pw), *rw = malloc((4 * (size_t)cnp + 1) * sizeof *rw);
    if (!same || !ps || !pc || !rs || !rc || !pw || !rw) {
        st = dk_error_set(err, DK_ERR_OUT_OF_MEMORY, "VolumetricARAP: out of memory (coarse "
                          "level)");
        goto done;
    }
    for (dk_index i = 0; i < np; i++)
        same[i] = i < va->n ? d->coarse_of[i] : -1;
    st = volumetric_map_rows(volume_points(cva), cnp, cva->tets, cva->nt, volume_points(va),
                             same, np, ps, pc, pw, err);
    if (st != DK_OK)
        goto done;
    for (dk_index j = 0; j < cnp; j++)
        same[j] = j < mk ? d->kept[j] : -1;
    st = volumetric_map_rows(volume_points(va), np, va->tets, va->nt, volume_points(cva), same,
                             cnp, rs, rc, rw, err);
    if (st != DK_OK)
        goto done;
    /* 4. attached */
    dk_error ignored = {0};
    dk_method_stats cs;
    dk_arap_stats(cva->arap, &cs);
    st = dk_arap_attach_coarse_level(va->arap, cva->arap, hv_fine, cs.n_handle_vertices, ps,
                                     pc, pw, rs, rc, rw, NO_CORRECTIONS, &ignored);
    if (st == DK_OK) {
        *out = l;
        l = NULL;
    } else if (st == DK_ERR_OUT_OF_MEMORY) {
        dk_error_set(err, st, "VolumetricARAP: out of memory (coarse level)");
    } else {
        st = DK_OK; /* cannot happen (the restriction is the constraints'): no level */
    }
done:
    volumetric_level_free(l);
    free(hv_fine);
    free(same);
    free(ps);
    free(pc);
    free(pw);
    free(rs);
    free(rc);
    free(rw);
    return st;
}
