/* DeformKit CPython module: deformkit.ARAP (native/methods/dk_arap.h), on the generic method
 * type (dk_py_method.h). What is ARAP's own: its options, solve(tolerance=...), its counters
 * and handle_sizes. */
#include "dk_py_arap.h"

#include "dk_arap.h"

#include <math.h>

static const char *const energy_names[] = {"spokes", "spokes_and_rims", NULL};
static const char *const weights_names[] = {"cotangent", "clamped_cotangent", "uniform", NULL};
static const char *const accel_names[] = {"none", "anderson", "newton", NULL};
static const char *const basis_names[] = {"auto", "off", NULL};
static const char *const cg_schedule_names[] = {"fixed", "growing", NULL};

static void default_options(void *o)
{
    dk_arap_default_options((dk_arap_options *)o);
}

static int parse_options(PyObject *kw, void *o, const char *context)
{
    dk_arap_options *opt = (dk_arap_options *)o;
    int energy = (int)opt->energy, weights = (int)opt->weights;
    int accel = (int)opt->acceleration, basis = (int)opt->basis;
    int cg_schedule = (int)opt->cg_schedule;
    if (dk_py_opt_choice(kw, "energy", energy_names, &energy, context) < 0 ||
        dk_py_opt_choice(kw, "weights", weights_names, &weights, context) < 0 ||
        dk_py_opt_int(kw, "max_iterations", &opt->max_iterations) < 0 ||
        dk_py_opt_double(kw, "tolerance", &opt->tolerance) < 0 ||
        dk_py_opt_choice(kw, "acceleration", accel_names, &accel, context) < 0 ||
        dk_py_opt_int(kw, "anderson_depth", &opt->anderson_depth) < 0 ||
        dk_py_opt_bool(kw, "predict", &opt->predict) < 0 ||
        dk_py_opt_int(kw, "cg_iterations", &opt->cg_iterations) < 0 ||
        dk_py_opt_choice(kw, "cg_schedule", cg_schedule_names, &cg_schedule, context) < 0 ||
        dk_py_opt_choice(kw, "basis", basis_names, &basis, context) < 0 ||
        dk_py_opt_int(kw, "levels", &opt->levels) < 0)
        return -1;
    opt->basis = (dk_arap_basis)basis;
    opt->cg_schedule = (dk_arap_cg_schedule)cg_schedule;
    opt->energy = (dk_arap_energy_kind)energy;
    opt->weights = (dk_arap_weight_kind)weights;
    opt->acceleration = (dk_arap_acceleration)accel;
    return 0;
}

/* solve(tolerance=..., cg_iterations=...): the tolerance replaces the bound one for this and
 * later solves; cg_iterations (Newton's CG iterations per step) holds for this call only
 * (None: as bound), so every call sets it. Read and checked first, set only when the whole
 * call has been validated (apply_extra). */
typedef struct arap_extra {
    int given;
    double tolerance;
    int cg; /* 0: as bound */
} arap_extra;

int dk_py_arap_solve_extra(dk_py_method *self, PyObject *kw, void *pending, const char *context)
{
    arap_extra *x = (arap_extra *)pending;
    PyObject *cg_obj = kw ? PyDict_GetItemString(kw, "cg_iterations") : NULL;
    if (cg_obj == Py_None) {
        if (PyDict_DelItemString(kw, "cg_iterations") < 0)
            return -1;
    } else if (cg_obj) {
        int cg = 0;
        if (dk_py_opt_int(kw, "cg_iterations", &cg) < 0)
            return -1;
        if (cg < 1 || cg > 100) {
            PyErr_Format(PyExc_ValueError, "%s: cg_iterations is %d, must be in [1, 100]",
                         context, cg);
            return -1;
        }
        x->cg = cg;
    }
    PyObject *tol_obj = kw ? PyDict_GetItemString(kw, "tolerance") : NULL;
    (void)self;
    if (!tol_obj || tol_obj == Py_None) {
        if (tol_obj && PyDict_DelItemString(kw, "tolerance") < 0)
            return -1;
        return 0;
    }
    double tol = -1.0;
    if (dk_py_opt_double(kw, "tolerance", &tol) < 0)
        return -1;
    if (!(isfinite(tol) && tol >= 0.0)) {
        PyErr_Format(PyExc_ValueError, "%s: tolerance is %R, must be finite and >= 0", context,
                     tol_obj);
        return -1;
    }
    x->given = 1;
    x->tolerance = tol;
    return 0;
}

void dk_py_arap_apply_extra_to(dk_arap *ar, const void *pending, void *saved)
{
    const arap_extra *x = (const arap_extra *)pending;
    dk_error err = {0};
    if (saved) {
        ((arap_extra *)saved)->given = x->given;
        ((arap_extra *)saved)->tolerance = dk_arap_tolerance(ar);
    }
    if (x->given)
        (void)dk_arap_set_tolerance(ar, x->tolerance, &err); /* checked above */
    /* every call sets the CG count (its own, or the bound one): nothing to save */
    (void)dk_arap_set_cg_iterations(ar, x->cg, &err);      /* checked above */
}

static void apply_extra(dk_py_method *self, const void *pending, void *saved)
{
    dk_py_arap_apply_extra_to(self->native, pending, saved);
}

static PyObject *stats(dk_py_method *self)
{
    const dk_constraints *k = dk_arap_constraints(self->native);
    dk_method_stats ms;
    dk_arap_counters ac;
    dk_arap_stats(self->native, &ms);
    dk_arap_get_counters(self->native, &ac);
    PyObject *coarse = PyTuple_New(ac.levels - 1);
    if (!coarse)
        return NULL;
    for (int k = 0; k < ac.levels - 1; k++) {
        PyObject *v = PyLong_FromLong((long)ac.coarse_vertices[k]);
        if (!v || PyTuple_SetItem(coarse, k, v) < 0) { /* SetItem steals v, even failing */
            Py_DECREF(coarse);
            return NULL;
        }
    }
    return Py_BuildValue("{s:i,s:i,s:i,s:i,s:i,s:i,s:i,s:N,s:i}", "n_unknowns",
                         (int)ms.n_unknowns, "n_free", (int)k->n_free, "analysis_count",
                         ms.analysis_count, "factorization_count", ms.factorization_count,
                         "basis_columns", ac.basis_columns, "basis_starts", ac.basis_starts,
                         "levels", ac.levels, "coarse_vertices", coarse, "coarse_starts",
                         ac.coarse_starts);
}

static PyObject *get_handle_sizes(PyObject *obj, void *c)
{
    if (!dk_py_method_readable((dk_py_method *)obj))
        return NULL;
    const dk_constraints *k = dk_arap_constraints(((dk_py_method *)obj)->native);
    PyObject *t = PyTuple_New(k->n_handles);
    (void)c;
    if (!t)
        return NULL;
    for (dk_index h = 0; h < k->n_handles; h++) {
        PyObject *v = PyLong_FromLong(k->handle_start[h + 1] - k->handle_start[h]);
        if (!v || PyTuple_SetItem(t, h, v) < 0) {
            Py_DECREF(t);
            return NULL;
        }
    }
    return t;
}

PyDoc_STRVAR(solve_doc,
             "solve(targets=None, transforms=None, warm_start=True, max_iterations=None,\n"
             "      resume=False, energy=True, preview=False, start_positions=None,\n"
             "      tolerance=None, cg_iterations=None) -> SolveResult\n\n"
             "targets: (sum of handle sizes) x 3 positions, concatenated in handle order;\n"
             "transforms: n_handles x 4 x 4 affine transforms of the rest pose. warm_start\n"
             "starts from the previous solution (else from the naive Laplacian-editing guess).\n"
             "max_iterations overrides the bound value for this call; tolerance replaces the\n"
             "bound value for this and later calls. resume=True with the previous call's\n"
             "targets continues that solve where it stopped (acceleration history kept), so\n"
             "solves sliced by max_iterations equal one longer solve; with other targets it\n"
             "is a warm start. cg_iterations: Newton's CG iterations per step for this\n"
             "call only (None: as bound); fewer make cheaper, less complete steps with the\n"
             "same stopping test (the add-on's time-budgeted slices); a resume with another\n"
             "count ends at a point that test accepts, not bit for bit one long solve.\n"
             "preview=True returns the start alone (iterations 0): the previous solution\n"
             "plus the global step's response to the handles' move, combined from the bind's\n"
             "response basis when each handle moved by an affine map (O(n), no\n"
             "back-substitution); a later resume=True with the same targets refines it.\n"
             "start_positions (n x 3, any buffer; not with resume) starts from those\n"
             "positions instead, constrained vertices put in place and their optimal\n"
             "rotations taken: a coarse level's result prolonged to this mesh, or a cached\n"
             "frame; the result then depends on this call alone, as for warm_start=False.\n"
             "Returns the positions, the ARAP energy of those positions, the iterations used\n"
             "and whether the relative energy change fell below the tolerance.");

PyDoc_STRVAR(arap_doc,
             "ARAP(mesh, handles, fixed=None, roi=None, handle_weights=None, stiffness=None,\n"
             "     energy='spokes', weights='clamped_cotangent', max_iterations=1000,\n"
             "     tolerance=1e-6, acceleration='newton', anderson_depth=5, predict=True,\n"
             "     cg_iterations=12, cg_schedule='fixed', basis='auto', levels=0)\n\n"
             "As-rigid-as-possible deformation (Sorkine & Alexa 2007; 'spokes_and_rims' after\n"
             "Chao et al. 2010). Fixed vertices, vertices outside roi and handle vertices of\n"
             "weight 1 are eliminated exactly; handle weights w < 1 become soft penalties\n"
             "lambda w/(1-w) |p - t|^2. stiffness (n values > 0) scales each vertex's cell\n"
             "energy. acceleration: 'none' (the paper's local/global iteration), 'anderson'\n"
             "(Anderson-accelerated, with an energy safeguard) or 'newton' (default; inexact Newton\n"
             "steps, cg_iterations conjugate-gradient iterations each, preconditioned by the\n"
             "local/global step; an energy line search). cg_schedule='growing' doubles a\n"
             "step's count while the last step gained at most 1e-3 of E and quadruples it\n"
             "below 1e-5 (default 'fixed': cg_iterations always). Stops when a local/global step\n"
             "changes the energy by at most tolerance (relative; Newton: predicted before the\n"
             "step). predict: warm starts may extrapolate along the drag (secant of the last\n"
             "two solutions). basis='auto' precomputes, 4 columns per handle (up to 16\n"
             "handles, 128 MB), the global step's response to each handle's affine motion, so\n"
             "warm starts after such a move need no back-substitution ('off': never).\n"
             "levels: the multi-scale solve: 1 the mesh alone, L > 1 adds L - 1 coarse levels\n"
             "(each 1/16 of the vertices, by quadric-error simplification); 0 (default)\n"
             "automatic: one from 100,000 unknowns on. A cold start solves the coarsest level\n"
             "first and starts the finer ones from its prolonged result; the answer is still\n"
             "the mesh's minimum. stats()['coarse_vertices'] lists the levels built.\n"
             "See docs/methods/arap.md.");

static PyGetSetDef arap_getset[] = {
    DK_PY_METHOD_GETSET,
    {"handle_sizes", get_handle_sizes, NULL, "tuple: vertices per handle group", NULL},
    {NULL, NULL, NULL, NULL, NULL},
};

/* response_basis() -> (n_vertices, 4 n_handles) array, or None when not built */
PyObject *dk_py_arap_response_basis(dk_py_method *self, const char *who,
                                    dk_status (*fill)(void *native, double *out,
                                                      dk_error *err),
                                    dk_arap *(*solver)(void *native))
{
    dk_arap_counters ac;
    dk_error err = {0};
    double *out;
    if (dk_py_method_enter(self) < 0)
        return NULL;
    dk_arap_get_counters(solver(self->native), &ac);
    if (ac.basis_columns == 0) {
        self->busy = 0;
        Py_RETURN_NONE;
    }
    PyObject *res = dk_py_new_doubles(2, self->mesh->n_vertices, ac.basis_columns, &out);
    dk_status st = res ? fill(self->native, out, &err) : DK_OK;
    self->busy = 0;
    if (res && st != DK_OK) {
        Py_DECREF(res);
        return dk_py_raise(&err, who);
    }
    return res;
}

static dk_status fill_basis(void *native, double *out, dk_error *err)
{
    return dk_arap_response_basis(native, out, err);
}

static dk_arap *itself(void *native)
{
    return native;
}

static PyObject *arap_response_basis(PyObject *obj, PyObject *unused)
{
    (void)unused;
    return dk_py_arap_response_basis((dk_py_method *)obj, "ARAP.response_basis", fill_basis,
                                     itself);
}

PyDoc_STRVAR(response_basis_doc,
             "response_basis() -> ndarray (n_vertices, 4 * n_handles), or None\n\n"
             "The warm start's response basis as a linear map: for handles moved from\n"
             "transforms T0 to T (n_handles x 4 x 4), positions x0 + B @ C with\n"
             "C[4h + j, d] = (T - T0)[h, d, j] are the global step's response with the\n"
             "rotations held (the plain warm start from x0, no solve). Hard handle vertices\n"
             "land on their targets, fixed ones stay. None when basis='off' or over the\n"
             "limits. Cheap to apply while another thread solves.");

static PyMethodDef arap_methods[] = {
    DK_PY_METHOD_METHODS(solve_doc),
    {"response_basis", arap_response_basis, METH_NOARGS, response_basis_doc},
    {NULL, NULL, 0, NULL}};

/* progress=: the shared callback (dk_py.h), phases named by the native bind / rebind */
static void bind_progress(void *options, dk_py_progress *p)
{
    ((dk_arap_options *)options)->progress = dk_py_progress_phase;
    ((dk_arap_options *)options)->progress_user = p;
}

static void rebind_progress(void *native, dk_py_progress *p)
{
    dk_arap_set_progress((dk_arap *)native, p ? dk_py_progress_phase : NULL, p);
}

static const dk_py_method_spec arap_spec = {
    .name = "ARAP",
    .type_name = "deformkit.ARAP",
    .ops = &dk_arap_ops,
    .doc = arap_doc,
    .takes_stiffness = 1,
    .options_size = sizeof(dk_arap_options),
    .default_options = default_options,
    .parse_options = parse_options,
    .solve_extra = dk_py_arap_solve_extra,
    .apply_extra = apply_extra,
    .stats = stats,
    .bind_progress = bind_progress,
    .rebind_progress = rebind_progress,
    .getset = arap_getset,
    .methods = arap_methods,
};

static PyObject *arap_new(PyTypeObject *type, PyObject *args, PyObject *kwargs)
{
    return dk_py_method_new(type, args, kwargs, &arap_spec);
}

int dk_py_init_arap(PyObject *module)
{
    return dk_py_method_register(module, &arap_spec, arap_new);
}
