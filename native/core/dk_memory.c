/* DeformKit: available memory and the refusal of binds that do not fit (see dk_memory.h). */
#define _GNU_SOURCE
#include "dk_memory.h"

#include <stdio.h>
#include <string.h>
#include <sys/resource.h>
#include <unistd.h>

uint64_t dk_memory_thread_reserve(void)
{
    long cpus = sysconf(_SC_NPROCESSORS_ONLN);
    if (cpus < 1)
        cpus = 1;
    return (96u + 48u * (uint64_t)cpus) << 20;
}

/* One unsigned number from the start of a small file; 0 when unreadable or "max". */
static int read_u64_file(const char *path, uint64_t *v)
{
    FILE *f = fopen(path, "r");
    unsigned long long x;
    int ok;
    if (!f)
        return 0;
    ok = fscanf(f, "%llu", &x) == 1;
    fclose(f);
    if (ok)
        *v = (uint64_t)x;
    return ok;
}

static uint64_t address_space_headroom(void)
{
    struct rlimit rl;
    if (getrlimit(RLIMIT_AS, &rl) != 0 || rl.rlim_cur == RLIM_INFINITY)
        return UINT64_MAX;
    FILE *f = fopen("/proc/self/statm", "r");
    unsigned long long pages = 0;
    if (f) {
        if (fscanf(f, "%llu", &pages) != 1)
            pages = 0;
        fclose(f);
    }
    const uint64_t used = (uint64_t)pages * (uint64_t)sysconf(_SC_PAGESIZE);
    const uint64_t lim = (uint64_t)rl.rlim_cur;
    return lim > used ? lim - used : 0;
}

static uint64_t cgroup_headroom(void)
{
    /* cgroup v2: the line "0::/path" of /proc/self/cgroup */
    char line[512], rel[512] = "", path[600];
    FILE *f = fopen("/proc/self/cgroup", "r");
    if (!f)
        return UINT64_MAX;
    while (fgets(line, sizeof line, f))
        if (strncmp(line, "0::", 3) == 0) {
            memcpy(rel, line + 3, strlen(line + 3) + 1);
            rel[strcspn(rel, "\n")] = '\0';
            break;
        }
    fclose(f);
    if (strcmp(rel, "/") == 0)
        rel[0] = '\0';
    uint64_t max = 0, cur = 0;
    snprintf(path, sizeof path, "/sys/fs/cgroup%s/memory.max", rel);
    if (!read_u64_file(path, &max)) /* absent, or "max" */
        return UINT64_MAX;
    snprintf(path, sizeof path, "/sys/fs/cgroup%s/memory.current", rel);
    if (!read_u64_file(path, &cur))
        cur = 0;
    return max > cur ? max - cur : 0;
}

static uint64_t mem_available(void)
{
    char line[256];
    unsigned long long kb;
    uint64_t v = UINT64_MAX;
    FILE *f = fopen("/proc/meminfo", "r");
    if (!f)
        return UINT64_MAX;
    while (fgets(line, sizeof line, f))
        if (sscanf(line, "MemAvailable: %llu kB", &kb) == 1) {
            v = (uint64_t)kb << 10;
            break;
        }
    fclose(f);
    return v;
}

void dk_memory_query(dk_memory_available *out)
{
    out->address_space = address_space_headroom();
    out->cgroup = cgroup_headroom();
    out->mem_available = mem_available();
    out->bytes = UINT64_MAX;
    out->limit = DK_MEMORY_UNLIMITED;
    if (out->address_space < out->bytes) {
        out->bytes = out->address_space;
        out->limit = DK_MEMORY_RLIMIT_AS;
    }
    if (out->cgroup < out->bytes) {
        out->bytes = out->cgroup;
        out->limit = DK_MEMORY_CGROUP;
    }
    if (out->mem_available < out->bytes) {
        out->bytes = out->mem_available;
        out->limit = DK_MEMORY_MEM_AVAILABLE;
    }
}

const char *dk_memory_limit_name(dk_memory_limit limit)
{
    switch (limit) {
    case DK_MEMORY_RLIMIT_AS: return "RLIMIT_AS headroom";
    case DK_MEMORY_CGROUP: return "cgroup memory.max headroom";
    case DK_MEMORY_MEM_AVAILABLE: return "MemAvailable";
    case DK_MEMORY_UNLIMITED: break;
    }
    return "no limit";
}

static double mib(uint64_t b)
{
    return (double)b / (1024.0 * 1024.0);
}

dk_status dk_memory_check(uint64_t need, const char *who, const char *what, dk_error *err)
{
    dk_memory_available a;
    dk_memory_query(&a);
    const uint64_t reserve = dk_memory_thread_reserve();
    const int over_as = a.address_space != UINT64_MAX &&
                        (need > a.address_space || a.address_space - need < reserve);
    const uint64_t physical = a.cgroup < a.mem_available ? a.cgroup : a.mem_available;
    const int over_phys = physical != UINT64_MAX && need > physical;
    if (!over_as && !over_phys)
        return DK_OK;
    if (over_as && (!over_phys || a.limit == DK_MEMORY_RLIMIT_AS))
        return dk_error_set(err, DK_ERR_OUT_OF_MEMORY,
                            "%s: %s needs about %.0f MiB (estimate) plus %.0f MiB of address "
                            "space for the thread pools, only %.0f MiB available (RLIMIT_AS "
                            "headroom); refused before allocating",
                            who, what, mib(need), mib(reserve), mib(a.address_space));
    return dk_error_set(err, DK_ERR_OUT_OF_MEMORY,
                        "%s: %s needs about %.0f MiB (estimate), only %.0f MiB available "
                        "(%s); refused before allocating",
                        who, what, mib(need), mib(physical),
                        dk_memory_limit_name(a.cgroup < a.mem_available ? DK_MEMORY_CGROUP
                                                                        : DK_MEMORY_MEM_AVAILABLE));
}
