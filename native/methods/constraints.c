/* DeformKit: validation of the shared constraint description and expansion of solve-time
 * handle targets. See dk_constraints.h for the contract.
 *
 * Choices the header leaves open, stated here:
 *  - a vertex listed twice in the SAME handle is refused like any other overlap (its target
 *    would be ambiguous); a vertex listed twice in the fixed set or the ROI is harmless and
 *    accepted;
 *  - the ROI only turns FREE vertices into FIXED ones: a handle vertex outside the ROI stays
 *    a handle (it is constrained either way, and dropping its target silently would be
 *    worse than honouring it);
 *  - having no free vertex is not an error here: a method then returns the constrained
 *    motion (dk_constraints_constrained_motion) instead of refusing;
 *  - a component is held when none of its vertices is a handle or fixed after the ROI is
 *    applied: a component outside the ROI is fixed by it, not held. */
#include "dk_constraints.h"

#include <math.h>
#include <stdlib.h>
#include <string.h>

void dk_constraints_free(dk_constraints *c)
{
    if (!c)
        return;
    free(c->handle_start);
    free(c->handle_vertices);
    free(c->handle_weights);
    free(c->role);
    free(c->free_index);
    free(c->free_vertices);
    free(c->stiffness);
    free(c->held);
    free(c);
}

static dk_status oom(dk_error *err, const char *what)
{
    return dk_error_set(err, DK_ERR_OUT_OF_MEMORY, "constraints: out of memory (%s)", what);
}

/* The description's shape: counts, lists present, handle sizes (none empty, their total
 * within the index type) into *total. */
static dk_status check_shape(const dk_constraint_desc *desc, int handles_optional,
                             int64_t *total_out, dk_error *err)
{
    if (desc->n_handles < 0 || desc->n_fixed < 0 || desc->n_roi < 0)
        return dk_error_set(err, DK_ERR_INVALID_ARGUMENT,
                            "constraints: negative count (handles %d, fixed %d, roi %d)",
                            (int)desc->n_handles, (int)desc->n_fixed, (int)desc->n_roi);
    if (desc->n_handles == 0 && !handles_optional)
        return dk_error_set(err, DK_ERR_INVALID_ARGUMENT,
                            "constraints: at least one handle group is required");
    if (desc->n_handles > 0 && (!desc->handle_sizes || !desc->handle_vertices))
        return dk_error_set(err, DK_ERR_INVALID_ARGUMENT,
                            "constraints: handle sizes and vertices must not be NULL");
    if (desc->n_fixed > 0 && !desc->fixed_vertices)
        return dk_error_set(err, DK_ERR_INVALID_ARGUMENT,
                            "constraints: %d fixed vertices announced but the list is NULL",
                            (int)desc->n_fixed);
    if (desc->n_roi > 0 && !desc->roi_vertices)
        return dk_error_set(err, DK_ERR_INVALID_ARGUMENT,
                            "constraints: %d ROI vertices announced but the list is NULL",
                            (int)desc->n_roi);

    /* Sizes: none empty, total fits the index type. */
    int64_t total = 0;
    for (dk_index h = 0; h < desc->n_handles; h++) {
        if (desc->handle_sizes[h] <= 0)
            return dk_error_set(err, DK_ERR_INVALID_ARGUMENT,
                                "constraints: handle %d is empty (size %d)", (int)h,
                                (int)desc->handle_sizes[h]);
        total += desc->handle_sizes[h];
        if (total > INT32_MAX)
            return dk_error_set(err, DK_ERR_INVALID_ARGUMENT,
                                "constraints: too many handle vertices");
    }

    *total_out = total;
    return DK_OK;
}

/* Every index in range and every weight and stiffness valid, naming the list and position. */
static dk_status check_values(const dk_mesh *mesh, const dk_constraint_desc *desc,
                              dk_error *err)
{
    const dk_index n = mesh->n_vertices;
    {
        int64_t k = 0;
        for (dk_index h = 0; h < desc->n_handles; h++)
            for (dk_index j = 0; j < desc->handle_sizes[h]; j++, k++) {
                dk_index v = desc->handle_vertices[k];
                if (v < 0 || v >= n)
                    return dk_error_set(err, DK_ERR_INDEX,
                                        "constraints: handle %d vertex %d is %d, out of range "
                                        "[0, %d)", (int)h, (int)j, (int)v, (int)n);
                if (desc->handle_weights) {
                    double w = desc->handle_weights[k];
                    if (!(isfinite(w) && w > 0.0 && w <= 1.0))
                        return dk_error_set(err, isfinite(w) ? DK_ERR_INVALID_ARGUMENT
                                                             : DK_ERR_NONFINITE,
                                            "constraints: handle %d vertex %d weight is %g, "
                                            "outside (0, 1]", (int)h, (int)v, w);
                }
            }
    }
    for (dk_index k = 0; k < desc->n_fixed; k++) {
        dk_index v = desc->fixed_vertices[k];
        if (v < 0 || v >= n)
            return dk_error_set(err, DK_ERR_INDEX,
                                "constraints: fixed vertex %d is %d, out of range [0, %d)",
                                (int)k, (int)v, (int)n);
    }
    for (dk_index k = 0; k < desc->n_roi; k++) {
        dk_index v = desc->roi_vertices[k];
        if (v < 0 || v >= n)
            return dk_error_set(err, DK_ERR_INDEX,
                                "constraints: ROI vertex %d is %d, out of range [0, %d)",
                                (int)k, (int)v, (int)n);
    }
    if (desc->stiffness)
        for (dk_index v = 0; v < n; v++) {
            double s = desc->stiffness[v];
            if (!(isfinite(s) && s > 0.0))
                return dk_error_set(err, isfinite(s) ? DK_ERR_INVALID_ARGUMENT
                                                     : DK_ERR_NONFINITE,
                                    "constraints: stiffness of vertex %d is %g, must be finite "
                                    "and > 0", (int)v, s);
        }

    return DK_OK;
}

/* Each vertex's role: a handle (refusing overlaps, naming both groups), fixed, or free;
 * vertices outside a non-empty ROI become fixed. */
static dk_status assign_roles(const dk_constraint_desc *desc, dk_constraints *c, dk_error *err)
{
    const dk_index n = c->n_vertices;
    for (dk_index v = 0; v < n; v++) {
        c->role[v] = DK_VERTEX_FREE;
        c->stiffness[v] = desc->stiffness ? desc->stiffness[v] : 1.0;
    }
    c->handle_start[0] = 0;
    for (dk_index h = 0, k = 0; h < c->n_handles; h++) {
        for (dk_index j = 0; j < desc->handle_sizes[h]; j++, k++) {
            dk_index v = desc->handle_vertices[k];
            if (c->role[v] >= 0) {
                dk_index other = c->role[v];
                if (other == h)
                    return dk_error_set(err, DK_ERR_INVALID_ARGUMENT,
                                        "constraints: vertex %d appears twice in handle %d",
                                        (int)v, (int)h);
                return dk_error_set(err, DK_ERR_INVALID_ARGUMENT,
                                    "constraints: vertex %d is both in handle %d and in handle "
                                    "%d", (int)v, (int)other, (int)h);
            }
            c->role[v] = h;
            c->handle_vertices[k] = v;
            c->handle_weights[k] = desc->handle_weights ? desc->handle_weights[k] : 1.0;
        }
        c->handle_start[h + 1] = c->handle_start[h] + desc->handle_sizes[h];
    }
    for (dk_index k = 0; k < desc->n_fixed; k++) {
        dk_index v = desc->fixed_vertices[k];
        if (c->role[v] >= 0) {
            dk_index h = c->role[v];
            return dk_error_set(err, DK_ERR_INVALID_ARGUMENT,
                                "constraints: vertex %d is both in handle %d and in the fixed "
                                "set", (int)v, (int)h);
        }
        c->role[v] = DK_VERTEX_FIXED;
    }
    if (desc->n_roi > 0) {
        /* Mark ROI membership in free_index temporarily. */
        for (dk_index v = 0; v < n; v++)
            c->free_index[v] = 0;
        for (dk_index k = 0; k < desc->n_roi; k++)
            c->free_index[desc->roi_vertices[k]] = 1;
        for (dk_index v = 0; v < n; v++)
            if (!c->free_index[v] && c->role[v] == DK_VERTEX_FREE)
                c->role[v] = DK_VERTEX_FIXED;
    }
    return DK_OK;
}

/* Components nothing constrains are held: their vertices become FIXED and marked held. */
static dk_status hold_unconstrained(const dk_mesh *mesh, dk_constraints *c, dk_error *err)
{
    const dk_index n = c->n_vertices, nc = mesh->report.n_components;
    c->first_held = -1;
    c->held = calloc((size_t)n + 1, 1);
    if (!c->held)
        return oom(err, "held vertices");
    if (!mesh->component || nc <= 0 || mesh->n_faces == 0)
        return DK_OK; /* a point set (no faces) has no loose geometry: its points are it */
    unsigned char *constrained = calloc((size_t)nc + 1, 1);
    if (!constrained)
        return oom(err, "components");
    for (dk_index v = 0; v < n; v++)
        if (c->role[v] != DK_VERTEX_FREE)
            constrained[mesh->component[v]] = 1;
    for (dk_index k = 0; k < nc; k++)
        if (!constrained[k])
            c->n_held_components++;
    for (dk_index v = 0; v < n; v++)
        if (!constrained[mesh->component[v]]) {
            c->role[v] = DK_VERTEX_FIXED;
            c->held[v] = 1;
            if (c->n_held++ == 0)
                c->first_held = v;
        }
    free(constrained);
    return DK_OK;
}

void dk_constraints_hold(const dk_constraints *c, const double *rest_positions,
                         double *positions)
{
    if (!c || !c->held || c->n_held == 0)
        return;
    for (dk_index v = 0; v < c->n_vertices; v++)
        if (c->held[v])
            memcpy(positions + 3 * (size_t)v, rest_positions + 3 * (size_t)v,
                   3 * sizeof(double));
}

void dk_constraints_constrained_motion(const dk_constraints *c, const double *rest_positions,
                                       const double *targets, double *positions)
{
    memcpy(positions, rest_positions, 3 * (size_t)c->n_vertices * sizeof(double));
    for (dk_index k = 0; k < c->n_handle_vertices; k++) {
        const dk_index v = c->handle_vertices[k];
        const double w = c->handle_weights[k];
        for (int d = 0; d < 3; d++) {
            const double r = rest_positions[3 * (size_t)v + d];
            positions[3 * (size_t)v + d] = w == 1.0 ? targets[3 * (size_t)k + d]
                                                    : r + w * (targets[3 * (size_t)k + d] - r);
        }
    }
}

/* The free vertices' numbering, both ways. */
static dk_status number_free(dk_constraints *c, dk_error *err)
{
    const dk_index n = c->n_vertices;
    dk_index nf = 0;
    for (dk_index v = 0; v < n; v++)
        c->free_index[v] = c->role[v] == DK_VERTEX_FREE ? nf++ : -1;
    c->n_free = nf;
    c->free_vertices = malloc(((size_t)nf + 1) * sizeof *c->free_vertices);
    if (!c->free_vertices)
        return oom(err, "free vertex map");
    for (dk_index v = 0; v < n; v++)
        if (c->free_index[v] >= 0)
            c->free_vertices[c->free_index[v]] = v;
    return DK_OK;
}

/* dk_constraints_create (simulated 0) and dk_constraints_create_simulated (1). */
static dk_status create(const dk_mesh *mesh, const dk_constraint_desc *desc, int simulated,
                        dk_constraints **out, dk_error *err)
{
    if (out)
        *out = NULL;
    if (!mesh || !desc || !out)
        return dk_error_set(err, DK_ERR_INVALID_ARGUMENT,
                            "constraints: mesh, description and output must not be NULL");
    const dk_index n = mesh->n_vertices;
    int64_t total = 0;
    dk_status st = dk_control_taken(desc->control, DK_CONTROL_VERTEX_GROUPS, "this method", err);
    if (st != DK_OK)
        return st;
    st = check_shape(desc, simulated, &total, err);
    if (st == DK_OK)
        st = check_values(mesh, desc, err);
    if (st != DK_OK)
        return st;
    dk_constraints *c = calloc(1, sizeof *c);
    if (!c)
        return oom(err, "object");
    c->n_vertices = n;
    c->n_handles = desc->n_handles;
    c->n_handle_vertices = (dk_index)total;
    c->handle_start = malloc(((size_t)c->n_handles + 1) * sizeof *c->handle_start);
    c->handle_vertices = malloc(((size_t)total + 1) * sizeof *c->handle_vertices);
    c->handle_weights = malloc(((size_t)total + 1) * sizeof *c->handle_weights);
    c->role = malloc(((size_t)n + 1) * sizeof *c->role);
    c->free_index = malloc(((size_t)n + 1) * sizeof *c->free_index);
    c->stiffness = malloc(((size_t)n + 1) * sizeof *c->stiffness);
    if (!c->handle_start || !c->handle_vertices || !c->handle_weights || !c->role ||
        !c->free_index || !c->stiffness) {
        dk_constraints_free(c);
        return oom(err, "arrays");
    }
    st = assign_roles(desc, c, err);
    if (st == DK_OK && simulated) {
        c->first_held = -1;
        c->held = calloc((size_t)n + 1, 1); /* nothing is held: it is simulated */
        if (!c->held)
            st = oom(err, "held vertices");
    } else if (st == DK_OK) {
        st = hold_unconstrained(mesh, c, err);
    }
    if (st == DK_OK)
        st = number_free(c, err);
    if (st != DK_OK) {
        dk_constraints_free(c);
        return st;
    }
    *out = c;
    return DK_OK;
}

dk_status dk_constraints_create(const dk_mesh *mesh, const dk_constraint_desc *desc,
                                dk_constraints **out, dk_error *err)
{
    return create(mesh, desc, 0, out, err);
}

dk_status dk_constraints_create_simulated(const dk_mesh *mesh, const dk_constraint_desc *desc,
                                          dk_constraints **out, dk_error *err)
{
    return create(mesh, desc, 1, out, err);
}

/* One expanded target: handle h's vertex v at row k, from a position (mode 0) or the
 * transform t (mode 1), checked finite and within DK_COORD_MAX. */
static dk_status target_of(const dk_constraints *c, const double *rest_positions,
                           const double *targets, int mode, dk_index h, dk_index k,
                           double o[3], dk_error *err)
{
    const dk_index v = c->handle_vertices[k];
    if (mode == 0) {
        const double *p = targets + 3 * (size_t)k;
        if (!(isfinite(p[0]) && isfinite(p[1]) && isfinite(p[2])))
            return dk_error_set(err, DK_ERR_NONFINITE,
                                "constraint targets: handle %d vertex %d (target row %d) is "
                                "not finite", (int)h, (int)v, (int)k);
        o[0] = p[0];
        o[1] = p[1];
        o[2] = p[2];
    } else {
        const double *t = targets + 16 * (size_t)h, *r = rest_positions + 3 * (size_t)v;
        for (int d = 0; d < 3; d++)
            o[d] = t[4 * d] * r[0] + t[4 * d + 1] * r[1] + t[4 * d + 2] * r[2] + t[4 * d + 3];
        if (!(isfinite(o[0]) && isfinite(o[1]) && isfinite(o[2])))
            return dk_error_set(err, DK_ERR_NONFINITE,
                                "constraint targets: handle %d vertex %d transformed position "
                                "is not finite (overflow)", (int)h, (int)v);
    }
    for (int d = 0; d < 3; d++)
        if (fabs(o[d]) > DK_COORD_MAX)
            return dk_error_set(err, DK_ERR_NONFINITE,
                                "constraint targets: handle %d vertex %d (target row %d) "
                                "coordinate %c is %g, beyond +-%g (the solve would overflow "
                                "double precision)", (int)h, (int)v, (int)k, "xyz"[d], o[d],
                                DK_COORD_MAX);
    return DK_OK;
}

dk_status dk_constraints_targets(const dk_constraints *c, const double *rest_positions,
                                 const double *targets, int mode, double *out, dk_error *err)
{
    if (!c || !rest_positions || !targets || !out)
        return dk_error_set(err, DK_ERR_INVALID_ARGUMENT,
                            "constraint targets: NULL argument");
    if (mode != 0 && mode != 1)
        return dk_error_set(err, DK_ERR_INVALID_ARGUMENT,
                            "constraint targets: unknown mode %d (0 = positions, "
                            "1 = 4x4 transforms)", mode);
    /* Everything is checked before anything is written: a refused request leaves `out`
     * (a method's current targets) as it was. */
    for (dk_index h = 0; h < c->n_handles; h++) {
        if (mode == 1) {
            const double *t = targets + 16 * (size_t)h;
            for (int e = 0; e < 16; e++)
                if (!isfinite(t[e]))
                    return dk_error_set(err, DK_ERR_NONFINITE,
                                        "constraint targets: handle %d transform entry "
                                        "(%d, %d) is not finite", (int)h, e / 4, e % 4);
            if (t[12] != 0.0 || t[13] != 0.0 || t[14] != 0.0 || t[15] != 1.0)
                return dk_error_set(err, DK_ERR_INVALID_ARGUMENT,
                                    "constraint targets: handle %d transform bottom row is "
                                    "(%g, %g, %g, %g), must be (0, 0, 0, 1)", (int)h, t[12],
                                    t[13], t[14], t[15]);
        }
        for (dk_index k = c->handle_start[h]; k < c->handle_start[h + 1]; k++) {
            double o[3];
            dk_status st = target_of(c, rest_positions, targets, mode, h, k, o, err);
            if (st != DK_OK)
                return st;
        }
    }
    for (dk_index h = 0; h < c->n_handles; h++)
        for (dk_index k = c->handle_start[h]; k < c->handle_start[h + 1]; k++)
            (void)target_of(c, rest_positions, targets, mode, h, k, out + 3 * (size_t)k, err);
    return DK_OK;
}
