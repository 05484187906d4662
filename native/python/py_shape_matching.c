/* DeformKit CPython module: deformkit.ShapeMatching (native/methods/dk_shape_matching.h), on
 * the generic method type (dk_py_method.h). What is its own: its options (per-vertex maps and
 * given clusters copied until release_options), the keyable dynamics as attributes, and the
 * simulation's velocities, goals, frame count and clusters. */
#include "dk_py_lap.h"
#include "dk_py_method.h"

#include "dk_shape_matching.h"

#include <stdint.h>
#include <stdio.h>
#include <string.h>

static const char *const mode_names[] = {"rigid", "linear", "quadratic", NULL};
static const char *const integrator_names[] = {"semi_implicit_euler", "explicit_euler",
                                               "implicit_euler", "rk4", NULL};
static const char *const cluster_names[] = {"cubes", "parts", NULL};

static void default_options(void *o)
{
    dk_shape_matching_default_options((dk_shape_matching_options *)o);
}

static void release_options(void *o)
{
    dk_shape_matching_options *opt = (dk_shape_matching_options *)o;
    PyMem_Free((void *)opt->masses);
    PyMem_Free((void *)opt->alpha_map);
    PyMem_Free((void *)opt->beta_map);
    PyMem_Free((void *)opt->damping_map);
    PyMem_Free((void *)opt->attach_map);
    PyMem_Free((void *)opt->cluster_sizes);
    PyMem_Free((void *)opt->cluster_vertices);
    opt->masses = opt->alpha_map = opt->beta_map = opt->damping_map = opt->attach_map = NULL;
    opt->cluster_sizes = opt->cluster_vertices = NULL;
    opt->n_masses = opt->n_alpha_map = opt->n_beta_map = opt->n_damping_map = 0;
    opt->n_attach_map = 0;
    opt->n_clusters = 0;
}

/* A per-vertex array keyword (None: absent), owned until release_options. */
static int read_map(PyObject *kw, const char *key, const double **data, dk_index *count)
{
    PyObject *v = dk_py_opt_object(kw, key);
    if (!v)
        return PyErr_Occurred() ? -1 : 0;
    int rc = 0;
    if (v != Py_None) {
        dk_py_doubles in = {0};
        rc = dk_py_read_doubles(v, -1, 0, key, &in);
        if (rc == 0) {
            *data = in.data;
            *count = (dk_index)in.rows;
        }
    }
    Py_DECREF(v);
    return rc;
}

/* gravity: three numbers. */
static int read_gravity(PyObject *v, double g[3], const char *context)
{
    PyObject *seq = PySequence_Tuple(v);
    if (!seq || PyTuple_Size(seq) != 3) {
        Py_XDECREF(seq);
        PyErr_Clear();
        PyErr_Format(PyExc_TypeError, "%s: gravity must be three numbers (x, y, z)", context);
        return -1;
    }
    for (int c = 0; c < 3; c++) {
        g[c] = PyFloat_AsDouble(PyTuple_GetItem(seq, c));
        if (g[c] == -1.0 && PyErr_Occurred()) {
            Py_DECREF(seq);
            PyErr_Clear();
            PyErr_Format(PyExc_TypeError, "%s: gravity must be three numbers (x, y, z)",
                         context);
            return -1;
        }
    }
    Py_DECREF(seq);
    return 0;
}

/* clusters: 'cubes', 'parts', or a list of index arrays (regions). */
static int read_clusters(PyObject *v, dk_shape_matching_options *opt, const char *context)
{
    if (PyUnicode_Check(v)) {
        const int k = dk_py_lap_choice(v, "clusters", cluster_names, context);
        if (k < 0)
            return -1;
        opt->clusters = (dk_shape_matching_cluster_kind)k;
        return 0;
    }
    PyObject *seq = PySequence_Tuple(v);
    if (!seq) {
        PyErr_Clear();
        PyErr_Format(PyExc_TypeError,
                     "%s: clusters must be 'cubes', 'parts' or a list of index arrays", context);
        return -1;
    }
    const Py_ssize_t nc = PyTuple_Size(seq);
    if (nc == 0 || nc > INT32_MAX) {
        Py_DECREF(seq);
        PyErr_Format(PyExc_ValueError, "%s: clusters is an empty list", context);
        return -1;
    }
    dk_py_indices *read = PyMem_Calloc((size_t)nc, sizeof *read);
    dk_index *sizes = PyMem_Malloc(sizeof(dk_index) * (size_t)nc);
    int rc = read && sizes ? 0 : -1;
    if (rc < 0)
        PyErr_NoMemory();
    Py_ssize_t total = 0;
    char name[48];
    for (Py_ssize_t c = 0; c < nc && rc == 0; c++) {
        snprintf(name, sizeof name, "cluster %zd", c);
        rc = dk_py_read_indices(PyTuple_GetItem(seq, c), -1, 0, name, &read[c]);
        if (rc == 0) {
            sizes[c] = (dk_index)read[c].rows;
            total += read[c].rows;
            if (total > INT32_MAX) {
                PyErr_Format(PyExc_ValueError, "%s: too many cluster vertices", context);
                rc = -1;
            }
        }
    }
    dk_index *verts = rc == 0 ? PyMem_Malloc(sizeof(dk_index) * (size_t)(total + 1)) : NULL;
    if (rc == 0 && !verts) {
        PyErr_NoMemory();
        rc = -1;
    }
    for (Py_ssize_t c = 0, at = 0; c < nc && read; c++) {
        if (rc == 0 && read[c].rows > 0)
            memcpy(verts + at, read[c].data, sizeof(dk_index) * (size_t)read[c].rows);
        at += read[c].rows;
        dk_py_indices_release(&read[c]);
    }
    PyMem_Free(read);
    Py_DECREF(seq);
    if (rc < 0) {
        PyMem_Free(sizes);
        PyMem_Free(verts);
        return -1;
    }
    opt->n_clusters = (dk_index)nc;
    opt->cluster_sizes = sizes;
    opt->cluster_vertices = verts;
    return 0;
}

static int parse_options(PyObject *kw, void *o, const char *context)
{
    dk_shape_matching_options *opt = (dk_shape_matching_options *)o;
    int mode = (int)opt->mode, integ = (int)opt->integrator;
    if (dk_py_opt_choice(kw, "mode", mode_names, &mode, context) < 0 ||
        dk_py_opt_double(kw, "alpha", &opt->alpha) < 0 ||
        dk_py_opt_double(kw, "beta", &opt->beta) < 0 ||
        dk_py_opt_double(kw, "damping", &opt->damping) < 0 ||
        dk_py_opt_double(kw, "time_step", &opt->time_step) < 0 ||
        dk_py_opt_int(kw, "substeps", &opt->substeps) < 0 ||
        dk_py_opt_choice(kw, "integrator", integrator_names, &integ, context) < 0 ||
        dk_py_opt_double(kw, "cluster_size", &opt->cluster_size) < 0 ||
        dk_py_opt_double(kw, "falloff", &opt->falloff) < 0 ||
        dk_py_opt_double(kw, "plastic_yield", &opt->plastic_yield) < 0 ||
        dk_py_opt_double(kw, "plastic_creep", &opt->plastic_creep) < 0 ||
        dk_py_opt_double(kw, "plastic_max", &opt->plastic_max) < 0 ||
        read_map(kw, "masses", &opt->masses, &opt->n_masses) < 0 ||
        read_map(kw, "alpha_map", &opt->alpha_map, &opt->n_alpha_map) < 0 ||
        read_map(kw, "beta_map", &opt->beta_map, &opt->n_beta_map) < 0 ||
        read_map(kw, "damping_map", &opt->damping_map, &opt->n_damping_map) < 0 ||
        read_map(kw, "attach_map", &opt->attach_map, &opt->n_attach_map) < 0)
        return -1;
    opt->mode = (dk_shape_matching_mode)mode;
    opt->integrator = (dk_shape_matching_integrator)integ;
    PyObject *g = dk_py_opt_object(kw, "gravity");
    if (!g && PyErr_Occurred())
        return -1;
    if (g) {
        double v[3];
        const int rc = read_gravity(g, v, context);
        Py_DECREF(g);
        if (rc < 0)
            return -1;
        opt->gravity_x = v[0], opt->gravity_y = v[1], opt->gravity_z = v[2];
    }
    PyObject *cl = dk_py_opt_object(kw, "clusters");
    if (!cl && PyErr_Occurred())
        return -1;
    if (cl) {
        const int rc = read_clusters(cl, opt, context);
        Py_DECREF(cl);
        if (rc < 0)
            return -1;
    }
    return 0;
}

/* ------------------------------------------------------------- the dynamics -------- */

/* Which field of dk_shape_matching_dynamics a getset entry reads (closure). */
enum { DYN_ALPHA, DYN_BETA, DYN_DAMPING, DYN_GRAVITY, DYN_YIELD, DYN_CREEP, DYN_MAX,
       DYN_TIME_STEP };

static double *dyn_field(dk_shape_matching_dynamics *d, int which)
{
    switch (which) {
    case DYN_ALPHA: return &d->alpha;
    case DYN_BETA: return &d->beta;
    case DYN_DAMPING: return &d->damping;
    case DYN_YIELD: return &d->plastic_yield;
    case DYN_CREEP: return &d->plastic_creep;
    case DYN_MAX: return &d->plastic_max;
    case DYN_TIME_STEP: return &d->time_step;
    default: return d->gravity;
    }
}

static PyObject *get_dyn(PyObject *obj, void *closure)
{
    dk_py_method *self = (dk_py_method *)obj;
    if (!dk_py_method_readable(self))
        return NULL;
    dk_shape_matching_dynamics d;
    dk_shape_matching_get_dynamics(self->native, &d);
    const int which = (int)(intptr_t)closure;
    if (which == DYN_GRAVITY)
        return Py_BuildValue("(ddd)", d.gravity[0], d.gravity[1], d.gravity[2]);
    return PyFloat_FromDouble(*dyn_field(&d, which));
}

static int set_dyn(PyObject *obj, PyObject *value, void *closure)
{
    dk_py_method *self = (dk_py_method *)obj;
    const int which = (int)(intptr_t)closure;
    if (!value) {
        PyErr_SetString(PyExc_AttributeError, "ShapeMatching: the dynamics cannot be deleted");
        return -1;
    }
    dk_shape_matching_dynamics d;
    double g[3];
    if (which == DYN_GRAVITY) {
        if (read_gravity(value, g, "ShapeMatching") < 0)
            return -1;
    } else {
        g[0] = PyFloat_AsDouble(value);
        if (g[0] == -1.0 && PyErr_Occurred())
            return -1;
    }
    if (dk_py_method_enter(self) < 0)
        return -1;
    dk_shape_matching_get_dynamics(self->native, &d);
    if (which == DYN_GRAVITY)
        memcpy(d.gravity, g, sizeof g);
    else
        *dyn_field(&d, which) = g[0];
    dk_error err = {0};
    const dk_status st = dk_shape_matching_set_dynamics(self->native, &d, &err);
    self->busy = 0;
    if (st != DK_OK) {
        dk_py_raise(&err, "ShapeMatching");
        return -1;
    }
    return 0;
}

/* solve(alpha=, beta=, damping=, gravity=, time_step=, plastic_yield=, plastic_creep=,
 * plastic_max=): this frame's keyed dynamics, kept
 * for the later frames (as the attributes); read and checked first, set only when the whole
 * call has been validated (apply_extra), put back if the solve fails. */
typedef struct sm_extra {
    int given;
    dk_shape_matching_dynamics dyn;
} sm_extra;

static int solve_extra(dk_py_method *self, PyObject *kw, void *pending, const char *context)
{
    static const char *const keys[] = {"alpha",         "beta",          "damping",
                                       "time_step",     "plastic_yield", "plastic_creep",
                                       "plastic_max"};
    static const int which[] = {DYN_ALPHA, DYN_BETA,  DYN_DAMPING, DYN_TIME_STEP,
                                DYN_YIELD, DYN_CREEP, DYN_MAX};
    sm_extra *x = (sm_extra *)pending;
    dk_shape_matching_get_dynamics(self->native, &x->dyn);
    for (int k = 0; k < 7; k++) {
        PyObject *v = kw ? PyDict_GetItemString(kw, keys[k]) : NULL;
        if (!v)
            continue;
        if (v == Py_None) {
            if (PyDict_DelItemString(kw, keys[k]) < 0)
                return -1;
            continue;
        }
        if (dk_py_opt_double(kw, keys[k], dyn_field(&x->dyn, which[k])) < 0)
            return -1;
        x->given = 1;
    }
    PyObject *g = kw ? PyDict_GetItemString(kw, "gravity") : NULL;
    if (g) {
        Py_INCREF(g);
        const int rc = PyDict_DelItemString(kw, "gravity");
        if (rc == 0 && g != Py_None) {
            if (read_gravity(g, x->dyn.gravity, context) < 0) {
                Py_DECREF(g);
                return -1;
            }
            x->given = 1;
        }
        Py_DECREF(g);
        if (rc < 0)
            return -1;
    }
    dk_error err = {0};
    if (x->given && dk_shape_matching_check_dynamics(&x->dyn, &err) != DK_OK) {
        dk_py_raise(&err, context);
        return -1;
    }
    return 0;
}

static void apply_extra(dk_py_method *self, const void *pending, void *saved)
{
    const sm_extra *x = (const sm_extra *)pending;
    dk_error err = {0};
    if (saved) {
        ((sm_extra *)saved)->given = x->given;
        dk_shape_matching_get_dynamics(self->native, &((sm_extra *)saved)->dyn);
    }
    if (x->given)
        (void)dk_shape_matching_set_dynamics(self->native, &x->dyn, &err); /* checked above */
}

/* ------------------------------------------------------------- the simulation ------ */

static PyObject *get_velocities(PyObject *obj, void *c)
{
    dk_py_method *self = (dk_py_method *)obj;
    (void)c;
    if (!dk_py_method_readable(self))
        return NULL;
    double *out;
    PyObject *a = dk_py_new_doubles(2, self->mesh->n_vertices, 3, &out);
    if (a)
        dk_shape_matching_velocities(self->native, out);
    return a;
}

static int set_velocities(PyObject *obj, PyObject *value, void *c)
{
    dk_py_method *self = (dk_py_method *)obj;
    (void)c;
    if (!value) {
        PyErr_SetString(PyExc_AttributeError, "ShapeMatching: velocities cannot be deleted");
        return -1;
    }
    if (dk_py_method_enter(self) < 0)
        return -1;
    dk_py_doubles in = {0};
    if (dk_py_read_doubles(value, self->mesh->n_vertices, 3, "velocities", &in) < 0) {
        self->busy = 0;
        return -1;
    }
    dk_error err = {0};
    const dk_status st = dk_shape_matching_set_velocities(self->native, in.data, &err);
    dk_py_doubles_release(&in);
    self->busy = 0;
    if (st != DK_OK) {
        dk_py_raise(&err, "ShapeMatching");
        return -1;
    }
    return 0;
}

static PyObject *get_frame(PyObject *obj, void *c)
{
    dk_py_method *self = (dk_py_method *)obj;
    (void)c;
    if (!dk_py_method_readable(self))
        return NULL;
    return PyLong_FromLongLong((long long)dk_shape_matching_frame(self->native));
}

/* One array per cluster: its vertices (shares 0) or their shares (shares 1). */
static PyObject *cluster_lists(PyObject *obj, int shares)
{
    dk_py_method *self = (dk_py_method *)obj;
    if (!dk_py_method_readable(self))
        return NULL;
    const dk_index *start, *verts;
    const double *share;
    const dk_index nc = dk_shape_matching_clusters(self->native, &start, &verts, &share);
    PyObject *list = PyList_New(nc);
    for (dk_index k = 0; list && k < nc; k++) {
        const dk_index n = start[k + 1] - start[k];
        dk_index *di = NULL;
        double *dd = NULL;
        PyObject *a = shares ? dk_py_new_doubles(1, n, 0, &dd) : dk_py_new_indices(1, n, 0, &di);
        if (!a) {
            Py_CLEAR(list);
            break;
        }
        if (shares)
            memcpy(dd, share + start[k], sizeof(double) * (size_t)n);
        else
            memcpy(di, verts + start[k], sizeof(dk_index) * (size_t)n);
        PyList_SetItem(list, k, a); /* steals */
    }
    return list;
}

PyDoc_STRVAR(clusters_doc, "clusters() -> list of vertex index arrays: the clusters, as bound");

static PyObject *sm_clusters(PyObject *obj, PyObject *unused)
{
    (void)unused;
    return cluster_lists(obj, 0);
}

PyDoc_STRVAR(cluster_shares_doc,
             "cluster_shares() -> list of float arrays, one per cluster of clusters(): each\n"
             "member's share phi of the cluster (its mass there is m phi, and its goal blends\n"
             "its clusters' goals by phi; a vertex's shares sum to 1). The automatic cubes\n"
             "give each member the cube's trilinear hat (1 at the centre, 0 on the faces),\n"
             "normalised; whole parts and given clusters 1 / (the vertex's clusters).");

static PyObject *sm_cluster_shares(PyObject *obj, PyObject *unused)
{
    (void)unused;
    return cluster_lists(obj, 1);
}

PyDoc_STRVAR(goals_doc,
             "goals(positions) -> n x 3 array\n\n"
             "Each vertex's goal g_i (its clusters' R q_i + x_cm blended by its shares, or the\n"
             "linear / quadratic blend with beta) for the configuration `positions`\n"
             "(n x 3), against the last solve's goal shape and the current plastic states:\n"
             "what the clusters pull each vertex towards (the attachment's blend with the\n"
             "input, which the integrators add, left out).");

static dk_status goals_of(void *native, const double *in, double *out, dk_error *err)
{
    return dk_shape_matching_goals(native, in, out, err);
}

static PyObject *sm_goals(PyObject *obj, PyObject *arg)
{
    if (arg == Py_None) {
        PyErr_SetString(PyExc_TypeError, "ShapeMatching.goals: positions are required");
        return NULL;
    }
    return dk_py_method_map_n3(obj, arg, "positions", "ShapeMatching.goals", goals_of);
}

PyDoc_STRVAR(solve_doc,
             "solve(targets=None, transforms=None, warm_start=True, max_iterations=None,\n"
             "      resume=False, energy=True, preview=False, start_positions=None,\n"
             "      input_positions=None, alpha=None, beta=None, damping=None, gravity=None,\n"
             "      time_step=None, plastic_yield=None, plastic_creep=None,\n"
             "      plastic_max=None) -> SolveResult\n\n"
             "One frame of the simulation (alpha ... time_step: this frame's keyed values,\n"
             "kept for the next frames as the attributes are). warm_start=True (the default) or resume=True:\n"
             "advance one frame (time_step seconds in `substeps` steps) from the current\n"
             "state, the kinematic vertices moving linearly to where this call puts them\n"
             "(handles: targets, positions of the handle vertices, or transforms of their\n"
             "input; fixed vertices and those outside roi: the input), the rest by the\n"
             "dynamics towards this frame's goal shape (input_positions, e.g. an animation's\n"
             "pose, or the rest). warm_start=False: reset the simulation to this call, at\n"
             "rest (velocities 0), and return it; start_positions: the same from these\n"
             "positions (a shape released at rest). A bind without handles needs no\n"
             "targets. Returns the\n"
             "positions, the shape-matching residual as energy, iterations = the substeps\n"
             "taken and converged = True.");

PyDoc_STRVAR(
    shape_matching_doc,
    "ShapeMatching(mesh, handles=None, fixed=None, roi=None, handle_weights=None,\n"
    "              mode='linear', alpha=0.3, beta=0.3, damping=4.0, gravity=(0, 0, 0),\n"
    "              time_step=1/24, substeps=2, integrator='semi_implicit_euler',\n"
    "              clusters='cubes', cluster_size=0.0, falloff=0.0, plastic_yield=0.1,\n"
    "              plastic_creep=0.0, plastic_max=1.0, masses=None, alpha_map=None,\n"
    "              beta_map=None, damping_map=None, attach_map=None, progress=None)\n\n"
    "Meshless deformation based on shape matching (Mueller et al. 2005), simulated in\n"
    "time: the vertices are particles (mass 1, or masses), grouped into overlapping\n"
    "clusters; each cluster finds the rotation R (mode='rigid'), or blends it by beta with\n"
    "the best linear ('linear', volume kept) or quadratic ('quadratic') map, that takes its\n"
    "rest shape onto the particles, and pulls them towards the goals g with stiffness alpha\n"
    "(in [0, 1] per integration step h = time_step / substeps; 1 reaches the goals in one\n"
    "step): v += alpha (g - x) / h + h gravity, damped at `damping` per second (against\n"
    "the input's own motion), then x += h v (integrator 'semi_implicit_euler', the\n"
    "paper's scheme; 'explicit_euler' as the slides' code, 'implicit_euler', 'rk4').\n"
    "Handles follow their targets, fixed vertices and those outside roi the input; they\n"
    "drive the rest, and the free vertices within falloff of them (0: half the depth of\n"
    "what is simulated, at most half a cube) are also pulled to where the input puts\n"
    "them, moved with the handles near them, fading with the distance (attach_map adds a\n"
    "painted attachment in [0, 1]). Clusters: 'cubes' (overlapping cubes of edge\n"
    "cluster_size, 0 = a quarter of the bounding box's diagonal, split where the mesh is\n"
    "not connected; each vertex's share of a cube its trilinear hat, so that its goal\n"
    "blends the cubes' continuously), 'parts' (one per connected part), or a list of\n"
    "index arrays.\n"
    "Plasticity (plastic_creep > 0): a cluster deformed beyond plastic_yield creeps into\n"
    "its new rest shape, at most plastic_max from the original. alpha_map, beta_map,\n"
    "damping_map: per-vertex factors (painted). alpha, beta, damping, gravity and the\n"
    "plastic settings are attributes, changeable between frames (keyed). A warm solve\n"
    "advances a frame; save_state() / restore_state() checkpoint the simulation.\n"
    "See docs/methods/shape_matching.md.");

static PyMethodDef shape_matching_methods[] = {
    DK_PY_METHOD_METHODS(solve_doc),
    {"goals", sm_goals, METH_O, goals_doc},
    {"clusters", sm_clusters, METH_NOARGS, clusters_doc},
    {"cluster_shares", sm_cluster_shares, METH_NOARGS, cluster_shares_doc},
    {NULL, NULL, 0, NULL},
};

#define DYN(name, which, doc)                                                                \
    {name, get_dyn, set_dyn, doc, (void *)(intptr_t)(which)}

static PyGetSetDef shape_matching_getset[] = {
    DK_PY_METHOD_GETSET,
    DYN("alpha", DYN_ALPHA, "stiffness in [0, 1] per integration step (settable)"),
    DYN("beta", DYN_BETA, "blend of the rotation with the linear / quadratic fit (settable)"),
    DYN("damping", DYN_DAMPING, "velocity damping rate per second (settable)"),
    DYN("gravity", DYN_GRAVITY, "acceleration (x, y, z), mesh units per s^2 (settable)"),
    DYN("plastic_yield", DYN_YIELD, "deformation |S - I|_F above which clusters creep"),
    DYN("plastic_creep", DYN_CREEP, "creep rate per second, 0: elastic (settable)"),
    DYN("plastic_max", DYN_MAX, "the largest plastic deformation |S_p - I|_F (settable)"),
    DYN("time_step", DYN_TIME_STEP, "seconds a warm solve advances: a frame (settable)"),
    {"velocities", get_velocities, set_velocities,
     "the particles' velocities (n x 3, a copy; settable: a throw, a spin)", NULL},
    {"frame", get_frame, NULL, "frames advanced since the last reset (cold solve)", NULL},
    {NULL, NULL, NULL, NULL, NULL},
};

static void bind_progress(void *options, dk_py_progress *p)
{
    ((dk_shape_matching_options *)options)->progress = dk_py_progress_phase;
    ((dk_shape_matching_options *)options)->progress_user = p;
}

static void rebind_progress(void *native, dk_py_progress *p)
{
    dk_shape_matching_set_progress((dk_shape_matching *)native, p ? dk_py_progress_phase : NULL,
                                   p);
}

static const dk_py_method_spec shape_matching_spec = {
    .name = "ShapeMatching",
    .type_name = "deformkit.ShapeMatching",
    .ops = &dk_shape_matching_ops,
    .doc = shape_matching_doc,
    .handles_optional = 1,
    .options_size = sizeof(dk_shape_matching_options),
    .default_options = default_options,
    .parse_options = parse_options,
    .release_options = release_options,
    .bind_progress = bind_progress,
    .rebind_progress = rebind_progress,
    .solve_extra = solve_extra,
    .apply_extra = apply_extra,
    .getset = shape_matching_getset,
    .methods = shape_matching_methods,
};

static PyObject *shape_matching_new(PyTypeObject *type, PyObject *args, PyObject *kwargs)
{
    return dk_py_method_new(type, args, kwargs, &shape_matching_spec);
}

int dk_py_init_shape_matching(PyObject *module)
{
    return dk_py_method_register(module, &shape_matching_spec, shape_matching_new);
}
