/* DeformKit: discrete differential operators and geometric queries on a dk_mesh.
 *
 * Sign convention for every Laplacian here: L is symmetric POSITIVE SEMIDEFINITE,
 *     L_ij = -w_ij (i != j, i~j),   L_ii = sum_j w_ij,
 * so (L x)_i = sum_j w_ij (x_i - x_j) and x^T L x = sum_edges w_ij |x_i - x_j|^2 >= 0
 * (for non-negative weights). The "mean curvature normal" of the slides is -M^-1 L x.
 */
#ifndef DK_OPERATORS_H
#define DK_OPERATORS_H

#include "dk_mesh.h"
#include "dk_sparse.h"
#include "dk_status.h"

#ifdef __cplusplus
extern "C" {
#endif

/* ---------------------------------------------------------------- Laplacians ----------- */

/** Uniform (graph) Laplacian: w_ij = 1 for every edge. n x n, PSD as above. The normalised
 *  "umbrella" operator of the slides is D^-1 L with D = diag(L). */
dk_status dk_laplacian_uniform(const dk_mesh *mesh, dk_sparse **out, dk_error *err);

/** Whether a triangle is degenerate: too thin for its cotangents, normal or area to mean
 *  anything. Either its area is below 1e-14 * (its longest edge)^2, or its height over the
 *  longest edge is within the rounding of its coordinates: below 64 * DBL_EPSILON times its
 *  largest absolute coordinate. The second rule makes a triangle that is degenerate in
 *  exact arithmetic (three collinear corners) stay degenerate wherever the mesh sits: turned
 *  or moved, its stored corners are off the line by a few rounding units, which the first
 *  rule alone read as a real sliver with cotangents of 1e12 (the ogre of ../shared/meshes,
 *  turned: a Laplacian whose rows no longer summed to 0). Every operator and method that
 *  skips degenerate triangles asks this.
 *  p0, p1, p2: the corners (3 doubles each); twice_area: |(p1 - p0) x (p2 - p0)| as the
 *  caller computed it; longest2: the squared length of its longest edge. Non-finite
 *  input is degenerate. */
int dk_triangle_degenerate(const double *p0, const double *p1, const double *p2,
                           double twice_area, double longest2);

/** Cotangent weights of every edge at the given positions (n_vertices x 3; pass
 *  mesh->positions for the rest shape): w_e = (cot alpha + cot beta) / 2 over the (one or
 *  two, or more on non-manifold edges) opposite angles. A degenerate triangle
 *  (dk_triangle_degenerate) contributes 0 to its three edges instead of an infinite
 *  cotangent, so the result is always finite. Weights may be negative (obtuse angles);
 *  clamping is the caller's choice. `weights` has n_edges entries. */
void dk_cotangent_weights(const dk_mesh *mesh, const double *positions, double *weights);

/** Cotangent Laplacian from dk_cotangent_weights at the rest positions. Symmetric, rows sum
 *  to 0, PSD on Delaunay meshes; finite on degenerate triangles (see above). */
dk_status dk_laplacian_cotangent(const dk_mesh *mesh, dk_sparse **out, dk_error *err);

/** Laplacian from arbitrary per-edge weights (n_edges entries), same sign convention. */
dk_status dk_laplacian_from_edge_weights(const dk_mesh *mesh, const double *weights,
                                         dk_sparse **out, dk_error *err);

/* ---------------------------------------------------------------- harmonic maps -------- */

/** Harmonic interpolation of a few painted values (the material map of Li's future work):
 *  u = values at the `n_painted` vertices `painted`, and L u = 0 at every other vertex,
 *  with L the cotangent Laplacian whose weights are clamped to >= 1e-2 of the mean weight
 *  (non-negative weights give the maximum principle: u stays between the painted minimum
 *  and maximum, so a positive material stays positive). A component with no painted vertex
 *  gets `fallback`. Writes `u_vertex` (n_vertices) and, when not NULL, `u_edge` (n_edges:
 *  the mean of each edge's two ends). Duplicate painted vertices are refused. */
dk_status dk_harmonic_interpolation(const dk_mesh *mesh, const dk_index *painted,
                                    const double *values, dk_index n_painted, double fallback,
                                    double *u_vertex, double *u_edge, dk_error *err);

/** dk_harmonic_interpolation for `n_columns` (>= 1) sets of painted values at once, with one
 *  factorization: `values` is n_painted x n_columns and `u` n_vertices x n_columns, both
 *  column-major. */
dk_status dk_harmonic_interpolation_columns(const dk_mesh *mesh, const dk_index *painted,
                                            const double *values, dk_index n_painted,
                                            int n_columns, double fallback, double *u,
                                            dk_error *err);

/* ---------------------------------------------------------------- mass matrices -------- */

/** Lumped mass matrix kinds (diagonal, one entry per vertex). */
typedef enum dk_mass_kind {
    DK_MASS_BARYCENTRIC = 0, /**< a third of each incident triangle's area                  */
    DK_MASS_VORONOI = 1      /**< mixed Voronoi area (Meyer et al. 2003): Voronoi region for
                                  non-obtuse triangles, area/2 at the obtuse corner and area/4
                                  at the others                                              */
} dk_mass_kind;

/** Writes the lumped mass of every vertex (n_vertices) into `mass`. Isolated vertices and
 *  vertices only on degenerate triangles get 0. */
dk_status dk_mass_matrix(const dk_mesh *mesh, dk_mass_kind kind, double *mass, dk_error *err);

/* ---------------------------------------------------------------- geodesics ------------ */

/** Exact shortest paths along mesh edges (Dijkstra, binary heap) from the `n_sources`
 *  vertices `sources`; `distance` (n_vertices) gets INFINITY for unreachable vertices. */
dk_status dk_geodesic_dijkstra(const dk_mesh *mesh, const dk_index *sources, dk_index n_sources,
                               double *distance, dk_error *err);

/** Edge-hop (breadth-first) distance from the sources; -1 for unreachable vertices. */
dk_status dk_hop_distance(const dk_mesh *mesh, const dk_index *sources, dk_index n_sources,
                          dk_index *hops, dk_error *err);

/** The heat method (Crane, Weischedel, Wardetzky 2013) with its two factorizations kept, so
 *  that every call after dk_heat_create costs two back-substitutions. */
typedef struct dk_heat_geodesic dk_heat_geodesic;

/** Precomputes the heat method: t = time_factor * h^2 with h the mean edge length
 *  (time_factor <= 0 selects the paper's default, 1). Factors M + tL and L + eps M.
 *  Boundary condition: the average of Neumann and Dirichlet solutions on meshes with a
 *  boundary, as the paper recommends. The object keeps a pointer to `mesh`, which must
 *  outlive it; calls on one object must not run concurrently. Vertices without area
 *  (isolated or only on degenerate triangles) get their smallest neighbour distance plus the
 *  edge length (INFINITY when none is reached). */
dk_status dk_heat_create(const dk_mesh *mesh, double time_factor, dk_heat_geodesic **out,
                         dk_error *err);

/** Approximate geodesic distance from the source vertices; shifted so that the smallest
 *  value over the sources of each component is 0. Vertices in components without a source
 *  get INFINITY. */
dk_status dk_heat_distance(dk_heat_geodesic *heat, const dk_index *sources, dk_index n_sources,
                           double *distance, dk_error *err);

/** Frees; NULL allowed. */
void dk_heat_free(dk_heat_geodesic *heat);

/** Total number of numeric Cholesky factorizations the object has done (2 without a
 *  boundary, 3 with one, fewer on meshes without area); constant across dk_heat_distance
 *  calls, which only back-substitute. For tests and reports. */
int dk_heat_factorization_count(const dk_heat_geodesic *heat);

/* ---------------------------------------------------------------- nearest source -------- */

struct dk_progress;

/** For every vertex, the source (of `n_sources` vertex indices) nearest to it along the
 *  edges: `label` (n) gets first_label + the source's position in `sources` (-1 where none
 *  is reachable), `dist` (n) the distance along the edges (edge counts with `unit_weights`,
 *  else lengths; INFINITY unreachable) and `eu` (n) the straight-line distance to that source.
 *  Ties go to the straight-line nearer source, then to the lower position. Progress (may be
 *  NULL): the search is group g of n_groups, reported as the first half of the group's
 *  share of the current phase; DK_ERR_CANCELLED when asked to stop. */
dk_status dk_labelled_search(const dk_mesh *mesh, const dk_index *sources, dk_index n_sources,
                             dk_index first_label, int unit_weights, double *dist, double *eu,
                             dk_index *label, struct dk_progress *prog, dk_index g,
                             dk_index n_groups, dk_error *err);

/* ---------------------------------------------------------------- nearest neighbours --- */

/** A static k-d tree over a copy of n points in R^3. */
typedef struct dk_kdtree dk_kdtree;

/** Builds the tree (O(n log n)). */
dk_status dk_kdtree_create(const double *points, dk_index n, dk_kdtree **out, dk_error *err);

/** For each of `n_queries` points, the indices of its k nearest tree points sorted by
 *  increasing distance (ties by index), and their squared distances (either output may be
 *  NULL). k must be in [1, n]. Read-only on the tree: safe from several threads. */
dk_status dk_kdtree_knn(const dk_kdtree *tree, const double *queries, dk_index n_queries,
                        dk_index k, dk_index *indices, double *sq_distances, dk_error *err);

/** Frees; NULL allowed. */
void dk_kdtree_free(dk_kdtree *tree);

/* ---------------------------------------------------------------- inside and outside -- */

/** Fast generalized winding numbers of a triangle soup (winding_number.c): 1 inside a
 *  closed outward-facing mesh, 0 outside, in between near holes; robust to several parts,
 *  non-manifold edges and self-intersections, so ">= 1/2" is the inside of a broken scan. */
typedef struct dk_winding dk_winding;

/** Builds the hierarchy over the `n_triangles` triangles (n_triangles x 3 indices into
 *  `vertices`, n_vertices x 3); both copied. */
dk_status dk_winding_create(const double *vertices, dk_index n_vertices,
                            const dk_index *triangles, dk_index n_triangles, dk_winding **out,
                            dk_error *err);

/** The winding number about each of `n_queries` points (n_queries x 3) into `out`; two
 *  threads for many queries. Read-only on `w`. */
void dk_winding_number(const dk_winding *w, const double *queries, dk_index n_queries,
                       double *out);

/** Frees; NULL allowed. */
void dk_winding_free(dk_winding *w);

/* ---------------------------------------------------------------- tetrahedra ----------- */

/** The Delaunay tetrahedralization of `n_points` distinct points (n_points x 3), by TetGen
 *  (Si 2015; its library, quiet, in tetrahedralize.cpp): `*tets` (malloc'ed, the caller
 *  frees) gets `*n_tets` x 4 point indices, in either orientation. Points
 *  all on a plane give no tetrahedra (DK_OK, *n_tets 0). TetGen's failures come back as
 *  DK_ERR_NUMERIC or DK_ERR_OUT_OF_MEMORY. */
dk_status dk_delaunay_tetrahedra(const double *points, dk_index n_points, dk_index **tets,
                                 dk_index *n_tets, dk_error *err);

/** How many of a surface's triangles certainly cross another of its triangles: *n_crossing
 *  (0 when none is found). positions: n_vertices x 3, finite and within DK_COORD_MAX
 *  (DK_ERR_NONFINITE otherwise); triangles: n_triangles x 3 indices into them (refused when
 *  out of range). Conservative: a pair without a common corner counts only when an edge of
 *  one certainly passes through the other's interior, each orientation it rests on
 *  certified by floating-point error bounds (Shewchuk's static filter); touching, coplanar
 *  and undecidable pairs do not count. So a count above 0 means the surface certainly
 *  intersects itself; 0 does not prove that it does not (nor does a sweep that gives up:
 *  past about 1024 box tests per triangle, where long triangles make it quadratic, it
 *  reports 0). About 0.1-0.3 s on scans of 50k-60k vertices. */
dk_status dk_surface_crossings(const double *positions, dk_index n_vertices,
                               const dk_index *triangles, dk_index n_triangles,
                               dk_index *n_crossing, dk_error *err);

/** The interior of a closed surface tetrahedralized by TetGen (its -p with -Y: the surface is
 *  the boundary and gets no point of its own, so the first n_vertices points are the surface's
 *  vertices, bit for bit; -q and -a bound the interior tetrahedra's quality and size).
 *  positions: n_vertices x 3, finite; triangles: n_triangles x 3, a closed manifold surface
 *  (every edge in exactly two triangles, none degenerate, every vertex used; refused by name
 *  otherwise, before TetGen runs). quality: 0 (none: no interior point, slivers allowed) or
 *  the largest radius-edge ratio in [1.1, 10] (TetGen's q; 1.5 is usual); max_volume: 0
 *  (none) or the largest tetrahedron volume (TetGen's a). Out (malloc'ed, the caller frees):
 *  *points (*n_points x 3) and *tets (*n_tets x 4 point indices); the interior may get
 *  points of its own even without bounds (a region that cannot be split otherwise). A
 *  self-intersecting surface is DK_ERR_DEGENERATE: found at once when its triangles clearly
 *  cross (dk_surface_crossings), otherwise by TetGen's own check (-d) before meshing;
 *  TetGen's other failures DK_ERR_NUMERIC or DK_ERR_OUT_OF_MEMORY. Nothing is written on
 *  failure. */
dk_status dk_tetrahedralize_surface(const double *positions, dk_index n_vertices,
                                    const dk_index *triangles, dk_index n_triangles,
                                    double quality, double max_volume, double **points,
                                    dk_index *n_points, dk_index **tets, dk_index *n_tets,
                                    dk_error *err);

/** A tetrahedron's frame for barycentric coordinates: grad (12 doubles) = the gradients of
 *  the barycentric coordinates of corners 0..3 (3 each), so that the coordinate of corner
 *  k >= 1 at q is grad_k . (q - x0). Returns 6 times the signed volume; 0 for a degenerate
 *  one (grad then unspecified). Allocation-free. */
double dk_tetrahedron_frame(const double *x0, const double *x1, const double *x2,
                            const double *x3, double grad[12]);

/** What dk_locate_in_tetrahedra does with a point outside every tetrahedron. */
typedef enum dk_locate_mode {
    /** the best tetrahedron's coordinates clamped to >= 0 and renormalised (a point on the
     *  domain's hull: weights in [0, 1]); beyond -0.5 the nearest point */
    DK_LOCATE_CLAMP = 0,
    /** the best tetrahedron's coordinates as they are (some negative): an affine map of the
     *  points moves the located point by the same map exactly, wherever it is */
    DK_LOCATE_EXTRAPOLATE = 1
} dk_locate_mode;

/** Where each of `n_queries` points (queries, n_queries x 3) lies in a tetrahedral mesh:
 *  its tetrahedron's corners (corners, n_queries x 4) and barycentric coordinates there
 *  (weights, n_queries x 4, summing to 1). points: n_points x 3; tets: n_tets x 4 indices
 *  into points; frames: n_tets x 12, per tetrahedron its corner 0 (3 doubles) then the
 *  gradients of the coordinates of corners 1..3 (9: dk_tetrahedron_frame's grad + 3).
 *  cell: the search grid's cell size (0: the tetrahedra's mean size). A point
 *  inside some tetrahedron gets it (the one with the largest smallest coordinate among those
 *  registered in its cell); outside every one, the tetrahedron with the largest smallest
 *  coordinate in the neighbouring cells (one ring; when extrapolating, a second while that
 *  coordinate is below -0.5), by `mode`; with
 *  none there (clamped: none nearer than a coordinate of -0.5), the nearest point alone
 *  (corners 1..3 -1, weight 1 on corner 0). Refuses (DK_ERR_INVALID_ARGUMENT) no point or
 *  tetrahedron, NULL arrays, corners out of range, points not finite, and a `cell` so small
 *  that the grid would pass 2^28 cells. Not
 *  interruptible; O(n_tets + n_queries) for a mesh of even size. */
dk_status dk_locate_in_tetrahedra(const double *points, dk_index n_points,
                                  const dk_index *tets, const double *frames, dk_index n_tets,
                                  double cell, dk_locate_mode mode, const double *queries,
                                  dk_index n_queries, dk_index *corners, double *weights,
                                  dk_error *err);

/** A tetrahedron's linear finite-element stiffness per edge: w_ab = -vol grad(phi_a) .
 *  grad(phi_b) for its edges (0,1), (0,2), (0,3), (1,2), (1,3), (2,3) into w (in the cotangent
 *  form |e_cd| cot(the dihedral angle at the opposite edge cd) / 6; negative at an obtuse
 *  angle), so that vol |grad u|^2 = sum_edges w_ab (u_a - u_b)^2 for every linear u. Returns
 *  the signed volume (positive when p1 - p0, p2 - p0, p3 - p0 are right-handed); a
 *  degenerate tetrahedron (|6 vol| at most 1e-12 of its longest edge cubed) gets w = 0 and
 *  returns 0. */
double dk_tetrahedron_stiffness(const double *p0, const double *p1, const double *p2,
                                const double *p3, double w[6]);

/* ---------------------------------------------------------------- skinning weights ---- */

/** Skinning weights fitted from example poses (fit_weights.c): for each vertex the weights
 *  (>= 0, summing to 1) with which linear blend skinning, p' = sum_j w_j T_pj B_j^-1 p,
 *  reproduces the example positions of every pose best in least squares; exact (a primal
 *  active-set method per vertex), two threads.
 *  rest: n x 3 rest positions; rest_frames: n_bones 4x4 row-major (affine, invertible);
 *  pose_frames: n_poses x n_bones 4x4, each bone's frame in each pose; pose_positions:
 *  n_poses x n x 3, the mesh in each pose; weights: n x n_bones out. n_bones <= 1024. */
dk_status dk_fit_skinning_weights(const double *rest, dk_index n, const double *rest_frames,
                                  dk_index n_bones, const double *pose_frames,
                                  const double *pose_positions, dk_index n_poses,
                                  double *weights, dk_error *err);

/* ---------------------------------------------------------------- rotations ------------ */

/** The rotation R (det R = +1) closest to the 3x3 matrix A in the Frobenius norm, i.e. the
 *  maximiser of trace(R^T A); both row-major. Robust for rank-deficient and reflected A
 *  (always returns a proper rotation; for A = 0 returns the identity). Allocation-free and
 *  fast enough to call per vertex per ARAP iteration. Returns trace(R^T A). */
double dk_closest_rotation(const double a[9], double r[9]);

/** The rotation R (det +1, row-major 3x3) as the unit quaternion q = (w, x, y, z) with
 *  w >= 0 (Shepperd's choice of the largest pivot: no cancellation near a half turn). For
 *  dual quaternion skinning and the logarithm of shape interpolation's rotations. */
void dk_rotation_quaternion(const double R[9], double q[4]);

/** The inverse: the rotation R (row-major 3x3) of the unit quaternion q = (w, x, y, z) (q and
 *  -q give the same R). For blends of rotations taken as normalised sums of quaternions (the
 *  multi-scale prolongation, dk_decimation_prolong). */
void dk_quaternion_rotation(const double q[4], double R[9]);

/** The inverse of the affine 4x4 `m` (row-major; its bottom row is taken as 0 0 0 1) into
 *  `inv` (16 doubles, bottom row 0 0 0 1). Returns 0, or -1 when the linear part is
 *  singular or not finite (inv then unspecified). Skinning's bones and the fit of their
 *  weights invert rest frames with it. */
int dk_affine_inverse(const double *m, double *inv);

/** The cofactor matrix c of the 3x3 matrix x (both row-major, 9 doubles; c = det(x) x^-T,
 *  so x^-1 = c^T / det(x)). Returns det(x). Allocation-free; x and c must not overlap. */
double dk_mat3_cofactor(const double x[9], double c[9]);

/* ---------------------------------------------------------------- affine fits ---------- */

/** An affine map T (4x4 row-major, bottom row 0 0 0 1) with q_k = T [p_k; 1] for the
 *  `count` points p_k = rest[3 verts[k] .. 3 verts[k] + 2] (rest: n x 3 row-major, verts:
 *  count indices into it) and their images q (count x 3 row-major). Tries the translation of
 *  the first point, then the least-squares map (centred normal equations, 3 x 3, solved with
 *  their pseudo-inverse, so that a planar or collinear set gets a map on its own span).
 *  Returns 1 when T reproduces every q_k to rel_tol times the largest
 *  coordinate magnitude (rest or image) of the points, 0 otherwise (T is then not to be
 *  used). count 0: the zero map, 1. O(count), allocation-free. */
int dk_affine_fit(const double *rest, const dk_index *verts, dk_index count, const double *q,
                  double rel_tol, double T[16]);

/* ---------------------------------------------------------------- simplification ------ */

/** A simplified copy of a mesh by half-edge collapses (see dk_decimate): the coarse
 *  vertices are a subset of the mesh's, where they were, and every removed vertex is
 *  recorded with the three vertices it is carried by (the corners of the coarse triangle
 *  nearest to it when it was removed) for the prolongation back to the mesh. */
typedef struct dk_decimation {
    dk_index n_vertices;   /**< the mesh's                                               */
    dk_index n_kept;       /**< coarse vertices                                          */
    dk_index *kept;        /**< n_kept: the mesh vertex of each coarse vertex, ascending  */
    dk_index *coarse_of;   /**< n_vertices: the coarse index of a kept vertex, else -1    */
    dk_index n_faces;      /**< coarse triangles                                         */
    dk_index *faces;       /**< n_faces x 3, coarse indices, orientation kept            */
    dk_index n_removed;    /**< n_vertices - n_kept                                      */
    dk_index *removed;     /**< n_removed: mesh vertices in the order they were removed   */
    dk_index *carrier;     /**< n_removed x 3: mesh vertices present when removed[k] was
                                (so kept, or removed later), corners of its nearest
                                remaining triangle; a corner repeats when fewer carry it */
    double *weight;        /**< n_removed x 3: barycentric weights of the nearest point of
                                that triangle, >= 0, summing to 1                         */
} dk_decimation;

/** Simplifies `mesh` to at most `target_vertices` vertices where it can, by half-edge
 *  collapses u -> v (u removed, v stays where it is) in the order of Garland & Heckbert's
 *  quadric error (face planes weighted by area; a boundary edge adds a plane through it
 *  perpendicular to its face, so boundaries keep their shape), each collapse checked to keep
 *  the mesh what it was: the link condition (no pinched edge or vertex), no triangle turned
 *  over or made degenerate, no duplicated triangle, a boundary vertex moved only along its
 *  boundary, valences at most 16, and no vertex removed that sits on a non-manifold edge or
 *  non-manifold boundary. vertex_class (n_vertices, may be NULL: all 0): u collapses only
 *  into a v of the same class, and a negative class is never removed: so every connected
 *  region of one class keeps a vertex (ARAP's coarse level passes each vertex's handle,
 *  fixed or free role). Stops at target_vertices or when no valid collapse is left. The
 *  order depends on the shape only up to rounding: uniform scale by a power of two gives the
 *  same result bit for bit. target_vertices >= 1. */
dk_status dk_decimate(const dk_mesh *mesh, const int *vertex_class, dk_index target_vertices,
                      dk_decimation **out, dk_error *err);

/** dk_decimate with a progress callback (NULL: none): called before every collapse (keep it
 *  cheap: dk_progress_tick asks its own callback every few thousand calls) with the
 *  collapses done and the most there can be (n_vertices - target_vertices); a non-zero
 *  return stops it (DK_ERR_CANCELLED, nothing written, nothing leaked). */
dk_status dk_decimate_progress(const dk_mesh *mesh, const int *vertex_class,
                               dk_index target_vertices,
                               int (*progress)(void *user, double done, double total),
                               void *user, dk_decimation **out, dk_error *err);

/** Frees; NULL allowed. */
void dk_decimation_free(dk_decimation *decimation);

/** The prolongation: mesh positions `fine` (n_vertices x 3) from coarse positions `coarse`
 *  (n_kept x 3): a kept vertex takes its coarse position; a removed vertex u, in reverse
 *  removal order, x_u = sum_k w_k (x_k + R_k (p_u - p_k)) over its carriers k, p = `pose`
 *  (n_vertices x 3: the positions the coarse level was made from, or a pose of them), R_k
 *  the carrier's rotation: `coarse_rotations` (n_kept x 9, row-major; NULL: identities)
 *  for kept vertices, for removed ones the normalised blend of their carriers' (as unit
 *  quaternions, `scratch`: n_vertices x 4, unused when coarse_rotations is NULL). So the
 *  pose prolongs to itself exactly, and a rigid motion of it to that motion. O(n),
 *  allocation-free. */
void dk_decimation_prolong(const dk_decimation *decimation, const double *pose,
                           const double *coarse, const double *coarse_rotations,
                           double *fine, double *scratch);

#ifdef __cplusplus
}
#endif
#endif
