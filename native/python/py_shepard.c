/* DeformKit CPython module: deformkit.Shepard (native/methods/dk_shepard.h), on the generic
 * method type (dk_py_method.h). What is Shepard's own: its options, and weights(v). */
#include "dk_py_method.h"

#include "dk_shepard.h"

static const char *const neighbourhood_names[] = {"all", "nearest", "radius", NULL};
static const char *const interpolate_names[] = {"transforms", "displacements", NULL};
static const char *const distance_names[] = {"euclidean", "geodesic", NULL};

static void default_options(void *o)
{
    dk_shepard_default_options((dk_shepard_options *)o);
}

static int parse_options(PyObject *kw, void *o, const char *context)
{
    dk_shepard_options *opt = (dk_shepard_options *)o;
    int nb = (int)opt->neighbourhood, in = (int)opt->interpolate, di = (int)opt->distance;
    if (dk_py_opt_double(kw, "power", &opt->power) < 0 ||
        dk_py_opt_choice(kw, "neighbourhood", neighbourhood_names, &nb, context) < 0 ||
        dk_py_opt_int(kw, "k", &opt->k) < 0 ||
        dk_py_opt_double(kw, "radius", &opt->radius) < 0 ||
        dk_py_opt_choice(kw, "interpolate", interpolate_names, &in, context) < 0 ||
        dk_py_opt_choice(kw, "distance", distance_names, &di, context) < 0)
        return -1;
    opt->distance = (dk_shepard_distance)di;
    opt->neighbourhood = (dk_shepard_neighbourhood)nb;
    opt->interpolate = (dk_shepard_interpolate)in;
    return 0;
}

PyDoc_STRVAR(weights_doc,
             "weights(v) -> (weights, distances): vertex v's weight of every group (the\n"
             "handles in order, then the fixed vertices when there are any: n_groups) and\n"
             "its distance to each group's nearest vertex, as bound (zeros and inf for a\n"
             "constrained vertex).");

static PyObject *shepard_weights_of(PyObject *obj, PyObject *arg)
{
    dk_py_method *self = (dk_py_method *)obj;
    if (!dk_py_method_readable(self))
        return NULL;
    long v = PyLong_AsLong(arg);
    if (v == -1 && PyErr_Occurred())
        return NULL;
    if (v < 0 || v >= self->mesh->n_vertices) {
        PyErr_Format(PyExc_IndexError, "Shepard.weights: vertex %ld out of range [0, %d)", v,
                     (int)self->mesh->n_vertices);
        return NULL;
    }
    const dk_index g = dk_shepard_n_groups(self->native);
    double *wp, *dp;
    PyObject *w = dk_py_new_doubles(1, g, 0, &wp);
    PyObject *d = w ? dk_py_new_doubles(1, g, 0, &dp) : NULL;
    if (!d) {
        Py_XDECREF(w);
        return NULL;
    }
    dk_shepard_vertex_weights(self->native, (dk_index)v, wp, dp);
    return Py_BuildValue("(NN)", w, d);
}

PyDoc_STRVAR(solve_doc,
             "solve(targets=None, transforms=None, warm_start=True, max_iterations=None,\n"
             "      resume=False, energy=True, preview=False, start_positions=None,\n"
             "      input_positions=None) -> SolveResult\n\n"
             "targets: (sum of handle sizes) x 3 positions, concatenated in handle order;\n"
             "transforms: n_handles x 4 x 4 affine transforms of the rest pose. Every free\n"
             "vertex moves by the Shepard-weighted motion of its data points (with\n"
             "interpolate='transforms' and transforms given: each handle's transform applied\n"
             "to the vertex). A direct method: the start and iteration keywords change\n"
             "nothing. Returns the positions, the sum of squared displacements as energy,\n"
             "iterations = 1 and converged = True.");

PyDoc_STRVAR(shepard_doc,
             "Shepard(mesh, handles, fixed=None, roi=None, handle_weights=None, power=2.0,\n"
             "        neighbourhood='all', k=4, radius=0.0, interpolate='transforms',\n"
             "        distance='euclidean', progress=None)\n\n"
             "Shepard interpolation (inverse distance weighting, the slides' scattered data\n"
             "interpolation) of the handles' motion: each handle group and the fixed vertices\n"
             "are data points at the distance d_g of their nearest vertex; a free vertex\n"
             "moves by sum_g phi_g f_g, phi_g = w_g / sum_j w_j. neighbourhood: 'all' (every\n"
             "group, d^-p: the slides' formula; the default), 'nearest' (its k nearest groups,\n"
             "Franke-Little weights ((R - d)/(R d))^p with R the (k+1)-th distance:\n"
             "continuous) or 'radius' (those within radius, at most k; radius 0 = a quarter of\n"
             "the bounding-box diagonal). interpolate: 'transforms' (each handle's transform\n"
             "applied to the vertex: linear nodal functions, no flat spots at the data; the\n"
             "default) or 'displacements' (the displacement of the group's nearest vertex:\n"
             "the slides' formula, within the data's range, flat at the data for p > 1).\n"
             "distance: 'euclidean' (straight through space) or 'geodesic' (along the surface,\n"
             "the heat method: a part touching another in space is not pulled by it).\n"
             "See docs/methods/shepard.md.");

static PyMethodDef shepard_methods[] = {
    DK_PY_METHOD_METHODS(solve_doc),
    {"weights", shepard_weights_of, METH_O, weights_doc},
    {NULL, NULL, 0, NULL},
};

static PyGetSetDef shepard_getset[] = {
    DK_PY_METHOD_GETSET,
    {NULL, NULL, NULL, NULL, NULL},
};

static void bind_progress(void *options, dk_py_progress *p)
{
    ((dk_shepard_options *)options)->progress = dk_py_progress_phase;
    ((dk_shepard_options *)options)->progress_user = p;
}

static void rebind_progress(void *native, dk_py_progress *p)
{
    dk_shepard_set_progress((dk_shepard *)native, p ? dk_py_progress_phase : NULL, p);
}

static const dk_py_method_spec shepard_spec = {
    .name = "Shepard",
    .type_name = "deformkit.Shepard",
    .ops = &dk_shepard_ops,
    .doc = shepard_doc,
    .options_size = sizeof(dk_shepard_options),
    .default_options = default_options,
    .parse_options = parse_options,
    .bind_progress = bind_progress,
    .rebind_progress = rebind_progress,
    .getset = shepard_getset,
    .methods = shepard_methods,
};

static PyObject *shepard_new(PyTypeObject *type, PyObject *args, PyObject *kwargs)
{
    return dk_py_method_new(type, args, kwargs, &shepard_spec);
}

int dk_py_init_shepard(PyObject *module)
{
    return dk_py_method_register(module, &shepard_spec, shepard_new);
}
