/* DeformKit CPython module: deformkit.LaplacianEdit (native/methods/dk_laplacian_edit.h), on
 * the generic method type (dk_py_method.h). What is its own: its options and its counters. */
#include "dk_py_method.h"

#include "dk_laplacian_edit.h"

static const char *const weights_names[] = {"uniform", "cotangent", NULL};
static const char *const detail_names[] = {"fixed", "membrane", "local_frame", NULL};
static const char *const constraint_names[] = {"hard", "soft", NULL};
static const char *const basis_names[] = {"auto", "off", NULL};

static void default_options(void *o)
{
    dk_laplacian_edit_default_options((dk_laplacian_edit_options *)o);
}

static int parse_options(PyObject *kw, void *o, const char *context)
{
    dk_laplacian_edit_options *opt = (dk_laplacian_edit_options *)o;
    int weights = (int)opt->weights, detail = (int)opt->detail;
    int constraints = (int)opt->constraints, basis = (int)opt->basis;
    if (dk_py_opt_choice(kw, "weights", weights_names, &weights, context) < 0 ||
        dk_py_opt_choice(kw, "detail", detail_names, &detail, context) < 0 ||
        dk_py_opt_choice(kw, "constraints", constraint_names, &constraints, context) < 0 ||
        dk_py_opt_choice(kw, "basis", basis_names, &basis, context) < 0 ||
        dk_py_opt_double(kw, "constraint_weight", &opt->constraint_weight) < 0 ||
        dk_py_opt_double(kw, "tikhonov", &opt->tikhonov) < 0 ||
        dk_py_opt_int(kw, "local_frame_iterations", &opt->local_frame_iterations) < 0 ||
        dk_py_opt_double(kw, "local_frame_tolerance", &opt->local_frame_tolerance) < 0)
        return -1;
    opt->weights = (dk_le_weights)weights;
    opt->detail = (dk_le_detail)detail;
    opt->constraints = (dk_le_constraint_mode)constraints;
    opt->basis = (dk_le_basis)basis;
    return 0;
}

static PyObject *stats(dk_py_method *self)
{
    dk_laplacian_edit_counters s;
    dk_laplacian_edit_get_counters(self->native, &s);
    return Py_BuildValue("{s:i,s:i,s:i,s:i,s:i,s:i,s:i,s:i}", "n_unknowns", (int)s.n_unknowns,
                         "n_soft_rows", (int)s.n_soft_rows, "n_cotangent_fallback",
                         (int)s.n_cotangent_fallback, "n_degenerate_frames",
                         (int)s.n_degenerate_frames, "analysis_count", s.analysis_count,
                         "factorization_count", s.factorization_count, "basis_columns",
                         s.basis_columns, "basis_solves", s.basis_solves);
}

PyDoc_STRVAR(solve_doc,
             "solve(targets=None, transforms=None, warm_start=True, max_iterations=None,\n"
             "      resume=False, energy=True, preview=False, start_positions=None)\n"
             "      -> SolveResult\n\n"
             "preview=True (the contract's keyword) solves as usual: this method has no\n"
             "faster result to show.\n"
             "targets: (sum of handle sizes) x 3 positions, concatenated in handle order;\n"
             "transforms: n_handles x 4 x 4 affine transforms of the rest pose. Returns the\n"
             "deformed positions, the energy ||A x - delta||^2 (+ soft and Tikhonov terms) at\n"
             "them, the number of linear solves and whether the local-frame iteration met\n"
             "its tolerance (always True for 'fixed' and 'membrane'). energy=False skips the\n"
             "energy (result.energy is nan): one pass over the operator less, for interactive\n"
             "updates that never show it. A direct method: the start and iteration keywords\n"
             "change nothing.");

PyDoc_STRVAR(lap_doc,
             "LaplacianEdit(mesh, handles, fixed=None, roi=None, handle_weights=None,\n"
             "              stiffness=None, weights='cotangent', detail='local_frame',\n"
             "              constraints='hard', constraint_weight=1.0, tikhonov=0.0,\n"
             "              local_frame_iterations=1, local_frame_tolerance=1e-6, basis='auto',\n"
             "              progress=None)\n\n"
             "Laplacian editing / least-squares meshes: minimises ||A x - delta||^2 with A the\n"
             "normalised umbrella operator (uniform or cotangent weights), delta = A x0\n"
             "('fixed', detail preserving but not rotation invariant), 0 ('membrane') or the\n"
             "rest deltas in local frames re-estimated on the solution ('local_frame', as\n"
             "Blender's Laplacian Deform; local_frame_iterations extra solves). Handles and\n"
             "fixed vertices are eliminated ('hard'; handle vertices with weight < 1 become\n"
             "soft rows) or soft rows of weight constraint_weight * handle weight ('soft').\n"
             "tikhonov = mu adds mu^2 ||x - x0||^2. Vertices outside roi stay at rest.\n"
             "stiffness is not supported (ValueError). basis='auto' precomputes the solution's\n"
             "affine response to the handle transforms at bind (up to 16 handles, 128 MB), so\n"
             "that drags by transforms, or by positions some affine map per handle reproduces,\n"
             "skip the back-substitution; 'off' never builds it. progress(fraction) is\n"
             "called during the bind with a deformkit.BindProgress (fraction.phase: renumber,\n"
             "operator, constraints, assemble, analyze, factorize, basis, then 'done' at 1);\n"
             "a true return or an exception stops it (the exception propagates). See\n"
             "docs/methods/laplacian_edit.md.");

static PyGetSetDef lap_getset[] = {DK_PY_METHOD_GETSET, {NULL, NULL, NULL, NULL, NULL}};

static PyMethodDef lap_methods[] = {DK_PY_METHOD_METHODS(solve_doc), {NULL, NULL, 0, NULL}};

/* progress=: the shared callback (dk_py.h), phases named by the native bind / rebind */
static void bind_progress(void *options, dk_py_progress *p)
{
    ((dk_laplacian_edit_options *)options)->progress = dk_py_progress_phase;
    ((dk_laplacian_edit_options *)options)->progress_user = p;
}

static void rebind_progress(void *native, dk_py_progress *p)
{
    dk_laplacian_edit_set_progress((dk_laplacian_edit *)native,
                                   p ? dk_py_progress_phase : NULL, p);
}

static const dk_py_method_spec lap_spec = {
    .name = "LaplacianEdit",
    .type_name = "deformkit.LaplacianEdit",
    .ops = &dk_laplacian_edit_ops,
    .doc = lap_doc,
    .options_size = sizeof(dk_laplacian_edit_options),
    .default_options = default_options,
    .parse_options = parse_options,
    .stats = stats,
    .bind_progress = bind_progress,
    .rebind_progress = rebind_progress,
    .getset = lap_getset,
    .methods = lap_methods,
};

static PyObject *lap_new(PyTypeObject *type, PyObject *args, PyObject *kwargs)
{
    return dk_py_method_new(type, args, kwargs, &lap_spec);
}

int dk_py_init_laplacian_edit(PyObject *module)
{
    return dk_py_method_register(module, &lap_spec, lap_new);
}
