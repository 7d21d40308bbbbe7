/*
 * Transparent huge pages for the point arrays (issue 11, step 7), when a tree's options
 * ask for them: a hint to the kernel (madvise MADV_HUGEPAGE) that the random accesses of
 * queries and of the build's gather would miss the TLB less on 2 MB pages. Only for
 * blocks from the default allocator (a custom allocator's memory is its own business) and
 * only where the system has the call; it never changes a result, and a refusal is ignored.
 */
#define _DEFAULT_SOURCE
#include <stdint.h>

#include "index/index_internal.h"

#if defined(__linux__)
#include <sys/mman.h>
#include <unistd.h>
#endif

void qk__advise_huge(const qk_allocator_t *a, void *p, size_t size) {
#if defined(__linux__) && defined(MADV_HUGEPAGE)
  if (!p || (a && a->fn) || size < ((size_t)4 << 20)) return;
  long page = sysconf(_SC_PAGESIZE);
  if (page <= 0) return;
  uintptr_t lo = ((uintptr_t)p + (uintptr_t)page - 1) & ~((uintptr_t)page - 1);
  uintptr_t hi = ((uintptr_t)p + size) & ~((uintptr_t)page - 1);
  if (hi > lo) (void)madvise((void *)lo, hi - lo, MADV_HUGEPAGE);
#else
  (void)a;
  (void)p;
  (void)size;
#endif
}
