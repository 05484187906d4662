/* DeformKit EigenDeformation: the part each handle drags (part.h). */
#include "part.h"

#include <math.h>
#include <stdlib.h>
#include <string.h>

#include "dk_operators.h"

void eigen_parts_free(eigen_parts *p)
{
    if (!p)
        return;
    free(p->sizes);
    free(p->verts);
    free(p->turn);
    free(p->follow);
    free(p->pivot);
    free(p->centre);
    memset(p, 0, sizeof *p);
}

static dk_status oom(dk_error *err)
{
    return dk_error_set(err, DK_ERR_OUT_OF_MEMORY,
                        "EigenDeformation: out of memory (the handles' parts)");
}

/* Harmonic fields solved together, with one factorization (n x BATCH doubles at a time). */
#define BATCH 8

/* The level of a handle's field where its part ends: one half, raised past a plateau. The
 * field is harmonic, so it falls steeply along a thin limb and hardly at all across a thick
 * body: the torso between a hand and the feet is one level, near one half, and a cut there
 * takes the torso into the hand's part (the whole body then leans). The free surface's area
 * in bins of 1/CUT_BINS of the field finds it: a bin with over twice the mean area is
 * thick; while a bin next to the cut is thick, the cut rises a bin (at most to 0.9). On a
 * limb fixed at one end no bin near one half is thick, and the cut stays there. */
#define CUT_BINS 20
static double cut_level(const double *u, const double *mass, const dk_constraints *c)
{
    double area[CUT_BINS] = {0.0}, total = 0.0;
    for (dk_index v = 0; v < c->n_vertices; v++)
        if (c->role[v] == DK_VERTEX_FREE) {
            int b = (int)(u[v] * CUT_BINS);
            b = b < 0 ? 0 : b >= CUT_BINS ? CUT_BINS - 1 : b;
            area[b] += mass[v];
            total += mass[v];
        }
    const double thick = 2.0 * total / CUT_BINS;
    int b = CUT_BINS / 2;
    while (b < CUT_BINS - 2 && (area[b - 1] > thick || area[b] > thick))
        b++;
    return (double)b / CUT_BINS;
}

/* owner[v] := the handle whose harmonic field is largest at free vertex v, among those
 * whose field there is above their cut level; -1 otherwise (handle and fixed vertices keep
 * -1: they are no part's turning piece) */
static dk_status owners(const dk_mesh *mesh, const dk_constraints *c, dk_index *owner,
                        dk_error *err)
{
    const dk_index n = mesh->n_vertices;
    const size_t cols = c->n_handles < 1 ? 1 : c->n_handles < BATCH ? (size_t)c->n_handles : BATCH;
    dk_index *painted = malloc(((size_t)n + 1) * sizeof *painted);
    double *val = malloc(((size_t)n + 1) * cols * sizeof *val);
    double *u = malloc(((size_t)n + 1) * cols * sizeof *u);
    double *best = malloc(((size_t)n + 1) * sizeof *best);
    double *mass = malloc(((size_t)n + 1) * sizeof *mass);
    dk_status st = (!painted || !val || !u || !best || !mass) ? oom(err) : DK_OK;
    if (st == DK_OK)
        st = dk_mass_matrix(mesh, DK_MASS_BARYCENTRIC, mass, err);
    dk_index np = 0;
    for (dk_index v = 0; st == DK_OK && v < n; v++) {
        owner[v] = -1;
        best[v] = 0.0;
        if (c->role[v] != DK_VERTEX_FREE)
            painted[np++] = v;
    }
    for (dk_index h0 = 0; st == DK_OK && h0 < c->n_handles; h0 += (dk_index)cols) {
        const dk_index k = c->n_handles - h0 < (dk_index)cols ? c->n_handles - h0 : (dk_index)cols;
        for (dk_index j = 0; j < k; j++)
            for (dk_index q = 0; q < np; q++)
                val[(size_t)np * j + q] = c->role[painted[q]] == h0 + j ? 1.0 : 0.0;
        st = dk_harmonic_interpolation_columns(mesh, painted, val, np, (int)k, 0.0, u, err);
        if (st != DK_OK)
            break;
        for (dk_index j = 0; j < k; j++) {
            const double *uj = u + (size_t)n * j, cut = cut_level(uj, mass, c);
            for (dk_index v = 0; v < n; v++)
                if (c->role[v] == DK_VERTEX_FREE && uj[v] > cut && uj[v] > best[v]) {
                    best[v] = uj[v];
                    owner[v] = h0 + j;
                }
        }
    }
    if (st != DK_OK && st != DK_ERR_OUT_OF_MEMORY)
        dk_error_prefix(err, "EigenDeformation: the handles' parts");
    free(painted);
    free(val);
    free(u);
    free(best);
    free(mass);
    return st;
}

dk_status eigen_parts_build(const dk_mesh *mesh, const dk_constraints *user,
                            const dk_index *fixed, dk_index n_fixed, eigen_parts *out,
                            dk_error *err)
{
    memset(out, 0, sizeof *out);
    const dk_index n = mesh->n_vertices, nh = user->n_handles;
    dk_index *owner = malloc(((size_t)n + 1) * sizeof *owner);
    out->sizes = malloc(2 * ((size_t)nh + 1) * sizeof *out->sizes);
    out->verts = malloc(((size_t)n + 1) * sizeof *out->verts);
    out->turn = malloc(((size_t)nh + 1) * sizeof *out->turn);
    out->follow = malloc(((size_t)nh + 1) * sizeof *out->follow);
    out->pivot = malloc(3 * ((size_t)nh + 1) * sizeof *out->pivot);
    out->centre = malloc(3 * ((size_t)nh + 1) * sizeof *out->centre);
    if (!owner || !out->sizes || !out->verts || !out->turn || !out->follow || !out->pivot ||
        !out->centre) {
        free(owner);
        eigen_parts_free(out);
        return oom(err);
    }
    dk_status st = owners(mesh, user, owner, err);
    if (st != DK_OK) {
        free(owner);
        eigen_parts_free(out);
        return st;
    }
    out->n_user = nh;
    dk_index g = 0, at = 0;
    for (dk_index h = 0; h < nh; h++) {
        /* the turning piece: the free vertices this handle owns */
        const dk_index start = at;
        for (dk_index v = 0; v < n; v++)
            if (owner[v] == h)
                out->verts[at++] = v;
        out->turn[h] = at > start ? g : -1;
        if (at > start)
            out->sizes[g++] = at - start;
        out->n_part_vertices += at - start;
        /* the handle group itself, in the caller's order */
        out->follow[h] = g;
        double cen[3] = {0.0, 0.0, 0.0};
        const dk_index hs = user->handle_start[h], he = user->handle_start[h + 1];
        for (dk_index q = hs; q < he; q++) {
            const dk_index v = user->handle_vertices[q];
            out->verts[at++] = v;
            for (int d = 0; d < 3; d++)
                cen[d] += mesh->positions[3 * (size_t)v + d] / (double)(he - hs);
        }
        out->sizes[g++] = he - hs;
        memcpy(out->centre + 3 * (size_t)h, cen, sizeof cen);
        /* the pivot: the centroid of the part's vertices (turning piece or handle) with a
         * neighbour outside the part */
        double piv[3] = {0.0, 0.0, 0.0};
        dk_index nb = 0;
        for (dk_index v = 0; v < n; v++) {
            const int in = owner[v] == h || user->role[v] == h;
            if (!in)
                continue;
            for (dk_index k = mesh->ring_start[v]; k < mesh->ring_start[v + 1]; k++) {
                const dk_index w = mesh->ring_index[k];
                if (!(owner[w] == h || user->role[w] == h)) {
                    for (int d = 0; d < 3; d++)
                        piv[d] += mesh->positions[3 * (size_t)v + d];
                    nb++;
                    break;
                }
            }
        }
        for (int d = 0; d < 3; d++)
            out->pivot[3 * (size_t)h + d] = nb > 0 ? piv[d] / (double)nb : NAN;
    }
    free(owner);
    out->n_groups = g;
    out->desc.n_handles = g;
    out->desc.handle_sizes = out->sizes;
    out->desc.handle_vertices = out->verts;
    out->desc.n_fixed = n_fixed;
    out->desc.fixed_vertices = fixed;
    return DK_OK;
}

/* R := the smallest rotation taking unit a to unit b (row-major 3 x 3). */
static void rotation_between(const double a[3], const double b[3], double R[9])
{
    const double v[3] = {a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2],
                         a[0] * b[1] - a[1] * b[0]};
    const double c = a[0] * b[0] + a[1] * b[1] + a[2] * b[2];
    const double s2 = v[0] * v[0] + v[1] * v[1] + v[2] * v[2];
    for (int r = 0; r < 9; r++)
        R[r] = (r % 4 == 0) ? 1.0 : 0.0;
    if (s2 < 1e-24) {
        if (c > 0.0)
            return;
        /* opposite: half a turn about an axis orthogonal to a */
        int k = fabs(a[0]) < fabs(a[1]) ? (fabs(a[0]) < fabs(a[2]) ? 0 : 2)
                                        : (fabs(a[1]) < fabs(a[2]) ? 1 : 2);
        double e[3] = {0.0, 0.0, 0.0}, x[3];
        e[k] = 1.0;
        x[0] = a[1] * e[2] - a[2] * e[1];
        x[1] = a[2] * e[0] - a[0] * e[2];
        x[2] = a[0] * e[1] - a[1] * e[0];
        const double l = sqrt(x[0] * x[0] + x[1] * x[1] + x[2] * x[2]);
        for (int d = 0; d < 3; d++)
            x[d] /= l;
        for (int r = 0; r < 3; r++)
            for (int q = 0; q < 3; q++)
                R[3 * r + q] = 2.0 * x[r] * x[q] - (r == q ? 1.0 : 0.0);
        return;
    }
    /* Rodrigues: I + [v]x + [v]x^2 (1 - c) / s^2 */
    const double K[9] = {0.0, -v[2], v[1], v[2], 0.0, -v[0], -v[1], v[0], 0.0};
    const double f = (1.0 - c) / s2;
    for (int r = 0; r < 3; r++)
        for (int q = 0; q < 3; q++) {
            double kk = 0.0;
            for (int t = 0; t < 3; t++)
                kk += K[3 * r + t] * K[3 * t + q];
            R[3 * r + q] += K[3 * r + q] + f * kk;
        }
}

void eigen_parts_transforms(const eigen_parts *p, const double *user_T, double *group_T)
{
    for (dk_index h = 0; h < p->n_user; h++) {
        const double *T = user_T + 16 * (size_t)h;
        memcpy(group_T + 16 * (size_t)p->follow[h], T, 16 * sizeof(double));
        if (p->turn[h] < 0)
            continue;
        double *M = group_T + 16 * (size_t)p->turn[h];
        memcpy(M, T, 16 * sizeof(double)); /* no pivot or no distance: the handle's motion */
        const double *piv = p->pivot + 3 * (size_t)h, *c = p->centre + 3 * (size_t)h;
        if (!isfinite(piv[0]))
            continue;
        double c2[3], a[3], b[3], la = 0.0, lb = 0.0;
        for (int r = 0; r < 3; r++) {
            c2[r] = T[4 * r] * c[0] + T[4 * r + 1] * c[1] + T[4 * r + 2] * c[2] + T[4 * r + 3];
            a[r] = c[r] - piv[r];
            b[r] = c2[r] - piv[r];
            la += a[r] * a[r];
            lb += b[r] * b[r];
        }
        la = sqrt(la);
        lb = sqrt(lb);
        if (!(la > 0.0) || !(lb > 0.0))
            continue;
        for (int r = 0; r < 3; r++) {
            a[r] /= la;
            b[r] /= lb;
        }
        double R[9];
        rotation_between(a, b, R);
        /* x -> R (x - pivot) + pivot + (lb - la) b: the centroid lands on c2 */
        for (int r = 0; r < 3; r++) {
            double rp = 0.0;
            for (int q = 0; q < 3; q++) {
                M[4 * r + q] = R[3 * r + q];
                rp += R[3 * r + q] * piv[q];
            }
            M[4 * r + 3] = piv[r] - rp + (lb - la) * b[r];
        }
        M[12] = M[13] = M[14] = 0.0;
        M[15] = 1.0;
    }
}
