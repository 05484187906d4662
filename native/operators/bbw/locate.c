/* DeformKit: where points lie in a tetrahedral domain of bounded biharmonic weights
 * (bbw_locate in bbw_internal.h): dk_locate_in_tetrahedra on the domain's tetrahedra and
 * frames, clamped, with the domain's grid size. */
#include "bbw_internal.h"
#include "dk_operators.h"

dk_status bbw_locate(const bbw_domain *d, const double *points, dk_index n, dk_index *embed,
                     double *w, dk_error *err)
{
    const dk_status st = dk_locate_in_tetrahedra(d->positions, d->n, d->tets, d->frames,
                                                 d->n_elements, d->cell, DK_LOCATE_CLAMP,
                                                 points, n, embed, w, err);
    return st == DK_OK ? DK_OK : dk_error_prefix(err, "bounded biharmonic weights");
}
