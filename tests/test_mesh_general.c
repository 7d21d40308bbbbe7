/*
 * Tests of the general mesh mode's building blocks (docs/mesh-general.md), checked against
 * exact rational arithmetic (GMP; without it the tests report themselves skipped):
 *  - qk__orient2d on random triples over many scales, on triples made collinear in
 *    floating point and then moved by a few ulps (where the floating-point estimate is
 *    unreliable), on exactly collinear dyadic triples, and on coincident points;
 *  - qk__seg_meets_box against exact rational clipping (Liang-Barsky in mpq) on random
 *    segments, segments through box corners, along box sides and one ulp off them;
 *  - qk__seg_budget and qk__seg_point: every point a + (k/2^m)(b - a) with m within the
 *    budget is exactly that rational point (dyadic endpoints of many magnitudes, axis-
 *    parallel segments, full-precision doubles), and requests beyond it are refused;
 *  - a CDT reserved far ahead of need (most of its room unused) and then grown, as the
 *    mesher's seeding does, keeps every live entry (the growth copies only those: a new
 *    block rather than a realloc) and stays a valid Delaunay triangulation as points follow,
 *    with libc's allocator and with the mesher's arena (no GMP needed).
 */
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "mesh/cdt_internal.h"
#include "mesh/general_internal.h"
#include "mesh/mesh_internal.h"
#include "qk_test.h"

#ifdef QK_HAVE_GMP
#include <gmp.h>

/* The sign of (b - a) x (c - a) with rationals. */
static int orient_q(const double *a, const double *b, const double *c) {
  mpq_t t[6];
  for (int i = 0; i < 6; i++) mpq_init(t[i]);
  mpq_set_d(t[0], b[0]), mpq_set_d(t[5], a[0]), mpq_sub(t[0], t[0], t[5]);
  mpq_set_d(t[1], c[1]), mpq_set_d(t[5], a[1]), mpq_sub(t[1], t[1], t[5]);
  mpq_set_d(t[2], b[1]), mpq_sub(t[2], t[2], t[5]);
  mpq_set_d(t[3], c[0]), mpq_set_d(t[5], a[0]), mpq_sub(t[3], t[3], t[5]);
  mpq_mul(t[4], t[0], t[1]), mpq_mul(t[5], t[2], t[3]), mpq_sub(t[4], t[4], t[5]);
  int s = mpq_sgn(t[4]);
  for (int i = 0; i < 6; i++) mpq_clear(t[i]);
  return s;
}

static void expect(const double *a, const double *b, const double *c, uint64_t seed, int k) {
  int want = orient_q(a, b, c), got = qk__orient2d(a, b, c);
  if (want != got)
    fail_msg("seed %llu case %d: orient((%.17g,%.17g),(%.17g,%.17g),(%.17g,%.17g)) = %d, "
             "exact %d",
             (unsigned long long)seed, k, a[0], a[1], b[0], b[1], c[0], c[1], got, want);
  /* The sign flips with the orientation and survives cyclic shifts. */
  if (qk__orient2d(b, a, c) != -want || qk__orient2d(b, c, a) != want)
    fail_msg("seed %llu case %d: orient is not antisymmetric", (unsigned long long)seed, k);
}

static void test_orient_random_scales(void **state) {
  (void)state;
  uint64_t seed = qkt_seed(12001);
  qkt_rng_t r;
  qkt_rng_seed(&r, seed);
  for (int k = 0; k < 20000; k++) {
    int e = (int)qkt_rng_below(&r, 81) - 40; /* scales 2^-40 .. 2^40 */
    double off = ldexp(qkt_rng_range(&r, -1, 1), (int)qkt_rng_below(&r, 41));
    double p[3][2];
    for (int i = 0; i < 3; i++)
      for (int j = 0; j < 2; j++) p[i][j] = off + ldexp(qkt_rng_range(&r, -1, 1), e);
    expect(p[0], p[1], p[2], seed, k);
  }
}

static void test_orient_near_collinear(void **state) {
  (void)state;
  uint64_t seed = qkt_seed(12002);
  qkt_rng_t r;
  qkt_rng_seed(&r, seed);
  int nonzero = 0, naive_wrong = 0;
  for (int k = 0; k < 20000; k++) {
    double scale = ldexp(1, (int)qkt_rng_below(&r, 41) - 20);
    double a[2] = {qkt_rng_range(&r, -1, 1) * scale, qkt_rng_range(&r, -1, 1) * scale};
    double b[2] = {qkt_rng_range(&r, -1, 1) * scale * 1e6, qkt_rng_range(&r, -1, 1) * scale};
    double t = qkt_rng_range(&r, -0.5, 1.5);
    double c[2] = {a[0] + t * (b[0] - a[0]), a[1] + t * (b[1] - a[1])};
    int moves = (int)qkt_rng_below(&r, 7) - 3; /* -3 .. 3 ulps in y */
    for (int m = 0; m < abs(moves); m++) c[1] = nextafter(c[1], moves > 0 ? INFINITY : -INFINITY);
    expect(a, b, c, seed, k);
    int want = orient_q(a, b, c);
    double naive = (b[0] - a[0]) * (c[1] - a[1]) - (b[1] - a[1]) * (c[0] - a[0]);
    nonzero += want != 0;
    naive_wrong += (naive > 0) - (naive < 0) != want;
  }
  /* The cases must reach both answers near the line, and many where plain floating
   * point gets the sign wrong (so the exact path is exercised). */
  assert_true(nonzero > 1000);
  assert_true(naive_wrong > 1000);
}

static void test_orient_exact_collinear(void **state) {
  (void)state;
  uint64_t seed = qkt_seed(12003);
  qkt_rng_t r;
  qkt_rng_seed(&r, seed);
  for (int k = 0; k < 5000; k++) {
    /* Dyadic endpoints and a dyadic parameter: the point is on the segment exactly. */
    double a[2] = {ldexp((double)qkt_rng_below(&r, 1u << 20), -10) + 1e5,
                   ldexp((double)qkt_rng_below(&r, 1u << 20), -10)};
    double b[2] = {ldexp((double)qkt_rng_below(&r, 1u << 20), -10),
                   ldexp((double)qkt_rng_below(&r, 1u << 20), -10) - 3e5};
    double tk = (double)qkt_rng_below(&r, 1u << 12), s = ldexp(1, -12);
    double c[2] = {a[0] + tk * ((b[0] - a[0]) * s), a[1] + tk * ((b[1] - a[1]) * s)};
    expect(a, b, c, seed, k);
    assert_int_equal(qk__orient2d(a, b, c), 0);
    double d[2] = {c[0], nextafter(c[1], INFINITY)};
    expect(a, b, d, seed, k);
  }
  double p[2] = {0.1, 0.3}, q[2] = {0.1, 0.3};
  assert_int_equal(qk__orient2d(p, q, p), 0);
  double u[2] = {3, -7}, v[2] = {3, 5}, w[2] = {3, 11};
  expect(u, v, w, seed, -1);
}

/* Whether segment ab meets the closed box, by clipping its parameter range with rationals. */
static int meets_q(const double *a, const double *b, const double *lo, const double *hi) {
  mpq_t t0, t1, d, u, v, w;
  mpq_inits(t0, t1, d, u, v, w, NULL);
  mpq_set_ui(t0, 0, 1), mpq_set_ui(t1, 1, 1);
  int ok = 1;
  for (int i = 0; i < 2 && ok; i++) {
    mpq_set_d(d, b[i]), mpq_set_d(w, a[i]), mpq_sub(d, d, w);
    if (mpq_sgn(d) == 0) {
      ok = a[i] >= lo[i] && a[i] <= hi[i];
      continue;
    }
    mpq_set_d(u, lo[i]), mpq_sub(u, u, w), mpq_div(u, u, d); /* parameter at lo */
    mpq_set_d(v, hi[i]), mpq_sub(v, v, w), mpq_div(v, v, d); /* parameter at hi */
    if (mpq_cmp(u, v) > 0) mpq_swap(u, v);
    if (mpq_cmp(u, t0) > 0) mpq_set(t0, u);
    if (mpq_cmp(v, t1) < 0) mpq_set(t1, v);
    ok = mpq_cmp(t0, t1) <= 0;
  }
  mpq_clears(t0, t1, d, u, v, w, NULL);
  return ok;
}

static void test_seg_meets_box(void **state) {
  (void)state;
  uint64_t seed = qkt_seed(12005);
  qkt_rng_t r;
  qkt_rng_seed(&r, seed);
  int hits = 0, misses = 0;
  for (int c = 0; c < 40000; c++) {
    double s = ldexp(1, (int)qkt_rng_below(&r, 40) - 20);
    double lo[2] = {s * (double)qkt_rng_below(&r, 64), s * (double)qkt_rng_below(&r, 64)};
    double hi[2] = {lo[0] + s, lo[1] + s};
    double a[2], b[2];
    int kind = (int)qkt_rng_below(&r, 4);
    for (int i = 0; i < 2; i++) {
      a[i] = lo[i] + s * qkt_rng_range(&r, -2, 3);
      b[i] = lo[i] + s * qkt_rng_range(&r, -2, 3);
    }
    if (kind == 1) { /* through a corner: b = 2 corner - a, exactly */
      double k0 = qkt_rng_below(&r, 2) ? lo[0] : hi[0], k1 = qkt_rng_below(&r, 2) ? lo[1] : hi[1];
      a[0] = k0 + s * (double)qkt_rng_below(&r, 8) / 8,
      a[1] = k1 - s * (double)qkt_rng_below(&r, 8) / 8;
      b[0] = 2 * k0 - a[0], b[1] = 2 * k1 - a[1];
    } else if (kind == 2) { /* along a side line, possibly beyond the box */
      a[1] = b[1] = qkt_rng_below(&r, 2) ? lo[1] : hi[1];
    }
    if (kind >= 1 && qkt_rng_below(&r, 2)) { /* one ulp off (not from 0: no subnormals) */
      int i = (int)qkt_rng_below(&r, 2);
      if (a[i] == 0) a[i] = ldexp(1, -300);
      a[i] = nextafter(a[i], qkt_rng_below(&r, 2) ? INFINITY : -INFINITY);
    }
    int want = meets_q(a, b, lo, hi), got = qk__seg_meets_box(a, b, lo, hi);
    if (want != got)
      fail_msg("seed %llu case %d: (%.17g,%.17g)-(%.17g,%.17g) vs box [%.17g,%.17g]x[%.17g,%.17g]: "
               "%d, exact %d",
               (unsigned long long)seed, c, a[0], a[1], b[0], b[1], lo[0], hi[0], lo[1], hi[1], got,
               want);
    hits += want, misses += !want;
  }
  assert_true(hits > 5000 && misses > 5000);
}

/* out == a + (k/2^m)(b - a) exactly. */
static int point_is(const double *a, const double *b, uint64_t k, int m, const double *out) {
  mpq_t t, d, x;
  mpq_inits(t, d, x, NULL);
  mpz_set_ui(mpq_numref(t), 1);
  mpz_mul_2exp(mpq_denref(t), mpq_numref(t), (mp_bitcnt_t)m);
  mpz_set_ui(mpq_numref(t), 0);
  mpz_import(mpq_numref(t), 1, -1, sizeof k, 0, 0, &k);
  mpq_canonicalize(t);
  int ok = 1;
  for (int i = 0; i < 2; i++) {
    mpq_set_d(d, b[i]), mpq_set_d(x, a[i]), mpq_sub(d, d, x), mpq_mul(d, d, t), mpq_add(d, d, x);
    mpq_set_d(x, out[i]);
    ok &= mpq_equal(d, x) != 0;
  }
  mpq_clears(t, d, x, NULL);
  return ok;
}

static void test_seg_points(void **state) {
  (void)state;
  uint64_t seed = qkt_seed(12004);
  qkt_rng_t r;
  qkt_rng_seed(&r, seed);
  int interior = 0;
  for (int c = 0; c < 20000; c++) {
    double a[2], b[2];
    int kind = (int)qkt_rng_below(&r, 3);
    int f = (int)qkt_rng_below(&r, 60) - 20; /* grid 2^-f */
    int bits = 1 + (int)qkt_rng_below(&r, 52);
    for (int i = 0; i < 2; i++) {
      a[i] = ldexp((double)(qkt_rng_next(&r) >> (64 - bits)) - ldexp(1, bits - 1), -f);
      b[i] = ldexp((double)(qkt_rng_next(&r) >> (64 - bits)) - ldexp(1, bits - 1), -f);
      if (kind == 2) a[i] = qkt_rng_range(&r, -1e6, 1e6), b[i] = qkt_rng_range(&r, -1e6, 1e6);
    }
    if (kind == 1) { /* axis-parallel */
      int axis = (int)qkt_rng_below(&r, 2);
      b[axis] = a[axis];
    }
    if (a[0] == b[0] && a[1] == b[1]) continue;
    int budget = qk__seg_budget(a, b);
    assert_true(budget <= 52);
    for (int m = 0; m <= budget && m <= 52; m += 1 + (int)qkt_rng_below(&r, 8)) {
      uint64_t k = m == 0 ? qkt_rng_below(&r, 2) : qkt_rng_next(&r) >> (64 - m);
      double out[2];
      assert_int_equal(qk__seg_point(a, b, k, m, out), 0);
      if (!point_is(a, b, k, m, out))
        fail_msg("seed %llu case %d: point %llu/2^%d of (%.17g,%.17g)-(%.17g,%.17g) is not exact",
                 (unsigned long long)seed, c, (unsigned long long)k, m, a[0], a[1], b[0], b[1]);
      interior += k != 0 && m > 0 && k != (uint64_t)1 << m;
    }
    double out[2] = {0, 0};
    if (budget >= 0 && budget < 52) {
      assert_int_equal(qk__seg_point(a, b, 1, budget + 1, out), -1);
      assert_true(out[0] == 0 && out[1] == 0);
    }
    /* The endpoints are always available, bit-identical. */
    assert_int_equal(qk__seg_point(a, b, 8, 3, out), 0);
    assert_true(out[0] == b[0] && out[1] == b[1]);
    assert_int_equal(qk__seg_point(a, b, 0, 40, out), 0);
    assert_true(out[0] == a[0] && out[1] == a[1]);
    assert_int_equal(qk__seg_point(a, b, 9, 3, out), -1);
  }
  assert_true(interior > 10000);
  /* Coordinates with 16 fractional bits up to 2^20 leave a budget of 16 (the doc's remark). */
  double p[2] = {ldexp(1, 20) - ldexp(1, -16), 0.5}, q[2] = {3.25, ldexp(1, 19) + ldexp(3, -16)};
  assert_int_equal(qk__seg_budget(p, q), 16);
}
#endif

/* The triangulation's links agree (every neighbour links back across the same two vertices)
 * and it is Delaunay: no vertex across an edge strictly inside a triangle's circumcircle. */
static void check_cdt(const qk__cdt_t *c) {
  for (size_t t = 0; t < c->nt; t++)
    for (int k = 0; k < 3; k++) {
      uint32_t n = c->nbr[3 * t + k], a = c->v[3 * t + (k + 1) % 3], b = c->v[3 * t + (k + 2) % 3];
      if (n == QK__CDT_NONE) continue;
      int j = c->nbr[3 * n] == t ? 0 : c->nbr[3 * n + 1] == t ? 1 : 2;
      assert_int_equal(c->nbr[3 * n + j], t);
      assert_int_equal(c->v[3 * n + (j + 1) % 3], b);
      assert_int_equal(c->v[3 * n + (j + 2) % 3], a);
      const double *q = &c->xy[2 * c->v[3 * n + j]];
      assert_true(qk__cdt_incircle(&c->xy[2 * c->v[3 * t]], &c->xy[2 * c->v[3 * t + 1]],
                                   &c->xy[2 * c->v[3 * t + 2]], q) <= 0);
    }
  for (size_t v = 4; v < c->nv; v++) {
    uint32_t t = c->vtri[v];
    assert_true(c->v[3 * t] == v || c->v[3 * t + 1] == v || c->v[3 * t + 2] == v);
  }
}

static void reserve_grow_run(const qk_allocator_t *alloc) {
  qk__cdt_t c;
  assert_int_equal(qk__cdt_init(&c, alloc, 0, 0, 1024, 4000), QK_OK);
  uint64_t s = 12345;
  double xy[2 * 600];
  for (int i = 0; i < 2 * 600; i++) {
    s ^= s << 13, s ^= s >> 7, s ^= s << 17;
    xy[i] = 1 + (double)(s >> 11) * 0x1p-53 * 1022;
  }
  uint32_t v;
  int existed;
  for (int i = 0; i < 50; i++)
    assert_int_equal(qk__cdt_insert(&c, xy[2 * i], xy[2 * i + 1], QK__CDT_NONE, &v, &existed),
                     QK_OK);
  /* Less than half the room in use on both sides: the growth below copies the live part. */
  assert_true(2 * c.nt < c.cap_t && 2 * c.nv < c.cap_v);
  size_t nt = c.nt, nv = c.nv;
  uint32_t *keep = malloc(3 * 3 * nt * sizeof *keep + nv * sizeof *keep);
  double *kxy = malloc(2 * nv * sizeof *kxy);
  assert_non_null(keep);
  assert_non_null(kxy);
  memcpy(keep, c.v, 3 * nt * sizeof *keep);
  memcpy(keep + 3 * nt, c.nbr, 3 * nt * sizeof *keep);
  memcpy(keep + 6 * nt, c.seg, 3 * nt * sizeof *keep);
  memcpy(keep + 9 * nt, c.vtri, nv * sizeof *keep);
  memcpy(kxy, c.xy, 2 * nv * sizeof *kxy);
  size_t cap_t = c.cap_t, cap_v = c.cap_v;
  assert_int_equal(qk__cdt_reserve(&c, 3 * cap_v, 3 * cap_t), QK_OK);
  assert_true(c.cap_t >= 3 * cap_t && c.cap_v >= 3 * cap_v);
  assert_memory_equal(c.v, keep, 3 * nt * sizeof *keep);
  assert_memory_equal(c.nbr, keep + 3 * nt, 3 * nt * sizeof *keep);
  assert_memory_equal(c.seg, keep + 6 * nt, 3 * nt * sizeof *keep);
  assert_memory_equal(c.vtri, keep + 9 * nt, nv * sizeof *keep);
  assert_memory_equal(c.xy, kxy, 2 * nv * sizeof *kxy);
  check_cdt(&c);
  for (int i = 50; i < 600; i++)
    assert_int_equal(qk__cdt_insert(&c, xy[2 * i], xy[2 * i + 1], QK__CDT_NONE, &v, &existed),
                     QK_OK);
  assert_int_equal(c.nv, 604);
  assert_int_equal(c.nt, 2 * 604 - 6); /* a triangulated square: 2n - 2 - 4 hull vertices */
  check_cdt(&c);
  free(keep);
  free(kxy);
  qk__cdt_free(&c);
}

static void test_cdt_reserve_grow(void **state) {
  (void)state;
  reserve_grow_run(NULL);
  qk__mesh_arena_t *r = qk__mesh_arena_new();
  assert_non_null(r);
  qk_allocator_t a = {qk__mesh_arena_fn, r};
  reserve_grow_run(&a);
  qk__mesh_arena_free(r);
}

static void skip_without_gmp(void **state) {
  (void)state;
  skip();
}

int main(void) {
#ifdef QK_HAVE_GMP
  const struct CMUnitTest tests[] = {
      cmocka_unit_test(test_orient_random_scales),   cmocka_unit_test(test_orient_near_collinear),
      cmocka_unit_test(test_orient_exact_collinear), cmocka_unit_test(test_seg_points),
      cmocka_unit_test(test_seg_meets_box),          cmocka_unit_test(test_cdt_reserve_grow),
  };
  (void)skip_without_gmp;
#else
  const struct CMUnitTest tests[] = {cmocka_unit_test(skip_without_gmp),
                                     cmocka_unit_test(test_cdt_reserve_grow)};
#endif
  return cmocka_run_group_tests(tests, NULL, NULL);
}
