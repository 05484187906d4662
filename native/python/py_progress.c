/* DeformKit CPython module: the bind progress callback shared by every method's constructor
 * and rebind (dk_py.h, "bind progress"). */
#include "dk_py.h"

#include <string.h>

static const char progress_doc[] =
    "BindProgress(fraction): what a bind's progress callback receives.\n\n"
    "A float, the fraction of the bind done (in [0, 1], non-decreasing, ending at 1), with\n"
    "the attribute `phase`: the step it is in ('renumber', 'cells', 'assemble', 'analyze',\n"
    "'factorize', 'basis', 'eigenvectors', ...; 'done' at 1).";

int dk_py_progress_init_type(PyObject *module, dk_py_state *st)
{
    /* type("BindProgress", (float,), {...}): a float subclass with one slot, built through
     * the type call since the Limited API has no PyFloatObject to extend */
    PyObject *slots = Py_BuildValue("(s)", "phase");
    PyObject *dict = slots ? Py_BuildValue("{s:O,s:s,s:s}", "__slots__", slots, "__module__",
                                           "deformkit", "__doc__", progress_doc)
                           : NULL;
    Py_XDECREF(slots);
    if (!dict)
        return -1;
    PyObject *type = PyObject_CallFunction((PyObject *)&PyType_Type, "s(O)O", "BindProgress",
                                           (PyObject *)&PyFloat_Type, dict);
    Py_DECREF(dict);
    if (!type)
        return -1;
    st->progress_type = type;
    Py_INCREF(type);
    if (PyModule_AddObject(module, "BindProgress", type) < 0) {
        Py_DECREF(type);
        return -1;
    }
    return 0;
}

int dk_py_progress_take(PyObject *kw, PyObject *module, const char *context, dk_py_progress *p)
{
    memset(p, 0, sizeof *p);
    PyObject *cb = NULL;
    if (kw) {
        cb = PyDict_GetItemString(kw, "progress"); /* borrowed */
        if (cb) {
            Py_INCREF(cb);
            if (PyDict_DelItemString(kw, "progress") < 0) {
                Py_DECREF(cb);
                return -1;
            }
        }
    }
    if (!cb || cb == Py_None) {
        Py_XDECREF(cb);
        return 0;
    }
    if (!PyCallable_Check(cb)) {
        Py_DECREF(cb);
        PyErr_Format(PyExc_TypeError, "%s: progress must be callable (fraction) -> bool",
                     context);
        return -1;
    }
    dk_py_state *st = dk_py_get_state(module);
    if (!st || !st->progress_type) {
        Py_DECREF(cb);
        if (!PyErr_Occurred())
            PyErr_SetString(PyExc_SystemError, "deformkit: no BindProgress type");
        return -1;
    }
    p->callable = cb;
    p->type = Py_NewRef(st->progress_type);
    p->state = st;
    return 0;
}

int dk_py_progress_phase(void *user, const char *phase, double fraction)
{
    dk_py_progress *p = user;
    if (!p || !p->callable)
        return 0;
    /* at a phase boundary: out of the fork gate while Python runs (dk_py.h). `paused` is set
     * before and cleared after, inside the gate, so a fork in between sees it set. */
    if (p->paused)
        *p->paused = 1;
    dk_py_native_pause(p->state);
    PyGILState_STATE g = PyGILState_Ensure();
    int stop = 1;
    if (!p->exc_type) { /* after a raise: stop, without calling again */
        PyObject *value = PyObject_CallFunction(p->type, "d", fraction);
        PyObject *name = value ? PyUnicode_FromString(phase ? phase : "") : NULL;
        PyObject *r = NULL;
        if (name && PyObject_SetAttrString(value, "phase", name) == 0)
            r = PyObject_CallFunctionObjArgs(p->callable, value, NULL);
        Py_XDECREF(name);
        Py_XDECREF(value);
        if (r) {
            const int t = PyObject_IsTrue(r);
            Py_DECREF(r);
            if (t >= 0)
                stop = t;
        }
        if (PyErr_Occurred()) /* kept for the caller's thread to raise */
            PyErr_Fetch(&p->exc_type, &p->exc_value, &p->exc_tb);
    }
    PyGILState_Release(g);
    dk_py_native_resume(p->state);
    if (p->paused)
        *p->paused = 0;
    return stop;
}

PyObject *dk_py_progress_raise(dk_py_progress *p, const dk_error *err, const char *context)
{
    if (p && p->exc_type) {
        PyErr_Restore(p->exc_type, p->exc_value, p->exc_tb); /* steals the references */
        p->exc_type = p->exc_value = p->exc_tb = NULL;
        return NULL;
    }
    return dk_py_raise(err, context);
}

int dk_py_progress_raised(dk_py_progress *p)
{
    if (!p || !p->exc_type)
        return 0;
    PyErr_Restore(p->exc_type, p->exc_value, p->exc_tb); /* steals the references */
    p->exc_type = p->exc_value = p->exc_tb = NULL;
    return 1;
}

void dk_py_progress_release(dk_py_progress *p)
{
    if (!p)
        return;
    Py_CLEAR(p->callable);
    Py_CLEAR(p->type);
    Py_CLEAR(p->exc_type);
    Py_CLEAR(p->exc_value);
    Py_CLEAR(p->exc_tb);
}
