/* Tetrahedralizing a closed surface's interior (dk_tetrahedralize_surface, TetGen): the
 * surface's vertices are the first points, bit for bit; the tetrahedra fill exactly the
 * enclosed volume (their volumes sum to the divergence theorem's); the faces used by one
 * tetrahedron only are the surface's triangles; quality and size bounds add interior points
 * and keep every tetrahedron under the size; open, non-manifold, degenerate, flat and
 * self-intersecting surfaces are refused by name, nothing written; the quick crossing check
 * (dk_surface_crossings) counts only clear crossings. */
#include <math.h>
#include <stdlib.h>
#include <string.h>

#include "dk_operators.h"
#include "dk_test.h"
#include "dk_test_meshes.h"

static double tet_volume(const double *p, const dk_index *t)
{
    const double *a = p + 3 * t[0], *b = p + 3 * t[1], *c = p + 3 * t[2], *d = p + 3 * t[3];
    double u[3], v[3], w[3];
    for (int k = 0; k < 3; k++)
        u[k] = b[k] - a[k], v[k] = c[k] - a[k], w[k] = d[k] - a[k];
    return (u[0] * (v[1] * w[2] - v[2] * w[1]) - u[1] * (v[0] * w[2] - v[2] * w[0]) +
            u[2] * (v[0] * w[1] - v[1] * w[0])) / 6.0;
}

static double enclosed_volume(const dk_test_mesh *m)
{
    double s = 0.0;
    for (dk_index t = 0; t < m->n_faces; t++) {
        const double *a = m->positions + 3 * m->faces[3 * t], *b = m->positions + 3 * m->faces[3 * t + 1],
                     *c = m->positions + 3 * m->faces[3 * t + 2];
        s += a[0] * (b[1] * c[2] - b[2] * c[1]) - a[1] * (b[0] * c[2] - b[2] * c[0]) +
             a[2] * (b[0] * c[1] - b[1] * c[0]);
    }
    return fabs(s) / 6.0;
}

typedef struct face3 {
    dk_index v[3];
} face3;

static int by_face(const void *a, const void *b)
{
    return memcmp(a, b, sizeof(face3));
}

static void sort3(dk_index *v)
{
    for (int i = 0; i < 2; i++)
        for (int j = 0; j < 2 - i; j++)
            if (v[j] > v[j + 1]) {
                const dk_index t = v[j];
                v[j] = v[j + 1], v[j + 1] = t;
            }
}

/* The faces of the tetrahedra used once, sorted, against the surface's triangles, sorted. */
static int boundary_is_the_surface(const dk_test_mesh *m, const dk_index *tets, dk_index nt)
{
    face3 *f = malloc(sizeof(face3) * 4 * (size_t)nt), *s = malloc(sizeof(face3) * (size_t)m->n_faces);
    if (!f || !s)
        abort();
    static const int opp[4][3] = {{1, 2, 3}, {0, 2, 3}, {0, 1, 3}, {0, 1, 2}};
    for (dk_index t = 0; t < nt; t++)
        for (int k = 0; k < 4; k++) {
            for (int j = 0; j < 3; j++)
                f[4 * t + k].v[j] = tets[4 * t + opp[k][j]];
            sort3(f[4 * t + k].v);
        }
    qsort(f, 4 * (size_t)nt, sizeof(face3), by_face);
    dk_index nb = 0;
    face3 *once = malloc(sizeof(face3) * 4 * (size_t)nt);
    if (!once)
        abort();
    for (size_t i = 0; i < 4 * (size_t)nt;) {
        size_t j = i;
        while (j < 4 * (size_t)nt && by_face(&f[j], &f[i]) == 0)
            j++;
        if (j - i == 1)
            once[nb++] = f[i];
        i = j;
    }
    for (dk_index t = 0; t < m->n_faces; t++) {
        memcpy(s[t].v, m->faces + 3 * t, sizeof s[t].v);
        sort3(s[t].v);
    }
    qsort(s, (size_t)m->n_faces, sizeof(face3), by_face);
    const int same = nb == m->n_faces && memcmp(once, s, sizeof(face3) * (size_t)nb) == 0;
    free(f);
    free(s);
    free(once);
    return same;
}

static void check_surface(const char *name, const dk_test_mesh *m, double quality, double max_volume)
{
    double *p = NULL;
    dk_index *t = NULL, np = 0, nt = 0;
    dk_error e = {0};
    const dk_status st = dk_tetrahedralize_surface(m->positions, m->n_vertices, m->faces, m->n_faces,
                                                   quality, max_volume, &p, &np, &t, &nt, &e);
    CHECK_MSG(st == DK_OK, "%s: %s", name, e.message);
    if (st != DK_OK)
        return;
    CHECK_MSG(np >= m->n_vertices && memcmp(p, m->positions, sizeof(double) * 3 * (size_t)m->n_vertices) == 0,
              "%s: the surface's vertices are not the first points", name);
    double vol = 0.0, largest = 0.0;
    for (dk_index k = 0; k < nt; k++) {
        const double v = fabs(tet_volume(p, t + 4 * k));
        vol += v;
        largest = fmax(largest, v);
    }
    const double want = enclosed_volume(m);
    CHECK_MSG(fabs(vol - want) <= 1e-9 * want, "%s: tetrahedra %.15g, enclosed %.15g", name, vol, want);
    CHECK_MSG(boundary_is_the_surface(m, t, nt), "%s: the tetrahedra's boundary is not the surface", name);
    if (max_volume > 0.0)
        CHECK_MSG(largest <= max_volume * (1.0 + 1e-9) && np > m->n_vertices,
                  "%s: largest tetrahedron %g over %g", name, largest, max_volume);
    free(p);
    free(t);
}

static void test_closed_surfaces(void)
{
    dk_test_mesh bar = {0}, sphere = {0};
    CHECK(dk_test_closed_bar(12, 3, 0.2, 2.0, &bar) == 0);
    CHECK(dk_test_icosphere(3, 1.0, &sphere) == 0);
    check_surface("closed bar", &bar, 0.0, 0.0);
    check_surface("closed bar, quality 1.5", &bar, 1.5, 0.0);
    check_surface("icosphere", &sphere, 0.0, 0.0);
    check_surface("icosphere, quality 1.5, volume 0.01", &sphere, 1.5, 0.01);
    dk_test_mesh_free(&bar);
    dk_test_mesh_free(&sphere);
}

static void refused(const char *name, const double *x, dk_index n, const dk_index *f, dk_index m,
                    dk_status want, const char *words)
{
    double *p = (double *)1;
    dk_index *t = (dk_index *)1, np = 7, nt = 7;
    dk_error e = {0};
    const dk_status st = dk_tetrahedralize_surface(x, n, f, m, 0.0, 0.0, &p, &np, &t, &nt, &e);
    CHECK_MSG(st == want && strstr(e.message, words) != NULL && !p && !t && np == 0 && nt == 0,
              "%s: status %d, '%s'", name, (int)st, e.message);
    free(p);
    free(t);
}

static void test_refusals(void)
{
    dk_test_mesh open = {0}, sphere = {0};
    CHECK(dk_test_cylinder(12, 6, 0.3, 1.0, 0, &open) == 0);
    CHECK(dk_test_icosphere(2, 1.0, &sphere) == 0);
    refused("an open tube", open.positions, open.n_vertices, open.faces, open.n_faces,
            DK_ERR_INVALID_ARGUMENT, "closed and manifold");
    /* two spheres overlapping, as one surface: closed and manifold, but self-intersecting */
    const dk_index n = sphere.n_vertices, m = sphere.n_faces;
    double *x2 = malloc(sizeof(double) * 6 * (size_t)n);
    dk_index *f2 = malloc(sizeof(dk_index) * 6 * (size_t)m);
    if (!x2 || !f2)
        abort();
    memcpy(x2, sphere.positions, sizeof(double) * 3 * (size_t)n);
    for (dk_index v = 0; v < n; v++)
        for (int k = 0; k < 3; k++)
            x2[3 * (n + v) + k] = sphere.positions[3 * v + k] + (k == 0 ? 0.7 : 0.01 * k);
    memcpy(f2, sphere.faces, sizeof(dk_index) * 3 * (size_t)m);
    for (dk_index i = 0; i < 3 * m; i++)
        f2[3 * m + i] = sphere.faces[i] + n;
    refused("two overlapping spheres", x2, 2 * n, f2, 2 * m, DK_ERR_DEGENERATE, "intersects itself");
    /* a corner out of range, a repeated corner, a degenerate triangle */
    f2[4] = 2 * n + 5;
    refused("a corner out of range", x2, 2 * n, f2, m, DK_ERR_INVALID_ARGUMENT, "out of [0,");
    memcpy(f2, sphere.faces, sizeof(dk_index) * 3 * (size_t)m);
    f2[4] = f2[3];
    refused("a repeated corner", sphere.positions, n, f2, m, DK_ERR_INVALID_ARGUMENT, "repeats");
    memcpy(f2, sphere.faces, sizeof(dk_index) * 3 * (size_t)m);
    memcpy(x2, sphere.positions, sizeof(double) * 3 * (size_t)n);
    memcpy(x2 + 3 * f2[1], x2 + 3 * f2[0], sizeof(double) * 3); /* corner 1 onto corner 0 */
    refused("a degenerate triangle", x2, n, f2, m, DK_ERR_DEGENERATE, "degenerate");
    /* flat: a closed "pillow" of two triangles back to back over four points on a plane */
    const double flat[12] = {0, 0, 0, 1, 0, 0, 0, 1, 0, 1, 1, 0};
    const dk_index pillow[12] = {0, 1, 2, 2, 1, 0, 1, 3, 2, 2, 3, 1};
    refused("a flat surface", flat, 4, pillow, 4, DK_ERR_INVALID_ARGUMENT, "closed and manifold");
    double nan_x[12];
    memcpy(nan_x, flat, sizeof nan_x);
    nan_x[4] = NAN;
    refused("a non-finite vertex", nan_x, 4, pillow, 4, DK_ERR_NONFINITE, "");
    free(x2);
    free(f2);
    dk_test_mesh_free(&open);
    dk_test_mesh_free(&sphere);
}

/* dk_surface_crossings, the quick self-intersection check: two triangles that certainly cross
 * count (both), a corner exactly on the other's plane, coplanar overlap, a shared corner and
 * separate triangles do not (left to TetGen's exact check); the same at any scale and
 * placement; a closed sphere has none, two overlapping spheres have some (shifted off the
 * axis too: a sphere moved along x alone meets its copy only in exactly degenerate pairs,
 * which the certified predicates leave to TetGen); a pair that only rounding makes cross
 * (the second review's sliver, two separate tetrahedra) is not reported. */
static dk_index crossings(const double *x, dk_index n, const dk_index *f, dk_index m)
{
    dk_index c = -1;
    dk_error err = {0};
    CHECK_MSG(dk_surface_crossings(x, n, f, m, &c, &err) == DK_OK, "%s", err.message);
    return c;
}

static void test_surface_crossings(void)
{
    /* a triangle in z = 0, and one standing through it (corners at z = -1 and z = 1) */
    double x[18] = {-1, -1, 0, 2, -1, 0, -1, 2, 0,   0.2, 0.3, -1, 0.2, 0.3, 1, 0.9, 0.3, 1};
    const dk_index f[6] = {0, 1, 2, 3, 4, 5};
    CHECK(crossings(x, 6, f, 2) == 2);
    for (int scale = 0; scale < 2; scale++) { /* the same far away and 1e6 times larger */
        double y[18];
        for (int i = 0; i < 18; i++)
            y[i] = (scale ? 1e6 : 1.0) * x[i] + (i % 3 == 0 ? 3e7 : -2e5);
        CHECK(crossings(y, 6, f, 2) == 2);
    }
    double touch[18];
    memcpy(touch, x, sizeof touch);
    touch[11] = 0.0; /* the standing triangle's lower corner on the plane: not clear */
    CHECK(crossings(touch, 6, f, 2) == 0);
    double flat[18];
    memcpy(flat, x, sizeof flat);
    flat[11] = flat[14] = flat[17] = 0.0; /* coplanar and overlapping: left to TetGen */
    CHECK(crossings(flat, 6, f, 2) == 0);
    double apart[18];
    memcpy(apart, x, sizeof apart);
    for (int k = 9; k < 18; k += 3)
        apart[k] += 5.0; /* beside the first one: no crossing */
    CHECK(crossings(apart, 6, f, 2) == 0);
    const dk_index sharing[6] = {0, 1, 2, 0, 4, 5}; /* the same pair sharing corner 0 */
    CHECK(crossings(x, 6, sharing, 2) == 0);
    dk_index bad[6] = {0, 1, 2, 3, 4, 6}, c = 0;
    dk_error err = {0};
    CHECK(dk_surface_crossings(x, 6, bad, 2, &c, &err) == DK_ERR_INVALID_ARGUMENT);
    CHECK(strstr(err.message, "out of [0, 6)") != NULL);

    /* rounding-only crossings (found by random search, checked with exact rationals): a pair
     * of nearly coplanar triangles 2e-9 apart, and two separate tetrahedra, one with a
     * sliver face; neither meets, and a tolerance-based test reported both */
    const double near_coplanar[18] = {
        -0.08433041013792048, -0.32599471057263346, 1.2798269522035677,
        0.5834255048546597, 1.1114120448058056, -0.4205955920176543,
        1.6655522090035815, 0.5669753706600789, -1.1214380807402653,
        1.8418360290402884, 0.5036919240532753, -1.2537754295102317,
        0.6539555241436579, 0.11042754964294144, 0.22405309367331472,
        1.7789488350944958, 0.11714992921066703, -0.914048441542058};
    CHECK(crossings(near_coplanar, 6, f, 2) == 0);
    const double two_tets[24] = {
        0x1.69fa30fd93f00p-1, 0x1.44c24e94077f4p+0, -0x1.f2d53b3b846ebp-1,
        -0x1.d42e8692d8820p-2, 0x1.17a37b61a0c44p-1, -0x1.f41034e59da70p-3,
        -0x1.a6f960cf47090p-5, 0x1.987ec0e8ae35ep-1, -0x1.fe7d01b0f99c6p-2,
        0x1.1dce2eb76c81fp-2, 0x1.1b9adc63b3e9cp+0, 0x1.4fbf6090a3564p-4,
        0x1.e8d1878a6d39ep+0, 0x1.4d8ae456f5203p-1, -0x1.10a56dabb2373p-1,
        -0x1.9fa6adf7387e0p-3, 0x1.0bfd3a942abcep+0, -0x1.68a7c32cd72a7p-1,
        0x1.30665984b2d5ap+1, 0x1.3ccee300e6f11p+0, -0x1.2174c82b8b8a8p+0,
        0x1.6743aa49a3eb1p+0, 0x1.acb6e33b4f3dfp-1, -0x1.f6d6e505cfa61p-1};
    const dk_index tet_faces[24] = {0, 1, 2, 0, 1, 3, 1, 2, 3, 2, 0, 3, 4, 5, 6, 4, 5, 7, 5, 6, 7, 6, 4, 7};
    CHECK(crossings(two_tets, 8, tet_faces, 8) == 0);
    dk_index *tets = NULL, nt = 0, np = 0;
    double *pts = NULL;
    dk_error terr = {0};
    CHECK_MSG(dk_tetrahedralize_surface(two_tets, 8, tet_faces, 8, 0.0, 0.0, &pts, &np, &tets,
                                        &nt, &terr) == DK_OK && nt >= 2, "%s", terr.message);
    free(pts);
    free(tets);

    dk_test_mesh sphere = {0};
    CHECK(dk_test_icosphere(3, 1.0, &sphere) == 0);
    const dk_index n = sphere.n_vertices, m = sphere.n_faces;
    CHECK(crossings(sphere.positions, n, sphere.faces, m) == 0);
    double *x2 = malloc(sizeof(double) * 6 * (size_t)n);
    dk_index *f2 = malloc(sizeof(dk_index) * 6 * (size_t)m);
    if (!x2 || !f2)
        abort();
    for (int overlap = 0; overlap < 2; overlap++) {
        for (dk_index v = 0; v < 2 * n; v++)
            for (int k = 0; k < 3; k++)
                x2[3 * v + k] = sphere.positions[3 * (v % n) + k] +
                                (v < n ? 0.0 : k == 0 ? (overlap ? 0.7 : 2.5) : 0.013 * k);
        for (dk_index i = 0; i < 6 * m; i++)
            f2[i] = sphere.faces[i % (3 * m)] + (i >= 3 * m ? n : 0);
        const dk_index got = crossings(x2, 2 * n, f2, 2 * m);
        CHECK_MSG(overlap ? got > 0 : got == 0, "overlap %d: %ld triangles", overlap, (long)got);
    }
    free(x2);
    free(f2);
    dk_test_mesh_free(&sphere);
}

DK_TEST_MAIN(test_closed_surfaces, test_refusals, test_surface_crossings)
