/* DeformKit CPython module: deformkit.Falloff (native/methods/dk_falloff.h), on the generic
 * method type (dk_py_method.h). What is Falloff's own: its options, and weights(). */
#include "dk_py_method.h"

#include "dk_falloff.h"

static const char *const distance_names[] = {"hops", "euclidean", "geodesic", "dijkstra",
                                             NULL};
static const char *const reach_names[] = {"range", "fixed", NULL};

static void default_options(void *o)
{
    dk_falloff_default_options((dk_falloff_options *)o);
}

static int parse_options(PyObject *kw, void *o, const char *context)
{
    dk_falloff_options *opt = (dk_falloff_options *)o;
    int distance = (int)opt->distance, reach = (int)opt->reach;
    if (dk_py_opt_choice(kw, "distance", distance_names, &distance, context) < 0 ||
        dk_py_opt_choice(kw, "reach", reach_names, &reach, context) < 0 ||
        dk_py_opt_double(kw, "range", &opt->range) < 0 ||
        dk_py_opt_double(kw, "k", &opt->k) < 0 ||
        dk_py_opt_double(kw, "heat_time_factor", &opt->heat_time_factor) < 0)
        return -1;
    opt->distance = (dk_falloff_distance)distance;
    opt->reach = (dk_falloff_reach)reach;
    return 0;
}

PyDoc_STRVAR(weights_doc,
             "weights(group) -> (distances, S): per-vertex distance from handle group `group`\n"
             "(INFINITY where unreachable) and attenuation S (0 for constrained vertices and\n"
             "beyond the range), as computed at bind.");

static PyObject *falloff_weights(PyObject *obj, PyObject *arg)
{
    dk_py_method *self = (dk_py_method *)obj;
    PyObject *d, *w = NULL;
    double *dp, *wp;
    dk_method_stats ms;
    long g = PyLong_AsLong(arg);
    if (g == -1 && PyErr_Occurred())
        return NULL;
    /* held busy while it reads: the allocations below may run Python, and a rebind in
     * another thread (or from a progress callback) frees what it reads */
    if (dk_py_method_enter(self) < 0)
        return NULL;
    dk_falloff_stats(self->native, &ms);
    if (g < 0 || g >= ms.n_handles) {
        PyErr_Format(PyExc_IndexError, "Falloff.weights: group %ld out of range [0, %d)", g,
                     (int)ms.n_handles);
        self->busy = 0;
        return NULL;
    }
    d = dk_py_new_doubles(1, self->mesh->n_vertices, 0, &dp);
    if (d)
        w = dk_py_new_doubles(1, self->mesh->n_vertices, 0, &wp);
    if (w)
        for (dk_index v = 0; v < self->mesh->n_vertices; v++)
            dk_falloff_vertex_weight(self->native, (dk_index)g, v, dp + v, wp + v);
    self->busy = 0;
    if (!w) {
        Py_XDECREF(d);
        return NULL;
    }
    return Py_BuildValue("(NN)", d, w);
}

PyDoc_STRVAR(solve_doc,
             "solve(targets=None, transforms=None, warm_start=True, max_iterations=None,\n"
             "      resume=False, energy=True, preview=False, start_positions=None)\n"
             "      -> SolveResult\n\n"
             "preview=True (the contract's keyword) solves as usual: this method has no\n"
             "faster result to show.\n"
             "targets: (sum of handle sizes) x 3 positions, concatenated in handle order;\n"
             "transforms: n_handles x 4 x 4 affine transforms of the rest pose (blended into\n"
             "the identity by S per vertex). A direct method: the start and iteration\n"
             "keywords change nothing. Returns the positions, the sum of squared\n"
             "displacements as energy, iterations = 1 and converged = True.");

PyDoc_STRVAR(falloff_doc,
             "Falloff(mesh, handles, fixed=None, roi=None, handle_weights=None,\n"
             "        stiffness=None, distance='euclidean', range=0.0, reach='fixed', k=0.0,\n"
             "        heat_time_factor=0.0, progress=None)\n\n"
             "Attenuated handle displacement (lecture slides 5-7): every free vertex moves by\n"
             "S(d) times the displacement of its nearest handle vertex (or S(d) (T p - p) for\n"
             "transforms), S(i) = 1 - (i/(n+1))^(k+1) for k >= 0, (1 - i/(n+1))^(1-k) for\n"
             "k < 0, 0 beyond the range. distance: 'hops' (range in edges), 'euclidean',\n"
             "'geodesic' (heat method) or 'dijkstra' (range a length; the formula is applied\n"
             "in units of the mean edge length). range 0 = a quarter of the bounding-box\n"
             "diagonal (hops: that in mean edge lengths). reach='fixed' (the default): each\n"
             "group's range is its distance to the nearest fixed vertex (the pull fades out\n"
             "where the fixed part begins; `range` for a group that reaches none, or without\n"
             "a fixed group); reach='range': `range` for every group. `ranges` holds the\n"
             "range of each group.\n"
             "Several groups add up. stiffness is not supported (ValueError). progress: as\n"
             "ARAP's (phases heat -- geodesic only -- and distances). See\n"
             "docs/methods/falloff.md.");

static PyObject *get_ranges(PyObject *obj, void *c)
{
    if (!dk_py_method_readable((dk_py_method *)obj))
        return NULL;
    dk_py_method *self = (dk_py_method *)obj;
    dk_method_stats ms;
    double *out;
    (void)c;
    dk_falloff_stats(self->native, &ms);
    PyObject *a = dk_py_new_doubles(1, ms.n_handles, 0, &out);
    for (dk_index g = 0; a && g < ms.n_handles; g++)
        out[g] = dk_falloff_group_range(self->native, g);
    return a;
}

static PyGetSetDef falloff_getset[] = {
    DK_PY_METHOD_GETSET,
    {"ranges", get_ranges, NULL,
     "n_handles: the range each handle group uses, in the distance's units (edges for "
     "'hops'): `range`, or with reach='fixed' its distance to the fixed part",
     NULL},
    {NULL, NULL, NULL, NULL, NULL},
};

static PyMethodDef falloff_methods[] = {
    DK_PY_METHOD_METHODS(solve_doc),
    {"weights", falloff_weights, METH_O, weights_doc},
    {NULL, NULL, 0, NULL},
};

/* progress=: the shared callback (dk_py.h), phases named by the native bind / rebind */
static void bind_progress(void *options, dk_py_progress *p)
{
    ((dk_falloff_options *)options)->progress = dk_py_progress_phase;
    ((dk_falloff_options *)options)->progress_user = p;
}

static void rebind_progress(void *native, dk_py_progress *p)
{
    dk_falloff_set_progress((dk_falloff *)native, p ? dk_py_progress_phase : NULL, p);
}

static const dk_py_method_spec falloff_spec = {
    .name = "Falloff",
    .type_name = "deformkit.Falloff",
    .ops = &dk_falloff_ops,
    .doc = falloff_doc,
    .options_size = sizeof(dk_falloff_options),
    .default_options = default_options,
    .parse_options = parse_options,
    .bind_progress = bind_progress,
    .rebind_progress = rebind_progress,
    .getset = falloff_getset,
    .methods = falloff_methods,
};

static PyObject *falloff_new(PyTypeObject *type, PyObject *args, PyObject *kwargs)
{
    return dk_py_method_new(type, args, kwargs, &falloff_spec);
}

int dk_py_init_falloff(PyObject *module)
{
    return dk_py_method_register(module, &falloff_spec, falloff_new);
}
