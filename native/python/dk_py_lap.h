/* DeformKit CPython module: the readers of the method contract's inputs, used by the generic
 * method type (py_method.c; implemented in py_lap_common.c): the common constraint keywords
 * (handles, fixed, roi, handle_weights) into a dk_constraint_desc, the solve inputs (targets
 * or transforms), and a keyword's choice among names. */
#ifndef DK_PY_LAP_H
#define DK_PY_LAP_H

#include "dk_py.h"
#include "dk_constraints.h"

/** Owned arrays behind a dk_constraint_desc (PyMem). */
typedef struct dk_py_lap_constraints {
    dk_constraint_desc desc; /* points into the arrays below                               */
    dk_index *sizes, *vertices, *fixed, *roi;
    double *weights;         /* NULL when handle_weights was None                          */
} dk_py_lap_constraints;

/** Reads `handles` (a list/tuple of index arrays, one per group, or a single 1-D index
 *  array = one group; NULL: no handles, for a method that takes none), `fixed` and `roi` (index arrays or None) and `handle_weights` (None,
 *  or a list matching `handles` whose items are per-vertex arrays or one number per group).
 *  Index range and overlap checks are left to the library (which names the vertex). Returns
 *  0, or -1 with an exception set (messages prefixed by `context`). */
int dk_py_lap_read_constraints(PyObject *handles, PyObject *fixed, PyObject *roi,
                               PyObject *handle_weights, const char *context,
                               dk_py_lap_constraints *out);

/** Frees what dk_py_lap_read_constraints allocated; safe on a zeroed struct. */
void dk_py_lap_constraints_release(dk_py_lap_constraints *c);

/** Reads the solve input: exactly one of `targets` ((n_handle_vertices) x 3) and
 *  `transforms` (n_handles x 4 x 4, or n_handles x 16, or nested sequences) must be given
 *  (not None). `*mode` gets 0 for targets, 1 for transforms. Returns 0 or -1. */
int dk_py_lap_read_solve_input(PyObject *targets, PyObject *transforms, dk_index n_handles,
                               dk_index n_handle_vertices, const char *context,
                               dk_py_doubles *out, int *mode);

/** Matches `value` (a str) against `names` (NULL-terminated); returns the index or -1 with
 *  ValueError naming the keyword and the accepted values. */
int dk_py_lap_choice(PyObject *value, const char *keyword, const char *const *names,
                     const char *context);

#endif
