// DeformKit: Delaunay tetrahedra by TetGen (dk_delaunay_tetrahedra in dk_operators.h).
//
// TetGen's API is C++ (tetgenio, tetrahedralize); this file is the one C++ translation unit
// of the library and exposes a C function. Built with TETLIBRARY, TetGen reports its
// failures by throwing an int (1 out of memory, 2 internal error, 3 self-intersection, 4 a
// feature too small, 10 bad input); every exception stops here. Switches: Q (quiet: TetGen
// prints nothing), z (indices from 0). Without p the input is a point set and TetGen makes
// its Delaunay tetrahedralization, adding no points.
#define TETLIBRARY
#include <tetgen.h>

#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <new>
#include <utility>

#include "dk_operators.h"

// Whether the points span space: not all on a plane (nor a line, nor one point), measured
// relative to their extent. TetGen's exact predicates assert (abort the process) when every
// point has one coordinate 0, and a flat set has no tetrahedra anyway.
static bool spans_space(const double *p, dk_index n)
{
    auto d2 = [](const double *a, const double *b) {
        return (a[0] - b[0]) * (a[0] - b[0]) + (a[1] - b[1]) * (a[1] - b[1]) +
               (a[2] - b[2]) * (a[2] - b[2]);
    };
    const double *a = p, *b = p;
    for (dk_index i = 1; i < n; i++)
        if (d2(p + 3 * (size_t)i, a) > d2(b, a)) b = p + 3 * (size_t)i;
    const double len2 = d2(a, b);
    if (!(len2 > 0.0)) return false;
    double u[3] = {b[0] - a[0], b[1] - a[1], b[2] - a[2]}, best = 0.0;
    const double *c = a;
    for (dk_index i = 0; i < n; i++) { // the point furthest from the line ab
        const double *q = p + 3 * (size_t)i;
        double v[3] = {q[0] - a[0], q[1] - a[1], q[2] - a[2]};
        double x[3] = {u[1] * v[2] - u[2] * v[1], u[2] * v[0] - u[0] * v[2],
                       u[0] * v[1] - u[1] * v[0]};
        double area2 = x[0] * x[0] + x[1] * x[1] + x[2] * x[2];
        if (area2 > best) best = area2, c = q;
    }
    if (!(best > 1e-20 * len2 * len2)) return false;
    double v[3] = {c[0] - a[0], c[1] - a[1], c[2] - a[2]};
    double nrm[3] = {u[1] * v[2] - u[2] * v[1], u[2] * v[0] - u[0] * v[2],
                     u[0] * v[1] - u[1] * v[0]};
    double nn = std::sqrt(nrm[0] * nrm[0] + nrm[1] * nrm[1] + nrm[2] * nrm[2]);
    for (dk_index i = 0; i < n; i++) { // some point off the plane abc
        const double *q = p + 3 * (size_t)i;
        double h = (nrm[0] * (q[0] - a[0]) + nrm[1] * (q[1] - a[1]) + nrm[2] * (q[2] - a[2])) / nn;
        if (std::fabs(h) > 1e-10 * std::sqrt(len2)) return true;
    }
    return false;
}

// TetGen's tetrahedra copied out (malloc'ed, 4 corners each), every corner checked against
// the `n_points` points TetGen returned.
static dk_status copy_tets(const tetgenio &out, size_t n_points, dk_index **tets,
                           dk_index *n_tets, const char *who, dk_error *err)
{
    const size_t nt = (size_t)(out.numberoftetrahedra > 0 ? out.numberoftetrahedra : 0);
    dk_index *t = static_cast<dk_index *>(std::malloc((4 * nt + 1) * sizeof(dk_index)));
    if (!t)
        return dk_error_set(err, DK_ERR_OUT_OF_MEMORY, "%s: out of memory", who);
    for (size_t i = 0; i < 4 * nt; i++) {
        const int v = out.tetrahedronlist[i];
        if (v < 0 || (size_t)v >= n_points) {
            std::free(t);
            return dk_error_set(err, DK_ERR_NUMERIC, "%s: TetGen returned corner %d", who, v);
        }
        t[i] = (dk_index)v;
    }
    *tets = t;
    *n_tets = (dk_index)nt;
    return DK_OK;
}

// The error for TetGen's thrown code (1 out of memory, 3 self-intersection, 4 a feature too
// small, others internal or bad input), on `count` points or vertices.
static dk_status tetgen_failure(int code, const char *who, long count, dk_error *err)
{
    if (code == 1)
        return dk_error_set(err, DK_ERR_OUT_OF_MEMORY, "%s: out of memory in TetGen", who);
    if (code == 3)
        return dk_error_set(err, DK_ERR_DEGENERATE, "%s: the surface intersects itself "
                            "(TetGen's code 3): it does not bound one volume", who);
    if (code == 4)
        return dk_error_set(err, DK_ERR_DEGENERATE, "%s: a feature of the surface is too "
                            "small for TetGen (its code 4)", who);
    return dk_error_set(err, DK_ERR_NUMERIC, "%s: TetGen failed (its code %d) on %ld points",
                        who, code, count);
}

extern "C" dk_status dk_delaunay_tetrahedra(const double *points, dk_index n_points,
                                            dk_index **tets, dk_index *n_tets, dk_error *err)
{
    static const char who[] = "Delaunay tetrahedra";
    if (!tets || !n_tets)
        return dk_error_set(err, DK_ERR_INVALID_ARGUMENT, "%s: out is NULL", who);
    *tets = NULL;
    *n_tets = 0;
    if (n_points < 0 || (n_points > 0 && !points))
        return dk_error_set(err, DK_ERR_INVALID_ARGUMENT, "%s: needs points", who);
    if (n_points < 4 || !spans_space(points, n_points))
        return DK_OK; // TetGen asserts (aborts) on points that do not span space
    try {
        tetgenio in, out;
        in.numberofpoints = (int)n_points;
        in.pointlist = new REAL[3 * (size_t)n_points];
        std::memcpy(in.pointlist, points, 3 * (size_t)n_points * sizeof(REAL));
        char switches[] = "Qz";
        tetrahedralize(switches, &in, &out);
        if (out.numberofpoints != (int)n_points || out.numberofcorners != 4)
            return dk_error_set(err, DK_ERR_NUMERIC, "%s: TetGen returned %d points of %ld",
                                who, out.numberofpoints, (long)n_points);
        return copy_tets(out, (size_t)n_points, tets, n_tets, who, err);
    } catch (const std::bad_alloc &) {
        return dk_error_set(err, DK_ERR_OUT_OF_MEMORY, "%s: out of memory in TetGen", who);
    } catch (int code) {
        return tetgen_failure(code, who, (long)n_points, err);
    } catch (...) {
        return dk_error_set(err, DK_ERR_NUMERIC, "%s: TetGen failed on %ld points", who,
                            (long)n_points);
    }
}

// Refuses a surface TetGen cannot take as the boundary of a volume, naming what is wrong,
// before TetGen sees it: indices out of range, a triangle with a repeated corner or
// degenerate (dk_triangle_degenerate), an edge not shared by exactly two triangles (a hole
// or a non-manifold edge), a vertex no triangle uses.
static dk_status check_closed(const double *x, dk_index n, const dk_index *tri, dk_index m,
                              const char *who, dk_error *err)
{
    for (dk_index t = 0; t < m; t++) {
        const dk_index *f = tri + 3 * (size_t)t;
        for (int k = 0; k < 3; k++)
            if (f[k] < 0 || f[k] >= n)
                return dk_error_set(err, DK_ERR_INVALID_ARGUMENT,
                                    "%s: triangle %ld has corner %ld, out of [0, %ld)", who,
                                    (long)t, (long)f[k], (long)n);
        if (f[0] == f[1] || f[1] == f[2] || f[2] == f[0])
            return dk_error_set(err, DK_ERR_INVALID_ARGUMENT,
                                "%s: triangle %ld repeats a corner", who, (long)t);
        const double *a = x + 3 * (size_t)f[0], *b = x + 3 * (size_t)f[1], *c = x + 3 * (size_t)f[2];
        double u[3], v[3], w[3];
        for (int d = 0; d < 3; d++) u[d] = b[d] - a[d], v[d] = c[d] - a[d], w[d] = c[d] - b[d];
        const double cr[3] = {u[1] * v[2] - u[2] * v[1], u[2] * v[0] - u[0] * v[2],
                              u[0] * v[1] - u[1] * v[0]};
        const double l2 = std::fmax(u[0] * u[0] + u[1] * u[1] + u[2] * u[2],
                                    std::fmax(v[0] * v[0] + v[1] * v[1] + v[2] * v[2],
                                              w[0] * w[0] + w[1] * w[1] + w[2] * w[2]));
        if (dk_triangle_degenerate(a, b, c, std::sqrt(cr[0] * cr[0] + cr[1] * cr[1] + cr[2] * cr[2]),
                                   l2))
            return dk_error_set(err, DK_ERR_DEGENERATE,
                                "%s: triangle %ld is degenerate (no area): a volume's boundary "
                                "needs every triangle to have one", who, (long)t);
    }
    // every edge in exactly two triangles: sort the 3m directed edges as (min, max) pairs
    const size_t ne = 3 * (size_t)m;
    long long *keys = static_cast<long long *>(std::malloc((ne + 1) * sizeof(long long)));
    unsigned char *used = static_cast<unsigned char *>(std::calloc((size_t)n + 1, 1));
    if (!keys || !used) {
        std::free(keys);
        std::free(used);
        return dk_error_set(err, DK_ERR_OUT_OF_MEMORY, "%s: out of memory", who);
    }
    for (dk_index t = 0; t < m; t++)
        for (int k = 0; k < 3; k++) {
            dk_index a = tri[3 * (size_t)t + k], b = tri[3 * (size_t)t + (k + 1) % 3];
            used[a] = 1;
            if (a > b) std::swap(a, b);
            keys[3 * (size_t)t + k] = (long long)a * (long long)n + b;
        }
    std::qsort(keys, ne, sizeof *keys, [](const void *p, const void *q) {
        const long long a = *static_cast<const long long *>(p), b = *static_cast<const long long *>(q);
        return (a > b) - (a < b);
    });
    dk_status st = DK_OK;
    for (size_t i = 0; i < ne && st == DK_OK;) {
        size_t j = i;
        while (j < ne && keys[j] == keys[i]) j++;
        if (j - i != 2)
            st = dk_error_set(err, DK_ERR_INVALID_ARGUMENT,
                              "%s: edge (%lld, %lld) is in %zu triangles: the surface must be "
                              "closed and manifold (every edge in two) to bound a volume", who,
                              keys[i] / n, keys[i] % n, j - i);
        i = j;
    }
    for (dk_index v = 0; v < n && st == DK_OK; v++)
        if (!used[v])
            st = dk_error_set(err, DK_ERR_INVALID_ARGUMENT,
                              "%s: vertex %ld is in no triangle", who, (long)v);
    std::free(keys);
    std::free(used);
    return st;
}

extern "C" dk_status dk_tetrahedralize_surface(const double *positions, dk_index n_vertices,
                                               const dk_index *triangles, dk_index n_triangles,
                                               double quality, double max_volume,
                                               double **points, dk_index *n_points,
                                               dk_index **tets, dk_index *n_tets, dk_error *err)
{
    static const char who[] = "Tetrahedralize";
    if (!points || !n_points || !tets || !n_tets)
        return dk_error_set(err, DK_ERR_INVALID_ARGUMENT, "%s: out is NULL", who);
    *points = nullptr;
    *tets = nullptr;
    *n_points = *n_tets = 0;
    if (!positions || !triangles || n_vertices < 4 || n_triangles < 4)
        return dk_error_set(err, DK_ERR_INVALID_ARGUMENT,
                            "%s: needs a closed surface (at least 4 vertices and 4 triangles)", who);
    if (!(quality == 0.0 || (quality >= 1.1 && quality <= 10.0)))
        return dk_error_set(err, DK_ERR_INVALID_ARGUMENT,
                            "%s: quality = %g, must be 0 (none) or in [1.1, 10] (the largest "
                            "radius-edge ratio)", who, quality);
    if (!(max_volume >= 0.0 && max_volume <= 1e300))
        return dk_error_set(err, DK_ERR_INVALID_ARGUMENT,
                            "%s: max_volume = %g, must be 0 (none) or > 0", who, max_volume);
    dk_status st = dk_check_positions(positions, n_vertices, err);
    if (st == DK_OK)
        st = check_closed(positions, n_vertices, triangles, n_triangles, who, err);
    if (st != DK_OK)
        return st;
    if (!spans_space(positions, n_vertices))
        return dk_error_set(err, DK_ERR_DEGENERATE, "%s: the surface is flat: it bounds no "
                            "volume", who);
    // clear crossings found in a fraction of a second; the rest is TetGen's exact check
    dk_index crossing = 0;
    st = dk_surface_crossings(positions, n_vertices, triangles, n_triangles, &crossing, err);
    if (st != DK_OK)
        return st;
    if (crossing > 0)
        return dk_error_set(err, DK_ERR_DEGENERATE, "%s: the surface intersects itself (%ld "
                            "triangles cross others): it does not bound one volume", who,
                            (long)crossing);
    try {
        tetgenio in, out;
        in.numberofpoints = (int)n_vertices;
        in.pointlist = new REAL[3 * (size_t)n_vertices];
        std::memcpy(in.pointlist, positions, 3 * (size_t)n_vertices * sizeof(REAL));
        in.numberoffacets = (int)n_triangles;
        in.facetlist = new tetgenio::facet[(size_t)n_triangles];
        for (dk_index t = 0; t < n_triangles; t++) {
            tetgenio::facet &f = in.facetlist[t];
            tetgenio::init(&f);
            f.numberofpolygons = 1;
            f.polygonlist = new tetgenio::polygon[1];
            tetgenio::init(&f.polygonlist[0]);
            f.polygonlist[0].numberofvertices = 3;
            f.polygonlist[0].vertexlist = new int[3];
            for (int k = 0; k < 3; k++)
                f.polygonlist[0].vertexlist[k] = (int)triangles[3 * (size_t)t + k];
        }
        // First TetGen's own check (d): which facets intersect each other. It returns them;
        // a meshing run (p) on a self-intersecting surface throws instead, and Debian's
        // TetGen 1.5 then crashes freeing its memory (measured: two overlapping spheres)
        {
            tetgenio found;
            char check[] = "pdQz";
            tetrahedralize(check, &in, &found);
            if (found.numberoftrifaces > 0)
                return dk_error_set(err, DK_ERR_DEGENERATE,
                                    "%s: the surface intersects itself (%d triangles cross "
                                    "others): it does not bound one volume", who,
                                    found.numberoftrifaces);
        }
        // p: the surface is a boundary; Y: no point added on it (the first n points are the
        // surface's vertices); q, a: quality and size bounds inside; Q: quiet; z: from 0
        char switches[64];
        int len = std::snprintf(switches, sizeof switches, "pYQz");
        if (quality > 0.0)
            len += std::snprintf(switches + len, sizeof switches - (size_t)len, "q%.4g", quality);
        if (max_volume > 0.0)
            std::snprintf(switches + len, sizeof switches - (size_t)len, "a%.6g", max_volume);
        tetrahedralize(switches, &in, &out);
        if (out.numberofpoints < (int)n_vertices || out.numberofcorners != 4 ||
            out.numberoftetrahedra <= 0)
            return dk_error_set(err, DK_ERR_NUMERIC, "%s: TetGen returned %d points and %d "
                                "tetrahedra for %ld vertices", who, out.numberofpoints,
                                out.numberoftetrahedra, (long)n_vertices);
        if (std::memcmp(out.pointlist, positions, 3 * (size_t)n_vertices * sizeof(REAL)) != 0)
            return dk_error_set(err, DK_ERR_DEGENERATE, "%s: TetGen moved or merged surface "
                                "vertices (two at the same place?)", who);
        const size_t np = (size_t)out.numberofpoints;
        double *p = static_cast<double *>(std::malloc((3 * np + 1) * sizeof(double)));
        if (!p)
            return dk_error_set(err, DK_ERR_OUT_OF_MEMORY, "%s: out of memory", who);
        std::memcpy(p, out.pointlist, 3 * np * sizeof(double));
        const dk_status st2 = copy_tets(out, np, tets, n_tets, who, err);
        if (st2 != DK_OK) {
            std::free(p);
            return st2;
        }
        *points = p;
        *n_points = (dk_index)np;
        return DK_OK;
    } catch (const std::bad_alloc &) {
        return dk_error_set(err, DK_ERR_OUT_OF_MEMORY, "%s: out of memory in TetGen", who);
    } catch (int code) {
        return tetgen_failure(code, who, (long)n_vertices, err);
    } catch (...) {
        return dk_error_set(err, DK_ERR_NUMERIC, "%s: TetGen failed on %ld vertices", who,
                            (long)n_vertices);
    }
}
