/* DeformKit: progress reports and cancellation of long work in named phases (binds).
 *
 * A method's bind is a sequence of phases (renumbering, cells, assembly, factorization, ...)
 * of very different costs. A dk_progress reporter turns "phase k, a part p of its work done"
 * into one fraction of the whole from fixed phase weights (the method measures its phases
 * and writes the weights next to them), calls the caller's dk_phase_progress_fn with the
 * phase's name and that fraction, and turns a non-zero return into DK_ERR_CANCELLED. The
 * fractions a reporter passes never decrease, lie in [0, 1], and end at exactly 1
 * (dk_progress_done). Inside long loops dk_progress_tick asks the callback only every
 * DK_PROGRESS_TICK calls, so that a loop over a million vertices calls it a few dozen times.
 *
 * A reporter without a callback (fn NULL), and a NULL reporter, do nothing and never cancel,
 * so a method calls them unconditionally. It is the caller's: no allocation, no global state. */
#ifndef DK_PROGRESS_H
#define DK_PROGRESS_H

#include "dk_status.h"

#ifdef __cplusplus
extern "C" {
#endif

/** Progress with the phase's name: `phase` is a short constant lower-case name ("factorize")
 *  valid for the call only, `fraction` of the whole work in [0, 1]. Returning non-zero asks
 *  the work to stop: the call then fails with DK_ERR_CANCELLED and changes nothing. Called
 *  from the working thread; it must not call back into the library on the same object. */
typedef int (*dk_phase_progress_fn)(void *user, const char *phase, double fraction);

/** One phase: its name and its weight (> 0, any unit: the weights are normalised). */
typedef struct dk_progress_phase {
    const char *name;
    double weight;
} dk_progress_phase;

/** How many dk_progress_tick calls pass between two questions to the callback. */
#define DK_PROGRESS_TICK 8192

/** A reporter; set up with dk_progress_init, read its fields through the functions only. */
typedef struct dk_progress {
    dk_phase_progress_fn fn;
    void *user;
    const dk_progress_phase *phases;
    int n_phases;
    int phase;          /* current phase, -1 before the first                               */
    double total;       /* sum of the weights                                               */
    double start, span; /* the current phase's share of the whole: [start, start + span]     */
    double last;        /* the last fraction reported                                       */
    unsigned ticks;     /* dk_progress_tick calls since the last question                   */
    const char *who;    /* prefix of the cancellation message ("ARAP bind")                 */
} dk_progress;

/** Sets up `p` for the `n_phases` phases (a static table the caller keeps alive), reporting
 *  to `fn(user, ...)` (fn may be NULL: no reports, no cancellation). `who` prefixes the
 *  DK_ERR_CANCELLED message. */
void dk_progress_init(dk_progress *p, dk_phase_progress_fn fn, void *user,
                      const dk_progress_phase *phases, int n_phases, const char *who);

/** Enters phase `k` (0 <= k < n_phases; phases may be skipped, never revisited) and reports
 *  its start. Returns DK_ERR_CANCELLED ("<who>: cancelled in phase <name>") when the callback
 *  asks to stop, else DK_OK. */
dk_status dk_progress_begin(dk_progress *p, int k, dk_error *err);

/** Reports that `part` (clamped to [0, 1]) of the current phase is done and asks the
 *  callback; DK_ERR_CANCELLED as dk_progress_begin. */
dk_status dk_progress_part(dk_progress *p, double part, dk_error *err);

/** For the body of a long loop: every DK_PROGRESS_TICK calls, dk_progress_part(p, done /
 *  total); otherwise only a counter increment. */
dk_status dk_progress_tick(dk_progress *p, double done, double total, dk_error *err);

/** Reports 1 (the whole work done) with the phase name "done". The work is complete: a
 *  request to stop is ignored here (the result is already whole). */
void dk_progress_done(dk_progress *p);

#ifdef __cplusplus
}
#endif
#endif
