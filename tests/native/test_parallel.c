/* Tests of dk_run_halves: every item is processed exactly once, by the part the split
 * assigns it to, for empty, tiny, odd and large ranges, with and without the helper thread;
 * the two parts really run at the same time when the helper is used. */
#include <stdatomic.h>
#include <stdlib.h>
#include <string.h>

#include "dk_parallel.h"
#include "dk_test.h"

typedef struct count_job {
    unsigned char *hits; /* per item: 1 + part that processed it */
    int calls[2];
    dk_index begin[2], end[2];
} count_job;

static void count_items(void *ctx, dk_index b, dk_index e, int part)
{
    count_job *j = ctx;
    j->calls[part]++;
    j->begin[part] = b;
    j->end[part] = e;
    for (dk_index i = b; i < e; i++)
        j->hits[i] = (unsigned char)(j->hits[i] + 1 + part);
}

static void test_every_item_once(void)
{
    const dk_index sizes[] = {0, 1, 2, 3, 7, 8191, 8192, 100001};
    for (size_t s = 0; s < sizeof sizes / sizeof sizes[0]; s++)
        for (int threaded = 0; threaded < 2; threaded++) {
            const dk_index n = sizes[s];
            count_job j;
            memset(&j, 0, sizeof j);
            j.hits = calloc((size_t)n + 1, 1);
            CHECK(j.hits != NULL);
            if (!j.hits)
                return;
            dk_run_halves(count_items, &j, n, threaded ? 2 : n + 1);
            CHECK(j.calls[0] == 1 && j.calls[1] == 1);
            CHECK(j.begin[0] == 0 && j.end[0] == n / 2 && j.begin[1] == n / 2 && j.end[1] == n);
            for (dk_index i = 0; i < n; i++)
                CHECK(j.hits[i] == (i < n / 2 ? 1 : 2));
            free(j.hits);
        }
}

/* Each part waits (bounded) for the other to start: only concurrent parts both see it. */
typedef struct meet_job {
    atomic_int arrived;
    int saw_other[2];
} meet_job;

static void meet(void *ctx, dk_index b, dk_index e, int part)
{
    meet_job *j = ctx;
    (void)b;
    (void)e;
    atomic_fetch_add(&j->arrived, 1);
    for (long spin = 0; spin < 2000000000L; spin++)
        if (atomic_load(&j->arrived) == 2) {
            j->saw_other[part] = 1;
            return;
        }
}

static void test_parts_run_concurrently(void)
{
    meet_job j;
    atomic_init(&j.arrived, 0);
    j.saw_other[0] = j.saw_other[1] = 0;
    dk_run_halves(meet, &j, 10, 2);
    /* if the helper could not be started part 0 times out alone: then both ran serially */
    CHECK(j.saw_other[0] == j.saw_other[1]);
    CHECK(j.saw_other[1] == 1);
}

DK_TEST_MAIN(test_every_item_once, test_parts_run_concurrently)
