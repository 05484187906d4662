/* DeformKit: checks of a control bound with the mesh (dk_controls.h). */
#include "dk_controls.h"

#include <math.h>
#include <stdint.h>
#include <stdio.h>

static const struct {
    dk_control_kind kind;
    const char *name, *id;
} kind_names[] = {{DK_CONTROL_VERTEX_GROUPS, "vertex groups", "vertex_groups"},
                  {DK_CONTROL_POINTS, "points", "points"},
                  {DK_CONTROL_BONES, "bones", "bones"},
                  {DK_CONTROL_CAGE, "a cage", "cage"},
                  {DK_CONTROL_LATTICE, "a lattice", "lattice"},
                  {DK_CONTROL_POSES, "poses", "poses"}};

const char *dk_control_kind_name(dk_control_kind kind)
{
    for (size_t i = 0; i < sizeof kind_names / sizeof kind_names[0]; i++)
        if (kind_names[i].kind == kind)
            return kind_names[i].name;
    return "unknown";
}

const char *dk_control_kind_id(dk_control_kind kind)
{
    for (size_t i = 0; i < sizeof kind_names / sizeof kind_names[0]; i++)
        if (kind_names[i].kind == kind)
            return kind_names[i].id;
    return NULL;
}

/* "vertex groups or a lattice" into buf: the kinds of `taken`. */
static void taken_names(unsigned taken, char *buf, size_t size)
{
    size_t used = 0;
    int first = 1;
    buf[0] = '\0';
    for (size_t i = 0; i < sizeof kind_names / sizeof kind_names[0]; i++) {
        if (!(taken & (unsigned)kind_names[i].kind))
            continue;
        int w = snprintf(buf + used, size - used, "%s%s", first ? "" : " or ",
                         kind_names[i].name);
        if (w < 0 || (size_t)w >= size - used)
            return;
        used += (size_t)w;
        first = 0;
    }
}

dk_status dk_control_taken(const dk_control_desc *control, unsigned taken, const char *who,
                           dk_error *err)
{
    const unsigned kind = control ? (unsigned)control->kind : DK_CONTROL_VERTEX_GROUPS;
    if (taken & kind)
        return DK_OK;
    char names[128];
    taken_names(taken, names, sizeof names);
    return dk_error_set(err, DK_ERR_INVALID_ARGUMENT, "%s binds to %s, not %s", who,
                        names[0] ? names : "nothing",
                        dk_control_kind_name((dk_control_kind)kind));
}

/* Every value finite and within DK_COORD_MAX: the first bad one named. */
static dk_status check_values(const double *v, size_t count, const char *what, dk_error *err)
{
    for (size_t i = 0; i < count; i++) {
        if (!isfinite(v[i]))
            return dk_error_set(err, DK_ERR_NONFINITE, "control: %s[%zu] is not finite", what,
                                i);
        if (fabs(v[i]) > DK_COORD_MAX)
            return dk_error_set(err, DK_ERR_INVALID_ARGUMENT,
                                "control: %s[%zu] = %g is beyond %g", what, i, v[i],
                                DK_COORD_MAX);
    }
    return DK_OK;
}

/* A 4x4 row-major affine map: bottom row 0 0 0 1 and an invertible 3x3 part (its
 * determinant not negligible against the product of its rows' lengths). */
static dk_status check_frame(const double *m, dk_index index, const char *what, dk_error *err)
{
    if (m[12] != 0.0 || m[13] != 0.0 || m[14] != 0.0 || m[15] != 1.0)
        return dk_error_set(err, DK_ERR_INVALID_ARGUMENT,
                            "control: %s %d is not affine (its bottom row must be 0 0 0 1)",
                            what, (int)index);
    const double det = m[0] * (m[5] * m[10] - m[6] * m[9]) - m[1] * (m[4] * m[10] - m[6] * m[8]) +
                       m[2] * (m[4] * m[9] - m[5] * m[8]);
    double scale = 1.0;
    for (int r = 0; r < 3; r++)
        scale *= sqrt(m[4 * r] * m[4 * r] + m[4 * r + 1] * m[4 * r + 1] +
                      m[4 * r + 2] * m[4 * r + 2]);
    if (!(fabs(det) > 1e-12 * scale))
        return dk_error_set(err, DK_ERR_INVALID_ARGUMENT,
                            "control: %s %d is not invertible (its 3x3 part is singular)", what,
                            (int)index);
    return DK_OK;
}

/* The fields that belong to other kinds are unset. */
static dk_status check_unused(const dk_control_desc *c, dk_error *err)
{
    const char *name = dk_control_kind_name(c->kind);
    if (c->kind != DK_CONTROL_CAGE && (c->n_triangles != 0 || c->triangles))
        return dk_error_set(err, DK_ERR_INVALID_ARGUMENT,
                            "control: %s has no triangles (only a cage does)", name);
    if (c->kind != DK_CONTROL_LATTICE &&
        (c->resolution[0] != 0 || c->resolution[1] != 0 || c->resolution[2] != 0))
        return dk_error_set(err, DK_ERR_INVALID_ARGUMENT,
                            "control: %s has no resolution (only a lattice does)", name);
    if (c->kind != DK_CONTROL_BONES && c->segments)
        return dk_error_set(err, DK_ERR_INVALID_ARGUMENT,
                            "control: %s has no segments (only bones do)", name);
    if (c->kind != DK_CONTROL_BONES && c->weights)
        return dk_error_set(err, DK_ERR_INVALID_ARGUMENT,
                            "control: %s has no per-vertex weights (only bones do)", name);
    return DK_OK;
}

static dk_status check_cage(const dk_control_desc *c, dk_error *err)
{
    if (c->n_triangles <= 0 || !c->triangles)
        return dk_error_set(err, DK_ERR_INVALID_ARGUMENT,
                            "control: a cage needs triangles (n_triangles %d)",
                            (int)c->n_triangles);
    for (dk_index t = 0; t < c->n_triangles; t++) {
        const dk_index *f = c->triangles + 3 * (size_t)t;
        for (int k = 0; k < 3; k++)
            if (f[k] < 0 || f[k] >= c->n_controls)
                return dk_error_set(err, DK_ERR_INDEX,
                                    "control: cage triangle %d has corner %d, outside the "
                                    "cage's %d vertices",
                                    (int)t, (int)f[k], (int)c->n_controls);
        if (f[0] == f[1] || f[1] == f[2] || f[0] == f[2])
            return dk_error_set(err, DK_ERR_INVALID_ARGUMENT,
                                "control: cage triangle %d repeats a corner (%d %d %d)", (int)t,
                                (int)f[0], (int)f[1], (int)f[2]);
    }
    return DK_OK;
}

static dk_status check_weights(const dk_control_desc *c, dk_index n_vertices, dk_error *err)
{
    const size_t nb = (size_t)c->n_controls;
    if (!c->weights && c->segments)
        return check_values(c->segments, 6 * nb, "segments", err);
    if (!c->weights)
        return dk_error_set(err, DK_ERR_INVALID_ARGUMENT,
                            "control: bones need weights (n_vertices x n_bones) or their "
                            "segments (n_bones x 2 x 3) to compute them from");
    if (c->segments)
        return dk_error_set(err, DK_ERR_INVALID_ARGUMENT,
                            "control: bones take weights or segments, not both");
    dk_status st = check_values(c->weights, (size_t)n_vertices * nb, "weights", err);
    if (st != DK_OK)
        return st;
    for (dk_index v = 0; v < n_vertices; v++) {
        double sum = 0.0;
        for (size_t b = 0; b < nb; b++) {
            const double w = c->weights[(size_t)v * nb + b];
            if (w < 0.0)
                return dk_error_set(err, DK_ERR_INVALID_ARGUMENT,
                                    "control: vertex %d's weight for bone %zu is negative (%g)",
                                    (int)v, b, w);
            sum += w;
        }
        if (fabs(sum - 1.0) > 1e-6)
            return dk_error_set(err, DK_ERR_INVALID_ARGUMENT,
                                "control: vertex %d's bone weights sum to %.9g, not 1", (int)v,
                                sum);
    }
    return DK_OK;
}

dk_status dk_control_check(const dk_control_desc *c, dk_index n_vertices, dk_error *err)
{
    if (!c)
        return dk_error_set(err, DK_ERR_INVALID_ARGUMENT, "control: the description is NULL");
    if (n_vertices <= 0)
        return dk_error_set(err, DK_ERR_INVALID_ARGUMENT, "control: the mesh has no vertices");
    switch (c->kind) {
    case DK_CONTROL_POINTS:
    case DK_CONTROL_BONES:
    case DK_CONTROL_CAGE:
    case DK_CONTROL_LATTICE:
    case DK_CONTROL_POSES:
        break;
    case DK_CONTROL_VERTEX_GROUPS:
        return dk_error_set(err, DK_ERR_INVALID_ARGUMENT,
                            "control: vertex groups are the handles of the constraint "
                            "description, not a control");
    default:
        return dk_error_set(err, DK_ERR_INVALID_ARGUMENT, "control: unknown kind %d",
                            (int)c->kind);
    }
    const char *name = dk_control_kind_name(c->kind);
    dk_status st = check_unused(c, err);
    if (st != DK_OK)
        return st;
    if (c->kind == DK_CONTROL_LATTICE) {
        int64_t product = 1;
        for (int k = 0; k < 3; k++) {
            if (c->resolution[k] < 2)
                return dk_error_set(err, DK_ERR_INVALID_ARGUMENT,
                                    "control: a lattice needs at least 2 points along each "
                                    "axis (resolution %d %d %d)",
                                    (int)c->resolution[0], (int)c->resolution[1],
                                    (int)c->resolution[2]);
            product *= c->resolution[k];
        }
        if (product != c->n_controls)
            return dk_error_set(err, DK_ERR_INVALID_ARGUMENT,
                                "control: a lattice of %d x %d x %d has %lld points, not %d",
                                (int)c->resolution[0], (int)c->resolution[1],
                                (int)c->resolution[2], (long long)product, (int)c->n_controls);
    }
    if (c->n_controls <= 0)
        return dk_error_set(err, DK_ERR_INVALID_ARGUMENT, "control: %s needs n_controls > 0",
                            name);
    if (!c->rest)
        return dk_error_set(err, DK_ERR_INVALID_ARGUMENT, "control: %s needs rest", name);
    const size_t nc = (size_t)c->n_controls;
    switch (c->kind) {
    case DK_CONTROL_POINTS:
        return check_values(c->rest, 3 * nc, "rest", err);
    case DK_CONTROL_CAGE:
        st = check_values(c->rest, 3 * nc, "rest", err);
        return st == DK_OK ? check_cage(c, err) : st;
    case DK_CONTROL_POSES:
        return check_values(c->rest, 3 * nc * (size_t)n_vertices, "rest", err);
    case DK_CONTROL_LATTICE:
        st = check_values(c->rest, 16, "rest", err);
        return st == DK_OK ? check_frame(c->rest, 0, "the lattice's frame", err) : st;
    case DK_CONTROL_BONES:
        st = check_values(c->rest, 16 * nc, "rest", err);
        for (size_t b = 0; st == DK_OK && b < nc; b++)
            st = check_frame(c->rest + 16 * b, (dk_index)b, "bone frame", err);
        return st == DK_OK ? check_weights(c, n_vertices, err) : st;
    default:
        return DK_OK; /* unreachable: the kind was checked above */
    }
}

size_t dk_control_target_count(const dk_control_desc *c)
{
    const size_t nc = c && c->n_controls > 0 ? (size_t)c->n_controls : 0;
    switch (c ? c->kind : DK_CONTROL_VERTEX_GROUPS) {
    case DK_CONTROL_POINTS:
    case DK_CONTROL_CAGE:
    case DK_CONTROL_LATTICE:
        return 3 * nc;
    case DK_CONTROL_BONES:
        return 16 * nc;
    case DK_CONTROL_POSES:
        return nc;
    default:
        return 0;
    }
}
