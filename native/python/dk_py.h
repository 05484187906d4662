/* DeformKit CPython module: shared helpers for the binding files.
 *
 * Built against the Limited API of Python 3.11 (Py_LIMITED_API=0x030B0000): no numpy C API,
 * no CPython internals. Inputs are read through the buffer protocol (numpy arrays,
 * memoryviews of Blender's foreach_get data, array.array, bytes) or, as a convenience,
 * nested Python sequences. Outputs are numpy arrays when numpy can be imported (created by
 * calling numpy.frombuffer on a bytearray the module filled), else memoryviews.
 *
 * One binding file per idea (py_mesh.c, py_operators.c, py_arap.c, ...); each exports
 * `int dk_py_init_<name>(PyObject *module)`, listed once in DK_PY_PARTS below, which
 * module.c calls; it returns 0 or -1 with an exception set.
 */
#ifndef DK_PY_H
#define DK_PY_H

#define PY_SSIZE_T_CLEAN
#include <Python.h>
#include <pthread.h>
#include <stdint.h>

#include "dk_mesh.h"
#include "dk_status.h"

/* ------------------------------------------------------------------ errors ------------- */

/** Raises the Python exception matching `err->status` with the C message:
 *  DK_ERR_INDEX -> IndexError (a subclass of LookupError, message names the index);
 *  INVALID_ARGUMENT, NONFINITE, DEGENERATE, TOPOLOGY -> ValueError;
 *  OUT_OF_MEMORY -> MemoryError; CANCELLED -> KeyboardInterrupt-free RuntimeError;
 *  NOT_POSITIVE_DEFINITE, NO_CONVERGENCE, NUMERIC, INTERNAL -> RuntimeError.
 *  `context` (may be NULL) is prefixed ("ARAP.solve: ..."). Returns NULL for convenience. */
PyObject *dk_py_raise(const dk_error *err, const char *context);

/* ------------------------------------------------------------------ inputs ------------- */

/** A contiguous double matrix read from any buffer or nested sequence. */
typedef struct dk_py_doubles {
    double *data;      /**< rows x cols, row-major; owned (PyMem_Malloc), free with _release */
    Py_ssize_t rows, cols;
    int ndim;          /**< 1 or 2: the dimensions of what was read                        */
} dk_py_doubles;

/** `cols` for a 1-D array (cols set to 1, ndim 1) or a 2-D one of any width (ndim 2), so that
 *  a caller that treats the two differently reads the input once and then looks at ndim. */
#define DK_PY_COLS_1D_OR_2D (-2)

/** `obj` (an array with a shape and reshape(), NumPy's) as rows of r*c values for
 *  dk_py_read_doubles(..., r * c, ...): shape ... x r x c (3 or more dimensions) is
 *  reshaped to k x (r*c), and so is shape (k r) x c (the blocks stacked: one r x c block
 *  is 1 x (r*c)); a shape of 3 or more dimensions whose
 *  last two are not r x c raises ValueError naming `name` (reshaping it would read its
 *  values in another order: a b x 3 x 2 array of bones is not b x 2 x 3). Anything else
 *  (lists, k x (r*c) arrays, buffers) is returned as it is. New reference, or NULL. */
PyObject *dk_py_as_blocks(PyObject *obj, int r, int c, const char *name);

/** Reads `obj` exactly once, as a float32/float64 array (any buffer of another element type is
 *  a TypeError naming `name` and the format found: integer and byte buffers are not
 *  coordinates, and complex data would lose its imaginary part) or a (nested) sequence of
 *  Python floats and ints (numpy scalars by their format), of shape (rows, cols), converting
 *  to double. Sequences are copied into lists of our own before their shape is decided, so
 *  Python code run by the conversion cannot make the shape and the data disagree. `cols` > 0 demands that many columns (a flat buffer of rows*cols is accepted and
 *  reshaped); cols == 0 accepts a 1-D array (cols set to 1). `rows` >= 0 demands that many
 *  rows, -1 accepts any. Non-finite values are NOT rejected here (callers name the vertex).
 *  `name` is used in messages ("vertices must have 3 columns, got 2"). Returns 0 or -1 with
 *  TypeError/ValueError set. */
int dk_py_read_doubles(PyObject *obj, Py_ssize_t rows, Py_ssize_t cols, const char *name,
                       dk_py_doubles *out);

/** A flag argument: True or False, a numpy bool, or the ints 0 and 1. Anything else (a
 *  string such as "no", None, 2) is a TypeError naming `name` and `context`: any truthy
 *  object used to count as True (the second hostile review: preview="no" previewed).
 *  Returns 0 with *value set, or -1. */
int dk_py_strict_bool(PyObject *obj, const char *name, const char *context, int *value);

/** A contiguous index array read from any int32/int64 (or other integer) buffer or sequence. */
typedef struct dk_py_indices {
    dk_index *data;    /**< rows x cols, row-major; owned, free with _release              */
    Py_ssize_t rows, cols;
    int ndim;          /**< 1 or 2: the dimensions of what was read                        */
} dk_py_indices;

/** Same contract as dk_py_read_doubles for integer data. Values outside int32 raise
 *  OverflowError naming the position; floats raise TypeError. */
int dk_py_read_indices(PyObject *obj, Py_ssize_t rows, Py_ssize_t cols, const char *name,
                       dk_py_indices *out);

/** Reads a surface: vertices (n x 3 doubles) and triangles (m x 3 indices), each as
 *  dk_py_read_doubles / dk_py_read_indices do; on failure nothing is held. Returns 0 or -1
 *  with an exception set. */
int dk_py_read_surface(PyObject *vobj, PyObject *fobj, dk_py_doubles *v, dk_py_indices *f);

void dk_py_doubles_release(dk_py_doubles *a);
void dk_py_indices_release(dk_py_indices *a);

/* ------------------------------------------------------------------ outputs ------------ */

/** A new writable array of doubles with the given shape (ndim 1 or 2; shape[1] ignored for
 *  ndim 1). `*data` receives the pointer to fill (row-major, valid while the result lives).
 *  Returns a numpy.ndarray when numpy is importable, else a memoryview; NULL on error. */
PyObject *dk_py_new_doubles(int ndim, Py_ssize_t rows, Py_ssize_t cols, double **data);

/** Same for int32 indices. */
PyObject *dk_py_new_indices(int ndim, Py_ssize_t rows, Py_ssize_t cols, dk_index **data);

/** Same for int64 (counts that may exceed int32). */
PyObject *dk_py_new_int64(int ndim, Py_ssize_t rows, Py_ssize_t cols, int64_t **data);

/* ------------------------------------------------------------------ the Mesh type ------- */

/** Returns the dk_mesh wrapped by a deformkit.Mesh, or NULL with TypeError set (naming
 *  `argname`) if `obj` is not a Mesh. The Mesh object must be kept alive (held with a
 *  reference) by whoever keeps the pointer. */
const dk_mesh *dk_py_mesh_get(PyObject *module, PyObject *obj, const char *argname);

/** The deformkit.Mesh type object (borrowed), from the module state. */
PyObject *dk_py_mesh_type(PyObject *module);

/* ------------------------------------------------------------------ module state ------- */

/** Per-module state (no C globals): the Mesh type, the lock that serialises ARPACK calls
 *  (ARPACK is not reentrant) and a cached numpy.frombuffer (or None). */
typedef struct dk_py_state {
    PyObject *mesh_type;
    PyObject *solve_result_type;
    PyThread_type_lock arpack_lock;
    _Atomic unsigned long arpack_owner; /* PyThread_get_thread_ident() of its holder, or 0 */
    PyObject *numpy_frombuffer; /* None if numpy is missing */
    /* the fork gate (dk_py_native_begin): */
    pthread_mutex_t gate_mu;
    pthread_cond_t gate_cv;
    int gate_ready;             /* gate_mu and gate_cv are initialised */
    int in_flight;              /* native calls running (under gate_mu) */
    int forks_pending;          /* os.fork calls waiting or forking (under gate_mu) */
    /* the method types and their specs, for their classmethods (estimate_memory): the type
     * pointers are compared, never followed (the module holds the types) */
    PyObject *progress_type;    /* deformkit.BindProgress (dk_py_progress)              */
    const void *method_type[16];
    const void *method_spec[16];
    int n_method_types;
} dk_py_state;

dk_py_state *dk_py_get_state(PyObject *module);

/* ------------------------------------------------------------------ bind progress ------ */
/* progress=callable(fraction) -> bool of the methods' constructors and rebind (issue 19,
 * item 3). `fraction` is a deformkit.BindProgress: a float in [0, 1] (non-decreasing over
 * one bind, ending at 1) whose `phase` attribute names the step ("factorize", ...). It is
 * called from the binding thread with the GIL taken for the call; a true return stops the
 * bind (RuntimeError "... cancelled ..."), and an exception stops it too and propagates
 * from the constructor or rebind unchanged. */
typedef struct dk_py_progress {
    PyObject *callable;  /* owned; NULL: no callback                                      */
    PyObject *type;      /* owned: deformkit.BindProgress                                 */
    PyObject *exc_type, *exc_value, *exc_tb; /* what the callable raised (owned), or NULL */
    dk_py_state *state;  /* the module's (the fork gate the call pauses in), or NULL      */
    int *paused;         /* set to 1 while the callable runs (a rebind's object), or NULL */
} dk_py_progress;

/** Takes the key "progress" out of the keyword dict `kw` (may be NULL) into `p` (zeroed
 *  first): None or absent is no callback, a non-callable a TypeError naming `context`.
 *  `module` is the deformkit module. Returns 0, or -1 with an exception set (p releasable).*/
int dk_py_progress_take(PyObject *kw, PyObject *module, const char *context,
                        dk_py_progress *p);

/** The native callback (dk_phase_progress_fn; user = a dk_py_progress with a callable).
 *  After the callable raised, every further call returns 1 without calling it. The native
 *  call it reports from is at a phase boundary: while the callable runs, the call leaves the
 *  fork gate (dk_py_native_pause), so that the callable may fork or make DeformKit calls of
 *  its own while another thread forks, without either waiting for the other. */
int dk_py_progress_phase(void *user, const char *phase, double fraction);

/** After a failed native call that reported to `p`: raises what the callable raised when it
 *  did (and returns NULL), else dk_py_raise(err, context). */
PyObject *dk_py_progress_raise(dk_py_progress *p, const dk_error *err, const char *context);

/** After a successful native call that reported to `p`: 1 with the exception set when the
 *  callable raised at the final report ("done", whose stop request the work ignores: it is
 *  complete), else 0. The caller then fails as for any error of the callable. */
int dk_py_progress_raised(dk_py_progress *p);

/** Drops the references of `p` (and any exception it still holds). */
void dk_py_progress_release(dk_py_progress *p);

/** Creates deformkit.BindProgress into the module and its state. Returns 0 or -1. */
int dk_py_progress_init_type(PyObject *module, dk_py_state *st);

/** The state of the module that defined `obj`'s type (a type created with the module), or
 *  NULL with no exception set. */
dk_py_state *dk_py_state_of(PyObject *obj);

/* ------------------------------------------------------------------ the fork gate ------ */
/* Issue 18, class 3. os.fork() in one thread while another is inside a native call copies
 * that call's half-done state into the child, where the thread does not exist: OpenBLAS's
 * own fork handler (which stops its thread pool) then waits forever for a worker that is
 * running that call's job (the *parent* hangs in fork), an ARPACK lock or an object's busy
 * flag stays taken in the child. So the heavy native calls (binds, solves, factorizations,
 * eigensolves, geodesics) pass through a gate: the package's os.register_at_fork handlers
 * close it before a fork -- waiting, without the GIL, for the calls in flight to return --
 * and open it after; a call that starts meanwhile waits at the gate. Calls that never touch
 * BLAS, OpenMP or a helper thread (Laplacian assembly, k-d trees, mesh building) do not pass
 * it. Both functions are called with the GIL released (DK_PY_BEGIN_NATIVE); st may be NULL
 * (no gate). */
void dk_py_native_begin(dk_py_state *st);
void dk_py_native_end(dk_py_state *st);

/** A call inside the gate that runs Python in between (a progress callback at a phase
 *  boundary) leaves the gate for that time: pause = dk_py_native_end, resume =
 *  dk_py_native_begin (it waits while a fork is under way). Without the GIL. */
void dk_py_native_pause(dk_py_state *st);
void dk_py_native_resume(dk_py_state *st);

/* ------------------------------------------------------------------ the ARPACK lock ---- */
/* ARPACK keeps its iteration state in Fortran SAVE variables: one eigensolve at a time in
 * the process. A second one started on the thread that holds the lock (from the progress
 * callback of an EigenDeformation bind) would wait for itself forever: refused instead. */

/** With the GIL: 0, or -1 with RuntimeError (naming `context`) when this thread already
 *  holds the ARPACK lock. */
int dk_py_arpack_check(dk_py_state *st, const char *context);
/** Without the GIL: takes the lock (waiting for another thread's eigensolve) / gives it
 *  back, recording the holder. */
void dk_py_arpack_acquire(dk_py_state *st);
void dk_py_arpack_release(dk_py_state *st);

/** Py_BEGIN_ALLOW_THREADS plus the fork gate (`st` evaluated once, with the GIL held). */
#define DK_PY_BEGIN_NATIVE(st)                                                             \
    {                                                                                      \
        dk_py_state *dk_gate_state_ = (st);                                                \
        Py_BEGIN_ALLOW_THREADS                                                             \
        dk_py_native_begin(dk_gate_state_);
#define DK_PY_END_NATIVE                                                                   \
        dk_py_native_end(dk_gate_state_);                                                  \
        Py_END_ALLOW_THREADS                                                               \
    }

/** The handlers the package registers with os.register_at_fork (module.c). Return 0. */
int dk_py_fork_before(dk_py_state *st);
void dk_py_fork_after_parent(dk_py_state *st);
void dk_py_fork_after_child(dk_py_state *st);

/* ------------------------------------------------------------------ solve results ------ */

/** A new deformkit.SolveResult (a struct sequence, also usable as a tuple) with the fields
 *  positions (n x 3 array), energy (float), iterations (int), converged (bool). Steals the
 *  reference to `positions`. Every method's solve() returns one. */
PyObject *dk_py_new_solve_result(PyObject *module, PyObject *positions, double energy,
                                 int iterations, int converged);

/* The binding files, in the order module.c registers them: each defines
 * `int dk_py_init_<part>(PyObject *module)`. A method's binding file adds one line here:
 * X(part) for the module's other parts, M(part, "Class") for a deformation method, whose
 * class name also goes into the module's `_methods` tuple (the list the add-on's mock module
 * and the tests compare against the add-on's registry). */
#define DK_PY_PARTS(X, M)                                                                  \
    X(mesh)                                                                                \
    X(operators)                                                                           \
    X(coordinates)                                                                         \
    X(bbw)                                                                                 \
    X(fit_weights)                                                                         \
    M(arap, "ARAP")                                                                        \
    M(laplacian_edit, "LaplacianEdit")                                                     \
    M(falloff, "Falloff")                                                                  \
    M(embedded, "EmbeddedDeformation")                                                     \
    M(eigen, "EigenDeformation")                                                           \
    M(fundamental, "LinearReconstruction")                                                 \
    M(lattice, "Lattice")                                                                  \
    M(cage, "Cage")                                                                        \
    M(shepard, "Shepard")                                                                  \
    M(skinning, "Skinning")                                                                \
    M(shape_matching, "ShapeMatching")                                                     \
    M(shape_interpolation, "ShapeInterpolation")                                           \
    M(volumetric_arap, "VolumetricARAP")                                                   \
    X(cholesky)

#define DK_PY_DECLARE_PART(part) int dk_py_init_##part(PyObject *module);
#define DK_PY_DECLARE_METHOD(part, cls) int dk_py_init_##part(PyObject *module);
DK_PY_PARTS(DK_PY_DECLARE_PART, DK_PY_DECLARE_METHOD)
#undef DK_PY_DECLARE_PART
#undef DK_PY_DECLARE_METHOD

#endif
