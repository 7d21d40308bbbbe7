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
 *
 * The streamed build (from 2^19 points: records and point arrays written around the
 * caches, with AVX2 where the processor has it, the scatter's tags sixteen keys a step and
 * the staged pairs copied out eight points a step): on a share size that is no multiple of
 * 16 and with a tenth of the points on grid lines or duplicated, on one and two threads,
 * the shape of inserting the points one by one, and in every leaf the input's points in
 * input order (ids rising, each id once, its coordinates bit for bit); with libc's
 * allocator, with point arrays on 32-byte boundaries or 8 bytes past them, and with x and y
 * 16 bytes apart modulo 32 (each of the two on a 32-byte boundary in turn); all of it
 * again with the AVX2 paths turned off (qk__build_avx2_off), so the SSE2 and plain paths
 * are checked on processors that have AVX2 too.
 *
 * The output pinned: the raw node and point arrays (every node's child, start, count,
 * room, liveness, parent and depth; every slot's coordinates' bits and id) of builds of a
 * uniform input at the benchmark's size and capacity (10^6 points, 32), clustered points,
 * duplicates, points on dyadic grid lines, one point and all points equal, hashed and
 * compared with the hashes of the build as it was before its sort was reworked (commit
 * 817321d), on one thread and on two, with and without AVX2: speed-ups of the build must
 * leave its output byte for byte. (An internal node's start, 0 when they were pinned, is
 * hashed as 0: it is checked by the next test.)
 *
 * Internal nodes keep their start (a prefetch hint for the searches): on the same inputs,
 * on one thread and two, and on a root far from the origin (the plain recursive build),
 * every internal node's start is its first child's and the leaves hold consecutive slots
 * in pre-order, so a subtree's points are the slots [start, start + count).
 *
 * The team a build holds for its parallel regions (qk__team_begin): the regions started
 * while it is held run their shares 1.. on the same workers (a thread-local count of the
 * shares each thread ran reaches the number of regions; threads started per region would
 * count one each), every share and every job exactly once, also for a region inside a
 * share (on threads of its own), one asking for more shares than the team has, and after
 * the team ended; nested teams serve as the outermost one.
 *
 * The pool the team and the world's workers are (qk__pool_t, index/threads.c): the same
 * workers run every region; a region started while the pool runs one (from a share), or
 * asking for more shares than it has threads, is refused (0, nothing run); a detached job
 * runs on a worker while the caller goes on, and the next region waits for it; in a child
 * forked after the workers started the pool refuses every region and its free only frees
 * memory.
 *
 * Where the pool's workers start (Linux, with more than one processor allowed): away from
 * the processor the starting thread ran on (this guest's scheduler left a new thread next
 * to its creator), and, once running, free to run wherever the starting thread may (the
 * same set of processors, not pinned); the same for the threads qk__run_shares starts for a
 * region when no team is held (on two and three shares).
 *
 * How the calling thread waits for a region's end: while it holds the pool it spins (up to
 * 1 ms) rather than parks for a worker that takes a few hundred microseconds more than it
 * (parked, it was woken late); not held, it parks after 50 us.
 */
#if defined(__linux__)
#define _GNU_SOURCE /* sched_getaffinity, CPU_EQUAL */
#else
#define _POSIX_C_SOURCE 200809L
#endif
#include <math.h>
#include <pthread.h>
#include <stdatomic.h>
#include <stdbool.h>
#include <stdlib.h>
#include <string.h>
#include <sys/wait.h>
#include <time.h>
#include <unistd.h>

#include "index/index_access.h"
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

/* The tree's shape the builds must give: the points inserted one by one with options o;
 * under the sanitizers the one-thread build instead (TSan is here for the threads, ASan
 * for the memory errors: a third of this test's time under ASan was these inserts, whose
 * paths test_index covers; the other builds check the builds against the inserts). */
static qkt_shape_t oracle_shape(const qk_point_t *p, size_t n, qk_tree_options_t o) {
  qk_tree_t *ins = NULL;
  if (QKT_TSAN || QKT_ASAN) {
    o.threads = 1;
    assert_int_equal(qk_tree_build(p, n, &o, &ins), QK_OK);
  } else {
    assert_int_equal(qk_tree_build(NULL, 0, &o, &ins), QK_OK);
    for (size_t i = 0; i < n; i++) assert_int_equal(qk_tree_insert(ins, p[i], NULL), QK_OK);
  }
  qkt_shape_t want = qkt_tree_shape(ins);
  qk_tree_free(ins);
  return want;
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
    /* the oracle (the other builds check the one-thread build against inserts) */
    qkt_shape_t want = oracle_shape(p, N, o);
    for (uint32_t threads = QKT_TSAN ? 2 : 1; threads <= 2; threads++) {
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
  o.threads = 1;
  qk_tree_t *one = NULL;
  assert_int_equal(qk_tree_build(p, N, &o, &one), QK_OK);
  QKT_CHECK_TREE(one);
  if (!QKT_TSAN) { /* one thread against inserts (TSan is here for the threads below) */
    qk_tree_t *ins = NULL;
    assert_int_equal(qk_tree_build(NULL, 0, &o, &ins), QK_OK);
    for (size_t i = 0; i < N; i++) assert_int_equal(qk_tree_insert(ins, p[i], NULL), QK_OK);
    qkt_shape_t want = qkt_tree_shape(ins), got = qkt_tree_shape(one);
    qk_tree_free(ins);
    assert_int_equal(got.nodes, want.nodes);
    assert_true(got.hash == want.hash);
  }
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

/* Every leaf holds input points with their coordinates bit for bit, every id once, and a
 * leaf that is one cell of the build's grid (depth `grid`) holds them in input order: the
 * sort by cell is stable (points in cells over the capacity are then split further by a
 * partition, which does not keep their order, and a shallower leaf holds its cells one
 * after another). */
typedef struct order_check {
  const qk_point_t *p;
  size_t n, seen_n, bad, ordered;
  unsigned grid;
  unsigned char *seen;
} order_check_t;

static qk_visit_t order_visit(const qk_tree_t *t, qk_node_t v, void *ud) {
  order_check_t *o = ud;
  const double *x, *y;
  const qk_id_t *id;
  size_t m;
  if (qk_tree_leaf_points(t, v, &x, &y, &id, &m) != QK_OK) return QK_VISIT_CONTINUE;
  qk_node_info_t info;
  assert_int_equal(qk_tree_node_info(t, v, &info), QK_OK);
  bool cell = info.depth == o->grid;
  for (size_t i = 0; i < m; i++) {
    qk_id_t k = id[i];
    if (k >= o->n || o->seen[k] || (cell && i > 0 && k <= id[i - 1]) ||
        memcmp(&x[i], &o->p[k].x, sizeof x[i]) || memcmp(&y[i], &o->p[k].y, sizeof y[i])) {
      o->bad++;
      continue;
    }
    o->seen[k] = 1;
    o->seen_n++;
    o->ordered += cell;
  }
  return QK_VISIT_CONTINUE;
}

/* An allocator whose blocks start `*ud` bytes past a 64-byte boundary (0 or 8 here), so
 * that the point arrays lie on 32-byte boundaries together, or 8 bytes past them together,
 * whatever the C library's heap does: the build's 32-byte streaming copies run, with and
 * without their unaligned head. */
static void *offset_alloc(void *ud, void *ptr, size_t osize, size_t nsize) {
  size_t off = *(const size_t *)ud;
  void *fresh = NULL;
  if (nsize) {
    unsigned char *b = aligned_alloc(64, (nsize + off + 63) / 64 * 64);
    if (!b) return NULL;
    fresh = b + off;
    if (ptr) memcpy(fresh, ptr, osize < nsize ? osize : nsize);
  }
  if (ptr) free((unsigned char *)ptr - off);
  return fresh;
}

/* An allocator whose successive blocks start `base` and `base + 16` bytes past a 64-byte
 * boundary in turn, so that the point arrays x and y (allocated one after the other) lie 16
 * bytes apart modulo 32, as two blocks from glibc's heap usually do: the staged pairs' copy
 * then streams x 32 bytes a store and y 16 (index/cellsort.c, pairs_avx2). */
typedef struct alt_ud {
  size_t base;
  unsigned calls;
} alt_ud_t;

static void *alt_alloc(void *ud, void *ptr, size_t osize, size_t nsize) {
  alt_ud_t *a = ud;
  void *fresh = NULL;
  if (nsize) {
    size_t off = a->base + 16 * (a->calls++ % 2);
    unsigned char *b = aligned_alloc(64, (nsize + off + 63) / 64 * 64);
    if (!b) return NULL;
    fresh = b + off;
    if (ptr) memcpy(fresh, ptr, osize < nsize ? osize : nsize);
  }
  if (ptr) free((unsigned char *)ptr - ((uintptr_t)ptr & 63u));
  return fresh;
}

/* index/cellsort.c: nonzero makes the build take its SSE2 and plain paths where the
 * processor has AVX2, so that both are checked here. */
extern int qk__build_avx2_off;

static void test_build_streamed_order(void **state) {
  (void)state;
  uint64_t seed = qkt_seed(1204);
  qkt_rng_t r;
  qkt_rng_seed(&r, seed);
  print_message("seed %llu\n", (unsigned long long)seed);
  enum { N = 600011 }; /* two shares of 300,005 and 300,006 points */
  qk_point_t *p = malloc(N * sizeof *p);
  unsigned char *seen = malloc(N);
  assert_non_null(p);
  assert_non_null(seen);
  qkt_points(&r, QKT_UNIFORM, p, N);
  for (size_t i = 0; i < N / 10; i++) {
    size_t k = qkt_rng_below(&r, N);
    if (i % 2) /* a duplicate of another point */
      p[k] = p[qkt_rng_below(&r, N)];
    else /* on a line of the 2^8 grid, or one ulp beside it */
      p[k] = (qk_point_t){near_line(&r, 0.0, 1.0), near_line(&r, 0.0, 1.0)};
  }
  qk_tree_options_t o;
  qk_tree_options_init(&o);
  o.capacity = 16;
  o.has_root = 1; /* the inserts' root */
  o.root = (qk_square_t){0, 0, 1};
  /* the oracle (TSan skips the one-thread runs below, which check it against inserts) */
  qkt_shape_t want = oracle_shape(p, N, o);
  /* libc's allocator, then blocks 0 and 8 bytes past a 64-byte boundary */
  size_t offsets[] = {0, 8};
  alt_ud_t alt[] = {{0, 0}, {8, 0}}; /* x and y 16 bytes apart modulo 32 */
  qk_allocator_t alloc[] = {{offset_alloc, &offsets[0]},
                            {offset_alloc, &offsets[1]},
                            {alt_alloc, &alt[0]},
                            {alt_alloc, &alt[1]}};
  /* runs 10 to 19 repeat 0 to 9 without the AVX2 paths; under TSan two threads only, every
   * other such run (1, 5, 9, 13, 17: the five allocators, with and without AVX2) */
  for (unsigned run = QKT_TSAN ? 1 : 0; run < 20; run += QKT_TSAN ? 4 : 1) {
    uint32_t threads = 1 + run % 2;
    o.threads = threads;
    o.allocator = run % 10 < 2 ? NULL : &alloc[(run % 10 - 2) / 2];
    qk__build_avx2_off = run >= 10;
    qk_tree_t *t = NULL;
    assert_int_equal(qk_tree_build(p, N, &o, &t), QK_OK);
    QKT_CHECK_TREE(t);
    qkt_shape_t got = qkt_tree_shape(t);
    if (got.nodes != want.nodes || got.hash != want.hash)
      print_error("seed %llu, run %u, %u threads: %zu nodes vs %zu by inserts\n",
                  (unsigned long long)seed, run, threads, got.nodes, want.nodes);
    assert_int_equal(got.nodes, want.nodes);
    assert_true(got.hash == want.hash);
    memset(seen, 0, N);
    /* the build's grid: 2^8 x 2^8 cells from 2^18 points on (index/build.c) */
    order_check_t oc = {p, N, 0, 0, 0, 8, seen};
    assert_int_equal(qk_tree_visit(t, qk_tree_root(t), order_visit, &oc), QK_OK);
    if (oc.bad)
      print_error("seed %llu, run %u, %u threads: %zu points out of order or altered\n",
                  (unsigned long long)seed, run, threads, oc.bad);
    assert_int_equal(oc.bad, 0);
    assert_int_equal(oc.seen_n, N);
    assert_true(oc.ordered > N / 2); /* most leaves are cells of the grid */
    qk_tree_free(t);
  }
  qk__build_avx2_off = 0;
  free(seen);
  free(p);
}

/* FNV-1a over 64-bit words (their values, not their bytes: the same on any byte order). */
static uint64_t mix(uint64_t h, uint64_t v) {
  for (int b = 0; b < 64; b += 8) h = (h ^ ((v >> b) & 0xff)) * 1099511628211ull;
  return h;
}

static uint64_t bits_of(double v) {
  uint64_t u;
  memcpy(&u, &v, sizeof u);
  return u;
}

/* The tree's raw arrays hashed: the nodes in index order, then the slots. */
static uint64_t raw_hash(const qk_tree_t *t) {
  uint64_t h = 1469598103934665603ull;
  uint32_t nn = qk__tree_node_bound(t), ns = qk__tree_slot_bound(t);
  h = mix(h, nn);
  h = mix(h, ns);
  for (qk_node_t v = 0; v < nn; v++) {
    h = mix(h, qk__node_child(t, v));
    /* An internal node's start is a prefetch hint, checked by test_build_internal_start
     * (it was 0 when these hashes were pinned). */
    h = mix(h, qk__node_leaf(t, v) ? qk__node_start(t, v) : 0);
    h = mix(h, qk__node_count(t, v));
    h = mix(h, qk__node_room(t, v));
    h = mix(h, qk__node_live(t, v));
    h = mix(h, qk__node_parent(t, v));
    h = mix(h, qk__node_depth(t, v));
  }
  const double *x = qk__tree_xs(t), *y = qk__tree_ys(t);
  const qk_id_t *id = qk__tree_ids(t);
  for (uint32_t s = 0; s < ns; s++) {
    h = mix(h, bits_of(x[s]));
    h = mix(h, bits_of(y[s]));
    h = mix(h, id[s]);
  }
  return h;
}

/* Every internal node's start is its first child's, and the leaves, in pre-order, hold
 * consecutive slots from 0: so a node's subtree is the slots [start, start + count), what the
 * searches' prefetch of a subtree's points relies on (query_internal.h). */
static void check_internal_start(const qk_tree_t *t) {
  uint32_t stack[4 * (QK_MAX_DEPTH_LIMIT + 2)], top = 0, pos = 0;
  stack[top++] = 0;
  while (top) {
    const qk_node_t v = stack[--top];
    const uint32_t c = qk__node_child(t, v);
    if (c == QK_NONE) {
      assert_int_equal(qk__node_start(t, v), pos);
      pos += qk__node_count(t, v);
      continue;
    }
    assert_int_equal(qk__node_start(t, v), qk__node_start(t, c));
    for (uint32_t q = 4; q-- > 0;) stack[top++] = c + q;
  }
  assert_int_equal(pos, qk__tree_count(t));
}

static void test_build_internal_start(void **state) {
  (void)state;
  struct {
    qkt_dist_t d;
    size_t n;
    uint32_t capacity;
    uint64_t seed;
  } cases[] = {
      {QKT_UNIFORM, 1000000, 32, 1},  {QKT_CLUSTERED, 300000, 16, 2},
      {QKT_DUPLICATES, 100000, 8, 3}, {QKT_GRID_EDGES, 600011, 16, 4},
      {QKT_UNIFORM, 5000, 1, 5},      {QKT_DUPLICATES, 70001, 16, 6},
  };
  qk_point_t *p = malloc(1000000 * sizeof *p);
  assert_non_null(p);
  for (size_t c = 0; c <= sizeof cases / sizeof *cases; c++) {
    size_t n = 20000;
    uint32_t capacity = 4;
    if (c < sizeof cases / sizeof *cases) {
      qkt_rng_t r;
      qkt_rng_seed(&r, cases[c].seed);
      qkt_points(&r, cases[c].d, p, cases[c].n);
      if (c == 5) /* all points equal */
        for (size_t i = 1; i < cases[c].n; i++) p[i] = p[0];
      n = cases[c].n, capacity = cases[c].capacity;
    } else {
      /* Far from the origin, where the grid's cells cannot be found by scaling: the plain
       * recursive build, whose splits keep their starts too. */
      qkt_rng_t r;
      qkt_rng_seed(&r, 7);
      for (size_t i = 0; i < n; i++)
        p[i] = (qk_point_t){1e15 + 0.125 * (double)(qkt_rng_next(&r) % 512),
                            1e15 + 0.125 * (double)(qkt_rng_next(&r) % 512)};
    }
    for (uint32_t threads = 1; threads <= 2; threads++) {
      qk_tree_options_t o;
      qk_tree_options_init(&o);
      o.capacity = capacity;
      o.threads = threads;
      qk_tree_t *t = NULL;
      assert_int_equal(qk_tree_build(p, n, &o, &t), QK_OK);
      check_internal_start(t);
      qk_tree_free(t);
    }
  }
  free(p);
}

static void test_build_output_pinned(void **state) {
  (void)state;
  struct {
    qkt_dist_t d;
    size_t n;
    uint32_t capacity;
    uint64_t seed, want;
  } cases[] = {
      {QKT_UNIFORM, 1000000, 32, 1, 0x4d6d80de23243b97ull},
      {QKT_CLUSTERED, 300000, 16, 2, 0x32eaba67f3e96db0ull},
      {QKT_DUPLICATES, 100000, 8, 3, 0x03e14f3c49a9630bull},
      {QKT_GRID_EDGES, 600011, 16, 4, 0x0fb1cbbcdca87149ull},
      {QKT_UNIFORM, 1, 16, 5, 0xb319fcbd760957fbull},
      {QKT_DUPLICATES, 70001, 16, 6, 0x765708de545e7c20ull},
  };
  qk_point_t *p = malloc(1000000 * sizeof *p);
  assert_non_null(p);
  for (size_t c = 0; c < sizeof cases / sizeof *cases; c++) {
    /* (under TSan, not the million points: case 3 takes the same threaded paths, the
     * grid's from 2^18 points on, at 600,011) */
    if (QKT_TSAN && c == 0) continue;
    qkt_rng_t r;
    qkt_rng_seed(&r, cases[c].seed);
    qkt_points(&r, cases[c].d, p, cases[c].n);
    if (c == 5) /* all points equal */
      for (size_t i = 1; i < cases[c].n; i++) p[i] = p[0];
    /* one and two threads, with and without the AVX2 paths; two threads with the team's
     * owner running every share, and with each share on its worker (under TSan only the
     * two-thread runs) */
    static const struct {
      uint32_t threads;
      int avx2_off, workers_idle, steal_off;
    } runs[] = {{1, 0, 0, 0}, {2, 0, 0, 0}, {1, 1, 0, 0}, {2, 1, 0, 0}, {2, 0, 1, 0}, {2, 0, 0, 1}};
    for (unsigned run = 0; run < sizeof runs / sizeof *runs; run++) {
      uint32_t threads = runs[run].threads;
      if (QKT_TSAN && threads == 1) continue;
      qk__build_avx2_off = runs[run].avx2_off;
      qk__pool_workers_idle = runs[run].workers_idle;
      qk__pool_steal_off = runs[run].steal_off;
      qk_tree_options_t o;
      qk_tree_options_init(&o);
      o.capacity = cases[c].capacity;
      o.threads = threads;
      qk_tree_t *t = NULL;
      assert_int_equal(qk_tree_build(p, cases[c].n, &o, &t), QK_OK);
      uint64_t h = raw_hash(t);
      if (h != cases[c].want)
        print_error("case %zu, run %u, %u threads: hash %#llx, want %#llx\n", c, run, threads,
                    (unsigned long long)h, (unsigned long long)cases[c].want);
      assert_true(h == cases[c].want);
      qk_tree_free(t);
    }
  }
  qk__build_avx2_off = 0;
  qk__pool_workers_idle = 0;
  qk__pool_steal_off = 0;
  free(p);
}

/* Shares run by the thread; 0 on every new thread. */
static _Thread_local unsigned team_runs;

typedef struct team_probe {
  unsigned ran[8];    /* times each share ran */
  unsigned runs[8];   /* the running thread's count of shares run, with this one */
  unsigned nested[8]; /* shares of a region started inside share 1 */
  bool nest;
} team_probe_t;

static void team_nested_share(void *ctx, unsigned w, unsigned nw) {
  (void)nw;
  unsigned *nested = ctx;
  nested[w]++;
}

static void team_share(void *ctx, unsigned w, unsigned nw) {
  (void)nw;
  team_probe_t *tp = ctx;
  tp->ran[w]++;
  tp->runs[w] = ++team_runs;
  if (tp->nest && w == 1) qk__run_shares(3, team_nested_share, tp->nested + 4);
}

static void team_job(unsigned i, unsigned w, void *ud) {
  (void)w;
  unsigned *done = ud;
  done[i]++;
}

static void test_build_team(void **state) {
  (void)state;
  qk__pool_steal_off = 1; /* (the workers' own counts of shares run are asserted) */
  qk__team_begin(3);
  qk__team_begin(2); /* nested: the outer team (two workers) serves */
  for (unsigned region = 1; region <= 5; region++) {
    team_probe_t tp = {.nest = region == 3};
    qk__run_shares(3, team_share, &tp);
    for (unsigned w = 0; w < 3; w++) assert_int_equal(tp.ran[w], 1);
    /* the workers ran a share of every region so far; thread 0 is the caller */
    assert_int_equal(tp.runs[1], region);
    assert_int_equal(tp.runs[2], region);
    for (unsigned w = 0; w < 3; w++) assert_int_equal(tp.nested[4 + w], region == 3 ? 1 : 0);
  }
  /* a region of two shares: worker 2 only reports back */
  team_probe_t two = {0};
  qk__run_shares(2, team_share, &two);
  assert_int_equal(two.ran[0] + two.ran[1] + two.ran[2], 2);
  assert_int_equal(two.runs[1], 6);
  /* more shares than the team: threads of its own, every share once */
  team_probe_t five = {0};
  qk__run_shares(5, team_share, &five);
  for (unsigned w = 0; w < 5; w++) assert_int_equal(five.ran[w], 1);
  assert_int_equal(five.runs[1], 1);
  unsigned done[100] = {0};
  qk__run_jobs_dynamic(3, 100, team_job, done);
  for (unsigned i = 0; i < 100; i++) assert_int_equal(done[i], 1);
  qk__team_end();
  /* the outer team still holds */
  team_probe_t more = {0};
  qk__run_shares(3, team_share, &more);
  assert_int_equal(more.runs[1], 7);
  assert_int_equal(more.runs[2], 6); /* (its share of the two-share region did not run) */
  qk__team_end();
  /* no team: threads started for the region */
  team_probe_t after = {0};
  qk__run_shares(3, team_share, &after);
  for (unsigned w = 0; w < 3; w++) assert_int_equal(after.ran[w], 1);
  assert_int_equal(after.runs[1], 1);
  assert_int_equal(after.runs[2], 1);
  qk__pool_steal_off = 0;
}

/* A region of nw shares on a team of nw held for it alone: the probe's counts. */
static team_probe_t team_round(unsigned nw) {
  team_probe_t tp = {0};
  qk__team_begin(nw);
  qk__run_shares(nw, team_share, &tp);
  qk__team_end();
  return tp;
}

/* A team on another thread of the process: its probe's counts (steal off). */
static void *team_elsewhere(void *arg) {
  *(team_probe_t *)arg = team_round(3);
  return NULL;
}

#if defined(__linux__)
/* A team of two on a thread pinned to the first processor it may run on. */
static void *team_pinned(void *arg) {
  cpu_set_t all, one;
  if (sched_getaffinity(0, sizeof all, &all) != 0) return NULL;
  CPU_ZERO(&one);
  for (int c = 0; c < CPU_SETSIZE; c++)
    if (CPU_ISSET(c, &all)) {
      CPU_SET(c, &one);
      break;
    }
  if (pthread_setaffinity_np(pthread_self(), sizeof one, &one) != 0) return NULL;
  *(team_probe_t *)arg = team_round(2);
  return NULL;
}
#endif

/*
 * The last team's workers are kept, parked, for the next team of the same size: the next
 * team runs on the same two workers (their thread-local counts go on), also when it is
 * held by another thread; a team of another size ends them and starts its own; after
 * qk__team_release() a team starts new workers; in a child forked while workers are kept,
 * a team starts workers of its own (the parent's are not there) and runs every share once.
 * Builds on two threads in a row give the same tree as one thread (test_build_threads).
 */
static void test_build_team_kept(void **state) {
  (void)state;
  qk__pool_steal_off = 1;
  qk__team_release();
  team_probe_t first = team_round(3);
  assert_int_equal(first.runs[1], 1);
  assert_int_equal(first.runs[2], 1);
  team_probe_t again = team_round(3);
  assert_int_equal(again.runs[1], 2); /* the same workers */
  assert_int_equal(again.runs[2], 2);
  pthread_t th;
  team_probe_t other = {0};
  assert_int_equal(pthread_create(&th, NULL, team_elsewhere, &other), 0);
  assert_int_equal(pthread_join(th, NULL), 0);
  for (unsigned w = 0; w < 3; w++) assert_int_equal(other.ran[w], 1);
  assert_int_equal(other.runs[1], 3);
  assert_int_equal(other.runs[2], 3);
  team_probe_t two = team_round(2); /* another size: new workers */
  assert_int_equal(two.runs[1], 1);
  team_probe_t two_again = team_round(2);
  assert_int_equal(two_again.runs[1], 2);
#if !QKT_TSAN /* (TSan does not follow a multithreaded process into fork) */
  pid_t pid = fork();
  assert_true(pid >= 0);
  if (pid == 0) {
    team_probe_t child = team_round(2);
    qk__team_release();
    _exit(child.ran[0] == 1 && child.ran[1] == 1 && child.runs[1] == 1 ? 0 : 1);
  }
  int st = 0;
  assert_int_equal(waitpid(pid, &st, 0), pid);
  assert_true(WIFEXITED(st) && WEXITSTATUS(st) == 0);
#endif
  qk__team_release();
  team_probe_t fresh = team_round(2);
  assert_int_equal(fresh.runs[1], 1);
  qk__team_release();
#if defined(__linux__)
  /* A team kept by a thread pinned to one processor (its workers took that set) does not
   * serve a thread allowed others: new workers (they served it, pinned, before). */
  cpu_set_t all;
  if (sched_getaffinity(0, sizeof all, &all) == 0 && CPU_COUNT(&all) > 1) {
    team_probe_t pinned = {0};
    assert_int_equal(pthread_create(&th, NULL, team_pinned, &pinned), 0);
    assert_int_equal(pthread_join(th, NULL), 0);
    assert_int_equal(pinned.ran[0] + pinned.ran[1], 2);
    team_probe_t after = team_round(2);
    assert_int_equal(after.runs[1], 1);
    qk__team_release();
  }
#endif
  qk__pool_steal_off = 0;
}

static void pool_inner(void *ctx, unsigned w, unsigned nw) {
  (void)ctx, (void)w, (void)nw;
  fail_msg("a refused region ran");
}

typedef struct pool_probe {
  unsigned ran[4], runs[4];
  qk__pool_t *p;
  int inner; /* qk__pool_run from share 1 */
} pool_probe_t;

static void pool_share(void *ctx, unsigned w, unsigned nw) {
  (void)nw;
  pool_probe_t *pp = ctx;
  pp->ran[w]++;
  pp->runs[w] = ++team_runs;
  if (w == 1) pp->inner = qk__pool_run(pp->p, 2, pool_inner, NULL);
}

typedef struct pool_job {
  atomic_int done;
  pthread_t by;
} pool_job_t;

static void pool_slow_job(void *ctx) {
  pool_job_t *j = ctx;
  struct timespec ts = {0, 20000000}; /* 20 ms */
  nanosleep(&ts, NULL);
  j->by = pthread_self();
  atomic_store(&j->done, 1);
}

static void test_build_pool(void **state) {
  (void)state;
  qk__pool_steal_off = 1; /* (which thread ran a share is asserted) */
  assert_null(qk__pool_new(NULL, 1));
  assert_int_equal(qk__pool_threads(NULL), 1);
  assert_int_equal(qk__pool_run(NULL, 2, pool_inner, NULL), 0);
  assert_int_equal(qk__pool_detach(NULL, pool_slow_job, NULL), 0);
  qk__pool_free(NULL);
  qk__pool_t *p = qk__pool_new(NULL, 3);
  assert_non_null(p);
  assert_int_equal(qk__pool_threads(p), 3);
  assert_true(qk__pool_live(p));
  unsigned base = 0;
  for (unsigned region = 1; region <= 4; region++) {
    pool_probe_t pp = {.p = p, .inner = -1};
    assert_int_equal(qk__pool_run(p, 3, pool_share, &pp), 1);
    for (unsigned w = 0; w < 3; w++) assert_int_equal(pp.ran[w], 1);
    if (region == 1) base = pp.runs[0] - 1;
    assert_int_equal(pp.runs[0], base + region); /* (the calling thread) */
    assert_int_equal(pp.runs[1], region);        /* the same two workers every time */
    assert_int_equal(pp.runs[2], region);
    assert_int_equal(pp.inner, 0); /* taken */
  }
  /* more shares than threads: refused */
  assert_int_equal(qk__pool_run(p, 4, pool_inner, NULL), 0);
  /* a detached job: the caller goes on, the next region waits for it */
  pool_job_t job = {0};
  assert_int_equal(qk__pool_detach(p, pool_slow_job, &job), 1);
  assert_int_equal(atomic_load(&job.done), 0);
  pool_probe_t after = {.p = p};
  assert_int_equal(qk__pool_run(p, 2, pool_share, &after), 1);
  assert_int_equal(atomic_load(&job.done), 1);
  assert_false(pthread_equal(job.by, pthread_self()));
  assert_int_equal(after.ran[0] + after.ran[1] + after.ran[2], 2);
#if !QKT_TSAN /* (TSan does not follow a multithreaded process into fork) */
  pid_t pid = fork();
  assert_true(pid >= 0);
  if (pid == 0) {
    int ok = !qk__pool_live(p) && qk__pool_run(p, 2, pool_inner, NULL) == 0 &&
             qk__pool_detach(p, pool_slow_job, NULL) == 0;
    qk__pool_free(p); /* (only the memory) */
    _exit(ok ? 0 : 1);
  }
  int st = 0;
  assert_int_equal(waitpid(pid, &st, 0), pid);
  assert_true(WIFEXITED(st) && WEXITSTATUS(st) == 0);
#endif
  pool_probe_t last = {.p = p};
  assert_int_equal(qk__pool_run(p, 3, pool_share, &last), 1);
  qk__pool_free(p);
  qk__pool_steal_off = 0;
}

/* Shares that count their runs, in a region of many (the race between a worker taking its
 * share and the owner taking it). */
static void steal_share(void *ctx, unsigned w, unsigned nw) {
  (void)nw;
  atomic_uint *ran = ctx;
  atomic_fetch_add(&ran[w], 1u);
}

/* The owner of a pool runs the shares its workers have not taken when share 0 ends: with
 * workers that take none, every share of every region on the calling thread, once; with
 * workers that do, every share once whoever takes it, over many short regions. */
static void test_build_pool_steal(void **state) {
  (void)state;
  qk__pool_t *p = qk__pool_new(NULL, 3);
  assert_non_null(p);
  qk__pool_workers_idle = 1;
  unsigned before = team_runs;
  for (unsigned region = 1; region <= 4; region++) {
    pool_probe_t pp = {.p = p, .inner = -1};
    assert_int_equal(qk__pool_run(p, 3, pool_share, &pp), 1);
    for (unsigned w = 0; w < 3; w++) assert_int_equal(pp.ran[w], 1);
    /* in order, on this thread */
    for (unsigned w = 0; w < 3; w++)
      assert_int_equal(pp.runs[w], before + 3 * (region - 1) + w + 1);
    assert_int_equal(pp.inner, 0); /* (the pool is taken while share 1 runs here too) */
  }
  qk__pool_workers_idle = 0;
  for (int hold = 0; hold <= 1; hold++) {
    qk__pool_hold(p, hold);
    for (unsigned region = 0; region < 3000; region++) {
      atomic_uint ran[3];
      for (unsigned w = 0; w < 3; w++) atomic_init(&ran[w], 0u);
      unsigned nw = 2 + region % 2;
      assert_int_equal(qk__pool_run(p, nw, steal_share, ran), 1);
      for (unsigned w = 0; w < 3; w++) assert_int_equal(atomic_load(&ran[w]), w < nw ? 1u : 0u);
    }
  }
  qk__pool_hold(p, 0);
  /* a detached job is never the owner's: it runs on a worker */
  pool_job_t job = {0};
  assert_int_equal(qk__pool_detach(p, pool_slow_job, &job), 1);
  pool_probe_t after = {.p = p};
  assert_int_equal(qk__pool_run(p, 2, pool_share, &after), 1);
  assert_int_equal(atomic_load(&job.done), 1);
  assert_false(pthread_equal(job.by, pthread_self()));
  qk__pool_free(p);
}

#if defined(__linux__) && defined(CPU_SET)
typedef struct away_probe {
  cpu_set_t mine; /* the test's processors */
  int same;       /* share 1 ran with the test's set of processors */
} away_probe_t;

static void away_share(void *ctx, unsigned w, unsigned nw) {
  (void)nw;
  away_probe_t *ap = ctx;
  if (w != 1) return;
  cpu_set_t s;
  CPU_ZERO(&s);
  ap->same = pthread_getaffinity_np(pthread_self(), sizeof s, &s) == 0 && CPU_EQUAL(&s, &ap->mine);
}

/* What the threads qk__run_shares starts for a region report about their start. */
typedef struct shares_probe {
  away_probe_t ap;
  int start[QK__MAX_THREADS], home[QK__MAX_THREADS];
} shares_probe_t;

static void shares_away_share(void *ctx, unsigned w, unsigned nw) {
  shares_probe_t *sp = ctx;
  sp->start[w] = qk__share_start_cpu(&sp->home[w]);
  if (w == 1) away_share(&sp->ap, w, nw);
}
#endif

static void owner_share(void *ctx, unsigned w, unsigned nw) {
  (void)nw;
  const long *ns = ctx;
  if (w != 1) return;
  /* busy, as a share's work is (a sleeping worker is woken late on a loaded machine) */
  struct timespec a, b;
  clock_gettime(CLOCK_MONOTONIC, &a);
  do clock_gettime(CLOCK_MONOTONIC, &b);
  while ((b.tv_sec - a.tv_sec) * 1000000000L + (b.tv_nsec - a.tv_nsec) < *ns);
}

static void test_build_pool_owner_spins(void **state) {
  (void)state;
  qk__pool_steal_off = 1; /* (share 1 is the worker's, however late) */
  qk__pool_t *p = qk__pool_new(NULL, 2);
  assert_non_null(p);
  /* Not held: 50 us, then parked (a worker 2 ms behind has the caller parked). */
  assert_int_equal(qk__pool_wait_spin_ns(p), 50000);
  long slow = 2000000, short_ = 150000;
  for (int r = 0; r < 3; r++) assert_int_equal(qk__pool_run(p, 2, owner_share, &slow), 1);
  unsigned parked = qk__pool_owner_parks(p);
  assert_true(parked >= 1); /* (unless the caller itself lost its processor for 2 ms) */
  /* Held: 1 ms; a worker 0.15 ms behind finds the caller still spinning (in at least one of
   * twenty regions: a loaded machine may take the worker's processor for longer). */
  qk__pool_hold(p, 1);
  assert_int_equal(qk__pool_wait_spin_ns(p), 1000000);
  for (int r = 0; r < 20; r++) assert_int_equal(qk__pool_run(p, 2, owner_share, &short_), 1);
  assert_true(qk__pool_owner_parks(p) - parked < 20);
  qk__pool_hold(p, 0);
  qk__pool_free(p);
  qk__pool_steal_off = 0;
}

static void test_build_pool_away(void **state) {
  (void)state;
#if defined(__linux__) && defined(CPU_SET)
  qk__pool_steal_off = 1; /* (share 1 runs on the worker, which has started when it ends) */
  away_probe_t ap = {.same = -1};
  CPU_ZERO(&ap.mine);
  assert_int_equal(sched_getaffinity(0, sizeof ap.mine, &ap.mine), 0);
  for (int round = 0; round < 4; round++) {
    qk__pool_t *p = qk__pool_new(NULL, 2);
    assert_non_null(p);
    assert_int_equal(qk__pool_run(p, 2, away_share, &ap), 1);
    int home, start = qk__pool_start_cpu(p, 0, &home);
    if (CPU_COUNT(&ap.mine) > 1 && sched_getcpu() >= 0) {
      assert_true(home >= 0 && CPU_ISSET(home, &ap.mine));
      assert_true(start >= 0 && CPU_ISSET(start, &ap.mine));
      assert_int_not_equal(start, home); /* started away */
    } else {
      assert_int_equal(start, -1); /* nowhere else to go: started as usual */
    }
    assert_int_equal(ap.same, 1); /* and not pinned there */
    ap.same = -1;
    qk__pool_free(p);
  }
  qk__pool_steal_off = 0;
#else
  skip();
#endif
}

/* The threads qk__run_shares starts for a region (no team held) start away from the
 * calling thread's processor too, and then run wherever it may. */
static void test_build_shares_away(void **state) {
  (void)state;
#if defined(__linux__) && defined(CPU_SET)
  cpu_set_t mine;
  CPU_ZERO(&mine);
  assert_int_equal(sched_getaffinity(0, sizeof mine, &mine), 0);
  const int many = CPU_COUNT(&mine) > 1 && sched_getcpu() >= 0;
  for (int round = 0; round < 8; round++) {
    const unsigned nw = 2 + (unsigned)round % 2;
    shares_probe_t sp = {.ap = {.mine = mine, .same = -1}};
    qk__run_shares(nw, shares_away_share, &sp);
    int home;
    assert_int_equal(sp.start[0], -1); /* share 0: the calling thread */
    assert_int_equal(qk__share_start_cpu(&home), -1);
    for (unsigned w = 1; w < nw; w++) {
      if (many) {
        assert_true(sp.home[w] >= 0 && CPU_ISSET(sp.home[w], &mine));
        assert_true(sp.start[w] >= 0 && CPU_ISSET(sp.start[w], &mine));
        assert_int_not_equal(sp.start[w], sp.home[w]); /* started away */
      } else {
        assert_int_equal(sp.start[w], -1); /* nowhere else to go: started as usual */
      }
    }
    assert_int_equal(sp.ap.same, 1); /* and not pinned there */
  }
#else
  skip();
#endif
}

int main(void) {
  qkt_filters_from_env();
  const struct CMUnitTest tests[] = {
      cmocka_unit_test(test_build_team),
      cmocka_unit_test(test_build_team_kept),
      cmocka_unit_test(test_build_pool),
      cmocka_unit_test(test_build_pool_steal),
      cmocka_unit_test(test_build_pool_away),
      cmocka_unit_test(test_build_shares_away),
      cmocka_unit_test(test_build_pool_owner_spins),
      cmocka_unit_test(test_build_deep_grid_lines),
      cmocka_unit_test(test_build_threads_adversarial),
      cmocka_unit_test(test_build_tree_beside_sort),
      cmocka_unit_test(test_build_streamed_order),
      cmocka_unit_test(test_build_output_pinned),
      cmocka_unit_test(test_build_internal_start),
  };
  return cmocka_run_group_tests(tests, NULL, NULL);
}
