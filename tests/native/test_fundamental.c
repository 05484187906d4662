/* Linear reconstruction's own native checks beyond the contract (test_contract.c), so that
 * the sanitized build walks them too: the rotations R_ij built from the fundamental forms
 * (the paper's three rotations) equal f_i^T f_j of the rest frames on a bumpy cylinder, and
 * a seed face with its frame reproduces the mesh; a patch joined to an icosphere at three
 * vertices only (no edge: no frame equation joins it, so before the bridges its frames kept
 * a free shear and the bind was refused as singular) binds and moves rigidly with a rigid
 * motion of all constraints. The behaviour is tested from Python,
 * tests/python/test_fundamental.py. */
#include <math.h>
#include <stdlib.h>
#include <string.h>

#include "dk_fundamental.h"
#include "dk_test.h"
#include "dk_test_meshes.h"

static void test_rotations_from_the_fundamental_forms(void)
{
    dk_test_mesh t;
    CHECK(dk_test_cylinder(24, 20, 0.5, 3.0, 1, &t) == 0);
    dk_mesh *m = dk_test_mesh_build(&t);
    CHECK(m != NULL);
    if (!m) {
        dk_test_mesh_free(&t);
        return;
    }
    dk_index seed[3] = {m->faces[0], m->faces[1], m->faces[2]}, size = 3;
    dk_constraint_desc d = {.n_handles = 1, .handle_sizes = &size, .handle_vertices = seed};
    dk_fundamental_options o;
    dk_fundamental_default_options(&o);
    o.orientation = 1;
    dk_fundamental *f = NULL;
    dk_error e;
    CHECK(dk_fundamental_bind(m, &d, &o, &f, &e) == DK_OK);
    if (f) {
        const double *F = dk_fundamental_frames(f); /* before any solve: the rest frames */
        double worst = 0.0;
        int n_interior = 0;
        for (dk_index k = 0; k < m->n_edges; k++) {
            double R[9];
            if (!dk_fundamental_edge_rotation(f, k, R))
                continue;
            n_interior++;
            const double *Fi = F + 9 * (size_t)m->edge_faces[2 * (size_t)k];
            const double *Fj = F + 9 * (size_t)m->edge_faces[2 * (size_t)k + 1];
            for (int a = 0; a < 3; a++) /* (F_i^T F_j)[a][b] = sum_d F_i[d][a] F_j[d][b] */
                for (int b = 0; b < 3; b++) {
                    double s = 0.0;
                    for (int q = 0; q < 3; q++)
                        s += Fi[3 * q + a] * Fj[3 * q + b];
                    worst = fmax(worst, fabs(s - R[3 * a + b]));
                }
        }
        CHECK(n_interior > 0);
        CHECK_MSG(worst < 1e-12, "R_ij differs from f_i^T f_j by %g", worst);
        const double T[16] = {0, -1, 0, 0.5, 1, 0, 0, -0.25, 0, 0, 1, 2, 0, 0, 0, 1};
        double *x = malloc(3 * (size_t)m->n_vertices * sizeof *x);
        if (!x)
            abort();
        dk_solve_info info;
        CHECK(dk_fundamental_solve(f, &(dk_solve_request){.targets = T,
                                                          .target_kind = DK_TARGETS_TRANSFORMS},
                                   x, &info, &e) == DK_OK);
        double dev = 0.0;
        for (dk_index v = 0; v < m->n_vertices; v++) {
            const double *p = m->positions + 3 * (size_t)v;
            for (int r = 0; r < 3; r++)
                dev = fmax(dev, fabs(x[3 * (size_t)v + r] -
                                     (T[4 * r] * p[0] + T[4 * r + 1] * p[1] +
                                      T[4 * r + 2] * p[2] + T[4 * r + 3])));
        }
        CHECK_MSG(dev < 1e-9, "reconstruction off by %g", dev);
        free(x);
    }
    dk_fundamental_free(f);
    dk_mesh_free(m);
    dk_test_mesh_free(&t);
}

/* An icosphere plus a 4-triangle patch over face t (its edges' midpoints lifted off the
 * surface), sharing only the face's three corners with the sphere. */
static void test_a_patch_joined_at_vertices_only(void)
{
    dk_test_mesh t;
    CHECK(dk_test_icosphere(2, 1.0, &t) == 0);
    const dk_index nv = t.n_vertices, nf = t.n_faces, face = nf / 2;
    double *p = malloc(3 * ((size_t)nv + 3) * sizeof *p);
    dk_index *fc = malloc(3 * ((size_t)nf + 4) * sizeof *fc);
    dk_index *top = malloc((size_t)nv * sizeof *top), *bottom = malloc((size_t)nv * sizeof *bottom);
    double *x = malloc(3 * ((size_t)nv + 3) * sizeof *x);
    if (!p || !fc || !top || !bottom || !x)
        abort();
    memcpy(p, t.positions, 3 * (size_t)nv * sizeof *p);
    memcpy(fc, t.faces, 3 * (size_t)nf * sizeof *fc);
    const dk_index *c = t.faces + 3 * (size_t)face;
    double u[3], v[3], n[3];
    for (int d = 0; d < 3; d++)
        u[d] = p[3 * c[1] + d] - p[3 * c[0] + d], v[d] = p[3 * c[2] + d] - p[3 * c[0] + d];
    n[0] = u[1] * v[2] - u[2] * v[1], n[1] = u[2] * v[0] - u[0] * v[2], n[2] = u[0] * v[1] - u[1] * v[0];
    const double nl = sqrt(n[0] * n[0] + n[1] * n[1] + n[2] * n[2]);
    for (int k = 0; k < 3; k++) /* midpoints of edges c[k] c[k+1], lifted */
        for (int d = 0; d < 3; d++)
            p[3 * (size_t)(nv + k) + d] =
                0.5 * (p[3 * c[k] + d] + p[3 * c[(k + 1) % 3] + d]) + 0.05 * n[d] / nl;
    const dk_index a = nv, b = nv + 1, cc = nv + 2; /* a on c0c1, b on c1c2, cc on c2c0 */
    const dk_index extra[12] = {c[0], a, cc, c[1], b, a, c[2], cc, b, a, b, cc};
    memcpy(fc + 3 * (size_t)nf, extra, sizeof extra);
    dk_mesh *m = NULL;
    dk_error e;
    CHECK(dk_mesh_create(p, nv + 3, fc, nf + 4, &m, &e) == DK_OK);
    dk_index n_top = 0, n_bottom = 0;
    for (dk_index i = 0; i < nv; i++) {
        if (p[3 * (size_t)i + 2] > 0.7)
            top[n_top++] = i;
        if (p[3 * (size_t)i + 2] < -0.7)
            bottom[n_bottom++] = i;
    }
    const dk_index sizes[2] = {n_top, n_bottom};
    dk_index *hv = malloc((size_t)(n_top + n_bottom) * sizeof *hv);
    if (!hv)
        abort();
    memcpy(hv, top, (size_t)n_top * sizeof *hv);
    memcpy(hv + n_top, bottom, (size_t)n_bottom * sizeof *hv);
    dk_constraint_desc d = {.n_handles = 2, .handle_sizes = sizes, .handle_vertices = hv};
    for (int orientation = 0; m && orientation < 2; orientation++) {
        dk_fundamental_options o;
        dk_fundamental_default_options(&o);
        o.orientation = orientation;
        dk_fundamental *f = NULL;
        CHECK_MSG(dk_fundamental_bind(m, &d, &o, &f, &e) == DK_OK, "bind: %s", e.message);
        if (!f)
            continue;
        CHECK(dk_fundamental_has_transform_basis(f));
        /* both handles by one rigid motion: the whole mesh, the patch too, moves rigidly */
        const double ca = cos(0.7), sa = sin(0.7);
        const double T[32] = {ca, -sa, 0, 0.5, sa, ca, 0, -0.2, 0, 0, 1, 1.0, 0, 0, 0, 1,
                              ca, -sa, 0, 0.5, sa, ca, 0, -0.2, 0, 0, 1, 1.0, 0, 0, 0, 1};
        dk_solve_info info;
        CHECK(dk_fundamental_solve(f, &(dk_solve_request){.targets = T,
                                                          .target_kind = DK_TARGETS_TRANSFORMS},
                                   x, &info, &e) == DK_OK);
        double dev = 0.0;
        for (dk_index i = 0; i < nv + 3; i++)
            for (int r = 0; r < 3; r++) {
                const double *q = p + 3 * (size_t)i;
                dev = fmax(dev, fabs(x[3 * (size_t)i + r] - (T[4 * r] * q[0] + T[4 * r + 1] * q[1] +
                                                            T[4 * r + 2] * q[2] + T[4 * r + 3])));
            }
        CHECK_MSG(dev < 1e-8, "orientation %d: rigid motion off by %g", orientation, dev);
        dk_fundamental_free(f);
    }
    free(hv);
    free(x);
    free(top);
    free(bottom);
    free(p);
    free(fc);
    dk_mesh_free(m);
    dk_test_mesh_free(&t);
}

DK_TEST_MAIN(test_rotations_from_the_fundamental_forms, test_a_patch_joined_at_vertices_only)
