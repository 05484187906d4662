/* DeformKit: the triangle mesh, its validation and its topology.
 *
 * A dk_mesh owns copies of its positions and triangles plus the topology derived from them.
 * It is immutable after creation, so it may be shared read-only by any number of bound
 * methods and threads. Polygons are triangulated on creation (dk_mesh_from_polygons) and
 * each triangle remembers the polygon it came from.
 *
 * Validation, done by both constructors:
 *   errors   (the mesh is refused): an index out of range (names the face and the corner),
 *            a non-finite coordinate (names the vertex), a face that repeats a vertex,
 *            a polygon with fewer than 3 corners.
 *   reported (the mesh is accepted and the counts are in dk_mesh_report): zero-area
 *            triangles, non-manifold edges (more than two incident faces), isolated vertices
 *            (in no face), several connected components, boundary edges.
 */
#ifndef DK_MESH_H
#define DK_MESH_H

#include <stdint.h>

#include "dk_status.h"

#ifdef __cplusplus
extern "C" {
#endif

/** Index type used for vertices, faces and edges everywhere in the library. */
typedef int32_t dk_index;

/** What validation found on an accepted mesh. */
typedef struct dk_mesh_report {
    dk_index n_degenerate_faces;    /**< triangles whose area is below 1e-14 * bbox_diag^2 */
    dk_index n_nonmanifold_edges;   /**< edges with more than two incident triangles       */
    dk_index n_isolated_vertices;   /**< vertices referenced by no triangle                 */
    dk_index n_boundary_edges;      /**< edges with exactly one incident triangle           */
    dk_index n_components;          /**< connected components (an isolated vertex is one)   */
    dk_index first_degenerate_face; /**< index of one zero-area triangle, or -1             */
    dk_index first_nonmanifold_edge;/**< index of one non-manifold edge, or -1              */
    dk_index first_isolated_vertex; /**< index of one isolated vertex, or -1                */
} dk_mesh_report;

/** A validated triangle mesh with topology. All arrays are owned; read them, never write. */
typedef struct dk_mesh {
    dk_index n_vertices;
    dk_index n_faces;          /**< triangles                                              */
    dk_index n_edges;          /**< unique undirected edges                               */
    dk_index n_polygons;       /**< input polygons (== n_faces for dk_mesh_create)         */

    double *positions;         /**< n_vertices x 3, row-major                               */
    dk_index *faces;           /**< n_faces x 3, row-major, counter-clockwise as given      */
    dk_index *face_polygon;    /**< n_faces: the input polygon each triangle came from       */

    /* Edges: edges[2e] < edges[2e+1]; sorted lexicographically.                              */
    dk_index *edges;           /**< n_edges x 2                                             */
    /* The first two triangles incident to each edge (-1 where absent); a non-manifold edge
     * has more, counted in the report.                                                      */
    dk_index *edge_faces;      /**< n_edges x 2                                             */
    dk_index *edge_face_count; /**< n_edges: number of incident triangles                  */
    /* face_edges[3f+k] is the edge opposite corner k, i.e. between corners k+1 and k+2.     */
    dk_index *face_edges;      /**< n_faces x 3                                             */

    /* One-rings in CSR form: the neighbours of v are ring_index[ring_start[v] ..
     * ring_start[v+1]-1] sorted ascending, and ring_edge[] holds the matching edge ids.      */
    dk_index *ring_start;      /**< n_vertices + 1                                          */
    dk_index *ring_index;      /**< 2 * n_edges                                             */
    dk_index *ring_edge;       /**< 2 * n_edges                                             */

    /* Vertex-to-face incidence in CSR form: faces of v are vf_index[vf_start[v]..].          */
    dk_index *vf_start;        /**< n_vertices + 1                                          */
    dk_index *vf_index;        /**< 3 * n_faces                                             */

    unsigned char *is_boundary_vertex; /**< n_vertices: 1 on a boundary edge                  */
    dk_index *component;       /**< n_vertices: connected component id, 0-based             */

    double bbox_min[3], bbox_max[3];
    double bbox_diagonal;      /**< length of the bounding box diagonal (0 for one point)   */
    double mean_edge_length;   /**< over unique edges (0 if there are none)                 */

    dk_mesh_report report;
} dk_mesh;

/** Builds and validates a mesh from `n_vertices` x 3 positions and `n_faces` x 3 triangle
 *  indices (both row-major; copied). `n_faces` may be 0 (a point cloud). On success `*out`
 *  owns a new mesh to free with dk_mesh_free(); on failure `*out` is NULL. */
dk_status dk_mesh_create(const double *positions, dk_index n_vertices,
                         const dk_index *faces, dk_index n_faces,
                         dk_mesh **out, dk_error *err);

/** Builds a mesh from polygons: `face_sizes[p]` corners for polygon p, whose vertex indices
 *  follow one another in `indices` (length = sum of face_sizes). Triangles are kept, quads
 *  are split along their shorter diagonal, larger polygons are ear-clipped in their
 *  Newell-normal plane (falling back to a fan when ear clipping finds no ear).
 *  `face_polygon` of the result maps each triangle back to its polygon. */
dk_status dk_mesh_from_polygons(const double *positions, dk_index n_vertices,
                                const dk_index *face_sizes, dk_index n_polygons,
                                const dk_index *indices, int64_t n_indices,
                                dk_mesh **out, dk_error *err);

/** Frees a mesh; NULL is allowed. */
void dk_mesh_free(dk_mesh *mesh);

/** Returns the index of the edge {a, b} or -1 if there is none. O(log degree). */
dk_index dk_mesh_find_edge(const dk_mesh *mesh, dk_index a, dk_index b);

/** Writes the area of every triangle into `areas` (n_faces). Zero for degenerate ones. */
void dk_mesh_face_areas(const dk_mesh *mesh, const double *positions, double *areas);

/** The largest coordinate magnitude DeformKit computes with: 1e75. Products of up to four
 *  coordinates (squared lengths, squared areas, the energies' squared residuals of them)
 *  then stay below the largest double (1.8e308), so the operators and factorizations do
 *  not overflow into a "not positive definite" matrix, a "vertex without area" or a NaN
 *  result (measured: every method binds and solves a mesh at 1e75; at 1e100 ARAP's
 *  matrix and EigenDeformation's areas overflowed). Positions and solve targets beyond
 *  it are refused with DK_ERR_NONFINITE naming the vertex. */
#define DK_COORD_MAX 1e75

/** Checks that `positions` (n x 3) are all finite and within +-DK_COORD_MAX; names the
 *  first bad vertex on failure (DK_ERR_NONFINITE). */
dk_status dk_check_positions(const double *positions, dk_index n, dk_error *err);

/** Checks `n` indices against [0, limit); `what` names the list in the message
 *  ("handle 2 vertex 17 is 90000, out of range [0, 43243)"). */
dk_status dk_check_indices(const dk_index *indices, int64_t n, dk_index limit,
                           const char *what, dk_error *err);

#ifdef __cplusplus
}
#endif
#endif
