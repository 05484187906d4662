/* Shape matching's integrators (sm_internal.h; the formulas are in dk_shape_matching.h): one
 * substep of h seconds for the vertices that are not kinematic. The kinematic ones are placed
 * by the driver's `place` at the stage's time; their velocities are the driver's. */
#include "sm_internal.h"

#include <math.h>
#include <string.h>

/* Acceleration of free vertex i at (x, v) with goals g: k (g - x) + gravity - d (v - u). */
static inline void accel(const sm_step *st, dk_index i, const double *x, const double *v,
                         const double *g, double a[3])
{
    for (int c = 0; c < 3; c++) {
        const size_t j = 3 * (size_t)i + (size_t)c;
        a[c] = st->k[i] * (g[j] - x[j]) + st->gravity[c] - st->d[i] * (v[j] - st->u[j]);
    }
}

static void semi_implicit(const sm_step *st, double *x, double *v, const double *g)
{
    const double h = st->h;
    for (dk_index i = 0; i < st->n; i++) {
        if (st->kinematic[i])
            continue;
        /* (v + h (k (g - x) + gravity) + h d u) / (1 + h d), the damping's share of u
         * written as hd / (1 + hd) so that no damping rate overflows it */
        const double hd = h * st->d[i], inv = 1.0 / (1.0 + hd), share = hd / (1.0 + hd);
        for (int c = 0; c < 3; c++) {
            const size_t j = 3 * (size_t)i + (size_t)c;
            v[j] = (v[j] + h * (st->k[i] * (g[j] - x[j]) + st->gravity[c])) * inv +
                   (isfinite(share) ? share : 1.0) * st->u[j];
            x[j] += h * v[j];
        }
    }
}

static void explicit_euler(const sm_step *st, double *x, double *v, const double *g)
{
    const double h = st->h;
    for (dk_index i = 0; i < st->n; i++) {
        if (st->kinematic[i])
            continue;
        double a[3];
        accel(st, i, x, v, g, a);
        for (int c = 0; c < 3; c++) {
            const size_t j = 3 * (size_t)i + (size_t)c;
            x[j] += h * v[j]; /* the old velocity: the slides' code */
            v[j] += h * a[c];
        }
    }
}

/* Backward Euler, v' = v + h (k (g(x') - x') + gravity - d v'), x' = x + h v': the linear
 * terms taken implicitly and the goals lagged, v'(1 + h d + h^2 k) = v + h k (g(x + h v'_old) -
 * x) + h gravity, iterated to its fixed point (each pass contracts the modes the goals follow,
 * a translation, by alpha / (1 + alpha) <= 1/2; the others settle at once). The first guess
 * holds the goals at x(t). (The damping acts on v - u, u the input's velocity.) */
enum { IMPLICIT_MAX_PASSES = 40 };

static void implicit_euler(const sm_step *st, double *x, double *v, double *g,
                           sm_goals_fn goals_at, sm_place_fn place, void *ctx, double *work)
{
    const size_t N = 3 * (size_t)st->n;
    const double h = st->h;
    double *vn = work, *xs = work + N, *vs = work + 2 * N;
    memcpy(xs, x, N * sizeof *xs);
    memcpy(vs, v, N * sizeof *vs);
    for (int pass = 0; pass < IMPLICIT_MAX_PASSES; pass++) {
        double change = 0.0, size = 0.0;
        for (dk_index i = 0; i < st->n; i++) {
            if (st->kinematic[i])
                continue;
            const double den = 1.0 + h * st->d[i] + h * h * st->k[i], inv = 1.0 / den;
            const double share = isfinite(den) ? h * st->d[i] / den : 1.0;
            for (int c = 0; c < 3; c++) {
                const size_t j = 3 * (size_t)i + (size_t)c;
                const double vj = (v[j] + h * (st->k[i] * (g[j] - x[j]) + st->gravity[c])) * inv +
                                  share * st->u[j];
                if (pass > 0) {
                    const double dv = vj - vn[j];
                    change = dv > change ? dv : -dv > change ? -dv : change;
                }
                size = vj > size ? vj : -vj > size ? -vj : size;
                vn[j] = vj;
            }
        }
        if (pass > 0 && !(change > 1e-13 * size))
            break;
        /* the goals at x + h v' (the kinematic vertices at the substep's end) */
        for (dk_index i = 0; i < st->n; i++) {
            if (st->kinematic[i])
                continue;
            for (int c = 0; c < 3; c++) {
                const size_t j = 3 * (size_t)i + (size_t)c;
                xs[j] = x[j] + h * vn[j];
            }
        }
        place(ctx, xs, vs, 1.0);
        goals_at(ctx, xs, g);
    }
    for (dk_index i = 0; i < st->n; i++) {
        if (st->kinematic[i])
            continue;
        for (int c = 0; c < 3; c++) {
            const size_t j = 3 * (size_t)i + (size_t)c;
            v[j] = vn[j];
            x[j] += h * vn[j];
        }
    }
}

/* x_s = x0 + f dx, v_s = v0 + f dv for the free vertices (the stage's state). */
static void stage(const sm_step *st, const double *x0, const double *v0, const double *dx,
                  const double *dv, double f, double *xs, double *vs)
{
    for (dk_index i = 0; i < st->n; i++) {
        if (st->kinematic[i])
            continue;
        for (int c = 0; c < 3; c++) {
            const size_t j = 3 * (size_t)i + (size_t)c;
            xs[j] = x0[j] + f * dx[j];
            vs[j] = v0[j] + f * dv[j];
        }
    }
}

static void rk4(const sm_step *st, double *x, double *v, double *g, sm_goals_fn goals_at,
                sm_place_fn place, void *ctx, double *work)
{
    const size_t N = 3 * (size_t)st->n;
    double *xs = work, *vs = work + N, *sx = work + 2 * N, *sv = work + 3 * N;
    double *dx = work + 4 * N, *dv = work + 5 * N;
    const double h = st->h;
    static const double frac[4] = {0.0, 0.5, 0.5, 1.0}, weight[4] = {1.0, 2.0, 2.0, 1.0};
    memcpy(xs, x, N * sizeof *xs);
    memcpy(vs, v, N * sizeof *vs);
    memset(sx, 0, N * sizeof *sx);
    memset(sv, 0, N * sizeof *sv);
    for (int s = 0; s < 4; s++) {
        if (s > 0) {
            stage(st, x, v, dx, dv, frac[s] * h, xs, vs);
            place(ctx, xs, vs, frac[s]);
            goals_at(ctx, xs, g);
        }
        /* s == 0: the caller's goals of x, in g */
        for (dk_index i = 0; i < st->n; i++) {
            if (st->kinematic[i])
                continue;
            double a[3];
            accel(st, i, xs, vs, g, a);
            for (int c = 0; c < 3; c++) {
                const size_t j = 3 * (size_t)i + (size_t)c;
                dx[j] = vs[j];
                dv[j] = a[c];
                sx[j] += weight[s] * dx[j];
                sv[j] += weight[s] * dv[j];
            }
        }
    }
    for (dk_index i = 0; i < st->n; i++) {
        if (st->kinematic[i])
            continue;
        for (int c = 0; c < 3; c++) {
            const size_t j = 3 * (size_t)i + (size_t)c;
            x[j] += h / 6.0 * sx[j];
            v[j] += h / 6.0 * sv[j];
        }
    }
}

void sm_integrate(const sm_step *st, dk_shape_matching_integrator integrator, double *x,
                  double *v, double *goals, sm_goals_fn goals_at, sm_place_fn place, void *ctx,
                  double *work)
{
    goals_at(ctx, x, goals);
    switch (integrator) {
    case DK_INTEGRATOR_EXPLICIT_EULER:
        explicit_euler(st, x, v, goals);
        break;
    case DK_INTEGRATOR_IMPLICIT_EULER:
        implicit_euler(st, x, v, goals, goals_at, place, ctx, work);
        break;
    case DK_INTEGRATOR_RK4:
        rk4(st, x, v, goals, goals_at, place, ctx, work);
        break;
    case DK_INTEGRATOR_SEMI_IMPLICIT_EULER:
    default:
        semi_implicit(st, x, v, goals);
        break;
    }
    place(ctx, x, v, 1.0);
}
