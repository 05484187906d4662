/* DeformKit CPython module: the shared helpers declared in dk_py.h (all but the Mesh type).
 *
 * Reading inputs: any object exporting the buffer protocol is read through a strided view
 * (PyBUF_RECORDS_RO, so non-contiguous numpy slices work without a copy on the Python side)
 * and converted element by element, honouring the byte order in the format string. Objects
 * without a usable buffer fall back to the (nested) sequence protocol.
 *
 * Writing outputs: a bytearray of the right size is filled by the caller through the pointer
 * returned here and wrapped by numpy.frombuffer (plain Python calls, no numpy C API), or cast
 * to a shaped memoryview when numpy cannot be imported.
 */
#include "dk_py.h"

#include <limits.h>
#include <stdio.h>
#include <string.h>

/* ================================================================== errors ============== */

/* Whether a native message already starts with the context's class name (the C library
 * names its method: "ARAP: ...", "LaplacianEdit rebind: ..."), so that prefixing the context
 * would say it twice ("ARAP: ARAP: ..."). */
static int names_itself(const char *message, const char *context)
{
    size_t k = strcspn(context, ".");
    return k > 0 && strncmp(message, context, k) == 0 &&
           (message[k] == ':' || message[k] == ' ');
}

int dk_py_strict_bool(PyObject *obj, const char *name, const char *context, int *value)
{
    if (PyBool_Check(obj)) {
        *value = obj == Py_True;
        return 0;
    }
    if (PyLong_Check(obj)) {
        const long v = PyLong_AsLong(obj);
        if (v == 0 || v == 1) {
            *value = (int)v;
            return 0;
        }
        PyErr_Clear();
    } else {
        /* numpy's bool scalar ("bool_" in numpy 1, "bool" in 2) is no Python bool */
        PyObject *mod = PyObject_GetAttrString((PyObject *)Py_TYPE(obj), "__module__");
        PyObject *qual = PyObject_GetAttrString((PyObject *)Py_TYPE(obj), "__name__");
        int numpy_bool = 0;
        if (mod && qual && PyUnicode_Check(mod) && PyUnicode_Check(qual))
            numpy_bool = PyUnicode_CompareWithASCIIString(mod, "numpy") == 0 &&
                         (PyUnicode_CompareWithASCIIString(qual, "bool_") == 0 ||
                          PyUnicode_CompareWithASCIIString(qual, "bool") == 0);
        Py_XDECREF(mod);
        Py_XDECREF(qual);
        PyErr_Clear();
        if (numpy_bool) {
            const int t = PyObject_IsTrue(obj);
            if (t < 0)
                return -1;
            *value = t;
            return 0;
        }
    }
    PyObject *r = PyObject_Repr(obj);
    PyErr_Format(PyExc_TypeError, "%s: %s must be True or False, got %s", context, name,
                 r && PyUnicode_Check(r) ? PyUnicode_AsUTF8AndSize(r, NULL) : "?");
    Py_XDECREF(r);
    return -1;
}

PyObject *dk_py_raise(const dk_error *err, const char *context)
{
    PyObject *type;
    dk_status status = err ? err->status : DK_ERR_INTERNAL;
    const char *message = (err && err->message[0]) ? err->message : dk_status_name(status);

    switch (status) {
    case DK_ERR_INDEX:
        type = PyExc_IndexError;
        break;
    case DK_ERR_INVALID_ARGUMENT:
    case DK_ERR_NONFINITE:
    case DK_ERR_DEGENERATE:
    case DK_ERR_TOPOLOGY:
        type = PyExc_ValueError;
        break;
    case DK_ERR_OUT_OF_MEMORY:
        type = PyExc_MemoryError;
        break;
    case DK_OK: /* a caller bug: raising "no error" would be confusing, say so */
        type = PyExc_SystemError;
        message = "dk_py_raise called without an error";
        break;
    case DK_ERR_CANCELLED:
    case DK_ERR_NOT_POSITIVE_DEFINITE:
    case DK_ERR_NO_CONVERGENCE:
    case DK_ERR_NUMERIC:
    case DK_ERR_INTERNAL:
    default:
        type = PyExc_RuntimeError;
        break;
    }
    if (context && context[0] && !names_itself(message, context))
        PyErr_Format(type, "%s: %s", context, message);
    else
        PyErr_SetString(type, message);
    return NULL;
}

/* ================================================================== inputs ============== */

/** What kind of scalar a buffer holds. */
typedef enum elem_kind { KIND_FLOAT, KIND_SIGNED, KIND_UNSIGNED } elem_kind;

/** Parses a struct-module format string of a single scalar ("d", "<f", "=l", "B", ...).
 *  Returns 0 and fills kind/swap, or -1 (no exception set) when the format is unsupported. */
static int parse_format(const char *fmt, Py_ssize_t itemsize, elem_kind *kind, int *swap)
{
    const unsigned one = 1;
    const int little = *(const unsigned char *)&one == 1;
    int want_little = little;

    if (fmt == NULL) /* NULL means unsigned bytes */
        fmt = "B";
    *swap = 0;
    switch (fmt[0]) {
    case '@':
    case '=':
        fmt++;
        break;
    case '<':
        want_little = 1;
        fmt++;
        break;
    case '>':
    case '!':
        want_little = 0;
        fmt++;
        break;
    default:
        break;
    }
    if (fmt[0] == '\0' || fmt[1] != '\0')
        return -1;
    switch (fmt[0]) {
    case 'f':
    case 'd':
        *kind = KIND_FLOAT;
        if (itemsize != 4 && itemsize != 8)
            return -1;
        break;
    case 'b':
    case 'h':
    case 'i':
    case 'l':
    case 'q':
    case 'n':
        *kind = KIND_SIGNED;
        break;
    case 'B':
    case 'H':
    case 'I':
    case 'L':
    case 'Q':
    case 'N':
        *kind = KIND_UNSIGNED;
        break;
    default:
        return -1;
    }
    if (*kind != KIND_FLOAT && itemsize != 1 && itemsize != 2 && itemsize != 4 && itemsize != 8)
        return -1;
    *swap = (itemsize > 1) && (want_little != little);
    return 0;
}

/** One scalar, loaded from memory: either a double or a 64-bit integer (with its sign). */
typedef struct scalar {
    int is_float;
    double d;
    long long i;          /* valid when !is_float and !too_big               */
    int too_big;          /* unsigned value above LLONG_MAX                   */
} scalar;

static scalar load_scalar(const char *p, Py_ssize_t itemsize, elem_kind kind, int swap)
{
    unsigned char b[8];
    scalar s = {0, 0.0, 0, 0};

    memcpy(b, p, (size_t)itemsize);
    if (swap) {
        for (Py_ssize_t k = 0; k < itemsize / 2; ++k) {
            unsigned char t = b[k];
            b[k] = b[itemsize - 1 - k];
            b[itemsize - 1 - k] = t;
        }
    }
    if (kind == KIND_FLOAT) {
        s.is_float = 1;
        if (itemsize == 4) {
            float f;
            memcpy(&f, b, 4);
            s.d = f;
        } else {
            memcpy(&s.d, b, 8);
        }
        return s;
    }
    if (kind == KIND_SIGNED) {
        switch (itemsize) {
        case 1: { int8_t v; memcpy(&v, b, 1); s.i = v; break; }
        case 2: { int16_t v; memcpy(&v, b, 2); s.i = v; break; }
        case 4: { int32_t v; memcpy(&v, b, 4); s.i = v; break; }
        default: { int64_t v; memcpy(&v, b, 8); s.i = v; break; }
        }
    } else {
        uint64_t u = 0;
        switch (itemsize) {
        case 1: { uint8_t v; memcpy(&v, b, 1); u = v; break; }
        case 2: { uint16_t v; memcpy(&v, b, 2); u = v; break; }
        case 4: { uint32_t v; memcpy(&v, b, 4); u = v; break; }
        default: { memcpy(&u, b, 8); break; }
        }
        if (u > (uint64_t)LLONG_MAX) {
            s.too_big = 1;
            s.d = (double)u;
        } else {
            s.i = (long long)u;
        }
    }
    if (!s.too_big)
        s.d = (double)s.i;
    return s;
}

/** Checks a source shape against the demanded (rows, cols) and works out the result shape.
 *  ndim is 1 or 2 (shape1 unused for 1). Returns 0 or -1 with ValueError set. */
static int resolve_shape(int ndim, Py_ssize_t shape0, Py_ssize_t shape1, Py_ssize_t rows,
                         Py_ssize_t cols, const char *name, Py_ssize_t *out_rows,
                         Py_ssize_t *out_cols)
{
    Py_ssize_t r, c;

    if (ndim != 1 && ndim != 2) {
        PyErr_Format(PyExc_ValueError, "%s must be a 1-D or 2-D array, got %d dimensions",
                     name, ndim);
        return -1;
    }
    if (cols > 0) {
        if (ndim == 2) {
            if (shape1 != cols) {
                PyErr_Format(PyExc_ValueError, "%s must have %zd columns, got %zd", name, cols,
                             shape1);
                return -1;
            }
            r = shape0;
        } else {
            if (shape0 % cols != 0) {
                PyErr_Format(PyExc_ValueError,
                             "%s: a flat array must hold a multiple of %zd values, got %zd",
                             name, cols, shape0);
                return -1;
            }
            r = shape0 / cols;
        }
        c = cols;
    } else if (cols == 0) {
        if (ndim == 2 && shape1 != 1) {
            PyErr_Format(PyExc_ValueError, "%s must be 1-D, got shape (%zd, %zd)", name, shape0,
                         shape1);
            return -1;
        }
        r = shape0;
        c = 1;
    } else if (cols == DK_PY_COLS_1D_OR_2D) {
        r = shape0;
        c = ndim == 2 ? shape1 : 1;
    } else {
        if (ndim != 2) {
            PyErr_Format(PyExc_ValueError, "%s must be 2-D, got a 1-D array of %zd values",
                         name, shape0);
            return -1;
        }
        r = shape0;
        c = shape1;
    }
    if (rows >= 0 && r != rows) {
        PyErr_Format(PyExc_ValueError, "%s must have %zd rows, got %zd", name, rows, r);
        return -1;
    }
    if (c > 0 && r > PY_SSIZE_T_MAX / c) {
        PyErr_Format(PyExc_ValueError, "%s is too large", name);
        return -1;
    }
    if (r > INT32_MAX || c > INT32_MAX) {
        PyErr_Format(PyExc_ValueError, "%s has more than 2^31-1 rows or columns", name);
        return -1;
    }
    *out_rows = r;
    *out_cols = c;
    return 0;
}

/** Stores scalar `s` at position k of the output; `(i, j)` names it in messages. */
static int store_scalar(scalar s, int want_int, void *out, Py_ssize_t k, Py_ssize_t i,
                        Py_ssize_t j, const char *name)
{
    if (!want_int) {
        ((double *)out)[k] = s.d;
        return 0;
    }
    if (s.is_float) {
        PyErr_Format(PyExc_TypeError, "%s must hold integers, got floating-point data", name);
        return -1;
    }
    if (s.too_big || s.i < INT32_MIN || s.i > INT32_MAX) {
        if (s.too_big)
            PyErr_Format(PyExc_OverflowError, "%s[%zd, %zd] is outside the int32 range", name,
                         i, j);
        else
            PyErr_Format(PyExc_OverflowError, "%s[%zd, %zd] = %lld is outside the int32 range",
                         name, i, j, s.i);
        return -1;
    }
    ((dk_index *)out)[k] = (dk_index)s.i;
    return 0;
}

/** Allocates rows*cols elements (at least one, so that NULL always means failure). */
static void *alloc_elems(Py_ssize_t rows, Py_ssize_t cols, size_t size)
{
    size_t n = (size_t)rows * (size_t)cols;
    void *p;
    if (n == 0)
        n = 1;
    if (n > (size_t)PY_SSIZE_T_MAX / size) {
        PyErr_NoMemory();
        return NULL;
    }
    p = PyMem_Malloc(n * size);
    if (!p)
        PyErr_NoMemory();
    return p;
}

/** Whether a buffer format (after any byte-order prefix) is a complex type ('Zd', 'Zf'). */
static int format_is_complex(const char *fmt)
{
    if (!fmt)
        return 0;
    if (fmt[0] == '@' || fmt[0] == '=' || fmt[0] == '<' || fmt[0] == '>' || fmt[0] == '!')
        fmt++;
    return fmt[0] == 'Z';
}

/** Whether a buffer format is the object format 'O' (a numpy object array, whose items are
 *  read as a sequence). */
static int format_is_object(const char *fmt)
{
    if (!fmt)
        return 0;
    if (fmt[0] == '@' || fmt[0] == '=' || fmt[0] == '<' || fmt[0] == '>' || fmt[0] == '!')
        fmt++;
    return fmt[0] == 'O' && fmt[1] == '\0';
}

/** Refuses a buffer whose elements are not what `name` needs: real inputs (want_int == 0)
 *  must be float32/float64 (integer or byte buffers were read as numbers before: raw
 *  `memoryview(V.tobytes())` passed as coordinates); indices must be integers. Complex data
 *  is always refused (its imaginary part would be dropped). Returns 0 or -1 with TypeError. */
static int check_kind(elem_kind kind, int want_int, const char *format, const char *name)
{
    const char *f = format ? format : "B";
    if (want_int && kind == KIND_FLOAT) {
        PyErr_Format(PyExc_TypeError, "%s must hold integers, got floating-point data "
                     "(buffer format '%s')", name, f);
        return -1;
    }
    if (!want_int && kind != KIND_FLOAT) {
        PyErr_Format(PyExc_TypeError,
                     "%s must hold floating-point values (float32 or float64), got integer "
                     "data (buffer format '%s'); convert it first, e.g. "
                     "numpy.asarray(x, dtype=float)", name, f);
        return -1;
    }
    return 0;
}

/** Reads through the buffer protocol. Returns 1 when done (0 on success in *rc), or 0 when
 *  the buffer is an object array that the caller reads with the sequence protocol (no
 *  exception set). Any other unsupported format is a TypeError naming it. */
static int read_buffer(PyObject *obj, Py_ssize_t rows, Py_ssize_t cols, const char *name,
                       int want_int, void **out, Py_ssize_t *out_rows, Py_ssize_t *out_cols,
                       int *out_ndim, int *rc)
{
    Py_buffer view;
    elem_kind kind;
    int swap;
    Py_ssize_t r, c, shape1;
    void *data = NULL;

    *rc = -1;
    if (PyObject_GetBuffer(obj, &view, PyBUF_RECORDS_RO) < 0)
        return 1;
    if (parse_format(view.format, view.itemsize, &kind, &swap) < 0) {
        const char *f = view.format ? view.format : "B";
        if (format_is_object(f) && PySequence_Check(obj)) {
            PyBuffer_Release(&view);
            return 0;
        }
        if (format_is_complex(f))
            PyErr_Format(PyExc_TypeError,
                         "%s must hold real numbers, got complex data (buffer format '%s'): "
                         "its imaginary part would be lost; pass the real part explicitly",
                         name, f);
        else
            PyErr_Format(PyExc_TypeError,
                         "%s: unsupported element type (buffer format '%s'); use %s", name, f,
                         want_int ? "int32/int64" : "float32/float64");
        goto done;
    }
    if (check_kind(kind, want_int, view.format, name) < 0)
        goto done;
    if (view.ndim == 0) {
        PyErr_Format(PyExc_ValueError, "%s must be an array, got a scalar", name);
        goto done;
    }
    shape1 = view.ndim >= 2 ? view.shape[1] : 1;
    if (resolve_shape(view.ndim, view.shape[0], shape1, rows, cols, name, &r, &c) < 0)
        goto done;
    data = alloc_elems(r, c, want_int ? sizeof(dk_index) : sizeof(double));
    if (!data)
        goto done;
    {
        const char *base = (const char *)view.buf;
        /* Strides are given for PyBUF_STRIDES requests; a NULL one means C-contiguous. */
        Py_ssize_t s0 = view.strides ? view.strides[0]
                                     : view.itemsize * (view.ndim >= 2 ? view.shape[1] : 1);
        Py_ssize_t s1 = (view.ndim >= 2) ? (view.strides ? view.strides[1] : view.itemsize) : 0;
        for (Py_ssize_t i = 0; i < r; ++i) {
            for (Py_ssize_t j = 0; j < c; ++j) {
                const char *p;
                Py_ssize_t k = i * c + j;
                if (view.ndim == 1)
                    p = base + k * s0;
                else
                    p = base + i * s0 + j * s1;
                if (store_scalar(load_scalar(p, view.itemsize, kind, swap), want_int, data, k,
                                 i, j, name) < 0) {
                    PyMem_Free(data);
                    data = NULL;
                    goto done;
                }
            }
        }
    }
    *out = data;
    *out_rows = r;
    *out_cols = c;
    *out_ndim = view.ndim;
    *rc = 0;
done:
    PyBuffer_Release(&view);
    return 1;
}

/** Converts one Python number into the output (double or int32). */
static int store_object(PyObject *item, int want_int, void *out, Py_ssize_t k, Py_ssize_t i,
                        Py_ssize_t j, const char *name)
{
    if (!want_int) {
        double d;
        if (PyComplex_Check(item)) {
            PyErr_Format(PyExc_TypeError, "%s[%zd, %zd] must be a real number, got complex",
                         name, i, j);
            return -1;
        }
        if (!PyFloat_Check(item) && !PyLong_Check(item) && PyObject_CheckBuffer(item)) {
            /* a numpy scalar: judged by its format, as an array of it would be */
            Py_buffer view;
            elem_kind kind;
            int swap;
            if (PyObject_GetBuffer(item, &view, PyBUF_RECORDS_RO) < 0)
                return -1;
            if (view.ndim != 0 || parse_format(view.format, view.itemsize, &kind, &swap) < 0 ||
                kind != KIND_FLOAT) {
                PyErr_Format(PyExc_TypeError,
                             "%s[%zd, %zd] must be a float, got an element of buffer format "
                             "'%s'%s", name, i, j, view.format ? view.format : "B",
                             view.ndim != 0 ? " that is not a scalar" : "");
                PyBuffer_Release(&view);
                return -1;
            }
            ((double *)out)[k] = load_scalar((const char *)view.buf, view.itemsize, kind,
                                             swap).d;
            PyBuffer_Release(&view);
            return 0;
        }
        d = PyFloat_AsDouble(item);
        if (d == -1.0 && PyErr_Occurred()) {
            if (PyErr_ExceptionMatches(PyExc_TypeError)) {
                PyObject *tn = PyType_GetName(Py_TYPE(item));
                PyErr_Clear();
                if (tn) {
                    PyErr_Format(PyExc_TypeError, "%s[%zd, %zd] must be a number, got %U", name,
                                 i, j, tn);
                    Py_DECREF(tn);
                }
            }
            return -1;
        }
        ((double *)out)[k] = d;
        return 0;
    } else {
        PyObject *index;
        long long v;
        int overflow = 0;
        if (PyFloat_Check(item)) {
            PyErr_Format(PyExc_TypeError, "%s[%zd, %zd] must be an integer, got a float", name,
                         i, j);
            return -1;
        }
        index = PyNumber_Index(item);
        if (!index) {
            if (PyErr_ExceptionMatches(PyExc_TypeError)) {
                PyObject *tn = PyType_GetName(Py_TYPE(item));
                PyErr_Clear();
                if (tn) {
                    PyErr_Format(PyExc_TypeError, "%s[%zd, %zd] must be an integer, got %U",
                                 name, i, j, tn);
                    Py_DECREF(tn);
                }
            }
            return -1;
        }
        v = PyLong_AsLongLongAndOverflow(index, &overflow);
        Py_DECREF(index);
        if (v == -1 && PyErr_Occurred())
            return -1;
        if (overflow || v < INT32_MIN || v > INT32_MAX) {
            PyErr_Format(PyExc_OverflowError, "%s[%zd, %zd] is outside the int32 range", name,
                         i, j);
            return -1;
        }
        ((dk_index *)out)[k] = (dk_index)v;
        return 0;
    }
}

/** Is `o` something we treat as a row (a sequence that is not text)? */
static int is_row_like(PyObject *o)
{
    if (PyUnicode_Check(o) || PyBytes_Check(o) || PyByteArray_Check(o))
        return 0;
    return PySequence_Check(o);
}

/** Reads a (nested) sequence. Returns 0 or -1 with an exception set.
 *
 * Every level is read exactly once, into lists this function owns, before any shape is
 * decided: Python code can run while the items are converted (__index__, __float__,
 * __len__, __getitem__) and may change the caller's sequences, but never these copies, so
 * a sequence that grows or shrinks meanwhile cannot make the shape disagree with the data. */
static int read_sequence(PyObject *obj, Py_ssize_t rows, Py_ssize_t cols, const char *name,
                         int want_int, void **out, Py_ssize_t *out_rows, Py_ssize_t *out_cols,
                         int *out_ndim)
{
    PyObject *outer, *snap = NULL;
    Py_ssize_t n0, n1 = 1, r, c;
    int ndim = 1;
    void *data = NULL;
    int rc = -1;

    outer = PySequence_List(obj);
    if (!outer)
        return -1;
    n0 = PyList_Size(outer);
    if (n0 > 0 && is_row_like(PyList_GetItem(outer, 0))) {
        /* snapshot every row (a list of lists of our own), then check they agree */
        ndim = 2;
        snap = PyList_New(n0);
        if (!snap)
            goto done;
        for (Py_ssize_t i = 0; i < n0; ++i) {
            PyObject *item = PyList_GetItem(outer, i), *row;
            if (!is_row_like(item)) {
                PyErr_Format(PyExc_ValueError, "%s row %zd is not a sequence", name, i);
                goto done;
            }
            row = PySequence_List(item);
            if (!row)
                goto done;
            PyList_SetItem(snap, i, row); /* steals */
        }
        n1 = PyList_Size(PyList_GetItem(snap, 0));
        for (Py_ssize_t i = 1; i < n0; ++i)
            if (PyList_Size(PyList_GetItem(snap, i)) != n1) {
                PyErr_Format(PyExc_ValueError, "%s row %zd has %zd values, expected %zd", name,
                             i, PyList_Size(PyList_GetItem(snap, i)), n1);
                goto done;
            }
    }
    if (n0 == 0) {
        r = 0;
        c = cols > 0 ? cols : (cols == 0 ? 1 : 0);
        if (rows > 0) {
            PyErr_Format(PyExc_ValueError, "%s must have %zd rows, got 0", name, rows);
            goto done;
        }
    } else if (resolve_shape(ndim, n0, n1, rows, cols, name, &r, &c) < 0) {
        goto done;
    }
    data = alloc_elems(r, c, want_int ? sizeof(dk_index) : sizeof(double));
    if (!data)
        goto done;
    if (ndim == 1) {
        for (Py_ssize_t k = 0; k < n0; ++k) {
            Py_ssize_t i = k / c, j = k % c;
            if (store_object(PyList_GetItem(outer, k), want_int, data, k, i, j,
                             name) < 0)
                goto done;
        }
    } else {
        for (Py_ssize_t i = 0; i < n0; ++i) {
            PyObject *row = PyList_GetItem(snap, i);
            for (Py_ssize_t j = 0; j < n1; ++j) {
                if (store_object(PyList_GetItem(row, j), want_int, data, i * n1 + j,
                                 i, j, name) < 0)
                    goto done;
            }
        }
    }
    *out = data;
    data = NULL;
    *out_rows = r;
    *out_cols = c;
    *out_ndim = ndim;
    rc = 0;
done:
    Py_XDECREF(snap);
    Py_DECREF(outer);
    PyMem_Free(data);
    return rc;
}

/** Common entry: buffer first, then sequences. */
static int read_array(PyObject *obj, Py_ssize_t rows, Py_ssize_t cols, const char *name,
                      int want_int, void **out, Py_ssize_t *out_rows, Py_ssize_t *out_cols,
                      int *out_ndim)
{
    *out = NULL;
    *out_rows = *out_cols = 0;
    if (obj == NULL || obj == Py_None) {
        PyErr_Format(PyExc_TypeError, "%s must be an array, got None", name);
        return -1;
    }
    if (PyUnicode_Check(obj)) {
        PyErr_Format(PyExc_TypeError, "%s must be an array, got str", name);
        return -1;
    }
    if (PyObject_CheckBuffer(obj)) {
        int rc;
        if (read_buffer(obj, rows, cols, name, want_int, out, out_rows, out_cols, out_ndim,
                        &rc))
            return rc;
        /* an object array: its items are read one by one below */
    } else if (!PySequence_Check(obj)) {
        PyObject *tn = PyType_GetName(Py_TYPE(obj));
        if (tn) {
            PyErr_Format(PyExc_TypeError, "%s must be an array or a sequence, got %U", name, tn);
            Py_DECREF(tn);
        }
        return -1;
    }
    return read_sequence(obj, rows, cols, name, want_int, out, out_rows, out_cols, out_ndim);
}

int dk_py_read_doubles(PyObject *obj, Py_ssize_t rows, Py_ssize_t cols, const char *name,
                       dk_py_doubles *out)
{
    void *data;
    out->data = NULL;
    out->rows = out->cols = 0;
    out->ndim = 0;
    if (read_array(obj, rows, cols, name, 0, &data, &out->rows, &out->cols, &out->ndim) < 0)
        return -1;
    out->data = (double *)data;
    return 0;
}

int dk_py_read_indices(PyObject *obj, Py_ssize_t rows, Py_ssize_t cols, const char *name,
                       dk_py_indices *out)
{
    void *data;
    out->data = NULL;
    out->rows = out->cols = 0;
    out->ndim = 0;
    if (read_array(obj, rows, cols, name, 1, &data, &out->rows, &out->cols, &out->ndim) < 0)
        return -1;
    out->data = (dk_index *)data;
    return 0;
}

int dk_py_read_surface(PyObject *vobj, PyObject *fobj, dk_py_doubles *v, dk_py_indices *f)
{
    if (dk_py_read_doubles(vobj, -1, 3, "vertices", v) < 0)
        return -1;
    if (dk_py_read_indices(fobj, -1, 3, "triangles", f) < 0) {
        dk_py_doubles_release(v);
        return -1;
    }
    return 0;
}

void dk_py_doubles_release(dk_py_doubles *a)
{
    if (!a)
        return;
    PyMem_Free(a->data);
    a->data = NULL;
    a->rows = a->cols = 0;
}

void dk_py_indices_release(dk_py_indices *a)
{
    if (!a)
        return;
    PyMem_Free(a->data);
    a->data = NULL;
    a->rows = a->cols = 0;
}

/* ================================================================== outputs ============= */

/** A zero-filled array of `itemsize`-byte elements; see dk_py_new_doubles. */
static PyObject *new_array(int ndim, Py_ssize_t rows, Py_ssize_t cols, Py_ssize_t itemsize,
                           const char *dtype, const char *mv_format, void **data)
{
    PyObject *bytes = NULL, *numpy = NULL, *flat = NULL, *result = NULL;
    Py_ssize_t n;

    *data = NULL;
    if (ndim != 1 && ndim != 2) {
        PyErr_SetString(PyExc_SystemError, "deformkit: output arrays are 1-D or 2-D");
        return NULL;
    }
    if (ndim == 1)
        cols = 1;
    if (rows < 0 || cols < 0) {
        PyErr_SetString(PyExc_SystemError, "deformkit: negative output shape");
        return NULL;
    }
    if (cols > 0 && rows > PY_SSIZE_T_MAX / cols / itemsize)
        return PyErr_NoMemory();
    n = rows * cols;
    bytes = PyByteArray_FromStringAndSize(NULL, n * itemsize);
    if (!bytes)
        return NULL;
    if (n > 0)
        memset(PyByteArray_AsString(bytes), 0, (size_t)(n * itemsize));

    numpy = PyImport_ImportModule("numpy");
    if (numpy) {
        flat = PyObject_CallMethod(numpy, "frombuffer", "Os", bytes, dtype);
        if (!flat)
            goto done;
        if (ndim == 2)
            result = PyObject_CallMethod(flat, "reshape", "(nn)", rows, cols);
        else
            result = Py_NewRef(flat);
    } else {
        if (!PyErr_ExceptionMatches(PyExc_ImportError))
            goto done;
        PyErr_Clear();
        flat = PyMemoryView_FromObject(bytes);
        if (!flat)
            goto done;
        /* memoryview.cast refuses zero-sized dimensions: keep empty results 1-D. */
        if (ndim == 2 && n > 0)
            result = PyObject_CallMethod(flat, "cast", "s(nn)", mv_format, rows, cols);
        else
            result = PyObject_CallMethod(flat, "cast", "s", mv_format);
    }
    if (result)
        *data = (void *)PyByteArray_AsString(bytes);
done:
    Py_XDECREF(flat);
    Py_XDECREF(numpy);
    Py_DECREF(bytes);
    return result;
}

PyObject *dk_py_new_doubles(int ndim, Py_ssize_t rows, Py_ssize_t cols, double **data)
{
    void *p;
    PyObject *r = new_array(ndim, rows, cols, (Py_ssize_t)sizeof(double), "float64", "d", &p);
    *data = (double *)p;
    return r;
}

PyObject *dk_py_new_indices(int ndim, Py_ssize_t rows, Py_ssize_t cols, dk_index **data)
{
    void *p;
    PyObject *r = new_array(ndim, rows, cols, (Py_ssize_t)sizeof(dk_index), "int32", "i", &p);
    *data = (dk_index *)p;
    return r;
}

PyObject *dk_py_new_int64(int ndim, Py_ssize_t rows, Py_ssize_t cols, int64_t **data)
{
    void *p;
    PyObject *r = new_array(ndim, rows, cols, (Py_ssize_t)sizeof(int64_t), "int64", "q", &p);
    *data = (int64_t *)p;
    return r;
}

/* ================================================================== state / results ===== */

dk_py_state *dk_py_get_state(PyObject *module)
{
    return (dk_py_state *)PyModule_GetState(module);
}

dk_py_state *dk_py_state_of(PyObject *obj)
{
    PyObject *module = PyType_GetModule(Py_TYPE(obj));
    if (!module) {
        PyErr_Clear();
        return NULL;
    }
    return dk_py_get_state(module);
}

/* ------------------------------------------------------------------ the fork gate ------ */

void dk_py_native_begin(dk_py_state *st)
{
    if (!st || !st->gate_ready)
        return;
    pthread_mutex_lock(&st->gate_mu);
    while (st->forks_pending > 0)
        pthread_cond_wait(&st->gate_cv, &st->gate_mu);
    st->in_flight++;
    pthread_mutex_unlock(&st->gate_mu);
}

void dk_py_native_end(dk_py_state *st)
{
    if (!st || !st->gate_ready)
        return;
    pthread_mutex_lock(&st->gate_mu);
    if (--st->in_flight == 0 && st->forks_pending > 0)
        pthread_cond_broadcast(&st->gate_cv);
    pthread_mutex_unlock(&st->gate_mu);
}

void dk_py_native_pause(dk_py_state *st)
{
    dk_py_native_end(st);
}

void dk_py_native_resume(dk_py_state *st)
{
    dk_py_native_begin(st);
}

int dk_py_arpack_check(dk_py_state *st, const char *context)
{
    if (st && st->arpack_owner != 0 && st->arpack_owner == PyThread_get_thread_ident()) {
        PyErr_Format(PyExc_RuntimeError,
                     "%s: an eigen computation is already running on this thread (this call "
                     "comes from its progress callback); ARPACK runs one at a time, so start "
                     "this one after that bind has returned",
                     context);
        return -1;
    }
    return 0;
}

void dk_py_arpack_acquire(dk_py_state *st)
{
    if (!PyThread_acquire_lock(st->arpack_lock, NOWAIT_LOCK)) {
        /* another thread's eigensolve holds it, perhaps standing at its progress callback
         * (outside the gate) where it may fork: wait for it outside the gate, or the fork
         * would wait for this thread, this thread for the lock, the holder for the fork */
        dk_py_native_end(st);
        PyThread_acquire_lock(st->arpack_lock, WAIT_LOCK);
        dk_py_native_begin(st);
    }
    st->arpack_owner = PyThread_get_thread_ident();
}

void dk_py_arpack_release(dk_py_state *st)
{
    st->arpack_owner = 0;
    PyThread_release_lock(st->arpack_lock);
}

int dk_py_fork_before(dk_py_state *st)
{
    if (!st || !st->gate_ready)
        return 0;
    Py_BEGIN_ALLOW_THREADS
    pthread_mutex_lock(&st->gate_mu);
    st->forks_pending++;
    while (st->in_flight > 0)
        pthread_cond_wait(&st->gate_cv, &st->gate_mu);
    pthread_mutex_unlock(&st->gate_mu);
    Py_END_ALLOW_THREADS
    return 0;
}

void dk_py_fork_after_parent(dk_py_state *st)
{
    if (!st || !st->gate_ready)
        return;
    pthread_mutex_lock(&st->gate_mu);
    if (st->forks_pending > 0)
        st->forks_pending--;
    pthread_cond_broadcast(&st->gate_cv);
    pthread_mutex_unlock(&st->gate_mu);
}

void dk_py_fork_after_child(dk_py_state *st)
{
    if (!st || !st->gate_ready)
        return;
    /* the child has one thread: nobody is in flight or waiting; the mutex was unlocked at
     * the fork but the condition may count waiters of the parent, so both start afresh */
    pthread_mutex_init(&st->gate_mu, NULL);
    pthread_cond_init(&st->gate_cv, NULL);
    st->in_flight = 0;
    st->forks_pending = 0;
}

PyObject *dk_py_new_solve_result(PyObject *module, PyObject *positions, double energy,
                                 int iterations, int converged)
{
    dk_py_state *st = dk_py_get_state(module);
    PyObject *result, *item;

    if (!st || !st->solve_result_type) {
        Py_XDECREF(positions);
        PyErr_SetString(PyExc_SystemError, "deformkit: SolveResult type is not initialised");
        return NULL;
    }
    if (!positions)
        return NULL;
    result = PyStructSequence_New((PyTypeObject *)st->solve_result_type);
    if (!result) {
        Py_DECREF(positions);
        return NULL;
    }
    PyStructSequence_SetItem(result, 0, positions); /* steals */
    item = PyFloat_FromDouble(energy);
    if (!item)
        goto fail;
    PyStructSequence_SetItem(result, 1, item);
    item = PyLong_FromLong(iterations);
    if (!item)
        goto fail;
    PyStructSequence_SetItem(result, 2, item);
    item = PyBool_FromLong(converged);
    PyStructSequence_SetItem(result, 3, item);
    return result;
fail:
    Py_DECREF(result);
    return NULL;
}

PyObject *dk_py_as_blocks(PyObject *obj, int r, int c, const char *name)
{
    if (!PyObject_HasAttrString(obj, "reshape"))
        return Py_NewRef(obj);
    PyObject *shape = PyObject_GetAttrString(obj, "shape");
    if (!shape || !PyTuple_Check(shape)) {
        Py_XDECREF(shape);
        PyErr_Clear();
        return Py_NewRef(obj);
    }
    const Py_ssize_t nd = PyTuple_Size(shape);
    long last[2] = {-1, -1};
    for (Py_ssize_t k = 0; k < 2 && nd >= 2 && !PyErr_Occurred(); k++)
        last[k] = PyLong_AsLong(PyTuple_GetItem(shape, nd - 2 + k));
    Py_DECREF(shape);
    if (PyErr_Occurred())
        return NULL;
    if (nd >= 3) {
        if (last[0] != r || last[1] != c) {
            PyErr_Format(PyExc_ValueError,
                         "%s: expected k x %d x %d (or k x %d) values, got an array whose last "
                         "two dimensions are %ld x %ld",
                         name, r, c, r * c, last[0], last[1]);
            return NULL;
        }
        return PyObject_CallMethod(obj, "reshape", "(ii)", -1, r * c);
    }
    if (nd == 2 && last[1] == c && last[0] % r == 0 && c != r * c) /* blocks stacked */
        return PyObject_CallMethod(obj, "reshape", "(ii)", -1, r * c);
    return Py_NewRef(obj);
}
