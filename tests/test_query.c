/*
 * Test plan for query/ (range, radius, kNN, point location, batch forms, threads):
 *  - range and radius on uniform, clustered, duplicate-heavy and cell-edge point sets at
 *    capacities 1, 4 and 32, against brute force: boxes and centres inside, straddling
 *    and outside the root square, empty, inverted and infinite boxes, radius 0;
 *  - kNN against brute force for k from 1 to n on small sets and a spread of k on large
 *    ones, with and without a distance cap, ties broken by id (duplicates, grid points);
 *  - kNN on leaves far over capacity (several scan chunks, many equal distances), k
 *    around the sorted-array limit, single and batch;
 *  - 1-NN ties on a duplicated dyadic grid (within a chunk, across leaves), caps equal to
 *    a grid distance, queries far outside, k above the point count, single and batch;
 *  - k > 1 ties on that grid (the id order decides which equal distances make the k), and
 *    queries beside a dense cluster, where the search's guessed first limit falls short;
 *  - the k-th bound for k = 8, 32 and 100 on clustered and duplicate-heavy points, caps
 *    exactly at the k-th and (k/2)-th distance and just below, single and batch;
 *  - squared distances a few units in the last place apart and exact ties among them
 *    (the sorted search's first sort keys drop the low bits), k from 2 to 33; kNN with
 *    subnormals flushed (the processor mode of -ffast-math programs) on stored points;
 *  - kNN exact against rationals (GMP) at scales 2^-1074 to 2^1017: squares that
 *    underflow, near-ties whose double squares are equal or misordered, caps one ulp
 *    either side of a point's distance, k from 1 to past the heap threshold, single and
 *    batch (the oracle qko_knn is exact too);
 *  - kNN from the corners, edge midpoints and centres of leaves' squares (and one unit in
 *    the last place off them) in a tree whose squares are rounded, k from 2 to 33;
 *  - batch kNN (Z-order, each query starting from the previous path) on every point set
 *    and capacity, one and two threads, against brute force;
 *  - kNN after random inserts and removals (qk_tree_check after each batch);
 *  - point location: every stored point is located in the leaf that holds it, random
 *    locations land in a leaf whose half-open square contains them, outside/NaN fail;
 *  - batch forms equal the single-query answers; buffers that are too small report the
 *    full count; callbacks stop early when asked; large radius batches on 1 to 3 threads
 *    (the shares' results copied into place by all of them) against the single calls and
 *    the oracle's counts, with the caller's buffer full size and cut short;
 *  - bad arguments; an empty tree;
 *  - four threads querying one tree at once get the single-threaded answers;
 *  - kNN and locate batches of 300,001 queries on two and three threads (chunks taken from a
 *    shared counter) equal one thread's bit for bit, and report the lower-numbered of two
 *    bad queries met by different threads;
 *  - pruning at every magnitude: radius and kNN (k = 1, 8, 40, capped, batch) on uniform
 *    points at scales 1, 1e-200, 1e-300 and 1e200 against brute force, with the number of
 *    exact (big-integer) tests counted through --wrap and bounded (no timing);
 *  - the real cities set (lon/lat as planar coordinates) when present.
 */
#include <math.h>
#include <pthread.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#if defined(__SSE2__)
#include <xmmintrin.h>
#endif

#include "qk_test.h"
#include "query_oracle.h"

/* Nonzero: the k = 1 scan's SSE2 path on processors with AVX2 (query/knn.c). */
extern int qk__knn_avx2_off;

static const qkt_dist_t dists[] = {QKT_UNIFORM, QKT_CLUSTERED, QKT_DUPLICATES, QKT_GRID_EDGES};
static const uint32_t caps[] = {1, 4, 32};
static uint64_t g_seed;

/* A checked tree of capacity cap, its memory from a (NULL: libc). */
static qk_tree_t *build_with(const qk_point_t *p, size_t n, uint32_t cap, const qk_allocator_t *a) {
  qk_tree_options_t o;
  qk_tree_options_init(&o);
  o.capacity = cap;
  o.allocator = a;
  qk_tree_t *t = NULL;
  assert_int_equal(qk_tree_build(p, n, &o, &t), QK_OK);
  QKT_CHECK_TREE(t);
  return t;
}

static qk_tree_t *build(const qk_point_t *p, size_t n, uint32_t cap) {
  return build_with(p, n, cap, NULL);
}

/* A query location: mostly inside the unit square, some on the grid, some outside. */
static qk_point_t rand_loc(qkt_rng_t *r) {
  qk_point_t q;
  switch (qkt_rng_below(r, 4)) {
  case 0:
    q.x = qkt_rng_below(r, 17) / 16.0;
    q.y = qkt_rng_below(r, 17) / 16.0;
    break;
  case 1:
    q.x = qkt_rng_range(r, -1, 2);
    q.y = qkt_rng_range(r, -1, 2);
    break;
  default:
    q.x = qkt_rng_unit(r);
    q.y = qkt_rng_unit(r);
  }
  return q;
}

static void assert_nb_equal(const qk_neighbor_t *a, size_t na, const qk_neighbor_t *b, size_t nb,
                            const char *what, size_t qi) {
  if (na != nb)
    fail_msg("%s query %zu: %zu results, oracle %zu (seed %llu)", what, qi, na, nb,
             (unsigned long long)g_seed);
  for (size_t i = 0; i < na; i++)
    if (a[i].id != b[i].id || a[i].dist != b[i].dist)
      fail_msg("%s query %zu rank %zu: (%u, %.17g) vs oracle (%u, %.17g) (seed %llu)", what, qi, i,
               a[i].id, a[i].dist, b[i].id, b[i].dist, (unsigned long long)g_seed);
}

/* The library's exact (big-integer) tests, counted: linked with --wrap for this program
 * (tests/CMakeLists.txt), so that a test can bound how many a query runs (the work a
 * query does when its filter cannot decide, which it is not allowed to time). */
int qk__within_exact(double ax, double ay, double bx, double by, double r1, double r2);
int qk__dist_cmp_exact(double qx, double qy, double ax, double ay, double bx, double by);
int __real_qk__within_exact(double ax, double ay, double bx, double by, double r1, double r2);
int __real_qk__dist_cmp_exact(double qx, double qy, double ax, double ay, double bx, double by);
int __wrap_qk__within_exact(double ax, double ay, double bx, double by, double r1, double r2);
int __wrap_qk__dist_cmp_exact(double qx, double qy, double ax, double ay, double bx, double by);
static _Atomic size_t g_exact_calls; /* (atomic: threaded tests call the library too) */
int __wrap_qk__within_exact(double ax, double ay, double bx, double by, double r1, double r2) {
  g_exact_calls++;
  return __real_qk__within_exact(ax, ay, bx, by, r1, r2);
}
int __wrap_qk__dist_cmp_exact(double qx, double qy, double ax, double ay, double bx, double by) {
  g_exact_calls++;
  return __real_qk__dist_cmp_exact(qx, qy, ax, ay, bx, by);
}

static int count_cb(qk_id_t id, qk_point_t p, double dist, void *ud) {
  (void)id, (void)p, (void)dist;
  ++*(size_t *)ud;
  return 0;
}

static void test_query_range_radius(void **state) {
  (void)state;
  qkt_rng_t r;
  qkt_rng_seed(&r, g_seed);
  const size_t n = 3000;
  qk_point_t *p = malloc(n * sizeof *p);
  qk_id_t *got = malloc(n * sizeof *got), *want = malloc(n * sizeof *want);
  qk_neighbor_t *gn = malloc(n * sizeof *gn), *wn = malloc(n * sizeof *wn);
  for (size_t d = 0; d < 4; d++)
    for (size_t c = 0; c < 3; c++) {
      qkt_points(&r, dists[d], p, n);
      qk_tree_t *t = build(p, n, caps[c]);
      for (size_t qi = 0; qi < 300; qi++) {
        qk_point_t a = rand_loc(&r), b = rand_loc(&r);
        qk_box_t box = {fmin(a.x, b.x), fmin(a.y, b.y), fmax(a.x, b.x), fmax(a.y, b.y)};
        if (qi % 50 == 1) box = (qk_box_t){-INFINITY, 0.25, INFINITY, 0.5};
        if (qi % 50 == 2) box = (qk_box_t){0.5, 0.5, 0.25, 0.75}; /* inverted: empty */
        if (qi % 50 == 3) box = (qk_box_t){a.x, a.y, a.x, a.y};   /* a single location */
        size_t ng = 0, nw = qko_range(p, n, box, want);
        assert_int_equal(qk_query_range_ids(t, box, got, n, &ng), QK_OK);
        qko_sort_ids(got, ng < n ? ng : n);
        if (ng != nw || memcmp(got, want, nw * sizeof *got))
          fail_msg("range query %zu: %zu ids, oracle %zu (seed %llu)", qi, ng, nw,
                   (unsigned long long)g_seed);
        size_t ncb = 0;
        assert_int_equal(qk_query_range(t, box, count_cb, &ncb), QK_OK);
        assert_int_equal(ncb, nw);

        qk_point_t q = rand_loc(&r);
        double rad = qi % 10 == 0 ? 0.0 : qkt_rng_range(&r, 0, 0.3);
        if (qi % 10 == 1 && n > 0) q = p[qkt_rng_below(&r, (uint32_t)n)];
        nw = qko_radius(p, n, q, rad, wn);
        assert_int_equal(qk_query_radius_list(t, q, rad, gn, n, &ng), QK_OK);
        qko_sort_by_id(gn, ng);
        assert_nb_equal(gn, ng, wn, nw, "radius", qi);
      }
      qk_tree_free(t);
    }
  free(p), free(got), free(want), free(gn), free(wn);
}

static void test_query_knn_all_k(void **state) {
  (void)state;
  qkt_rng_t r;
  qkt_rng_seed(&r, g_seed + 1);
  const size_t n = 60;
  qk_point_t p[60];
  qk_neighbor_t got[61], want[61];
  for (size_t d = 0; d < 4; d++)
    for (size_t c = 0; c < 3; c++) {
      qkt_points(&r, dists[d], p, n);
      qk_tree_t *t = build(p, n, caps[c]);
      for (size_t qi = 0; qi < 20; qi++) {
        qk_point_t q = rand_loc(&r);
        for (size_t k = 1; k <= n + 1; k++) {
          double cap = qi % 3 == 0 ? qkt_rng_range(&r, 0, 0.5) : INFINITY;
          size_t ng = 99;
          assert_int_equal(qk_query_knn(t, q, k, cap, got, &ng), QK_OK);
          size_t nw = qko_knn(p, NULL, n, q, k, cap, want);
          assert_nb_equal(got, ng, want, nw, "knn", qi * 100 + k);
        }
      }
      qk_tree_free(t);
    }
}

static void test_query_knn_large(void **state) {
  (void)state;
  qkt_rng_t r;
  qkt_rng_seed(&r, g_seed + 2);
  const size_t n = 20000;
  const size_t ks[] = {1, 2, 8, 33, 500};
  qk_point_t *p = malloc(n * sizeof *p);
  qk_neighbor_t *got = malloc(500 * sizeof *got), *want = malloc(500 * sizeof *want);
  for (size_t d = 0; d < 4; d++)
    for (size_t c = 0; c < 3; c++) {
      qkt_points(&r, dists[d], p, n);
      qk_tree_t *t = build(p, n, caps[c]);
      for (size_t qi = 0; qi < 40; qi++) {
        qk_point_t q = rand_loc(&r);
        size_t k = ks[qi % 5];
        double cap = qi % 4 == 0 ? 0.01 : INFINITY;
        size_t ng;
        assert_int_equal(qk_query_knn(t, q, k, cap, got, &ng), QK_OK);
        size_t nw = qko_knn(p, NULL, n, q, k, cap, want);
        assert_nb_equal(got, ng, want, nw, "knn-large", qi);
      }
      qk_tree_free(t);
    }
  free(p), free(got), free(want);
}

static void test_query_knn_after_mutation(void **state) {
  (void)state;
  qkt_rng_t r;
  qkt_rng_seed(&r, g_seed + 3);
  const size_t n0 = 500, extra = 1500;
  qk_point_t *p = malloc((n0 + extra) * sizeof *p);
  unsigned char *alive = calloc(n0 + extra, 1);
  qkt_points(&r, QKT_CLUSTERED, p, n0 + extra);
  qk_tree_options_t o;
  qk_tree_options_init(&o);
  o.capacity = 4;
  o.has_root = 1;
  o.root = (qk_square_t){0, 0, 1};
  qk_tree_t *t = NULL;
  assert_int_equal(qk_tree_build(p, n0, &o, &t), QK_OK);
  memset(alive, 1, n0);
  /* The model by id: inserts may reuse removed ids (index.h), so id != input index. */
  qk_point_t *by_id = malloc((n0 + extra) * sizeof *by_id);
  memcpy(by_id, p, n0 * sizeof *p);
  size_t next = n0, n_ids = n0;
  qk_neighbor_t got[16], want[16];
  for (int round = 0; round < 30; round++) {
    for (int j = 0; j < 50 && next < n0 + extra; j++) {
      qk_id_t id;
      assert_int_equal(qk_tree_insert(t, p[next], &id), QK_OK);
      assert_true(id <= n_ids && !(id < n_ids && alive[id]));
      if (id == n_ids) n_ids++;
      by_id[id] = p[next++];
      alive[id] = 1;
    }
    for (int j = 0; j < 30; j++) {
      qk_id_t id = qkt_rng_below(&r, (uint32_t)n_ids);
      if (alive[id]) {
        assert_int_equal(qk_tree_remove(t, id), QK_OK);
        alive[id] = 0;
      }
    }
    QKT_CHECK_TREE(t);
    for (int qi = 0; qi < 20; qi++) {
      qk_point_t q = rand_loc(&r);
      size_t ng, nw = qko_knn(by_id, alive, n_ids, q, 16, INFINITY, want);
      assert_int_equal(qk_query_knn(t, q, 16, INFINITY, got, &ng), QK_OK);
      assert_nb_equal(got, ng, want, nw, "knn-mut", (size_t)round * 100 + (size_t)qi);
    }
  }
  qk_tree_free(t);
  free(p), free(alive), free(by_id);
}

/* Half-open containment with the root's closed outer edges. */
static int square_holds(qk_square_t s, qk_square_t root, qk_point_t p) {
  int inx = (p.x > s.x || (s.x == root.x && p.x == s.x)) && p.x <= s.x + s.side;
  int iny = (p.y > s.y || (s.y == root.y && p.y == s.y)) && p.y <= s.y + s.side;
  return inx && iny;
}

static void test_query_locate(void **state) {
  (void)state;
  qkt_rng_t r;
  qkt_rng_seed(&r, g_seed + 4);
  const size_t n = 4000;
  qk_point_t *p = malloc(n * sizeof *p);
  for (size_t d = 0; d < 4; d++)
    for (size_t c = 0; c < 3; c++) {
      qkt_points(&r, dists[d], p, n);
      qk_tree_t *t = build(p, n, caps[c]);
      qk_tree_stats_t st;
      qk_tree_stats(t, &st);
      for (size_t i = 0; i < n; i += 7) {
        qk_location_t loc;
        qk_node_t leaf;
        assert_int_equal(qk_query_locate(t, p[i], &loc), QK_OK);
        assert_int_equal(qk_tree_leaf_of(t, (qk_id_t)i, &leaf), QK_OK);
        assert_int_equal(loc.leaf, leaf);
        int found = 0;
        for (size_t j = 0; j < loc.count; j++) found |= loc.ids[j] == i;
        assert_true(found);
      }
      for (size_t qi = 0; qi < 500; qi++) {
        qk_point_t q = rand_loc(&r);
        qk_location_t loc;
        qk_status_t s = qk_query_locate(t, q, &loc);
        int inside = q.x >= st.root.x && q.x <= st.root.x + st.root.side && q.y >= st.root.y &&
                     q.y <= st.root.y + st.root.side;
        if (!inside) {
          assert_int_equal(s, QK_ERR_OUTSIDE);
          continue;
        }
        assert_int_equal(s, QK_OK);
        assert_true(qk_tree_node_is_leaf(t, loc.leaf));
        assert_true(square_holds(loc.square, st.root, q));
        qk_node_info_t info;
        assert_int_equal(qk_tree_node_info(t, loc.leaf, &info), QK_OK);
        assert_int_equal(info.depth, loc.depth);
        assert_int_equal(info.count, loc.count);
        const qk_id_t *ids;
        size_t m;
        assert_int_equal(qk_tree_leaf_points(t, loc.leaf, NULL, NULL, &ids, &m), QK_OK);
        assert_int_equal(m, loc.count);
        assert_ptr_equal(ids, loc.ids);
        for (size_t j = 0; j < m; j++) {
          assert_true(loc.x[j] == p[ids[j]].x && loc.y[j] == p[ids[j]].y);
        }
      }
      qk_location_t loc;
      assert_int_equal(qk_query_locate(t, (qk_point_t){NAN, 0}, &loc), QK_ERR_NONFINITE);
      qk_tree_free(t);
    }
  free(p);
}

static void test_query_batch(void **state) {
  (void)state;
  qkt_rng_t r;
  qkt_rng_seed(&r, g_seed + 5);
  const size_t n = 5000, nq = 200, k = 5;
  qk_point_t *p = malloc(n * sizeof *p), *qs = malloc(nq * sizeof *qs);
  qkt_points(&r, QKT_UNIFORM, p, n);
  for (size_t i = 0; i < nq; i++) qs[i] = rand_loc(&r);
  qs[7].x = NAN;
  qk_tree_t *t = build(p, n, 8);
  qk_neighbor_t *out = malloc(nq * k * sizeof *out), one[5];
  size_t counts[200];
  assert_int_equal(qk_query_knn_batch(t, qs, nq, k, INFINITY, out, counts), QK_ERR_NONFINITE);
  for (size_t i = 0; i < nq; i++) {
    size_t m = 0;
    if (i == 7) {
      assert_int_equal(counts[i], 0);
      assert_int_equal(out[i * k].id, QK_NONE);
      continue;
    }
    assert_int_equal(qk_query_knn(t, qs[i], k, INFINITY, one, &m), QK_OK);
    assert_nb_equal(out + i * k, counts[i], one, m, "knn-batch", i);
  }
  qs[7].x = 0.5;
  /* Radius batch: first size it, then fill it. */
  size_t *off = malloc((nq + 1) * sizeof *off);
  assert_int_equal(qk_query_radius_batch(t, qs, nq, 0.05, NULL, 0, off), QK_OK);
  size_t total = off[nq];
  assert_true(total > 0);
  qk_neighbor_t *rb = malloc(total * sizeof *rb), *want = malloc(n * sizeof *want);
  assert_int_equal(qk_query_radius_batch(t, qs, nq, 0.05, rb, total, off), QK_OK);
  for (size_t i = 0; i < nq; i++) {
    size_t nw = qko_radius(p, n, qs[i], 0.05, want);
    qko_sort_by_id(rb + off[i], off[i + 1] - off[i]);
    assert_nb_equal(rb + off[i], off[i + 1] - off[i], want, nw, "radius-batch", i);
  }
  /* Locate batch. */
  qk_node_t *leaves = malloc(nq * sizeof *leaves);
  qs[3] = (qk_point_t){5, 5};
  assert_int_equal(qk_query_locate_batch(t, qs, nq, leaves), QK_OK);
  for (size_t i = 0; i < nq; i++) {
    qk_node_t l;
    if (qk_tree_find_leaf(t, qs[i], &l) != QK_OK) l = QK_NONE;
    assert_int_equal(leaves[i], l);
  }
  assert_int_equal(leaves[3], QK_NONE);
  /* A buffer too small still reports the full count. */
  size_t ng = 0;
  qk_id_t few[3];
  assert_int_equal(qk_query_range_ids(t, (qk_box_t){0, 0, 1, 1}, few, 3, &ng), QK_OK);
  assert_int_equal(ng, n);
  qk_tree_free(t);
  free(p), free(qs), free(out), free(off), free(rb), free(want), free(leaves);
}

/* Batch kNN borrows memory for its ordering; when none is to be had it must still answer
 * correctly, in the given order. */
static void test_query_batch_nomem(void **state) {
  (void)state;
  qkt_rng_t r;
  qkt_rng_seed(&r, g_seed + 9);
  const size_t n = 2000, nq = 300, k = 3;
  qk_point_t *p = malloc(n * sizeof *p), *qs = malloc(nq * sizeof *qs);
  qkt_points(&r, QKT_CLUSTERED, p, n);
  for (size_t i = 0; i < nq; i++) qs[i] = rand_loc(&r);
  qkt_alloc_t st;
  qk_allocator_t a = qkt_alloc_make(&st);
  qk_tree_t *t = build_with(p, n, 8, &a);
  qk_neighbor_t *out = malloc(nq * k * sizeof *out), want[3];
  for (int failing = 0; failing < 2; failing++) {
    size_t before = st.calls;
    st.fail_at = failing ? st.calls + 1 : 0;
    assert_int_equal(qk_query_knn_batch(t, qs, nq, k, INFINITY, out, NULL), QK_OK);
    if (failing)
      assert_true(st.failed);
    else
      assert_true(st.calls > before); /* the ordering was allocated */
    for (size_t i = 0; i < nq; i++) {
      size_t nw = qko_knn(p, NULL, n, qs[i], k, INFINITY, want);
      assert_nb_equal(out + i * k, nw, want, nw, "knn-batch-nomem", i);
    }
  }
  st.fail_at = 0;
  qk_tree_free(t);
  assert_int_equal(st.live_blocks, 0);
  free(p), free(qs), free(out);
}

static int stop_after_3(qk_id_t id, qk_point_t p, double dist, void *ud) {
  (void)id, (void)p, (void)dist;
  return ++*(int *)ud == 3;
}

/*
 * kNN where squared distances leave the double range: points 2e154 and 3e154 from the
 * query square to infinity alike, so a plain search would rank point 0 first at distance
 * inf; the query is refused (QK_ERR_LIMIT) instead, single and batch. Just inside the
 * range (2^509) the answer is the brute-force one.
 */
static void test_query_knn_distance_range(void **state) {
  (void)state;
  const double scales[] = {1e154, 0x1p509 / 4};
  for (int s = 0; s < 2; s++) {
    const qk_point_t p[2] = {{3 * scales[s], 0}, {2 * scales[s], 0}};
    qk_tree_t *t = NULL;
    assert_int_equal(qk_tree_build(p, 2, NULL, &t), QK_OK);
    qk_neighbor_t nb[2];
    size_t m = 9, counts[2];
    const qk_point_t qs[2] = {{0, 0}, {0, 0}};
    qk_status_t st = qk_query_knn(t, qs[0], 1, INFINITY, nb, &m);
    qk_status_t bt = qk_query_knn_batch(t, qs, 2, 1, INFINITY, nb, counts);
    if (s == 0) {
      assert_int_equal(st, QK_ERR_LIMIT);
      assert_int_equal(m, 0);
      assert_int_equal(bt, QK_ERR_LIMIT);
      assert_int_equal(counts[0], 0);
    } else {
      assert_int_equal(st, QK_OK);
      assert_int_equal(m, 1);
      assert_int_equal(bt, QK_OK);
      assert_int_equal(nb[0].id, 1);
      assert_true(nb[0].dist == 2 * scales[s]);
    }
    /* A query beyond the range is refused even on a small tree. */
    if (s == 1) {
      qk_tree_free(t);
      const qk_point_t u[1] = {{0.5, 0.5}};
      assert_int_equal(qk_tree_build(u, 1, NULL, &t), QK_OK);
      assert_int_equal(qk_query_knn(t, (qk_point_t){1e300, 0}, 1, INFINITY, nb, &m), QK_ERR_LIMIT);
      assert_int_equal(qk_query_knn(t, (qk_point_t){-1e150, 1e150}, 1, INFINITY, nb, &m), QK_OK);
      assert_int_equal(m, 1);
    }
    qk_tree_free(t);
  }
}

/*
 * The kNN argument checks in every combination of query coordinate and limit, single and
 * batch: a non-finite query first (QK_ERR_NONFINITE), then a NaN or negative limit
 * (QK_ERR_INVALID; a batch checks its limit first), then a coordinate beyond 2^510
 * (QK_ERR_LIMIT), checked against those
 * rules written out here. The checks take a shortcut for the common case (every value in
 * range, both axes at once, query/query_internal.h): each value of the table fails it in
 * its own way, and -0.0, 0, infinity and 2^510 itself must pass.
 */
static void test_query_knn_check_order(void **state) {
  (void)state;
  const qk_point_t p[3] = {{0.25, 0.5}, {0.75, 0.5}, {0.5, 0.9}};
  qk_tree_t *t = NULL;
  assert_int_equal(qk_tree_build(p, 3, NULL, &t), QK_OK);
  const double big = 0x1p510, over = nextafter(0x1p510, INFINITY);
  const double coords[] = {0.5, -0.0, big, -big, over, -over, 1e300, INFINITY, -INFINITY, NAN};
  const double limits[] = {INFINITY, 1.0, 0.0, -0.0, -1.0, -INFINITY, NAN};
  const size_t nc = sizeof coords / sizeof coords[0], nl = sizeof limits / sizeof limits[0];
  int tag = 0;
  for (size_t i = 0; i < nc; i++)
    for (size_t j = 0; j < nc; j++)
      for (size_t l = 0; l < nl; l++, tag++) {
        const qk_point_t q = {coords[i], coords[j]};
        const double md = limits[l];
        qk_status_t want = QK_OK;
        if (!isfinite(q.x) || !isfinite(q.y))
          want = QK_ERR_NONFINITE;
        else if (isnan(md) || md < 0)
          want = QK_ERR_INVALID;
        else if (fabs(q.x) > 0x1p510 || fabs(q.y) > 0x1p510)
          want = QK_ERR_LIMIT;
        /* The batch checks its one limit before any query. */
        const qk_status_t want_b = (isnan(md) || md < 0) ? QK_ERR_INVALID : want;
        for (size_t k = 1; k <= 4; k += 3) {
          qk_neighbor_t nb[4];
          size_t m = 9, counts[1] = {9};
          if (qk_query_knn(t, q, k, md, nb, &m) != want ||
              qk_query_knn_batch(t, &q, 1, k, md, nb, counts) != want_b)
            fail_msg("knn check: case %d (%g, %g) limit %g k %zu", tag, q.x, q.y, md, k);
          if (want != QK_OK) continue;
          /* In range: the brute-force answer. */
          qk_neighbor_t w[4];
          const size_t nw = qko_knn(p, NULL, 3, q, k, md, w);
          assert_nb_equal(nb, counts[0], w, nw, "knn-check-batch", (size_t)tag);
          assert_int_equal(qk_query_knn(t, q, k, md, nb, &m), QK_OK);
          assert_nb_equal(nb, m, w, nw, "knn-check", (size_t)tag);
        }
      }
  qk_tree_free(t);
}

static void test_query_stop_and_bad_args(void **state) {
  (void)state;
  qk_point_t p[100];
  qkt_rng_t r;
  qkt_rng_seed(&r, g_seed + 6);
  qkt_points(&r, QKT_UNIFORM, p, 100);
  qk_tree_t *t = build(p, 100, 4);
  int calls = 0;
  assert_int_equal(qk_query_range(t, (qk_box_t){0, 0, 1, 1}, stop_after_3, &calls), QK_OK);
  assert_int_equal(calls, 3);
  calls = 0;
  assert_int_equal(qk_query_radius(t, (qk_point_t){0.5, 0.5}, 2, stop_after_3, &calls), QK_OK);
  assert_int_equal(calls, 3);
  qk_neighbor_t nb[4];
  size_t m;
  assert_int_equal(qk_query_radius(t, (qk_point_t){0.5, 0.5}, -1, count_cb, &m), QK_ERR_INVALID);
  assert_int_equal(qk_query_radius(t, (qk_point_t){NAN, 0.5}, 1, count_cb, &m), QK_ERR_NONFINITE);
  assert_int_equal(qk_query_radius(t, (qk_point_t){0.5, 0.5}, NAN, count_cb, &m), QK_ERR_NONFINITE);
  assert_int_equal(qk_query_range(t, (qk_box_t){NAN, 0, 1, 1}, count_cb, &m), QK_ERR_NONFINITE);
  assert_int_equal(qk_query_knn(t, (qk_point_t){INFINITY, 0}, 4, INFINITY, nb, &m),
                   QK_ERR_NONFINITE);
  assert_int_equal(qk_query_knn(t, (qk_point_t){0, 0}, 4, -1, nb, &m), QK_ERR_INVALID);
  assert_int_equal(qk_query_knn(t, (qk_point_t){0, 0}, 4, NAN, nb, &m), QK_ERR_INVALID);
  assert_int_equal(qk_query_knn(t, (qk_point_t){0, 0}, 0, INFINITY, NULL, &m), QK_OK);
  assert_int_equal(m, 0);
  assert_int_equal(qk_query_knn(NULL, (qk_point_t){0, 0}, 1, INFINITY, nb, &m), QK_ERR_INVALID);
  assert_int_equal(qk_query_range_ids(t, (qk_box_t){0, 0, 1, 1}, NULL, 5, &m), QK_ERR_INVALID);
  /* Either handle missing is invalid on its own (the mutation sweep found neither case
   * tested: `!tree && !loc` passed). */
  /* qk_query_radius_list's own argument checks (no other test reached them). */
  assert_int_equal(qk_query_radius_list(NULL, p[0], 1, nb, 4, &m), QK_ERR_INVALID);
  assert_int_equal(qk_query_radius_list(t, p[0], 1, nb, 4, NULL), QK_ERR_INVALID);
  assert_int_equal(qk_query_radius_list(t, p[0], 1, NULL, 4, &m), QK_ERR_INVALID);
  qk_location_t lc;
  assert_int_equal(qk_query_locate(NULL, p[0], &lc), QK_ERR_INVALID);
  assert_int_equal(qk_query_locate(t, p[0], NULL), QK_ERR_INVALID);
  /* Radius of infinity reaches everything; a zero radius on a stored point finds it. */
  assert_int_equal(qk_query_radius_list(t, (qk_point_t){-1e300, 1e300}, INFINITY, NULL, 0, &m),
                   QK_OK);
  assert_int_equal(m, 100);
  assert_int_equal(qk_query_radius_list(t, p[17], 0, nb, 4, &m), QK_OK);
  assert_true(m >= 1);
  qk_tree_free(t);

  /* An empty tree answers everything with nothing. */
  assert_int_equal(qk_tree_build(NULL, 0, NULL, &t), QK_OK);
  assert_int_equal(qk_query_knn(t, (qk_point_t){0, 0}, 4, INFINITY, nb, &m), QK_OK);
  assert_int_equal(m, 0);
  assert_int_equal(qk_query_range_ids(t, (qk_box_t){-1, -1, 2, 2}, NULL, 0, &m), QK_OK);
  assert_int_equal(m, 0);
  assert_int_equal(qk_query_radius_list(t, (qk_point_t){0, 0}, 5, NULL, 0, &m), QK_OK);
  assert_int_equal(m, 0);
  qk_location_t loc;
  assert_int_equal(qk_query_locate(t, (qk_point_t){0.5, 0.5}, &loc), QK_OK);
  assert_int_equal(loc.count, 0);
  qk_tree_free(t);
}

/* Threads: each runs the same queries and compares with answers computed beforehand. */
typedef struct thr {
  const qk_tree_t *t;
  const qk_point_t *qs;
  size_t nq, k;
  const qk_neighbor_t *expect;
  const size_t *expect_radius;
  int ok;
} thr_t;

static void *thread_main(void *arg) {
  thr_t *a = arg;
  qk_neighbor_t got[8];
  a->ok = 1;
  for (int rep = 0; rep < 5; rep++)
    for (size_t i = 0; i < a->nq; i++) {
      size_t m, cnt;
      if (qk_query_knn(a->t, a->qs[i], a->k, INFINITY, got, &m) != QK_OK || m != a->k) a->ok = 0;
      for (size_t j = 0; j < m && j < a->k; j++)
        if (got[j].id != a->expect[i * a->k + j].id) a->ok = 0;
      if (qk_query_radius_list(a->t, a->qs[i], 0.02, NULL, 0, &cnt) != QK_OK ||
          cnt != a->expect_radius[i])
        a->ok = 0;
      qk_location_t loc;
      if (qk_query_locate(a->t, a->qs[i], &loc) != QK_OK) a->ok = 0;
      if (!a->ok) return NULL;
    }
  return NULL;
}

static void test_query_threads(void **state) {
  (void)state;
  qkt_rng_t r;
  qkt_rng_seed(&r, g_seed + 7);
  const size_t n = 20000, nq = 500, k = 8;
  qk_point_t *p = malloc(n * sizeof *p), *qs = malloc(nq * sizeof *qs);
  qkt_points(&r, QKT_CLUSTERED, p, n);
  qkt_points(&r, QKT_UNIFORM, qs, nq);
  qk_tree_options_t o;
  qk_tree_options_init(&o);
  o.capacity = 16;
  o.has_root = 1;
  o.root = (qk_square_t){0, 0, 1}; /* so that every query can be located */
  qk_tree_t *t = NULL;
  assert_int_equal(qk_tree_build(p, n, &o, &t), QK_OK);
  qk_neighbor_t *expect = malloc(nq * k * sizeof *expect);
  size_t *er = malloc(nq * sizeof *er);
  for (size_t i = 0; i < nq; i++) {
    qko_knn(p, NULL, n, qs[i], k, INFINITY, expect + i * k);
  }
  qk_neighbor_t *tmp = malloc(n * sizeof *tmp);
  for (size_t i = 0; i < nq; i++) er[i] = qko_radius(p, n, qs[i], 0.02, tmp);
  free(tmp);
  pthread_t th[4];
  thr_t args[4];
  for (int i = 0; i < 4; i++) {
    args[i] = (thr_t){t, qs, nq, k, expect, er, 0};
    assert_int_equal(pthread_create(&th[i], NULL, thread_main, &args[i]), 0);
  }
  for (int i = 0; i < 4; i++) pthread_join(th[i], NULL);
  for (int i = 0; i < 4; i++) {
    if (!args[i].ok)
      fail_msg("thread %d got a wrong answer (seed %llu)", i, (unsigned long long)g_seed);
  }
  qk_tree_free(t);
  free(p), free(qs), free(expect), free(er);
}

/*
 * Leaves far over capacity (a shallow depth cap over clumps of equal points), so that the
 * leaf scans work in several chunks and meet many exactly equal distances: kNN for k
 * around the sorted-array limit (32) and beyond, single and batch, against brute force.
 */
static void test_query_knn_big_leaves(void **state) {
  (void)state;
  qkt_rng_t r;
  qkt_rng_seed(&r, g_seed + 11);
  const size_t n = 3000, nq = 300;
  const size_t ks[] = {1, 2, 7, 31, 32, 33, 100};
  qk_point_t *p = malloc(n * sizeof *p), *qs = malloc(nq * sizeof *qs);
  for (size_t i = 0; i < n; i++) {
    if (i % 3 == 0) {
      p[i] = (qk_point_t){qkt_rng_unit(&r), qkt_rng_unit(&r)};
    } else {
      /* One of 9 clump centres, on the midlines of the first levels. */
      size_t c = qkt_rng_below(&r, 9);
      p[i] = (qk_point_t){0.25 * (double)(1 + c % 3), 0.25 * (double)(1 + c / 3)};
    }
  }
  for (size_t i = 0; i < nq; i++) qs[i] = i % 4 == 0 ? p[qkt_rng_below(&r, n)] : rand_loc(&r);
  qk_tree_options_t o;
  qk_tree_options_init(&o);
  o.capacity = 4;
  o.max_depth = 3;
  o.has_root = 1;
  o.root = (qk_square_t){0, 0, 1};
  qk_tree_t *t = NULL;
  assert_int_equal(qk_tree_build(p, n, &o, &t), QK_OK);
  QKT_CHECK_TREE(t);
  qk_tree_stats_t st;
  qk_tree_stats(t, &st);
  assert_true(st.max_leaf_points > 128); /* several chunks of 64 */
  qk_neighbor_t *got = malloc(nq * 100 * sizeof *got), *want = malloc(100 * sizeof *want);
  size_t *counts = malloc(nq * sizeof *counts);
  for (size_t ki = 0; ki < sizeof ks / sizeof ks[0]; ki++) {
    const size_t k = ks[ki];
    for (size_t i = 0; i < nq; i++) {
      size_t ng;
      double cap = i % 5 == 0 ? 0.1 : INFINITY;
      assert_int_equal(qk_query_knn(t, qs[i], k, cap, got, &ng), QK_OK);
      size_t nw = qko_knn(p, NULL, n, qs[i], k, cap, want);
      assert_nb_equal(got, ng, want, nw, "knn-big-leaves", i * 1000 + k);
    }
    assert_int_equal(qk_query_knn_batch(t, qs, nq, k, INFINITY, got, counts), QK_OK);
    for (size_t i = 0; i < nq; i++) {
      size_t nw = qko_knn(p, NULL, n, qs[i], k, INFINITY, want);
      assert_nb_equal(got + i * k, counts[i], want, nw, "knn-big-leaves-batch", i * 1000 + k);
    }
  }
  qk_tree_free(t);
  free(p), free(qs), free(got), free(want), free(counts);
}

/*
 * Batch kNN answers in Z-order, each query starting from the path of the one before: a
 * large batch over every point set and capacity, with queries on the split lines, outside
 * the root and repeated, on one and on two threads, against brute force.
 */
static void test_query_knn_batch_paths(void **state) {
  (void)state;
  qkt_rng_t r;
  qkt_rng_seed(&r, g_seed + 12);
  const size_t n = 4000, nq = 1000;
  const size_t ks[] = {1, 8, 32};
  qk_point_t *p = malloc(n * sizeof *p), *qs = malloc(nq * sizeof *qs);
  qk_neighbor_t *got = malloc(nq * 32 * sizeof *got), *want = malloc(nq * 32 * sizeof *want);
  size_t *counts = malloc(nq * sizeof *counts);
  for (size_t d = 0; d < 4; d++)
    for (size_t c = 0; c < 3; c++) {
      qkt_points(&r, dists[d], p, n);
      for (size_t i = 0; i < nq; i++)
        qs[i] = i % 7 == 0 ? p[qkt_rng_below(&r, n)] : i % 11 == 0 ? qs[i / 2] : rand_loc(&r);
      qk_tree_t *t = build(p, n, caps[c]);
      /* brute force once for the largest k; a smaller k's answer is its prefix */
      for (size_t i = 0; i < nq; i++)
        assert_int_equal(qko_knn(p, NULL, n, qs[i], 32, INFINITY, want + i * 32), 32);
      for (unsigned threads = 1; threads <= 2; threads++) {
        qk_tree_set_threads(t, threads);
        const size_t k = ks[(d + c + threads) % 3];
        assert_int_equal(qk_query_knn_batch(t, qs, nq, k, INFINITY, got, counts), QK_OK);
        for (size_t i = 0; i < nq; i++)
          assert_nb_equal(got + i * k, counts[i], want + i * 32, k, "knn-batch-paths",
                          d * 100000 + c * 10000 + i);
      }
      qk_tree_free(t);
    }
  free(p), free(qs), free(got), free(want), free(counts);
}

/*
 * The k = 1 search keeps its best as a point slot and reads ids only to break ties
 * (issue 11): points on a dyadic grid, many duplicated, with ids in random order, so that
 * queries on grid points and cell centres see exact ties within a leaf, within one scan
 * chunk and across sibling and non-sibling leaves; caps equal to a grid distance (a point
 * exactly at the cap counts); queries far outside the root; k larger than the tree.
 * Single and batch calls (the batch is large enough to be answered in Z-order with its
 * look-ahead) against brute force.
 */
static void test_query_knn1_ties(void **state) {
  (void)state;
  qkt_rng_t r;
  qkt_rng_seed(&r, g_seed + 13);
  const size_t n = 1500, nq = 400;
  qk_point_t *p = malloc(n * sizeof *p), *qs = malloc(nq * sizeof *qs);
  qk_neighbor_t *got = malloc(nq * 4 * sizeof *got), want[4];
  size_t *counts = malloc(nq * sizeof *counts);
  for (size_t i = 0; i < n; i++) /* 17 x 17 grid points, about 5 points at each */
    p[i] = (qk_point_t){qkt_rng_below(&r, 17) / 16.0, qkt_rng_below(&r, 17) / 16.0};
  for (size_t i = 0; i < nq; i++) {
    switch (i % 5) {
    case 0: /* a grid point (often a stored one) */
      qs[i] = (qk_point_t){qkt_rng_below(&r, 17) / 16.0, qkt_rng_below(&r, 17) / 16.0};
      break;
    case 1: /* a cell centre: four grid points at the same distance */
      qs[i] = (qk_point_t){(2.0 * qkt_rng_below(&r, 16) + 1) / 32.0,
                           (2.0 * qkt_rng_below(&r, 16) + 1) / 32.0};
      break;
    case 2: /* far outside */
      qs[i] = (qk_point_t){qkt_rng_range(&r, -1e6, 1e6), i % 2 ? 1e6 : -3.0};
      break;
    default:
      qs[i] = rand_loc(&r);
    }
  }
  const double limits[] = {INFINITY, 1.0 / 16, 1.0 / 32};
  for (size_t c = 0; c < 3; c++) {
    qk_tree_t *t = build(p, n, caps[c]);
    for (size_t li = 0; li < 3; li++) {
      const double cap = limits[li];
      for (size_t i = 0; i < nq; i++) {
        size_t ng;
        assert_int_equal(qk_query_knn(t, qs[i], 1, cap, got, &ng), QK_OK);
        size_t nw = qko_knn(p, NULL, n, qs[i], 1, cap, want);
        assert_nb_equal(got, ng, want, nw, "knn1-ties", c * 10000 + li * 1000 + i);
      }
      assert_int_equal(qk_query_knn_batch(t, qs, nq, 1, cap, got, counts), QK_OK);
      for (size_t i = 0; i < nq; i++) {
        size_t nw = qko_knn(p, NULL, n, qs[i], 1, cap, want);
        assert_nb_equal(got + i, counts[i], want, nw, "knn1-ties-batch", c * 10000 + li * 1000 + i);
      }
    }
    qk_tree_free(t);
  }
  /* More neighbours asked for than the tree holds: all of them, by (distance, id). */
  qk_tree_t *t = build(p, 3, 1);
  for (size_t k = 1; k <= 4; k++) {
    assert_int_equal(qk_query_knn_batch(t, qs, nq, k, INFINITY, got, counts), QK_OK);
    for (size_t i = 0; i < nq; i++) {
      size_t ng, nw = qko_knn(p, NULL, 3, qs[i], k, INFINITY, want);
      assert_nb_equal(got + i * k, counts[i], want, nw, "knn-k-over-n-batch", k * 1000 + i);
      assert_int_equal(qk_query_knn(t, qs[i], k, INFINITY, got, &ng), QK_OK);
      assert_nb_equal(got, ng, want, nw, "knn-k-over-n", k * 1000 + i);
    }
  }
  qk_tree_free(t);
  free(p), free(qs), free(got), free(counts);
}

/*
 * k > 1 on a duplicated dyadic grid (many equal distances, so the (distance, id) order
 * decides which of them make the k), with caps equal to grid distances, single and batch;
 * and on a dense cluster beside sparse points, where the first limit a search guesses
 * from the density of a cell on its path (query/knn.c) holds fewer than k points and the
 * search has to run again with the caller's limit.
 */
static void test_query_knn_ties_k(void **state) {
  (void)state;
  qkt_rng_t r;
  qkt_rng_seed(&r, g_seed + 14);
  const size_t n = 1500, nq = 60;
  const size_t ks[] = {2, 5, 8, 32, 33};
  qk_point_t *p = malloc(n * sizeof *p), *qs = malloc(nq * sizeof *qs);
  qk_neighbor_t *got = malloc(nq * 33 * sizeof *got), one[33], want[33];
  size_t *counts = malloc(nq * sizeof *counts);
  for (int set = 0; set < 2; set++) {
    for (size_t i = 0; i < n; i++) {
      if (set == 0) /* 17 x 17 grid points, about 5 at each */
        p[i] = (qk_point_t){qkt_rng_below(&r, 17) / 16.0, qkt_rng_below(&r, 17) / 16.0};
      else if (i % 50 == 0) /* sparse, over the unit square */
        p[i] = (qk_point_t){qkt_rng_unit(&r), qkt_rng_unit(&r)};
      else /* a cluster of side 2^-12 */
        p[i] = (qk_point_t){0.25 + qkt_rng_unit(&r) * 0x1p-12, 0.25 + qkt_rng_unit(&r) * 0x1p-12};
    }
    for (size_t i = 0; i < nq; i++) {
      if (set == 0 && i % 3 == 0) /* a cell centre: four grid points at the same distance */
        qs[i] = (qk_point_t){(2.0 * qkt_rng_below(&r, 16) + 1) / 32.0,
                             (2.0 * qkt_rng_below(&r, 16) + 1) / 32.0};
      else if (set == 1 && i % 2 == 0) /* next to the cluster */
        qs[i] = (qk_point_t){0.25 + qkt_rng_range(&r, -0.01, 0.01),
                             0.25 + qkt_rng_range(&r, -0.01, 0.01)};
      else
        qs[i] = rand_loc(&r);
    }
    const double limits[] = {INFINITY, 1.0 / 16, 1.0 / 32};
    for (size_t c = 0; c < 3; c++) {
      qk_tree_t *t = build(p, n, caps[c]);
      for (size_t ki = 0; ki < sizeof ks / sizeof *ks; ki++) {
        const size_t k = ks[ki];
        const double cap = limits[(ki + c) % 3];
        assert_int_equal(qk_query_knn_batch(t, qs, nq, k, cap, got, counts), QK_OK);
        for (size_t i = 0; i < nq; i++) {
          const size_t tag = (size_t)set * 100000 + c * 10000 + k * 100 + i;
          size_t ng, nw = qko_knn(p, NULL, n, qs[i], k, cap, want);
          assert_int_equal(qk_query_knn(t, qs[i], k, cap, one, &ng), QK_OK);
          assert_nb_equal(one, ng, want, nw, "knn-ties-k", tag);
          assert_nb_equal(got + i * k, counts[i], want, nw, "knn-ties-k-batch", tag);
        }
      }
      qk_tree_free(t);
    }
  }
  free(p), free(qs), free(got), free(counts);
}

/*
 * The k-th bound and the tie order for k = 8, 32 (the sorted array's limit) and 100 (more
 * than a leaf holds) on clustered points, on a few heavily duplicated locations and on
 * clustered points with every third one a copy of an earlier one: queries on stored
 * points (runs of distance 0), between two stored points (equal distances) and at random;
 * caps equal to the oracle's k-th and (k/2)-th distances (a point exactly at the cap
 * counts, so a search that prunes or rejects at the bound with < instead of <= loses it)
 * and just below the k-th. Single calls and batches at capacities 4 and 32, against
 * brute force.
 */
static void test_query_knn_kth_bound(void **state) {
  (void)state;
  qkt_rng_t r;
  qkt_rng_seed(&r, g_seed + 15);
  const size_t n = 6000, nq = 120;
  const size_t ks[] = {8, 32, 100};
  const uint32_t bcaps[] = {4, 32};
  qk_point_t *p = malloc(n * sizeof *p), *qs = malloc(nq * sizeof *qs);
  qk_neighbor_t *got = malloc(nq * 100 * sizeof *got), *full = malloc(nq * 100 * sizeof *full);
  qk_neighbor_t one[100];
  size_t *counts = malloc(nq * sizeof *counts);
  for (int set = 0; set < 3; set++) {
    qkt_points(&r, set == 1 ? QKT_DUPLICATES : QKT_CLUSTERED, p, n);
    if (set == 2)
      for (size_t i = 3; i < n; i += 3) p[i] = p[qkt_rng_below(&r, (uint32_t)i)];
    for (size_t i = 0; i < nq; i++) {
      const qk_point_t a = p[qkt_rng_below(&r, (uint32_t)n)], b = p[qkt_rng_below(&r, (uint32_t)n)];
      qs[i] = i % 3 == 0   ? a
              : i % 3 == 1 ? (qk_point_t){0.5 * (a.x + b.x), 0.5 * (a.y + b.y)}
                           : rand_loc(&r);
    }
    /* Brute force once per query for the largest k: the answer for a smaller k is its
     * prefix (the order is total), and under a cap the prefix the cap holds exactly. */
    for (size_t i = 0; i < nq; i++)
      assert_int_equal(qko_knn(p, NULL, n, qs[i], 100, INFINITY, full + i * 100), 100);
    for (size_t c = 0; c < 2; c++) {
      qk_tree_t *t = build(p, n, bcaps[c]);
      for (size_t ki = 0; ki < 3; ki++) {
        const size_t k = ks[ki];
        assert_int_equal(qk_query_knn_batch(t, qs, nq, k, INFINITY, got, counts), QK_OK);
        for (size_t i = 0; i < nq; i++) {
          const size_t tag = (size_t)set * 100000 + c * 10000 + k * 100 + i;
          const qk_neighbor_t *want = full + i * 100;
          size_t ng;
          assert_nb_equal(got + i * k, counts[i], want, k, "knn-kth-batch", tag);
          const double caps_k[] = {INFINITY, want[k - 1].dist, want[k / 2 - 1].dist,
                                   nextafter(want[k - 1].dist, 0)};
          for (size_t j = 0; j < 4; j++) {
            size_t nw = 0;
            while (nw < k && (isinf(caps_k[j]) || qko_within(p[want[nw].id].x, p[want[nw].id].y,
                                                             qs[i].x, qs[i].y, caps_k[j], 0)))
              nw++;
            assert_int_equal(qk_query_knn(t, qs[i], k, caps_k[j], one, &ng), QK_OK);
            assert_nb_equal(one, ng, want, nw, "knn-kth", tag * 10 + j);
          }
        }
      }
      qk_tree_free(t);
    }
  }
  free(p), free(qs), free(got), free(counts), free(full);
}

/*
 * Queries on the lines the climb bounds by (issue 11, thirteenth session): points uniform
 * in a box off the origin whose side is not a power of two (the tree's squares are
 * rounded), queries at the corners, edge midpoints and centres of leaves' squares and one
 * unit in the last place off them, where the gaps to the neighbouring squares are 0 or
 * nearly so on both axes and the siblings' bounds tie; k = 2, 3, 8, 17, 32 and 33, single
 * calls, capacities 1, 4 and 32, against brute force.
 */
static void test_query_knn_cell_lines(void **state) {
  (void)state;
  qkt_rng_t r;
  qkt_rng_seed(&r, g_seed + 19);
  const size_t n = 3000;
  const size_t ks[] = {2, 3, 8, 17, 32, 33};
  qk_point_t *p = malloc(n * sizeof *p);
  qk_neighbor_t got[33], want[33];
  for (size_t i = 0; i < n; i++)
    p[i] = (qk_point_t){-3.3 + 10.4 * qkt_rng_unit(&r), 0.7 + 10.4 * qkt_rng_unit(&r)};
  for (size_t c = 0; c < 3; c++) {
    qk_tree_t *t = build(p, n, caps[c]);
    for (size_t j = 0; j < 40; j++) {
      qk_location_t loc;
      assert_int_equal(qk_query_locate(t, p[qkt_rng_below(&r, (uint32_t)n)], &loc), QK_OK);
      const qk_square_t sq = loc.square;
      for (unsigned a = 0; a < 9; a++) {
        const double fx[3] = {sq.x, sq.x + 0.5 * sq.side, sq.x + sq.side};
        const double fy[3] = {sq.y, sq.y + 0.5 * sq.side, sq.y + sq.side};
        for (int off = 0; off < 3; off++) {
          qk_point_t q = {fx[a % 3], fy[a / 3]};
          if (off == 1) q = (qk_point_t){nextafter(q.x, -INFINITY), nextafter(q.y, INFINITY)};
          if (off == 2) q = (qk_point_t){nextafter(q.x, INFINITY), nextafter(q.y, -INFINITY)};
          /* brute force once for the largest k; a smaller k's answer is its prefix */
          const size_t nall = qko_knn(p, NULL, n, q, 33, INFINITY, want);
          for (size_t ki = 0; ki < 6; ki++) {
            const size_t k = ks[ki], tag = c * 100000 + j * 1000 + a * 100 + (size_t)off * 10 + ki;
            size_t ng;
            assert_int_equal(qk_query_knn(t, q, k, INFINITY, got, &ng), QK_OK);
            assert_nb_equal(got, ng, want, nall < k ? nall : k, "knn-cell-lines", tag);
          }
        }
      }
    }
    qk_tree_free(t);
  }
  free(p);
}

/*
 * Distances that differ only in the last bits of their squares: the sorted search sorts
 * its first k candidates by keys that drop the six low bits of the squared distance
 * (query/knn.c, fill_sort), so the order of such points, and of exactly equal ones (by
 * id), must come from the exact comparison. Points at x = 1/4 + j 2^-54 on the four
 * half-axes from the query (squares about 2 units in the last place apart; the four
 * directions tie exactly), ids in a random order, with random points around; k from 2 to
 * 32 and 33, with and without caps at those distances, single and batch, at capacities 1,
 * 4 and 32, against brute force.
 */
static void test_query_knn_near_ties(void **state) {
  (void)state;
  qkt_rng_t r;
  qkt_rng_seed(&r, g_seed + 16);
  const size_t nj = 24, n = 4 * nj + 200, nq = 6;
  qk_point_t *p = malloc(n * sizeof *p);
  qk_neighbor_t *got = malloc(nq * 33 * sizeof *got), one[33], want[33];
  size_t *counts = malloc(nq * sizeof *counts);
  for (size_t j = 0; j < nj; j++) {
    const double x = 0.25 + (double)j * 0x1p-54;
    p[4 * j] = (qk_point_t){x, 0};
    p[4 * j + 1] = (qk_point_t){0, x};
    p[4 * j + 2] = (qk_point_t){-x, 0};
    p[4 * j + 3] = (qk_point_t){0, -x};
  }
  for (size_t i = 4 * nj; i < n; i++)
    p[i] = (qk_point_t){qkt_rng_range(&r, -1, 1), qkt_rng_range(&r, -1, 1)};
  for (size_t i = n - 1; i > 0; i--) { /* ids in a random order */
    const size_t j = qkt_rng_below(&r, (uint32_t)(i + 1));
    const qk_point_t v = p[i];
    p[i] = p[j], p[j] = v;
  }
  /* The origin (the near ties), tiny offsets of it, and the ends of two rays. */
  const qk_point_t qs[] = {{0, 0},    {0x1p-60, 0},        {0, -0x1p-58}, {0x1p-70, 0x1p-70},
                           {0.25, 0}, {-0.25 - 0x1p-53, 0}};
  for (size_t c = 0; c < 3; c++) {
    qk_tree_t *t = build(p, n, caps[c]);
    for (size_t k = 2; k <= 33; k++) {
      const double limits[] = {INFINITY, 0.25 + 5 * 0x1p-54, 0.25 + 0x1p-54};
      const double cap = limits[k % 3];
      assert_int_equal(qk_query_knn_batch(t, qs, nq, k, cap, got, counts), QK_OK);
      for (size_t i = 0; i < nq; i++) {
        const size_t tag = c * 10000 + k * 100 + i;
        size_t ng, nw = qko_knn(p, NULL, n, qs[i], k, cap, want);
        assert_int_equal(qk_query_knn(t, qs[i], k, cap, one, &ng), QK_OK);
        assert_nb_equal(one, ng, want, nw, "knn-near-ties", tag);
        assert_nb_equal(got + i * k, counts[i], want, nw, "knn-near-ties-batch", tag);
      }
    }
    qk_tree_free(t);
  }
  free(p), free(got), free(counts);
}

/* The 80 points at distance exactly 5 s from c on the (3, 4, 5) triangles' corners, and
 * each one ulp off in x (both ways) and in y (both ways), appended to p[n ..): the new n. */
static size_t on_circle_5s(qk_point_t *p, size_t n, qk_point_t c, double s) {
  const double tr[][2] = {{3, 4}, {4, 3}, {5, 0}, {0, 5}};
  for (int t = 0; t < 4; t++)
    for (int sg = 0; sg < 4; sg++) {
      double x = c.x + (sg & 1 ? -1 : 1) * tr[t][0] * s, y = c.y + (sg & 2 ? -1 : 1) * tr[t][1] * s;
      p[n++] = (qk_point_t){x, y};
      p[n++] = (qk_point_t){nextafter(x, c.x), y};
      p[n++] = (qk_point_t){nextafter(x, -c.x * 4), y};
      p[n++] = (qk_point_t){x, nextafter(y, 1e308)};
      p[n++] = (qk_point_t){x, nextafter(y, -1e308)};
    }
  return n;
}

/* The radius query is exact for any finite values (seventeenth session): points on a
 * circle of radius 5 s through Pythagorean triples (3 s, 4 s), their neighbours one ulp
 * inside and outside, and random points, for scales s from 2^-1074 (subnormal) to 2^1017,
 * and radii 5 s and its neighbours, against the exact oracle (rationals). Before, squares
 * overflowed (inf <= inf: every point within r) or underflowed (0 <= 0). */
static void test_query_radius_exact(void **state) {
  (void)state;
  const int scales[] = {-1074, -1073, -1060, -1000, -600, -537, -300,
                        0,     1,     300,   511,   600,  900,  1017};
  qkt_rng_t g;
  qkt_rng_seed(&g, 1717);
  for (size_t si = 0; si < sizeof scales / sizeof scales[0]; si++) {
    double s = ldexp(1, scales[si]);
    qk_point_t c = {7 * s, -2 * s}, p[200];
    size_t n = 0;
    n = on_circle_5s(p, n, c, s);
    while (n < 200)
      p[n++] = (qk_point_t){c.x + qkt_rng_range(&g, -6, 6) * s, c.y + qkt_rng_range(&g, -6, 6) * s};
    qk_tree_t *t;
    qk_tree_options_t o;
    qk_tree_options_init(&o);
    o.capacity = 4;
    assert_int_equal(qk_tree_build(p, n, &o, &t), QK_OK);
    const double radii[] = {5 * s,   nextafter(5 * s, 0), nextafter(5 * s, INFINITY), 3 * s, 0,
                            INFINITY};
    for (size_t ri = 0; ri < sizeof radii / sizeof radii[0]; ri++) {
      qk_neighbor_t got[200], want[200];
      size_t ng, nw = qko_radius(p, n, c, radii[ri], want);
      assert_int_equal(qk_query_radius_list(t, c, radii[ri], got, 200, &ng), QK_OK);
      qko_sort_by_id(got, ng);
      if (ng != nw)
        fail_msg("scale 2^%d, r %.17g: %zu points, oracle %zu", scales[si], radii[ri], ng, nw);
      for (size_t i = 0; i < nw; i++) {
        if (got[i].id != want[i].id || got[i].dist != want[i].dist)
          fail_msg("scale 2^%d, r %.17g: point %u at %.17g, oracle %u at %.17g", scales[si],
                   radii[ri], (unsigned)got[i].id, got[i].dist, (unsigned)want[i].id, want[i].dist);
      }
    }
    qk_tree_free(t);
  }
}

#if defined(QK_HAVE_GMP)
#include <gmp.h>

/* The exact oracle of kNN: every point's squared distance to q as a rational, the points
 * with D <= max_dist^2 (all when max_dist is infinite) sorted by (D, id), the first k;
 * distances as the library rounds them (sqrt of the double square, hypot beyond 2^1000). */
typedef struct xknn {
  mpq_t d;
  qk_id_t id;
} xknn_t;
static int xknn_cmp(const void *a, const void *b) {
  const xknn_t *x = a, *y = b;
  int c = mpq_cmp(x->d, y->d);
  return c ? c : (x->id > y->id) - (x->id < y->id);
}
static size_t xknn_oracle(const qk_point_t *p, size_t n, qk_point_t q, size_t k, double max_dist,
                          qk_neighbor_t *out) {
  xknn_t *v = malloc(n * sizeof *v);
  mpq_t a, b, cap;
  mpq_inits(a, b, cap, NULL);
  mpq_set_d(cap, isinf(max_dist) ? 0 : max_dist), mpq_mul(cap, cap, cap);
  size_t m = 0;
  for (size_t i = 0; i < n; i++) {
    mpq_init(v[m].d);
    mpq_set_d(a, p[i].x), mpq_set_d(b, q.x), mpq_sub(a, a, b), mpq_mul(v[m].d, a, a);
    mpq_set_d(a, p[i].y), mpq_set_d(b, q.y), mpq_sub(a, a, b), mpq_mul(a, a, a);
    mpq_add(v[m].d, v[m].d, a);
    v[m].id = (qk_id_t)i;
    if (isinf(max_dist) || mpq_cmp(v[m].d, cap) <= 0)
      m++;
    else
      mpq_clear(v[m].d);
  }
  qsort(v, m, sizeof *v, xknn_cmp);
  size_t r = m < k ? m : k;
  for (size_t i = 0; i < r; i++) {
    const double dx = p[v[i].id].x - q.x, dy = p[v[i].id].y - q.y, d2 = dx * dx + dy * dy;
    out[i] = (qk_neighbor_t){v[i].id, d2 < 0x1p1000 ? sqrt(d2) : hypot(dx, dy)};
  }
  for (size_t i = 0; i < m; i++) mpq_clear(v[i].d);
  mpq_clears(a, b, cap, NULL);
  free(v);
  return r;
}
#endif

/*
 * The exact distance tests themselves (index/dist_exact.h, behind the radius query, the
 * kNN searches and the static collider), against rationals: they first try the doubles
 * (twentieth session), which must decide only where every operation is exact. Inputs:
 * dyadic grids at scales 2^-600 to 2^520 with radii on, one ulp off and far from a grid
 * distance and the rounded root of one that is no square (the doubles decide, or
 * overflow or fall below 2^-480 and hand over); values
 * of 27 to 53 significant bits and sums that round (the doubles must refuse); random
 * reals; pairs of points at equal and near-equal distances for the comparison.
 */
#include "index/dist_exact.h"

/* A value for the cases: a small integer, or one with `bits` significant bits, at 2^e. */
static double dx_value(qkt_rng_t *r, int bits, int e) {
  uint64_t m = qkt_rng_next(r) >> (64 - bits) | UINT64_C(1) << (bits - 1);
  if (qkt_rng_below(r, 3) == 0) m = qkt_rng_below(r, 40);
  const double v = ldexp((double)m, e - bits);
  return qkt_rng_below(r, 2) ? -v : v;
}

static void test_query_dist_exact(void **state) {
  (void)state;
#if !defined(QK_HAVE_GMP)
  skip();
#else
  static const int scales[] = {-600, -500, -470, -60, -1, 0, 3, 40, 480, 500, 508, 520};
  static const int bits[] = {1, 5, 20, 26, 27, 30, 53};
  qkt_rng_t r;
  qkt_rng_seed(&r, g_seed ^ 0xd157);
  size_t checked = 0, on = 0;
  for (size_t si = 0; si < sizeof scales / sizeof *scales; si++) {
    for (size_t bi = 0; bi < sizeof bits / sizeof *bits; bi++) {
      for (int rep = 0; rep < 300; rep++) {
        const int e = scales[si], nb = bits[bi];
        const double bx = dx_value(&r, nb, e), by = dx_value(&r, nb, e);
        /* b + (dx, dy) for dx, dy of a Pythagorean triple (3, 4, 5) or random. */
        static const int trip[][3] = {{3, 4, 5}, {5, 12, 13}, {8, 15, 17}, {0, 7, 7}};
        const int *t = trip[qkt_rng_below(&r, 4)];
        const int sh = e - 4 - (int)qkt_rng_below(&r, 8);
        double ax = bx + ldexp(t[0], sh), ay = by + ldexp(t[1], sh);
        if (qkt_rng_below(&r, 4) == 0) ax = dx_value(&r, nb, e), ay = dx_value(&r, nb, e);
        double rad = ldexp(t[2], sh);
        switch (qkt_rng_below(&r, 6)) {
        case 0:
          rad = nextafter(rad, 0);
          break;
        case 1:
          rad = nextafter(rad, INFINITY);
          break;
        case 2:
          rad = fabs(dx_value(&r, nb, e));
          break;
        case 3: /* the rounded root of a sum of squares that is no square: rad^2 in doubles
                 * often rounds back to that sum */
          ax = bx + ldexp((double)qkt_rng_below(&r, 1u << 20), sh - 20);
          ay = by + ldexp((double)qkt_rng_below(&r, 1u << 20), sh - 20);
          rad = sqrt((ax - bx) * (ax - bx) + (ay - by) * (ay - by));
          break;
        default:
          break;
        }
        double r1 = rad, r2 = 0;
        if (qkt_rng_below(&r, 2)) { /* split it: r1 + r2 exact or rounded */
          r1 = ldexp(floor(ldexp(rad, -sh) / 3), sh);
          r2 = rad - r1;
          if (qkt_rng_below(&r, 3) == 0) r2 = nextafter(r2, INFINITY);
        }
        if (!isfinite(ax) || !isfinite(ay) || !isfinite(r1) || !isfinite(r2)) continue;
        const int want = qko_within(ax, ay, bx, by, r1, r2);
        const int got = qk__within_exact(ax, ay, bx, by, r1, r2);
        if (got != want)
          fail_msg("within: a (%a, %a) b (%a, %a) r %a + %a: %d, rationals %d", ax, ay, bx, by, r1,
                   r2, got, want);
        on += want;
        /* c: a rotated about b by a quarter turn (same distance), or nudged one ulp. */
        double cx = bx - (ay - by), cy = by + (ax - bx);
        if (qkt_rng_below(&r, 2)) cx = nextafter(cx, qkt_rng_below(&r, 2) ? INFINITY : -INFINITY);
        if (!isfinite(cx) || !isfinite(cy)) continue;
        const int wc = qko_dist_cmp((qk_point_t){bx, by}, (qk_point_t){ax, ay},
                                    (qk_point_t){cx, cy}),
                  gc = qk__dist_cmp_exact(bx, by, ax, ay, cx, cy);
        if ((gc > 0) - (gc < 0) != wc)
          fail_msg("cmp: q (%a, %a) a (%a, %a) c (%a, %a): %d, rationals %d", bx, by, ax, ay, cx,
                   cy, gc, wc);
        checked++;
      }
    }
  }
  /* Both answers occur often enough for the cases to mean something. */
  assert_true(checked > 20000);
  assert_true(on > checked / 5 && on < checked - checked / 5);
#endif
}

/*
 * kNN is exact for any finite values (eighteenth session): points on a circle of radius
 * 5 s through Pythagorean triples, their neighbours one ulp inside and outside, pairs
 * whose squares in doubles are equal or misordered but not their exact values ((s, 0)
 * and (s, 2^-27 s), whose square rounds to s^2; (3 s, 4 s) against (5 s, 2^-27 s)), and
 * random points, at scales s from 2^-1074 (subnormal) to 2^1017, with caps at 5 s and one
 * ulp either side, 3 s and 0; k from 1 to past the sorted array (33, 40) and all; single
 * queries and batches, against the rational oracle. Before, the double squares decided:
 * below 2^-537 they underflowed (every point at distance 0, ranked by id), near-equal
 * squares ranked by their roundings, and the cap admitted points one ulp outside.
 * A scale whose values reach beyond 2^510 may be refused (QK_ERR_LIMIT, as documented).
 */
static void test_query_knn_exact(void **state) {
  (void)state;
#if !defined(QK_HAVE_GMP)
  skip();
#else
  const int scales[] = {-1074, -1073, -1060, -1000, -600, -537, -300, -30,
                        0,     1,     300,   505,   511,  600,  900,  1017};
  const size_t ks[] = {1, 2, 3, 5, 8, 16, 32, 33, 40, 1000};
  qkt_rng_t g;
  qkt_rng_seed(&g, 1818);
  enum { N = 240, NQ = 4 };
  static qk_neighbor_t got[NQ * 1000], all[NQ * N], one[1000];
  for (size_t si = 0; si < sizeof scales / sizeof scales[0]; si++) {
    const double s = ldexp(1, scales[si]);
    const qk_point_t c = {7 * s, -2 * s};
    qk_point_t p[N];
    size_t n = 0;
    /* The near-ties first, then their mirror images with larger ids. */
    p[n++] = (qk_point_t){c.x + s, c.y + 0x1p-27 * s};
    p[n++] = (qk_point_t){c.x + s, c.y};
    p[n++] = (qk_point_t){c.x - 5 * s, c.y + 0x1p-27 * s};
    p[n++] = (qk_point_t){c.x + 3 * s, c.y - 4 * s};
    p[n++] = (qk_point_t){c.x - 2 * s, c.y + nextafter(2 * s, 0)};
    p[n++] = (qk_point_t){c.x + nextafter(2 * s, INFINITY), c.y - 2 * s};
    n = on_circle_5s(p, n, c, s);
    while (n < N)
      p[n++] = (qk_point_t){c.x + qkt_rng_range(&g, -6, 6) * s, c.y + qkt_rng_range(&g, -6, 6) * s};
    const qk_point_t qs[NQ] = {c, p[7], {c.x + 0.5 * s, c.y}, {c.x - 20 * s, c.y + 9 * s}};
    const double caps_[] = {INFINITY, 5 * s, nextafter(5 * s, 0), nextafter(5 * s, INFINITY),
                            3 * s,    0};
    const int beyond = 20 * s > 0x1p510;
    /* The oracle once per cap and query: every point within the cap in the exact order,
     * whose first k are the answer for k (the order is total). */
    const uint32_t tcaps[] = {1, 4, 16};
    qk_tree_t *trees[3];
    for (size_t c = 0; c < 3; c++) trees[c] = build(p, n, tcaps[c]);
    for (size_t li = 0; li < sizeof caps_ / sizeof caps_[0]; li++) {
      const double md = caps_[li];
      size_t nall[NQ];
      for (size_t i = 0; i < NQ; i++) nall[i] = xknn_oracle(p, n, qs[i], n, md, all + i * N);
      for (size_t c = 0; c < 3; c++)
        for (size_t ki = 0; ki < sizeof ks / sizeof ks[0]; ki++) {
          const size_t k = ks[ki];
          size_t counts[NQ];
          const qk_status_t bs = qk_query_knn_batch(trees[c], qs, NQ, k, md, got, counts);
          for (size_t i = 0; i < NQ; i++) {
            const qk_neighbor_t *want = all + i * N;
            size_t ng, nw = nall[i] < k ? nall[i] : k;
            const qk_status_t st = qk_query_knn(trees[c], qs[i], k, md, one, &ng);
            if (st == QK_ERR_LIMIT && beyond && bs == QK_ERR_LIMIT) continue;
            if (st != QK_OK || bs != QK_OK)
              fail_msg("scale 2^%d k %zu cap %.17g query %zu: status %d, batch %d", scales[si], k,
                       md, i, (int)st, (int)bs);
            if (ng != nw || counts[i] != nw)
              fail_msg("scale 2^%d cap %u k %zu max %.17g query %zu: %zu (batch %zu), oracle %zu",
                       scales[si], tcaps[c], k, md, i, ng, counts[i], nw);
            for (size_t j = 0; j < nw; j++) {
              const qk_neighbor_t a = one[j], b = got[i * k + j], w = want[j];
              if (a.id != w.id || a.dist != w.dist || b.id != w.id || b.dist != w.dist)
                fail_msg("scale 2^%d cap %u k %zu max %.17g query %zu rank %zu: %u at %.17g "
                         "(batch %u at %.17g), oracle %u at %.17g",
                         scales[si], tcaps[c], k, md, i, j, (unsigned)a.id, a.dist, (unsigned)b.id,
                         b.dist, (unsigned)w.id, w.dist);
            }
          }
        }
    }
    for (size_t c = 0; c < 3; c++) qk_tree_free(trees[c]);
  }
#endif
}

static int cmp_id(const void *a, const void *b) {
  const qk_id_t x = *(const qk_id_t *)a, y = *(const qk_id_t *)b;
  return (x > y) - (x < y);
}

/*
 * Trees over subnormal coordinates (whole numbers of units 2^-1074 to 2^-1030): their
 * sides do not halve exactly, so a leaf's square as computed may sit a unit off the split
 * lines that placed its points, and the pruning margin, 2^-40 of the root's magnitude,
 * underflowed to 0: a range query missed a leaf's points on its top edge (forty-ninth
 * session's review: six points, capacity 1, ids 1 and 2 at y = 0x400 units). Range boxes
 * with edges on the points' coordinates, and radius 0 at each point, against brute force.
 */
static void test_query_subnormal_roots(void **state) {
  (void)state;
  qkt_rng_t r;
  qkt_rng_seed(&r, g_seed + 23);
  static const int ux[6] = {0x30d, 0, 0, -0x24f, 0x1f8, 0x200};
  static const int uy[6] = {-0x328, 0x400, 0x400, 0x39d, 0x2a, -0x3b};
  enum { N = 300 };
  qk_point_t p[N];
  qk_id_t got[N], want[N];
  qk_neighbor_t nb[N], nw[N];
  size_t bad = 0, boxes = 0;
  for (int scale = -1074; scale <= -1030; scale += 4)
    for (int trial = 0; trial < 6; trial++) {
      const double u = ldexp(1, scale);
      const size_t n = trial == 0 ? 6 : 6 + qkt_rng_below(&r, N - 6);
      for (size_t i = 0; i < n; i++)
        p[i] = trial == 0 ? (qk_point_t){ux[i] * u, uy[i] * u}
                          : (qk_point_t){((int)qkt_rng_below(&r, 4096) - 2048) * u,
                                         ((int)qkt_rng_below(&r, 4096) - 2048) * u};
      for (size_t i = 3; trial && i < n; i += 11) p[i] = p[i - 3]; /* repeats */
      qk_tree_t *t = build(p, n, trial % 3 == 0 ? 1 : 4);
      for (int q = 0; q < 60; q++) {
        const qk_point_t a = p[qkt_rng_below(&r, (uint32_t)n)],
                         b = p[qkt_rng_below(&r, (uint32_t)n)];
        qk_box_t box = {fmin(a.x, b.x), fmin(a.y, b.y), fmax(a.x, b.x), fmax(a.y, b.y)};
        if (q % 4 == 0) box = (qk_box_t){a.x, a.y, a.x, a.y};
        if (q % 4 == 1) box = (qk_box_t){-1, a.y, 1, a.y};
        size_t ng = 0, nwn = qko_range(p, n, box, want);
        assert_int_equal(qk_query_range_list(t, box, got, N, &ng), QK_OK);
        qsort(got, ng < N ? ng : N, sizeof *got, cmp_id);
        boxes++;
        if (ng != nwn || memcmp(got, want, nwn * sizeof *got)) {
          if (!bad++)
            fprintf(stderr, "range, scale 2^%d trial %d: %zu points, want %zu (seed %llu)\n", scale,
                    trial, ng, nwn, (unsigned long long)g_seed);
        }
        size_t nr = 0, nrw = qko_radius(p, n, a, 0, nw);
        assert_int_equal(qk_query_radius_list(t, a, 0, nb, N, &nr), QK_OK);
        if (nr != nrw) {
          if (!bad++)
            fprintf(stderr, "radius 0, scale 2^%d trial %d: %zu points, want %zu\n", scale, trial,
                    nr, nrw);
        }
      }
      qk_tree_free(t);
    }
  printf("# %zu boxes and as many radius queries on subnormal trees\n", boxes);
  assert_int_equal(bad, 0);
}

/*
 * Pruning at every magnitude: uniform points in [0, S]^2 for S = 1, 2^-664, 1e-200,
 * 1e-300 and 1e200 (and 1e150 for kNN, which refuses 1e200: QK_ERR_LIMIT), radius and kNN
 * (k = 1, 8 and 40, the heap) against brute force, from inside and outside the root.
 * Below about 1e-154 every square underflowed under the filter's absolute margin, and
 * from r = 2^500 on r^2 was beyond the filter's range: no square was pruned and every
 * point went to the exact test, some n exact tests a query (fifty-sixth session; 35-80
 * ms a kNN query at 10^5 points). The count of exact tests (wrapped at link time) must
 * stay below one a query; before the fix it was about n a query at every scale but 1.
 */
static void test_query_scale_pruning(void **state) {
  (void)state;
  qkt_rng_t r;
  qkt_rng_seed(&r, g_seed + 56);
  enum { N = 3000, Q = 24, K = 40 };
  static const double scales[] = {1, 0x1p-664, 1e-200, 1e-300, 1e150, 1e200};
  qk_point_t *p = malloc(N * sizeof *p);
  qk_neighbor_t *got = malloc(N * sizeof *got), *want = malloc(N * sizeof *want);
  assert_non_null(p);
  assert_non_null(got);
  assert_non_null(want);
  for (size_t si = 0; si < sizeof scales / sizeof scales[0]; si++) {
    const double S = scales[si];
    for (size_t i = 0; i < N; i++) p[i] = (qk_point_t){qkt_rng_unit(&r) * S, qkt_rng_unit(&r) * S};
    qk_tree_t *t = build(p, N, 8);
    size_t queries = 0, calls = 0;
    for (size_t qi = 0; qi < Q; qi++) {
      /* Inside mostly; every fourth beside the root (up to half its side away). */
      const qk_point_t q = qi % 4 == 3 ? (qk_point_t){(1.0 + 0.5 * qkt_rng_unit(&r)) * S,
                                                      -0.5 * qkt_rng_unit(&r) * S}
                                       : (qk_point_t){qkt_rng_unit(&r) * S, qkt_rng_unit(&r) * S};
      /* Radius: about 1, 10 and 40 points. */
      static const double radii[] = {0.01, 0.03, 0.06};
      for (int ri = 0; ri < 3; ri++) {
        const double rad = radii[ri] * S;
        size_t ng = 0;
        const size_t before = g_exact_calls;
        assert_int_equal(qk_query_radius_list(t, q, rad, got, N, &ng), QK_OK);
        calls += g_exact_calls - before;
        queries++;
        const size_t nw = qko_radius(p, N, q, rad, want);
        qko_sort_by_id(got, ng);
        assert_nb_equal(got, ng, want, nw, "radius at scale", qi);
      }
      if (S > 1e153) continue; /* beyond kNN's range (qk__knn_check) */
      static const size_t ks[] = {1, 8, K};
      for (int ki = 0; ki < 3; ki++) {
        size_t ng = 0;
        const size_t before = g_exact_calls;
        assert_int_equal(qk_query_knn(t, q, ks[ki], INFINITY, got, &ng), QK_OK);
        calls += g_exact_calls - before;
        queries++;
        const size_t nw = qko_knn(p, NULL, N, q, ks[ki], INFINITY, want);
        assert_nb_equal(got, ng, want, nw, "knn at scale", qi);
        /* With a cap near the k-th's distance. */
        const double cap = want[nw - 1].dist;
        const size_t before2 = g_exact_calls;
        assert_int_equal(qk_query_knn(t, q, ks[ki], cap, got, &ng), QK_OK);
        calls += g_exact_calls - before2;
        queries++;
        const size_t nw2 = qko_knn(p, NULL, N, q, ks[ki], cap, want);
        assert_nb_equal(got, ng, want, nw2, "capped knn at scale", qi);
      }
    }
    /* A batch too (its paths walked ahead). */
    {
      qk_point_t qs[Q];
      size_t counts[Q];
      for (size_t qi = 0; qi < Q; qi++)
        qs[qi] = (qk_point_t){qkt_rng_unit(&r) * S, qkt_rng_unit(&r) * S};
      if (S <= 1e153) {
        qk_neighbor_t *bo = malloc(Q * 8 * sizeof *bo);
        assert_non_null(bo);
        const size_t before = g_exact_calls;
        assert_int_equal(qk_query_knn_batch(t, qs, Q, 8, INFINITY, bo, counts), QK_OK);
        calls += g_exact_calls - before;
        queries += Q;
        for (size_t qi = 0; qi < Q; qi++) {
          const size_t nw = qko_knn(p, NULL, N, qs[qi], 8, INFINITY, want);
          assert_nb_equal(bo + qi * 8, counts[qi], want, nw, "batch knn at scale", qi);
        }
        free(bo);
      }
    }
    printf("# scale %g: %zu exact tests in %zu queries\n", S, calls, queries);
    if (calls > queries)
      fail_msg("scale %g: %zu exact tests in %zu queries (seed %llu)", S, calls, queries,
               (unsigned long long)g_seed);
    qk_tree_free(t);
  }
  free(p);
  free(got);
  free(want);
}

#if defined(__SSE2__)
/*
 * kNN with the processor set to flush subnormal numbers (DAZ and FTZ in MXCSR, as a
 * program linked with -ffast-math runs): the sorted search sorts by keys that are
 * doubles, and a subnormal key would read as 0. Queries on stored points (distance 0,
 * alone or, where a point repeats, with its copy) and between two, k = 2, 8, 32, single
 * and batch, against brute force computed before the mode is set.
 */
static void test_query_knn_flush_subnormals(void **state) {
  (void)state;
  qkt_rng_t r;
  qkt_rng_seed(&r, g_seed + 17);
  const size_t n = 3000, nq = 90;
  const size_t ks[] = {2, 8, 32};
  qk_point_t *p = malloc(n * sizeof *p), *qs = malloc(nq * sizeof *qs);
  qk_neighbor_t *want = malloc(3 * nq * 32 * sizeof *want), *got = malloc(nq * 32 * sizeof *got);
  qk_neighbor_t one[32];
  size_t *nw = malloc(3 * nq * sizeof *nw), *counts = malloc(nq * sizeof *counts);
  /* Distinct points, most at random; a few repeated. */
  qkt_points(&r, QKT_UNIFORM, p, n);
  for (size_t i = 7; i < n; i += 97) p[i] = p[i - 7];
  for (size_t i = 0; i < nq; i++) {
    const qk_point_t a = p[qkt_rng_below(&r, (uint32_t)n)], b = p[qkt_rng_below(&r, (uint32_t)n)];
    qs[i] = i % 3 ? a : (qk_point_t){0.5 * (a.x + b.x), 0.5 * (a.y + b.y)};
  }
  for (size_t ki = 0; ki < 3; ki++)
    for (size_t i = 0; i < nq; i++)
      nw[ki * nq + i] = qko_knn(p, NULL, n, qs[i], ks[ki], INFINITY, want + (ki * nq + i) * 32);
  qk_tree_t *t = build(p, n, 4);
  const unsigned csr = _mm_getcsr();
  _mm_setcsr(csr | 0x8040); /* FTZ | DAZ */
  int ok = 1;
  for (size_t ki = 0; ki < 3 && ok; ki++) {
    const size_t k = ks[ki];
    ok &= qk_query_knn_batch(t, qs, nq, k, INFINITY, got, counts) == QK_OK;
    for (size_t i = 0; i < nq && ok; i++) {
      const qk_neighbor_t *w = want + (ki * nq + i) * 32;
      size_t ng;
      ok &= qk_query_knn(t, qs[i], k, INFINITY, one, &ng) == QK_OK && ng == nw[ki * nq + i] &&
            counts[i] == ng;
      for (size_t j = 0; j < ng && ok; j++)
        ok &= one[j].id == w[j].id && one[j].dist == w[j].dist && got[i * k + j].id == w[j].id &&
              got[i * k + j].dist == w[j].dist;
      if (!ok)
        fprintf(stderr, "knn-flush: k %zu query %zu (seed %llu)\n", k, i,
                (unsigned long long)g_seed);
    }
  }
  _mm_setcsr(csr);
  assert_true(ok);
  qk_tree_free(t);
  free(p), free(qs), free(want), free(got), free(nw), free(counts);
}
#endif

static void test_query_cities(void **state) {
  (void)state;
  size_t n;
  qk_point_t *p = qko_load_cities(&n);
  if (!p) {
    print_message("cities.csv not found: skipping the real-data test\n");
    skip();
  }
  qkt_rng_t r;
  qkt_rng_seed(&r, g_seed + 8);
  qk_tree_t *t = build(p, n, 32);
  qk_neighbor_t got[10], want[10];
  qk_neighbor_t *gr = malloc(n * sizeof *gr), *wr = malloc(n * sizeof *wr);
  for (size_t qi = 0; qi < 150; qi++) {
    qk_point_t q = qi % 2 ? p[qkt_rng_below(&r, (uint32_t)n)]
                          : (qk_point_t){qkt_rng_range(&r, -180, 180), qkt_rng_range(&r, -90, 90)};
    size_t ng, nw = qko_knn(p, NULL, n, q, 10, INFINITY, want);
    assert_int_equal(qk_query_knn(t, q, 10, INFINITY, got, &ng), QK_OK);
    assert_nb_equal(got, ng, want, nw, "cities-knn", qi);
    nw = qko_radius(p, n, q, 1.0, wr);
    assert_int_equal(qk_query_radius_list(t, q, 1.0, gr, n, &ng), QK_OK);
    qko_sort_by_id(gr, ng);
    assert_nb_equal(gr, ng, wr, nw, "cities-radius", qi);
  }
  qk_tree_free(t);
  free(p), free(gr), free(wr);
}

/* Large batches (from 65536 queries) put their queries in Z-order on the batch's threads:
 * on one, two and three threads, and with either of that sort's allocations failing, every
 * kNN and located leaf is the single call's, and nothing is left allocated. */
static void test_query_batch_threaded_order(void **state) {
  (void)state;
  qkt_rng_t r;
  qkt_rng_seed(&r, g_seed + 11);
  const size_t n = 4000, nq = 70000, k = 2;
  qk_point_t *p = malloc(n * sizeof *p), *qs = malloc(nq * sizeof *qs);
  qk_neighbor_t *want = malloc(nq * k * sizeof *want), *out = malloc(nq * k * sizeof *out);
  qk_node_t *wleaf = malloc(nq * sizeof *wleaf), *leaves = malloc(nq * sizeof *leaves);
  assert_non_null(p && qs && want && out && wleaf && leaves);
  qkt_points(&r, QKT_CLUSTERED, p, n);
  for (size_t i = 0; i < nq; i++) qs[i] = rand_loc(&r);
  qkt_alloc_t st;
  qk_allocator_t a = qkt_alloc_make(&st);
  qk_tree_t *t = build_with(p, n, 4, &a);
  for (size_t i = 0; i < nq; i++) {
    size_t m = 0;
    assert_int_equal(qk_query_knn(t, qs[i], k, INFINITY, want + i * k, &m), QK_OK);
    assert_int_equal(m, k);
    if (qk_tree_find_leaf(t, qs[i], &wleaf[i]) != QK_OK) wleaf[i] = QK_NONE;
  }
  const size_t live = st.live_blocks;
  for (unsigned threads = 1; threads <= 3; threads++) {
    qk_tree_set_threads(t, threads);
    for (size_t fail_at = 0; fail_at <= 2; fail_at++) { /* 0: no failure; 1, 2: the sort's */
      qkt_alloc_arm(&st, fail_at);
      assert_int_equal(qk_query_knn_batch(t, qs, nq, k, INFINITY, out, NULL), QK_OK);
      assert_int_equal(st.live_blocks, live);
      for (size_t i = 0; i < nq * k; i++)
        if (out[i].id != want[i].id || out[i].dist != want[i].dist)
          fail_msg("threads %u fail_at %zu: knn %zu (%u, %.17g) vs single (%u, %.17g) (seed %llu)",
                   threads, fail_at, i, out[i].id, out[i].dist, want[i].id, want[i].dist,
                   (unsigned long long)g_seed);
      qkt_alloc_arm(&st, fail_at);
      assert_int_equal(qk_query_locate_batch(t, qs, nq, leaves), QK_OK);
      assert_int_equal(st.live_blocks, live);
      assert_memory_equal(leaves, wleaf, nq * sizeof *leaves);
    }
  }
  qkt_alloc_arm(&st, 0);
  qk_tree_free(t);
  assert_int_equal(st.live_blocks, 0);
  free(p), free(qs), free(want), free(out), free(wleaf), free(leaves);
}

/*
 * kNN and locate batches of 300,001 queries (their threads take chunks of the Z-order from
 * a shared counter, a few thousand queries each, the last one short): on two and three
 * threads every answer is the one thread's, bit for bit; with a non-finite query and one
 * beyond the search's range (which sort to opposite ends of the Z-order, so different
 * threads meet them) the status is that of the lower-numbered one, either way round, and
 * every other query is still answered.
 */
/* The same ids and the same distances bit for bit (the records have padding). */
static int same_neighbors(const qk_neighbor_t *a, const qk_neighbor_t *b, size_t k) {
  for (size_t m = 0; m < k; m++)
    if (a[m].id != b[m].id || memcmp(&a[m].dist, &b[m].dist, sizeof a[m].dist) != 0) return 0;
  return 1;
}

static void test_query_batch_chunks(void **state) {
  (void)state;
  qkt_rng_t r;
  qkt_rng_seed(&r, g_seed + 14);
  const size_t n = 20000, nq = 300001, k = 3;
  qk_point_t *p = malloc(n * sizeof *p), *qs = malloc(nq * sizeof *qs);
  qk_neighbor_t *want = malloc(nq * k * sizeof *want), *out = malloc(nq * k * sizeof *out);
  size_t *wc = malloc(nq * sizeof *wc), *counts = malloc(nq * sizeof *counts);
  qk_node_t *wleaf = malloc(nq * sizeof *wleaf), *leaves = malloc(nq * sizeof *leaves);
  assert_non_null(p && qs && want && out && wc && counts && wleaf && leaves);
  qkt_points(&r, QKT_CLUSTERED, p, n);
  for (size_t i = 0; i < nq; i++) qs[i] = i % 5 == 0 ? p[qkt_rng_below(&r, n)] : rand_loc(&r);
  qk_tree_t *t = build(p, n, 8);
  for (int round = 0; round < 3; round++) {
    /* round 0: no bad query; 1: the non-finite one first; 2: the far one first */
    const size_t lo = 123457, hi = 271829;
    const qk_point_t nan_q = {NAN, 0.5}, far_q = {0x1p600, 0.5};
    qk_status_t expect = QK_OK;
    if (round > 0) {
      qs[lo] = round == 1 ? nan_q : far_q;
      qs[hi] = round == 1 ? far_q : nan_q;
      expect = round == 1 ? QK_ERR_NONFINITE : QK_ERR_LIMIT;
    }
    qk_tree_set_threads(t, 1);
    assert_int_equal(qk_query_knn_batch(t, qs, nq, k, INFINITY, want, wc), expect);
    assert_int_equal(qk_query_locate_batch(t, qs, nq, wleaf), QK_OK);
    for (size_t i = 0; i < nq; i += 997) { /* the one-thread batch against single calls */
      qk_neighbor_t one[3];
      size_t m = 0;
      if (qk_query_knn(t, qs[i], k, INFINITY, one, &m) != QK_OK) m = 0;
      assert_nb_equal(want + i * k, wc[i], one, m, "knn-chunks-one", i);
    }
    for (unsigned threads = 2; threads <= 3; threads++) {
      qk_tree_set_threads(t, threads);
      memset(out, 0xA5, nq * k * sizeof *out);
      memset(counts, 0xA5, nq * sizeof *counts);
      memset(leaves, 0xA5, nq * sizeof *leaves);
      assert_int_equal(qk_query_knn_batch(t, qs, nq, k, INFINITY, out, counts), expect);
      for (size_t i = 0; i < nq; i++)
        if (counts[i] != wc[i] || !same_neighbors(out + i * k, want + i * k, k))
          fail_msg("round %d threads %u: query %zu differs from one thread's (seed %llu)", round,
                   threads, i, (unsigned long long)g_seed);
      assert_int_equal(qk_query_locate_batch(t, qs, nq, leaves), QK_OK);
      assert_memory_equal(leaves, wleaf, nq * sizeof *leaves);
    }
  }
  qk_tree_free(t);
  free(p), free(qs), free(want), free(out), free(wc), free(counts), free(wleaf), free(leaves);
}

/*
 * Radius batches on 1, 2 and 3 threads, large enough that the other shares' results are
 * copied into place by all the shares at once: the results are the single calls' laid end
 * to end, the counts the brute-force oracle's; with the caller's buffer cut short (inside
 * a share, so that the shares' buffers are too small and answered again, and by one
 * result) the buffer holds that sequence's prefix and the total is still the full count.
 */
/* How many of the points lie within r of q, exactly: each point whose x is within 2 r of
 * q's (a band around the disc, wide enough that rounding its ends cannot cut the disc;
 * found in the points sorted by x) tested with the oracle's exact test. */
typedef struct {
  double x;
  uint32_t id;
} by_x_t;
static int by_x_cmp(const void *a, const void *b) {
  const double u = ((const by_x_t *)a)->x, v = ((const by_x_t *)b)->x;
  return (u > v) - (u < v);
}
static size_t radius_count_by_x(const qk_point_t *p, const by_x_t *s, size_t n, qk_point_t q,
                                double r) {
  const double from = q.x - 2 * r, to = q.x + 2 * r;
  size_t lo = 0, hi = n, m = 0;
  while (lo < hi) {
    const size_t mid = lo + (hi - lo) / 2;
    if (s[mid].x < from)
      lo = mid + 1;
    else
      hi = mid;
  }
  for (size_t i = lo; i < n && s[i].x <= to; i++)
    m += (size_t)qko_within(p[s[i].id].x, p[s[i].id].y, q.x, q.y, r, 0);
  return m;
}

static void test_query_radius_batch_threads(void **state) {
  (void)state;
  qkt_rng_t r;
  qkt_rng_seed(&r, g_seed + 14);
  const size_t n = 20000, nq = 12000;
  const double rad = 0.002;
  qk_point_t *p = malloc(n * sizeof *p), *qs = malloc(nq * sizeof *qs);
  qkt_points(&r, QKT_CLUSTERED, p, n);
  for (size_t i = 0; i < nq; i++) qs[i] = i % 3 == 0 ? p[qkt_rng_below(&r, n)] : rand_loc(&r);
  qk_tree_t *t = build(p, n, 8);
  size_t *want_n = malloc(nq * sizeof *want_n), *counts = malloc(nq * sizeof *counts);
  by_x_t *sx = malloc(n * sizeof *sx);
  for (size_t i = 0; i < n; i++) sx[i] = (by_x_t){p[i].x, (uint32_t)i};
  qsort(sx, n, sizeof *sx, by_x_cmp);
  size_t total = 0;
  for (size_t i = 0; i < nq; i++) {
    assert_int_equal(qk_query_radius_list(t, qs[i], rad, NULL, 0, &want_n[i]), QK_OK);
    if (want_n[i] != radius_count_by_x(p, sx, n, qs[i], rad))
      fail_msg("radius %zu: %zu vs oracle (seed %llu)", i, want_n[i], (unsigned long long)g_seed);
    total += want_n[i];
  }
  assert_true(total > 3 * 16384); /* past the shared copy's threshold on any share count */
  /* The first cap leaves the other shares' buffers (sized from it) room for all their
   * results: the shared copy; the others cut into them: the shares answered again. */
  const size_t caps[] = {total + total / 4, total, total - 1, total / 2, total / 5};
  qk_neighbor_t *want = malloc(total * sizeof *want), *got = malloc(caps[0] * sizeof *got);
  for (size_t i = 0, at = 0; i < nq; at += want_n[i++]) {
    size_t m;
    assert_int_equal(qk_query_radius_list(t, qs[i], rad, want + at, want_n[i], &m), QK_OK);
  }
  for (unsigned threads = 1; threads <= 3; threads++) {
    qk_tree_set_threads(t, threads);
    for (size_t c = 0; c < sizeof caps / sizeof *caps; c++) {
      memset(got, 0xA5, caps[0] * sizeof *got);
      size_t n_out = 0;
      assert_int_equal(qk_query_radius_list_batch(t, qs, nq, rad, got, caps[c], counts, &n_out),
                       QK_OK);
      assert_int_equal(n_out, total);
      assert_memory_equal(counts, want_n, nq * sizeof *counts);
      const size_t held = caps[c] < total ? caps[c] : total;
      for (size_t i = 0; i < held; i++)
        if (got[i].id != want[i].id || got[i].dist != want[i].dist)
          fail_msg("threads %u cap %zu: result %zu (%u, %.17g) vs single calls (%u, %.17g) "
                   "(seed %llu)",
                   threads, caps[c], i, got[i].id, got[i].dist, want[i].id, want[i].dist,
                   (unsigned long long)g_seed);
      for (size_t i = held; i < caps[0]; i++) /* nothing past the results or the cap */
        assert_int_equal(got[i].id, 0xA5A5A5A5u);
    }
  }
  qk_tree_free(t);
  free(p), free(qs), free(want_n), free(counts), free(sx), free(want), free(got);
}

static int sse2_on(void **state) {
  (void)state;
  qk__knn_avx2_off = 1;
  return 0;
}

static int sse2_off(void **state) {
  (void)state;
  qk__knn_avx2_off = 0;
  return 0;
}

int main(void) {
  g_seed = qkt_seed(20261122);
  const struct CMUnitTest tests[] = {
    cmocka_unit_test(test_query_range_radius),
    cmocka_unit_test(test_query_knn_all_k),
    cmocka_unit_test(test_query_knn_check_order),
    cmocka_unit_test(test_query_dist_exact),
    cmocka_unit_test(test_query_knn_large),
    cmocka_unit_test(test_query_knn_after_mutation),
    cmocka_unit_test(test_query_locate),
    cmocka_unit_test(test_query_batch),
    cmocka_unit_test(test_query_batch_nomem),
    cmocka_unit_test(test_query_stop_and_bad_args),
    cmocka_unit_test(test_query_knn_distance_range),
    cmocka_unit_test(test_query_threads),
    cmocka_unit_test(test_query_batch_threaded_order),
    cmocka_unit_test(test_query_batch_chunks),
    cmocka_unit_test(test_query_cities),
    cmocka_unit_test(test_query_knn_big_leaves),
    cmocka_unit_test(test_query_knn_batch_paths),
    cmocka_unit_test(test_query_knn1_ties),
    cmocka_unit_test(test_query_knn_ties_k),
    cmocka_unit_test(test_query_knn_kth_bound),
    cmocka_unit_test(test_query_knn_near_ties),
    cmocka_unit_test(test_query_radius_batch_threads),
    cmocka_unit_test(test_query_knn_cell_lines),
    cmocka_unit_test(test_query_radius_exact),
    cmocka_unit_test(test_query_knn_exact),
    cmocka_unit_test(test_query_subnormal_roots),
    cmocka_unit_test(test_query_scale_pruning),
#if defined(__SSE2__) /* (the flush mode is set through SSE's MXCSR) */
    cmocka_unit_test(test_query_knn_flush_subnormals),
#endif
  };
  /* Under ThreadSanitizer (scripts/tsan.sh) only the tests that start threads: the others
   * would take minutes there and TSan finds nothing without a second thread. */
  const struct CMUnitTest threaded[] = {
      cmocka_unit_test(test_query_threads),
      cmocka_unit_test(test_query_batch_threaded_order),
      cmocka_unit_test(test_query_batch_chunks),
      cmocka_unit_test(test_query_radius_batch_threads),
  };
  /* The kNN tests again with the k = 1 scan's SSE2 path where the processor has AVX2 (the
   * group above takes the AVX2 path there). */
  const struct CMUnitTest sse2[] = {
    cmocka_unit_test(test_query_knn_all_k),
    cmocka_unit_test(test_query_knn_large),
    cmocka_unit_test(test_query_knn_after_mutation),
    cmocka_unit_test(test_query_batch),
    cmocka_unit_test(test_query_knn_distance_range),
    cmocka_unit_test(test_query_knn_big_leaves),
    cmocka_unit_test(test_query_knn_batch_paths),
    cmocka_unit_test(test_query_knn1_ties),
    cmocka_unit_test(test_query_knn_near_ties),
    cmocka_unit_test(test_query_knn_cell_lines),
    cmocka_unit_test(test_query_knn_exact),
#if defined(__SSE2__)
    cmocka_unit_test(test_query_knn_flush_subnormals),
#endif
  };
  if (QKT_TSAN) return cmocka_run_group_tests(threaded, NULL, NULL);
  int failed = cmocka_run_group_tests(tests, NULL, NULL);
  return failed + cmocka_run_group_tests_name("knn, SSE2 scans", sse2, sse2_on, sse2_off);
}
