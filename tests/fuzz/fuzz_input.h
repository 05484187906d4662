/* DeformKit fuzzing: reading structured values out of libFuzzer's bytes.
 *
 * A harness decodes its input front to back with these readers; past the end every reader
 * returns 0, so any input (the empty one included) decodes to something and short inputs
 * to small, simple cases. Values are drawn so that most of them are valid and the rest sit
 * on the boundaries the library must refuse (0, -1, NaN, Inf, 1e300, the limits of an int):
 * inputs then get past the first check and exercise bind and solve deeply, and mutations of
 * one byte move between the valid and the refused cases.
 *
 * dk_fuzz_check: a harness's own invariant (what the library promises on success or on
 * failure). A violation is a bug: it aborts, which libFuzzer reports as a crash with the
 * input saved, like a sanitizer report.
 */
#ifndef DK_FUZZ_INPUT_H
#define DK_FUZZ_INPUT_H

#include <float.h>
#include <limits.h>
#include <math.h>
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

typedef struct dk_fuzz_input {
    const uint8_t *data;
    size_t size, pos;
} dk_fuzz_input;

static inline dk_fuzz_input dk_fuzz_begin(const uint8_t *data, size_t size)
{
    dk_fuzz_input in = {data, size, 0};
    return in;
}

static inline size_t dk_fuzz_left(const dk_fuzz_input *in)
{
    return in->size - in->pos;
}

static inline uint8_t dk_fuzz_u8(dk_fuzz_input *in)
{
    return in->pos < in->size ? in->data[in->pos++] : 0;
}

static inline uint32_t dk_fuzz_u32(dk_fuzz_input *in)
{
    uint32_t v = 0;
    for (int i = 0; i < 4; i++)
        v |= (uint32_t)dk_fuzz_u8(in) << (8 * i);
    return v;
}

/* an integer in [0, n) (n >= 1) */
static inline int dk_fuzz_below(dk_fuzz_input *in, int n)
{
    if (n <= 256)
        return dk_fuzz_u8(in) % n;
    return (int)(dk_fuzz_u32(in) % (uint32_t)n);
}

/* a raw double from 8 bytes (any bit pattern: NaN, Inf, subnormals) */
static inline double dk_fuzz_raw_double(dk_fuzz_input *in)
{
    uint64_t b = 0;
    for (int i = 0; i < 8; i++)
        b |= (uint64_t)dk_fuzz_u8(in) << (8 * i);
    double d;
    memcpy(&d, &b, sizeof d);
    return d;
}

/* A real for an option or a weight: usually `usual` scaled by a small factor, sometimes a
 * boundary value. */
static inline double dk_fuzz_real(dk_fuzz_input *in, double usual)
{
    const uint8_t c = dk_fuzz_u8(in);
    switch (c % 16) {
    case 0: return 0.0;
    case 1: return -usual;
    case 2: return NAN;
    case 3: return INFINITY;
    case 4: return 1e300;
    case 5: return 1e-300;
    case 6: return DBL_MIN / 4; /* subnormal */
    case 7: return dk_fuzz_raw_double(in);
    default: return usual * (0.25 + (double)(c >> 4) / 4.0); /* 0.25 .. 4 x usual */
    }
}

/* An integer option: usually in [lo, hi] (hi - lo < 256), sometimes just outside or an
 * int's limit. With `huge_ok` 0 the value never exceeds hi + 1: for iteration counts, which
 * the library accepts up to INT_MAX and would then honour for minutes. */
static inline int dk_fuzz_int(dk_fuzz_input *in, int lo, int hi, int huge_ok)
{
    const uint8_t c = dk_fuzz_u8(in);
    switch (c % 16) {
    case 0: return lo > INT_MIN ? lo - 1 : lo;
    case 1: return hi < INT_MAX ? hi + 1 : hi;
    case 2: return INT_MIN;
    case 3: return huge_ok ? INT_MAX : hi;
    default: return lo + (int)(dk_fuzz_u8(in) % (unsigned)(hi - lo + 1));
    }
}

/* An enum option with `n` named values: a named one, or (one time in 16) one past them. */
static inline int dk_fuzz_enum(dk_fuzz_input *in, int n)
{
    const uint8_t c = dk_fuzz_u8(in);
    if (c % 16 == 15)
        return c & 16 ? n : -1;
    return c % n;
}

#define dk_fuzz_check(cond, ...)                                                          \
    do {                                                                                  \
        if (!(cond)) {                                                                    \
            fprintf(stderr, "fuzz invariant failed at %s:%d: %s: ", __FILE__, __LINE__,   \
                    #cond);                                                               \
            fprintf(stderr, __VA_ARGS__);                                                 \
            fprintf(stderr, "\n");                                                        \
            abort();                                                                      \
        }                                                                                 \
    } while (0)

#endif
