/* DeformKit CPython module: deformkit.bounded_biharmonic_weights (native/operators/dk_bbw.h). */
#include "dk_py.h"

#include "dk_bbw.h"

#include <string.h>

static const char *const domain_names[] = {"auto", "volume", "surface", NULL};

/* Reads an optional (rows x cols) array of handles; None or absent: none. */
static int read_handles(PyObject *obj, Py_ssize_t cols, const char *name, dk_py_doubles *out)
{
    memset(out, 0, sizeof *out);
    if (!obj || obj == Py_None)
        return 0;
    if (cols == 6) {
        PyObject *flat = dk_py_as_blocks(obj, 2, 3, name);
        if (!flat) return -1;
        int r = dk_py_read_doubles(flat, -1, 6, name, out);
        Py_DECREF(flat);
        return r;
    }
    return dk_py_read_doubles(obj, -1, cols, name, out);
}

PyDoc_STRVAR(bbw_doc,
             "bounded_biharmonic_weights(mesh, points=None, bones=None, cage=None,\n"
             "                           domain='auto', resolution=24, max_iterations=200,\n"
             "                           report=False, progress=None) -> weights\n\n"
             "Bounded biharmonic weights (Jacobson, Baran, Popovic, Sorkine 2011): one\n"
             "smooth weight per vertex and handle, in [0, 1], 1 on its handle and 0 on the\n"
             "others, each vertex's summing to 1; the minimisers of the discrete biharmonic\n"
             "energy under those bounds, each handle's an exact quadratic program (active set\n"
             "on the sparse system), divided by their sum as the paper does.\n"
             "Handles (columns in this order): points (p x 3), bones (b x 2 x 3: head, tail;\n"
             "held along the whole segment), cage (vertices c x 3, triangles t x 3): a closed\n"
             "cage around the mesh, its vertices the handles, its faces blending them\n"
             "linearly.\n"
             "domain: 'volume' (the solid the mesh or the cage encloses, tetrahedralized by\n"
             "TetGen on a grid of `resolution` cells along the longest side, robust to holes\n"
             "and several parts), 'surface' (the mesh's triangles: handles held at their\n"
             "nearest vertices; for open meshes), 'auto' (volume when there is one).\n"
             "Returns the n x h weights; report=True returns (weights, dict) with the domain\n"
             "used, its size, the active-set iterations, the KKT residual and how far the\n"
             "sums were from 1 before the division. progress=callable(fraction) as the\n"
             "methods' binds take it. See docs/methods/skinning.md.");

static PyObject *py_bbw(PyObject *module, PyObject *args, PyObject *kwargs)
{
    static char *kwlist[] = {"mesh", "points", "bones", "cage", "domain", "resolution",
                             "max_iterations", "report", NULL};
    PyObject *mobj, *pobj = NULL, *bobj = NULL, *cobj = NULL, *repobj = Py_False;
    PyObject *result = NULL, *kw = NULL;
    const char *domain = "auto";
    dk_bbw_options defaults;
    dk_bbw_default_options(&defaults);
    int resolution = defaults.resolution, max_iterations = defaults.max_iterations;
    int want_report = 0;
    dk_py_doubles pts = {0}, bones = {0}, cv = {0};
    dk_py_indices ct = {0};
    dk_py_progress prog;
    memset(&prog, 0, sizeof prog);
    /* progress is taken out of the keywords first */
    if (kwargs) {
        kw = PyDict_Copy(kwargs);
        if (!kw) return NULL;
    }
    if (dk_py_progress_take(kw, module, "bounded_biharmonic_weights", &prog) < 0) goto fail;
    if (!PyArg_ParseTupleAndKeywords(args, kw, "O|OOOsiiO:bounded_biharmonic_weights", kwlist,
                                     &mobj, &pobj, &bobj, &cobj, &domain, &resolution,
                                     &max_iterations, &repobj))
        goto fail;
    const dk_mesh *mesh = dk_py_mesh_get(module, mobj, "mesh");
    if (!mesh) goto fail;
    if (dk_py_strict_bool(repobj, "report", "bounded_biharmonic_weights", &want_report) < 0)
        goto fail;
    dk_bbw_options opt;
    dk_bbw_default_options(&opt);
    int d = -1;
    for (int i = 0; domain_names[i]; i++)
        if (strcmp(domain, domain_names[i]) == 0) d = i;
    if (d < 0) {
        PyErr_Format(PyExc_ValueError, "bounded_biharmonic_weights: domain must be 'auto', "
                     "'volume' or 'surface', not '%s'", domain);
        goto fail;
    }
    if (resolution < 4 || resolution > 256 || max_iterations < 1) {
        PyErr_Format(PyExc_ValueError, "bounded_biharmonic_weights: resolution must be in "
                     "[4, 256] (got %d) and max_iterations >= 1 (got %d)", resolution,
                     max_iterations);
        goto fail;
    }
    opt.domain = (dk_bbw_domain)d;
    opt.resolution = resolution;
    opt.max_iterations = max_iterations;
    if (read_handles(pobj, 3, "points", &pts) < 0 || read_handles(bobj, 6, "bones", &bones) < 0)
        goto fail;
    if (cobj && cobj != Py_None) {
        if (!PyTuple_Check(cobj) || PyTuple_Size(cobj) != 2) {
            PyErr_SetString(PyExc_TypeError, "bounded_biharmonic_weights: cage must be a pair "
                            "(vertices c x 3, triangles t x 3)");
            goto fail;
        }
        if (dk_py_read_doubles(PyTuple_GetItem(cobj, 0), -1, 3, "cage vertices", &cv) < 0 ||
            dk_py_read_indices(PyTuple_GetItem(cobj, 1), -1, 3, "cage triangles", &ct) < 0)
            goto fail;
    }
    dk_bbw_handles h = {
        .n_points = (dk_index)pts.rows, .points = pts.data,
        .n_bones = (dk_index)bones.rows, .bones = bones.data,
        .n_cage_vertices = (dk_index)cv.rows, .cage_vertices = cv.data,
        .n_cage_triangles = (dk_index)ct.rows, .cage_triangles = ct.data,
    };
    dk_index nh = dk_bbw_handle_count(&h);
    if (nh < 1) {
        PyErr_SetString(PyExc_ValueError, "bounded_biharmonic_weights: needs at least one "
                        "handle (points, bones or cage)");
        goto fail;
    }
    if (prog.callable) {
        opt.progress = dk_py_progress_phase;
        opt.progress_user = &prog;
    }
    double *out;
    PyObject *w = dk_py_new_doubles(2, mesh->n_vertices, nh, &out);
    if (!w) goto fail;
    dk_bbw_report rep;
    dk_error err = {0};
    dk_status st;
    DK_PY_BEGIN_NATIVE(dk_py_get_state(module))
    st = dk_bounded_biharmonic_weights(mesh, &h, &opt, out, &rep, &err);
    DK_PY_END_NATIVE
    if (st != DK_OK) {
        Py_DECREF(w);
        dk_py_progress_raise(&prog, &err, "bounded_biharmonic_weights");
        goto fail;
    }
    if (dk_py_progress_raised(&prog)) {
        Py_DECREF(w);
        goto fail;
    }
    if (want_report) {
        result = Py_BuildValue(
            "N{s:s,s:n,s:n,s:i,s:i,s:d,s:d,s:n}", w, "domain",
            rep.domain == DK_BBW_VOLUME ? "volume" : "surface", "domain_vertices",
            (Py_ssize_t)rep.domain_vertices, "domain_elements", (Py_ssize_t)rep.domain_elements,
            "max_iterations", rep.max_iterations, "total_iterations", rep.total_iterations,
            "kkt_residual", rep.kkt_residual, "sum_deviation", rep.sum_deviation, "unreached",
            (Py_ssize_t)rep.unreached);
    } else {
        result = w;
    }
fail:
    Py_XDECREF(kw);
    dk_py_progress_release(&prog);
    dk_py_doubles_release(&pts);
    dk_py_doubles_release(&bones);
    dk_py_doubles_release(&cv);
    dk_py_indices_release(&ct);
    return result;
}

static PyMethodDef bbw_functions[] = {
    {"bounded_biharmonic_weights", (PyCFunction)(void (*)(void))py_bbw,
     METH_VARARGS | METH_KEYWORDS, bbw_doc},
    {NULL, NULL, 0, NULL},
};

int dk_py_init_bbw(PyObject *module)
{
    return PyModule_AddFunctions(module, bbw_functions);
}
