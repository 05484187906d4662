/* DeformKit: two-way data parallelism for per-vertex passes.
 *
 * The target machines have two cores and a pass over 10^4..10^6 vertices (frames, right-hand
 * sides, energies) is memory-light enough to scale. A pass is split at a point that depends
 * only on its length, each half writes only its own outputs (per-part partial results are
 * combined by the caller in part order), so results are bit-for-bit the same whether or not
 * the helper thread ran. No global state.
 *
 * Two ways to run a pass: dk_run_halves starts and joins a helper thread per call (~40 us on
 * the 2-core test VM, idle), and a team (dk_team) keeps one helper thread per solver object
 * that waits for the next pass, spinning briefly and then sleeping, so a hand-off costs a few
 * microseconds. A drag step of Laplacian editing runs ~6 passes and a Newton step of ARAP ~40:
 * methods own a team and pass it to every pass of their solves. */
#ifndef DK_PARALLEL_H
#define DK_PARALLEL_H

#include "dk_mesh.h"

/** A range task: processes items [begin, end) as part `part` (0 = the first half, 1 = the
 *  second) of the pass described by ctx. */
typedef void (*dk_range_fn)(void *ctx, dk_index begin, dk_index end, int part);

/** Runs fn(ctx, 0, n/2, 0) on the calling thread and fn(ctx, n/2, n, 1) on a helper thread
 *  when n >= min_parallel; otherwise, when no thread can be started, or when the calling
 *  thread's CPU affinity allows one CPU only (taskset, cpusets, a farm binding one core per
 *  task), both on the calling thread, part 0 first. Always two parts with the same split, so the caller may combine
 *  part results in order and get the same answer either way. n may be 0. Never fails. */
void dk_run_halves(dk_range_fn fn, void *ctx, dk_index n, dk_index min_parallel);

/** The calling thread plus one persistent helper thread (with all signals blocked). */
typedef struct dk_team dk_team;

/** Starts a team. Returns NULL when its helper thread or its synchronisation objects cannot
 *  be created, or when the calling thread may run on one CPU only; NULL is a valid team for every function below (passes then run through
 *  dk_run_halves). */
dk_team *dk_team_create(void);

/** Like dk_run_halves, with part 1 on the team's helper thread. Falls back to dk_run_halves
 *  when team is NULL, when another pass is running on the team (a nested or concurrent call:
 *  one caller at a time gets the helper), and in a child process forked after the team was
 *  created (the helper thread does not exist there). Never fails. */
void dk_team_run_halves(dk_team *team, dk_range_fn fn, void *ctx, dk_index n,
                        dk_index min_parallel);

/** Lets the helper sleep now instead of spinning for the next pass (~0.3 ms): call at the end
 *  of a solve, so that the helper does not take a core from whatever the application does
 *  next. The next pass wakes it (a futex wake, ~10 us). NULL is fine. */
void dk_team_park(dk_team *team);

/** Stops and joins the helper and frees the team (NULL is fine). No pass may be running. */
void dk_team_free(dk_team *team);

/** Call in a child process just after fork(), on the thread that forked (the only thread of
 *  the child): makes every OpenMP parallel region this thread starts from now on run on this
 *  thread alone. CHOLMOD runs its supernodal loops in OpenMP teams; GNU libgomp keeps the
 *  team of threads a thread led in its thread-local state and reuses it, so in a forked child
 *  the forking thread's next parallel region hands work to threads that exist only in the
 *  parent (a crash in GOMP_parallel or a hang). With the thread's max-active-levels ICV at 0
 *  (a per-thread OpenMP setting, not a DeformKit global) its regions run on one thread and
 *  never touch that team; threads the child creates later start clean teams and keep full
 *  parallelism. CHOLMOD's OpenMP loops are its light ones (the heavy work is BLAS, whose
 *  OpenBLAS pool has its own fork handler), so the cost is small. Does nothing when no
 *  OpenMP runtime is loaded in the process. Never fails. */
void dk_openmp_after_fork_child(void);

/** The most OpenMP runtimes a scope handles (CHOLMOD's, and others a host loaded). */
#define DK_OPENMP_MAX_RUNTIMES 4

/** A scope in which the OpenMP parallel regions the calling thread starts run on it alone. */
typedef struct dk_openmp_serial {
    int n;                                        /**< runtimes whose setting begin changed */
    void *handle[DK_OPENMP_MAX_RUNTIMES];         /**< each one's handle, open until end    */
    int saved_levels[DK_OPENMP_MAX_RUNTIMES];     /**< and its max-active-levels before     */
} dk_openmp_serial;

/** Below this many CPUs for the calling thread, dk_openmp_serial_begin serialises. Debian's
 *  CHOLMOD runs its supernodal factorization's OpenMP regions (copies and assembly into each
 *  front, O(front rows) each) on CHOLMOD_OMP_NUM_THREADS = 4 threads; with fewer CPUs libgomp
 *  waits 100 spins instead of 300,000 and then sleeps on a futex, so each of the many small
 *  regions costs wake-ups (perf: 45% of a 2,640-unknown factorization in the kernel's
 *  scheduler). Measured on the 2-core VM (docs/benchmarks.md, "CHOLMOD's OpenMP regions"):
 *  serial regions are faster at every size tried, 43k to 692k vertices, and cut an
 *  EmbeddedDeformation iteration by a third. With 4 or more CPUs the regions are left as
 *  they are (not measured). */
#define DK_OPENMP_SERIAL_BELOW_CPUS 4

/** Begins such a scope when the calling thread may run on fewer than
 *  DK_OPENMP_SERIAL_BELOW_CPUS CPUs: in each OpenMP runtime loaded in the process (found by
 *  file name, so also the copy a wheel bundles under another name) whose max-active-levels
 *  for this thread is above 0, sets it to 0, saving it in `s`. In libgomp from GCC 11 on (and
 *  in the copies DeformKit ships, Debian 12's GCC 12) that setting is the calling thread's
 *  own; older ones keep it process-wide, so there the scope serialises other threads'
 *  regions too while it lasts. BLAS threads are not affected (OpenBLAS's pool is its own).
 *  Never fails. */
void dk_openmp_serial_begin(dk_openmp_serial *s);

/** Ends the scope begun by dk_openmp_serial_begin(s) on the same thread: restores each
 *  changed runtime's setting (and only those). */
void dk_openmp_serial_end(const dk_openmp_serial *s);

#endif
