/*
 * The failing allocator of the tests and the fuzz targets (one, header-only, so that the
 * standalone fuzz builds need no extra source): a realloc-style qk_allocator_t that fails
 * its `fail_at`-th allocating call (1-based; 0 = never) and keeps live counts, so that a
 * test can check that a failed call leaked nothing (libuv's test-loop-oom.c, Lua's
 * ltests.h). Each block carries its size in a header, so a wrong `osize` from the library
 * is caught: the includer says how to fail by defining QKT_ALLOC_FAIL(fmt, ...) before
 * including this file (tests: cmocka's fail_msg; fuzz targets: an abort libFuzzer sees).
 */
#ifndef QKT_FAIL_ALLOC_H
#define QKT_FAIL_ALLOC_H

#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "quadkit/common.h"

#ifndef QKT_ALLOC_FAIL
#define QKT_ALLOC_FAIL(...)                                                                        \
  do {                                                                                             \
    fprintf(stderr, __VA_ARGS__);                                                                  \
    abort();                                                                                       \
  } while (0)
#endif

typedef struct qkt_alloc {
  size_t calls;   /* allocating calls since the last arm */
  size_t fail_at; /* the call to fail (1-based), 0 = never */
  size_t live_bytes;
  size_t live_blocks;
  int failed; /* whether the armed call has failed */
} qkt_alloc_t;

typedef struct qkt_alloc_hdr {
  size_t size, pad; /* pad keeps the block 16-byte aligned */
} qkt_alloc_hdr_t;

static inline void *qkt_alloc_fn(void *ud, void *ptr, size_t osize, size_t nsize) {
  qkt_alloc_t *a = ud;
  qkt_alloc_hdr_t *h = ptr ? (qkt_alloc_hdr_t *)ptr - 1 : NULL;
  if (h && h->size != osize)
    QKT_ALLOC_FAIL("allocator: osize %zu but the block has %zu", osize, h->size);
  if (nsize == 0) {
    if (h) {
      a->live_blocks--;
      a->live_bytes -= h->size;
      free(h);
    }
    return NULL;
  }
  a->calls++;
  if (a->fail_at && a->calls == a->fail_at) {
    a->failed = 1;
    return NULL;
  }
  qkt_alloc_hdr_t *n = realloc(h, sizeof *n + nsize);
  if (!n) return NULL;
  if (!h) a->live_blocks++;
  a->live_bytes = a->live_bytes - (h ? osize : 0) + nsize;
  n->size = nsize;
  return n + 1;
}

/* Reset the counts and hand out the allocator. */
static inline qk_allocator_t qkt_alloc_make(qkt_alloc_t *a) {
  memset(a, 0, sizeof *a);
  qk_allocator_t al = {qkt_alloc_fn, a};
  return al;
}

/* Arm the allocator to fail the k-th allocation from now (0 = never). */
static inline void qkt_alloc_arm(qkt_alloc_t *a, size_t k) {
  a->calls = 0;
  a->fail_at = k;
  a->failed = 0;
}

#endif /* QKT_FAIL_ALLOC_H */
