/* DeformKit: bounded biharmonic weights in the solid the mesh (or a cage) encloses
 * (bbw_internal.h).
 *
 * Steps: (1) the grid: cells of h = the longest side / resolution over the shape's box, and
 * the generalized winding number of the shape's triangles at every grid point (the inside is
 * winding >= 1/2: holes, parts inside parts, non-manifold edges and self-intersections of a
 * scan do not break it); (2) the points: the handles' samples (h/2 apart, so a bone is a
 * chain of domain vertices), samples of the mesh's vertices h apart (a thin part, thinner
 * than a cell, still has points on both sides; a quarter cell from the handles' at least),
 * the inside grid points further than h/2 from those; (3) TetGen's Delaunay tetrahedralization of the points, of which the
 * tetrahedra with their centroid inside are the domain; (4) the linear finite elements on
 * it: K_ij = sum over tetrahedra of vol grad(phi_i) . grad(phi_j) (the cotangent stiffness
 * of 3D), M_ii = a quarter of each incident tetrahedron's volume; (5) the mesh's vertices
 * read their weights from the tetrahedron they lie in (a sampled vertex is a domain vertex
 * itself), linearly (bbw_locate, locate.c). */
#include <math.h>
#include <stdlib.h>
#include <string.h>

#include "bbw_internal.h"
#include "dk_operators.h"

/* Whether some point of `pts` in the list of grid `g` lies within r of p. */
static int near_any(const cell_grid *g, const dk_index *next, const double *pts, const double *p,
                    double r)
{
    dk_index c[3];
    for (int k = 0; k < 3; k++) c[k] = cell_coord(g, p, k);
    for (dk_index z = c[2] > 0 ? c[2] - 1 : 0; z <= c[2] + 1 && z < g->dim[2]; z++)
        for (dk_index y = c[1] > 0 ? c[1] - 1 : 0; y <= c[1] + 1 && y < g->dim[1]; y++)
            for (dk_index x = c[0] > 0 ? c[0] - 1 : 0; x <= c[0] + 1 && x < g->dim[0]; x++)
                for (dk_index i = g->head[cell_index(g, x, y, z)]; i >= 0; i = next[i]) {
                    const double *q = pts + 3 * (size_t)i;
                    double d2 = (p[0] - q[0]) * (p[0] - q[0]) + (p[1] - q[1]) * (p[1] - q[1]) +
                                (p[2] - q[2]) * (p[2] - q[2]);
                    if (d2 < r * r) return 1;
                }
    return 0;
}

static void grid_insert(cell_grid *g, dk_index *next, const double *p, dk_index i)
{
    size_t c = cell_index(g, cell_coord(g, p, 0), cell_coord(g, p, 1), cell_coord(g, p, 2));
    next[i] = g->head[c];
    g->head[c] = i;
}

dk_status bbw_volume_domain(const dk_mesh *mesh, const dk_bbw_handles *h, int resolution,
                            bbw_domain *d, int *has_volume, dk_error *err)
{
    static const char who[] = "bounded biharmonic weights";
    memset(d, 0, sizeof *d);
    d->kind = DK_BBW_VOLUME;
    *has_volume = 0;
    const int caged = h->n_cage_triangles > 0;
    const double *sv = caged ? h->cage_vertices : mesh->positions;
    const dk_index nsv = caged ? h->n_cage_vertices : mesh->n_vertices;
    const dk_index *st_tris = caged ? h->cage_triangles : mesh->faces;
    const dk_index nst = caged ? h->n_cage_triangles : mesh->n_faces;
    const dk_index nm = mesh->n_vertices;
    double lo[3] = {INFINITY, INFINITY, INFINITY}, hi[3] = {-INFINITY, -INFINITY, -INFINITY};
    for (dk_index i = 0; i < nsv; i++)
        for (int k = 0; k < 3; k++) {
            lo[k] = fmin(lo[k], sv[3 * (size_t)i + k]);
            hi[k] = fmax(hi[k], sv[3 * (size_t)i + k]);
        }
    double longest = 0.0;
    for (int k = 0; k < 3; k++) longest = fmax(longest, hi[k] - lo[k]);
    if (nst == 0 || !(longest > 0.0) || !isfinite(longest)) return DK_OK;
    double hc = longest / resolution;

    dk_winding *wind = NULL;
    cell_grid g = {{0, 0, 0}, hc, {0, 0, 0}, NULL}, gm = g;
    double *pts = NULL, *wn = NULL, *gp = NULL, *cent = NULL;
    dk_index *next = NULL, *tets = NULL, *keep = NULL, *vmap = NULL, *mesh_point = NULL;
    dk_index *ri = NULL, *ci = NULL;
    double *vv = NULL;
    dk_index n_tets = 0;
    dk_status st = dk_winding_create(sv, nsv, st_tris, nst, &wind, err);
    if (st != DK_OK) goto done;

    /* (1) grid points and their winding numbers; the grid is centred on the box. The cost
     * is the 3D bilaplacian's factorizations, which grow with the points inside, not with
     * the box: a compact shape (a sphere fills half its box, the armadillo a fifth) gets
     * coarser cells, so that about resolution^3 / 8 grid points are inside */
    dk_index gdim[3];
    size_t n_grid = 1, n_inside = 0;
    const double target = (double)resolution * resolution * resolution / 8.0;
    for (int pass = 0; pass < 2; pass++) {
        n_grid = 1;
        for (int k = 0; k < 3; k++) {
            gdim[k] = (dk_index)floor((hi[k] - lo[k]) / hc) + 2;
            g.origin[k] = 0.5 * (lo[k] + hi[k]) - 0.5 * (double)(gdim[k] - 1) * hc;
            n_grid *= (size_t)gdim[k];
        }
        free(gp);
        free(wn);
        gp = malloc(n_grid * 3 * sizeof *gp);
        wn = malloc(n_grid * sizeof *wn);
        if (!gp || !wn) goto oom;
        for (size_t i = 0; i < n_grid; i++) {
            size_t x = i % (size_t)gdim[0], y = (i / (size_t)gdim[0]) % (size_t)gdim[1],
                   z = i / ((size_t)gdim[0] * (size_t)gdim[1]);
            gp[3 * i] = g.origin[0] + (double)x * hc;
            gp[3 * i + 1] = g.origin[1] + (double)y * hc;
            gp[3 * i + 2] = g.origin[2] + (double)z * hc;
        }
        dk_winding_number(wind, gp, (dk_index)n_grid, wn);
        /* |w|: a mesh whose triangles all face inwards (the horse of ../shared/meshes) winds
         * -1 about its inside */
        for (size_t i = 0; i < n_grid; i++) wn[i] = fabs(wn[i]);
        n_inside = 0;
        for (size_t i = 0; i < n_grid; i++) n_inside += wn[i] >= 0.5;
        if (pass == 0 && (double)n_inside > 1.25 * target)
            hc *= cbrt((double)n_inside / target);
        else
            break;
    }
    g.h = hc;
    d->cell = hc;
    st = bbw_sample_handles(h, 0.5 * hc, &d->samples, &d->n_samples, err);
    if (st != DK_OK) goto done;
    if (n_inside == 0) goto done; /* no volume: the caller takes the surface */
    *has_volume = 1;

    /* (2) the points: handle samples, mesh samples, inside grid points; a cell list of h
     * over the box with a margin of one cell finds neighbours */
    for (int k = 0; k < 3; k++) {
        g.origin[k] -= hc;
        g.dim[k] = gdim[k] + 2;
    }
    size_t cap = (size_t)d->n_samples + (size_t)(caged ? 0 : nm) + n_inside;
    size_t n_cells = (size_t)g.dim[0] * (size_t)g.dim[1] * (size_t)g.dim[2];
    pts = malloc((cap + 1) * 3 * sizeof *pts);
    next = malloc((cap + 1) * sizeof *next);
    g.head = malloc(n_cells * sizeof *g.head);
    mesh_point = malloc(((size_t)nm + 1) * sizeof *mesh_point);
    if (!pts || !next || !g.head || !mesh_point) goto oom;
    for (size_t c = 0; c < n_cells; c++) g.head[c] = -1;
    dk_index np = 0;
    for (dk_index s = 0; s < d->n_samples; s++) {
        memcpy(pts + 3 * (size_t)np, d->samples[s].p, 3 * sizeof(double));
        grid_insert(&g, next, pts + 3 * (size_t)np, np);
        np++;
    }
    const dk_index n_handle_points = np;
    /* the mesh's samples in a cell list of their own: h apart from each other, but only a
     * quarter cell from the handles' (a thin limb around a bone keeps its surface) */
    gm = g;
    gm.head = malloc(n_cells * sizeof *gm.head);
    if (!gm.head) goto oom;
    for (size_t c = 0; c < n_cells; c++) gm.head[c] = -1;
    for (dk_index v = 0; v < nm; v++) {
        mesh_point[v] = -1;
        const double *p = mesh->positions + 3 * (size_t)v;
        if (caged || near_any(&gm, next, pts, p, hc) || near_any(&g, next, pts, p, 0.25 * hc))
            continue;
        mesh_point[v] = np;
        memcpy(pts + 3 * (size_t)np, p, 3 * sizeof(double));
        grid_insert(&gm, next, p, np);
        np++;
    }
    for (size_t i = 0; i < n_grid; i++) {
        if (wn[i] < 0.5 || near_any(&g, next, pts, gp + 3 * i, 0.5 * hc) ||
            near_any(&gm, next, pts, gp + 3 * i, 0.5 * hc))
            continue;
        memcpy(pts + 3 * (size_t)np, gp + 3 * i, 3 * sizeof(double));
        grid_insert(&g, next, gp + 3 * i, np);
        np++;
    }
    free(gp);
    gp = NULL;
    free(wn);
    wn = NULL;

    /* (3) Delaunay tetrahedra, those with the centroid inside kept */
    st = dk_delaunay_tetrahedra(pts, np, &tets, &n_tets, err);
    if (st != DK_OK) goto done;
    cent = malloc(((size_t)n_tets + 1) * 3 * sizeof *cent);
    wn = malloc(((size_t)n_tets + 1) * sizeof *wn);
    keep = malloc(((size_t)n_tets + 1) * sizeof *keep);
    vmap = malloc(((size_t)np + 1) * sizeof *vmap);
    if (!cent || !wn || !keep || !vmap) goto oom;
    for (dk_index t = 0; t < n_tets; t++)
        for (int k = 0; k < 3; k++) {
            double s = 0.0;
            for (int c = 0; c < 4; c++) s += pts[3 * (size_t)tets[4 * (size_t)t + c] + k];
            cent[3 * (size_t)t + k] = 0.25 * s;
        }
    dk_winding_number(wind, cent, n_tets, wn);
    for (dk_index t = 0; t < n_tets; t++) wn[t] = fabs(wn[t]);
    dk_index n_keep = 0;
    const double min_vol6 = 1e-9 * hc * hc * hc;
    for (dk_index i = 0; i < np; i++) vmap[i] = -1;
    for (dk_index t = 0; t < n_tets; t++) {
        const dk_index *tv = tets + 4 * (size_t)t;
        double grad[12];
        double vol6 = dk_tetrahedron_frame(pts + 3 * (size_t)tv[0], pts + 3 * (size_t)tv[1],
                                pts + 3 * (size_t)tv[2], pts + 3 * (size_t)tv[3], grad);
        if (wn[t] < 0.5 || !(fabs(vol6) > min_vol6)) continue;
        keep[n_keep++] = t;
        for (int c = 0; c < 4; c++) vmap[tv[c]] = 0;
    }
    /* a handle sample no kept tetrahedron touches (a point on the surface, where the cells
     * are coarse) joins by its incident tetrahedron with the most inside centroid */
    {
        dk_index *join = malloc(((size_t)n_handle_points + 1) * sizeof *join);
        if (!join) goto oom;
        for (dk_index s = 0; s < n_handle_points; s++) join[s] = -1;
        for (dk_index t = 0; t < n_tets; t++)
            for (int c = 0; c < 4; c++) {
                dk_index v = tets[4 * (size_t)t + c];
                if (v < n_handle_points && vmap[v] < 0 && (join[v] < 0 || wn[t] > wn[join[v]])) {
                    double grad[12];
                    const dk_index *tv = tets + 4 * (size_t)t;
                    if (fabs(dk_tetrahedron_frame(pts + 3 * (size_t)tv[0], pts + 3 * (size_t)tv[1],
                                       pts + 3 * (size_t)tv[2], pts + 3 * (size_t)tv[3], grad)) > min_vol6)
                        join[v] = t;
                }
            }
        for (dk_index s = 0; s < n_handle_points; s++) {
            if (join[s] < 0 || vmap[s] == 0) continue;
            if (wn[join[s]] < 0.5) { /* not kept yet (another sample may have joined it) */
                keep[n_keep++] = join[s];
                wn[join[s]] = 1.0;
            }
            for (int c = 0; c < 4; c++) vmap[tets[4 * (size_t)join[s] + c]] = 0;
        }
        free(join);
    }
    dk_index nd = 0;
    for (dk_index i = 0; i < np; i++)
        if (vmap[i] == 0) vmap[i] = nd++;
    if (n_keep == 0 || nd == 0) {
        *has_volume = 0;
        goto done;
    }

    /* (4) the domain: positions, stiffness, mass, held samples */
    d->n = nd;
    d->n_elements = n_keep;
    d->positions = malloc((size_t)nd * 3 * sizeof *d->positions);
    d->mass = calloc((size_t)nd, sizeof *d->mass);
    d->held = malloc(((size_t)n_handle_points + 1) * sizeof *d->held);
    d->held_sample = malloc(((size_t)n_handle_points + 1) * sizeof *d->held_sample);
    ri = malloc((size_t)n_keep * 16 * sizeof *ri);
    ci = malloc((size_t)n_keep * 16 * sizeof *ci);
    vv = malloc((size_t)n_keep * 16 * sizeof *vv);
    d->tets = malloc((size_t)n_keep * 4 * sizeof *d->tets);
    d->frames = malloc((size_t)n_keep * 12 * sizeof *d->frames);
    d->cell = hc;
    if (!d->positions || !d->mass || !d->held || !d->held_sample || !ri || !ci || !vv ||
        !d->tets || !d->frames)
        goto oom;
    for (dk_index i = 0; i < np; i++)
        if (vmap[i] >= 0) memcpy(d->positions + 3 * (size_t)vmap[i], pts + 3 * (size_t)i,
                                 3 * sizeof(double));
    for (dk_index k = 0; k < n_keep; k++) {
        const dk_index *tv = tets + 4 * (size_t)keep[k];
        double grad[12];
        double vol = fabs(dk_tetrahedron_frame(pts + 3 * (size_t)tv[0], pts + 3 * (size_t)tv[1],
                                    pts + 3 * (size_t)tv[2], pts + 3 * (size_t)tv[3], grad)) / 6.0;
        for (int a = 0; a < 4; a++) {
            d->mass[vmap[tv[a]]] += 0.25 * vol;
            for (int b = 0; b < 4; b++) {
                size_t q = 16 * (size_t)k + 4 * (size_t)a + (size_t)b;
                ri[q] = vmap[tv[a]];
                ci[q] = vmap[tv[b]];
                vv[q] = vol * (grad[3 * a] * grad[3 * b] + grad[3 * a + 1] * grad[3 * b + 1] +
                               grad[3 * a + 2] * grad[3 * b + 2]);
            }
        }
        /* for locating: corner 0 and the gradients of corners 1..3 */
        for (int c = 0; c < 4; c++) d->tets[4 * (size_t)k + c] = vmap[tv[c]];
        memcpy(d->frames + 12 * (size_t)k, pts + 3 * (size_t)tv[0], 3 * sizeof(double));
        memcpy(d->frames + 12 * (size_t)k + 3, grad + 3, 9 * sizeof(double));
    }
    st = dk_sparse_from_triplets(nd, nd, (int64_t)n_keep * 16, ri, ci, vv, &d->stiffness, err);
    if (st != DK_OK) goto done;
    for (dk_index s = 0; s < n_handle_points; s++)
        if (vmap[s] >= 0) {
            d->held[d->n_held] = vmap[s];
            d->held_sample[d->n_held++] = s;
        }
    st = bbw_check_held(d, h, err);
    if (st != DK_OK) goto done;

    /* (5) the mesh's vertices in the domain: sampled ones directly, the others located */
    d->embed = malloc(((size_t)nm + 1) * 4 * sizeof *d->embed);
    d->embed_weight = calloc(((size_t)nm + 1) * 4, sizeof *d->embed_weight);
    if (!d->embed || !d->embed_weight) goto oom;
    st = bbw_locate(d, mesh->positions, nm, d->embed, d->embed_weight, err);
    if (st != DK_OK) goto done;
    for (dk_index v = 0; v < nm; v++)
        if (mesh_point[v] >= 0 && vmap[mesh_point[v]] >= 0) {
            dk_index *e = d->embed + 4 * (size_t)v;
            double *ew = d->embed_weight + 4 * (size_t)v;
            e[0] = vmap[mesh_point[v]];
            e[1] = e[2] = e[3] = -1;
            ew[0] = 1.0;
            ew[1] = ew[2] = ew[3] = 0.0;
        }
    goto done;
oom:
    st = dk_error_set(err, DK_ERR_OUT_OF_MEMORY, "%s: out of memory", who);
done:
    dk_winding_free(wind);
    free(pts);
    free(next);
    free(g.head);
    free(gm.head);
    free(gp);
    free(wn);
    free(tets);
    free(cent);
    free(keep);
    free(vmap);
    free(mesh_point);
    free(ri);
    free(ci);
    free(vv);
    if (st != DK_OK || !*has_volume) bbw_domain_free(d);
    return st;
}
