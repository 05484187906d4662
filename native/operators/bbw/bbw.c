/* DeformKit: bounded biharmonic weights, the driver (dk_bounded_biharmonic_weights in
 * dk_bbw.h). Its steps: the domain (volume or surface, with the handles held on it), the
 * operator (the bilaplacian K M^-1 K and its block over the free vertices), the weights
 * (the equality-constrained solution of every handle with one factorization, then each
 * handle's bounded quadratic program from there, two handles at a time while the factors
 * are small), and the result (parts no handle reaches, the division by the sum, the mesh's
 * vertices read from the domain).
 *
 * Tried and taken out: seeding the active sets from the weights of a coarser volume (half
 * and a quarter of the resolution). On the armadillo with 10 handles it cut the active-set
 * iterations by 0-15% and cost more in building the coarse domains than it saved (points
 * 6.4 s against 5.4 s, bones 8.4 s against 6.0 s): the active regions' boundaries of the
 * coarse weights are not where the fine ones settle, and the method still moves them about
 * a ring of vertices per iteration. */
#include <math.h>
#include <stdatomic.h>
#include <stdlib.h>
#include <string.h>

#include "bbw_internal.h"
#include "dk_cholesky.h"
#include "dk_operators.h"
#include "dk_parallel.h"

static const char who[] = "bounded biharmonic weights";

void dk_bbw_default_options(dk_bbw_options *o)
{
    memset(o, 0, sizeof *o);
    o->domain = DK_BBW_AUTO;
    o->resolution = 24;
    o->max_iterations = 200;
}

dk_index dk_bbw_handle_count(const dk_bbw_handles *h)
{
    return h ? h->n_points + h->n_bones + h->n_cage_vertices : 0;
}

static dk_status check_finite(const double *v, size_t n, const char *what, dk_error *err)
{
    for (size_t i = 0; i < n; i++)
        if (!isfinite(v[i]) || fabs(v[i]) > DK_COORD_MAX)
            return dk_error_set(err, DK_ERR_NONFINITE, "%s: %s entry %zu is not a finite "
                                "coordinate", who, what, i);
    return DK_OK;
}

static dk_status check_input(const dk_mesh *mesh, const dk_bbw_handles *h,
                             const dk_bbw_options *o, const double *weights, dk_error *err)
{
    if (!mesh || !h || !weights)
        return dk_error_set(err, DK_ERR_INVALID_ARGUMENT, "%s: mesh, handles and weights must "
                            "not be NULL", who);
    if (h->n_points < 0 || h->n_bones < 0 || h->n_cage_vertices < 0 || h->n_cage_triangles < 0 ||
        (h->n_points && !h->points) || (h->n_bones && !h->bones) ||
        (h->n_cage_vertices && !h->cage_vertices) || (h->n_cage_triangles && !h->cage_triangles))
        return dk_error_set(err, DK_ERR_INVALID_ARGUMENT, "%s: a handle count is negative or "
                            "its array is missing", who);
    if (dk_bbw_handle_count(h) < 1)
        return dk_error_set(err, DK_ERR_INVALID_ARGUMENT, "%s: needs at least one handle", who);
    if ((h->n_cage_triangles > 0) != (h->n_cage_vertices > 0))
        return dk_error_set(err, DK_ERR_INVALID_ARGUMENT, "%s: a cage needs both vertices and "
                            "triangles", who);
    if (mesh->n_vertices < 1)
        return dk_error_set(err, DK_ERR_INVALID_ARGUMENT, "%s: the mesh has no vertices", who);
    if (o->domain < DK_BBW_AUTO || o->domain > DK_BBW_SURFACE || o->resolution < 4 ||
        o->resolution > 256 || o->max_iterations < 1)
        return dk_error_set(err, DK_ERR_INVALID_ARGUMENT, "%s: options out of range (domain "
                            "%d, resolution %d in [4, 256], max_iterations %d >= 1)", who,
                            (int)o->domain, o->resolution, o->max_iterations);
    dk_status st = check_finite(h->points, 3 * (size_t)h->n_points, "points", err);
    if (st == DK_OK) st = check_finite(h->bones, 6 * (size_t)h->n_bones, "bones", err);
    if (st == DK_OK)
        st = check_finite(h->cage_vertices, 3 * (size_t)h->n_cage_vertices, "cage vertices", err);
    if (st == DK_OK)
        st = dk_check_indices(h->cage_triangles, 3 * (int64_t)h->n_cage_triangles,
                              h->n_cage_vertices, "cage triangles", err);
    return st;
}

/* The handles' quadratic programs, two at a time. */
typedef struct qp_pass {
    const dk_sparse *a;
    const double *b;       /* nu x nh, column-major */
    double *x;             /* nu x nh: starts in, weights out */
    dk_index nu, nh;
    int max_iterations;
    int start_solves;      /* x holds the equality-constrained solutions */
    int simplicial;        /* small factors: simplicial, two handles at a time */
    int *iterations;       /* nh */
    double *kkt;           /* nh */
    dk_status status[2];
    dk_error error[2];
    atomic_int stop;
    atomic_int done;
    dk_progress *prog;
} qp_pass;

static void qp_range(void *ctx, dk_index begin, dk_index end, int part)
{
    qp_pass *p = (qp_pass *)ctx;
    p->status[part] = DK_OK;
    for (dk_index j = begin; j < end && p->status[part] == DK_OK; j++) {
        if (atomic_load(&p->stop)) return;
        size_t off = (size_t)p->nu * (size_t)j;
        p->status[part] = bbw_box_qp(p->a, p->b + off, 0.0, 1.0, p->x + off, p->start_solves,
                                     p->simplicial, p->max_iterations, &p->iterations[j], &p->kkt[j],
                                     &p->error[part]);
        int done = atomic_fetch_add(&p->done, 1) + 1;
        if (p->status[part] != DK_OK) atomic_store(&p->stop, 1);
        else if (part == 0 &&
                 dk_progress_part(p->prog, (double)done / (double)p->nh, &p->error[0]) != DK_OK) {
            p->status[0] = DK_ERR_CANCELLED;
            atomic_store(&p->stop, 1);
        }
    }
}

/* Labels the connected parts of the pattern of `a` (n x n); returns the count. */
static dk_index label_parts(const dk_sparse *a, dk_index *label, dk_index *queue)
{
    dk_index n = a->n_rows, parts = 0;
    for (dk_index i = 0; i < n; i++) label[i] = -1;
    for (dk_index s = 0; s < n; s++) {
        if (label[s] >= 0) continue;
        dk_index head = 0, tail = 0;
        label[s] = parts;
        queue[tail++] = s;
        while (head < tail) {
            dk_index v = queue[head++];
            for (dk_index p = a->col_start[v]; p < a->col_start[v + 1]; p++)
                if (label[a->row_index[p]] < 0 && a->values[p] != 0.0) {
                    label[a->row_index[p]] = parts;
                    queue[tail++] = a->row_index[p];
                }
        }
        parts++;
    }
    return parts;
}

static const dk_progress_phase phases[] = {{"domain", 3.0}, {"operator", 1.0}, {"weights", 6.0}};

/* Every handle's weights on the domain `d`, undivided: `raw` (d->n x nh, row-major). The
 * active sets start from the equality-constrained solutions (one factorization for all
 * handles). Vertices in parts without a held vertex copy their nearest reached vertex.
 * `prog` gets the "operator" and "weights" phases. */
static dk_status solve_on(const bbw_domain *d, dk_index nh, const dk_bbw_options *o,
                          double *raw, dk_bbw_report *rep, dk_progress *prog, dk_error *err)
{
    const dk_index n = d->n;
    dk_sparse *A = NULL, *Auu = NULL;
    dk_cholesky *chol = NULL;
    dk_kdtree *tree = NULL;
    double *minv = NULL, *B = NULL, *X = NULL, *reached_pos = NULL, *kkt = NULL;
    dk_index *label = NULL, *queue = NULL, *umap = NULL, *reached_ids = NULL;
    unsigned char *held_part = NULL, *is_held = NULL;
    int *iters = NULL;
    qp_pass *pass = NULL;
    dk_status st = dk_progress_begin(prog, 1, err);
    if (st != DK_OK) return st;

    /* the operator: A = K M^-1 K; the free vertices are those neither held nor in a part
     * without a held vertex (there A would be singular) */
    minv = malloc(((size_t)n + 1) * sizeof *minv);
    label = malloc(((size_t)n + 1) * sizeof *label);
    queue = malloc(((size_t)n + 1) * sizeof *queue);
    umap = malloc(((size_t)n + 1) * sizeof *umap);
    is_held = calloc((size_t)n + 1, 1);
    if (!minv || !label || !queue || !umap || !is_held) goto oom;
    double mean_mass = 0.0;
    for (dk_index i = 0; i < n; i++) mean_mass += d->mass[i] / (double)n;
    for (dk_index i = 0; i < n; i++)
        minv[i] = 1.0 / fmax(d->mass[i], 1e-12 * (mean_mass > 0.0 ? mean_mass : 1.0));
    st = dk_sparse_product(d->stiffness, minv, d->stiffness, &A, err);
    if (st != DK_OK) goto done;
    dk_index parts = label_parts(d->stiffness, label, queue);
    held_part = calloc((size_t)parts + 1, 1);
    if (!held_part) goto oom;
    for (dk_index k = 0; k < d->n_held; k++) {
        is_held[d->held[k]] = 1;
        held_part[label[d->held[k]]] = 1;
    }
    dk_index nu = 0, unreached = 0;
    for (dk_index i = 0; i < n; i++) {
        umap[i] = -1;
        if (is_held[i]) continue;
        if (!held_part[label[i]]) {
            unreached++;
            continue;
        }
        umap[i] = nu++;
    }
    rep->unreached = unreached;
    B = calloc((size_t)nu * (size_t)nh + 1, sizeof *B);
    X = malloc(((size_t)nu * (size_t)nh + 1) * sizeof *X);
    if (!B || !X) goto oom;
    memset(raw, 0, (size_t)n * (size_t)nh * sizeof *raw);
    for (dk_index k = 0; k < d->n_held; k++) {
        const bbw_sample *s = &d->samples[d->held_sample[k]];
        dk_index c = d->held[k];
        for (int q = 0; q < BBW_SAMPLE_HANDLES; q++)
            if (s->handle[q] >= 0) raw[(size_t)c * (size_t)nh + (size_t)s->handle[q]] = s->weight[q];
        for (dk_index p = A->col_start[c]; p < A->col_start[c + 1]; p++) {
            dk_index i = umap[A->row_index[p]];
            if (i < 0) continue;
            for (int q = 0; q < BBW_SAMPLE_HANDLES; q++)
                if (s->handle[q] >= 0)
                    B[(size_t)nu * (size_t)s->handle[q] + (size_t)i] -= A->values[p] * s->weight[q];
        }
    }

    /* the weights: each handle's bounded program from its start */
    st = dk_progress_begin(prog, 2, err);
    if (st != DK_OK) goto done;
    iters = calloc((size_t)nh, sizeof *iters);
    kkt = calloc((size_t)nh, sizeof *kkt);
    pass = calloc(1, sizeof *pass);
    if (!iters || !kkt || !pass) goto oom;
    if (nu > 0) {
        st = dk_sparse_submatrix(A, umap, nu, umap, nu, &Auu, err);
        if (st != DK_OK) goto done;
        /* small systems (sparse factors) factor without BLAS, two handles at a time; big
         * ones (dense fronts: a fine volume) one handle at a time with the BLAS on both
         * cores: simplicial factors of those are many times slower */
        st = dk_cholesky_analyze(Auu, &chol, err);
        if (st != DK_OK) goto done;
        const int simplicial = !dk_cholesky_is_supernodal(chol);
        st = dk_cholesky_factorize(chol, Auu, err);
        if (st == DK_OK) st = dk_cholesky_solve(chol, B, (int)nh, X, err);
        dk_cholesky_free(chol);
        chol = NULL;
        if (st != DK_OK) goto done;
        pass->a = Auu;
        pass->b = B;
        pass->x = X;
        pass->nu = nu;
        pass->nh = nh;
        pass->max_iterations = o->max_iterations;
        pass->start_solves = 1;
        pass->simplicial = simplicial;
        pass->iterations = iters;
        pass->kkt = kkt;
        pass->prog = prog;
        atomic_init(&pass->stop, 0);
        atomic_init(&pass->done, 0);
        if (simplicial) {
            dk_run_halves(qp_range, pass, nh, 2);
        } else {
            qp_range(pass, 0, nh, 0);
            pass->status[1] = DK_OK;
        }
        for (int part = 0; part < 2; part++)
            if (pass->status[part] != DK_OK) {
                st = pass->status[part];
                if (err) *err = pass->error[part];
                goto done;
            }
        for (dk_index j = 0; j < nh; j++) {
            rep->max_iterations = iters[j] > rep->max_iterations ? iters[j] : rep->max_iterations;
            rep->total_iterations += iters[j];
            rep->kkt_residual = fmax(rep->kkt_residual, kkt[j]);
        }
        for (dk_index i = 0; i < n; i++)
            if (umap[i] >= 0)
                for (dk_index j = 0; j < nh; j++)
                    raw[(size_t)i * (size_t)nh + (size_t)j] = X[(size_t)nu * (size_t)j + (size_t)umap[i]];
    }

    /* parts no handle reaches copy their nearest reached vertex */
    if (unreached > 0) {
        dk_index nr = n - unreached;
        reached_pos = malloc(((size_t)nr + 1) * 3 * sizeof *reached_pos);
        reached_ids = malloc(((size_t)nr + 1) * sizeof *reached_ids);
        if (!reached_pos || !reached_ids) goto oom;
        dk_index r = 0;
        for (dk_index i = 0; i < n; i++)
            if (is_held[i] || umap[i] >= 0) {
                memcpy(reached_pos + 3 * (size_t)r, d->positions + 3 * (size_t)i, 3 * sizeof(double));
                reached_ids[r++] = i;
            }
        st = dk_kdtree_create(reached_pos, nr, &tree, err);
        for (dk_index i = 0; i < n && st == DK_OK; i++) {
            if (is_held[i] || umap[i] >= 0) continue;
            dk_index near;
            st = dk_kdtree_knn(tree, d->positions + 3 * (size_t)i, 1, 1, &near, NULL, err);
            if (st == DK_OK)
                memcpy(raw + (size_t)i * (size_t)nh, raw + (size_t)reached_ids[near] * (size_t)nh,
                       (size_t)nh * sizeof(double));
        }
        if (st != DK_OK) goto done;
    }
    for (dk_index i = 0; i < n; i++) {
        double sum = 0.0;
        for (dk_index j = 0; j < nh; j++) sum += raw[(size_t)i * (size_t)nh + (size_t)j];
        if (is_held[i] || umap[i] >= 0) rep->sum_deviation = fmax(rep->sum_deviation, fabs(sum - 1.0));
    }
    goto done;
oom:
    st = dk_error_set(err, DK_ERR_OUT_OF_MEMORY, "%s: out of memory", who);
done:
    dk_sparse_free(A);
    dk_sparse_free(Auu);
    dk_kdtree_free(tree);
    free(minv);
    free(B);
    free(X);
    free(reached_pos);
    free(kkt);
    free(label);
    free(queue);
    free(umap);
    free(reached_ids);
    free(held_part);
    free(is_held);
    free(iters);
    free(pass);
    return st;
}

dk_status dk_bounded_biharmonic_weights(const dk_mesh *mesh, const dk_bbw_handles *h,
                                        const dk_bbw_options *options, double *weights,
                                        dk_bbw_report *report, dk_error *err)
{
    dk_bbw_options o;
    if (options) o = *options;
    else dk_bbw_default_options(&o);
    dk_bbw_report rep;
    memset(&rep, 0, sizeof rep);
    if (report) *report = rep;
    dk_status st = check_input(mesh, h, &o, weights, err);
    if (st != DK_OK) return st;
    const dk_index nh = dk_bbw_handle_count(h), nm = mesh->n_vertices;
    dk_progress prog;
    dk_progress_init(&prog, o.progress, o.progress_user, phases, 3, who);
    bbw_domain d;
    double *raw = NULL;
    memset(&d, 0, sizeof d);
    st = dk_progress_begin(&prog, 0, err);
    if (st != DK_OK) goto done;
    int has_volume = 0;
    if (o.domain != DK_BBW_SURFACE) {
        st = bbw_volume_domain(mesh, h, o.resolution, &d, &has_volume, err);
        if (st != DK_OK) goto done;
        if (!has_volume && o.domain == DK_BBW_VOLUME) {
            st = dk_error_set(err, DK_ERR_DEGENERATE, "%s: the %s encloses no volume at "
                              "resolution %d: use the surface domain", who,
                              h->n_cage_triangles ? "cage" : "mesh", o.resolution);
            goto done;
        }
    }
    if (!has_volume) {
        st = bbw_surface_domain(mesh, h, &d, err);
        if (st != DK_OK) goto done;
    }
    rep.domain = d.kind;
    rep.domain_vertices = d.n;
    rep.domain_elements = d.n_elements;
    raw = malloc(((size_t)d.n * (size_t)nh + 1) * sizeof *raw);
    if (!raw) goto oom;
    st = solve_on(&d, nh, &o, raw, &rep, &prog, err);
    if (st != DK_OK) goto done;

    /* the result: rows divided by their sums; the mesh's vertices read through the
     * embedding */
    for (dk_index i = 0; i < d.n; i++) {
        double *row = raw + (size_t)i * (size_t)nh, sum = 0.0;
        for (dk_index j = 0; j < nh; j++) sum += row[j];
        if (sum > 1e-300) {
            for (dk_index j = 0; j < nh; j++) row[j] /= sum;
        } else {
            /* every bound active at once (the division has nothing to divide): the weights
             * of the nearest handle sample's owner */
            dk_index best = 0;
            double bd = INFINITY;
            for (dk_index k = 0; k < d.n_held; k++) {
                const double *p = d.positions + 3 * (size_t)i;
                const double *q = d.positions + 3 * (size_t)d.held[k];
                double dd = (p[0] - q[0]) * (p[0] - q[0]) + (p[1] - q[1]) * (p[1] - q[1]) +
                            (p[2] - q[2]) * (p[2] - q[2]);
                if (dd < bd) bd = dd, best = d.samples[d.held_sample[k]].owner;
            }
            row[best] = 1.0;
        }
    }
    for (dk_index v = 0; v < nm; v++) {
        double *out = weights + (size_t)v * (size_t)nh;
        for (dk_index j = 0; j < nh; j++) out[j] = 0.0;
        for (int q = 0; q < 4; q++) {
            dk_index e = d.embed[4 * (size_t)v + q];
            if (e < 0) continue;
            double f = d.embed_weight[4 * (size_t)v + q];
            for (dk_index j = 0; j < nh; j++) out[j] += f * raw[(size_t)e * (size_t)nh + (size_t)j];
        }
    }
    dk_progress_done(&prog);
    if (report) *report = rep;
    goto done;
oom:
    st = dk_error_set(err, DK_ERR_OUT_OF_MEMORY, "%s: out of memory", who);
done:
    bbw_domain_free(&d);
    free(raw);
    return st;
}
