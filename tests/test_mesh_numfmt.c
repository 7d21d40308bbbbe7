/*
 * Tests of the mesh writers' number formatting (mesh/numfmt.h) against printf itself.
 *
 * Plan:
 *  - qk__fmt_g17 gives exactly snprintf("%.17g") on random bit patterns (every exponent,
 *    NaN and infinities included), on random doubles of moderate magnitude (the fixed
 *    notation range and just beyond it, both signs), on dyadic values with few significant
 *    bits (exact decimal expansions, so rounding ties to even happen), on powers of ten and
 *    their neighbours, on integers and half-integers up to 1e18, and on the signed zeros
 *    (-0 is written "0");
 *  - qk__fmt_u64 gives snprintf("%llu") on powers of ten, their neighbours and random values;
 *  - the buffered writer keeps what it is given across flushes;
 *  - the writers' decimal line counter counts as snprintf prints, across powers of ten.
 * Seeds come from QK_SEED (qkt_seed) and are printed on failure.
 */
#include <float.h>
#include <math.h>
#include <stdio.h>
#include <string.h>

#include "mesh/numfmt.h"
#include "qk_test.h"

static uint64_t g_seed;

static void check_g17(double x) {
  char a[QK__NUMFMT_MAX + 8], b[64];
  size_t n = qk__fmt_g17(x, a);
  snprintf(b, sizeof b, "%.17g", x == 0 ? 0.0 : x); /* -0 is written "0" */
  if (n != strlen(b) || strcmp(a, b))
    fail_msg("seed %llu: %a formats as '%s', printf says '%s'", (unsigned long long)g_seed, x, a,
             b);
}

static void test_numfmt_g17(void **state) {
  (void)state;
  g_seed = qkt_seed(12401);
  qkt_rng_t r;
  qkt_rng_seed(&r, g_seed);
  check_g17(0.0), check_g17(-0.0), check_g17(INFINITY), check_g17(-INFINITY), check_g17(NAN);
  check_g17(DBL_MIN), check_g17(DBL_MAX), check_g17(5e-324);
  for (int i = 0; i < 40000; i++) {
    uint64_t bits = qkt_rng_next(&r);
    double x;
    memcpy(&x, &bits, sizeof x);
    check_g17(x);
    double y = ldexp((double)(qkt_rng_next(&r) >> 11), (int)qkt_rng_below(&r, 100) - 90);
    check_g17(y), check_g17(-y);
    /* few significant bits: exact decimals, ties at the 18th digit */
    double z = ldexp((double)(qkt_rng_next(&r) >> (11 + qkt_rng_below(&r, 50))),
                     -(int)qkt_rng_below(&r, 64));
    check_g17(z), check_g17(-z);
    double t = ldexp((double)(qkt_rng_next(&r) >> 10), -(int)qkt_rng_below(&r, 8));
    check_g17(t), check_g17(t / 2);
    double q = (double)(qkt_rng_next(&r) % 1000000000000000000ull);
    check_g17(q), check_g17(q + 0.5), check_g17(q / 1024);
  }
  for (int k = -30; k <= 30; k++) {
    double p = pow(10, k);
    check_g17(p), check_g17(nextafter(p, 0)), check_g17(nextafter(p, INFINITY));
    check_g17(-p), check_g17(p * 0.5), check_g17(p * 1.5);
  }
}

static void test_numfmt_u64(void **state) {
  (void)state;
  g_seed = qkt_seed(12402);
  qkt_rng_t r;
  qkt_rng_seed(&r, g_seed);
  char a[32], b[32];
  for (int i = 0; i < 20000 + 64; i++) {
    uint64_t v = i < 20   ? (uint64_t)pow(10, i)
                 : i < 40 ? (uint64_t)pow(10, i - 20) - 1
                 : i < 64 ? UINT64_MAX - (uint64_t)(i - 40)
                          : qkt_rng_next(&r) >> qkt_rng_below(&r, 64);
    size_t n = qk__fmt_u64(v, a);
    a[n] = 0;
    snprintf(b, sizeof b, "%llu", (unsigned long long)v);
    if (strcmp(a, b)) fail_msg("seed %llu: %s vs %s", (unsigned long long)g_seed, a, b);
  }
}

static void test_numfmt_buffer(void **state) {
  (void)state;
  FILE *f = tmpfile();
  assert_non_null(f);
  qk__wbuf_t w;
  w.f = f, w.n = 0;
  size_t expect = 0;
  for (int i = 0; i < 20000; i++) {
    qk__wbuf_u(&w, (uint64_t)i), qk__wbuf_c(&w, ' '), qk__wbuf_i(&w, -i);
    qk__wbuf_s(&w, " x "), qk__wbuf_g17(&w, i / 8.0), qk__wbuf_c(&w, '\n');
    char line[96];
    expect += (size_t)snprintf(line, sizeof line, "%d %d x %.17g\n", i, -i, i / 8.0);
  }
  qk__wbuf_flush(&w);
  assert_int_equal(ftell(f), (long)expect);
  rewind(f);
  char line[96];
  for (int i = 0; i < 20000; i++) {
    char want[96];
    snprintf(want, sizeof want, "%d %d x %.17g\n", i, -i, i / 8.0);
    assert_non_null(fgets(line, sizeof line, f));
    assert_string_equal(line, want);
  }
  fclose(f);
}

/* The writers' line counter against snprintf: from 0, from 1, across every power of ten
 * (9 -> 10, 99 -> 100, ...) and from random starts. It copies 24 bytes; only the length it
 * returns counts. */
static void check_dcount(uint64_t start, int steps) {
  qk__dcount_t c;
  qk__dcount_init(&c, start);
  for (int i = 0; i < steps; i++) {
    char a[32], b[32];
    memset(a, 'x', sizeof a);
    size_t n = qk__dcount_put(&c, a);
    a[n] = 0;
    snprintf(b, sizeof b, "%llu", (unsigned long long)(start + (uint64_t)i));
    if (strcmp(a, b))
      fail_msg("seed %llu: counter from %llu at step %d says '%s', printf '%s'",
               (unsigned long long)g_seed, (unsigned long long)start, i, a, b);
  }
}

static void test_numfmt_counter(void **state) {
  (void)state;
  g_seed = qkt_seed(12403);
  qkt_rng_t r;
  qkt_rng_seed(&r, g_seed);
  check_dcount(0, 120000), check_dcount(1, 1200);
  for (int k = 1; k <= 19; k++) {
    uint64_t p = 1;
    for (int j = 0; j < k; j++) p *= 10;
    check_dcount(p - 3, 6);
  }
  for (int i = 0; i < 200; i++) check_dcount(qkt_rng_next(&r) >> qkt_rng_below(&r, 64) >> 1, 50);
}

int main(void) {
  const struct CMUnitTest tests[] = {
      cmocka_unit_test(test_numfmt_g17),
      cmocka_unit_test(test_numfmt_u64),
      cmocka_unit_test(test_numfmt_buffer),
      cmocka_unit_test(test_numfmt_counter),
  };
  return cmocka_run_group_tests(tests, NULL, NULL);
}
