/* Tests of dk_eigs_smallest: sphere harmonics, dense LAPACK reference, identical disconnected
 * copies (full multiplicities), band-by-band mode
 * against single-band and dense results (no missing or duplicated eigenvalues), argument
 * checks, progress and cancellation. The meshes and operators are built here (icosphere,
 * cotangent Laplacian, barycentric mass) so the test depends only on the numerics layer. */
#define _POSIX_C_SOURCE 199309L /* clock_gettime */
#include <lapacke.h>
#include <math.h>
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <time.h>

#include "dk_eigs.h"
#include "dk_test.h"

#if defined(__SANITIZE_ADDRESS__)
#define SANITIZED 1
#elif defined(__has_feature)
#if __has_feature(address_sanitizer)
#define SANITIZED 1
#endif
#endif
#ifndef SANITIZED
#define SANITIZED 0
#endif

static double now(void)
{
    struct timespec t;
    clock_gettime(CLOCK_MONOTONIC, &t);
    return (double)t.tv_sec + 1e-9 * (double)t.tv_nsec;
}

/* ------------------------------------------------------------------ test meshes -------- */

typedef struct tmesh {
    int nv, nf;
    double *pos; /* nv x 3 */
    int *tri;    /* nf x 3 */
} tmesh;

static void tmesh_free(tmesh *m)
{
    free(m->pos);
    free(m->tri);
    m->pos = NULL;
    m->tri = NULL;
}

/* Midpoint of edge (a, b), created once: edges are looked up in a per-vertex list. */
typedef struct edge_map {
    int *head, *next, *other, *mid;
    int count;
} edge_map;

static int midpoint(edge_map *em, tmesh *m, int a, int b)
{
    const int lo = a < b ? a : b, hi = a < b ? b : a;
    for (int e = em->head[lo]; e >= 0; e = em->next[e])
        if (em->other[e] == hi) return em->mid[e];
    const int v = m->nv++;
    for (int d = 0; d < 3; d++) m->pos[3 * v + d] = 0.5 * (m->pos[3 * a + d] + m->pos[3 * b + d]);
    const int e = em->count++;
    em->other[e] = hi;
    em->mid[e] = v;
    em->next[e] = em->head[lo];
    em->head[lo] = e;
    return v;
}

/* Icosphere of radius r after `level` 1:4 subdivisions, vertices projected on the sphere,
 * then displaced radially by bump * (a smooth non-symmetric function) when bump != 0. */
static int icosphere(int level, double r, double bump, tmesh *out)
{
    int nv_final = 12, nf_final = 20;
    for (int l = 0; l < level; l++) {
        nv_final += nf_final * 3 / 2;
        nf_final *= 4;
    }
    tmesh m = {0};
    m.pos = malloc(sizeof(double) * 3 * (size_t)nv_final);
    m.tri = malloc(sizeof(int) * 3 * (size_t)nf_final);
    int *tri2 = malloc(sizeof(int) * 3 * (size_t)nf_final);
    edge_map em = {0};
    em.head = malloc(sizeof(int) * (size_t)nv_final);
    em.next = malloc(sizeof(int) * (size_t)nf_final * 3);
    em.other = malloc(sizeof(int) * (size_t)nf_final * 3);
    em.mid = malloc(sizeof(int) * (size_t)nf_final * 3);
    if (!m.pos || !m.tri || !tri2 || !em.head || !em.next || !em.other || !em.mid) {
        free(m.pos); free(m.tri); free(tri2); free(em.head); free(em.next); free(em.other);
        free(em.mid);
        return 0;
    }
    const double t = (1.0 + sqrt(5.0)) / 2.0;
    const double v0[12][3] = {{-1, t, 0}, {1, t, 0},  {-1, -t, 0}, {1, -t, 0},
                              {0, -1, t}, {0, 1, t},  {0, -1, -t}, {0, 1, -t},
                              {t, 0, -1}, {t, 0, 1},  {-t, 0, -1}, {-t, 0, 1}};
    const int f0[20][3] = {{0, 11, 5}, {0, 5, 1},  {0, 1, 7},   {0, 7, 10}, {0, 10, 11},
                           {1, 5, 9},  {5, 11, 4}, {11, 10, 2}, {10, 7, 6}, {7, 1, 8},
                           {3, 9, 4},  {3, 4, 2},  {3, 2, 6},   {3, 6, 8},  {3, 8, 9},
                           {4, 9, 5},  {2, 4, 11}, {6, 2, 10},  {8, 6, 7},  {9, 8, 1}};
    m.nv = 12;
    m.nf = 20;
    memcpy(m.pos, v0, sizeof v0);
    memcpy(m.tri, f0, sizeof f0);
    for (int l = 0; l < level; l++) {
        for (int i = 0; i < nv_final; i++) em.head[i] = -1;
        em.count = 0;
        int nf2 = 0;
        for (int f = 0; f < m.nf; f++) {
            const int a = m.tri[3 * f], b = m.tri[3 * f + 1], c = m.tri[3 * f + 2];
            const int ab = midpoint(&em, &m, a, b), bc = midpoint(&em, &m, b, c),
                      ca = midpoint(&em, &m, c, a);
            const int nt[4][3] = {{a, ab, ca}, {b, bc, ab}, {c, ca, bc}, {ab, bc, ca}};
            memcpy(tri2 + 3 * nf2, nt, sizeof nt);
            nf2 += 4;
        }
        memcpy(m.tri, tri2, sizeof(int) * 3 * (size_t)nf2);
        m.nf = nf2;
    }
    for (int v = 0; v < m.nv; v++) {
        double *p = m.pos + 3 * v;
        const double len = sqrt(p[0] * p[0] + p[1] * p[1] + p[2] * p[2]);
        const double u[3] = {p[0] / len, p[1] / len, p[2] / len};
        const double f = sin(3.0 * u[0] + 1.0) * cos(2.0 * u[1]) + u[2] * u[2] * u[0];
        const double rr = r * (1.0 + bump * f);
        for (int d = 0; d < 3; d++) p[d] = rr * u[d];
    }
    free(tri2); free(em.head); free(em.next); free(em.other); free(em.mid);
    *out = m;
    return 1;
}

/* ------------------------------------------------------------------ operators ---------- */

typedef struct trip {
    int64_t key; /* col * n + row */
    double v;
} trip;

static int cmp_trip(const void *a, const void *b)
{
    const int64_t x = ((const trip *)a)->key, y = ((const trip *)b)->key;
    return (x > y) - (x < y);
}

static void csc_free(dk_sparse *a)
{
    if (!a) return;
    free(a->col_start); free(a->row_index); free(a->values); free(a);
}

/* Cotangent Laplacian (PSD sign convention, both triangles) and barycentric mass. */
static dk_sparse *cotan_laplacian(const tmesh *m, double *mass)
{
    const int n = m->nv;
    const size_t nt = (size_t)m->nf * 12;
    trip *t = malloc(nt * sizeof *t);
    dk_sparse *a = calloc(1, sizeof *a);
    if (!t || !a) { free(t); free(a); return NULL; }
    size_t q = 0;
    for (int i = 0; i < n; i++) mass[i] = 0.0;
    for (int f = 0; f < m->nf; f++) {
        const int *v = m->tri + 3 * f;
        double e[3][3]; /* e[c] = edge opposite corner c, from v[c+1] to v[c+2] */
        for (int c = 0; c < 3; c++)
            for (int d = 0; d < 3; d++)
                e[c][d] = m->pos[3 * v[(c + 2) % 3] + d] - m->pos[3 * v[(c + 1) % 3] + d];
        const double cr[3] = {e[0][1] * e[1][2] - e[0][2] * e[1][1],
                              e[0][2] * e[1][0] - e[0][0] * e[1][2],
                              e[0][0] * e[1][1] - e[0][1] * e[1][0]};
        const double a2 = sqrt(cr[0] * cr[0] + cr[1] * cr[1] + cr[2] * cr[2]);
        for (int c = 0; c < 3; c++) mass[v[c]] += a2 / 6.0;
        for (int c = 0; c < 3; c++) {
            const double *p = e[(c + 1) % 3], *r = e[(c + 2) % 3];
            const double dot = -(p[0] * r[0] + p[1] * r[1] + p[2] * r[2]);
            const double w = 0.5 * dot / a2; /* half the cotangent at corner c */
            const int i = v[(c + 1) % 3], j = v[(c + 2) % 3];
            t[q++] = (trip){(int64_t)j * n + i, -w};
            t[q++] = (trip){(int64_t)i * n + j, -w};
            t[q++] = (trip){(int64_t)i * n + i, w};
            t[q++] = (trip){(int64_t)j * n + j, w};
        }
    }
    qsort(t, q, sizeof *t, cmp_trip);
    a->n_rows = a->n_cols = n;
    a->col_start = calloc((size_t)n + 1, sizeof(dk_index));
    a->row_index = malloc(q * sizeof(dk_index));
    a->values = malloc(q * sizeof(double));
    if (!a->col_start || !a->row_index || !a->values) { free(t); csc_free(a); return NULL; }
    size_t nz = 0;
    for (size_t r = 0; r < q; r++) {
        if (r > 0 && t[r].key == t[r - 1].key) {
            a->values[nz - 1] += t[r].v;
            continue;
        }
        a->row_index[nz] = (dk_index)(t[r].key % n);
        a->values[nz++] = t[r].v;
        a->col_start[t[r].key / n + 1]++;
    }
    for (int j = 0; j < n; j++) a->col_start[j + 1] += a->col_start[j];
    free(t);
    return a;
}

static void matvec(const dk_sparse *a, const double *x, double *y)
{
    memset(y, 0, sizeof(double) * (size_t)a->n_rows);
    for (dk_index j = 0; j < a->n_cols; j++)
        for (dk_index p = a->col_start[j]; p < a->col_start[j + 1]; p++)
            y[a->row_index[p]] += a->values[p] * x[j];
}

static double mdot(const double *m, const double *x, const double *y, int n)
{
    double s = 0;
    for (int i = 0; i < n; i++) s += m[i] * x[i] * y[i];
    return s;
}

/* ------------------------------------------------------------------ checks ------------- */

/* max |X^T M X - I| */
static double orthonormality_error(const double *mass, const double *x, int n, int k)
{
    double worst = 0;
    for (int a = 0; a < k; a++)
        for (int b = 0; b <= a; b++)
            worst = fmax(worst, fabs(mdot(mass, x + (size_t)a * n, x + (size_t)b * n, n) -
                                     (a == b)));
    return worst;
}

/* max over pairs of ||L x - lambda M x||_{M^-1} / max(lambda, scale) */
static double residual_error(const dk_sparse *l, const double *mass, const double *val,
                             const double *x, int n, int k, double scale)
{
    double *y = malloc(sizeof(double) * (size_t)n);
    if (!y) return INFINITY;
    double worst = 0;
    for (int j = 0; j < k; j++) {
        const double *v = x + (size_t)j * n;
        matvec(l, v, y);
        double s = 0;
        for (int i = 0; i < n; i++) {
            const double r = y[i] - val[j] * mass[i] * v[i];
            s += r * r / mass[i];
        }
        worst = fmax(worst, sqrt(s) / fmax(val[j], scale));
    }
    free(y);
    return worst;
}

/* Compares the first k computed pairs with a reference (both M-orthonormal): eigenvalues to
 * `vtol` relative, and for every group of eigenvalues closer than `gtol` relative the
 * subspaces: ||X_g - R_g (R_g^T M X_g)||_M (zero when the spans agree; signs and rotations
 * within a degenerate group do not matter). Returns the worst subspace distance. */
static double compare_pairs(const double *mass, int n, int k, const double *val,
                            const double *x, const double *rval, const double *rx, int rk,
                            double vtol, double gtol, double scale, int *val_fail)
{
    *val_fail = 0;
    for (int j = 0; j < k; j++)
        if (fabs(val[j] - rval[j]) > vtol * fmax(fabs(rval[j]), scale)) {
            if (*val_fail < 5)
                fprintf(stderr, "eigenvalue %d: %.15g vs reference %.15g\n", j, val[j], rval[j]);
            (*val_fail)++;
        }
    double worst = 0;
    double *r = malloc(sizeof(double) * (size_t)n);
    if (!r) return INFINITY;
    int g0 = 0;
    while (g0 < k) {
        int g1 = g0 + 1;
        while (g1 < rk && rval[g1] - rval[g1 - 1] <= gtol * fmax(fabs(rval[g1]), scale)) g1++;
        /* the group [g0, g1) of the reference; computed vectors of the group inside k */
        const int top = g1 < k ? g1 : k;
        if (g1 > k) { g0 = g1; continue; } /* group cut by k: the choice inside is arbitrary */
        for (int j = g0; j < top; j++) {
            memcpy(r, x + (size_t)j * n, sizeof(double) * (size_t)n);
            for (int a = g0; a < g1; a++) {
                const double *u = rx + (size_t)a * n;
                const double c = mdot(mass, u, r, n);
                for (int i = 0; i < n; i++) r[i] -= c * u[i];
            }
            worst = fmax(worst, sqrt(fabs(mdot(mass, r, r, n))));
        }
        g0 = g1;
    }
    free(r);
    return worst;
}

/* Dense generalized solve L x = lambda M x with LAPACK dsygvd (B = diag(M)). */
static int dense_reference(const dk_sparse *l, const double *mass, double **val, double **vec)
{
    const int n = l->n_rows;
    double *a = calloc((size_t)n * n, sizeof(double)), *b = calloc((size_t)n * n, sizeof(double));
    double *w = malloc(sizeof(double) * (size_t)n);
    if (!a || !b || !w) { free(a); free(b); free(w); return 0; }
    for (int j = 0; j < n; j++) {
        for (dk_index p = l->col_start[j]; p < l->col_start[j + 1]; p++)
            a[(size_t)j * n + l->row_index[p]] = l->values[p];
        b[(size_t)j * n + j] = mass[j];
    }
    const int info = LAPACKE_dsygvd(LAPACK_COL_MAJOR, 1, 'V', 'U', n, a, n, b, n, w);
    free(b);
    if (info != 0) { free(a); free(w); return 0; }
    *val = w;
    *vec = a;
    return 1;
}

/* ------------------------------------------------------------------ the tests ---------- */

typedef struct problem {
    tmesh mesh;
    dk_sparse *l;
    double *mass;
    int n;
} problem;

static int problem_make(int level, double r, double bump, problem *p)
{
    memset(p, 0, sizeof *p);
    if (!icosphere(level, r, bump, &p->mesh)) return 0;
    p->n = p->mesh.nv;
    p->mass = malloc(sizeof(double) * (size_t)p->n);
    if (!p->mass) { tmesh_free(&p->mesh); return 0; }
    p->l = cotan_laplacian(&p->mesh, p->mass);
    if (!p->l) { free(p->mass); tmesh_free(&p->mesh); return 0; }
    return 1;
}

static void problem_free(problem *p)
{
    csc_free(p->l);
    free(p->mass);
    tmesh_free(&p->mesh);
}

static void test_sphere_harmonics(void)
{
    /* Laplace-Beltrami on a sphere of radius R: eigenvalues l(l+1)/R^2 with multiplicity
     * 2l+1, so the first 16 come as 1, 3, 5, 7 near 0, 2, 6, 12 (/R^2). */
    const int level = SANITIZED ? 3 : 4;
    const double radius = 2.0;
    problem p;
    CHECK(problem_make(level, radius, 0.0, &p));
    if (!p.l) return;
    const int k = 16;
    double val[16];
    double *vec = malloc(sizeof(double) * (size_t)p.n * k);
    CHECK(vec != NULL);
    if (!vec) { problem_free(&p); return; }
    dk_eigs_options opt;
    dk_eigs_options_default(&opt);
    dk_error err = {0};
    int conv = -1;
    const double t0 = now();
    dk_status st = dk_eigs_smallest(p.l, p.mass, k, &opt, val, vec, &conv, &err);
    printf("sphere level %d (n=%d): 16 eigenpairs in %.3f s\n", level, p.n, now() - t0);
    CHECK_MSG(st == DK_OK, "%s", err.message);
    CHECK(conv == k);
    CHECK_NEAR(val[0], 0.0, 1e-9);
    const int group_start[5] = {0, 1, 4, 9, 16};
    const double tol = level >= 4 ? 0.02 : 0.05;
    for (int l = 1; l <= 3; l++) {
        const double expect = l * (l + 1) / (radius * radius);
        for (int j = group_start[l]; j < group_start[l + 1]; j++)
            CHECK_MSG(fabs(val[j] - expect) <= tol * expect, "eigenvalue %d = %g, expected %g",
                      j, val[j], expect);
        /* groups are well separated from each other */
        if (l < 3) CHECK(val[group_start[l + 1]] > 1.3 * val[group_start[l + 1] - 1]);
    }
    for (int j = 1; j < k; j++) CHECK(val[j] >= val[j - 1]);
    const double orth = orthonormality_error(p.mass, vec, p.n, k);
    CHECK_MSG(orth < 1e-8, "M-orthonormality error %g", orth);
    const double res = residual_error(p.l, p.mass, val, vec, p.n, k, 1.0);
    CHECK_MSG(res < 1e-6, "residual %g", res);
    /* the first eigenvector is constant */
    double lo = INFINITY, hi = -INFINITY;
    for (int i = 0; i < p.n; i++) { lo = fmin(lo, vec[i]); hi = fmax(hi, vec[i]); }
    CHECK_NEAR(hi - lo, 0.0, 1e-7 * fabs(hi));
    free(vec);
    problem_free(&p);
}

static void check_against_dense(problem *p, int k, int band_size, const char *name)
{
    double *rval = NULL, *rvec = NULL;
    CHECK(dense_reference(p->l, p->mass, &rval, &rvec));
    if (!rval) return;
    double *val = malloc(sizeof(double) * (size_t)k);
    double *vec = malloc(sizeof(double) * (size_t)p->n * k);
    if (val && vec) {
        dk_eigs_options opt;
        dk_eigs_options_default(&opt);
        opt.band_size = band_size;
        dk_error err = {0};
        int conv = -1;
        dk_status st = dk_eigs_smallest(p->l, p->mass, k, &opt, val, vec, &conv, &err);
        CHECK_MSG(st == DK_OK, "%s: %s", name, err.message);
        CHECK(conv == k);
        const double scale = rval[k - 1];
        int vfail = 0;
        const double sub = compare_pairs(p->mass, p->n, k, val, vec, rval, rvec, p->n, 1e-8,
                                         1e-6, scale, &vfail);
        CHECK_MSG(vfail == 0, "%s: %d eigenvalues differ from the dense solve", name, vfail);
        CHECK_MSG(sub < 1e-7, "%s: eigenvector subspace distance %g", name, sub);
        const double orth = orthonormality_error(p->mass, vec, p->n, k);
        CHECK_MSG(orth < 1e-8, "%s: M-orthonormality error %g", name, orth);
        printf("%s: n=%d k=%d band %d: worst subspace distance %.2e, orthonormality %.2e\n",
               name, p->n, k, band_size, sub, orth);
    }
    free(val); free(vec); free(rval); free(rvec);
}

static void test_against_dense(void)
{
    problem p;
    /* a bumpy sphere (few degeneracies) and the round one (exact degenerate groups) */
    CHECK(problem_make(2, 1.0, 0.15, &p));
    if (p.l) check_against_dense(&p, 20, 50, "bumpy sphere, single band");
    problem_free(&p);
    CHECK(problem_make(3, 1.0, 0.0, &p));
    if (p.l) {
        check_against_dense(&p, 40, 50, "round sphere, single band");
        /* band mode with groups of 2l+1 straddling band boundaries */
        check_against_dense(&p, 110, 16, "round sphere, bands of 16");
    }
    problem_free(&p);
    CHECK(problem_make(3, 1.0, 0.1, &p));
    if (p.l) check_against_dense(&p, 150, 30, "bumpy sphere, bands of 30");
    problem_free(&p);
    /* the whole spectrum (k = n - 1) in bands: big degenerate clusters, a wide spectral gap
     * (64 -> 86) that bands must jump, and the top of the spectrum */
    CHECK(problem_make(2, 1.0, 0.0, &p));
    if (p.l) check_against_dense(&p, p.n - 1, 16, "round sphere, whole spectrum in bands");
    problem_free(&p);
    CHECK(problem_make(1, 1.0, 0.0, &p));
    if (p.l) check_against_dense(&p, p.n - 1, 16, "icosahedron level 1, whole spectrum");
    problem_free(&p);
}

static void test_two_components(void)
{
    /* Two disjoint spheres (radius 1 and 1.5): eigenvalue 0 twice, then the union of both
     * spectra with their multiplicities; against the dense solve, single band and bands. */
    tmesh a, b;
    CHECK(icosphere(2, 1.0, 0.0, &a));
    CHECK(icosphere(2, 1.5, 0.05, &b));
    if (!a.pos || !b.pos) { tmesh_free(&a); tmesh_free(&b); return; }
    problem p;
    memset(&p, 0, sizeof p);
    p.mesh.nv = a.nv + b.nv;
    p.mesh.nf = a.nf + b.nf;
    p.mesh.pos = malloc(sizeof(double) * 3 * (size_t)p.mesh.nv);
    p.mesh.tri = malloc(sizeof(int) * 3 * (size_t)p.mesh.nf);
    p.n = p.mesh.nv;
    p.mass = malloc(sizeof(double) * (size_t)p.n);
    if (p.mesh.pos && p.mesh.tri && p.mass) {
        memcpy(p.mesh.pos, a.pos, sizeof(double) * 3 * (size_t)a.nv);
        memcpy(p.mesh.pos + 3 * (size_t)a.nv, b.pos, sizeof(double) * 3 * (size_t)b.nv);
        memcpy(p.mesh.tri, a.tri, sizeof(int) * 3 * (size_t)a.nf);
        for (int k = 0; k < 3 * b.nf; k++) p.mesh.tri[3 * a.nf + k] = b.tri[k] + a.nv;
        p.l = cotan_laplacian(&p.mesh, p.mass);
    }
    CHECK(p.l != NULL);
    if (p.l) {
        check_against_dense(&p, 30, 50, "two spheres, single band");
        check_against_dense(&p, 100, 16, "two spheres, bands of 16");
    }
    problem_free(&p);
    tmesh_free(&a);
    tmesh_free(&b);
}

/* Appends mesh b, translated by (dx, 0, 0), to a (a grows). */
static int tmesh_append(tmesh *a, const tmesh *b, double dx)
{
    double *pos = realloc(a->pos, sizeof(double) * 3 * (size_t)(a->nv + b->nv));
    if (!pos) return 0;
    a->pos = pos;
    int *tri = realloc(a->tri, sizeof(int) * 3 * (size_t)(a->nf + b->nf));
    if (!tri) return 0;
    a->tri = tri;
    for (int v = 0; v < b->nv; v++)
        for (int d = 0; d < 3; d++)
            a->pos[3 * (size_t)(a->nv + v) + d] = b->pos[3 * (size_t)v + d] + (d == 0 ? dx : 0.0);
    for (int f = 0; f < 3 * b->nf; f++) a->tri[3 * (size_t)a->nf + f] = b->tri[f] + a->nv;
    a->nv += b->nv;
    a->nf += b->nf;
    return 1;
}

static int cmp_double(const void *a, const void *b)
{
    const double x = *(const double *)a, y = *(const double *)b;
    return (x > y) - (x < y);
}

typedef struct progress_log {
    int calls, cancel_at; /* cancel at the cancel_at-th report of a new fraction (0: never) */
    double last;
    int monotone, reports;
} progress_log;

/* The solver reports after each band and repeats the same fraction within a band (so that
 * a cancel lands quickly); `reports` counts the new fractions. */
static int progress_cb(void *user, double fraction)
{
    progress_log *pl = user;
    if (fraction < pl->last || fraction < 0 || fraction > 1) pl->monotone = 0;
    if (pl->calls == 0 || fraction != pl->last)
        pl->reports++;
    pl->last = fraction;
    pl->calls++;
    return pl->cancel_at > 0 && pl->reports >= pl->cancel_at;
}

/* `small` copies of a bumped icosphere (162 vertices: the dense path), `medium` copies of a
 * finer one (642: the sparse path) and one big bumped sphere (642), checked for each k of
 * `ks` against the merged dense spectra of the three shapes. */
static void check_copies(int small, int medium, const int *ks, int nk)
{
    /* The ogre's case (docs/methods/eigen.md): many identical disconnected components, so
     * that every eigenvalue of a component, 0 included, is repeated once per copy, with a
     * bigger component whose spectrum interleaves. The k smallest must be the merged spectra
     * with their full multiplicities, M-orthonormal with small residuals: bases of whole
     * eigenspaces. Before the solver split the problem by components, 40 copies failed
     * ("band 2 near lambda 1.90379 found no certifiable new eigenvalue", the 40-fold cluster
     * missed by the band search); k = 150 also cuts a cluster of copies (its copies given to
     * the components in order). */
    const int SMALL = small, MEDIUM = medium;
    problem one, two, big, all;
    memset(&all, 0, sizeof all);
    CHECK(problem_make(2, 1.0, 0.1, &one));
    CHECK(problem_make(3, 1.2, 0.1, &two));
    CHECK(problem_make(3, 3.0, 0.05, &big));
    if (!one.l || !two.l || !big.l) {
        problem_free(&one); problem_free(&two); problem_free(&big);
        return;
    }
    int ok = icosphere(3, 3.0, 0.05, &all.mesh);
    for (int c = 0; ok && c < SMALL; c++) ok = tmesh_append(&all.mesh, &one.mesh, 7.0 + 2.5 * c);
    for (int c = 0; ok && c < MEDIUM; c++) ok = tmesh_append(&all.mesh, &two.mesh, -7.0 - 3.0 * c);
    CHECK(ok);
    all.n = all.mesh.nv;
    all.mass = ok ? malloc(sizeof(double) * (size_t)all.n) : NULL;
    if (all.mass) all.l = cotan_laplacian(&all.mesh, all.mass);
    CHECK(all.l != NULL);
    double *v1 = NULL, *x1 = NULL, *v2 = NULL, *x2 = NULL, *vb = NULL, *xb = NULL;
    CHECK(dense_reference(one.l, one.mass, &v1, &x1));
    CHECK(dense_reference(two.l, two.mass, &v2, &x2));
    CHECK(dense_reference(big.l, big.mass, &vb, &xb));
    const int nref = SMALL * one.n + MEDIUM * two.n + big.n;
    double *ref = malloc(sizeof(double) * (size_t)nref);
    if (all.l && v1 && v2 && vb && ref) {
        int q = 0;
        for (int c = 0; c < SMALL; c++)
            for (int i = 0; i < one.n; i++) ref[q++] = v1[i];
        for (int c = 0; c < MEDIUM; c++)
            for (int i = 0; i < two.n; i++) ref[q++] = v2[i];
        for (int i = 0; i < big.n; i++) ref[q++] = vb[i];
        qsort(ref, (size_t)nref, sizeof(double), cmp_double);
        for (int t = 0; t < nk; t++) {
            const int k = ks[t];
            double *val = malloc(sizeof(double) * (size_t)k);
            double *vec = malloc(sizeof(double) * (size_t)all.n * k);
            if (!val || !vec) { free(val); free(vec); CHECK(0); break; }
            dk_eigs_options opt;
            dk_eigs_options_default(&opt);
            opt.band_size = 50;
            dk_error err = {0};
            int conv = -1;
            const dk_status st = dk_eigs_smallest(all.l, all.mass, k, &opt, val, vec, &conv, &err);
            CHECK_MSG(st == DK_OK, "copies, k %d: %s", k, err.message);
            if (st == DK_OK) {
                CHECK(conv == k);
                const double scale = ref[k - 1];
                int bad = 0, sorted = 1;
                for (int j = 0; j < k; j++) {
                    if (fabs(val[j] - ref[j]) > 1e-8 * fmax(ref[j], scale)) {
                        if (bad++ < 5)
                            fprintf(stderr, "copies: eigenvalue %d %.15g vs %.15g\n", j, val[j],
                                    ref[j]);
                    }
                    if (j > 0 && val[j] < val[j - 1]) sorted = 0;
                }
                CHECK_MSG(bad == 0, "copies, k %d: %d eigenvalues differ from the merged "
                          "spectra", k, bad);
                CHECK_MSG(sorted, "copies, k %d: eigenvalues not ascending", k);
                /* eigenvalue 0 is there once per component */
                int zeros = 0;
                for (int j = 0; j < k; j++) zeros += fabs(val[j]) < 1e-9 * scale;
                CHECK_MSG(zeros == SMALL + MEDIUM + 1, "copies, k %d: eigenvalue 0 %d times", k,
                          zeros);
                const double res = residual_error(all.l, all.mass, val, vec, all.n, k, scale);
                const double orth = orthonormality_error(all.mass, vec, all.n, k);
                CHECK_MSG(res < 1e-7, "copies, k %d: residual %g", k, res);
                CHECK_MSG(orth < 1e-8, "copies, k %d: M-orthonormality error %g", k, orth);
                if (t == 0) {
                    /* progress and cancellation on the split path: reports monotone up to
                     * 1; a cancel at the first question (the counts) or at a later one
                     * (inside a component) fails cleanly */
                    progress_log pl = {0, 0, 0.0, 1, 0};
                    opt.progress = progress_cb;
                    opt.progress_user = &pl;
                    CHECK(dk_eigs_smallest(all.l, all.mass, k, &opt, val, vec, &conv, &err) ==
                          DK_OK);
                    CHECK(pl.monotone && pl.last == 1.0 && pl.reports >= 2);
                    for (int at = 1; at <= 3; at++) {
                        progress_log cancel = {0, at, 0.0, 1, 0};
                        opt.progress_user = &cancel;
                        CHECK(dk_eigs_smallest(all.l, all.mass, k, &opt, val, vec, &conv,
                                               &err) == DK_ERR_CANCELLED);
                        CHECK(err.status == DK_ERR_CANCELLED && conv == 0);
                    }
                    opt.progress = NULL;
                }
                printf("identical copies (%d + %d): n=%d k=%d: residual %.2e, orthonormality %.2e\n",
                       SMALL, MEDIUM, all.n, k, res, orth);
            }
            free(val);
            free(vec);
        }
    }
    free(ref); free(v1); free(x1); free(v2); free(x2); free(vb); free(xb);
    problem_free(&one);
    problem_free(&two);
    problem_free(&big);
    problem_free(&all);
}

static void test_identical_copies(void)
{
    const int ks_a[2] = {60, 150}, ks_b[1] = {400};
    check_copies(40, 0, ks_a, 2);
    check_copies(40, 6, ks_b, 1);
}

static void test_isolated_vertex(void)
{
    /* A vertex in no triangle: L has an empty column (no diagonal entry), the mass is given
     * by the caller; eigenvalue 0 is then double (constants, and the isolated vertex). */
    problem p;
    memset(&p, 0, sizeof p);
    CHECK(icosphere(2, 1.0, 0.1, &p.mesh));
    if (!p.mesh.pos) return;
    double *grown = realloc(p.mesh.pos, sizeof(double) * 3 * (size_t)(p.mesh.nv + 1));
    CHECK(grown != NULL);
    if (!grown) { tmesh_free(&p.mesh); return; }
    p.mesh.pos = grown;
    p.mesh.pos[3 * p.mesh.nv] = 5.0;
    p.mesh.pos[3 * p.mesh.nv + 1] = p.mesh.pos[3 * p.mesh.nv + 2] = 0.0;
    p.mesh.nv++;
    p.n = p.mesh.nv;
    p.mass = malloc(sizeof(double) * (size_t)p.n);
    if (p.mass) p.l = cotan_laplacian(&p.mesh, p.mass);
    CHECK(p.l != NULL);
    if (p.l) {
        CHECK(p.l->col_start[p.n] == p.l->col_start[p.n - 1]); /* empty last column */
        p.mass[p.n - 1] = 0.01;
        check_against_dense(&p, 12, 50, "sphere + isolated vertex");
        check_against_dense(&p, 60, 16, "sphere + isolated vertex, bands");
    }
    problem_free(&p);
}

static void test_bands_equal_single(void)
{
    /* k = 120 with bands of 30 vs one band of 120, on a ~2.5k-vertex mesh */
    const int level = SANITIZED ? 3 : 4;
    problem p;
    CHECK(problem_make(level, 1.0, 0.08, &p));
    if (!p.l) return;
    const int k = 120;
    double *v1 = malloc(sizeof(double) * k), *v2 = malloc(sizeof(double) * k);
    double *x1 = malloc(sizeof(double) * (size_t)p.n * k);
    double *x2 = malloc(sizeof(double) * (size_t)p.n * k);
    if (v1 && v2 && x1 && x2) {
        dk_eigs_options opt;
        dk_eigs_options_default(&opt);
        dk_error err = {0};
        int conv = 0;
        opt.band_size = 30;
        double t0 = now();
        CHECK_MSG(dk_eigs_smallest(p.l, p.mass, k, &opt, v1, x1, &conv, &err) == DK_OK, "%s",
                  err.message);
        const double t_band = now() - t0;
        opt.band_size = k;
        t0 = now();
        CHECK_MSG(dk_eigs_smallest(p.l, p.mass, k, &opt, v2, x2, &conv, &err) == DK_OK, "%s",
                  err.message);
        const double t_single = now() - t0;
        int vfail = 0;
        const double sub = compare_pairs(p.mass, p.n, k, v1, x1, v2, x2, k, 1e-8, 1e-6, v2[k - 1],
                                         &vfail);
        CHECK_MSG(vfail == 0, "%d eigenvalues differ between band and single runs", vfail);
        CHECK_MSG(sub < 1e-7, "subspace distance %g", sub);
        /* no duplicates: strictly M-orthonormal; no missing: sorted and matching above */
        CHECK(orthonormality_error(p.mass, x1, p.n, k) < 1e-8);
        for (int j = 1; j < k; j++) CHECK(v1[j] >= v1[j - 1]);
        CHECK(residual_error(p.l, p.mass, v1, x1, p.n, k, v1[k - 1]) < 1e-7);
        printf("n=%d k=%d: bands of 30 %.3f s, single band %.3f s, subspace distance %.2e\n",
               p.n, k, t_band, t_single, sub);
    }
    free(v1); free(v2); free(x1); free(x2);
    problem_free(&p);
}

static void test_progress_and_cancel(void)
{
    problem p;
    CHECK(problem_make(3, 1.0, 0.1, &p));
    if (!p.l) return;
    const int k = 60;
    double *val = malloc(sizeof(double) * k), *vec = malloc(sizeof(double) * (size_t)p.n * k);
    if (val && vec) {
        dk_eigs_options opt;
        dk_eigs_options_default(&opt);
        opt.band_size = 20;
        progress_log pl = {0, 0, 0.0, 1, 0};
        opt.progress = progress_cb;
        opt.progress_user = &pl;
        dk_error err = {0};
        int conv = 0;
        CHECK(dk_eigs_smallest(p.l, p.mass, k, &opt, val, vec, &conv, &err) == DK_OK);
        CHECK(pl.reports >= 3 && pl.monotone && pl.last == 1.0);
        progress_log cancel = {0, 2, 0.0, 1, 0};
        opt.progress_user = &cancel;
        CHECK(dk_eigs_smallest(p.l, p.mass, k, &opt, val, vec, &conv, &err) == DK_ERR_CANCELLED);
        CHECK(err.status == DK_ERR_CANCELLED);
        CHECK(conv > 0 && conv < k);
        /* cancelled at the first question, inside the first band: nothing converged */
        progress_log early = {0, 1, 0.0, 1, 0};
        opt.progress_user = &early;
        CHECK(dk_eigs_smallest(p.l, p.mass, k, &opt, val, vec, &conv, &err) == DK_ERR_CANCELLED);
        CHECK(early.calls == 1 && early.last == 0.0 && conv == 0);
    }
    free(val); free(vec);
    problem_free(&p);
}

/* dk_eigs_smallest with default options */
static dk_status eigs0(const dk_sparse *l, const double *mass, int k, double *val, double *vec,
                       int *conv, dk_error *err)
{
    return dk_eigs_smallest(l, mass, k, NULL, val, vec, conv, err);
}

static void test_bad_input(void)
{
    problem p;
    CHECK(problem_make(1, 1.0, 0.0, &p));
    if (!p.l) return;
    double val[60], *vec = malloc(sizeof(double) * (size_t)p.n * 60);
    if (vec) {
        dk_error err = {0};
        int conv = 7;
        CHECK(eigs0(p.l, p.mass, 0, val, vec, &conv, &err) == DK_ERR_INVALID_ARGUMENT);
        CHECK(conv == 0);
        CHECK(strstr(err.message, "k is 0") != NULL);
        CHECK(eigs0(p.l, p.mass, -3, val, vec, NULL, &err) == DK_ERR_INVALID_ARGUMENT);
        CHECK(eigs0(p.l, p.mass, p.n, val, vec, NULL, &err) == DK_ERR_INVALID_ARGUMENT);
        CHECK(eigs0(NULL, p.mass, 3, val, vec, NULL, &err) == DK_ERR_INVALID_ARGUMENT);
        CHECK(eigs0(p.l, p.mass, 3, NULL, vec, NULL, &err) == DK_ERR_INVALID_ARGUMENT);
        const double keep = p.mass[5];
        p.mass[5] = 0.0;
        CHECK(eigs0(p.l, p.mass, 3, val, vec, NULL, &err) == DK_ERR_INVALID_ARGUMENT);
        CHECK_MSG(strstr(err.message, "vertex 5") != NULL, "%s", err.message);
        p.mass[5] = -1.0;
        CHECK(eigs0(p.l, p.mass, 3, val, vec, NULL, &err) == DK_ERR_INVALID_ARGUMENT);
        p.mass[5] = keep;
        const double lv = p.l->values[3];
        p.l->values[3] = NAN;
        CHECK(eigs0(p.l, p.mass, 3, val, vec, NULL, &err) == DK_ERR_NONFINITE);
        p.l->values[3] = lv;
        /* k = n - 1 (the largest allowed) works on this small mesh (42 vertices) */
        CHECK_MSG(eigs0(p.l, p.mass, p.n - 1, val, vec, &conv, &err) == DK_OK,
                  "%s", err.message);
        CHECK(conv == p.n - 1);
        /* an indefinite "Laplacian" is refused by the positive definite first shift */
        for (dk_index j = 0; j < p.l->n_cols; j++)
            for (dk_index q = p.l->col_start[j]; q < p.l->col_start[j + 1]; q++)
                if (p.l->row_index[q] == j) p.l->values[q] -= 10.0;
        dk_status st = eigs0(p.l, p.mass, 3, val, vec, NULL, &err);
        CHECK(st == DK_ERR_NOT_POSITIVE_DEFINITE || st == DK_ERR_INVALID_ARGUMENT);
    }
    free(vec);
    problem_free(&p);
}

static void test_no_convergence(void)
{
    /* One restart with an unreachable tolerance cannot converge the pairs: the failure must
     * say how many did and hand back those, each a genuine eigenpair. (Deterministic: the
     * ARPACK start vectors are fixed.) */
    problem p;
    CHECK(problem_make(3, 1.0, 0.0, &p));
    if (!p.l) return;
    const int k = 100;
    double *val = malloc(sizeof(double) * k), *vec = malloc(sizeof(double) * (size_t)p.n * k);
    if (val && vec) {
        dk_eigs_options opt;
        dk_eigs_options_default(&opt);
        opt.max_iterations = 1;
        opt.tolerance = 1e-300;
        opt.band_size = 16;
        dk_error err = {0};
        int conv = -1;
        dk_status st = dk_eigs_smallest(p.l, p.mass, k, &opt, val, vec, &conv, &err);
        printf("no-convergence case: status %d, %d of %d converged: %s\n", (int)st, conv, k,
               err.message);
        CHECK_MSG(st == DK_ERR_NO_CONVERGENCE, "%d: %s", (int)st, err.message);
        CHECK(err.status == DK_ERR_NO_CONVERGENCE);
        CHECK(conv > 0 && conv < k);
        char expect[64];
        snprintf(expect, sizeof expect, "%d of %d eigenpairs converged", conv, k);
        CHECK_MSG(strstr(err.message, expect) != NULL, "%s", err.message);
        if (conv > 0 && conv < k) {
            CHECK(residual_error(p.l, p.mass, val, vec, p.n, conv, 1.0) < 1e-6);
            CHECK(orthonormality_error(p.mass, vec, p.n, conv) < 1e-8);
        }
    }
    free(val); free(vec);
    problem_free(&p);
}

DK_TEST_MAIN(test_sphere_harmonics, test_against_dense, test_two_components, test_identical_copies,
              test_isolated_vertex,
             test_bands_equal_single,
             test_progress_and_cancel, test_bad_input, test_no_convergence)
