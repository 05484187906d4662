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
#include <cstdlib>
#include <cstring>
#include <new>

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
        size_t nt = (size_t)(out.numberoftetrahedra > 0 ? out.numberoftetrahedra : 0);
        dk_index *t = static_cast<dk_index *>(std::malloc((4 * nt + 1) * sizeof(dk_index)));
        if (!t)
            return dk_error_set(err, DK_ERR_OUT_OF_MEMORY, "%s: out of memory", who);
        for (size_t i = 0; i < 4 * nt; i++) {
            int v = out.tetrahedronlist[i];
            if (v < 0 || v >= (int)n_points) {
                std::free(t);
                return dk_error_set(err, DK_ERR_NUMERIC, "%s: TetGen returned corner %d", who, v);
            }
            t[i] = (dk_index)v;
        }
        *tets = t;
        *n_tets = (dk_index)nt;
        return DK_OK;
    } catch (const std::bad_alloc &) {
        return dk_error_set(err, DK_ERR_OUT_OF_MEMORY, "%s: out of memory in TetGen", who);
    } catch (int code) {
        if (code == 1)
            return dk_error_set(err, DK_ERR_OUT_OF_MEMORY, "%s: out of memory in TetGen", who);
        return dk_error_set(err, DK_ERR_NUMERIC, "%s: TetGen failed (its code %d) on %ld points",
                            who, code, (long)n_points);
    } catch (...) {
        return dk_error_set(err, DK_ERR_NUMERIC, "%s: TetGen failed on %ld points", who,
                            (long)n_points);
    }
}
