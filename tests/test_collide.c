/*
 * Test plan for the collider (collide/collider.c):
 *  - all overlapping pairs of random discs, boxes and mixed sets (small and large items,
 *    touching items, zero radii and degenerate boxes, clustered centres) at several
 *    capacities, against the O(n^2) loop;
 *  - items overlapping a query box (also of zero width, height or both) or disc
 *    against brute force;
 *  - first hit of rays and segments against an oracle derived independently (exact
 *    rational arithmetic with GMP; tests/support/query_oracle.c): origins inside
 *    items (t = 0), outside the whole set, axis-parallel directions, components so
 *    small that their reciprocals overflow, tmax cut-offs;
 *  - hand-computed cases (tangent discs, a ray grazing a box corner);
 *  - bad input and allocation failure at every N (clean QK_ERR_NOMEM, no leak);
 *  - three threads casting rays and finding pairs on one collider at once;
 *  - the threads option: pairs (in callback order, also stopped early), the pairs list
 *    and ray batches on 2, 3 and all cores equal to one thread; allocation failure at
 *    every N on the threaded paths (the same answers, or a clean QK_ERR_NOMEM), and
 *    every allocation of the worker threads failing (the same pairs, in order); ray
 *    batches of counts around the 16 jobs whose error records live on the stack (every
 *    block given back after each batch);
 *  - on Linux, the ray arrays advised for huge pages by default (huge_pages left 0): a
 *    region flagged "hg" in /proc/self/smaps appears with the build, and the answers are
 *    those of the same collider from an allocator that is never advised.
 *  - a skewed scene (most pairs in a few leaves) on 2 and 3 threads: the one-thread
 *    sequence, also stopped early at many places, the oracle's set, the calling thread;
 *  - rays over leaves of every count up to the capacity, with discs given twice under
 *    other ids, and searches that climb, against brute force to the last bit of t;
 *  - the order of the pairs (leaf of the smaller id in pre-order, then the other's leaf,
 *    then their places in the leaves) against the oracle's set sorted into that order;
 *  - the ray structures made on first need: a collider never cast holds none and frees
 *    cleanly, qk_collider_prepare_rays makes them (once: a second call allocates
 *    nothing), rays from 2 and 4 threads at once on an unprepared collider (single casts
 *    and a batch) give the oracle's answers, and allocation failure at every N during the
 *    preparation (by each entry point) returns QK_ERR_NOMEM, holds nothing more, and a
 *    retry answers as the oracle;
 *  - disc pairs at scales 1, 1e-200, 2^-1000 and 1e200 against the oracle, with the exact
 *    (big-integer) tests counted through --wrap and bounded (no timing).
 */
#define _DEFAULT_SOURCE /* madvise and MADV_HUGEPAGE in <sys/mman.h> */
#include <math.h>
#include <pthread.h>
#include <sched.h>
#include <stdatomic.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#if defined(__GLIBC__)
#include <malloc.h> /* mallopt */
#endif
#if defined(__linux__)
#include <sys/mman.h>
#endif

#include "qk_test.h"
#include "query_oracle.h"

static uint64_t g_seed;

/* Random items: `big` mixes a few large items into many small ones. */
static void make_items(qkt_rng_t *r, qk_disc_t *d, size_t nd, qk_box_t *b, size_t nb, int clustered,
                       double scale) {
  for (size_t i = 0; i < nd; i++) {
    double cx = qkt_rng_unit(r), cy = qkt_rng_unit(r);
    if (clustered) cx = 0.3 + 0.1 * cx, cy = 0.6 + 0.1 * cy;
    double rad =
        qkt_rng_below(r, 20) == 0 ? qkt_rng_range(r, 0, 10 * scale) : qkt_rng_range(r, 0, scale);
    if (i % 37 == 5) rad = 0;
    d[i] = (qk_disc_t){cx, cy, rad};
  }
  for (size_t i = 0; i < nb; i++) {
    double cx = qkt_rng_unit(r), cy = qkt_rng_unit(r);
    if (clustered) cx = 0.3 + 0.1 * cx, cy = 0.6 + 0.1 * cy;
    double w =
        qkt_rng_below(r, 20) == 0 ? qkt_rng_range(r, 0, 10 * scale) : qkt_rng_range(r, 0, scale);
    double h = qkt_rng_range(r, 0, scale);
    if (i % 41 == 3) w = 0;
    b[i] = (qk_box_t){cx - w, cy - h, cx + w, cy + h};
  }
  /* A few exactly touching pairs: a disc tangent to the previous one, a box sharing an
   * edge with the previous one. */
  for (size_t i = 1; i + 1 < nd; i += 50)
    d[i] = (qk_disc_t){d[i - 1].x + d[i - 1].r + 0.25, d[i - 1].y, 0.25};
  for (size_t i = 1; i + 1 < nb; i += 50)
    b[i] = (qk_box_t){b[i - 1].xmax, b[i - 1].ymin, b[i - 1].xmax + 0.01, b[i - 1].ymax};
}

static qk_tree_options_t opts(uint32_t cap) {
  qk_tree_options_t o;
  qk_tree_options_init(&o);
  o.capacity = cap;
  return o;
}

static void check_pairs(const qk_disc_t *d, size_t nd, const qk_box_t *b, size_t nb, uint32_t cap) {
  qk_tree_options_t o = opts(cap);
  qk_collider_t *c = NULL;
  assert_int_equal(qk_collider_build(d, nd, b, nb, &o, &c), QK_OK);
  QKT_CHECK_TREE(qk_collider_tree(c));
  assert_int_equal(qk_collider_size(c), nd + nb);
  qk_pair_t *want;
  size_t nw = qko_pairs(d, nd, b, nb, &want), ng = 0;
  assert_int_equal(qk_collider_pairs_list(c, NULL, 0, &ng), QK_OK);
  if (ng != nw)
    fail_msg("pairs: %zu, oracle %zu (nd %zu nb %zu cap %u seed %llu)", ng, nw, nd, nb, cap,
             (unsigned long long)g_seed);
  qk_pair_t *got = malloc((ng ? ng : 1) * sizeof *got);
  assert_int_equal(qk_collider_pairs_list(c, got, ng, &ng), QK_OK);
  for (size_t i = 0; i < nw; i++)
    if (got[i].a != want[i].a || got[i].b != want[i].b)
      fail_msg("pair %zu: (%u,%u) vs oracle (%u,%u) (seed %llu)", i, got[i].a, got[i].b, want[i].a,
               want[i].b, (unsigned long long)g_seed);
  free(got);
  free(want);
  qk_collider_free(c);
}

/* The library's exact (big-integer) test, counted: linked with --wrap for this program
 * (tests/CMakeLists.txt; test_collide_scale). */
int qk__within_exact(double ax, double ay, double bx, double by, double r1, double r2);
int __real_qk__within_exact(double ax, double ay, double bx, double by, double r1, double r2);
int __wrap_qk__within_exact(double ax, double ay, double bx, double by, double r1, double r2);
static _Atomic size_t g_exact_calls; /* (atomic: threaded tests call the library too) */
int __wrap_qk__within_exact(double ax, double ay, double bx, double by, double r1, double r2) {
  g_exact_calls++;
  return __real_qk__within_exact(ax, ay, bx, by, r1, r2);
}

/*
 * Disc pairs and disc queries at every magnitude: discs of radius S/1000 (some 0) at
 * uniform centres in [0, S]^2 for S = 1, 1e-200, 2^-1000 and 1e200, on one thread, against
 * brute force. Below about 1e-154 the squares underflowed under the filter's absolute
 * margin and from radii of 2^500 on they left its range: every candidate pair went to the
 * exact test (pairs_list of 32,000 discs 3.5 s at 1e-200 and 1e200 against 2 ms at 1;
 * fifty-sixth session). The count of exact tests (wrapped at link time) must stay below
 * one per ten discs (0 here); before the fix it was one per candidate pair (885 here at
 * every scale but 1).
 */
static void test_collide_scale(void **state) {
  (void)state;
  QKT_ONE_THREAD_TEST();
  qkt_rng_t r;
  qkt_rng_seed(&r, g_seed + 56);
  enum { N = 1000 };
  static const double scales[] = {1, 1e-200, 0x1p-1000, 1e200};
  qk_disc_t *d = malloc(N * sizeof *d);
  assert_non_null(d);
  for (size_t si = 0; si < sizeof scales / sizeof scales[0]; si++) {
    const double S = scales[si];
    for (size_t i = 0; i < N; i++)
      d[i] = (qk_disc_t){qkt_rng_unit(&r) * S, qkt_rng_unit(&r) * S,
                         i % 37 == 5 ? 0 : qkt_rng_range(&r, 0, 0.02) * S};
    qk_tree_options_t o = opts(8);
    o.threads = 1;
    qk_collider_t *c = NULL;
    assert_int_equal(qk_collider_build(d, N, NULL, 0, &o, &c), QK_OK);
    qk_pair_t *want;
    const size_t nw = qko_pairs(d, N, NULL, 0, &want);
    size_t ng = 0;
    const size_t before = g_exact_calls;
    assert_int_equal(qk_collider_pairs_list(c, NULL, 0, &ng), QK_OK);
    const size_t calls = g_exact_calls - before;
    qk_pair_t *got = malloc((ng ? ng : 1) * sizeof *got);
    assert_non_null(got);
    assert_int_equal(qk_collider_pairs_list(c, got, ng, &ng), QK_OK);
    if (ng != nw) fail_msg("scale %g: %zu pairs, oracle %zu", S, ng, nw);
    for (size_t i = 0; i < nw; i++)
      if (got[i].a != want[i].a || got[i].b != want[i].b)
        fail_msg("scale %g pair %zu: (%u,%u) vs oracle (%u,%u) (seed %llu)", S, i, got[i].a,
                 got[i].b, want[i].a, want[i].b, (unsigned long long)g_seed);
    printf("# scale %g: %zu pairs, %zu exact tests\n", S, ng, calls);
    if (calls > N / 10)
      fail_msg("scale %g: %zu exact tests for %d discs (seed %llu)", S, calls, N,
               (unsigned long long)g_seed);
    free(got);
    free(want);
    qk_collider_free(c);
  }
  free(d);
}

static void test_collide_pairs(void **state) {
  (void)state;
  QKT_ONE_THREAD_TEST();
  qkt_rng_t r;
  qkt_rng_seed(&r, g_seed);
  const size_t n = 1500;
  qk_disc_t *d = malloc(n * sizeof *d);
  qk_box_t *b = malloc(n * sizeof *b);
  const uint32_t caps[] = {1, 4, 16};
  for (int cl = 0; cl < 2; cl++)
    for (int ci = 0; ci < 3; ci++) {
      make_items(&r, d, n, b, n, cl, cl ? 0.002 : 0.01);
      check_pairs(d, n, NULL, 0, caps[ci]);
      check_pairs(NULL, 0, b, n, caps[ci]);
      check_pairs(d, n / 2, b, n / 2, caps[ci]);
    }
  check_pairs(NULL, 0, NULL, 0, 4);
  free(d), free(b);
}

typedef struct ids {
  qk_id_t *v;
  size_t n;
} ids_t;

static int add_id(qk_id_t id, qk_point_t p, double dist, void *ud) {
  ids_t *s = ud;
  (void)p, (void)dist;
  s->v[s->n++] = id;
  return 0;
}

static void test_collide_query_shapes(void **state) {
  (void)state;
  QKT_ONE_THREAD_TEST();
  qkt_rng_t r;
  qkt_rng_seed(&r, g_seed + 1);
  const size_t nd = 800, nb = 800;
  qk_disc_t *d = malloc(nd * sizeof *d);
  qk_box_t *b = malloc(nb * sizeof *b);
  qk_id_t *want = malloc((nd + nb) * sizeof *want);
  ids_t got = {malloc((nd + nb) * sizeof(qk_id_t)), 0};
  make_items(&r, d, nd, b, nb, 0, 0.02);
  qk_tree_options_t o = opts(4);
  qk_collider_t *c = NULL;
  assert_int_equal(qk_collider_build(d, nd, b, nb, &o, &c), QK_OK);
  for (int qi = 0; qi < 400; qi++) {
    double x = qkt_rng_range(&r, -0.5, 1.5), y = qkt_rng_range(&r, -0.5, 1.5);
    double s = qkt_rng_range(&r, 0, 0.2);
    qk_disc_t qd = {x, y, qi % 20 == 0 ? 0 : s};
    qk_box_t qb = {x - s, y - s * 0.5, x + s, y + s * 0.5};
    /* degenerate boxes too (valid, as items): a horizontal line's, a vertical one's and a
     * point's */
    if (qi % 20 == 10) qb.ymin = qb.ymax = y;
    if (qi % 20 == 15) qb.xmin = qb.xmax = x;
    if (qi % 40 == 5) qb = (qk_box_t){x, y, x, y};
    got.n = 0;
    assert_int_equal(qk_collider_query_disc(c, qd, add_id, &got), QK_OK);
    qko_sort_ids(got.v, got.n);
    size_t nw = qko_overlap(d, nd, b, nb, 1, qd, qb, want);
    if (got.n != nw || memcmp(got.v, want, nw * sizeof *want))
      fail_msg("disc query %d: %zu vs oracle %zu (seed %llu)", qi, got.n, nw,
               (unsigned long long)g_seed);
    got.n = 0;
    assert_int_equal(qk_collider_query_box(c, qb, add_id, &got), QK_OK);
    qko_sort_ids(got.v, got.n);
    nw = qko_overlap(d, nd, b, nb, 0, qd, qb, want);
    if (got.n != nw || memcmp(got.v, want, nw * sizeof *want))
      fail_msg("box query %d: %zu vs oracle %zu (seed %llu)", qi, got.n, nw,
               (unsigned long long)g_seed);
  }
  assert_int_equal(qk_collider_query_box(c, (qk_box_t){1, 0, 0, 1}, add_id, &got), QK_ERR_GEOMETRY);
  assert_int_equal(qk_collider_query_disc(c, (qk_disc_t){0, 0, -1}, add_id, &got), QK_ERR_GEOMETRY);
  assert_int_equal(qk_collider_query_disc(c, (qk_disc_t){NAN, 0, 1}, add_id, &got),
                   QK_ERR_NONFINITE);
  qk_collider_free(c);
  free(d), free(b), free(want), free(got.v);
}

/*
 * The library's hit agrees with the oracle's: the same item, or one the oracle says is
 * entered within a rounding of the best; and a t within a rounding of the oracle's
 * (exact with GMP) entry parameter for that item.
 */
static int ray_agrees(qk_hit_t h, qk_hit_t w, const qk_disc_t *d, size_t nd, const qk_box_t *b,
                      qk_point_t o, qk_point_t dir, double tmax) {
  if (w.id == QK_NONE || h.id == QK_NONE) return w.id == h.id;
  double tol = 1e-12 * (1 + w.t + (fabs(o.x) + fabs(o.y) + 1) / hypot(dir.x, dir.y));
  double th = h.id == w.id ? w.t : qko_ray_item(d, nd, b, h.id, o, dir, tmax);
  return th >= 0 && fabs(th - w.t) <= tol && fabs(h.t - th) <= tol;
}

static void test_collide_raycast(void **state) {
  (void)state;
  QKT_ONE_THREAD_TEST();
  qkt_rng_t r;
  qkt_rng_seed(&r, g_seed + 2);
  const size_t nd = 1000, nb = 1000;
  qk_disc_t *d = malloc(nd * sizeof *d);
  qk_box_t *b = malloc(nb * sizeof *b);
  for (int set = 0; set < 3; set++) {
    make_items(&r, d, nd, b, nb, set == 2, 0.01);
    size_t use_d = set == 1 ? 0 : nd, use_b = set == 0 ? 0 : nb;
    qk_tree_options_t o = opts(set == 2 ? 1 : 8);
    qk_collider_t *c = NULL;
    assert_int_equal(qk_collider_build(use_d ? d : NULL, use_d, use_b ? b : NULL, use_b, &o, &c),
                     QK_OK);
    for (int qi = 0; qi < 1000; qi++) {
      qk_point_t org = {qkt_rng_range(&r, -0.5, 1.5), qkt_rng_range(&r, -0.5, 1.5)};
      double ang = qkt_rng_range(&r, 0, 6.283185307179586);
      qk_point_t dir = {cos(ang), sin(ang)};
      if (qi % 10 == 0) dir = (qk_point_t){0, qi % 20 ? 1.0 : -2.0};
      if (qi % 10 == 1) dir = (qk_point_t){qi % 20 ? 3.0 : -1.0, 0};
      /* A component so small that its reciprocal overflows: the dividing node test. */
      if (qi % 10 == 3)
        dir = (qk_point_t){qi % 20 < 10 ? -0.7 : 0.7, qi % 40 < 20 ? 1e-310 : -3e-320};
      if (qi % 10 == 4)
        dir = (qk_point_t){qi % 20 < 10 ? 1e-309 : -5e-324, qi % 40 < 20 ? 1.0 : -2.0};
      if (qi % 10 == 2 && use_d) org = (qk_point_t){d[qi % nd].x, d[qi % nd].y};
      double tmax = qi % 3 == 0 ? qkt_rng_range(&r, 0, 0.5) : INFINITY;
      qk_hit_t h, w = qko_raycast(use_d ? d : NULL, use_d, use_b ? b : NULL, use_b, org, dir, tmax);
      assert_int_equal(qk_collider_raycast(c, org, dir, tmax, &h), QK_OK);
      if (!ray_agrees(h, w, use_d ? d : NULL, use_d, use_b ? b : NULL, org, dir, tmax))
        fail_msg("ray %d (set %d): hit (%u, %.17g) vs oracle (%u, %.17g) (seed %llu)", qi, set,
                 h.id, h.t, w.id, w.t, (unsigned long long)g_seed);
    }
    qk_collider_free(c);
  }
  free(d), free(b);
}

/* The failing allocator behind a lock, for the worker threads. */
typedef struct locked {
  pthread_mutex_t mu;
  qkt_alloc_t st;
} locked_t;

static void *locked_fn(void *ud, void *ptr, size_t osize, size_t nsize) {
  locked_t *l = ud;
  pthread_mutex_lock(&l->mu);
  void *p = qkt_alloc_fn(&l->st, ptr, osize, nsize);
  pthread_mutex_unlock(&l->mu);
  return p;
}

/* A collider holds exactly the given items: its size and tree, every overlapping pair,
 * items overlapping query boxes and discs, and first hits of rays, all against the
 * oracle. */
static void expect_items(const qk_collider_t *c, const qk_disc_t *d, size_t nd, const qk_box_t *b,
                         size_t nb, qkt_rng_t *r, const char *what) {
  const size_t n = nd + nb;
  if (qk_collider_size(c) != n)
    fail_msg("%s: %zu items, %zu given (seed %llu)", what, qk_collider_size(c), n,
             (unsigned long long)g_seed);
  QKT_CHECK_TREE(qk_collider_tree(c));
  qk_pair_t *want;
  size_t nw = qko_pairs(d, nd, b, nb, &want), ng = 0;
  assert_int_equal(qk_collider_pairs_list(c, NULL, 0, &ng), QK_OK);
  if (ng != nw)
    fail_msg("%s: %zu pairs, oracle %zu (seed %llu)", what, ng, nw, (unsigned long long)g_seed);
  qk_pair_t *got = malloc((ng ? ng : 1) * sizeof *got);
  assert_int_equal(qk_collider_pairs_list(c, got, ng, &ng), QK_OK);
  for (size_t i = 0; i < nw; i++)
    if (got[i].a != want[i].a || got[i].b != want[i].b)
      fail_msg("%s: pair %zu (%u,%u) vs oracle (%u,%u) (seed %llu)", what, i, got[i].a, got[i].b,
               want[i].a, want[i].b, (unsigned long long)g_seed);
  free(got);
  free(want);
  qk_id_t *wid = malloc((n ? n : 1) * sizeof *wid);
  ids_t gid = {malloc((n ? n : 1) * sizeof(qk_id_t)), 0};
  for (int qi = 0; qi < 12; qi++) {
    double x = qkt_rng_range(r, -0.2, 1.2), y = qkt_rng_range(r, -0.2, 1.2);
    double h = qkt_rng_range(r, 0, 0.1);
    qk_disc_t qd = {x, y, h};
    qk_box_t qb = {x - h, y - 2 * h, x + h, y + h};
    for (int is_disc = 0; is_disc < 2; is_disc++) {
      gid.n = 0;
      if (is_disc)
        assert_int_equal(qk_collider_query_disc(c, qd, add_id, &gid), QK_OK);
      else
        assert_int_equal(qk_collider_query_box(c, qb, add_id, &gid), QK_OK);
      qko_sort_ids(gid.v, gid.n);
      size_t k = qko_overlap(d, nd, b, nb, is_disc, qd, qb, wid);
      if (gid.n != k || memcmp(gid.v, wid, k * sizeof *wid))
        fail_msg("%s: %s query %d: %zu items, oracle %zu (seed %llu)", what,
                 is_disc ? "disc" : "box", qi, gid.n, k, (unsigned long long)g_seed);
    }
    if (qi % 3) continue; /* (a ray every third query: the oracle's exact entries are dear) */
    double ang = qkt_rng_range(r, 0, 6.283185307179586);
    qk_point_t org = {x, y}, dir = {cos(ang), sin(ang)};
    qk_hit_t hit, w = qko_raycast(d, nd, b, nb, org, dir, INFINITY);
    assert_int_equal(qk_collider_raycast(c, org, dir, INFINITY, &hit), QK_OK);
    if (!ray_agrees(hit, w, d, nd, b, org, dir, INFINITY))
      fail_msg("%s: ray %d hit (%u, %.17g), oracle (%u, %.17g) (seed %llu)", what, qi, hit.id,
               hit.t, w.id, w.t, (unsigned long long)g_seed);
  }
  free(wid);
  free(gid.v);
}

/*
 * qk_collider_rebuild: a collider rebuilt over sets that grow, shrink, change kind (discs
 * only, boxes only, both, none) and pass the threaded passes' size, on one and two
 * threads, holds exactly the new items (pairs, queries and rays against the oracle, the
 * rays after structures made for the old items); once its arrays are large enough a
 * rebuild holds no more memory; bad input and a centre outside a given root leave it as
 * it was; allocation failure at every N leaves it valid and empty with nothing more held,
 * and a rebuild after that holds the items again.
 */
static void test_collide_rebuild(void **state) {
  (void)state;
  qkt_rng_t r;
  qkt_rng_seed(&r, g_seed + 11);
  const size_t nmax = 4100;
  qk_disc_t *d = malloc(nmax * sizeof *d);
  qk_box_t *b = malloc(nmax * sizeof *b);
  /* (the fifth: past the build's threaded passes, 4096 items; with two threads only) */
  static const size_t sets[][2] = {{300, 300}, {800, 0}, {0, 900}, {0, 0}, {10, 4090}, {200, 100}};
  for (unsigned threads = 1; threads <= 2; threads++)
    for (int given_root = 0; given_root < 2; given_root++) {
      locked_t l; /* the worker threads allocate too */
      pthread_mutex_init(&l.mu, NULL);
      qkt_alloc_make(&l.st);
      qkt_alloc_t *const st = &l.st;
      const qk_allocator_t a = {locked_fn, &l};
      qk_tree_options_t o = opts(given_root ? 1 : 8);
      o.allocator = &a;
      o.threads = threads;
      o.has_root = given_root;
      o.root = (qk_square_t){-1, -1, 3};
      make_items(&r, d, 300, b, 300, 0, 0.02);
      qk_collider_t *c = NULL;
      assert_int_equal(qk_collider_build(d, 300, b, 300, &o, &c), QK_OK);
      assert_int_equal(qk_collider_prepare_rays(c), QK_OK);
      for (size_t k = 0; k < sizeof sets / sizeof *sets; k++) {
        const size_t nd = sets[k][0], nb = sets[k][1];
        if (nd + nb > 4096 && (threads == 1 || given_root)) continue;
        make_items(&r, d, nd, b, nb, k % 2, k % 3 ? 0.003 : 0.02);
        assert_int_equal(qk_collider_rebuild(c, nd ? d : NULL, nd, nb ? b : NULL, nb), QK_OK);
        char what[64];
        snprintf(what, sizeof what, "rebuild %zu (threads %u root %d)", k, threads, given_root);
        expect_items(c, d, nd, b, nb, &r, what);
        /* Again over the same items: no more memory held. (Other items of the same numbers
         * may make a larger tree, whose node block then grows.) */
        const size_t held = st->live_bytes;
        assert_int_equal(qk_collider_rebuild(c, nd ? d : NULL, nd, nb ? b : NULL, nb), QK_OK);
        if (st->live_bytes > held)
          fail_msg("%s, again: %zu bytes held, %zu before", what, st->live_bytes, held);
        /* And over other items of the same numbers (the other kind's layout, other sizes). */
        make_items(&r, d, nd, b, nb, 1, 0.01);
        assert_int_equal(qk_collider_rebuild(c, nd ? d : NULL, nd, nb ? b : NULL, nb), QK_OK);
        if (nd + nb <= 1000) expect_items(c, d, nd, b, nb, &r, what);
      }
      /* Rejected input: the collider as it was. */
      const size_t nd = 30, nb = 250;
      make_items(&r, d, nd, b, nb, 0, 0.02);
      assert_int_equal(qk_collider_rebuild(c, d, nd, b, nb), QK_OK);
      const qk_box_t keep = b[7];
      b[7].xmin = NAN;
      assert_int_equal(qk_collider_rebuild(c, d, nd, b, nb), QK_ERR_NONFINITE);
      b[7] = (qk_box_t){keep.xmax, keep.ymin, keep.xmin, keep.ymax};
      if (keep.xmin < keep.xmax)
        assert_int_equal(qk_collider_rebuild(c, d, nd, b, nb), QK_ERR_GEOMETRY);
      b[7] = (qk_box_t){5, 5, 6, 6};
      if (given_root) {
        assert_int_equal(qk_collider_rebuild(c, d, nd, b, nb), QK_ERR_OUTSIDE);
      } else { /* a fitted root takes it */
        assert_int_equal(qk_collider_rebuild(c, d, nd, b, nb), QK_OK);
        expect_items(c, d, nd, b, nb, &r, "a box far out");
        b[7] = keep;
        assert_int_equal(qk_collider_rebuild(c, d, nd, b, nb), QK_OK);
      }
      b[7] = keep;
      expect_items(c, d, nd, b, nb, &r, "after rejected rebuilds");
      assert_int_equal(qk_collider_rebuild(NULL, d, nd, b, nb), QK_ERR_INVALID);
      assert_int_equal(qk_collider_rebuild(c, NULL, 3, b, nb), QK_ERR_INVALID);
      /* Allocation failure at every N: valid, empty, nothing more held; then a rebuild
       * without failure holds the items. */
      assert_int_equal(qk_collider_rebuild(c, d, 200, b, 200), QK_OK);
      for (size_t fail_at = 1;; fail_at++) {
        const size_t held = st->live_bytes;
        qkt_alloc_arm(st, fail_at);
        qk_status_t s = qk_collider_rebuild(c, d, nd, b, nb);
        qkt_alloc_arm(st, 0);
        if (s == QK_OK) {
          assert_true(fail_at > 1);
          expect_items(c, d, nd, b, nb, &r, "rebuild after the failures");
          break;
        }
        assert_int_equal(s, QK_ERR_NOMEM);
        if (st->live_bytes > held)
          fail_msg("fail_at %zu: %zu bytes held, %zu before", fail_at, st->live_bytes, held);
        expect_items(c, NULL, 0, NULL, 0, &r, "emptied by a failed rebuild");
        assert_int_equal(qk_collider_rebuild(c, d, 200, b, 200), QK_OK);
        assert_int_equal(qk_collider_size(c), 400);
        assert_true(fail_at < 1000);
      }
      qk_collider_free(c);
      assert_int_equal(st->live_blocks, 0);
      pthread_mutex_destroy(&l.mu);
    }
  free(d), free(b);
}

/* Disc tests exact for any finite values (seventeenth session): discs and boxes that
 * touch exactly (3-4-5 triangles) or miss by one ulp, at scales from 2^-1074 to 2^1017,
 * against the exact oracle. Before, squares overflowed (inf <= inf: discs 1e300 apart
 * overlapped) or underflowed (0 <= 0). */
static void test_collide_exact_extremes(void **state) {
  (void)state;
  QKT_ONE_THREAD_TEST();
  const int scales[] = {-1074, -1070, -1000, -600, -537, -300, 0, 300, 511, 600, 900, 1017};
  for (size_t si = 0; si < sizeof scales / sizeof scales[0]; si++) {
    double s = ldexp(1, scales[si]), cx = 7 * s, cy = -2 * s;
    qk_disc_t d[64];
    qk_box_t b[32];
    size_t nd = 0, nb = 0;
    d[nd++] = (qk_disc_t){cx, cy, 2 * s};
    const double tr[][2] = {{3, 4}, {4, 3}};
    for (int t = 0; t < 2; t++)
      for (int sg = 0; sg < 4; sg++) {
        double ux = sg & 1 ? -1 : 1, uy = sg & 2 ? -1 : 1;
        double x = cx + ux * tr[t][0] * s, y = cy + uy * tr[t][1] * s;
        d[nd++] = (qk_disc_t){x, y, 3 * s};                        /* touches disc 0 */
        d[nd++] = (qk_disc_t){x, y, nextafter(3 * s, 0)};          /* misses it */
        d[nd++] = (qk_disc_t){nextafter(x, x + ux * s), y, 3 * s}; /* misses it */
        d[nd++] = (qk_disc_t){nextafter(x, x - ux * s), y, 3 * s}; /* overlaps it */
        /* a box whose nearest corner is 5 s from the centre: touches a disc of radius 5 s */
        double bx = x + ux * 2 * s, by = y + uy * 2 * s;
        b[nb++] = (qk_box_t){fmin(x, bx), fmin(y, by), fmax(x, bx), fmax(y, by)};
        double nx = nextafter(x, bx);
        b[nb++] = (qk_box_t){fmin(nx, bx), fmin(y, by), fmax(nx, bx), fmax(y, by)};
      }
    d[nd++] = (qk_disc_t){cx, cy, 5 * s};
    d[nd++] = (qk_disc_t){cx, cy, nextafter(5 * s, 0)};
    check_pairs(d, nd, b, nb, 1);
    check_pairs(d, nd, b, nb, 8);
  }
}

static void test_collide_exact_cases(void **state) {
  (void)state;
  QKT_ONE_THREAD_TEST();
  /* Two tangent discs and a box touching the second at one corner point. */
  qk_disc_t d[2] = {{0, 0, 1}, {2, 0, 1}};
  qk_box_t b[1] = {{3, 0, 4, 1}};
  qk_collider_t *c = NULL;
  assert_int_equal(qk_collider_build(d, 2, b, 1, NULL, &c), QK_OK);
  qk_pair_t pairs[4];
  size_t n;
  assert_int_equal(qk_collider_pairs_list(c, pairs, 4, &n), QK_OK);
  assert_int_equal(n, 2);
  assert_int_equal(pairs[0].a, 0);
  assert_int_equal(pairs[0].b, 1);
  assert_int_equal(pairs[1].a, 1);
  assert_int_equal(pairs[1].b, 2);
  qk_hit_t h;
  /* From the left along y = 0: hits disc 0 at x = -1, t = 4 from x = -5. */
  assert_int_equal(qk_collider_raycast(c, (qk_point_t){-5, 0}, (qk_point_t){1, 0}, INFINITY, &h),
                   QK_OK);
  assert_int_equal(h.id, 0);
  assert_true(h.t == 4.0);
  /* Origin inside disc 1: t = 0. */
  assert_int_equal(qk_collider_raycast(c, (qk_point_t){2, 0.5}, (qk_point_t){0, 1}, 1, &h), QK_OK);
  assert_int_equal(h.id, 1);
  assert_true(h.t == 0.0);
  /* A segment that stops short of the box. */
  assert_int_equal(qk_collider_raycast(c, (qk_point_t){3.5, 5}, (qk_point_t){0, -1}, 3.5, &h),
                   QK_OK);
  assert_int_equal(h.id, QK_NONE);
  assert_true(isinf(h.t));
  assert_int_equal(qk_collider_raycast(c, (qk_point_t){3.5, 5}, (qk_point_t){0, -1}, 4, &h), QK_OK);
  assert_int_equal(h.id, 2);
  assert_true(h.t == 4.0);
  /* Grazing the box's top-right corner exactly. */
  assert_int_equal(qk_collider_raycast(c, (qk_point_t){5, 2}, (qk_point_t){-1, -1}, INFINITY, &h),
                   QK_OK);
  assert_int_equal(h.id, 2);
  assert_true(h.t == 1.0);
  assert_int_equal(qk_collider_raycast(c, (qk_point_t){NAN, 2}, (qk_point_t){1, 0}, 1, &h),
                   QK_ERR_NONFINITE);
  assert_int_equal(qk_collider_raycast(c, (qk_point_t){0, 2}, (qk_point_t){1, 0}, -1, &h),
                   QK_ERR_INVALID);
  qk_collider_free(c);

  qk_disc_t bad = {0, 0, -1};
  assert_int_equal(qk_collider_build(&bad, 1, NULL, 0, NULL, &c), QK_ERR_GEOMETRY);
  assert_null(c);
  qk_box_t inv = {1, 0, 0, 1};
  assert_int_equal(qk_collider_build(NULL, 0, &inv, 1, NULL, &c), QK_ERR_GEOMETRY);
  qk_box_t nanb = {NAN, 0, 0, 1};
  assert_int_equal(qk_collider_build(NULL, 0, &nanb, 1, NULL, &c), QK_ERR_NONFINITE);
  qk_collider_free(NULL);
}

static void test_collide_nomem(void **state) {
  (void)state;
  QKT_ONE_THREAD_TEST();
  qkt_rng_t r;
  qkt_rng_seed(&r, g_seed + 3);
  qk_disc_t d[300];
  qk_box_t b[300];
  make_items(&r, d, 300, b, 300, 0, 0.05);
  for (size_t fail_at = 1;; fail_at++) {
    qkt_alloc_t st;
    qk_allocator_t a = qkt_alloc_make(&st);
    st.fail_at = fail_at;
    qk_tree_options_t o = opts(4);
    o.allocator = &a;
    qk_collider_t *c = NULL;
    qk_status_t s = qk_collider_build(d, 300, b, 300, &o, &c);
    if (s == QK_OK) {
      size_t n;
      assert_int_equal(qk_collider_pairs_list(c, NULL, 0, &n), QK_OK);
      qk_collider_free(c);
      assert_int_equal(st.live_blocks, 0);
      assert_true(fail_at > 4); /* the build allocates at least this often */
      break;
    }
    assert_int_equal(s, QK_ERR_NOMEM);
    assert_null(c);
    assert_int_equal(st.live_blocks, 0);
    assert_true(fail_at < 1000);
  }
}

/* Threads: several raycast and pair searches at once on one collider. */
typedef struct thr {
  const qk_collider_t *c;
  const qk_point_t *org, *dir;
  const qk_hit_t *expect;
  size_t nr, pairs;
  int ok;
} thr_t;

static int count_pair(qk_id_t a, qk_id_t b, void *ud) {
  (void)a, (void)b;
  ++*(size_t *)ud;
  return 0;
}

static void *thread_main(void *arg) {
  thr_t *a = arg;
  a->ok = 1;
  for (int rep = 0; rep < 3; rep++) {
    for (size_t i = 0; i < a->nr; i++) {
      qk_hit_t h;
      if (qk_collider_raycast(a->c, a->org[i], a->dir[i], INFINITY, &h) != QK_OK ||
          h.id != a->expect[i].id || !(h.t == a->expect[i].t))
        a->ok = 0;
    }
    size_t np = 0;
    qk_collider_pairs(a->c, count_pair, &np);
    if (np != a->pairs) a->ok = 0;
  }
  return NULL;
}

static void test_collide_threads(void **state) {
  (void)state;
  qkt_rng_t r;
  qkt_rng_seed(&r, g_seed + 4);
  const size_t nd = 2000, nb = 2000, nr = 2000;
  qk_disc_t *d = malloc(nd * sizeof *d);
  qk_box_t *b = malloc(nb * sizeof *b);
  qk_point_t *org = malloc(nr * sizeof *org), *dir = malloc(nr * sizeof *dir);
  qk_hit_t *expect = malloc(nr * sizeof *expect);
  make_items(&r, d, nd, b, nb, 0, 0.005);
  qk_collider_t *c = NULL;
  assert_int_equal(qk_collider_build(d, nd, b, nb, NULL, &c), QK_OK);
  for (size_t i = 0; i < nr; i++) {
    org[i] = (qk_point_t){qkt_rng_unit(&r), qkt_rng_unit(&r)};
    double ang = qkt_rng_range(&r, 0, 6.283185307179586);
    dir[i] = (qk_point_t){cos(ang), sin(ang)};
    /* the threads must repeat the single-threaded answer, which the oracle checks */
    qk_hit_t w = qko_raycast(d, nd, b, nb, org[i], dir[i], INFINITY);
    assert_int_equal(qk_collider_raycast(c, org[i], dir[i], INFINITY, &expect[i]), QK_OK);
    assert_true(ray_agrees(expect[i], w, d, nd, b, org[i], dir[i], INFINITY));
  }
  qk_pair_t *pairs;
  size_t np = qko_pairs(d, nd, b, nb, &pairs);
  free(pairs);
  pthread_t th[3];
  thr_t args[3];
  for (int i = 0; i < 3; i++) {
    args[i] = (thr_t){c, org, dir, expect, nr, np, 0};
    assert_int_equal(pthread_create(&th[i], NULL, thread_main, &args[i]), 0);
  }
  for (int i = 0; i < 3; i++) pthread_join(th[i], NULL);
  for (int i = 0; i < 3; i++)
    if (!args[i].ok)
      fail_msg("thread %d got a wrong answer (seed %llu)", i, (unsigned long long)g_seed);
  qk_collider_free(c);
  free(d), free(b), free(org), free(dir), free(expect);
}

/* Every pair in callback order, up to `stop` of them (0: all). */
typedef struct seq {
  qk_pair_t *p;
  size_t n, cap, stop;
} seq_t;

static int seq_pair(qk_id_t a, qk_id_t b, void *ud) {
  seq_t *s = ud;
  if (s->n == s->cap) {
    s->cap = s->cap ? 2 * s->cap : 1024;
    s->p = realloc(s->p, s->cap * sizeof *s->p);
    assert_non_null(s->p);
  }
  s->p[s->n].a = a;
  s->p[s->n++].b = b;
  return s->stop && s->n == s->stop;
}

static seq_t pairs_seq(const qk_collider_t *c, size_t stop) {
  seq_t s = {NULL, 0, 0, stop};
  assert_int_equal(qk_collider_pairs(c, seq_pair, &s), QK_OK);
  return s;
}

static void assert_same_seq(const seq_t *x, const seq_t *y, uint32_t threads) {
  if (x->n != y->n || (x->n && memcmp(x->p, y->p, x->n * sizeof *x->p)))
    fail_msg("threads %u: %zu pairs vs %zu on one thread, or another order (seed %llu)", threads,
             y->n, x->n, (unsigned long long)g_seed);
}

/* Ray batches of counts around the per-job records' room on the stack (16 jobs of 256
 * rays; more borrow them from the allocator) and around a job's 256 rays, on one and two
 * threads: every hit equals the single cast's, and each batch gives back every block and
 * byte it took (a batch of 17 jobs, the first that borrows, must free them too). */
static void test_collide_rays_batch_counts(void **state) {
  (void)state;
  qkt_rng_t r;
  qkt_rng_seed(&r, g_seed + 17);
  enum { ND = 400, NB = 400, NMAX = 20 * 256 };
  static const size_t counts[] = {
      1, 255, 256, 257, 16 * 256, 16 * 256 + 1, 17 * 256 - 1, 17 * 256, 17 * 256 + 1, NMAX};
  qk_disc_t *d = malloc(ND * sizeof *d);
  qk_box_t *b = malloc(NB * sizeof *b);
  qk_point_t *org = malloc(NMAX * sizeof *org), *dir = malloc(NMAX * sizeof *dir);
  qk_hit_t *one = malloc(NMAX * sizeof *one), *many = malloc(NMAX * sizeof *many);
  make_items(&r, d, ND, b, NB, 0, 0.02);
  for (size_t i = 0; i < NMAX; i++) {
    org[i] = (qk_point_t){qkt_rng_range(&r, -0.2, 1.2), qkt_rng_range(&r, -0.2, 1.2)};
    double ang = qkt_rng_range(&r, 0, 6.283185307179586);
    dir[i] = (qk_point_t){cos(ang), sin(ang)};
  }
  qkt_alloc_t st;
  qk_allocator_t a = qkt_alloc_make(&st);
  qk_tree_options_t o = opts(4);
  o.allocator = &a;
  qk_collider_t *c = NULL;
  assert_int_equal(qk_collider_build(d, ND, b, NB, &o, &c), QK_OK);
  for (size_t i = 0; i < NMAX; i++)
    assert_int_equal(qk_collider_raycast(c, org[i], dir[i], 0.5, &one[i]), QK_OK);
  const size_t blocks = st.live_blocks, bytes = st.live_bytes; /* (the ray structures made) */
  for (uint32_t threads = 1; threads <= 2; threads++) {
    qk_collider_set_threads(c, threads);
    for (size_t k = 0; k < sizeof counts / sizeof *counts; k++) {
      size_t n = counts[k];
      assert_int_equal(qk_collider_raycast_batch(c, org, dir, n, 0.5, many), QK_OK);
      if (st.live_blocks != blocks || st.live_bytes != bytes)
        fail_msg("threads %u, %zu rays: %zu blocks (%zu bytes) held after the batch, %zu (%zu) "
                 "before",
                 threads, n, st.live_blocks, st.live_bytes, blocks, bytes);
      for (size_t i = 0; i < n; i++)
        if (many[i].id != one[i].id || !(many[i].t == one[i].t))
          fail_msg("threads %u, %zu rays: ray %zu %u at %g, one call %u at %g (seed %llu)", threads,
                   n, i, (unsigned)many[i].id, many[i].t, (unsigned)one[i].id, one[i].t,
                   (unsigned long long)g_seed);
    }
  }
  qk_collider_free(c);
  assert_int_equal(st.live_blocks, 0);
  free(d), free(b), free(org), free(dir), free(one), free(many);
}

static void test_collide_threads_option(void **state) {
  (void)state;
  qkt_rng_t r;
  qkt_rng_seed(&r, g_seed + 5);
  const size_t nd = 1500, nb = 1500, nr = 5000; /* more than 4096 rays: the borrowed path */
  qk_disc_t *d = malloc(nd * sizeof *d);
  qk_box_t *b = malloc(nb * sizeof *b);
  qk_point_t *org = malloc(nr * sizeof *org), *dir = malloc(nr * sizeof *dir);
  qk_hit_t *one = malloc(nr * sizeof *one), *many = malloc(nr * sizeof *many);
  make_items(&r, d, nd, b, nb, 0, 0.01);
  for (size_t i = 0; i < nr; i++) {
    org[i] = (qk_point_t){qkt_rng_range(&r, -0.2, 1.2), qkt_rng_range(&r, -0.2, 1.2)};
    double ang = qkt_rng_range(&r, 0, 6.283185307179586);
    dir[i] = i % 97 == 0 ? (qk_point_t){0, 1} : (qk_point_t){cos(ang), sin(ang)};
  }
  qk_tree_options_t o = opts(4);
  qk_collider_t *c = NULL;
  assert_int_equal(qk_collider_build(d, nd, b, nb, &o, &c), QK_OK);
  seq_t ref = pairs_seq(c, 0), ref_stop = pairs_seq(c, 777);
  assert_true(ref.n > 777);
  size_t nl;
  assert_int_equal(qk_collider_pairs_list(c, NULL, 0, &nl), QK_OK);
  qk_pair_t *list1 = malloc(nl * sizeof *list1), *list2 = malloc(nl * sizeof *list2);
  assert_int_equal(qk_collider_pairs_list(c, list1, nl, &nl), QK_OK);
  for (size_t i = 0; i < nr; i++)
    assert_int_equal(qk_collider_raycast(c, org[i], dir[i], 2.0, &one[i]), QK_OK);
  const uint32_t ts[] = {1, 2, 3, 0};
  for (size_t k = 0; k < sizeof ts / sizeof *ts; k++) {
    qk_collider_set_threads(c, ts[k]);
    seq_t got = pairs_seq(c, 0), got_stop = pairs_seq(c, 777);
    assert_same_seq(&ref, &got, ts[k]);
    assert_same_seq(&ref_stop, &got_stop, ts[k]);
    free(got.p), free(got_stop.p);
    size_t n2;
    assert_int_equal(qk_collider_pairs_list(c, list2, nl, &n2), QK_OK);
    assert_int_equal(n2, nl);
    assert_memory_equal(list1, list2, nl * sizeof *list1);
    assert_int_equal(qk_collider_raycast_batch(c, org, dir, nr, 2.0, many), QK_OK);
    for (size_t i = 0; i < nr; i++)
      if (many[i].id != one[i].id || !(many[i].t == one[i].t))
        fail_msg("threads %u ray %zu: %u at %g, one call %u at %g (seed %llu)", ts[k], i,
                 (unsigned)many[i].id, many[i].t, (unsigned)one[i].id, one[i].t,
                 (unsigned long long)g_seed);
    /* Failing rays: the lowest-numbered one's error, the others still answered. */
    qk_point_t keep0 = org[4500], keep1 = dir[300];
    org[4500].x = NAN;
    dir[300].y = INFINITY;
    assert_int_equal(qk_collider_raycast_batch(c, org, dir, nr, 2.0, many), QK_ERR_NONFINITE);
    assert_int_equal(many[300].id, QK_NONE);
    assert_int_equal(many[4500].id, QK_NONE);
    assert_int_equal(many[301].id, one[301].id);
    org[4500] = keep0, dir[300] = keep1;
    assert_int_equal(qk_collider_raycast_batch(c, org, dir, 3, -1.0, many), QK_ERR_INVALID);
    assert_int_equal(qk_collider_raycast_batch(c, NULL, dir, 3, 1.0, many), QK_ERR_INVALID);
    assert_int_equal(qk_collider_raycast_batch(c, NULL, NULL, 0, 1.0, NULL), QK_OK);
  }
  qk_collider_set_threads(NULL, 2);
  qk_collider_free(c);
  free(ref.p), free(ref_stop.p), free(list1), free(list2);
  free(d), free(b), free(org), free(dir), free(one), free(many);
}

static void test_collide_threads_nomem(void **state) {
  (void)state;
  qkt_rng_t r;
  qkt_rng_seed(&r, g_seed + 6);
  enum { ND = 400, NB = 400, NR = 4500 };
  qk_disc_t d[ND];
  qk_box_t b[NB];
  make_items(&r, d, ND, b, NB, 0, 0.03);
  static qk_point_t org[NR], dir[NR];
  static qk_hit_t one[NR], many[NR];
  for (size_t i = 0; i < NR; i++) {
    org[i] = (qk_point_t){qkt_rng_unit(&r), qkt_rng_unit(&r)};
    dir[i] = (qk_point_t){qkt_rng_range(&r, -1, 1), qkt_rng_range(&r, -1, 1)};
  }
  locked_t l;
  pthread_mutex_init(&l.mu, NULL);
  qk_allocator_t a = qkt_alloc_make(&l.st);
  a.fn = locked_fn;
  a.ud = &l;
  qk_tree_options_t o = opts(4);
  o.allocator = &a;
  qk_collider_t *c = NULL;
  assert_int_equal(qk_collider_build(d, ND, b, NB, &o, &c), QK_OK);
  seq_t ref = pairs_seq(c, 0);
  for (size_t i = 0; i < NR; i++)
    assert_int_equal(qk_collider_raycast(c, org[i], dir[i], INFINITY, &one[i]), QK_OK);
  qk_collider_set_threads(c, 2);
  size_t live = l.st.live_blocks;
  /* Pairs: the same sequence whichever allocation fails (the one-thread fallback). */
  for (size_t fail_at = 1;; fail_at++) {
    qkt_alloc_arm(&l.st, fail_at);
    seq_t got = pairs_seq(c, 0);
    assert_same_seq(&ref, &got, 2);
    free(got.p);
    assert_int_equal(l.st.live_blocks, live);
    if (!l.st.failed) break;
    assert_true(fail_at < 1000);
  }
  for (size_t fail_at = 1;; fail_at++) {
    qkt_alloc_arm(&l.st, fail_at);
    qk_status_t s = qk_collider_raycast_batch(c, org, dir, NR, INFINITY, many);
    assert_int_equal(l.st.live_blocks, live);
    if (s == QK_OK) {
      for (size_t i = 0; i < NR; i++) assert_true(many[i].id == one[i].id && many[i].t == one[i].t);
      break;
    }
    assert_int_equal(s, QK_ERR_NOMEM);
    assert_true(fail_at < 10);
  }
  qkt_alloc_arm(&l.st, 0);
  qk_collider_free(c);
  assert_int_equal(l.st.live_blocks, 0);
  free(ref.p);
  pthread_mutex_destroy(&l.mu);
}

/* An allocator that refuses every allocation made off the main thread: every job a
 * worker thread takes then fails to keep its pairs. */
typedef struct offmain {
  pthread_mutex_t mu;
  pthread_t main;
  size_t live, refused;
} offmain_t;

static void *offmain_fn(void *ud, void *ptr, size_t osize, size_t nsize) {
  (void)osize;
  offmain_t *m = ud;
  pthread_mutex_lock(&m->mu);
  void *p = NULL;
  if (nsize == 0) {
    if (ptr) m->live--;
    free(ptr);
  } else if (!pthread_equal(pthread_self(), m->main)) {
    m->refused++; /* ptr stays the caller's */
  } else {
    p = realloc(ptr, nsize);
    if (p && !ptr) m->live++;
  }
  pthread_mutex_unlock(&m->mu);
  return p;
}

/* Pairs on threads whose every buffer allocation fails: whatever the threaded pass does
 * about it, the pairs are still those of one thread, in order (also when stopped early),
 * and nothing leaks. */
static void test_collide_threads_worker_nomem(void **state) {
  (void)state;
  qkt_rng_t r;
  qkt_rng_seed(&r, g_seed + 8);
  enum { ND = 3000, NB = 3000 };
  qk_disc_t *d = malloc(ND * sizeof *d);
  qk_box_t *b = malloc(NB * sizeof *b);
  make_items(&r, d, ND, b, NB, 0, 0.01);
  offmain_t m;
  pthread_mutex_init(&m.mu, NULL);
  m.main = pthread_self();
  m.live = m.refused = 0;
  qk_allocator_t a = {offmain_fn, &m};
  qk_tree_options_t o = opts(4);
  o.allocator = &a;
  qk_collider_t *c = NULL;
  assert_int_equal(qk_collider_build(d, ND, b, NB, &o, &c), QK_OK);
  seq_t ref = pairs_seq(c, 0), ref_stop = pairs_seq(c, 501);
  assert_true(ref.n > 501);
  const size_t live = m.live;
  const uint32_t ts[] = {2, 3};
  for (int rep = 0; rep < 10; rep++)
    for (size_t k = 0; k < sizeof ts / sizeof *ts; k++) {
      qk_collider_set_threads(c, ts[k]);
      seq_t got = pairs_seq(c, 0), got_stop = pairs_seq(c, 501);
      assert_same_seq(&ref, &got, ts[k]);
      assert_same_seq(&ref_stop, &got_stop, ts[k]);
      free(got.p), free(got_stop.p);
      assert_int_equal(m.live, live);
    }
  qk_collider_free(c);
  assert_int_equal(m.live, 0);
  free(ref.p), free(ref_stop.p), free(d), free(b);
  pthread_mutex_destroy(&m.mu);
}

/* Pairs compared by (a, b), for sorting a callback sequence against the oracle's list. */
static int pair_cmp(const void *x, const void *y) {
  const qk_pair_t *p = x, *q = y;
  if (p->a != q->a) return p->a < q->a ? -1 : 1;
  return p->b < q->b ? -1 : p->b > q->b;
}

/* The callback of a threaded search: the pairs in order, and whether any came on another
 * thread than the caller's (the API promises the calling thread). */
typedef struct onthread {
  seq_t s;
  pthread_t caller;
  int elsewhere;
} onthread_t;

static int onthread_pair(qk_id_t a, qk_id_t b, void *ud) {
  onthread_t *o = ud;
  if (!pthread_equal(pthread_self(), o->caller)) o->elsewhere = 1;
  return seq_pair(a, b, &o->s);
}

/*
 * A skewed scene on 2 and 3 threads: most boxes in one small square, packed so that a few
 * leaves hold most of the pairs (jobs of very unequal work, taken from a shared counter
 * and reported in job order while others still search), the rest scattered, a few large.
 * The pairs, in callback order and stopped early at many places (job boundaries among
 * them), are those of one thread; as a set they are the brute-force oracle's; every call
 * of the callback is on the calling thread.
 */
static void test_collide_threads_skewed(void **state) {
  (void)state;
  qkt_rng_t r;
  qkt_rng_seed(&r, g_seed + 9);
  enum { NB = 6000 };
  qk_box_t *b = malloc(NB * sizeof *b);
  for (size_t i = 0; i < NB; i++) {
    const int dense = i % 8 != 0;
    double cx = qkt_rng_unit(&r), cy = qkt_rng_unit(&r);
    if (dense) cx = 0.7 + 0.03 * cx, cy = 0.2 + 0.03 * cy;
    double w = dense ? qkt_rng_range(&r, 0, 0.002) : qkt_rng_range(&r, 0, 0.004);
    double h = dense ? qkt_rng_range(&r, 0, 0.002) : qkt_rng_range(&r, 0, 0.004);
    if (i % 997 == 1) w = 0.1; /* a few long ones */
    b[i] = (qk_box_t){cx - w, cy - h, cx + w, cy + h};
  }
  qk_tree_options_t o = opts(2);
  qk_collider_t *c = NULL;
  assert_int_equal(qk_collider_build(NULL, 0, b, NB, &o, &c), QK_OK);
  qk_pair_t *want;
  const size_t nw = qko_pairs(NULL, 0, b, NB, &want);
  seq_t ref = pairs_seq(c, 0);
  assert_int_equal(ref.n, nw);
  assert_true(nw > 20000);
  qk_pair_t *sorted = malloc(nw * sizeof *sorted);
  const uint32_t ts[] = {2, 3};
  for (size_t k = 0; k < sizeof ts / sizeof *ts; k++) {
    qk_collider_set_threads(c, ts[k]);
    onthread_t got = {{NULL, 0, 0, 0}, pthread_self(), 0};
    assert_int_equal(qk_collider_pairs(c, onthread_pair, &got), QK_OK);
    assert_false(got.elsewhere);
    assert_same_seq(&ref, &got.s, ts[k]);
    memcpy(sorted, got.s.p, nw * sizeof *sorted);
    qsort(sorted, nw, sizeof *sorted, pair_cmp);
    if (memcmp(sorted, want, nw * sizeof *want))
      fail_msg("threads %u: the pairs differ from the oracle's (seed %llu)", ts[k],
               (unsigned long long)g_seed);
    free(got.s.p);
    /* Stopped early: 1, 2, then spread over the whole sequence, and the last pair. */
    for (size_t stop = 1; stop <= nw; stop = stop < 3 ? stop + 1 : stop + nw / 41 + 1) {
      seq_t one = {ref.p, stop, stop, stop};
      onthread_t part = {{NULL, 0, 0, stop}, pthread_self(), 0};
      assert_int_equal(qk_collider_pairs(c, onthread_pair, &part), QK_OK);
      assert_false(part.elsewhere);
      assert_same_seq(&one, &part.s, ts[k]);
      free(part.s.p);
    }
    onthread_t last = {{NULL, 0, 0, nw}, pthread_self(), 0};
    assert_int_equal(qk_collider_pairs(c, onthread_pair, &last), QK_OK);
    assert_same_seq(&ref, &last.s, ts[k]);
    free(last.s.p);
  }
  qk_collider_free(c);
  free(ref.p), free(want), free(sorted), free(b);
}

/* The build on several threads (the slot fill, the node boxes and the ray cast's nodes by
 * subtrees: from 4096 items on) gives the collider one thread gives: the same pairs in
 * the same order, the same hits to the last bit, which agree with the oracle; and every
 * failed allocation of such a build leaves nothing behind. */
static void test_collide_threaded_build(void **state) {
  (void)state;
  qkt_rng_t r;
  qkt_rng_seed(&r, g_seed + 7);
  enum { ND = 3000, NB = 2500, NR = 1000 };
  qk_disc_t *d = malloc(ND * sizeof *d);
  qk_box_t *b = malloc(NB * sizeof *b);
  qk_point_t *org = malloc(NR * sizeof *org), *dir = malloc(NR * sizeof *dir);
  qk_hit_t *one = malloc(NR * sizeof *one);
  assert_non_null(d && b && org && dir && one);
  for (int set = 0; set < 2; set++) {
    make_items(&r, d, ND, b, NB, set, set ? 0.001 : 0.005);
    for (size_t i = 0; i < NR; i++) {
      org[i] = (qk_point_t){qkt_rng_range(&r, -0.1, 1.1), qkt_rng_range(&r, -0.1, 1.1)};
      double ang = qkt_rng_range(&r, 0, 6.283185307179586);
      dir[i] = (qk_point_t){cos(ang), sin(ang)};
    }
    seq_t ref = {NULL, 0, 0, 0};
    const uint32_t ts[] = {1, 2, 3};
    for (size_t k = 0; k < sizeof ts / sizeof *ts; k++) {
      qk_tree_options_t o = opts(set ? 2 : 8);
      o.threads = ts[k];
      qk_collider_t *c = NULL;
      assert_int_equal(qk_collider_build(d, ND, b, NB, &o, &c), QK_OK);
      qk_collider_set_threads(c, 1);
      seq_t got = pairs_seq(c, 0);
      for (size_t i = 0; i < NR; i++) {
        qk_hit_t h;
        assert_int_equal(qk_collider_raycast(c, org[i], dir[i], INFINITY, &h), QK_OK);
        if (k == 0) {
          one[i] = h;
          if (i % 10 == 0) {
            qk_hit_t w = qko_raycast(d, ND, b, NB, org[i], dir[i], INFINITY);
            if (!ray_agrees(h, w, d, ND, b, org[i], dir[i], INFINITY))
              fail_msg("set %d ray %zu: hit (%u, %.17g) vs oracle (%u, %.17g) (seed %llu)", set, i,
                       h.id, h.t, w.id, w.t, (unsigned long long)g_seed);
          }
        } else if (h.id != one[i].id || !(h.t == one[i].t || (isinf(h.t) && isinf(one[i].t)))) {
          fail_msg("set %d, built on %u threads, ray %zu: (%u, %.17g) vs one thread (%u, %.17g) "
                   "(seed %llu)",
                   set, ts[k], i, h.id, h.t, one[i].id, one[i].t, (unsigned long long)g_seed);
        }
      }
      if (k == 0)
        ref = got;
      else {
        assert_same_seq(&ref, &got, ts[k]);
        free(got.p);
      }
      qk_collider_free(c);
    }
    assert_true(ref.n > 0);
    free(ref.p);
  }
  /* Bad items checked on the threads: the first bad item's status (discs come first). */
  {
    qk_tree_options_t o = opts(8);
    o.threads = 2;
    qk_collider_t *c = NULL;
    const qk_box_t keep_b = b[NB - 10];
    const qk_disc_t keep_d = d[ND / 2];
    b[NB - 10] = (qk_box_t){1, 0, 0, 1}; /* inverted, in the last range */
    assert_int_equal(qk_collider_build(d, ND, b, NB, &o, &c), QK_ERR_GEOMETRY);
    assert_null(c);
    d[ND / 2].y = NAN; /* earlier in item order */
    assert_int_equal(qk_collider_build(d, ND, b, NB, &o, &c), QK_ERR_NONFINITE);
    d[ND / 2] = keep_d;
    d[ND - 1].r = -1;
    assert_int_equal(qk_collider_build(d, ND, b, NB, &o, &c), QK_ERR_GEOMETRY);
    d[ND - 1].r = 0;
    b[NB - 10].xmax = INFINITY;
    assert_int_equal(qk_collider_build(d, ND, b, NB, &o, &c), QK_ERR_NONFINITE);
    b[NB - 10] = keep_b;
  }
  /* Allocation failures of the threaded build: NOMEM and nothing held, until it succeeds. */
  locked_t l;
  pthread_mutex_init(&l.mu, NULL);
  qk_allocator_t a = qkt_alloc_make(&l.st);
  a.fn = locked_fn;
  a.ud = &l;
  for (size_t fail_at = 1;; fail_at++) {
    qkt_alloc_arm(&l.st, fail_at);
    qk_tree_options_t o = opts(8);
    o.threads = 2;
    o.allocator = &a;
    qk_collider_t *c = NULL;
    qk_status_t s = qk_collider_build(d, ND, b, NB, &o, &c);
    if (s == QK_OK) {
      qkt_alloc_arm(&l.st, 0);
      qk_hit_t h;
      assert_int_equal(qk_collider_raycast(c, org[0], dir[0], INFINITY, &h), QK_OK);
      qk_collider_free(c);
      assert_int_equal(l.st.live_blocks, 0);
      break;
    }
    assert_int_equal(s, QK_ERR_NOMEM);
    assert_null(c);
    assert_int_equal(l.st.live_blocks, 0);
    assert_true(fail_at < 1000);
  }
  pthread_mutex_destroy(&l.mu);
  free(d), free(b), free(org), free(dir), free(one);
}

#if defined(__linux__) && defined(MADV_HUGEPAGE)
/* Mappings of this process flagged for huge pages (VmFlags "hg"), or -1 when
 * /proc/self/smaps cannot be read. */
static long count_hg_regions(void) {
  FILE *f = fopen("/proc/self/smaps", "r");
  if (!f) return -1;
  char line[512];
  long n = 0;
  while (fgets(line, sizeof line, f))
    if (strncmp(line, "VmFlags:", 8) == 0 && strstr(line, " hg")) n++;
  fclose(f);
  return n;
}

static void *plain_alloc(void *ud, void *ptr, size_t osize, size_t nsize) {
  (void)ud, (void)osize;
  if (nsize == 0) {
    free(ptr);
    return NULL;
  }
  return realloc(ptr, nsize);
}
#endif

/* The collider advises its large arrays for huge pages whatever the options' hint: the
 * item boxes of a set of boxes before any ray is cast, the ray arrays (disc records, ray
 * entries) of a set of discs; a custom allocator is never advised. Same answers either
 * way. */
static void test_collide_arrays_huge(void **state) {
  (void)state;
  QKT_ONE_THREAD_TEST();
#if defined(__linux__) && defined(MADV_HUGEPAGE)
  /* Skip where the kernel has no transparent huge pages (madvise fails) or no smaps. */
  const size_t probe_bytes = (size_t)8 << 20;
  void *probe = mmap(NULL, probe_bytes, PROT_READ | PROT_WRITE, MAP_PRIVATE | MAP_ANONYMOUS, -1, 0);
  assert_true(probe != MAP_FAILED);
  const int thp = madvise(probe, probe_bytes, MADV_HUGEPAGE) == 0;
  munmap(probe, probe_bytes);
  /* Every block of 1 MB and more a mapping of its own (glibc), so that an advised array
   * makes a region of its own, never hidden in a part of the heap that an earlier test
   * advised. (The sanitizers' allocators ignore the setting and map large blocks apart
   * anyway.) */
#if defined(__GLIBC__)
  (void)mallopt(M_MMAP_THRESHOLD, 1 << 20);
#endif
  const long before = count_hg_regions();
  if (!thp || before < 0) {
    print_message("skipped: no transparent huge pages or no /proc/self/smaps\n");
    return;
  }
  qkt_rng_t r;
  qkt_rng_seed(&r, g_seed ^ 0x4855u);
  const size_t n = 200000; /* 6.4 MB of disc records: above qk__advise_huge's 4 MB */
  qk_disc_t *d = malloc(n * sizeof *d);
  assert_non_null(d);
  for (size_t i = 0; i < n; i++)
    d[i] = (qk_disc_t){qkt_rng_unit(&r), qkt_rng_unit(&r), qkt_rng_range(&r, 0, 1e-3)};
  qk_tree_options_t o;
  qk_tree_options_init(&o);
  o.capacity = 8;
  assert_int_equal(o.huge_pages, 0);
  qk_collider_t *c = NULL, *p = NULL;
  qk_allocator_t plain = {plain_alloc, NULL};
  qk_tree_options_t op = o;
  op.allocator = &plain;
  assert_int_equal(qk_collider_build(d, n, NULL, 0, &op, &p), QK_OK);
  assert_int_equal(count_hg_regions(), before); /* a custom allocator: not advised */
  /* The same centres as boxes: 6.4 MB of item boxes, and no ray structures yet. */
  qk_box_t *b = malloc(n * sizeof *b);
  assert_non_null(b);
  for (size_t i = 0; i < n; i++)
    b[i] = (qk_box_t){d[i].x - d[i].r, d[i].y - d[i].r, d[i].x + d[i].r, d[i].y + d[i].r};
  qk_collider_t *cb = NULL, *pb = NULL;
  assert_int_equal(qk_collider_build(NULL, 0, b, n, &op, &pb), QK_OK);
  assert_int_equal(count_hg_regions(), before);
  assert_int_equal(qk_collider_build(NULL, 0, b, n, &o, &cb), QK_OK);
  if (count_hg_regions() <= before)
    fail_msg("no region advised for huge pages after a build of boxes (seed %llu)",
             (unsigned long long)g_seed);
  size_t np_c = 0, np_p = 0;
  assert_int_equal(qk_collider_pairs_list(cb, NULL, 0, &np_c), QK_OK);
  assert_int_equal(qk_collider_pairs_list(pb, NULL, 0, &np_p), QK_OK);
  assert_int_equal(np_c, np_p);
  assert_true(np_c > 0);
  qk_pair_t *pairs_c = malloc(np_c * sizeof *pairs_c), *pairs_p = malloc(np_p * sizeof *pairs_p);
  assert_true(pairs_c && pairs_p);
  assert_int_equal(qk_collider_pairs_list(cb, pairs_c, np_c, &np_c), QK_OK);
  assert_int_equal(qk_collider_pairs_list(pb, pairs_p, np_p, &np_p), QK_OK);
  assert_memory_equal(pairs_c, pairs_p, np_c * sizeof *pairs_c);
  free(pairs_c), free(pairs_p);
  /* The discs' collider while the boxes' still lives, so that its arrays cannot take the
   * boxes' advised memory (which freed blocks, held by valgrind or a sanitizer, could). */
  const long with_boxes = count_hg_regions();
  assert_int_equal(qk_collider_build(d, n, NULL, 0, &o, &c), QK_OK);
  if (count_hg_regions() <= with_boxes)
    fail_msg("no region advised for huge pages after the build (seed %llu)",
             (unsigned long long)g_seed);
  qk_collider_free(cb);
  qk_collider_free(pb);
  free(b);
  for (int i = 0; i < 2000; i++) {
    const double a = 6.283185307179586 * qkt_rng_unit(&r);
    const qk_point_t org = {qkt_rng_unit(&r), qkt_rng_unit(&r)}, dir = {cos(a), sin(a)};
    qk_hit_t h1, h2;
    assert_int_equal(qk_collider_raycast(c, org, dir, INFINITY, &h1), QK_OK);
    assert_int_equal(qk_collider_raycast(p, org, dir, INFINITY, &h2), QK_OK);
    assert_int_equal(h1.id, h2.id);
    assert_true(h1.t == h2.t || (isinf(h1.t) && isinf(h2.t)));
  }
  qk_collider_free(c);
  qk_collider_free(p);
  free(d);
#endif
}

/*
 * Leaves of every count from 1 to the capacity, odd ones included (the leaf scan tests
 * discs in pairs, an odd count's last pair overlapping the one before), and searches
 * that climb above their start (which pass over the child searched already): random
 * discs in small clusters of 1 to 9, some given twice or three times under other ids (ties
 * decided by the smallest id, also within an overlapping pair), at capacities 1 to 8;
 * rays from inside the clusters, from between them and from outside the set, short
 * (tmax) and unbounded. Against brute force over every disc with the library's own disc
 * test: the same id and the same t to the last bit.
 */
static void test_collide_raycast_leaf_counts(void **state) {
  (void)state;
  QKT_ONE_THREAD_TEST();
  qkt_rng_t r;
  qkt_rng_seed(&r, g_seed + 41);
  const size_t cap_n = 3000;
  qk_disc_t *d = malloc(cap_n * sizeof *d);
  assert_non_null(d);
  for (uint32_t cap = 1; cap <= 8; cap++) {
    size_t n = 0;
    while (n + 30 < cap_n) {
      const double cx = qkt_rng_range(&r, 0, 1), cy = qkt_rng_range(&r, 0, 1);
      const uint32_t k = 1 + qkt_rng_below(&r, 9);
      for (uint32_t j = 0; j < k; j++) {
        const double vx = cx + qkt_rng_range(&r, -0.004, 0.004);
        const double vy = cy + qkt_rng_range(&r, -0.004, 0.004);
        const qk_disc_t v = {vx, vy, qkt_rng_range(&r, 0, 0.003)};
        uint32_t copies = qkt_rng_below(&r, 4) == 0 ? 1 + qkt_rng_below(&r, 2) : 0;
        d[n++] = v;
        for (uint32_t m = 0; m < copies; m++) d[n++] = v;
      }
    }
    /* Shuffle, so that copies get ids far apart and in either order. */
    for (size_t i = n - 1; i > 0; i--) {
      size_t j = qkt_rng_below(&r, (uint32_t)(i + 1));
      qk_disc_t t = d[i];
      d[i] = d[j], d[j] = t;
    }
    qk_tree_options_t o = opts(cap);
    qk_collider_t *c = NULL;
    assert_int_equal(qk_collider_build(d, n, NULL, 0, &o, &c), QK_OK);
    for (int qi = 0; qi < 3000; qi++) {
      qk_point_t org;
      if (qi % 3 == 0) {
        const qk_disc_t *e = &d[qkt_rng_below(&r, (uint32_t)n)];
        org.x = e->x + qkt_rng_range(&r, -0.01, 0.01);
        org.y = e->y + qkt_rng_range(&r, -0.01, 0.01);
      } else {
        org.x = qkt_rng_range(&r, -0.2, 1.2);
        org.y = qkt_rng_range(&r, -0.2, 1.2);
      }
      const double ang = qkt_rng_range(&r, 0, 6.283185307179586);
      const qk_point_t dir = {cos(ang), sin(ang)};
      const double tmax = qi % 4 == 0 ? qkt_rng_range(&r, 0, 0.05) : INFINITY;
      qk_hit_t w = {QK_NONE, INFINITY};
      for (size_t i = 0; i < n; i++) {
        const double t = qko_ray_disc_bits(d[i], org, dir, tmax);
        if (t >= 0 && (t < w.t || (t == w.t && i < w.id))) w = (qk_hit_t){(qk_id_t)i, t};
      }
      qk_hit_t h;
      assert_int_equal(qk_collider_raycast(c, org, dir, tmax, &h), QK_OK);
      if (h.id != w.id || memcmp(&h.t, &w.t, sizeof h.t) != 0)
        fail_msg("cap %u ray %d: hit (%u, %a) vs brute force (%u, %a) (seed %llu)", cap, qi, h.id,
                 h.t, w.id, w.t, (unsigned long long)g_seed);
    }
    qk_collider_free(c);
  }
  free(d);
}

/* The place of an item in the callback order: its leaf's rank among the leaves in
 * pre-order and its place among that leaf's points. */
typedef struct place {
  size_t leaf, pos;
} place_t;

static const place_t *g_place;

/* Pairs (a < b) in the order qk_collider_pairs promises: by the leaf of a, then the leaf
 * of b (both in pre-order), then the places of a and b within them. */
static int place_cmp(const void *x, const void *y) {
  const qk_pair_t *p = x, *q = y;
  const place_t pa = g_place[p->a], pb = g_place[p->b], qa = g_place[q->a], qb = g_place[q->b];
  if (pa.leaf != qa.leaf) return pa.leaf < qa.leaf ? -1 : 1;
  if (pb.leaf != qb.leaf) return pb.leaf < qb.leaf ? -1 : 1;
  if (pa.pos != qa.pos) return pa.pos < qa.pos ? -1 : 1;
  return pb.pos < qb.pos ? -1 : pb.pos > qb.pos;
}

/* The callback order of one collider against the oracle's pairs put in that order from
 * the tree's public leaf listing, on one and two threads. */
static void check_pairs_order(const qk_disc_t *d, size_t nd, const qk_box_t *b, size_t nb,
                              uint32_t cap) {
  qk_tree_options_t o = opts(cap);
  qk_collider_t *c = NULL;
  assert_int_equal(qk_collider_build(d, nd, b, nb, &o, &c), QK_OK);
  const qk_tree_t *t = qk_collider_tree(c);
  size_t nl = 0;
  assert_int_equal(qk_tree_leaves(t, NULL, 0, &nl), QK_OK);
  qk_node_t *leaves = malloc(nl * sizeof *leaves);
  assert_int_equal(qk_tree_leaves(t, leaves, nl, &nl), QK_OK);
  place_t *place = malloc((nd + nb + 1) * sizeof *place);
  for (size_t l = 0; l < nl; l++) {
    const qk_id_t *ids;
    size_t n;
    assert_int_equal(qk_tree_leaf_points(t, leaves[l], NULL, NULL, &ids, &n), QK_OK);
    for (size_t k = 0; k < n; k++) place[ids[k]] = (place_t){l, k};
  }
  qk_pair_t *want;
  const size_t nw = qko_pairs(d, nd, b, nb, &want);
  g_place = place;
  qsort(want, nw, sizeof *want, place_cmp);
  for (uint32_t th = 1; th <= 2; th++) {
    qk_collider_set_threads(c, th);
    seq_t got = pairs_seq(c, 0);
    if (got.n != nw)
      fail_msg("order: %zu pairs, oracle %zu (threads %u cap %u seed %llu)", got.n, nw, th, cap,
               (unsigned long long)g_seed);
    for (size_t i = 0; i < nw; i++)
      if (got.p[i].a != want[i].a || got.p[i].b != want[i].b)
        fail_msg("order: pair %zu is (%u,%u), expected (%u,%u) (threads %u cap %u seed %llu)", i,
                 got.p[i].a, got.p[i].b, want[i].a, want[i].b, th, cap, (unsigned long long)g_seed);
    free(got.p);
  }
  free(want), free(place), free(leaves);
  qk_collider_free(c);
}

/*
 * The order of the pairs (collide/collider.c: by the leaf of the smaller id in pre-order,
 * then the other's leaf, then their places in the leaves) against the brute-force oracle's
 * set sorted into that order: discs, boxes and both, uniform and clustered, small and
 * large items (leaf boxes reaching over many leaves), capacities 1 to 16, coincident
 * centres (leaves over capacity at the depth cap), items on a negative, far-off grid
 * (boxes touching exactly, sides that are not floats), and long items among small ones
 * (the leaves near them meet more leaves than a family list holds), and boxes beyond the
 * float range (node boxes with infinite sides).
 */
static void test_collide_pairs_order(void **state) {
  (void)state;
  qkt_rng_t r;
  qkt_rng_seed(&r, g_seed + 17);
  enum { N = 1200 };
  qk_disc_t *d = malloc(N * sizeof *d);
  qk_box_t *b = malloc(N * sizeof *b);
  const uint32_t caps[] = {1, 3, 8, 16};
  for (int cl = 0; cl < 2; cl++)
    for (int ci = 0; ci < 4; ci++) {
      make_items(&r, d, N, b, N, cl, cl ? 0.003 : 0.02);
      check_pairs_order(d, N, NULL, 0, caps[ci]);
      check_pairs_order(NULL, 0, b, N, caps[ci]);
      check_pairs_order(d, N / 3, b, N / 2, caps[ci]);
    }
  /* Coincident centres: 40 items on each of 20 points, boxes of several sizes. */
  for (size_t i = 0; i < N; i++) {
    const double cx = 0.05 * (double)(i % 20), cy = 0.3 + 0.01 * (double)(i % 20);
    const double w = 0.001 * (double)(1 + i % 7), h = 0.02 * (double)(1 + i % 3);
    b[i] = (qk_box_t){cx - w, cy - h, cx + w, cy + h};
    d[i] = (qk_disc_t){cx, cy, 0.5 * w};
  }
  check_pairs_order(NULL, 0, b, 800, 4);
  check_pairs_order(d, 500, b, 500, 2);
  /* A grid of boxes with touching sides, far from the origin and not float-exact. */
  for (size_t i = 0; i < N; i++) {
    const double x = -1e7 + 0.1 * (double)(i % 40), y = 3e6 + 0.1 * (double)(i / 40);
    b[i] = (qk_box_t){x, y, x + 0.1, y + 0.1};
  }
  check_pairs_order(NULL, 0, b, N, 4);
  /* Small boxes and every 60th a long one: the leaves near a long one meet hundreds of
   * others. */
  for (size_t i = 0; i < N; i++) {
    const double cx = qkt_rng_unit(&r), cy = qkt_rng_unit(&r);
    const double w = i % 60 == 7 ? 0.4 : 0.004, h = i % 60 == 7 ? 0.01 : 0.004;
    b[i] = (qk_box_t){cx - w, cy - h, cx + w, cy + h};
    d[i] = (qk_disc_t){cx, cy, i % 60 == 7 ? 0.3 : 0.003};
  }
  check_pairs_order(NULL, 0, b, N, 1);
  check_pairs_order(d, N / 2, b, N / 2, 2);
  /* Beyond the float range: node boxes with infinite sides. */
  for (size_t i = 0; i < N; i++) {
    const double cx = 1e300 * qkt_rng_unit(&r), cy = -1e300 * qkt_rng_unit(&r);
    const double w = 3e298 * qkt_rng_unit(&r), h = i % 9 ? 3e298 * qkt_rng_unit(&r) : 1e40;
    b[i] = (qk_box_t){cx - w, cy - h, cx + w, cy + h};
  }
  check_pairs_order(NULL, 0, b, N, 3);
  free(d), free(b);
}

/*
 * The ray structures are made on first need (qk_collider_prepare_rays). A scene for the
 * tests below: items and rays with their oracle answers, large enough (above 4096 items)
 * that a collider with threads makes its ray entries on them, and deep enough for a start
 * table.
 */
enum { LZ_ND = 3000, LZ_NB = 3000, LZ_NR = 200 };
typedef struct lazy_scene {
  qk_disc_t d[LZ_ND];
  qk_box_t b[LZ_NB];
  qk_point_t org[LZ_NR], dir[LZ_NR];
  qk_hit_t want[LZ_NR];
} lazy_scene_t;

static lazy_scene_t *lazy_scene(uint64_t seed) {
  lazy_scene_t *s = malloc(sizeof *s);
  assert_non_null(s);
  qkt_rng_t r;
  qkt_rng_seed(&r, seed);
  make_items(&r, s->d, LZ_ND, s->b, LZ_NB, 0, 0.003);
  for (size_t i = 0; i < LZ_NR; i++) {
    s->org[i] = (qk_point_t){qkt_rng_range(&r, -0.1, 1.1), qkt_rng_range(&r, -0.1, 1.1)};
    double ang = qkt_rng_range(&r, 0, 6.283185307179586);
    s->dir[i] = (qk_point_t){cos(ang), sin(ang)};
    s->want[i] = qko_raycast(s->d, LZ_ND, s->b, LZ_NB, s->org[i], s->dir[i], INFINITY);
  }
  return s;
}

/* The oracle's answers for rays [lo, hi) of the scene, hits[i - lo] for ray i. */
static int lazy_agrees(const lazy_scene_t *s, const qk_hit_t *hits, size_t lo, size_t hi) {
  for (size_t i = lo; i < hi; i++)
    if (!ray_agrees(hits[i - lo], s->want[i], s->d, LZ_ND, s->b, s->org[i], s->dir[i], INFINITY))
      return 0;
  return 1;
}

/* A collider that is never cast holds no ray structures and frees cleanly; preparing makes
 * them (more memory held), preparing again changes nothing, and the casts then agree
 * with the oracle. */
static void test_collide_rays_lazy_prepare(void **state) {
  (void)state;
  lazy_scene_t *s = lazy_scene(g_seed + 21);
  locked_t l;
  pthread_mutex_init(&l.mu, NULL);
  qk_allocator_t a = qkt_alloc_make(&l.st);
  a.fn = locked_fn;
  a.ud = &l;
  for (uint32_t threads = 1; threads <= 2; threads++) {
    qk_tree_options_t o = opts(4);
    o.allocator = &a;
    o.threads = threads;
    /* Never cast: pairs and an overlap query, then free. */
    qk_collider_t *c = NULL;
    assert_int_equal(qk_collider_build(s->d, LZ_ND, s->b, LZ_NB, &o, &c), QK_OK);
    size_t np = 0;
    assert_int_equal(qk_collider_pairs_list(c, NULL, 0, &np), QK_OK);
    assert_true(np > 0);
    qk_collider_free(c);
    assert_int_equal(l.st.live_blocks, 0);
    /* Prepared explicitly, twice. */
    assert_int_equal(qk_collider_build(s->d, LZ_ND, s->b, LZ_NB, &o, &c), QK_OK);
    const size_t built = l.st.live_bytes, blocks = l.st.live_blocks;
    assert_int_equal(qk_collider_prepare_rays(c), QK_OK);
    if (!(l.st.live_bytes > built && l.st.live_blocks >= blocks + 2))
      fail_msg("threads %u: the build already held the ray structures (%zu bytes, then %zu)",
               threads, built, l.st.live_bytes);
    const size_t prepared = l.st.live_bytes;
    qkt_alloc_arm(&l.st, 0);
    assert_int_equal(qk_collider_prepare_rays(c), QK_OK);
    assert_int_equal(l.st.calls, 0); /* the second call allocates nothing */
    assert_int_equal(l.st.live_bytes, prepared);
    qk_hit_t h[LZ_NR];
    for (size_t i = 0; i < LZ_NR; i++)
      assert_int_equal(qk_collider_raycast(c, s->org[i], s->dir[i], INFINITY, &h[i]), QK_OK);
    if (!lazy_agrees(s, h, 0, LZ_NR))
      fail_msg("threads %u: prepared casts disagree with the oracle (seed %llu)", threads,
               (unsigned long long)g_seed);
    assert_int_equal(qk_collider_prepare_rays(c), QK_OK);
    assert_int_equal(l.st.live_bytes, prepared);
    qk_collider_free(c);
    assert_int_equal(l.st.live_blocks, 0);
  }
  assert_int_equal(qk_collider_prepare_rays(NULL), QK_ERR_INVALID);
  /* An empty collider and one beyond 2^100 (no ray entries) prepare and cast too. */
  {
    qk_collider_t *c = NULL;
    assert_int_equal(qk_collider_build(NULL, 0, NULL, 0, NULL, &c), QK_OK);
    assert_int_equal(qk_collider_prepare_rays(c), QK_OK);
    qk_hit_t h;
    assert_int_equal(qk_collider_raycast(c, (qk_point_t){0, 0}, (qk_point_t){1, 0}, 1, &h), QK_OK);
    assert_int_equal(h.id, QK_NONE);
    qk_collider_free(c);
    const qk_disc_t far[2] = {{1e120, 0, 1e119}, {3e120, 0, 1e119}};
    assert_int_equal(qk_collider_build(far, 2, NULL, 0, NULL, &c), QK_OK);
    assert_int_equal(qk_collider_raycast(c, (qk_point_t){0, 0}, (qk_point_t){1, 0}, INFINITY, &h),
                     QK_OK);
    assert_int_equal(h.id, 0);
    assert_int_equal(qk_collider_prepare_rays(c), QK_OK);
    qk_collider_free(c);
  }
  pthread_mutex_destroy(&l.mu);
  free(s);
}

/* Rays from several threads at once on a collider not yet prepared: one of them makes the
 * ray structures, the others wait; every answer is the oracle's. */
typedef struct lazy_thr {
  const qk_collider_t *c;
  const lazy_scene_t *s;
  atomic_int *go;
  unsigned k;
  int batch, ok;
} lazy_thr_t;

static void *lazy_thread(void *arg) {
  lazy_thr_t *t = arg;
  qk_hit_t h[LZ_NR];
  while (!atomic_load(t->go)) /* start together (yielding: under valgrind the threads */
    sched_yield();            /* take turns, and a bare spin starves the others) */
  /* Each thread from its own ray, so that different rays make the first call. */
  const size_t first = (size_t)t->k * 37 % LZ_NR;
  t->ok = 1;
  if (t->batch) {
    if (qk_collider_raycast_batch(t->c, t->s->org, t->s->dir, LZ_NR, INFINITY, h) != QK_OK)
      t->ok = 0;
  } else {
    for (size_t j = 0; j < LZ_NR; j++) {
      const size_t i = (first + j) % LZ_NR;
      if (qk_collider_raycast(t->c, t->s->org[i], t->s->dir[i], INFINITY, &h[i]) != QK_OK)
        t->ok = 0;
    }
  }
  if (t->ok) t->ok = lazy_agrees(t->s, h, 0, LZ_NR);
  return NULL;
}

static void test_collide_rays_lazy_threads(void **state) {
  (void)state;
  lazy_scene_t *s = lazy_scene(g_seed + 22);
  for (unsigned nt = 2; nt <= 4; nt += 2) {
    for (int round = 0; round < 4; round++) {
      qk_tree_options_t o = opts(4);
      qk_collider_t *c = NULL;
      assert_int_equal(qk_collider_build(s->d, LZ_ND, s->b, LZ_NB, &o, &c), QK_OK);
      /* odd rounds: the first caller makes the ray entries on two threads of its own */
      qk_collider_set_threads(c, round % 2 ? 2 : 1);
      atomic_int go;
      atomic_init(&go, 0);
      pthread_t th[4];
      lazy_thr_t t[4];
      for (unsigned k = 0; k < nt; k++) {
        t[k] = (lazy_thr_t){c, s, &go, k, round >= 2 && k == 0, 0};
        assert_int_equal(pthread_create(&th[k], NULL, lazy_thread, &t[k]), 0);
      }
      atomic_store(&go, 1);
      for (unsigned k = 0; k < nt; k++) pthread_join(th[k], NULL);
      for (unsigned k = 0; k < nt; k++)
        if (!t[k].ok)
          fail_msg("%u threads, round %d: thread %u disagrees with the oracle (seed %llu)", nt,
                   round, k, (unsigned long long)g_seed);
      qk_collider_free(c);
    }
  }
  free(s);
}

/* Allocation failure at every N while the ray structures are made, through each entry
 * point: QK_ERR_NOMEM, nothing kept; a retry then succeeds with the oracle's answers. */
static void test_collide_rays_lazy_nomem(void **state) {
  (void)state;
  lazy_scene_t *s = lazy_scene(g_seed + 23);
  locked_t l;
  pthread_mutex_init(&l.mu, NULL);
  qk_allocator_t a = qkt_alloc_make(&l.st);
  a.fn = locked_fn;
  a.ud = &l;
  for (uint32_t threads = 1; threads <= 2; threads++) {
    for (int entry = 0; entry < 3; entry++) { /* prepare, raycast, batch */
      size_t fail_at, n_nomem = 0;
      for (fail_at = 1;; fail_at++) {
        qkt_alloc_arm(&l.st, 0);
        qk_tree_options_t o = opts(4);
        o.allocator = &a;
        o.threads = threads;
        qk_collider_t *c = NULL;
        assert_int_equal(qk_collider_build(s->d, LZ_ND, s->b, LZ_NB, &o, &c), QK_OK);
        const size_t built = l.st.live_bytes, blocks = l.st.live_blocks;
        qk_hit_t h[LZ_NR];
        qkt_alloc_arm(&l.st, fail_at);
        qk_status_t st;
        if (entry == 0) {
          st = qk_collider_prepare_rays(c);
        } else if (entry == 1) {
          st = qk_collider_raycast(c, s->org[0], s->dir[0], INFINITY, &h[0]);
          if (st != QK_OK) assert_int_equal(h[0].id, QK_NONE);
        } else {
          st = qk_collider_raycast_batch(c, s->org, s->dir, LZ_NR, INFINITY, h);
        }
        const int failed = l.st.failed;
        qkt_alloc_arm(&l.st, 0);
        if (st == QK_OK) { /* nothing failed, or the threads' plan (then made serially) */
          assert_false(failed && threads == 1); /* one thread: every allocation is needed */
          qk_collider_free(c);
          assert_int_equal(l.st.live_blocks, 0);
          if (!failed) break;
          continue;
        }
        assert_int_equal(st, QK_ERR_NOMEM);
        n_nomem++;
        if (l.st.live_bytes != built || l.st.live_blocks != blocks)
          fail_msg("threads %u entry %d fail_at %zu: %zu bytes held, %zu after the build", threads,
                   entry, fail_at, l.st.live_bytes, built);
        /* The retry (a cast) succeeds, with the oracle's answers. */
        for (size_t i = 0; i < LZ_NR; i++)
          assert_int_equal(qk_collider_raycast(c, s->org[i], s->dir[i], INFINITY, &h[i]), QK_OK);
        if (!lazy_agrees(s, h, 0, LZ_NR))
          fail_msg("threads %u entry %d fail_at %zu: retried casts disagree (seed %llu)", threads,
                   entry, fail_at, (unsigned long long)g_seed);
        qk_collider_free(c);
        assert_int_equal(l.st.live_blocks, 0);
        assert_true(fail_at < 100);
      }
      assert_int_equal(n_nomem, 2); /* quads, start table: each failed once */
    }
  }
  pthread_mutex_destroy(&l.mu);
  free(s);
}

int main(void) {
  qkt_filters_from_env();
  g_seed = qkt_seed(7031);
  const struct CMUnitTest tests[] = {
      cmocka_unit_test(test_collide_pairs),
      cmocka_unit_test(test_collide_query_shapes),
      cmocka_unit_test(test_collide_raycast),
      cmocka_unit_test(test_collide_exact_cases),
      cmocka_unit_test(test_collide_nomem),
      cmocka_unit_test(test_collide_threads),
      cmocka_unit_test(test_collide_threads_option),
      cmocka_unit_test(test_collide_rays_batch_counts),
      cmocka_unit_test(test_collide_threads_nomem),
      cmocka_unit_test(test_collide_threaded_build),
      cmocka_unit_test(test_collide_threads_worker_nomem),
      cmocka_unit_test(test_collide_arrays_huge),
      cmocka_unit_test(test_collide_threads_skewed),
      cmocka_unit_test(test_collide_raycast_leaf_counts),
      cmocka_unit_test(test_collide_pairs_order),
      cmocka_unit_test(test_collide_rebuild),
      cmocka_unit_test(test_collide_rays_lazy_prepare),
      cmocka_unit_test(test_collide_rays_lazy_threads),
      cmocka_unit_test(test_collide_rays_lazy_nomem),
      cmocka_unit_test(test_collide_exact_extremes),
      cmocka_unit_test(test_collide_scale),
  };
  return cmocka_run_group_tests(tests, NULL, NULL);
}
