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

/** response_basis() of a method whose solves run on an ARAP object (`solver` gives it from
 *  the native object): None without a basis, else n_vertices x columns from `fill`; `who`
 *  prefixes errors. */
PyObject *dk_py_arap_response_basis(dk_py_method *self, const char *who,
                                    dk_status (*fill)(void *native, double *out,
                                                      dk_error *err),
                                    dk_arap *(*solver)(void *native));

/** The matching apply_extra, on the ARAP object `ar`. */
void dk_py_arap_apply_extra_to(dk_arap *ar, const void *pending, void *saved);

#endif
