/* DeformKit CPython module: deformkit.ARAP (native/methods/dk_arap.h).
 *
 * The constructor binds (cells, reduced matrix, CHOLMOD factor) with the GIL released;
 * solve() iterates with the GIL released. The object keeps the Mesh alive and remembers the
 * constraint keywords so that rebind() may change only some of them. One call at a time per
 * object: a concurrent call from another thread gets RuntimeError (the native object reuses
 * its buffers). Constraint keywords are read by the helpers shared with LaplacianEdit
 * (dk_py_lap.h). */
#include "dk_py.h"
#include "dk_py_lap.h"

#include <math.h>
#include <string.h>

#include "dk_arap.h"

typedef struct ArapObject {
    PyObject_HEAD
    PyObject *mesh_obj;
    const dk_mesh *mesh;
    dk_arap *arap;
    PyObject *handles, *fixed, *roi, *handle_weights, *stiffness; /* as last bound        */
    int busy;
} ArapObject;

static const char *const energy_names[] = {"spokes", "spokes_and_rims", NULL};
static const char *const weights_names[] = {"cotangent", "clamped_cotangent", "uniform", NULL};
static const char *const accel_names[] = {"none", "anderson", "newton", NULL};

static int enter(ArapObject *self)
{
    if (self->busy) {
        PyErr_SetString(PyExc_RuntimeError, "ARAP: the object is in use by another thread");
        return -1;
    }
    if (!self->arap) {
        PyErr_SetString(PyExc_RuntimeError, "ARAP: the object is not bound");
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

/* Reads constraints plus the optional per-vertex stiffness (n values). */
static int read_all(PyObject *handles, PyObject *fixed, PyObject *roi, PyObject *hw,
                    PyObject *stiffness, dk_index n, const char *context,
                    dk_py_lap_constraints *con, dk_py_doubles *stiff)
{
    memset(stiff, 0, sizeof *stiff);
    if (dk_py_lap_read_constraints(handles, fixed, roi, hw, context, con) < 0)
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

static PyObject *arap_new(PyTypeObject *type, PyObject *args, PyObject *kwargs)
{
    static char *kwlist[] = {"mesh", "handles", "fixed", "roi", "handle_weights", "stiffness",
                             "energy", "weights", "max_iterations", "tolerance",
                             "acceleration", "anderson_depth", "predict", "cg_iterations",
                             NULL};
    PyObject *mesh_obj, *handles, *fixed = Py_None, *roi = Py_None, *hw = Py_None;
    PyObject *stiffness = Py_None, *energy = NULL, *weights = NULL, *accel = NULL;
    PyObject *module = PyType_GetModule(type);
    dk_arap_options opt;
    dk_py_lap_constraints con;
    dk_py_doubles stiff;
    dk_arap *arap = NULL;
    dk_error err = {0};
    dk_status st;
    const dk_mesh *mesh;
    ArapObject *self;
    allocfunc alloc;
    int c;

    if (!module)
        return NULL;
    dk_arap_default_options(&opt);
    if (!PyArg_ParseTupleAndKeywords(args, kwargs, "OO|OOOOOOidOipi:ARAP", kwlist, &mesh_obj,
                                     &handles, &fixed, &roi, &hw, &stiffness, &energy, &weights,
                                     &opt.max_iterations, &opt.tolerance, &accel,
                                     &opt.anderson_depth, &opt.predict, &opt.cg_iterations))
        return NULL;
    mesh = dk_py_mesh_get(module, mesh_obj, "mesh");
    if (!mesh)
        return NULL;
    if (energy) {
        if ((c = dk_py_lap_choice(energy, "energy", energy_names, "ARAP")) < 0)
            return NULL;
        opt.energy = (dk_arap_energy_kind)c;
    }
    if (weights) {
        if ((c = dk_py_lap_choice(weights, "weights", weights_names, "ARAP")) < 0)
            return NULL;
        opt.weights = (dk_arap_weight_kind)c;
    }
    if (accel) {
        if ((c = dk_py_lap_choice(accel, "acceleration", accel_names, "ARAP")) < 0)
            return NULL;
        opt.acceleration = (dk_arap_acceleration)c;
    }
    if (read_all(handles, fixed, roi, hw, stiffness, mesh->n_vertices, "ARAP", &con, &stiff) <
        0)
        return NULL;
    Py_BEGIN_ALLOW_THREADS
    st = dk_arap_bind(mesh, &con.desc, &opt, &arap, &err);
    Py_END_ALLOW_THREADS
    dk_py_lap_constraints_release(&con);
    dk_py_doubles_release(&stiff);
    if (st != DK_OK)
        return dk_py_raise(&err, "ARAP");
    alloc = (allocfunc)PyType_GetSlot(type, Py_tp_alloc);
    self = alloc ? (ArapObject *)alloc(type, 0) : NULL;
    if (!self) {
        dk_arap_free(arap);
        if (!PyErr_Occurred())
            PyErr_NoMemory();
        return NULL;
    }
    self->arap = arap;
    self->mesh = mesh;
    self->mesh_obj = Py_NewRef(mesh_obj);
    replace_ref(&self->handles, handles);
    replace_ref(&self->fixed, fixed);
    replace_ref(&self->roi, roi);
    replace_ref(&self->handle_weights, hw);
    replace_ref(&self->stiffness, stiffness);
    return (PyObject *)self;
}

static void arap_dealloc(PyObject *obj)
{
    ArapObject *self = (ArapObject *)obj;
    PyTypeObject *type = Py_TYPE(obj);
    freefunc tp_free = (freefunc)PyType_GetSlot(type, Py_tp_free);
    dk_arap_free(self->arap);
    self->arap = NULL;
    Py_CLEAR(self->mesh_obj);
    Py_CLEAR(self->handles);
    Py_CLEAR(self->fixed);
    Py_CLEAR(self->roi);
    Py_CLEAR(self->handle_weights);
    Py_CLEAR(self->stiffness);
    tp_free(obj);
    Py_DECREF((PyObject *)type);
}

PyDoc_STRVAR(solve_doc,
             "solve(targets=None, transforms=None, warm_start=True, max_iterations=None,\n"
             "      tolerance=None, resume=False) -> SolveResult\n\n"
             "targets: (sum of handle sizes) x 3 positions, concatenated in handle order;\n"
             "transforms: n_handles x 4 x 4 affine transforms of the rest pose. warm_start\n"
             "starts from the previous solution (else from the naive Laplacian-editing guess).\n"
             "max_iterations overrides the bound value for this call; tolerance replaces the\n"
             "bound value for this and later calls. resume=True with the previous call's\n"
             "targets continues that solve where it stopped (acceleration history kept), so\n"
             "solves sliced by max_iterations equal one longer solve; with other targets it\n"
             "is a warm start.\n"
             "Returns the positions, the ARAP energy of those positions, the iterations used\n"
             "and whether the relative energy change fell below the tolerance.");

static PyObject *arap_solve(PyObject *obj, PyObject *args, PyObject *kwargs)
{
    static char *kwlist[] = {"targets", "transforms", "warm_start", "max_iterations",
                             "tolerance", "resume", NULL};
    ArapObject *self = (ArapObject *)obj;
    PyObject *targets = Py_None, *transforms = Py_None, *maxit_obj = Py_None, *positions;
    PyObject *tol_obj = Py_None;
    PyObject *module;
    int warm = 1, maxit = 0, mode, resume = 0;
    dk_py_doubles in = {0};
    dk_solve_info info;
    dk_error err = {0};
    dk_status st;
    double *out;
    const dk_constraints *c;

    if (!PyArg_ParseTupleAndKeywords(args, kwargs, "|OOpOOp:solve", kwlist, &targets,
                                     &transforms, &warm, &maxit_obj, &tol_obj, &resume))
        return NULL;
    if (maxit_obj != Py_None) {
        long v = PyLong_AsLong(maxit_obj);
        if (v == -1 && PyErr_Occurred())
            return NULL;
        if (v < 1 || v > 1000000000L) {
            PyErr_Format(PyExc_ValueError, "ARAP.solve: max_iterations is %ld, must be >= 1",
                         v);
            return NULL;
        }
        maxit = (int)v;
    }
    module = PyType_GetModule(Py_TYPE(obj));
    if (!module || enter(self) < 0)
        return NULL;
    if (tol_obj != Py_None) {
        double tol = PyFloat_AsDouble(tol_obj);
        if ((tol == -1.0 && PyErr_Occurred()) ||
            dk_arap_set_tolerance(self->arap, tol, &err) != DK_OK) {
            self->busy = 0;
            return PyErr_Occurred() ? NULL : dk_py_raise(&err, "ARAP.solve");
        }
    }
    c = dk_arap_constraints(self->arap);
    if (dk_py_lap_read_solve_input(targets, transforms, c->n_handles, c->n_handle_vertices,
                                   "ARAP.solve", &in, &mode) < 0) {
        self->busy = 0;
        return NULL;
    }
    positions = dk_py_new_doubles(2, self->mesh->n_vertices, 3, &out);
    if (!positions) {
        dk_py_doubles_release(&in);
        self->busy = 0;
        return NULL;
    }
    const dk_solve_request rq = {
        .targets = in.data,
        .target_kind = (dk_target_kind)mode,
        .start = resume ? DK_START_RESUME : warm ? DK_START_WARM : DK_START_COLD,
        .max_iterations = maxit};
    Py_BEGIN_ALLOW_THREADS
    st = dk_arap_solve(self->arap, &rq, out, &info, &err);
    Py_END_ALLOW_THREADS
    dk_py_doubles_release(&in);
    self->busy = 0;
    if (st != DK_OK) {
        Py_DECREF(positions);
        return dk_py_raise(&err, "ARAP.solve");
    }
    return dk_py_new_solve_result(module, positions, info.energy, info.iterations,
                                  info.converged);
}

PyDoc_STRVAR(rebind_doc,
             "rebind(handles=None, fixed=None, roi=None, handle_weights=None, stiffness=None)\n\n"
             "Changes the constraints (and stiffness); arguments not given keep their bound\n"
             "value. The cells are kept; the symbolic analysis is reused when the set of\n"
             "unknown vertices is unchanged. The previous solution stays as warm start. On\n"
             "error the previous constraints stay bound.");

static PyObject *arap_rebind(PyObject *obj, PyObject *args, PyObject *kwargs)
{
    static char *kwlist[] = {"handles", "fixed", "roi", "handle_weights", "stiffness", NULL};
    ArapObject *self = (ArapObject *)obj;
    PyObject *handles = NULL, *fixed = NULL, *roi = NULL, *hw = NULL, *stiffness = NULL;
    dk_py_lap_constraints con;
    dk_py_doubles stiff;
    dk_error err = {0};
    dk_status st;

    if (!PyArg_ParseTupleAndKeywords(args, kwargs, "|OOOOO:rebind", kwlist, &handles, &fixed,
                                     &roi, &hw, &stiffness))
        return NULL;
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
    if (enter(self) < 0)
        return NULL;
    if (read_all(handles, fixed, roi, hw, stiffness, self->mesh->n_vertices, "ARAP.rebind",
                 &con, &stiff) < 0) {
        self->busy = 0;
        return NULL;
    }
    Py_BEGIN_ALLOW_THREADS
    st = dk_arap_rebind(self->arap, &con.desc, &err);
    Py_END_ALLOW_THREADS
    dk_py_lap_constraints_release(&con);
    dk_py_doubles_release(&stiff);
    self->busy = 0;
    if (st != DK_OK)
        return dk_py_raise(&err, "ARAP.rebind");
    replace_ref(&self->handles, handles);
    replace_ref(&self->fixed, fixed);
    replace_ref(&self->roi, roi);
    replace_ref(&self->handle_weights, hw);
    replace_ref(&self->stiffness, stiffness);
    Py_RETURN_NONE;
}

PyDoc_STRVAR(energy_doc,
             "energy(positions) -> float\n\n"
             "The ARAP energy of arbitrary n x 3 positions with their optimal rotations (plus\n"
             "the soft-handle penalties for the targets of the last solve).");

static PyObject *arap_energy(PyObject *obj, PyObject *arg)
{
    ArapObject *self = (ArapObject *)obj;
    dk_py_doubles x = {0};
    double e;
    if (enter(self) < 0)
        return NULL;
    if (dk_py_read_doubles(arg, self->mesh->n_vertices, 3, "positions", &x) < 0) {
        self->busy = 0;
        return NULL;
    }
    for (Py_ssize_t k = 0; k < 3 * x.rows; k++)
        if (!isfinite(x.data[k])) {
            PyErr_Format(PyExc_ValueError, "ARAP.energy: positions of vertex %zd are not finite",
                         k / 3);
            dk_py_doubles_release(&x);
            self->busy = 0;
            return NULL;
        }
    dk_error err = {0};
    dk_status st;
    Py_BEGIN_ALLOW_THREADS
    st = dk_arap_energy(self->arap, x.data, &e, &err);
    Py_END_ALLOW_THREADS
    dk_py_doubles_release(&x);
    self->busy = 0;
    if (st != DK_OK)
        return dk_py_raise(&err, "ARAP.energy");
    return PyFloat_FromDouble(e);
}

static PyObject *get_mesh(PyObject *obj, void *c)
{
    (void)c;
    return Py_NewRef(((ArapObject *)obj)->mesh_obj);
}

static PyObject *get_n_vertices(PyObject *obj, void *c)
{
    (void)c;
    return PyLong_FromLong(((ArapObject *)obj)->mesh->n_vertices);
}

static PyObject *get_n_handles(PyObject *obj, void *c)
{
    (void)c;
    return PyLong_FromLong(dk_arap_constraints(((ArapObject *)obj)->arap)->n_handles);
}

static PyObject *get_n_handle_vertices(PyObject *obj, void *c)
{
    (void)c;
    return PyLong_FromLong(dk_arap_constraints(((ArapObject *)obj)->arap)->n_handle_vertices);
}

static PyObject *get_handle_sizes(PyObject *obj, void *c)
{
    const dk_constraints *k = dk_arap_constraints(((ArapObject *)obj)->arap);
    PyObject *t = PyTuple_New(k->n_handles);
    (void)c;
    if (!t)
        return NULL;
    for (dk_index h = 0; h < k->n_handles; h++) {
        PyObject *v = PyLong_FromLong(k->handle_start[h + 1] - k->handle_start[h]);
        if (!v || PyTuple_SetItem(t, h, v) < 0) {
            Py_DECREF(t);
            return NULL;
        }
    }
    return t;
}

static PyObject *get_stats(PyObject *obj, void *c)
{
    ArapObject *self = (ArapObject *)obj;
    const dk_constraints *k = dk_arap_constraints(self->arap);
    dk_method_stats ms;
    (void)c;
    dk_arap_stats(self->arap, &ms);
    return Py_BuildValue("{s:i,s:i,s:i,s:i}", "n_unknowns", (int)ms.n_unknowns, "n_free",
                         (int)k->n_free, "analysis_count", ms.analysis_count,
                         "factorization_count", ms.factorization_count);
}

static PyGetSetDef arap_getset[] = {
    {"mesh", get_mesh, NULL, "the bound deformkit.Mesh", NULL},
    {"n_vertices", get_n_vertices, NULL, "number of mesh vertices", NULL},
    {"n_handles", get_n_handles, NULL, "number of handle groups", NULL},
    {"n_handle_vertices", get_n_handle_vertices, NULL, "rows expected in solve(targets)", NULL},
    {"handle_sizes", get_handle_sizes, NULL, "tuple: vertices per handle group", NULL},
    {"stats", get_stats, NULL,
     "dict: n_unknowns, n_free, analysis_count, factorization_count", NULL},
    {NULL, NULL, NULL, NULL, NULL},
};

static PyMethodDef arap_methods[] = {
    {"solve", (PyCFunction)(void (*)(void))arap_solve, METH_VARARGS | METH_KEYWORDS,
     solve_doc},
    {"rebind", (PyCFunction)(void (*)(void))arap_rebind, METH_VARARGS | METH_KEYWORDS,
     rebind_doc},
    {"energy", arap_energy, METH_O, energy_doc},
    {NULL, NULL, 0, NULL},
};

PyDoc_STRVAR(arap_doc,
             "ARAP(mesh, handles, fixed=None, roi=None, handle_weights=None, stiffness=None,\n"
             "     energy='spokes', weights='clamped_cotangent', max_iterations=100,\n"
             "     tolerance=1e-6, acceleration='newton', anderson_depth=5, predict=True,\n"
             "     cg_iterations=12)\n\n"
             "As-rigid-as-possible deformation (Sorkine & Alexa 2007; 'spokes_and_rims' after\n"
             "Chao et al. 2010). Fixed vertices, vertices outside roi and handle vertices of\n"
             "weight 1 are eliminated exactly; handle weights w < 1 become soft penalties\n"
             "lambda w/(1-w) |p - t|^2. stiffness (n values > 0) scales each vertex's cell\n"
             "energy. acceleration: 'none' (the paper's local/global iteration), 'anderson'\n"
             "(Anderson-accelerated, with an energy safeguard) or 'newton' (default; inexact Newton\n"
             "steps, cg_iterations conjugate-gradient iterations each, preconditioned by the\n"
             "local/global step; an energy line search). Stops when a local/global step\n"
             "changes the energy by at most tolerance (relative; Newton: predicted before the\n"
             "step). predict: warm starts may extrapolate along the drag (secant of the last\n"
             "two solutions). See docs/methods/arap.md.");

static PyType_Slot arap_slots[] = {
    {Py_tp_new, (void *)arap_new},
    {Py_tp_dealloc, (void *)arap_dealloc},
    {Py_tp_getset, arap_getset},
    {Py_tp_methods, arap_methods},
    {Py_tp_doc, (void *)arap_doc},
    {0, NULL},
};

static PyType_Spec arap_spec = {
    "deformkit.ARAP",
    (int)sizeof(ArapObject),
    0,
    Py_TPFLAGS_DEFAULT | Py_TPFLAGS_IMMUTABLETYPE,
    arap_slots,
};

int dk_py_init_arap(PyObject *module)
{
    PyObject *type = PyType_FromModuleAndSpec(module, &arap_spec, NULL);
    int r;
    if (!type)
        return -1;
    r = PyModule_AddObjectRef(module, "ARAP", type);
    Py_DECREF(type);
    return r;
}
