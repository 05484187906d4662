/* DeformKit CPython module: deformkit.Cage (native/methods/dk_cage.h), on the generic method
 * type (dk_py_method.h) as a method bound to a control. What is Cage's own: its control's
 * keywords (cage_vertices, cage_triangles), its options, rest_points. */
#include "dk_py_method.h"

#include "dk_cage.h"

#include <string.h>

static const char *const weights_names[] = {"double", "single", NULL};
static const char *const coordinates_names[] = {"mean_value", "green", NULL};
static const char *const evaluation_names[] = {"auto", "exact", "grid", NULL};

static void default_options(void *o)
{
    dk_cage_default_options((dk_cage_options *)o);
}

static int parse_options(PyObject *kw, void *o, const char *context)
{
    dk_cage_options *opt = (dk_cage_options *)o;
    int w = (int)opt->weights;
    if (dk_py_opt_choice(kw, "weights", weights_names, &w, context) < 0)
        return -1;
    opt->weights = (dk_cage_weights)w;
    int c = (int)opt->coordinates;
    if (dk_py_opt_choice(kw, "coordinates", coordinates_names, &c, context) < 0)
        return -1;
    opt->coordinates = (dk_cage_coordinates)c;
    int ev = (int)opt->evaluation;
    if (dk_py_opt_choice(kw, "evaluation", evaluation_names, &ev, context) < 0)
        return -1;
    opt->evaluation = (dk_cage_evaluation)ev;
    if (dk_py_opt_int(kw, "grid_resolution", &opt->grid_resolution) < 0)
        return -1;
    return 0;
}

/* What parse_control writes: the control and the arrays it points to (PyMem). */
typedef struct cage_store {
    dk_control_desc control;
    dk_py_doubles vertices;
    dk_py_indices triangles;
} cage_store;

static void release_control(void *store)
{
    cage_store *s = (cage_store *)store;
    dk_py_doubles_release(&s->vertices);
    dk_py_indices_release(&s->triangles);
}

static int parse_control(PyObject *kw, const dk_mesh *mesh, const void *bound, void *store,
                         const char *context)
{
    cage_store *s = (cage_store *)store;
    (void)mesh;
    (void)bound; /* a rebind takes a whole new cage */
    PyObject *v = dk_py_opt_object(kw, "cage_vertices");
    PyObject *t = v ? dk_py_opt_object(kw, "cage_triangles") : NULL;
    if (!v || !t) {
        Py_XDECREF(v);
        if (!PyErr_Occurred())
            PyErr_Format(PyExc_TypeError, "%s: needs cage_vertices (k x 3) and "
                         "cage_triangles (m x 3): the closed cage around the mesh", context);
        return -1;
    }
    const int bad = dk_py_read_doubles(v, -1, 3, "cage_vertices", &s->vertices) < 0 ||
                    dk_py_read_indices(t, -1, 3, "cage_triangles", &s->triangles) < 0;
    Py_DECREF(v);
    Py_DECREF(t);
    if (bad)
        return -1;
    s->control = (dk_control_desc){.kind = DK_CONTROL_CAGE,
                                   .n_controls = (dk_index)s->vertices.rows,
                                   .rest = s->vertices.data,
                                   .n_triangles = (dk_index)s->triangles.rows,
                                   .triangles = s->triangles.data};
    return 0;
}

static PyObject *get_rest_points(PyObject *obj, void *c)
{
    (void)c;
    if (!dk_py_method_readable((dk_py_method *)obj))
        return NULL;
    dk_py_method *self = (dk_py_method *)obj;
    dk_method_stats ms;
    double *out;
    dk_cage_stats(self->native, &ms);
    PyObject *a = dk_py_new_doubles(2, ms.n_controls, 3, &out);
    if (a)
        memcpy(out, dk_cage_rest_points(self->native), 3 * sizeof(double) * (size_t)ms.n_controls);
    return a;
}

static PyGetSetDef cage_getset[] = {
    DK_PY_METHOD_GETSET,
    {"rest_points", get_rest_points, NULL,
     "k x 3: the cage's vertices at rest, in the order solve(targets=...) takes them", NULL},
    {NULL, NULL, NULL, NULL, NULL},
};

PyDoc_STRVAR(solve_doc,
             "solve(targets, energy=True) -> SolveResult\n\n"
             "targets: the cage vertices' positions, k x 3 in the order given at bind\n"
             "(transforms are refused: a cage has no handles). Every vertex moves by the\n"
             "coordinate-weighted motion of the cage's vertices (and, with Green\n"
             "coordinates, of its faces' scaled normals); the cage at rest gives the mesh\n"
             "back exactly, an affine map of the cage maps it (mean value coordinates) or a\n"
             "similarity does (Green). A direct method; energy is the sum of squared\n"
             "displacements, iterations 1.");

static PyMethodDef cage_methods[] = {
    DK_PY_METHOD_METHODS(solve_doc),
    {NULL, NULL, 0, NULL},
};

PyDoc_STRVAR(cage_doc,
             "Cage(mesh, cage_vertices, cage_triangles, coordinates='mean_value',\n"
             "     evaluation='auto', grid_resolution=64, weights='double')\n\n"
             "Cage-based free-form deformation: the closed triangle cage (k x 3 vertices,\n"
             "m x 3 triangles, every edge in two of them) around the mesh. coordinates:\n"
             "'mean_value' (Ju, Schaefer, Warren 2005; the slides' arbitrary polyhedron\n"
             "cells: affine maps of the cage map the mesh) or 'green' (Lipman, Levin,\n"
             "Cohen-Or 2008: from the cage's vertices and its faces' normals,\n"
             "quasi-conformal, keeps the shape; the triangles oriented consistently).\n"
             "Bind computes each vertex's coordinates (an n x k matrix, and n x m more for\n"
             "Green; two threads), a solve is one or two products with the cage's motion.\n"
             "weights='single' stores them as floats (half the memory; the motion to about\n"
             "1e-7 of itself). evaluation: 'exact' (at every vertex), 'grid' (at the corners\n"
             "of the cells, grid_resolution along the mesh's longest side, that hold a\n"
             "vertex, blended trilinearly: linear precision kept, memory and solves by the\n"
             "nodes) or 'auto' (exact up to 64 M coefficients, else grid).\n"
             "rebind(cage_vertices=..., cage_triangles=...) takes another cage. See\n"
             "docs/methods/cage.md.");

static const dk_py_method_spec cage_spec = {
    .name = "Cage",
    .type_name = "deformkit.Cage",
    .ops = &dk_cage_ops,
    .doc = cage_doc,
    .options_size = sizeof(dk_cage_options),
    .default_options = default_options,
    .parse_options = parse_options,
    .parse_control = parse_control,
    .release_control = release_control,
    .getset = cage_getset,
    .methods = cage_methods,
};

static PyObject *cage_new(PyTypeObject *type, PyObject *args, PyObject *kwargs)
{
    return dk_py_method_new(type, args, kwargs, &cage_spec);
}

int dk_py_init_cage(PyObject *module)
{
    return dk_py_method_register(module, &cage_spec, cage_new);
}
