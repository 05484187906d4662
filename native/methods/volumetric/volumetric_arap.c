/* DeformKit: volumetric ARAP, the public verbs (dk_volumetric_arap.h). See
 * volumetric_internal.h for the files of this folder, docs/methods/volumetric_arap.md for
 * the choices and measurements. */
#include "volumetric_internal.h"

#include <float.h>
#include <limits.h>
#include <math.h>
#include <stdio.h>

void dk_volumetric_arap_default_options(dk_volumetric_arap_options *o)
{
    if (!o)
        return;
    dk_arap_options a;
    dk_arap_default_options(&a);
    o->quality = 1.5; /* TetGen's usual bound: no needles, few points added */
    o->max_volume = 0.0;
    o->max_iterations = a.max_iterations;
    o->tolerance = a.tolerance;
    o->acceleration = a.acceleration;
    o->cg_iterations = a.cg_iterations;
    o->levels = 0;
    o->embed = 0;
    o->progress = NULL;
    o->progress_user = NULL;
}

/* The bind's phases, weighted by their measured seconds (the 43k armadillo, defaults). */
static const dk_progress_phase bind_phases[] = {
    {"tetrahedralize", 6.0}, /* TetGen (uninterruptible) and the volume mesh               */
    {"interior", 0.6},       /* the harmonic extension's factor                            */
    {"arap", 3.0},           /* ARAP's bind on the tetrahedra, its own phases inside        */
    {"coarse", 0.7}};        /* the multi-scale solve's coarse level (none below 10k points
                                by default; uninterruptible)                                */

/* The embedded domain's bind (embed 2): the coarse volume, its own phases inside. */
static const dk_progress_phase embed_phases[] = {{"coarse volume", 1.0}};

static void arap_options(const dk_volumetric_arap_options *o, dk_arap_options *a);

/* A bound on max_volume: TetGen's refinement to a tiny size cannot be interrupted. */
#define MAX_TETRAHEDRA 5e7

/* The volume of the mesh's bounding box (0 for a flat one). */
static double box_volume(const dk_mesh *m)
{
    double v = 1.0;
    for (int k = 0; k < 3; k++)
        v *= m->bbox_max[k] - m->bbox_min[k];
    return v;
}

/* Every option, the solver's too (what ARAP's bind would refuse, before TetGen's seconds). */
static dk_status check_options(const dk_mesh *mesh, const dk_volumetric_arap_options *o,
                               dk_error *err)
{
    if (!(o->quality == 0.0 || (o->quality >= 1.1 && o->quality <= 10.0)))
        return dk_error_set(err, DK_ERR_INVALID_ARGUMENT,
                            "VolumetricARAP: quality is %g, must be 0 (none) or in [1.1, 10] "
                            "(the tetrahedra's largest radius-edge ratio)", o->quality);
    if (o->levels < 0 || o->levels > 2)
        return dk_error_set(err, DK_ERR_INVALID_ARGUMENT,
                            "VolumetricARAP: levels is %d, must be 1 or 2 (0: automatic)",
                            o->levels);
    if (o->embed < 0 || o->embed > 2)
        return dk_error_set(err, DK_ERR_INVALID_ARGUMENT,
                            "VolumetricARAP: embed is %d, must be 1 (the surface is the "
                            "volume's boundary) or 2 (a coarse volume carries it); 0: "
                            "automatic", o->embed);
    if (!(o->max_volume >= 0.0 && o->max_volume <= 1e300))
        return dk_error_set(err, DK_ERR_INVALID_ARGUMENT,
                            "VolumetricARAP: max_volume is %g, must be 0 (none) or > 0",
                            o->max_volume);
    const double box = box_volume(mesh);
    if (o->max_volume > 0.0 && box / o->max_volume > MAX_TETRAHEDRA)
        return dk_error_set(err, DK_ERR_INVALID_ARGUMENT,
                            "VolumetricARAP: max_volume %g would cut the mesh's box (%g) into "
                            "more than %.0e tetrahedra: raise it", o->max_volume, box,
                            MAX_TETRAHEDRA);
    dk_arap_options a;
    uint64_t ignored;
    arap_options(o, &a);
    const dk_status st = dk_arap_estimate_memory(mesh, &a, &ignored, err); /* checks them */
    return st == DK_OK ? DK_OK : dk_error_prefix(err, "VolumetricARAP");
}

static void arap_options(const dk_volumetric_arap_options *o, dk_arap_options *a)
{
    dk_arap_default_options(a);
    a->max_iterations = o->max_iterations;
    a->tolerance = o->tolerance;
    a->acceleration = o->acceleration;
    a->cg_iterations = o->cg_iterations;
    /* ARAP's own levels serve a mesh that bounds no volume at all (on the tetrahedra it
     * builds none): none when none is asked for */
    a->levels = o->levels == 1 ? 1 : 0;
}

void dk_volumetric_arap_free(dk_volumetric_arap *va)
{
    if (!va)
        return;
    dk_arap_free(va->arap); /* first: it borrows the level's object */
    volumetric_level_free(va->level);
    volumetric_embedding_free(va->emb);
    volumetric_extension_free(va);
    dk_constraints_free(va->con);
    dk_mesh_free(va->volume);
    free(va->tets);
    free(va->input_full);
    free(va->input_key);
    free(va->start_full);
    free(va->full);
    free(va->last);
    free(va->scratch);
    free(va);
}

/* ARAP's bind progress, forwarded as the part done of the phase "arap". */
static int forward_progress(void *user, const char *phase, double fraction)
{
    dk_error ignored = {0};
    (void)phase;
    return dk_progress_part(user, fraction, &ignored) != DK_OK;
}

/* ARAP on the tetrahedra with the surface's constraints carried into the volume; a rebind
 * when the object has one. On failure nothing changes. */
static dk_status bind_solver(dk_volumetric_arap *va, const dk_constraint_desc *c,
                             dk_progress *prog, dk_error *err)
{
    dk_constraints *con = NULL;
    dk_constraint_desc vd;
    dk_index *roi;
    double *stiffness;
    dk_status st = volumetric_constraints(va, c, &con, &vd, &roi, &stiffness, err);
    if (st != DK_OK)
        return st;
    if (va->arap) {
        st = dk_arap_rebind(va->arap, &vd, err);
    } else {
        dk_arap_options a;
        arap_options(&va->opt, &a);
        a.progress = prog ? forward_progress : NULL;
        a.progress_user = prog;
        st = va->volume ? dk_arap_bind_tetrahedra(va->volume, va->tets, va->nt, &vd, &a,
                                                  &va->arap, err)
                        : dk_arap_bind(va->mesh, &vd, &a, &va->arap, err);
    }
    free(roi);
    free(stiffness);
    if (st != DK_OK) {
        dk_constraints_free(con);
        return st == DK_ERR_CANCELLED ? st : dk_error_prefix(err, "VolumetricARAP");
    }
    dk_constraints_free(va->con);
    va->con = con;
    /* the coarse level for these constraints (the rebind dropped the old one's attachment);
     * an accelerator: when it cannot be built (out of memory included), solves run without
     * it */
    volumetric_level_free(va->level);
    va->level = NULL;
    if (prog && dk_progress_begin(prog, 3, err) != DK_OK)
        return DK_ERR_CANCELLED;
    dk_error ignored = {0};
    if (volumetric_level_build(va, &va->level, &ignored) != DK_OK)
        va->level = NULL;
    return DK_OK;
}

dk_status dk_volumetric_arap_bind(const dk_mesh *mesh, const dk_constraint_desc *constraints,
                                  const dk_volumetric_arap_options *options,
                                  dk_volumetric_arap **out, dk_error *err)
{
    if (out)
        *out = NULL;
    if (!mesh || !constraints || !out)
        return dk_error_set(err, DK_ERR_INVALID_ARGUMENT,
                            "VolumetricARAP bind: mesh, constraints and output must not be "
                            "NULL");
    dk_volumetric_arap_options opt;
    if (options)
        opt = *options;
    else
        dk_volumetric_arap_default_options(&opt);
    dk_status st = check_options(mesh, &opt, err);
    if (st != DK_OK)
        return st;
    /* the constraints first: bad ones are refused before TetGen's seconds */
    dk_constraints *check = NULL;
    if ((st = dk_constraints_create(mesh, constraints, &check, err)) != DK_OK)
        return dk_error_prefix(err, "VolumetricARAP");
    dk_constraints_free(check);
    dk_volumetric_arap *va = calloc(1, sizeof *va);
    if (!va)
        return dk_error_set(err, DK_ERR_OUT_OF_MEMORY, "VolumetricARAP bind: out of memory");
    va->mesh = mesh;
    va->opt = opt;
    va->opt.progress = NULL; /* the caller's callback is for this bind only */
    va->opt.progress_user = NULL;
    va->n = mesh->n_vertices;
    int surface_only = 0;
    if (volumetric_embed_wanted(mesh, &opt)) { /* a coarse volume carries the surface */
        dk_progress prog;
        dk_progress_init(&prog, opt.progress, opt.progress_user, embed_phases, 1,
                         "VolumetricARAP bind");
        st = dk_constraints_create(mesh, constraints, &va->con, err);
        if (st != DK_OK)
            st = dk_error_prefix(err, "VolumetricARAP");
        if (st == DK_OK)
            st = dk_progress_begin(&prog, 0, err);
        if (st == DK_OK)
            st = volumetric_embedding_build(va, &prog, &va->emb, err);
        if (st == DK_OK) {
            dk_progress_done(&prog);
            *out = va;
            return DK_OK;
        }
        if (!(st == DK_ERR_TOPOLOGY && opt.embed == 0)) {
            dk_volumetric_arap_free(va);
            return st;
        }
        /* automatic: no coarse volume carries it (its closed parts cross), and its own would
         * not fit: it deforms as a surface, as embed=1 would after TetGen's refusal, without
         * TetGen's minutes on the whole mesh */
        dk_constraints_free(va->con);
        va->con = NULL;
        surface_only = 1;
        st = DK_OK;
        if (err)
            memset(err, 0, sizeof *err);
        snprintf(va->note, sizeof va->note,
                 "no volume: no coarse volume carries it (TetGen refused the simplified "
                 "surfaces: its closed parts may cross each other)");
    }
    dk_progress prog;
    dk_progress_init(&prog, opt.progress, opt.progress_user, bind_phases,
                     (int)(sizeof bind_phases / sizeof bind_phases[0]), "VolumetricARAP bind");
    /* 1. the tetrahedra */
    st = dk_progress_begin(&prog, 0, err);
    if (st == DK_OK && !surface_only)
        st = volumetric_domain(va, &prog, err);
    else if (st == DK_OK) { /* no tetrahedra: ARAP on the surface */
        va->np = va->n;
        va->nt = 0;
    }
    /* 2. the interior's harmonic extension */
    if (st == DK_OK)
        st = dk_progress_begin(&prog, 1, err);
    if (st == DK_OK)
        st = volumetric_extension_build(va, err);
    /* 3. the poses' buffers */
    if (st == DK_OK) {
        const size_t bytes = 3 * (size_t)va->np * sizeof(double);
        va->input_full = malloc(bytes);
        va->input_key = malloc(3 * (size_t)va->n * sizeof(double));
        va->start_full = malloc(bytes);
        va->full = malloc(bytes);
        va->last = malloc(bytes);
        va->scratch = malloc(bytes);
        if (!va->input_full || !va->input_key || !va->start_full || !va->full || !va->last ||
            !va->scratch)
            st = dk_error_set(err, DK_ERR_OUT_OF_MEMORY, "VolumetricARAP bind: out of memory");
        else
            memcpy(va->last, volume_points(va), bytes);
    }
    /* 4. ARAP on the tetrahedra */
    if (st == DK_OK)
        st = dk_progress_begin(&prog, 2, err);
    if (st == DK_OK)
        st = bind_solver(va, constraints, &prog, err);
    if (st != DK_OK) {
        dk_volumetric_arap_free(va);
        return st;
    }
    dk_progress_done(&prog);
    *out = va;
    return DK_OK;
}

dk_status dk_volumetric_arap_rebind(dk_volumetric_arap *va,
                                    const dk_constraint_desc *constraints, dk_error *err)
{
    if (!va || !constraints)
        return dk_error_set(err, DK_ERR_INVALID_ARGUMENT,
                            "VolumetricARAP rebind: object and constraints must not be NULL");
    if (!va->emb)
        return bind_solver(va, constraints, NULL, err);
    /* the embedded domain: the simplification keeps the roles, so new constraints need a
     * new coarse volume; on failure the old one stays */
    dk_volumetric_arap tmp = *va;
    tmp.con = NULL;
    tmp.emb = NULL;
    dk_status st = dk_constraints_create(va->mesh, constraints, &tmp.con, err);
    if (st != DK_OK)
        return dk_error_prefix(err, "VolumetricARAP rebind");
    dk_progress prog;
    dk_progress_init(&prog, va->rebind_progress, va->rebind_user, embed_phases, 1,
                     "VolumetricARAP rebind");
    st = dk_progress_begin(&prog, 0, err);
    if (st == DK_OK)
        st = volumetric_embedding_build(&tmp, &prog, &tmp.emb, err);
    if (st != DK_OK) {
        dk_constraints_free(tmp.con);
        return st;
    }
    dk_progress_done(&prog);
    dk_constraints_free(va->con);
    volumetric_embedding_free(va->emb);
    va->con = tmp.con;
    va->emb = tmp.emb;
    return DK_OK;
}

void dk_volumetric_arap_set_progress(dk_volumetric_arap *va, dk_phase_progress_fn progress,
                                     void *user)
{
    if (!va)
        return;
    va->rebind_progress = progress;
    va->rebind_user = user;
    if (va->arap)
        dk_arap_set_progress(va->arap, progress, user);
}

/* The input pose extended into the volume (cached: a pose extended once serves every solve
 * that edits it); NULL when the request edits the rest. */
static dk_status take_input(dk_volumetric_arap *va, const dk_solve_request *rq,
                            const double **input, dk_error *err)
{
    *input = NULL;
    if (!rq->input_positions)
        return DK_OK;
    const size_t bytes = 3 * (size_t)va->n * sizeof(double);
    if (!va->have_input || memcmp(va->input_key, rq->input_positions, bytes) != 0) {
        va->have_input = 0;
        const dk_status st = volumetric_extend(va, volume_points(va), rq->input_positions,
                                               va->input_full, va->rhs, err);
        if (st != DK_OK)
            return st;
        memcpy(va->input_key, rq->input_positions, bytes);
        va->have_input = 1;
    }
    *input = va->input_full;
    return DK_OK;
}

dk_status dk_volumetric_arap_solve(dk_volumetric_arap *va, const dk_solve_request *rq,
                                   double *positions, dk_solve_info *info, dk_error *err)
{
    if (info)
        memset(info, 0, sizeof *info);
    if (!va || !positions)
        return dk_error_set(err, DK_ERR_INVALID_ARGUMENT,
                            "VolumetricARAP solve: object and positions must not be NULL");
    dk_status st = dk_solve_request_check_input(rq, va->n, "VolumetricARAP solve", err);
    if (st == DK_OK && rq->start == DK_START_GIVEN)
        st = dk_start_positions_check(rq->start_positions, va->n, "VolumetricARAP solve", err);
    if (st != DK_OK)
        return st;
    if (va->emb)
        return volumetric_embedding_solve(va, rq, positions, info, err);
    /* 1. the pose edited, and a given start, extended into the volume */
    const double *input = NULL;
    if ((st = take_input(va, rq, &input, err)) != DK_OK)
        return st;
    dk_solve_request inner = *rq;
    inner.input_positions = input;
    if (rq->start == DK_START_GIVEN) {
        st = volumetric_extend(va, input ? input : volume_points(va), rq->start_positions,
                               va->start_full, va->rhs, err);
        if (st != DK_OK)
            return st;
        inner.start_positions = va->start_full;
    }
    /* 2. ARAP on the tetrahedra */
    st = dk_arap_solve(va->arap, &inner, va->full, info, err);
    if (st != DK_OK)
        return st == DK_ERR_CANCELLED ? st : dk_error_prefix(err, "VolumetricARAP");
    /* 3. the surface out, the volume kept for energy() */
    memcpy(positions, va->full, 3 * (size_t)va->n * sizeof(double));
    memcpy(va->last, va->full, 3 * (size_t)va->np * sizeof(double));
    return DK_OK;
}

dk_status dk_volumetric_arap_energy(const dk_volumetric_arap *va, const double *positions,
                                    double *energy, dk_error *err)
{
    if (energy)
        *energy = NAN;
    if (!va || !positions || !energy)
        return dk_error_set(err, DK_ERR_INVALID_ARGUMENT,
                            "VolumetricARAP energy: object, positions and energy must not be "
                            "NULL");
    if (va->emb)
        return volumetric_embedding_energy(va, positions, energy, err);
    dk_status st = dk_check_positions(positions, va->n, err);
    if (st == DK_OK)
        st = volumetric_extend(va, va->last, positions, va->scratch, va->rhs, err);
    if (st == DK_OK)
        st = dk_arap_energy(va->arap, va->scratch, energy, err);
    return st == DK_OK ? DK_OK : dk_error_prefix(err, "VolumetricARAP energy");
}

void dk_volumetric_arap_stats(const dk_volumetric_arap *va, dk_method_stats *stats)
{
    if (!stats)
        return;
    memset(stats, 0, sizeof *stats);
    if (!va)
        return;
    dk_method_stats inner;
    dk_arap_stats(dk_volumetric_arap_solver((dk_volumetric_arap *)va), &inner);
    stats->n_vertices = va->n;
    stats->n_handles = va->con->n_handles;
    stats->n_handle_vertices = va->con->n_handle_vertices;
    dk_constraints_held_stats(va->con, NULL, stats);
    stats->n_unknowns = inner.n_unknowns;
    stats->analysis_count = inner.analysis_count;
    stats->factorization_count = inner.factorization_count;
}

dk_arap *dk_volumetric_arap_solver(dk_volumetric_arap *va)
{
    if (va && va->emb)
        return dk_volumetric_arap_solver(volumetric_embedding_inner(va->emb));
    return va ? va->arap : NULL;
}

dk_status dk_volumetric_arap_response_basis(const dk_volumetric_arap *va, double *out,
                                            dk_error *err)
{
    if (!va || !out)
        return dk_error_set(err, DK_ERR_INVALID_ARGUMENT,
                            "VolumetricARAP response basis: object and out must not be NULL");
    if (va->emb)
        return volumetric_embedding_response_basis(va, out, err);
    dk_arap_counters c;
    dk_arap_get_counters(va->arap, &c);
    if (va->np == va->n || c.basis_columns == 0) /* no interior: the rows are the mesh's */
        return dk_arap_response_basis(va->arap, out, err);
    const size_t row = (size_t)c.basis_columns * sizeof(double);
    double *all = malloc((size_t)va->np * row);
    if (!all)
        return dk_error_set(err, DK_ERR_OUT_OF_MEMORY,
                            "VolumetricARAP response basis: out of memory");
    const dk_status st = dk_arap_response_basis(va->arap, all, err);
    if (st == DK_OK)
        memcpy(out, all, (size_t)va->n * row); /* the vertices are the first points */
    free(all);
    return st;
}

int dk_volumetric_arap_embedded(const dk_volumetric_arap *va)
{
    return va && va->emb ? 1 : 0;
}

const char *dk_volumetric_arap_note(const dk_volumetric_arap *va)
{
    return va ? va->note : "";
}

void dk_volumetric_arap_get_counters(const dk_volumetric_arap *va,
                                     dk_volumetric_arap_counters *c)
{
    if (!c)
        return;
    memset(c, 0, sizeof *c);
    if (!va)
        return;
    if (va->emb) { /* the coarse volume's */
        dk_volumetric_arap_get_counters(volumetric_embedding_inner(va->emb), c);
        return;
    }
    c->n_points = va->np;
    c->n_interior_points = va->np - va->n;
    c->n_tetrahedra = va->nt;
}

void dk_volumetric_arap_tetrahedra(const dk_volumetric_arap *va, double *points,
                                   dk_index *tetrahedra)
{
    if (!va)
        return;
    if (va->emb) {
        dk_volumetric_arap_tetrahedra(volumetric_embedding_inner(va->emb), points, tetrahedra);
        return;
    }
    if (points)
        memcpy(points, va->last, 3 * (size_t)va->np * sizeof(double));
    if (tetrahedra && va->nt > 0)
        memcpy(tetrahedra, va->tets, 4 * (size_t)va->nt * sizeof(dk_index));
}

/* ---------------------------------------------------------------- state ------------------ */

/* This object's part: the last solved volume (energy's interior); ARAP's state follows. */
static void own_spans(const dk_volumetric_arap *va, dk_state_span sp[1])
{
    sp[0] = (dk_state_span){va->last, 3 * (size_t)va->np * sizeof(double)};
}

static void shape_of(const dk_volumetric_arap *va, uint64_t shape[4])
{
    shape[0] = (uint64_t)va->n;
    shape[1] = (uint64_t)va->np;
    shape[2] = (uint64_t)va->nt;
    shape[3] = 0;
}

size_t dk_volumetric_arap_state_size(const dk_volumetric_arap *va)
{
    if (!va)
        return 0;
    if (va->emb) /* the coarse volume's: the surface follows from it */
        return dk_volumetric_arap_state_size(volumetric_embedding_inner(va->emb));
    dk_state_span sp[1];
    own_spans(va, sp);
    return dk_state_size(sp, 1) + dk_arap_state_size(va->arap);
}

dk_status dk_volumetric_arap_save_state(const dk_volumetric_arap *va, void *state, size_t size,
                                        dk_error *err)
{
    if (!va)
        return dk_error_set(err, DK_ERR_INVALID_ARGUMENT, "VolumetricARAP save_state: NULL");
    if (va->emb)
        return dk_volumetric_arap_save_state(volumetric_embedding_inner(va->emb), state, size,
                                             err);
    dk_state_span sp[1];
    uint64_t shape[4];
    own_spans(va, sp);
    shape_of(va, shape);
    const size_t own = dk_state_size(sp, 1), want = own + dk_arap_state_size(va->arap);
    if (!state || size != want)
        return dk_error_set(err, DK_ERR_INVALID_ARGUMENT,
                            "VolumetricARAP save_state: the buffer must be state_size() = %zu "
                            "bytes, not %zu", want, state ? size : (size_t)0);
    dk_status st = dk_state_save("VolumetricARAP", shape, sp, 1, state, own, err);
    if (st == DK_OK)
        st = dk_arap_save_state(va->arap, (unsigned char *)state + own, size - own, err);
    return st;
}

dk_status dk_volumetric_arap_restore_state(dk_volumetric_arap *va, const void *state,
                                           size_t size, dk_error *err)
{
    if (!va)
        return dk_error_set(err, DK_ERR_INVALID_ARGUMENT, "VolumetricARAP restore_state: NULL");
    if (va->emb)
        return dk_volumetric_arap_restore_state(volumetric_embedding_inner(va->emb), state,
                                                size, err);
    dk_state_span sp[1];
    uint64_t shape[4];
    own_spans(va, sp);
    shape_of(va, shape);
    const size_t own = dk_state_size(sp, 1);
    dk_status st = dk_state_check("VolumetricARAP", shape, sp, 1, state,
                                  size < own ? size : own, err);
    if (st == DK_OK) /* ARAP's part (its own header, shape and size checked) first: it
                        refuses without changing anything */
        st = dk_arap_restore_state(va->arap, (const unsigned char *)state + own, size - own,
                                   err);
    if (st != DK_OK)
        return st;
    dk_state_restore_spans(sp, 1, state);
    va->have_input = 0; /* a cache: rebuilt from the next input */
    return DK_OK;
}

/* ---------------------------------------------------------------- memory ---------------- */

/* A bind's bytes for a surface of nv vertices (the mesh's, or its coarse volume's). */
static uint64_t volume_bytes(const dk_mesh *mesh, const dk_volumetric_arap_options *o,
                             double nv)
{
    /* the points: the vertices, and the interior's (about a third as many at quality 1.5
     * without a size bound, measured on the shared meshes; a size bound adds about one per
     * six tetrahedra of that volume) */
    double n = 1.35 * nv;
    if (o->max_volume > 0.0)
        n += box_volume(mesh) / o->max_volume / 6.0;
    /* the coarse level (levels 0 or 2): a volume of its own for a sixteenth of the surface */
    if (o->levels != 1)
        n += 1.35 * nv / 16.0;
    const double lg = n > 2.0 ? log2(n) : 1.0;
    /* TetGen's mesh and the tetrahedra's ARAP per point (docs/methods/volumetric_arap.md) */
    return dk_memory_model(6000.0 + 150.0 * lg, n, 0.0);
}

dk_status dk_volumetric_arap_estimate_memory(const dk_mesh *mesh,
                                             const dk_volumetric_arap_options *options,
                                             uint64_t *bytes, dk_error *err)
{
    if (!mesh || !bytes)
        return dk_error_set(err, DK_ERR_INVALID_ARGUMENT,
                            "VolumetricARAP estimate_memory: mesh and bytes must not be NULL");
    dk_status st = options ? check_options(mesh, options, err) : DK_OK;
    if (st != DK_OK)
        return st;
    dk_volumetric_arap_options o;
    if (options)
        o = *options;
    else
        dk_volumetric_arap_default_options(&o);
    const double nv = (double)mesh->n_vertices;
    if (volumetric_embed_wanted(mesh, &o)) { /* the coarse volume at its largest retry; it
                                                grows its own tetrahedra (no size bound) */
        o.max_volume = 0.0;
        *bytes = volumetric_embedding_bytes(
            nv, volume_bytes(mesh, &o, (double)volumetric_embed_most(mesh->n_vertices)));
    } else {
        *bytes = volume_bytes(mesh, &o, nv);
    }
    return DK_OK;
}

/* ---------------------------------------------------------------- the method contract --- */

static const dk_option_desc volumetric_fields[] = {
    {"quality", DK_OPTION_DOUBLE, offsetof(dk_volumetric_arap_options, quality), 0, 1.1, 10.0,
     1.5, 10.0, DK_OPTION_ZERO_AUTO},
    {"max_volume", DK_OPTION_DOUBLE, offsetof(dk_volumetric_arap_options, max_volume), 0, 0.0,
     DBL_MAX, 0.0, DBL_MAX, 0},
    {"max_iterations", DK_OPTION_INT, offsetof(dk_volumetric_arap_options, max_iterations), 0,
     1, INT_MAX, 100, 40, 0},
    {"tolerance", DK_OPTION_DOUBLE, offsetof(dk_volumetric_arap_options, tolerance), 0, 0,
     DBL_MAX, 1e-6, DBL_MAX, 0},
    {"acceleration", DK_OPTION_ENUM, offsetof(dk_volumetric_arap_options, acceleration), 0, 0,
     2, 2, 2, 0},
    {"cg_iterations", DK_OPTION_INT, offsetof(dk_volumetric_arap_options, cg_iterations), 0, 1,
     100, 12, 100, 0},
    {"levels", DK_OPTION_INT, offsetof(dk_volumetric_arap_options, levels), 0, 1, 2, 2, 2,
     DK_OPTION_ZERO_AUTO},
    {"embed", DK_OPTION_INT, offsetof(dk_volumetric_arap_options, embed), 0, 1, 2, 2, 2,
     DK_OPTION_ZERO_AUTO},
};

DK_METHOD_OPS_STATEFUL(dk_volumetric_arap_ops, "VolumetricARAP",
                       DK_METHOD_ITERATIVE | DK_METHOD_TRANSFORMS_AS_POSITIONS |
                           DK_METHOD_TRANSLATION_INVARIANT | DK_METHOD_RIGID_INVARIANT |
                           DK_METHOD_GIVEN_START | DK_METHOD_EDITS_INPUT |
                           DK_METHOD_INTERIOR,
                       DK_CONTROL_VERTEX_GROUPS, dk_volumetric_arap, dk_volumetric_arap,
                       dk_volumetric_arap_options, volumetric_fields);
