/* DeformKit CPython module: discrete operators and geometric queries.
 *
 * Functions: uniform_laplacian, cotangent_laplacian, cotangent_weights, mass_matrix,
 * geodesic_distance, laplacian_eigenpairs, knn, closest_rotation. Classes: HeatGeodesic
 * (keeps the heat method's factorizations) and KDTree. Every native computation runs with
 * the GIL released; ARPACK runs are serialised with the module's arpack_lock, taken without
 * holding the GIL so that a waiting thread never blocks the interpreter.
 */
#include "dk_py.h"

#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "dk_eigs.h"
#include "dk_operators.h"
#include "dk_sparse.h"

/* ------------------------------------------------------------------ helpers ------------- */

/** (rows, cols, values) COO arrays of a CSC matrix, as a new tuple. */
static PyObject *sparse_to_coo(const dk_sparse *a)
{
    Py_ssize_t nnz = (Py_ssize_t)dk_sparse_nnz(a);
    dk_index *r, *c;
    double *v;
    PyObject *rows = NULL, *cols = NULL, *vals = NULL, *result = NULL;

    rows = dk_py_new_indices(1, nnz, 0, &r);
    cols = rows ? dk_py_new_indices(1, nnz, 0, &c) : NULL;
    vals = cols ? dk_py_new_doubles(1, nnz, 0, &v) : NULL;
    if (vals) {
        for (dk_index j = 0; j < a->n_cols; ++j) {
            for (dk_index p = a->col_start[j]; p < a->col_start[j + 1]; ++p) {
                r[p] = a->row_index[p];
                c[p] = j;
                v[p] = a->values[p];
            }
        }
        result = PyTuple_Pack(3, rows, cols, vals);
    }
    Py_XDECREF(rows);
    Py_XDECREF(cols);
    Py_XDECREF(vals);
    return result;
}

/** Parses a mass-matrix kind name. */
static int parse_mass_kind(const char *name, const char *argname, dk_mass_kind *kind)
{
    if (strcmp(name, "voronoi") == 0) {
        *kind = DK_MASS_VORONOI;
        return 0;
    }
    if (strcmp(name, "barycentric") == 0) {
        *kind = DK_MASS_BARYCENTRIC;
        return 0;
    }
    PyErr_Format(PyExc_ValueError, "%s must be 'voronoi' or 'barycentric', got '%s'", argname,
                 name);
    return -1;
}

/** Reads source vertices (an int or any 1-D index array), checked against the mesh. */
static int read_sources(PyObject *obj, const dk_mesh *mesh, dk_py_indices *out)
{
    dk_error err = {0};
    int rc;

    if (PyLong_Check(obj)) {
        PyObject *list = PyList_New(1);
        if (!list)
            return -1;
        PyList_SetItem(list, 0, Py_NewRef(obj));
        rc = dk_py_read_indices(list, -1, 0, "sources", out);
        Py_DECREF(list);
    } else {
        rc = dk_py_read_indices(obj, -1, 0, "sources", out);
    }
    if (rc < 0)
        return -1;
    if (out->rows == 0) {
        dk_py_indices_release(out);
        PyErr_SetString(PyExc_ValueError, "sources is empty: give at least one vertex");
        return -1;
    }
    if (dk_check_indices(out->data, out->rows, mesh->n_vertices, "sources", &err) != DK_OK) {
        dk_py_indices_release(out);
        dk_py_raise(&err, NULL);
        return -1;
    }
    return 0;
}

/* ------------------------------------------------------------------ Laplacians ---------- */

typedef dk_status (*laplacian_fn)(const dk_mesh *, dk_sparse **, dk_error *);

static PyObject *laplacian_common(PyObject *module, PyObject *args, PyObject *kwargs,
                                  laplacian_fn fn, const char *fname)
{
    static char *kwlist[] = {"mesh", NULL};
    PyObject *mobj, *result;
    const dk_mesh *mesh;
    dk_sparse *l = NULL;
    dk_error err = {0};
    dk_status st;
    char format[64];

    snprintf(format, sizeof format, "O:%s", fname);
    if (!PyArg_ParseTupleAndKeywords(args, kwargs, format, kwlist, &mobj))
        return NULL;
    mesh = dk_py_mesh_get(module, mobj, "mesh");
    if (!mesh)
        return NULL;
    Py_BEGIN_ALLOW_THREADS
    st = fn(mesh, &l, &err);
    Py_END_ALLOW_THREADS
    if (st != DK_OK)
        return dk_py_raise(&err, fname);
    result = sparse_to_coo(l);
    dk_sparse_free(l);
    return result;
}

PyDoc_STRVAR(uniform_laplacian_doc,
             "uniform_laplacian(mesh) -> (rows, cols, values)\n\n"
             "The graph Laplacian (L_ij = -1 per edge, L_ii = degree) as COO arrays (int32,\n"
             "int32, float64) of its CSC entries, column by column; both triangles stored.\n"
             "scipy.sparse.csc_matrix((values, (rows, cols)), shape=(n, n)) rebuilds it.");

static PyObject *py_uniform_laplacian(PyObject *module, PyObject *args, PyObject *kwargs)
{
    return laplacian_common(module, args, kwargs, dk_laplacian_uniform, "uniform_laplacian");
}

PyDoc_STRVAR(cotangent_laplacian_doc,
             "cotangent_laplacian(mesh) -> (rows, cols, values)\n\n"
             "The cotangent Laplacian, positive semidefinite: L_ij = -(cot a + cot b)/2,\n"
             "L_ii = -sum_j L_ij. COO arrays of its CSC entries (see uniform_laplacian).");

static PyObject *py_cotangent_laplacian(PyObject *module, PyObject *args, PyObject *kwargs)
{
    return laplacian_common(module, args, kwargs, dk_laplacian_cotangent,
                            "cotangent_laplacian");
}

PyDoc_STRVAR(cotangent_weights_doc,
             "cotangent_weights(mesh, positions=None) -> float64 array (n_edges,)\n\n"
             "w_e = (cot alpha + cot beta) / 2 for every edge of mesh.edges, at `positions`\n"
             "(n_vertices x 3; default: the rest positions). Degenerate triangles add 0.");

static PyObject *py_cotangent_weights(PyObject *module, PyObject *args, PyObject *kwargs)
{
    static char *kwlist[] = {"mesh", "positions", NULL};
    PyObject *mobj, *pobj = Py_None, *result;
    const dk_mesh *mesh;
    dk_py_doubles pos = {0};
    const double *p;
    double *w;
    dk_error err = {0};

    if (!PyArg_ParseTupleAndKeywords(args, kwargs, "O|O:cotangent_weights", kwlist, &mobj,
                                     &pobj))
        return NULL;
    mesh = dk_py_mesh_get(module, mobj, "mesh");
    if (!mesh)
        return NULL;
    p = mesh->positions;
    if (pobj != Py_None) {
        if (dk_py_read_doubles(pobj, mesh->n_vertices, 3, "positions", &pos) < 0)
            return NULL;
        if (dk_check_positions(pos.data, mesh->n_vertices, &err) != DK_OK) {
            dk_py_doubles_release(&pos);
            return dk_py_raise(&err, "cotangent_weights: positions");
        }
        p = pos.data;
    }
    result = dk_py_new_doubles(1, mesh->n_edges, 0, &w);
    if (result) {
        Py_BEGIN_ALLOW_THREADS
        dk_cotangent_weights(mesh, p, w);
        Py_END_ALLOW_THREADS
    }
    dk_py_doubles_release(&pos);
    return result;
}

/* ------------------------------------------------------------------ mass ---------------- */

PyDoc_STRVAR(mass_matrix_doc,
             "mass_matrix(mesh, kind='voronoi') -> float64 array (n_vertices,)\n\n"
             "The lumped (diagonal) mass of every vertex: 'voronoi' (mixed Voronoi areas,\n"
             "Meyer et al. 2003) or 'barycentric' (a third of each incident triangle).\n"
             "Both sum to the surface area.");

static PyObject *py_mass_matrix(PyObject *module, PyObject *args, PyObject *kwargs)
{
    static char *kwlist[] = {"mesh", "kind", NULL};
    PyObject *mobj, *result;
    const char *kind_name = "voronoi";
    const dk_mesh *mesh;
    dk_mass_kind kind;
    double *m;
    dk_error err = {0};
    dk_status st;

    if (!PyArg_ParseTupleAndKeywords(args, kwargs, "O|s:mass_matrix", kwlist, &mobj,
                                     &kind_name))
        return NULL;
    mesh = dk_py_mesh_get(module, mobj, "mesh");
    if (!mesh || parse_mass_kind(kind_name, "kind", &kind) < 0)
        return NULL;
    result = dk_py_new_doubles(1, mesh->n_vertices, 0, &m);
    if (!result)
        return NULL;
    Py_BEGIN_ALLOW_THREADS
    st = dk_mass_matrix(mesh, kind, m, &err);
    Py_END_ALLOW_THREADS
    if (st != DK_OK) {
        Py_DECREF(result);
        return dk_py_raise(&err, "mass_matrix");
    }
    return result;
}

/* ------------------------------------------------------------------ geodesics ----------- */

/** Runs the chosen geodesic method; `distance` has n_vertices entries. GIL released. */
static int geodesic_native(dk_py_state *gate, const dk_mesh *mesh, const char *method,
                           double time_factor, const dk_py_indices *src, double *distance)
{
    dk_error err = {0};
    dk_status st = DK_OK;

    if (strcmp(method, "dijkstra") == 0) {
        Py_BEGIN_ALLOW_THREADS
        st = dk_geodesic_dijkstra(mesh, src->data, (dk_index)src->rows, distance, &err);
        Py_END_ALLOW_THREADS
    } else if (strcmp(method, "hops") == 0) {
        dk_index *hops = PyMem_Malloc(sizeof(dk_index) * (size_t)(mesh->n_vertices + 1));
        if (!hops) {
            PyErr_NoMemory();
            return -1;
        }
        Py_BEGIN_ALLOW_THREADS
        st = dk_hop_distance(mesh, src->data, (dk_index)src->rows, hops, &err);
        if (st == DK_OK)
            for (dk_index v = 0; v < mesh->n_vertices; ++v)
                distance[v] = hops[v] < 0 ? INFINITY : (double)hops[v];
        Py_END_ALLOW_THREADS
        PyMem_Free(hops);
    } else if (strcmp(method, "heat") == 0) {
        DK_PY_BEGIN_NATIVE(gate)
        dk_heat_geodesic *heat = NULL;
        st = dk_heat_create(mesh, time_factor, &heat, &err);
        if (st == DK_OK)
            st = dk_heat_distance(heat, src->data, (dk_index)src->rows, distance, &err);
        dk_heat_free(heat);
        DK_PY_END_NATIVE
    } else {
        PyErr_Format(PyExc_ValueError,
                     "method must be 'heat', 'dijkstra' or 'hops', got '%s'", method);
        return -1;
    }
    if (st != DK_OK) {
        dk_py_raise(&err, "geodesic_distance");
        return -1;
    }
    return 0;
}

PyDoc_STRVAR(geodesic_distance_doc,
             "geodesic_distance(mesh, sources, method='heat', time_factor=1.0)\n"
             "    -> float64 array (n_vertices,)\n\n"
             "Distance of every vertex from the nearest source vertex (an int or an index\n"
             "array). 'heat': the heat method (t = time_factor * mean_edge_length^2);\n"
             "'dijkstra': exact shortest paths along edges; 'hops': edge counts (as floats).\n"
             "Unreachable vertices get inf. For many queries on one mesh use HeatGeodesic.");

static PyObject *py_geodesic_distance(PyObject *module, PyObject *args, PyObject *kwargs)
{
    static char *kwlist[] = {"mesh", "sources", "method", "time_factor", NULL};
    PyObject *mobj, *sobj, *result;
    const char *method = "heat";
    double time_factor = 1.0;
    const dk_mesh *mesh;
    dk_py_indices src = {0};
    double *d;

    if (!PyArg_ParseTupleAndKeywords(args, kwargs, "OO|sd:geodesic_distance", kwlist, &mobj,
                                     &sobj, &method, &time_factor))
        return NULL;
    mesh = dk_py_mesh_get(module, mobj, "mesh");
    if (!mesh)
        return NULL;
    if (!(time_factor > 0.0) || !isfinite(time_factor)) {
        PyErr_SetString(PyExc_ValueError, "time_factor must be positive and finite");
        return NULL;
    }
    if (read_sources(sobj, mesh, &src) < 0)
        return NULL;
    result = dk_py_new_doubles(1, mesh->n_vertices, 0, &d);
    if (result && geodesic_native(dk_py_get_state(module), mesh, method, time_factor, &src, d) < 0)
        Py_CLEAR(result);
    dk_py_indices_release(&src);
    return result;
}

/* ---- HeatGeodesic ---------------------------------------------------------------------- */

/** deformkit.HeatGeodesic: the heat method with both factorizations kept. */
typedef struct HeatObject {
    PyObject_HEAD
    PyObject *mesh_obj;          /* keeps the Mesh (and its dk_mesh) alive              */
    dk_heat_geodesic *heat;      /* owned                                               */
    PyThread_type_lock lock;     /* serialises distance() on this object (shared buffers) */
    dk_index n_vertices;
    double time_factor;
} HeatObject;

static PyObject *heat_new(PyTypeObject *type, PyObject *args, PyObject *kwargs)
{
    static char *kwlist[] = {"mesh", "time_factor", NULL};
    PyObject *mobj, *module, *self;
    double time_factor = 1.0;
    const dk_mesh *mesh;
    dk_heat_geodesic *heat = NULL;
    PyThread_type_lock lock;
    allocfunc alloc;
    dk_error err = {0};
    dk_status st;

    if (!PyArg_ParseTupleAndKeywords(args, kwargs, "O|d:HeatGeodesic", kwlist, &mobj,
                                     &time_factor))
        return NULL;
    module = PyType_GetModule(type);
    if (!module)
        return NULL;
    mesh = dk_py_mesh_get(module, mobj, "mesh");
    if (!mesh)
        return NULL;
    if (!(time_factor > 0.0) || !isfinite(time_factor)) {
        PyErr_SetString(PyExc_ValueError, "time_factor must be positive and finite");
        return NULL;
    }
    DK_PY_BEGIN_NATIVE((dk_py_state *)PyType_GetModuleState(type))
    st = dk_heat_create(mesh, time_factor, &heat, &err);
    DK_PY_END_NATIVE
    if (st != DK_OK)
        return dk_py_raise(&err, "HeatGeodesic");
    lock = PyThread_allocate_lock();
    if (!lock) {
        dk_heat_free(heat);
        return PyErr_NoMemory();
    }
    alloc = (allocfunc)PyType_GetSlot(type, Py_tp_alloc);
    self = alloc(type, 0);
    if (!self) {
        PyThread_free_lock(lock);
        dk_heat_free(heat);
        return NULL;
    }
    ((HeatObject *)self)->mesh_obj = Py_NewRef(mobj);
    ((HeatObject *)self)->heat = heat;
    ((HeatObject *)self)->lock = lock;
    ((HeatObject *)self)->n_vertices = mesh->n_vertices;
    ((HeatObject *)self)->time_factor = time_factor;
    return self;
}

/* Garbage-collector support: the object holds its Mesh, so it takes part in cycles
 * through anything that holds it (issue 18, class 5). */
static int heat_traverse(PyObject *self, visitproc visit, void *arg)
{
    Py_VISIT(Py_TYPE(self)); /* a heap type is owned by its instances */
    Py_VISIT(((HeatObject *)self)->mesh_obj);
    return 0;
}

static int heat_clear(PyObject *self)
{
    HeatObject *h = (HeatObject *)self;
    /* the factorizations borrow the mesh: free them before the mesh can go */
    dk_heat_free(h->heat);
    h->heat = NULL;
    Py_CLEAR(h->mesh_obj);
    return 0;
}

static void heat_dealloc(PyObject *self)
{
    HeatObject *h = (HeatObject *)self;
    PyTypeObject *type = Py_TYPE(self);
    freefunc tp_free = (freefunc)PyType_GetSlot(type, Py_tp_free);
    PyObject_GC_UnTrack(self);
    heat_clear(self);
    if (h->lock)
        PyThread_free_lock(h->lock);
    tp_free(self);
    Py_DECREF((PyObject *)type);
}

PyDoc_STRVAR(heat_distance_doc,
             "distance(sources) -> float64 array (n_vertices,)\n\n"
             "Approximate geodesic distance from the source vertices (two back-substitutions;\n"
             "the GIL is released). Vertices in components without a source get inf.");

static PyObject *heat_distance(PyObject *self, PyObject *args, PyObject *kwargs)
{
    static char *kwlist[] = {"sources", NULL};
    HeatObject *h = (HeatObject *)self;
    PyObject *sobj, *module, *result;
    const dk_mesh *mesh;
    dk_py_indices src = {0};
    double *d;
    dk_error err = {0};
    dk_status st;

    if (!PyArg_ParseTupleAndKeywords(args, kwargs, "O:distance", kwlist, &sobj))
        return NULL;
    if (!h->heat || !h->mesh_obj) {
        PyErr_SetString(PyExc_RuntimeError,
                        "HeatGeodesic: the object was cleared by the garbage collector");
        return NULL;
    }
    module = PyType_GetModule(Py_TYPE(self));
    if (!module)
        return NULL;
    mesh = dk_py_mesh_get(module, h->mesh_obj, "mesh");
    if (!mesh || read_sources(sobj, mesh, &src) < 0)
        return NULL;
    result = dk_py_new_doubles(1, h->n_vertices, 0, &d);
    if (!result) {
        dk_py_indices_release(&src);
        return NULL;
    }
    DK_PY_BEGIN_NATIVE(dk_py_get_state(module))
    PyThread_acquire_lock(h->lock, WAIT_LOCK);
    st = dk_heat_distance(h->heat, src.data, (dk_index)src.rows, d, &err);
    PyThread_release_lock(h->lock);
    DK_PY_END_NATIVE
    dk_py_indices_release(&src);
    if (st != DK_OK) {
        Py_DECREF(result);
        return dk_py_raise(&err, "HeatGeodesic.distance");
    }
    return result;
}

static PyObject *heat_get_mesh(PyObject *self, void *c)
{
    PyObject *m = ((HeatObject *)self)->mesh_obj;
    (void)c;
    return Py_NewRef(m ? m : Py_None);
}

static PyObject *heat_get_time_factor(PyObject *self, void *c)
{
    (void)c;
    return PyFloat_FromDouble(((HeatObject *)self)->time_factor);
}

static PyGetSetDef heat_getset[] = {
    {"mesh", heat_get_mesh, NULL, "the Mesh this was built on", NULL},
    {"time_factor", heat_get_time_factor, NULL, "t / mean_edge_length^2", NULL},
    {NULL, NULL, NULL, NULL, NULL},
};

static PyMethodDef heat_methods[] = {
    {"distance", (PyCFunction)(void (*)(void))heat_distance, METH_VARARGS | METH_KEYWORDS,
     heat_distance_doc},
    {NULL, NULL, 0, NULL},
};

PyDoc_STRVAR(heat_doc,
             "HeatGeodesic(mesh, time_factor=1.0)\n\n"
             "The heat method for geodesic distances (Crane et al. 2013), factorized once:\n"
             "each distance(sources) call then costs two back-substitutions. The time step\n"
             "is t = time_factor * mesh.mean_edge_length ** 2.");

static PyType_Slot heat_slots[] = {
    {Py_tp_new, (void *)heat_new},
    {Py_tp_dealloc, (void *)heat_dealloc},
    {Py_tp_traverse, (void *)heat_traverse},
    {Py_tp_clear, (void *)heat_clear},
    {Py_tp_methods, heat_methods},
    {Py_tp_getset, heat_getset},
    {Py_tp_doc, (void *)heat_doc},
    {0, NULL},
};

static PyType_Spec heat_spec = {
    "deformkit.HeatGeodesic",
    (int)sizeof(HeatObject),
    0,
    Py_TPFLAGS_DEFAULT | Py_TPFLAGS_IMMUTABLETYPE | Py_TPFLAGS_HAVE_GC,
    heat_slots,
};

/* ------------------------------------------------------------------ eigenpairs ---------- */

PyDoc_STRVAR(eigenpairs_doc,
             "laplacian_eigenpairs(mesh, k, mass='voronoi', tolerance=1e-10, band_size=50,\n"
             "                     max_iterations=1000) -> (eigenvalues, eigenvectors)\n\n"
             "The k smallest eigenpairs of L x = lambda M x with L the cotangent Laplacian and\n"
             "M the lumped mass matrix of the given kind: eigenvalues (k,) ascending,\n"
             "eigenvectors (n_vertices, k) M-orthonormal, one per column. Computed with\n"
             "ARPACK in shift-invert mode, band by band when k > band_size. Calls from\n"
             "several threads are serialised (ARPACK is not reentrant); the GIL is released.");

static PyObject *py_laplacian_eigenpairs(PyObject *module, PyObject *args, PyObject *kwargs)
{
    static char *kwlist[] = {"mesh", "k", "mass", "tolerance", "band_size", "max_iterations",
                             NULL};
    PyObject *mobj, *evals = NULL, *evecs = NULL, *result = NULL;
    const char *mass_name = "voronoi";
    double tolerance = 0.0;
    int k, band_size = 0, max_iterations = 0, n_converged = 0;
    const dk_mesh *mesh;
    dk_mass_kind kind;
    dk_eigs_options opt;
    dk_py_state *state = dk_py_get_state(module);
    double *vals, *vecs, *colmajor = NULL, *mass = NULL;
    dk_sparse *l = NULL;
    dk_error err = {0};
    dk_status st;
    Py_ssize_t n;

    if (!PyArg_ParseTupleAndKeywords(args, kwargs, "Oi|sdii:laplacian_eigenpairs", kwlist,
                                     &mobj, &k, &mass_name, &tolerance, &band_size,
                                     &max_iterations))
        return NULL;
    mesh = dk_py_mesh_get(module, mobj, "mesh");
    if (!mesh || parse_mass_kind(mass_name, "mass", &kind) < 0)
        return NULL;
    n = mesh->n_vertices;
    if (k < 1 || k >= n)
        return PyErr_Format(PyExc_ValueError, "k must be in [1, %zd] for a mesh of %zd "
                            "vertices, got %d", n - 1, n, k);
    if (tolerance < 0.0 || !isfinite(tolerance) || band_size < 0 || max_iterations < 0)
        return PyErr_Format(PyExc_ValueError,
                            "tolerance, band_size and max_iterations must be non-negative");
    if (dk_py_arpack_check(state, "laplacian_eigenpairs") < 0)
        return NULL;
    dk_eigs_options_default(&opt);
    if (tolerance > 0.0)
        opt.tolerance = tolerance;
    if (band_size > 0)
        opt.band_size = band_size;
    if (max_iterations > 0)
        opt.max_iterations = max_iterations;

    colmajor = PyMem_Malloc(sizeof(double) * (size_t)n * (size_t)k);
    mass = PyMem_Malloc(sizeof(double) * (size_t)n);
    if (!colmajor || !mass) {
        PyErr_NoMemory();
        goto done;
    }
    evals = dk_py_new_doubles(1, k, 0, &vals);
    evecs = evals ? dk_py_new_doubles(2, n, k, &vecs) : NULL;
    if (!evecs)
        goto done;

    DK_PY_BEGIN_NATIVE(state)
    st = dk_laplacian_cotangent(mesh, &l, &err);
    if (st == DK_OK)
        st = dk_mass_matrix(mesh, kind, mass, &err);
    if (st == DK_OK) {
        dk_py_arpack_acquire(state);
        st = dk_eigs_smallest(l, mass, k, &opt, vals, colmajor, &n_converged, &err);
        dk_py_arpack_release(state);
    }
    if (st == DK_OK)
        for (Py_ssize_t i = 0; i < n; ++i)
            for (int j = 0; j < k; ++j)
                vecs[i * k + j] = colmajor[(Py_ssize_t)j * n + i];
    DK_PY_END_NATIVE
    if (st != DK_OK) {
        dk_py_raise(&err, "laplacian_eigenpairs");
        goto done;
    }
    result = PyTuple_Pack(2, evals, evecs);
done:
    Py_XDECREF(evals);
    Py_XDECREF(evecs);
    dk_sparse_free(l);
    PyMem_Free(colmajor);
    PyMem_Free(mass);
    return result;
}

/* ------------------------------------------------------------------ nearest neighbours -- */

/** Reads finite n x 3 points; `what` names them in messages. */
static int read_points(PyObject *obj, const char *what, dk_py_doubles *out)
{
    dk_error err = {0};
    if (dk_py_read_doubles(obj, -1, 3, what, out) < 0)
        return -1;
    if (dk_check_positions(out->data, (dk_index)out->rows, &err) != DK_OK) {
        dk_py_doubles_release(out);
        dk_py_raise(&err, what);
        return -1;
    }
    return 0;
}

/** Queries `tree` (n_points points) for k neighbours of `qobj`; returns (indices, sqdist). */
static PyObject *knn_query(const dk_kdtree *tree, dk_index n_points, PyObject *qobj, int k,
                           const char *context)
{
    dk_py_doubles q = {0};
    PyObject *idx = NULL, *dist = NULL, *result = NULL;
    dk_index *ip;
    double *dp;
    dk_error err = {0};
    dk_status st;

    if (k < 1 || k > n_points)
        return PyErr_Format(PyExc_ValueError, "%s: k must be in [1, %d], got %d", context,
                            (int)n_points, k);
    if (read_points(qobj, "queries", &q) < 0)
        return NULL;
    idx = dk_py_new_indices(2, q.rows, k, &ip);
    dist = idx ? dk_py_new_doubles(2, q.rows, k, &dp) : NULL;
    if (dist) {
        Py_BEGIN_ALLOW_THREADS
        st = dk_kdtree_knn(tree, q.data, (dk_index)q.rows, (dk_index)k, ip, dp, &err);
        Py_END_ALLOW_THREADS
        if (st != DK_OK)
            dk_py_raise(&err, context);
        else
            result = PyTuple_Pack(2, idx, dist);
    }
    Py_XDECREF(idx);
    Py_XDECREF(dist);
    dk_py_doubles_release(&q);
    return result;
}

PyDoc_STRVAR(knn_doc,
             "knn(points, queries, k) -> (indices, squared_distances)\n\n"
             "The k nearest of `points` (n x 3) to each of `queries` (m x 3): int32 (m, k)\n"
             "indices sorted by increasing distance (ties by index) and float64 (m, k)\n"
             "squared distances. Builds a KDTree per call; keep a KDTree to query often.");

static PyObject *py_knn(PyObject *module, PyObject *args, PyObject *kwargs)
{
    static char *kwlist[] = {"points", "queries", "k", NULL};
    PyObject *pobj, *qobj, *result;
    dk_py_doubles p = {0};
    dk_kdtree *tree = NULL;
    int k;
    dk_error err = {0};
    dk_status st;

    (void)module;
    if (!PyArg_ParseTupleAndKeywords(args, kwargs, "OOi:knn", kwlist, &pobj, &qobj, &k))
        return NULL;
    if (read_points(pobj, "points", &p) < 0)
        return NULL;
    if (p.rows == 0) {
        dk_py_doubles_release(&p);
        PyErr_SetString(PyExc_ValueError, "knn: points is empty");
        return NULL;
    }
    Py_BEGIN_ALLOW_THREADS
    st = dk_kdtree_create(p.data, (dk_index)p.rows, &tree, &err);
    Py_END_ALLOW_THREADS
    if (st != DK_OK) {
        dk_py_doubles_release(&p);
        return dk_py_raise(&err, "knn");
    }
    result = knn_query(tree, (dk_index)p.rows, qobj, k, "knn");
    dk_kdtree_free(tree);
    dk_py_doubles_release(&p);
    return result;
}

PyDoc_STRVAR(tetrahedralize_doc,
             "tetrahedralize(vertices, triangles, quality=0.0, max_volume=0.0)\n"
             "    -> (points, tetrahedra)\n\n"
             "The interior of a closed surface tetrahedralized by TetGen: vertices (n x 3)\n"
             "and triangles (m x 3) a closed manifold surface (every edge in two triangles,\n"
             "none degenerate, no self-intersection: refused by name, ValueError). The\n"
             "surface is the boundary and gets no point of its own: points[:n] is\n"
             "vertices, bit for bit; points past n lie inside. quality: 0 (none) or the\n"
             "largest radius-edge ratio in [1.1, 10] (1.5 is usual); max_volume: 0 (none)\n"
             "or the largest tetrahedron volume. tetrahedra: int32 (k, 4) indices into\n"
             "points.");

static PyObject *py_tetrahedralize(PyObject *module, PyObject *args, PyObject *kwargs)
{
    static char *kwlist[] = {"vertices", "triangles", "quality", "max_volume", NULL};
    PyObject *vobj, *fobj;
    double quality = 0.0, max_volume = 0.0;
    dk_py_doubles v = {0};
    dk_py_indices f = {0};
    double *points = NULL;
    dk_index *tets = NULL, np = 0, nt = 0;
    dk_error err = {0};
    dk_status st;

    (void)module;
    if (!PyArg_ParseTupleAndKeywords(args, kwargs, "OO|dd:tetrahedralize", kwlist, &vobj, &fobj,
                                     &quality, &max_volume))
        return NULL;
    if (dk_py_read_surface(vobj, fobj, &v, &f) < 0)
        return NULL;
    Py_BEGIN_ALLOW_THREADS
    st = dk_tetrahedralize_surface(v.data, (dk_index)v.rows, f.data, (dk_index)f.rows, quality,
                                   max_volume, &points, &np, &tets, &nt, &err);
    Py_END_ALLOW_THREADS
    dk_py_doubles_release(&v);
    dk_py_indices_release(&f);
    if (st != DK_OK)
        return dk_py_raise(&err, NULL); /* the message names it */
    double *pd;
    dk_index *td;
    PyObject *po = dk_py_new_doubles(2, np, 3, &pd);
    PyObject *to = po ? dk_py_new_indices(2, nt, 4, &td) : NULL;
    if (to) {
        memcpy(pd, points, sizeof(double) * 3 * (size_t)np);
        memcpy(td, tets, sizeof(dk_index) * 4 * (size_t)nt);
    }
    free(points);
    free(tets);
    if (!to) {
        Py_XDECREF(po);
        return NULL;
    }
    return Py_BuildValue("(NN)", po, to);
}

PyDoc_STRVAR(decimate_doc,
             "decimate(mesh, target_vertices, classes=None) -> dict\n\n"
             "The mesh (a deformkit.Mesh) simplified by half-edge collapses in quadric-error\n"
             "order to at most target_vertices vertices where it can (fewer collapses when\n"
             "none keeps the mesh manifold and unfolded): the coarse level of ARAP's multi-\n"
             "scale solve. The coarse vertices are mesh vertices, where they were. classes:\n"
             "None or one int per vertex: a vertex collapses only into one of its class, and\n"
             "a negative class is never removed. Returns {'kept': coarse vertex -> mesh\n"
             "vertex (ascending), 'triangles': the coarse triangles (coarse indices),\n"
             "'removed': mesh vertices in removal order, 'carriers' (len(removed) x 3) and\n"
             "'weights' (len(removed) x 3): the corners of the coarse triangle nearest to\n"
             "each when it was removed and its nearest point's barycentric weights}.");

static PyObject *py_decimate(PyObject *module, PyObject *args, PyObject *kwargs)
{
    static char *kwlist[] = {"mesh", "target_vertices", "classes", NULL};
    PyObject *mobj, *cobj = Py_None;
    Py_ssize_t target = 0;
    dk_py_indices c = {0};
    dk_decimation *d = NULL;
    dk_error err = {0};
    dk_status st;

    if (!PyArg_ParseTupleAndKeywords(args, kwargs, "On|O:decimate", kwlist, &mobj, &target,
                                     &cobj))
        return NULL;
    const dk_mesh *mesh = dk_py_mesh_get(module, mobj, "mesh");
    if (!mesh)
        return NULL;
    if (target < 1 || target > (Py_ssize_t)mesh->n_vertices) {
        PyErr_Format(PyExc_ValueError,
                     "decimate: target_vertices is %zd, must be in [1, %ld] (the mesh's)",
                     target, (long)mesh->n_vertices);
        return NULL;
    }
    if (cobj != Py_None && dk_py_read_indices(cobj, mesh->n_vertices, 0, "classes", &c) < 0)
        return NULL;
    int *cls = NULL;
    if (c.data) {
        cls = malloc(sizeof(int) * ((size_t)mesh->n_vertices + 1));
        if (!cls) {
            dk_py_indices_release(&c);
            return PyErr_NoMemory();
        }
        for (dk_index v = 0; v < mesh->n_vertices; v++)
            cls[v] = (int)c.data[v];
        dk_py_indices_release(&c);
    }
    Py_BEGIN_ALLOW_THREADS
    st = dk_decimate(mesh, cls, (dk_index)target, &d, &err);
    Py_END_ALLOW_THREADS
    free(cls);
    if (st != DK_OK)
        return dk_py_raise(&err, NULL);
    dk_index *kd, *fd, *rd, *cd;
    double *wd;
    PyObject *ko = dk_py_new_indices(1, d->n_kept, 1, &kd);
    PyObject *fo = ko ? dk_py_new_indices(2, d->n_faces, 3, &fd) : NULL;
    PyObject *ro = fo ? dk_py_new_indices(1, d->n_removed, 1, &rd) : NULL;
    PyObject *co = ro ? dk_py_new_indices(2, d->n_removed, 3, &cd) : NULL;
    PyObject *wo = co ? dk_py_new_doubles(2, d->n_removed, 3, &wd) : NULL;
    PyObject *result = NULL;
    if (wo) {
        memcpy(kd, d->kept, sizeof(dk_index) * (size_t)d->n_kept);
        memcpy(fd, d->faces, sizeof(dk_index) * 3 * (size_t)d->n_faces);
        memcpy(rd, d->removed, sizeof(dk_index) * (size_t)d->n_removed);
        memcpy(cd, d->carrier, sizeof(dk_index) * 3 * (size_t)d->n_removed);
        memcpy(wd, d->weight, sizeof(double) * 3 * (size_t)d->n_removed);
        result = Py_BuildValue("{sOsOsOsOsO}", "kept", ko, "triangles", fo, "removed", ro,
                               "carriers", co, "weights", wo);
    }
    Py_XDECREF(ko);
    Py_XDECREF(fo);
    Py_XDECREF(ro);
    Py_XDECREF(co);
    Py_XDECREF(wo);
    dk_decimation_free(d);
    return result;
}

/** deformkit.KDTree: a static k-d tree over a copy of the points. */
typedef struct KDTreeObject {
    PyObject_HEAD
    dk_kdtree *tree; /* owned */
    dk_index n_points;
} KDTreeObject;

static PyObject *kdtree_new(PyTypeObject *type, PyObject *args, PyObject *kwargs)
{
    static char *kwlist[] = {"points", NULL};
    PyObject *pobj, *self;
    dk_py_doubles p = {0};
    dk_kdtree *tree = NULL;
    allocfunc alloc;
    dk_error err = {0};
    dk_status st;

    if (!PyArg_ParseTupleAndKeywords(args, kwargs, "O:KDTree", kwlist, &pobj))
        return NULL;
    if (read_points(pobj, "points", &p) < 0)
        return NULL;
    if (p.rows == 0) {
        dk_py_doubles_release(&p);
        PyErr_SetString(PyExc_ValueError, "KDTree: points is empty");
        return NULL;
    }
    Py_BEGIN_ALLOW_THREADS
    st = dk_kdtree_create(p.data, (dk_index)p.rows, &tree, &err);
    Py_END_ALLOW_THREADS
    if (st != DK_OK) {
        dk_py_doubles_release(&p);
        return dk_py_raise(&err, "KDTree");
    }
    alloc = (allocfunc)PyType_GetSlot(type, Py_tp_alloc);
    self = alloc(type, 0);
    if (!self) {
        dk_kdtree_free(tree);
        dk_py_doubles_release(&p);
        return NULL;
    }
    ((KDTreeObject *)self)->tree = tree;
    ((KDTreeObject *)self)->n_points = (dk_index)p.rows;
    dk_py_doubles_release(&p);
    return self;
}

static void kdtree_dealloc(PyObject *self)
{
    PyTypeObject *type = Py_TYPE(self);
    freefunc tp_free = (freefunc)PyType_GetSlot(type, Py_tp_free);
    dk_kdtree_free(((KDTreeObject *)self)->tree);
    tp_free(self);
    Py_DECREF((PyObject *)type);
}

PyDoc_STRVAR(kdtree_query_doc,
             "query(queries, k) -> (indices, squared_distances)\n\n"
             "As knn(points, queries, k) on this tree's points. Thread-safe; GIL released.");

static PyObject *kdtree_query(PyObject *self, PyObject *args, PyObject *kwargs)
{
    static char *kwlist[] = {"queries", "k", NULL};
    PyObject *qobj;
    int k;
    if (!PyArg_ParseTupleAndKeywords(args, kwargs, "Oi:query", kwlist, &qobj, &k))
        return NULL;
    return knn_query(((KDTreeObject *)self)->tree, ((KDTreeObject *)self)->n_points, qobj, k,
                     "KDTree.query");
}

static PyObject *kdtree_get_n_points(PyObject *self, void *c)
{
    (void)c;
    return PyLong_FromLong(((KDTreeObject *)self)->n_points);
}

static PyGetSetDef kdtree_getset[] = {
    {"n_points", kdtree_get_n_points, NULL, "number of points in the tree", NULL},
    {NULL, NULL, NULL, NULL, NULL},
};

static PyMethodDef kdtree_methods[] = {
    {"query", (PyCFunction)(void (*)(void))kdtree_query, METH_VARARGS | METH_KEYWORDS,
     kdtree_query_doc},
    {NULL, NULL, 0, NULL},
};

PyDoc_STRVAR(kdtree_doc, "KDTree(points)\n\n"
                         "A static k-d tree over a copy of n x 3 points, for repeated\n"
                         "nearest-neighbour queries (see query).");

static PyType_Slot kdtree_slots[] = {
    {Py_tp_new, (void *)kdtree_new},
    {Py_tp_dealloc, (void *)kdtree_dealloc},
    {Py_tp_methods, kdtree_methods},
    {Py_tp_getset, kdtree_getset},
    {Py_tp_doc, (void *)kdtree_doc},
    {0, NULL},
};

static PyType_Spec kdtree_spec = {
    "deformkit.KDTree",
    (int)sizeof(KDTreeObject),
    0,
    Py_TPFLAGS_DEFAULT | Py_TPFLAGS_IMMUTABLETYPE,
    kdtree_slots,
};

/* ------------------------------------------------------------------ rotations ----------- */

PyDoc_STRVAR(closest_rotation_doc,
             "closest_rotation(A) -> float64 array (3, 3)\n\n"
             "The rotation R (det R = +1) nearest to the 3x3 matrix A in the Frobenius norm,\n"
             "i.e. the maximiser of trace(R^T A). Proper even for reflections and\n"
             "rank-deficient A; the identity for A = 0.");

static PyObject *py_closest_rotation(PyObject *module, PyObject *arg)
{
    dk_py_doubles a = {0};
    double *r;
    PyObject *result;

    (void)module;
    if (dk_py_read_doubles(arg, 3, 3, "A", &a) < 0)
        return NULL;
    for (int i = 0; i < 9; ++i) {
        if (!isfinite(a.data[i])) {
            dk_py_doubles_release(&a);
            return PyErr_Format(PyExc_ValueError, "A[%d, %d] is not finite", i / 3, i % 3);
        }
    }
    result = dk_py_new_doubles(2, 3, 3, &r);
    if (result)
        (void)dk_closest_rotation(a.data, r);
    dk_py_doubles_release(&a);
    return result;
}

/* ------------------------------------------------------------------ harmonic maps ------- */

PyDoc_STRVAR(harmonic_material_doc,
             "harmonic_material(mesh, vertices, values, fallback=1.0, per='edge') -> array\n\n"
             "A smooth material map from a few painted values (the future work of Li's\n"
             "paper): u = values at `vertices`, L u = 0 elsewhere (cotangent weights clamped\n"
             "non-negative, so u stays between the painted extremes). A component with no\n"
             "painted vertex gets `fallback`. per='edge' returns one value per edge\n"
             "(Mesh.edges order: the mean of its ends), as LinearReconstruction's material\n"
             "takes it; per='vertex' the per-vertex u.");

static PyObject *py_harmonic_material(PyObject *module, PyObject *args, PyObject *kwargs)
{
    static char *kwlist[] = {"mesh", "vertices", "values", "fallback", "per", NULL};
    PyObject *mobj, *vobj, *valobj, *result = NULL;
    double fallback = 1.0, *out, *uv = NULL;
    const char *per = "edge";
    dk_py_indices idx = {0};
    dk_py_doubles val = {0};
    dk_error err = {0};
    dk_status st;
    if (!PyArg_ParseTupleAndKeywords(args, kwargs, "OOO|ds:harmonic_material", kwlist, &mobj,
                                     &vobj, &valobj, &fallback, &per))
        return NULL;
    const dk_mesh *mesh = dk_py_mesh_get(module, mobj, "mesh");
    if (!mesh)
        return NULL;
    const int by_edge = strcmp(per, "edge") == 0;
    if (!by_edge && strcmp(per, "vertex") != 0) {
        PyErr_Format(PyExc_ValueError, "harmonic_material: per must be 'edge' or 'vertex', "
                     "not '%s'", per);
        return NULL;
    }
    if (dk_py_read_indices(vobj, -1, 0, "vertices", &idx) < 0)
        return NULL;
    if (dk_py_read_doubles(valobj, idx.rows, 0, "values", &val) < 0) {
        dk_py_indices_release(&idx);
        return NULL;
    }
    result = dk_py_new_doubles(1, by_edge ? mesh->n_edges : mesh->n_vertices, 0, &out);
    uv = by_edge ? PyMem_Malloc(((size_t)mesh->n_vertices + 1) * sizeof *uv) : NULL;
    if (result && (!by_edge || uv)) {
        DK_PY_BEGIN_NATIVE(dk_py_get_state(module))
        st = dk_harmonic_interpolation(mesh, idx.data, val.data, (dk_index)idx.rows, fallback,
                                       by_edge ? uv : out, by_edge ? out : NULL, &err);
        DK_PY_END_NATIVE
        if (st != DK_OK) {
            Py_CLEAR(result);
            dk_py_raise(&err, "harmonic_material");
        }
    } else if (result) {
        Py_CLEAR(result);
        PyErr_NoMemory();
    }
    PyMem_Free(uv);
    dk_py_indices_release(&idx);
    dk_py_doubles_release(&val);
    return result;
}

/* ------------------------------------------------------------------ registration -------- */

static PyMethodDef operator_functions[] = {
    {"uniform_laplacian", (PyCFunction)(void (*)(void))py_uniform_laplacian,
     METH_VARARGS | METH_KEYWORDS, uniform_laplacian_doc},
    {"cotangent_laplacian", (PyCFunction)(void (*)(void))py_cotangent_laplacian,
     METH_VARARGS | METH_KEYWORDS, cotangent_laplacian_doc},
    {"cotangent_weights", (PyCFunction)(void (*)(void))py_cotangent_weights,
     METH_VARARGS | METH_KEYWORDS, cotangent_weights_doc},
    {"mass_matrix", (PyCFunction)(void (*)(void))py_mass_matrix, METH_VARARGS | METH_KEYWORDS,
     mass_matrix_doc},
    {"geodesic_distance", (PyCFunction)(void (*)(void))py_geodesic_distance,
     METH_VARARGS | METH_KEYWORDS, geodesic_distance_doc},
    {"laplacian_eigenpairs", (PyCFunction)(void (*)(void))py_laplacian_eigenpairs,
     METH_VARARGS | METH_KEYWORDS, eigenpairs_doc},
    {"knn", (PyCFunction)(void (*)(void))py_knn, METH_VARARGS | METH_KEYWORDS, knn_doc},
    {"tetrahedralize", (PyCFunction)(void (*)(void))py_tetrahedralize,
     METH_VARARGS | METH_KEYWORDS, tetrahedralize_doc},
    {"decimate", (PyCFunction)(void (*)(void))py_decimate, METH_VARARGS | METH_KEYWORDS,
     decimate_doc},
    {"closest_rotation", py_closest_rotation, METH_O, closest_rotation_doc},
    {"harmonic_material", (PyCFunction)(void (*)(void))py_harmonic_material,
     METH_VARARGS | METH_KEYWORDS, harmonic_material_doc},
    {NULL, NULL, 0, NULL},
};

static int add_type(PyObject *module, PyType_Spec *spec, const char *name)
{
    PyObject *type = PyType_FromModuleAndSpec(module, spec, NULL);
    int rc;
    if (!type)
        return -1;
    rc = PyModule_AddObjectRef(module, name, type);
    Py_DECREF(type);
    return rc;
}

int dk_py_init_operators(PyObject *module)
{
    if (add_type(module, &heat_spec, "HeatGeodesic") < 0 ||
        add_type(module, &kdtree_spec, "KDTree") < 0)
        return -1;
    return PyModule_AddFunctions(module, operator_functions);
}
