/* Fuzzes a mesh reader (dk_read_mesh_memory, the parser of dk_read_mesh_file) with the
 * format DK_FUZZ_FORMAT ("obj", "off" or "ply": one executable each, fuzz_mesh_<format>),
 * then builds a mesh from what was read (dk_mesh_from_polygons).
 *
 * Checked besides the sanitizers: on success every array is there, every face has at least
 * 3 corners, the corner counts add up to n_indices, every index is in range and every
 * coordinate is finite; on failure the output is zeroed and the message is not empty. */
#include <stddef.h>
#include <stdint.h>

#include "dk_io.h"
#include "dk_mesh.h"
#include "fuzz_input.h"

int LLVMFuzzerTestOneInput(const uint8_t *data, size_t size);

int LLVMFuzzerTestOneInput(const uint8_t *data, size_t size)
{
    dk_mesh_file f;
    dk_error err = {0};
    dk_status st = dk_read_mesh_memory((const char *)data, size, "fuzz." DK_FUZZ_FORMAT, &f,
                                       &err);
    if (st != DK_OK) {
        dk_fuzz_check(err.message[0] != '\0', "status %d without a message", (int)st);
        dk_fuzz_check(!f.positions && !f.face_sizes && !f.indices && !f.n_vertices &&
                          !f.n_polygons && !f.n_indices,
                      "a failed read left output behind");
        return 0;
    }
    dk_fuzz_check(f.positions && f.face_sizes && f.indices, "a successful read without arrays");
    dk_fuzz_check(f.n_vertices >= 0 && f.n_polygons >= 0 && f.n_indices >= 0, "negative counts");
    int64_t sum = 0;
    for (dk_index p = 0; p < f.n_polygons; p++) {
        dk_fuzz_check(f.face_sizes[p] >= 3, "polygon %d has %d corners", (int)p,
                      (int)f.face_sizes[p]);
        sum += f.face_sizes[p];
    }
    dk_fuzz_check(sum == f.n_indices, "corner counts add up to %lld, n_indices is %lld",
                  (long long)sum, (long long)f.n_indices);
    for (int64_t i = 0; i < f.n_indices; i++)
        dk_fuzz_check(f.indices[i] >= 0 && f.indices[i] < f.n_vertices,
                      "index %lld is %d, out of [0, %d)", (long long)i, (int)f.indices[i],
                      (int)f.n_vertices);
    for (int64_t i = 0; i < 3 * (int64_t)f.n_vertices; i++)
        dk_fuzz_check(isfinite(f.positions[i]), "coordinate %lld is not finite", (long long)i);

    dk_mesh *m = NULL;
    st = dk_mesh_from_polygons(f.positions, f.n_vertices, f.face_sizes, f.n_polygons, f.indices,
                               f.n_indices, &m, &err);
    dk_fuzz_check((st == DK_OK) == (m != NULL), "status %d with mesh %p", (int)st, (void *)m);
    if (m)
        dk_fuzz_check(m->n_vertices == f.n_vertices && m->n_polygons == f.n_polygons,
                      "the mesh has %d vertices and %d polygons, the file %d and %d",
                      (int)m->n_vertices, (int)m->n_polygons, (int)f.n_vertices,
                      (int)f.n_polygons);
    dk_mesh_free(m);
    dk_mesh_file_free(&f);
    return 0;
}
