/* DeformKit CPython module: deformkit.LaplacianEdit (native/methods/dk_laplacian_edit.h).
 *
 * The constructor binds (operator, deltas, factorization) with the GIL released; solve()
 * runs the back-substitutions with the GIL released. The object keeps the Mesh alive and
 * remembers the constraint keywords so that rebind() may change only some of them. One call
 * at a time per object: a second thread calling while the first runs gets RuntimeError
 * (the native object reuses its buffers). */
#include "dk_py.h"
#include "dk_py_lap.h"

#include <string.h>

#include "dk_laplacian_edit.h"

typedef struct LapObject {
    PyObject_HEAD
    PyObject *mesh_obj;
    const dk_mesh *mesh;
    dk_laplacian_edit *le;
    PyObject *handles, *fixed, *roi, *handle_weights; /* as last bound (owned refs)        */
    int busy;
} LapObject;

static const char *const weights_names[] = {"uniform", "cotangent", NULL};
static const char *const detail_names[] = {"fixed", "membrane", "local_frame", NULL};
static const char *const constraint_names[] = {"hard", "soft", NULL};

static int enter(LapObject *self)
{
    if (self->busy) {
        PyErr_SetString(PyExc_RuntimeError,
                        "LaplacianEdit: the object is in use by another thread");
        return -1;
    }
    if (!self->le) {
        PyErr_SetString(PyExc_RuntimeError, "LaplacianEdit: the object is not bound");
        return -1;
    }
    self->busy = 1;
    return 0;
}

static void replace_ref(PyObject **slot, PyObject *value)
{
    PyObject *old = *slot;
    *slot = Py_NewRef(value ? value : Py_None);
    Py_XDECREF(old);
}

static void remember(LapObject *self, PyObject *handles, PyObject *fixed, PyObject *roi,
                     PyObject *weights)
{
    replace_ref(&self->handles, handles);
    replace_ref(&self->fixed, fixed);
    replace_ref(&self->roi, roi);
    replace_ref(&self->handle_weights, weights);
}

static PyObject *lap_new(PyTypeObject *type, PyObject *args, PyObject *kwargs)
{
    static char *kwlist[] = {"mesh", "handles", "fixed", "roi", "handle_weights", "stiffness",
                             "weights", "detail", "constraints", "constraint_weight",
                             "tikhonov", "local_frame_iterations", "local_frame_tolerance",
                             NULL};
    PyObject *mesh_obj, *handles, *fixed = Py_None, *roi = Py_None, *hw = Py_None;
    PyObject *stiffness = Py_None, *weights = NULL, *detail = NULL, *constraints = NULL;
    PyObject *module = PyType_GetModule(type);
    dk_laplacian_edit_options opt;
    dk_py_lap_constraints con;
    dk_laplacian_edit *le = NULL;
    dk_error err = {0};
    dk_status st;
    const dk_mesh *mesh;
    LapObject *self;
    allocfunc alloc;
    int c;

    if (!module)
        return NULL;
    dk_laplacian_edit_default_options(&opt);
    if (!PyArg_ParseTupleAndKeywords(args, kwargs, "OO|OOOOOOOddid:LaplacianEdit", kwlist,
                                     &mesh_obj, &handles, &fixed, &roi, &hw, &stiffness,
                                     &weights, &detail, &constraints, &opt.constraint_weight,
                                     &opt.tikhonov, &opt.local_frame_iterations,
                                     &opt.local_frame_tolerance))
        return NULL;
    mesh = dk_py_mesh_get(module, mesh_obj, "mesh");
    if (!mesh)
        return NULL;
    if (stiffness != Py_None) {
        PyErr_SetString(PyExc_ValueError,
                        "LaplacianEdit: stiffness is not supported by Laplacian editing (its "
                        "energy has no per-vertex regulariser weight); pass None");
        return NULL;
    }
    if (weights && (c = dk_py_lap_choice(weights, "weights", weights_names, "LaplacianEdit")) < 0)
        return NULL;
    else if (weights)
        opt.weights = (dk_le_weights)c;
    if (detail && (c = dk_py_lap_choice(detail, "detail", detail_names, "LaplacianEdit")) < 0)
        return NULL;
    else if (detail)
        opt.detail = (dk_le_detail)c;
    if (constraints &&
        (c = dk_py_lap_choice(constraints, "constraints", constraint_names, "LaplacianEdit")) < 0)
        return NULL;
    else if (constraints)
        opt.constraints = (dk_le_constraint_mode)c;
    if (dk_py_lap_read_constraints(handles, fixed, roi, hw, "LaplacianEdit", &con) < 0)
        return NULL;
    Py_BEGIN_ALLOW_THREADS
    st = dk_laplacian_edit_bind(mesh, &con.desc, &opt, &le, &err);
    Py_END_ALLOW_THREADS
    dk_py_lap_constraints_release(&con);
    if (st != DK_OK)
        return dk_py_raise(&err, "LaplacianEdit");
    alloc = (allocfunc)PyType_GetSlot(type, Py_tp_alloc);
    self = alloc ? (LapObject *)alloc(type, 0) : NULL;
    if (!self) {
        dk_laplacian_edit_free(le);
        if (!PyErr_Occurred())
            PyErr_NoMemory();
        return NULL;
    }
    self->le = le;
    self->mesh = mesh;
    self->mesh_obj = Py_NewRef(mesh_obj);
    remember(self, handles, fixed, roi, hw);
    return (PyObject *)self;
}

static void lap_dealloc(PyObject *obj)
{
    LapObject *self = (LapObject *)obj;
    PyTypeObject *type = Py_TYPE(obj);
    freefunc tp_free = (freefunc)PyType_GetSlot(type, Py_tp_free);
    dk_laplacian_edit_free(self->le);
    self->le = NULL;
    Py_CLEAR(self->mesh_obj);
    Py_CLEAR(self->handles);
    Py_CLEAR(self->fixed);
    Py_CLEAR(self->roi);
    Py_CLEAR(self->handle_weights);
    tp_free(obj);
    Py_DECREF((PyObject *)type);
}

PyDoc_STRVAR(solve_doc,
             "solve(targets=None, transforms=None, energy=True) -> SolveResult\n\n"
             "targets: (sum of handle sizes) x 3 positions, concatenated in handle order;\n"
             "transforms: n_handles x 4 x 4 affine transforms of the rest pose. Returns the\n"
             "deformed positions, the energy ||A x - delta||^2 (+ soft and Tikhonov terms) at\n"
             "them, the number of linear solves and whether the local-frame iteration met\n"
             "its tolerance (always True for 'fixed' and 'membrane'). energy=False skips the\n"
             "energy (result.energy is nan): one pass over the operator less, for interactive\n"
             "updates that never show it.");

static PyObject *lap_solve(PyObject *obj, PyObject *args, PyObject *kwargs)
{
    static char *kwlist[] = {"targets", "transforms", "energy", NULL};
    LapObject *self = (LapObject *)obj;
    int want_energy = 1;
    PyObject *targets = Py_None, *transforms = Py_None, *positions, *module;
    dk_py_doubles in = {0};
    dk_solve_info info;
    dk_method_stats ms;
    dk_error err = {0};
    dk_status st;
    double *out;
    int mode;

    if (!PyArg_ParseTupleAndKeywords(args, kwargs, "|OOp:solve", kwlist, &targets, &transforms,
                                     &want_energy))
        return NULL;
    module = PyType_GetModule(Py_TYPE(obj));
    if (!module || enter(self) < 0)
        return NULL;
    dk_laplacian_edit_stats(self->le, &ms);
    if (dk_py_lap_read_solve_input(targets, transforms, ms.n_handles, ms.n_handle_vertices,
                                   "LaplacianEdit.solve", &in, &mode) < 0) {
        self->busy = 0;
        return NULL;
    }
    positions = dk_py_new_doubles(2, self->mesh->n_vertices, 3, &out);
    if (!positions) {
        dk_py_doubles_release(&in);
        self->busy = 0;
        return NULL;
    }
    const dk_solve_request rq = {.targets = in.data,
                                 .target_kind = (dk_target_kind)mode,
                                 .skip_energy = !want_energy};
    Py_BEGIN_ALLOW_THREADS
    st = dk_laplacian_edit_solve(self->le, &rq, out, &info, &err);
    Py_END_ALLOW_THREADS
    dk_py_doubles_release(&in);
    self->busy = 0;
    if (st != DK_OK) {
        Py_DECREF(positions);
        return dk_py_raise(&err, "LaplacianEdit.solve");
    }
    return dk_py_new_solve_result(module, positions, info.energy, info.iterations,
                                  info.converged);
}

PyDoc_STRVAR(rebind_doc,
             "rebind(handles=None, fixed=None, roi=None, handle_weights=None)\n\n"
             "Changes the constraint sets; arguments not given keep their bound value (pass\n"
             "an empty list for fixed to clear it). The operator and rest deltas are kept;\n"
             "the symbolic analysis (and the factor) is reused when the set of unknowns is\n"
             "unchanged. On error the previous constraints stay bound.");

static PyObject *lap_rebind(PyObject *obj, PyObject *args, PyObject *kwargs)
{
    static char *kwlist[] = {"handles", "fixed", "roi", "handle_weights", NULL};
    LapObject *self = (LapObject *)obj;
    PyObject *handles = NULL, *fixed = NULL, *roi = NULL, *hw = NULL;
    dk_py_lap_constraints con;
    dk_error err = {0};
    dk_status st;

    if (!PyArg_ParseTupleAndKeywords(args, kwargs, "|OOOO:rebind", kwlist, &handles, &fixed,
                                     &roi, &hw))
        return NULL;
    if (!handles)
        handles = self->handles;
    if (!fixed)
        fixed = self->fixed;
    if (!roi)
        roi = self->roi;
    if (!hw)
        hw = handles == self->handles ? self->handle_weights : Py_None;
    if (enter(self) < 0)
        return NULL;
    if (dk_py_lap_read_constraints(handles, fixed, roi, hw, "LaplacianEdit.rebind", &con) < 0) {
        self->busy = 0;
        return NULL;
    }
    Py_BEGIN_ALLOW_THREADS
    st = dk_laplacian_edit_rebind(self->le, &con.desc, &err);
    Py_END_ALLOW_THREADS
    dk_py_lap_constraints_release(&con);
    self->busy = 0;
    if (st != DK_OK)
        return dk_py_raise(&err, "LaplacianEdit.rebind");
    remember(self, handles, fixed, roi, hw);
    Py_RETURN_NONE;
}

PyDoc_STRVAR(energy_doc,
             "energy(positions) -> float\n\n"
             "The energy of arbitrary n x 3 positions with the handle targets and deltas of\n"
             "the last solve (for checking optimality).");

static PyObject *lap_energy(PyObject *obj, PyObject *arg)
{
    LapObject *self = (LapObject *)obj;
    dk_py_doubles x = {0};
    dk_error err = {0};
    double e = 0.0;
    dk_status st;
    if (enter(self) < 0)
        return NULL;
    if (dk_py_read_doubles(arg, self->mesh->n_vertices, 3, "positions", &x) < 0) {
        self->busy = 0;
        return NULL;
    }
    st = dk_laplacian_edit_energy(self->le, x.data, &e, &err);
    dk_py_doubles_release(&x);
    self->busy = 0;
    if (st != DK_OK)
        return dk_py_raise(&err, "LaplacianEdit.energy");
    return PyFloat_FromDouble(e);
}

static PyObject *get_stats(PyObject *obj, void *c)
{
    LapObject *self = (LapObject *)obj;
    dk_laplacian_edit_counters s;
    (void)c;
    dk_laplacian_edit_get_counters(self->le, &s);
    return Py_BuildValue("{s:i,s:i,s:i,s:i,s:i,s:i}", "n_unknowns", (int)s.n_unknowns,
                         "n_soft_rows", (int)s.n_soft_rows, "n_cotangent_fallback",
                         (int)s.n_cotangent_fallback, "n_degenerate_frames",
                         (int)s.n_degenerate_frames, "analysis_count", s.analysis_count,
                         "factorization_count", s.factorization_count);
}

static PyObject *get_mesh(PyObject *obj, void *c)
{
    (void)c;
    return Py_NewRef(((LapObject *)obj)->mesh_obj);
}

static PyObject *get_n_handles(PyObject *obj, void *c)
{
    (void)c;
    dk_method_stats ms;
    dk_laplacian_edit_stats(((LapObject *)obj)->le, &ms);
    return PyLong_FromLong(ms.n_handles);
}

static PyObject *get_n_handle_vertices(PyObject *obj, void *c)
{
    (void)c;
    dk_method_stats ms;
    dk_laplacian_edit_stats(((LapObject *)obj)->le, &ms);
    return PyLong_FromLong(ms.n_handle_vertices);
}

static PyGetSetDef lap_getset[] = {
    {"mesh", get_mesh, NULL, "the bound deformkit.Mesh", NULL},
    {"n_handles", get_n_handles, NULL, "number of handle groups", NULL},
    {"n_handle_vertices", get_n_handle_vertices, NULL, "rows expected in solve(targets)", NULL},
    {"stats", get_stats, NULL,
     "dict: n_unknowns, n_soft_rows, n_cotangent_fallback, n_degenerate_frames, "
     "analysis_count, factorization_count",
     NULL},
    {NULL, NULL, NULL, NULL, NULL},
};

static PyMethodDef lap_methods[] = {
    {"solve", (PyCFunction)(void (*)(void))lap_solve, METH_VARARGS | METH_KEYWORDS, solve_doc},
    {"rebind", (PyCFunction)(void (*)(void))lap_rebind, METH_VARARGS | METH_KEYWORDS,
     rebind_doc},
    {"energy", lap_energy, METH_O, energy_doc},
    {NULL, NULL, 0, NULL},
};

PyDoc_STRVAR(lap_doc,
             "LaplacianEdit(mesh, handles, fixed=None, roi=None, handle_weights=None,\n"
             "              stiffness=None, weights='cotangent', detail='fixed',\n"
             "              constraints='hard', constraint_weight=1.0, tikhonov=0.0,\n"
             "              local_frame_iterations=1, local_frame_tolerance=1e-6)\n\n"
             "Laplacian editing / least-squares meshes: minimises ||A x - delta||^2 with A the\n"
             "normalised umbrella operator (uniform or cotangent weights), delta = A x0\n"
             "('fixed', detail preserving but not rotation invariant), 0 ('membrane') or the\n"
             "rest deltas in local frames re-estimated on the solution ('local_frame', as\n"
             "Blender's Laplacian Deform; local_frame_iterations extra solves). Handles and\n"
             "fixed vertices are eliminated ('hard'; handle vertices with weight < 1 become\n"
             "soft rows) or soft rows of weight constraint_weight * handle weight ('soft').\n"
             "tikhonov = mu adds mu^2 ||x - x0||^2. Vertices outside roi stay at rest.\n"
             "stiffness is not supported (ValueError). See docs/methods/laplacian_edit.md.");

static PyType_Slot lap_slots[] = {
    {Py_tp_new, (void *)lap_new},
    {Py_tp_dealloc, (void *)lap_dealloc},
    {Py_tp_getset, lap_getset},
    {Py_tp_methods, lap_methods},
    {Py_tp_doc, (void *)lap_doc},
    {0, NULL},
};

static PyType_Spec lap_spec = {
    "deformkit.LaplacianEdit",
    (int)sizeof(LapObject),
    0,
    Py_TPFLAGS_DEFAULT | Py_TPFLAGS_IMMUTABLETYPE,
    lap_slots,
};

int dk_py_init_laplacian_edit(PyObject *module)
{
    PyObject *type = PyType_FromModuleAndSpec(module, &lap_spec, NULL);
    int r;
    if (!type)
        return -1;
    r = PyModule_AddObjectRef(module, "LaplacianEdit", type);
    Py_DECREF(type);
    return r;
}
