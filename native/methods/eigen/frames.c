/* DeformKit EigenDeformation: local frames and Step 3's detail recovery
 * (eigen_internal.h). */
#include "eigen_internal.h"

#include <math.h>
#include <stdlib.h>
#include <string.h>

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
double eigen_frame_threshold(const dk_mesh *mesh)
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
void eigen_record_frames(const dk_eigen *e, level *L, double *nrm)
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

/* Step 3 on level L: out = p* + d~, with d~ the local-frame detail (frames of p*) blended
 * with the transformation-based one by w (blend = 1) or the local-frame one alone. A vertex
 * whose frame is undefined (on the rest or the deformed skeleton) takes the
 * transformation-based detail. */
void eigen_step3(dk_eigen *e, const level *L, const double *pstar, int blend, double *out)
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
