/* DeformKit: the one contract every deformation method implements.
 *
 * A method is a bound object with two verbs, as in libigl's precompute/solve pairs:
 *   bind   (precompute, seconds on big meshes): mesh + constraint description + the method's
 *          own typed options -> an object holding factorizations and buffers;
 *   solve  (per update, allocation-free): a dk_solve_request -> n_vertices x 3 positions and
 *          one dk_solve_info.
 * plus rebind (new constraints, same mesh and options, reusing what it can; on failure the
 * object keeps its previous constraints), energy (of arbitrary positions), stats (counters)
 * and free. Each method fills one dk_method_ops table with these (Blender's ModifierTypeInfo
 * is the model), so that code written against the contract -- the generic tests, the
 * Python binding -- works for every method registered in dk_methods().
 *
 * The request follows CHOLMOD's short form over a full form: a zero-initialised request with
 * only `targets` set, `(dk_solve_request){.targets = t}`, is the common case (handle
 * positions, a cold start, the bound iteration cap, the energy reported); the other fields
 * can grow without changing any signature. Options stay typed per method (dk_arap_options,
 * ...); the ops table takes them as `const void *`, NULL meaning the defaults.
 */
#ifndef DK_METHOD_H
#define DK_METHOD_H

#include "dk_constraints.h"
#include "dk_controls.h"
#include "dk_mesh.h"
#include "dk_status.h"
#include <stddef.h>
#include <stdint.h>

#ifdef __cplusplus
extern "C" {
#endif

/** What `targets` holds. */
typedef enum dk_target_kind {
    DK_TARGETS_POSITIONS = 0,  /**< n_handle_vertices x 3 positions, concatenated in handle
                                    order                                                  */
    DK_TARGETS_TRANSFORMS = 1  /**< n_handles 4x4 row-major affine transforms of the rest
                                    positions of each handle's vertices (bottom row
                                    0 0 0 1); see dk_constraints_targets                   */
} dk_target_kind;

/** Where an iterative method starts. Direct methods give the same result for each. */
typedef enum dk_start {
    DK_START_COLD = 0,   /**< from the rest state only: the result depends on this request
                              alone (frames, renders, bakes)                               */
    DK_START_WARM = 1,   /**< from the previous solution when there is one (dragging)      */
    DK_START_RESUME = 2, /**< when the targets equal the previous request's and it ended
                              normally: continue exactly where it stopped, so that a solve
                              cut into slices by max_iterations equals one long solve;
                              otherwise as WARM                                            */
    DK_START_GIVEN = 3   /**< from request->start_positions (a coarse level's prolonged
                              result, a cached frame, another method's output) with the
                              constrained vertices put in place: the result depends on
                              this request alone, as for COLD. A method whose iterate is
                              not the positions (EmbeddedDeformation: node transforms)
                              refuses it                                                   */
} dk_start;

/** One solve. Zero-initialise, then set what differs from the defaults. */
typedef struct dk_solve_request {
    const double *targets;      /**< see target_kind; must not be NULL                     */
    dk_target_kind target_kind; /**< default DK_TARGETS_POSITIONS                          */
    dk_start start;             /**< default DK_START_COLD                                 */
    int max_iterations;         /**< > 0 overrides the bound option for this call; 0 keeps
                                     it (direct methods ignore it)                         */
    int skip_energy;            /**< 1: do not evaluate the energy (info.energy is NaN), for
                                     interactive updates that never show it                */
    int preview;                /**< 1: the fastest result the method can show while the
                                     handle moves, not its full solve: ARAP its start (the
                                     previous solution plus the global step's response,
                                     no iterations: info.iterations 0), EigenDeformation
                                     Steps 1-2 (dk_eigen.h); the other methods' solves are
                                     already their fastest and ignore it. A later request
                                     with start RESUME and the same targets continues
                                     from the preview                                      */
    const double *start_positions; /**< start DK_START_GIVEN: n_vertices x 3, row-major, in
                                     the mesh's vertex order, finite; must be NULL for the
                                     other starts                                          */
    const double *input_positions; /**< NULL (the default): the method edits the bind's
                                     rest. Else n_vertices x 3, row-major, in the mesh's
                                     vertex order, finite: this frame's input (an
                                     Armature's pose), which the method edits as if it
                                     were the rest: fixed and held vertices stay there,
                                     transforms act on the handle vertices' input
                                     positions, and targets equal to the input give the
                                     input. Only methods with DK_METHOD_EDITS_INPUT take
                                     it (dk_solve_request_check refuses it otherwise). What
                                     the bind precomputed from the rest (weights,
                                     factorizations) is kept: the method's header says what
                                     follows the input                                     */
} dk_solve_request;

/** What one solve did. Fields a method does not have are 0. */
typedef struct dk_solve_info {
    double energy;      /**< the method's energy at the returned positions (its header says
                             which); NaN when the request skipped it                       */
    int iterations;     /**< iterations done (1 for a direct method)                       */
    int converged;      /**< 1 if the method's stopping test held (always for direct ones) */
    int rejected;       /**< ARAP: accelerated steps rejected by the safeguard             */
    int predicted;      /**< ARAP: 1 if the warm start extrapolated along the drag         */
    int cg_iterations;  /**< ARAP Newton: Hessian products done in all                     */
    double last_change; /**< Laplacian editing, local frames: max vertex move of the last
                             iteration / bounding-box diagonal                             */
} dk_solve_info;

/** Counters every method reports; a method may have more of its own. */
typedef struct dk_method_stats {
    dk_index n_vertices;         /**< of the bound mesh                                     */
    dk_index n_handles;          /**< of the current constraints                            */
    dk_index n_handle_vertices;  /**< of the current constraints                            */
    dk_index n_unknowns;         /**< size of the factored system (0 for direct methods)    */
    int analysis_count;          /**< symbolic analyses since bind                          */
    int factorization_count;     /**< numeric factorizations since bind                     */
    dk_index n_held;             /**< vertices held at rest because no handle or fixed
                                      vertex is in their connected component (loose
                                      geometry, dk_constraints.h)                          */
    dk_index n_held_components;  /**< the components they make up                          */
    dk_index first_held;         /**< the smallest held vertex, -1 when none                */
    dk_index n_controls;         /**< points of the control a method binds to (lattice
                                      points, cage vertices: dk_controls.h), 0 for the
                                      vertex-group methods                                 */
    dk_index n_graph_nodes;      /**< nodes of the deformation graph (embedded deformation),
                                      0 for methods without one; more nodes than vertices
                                      make a floppy graph (docs/methods/embedded.md)       */
} dk_method_stats;

/** Fills the held-vertex counters of `stats` from the method's constraints (NULL: none).
 *  `to_caller` maps the constraints' vertex numbering to the caller's (a method that binds
 *  on its own numbering passes its dk_reorder perm), NULL when they are the same, so that
 *  first_held names the caller's vertex. */
void dk_constraints_held_stats(const dk_constraints *c, const dk_index *to_caller,
                               dk_method_stats *stats);

/** What a method's results depend on, for code that is written against the contract. */
typedef enum dk_method_flags {
    DK_METHOD_ITERATIVE = 1,               /**< request.start and max_iterations matter    */
    DK_METHOD_TRANSFORMS_AS_POSITIONS = 2, /**< a transform gives the result of the
                                                positions it maps the handle to (else only
                                                translations do: Falloff blends transforms
                                                per vertex)                                */
    DK_METHOD_TRANSLATION_INVARIANT = 4,   /**< translating every constraint by t (handles,
                                                and fixed vertices' rest) translates the
                                                result by t                                */
    DK_METHOD_RIGID_INVARIANT = 8,         /**< the same for every rigid motion (ARAP; naive
                                                Laplacian editing does not rotate details) */
    DK_METHOD_PENALTY_HANDLES = 16,        /**< handles are penalty terms, met to the
                                                solver's tolerance rather than exactly
                                                (embedded deformation); fixed vertices are
                                                still exact                               */
    DK_METHOD_SOFT_REGIONS = 32,           /**< handles are regions that guide a smooth
                                                least-squares fit (eigen deformation): met
                                                approximately, and every vertex outside them
                                                is held approximately, fixed or not; a
                                                handle covering the whole mesh moves it
                                                exactly                                   */
    DK_METHOD_GIVEN_START = 64,            /**< iterative, and its iterate is the positions:
                                                DK_START_GIVEN starts there (ARAP). Direct
                                                methods ignore that start; iterative ones
                                                without this flag refuse it               */
    DK_METHOD_EDITS_INPUT = 128,           /**< takes request.input_positions: edits the
                                                pose it is given for this frame, without
                                                binding again                             */
    DK_METHOD_GRAPH = 256,                 /**< deforms through a graph of its own, whose
                                                nodes stats.n_graph_nodes counts           */
    DK_METHOD_LINEAR_PRECISION = 512,      /**< binds to a control (dk_controls.h) and an
                                                affine map of the control's points moves
                                                every vertex by that map, with the method's
                                                default options (a lattice, a cage with
                                                mean value coordinates; not a cage with
                                                Green ones, nor Shepard's interpolation)   */
    DK_METHOD_DYNAMIC = 1024,              /**< simulates in time (shape matching): a cold
                                                solve resets the simulation to this
                                                request, at rest; each warm or resumed solve
                                                advances it one frame, so that a frame's
                                                result depends on the frames before it (its
                                                state); played in order from a cold start,
                                                checkpointed by save_state                 */
    DK_METHOD_INTERIOR = 2048              /**< solves for points the positions do not
                                                carry too (a volume's interior: volumetric
                                                ARAP): a given start rebuilds them from
                                                the positions, so a start at its own result
                                                takes a few steps more than one            */
} dk_method_flags;

/** What one field of a method's options struct holds (dk_option_desc). */
typedef enum dk_option_type {
    DK_OPTION_INT = 0,        /**< int                                                     */
    DK_OPTION_DOUBLE = 1,     /**< double                                                  */
    DK_OPTION_ENUM = 2,       /**< an enum (int-sized): the values min .. max              */
    DK_OPTION_SEED = 3,       /**< uint64_t, every value valid                             */
    DK_OPTION_VERTICES = 4,   /**< const dk_index * at offset, its length (dk_index) at
                                   count_offset: vertex indices of the bound mesh          */
    DK_OPTION_EDGE_VALUES = 5, /**< const double * at offset, its length (dk_index) at
                                   count_offset, which must be the mesh's edge count: one
                                   value per edge in [min, max]                            */
    DK_OPTION_VERTEX_VALUES = 6 /**< as EDGE_VALUES, one value per vertex (NULL: none) */
} dk_option_type;

/** dk_option_desc.flags */
enum {
    DK_OPTION_LENGTH = 1,   /**< a length in the mesh's units: `usual` is a fraction of the
                                 bounding-box diagonal                                    */
    DK_OPTION_ZERO_AUTO = 2 /**< 0 is also valid (and means "automatic" or "none"), below
                                 or outside [min, max]                                    */
};

/** One field of a method's options struct, for code written against the contract (the
 *  fuzzer, the generic tests) that fills or checks options without knowing the method. */
typedef struct dk_option_desc {
    const char *name;     /**< the field's name, as the Python keyword                      */
    dk_option_type type;
    size_t offset;        /**< offsetof(options struct, field)                              */
    size_t count_offset;  /**< VERTICES, EDGE_VALUES, VERTEX_VALUES: offsetof the length field; else 0     */
    double min, max;      /**< the valid values, inclusive (a bind refuses the others)      */
    double usual;         /**< a typical valid value (LENGTH: a fraction of the diagonal)   */
    double quick_max;     /**< INT: the largest value that keeps a bind and a solve quick
                               (iteration counts, node counts; tests and fuzzers); else max */
    unsigned flags;       /**< DK_OPTION_LENGTH, DK_OPTION_ZERO_AUTO                        */
} dk_option_desc;

/** The functions of one method; every entry is set. `self` is the method's object. */
typedef struct dk_method_ops {
    const char *name;  /**< the class name, as in the Python module ("ARAP", ...)          */
    unsigned flags;    /**< dk_method_flags                                                 */
    unsigned controls; /**< the dk_control_kind bits its bind takes: DK_CONTROL_VERTEX_GROUPS
                            (handles of dk_constraint_desc) and/or a control's kind
                            (dk_constraint_desc.control); a bind refuses the others by name */
    size_t options_size; /**< sizeof the method's options struct                            */
    /** Fills an options struct (options_size bytes) with the method's defaults. */
    void (*default_options)(void *options);
    const dk_option_desc *option_fields; /**< every field a caller sets, in the struct's
                                              order (the progress hook below excepted)     */
    int n_option_fields;
    /** Where the bind's progress hook lives in the options struct: a dk_phase_progress_fn
     *  at progress_offset and its user pointer (void *) at progress_user_offset. */
    size_t progress_offset, progress_user_offset;
    /** Binds: `options` is the method's own options struct, or NULL for the defaults. The
     *  mesh is borrowed and must outlive the object. */
    dk_status (*bind)(const dk_mesh *mesh, const dk_constraint_desc *constraints,
                      const void *options, void **out, dk_error *err);
    /** New constraints, same mesh and options; on failure nothing changes. */
    dk_status (*rebind)(void *self, const dk_constraint_desc *constraints, dk_error *err);
    /** Writes positions (n_vertices x 3, row-major) and info (may be NULL). */
    dk_status (*solve)(void *self, const dk_solve_request *request, double *positions,
                       dk_solve_info *info, dk_error *err);
    /** The method's energy of arbitrary positions (n_vertices x 3) for the targets of the
     *  last solve (before any solve: the rest targets). */
    dk_status (*energy)(const void *self, const double *positions, double *energy,
                        dk_error *err);
    void (*stats)(const void *self, dk_method_stats *stats);
    void (*free)(void *self);
    /** The bytes a bind on `mesh` with `options` (NULL: the defaults) needs at its peak, its
     *  first solve included (dk_method_estimate_memory). */
    dk_status (*estimate_memory)(const dk_mesh *mesh, const void *options, uint64_t *bytes,
                                 dk_error *err);
    /** State (optional: all three NULL for a method whose solves read nothing an earlier
     *  call left behind). What a solve leaves for the next call -- a warm start's iterate
     *  and history, a resumable solve's place, the pose and targets it solved -- as bytes,
     *  so that a bake can checkpoint and a chunk can start mid-shot, in this object or in
     *  another bound the same way. state_size: the bytes save_state writes (fixed while the
     *  constraints are). restore_state takes a state saved by an object of the same method
     *  on the same mesh size, constraints and options (a dk_state_header says which; any
     *  other, or a wrong size, is DK_ERR_INVALID_ARGUMENT and nothing changes); every call
     *  after it then returns, bit for bit, what it returned right after the save. The
     *  contract test checks this for every method that has them. */
    size_t (*state_size)(const void *self);
    dk_status (*save_state)(const void *self, void *state, size_t size, dk_error *err);
    dk_status (*restore_state)(void *self, const void *state, size_t size, dk_error *err);
} dk_method_ops;

/** Every registered method, in a fixed order, terminated by NULL. Adding a method adds its
 *  table here (methods.c). */
const dk_method_ops *const *dk_methods(void);

/** Defines `const dk_method_ops VAR` for a method whose public functions follow the
 *  contract's names and argument order: PREFIX_bind(mesh, constraints, const OPTS *, TYPE **,
 *  err), PREFIX_rebind, PREFIX_solve, PREFIX_energy, PREFIX_stats, PREFIX_free,
 *  PREFIX_estimate_memory(mesh, const OPTS *, uint64_t *bytes, err) and
 *  PREFIX_default_options(OPTS *), where TYPE is the method's object and OPTS its options
 *  struct, whose bind progress hook is the fields `progress` and `progress_user`. The
 *  generated adapters only convert `void *` to those types, so the table cannot drift from
 *  the typed functions. FIELDS: a static array of the options' dk_option_desc. Use it once,
 *  at file scope, after the functions are declared; NAME, FLAGS and CONTROLS as in
 *  dk_method_ops. */
#define DK_METHOD_OPS(VAR, NAME, FLAGS, CONTROLS, PREFIX, TYPE, OPTS, FIELDS)                 \
    DK_METHOD_OPS_WITH(VAR, NAME, FLAGS, CONTROLS, PREFIX, TYPE, OPTS, FIELDS, .free = VAR##_free)

/** DK_METHOD_OPS for a method that carries state (dk_method_ops.state_size): its
 *  PREFIX_state_size(const TYPE *), PREFIX_save_state(const TYPE *, void *, size_t, err)
 *  and PREFIX_restore_state(TYPE *, const void *, size_t, err) fill the three entries. */
#define DK_METHOD_OPS_STATEFUL(VAR, NAME, FLAGS, CONTROLS, PREFIX, TYPE, OPTS, FIELDS)        \
    static size_t VAR##_state_size(const void *self)                                          \
    {                                                                                         \
        return PREFIX##_state_size((const TYPE *)self);                                        \
    }                                                                                         \
    static dk_status VAR##_save_state(const void *self, void *state, size_t size,             \
                                      dk_error *err)                                          \
    {                                                                                         \
        return PREFIX##_save_state((const TYPE *)self, state, size, err);                      \
    }                                                                                         \
    static dk_status VAR##_restore_state(void *self, const void *state, size_t size,          \
                                         dk_error *err)                                       \
    {                                                                                         \
        return PREFIX##_restore_state((TYPE *)self, state, size, err);                         \
    }                                                                                         \
    DK_METHOD_OPS_WITH(VAR, NAME, FLAGS, CONTROLS, PREFIX, TYPE, OPTS, FIELDS,                 \
                       .free = VAR##_free, .state_size = VAR##_state_size,                    \
                       .save_state = VAR##_save_state, .restore_state = VAR##_restore_state)

/* The shared part of DK_METHOD_OPS and DK_METHOD_OPS_STATEFUL; the trailing designated
 * initializers (at least .free) end the table. */
#define DK_METHOD_OPS_WITH(VAR, NAME, FLAGS, CONTROLS, PREFIX, TYPE, OPTS, FIELDS, ...)        \
    static void VAR##_default_options(void *options)                                          \
    {                                                                                         \
        PREFIX##_default_options((OPTS *)options);                                             \
    }                                                                                         \
    static dk_status VAR##_bind(const dk_mesh *mesh, const dk_constraint_desc *c,              \
                                const void *options, void **out, dk_error *err)                \
    {                                                                                         \
        return PREFIX##_bind(mesh, c, (const OPTS *)options, (TYPE **)out, err);               \
    }                                                                                         \
    static dk_status VAR##_rebind(void *self, const dk_constraint_desc *c, dk_error *err)      \
    {                                                                                         \
        return PREFIX##_rebind((TYPE *)self, c, err);                                          \
    }                                                                                         \
    static dk_status VAR##_solve(void *self, const dk_solve_request *rq, double *positions,   \
                                 dk_solve_info *info, dk_error *err)                          \
    {                                                                                         \
        return PREFIX##_solve((TYPE *)self, rq, positions, info, err);                         \
    }                                                                                         \
    static dk_status VAR##_energy(const void *self, const double *positions, double *energy,  \
                                  dk_error *err)                                              \
    {                                                                                         \
        return PREFIX##_energy((const TYPE *)self, positions, energy, err);                    \
    }                                                                                         \
    static void VAR##_stats(const void *self, dk_method_stats *stats)                         \
    {                                                                                         \
        PREFIX##_stats((const TYPE *)self, stats);                                             \
    }                                                                                         \
    static void VAR##_free(void *self)                                                        \
    {                                                                                         \
        PREFIX##_free((TYPE *)self);                                                           \
    }                                                                                         \
    static dk_status VAR##_estimate_memory(const dk_mesh *mesh, const void *options,          \
                                           uint64_t *bytes, dk_error *err)                    \
    {                                                                                         \
        return PREFIX##_estimate_memory(mesh, (const OPTS *)options, bytes, err);              \
    }                                                                                         \
    const dk_method_ops VAR = {.name = NAME,                                                  \
                               .flags = FLAGS,                                                \
                               .controls = CONTROLS,                                          \
                               .options_size = sizeof(OPTS),                                  \
                               .default_options = VAR##_default_options,                      \
                               .option_fields = FIELDS,                                       \
                               .n_option_fields = (int)(sizeof FIELDS / sizeof FIELDS[0]),    \
                               .progress_offset = offsetof(OPTS, progress),                   \
                               .progress_user_offset = offsetof(OPTS, progress_user),         \
                               .bind = VAR##_bind,                                            \
                               .rebind = VAR##_rebind,                                        \
                               .solve = VAR##_solve,                                          \
                               .energy = VAR##_energy,                                        \
                               .stats = VAR##_stats,                                          \
                               .estimate_memory = VAR##_estimate_memory,                      \
                               __VA_ARGS__}

/** The registered method called `name`, or NULL. */
const dk_method_ops *dk_method_find(const char *name);

/** Checks the parts of a request every method checks the same way: a non-NULL request and
 *  targets, known target kind and start, start_positions given exactly for DK_START_GIVEN,
 *  max_iterations >= 0. `who` prefixes the message ("ARAP solve"). */
dk_status dk_solve_request_check(const dk_solve_request *request, const char *who,
                                 dk_error *err);

/** dk_solve_request_check for a method with DK_METHOD_EDITS_INPUT: the same checks, and
 *  input_positions (when given, n_vertices x 3) every coordinate finite and within
 *  DK_COORD_MAX (dk_check_positions: DK_ERR_NONFINITE naming the first bad vertex).
 *  dk_solve_request_check itself refuses input_positions, so that a method that does not
 *  edit an input never ignores one silently. */
dk_status dk_solve_request_check_input(const dk_solve_request *request, dk_index n_vertices,
                                       const char *who, dk_error *err);

/** Checks a DK_START_GIVEN request's start_positions (n_vertices x 3): every coordinate
 *  finite (DK_ERR_NONFINITE naming the first bad vertex otherwise). A method that starts
 *  from them calls it before it changes anything. */
dk_status dk_start_positions_check(const double *start_positions, dk_index n_vertices,
                                   const char *who, dk_error *err);

/** Checks a solve's result before it is returned: every position finite, and the energy
 *  finite unless `check_energy` is 0 (the request skipped it: NaN by contract). Every
 *  method's solve ends with it, so that no solve returns NaN or Inf without an error
 *  (DK_ERR_NONFINITE, naming the first bad vertex, or saying that the energy overflowed
 *  while the positions are finite, with the remedy). `who` prefixes the message. */
dk_status dk_solve_result_check(const double *positions, dk_index n_vertices, double energy,
                                int check_energy, const char *who, dk_error *err);

/** What a saved state begins with (dk_method_ops.save_state): the method's name and the
 *  shape of the object it was saved from (the method's own numbers: vertices, constrained
 *  vertices, unknowns, options that size its buffers), so that a restore into anything
 *  else is refused by name. Stored byte for byte at the start of the state; the state
 *  itself may sit at any alignment (Python bytes). */
typedef struct dk_state_header {
    char magic[8];        /**< "DKSTATE1"                                                  */
    char method[32];      /**< the method's name, NUL-padded                               */
    uint64_t shape[4];    /**< the method's numbers, 0 where unused                        */
    uint64_t payload;     /**< the bytes after the header                                  */
} dk_state_header;

/** One run of bytes of a method's state (its iterate, a counter): save and restore walk
 *  the same list, so that they cannot disagree on what the state holds. */
typedef struct dk_state_span {
    void *data;
    size_t bytes;
} dk_state_span;

/** sizeof(dk_state_header) plus the spans' bytes: a method's state_size. */
size_t dk_state_size(const dk_state_span *spans, int n_spans);

/** Writes the header for `method` and `shape`, then the spans, into `state` of `size`
 *  bytes (DK_ERR_INVALID_ARGUMENT, nothing written, unless size is dk_state_size). */
dk_status dk_state_save(const char *method, const uint64_t shape[4], const dk_state_span *spans,
                        int n_spans, void *state, size_t size, dk_error *err);

/** Checks that `state` (`size` bytes) was saved by `method` for `shape` with these spans'
 *  sizes, naming what differs (another method, another mesh size or constraints, a
 *  truncated buffer) as DK_ERR_INVALID_ARGUMENT. dk_state_restore_spans then copies it in;
 *  a method restores what must be set first (a pose) between the two. */
dk_status dk_state_check(const char *method, const uint64_t shape[4],
                         const dk_state_span *spans, int n_spans, const void *state,
                         size_t size, dk_error *err);

/** Copies a checked state's spans back into place. */
void dk_state_restore_spans(const dk_state_span *spans, int n_spans, const void *state);

/** The sum over `n` vertices of |positions - base|^2 (both n x 3): the squared
 *  displacement, the energy of the direct space deformations (Lattice, Cage). */
double dk_displacement_energy(const double *positions, const double *base, dk_index n);

/** The end of a direct method's solve whose energy is the squared displacement from `base`:
 *  that energy (NaN when the request skips it), dk_solve_result_check, and `info` (may be
 *  NULL) filled with iterations 1 and converged 1. `who` prefixes the messages. */
dk_status dk_direct_solve_finish(const double *positions, const double *base, dk_index n,
                                 const dk_solve_request *request, const char *who,
                                 dk_solve_info *info, dk_error *err);

/** The energy() of a direct space deformation (Lattice, Cage, Shepard, Skinning): the
 *  squared displacement of `positions` from `base` (both n x 3), checked as
 *  dk_energy_result_check does, into *energy. `who` prefixes the messages ("Cage energy");
 *  DK_ERR_INVALID_ARGUMENT for NULL arguments. */
dk_status dk_displacement_energy_result(const double *positions, const double *base,
                                        dk_index n, const char *who, double *energy,
                                        dk_error *err);

/** Checks an energy value before energy() returns it (DK_ERR_NONFINITE when not finite). */
dk_status dk_energy_result_check(double energy, const char *who, dk_error *err);

#ifdef __cplusplus
}
#endif
/** The memory (bytes) a bind of method `ops` on `mesh` with `options` (the method's options
 *  struct, or NULL for its defaults) needs at its peak, including its first solve: each
 *  method's own model (ops->estimate_memory, next to the method), fitted to measured peak
 *  RSS (the ratios are in docs/benchmarks.md), read through dk_memory_model. Each reads the
 *  vertex count and, where they change the size, the options (EigenDeformation's basis
 *  size, EmbeddedDeformation's node count and k). A Cholesky factor is modelled (fill ~ n
 *  log n) and checked exactly from the symbolic analysis (nnz(L)) before the numeric
 *  factorization. DK_ERR_INVALID_ARGUMENT for NULL arguments. */
dk_status dk_method_estimate_memory(const dk_method_ops *ops, const dk_mesh *mesh,
                                    const void *options, uint64_t *bytes, dk_error *err);

/** The bytes of a bind whose measured peak is `per_vertex` bytes per vertex over
 *  `n_vertices` plus `extra` bytes, with the margin every model carries (25%) and the small
 *  per-object tables (8 MiB). For the methods' estimate_memory. */
uint64_t dk_memory_model(double per_vertex, double n_vertices, double extra);

#endif
