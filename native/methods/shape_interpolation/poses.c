/* Shape interpolation: triangle frames, and what the bind keeps of each pose (rotation
 * vectors with their branches, residuals, stretches, the parts' mean displacements). */
#include "si_internal.h"

#include <math.h>
#include <stdlib.h>
#include <string.h>

#include "dk_memory.h"
#include "dk_operators.h"

void si_frame(const double *p0, const double *p1, const double *p2, double V[9])
{
    double e1[3], e2[3], n[3];
    for (int d = 0; d < 3; d++) {
        e1[d] = p1[d] - p0[d];
        e2[d] = p2[d] - p0[d];
    }
    n[0] = e1[1] * e2[2] - e1[2] * e2[1];
    n[1] = e1[2] * e2[0] - e1[0] * e2[2];
    n[2] = e1[0] * e2[1] - e1[1] * e2[0];
    const double len = sqrt(n[0] * n[0] + n[1] * n[1] + n[2] * n[2]);
    const double f = len > 0.0 ? 1.0 / sqrt(len) : 0.0;
    for (int d = 0; d < 3; d++) {
        V[3 * d] = e1[d];
        V[3 * d + 1] = e2[d];
        V[3 * d + 2] = n[d] * f;
    }
}

void si_rest_frames(const dk_mesh *mesh, double *vinv, unsigned char *degenerate)
{
    const double *x = mesh->positions;
    for (dk_index t = 0; t < mesh->n_faces; t++) {
        const dk_index *f = mesh->faces + 3 * (size_t)t;
        const double *p0 = x + 3 * (size_t)f[0], *p1 = x + 3 * (size_t)f[1],
                     *p2 = x + 3 * (size_t)f[2];
        double V[9], C[9];
        si_frame(p0, p1, p2, V);
        double longest2 = 0.0, nn = 0.0;
        for (int k = 0; k < 3; k++) {
            const double *a = x + 3 * (size_t)f[k], *b = x + 3 * (size_t)f[(k + 1) % 3];
            double l2 = 0.0;
            for (int d = 0; d < 3; d++)
                l2 += (a[d] - b[d]) * (a[d] - b[d]);
            longest2 = fmax(longest2, l2);
        }
        for (int d = 0; d < 3; d++) /* the third column is n / sqrt|n|: |n| = its length^2 */
            nn += V[3 * d + 2] * V[3 * d + 2];
        const double det = dk_mat3_cofactor(V, C);
        double *vi = vinv + 9 * (size_t)t;
        degenerate[t] = (unsigned char)(dk_triangle_degenerate(p0, p1, p2, nn, longest2) ||
                                        !(fabs(det) > 0.0) || !isfinite(det));
        for (int r = 0; r < 3; r++)
            for (int c = 0; c < 3; c++)
                vi[3 * r + c] = degenerate[t] ? 0.0 : C[3 * c + r] / det;
    }
}

void si_poses_free(si_poses *p)
{
    if (!p)
        return;
    free(p->positions);
    free(p->omega);
    free(p->eps);
    free(p->stretch);
    free(p->shift);
    memset(p, 0, sizeof *p);
}

/* Pose `pose`'s rotation R (9) and stretch S (6: xx, xy, xz, yy, yz, zz) of the
 * non-degenerate triangle t. */
static void pose_rotation(const dk_mesh *mesh, const double *vinv, const double *pose,
                          dk_index t, double R[9], double S[6])
{
    const dk_index *f = mesh->faces + 3 * (size_t)t;
    double V[9], J[9], RJ[9];
    si_frame(pose + 3 * (size_t)f[0], pose + 3 * (size_t)f[1], pose + 3 * (size_t)f[2], V);
    si_mat3_mul(V, vinv + 9 * (size_t)t, J);
    dk_closest_rotation(J, R);
    si_mat3_tmul(R, J, RJ); /* S = R^T J, symmetrised */
    S[0] = RJ[0];
    S[1] = 0.5 * (RJ[1] + RJ[3]);
    S[2] = 0.5 * (RJ[2] + RJ[6]);
    S[3] = RJ[4];
    S[4] = 0.5 * (RJ[5] + RJ[7]);
    S[5] = RJ[8];
}

/* A triangle's sort key for the roots: those touching a seed vertex first, each group by
 * its rotation angles summed over the poses (the least turned first), ties by index. */
typedef struct keyed {
    double key;
    dk_index t;
} keyed;

static int by_key(const void *a, const void *b)
{
    const keyed *x = a, *y = b;
    if (x->key != y->key)
        return x->key < y->key ? -1 : 1;
    return (x->t > y->t) - (x->t < y->t);
}

static int touches(const dk_mesh *m, dk_index t, const unsigned char *seed_vertex)
{
    if (!seed_vertex)
        return 0;
    const dk_index *f = m->faces + 3 * (size_t)t;
    return seed_vertex[f[0]] || seed_vertex[f[1]] || seed_vertex[f[2]];
}

/* Pose k's rotations into R (identity where degenerate) and stretches as the blend takes
 * them (S - I, or log S for `stretches` LOG; 0 where degenerate); adds each rotation's angle
 * to keys[t].key when keys is given. */
static void rotations_of(const dk_mesh *m, const double *vinv, const unsigned char *degenerate,
                         const double *pose, dk_shape_interpolation_stretches stretches,
                         double *R, double *stretch, keyed *keys)
{
    static const double I[9] = {1, 0, 0, 0, 1, 0, 0, 0, 1};
    for (dk_index t = 0; t < m->n_faces; t++) {
        double *Rt = R + 9 * (size_t)t, *S = stretch + 6 * (size_t)t;
        if (degenerate[t]) {
            memcpy(Rt, I, sizeof I);
            memset(S, 0, 6 * sizeof(double));
            continue;
        }
        double full[6];
        pose_rotation(m, vinv, pose, t, Rt, full);
        if (stretches == DK_SI_STRETCHES_LOG) {
            si_sym_log(full, S);
        } else {
            memcpy(S, full, sizeof full);
            S[0] -= 1.0, S[3] -= 1.0, S[5] -= 1.0;
        }
        if (keys) {
            double w[3];
            keys[t].key += si_rotation_log(Rt, w);
        }
    }
}

/* The parts' mean displacements in `pose` (3 per component), with `count` scratch. */
static void part_shifts(const dk_mesh *m, const double *pose, double *shift, double *count)
{
    const dk_index nc = m->report.n_components;
    memset(shift, 0, 3 * (size_t)nc * sizeof(double));
    memset(count, 0, (size_t)nc * sizeof(double));
    for (dk_index v = 0; v < m->n_vertices; v++) {
        const dk_index c = m->component[v];
        for (int d = 0; d < 3; d++)
            shift[3 * (size_t)c + d] += pose[3 * (size_t)v + d] - m->positions[3 * (size_t)v + d];
        count[c] += 1.0;
    }
    for (dk_index c = 0; c < nc; c++)
        for (int d = 0; d < 3; d++)
            shift[3 * (size_t)c + d] /= count[c] > 0.0 ? count[c] : 1.0;
}

dk_status si_poses_build(const dk_mesh *mesh, const double *vinv, const unsigned char *degenerate,
                         const double *poses, dk_index n_poses,
                         const dk_shape_interpolation_options *options,
                         const unsigned char *seed_vertex, si_poses *out, dk_progress *progress,
                         int phase, dk_error *err)
{
    const dk_shape_interpolation_rotations rotations = options->rotations;
    memset(out, 0, sizeof *out);
    dk_status st = dk_progress_begin(progress, phase, err);
    if (st != DK_OK || n_poses == 0)
        return st;
    const size_t P = (size_t)n_poses, F = (size_t)mesh->n_faces, n = (size_t)mesh->n_vertices;
    const size_t nc = (size_t)mesh->report.n_components;
    out->n_poses = n_poses;
    out->positions = malloc(P * n * 3 * sizeof(double) + 1);
    out->omega = malloc(P * F * 3 * sizeof(double) + 1);
    out->eps = malloc(P * F * 3 * sizeof(double) + 1);
    out->stretch = malloc(P * F * 6 * sizeof(double) + 1);
    out->shift = malloc(P * nc * 3 * sizeof(double) + 1);
    double *R = malloc(F * 9 * sizeof(double) + 1), *count = malloc(nc * sizeof(double) + 1);
    keyed *keys = malloc(F * sizeof *keys + 1);
    dk_index *by = malloc(F * sizeof *by + 1);
    si_lift lift;
    memset(&lift, 0, sizeof lift);
    if (!out->positions || !out->omega || !out->eps || !out->stretch || !out->shift || !R ||
        !count || !keys || !by)
        st = dk_error_set(err, DK_ERR_OUT_OF_MEMORY,
                          "ShapeInterpolation: out of memory (%d poses of %d triangles)",
                          (int)n_poses, (int)F);
    if (st == DK_OK) {
        memcpy(out->positions, poses, P * n * 3 * sizeof(double));
        for (size_t t = 0; t < F; t++) {
            keys[t].key = touches(mesh, (dk_index)t, seed_vertex) ? 0.0 : 4.0 * (double)P;
            keys[t].t = (dk_index)t;
        }
    }
    /* the lift's roots, from the poses' angles */
    for (size_t k = 0; k < P && st == DK_OK; k++) {
        rotations_of(mesh, vinv, degenerate, poses + k * n * 3, options->stretches, R,
                     out->stretch + k * F * 6, keys);
        st = dk_progress_part(progress, 0.5 * (double)(k + 1) / (double)P, err);
    }
    if (st == DK_OK && rotations == DK_SI_ROTATIONS_CONSISTENT) {
        qsort(keys, F, sizeof *keys, by_key);
        for (size_t t = 0; t < F; t++)
            by[t] = keys[t].t;
        st = si_lift_build(mesh, degenerate, by, &lift, err);
    }
    for (size_t k = 0; k < P && st == DK_OK; k++) {
        double *om = out->omega + k * F * 3, *ep = out->eps + k * F * 3;
        rotations_of(mesh, vinv, degenerate, poses + k * n * 3, options->stretches, R,
                     out->stretch + k * F * 6, NULL);
        if (rotations == DK_SI_ROTATIONS_CONSISTENT) {
            st = si_lift_pose(&lift, mesh, degenerate, R, om, ep, err);
        } else {
            for (size_t t = 0; t < F; t++)
                si_rotation_log(R + 9 * t, om + 3 * t);
            memset(ep, 0, 3 * F * sizeof(double));
        }
        if (st != DK_OK)
            break; /* the lift's solve failed: omega and eps are not written */
        part_shifts(mesh, poses + k * n * 3, out->shift + k * nc * 3, count);
        st = dk_progress_part(progress, 0.5 + 0.5 * (double)(k + 1) / (double)P, err);
    }
    free(R);
    free(count);
    free(keys);
    free(by);
    si_lift_free(&lift);
    if (st != DK_OK)
        si_poses_free(out);
    return st;
}
