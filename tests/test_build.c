/*
 * The bucketed bulk build at its deepest grid (2^8 x 2^8 cells, from 2^18 points on), where
 * the keys are computed four at a time on processors with AVX2: points on, one ulp before
 * and one ulp after every grid line, mixed with uniform ones, in a unit root and in an
 * offset, scaled one, must give the same tree as inserting them one by one (the book's
 * definition), on one thread and on two.
 *
 * The threaded build on inputs that load its buckets unevenly (all points equal, a few
 * duplicated locations, points on dyadic grid lines, half of them in one spot, capacity
 * 1): on two and on three threads the same tree node for node, with the same point order
 * in every leaf, as on one; and a uniform input whose tree is made on one thread after
 * the threaded sort.
 *
 * The tree made from the counts beside the threaded sort's last pass (fewer than 2^16 points
 * in cells over the capacity), waiting for the buckets of the cells it splits: the same
 * tree on 2, 3 and 4 threads as on one, and the shape of inserting the points one by one.
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

static void test_build_threads_adversarial(void **state) {
  (void)state;
  uint64_t seed = qkt_seed(1202);
  qkt_rng_t r;
  qkt_rng_seed(&r, seed);
  print_message("seed %llu\n", (unsigned long long)seed);
  enum { N = 200000 }; /* three shares of 2^16 points */
  qk_point_t *p = malloc(N * sizeof *p);
  assert_non_null(p);
  /* The last input's cells hold fewer points than its capacity: its subtrees are built on
   * the calling thread after the threaded sort (the others': on threads). */
  const uint32_t capacity[] = {1, 1, 2, 4, 1, 1, 1, 64};
  const size_t count[] = {N, N, N, N, N, 1, 70, N};
  for (int k = 0; k < 8; k++) {
    size_t n = count[k];
    switch (k) {
    case 0: /* all equal */
      for (size_t i = 0; i < n; i++) p[i] = (qk_point_t){0.25, 0.75};
      break;
    case 1:
      qkt_points(&r, QKT_DUPLICATES, p, n);
      break;
    case 2:
      qkt_points(&r, QKT_GRID_EDGES, p, n);
      break;
    case 3: /* half in one spot, after the first share */
      qkt_points(&r, QKT_UNIFORM, p, n);
      for (size_t i = n / 3; i < n / 3 + n / 2; i++) p[i] = (qk_point_t){0.5, 0.5};
      break;
    default:
      qkt_points(&r, QKT_UNIFORM, p, n);
      break;
    }
    qk_tree_options_t o;
    qk_tree_options_init(&o);
    o.capacity = capacity[k];
    o.max_depth = 12;
    o.threads = 1;
    qk_tree_t *one = NULL;
    assert_int_equal(qk_tree_build(p, n, &o, &one), QK_OK);
    QKT_CHECK_TREE(one);
    for (uint32_t threads = 2; threads <= 3; threads++) {
      o.threads = threads;
      qk_tree_t *t = NULL;
      assert_int_equal(qk_tree_build(p, n, &o, &t), QK_OK);
      print_message("input %d, %u threads\n", k, threads);
      qkt_assert_same_tree(one, t);
      qk_tree_free(t);
    }
    qk_tree_free(one);
  }
  free(p);
}

/* Between 1 and 2^16 points in cells over the capacity: on several threads the tree is made
 * from the counts on the calling thread while the other threads sort the buckets, and it
 * waits for (or sorts itself) each bucket holding a cell it splits point by point. Uniform
 * points at capacity 8 (about 29,000 of them in cells over 8) and 24 spots of 200 equal
 * points, in buckets spread over the grid, split to depth 14: the same tree, node for node
 * and point for point, on 2, 3 and 4 threads as on one, and the same shape as inserting the
 * points one by one. */
static void test_build_tree_beside_sort(void **state) {
  (void)state;
  uint64_t seed = qkt_seed(1203);
  qkt_rng_t r;
  qkt_rng_seed(&r, seed);
  print_message("seed %llu\n", (unsigned long long)seed);
  enum { N = 300000, SPOTS = 24, PER = 200 };
  qk_point_t *p = malloc(N * sizeof *p);
  assert_non_null(p);
  qkt_points(&r, QKT_UNIFORM, p, N);
  for (size_t s = 0; s < SPOTS; s++) {
    qk_point_t c = {(double)qkt_rng_below(&r, 1u << 20) / (double)(1u << 20),
                    (double)qkt_rng_below(&r, 1u << 20) / (double)(1u << 20)};
    for (size_t i = 0; i < PER; i++) p[(s * 12007 + i * 61) % N] = c;
  }
  qk_tree_options_t o;
  qk_tree_options_init(&o);
  o.capacity = 8;
  o.max_depth = 14;
  o.has_root = 1; /* the inserts' root: a fitted one would differ */
  o.root = (qk_square_t){0, 0, 1};
  qk_tree_t *ins = NULL;
  assert_int_equal(qk_tree_build(NULL, 0, &o, &ins), QK_OK);
  for (size_t i = 0; i < N; i++) assert_int_equal(qk_tree_insert(ins, p[i], NULL), QK_OK);
  qkt_shape_t want = qkt_tree_shape(ins);
  qk_tree_free(ins);
  o.threads = 1;
  qk_tree_t *one = NULL;
  assert_int_equal(qk_tree_build(p, N, &o, &one), QK_OK);
  QKT_CHECK_TREE(one);
  qkt_shape_t got = qkt_tree_shape(one);
  assert_int_equal(got.nodes, want.nodes);
  assert_true(got.hash == want.hash);
  for (uint32_t threads = 2; threads <= 4; threads++) {
    o.threads = threads;
    qk_tree_t *t = NULL;
    assert_int_equal(qk_tree_build(p, N, &o, &t), QK_OK);
    print_message("%u threads\n", threads);
    QKT_CHECK_TREE(t);
    qkt_assert_same_tree(one, t);
    qk_tree_free(t);
  }
  qk_tree_free(one);
  free(p);
}

int main(void) {
  const struct CMUnitTest tests[] = {
      cmocka_unit_test(test_build_deep_grid_lines),
      cmocka_unit_test(test_build_threads_adversarial),
      cmocka_unit_test(test_build_tree_beside_sort),
  };
  return cmocka_run_group_tests(tests, NULL, NULL);
}
