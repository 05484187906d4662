/* DeformKit: geodesic distance by the heat method (Crane, Weischedel, Wardetzky 2013).
 *
 * Create (once per mesh):
 *   t = time_factor * h^2, h = mean edge length; M = barycentric lumped mass; L = cotangent
 *   Laplacian (PSD sign, see dk_operators.h).
 *   Heat operator M + tL, factored on all vertices (Neumann); on a mesh with a boundary also
 *   restricted to the interior vertices with u = 0 on the boundary (Dirichlet).
 *   Poisson operator L, made definite by pinning one vertex per "area component" (vertices
 *   joined through triangles with area; this refines the mesh's components where two parts
 *   touch only through degenerate triangles, on which L is block diagonal) with phi = 0
 *   there, its row and column dropped. The pinned system is exact: the solution differs
 *   from any other solution of L phi = b only by a constant per area component, and the
 *   per-area-component shift below removes that constant.
 * Each dk_heat_distance call is then two or three back-substitutions plus O(faces) work:
 *   1. (M + tL) u = delta_sources (Neumann; averaged with the Dirichlet solution when the
 *      mesh has a boundary, as the paper recommends);
 *   2. per face X = -grad u / |grad u| (X = 0 where grad u vanishes);
 *   3. integrated divergence at vertex i: 1/2 sum over its corners of
 *      cot(theta_1) (e_1 . X) + cot(theta_2) (e_2 . X), e_1, e_2 the edges leaving i and
 *      theta_1, theta_2 the angles opposite them;
 *   4. L phi = -div (L = -Delta here), then phi - min over the sources, per area component.
 * Vertices carrying no area (isolated, or only on triangles below the degenerate-area rule)
 * are decoupled from both systems. They, and area components without a source, get the
 * smallest (neighbour distance + edge length) over their neighbours, propagated along
 * edges from the vertices the heat method reached, or INFINITY when none is reached (so a
 * mesh component without a source is INFINITY everywhere).
 *
 * The object keeps a pointer to the mesh: the mesh must outlive it (meshes are immutable).
 * Calls on one object must not run concurrently (the factor objects hold solve workspace).
 */
#include <math.h>
#include <stdlib.h>
#include <string.h>

#include "dk_cholesky.h"
#include "dk_operators.h"

struct dk_heat_geodesic {
    const dk_mesh *mesh;
    dk_index n;
    double t;
    double *mass;          /* n                                                  */
    double *cot;           /* 3 per face: cotangent at each corner (0: degenerate) */
    double *grad;          /* 9 per face: (N x e_k) / (2A), 0 for degenerate faces */
    unsigned char *active; /* n: vertex carries area                              */
    dk_index *acomp;       /* n: area component of active vertices, -1 otherwise  */
    dk_index n_acomp;
    dk_index *relax;       /* n: vertices to relax in a call                      */
    dk_cholesky *heat_n;   /* M + tL on active vertices                           */
    dk_cholesky *heat_d;   /* M + tL on active interior vertices, or NULL         */
    dk_cholesky *poisson;  /* L on active vertices minus one pin per component    */
    dk_index *map_n, *map_d, *map_p; /* vertex -> row in each system, or -1       */
    dk_index size_n, size_d, size_p;
    double *work;          /* 4 n                                                 */
    double *xf;            /* 3 per face: X                                       */
};

void dk_heat_free(dk_heat_geodesic *heat)
{
    if (!heat) return;
    free(heat->mass);
    free(heat->cot);
    free(heat->grad);
    free(heat->active);
    free(heat->acomp);
    free(heat->relax);
    dk_cholesky_free(heat->heat_n);
    dk_cholesky_free(heat->heat_d);
    dk_cholesky_free(heat->poisson);
    free(heat->map_n);
    free(heat->map_d);
    free(heat->map_p);
    free(heat->work);
    free(heat->xf);
    free(heat);
}

/* CSC of (diag(dadd) + s L) on the vertices with map[v] >= 0 (map increasing in v, so the
 * one-ring order stays sorted). The diagonal keeps the weights to dropped neighbours
 * (elimination of Dirichlet / pinned values 0). */
static dk_status build_restricted(const dk_mesh *mesh, const double *w, const double *dadd,
                                  double s, const dk_index *map, dk_index m, dk_sparse **out,
                                  dk_error *err)
{
    int64_t nnz = 0;
    for (dk_index v = 0; v < mesh->n_vertices; v++) {
        if (map[v] < 0) continue;
        nnz++;
        for (dk_index r = mesh->ring_start[v]; r < mesh->ring_start[v + 1]; r++)
            if (map[mesh->ring_index[r]] >= 0) nnz++;
    }
    dk_sparse *a = NULL;
    dk_status st = dk_sparse_alloc(m, m, nnz, &a, err);
    if (st != DK_OK) return st;
    int64_t pos = 0;
    for (dk_index v = 0; v < mesh->n_vertices; v++) {
        if (map[v] < 0) continue;
        a->col_start[map[v]] = (dk_index)pos;
        double diag = dadd ? dadd[v] : 0.0;
        int64_t dpos = -1;
        for (dk_index r = mesh->ring_start[v]; r < mesh->ring_start[v + 1]; r++) {
            dk_index j = mesh->ring_index[r];
            double wj = w[mesh->ring_edge[r]];
            diag += s * wj;
            if (map[j] < 0) continue;
            if (dpos < 0 && j > v) {
                dpos = pos;
                a->row_index[pos++] = map[v];
            }
            a->row_index[pos] = map[j];
            a->values[pos++] = -s * wj;
        }
        if (dpos < 0) {
            dpos = pos;
            a->row_index[pos++] = map[v];
        }
        a->values[dpos] = diag;
    }
    a->col_start[m] = (dk_index)pos;
    *out = a;
    return DK_OK;
}

static dk_status factor(const dk_mesh *mesh, const double *w, const double *dadd, double s,
                        const dk_index *map, dk_index m, dk_cholesky **out, const char *what,
                        dk_error *err)
{
    dk_sparse *a = NULL;
    dk_status st = build_restricted(mesh, w, dadd, s, map, m, &a, err);
    if (st == DK_OK) st = dk_cholesky_analyze(a, out, err);
    if (st == DK_OK) st = dk_cholesky_factorize(*out, a, err);
    dk_sparse_free(a);
    if (st != DK_OK) dk_error_prefix(err, "heat method: %s", what);
    return st;
}

/* Per-face cotangents and gradient basis at the rest positions. */
static void face_geometry(const dk_mesh *mesh, double *cot, double *grad)
{
    const double *x = mesh->positions;
    for (dk_index f = 0; f < mesh->n_faces; f++) {
        const dk_index *tri = mesh->faces + 3 * f;
        double e[3][3], len2[3];
        for (int k = 0; k < 3; k++) {
            const double *a = x + 3 * tri[(k + 1) % 3], *b = x + 3 * tri[(k + 2) % 3];
            for (int d = 0; d < 3; d++) e[k][d] = b[d] - a[d];
            len2[k] = e[k][0] * e[k][0] + e[k][1] * e[k][1] + e[k][2] * e[k][2];
        }
        double nrm[3] = {e[0][1] * e[1][2] - e[0][2] * e[1][1],
                         e[0][2] * e[1][0] - e[0][0] * e[1][2],
                         e[0][0] * e[1][1] - e[0][1] * e[1][0]};
        double twice_area = sqrt(nrm[0] * nrm[0] + nrm[1] * nrm[1] + nrm[2] * nrm[2]);
        double longest = fmax(len2[0], fmax(len2[1], len2[2]));
        if (dk_triangle_degenerate(x + 3 * tri[0], x + 3 * tri[1], x + 3 * tri[2], twice_area,
                                   longest)) {
            for (int k = 0; k < 3; k++) cot[3 * f + k] = 0.0;
            for (int k = 0; k < 9; k++) grad[9 * f + k] = 0.0;
            continue;
        }
        for (int d = 0; d < 3; d++) nrm[d] /= twice_area; /* unit normal */
        for (int k = 0; k < 3; k++) {
            const double *u = e[(k + 2) % 3], *v = e[(k + 1) % 3];
            cot[3 * f + k] = -(u[0] * v[0] + u[1] * v[1] + u[2] * v[2]) / twice_area;
            /* grad of the hat function of corner k: (N x e_k) / (2A) */
            double *g = grad + 9 * f + 3 * k;
            g[0] = (nrm[1] * e[k][2] - nrm[2] * e[k][1]) / twice_area;
            g[1] = (nrm[2] * e[k][0] - nrm[0] * e[k][2]) / twice_area;
            g[2] = (nrm[0] * e[k][1] - nrm[1] * e[k][0]) / twice_area;
        }
    }
}

dk_status dk_heat_create(const dk_mesh *mesh, double time_factor, dk_heat_geodesic **out,
                         dk_error *err)
{
    if (!out) return dk_error_set(err, DK_ERR_INVALID_ARGUMENT, "heat method: out is NULL");
    *out = NULL;
    if (!mesh) return dk_error_set(err, DK_ERR_INVALID_ARGUMENT, "heat method: mesh is NULL");
    if (!isfinite(time_factor))
        return dk_error_set(err, DK_ERR_NONFINITE, "heat method: time factor is %g", time_factor);
    if (mesh->n_vertices < 1)
        return dk_error_set(err, DK_ERR_INVALID_ARGUMENT, "heat method: the mesh has no vertices");
    dk_index n = mesh->n_vertices, nf = mesh->n_faces, ne = mesh->n_edges;
    dk_heat_geodesic *h = calloc(1, sizeof *h);
    if (!h) return dk_error_set(err, DK_ERR_OUT_OF_MEMORY, "heat method: out of memory");
    h->mesh = mesh;
    h->n = n;
    double hbar = mesh->mean_edge_length;
    h->t = (time_factor > 0 ? time_factor : 1.0) * hbar * hbar;
    size_t nfs = (size_t)(nf > 0 ? nf : 1);
    h->mass = malloc((size_t)n * sizeof *h->mass);
    h->cot = malloc(3 * nfs * sizeof *h->cot);
    h->grad = malloc(9 * nfs * sizeof *h->grad);
    h->xf = malloc(3 * nfs * sizeof *h->xf);
    h->active = malloc((size_t)n);
    h->map_n = malloc((size_t)n * sizeof *h->map_n);
    h->map_d = malloc((size_t)n * sizeof *h->map_d);
    h->map_p = malloc((size_t)n * sizeof *h->map_p);
    h->work = malloc(4 * (size_t)n * sizeof *h->work);
    double *w = malloc((size_t)(ne > 0 ? ne : 1) * sizeof *w);
    unsigned char *pinned = calloc((size_t)n, 1);
    h->acomp = malloc((size_t)n * sizeof *h->acomp);
    h->relax = malloc((size_t)n * sizeof *h->relax);
    dk_status st = DK_OK;
    if (!h->mass || !h->cot || !h->grad || !h->xf || !h->active || !h->map_n || !h->map_d ||
        !h->map_p || !h->work || !w || !pinned || !h->acomp || !h->relax) {
        st = dk_error_set(err, DK_ERR_OUT_OF_MEMORY, "heat method: out of memory (%d vertices)",
                          (int)n);
        goto done;
    }
    st = dk_mass_matrix(mesh, DK_MASS_BARYCENTRIC, h->mass, err);
    if (st != DK_OK) goto done;
    dk_cotangent_weights(mesh, mesh->positions, w);
    face_geometry(mesh, h->cot, h->grad);

    /* area components: union-find over the vertices of triangles with area (acomp is the
     * parent array here, then relabelled 0 .. n_acomp - 1) */
    for (dk_index v = 0; v < n; v++) h->acomp[v] = v;
    for (dk_index f = 0; f < nf; f++) {
        const double *g = h->grad + 9 * f;
        if (g[0] == 0.0 && g[1] == 0.0 && g[2] == 0.0 && g[3] == 0.0 && g[4] == 0.0 &&
            g[5] == 0.0)
            continue; /* degenerate */
        dk_index r[3];
        for (int k = 0; k < 3; k++) {
            dk_index x = mesh->faces[3 * f + k];
            while (h->acomp[x] != x) x = h->acomp[x] = h->acomp[h->acomp[x]];
            r[k] = x;
        }
        h->acomp[r[1]] = r[0];
        h->acomp[r[2]] = r[0];
    }
    /* labels: root of every vertex into map_p (scratch), label per root into relax */
    for (dk_index v = 0; v < n; v++) {
        dk_index x = v;
        while (h->acomp[x] != x) x = h->acomp[x];
        h->map_p[v] = x;
        h->relax[v] = -1;
    }
    h->n_acomp = 0;
    for (dk_index v = 0; v < n; v++) {
        dk_index root = h->map_p[v];
        if (!(h->mass[v] > 0.0)) continue;
        if (h->relax[root] < 0) h->relax[root] = h->n_acomp++;
    }
    for (dk_index v = 0; v < n; v++)
        h->acomp[v] = h->mass[v] > 0.0 ? h->relax[h->map_p[v]] : -1;

    h->size_n = h->size_d = h->size_p = 0;
    for (dk_index v = 0; v < n; v++) {
        h->active[v] = h->mass[v] > 0.0;
        h->map_n[v] = h->map_d[v] = h->map_p[v] = -1;
        if (!h->active[v]) continue;
        h->map_n[v] = h->size_n++;
        if (!mesh->is_boundary_vertex[v]) h->map_d[v] = h->size_d++;
        dk_index c = h->acomp[v];
        if (!pinned[c]) pinned[c] = 1;
        else h->map_p[v] = h->size_p++;
    }
    if (h->size_n == 0) goto done; /* no area anywhere: distances come from the fallback */
    st = factor(mesh, w, h->mass, h->t, h->map_n, h->size_n, &h->heat_n, "heat operator M + tL",
                err);
    if (st != DK_OK) goto done;
    if (mesh->report.n_boundary_edges > 0 && h->size_d > 0) {
        st = factor(mesh, w, h->mass, h->t, h->map_d, h->size_d, &h->heat_d,
                    "Dirichlet heat operator M + tL", err);
        if (st != DK_OK) goto done;
    }
    if (h->size_p > 0) {
        st = factor(mesh, w, NULL, 1.0, h->map_p, h->size_p, &h->poisson,
                    "Poisson operator L (one vertex pinned per area component)", err);
        if (st != DK_OK) goto done;
    }
done:
    free(w);
    free(pinned);
    if (st != DK_OK) {
        dk_heat_free(h);
        return st;
    }
    *out = h;
    return DK_OK;
}

/* Solves the system behind `chol` for the vertices in `map` with rhs[v] given per vertex;
 * writes the solution per vertex into `sol` (0 where map < 0). `buf` has 2 * n entries. */
static dk_status solve_mapped(dk_cholesky *chol, const dk_index *map, dk_index n,
                              const double *rhs, double *sol, double *buf, dk_error *err)
{
    dk_index m = dk_cholesky_size(chol);
    double *b = buf, *x = buf + n;
    for (dk_index v = 0; v < n; v++)
        if (map[v] >= 0) b[map[v]] = rhs[v];
    dk_status st = dk_cholesky_solve(chol, b, 1, x, err);
    if (st != DK_OK) return st;
    (void)m;
    for (dk_index v = 0; v < n; v++) sol[v] = map[v] >= 0 ? x[map[v]] : 0.0;
    return DK_OK;
}

dk_status dk_heat_distance(dk_heat_geodesic *heat, const dk_index *sources, dk_index n_sources,
                           double *distance, dk_error *err)
{
    if (!heat) return dk_error_set(err, DK_ERR_INVALID_ARGUMENT, "heat distance: heat is NULL");
    if (!distance)
        return dk_error_set(err, DK_ERR_INVALID_ARGUMENT, "heat distance: distance is NULL");
    if (n_sources < 0 || (n_sources > 0 && !sources))
        return dk_error_set(err, DK_ERR_INVALID_ARGUMENT,
                            "heat distance: bad source list (%d sources%s)", (int)n_sources,
                            sources ? "" : ", NULL pointer");
    const dk_mesh *mesh = heat->mesh;
    dk_status st = dk_check_indices(sources, n_sources, mesh->n_vertices, "source", err);
    if (st != DK_OK) {
        dk_error_prefix(err, "heat distance");
        return st;
    }
    dk_index n = heat->n;
    double *u = heat->work, *tmp = heat->work + n, *buf = heat->work + 2 * n;
    const double *x = mesh->positions;

    if (heat->heat_n) {
        /* 1. heat flow from the sources */
        for (dk_index v = 0; v < n; v++) tmp[v] = 0.0;
        for (dk_index s = 0; s < n_sources; s++) tmp[sources[s]] = 1.0;
        st = solve_mapped(heat->heat_n, heat->map_n, n, tmp, u, buf, err);
        if (st == DK_OK && heat->heat_d) {
            /* Dirichlet solution into distance[] (used as scratch), then the average */
            st = solve_mapped(heat->heat_d, heat->map_d, n, tmp, distance, buf, err);
            for (dk_index v = 0; v < n && st == DK_OK; v++) u[v] = 0.5 * (u[v] + distance[v]);
        }
        if (st != DK_OK) {
            dk_error_prefix(err, "heat distance: heat step");
            return st;
        }
        /* 2. normalised negative gradient per face */
        for (dk_index f = 0; f < mesh->n_faces; f++) {
            const dk_index *tri = mesh->faces + 3 * f;
            const double *g = heat->grad + 9 * f;
            double gx = 0, gy = 0, gz = 0;
            for (int k = 0; k < 3; k++) {
                double uk = u[tri[k]];
                gx += uk * g[3 * k], gy += uk * g[3 * k + 1], gz += uk * g[3 * k + 2];
            }
            double len = sqrt(gx * gx + gy * gy + gz * gz);
            double *xv = heat->xf + 3 * f;
            if (len > 0 && isfinite(len)) xv[0] = -gx / len, xv[1] = -gy / len, xv[2] = -gz / len;
            else xv[0] = xv[1] = xv[2] = 0.0;
        }
        /* 3. integrated divergence (tmp) */
        for (dk_index v = 0; v < n; v++) tmp[v] = 0.0;
        for (dk_index f = 0; f < mesh->n_faces; f++) {
            const dk_index *tri = mesh->faces + 3 * f;
            const double *xv = heat->xf + 3 * f, *c = heat->cot + 3 * f;
            for (int k = 0; k < 3; k++) {
                int k1 = (k + 1) % 3, k2 = (k + 2) % 3;
                const double *p = x + 3 * tri[k], *p1 = x + 3 * tri[k1], *p2 = x + 3 * tri[k2];
                double d1 = (p1[0] - p[0]) * xv[0] + (p1[1] - p[1]) * xv[1] + (p1[2] - p[2]) * xv[2];
                double d2 = (p2[0] - p[0]) * xv[0] + (p2[1] - p[1]) * xv[1] + (p2[2] - p[2]) * xv[2];
                /* edge k -> k1 is opposite corner k2, edge k -> k2 opposite corner k1 */
                tmp[tri[k]] += 0.5 * (c[k2] * d1 + c[k1] * d2);
            }
        }
        /* 4. L phi = -div with one pinned vertex per component (phi = 0 there) */
        for (dk_index v = 0; v < n; v++) tmp[v] = -tmp[v];
        if (heat->poisson) {
            st = solve_mapped(heat->poisson, heat->map_p, n, tmp, distance, buf, err);
            if (st != DK_OK) {
                dk_error_prefix(err, "heat distance: Poisson step");
                return st;
            }
        } else {
            for (dk_index v = 0; v < n; v++) distance[v] = 0.0;
        }
    } else {
        for (dk_index v = 0; v < n; v++) distance[v] = 0.0;
    }

    /* 5. shift per area component: min over its sources */
    double *shift = buf; /* n_acomp <= n entries */
    for (dk_index c = 0; c < heat->n_acomp; c++) shift[c] = INFINITY;
    for (dk_index s = 0; s < n_sources; s++) {
        dk_index c = heat->acomp[sources[s]];
        if (c >= 0 && distance[sources[s]] < shift[c]) shift[c] = distance[sources[s]];
    }
    dk_index n_relax = 0;
    for (dk_index v = 0; v < n; v++) {
        dk_index c = heat->acomp[v];
        if (c >= 0 && shift[c] < INFINITY) {
            distance[v] -= shift[c];
        } else {
            distance[v] = INFINITY;
            heat->relax[n_relax++] = v;
        }
    }
    /* Sources the heat method did not cover (no area) are at 0; then the rest is relaxed
     * along edges from what was reached (Bellman-Ford sweeps over these vertices only). */
    for (dk_index s = 0; s < n_sources; s++)
        if (heat->acomp[sources[s]] < 0) distance[sources[s]] = 0.0;
    for (int changed = n_relax > 0; changed;) {
        changed = 0;
        for (dk_index i = 0; i < n_relax; i++) {
            dk_index v = heat->relax[i];
            for (dk_index r = mesh->ring_start[v]; r < mesh->ring_start[v + 1]; r++) {
                dk_index j = mesh->ring_index[r];
                if (!(distance[j] < INFINITY)) continue;
                double dx = x[3 * j] - x[3 * v], dy = x[3 * j + 1] - x[3 * v + 1],
                       dz = x[3 * j + 2] - x[3 * v + 2];
                double nd = distance[j] + sqrt(dx * dx + dy * dy + dz * dz);
                if (nd < distance[v]) {
                    distance[v] = nd;
                    changed = 1;
                }
            }
        }
    }
    return DK_OK;
}

int dk_heat_factorization_count(const dk_heat_geodesic *heat)
{
    if (!heat) return 0;
    int c = 0;
    if (heat->heat_n) c += dk_cholesky_factorization_count(heat->heat_n);
    if (heat->heat_d) c += dk_cholesky_factorization_count(heat->heat_d);
    if (heat->poisson) c += dk_cholesky_factorization_count(heat->poisson);
    return c;
}
