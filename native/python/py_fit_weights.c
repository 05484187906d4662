/* DeformKit CPython module: deformkit.fit_skinning_weights (dk_operators.h). */
#include "dk_py.h"

#include "dk_operators.h"

#include <string.h>

/* Reads frames (k x 4 x 4 or k*16 flat) as rows of 16. */
static int read_frames(PyObject *obj, Py_ssize_t rows, const char *name, dk_py_doubles *out)
{
    PyObject *flat = dk_py_as_blocks(obj, 4, 4, name);
    if (!flat)
        return -1;
    int r = dk_py_read_doubles(flat, rows, 16, name, out);
    Py_DECREF(flat);
    return r;
}

PyDoc_STRVAR(fit_doc,
             "fit_skinning_weights(rest_positions, bone_frames, pose_frames, pose_positions)\n"
             "    -> weights\n\n"
             "Skinning weights from example poses (the slides' \"using example poses &\n"
             "skins\"): for each vertex the weights (>= 0, summing to 1) with which linear\n"
             "blend skinning reproduces the examples best in least squares, solved exactly.\n"
             "rest_positions n x 3; bone_frames b x 4 x 4 (rest); pose_frames P x b x 4 x 4\n"
             "(each bone's frame in each pose); pose_positions P x n x 3 (the mesh in each\n"
             "pose). Returns n x b. Bones that move alike in every pose cannot be told apart\n"
             "by the examples: the weight goes to one of them. See docs/methods/skinning.md.");

static PyObject *py_fit(PyObject *module, PyObject *args, PyObject *kwargs)
{
    static char *kwlist[] = {"rest_positions", "bone_frames", "pose_frames", "pose_positions",
                             NULL};
    PyObject *robj, *bobj, *fobj, *pobj, *result = NULL;
    dk_py_doubles rest = {0}, bf = {0}, pf = {0}, pp = {0};
    if (!PyArg_ParseTupleAndKeywords(args, kwargs, "OOOO:fit_skinning_weights", kwlist, &robj,
                                     &bobj, &fobj, &pobj))
        return NULL;
    if (dk_py_read_doubles(robj, -1, 3, "rest_positions", &rest) < 0 ||
        read_frames(bobj, -1, "bone_frames", &bf) < 0)
        goto done;
    if (bf.rows < 1 || rest.rows < 1) {
        PyErr_SetString(PyExc_ValueError, "fit_skinning_weights: needs at least one vertex and "
                        "one bone");
        goto done;
    }
    if (read_frames(fobj, -1, "pose_frames", &pf) < 0) goto done;
    if (pf.rows % bf.rows != 0 || pf.rows == 0) {
        PyErr_Format(PyExc_ValueError, "fit_skinning_weights: pose_frames must be P x %zd x 4 x 4 "
                     "(%zd frames for %zd bones)", bf.rows, pf.rows, bf.rows);
        goto done;
    }
    const Py_ssize_t P = pf.rows / bf.rows;
    PyObject *flat = PyObject_HasAttrString(pobj, "reshape")
                         ? PyObject_CallMethod(pobj, "reshape", "(ii)", -1, 3) : Py_NewRef(pobj);
    if (!flat) goto done;
    int bad = dk_py_read_doubles(flat, P * rest.rows, 3, "pose_positions", &pp) < 0;
    Py_DECREF(flat);
    if (bad) goto done;
    double *out;
    PyObject *w = dk_py_new_doubles(2, rest.rows, bf.rows, &out);
    if (!w) goto done;
    dk_error err = {0};
    dk_status st;
    DK_PY_BEGIN_NATIVE(dk_py_get_state(module))
    st = dk_fit_skinning_weights(rest.data, (dk_index)rest.rows, bf.data, (dk_index)bf.rows,
                                 pf.data, pp.data, (dk_index)P, out, &err);
    DK_PY_END_NATIVE
    if (st != DK_OK) {
        Py_DECREF(w);
        dk_py_raise(&err, "fit_skinning_weights");
        goto done;
    }
    result = w;
done:
    dk_py_doubles_release(&rest);
    dk_py_doubles_release(&bf);
    dk_py_doubles_release(&pf);
    dk_py_doubles_release(&pp);
    return result;
}

static PyMethodDef fit_functions[] = {
    {"fit_skinning_weights", (PyCFunction)(void (*)(void))py_fit, METH_VARARGS | METH_KEYWORDS,
     fit_doc},
    {NULL, NULL, 0, NULL},
};

int dk_py_init_fit_weights(PyObject *module)
{
    return PyModule_AddFunctions(module, fit_functions);
}
