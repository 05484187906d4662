/* DeformKit: eigen deformation (Dey, Ranjan & Wang). See dk_eigen.h for the method, and
 * docs/methods/eigen.md for the choices the paper leaves open. */
#include "dk_eigen.h"

#include <cblas.h>
#include <lapacke.h>
#include <math.h>
#include <stdlib.h>
#include <string.h>

#include "dk_eigs.h"
#include "dk_operators.h"
#include "dk_sparse.h"
#include "eigen_part.h"

/* Below this many vertices (or when K is a large share of n) the eigenpairs come from a dense
 * solve: ARPACK wants K well below n, and the tests need all n of them. */
#define DENSE_MAX 600

/* One level of the scheme: a skeleton with m eigenvectors, and the detail vectors that lead
 * from it to the next level (the mesh, or K_n' in the two-iteration scheme). */
typedef struct level {
    int m;
    double *p;       /* n x 3: the rest skeleton K_m                                       */
    double *b0;      /* m x 3: U_m^T p, eq. 1's right-hand side when nothing moves         */
    double *detail;  /* n x 3: to the next level, in world coordinates (d = next - p)       */
    double *coord;   /* n x 3: d in the rest skeleton's local frame (edge, cross, normal)   */
    dk_index *frame_nb; /* n: the neighbour whose edge gives the frame, -1: no valid frame */
} level;

/* What the constraints give: replaced as a whole by rebind. */
typedef struct eigen_regions {
    dk_constraints *user;    /* the caller's constraints, for region PART (NULL: HANDLES,
                                where they are con)                                         */
    eigen_parts parts;       /* PART: the groups each handle drags (eigen_part.h)           */
    dk_constraints *con;     /* the groups R is made of                                     */
    dk_index *region;        /* n: the group, or -1 outside R                               */
    double *g, *w;           /* n: distance to the boundary of R; interpolation weight     */
    double delta3;
    /* the last request: per group the linear part of its motion (identity for targets given
     * as positions: the paper's translation-type motion, per vertex), and the Step-1 targets
     * of R's vertices */
    double *lin;             /* con->n_handles x 9                                          */
    double *target;          /* con->n_handle_vertices x 3                                  */
    double *utarget;         /* PART: user->n_handle_vertices x 3, the caller's targets     */
    double *uT, *gT;         /* PART: the handles' and the groups' transforms (x 16)        */
} eigen_regions;

struct dk_eigen {
    const dk_mesh *mesh;
    dk_eigen_options opt;
    dk_progress prog;        /* the bind's reporter (eigen_phases)                         */
    dk_index n;
    int K, m, n_levels;      /* n_levels 1 (one iteration) or 2 (section 4.3)              */
    double *evals, *U;       /* K; n x K column-major                                      */
    double *chol;            /* K x K column-major, upper: Phi_K = R^T R                   */
    level lv[2];
    eigen_regions r;         /* the regions and the last request's targets                  */
    int preview;             /* dk_eigen_set_preview                                        */
    /* scratch, allocated at bind */
    double *ptil, *pstar, *normals, *b, *next;
    double *cm;              /* n x 3 column-major, for the products with U                 */
    double tiny;             /* a skeleton edge shorter than this defines no frame (FRAME_*) */
};

static dk_status oom(dk_error *err, const char *what)
{
    return dk_error_set(err, DK_ERR_OUT_OF_MEMORY, "EigenDeformation: out of memory (%s)", what);
}

void dk_eigen_default_options(dk_eigen_options *o)
{
    memset(o, 0, sizeof *o);
    o->n_eigenvectors = 0;
    o->refine = 300;
    o->laplacian = DK_EIGEN_COTANGENT;
    o->region = DK_EIGEN_REGION_PART;
    o->bsw_width = 1.0;
}

/* ------------------------------------------------------------------ eigenpairs --------- */

/* The K smallest pairs of L phi = lambda M phi, densely: C = M^-1/2 L M^-1/2, phi = M^-1/2 y. */
static dk_status dense_eigenpairs(const dk_sparse *l, const double *mass, dk_index n, int K,
                                  double *evals, double *U, dk_error *err)
{
    double *c = calloc((size_t)n * (size_t)n, sizeof *c), *ev = malloc((size_t)n * sizeof *ev);
    if (!c || !ev) {
        free(c);
        free(ev);
        return oom(err, "dense eigenproblem");
    }
    for (dk_index j = 0; j < n; j++)
        for (dk_index q = l->col_start[j]; q < l->col_start[j + 1]; q++) {
            const dk_index i = l->row_index[q];
            c[(size_t)j * n + i] = l->values[q] / sqrt(mass[i] * mass[j]);
        }
    const lapack_int info = LAPACKE_dsyevd(LAPACK_COL_MAJOR, 'V', 'U', n, c, n, ev);
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
        return oom(err, "Belkin-Sun-Wang Laplacian");
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
    dk_status st = (!nb || !d2 || !ri || !ci || !val) ? oom(err, "Belkin-Sun-Wang Laplacian")
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
            st = oom(err, "Belkin-Sun-Wang Laplacian");
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

/* The bind's phases (dk_progress.h). Weights: seconds measured on the 43k armadillo
 * (the armadillo-wave handle, K = 300, cotangent; 2 cores at a load of ~2): the
 * eigenvectors dominate at every size (713 s of the 1M ogre's bind, docs/methods/eigen.md). */
enum { EIGEN_PHASE_REGIONS, EIGEN_PHASE_OPERATOR, EIGEN_PHASE_EIGENVECTORS,
       EIGEN_PHASE_SKELETONS };
static const dk_progress_phase eigen_phases[] = {
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
static dk_status eigenvectors(dk_eigen *e, dk_error *err)
{
    const dk_index n = e->n;
    dk_sparse *l = NULL;
    double *mass = malloc((size_t)n * sizeof *mass);
    e->evals = malloc((size_t)e->K * sizeof *e->evals);
    e->U = malloc((size_t)n * (size_t)e->K * sizeof *e->U);
    e->chol = malloc((size_t)e->K * (size_t)e->K * sizeof *e->chol);
    dk_status st = (!mass || !e->evals || !e->U || !e->chol) ? oom(err, "eigenvectors") : DK_OK;
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
            st = oom(err, "eigenvectors");
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

/* ------------------------------------------------------------------ eq. 1 -------------- */

/* b (m x 3, column-major) = U_m^T x, for x n x 3 row-major: x is first copied into
 * column-major scratch, so that both operands are read along their columns. */
static void project(const dk_eigen *e, int m, const double *x, double *b)
{
    const dk_index n = e->n;
    for (dk_index i = 0; i < n; i++)
        for (int r = 0; r < 3; r++)
            e->cm[(size_t)r * n + i] = x[3 * (size_t)i + r];
    cblas_dgemm(CblasColMajor, CblasTrans, CblasNoTrans, m, 3, (int)n, 1.0, e->U, (int)n, e->cm,
                (int)n, 0.0, b, m);
}

/* Step 2: A = Phi_m^-1 b in place (b m x 3), then out = U_m A (n x 3 row-major), computed
 * column-major (U_m read along its columns) and transposed. The factor of Phi_m is the
 * leading block of Phi_K's. */
static void fit(const dk_eigen *e, int m, double *b, double *out)
{
    const dk_index n = e->n;
    LAPACKE_dpotrs(LAPACK_COL_MAJOR, 'U', m, 3, e->chol, e->K, b, m);
    cblas_dgemm(CblasColMajor, CblasNoTrans, CblasNoTrans, (int)n, 3, m, 1.0, e->U, (int)n, b, m,
                0.0, e->cm, (int)n);
    for (dk_index i = 0; i < n; i++)
        for (int r = 0; r < 3; r++)
            out[3 * (size_t)i + r] = e->cm[(size_t)r * n + i];
}

/* ------------------------------------------------------------------ local frames ------- */

/* Area-weighted vertex normals of the mesh's connectivity at positions p (not normalised). */
static void vertex_normals(const dk_mesh *mesh, const double *p, double *nrm)
{
    memset(nrm, 0, 3 * (size_t)mesh->n_vertices * sizeof *nrm);
    for (dk_index f = 0; f < mesh->n_faces; f++) {
        const dk_index *t = mesh->faces + 3 * (size_t)f;
        const double *a = p + 3 * (size_t)t[0], *b = p + 3 * (size_t)t[1];
        const double *c = p + 3 * (size_t)t[2];
        const double u[3] = {b[0] - a[0], b[1] - a[1], b[2] - a[2]};
        const double v[3] = {c[0] - a[0], c[1] - a[1], c[2] - a[2]};
        const double x[3] = {u[1] * v[2] - u[2] * v[1], u[2] * v[0] - u[0] * v[2],
                             u[0] * v[1] - u[1] * v[0]};
        for (int k = 0; k < 3; k++)
            for (int d = 0; d < 3; d++)
                nrm[3 * (size_t)t[k] + d] += x[d];
    }
}

/* How short a skeleton edge may be and still define a frame: FRAME_REL of the mesh's bounding
 * box diagonal plus FRAME_ABS of its largest coordinate (rounding in the fit grows with the
 * coordinates). Our choice, the paper has none: a skeleton collapsed to a point (m smaller
 * than a mesh's number of parts gives a part the constant eigenvector alone) is a point up to
 * rounding, ~1e-15 of the coordinates, and a frame taken from that noise turns at random
 * between the rest skeleton and p* (the ogre's 44 parts at m = 50 moved 3 of them by up to
 * 3 units at zero drag). At the threshold, rounding turns a frame by ~1e-9 rad; no skeleton
 * an artist can see is that small. Such a vertex takes the transformation-based detail. */
#define FRAME_REL 1e-6
#define FRAME_ABS 1e-9

/* The frame of vertex i at positions p with normal nrm_i, from the edge to neighbour j:
 * rows F[0] = the edge projected on the tangent plane, F[1] = normal x F[0], F[2] = normal.
 * Returns 0 when the normal, the edge or the projected edge is too short to define it: the
 * edge under tiny, the area-weighted normal (twice the one-ring's area) under tiny^2. */
static int frame(const double *p, const double *nrm, dk_index i, dk_index j, double tiny,
                 double F[9])
{
    const double *ni = nrm + 3 * (size_t)i;
    const double nl = sqrt(ni[0] * ni[0] + ni[1] * ni[1] + ni[2] * ni[2]);
    const double ed[3] = {p[3 * (size_t)j] - p[3 * (size_t)i],
                          p[3 * (size_t)j + 1] - p[3 * (size_t)i + 1],
                          p[3 * (size_t)j + 2] - p[3 * (size_t)i + 2]};
    const double el = sqrt(ed[0] * ed[0] + ed[1] * ed[1] + ed[2] * ed[2]);
    if (!(nl > tiny * tiny) || !(el > tiny) || !isfinite(nl) || !isfinite(el))
        return 0;
    double z[3] = {ni[0] / nl, ni[1] / nl, ni[2] / nl};
    const double dn = ed[0] * z[0] + ed[1] * z[1] + ed[2] * z[2];
    double x[3] = {ed[0] - dn * z[0], ed[1] - dn * z[1], ed[2] - dn * z[2]};
    const double xl = sqrt(x[0] * x[0] + x[1] * x[1] + x[2] * x[2]);
    if (!(xl > 1e-6 * el)) /* the edge (nearly) along the normal */
        return 0;
    for (int d = 0; d < 3; d++)
        x[d] /= xl;
    F[0] = x[0], F[1] = x[1], F[2] = x[2];
    F[3] = z[1] * x[2] - z[2] * x[1];
    F[4] = z[2] * x[0] - z[0] * x[2];
    F[5] = z[0] * x[1] - z[1] * x[0];
    F[6] = z[0], F[7] = z[1], F[8] = z[2];
    return 1;
}

/* FRAME_REL of the bounding box diagonal plus FRAME_ABS of the largest coordinate. */
static double frame_threshold(const dk_mesh *mesh)
{
    double lo[3] = {INFINITY, INFINITY, INFINITY}, hi[3] = {-INFINITY, -INFINITY, -INFINITY};
    double big = 0.0;
    for (size_t q = 0; q < 3 * (size_t)mesh->n_vertices; q++) {
        const double x = mesh->positions[q];
        lo[q % 3] = fmin(lo[q % 3], x);
        hi[q % 3] = fmax(hi[q % 3], x);
        big = fmax(big, fabs(x));
    }
    const double dx = hi[0] - lo[0], dy = hi[1] - lo[1], dz = hi[2] - lo[2];
    return FRAME_REL * sqrt(dx * dx + dy * dy + dz * dz) + FRAME_ABS * big;
}

/* Chooses each vertex's frame edge on the rest skeleton (the first neighbour that gives a
 * valid frame) and records the detail vectors' coordinates in it. */
static void record_frames(const dk_eigen *e, level *L, double *nrm)
{
    const dk_mesh *mesh = e->mesh;
    vertex_normals(mesh, L->p, nrm);
    for (dk_index i = 0; i < e->n; i++) {
        double F[9];
        L->frame_nb[i] = -1;
        for (dk_index q = mesh->ring_start[i]; q < mesh->ring_start[i + 1]; q++)
            if (frame(L->p, nrm, i, mesh->ring_index[q], e->tiny, F)) {
                L->frame_nb[i] = mesh->ring_index[q];
                break;
            }
        const double *d = L->detail + 3 * (size_t)i;
        double *c = L->coord + 3 * (size_t)i;
        if (L->frame_nb[i] < 0) {
            c[0] = c[1] = c[2] = 0.0;
            continue;
        }
        for (int r = 0; r < 3; r++)
            c[r] = F[3 * r] * d[0] + F[3 * r + 1] * d[1] + F[3 * r + 2] * d[2];
    }
}

/* ------------------------------------------------------------------ regions ------------ */

/* 2. R, its boundary, g (Dijkstra from the boundary), w (section 4.1) and delta_3 (4.2). */
/* What the method does not use, refused rather than ignored. */
static dk_status refuse_unused(const dk_constraint_desc *desc, dk_error *err)
{
    if (desc->n_roi > 0)
        return dk_error_set(err, DK_ERR_INVALID_ARGUMENT,
                            "EigenDeformation: no region of interest (roi) is used: the region "
                            "R is what the handles move");
    if (desc->handle_weights)
        for (int64_t i = 0, tot = 0; i < desc->n_handles; tot += desc->handle_sizes[i], i++)
            for (dk_index k = 0; k < desc->handle_sizes[i]; k++)
                if (desc->handle_weights[tot + k] != 1.0)
                    return dk_error_set(err, DK_ERR_INVALID_ARGUMENT,
                                        "EigenDeformation: handle weights are not used (a "
                                        "region moves as a whole): leave them at 1");
    return DK_OK;
}

/* g, w and delta3 of R (the vertices with region >= 0). */
static dk_status distances(const dk_mesh *mesh, eigen_regions *R, dk_error *err)
{
    const dk_index n = mesh->n_vertices;
    const dk_index *region = R->region;
    double *g = R->g, *w = R->w;
    dk_index *src = malloc(((size_t)n + 1) * sizeof *src), ns = 0;
    if (!src)
        return oom(err, "regions");
    for (dk_index v = 0; v < n; v++) { /* in R, with a neighbour outside: the boundary */
        if (region[v] < 0)
            continue;
        for (dk_index q = mesh->ring_start[v]; q < mesh->ring_start[v + 1]; q++)
            if (region[mesh->ring_index[q]] < 0) {
                src[ns++] = v;
                break;
            }
    }
    dk_status st = DK_OK;
    if (ns > 0) {
        st = dk_geodesic_dijkstra(mesh, src, ns, g, err);
    } else {
        for (dk_index v = 0; v < n; v++)
            g[v] = INFINITY;
    }
    free(src);
    if (st != DK_OK)
        return dk_error_prefix(err, "EigenDeformation: distances to the boundary of R");
    double diam_r = 0.0, diam_out = 0.0;
    for (dk_index v = 0; v < n; v++)
        if (isfinite(g[v])) {
            if (region[v] >= 0)
                diam_r = fmax(diam_r, g[v]);
            else
                diam_out = fmax(diam_out, g[v]);
        }
    /* section 4.1: w = 1 within diam R / 8 of the boundary, 0 beyond diam R / 4 */
    const double d1 = diam_r / 8.0, d2 = diam_r / 4.0;
    for (dk_index v = 0; v < n; v++) {
        if (!isfinite(g[v]) || !(diam_r > 0.0))
            w[v] = 0.0;
        else if (g[v] < d1)
            w[v] = 1.0;
        else if (g[v] > d2)
            w[v] = 0.0;
        else
            w[v] = (d2 - g[v]) / (d2 - d1);
    }
    R->delta3 = diam_out > 0.0 ? diam_r / diam_out : INFINITY;
    return DK_OK;
}

/* What the constraints give; frees what `R` holds */
static void regions_free(eigen_regions *R)
{
    dk_constraints_free(R->user);
    eigen_parts_free(&R->parts);
    dk_constraints_free(R->con);
    free(R->region);
    free(R->g);
    free(R->w);
    free(R->lin);
    free(R->target);
    free(R->utarget);
    free(R->uT);
    free(R->gT);
    memset(R, 0, sizeof *R);
}

/* The caller's constraints as the groups of R (region PART: each handle's part and the
 * handle; HANDLES: the handle groups), their distances and weights, and the request
 * buffers, with every target at rest. On failure `R` is empty. */
static dk_status regions(dk_eigen *e, const dk_constraint_desc *desc, eigen_regions *R,
                         dk_error *err)
{
    const dk_mesh *mesh = e->mesh;
    const dk_index n = e->n;
    memset(R, 0, sizeof *R);
    dk_status st = refuse_unused(desc, err);
    if (st != DK_OK)
        return st;
    const dk_constraint_desc *groups = desc;
    if (e->opt.region == DK_EIGEN_REGION_PART) {
        st = dk_constraints_create(mesh, desc, &R->user, err);
        if (st != DK_OK)
            return dk_error_prefix(err, "EigenDeformation");
        st = eigen_parts_build(mesh, R->user, desc->fixed_vertices, desc->n_fixed, &R->parts,
                               err);
        if (st != DK_OK) {
            regions_free(R);
            return st;
        }
        groups = &R->parts.desc;
    }
    st = dk_constraints_create(mesh, groups, &R->con, err);
    if (st != DK_OK) {
        regions_free(R);
        return dk_error_prefix(err, "EigenDeformation");
    }
    const dk_constraints *c = R->con, *u = R->user;
    R->region = malloc(((size_t)n + 1) * sizeof *R->region);
    R->g = malloc(((size_t)n + 1) * sizeof *R->g);
    R->w = malloc(((size_t)n + 1) * sizeof *R->w);
    R->lin = malloc(9 * ((size_t)c->n_handles + 1) * sizeof *R->lin);
    R->target = malloc(3 * ((size_t)c->n_handle_vertices + 1) * sizeof *R->target);
    if (u) {
        R->utarget = malloc(3 * ((size_t)u->n_handle_vertices + 1) * sizeof *R->utarget);
        R->uT = malloc(16 * ((size_t)u->n_handles + 1) * sizeof *R->uT);
        R->gT = malloc(16 * ((size_t)c->n_handles + 1) * sizeof *R->gT);
    }
    if (!R->region || !R->g || !R->w || !R->lin || !R->target ||
        (u && (!R->utarget || !R->uT || !R->gT))) {
        regions_free(R);
        return oom(err, "regions");
    }
    for (dk_index v = 0; v < n; v++)
        R->region[v] = c->role[v] >= 0 ? c->role[v] : -1;
    st = distances(mesh, R, err);
    if (st != DK_OK) {
        regions_free(R);
        return st;
    }
    for (dk_index i = 0; i < c->n_handle_vertices; i++) /* before any solve: the rest */
        memcpy(R->target + 3 * (size_t)i, mesh->positions + 3 * (size_t)c->handle_vertices[i],
               3 * sizeof(double));
    for (dk_index h = 0; h < c->n_handles; h++)
        for (int k = 0; k < 9; k++)
            R->lin[9 * (size_t)h + k] = k % 4 == 0 ? 1.0 : 0.0;
    return DK_OK;
}

/* section 4.2 */
static int automatic_m(double delta3)
{
    return delta3 >= 0.75 ? 8 : delta3 >= 0.1 ? 50 : 300;
}

/* ------------------------------------------------------------------ bind --------------- */

static void level_free(level *L)
{
    free(L->p);
    free(L->b0);
    free(L->detail);
    free(L->coord);
    free(L->frame_nb);
    memset(L, 0, sizeof *L);
}

void dk_eigen_free(dk_eigen *e)
{
    if (!e)
        return;
    free(e->evals);
    free(e->U);
    free(e->chol);
    level_free(&e->lv[0]);
    level_free(&e->lv[1]);
    regions_free(&e->r);
    free(e->ptil);
    free(e->pstar);
    free(e->normals);
    free(e->b);
    free(e->next);
    free(e->cm);
    free(e);
}

static dk_status level_alloc(level *L, int m, dk_index n)
{
    L->m = m;
    L->p = malloc(3 * (size_t)n * sizeof *L->p);
    L->b0 = malloc(3 * (size_t)m * sizeof *L->b0);
    L->detail = malloc(3 * (size_t)n * sizeof *L->detail);
    L->coord = malloc(3 * (size_t)n * sizeof *L->coord);
    L->frame_nb = malloc((size_t)n * sizeof *L->frame_nb);
    return (L->p && L->b0 && L->detail && L->coord && L->frame_nb) ? DK_OK
                                                                   : DK_ERR_OUT_OF_MEMORY;
}

/* 3. the skeletons of the levels for m (and n'), their details and frames */
static dk_status skeletons(dk_eigen *e, int m, dk_error *err)
{
    const dk_index n = e->n;
    const int two = e->opt.refine > m && e->K > m;
    level_free(&e->lv[0]);
    level_free(&e->lv[1]);
    e->m = m;
    e->n_levels = two ? 2 : 1;
    for (int k = 0; k < e->n_levels; k++)
        if (level_alloc(&e->lv[k], k == 0 ? m : e->K, n) != DK_OK)
            return oom(err, "skeletons");
    for (int k = 0; k < e->n_levels; k++) { /* eq. 1 fitted to the mesh: K_m */
        level *L = &e->lv[k];
        project(e, L->m, e->mesh->positions, e->b);
        fit(e, L->m, e->b, L->p);
        project(e, L->m, L->p, L->b0);
    }
    for (int k = 0; k < e->n_levels; k++) { /* details to the next level, in frames */
        level *L = &e->lv[k];
        const double *next = k + 1 < e->n_levels ? e->lv[k + 1].p : e->mesh->positions;
        for (size_t i = 0; i < 3 * (size_t)n; i++)
            L->detail[i] = next[i] - L->p[i];
        record_frames(e, L, e->normals);
    }
    return DK_OK;
}

static dk_status check_options(const dk_eigen_options *o, dk_index n, dk_error *err)
{
    if (o->laplacian != DK_EIGEN_COTANGENT && o->laplacian != DK_EIGEN_BELKIN_SUN_WANG)
        return dk_error_set(err, DK_ERR_INVALID_ARGUMENT,
                            "EigenDeformation: laplacian must be cotangent (0) or "
                            "belkin_sun_wang (1)");
    if (o->region != DK_EIGEN_REGION_PART && o->region != DK_EIGEN_REGION_HANDLES)
        return dk_error_set(err, DK_ERR_INVALID_ARGUMENT,
                            "EigenDeformation: region must be part (0) or handles (1)");
    if (!(o->bsw_width > 0.0) || !isfinite(o->bsw_width))
        return dk_error_set(err, DK_ERR_INVALID_ARGUMENT,
                            "EigenDeformation: bsw_width must be finite and > 0");
    if (o->n_eigenvectors < 0 || o->n_eigenvectors > n)
        return dk_error_set(err, DK_ERR_INVALID_ARGUMENT,
                            "EigenDeformation: n_eigenvectors is %d; it must be 0 (automatic) "
                            "to %d (the vertex count)", o->n_eigenvectors, (int)n);
    if (o->refine < 0)
        return dk_error_set(err, DK_ERR_INVALID_ARGUMENT,
                            "EigenDeformation: refine is %d; it must be >= 0 (0: one iteration)",
                            o->refine);
    return DK_OK;
}

/* The constant eigenvectors beyond the first: one per further connected component. Each
 * component's constant has eigenvalue 0, so they come first and a small component takes one
 * whatever its size; the automatic count adds them to section 4.2's (the paper's models have
 * one component; a scan with loose pieces would otherwise give the body none of its 8). */
static int extra_constants(const dk_eigen *e)
{
    const dk_index c = e->mesh->report.n_components - e->mesh->report.n_isolated_vertices;
    return c > 1 ? (int)(c - 1) : 0; /* an isolated vertex has no eigenvector of its own */
}

/* The eigenvector count for the regions: the option (at most n), or section 4.2's rule
 * capped at n / 4 (at least 4), plus the components' constants: on a small mesh the rule's
 * 50 or 300 would be most of the spectrum, and a fit with that many no longer smooths the
 * cut of Step 1 (with n of them it reproduces the cut exactly). */
static int choose_m(const dk_eigen *e, double delta3)
{
    if (e->opt.n_eigenvectors > 0)
        return e->opt.n_eigenvectors < e->n ? e->opt.n_eigenvectors : (int)e->n;
    const int rule = automatic_m(delta3), cap = (int)(e->n / 4) > 4 ? (int)(e->n / 4) : 4;
    const int64_t m = (int64_t)(rule < cap ? rule : cap) + extra_constants(e);
    return m < e->n ? (int)m : (int)e->n;
}

dk_status dk_eigen_bind(const dk_mesh *mesh, const dk_constraint_desc *desc,
                        const dk_eigen_options *options, dk_eigen **out, dk_error *err)
{
    if (!out)
        return dk_error_set(err, DK_ERR_INVALID_ARGUMENT, "EigenDeformation: out is NULL");
    *out = NULL;
    if (!mesh || !desc)
        return dk_error_set(err, DK_ERR_INVALID_ARGUMENT,
                            "EigenDeformation: mesh and constraints must not be NULL");
    if (mesh->n_faces == 0 || mesh->n_vertices < 4)
        return dk_error_set(err, DK_ERR_TOPOLOGY,
                            "EigenDeformation: needs a surface (faces and at least 4 vertices); "
                            "this mesh has %d vertices and %d faces", (int)mesh->n_vertices,
                            (int)mesh->n_faces);
    dk_eigen *e = calloc(1, sizeof *e);
    if (!e)
        return oom(err, "object");
    e->mesh = mesh;
    e->n = mesh->n_vertices;
    if (options)
        e->opt = *options;
    else
        dk_eigen_default_options(&e->opt);
    const dk_index n = e->n;
    dk_status st = check_options(&e->opt, n, err);
    if (st != DK_OK) {
        free(e);
        return st;
    }
    e->ptil = malloc(3 * (size_t)n * sizeof *e->ptil);
    e->pstar = malloc(3 * (size_t)n * sizeof *e->pstar);
    e->normals = malloc(3 * (size_t)n * sizeof *e->normals);
    e->next = malloc(3 * (size_t)n * sizeof *e->next);
    e->cm = malloc(3 * (size_t)n * sizeof *e->cm);
    if (!e->ptil || !e->pstar || !e->normals || !e->next || !e->cm) {
        dk_eigen_free(e);
        return oom(err, "buffers");
    }
    e->tiny = frame_threshold(mesh);
    /* 1. the regions; 2. the eigenvectors (K = max(m, n') so that a later rebind, whose
     * automatic m may differ, needs none); 3. the skeletons */
    dk_progress_init(&e->prog, e->opt.progress, e->opt.progress_user, eigen_phases,
                     (int)(sizeof eigen_phases / sizeof eigen_phases[0]), "EigenDeformation");
    st = dk_progress_begin(&e->prog, EIGEN_PHASE_REGIONS, err);
    if (st == DK_OK)
        st = regions(e, desc, &e->r, err);
    if (st == DK_OK) {
        const int m = choose_m(e, e->r.delta3);
        int K = m;
        if (e->opt.refine > K)
            K = e->opt.refine;
        if (e->opt.n_eigenvectors == 0 && K < 300 + extra_constants(e))
            K = 300 + extra_constants(e); /* the automatic rule may ask for 300 */
        e->K = K < n ? K : (int)n;
        e->b = malloc(3 * (size_t)e->K * sizeof *e->b);
        st = e->b ? eigenvectors(e, err) : oom(err, "buffers");
        if (st == DK_OK)
            st = skeletons(e, m, err);
    }
    if (st != DK_OK) {
        dk_eigen_free(e);
        return st;
    }
    dk_progress_done(&e->prog);
    e->opt.progress = NULL; /* the caller's callback is for this bind only */
    e->opt.progress_user = NULL;
    dk_progress_init(&e->prog, NULL, NULL, eigen_phases, 1, "EigenDeformation");
    *out = e;
    return DK_OK;
}

dk_status dk_eigen_rebind(dk_eigen *e, const dk_constraint_desc *desc, dk_error *err)
{
    if (!e || !desc)
        return dk_error_set(err, DK_ERR_INVALID_ARGUMENT,
                            "EigenDeformation rebind: object and constraints must not be NULL");
    eigen_regions R;
    dk_status st = regions(e, desc, &R, err);
    const int m = st == DK_OK ? choose_m(e, R.delta3) : 0;
    if (st == DK_OK && m > e->K)
        st = dk_error_set(err, DK_ERR_INVALID_ARGUMENT,
                          "EigenDeformation rebind: these regions need %d eigenvectors and %d "
                          "were computed at bind: bind again", m, e->K);
    if (st == DK_OK && m != e->m) { /* a new m: new skeletons (the eigenvectors stay) */
        level keep[2] = {e->lv[0], e->lv[1]};
        const int keep_m = e->m, keep_levels = e->n_levels;
        memset(e->lv, 0, sizeof e->lv);
        st = skeletons(e, m, err);
        if (st != DK_OK) {
            level_free(&e->lv[0]);
            level_free(&e->lv[1]);
            e->lv[0] = keep[0];
            e->lv[1] = keep[1];
            e->m = keep_m;
            e->n_levels = keep_levels;
        } else {
            level_free(&keep[0]);
            level_free(&keep[1]);
        }
    }
    if (st != DK_OK) {
        regions_free(&R);
        return st;
    }
    regions_free(&e->r);
    e->r = R;
    return DK_OK;
}

/* ------------------------------------------------------------------ solve -------------- */

/* PART: the handles' transforms from the caller's targets (R->utarget), for the parts they
 * turn: the given transforms, or for positions the affine map that gives them when there is
 * one, else the translation of the handle's centroid. */
static void handle_transforms(const dk_eigen *e, const dk_solve_request *rq)
{
    const eigen_regions *R = &e->r;
    const dk_constraints *u = R->user;
    for (dk_index h = 0; h < u->n_handles; h++) {
        double *T = R->uT + 16 * (size_t)h;
        if (rq->target_kind == DK_TARGETS_TRANSFORMS) {
            memcpy(T, rq->targets + 16 * (size_t)h, 16 * sizeof(double));
            continue;
        }
        const dk_index s = u->handle_start[h], cnt = u->handle_start[h + 1] - s;
        if (dk_affine_fit(e->mesh->positions, u->handle_vertices + s, cnt,
                          R->utarget + 3 * (size_t)s, 1e-9, T))
            continue;
        double d[3] = {0.0, 0.0, 0.0};
        for (dk_index q = s; q < s + cnt; q++)
            for (int r = 0; r < 3; r++)
                d[r] += (R->utarget[3 * (size_t)q + r] -
                         e->mesh->positions[3 * (size_t)u->handle_vertices[q] + r]) /
                        (double)cnt;
        for (int k = 0; k < 16; k++)
            T[k] = k % 5 == 0 ? 1.0 : 0.0;
        for (int r = 0; r < 3; r++)
            T[4 * r + 3] = d[r];
    }
}

/* PART: the groups' targets and linear parts. A handle group takes the caller's targets
 * (and linear part: the transform's, or the identity for positions); a turning part the
 * turn eigen_parts_transforms gives it. */
static void part_targets(eigen_regions *R, const dk_mesh *mesh, int per_vertex)
{
    const eigen_parts *P = &R->parts;
    const dk_constraints *c = R->con, *u = R->user;
    eigen_parts_transforms(P, R->uT, R->gT);
    for (dk_index h = 0; h < u->n_handles; h++) {
        const dk_index f = P->follow[h], t = P->turn[h];
        memcpy(R->target + 3 * (size_t)c->handle_start[f],
               R->utarget + 3 * (size_t)u->handle_start[h],
               3 * (size_t)(u->handle_start[h + 1] - u->handle_start[h]) * sizeof(double));
        for (int r = 0; r < 3; r++)
            for (int q = 0; q < 3; q++)
                R->lin[9 * (size_t)f + 3 * r + q] =
                    per_vertex ? (r == q) : R->uT[16 * (size_t)h + 4 * r + q];
        if (t < 0)
            continue;
        const double *M = R->gT + 16 * (size_t)t;
        for (int r = 0; r < 3; r++)
            for (int q = 0; q < 3; q++)
                R->lin[9 * (size_t)t + 3 * r + q] = M[4 * r + q];
        for (dk_index q = c->handle_start[t]; q < c->handle_start[t + 1]; q++) {
            const double *v = mesh->positions + 3 * (size_t)c->handle_vertices[q];
            for (int r = 0; r < 3; r++)
                R->target[3 * (size_t)q + r] =
                    M[4 * r] * v[0] + M[4 * r + 1] * v[1] + M[4 * r + 2] * v[2] + M[4 * r + 3];
        }
    }
}

/* Reads the request: the Step-1 targets of R's vertices (for the energy), and per group the
 * linear part of its motion (identity for positions) into R->lin. Checked before anything
 * is written: a refused request leaves the last one's targets. */
static dk_status read_request(dk_eigen *e, const dk_solve_request *rq, dk_error *err)
{
    dk_status st = dk_solve_request_check(rq, "EigenDeformation solve", err);
    if (st != DK_OK)
        return st;
    eigen_regions *R = &e->r;
    const int per_vertex = rq->target_kind == DK_TARGETS_POSITIONS;
    if (R->user) {
        st = dk_constraints_targets(R->user, e->mesh->positions, rq->targets,
                                    (int)rq->target_kind, R->utarget, err);
        if (st != DK_OK)
            return dk_error_prefix(err, "EigenDeformation solve");
        handle_transforms(e, rq);
        part_targets(R, e->mesh, per_vertex);
        return DK_OK;
    }
    const dk_constraints *c = R->con;
    st = dk_constraints_targets(c, e->mesh->positions, rq->targets, (int)rq->target_kind,
                                R->target, err);
    if (st != DK_OK)
        return dk_error_prefix(err, "EigenDeformation solve");
    for (dk_index h = 0; h < c->n_handles; h++)
        for (int r = 0; r < 3; r++)
            for (int q = 0; q < 3; q++)
                R->lin[9 * (size_t)h + 3 * r + q] =
                    per_vertex ? (r == q) : rq->targets[16 * (size_t)h + 4 * r + q];
    return DK_OK;
}

/* Step 1 on level L's skeleton into e->ptil, and Step 2's right-hand side from R's rows
 * alone: b = b0 + U_m^T (p~ - p), the change being zero outside R. A vertex v of group h
 * with target t and linear part A moves its skeleton point p to t - A (v - p): for a
 * transform T, T p; for a position (A = I), p + (t - v). */
static void step1_step2_rhs(dk_eigen *e, const level *L)
{
    const dk_constraints *c = e->r.con;
    const dk_index n = e->n;
    memcpy(e->ptil, L->p, 3 * (size_t)n * sizeof(double));
    memcpy(e->b, L->b0, 3 * (size_t)L->m * sizeof(double));
    for (dk_index h = 0; h < c->n_handles; h++)
        for (dk_index q = c->handle_start[h]; q < c->handle_start[h + 1]; q++) {
            const dk_index i = c->handle_vertices[q];
            const double *p = L->p + 3 * (size_t)i, *v = e->mesh->positions + 3 * (size_t)i;
            const double *tg = e->r.target + 3 * (size_t)q, *A = e->r.lin + 9 * (size_t)h;
            double *pt = e->ptil + 3 * (size_t)i;
            for (int r = 0; r < 3; r++)
                pt[r] = tg[r] - (A[3 * r] * (v[0] - p[0]) + A[3 * r + 1] * (v[1] - p[1]) +
                                 A[3 * r + 2] * (v[2] - p[2]));
            for (int r = 0; r < 3; r++) {
                const double dp = pt[r] - p[r];
                if (dp != 0.0)
                    cblas_daxpy(L->m, dp, e->U + i, (int)n, e->b + (size_t)r * L->m, 1);
            }
        }
}

/* Step 3 on level L: out = p* + d~, with d~ the local-frame detail (frames of p*) blended
 * with the transformation-based one by w (blend = 1) or the local-frame one alone. A vertex
 * whose frame is undefined (on the rest or the deformed skeleton) takes the
 * transformation-based detail. */
static void step3(dk_eigen *e, const level *L, const double *pstar, int blend, double *out)
{
    const dk_mesh *mesh = e->mesh;
    vertex_normals(mesh, pstar, e->normals);
    for (dk_index i = 0; i < e->n; i++) {
        const double *d = L->detail + 3 * (size_t)i, *c = L->coord + 3 * (size_t)i;
        const dk_index h = e->r.region[i];
        double d2[3];
        if (h >= 0) { /* the Step-1 transformation's linear part applied to d */
            const double *A = e->r.lin + 9 * (size_t)h;
            for (int r = 0; r < 3; r++)
                d2[r] = A[3 * r] * d[0] + A[3 * r + 1] * d[1] + A[3 * r + 2] * d[2];
        } else {
            memcpy(d2, d, sizeof d2);
        }
        double F[9], d1[3];
        const int ok =
            L->frame_nb[i] >= 0 && frame(pstar, e->normals, i, L->frame_nb[i], e->tiny, F);
        if (ok)
            for (int r = 0; r < 3; r++)
                d1[r] = F[r] * c[0] + F[3 + r] * c[1] + F[6 + r] * c[2];
        double *o = out + 3 * (size_t)i;
        const double *ps = pstar + 3 * (size_t)i;
        if (!ok) {
            for (int r = 0; r < 3; r++)
                o[r] = ps[r] + d2[r];
            continue;
        }
        const double wi = blend ? e->r.w[i] : 1.0;
        if (wi >= 1.0) {
            for (int r = 0; r < 3; r++)
                o[r] = ps[r] + d1[r];
            continue;
        }
        /* section 4.1: interpolate the directions, keep the local-frame length. The paper's
         * formula leaves the blend of two unit vectors unnormalised (shorter where they
         * differ); we renormalise it, as "interpolates their directions" intends */
        const double l1 = sqrt(d1[0] * d1[0] + d1[1] * d1[1] + d1[2] * d1[2]);
        const double l2 = sqrt(d2[0] * d2[0] + d2[1] * d2[1] + d2[2] * d2[2]);
        double dir[3];
        for (int r = 0; r < 3; r++)
            dir[r] = (l1 > 0.0 ? wi * d1[r] / l1 : 0.0) + (l2 > 0.0 ? (1.0 - wi) * d2[r] / l2 : 0.0);
        const double dl = sqrt(dir[0] * dir[0] + dir[1] * dir[1] + dir[2] * dir[2]);
        for (int r = 0; r < 3; r++)
            o[r] = ps[r] + (dl > 1e-12 ? dir[r] / dl * l1 : d1[r]);
    }
}

int dk_eigen_preview(const dk_eigen *e)
{
    return e ? e->preview : 0;
}

void dk_eigen_set_preview(dk_eigen *e, int preview)
{
    if (e)
        e->preview = preview != 0;
}

dk_status dk_eigen_energy(const dk_eigen *e, const double *positions, double *energy,
                          dk_error *err)
{
    if (!e || !positions || !energy)
        return dk_error_set(err, DK_ERR_INVALID_ARGUMENT,
                            "EigenDeformation energy: arguments must not be NULL");
    const dk_constraints *c = e->r.con;
    double E = 0.0;
    /* R's vertices against their targets, the others against the rest */
    for (dk_index i = 0; i < e->n; i++)
        if (c->role[i] < 0)
            for (int r = 0; r < 3; r++) {
                const double d = positions[3 * (size_t)i + r] - e->mesh->positions[3 * (size_t)i + r];
                E += d * d;
            }
    for (dk_index q = 0; q < c->n_handle_vertices; q++) {
        const dk_index i = c->handle_vertices[q];
        for (int r = 0; r < 3; r++) {
            const double d = positions[3 * (size_t)i + r] - e->r.target[3 * (size_t)q + r];
            E += d * d;
        }
    }
    *energy = E;
    return dk_energy_result_check(E, "EigenDeformation energy", err);
}

dk_status dk_eigen_solve(dk_eigen *e, const dk_solve_request *rq, double *positions,
                         dk_solve_info *info, dk_error *err)
{
    if (info)
        memset(info, 0, sizeof *info);
    if (!e || !positions)
        return dk_error_set(err, DK_ERR_INVALID_ARGUMENT,
                            "EigenDeformation solve: object and positions must not be NULL");
    dk_status st = read_request(e, rq, err);
    if (st != DK_OK)
        return st;
    /* Steps 1-2 on the first level */
    const level *L = &e->lv[0];
    step1_step2_rhs(e, L);
    fit(e, L->m, e->b, e->pstar);
    const int preview = rq->preview || e->preview;
    if (preview) { /* the skeleton's motion, details unrotated */
        for (size_t i = 0; i < 3 * (size_t)e->n; i++)
            positions[i] = e->mesh->positions[i] + (e->pstar[i] - L->p[i]);
    } else if (e->n_levels == 1) {
        /* Step 3, interpolation-based (Algorithm 1 with section 4.1) */
        step3(e, L, e->pstar, 1, positions);
    } else {
        /* section 4.3, iteration 1: interpolation-based recovery to K~_n' */
        step3(e, L, e->pstar, 1, e->next);
        /* iteration 2: K~_n' as the coarse target, a re-fit with n' eigenvectors, and
         * local-frame recovery of the mesh */
        const level *L2 = &e->lv[1];
        project(e, L2->m, e->next, e->b);
        fit(e, L2->m, e->b, e->pstar);
        step3(e, L2, e->pstar, 0, positions);
    }
    /* loose vertices (on no face) follow their constraint exactly, held ones stay at rest */
    {
        const dk_constraints *c = e->r.con;
        const dk_mesh *mesh = e->mesh;
        for (dk_index i = 0; i < e->n; i++)
            if (mesh->ring_start[i + 1] == mesh->ring_start[i] && c->role[i] < 0)
                memcpy(positions + 3 * (size_t)i, mesh->positions + 3 * (size_t)i,
                       3 * sizeof(double));
        for (dk_index q = 0; q < c->n_handle_vertices; q++) {
            const dk_index i = c->handle_vertices[q];
            if (mesh->ring_start[i + 1] == mesh->ring_start[i])
                memcpy(positions + 3 * (size_t)i, e->r.target + 3 * (size_t)q,
                       3 * sizeof(double));
        }
        dk_constraints_hold(c, mesh->positions, positions);
    }
    double energy = NAN;
    if (!rq->skip_energy && (st = dk_eigen_energy(e, positions, &energy, err)) != DK_OK &&
        st != DK_ERR_NONFINITE)
        return st;
    st = dk_solve_result_check(positions, e->n, energy, !rq->skip_energy,
                               "EigenDeformation solve", err);
    if (st != DK_OK)
        return st;
    if (info) {
        info->iterations = preview ? 0 : e->n_levels;
        info->converged = 1;
        info->energy = energy;
    }
    return DK_OK;
}

/* ------------------------------------------------------------------ queries ------------ */

const double *dk_eigen_skeleton(const dk_eigen *e)
{
    return e ? e->lv[0].p : NULL;
}

int dk_eigen_m(const dk_eigen *e)
{
    return e ? e->m : 0;
}

int dk_eigen_k(const dk_eigen *e)
{
    return e ? e->K : 0;
}

const double *dk_eigen_eigenvalues(const dk_eigen *e)
{
    return e ? e->evals : NULL;
}

const double *dk_eigen_eigenvectors(const dk_eigen *e)
{
    return e ? e->U : NULL;
}

double dk_eigen_delta3(const dk_eigen *e)
{
    return e ? e->r.delta3 : NAN;
}

const double *dk_eigen_weights(const dk_eigen *e)
{
    return e ? e->r.w : NULL;
}

void dk_eigen_stats(const dk_eigen *e, dk_method_stats *st)
{
    memset(st, 0, sizeof *st);
    if (!e)
        return;
    st->n_vertices = e->n;
    const dk_constraints *c = e->r.user ? e->r.user : e->r.con; /* the caller's */
    st->n_handles = c->n_handles;
    st->n_handle_vertices = c->n_handle_vertices;
    dk_constraints_held_stats(c, NULL, st);
    st->n_unknowns = 3 * e->m;
    st->factorization_count = 1;
}

dk_status dk_eigen_estimate_memory(const dk_mesh *mesh, const dk_eigen_options *o,
                                   uint64_t *bytes, dk_error *err)
{
    if (!mesh || !bytes)
        return dk_error_set(err, DK_ERR_INVALID_ARGUMENT,
                            "EigenDeformation estimate_memory: mesh and bytes must not be NULL");
    dk_status st = o ? check_options(o, mesh->n_vertices, err) : DK_OK; /* what bind refuses */
    if (st != DK_OK)
        return st;
    const double n = (double)mesh->n_vertices, lg = n > 2.0 ? log2(n) : 1.0;
    /* The K basis vectors (n doubles each; the eigensolver builds them in place), the band's
     * Krylov basis of 2 min(K, 50) + 1 vectors and its results of about min(K, 50) more
     * (eigs.c), and the Laplacian's LDL' factor (the log term). K is the larger of the
     * requested m (automatic: up to 300 plus a constant per further component) and the
     * refinement n'. Measured (2026-12-02): 4600 /
     * 4700 B/vertex for K = 300 at 62k / 248k vertices, 2660 for K = 50 at 62k. */
    const dk_index surfaces = mesh->report.n_components - mesh->report.n_isolated_vertices;
    const double constants = surfaces > 1 ? (double)(surfaces - 1) : 0.0;
    double k = o && o->n_eigenvectors > 0 ? o->n_eigenvectors : 300.0 + constants;
    const double refine = o ? o->refine : 300.0;
    if (refine > k)
        k = refine;
    if (k > n)
        k = n;
    double per_vertex = 350.0 + 40.0 * lg + 8.0 * k + 26.0 * (k < 50.0 ? k : 50.0);
    if (n <= 600.0 || k > n / 4.0) /* the dense path: the n x n matrix, dsyevd's workspace of
                                      2 n^2 + 6n + 1 more */
        per_vertex += 24.0 * n;
    *bytes = dk_memory_model(per_vertex, n, 0.0);
    return DK_OK;
}

DK_METHOD_OPS(dk_eigen_ops, "EigenDeformation", DK_METHOD_SOFT_REGIONS, dk_eigen, dk_eigen,
              dk_eigen_options);
