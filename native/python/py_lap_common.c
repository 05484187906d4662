/* DeformKit CPython module: constraint and solve-input readers of the generic method type.
 * See dk_py_lap.h. */
#include "dk_py_lap.h"

#include <stdio.h>
#include <string.h>

void dk_py_lap_constraints_release(dk_py_lap_constraints *c)
{
    if (!c)
        return;
    PyMem_Free(c->sizes);
    PyMem_Free(c->vertices);
    PyMem_Free(c->fixed);
    PyMem_Free(c->roi);
    PyMem_Free(c->weights);
    memset(c, 0, sizeof *c);
}

/* Reads an optional 1-D index array into a PyMem copy; None gives n = 0, data = NULL. */
static int read_optional_indices(PyObject *obj, const char *name, dk_index **data, dk_index *n)
{
    dk_py_indices a = {0};
    *data = NULL;
    *n = 0;
    if (!obj || obj == Py_None)
        return 0;
    if (dk_py_read_indices(obj, -1, 0, name, &a) < 0)
        return -1;
    *data = PyMem_Malloc(sizeof(dk_index) * (size_t)(a.rows + 1));
    if (!*data) {
        dk_py_indices_release(&a);
        PyErr_NoMemory();
        return -1;
    }
    if (a.rows > 0)
        memcpy(*data, a.data, sizeof(dk_index) * (size_t)a.rows);
    *n = (dk_index)a.rows;
    dk_py_indices_release(&a);
    return 0;
}

int dk_py_lap_read_constraints(PyObject *handles, PyObject *fixed, PyObject *roi,
                               PyObject *handle_weights, const char *context,
                               dk_py_lap_constraints *out)
{
    PyObject *groups = NULL;
    Py_ssize_t ng, total = 0;
    char name[64];

    memset(out, 0, sizeof *out);
    if (!handles || handles == Py_None) {
        PyErr_Format(PyExc_TypeError, "%s: handles are required (a list of index arrays)",
                     context);
        return -1;
    }
    if (PyList_Check(handles) || PyTuple_Check(handles)) {
        Py_ssize_t len = PySequence_Size(handles);
        PyObject *first = len > 0 ? PySequence_GetItem(handles, 0) : NULL;
        int flat = first && PyLong_Check(first);
        Py_XDECREF(first);
        if (len > 0 && !first)
            return -1;
        groups = flat ? PyTuple_Pack(1, handles) : PySequence_Tuple(handles);
    } else {
        groups = PyTuple_Pack(1, handles); /* a single array: one group */
    }
    if (!groups)
        return -1;
    ng = PyTuple_Size(groups);
    if (ng == 0) {
        PyErr_Format(PyExc_ValueError, "%s: handles is empty: give at least one handle group",
                     context);
        goto fail;
    }
    if (ng > INT32_MAX) {
        PyErr_Format(PyExc_ValueError, "%s: too many handle groups", context);
        goto fail;
    }
    out->sizes = PyMem_Malloc(sizeof(dk_index) * (size_t)ng);
    if (!out->sizes) {
        PyErr_NoMemory();
        goto fail;
    }
    /* first pass: sizes; second: copy */
    for (int pass = 0; pass < 2; pass++) {
        Py_ssize_t at = 0;
        for (Py_ssize_t g = 0; g < ng; g++) {
            dk_py_indices a = {0};
            snprintf(name, sizeof name, "handle %zd", g);
            if (dk_py_read_indices(PyTuple_GetItem(groups, g), -1, 0, name, &a) < 0)
                goto fail;
            if (pass == 0) {
                out->sizes[g] = (dk_index)a.rows;
                total += a.rows;
            } else if (a.rows > 0) {
                memcpy(out->vertices + at, a.data, sizeof(dk_index) * (size_t)a.rows);
            }
            at += a.rows;
            dk_py_indices_release(&a);
        }
        if (pass == 0) {
            if (total > INT32_MAX) {
                PyErr_Format(PyExc_ValueError, "%s: too many handle vertices", context);
                goto fail;
            }
            out->vertices = PyMem_Malloc(sizeof(dk_index) * (size_t)(total + 1));
            if (!out->vertices) {
                PyErr_NoMemory();
                goto fail;
            }
        }
    }
    if (handle_weights && handle_weights != Py_None) {
        PyObject *wl = NULL;
        if (ng == 1) {
            /* one group: a flat per-vertex array is accepted as well as [array] */
            PyObject *first = PySequence_Check(handle_weights) && PySequence_Size(handle_weights) > 0
                                  ? PySequence_GetItem(handle_weights, 0)
                                  : NULL;
            PyErr_Clear();
            if (first && (PyFloat_Check(first) || PyLong_Check(first)) &&
                PySequence_Size(handle_weights) == total && total > 1)
                wl = PyTuple_Pack(1, handle_weights);
            else if (!first && PyObject_HasAttrString(handle_weights, "ndim"))
                wl = PyTuple_Pack(1, handle_weights);
            Py_XDECREF(first);
            if (!wl && PyErr_Occurred())
                goto fail;
        }
        if (!wl)
            wl = PySequence_Tuple(handle_weights);
        Py_ssize_t at = 0;
        if (!wl)
            goto fail;
        if (PyTuple_Size(wl) != ng) {
            PyErr_Format(PyExc_ValueError,
                         "%s: handle_weights must have one entry per handle group (%zd), got %zd",
                         context, ng, PyTuple_Size(wl));
            Py_DECREF(wl);
            goto fail;
        }
        out->weights = PyMem_Malloc(sizeof(double) * (size_t)(total + 1));
        if (!out->weights) {
            Py_DECREF(wl);
            PyErr_NoMemory();
            goto fail;
        }
        for (Py_ssize_t g = 0; g < ng; g++) {
            PyObject *item = PyTuple_GetItem(wl, g);
            if (PyFloat_Check(item) || PyLong_Check(item)) {
                double w = PyFloat_AsDouble(item);
                if (w == -1.0 && PyErr_Occurred()) {
                    Py_DECREF(wl);
                    goto fail;
                }
                for (dk_index k = 0; k < out->sizes[g]; k++)
                    out->weights[at + k] = w;
            } else {
                dk_py_doubles a = {0};
                snprintf(name, sizeof name, "handle_weights[%zd]", g);
                if (dk_py_read_doubles(item, out->sizes[g], 0, name, &a) < 0) {
                    Py_DECREF(wl);
                    goto fail;
                }
                if (a.rows > 0)
                    memcpy(out->weights + at, a.data, sizeof(double) * (size_t)a.rows);
                dk_py_doubles_release(&a);
            }
            at += out->sizes[g];
        }
        Py_DECREF(wl);
    }
    if (read_optional_indices(fixed, "fixed", &out->fixed, &out->desc.n_fixed) < 0 ||
        read_optional_indices(roi, "roi", &out->roi, &out->desc.n_roi) < 0)
        goto fail;
    if (roi && roi != Py_None && out->desc.n_roi == 0) {
        PyErr_Format(PyExc_ValueError,
                     "%s: roi is empty (pass None for the whole mesh)", context);
        goto fail;
    }
    out->desc.n_handles = (dk_index)ng;
    out->desc.handle_sizes = out->sizes;
    out->desc.handle_vertices = out->vertices;
    out->desc.handle_weights = out->weights;
    out->desc.fixed_vertices = out->fixed;
    out->desc.roi_vertices = out->roi;
    out->desc.stiffness = NULL;
    Py_DECREF(groups);
    return 0;
fail:
    Py_XDECREF(groups);
    dk_py_lap_constraints_release(out);
    return -1;
}

/* Flattens a nested sequence of n x 4 x 4 numbers into a list of n lists of 16 numbers. */
static PyObject *flatten_transforms(PyObject *obj)
{
    PyObject *seq = PySequence_Tuple(obj), *result;
    if (!seq)
        return NULL;
    result = PyList_New(PyTuple_Size(seq));
    if (!result) {
        Py_DECREF(seq);
        return NULL;
    }
    for (Py_ssize_t i = 0; i < PyTuple_Size(seq); i++) {
        PyObject *m = PyTuple_GetItem(seq, i), *row = PyList_New(0);
        PyObject *rows = row ? PySequence_Tuple(m) : NULL;
        if (!rows) {
            Py_XDECREF(row);
            goto fail;
        }
        for (Py_ssize_t r = 0; r < PyTuple_Size(rows); r++) {
            PyObject *it = PyTuple_GetItem(rows, r);
            int ok;
            if (PyFloat_Check(it) || PyLong_Check(it))
                ok = PyList_Append(row, it);
            else {
                PyObject *ext = PySequence_Tuple(it);
                ok = ext ? 0 : -1;
                for (Py_ssize_t q = 0; ext && q < PyTuple_Size(ext) && ok == 0; q++)
                    ok = PyList_Append(row, PyTuple_GetItem(ext, q));
                Py_XDECREF(ext);
            }
            if (ok < 0) {
                Py_DECREF(rows);
                Py_DECREF(row);
                goto fail;
            }
        }
        Py_DECREF(rows);
        PyList_SetItem(result, i, row); /* steals */
    }
    Py_DECREF(seq);
    return result;
fail:
    Py_DECREF(seq);
    Py_DECREF(result);
    return NULL;
}

int dk_py_lap_read_solve_input(PyObject *targets, PyObject *transforms, dk_index n_handles,
                               dk_index n_handle_vertices, const char *context,
                               dk_py_doubles *out, int *mode)
{
    const int has_t = targets && targets != Py_None;
    const int has_x = transforms && transforms != Py_None;
    memset(out, 0, sizeof *out);
    if (has_t == has_x) {
        PyErr_Format(PyExc_TypeError, "%s: give exactly one of targets and transforms", context);
        return -1;
    }
    if (has_t) {
        *mode = 0;
        return dk_py_read_doubles(targets, n_handle_vertices, 3, "targets", out);
    }
    *mode = 1;
    {
        PyObject *flat = NULL;
        int r;
        if (PyObject_HasAttrString(transforms, "reshape")) {
            flat = PyObject_CallMethod(transforms, "reshape", "(ii)", -1, 16);
            if (!flat) {
                PyErr_Clear();
                flat = Py_NewRef(transforms);
            }
        } else if (PyList_Check(transforms) || PyTuple_Check(transforms)) {
            flat = flatten_transforms(transforms);
            if (!flat)
                return -1;
        } else {
            flat = Py_NewRef(transforms);
        }
        r = dk_py_read_doubles(flat, n_handles, 16, "transforms", out);
        Py_DECREF(flat);
        return r;
    }
}

int dk_py_lap_choice(PyObject *value, const char *keyword, const char *const *names,
                     const char *context)
{
    const char *s;
    if (!PyUnicode_Check(value)) {
        PyErr_Format(PyExc_TypeError, "%s: %s must be a str", context, keyword);
        return -1;
    }
    s = PyUnicode_AsUTF8AndSize(value, NULL);
    if (!s)
        return -1;
    for (int i = 0; names[i]; i++)
        if (strcmp(s, names[i]) == 0)
            return i;
    {
        char accepted[256] = "";
        for (int i = 0; names[i]; i++) {
            strncat(accepted, i ? ", " : "", sizeof accepted - strlen(accepted) - 1);
            strncat(accepted, names[i], sizeof accepted - strlen(accepted) - 1);
        }
        PyErr_Format(PyExc_ValueError, "%s: unknown %s '%s' (accepted: %s)", context, keyword, s,
                     accepted);
    }
    return -1;
}
