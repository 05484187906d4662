/* DeformKit CPython module: deformkit.EigenDeformation (native/methods/dk_eigen.h), on the
 * generic method type (dk_py_method.h). What is its own: its options (the preview keyword
 * of solve is the contract's, dk_solve_request.preview) and the skeleton, eigenvalues and weights. The translation / rotation / pivot forms of
 * solve are in the Python package (deformkit/__init__.py). */
#include "dk_py_method.h"

#include "dk_eigen.h"

#include <math.h>
#include <string.h>

static const char *const laplacian_names[] = {"cotangent", "belkin_sun_wang", NULL};
static const char *const region_names[] = {"part", "handles", NULL};

static void default_options(void *o)
{
    dk_eigen_default_options((dk_eigen_options *)o);
}

/* progress=: the shared callback (dk_py.h), phases named by the native bind */
static void bind_progress(void *o, dk_py_progress *p)
{
    dk_eigen_options *opt = (dk_eigen_options *)o;
    opt->progress = dk_py_progress_phase;
    opt->progress_user = p;
}

static int parse_options(PyObject *kw, void *o, const char *context)
{
    dk_eigen_options *opt = (dk_eigen_options *)o;
    int lap = (int)opt->laplacian, region = (int)opt->region;
    PyObject *m = dk_py_opt_object(kw, "n_eigenvectors");
    if (!m && PyErr_Occurred())
        return -1;
    if (m) {
        int bad = 0;
        if (PyUnicode_Check(m)) {
            bad = PyUnicode_CompareWithASCIIString(m, "auto") != 0;
            opt->n_eigenvectors = 0;
        } else {
            long v = PyLong_AsLong(m);
            if (v == -1 && PyErr_Occurred()) {
                Py_DECREF(m);
                return -1;
            }
            bad = v < 0 || v > 1000000; /* 0: automatic, as 'auto' */
            opt->n_eigenvectors = (int)v;
        }
        Py_DECREF(m);
        if (bad) {
            PyErr_Format(PyExc_ValueError, "%s: n_eigenvectors must be 'auto' (or 0) or a count >= 1",
                         context);
            return -1;
        }
    }
    if (dk_py_opt_int(kw, "refine", &opt->refine) < 0 ||
        dk_py_opt_double(kw, "bsw_width", &opt->bsw_width) < 0 ||
        dk_py_opt_choice(kw, "laplacian", laplacian_names, &lap, context) < 0 ||
        dk_py_opt_choice(kw, "region", region_names, &region, context) < 0)
        return -1;
    opt->laplacian = (dk_eigen_laplacian)lap;
    opt->region = (dk_eigen_region)region;
    return 0;
}

/* solve(translation=t, rotation=r, pivot=p): the paper's one motion of R, as transforms
 * T = [r | p + t - r p] for every handle region (rotation about the pivot, then the
 * translation; each part optional, the pivot needing a rotation) */
static PyObject *solve_motion(dk_py_method *self, PyObject *kw, const char *context)
{
    static const char *const keys[] = {"translation", "rotation", "pivot"};
    PyObject *obj[3] = {NULL, NULL, NULL};
    dk_py_doubles in[3] = {{0}, {0}, {0}};
    const Py_ssize_t rows[3] = {1, 3, 1}, cols[3] = {3, 3, 3};
    PyObject *res = NULL;
    int any = 0, ok = 1;
    for (int k = 0; k < 3 && ok; k++) {
        obj[k] = kw ? dk_py_opt_object(kw, keys[k]) : NULL;
        if (!obj[k] && PyErr_Occurred())
            ok = 0;
        if (obj[k] == Py_None)
            Py_CLEAR(obj[k]);
        if (obj[k]) {
            any = 1;
            if (dk_py_read_doubles(obj[k], rows[k], cols[k], keys[k], &in[k]) < 0)
                ok = 0;
        }
    }
    if (ok && !any)
        res = Py_NewRef(Py_None);
    if (ok && any && obj[2] && !obj[1]) {
        PyErr_Format(PyExc_TypeError, "%s: a pivot needs a rotation", context);
        ok = 0;
    }
    if (ok && any) {
        double T[16] = {1, 0, 0, 0, 0, 1, 0, 0, 0, 0, 1, 0, 0, 0, 0, 1};
        if (obj[1])
            for (int r = 0; r < 3; r++)
                for (int c = 0; c < 3; c++)
                    T[4 * r + c] = in[1].data[3 * r + c];
        for (int r = 0; r < 3; r++) {
            double t = obj[0] ? in[0].data[r] : 0.0;
            if (obj[2])
                t += in[2].data[r] - (T[4 * r] * in[2].data[0] + T[4 * r + 1] * in[2].data[1] +
                                      T[4 * r + 2] * in[2].data[2]);
            T[4 * r + 3] = t;
        }
        dk_method_stats ms;
        double *out;
        self->spec->ops->stats(self->native, &ms);
        res = dk_py_new_doubles(2, (Py_ssize_t)ms.n_handles * 4, 4, &out);
        if (res)
            for (dk_index h = 0; h < ms.n_handles; h++)
                memcpy(out + 16 * (size_t)h, T, sizeof T);
    }
    for (int k = 0; k < 3; k++) {
        Py_XDECREF(obj[k]);
        dk_py_doubles_release(&in[k]);
    }
    return res;
}

static PyObject *get_skeleton(PyObject *obj, void *c)
{
    if (!dk_py_method_readable((dk_py_method *)obj))
        return NULL;
    dk_py_method *self = (dk_py_method *)obj;
    const dk_index n = self->mesh->n_vertices;
    double *out;
    (void)c;
    PyObject *a = dk_py_new_doubles(2, n, 3, &out);
    if (a)
        memcpy(out, dk_eigen_skeleton(self->native), 3 * (size_t)n * sizeof(double));
    return a;
}

static PyObject *get_m(PyObject *obj, void *c)
{
    if (!dk_py_method_readable((dk_py_method *)obj))
        return NULL;
    (void)c;
    return PyLong_FromLong(dk_eigen_m(((dk_py_method *)obj)->native));
}

static PyObject *get_delta3(PyObject *obj, void *c)
{
    if (!dk_py_method_readable((dk_py_method *)obj))
        return NULL;
    (void)c;
    return PyFloat_FromDouble(dk_eigen_delta3(((dk_py_method *)obj)->native));
}

static PyObject *get_eigenvalues(PyObject *obj, void *c)
{
    if (!dk_py_method_readable((dk_py_method *)obj))
        return NULL;
    dk_py_method *self = (dk_py_method *)obj;
    const int k = dk_eigen_k(self->native);
    double *out;
    (void)c;
    PyObject *a = dk_py_new_doubles(1, k, 0, &out);
    if (a)
        memcpy(out, dk_eigen_eigenvalues(self->native), (size_t)k * sizeof(double));
    return a;
}

static PyObject *get_weights(PyObject *obj, void *c)
{
    if (!dk_py_method_readable((dk_py_method *)obj))
        return NULL;
    dk_py_method *self = (dk_py_method *)obj;
    const dk_index n = self->mesh->n_vertices;
    double *out;
    (void)c;
    PyObject *a = dk_py_new_doubles(1, n, 0, &out);
    if (a)
        memcpy(out, dk_eigen_weights(self->native), (size_t)n * sizeof(double));
    return a;
}

PyDoc_STRVAR(eigenvectors_doc,
             "eigenvectors() -> n x K array: the Laplacian's eigenvectors (M-orthonormal,\n"
             "in the order of `eigenvalues`). A copy: n x K doubles.");

static PyObject *eig_eigenvectors(PyObject *obj, PyObject *unused)
{
    dk_py_method *self = (dk_py_method *)obj;
    (void)unused;
    /* held busy while it reads: the allocation may run Python, and a rebind in another
     * thread frees the basis */
    if (dk_py_method_enter(self) < 0)
        return NULL;
    const dk_index n = self->mesh->n_vertices;
    const int k = dk_eigen_k(self->native);
    double *out;
    PyObject *a = dk_py_new_doubles(2, n, k, &out);
    if (a) {
        const double *U = dk_eigen_eigenvectors(self->native);
        for (dk_index i = 0; i < n; i++)
            for (int j = 0; j < k; j++)
                out[(size_t)i * k + j] = U[(size_t)j * n + i];
    }
    self->busy = 0;
    return a;
}

PyDoc_STRVAR(solve_doc,
             "solve(targets=None, transforms=None, translation=None, rotation=None,\n"
             "      pivot=None, preview=False, energy=True) -> SolveResult\n\n"
             "Steps 1-3 of eigen deformation: each handle region's skeleton points moved\n"
             "(transforms: rotation-type, T applied; targets: translation-type, each point by\n"
             "its vertex's displacement; translation / rotation about pivot: one motion for\n"
             "every region), eq. 1 fitted with m eigenvectors, details recovered (two\n"
             "iterations when m < refine). preview=True: Steps 1-2 only, the skeleton's\n"
             "motion carried to the mesh. energy: |x - x~|^2 to the Step-1 target.");

PyDoc_STRVAR(eig_doc,
             "EigenDeformation(mesh, handles, fixed=None, region='part' | 'handles',\n"
             "    n_eigenvectors='auto', refine=300, laplacian='cotangent' | 'belkin_sun_wang',\n"
             "    bsw_width=1.0, progress=None)\n\n"
             "Eigen deformation (Dey, Ranjan & Wang): the mesh's eigen-skeleton (its\n"
             "coordinates fitted with the first m Laplace-Beltrami eigenvectors) is deformed\n"
             "by a least-squares fit to the motion of a region R, and the details are added\n"
             "back in local frames. region 'part': each handle drags the part of the mesh\n"
             "nearer to it than to the fixed vertices and the other handles, turned about the\n"
             "part's border so that the handle reaches its target; 'handles': R is the handle\n"
             "groups alone (the paper's figures). Every other vertex is held by the fit.\n"
             "m 'auto': 8, 50 or 300 from R's size (section 4.2), plus one per loose piece.\n"
             "progress(fraction): as ARAP's (phases regions, operator, eigenvectors,\n"
             "skeletons); True cancels the bind.\n"
             "It must not start another eigen computation. See docs/methods/eigen.md.");

static PyGetSetDef eig_getset[] = {
    DK_PY_METHOD_GETSET,
    {"skeleton", get_skeleton, NULL, "n x 3: the rest eigen-skeleton K_m", NULL},
    {"n_eigenvectors", get_m, NULL, "m in use (the automatic choice, or the option)", NULL},
    {"eigenvalues", get_eigenvalues, NULL, "the K computed eigenvalues, ascending", NULL},
    {"delta3", get_delta3, NULL, "diam R / diam(V \\ R) (section 4.2)", NULL},
    {"weights", get_weights, NULL, "n: the detail interpolation weight w (section 4.1)", NULL},
    {NULL, NULL, NULL, NULL, NULL},
};

static PyMethodDef eig_methods[] = {
    DK_PY_METHOD_METHODS(solve_doc),
    {"eigenvectors", eig_eigenvectors, METH_NOARGS, eigenvectors_doc},
    {NULL, NULL, 0, NULL},
};

static const dk_py_method_spec eig_spec = {
    .name = "EigenDeformation",
    .type_name = "deformkit.EigenDeformation",
    .ops = &dk_eigen_ops,
    .doc = eig_doc,
    .options_size = sizeof(dk_eigen_options),
    .default_options = default_options,
    .parse_options = parse_options,
    .bind_progress = bind_progress,
    .solve_motion = solve_motion,
    .serialise_bind = 1,
    .getset = eig_getset,
    .methods = eig_methods,
};

static PyObject *eig_new(PyTypeObject *type, PyObject *args, PyObject *kwargs)
{
    return dk_py_method_new(type, args, kwargs, &eig_spec);
}

int dk_py_init_eigen(PyObject *module)
{
    return dk_py_method_register(module, &eig_spec, eig_new);
}
