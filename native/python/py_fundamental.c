/* DeformKit CPython module: deformkit.LinearReconstruction (native/methods/dk_fundamental.h),
 * on the generic method type (dk_py_method.h). What is its own: its options (the material
 * map an array copied until release_options) and the frames. */
#include "dk_py_method.h"

#include "dk_fundamental.h"

#include <string.h>

static void default_options(void *o)
{
    dk_fundamental_default_options((dk_fundamental_options *)o);
}

static void release_options(void *o)
{
    dk_fundamental_options *opt = (dk_fundamental_options *)o;
    PyMem_Free((void *)opt->material);
    opt->material = NULL;
    opt->n_material = 0;
}

static int parse_options(PyObject *kw, void *o, const char *context)
{
    dk_fundamental_options *opt = (dk_fundamental_options *)o;
    (void)context;
    if (dk_py_opt_double(kw, "w", &opt->w) < 0 ||
        dk_py_opt_bool(kw, "orientation", &opt->orientation) < 0)
        return -1;
    PyObject *mat = dk_py_opt_object(kw, "material");
    if (!mat)
        return PyErr_Occurred() ? -1 : 0;
    int rc = 0;
    if (mat != Py_None) {
        dk_py_doubles in = {0};
        rc = dk_py_read_doubles(mat, -1, 0, "material", &in);
        if (rc == 0) {
            opt->material = in.data; /* owned until release_options */
            opt->n_material = (dk_index)in.rows;
        }
    }
    Py_DECREF(mat);
    return rc;
}

static PyObject *get_frames(PyObject *obj, void *c)
{
    if (!dk_py_method_readable((dk_py_method *)obj))
        return NULL;
    dk_py_method *self = (dk_py_method *)obj;
    const dk_index nf = self->mesh->n_faces;
    double *out;
    (void)c;
    PyObject *a = dk_py_new_doubles(2, nf, 9, &out);
    if (a)
        memcpy(out, dk_fundamental_frames(self->native), 9 * (size_t)nf * sizeof(double));
    return a;
}

static PyObject *get_transform_basis(PyObject *obj, void *c)
{
    if (!dk_py_method_readable((dk_py_method *)obj))
        return NULL;
    (void)c;
    return PyBool_FromLong(dk_fundamental_has_transform_basis(((dk_py_method *)obj)->native));
}

PyDoc_STRVAR(solve_doc,
             "solve(targets=None, transforms=None, energy=True) -> SolveResult\n\n"
             "One linear solve for positions and frames together (eq. 7 with the handle and\n"
             "fixed vertices, and with orientation constraints the frames of their faces,\n"
             "held). energy: w E_f + E_x. The frames are in `frames` afterwards.");

PyDoc_STRVAR(lr_doc,
             "LinearReconstruction(mesh, handles, fixed=None, w=1.0, orientation=False,\n"
             "    material=None, progress=None)\n\n"
             "Surface deformation by linear reconstruction from the discrete fundamental\n"
             "forms (Li, after Wang, Liu & Tong 2012): edge lengths and dihedral angles of\n"
             "the rest mesh, a frame per triangle, and one sparse linear system for the\n"
             "positions and frames. Handles and fixed vertices are hard constraints; with\n"
             "orientation=True a handle's transform also turns its faces' frames. material:\n"
             "one value per edge (Mesh.edges order), multiplying the stretching weights and\n"
             "dividing the bending ones: > 1 folds more easily there (the add-on's Softness s\n"
             "paints 20**s), < 1 resists folding (the paper's 'soft', which measured spreads\n"
             "a fold away). progress(fraction) is called during\n"
             "the bind with a deformkit.BindProgress (fraction.phase: forms, constraints,\n"
             "assemble, analyze, factorize, basis, then 'done' at 1); a true return or an\n"
             "exception stops it (the exception propagates). rebind(progress=...) reports\n"
             "the same from constraints on; a cancelled rebind keeps the previous binding.\n"
             "See docs/methods/fundamental.md.");

static PyGetSetDef lr_getset[] = {
    DK_PY_METHOD_GETSET,
    {"frames", get_frames, NULL,
     "n_faces x 9: each face's frame (row-major 3 x 3, columns e1, e2, normal) of the last "
     "solve",
     NULL},
    {"transform_basis", get_transform_basis, NULL,
     "True when solve(transforms=...) combines solutions precomputed at bind (the result is "
     "affine in the transforms' entries): one small product per drag instead of two "
     "triangular solves. False when a component is regularized or it would take > 256 MB",
     NULL},
    {NULL, NULL, NULL, NULL, NULL},
};

static PyMethodDef lr_methods[] = {
    DK_PY_METHOD_METHODS(solve_doc),
    {NULL, NULL, 0, NULL},
};

/* progress=: the shared callback (dk_py.h), phases named by the native bind / rebind */
static void bind_progress(void *options, dk_py_progress *p)
{
    ((dk_fundamental_options *)options)->progress = dk_py_progress_phase;
    ((dk_fundamental_options *)options)->progress_user = p;
}

static void rebind_progress(void *native, dk_py_progress *p)
{
    dk_fundamental_set_progress((dk_fundamental *)native, p ? dk_py_progress_phase : NULL, p);
}

static const dk_py_method_spec lr_spec = {
    .name = "LinearReconstruction",
    .type_name = "deformkit.LinearReconstruction",
    .ops = &dk_fundamental_ops,
    .doc = lr_doc,
    .options_size = sizeof(dk_fundamental_options),
    .default_options = default_options,
    .parse_options = parse_options,
    .release_options = release_options,
    .bind_progress = bind_progress,
    .rebind_progress = rebind_progress,
    .getset = lr_getset,
    .methods = lr_methods,
};

static PyObject *lr_new(PyTypeObject *type, PyObject *args, PyObject *kwargs)
{
    return dk_py_method_new(type, args, kwargs, &lr_spec);
}

int dk_py_init_fundamental(PyObject *module)
{
    return dk_py_method_register(module, &lr_spec, lr_new);
}
