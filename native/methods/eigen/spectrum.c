/* DeformKit EigenDeformation: the eigenpairs of the mesh Laplacian and Phi's factor
 * (eigen_internal.h). */
#include "eigen_internal.h"
#include "dk_lapack.h"

#include <cblas.h>
#include <lapacke.h>
#include <math.h>
#include <stdlib.h>
#include <string.h>

#include "dk_eigs.h"
#include "dk_operators.h"
#include "dk_sparse.h"

/* Below this many vertices (or when K is a large share of n) the eigenpairs come from a dense
 * solve: ARPACK wants K well below n, and the tests need all n of them. */
#define DENSE_MAX 600

/* The K smallest pairs of L phi = lambda M phi, densely: C = M^-1/2 L M^-1/2, phi = M^-1/2 y. */
static dk_status dense_eigenpairs(const dk_sparse *l, const double *mass, dk_index n, int K,
                                  double *evals, double *U, dk_error *err)
{
    double *c = calloc((size_t)n * (size_t)n, sizeof *c), *ev = malloc((size_t)n * sizeof *ev);
    if (!c || !ev) {
        free(c);
        free(ev);
        return eigen_oom(err, "dense eigenproblem");
    }
    for (dk_index j = 0; j < n; j++)
        for (dk_index q = l->col_start[j]; q < l->col_start[j + 1]; q++) {
            const dk_index i = l->row_index[q];
            c[(size_t)j * n + i] = l->values[q] / sqrt(mass[i] * mass[j]);
        }
    const int info = dk_lapack_dsyevd('V', n, c, ev);
    dk_status st = DK_OK;
    if (info != 0) {
        st = dk_error_set(err, DK_ERR_NUMERIC, "EigenDeformation: dense eigensolver failed "
                          "(LAPACK dsyevd info %d)", (int)info);
    } else {
        memcpy(evals, ev, (size_t)K * sizeof *evals);
        for (int k = 0; k < K; k++)
            for (dk_index i = 0; i < n; i++)
                U[(size_t)k * n + i] = c[(size_t)k * n + i] / sqrt(mass[i]);
    }
    free(c);
    free(ev);
    return st;
}

/* The kernel must connect what the mesh connects. Where it does not reach across an edge of
 * the mesh, the operator splits a component into pieces, each with a constant eigenvector of
 * its own, and a kernel narrower than the edges leaves every row empty: every drag returned
 * the rest mesh without a word (the second hostile review: bsw_width 0.3). So the pairs'
 * components (union-find) must join the two ends of every mesh edge, or the bind is refused
 * with the count. Nearby components of the mesh joined by the kernel are the method's own
 * (a point-cloud Laplacian). */
static dk_index uf_root(dk_index *parent, dk_index a)
{
    while (parent[a] != a) {
        parent[a] = parent[parent[a]];
        a = parent[a];
    }
    return a;
}

static dk_status bsw_check_reach(const dk_mesh *mesh, double width, const dk_index *ri,
                                 const dk_index *ci, int64_t t, dk_error *err)
{
    const dk_index n = mesh->n_vertices;
    dk_index *parent = malloc(((size_t)n + 1) * sizeof *parent);
    if (!parent)
        return eigen_oom(err, "Belkin-Sun-Wang Laplacian");
    for (dk_index w = 0; w < n; w++)
        parent[w] = w;
    for (int64_t q = 0; q < t; q++) {
        const dk_index a = uf_root(parent, ri[q]), b = uf_root(parent, ci[q]);
        if (a != b)
            parent[a] = b;
    }
    dk_index split = 0, first = -1;
    for (dk_index e = 0; e < mesh->n_edges; e++)
        if (uf_root(parent, mesh->edges[2 * e]) != uf_root(parent, mesh->edges[2 * e + 1]) &&
            split++ == 0)
            first = mesh->edges[2 * e];
    free(parent);
    if (split == 0)
        return DK_OK;
    return dk_error_set(err, DK_ERR_INVALID_ARGUMENT,
                        "EigenDeformation: bsw_width %g is too narrow for this mesh: the "
                        "kernel's reach (3 x bsw_width x the mean edge length, %g) does not "
                        "connect the ends of %lld of its %lld edges (first at vertex %lld), so "
                        "the Laplacian would split the surface into pieces that move apart; "
                        "raise bsw_width (1, the default, reaches the neighbours of a regular "
                        "mesh)",
                        width, 3.0 * width * mesh->mean_edge_length, (long long)split,
                        (long long)mesh->n_edges, (long long)first);
}

/* The Belkin-Sun-Wang mesh-Laplacian as a symmetric pair: stiffness
 * S_wp = -a_w a_p G(w, p) / (4 pi h^2) off the diagonal (rows summing to 0) and the mass a
 * (barycentric, `mass`), so that M^-1 S is the operator of dk_eigen.h. Each vertex's pairs
 * come from its 64 nearest vertices within the cut; a pair seen from both ends gets half
 * from each, so S is symmetric whatever the neighbour lists. */
#define BSW_NEIGHBOURS 64

static dk_status bsw_laplacian(const dk_mesh *mesh, double width, const double *mass,
                               dk_sparse **out, dk_error *err)
{
    const dk_index n = mesh->n_vertices;
    const dk_index k = n < BSW_NEIGHBOURS + 1 ? n : BSW_NEIGHBOURS + 1; /* + itself */
    const double four_h = (width * mesh->mean_edge_length) * (width * mesh->mean_edge_length);
    const double pi = 3.14159265358979323846;
    const double h = 0.25 * four_h, cut2 = 9.0 * four_h, scale = 1.0 / (4.0 * pi * h * h);
    dk_kdtree *tree = NULL;
    dk_index *nb = malloc((size_t)n * (size_t)k * sizeof *nb);
    double *d2 = malloc((size_t)n * (size_t)k * sizeof *d2);
    const int64_t cap = 2 * (int64_t)n * k + n;
    dk_index *ri = malloc((size_t)cap * sizeof *ri), *ci = malloc((size_t)cap * sizeof *ci);
    double *val = malloc((size_t)cap * sizeof *val);
    dk_status st = (!nb || !d2 || !ri || !ci || !val) ? eigen_oom(err, "Belkin-Sun-Wang Laplacian")
                                                       : DK_OK;
    if (st == DK_OK && !(four_h > 0.0))
        st = dk_error_set(err, DK_ERR_DEGENERATE,
                          "EigenDeformation: the mesh has no edge length for the "
                          "Belkin-Sun-Wang kernel");
    if (st == DK_OK)
        st = dk_kdtree_create(mesh->positions, n, &tree, err);
    if (st == DK_OK)
        st = dk_kdtree_knn(tree, mesh->positions, n, k, nb, d2, err);
    int64_t t = 0;
    for (dk_index w = 0; st == DK_OK && w < n; w++)
        for (dk_index q = 0; q < k; q++) {
            const dk_index p = nb[(size_t)w * k + q];
            const double dd = d2[(size_t)w * k + q];
            if (p == w || dd > cut2)
                continue;
            const double x = 0.5 * scale * mass[w] * mass[p] * exp(-dd / four_h);
            ri[t] = w, ci[t] = p, val[t++] = -x; /* half from each end */
            ri[t] = p, ci[t] = w, val[t++] = -x;
        }
    if (st == DK_OK)
        st = bsw_check_reach(mesh, width, ri, ci, t, err);
    if (st == DK_OK) { /* the diagonal: minus the row sums (each pair added to both rows) */
        double *diag = calloc((size_t)n, sizeof *diag);
        if (!diag) {
            st = eigen_oom(err, "Belkin-Sun-Wang Laplacian");
        } else {
            for (int64_t q = 0; q < t; q++)
                diag[ri[q]] -= val[q];
            for (dk_index w = 0; w < n; w++)
                ri[t] = w, ci[t] = w, val[t++] = diag[w];
            free(diag);
            st = dk_sparse_from_triplets(n, n, t, ri, ci, val, out, err);
        }
    }
    dk_kdtree_free(tree);
    free(nb);
    free(d2);
    free(ri);
    free(ci);
    free(val);
    return st;
}

const dk_progress_phase eigen_phases[EIGEN_N_PHASES] = {
    {"regions", 0.01},      /* EIGEN_PHASE_REGIONS: regions, g, w, delta_3                 */
    {"operator", 0.02},     /* EIGEN_PHASE_OPERATOR: mass and Laplacian                    */
    {"eigenvectors", 15.7}, /* EIGEN_PHASE_EIGENVECTORS: the band-by-band eigensolver      */
    {"skeletons", 0.45},    /* EIGEN_PHASE_SKELETONS: U^T U, its factor, the skeletons     */
};

/* The eigensolver's fraction of pairs found, relayed as the part done of the eigenvectors
 * phase; a stop there keeps the reporter's message ("cancelled in phase eigenvectors"). */
typedef struct eigs_relay {
    dk_progress *p;
    dk_error err;
    int stopped;
} eigs_relay;

static int relay_eigs_progress(void *user, double fraction)
{
    eigs_relay *r = user;
    if (dk_progress_part(r->p, fraction, &r->err) != DK_OK) {
        r->stopped = 1;
        return 1;
    }
    return 0;
}

/* 1. the eigenvectors of the mesh Laplacian, and Phi's factor */
dk_status eigen_eigenvectors(dk_eigen *e, dk_error *err)
{
    const dk_index n = e->n;
    dk_sparse *l = NULL;
    double *mass = malloc((size_t)n * sizeof *mass);
    e->evals = malloc((size_t)e->K * sizeof *e->evals);
    e->U = malloc((size_t)n * (size_t)e->K * sizeof *e->U);
    e->chol = malloc((size_t)e->K * (size_t)e->K * sizeof *e->chol);
    dk_status st = (!mass || !e->evals || !e->U || !e->chol) ? eigen_oom(err, "eigenvectors") : DK_OK;
    if (st == DK_OK)
        st = dk_progress_begin(&e->prog, EIGEN_PHASE_OPERATOR, err);
    const int bsw = e->opt.laplacian == DK_EIGEN_BELKIN_SUN_WANG;
    if (st == DK_OK)
        st = dk_mass_matrix(e->mesh, bsw ? DK_MASS_BARYCENTRIC : DK_MASS_VORONOI, mass, err);
    if (st == DK_OK)
        st = bsw ? bsw_laplacian(e->mesh, e->opt.bsw_width, mass, &l, err)
                 : dk_laplacian_cotangent(e->mesh, &l, err);
    for (dk_index i = 0; st == DK_OK && i < n; i++)
        if (!(mass[i] > 0.0) && e->mesh->ring_start[i + 1] > e->mesh->ring_start[i])
            st = dk_error_set(err, DK_ERR_DEGENERATE,
                              "EigenDeformation: vertex %d has no area (it is only on "
                              "degenerate triangles): the Laplacian's mass matrix needs every "
                              "vertex of a face to have area", (int)i);
    /* Loose vertices (on no face, issue 18 class 12) take no part in the spectral fit: each
     * gets mass 1 and a Laplacian diagonal above every eigenvalue of the surface (a
     * Gershgorin bound of M^-1 L), so that it decouples into a mode of its own that is
     * never among the smallest, and every surface eigenvector is exactly 0 there. Their
     * result is their constraint's (solve: handle target, or rest). */
    if (st == DK_OK) {
        double bound = 0.0;
        dk_index n_loose = 0;
        double *row = calloc((size_t)n + 1, sizeof *row);
        if (!row)
            st = eigen_oom(err, "eigenvectors");
        for (dk_index j = 0; st == DK_OK && j < n; j++) /* symmetric: columns are rows */
            for (dk_index p = l->col_start[j]; p < l->col_start[j + 1]; p++)
                row[j] += fabs(l->values[p]);
        for (dk_index i = 0; st == DK_OK && i < n; i++) {
            if (mass[i] > 0.0)
                bound = fmax(bound, row[i] / mass[i]);
            else
                n_loose++;
        }
        if (st == DK_OK && n_loose > 0) {
            dk_sparse *l2 = NULL;
            for (dk_index i = 0; i < n; i++) {
                row[i] = mass[i] > 0.0 ? 0.0 : 1e3 * bound + 1.0;
                if (!(mass[i] > 0.0))
                    mass[i] = 1.0;
            }
            st = dk_sparse_add_diagonal(l, row, &l2, err);
            if (st == DK_OK) {
                dk_sparse_free(l);
                l = l2;
            }
        }
        free(row);
    }
    if (st == DK_OK)
        st = dk_progress_begin(&e->prog, EIGEN_PHASE_EIGENVECTORS, err);
    if (st == DK_OK) {
        eigs_relay relay = {&e->prog, {0}, 0};
        if (n <= DENSE_MAX || e->K > n / 4) {
            st = dense_eigenpairs(l, mass, n, e->K, e->evals, e->U, err);
        } else {
            dk_eigs_options eo;
            dk_eigs_options_default(&eo);
            if (e->opt.progress) {
                eo.progress = relay_eigs_progress;
                eo.progress_user = &relay;
            }
            st = dk_eigs_smallest(l, mass, e->K, &eo, e->evals, e->U, NULL, err);
        }
        if (st == DK_ERR_CANCELLED && relay.stopped) {
            if (err)
                *err = relay.err; /* "EigenDeformation: cancelled in phase eigenvectors" */
        } else if (st != DK_OK) {
            dk_error_prefix(err, "EigenDeformation: eigenvectors");
        }
    }
    if (st == DK_OK)
        st = dk_progress_begin(&e->prog, EIGEN_PHASE_SKELETONS, err);
    if (st == DK_OK) { /* Phi = U^T U (the sum over the vertices of eq. 1), and its factor */
        cblas_dsyrk(CblasColMajor, CblasUpper, CblasTrans, e->K, (int)n, 1.0, e->U, (int)n, 0.0,
                    e->chol, e->K);
        const lapack_int info = LAPACKE_dpotrf(LAPACK_COL_MAJOR, 'U', e->K, e->chol, e->K);
        if (info != 0)
            st = dk_error_set(err, DK_ERR_NOT_POSITIVE_DEFINITE,
                              "EigenDeformation: Phi = U^T U is singular at eigenvector %d "
                              "(LAPACK dpotrf info %d)", (int)info, (int)info);
    }
    dk_sparse_free(l);
    free(mass);
    return st;
}
