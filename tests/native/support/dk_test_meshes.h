/* Small generated meshes for DeformKit's C tests, so that tests run without any mesh file.
 *
 * Every generator fills a dk_test_mesh whose `positions` (n_vertices x 3, row-major) and
 * `faces` (n_faces x 3, row-major, counter-clockwise seen from outside / from +z) are
 * malloc'ed and OWNED BY THE CALLER: release them with dk_test_mesh_free(). Generators return
 * 0 on success and -1 on a bad argument or failed allocation (then the struct is zeroed and
 * nothing needs freeing). All generators are deterministic (the jitter uses a fixed seed).
 */
#ifndef DK_TEST_MESHES_H
#define DK_TEST_MESHES_H

#include <stdint.h>

#include "dk_mesh.h"

/** A generated triangle mesh; arrays are malloc'ed and owned by whoever holds the struct. */
typedef struct dk_test_mesh {
    double *positions;   /**< n_vertices x 3 */
    dk_index *faces;     /**< n_faces x 3    */
    dk_index n_vertices;
    dk_index n_faces;
} dk_test_mesh;

/** Frees both arrays and zeroes the struct; NULL and a zeroed struct are allowed. */
void dk_test_mesh_free(dk_test_mesh *m);

/** A flat grid on [0, size] x [0, size] at z = 0 with (n + 1) x (n + 1) vertices (n >= 1),
 *  vertex (i, j) at index j * (n + 1) + i. Interior vertices are moved by up to
 *  `jitter` x cell size (use < 0.3 to keep every triangle positively oriented); boundary
 *  vertices stay exactly on the square. Cells are split along alternating diagonals. */
int dk_test_grid(int n, double size, double jitter, dk_test_mesh *out);

/** A height field over a regular n x n-cell grid on [-1, 1]^2: z = amplitude * sum of a few
 *  Gaussian bumps. Same vertex numbering as dk_test_grid. */
int dk_test_bumpy_plane(int n, double amplitude, dk_test_mesh *out);

/** An open square tube (bar) along +z from z = 0 to z = length with half-width `half_width`:
 *  `segments` >= 1 rings of 4 * `per_side` vertices (per_side >= 1) plus the first ring, no
 *  caps. Ring r has vertices r * 4 * per_side ... ; ring 0 is at z = 0. Good for twisting. */
int dk_test_bar(int segments, int per_side, double half_width, double length,
                dk_test_mesh *out);

/** A closed box tube: dk_test_bar plus a fan-triangulated cap at each end (one centre vertex
 *  per cap, appended after the rings: index n_rings * ring_size is the z = 0 cap centre,
 *  the next one the z = length cap centre). Closed and manifold: V - E + F = 2. */
int dk_test_closed_bar(int segments, int per_side, double half_width, double length,
                       dk_test_mesh *out);

/** An open cylinder ("arm") of radius `radius` along +z from 0 to `length`: `rings` + 1 rings
 *  of `around` >= 3 vertices, ring r at index r * around. With `capped` != 0 a centre vertex
 *  closes each end (z = 0 centre first, then z = length), making it a closed sphere-like
 *  surface. */
int dk_test_cylinder(int around, int rings, double radius, double length, int capped,
                     dk_test_mesh *out);

/** An icosphere: the icosahedron subdivided `level` >= 0 times (each triangle into four),
 *  every vertex projected exactly onto the sphere of `radius` centred at the origin.
 *  V = 10 * 4^level + 2, F = 20 * 4^level, closed, manifold, outward orientation. */
int dk_test_icosphere(int level, double radius, dk_test_mesh *out);

/** A UV sphere with `around` >= 3 meridian vertices and `bands` >= 2 latitude bands (poles
 *  are single vertices: index 0 south pole, last index north pole). Closed and manifold. */
int dk_test_uv_sphere(int around, int bands, double radius, dk_test_mesh *out);

/** Builds a dk_mesh from a generated mesh (dk_mesh_create); returns NULL on failure and
 *  then prints the error message to stderr (it is test code). */
dk_mesh *dk_test_mesh_build(const dk_test_mesh *m);

/** Reads a whole file into a malloc'ed NUL-terminated buffer (caller frees); NULL on failure.
 *  `*size` (may be NULL) receives the length without the NUL. */
char *dk_test_read_file(const char *path, size_t *size);

/** Writes `text` to a file; returns 0 on success. */
int dk_test_write_file(const char *path, const char *text);

/** Returns a path in DK_SHARED_DIR/meshes for `name` in `buf` or NULL if it does not fit. */
const char *dk_test_shared_mesh_path(const char *shared_dir, const char *name, char *buf,
                                     size_t buf_size);

#endif
