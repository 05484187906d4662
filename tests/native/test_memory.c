/* Tests of the memory guard (dk_memory.h) and the per-method estimates (dk_method.h):
 * the available memory follows an RLIMIT_AS set in a forked child, a need beyond it is
 * refused with the figures in the message, one within it is not; the estimates exist for
 * every method and grow with the mesh and with EigenDeformation's basis size. */
#define _GNU_SOURCE
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/resource.h>
#include <sys/wait.h>
#include <unistd.h>

#include "dk_eigen.h"
#include "dk_memory.h"
#include "dk_method.h"
#include "dk_test.h"
#include "dk_test_meshes.h"

static void test_query_without_limit(void)
{
    dk_memory_available a;
    dk_memory_query(&a);
    CHECK(a.bytes > 0);
    CHECK(a.bytes <= a.mem_available);
    CHECK(a.bytes <= a.address_space && a.bytes <= a.cgroup);
    CHECK(strlen(dk_memory_limit_name(a.limit)) > 0);
    dk_error err = {0};
    CHECK(dk_memory_check(1u << 20, "test", "one MiB", &err) == DK_OK);
    CHECK(dk_memory_check(UINT64_MAX / 4, "test", "everything", &err) == DK_ERR_OUT_OF_MEMORY);
    CHECK_MSG(strstr(err.message, "test: everything needs about") != NULL, "%s", err.message);
    CHECK_MSG(strstr(err.message, "refused before allocating") != NULL, "%s", err.message);
}

/* In a child (the limit must not stay on the test process): 0 when every check passed. */
static int limited_child(void)
{
    dk_memory_available a;
    dk_memory_query(&a);
    const uint64_t base = a.address_space; /* unlimited here */
    FILE *f = fopen("/proc/self/statm", "r");
    unsigned long long pages = 0;
    if (!f || fscanf(f, "%llu", &pages) != 1)
        return 10;
    fclose(f);
    const uint64_t used = pages * (uint64_t)sysconf(_SC_PAGESIZE);
    const uint64_t headroom = 512u << 20;
    struct rlimit rl = {used + headroom, used + headroom};
    if (base != UINT64_MAX || setrlimit(RLIMIT_AS, &rl) != 0)
        return 11;
    dk_memory_query(&a);
    if (a.limit != DK_MEMORY_RLIMIT_AS || a.address_space > headroom ||
        a.address_space < headroom - (64u << 20))
        return 12;
    dk_error err = {0};
    if (dk_memory_check(64u << 20, "t", "64 MiB", &err) != DK_OK)
        return 13;
    if (dk_memory_check(400u << 20, "t", "400 MiB", &err) != DK_ERR_OUT_OF_MEMORY ||
        !strstr(err.message, "RLIMIT_AS headroom") || !strstr(err.message, "needs about 400 MiB"))
        return 14; /* 400 MiB + the thread reserve (>= 192 MiB on 2 cores) exceed 512 MiB */
    return 0;
}

static void test_query_under_rlimit_as(void)
{
    pid_t pid = fork();
    if (pid == 0)
        _exit(limited_child());
    int status = 0;
    CHECK(pid > 0 && waitpid(pid, &status, 0) == pid);
    CHECK_MSG(WIFEXITED(status) && WEXITSTATUS(status) == 0, "child status %d", status);
}

static void test_estimates(void)
{
    dk_test_mesh small, big;
    CHECK(dk_test_grid(20, 1.0, 0.0, &small) == 0);
    CHECK(dk_test_grid(80, 1.0, 0.0, &big) == 0);
    dk_mesh *ms = dk_test_mesh_build(&small), *mb = dk_test_mesh_build(&big);
    CHECK(ms && mb);
    dk_error err = {0};
    int n_methods = 0;
    for (const dk_method_ops *const *m = dk_methods(); *m; m++, n_methods++) {
        uint64_t a = 0, b = 0;
        CHECK_MSG(dk_method_estimate_memory(*m, ms, NULL, &a, &err) == DK_OK, "%s: %s",
                  (*m)->name, err.message);
        CHECK(dk_method_estimate_memory(*m, mb, NULL, &b, &err) == DK_OK);
        CHECK_MSG(b > a && a > 0, "%s: %llu then %llu", (*m)->name, (unsigned long long)a,
                  (unsigned long long)b);
    }
    CHECK(n_methods == 13);
    dk_eigen_options o;
    dk_eigen_default_options(&o);
    uint64_t k20 = 0, k200 = 0;
    o.n_eigenvectors = 20;
    o.refine = 0;
    CHECK(dk_method_estimate_memory(dk_method_find("EigenDeformation"), mb, &o, &k20, &err) ==
          DK_OK);
    o.n_eigenvectors = 200;
    CHECK(dk_method_estimate_memory(dk_method_find("EigenDeformation"), mb, &o, &k200, &err) ==
          DK_OK);
    CHECK(k200 > k20);
    CHECK(dk_method_estimate_memory(NULL, mb, NULL, &k20, &err) == DK_ERR_INVALID_ARGUMENT);
    dk_mesh_free(ms);
    dk_mesh_free(mb);
    dk_test_mesh_free(&small);
    dk_test_mesh_free(&big);
}

DK_TEST_MAIN(test_query_without_limit, test_query_under_rlimit_as, test_estimates)
