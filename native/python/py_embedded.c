/* DeformKit CPython module: deformkit.EmbeddedDeformation (native/methods/dk_embedded.h), on
 * the generic method type (dk_py_method.h). What is its own: its options and the graph. */
#include "dk_py_method.h"

#include "dk_embedded.h"

#include <string.h>

static const char *const node_names[] = {"surface", "vertices", NULL};
static const char *const distance_names[] = {"euclidean", "geodesic", NULL};

static void default_options(void *o)
{
    dk_embedded_default_options((dk_embedded_options *)o);
}

/* cut=(group_a, group_b): two index arrays, copied into options until release_options */
static int parse_cut(PyObject *kw, dk_embedded_options *opt, const char *context)
{
    PyObject *cut = dk_py_opt_object(kw, "cut");
    if (!cut)
        return PyErr_Occurred() ? -1 : 0;
    int rc = -1;
    PyObject *pair = NULL;
    if (cut != Py_None && PySequence_Check(cut) && !PyUnicode_Check(cut))
        pair = PySequence_Tuple(cut); /* read once: the pair cannot change below */
    if (cut == Py_None) {
        rc = 0;
    } else if (!pair || PyTuple_Size(pair) != 2) {
        PyErr_Clear();
        PyErr_Format(PyExc_ValueError,
                     "%s: cut must be a pair (group_a, group_b) of vertex index arrays",
                     context);
    } else {
        dk_py_indices side[2] = {{0}, {0}};
        rc = 0;
        for (int i = 0; i < 2 && rc == 0; i++)
            rc = dk_py_read_indices(PyTuple_GetItem(pair, i), -1, 0,
                                    i ? "cut group B" : "cut group A", &side[i]);
        if (rc == 0 && (side[0].rows == 0 || side[1].rows == 0)) {
            PyErr_Format(PyExc_ValueError,
                         "%s: cut group %c is empty; a cut needs vertices on both sides",
                         context, side[0].rows == 0 ? 'A' : 'B');
            rc = -1;
        }
        if (rc == 0) {
            opt->cut_a = side[0].data;
            opt->n_cut_a = (dk_index)side[0].rows;
            opt->cut_b = side[1].data;
            opt->n_cut_b = (dk_index)side[1].rows;
        } else {
            dk_py_indices_release(&side[0]);
            dk_py_indices_release(&side[1]);
        }
    }
    Py_XDECREF(pair);
    Py_DECREF(cut);
    return rc;
}

static void release_options(void *o)
{
    dk_embedded_options *opt = (dk_embedded_options *)o;
    PyMem_Free((void *)opt->cut_a);
    PyMem_Free((void *)opt->cut_b);
    opt->cut_a = opt->cut_b = NULL;
    opt->n_cut_a = opt->n_cut_b = 0;
}

static int parse_options(PyObject *kw, void *o, const char *context)
{
    dk_embedded_options *opt = (dk_embedded_options *)o;
    int nodes = (int)opt->nodes, distance = (int)opt->distance;
    double seed = (double)opt->seed;
    if (dk_py_opt_choice(kw, "nodes", node_names, &nodes, context) < 0 ||
        dk_py_opt_int(kw, "n_nodes", &opt->n_nodes) < 0 ||
        dk_py_opt_double(kw, "radius", &opt->radius) < 0 ||
        dk_py_opt_int(kw, "k", &opt->k) < 0 ||
        dk_py_opt_choice(kw, "distance", distance_names, &distance, context) < 0 ||
        dk_py_opt_double(kw, "w_rot", &opt->w_rot) < 0 ||
        dk_py_opt_double(kw, "w_reg", &opt->w_reg) < 0 ||
        dk_py_opt_double(kw, "w_con", &opt->w_con) < 0 ||
        dk_py_opt_double(kw, "tolerance", &opt->tolerance) < 0 ||
        dk_py_opt_int(kw, "max_iterations", &opt->max_iterations) < 0 ||
        dk_py_opt_double(kw, "seed", &seed) < 0 || parse_cut(kw, opt, context) < 0)
        return -1;
    if (!(seed >= 0.0 && seed < 9007199254740992.0 && seed == (double)(uint64_t)seed)) {
        PyErr_Format(PyExc_ValueError, "%s: seed must be a whole number in [0, 2^53)", context);
        return -1;
    }
    opt->nodes = (dk_ed_node_source)nodes;
    opt->distance = (dk_ed_distance)distance;
    opt->seed = (uint64_t)seed;
    return 0;
}

static PyObject *get_nodes(PyObject *obj, void *c)
{
    if (!dk_py_method_readable((dk_py_method *)obj))
        return NULL;
    dk_py_method *self = (dk_py_method *)obj;
    const dk_index m = dk_embedded_n_nodes(self->native);
    double *out;
    (void)c;
    PyObject *a = dk_py_new_doubles(2, m, 3, &out);
    if (a)
        memcpy(out, dk_embedded_nodes(self->native), 3 * (size_t)m * sizeof(double));
    return a;
}

static PyObject *get_transforms(PyObject *obj, void *c)
{
    if (!dk_py_method_readable((dk_py_method *)obj))
        return NULL;
    dk_py_method *self = (dk_py_method *)obj;
    const dk_index m = dk_embedded_n_nodes(self->native);
    double *out;
    (void)c;
    PyObject *a = dk_py_new_doubles(2, m, 12, &out);
    if (a)
        memcpy(out, dk_embedded_transforms(self->native), 12 * (size_t)m * sizeof(double));
    return a;
}

static PyObject *get_edges(PyObject *obj, void *c)
{
    if (!dk_py_method_readable((dk_py_method *)obj))
        return NULL;
    dk_py_method *self = (dk_py_method *)obj;
    const dk_index ne = dk_embedded_n_edges(self->native);
    dk_index *out;
    (void)c;
    PyObject *a = dk_py_new_indices(2, ne, 2, &out);
    if (a)
        memcpy(out, dk_embedded_edges(self->native), 2 * (size_t)ne * sizeof(dk_index));
    return a;
}

static PyObject *get_fixed_nodes(PyObject *obj, void *c)
{
    if (!dk_py_method_readable((dk_py_method *)obj))
        return NULL;
    dk_py_method *self = (dk_py_method *)obj;
    const dk_index m = dk_embedded_n_nodes(self->native);
    (void)c;
    PyObject *t = PyTuple_New(m);
    for (dk_index j = 0; t && j < m; j++)
        PyTuple_SetItem(t, j, PyBool_FromLong(dk_embedded_node_is_fixed(self->native, j)));
    return t;
}

PyDoc_STRVAR(normals_doc,
             "normals(normals=None) -> n x 3 array\n\n"
             "The vertex normals deformed by the current node transformations (eq. 3:\n"
             "the blend of R^-T n, renormalised). normals: the rest normals (n x 3), or None\n"
             "for the mesh's area-weighted vertex normals.");

static dk_status normals_of(void *native, const double *in, double *out, dk_error *err)
{
    return dk_embedded_normals(native, in, out, err);
}

static PyObject *ed_normals(PyObject *obj, PyObject *args, PyObject *kwargs)
{
    static char *kwlist[] = {"normals", NULL};
    PyObject *in_obj = Py_None;
    if (!PyArg_ParseTupleAndKeywords(args, kwargs, "|O:normals", kwlist, &in_obj))
        return NULL;
    return dk_py_method_map_n3(obj, in_obj, "normals", "EmbeddedDeformation.normals",
                               normals_of);
}

PyDoc_STRVAR(deformed_doc,
             "deformed() -> n x 3 array\n\n"
             "The vertices under the current node transformations (eq. 2): what the last\n"
             "solve returned, computed again.");

static PyObject *ed_deformed(PyObject *obj, PyObject *unused)
{
    dk_py_method *self = (dk_py_method *)obj;
    dk_error err = {0};
    double *out;
    (void)unused;
    if (dk_py_method_enter(self) < 0)
        return NULL;
    PyObject *res = dk_py_new_doubles(2, self->mesh->n_vertices, 3, &out);
    dk_status st = DK_OK;
    if (res) {
        DK_PY_BEGIN_NATIVE(dk_py_state_of(obj))
        st = dk_embedded_deformed(self->native, out, &err);
        DK_PY_END_NATIVE
    }
    self->busy = 0;
    if (res && st != DK_OK) {
        Py_DECREF(res);
        return dk_py_raise(&err, "EmbeddedDeformation.deformed");
    }
    return res;
}

PyDoc_STRVAR(update_source_doc,
             "update_source(positions)\n\n"
             "Section 5, an animated source: the mesh's positions on a new frame (n x 3).\n"
             "The nodes move with the source: a node on a vertex with its vertex (section 5),\n"
             "a surface sample at its place in its triangle. The graph, the weights and the\n"
             "constraints stay as bound,\n"
             "and the node transformations stay as a warm start. Later solves, targets given\n"
             "as transforms, held fixed vertices, deformed(), normals() and energy() take\n"
             "these positions as the rest. The same handle offsets solved on every frame\n"
             "carry one edit through an animation.");

static PyObject *ed_update_source(PyObject *obj, PyObject *arg)
{
    dk_py_method *self = (dk_py_method *)obj;
    dk_error err = {0};
    dk_py_doubles in = {0};
    if (dk_py_method_enter(self) < 0)
        return NULL;
    if (dk_py_read_doubles(arg, self->mesh->n_vertices, 3, "positions", &in) < 0) {
        self->busy = 0;
        return NULL;
    }
    dk_status st;
    DK_PY_BEGIN_NATIVE(dk_py_state_of(obj))
    st = dk_embedded_update_source(self->native, in.data, &err);
    DK_PY_END_NATIVE
    self->busy = 0;
    dk_py_doubles_release(&in);
    if (st != DK_OK)
        return dk_py_raise(&err, "EmbeddedDeformation.update_source");
    Py_RETURN_NONE;
}

PyDoc_STRVAR(embed_doc,
             "embed(points) -> (nodes, weights, deformed)\n\n"
             "Any points in space (m x 3) in the graph: each point's k nearest nodes\n"
             "(m x k int32, -1 where a weight is 0), their weights (m x k, eq. 4) and the\n"
             "points moved by the current node transformations (m x 3, eq. 2).");

static PyObject *ed_embed(PyObject *obj, PyObject *arg)
{
    dk_py_method *self = (dk_py_method *)obj;
    dk_py_doubles pts = {0};
    dk_error err = {0};
    if (dk_py_method_enter(self) < 0)
        return NULL;
    if (dk_py_read_doubles(arg, -1, 3, "points", &pts) < 0) {
        self->busy = 0;
        return NULL;
    }
    dk_index *nb;
    double *w, *out;
    const dk_index np = (dk_index)pts.rows, kk = dk_embedded_k(self->native);
    PyObject *a = dk_py_new_indices(2, np, kk, &nb);
    PyObject *b = a ? dk_py_new_doubles(2, np, kk, &w) : NULL;
    PyObject *c = b ? dk_py_new_doubles(2, np, 3, &out) : NULL;
    dk_status st = DK_OK;
    if (c) {
        DK_PY_BEGIN_NATIVE(dk_py_state_of(obj))
        st = dk_embedded_embed(self->native, pts.data, np, nb, w, out, &err);
        DK_PY_END_NATIVE
    }
    dk_py_doubles_release(&pts);
    self->busy = 0;
    if (!c || st != DK_OK) {
        Py_XDECREF(a);
        Py_XDECREF(b);
        Py_XDECREF(c);
        return c ? dk_py_raise(&err, "EmbeddedDeformation.embed") : NULL;
    }
    return Py_BuildValue("(NNN)", a, b, c);
}

PyDoc_STRVAR(solve_doc,
             "solve(targets=None, transforms=None, warm_start=True, max_iterations=None,\n"
             "      resume=False, energy=True, preview=False, start_positions=None)\n"
             "      -> SolveResult\n\n"
             "preview=True (the contract's keyword) solves as usual: this method has no\n"
             "faster result to show. start_positions (the contract's keyword) raises\n"
             "ValueError: positions do not determine the nodes' affine maps.\n"
             "Gauss-Newton with Levenberg-Marquardt damping on the node transformations.\n"
             "Returns the deformed vertices (eq. 2), F = w_rot E_rot + w_reg E_reg + w_con\n"
             "E_con, the iterations and whether the tests of eq. 12 held.");

PyDoc_STRVAR(ed_doc,
             "EmbeddedDeformation(mesh, handles, fixed=None, roi=None, handle_weights=None,\n"
             "    stiffness=None, nodes='surface', n_nodes=200, radius=0.0, k=4,\n"
             "    distance='euclidean', cut=None, w_rot=1.0, w_reg=10.0, w_con=2000.0,\n"
             "    tolerance=1e-6, max_iterations=100, seed=1, progress=None)\n\n"
             "Embedded deformation (Sumner, Schmid & Pauly 2007): a deformation graph of\n"
             "nodes sampled uniformly on the surface (or among the vertices), one affine\n"
             "transformation per node, each vertex moved by its k nearest nodes (in space, or\n"
             "along the surface with distance='geodesic'). Handles are positional constraints\n"
             "(weight w_con); every node that influences a fixed vertex is a constant, so\n"
             "fixed vertices stay exactly at rest. cut=(group_a, group_b) separates two\n"
             "vertex sets: no node of one side influences the other, and no graph edge\n"
             "joins them. See docs/methods/embedded.md.");

static PyGetSetDef ed_getset[] = {
    DK_PY_METHOD_GETSET,
    {"nodes", get_nodes, NULL, "n_nodes x 3 node positions g_j", NULL},
    {"transforms", get_transforms, NULL, "n_nodes x 12: each node's R (row-major) and t", NULL},
    {"edges", get_edges, NULL, "n_edges x 2 node pairs (i < j)", NULL},
    {"fixed_nodes", get_fixed_nodes, NULL, "tuple of bool: the constant nodes", NULL},
    {NULL, NULL, NULL, NULL, NULL},
};

static PyMethodDef ed_methods[] = {
    DK_PY_METHOD_METHODS(solve_doc),
    {"normals", (PyCFunction)(void (*)(void))ed_normals, METH_VARARGS | METH_KEYWORDS,
     normals_doc},
    {"embed", ed_embed, METH_O, embed_doc},
    {"deformed", ed_deformed, METH_NOARGS, deformed_doc},
    {"update_source", ed_update_source, METH_O, update_source_doc},
    {NULL, NULL, 0, NULL},
};

/* progress=: the shared callback (dk_py.h), phases named by the native bind / rebind */
static void bind_progress(void *options, dk_py_progress *p)
{
    ((dk_embedded_options *)options)->progress = dk_py_progress_phase;
    ((dk_embedded_options *)options)->progress_user = p;
}

static void rebind_progress(void *native, dk_py_progress *p)
{
    dk_embedded_set_progress((dk_embedded *)native, p ? dk_py_progress_phase : NULL, p);
}

static const dk_py_method_spec ed_spec = {
    .name = "EmbeddedDeformation",
    .type_name = "deformkit.EmbeddedDeformation",
    .ops = &dk_embedded_ops,
    .doc = ed_doc,
    .options_size = sizeof(dk_embedded_options),
    .default_options = default_options,
    .parse_options = parse_options,
    .release_options = release_options,
    .bind_progress = bind_progress,
    .rebind_progress = rebind_progress,
    .getset = ed_getset,
    .methods = ed_methods,
};

static PyObject *ed_new(PyTypeObject *type, PyObject *args, PyObject *kwargs)
{
    return dk_py_method_new(type, args, kwargs, &ed_spec);
}

int dk_py_init_embedded(PyObject *module)
{
    return dk_py_method_register(module, &ed_spec, ed_new);
}
