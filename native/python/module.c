/* DeformKit CPython module: deformkit._native.
 *
 * Multi-phase initialisation with per-module state (dk_py_state): no C globals, so the module
 * may be loaded in several interpreters. The exec step creates the state (ARPACK lock,
 * SolveResult type, cached numpy.frombuffer) and then calls each binding file's
 * dk_py_init_<name> hook (declared in dk_py.h, defined in its py_<name>.c) in a fixed order.
 * A binding file missing from the build makes the import fail (undefined symbol) instead of
 * silently giving a module without its class.
 */
#include "dk_py.h"

#include "dk_method.h"
#include "dk_memory.h"
#include "dk_parallel.h"

#include <string.h>

/* ------------------------------------------------------------------ SolveResult --------- */

static int init_solve_result(PyObject *module, dk_py_state *st)
{
    /* Built on the stack: CPython copies what it keeps (names are string literals). */
    PyStructSequence_Field fields[] = {
        {"positions", "n x 3 float64 array of deformed vertex positions"},
        {"energy", "the method's energy at those positions (float)"},
        {"iterations", "iterations used (1 for direct methods)"},
        {"converged", "True when the method met its tolerance"},
        {NULL, NULL},
    };
    PyStructSequence_Desc desc = {
        "deformkit.SolveResult",
        "SolveResult(positions, energy, iterations, converged)\n\n"
        "What every deformation method's solve() returns; also usable as a 4-tuple.",
        fields,
        4,
    };
    PyTypeObject *type = PyStructSequence_NewType(&desc);
    if (!type)
        return -1;
    st->solve_result_type = (PyObject *)type;
    Py_INCREF((PyObject *)type);
    if (PyModule_AddObject(module, "SolveResult", (PyObject *)type) < 0) {
        Py_DECREF(type);
        return -1;
    }
    return 0;
}

/* ------------------------------------------------------------------ test helpers -------- */
/* Private (underscore) functions exposing the buffer readers so that tests can check every
 * input path directly: they read `obj` and return what the native side saw, as a new array. */

PyDoc_STRVAR(read_doubles_doc,
             "_read_doubles(obj, rows=-1, cols=0) -> float64 array (rows x cols, or 1-D)\n\n"
             "Test helper: reads obj with dk_py_read_doubles and returns a copy.");

static PyObject *py_read_doubles(PyObject *module, PyObject *args, PyObject *kwargs)
{
    static char *kwlist[] = {"obj", "rows", "cols", NULL};
    PyObject *obj, *result;
    Py_ssize_t rows = -1, cols = 0;
    dk_py_doubles a;
    double *dst;

    (void)module;
    if (!PyArg_ParseTupleAndKeywords(args, kwargs, "O|nn:_read_doubles", kwlist, &obj, &rows,
                                     &cols))
        return NULL;
    if (dk_py_read_doubles(obj, rows, cols, "obj", &a) < 0)
        return NULL;
    result = dk_py_new_doubles(cols == 0 ? 1 : 2, a.rows, a.cols, &dst);
    if (result && a.rows * a.cols > 0)
        memcpy(dst, a.data, sizeof(double) * (size_t)(a.rows * a.cols));
    dk_py_doubles_release(&a);
    return result;
}

PyDoc_STRVAR(read_indices_doc,
             "_read_indices(obj, rows=-1, cols=0) -> int32 array (rows x cols, or 1-D)\n\n"
             "Test helper: reads obj with dk_py_read_indices and returns a copy.");

static PyObject *py_read_indices(PyObject *module, PyObject *args, PyObject *kwargs)
{
    static char *kwlist[] = {"obj", "rows", "cols", NULL};
    PyObject *obj, *result;
    Py_ssize_t rows = -1, cols = 0;
    dk_py_indices a;
    dk_index *dst;

    (void)module;
    if (!PyArg_ParseTupleAndKeywords(args, kwargs, "O|nn:_read_indices", kwlist, &obj, &rows,
                                     &cols))
        return NULL;
    if (dk_py_read_indices(obj, rows, cols, "obj", &a) < 0)
        return NULL;
    result = dk_py_new_indices(cols == 0 ? 1 : 2, a.rows, a.cols, &dst);
    if (result && a.rows * a.cols > 0)
        memcpy(dst, a.data, sizeof(dk_index) * (size_t)(a.rows * a.cols));
    dk_py_indices_release(&a);
    return result;
}

PyDoc_STRVAR(raise_status_doc,
             "_raise_status(status, message, context=None)\n\n"
             "Test helper: raises what dk_py_raise raises for a dk_status code.");

static PyObject *py_raise_status(PyObject *module, PyObject *args)
{
    int status;
    const char *message, *context = NULL;
    dk_error err;

    (void)module;
    if (!PyArg_ParseTuple(args, "is|z:_raise_status", &status, &message, &context))
        return NULL;
    dk_error_set(&err, (dk_status)status, "%s", message);
    return dk_py_raise(&err, context);
}

PyDoc_STRVAR(method_info_doc,
             "_method_info(name) -> dict\n\n"
             "What the native method contract says of method `name` (dk_method.h flags):\n"
             "iterative, transforms_as_positions, translation_invariant, rigid_invariant,\n"
             "penalty_handles, soft_regions, given_start, edits_input, graph,\n"
             "linear_precision, dynamic (a simulation: a cold solve resets it, each\n"
             "warm one advances a frame), interior (solves for points the positions do\n"
             "not carry: a volume's interior); and\n"
             "'controls', the control kinds its bind takes (dk_controls.h), a tuple of\n"
             "'vertex_groups', 'points', 'bones', 'cage', 'lattice', 'poses'; 'state',\n"
             "whether it carries state from solve to solve (save_state, restore_state).\n"
             "For code and tests written against the contract.");

static PyObject *py_method_info(PyObject *module, PyObject *arg)
{
    (void)module;
    const char *name = PyUnicode_AsUTF8AndSize(arg, NULL);
    if (!name)
        return NULL;
    const dk_method_ops *ops = dk_method_find(name);
    if (!ops) {
        PyErr_Format(PyExc_KeyError, "no method %R", arg);
        return NULL;
    }
    const unsigned f = ops->flags;
    PyObject *list = PyList_New(0);
    for (unsigned bit = 1; list && bit <= DK_CONTROL_ALL; bit <<= 1) {
        const char *id = (ops->controls & bit) ? dk_control_kind_id((dk_control_kind)bit) : NULL;
        PyObject *s = id ? PyUnicode_FromString(id) : NULL;
        if (id && (!s || PyList_Append(list, s) != 0))
            Py_CLEAR(list);
        Py_XDECREF(s);
    }
    PyObject *controls = list ? PyList_AsTuple(list) : NULL;
    Py_XDECREF(list);
    if (!controls)
        return NULL;
    PyObject *info = Py_BuildValue("{s:O,s:O,s:O,s:O,s:O,s:O,s:O,s:O,s:O,s:O,s:O,s:O,s:O,s:O}",
                                   "interior", (f & DK_METHOD_INTERIOR) ? Py_True : Py_False,
                                   "dynamic", (f & DK_METHOD_DYNAMIC) ? Py_True : Py_False,
                                   "linear_precision",
                                   (f & DK_METHOD_LINEAR_PRECISION) ? Py_True : Py_False,
                                   "state", ops->state_size ? Py_True : Py_False, "iterative",
                         (f & DK_METHOD_ITERATIVE) ? Py_True : Py_False,
                         "transforms_as_positions",
                         (f & DK_METHOD_TRANSFORMS_AS_POSITIONS) ? Py_True : Py_False,
                         "translation_invariant",
                         (f & DK_METHOD_TRANSLATION_INVARIANT) ? Py_True : Py_False,
                         "rigid_invariant", (f & DK_METHOD_RIGID_INVARIANT) ? Py_True : Py_False,
                         "penalty_handles",
                         (f & DK_METHOD_PENALTY_HANDLES) ? Py_True : Py_False, "soft_regions",
                         (f & DK_METHOD_SOFT_REGIONS) ? Py_True : Py_False, "given_start",
                         (f & DK_METHOD_GIVEN_START) ? Py_True : Py_False, "edits_input",
                         (f & DK_METHOD_EDITS_INPUT) ? Py_True : Py_False, "graph",
                         (f & DK_METHOD_GRAPH) ? Py_True : Py_False, "controls", controls);
    Py_DECREF(controls);
    return info;
}

/* ------------------------------------------------------------------ memory ------------- */

PyDoc_STRVAR(available_memory_doc,
             "available_memory() -> dict\n\n"
             "What a bind may still take now (issue 19, item 4): 'bytes', the least of\n"
             "'address_space' (RLIMIT_AS minus the process's VmSize), 'cgroup' (the cgroup v2\n"
             "memory.max minus memory.current) and 'mem_available' (/proc/meminfo); each is\n"
             "None when there is no such limit; 'limit' names the tightest ('RLIMIT_AS\n"
             "headroom', 'cgroup memory.max headroom', 'MemAvailable' or 'no limit');\n"
             "'thread_reserve', the address space the numerics' thread pools may take on\n"
             "first use, which binds keep free below RLIMIT_AS.");

static PyObject *opt_bytes(uint64_t v)
{
    if (v == UINT64_MAX)
        Py_RETURN_NONE;
    return PyLong_FromUnsignedLongLong((unsigned long long)v);
}

static PyObject *py_available_memory(PyObject *module, PyObject *unused)
{
    dk_memory_available a;
    (void)module;
    (void)unused;
    dk_memory_query(&a);
    PyObject *vals[5] = {opt_bytes(a.bytes), opt_bytes(a.address_space), opt_bytes(a.cgroup),
                         opt_bytes(a.mem_available), opt_bytes(dk_memory_thread_reserve())};
    PyObject *d = NULL;
    if (vals[0] && vals[1] && vals[2] && vals[3] && vals[4])
        d = Py_BuildValue("{s:O,s:s,s:O,s:O,s:O,s:O}", "bytes", vals[0], "limit",
                          dk_memory_limit_name(a.limit), "address_space", vals[1], "cgroup",
                          vals[2], "mem_available", vals[3], "thread_reserve", vals[4]);
    for (int i = 0; i < 5; i++)
        Py_XDECREF(vals[i]);
    return d;
}

/* ------------------------------------------------------------------ fork --------------- */

PyDoc_STRVAR(after_fork_child_doc,
             "_after_fork_in_child()\n\n"
             "Registered by the deformkit package with os.register_at_fork(after_in_child=...):\n"
             "runs in a forked child on the thread that forked (issue 18, class 3). Makes\n"
             "OpenMP regions started from this thread run on it alone (its OpenMP team\n"
             "exists only in the parent) and gives the module a fresh ARPACK lock (another\n"
             "thread may have held it at the fork; that thread does not exist here).");

/* Why fork handlers and not a pid check per call: the hazards are per process and per
 * thread -- only the thread that forked carries an OpenMP team whose threads stayed in the
 * parent; a call in flight in another thread at the fork must not be copied half-done (the
 * fork gate, dk_py.h) -- and the handlers run exactly there, at the right moments. They are
 * registered through os.register_at_fork (deformkit/__init__.py), which keeps them in the
 * interpreter, so the C library and the module keep no global of their own: what they touch
 * (the gate, the ARPACK lock) is module state. A method object entered but not yet inside
 * its native call at the fork is handled per object, by the pid recorded when it was
 * entered (dk_py_method_enter). Forks that bypass os.fork (a C extension calling fork()
 * without PyOS_AfterFork_Child) are not covered: the interpreter itself is not usable in
 * such a child. */
static PyObject *py_after_fork_child(PyObject *module, PyObject *unused)
{
    dk_py_state *st = dk_py_get_state(module);
    (void)unused;
    dk_openmp_after_fork_child();
    dk_py_fork_after_child(st);
    if (st && st->arpack_lock) {
        if (st->arpack_owner == PyThread_get_thread_ident()) {
            /* held by this very thread: it forked from the progress callback of its own
             * eigen bind, which goes on here and gives the lock back: keep it */
        } else if (PyThread_acquire_lock(st->arpack_lock, NOWAIT_LOCK)) {
            PyThread_release_lock(st->arpack_lock); /* free at the fork: keep it */
        } else {
            /* held by a thread that did not survive the fork: it would never be released.
             * Replaced, and the held one dropped (freeing a held lock is undefined). */
            PyThread_type_lock fresh = PyThread_allocate_lock();
            if (!fresh)
                return PyErr_NoMemory();
            st->arpack_lock = fresh;
            st->arpack_owner = 0;
        }
    }
    Py_RETURN_NONE;
}

PyDoc_STRVAR(before_fork_doc,
             "_before_fork()\n\n"
             "Registered with os.register_at_fork(before=...): closes the fork gate and waits\n"
             "(without the GIL) until no heavy native call runs in another thread, so that\n"
             "none is copied half-done into the child (dk_py.h, the fork gate).");

static PyObject *py_before_fork(PyObject *module, PyObject *unused)
{
    (void)unused;
    dk_py_fork_before(dk_py_get_state(module));
    Py_RETURN_NONE;
}

PyDoc_STRVAR(after_fork_parent_doc,
             "_after_fork_in_parent()\n\n"
             "Registered with os.register_at_fork(after_in_parent=...): opens the fork gate.");

static PyObject *py_after_fork_parent(PyObject *module, PyObject *unused)
{
    (void)unused;
    dk_py_fork_after_parent(dk_py_get_state(module));
    Py_RETURN_NONE;
}

static PyMethodDef module_methods[] = {
    {"available_memory", py_available_memory, METH_NOARGS, available_memory_doc},
    {"_before_fork", py_before_fork, METH_NOARGS, before_fork_doc},
    {"_after_fork_in_parent", py_after_fork_parent, METH_NOARGS, after_fork_parent_doc},
    {"_after_fork_in_child", py_after_fork_child, METH_NOARGS, after_fork_child_doc},
    {"_method_info", py_method_info, METH_O, method_info_doc},
    {"_read_doubles", (PyCFunction)(void (*)(void))py_read_doubles,
     METH_VARARGS | METH_KEYWORDS, read_doubles_doc},
    {"_read_indices", (PyCFunction)(void (*)(void))py_read_indices,
     METH_VARARGS | METH_KEYWORDS, read_indices_doc},
    {"_raise_status", py_raise_status, METH_VARARGS, raise_status_doc},
    {NULL, NULL, 0, NULL},
};

/* ------------------------------------------------------------------ module lifecycle ---- */

static int module_exec(PyObject *module)
{
    dk_py_state *st = dk_py_get_state(module);
    PyObject *numpy;

    if (!st) {
        PyErr_SetString(PyExc_SystemError, "deformkit: module state missing");
        return -1;
    }
    st->arpack_lock = PyThread_allocate_lock();
    if (!st->arpack_lock) {
        PyErr_NoMemory();
        return -1;
    }
    if (pthread_mutex_init(&st->gate_mu, NULL) != 0) {
        PyErr_NoMemory();
        return -1;
    }
    if (pthread_cond_init(&st->gate_cv, NULL) != 0) {
        pthread_mutex_destroy(&st->gate_mu);
        PyErr_NoMemory();
        return -1;
    }
    st->gate_ready = 1;
    numpy = PyImport_ImportModule("numpy");
    if (numpy) {
        st->numpy_frombuffer = PyObject_GetAttrString(numpy, "frombuffer");
        Py_DECREF(numpy);
        if (!st->numpy_frombuffer)
            return -1;
    } else {
        if (!PyErr_ExceptionMatches(PyExc_ImportError))
            return -1;
        PyErr_Clear();
        st->numpy_frombuffer = Py_NewRef(Py_None);
    }
    if (init_solve_result(module, st) < 0 || dk_py_progress_init_type(module, st) < 0)
        return -1;
#define DK_PY_INIT_PART(part)                                                              \
    if (dk_py_init_##part(module) < 0)                                                     \
        return -1;
#define DK_PY_INIT_METHOD(part, cls) DK_PY_INIT_PART(part)
    DK_PY_PARTS(DK_PY_INIT_PART, DK_PY_INIT_METHOD)
#undef DK_PY_INIT_PART
#undef DK_PY_INIT_METHOD
    /* _methods: the deformation classes, in registration order */
#define DK_PY_NO_NAME(part)
#define DK_PY_METHOD_NAME(part, cls) cls,
    static const char *const method_names[] = {DK_PY_PARTS(DK_PY_NO_NAME, DK_PY_METHOD_NAME)};
#undef DK_PY_NO_NAME
#undef DK_PY_METHOD_NAME
    const Py_ssize_t n_methods = (Py_ssize_t)(sizeof method_names / sizeof method_names[0]);
    PyObject *names = PyTuple_New(n_methods);
    if (!names)
        return -1;
    for (Py_ssize_t i = 0; i < n_methods; i++) {
        PyObject *name = PyUnicode_FromString(method_names[i]);
        if (!name) {
            Py_DECREF(names);
            return -1;
        }
        PyTuple_SetItem(names, i, name);
    }
    return PyModule_AddObject(module, "_methods", names) < 0 ? (Py_DECREF(names), -1) : 0;
}

static int module_traverse(PyObject *module, visitproc visit, void *arg)
{
    dk_py_state *st = dk_py_get_state(module);
    if (st) {
        Py_VISIT(st->mesh_type);
        Py_VISIT(st->solve_result_type);
        Py_VISIT(st->numpy_frombuffer);
        Py_VISIT(st->progress_type);
    }
    return 0;
}

static int module_clear(PyObject *module)
{
    dk_py_state *st = dk_py_get_state(module);
    if (st) {
        Py_CLEAR(st->mesh_type);
        Py_CLEAR(st->solve_result_type);
        Py_CLEAR(st->numpy_frombuffer);
        Py_CLEAR(st->progress_type);
    }
    return 0;
}

static void module_free(void *module)
{
    dk_py_state *st = dk_py_get_state((PyObject *)module);
    module_clear((PyObject *)module);
    if (st && st->arpack_lock) {
        PyThread_free_lock(st->arpack_lock);
        st->arpack_lock = NULL;
    }
    if (st && st->gate_ready) {
        pthread_cond_destroy(&st->gate_cv);
        pthread_mutex_destroy(&st->gate_mu);
        st->gate_ready = 0;
    }
}

static PyModuleDef_Slot module_slots[] = {
    {Py_mod_exec, (void *)module_exec},
    {0, NULL},
};

PyDoc_STRVAR(module_doc,
             "deformkit._native: the native half of DeformKit.\n\n"
             "Mesh construction and topology, discrete operators (Laplacians, mass matrices,\n"
             "geodesics, eigenpairs, nearest neighbours, rotation fitting) and one class per\n"
             "deformation method. Import the `deformkit` package rather than this module.");

static struct PyModuleDef module_def = {
    PyModuleDef_HEAD_INIT,
    "deformkit._native",
    module_doc,
    (Py_ssize_t)sizeof(dk_py_state),
    module_methods,
    module_slots,
    module_traverse,
    module_clear,
    module_free,
};

PyMODINIT_FUNC PyInit__native(void)
{
    return PyModuleDef_Init(&module_def);
}
