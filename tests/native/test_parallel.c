/* Tests of dk_run_halves and of teams (dk_team_run_halves): every item is processed exactly
 * once, by the part the split assigns it to, for empty, tiny, odd and large ranges, with and
 * without the helper thread; the two parts really run at the same time when the helper is
 * used; a team survives many passes back to back, passes after parking (the helper asleep),
 * nested passes (which must not deadlock) and a fork (the child has no helper); a thread
 * bound to one CPU gets no helper at all (every part on the caller); a serial OpenMP scope
 * (dk_openmp_serial_begin/end) serialises the calling thread's regions on few CPUs only,
 * restores the thread's setting and leaves other threads' alone. */
#define _GNU_SOURCE /* sched_setaffinity, RTLD_NOLOAD; includes POSIX 2008 */
#include <dlfcn.h>
#include <pthread.h>
#include <sched.h>
#include <stdatomic.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/wait.h>
#include <time.h>
#include <unistd.h>

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

/* Every item once, by the part the split assigns it to: through dk_run_halves (mode 0) or
 * dk_team_run_halves on `team` (mode 1; team may be NULL), with and without a helper. */
static void check_every_item_once(int mode, dk_team *team)
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
            if (mode)
                dk_team_run_halves(team, count_items, &j, n, threaded ? 2 : n + 1);
            else
                dk_run_halves(count_items, &j, n, threaded ? 2 : n + 1);
            CHECK(j.calls[0] == 1 && j.calls[1] == 1);
            CHECK(j.begin[0] == 0 && j.end[0] == n / 2 && j.begin[1] == n / 2 && j.end[1] == n);
            for (dk_index i = 0; i < n; i++)
                CHECK(j.hits[i] == (i < n / 2 ? 1 : 2));
            free(j.hits);
        }
}

static void test_every_item_once(void)
{
    check_every_item_once(0, NULL);
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

static void test_team_every_item_once(void)
{
    dk_team *team = dk_team_create();
    CHECK(team != NULL);
    check_every_item_once(1, team);
    check_every_item_once(1, NULL);
    dk_team_free(team);
    dk_team_free(NULL);
    dk_team_park(NULL);
}

static void test_team_parts_run_concurrently(void)
{
    dk_team *team = dk_team_create();
    CHECK(team != NULL);
    for (int round = 0; round < 3; round++) {
        meet_job j;
        atomic_init(&j.arrived, 0);
        j.saw_other[0] = j.saw_other[1] = 0;
        if (round == 2)
            dk_team_park(team);
        dk_team_run_halves(team, meet, &j, 10, 2);
        CHECK_MSG(j.saw_other[0] == 1 && j.saw_other[1] == 1, "round %d", round);
    }
    dk_team_free(team);
}

/* Part sums of many short passes back to back, with parks and sleeps in between (the helper
 * spinning, going to sleep by itself, parked): each pass's result must be complete when
 * dk_team_run_halves returns. */
typedef struct sum_job {
    const int *v;
    long part[2];
} sum_job;

static void sum_items(void *ctx, dk_index b, dk_index e, int part)
{
    sum_job *j = ctx;
    long s = 0;
    for (dk_index i = b; i < e; i++)
        s += j->v[i];
    j->part[part] = s;
}

static void test_team_many_passes(void)
{
    enum { N = 4099 };
    int *v = malloc(sizeof(int) * N);
    CHECK(v != NULL);
    if (!v)
        return;
    long want = 0;
    for (int i = 0; i < N; i++) {
        v[i] = (i * 7919) % 1013 - 500;
        want += v[i];
    }
    dk_team *team = dk_team_create();
    CHECK(team != NULL);
    int bad = 0;
    for (int pass = 0; pass < 20000; pass++) {
        sum_job j = {v, {-1, -1}};
        if (pass % 1000 == 999)
            dk_team_park(team);
        if (pass % 5000 == 4999) { /* longer than the helper spins: it sleeps by itself */
            struct timespec ts = {0, 2000000};
            nanosleep(&ts, NULL);
        }
        dk_team_run_halves(team, sum_items, &j, N, 2);
        bad += j.part[0] + j.part[1] != want;
    }
    CHECK_MSG(bad == 0, "%d of 20000 passes were incomplete", bad);
    dk_team_free(team);
    free(v);
}

/* A pass whose parts run passes on the same team (e.g. a solve called from a callback): the
 * inner passes cannot get the helper and must fall back instead of waiting for it. */
typedef struct nested_job {
    dk_team *team;
    count_job inner[2];
    unsigned char hits[2][101];
} nested_job;

static void nested_outer(void *ctx, dk_index b, dk_index e, int part)
{
    nested_job *j = ctx;
    (void)b;
    (void)e;
    j->inner[part].hits = j->hits[part];
    dk_team_run_halves(j->team, count_items, &j->inner[part], 101, 2);
}

static void test_team_nested(void)
{
    nested_job j;
    memset(&j, 0, sizeof j);
    j.team = dk_team_create();
    CHECK(j.team != NULL);
    dk_team_run_halves(j.team, nested_outer, &j, 2, 2);
    for (int p = 0; p < 2; p++) {
        CHECK(j.inner[p].calls[0] == 1 && j.inner[p].calls[1] == 1);
        for (int i = 0; i < 101; i++)
            CHECK(j.hits[p][i] == (i < 50 ? 1 : 2));
    }
    dk_team_free(j.team);
}

/* After fork() the child has the team's memory but not its helper thread: passes must still
 * run (on a started thread or serially) and freeing must not wait for the missing helper. */
static void test_team_after_fork(void)
{
    dk_team *team = dk_team_create();
    CHECK(team != NULL);
    unsigned char hits[1000];
    count_job j;
    memset(&j, 0, sizeof j);
    memset(hits, 0, sizeof hits);
    j.hits = hits;
    dk_team_run_halves(team, count_items, &j, 1000, 2); /* the helper exists and has run */
    const pid_t pid = fork();
    CHECK(pid >= 0);
    if (pid == 0) {
        count_job c;
        unsigned char h[1000];
        memset(&c, 0, sizeof c);
        memset(h, 0, sizeof h);
        c.hits = h;
        alarm(20); /* a hang becomes a failure */
        dk_team_run_halves(team, count_items, &c, 1000, 2);
        int ok = c.calls[0] == 1 && c.calls[1] == 1;
        for (int i = 0; i < 1000; i++)
            ok = ok && h[i] == (i < 500 ? 1 : 2);
        dk_team_free(team);
        _exit(ok ? 0 : 3);
    }
    int status = 0;
    CHECK(pid > 0 && waitpid(pid, &status, 0) == pid);
    CHECK_MSG(WIFEXITED(status) && WEXITSTATUS(status) == 0, "child status %d", status);
    dk_team_free(team);
}

/* Bound to one CPU (as taskset or a farm's one-core binding does), the caller runs both parts
 * itself: no team helper, no started thread. Run in a child process, so the binding ends
 * with it. */
typedef struct who_job {
    pthread_t caller;
    int parts_on_caller;
} who_job;

static void record_thread(void *ctx, dk_index b, dk_index e, int part)
{
    (void)b, (void)e, (void)part;
    who_job *j = ctx;
    if (pthread_equal(pthread_self(), j->caller))
        j->parts_on_caller++;
}

static void test_one_cpu_no_helper(void)
{
    const pid_t pid = fork();
    CHECK(pid >= 0);
    if (pid == 0) {
        cpu_set_t one;
        CPU_ZERO(&one);
        const int cpu = sched_getcpu();
        CPU_SET(cpu < 0 ? 0 : cpu, &one);
        if (sched_setaffinity(0, sizeof one, &one) != 0)
            _exit(4);
        alarm(20);
        who_job j = {pthread_self(), 0};
        dk_run_halves(record_thread, &j, 1000, 2);
        int ok = j.parts_on_caller == 2;
        dk_team *team = dk_team_create();
        ok = ok && team == NULL;
        j.parts_on_caller = 0;
        dk_team_run_halves(team, record_thread, &j, 1000, 2);
        ok = ok && j.parts_on_caller == 2;
        _exit(ok ? 0 : 3);
    }
    int status = 0;
    CHECK(pid > 0 && waitpid(pid, &status, 0) == pid);
    CHECK_MSG(WIFEXITED(status) && WEXITSTATUS(status) == 0, "child status %d", status);
    /* and where this thread may use two CPUs or more, the second part runs on a helper */
    cpu_set_t mine;
    if (sched_getaffinity(0, sizeof mine, &mine) == 0 && CPU_COUNT(&mine) >= 2) {
        who_job j = {pthread_self(), 0};
        dk_run_halves(record_thread, &j, 1000, 2);
        CHECK_MSG(j.parts_on_caller == 1, "%d parts on the caller", j.parts_on_caller);
    }
}

/* libgomp's per-thread max-active-levels. This program does not link CHOLMOD, so it loads
 * the runtime itself (as CHOLMOD's users have it loaded); the handle stays open. */
typedef struct omp_fns {
    int (*get)(void);
    void (*set)(int);
} omp_fns;

static int omp_fns_of(void *h, omp_fns *f)
{
    void *g = h ? dlsym(h, "omp_get_max_active_levels") : NULL;
    void *s = h ? dlsym(h, "omp_set_max_active_levels") : NULL;
    if (!g || !s)
        return 0;
    memcpy(&f->get, &g, sizeof f->get); /* object to function pointers */
    memcpy(&f->set, &s, sizeof f->set);
    return 1;
}

static int omp_lookup(omp_fns *f)
{
    return omp_fns_of(dlopen("libgomp.so.1", RTLD_NOW), f);
}

/* a copy of the runtime `f` came from, saved as `path` and loaded (a wheel's bundled copy) */
static int omp_copy(const omp_fns *f, omp_fns *g, const char *path)
{
    Dl_info info;
    void *sym;
    memcpy(&sym, &f->get, sizeof sym); /* function to object pointer */
    if (!dladdr(sym, &info) || !info.dli_fname)
        return 0;
    FILE *in = fopen(info.dli_fname, "rb"), *out = fopen(path, "wb");
    int ok = in && out;
    char buf[65536];
    size_t n;
    while (ok && (n = fread(buf, 1, sizeof buf, in)) > 0)
        ok = fwrite(buf, 1, n, out) == n;
    if (in)
        fclose(in);
    if (out && fclose(out) != 0)
        ok = 0;
    void *h = ok ? dlopen(path, RTLD_NOW | RTLD_LOCAL) : NULL;
    unlink(path);
    return omp_fns_of(h, g);
}

typedef struct levels_job {
    omp_fns f;
    atomic_int stage; /* 1: the other thread is in its scope; 2: it may end it */
    int inside, after;
} levels_job;

static void *scope_on_other_thread(void *arg)
{
    levels_job *j = arg;
    j->f.set(3);
    dk_openmp_serial s;
    dk_openmp_serial_begin(&s);
    j->inside = j->f.get();
    atomic_store(&j->stage, 1);
    while (atomic_load(&j->stage) != 2)
        sched_yield();
    dk_openmp_serial_end(&s);
    j->after = j->f.get();
    return NULL;
}

static void test_openmp_serial_scope(void)
{
    omp_fns f;
    const int have = omp_lookup(&f);
    CHECK_MSG(have, "libgomp.so.1 (CHOLMOD's OpenMP runtime) cannot be loaded: %s", dlerror());
    if (!have)
        return;
    /* on one CPU (a forked child bound to one): serial inside, restored after; and a second
     * copy of the runtime under a wheel's name (libgomp-<hash>.so...) found and restored on
     * its own, a runtime already at 0 left so */
    const pid_t pid = fork();
    if (pid == 0) {
        cpu_set_t one;
        CPU_ZERO(&one);
        CPU_SET(0, &one);
        if (sched_setaffinity(0, sizeof one, &one) != 0)
            _exit(4);
        f.set(5);
        dk_openmp_serial s;
        dk_openmp_serial_begin(&s);
        int ok = s.n == 1 && f.get() == 0;
        dk_openmp_serial_end(&s);
        ok = ok && f.get() == 5;
        omp_fns g;
        char path[64];
        snprintf(path, sizeof path, "/tmp/libgomp-dk%ld.so.1.0.0", (long)getpid());
        if (!omp_copy(&f, &g, path))
            _exit(5);
        g.set(0); /* the copy already serial: left so */
        dk_openmp_serial_begin(&s);
        ok = ok && s.n == 1 && f.get() == 0 && g.get() == 0;
        dk_openmp_serial_end(&s);
        ok = ok && f.get() == 5 && g.get() == 0;
        g.set(7);
        dk_openmp_serial_begin(&s);
        ok = ok && s.n == 2 && f.get() == 0 && g.get() == 0;
        dk_openmp_serial_end(&s);
        ok = ok && f.get() == 5 && g.get() == 7;
        _exit(ok ? 0 : 3);
    }
    int status = 0;
    CHECK(pid > 0 && waitpid(pid, &status, 0) == pid);
    CHECK_MSG(WIFEXITED(status) && WEXITSTATUS(status) == 0, "child status %d", status);
    /* here: another thread's scope leaves this thread's setting alone */
    cpu_set_t mine;
    const int few = sched_getaffinity(0, sizeof mine, &mine) == 0 &&
                    CPU_COUNT(&mine) < DK_OPENMP_SERIAL_BELOW_CPUS;
    const int before = f.get();
    f.set(4);
    levels_job j = {f, 0, -1, -1};
    pthread_t th;
    CHECK(pthread_create(&th, NULL, scope_on_other_thread, &j) == 0);
    while (atomic_load(&j.stage) != 1)
        sched_yield();
    CHECK_MSG(f.get() == 4, "this thread's levels %d during the other's scope", f.get());
    atomic_store(&j.stage, 2);
    CHECK(pthread_join(th, NULL) == 0);
    CHECK_MSG(j.inside == (few ? 0 : 3), "levels %d inside the scope", j.inside);
    CHECK_MSG(j.after == 3, "levels %d after the scope", j.after);
    f.set(before);
}

DK_TEST_MAIN(test_every_item_once, test_parts_run_concurrently, test_team_every_item_once,
             test_team_parts_run_concurrently, test_team_many_passes, test_team_nested,
             test_team_after_fork, test_one_cpu_no_helper, test_openmp_serial_scope)
