/* DeformKit CPython module: one generic Python type for every deformation method, driven by
 * a per-method spec (implemented in py_method.c).
 *
 * The generic part is the method contract (native/methods/dk_method.h) as Python sees it:
 *
 *   Cls(mesh, handles, fixed=None, roi=None, handle_weights=None, stiffness=None, **options)
 *       binds with the GIL released; `options` are the method's own keywords, read by its
 *       spec's parse_options into its native options struct;
 *   solve(targets=None, transforms=None, warm_start=True, max_iterations=None, resume=False,
 *         energy=True, preview=False, start_positions=None, **extra) -> SolveResult
 *       exactly one of targets / transforms; warm_start, resume, start_positions (n x 3:
 *       DK_START_GIVEN, not with resume) and max_iterations matter for iterative methods
 *       only; energy=False lets a method skip its energy (NaN); `extra`
 *       are the method's own solve keywords (its spec's solve_extra);
 *   rebind(handles=None, fixed=None, roi=None, handle_weights=None, stiffness=None)
 *       arguments not given keep their bound value;
 *   energy(positions) -> float;
 *   mesh, n_vertices, n_handles, n_handle_vertices, stats.
 *
 * and the object's life: the Mesh kept alive, the constraint keywords remembered for rebind,
 * one call at a time (a concurrent call from another thread gets RuntimeError: the native
 * object reuses its buffers), garbage-collector support (a method object in a reference cycle
 * is freed, with its helper thread).
 *
 * A method's binding file (py_<method>.c) keeps only what is its own: its option names and
 * parse_options, its docs, any extra solve keywords, getters or methods, and a spec. */
#ifndef DK_PY_METHOD_H
#define DK_PY_METHOD_H

#include "dk_py.h"
#include "dk_py_lap.h"

#include "dk_method.h"

typedef struct dk_py_method_spec dk_py_method_spec;

/** The size of a method's pending solve keywords (see dk_py_method_spec.solve_extra). */
#define DK_PY_EXTRA_MAX 128

/** The size of a control read from keywords (see dk_py_method_spec.parse_control). */
#define DK_PY_CONTROL_MAX 512

/** The Python object of every method. */
typedef struct dk_py_method {
    PyObject_HEAD
    const dk_py_method_spec *spec;
    PyObject *mesh_obj;
    const dk_mesh *mesh;
    void *native;                                              /* the bound method object */
    PyObject *handles, *fixed, *roi, *handle_weights, *stiffness; /* as last bound         */
    int busy;                /* a call is running on the object ...                      */
    long busy_pid;           /* ... in this process (getpid() when it was entered)       */
    unsigned long busy_tid;  /* ... on this thread (PyThread_get_thread_ident())          */
    int busy_paused;         /* ... and stands at a progress callback (dk_py_progress)    */
} dk_py_method;

/** What is a method's own. */
struct dk_py_method_spec {
    const char *name;         /**< "ARAP": the class deformkit.ARAP, the native ops' name   */
    const char *type_name;    /**< "deformkit.ARAP" (a literal: the type keeps pointing to it)*/
    const dk_method_ops *ops; /**< the native contract                                      */
    const char *doc;          /**< the class docstring (constructor signature first)         */
    int takes_stiffness;      /**< 0: a non-None stiffness is a ValueError naming the method */
    int handles_optional;     /**< 1: handles may be None or [] (a method that simulates what
                                   no handle holds): the constructor's handles keyword is
                                   optional and solve needs no targets without handles    */
    size_t options_size;      /**< sizeof the native options struct (<= 256)                  */
    /** Fills `options` with the defaults. */
    void (*default_options)(void *options);
    /** Reads the method's own keywords from `kw` (a dict it may consume entries of, with the
     *  dk_py_opt_* helpers) into `options`; what is left in `kw` afterwards is a TypeError.
     *  Returns 0 or -1 with an exception set. */
    int (*parse_options)(PyObject *kw, void *options, const char *context);
    /** Optional: frees what parse_options allocated into `options` (arrays the native
     *  options point to during bind); called once after the bind, and after a failed
     *  parse, so parse_options must leave `options` releasable at every exit. */
    void (*release_options)(void *options);
    /** Optional: the method's own solve keywords, in two steps so that a call that raises
     *  changes nothing (issue 18, class 8). solve_extra takes them out of `kw` (like
     *  parse_options) and checks them into `pending` (DK_PY_EXTRA_MAX bytes, zeroed),
     *  changing nothing; returns 0 or -1 with an exception set. apply_extra runs only after
     *  every input of the call has been read and checked, just before the native solve: it
     *  sets `pending` on the bound object and writes what it replaced into `saved` (same
     *  layout); when the solve fails it is called again with (saved, NULL) to put the
     *  object back. Both are called with the object entered. */
    int (*solve_extra)(dk_py_method *self, PyObject *kw, void *pending, const char *context);
    void (*apply_extra)(dk_py_method *self, const void *pending, void *saved);
    /** Optional: the method's own forms of the motion (e.g. translation=, rotation=, pivot=),
     *  read from `kw` like solve_extra: returns the equivalent `transforms` (n_handles x 4 x
     *  4, a new reference), Py_None (a new reference) when none of its keywords is given,
     *  or NULL with an exception set. Combining them with targets or transforms is a
     *  TypeError. */
    PyObject *(*solve_motion)(dk_py_method *self, PyObject *kw, const char *context);
    /** Optional: the method reports bind progress. Installs the shared callback (dk_py.h:
     *  dk_py_progress_phase) with user `p` into the native `options`; the generic
     *  constructor then takes progress= (dk_py_progress_take) and raises what the callback
     *  raised. */
    void (*bind_progress)(void *options, dk_py_progress *p);
    /** Optional: the native object's rebind reports progress: installs the callback for
     *  the following rebinds (p NULL: removes it); rebind(progress=...) then exists. */
    void (*rebind_progress)(void *native, dk_py_progress *p);
    /** Optional: the method binds to a control (dk_controls.h: a lattice, a cage...)
     *  instead of vertex groups. Reads it from the constructor's or rebind's keywords `kw`
     *  (taking them out, like parse_options) for `mesh` into `store` (DK_PY_CONTROL_MAX
     *  bytes, zeroed, max_align_t-aligned), whose first member is the dk_control_desc the
     *  bind gets; `bound` is NULL for the constructor (absent keywords: the defaults), the
     *  bound native object for rebind (absent keywords: its current values). Returns 0, or
     *  -1 with an exception set. Such a method's constructor takes the mesh and keywords
     *  only (no handles), its rebind the control's keywords, and its solve the control's
     *  targets (stats.n_controls rows). */
    int (*parse_control)(PyObject *kw, const dk_mesh *mesh, const void *bound, void *store,
                         const char *context);
    /** Optional: frees what parse_control allocated into `store`; called once after the
     *  bind or rebind, and after a failed parse (so parse_control leaves `store`
     *  releasable at every exit). */
    void (*release_control)(void *store);
    /** 1: the method binds to vertex groups (handles, fixed, ...) with an optional
     *  control beside them (poses): the constructor takes the groups as every vertex-group
     *  method does and the control's keywords through parse_control (absent: a store whose
     *  kind is 0, no control); rebind takes both (absent control keywords keep the bound
     *  control); solve takes the handles' targets as targets / transforms. */
    int control_with_groups;
    /** Optional, with control_with_groups: the solve keyword holding one value per control
     *  ("weights": a weight per pose), required when the bind has a control, put in front
     *  of the handles' targets; control_values_of names what they are for ("poses"). */
    const char *control_values;
    const char *control_values_of;
    /** 1: the control's targets are one 4 x 4 transform per control (bones' frames, from
     *  solve(transforms=...)); 0: one position per control point (solve(targets=...)). */
    int control_transforms;
    /** 1: the bind runs under the module's ARPACK lock (ARPACK is not reentrant). */
    int serialise_bind;
    /** Optional: the `stats` dict; default: the contract's counters. */
    PyObject *(*stats)(dk_py_method *self);
    PyGetSetDef *getset;   /**< the type's getters: DK_PY_METHOD_GETSET, then the method's
                                own, NULL-terminated                                      */
    PyMethodDef *methods;  /**< the type's methods: DK_PY_METHOD_METHODS(solve_doc), then the
                                method's own, NULL-terminated                             */
};

/* The contract's methods and getters, for the start of a spec's tables (static data, so
 * that nothing is written at run time). */
PyObject *dk_py_method_solve(PyObject *obj, PyObject *args, PyObject *kwargs);
PyObject *dk_py_method_rebind(PyObject *obj, PyObject *args, PyObject *kwargs);
PyObject *dk_py_method_energy(PyObject *obj, PyObject *arg);
PyObject *dk_py_method_save_state(PyObject *obj, PyObject *unused);
PyObject *dk_py_method_restore_state(PyObject *obj, PyObject *arg);
PyObject *dk_py_method_estimate_memory(PyObject *cls, PyObject *args, PyObject *kwargs);
PyObject *dk_py_method_get_mesh(PyObject *obj, void *closure);
PyObject *dk_py_method_get_n_vertices(PyObject *obj, void *closure);
PyObject *dk_py_method_get_n_handles(PyObject *obj, void *closure);
PyObject *dk_py_method_get_n_handle_vertices(PyObject *obj, void *closure);
PyObject *dk_py_method_get_stats(PyObject *obj, void *closure);
PyObject *dk_py_method_get_warnings(PyObject *obj, void *closure);
extern const char dk_py_method_rebind_doc[];
extern const char dk_py_method_energy_doc[];
extern const char dk_py_method_save_state_doc[];
extern const char dk_py_method_restore_state_doc[];
extern const char dk_py_method_estimate_memory_doc[];

#define DK_PY_METHOD_METHODS(solve_doc)                                                    \
    {"solve", (PyCFunction)(void (*)(void))dk_py_method_solve, METH_VARARGS | METH_KEYWORDS, \
     solve_doc},                                                                           \
        {"rebind", (PyCFunction)(void (*)(void))dk_py_method_rebind,                       \
         METH_VARARGS | METH_KEYWORDS, dk_py_method_rebind_doc},                           \
        {"energy", dk_py_method_energy, METH_O, dk_py_method_energy_doc},                  \
        {"save_state", dk_py_method_save_state, METH_NOARGS, dk_py_method_save_state_doc}, \
        {"restore_state", dk_py_method_restore_state, METH_O,                              \
         dk_py_method_restore_state_doc},                                                  \
        {"estimate_memory", (PyCFunction)(void (*)(void))dk_py_method_estimate_memory,      \
         METH_VARARGS | METH_KEYWORDS | METH_CLASS, dk_py_method_estimate_memory_doc}

#define DK_PY_METHOD_GETSET                                                                \
    {"mesh", dk_py_method_get_mesh, NULL, "the bound deformkit.Mesh", NULL},               \
        {"n_vertices", dk_py_method_get_n_vertices, NULL, "number of mesh vertices", NULL}, \
        {"n_handles", dk_py_method_get_n_handles, NULL, "number of handle groups", NULL},  \
        {"n_handle_vertices", dk_py_method_get_n_handle_vertices, NULL,                    \
         "rows expected in solve(targets)", NULL},                                         \
        {"stats", dk_py_method_get_stats, NULL,                                            \
         "dict of counters: n_unknowns, analysis_count, factorization_count, n_held and "  \
         "n_held_components (loose geometry held at rest), and the method's own",          \
         NULL},                                                                            \
        {"warnings", dk_py_method_get_warnings, NULL,                                      \
         "tuple of str: what the bind decided for the caller, e.g. vertices held at rest " \
         "because nothing constrains their component (empty when nothing)",               \
         NULL}

/** tp_new of a method's type: binds per `spec`. A method's binding file defines its tp_new
 *  as a one-line call to this (the type reaches its spec through it). */
PyObject *dk_py_method_new(PyTypeObject *type, PyObject *args, PyObject *kwargs,
                           const dk_py_method_spec *spec);

/** Creates the type from `spec` with `tp_new`, adds it to the module as spec->name.
 *  Returns 0 or -1. */
int dk_py_method_register(PyObject *module, const dk_py_method_spec *spec, newfunc tp_new);

/** Enters the object for one native call (RuntimeError when busy or unbound); leave with
 *  self->busy = 0. For a spec's extra methods. An object that is busy in another process --
 *  a thread of the parent had entered it when this process forked, and that thread does not
 *  exist here -- is taken over (issue 18, class 3): the fork gate (dk_py.h) guarantees that
 *  its native call was not running at the fork, so its native state is whole. Every native
 *  call on a method object that releases the GIL must therefore pass the gate
 *  (DK_PY_BEGIN_NATIVE). Two exceptions: the forking thread itself, inside the object's
 *  rebind from its progress callback, still owns it in the child (busy); and an object whose
 *  rebind stood at a progress callback in another thread at the fork is half-way through
 *  it, so the child refuses every call on it (RuntimeError saying so). */
int dk_py_method_enter(dk_py_method *self);

/** For getters that read the native object (with the GIL held, without entering it):
 *  returns 1 when it is bound and no native call of this process runs on it, else 0 with a
 *  RuntimeError set ("in use by another thread"). A solve or rebind in another thread
 *  releases the GIL and may free and rebuild what a getter would read (a rebind replaces
 *  the constraint sets, Embedded deformation's graph): reading it then is a use after
 *  free, so every such getter asks this first. */
int dk_py_method_readable(dk_py_method *self);

/** A native query from n x 3 values to n x 3 values (positions, normals) on the bound
 *  object: `in` is NULL when the caller gave None. */
typedef dk_status (*dk_py_map_fn)(void *native, const double *in, double *out, dk_error *err);

/** Runs `fn` on the entered object without the GIL: reads `in_obj` (n x 3 of the mesh's
 *  vertices, named `arg` in errors; Py_None passes NULL) and returns a new n x 3 array, or
 *  NULL with the native error raised (prefixed `context`). For the methods' own queries
 *  (EmbeddedDeformation.normals, ShapeMatching.goals). */
PyObject *dk_py_method_map_n3(PyObject *obj, PyObject *in_obj, const char *arg,
                              const char *context, dk_py_map_fn fn);

/* Reading options: each takes `key` out of the dict `kw` when present (absent: `*value`
 * keeps its default) and converts it as PyArg_ParseTuple would ("i", "d", "p"), or matches
 * a choice against `names` (NULL-terminated; ValueError naming the accepted values). Return
 * 0, or -1 with an exception set. */
int dk_py_opt_int(PyObject *kw, const char *key, int *value);
/** Takes `key` out of `kw`: a new reference, or NULL when absent (or with an exception set:
 *  check PyErr_Occurred). */
PyObject *dk_py_opt_object(PyObject *kw, const char *key);
int dk_py_opt_double(PyObject *kw, const char *key, double *value);
int dk_py_opt_bool(PyObject *kw, const char *key, int *value);
int dk_py_opt_choice(PyObject *kw, const char *key, const char *const *names, int *value,
                     const char *context);

#endif
