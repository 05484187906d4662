/* DeformKit: reading and writing polygon mesh files (OBJ, OFF, PLY).
 *
 * Readers return polygons exactly as stored (vertex order as in the file), ready for
 * dk_mesh_from_polygons. They check what a file can get wrong: malformed numbers, missing
 * data, face indices out of range, polygons with fewer than 3 corners; messages name the file
 * and the line ("mesh.obj line 12: face index 90 is out of range [1, 40] (the file has 40
 * vertices)"; OBJ face indices may refer to vertices listed later), or the element
 * number for binary PLY. Nothing is printed; the library never aborts.
 *
 * Supported:
 *   OBJ  `v x y z [w]` and `f a b c ...` with `a`, `a/t`, `a//n`, `a/t/n` corners and
 *        negative (relative) indices; every other statement is ignored.
 *   OFF  `OFF` header (also COFF/NOFF/CNOFF, counts on the header line or the next), vertex
 *        lines whose extra values (colours) are ignored, faces `k i1 .. ik [colour]`.
 *   PLY  `ascii 1.0` and `binary_little_endian 1.0`; element `vertex` with x, y, z of any
 *        numeric type, element `face` with a list property `vertex_indices` (or
 *        `vertex_index`) of any integer count/index type; other properties and elements are
 *        skipped correctly (lists included).
 */
#ifndef DK_IO_H
#define DK_IO_H

#include <stddef.h>
#include <stdint.h>

#include "dk_mesh.h"
#include "dk_status.h"

#ifdef __cplusplus
extern "C" {
#endif

/** The largest mesh file read, in bytes (2 GiB). A larger file is refused up front with
 *  DK_ERR_INVALID_ARGUMENT naming the limit, and so is one that grows past it while being
 *  read. Only regular files are read (symlinks are followed): a directory, a FIFO, a
 *  socket or a device (an .obj symlink to /dev/zero) is refused before anything is read,
 *  instead of growing memory until the process is killed. */
#define DK_MESH_FILE_MAX_BYTES (INT64_C(2) * 1024 * 1024 * 1024)

/** Polygons read from a file. All arrays are malloc'ed and owned by the struct: release them
 *  with dk_mesh_file_free(). Arrays are never NULL after a successful read (they have at
 *  least one allocated element even when a count is zero). */
typedef struct dk_mesh_file {
    double *positions;   /**< n_vertices x 3, row-major                         */
    dk_index n_vertices;
    dk_index *face_sizes; /**< n_polygons corner counts                          */
    dk_index n_polygons;
    dk_index *indices;    /**< n_indices 0-based vertex indices, polygon after polygon */
    int64_t n_indices;
} dk_mesh_file;

/** Reads an .obj, .off or .ply file (chosen by the extension, case-insensitive; unknown
 *  extensions are sniffed from the first bytes). On success `*out` owns the arrays; on
 *  failure `*out` is zeroed and nothing needs freeing. */
dk_status dk_read_mesh_file(const char *path, dk_mesh_file *out, dk_error *err);

/** Parses a mesh file already in memory: `size` bytes at `data` (NULL allowed when size is
 *  0; need not be NUL-terminated; copied), as dk_read_mesh_file would parse a file of that
 *  content called `name` (its extension picks the format, as there, and messages name it).
 *  For callers that hold the bytes (an archive member, a download) and for the fuzzers.
 *  Refuses more than DK_MESH_FILE_MAX_BYTES. On failure `*out` is zeroed. */
dk_status dk_read_mesh_memory(const char *data, size_t size, const char *name,
                              dk_mesh_file *out, dk_error *err);

/** Frees the arrays of `file` and zeroes it; NULL and a zeroed struct are allowed. */
void dk_mesh_file_free(dk_mesh_file *file);

/** Same as dk_read_mesh_file with separate outputs. On success the caller owns
 *  `*positions`, `*face_sizes` and `*indices` and releases them with dk_free_mesh_arrays()
 *  (or free()); on failure all three are set to NULL and the counts to 0. */
dk_status dk_read_mesh_arrays(const char *path, double **positions, dk_index *n_vertices,
                              dk_index **face_sizes, dk_index *n_polygons, dk_index **indices,
                              int64_t *n_indices, dk_error *err);

/** Frees the three arrays returned by dk_read_mesh_arrays (NULLs allowed). */
void dk_free_mesh_arrays(double *positions, dk_index *face_sizes, dk_index *indices);

/** Writes an OBJ file (`v` lines with 17 significant digits, then 1-based `f` lines).
 *  With `face_sizes` NULL the faces are triangles: `indices` holds 3 * n_polygons entries.
 *  Indices are checked against n_vertices. Used for debugging and demos. */
dk_status dk_write_obj(const char *path, const double *positions, dk_index n_vertices,
                       const dk_index *face_sizes, dk_index n_polygons,
                       const dk_index *indices, dk_error *err);

#ifdef __cplusplus
}
#endif
#endif
