/* DeformKit volumetric ARAP, internal: the object and the functions the files of
 * native/methods/volumetric/ share. Not part of the public API (dk_volumetric_arap.h is).
 *
 * Files, one idea each:
 *   domain.c           the tetrahedra (TetGen), oriented, the volume mesh of their faces
 *                      (ARAP's adjacency), and the surface's constraints carried into the
 *                      volume (region of interest, stiffness spread inwards)
 *   extension.c        the interior's harmonic extension: the linear elements' Laplacian on
 *                      the interior points, factored, moving the interior with the surface
 *   multiscale.c       the coarse level: the surface simplified, its own tetrahedra and
 *                      VolumetricARAP, the maps between the two volumes, attached to ARAP
 *   embedded.c         the embedded domain (option embed): a coarse volume that carries the
 *                      surface, for meshes whose own volume would not fit
 *   volumetric_arap.c  the public verbs (a driver naming its steps) and the method's table
 */
#ifndef DK_VOLUMETRIC_INTERNAL_H
#define DK_VOLUMETRIC_INTERNAL_H

#include "dk_volumetric_arap.h"

#include <stdint.h>
#include <stdlib.h>
#include <string.h>

#include "dk_cholesky.h"
#include "dk_operators.h"
#include "dk_sparse.h"

/* The multi-scale solve's coarse level (multiscale.c): the surface simplified (each vertex's
 * role kept), its mesh, and the VolumetricARAP bound on it whose ARAP object the fine one
 * borrows (dk_arap_attach_coarse_level). */
typedef struct volumetric_level {
    dk_decimation *dec;
    dk_mesh *mesh;
    dk_volumetric_arap *coarse;
} volumetric_level;

/* The embedded domain (embedded.c). */
typedef struct volumetric_embedding volumetric_embedding;

struct dk_volumetric_arap {
    const dk_mesh *mesh;       /* the caller's surface                                      */
    dk_volumetric_arap_options opt;
    dk_index n, np, nt;        /* surface vertices, all points (surface first), tetrahedra   */
    dk_mesh *volume;           /* the points at rest, the tetrahedra's faces and the parts'
                                  that bound no volume triangles; NULL without tetrahedra
                                  (ARAP on the mesh itself)                                */
    char note[DK_ERROR_MESSAGE_SIZE + 32]; /* why a part or the whole bounds no volume ("":
                                              every part does) */
    dk_index *tets;            /* nt x 4, positively oriented at rest                        */
    dk_arap *arap;             /* ARAP on the tetrahedra                                     */
    dk_constraints *con;       /* the surface's constraints (validated on the surface: held
                                  parts and messages in its terms)                          */
    /* the harmonic extension (extension.c): interior point i (point n + i) couples to the
     * surface vertices ib_col[ib_start[i] .. ib_start[i + 1] - 1] with weights ib_w; L_II is
     * factored in chol (NULL when there is no interior point) */
    dk_index *ib_start, *ib_col;
    double *ib_w;
    dk_sparse *lii;
    dk_cholesky *chol;
    double *rhs;               /* (np - n) x 3, column-major: the extension's scratch       */
    /* poses, np x 3 each */
    double *input_full;        /* the last input pose, extended (valid: have_input)          */
    double *input_key;         /* n x 3: the surface it was extended from                    */
    int have_input;
    double *start_full;        /* a given start, extended                                   */
    double *full;              /* the inner solve's result                                  */
    double *last;              /* the last solve's volume (energy's interior); the rest
                                  points before any solve                                   */
    double *scratch;           /* np x 3: energy's and the extension's scratch             */
    volumetric_level *level;   /* the coarse level for the current constraints, or NULL     */
    volumetric_embedding *emb; /* the embedded domain (embed 2): then the verbs are its, and
                                  volume, tets, arap, the extension, the poses, np and nt
                                  are unset; n and con are the surface's                   */
    dk_phase_progress_fn rebind_progress; /* dk_volumetric_arap_set_progress's             */
    void *rebind_user;
};

/* The points at rest: the volume's, or the mesh's without tetrahedra. */
static inline const double *volume_points(const dk_volumetric_arap *va)
{
    return va->volume ? va->volume->positions : va->mesh->positions;
}

/* domain.c: the tetrahedra and the volume mesh (va->mesh, va->opt set; fills n, np, nt,
 * volume, tets); refusals name the surface's problem. */
dk_status volumetric_domain(dk_volumetric_arap *va, dk_progress *prog, dk_error *err);

/* domain.c: the surface's constraints `in`, validated on the surface (into *con), carried
 * into the volume: *out is `in` with the interior points added to a non-empty region of
 * interest and the stiffness spread inwards (owned arrays in *roi, *stiffness: free both). */
dk_status volumetric_constraints(const dk_volumetric_arap *va, const dk_constraint_desc *in,
                                 dk_constraints **con, dk_constraint_desc *out, dk_index **roi,
                                 double **stiffness, dk_error *err);

/* extension.c: builds and factors the interior Laplacian; frees what it built. */
dk_status volumetric_extension_build(dk_volumetric_arap *va, dk_error *err);
void volumetric_extension_free(dk_volumetric_arap *va);

/* extension.c: out (np x 3) = the volume `from` (np x 3) with its surface moved to `surface`
 * (n x 3) and its interior by the harmonic extension of that move. rhs: (np - n) x 3
 * scratch. out may be `from`. */
dk_status volumetric_extend(const dk_volumetric_arap *va, const double *from,
                            const double *surface, double *out, double *rhs, dk_error *err);

/* multiscale.c: the coarse level for va's constraints (va->con) attached to va->arap (*out
 * NULL: none, by the levels option, the size, or a step that failed for the mesh's reasons:
 * it is an accelerator); frees one. */
dk_status volumetric_level_build(dk_volumetric_arap *va, volumetric_level **out, dk_error *err);
void volumetric_level_free(volumetric_level *level);

/* multiscale.c: the surface of va (mesh, con, n, opt) simplified to a sixteenth of its
 * vertices (at least 256, at most `most`; twice as many, up to `most`, where TetGen refuses
 * the simplified surface) and bound as a VolumetricARAP of its own (embed 1, `levels` its
 * levels, the bind's progress to `progress`), with per coarse handle vertex its mesh vertex
 * (*hv_fine, owned by the caller). *out NULL when no coarse volume could be made for the
 * mesh's reasons (a simplification blocked above `most`, TetGen refusing every simplified
 * surface, a part bounding no volume); errors: out of memory, cancelled. */
dk_status volumetric_coarse_build(const dk_volumetric_arap *va, dk_index most, int levels,
                                  dk_phase_progress_fn progress, void *user,
                                  volumetric_level **out, dk_index **hv_fine, dk_error *err);

/* multiscale.c: sparse rows of a linear map onto the points of a tetrahedral mesh (points p,
 * np of them; tets, nt): row i is point same[i] with weight 1 when same[i] >= 0, else the
 * query i (queries, rows x 3) located in the tetrahedra, its barycentric coordinates
 * extrapolated outside them. At most 4 entries a row: start (rows + 1), col, w (4 rows). */
dk_status volumetric_map_rows(const double *p, dk_index np, const dk_index *tets, dk_index nt,
                              const double *queries, const dk_index *same, dk_index rows,
                              dk_index *start, dk_index *col, double *w, dk_error *err);

/* embedded.c: the most vertices the coarse surface of a mesh of n vertices may keep (an
 * eighth, or up to 8,192). */
dk_index volumetric_embed_most(dk_index n);

/* embedded.c: whether options ask for the embedded domain on this mesh (embed 2, or 0 from
 * EMBED_AUTO_VERTICES on where every part is closed). */
int volumetric_embed_wanted(const dk_mesh *mesh, const dk_volumetric_arap_options *o);

/* embedded.c: the embedded domain for va's surface and constraints (va->mesh, va->con,
 * va->opt), into *out; the bind's progress to `progress` (may be NULL). Refuses, by name, a
 * surface that no coarse volume can carry. */
dk_status volumetric_embedding_build(const dk_volumetric_arap *va, dk_progress *progress,
                                     volumetric_embedding **out, dk_error *err);
void volumetric_embedding_free(volumetric_embedding *e);

/* embedded.c: the verbs on the embedded domain (dk_volumetric_arap.h's, va->emb set). */
dk_status volumetric_embedding_solve(dk_volumetric_arap *va, const dk_solve_request *rq,
                                     double *positions, dk_solve_info *info, dk_error *err);
dk_status volumetric_embedding_energy(const dk_volumetric_arap *va, const double *positions,
                                      double *energy, dk_error *err);
dk_status volumetric_embedding_response_basis(const dk_volumetric_arap *va, double *out,
                                              dk_error *err);
/* embedded.c: the VolumetricARAP on the coarse volume. */
dk_volumetric_arap *volumetric_embedding_inner(const volumetric_embedding *e);
/* embedded.c: the bytes of an embedded bind of a surface of n vertices (the coarse volume's
 * model `coarse_bytes` for n / 16 vertices given by the caller). */
uint64_t volumetric_embedding_bytes(double n, uint64_t coarse_bytes);

#endif
