/*
 * Shared plumbing of the fuzz targets: a byte reader that turns the fuzzer's input into
 * choices, the failing allocator of the tests, and the failure hook.
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

/* The failing allocator shared with the tests (tests/support/fail_alloc.h); a wrong
 * osize from the library is an oracle failure. */
#ifndef QKT_ALLOC_FAIL
#define QKT_ALLOC_FAIL(...) QKF_FAIL(__VA_ARGS__)
#endif
#include "tests/support/fail_alloc.h"

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
