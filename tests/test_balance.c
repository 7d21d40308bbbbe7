/*
 * Test plan for qk_tree_balance() / qk_tree_is_balanced() (BalanceQuadTree, notes V):
 *  - random point trees (uniform, clustered, duplicates, cell-edge points) and random
 *    deep refinements (subdivision-like trees): after balancing, a brute-force check over
 *    all pairs of leaves finds no two edge-adjacent leaves more than one level apart;
 *    qk_tree_check() passes (points moved into the right new leaves, none lost);
 *  - the result equals the smallest balanced refinement, computed by a brute-force
 *    fixpoint (split any leaf with an adjacent leaf two levels deeper, repeat);
 *  - the number of leaves stays within a constant factor of the input's (Theorem 2);
 *  - qk_tree_is_balanced() agrees with the brute-force check before and after; most
 *    rounds start unbalanced (counted per kind), and balancing a balanced tree again
 *    leaves the same leaf squares;
 *  - larger trees (10^3..2x10^4 points; uniform, clustered, duplicates, grid edges, a
 *    root fitted to offset coordinates, random capacities and depth caps): the result
 *    equals a second oracle that scales, a fixpoint over qk_tree_adjacent_leaves()
 *    (NorthNeighbor, independent of the balance code: split every leaf with an adjacent
 *    leaf two levels deeper, repeat), leaf for leaf; qk_tree_is_balanced() agrees with
 *    that oracle's check before and after;
 *  - balancing a balanced tree allocates nothing;
 *  - allocation failure at every N: QK_ERR_NOMEM, the tree unchanged and valid, no leak.
 */
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "qk_test.h"

typedef struct leaf {
  double x, y, s;
  uint32_t depth;
} leaf_t;

static size_t get_leaves(const qk_tree_t *t, leaf_t **out) {
  size_t n = 0;
  qk_tree_leaves(t, NULL, 0, &n);
  qk_node_t *ids = malloc((n + 1) * sizeof *ids);
  *out = malloc((n + 1) * sizeof **out);
  assert_non_null(ids);
  assert_non_null(*out);
  qk_tree_leaves(t, ids, n, &n);
  for (size_t i = 0; i < n; i++) {
    qk_node_info_t info;
    assert_int_equal(qk_tree_node_info(t, ids[i], &info), QK_OK);
    (*out)[i] = (leaf_t){info.square.x, info.square.y, info.square.side, info.depth};
  }
  free(ids);
  return n;
}

/* Do two squares share a segment of positive length? (Dyadic squares: exact.) */
static int share_edge(const leaf_t *a, const leaf_t *b) {
  double ax1 = a->x + a->s, ay1 = a->y + a->s, bx1 = b->x + b->s, by1 = b->y + b->s;
  double ylo = a->y > b->y ? a->y : b->y, yhi = ay1 < by1 ? ay1 : by1;
  double xlo = a->x > b->x ? a->x : b->x, xhi = ax1 < bx1 ? ax1 : bx1;
  if ((ax1 == b->x || bx1 == a->x) && yhi > ylo) return 1;
  if ((ay1 == b->y || by1 == a->y) && xhi > xlo) return 1;
  return 0;
}

/* Brute force: index of a leaf having an adjacent leaf 2+ levels deeper, or -1. */
static long brute_unbalanced(const leaf_t *L, size_t n) {
  for (size_t i = 0; i < n; i++)
    for (size_t j = 0; j < n; j++)
      if (L[j].depth >= L[i].depth + 2 && share_edge(&L[i], &L[j])) return (long)i;
  return -1;
}

static int leaf_cmp(const void *a, const void *b) {
  const leaf_t *p = a, *q = b;
  if (p->x != q->x) return p->x < q->x ? -1 : 1;
  if (p->y != q->y) return p->y < q->y ? -1 : 1;
  return (p->depth > q->depth) - (p->depth < q->depth);
}

/* The smallest balanced refinement by brute force, using only public calls: every leaf
 * with an adjacent leaf two levels deeper must be split in any balanced refinement, so
 * split all of them and repeat until none is left. */
static void brute_balance(qk_tree_t *t) {
  for (;;) {
    leaf_t *L;
    size_t n = get_leaves(t, &L), split = 0;
    for (size_t i = 0; i < n; i++) {
      int need = 0;
      for (size_t j = 0; j < n && !need; j++)
        need = L[j].depth >= L[i].depth + 2 && share_edge(&L[i], &L[j]);
      if (!need) continue;
      qk_node_t leaf;
      qk_point_t c = {L[i].x + L[i].s / 2, L[i].y + L[i].s / 2};
      assert_int_equal(qk_tree_find_leaf(t, c, &leaf), QK_OK);
      assert_int_equal(qk_tree_split_leaf(t, leaf), QK_OK);
      split++;
    }
    free(L);
    if (!split) return;
  }
}

/* Does some leaf have an adjacent leaf two or more levels deeper? Through the public
 * neighbour calls; when `split` is set, splits every such leaf and returns how many. */
static size_t neighbour_violations(qk_tree_t *t, int split) {
  size_t n = 0, count = 0;
  qk_tree_leaves(t, NULL, 0, &n);
  qk_node_t *ids = malloc((n + 1) * sizeof *ids);
  qk_node_t adj[4096];
  assert_non_null(ids);
  qk_tree_leaves(t, ids, n, &n);
  /* Decide every leaf first, split afterwards: a split renames no other node. */
  size_t *bad = malloc((n + 1) * sizeof *bad), nbad = 0;
  assert_non_null(bad);
  for (size_t i = 0; i < n; i++) {
    qk_node_info_t a;
    assert_int_equal(qk_tree_node_info(t, ids[i], &a), QK_OK);
    int need = 0;
    for (int d = 0; d < 4 && !need; d++) {
      size_t m = 0;
      assert_int_equal(qk_tree_adjacent_leaves(t, ids[i], (qk_dir_t)d, adj, 4096, &m), QK_OK);
      assert_true(m <= 4096);
      for (size_t j = 0; j < m && !need; j++) {
        qk_node_info_t b;
        assert_int_equal(qk_tree_node_info(t, adj[j], &b), QK_OK);
        need = b.depth >= a.depth + 2;
      }
    }
    if (need) bad[nbad++] = ids[i];
  }
  count = nbad;
  if (split)
    for (size_t i = 0; i < nbad; i++) assert_int_equal(qk_tree_split_leaf(t, bad[i]), QK_OK);
  free(bad);
  free(ids);
  return count;
}

/* The smallest balanced refinement by the neighbour fixpoint. */
static void neighbour_balance(qk_tree_t *t) {
  while (neighbour_violations(t, 1)) {
  }
}

typedef struct refine_ud {
  qk_point_t p[4];
  uint32_t depth;
} refine_ud_t;

/* Split squares whose closure holds one of a few random points, down to `depth`: the
 * deep, narrow trees of a mesh subdivision. */
static int refine_near(const qk_tree_t *t, qk_node_t leaf, qk_square_t sq, uint32_t depth,
                       void *ud) {
  (void)t, (void)leaf;
  const refine_ud_t *r = ud;
  if (depth >= r->depth) return 0;
  for (int i = 0; i < 4; i++)
    if (r->p[i].x >= sq.x && r->p[i].x <= sq.x + sq.side && r->p[i].y >= sq.y &&
        r->p[i].y <= sq.y + sq.side)
      return 1;
  return 0;
}

static qk_tree_t *make_tree(qkt_rng_t *r, int kind, size_t n, qk_point_t *pts,
                            const qk_allocator_t *a) {
  qk_tree_options_t o;
  qk_tree_options_init(&o);
  o.has_root = 1;
  o.root = (qk_square_t){0, 0, 1};
  o.allocator = a;
  o.max_depth = 20; /* duplicates stop here; keeps the quadratic brute force quick */
  qk_tree_t *t = NULL;
  if (kind < 4) {
    qkt_points(r, (qkt_dist_t)kind, pts, n);
    if (qk_tree_build(pts, n, &o, &t) != QK_OK) return NULL;
  } else {
    if (qk_tree_build(NULL, 0, &o, &t) != QK_OK) return NULL;
    refine_ud_t ud;
    for (int i = 0; i < 4; i++) ud.p[i] = (qk_point_t){qkt_rng_unit(r), qkt_rng_unit(r)};
    ud.depth = 4 + qkt_rng_below(r, 6);
    if (qk_tree_refine(t, refine_near, &ud) != QK_OK) {
      qk_tree_free(t);
      return NULL;
    }
  }
  return t;
}

static void test_balance_random(void **state) {
  (void)state;
  uint64_t seed = qkt_seed(20261122);
  qkt_rng_t r;
  qkt_rng_seed(&r, seed);
  print_message("seed %llu\n", (unsigned long long)seed);
  qk_point_t pts[400];
  double worst_ratio = 0;
  /* Rounds whose tree started unbalanced, per kind: a run where every input happened to
   * be balanced already would test nothing, so each kind must contribute some. */
  int unbalanced[5] = {0}, rounds[5] = {0};
  for (int round = 0; round < 40; round++) {
    int kind = round % 5;
    size_t n = 1 + qkt_rng_below(&r, 150);
    qkt_rng_t r2 = r; /* the same tree again, for the brute-force balance */
    qk_tree_t *t = make_tree(&r, kind, n, pts, NULL);
    qk_tree_t *u = make_tree(&r2, kind, n, pts, NULL);
    assert_non_null(t);
    assert_non_null(u);
    leaf_t *L;
    size_t n0 = get_leaves(t, &L);
    int was = brute_unbalanced(L, n0) < 0;
    free(L);
    rounds[kind]++;
    unbalanced[kind] += !was;
    if (qk_tree_is_balanced(t) != was)
      fail_msg("seed %llu round %d: is_balanced before", (unsigned long long)seed, round);

    assert_int_equal(qk_tree_balance(t), QK_OK);
    QKT_CHECK_TREE(t);
    assert_true(qk_tree_is_balanced(t));
    size_t n1 = get_leaves(t, &L);
    if (brute_unbalanced(L, n1) >= 0)
      fail_msg("seed %llu round %d: not balanced after qk_tree_balance", (unsigned long long)seed,
               round);
    qk_tree_stats_t s;
    qk_tree_stats(t, &s);
    if (kind < 4) assert_int_equal(s.points, n);

    brute_balance(u);
    leaf_t *M;
    size_t n2 = get_leaves(u, &M);
    if (n1 != n2)
      fail_msg("seed %llu round %d: %zu leaves, brute force %zu", (unsigned long long)seed, round,
               n1, n2);
    qsort(L, n1, sizeof *L, leaf_cmp);
    qsort(M, n2, sizeof *M, leaf_cmp);
    for (size_t i = 0; i < n1; i++)
      if (leaf_cmp(&L[i], &M[i]))
        fail_msg("seed %llu round %d: leaf %zu differs", (unsigned long long)seed, round, i);
    double ratio = (double)n1 / (double)n0;
    if (ratio > worst_ratio) worst_ratio = ratio;
    /* Theorem 2: O(m) nodes. The constant for leaves is small in practice. */
    if (ratio > 12)
      fail_msg("seed %llu round %d: %zu leaves from %zu", (unsigned long long)seed, round, n1, n0);
    /* Balancing again changes nothing: the same leaf squares at the same depths. */
    assert_int_equal(qk_tree_balance(t), QK_OK);
    QKT_CHECK_TREE(t);
    leaf_t *K;
    size_t n3 = get_leaves(t, &K);
    if (n3 != n1)
      fail_msg("seed %llu round %d: balancing again gave %zu leaves, not %zu",
               (unsigned long long)seed, round, n3, n1);
    qsort(K, n3, sizeof *K, leaf_cmp);
    for (size_t i = 0; i < n3; i++)
      if (leaf_cmp(&K[i], &L[i]) || K[i].s != L[i].s)
        fail_msg("seed %llu round %d: balancing again changed leaf %zu", (unsigned long long)seed,
                 round, i);
    free(K);
    /* The balanced tree stays a working index: inserts and removes keep it valid, and
     * every point is found in the leaf that holds its location. */
    if (kind < 4) {
      for (int i = 0; i < 20; i++) {
        qk_id_t id;
        qk_point_t q = {qkt_rng_unit(&r), qkt_rng_unit(&r)};
        assert_int_equal(qk_tree_insert(t, q, &id), QK_OK);
        qk_node_t a, b;
        assert_int_equal(qk_tree_leaf_of(t, id, &a), QK_OK);
        assert_int_equal(qk_tree_find_leaf(t, q, &b), QK_OK);
        assert_int_equal(a, b);
      }
      for (qk_id_t id = 0; id < n && id < 10; id++) assert_int_equal(qk_tree_remove(t, id), QK_OK);
      QKT_CHECK_TREE(t);
      /* Inserts may unbalance it again; balancing restores the property. */
      assert_int_equal(qk_tree_balance(t), QK_OK);
      QKT_CHECK_TREE(t);
      assert_true(qk_tree_is_balanced(t));
    }
    free(L);
    free(M);
    qk_tree_free(t);
    qk_tree_free(u);
  }
  print_message("worst leaf ratio %.2f\n", worst_ratio);
  for (int k = 0; k < 5; k++) {
    print_message("kind %d: %d of %d rounds started unbalanced\n", k, unbalanced[k], rounds[k]);
    /* Most of each kind's rounds must exercise the balancing proper (all do today). */
    if (2 * unbalanced[k] < rounds[k])
      fail_msg("seed %llu kind %d: only %d of %d rounds started unbalanced",
               (unsigned long long)seed, k, unbalanced[k], rounds[k]);
  }
}

/* A single deep leaf next to a huge one: the cascade the notes describe. */
static void test_balance_cascade(void **state) {
  (void)state;
  qk_tree_options_t o;
  qk_tree_options_init(&o);
  o.has_root = 1;
  o.root = (qk_square_t){0, 0, 1};
  qk_tree_t *t;
  /* Two points very close to the centre force a deep split there. */
  qk_point_t p[2] = {{0.5 + 1e-6, 0.5 + 1e-6}, {0.5 + 2e-6, 0.5 + 2e-6}};
  assert_int_equal(qk_tree_build(p, 2, &o, &t), QK_OK);
  assert_false(qk_tree_is_balanced(t));
  assert_int_equal(qk_tree_balance(t), QK_OK);
  QKT_CHECK_TREE(t);
  assert_true(qk_tree_is_balanced(t));
  leaf_t *L;
  size_t n = get_leaves(t, &L);
  assert_true(brute_unbalanced(L, n) < 0);
  free(L);
  /* The points are still found where they are. */
  for (qk_id_t i = 0; i < 2; i++) {
    qk_point_t q;
    assert_int_equal(qk_tree_point(t, i, &q), QK_OK);
    assert_true(q.x == p[i].x && q.y == p[i].y);
  }
  qk_tree_free(t);
}

/* Larger trees against the neighbour fixpoint, leaf for leaf. */
static void test_balance_larger_random(void **state) {
  (void)state;
  uint64_t seed = qkt_seed(20261130);
  qkt_rng_t r;
  qkt_rng_seed(&r, seed);
  print_message("seed %llu\n", (unsigned long long)seed);
  size_t cap_pts = 20000;
  qk_point_t *pts = malloc(cap_pts * sizeof *pts);
  assert_non_null(pts);
  int started_unbalanced = 0;
  for (int round = 0; round < 10; round++) {
    int kind = round % 5;
    size_t n = 1000 + qkt_rng_below(&r, (uint32_t)(cap_pts - 1000));
    qkt_points(&r, (qkt_dist_t)(kind % 4), pts, n);
    qk_tree_options_t o;
    qk_tree_options_init(&o);
    o.capacity = 1 + qkt_rng_below(&r, 8);
    o.max_depth = 12 + qkt_rng_below(&r, 20);
    if (kind == 4) /* a root fitted to offset, scaled points: non-dyadic squares */
      for (size_t i = 0; i < n; i++)
        pts[i] = (qk_point_t){1234.5 + 0.37 * pts[i].x, -77.25 + 0.37 * pts[i].y};
    else {
      o.has_root = 1;
      o.root = (qk_square_t){0, 0, 1};
    }
    qk_tree_t *t = NULL, *u = NULL;
    assert_int_equal(qk_tree_build(pts, n, &o, &t), QK_OK);
    assert_int_equal(qk_tree_build(pts, n, &o, &u), QK_OK);
    int was = neighbour_violations(t, 0) == 0;
    started_unbalanced += !was;
    if (qk_tree_is_balanced(t) != was)
      fail_msg("seed %llu round %d: is_balanced before", (unsigned long long)seed, round);
    assert_int_equal(qk_tree_balance(t), QK_OK);
    QKT_CHECK_TREE(t);
    neighbour_balance(u);
    if (!qk_tree_is_balanced(t) || neighbour_violations(t, 0))
      fail_msg("seed %llu round %d: not balanced", (unsigned long long)seed, round);
    leaf_t *L, *M;
    size_t n1 = get_leaves(t, &L), n2 = get_leaves(u, &M);
    if (n1 != n2)
      fail_msg("seed %llu round %d: %zu leaves, oracle %zu", (unsigned long long)seed, round, n1,
               n2);
    qsort(L, n1, sizeof *L, leaf_cmp);
    qsort(M, n2, sizeof *M, leaf_cmp);
    for (size_t i = 0; i < n1; i++)
      if (leaf_cmp(&L[i], &M[i]) || L[i].s != M[i].s)
        fail_msg("seed %llu round %d: leaf %zu differs", (unsigned long long)seed, round, i);
    free(L);
    free(M);
    qk_tree_free(t);
    qk_tree_free(u);
  }
  free(pts);
  print_message("%d of 10 rounds started unbalanced\n", started_unbalanced);
  if (started_unbalanced < 5)
    fail_msg("seed %llu: only %d rounds started unbalanced", (unsigned long long)seed,
             started_unbalanced);
}

/* A balanced tree: qk_tree_balance only checks it, without allocating. */
static void test_balance_balanced_allocates_nothing(void **state) {
  (void)state;
  qkt_rng_t r;
  qkt_rng_seed(&r, 11);
  qk_point_t pts[3000];
  qkt_points(&r, QKT_CLUSTERED, pts, 3000);
  qkt_alloc_t st = {0};
  qk_allocator_t a = qkt_alloc_make(&st);
  qk_tree_options_t o;
  qk_tree_options_init(&o);
  o.allocator = &a;
  qk_tree_t *t = NULL;
  assert_int_equal(qk_tree_build(pts, 3000, &o, &t), QK_OK);
  assert_int_equal(qk_tree_balance(t), QK_OK);
  size_t before = st.calls;
  assert_int_equal(qk_tree_balance(t), QK_OK);
  assert_int_equal(st.calls, before);
  assert_true(qk_tree_is_balanced(t));
  QKT_CHECK_TREE(t);
  qk_tree_free(t);
  assert_int_equal(st.live_bytes, 0);
}

static void test_balance_alloc_failure(void **state) {
  (void)state;
  qkt_rng_t r;
  qkt_rng_seed(&r, 7);
  qk_point_t pts[64];
  for (size_t fail_at = 1;; fail_at++) {
    qkt_alloc_t st = {0};
    qk_allocator_t a = qkt_alloc_make(&st);
    qkt_rng_t r2 = r;
    qk_tree_t *t = make_tree(&r2, QKT_CLUSTERED, 64, pts, &a);
    assert_non_null(t);
    size_t leaves_before = 0, leaves_after = 0;
    qk_tree_leaves(t, NULL, 0, &leaves_before);
    st.fail_at = st.calls + fail_at;
    qk_status_t s = qk_tree_balance(t);
    int failed = st.failed; /* before the check, whose scratch may take the failure */
    qk_tree_leaves(t, NULL, 0, &leaves_after);
    if (s != QK_OK) assert_int_equal(leaves_after, leaves_before); /* unchanged */
    QKT_CHECK_TREE(t);
    qk_tree_free(t);
    assert_int_equal(st.live_bytes, 0);
    if (s == QK_OK && !failed) break;
    assert_int_equal(s, QK_ERR_NOMEM);
    assert_true(fail_at < 1000);
  }
}

int main(void) {
  const struct CMUnitTest tests[] = {
      cmocka_unit_test(test_balance_random),
      cmocka_unit_test(test_balance_cascade),
      cmocka_unit_test(test_balance_larger_random),
      cmocka_unit_test(test_balance_balanced_allocates_nothing),
      cmocka_unit_test(test_balance_alloc_failure),
  };
  return cmocka_run_group_tests(tests, NULL, NULL);
}
