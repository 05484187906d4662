/* DeformKit, internal to EigenDeformation: the part of the mesh each handle drags
 * (region = DK_EIGEN_REGION_PART, dk_eigen.h).
 *
 * The paper's edit is a region R the user selects -- a whole part, the arm, half the dragon --
 * moved by a translation, or turned about a pivot so that a dragged point reaches its target;
 * everything outside R keeps its place. Given handles (the grabbed vertices) and a fixed part
 * instead, as every other method is, R was the handle group alone: dragging a hand translated
 * the hand and nothing else, and the only smooth fit of that is a spike (the second hostile
 * review). So each handle group H gets the part it drags: the vertices nearer to it than to
 * the fixed part and the other handles, by a harmonic field (1 on H, 0 on the other handles
 * and the fixed vertices; a vertex joins the part of the handle whose field is largest, when
 * it is above one half). The part without H turns about its border (the centroid of its
 * vertices next to the rest of the mesh) so that H's centroid reaches where the handle's
 * transform takes it -- the smallest turn, then a shift along the new direction for the
 * change of distance -- and H follows the handle's transform. These are the groups the
 * eigen machinery moves: for each handle, the turning part (when not empty) and H.
 *
 * Our construction: the paper leaves the choice of R and of the pivot to its user. */
#ifndef DK_EIGEN_PART_H
#define DK_EIGEN_PART_H

#include "dk_constraints.h"
#include "dk_mesh.h"
#include "dk_status.h"

typedef struct eigen_parts {
    dk_index n_user;          /* the caller's handle groups                                   */
    dk_index n_groups;        /* the groups the eigen machinery moves                          */
    dk_index *sizes;          /* n_groups                                                      */
    dk_index *verts;          /* concatenated, sum(sizes)                                      */
    dk_index *turn;           /* n_user: the group that turns about the pivot, or -1          */
    dk_index *follow;         /* n_user: the group that follows the handle's transform         */
    double *pivot;            /* n_user x 3: the border's centroid (NaN: a part without one)   */
    double *centre;           /* n_user x 3: the handle group's rest centroid                  */
    dk_index n_part_vertices; /* vertices in the turning groups, over all handles             */
    dk_constraint_desc desc;  /* the groups and the caller's fixed vertices (borrowed views) */
} eigen_parts;

/** Builds the parts of the validated caller's constraints `user` (its handle groups and its
 *  fixed vertices, held components included) on `mesh`. `fixed` / `n_fixed`: the caller's
 *  fixed vertices, kept in the groups' description. On failure `out` is empty (freeable). */
dk_status eigen_parts_build(const dk_mesh *mesh, const dk_constraints *user,
                            const dk_index *fixed, dk_index n_fixed, eigen_parts *out,
                            dk_error *err);

/** Frees what eigen_parts_build allocated (zeroes `p`). */
void eigen_parts_free(eigen_parts *p);

/** The groups' transforms (n_groups x 16, row-major 4 x 4) from the caller's handle
 *  transforms `user_T` (n_user x 16): each handle group its own, each turning part the turn
 *  about its pivot that takes the handle's centroid where the handle's transform does. */
void eigen_parts_transforms(const eigen_parts *p, const double *user_T, double *group_T);

#endif
