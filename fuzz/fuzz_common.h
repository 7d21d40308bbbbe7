/*
 * Shared plumbing of the fuzz targets: a byte reader that turns the fuzzer's input into
 * choices, an allocator that fails on a chosen call and counts live blocks, and the
 * failure hook.
 *
 * Every target defines `int qkf_<name>(const uint8_t *data, size_t size)` and, unless
 * QKF_REPLAY is defined, libFuzzer's entry point calling it. tests/test_reliability.c
 * defines QKF_REPLAY and QKF_FAIL (as cmocka's fail_msg) and includes the target sources,
 * so the normal test suite replays the seed corpus and every regression input through
 * exactly the code the fuzzer ran.
 */
#ifndef QKF_FUZZ_COMMON_H
#define QKF_FUZZ_COMMON_H

#include <math.h>
#include <stddef.h>
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "quadkit/quadkit.h"

/* An oracle disagreed with the library: print why and crash so that libFuzzer keeps the
 * input. The replaying test replaces this with a cmocka failure. */
#ifndef QKF_FAIL
#define QKF_FAIL(...)                                                                              \
  do {                                                                                             \
    fprintf(stderr, "fuzz oracle: " __VA_ARGS__);                                                  \
    fputc('\n', stderr);                                                                           \
    abort();                                                                                       \
  } while (0)
#endif

/* Bugs found by fuzzing and reported but not yet fixed, which the targets step around so
 * that fuzzing can go on past them. Each has its input under
 * fuzz/regressions/<target>/open/ (not replayed by the test suite until fixed). Build with
 * -DQKF_OPEN_BUGS=0 to exercise them again. */
#ifndef QKF_OPEN_BUGS
#define QKF_OPEN_BUGS 0
#endif

#define QKF_ASSERT(cond, ...)                                                                      \
  do {                                                                                             \
    if (!(cond)) QKF_FAIL(__VA_ARGS__);                                                            \
  } while (0)

/* Reads choices from the input; past its end every read gives zero, so any prefix of an
 * input is itself a meaningful input (which helps libFuzzer minimise). */
typedef struct qkf_bytes {
  const uint8_t *p;
  size_t n, at;
} qkf_bytes_t;

static inline uint8_t qkf_u8(qkf_bytes_t *b) { return b->at < b->n ? b->p[b->at++] : 0; }

static inline uint32_t qkf_u32(qkf_bytes_t *b) {
  uint32_t v = 0;
  for (int i = 0; i < 4; i++) v = v << 8 | qkf_u8(b);
  return v;
}

static inline int qkf_done(const qkf_bytes_t *b) { return b->at >= b->n; }

/* A raw double from eight input bytes: reaches NaN, infinities, subnormals and -0. */
static inline double qkf_raw_double(qkf_bytes_t *b) {
  uint64_t v = 0;
  for (int i = 0; i < 8; i++) v = v << 8 | qkf_u8(b);
  double d;
  memcpy(&d, &v, sizeof d);
  return d;
}

/* Allocator that fails its `fail_at`-th allocating call (1-based; 0 = never) and keeps
 * live counts, so a target can check that a failed call leaked nothing. */
typedef struct qkf_alloc {
  size_t calls, fail_at, live_blocks, live_bytes;
  int failed;
} qkf_alloc_t;

typedef struct qkf_hdr {
  size_t size, pad;
} qkf_hdr_t;

static void *qkf_alloc_fn(void *ud, void *ptr, size_t osize, size_t nsize) {
  qkf_alloc_t *a = ud;
  qkf_hdr_t *h = ptr ? (qkf_hdr_t *)ptr - 1 : NULL;
  QKF_ASSERT(!h || h->size == osize, "allocator: osize %zu but block has %zu", osize,
             h ? h->size : 0);
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
  qkf_hdr_t *n = realloc(h, sizeof *n + nsize);
  if (!n) return NULL;
  if (!h) a->live_blocks++;
  a->live_bytes = a->live_bytes - (h ? osize : 0) + nsize;
  n->size = nsize;
  return n + 1;
}

static inline qk_allocator_t qkf_alloc_make(qkf_alloc_t *a) {
  memset(a, 0, sizeof *a);
  qk_allocator_t al = {qkf_alloc_fn, a};
  return al;
}

/* Arm the allocator to fail the k-th allocation from now (0 = never). */
static inline void qkf_alloc_arm(qkf_alloc_t *a, size_t k) {
  a->calls = 0;
  a->fail_at = k;
  a->failed = 0;
}

/* Check a tree's invariants. */
static inline void qkf_check_tree(const qk_tree_t *t, const char *after) {
  char msg[256];
  qk_status_t st = qk_tree_check(t, msg, sizeof msg);
  /* The check's own scratch allocation may be the one an armed allocator fails (it fails
   * once): then check again. */
  if (st == QK_ERR_NOMEM) st = qk_tree_check(t, msg, sizeof msg);
  if (st != QK_OK) QKF_FAIL("qk_tree_check after %s: %s", after, msg);
}

#endif /* QKF_FUZZ_COMMON_H */
