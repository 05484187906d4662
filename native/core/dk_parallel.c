/* DeformKit: two-way data parallelism (see dk_parallel.h). */
#include "dk_parallel.h"

#include <pthread.h>

typedef struct half_job {
    dk_range_fn fn;
    void *ctx;
    dk_index begin, end;
} half_job;

static void *run_half(void *arg)
{
    const half_job *j = arg;
    j->fn(j->ctx, j->begin, j->end, 1);
    return NULL;
}

void dk_run_halves(dk_range_fn fn, void *ctx, dk_index n, dk_index min_parallel)
{
    const dk_index mid = n / 2;
    half_job job = {fn, ctx, mid, n};
    pthread_t th;
    int started = 0;
    if (n < 0)
        return;
    if (n >= min_parallel && n >= 2)
        started = pthread_create(&th, NULL, run_half, &job) == 0;
    fn(ctx, 0, mid, 0);
    if (started)
        pthread_join(th, NULL);
    else
        fn(ctx, mid, n, 1);
}
