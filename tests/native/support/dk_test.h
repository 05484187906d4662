/* Minimal test harness for DeformKit's C tests: CHECK records a failure and continues,
 * DK_TEST_MAIN prints "N passed, N failed" and returns non-zero on any failure. */
#ifndef DK_TEST_H
#define DK_TEST_H

#include <math.h>
#include <stdio.h>

typedef struct dk_test_state {
    int passed, failed;
} dk_test_state;

extern dk_test_state dk_test_global_state; /* defined by DK_TEST_MAIN in each test program */

#define CHECK(cond)                                                                        \
    do {                                                                                   \
        if (cond) {                                                                        \
            dk_test_global_state.passed++;                                                 \
        } else {                                                                           \
            dk_test_global_state.failed++;                                                 \
            fprintf(stderr, "%s:%d: CHECK failed: %s\n", __FILE__, __LINE__, #cond);      \
        }                                                                                  \
    } while (0)

#define CHECK_MSG(cond, ...)                                                               \
    do {                                                                                   \
        if (cond) {                                                                        \
            dk_test_global_state.passed++;                                                 \
        } else {                                                                           \
            dk_test_global_state.failed++;                                                 \
            fprintf(stderr, "%s:%d: CHECK failed: %s: ", __FILE__, __LINE__, #cond);      \
            fprintf(stderr, __VA_ARGS__);                                                  \
            fprintf(stderr, "\n");                                                         \
        }                                                                                  \
    } while (0)

#define CHECK_NEAR(a, b, tol)                                                              \
    CHECK_MSG(fabs((double)(a) - (double)(b)) <= (tol), "%.17g vs %.17g (tol %g)",          \
              (double)(a), (double)(b), (double)(tol))

#define DK_TEST_MAIN(...)                                                                  \
    dk_test_state dk_test_global_state;                                                    \
    int main(void)                                                                         \
    {                                                                                      \
        void (*tests[])(void) = {__VA_ARGS__};                                             \
        for (size_t i = 0; i < sizeof tests / sizeof tests[0]; i++) tests[i]();            \
        printf("%d passed, %d failed\n", dk_test_global_state.passed,                      \
               dk_test_global_state.failed);                                               \
        return dk_test_global_state.failed ? 1 : 0;                                        \
    }

#endif
