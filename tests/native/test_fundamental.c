/* Linear reconstruction's own native checks beyond the contract (test_contract.c), so that
 * the sanitized build walks them too: the rotations R_ij built from the fundamental forms
 * (the paper's three rotations) equal f_i^T f_j of the rest frames on a bumpy cylinder, and
 * a seed face with its frame reproduces the mesh. The behaviour is tested from Python,
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

DK_TEST_MAIN(test_rotations_from_the_fundamental_forms)
