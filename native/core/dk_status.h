/* DeformKit: status codes and error reporting.
 *
 * Every fallible function in the library returns a dk_status and, on failure, fills a
 * caller-owned dk_error with a human-readable message that names the problem precisely
 * ("face 12 index 2 is 5000, out of range [0, 4999]"). The library never aborts, exits or
 * prints. A NULL dk_error pointer is allowed everywhere: the message is then dropped.
 */
#ifndef DK_STATUS_H
#define DK_STATUS_H

#include <stdint.h>

#include <stddef.h>

#ifdef __cplusplus
extern "C" {
#endif

/** Result of a library call. DK_OK is zero; every failure is non-zero. */
typedef enum dk_status {
    DK_OK = 0,
    DK_ERR_INVALID_ARGUMENT = 1, /**< a NULL pointer, a negative size, an unknown option      */
    DK_ERR_OUT_OF_MEMORY = 2,    /**< an allocation failed; nothing was leaked               */
    DK_ERR_INDEX = 3,            /**< an index out of range (faces, constraint lists)        */
    DK_ERR_NONFINITE = 4,        /**< a NaN or infinite input value                          */
    DK_ERR_DEGENERATE = 5,       /**< degenerate geometry where the operation cannot cope    */
    DK_ERR_TOPOLOGY = 6,         /**< invalid or unsupported topology, or a change since bind */
    DK_ERR_NOT_POSITIVE_DEFINITE = 7, /**< Cholesky met a non positive definite matrix      */
    DK_ERR_NO_CONVERGENCE = 8,   /**< an iterative solver did not converge                   */
    DK_ERR_NUMERIC = 9,          /**< another numerical failure (LAPACK/ARPACK info != 0)    */
    DK_ERR_CANCELLED = 10,       /**< a progress callback asked to stop                      */
    DK_ERR_INTERNAL = 11         /**< a bug: a broken invariant inside the library           */
} dk_status;

/** Length of the message buffer, terminating NUL included. */
#define DK_ERROR_MESSAGE_SIZE 512

/** Caller-owned error report. Initialise with dk_error_clear() or `dk_error e = {0};`. */
typedef struct dk_error {
    dk_status status;                      /**< the failure, or DK_OK             */
    char message[DK_ERROR_MESSAGE_SIZE];   /**< NUL-terminated, never longer      */
    int64_t column;                        /**< 1 + the matrix column a numerical
                                                failure is about, 0 when none: for the
                                                caller to name its own vertex instead
                                                (dk_error_set resets it)           */
} dk_error;

/** Resets `err` (may be NULL) to DK_OK with an empty message. */
void dk_error_clear(dk_error *err);

/** Records `status` and a printf-style message in `err` (may be NULL) and returns `status`,
 *  so that a failing path can read `return dk_error_set(err, DK_ERR_INDEX, "...", ...);`.
 *  The message is truncated to DK_ERROR_MESSAGE_SIZE - 1 characters. */
dk_status dk_error_set(dk_error *err, dk_status status, const char *fmt, ...)
#if defined(__GNUC__)
    __attribute__((format(printf, 3, 4)))
#endif
    ;

/** Prepends "context: " to the message already in `err` (may be NULL); returns its status.
 *  Used when a lower layer's message needs the caller's context ("ARAP bind: ..."). */
dk_status dk_error_prefix(dk_error *err, const char *fmt, ...)
#if defined(__GNUC__)
    __attribute__((format(printf, 2, 3)))
#endif
    ;

/** A short constant name for a status ("out of memory"); never NULL. */
const char *dk_status_name(dk_status status);

/** Optional progress callback for long work (bind of a big mesh, many eigenpairs).
 *  `fraction` is in [0, 1]; returning non-zero asks the library to stop, and the call then
 *  fails with DK_ERR_CANCELLED. Called from the working thread: it must not call back into
 *  the library on the same object. */
typedef int (*dk_progress_fn)(void *user, double fraction);

#ifdef __cplusplus
}
#endif
#endif
