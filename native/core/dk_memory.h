/* DeformKit: how much memory a bind may still take, and refusing one that does not fit
 * (issue 18 class 4, issue 19 item 4).
 *
 * A bind that runs out of memory half-way is not a clean failure: under an address-space
 * limit (RLIMIT_AS, as render-farm job limits set) OpenBLAS's buffer allocator retries a
 * failed mmap forever and libgomp exits the process when it cannot create a thread; without
 * a limit the kernel's OOM killer ends the process. So binds compare an estimate of what they
 * need with what is available *before* the big allocations and fail with
 * DK_ERR_OUT_OF_MEMORY and a message giving both figures. */
#ifndef DK_MEMORY_H
#define DK_MEMORY_H

#include <stdint.h>

#include "dk_status.h"

/** Which limit is the tightest. */
typedef enum dk_memory_limit {
    DK_MEMORY_UNLIMITED = 0,      /**< nothing could be read (no /proc): no limit known      */
    DK_MEMORY_RLIMIT_AS = 1,      /**< the address-space limit minus the current VmSize      */
    DK_MEMORY_CGROUP = 2,         /**< the cgroup's memory.max minus its memory.current      */
    DK_MEMORY_MEM_AVAILABLE = 3,  /**< MemAvailable from /proc/meminfo                       */
} dk_memory_limit;

/** What is available now. */
typedef struct dk_memory_available {
    uint64_t bytes;          /**< min over the limits below (UINT64_MAX when none is known) */
    dk_memory_limit limit;   /**< the one that gave `bytes`                                 */
    uint64_t address_space;  /**< RLIMIT_AS headroom (UINT64_MAX: unlimited)                */
    uint64_t cgroup;         /**< cgroup v2 headroom (UINT64_MAX: none, or memory.max "max") */
    uint64_t mem_available;  /**< /proc/meminfo MemAvailable (UINT64_MAX: unreadable)       */
} dk_memory_available;

/** Address space taken on first use by the thread pools of the numerics (OpenBLAS's per-call
 *  buffers, OpenMP and helper-thread stacks), which RLIMIT_AS counts although little of it is
 *  resident: 96 MiB plus 48 MiB per online CPU (measured on the 2-core test VM: the first
 *  supernodal factorization grows VmSize by ~180 MiB). Checked against the RLIMIT_AS headroom
 *  only. */
uint64_t dk_memory_thread_reserve(void);

/** Fills `out` from getrlimit(RLIMIT_AS) and /proc/self/statm, the process's cgroup v2
 *  (/proc/self/cgroup, then memory.max and memory.current under /sys/fs/cgroup) and
 *  /proc/meminfo. A source that cannot be read counts as unlimited. Never fails; `out` must
 *  not be NULL. */
void dk_memory_query(dk_memory_available *out);

/** "RLIMIT_AS headroom", "cgroup memory.max headroom", "MemAvailable" or "no limit". */
const char *dk_memory_limit_name(dk_memory_limit limit);

/** DK_OK when `need` bytes fit in what is available now (with dk_memory_thread_reserve()
 *  more against the address-space limit); otherwise DK_ERR_OUT_OF_MEMORY with the message
 *  "<who>: <what> needs about X MiB (estimate), only Y MiB available (<limit>); refused
 *  before allocating". `who` and `what` are strings for the message (not NULL). */
dk_status dk_memory_check(uint64_t need, const char *who, const char *what, dk_error *err);

#endif
