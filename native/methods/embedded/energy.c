/* DeformKit embedded deformation: F, J^T f and J^T J (embedded_internal.h). */
#include "embedded_internal.h"

/* One residual's Jacobian row: up to 2 K_MAX nodes' entries, each a free index u (-1: a
 * constant node, no unknowns), its 4 slots of coordinate d (R[d][0..2], t[d]) or 6 of a
 * rotation residual, and their coefficients. */
typedef struct jrow {
    int n;
    dk_index u[2 * K_MAX];
    int64_t blk[2 * K_MAX][2 * K_MAX];
    int ns;
    int slot[2 * K_MAX][6];
    double coef[2 * K_MAX][6];
} jrow;

/* a slot's place among one coordinate's four (R[d][0..2], t[d]) */
static int slot4(int a)
{
    return a < 9 ? a % 3 : 3;
}

/* Adds r^2 to *F, and, when `s` is given, the row's part of J^T f (into grad, for
 * ED_GRADIENT) or of K (into kblk, for ED_QUADRATIC: rows of the regularization and
 * positional terms of one coordinate). */
static void add_row(ed_system *s, unsigned what, const jrow *j, double r, double *F)
{
    *F += r * r;
    if (!s)
        return;
    for (int p = 0; p < j->n; p++) {
        if (j->u[p] < 0)
            continue;
        if (what & ED_GRADIENT)
            for (int i = 0; i < j->ns; i++)
                s->grad[12 * j->u[p] + j->slot[p][i]] += j->coef[p][i] * r;
        if (!(what & ED_QUADRATIC))
            continue;
        for (int q = 0; q < j->n; q++) {
            const int64_t b = j->blk[p][q];
            if (b < 0)
                continue;
            double *B = s->kblk + 16 * (size_t)b;
            for (int i = 0; i < j->ns; i++)
                for (int c = 0; c < j->ns; c++)
                    B[4 * slot4(j->slot[p][i]) + slot4(j->slot[q][c])] +=
                        j->coef[p][i] * j->coef[q][c];
        }
    }
}

/* The unit of length of F: twice the root mean square distance of the points from their
 * centroid (a sphere's diameter, 0.82 for the unit square), so that it does not depend on
 * where the model is or how it is turned, as a bounding box would; 1 when the points
 * coincide. Our choice: the paper gives no unit. */
double ed_unit_length(const double *p, dk_index n)
{
    double c[3] = {0.0, 0.0, 0.0}, s = 0.0;
    for (dk_index i = 0; i < n; i++)
        for (int d = 0; d < 3; d++)
            c[d] += p[3 * (size_t)i + d] / (double)n;
    for (dk_index i = 0; i < n; i++)
        for (int d = 0; d < 3; d++) {
            const double e = p[3 * (size_t)i + d] - c[d];
            s += e * e / (double)n;
        }
    const double L = 2.0 * sqrt(s);
    return L > 0.0 && isfinite(L) ? L : 1.0;
}

/* F(x) (eq. 9); with `s`, also what `what` asks for: J^T f (s->grad) and E_rot's part of
 * J^T J (s->rot) for ED_GRADIENT, or the constant part K (s->kblk) for ED_QUADRATIC, whose
 * returned F is then that of the first coordinate's regularization and positional terms.
 *
 * Lengths are measured in units of ed->L (ed_unit_length() of the bind mesh): E_reg and E_con are
 * divided by L^2, and the unknowns are R and t / L. The paper gives fixed weights (w_rot 1,
 * w_reg 10, w_con 100) and eq. 12's tests against 1, but E_rot is dimensionless while E_reg
 * and E_con scale with length squared: in the model's own units the same scene scaled by
 * 0.01 stopped 5% of its diagonal off, at 1e-6 after no iteration at all, and from about 20x
 * up a 45 degree handle turn returned the rest pose (the second hostile review). In units of
 * L, F, its gradient, the steps and the tests are the same at any scale. So the Jacobian's
 * columns are those of t / L (a t entry's coefficient is L times its length one: wg, wc w),
 * gn_step moves t by L times its step, and the step and iterate norms read t / L. ed->x
 * itself stays in the model's units. */
double ed_evaluate(const dk_embedded *ed, ed_system *s, const ed_system *sys,
                   const double *x, unsigned what)
{
    const dk_index k = ed->k, m = ed->m;
    const double wr = sqrt(ed->opt.w_rot), wg = sqrt(ed->opt.w_reg), wc = sqrt(ed->opt.w_con);
    const double wgL = wg / ed->L, wcL = wc / ed->L; /* per unit of length */
    double F = 0.0;
    jrow jr;
    if (!s)
        what &= ED_MOVING | ED_CONSTANT;
    const int moving_only = (what & ED_MOVING) != 0, constant_only = (what & ED_CONSTANT) != 0;
    if (what & ED_GRADIENT) {
        memset(s->grad, 0, 12 * (size_t)s->n_free * sizeof(double));
        memset(s->rot, 0, 81 * (size_t)s->n_free * sizeof(double));
    }
    if (what & ED_QUADRATIC)
        memset(s->kblk, 0, 16 * (size_t)s->n_blocks * sizeof(double));
    const int n_coord = what == ED_QUADRATIC ? 1 : 3; /* K is the same for each coordinate */
    /* rotation (eqs. 5-6): six residuals per free node over its 9 R entries */
    static const int pairs[6][2] = {{0, 1}, {0, 2}, {1, 2}, {0, 0}, {1, 1}, {2, 2}};
    for (dk_index j = 0; j < m && !(what & ED_QUADRATIC) && !constant_only; j++) {
        const dk_index u = sys->node_unknown[j];
        if (u < 0)
            continue; /* R = I: Rot = 0 */
        const double *R = x + 12 * (size_t)j;
        for (int r = 0; r < 6; r++) {
            const int a = pairs[r][0], b = pairs[r][1];
            double dot = 0.0;
            for (int d = 0; d < 3; d++)
                dot += R[3 * d + a] * R[3 * d + b];
            if (a == b)
                dot -= 1.0;
            jr.n = 1;
            jr.u[0] = u;
            jr.ns = 6;
            for (int d = 0; d < 3; d++) { /* d(c_a . c_b)/dR[d][a] = R[d][b] and vice versa */
                jr.slot[0][2 * d] = 3 * d + a;
                jr.slot[0][2 * d + 1] = 3 * d + b;
                jr.coef[0][2 * d] = wr * (a == b ? R[3 * d + a] : R[3 * d + b]);
                jr.coef[0][2 * d + 1] = wr * (a == b ? R[3 * d + a] : R[3 * d + a]);
            }
            add_row(s, what, &jr, wr * dot, &F);
            if (what & ED_GRADIENT) { /* J^T J's rotation block */
                double *B = s->rot + 81 * (size_t)u;
                for (int i = 0; i < 6; i++)
                    for (int c = 0; c < 6; c++)
                        B[9 * jr.slot[0][i] + jr.slot[0][c]] += jr.coef[0][i] * jr.coef[0][c];
            }
        }
    }
    /* regularization (eq. 7), both directions of each edge, one residual per coordinate */
    for (dk_index e = 0; e < ed->n_edges; e++)
        for (int dir = 0; dir < 2; dir++) {
            const dk_index j = ed->edges[2 * e + dir], q = ed->edges[2 * e + 1 - dir];
            const int moves = sys->node_unknown[j] >= 0 || sys->node_unknown[q] >= 0;
            if ((moving_only && !moves) || (constant_only && moves))
                continue;
            const double *Rj = x + 12 * (size_t)j, *tj = Rj + 9, *tq = x + 12 * (size_t)q + 9;
            const double *gj = ed->g + 3 * j, *gq = ed->g + 3 * q;
            const double dg[3] = {gq[0] - gj[0], gq[1] - gj[1], gq[2] - gj[2]};
            const int64_t *b = sys->edge_blk + 8 * (size_t)e + 4 * dir;
            for (int d = 0; d < n_coord; d++) {
                const double r = Rj[3 * d] * dg[0] + Rj[3 * d + 1] * dg[1] +
                                 Rj[3 * d + 2] * dg[2] + gj[d] + tj[d] - gq[d] - tq[d];
                jr.n = 2;
                jr.u[0] = sys->node_unknown[j];
                jr.u[1] = sys->node_unknown[q];
                jr.blk[0][0] = b[0];
                jr.blk[0][1] = b[1];
                jr.blk[1][0] = b[2];
                jr.blk[1][1] = b[3];
                jr.ns = 4;
                for (int c = 0; c < 3; c++) {
                    jr.slot[0][c] = 3 * d + c;
                    jr.coef[0][c] = wgL * dg[c];
                    jr.slot[1][c] = 3 * d + c;
                    jr.coef[1][c] = 0.0; /* t_q only: its R does not enter */
                }
                jr.slot[0][3] = 9 + d;
                jr.coef[0][3] = wg;
                jr.slot[1][3] = 9 + d;
                jr.coef[1][3] = -wg;
                add_row(s, what, &jr, wgL * r, &F);
            }
        }
    /* positional terms (eq. 8): handles to their targets, held fixed vertices to rest */
    const dk_index l0 = constant_only ? sys->n_pos_moving : 0;
    const dk_index l1 = moving_only ? sys->n_pos_moving : sys->n_pos;
    for (dk_index l = l0; l < l1; l++) {
        const dk_index v = sys->pos_vertex[l];
        const double *p = ed->p + 3 * v;
        const dk_index *nb = ed->nb + (size_t)v * k;
        const double *wv = ed->w + (size_t)v * k;
        const double *tg = sys->pos_target_row[l] >= 0 ? sys->targets + 3 * sys->pos_target_row[l]
                                                       : p;
        for (int d = 0; d < n_coord; d++) {
            double r = -tg[d];
            jr.n = 0;
            jr.ns = 4;
            for (dk_index q = 0; q < k; q++) {
                const dk_index j = nb[q];
                if (j < 0)
                    continue;
                const double *R = x + 12 * (size_t)j, *g = ed->g + 3 * j;
                const double dv[3] = {p[0] - g[0], p[1] - g[1], p[2] - g[2]};
                r += wv[q] * (R[3 * d] * dv[0] + R[3 * d + 1] * dv[1] + R[3 * d + 2] * dv[2] +
                              g[d] + R[9 + d]);
                const int c = jr.n++;
                jr.u[c] = sys->node_unknown[j];
                for (int e = 0; e < 3; e++) {
                    jr.slot[c][e] = 3 * d + e;
                    jr.coef[c][e] = wcL * wv[q] * dv[e];
                }
                jr.slot[c][3] = 9 + d;
                jr.coef[c][3] = wc * wv[q];
            }
            if (what & ED_QUADRATIC) { /* the blocks of this vertex's node pairs */
                int c = 0;
                int idx[K_MAX];
                for (dk_index q = 0; q < k; q++)
                    if (nb[q] >= 0)
                        idx[c++] = (int)q;
                for (int a = 0; a < jr.n; a++)
                    for (int b2 = 0; b2 < jr.n; b2++)
                        jr.blk[a][b2] = sys->pos_blk[((size_t)l * k + idx[a]) * k + idx[b2]];
            }
            add_row(s, what, &jr, wcL * r, &F);
        }
    }
    return F;
}
