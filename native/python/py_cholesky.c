/* DeformKit CPython module: deformkit.SparseCholesky (native/numerics/dk_cholesky.h).
 *
 * A symmetric positive definite matrix given as (rows, cols, values) triplets, the same
 * layout the operator functions return. The constructor assembles it (duplicates summed),
 * analyses the pattern once and factorizes; refactorize(values) takes new values for the same
 * triplets and reuses the analysis; solve(b) back-substitutes one or several right-hand sides
 * in one call. All native work runs with the GIL released. One call at a time per object: a
 * concurrent call from another thread gets RuntimeError (the factor's workspace is shared).
 *
 * Both triangles must be given (as cotangent_laplacian returns them) and must agree: CHOLMOD
 * reads only the upper triangle, so a non-symmetric input would otherwise be factorized as a
 * different matrix without a word.
 */
#include "dk_py.h"

#include <math.h>
#include <string.h>

#include "dk_cholesky.h"
#include "dk_sparse.h"

#include <unistd.h>

typedef struct CholeskyObject {
    PyObject_HEAD
    dk_cholesky *chol;
    dk_index n;
    Py_ssize_t n_triplets;
    dk_index *rows, *cols; /* the triplets' positions, kept for refactorize (PyMem) */
    int busy;
    long busy_pid;         /* getpid() of the process that set busy */
} CholeskyObject;

/* Relative asymmetry allowed: round-off of an assembly that sums the same terms in another
 * order, far below any genuine asymmetry. */
#define DK_PY_SYMMETRY_TOL 1e-12

static int enter(CholeskyObject *self)
{
    /* busy in the parent when this process forked: its native call was not running (the
     * fork gate, dk_py.h), so the factor is whole; the thread that set it is not here */
    if (self->busy && self->busy_pid != (long)getpid())
        self->busy = 0;
    if (self->busy) {
        PyErr_SetString(PyExc_RuntimeError,
                        "SparseCholesky: the object is in use by another thread");
        return -1;
    }
    self->busy = 1;
    self->busy_pid = (long)getpid();
    return 0;
}

/* Checks the values are finite; ValueError naming the triplet otherwise. */
static int check_finite(const dk_py_doubles *v, const char *context)
{
    for (Py_ssize_t k = 0; k < v->rows; k++)
        if (!isfinite(v->data[k])) {
            PyErr_Format(PyExc_ValueError, "%s: value %zd is not finite", context, k);
            return -1;
        }
    return 0;
}

/* Assembles the triplets into a CSC matrix and checks it is symmetric. Runs without the
 * GIL; fills err. */
static dk_status assemble(dk_index n, Py_ssize_t nt, const dk_index *rows, const dk_index *cols,
                          const double *vals, dk_sparse **out, dk_error *err)
{
    dk_sparse *a = NULL;
    dk_status st = dk_sparse_from_triplets(n, n, (int64_t)nt, rows, cols, vals, &a, err);
    if (st != DK_OK)
        return st;
    double amax = 0.0;
    int64_t nnz = dk_sparse_nnz(a);
    for (int64_t p = 0; p < nnz; p++)
        if (fabs(a->values[p]) > amax)
            amax = fabs(a->values[p]);
    double asym = dk_sparse_asymmetry(a);
    if (asym > DK_PY_SYMMETRY_TOL * amax) {
        dk_sparse_free(a);
        return dk_error_set(err, DK_ERR_INVALID_ARGUMENT,
                            "the matrix is not symmetric (largest |A - A^T| = %.3g, largest "
                            "|A| = %.3g): give both triangles with equal values",
                            asym, amax);
    }
    *out = a;
    return DK_OK;
}

static PyObject *cholesky_new(PyTypeObject *type, PyObject *args, PyObject *kwargs)
{
    static char *kwlist[] = {"rows", "cols", "values", "n", NULL};
    PyObject *rows_obj, *cols_obj, *vals_obj;
    Py_ssize_t n;
    dk_py_indices r = {0}, c = {0};
    dk_py_doubles v = {0};
    dk_sparse *a = NULL;
    dk_cholesky *chol = NULL;
    dk_error err = {0};
    dk_status st;
    CholeskyObject *self;
    allocfunc alloc;

    if (!PyArg_ParseTupleAndKeywords(args, kwargs, "OOOn:SparseCholesky", kwlist, &rows_obj,
                                     &cols_obj, &vals_obj, &n))
        return NULL;
    if (n < 1 || n > INT32_MAX) {
        PyErr_Format(PyExc_ValueError, "SparseCholesky: n is %zd, must be in [1, 2^31)", n);
        return NULL;
    }
    if (dk_py_read_indices(rows_obj, -1, 0, "rows", &r) < 0)
        return NULL;
    if (dk_py_read_indices(cols_obj, r.rows, 0, "cols", &c) < 0 ||
        dk_py_read_doubles(vals_obj, r.rows, 0, "values", &v) < 0 ||
        check_finite(&v, "SparseCholesky") < 0)
        goto fail;
    DK_PY_BEGIN_NATIVE((dk_py_state *)PyType_GetModuleState(type))
    st = assemble((dk_index)n, r.rows, r.data, c.data, v.data, &a, &err);
    if (st == DK_OK)
        st = dk_cholesky_analyze(a, &chol, &err);
    if (st == DK_OK)
        st = dk_cholesky_factorize(chol, a, &err);
    DK_PY_END_NATIVE
    dk_sparse_free(a);
    dk_py_doubles_release(&v);
    if (st != DK_OK) {
        dk_cholesky_free(chol);
        dk_py_raise(&err, "SparseCholesky");
        goto fail;
    }
    alloc = (allocfunc)PyType_GetSlot(type, Py_tp_alloc);
    self = alloc ? (CholeskyObject *)alloc(type, 0) : NULL;
    if (!self) {
        dk_cholesky_free(chol);
        if (!PyErr_Occurred())
            PyErr_NoMemory();
        goto fail;
    }
    self->chol = chol;
    self->n = (dk_index)n;
    self->n_triplets = r.rows;
    self->rows = r.data; /* ownership moves to the object */
    self->cols = c.data;
    return (PyObject *)self;

fail:
    dk_py_indices_release(&r);
    dk_py_indices_release(&c);
    dk_py_doubles_release(&v);
    return NULL;
}

static void cholesky_dealloc(PyObject *obj)
{
    CholeskyObject *self = (CholeskyObject *)obj;
    PyTypeObject *type = Py_TYPE(obj);
    freefunc tp_free = (freefunc)PyType_GetSlot(type, Py_tp_free);
    dk_cholesky_free(self->chol);
    PyMem_Free(self->rows);
    PyMem_Free(self->cols);
    tp_free(obj);
    Py_DECREF((PyObject *)type);
}

PyDoc_STRVAR(refactorize_doc,
             "refactorize(values)\n\n"
             "New values for the triplets given to the constructor (same rows and cols, same\n"
             "order). The symbolic analysis is reused; only the numeric factorization runs.\n"
             "On failure (not positive definite, not symmetric) the previous factor is lost\n"
             "and solve() raises until a refactorize succeeds.");

static PyObject *cholesky_refactorize(PyObject *obj, PyObject *arg)
{
    CholeskyObject *self = (CholeskyObject *)obj;
    dk_py_doubles v = {0};
    dk_sparse *a = NULL;
    dk_error err = {0};
    dk_status st;

    if (enter(self) < 0)
        return NULL;
    if (dk_py_read_doubles(arg, self->n_triplets, 0, "values", &v) < 0 ||
        check_finite(&v, "SparseCholesky.refactorize") < 0) {
        dk_py_doubles_release(&v);
        self->busy = 0;
        return NULL;
    }
    DK_PY_BEGIN_NATIVE(dk_py_state_of(obj))
    st = assemble(self->n, self->n_triplets, self->rows, self->cols, v.data, &a, &err);
    if (st == DK_OK)
        st = dk_cholesky_factorize(self->chol, a, &err);
    DK_PY_END_NATIVE
    dk_sparse_free(a);
    dk_py_doubles_release(&v);
    self->busy = 0;
    if (st != DK_OK)
        return dk_py_raise(&err, "SparseCholesky.refactorize");
    Py_RETURN_NONE;
}

PyDoc_STRVAR(solve_doc,
             "solve(b) -> x\n\n"
             "Solves A x = b. b has n entries, or n rows and k columns (k right-hand sides,\n"
             "solved in one call); x has b's shape.");

static PyObject *cholesky_solve(PyObject *obj, PyObject *arg)
{
    CholeskyObject *self = (CholeskyObject *)obj;
    dk_py_doubles b = {0};
    double *xdata, *work = NULL;
    PyObject *x;
    dk_error err = {0};
    dk_status st;
    Py_ssize_t n = self->n, k;
    int flat;

    if (enter(self) < 0)
        return NULL;
    /* 1-D b (n values) or 2-D (n x k): read once, then look at what it was */
    if (dk_py_read_doubles(arg, n, DK_PY_COLS_1D_OR_2D, "b", &b) < 0)
        goto fail;
    flat = b.ndim == 1;
    k = b.cols;
    if (k < 1 || k > INT32_MAX) {
        PyErr_SetString(PyExc_ValueError, "SparseCholesky.solve: b has no columns");
        goto fail;
    }
    for (Py_ssize_t i = 0; i < n * k; i++)
        if (!isfinite(b.data[i])) {
            PyErr_Format(PyExc_ValueError,
                         "SparseCholesky.solve: b[%zd, %zd] is not finite", i / k, i % k);
            goto fail;
        }
    x = flat ? dk_py_new_doubles(1, n, 0, &xdata) : dk_py_new_doubles(2, n, k, &xdata);
    if (!x)
        goto fail;
    if (k > 1) {
        work = PyMem_Malloc((size_t)(n * k) * sizeof *work);
        if (!work) {
            Py_DECREF(x);
            PyErr_NoMemory();
            goto fail;
        }
    }
    DK_PY_BEGIN_NATIVE(dk_py_state_of(obj))
    if (k == 1) {
        st = dk_cholesky_solve(self->chol, b.data, 1, xdata, &err);
    } else {
        /* row-major n x k in, column-major for CHOLMOD, row-major out */
        for (Py_ssize_t i = 0; i < n; i++)
            for (Py_ssize_t j = 0; j < k; j++)
                work[j * n + i] = b.data[i * k + j];
        st = dk_cholesky_solve(self->chol, work, (int)k, work, &err);
        if (st == DK_OK)
            for (Py_ssize_t i = 0; i < n; i++)
                for (Py_ssize_t j = 0; j < k; j++)
                    xdata[i * k + j] = work[j * n + i];
    }
    DK_PY_END_NATIVE
    PyMem_Free(work);
    dk_py_doubles_release(&b);
    self->busy = 0;
    if (st != DK_OK) {
        Py_DECREF(x);
        return dk_py_raise(&err, "SparseCholesky.solve");
    }
    for (Py_ssize_t i = 0; i < n * k; i++) /* a factor that is fine can overflow */
        if (!isfinite(xdata[i])) {
            Py_DECREF(x);
            PyErr_Format(PyExc_RuntimeError,
                         "SparseCholesky.solve: x[%zd, %zd] is not finite: the matrix is too "
                         "ill-conditioned (or b too large) for this solve",
                         i / k, i % k);
            return NULL;
        }
    return x;

fail:
    dk_py_doubles_release(&b);
    self->busy = 0;
    return NULL;
}

static PyObject *get_n(PyObject *obj, void *c)
{
    (void)c;
    return PyLong_FromLong(((CholeskyObject *)obj)->n);
}

static PyObject *get_stats(PyObject *obj, void *c)
{
    CholeskyObject *self = (CholeskyObject *)obj;
    (void)c;
    if (enter(self) < 0) /* not while a refactorization in another thread replaces it */
        return NULL;
    PyObject *r = Py_BuildValue("{s:i,s:i,s:n}", "analysis_count",
                                dk_cholesky_analysis_count(self->chol), "factorization_count",
                                dk_cholesky_factorization_count(self->chol), "factor_bytes",
                                (Py_ssize_t)dk_cholesky_memory(self->chol));
    self->busy = 0;
    return r;
}

static PyGetSetDef cholesky_getset[] = {
    {"n", get_n, NULL, "matrix dimension", NULL},
    {"stats", get_stats, NULL, "dict: analysis_count, factorization_count, factor_bytes", NULL},
    {NULL, NULL, NULL, NULL, NULL},
};

static PyMethodDef cholesky_methods[] = {
    {"refactorize", cholesky_refactorize, METH_O, refactorize_doc},
    {"solve", cholesky_solve, METH_O, solve_doc},
    {NULL, NULL, 0, NULL},
};

PyDoc_STRVAR(cholesky_doc,
             "SparseCholesky(rows, cols, values, n)\n\n"
             "Sparse Cholesky factorization (CHOLMOD, AMD ordering) of the symmetric positive\n"
             "definite n x n matrix given as triplets (duplicates are summed; both triangles,\n"
             "as deformkit.cotangent_laplacian returns them). Analyses the pattern once and\n"
             "factorizes; refactorize(values) reuses the analysis; solve(b) takes one or many\n"
             "right-hand sides. A matrix that is not positive definite raises RuntimeError\n"
             "naming the column; a non-symmetric one raises ValueError.");

static PyType_Slot cholesky_slots[] = {
    {Py_tp_new, (void *)cholesky_new},
    {Py_tp_dealloc, (void *)cholesky_dealloc},
    {Py_tp_getset, cholesky_getset},
    {Py_tp_methods, cholesky_methods},
    {Py_tp_doc, (void *)cholesky_doc},
    {0, NULL},
};

static PyType_Spec cholesky_spec = {
    "deformkit.SparseCholesky",
    (int)sizeof(CholeskyObject),
    0,
    Py_TPFLAGS_DEFAULT | Py_TPFLAGS_IMMUTABLETYPE,
    cholesky_slots,
};

int dk_py_init_cholesky(PyObject *module)
{
    PyObject *type = PyType_FromModuleAndSpec(module, &cholesky_spec, NULL);
    int r;
    if (!type)
        return -1;
    r = PyModule_AddObjectRef(module, "SparseCholesky", type);
    Py_DECREF(type);
    return r;
}
