/* Shape interpolation: rotations beyond 180 degrees (dk_shape_interpolation.h, rotations
 * CONSISTENT), by a least-squares lift of the rotation vectors across the mesh.
 *
 * A rotation's own vector (angle in [0, pi]) cannot say that a part turned by 270 degrees
 * or a bar twisted by 360: the whole turn is invisible in R. Choosing a branch per triangle
 * (its axis times angle + 2 pi m, nearest its neighbour's) handles a pure turn but not a turn
 * beyond pi composed with a small tilt (a twisted tube's triangles are sheared, their
 * rotations tilted round the tube): near a whole turn every vector of such a rotation points
 * along the tilt, and exp(w omega) tilts the in-between by far more than w times it.
 * Between neighbouring triangles p, c the relative rotation R_c R_p^T is small, so its
 * principal vector delta_pc is the turn from one to the other without ambiguity (in the
 * pose's frame: a twist about a fixed axis gives steps along that axis). The lift is the
 * vector field omega closest to those steps in the least-squares sense,
 *     min sum_{adjacent p, c} |omega_c - omega_p - delta_pc|^2,
 * with omega at one root per connected group of triangles fixed to its principal vector
 * (a triangle touching a handle or fixed vertex if there is one: a part pinned there does
 * not turn; else the least turned one): a graph Laplacian on the triangles, factored once
 * per bind, one solve per pose. Summed steps count whole turns; summing them in the least-
 * squares sense makes omega independent of any path (a tree walk would carry the curl of
 * the steps, second order in their size but a visible seam where two branches of the tree
 * meet). omega need not give R exactly (exp(omega) != R_c where the steps do not commute);
 * the residual eps = log(exp(omega)^T R) does, and the blend takes exp(w omega) exp(w eps).
 * Adjacency skips degenerate triangles (their rotation is meaningless): each is its own
 * root, at 0. */
#include "si_internal.h"

#include <math.h>
#include <stdlib.h>
#include <string.h>

void si_lift_free(si_lift *l)
{
    if (!l)
        return;
    free(l->unk);
    dk_sparse_free(l->a);
    dk_cholesky_free(l->chol);
    free(l->rhs);
    memset(l, 0, sizeof *l);
}

/* The other triangle across edge e from t, when both are non-degenerate (else -1). */
static dk_index across(const dk_mesh *m, const unsigned char *degenerate, dk_index e, dk_index t)
{
    if (m->edge_face_count[e] != 2)
        return -1; /* a border, or a non-manifold edge: no single neighbour */
    const dk_index a = m->edge_faces[2 * (size_t)e], b = m->edge_faces[2 * (size_t)e + 1];
    const dk_index o = a == t ? b : a;
    return o >= 0 && o != t && !degenerate[o] && !degenerate[t] ? o : -1;
}

dk_status si_lift_build(const dk_mesh *mesh, const unsigned char *degenerate,
                        const dk_index *by_key, si_lift *out, dk_error *err)
{
    memset(out, 0, sizeof *out);
    const dk_index F = mesh->n_faces;
    out->unk = malloc((size_t)F * sizeof *out->unk + 1);
    dk_index *queue = malloc((size_t)F * sizeof *queue + 1);
    unsigned char *visited = calloc((size_t)F + 1, 1);
    if (!out->unk || !queue || !visited) {
        free(queue);
        free(visited);
        si_lift_free(out);
        return dk_error_set(err, DK_ERR_OUT_OF_MEMORY, "ShapeInterpolation: out of memory "
                            "(lift of %d triangles)", (int)F);
    }
    /* roots: the first triangle of each connected group in by_key's order */
    for (dk_index t = 0; t < F; t++)
        out->unk[t] = 0;
    for (dk_index i = 0; i < F; i++) {
        const dk_index root = by_key[i];
        if (visited[root])
            continue;
        visited[root] = 1;
        out->unk[root] = -1;
        dk_index head = 0, tail = 0;
        queue[tail++] = root;
        while (head < tail) {
            const dk_index p = queue[head++];
            for (int k = 0; k < 3; k++) {
                const dk_index c = across(mesh, degenerate, mesh->face_edges[3 * (size_t)p + k], p);
                if (c >= 0 && !visited[c]) {
                    visited[c] = 1;
                    queue[tail++] = c;
                }
            }
        }
    }
    free(queue);
    free(visited);
    out->nu = 0;
    for (dk_index t = 0; t < F; t++)
        out->unk[t] = out->unk[t] < 0 ? -1 : out->nu++;
    if (out->nu == 0)
        return DK_OK;
    /* the Laplacian over the unknowns (upper triangle with the diagonal) */
    int64_t count = out->nu;
    for (dk_index e = 0; e < mesh->n_edges; e++) {
        const dk_index a = mesh->edge_faces[2 * (size_t)e];
        const dk_index b = a >= 0 ? across(mesh, degenerate, e, a) : -1;
        count += b >= 0 && out->unk[a] >= 0 && out->unk[b] >= 0;
    }
    dk_index *rows = malloc((size_t)count * sizeof *rows + 1);
    dk_index *cols = malloc((size_t)count * sizeof *cols + 1);
    double *vals = malloc((size_t)count * sizeof *vals + 1);
    out->rhs = malloc(3 * (size_t)out->nu * sizeof(double) + 1);
    dk_status st = DK_OK;
    if (!rows || !cols || !vals || !out->rhs)
        st = dk_error_set(err, DK_ERR_OUT_OF_MEMORY, "ShapeInterpolation: out of memory "
                          "(lift system)");
    if (st == DK_OK) {
        for (dk_index u = 0; u < out->nu; u++) {
            rows[u] = cols[u] = u;
            vals[u] = 0.0;
        }
        int64_t k = out->nu;
        for (dk_index e = 0; e < mesh->n_edges; e++) {
            const dk_index a = mesh->edge_faces[2 * (size_t)e];
            const dk_index b = a >= 0 ? across(mesh, degenerate, e, a) : -1;
            if (b < 0)
                continue;
            const dk_index ua = out->unk[a], ub = out->unk[b];
            if (ua >= 0)
                vals[ua] += 1.0;
            if (ub >= 0)
                vals[ub] += 1.0;
            if (ua >= 0 && ub >= 0) {
                rows[k] = ua < ub ? ua : ub;
                cols[k] = ua < ub ? ub : ua;
                vals[k++] = -1.0;
            }
        }
        st = dk_sparse_from_triplets(out->nu, out->nu, count, rows, cols, vals, &out->a, err);
    }
    free(rows);
    free(cols);
    free(vals);
    if (st == DK_OK)
        st = dk_cholesky_analyze(out->a, &out->chol, err);
    if (st == DK_OK)
        st = dk_cholesky_factorize(out->chol, out->a, err);
    if (st != DK_OK)
        si_lift_free(out);
    return st;
}

dk_status si_lift_pose(si_lift *l, const dk_mesh *mesh, const unsigned char *degenerate,
                       const double *R, double *omega, double *eps, dk_error *err)
{
    const dk_index F = mesh->n_faces;
    const size_t nu = (size_t)l->nu;
    /* the roots (and degenerate triangles) at their principal vectors */
    for (dk_index t = 0; t < F; t++)
        if (l->unk[t] < 0) {
            if (degenerate[t])
                memset(omega + 3 * (size_t)t, 0, 3 * sizeof(double));
            else
                si_rotation_log(R + 9 * (size_t)t, omega + 3 * (size_t)t);
        }
    if (nu > 0) {
        memset(l->rhs, 0, 3 * nu * sizeof(double));
        for (dk_index e = 0; e < mesh->n_edges; e++) {
            const dk_index a = mesh->edge_faces[2 * (size_t)e];
            const dk_index b = a >= 0 ? across(mesh, degenerate, e, a) : -1;
            if (b < 0)
                continue;
            /* omega_b - omega_a ~ delta = log(R_b R_a^T) */
            const double *Ra = R + 9 * (size_t)a, *Rb = R + 9 * (size_t)b;
            double Rat[9], Q[9], d[3];
            for (int r = 0; r < 3; r++)
                for (int c = 0; c < 3; c++)
                    Rat[3 * r + c] = Ra[3 * c + r];
            si_mat3_mul(Rb, Rat, Q);
            si_rotation_log(Q, d);
            const dk_index ua = l->unk[a], ub = l->unk[b];
            for (int k = 0; k < 3; k++) {
                if (ub >= 0)
                    l->rhs[(size_t)k * nu + (size_t)ub] += d[k] + (ua < 0 ? omega[3 * (size_t)a + k] : 0.0);
                if (ua >= 0)
                    l->rhs[(size_t)k * nu + (size_t)ua] += -d[k] + (ub < 0 ? omega[3 * (size_t)b + k] : 0.0);
            }
        }
        dk_status st = dk_cholesky_solve(l->chol, l->rhs, 3, l->rhs, err);
        if (st != DK_OK)
            return st;
        for (dk_index t = 0; t < F; t++)
            if (l->unk[t] >= 0)
                for (int k = 0; k < 3; k++)
                    omega[3 * (size_t)t + k] = l->rhs[(size_t)k * nu + (size_t)l->unk[t]];
    }
    for (dk_index t = 0; t < F; t++) {
        double *e = eps + 3 * (size_t)t;
        if (degenerate[t]) {
            e[0] = e[1] = e[2] = 0.0;
            continue;
        }
        double E[9], Q[9];
        si_rotation_exp(omega + 3 * (size_t)t, E);
        si_mat3_tmul(E, R + 9 * (size_t)t, Q);
        si_rotation_log(Q, e);
    }
    return DK_OK;
}
