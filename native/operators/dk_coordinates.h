/* DeformKit: generalized barycentric coordinates in the plane, the slides' building blocks
 * of free-form deformation with cells other than a lattice's: a point of a cell written as
 * a combination of the cell's vertices, kept while the vertices move.
 *
 *   barycentric   a triangle: lambda_i = the area of the triangle the point makes with the
 *                 opposite edge, over the triangle's.
 *   Wachspress    a convex polygon (Wachspress 1975, in Floater's form): with A_i the
 *                 signed area of (v_i-1, v_i, v_i+1) and B_i(p) that of (p, v_i, v_i+1),
 *                 w_i = A_i / (B_i-1(p) B_i(p)), lambda = w / sum w. Rational, positive
 *                 inside, smooth; the polygon must be strictly convex.
 *   mean value    any simple polygon (Floater 2003), the slides' formula:
 *                 w_i = (tan(alpha_i-1 / 2) + tan(alpha_i / 2)) / r_i, lambda = w / sum w,
 *                 r_i = |v_i - p|, alpha_i the signed angle at p from v_i to v_i+1;
 *                 evaluated with d_i = v_i - p as tan(alpha/2) = (d_i x d_i+1) /
 *                 (r_i r_i+1 + d_i . d_i+1) for acute angles and (r_i r_i+1 - d_i . d_i+1)
 *                 / (d_i x d_i+1) for obtuse ones (Hormann and Floater 2006 give the
 *                 latter): no trigonometry, and no cancellation near an edge nor near an
 *                 edge's line beyond its ends. Defined in the whole plane but on the
 *                 boundary; positive inside convex polygons (and the kernel of star-shaped
 *                 ones), possibly negative elsewhere.
 * Every one reproduces linear functions (sum lambda_i v_i = p, sum lambda_i = 1) and takes
 * each vertex to itself (lambda = the unit vector). A point on the boundary (within 1e-12
 * of the polygon's size from an edge) gets the edge's linear interpolation, which is each
 * kind's limit there; Wachspress refuses a point outside its polygon, where its weights
 * have poles.
 *
 * Polygons are n x 2 coordinates (row-major) in order around the boundary, either way
 * round, n >= 3, no two consecutive vertices equal; a point is 2 coordinates; the output is
 * n coordinates (3 for a triangle). Nothing is allocated.
 */
#ifndef DK_COORDINATES_H
#define DK_COORDINATES_H

#include "dk_status.h"

#ifdef __cplusplus
extern "C" {
#endif

/** Barycentric coordinates of `point` (2) in `triangle` (3 x 2): DK_ERR_INVALID_ARGUMENT for
 *  a degenerate triangle (its area not above 1e-14 of its longest edge squared). */
dk_status dk_barycentric_2d(const double *triangle, const double *point, double *lambda,
                            dk_error *err);

/** Wachspress coordinates of `point` (2) in the strictly convex `polygon` (n x 2), into
 *  `lambda` (n): DK_ERR_INVALID_ARGUMENT for a polygon that is not strictly convex (or
 *  degenerate) or a point outside it. */
dk_status dk_wachspress_2d(const double *polygon, int n, const double *point, double *lambda,
                           dk_error *err);

/** Mean value coordinates of `point` (2) for the simple `polygon` (n x 2), into `lambda`
 *  (n): DK_ERR_INVALID_ARGUMENT for a degenerate polygon (a repeated consecutive vertex, no
 *  area) or non-finite input. */
dk_status dk_mean_value_2d(const double *polygon, int n, const double *point, double *lambda,
                           dk_error *err);

#ifdef __cplusplus
}
#endif

#endif
