/* DeformKit: two-way data parallelism for per-vertex passes.
 *
 * The target machines have two cores and a pass over 10^4..10^6 vertices (frames, right-hand
 * sides, energies) is memory-light enough to scale. A pass is split at a point that depends
 * only on its length, each half writes only its own outputs (per-part partial results are
 * combined by the caller in part order), so results are bit-for-bit the same whether or not
 * the helper thread ran. No global state: the helper is started and joined per call. */
#ifndef DK_PARALLEL_H
#define DK_PARALLEL_H

#include "dk_mesh.h"

/** A range task: processes items [begin, end) as part `part` (0 = the first half, 1 = the
 *  second) of the pass described by ctx. */
typedef void (*dk_range_fn)(void *ctx, dk_index begin, dk_index end, int part);

/** Runs fn(ctx, 0, n/2, 0) on the calling thread and fn(ctx, n/2, n, 1) on a helper thread
 *  when n >= min_parallel; otherwise, or when no thread can be started, both on the calling
 *  thread, part 0 first. Always two parts with the same split, so the caller may combine
 *  part results in order and get the same answer either way. n may be 0. Never fails. */
void dk_run_halves(dk_range_fn fn, void *ctx, dk_index n, dk_index min_parallel);

#endif
