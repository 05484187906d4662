/* DeformKit CPython module: deformkit.Lattice (native/methods/dk_lattice.h), on the generic
 * method type (dk_py_method.h) as a method bound to a control. What is Lattice's own: its
 * control's keywords (resolution, frame), its options, rest_points. */
#include "dk_py_method.h"

#include "dk_lattice.h"

#include <math.h>
#include <string.h>

static const char *const interpolation_names[] = {"linear", "bernstein", "bspline", NULL};
static const char *const outside_names[] = {"extend", "clamp", "still", NULL};

/* The default box grows the mesh's bounding box by this part of each side (and, for a flat
 * mesh, of the diagonal), so that no vertex sits on its border. */
#define LATTICE_MARGIN 0.05

static void default_options(void *o)
{
    dk_lattice_default_options((dk_lattice_options *)o);
}

static int parse_options(PyObject *kw, void *o, const char *context)
{
    dk_lattice_options *opt = (dk_lattice_options *)o;
    int interpolation = (int)opt->interpolation, outside = (int)opt->outside;
    if (dk_py_opt_choice(kw, "interpolation", interpolation_names, &interpolation, context) <
            0 ||
        dk_py_opt_choice(kw, "outside", outside_names, &outside, context) < 0)
        return -1;
    opt->interpolation = (dk_lattice_interpolation)interpolation;
    opt->outside = (dk_lattice_outside)outside;
    return 0;
}

/* What parse_control writes: the control, then the frame it points to. */
typedef struct lattice_store {
    dk_control_desc control;
    double frame[16];
} lattice_store;

/* The mesh's bounding box grown by LATTICE_MARGIN, as a frame (row-major 4 x 4). */
static void box_around(const dk_mesh *m, double *F)
{
    const double *lo = m->bbox_min, *hi = m->bbox_max;
    const double diag = m->bbox_diagonal > 0.0 ? m->bbox_diagonal : 1.0;
    memset(F, 0, 16 * sizeof(double));
    for (int d = 0; d < 3; d++) {
        const double pad = LATTICE_MARGIN * (hi[d] - lo[d]) + 1e-3 * diag;
        F[5 * d] = hi[d] - lo[d] + 2.0 * pad;
        F[4 * d + 3] = lo[d] - pad;
    }
    F[15] = 1.0;
}

static int parse_control(PyObject *kw, const dk_mesh *mesh, const void *bound, void *store,
                         const char *context)
{
    lattice_store *s = (lattice_store *)store;
    dk_index res[3] = {3, 3, 3};
    if (bound)
        dk_lattice_get((const dk_lattice *)bound, res, s->frame, NULL);
    else
        box_around(mesh, s->frame);
    PyObject *r = dk_py_opt_object(kw, "resolution");
    if (!r && PyErr_Occurred())
        return -1;
    if (r) {
        dk_py_indices idx = {0};
        const int bad = dk_py_read_indices(r, 3, 0, "resolution", &idx) < 0;
        Py_DECREF(r);
        if (bad)
            return -1;
        for (int d = 0; d < 3; d++)
            res[d] = idx.data[d];
        dk_py_indices_release(&idx);
        for (int d = 0; d < 3; d++)
            if (res[d] < 2) {
                PyErr_Format(PyExc_ValueError, "%s: resolution %d %d %d: at least 2 points "
                             "along each axis", context, (int)res[0], (int)res[1], (int)res[2]);
                return -1;
            }
    }
    PyObject *f = dk_py_opt_object(kw, "frame");
    if (!f && PyErr_Occurred())
        return -1;
    if (f && f != Py_None) {
        dk_py_doubles fr = {0};
        const int bad = dk_py_read_doubles(f, 4, 4, "frame", &fr) < 0;
        Py_DECREF(f);
        if (bad)
            return -1;
        memcpy(s->frame, fr.data, sizeof s->frame);
        dk_py_doubles_release(&fr);
    } else if (f) { /* None: the box around the mesh */
        Py_DECREF(f);
        box_around(mesh, s->frame);
    }
    s->control = (dk_control_desc){.kind = DK_CONTROL_LATTICE,
                                   .n_controls = res[0] * res[1] * res[2],
                                   .rest = s->frame,
                                   .resolution = {res[0], res[1], res[2]}};
    return 0;
}

static PyObject *get_rest_points(PyObject *obj, void *c)
{
    (void)c;
    if (!dk_py_method_readable((dk_py_method *)obj))
        return NULL;
    dk_py_method *self = (dk_py_method *)obj;
    dk_index res[3];
    double *out;
    dk_lattice_get(self->native, res, NULL, NULL);
    PyObject *a = dk_py_new_doubles(2, (Py_ssize_t)res[0] * res[1] * res[2], 3, &out);
    if (a)
        dk_lattice_get(self->native, NULL, NULL, out);
    return a;
}

static PyObject *get_resolution(PyObject *obj, void *c)
{
    (void)c;
    if (!dk_py_method_readable((dk_py_method *)obj))
        return NULL;
    dk_index res[3];
    dk_lattice_get(((dk_py_method *)obj)->native, res, NULL, NULL);
    return Py_BuildValue("(iii)", (int)res[0], (int)res[1], (int)res[2]);
}

static PyObject *get_frame(PyObject *obj, void *c)
{
    (void)c;
    if (!dk_py_method_readable((dk_py_method *)obj))
        return NULL;
    double *out;
    PyObject *a = dk_py_new_doubles(2, 4, 4, &out);
    if (a)
        dk_lattice_get(((dk_py_method *)obj)->native, NULL, out, NULL);
    return a;
}

static PyGetSetDef lattice_getset[] = {
    DK_PY_METHOD_GETSET,
    {"rest_points", get_rest_points, NULL,
     "n_points x 3: the lattice points at rest, x fastest, then y, then z (index i + l (j + "
     "m k)): solve(targets=...) takes their new positions in this order",
     NULL},
    {"resolution", get_resolution, NULL, "(l, m, n): the points along x, y, z", NULL},
    {"frame", get_frame, NULL, "4 x 4: the affine map of the unit cube onto the box", NULL},
    {NULL, NULL, NULL, NULL, NULL},
};

PyDoc_STRVAR(solve_doc,
             "solve(targets, input_positions=None, energy=True) -> SolveResult\n\n"
             "targets: the lattice points' positions, n_points x 3 in rest_points' order\n"
             "(transforms are refused: a lattice has no handles). Every vertex moves by the\n"
             "weighted motion of the points (rest_points as targets give the mesh back\n"
             "exactly). input_positions (n x 3): the pose to deform instead of the rest,\n"
             "registered to the lattice where it lies. A direct method: the start and\n"
             "iteration keywords change nothing; energy is the sum of squared\n"
             "displacements, iterations 1.");

static PyMethodDef lattice_methods[] = {
    DK_PY_METHOD_METHODS(solve_doc),
    {NULL, NULL, 0, NULL},
};

PyDoc_STRVAR(lattice_doc,
             "Lattice(mesh, resolution=(3, 3, 3), frame=None, interpolation='bspline',\n"
             "        outside='extend')\n\n"
             "Lattice free-form deformation (the lecture's FFD): l x m x n points over a box\n"
             "(frame: the 4 x 4 affine map of the unit cube onto it; None: the mesh's\n"
             "bounding box grown by 5%); every vertex moves by the weighted motion of the\n"
             "points. interpolation: 'linear' (trilinear, the slides), 'bernstein'\n"
             "(Sederberg-Parry, every point weighs on every vertex, at most 32 per axis) or\n"
             "'bspline' (uniform cubic, the lattice extended linearly past its ends: border\n"
             "points are interpolated). Affine maps of the points move the mesh by them.\n"
             "outside: 'extend' (the border cell continued), 'clamp' (the motion at the\n"
             "box's nearest point, as Blender's linear lattice) or 'still' (that motion\n"
             "fading to none one cell beyond the box). rebind(resolution=..., frame=...)\n"
             "takes another lattice (absent keywords keep their values). See\n"
             "docs/methods/lattice.md.");

static const dk_py_method_spec lattice_spec = {
    .name = "Lattice",
    .type_name = "deformkit.Lattice",
    .ops = &dk_lattice_ops,
    .doc = lattice_doc,
    .options_size = sizeof(dk_lattice_options),
    .default_options = default_options,
    .parse_options = parse_options,
    .parse_control = parse_control,
    .getset = lattice_getset,
    .methods = lattice_methods,
};

static PyObject *lattice_new(PyTypeObject *type, PyObject *args, PyObject *kwargs)
{
    return dk_py_method_new(type, args, kwargs, &lattice_spec);
}

int dk_py_init_lattice(PyObject *module)
{
    return dk_py_method_register(module, &lattice_spec, lattice_new);
}
