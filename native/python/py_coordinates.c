/* DeformKit CPython module: the generalized barycentric coordinates in the plane
 * (native/operators/dk_coordinates.h): barycentric_coordinates, wachspress_coordinates,
 * mean_value_coordinates. */
#include "dk_py.h"

#include "dk_coordinates.h"

#include <stdio.h>

typedef dk_status (*polygon_fn)(const double *, int, const double *, double *, dk_error *);

/* The coordinates of each point (m x 2, or one point of 2) for the polygon (n x 2): m x n
 * (or n), the first refused point named. */
static PyObject *coordinates(PyObject *args, PyObject *kwargs, const char *name, int corners,
                             polygon_fn fn)
{
    static char *kwlist[] = {"polygon", "points", NULL};
    PyObject *poly_obj, *pts_obj;
    char fmt[64];
    snprintf(fmt, sizeof fmt, "OO:%s", name);
    if (!PyArg_ParseTupleAndKeywords(args, kwargs, fmt, kwlist, &poly_obj, &pts_obj))
        return NULL;
    dk_py_doubles poly = {0}, pts = {0};
    if (dk_py_read_doubles(poly_obj, corners, 2, "polygon", &poly) < 0)
        return NULL;
    if (dk_py_read_doubles(pts_obj, -1, DK_PY_COLS_1D_OR_2D, "points", &pts) < 0) {
        dk_py_doubles_release(&poly);
        return NULL;
    }
    const int one = pts.ndim == 1;
    const Py_ssize_t m = one ? 1 : pts.rows, n = poly.rows;
    if ((one && pts.rows != 2) || (!one && pts.cols != 2) || n < 3 || n > 1000000) {
        PyErr_Format(PyExc_ValueError, "%s: points must be m x 2 (or one point of 2) and the "
                     "polygon n x 2 with n >= 3", name);
        dk_py_doubles_release(&poly);
        dk_py_doubles_release(&pts);
        return NULL;
    }
    double *out;
    PyObject *res = dk_py_new_doubles(one ? 1 : 2, one ? n : m, n, &out);
    dk_error err = {0};
    dk_status st = DK_OK;
    Py_ssize_t bad = -1;
    if (res) {
        Py_BEGIN_ALLOW_THREADS
        for (Py_ssize_t k = 0; k < m && st == DK_OK; k++) {
            st = fn(poly.data, (int)n, pts.data + 2 * k, out + (size_t)k * (size_t)n, &err);
            if (st != DK_OK)
                bad = k;
        }
        Py_END_ALLOW_THREADS
    }
    dk_py_doubles_release(&poly);
    dk_py_doubles_release(&pts);
    if (res && st != DK_OK) {
        Py_DECREF(res);
        char ctx[96];
        snprintf(ctx, sizeof ctx, "%s, point %zd", name, bad);
        return dk_py_raise(&err, ctx);
    }
    return res;
}

static dk_status triangle_fn(const double *t, int n, const double *x, double *l, dk_error *e)
{
    (void)n;
    return dk_barycentric_2d(t, x, l, e);
}

PyDoc_STRVAR(barycentric_doc,
             "barycentric_coordinates(triangle, points) -> ndarray\n\n"
             "Each point's (m x 2, or one point of 2) barycentric coordinates in the triangle\n"
             "(3 x 2): m x 3 (or 3), the area of the triangle a point makes with the opposite\n"
             "edge over the triangle's. Any buffer. See native/operators/dk_coordinates.h.");

static PyObject *py_barycentric(PyObject *self, PyObject *args, PyObject *kwargs)
{
    (void)self;
    return coordinates(args, kwargs, "barycentric_coordinates", 3, triangle_fn);
}

PyDoc_STRVAR(wachspress_doc,
             "wachspress_coordinates(polygon, points) -> ndarray\n\n"
             "Wachspress coordinates (rational, positive) of each point (m x 2, or one of 2)\n"
             "inside the strictly convex polygon (n x 2, either way round): m x n (or n).\n"
             "A point on the boundary gets its edge's linear interpolation; outside, or a\n"
             "polygon that is not convex: ValueError.");

static PyObject *py_wachspress(PyObject *self, PyObject *args, PyObject *kwargs)
{
    (void)self;
    return coordinates(args, kwargs, "wachspress_coordinates", -1, dk_wachspress_2d);
}

PyDoc_STRVAR(mean_value_doc,
             "mean_value_coordinates(polygon, points) -> ndarray\n\n"
             "Mean value coordinates (Floater 2003; the slides' formula, evaluated without\n"
             "trigonometry) of each point (m x 2, or one of 2) for any simple polygon (n x 2):\n"
             "m x n (or n). Defined in the whole plane; positive inside convex polygons; a\n"
             "point on the boundary gets its edge's linear interpolation.");

static PyObject *py_mean_value(PyObject *self, PyObject *args, PyObject *kwargs)
{
    (void)self;
    return coordinates(args, kwargs, "mean_value_coordinates", -1, dk_mean_value_2d);
}

static PyMethodDef coordinate_functions[] = {
    {"barycentric_coordinates", (PyCFunction)(void (*)(void))py_barycentric,
     METH_VARARGS | METH_KEYWORDS, barycentric_doc},
    {"wachspress_coordinates", (PyCFunction)(void (*)(void))py_wachspress,
     METH_VARARGS | METH_KEYWORDS, wachspress_doc},
    {"mean_value_coordinates", (PyCFunction)(void (*)(void))py_mean_value,
     METH_VARARGS | METH_KEYWORDS, mean_value_doc},
    {NULL, NULL, 0, NULL},
};

int dk_py_init_coordinates(PyObject *module)
{
    return PyModule_AddFunctions(module, coordinate_functions);
}
