/* DeformKit ARAP: the local step: rotations refined by Newton steps on SO(3), cell
 * energies, the global step's right-hand side (see arap_internal.h). */
#include "arap_internal.h"

/* One Newton step of refine_rotation for element type T (double, or a GCC vector of
 * doubles lane by lane): declares M = r^T a, its skew part g, K = tr(M) I - sym(M), K's
 * adjugate c.., det, the margin s, the step w = -K^-1 g with t2 = |w|^2, and the Cayley
 * factors q0..q8 of the rotation update. Computed before the caller's tests of K and t2
 * (pure arithmetic: a failed test discards them), in one text for the scalar and the
 * four-lane code, so that both round every lane identically. */
#define DK_NEWTON_STEP(T, a, r)                                                            \
    T m0 = r[0] * a[0] + r[3] * a[3] + r[6] * a[6];                                        \
    T m1 = r[0] * a[1] + r[3] * a[4] + r[6] * a[7];                                        \
    T m2 = r[0] * a[2] + r[3] * a[5] + r[6] * a[8];                                        \
    T m3 = r[1] * a[0] + r[4] * a[3] + r[7] * a[6];                                        \
    T m4 = r[1] * a[1] + r[4] * a[4] + r[7] * a[7];                                        \
    T m5 = r[1] * a[2] + r[4] * a[5] + r[7] * a[8];                                        \
    T m6 = r[2] * a[0] + r[5] * a[3] + r[8] * a[6];                                        \
    T m7 = r[2] * a[1] + r[5] * a[4] + r[8] * a[7];                                        \
    T m8 = r[2] * a[2] + r[5] * a[5] + r[8] * a[8];                                        \
    T g0 = m5 - m7, g1 = m6 - m2, g2 = m1 - m3;                                            \
    T tr = m0 + m4 + m8;                                                                   \
    T k00 = tr - m0, k11 = tr - m4, k22 = tr - m8;                                         \
    T k01 = -0.5 * (m1 + m3), k02 = -0.5 * (m2 + m6), k12 = -0.5 * (m5 + m7);              \
    /* adjugate of K; Sylvester's criterion (the caller) with margins relative to tr K */ \
    T c00 = k11 * k22 - k12 * k12, c01 = k02 * k12 - k01 * k22,                            \
      c02 = k01 * k12 - k02 * k11, c11 = k00 * k22 - k02 * k02,                            \
      c12 = k01 * k02 - k00 * k12, c22 = k00 * k11 - k01 * k01;                            \
    T det = k00 * c00 + k01 * c01 + k02 * c02;                                             \
    T s = 1e-3 * (k00 + k11 + k22);                                                        \
    T inv = -1.0 / det;                                                                    \
    T w0 = inv * (c00 * g0 + c01 * g1 + c02 * g2);                                         \
    T w1 = inv * (c01 * g0 + c11 * g1 + c12 * g2);                                         \
    T w2 = inv * (c02 * g0 + c12 * g1 + c22 * g2);                                         \
    T t2 = w0 * w0 + w1 * w1 + w2 * w2;                                                    \
    /* Cayley retraction Q = I + f ([v]x + [v]x^2), v = w / 2, f = 2 / (1 + |v|^2):       \
     * orthogonal, agrees with exp([w]x) to second order */                               \
    T v0 = 0.5 * w0, v1 = 0.5 * w1, v2 = 0.5 * w2, vv = 0.25 * t2;                         \
    T f = 2.0 / (1.0 + vv);                                                                \
    T q0 = 1.0 + f * (v0 * v0 - vv), q4 = 1.0 + f * (v1 * v1 - vv),                        \
      q8 = 1.0 + f * (v2 * v2 - vv);                                                       \
    T q1 = f * (v0 * v1 - v2), q3 = f * (v0 * v1 + v2);                                    \
    T q2 = f * (v0 * v2 + v1), q6 = f * (v0 * v2 - v1);                                    \
    T q5 = f * (v1 * v2 - v0), q7 = f * (v1 * v2 + v0);

/* The rotation maximising trace(R^T a), refined from the guess r (in/out; a rotation on
 * entry) by Newton steps on SO(3). For R = r exp([w]x) and M = r^T a,
 *     trace(R^T a) = tr M - w.g - w^T K w / 2 + O(|w|^3),
 *     g = (M12 - M21, M20 - M02, M01 - M10),  K = tr(M) I - (M + M^T) / 2,
 * so a Newton step is w = -K^-1 g, applied with the Cayley rotation (exactly orthogonal,
 * equal to exp([w]x) to second order, so the convergence stays quadratic). At a stationary
 * point (M symmetric) K positive definite means a strict local maximum, and on SO(3) every
 * strict local maximum of trace(R^T a) is the global one (at the other stationary points
 * U diag(+-1) V^T some pair of signed singular values has a sum <= 0, an eigenvalue of K).
 * Returns 1 once a step of at most 1e-8 rad has been taken (the remaining error is then of
 * order 1e-16) with K positive definite by a margin; 0 when the guess is too far (a step
 * over 1 rad, or not converged in 4 steps) or a is degenerate (rank <= 1, equal singular
 * values at a reflection): the caller then uses dk_closest_rotation, whose result is the
 * same maximiser. In a local/global iteration a cell's rotation moves little from one
 * iteration to the next: two steps from the previous rotation cost about half of
 * dk_closest_rotation from scratch (61 vs 132 ns on near-rotations; on the armadillo a plain
 * iteration went from 9.0 to 5.4 ms). */
static int refine_rotation(const double a[9], double r[9])
{
    for (int step = 0; step < 4; step++) {
        DK_NEWTON_STEP(double, a, r)
        if (!(k00 > s && c22 > s * s && det > s * s * s))
            return 0;
        if (!(t2 <= 1.0))
            return 0; /* not finite, or too far for a Newton step */
        for (int i = 0; i < 3; i++) {
            double x = r[3 * i], y = r[3 * i + 1], z = r[3 * i + 2];
            r[3 * i] = x * q0 + y * q3 + z * q6;
            r[3 * i + 1] = x * q1 + y * q4 + z * q7;
            r[3 * i + 2] = x * q2 + y * q5 + z * q8;
        }
        if (t2 <= 1e-16) {
            /* one Newton-Schulz step R (3 I - R^T R) / 2: the products above add ~1e-16 of
             * non-orthogonality each, which would otherwise accumulate over many calls */
            double c[9];
            for (int i = 0; i < 3; i++)
                for (int j = i; j < 3; j++)
                    c[3 * i + j] = c[3 * j + i] =
                        (i == j ? 1.5 : 0.0) -
                        0.5 * (r[i] * r[j] + r[3 + i] * r[3 + j] + r[6 + i] * r[6 + j]);
            for (int i = 0; i < 3; i++) {
                double x = r[3 * i], y = r[3 * i + 1], z = r[3 * i + 2];
                r[3 * i] = x * c[0] + y * c[3] + z * c[6];
                r[3 * i + 1] = x * c[1] + y * c[4] + z * c[7];
                r[3 * i + 2] = x * c[2] + y * c[5] + z * c[8];
            }
            return 1;
        }
    }
    return 0;
}

#if defined(__GNUC__)
/* Four cells' refine_rotation at once, lane by lane the same operations in the same order
 * (no contraction: the results equal refine_rotation's bit for bit), on GCC/Clang generic
 * vectors: SSE2 / NEON pairs or one AVX register. refine_rotation is about half of a local
 * step's instructions, all of it arithmetic on a few registers: in lock step the four
 * dependency chains overlap. a: 9 x 4 (entry-major, lane-minor); r: 9 x 4 in/out. Returns
 * a bit mask of the lanes that converged (bit l); the other lanes' r are unspecified and the
 * caller redoes them with dk_closest_rotation. */
typedef double v4d __attribute__((vector_size(32)));
typedef long long v4l __attribute__((vector_size(32)));

/* On x86-64 Linux (ifunc) an AVX2 clone runs the four lanes in one register where the CPU
 * has it; without FMA, so every lane rounds exactly as the baseline SSE2 code does. */
#if defined(__x86_64__) && defined(__linux__) && !defined(__clang__)
#define DK_VEC_CLONES __attribute__((target_clones("avx2", "default")))
#else
#define DK_VEC_CLONES
#endif
#define V4SEL(m, x, y) ((v4d)(((v4l)(x) & (m)) | ((v4l)(y) & ~(m))))

DK_VEC_CLONES static int refine_rotation4(const v4d a[9], v4d r[9])
{
    const v4d half = {0.5, 0.5, 0.5, 0.5};
    v4l done = {0, 0, 0, 0}, failed = {0, 0, 0, 0};
    for (int step = 0; step < 4; step++) {
        const v4l active = ~(done | failed);
        DK_NEWTON_STEP(v4d, a, r)
        v4l spd = (k00 > s) & (c22 > s * s) & (det > s * s * s);
        const v4l ok = spd & (t2 <= 1.0); /* false for NaN */
        failed |= active & ~ok;
        const v4l go = active & ok;
        for (int i = 0; i < 3; i++) {
            v4d x = r[3 * i], y = r[3 * i + 1], z = r[3 * i + 2];
            r[3 * i] = V4SEL(go, x * q0 + y * q3 + z * q6, x);
            r[3 * i + 1] = V4SEL(go, x * q1 + y * q4 + z * q7, y);
            r[3 * i + 2] = V4SEL(go, x * q2 + y * q5 + z * q8, z);
        }
        const v4l fin = go & (t2 <= 1e-16);
        if (fin[0] | fin[1] | fin[2] | fin[3]) {
            v4d c[9];
            for (int i = 0; i < 3; i++)
                for (int j = i; j < 3; j++)
                    c[3 * i + j] = c[3 * j + i] =
                        (i == j ? 1.5 : 0.0) -
                        half * (r[i] * r[j] + r[3 + i] * r[3 + j] + r[6 + i] * r[6 + j]);
            for (int i = 0; i < 3; i++) {
                v4d x = r[3 * i], y = r[3 * i + 1], z = r[3 * i + 2];
                r[3 * i] = V4SEL(fin, x * c[0] + y * c[3] + z * c[6], x);
                r[3 * i + 1] = V4SEL(fin, x * c[1] + y * c[4] + z * c[7], y);
                r[3 * i + 2] = V4SEL(fin, x * c[2] + y * c[5] + z * c[8], z);
            }
            done |= fin;
        }
        const v4l left = ~(done | failed);
        if (!(left[0] | left[1] | left[2] | left[3]))
            break;
    }
    return (done[0] ? 1 : 0) | (done[1] ? 2 : 0) | (done[2] ? 4 : 0) | (done[3] ? 8 : 0);
}
#endif

/* Cell i's covariance a = sum_t w_t (x_a - x_b) e_t^T (the local step's input). */
static inline void cell_covariance(const dk_arap *ar, const double *x, dk_index i, double a[9])
{
    for (int k = 0; k < 9; k++)
        a[k] = 0.0;
    for (dk_index t = ar->cell_start[i]; t < ar->cell_start[i + 1]; t++) {
        const double *pa = x + 3 * ar->ta[t], *pb = x + 3 * ar->tb[t];
        const double *e = ar->te + 3 * t;
        double w = ar->tw[t];
        double d0 = w * (pa[0] - pb[0]), d1 = w * (pa[1] - pb[1]), d2 = w * (pa[2] - pb[2]);
        a[0] += d0 * e[0]; a[1] += d0 * e[1]; a[2] += d0 * e[2];
        a[3] += d1 * e[0]; a[4] += d1 * e[1]; a[5] += d1 * e[2];
        a[6] += d2 * e[0]; a[7] += d2 * e[1]; a[8] += d2 * e[2];
    }
}

/* K^-1 for the optimal rotation r of covariance a, K = tr(M) I - sym(M), M = r^T a: the
 * Hessian of -trace(R^T a) in R = r exp([w]x) at w = 0 (see refine_rotation), whose inverse
 * maps a change of a to the rotation's response (newton_step). Stored as 00 01 02 11 12
 * 22; all zero (the rotation held in the Hessian, a positive semi-definite simplification)
 * where K is not positive definite by refine_rotation's margins (a degenerate cell). */
static inline void cell_kinv(const double a[9], const double r[9], double o[6])
{
    DK_NEWTON_STEP(double, a, r)
    (void)g0, (void)g1, (void)g2, (void)inv, (void)w0, (void)w1, (void)w2, (void)q0, (void)q1,
        (void)q2, (void)q3, (void)q4, (void)q5, (void)q6, (void)q7, (void)q8;
    if (k00 > s && c22 > s * s && det > s * s * s && isfinite(det)) {
        const double id = 1.0 / det;
        o[0] = c00 * id;
        o[1] = c01 * id;
        o[2] = c02 * id;
        o[3] = c11 * id;
        o[4] = c12 * id;
        o[5] = c22 * id;
    } else {
        o[0] = o[1] = o[2] = o[3] = o[4] = o[5] = 0.0;
    }
}

/* Cell i's energy with rotation r. */
static inline double cell_energy(const dk_arap *ar, const arap_system *s, const double *x,
                                 dk_index i, const double r[9])
{
    double ce = 0.0;
    for (dk_index t = ar->cell_start[i]; t < ar->cell_start[i + 1]; t++) {
        const double *pa = x + 3 * ar->ta[t], *pb = x + 3 * ar->tb[t];
        const double *e = ar->te + 3 * t;
        double re0 = r[0] * e[0] + r[1] * e[1] + r[2] * e[2];
        double re1 = r[3] * e[0] + r[4] * e[1] + r[5] * e[2];
        double re2 = r[6] * e[0] + r[7] * e[1] + r[8] * e[2];
        double q0 = pa[0] - pb[0] - re0, q1 = pa[1] - pb[1] - re1, q2 = pa[2] - pb[2] - re2;
        ce += s->tws[t] * (q0 * q0 + q1 * q1 + q2 * q2);
    }
    return ce;
}

/* Local step and energy of the cells v0 .. v1-1 at positions x: rotations into rot (may be
 * NULL: then only the energy, with rotations from scratch); returns their energy. When rot
 * is given it holds rotations on entry (the previous local step's, or identities at a cold
 * start) from which each cell's rotation is refined (refine_rotation, else
 * dk_closest_rotation): both give the maximiser to rounding. The refinements run four cells
 * at a time (refine_rotation4, the same result); the energies are summed in cell order
 * either way. */
static double cells_energy(const dk_arap *ar, const arap_system *s, const double *x,
                           double *rot, dk_index v0, dk_index v1)
{
    double energy = 0.0;
    dk_index i = v0;
#if defined(__GNUC__)
    if (rot)
        for (; i + 4 <= v1; i += 4) {
            double a4[4][9];
            v4d av[9], rv[9];
            for (int l = 0; l < 4; l++)
                cell_covariance(ar, x, i + l, a4[l]);
            const double *r0 = rot + 9 * (size_t)i;
            for (int k = 0; k < 9; k++) {
                av[k] = (v4d){a4[0][k], a4[1][k], a4[2][k], a4[3][k]};
                rv[k] = (v4d){r0[k], r0[9 + k], r0[18 + k], r0[27 + k]};
            }
            const int okmask = refine_rotation4(av, rv);
            for (int l = 0; l < 4; l++) {
                double r[9];
                if (okmask & (1 << l))
                    for (int k = 0; k < 9; k++)
                        r[k] = rv[k][l];
                else
                    dk_closest_rotation(a4[l], r);
                if (s->kinv)
                    cell_kinv(a4[l], r, s->kinv + 6 * (size_t)(i + l));
                energy += cell_energy(ar, s, x, i + l, r);
                memcpy(rot + 9 * (size_t)(i + l), r, sizeof r);
            }
        }
#endif
    for (; i < v1; i++) {
        double a[9], r[9];
        cell_covariance(ar, x, i, a);
        if (rot) {
            memcpy(r, rot + 9 * (size_t)i, sizeof r);
            if (!refine_rotation(a, r))
                dk_closest_rotation(a, r);
        } else {
            dk_closest_rotation(a, r);
        }
        energy += cell_energy(ar, s, x, i, r);
        if (rot) {
            memcpy(rot + 9 * (size_t)i, r, sizeof r);
            if (s->kinv)
                cell_kinv(a, r, s->kinv + 6 * (size_t)i);
        }
    }
    return energy;
}

typedef struct cells_job {
    const dk_arap *ar;
    const arap_system *s;
    const double *x;
    double *rot;
    double energy[2];
} cells_job;

/* One half of the cells (a dk_range_fn). */
static void cells_part(void *ctx, dk_index v0, dk_index v1, int part)
{
    cells_job *j = ctx;
    j->energy[part] = cells_energy(j->ar, j->s, j->x, j->rot, v0, v1);
}

typedef struct rhs_job {
    const arap_system *s;
    const double *rot;
} rhs_job;

/* Rows [u0, u1) of the right-hand side for the rotations (a dk_range_fn; see
 * arap_system.rg). */
static void rhs_part(void *ctx, dk_index u0, dk_index u1, int part)
{
    const rhs_job *j = ctx;
    const arap_system *s = j->s;
    const size_t nu = (size_t)s->nu;
    (void)part;
    for (dk_index u = u0; u < u1; u++) {
        double b0 = s->rhs_const[u], b1 = s->rhs_const[nu + u], b2 = s->rhs_const[2 * nu + u];
        for (int64_t k = s->rg_start[u]; k < s->rg_start[u + 1]; k++) {
            const double *g = s->rg[k].g, *r = j->rot + 9 * (size_t)s->rg[k].cell;
            const double h0 = r[0] * g[0] + r[1] * g[1] + r[2] * g[2];
            const double h1 = r[3] * g[0] + r[4] * g[1] + r[5] * g[2];
            const double h2 = r[6] * g[0] + r[7] * g[1] + r[8] * g[2];
            b0 += h0;
            b1 += h1;
            b2 += h2;
            if (s->nt) { /* Newton: R_c g_{v,c}, for the Hessian products */
                s->nt[k].h[0] = (float)h0;
                s->nt[k].h[1] = (float)h1;
                s->nt[k].h[2] = (float)h2;
            }
        }
        s->rhs[u] = b0;
        s->rhs[nu + u] = b1;
        s->rhs[2 * nu + u] = b2;
    }
}

/* s->rhs := the global step's right-hand side for the rotations rot. */
void arap_rotations_rhs(const dk_arap *ar, arap_system *s, const double *rot)
{
    rhs_job job = {s, rot};
    dk_team_run_halves(ar->team, rhs_part, &job, s->nu,
                       ar->n_terms >= PARALLEL_TERMS ? 0 : s->nu + 1);
}

/* The soft handles' penalties at x (0 before the first solve's targets). */
static double soft_penalties(const arap_system *s, const double *x)
{
    double energy = 0.0;
    if (s->have_targets)
        for (dk_index u = 0; u < s->nu; u++) {
            dk_index v = s->unknowns[u];
            if (s->soft_k[v] > 0.0)
                energy += s->soft_k[v] * dist2(x + 3 * v, s->targets + 3 * s->target_of[v]);
        }
    return energy;
}

/* Local step and energy at positions x: rotations into rot (may be NULL: then only the
 * energy), returns E(x) including soft penalties (when targets are known); the caller gets
 * the next global step's right-hand side from rotations_rhs, once it keeps the iterate. On
 * big meshes the cells are split in two halves, the second on the object's helper thread
 * (the target machines have two cores); without one the calling thread does both halves.
 * The split point depends only on the mesh, so results are reproducible. */
double arap_local_energy(const dk_arap *ar, const arap_system *s, const double *x,
                           double *rot)
{
    double energy;
    if (ar->n_terms >= PARALLEL_TERMS) {
        cells_job job = {ar, s, x, rot, {0.0, 0.0}};
        dk_team_run_halves(ar->team, cells_part, &job, ar->nc, 0);
        energy = job.energy[0] + job.energy[1];
    } else {
        energy = cells_energy(ar, s, x, rot, 0, ar->nc);
    }
    return energy + soft_penalties(s, x);
}

typedef struct sample_job {
    const dk_arap *ar;
    const arap_system *s;
    const double *x;
    dk_index stride;
    double energy[2];
} sample_job;

/* Sample blocks [k0, k1) of arap_sampled_energy (a dk_range_fn): block k is the cells
 * k stride SAMPLE_BLOCK .. + SAMPLE_BLOCK - 1 (consecutive cells share their neighbours'
 * cache lines in the locality order; single cells stride apart cost a miss each). */
#define SAMPLE_BLOCK 64
static void sample_part(void *ctx, dk_index k0, dk_index k1, int part)
{
    sample_job *j = ctx;
    const dk_index n = j->ar->nc;
    double energy = 0.0;
    for (dk_index k = k0; k < k1; k++) {
        const dk_index i0 = k * j->stride * SAMPLE_BLOCK;
        const dk_index i1 = n - i0 > SAMPLE_BLOCK ? i0 + SAMPLE_BLOCK : n;
        for (dk_index i = i0; i < i1; i++) {
            double a[9], r[9];
            cell_covariance(j->ar, j->x, i, a);
            memcpy(r, j->ar->rot + 9 * (size_t)i, sizeof r);
            if (!refine_rotation(a, r))
                dk_closest_rotation(a, r);
            energy += cell_energy(j->ar, j->s, j->x, i, r);
        }
    }
    j->energy[part] = energy;
}

double arap_sampled_energy(const dk_arap *ar, const arap_system *s, const double *x,
                           dk_index stride)
{
    sample_job job = {ar, s, x, stride, {0.0, 0.0}};
    const dk_index span = stride * SAMPLE_BLOCK, m = (ar->nc + span - 1) / span;
    dk_team_run_halves(ar->team, sample_part, &job, m, 64);
    double energy = job.energy[0] + job.energy[1];
    return energy + soft_penalties(s, x);
}

/* Constant part of the right-hand side: couplings to eliminated vertices at positions x,
 * and the soft targets. */
void arap_build_rhs_const(const dk_arap *ar, arap_system *s, const double *x)
{
    const dk_index nu = s->nu;
    memset(s->rhs_const, 0, 3 * (size_t)nu * sizeof(double));
    for (int64_t t = 0; t < ar->n_terms; t++) {
        dk_index a = ar->ta[t], b = ar->tb[t];
        dk_index ua = s->unk[a], ub = s->unk[b];
        if ((ua >= 0) == (ub >= 0))
            continue;
        dk_index u = ua >= 0 ? ua : ub, known = ua >= 0 ? b : a;
        for (int d = 0; d < 3; d++)
            s->rhs_const[(size_t)d * nu + u] += s->tws[t] * x[3 * known + d];
    }
    for (dk_index u = 0; u < nu; u++) {
        dk_index v = s->unknowns[u];
        if (s->soft_k[v] > 0.0)
            for (int d = 0; d < 3; d++)
                s->rhs_const[(size_t)d * nu + u] +=
                    s->soft_k[v] * s->targets[3 * s->target_of[v] + d];
    }
}

void arap_scatter(const arap_system *s, const double *xu, double *x)
{
    const dk_index nu = s->nu;
    for (dk_index u = 0; u < nu; u++)
        for (int d = 0; d < 3; d++)
            x[3 * s->unknowns[u] + d] = xu[(size_t)d * nu + u];
}

void arap_gather(const arap_system *s, const double *x, double *xu)
{
    const dk_index nu = s->nu;
    for (dk_index u = 0; u < nu; u++)
        for (int d = 0; d < 3; d++)
            xu[(size_t)d * nu + u] = x[3 * s->unknowns[u] + d];
}

