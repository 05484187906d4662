/* Linear reconstruction's residuals (fundamental_internal.h): every term of the energy
 * visited in turn, to assemble its matrices or to evaluate it. */
#include "fundamental_internal.h"

#include <stdlib.h>
#include <string.h>

/* One residual of one coordinate: weight and up to 4 terms, each a vertex (frame < 0) or
 * entry k of a face's frame row. */
typedef struct term {
    dk_index id;
    int k; /* -1: vertex id; 0..2: entry k of face id's frame row; 3..5: entry k - 3 of its
              rest frame row (a constant: the regularization's anchor) */
    double c;
} term;


typedef void (*visit_fn)(void *ctx, double weight, const term *t, int nt);

/* The weight of E_f's residuals across edge e between faces ti and tj (eq. 6):
 * w / (material_e (cot alpha + cot beta)), the angles opposite e in the two faces. */
static double frame_weight(const dk_fundamental *f, dk_index ti, dk_index tj, dk_index e)
{
    const dk_mesh *m = f->mesh;
    const dk_index a = m->edges[2 * (size_t)e], b = m->edges[2 * (size_t)e + 1];
    const int ki = fr_corner_of(m, ti, a) ^ fr_corner_of(m, ti, b) ^ 3;
    const int kj = fr_corner_of(m, tj, a) ^ fr_corner_of(m, tj, b) ^ 3;
    const double we = f->cot[3 * (size_t)ti + ki] + f->cot[3 * (size_t)tj + kj];
    return f->w_scaled / (f->material[e] * we);
}

/* The three residuals f_j - f_i R (one per entry k of the frame rows), with weight wgt. */
static void visit_frame_pair(dk_index ti, dk_index tj, const double R[9], double wgt,
                             visit_fn visit, void *ctx)
{
    for (int k = 0; k < 3; k++) {
        const term tt[4] = {{tj, k, 1.0}, {ti, 0, -R[k]}, {ti, 1, -R[3 + k]},
                            {ti, 2, -R[6 + k]}};
        visit(ctx, wgt, tt, 4);
    }
}

/* Every residual of E = w E_f + E_x (eqs. 5-7), the same for each coordinate. */
void fr_for_each_residual(const dk_fundamental *f, visit_fn visit, void *ctx)
{
    const dk_mesh *m = f->mesh;
    for (dk_index t = 0; t < m->n_faces; t++) { /* E_x: each edge of each face */
        if (f->degenerate[t])
            continue;
        const dk_index *c = m->faces + 3 * (size_t)t;
        const double *co = f->coord + 6 * (size_t)t;
        for (int k = 0; k < 3; k++) {
            const int a = (k + 1) % 3, b = (k + 2) % 3; /* the edge opposite corner k */
            const dk_index e = m->face_edges[3 * (size_t)t + k];
            const double wgt = f->material[e] * f->cot[3 * (size_t)t + k];
            const term tt[4] = {{c[b], -1, 1.0}, {c[a], -1, -1.0},
                                {t, 0, -(co[2 * b] - co[2 * a])},
                                {t, 1, -(co[2 * b + 1] - co[2 * a + 1])}};
            visit(ctx, wgt, tt, 4);
        }
    }
    for (dk_index e = 0; e < m->n_edges; e++) { /* E_f: f_j - f_i R_ij across interior edges */
        if (!f->has_R[e])
            continue;
        const dk_index ti = m->edge_faces[2 * (size_t)e], tj = m->edge_faces[2 * (size_t)e + 1];
        visit_frame_pair(ti, tj, f->R + 9 * (size_t)e, frame_weight(f, ti, tj, e), visit, ctx);
    }
    for (dk_index q = 0; q < f->n_fins; q++) { /* E_f on the fins (fr_fin_pairs) */
        const dk_index ti = f->fin[3 * (size_t)q], tj = f->fin[3 * (size_t)q + 1];
        const dk_index e = f->fin[3 * (size_t)q + 2];
        visit_frame_pair(ti, tj, f->fin_R + 9 * (size_t)q, frame_weight(f, ti, tj, e), visit,
                         ctx);
    }
    for (dk_index b = 0; b < f->n_bridges; b++) /* the bridges (fr_pieces_and_bridges) */
        visit_frame_pair(f->bridge[2 * (size_t)b], f->bridge[2 * (size_t)b + 1],
                         f->bridge_R + 9 * (size_t)b, REGULARIZATION * f->w_scaled, visit, ctx);
    for (dk_index t = 0; f->el.fa && t < m->n_faces; t++) /* the regularization, where needed */
        if (f->el.fa[t] >= 0)
            for (int k = 0; k < 3; k++) {
                const term tt[2] = {{t, k, 1.0}, {t, 3 + k, -1.0}};
                visit(ctx, REGULARIZATION * f->w_scaled, tt, 2);
            }
}

/* The unknown (free >= 0) or constraint (encoded -2 - index) index of a term. */
static dk_index slot(const dk_fundamental *f, const term *t)
{
    if (t->k < 0)
        return f->el.vu[t->id] >= 0 ? f->el.vu[t->id] : -2 - f->el.vc[t->id];
    if (t->k >= 3)
        return -2 - (f->el.fa[t->id] + t->k - 3);
    return f->el.fu[t->id] >= 0 ? f->el.fu[t->id] + t->k : -2 - (f->el.fc[t->id] + t->k);
}

/* The energy's matrices, assembled straight into columns in two passes over the residuals
 * (issue 19, memory): the first counts each column's entries, the second writes them; A's
 * upper triangle only (CHOLMOD reads no more). Triplets of the whole A (16 bytes an entry,
 * plus 12 for dk_sparse_from_triplets's copy) were the bind's peak up to ~60k vertices:
 * 28 bytes for each of ~230 per vertex, against 12 for each of ~120 now. */
typedef struct assembly {
    const dk_fundamental *f;
    int fill;                 /* 0: count into a_next[j + 1], b_next[j + 1]; 1: write      */
    int64_t *a_next, *b_next; /* per column of A (n_unk + 1), of B (n_con + 1)             */
    dk_index *ar, *br;
    double *av, *bv;
    /* progress: residuals visited in both passes, an estimate of one pass's count, and the
     * first failure (a cancellation), after which the visits do nothing */
    double visits, per_pass;
    dk_status st;
    dk_error *err;
} assembly;

static void assemble_visit(void *ctx, double w, const term *t, int nt)
{
    assembly *s = ctx;
    if (s->st != DK_OK ||
        (s->st = dk_progress_tick(s->f->prog, s->visits++, 2.0 * s->per_pass, s->err)) != DK_OK)
        return;
    dk_index idx[4];
    for (int i = 0; i < nt; i++)
        idx[i] = slot(s->f, t + i);
    for (int i = 0; i < nt; i++) {
        if (idx[i] < 0)
            continue;
        for (int j = 0; j < nt; j++) {
            if (t[i].c == 0.0 || t[j].c == 0.0)
                continue;
            if (idx[j] >= 0) {
                if (idx[i] > idx[j])
                    continue; /* the lower triangle */
                if (!s->fill) {
                    s->a_next[idx[j] + 1]++;
                } else {
                    const int64_t p = s->a_next[idx[j]]++;
                    s->ar[p] = idx[i], s->av[p] = w * t[i].c * t[j].c;
                }
            } else {
                const dk_index col = -2 - idx[j];
                if (!s->fill) {
                    s->b_next[col + 1]++;
                } else {
                    const int64_t p = s->b_next[col]++;
                    s->br[p] = idx[i], s->bv[p] = w * t[i].c * t[j].c;
                }
            }
        }
    }
}

/* Counts, allocates and writes A (upper triangle) and B of the numbering in `view`. */
dk_status fr_assemble(const dk_fundamental *view, dk_index nu, dk_index ncon, dk_sparse **A,
                          dk_sparse **B, dk_error *err)
{
    const dk_index nb_cols = ncon > 0 ? ncon : 1;
    assembly a = {view, 0, calloc((size_t)nu + 2, sizeof(int64_t)),
                  calloc((size_t)nb_cols + 2, sizeof(int64_t)), NULL, NULL, NULL, NULL,
                  0.0, 3.0 * ((double)view->mesh->n_faces + (double)view->mesh->n_edges +
                              (double)view->n_bridges + (double)view->n_fins), DK_OK, err};
    int64_t *a_start = malloc(((size_t)nu + 2) * sizeof(int64_t));
    int64_t *b_start = malloc(((size_t)nb_cols + 2) * sizeof(int64_t));
    dk_status st = DK_OK;
    if (!a.a_next || !a.b_next || !a_start || !b_start) {
        st = fr_oom(err, "assembly");
        goto done;
    }
    fr_for_each_residual(view, assemble_visit, &a);
    if ((st = a.st) != DK_OK)
        goto done;
    for (dk_index j = 0; j < nu; j++)
        a.a_next[j + 1] += a.a_next[j];
    for (dk_index j = 0; j < nb_cols; j++)
        a.b_next[j + 1] += a.b_next[j];
    memcpy(a_start, a.a_next, ((size_t)nu + 1) * sizeof(int64_t));
    memcpy(b_start, a.b_next, ((size_t)nb_cols + 1) * sizeof(int64_t));
    const size_t na = (size_t)a_start[nu], nbe = (size_t)b_start[nb_cols];
    a.ar = malloc((na + 1) * sizeof(dk_index)), a.av = malloc((na + 1) * sizeof(double));
    a.br = malloc((nbe + 1) * sizeof(dk_index)), a.bv = malloc((nbe + 1) * sizeof(double));
    if (!a.ar || !a.av || !a.br || !a.bv) {
        free(a.ar), free(a.av), free(a.br), free(a.bv);
        st = fr_oom(err, "assembly");
        goto done;
    }
    a.fill = 1;
    a.visits = a.per_pass; /* the second pass: the first one's share is done */
    fr_for_each_residual(view, assemble_visit, &a);
    if ((st = a.st) != DK_OK) {
        free(a.ar), free(a.av), free(a.br), free(a.bv);
        goto done;
    }
    /* (both take the arrays, on every path) */
    st = dk_sparse_from_columns(nu, nu, a_start, a.ar, a.av, A, err);
    if (st == DK_OK)
        st = dk_sparse_from_columns(nu, nb_cols, b_start, a.br, a.bv, B, err);
    else
        free(a.br), free(a.bv);
done:
    free(a.a_next), free(a.b_next), free(a_start), free(b_start);
    return st;
}

typedef struct evaluation {
    const dk_fundamental *f;
    const double *x, *frames;
    double E;
} evaluation;

static void energy_visit(void *ctx, double w, const term *t, int nt)
{
    evaluation *s = ctx;
    for (int d = 0; d < 3; d++) {
        double r = 0.0;
        for (int i = 0; i < nt; i++)
            r += t[i].c * (t[i].k < 0    ? s->x[3 * (size_t)t[i].id + d]
                           : t[i].k < 3 ? s->frames[9 * (size_t)t[i].id + 3 * d + t[i].k]
                                        : s->f->el.zc[(size_t)d * s->f->el.n_con + s->f->el.fa[t[i].id] +
                                                   t[i].k - 3]);
        s->E += 0.5 * w * r * r;
    }
}

double fr_energy(const dk_fundamental *f, const double *positions)
{
    evaluation ev = {f, positions, f->frames, 0.0};
    fr_for_each_residual(f, energy_visit, &ev);
    return ev.E;
}
