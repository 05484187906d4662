/* DeformKit: linear reconstruction from discrete fundamental forms with a material map: the
 * public verbs (dk_fundamental.h) and the bind's phases. The files of this folder are listed
 * in fundamental_internal.h; docs/methods/fundamental.md has the choices. */
#include "fundamental_internal.h"

#include <float.h>
#include <math.h>
#include <stdlib.h>
#include <string.h>

#include <cblas.h>

#include "dk_operators.h"

static const dk_progress_phase fr_bind_phases[] = {
    {"forms", 0.72},       /* the fundamental forms, the pieces and bridges              */
    {"constraints", 0.02}, /* FR_PHASE_CONSTRAINTS ...                                  */
    {"assemble", 2.30},
    {"analyze", 3.83},
    {"factorize", 10.0},
    {"basis", 0.80}};
static const dk_progress_phase fr_rebind_phases[] = {
    {"constraints", 0.02}, {"assemble", 2.30}, {"analyze", 3.83}, {"factorize", 10.0},
    {"basis", 0.80}};
#define FR_BIND_PHASE_BASE 1 /* FR_PHASE_CONSTRAINTS in fr_bind_phases */

dk_status fr_phase(const dk_fundamental *f, int k, dk_error *err)
{
    return dk_progress_begin(f->prog, f->prog_base + k, err);
}

dk_status fr_oom(dk_error *err, const char *what)
{
    return dk_error_set(err, DK_ERR_OUT_OF_MEMORY, "LinearReconstruction: out of memory (%s)",
                        what);
}

void dk_fundamental_default_options(dk_fundamental_options *o)
{
    memset(o, 0, sizeof *o);
    o->w = 1.0;
}

void dk_fundamental_free(dk_fundamental *f)
{
    if (!f)
        return;
    fr_elim_free(&f->el);
    free(f->material);
    free(f->degenerate);
    free(f->coord);
    free(f->cot);
    free(f->rest_frame);
    free(f->R);
    free(f->has_R);
    free(f->frames);
    free(f->comp_fit);
    free(f->piece);
    free(f->piece_rep);
    free(f->bridge);
    free(f->bridge_R);
    free(f->fin);
    free(f->fin_R);
    free(f);
}

/* The options a bind on `mesh` accepts (the estimate refuses the same). */
static dk_status check_options(const dk_mesh *mesh, const dk_fundamental_options *opt,
                               dk_error *err)
{
    if (!(opt->w > 0.0) || !isfinite(opt->w))
        return dk_error_set(err, DK_ERR_INVALID_ARGUMENT,
                            "LinearReconstruction: w must be finite and > 0");
    if (opt->orientation != 0 && opt->orientation != 1)
        return dk_error_set(err, DK_ERR_INVALID_ARGUMENT,
                            "LinearReconstruction: orientation must be 0 or 1");
    if (opt->material && opt->n_material != mesh->n_edges)
        return dk_error_set(err, DK_ERR_INVALID_ARGUMENT,
                            "LinearReconstruction: the material map has %d entries; the mesh "
                            "has %d edges (one value per edge, in Mesh.edges order)",
                            (int)opt->n_material, (int)mesh->n_edges);
    for (dk_index e = 0; opt->material && e < mesh->n_edges; e++)
        if (!(opt->material[e] > 0.0) || !isfinite(opt->material[e]))
            return dk_error_set(err, DK_ERR_INVALID_ARGUMENT,
                                "LinearReconstruction: the material map must be finite and > 0; "
                                "edge %d (vertices %d-%d) has %g", (int)e,
                                (int)mesh->edges[2 * (size_t)e],
                                (int)mesh->edges[2 * (size_t)e + 1], opt->material[e]);
    return DK_OK;
}

dk_status dk_fundamental_bind(const dk_mesh *mesh, const dk_constraint_desc *desc,
                              const dk_fundamental_options *options, dk_fundamental **out,
                              dk_error *err)
{
    if (!out)
        return dk_error_set(err, DK_ERR_INVALID_ARGUMENT, "LinearReconstruction: out is NULL");
    *out = NULL;
    if (!mesh || !desc)
        return dk_error_set(err, DK_ERR_INVALID_ARGUMENT,
                            "LinearReconstruction: mesh and constraints must not be NULL");
    if (mesh->n_faces == 0)
        return dk_error_set(err, DK_ERR_TOPOLOGY, "LinearReconstruction: the mesh has no faces");
    dk_fundamental_options opt;
    if (options)
        opt = *options;
    else
        dk_fundamental_default_options(&opt);
    dk_status st0 = check_options(mesh, &opt, err);
    if (st0 != DK_OK)
        return st0;
    dk_fundamental *f = calloc(1, sizeof *f);
    if (!f)
        return fr_oom(err, "object");
    f->mesh = mesh;
    f->opt = opt;
    dk_progress prog;
    dk_progress_init(&prog, opt.progress, opt.progress_user, fr_bind_phases,
                     (int)(sizeof fr_bind_phases / sizeof fr_bind_phases[0]),
                     "LinearReconstruction bind");
    f->opt.progress = NULL; /* the caller's callback is for this bind only */
    f->opt.progress_user = NULL;
    f->prog = &prog;
    f->prog_base = FR_BIND_PHASE_BASE;
    f->w_scaled = opt.w * mesh->mean_edge_length * mesh->mean_edge_length;
    if (!(f->w_scaled > 0.0 && isfinite(f->w_scaled))) { /* name the cause it can see */
        const double ws = f->w_scaled;
        free(f);
        if (!(mesh->mean_edge_length > 0.0))
            return dk_error_set(err, DK_ERR_DEGENERATE, "LinearReconstruction: the mesh has "
                                "no edge length");
        return dk_error_set(err, DK_ERR_INVALID_ARGUMENT,
                            "LinearReconstruction: w = %g times the mean edge length squared "
                            "(%g) is %s in double precision: give a w nearer 1", opt.w,
                            mesh->mean_edge_length * mesh->mean_edge_length,
                            ws > 0.0 ? "infinite" : "zero");
    }
    const size_t F = (size_t)mesh->n_faces, E = (size_t)mesh->n_edges;
    f->material = malloc((E + 1) * sizeof *f->material);
    f->degenerate = malloc(F + 1);
    f->coord = malloc(6 * F * sizeof *f->coord);
    f->cot = malloc(3 * F * sizeof *f->cot);
    f->rest_frame = malloc(9 * F * sizeof *f->rest_frame);
    f->frames = malloc(9 * F * sizeof *f->frames);
    f->R = malloc((9 * E + 1) * sizeof *f->R);
    f->has_R = malloc(E + 1);
    f->piece = malloc(((size_t)mesh->n_vertices + 1) * sizeof *f->piece);
    if (!f->material || !f->degenerate || !f->coord || !f->cot || !f->rest_frame || !f->frames ||
        !f->R || !f->has_R || !f->piece) {
        dk_fundamental_free(f);
        return fr_oom(err, "fundamental forms");
    }
    dk_status st = dk_progress_begin(&prog, 0, err); /* forms */
    if (st != DK_OK) {
        dk_fundamental_free(f);
        return st;
    }
    for (size_t e = 0; e < E; e++)
        f->material[e] = opt.material ? opt.material[e] : 1.0;
    f->opt.material = NULL; /* the copy is ours */
    f->opt.n_material = 0;
    /* (the forms phase's shares: faces ~0.2, edge rotations ~0.7, pieces ~0.1)
     * 1. the first fundamental form per face; 2. the second per interior edge (R_ij);
     * 3. the fins' frame equations, the pieces and the bridges between groups of faces that
     * meet at vertices only;
     * 4. the elimination of the constraints, the energy's matrices and their factor */
    fr_faces(f);
    if ((st = dk_progress_part(&prog, 0.2, err)) == DK_OK &&
        (st = fr_edge_rotations(f, err)) == DK_OK)
        st = dk_progress_part(&prog, 0.9, err);
    if (st != DK_OK) {
        dk_fundamental_free(f);
        return st;
    }
    memcpy(f->frames, f->rest_frame, 9 * F * sizeof *f->frames);
    if ((st = fr_fin_pairs(f, err)) == DK_OK)
        st = fr_pieces_and_bridges(f, err);
    if (st != DK_OK) {
        dk_fundamental_free(f);
        return st;
    }
    elim s;
    st = fr_eliminate(f, desc, &s, err);
    if (st != DK_OK) {
        fr_elim_free(&s);
        dk_fundamental_free(f);
        return st;
    }
    fr_elim_install(f, &s);
    f->prog = NULL;
    dk_progress_done(&prog);
    *out = f;
    return DK_OK;
}

dk_status dk_fundamental_rebind(dk_fundamental *f, const dk_constraint_desc *desc, dk_error *err)
{
    if (!f || !desc)
        return dk_error_set(err, DK_ERR_INVALID_ARGUMENT,
                            "LinearReconstruction rebind: object and constraints must not be "
                            "NULL");
    dk_progress prog;
    dk_progress_init(&prog, f->opt.progress, f->opt.progress_user, fr_rebind_phases,
                     (int)(sizeof fr_rebind_phases / sizeof fr_rebind_phases[0]),
                     "LinearReconstruction rebind");
    f->prog = &prog;
    f->prog_base = 0;
    elim s;
    dk_status st = fr_eliminate(f, desc, &s, err); /* const f: on failure f is as it was */
    f->prog = NULL;
    if (st != DK_OK) {
        fr_elim_free(&s);
        return st;
    }
    fr_elim_install(f, &s);
    dk_progress_done(&prog);
    return DK_OK;
}

void dk_fundamental_set_progress(dk_fundamental *f, dk_phase_progress_fn progress, void *user)
{
    if (!f)
        return;
    f->opt.progress = progress;
    f->opt.progress_user = progress ? user : NULL;
}

/* ------------------------------------------------------------------ solve -------------- */

/* Per handle, the linear part that turns its faces' frames: the transform's, or the
 * rotation that best fits the rest handle vertices to the targets (Kabsch). */
static void handle_rotations(dk_fundamental *f, int transforms, const double *targets)
{
    const dk_constraints *c = f->el.con;
    const double *p = f->mesh->positions;
    for (dk_index h = 0; h < c->n_handles; h++) {
        double *L = f->el.lin + 9 * (size_t)h;
        if (transforms) {
            for (int r = 0; r < 3; r++)
                for (int q = 0; q < 3; q++)
                    L[3 * r + q] = targets[16 * (size_t)h + 4 * r + q];
            continue;
        }
        double cp[3] = {0, 0, 0}, cq[3] = {0, 0, 0}, A[9] = {0};
        const dk_index a = c->handle_start[h], b = c->handle_start[h + 1];
        for (dk_index q = a; q < b; q++)
            for (int d = 0; d < 3; d++) {
                cp[d] += p[3 * (size_t)c->handle_vertices[q] + d] / (double)(b - a);
                cq[d] += f->el.tgt[3 * (size_t)q + d] / (double)(b - a);
            }
        for (dk_index q = a; q < b; q++) /* A = sum (q - cq)(p - cp)^T: R maximises tr(R^T A) */
            for (int r = 0; r < 3; r++)
                for (int s = 0; s < 3; s++)
                    A[3 * r + s] += (f->el.tgt[3 * (size_t)q + r] - cq[r]) *
                                    (p[3 * (size_t)c->handle_vertices[q] + s] - cp[s]);
        dk_closest_rotation(A, L);
    }
}

dk_status dk_fundamental_solve(dk_fundamental *f, const dk_solve_request *rq, double *positions,
                               dk_solve_info *info, dk_error *err)
{
    if (info)
        memset(info, 0, sizeof *info);
    if (!f || !positions)
        return dk_error_set(err, DK_ERR_INVALID_ARGUMENT,
                            "LinearReconstruction solve: object and positions must not be NULL");
    dk_status st = dk_solve_request_check(rq, "LinearReconstruction solve", err);
    if (st != DK_OK)
        return st;
    const dk_mesh *m = f->mesh;
    const dk_constraints *c = f->el.con;
    st = dk_constraints_targets(c, m->positions, rq->targets, (int)rq->target_kind, f->el.tgt, err);
    if (st != DK_OK)
        return dk_error_prefix(err, "LinearReconstruction solve");
    if (f->opt.orientation)
        handle_rotations(f, rq->target_kind == DK_TARGETS_TRANSFORMS, rq->targets);
    /* the constraint values, per coordinate (column-major n_con x 3) */
    const size_t nc = (size_t)f->el.n_con, nu = (size_t)f->el.n_unk;
    for (dk_index v = 0; v < m->n_vertices; v++) {
        if (f->el.vc[v] < 0)
            continue;
        const double *src = m->positions + 3 * (size_t)v;
        if (c->role[v] >= 0) /* a handle vertex: its target */
            for (dk_index q = c->handle_start[c->role[v]]; q < c->handle_start[c->role[v] + 1]; q++)
                if (c->handle_vertices[q] == v) {
                    src = f->el.tgt + 3 * (size_t)q;
                    break;
                }
        for (int d = 0; d < 3; d++)
            f->el.zc[(size_t)d * nc + f->el.vc[v]] = src[d];
    }
    for (dk_index t = 0; t < m->n_faces; t++) {
        if (f->el.fc[t] < 0)
            continue;
        const double *F0 = f->rest_frame + 9 * (size_t)t;
        double Ft[9];
        if (f->el.face_handle[t] >= 0)
            fr_mat_mul(f->el.lin + 9 * (size_t)f->el.face_handle[t], F0, Ft);
        else
            memcpy(Ft, F0, sizeof Ft);
        for (int d = 0; d < 3; d++)
            for (int k = 0; k < 3; k++)
                f->el.zc[(size_t)d * nc + f->el.fc[t] + k] = Ft[3 * d + k];
        memcpy(f->frames + 9 * (size_t)t, Ft, sizeof Ft);
    }
    if (f->el.any_anchor) { /* the regularization's anchors: rest frames, turned per component */
        const dk_index ncomp = f->n_pieces;
        memset(f->comp_fit, 0, 25 * (size_t)ncomp * sizeof *f->comp_fit);
        for (int pass = 0; pass < 2; pass++)
            for (dk_index v = 0; v < m->n_vertices; v++) {
                if (f->el.vc[v] < 0)
                    continue;
                double *cf = f->comp_fit + 25 * (size_t)f->piece[v];
                const double *p = m->positions + 3 * (size_t)v;
                double q[3];
                for (int d = 0; d < 3; d++)
                    q[d] = f->el.zc[(size_t)d * nc + f->el.vc[v]];
                if (pass == 0) { /* the centroids' sums */
                    cf[0] += 1.0;
                    for (int d = 0; d < 3; d++)
                        cf[1 + d] += p[d], cf[4 + d] += q[d];
                    continue;
                }
                for (int a = 0; a < 3; a++) /* sum (q - cq)(p - cp)^T */
                    for (int b = 0; b < 3; b++)
                        cf[7 + 3 * a + b] += (q[a] - cf[4 + a] / cf[0]) * (p[b] - cf[1 + b] / cf[0]);
            }
        for (dk_index c = 0; c < ncomp; c++)
            dk_closest_rotation(f->comp_fit + 25 * (size_t)c + 7, f->comp_fit + 25 * (size_t)c + 16);
        for (dk_index t = 0; t < m->n_faces; t++)
            if (f->el.fa[t] >= 0) {
                double Ft[9];
                fr_mat_mul(f->comp_fit + 25 * (size_t)f->piece[m->faces[3 * (size_t)t]] + 16,
                        f->rest_frame + 9 * (size_t)t, Ft);
                for (int d = 0; d < 3; d++)
                    for (int k = 0; k < 3; k++)
                        f->el.zc[(size_t)d * nc + f->el.fa[t] + k] = Ft[3 * d + k];
            }
    }
    /* A z = -B z_c, three coordinates at once; with transforms and the basis, its
     * combination z_d = S_d + sum T_h[d][j] G_{4h+j} */
    if (nu > 0 && f->el.basis && rq->target_kind == DK_TARGETS_TRANSFORMS) {
        const int nh = (int)c->n_handles;
        double *P = f->el.coef;
        for (int h = 0; h < nh; h++)
            for (int j = 0; j < 4; j++)
                for (int d = 0; d < 3; d++)
                    P[(size_t)d * 4 * nh + 4 * (size_t)h + j] = rq->targets[16 * (size_t)h + 4 * d + j];
        for (int d = 0; d < 3; d++)
            memcpy(f->el.rhs + (size_t)d * nu, f->el.basis + (4 * (size_t)nh + d) * nu,
                   nu * sizeof(double));
        cblas_dgemm(CblasColMajor, CblasNoTrans, CblasNoTrans, (int)nu, 3, 4 * nh, 1.0,
                    f->el.basis, (int)nu, P, 4 * nh, 1.0, f->el.rhs, (int)nu);
    } else if (nu > 0) {
        for (int d = 0; d < 3; d++) {
            dk_sparse_matvec(f->el.B, f->el.zc + (size_t)d * nc, f->el.rhs + (size_t)d * nu);
            for (size_t i = 0; i < nu; i++)
                f->el.rhs[(size_t)d * nu + i] = -f->el.rhs[(size_t)d * nu + i];
        }
        st = dk_cholesky_solve(f->el.chol, f->el.rhs, 3, f->el.rhs, err);
        if (st != DK_OK)
            return dk_error_prefix(err, "LinearReconstruction solve");
    }
    for (dk_index v = 0; v < m->n_vertices; v++)
        for (int d = 0; d < 3; d++)
            positions[3 * (size_t)v + d] = f->el.vu[v] >= 0 ? f->el.rhs[(size_t)d * nu + f->el.vu[v]]
                                                         : f->el.zc[(size_t)d * nc + f->el.vc[v]];
    for (dk_index t = 0; t < m->n_faces; t++)
        if (f->el.fu[t] >= 0)
            for (int d = 0; d < 3; d++)
                for (int k = 0; k < 3; k++)
                    f->frames[9 * (size_t)t + 3 * d + k] = f->el.rhs[(size_t)d * nu + f->el.fu[t] + k];
    double energy = NAN;
    if (!rq->skip_energy && (st = dk_fundamental_energy(f, positions, &energy, err)) != DK_OK &&
        st != DK_ERR_NONFINITE)
        return st;
    st = dk_solve_result_check(positions, m->n_vertices, energy, !rq->skip_energy,
                               "LinearReconstruction solve", err);
    if (st != DK_OK)
        return st;
    if (info) {
        info->iterations = info->converged = 1;
        info->energy = energy;
    }
    return DK_OK;
}

int dk_fundamental_has_transform_basis(const dk_fundamental *f)
{
    return f && f->el.basis != NULL;
}

dk_status dk_fundamental_energy(const dk_fundamental *f, const double *positions,
                                double *energy, dk_error *err)
{
    if (!f || !positions || !energy)
        return dk_error_set(err, DK_ERR_INVALID_ARGUMENT,
                            "LinearReconstruction energy: arguments must not be NULL");
    *energy = fr_energy(f, positions);
    return dk_energy_result_check(*energy, "LinearReconstruction energy", err);
}

const double *dk_fundamental_frames(const dk_fundamental *f)
{
    return f ? f->frames : NULL;
}

int dk_fundamental_edge_rotation(const dk_fundamental *f, dk_index edge, double r[9])
{
    if (!f || edge < 0 || edge >= f->mesh->n_edges || !f->has_R[edge])
        return 0;
    memcpy(r, f->R + 9 * (size_t)edge, 9 * sizeof *r);
    return 1;
}

void dk_fundamental_stats(const dk_fundamental *f, dk_method_stats *st)
{
    memset(st, 0, sizeof *st);
    if (!f)
        return;
    st->n_vertices = f->mesh->n_vertices;
    st->n_handles = f->el.con->n_handles;
    st->n_handle_vertices = f->el.con->n_handle_vertices;
    dk_constraints_held_stats(f->el.con, NULL, st);
    st->n_unknowns = f->el.n_unk;
    st->analysis_count = st->factorization_count = f->el.n_unk > 0;
}

dk_status dk_fundamental_estimate_memory(const dk_mesh *mesh,
                                         const dk_fundamental_options *options,
                                         uint64_t *bytes, dk_error *err)
{
    if (!mesh || !bytes)
        return dk_error_set(err, DK_ERR_INVALID_ARGUMENT,
                            "LinearReconstruction estimate_memory: mesh and bytes must not be "
                            "NULL");
    dk_status st = options ? check_options(mesh, options, err) : DK_OK; /* what bind refuses */
    if (st != DK_OK)
        return st;
    const double n = (double)mesh->n_vertices, lg = n > 2.0 ? log2(n) : 1.0;
    /* the factor of the 7n-unknown system dominates, and its fill grows ~n log n. Measured
     * (2026-12-02): 6560 / 6890 / 8220 / 9720 B/vertex on the arm 8k, the armadillo 43k and
     * subdivided once and twice (173k, 692k) */
    *bytes = dk_memory_model(1500.0 + 450.0 * lg, n, 0.0);
    return DK_OK;
}

/* the options' fields (dk_option_desc): where each is, what values bind takes */
static const dk_option_desc fundamental_fields[] = {
    {"w", DK_OPTION_DOUBLE, offsetof(dk_fundamental_options, w), 0, DBL_TRUE_MIN, DBL_MAX, 1.0,
     DBL_MAX, 0},
    {"orientation", DK_OPTION_INT, offsetof(dk_fundamental_options, orientation), 0, 0, 1, 0, 1,
     0},
    {"material", DK_OPTION_EDGE_VALUES, offsetof(dk_fundamental_options, material),
     offsetof(dk_fundamental_options, n_material), DBL_TRUE_MIN, DBL_MAX, 1.0, DBL_MAX, 0},
};

DK_METHOD_OPS(dk_fundamental_ops, "LinearReconstruction",
              DK_METHOD_TRANSFORMS_AS_POSITIONS | DK_METHOD_TRANSLATION_INVARIANT |
                  DK_METHOD_RIGID_INVARIANT,
              DK_CONTROL_VERTEX_GROUPS, dk_fundamental, dk_fundamental, dk_fundamental_options,
              fundamental_fields);
