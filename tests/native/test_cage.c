/* Cage FFD with 3D mean value coordinates (dk_cage.h): the coordinates against their
 * definition integrated numerically (an independent evaluation), partition of unity and
 * linear precision inside and outside, positivity inside a convex cage, a cage vertex's
 * unit vector, a cage face's barycentric coordinates (and their limit just off the face),
 * a non-convex cage; the method: a vertex on a cage vertex follows it, an affine map of the
 * cage maps the mesh (double and single weights), an open cage refused. Green coordinates:
 * each face's psi and the phi against their definitions integrated numerically, x
 * reproduced from the vertices and normals inside and (continued) outside, a similarity of
 * the cage mapping the mesh while a shear does not, either orientation, an inconsistently
 * oriented cage refused. */
#include <math.h>
#include <stdlib.h>
#include <string.h>

#include "dk_cage.h"
#include "dk_test.h"

#define PI 3.14159265358979323846

/* The cube [-1, 1]^3: corners x fastest, 12 triangles facing out. */
static const double cube[24] = {-1, -1, -1, 1, -1, -1, -1, 1, -1, 1, 1, -1,
                                -1, -1, 1,  1, -1, 1,  -1, 1, 1,  1, 1, 1};
static const dk_index cube_tris[36] = {0, 2, 1, 1, 2, 3, 4, 5, 6, 5, 7, 6, 0, 1, 4, 1, 5, 4,
                                       2, 6, 3, 3, 6, 7, 0, 4, 2, 2, 4, 6, 1, 3, 5, 3, 7, 5};

/* dk_cage_mean_value with the cage's edge table built here (scratch: 4 nc + 3 edges). */
static int mean_value(const double *x, const double *cage, int nc, const dk_index *tris,
                      int nt, double *l)
{
    dk_index *edges = NULL, *opposite = NULL, ne = 0;
    dk_error e = {0};
    if (dk_cage_edges(tris, nt, &edges, &ne, &opposite, &e) != DK_OK)
        return -1;
    double *scratch = malloc((4 * (size_t)nc + 3 * (size_t)ne) * sizeof(double));
    const int r = scratch ? dk_cage_mean_value(x, cage, nc, tris, nt, edges, ne, opposite, l,
                                               scratch)
                          : -1;
    free(scratch);
    free(edges);
    free(opposite);
    return r;
}

static double rnd(unsigned *s)
{
    *s = *s * 1664525u + 1013904223u;
    return (double)(*s >> 8) / 16777216.0;
}

static double precision(const double *cage, int nc, const double *x, const double *l)
{
    double s = 0.0, p[3] = {0, 0, 0};
    for (int j = 0; j < nc; j++) {
        s += l[j];
        for (int d = 0; d < 3; d++)
            p[d] += l[j] * cage[3 * j + d];
    }
    return fmax(fabs(s - 1.0), fmax(fabs(p[0] - x[0]), fmax(fabs(p[1] - x[1]), fabs(p[2] - x[2]))));
}

/* The definition, integrated: w_j = integral over the directions xi of phi_j(hit) / |hit - x|,
 * phi_j the barycentric coordinate of the ray's hit on its triangle (a convex cage: one
 * hit), over a Fibonacci sphere of m directions. */
static void integrated(const double *cage, const dk_index *tris, int nt, int nc,
                       const double *x, int m, double *l)
{
    memset(l, 0, (size_t)nc * sizeof *l);
    const double golden = PI * (3.0 - sqrt(5.0));
    for (int k = 0; k < m; k++) {
        const double z = 1.0 - 2.0 * (k + 0.5) / m, r = sqrt(1.0 - z * z), a = golden * k;
        const double dir[3] = {r * cos(a), r * sin(a), z};
        for (int t = 0; t < nt; t++) { /* Moller-Trumbore */
            const double *p0 = cage + 3 * tris[3 * t], *p1 = cage + 3 * tris[3 * t + 1],
                         *p2 = cage + 3 * tris[3 * t + 2];
            double e1[3], e2[3], h[3], s[3], q[3];
            for (int d = 0; d < 3; d++)
                e1[d] = p1[d] - p0[d], e2[d] = p2[d] - p0[d], s[d] = x[d] - p0[d];
            h[0] = dir[1] * e2[2] - dir[2] * e2[1];
            h[1] = dir[2] * e2[0] - dir[0] * e2[2];
            h[2] = dir[0] * e2[1] - dir[1] * e2[0];
            const double det = e1[0] * h[0] + e1[1] * h[1] + e1[2] * h[2];
            if (fabs(det) < 1e-15)
                continue;
            const double u = (s[0] * h[0] + s[1] * h[1] + s[2] * h[2]) / det;
            q[0] = s[1] * e1[2] - s[2] * e1[1];
            q[1] = s[2] * e1[0] - s[0] * e1[2];
            q[2] = s[0] * e1[1] - s[1] * e1[0];
            const double v = (dir[0] * q[0] + dir[1] * q[1] + dir[2] * q[2]) / det;
            const double dist = (e2[0] * q[0] + e2[1] * q[1] + e2[2] * q[2]) / det;
            if (u < 0 || v < 0 || u + v > 1 || dist <= 0)
                continue;
            l[tris[3 * t]] += (1 - u - v) / dist;
            l[tris[3 * t + 1]] += u / dist;
            l[tris[3 * t + 2]] += v / dist;
            break;
        }
    }
    double sum = 0.0;
    for (int j = 0; j < nc; j++)
        sum += l[j];
    for (int j = 0; j < nc; j++)
        l[j] /= sum;
}

static void test_against_the_definition(void)
{
    double l[8], ref[8];
    unsigned st = 3;
    double worst = 0.0;
    for (int k = 0; k < 6; k++) {
        const double x[3] = {-0.8 + 1.6 * rnd(&st), -0.8 + 1.6 * rnd(&st), -0.8 + 1.6 * rnd(&st)};
        CHECK(mean_value(x, cube, 8, cube_tris, 12, l) == 0);
        integrated(cube, cube_tris, 12, 8, x, 200000, ref);
        for (int j = 0; j < 8; j++)
            worst = fmax(worst, fabs(l[j] - ref[j]));
    }
    CHECK_MSG(worst < 1e-3, "mean value coordinates %g from their integrated definition", worst);
}

static void test_properties(void)
{
    double l[8];
    unsigned st = 7;
    double worst_in = 0.0, worst_out = 0.0, least = 1.0;
    for (int k = 0; k < 300; k++) {
        const int out = k % 3 == 0;
        double x[3];
        for (int d = 0; d < 3; d++)
            x[d] = out ? -3.0 + 6.0 * rnd(&st) : -0.99 + 1.98 * rnd(&st);
        if (out && fabs(x[0]) < 1 && fabs(x[1]) < 1 && fabs(x[2]) < 1)
            x[0] = 2.5;
        CHECK(mean_value(x, cube, 8, cube_tris, 12, l) == 0);
        const double e = precision(cube, 8, x, l);
        if (out)
            worst_out = fmax(worst_out, e);
        else {
            worst_in = fmax(worst_in, e);
            for (int j = 0; j < 8; j++)
                least = fmin(least, l[j]);
        }
    }
    CHECK_MSG(worst_in < 1e-12 && worst_out < 1e-10, "linear precision %g inside, %g outside",
              worst_in, worst_out);
    CHECK_MSG(least > 0.0, "a negative weight %g inside a convex cage", least);
    /* a cage vertex: its unit vector; a face: barycentric; just off it: the same limit */
    CHECK(mean_value(cube + 9, cube, 8, cube_tris, 12, l) == 0 && l[3] == 1.0);
    const double on[3] = {-1.0 / 3, -1.0, -1.0 / 3}; /* triangle 0 1 4 (corners 0, 1, 4) */
    CHECK(mean_value(on, cube, 8, cube_tris, 12, l) == 0 &&
          precision(cube, 8, on, l) < 1e-12 && fabs(l[0] - 1.0 / 3) < 1e-12 &&
          fabs(l[1] - 1.0 / 3) < 1e-12 && fabs(l[4] - 1.0 / 3) < 1e-12);
    const double near[3] = {-1.0 / 3, -1.0 + 1e-9, -1.0 / 3};
    CHECK(mean_value(near, cube, 8, cube_tris, 12, l) == 0 &&
          precision(cube, 8, near, l) < 1e-9 && fabs(l[0] - 1.0 / 3) < 1e-6);
    /* a non-convex cage: the cube with its top face pushed in to a pyramid */
    double dent[27];
    memcpy(dent, cube, sizeof cube);
    dent[24] = 0, dent[25] = 0, dent[26] = 0.2; /* vertex 8: the dent's tip, below the top */
    static const dk_index dent_tris[42] = {0, 2, 1, 1, 2, 3, 0, 1, 4, 1, 5, 4, 2, 6, 3, 3, 6, 7,
                                           0, 4, 2, 2, 4, 6, 1, 3, 5, 3, 7, 5, 4, 5, 8, 5, 7, 8,
                                           7, 6, 8, 6, 4, 8};
    double ld[9];
    double worst = 0.0;
    for (int k = 0; k < 200; k++) {
        const double x[3] = {-0.9 + 1.8 * rnd(&st), -0.9 + 1.8 * rnd(&st), -0.9 + 1.05 * rnd(&st)};
        CHECK(mean_value(x, dent, 9, dent_tris, 14, ld) == 0);
        worst = fmax(worst, precision(dent, 9, x, ld));
    }
    CHECK_MSG(worst < 1e-11, "a non-convex cage: linear precision %g", worst);
}

static void test_the_method(void)
{
    /* the mesh: points inside and outside, two on cage vertices */
    enum { N = 60 };
    double p[3 * N];
    unsigned st = 11;
    for (int v = 0; v < N; v++)
        for (int d = 0; d < 3; d++)
            p[3 * v + d] = v < 40 ? -0.9 + 1.8 * rnd(&st) : -2.0 + 4.0 * rnd(&st);
    memcpy(p, cube + 9, 3 * sizeof(double));
    memcpy(p + 3, cube + 18, 3 * sizeof(double));
    dk_mesh *mesh = NULL;
    dk_error e = {0};
    CHECK(dk_mesh_create(p, N, NULL, 0, &mesh, &e) == DK_OK);
    if (!mesh)
        return;
    dk_control_desc c = {.kind = DK_CONTROL_CAGE, .n_controls = 8, .rest = cube,
                         .n_triangles = 12, .triangles = cube_tris};
    dk_constraint_desc d = {.control = &c};
    double P[24], x[3 * N];
    const double A[12] = {1.1, 0.2, -0.3, 0.5, -0.1, 0.9, 0.25, -2.0, 0.3, 0.1, 1.2, 0.7};
    for (int weights = 0; weights < 2; weights++) {
        dk_cage_options o;
        dk_cage_default_options(&o);
        o.weights = (dk_cage_weights)weights;
        dk_cage *cg = NULL;
        CHECK(dk_cage_bind(mesh, &d, &o, &cg, &e) == DK_OK);
        if (!cg)
            continue;
        for (int k = 0; k < 8; k++)
            for (int dd = 0; dd < 3; dd++)
                P[3 * k + dd] = A[4 * dd] * cube[3 * k] + A[4 * dd + 1] * cube[3 * k + 1] +
                                A[4 * dd + 2] * cube[3 * k + 2] + A[4 * dd + 3];
        dk_solve_request rq = {.targets = P};
        double worst = INFINITY;
        if (dk_cage_solve(cg, &rq, x, NULL, &e) == DK_OK) {
            worst = 0.0;
            for (int v = 0; v < N; v++)
                for (int dd = 0; dd < 3; dd++)
                    worst = fmax(worst, fabs(x[3 * v + dd] -
                                             (A[4 * dd] * p[3 * v] + A[4 * dd + 1] * p[3 * v + 1] +
                                              A[4 * dd + 2] * p[3 * v + 2] + A[4 * dd + 3])));
        }
        CHECK_MSG(worst < (weights ? 1e-5 : 1e-11), "weights %d: an affine map off by %g",
                  weights, worst);
        for (int k = 0; k < 24; k++) /* any motion: a vertex on a cage vertex follows it */
            P[k] = cube[k] + 0.3 * (rnd(&st) - 0.5);
        if (dk_cage_solve(cg, &rq, x, NULL, &e) == DK_OK)
            CHECK(fabs(x[0] - P[9]) < 1e-6 && fabs(x[4] - P[19]) < 1e-6);
        dk_method_stats ms;
        dk_cage_stats(cg, &ms);
        CHECK(ms.n_controls == 8 && ms.n_vertices == N);
        dk_cage_free(cg);
    }
    /* an open cage: refused by name */
    dk_control_desc open = c;
    open.n_triangles = 11;
    dk_constraint_desc od = {.control = &open};
    dk_cage *none = NULL;
    CHECK(dk_cage_bind(mesh, &od, NULL, &none, &e) == DK_ERR_INVALID_ARGUMENT && !none &&
          strstr(e.message, "not closed"));
    dk_mesh_free(mesh);
}

/* dk_cage_green with the cage's edges and outward normals built here; phi (nc), psi (nt). */
static int green(const double *x, const double *cage, int nc, const dk_index *tris, int nt,
                 double *phi, double *psi)
{
    dk_index *edges = NULL, *opposite = NULL, ne = 0;
    dk_error e = {0};
    if (dk_cage_edges(tris, nt, &edges, &ne, &opposite, &e) != DK_OK)
        return -1;
    double *scratch = malloc((4 * (size_t)nc + (size_t)ne + 3 * (size_t)nt) * sizeof(double));
    double *nrm = scratch ? scratch + 4 * (size_t)nc + (size_t)ne : NULL;
    int r = -1;
    if (scratch) {
        for (int t = 0; t < nt; t++) {
            const double *a = cage + 3 * tris[3 * t], *b = cage + 3 * tris[3 * t + 1],
                         *c = cage + 3 * tris[3 * t + 2];
            double *n = nrm + 3 * t;
            n[0] = (b[1] - a[1]) * (c[2] - a[2]) - (b[2] - a[2]) * (c[1] - a[1]);
            n[1] = (b[2] - a[2]) * (c[0] - a[0]) - (b[0] - a[0]) * (c[2] - a[2]);
            n[2] = (b[0] - a[0]) * (c[1] - a[1]) - (b[1] - a[1]) * (c[0] - a[0]);
            const double len = sqrt(n[0] * n[0] + n[1] * n[1] + n[2] * n[2]);
            for (int k = 0; k < 3; k++)
                n[k] /= len;
        }
        r = dk_cage_green(x, cage, nc, tris, nt, nrm, edges, ne, opposite, phi, psi, scratch);
    }
    free(scratch);
    free(edges);
    free(opposite);
    return r;
}

/* int_t f(xi) over the triangle t by the midpoint rule on m^2 sub-triangles' centroids:
 * psi = 1/(4 pi) int 1/r, and the corners' phi = 1/(4 pi) int Gamma_l h / r^3. */
static void green_integrated(const double *cage, const dk_index *f, const double *x, int m,
                             double *psi, double phi[3])
{
    const double *a = cage + 3 * f[0], *b = cage + 3 * f[1], *c = cage + 3 * f[2];
    double u[3], v[3], n[3];
    for (int k = 0; k < 3; k++)
        u[k] = b[k] - a[k], v[k] = c[k] - a[k];
    n[0] = u[1] * v[2] - u[2] * v[1];
    n[1] = u[2] * v[0] - u[0] * v[2];
    n[2] = u[0] * v[1] - u[1] * v[0];
    const double area = 0.5 * sqrt(n[0] * n[0] + n[1] * n[1] + n[2] * n[2]);
    for (int k = 0; k < 3; k++)
        n[k] /= 2.0 * area;
    const double h = n[0] * (a[0] - x[0]) + n[1] * (a[1] - x[1]) + n[2] * (a[2] - x[2]);
    *psi = 0.0;
    phi[0] = phi[1] = phi[2] = 0.0;
    const double w = area / ((double)m * m) / (4.0 * PI);
    for (int i = 0; i < m; i++)
        for (int j = 0; j < m - i; j++)
            for (int up = 0; up < (j < m - i - 1 ? 2 : 1); up++) {
                /* the sub-triangle's centroid in barycentric (s, t) of (u, v) */
                const double s = up ? (i + 2.0 / 3.0) / m : (i + 1.0 / 3.0) / m;
                const double t = up ? (j + 2.0 / 3.0) / m : (j + 1.0 / 3.0) / m;
                double q[3];
                for (int k = 0; k < 3; k++)
                    q[k] = a[k] + s * u[k] + t * v[k] - x[k];
                const double r = sqrt(q[0] * q[0] + q[1] * q[1] + q[2] * q[2]);
                *psi += w / r;
                const double g[3] = {1.0 - s - t, s, t};
                for (int l = 0; l < 3; l++)
                    phi[l] += w * g[l] * h / (r * r * r);
            }
}

static void test_green_against_the_definition(void)
{
    /* one face of the cube seen from inside points: its psi and its corners' parts of phi
     * (the face alone: a cage of that one triangle, its edges' integrals included) */
    unsigned st = 5;
    double worst = 0.0;
    for (int k = 0; k < 4; k++) {
        const double x[3] = {-0.7 + 1.4 * rnd(&st), -0.7 + 1.4 * rnd(&st), -0.7 + 1.4 * rnd(&st)};
        double phi[8], psi[12];
        CHECK(green(x, cube, 8, cube_tris, 12, phi, psi) == 0);
        for (int t = 0; t < 12; t++) {
            double ipsi, iphi[3];
            green_integrated(cube, cube_tris + 3 * t, x, 400, &ipsi, iphi);
            worst = fmax(worst, fabs(psi[t] - ipsi));
        }
        /* phi: the sum over the faces of the integrated corners' parts */
        double sum[8] = {0};
        for (int t = 0; t < 12; t++) {
            double ipsi, iphi[3];
            green_integrated(cube, cube_tris + 3 * t, x, 400, &ipsi, iphi);
            for (int l = 0; l < 3; l++)
                sum[cube_tris[3 * t + l]] += iphi[l];
        }
        for (int j = 0; j < 8; j++)
            worst = fmax(worst, fabs(phi[j] - sum[j]));
    }
    CHECK_MSG(worst < 2e-4, "Green coordinates %g from their integrated definition", worst);
}

static void test_green_properties(void)
{
    /* x = sum phi_i v_i + sum psi_t n_t and sum phi = 1, inside and (continued) outside, for
     * the cube and a non-convex cage */
    unsigned st = 9;
    double worst_in = 0.0, worst_out = 0.0;
    for (int k = 0; k < 200; k++) {
        const int out = k % 4 == 0;
        double x[3];
        for (int d = 0; d < 3; d++)
            x[d] = out ? -2.5 + 5.0 * rnd(&st) : -0.98 + 1.96 * rnd(&st);
        if (out && fabs(x[0]) < 1.05 && fabs(x[1]) < 1.05 && fabs(x[2]) < 1.05)
            x[2] = 1.8;
        double phi[8], psi[12];
        CHECK(green(x, cube, 8, cube_tris, 12, phi, psi) == 0);
        double p[3] = {0, 0, 0}, s = 0.0;
        for (int j = 0; j < 8; j++) {
            s += phi[j];
            for (int d = 0; d < 3; d++)
                p[d] += phi[j] * cube[3 * j + d];
        }
        for (int t = 0; t < 12; t++) { /* the cube's outward normals */
            const double *a = cube + 3 * cube_tris[3 * t], *b = cube + 3 * cube_tris[3 * t + 1],
                         *c = cube + 3 * cube_tris[3 * t + 2];
            for (int d = 0; d < 3; d++) {
                const double nd = (a[d] + b[d] + c[d]) / 3.0;
                /* a face of the cube: its centroid's coordinate of magnitude 1 is the normal */
                p[d] += psi[t] * (fabs(nd) > 0.999 ? (nd > 0 ? 1.0 : -1.0) : 0.0);
            }
        }
        const double e = fmax(fabs(s - 1.0), fmax(fabs(p[0] - x[0]),
                                                  fmax(fabs(p[1] - x[1]), fabs(p[2] - x[2]))));
        if (out)
            worst_out = fmax(worst_out, e);
        else
            worst_in = fmax(worst_in, e);
    }
    CHECK_MSG(worst_in < 1e-12 && worst_out < 1e-12,
              "Green coordinates reproduce x to %g inside, %g outside", worst_in, worst_out);
}

static void test_green_method(void)
{
    enum { N = 50 };
    double p[3 * N];
    unsigned st = 13;
    for (int v = 0; v < N; v++)
        for (int d = 0; d < 3; d++)
            p[3 * v + d] = v < 40 ? -0.9 + 1.8 * rnd(&st) : -2.0 + 4.0 * rnd(&st);
    dk_mesh *mesh = NULL;
    dk_error e = {0};
    CHECK(dk_mesh_create(p, N, NULL, 0, &mesh, &e) == DK_OK);
    if (!mesh)
        return;
    /* the cube's triangles turned inwards: Green orients them itself */
    dk_index inward[36];
    for (int t = 0; t < 12; t++) {
        inward[3 * t] = cube_tris[3 * t];
        inward[3 * t + 1] = cube_tris[3 * t + 2];
        inward[3 * t + 2] = cube_tris[3 * t + 1];
    }
    const dk_index *orders[2] = {cube_tris, inward};
    /* a similarity: scale 1.6, a turn about (1, 2, 2)/3 by 0.8, a move */
    const double th = 0.8, ax[3] = {1.0 / 3, 2.0 / 3, 2.0 / 3}, sc = 1.6, mv[3] = {0.3, -1, 2};
    double Q[9];
    for (int i = 0; i < 3; i++)
        for (int j = 0; j < 3; j++) {
            const double cross = i == j ? 0.0 : (((j - i + 3) % 3 == 1) ? -1.0 : 1.0) *
                                                    ax[3 - i - j];
            Q[3 * i + j] = (i == j ? cos(th) : 0.0) + (1 - cos(th)) * ax[i] * ax[j] +
                           sin(th) * cross;
        }
    double worst_sim = 0.0, worst_affine = 0.0;
    for (int w = 0; w < 2; w++)
        for (int o = 0; o < 2; o++) {
            dk_control_desc c = {.kind = DK_CONTROL_CAGE, .n_controls = 8, .rest = cube,
                                 .n_triangles = 12, .triangles = orders[o]};
            dk_constraint_desc d = {.control = &c};
            dk_cage_options opt;
            dk_cage_default_options(&opt);
            opt.coordinates = DK_CAGE_GREEN;
            opt.weights = (dk_cage_weights)w;
            dk_cage *cg = NULL;
            CHECK(dk_cage_bind(mesh, &d, &opt, &cg, &e) == DK_OK);
            if (!cg)
                continue;
            double P[24], x[3 * N];
            dk_solve_request rq = {.targets = P};
            memcpy(P, cube, sizeof P);
            if (dk_cage_solve(cg, &rq, x, NULL, &e) == DK_OK)
                for (int k = 0; k < 3 * N; k++)
                    CHECK(x[k] == p[k]); /* at rest: bit for bit */
            for (int k = 0; k < 8; k++)
                for (int i = 0; i < 3; i++)
                    P[3 * k + i] = sc * (Q[3 * i] * cube[3 * k] + Q[3 * i + 1] * cube[3 * k + 1] +
                                         Q[3 * i + 2] * cube[3 * k + 2]) + mv[i];
            if (dk_cage_solve(cg, &rq, x, NULL, &e) == DK_OK)
                for (int v = 0; v < N; v++)
                    for (int i = 0; i < 3; i++) {
                        const double want = sc * (Q[3 * i] * p[3 * v] + Q[3 * i + 1] * p[3 * v + 1] +
                                                  Q[3 * i + 2] * p[3 * v + 2]) + mv[i];
                        const double err = fabs(x[3 * v + i] - want);
                        if (w == 0)
                            worst_sim = fmax(worst_sim, err);
                        else
                            CHECK_MSG(err < 1e-5, "single weights: a similarity off by %g", err);
                    }
            /* a shear is not reproduced: the shape is kept instead */
            for (int k = 0; k < 8; k++) {
                memcpy(P + 3 * k, cube + 3 * k, 3 * sizeof(double));
                P[3 * k] += 0.8 * cube[3 * k + 1];
            }
            if (w == 0 && dk_cage_solve(cg, &rq, x, NULL, &e) == DK_OK)
                for (int v = 0; v < 40; v++)
                    worst_affine = fmax(worst_affine,
                                        fabs(x[3 * v] - (p[3 * v] + 0.8 * p[3 * v + 1])));
            dk_cage_free(cg);
        }
    CHECK_MSG(worst_sim < 1e-11, "Green: a similarity of the cage off by %g", worst_sim);
    CHECK_MSG(worst_affine > 1e-3, "Green reproduced a shear (%g): not Green coordinates",
              worst_affine);
    /* inconsistently oriented triangles: refused by name */
    dk_index mixed[36];
    memcpy(mixed, cube_tris, sizeof mixed);
    mixed[1] = cube_tris[2];
    mixed[2] = cube_tris[1];
    dk_control_desc c = {.kind = DK_CONTROL_CAGE, .n_controls = 8, .rest = cube,
                         .n_triangles = 12, .triangles = mixed};
    dk_constraint_desc d = {.control = &c};
    dk_cage_options opt;
    dk_cage_default_options(&opt);
    opt.coordinates = DK_CAGE_GREEN;
    dk_cage *none = NULL;
    CHECK(dk_cage_bind(mesh, &d, &opt, &none, &e) == DK_ERR_INVALID_ARGUMENT && !none &&
          strstr(e.message, "oriented consistently"));
    opt.coordinates = (dk_cage_coordinates)7;
    c.triangles = cube_tris;
    CHECK(dk_cage_bind(mesh, &d, &opt, &none, &e) == DK_ERR_INVALID_ARGUMENT && !none);
    dk_mesh_free(mesh);
}

static void test_grid_evaluation(void)
{
    /* coordinates on a grid, blended: affine maps (mean value) and similarities (Green) still
     * exact, inside and outside the cage; close to the exact coordinates' result; AUTO is
     * EXACT at this size, bit for bit */
    enum { N = 400 };
    double p[3 * N];
    unsigned st = 17;
    for (int v = 0; v < N; v++)
        for (int d = 0; d < 3; d++)
            p[3 * v + d] = v < 360 ? -0.95 + 1.9 * rnd(&st) : -1.6 + 3.2 * rnd(&st);
    dk_mesh *mesh = NULL;
    dk_error e = {0};
    CHECK(dk_mesh_create(p, N, NULL, 0, &mesh, &e) == DK_OK);
    if (!mesh)
        return;
    dk_control_desc c = {.kind = DK_CONTROL_CAGE, .n_controls = 8, .rest = cube,
                         .n_triangles = 12, .triangles = cube_tris};
    dk_constraint_desc d = {.control = &c};
    const double A[12] = {1.1, 0.2, -0.3, 0.5, -0.1, 0.9, 0.25, -2.0, 0.3, 0.1, 1.2, 0.7};
    double P[24], Pm[24], x[3 * N], xe[3 * N], xa[3 * N];
    for (int k = 0; k < 8; k++)
        for (int dd = 0; dd < 3; dd++) {
            P[3 * k + dd] = A[4 * dd] * cube[3 * k] + A[4 * dd + 1] * cube[3 * k + 1] +
                            A[4 * dd + 2] * cube[3 * k + 2] + A[4 * dd + 3];
            Pm[3 * k + dd] = cube[3 * k + dd] + (k == 7 ? 0.4 : 0.0); /* one corner pulled */
        }
    for (int green = 0; green < 2; green++) {
        dk_cage_options o;
        dk_cage_default_options(&o);
        o.coordinates = green ? DK_CAGE_GREEN : DK_CAGE_MEAN_VALUE;
        dk_cage *grid = NULL, *exact = NULL, *aut = NULL;
        o.evaluation = DK_CAGE_GRID;
        o.grid_resolution = 16;
        CHECK(dk_cage_bind(mesh, &d, &o, &grid, &e) == DK_OK);
        o.evaluation = DK_CAGE_EXACT;
        CHECK(dk_cage_bind(mesh, &d, &o, &exact, &e) == DK_OK);
        o.evaluation = DK_CAGE_AUTO;
        CHECK(dk_cage_bind(mesh, &d, &o, &aut, &e) == DK_OK);
        if (!grid || !exact || !aut) {
            dk_cage_free(grid);
            dk_cage_free(exact);
            dk_cage_free(aut);
            continue;
        }
        dk_solve_request rq = {.targets = P};
        if (!green && dk_cage_solve(grid, &rq, x, NULL, &e) == DK_OK) {
            double worst = 0.0;
            for (int v = 0; v < N; v++)
                for (int dd = 0; dd < 3; dd++)
                    worst = fmax(worst, fabs(x[3 * v + dd] -
                                             (A[4 * dd] * p[3 * v] + A[4 * dd + 1] * p[3 * v + 1] +
                                              A[4 * dd + 2] * p[3 * v + 2] + A[4 * dd + 3])));
            CHECK_MSG(worst < 1e-12, "grid: an affine map off by %g", worst);
        }
        if (green) { /* a similarity: scale 2 and a move */
            for (int k = 0; k < 24; k++)
                P[k] = 2.0 * cube[k] + (k % 3 == 1 ? 0.7 : 0.0);
            if (dk_cage_solve(grid, &rq, x, NULL, &e) == DK_OK) {
                double worst = 0.0;
                for (int k = 0; k < 3 * N; k++)
                    worst = fmax(worst, fabs(x[k] - (2.0 * p[k] + (k % 3 == 1 ? 0.7 : 0.0))));
                CHECK_MSG(worst < 1e-12, "grid, Green: a similarity off by %g", worst);
            }
        }
        rq.targets = Pm;
        double worst = INFINITY, moved = 0.0;
        if (dk_cage_solve(grid, &rq, x, NULL, &e) == DK_OK &&
            dk_cage_solve(exact, &rq, xe, NULL, &e) == DK_OK &&
            dk_cage_solve(aut, &rq, xa, NULL, &e) == DK_OK) {
            worst = 0.0;
            for (int k = 0; k < 3 * N; k++) {
                worst = fmax(worst, fabs(x[k] - xe[k]));
                moved = fmax(moved, fabs(xe[k] - p[k]));
                CHECK(xa[k] == xe[k]);
            }
        }
        CHECK_MSG(worst < 0.02 * moved, "%s: the grid's result %g from the exact one (moved %g)",
                  green ? "Green" : "mean value", worst, moved);
        dk_cage_free(grid);
        dk_cage_free(exact);
        dk_cage_free(aut);
    }
    dk_cage_options o;
    dk_cage_default_options(&o);
    o.evaluation = DK_CAGE_GRID;
    o.grid_resolution = 3;
    dk_cage *none = NULL;
    CHECK(dk_cage_bind(mesh, &d, &o, &none, &e) == DK_ERR_INVALID_ARGUMENT && !none &&
          strstr(e.message, "grid_resolution"));
    dk_mesh_free(mesh);
}

DK_TEST_MAIN(test_against_the_definition, test_properties, test_the_method,
             test_green_against_the_definition, test_green_properties, test_green_method,
             test_grid_evaluation)
