/* DeformKit CPython module: deformkit.Mesh and the mesh file readers.
 *
 * A Mesh wraps an immutable dk_mesh. Properties return fresh arrays (copies), so Python code
 * can never write into the native mesh that bound methods share.
 */
#include "dk_py.h"

#include <string.h>

#if defined(__has_include)
#if __has_include("dk_io.h")
#include "dk_io.h"
#define DK_PY_HAVE_IO 1
#endif
#endif
#ifndef DK_PY_HAVE_IO
#define DK_PY_HAVE_IO 0
#endif

/** The instance layout of deformkit.Mesh. */
typedef struct MeshObject {
    PyObject_HEAD
    dk_mesh *mesh; /* owned; never NULL on a constructed object */
} MeshObject;

static dk_mesh *mesh_of(PyObject *self)
{
    return ((MeshObject *)self)->mesh;
}

/* ------------------------------------------------------------------ construction -------- */

/** Wraps `mesh` (ownership taken, freed on failure) into a new instance of `type`. */
static PyObject *wrap_mesh(PyTypeObject *type, dk_mesh *mesh)
{
    allocfunc alloc = (allocfunc)PyType_GetSlot(type, Py_tp_alloc);
    PyObject *self = alloc ? alloc(type, 0) : NULL;
    if (!self) {
        dk_mesh_free(mesh);
        if (!PyErr_Occurred())
            PyErr_NoMemory();
        return NULL;
    }
    ((MeshObject *)self)->mesh = mesh;
    return self;
}

static PyObject *mesh_new(PyTypeObject *type, PyObject *args, PyObject *kwargs)
{
    static char *kwlist[] = {"vertices", "triangles", NULL};
    PyObject *vobj, *fobj;
    dk_py_doubles v = {0};
    dk_py_indices f = {0};
    dk_mesh *mesh = NULL;
    dk_error err = {0};
    dk_status st;

    if (!PyArg_ParseTupleAndKeywords(args, kwargs, "OO:Mesh", kwlist, &vobj, &fobj))
        return NULL;
    if (dk_py_read_surface(vobj, fobj, &v, &f) < 0)
        return NULL;
    Py_BEGIN_ALLOW_THREADS
    st = dk_mesh_create(v.data, (dk_index)v.rows, f.data, (dk_index)f.rows, &mesh, &err);
    Py_END_ALLOW_THREADS
    dk_py_doubles_release(&v);
    dk_py_indices_release(&f);
    if (st != DK_OK)
        return dk_py_raise(&err, "Mesh");
    return wrap_mesh(type, mesh);
}

/** Builds a dk_mesh from polygon arrays already read; releases the GIL while working. */
static dk_mesh *mesh_from_polygon_arrays(const dk_py_doubles *v, const dk_py_indices *sizes,
                                         const dk_py_indices *idx, const char *context)
{
    dk_mesh *mesh = NULL;
    dk_error err = {0};
    dk_status st;

    Py_BEGIN_ALLOW_THREADS
    st = dk_mesh_from_polygons(v->data, (dk_index)v->rows, sizes->data, (dk_index)sizes->rows,
                               idx->data, (int64_t)idx->rows, &mesh, &err);
    Py_END_ALLOW_THREADS
    if (st != DK_OK) {
        dk_py_raise(&err, context);
        return NULL;
    }
    return mesh;
}

PyDoc_STRVAR(from_polygons_doc,
             "Mesh.from_polygons(vertices, face_sizes, indices) -> Mesh\n\n"
             "Builds a mesh from n-gons: polygon p has face_sizes[p] corners whose vertex\n"
             "indices follow one another in `indices`. Quads are split along the shorter\n"
             "diagonal, larger polygons ear-clipped; `face_polygon` maps triangles back.");

static PyObject *mesh_from_polygons(PyObject *cls, PyObject *args, PyObject *kwargs)
{
    static char *kwlist[] = {"vertices", "face_sizes", "indices", NULL};
    PyObject *vobj, *sobj, *iobj;
    dk_py_doubles v = {0};
    dk_py_indices sizes = {0}, idx = {0};
    dk_mesh *mesh;

    if (!PyArg_ParseTupleAndKeywords(args, kwargs, "OOO:from_polygons", kwlist, &vobj, &sobj,
                                     &iobj))
        return NULL;
    if (dk_py_read_doubles(vobj, -1, 3, "vertices", &v) < 0 ||
        dk_py_read_indices(sobj, -1, 0, "face_sizes", &sizes) < 0 ||
        dk_py_read_indices(iobj, -1, 0, "indices", &idx) < 0) {
        dk_py_doubles_release(&v);
        dk_py_indices_release(&sizes);
        dk_py_indices_release(&idx);
        return NULL;
    }
    mesh = mesh_from_polygon_arrays(&v, &sizes, &idx, "Mesh.from_polygons");
    dk_py_doubles_release(&v);
    dk_py_indices_release(&sizes);
    dk_py_indices_release(&idx);
    if (!mesh)
        return NULL;
    return wrap_mesh((PyTypeObject *)cls, mesh);
}

static void mesh_dealloc(PyObject *self)
{
    PyTypeObject *type = Py_TYPE(self);
    freefunc tp_free = (freefunc)PyType_GetSlot(type, Py_tp_free);
    dk_mesh_free(mesh_of(self));
    ((MeshObject *)self)->mesh = NULL;
    tp_free(self);
    Py_DECREF((PyObject *)type);
}

static PyObject *mesh_repr(PyObject *self)
{
    const dk_mesh *m = mesh_of(self);
    return PyUnicode_FromFormat("deformkit.Mesh(n_vertices=%d, n_faces=%d, n_edges=%d)",
                                (int)m->n_vertices, (int)m->n_faces, (int)m->n_edges);
}

/* ------------------------------------------------------------------ properties ---------- */

/** A fresh (rows x cols) int32 array copied from `src` (ndim 1 when cols == 0). */
static PyObject *copy_indices(const dk_index *src, Py_ssize_t rows, Py_ssize_t cols)
{
    dk_index *dst;
    PyObject *a = dk_py_new_indices(cols ? 2 : 1, rows, cols, &dst);
    if (a && rows > 0)
        memcpy(dst, src, sizeof(dk_index) * (size_t)rows * (size_t)(cols ? cols : 1));
    return a;
}

static PyObject *get_n_vertices(PyObject *self, void *c)
{
    (void)c;
    return PyLong_FromLong(mesh_of(self)->n_vertices);
}

static PyObject *get_n_faces(PyObject *self, void *c)
{
    (void)c;
    return PyLong_FromLong(mesh_of(self)->n_faces);
}

static PyObject *get_n_edges(PyObject *self, void *c)
{
    (void)c;
    return PyLong_FromLong(mesh_of(self)->n_edges);
}

static PyObject *get_n_polygons(PyObject *self, void *c)
{
    (void)c;
    return PyLong_FromLong(mesh_of(self)->n_polygons);
}

static PyObject *get_n_components(PyObject *self, void *c)
{
    (void)c;
    return PyLong_FromLong(mesh_of(self)->report.n_components);
}

static PyObject *get_vertices(PyObject *self, void *c)
{
    const dk_mesh *m = mesh_of(self);
    double *dst;
    PyObject *a = dk_py_new_doubles(2, m->n_vertices, 3, &dst);
    (void)c;
    if (a && m->n_vertices > 0)
        memcpy(dst, m->positions, sizeof(double) * 3 * (size_t)m->n_vertices);
    return a;
}

static PyObject *get_triangles(PyObject *self, void *c)
{
    (void)c;
    return copy_indices(mesh_of(self)->faces, mesh_of(self)->n_faces, 3);
}

static PyObject *get_edges(PyObject *self, void *c)
{
    (void)c;
    return copy_indices(mesh_of(self)->edges, mesh_of(self)->n_edges, 2);
}

static PyObject *get_edge_faces(PyObject *self, void *c)
{
    (void)c;
    return copy_indices(mesh_of(self)->edge_faces, mesh_of(self)->n_edges, 2);
}

static PyObject *get_face_polygon(PyObject *self, void *c)
{
    (void)c;
    return copy_indices(mesh_of(self)->face_polygon, mesh_of(self)->n_faces, 0);
}

static PyObject *get_components(PyObject *self, void *c)
{
    (void)c;
    return copy_indices(mesh_of(self)->component, mesh_of(self)->n_vertices, 0);
}

static PyObject *get_boundary_vertices(PyObject *self, void *c)
{
    const dk_mesh *m = mesh_of(self);
    Py_ssize_t count = 0, k = 0;
    dk_index *dst;
    PyObject *a;
    (void)c;
    for (dk_index v = 0; v < m->n_vertices; ++v)
        count += m->is_boundary_vertex[v] != 0;
    a = dk_py_new_indices(1, count, 0, &dst);
    if (!a)
        return NULL;
    for (dk_index v = 0; v < m->n_vertices; ++v)
        if (m->is_boundary_vertex[v])
            dst[k++] = v;
    return a;
}

static PyObject *get_bbox(PyObject *self, void *c)
{
    const dk_mesh *m = mesh_of(self);
    double *dst;
    PyObject *a = dk_py_new_doubles(2, 2, 3, &dst);
    (void)c;
    if (a) {
        memcpy(dst, m->bbox_min, sizeof m->bbox_min);
        memcpy(dst + 3, m->bbox_max, sizeof m->bbox_max);
    }
    return a;
}

static PyObject *get_bbox_diagonal(PyObject *self, void *c)
{
    (void)c;
    return PyFloat_FromDouble(mesh_of(self)->bbox_diagonal);
}

static PyObject *get_mean_edge_length(PyObject *self, void *c)
{
    (void)c;
    return PyFloat_FromDouble(mesh_of(self)->mean_edge_length);
}

static PyObject *get_report(PyObject *self, void *c)
{
    const dk_mesh_report *r = &mesh_of(self)->report;
    (void)c;
    return Py_BuildValue("{s:i,s:i,s:i,s:i,s:i,s:i,s:i,s:i}",
                         "n_degenerate_faces", (int)r->n_degenerate_faces,
                         "n_nonmanifold_edges", (int)r->n_nonmanifold_edges,
                         "n_isolated_vertices", (int)r->n_isolated_vertices,
                         "n_boundary_edges", (int)r->n_boundary_edges,
                         "n_components", (int)r->n_components,
                         "first_degenerate_face", (int)r->first_degenerate_face,
                         "first_nonmanifold_edge", (int)r->first_nonmanifold_edge,
                         "first_isolated_vertex", (int)r->first_isolated_vertex);
}

static PyGetSetDef mesh_getset[] = {
    {"n_vertices", get_n_vertices, NULL, "number of vertices (int)", NULL},
    {"n_faces", get_n_faces, NULL, "number of triangles (int)", NULL},
    {"n_edges", get_n_edges, NULL, "number of unique undirected edges (int)", NULL},
    {"n_polygons", get_n_polygons, NULL, "number of input polygons (== n_faces for Mesh())",
     NULL},
    {"n_components", get_n_components, NULL,
     "number of connected components (an isolated vertex counts as one)", NULL},
    {"vertices", get_vertices, NULL, "n_vertices x 3 float64 positions (a copy)", NULL},
    {"triangles", get_triangles, NULL, "n_faces x 3 int32 vertex indices (a copy)", NULL},
    {"edges", get_edges, NULL,
     "n_edges x 2 int32 unique edges (a < b per row, rows sorted lexicographically)", NULL},
    {"edge_faces", get_edge_faces, NULL,
     "n_edges x 2 int32: the first two triangles on each edge, -1 where absent", NULL},
    {"face_polygon", get_face_polygon, NULL,
     "n_faces int32: the input polygon each triangle came from", NULL},
    {"boundary_vertices", get_boundary_vertices, NULL,
     "int32 indices (ascending) of the vertices on a boundary edge", NULL},
    {"components", get_components, NULL, "n_vertices int32 connected-component ids", NULL},
    {"bbox", get_bbox, NULL, "2 x 3 float64: bounding box minimum (row 0), maximum (row 1)",
     NULL},
    {"bbox_diagonal", get_bbox_diagonal, NULL, "length of the bounding box diagonal", NULL},
    {"mean_edge_length", get_mean_edge_length, NULL, "mean length of the unique edges", NULL},
    {"report", get_report, NULL,
     "dict of what validation found: degenerate faces, non-manifold edges, isolated "
     "vertices, boundary edges, components, and one example index of each (-1 if none)",
     NULL},
    {NULL, NULL, NULL, NULL, NULL},
};

PyDoc_STRVAR(one_ring_doc, "one_ring(v) -> int32 array\n\n"
                           "The neighbours of vertex v, sorted ascending. IndexError when v "
                           "is out of range.");

static PyObject *mesh_one_ring(PyObject *self, PyObject *arg)
{
    const dk_mesh *m = mesh_of(self);
    long long v = PyLong_AsLongLong(arg);
    dk_index begin, end;

    if (v == -1 && PyErr_Occurred())
        return NULL;
    if (v < 0 || v >= m->n_vertices)
        return PyErr_Format(PyExc_IndexError, "vertex %lld is out of range [0, %d)", v,
                            (int)m->n_vertices);
    begin = m->ring_start[v];
    end = m->ring_start[v + 1];
    return copy_indices(m->ring_index + begin, end - begin, 0);
}

static PyMethodDef mesh_methods[] = {
    {"from_polygons", (PyCFunction)(void (*)(void))mesh_from_polygons,
     METH_VARARGS | METH_KEYWORDS | METH_CLASS, from_polygons_doc},
    {"one_ring", mesh_one_ring, METH_O, one_ring_doc},
    {NULL, NULL, 0, NULL},
};

PyDoc_STRVAR(mesh_doc,
             "Mesh(vertices, triangles)\n\n"
             "A validated, immutable triangle mesh with its topology.\n\n"
             "vertices: n x 3 floats (any buffer or nested sequence, or a flat 3n array);\n"
             "triangles: m x 3 integer vertex indices. Raises IndexError for an index out of\n"
             "range (naming face and corner), ValueError for a non-finite coordinate (naming\n"
             "the vertex) or a face repeating a vertex, TypeError for non-numeric data.\n"
             "Zero-area faces, non-manifold edges, isolated vertices and several components\n"
             "are accepted and counted in `report`.");

static PyType_Slot mesh_slots[] = {
    {Py_tp_new, (void *)mesh_new},
    {Py_tp_dealloc, (void *)mesh_dealloc},
    {Py_tp_repr, (void *)mesh_repr},
    {Py_tp_getset, mesh_getset},
    {Py_tp_methods, mesh_methods},
    {Py_tp_doc, (void *)mesh_doc},
    {0, NULL},
};

static PyType_Spec mesh_spec = {
    "deformkit.Mesh",
    (int)sizeof(MeshObject),
    0,
    Py_TPFLAGS_DEFAULT | Py_TPFLAGS_IMMUTABLETYPE,
    mesh_slots,
};

/* ------------------------------------------------------------------ shared accessors ---- */

const dk_mesh *dk_py_mesh_get(PyObject *module, PyObject *obj, const char *argname)
{
    dk_py_state *st = dk_py_get_state(module);
    if (!st || !st->mesh_type) {
        PyErr_SetString(PyExc_SystemError, "deformkit: Mesh type is not initialised");
        return NULL;
    }
    if (!obj || !PyObject_TypeCheck(obj, (PyTypeObject *)st->mesh_type)) {
        PyObject *tn = obj ? PyType_GetName(Py_TYPE(obj)) : NULL;
        if (tn) {
            PyErr_Format(PyExc_TypeError, "%s must be a deformkit.Mesh, got %U",
                         argname ? argname : "mesh", tn);
            Py_DECREF(tn);
        } else if (!PyErr_Occurred()) {
            PyErr_Format(PyExc_TypeError, "%s must be a deformkit.Mesh",
                         argname ? argname : "mesh");
        }
        return NULL;
    }
    return mesh_of(obj);
}

PyObject *dk_py_mesh_type(PyObject *module)
{
    dk_py_state *st = dk_py_get_state(module);
    return st ? st->mesh_type : NULL;
}

/* ------------------------------------------------------------------ file reading -------- */

#if DK_PY_HAVE_IO
/** Reads a mesh file into owned arrays; the GIL is released while reading. */
static int read_file_arrays(PyObject *pathobj, dk_py_doubles *v, dk_py_indices *sizes,
                            dk_py_indices *idx)
{
    PyObject *bytes = NULL;
    const char *path;
    dk_mesh_file data;
    dk_error err = {0};
    dk_status st;

    memset(&data, 0, sizeof data);
    if (!PyUnicode_FSConverter(pathobj, &bytes))
        return -1;
    path = PyBytes_AsString(bytes);
    if (!path) {
        Py_DECREF(bytes);
        return -1;
    }
    Py_BEGIN_ALLOW_THREADS
    st = dk_read_mesh_file(path, &data, &err);
    Py_END_ALLOW_THREADS
    Py_DECREF(bytes);
    if (st != DK_OK) {
        dk_py_raise(&err, "load_mesh_file");
        return -1;
    }
    /* Hand the arrays over in the helper structs' layout (copied into PyMem memory). */
    v->rows = data.n_vertices;
    v->cols = 3;
    sizes->rows = data.n_polygons;
    sizes->cols = 1;
    idx->rows = (Py_ssize_t)data.n_indices;
    idx->cols = 1;
    v->data = PyMem_Malloc(sizeof(double) * 3 * (size_t)(data.n_vertices + 1));
    sizes->data = PyMem_Malloc(sizeof(dk_index) * (size_t)(data.n_polygons + 1));
    idx->data = PyMem_Malloc(sizeof(dk_index) * (size_t)(data.n_indices + 1));
    if (!v->data || !sizes->data || !idx->data) {
        dk_mesh_file_free(&data);
        dk_py_doubles_release(v);
        dk_py_indices_release(sizes);
        dk_py_indices_release(idx);
        PyErr_NoMemory();
        return -1;
    }
    if (data.n_vertices)
        memcpy(v->data, data.positions, sizeof(double) * 3 * (size_t)data.n_vertices);
    if (data.n_polygons)
        memcpy(sizes->data, data.face_sizes, sizeof(dk_index) * (size_t)data.n_polygons);
    if (data.n_indices)
        memcpy(idx->data, data.indices, sizeof(dk_index) * (size_t)data.n_indices);
    dk_mesh_file_free(&data);
    return 0;
}
#else
static int read_file_arrays(PyObject *pathobj, dk_py_doubles *v, dk_py_indices *sizes,
                            dk_py_indices *idx)
{
    (void)pathobj;
    (void)v;
    (void)sizes;
    (void)idx;
    PyErr_SetString(PyExc_NotImplementedError,
                    "deformkit was built without the mesh file reader (dk_io.h)");
    return -1;
}
#endif

PyDoc_STRVAR(load_mesh_file_doc,
             "load_mesh_file(path) -> (vertices, face_sizes, indices)\n\n"
             "Reads an .obj, .off or .ply file: n x 3 float64 positions, one int32 corner\n"
             "count per polygon and the concatenated int32 corner indices, ready for\n"
             "Mesh.from_polygons. OSError-like failures raise ValueError/IndexError with the\n"
             "reader's message (file name and line).");

static PyObject *py_load_mesh_file(PyObject *module, PyObject *args, PyObject *kwargs)
{
    static char *kwlist[] = {"path", NULL};
    PyObject *pathobj, *a = NULL, *b = NULL, *c = NULL, *result = NULL;
    dk_py_doubles v = {0};
    dk_py_indices sizes = {0}, idx = {0};
    double *vd;
    dk_index *sd, *id;

    (void)module;
    if (!PyArg_ParseTupleAndKeywords(args, kwargs, "O:load_mesh_file", kwlist, &pathobj))
        return NULL;
    if (read_file_arrays(pathobj, &v, &sizes, &idx) < 0)
        return NULL;
    a = dk_py_new_doubles(2, v.rows, 3, &vd);
    b = a ? dk_py_new_indices(1, sizes.rows, 0, &sd) : NULL;
    c = b ? dk_py_new_indices(1, idx.rows, 0, &id) : NULL;
    if (c) {
        if (v.rows)
            memcpy(vd, v.data, sizeof(double) * 3 * (size_t)v.rows);
        if (sizes.rows)
            memcpy(sd, sizes.data, sizeof(dk_index) * (size_t)sizes.rows);
        if (idx.rows)
            memcpy(id, idx.data, sizeof(dk_index) * (size_t)idx.rows);
        result = PyTuple_Pack(3, a, b, c);
    }
    Py_XDECREF(a);
    Py_XDECREF(b);
    Py_XDECREF(c);
    dk_py_doubles_release(&v);
    dk_py_indices_release(&sizes);
    dk_py_indices_release(&idx);
    return result;
}

PyDoc_STRVAR(read_mesh_doc, "read_mesh(path) -> Mesh\n\n"
                            "load_mesh_file followed by Mesh.from_polygons.");

static PyObject *py_read_mesh(PyObject *module, PyObject *args, PyObject *kwargs)
{
    static char *kwlist[] = {"path", NULL};
    PyObject *pathobj, *type = dk_py_mesh_type(module);
    dk_py_doubles v = {0};
    dk_py_indices sizes = {0}, idx = {0};
    dk_mesh *mesh;

    if (!PyArg_ParseTupleAndKeywords(args, kwargs, "O:read_mesh", kwlist, &pathobj))
        return NULL;
    if (!type) {
        PyErr_SetString(PyExc_SystemError, "deformkit: Mesh type is not initialised");
        return NULL;
    }
    if (read_file_arrays(pathobj, &v, &sizes, &idx) < 0)
        return NULL;
    mesh = mesh_from_polygon_arrays(&v, &sizes, &idx, "read_mesh");
    dk_py_doubles_release(&v);
    dk_py_indices_release(&sizes);
    dk_py_indices_release(&idx);
    if (!mesh)
        return NULL;
    return wrap_mesh((PyTypeObject *)type, mesh);
}

static PyMethodDef mesh_functions[] = {
    {"load_mesh_file", (PyCFunction)(void (*)(void))py_load_mesh_file,
     METH_VARARGS | METH_KEYWORDS, load_mesh_file_doc},
    {"read_mesh", (PyCFunction)(void (*)(void))py_read_mesh, METH_VARARGS | METH_KEYWORDS,
     read_mesh_doc},
    {NULL, NULL, 0, NULL},
};

int dk_py_init_mesh(PyObject *module)
{
    dk_py_state *st = dk_py_get_state(module);
    PyObject *type = PyType_FromModuleAndSpec(module, &mesh_spec, NULL);
    if (!type)
        return -1;
    Py_XDECREF(st->mesh_type);
    st->mesh_type = type;
    if (PyModule_AddObjectRef(module, "Mesh", type) < 0)
        return -1;
    return PyModule_AddFunctions(module, mesh_functions);
}
