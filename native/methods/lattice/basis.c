/* DeformKit lattice FFD: the 1D bases and the registration of a pose (lattice_internal.h). */
#include "lattice_internal.h"

/* A vertex's place along one axis of L = res - 1 cells: its index-space coordinate `a`
 * (0 at the first point, L at the last). Writes the first index and k weights, and returns
 * how far beyond the border the vertex lies, in cells (0 inside), for the fade of
 * OUTSIDE_STILL. */
static double axis_weights(const dk_lattice_options *opt, dk_index res, int k, double a,
                           dk_index *first, double *w)
{
    const double L = (double)(res - 1);
    const double beyond = a < 0.0 ? -a : a > L ? a - L : 0.0;
    if (opt->outside != DK_LATTICE_OUTSIDE_EXTEND) /* the border's map, not continued */
        a = a < 0.0 ? 0.0 : a > L ? L : a;
    switch (opt->interpolation) {
    case DK_LATTICE_BERNSTEIN: {
        /* B_i^L(s) = C(L, i) s^i (1 - s)^(L - i), s = a / L; C built up term by term */
        const int deg = (int)res - 1;
        const double s = a / L, r = 1.0 - s;
        double c = 1.0;
        for (int i = 0; i <= deg; i++) {
            if (i > 0)
                c = c * (double)(deg - i + 1) / (double)i;
            double v = c;
            for (int e = 0; e < i; e++)
                v *= s;
            for (int e = 0; e < deg - i; e++)
                v *= r;
            w[i] = v;
        }
        *first = 0;
        return beyond;
    }
    case DK_LATTICE_BSPLINE: {
        /* the interval i0 <= a < i0 + 1 (the border one, continued, outside); the uniform
         * cubic B-spline's weights of points i0 - 1 .. i0 + 2, the two beyond the ends
         * being the lattice extended linearly (P_-1 = 2 P_0 - P_1, P_res = 2 P_L - P_L-1)
         * and folded into the real points */
        dk_index i0 = (dk_index)floor(a);
        if (i0 < 0)
            i0 = 0;
        if (i0 > res - 2)
            i0 = res - 2;
        const double f = a - (double)i0, f2 = f * f, f3 = f2 * f;
        const double b[4] = {(1.0 - 3.0 * f + 3.0 * f2 - f3) / 6.0,
                             (4.0 - 6.0 * f2 + 3.0 * f3) / 6.0,
                             (1.0 + 3.0 * f + 3.0 * f2 - 3.0 * f3) / 6.0, f3 / 6.0};
        dk_index lo = i0 - 1 < 0 ? 0 : i0 - 1;
        if (lo > res - k)
            lo = res - k;
        for (int j = 0; j < k; j++)
            w[j] = 0.0;
        for (int j = 0; j < 4; j++) {
            const dk_index idx = i0 - 1 + j;
            if (idx < 0) { /* P_-1 = 2 P_0 - P_1 */
                w[0 - lo] += 2.0 * b[j];
                w[1 - lo] -= b[j];
            } else if (idx > res - 1) { /* P_res = 2 P_L - P_L-1 */
                w[res - 1 - lo] += 2.0 * b[j];
                w[res - 2 - lo] -= b[j];
            } else {
                w[idx - lo] += b[j];
            }
        }
        *first = lo;
        return beyond;
    }
    case DK_LATTICE_LINEAR:
    default: {
        dk_index i0 = (dk_index)floor(a);
        if (i0 < 0)
            i0 = 0;
        if (i0 > res - 2)
            i0 = res - 2;
        const double f = a - (double)i0;
        w[0] = 1.0 - f;
        w[1] = f;
        *first = i0;
        return beyond;
    }
    }
}

void lattice_register(const dk_lattice_options *opt, lattice_grid *g, const double *p,
                      dk_index n)
{
    const int kt = g->k[0] + g->k[1] + g->k[2];
    for (dk_index v = 0; v < n; v++) {
        const double *x = p + 3 * (size_t)v;
        double *w = g->w + (size_t)kt * (size_t)v;
        dk_index *first = g->first + 3 * (size_t)v;
        double beyond = 0.0;
        for (int d = 0, off = 0; d < 3; off += g->k[d], d++) {
            const double *r = g->inv + 4 * d;
            const double s = r[0] * x[0] + r[1] * x[1] + r[2] * x[2] + r[3];
            const double out = axis_weights(opt, g->res[d], g->k[d],
                                            s * (double)(g->res[d] - 1), first + d, w + off);
            beyond = out > beyond ? out : beyond;
        }
        if (opt->outside == DK_LATTICE_OUTSIDE_STILL && beyond > 0.0) {
            /* one cell beyond the border the motion has faded to none */
            const double fade = beyond >= 1.0 ? 0.0 : 1.0 - beyond;
            for (int j = 0; j < g->k[0]; j++)
                w[j] *= fade;
        }
    }
}

/* The 3 x 4 affine inverse of the 4 x 4 row-major `m` (its bottom row 0 0 0 1, checked by
 * dk_control_check) into `inv`. */
static void affine_inverse(const double *m, double *inv)
{
    const double a = m[0], b = m[1], c = m[2], d = m[4], e = m[5], f = m[6], g = m[8],
                 h = m[9], i = m[10];
    const double A = e * i - f * h, B = -(d * i - f * g), C = d * h - e * g;
    const double det = a * A + b * B + c * C;
    const double r[9] = {A / det,
                         -(b * i - c * h) / det,
                         (b * f - c * e) / det,
                         B / det,
                         (a * i - c * g) / det,
                         -(a * f - c * d) / det,
                         C / det,
                         -(a * h - b * g) / det,
                         (a * e - b * d) / det};
    for (int row = 0; row < 3; row++) {
        const double *q = r + 3 * row;
        inv[4 * row] = q[0];
        inv[4 * row + 1] = q[1];
        inv[4 * row + 2] = q[2];
        inv[4 * row + 3] = -(q[0] * m[3] + q[1] * m[7] + q[2] * m[11]);
    }
}

void lattice_grid_free(lattice_grid *g)
{
    free(g->rest);
    free(g->first);
    free(g->w);
    free(g->disp);
    memset(g, 0, sizeof *g);
}

dk_status lattice_grid_create(const dk_control_desc *control, const dk_lattice_options *opt,
                              dk_index n_vertices, lattice_grid *g, dk_error *err)
{
    memset(g, 0, sizeof *g);
    if (!control)
        return dk_error_set(err, DK_ERR_INVALID_ARGUMENT,
                            "Lattice: binds to a lattice (constraints->control), none given");
    dk_status st = dk_control_taken(control, DK_CONTROL_LATTICE, "Lattice", err);
    if (st == DK_OK)
        st = dk_control_check(control, n_vertices, err);
    if (st != DK_OK)
        return st;
    const int bern = opt->interpolation == DK_LATTICE_BERNSTEIN;
    const dk_index limit = bern ? LATTICE_MAX_BERNSTEIN : LATTICE_MAX_RESOLUTION;
    for (int d = 0; d < 3; d++)
        if (control->resolution[d] > limit)
            return dk_error_set(err, DK_ERR_INVALID_ARGUMENT,
                                "Lattice: %d points along %c, at most %d with %s interpolation",
                                (int)control->resolution[d], "xyz"[d], (int)limit,
                                bern ? "Bernstein (every point weighs on every vertex)"
                                     : "this");
    for (int d = 0; d < 3; d++) {
        g->res[d] = control->resolution[d];
        g->k[d] = bern ? (int)g->res[d]
                  : opt->interpolation == DK_LATTICE_BSPLINE ? (g->res[d] < 4 ? (int)g->res[d] : 4)
                                                             : 2;
    }
    g->n_points = control->n_controls;
    memcpy(g->frame, control->rest, sizeof g->frame);
    affine_inverse(g->frame, g->inv);
    const size_t np = (size_t)g->n_points, n = (size_t)n_vertices;
    const size_t kt = (size_t)(g->k[0] + g->k[1] + g->k[2]);
    g->rest = malloc(3 * np * sizeof *g->rest);
    g->disp = malloc(3 * np * sizeof *g->disp);
    g->first = malloc((3 * n + 1) * sizeof *g->first);
    g->w = malloc((kt * n + 1) * sizeof *g->w);
    if (!g->rest || !g->disp || !g->first || !g->w) {
        lattice_grid_free(g);
        return dk_error_set(err, DK_ERR_OUT_OF_MEMORY, "Lattice: out of memory (%zu weights)",
                            kt * n);
    }
    for (dk_index k = 0; k < g->res[2]; k++)
        for (dk_index j = 0; j < g->res[1]; j++)
            for (dk_index i = 0; i < g->res[0]; i++) {
                const double u[3] = {(double)i / (double)(g->res[0] - 1),
                                     (double)j / (double)(g->res[1] - 1),
                                     (double)k / (double)(g->res[2] - 1)};
                double *r = g->rest + 3 * ((size_t)i + (size_t)g->res[0] *
                                                           ((size_t)j + (size_t)g->res[1] * k));
                for (int d = 0; d < 3; d++)
                    r[d] = g->frame[4 * d] * u[0] + g->frame[4 * d + 1] * u[1] +
                           g->frame[4 * d + 2] * u[2] + g->frame[4 * d + 3];
            }
    return DK_OK;
}
