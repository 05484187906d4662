/* DeformKit CPython module: deformkit.Falloff (native/methods/dk_falloff.h).
 *
 * The constructor computes the distances and weights with the GIL released; solve() is one
 * pass over the vertices, also without the GIL. The object keeps the Mesh alive and
 * remembers the constraint keywords so that rebind() may change only some of them. One call
 * at a time per object: a second thread calling while the first runs gets RuntimeError
 * (the native object reuses its buffers). */
#include "dk_py.h"
#include "dk_py_lap.h"

#include <string.h>

#include "dk_falloff.h"

typedef struct FalloffObject {
    PyObject_HEAD
    PyObject *mesh_obj;
    const dk_mesh *mesh;
    dk_falloff *f;
    PyObject *handles, *fixed, *roi, *handle_weights; /* as last bound (owned refs)        */
    int busy;
} FalloffObject;

static const char *const distance_names[] = {"hops", "euclidean", "geodesic", "dijkstra",
                                             NULL};

static int enter(FalloffObject *self)
{
    if (self->busy) {
        PyErr_SetString(PyExc_RuntimeError,
                        "Falloff: the object is in use by another thread");
        return -1;
    }
    if (!self->f) {
        PyErr_SetString(PyExc_RuntimeError, "Falloff: the object is not bound");
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

static void remember(FalloffObject *self, PyObject *handles, PyObject *fixed, PyObject *roi,
                     PyObject *weights)
{
    replace_ref(&self->handles, handles);
    replace_ref(&self->fixed, fixed);
    replace_ref(&self->roi, roi);
    replace_ref(&self->handle_weights, weights);
}

static PyObject *falloff_new(PyTypeObject *type, PyObject *args, PyObject *kwargs)
{
    static char *kwlist[] = {"mesh", "handles", "fixed", "roi", "handle_weights", "stiffness",
                             "distance", "range", "k", "heat_time_factor", NULL};
    PyObject *mesh_obj, *handles, *fixed = Py_None, *roi = Py_None, *hw = Py_None;
    PyObject *stiffness = Py_None, *distance = NULL;
    PyObject *module = PyType_GetModule(type);
    dk_falloff_options opt;
    dk_py_lap_constraints con;
    dk_falloff *f = NULL;
    dk_error err = {0};
    dk_status st;
    const dk_mesh *mesh;
    FalloffObject *self;
    allocfunc alloc;
    int c;

    if (!module)
        return NULL;
    dk_falloff_default_options(&opt);
    if (!PyArg_ParseTupleAndKeywords(args, kwargs, "OO|OOOOOddd:Falloff", kwlist, &mesh_obj,
                                     &handles, &fixed, &roi, &hw, &stiffness, &distance,
                                     &opt.range, &opt.k, &opt.heat_time_factor))
        return NULL;
    mesh = dk_py_mesh_get(module, mesh_obj, "mesh");
    if (!mesh)
        return NULL;
    if (stiffness != Py_None) {
        PyErr_SetString(PyExc_ValueError,
                        "Falloff: stiffness is not supported by the falloff method; pass None");
        return NULL;
    }
    if (distance && (c = dk_py_lap_choice(distance, "distance", distance_names, "Falloff")) < 0)
        return NULL;
    else if (distance)
        opt.distance = (dk_falloff_distance)c;
    if (dk_py_lap_read_constraints(handles, fixed, roi, hw, "Falloff", &con) < 0)
        return NULL;
    Py_BEGIN_ALLOW_THREADS
    st = dk_falloff_bind(mesh, &con.desc, &opt, &f, &err);
    Py_END_ALLOW_THREADS
    dk_py_lap_constraints_release(&con);
    if (st != DK_OK)
        return dk_py_raise(&err, "Falloff");
    alloc = (allocfunc)PyType_GetSlot(type, Py_tp_alloc);
    self = alloc ? (FalloffObject *)alloc(type, 0) : NULL;
    if (!self) {
        dk_falloff_free(f);
        if (!PyErr_Occurred())
            PyErr_NoMemory();
        return NULL;
    }
    self->f = f;
    self->mesh = mesh;
    self->mesh_obj = Py_NewRef(mesh_obj);
    remember(self, handles, fixed, roi, hw);
    return (PyObject *)self;
}

static void falloff_dealloc(PyObject *obj)
{
    FalloffObject *self = (FalloffObject *)obj;
    PyTypeObject *type = Py_TYPE(obj);
    freefunc tp_free = (freefunc)PyType_GetSlot(type, Py_tp_free);
    dk_falloff_free(self->f);
    self->f = NULL;
    Py_CLEAR(self->mesh_obj);
    Py_CLEAR(self->handles);
    Py_CLEAR(self->fixed);
    Py_CLEAR(self->roi);
    Py_CLEAR(self->handle_weights);
    tp_free(obj);
    Py_DECREF((PyObject *)type);
}

PyDoc_STRVAR(solve_doc,
             "solve(targets=None, transforms=None) -> SolveResult\n\n"
             "targets: (sum of handle sizes) x 3 positions, concatenated in handle order;\n"
             "transforms: n_handles x 4 x 4 affine transforms of the rest pose. Returns the\n"
             "deformed positions; energy = sum of squared vertex displacements; iterations = 1;\n"
             "converged = True (a direct method).");

static PyObject *falloff_solve(PyObject *obj, PyObject *args, PyObject *kwargs)
{
    static char *kwlist[] = {"targets", "transforms", NULL};
    FalloffObject *self = (FalloffObject *)obj;
    PyObject *targets = Py_None, *transforms = Py_None, *positions, *module;
    dk_py_doubles in = {0};
    dk_solve_info info;
    dk_method_stats ms;
    dk_error err = {0};
    dk_status st;
    double *out;
    int mode;

    if (!PyArg_ParseTupleAndKeywords(args, kwargs, "|OO:solve", kwlist, &targets, &transforms))
        return NULL;
    module = PyType_GetModule(Py_TYPE(obj));
    if (!module || enter(self) < 0)
        return NULL;
    dk_falloff_stats(self->f, &ms);
    if (dk_py_lap_read_solve_input(targets, transforms, ms.n_handles, ms.n_handle_vertices,
                                   "Falloff.solve", &in, &mode) < 0) {
        self->busy = 0;
        return NULL;
    }
    positions = dk_py_new_doubles(2, self->mesh->n_vertices, 3, &out);
    if (!positions) {
        dk_py_doubles_release(&in);
        self->busy = 0;
        return NULL;
    }
    const dk_solve_request rq = {.targets = in.data, .target_kind = (dk_target_kind)mode};
    Py_BEGIN_ALLOW_THREADS
    st = dk_falloff_solve(self->f, &rq, out, &info, &err);
    Py_END_ALLOW_THREADS
    dk_py_doubles_release(&in);
    self->busy = 0;
    if (st != DK_OK) {
        Py_DECREF(positions);
        return dk_py_raise(&err, "Falloff.solve");
    }
    return dk_py_new_solve_result(module, positions, info.energy, info.iterations,
                                  info.converged);
}

PyDoc_STRVAR(rebind_doc,
             "rebind(handles=None, fixed=None, roi=None, handle_weights=None)\n\n"
             "Changes the constraint sets; arguments not given keep their bound value (pass\n"
             "an empty list for fixed to clear it). Distances are recomputed (the heat\n"
             "method's factorization is reused). On error the previous constraints stay.");

static PyObject *falloff_rebind(PyObject *obj, PyObject *args, PyObject *kwargs)
{
    static char *kwlist[] = {"handles", "fixed", "roi", "handle_weights", NULL};
    FalloffObject *self = (FalloffObject *)obj;
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
    if (dk_py_lap_read_constraints(handles, fixed, roi, hw, "Falloff.rebind", &con) < 0) {
        self->busy = 0;
        return NULL;
    }
    Py_BEGIN_ALLOW_THREADS
    st = dk_falloff_rebind(self->f, &con.desc, &err);
    Py_END_ALLOW_THREADS
    dk_py_lap_constraints_release(&con);
    self->busy = 0;
    if (st != DK_OK)
        return dk_py_raise(&err, "Falloff.rebind");
    remember(self, handles, fixed, roi, hw);
    Py_RETURN_NONE;
}

PyDoc_STRVAR(weights_doc,
             "weights(group) -> (distances, S): per-vertex distance from handle group `group`\n"
             "(INFINITY where unreachable) and attenuation S (0 for constrained vertices and\n"
             "beyond the range), as computed at bind.");

static PyObject *falloff_weights(PyObject *obj, PyObject *arg)
{
    FalloffObject *self = (FalloffObject *)obj;
    PyObject *d, *w;
    double *dp, *wp;
    dk_method_stats ms;
    long g = PyLong_AsLong(arg);
    if (g == -1 && PyErr_Occurred())
        return NULL;
    dk_falloff_stats(self->f, &ms);
    if (g < 0 || g >= ms.n_handles) {
        PyErr_Format(PyExc_IndexError, "Falloff.weights: group %ld out of range [0, %d)", g,
                     (int)ms.n_handles);
        return NULL;
    }
    d = dk_py_new_doubles(1, self->mesh->n_vertices, 0, &dp);
    if (!d)
        return NULL;
    w = dk_py_new_doubles(1, self->mesh->n_vertices, 0, &wp);
    if (!w) {
        Py_DECREF(d);
        return NULL;
    }
    for (dk_index v = 0; v < self->mesh->n_vertices; v++)
        dk_falloff_vertex_weight(self->f, (dk_index)g, v, dp + v, wp + v);
    return Py_BuildValue("(NN)", d, w);
}

static PyObject *get_mesh(PyObject *obj, void *c)
{
    (void)c;
    return Py_NewRef(((FalloffObject *)obj)->mesh_obj);
}

static PyObject *get_n_handles(PyObject *obj, void *c)
{
    (void)c;
    dk_method_stats ms;
    dk_falloff_stats(((FalloffObject *)obj)->f, &ms);
    return PyLong_FromLong(ms.n_handles);
}

static PyObject *get_n_handle_vertices(PyObject *obj, void *c)
{
    (void)c;
    dk_method_stats ms;
    dk_falloff_stats(((FalloffObject *)obj)->f, &ms);
    return PyLong_FromLong(ms.n_handle_vertices);
}

static PyGetSetDef falloff_getset[] = {
    {"mesh", get_mesh, NULL, "the bound deformkit.Mesh", NULL},
    {"n_handles", get_n_handles, NULL, "number of handle groups", NULL},
    {"n_handle_vertices", get_n_handle_vertices, NULL, "rows expected in solve(targets)", NULL},
    {NULL, NULL, NULL, NULL, NULL},
};

static PyMethodDef falloff_methods[] = {
    {"solve", (PyCFunction)(void (*)(void))falloff_solve, METH_VARARGS | METH_KEYWORDS, solve_doc},
    {"rebind", (PyCFunction)(void (*)(void))falloff_rebind, METH_VARARGS | METH_KEYWORDS,
     rebind_doc},
    {"weights", falloff_weights, METH_O, weights_doc},
    {NULL, NULL, 0, NULL},
};

PyDoc_STRVAR(falloff_doc,
             "Falloff(mesh, handles, fixed=None, roi=None, handle_weights=None,\n"
             "        stiffness=None, distance='hops', range=0.0, k=0.0, heat_time_factor=0.0)\n\n"
             "Attenuated handle displacement (lecture slides 5-7): every free vertex moves by\n"
             "S(d) times the displacement of its nearest handle vertex (or S(d) (T p - p) for\n"
             "transforms), S(i) = 1 - (i/(n+1))^(k+1) for k >= 0, (1 - i/(n+1))^(1-k) for\n"
             "k < 0, 0 beyond the range. distance: 'hops' (range in edges), 'euclidean',\n"
             "'geodesic' (heat method) or 'dijkstra' (range a length; the formula is applied\n"
             "in units of the mean edge length). range 0 = 10 hops / 10 mean edge lengths.\n"
             "Several groups add up. See docs/methods/falloff.md.");

static PyType_Slot falloff_slots[] = {
    {Py_tp_new, (void *)falloff_new},
    {Py_tp_dealloc, (void *)falloff_dealloc},
    {Py_tp_getset, falloff_getset},
    {Py_tp_methods, falloff_methods},
    {Py_tp_doc, (void *)falloff_doc},
    {0, NULL},
};

static PyType_Spec falloff_spec = {
    "deformkit.Falloff",
    (int)sizeof(FalloffObject),
    0,
    Py_TPFLAGS_DEFAULT | Py_TPFLAGS_IMMUTABLETYPE,
    falloff_slots,
};

int dk_py_init_falloff(PyObject *module)
{
    PyObject *type = PyType_FromModuleAndSpec(module, &falloff_spec, NULL);
    int r;
    if (!type)
        return -1;
    r = PyModule_AddObjectRef(module, "Falloff", type);
    Py_DECREF(type);
    return r;
}
