/* DeformKit CPython module: what ARAP's binding shares with the methods that solve with an
 * ARAP object inside (VolumetricARAP): the solve keywords tolerance= and cg_iterations=. */
#ifndef DK_PY_ARAP_H
#define DK_PY_ARAP_H

#include "dk_py_method.h"

#include "dk_arap.h"

/** A dk_py_method_spec.solve_extra: reads tolerance= (for this and later solves) and
 *  cg_iterations= (this call only; None: as bound) out of `kw`, checked, into `pending`. */
int dk_py_arap_solve_extra(dk_py_method *self, PyObject *kw, void *pending,
                           const char *context);

/** The matching apply_extra, on the ARAP object `ar`. */
void dk_py_arap_apply_extra_to(dk_arap *ar, const void *pending, void *saved);

#endif
