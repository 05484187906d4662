/* Simplification by half-edge collapses (dk_decimate) and its prolongation: the coarse
 * mesh keeps the surface's topology (a closed sphere stays a closed manifold of Euler
 * characteristic 2, a grid keeps its boundary loop), reaches its target, never merges
 * vertices of different classes nor removes a negative class; the prolongation gives the
 * pose back exactly from its own coarse vertices and a rigid motion from the moved coarse
 * vertices with their rotation; scaling by a power of two changes nothing. */
#include <math.h>
#include <stdlib.h>
#include <string.h>

#include "dk_mesh.h"
#include "dk_operators.h"
#include "dk_test.h"
#include "dk_test_meshes.h"

static int cmp(const void *x, const void *y)
{
    const dk_index *a = x, *b = y;
    return a[0] != b[0] ? (a[0] < b[0] ? -1 : 1) : a[1] != b[1] ? (a[1] < b[1] ? -1 : 1) : 0;
}

/* every coarse edge in one or two triangles (one only on the boundary when open), no
 * repeated triangle, no degenerate index; returns V - E + F */
static long check_manifold(const dk_decimation *d, int closed)
{
    const dk_index nf = d->n_faces;
    dk_index *e = malloc(6 * (size_t)nf * sizeof *e);
    CHECK(e != NULL);
    for (dk_index f = 0; f < nf; f++) {
        const dk_index *t = d->faces + 3 * f;
        CHECK(t[0] != t[1] && t[1] != t[2] && t[0] != t[2]);
        for (int k = 0; k < 3; k++) {
            CHECK(t[k] >= 0 && t[k] < d->n_kept);
            const dk_index a = t[k], b = t[(k + 1) % 3];
            e[6 * f + 2 * k] = a < b ? a : b;
            e[6 * f + 2 * k + 1] = a < b ? b : a;
        }
    }
    const size_t ne = 3 * (size_t)nf; /* edges counted by sorting the pairs */
    qsort(e, ne, 2 * sizeof *e, cmp);
    long edges = 0;
    int bad = 0;
    for (size_t i = 0; i < ne;) {
        size_t j = i;
        while (j < ne && e[2 * j] == e[2 * i] && e[2 * j + 1] == e[2 * i + 1])
            j++;
        const size_t count = j - i;
        if (count > 2 || (closed && count != 2))
            bad++;
        edges++;
        i = j;
    }
    CHECK_MSG(bad == 0, "%d edges in the wrong number of triangles", bad);
    free(e);
    return (long)d->n_kept - edges + (long)nf;
}

static void test_sphere(void)
{
    dk_test_mesh s;
    CHECK(dk_test_icosphere(4, 1.0, &s) == 0); /* 2562 vertices */
    dk_mesh *m = dk_test_mesh_build(&s);
    dk_decimation *d = NULL;
    dk_error err;
    CHECK(dk_decimate(m, NULL, 300, &d, &err) == DK_OK);
    CHECK_MSG(d->n_kept == 300, "kept %ld", (long)d->n_kept);
    CHECK(d->n_kept + d->n_removed == m->n_vertices);
    CHECK_MSG(check_manifold(d, 1) == 2, "Euler characteristic changed");
    /* the kept vertices ascending, coarse_of their inverse */
    for (dk_index c = 0; c < d->n_kept; c++) {
        CHECK(c == 0 || d->kept[c] > d->kept[c - 1]);
        CHECK(d->coarse_of[d->kept[c]] == c);
    }
    /* the coarse sphere stays round: every coarse triangle's plane near the unit sphere */
    double worst = 0.0;
    for (dk_index f = 0; f < d->n_faces; f++) {
        double cen[3] = {0, 0, 0};
        for (int k = 0; k < 3; k++)
            for (int j = 0; j < 3; j++)
                cen[j] += m->positions[3 * d->kept[d->faces[3 * f + k]] + j] / 3.0;
        worst = fmax(worst, 1.0 - sqrt(cen[0] * cen[0] + cen[1] * cen[1] + cen[2] * cen[2]));
    }
    CHECK_MSG(worst < 0.05, "a coarse triangle %g inside the sphere", worst);

    /* the pose from its own coarse vertices, exactly; with identity rotations too */
    const dk_index n = m->n_vertices;
    double *y = malloc(3 * (size_t)d->n_kept * sizeof *y), *x = malloc(3 * (size_t)n * sizeof *x);
    double *rot = malloc(9 * (size_t)d->n_kept * sizeof *rot), *scratch = malloc(4 * (size_t)n * sizeof *scratch);
    for (dk_index c = 0; c < d->n_kept; c++)
        memcpy(y + 3 * c, m->positions + 3 * d->kept[c], 3 * sizeof *y);
    dk_decimation_prolong(d, m->positions, y, NULL, x, NULL);
    double e0 = 0.0;
    for (dk_index i = 0; i < 3 * n; i++)
        e0 = fmax(e0, fabs(x[i] - m->positions[i]));
    CHECK_MSG(e0 < 1e-14, "pose not given back: %g", e0);
    /* a rigid motion: 0.7 rad about (1, 2, 2)/3, then (5, -3, 2) */
    const double ax[3] = {1.0 / 3, 2.0 / 3, 2.0 / 3}, th = 0.7, co = cos(th), si = sin(th);
    double R[9];
    for (int i = 0; i < 3; i++)
        for (int j = 0; j < 3; j++)
            R[3 * i + j] = (i == j ? co : 0.0) + (1 - co) * ax[i] * ax[j];
    R[1] -= si * ax[2], R[2] += si * ax[1], R[3] += si * ax[2];
    R[5] -= si * ax[0], R[6] -= si * ax[1], R[7] += si * ax[0];
    const double t[3] = {5.0, -3.0, 2.0};
    for (dk_index c = 0; c < d->n_kept; c++) {
        const double *p = m->positions + 3 * d->kept[c];
        for (int i = 0; i < 3; i++)
            y[3 * c + i] = R[3 * i] * p[0] + R[3 * i + 1] * p[1] + R[3 * i + 2] * p[2] + t[i];
        memcpy(rot + 9 * c, R, sizeof R);
    }
    dk_decimation_prolong(d, m->positions, y, rot, x, scratch);
    double e1 = 0.0, e2 = 0.0;
    for (dk_index v = 0; v < n; v++) {
        const double *p = m->positions + 3 * v;
        for (int i = 0; i < 3; i++)
            e1 = fmax(e1, fabs(x[3 * v + i] - (R[3 * i] * p[0] + R[3 * i + 1] * p[1] +
                                               R[3 * i + 2] * p[2] + t[i])));
    }
    CHECK_MSG(e1 < 1e-12, "rigid motion not prolonged exactly: %g", e1);
    /* without the rotations the details keep their rest offsets: not rigid */
    dk_decimation_prolong(d, m->positions, y, NULL, x, NULL);
    for (dk_index v = 0; v < n; v++) {
        const double *p = m->positions + 3 * v;
        for (int i = 0; i < 3; i++)
            e2 = fmax(e2, fabs(x[3 * v + i] - (R[3 * i] * p[0] + R[3 * i + 1] * p[1] +
                                               R[3 * i + 2] * p[2] + t[i])));
    }
    CHECK_MSG(e2 > 1e-4, "offsets not rotated should show: %g", e2);

    /* scaled by 4: the same collapses */
    dk_test_mesh s4;
    CHECK(dk_test_icosphere(4, 4.0, &s4) == 0);
    for (dk_index i = 0; i < 3 * n; i++)
        s4.positions[i] = 4.0 * s.positions[i];
    dk_mesh *m4 = dk_test_mesh_build(&s4);
    dk_decimation *d4 = NULL;
    CHECK(dk_decimate(m4, NULL, 300, &d4, &err) == DK_OK);
    CHECK(d4->n_kept == d->n_kept && d4->n_faces == d->n_faces);
    CHECK(memcmp(d4->kept, d->kept, (size_t)d->n_kept * sizeof *d->kept) == 0);
    CHECK(memcmp(d4->faces, d->faces, 3 * (size_t)d->n_faces * sizeof *d->faces) == 0);
    dk_decimation_free(d4);
    dk_mesh_free(m4);
    dk_test_mesh_free(&s4);
    free(y);
    free(x);
    free(rot);
    free(scratch);
    dk_decimation_free(d);
    dk_mesh_free(m);
    dk_test_mesh_free(&s);
}

static void test_grid_classes(void)
{
    dk_test_mesh g;
    CHECK(dk_test_grid(30, 1.0, 0.2, &g) == 0); /* 961 vertices, open */
    dk_mesh *m = dk_test_mesh_build(&g);
    const dk_index n = m->n_vertices;
    int *cls = malloc((size_t)n * sizeof *cls);
    for (dk_index v = 0; v < n; v++) {
        const double x = m->positions[3 * v], y = m->positions[3 * v + 1];
        cls[v] = x < 0.2 ? 1 : (x > 0.8 && y > 0.8) ? 2 : 0;
    }
    cls[15 * 31 + 15] = -1; /* a single vertex that must stay */
    dk_decimation *d = NULL;
    dk_error err;
    CHECK(dk_decimate(m, cls, 60, &d, &err) == DK_OK);
    CHECK(d->coarse_of[15 * 31 + 15] >= 0);
    CHECK_MSG(check_manifold(d, 0) == 1, "a disc stays a disc");
    /* each class keeps vertices */
    int seen[3] = {0, 0, 0};
    for (dk_index c = 0; c < d->n_kept; c++)
        if (cls[d->kept[c]] >= 0)
            seen[cls[d->kept[c]]] = 1;
    CHECK(seen[0] && seen[1] && seen[2]);
    /* the square's corners are kept (each is a boundary vertex with a right angle: its
     * boundary planes make moving it cost) and every boundary edge of the coarse mesh runs
     * along a side of the square (boundary vertices collapse along the boundary only) */
    int along = 0, boundary = 0;
    for (dk_index f = 0; f < d->n_faces; f++)
        for (int k = 0; k < 3; k++) {
            const dk_index a = d->faces[3 * f + k], b = d->faces[3 * f + (k + 1) % 3];
            int twin = 0; /* the edge (b, a) in another triangle */
            for (dk_index g = 0; g < d->n_faces && !twin; g++)
                for (int j = 0; j < 3 && !twin; j++)
                    twin = d->faces[3 * g + j] == b && d->faces[3 * g + (j + 1) % 3] == a;
            if (twin)
                continue;
            const double *p = m->positions + 3 * d->kept[a], *q = m->positions + 3 * d->kept[b];
            boundary++;
            along += (p[0] == q[0] && (p[0] == 0.0 || p[0] == 1.0)) ||
                     (p[1] == q[1] && (p[1] == 0.0 || p[1] == 1.0));
        }
    CHECK_MSG(boundary >= 4 && along == boundary, "%d of %d boundary edges along the square",
              along, boundary);
    const dk_index corners[4] = {0, 30, 30 * 31, 31 * 31 - 1};
    for (int k = 0; k < 4; k++)
        CHECK_MSG(d->coarse_of[corners[k]] >= 0, "corner %ld removed", (long)corners[k]);
    /* weights are barycentric */
    for (dk_index k = 0; k < d->n_removed; k++) {
        const double *w = d->weight + 3 * k;
        CHECK(w[0] >= 0 && w[1] >= 0 && w[2] >= 0 && fabs(w[0] + w[1] + w[2] - 1.0) < 1e-12);
    }
    dk_decimation_free(d);
    /* bad input */
    CHECK(dk_decimate(m, NULL, 0, &d, &err) == DK_ERR_INVALID_ARGUMENT && d == NULL);
    CHECK(strstr(err.message, "target_vertices") != NULL);
    free(cls);
    dk_mesh_free(m);
    dk_test_mesh_free(&g);
}

static int stop_after(void *user, double done, double total)
{
    int *calls = user;
    CHECK(done >= 0.0 && done <= total);
    return ++*calls > 100;
}

static void test_cancelled(void)
{
    dk_test_mesh s;
    CHECK(dk_test_icosphere(3, 1.0, &s) == 0);
    dk_mesh *m = dk_test_mesh_build(&s);
    dk_decimation *d = (dk_decimation *)&s; /* overwritten with NULL */
    dk_error err;
    int calls = 0;
    CHECK(dk_decimate_progress(m, NULL, 50, stop_after, &calls, &d, &err) == DK_ERR_CANCELLED);
    CHECK(d == NULL && calls == 101);
    dk_mesh_free(m);
    dk_test_mesh_free(&s);
}

DK_TEST_MAIN(test_sphere, test_grid_classes, test_cancelled)
