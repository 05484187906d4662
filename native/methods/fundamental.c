/* DeformKit: linear reconstruction from discrete fundamental forms with a material map.
 * See dk_fundamental.h for the method and docs/methods/fundamental.md for the choices. */
#include "dk_fundamental.h"

#include <float.h>
#include <limits.h>
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include <cblas.h>
#include <lapacke.h>

#include "dk_cholesky.h"
#include "dk_operators.h"
#include "dk_progress.h"
#include "dk_sparse.h"

#define COT_MIN 1e-2
#define COT_MAX 1e2
#define PI 3.14159265358979323846

/* The phases of a bind and of a rebind (dk_progress.h), weighted by their cost in seconds
 * measured on the ogre subdivided once (248,324 vertices, 1.56M unknowns; bench_scale.py's
 * ogre scenario: the lowest 10% fixed, one handle, so a 7-column transform basis) on the
 * shared 2-core machine (load ~1.4), timed between the callback's reports: 17.7 s in all.
 * On the 692k armadillo (load ~6, no basis: it would pass 256 MB) the same phases took
 * 4.8, 0.25, 18.0, 42.0 and 114.4 s of 179 s, about the same shares; the factorization is
 * the longest stretch without a report. Within "forms": the faces ~0.2 of it, the edge
 * rotations ~0.7 (asked every few thousand edges), the pieces ~0.1. The rebind's phases
 * are the bind's from FR_PHASE_CONSTRAINTS on, in the same order. */
enum {
    FR_PHASE_CONSTRAINTS = 0, /* the constraints, the numbering, the pieces' check          */
    FR_PHASE_ASSEMBLE = 1,    /* the energy's matrices, two passes over the residuals       */
    FR_PHASE_ANALYZE = 2,     /* CHOLMOD's symbolic analysis (uninterruptible)             */
    FR_PHASE_FACTORIZE = 3,   /* CHOLMOD's numeric factorization (uninterruptible)         */
    FR_PHASE_BASIS = 4        /* the transform basis: its right-hand sides and solves      */
};
static const dk_progress_phase fr_bind_phases[] = {
    {"forms", 0.72},       /* the fundamental forms, the pieces and bridges              */
    {"constraints", 0.02}, /* FR_PHASE_CONSTRAINTS ...                                  */
    {"assemble", 2.30},
    {"analyze", 3.83},
    {"factorize", 10.0},
    {"basis", 0.80}};
static const dk_progress_phase fr_rebind_phases[] = {
    {"constraints", 0.02}, {"assemble", 2.30}, {"analyze", 3.83}, {"factorize", 10.0},
    {"basis", 0.80}};
#define FR_BIND_PHASE_BASE 1 /* FR_PHASE_CONSTRAINTS in fr_bind_phases */

/* What depends on the constraints, replaced as a whole by rebind. */
typedef struct elim {
    dk_constraints *con;
    dk_index n_unk, n_con;     /* per coordinate                                             */
    int any_anchor;            /* some face is regularized (fa >= 0)                         */
    dk_index *vu, *vc;         /* n: free / constrained index of each vertex, or -1          */
    dk_index *fu, *fc;         /* F: first of the frame's 3 free / constrained indices, or -1 */
    dk_index *face_handle;     /* F: the handle prescribing the frame, -2 fixed, -1 none     */
    dk_index *fa;              /* F: first of the 3 constrained slots holding the anchor
                                  frame row a regularized face is drawn to, or -1            */
    dk_sparse *A, *B;          /* n_unk x n_unk (upper triangle; freed once factored);
                                  n_unk x n_con                                               */
    dk_cholesky *chol;
    double *zc, *rhs, *lin, *tgt; /* solve buffers                                           */
    /* The transform basis (NULL when not built): the solution is affine in the handles'
     * transforms, z_d = S_d + sum_{h,j} T_h[d][j] G_{4h+j} for coordinate d, so a solve
     * with transforms is one small dense product instead of two triangular solves.
     * basis: n_unk x (4 n_handles + 3) column-major, G then S; coef: (4 n_handles) x 3. */
    double *basis, *coef;
} elim;

struct dk_fundamental {
    const dk_mesh *mesh;
    dk_fundamental_options opt;
    double *material;          /* n_edges                                                    */
    /* the fundamental forms, per face and per interior edge */
    unsigned char *degenerate; /* F                                                          */
    double *coord;             /* F x 6: the corners' 2-D coordinates in the face's frame    */
    double *cot;               /* F x 3: clamped cot of the angle at corner k                */
    double *rest_frame;        /* F x 9                                                      */
    double *R;                 /* n_edges x 9                                                */
    unsigned char *has_R;      /* n_edges                                                    */
    /* Pieces and bridges (see pieces_and_bridges): the frame equations join faces across
     * interior edges only, so faces meeting at a vertex alone (a part pinched on at its
     * corners) or across a degenerate triangle are not joined by them. */
    dk_index *piece;           /* n_vertices: the piece (vertices joined through faces that
                                  have a frame), 0..n_pieces-1                               */
    dk_index n_pieces;
    dk_index *piece_rep;       /* n_pieces: a vertex of each, for messages                   */
    /* Fins (see fin_pairs): a non-manifold edge's faces, joined by frame equations between
     * neighbours in their order around the edge. */
    dk_index n_fins;
    dk_index *fin;             /* n_fins x 3: faces i, j and their edge                      */
    double *fin_R;             /* n_fins x 9: f_i^T f_j of the rest frames                   */
    dk_index n_bridges;
    dk_index *bridge;          /* n_bridges x 2: faces i, j whose frames are tied weakly     */
    double *bridge_R;          /* n_bridges x 9: f_i^T f_j of the rest frames              */
    elim el;                   /* the elimination of the current constraints             */
    double *frames;            /* F x 9: the last solve's frames                          */
    double *comp_fit;          /* n_pieces x 25: per piece, the sums for the
                                  rotation that best fits its constrained vertices (count,
                                  rest sum 3, target sum 3, cross moments 9) and R (9)       */
    double w_scaled;           /* w times the mean edge length squared: E_f is dimensionless
                                  and E_x a squared length, so this keeps w scale-free      */
    /* during a bind or rebind only (NULL otherwise): its progress reporter, and the index
     * of FR_PHASE_CONSTRAINTS in its phase table */
    dk_progress *prog;
    int prog_base;
};

static dk_status fr_phase(const dk_fundamental *f, int k, dk_error *err)
{
    return dk_progress_begin(f->prog, f->prog_base + k, err);
}

static dk_status oom(dk_error *err, const char *what)
{
    return dk_error_set(err, DK_ERR_OUT_OF_MEMORY, "LinearReconstruction: out of memory (%s)",
                        what);
}

void dk_fundamental_default_options(dk_fundamental_options *o)
{
    memset(o, 0, sizeof *o);
    o->w = 1.0;
}

/* ------------------------------------------------------------------ fundamental forms -- */

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

static void mat_mul(const double a[9], const double b[9], double o[9])
{
    double t[9];
    for (int i = 0; i < 3; i++)
        for (int j = 0; j < 3; j++)
            t[3 * i + j] = a[3 * i] * b[j] + a[3 * i + 1] * b[3 + j] + a[3 * i + 2] * b[6 + j];
    memcpy(o, t, sizeof t);
}

/* Per face: angles by the law of cosines, 2-D corner coordinates, clamped cotangents, and
 * the rest frame (columns: first edge, normal x first edge, normal). */
static void faces(dk_fundamental *f)
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
static int corner_of(const dk_mesh *m, dk_index t, dk_index v)
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
static dk_status edge_rotations(dk_fundamental *f, dk_error *err)
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
        int pa = corner_of(m, ti, a), pb = corner_of(m, ti, b);
        /* m -> n in face i's own order */
        const int forward = (pa + 1) % 3 == pb;
        const dk_index vm = forward ? a : b, vn = forward ? b : a;
        const int im = forward ? pa : pb, in = forward ? pb : pa;
        const int jm = corner_of(m, tj, vm), jn = corner_of(m, tj, vn);
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
        mat_mul(r1, r2, R);
        mat_mul(R, r3, R);
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
static dk_status fin_pairs(dk_fundamental *f, dk_error *err)
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
        return oom(err, "fins");
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
            if (f->degenerate[t] || corner_of(m, t, b) < 0)
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
static dk_status pieces_and_bridges(dk_fundamental *f, dk_error *err)
{
    const dk_mesh *m = f->mesh;
    const dk_index n = m->n_vertices, F = m->n_faces;
    dk_index *parent = malloc(((size_t)F + 1) * sizeof *parent);
    dk_index *root_piece = malloc(((size_t)F + 1) * sizeof *root_piece);
    dk_index cap = 0;
    if (!parent || !root_piece) {
        free(parent), free(root_piece);
        return oom(err, "pieces");
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
    for (dk_index q = 0; q < f->n_fins; q++) { /* and the fins (fin_pairs) */
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
                    return oom(err, "bridges");
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
        return oom(err, "pieces");
    for (dk_index c = 0; c < f->n_pieces; c++)
        f->piece_rep[c] = -1;
    for (dk_index v = n - 1; v >= 0; v--)
        f->piece_rep[f->piece[v]] = v;
    return DK_OK;
}

/* ------------------------------------------------------------------ residuals ---------- */

/* One residual of one coordinate: weight and up to 4 terms, each a vertex (frame < 0) or
 * entry k of a face's frame row. */
typedef struct term {
    dk_index id;
    int k; /* -1: vertex id; 0..2: entry k of face id's frame row; 3..5: entry k - 3 of its
              rest frame row (a constant: the regularization's anchor) */
    double c;
} term;

/* The weight, relative to w, that draws the frames of an under-constrained component to
 * their rest frames (see eliminate). */
#define REGULARIZATION 1e-8

typedef void (*visit_fn)(void *ctx, double weight, const term *t, int nt);

/* The weight of E_f's residuals across edge e between faces ti and tj (eq. 6):
 * w / (material_e (cot alpha + cot beta)), the angles opposite e in the two faces. */
static double frame_weight(const dk_fundamental *f, dk_index ti, dk_index tj, dk_index e)
{
    const dk_mesh *m = f->mesh;
    const dk_index a = m->edges[2 * (size_t)e], b = m->edges[2 * (size_t)e + 1];
    const int ki = corner_of(m, ti, a) ^ corner_of(m, ti, b) ^ 3;
    const int kj = corner_of(m, tj, a) ^ corner_of(m, tj, b) ^ 3;
    const double we = f->cot[3 * (size_t)ti + ki] + f->cot[3 * (size_t)tj + kj];
    return f->w_scaled / (f->material[e] * we);
}

/* The three residuals f_j - f_i R (one per entry k of the frame rows), with weight wgt. */
static void visit_frame_pair(dk_index ti, dk_index tj, const double R[9], double wgt,
                             visit_fn visit, void *ctx)
{
    for (int k = 0; k < 3; k++) {
        const term tt[4] = {{tj, k, 1.0}, {ti, 0, -R[k]}, {ti, 1, -R[3 + k]},
                            {ti, 2, -R[6 + k]}};
        visit(ctx, wgt, tt, 4);
    }
}

/* Every residual of E = w E_f + E_x (eqs. 5-7), the same for each coordinate. */
static void for_each_residual(const dk_fundamental *f, visit_fn visit, void *ctx)
{
    const dk_mesh *m = f->mesh;
    for (dk_index t = 0; t < m->n_faces; t++) { /* E_x: each edge of each face */
        if (f->degenerate[t])
            continue;
        const dk_index *c = m->faces + 3 * (size_t)t;
        const double *co = f->coord + 6 * (size_t)t;
        for (int k = 0; k < 3; k++) {
            const int a = (k + 1) % 3, b = (k + 2) % 3; /* the edge opposite corner k */
            const dk_index e = m->face_edges[3 * (size_t)t + k];
            const double wgt = f->material[e] * f->cot[3 * (size_t)t + k];
            const term tt[4] = {{c[b], -1, 1.0}, {c[a], -1, -1.0},
                                {t, 0, -(co[2 * b] - co[2 * a])},
                                {t, 1, -(co[2 * b + 1] - co[2 * a + 1])}};
            visit(ctx, wgt, tt, 4);
        }
    }
    for (dk_index e = 0; e < m->n_edges; e++) { /* E_f: f_j - f_i R_ij across interior edges */
        if (!f->has_R[e])
            continue;
        const dk_index ti = m->edge_faces[2 * (size_t)e], tj = m->edge_faces[2 * (size_t)e + 1];
        visit_frame_pair(ti, tj, f->R + 9 * (size_t)e, frame_weight(f, ti, tj, e), visit, ctx);
    }
    for (dk_index q = 0; q < f->n_fins; q++) { /* E_f on the fins (fin_pairs) */
        const dk_index ti = f->fin[3 * (size_t)q], tj = f->fin[3 * (size_t)q + 1];
        const dk_index e = f->fin[3 * (size_t)q + 2];
        visit_frame_pair(ti, tj, f->fin_R + 9 * (size_t)q, frame_weight(f, ti, tj, e), visit,
                         ctx);
    }
    for (dk_index b = 0; b < f->n_bridges; b++) /* the bridges (pieces_and_bridges) */
        visit_frame_pair(f->bridge[2 * (size_t)b], f->bridge[2 * (size_t)b + 1],
                         f->bridge_R + 9 * (size_t)b, REGULARIZATION * f->w_scaled, visit, ctx);
    for (dk_index t = 0; f->el.fa && t < m->n_faces; t++) /* the regularization, where needed */
        if (f->el.fa[t] >= 0)
            for (int k = 0; k < 3; k++) {
                const term tt[2] = {{t, k, 1.0}, {t, 3 + k, -1.0}};
                visit(ctx, REGULARIZATION * f->w_scaled, tt, 2);
            }
}

/* The unknown (free >= 0) or constraint (encoded -2 - index) index of a term. */
static dk_index slot(const dk_fundamental *f, const term *t)
{
    if (t->k < 0)
        return f->el.vu[t->id] >= 0 ? f->el.vu[t->id] : -2 - f->el.vc[t->id];
    if (t->k >= 3)
        return -2 - (f->el.fa[t->id] + t->k - 3);
    return f->el.fu[t->id] >= 0 ? f->el.fu[t->id] + t->k : -2 - (f->el.fc[t->id] + t->k);
}

/* The energy's matrices, assembled straight into columns in two passes over the residuals
 * (issue 19, memory): the first counts each column's entries, the second writes them; A's
 * upper triangle only (CHOLMOD reads no more). Triplets of the whole A (16 bytes an entry,
 * plus 12 for dk_sparse_from_triplets's copy) were the bind's peak up to ~60k vertices:
 * 28 bytes for each of ~230 per vertex, against 12 for each of ~120 now. */
typedef struct assembly {
    const dk_fundamental *f;
    int fill;                 /* 0: count into a_next[j + 1], b_next[j + 1]; 1: write      */
    int64_t *a_next, *b_next; /* per column of A (n_unk + 1), of B (n_con + 1)             */
    dk_index *ar, *br;
    double *av, *bv;
    /* progress: residuals visited in both passes, an estimate of one pass's count, and the
     * first failure (a cancellation), after which the visits do nothing */
    double visits, per_pass;
    dk_status st;
    dk_error *err;
} assembly;

static void assemble_visit(void *ctx, double w, const term *t, int nt)
{
    assembly *s = ctx;
    if (s->st != DK_OK ||
        (s->st = dk_progress_tick(s->f->prog, s->visits++, 2.0 * s->per_pass, s->err)) != DK_OK)
        return;
    dk_index idx[4];
    for (int i = 0; i < nt; i++)
        idx[i] = slot(s->f, t + i);
    for (int i = 0; i < nt; i++) {
        if (idx[i] < 0)
            continue;
        for (int j = 0; j < nt; j++) {
            if (t[i].c == 0.0 || t[j].c == 0.0)
                continue;
            if (idx[j] >= 0) {
                if (idx[i] > idx[j])
                    continue; /* the lower triangle */
                if (!s->fill) {
                    s->a_next[idx[j] + 1]++;
                } else {
                    const int64_t p = s->a_next[idx[j]]++;
                    s->ar[p] = idx[i], s->av[p] = w * t[i].c * t[j].c;
                }
            } else {
                const dk_index col = -2 - idx[j];
                if (!s->fill) {
                    s->b_next[col + 1]++;
                } else {
                    const int64_t p = s->b_next[col]++;
                    s->br[p] = idx[i], s->bv[p] = w * t[i].c * t[j].c;
                }
            }
        }
    }
}

/* Counts, allocates and writes A (upper triangle) and B of the numbering in `view`. */
static dk_status assemble(const dk_fundamental *view, dk_index nu, dk_index ncon, dk_sparse **A,
                          dk_sparse **B, dk_error *err)
{
    const dk_index nb_cols = ncon > 0 ? ncon : 1;
    assembly a = {view, 0, calloc((size_t)nu + 2, sizeof(int64_t)),
                  calloc((size_t)nb_cols + 2, sizeof(int64_t)), NULL, NULL, NULL, NULL,
                  0.0, 3.0 * ((double)view->mesh->n_faces + (double)view->mesh->n_edges +
                              (double)view->n_bridges + (double)view->n_fins), DK_OK, err};
    int64_t *a_start = malloc(((size_t)nu + 2) * sizeof(int64_t));
    int64_t *b_start = malloc(((size_t)nb_cols + 2) * sizeof(int64_t));
    dk_status st = DK_OK;
    if (!a.a_next || !a.b_next || !a_start || !b_start) {
        st = oom(err, "assembly");
        goto done;
    }
    for_each_residual(view, assemble_visit, &a);
    if ((st = a.st) != DK_OK)
        goto done;
    for (dk_index j = 0; j < nu; j++)
        a.a_next[j + 1] += a.a_next[j];
    for (dk_index j = 0; j < nb_cols; j++)
        a.b_next[j + 1] += a.b_next[j];
    memcpy(a_start, a.a_next, ((size_t)nu + 1) * sizeof(int64_t));
    memcpy(b_start, a.b_next, ((size_t)nb_cols + 1) * sizeof(int64_t));
    const size_t na = (size_t)a_start[nu], nbe = (size_t)b_start[nb_cols];
    a.ar = malloc((na + 1) * sizeof(dk_index)), a.av = malloc((na + 1) * sizeof(double));
    a.br = malloc((nbe + 1) * sizeof(dk_index)), a.bv = malloc((nbe + 1) * sizeof(double));
    if (!a.ar || !a.av || !a.br || !a.bv) {
        free(a.ar), free(a.av), free(a.br), free(a.bv);
        st = oom(err, "assembly");
        goto done;
    }
    a.fill = 1;
    a.visits = a.per_pass; /* the second pass: the first one's share is done */
    for_each_residual(view, assemble_visit, &a);
    if ((st = a.st) != DK_OK) {
        free(a.ar), free(a.av), free(a.br), free(a.bv);
        goto done;
    }
    /* (both take the arrays, on every path) */
    st = dk_sparse_from_columns(nu, nu, a_start, a.ar, a.av, A, err);
    if (st == DK_OK)
        st = dk_sparse_from_columns(nu, nb_cols, b_start, a.br, a.bv, B, err);
    else
        free(a.br), free(a.bv);
done:
    free(a.a_next), free(a.b_next), free(a_start), free(b_start);
    return st;
}

typedef struct evaluation {
    const dk_fundamental *f;
    const double *x, *frames;
    double E;
} evaluation;

static void energy_visit(void *ctx, double w, const term *t, int nt)
{
    evaluation *s = ctx;
    for (int d = 0; d < 3; d++) {
        double r = 0.0;
        for (int i = 0; i < nt; i++)
            r += t[i].c * (t[i].k < 0    ? s->x[3 * (size_t)t[i].id + d]
                           : t[i].k < 3 ? s->frames[9 * (size_t)t[i].id + 3 * d + t[i].k]
                                        : s->f->el.zc[(size_t)d * s->f->el.n_con + s->f->el.fa[t[i].id] +
                                                   t[i].k - 3]);
        s->E += 0.5 * w * r * r;
    }
}

/* ------------------------------------------------------------------ elimination -------- */


static void elim_free(elim *s)
{
    dk_constraints_free(s->con);
    free(s->vu);
    free(s->vc);
    free(s->fu);
    free(s->fc);
    free(s->face_handle);
    free(s->fa);
    dk_sparse_free(s->A);
    dk_sparse_free(s->B);
    dk_cholesky_free(s->chol);
    free(s->zc);
    free(s->rhs);
    free(s->lin);
    free(s->tgt);
    free(s->basis);
    free(s->coef);
    memset(s, 0, sizeof *s);
}

/* Before any solve the anchors are the rest frames (for the energy). */
static void rest_anchors(dk_fundamental *f)
{
    const size_t nc = (size_t)f->el.n_con;
    for (dk_index t = 0; t < f->mesh->n_faces; t++)
        if (f->el.fa[t] >= 0)
            for (int d = 0; d < 3; d++)
                for (int k = 0; k < 3; k++)
                    f->el.zc[(size_t)d * nc + f->el.fa[t] + k] = f->rest_frame[9 * (size_t)t + 3 * d + k];
}

static void elim_install(dk_fundamental *f, elim *s)
{
    elim_free(&f->el);
    f->el = *s;
    memset(s, 0, sizeof *s);
    rest_anchors(f);
}

/* Every piece (pieces_and_bridges: a connected component, or a part of one that only
 * degenerate triangles join to the rest) must be held by a constraint, else its translation
 * is free. A component without any constraint is held at rest by dk_constraints already, so
 * what is left to refuse is a part cut off by degenerate triangles: the error names a vertex
 * of it and a degenerate triangle on its rim. The frames are linear unknowns, so the energy
 * is invariant under any affine map of a piece's positions and frames together:
 * constraints pin that map only when the piece's constrained vertices span space (four not
 * in a plane) or a face's frame is prescribed. A piece held more thinly (a planar rim, a
 * line, one vertex) gets `thin` = 1: eliminate() then draws its frames weakly
 * (REGULARIZATION) to their rest frames turned by the rotation that best fits the piece's
 * constrained vertices to their targets (solve), which picks, among the equally good
 * results, the one without a free shear, and keeps a rigid motion of every constraint
 * exact. */
static dk_status check_components(const dk_fundamental *f, const elim *s, unsigned char *thin,
                                  dk_error *err)
{
    const dk_mesh *m = f->mesh;
    const dk_index nc = f->n_pieces;
    dk_index *cv = calloc((size_t)nc + 1, sizeof *cv), *cf = calloc((size_t)nc + 1, sizeof *cf);
    double *mom = calloc(9 * (size_t)nc + 1, sizeof *mom), *mean = calloc(3 * (size_t)nc + 1, sizeof *mean);
    if (!cv || !cf || !mom || !mean) {
        free(cv), free(cf), free(mom), free(mean);
        return oom(err, "components");
    }
    for (dk_index v = 0; v < m->n_vertices; v++) {
        const dk_index c = f->piece[v];
        if (s->vc[v] < 0)
            continue;
        cv[c]++;
        for (int d = 0; d < 3; d++)
            mean[3 * (size_t)c + d] += m->positions[3 * (size_t)v + d];
    }
    for (dk_index v = 0; v < m->n_vertices; v++) { /* the constrained vertices' covariance */
        const dk_index c = f->piece[v];
        if (s->vc[v] < 0)
            continue;
        double q[3];
        for (int d = 0; d < 3; d++)
            q[d] = m->positions[3 * (size_t)v + d] - mean[3 * (size_t)c + d] / (double)cv[c];
        for (int a = 0; a < 3; a++)
            for (int b = 0; b < 3; b++)
                mom[9 * (size_t)c + 3 * a + b] += q[a] * q[b];
    }
    for (dk_index t = 0; t < m->n_faces; t++)
        if (s->fc[t] >= 0)
            cf[f->piece[m->faces[3 * (size_t)t]]]++;
    dk_status st = DK_OK;
    for (dk_index c = 0; c < nc && st == DK_OK; c++) {
        if (cv[c] == 0 && cf[c] == 0) {
            const dk_index rep = f->piece_rep[c];
            dk_index rim = -1; /* a degenerate triangle touching the piece */
            for (dk_index t = 0; t < m->n_faces && rim < 0; t++)
                if (f->degenerate[t])
                    for (int k = 0; k < 3; k++)
                        if (f->piece[m->faces[3 * (size_t)t + k]] == c)
                            rim = t;
            if (rim >= 0)
                st = dk_error_set(err, DK_ERR_DEGENERATE,
                                  "LinearReconstruction: the part containing vertex %d is joined "
                                  "to the rest of its component only through degenerate "
                                  "(zero-area) triangles such as face %d, which carry no "
                                  "energy, and has no constraint of its own: fix those "
                                  "triangles or constrain the part", (int)rep, (int)rim);
            else
                st = dk_error_set(err, DK_ERR_INVALID_ARGUMENT,
                                  "LinearReconstruction: the component containing vertex %d has "
                                  "no constraint: every component needs a handle or fixed "
                                  "vertices", (int)rep);
            break;
        }
        double ev[3];
        const lapack_int info = LAPACKE_dsyev(LAPACK_ROW_MAJOR, 'N', 'U', 3, mom + 9 * (size_t)c,
                                              3, ev);
        /* spanning space: the smallest spread at least 1e-3 of the largest */
        const int flat = info != 0 || !(ev[0] > 1e-6 * ev[2]);
        thin[c] = cf[c] == 0 && (cv[c] < 4 || flat);
    }
    free(cv), free(cf), free(mom), free(mean);
    return st;
}

/* The constraints' roles, the numbering, the matrices and the factor. */
/* The transform basis of the elimination `s` (see elim), when it pays and is exact:
 *  - exact: the constraint values are affine in the transforms' entries unless a
 *    component is regularized (its anchors come from a best-fit rotation: not affine);
 *  - pays: a drag costs n_unk x 4 n_handles x 3 multiply-adds instead of the triangular
 *    solves (armadillo, one handle: ~3 ms against ~44 ms), for 4 n_handles + 3 solves at
 *    bind; built while it takes at most TRANSFORM_BASIS_BYTES.
 * Column 4h + j holds the solution for "T_h[d][j] = 1, everything else 0" (the same for
 * every coordinate d: a handle vertex's target coordinate d is sum_j T[d][j] p_j + T[d][3],
 * a prescribed frame's row d is sum_j T[d][j] F0 row j); columns 4 n_h + d the solution for
 * the fixed values alone (fixed vertices' and fixed faces' rest coordinate d). Its absence
 * is not an error (out of memory included): solves then take the direct path. */
#define TRANSFORM_BASIS_BYTES (256.0 * 1024 * 1024)
static dk_status transform_basis(const dk_fundamental *f, elim *s, dk_error *err)
{
    const dk_mesh *m = f->mesh;
    const dk_constraints *c = s->con;
    const dk_index nh = c->n_handles;
    const size_t nu = (size_t)s->n_unk, nc = (size_t)s->n_con, cols = 4 * (size_t)nh + 3;
    if (s->any_anchor || nh == 0 || nu == 0 ||
        (double)(nu + nc) * (double)cols * sizeof(double) > TRANSFORM_BASIS_BYTES)
        return DK_OK;
    double *e = calloc(nc * cols, sizeof *e);     /* the constraint values per column */
    s->basis = malloc(nu * cols * sizeof *s->basis);
    s->coef = malloc(4 * (size_t)nh * 3 * sizeof *s->coef);
    if (!e || !s->basis || !s->coef) {
        free(e);
        free(s->basis), free(s->coef);
        s->basis = s->coef = NULL;
        return DK_OK;
    }
    const size_t fixed0 = 4 * (size_t)nh;
    for (dk_index v = 0; v < m->n_vertices; v++) {
        if (s->vc[v] < 0)
            continue;
        const double *p = m->positions + 3 * (size_t)v;
        const size_t slot = (size_t)s->vc[v];
        if (c->role[v] >= 0) {
            const size_t col = 4 * (size_t)c->role[v];
            for (int j = 0; j < 3; j++)
                e[(col + j) * nc + slot] = p[j];
            e[(col + 3) * nc + slot] = 1.0;
        } else {
            for (int d = 0; d < 3; d++)
                e[(fixed0 + d) * nc + slot] = p[d];
        }
    }
    for (dk_index t = 0; t < m->n_faces; t++) {
        if (s->fc[t] < 0)
            continue;
        const double *F0 = f->rest_frame + 9 * (size_t)t;
        const size_t slot = (size_t)s->fc[t];
        for (int k = 0; k < 3; k++) {
            if (s->face_handle[t] >= 0) {
                const size_t col = 4 * (size_t)s->face_handle[t];
                for (int j = 0; j < 3; j++)
                    e[(col + j) * nc + slot + k] = F0[3 * j + k];
            } else {
                for (int d = 0; d < 3; d++)
                    e[(fixed0 + d) * nc + slot + k] = F0[3 * d + k];
            }
        }
    }
    for (size_t q = 0; q < cols; q++) { /* A G = -B E */
        double *g = s->basis + q * nu;
        dk_sparse_matvec(s->B, e + q * nc, g);
        for (size_t i = 0; i < nu; i++)
            g[i] = -g[i];
    }
    free(e);
    /* The solves: the fixed values' 3 columns, then each handle's 4, so that a cancellation
     * is seen between them; in these groups whether progress is asked or not, so that the
     * basis does not depend on it. */
    for (dk_index h = -1; h < nh; h++) {
        const size_t q0 = h < 0 ? fixed0 : 4 * (size_t)h, nq = h < 0 ? 3 : 4;
        dk_status st = dk_progress_part(f->prog, (double)(h + 1) / (double)(nh + 1), err);
        if (st != DK_OK)
            return st;
        st = dk_cholesky_solve(s->chol, s->basis + q0 * nu, (int)nq, s->basis + q0 * nu, err);
        if (st != DK_OK)
            return dk_error_prefix(err, "LinearReconstruction (transform basis)");
    }
    return DK_OK;
}

static dk_status eliminate(const dk_fundamental *f, const dk_constraint_desc *desc, elim *s,
                           dk_error *err)
{
    const dk_mesh *m = f->mesh;
    const dk_index n = m->n_vertices, F = m->n_faces;
    memset(s, 0, sizeof *s);
    dk_status st = fr_phase(f, FR_PHASE_CONSTRAINTS, err);
    if (st != DK_OK)
        return st;
    st = dk_constraints_create(m, desc, &s->con, err);
    if (st != DK_OK)
        return dk_error_prefix(err, "LinearReconstruction");
    const dk_constraints *c = s->con;
    s->vu = malloc((size_t)n * sizeof *s->vu), s->vc = malloc((size_t)n * sizeof *s->vc);
    s->fu = malloc(((size_t)F + 1) * sizeof *s->fu), s->fc = malloc(((size_t)F + 1) * sizeof *s->fc);
    s->face_handle = malloc(((size_t)F + 1) * sizeof *s->face_handle);
    if (!s->vu || !s->vc || !s->fu || !s->fc || !s->face_handle)
        return oom(err, "numbering");
    dk_index nu = 0, ncon = 0;
    for (dk_index v = 0; v < n; v++) {
        const int held = c->role[v] != DK_VERTEX_FREE;
        s->vu[v] = held ? -1 : nu++;
        s->vc[v] = held ? ncon++ : -1;
    }
    for (dk_index t = 0; t < F; t++) {
        const dk_index *fv = m->faces + 3 * (size_t)t;
        dk_index h = -1;
        if (f->opt.orientation && !f->degenerate[t] && c->role[fv[0]] != DK_VERTEX_FREE &&
            c->role[fv[0]] == c->role[fv[1]] && c->role[fv[0]] == c->role[fv[2]])
            h = c->role[fv[0]] == DK_VERTEX_FIXED ? -2 : c->role[fv[0]];
        s->face_handle[t] = h;
        if (f->degenerate[t]) {
            s->fu[t] = s->fc[t] = -1;
        } else if (h != -1) {
            s->fu[t] = -1, s->fc[t] = ncon, ncon += 3;
        } else {
            s->fu[t] = nu, s->fc[t] = -1, nu += 3;
        }
    }
    s->n_unk = nu;
    for (dk_index v = 0; v < n; v++) /* a vertex on degenerate faces only has no energy */
        if (s->vu[v] >= 0 && m->vf_start[v + 1] > m->vf_start[v]) {
            int any = 0;
            for (dk_index q = m->vf_start[v]; q < m->vf_start[v + 1]; q++)
                any |= !f->degenerate[m->vf_index[q]];
            if (!any)
                return dk_error_set(err, DK_ERR_DEGENERATE,
                                    "LinearReconstruction: vertex %d lies on degenerate "
                                    "triangles only, so nothing places it: fix the mesh or "
                                    "constrain it", (int)v);
        }
    {
        unsigned char *thin = calloc((size_t)f->n_pieces + 1, 1);
        s->fa = malloc(((size_t)F + 1) * sizeof *s->fa);
        if (!thin || !s->fa) {
            free(thin);
            return oom(err, "numbering");
        }
        st = check_components(f, s, thin, err);
        for (dk_index t = 0; t < F; t++) { /* anchors of the thinly held components' frames */
            const int reg = st == DK_OK && s->fu[t] >= 0 && thin[f->piece[m->faces[3 * (size_t)t]]];
            s->fa[t] = reg ? ncon : -1;
            ncon += reg ? 3 : 0;
            s->any_anchor |= reg;
        }
        free(thin);
        if (st != DK_OK)
            return st;
    }
    s->n_con = ncon;
    /* (a scratch view of the numbering for slot()) */
    dk_fundamental view = *f;
    view.el = *s;
    st = fr_phase(f, FR_PHASE_ASSEMBLE, err);
    if (st == DK_OK)
        st = assemble(&view, nu, ncon, &s->A, &s->B, err);
    if (st == DK_OK && nu > 0 && (st = fr_phase(f, FR_PHASE_ANALYZE, err)) == DK_OK)
        st = dk_cholesky_analyze_compact(s->A, &s->chol, err);
    if (st == DK_OK && nu > 0 && (st = fr_phase(f, FR_PHASE_FACTORIZE, err)) == DK_OK) {
        st = dk_cholesky_factorize(s->chol, s->A, err);
        if (st == DK_ERR_NOT_POSITIVE_DEFINITE) {
            /* name the caller's vertex (or face frame), not the matrix column */
            const int64_t col = err ? err->column - 1 : -1;
            char at[64] = "";
            for (dk_index v = 0; col >= 0 && !at[0] && v < n; v++)
                if (s->vu[v] == col)
                    snprintf(at, sizeof at, " at vertex %d", (int)v);
            for (dk_index t = 0; col >= 0 && !at[0] && t < F; t++)
                if (s->fu[t] >= 0 && col >= s->fu[t] && col < s->fu[t] + 3)
                    snprintf(at, sizeof at, " at the frame of face %d", (int)t);
            /* the likely cause first: the magnitudes of the material map or of w leave the
             * system singular to rounding (the second hostile review: the message blamed the
             * geometry when a material of 1e-14 was the cause) */
            double lo = 1.0, hi = 1.0;
            for (dk_index e = 0; f->material && e < f->mesh->n_edges; e++) {
                lo = fmin(lo, f->material[e]);
                hi = fmax(hi, f->material[e]);
            }
            const double w = f->opt.w;
            if (hi / lo > 1e12)
                dk_error_set(err, DK_ERR_NOT_POSITIVE_DEFINITE,
                             "LinearReconstruction: the system is singular%s: the material map "
                             "spans %g to %g, a ratio of %.3g, beyond what double precision "
                             "resolves (keep it within 1e12, e.g. 1e-6 to 1e6)",
                             at, lo, hi, hi / lo);
            else if (w < 1e-12 || w > 1e12)
                dk_error_set(err, DK_ERR_NOT_POSITIVE_DEFINITE,
                             "LinearReconstruction: the system is singular%s: w = %g is too "
                             "%s beside the edge terms for double precision (keep it within "
                             "1e-12 to 1e12; 1, the default, weighs both alike)",
                             at, w, w < 1e-12 ? "small" : "large");
            else
                dk_error_set(err, DK_ERR_NOT_POSITIVE_DEFINITE,
                             "LinearReconstruction: the system is singular%s (constrained "
                             "vertices on a line, or degenerate triangles around it)", at);
        } else if (st != DK_OK)
            dk_error_prefix(err, "LinearReconstruction");
    }
    /* A is in the factor now; solves need B and the factor only */
    dk_sparse_free(s->A);
    s->A = NULL;
    if (st == DK_OK) {
        s->zc = malloc((3 * (size_t)ncon + 1) * sizeof *s->zc);
        s->rhs = malloc((3 * (size_t)nu + 1) * sizeof *s->rhs);
        s->lin = malloc((9 * (size_t)c->n_handles + 1) * sizeof *s->lin);
        s->tgt = malloc((3 * (size_t)c->n_handle_vertices + 1) * sizeof *s->tgt);
        if (!s->zc || !s->rhs || !s->lin || !s->tgt)
            st = oom(err, "buffers");
    }
    if (st == DK_OK && s->con->n_handles > 0 && nu > 0 &&
        (st = fr_phase(f, FR_PHASE_BASIS, err)) == DK_OK)
        st = transform_basis(f, s, err);
    return st;
}

/* ------------------------------------------------------------------ bind ---------------- */

void dk_fundamental_free(dk_fundamental *f)
{
    if (!f)
        return;
    elim_free(&f->el);
    free(f->material);
    free(f->degenerate);
    free(f->coord);
    free(f->cot);
    free(f->rest_frame);
    free(f->R);
    free(f->has_R);
    free(f->frames);
    free(f->comp_fit);
    free(f->piece);
    free(f->piece_rep);
    free(f->bridge);
    free(f->bridge_R);
    free(f->fin);
    free(f->fin_R);
    free(f);
}

/* The options a bind on `mesh` accepts (the estimate refuses the same). */
static dk_status check_options(const dk_mesh *mesh, const dk_fundamental_options *opt,
                               dk_error *err)
{
    if (!(opt->w > 0.0) || !isfinite(opt->w))
        return dk_error_set(err, DK_ERR_INVALID_ARGUMENT,
                            "LinearReconstruction: w must be finite and > 0");
    if (opt->orientation != 0 && opt->orientation != 1)
        return dk_error_set(err, DK_ERR_INVALID_ARGUMENT,
                            "LinearReconstruction: orientation must be 0 or 1");
    if (opt->material && opt->n_material != mesh->n_edges)
        return dk_error_set(err, DK_ERR_INVALID_ARGUMENT,
                            "LinearReconstruction: the material map has %d entries; the mesh "
                            "has %d edges (one value per edge, in Mesh.edges order)",
                            (int)opt->n_material, (int)mesh->n_edges);
    for (dk_index e = 0; opt->material && e < mesh->n_edges; e++)
        if (!(opt->material[e] > 0.0) || !isfinite(opt->material[e]))
            return dk_error_set(err, DK_ERR_INVALID_ARGUMENT,
                                "LinearReconstruction: the material map must be finite and > 0; "
                                "edge %d (vertices %d-%d) has %g", (int)e,
                                (int)mesh->edges[2 * (size_t)e],
                                (int)mesh->edges[2 * (size_t)e + 1], opt->material[e]);
    return DK_OK;
}

dk_status dk_fundamental_bind(const dk_mesh *mesh, const dk_constraint_desc *desc,
                              const dk_fundamental_options *options, dk_fundamental **out,
                              dk_error *err)
{
    if (!out)
        return dk_error_set(err, DK_ERR_INVALID_ARGUMENT, "LinearReconstruction: out is NULL");
    *out = NULL;
    if (!mesh || !desc)
        return dk_error_set(err, DK_ERR_INVALID_ARGUMENT,
                            "LinearReconstruction: mesh and constraints must not be NULL");
    if (mesh->n_faces == 0)
        return dk_error_set(err, DK_ERR_TOPOLOGY, "LinearReconstruction: the mesh has no faces");
    dk_fundamental_options opt;
    if (options)
        opt = *options;
    else
        dk_fundamental_default_options(&opt);
    dk_status st0 = check_options(mesh, &opt, err);
    if (st0 != DK_OK)
        return st0;
    dk_fundamental *f = calloc(1, sizeof *f);
    if (!f)
        return oom(err, "object");
    f->mesh = mesh;
    f->opt = opt;
    dk_progress prog;
    dk_progress_init(&prog, opt.progress, opt.progress_user, fr_bind_phases,
                     (int)(sizeof fr_bind_phases / sizeof fr_bind_phases[0]),
                     "LinearReconstruction bind");
    f->opt.progress = NULL; /* the caller's callback is for this bind only */
    f->opt.progress_user = NULL;
    f->prog = &prog;
    f->prog_base = FR_BIND_PHASE_BASE;
    f->w_scaled = opt.w * mesh->mean_edge_length * mesh->mean_edge_length;
    if (!(f->w_scaled > 0.0 && isfinite(f->w_scaled))) { /* name the cause it can see */
        const double ws = f->w_scaled;
        free(f);
        if (!(mesh->mean_edge_length > 0.0))
            return dk_error_set(err, DK_ERR_DEGENERATE, "LinearReconstruction: the mesh has "
                                "no edge length");
        return dk_error_set(err, DK_ERR_INVALID_ARGUMENT,
                            "LinearReconstruction: w = %g times the mean edge length squared "
                            "(%g) is %s in double precision: give a w nearer 1", opt.w,
                            mesh->mean_edge_length * mesh->mean_edge_length,
                            ws > 0.0 ? "infinite" : "zero");
    }
    const size_t F = (size_t)mesh->n_faces, E = (size_t)mesh->n_edges;
    f->material = malloc((E + 1) * sizeof *f->material);
    f->degenerate = malloc(F + 1);
    f->coord = malloc(6 * F * sizeof *f->coord);
    f->cot = malloc(3 * F * sizeof *f->cot);
    f->rest_frame = malloc(9 * F * sizeof *f->rest_frame);
    f->frames = malloc(9 * F * sizeof *f->frames);
    f->R = malloc((9 * E + 1) * sizeof *f->R);
    f->has_R = malloc(E + 1);
    f->piece = malloc(((size_t)mesh->n_vertices + 1) * sizeof *f->piece);
    if (!f->material || !f->degenerate || !f->coord || !f->cot || !f->rest_frame || !f->frames ||
        !f->R || !f->has_R || !f->piece) {
        dk_fundamental_free(f);
        return oom(err, "fundamental forms");
    }
    dk_status st = dk_progress_begin(&prog, 0, err); /* forms */
    if (st != DK_OK) {
        dk_fundamental_free(f);
        return st;
    }
    for (size_t e = 0; e < E; e++)
        f->material[e] = opt.material ? opt.material[e] : 1.0;
    f->opt.material = NULL; /* the copy is ours */
    f->opt.n_material = 0;
    /* (the forms phase's shares: faces ~0.2, edge rotations ~0.7, pieces ~0.1)
     * 1. the first fundamental form per face; 2. the second per interior edge (R_ij);
     * 3. the fins' frame equations, the pieces and the bridges between groups of faces that
     * meet at vertices only;
     * 4. the elimination of the constraints, the energy's matrices and their factor */
    faces(f);
    if ((st = dk_progress_part(&prog, 0.2, err)) == DK_OK &&
        (st = edge_rotations(f, err)) == DK_OK)
        st = dk_progress_part(&prog, 0.9, err);
    if (st != DK_OK) {
        dk_fundamental_free(f);
        return st;
    }
    memcpy(f->frames, f->rest_frame, 9 * F * sizeof *f->frames);
    if ((st = fin_pairs(f, err)) == DK_OK)
        st = pieces_and_bridges(f, err);
    if (st != DK_OK) {
        dk_fundamental_free(f);
        return st;
    }
    elim s;
    st = eliminate(f, desc, &s, err);
    if (st != DK_OK) {
        elim_free(&s);
        dk_fundamental_free(f);
        return st;
    }
    elim_install(f, &s);
    f->prog = NULL;
    dk_progress_done(&prog);
    *out = f;
    return DK_OK;
}

dk_status dk_fundamental_rebind(dk_fundamental *f, const dk_constraint_desc *desc, dk_error *err)
{
    if (!f || !desc)
        return dk_error_set(err, DK_ERR_INVALID_ARGUMENT,
                            "LinearReconstruction rebind: object and constraints must not be "
                            "NULL");
    dk_progress prog;
    dk_progress_init(&prog, f->opt.progress, f->opt.progress_user, fr_rebind_phases,
                     (int)(sizeof fr_rebind_phases / sizeof fr_rebind_phases[0]),
                     "LinearReconstruction rebind");
    f->prog = &prog;
    f->prog_base = 0;
    elim s;
    dk_status st = eliminate(f, desc, &s, err); /* const f: on failure f is as it was */
    f->prog = NULL;
    if (st != DK_OK) {
        elim_free(&s);
        return st;
    }
    elim_install(f, &s);
    dk_progress_done(&prog);
    return DK_OK;
}

void dk_fundamental_set_progress(dk_fundamental *f, dk_phase_progress_fn progress, void *user)
{
    if (!f)
        return;
    f->opt.progress = progress;
    f->opt.progress_user = progress ? user : NULL;
}

/* ------------------------------------------------------------------ solve -------------- */

/* Per handle, the linear part that turns its faces' frames: the transform's, or the
 * rotation that best fits the rest handle vertices to the targets (Kabsch). */
static void handle_rotations(dk_fundamental *f, int transforms, const double *targets)
{
    const dk_constraints *c = f->el.con;
    const double *p = f->mesh->positions;
    for (dk_index h = 0; h < c->n_handles; h++) {
        double *L = f->el.lin + 9 * (size_t)h;
        if (transforms) {
            for (int r = 0; r < 3; r++)
                for (int q = 0; q < 3; q++)
                    L[3 * r + q] = targets[16 * (size_t)h + 4 * r + q];
            continue;
        }
        double cp[3] = {0, 0, 0}, cq[3] = {0, 0, 0}, A[9] = {0};
        const dk_index a = c->handle_start[h], b = c->handle_start[h + 1];
        for (dk_index q = a; q < b; q++)
            for (int d = 0; d < 3; d++) {
                cp[d] += p[3 * (size_t)c->handle_vertices[q] + d] / (double)(b - a);
                cq[d] += f->el.tgt[3 * (size_t)q + d] / (double)(b - a);
            }
        for (dk_index q = a; q < b; q++) /* A = sum (q - cq)(p - cp)^T: R maximises tr(R^T A) */
            for (int r = 0; r < 3; r++)
                for (int s = 0; s < 3; s++)
                    A[3 * r + s] += (f->el.tgt[3 * (size_t)q + r] - cq[r]) *
                                    (p[3 * (size_t)c->handle_vertices[q] + s] - cp[s]);
        dk_closest_rotation(A, L);
    }
}

dk_status dk_fundamental_solve(dk_fundamental *f, const dk_solve_request *rq, double *positions,
                               dk_solve_info *info, dk_error *err)
{
    if (info)
        memset(info, 0, sizeof *info);
    if (!f || !positions)
        return dk_error_set(err, DK_ERR_INVALID_ARGUMENT,
                            "LinearReconstruction solve: object and positions must not be NULL");
    dk_status st = dk_solve_request_check(rq, "LinearReconstruction solve", err);
    if (st != DK_OK)
        return st;
    const dk_mesh *m = f->mesh;
    const dk_constraints *c = f->el.con;
    st = dk_constraints_targets(c, m->positions, rq->targets, (int)rq->target_kind, f->el.tgt, err);
    if (st != DK_OK)
        return dk_error_prefix(err, "LinearReconstruction solve");
    if (f->opt.orientation)
        handle_rotations(f, rq->target_kind == DK_TARGETS_TRANSFORMS, rq->targets);
    /* the constraint values, per coordinate (column-major n_con x 3) */
    const size_t nc = (size_t)f->el.n_con, nu = (size_t)f->el.n_unk;
    for (dk_index v = 0; v < m->n_vertices; v++) {
        if (f->el.vc[v] < 0)
            continue;
        const double *src = m->positions + 3 * (size_t)v;
        if (c->role[v] >= 0) /* a handle vertex: its target */
            for (dk_index q = c->handle_start[c->role[v]]; q < c->handle_start[c->role[v] + 1]; q++)
                if (c->handle_vertices[q] == v) {
                    src = f->el.tgt + 3 * (size_t)q;
                    break;
                }
        for (int d = 0; d < 3; d++)
            f->el.zc[(size_t)d * nc + f->el.vc[v]] = src[d];
    }
    for (dk_index t = 0; t < m->n_faces; t++) {
        if (f->el.fc[t] < 0)
            continue;
        const double *F0 = f->rest_frame + 9 * (size_t)t;
        double Ft[9];
        if (f->el.face_handle[t] >= 0)
            mat_mul(f->el.lin + 9 * (size_t)f->el.face_handle[t], F0, Ft);
        else
            memcpy(Ft, F0, sizeof Ft);
        for (int d = 0; d < 3; d++)
            for (int k = 0; k < 3; k++)
                f->el.zc[(size_t)d * nc + f->el.fc[t] + k] = Ft[3 * d + k];
        memcpy(f->frames + 9 * (size_t)t, Ft, sizeof Ft);
    }
    if (f->el.any_anchor) { /* the regularization's anchors: rest frames, turned per component */
        const dk_index ncomp = f->n_pieces;
        memset(f->comp_fit, 0, 25 * (size_t)ncomp * sizeof *f->comp_fit);
        for (int pass = 0; pass < 2; pass++)
            for (dk_index v = 0; v < m->n_vertices; v++) {
                if (f->el.vc[v] < 0)
                    continue;
                double *cf = f->comp_fit + 25 * (size_t)f->piece[v];
                const double *p = m->positions + 3 * (size_t)v;
                double q[3];
                for (int d = 0; d < 3; d++)
                    q[d] = f->el.zc[(size_t)d * nc + f->el.vc[v]];
                if (pass == 0) { /* the centroids' sums */
                    cf[0] += 1.0;
                    for (int d = 0; d < 3; d++)
                        cf[1 + d] += p[d], cf[4 + d] += q[d];
                    continue;
                }
                for (int a = 0; a < 3; a++) /* sum (q - cq)(p - cp)^T */
                    for (int b = 0; b < 3; b++)
                        cf[7 + 3 * a + b] += (q[a] - cf[4 + a] / cf[0]) * (p[b] - cf[1 + b] / cf[0]);
            }
        for (dk_index c = 0; c < ncomp; c++)
            dk_closest_rotation(f->comp_fit + 25 * (size_t)c + 7, f->comp_fit + 25 * (size_t)c + 16);
        for (dk_index t = 0; t < m->n_faces; t++)
            if (f->el.fa[t] >= 0) {
                double Ft[9];
                mat_mul(f->comp_fit + 25 * (size_t)f->piece[m->faces[3 * (size_t)t]] + 16,
                        f->rest_frame + 9 * (size_t)t, Ft);
                for (int d = 0; d < 3; d++)
                    for (int k = 0; k < 3; k++)
                        f->el.zc[(size_t)d * nc + f->el.fa[t] + k] = Ft[3 * d + k];
            }
    }
    /* A z = -B z_c, three coordinates at once; with transforms and the basis, its
     * combination z_d = S_d + sum T_h[d][j] G_{4h+j} */
    if (nu > 0 && f->el.basis && rq->target_kind == DK_TARGETS_TRANSFORMS) {
        const int nh = (int)c->n_handles;
        double *P = f->el.coef;
        for (int h = 0; h < nh; h++)
            for (int j = 0; j < 4; j++)
                for (int d = 0; d < 3; d++)
                    P[(size_t)d * 4 * nh + 4 * (size_t)h + j] = rq->targets[16 * (size_t)h + 4 * d + j];
        for (int d = 0; d < 3; d++)
            memcpy(f->el.rhs + (size_t)d * nu, f->el.basis + (4 * (size_t)nh + d) * nu,
                   nu * sizeof(double));
        cblas_dgemm(CblasColMajor, CblasNoTrans, CblasNoTrans, (int)nu, 3, 4 * nh, 1.0,
                    f->el.basis, (int)nu, P, 4 * nh, 1.0, f->el.rhs, (int)nu);
    } else if (nu > 0) {
        for (int d = 0; d < 3; d++) {
            dk_sparse_matvec(f->el.B, f->el.zc + (size_t)d * nc, f->el.rhs + (size_t)d * nu);
            for (size_t i = 0; i < nu; i++)
                f->el.rhs[(size_t)d * nu + i] = -f->el.rhs[(size_t)d * nu + i];
        }
        st = dk_cholesky_solve(f->el.chol, f->el.rhs, 3, f->el.rhs, err);
        if (st != DK_OK)
            return dk_error_prefix(err, "LinearReconstruction solve");
    }
    for (dk_index v = 0; v < m->n_vertices; v++)
        for (int d = 0; d < 3; d++)
            positions[3 * (size_t)v + d] = f->el.vu[v] >= 0 ? f->el.rhs[(size_t)d * nu + f->el.vu[v]]
                                                         : f->el.zc[(size_t)d * nc + f->el.vc[v]];
    for (dk_index t = 0; t < m->n_faces; t++)
        if (f->el.fu[t] >= 0)
            for (int d = 0; d < 3; d++)
                for (int k = 0; k < 3; k++)
                    f->frames[9 * (size_t)t + 3 * d + k] = f->el.rhs[(size_t)d * nu + f->el.fu[t] + k];
    double energy = NAN;
    if (!rq->skip_energy && (st = dk_fundamental_energy(f, positions, &energy, err)) != DK_OK &&
        st != DK_ERR_NONFINITE)
        return st;
    st = dk_solve_result_check(positions, m->n_vertices, energy, !rq->skip_energy,
                               "LinearReconstruction solve", err);
    if (st != DK_OK)
        return st;
    if (info) {
        info->iterations = info->converged = 1;
        info->energy = energy;
    }
    return DK_OK;
}

int dk_fundamental_has_transform_basis(const dk_fundamental *f)
{
    return f && f->el.basis != NULL;
}

dk_status dk_fundamental_energy(const dk_fundamental *f, const double *positions,
                                double *energy, dk_error *err)
{
    if (!f || !positions || !energy)
        return dk_error_set(err, DK_ERR_INVALID_ARGUMENT,
                            "LinearReconstruction energy: arguments must not be NULL");
    evaluation ev = {f, positions, f->frames, 0.0};
    for_each_residual(f, energy_visit, &ev);
    *energy = ev.E;
    return dk_energy_result_check(ev.E, "LinearReconstruction energy", err);
}

const double *dk_fundamental_frames(const dk_fundamental *f)
{
    return f ? f->frames : NULL;
}

int dk_fundamental_edge_rotation(const dk_fundamental *f, dk_index edge, double r[9])
{
    if (!f || edge < 0 || edge >= f->mesh->n_edges || !f->has_R[edge])
        return 0;
    memcpy(r, f->R + 9 * (size_t)edge, 9 * sizeof *r);
    return 1;
}

void dk_fundamental_stats(const dk_fundamental *f, dk_method_stats *st)
{
    memset(st, 0, sizeof *st);
    if (!f)
        return;
    st->n_vertices = f->mesh->n_vertices;
    st->n_handles = f->el.con->n_handles;
    st->n_handle_vertices = f->el.con->n_handle_vertices;
    dk_constraints_held_stats(f->el.con, NULL, st);
    st->n_unknowns = f->el.n_unk;
    st->analysis_count = st->factorization_count = f->el.n_unk > 0;
}

dk_status dk_fundamental_estimate_memory(const dk_mesh *mesh,
                                         const dk_fundamental_options *options,
                                         uint64_t *bytes, dk_error *err)
{
    if (!mesh || !bytes)
        return dk_error_set(err, DK_ERR_INVALID_ARGUMENT,
                            "LinearReconstruction estimate_memory: mesh and bytes must not be "
                            "NULL");
    dk_status st = options ? check_options(mesh, options, err) : DK_OK; /* what bind refuses */
    if (st != DK_OK)
        return st;
    const double n = (double)mesh->n_vertices, lg = n > 2.0 ? log2(n) : 1.0;
    /* the factor of the 7n-unknown system dominates, and its fill grows ~n log n. Measured
     * (2026-12-02): 6560 / 6890 / 8220 / 9720 B/vertex on the arm 8k, the armadillo 43k and
     * subdivided once and twice (173k, 692k) */
    *bytes = dk_memory_model(1500.0 + 450.0 * lg, n, 0.0);
    return DK_OK;
}

/* the options' fields (dk_option_desc): where each is, what values bind takes */
static const dk_option_desc fundamental_fields[] = {
    {"w", DK_OPTION_DOUBLE, offsetof(dk_fundamental_options, w), 0, DBL_TRUE_MIN, DBL_MAX, 1.0,
     DBL_MAX, 0},
    {"orientation", DK_OPTION_INT, offsetof(dk_fundamental_options, orientation), 0, 0, 1, 0, 1,
     0},
    {"material", DK_OPTION_EDGE_VALUES, offsetof(dk_fundamental_options, material),
     offsetof(dk_fundamental_options, n_material), DBL_TRUE_MIN, DBL_MAX, 1.0, DBL_MAX, 0},
};

DK_METHOD_OPS(dk_fundamental_ops, "LinearReconstruction",
              DK_METHOD_TRANSFORMS_AS_POSITIONS | DK_METHOD_TRANSLATION_INVARIANT |
                  DK_METHOD_RIGID_INVARIANT,
              DK_CONTROL_VERTEX_GROUPS, dk_fundamental, dk_fundamental, dk_fundamental_options,
              fundamental_fields);
