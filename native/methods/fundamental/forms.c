/* Linear reconstruction's fundamental forms (fundamental_internal.h): the faces' frames and
 * cotangents, the interior edges' rotations, the fins and the pieces with their bridges. */
#include "fundamental_internal.h"

#include <math.h>
#include <stdlib.h>
#include <string.h>

#include "dk_operators.h"

#define COT_MIN 1e-2
#define COT_MAX 1e2
#define PI 3.14159265358979323846

static double clamp_cot(double c)
{
    return !(c >= COT_MIN) ? COT_MIN : c > COT_MAX ? COT_MAX : c;
}

/* Rz(a) or Rx(a) into r (row-major). */
static void rot_z(double a, double r[9])
{
    const double c = cos(a), s = sin(a);
    const double m[9] = {c, -s, 0, s, c, 0, 0, 0, 1};
    memcpy(r, m, sizeof m);
}

static void rot_x(double a, double r[9])
{
    const double c = cos(a), s = sin(a);
    const double m[9] = {1, 0, 0, 0, c, -s, 0, s, c};
    memcpy(r, m, sizeof m);
}

void fr_mat_mul(const double a[9], const double b[9], double o[9])
{
    double t[9];
    for (int i = 0; i < 3; i++)
        for (int j = 0; j < 3; j++)
            t[3 * i + j] = a[3 * i] * b[j] + a[3 * i + 1] * b[3 + j] + a[3 * i + 2] * b[6 + j];
    memcpy(o, t, sizeof t);
}

/* Per face: angles by the law of cosines, 2-D corner coordinates, clamped cotangents, and
 * the rest frame (columns: first edge, normal x first edge, normal). */
void fr_faces(dk_fundamental *f)
{
    const dk_mesh *m = f->mesh;
    for (dk_index t = 0; t < m->n_faces; t++) {
        const dk_index *c = m->faces + 3 * (size_t)t;
        const double *p0 = m->positions + 3 * (size_t)c[0], *p1 = m->positions + 3 * (size_t)c[1];
        const double *p2 = m->positions + 3 * (size_t)c[2];
        double u[3], v[3], w[3], n[3];
        for (int d = 0; d < 3; d++)
            u[d] = p1[d] - p0[d], v[d] = p2[d] - p0[d], w[d] = p2[d] - p1[d];
        const double l01 = sqrt(u[0] * u[0] + u[1] * u[1] + u[2] * u[2]);
        const double l02 = sqrt(v[0] * v[0] + v[1] * v[1] + v[2] * v[2]);
        const double l12 = sqrt(w[0] * w[0] + w[1] * w[1] + w[2] * w[2]);
        n[0] = u[1] * v[2] - u[2] * v[1], n[1] = u[2] * v[0] - u[0] * v[2];
        n[2] = u[0] * v[1] - u[1] * v[0];
        const double nl = sqrt(n[0] * n[0] + n[1] * n[1] + n[2] * n[2]);
        const double lmax = fmax(l01, fmax(l02, l12));
        double *co = f->coord + 6 * (size_t)t, *ct = f->cot + 3 * (size_t)t;
        double *F = f->rest_frame + 9 * (size_t)t;
        f->degenerate[t] = dk_triangle_degenerate(p0, p1, p2, nl, lmax * lmax) || !(l01 > 0.0) ||
                           !(l02 > 0.0);
        if (f->degenerate[t]) {
            memset(co, 0, 6 * sizeof *co);
            memset(ct, 0, 3 * sizeof *ct);
            memset(F, 0, 9 * sizeof *F);
            continue;
        }
        /* from the lengths alone: cosines by the law of cosines, sines from the area by
         * Kahan's stable Heron formula, angles by atan2 (acos alone loses half the digits
         * of small angles, which the reconstruction would show as 1e-8 errors) */
        double sa = l01, sb = l02, sc = l12, tmp;
        if (sa < sb) tmp = sa, sa = sb, sb = tmp;
        if (sb < sc) tmp = sb, sb = sc, sc = tmp;
        if (sa < sb) tmp = sa, sa = sb, sb = tmp;
        const double h2 = (sa + (sb + sc)) * (sc - (sa - sb)) * (sc + (sa - sb)) * (sa + (sb - sc));
        const double area = 0.25 * sqrt(h2 > 0.0 ? h2 : 0.0);
        const double a0 = atan2(2.0 * area, 0.5 * (l01 * l01 + l02 * l02 - l12 * l12));
        const double a1 = atan2(2.0 * area, 0.5 * (l01 * l01 + l12 * l12 - l02 * l02));
        const double a2 = PI - a0 - a1;
        co[0] = 0.0, co[1] = 0.0, co[2] = l01, co[3] = 0.0;
        co[4] = l02 * cos(a0), co[5] = l02 * sin(a0);
        ct[0] = clamp_cot(1.0 / tan(a0));
        ct[1] = clamp_cot(1.0 / tan(a1));
        ct[2] = clamp_cot(a2 > 0.0 ? 1.0 / tan(a2) : COT_MAX);
        double e1[3] = {u[0] / l01, u[1] / l01, u[2] / l01}, e3[3] = {n[0] / nl, n[1] / nl, n[2] / nl};
        double e2[3] = {e3[1] * e1[2] - e3[2] * e1[1], e3[2] * e1[0] - e3[0] * e1[2],
                        e3[0] * e1[1] - e3[1] * e1[0]};
        for (int d = 0; d < 3; d++)
            F[3 * d] = e1[d], F[3 * d + 1] = e2[d], F[3 * d + 2] = e3[d];
    }
}

/* The local corner of vertex v in face t, or -1. */
int fr_corner_of(const dk_mesh *m, dk_index t, dk_index v)
{
    for (int k = 0; k < 3; k++)
        if (m->faces[3 * (size_t)t + k] == v)
            return k;
    return -1;
}

/* The direction angle, in face t's frame, of the edge from corner a to corner b. */
static double edge_angle(const dk_fundamental *f, dk_index t, int a, int b)
{
    const double *co = f->coord + 6 * (size_t)t;
    return atan2(co[2 * b + 1] - co[2 * a + 1], co[2 * b] - co[2 * a]);
}

/* Per interior edge: R_ij = Rz(theta_i) Rx(phi) Rz(-theta_j), the paper's three rotations:
 * theta_i aligns i's e_1 with the shared edge (m -> n as in face i), phi is the dihedral
 * angle turning i's normal into j's about the edge, theta_j is the edge's angle in j. */
dk_status fr_edge_rotations(dk_fundamental *f, dk_error *err)
{
    const dk_mesh *m = f->mesh;
    for (dk_index e = 0; e < m->n_edges; e++) {
        /* (the forms phase's share 0.2 to 0.9, see fr_bind_phases) */
        const dk_status st = dk_progress_tick(f->prog, 0.2 * m->n_edges + 0.7 * e,
                                              (double)m->n_edges, err);
        if (st != DK_OK)
            return st;
        const dk_index ti = m->edge_faces[2 * (size_t)e], tj = m->edge_faces[2 * (size_t)e + 1];
        f->has_R[e] = 0;
        if (ti < 0 || tj < 0 || m->edge_face_count[e] != 2 || f->degenerate[ti] ||
            f->degenerate[tj])
            continue;
        const dk_index a = m->edges[2 * (size_t)e], b = m->edges[2 * (size_t)e + 1];
        int pa = fr_corner_of(m, ti, a), pb = fr_corner_of(m, ti, b);
        /* m -> n in face i's own order */
        const int forward = (pa + 1) % 3 == pb;
        const dk_index vm = forward ? a : b, vn = forward ? b : a;
        const int im = forward ? pa : pb, in = forward ? pb : pa;
        const int jm = fr_corner_of(m, tj, vm), jn = fr_corner_of(m, tj, vn);
        const double th_i = edge_angle(f, ti, im, in), th_j = edge_angle(f, tj, jm, jn);
        const double *Fi = f->rest_frame + 9 * (size_t)ti, *Fj = f->rest_frame + 9 * (size_t)tj;
        const double *xm = m->positions + 3 * (size_t)vm, *xn = m->positions + 3 * (size_t)vn;
        double ed[3] = {xn[0] - xm[0], xn[1] - xm[1], xn[2] - xm[2]};
        const double el = sqrt(ed[0] * ed[0] + ed[1] * ed[1] + ed[2] * ed[2]);
        for (int d = 0; d < 3; d++)
            ed[d] /= el;
        const double ni[3] = {Fi[2], Fi[5], Fi[8]}, nj[3] = {Fj[2], Fj[5], Fj[8]};
        const double e2[3] = {ni[1] * ed[2] - ni[2] * ed[1], ni[2] * ed[0] - ni[0] * ed[2],
                              ni[0] * ed[1] - ni[1] * ed[0]};
        const double phi = atan2(-(nj[0] * e2[0] + nj[1] * e2[1] + nj[2] * e2[2]),
                                 nj[0] * ni[0] + nj[1] * ni[1] + nj[2] * ni[2]);
        double r1[9], r2[9], r3[9], *R = f->R + 9 * (size_t)e;
        rot_z(th_i, r1);
        rot_x(phi, r2);
        rot_z(-th_j, r3);
        fr_mat_mul(r1, r2, R);
        fr_mat_mul(R, r3, R);
        f->has_R[e] = 1;
    }
    return DK_OK;
}

/* Union-find over faces: the root of t, halving the path on the way. */
static dk_index uf_find(dk_index *parent, dk_index t)
{
    while (parent[t] != t)
        t = parent[t] = parent[parent[t]];
    return t;
}

/* F_i^T F_j of the rest frames of faces i and j, into R (row-major): the relative rotation
 * the paper's R_ij gives at rest, for faces that no manifold edge joins. */
static void rest_relative(const dk_fundamental *f, dk_index i, dk_index j, double R[9])
{
    const double *Fi = f->rest_frame + 9 * (size_t)i, *Fj = f->rest_frame + 9 * (size_t)j;
    for (int a = 0; a < 3; a++) /* (F_i^T F_j)[a][b] = sum_d F_i[d][a] F_j[d][b] */
        for (int b = 0; b < 3; b++)
            R[3 * a + b] = Fi[a] * Fj[b] + Fi[3 + a] * Fj[3 + b] + Fi[6 + a] * Fj[6 + b];
}

/* The angle about edge (a, b) of face t's third corner, from the reference direction u0
 * (perpendicular to the unit edge direction d). */
static double fin_angle(const dk_mesh *m, dk_index t, dk_index a, dk_index b, const double d[3],
                        const double u0[3], double u[3])
{
    dk_index c = m->faces[3 * (size_t)t];
    for (int k = 0; k < 3; k++)
        if (m->faces[3 * (size_t)t + k] != a && m->faces[3 * (size_t)t + k] != b)
            c = m->faces[3 * (size_t)t + k];
    const double *pa = m->positions + 3 * (size_t)a, *pc = m->positions + 3 * (size_t)c;
    double w[3] = {pc[0] - pa[0], pc[1] - pa[1], pc[2] - pa[2]};
    const double along = w[0] * d[0] + w[1] * d[1] + w[2] * d[2];
    for (int k = 0; k < 3; k++)
        u[k] = w[k] - along * d[k];
    if (!u0)
        return 0.0;
    const double x[3] = {d[1] * u0[2] - d[2] * u0[1], d[2] * u0[0] - d[0] * u0[2],
                         d[0] * u0[1] - d[1] * u0[0]};
    return atan2(x[0] * u[0] + x[1] * u[1] + x[2] * u[2], u0[0] * u[0] + u0[1] * u[1] + u0[2] * u[2]);
}

/* Fins. A non-manifold edge (k > 2 faces) has no pair of faces the paper's E_f term is
 * defined for; the paper's surfaces are manifold. Our choice: order the edge's non-degenerate
 * faces by angle about it and join each to the next, around the cycle (k pairs; one pair
 * when only two are non-degenerate), by the frame equation f_j = f_i F_i^T F_j, which is the
 * R_ij a manifold edge between them would have at rest, with E_f's weight for that pair's
 * cotangents. So a fin keeps its bending stiffness (treating the edge as a boundary would
 * hinge the sheets on it, held only by the bridges' weak terms), and the energy stays zero
 * at rest and for any rigid or affine motion. The beast of ../shared/meshes has one such edge. */
dk_status fr_fin_pairs(dk_fundamental *f, dk_error *err)
{
    const dk_mesh *m = f->mesh;
    f->n_fins = 0;
    if (m->report.n_nonmanifold_edges == 0)
        return DK_OK;
    size_t cap = 0, maxk = 0;
    for (dk_index e = 0; e < m->n_edges; e++)
        if (m->edge_face_count[e] > 2) {
            cap += (size_t)m->edge_face_count[e];
            maxk = (size_t)m->edge_face_count[e] > maxk ? (size_t)m->edge_face_count[e] : maxk;
        }
    f->fin = malloc((3 * cap + 1) * sizeof *f->fin);
    f->fin_R = malloc((9 * cap + 1) * sizeof *f->fin_R);
    dk_index *ring = malloc((maxk + 1) * sizeof *ring);
    double *ang = malloc((maxk + 1) * sizeof *ang);
    if (!f->fin || !f->fin_R || !ring || !ang) {
        free(ring), free(ang);
        return fr_oom(err, "fins");
    }
    for (dk_index e = 0; e < m->n_edges; e++) {
        if (m->edge_face_count[e] <= 2)
            continue;
        const dk_index a = m->edges[2 * (size_t)e], b = m->edges[2 * (size_t)e + 1];
        const double *pa = m->positions + 3 * (size_t)a, *pb = m->positions + 3 * (size_t)b;
        double d[3] = {pb[0] - pa[0], pb[1] - pa[1], pb[2] - pa[2]}, u0[3], u[3];
        const double dl = sqrt(d[0] * d[0] + d[1] * d[1] + d[2] * d[2]);
        if (!(dl > 0.0))
            continue;
        for (int k = 0; k < 3; k++)
            d[k] /= dl;
        size_t k = 0;
        for (dk_index q = m->vf_start[a]; q < m->vf_start[a + 1] && k < maxk; q++) {
            const dk_index t = m->vf_index[q];
            if (f->degenerate[t] || fr_corner_of(m, t, b) < 0)
                continue;
            if (k == 0)
                fin_angle(m, t, a, b, d, NULL, u0);
            /* insertion sort by angle: k is a handful */
            const double at = k == 0 ? 0.0 : fin_angle(m, t, a, b, d, u0, u);
            size_t p = k++;
            while (p > 0 && ang[p - 1] > at)
                ring[p] = ring[p - 1], ang[p] = ang[p - 1], p--;
            ring[p] = t, ang[p] = at;
        }
        for (size_t p = 0; k >= 2 && p < (k == 2 ? 1 : k); p++) {
            dk_index *fp = f->fin + 3 * (size_t)f->n_fins;
            fp[0] = ring[p], fp[1] = ring[(p + 1) % k], fp[2] = e;
            rest_relative(f, fp[0], fp[1], f->fin_R + 9 * (size_t)f->n_fins);
            f->n_fins++;
        }
    }
    free(ring), free(ang);
    return DK_OK;
}

/* Pieces and bridges. The frame equations (E_f) join two faces across an interior edge
 * between non-degenerate faces; faces that meet at a vertex only, or across a degenerate
 * triangle (which has no frame), are joined by the positions they share and by nothing
 * else. E is invariant under an affine map of positions and frames together, per group of
 * faces the frame equations join ("island"), as long as the maps agree at the vertices the
 * islands share: an island pinned to the rest at three vertices (a part of a scan touching
 * the surface at its corners: the ogre has one of 4 faces) keeps a free shear off the plane
 * of those vertices, and the system is singular (the once-subdivided ogre's "singular at the
 * frame of face 59943"; the ogre itself passed on rounding, with that island's frames
 * undetermined). The paper's surfaces are edge-connected, so it says nothing here. Our
 * choice: at every vertex where islands meet, one "bridge" per island not yet joined ties a
 * face of it to a face of the other, f_j = f_i F_i^T F_j (the rest frames' relative
 * rotation, the R_ij an edge would have) with the regularization's small weight. It is zero
 * at rest and for any rigid or affine motion of the whole, linear (the transform basis stays
 * exact), and it picks, among the equally good results, the one whose pinched part turns
 * with its neighbours; elsewhere it changes nothing beyond rounding. With the bridges, all
 * faces around a vertex are joined, so the pieces that need constraints of their own are
 * the vertices joined through non-degenerate faces (a component cut by degenerate
 * triangles only has several). Out of memory returns DK_ERR_OUT_OF_MEMORY. */
dk_status fr_pieces_and_bridges(dk_fundamental *f, dk_error *err)
{
    const dk_mesh *m = f->mesh;
    const dk_index n = m->n_vertices, F = m->n_faces;
    dk_index *parent = malloc(((size_t)F + 1) * sizeof *parent);
    dk_index *root_piece = malloc(((size_t)F + 1) * sizeof *root_piece);
    dk_index cap = 0;
    if (!parent || !root_piece) {
        free(parent), free(root_piece);
        return fr_oom(err, "pieces");
    }
    for (dk_index t = 0; t < F; t++)
        parent[t] = t, root_piece[t] = -1;
    for (dk_index e = 0; e < m->n_edges; e++) /* the islands */
        if (f->has_R[e]) {
            const dk_index a = uf_find(parent, m->edge_faces[2 * (size_t)e]);
            const dk_index b = uf_find(parent, m->edge_faces[2 * (size_t)e + 1]);
            if (a != b)
                parent[a < b ? b : a] = a < b ? a : b;
        }
    for (dk_index q = 0; q < f->n_fins; q++) { /* and the fins (fr_fin_pairs) */
        const dk_index a = uf_find(parent, f->fin[3 * (size_t)q]);
        const dk_index b = uf_find(parent, f->fin[3 * (size_t)q + 1]);
        if (a != b)
            parent[a < b ? b : a] = a < b ? a : b;
    }
    f->n_bridges = 0;
    for (dk_index v = 0; v < n; v++) { /* the bridges, a spanning forest of the islands */
        dk_index t0 = -1;
        for (dk_index q = m->vf_start[v]; q < m->vf_start[v + 1]; q++) {
            const dk_index t = m->vf_index[q];
            if (f->degenerate[t])
                continue;
            if (t0 < 0) {
                t0 = t;
                continue;
            }
            const dk_index a = uf_find(parent, t0), b = uf_find(parent, t);
            if (a == b)
                continue;
            parent[a < b ? b : a] = a < b ? a : b;
            if (f->n_bridges == cap) {
                const dk_index nc = cap ? 2 * cap : 16;
                dk_index *nb = realloc(f->bridge, 2 * (size_t)nc * sizeof *nb);
                if (nb)
                    f->bridge = nb;
                double *nr = nb ? realloc(f->bridge_R, 9 * (size_t)nc * sizeof *nr) : NULL;
                if (nr)
                    f->bridge_R = nr;
                if (!nb || !nr) {
                    free(parent), free(root_piece);
                    return fr_oom(err, "bridges");
                }
                cap = nc;
            }
            rest_relative(f, t0, t, f->bridge_R + 9 * (size_t)f->n_bridges);
            f->bridge[2 * (size_t)f->n_bridges] = t0;
            f->bridge[2 * (size_t)f->n_bridges + 1] = t;
            f->n_bridges++;
        }
    }
    f->n_pieces = 0;
    for (dk_index v = 0; v < n; v++) { /* a vertex's piece: its faces' root, or its own */
        dk_index t0 = -1;
        for (dk_index q = m->vf_start[v]; q < m->vf_start[v + 1] && t0 < 0; q++)
            if (!f->degenerate[m->vf_index[q]])
                t0 = m->vf_index[q];
        if (t0 < 0) {
            f->piece[v] = f->n_pieces++;
            continue;
        }
        const dk_index r = uf_find(parent, t0);
        if (root_piece[r] < 0)
            root_piece[r] = f->n_pieces++;
        f->piece[v] = root_piece[r];
    }
    free(parent), free(root_piece);
    f->piece_rep = malloc(((size_t)f->n_pieces + 1) * sizeof *f->piece_rep);
    f->comp_fit = malloc(25 * ((size_t)f->n_pieces + 1) * sizeof *f->comp_fit);
    if (!f->piece_rep || !f->comp_fit)
        return fr_oom(err, "pieces");
    for (dk_index c = 0; c < f->n_pieces; c++)
        f->piece_rep[c] = -1;
    for (dk_index v = n - 1; v >= 0; v--)
        f->piece_rep[f->piece[v]] = v;
    return DK_OK;
}
