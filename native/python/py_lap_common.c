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

/* Whether `o` is a single number (a Python int or float, or a 0-d numeric buffer such as a
 * numpy scalar), as one weight for a whole handle group. */
static int is_number(PyObject *o)
{
    if (PyFloat_Check(o) || PyLong_Check(o))
        return 1;
    if (PyObject_CheckBuffer(o) && !PySequence_Check(o)) {
        Py_buffer view;
        if (PyObject_GetBuffer(o, &view, PyBUF_RECORDS_RO) < 0) {
            PyErr_Clear();
            return 0;
        }
        int scalar = view.ndim == 0;
        PyBuffer_Release(&view);
        return scalar;
    }
    return 0;
}

/* Reads `handle_weights` into out->weights (out->sizes and the total known). Each input is
 * read exactly once: a list or tuple is first copied into a tuple of our own, an array is
 * read in one go and then interpreted by its length. */
static int read_weights(PyObject *hw, Py_ssize_t ng, Py_ssize_t total, const char *context,
                        dk_py_lap_constraints *out)
{
    PyObject *wl = NULL;
    char name[64];
    int rc = -1;

    out->weights = PyMem_Malloc(sizeof(double) * (size_t)(total + 1));
    if (!out->weights) {
        PyErr_NoMemory();
        return -1;
    }
    if (!PyList_Check(hw) && !PyTuple_Check(hw) && ng == 1) {
        /* one group and an array: per-vertex weights, or one weight for the group */
        dk_py_doubles a = {0};
        if (dk_py_read_doubles(hw, -1, 0, "handle_weights", &a) < 0)
            return -1;
        if (a.rows == total) {
            memcpy(out->weights, a.data, sizeof(double) * (size_t)total);
            rc = 0;
        } else if (a.rows == 1) {
            for (Py_ssize_t k = 0; k < total; k++)
                out->weights[k] = a.data[0];
            rc = 0;
        } else {
            PyErr_Format(PyExc_ValueError,
                         "%s: handle_weights has %zd values; the handle has %zd vertices",
                         context, a.rows, total);
        }
        dk_py_doubles_release(&a);
        return rc;
    }
    wl = PySequence_Tuple(hw); /* our own copy: what is read below cannot change */
    if (!wl)
        return -1;
    if (ng == 1 && total > 1 && PyTuple_Size(wl) == total) {
        /* one group: a flat per-vertex list is accepted as well as [list] */
        int all_numbers = 1;
        for (Py_ssize_t k = 0; k < total && all_numbers; k++)
            all_numbers = is_number(PyTuple_GetItem(wl, k));
        if (all_numbers) {
            PyObject *one = PyTuple_Pack(1, wl);
            Py_DECREF(wl);
            wl = one;
            if (!wl)
                return -1;
        }
    }
    if (PyTuple_Size(wl) != ng) {
        PyErr_Format(PyExc_ValueError,
                     "%s: handle_weights must have one entry per handle group (%zd), got %zd",
                     context, ng, PyTuple_Size(wl));
        goto done;
    }
    for (Py_ssize_t g = 0, at = 0; g < ng; g++) {
        PyObject *item = PyTuple_GetItem(wl, g);
        dk_py_doubles a = {0};
        snprintf(name, sizeof name, "handle_weights[%zd]", g);
        if (is_number(item)) {
            /* one weight for the group, converted as a 1-element sequence would be */
            PyObject *one = PyTuple_Pack(1, item);
            int r = one ? dk_py_read_doubles(one, 1, 0, name, &a) : -1;
            Py_XDECREF(one);
            if (r < 0)
                goto done;
            for (dk_index k = 0; k < out->sizes[g]; k++)
                out->weights[at + k] = a.data[0];
        } else {
            if (dk_py_read_doubles(item, out->sizes[g], 0, name, &a) < 0)
                goto done;
            if (a.rows > 0)
                memcpy(out->weights + at, a.data, sizeof(double) * (size_t)a.rows);
        }
        dk_py_doubles_release(&a);
        at += out->sizes[g];
    }
    rc = 0;
done:
    Py_XDECREF(wl);
    return rc;
}

int dk_py_lap_read_constraints(PyObject *handles, PyObject *fixed, PyObject *roi,
                               PyObject *handle_weights, const char *context,
                               dk_py_lap_constraints *out)
{
    PyObject *groups = NULL;
    dk_py_indices *read = NULL;
    Py_ssize_t ng = 0, total = 0;
    char name[64];

    memset(out, 0, sizeof *out);
    if (handles == Py_None) {
        PyErr_Format(PyExc_TypeError, "%s: handles are required (a list of index arrays)",
                     context);
        return -1;
    }
    if (!handles) {
        groups = PyTuple_New(0); /* none, for a method that takes none */
    } else if (PyList_Check(handles) || PyTuple_Check(handles)) {
        /* our own copy of the outer list first: nothing below looks at the caller's again */
        PyObject *snap = PySequence_Tuple(handles);
        if (!snap)
            return -1;
        if (PyTuple_Size(snap) > 0 && PyLong_Check(PyTuple_GetItem(snap, 0))) {
            groups = PyTuple_Pack(1, snap); /* a flat list of ints: one group */
            Py_DECREF(snap);
        } else {
            groups = snap;
        }
    } else {
        groups = PyTuple_Pack(1, handles); /* a single array: one group */
    }
    if (!groups)
        return -1;
    ng = PyTuple_Size(groups);
    if (ng == 0 && handles) {
        PyErr_Format(PyExc_ValueError, "%s: handles is empty: give at least one handle group",
                     context);
        goto fail;
    }
    if (ng > INT32_MAX) {
        PyErr_Format(PyExc_ValueError, "%s: too many handle groups", context);
        goto fail;
    }
    out->sizes = PyMem_Malloc(sizeof(dk_index) * (size_t)(ng + 1));
    read = PyMem_Calloc((size_t)ng + 1, sizeof *read);
    if (!out->sizes || !read) {
        PyErr_NoMemory();
        goto fail;
    }
    /* One pass: each group read exactly once into memory of our own (its size is the size
     * of what was read), then concatenated. Reading a group can run Python code
     * (__index__, __len__) that changes the others; it changes nothing already read. */
    for (Py_ssize_t g = 0; g < ng; g++) {
        snprintf(name, sizeof name, "handle %zd", g);
        if (dk_py_read_indices(PyTuple_GetItem(groups, g), -1, 0, name, &read[g]) < 0)
            goto fail;
        out->sizes[g] = (dk_index)read[g].rows;
        total += read[g].rows;
        if (total > INT32_MAX) {
            PyErr_Format(PyExc_ValueError, "%s: too many handle vertices", context);
            goto fail;
        }
    }
    out->vertices = PyMem_Malloc(sizeof(dk_index) * (size_t)(total + 1));
    if (!out->vertices) {
        PyErr_NoMemory();
        goto fail;
    }
    for (Py_ssize_t g = 0, at = 0; g < ng; g++) {
        if (read[g].rows > 0)
            memcpy(out->vertices + at, read[g].data, sizeof(dk_index) * (size_t)read[g].rows);
        at += read[g].rows;
        dk_py_indices_release(&read[g]);
    }
    PyMem_Free(read);
    read = NULL;
    if (handle_weights && handle_weights != Py_None &&
        read_weights(handle_weights, ng, total, context, out) < 0)
        goto fail;
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
    if (read) {
        for (Py_ssize_t g = 0; g < ng; g++)
            dk_py_indices_release(&read[g]);
        PyMem_Free(read);
    }
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
            flat = dk_py_as_blocks(transforms, 4, 4, "transforms");
            if (!flat)
                return -1;
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
