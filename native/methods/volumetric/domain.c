/* DeformKit volumetric ARAP: the tetrahedra, their volume mesh, and the surface's
 * constraints carried into the volume (volumetric_internal.h). */
#include "volumetric_internal.h"

#include "dk_operators.h"

#include <math.h>
#include <stdio.h>

static int tri_less(const dk_index *a, const dk_index *b)
{
    return a[0] < b[0] || (a[0] == b[0] && (a[1] < b[1] || (a[1] == b[1] && a[2] < b[2])));
}

static int tri_cmp(const void *x, const void *y)
{
    const dk_index *a = x, *b = y;
    return tri_less(a, b) ? -1 : tri_less(b, a) ? 1 : 0;
}

static void sort3(dk_index *t)
{
    dk_index s;
    if (t[0] > t[1]) s = t[0], t[0] = t[1], t[1] = s;
    if (t[1] > t[2]) s = t[1], t[1] = t[2], t[2] = s;
    if (t[0] > t[1]) s = t[0], t[0] = t[1], t[1] = s;
}

/* The volume mesh: the tetrahedra's faces, each once (sorted corners: only the adjacency
 * is read), and the triangles of the parts that bound no volume (`keep`, as given). */
static dk_status volume_mesh(dk_volumetric_arap *va, const double *points,
                             const unsigned char *in_volume, dk_error *err)
{
    const dk_mesh *sm = va->mesh;
    const size_t nf = 4 * (size_t)va->nt;
    dk_index *f = malloc(3 * (nf + (size_t)sm->n_faces) * sizeof *f + sizeof *f);
    if (!f)
        return dk_error_set(err, DK_ERR_OUT_OF_MEMORY, "VolumetricARAP bind: out of memory");
    static const int face[4][3] = {{1, 2, 3}, {0, 2, 3}, {0, 1, 3}, {0, 1, 2}};
    for (size_t t = 0; t < (size_t)va->nt; t++)
        for (int k = 0; k < 4; k++) {
            dk_index *q = f + 3 * (4 * t + (size_t)k);
            for (int j = 0; j < 3; j++)
                q[j] = va->tets[4 * t + (size_t)face[k][j]];
            sort3(q);
        }
    qsort(f, nf, 3 * sizeof *f, tri_cmp);
    size_t m = 0;
    for (size_t i = 0; i < nf; i++)
        if (m == 0 || tri_cmp(f + 3 * i, f + 3 * (m - 1)) != 0) {
            memmove(f + 3 * m, f + 3 * i, 3 * sizeof *f);
            m++;
        }
    for (dk_index t = 0; t < sm->n_faces; t++)
        if (!in_volume[sm->faces[3 * (size_t)t]])
            memcpy(f + 3 * m++, sm->faces + 3 * (size_t)t, 3 * sizeof *f);
    dk_status st = dk_mesh_create(points, va->np, f, (dk_index)m, &va->volume, err);
    free(f);
    return st == DK_OK ? DK_OK : dk_error_prefix(err, "VolumetricARAP bind: the volume mesh");
}

/* The closed parts: components whose every edge is in exactly two triangles (into
 * in_volume, per vertex); their triangles into *faces (*nf of them). */
static dk_status closed_parts(const dk_mesh *m, unsigned char *in_volume, dk_index **faces,
                              dk_index *nf, dk_error *err)
{
    unsigned char *open = calloc((size_t)m->n_vertices + 1, 1); /* per component */
    *faces = malloc(3 * (size_t)m->n_faces * sizeof **faces + 1);
    if (!open || !*faces) {
        free(open);
        free(*faces);
        *faces = NULL;
        return dk_error_set(err, DK_ERR_OUT_OF_MEMORY, "VolumetricARAP bind: out of memory");
    }
    for (dk_index e = 0; e < m->n_edges; e++)
        if (m->edge_face_count[e] != 2)
            open[m->component[m->edges[2 * (size_t)e]]] = 1;
    for (dk_index v = 0; v < m->n_vertices; v++)
        in_volume[v] = m->vf_start[v + 1] > m->vf_start[v] && !open[m->component[v]];
    *nf = 0;
    for (dk_index t = 0; t < m->n_faces; t++)
        if (in_volume[m->faces[3 * (size_t)t]])
            memcpy(*faces + 3 * (size_t)(*nf)++, m->faces + 3 * (size_t)t, 3 * sizeof **faces);
    free(open);
    return DK_OK;
}

/* The frame TetGen meshes in: TetGen's choices (which points it adds, where) depend on the
 * coordinates, so that a mesh moved, turned or scaled would get other tetrahedra and another
 * result. The frame moves with the mesh: its origin the first vertex, its x axis towards the
 * vertex farthest from it, its y axis towards the one farthest from that line (the first in
 * index order among those within 1e-9 of the farthest: a symmetric mesh has ties that
 * rounding would break differently), its unit their distance; and the coordinates there are
 * rounded to 2^-22 of the unit, so that every placement and scale of one mesh gives TetGen
 * the same input (unless a coordinate lies within rounding of a step: about 1e-8 of them).
 * frame: origin (3), axes (3 rows), unit; returns 0 when the points are collinear. */
static dk_index farthest(const double *p, dk_index n, const double *o, const double *x,
                         double *dist2)
{
    double best = 0.0;
    for (int pass = 0; pass < 2; pass++)
        for (dk_index k = 1; k < n; k++) {
            const double *q = p + 3 * (size_t)k;
            double r[3] = {q[0] - o[0], q[1] - o[1], q[2] - o[2]};
            if (x) { /* the distance from the line through o along x */
                const double t = r[0] * x[0] + r[1] * x[1] + r[2] * x[2];
                for (int d = 0; d < 3; d++)
                    r[d] -= t * x[d];
            }
            const double d = r[0] * r[0] + r[1] * r[1] + r[2] * r[2];
            if (pass == 0 && d > best)
                best = d;
            else if (pass == 1 && d >= best * (1.0 - 2e-9)) {
                *dist2 = best;
                return k;
            }
        }
    *dist2 = 0.0;
    return 0;
}

static int canonical_frame(const double *p, dk_index n, double frame[13])
{
    const double *o = p;
    double best;
    const dk_index a = farthest(p, n, o, NULL, &best);
    if (!(best > 0.0))
        return 0;
    const double unit = sqrt(best);
    double x[3], y[3], z[3];
    for (int d = 0; d < 3; d++)
        x[d] = (p[3 * (size_t)a + d] - o[d]) / unit;
    const dk_index b = farthest(p, n, o, x, &best);
    if (!(best > 1e-24 * unit * unit))
        return 0;
    double r[3];
    for (int d = 0; d < 3; d++)
        r[d] = p[3 * (size_t)b + d] - o[d];
    const double t = r[0] * x[0] + r[1] * x[1] + r[2] * x[2];
    for (int d = 0; d < 3; d++)
        y[d] = r[d] - t * x[d];
    const double ly = sqrt(y[0] * y[0] + y[1] * y[1] + y[2] * y[2]);
    for (int d = 0; d < 3; d++)
        y[d] /= ly;
    z[0] = x[1] * y[2] - x[2] * y[1];
    z[1] = x[2] * y[0] - x[0] * y[2];
    z[2] = x[0] * y[1] - x[1] * y[0];
    memcpy(frame, o, 3 * sizeof *frame);
    memcpy(frame + 3, x, sizeof x);
    memcpy(frame + 6, y, sizeof y);
    memcpy(frame + 9, z, sizeof z);
    frame[12] = unit;
    return 1;
}

/* p (n x 3) into the frame's coordinates, rounded to 2^-22 (to_frame), or back, in place. */
static void frame_map(const double frame[13], double *p, dk_index n, int to_frame)
{
    const double *o = frame, *ax = frame + 3, unit = frame[12], step = 0x1p-22;
    for (dk_index k = 0; k < n; k++) {
        double *q = p + 3 * (size_t)k, r[3];
        if (to_frame) {
            const double d[3] = {q[0] - o[0], q[1] - o[1], q[2] - o[2]};
            for (int i = 0; i < 3; i++)
                r[i] = step * nearbyint((ax[3 * i] * d[0] + ax[3 * i + 1] * d[1] +
                                         ax[3 * i + 2] * d[2]) / unit / step);
        } else {
            for (int i = 0; i < 3; i++)
                r[i] = o[i] + unit * (ax[i] * q[0] + ax[3 + i] * q[1] + ax[6 + i] * q[2]);
        }
        memcpy(q, r, sizeof r);
    }
}

dk_status volumetric_domain(dk_volumetric_arap *va, dk_progress *prog, dk_error *err)
{
    const dk_mesh *m = va->mesh;
    const dk_index n = m->n_vertices;
    va->n = va->np = n;
    va->nt = 0;
    unsigned char *in_volume = calloc((size_t)n + 1, 1);
    dk_index *sub = malloc((size_t)n * sizeof *sub + 1), *faces = NULL, nf = 0;
    double *sp = malloc(3 * (size_t)n * sizeof *sp + 1), *points = NULL, *all = NULL;
    dk_index *tets = NULL, np = 0, nt = 0, nsub = 0;
    dk_status st = in_volume && sub && sp ? closed_parts(m, in_volume, &faces, &nf, err)
                                          : dk_error_set(err, DK_ERR_OUT_OF_MEMORY,
                                                         "VolumetricARAP bind: out of memory");
    if (st != DK_OK)
        goto done;
    /* the closed parts' vertices, compacted: sub[k] is the mesh's vertex of TetGen's k */
    dk_index *to_sub = malloc((size_t)n * sizeof *to_sub + 1);
    if (!to_sub) {
        st = dk_error_set(err, DK_ERR_OUT_OF_MEMORY, "VolumetricARAP bind: out of memory");
        goto done;
    }
    for (dk_index v = 0; v < n; v++) {
        to_sub[v] = in_volume[v] ? nsub : -1;
        if (in_volume[v]) {
            memcpy(sp + 3 * (size_t)nsub, m->positions + 3 * (size_t)v, 3 * sizeof *sp);
            sub[nsub++] = v;
        }
    }
    for (size_t k = 0; k < 3 * (size_t)nf; k++)
        faces[k] = to_sub[faces[k]];
    free(to_sub);
    double frame[13];
    const int framed = nf > 0 && canonical_frame(sp, nsub, frame);
    if (framed)
        frame_map(frame, sp, nsub, 1);
    if (nf > 0) {
        dk_error why = {0};
        const double unit3 = framed ? frame[12] * frame[12] * frame[12] : 1.0;
        st = dk_tetrahedralize_surface(sp, nsub, faces, nf, va->opt.quality,
                                       va->opt.max_volume / unit3, &points, &np, &tets, &nt,
                                       &why);
        if (st == DK_ERR_OUT_OF_MEMORY) {
            st = dk_error_set(err, st, "VolumetricARAP bind: %s", why.message);
            goto done;
        }
        if (st != DK_OK) { /* crossing or degenerate triangles: the whole mesh a surface */
            snprintf(va->note, sizeof va->note, "no volume: %s", why.message);
            memset(in_volume, 0, (size_t)n);
            st = DK_OK;
            nt = 0;
        } else if (nf < m->n_faces) {
            snprintf(va->note, sizeof va->note, "%ld of %ld triangles are in parts with a hole "
                     "or a non-manifold edge: those parts deform as surfaces",
                     (long)(m->n_faces - nf), (long)m->n_faces);
        }
    }
    /* the points: the mesh's vertices, then TetGen's interior ones */
    const dk_index ni = nt > 0 ? np - nsub : 0;
    all = malloc(3 * ((size_t)n + (size_t)ni) * sizeof *all + 1);
    if (!all) {
        st = dk_error_set(err, DK_ERR_OUT_OF_MEMORY, "VolumetricARAP bind: out of memory");
        goto done;
    }
    memcpy(all, m->positions, 3 * (size_t)n * sizeof *all);
    if (ni > 0) {
        memcpy(all + 3 * (size_t)n, points + 3 * (size_t)nsub, 3 * (size_t)ni * sizeof *all);
        if (framed) /* the interior back where the mesh is (its vertices are the caller's) */
            frame_map(frame, all + 3 * (size_t)n, ni, 0);
    }
    for (size_t k = 0; k < 4 * (size_t)nt; k++)
        tets[k] = tets[k] < nsub ? sub[tets[k]] : n + (tets[k] - nsub);
    /* positively oriented: two corners swapped where TetGen's order is left-handed */
    for (dk_index t = 0; t < nt; t++) {
        dk_index *q = tets + 4 * (size_t)t;
        double w[6];
        if (dk_tetrahedron_stiffness(all + 3 * q[0], all + 3 * q[1], all + 3 * q[2],
                                     all + 3 * q[3], w) < 0.0) {
            const dk_index s = q[2];
            q[2] = q[3];
            q[3] = s;
        }
    }
    va->np = n + ni;
    va->nt = nt;
    va->tets = tets;
    tets = NULL;
    if (nt == 0 && !va->note[0])
        snprintf(va->note, sizeof va->note, "no volume: no closed part");
    if ((st = dk_progress_part(prog, 1.0, err)) == DK_OK && nt > 0)
        st = volume_mesh(va, all, in_volume, err);
done:
    free(in_volume);
    free(sub);
    free(faces);
    free(sp);
    free(points);
    free(tets);
    free(all);
    return st;
}

/* Interior stiffness: breadth-first from the surface over the volume's edges, each interior
 * point the mean of its neighbours one layer nearer the surface. */
static dk_status spread_stiffness(const dk_volumetric_arap *va, const double *surface,
                                  double *out, dk_error *err)
{
    const dk_mesh *v = va->volume ? va->volume : va->mesh;
    const dk_index n = va->n, np = va->np;
    dk_index *queue = malloc((size_t)np * sizeof *queue + sizeof *queue);
    dk_index *layer = malloc((size_t)np * sizeof *layer + sizeof *layer);
    if (!queue || !layer) {
        free(queue);
        free(layer);
        return dk_error_set(err, DK_ERR_OUT_OF_MEMORY, "VolumetricARAP: out of memory");
    }
    dk_index head = 0, tail = 0;
    for (dk_index i = 0; i < np; i++) {
        layer[i] = i < n ? 0 : -1;
        out[i] = i < n ? surface[i] : 0.0;
        if (i < n)
            queue[tail++] = i;
    }
    while (head < tail) {
        const dk_index i = queue[head++];
        for (dk_index q = v->ring_start[i]; q < v->ring_start[i + 1]; q++) {
            const dk_index j = v->ring_index[q];
            if (layer[j] < 0) {
                layer[j] = layer[i] + 1;
                queue[tail++] = j;
            }
        }
    }
    for (dk_index k = 0; k < tail; k++) { /* layer order: the nearer ones are set */
        const dk_index i = queue[k];
        if (i < n)
            continue;
        double sum = 0.0;
        int count = 0;
        for (dk_index q = v->ring_start[i]; q < v->ring_start[i + 1]; q++) {
            const dk_index j = v->ring_index[q];
            if (layer[j] == layer[i] - 1) {
                sum += out[j];
                count++;
            }
        }
        out[i] = count ? sum / count : 1.0;
    }
    for (dk_index i = n; i < np; i++) /* a part no surface vertex reaches: cannot happen */
        if (layer[i] < 0)
            out[i] = 1.0;
    free(queue);
    free(layer);
    return DK_OK;
}

dk_status volumetric_constraints(const dk_volumetric_arap *va, const dk_constraint_desc *in,
                                 dk_constraints **con, dk_constraint_desc *out, dk_index **roi,
                                 double **stiffness, dk_error *err)
{
    *roi = NULL;
    *stiffness = NULL;
    dk_status st = dk_constraints_create(va->mesh, in, con, err);
    if (st != DK_OK)
        return dk_error_prefix(err, "VolumetricARAP");
    *out = *in;
    const dk_index n = va->n, ni = va->np - va->n;
    if (in->n_roi > 0) {
        if (!(*roi = malloc(((size_t)in->n_roi + (size_t)ni) * sizeof **roi + 1)))
            goto oom;
        memcpy(*roi, in->roi_vertices, (size_t)in->n_roi * sizeof **roi);
        for (dk_index i = 0; i < ni; i++)
            (*roi)[in->n_roi + i] = n + i;
        out->n_roi = in->n_roi + ni;
        out->roi_vertices = *roi;
    }
    if (in->stiffness) {
        if (!(*stiffness = malloc((size_t)va->np * sizeof **stiffness + 1)))
            goto oom;
        if ((st = spread_stiffness(va, in->stiffness, *stiffness, err)) != DK_OK)
            goto fail;
        out->stiffness = *stiffness;
    }
    return DK_OK;
oom:
    st = dk_error_set(err, DK_ERR_OUT_OF_MEMORY, "VolumetricARAP: out of memory");
fail:
    dk_constraints_free(*con);
    *con = NULL;
    free(*roi);
    free(*stiffness);
    *roi = NULL;
    *stiffness = NULL;
    return st;
}
