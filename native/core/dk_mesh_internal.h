/* DeformKit core internals shared by dk_mesh.c and dk_mesh_polygons.c; not a public API. */
#ifndef DK_MESH_INTERNAL_H
#define DK_MESH_INTERNAL_H

#include "dk_mesh.h"

/** Builds the topology of already validated triangles (indices in range, no repeats,
 *  finite positions). Takes ownership of the three malloc'ed arrays on every path. */
dk_status dk_mesh_build_owned(double *positions, dk_index n_vertices, dk_index *faces,
                              dk_index n_faces, dk_index *face_polygon, dk_index n_polygons,
                              dk_mesh **out, dk_error *err);

#endif
