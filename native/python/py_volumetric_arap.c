/* DeformKit CPython module: deformkit.VolumetricARAP (native/methods/dk_volumetric_arap.h),
 * on the generic method type (dk_py_method.h). What is its own: its options, the tetrahedra
 * (tetrahedra(), n_points, n_interior_points, n_tetrahedra). */
#include "dk_py_arap.h"

#include "dk_volumetric_arap.h"

static const char *const accel_names[] = {"none", "anderson", "newton", NULL};

static void default_options(void *o)
{
    dk_volumetric_arap_default_options((dk_volumetric_arap_options *)o);
}

static int parse_options(PyObject *kw, void *o, const char *context)
{
    dk_volumetric_arap_options *opt = (dk_volumetric_arap_options *)o;
    int accel = (int)opt->acceleration;
    if (dk_py_opt_double(kw, "quality", &opt->quality) < 0 ||
        dk_py_opt_double(kw, "max_volume", &opt->max_volume) < 0 ||
        dk_py_opt_int(kw, "max_iterations", &opt->max_iterations) < 0 ||
        dk_py_opt_double(kw, "tolerance", &opt->tolerance) < 0 ||
        dk_py_opt_choice(kw, "acceleration", accel_names, &accel, context) < 0 ||
        dk_py_opt_int(kw, "cg_iterations", &opt->cg_iterations) < 0 ||
        dk_py_opt_int(kw, "levels", &opt->levels) < 0 ||
        dk_py_opt_int(kw, "embed", &opt->embed) < 0)
        return -1;
    opt->acceleration = (dk_arap_acceleration)accel;
    return 0;
}

/* solve(tolerance=, cg_iterations=): ARAP's, on the solver inside */
static void apply_extra(dk_py_method *self, const void *pending, void *saved)
{
    dk_py_arap_apply_extra_to(dk_volumetric_arap_solver(self->native), pending, saved);
}

static PyObject *stats(dk_py_method *self)
{
    dk_method_stats ms;
    dk_volumetric_arap_counters c;
    dk_arap_counters ac;
    dk_volumetric_arap_stats(self->native, &ms);
    dk_volumetric_arap_get_counters(self->native, &c);
    dk_arap_get_counters(dk_volumetric_arap_solver(self->native), &ac);
    return Py_BuildValue("{s:i,s:i,s:i,s:i,s:i,s:i,s:i,s:i,s:i,s:i}", "n_unknowns",
                         (int)ms.n_unknowns, "n_points", (int)c.n_points, "n_interior_points",
                         (int)c.n_interior_points, "n_tetrahedra", (int)c.n_tetrahedra,
                         "analysis_count", ms.analysis_count, "factorization_count",
                         ms.factorization_count, "levels", ac.levels, "coarse_points",
                         ac.levels > 1 ? (int)ac.coarse_vertices[0] : 0, "coarse_starts",
                         ac.coarse_starts, "embedded",
                         dk_volumetric_arap_embedded(self->native));
}

/* n_points, n_interior_points, n_tetrahedra: closure 0, 1, 2 */
static PyObject *get_count(PyObject *obj, void *which)
{
    if (!dk_py_method_readable((dk_py_method *)obj))
        return NULL;
    dk_volumetric_arap_counters c;
    dk_volumetric_arap_get_counters(((dk_py_method *)obj)->native, &c);
    const long v[3] = {(long)c.n_points, (long)c.n_interior_points, (long)c.n_tetrahedra};
    return PyLong_FromLong(v[(Py_ssize_t)which]);
}

static dk_status fill_basis(void *native, double *out, dk_error *err)
{
    return dk_volumetric_arap_response_basis(native, out, err);
}

static dk_arap *solver(void *native)
{
    return dk_volumetric_arap_solver(native);
}

static PyObject *vol_response_basis(PyObject *obj, PyObject *unused)
{
    (void)unused;
    return dk_py_arap_response_basis((dk_py_method *)obj, "VolumetricARAP.response_basis",
                                     fill_basis, solver);
}

PyDoc_STRVAR(response_basis_doc,
             "response_basis() -> ndarray (n_vertices, 4 * n_handles), or None\n\n"
             "ARAP.response_basis of the solver on the tetrahedra, the mesh's vertices' rows:\n"
             "the global step's response to each handle's affine motion (rotations held).\n"
             "None over the limits (16 handles, 128 MB).");

static PyObject *get_note(PyObject *obj, void *c)
{
    (void)c;
    if (!dk_py_method_readable((dk_py_method *)obj))
        return NULL;
    return PyUnicode_FromString(dk_volumetric_arap_note(((dk_py_method *)obj)->native));
}

static PyObject *vol_tetrahedra(PyObject *obj, PyObject *unused)
{
    dk_py_method *self = (dk_py_method *)obj;
    (void)unused;
    if (dk_py_method_enter(self) < 0)
        return NULL;
    dk_volumetric_arap_counters c;
    dk_volumetric_arap_get_counters(self->native, &c);
    double *p = NULL;
    dk_index *t = NULL;
    PyObject *points = dk_py_new_doubles(2, c.n_points, 3, &p);
    PyObject *tets = points ? dk_py_new_indices(2, c.n_tetrahedra, 4, &t) : NULL;
    if (tets)
        dk_volumetric_arap_tetrahedra(self->native, p, t);
    self->busy = 0;
    if (!tets) {
        Py_XDECREF(points);
        return NULL;
    }
    return Py_BuildValue("(NN)", points, tets);
}

PyDoc_STRVAR(tetrahedra_doc,
             "tetrahedra() -> (points, tetrahedra)\n\n"
             "The volume being deformed: points (n_points x 3: the mesh's vertices first,\n"
             "then the interior's, at the last solve's result, or at rest before any) and\n"
             "tetrahedra (n_tetrahedra x 4 point indices, positively oriented at rest).");

PyDoc_STRVAR(solve_doc,
             "solve(targets=None, transforms=None, warm_start=True, max_iterations=None,\n"
             "      resume=False, energy=True, preview=False, start_positions=None,\n"
             "      input_positions=None, tolerance=None, cg_iterations=None) -> SolveResult\n\n"
             "As ARAP.solve, on the volume: the positions are the mesh's vertices (the\n"
             "interior stays in the object, tetrahedra() shows it). input_positions (the pose\n"
             "to edit) and start_positions move the interior with them by the harmonic\n"
             "extension. energy: the tetrahedra's ARAP energy, sum vol |F - R|^2.");

PyDoc_STRVAR(volumetric_doc,
             "VolumetricARAP(mesh, handles, fixed=None, roi=None, handle_weights=None,\n"
             "               stiffness=None, quality=1.5, max_volume=0.0,\n"
             "               max_iterations=1000, tolerance=1e-6, acceleration='newton',\n"
             "               cg_iterations=12, levels=0, embed=0, progress=None)\n\n"
             "As-rigid-as-possible deformation of the solid a closed surface bounds (the\n"
             "slides' volume-based deformation): the interior tetrahedralized by TetGen (the\n"
             "mesh's vertices are its boundary), each tetrahedron's deformation gradient\n"
             "F = Ds Dm^-1 kept as near a rotation as it can, sum vol |F - R|^2, so a bent limb\n"
             "keeps its volume where surface ARAP lets it shrink or swell. Handles, fixed\n"
             "vertices, region of interest, soft handle weights and stiffness as for ARAP (the\n"
             "interior's stiffness spreads in from the surface). quality: the tetrahedra's\n"
             "largest radius-edge ratio (0: none, else 1.1 to 10); max_volume: the largest\n"
             "tetrahedron (0: none). Each closed part of the mesh is a volume; a part with a\n"
             "hole or a non-manifold edge bounds none and deforms as a surface (as ARAP),\n"
             "and so does the whole mesh when its closed parts cross themselves:\n"
             "volume_note says which. levels: 1 the volume alone, 2 with a coarse level (the\n"
             "surface simplified to 1/16, its own tetrahedra: cold solves start from its\n"
             "result prolonged, then converge on the volume as without it), 0 automatic\n"
             "(the level from 10,000 points on); stats reports levels,\n"
             "coarse_points, coarse_starts. embed: 1 the surface is the tetrahedra's\n"
             "boundary, 2 a coarse volume carries it (the surface simplified to 1/16, its own\n"
             "tetrahedra and VolumetricARAP; each vertex moved by the coarse volume's move at\n"
             "its barycentric coordinates, handles and fixed vertices exactly placed; every\n"
             "part must be closed), 0 automatic (2 from 250,000 vertices on when every part\n"
             "is closed: the full volume would pass 3 GB); then tetrahedra() and the counts\n"
             "are the coarse volume's. See docs/methods/volumetric_arap.md.");

static PyMethodDef vol_methods[] = {
    DK_PY_METHOD_METHODS(solve_doc),
    {"tetrahedra", vol_tetrahedra, METH_NOARGS, tetrahedra_doc},
    {"response_basis", vol_response_basis, METH_NOARGS, response_basis_doc},
    {NULL, NULL, 0, NULL},
};

static PyGetSetDef vol_getset[] = {
    DK_PY_METHOD_GETSET,
    {"n_points", get_count, NULL, "the volume's points: vertices, then interior", (void *)0},
    {"n_interior_points", get_count, NULL, "points TetGen added inside", (void *)1},
    {"n_tetrahedra", get_count, NULL, "the tetrahedra", (void *)2},
    {"volume_note", get_note, NULL,
     "why a part of the mesh (or all of it) deforms as a surface: '' when every part bounds "
     "a volume", NULL},
    {NULL, NULL, NULL, NULL, NULL},
};

static void bind_progress(void *options, dk_py_progress *p)
{
    ((dk_volumetric_arap_options *)options)->progress = dk_py_progress_phase;
    ((dk_volumetric_arap_options *)options)->progress_user = p;
}

static void rebind_progress(void *native, dk_py_progress *p)
{
    dk_volumetric_arap_set_progress((dk_volumetric_arap *)native,
                                    p ? dk_py_progress_phase : NULL, p);
}

static const dk_py_method_spec vol_spec = {
    .name = "VolumetricARAP",
    .type_name = "deformkit.VolumetricARAP",
    .ops = &dk_volumetric_arap_ops,
    .doc = volumetric_doc,
    .takes_stiffness = 1,
    .options_size = sizeof(dk_volumetric_arap_options),
    .default_options = default_options,
    .parse_options = parse_options,
    .stats = stats,
    .solve_extra = dk_py_arap_solve_extra,
    .apply_extra = apply_extra,
    .bind_progress = bind_progress,
    .rebind_progress = rebind_progress,
    .getset = vol_getset,
    .methods = vol_methods,
};

static PyObject *vol_new(PyTypeObject *type, PyObject *args, PyObject *kwargs)
{
    return dk_py_method_new(type, args, kwargs, &vol_spec);
}

int dk_py_init_volumetric_arap(PyObject *module)
{
    return dk_py_method_register(module, &vol_spec, vol_new);
}
