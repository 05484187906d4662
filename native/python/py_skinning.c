/* DeformKit CPython module: deformkit.Skinning (native/methods/dk_skinning.h), on the generic
 * method type (dk_py_method.h) as a method bound to a control (bones). What is Skinning's
 * own: its control's keywords (bone_frames, weights), its option, rest_frames. */
#include "dk_py_method.h"

#include "dk_skinning.h"

#include <string.h>

static const char *const blend_names[] = {"linear", "dual_quaternion", NULL};
static const char *const domain_names[] = {"auto", "volume", "surface", NULL};

static void default_options(void *o)
{
    dk_skinning_default_options((dk_skinning_options *)o);
}

static int parse_options(PyObject *kw, void *o, const char *context)
{
    dk_skinning_options *opt = (dk_skinning_options *)o;
    int b = (int)opt->blend;
    if (dk_py_opt_choice(kw, "blend", blend_names, &b, context) < 0)
        return -1;
    opt->blend = (dk_skinning_blend)b;
    int d = (int)opt->computed.domain;
    if (dk_py_opt_choice(kw, "domain", domain_names, &d, context) < 0 ||
        dk_py_opt_int(kw, "resolution", &opt->computed.resolution) < 0)
        return -1;
    if (opt->computed.resolution < 4 || opt->computed.resolution > 256) {
        PyErr_Format(PyExc_ValueError, "%s: resolution must be in [4, 256], not %d", context,
                     opt->computed.resolution);
        return -1;
    }
    opt->computed.domain = (dk_bbw_domain)d;
    return 0;
}

/* What parse_control writes: the control and the arrays it points to (PyMem). */
typedef struct skinning_store {
    dk_control_desc control;
    dk_py_doubles frames;
    dk_py_doubles weights;
    dk_py_doubles segments;
} skinning_store;

static void release_control(void *store)
{
    skinning_store *s = (skinning_store *)store;
    dk_py_doubles_release(&s->frames);
    dk_py_doubles_release(&s->weights);
    dk_py_doubles_release(&s->segments);
}

static int parse_control(PyObject *kw, const dk_mesh *mesh, const void *bound, void *store,
                         const char *context)
{
    skinning_store *s = (skinning_store *)store;
    (void)bound; /* a rebind takes whole new bones */
    PyObject *f = dk_py_opt_object(kw, "bone_frames");
    PyObject *w = f ? dk_py_opt_object(kw, "weights") : NULL;
    PyObject *g = f && !w && !PyErr_Occurred() ? dk_py_opt_object(kw, "bones") : NULL;
    if (!f || (!w && !g)) {
        Py_XDECREF(f);
        if (!PyErr_Occurred())
            PyErr_Format(PyExc_TypeError, "%s: needs bone_frames (b x 4 x 4: each bone's rest "
                         "frame) and weights (n_vertices x b) or bones (b x 2 x 3: each bone's "
                         "head and tail, to compute the weights from)", context);
        return -1;
    }
    PyObject *flat = dk_py_as_blocks(f, 4, 4, "bone_frames");
    int bad = !flat || dk_py_read_doubles(flat, -1, 16, "bone_frames", &s->frames) < 0;
    Py_XDECREF(flat);
    Py_DECREF(f);
    if (!bad && w)
        bad = dk_py_read_doubles(w, mesh->n_vertices, s->frames.rows, "weights", &s->weights) < 0;
    if (!bad && g) {
        PyObject *gf = dk_py_as_blocks(g, 2, 3, "bones");
        bad = !gf || dk_py_read_doubles(gf, s->frames.rows, 6, "bones", &s->segments) < 0;
        Py_XDECREF(gf);
    }
    Py_XDECREF(w);
    Py_XDECREF(g);
    if (bad)
        return -1;
    s->control = (dk_control_desc){.kind = DK_CONTROL_BONES,
                                   .n_controls = (dk_index)s->frames.rows,
                                   .rest = s->frames.data,
                                   .weights = s->weights.data,
                                   .segments = s->segments.data};
    return 0;
}

static PyObject *get_rest_frames(PyObject *obj, void *c)
{
    (void)c;
    if (!dk_py_method_readable((dk_py_method *)obj))
        return NULL;
    dk_py_method *self = (dk_py_method *)obj;
    dk_method_stats ms;
    double *out;
    dk_skinning_stats(self->native, &ms);
    PyObject *a = dk_py_new_doubles(2, ms.n_controls, 16, &out);
    if (!a)
        return NULL;
    memcpy(out, dk_skinning_rest_frames(self->native),
           16 * sizeof(double) * (size_t)ms.n_controls);
    PyObject *r = PyObject_CallMethod(a, "reshape", "(iii)", -1, 4, 4);
    Py_DECREF(a);
    return r;
}

static PyGetSetDef skinning_getset[] = {
    DK_PY_METHOD_GETSET,
    {"rest_frames", get_rest_frames, NULL,
     "b x 4 x 4: the bones' rest frames, in the order solve(transforms=...) takes them", NULL},
    {NULL, NULL, NULL, NULL, NULL},
};

PyDoc_STRVAR(solve_doc,
             "solve(transforms, input_positions=None, energy=True) -> SolveResult\n\n"
             "transforms: the bones' current frames T_j (b x 4 x 4, in rest_frames' order;\n"
             "positions are refused). Bone j moves the mesh by T_j B_j^-1 (B_j its rest\n"
             "frame): blended linearly per vertex by its weights (linear blend skinning), or\n"
             "as dual quaternions (blend='dual_quaternion'); the rest frames give the mesh\n"
             "back exactly (linear blend; dual quaternions to the weights' rounding, 1e-6 of\n"
             "|p|). input_positions: a pose (n x 3) skinned instead of the rest. A\n"
             "direct method; energy is the sum of squared displacements, iterations 1.");

static PyMethodDef skinning_methods[] = {
    DK_PY_METHOD_METHODS(solve_doc),
    {NULL, NULL, 0, NULL},
};

PyDoc_STRVAR(skinning_doc,
             "Skinning(mesh, bone_frames, weights=None, bones=None, blend='linear',\n"
             "         domain='auto', resolution=24)\n\n"
             "Skinning (the slides' skeletal subspace deformation): each bone's rest frame B_j\n"
             "(b x 4 x 4 affine) and each vertex's weights (n x b, >= 0, rows summing to 1);\n"
             "a solve with the bones' current frames T_j moves vertex i to\n"
             "sum_j w_ij T_j B_j^-1 p_i (blend='linear', linear blend skinning), or blends\n"
             "each bone's rigid part as a unit dual quaternion and its stretch linearly\n"
             "(blend='dual_quaternion': a half-turn twist keeps the limb's girth).\n"
             "Without weights, bones (b x 2 x 3: each bone's head and tail in the mesh's\n"
             "space) give them: bounded biharmonic weights computed at bind (domain and\n"
             "resolution as deformkit.bounded_biharmonic_weights takes them).\n"
             "rebind(bone_frames=..., weights=... or bones=...) takes other bones. See\n"
             "docs/methods/skinning.md.");

static void bind_progress(void *options, dk_py_progress *p)
{
    ((dk_skinning_options *)options)->progress = dk_py_progress_phase;
    ((dk_skinning_options *)options)->progress_user = p;
}

static const dk_py_method_spec skinning_spec = {
    .name = "Skinning",
    .type_name = "deformkit.Skinning",
    .ops = &dk_skinning_ops,
    .doc = skinning_doc,
    .options_size = sizeof(dk_skinning_options),
    .default_options = default_options,
    .parse_options = parse_options,
    .bind_progress = bind_progress,
    .parse_control = parse_control,
    .release_control = release_control,
    .control_transforms = 1,
    .getset = skinning_getset,
    .methods = skinning_methods,
};

static PyObject *skinning_new(PyTypeObject *type, PyObject *args, PyObject *kwargs)
{
    return dk_py_method_new(type, args, kwargs, &skinning_spec);
}

int dk_py_init_skinning(PyObject *module)
{
    return dk_py_method_register(module, &skinning_spec, skinning_new);
}
