/* DeformKit CPython module: the generic deformation-method type (dk_py_method.h). */
#include "dk_py_method.h"

#include "dk_memory.h"

#include <math.h>
#include <stddef.h>
#include <stdio.h>
#include <string.h>
#include <unistd.h>

#define OPTIONS_MAX 256

/* ------------------------------------------------------------------ option helpers ------ */

/* `key`'s value in `kw` (borrowed, taken out of the dict), or NULL when absent (no error). */
static PyObject *take(PyObject *kw, const char *key, PyObject **owned)
{
    *owned = NULL;
    if (!kw)
        return NULL;
    PyObject *v = PyDict_GetItemString(kw, key);
    if (!v)
        return NULL;
    *owned = Py_NewRef(v);
    if (PyDict_DelItemString(kw, key) < 0) {
        Py_CLEAR(*owned);
        return NULL;
    }
    return *owned;
}

PyObject *dk_py_opt_object(PyObject *kw, const char *key)
{
    PyObject *owned;
    return take(kw, key, &owned);
}

/* Replaces a conversion error (OverflowError, TypeError) with one naming the keyword: the
 * interpreter's "Python int too large to convert to C long" does not say which argument. */
static int name_the_argument(const char *key, PyObject *v, const char *want)
{
    PyObject *tn = PyType_GetName(Py_TYPE(v));
    if (PyErr_ExceptionMatches(PyExc_OverflowError)) {
        PyErr_Clear();
        PyErr_Format(PyExc_OverflowError, "%s is %.40R, out of the range of %s", key, v, want);
    } else if (PyErr_ExceptionMatches(PyExc_TypeError) && tn) {
        PyErr_Clear();
        PyErr_Format(PyExc_TypeError, "%s must be %s, got %U", key, want, tn);
    }
    Py_XDECREF(tn);
    return -1;
}

int dk_py_opt_int(PyObject *kw, const char *key, int *value)
{
    PyObject *owned, *v = take(kw, key, &owned);
    if (!v)
        return PyErr_Occurred() ? -1 : 0;
    long x = PyLong_AsLong(v);
    if (x == -1 && PyErr_Occurred()) {
        name_the_argument(key, v, "an int");
        Py_DECREF(owned);
        return -1;
    }
    Py_DECREF(owned);
    if (x < INT32_MIN || x > INT32_MAX) {
        PyErr_Format(PyExc_OverflowError, "%s is %ld, out of the range of an int", key, x);
        return -1;
    }
    *value = (int)x;
    return 0;
}

int dk_py_opt_double(PyObject *kw, const char *key, double *value)
{
    PyObject *owned, *v = take(kw, key, &owned);
    if (!v)
        return PyErr_Occurred() ? -1 : 0;
    double x = PyFloat_AsDouble(v);
    if (x == -1.0 && PyErr_Occurred()) {
        name_the_argument(key, v, "a float");
        Py_DECREF(owned);
        return -1;
    }
    Py_DECREF(owned);
    *value = x;
    return 0;
}

int dk_py_opt_bool(PyObject *kw, const char *key, int *value)
{
    PyObject *owned, *v = take(kw, key, &owned);
    if (!v)
        return PyErr_Occurred() ? -1 : 0;
    int x = 0;
    const int r = dk_py_strict_bool(v, key, "option", &x);
    Py_DECREF(owned);
    if (r < 0)
        return -1;
    *value = x;
    return 0;
}

int dk_py_opt_choice(PyObject *kw, const char *key, const char *const *names, int *value,
                     const char *context)
{
    PyObject *owned, *v = take(kw, key, &owned);
    if (!v)
        return PyErr_Occurred() ? -1 : 0;
    int c = dk_py_lap_choice(v, key, names, context);
    Py_DECREF(owned);
    if (c < 0)
        return -1;
    *value = c;
    return 0;
}

/* A TypeError naming the first key left in `kw`, as for a function's unknown keyword. */
static int refuse_leftovers(PyObject *kw, const char *where)
{
    Py_ssize_t pos = 0;
    PyObject *key, *val;
    if (kw && PyDict_Next(kw, &pos, &key, &val)) {
        PyErr_Format(PyExc_TypeError, "%s got an unexpected keyword argument %R", where, key);
        return -1;
    }
    return 0;
}

/* Splits `kwargs` into the keywords named in `common` (into *mine) and the rest (*rest). */
static int split_keywords(PyObject *kwargs, char *const *common, PyObject **mine,
                          PyObject **rest)
{
    *mine = PyDict_New();
    *rest = PyDict_New();
    if (!*mine || !*rest)
        goto fail;
    Py_ssize_t pos = 0;
    PyObject *key, *val;
    while (kwargs && PyDict_Next(kwargs, &pos, &key, &val)) {
        int is_common = 0;
        for (char *const *c = common; *c && !is_common; c++) {
            PyObject *name = PyUnicode_FromString(*c);
            if (!name)
                goto fail;
            is_common = PyObject_RichCompareBool(key, name, Py_EQ);
            Py_DECREF(name);
            if (is_common < 0)
                goto fail;
        }
        if (PyDict_SetItem(is_common ? *mine : *rest, key, val) < 0)
            goto fail;
    }
    return 0;
fail:
    Py_CLEAR(*mine);
    Py_CLEAR(*rest);
    return -1;
}

/* ------------------------------------------------------------------ the object --------- */

/* Whether the object is busy in this process; with an exception set when the reason is
 * that a fork copied it half-way through a rebind (see dk_py_method_enter), which no call
 * can use. */
static int busy_here(dk_py_method *self, int *copied_half_way)
{
    const long pid = (long)getpid();
    const unsigned long me = PyThread_get_thread_ident();
    *copied_half_way = 0;
    if (!self->busy || self->busy_pid == pid || self->busy_tid == me)
        return self->busy;
    /* Busy in another process, entered by a thread of the parent that does not exist here.
     * The fork gate (dk_py.h) guarantees that no native call on it was running at the fork
     * -- that thread was reading its inputs, waiting at the gate, or back from its native
     * call and waiting for the GIL -- unless the call stood at a progress callback, which
     * leaves the gate: then the native state is half-way through a rebind. */
    if (self->busy_paused) {
        *copied_half_way = 1;
        PyErr_Format(PyExc_RuntimeError,
                     "%s: this process was forked while a rebind of the object in another "
                     "thread stood at its progress callback; the copy here is half-way "
                     "through that rebind and cannot be used (make a new object)",
                     self->spec->name);
        return 1;
    }
    return 0; /* whole: taken over */
}

int dk_py_method_enter(dk_py_method *self)
{
    int half;
    if (busy_here(self, &half)) {
        if (half)
            return -1;
        if (self->busy_tid == PyThread_get_thread_ident())
            PyErr_Format(PyExc_RuntimeError,
                         "%s: the object is in use by a call on this same thread (this one "
                         "comes from that call's progress callback): call it after that one "
                         "has returned",
                         self->spec->name);
        else
            PyErr_Format(PyExc_RuntimeError, "%s: the object is in use by another thread",
                         self->spec->name);
        return -1;
    }
    if (!self->native) {
        PyErr_Format(PyExc_RuntimeError, "%s: the object is not bound", self->spec->name);
        return -1;
    }
    self->busy = 1;
    self->busy_pid = (long)getpid();
    self->busy_tid = PyThread_get_thread_ident();
    self->busy_paused = 0;
    return 0;
}

static void replace_ref(PyObject **slot, PyObject *value)
{
    PyObject *old = *slot;
    *slot = Py_NewRef(value ? value : Py_None);
    Py_XDECREF(old);
}

/* Constraints plus the optional per-vertex stiffness (n values). */
static int read_all(const dk_py_method_spec *spec, PyObject *handles, PyObject *fixed,
                    PyObject *roi, PyObject *hw, PyObject *stiffness, dk_index n,
                    const char *context, dk_py_lap_constraints *con, dk_py_doubles *stiff)
{
    memset(stiff, 0, sizeof *stiff);
    if (stiffness && stiffness != Py_None && !spec->takes_stiffness) {
        PyErr_Format(PyExc_ValueError,
                     "%s: stiffness is not supported by this method (its energy has no "
                     "per-vertex weight); pass None",
                     spec->name);
        return -1;
    }
    /* a method that simulates what no handle holds takes none (None or []): NULL */
    int none = 0;
    if (spec->handles_optional && handles != Py_None && PySequence_Check(handles) &&
        !PyObject_CheckBuffer(handles)) {
        const Py_ssize_t len = PySequence_Size(handles);
        if (len < 0)
            return -1;
        none = len == 0;
    }
    if (spec->handles_optional && handles == Py_None)
        none = 1;
    if (dk_py_lap_read_constraints(none ? NULL : handles, fixed, roi, hw, context, con) < 0)
        return -1;
    if (stiffness && stiffness != Py_None) {
        if (dk_py_read_doubles(stiffness, n, 0, "stiffness", stiff) < 0) {
            dk_py_lap_constraints_release(con);
            return -1;
        }
        con->desc.stiffness = stiff->data;
    }
    return 0;
}

/* Keeps an argument for rebind's defaults in `slot`: a deep copy, so that the caller
 * changing its array in place afterwards changes nothing here (rebind reads what was
 * bound); the object itself when it cannot be copied (a memoryview: read again by a later
 * rebind that leaves it out) or is the one kept already. */
static void keep(PyObject **slot, PyObject *value)
{
    if (!value || value == Py_None || value == *slot) {
        replace_ref(slot, value);
        return;
    }
    PyObject *copy = PyImport_ImportModule("copy");
    PyObject *mine = copy ? PyObject_CallMethod(copy, "deepcopy", "O", value) : NULL;
    Py_XDECREF(copy);
    if (!mine)
        PyErr_Clear();
    replace_ref(slot, mine ? mine : value);
    Py_XDECREF(mine);
}

static void remember(dk_py_method *self, PyObject *handles, PyObject *fixed, PyObject *roi,
                     PyObject *hw, PyObject *stiffness)
{
    keep(&self->handles, handles);
    keep(&self->fixed, fixed);
    keep(&self->roi, roi);
    keep(&self->handle_weights, hw);
    keep(&self->stiffness, stiffness);
}

PyObject *dk_py_method_new(PyTypeObject *type, PyObject *args, PyObject *kwargs,
                           const dk_py_method_spec *spec)
{
    static char *kwlist[] = {"mesh", "handles", "fixed", "roi", "handle_weights", "stiffness",
                             NULL};
    static char *kwlist_control[] = {"mesh", NULL};
    union {
        max_align_t align;
        unsigned char bytes[DK_PY_CONTROL_MAX];
    } control;
    PyObject *mesh_obj, *handles, *fixed = Py_None, *roi = Py_None, *hw = Py_None;
    PyObject *stiffness = Py_None, *mine = NULL, *rest = NULL;
    PyObject *module = PyType_GetModule(type);
    union {
        max_align_t align;
        unsigned char bytes[OPTIONS_MAX];
    } opt;
    dk_py_lap_constraints con;
    dk_py_doubles stiff;
    dk_py_progress prog;
    void *native = NULL;
    dk_error err = {0};
    dk_status st;
    char fmt[64], where[80];

    memset(&prog, 0, sizeof prog);
    memset(&control, 0, sizeof control);
    memset(&con, 0, sizeof con);
    memset(&stiff, 0, sizeof stiff);
    /* bound to a control only (a lattice), or to vertex groups with an optional control
     * beside them (poses: control_with_groups) */
    const int controlled = spec->parse_control != NULL && !spec->control_with_groups;

    if (!module)
        return NULL;
    if (spec->options_size > OPTIONS_MAX) {
        PyErr_Format(PyExc_SystemError, "%s: options struct too large", spec->name);
        return NULL;
    }
    snprintf(fmt, sizeof fmt,
             controlled ? "O:%s" : spec->handles_optional ? "O|OOOOO:%s" : "OO|OOOO:%s",
             spec->name);
    handles = Py_None;
    snprintf(where, sizeof where, "%s()", spec->name);
    if (split_keywords(kwargs, controlled ? kwlist_control : kwlist, &mine, &rest) < 0)
        return NULL;
    spec->default_options(&opt);
    int ok = (controlled ? PyArg_ParseTupleAndKeywords(args, mine, fmt, kwlist_control,
                                                       &mesh_obj)
                         : PyArg_ParseTupleAndKeywords(args, mine, fmt, kwlist, &mesh_obj,
                                                       &handles, &fixed, &roi, &hw,
                                                       &stiffness)) &&
             (!spec->bind_progress || dk_py_progress_take(rest, module, spec->name, &prog) == 0) &&
             spec->parse_options(rest, &opt, spec->name) == 0;
    /* mesh_obj ... borrow from `mine`, which stays alive until the end */
    const dk_mesh *mesh = ok ? dk_py_mesh_get(module, mesh_obj, "mesh") : NULL;
    ok = mesh &&
         (!spec->parse_control ||
          spec->parse_control(rest, mesh, NULL, control.bytes, spec->name) == 0) &&
         refuse_leftovers(rest, where) == 0;
    Py_DECREF(rest);
    if (ok && prog.callable)
        spec->bind_progress(&opt, &prog);
    if (ok && controlled) {
        con.desc.control = (const dk_control_desc *)control.bytes;
        handles = fixed = roi = hw = stiffness = Py_None;
    }
    if (!ok || (!controlled && read_all(spec, handles, fixed, roi, hw, stiffness,
                                        mesh->n_vertices, spec->name, &con, &stiff) < 0)) {
        if (spec->release_control)
            spec->release_control(control.bytes);
        if (spec->release_options)
            spec->release_options(&opt);
        dk_py_progress_release(&prog);
        Py_DECREF(mine);
        return NULL;
    }
    if (spec->control_with_groups && ((const dk_control_desc *)control.bytes)->kind != 0)
        con.desc.control = (const dk_control_desc *)control.bytes;
    dk_py_state *state = spec->serialise_bind ? dk_py_get_state(module) : NULL;
    /* refused before anything big is allocated when it cannot fit (issue 18 class 4) */
    uint64_t need = 0;
    st = dk_method_estimate_memory(spec->ops, mesh, &opt, &need, &err);
    if (st == DK_OK) {
        char what[96];
        snprintf(what, sizeof what, "binding %lld vertices", (long long)mesh->n_vertices);
        st = dk_memory_check(need, spec->name, what, &err);
    }
    if (st != DK_OK) {
        if (spec->release_control)
            spec->release_control(control.bytes);
        if (spec->release_options)
            spec->release_options(&opt);
        dk_py_lap_constraints_release(&con);
        dk_py_doubles_release(&stiff);
        dk_py_progress_release(&prog);
        Py_DECREF(mine);
        return dk_py_raise(&err, NULL);
    }
    if (dk_py_arpack_check(state, spec->name) < 0) {
        if (spec->release_control)
            spec->release_control(control.bytes);
        if (spec->release_options)
            spec->release_options(&opt);
        dk_py_lap_constraints_release(&con);
        dk_py_doubles_release(&stiff);
        dk_py_progress_release(&prog);
        Py_DECREF(mine);
        return NULL;
    }
    DK_PY_BEGIN_NATIVE(dk_py_get_state(module))
    if (state)
        dk_py_arpack_acquire(state);
    st = spec->ops->bind(mesh, &con.desc, &opt, &native, &err);
    if (state)
        dk_py_arpack_release(state);
    DK_PY_END_NATIVE
    if (spec->release_control)
        spec->release_control(control.bytes);
    if (spec->release_options)
        spec->release_options(&opt);
    dk_py_lap_constraints_release(&con);
    dk_py_doubles_release(&stiff);
    if (st != DK_OK) {
        Py_DECREF(mine);
        PyObject *r = dk_py_progress_raise(&prog, &err, spec->name);
        dk_py_progress_release(&prog);
        return r;
    }
    if (dk_py_progress_raised(&prog)) { /* at "done": the bind is whole, and dropped */
        spec->ops->free(native);
        dk_py_progress_release(&prog);
        Py_DECREF(mine);
        return NULL;
    }
    dk_py_progress_release(&prog);
    allocfunc alloc = (allocfunc)PyType_GetSlot(type, Py_tp_alloc);
    dk_py_method *self = alloc ? (dk_py_method *)alloc(type, 0) : NULL;
    if (!self) {
        spec->ops->free(native);
        Py_DECREF(mine);
        if (!PyErr_Occurred())
            PyErr_NoMemory();
        return NULL;
    }
    self->spec = spec;
    self->native = native;
    self->mesh = mesh;
    self->mesh_obj = Py_NewRef(mesh_obj);
    remember(self, handles, fixed, roi, hw, stiffness);
    Py_DECREF(mine);
    return (PyObject *)self;
}

static int method_traverse(PyObject *obj, visitproc visit, void *arg)
{
    dk_py_method *self = (dk_py_method *)obj;
    Py_VISIT(Py_TYPE(obj)); /* a heap type is owned by its instances */
    Py_VISIT(self->mesh_obj);
    Py_VISIT(self->handles);
    Py_VISIT(self->fixed);
    Py_VISIT(self->roi);
    Py_VISIT(self->handle_weights);
    Py_VISIT(self->stiffness);
    return 0;
}

static int method_clear(PyObject *obj)
{
    dk_py_method *self = (dk_py_method *)obj;
    /* the native object borrows the mesh: free it before the mesh can go */
    if (self->native && !self->busy) {
        self->spec->ops->free(self->native);
        self->native = NULL;
    }
    if (!self->native)
        Py_CLEAR(self->mesh_obj);
    Py_CLEAR(self->handles);
    Py_CLEAR(self->fixed);
    Py_CLEAR(self->roi);
    Py_CLEAR(self->handle_weights);
    Py_CLEAR(self->stiffness);
    return 0;
}

static void method_dealloc(PyObject *obj)
{
    dk_py_method *self = (dk_py_method *)obj;
    PyTypeObject *type = Py_TYPE(obj);
    PyObject_GC_UnTrack(obj);
    if (self->native) {
        self->spec->ops->free(self->native);
        self->native = NULL;
    }
    method_clear(obj);
    Py_CLEAR(self->mesh_obj);
    freefunc tp_free = (freefunc)PyType_GetSlot(type, Py_tp_free);
    tp_free(obj);
    Py_DECREF((PyObject *)type);
}

/* ------------------------------------------------------------------ solve -------------- */

/* The solve's control values (spec->control_values: a weight per pose), n of them, finite. */
static int read_control_values(const dk_py_method_spec *spec, PyObject *obj, dk_index n,
                               const char *ctx, dk_py_doubles *out)
{
    if (!obj || obj == Py_None) {
        PyErr_Format(PyExc_TypeError, "%s: give %s, one value for each of its %d %s", ctx,
                     spec->control_values, (int)n, spec->control_values_of);
        return -1;
    }
    if (dk_py_read_doubles(obj, n, 0, spec->control_values, out) < 0)
        return -1;
    for (Py_ssize_t k = 0; k < out->rows; k++)
        if (!isfinite(out->data[k])) {
            PyErr_Format(PyExc_ValueError, "%s: %s[%zd] is not finite", ctx, spec->control_values,
                         k);
            dk_py_doubles_release(out);
            return -1;
        }
    return 0;
}

/* Puts the control values in front of the handles' targets in `in` (one buffer, as the
 * native solve takes them); `values` is emptied. */
static int prepend_values(dk_py_doubles *values, dk_py_doubles *in)
{
    const Py_ssize_t nv = values->rows, nt = in->data ? in->rows * in->cols : 0;
    double *all = PyMem_Malloc((size_t)(nv + nt + 1) * sizeof(double));
    if (!all) {
        PyErr_NoMemory();
        return -1;
    }
    memcpy(all, values->data, (size_t)nv * sizeof(double));
    if (nt)
        memcpy(all + nv, in->data, (size_t)nt * sizeof(double));
    dk_py_doubles_release(in);
    dk_py_doubles_release(values);
    in->data = all;
    in->rows = nv + nt;
    in->cols = 1;
    in->ndim = 1;
    return 0;
}

PyObject *dk_py_method_solve(PyObject *obj, PyObject *args, PyObject *kwargs)
{
    static char *kwlist[] = {"targets", "transforms", "warm_start", "max_iterations",
                             "resume", "energy", "preview", "start_positions",
                             "input_positions", NULL};
    dk_py_method *self = (dk_py_method *)obj;
    const dk_py_method_spec *spec = self->spec;
    PyObject *targets = Py_None, *transforms = Py_None, *maxit_obj = Py_None;
    PyObject *start_obj = Py_None, *input_obj = Py_None;
    PyObject *warm_obj = Py_True, *resume_obj = Py_False, *energy_obj = Py_True,
             *preview_obj = Py_False;
    PyObject *mine = NULL, *rest = NULL, *positions, *module;
    int warm = 1, resume = 0, want_energy = 1, maxit = 0, preview = 0, mode;
    dk_py_doubles in = {0}, start = {0}, input = {0}, values = {0};
    PyObject *values_obj = NULL; /* borrowed from `rest` */
    dk_solve_info info;
    dk_method_stats ms;
    dk_error err = {0};
    dk_status st;
    double *out;
    char fmt[64], ctx[80];
    union {
        max_align_t align;
        unsigned char bytes[DK_PY_EXTRA_MAX];
    } pending, saved;

    memset(&pending, 0, sizeof pending);
    memset(&saved, 0, sizeof saved);
    snprintf(fmt, sizeof fmt, "|OOOOOOOOO:solve");
    snprintf(ctx, sizeof ctx, "%s.solve", spec->name);
    if (split_keywords(kwargs, kwlist, &mine, &rest) < 0)
        return NULL;
    int ok = PyArg_ParseTupleAndKeywords(args, mine, fmt, kwlist, &targets, &transforms,
                                         &warm_obj, &maxit_obj, &resume_obj, &energy_obj,
                                         &preview_obj, &start_obj, &input_obj) &&
             dk_py_strict_bool(warm_obj, "warm_start", ctx, &warm) == 0 &&
             dk_py_strict_bool(resume_obj, "resume", ctx, &resume) == 0 &&
             dk_py_strict_bool(energy_obj, "energy", ctx, &want_energy) == 0 &&
             dk_py_strict_bool(preview_obj, "preview", ctx, &preview) == 0;
    Py_INCREF(targets);
    Py_INCREF(transforms);
    Py_DECREF(mine);
    if (ok && maxit_obj != Py_None) {
        long v = PyLong_AsLong(maxit_obj);
        if (v == -1 && PyErr_Occurred()) {
            name_the_argument("max_iterations", maxit_obj, "an int");
            ok = 0;
        }
        else if (v < 1 || v > 1000000000L) {
            PyErr_Format(PyExc_ValueError, "%s: max_iterations is %ld, must be >= 1", ctx, v);
            ok = 0;
        } else
            maxit = (int)v;
    }
    if (ok && start_obj != Py_None && resume) {
        PyErr_Format(PyExc_ValueError, "%s: give start_positions or resume=True, not both "
                     "(a resumed solve continues from where the last one stopped)", ctx);
        ok = 0;
    }
    module = ok ? PyType_GetModule(Py_TYPE(obj)) : NULL;
    if (!module || dk_py_method_enter(self) < 0)
        goto fail;
    if (spec->solve_motion) {
        PyObject *motion = spec->solve_motion(self, rest, ctx);
        if (!motion)
            goto fail_busy;
        if (motion != Py_None) {
            if (targets != Py_None || transforms != Py_None) {
                Py_DECREF(motion);
                PyErr_Format(PyExc_TypeError, "%s: give targets, transforms, or the motion "
                             "(translation / rotation / pivot), not several", ctx);
                goto fail_busy;
            }
            Py_DECREF(transforms);
            transforms = motion;
        } else {
            Py_DECREF(motion);
        }
    }
    /* Everything is read and checked before anything changes (issue 18, class 8): the
     * method's own keywords into `pending`, applied only just before the native solve,
     * and put back if the solve fails. */
    if (spec->control_values) {
        values_obj = PyDict_GetItemString(rest, spec->control_values);
        if (values_obj) {
            Py_INCREF(values_obj);
            if (PyDict_DelItemString(rest, spec->control_values) < 0) {
                Py_CLEAR(values_obj);
                goto fail_busy;
            }
        }
    }
    if ((spec->solve_extra && spec->solve_extra(self, rest, pending.bytes, ctx) < 0) ||
        refuse_leftovers(rest, "solve()") < 0)
        goto fail_busy;
    spec->ops->stats(self->native, &ms);
    /* the control's values (a weight per pose) come before the handles' targets */
    if (spec->control_values && ms.n_controls > 0 &&
        read_control_values(spec, values_obj, ms.n_controls, ctx, &values) < 0)
        goto fail_busy;
    if (spec->control_values && ms.n_controls == 0 && values_obj && values_obj != Py_None) {
        /* bound without a control: only an empty sequence of values is accepted */
        const Py_ssize_t len = PySequence_Check(values_obj) ? PySequence_Size(values_obj) : -1;
        if (len != 0) {
            if (len < 0)
                PyErr_Clear();
            PyErr_Format(PyExc_TypeError, "%s: bound without %s, it takes no %s", ctx,
                         spec->control_values_of, spec->control_values);
            goto fail_busy;
        }
    }
    /* the targets are the control's (its points, its bones' frames), not the handles' */
    const int control_targets = ms.n_controls > 0 && !spec->control_with_groups;
    if (control_targets && !spec->control_transforms && transforms != Py_None) {
        PyErr_Format(PyExc_TypeError, "%s: takes the positions of its %d control points "
                     "(targets), not transforms", ctx, (int)ms.n_controls);
        goto fail_busy;
    }
    if (control_targets && spec->control_transforms && targets != Py_None) {
        PyErr_Format(PyExc_TypeError, "%s: takes the frames of its %d bones (transforms, "
                     "n x 4 x 4), not positions", ctx, (int)ms.n_controls);
        goto fail_busy;
    }
    if (!control_targets && ms.n_handles == 0 && targets == Py_None &&
        transforms == Py_None) { /* bound without handles (handles_optional): none to give */
        Py_DECREF(targets);
        targets = PyTuple_New(0);
        if (!targets)
            goto fail_busy;
    }
    /* a method bound to a control: its points' positions, or its bones' frames, are the
     * targets */
    if (dk_py_lap_read_solve_input(targets, transforms,
                                   control_targets
                                       ? (spec->control_transforms ? ms.n_controls : 0)
                                       : ms.n_handles,
                                   control_targets ? ms.n_controls : ms.n_handle_vertices, ctx,
                                   &in, &mode) < 0)
        goto fail_busy;
    if (values.data && prepend_values(&values, &in) < 0) {
        dk_py_doubles_release(&in);
        goto fail_busy;
    }
    if (start_obj != Py_None) { /* read and checked for every method, used by some */
        if (dk_py_read_doubles(start_obj, self->mesh->n_vertices, 3, "start_positions",
                               &start) < 0) {
            dk_py_doubles_release(&in);
            goto fail_busy;
        }
        for (Py_ssize_t k = 0; k < 3 * start.rows; k++)
            if (!isfinite(start.data[k])) {
                PyErr_Format(PyExc_ValueError, "%s: start_positions of vertex %zd are not "
                             "finite", ctx, k / 3);
                dk_py_doubles_release(&in);
                dk_py_doubles_release(&start);
                goto fail_busy;
            }
    }
    if (input_obj != Py_None && /* the native solve checks the values */
        dk_py_read_doubles(input_obj, self->mesh->n_vertices, 3, "input_positions",
                           &input) < 0) {
        dk_py_doubles_release(&in);
        dk_py_doubles_release(&start);
        goto fail_busy;
    }
    positions = dk_py_new_doubles(2, self->mesh->n_vertices, 3, &out);
    if (!positions) {
        dk_py_doubles_release(&in);
        dk_py_doubles_release(&start);
        dk_py_doubles_release(&input);
        goto fail_busy;
    }
    static const double no_targets[1] = {0.0}; /* a bind without handles: none, not NULL */
    const dk_solve_request rq = {
        .targets = in.data ? in.data : no_targets,
        .target_kind = (dk_target_kind)mode,
        .start = start.data ? DK_START_GIVEN
                 : resume   ? DK_START_RESUME
                 : warm     ? DK_START_WARM
                            : DK_START_COLD,
        .start_positions = start.data,
        .input_positions = input.data,
        .max_iterations = maxit,
        .skip_energy = !want_energy,
        .preview = preview,
    };
    if (spec->apply_extra)
        spec->apply_extra(self, pending.bytes, saved.bytes);
    DK_PY_BEGIN_NATIVE(dk_py_get_state(module))
    st = spec->ops->solve(self->native, &rq, out, &info, &err);
    DK_PY_END_NATIVE
    if (st != DK_OK && spec->apply_extra)
        spec->apply_extra(self, saved.bytes, NULL); /* the call raised: put it back */
    dk_py_doubles_release(&in);
    dk_py_doubles_release(&start);
    dk_py_doubles_release(&input);
    dk_py_doubles_release(&values);
    Py_XDECREF(values_obj);
    self->busy = 0;
    Py_DECREF(rest);
    Py_DECREF(targets);
    Py_DECREF(transforms);
    if (st != DK_OK) {
        Py_DECREF(positions);
        return dk_py_raise(&err, ctx);
    }
    return dk_py_new_solve_result(module, positions, info.energy, info.iterations,
                                  info.converged);
fail_busy:
    self->busy = 0;
fail:
    dk_py_doubles_release(&values);
    Py_XDECREF(values_obj);
    Py_XDECREF(rest);
    Py_DECREF(targets);
    Py_DECREF(transforms);
    return NULL;
}

/* ------------------------------------------------------------------ estimate_memory ---- */

PyObject *dk_py_method_estimate_memory(PyObject *cls, PyObject *args, PyObject *kwargs)
{
    static char *kwlist[] = {"mesh", NULL};
    PyObject *module = PyType_GetModule((PyTypeObject *)cls);
    dk_py_state *state = module ? dk_py_get_state(module) : NULL;
    const dk_py_method_spec *spec = NULL;
    PyObject *mine = NULL, *rest = NULL, *mesh_obj;
    union {
        max_align_t align;
        unsigned char bytes[OPTIONS_MAX];
    } opt;
    dk_error err = {0};
    uint64_t bytes = 0;
    char where[80];

    if (!state)
        return NULL;
    for (int i = 0; i < state->n_method_types; i++)
        if (state->method_type[i] == (const void *)cls)
            spec = state->method_spec[i];
    if (!spec) {
        PyErr_SetString(PyExc_TypeError, "estimate_memory: not a deformkit method class");
        return NULL;
    }
    snprintf(where, sizeof where, "%s.estimate_memory()", spec->name);
    if (split_keywords(kwargs, kwlist, &mine, &rest) < 0)
        return NULL;
    spec->default_options(&opt);
    dk_py_progress prog; /* progress= is a bind keyword too: accepted, not called */
    memset(&prog, 0, sizeof prog);
    int ok = PyArg_ParseTupleAndKeywords(args, mine, "O:estimate_memory", kwlist, &mesh_obj) &&
             (!spec->bind_progress || dk_py_progress_take(rest, module, where, &prog) == 0) &&
             spec->parse_options(rest, &opt, spec->name) == 0 &&
             refuse_leftovers(rest, where) == 0;
    if (spec->bind_progress)
        dk_py_progress_release(&prog);
    const dk_mesh *mesh = ok ? dk_py_mesh_get(module, mesh_obj, "mesh") : NULL;
    dk_status st = mesh ? dk_method_estimate_memory(spec->ops, mesh, &opt, &bytes, &err)
                        : DK_OK;
    if (spec->release_options)
        spec->release_options(&opt);
    Py_DECREF(mine);
    Py_DECREF(rest);
    if (!mesh)
        return NULL;
    if (st != DK_OK)
        return dk_py_raise(&err, where);
    return PyLong_FromUnsignedLongLong((unsigned long long)bytes);
}

const char dk_py_method_estimate_memory_doc[] =
             "estimate_memory(mesh, **options) -> int (classmethod)\n\n"
             "The bytes a bind of this method on `mesh` with these options (the\n"
             "constructor's own keywords) needs at its peak, first solve included: a model\n"
             "fitted to measured peak RSS (docs/benchmarks.md, Memory). A bind whose estimate\n"
             "does not fit deformkit.available_memory() is refused with MemoryError before\n"
             "allocating; so is a factorization whose exact size (from the symbolic\n"
             "analysis) does not.";

/* ------------------------------------------------------------------ rebind, energy ----- */

/* rebind(**control keywords) of a method bound to a control: another control for the same
 * mesh and options; on error the previous one stays. */
static PyObject *control_rebind(dk_py_method *self, PyObject *args, PyObject *kwargs)
{
    char ctx[80];
    union {
        max_align_t align;
        unsigned char bytes[DK_PY_CONTROL_MAX];
    } control;
    dk_error err = {0};
    snprintf(ctx, sizeof ctx, "%s.rebind", self->spec->name);
    memset(&control, 0, sizeof control);
    if (args && PyTuple_Size(args) > 0) {
        PyErr_Format(PyExc_TypeError, "%s: takes keywords only (the control's)", ctx);
        return NULL;
    }
    PyObject *kw = kwargs ? PyDict_Copy(kwargs) : PyDict_New();
    if (!kw)
        return NULL;
    if (dk_py_method_enter(self) < 0) {
        Py_DECREF(kw);
        return NULL;
    }
    if (self->spec->parse_control(kw, self->mesh, self->native, control.bytes, ctx) < 0 ||
        refuse_leftovers(kw, ctx) < 0) {
        if (self->spec->release_control)
            self->spec->release_control(control.bytes);
        self->busy = 0;
        Py_DECREF(kw);
        return NULL;
    }
    Py_DECREF(kw);
    dk_constraint_desc desc;
    memset(&desc, 0, sizeof desc);
    desc.control = (const dk_control_desc *)control.bytes;
    dk_status st;
    DK_PY_BEGIN_NATIVE(dk_py_state_of((PyObject *)self))
    st = self->spec->ops->rebind(self->native, &desc, &err);
    DK_PY_END_NATIVE
    if (self->spec->release_control)
        self->spec->release_control(control.bytes);
    self->busy = 0;
    if (st != DK_OK)
        return dk_py_raise(&err, ctx);
    Py_RETURN_NONE;
}

PyObject *dk_py_method_rebind(PyObject *obj, PyObject *args, PyObject *kwargs)
{
    if (((dk_py_method *)obj)->spec->parse_control &&
        !((dk_py_method *)obj)->spec->control_with_groups)
        return control_rebind((dk_py_method *)obj, args, kwargs);
    static char *kwlist[] = {"handles", "fixed", "roi", "handle_weights", "stiffness", NULL};
    dk_py_method *self = (dk_py_method *)obj;
    PyObject *handles = NULL, *fixed = NULL, *roi = NULL, *hw = NULL, *stiffness = NULL;
    PyObject *kw = NULL;
    dk_py_lap_constraints con;
    dk_py_doubles stiff;
    dk_py_progress prog;
    dk_error err = {0};
    dk_status st;
    char ctx[80];

    union {
        max_align_t align;
        unsigned char bytes[DK_PY_CONTROL_MAX];
    } control;
    memset(&control, 0, sizeof control);
    snprintf(ctx, sizeof ctx, "%s.rebind", self->spec->name);
    memset(&prog, 0, sizeof prog);
    /* the control's keywords beside the groups (control_with_groups): taken out first;
     * absent, the bound control stays */
    if (kwargs && self->spec->control_with_groups) {
        if (!dk_py_method_readable(self)) /* the control is read for the bound mesh */
            return NULL;
        kw = PyDict_Copy(kwargs);
        if (!kw || self->spec->parse_control(kw, self->mesh, NULL, control.bytes, ctx) < 0) {
            if (self->spec->release_control)
                self->spec->release_control(control.bytes);
            Py_XDECREF(kw);
            return NULL;
        }
        kwargs = kw;
    }
    /* progress=: only for a method whose rebind reports (else a TypeError, as any unknown
     * keyword) */
    if (kwargs && self->spec->rebind_progress && PyDict_GetItemString(kwargs, "progress")) {
        PyObject *module = PyType_GetModule(Py_TYPE(obj));
        if (!kw)
            kw = PyDict_Copy(kwargs);
        if (!kw || !module || dk_py_progress_take(kw, module, ctx, &prog) < 0) {
            if (self->spec->release_control)
                self->spec->release_control(control.bytes);
            Py_XDECREF(kw);
            return NULL;
        }
        kwargs = kw;
    }
    if (!PyArg_ParseTupleAndKeywords(args, kwargs, "|OOOOO:rebind", kwlist, &handles, &fixed,
                                     &roi, &hw, &stiffness)) {
        if (self->spec->release_control)
            self->spec->release_control(control.bytes);
        Py_XDECREF(kw);
        dk_py_progress_release(&prog);
        return NULL;
    }
    if (!handles)
        handles = self->handles;
    if (!fixed)
        fixed = self->fixed;
    if (!roi)
        roi = self->roi;
    if (!hw)
        hw = handles == self->handles ? self->handle_weights : Py_None;
    if (!stiffness)
        stiffness = self->stiffness;
    /* handles ... borrow from `kw` (when copied), which lives until the end */
    PyObject *result = NULL;
    if (dk_py_method_enter(self) < 0)
        goto out;
    if (read_all(self->spec, handles, fixed, roi, hw, stiffness, self->mesh->n_vertices, ctx,
                 &con, &stiff) < 0) {
        self->busy = 0;
        goto out;
    }
    if (prog.callable) {
        prog.paused = &self->busy_paused;
        self->spec->rebind_progress(self->native, &prog);
    }
    if (((const dk_control_desc *)control.bytes)->kind != 0)
        con.desc.control = (const dk_control_desc *)control.bytes;
    DK_PY_BEGIN_NATIVE(dk_py_state_of(obj))
    st = self->spec->ops->rebind(self->native, &con.desc, &err);
    DK_PY_END_NATIVE
    if (prog.callable)
        self->spec->rebind_progress(self->native, NULL);
    dk_py_lap_constraints_release(&con);
    dk_py_doubles_release(&stiff);
    /* kept while still busy: the copies run Python, and some of these arguments are
     * borrowed from the kept ones, which no other call may replace meanwhile */
    if (st == DK_OK)
        remember(self, handles, fixed, roi, hw, stiffness);
    self->busy = 0;
    if (st != DK_OK) {
        result = dk_py_progress_raise(&prog, &err, ctx);
        goto out;
    }
    /* raised at "done": the rebind is complete (its new constraints stay), the error goes up */
    result = dk_py_progress_raised(&prog) ? NULL : Py_NewRef(Py_None);
out:
    if (self->spec->release_control)
        self->spec->release_control(control.bytes);
    dk_py_progress_release(&prog);
    Py_XDECREF(kw);
    return result;
}

const char dk_py_method_rebind_doc[] =
             "rebind(handles=None, fixed=None, roi=None, handle_weights=None, stiffness=None)\n\n"
             "Changes the constraints (and stiffness, where the method takes it); arguments\n"
             "not given keep their bound value (pass an empty list for fixed to clear it;\n"
             "new handles without handle_weights get weight 1). What can be kept is kept:\n"
             "the symbolic analysis when the set of unknowns is unchanged, the previous\n"
             "solution as warm start. On error the previous constraints stay bound.\n"
             "progress=callable(fraction) (all but EigenDeformation): as the constructor's; a\n"
             "cancelled rebind keeps the previous constraints exactly.";

PyObject *dk_py_method_energy(PyObject *obj, PyObject *arg)
{
    dk_py_method *self = (dk_py_method *)obj;
    dk_py_doubles x = {0};
    dk_error err = {0};
    double e = NAN;
    dk_status st;
    char ctx[80];

    snprintf(ctx, sizeof ctx, "%s.energy", self->spec->name);
    if (dk_py_method_enter(self) < 0)
        return NULL;
    if (dk_py_read_doubles(arg, self->mesh->n_vertices, 3, "positions", &x) < 0) {
        self->busy = 0;
        return NULL;
    }
    for (Py_ssize_t k = 0; k < 3 * x.rows; k++)
        if (!isfinite(x.data[k])) {
            PyErr_Format(PyExc_ValueError, "%s: positions of vertex %zd are not finite", ctx,
                         k / 3);
            dk_py_doubles_release(&x);
            self->busy = 0;
            return NULL;
        }
    DK_PY_BEGIN_NATIVE(dk_py_state_of(obj))
    st = self->spec->ops->energy(self->native, x.data, &e, &err);
    DK_PY_END_NATIVE
    dk_py_doubles_release(&x);
    self->busy = 0;
    if (st != DK_OK)
        return dk_py_raise(&err, ctx);
    return PyFloat_FromDouble(e);
}

const char dk_py_method_energy_doc[] =
             "energy(positions) -> float\n\n"
             "The method's energy of arbitrary n x 3 (finite) positions, for the handle\n"
             "targets of the last solve (before any solve: the rest targets); the value a\n"
             "solve reports for its own result.";

/* ------------------------------------------------------------------ state -------------- */

/* 1 when the method carries state; else 0 with TypeError set. */
static int has_state(dk_py_method *self, const char *verb)
{
    if (self->spec->ops->state_size)
        return 1;
    PyErr_Format(PyExc_TypeError,
                 "%s.%s: %s carries no state from solve to solve (each solve depends on its "
                 "request alone): there is nothing to save or restore",
                 self->spec->name, verb, self->spec->name);
    return 0;
}

PyObject *dk_py_method_save_state(PyObject *obj, PyObject *unused)
{
    dk_py_method *self = (dk_py_method *)obj;
    dk_error err = {0};
    char ctx[80];
    (void)unused;
    snprintf(ctx, sizeof ctx, "%s.save_state", self->spec->name);
    if (!has_state(self, "save_state") || dk_py_method_enter(self) < 0)
        return NULL;
    const size_t size = self->spec->ops->state_size(self->native);
    PyObject *out = PyBytes_FromStringAndSize(NULL, (Py_ssize_t)size);
    if (!out) {
        self->busy = 0;
        return NULL;
    }
    char *buf = PyBytes_AsString(out);
    dk_status st = buf ? DK_OK : DK_ERR_INVALID_ARGUMENT;
    if (buf) {
        DK_PY_BEGIN_NATIVE(dk_py_state_of(obj))
        st = self->spec->ops->save_state(self->native, buf, size, &err);
        DK_PY_END_NATIVE
    }
    self->busy = 0;
    if (!buf) {
        Py_DECREF(out);
        return NULL;
    }
    if (st != DK_OK) {
        Py_DECREF(out);
        return dk_py_raise(&err, ctx);
    }
    return out;
}

const char dk_py_method_save_state_doc[] =
             "save_state() -> bytes\n\n"
             "What the solves left for the next call -- a warm start's iterate and history,\n"
             "a resumable solve's place, the pose and targets last solved -- for\n"
             "restore_state: a bake's checkpoint, or the start of a chunk of a shot in\n"
             "another process. Methods whose solves depend on their request alone\n"
             "(_method_info(name)['state'] False) raise TypeError.";

PyObject *dk_py_method_restore_state(PyObject *obj, PyObject *arg)
{
    dk_py_method *self = (dk_py_method *)obj;
    dk_error err = {0};
    char ctx[80];
    Py_buffer view;
    snprintf(ctx, sizeof ctx, "%s.restore_state", self->spec->name);
    if (!has_state(self, "restore_state"))
        return NULL;
    if (PyObject_GetBuffer(arg, &view, PyBUF_SIMPLE) < 0)
        return NULL;
    if (dk_py_method_enter(self) < 0) {
        PyBuffer_Release(&view);
        return NULL;
    }
    dk_status st;
    DK_PY_BEGIN_NATIVE(dk_py_state_of(obj))
    st = self->spec->ops->restore_state(self->native, view.buf, (size_t)view.len, &err);
    DK_PY_END_NATIVE
    self->busy = 0;
    PyBuffer_Release(&view);
    if (st != DK_OK)
        return dk_py_raise(&err, ctx);
    Py_RETURN_NONE;
}

const char dk_py_method_restore_state_doc[] =
             "restore_state(state)\n\n"
             "Puts back what save_state() returned (any buffer of its bytes), into this\n"
             "object or another bound on the same mesh with the same constraints and\n"
             "options: every solve after it returns, bit for bit, what it would have\n"
             "returned right after the save. A state saved by another method, mesh size,\n"
             "constraints or options raises ValueError and changes nothing.";

/* ------------------------------------------------------------------ getters ------------ */

/* Whether the object still has its native part (the garbage collector's tp_clear frees it
 * when the object is in a cycle; anything that reaches the object afterwards gets an
 * error instead of a NULL dereference). 0 with RuntimeError set when not. */
PyObject *dk_py_method_map_n3(PyObject *obj, PyObject *in_obj, const char *arg,
                              const char *context, dk_py_map_fn fn)
{
    dk_py_method *self = (dk_py_method *)obj;
    dk_py_doubles in = {0};
    dk_error err = {0};
    double *out;
    if (dk_py_method_enter(self) < 0)
        return NULL;
    if (in_obj != Py_None &&
        dk_py_read_doubles(in_obj, self->mesh->n_vertices, 3, arg, &in) < 0) {
        self->busy = 0;
        return NULL;
    }
    PyObject *res = dk_py_new_doubles(2, self->mesh->n_vertices, 3, &out);
    dk_status st = DK_OK;
    if (res) {
        DK_PY_BEGIN_NATIVE(dk_py_state_of(obj))
        st = fn(self->native, in.data, out, &err);
        DK_PY_END_NATIVE
    }
    dk_py_doubles_release(&in);
    self->busy = 0;
    if (res && st != DK_OK) {
        Py_DECREF(res);
        return dk_py_raise(&err, context);
    }
    return res;
}

int dk_py_method_readable(dk_py_method *self)
{
    if (!self->native || !self->mesh_obj) {
        PyErr_Format(PyExc_RuntimeError, "%s: the object is not bound (it was cleared by the "
                     "garbage collector)", self->spec->name);
        return 0;
    }
    /* busy in another process: taken over as dk_py_method_enter does */
    int half;
    if (busy_here(self, &half)) {
        if (half)
            return 0;
        if (self->busy_tid == PyThread_get_thread_ident())
            PyErr_Format(PyExc_RuntimeError, "%s: the object is in use by a call on this same "
                         "thread (a solve or rebind whose progress callback this is); read it "
                         "when that call has returned",
                         self->spec->name);
        else
            PyErr_Format(PyExc_RuntimeError, "%s: the object is in use by another thread (a "
                         "solve or rebind is running); read it when that call has returned",
                         self->spec->name);
        return 0;
    }
    return 1;
}

static int still_bound(dk_py_method *self)
{
    return dk_py_method_readable(self);
}

PyObject *dk_py_method_get_mesh(PyObject *obj, void *c)
{
    dk_py_method *self = (dk_py_method *)obj;
    (void)c;
    return Py_NewRef(self->mesh_obj ? self->mesh_obj : Py_None);
}

PyObject *dk_py_method_get_n_vertices(PyObject *obj, void *c)
{
    (void)c;
    if (!still_bound((dk_py_method *)obj))
        return NULL;
    return PyLong_FromSsize_t((Py_ssize_t)((dk_py_method *)obj)->mesh->n_vertices);
}

PyObject *dk_py_method_get_n_handles(PyObject *obj, void *c)
{
    dk_py_method *self = (dk_py_method *)obj;
    dk_method_stats ms;
    (void)c;
    if (!still_bound(self))
        return NULL;
    self->spec->ops->stats(self->native, &ms);
    return PyLong_FromSsize_t((Py_ssize_t)ms.n_handles);
}

PyObject *dk_py_method_get_n_handle_vertices(PyObject *obj, void *c)
{
    dk_py_method *self = (dk_py_method *)obj;
    dk_method_stats ms;
    (void)c;
    if (!still_bound(self))
        return NULL;
    self->spec->ops->stats(self->native, &ms);
    return PyLong_FromSsize_t((Py_ssize_t)ms.n_handle_vertices);
}

PyObject *dk_py_method_get_stats(PyObject *obj, void *c)
{
    dk_py_method *self = (dk_py_method *)obj;
    dk_method_stats ms;
    (void)c;
    if (!still_bound(self))
        return NULL;
    self->spec->ops->stats(self->native, &ms);
    PyObject *d = self->spec->stats
                      ? self->spec->stats(self)
                      : Py_BuildValue("{s:n,s:i,s:i}", "n_unknowns", (Py_ssize_t)ms.n_unknowns,
                                      "analysis_count", ms.analysis_count,
                                      "factorization_count", ms.factorization_count);
    if (!d)
        return NULL;
    /* every method: what the shared constraint layer held at rest (loose geometry) */
    PyObject *a = PyLong_FromSsize_t((Py_ssize_t)ms.n_held);
    PyObject *b = PyLong_FromSsize_t((Py_ssize_t)ms.n_held_components);
    if (!a || !b || PyDict_SetItemString(d, "n_held", a) < 0 ||
        PyDict_SetItemString(d, "n_held_components", b) < 0) {
        Py_XDECREF(a);
        Py_XDECREF(b);
        Py_DECREF(d);
        return NULL;
    }
    Py_DECREF(a);
    Py_DECREF(b);
    if (ms.n_controls > 0) { /* a method bound to a control: its points */
        PyObject *k = PyLong_FromSsize_t((Py_ssize_t)ms.n_controls);
        if (!k || PyDict_SetItemString(d, "n_controls", k) < 0) {
            Py_XDECREF(k);
            Py_DECREF(d);
            return NULL;
        }
        Py_DECREF(k);
    }
    return d;
}

/* Appends msg (a new reference, NULL on failure) to the list; -1 on failure. */
static int append_warning(PyObject *list, PyObject *msg)
{
    if (!msg)
        return -1;
    const int rc = PyList_Append(list, msg);
    Py_DECREF(msg);
    return rc;
}

/* What the bound object's stats say the user should know: loose geometry held at rest, and
 * a deformation graph denser than its mesh (floppy: its inner vertices can lag behind the
 * handles even at a small energy; docs/methods/embedded.md, "Edges"). */
PyObject *dk_py_method_get_warnings(PyObject *obj, void *c)
{
    dk_py_method *self = (dk_py_method *)obj;
    dk_method_stats ms;
    (void)c;
    if (!still_bound(self))
        return NULL;
    self->spec->ops->stats(self->native, &ms);
    PyObject *list = PyList_New(0);
    if (!list)
        return NULL;
    if (ms.n_held > 0 &&
        append_warning(list, PyUnicode_FromFormat(
            "%zd %s in %zd connected component%s with no handle or fixed vertex %s held at "
            "rest (first: vertex %zd); constrain a vertex there to move %s",
            (Py_ssize_t)ms.n_held, ms.n_held == 1 ? "vertex" : "vertices",
            (Py_ssize_t)ms.n_held_components, ms.n_held_components == 1 ? "" : "s",
            ms.n_held == 1 ? "is" : "are", (Py_ssize_t)ms.first_held,
            ms.n_held_components == 1 ? "it" : "them")) < 0)
        goto fail;
    if (ms.n_graph_nodes > ms.n_vertices &&
        append_warning(list, PyUnicode_FromFormat(
            "the deformation graph has %zd nodes for %zd vertices: a graph denser than its "
            "mesh is floppy, and vertices between the handles can lag behind them; use fewer "
            "nodes (a smaller n_nodes or a larger radius)",
            (Py_ssize_t)ms.n_graph_nodes, (Py_ssize_t)ms.n_vertices)) < 0)
        goto fail;
    PyObject *t = PyList_AsTuple(list);
    Py_DECREF(list);
    return t;
fail:
    Py_DECREF(list);
    return NULL;
}

/* ------------------------------------------------------------------ registration ------- */

int dk_py_method_register(PyObject *module, const dk_py_method_spec *spec, newfunc tp_new)
{
    PyType_Slot slots[] = {
        {Py_tp_new, (void *)tp_new},
        {Py_tp_dealloc, (void *)method_dealloc},
        {Py_tp_traverse, (void *)method_traverse},
        {Py_tp_clear, (void *)method_clear},
        {Py_tp_getset, spec->getset},
        {Py_tp_methods, spec->methods},
        {Py_tp_doc, (void *)spec->doc},
        {0, NULL},
    };
    PyType_Spec type_spec = {
        spec->type_name,
        (int)sizeof(dk_py_method),
        0,
        Py_TPFLAGS_DEFAULT | Py_TPFLAGS_IMMUTABLETYPE | Py_TPFLAGS_HAVE_GC,
        slots,
    };
    PyObject *type = PyType_FromModuleAndSpec(module, &type_spec, NULL);
    if (!type)
        return -1;
    dk_py_state *state = dk_py_get_state(module);
    if (state && state->n_method_types < 16) {
        state->method_type[state->n_method_types] = type;
        state->method_spec[state->n_method_types] = spec;
        state->n_method_types++;
    }
    int r = PyModule_AddObjectRef(module, spec->name, type);
    Py_DECREF(type);
    return r;
}
