/* DeformKit ARAP: its state (dk_method_ops.state_size): everything a solve leaves for the
 * next call to read (not the settings: the tolerance and the CG count stay the object's), so that a restored object continues bit for bit as the saved one would
 * (see arap_internal.h). The pose a solve edited is part of it: a warm start's drag history
 * is kept only while the pose stays (take_pose), and energy() reads the pose's edges. */
#include "arap_internal.h"

enum { MAX_SPANS = 48 };

/* The scalars, in one block so that each is named once. */
typedef struct arap_scalars {
    int have_prev, n_hist, basis_starts;
    int have_targets, resumable, aa_hist, aa_head, aa_have_pair, predicted, start_pending;
    int cut, cg_level, nt_indefinite, base_is_input, coarse_active;
    double last_energy, nt_decrease, nt_ratio[2], nt_ratio_before;
} arap_scalars;

/* The object's state as spans over its own buffers (scratch `sc` for the scalars, `pose`
 * for the edited pose, n x 3). Buffers a configuration lacks (Anderson's history under
 * Newton) are 0-byte spans, so that every object of one shape has one layout. */
static int spans_of(const dk_arap *ar_const, arap_scalars *sc, double *pose, dk_state_span *sp)
{
    dk_arap *ar = (dk_arap *)ar_const; /* save reads through the same list restore writes */
    arap_system *s = &ar->sys;
    const size_t n = (size_t)ar->n, N = 3 * (size_t)s->nu;
    const size_t nhv = 3 * (size_t)s->con->n_handle_vertices;
    const size_t m = (size_t)ar->opt.anderson_depth;
    const size_t D = sizeof(double);
    int k = 0;
#define SPAN(ptr, count) (sp[k++] = (dk_state_span){(ptr), (ptr) ? (count) * sizeof *(ptr) : 0})
    sp[k++] = (dk_state_span){sc, sizeof *sc};
    sp[k++] = (dk_state_span){pose, 3 * n * D};
    SPAN(ar->x, 3 * n);
    SPAN(ar->rot, 9 * (size_t)ar->nc);
    SPAN(ar->prev, 3 * n);
    SPAN(ar->prev2, 3 * n);
    SPAN(s->targets, nhv);
    SPAN(s->targets_prev, nhv);
    SPAN(s->targets_prev2, nhv);
    SPAN(s->rhs_const, N);
    SPAN(s->rhs, N);
    SPAN(s->xu, N);
    SPAN(s->gu, N);
    SPAN(s->warm, 2 * N);
    SPAN(s->fu, N);
    SPAN(s->gprev, N);
    SPAN(s->fprev, N);
    SPAN(s->dg, N * m);
    SPAN(s->df, N * m);
    sp[k++] = (dk_state_span){s->aa_gram, sizeof s->aa_gram};
    SPAN(s->kinv, 6 * (size_t)ar->nc);
    SPAN(s->omega, 3 * (size_t)ar->nc);
    SPAN(s->vfull, 3 * n);
    SPAN(s->nt_r, N);
    SPAN(s->nt_z, N);
    SPAN(s->nt_p, N);
    SPAN(s->nt_q, N);
    SPAN(s->nt_d, N);
    SPAN(s->nt_z0, N);
    /* Newton's R_c g_{v,c} per right-hand-side entry, written with the right-hand side: a
     * resumed step's Hessian products read them */
    SPAN(s->nt, s->rg_start ? (size_t)s->rg_start[s->nu] : 0);
#undef SPAN
    return k;
}

static void gather_scalars(const dk_arap *ar, arap_scalars *sc)
{
    const arap_system *s = &ar->sys;
    memset(sc, 0, sizeof *sc);
    *sc = (arap_scalars){.have_prev = ar->have_prev,
                         .n_hist = ar->n_hist,
                         .basis_starts = ar->basis_starts,
                         .have_targets = s->have_targets,
                         .resumable = s->resumable,
                         .aa_hist = s->aa_hist,
                         .aa_head = s->aa_head,
                         .aa_have_pair = s->aa_have_pair,
                         .predicted = s->predicted,
                         .start_pending = s->start_pending,
                         .cut = s->cut,
                         .cg_level = s->cg_level,
                         .nt_indefinite = s->nt_indefinite,
                         .base_is_input = ar->base != ar->mesh->positions,
                         .coarse_active = s->coarse_active,
                         .last_energy = s->last_energy,
                         .nt_decrease = s->nt_decrease,
                         .nt_ratio = {s->nt_ratio[0], s->nt_ratio[1]},
                         .nt_ratio_before = s->nt_ratio_before};
}

static void scatter_scalars(dk_arap *ar, const arap_scalars *sc)
{
    arap_system *s = &ar->sys;
    ar->have_prev = sc->have_prev;
    ar->n_hist = sc->n_hist;
    ar->basis_starts = sc->basis_starts;
    s->have_targets = sc->have_targets;
    s->resumable = sc->resumable;
    s->aa_hist = sc->aa_hist;
    s->aa_head = sc->aa_head;
    s->aa_have_pair = sc->aa_have_pair;
    s->predicted = sc->predicted;
    s->start_pending = sc->start_pending;
    s->cut = sc->cut;
    s->cg_level = sc->cg_level;
    s->nt_indefinite = sc->nt_indefinite;
    s->coarse_active = sc->coarse_active;
    s->last_energy = sc->last_energy;
    s->nt_decrease = sc->nt_decrease;
    s->nt_ratio[0] = sc->nt_ratio[0];
    s->nt_ratio[1] = sc->nt_ratio[1];
    s->nt_ratio_before = sc->nt_ratio_before;
}

/* Whether the scalars of a state are ones a solve can leave (a damaged or forged state must
 * not index outside a buffer or shift past an int): flags 0 or 1, the counts and the
 * history's head within their ranges. The doubles need no check: a non-finite iterate
 * makes the next solve fail its result check, as a non-finite solve would. */
static int scalars_valid(const dk_arap *ar, const arap_scalars *sc)
{
    const int flags[] = {sc->have_prev,    sc->have_targets,
                         sc->resumable,    sc->aa_have_pair, sc->predicted,
                         sc->start_pending, sc->cut,         sc->nt_indefinite,
                         sc->base_is_input, sc->coarse_active};
    for (size_t k = 0; k < sizeof flags / sizeof flags[0]; k++)
        if (flags[k] != 0 && flags[k] != 1)
            return 0;
    const int depth = ar->opt.anderson_depth;
    return sc->n_hist >= 0 && sc->n_hist <= 2 && sc->basis_starts >= 0 &&
           sc->aa_hist >= 0 && sc->aa_hist <= depth && sc->aa_head >= 0 &&
           sc->aa_head <= (depth > 0 ? depth - 1 : 0) && sc->cg_level >= 0 &&
           sc->cg_level <= 2;
}

/* What the object's layout depends on: a state fits another object with the same. */
static void shape_of(const dk_arap *ar, uint64_t shape[4])
{
    shape[0] = (uint64_t)ar->n;
    shape[1] = (uint64_t)ar->sys.con->n_handle_vertices;
    shape[2] = (uint64_t)ar->sys.nu;
    shape[3] = (uint64_t)ar->opt.acceleration * 1000u + (uint64_t)ar->opt.anderson_depth;
}

size_t dk_arap_state_size(const dk_arap *ar)
{
    if (!ar)
        return 0;
    arap_scalars sc;
    dk_state_span sp[MAX_SPANS];
    return dk_state_size(sp, spans_of(ar, &sc, NULL, sp));
}

dk_status dk_arap_save_state(const dk_arap *ar, void *state, size_t size, dk_error *err)
{
    if (!ar)
        return dk_error_set(err, DK_ERR_INVALID_ARGUMENT, "ARAP save_state: object is NULL");
    arap_scalars sc;
    gather_scalars(ar, &sc);
    dk_state_span sp[MAX_SPANS];
    const int k = spans_of(ar, &sc, (double *)ar->base, sp); /* the pose, read only */
    uint64_t shape[4];
    shape_of(ar, shape);
    return dk_state_save("ARAP", shape, sp, k, state, size, err);
}

dk_status dk_arap_restore_state(dk_arap *ar, const void *state, size_t size, dk_error *err)
{
    if (!ar)
        return dk_error_set(err, DK_ERR_INVALID_ARGUMENT, "ARAP restore_state: object is NULL");
    arap_scalars sc;
    dk_state_span sp[MAX_SPANS];
    const int k = spans_of(ar, &sc, NULL, sp);
    uint64_t shape[4];
    shape_of(ar, shape);
    dk_status st = dk_state_check("ARAP", shape, sp, k, state, size, err);
    if (st != DK_OK)
        return st;
    const size_t pose_bytes = 3 * (size_t)ar->n * sizeof(double);
    const unsigned char *blob = (const unsigned char *)state + sizeof(dk_state_header);
    memcpy(&sc, blob, sizeof sc);
    if (!scalars_valid(ar, &sc))
        return dk_error_set(err, DK_ERR_INVALID_ARGUMENT,
                            "ARAP restore_state: the state is damaged (its counters are out "
                            "of range)");
    /* the buffers the pose needs, before anything changes */
    if (!ar->input_next && !(ar->input_next = malloc(pose_bytes + sizeof(double))))
        return dk_error_set(err, DK_ERR_OUT_OF_MEMORY,
                            "ARAP restore_state: out of memory (the pose)");
    if (sc.base_is_input && !ar->input && !(ar->input = malloc(pose_bytes + sizeof(double))))
        return dk_error_set(err, DK_ERR_OUT_OF_MEMORY,
                            "ARAP restore_state: out of memory (the pose)");
    /* the pose first: its edges and what the system made of them, as take_pose does */
    const double *base = ar->mesh->positions;
    if (sc.base_is_input) {
        memcpy(ar->input, blob + sizeof sc, pose_bytes);
        base = ar->input;
    }
    ar->base = base;
    arap_cells_set_edges(ar, base);
    arap_system_edges_changed(ar, &ar->sys);
    /* then every buffer, the pose's span into scratch (it is in place already) */
    double *scratch_pose = ar->input_next;
    const int k2 = spans_of(ar, &sc, scratch_pose, sp);
    dk_state_restore_spans(sp, k2, state);
    scatter_scalars(ar, &sc);
    if (ar->sys.nt) /* the entries' cells are the system's, never the state's */
        for (int64_t e = 0; e < ar->sys.rg_start[ar->sys.nu]; e++)
            ar->sys.nt[e].cell = ar->sys.rg[e].cell;
    return DK_OK;
}
