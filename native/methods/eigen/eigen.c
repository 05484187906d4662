/* DeformKit: eigen deformation (Dey, Ranjan & Wang). See dk_eigen.h for the method,
 * eigen_internal.h for the files, and docs/methods/eigen.md for the choices the paper
 * leaves open. */
#include "eigen_internal.h"

#include <float.h>
#include <limits.h>
#include <math.h>
#include <stdlib.h>
#include <string.h>

dk_status eigen_oom(dk_error *err, const char *what)
{
    return dk_error_set(err, DK_ERR_OUT_OF_MEMORY, "EigenDeformation: out of memory (%s)", what);
}

void dk_eigen_default_options(dk_eigen_options *o)
{
    memset(o, 0, sizeof *o);
    o->n_eigenvectors = 0;
    o->refine = 300;
    o->laplacian = DK_EIGEN_COTANGENT;
    o->region = DK_EIGEN_REGION_PART;
    o->bsw_width = 1.0;
}

/* section 4.2 */
static int automatic_m(double delta3)
{
    return delta3 >= 0.75 ? 8 : delta3 >= 0.1 ? 50 : 300;
}

void dk_eigen_free(dk_eigen *e)
{
    if (!e)
        return;
    free(e->evals);
    free(e->U);
    free(e->chol);
    eigen_level_free(&e->lv[0]);
    eigen_level_free(&e->lv[1]);
    eigen_regions_free(&e->r);
    free(e->ptil);
    free(e->pstar);
    free(e->normals);
    free(e->b);
    free(e->next);
    free(e->cm);
    free(e);
}

static dk_status check_options(const dk_eigen_options *o, dk_index n, dk_error *err)
{
    if (o->laplacian != DK_EIGEN_COTANGENT && o->laplacian != DK_EIGEN_BELKIN_SUN_WANG)
        return dk_error_set(err, DK_ERR_INVALID_ARGUMENT,
                            "EigenDeformation: laplacian must be cotangent (0) or "
                            "belkin_sun_wang (1)");
    if (o->region != DK_EIGEN_REGION_PART && o->region != DK_EIGEN_REGION_HANDLES)
        return dk_error_set(err, DK_ERR_INVALID_ARGUMENT,
                            "EigenDeformation: region must be part (0) or handles (1)");
    if (!(o->bsw_width > 0.0) || !isfinite(o->bsw_width))
        return dk_error_set(err, DK_ERR_INVALID_ARGUMENT,
                            "EigenDeformation: bsw_width must be finite and > 0");
    if (o->n_eigenvectors < 0 || o->n_eigenvectors > n)
        return dk_error_set(err, DK_ERR_INVALID_ARGUMENT,
                            "EigenDeformation: n_eigenvectors is %d; it must be 0 (automatic) "
                            "to %d (the vertex count)", o->n_eigenvectors, (int)n);
    if (o->refine < 0)
        return dk_error_set(err, DK_ERR_INVALID_ARGUMENT,
                            "EigenDeformation: refine is %d; it must be >= 0 (0: one iteration)",
                            o->refine);
    return DK_OK;
}

/* The constant eigenvectors beyond the first: one per further connected component. Each
 * component's constant has eigenvalue 0, so they come first and a small component takes one
 * whatever its size; the automatic count adds them to section 4.2's (the paper's models have
 * one component; a scan with loose pieces would otherwise give the body none of its 8). */
static int extra_constants(const dk_eigen *e)
{
    const dk_index c = e->mesh->report.n_components - e->mesh->report.n_isolated_vertices;
    return c > 1 ? (int)(c - 1) : 0; /* an isolated vertex has no eigenvector of its own */
}

/* The eigenvector count for the regions: the option (at most n), or section 4.2's rule
 * capped at n / 4 (at least 4), plus the components' constants: on a small mesh the rule's
 * 50 or 300 would be most of the spectrum, and a fit with that many no longer smooths the
 * cut of Step 1 (with n of them it reproduces the cut exactly). */
static int choose_m(const dk_eigen *e, double delta3)
{
    if (e->opt.n_eigenvectors > 0)
        return e->opt.n_eigenvectors < e->n ? e->opt.n_eigenvectors : (int)e->n;
    const int rule = automatic_m(delta3), cap = (int)(e->n / 4) > 4 ? (int)(e->n / 4) : 4;
    const int64_t m = (int64_t)(rule < cap ? rule : cap) + extra_constants(e);
    return m < e->n ? (int)m : (int)e->n;
}

dk_status dk_eigen_bind(const dk_mesh *mesh, const dk_constraint_desc *desc,
                        const dk_eigen_options *options, dk_eigen **out, dk_error *err)
{
    if (!out)
        return dk_error_set(err, DK_ERR_INVALID_ARGUMENT, "EigenDeformation: out is NULL");
    *out = NULL;
    if (!mesh || !desc)
        return dk_error_set(err, DK_ERR_INVALID_ARGUMENT,
                            "EigenDeformation: mesh and constraints must not be NULL");
    if (mesh->n_faces == 0 || mesh->n_vertices < 4)
        return dk_error_set(err, DK_ERR_TOPOLOGY,
                            "EigenDeformation: needs a surface (faces and at least 4 vertices); "
                            "this mesh has %d vertices and %d faces", (int)mesh->n_vertices,
                            (int)mesh->n_faces);
    dk_eigen *e = calloc(1, sizeof *e);
    if (!e)
        return eigen_oom(err, "object");
    e->mesh = mesh;
    e->n = mesh->n_vertices;
    if (options)
        e->opt = *options;
    else
        dk_eigen_default_options(&e->opt);
    const dk_index n = e->n;
    dk_status st = check_options(&e->opt, n, err);
    if (st != DK_OK) {
        free(e);
        return st;
    }
    e->ptil = malloc(3 * (size_t)n * sizeof *e->ptil);
    e->pstar = malloc(3 * (size_t)n * sizeof *e->pstar);
    e->normals = malloc(3 * (size_t)n * sizeof *e->normals);
    e->next = malloc(3 * (size_t)n * sizeof *e->next);
    e->cm = malloc(3 * (size_t)n * sizeof *e->cm);
    if (!e->ptil || !e->pstar || !e->normals || !e->next || !e->cm) {
        dk_eigen_free(e);
        return eigen_oom(err, "buffers");
    }
    e->tiny = eigen_frame_threshold(mesh);
    /* 1. the regions; 2. the eigenvectors (K = max(m, n') so that a later rebind, whose
     * automatic m may differ, needs none); 3. the skeletons */
    dk_progress_init(&e->prog, e->opt.progress, e->opt.progress_user, eigen_phases,
                     EIGEN_N_PHASES, "EigenDeformation");
    st = dk_progress_begin(&e->prog, EIGEN_PHASE_REGIONS, err);
    if (st == DK_OK)
        st = eigen_regions_build(e, desc, &e->r, err);
    if (st == DK_OK) {
        const int m = choose_m(e, e->r.delta3);
        int K = m;
        if (e->opt.refine > K)
            K = e->opt.refine;
        if (e->opt.n_eigenvectors == 0 && K < 300 + extra_constants(e))
            K = 300 + extra_constants(e); /* the automatic rule may ask for 300 */
        e->K = K < n ? K : (int)n;
        /* n' (section 4.3) is refine itself: the K computed for the automatic rule's sake
         * (a rebind may ask for up to 300) must not make Detail Shapes 100 fit 300 */
        const int64_t np = (int64_t)e->opt.refine +
                           (e->opt.n_eigenvectors == 0 ? extra_constants(e) : 0);
        e->n_prime = np < e->K ? (int)np : e->K;
        e->b = malloc(3 * (size_t)e->K * sizeof *e->b);
        st = e->b ? eigen_eigenvectors(e, err) : eigen_oom(err, "buffers");
        if (st == DK_OK)
            st = eigen_skeletons(e, m, err);
    }
    if (st != DK_OK) {
        dk_eigen_free(e);
        return st;
    }
    dk_progress_done(&e->prog);
    e->opt.progress = NULL; /* the caller's callback is for this bind only */
    e->opt.progress_user = NULL;
    dk_progress_init(&e->prog, NULL, NULL, eigen_phases, 1, "EigenDeformation");
    *out = e;
    return DK_OK;
}

dk_status dk_eigen_rebind(dk_eigen *e, const dk_constraint_desc *desc, dk_error *err)
{
    if (!e || !desc)
        return dk_error_set(err, DK_ERR_INVALID_ARGUMENT,
                            "EigenDeformation rebind: object and constraints must not be NULL");
    eigen_regions R;
    dk_status st = eigen_regions_build(e, desc, &R, err);
    const int m = st == DK_OK ? choose_m(e, R.delta3) : 0;
    if (st == DK_OK && m > e->K)
        st = dk_error_set(err, DK_ERR_INVALID_ARGUMENT,
                          "EigenDeformation rebind: these regions need %d eigenvectors and %d "
                          "were computed at bind: bind again", m, e->K);
    if (st == DK_OK && eigen_whole_count(e, m) != e->m) { /* a new m: new skeletons (the
                                                             eigenvectors stay) */
        level keep[2] = {e->lv[0], e->lv[1]};
        const int keep_m = e->m, keep_levels = e->n_levels;
        memset(e->lv, 0, sizeof e->lv);
        st = eigen_skeletons(e, m, err);
        if (st != DK_OK) {
            eigen_level_free(&e->lv[0]);
            eigen_level_free(&e->lv[1]);
            e->lv[0] = keep[0];
            e->lv[1] = keep[1];
            e->m = keep_m;
            e->n_levels = keep_levels;
        } else {
            eigen_level_free(&keep[0]);
            eigen_level_free(&keep[1]);
        }
    }
    if (st != DK_OK) {
        eigen_regions_free(&R);
        return st;
    }
    eigen_regions_free(&e->r);
    e->r = R;
    return DK_OK;
}

int dk_eigen_preview(const dk_eigen *e)
{
    return e ? e->preview : 0;
}

void dk_eigen_set_preview(dk_eigen *e, int preview)
{
    if (e)
        e->preview = preview != 0;
}

dk_status dk_eigen_energy(const dk_eigen *e, const double *positions, double *energy,
                          dk_error *err)
{
    if (!e || !positions || !energy)
        return dk_error_set(err, DK_ERR_INVALID_ARGUMENT,
                            "EigenDeformation energy: arguments must not be NULL");
    const dk_constraints *c = e->r.con;
    double E = 0.0;
    /* R's vertices against their targets, the others against the rest */
    for (dk_index i = 0; i < e->n; i++)
        if (c->role[i] < 0)
            for (int r = 0; r < 3; r++) {
                const double d = positions[3 * (size_t)i + r] - e->mesh->positions[3 * (size_t)i + r];
                E += d * d;
            }
    for (dk_index q = 0; q < c->n_handle_vertices; q++) {
        const dk_index i = c->handle_vertices[q];
        for (int r = 0; r < 3; r++) {
            const double d = positions[3 * (size_t)i + r] - e->r.target[3 * (size_t)q + r];
            E += d * d;
        }
    }
    *energy = E;
    return dk_energy_result_check(E, "EigenDeformation energy", err);
}

dk_status dk_eigen_solve(dk_eigen *e, const dk_solve_request *rq, double *positions,
                         dk_solve_info *info, dk_error *err)
{
    if (info)
        memset(info, 0, sizeof *info);
    if (!e || !positions)
        return dk_error_set(err, DK_ERR_INVALID_ARGUMENT,
                            "EigenDeformation solve: object and positions must not be NULL");
    dk_status st = eigen_read_request(e, rq, err);
    if (st != DK_OK)
        return st;
    /* Steps 1-2 on the first level */
    const level *L = &e->lv[0];
    eigen_step1_step2_rhs(e, L);
    eigen_fit(e, L->m, e->b, e->pstar);
    const int preview = rq->preview || e->preview;
    if (preview) { /* the skeleton's motion, details unrotated */
        for (size_t i = 0; i < 3 * (size_t)e->n; i++)
            positions[i] = e->mesh->positions[i] + (e->pstar[i] - L->p[i]);
    } else if (e->n_levels == 1) {
        /* Step 3, interpolation-based (Algorithm 1 with section 4.1) */
        eigen_step3(e, L, e->pstar, 1, positions);
    } else {
        /* section 4.3, iteration 1: interpolation-based recovery to K~_n' */
        eigen_step3(e, L, e->pstar, 1, e->next);
        /* iteration 2: K~_n' as the coarse target, a re-fit with n' eigenvectors, and
         * local-frame recovery of the mesh */
        const level *L2 = &e->lv[1];
        eigen_project(e, L2->m, e->next, e->b);
        eigen_fit(e, L2->m, e->b, e->pstar);
        eigen_step3(e, L2, e->pstar, 0, positions);
    }
    /* loose vertices (on no face) follow their constraint exactly, held ones stay at rest */
    {
        const dk_constraints *c = e->r.con;
        const dk_mesh *mesh = e->mesh;
        for (dk_index i = 0; i < e->n; i++)
            if (mesh->ring_start[i + 1] == mesh->ring_start[i] && c->role[i] < 0)
                memcpy(positions + 3 * (size_t)i, mesh->positions + 3 * (size_t)i,
                       3 * sizeof(double));
        for (dk_index q = 0; q < c->n_handle_vertices; q++) {
            const dk_index i = c->handle_vertices[q];
            if (mesh->ring_start[i + 1] == mesh->ring_start[i])
                memcpy(positions + 3 * (size_t)i, e->r.target + 3 * (size_t)q,
                       3 * sizeof(double));
        }
        dk_constraints_hold(c, mesh->positions, positions);
    }
    double energy = NAN;
    if (!rq->skip_energy && (st = dk_eigen_energy(e, positions, &energy, err)) != DK_OK &&
        st != DK_ERR_NONFINITE)
        return st;
    st = dk_solve_result_check(positions, e->n, energy, !rq->skip_energy,
                               "EigenDeformation solve", err);
    if (st != DK_OK)
        return st;
    if (info) {
        info->iterations = preview ? 0 : e->n_levels;
        info->converged = 1;
        info->energy = energy;
    }
    return DK_OK;
}

const double *dk_eigen_skeleton(const dk_eigen *e)
{
    return e ? e->lv[0].p : NULL;
}

int dk_eigen_m(const dk_eigen *e)
{
    return e ? e->m : 0;
}

int dk_eigen_k(const dk_eigen *e)
{
    return e ? e->K : 0;
}

const double *dk_eigen_eigenvalues(const dk_eigen *e)
{
    return e ? e->evals : NULL;
}

const double *dk_eigen_eigenvectors(const dk_eigen *e)
{
    return e ? e->U : NULL;
}

double dk_eigen_delta3(const dk_eigen *e)
{
    return e ? e->r.delta3 : NAN;
}

const double *dk_eigen_weights(const dk_eigen *e)
{
    return e ? e->r.w : NULL;
}

void dk_eigen_stats(const dk_eigen *e, dk_method_stats *st)
{
    memset(st, 0, sizeof *st);
    if (!e)
        return;
    st->n_vertices = e->n;
    const dk_constraints *c = e->r.user ? e->r.user : e->r.con; /* the caller's */
    st->n_handles = c->n_handles;
    st->n_handle_vertices = c->n_handle_vertices;
    dk_constraints_held_stats(c, NULL, st);
    st->n_unknowns = 3 * e->m;
    st->factorization_count = 1;
}

dk_status dk_eigen_estimate_memory(const dk_mesh *mesh, const dk_eigen_options *o,
                                   uint64_t *bytes, dk_error *err)
{
    if (!mesh || !bytes)
        return dk_error_set(err, DK_ERR_INVALID_ARGUMENT,
                            "EigenDeformation estimate_memory: mesh and bytes must not be NULL");
    dk_status st = o ? check_options(o, mesh->n_vertices, err) : DK_OK; /* what bind refuses */
    if (st != DK_OK)
        return st;
    const double n = (double)mesh->n_vertices, lg = n > 2.0 ? log2(n) : 1.0;
    /* The K basis vectors (n doubles each; the eigensolver builds them in place), the band's
     * Krylov basis of 2 min(K, 50) + 1 vectors and its results of about min(K, 50) more
     * (eigs.c), and the Laplacian's LDL' factor (the log term). K is the larger of the
     * requested m (automatic: up to 300 plus a constant per further component) and the
     * refinement n'. Measured (2026-12-02): 4600 /
     * 4700 B/vertex for K = 300 at 62k / 248k vertices, 2660 for K = 50 at 62k. */
    const dk_index surfaces = mesh->report.n_components - mesh->report.n_isolated_vertices;
    const double constants = surfaces > 1 ? (double)(surfaces - 1) : 0.0;
    double k = o && o->n_eigenvectors > 0 ? o->n_eigenvectors : 300.0 + constants;
    const double refine = o ? o->refine : 300.0;
    if (refine > k)
        k = refine;
    if (k > n)
        k = n;
    double per_vertex = 350.0 + 40.0 * lg + 8.0 * k + 26.0 * (k < 50.0 ? k : 50.0);
    if (n <= 600.0 || k > n / 4.0) /* the dense path: the n x n matrix, dsyevd's workspace of
                                      2 n^2 + 6n + 1 more */
        per_vertex += 24.0 * n;
    *bytes = dk_memory_model(per_vertex, n, 0.0);
    return DK_OK;
}

/* the options' fields (dk_option_desc): where each is, what values bind takes (an
 * eigenvector count is also at most the vertex count) */
static const dk_option_desc eigen_fields[] = {
    {"n_eigenvectors", DK_OPTION_INT, offsetof(dk_eigen_options, n_eigenvectors), 0, 1, INT_MAX,
     50, 40, DK_OPTION_ZERO_AUTO},
    {"refine", DK_OPTION_INT, offsetof(dk_eigen_options, refine), 0, 0, INT_MAX, 300, 60, 0},
    {"laplacian", DK_OPTION_ENUM, offsetof(dk_eigen_options, laplacian), 0, 0, 1, 0, 1, 0},
    {"region", DK_OPTION_ENUM, offsetof(dk_eigen_options, region), 0, 0, 1, 0, 1, 0},
    {"bsw_width", DK_OPTION_DOUBLE, offsetof(dk_eigen_options, bsw_width), 0, DBL_TRUE_MIN,
     DBL_MAX, 1.0, DBL_MAX, 0},
};

DK_METHOD_OPS(dk_eigen_ops, "EigenDeformation", DK_METHOD_SOFT_REGIONS,
              DK_CONTROL_VERTEX_GROUPS, dk_eigen, dk_eigen, dk_eigen_options, eigen_fields);
