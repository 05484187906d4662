/* DeformKit: two-way data parallelism (see dk_parallel.h). */
#define _GNU_SOURCE /* RTLD_NOLOAD; includes POSIX 2008 */
#include "dk_parallel.h"

#include <dlfcn.h>
#include <link.h>
#include <pthread.h>
#include <sched.h>
#include <signal.h>
#include <stdatomic.h>
#include <stdlib.h>
#include <string.h>
#include <time.h>
#include <unistd.h>

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

/* 1 when the calling thread may run on one CPU only (taskset, a cpuset, a farm's binding of
 * one core per task): a helper thread would only take turns with it there, its spinning
 * taking the caller's time. 0 when it may run on more, or when the mask cannot be read. */
static int cpus(void)
{
    cpu_set_t set;
    if (sched_getaffinity(0, sizeof set, &set) != 0)
        return 0;
    return CPU_COUNT(&set);
}

static int one_cpu(void)
{
    const int k = cpus();
    return k > 0 && k < 2;
}

void dk_run_halves(dk_range_fn fn, void *ctx, dk_index n, dk_index min_parallel)
{
    const dk_index mid = n / 2;
    half_job job = {fn, ctx, mid, n};
    pthread_t th;
    int started = 0;
    if (n < 0)
        return;
    if (n >= min_parallel && n >= 2 && !one_cpu())
        started = pthread_create(&th, NULL, run_half, &job) == 0;
    fn(ctx, 0, mid, 0);
    if (started)
        pthread_join(th, NULL);
    else
        fn(ctx, mid, n, 1);
}

/* ------------------------------------------------------------------ teams --------------- */

/* How long the helper spins for the next pass before sleeping, and the caller for the
 * helper's half before sleeping. Passes of one solve follow each other within tens to
 * hundreds of microseconds (the serial work between them); a futex wake-up costs ~10 us. */
#define HELPER_SPIN_NS 300000L
#define CALLER_SPIN_NS 200000L

struct dk_team {
    pthread_t thread;
    pthread_mutex_t mu;
    pthread_cond_t wake;     /* the helper waits here for a pass                  */
    pthread_cond_t finished; /* the caller waits here for the helper's half       */
    atomic_uint gen;         /* number of passes posted (bumped under mu)         */
    atomic_uint done;        /* number of passes whose helper half has finished    */
    atomic_int busy;         /* a caller holds the team                           */
    atomic_int park;         /* sleep after the current pass instead of spinning  */
    int helper_sleeping;     /* under mu */
    int caller_waiting;      /* under mu */
    int quit;                /* under mu */
    pid_t pid;               /* process that owns the helper thread               */
    half_job job;            /* written before gen is bumped, read after          */
};

static inline void cpu_relax(void)
{
#if defined(__x86_64__) || defined(__i386__)
    __builtin_ia32_pause();
#elif defined(__aarch64__)
    __asm__ __volatile__("yield");
#endif
}

static long elapsed_ns(const struct timespec *t0)
{
    struct timespec t;
    clock_gettime(CLOCK_MONOTONIC, &t);
    return (long)(t.tv_sec - t0->tv_sec) * 1000000000L + (t.tv_nsec - t0->tv_nsec);
}

static void *helper_main(void *arg)
{
    dk_team *t = arg;
    unsigned seen = 0;
    for (;;) {
        unsigned g = atomic_load_explicit(&t->gen, memory_order_acquire);
        if (g == seen && !atomic_load_explicit(&t->park, memory_order_relaxed)) {
            struct timespec t0;
            clock_gettime(CLOCK_MONOTONIC, &t0);
            while (g == seen && !atomic_load_explicit(&t->park, memory_order_relaxed)) {
                for (int k = 0; k < 64; k++)
                    cpu_relax();
                g = atomic_load_explicit(&t->gen, memory_order_acquire);
                if (g == seen && elapsed_ns(&t0) > HELPER_SPIN_NS)
                    break;
            }
        }
        if (g == seen) {
            int quit;
            pthread_mutex_lock(&t->mu);
            while ((g = atomic_load_explicit(&t->gen, memory_order_acquire)) == seen &&
                   !t->quit) {
                t->helper_sleeping = 1;
                pthread_cond_wait(&t->wake, &t->mu);
                t->helper_sleeping = 0;
            }
            quit = t->quit;
            pthread_mutex_unlock(&t->mu);
            if (g == seen && quit)
                return NULL;
        }
        seen = g;
        t->job.fn(t->job.ctx, t->job.begin, t->job.end, 1);
        atomic_store_explicit(&t->done, g, memory_order_release);
        pthread_mutex_lock(&t->mu);
        if (t->caller_waiting)
            pthread_cond_signal(&t->finished);
        pthread_mutex_unlock(&t->mu);
    }
}

dk_team *dk_team_create(void)
{
    dk_team *t = calloc(1, sizeof *t);
    int have_mu = 0, have_wake = 0, have_fin = 0, started = 0;
    if (!t)
        return NULL;
    if (one_cpu()) { /* no helper: every pass runs on the caller (dk_run_halves) */
        free(t);
        return NULL;
    }
    atomic_init(&t->gen, 0u);
    atomic_init(&t->done, 0u);
    atomic_init(&t->busy, 0);
    atomic_init(&t->park, 0);
    t->pid = getpid();
    have_mu = pthread_mutex_init(&t->mu, NULL) == 0;
    have_wake = have_mu && pthread_cond_init(&t->wake, NULL) == 0;
    have_fin = have_wake && pthread_cond_init(&t->finished, NULL) == 0;
    if (have_fin) {
        /* the helper blocks every signal: they go to the application's own threads */
        sigset_t all, old;
        sigfillset(&all);
        const int masked = pthread_sigmask(SIG_SETMASK, &all, &old) == 0;
        started = pthread_create(&t->thread, NULL, helper_main, t) == 0;
        if (masked)
            pthread_sigmask(SIG_SETMASK, &old, NULL);
    }
    if (started)
        return t;
    if (have_fin)
        pthread_cond_destroy(&t->finished);
    if (have_wake)
        pthread_cond_destroy(&t->wake);
    if (have_mu)
        pthread_mutex_destroy(&t->mu);
    free(t);
    return NULL;
}

void dk_team_run_halves(dk_team *t, dk_range_fn fn, void *ctx, dk_index n,
                        dk_index min_parallel)
{
    if (n < 0)
        return;
    if (!t || n < min_parallel || n < 2) {
        dk_run_halves(fn, ctx, n, min_parallel);
        return;
    }
    if (t->pid != getpid() || atomic_exchange(&t->busy, 1)) {
        dk_run_halves(fn, ctx, n, min_parallel);
        return;
    }
    const dk_index mid = n / 2;
    t->job = (half_job){fn, ctx, mid, n};
    pthread_mutex_lock(&t->mu);
    const unsigned g = atomic_load_explicit(&t->gen, memory_order_relaxed) + 1u;
    atomic_store_explicit(&t->park, 0, memory_order_relaxed);
    atomic_store_explicit(&t->gen, g, memory_order_release);
    if (t->helper_sleeping)
        pthread_cond_signal(&t->wake);
    pthread_mutex_unlock(&t->mu);

    fn(ctx, 0, mid, 0);

    if (atomic_load_explicit(&t->done, memory_order_acquire) != g) {
        struct timespec t0;
        clock_gettime(CLOCK_MONOTONIC, &t0);
        while (atomic_load_explicit(&t->done, memory_order_acquire) != g) {
            for (int k = 0; k < 16; k++)
                cpu_relax();
            if (elapsed_ns(&t0) > CALLER_SPIN_NS) {
                pthread_mutex_lock(&t->mu);
                while (atomic_load_explicit(&t->done, memory_order_acquire) != g) {
                    t->caller_waiting = 1;
                    pthread_cond_wait(&t->finished, &t->mu);
                    t->caller_waiting = 0;
                }
                pthread_mutex_unlock(&t->mu);
                break;
            }
        }
    }
    atomic_store_explicit(&t->busy, 0, memory_order_release);
}

void dk_team_park(dk_team *t)
{
    if (t)
        atomic_store_explicit(&t->park, 1, memory_order_relaxed);
}

void dk_team_free(dk_team *t)
{
    if (!t)
        return;
    if (t->pid == getpid()) {
        atomic_store_explicit(&t->park, 1, memory_order_relaxed); /* stop spinning now */
        pthread_mutex_lock(&t->mu);
        t->quit = 1;
        pthread_cond_signal(&t->wake);
        pthread_mutex_unlock(&t->mu);
        pthread_join(t->thread, NULL);
        pthread_cond_destroy(&t->finished);
        pthread_cond_destroy(&t->wake);
        pthread_mutex_destroy(&t->mu);
    }
    /* in a forked child the helper does not exist and the mutex may have been copied in any
     * state: free the memory only */
    free(t);
}

/* The OpenMP runtimes loaded in the process. They are looked up, not linked: whatever the
 * process's CHOLMOD was built with (libgomp on Linux), under its own name or under the one
 * auditwheel gives the copy it bundles into a wheel (libgomp-<hash>.so.1.0.0), and any other
 * a host application loaded. The names are collected first and opened after the walk (no
 * dlopen while dl_iterate_phdr holds the loader's lock). */
typedef struct runtime_names {
    int n;
    char name[DK_OPENMP_MAX_RUNTIMES][512];
} runtime_names;

static int is_runtime(const char *path)
{
    static const char *const prefixes[] = {"libgomp.", "libgomp-", "libomp.", "libomp-",
                                           "libiomp5.", "libiomp5-"};
    const char *base = strrchr(path, '/');
    base = base ? base + 1 : path;
    for (size_t k = 0; k < sizeof prefixes / sizeof prefixes[0]; k++)
        if (strncmp(base, prefixes[k], strlen(prefixes[k])) == 0)
            return 1;
    return 0;
}

static int collect_runtime(struct dl_phdr_info *info, size_t size, void *ctx)
{
    (void)size;
    runtime_names *r = ctx;
    if (info->dlpi_name && info->dlpi_name[0] && is_runtime(info->dlpi_name) &&
        r->n < DK_OPENMP_MAX_RUNTIMES && strlen(info->dlpi_name) < sizeof r->name[0])
        strcpy(r->name[r->n++], info->dlpi_name);
    return 0;
}

/* Handles of the loaded runtimes (up to DK_OPENMP_MAX_RUNTIMES; dlclose each). */
static int open_runtimes(void *handle[DK_OPENMP_MAX_RUNTIMES])
{
    runtime_names r;
    r.n = 0;
    dl_iterate_phdr(collect_runtime, &r);
    int n = 0;
    for (int k = 0; k < r.n; k++) {
        void *h = dlopen(r.name[k], RTLD_LAZY | RTLD_NOLOAD);
        if (h)
            handle[n++] = h;
    }
    return n;
}

/* The runtime `h`'s setter and getter of max-active-levels, or NULL (object to function
 * pointer by memcpy). */
static void (*set_fn(void *h))(int)
{
    void *sym = dlsym(h, "omp_set_max_active_levels");
    void (*f)(int) = NULL;
    if (sym)
        memcpy(&f, &sym, sizeof f);
    return f;
}

static int (*get_fn(void *h))(void)
{
    void *sym = dlsym(h, "omp_get_max_active_levels");
    int (*f)(void) = NULL;
    if (sym)
        memcpy(&f, &sym, sizeof f);
    return f;
}

void dk_openmp_after_fork_child(void)
{
    void *h[DK_OPENMP_MAX_RUNTIMES];
    const int n = open_runtimes(h);
    for (int k = 0; k < n; k++) {
        void (*set_levels)(int) = set_fn(h[k]);
        if (set_levels)
            set_levels(0);
        dlclose(h[k]);
    }
}

void dk_openmp_serial_begin(dk_openmp_serial *s)
{
    s->n = 0;
    const int k = cpus();
    if (k <= 0 || k >= DK_OPENMP_SERIAL_BELOW_CPUS)
        return;
    void *h[DK_OPENMP_MAX_RUNTIMES];
    const int n = open_runtimes(h);
    for (int r = 0; r < n; r++) {
        void (*set_levels)(int) = set_fn(h[r]);
        int (*get_levels)(void) = get_fn(h[r]);
        const int saved = set_levels && get_levels ? get_levels() : 0;
        if (saved <= 0) { /* already serial (a forked child, the caller's choice), or no
                             such functions: left as it is */
            dlclose(h[r]);
            continue;
        }
        set_levels(0);
        s->handle[s->n] = h[r]; /* kept open until the end restores it */
        s->saved_levels[s->n++] = saved;
    }
}

void dk_openmp_serial_end(const dk_openmp_serial *s)
{
    for (int r = 0; r < s->n; r++) {
        set_fn(s->handle[r])(s->saved_levels[r]);
        dlclose(s->handle[r]);
    }
}
