/* DeformKit CPython module: deformkit.ShapeInterpolation (native/methods/
 * dk_shape_interpolation.h), on the generic method type (dk_py_method.h) as a method bound to
 * vertex groups with poses beside them. What is its own: the poses keyword, its options and
 * n_poses. */
#include "dk_py_method.h"

#include "dk_shape_interpolation.h"

#include <math.h>
#include <stdio.h>
#include <string.h>

static const char *const rotations_names[] = {"consistent", "principal", NULL};
static const char *const stretches_names[] = {"linear", "log", NULL};
static const char *const edge_weights_names[] = {"clamped_cotangent", "cotangent", "uniform",
                                                 NULL};

static void default_options(void *o)
{
    dk_shape_interpolation_default_options((dk_shape_interpolation_options *)o);
}

static int parse_options(PyObject *kw, void *o, const char *context)
{
    dk_shape_interpolation_options *opt = (dk_shape_interpolation_options *)o;
    int r = (int)opt->rotations, w = (int)opt->edge_weights, st = (int)opt->stretches;
    if (dk_py_opt_choice(kw, "rotations", rotations_names, &r, context) < 0 ||
        dk_py_opt_choice(kw, "stretches", stretches_names, &st, context) < 0 ||
        dk_py_opt_int(kw, "refine", &opt->refine) < 0 ||
        dk_py_opt_choice(kw, "edge_weights", edge_weights_names, &w, context) < 0)
        return -1;
    opt->rotations = (dk_shape_interpolation_rotations)r;
    opt->stretches = (dk_shape_interpolation_stretches)st;
    opt->edge_weights = (dk_shape_interpolation_weights)w;
    return 0;
}

/* What parse_control writes: the control, then the poses it points to (PyMem). */
typedef struct poses_store {
    dk_control_desc control;
    double *data;
} poses_store;

static void release_control(void *store)
{
    poses_store *s = (poses_store *)store;
    PyMem_Free(s->data);
    s->data = NULL;
}

/* poses: a sequence of example shapes, each n x 3 (a P x n x 3 array is one); absent or None:
 * no control (the constructor: no poses; rebind: the bound ones stay). */
static int parse_control(PyObject *kw, const dk_mesh *mesh, const void *bound, void *store,
                         const char *context)
{
    (void)bound;
    poses_store *s = (poses_store *)store;
    PyObject *obj = dk_py_opt_object(kw, "poses");
    if (!obj)
        return PyErr_Occurred() ? -1 : 0;
    if (obj == Py_None) {
        Py_DECREF(obj);
        return 0;
    }
    PyObject *seq = PySequence_Check(obj) ? PySequence_List(obj) : NULL; /* a copy: read once */
    if (!seq && !PyErr_Occurred())
        PyErr_Format(PyExc_TypeError, "%s: poses must be a sequence of n x 3 arrays", context);
    Py_DECREF(obj);
    if (!seq)
        return -1;
    const Py_ssize_t P = PyList_Size(seq), n = mesh->n_vertices;
    if (P < 1 || P > 100000) {
        PyErr_Format(PyExc_ValueError, "%s: poses has %zd shapes, give 1 to 100000 (or None)",
                     context, P);
        Py_DECREF(seq);
        return -1;
    }
    s->data = PyMem_Malloc((size_t)P * (size_t)n * 3 * sizeof(double) + 1);
    if (!s->data) {
        Py_DECREF(seq);
        PyErr_NoMemory();
        return -1;
    }
    for (Py_ssize_t k = 0; k < P; k++) {
        char name[48];
        snprintf(name, sizeof name, "poses[%zd]", k);
        dk_py_doubles p = {0};
        if (dk_py_read_doubles(PyList_GetItem(seq, k), n, 3, name, &p) < 0) {
            Py_DECREF(seq);
            return -1;
        }
        memcpy(s->data + (size_t)k * (size_t)n * 3, p.data, (size_t)n * 3 * sizeof(double));
        dk_py_doubles_release(&p);
    }
    Py_DECREF(seq);
    s->control = (dk_control_desc){.kind = DK_CONTROL_POSES, .n_controls = (dk_index)P,
                                   .rest = s->data};
    return 0;
}

static PyObject *get_n_poses(PyObject *obj, void *c)
{
    (void)c;
    if (!dk_py_method_readable((dk_py_method *)obj))
        return NULL;
    return PyLong_FromLong((long)dk_shape_interpolation_n_poses(((dk_py_method *)obj)->native));
}

PyDoc_STRVAR(solve_doc,
             "solve(weights=None, targets=None, transforms=None, input_positions=None,\n"
             "      energy=True) -> SolveResult\n\n"
             "weights: one per pose (required when the bind has poses; the rest weighs 1 -\n"
             "sum(weights), as Blender's relative shape keys), any real values: 0 and 1 give\n"
             "the rest and the poses, values between them in-betweens, beyond them\n"
             "extrapolations. targets / transforms: the handles' positions or 4 x 4\n"
             "transforms when the bind has handles. input_positions (n x 3): the pose to edit\n"
             "instead of the rest (its triangles' own turn kept under the blend). A direct\n"
             "method: the start and iteration keywords change nothing; energy is the\n"
             "least-squares misfit of the edges to their blended gradients, iterations 1.");

PyDoc_STRVAR(shape_interpolation_doc,
             "ShapeInterpolation(mesh, handles=None, fixed=None, roi=None, handle_weights=None,\n"
             "                   poses=None, rotations='consistent', stretches='linear',\n"
             "                   refine=0, edge_weights='clamped_cotangent', progress=None)\n\n"
             "In-betweens of example poses that keep the shape (the slides' shape\n"
             "interpolation; Alexa, Cohen-Or, Levin 2000; the gradient-domain solve of Xu et al.\n"
             "2005): every triangle's gradient from the rest to each pose is split into a\n"
             "rotation and a stretch, those are blended separately for the solve's weights,\n"
             "and the positions are the least-squares fit of the edges to the blended\n"
             "gradients (one prefactored back-substitution). poses: a sequence of n x 3\n"
             "shapes of the mesh (a P x n x 3 array is one). rotations: 'consistent' (each\n"
             "triangle's rotation angle chosen across the mesh, so a part turned beyond 180\n"
             "degrees, or a bar twisted by 360, keeps turning the same way in between; the\n"
             "default) or 'principal' (each angle within [0, pi]: for comparison).\n"
             "stretches: 'linear' (I + sum w (S - I), the paper's: exact for bends; the\n"
             "default) or 'log' (exp(sum w log S): keeps areas under shears, as a wide body\n"
             "twisted; about twice the solve's time). refine: local/global iterations that\n"
             "fit each triangle's rotation to the blended shape, its blended stretch kept\n"
             "(0 to 100; a bar twisted by 360 degrees narrows in the middle without them;\n"
             "each costs about twice the blend).\n"
             "edge_weights: 'clamped_cotangent' (default), 'cotangent' or 'uniform'. Handles\n"
             "and fixed vertices are optional and kept exactly, so an in-between can be\n"
             "pinned; a part without any follows the linear blend's mean. rebind(poses=...)\n"
             "takes other poses; rebind(handles=...) other groups, the poses kept. See\n"
             "docs/methods/shape_interpolation.md.");

static PyMethodDef si_methods[] = {
    DK_PY_METHOD_METHODS(solve_doc),
    {NULL, NULL, 0, NULL},
};

static PyGetSetDef si_getset[] = {
    DK_PY_METHOD_GETSET,
    {"n_poses", get_n_poses, NULL, "the poses bound (0: none)", NULL},
    {NULL, NULL, NULL, NULL, NULL},
};

static void bind_progress(void *options, dk_py_progress *p)
{
    ((dk_shape_interpolation_options *)options)->progress = dk_py_progress_phase;
    ((dk_shape_interpolation_options *)options)->progress_user = p;
}

static void rebind_progress(void *native, dk_py_progress *p)
{
    dk_shape_interpolation_set_progress((dk_shape_interpolation *)native,
                                        p ? dk_py_progress_phase : NULL, p);
}

static const dk_py_method_spec si_spec = {
    .name = "ShapeInterpolation",
    .type_name = "deformkit.ShapeInterpolation",
    .ops = &dk_shape_interpolation_ops,
    .doc = shape_interpolation_doc,
    .handles_optional = 1,
    .options_size = sizeof(dk_shape_interpolation_options),
    .default_options = default_options,
    .parse_options = parse_options,
    .bind_progress = bind_progress,
    .rebind_progress = rebind_progress,
    .parse_control = parse_control,
    .release_control = release_control,
    .control_with_groups = 1,
    .control_values = "weights",
    .control_values_of = "poses",
    .getset = si_getset,
    .methods = si_methods,
};

static PyObject *si_new(PyTypeObject *type, PyObject *args, PyObject *kwargs)
{
    return dk_py_method_new(type, args, kwargs, &si_spec);
}

int dk_py_init_shape_interpolation(PyObject *module)
{
    return dk_py_method_register(module, &si_spec, si_new);
}
