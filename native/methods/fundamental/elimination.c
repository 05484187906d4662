/* Linear reconstruction's elimination of the constraints (fundamental_internal.h): the
 * unknowns' numbering, the pieces' check, the factorization and the transform basis. */
#include "fundamental_internal.h"
#include "dk_lapack.h"

#include <math.h>
#include <stdlib.h>
#include <string.h>

#include <cblas.h>

void fr_elim_free(elim *s)
{
    dk_constraints_free(s->con);
    free(s->vu);
    free(s->vc);
    free(s->fu);
    free(s->fc);
    free(s->face_handle);
    free(s->fa);
    dk_sparse_free(s->A);
    dk_sparse_free(s->B);
    dk_cholesky_free(s->chol);
    free(s->zc);
    free(s->rhs);
    free(s->lin);
    free(s->tgt);
    free(s->basis);
    free(s->coef);
    memset(s, 0, sizeof *s);
}

/* Before any solve the anchors are the rest frames (for the energy). */
static void rest_anchors(dk_fundamental *f)
{
    const size_t nc = (size_t)f->el.n_con;
    for (dk_index t = 0; t < f->mesh->n_faces; t++)
        if (f->el.fa[t] >= 0)
            for (int d = 0; d < 3; d++)
                for (int k = 0; k < 3; k++)
                    f->el.zc[(size_t)d * nc + f->el.fa[t] + k] = f->rest_frame[9 * (size_t)t + 3 * d + k];
}

void fr_elim_install(dk_fundamental *f, elim *s)
{
    fr_elim_free(&f->el);
    f->el = *s;
    memset(s, 0, sizeof *s);
    rest_anchors(f);
}

/* Every piece (fr_pieces_and_bridges: a connected component, or a part of one that only
 * degenerate triangles join to the rest) must be held by a constraint, else its translation
 * is free. A component without any constraint is held at rest by dk_constraints already, so
 * what is left to refuse is a part cut off by degenerate triangles: the error names a vertex
 * of it and a degenerate triangle on its rim. The frames are linear unknowns, so the energy
 * is invariant under any affine map of a piece's positions and frames together:
 * constraints pin that map only when the piece's constrained vertices span space (four not
 * in a plane) or a face's frame is prescribed. A piece held more thinly (a planar rim, a
 * line, one vertex) gets `thin` = 1: fr_eliminate() then draws its frames weakly
 * (REGULARIZATION) to their rest frames turned by the rotation that best fits the piece's
 * constrained vertices to their targets (solve), which picks, among the equally good
 * results, the one without a free shear, and keeps a rigid motion of every constraint
 * exact. */
static dk_status check_components(const dk_fundamental *f, const elim *s, unsigned char *thin,
                                  dk_error *err)
{
    const dk_mesh *m = f->mesh;
    const dk_index nc = f->n_pieces;
    dk_index *cv = calloc((size_t)nc + 1, sizeof *cv), *cf = calloc((size_t)nc + 1, sizeof *cf);
    double *mom = calloc(9 * (size_t)nc + 1, sizeof *mom), *mean = calloc(3 * (size_t)nc + 1, sizeof *mean);
    if (!cv || !cf || !mom || !mean) {
        free(cv), free(cf), free(mom), free(mean);
        return fr_oom(err, "components");
    }
    for (dk_index v = 0; v < m->n_vertices; v++) {
        const dk_index c = f->piece[v];
        if (s->vc[v] < 0)
            continue;
        cv[c]++;
        for (int d = 0; d < 3; d++)
            mean[3 * (size_t)c + d] += m->positions[3 * (size_t)v + d];
    }
    for (dk_index v = 0; v < m->n_vertices; v++) { /* the constrained vertices' covariance */
        const dk_index c = f->piece[v];
        if (s->vc[v] < 0)
            continue;
        double q[3];
        for (int d = 0; d < 3; d++)
            q[d] = m->positions[3 * (size_t)v + d] - mean[3 * (size_t)c + d] / (double)cv[c];
        for (int a = 0; a < 3; a++)
            for (int b = 0; b < 3; b++)
                mom[9 * (size_t)c + 3 * a + b] += q[a] * q[b];
    }
    for (dk_index t = 0; t < m->n_faces; t++)
        if (s->fc[t] >= 0)
            cf[f->piece[m->faces[3 * (size_t)t]]]++;
    dk_status st = DK_OK;
    for (dk_index c = 0; c < nc && st == DK_OK; c++) {
        if (cv[c] == 0 && cf[c] == 0) {
            const dk_index rep = f->piece_rep[c];
            dk_index rim = -1; /* a degenerate triangle touching the piece */
            for (dk_index t = 0; t < m->n_faces && rim < 0; t++)
                if (f->degenerate[t])
                    for (int k = 0; k < 3; k++)
                        if (f->piece[m->faces[3 * (size_t)t + k]] == c)
                            rim = t;
            if (rim >= 0)
                st = dk_error_set(err, DK_ERR_DEGENERATE,
                                  "LinearReconstruction: the part containing vertex %d is joined "
                                  "to the rest of its component only through degenerate "
                                  "(zero-area) triangles such as face %d, which carry no "
                                  "energy, and has no constraint of its own: fix those "
                                  "triangles or constrain the part", (int)rep, (int)rim);
            else
                st = dk_error_set(err, DK_ERR_INVALID_ARGUMENT,
                                  "LinearReconstruction: the component containing vertex %d has "
                                  "no constraint: every component needs a handle or fixed "
                                  "vertices", (int)rep);
            break;
        }
        double ev[3];
        /* symmetric, filled whole: its column-major reading is the same matrix */
        const int info = dk_lapack_dsyev('N', 3, mom + 9 * (size_t)c, ev);
        /* spanning space: the smallest spread at least 1e-3 of the largest */
        const int flat = info != 0 || !(ev[0] > 1e-6 * ev[2]);
        thin[c] = cf[c] == 0 && (cv[c] < 4 || flat);
    }
    free(cv), free(cf), free(mom), free(mean);
    return st;
}

/* The constraints' roles, the numbering, the matrices and the factor. */
/* The transform basis of the elimination `s` (see elim), when it pays and is exact:
 *  - exact: the constraint values are affine in the transforms' entries unless a
 *    component is regularized (its anchors come from a best-fit rotation: not affine);
 *  - pays: a drag costs n_unk x 4 n_handles x 3 multiply-adds instead of the triangular
 *    solves (armadillo, one handle: ~3 ms against ~44 ms), for 4 n_handles + 3 solves at
 *    bind; built while it takes at most TRANSFORM_BASIS_BYTES.
 * Column 4h + j holds the solution for "T_h[d][j] = 1, everything else 0" (the same for
 * every coordinate d: a handle vertex's target coordinate d is sum_j T[d][j] p_j + T[d][3],
 * a prescribed frame's row d is sum_j T[d][j] F0 row j); columns 4 n_h + d the solution for
 * the fixed values alone (fixed vertices' and fixed faces' rest coordinate d). Its absence
 * is not an error (out of memory included): solves then take the direct path. */
#define TRANSFORM_BASIS_BYTES (256.0 * 1024 * 1024)
static dk_status transform_basis(const dk_fundamental *f, elim *s, dk_error *err)
{
    const dk_mesh *m = f->mesh;
    const dk_constraints *c = s->con;
    const dk_index nh = c->n_handles;
    const size_t nu = (size_t)s->n_unk, nc = (size_t)s->n_con, cols = 4 * (size_t)nh + 3;
    if (s->any_anchor || nh == 0 || nu == 0 ||
        (double)(nu + nc) * (double)cols * sizeof(double) > TRANSFORM_BASIS_BYTES)
        return DK_OK;
    double *e = calloc(nc * cols, sizeof *e);     /* the constraint values per column */
    s->basis = malloc(nu * cols * sizeof *s->basis);
    s->coef = malloc(4 * (size_t)nh * 3 * sizeof *s->coef);
    if (!e || !s->basis || !s->coef) {
        free(e);
        free(s->basis), free(s->coef);
        s->basis = s->coef = NULL;
        return DK_OK;
    }
    const size_t fixed0 = 4 * (size_t)nh;
    for (dk_index v = 0; v < m->n_vertices; v++) {
        if (s->vc[v] < 0)
            continue;
        const double *p = m->positions + 3 * (size_t)v;
        const size_t slot = (size_t)s->vc[v];
        if (c->role[v] >= 0) {
            const size_t col = 4 * (size_t)c->role[v];
            for (int j = 0; j < 3; j++)
                e[(col + j) * nc + slot] = p[j];
            e[(col + 3) * nc + slot] = 1.0;
        } else {
            for (int d = 0; d < 3; d++)
                e[(fixed0 + d) * nc + slot] = p[d];
        }
    }
    for (dk_index t = 0; t < m->n_faces; t++) {
        if (s->fc[t] < 0)
            continue;
        const double *F0 = f->rest_frame + 9 * (size_t)t;
        const size_t slot = (size_t)s->fc[t];
        for (int k = 0; k < 3; k++) {
            if (s->face_handle[t] >= 0) {
                const size_t col = 4 * (size_t)s->face_handle[t];
                for (int j = 0; j < 3; j++)
                    e[(col + j) * nc + slot + k] = F0[3 * j + k];
            } else {
                for (int d = 0; d < 3; d++)
                    e[(fixed0 + d) * nc + slot + k] = F0[3 * d + k];
            }
        }
    }
    for (size_t q = 0; q < cols; q++) { /* A G = -B E */
        double *g = s->basis + q * nu;
        dk_sparse_matvec(s->B, e + q * nc, g);
        for (size_t i = 0; i < nu; i++)
            g[i] = -g[i];
    }
    free(e);
    /* The solves: the fixed values' 3 columns, then each handle's 4, so that a cancellation
     * is seen between them; in these groups whether progress is asked or not, so that the
     * basis does not depend on it. */
    for (dk_index h = -1; h < nh; h++) {
        const size_t q0 = h < 0 ? fixed0 : 4 * (size_t)h, nq = h < 0 ? 3 : 4;
        dk_status st = dk_progress_part(f->prog, (double)(h + 1) / (double)(nh + 1), err);
        if (st != DK_OK)
            return st;
        st = dk_cholesky_solve(s->chol, s->basis + q0 * nu, (int)nq, s->basis + q0 * nu, err);
        if (st != DK_OK)
            return dk_error_prefix(err, "LinearReconstruction (transform basis)");
    }
    return DK_OK;
}

dk_status fr_eliminate(const dk_fundamental *f, const dk_constraint_desc *desc, elim *s,
                           dk_error *err)
{
    const dk_mesh *m = f->mesh;
    const dk_index n = m->n_vertices, F = m->n_faces;
    memset(s, 0, sizeof *s);
    dk_status st = fr_phase(f, FR_PHASE_CONSTRAINTS, err);
    if (st != DK_OK)
        return st;
    st = dk_constraints_create(m, desc, &s->con, err);
    if (st != DK_OK)
        return dk_error_prefix(err, "LinearReconstruction");
    const dk_constraints *c = s->con;
    s->vu = malloc((size_t)n * sizeof *s->vu), s->vc = malloc((size_t)n * sizeof *s->vc);
    s->fu = malloc(((size_t)F + 1) * sizeof *s->fu), s->fc = malloc(((size_t)F + 1) * sizeof *s->fc);
    s->face_handle = malloc(((size_t)F + 1) * sizeof *s->face_handle);
    if (!s->vu || !s->vc || !s->fu || !s->fc || !s->face_handle)
        return fr_oom(err, "numbering");
    dk_index nu = 0, ncon = 0;
    for (dk_index v = 0; v < n; v++) {
        const int held = c->role[v] != DK_VERTEX_FREE;
        s->vu[v] = held ? -1 : nu++;
        s->vc[v] = held ? ncon++ : -1;
    }
    for (dk_index t = 0; t < F; t++) {
        const dk_index *fv = m->faces + 3 * (size_t)t;
        dk_index h = -1;
        if (f->opt.orientation && !f->degenerate[t] && c->role[fv[0]] != DK_VERTEX_FREE &&
            c->role[fv[0]] == c->role[fv[1]] && c->role[fv[0]] == c->role[fv[2]])
            h = c->role[fv[0]] == DK_VERTEX_FIXED ? -2 : c->role[fv[0]];
        s->face_handle[t] = h;
        if (f->degenerate[t]) {
            s->fu[t] = s->fc[t] = -1;
        } else if (h != -1) {
            s->fu[t] = -1, s->fc[t] = ncon, ncon += 3;
        } else {
            s->fu[t] = nu, s->fc[t] = -1, nu += 3;
        }
    }
    s->n_unk = nu;
    for (dk_index v = 0; v < n; v++) /* a vertex on degenerate faces only has no energy */
        if (s->vu[v] >= 0 && m->vf_start[v + 1] > m->vf_start[v]) {
            int any = 0;
            for (dk_index q = m->vf_start[v]; q < m->vf_start[v + 1]; q++)
                any |= !f->degenerate[m->vf_index[q]];
            if (!any)
                return dk_error_set(err, DK_ERR_DEGENERATE,
                                    "LinearReconstruction: vertex %d lies on degenerate "
                                    "triangles only, so nothing places it: fix the mesh or "
                                    "constrain it", (int)v);
        }
    {
        unsigned char *thin = calloc((size_t)f->n_pieces + 1, 1);
        s->fa = malloc(((size_t)F + 1) * sizeof *s->fa);
        if (!thin || !s->fa) {
            free(thin);
            return fr_oom(err, "numbering");
        }
        st = check_components(f, s, thin, err);
        for (dk_index t = 0; t < F; t++) { /* anchors of the thinly held components' frames */
            const int reg = st == DK_OK && s->fu[t] >= 0 && thin[f->piece[m->faces[3 * (size_t)t]]];
            s->fa[t] = reg ? ncon : -1;
            ncon += reg ? 3 : 0;
            s->any_anchor |= reg;
        }
        free(thin);
        if (st != DK_OK)
            return st;
    }
    s->n_con = ncon;
    /* (a scratch view of the numbering for slot()) */
    dk_fundamental view = *f;
    view.el = *s;
    st = fr_phase(f, FR_PHASE_ASSEMBLE, err);
    if (st == DK_OK)
        st = fr_assemble(&view, nu, ncon, &s->A, &s->B, err);
    if (st == DK_OK && nu > 0 && (st = fr_phase(f, FR_PHASE_ANALYZE, err)) == DK_OK)
        st = dk_cholesky_analyze_compact(s->A, &s->chol, err);
    if (st == DK_OK && nu > 0 && (st = fr_phase(f, FR_PHASE_FACTORIZE, err)) == DK_OK) {
        st = dk_cholesky_factorize(s->chol, s->A, err);
        if (st == DK_ERR_NOT_POSITIVE_DEFINITE) {
            /* name the caller's vertex (or face frame), not the matrix column */
            const int64_t col = err ? err->column - 1 : -1;
            char at[64] = "";
            for (dk_index v = 0; col >= 0 && !at[0] && v < n; v++)
                if (s->vu[v] == col)
                    snprintf(at, sizeof at, " at vertex %d", (int)v);
            for (dk_index t = 0; col >= 0 && !at[0] && t < F; t++)
                if (s->fu[t] >= 0 && col >= s->fu[t] && col < s->fu[t] + 3)
                    snprintf(at, sizeof at, " at the frame of face %d", (int)t);
            /* the likely cause first: the magnitudes of the material map or of w leave the
             * system singular to rounding (the second hostile review: the message blamed the
             * geometry when a material of 1e-14 was the cause) */
            double lo = 1.0, hi = 1.0;
            for (dk_index e = 0; f->material && e < f->mesh->n_edges; e++) {
                lo = fmin(lo, f->material[e]);
                hi = fmax(hi, f->material[e]);
            }
            const double w = f->opt.w;
            if (hi / lo > 1e12)
                dk_error_set(err, DK_ERR_NOT_POSITIVE_DEFINITE,
                             "LinearReconstruction: the system is singular%s: the material map "
                             "spans %g to %g, a ratio of %.3g, beyond what double precision "
                             "resolves (keep it within 1e12, e.g. 1e-6 to 1e6)",
                             at, lo, hi, hi / lo);
            else if (w < 1e-12 || w > 1e12)
                dk_error_set(err, DK_ERR_NOT_POSITIVE_DEFINITE,
                             "LinearReconstruction: the system is singular%s: w = %g is too "
                             "%s beside the edge terms for double precision (keep it within "
                             "1e-12 to 1e12; 1, the default, weighs both alike)",
                             at, w, w < 1e-12 ? "small" : "large");
            else
                dk_error_set(err, DK_ERR_NOT_POSITIVE_DEFINITE,
                             "LinearReconstruction: the system is singular%s (constrained "
                             "vertices on a line, or degenerate triangles around it)", at);
        } else if (st != DK_OK)
            dk_error_prefix(err, "LinearReconstruction");
    }
    /* A is in the factor now; solves need B and the factor only */
    dk_sparse_free(s->A);
    s->A = NULL;
    if (st == DK_OK) {
        s->zc = malloc((3 * (size_t)ncon + 1) * sizeof *s->zc);
        s->rhs = malloc((3 * (size_t)nu + 1) * sizeof *s->rhs);
        s->lin = malloc((9 * (size_t)c->n_handles + 1) * sizeof *s->lin);
        s->tgt = malloc((3 * (size_t)c->n_handle_vertices + 1) * sizeof *s->tgt);
        if (!s->zc || !s->rhs || !s->lin || !s->tgt)
            st = fr_oom(err, "buffers");
    }
    if (st == DK_OK && s->con->n_handles > 0 && nu > 0 &&
        (st = fr_phase(f, FR_PHASE_BASIS, err)) == DK_OK)
        st = transform_basis(f, s, err);
    return st;
}
