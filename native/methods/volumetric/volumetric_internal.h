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

#endif
