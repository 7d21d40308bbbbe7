/*
 * The bucketed bulk build at its deepest grid (2^8 x 2^8 cells, from 2^18 points on), where
 * the keys are computed four at a time on processors with AVX2: points on, one ulp before
 * and one ulp after every grid line, mixed with uniform ones, in a unit root and in an
 * offset, scaled one, must give the same tree as inserting them one by one (the book's
 * definition), on one thread and on two.
 */
#include <math.h>
#include <stdlib.h>
#include <string.h>

#include "qk_test.h"

/* A coordinate on grid line k of 2^8 over [x0, x0 + side], or one ulp either side of it,
 * or anywhere (a quarter of them). */
static double near_line(qkt_rng_t *r, double x0, double side) {
  double k = (double)qkt_rng_below(r, 257), v = x0 + side * (k / 256.0);
  switch (qkt_rng_below(r, 4)) {
  case 0:
    return x0 + side * ((double)qkt_rng_below(r, 1u << 30) / (double)(1u << 30));
  case 1:
    v = nextafter(v, -INFINITY);
    break;
  case 2:
    v = nextafter(v, INFINITY);
    break;
  default:
    break;
  }
  return v < x0 ? x0 : v > x0 + side ? x0 + side : v;
}

static void test_build_deep_grid_lines(void **state) {
  (void)state;
  uint64_t seed = qkt_seed(1201);
  qkt_rng_t r;
  qkt_rng_seed(&r, seed);
  enum { N = 300000 }; /* 2^18 points and more: the 2^8 x 2^8 grid */
  qk_point_t *p = malloc(N * sizeof *p);
  assert_non_null(p);
  const double x0[] = {0.0, 1e6, -3.7e3};
  const double side[] = {1.0, 3.3, 1e-3};
  for (int k = 0; k < 3; k++) {
    for (size_t i = 0; i < N; i++) {
      p[i].x = near_line(&r, x0[k], side[k]);
      p[i].y = near_line(&r, -x0[k], side[k]);
    }
    qk_tree_options_t o;
    qk_tree_options_init(&o);
    o.capacity = 8;
    o.has_root = 1;
    o.root = (qk_square_t){x0[k], -x0[k], side[k]};
    qk_tree_t *ins = NULL;
    assert_int_equal(qk_tree_build(NULL, 0, &o, &ins), QK_OK);
    for (size_t i = 0; i < N; i++) assert_int_equal(qk_tree_insert(ins, p[i], NULL), QK_OK);
    qkt_shape_t want = qkt_tree_shape(ins);
    qk_tree_free(ins);
    for (uint32_t threads = 1; threads <= 2; threads++) {
      o.threads = threads;
      qk_tree_t *t = NULL;
      assert_int_equal(qk_tree_build(p, N, &o, &t), QK_OK);
      QKT_CHECK_TREE(t);
      qkt_shape_t got = qkt_tree_shape(t);
      if (got.nodes != want.nodes || got.hash != want.hash)
        print_error("seed %llu, root %d, %u threads: %zu nodes vs %zu by inserts\n",
                    (unsigned long long)seed, k, threads, got.nodes, want.nodes);
      assert_int_equal(got.nodes, want.nodes);
      assert_true(got.hash == want.hash);
      qk_tree_free(t);
    }
  }
  free(p);
}

int main(void) {
  const struct CMUnitTest tests[] = {
      cmocka_unit_test(test_build_deep_grid_lines),
  };
  return cmocka_run_group_tests(tests, NULL, NULL);
}
