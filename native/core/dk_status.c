#include "dk_status.h"

#include <stdarg.h>
#include <stdio.h>
#include <string.h>

void dk_error_clear(dk_error *err)
{
    if (!err) return;
    err->status = DK_OK;
    err->message[0] = '\0';
    err->column = 0;
}

dk_status dk_error_set(dk_error *err, dk_status status, const char *fmt, ...)
{
    if (!err) return status;
    err->status = status;
    err->column = 0;
    va_list ap;
    va_start(ap, fmt);
    vsnprintf(err->message, sizeof err->message, fmt, ap);
    va_end(ap);
    return status;
}

dk_status dk_error_prefix(dk_error *err, const char *fmt, ...)
{
    if (!err) return DK_ERR_INTERNAL;
    char prefix[DK_ERROR_MESSAGE_SIZE];
    char old[DK_ERROR_MESSAGE_SIZE];
    va_list ap;
    va_start(ap, fmt);
    vsnprintf(prefix, sizeof prefix, fmt, ap);
    va_end(ap);
    memcpy(old, err->message, sizeof old);
    old[sizeof old - 1] = '\0';
    /* "prefix: old", cut to the buffer (prefix first; the old message's tail goes). Assembled
     * by hand so the intended truncation is explicit rather than a snprintf warning. */
    size_t cap = sizeof err->message - 1;
    size_t lp = strlen(prefix);
    if (lp > cap) lp = cap;
    memcpy(err->message, prefix, lp);
    size_t at = lp;
    for (const char *sep = ": "; *sep && at < cap; sep++) err->message[at++] = *sep;
    size_t lo = strlen(old);
    if (lo > cap - at) lo = cap - at;
    memcpy(err->message + at, old, lo);
    err->message[at + lo] = '\0';
    return err->status;
}

const char *dk_status_name(dk_status status)
{
    switch (status) {
    case DK_OK: return "ok";
    case DK_ERR_INVALID_ARGUMENT: return "invalid argument";
    case DK_ERR_OUT_OF_MEMORY: return "out of memory";
    case DK_ERR_INDEX: return "index out of range";
    case DK_ERR_NONFINITE: return "non-finite value";
    case DK_ERR_DEGENERATE: return "degenerate geometry";
    case DK_ERR_TOPOLOGY: return "invalid topology";
    case DK_ERR_NOT_POSITIVE_DEFINITE: return "matrix not positive definite";
    case DK_ERR_NO_CONVERGENCE: return "no convergence";
    case DK_ERR_NUMERIC: return "numerical failure";
    case DK_ERR_CANCELLED: return "cancelled";
    case DK_ERR_INTERNAL: return "internal error";
    }
    return "unknown status";
}
