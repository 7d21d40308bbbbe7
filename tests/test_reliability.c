/*
 * Test plan for reliability (issue 6), across modules:
 *  - replay: every seed input under fuzz/corpus/<target>/ and every crash found so far
 *    under fuzz/regressions/<target>/ goes through the fuzz target's own entry point
 *    (the target sources are compiled into this test), so a fixed bug stays fixed; inputs
 *    under regressions/<target>/open/ are known, reported, unfixed bugs and are listed,
 *    not run;
 *  - allocation failure at every N until success, with a clean QK_ERR_NOMEM, no leak and
 *    the inputs unchanged (or, where documented, the tree still valid) for: balance,
 *    refine, the collider and the geodesic index, the .poly reader, inputs from arrays
 *    and mesh generation (build, insert and remove are in test_index.c);
 *  - the queries that promise not to allocate (range, radius, kNN, locate, collider
 *    queries and pairs) make no allocation call at all; batches of 64 or more, which
 *    borrow a buffer, give the same answers when that allocation fails;
 *  - writers report a full disk (/dev/full) as QK_ERR_IO;
 *  - limits: counts beyond QK_MAX_POINTS, domains beyond QK_MESH_MAX_SIZE and absurd
 *    counts in a .poly header give QK_ERR_LIMIT / QK_ERR_INVALID / QK_ERR_GEOMETRY
 *    before anything is read or allocated.
 */
#define _XOPEN_SOURCE 700 /* opendir here, getpid in fuzz/fuzz_csv.c */
#include <dirent.h>
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "qk_test.h"
#include "index/index_access.h" /* and, for the id limit test, the tree struct */
#include "mesh_check.h"

/* The fuzz targets, compiled in with failures reported through cmocka. */
static const char *qkr_current = "";
#define QKF_REPLAY 1
#define QKF_FAIL(...)                                                                              \
  do {                                                                                             \
    print_error("while replaying %s:\n", qkr_current);                                             \
    fail_msg(__VA_ARGS__);                                                                         \
  } while (0)
#include "fuzz/fuzz_csv.c"
#include "fuzz/fuzz_poly.c"
#include "fuzz/fuzz_tree_ops.c"
#include "fuzz/fuzz_world.c"

/* ---- replay of the fuzz corpus and regressions ---------------------------------------- */

static const char *source_dir(void) {
  const char *s = getenv("QK_SOURCE_DIR");
  if (!s) fail_msg("QK_SOURCE_DIR is not set (run the test through ctest)");
  return s;
}

static unsigned char *read_all(const char *path, size_t *n) {
  FILE *f = fopen(path, "rb");
  if (!f) fail_msg("cannot open %s", path);
  size_t cap = 4096, len = 0;
  unsigned char *buf = malloc(cap);
  assert_non_null(buf);
  size_t got;
  while ((got = fread(buf + len, 1, cap - len, f)) > 0) {
    len += got;
    if (len == cap) {
      buf = realloc(buf, cap *= 2);
      assert_non_null(buf);
    }
  }
  fclose(f);
  *n = len;
  return buf;
}

/* Run every regular file of dir through fn; returns how many. Lists (but does not run)
 * the files of dir/open when `open_note` is set. */
static size_t replay_dir(const char *dir, int (*fn)(const uint8_t *, size_t), int open_note) {
  DIR *d = opendir(dir);
  if (!d) return 0;
  size_t count = 0;
  struct dirent *e;
  char path[4096];
  while ((e = readdir(d)) != NULL) {
    if (e->d_name[0] == '.') continue;
    snprintf(path, sizeof path, "%s/%s", dir, e->d_name);
    if (!strcmp(e->d_name, "open")) {
      if (open_note) {
        DIR *o = opendir(path);
        struct dirent *oe;
        while (o && (oe = readdir(o)) != NULL)
          if (oe->d_name[0] != '.')
            print_message("known open bug, not replayed: %s/%s\n", path, oe->d_name);
        if (o) closedir(o);
      }
      continue;
    }
    size_t n;
    unsigned char *buf = read_all(path, &n);
    qkr_current = path;
    fn(buf, n);
    free(buf);
    count++;
  }
  closedir(d);
  return count;
}

static void replay_target(const char *name, int (*fn)(const uint8_t *, size_t)) {
  char dir[4096];
  snprintf(dir, sizeof dir, "%s/fuzz/corpus/%s", source_dir(), name);
  size_t seeds = replay_dir(dir, fn, 0);
  snprintf(dir, sizeof dir, "%s/fuzz/regressions/%s", source_dir(), name);
  size_t regressions = replay_dir(dir, fn, 1);
  print_message("%s: replayed %zu seeds and %zu regression inputs\n", name, seeds, regressions);
  /* The corpus is part of the test: an empty one means the replay checks nothing. */
  assert_true(seeds > 0);
}

static void test_reliability_replay_tree_ops(void **state) {
  (void)state;
  replay_target("tree_ops", qkf_tree_ops);
}

static void test_reliability_replay_csv(void **state) {
  (void)state;
  replay_target("csv", qkf_csv);
}

static void test_reliability_replay_poly(void **state) {
  (void)state;
  replay_target("poly", qkf_poly);
}

static void test_reliability_replay_world(void **state) {
  (void)state;
  replay_target("world", qkf_world);
}

/* ---- allocation failure ------------------------------------------------------------ */

/* Shape of a tree, to tell whether a failed call changed it. */
typedef struct shape {
  qk_tree_stats_t s;
} shape_t;

static shape_t shape_of(const qk_tree_t *t) {
  shape_t sh;
  memset(&sh, 0, sizeof sh);
  qk_tree_stats(t, &sh.s);
  return sh;
}

/* Balance and refine may stop half-way on QK_ERR_NOMEM (documented): the tree must be
 * valid, hold the same points, and freeing it must return every byte. */
static int refine_some(const qk_tree_t *t, qk_node_t leaf, qk_square_t sq, uint32_t depth,
                       void *ud) {
  size_t n = 0;
  (void)ud;
  qk_tree_leaf_points(t, leaf, NULL, NULL, NULL, &n);
  return depth < 7 && (n > 0 || sq.x < 0.25);
}

static void sweep_tree_change(int which) {
  qkt_rng_t r;
  qkt_rng_seed(&r, qkt_seed(61 + (uint64_t)which));
  enum { N = 300 };
  qk_point_t p[N];
  qkt_points(&r, QKT_CLUSTERED, p, N);
  qkt_alloc_t a;
  qk_allocator_t al = qkt_alloc_make(&a);
  qk_tree_options_t o = qkt_unit_options(2, &al);
  size_t failures = 0;
  for (size_t k = 1;; k++) {
    a.fail_at = 0;
    qk_tree_t *t = NULL;
    assert_int_equal(qk_tree_build(p, N, &o, &t), QK_OK);
    shape_t before = shape_of(t);
    a.calls = 0;
    a.fail_at = k;
    a.failed = 0;
    qk_status_t st = which ? qk_tree_refine(t, refine_some, NULL) : qk_tree_balance(t);
    int failed = a.failed;
    a.fail_at = 0;
    QKT_CHECK_TREE(t);
    assert_int_equal(shape_of(t).s.points, before.s.points);
    if (!failed || st == QK_OK) {
      assert_int_equal(st, QK_OK);
      if (!which) assert_true(qk_tree_is_balanced(t));
      qk_tree_free(t);
      assert_int_equal(a.live_blocks, 0);
      break;
    }
    assert_int_equal(st, QK_ERR_NOMEM);
    /* The tree is still usable: finishing the job now succeeds. */
    st = which ? qk_tree_refine(t, refine_some, NULL) : qk_tree_balance(t);
    assert_int_equal(st, QK_OK);
    QKT_CHECK_TREE(t);
    qk_tree_free(t);
    assert_int_equal(a.live_blocks, 0);
    assert_int_equal(a.live_bytes, 0);
    failures++;
  }
  print_message("%s: %zu failing allocations swept\n", which ? "refine" : "balance", failures);
  assert_true(failures >= 1);
}

static void test_reliability_alloc_balance(void **state) {
  (void)state;
  sweep_tree_change(0);
}

static void test_reliability_alloc_refine(void **state) {
  (void)state;
  sweep_tree_change(1);
}

static void test_reliability_alloc_collider(void **state) {
  (void)state;
  qkt_rng_t r;
  qkt_rng_seed(&r, qkt_seed(63));
  enum { ND = 120, NB = 80 };
  qk_disc_t d[ND], d0[ND];
  qk_box_t b[NB], b0[NB];
  for (int i = 0; i < ND; i++)
    d[i] = (qk_disc_t){qkt_rng_unit(&r), qkt_rng_unit(&r), 0.02 * qkt_rng_unit(&r)};
  for (int i = 0; i < NB; i++) {
    double x = qkt_rng_unit(&r), y = qkt_rng_unit(&r);
    b[i] = (qk_box_t){x, y, x + 0.03 * qkt_rng_unit(&r), y + 0.03 * qkt_rng_unit(&r)};
  }
  memcpy(d0, d, sizeof d);
  memcpy(b0, b, sizeof b);
  qkt_alloc_t a;
  qk_allocator_t al = qkt_alloc_make(&a);
  qk_tree_options_t o;
  qk_tree_options_init(&o);
  o.capacity = 4;
  o.allocator = &al;
  size_t failures = 0, pairs_ok = 0;
  for (size_t k = 1;; k++) {
    a.calls = 0;
    a.fail_at = k;
    a.failed = 0;
    qk_collider_t *c = (qk_collider_t *)&a;
    qk_status_t st = qk_collider_build(d, ND, b, NB, &o, &c);
    assert_memory_equal(d, d0, sizeof d);
    assert_memory_equal(b, b0, sizeof b);
    if (st == QK_OK) {
      a.fail_at = 0;
      /* The pair search makes no allocation at all; a ray cast none once the ray
       * structures are prepared (the first cast prepares them: its failing allocations
       * are swept in test_collide's test_collide_rays_lazy_nomem). */
      size_t calls = a.calls;
      assert_int_equal(qk_collider_pairs_list(c, NULL, 0, &pairs_ok), QK_OK);
      assert_int_equal(a.calls, calls);
      assert_int_equal(qk_collider_prepare_rays(c), QK_OK);
      calls = a.calls;
      qk_hit_t hit;
      assert_int_equal(qk_collider_raycast(c, (qk_point_t){0, 0.5}, (qk_point_t){1, 0}, 1, &hit),
                       QK_OK);
      assert_int_equal(a.calls, calls);
      qk_collider_free(c);
      break;
    }
    assert_true(a.failed);
    assert_int_equal(st, QK_ERR_NOMEM);
    assert_null(c);
    assert_int_equal(a.live_blocks, 0);
    failures++;
  }
  assert_int_equal(a.live_blocks, 0);
  assert_true(failures >= 3);
  assert_true(pairs_ok > 0);
}

static void test_reliability_alloc_geo(void **state) {
  (void)state;
  qkt_rng_t r;
  qkt_rng_seed(&r, qkt_seed(64));
  enum { N = 200 };
  qk_point_t p[N], p0[N];
  for (int i = 0; i < N; i++)
    p[i] = (qk_point_t){qkt_rng_range(&r, -180, 180), qkt_rng_range(&r, -90, 90)};
  memcpy(p0, p, sizeof p);
  qkt_alloc_t a;
  qk_allocator_t al = qkt_alloc_make(&a);
  qk_tree_options_t o;
  qk_tree_options_init(&o);
  o.allocator = &al;
  size_t failures = 0;
  for (size_t k = 1;; k++) {
    a.calls = 0;
    a.fail_at = k;
    a.failed = 0;
    qk_geo_t *g = (qk_geo_t *)&a;
    qk_status_t st = qk_geo_build(p, N, &o, &g);
    assert_memory_equal(p, p0, sizeof p);
#ifndef QK_HAVE_GEODESIC
    assert_int_equal(st, QK_ERR_UNSUPPORTED);
    assert_null(g);
    skip();
#endif
    if (st == QK_OK) {
      a.fail_at = 0;
      size_t calls = a.calls, n = 0;
      qk_neighbor_t nb[5];
      assert_int_equal(qk_geo_knn(g, (qk_point_t){2.35, 48.85}, 5, INFINITY, nb, &n), QK_OK);
      assert_int_equal(n, 5);
      assert_int_equal(a.calls, calls);
      qk_geo_free(g);
      break;
    }
    assert_true(a.failed);
    assert_int_equal(st, QK_ERR_NOMEM);
    assert_null(g);
    assert_int_equal(a.live_blocks, 0);
    failures++;
  }
  assert_int_equal(a.live_blocks, 0);
  assert_true(failures >= 2);
}

/* Single planar queries (and small batches) allocate nothing: a tree whose allocator
 * fails every call still answers them. */
static int count_found(qk_id_t id, qk_point_t p, double dist, void *ud) {
  (void)id, (void)p, (void)dist;
  ++*(size_t *)ud;
  return 0;
}

static void test_reliability_queries_do_not_allocate(void **state) {
  (void)state;
  qkt_rng_t r;
  qkt_rng_seed(&r, qkt_seed(65));
  enum { N = 2000 };
  static qk_point_t p[N];
  qkt_points(&r, QKT_UNIFORM, p, N);
  qkt_alloc_t a;
  qk_allocator_t al = qkt_alloc_make(&a);
  qk_tree_options_t o = qkt_unit_options(8, &al);
  qk_tree_t *t;
  assert_int_equal(qk_tree_build(p, N, &o, &t), QK_OK);
  a.calls = 0;
  a.fail_at = 1; /* any allocation from here on fails */
  size_t n = 0, found = 0;
  qk_neighbor_t nb[16];
  static qk_id_t ids[N];
  assert_int_equal(qk_query_knn(t, (qk_point_t){0.5, 0.5}, 16, INFINITY, nb, &n), QK_OK);
  assert_int_equal(n, 16);
  assert_int_equal(qk_query_range_ids(t, (qk_box_t){0.2, 0.2, 0.6, 0.7}, ids, N, &n), QK_OK);
  assert_true(n > 0);
  assert_int_equal(qk_query_radius(t, (qk_point_t){0.3, 0.3}, 0.2, count_found, &found), QK_OK);
  assert_true(found > 0);
  qk_location_t loc;
  assert_int_equal(qk_query_locate(t, (qk_point_t){0.1, 0.9}, &loc), QK_OK);
  size_t offsets[3];
  qk_point_t cs[2] = {{0.1, 0.1}, {0.9, 0.9}};
  static qk_neighbor_t out[N];
  assert_int_equal(qk_query_radius_batch(t, cs, 2, 0.1, out, N, offsets), QK_OK);
  assert_int_equal(a.calls, 0);
  assert_false(a.failed);
  a.fail_at = 0;
  qk_tree_free(t);
  assert_int_equal(a.live_blocks, 0);
}

/* Batches of 64 or more queries borrow a buffer to answer in Z-order; when that
 * allocation fails they answer in the given order instead, with the same results. */
static void test_reliability_batches_fall_back(void **state) {
  (void)state;
  qkt_rng_t r;
  qkt_rng_seed(&r, qkt_seed(67));
  enum { N = 3000, NQ = 200, K = 5 };
  static qk_point_t p[N], q[NQ];
  qkt_points(&r, QKT_CLUSTERED, p, N);
  qkt_points(&r, QKT_UNIFORM, q, NQ);
  qkt_alloc_t a;
  qk_allocator_t al = qkt_alloc_make(&a);
  qk_tree_options_t o = qkt_unit_options(8, &al);
  qk_tree_t *t;
  assert_int_equal(qk_tree_build(p, N, &o, &t), QK_OK);
  static qk_neighbor_t ref[NQ * K], got[NQ * K];
  static size_t ref_n[NQ], got_n[NQ];
  static qk_node_t ref_l[NQ], got_l[NQ];
  /* Reference: one query at a time (no allocation). */
  for (size_t i = 0; i < NQ; i++) {
    assert_int_equal(qk_query_knn(t, q[i], K, INFINITY, ref + i * K, &ref_n[i]), QK_OK);
    assert_int_equal(qk_tree_find_leaf(t, q[i], &ref_l[i]), QK_OK);
  }
  for (size_t fail = 0; fail <= 1; fail++) {
    a.calls = 0;
    a.fail_at = fail; /* 0: allocation works; 1: the first allocation fails */
    a.failed = 0;
    size_t blocks = a.live_blocks;
    assert_int_equal(qk_query_knn_batch(t, q, NQ, K, INFINITY, got, got_n), QK_OK);
    assert_int_equal(qk_query_locate_batch(t, q, NQ, got_l), QK_OK);
    assert_int_equal(a.live_blocks, blocks); /* whatever was borrowed was given back */
    for (size_t i = 0; i < NQ; i++) {
      assert_int_equal(got_n[i], ref_n[i]);
      for (size_t j = 0; j < got_n[i]; j++) {
        assert_int_equal(got[i * K + j].id, ref[i * K + j].id);
        assert_true(got[i * K + j].dist == ref[i * K + j].dist);
      }
      assert_int_equal(got_l[i], ref_l[i]);
    }
    if (fail) assert_true(a.failed);     /* the fallback path really ran */
    if (!fail) assert_true(a.calls > 0); /* and the Z-order path borrowed its buffer */
  }
  a.fail_at = 0;
  qk_tree_free(t);
  assert_int_equal(a.live_blocks, 0);
}

/* ---- the mesh pipeline --------------------------------------------------------------- */

static const char square_with_hole[] = "# a 4x4 square with a 2x2 hole, on [0,8]^2\n"
                                       "8 2 0 0\n"
                                       "1 2 2\n2 6 2\n3 6 6\n4 2 6\n"
                                       "5 3 3\n6 5 3\n7 5 5\n8 3 5\n"
                                       "8 0\n"
                                       "1 1 2\n2 2 3\n3 3 4\n4 4 1\n"
                                       "5 5 6\n6 6 7\n7 7 8\n8 8 5\n"
                                       "1\n1 4 4\n";

static qk_status_t read_poly_text(const char *text, const qk_allocator_t *al, qk_poly_t **out) {
  FILE *f = fmemopen((void *)text, strlen(text), "rb");
  assert_non_null(f);
  qk_mesh_error_t err;
  qk_status_t st = qk_poly_read(f, al, out, &err);
  fclose(f);
  if (st != QK_OK && st != QK_ERR_NOMEM) fail_msg("line %lu: %s", err.line, err.message);
  if (st == QK_ERR_NOMEM) assert_string_not_equal(err.message, "");
  return st;
}

static void test_reliability_alloc_poly_read(void **state) {
  (void)state;
  qkt_alloc_t a;
  qk_allocator_t al = qkt_alloc_make(&a);
  size_t failures = 0;
  for (size_t k = 1;; k++) {
    a.calls = 0;
    a.fail_at = k;
    a.failed = 0;
    qk_poly_t *p = (qk_poly_t *)&a;
    qk_status_t st = read_poly_text(square_with_hole, &al, &p);
    if (st == QK_OK) {
      size_t nv, ns, nh;
      qk_poly_counts(p, &nv, &ns, &nh);
      assert_int_equal(nv, 8);
      assert_int_equal(ns, 8);
      assert_int_equal(nh, 1);
      qk_poly_free(p);
      break;
    }
    assert_true(a.failed);
    assert_null(p);
    assert_int_equal(a.live_blocks, 0);
    failures++;
  }
  assert_int_equal(a.live_blocks, 0);
  assert_true(failures >= 2);
}

static void test_reliability_alloc_poly_arrays(void **state) {
  (void)state;
  double xy[8] = {1, 1, 3, 1, 3, 3, 1, 3}, xy0[8];
  uint32_t seg[8] = {0, 1, 1, 2, 2, 3, 3, 0}, seg0[8];
  double holes[2] = {2, 2}, holes0[2];
  memcpy(xy0, xy, sizeof xy), memcpy(seg0, seg, sizeof seg), memcpy(holes0, holes, sizeof holes);
  qkt_alloc_t a;
  qk_allocator_t al = qkt_alloc_make(&a);
  size_t failures = 0;
  for (size_t k = 1;; k++) {
    a.calls = 0;
    a.fail_at = k;
    a.failed = 0;
    qk_poly_t *p = (qk_poly_t *)&a;
    qk_status_t st = qk_poly_from_arrays(xy, 4, seg, 4, holes, 1, &al, &p, NULL);
    assert_memory_equal(xy, xy0, sizeof xy);
    assert_memory_equal(seg, seg0, sizeof seg);
    assert_memory_equal(holes, holes0, sizeof holes);
    if (st == QK_OK) {
      qk_poly_free(p);
      break;
    }
    assert_true(a.failed);
    assert_int_equal(st, QK_ERR_NOMEM);
    assert_null(p);
    assert_int_equal(a.live_blocks, 0);
    failures++;
  }
  assert_int_equal(a.live_blocks, 0);
  assert_true(failures >= 1);
}

static void test_reliability_alloc_mesh_generate(void **state) {
  (void)state;
  qk_poly_t *poly;
  assert_int_equal(read_poly_text(square_with_hole, NULL, &poly), QK_OK);
  qkt_alloc_t a;
  qk_allocator_t al = qkt_alloc_make(&a);
  qk_mesh_options_t mo;
  qk_mesh_options_init(&mo);
  mo.allocator = &al;
  /* The reference: the mesh made without failures. */
  qk_mesh_t *ref;
  qk_mesh_error_t err;
  assert_int_equal(qk_mesh_generate(poly, NULL, &ref, &err), QK_OK);
  size_t ref_nt, ref_nv;
  qk_mesh_triangles(ref, &ref_nt);
  qk_mesh_vertices(ref, &ref_nv);
  size_t failures = 0;
  for (size_t k = 1;; k++) {
    a.calls = 0;
    a.fail_at = k;
    a.failed = 0;
    qk_mesh_t *m = (qk_mesh_t *)&a;
    qk_status_t st = qk_mesh_generate(poly, &mo, &m, &err);
    if (st == QK_OK) {
      /* The input was left as it was: the mesh made now equals the reference. */
      size_t nt, nv;
      const uint32_t *tri = qk_mesh_triangles(m, &nt);
      const double *xy = qk_mesh_vertices(m, &nv);
      assert_int_equal(nt, ref_nt);
      assert_int_equal(nv, ref_nv);
      assert_memory_equal(tri, qk_mesh_triangles(ref, &nt), 3 * nt * sizeof *tri);
      assert_memory_equal(xy, qk_mesh_vertices(ref, &nv), 2 * nv * sizeof *xy);
      qk_mesh_free(m);
      break;
    }
    assert_true(a.failed);
    assert_int_equal(st, QK_ERR_NOMEM);
    assert_null(m);
    assert_string_not_equal(err.message, "");
    assert_int_equal(a.live_blocks, 0);
    failures++;
  }
  print_message("mesh_generate: %zu failing allocations swept\n", failures);
  assert_int_equal(a.live_blocks, 0);
  assert_true(failures >= 5);
  qk_mesh_free(ref);
  qk_poly_free(poly);
}

/* ---- writers on a full disk ---------------------------------------------------------- */

static void test_reliability_writers_full_disk(void **state) {
  (void)state;
  FILE *full = fopen("/dev/full", "w");
  if (!full) skip();
  qk_poly_t *poly;
  assert_int_equal(read_poly_text(square_with_hole, NULL, &poly), QK_OK);
  qk_mesh_t *m;
  assert_int_equal(qk_mesh_generate(poly, NULL, &m, NULL), QK_OK);
  /* Each writer writes more than a stdio buffer or flushes; either way the error must
   * surface. Unbuffered, so that every write reaches the device at once. */
  setvbuf(full, NULL, _IONBF, 0);
  assert_int_equal(qk_mesh_write_node(m, full, 1), QK_ERR_IO);
  clearerr(full);
  assert_int_equal(qk_mesh_write_ele(m, full, 1), QK_ERR_IO);
  clearerr(full);
  assert_int_equal(qk_mesh_write_msh(m, full), QK_ERR_IO);
  clearerr(full);
  assert_int_equal(qk_mesh_write_vtu(m, full), QK_ERR_IO);
  clearerr(full);
  assert_int_equal(qk_mesh_write_svg(m, full, 0), QK_ERR_IO);
  clearerr(full);
  assert_int_equal(qk_tree_write_svg(qk_mesh_tree(m), full, 0), QK_ERR_IO);
  fclose(full);
  /* Buffered as fopen leaves it: a small mesh fits in stdio's buffer, and the writers
   * returned QK_OK, the failure left to the caller's fclose. */
  for (int k = 0; k < 7; k++) {
    FILE *f = fopen("/dev/full", "w");
    assert_non_null(f);
    qk_status_t st = k == 0   ? qk_mesh_write_node(m, f, 1)
                     : k == 1 ? qk_mesh_write_ele(m, f, 1)
                     : k == 2 ? qk_mesh_write_poly(m, f, 1)
                     : k == 3 ? qk_mesh_write_msh(m, f)
                     : k == 4 ? qk_mesh_write_vtu(m, f)
                     : k == 5 ? qk_mesh_write_svg(m, f, 0)
                              : qk_tree_write_svg(qk_mesh_tree(m), f, 0);
    if (st != QK_ERR_IO) fail_msg("writer %d on a buffered /dev/full: status %d", k, (int)st);
    fclose(f);
  }
  qk_mesh_free(m);
  qk_poly_free(poly);
}

/* ---- NULL where a struct is filled -------------------------------------------------- */

/* The options initialisers and the statistics calls do nothing with a NULL output (and
 * stats of a NULL object are zeros), as qk_world_options_init, qk_mesh_options_init and
 * qk_tree_stats did: qk_tree_options_init, qk_region_options_init, qk_csv_options_init
 * and qk_region_stats dereferenced it (a crash). */
static void test_reliability_null_outputs(void **state) {
  (void)state;
  qk_tree_options_init(NULL);
  qk_region_options_init(NULL);
  qk_csv_options_init(NULL);
  qk_world_options_init(NULL);
  qk_mesh_options_init(NULL);
  qk_tree_stats(NULL, NULL);
  qk_region_stats_t rs;
  memset(&rs, 0xab, sizeof rs);
  qk_region_stats(NULL, &rs);
  assert_int_equal(rs.features, 0);
  assert_int_equal(rs.bytes, 0);
  const double xy[] = {0, 0, 1, 0, 1, 1, 0, 0};
  const size_t rings[] = {0, 4}, feats[] = {0, 1};
  qk_region_arrays_t arr = {xy, rings, 1, feats, 1};
  qk_region_options_t ro;
  qk_region_options_init(&ro);
  ro.planar = 1;
  qk_region_t *r = NULL;
  assert_int_equal(qk_region_from_arrays(&arr, &ro, &r, NULL), QK_OK);
  qk_region_stats(r, NULL);
  qk_region_stats(r, &rs);
  assert_int_equal(rs.features, 1);
  qk_region_free(r);
  /* a NULL tree is a bad argument, not a corrupt tree or a missing node */
  char msg[64];
  qk_node_info_t info;
  assert_int_equal(qk_tree_check(NULL, msg, sizeof msg), QK_ERR_INVALID);
  assert_int_equal(qk_tree_node_info(NULL, 0, &info), QK_ERR_INVALID);
}

/* ---- error records filled whole ------------------------------------------------------ */

/* common.h: a call that takes a qk_error_t fills it (item SIZE_MAX when there is none,
 * message "" on success). The mesh module set only line and message (column and item
 * kept the caller's bytes), and qk_world_move_batch left the record untouched on success
 * and on a NULL argument. */
static void expect_record(const qk_error_t *e, unsigned long line, unsigned long column,
                          size_t item, int has_message) {
  assert_int_equal(e->line, line);
  assert_int_equal(e->column, column);
  assert_int_equal(e->item, item);
  assert_int_equal(e->message[0] != '\0', has_message);
}

static void test_reliability_error_records(void **state) {
  (void)state;
  qk_error_t e;
  qk_poly_t *p = NULL;
  const double xy[] = {0, 0, 4, 0, 4, 4, 0, NAN};
  const uint32_t seg[] = {0, 1, 1, 2, 2, 3, 3, 9};
  memset(&e, 0xab, sizeof e);
  assert_int_equal(qk_poly_from_arrays(xy, 4, seg, 4, NULL, 0, NULL, &p, &e), QK_ERR_INVALID);
  expect_record(&e, 0, 0, 3, 1); /* vertex 3 */
  const double ok_xy[] = {0, 0, 4, 0, 4, 4, 0, 4};
  memset(&e, 0xab, sizeof e);
  assert_int_equal(qk_poly_from_arrays(ok_xy, 4, seg, 4, NULL, 0, NULL, &p, &e), QK_ERR_INVALID);
  expect_record(&e, 0, 0, 3, 1); /* segment 3 */
  const uint32_t ok_seg[] = {0, 1, 1, 2, 2, 3, 3, 0};
  memset(&e, 0xab, sizeof e);
  assert_int_equal(qk_poly_from_arrays(ok_xy, 4, ok_seg, 4, NULL, 0, NULL, &p, &e), QK_OK);
  expect_record(&e, 0, 0, SIZE_MAX, 0);
  qk_mesh_t *m = NULL;
  memset(&e, 0xab, sizeof e);
  assert_int_equal(qk_mesh_generate(p, NULL, &m, &e), QK_OK);
  expect_record(&e, 0, 0, SIZE_MAX, 0);
  qk_mesh_free(m);
  qk_mesh_options_t mo;
  qk_mesh_options_init(&mo);
  mo.min_angle_deg = 80; /* refused */
  memset(&e, 0xab, sizeof e);
  assert_int_not_equal(qk_mesh_generate(p, &mo, &m, &e), QK_OK);
  expect_record(&e, 0, 0, SIZE_MAX, 1);
  qk_poly_free(p);
  qk_world_t *w;
  assert_int_equal(qk_world_new(NULL, &w), QK_OK);
  qk_handle_t h;
  qk_shape_t sh = {QK_SHAPE_DISC, 0, 0, 1, 0};
  assert_int_equal(qk_world_add(w, &sh, 1, &h), QK_OK);
  memset(&e, 0xab, sizeof e);
  assert_int_equal(qk_world_move_batch(w, &h, &sh, 1, &e), QK_OK);
  expect_record(&e, 0, 0, SIZE_MAX, 0);
  memset(&e, 0xab, sizeof e);
  assert_int_equal(qk_world_move_batch(w, NULL, &sh, 1, &e), QK_ERR_INVALID);
  expect_record(&e, 0, 0, SIZE_MAX, 1);
  qk_handle_t stale = h + 1;
  memset(&e, 0xab, sizeof e);
  assert_int_equal(qk_world_move_batch(w, &stale, &sh, 1, &e), QK_ERR_NOT_FOUND);
  expect_record(&e, 0, 0, 0, 1);
  qk_world_free(w);
}

/* ---- limits -------------------------------------------------------------------------- */

static void test_reliability_limits(void **state) {
  (void)state;
  qkt_alloc_t a;
  qk_allocator_t al = qkt_alloc_make(&a);
  qk_tree_options_t o = qkt_unit_options(1, &al);
  qk_point_t one = {0.5, 0.5};
  qk_tree_t *t = (qk_tree_t *)&a;
  /* Counts past 32-bit ids are refused before the points are read or memory taken. */
  assert_int_equal(qk_tree_build(&one, (size_t)QK_MAX_POINTS + 1, &o, &t), QK_ERR_LIMIT);
  assert_null(t);
  qk_collider_t *c = (qk_collider_t *)&a;
  qk_disc_t disc = {0.5, 0.5, 0.1};
  assert_int_equal(qk_collider_build(&disc, (size_t)QK_MAX_POINTS + 1, NULL, 0, &o, &c),
                   QK_ERR_LIMIT);
  assert_null(c);
  assert_int_equal(a.calls, 0);
  assert_int_equal(a.live_blocks, 0);
  /* The id counter at its limit: the next insert is refused and changes nothing. The
   * private layout is used to get there without 2^32 inserts. */
  o.allocator = NULL;
  assert_int_equal(qk_tree_build(&one, 1, &o, &t), QK_OK);
  uint32_t saved = t->n_ids;
  t->n_ids = QK_MAX_POINTS;
  qk_id_t id = 7;
  assert_int_equal(qk_tree_insert(t, one, &id), QK_ERR_LIMIT);
  assert_int_equal(id, 7);
  t->n_ids = saved;
  QKT_CHECK_TREE(t);
  qk_tree_free(t);
  o.allocator = &al;
  /* Bad options are refused, not clamped. */
  o.max_depth = QK_MAX_DEPTH_LIMIT + 1;
  assert_int_equal(qk_tree_build(&one, 1, &o, &t), QK_ERR_INVALID);
  o.max_depth = 0;
  o.root.side = 0;
  assert_int_equal(qk_tree_build(&one, 1, &o, &t), QK_ERR_INVALID);
  o.root.side = NAN;
  qk_status_t st = qk_tree_build(&one, 1, &o, &t);
  assert_true(st == QK_ERR_INVALID || st == QK_ERR_NONFINITE);

  /* Mesh domain: 2^30 at most, a power of two. */
  qk_poly_t *poly;
  assert_int_equal(read_poly_text(square_with_hole, NULL, &poly), QK_OK);
  qk_mesh_options_t mo;
  qk_mesh_options_init(&mo);
  qk_mesh_t *m = (qk_mesh_t *)&a;
  qk_mesh_error_t err;
  mo.size = QK_MESH_MAX_SIZE * 2;
  assert_int_equal(qk_mesh_generate(poly, &mo, &m, &err), QK_ERR_INVALID);
  assert_null(m);
  assert_non_null(strstr(err.message, "power of two"));
  mo.size = 12;
  assert_int_equal(qk_mesh_generate(poly, &mo, &m, &err), QK_ERR_INVALID);
  mo.size = 4; /* the square reaches 6: outside [0,4]^2 */
  assert_int_equal(qk_mesh_generate(poly, &mo, &m, &err), QK_ERR_GEOMETRY);
  assert_true(err.line > 0);
  qk_poly_free(poly);
  /* A vertex beyond 2^30 is out of the book's domain (QK_MESH_AUTO hands such an input to
   * the general mode, which has no domain limit). */
  double xy[8] = {0, 0, 2147483648.0, 0, 2147483648.0, 2147483648.0, 0, 2147483648.0};
  uint32_t seg[8] = {0, 1, 1, 2, 2, 3, 3, 0};
  assert_int_equal(qk_poly_from_arrays(xy, 4, seg, 4, NULL, 0, NULL, &poly, NULL), QK_OK);
  mo.size = 0;
  mo.mode = QK_MESH_BOOK;
  st = qk_mesh_generate(poly, &mo, &m, &err);
  assert_true(st == QK_ERR_GEOMETRY || st == QK_ERR_LIMIT);
  assert_null(m);
  mo.mode = QK_MESH_AUTO;
  qk_poly_free(poly);
  /* The largest domain, U = 2^30, chosen automatically: a unit square in its far corner
   * and a diamond near the origin mesh exactly (checked by the independent checker). */
  {
    const double T = (double)QK_MESH_MAX_SIZE;
    double big[16] = {T - 1, T - 1, T, T - 1, T, T, T - 1, T, 4, 2, 6, 4, 4, 6, 2, 4};
    uint32_t bseg[16] = {0, 1, 1, 2, 2, 3, 3, 0, 4, 5, 5, 6, 6, 7, 7, 4};
    assert_int_equal(qk_poly_from_arrays(big, 8, bseg, 8, NULL, 0, NULL, &poly, NULL), QK_OK);
    mo.size = 0;
    qk_mesh_t *bm;
    assert_int_equal(qk_mesh_generate(poly, &mo, &bm, &err), QK_OK);
    qk_mesh_stats_t ms;
    qk_mesh_stats(bm, &ms);
    assert_true(ms.size == QK_MESH_MAX_SIZE);
    mc_input_t in = {big, 8, bseg, 8, NULL, 0, ms.size};
    mc_mesh_t mm;
    mm.xy = qk_mesh_vertices(bm, &mm.nv);
    mm.tri = qk_mesh_triangles(bm, &mm.nt);
    mm.comp = qk_mesh_triangle_components(bm, NULL);
    char msg[256];
    if (mc_check(&in, &mm, msg, sizeof msg)) fail_msg("mesh at U = 2^30: %s", msg);
    print_message("U = 2^30: %zu triangles, %zu leaves\n", mm.nt, ms.leaves);
    qk_mesh_free(bm);
    qk_poly_free(poly);
    /* One past it: a clear error naming the vertex, not an overflow (the book's mode
     * insisted on: QK_MESH_AUTO hands the input to the general mode). */
    big[2] = T + 1;
    assert_int_equal(qk_poly_from_arrays(big, 8, bseg, 8, NULL, 0, NULL, &poly, NULL), QK_OK);
    bm = (qk_mesh_t *)&a;
    mo.mode = QK_MESH_BOOK;
    st = qk_mesh_generate(poly, &mo, &bm, &err);
    mo.mode = QK_MESH_AUTO;
    assert_true(st == QK_ERR_GEOMETRY || st == QK_ERR_LIMIT);
    assert_null(bm);
    assert_non_null(strstr(err.message, "1073741825"));
    qk_poly_free(poly);
  }
  /* Absurd counts in a .poly header are refused before anything is allocated for them. */
  a.calls = 0;
  poly = (qk_poly_t *)&a;
  FILE *f = fmemopen((void *)"99999999999 2 0 0\n0 0 0\n", 24, "rb");
  assert_non_null(f);
  st = qk_poly_read(f, &al, &poly, &err);
  fclose(f);
  assert_true(st == QK_ERR_LIMIT || st == QK_ERR_PARSE);
  assert_null(poly);
  assert_true(err.line == 1);
  assert_int_equal(a.live_blocks, 0);
}

int main(void) {
  const struct CMUnitTest tests[] = {
      cmocka_unit_test(test_reliability_replay_tree_ops),
      cmocka_unit_test(test_reliability_replay_csv),
      cmocka_unit_test(test_reliability_replay_poly),
      cmocka_unit_test(test_reliability_replay_world),
      cmocka_unit_test(test_reliability_alloc_balance),
      cmocka_unit_test(test_reliability_alloc_refine),
      cmocka_unit_test(test_reliability_alloc_collider),
      cmocka_unit_test(test_reliability_alloc_geo),
      cmocka_unit_test(test_reliability_queries_do_not_allocate),
      cmocka_unit_test(test_reliability_batches_fall_back),
      cmocka_unit_test(test_reliability_alloc_poly_read),
      cmocka_unit_test(test_reliability_alloc_poly_arrays),
      cmocka_unit_test(test_reliability_alloc_mesh_generate),
      cmocka_unit_test(test_reliability_writers_full_disk),
      cmocka_unit_test(test_reliability_null_outputs),
      cmocka_unit_test(test_reliability_error_records),
      cmocka_unit_test(test_reliability_limits),
  };
  return cmocka_run_group_tests(tests, NULL, NULL);
}
