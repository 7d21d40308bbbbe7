/*
 * Test plan for the thread-safety contract (index.h, query.h, mesh.h): any number of
 * threads may call the read-only functions on one tree, collider, geodesic index or
 * mesh at the same time.
 *  - one tree, one collider, one geodesic index and one mesh are built up front, and the
 *    answers to a fixed list of queries computed on the main thread;
 *  - then several threads run the whole list at once, in different orders, many times,
 *    each comparing every answer with the precomputed one: kNN (single and batch), range,
 *    radius (single, list, batch), locate, find_leaf, leaf_of, neighbours, adjacent
 *    leaves, leaf points, stats, qk_tree_check, is_balanced, collider box/disc queries,
 *    pairs and ray casts, geodesic kNN and radius, and the mesh and tree writers into
 *    memory streams;
 *  - several threads mesh one .poly input at once, three times each, and get the same
 *    mesh; again with a general-mode input large enough for the mesher's arena, whose
 *    kept chunks (mesh.h, qk_mesh_trim) the threads then take and give back at once, one
 *    of them trimming the cache meanwhile;
 *  - the library's own threads (issue 11): a bulk build and the kNN, locate and radius
 *    batches with threads = 2 and 0 (every core) give exactly what one thread gives;
 *  - scripts/tsan.sh runs this test under ThreadSanitizer, which reports any data race
 *    (a hidden cache, a static buffer) even when the answers happen to come out right.
 */
#define _POSIX_C_SOURCE 200809L
#include <math.h>
#include <pthread.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "qk_test.h"

enum { NPTS = 20000, NQ = 64, KNN = 8, THREADS = 4, ROUNDS = 3 };

typedef struct shared {
  const qk_tree_t *tree;
  const qk_collider_t *col;
  const qk_geo_t *geo;
  const qk_mesh_t *mesh;
  qk_point_t q[NQ];
  /* Expected answers, computed single-threaded. */
  qk_neighbor_t knn[NQ][KNN];
  size_t range_n[NQ], radius_n[NQ], col_n[NQ], geo_n[NQ];
  qk_node_t leaf[NQ], nb[NQ][4];
  size_t pairs;
  qk_hit_t hit[NQ];
  qk_tree_stats_t stats;
  char *svg;
  size_t svg_len;
  char *msh;
  size_t msh_len;
} shared_t;

static shared_t S;

static int count_cb(qk_id_t id, qk_point_t p, double d, void *ud) {
  (void)id, (void)p, (void)d;
  ++*(size_t *)ud;
  return 0;
}

static int count_pairs(qk_id_t a, qk_id_t b, void *ud) {
  (void)a, (void)b;
  ++*(size_t *)ud;
  return 0;
}

static qk_box_t box_around(qk_point_t p) {
  return (qk_box_t){p.x - 0.05, p.y - 0.03, p.x + 0.04, p.y + 0.05};
}

static char *write_mem(int which, size_t *len) {
  char *buf = NULL;
  FILE *f = open_memstream(&buf, len);
  if (!f) return NULL;
  qk_status_t st = which == 0   ? qk_tree_write_svg(S.tree, f, 400)
                   : which == 1 ? qk_mesh_write_msh(S.mesh, f)
                                : QK_ERR_INVALID;
  fclose(f);
  if (st != QK_OK) {
    free(buf);
    return NULL;
  }
  return buf;
}

/* Answer query i; returns 0 when every answer matches, else a code naming the query. */
static int run_query(size_t i) {
  qk_point_t q = S.q[i];
  qk_neighbor_t nb[KNN];
  size_t n = 0;
  if (qk_query_knn(S.tree, q, KNN, INFINITY, nb, &n) != QK_OK || n != KNN) return 1;
  for (int k = 0; k < KNN; k++)
    if (nb[k].id != S.knn[i][k].id || nb[k].dist != S.knn[i][k].dist) return 2;
  size_t counts[1];
  if (qk_query_knn_batch(S.tree, &q, 1, KNN, INFINITY, nb, counts) != QK_OK || counts[0] != KNN ||
      nb[KNN - 1].id != S.knn[i][KNN - 1].id)
    return 3;
  if (qk_query_range_ids(S.tree, box_around(q), NULL, 0, &n) != QK_OK || n != S.range_n[i])
    return 4;
  size_t c = 0;
  if (qk_query_radius(S.tree, q, 0.02, count_cb, &c) != QK_OK || c != S.radius_n[i]) return 5;
  size_t off[2];
  /* With no room for results the batch reports only the sizes (and QK_OK, as every
   * buffer does). */
  if (qk_query_radius_batch(S.tree, &q, 1, 0.02, NULL, 0, off) != QK_OK || off[1] != S.radius_n[i])
    return 6;
  qk_location_t loc;
  if (qk_query_locate(S.tree, q, &loc) != QK_OK || loc.leaf != S.leaf[i]) return 7;
  qk_node_t leaf;
  if (qk_tree_find_leaf(S.tree, q, &leaf) != QK_OK || leaf != S.leaf[i]) return 8;
  for (int d = 0; d < 4; d++)
    if (qk_tree_neighbor(S.tree, leaf, (qk_dir_t)d) != S.nb[i][d]) return 9;
  qk_node_t adj[64];
  if (qk_tree_adjacent_leaves(S.tree, leaf, QK_NORTH, adj, 64, &n) != QK_OK) return 10;
  const qk_id_t *ids;
  if (qk_tree_leaf_points(S.tree, leaf, NULL, NULL, &ids, &n) != QK_OK) return 11;
  for (size_t k = 0; k < n; k++) {
    qk_node_t l2;
    if (qk_tree_leaf_of(S.tree, ids[k], &l2) != QK_OK || l2 != leaf) return 12;
  }
  c = 0;
  if (qk_collider_query_box(S.col, box_around(q), count_cb, &c) != QK_OK || c != S.col_n[i])
    return 13;
  qk_hit_t hit;
  if (qk_collider_raycast(S.col, q, (qk_point_t){0.3, 0.1}, 1, &hit) != QK_OK ||
      hit.id != S.hit[i].id || hit.t != S.hit[i].t)
    return 14;
  if (S.geo) {
    qk_point_t g = {q.x * 360 - 180, q.y * 170 - 85};
    if (qk_geo_knn(S.geo, g, KNN, INFINITY, nb, &n) != QK_OK || n != KNN) return 15;
    if (qk_geo_radius_list(S.geo, g, 200e3, NULL, 0, &n) != QK_OK || n != S.geo_n[i]) return 16;
  }
  if (i % 16 == 0) {
    qk_tree_stats_t st;
    qk_tree_stats(S.tree, &st);
    if (st.nodes != S.stats.nodes || st.memory_bytes != S.stats.memory_bytes) return 17;
    if (qk_tree_check(S.tree, NULL, 0) != QK_OK) return 18;
    c = 0;
    if (qk_collider_pairs(S.col, count_pairs, &c) != QK_OK || c != S.pairs) return 19;
    size_t len;
    char *svg = write_mem(0, &len);
    if (!svg || len != S.svg_len || memcmp(svg, S.svg, len)) return 20;
    free(svg);
    char *msh = write_mem(1, &len);
    if (!msh || len != S.msh_len || memcmp(msh, S.msh, len)) return 21;
    free(msh);
    if (!qk_tree_is_balanced(qk_mesh_tree(S.mesh))) return 22;
    /* Batches of 64 borrow a buffer from the tree's allocator (libc here) and answer
     * in Z-order: the same answers as one query at a time. */
    static _Thread_local qk_neighbor_t bn[NQ * KNN];
    static _Thread_local size_t bc[NQ];
    static _Thread_local qk_node_t bl[NQ];
    if (qk_query_knn_batch(S.tree, S.q, NQ, KNN, INFINITY, bn, bc) != QK_OK) return 23;
    if (qk_query_locate_batch(S.tree, S.q, NQ, bl) != QK_OK) return 24;
    for (size_t j = 0; j < NQ; j++) {
      if (bc[j] != KNN || bl[j] != S.leaf[j]) return 25;
      for (int k = 0; k < KNN; k++)
        if (bn[j * KNN + k].id != S.knn[j][k].id || bn[j * KNN + k].dist != S.knn[j][k].dist)
          return 26;
    }
  }
  return 0;
}

typedef struct worker {
  pthread_t th;
  unsigned id;
  int bad;      /* first failing query code, 0 if none */
  size_t where; /* and its index */
} worker_t;

static void *work(void *arg) {
  worker_t *w = arg;
  for (int r = 0; r < ROUNDS && !w->bad; r++)
    for (size_t k = 0; k < NQ && !w->bad; k++) {
      /* Each thread walks the queries in its own order, so that different queries
       * overlap in time. */
      size_t i = (k * (2 * w->id + 1) + w->id * 7) % NQ;
      int rc = run_query(i);
      if (rc) w->bad = rc, w->where = i;
    }
  return NULL;
}

static void test_reliab_threads_concurrent_readers(void **state) {
  (void)state;
  qkt_rng_t r;
  qkt_rng_seed(&r, qkt_seed(66));
  static qk_point_t pts[NPTS];
  qkt_points(&r, QKT_CLUSTERED, pts, NPTS / 2);
  qkt_points(&r, QKT_UNIFORM, pts + NPTS / 2, NPTS / 2);
  qk_tree_options_t o;
  qk_tree_options_init(&o);
  o.capacity = 8;
  qk_tree_t *tree;
  assert_int_equal(qk_tree_build(pts, NPTS, &o, &tree), QK_OK);
  S.tree = tree;
  enum { ND = 3000 };
  static qk_disc_t discs[ND];
  for (int i = 0; i < ND; i++)
    discs[i] = (qk_disc_t){pts[i * 6].x, pts[i * 6].y, 0.004 * qkt_rng_unit(&r)};
  qk_collider_t *col;
  assert_int_equal(qk_collider_build(discs, ND, NULL, 0, NULL, &col), QK_OK);
  S.col = col;
  static qk_point_t ll[NPTS];
  for (int i = 0; i < NPTS; i++) ll[i] = (qk_point_t){pts[i].x * 360 - 180, pts[i].y * 170 - 85};
  qk_geo_t *geo = NULL;
  qk_status_t gs = qk_geo_build(ll, NPTS, NULL, &geo);
  assert_true(gs == QK_OK || gs == QK_ERR_UNSUPPORTED);
  S.geo = geo;
  const char *poly_text = "4 2 0 0\n1 3 3\n2 11 3\n3 11 7\n4 3 7\n4 0\n1 1 2\n2 2 3\n3 3 4\n"
                          "4 4 1\n0\n";
  FILE *f = fmemopen((void *)poly_text, strlen(poly_text), "rb");
  assert_non_null(f);
  qk_poly_t *poly;
  assert_int_equal(qk_poly_read(f, NULL, &poly, NULL), QK_OK);
  fclose(f);
  qk_mesh_t *mesh;
  assert_int_equal(qk_mesh_generate(poly, NULL, &mesh, NULL), QK_OK);
  S.mesh = mesh;

  for (size_t i = 0; i < NQ; i++) {
    S.q[i] = (qk_point_t){qkt_rng_unit(&r), qkt_rng_unit(&r)};
    qk_point_t q = S.q[i];
    size_t n;
    assert_int_equal(qk_query_knn(tree, q, KNN, INFINITY, S.knn[i], &n), QK_OK);
    assert_int_equal(n, KNN);
    assert_int_equal(qk_query_range_ids(tree, box_around(q), NULL, 0, &S.range_n[i]), QK_OK);
    assert_int_equal(qk_query_radius(tree, q, 0.02, count_cb, &S.radius_n[i]), QK_OK);
    assert_int_equal(qk_tree_find_leaf(tree, q, &S.leaf[i]), QK_OK);
    for (int d = 0; d < 4; d++) S.nb[i][d] = qk_tree_neighbor(tree, S.leaf[i], (qk_dir_t)d);
    assert_int_equal(qk_collider_query_box(col, box_around(q), count_cb, &S.col_n[i]), QK_OK);
    assert_int_equal(qk_collider_raycast(col, q, (qk_point_t){0.3, 0.1}, 1, &S.hit[i]), QK_OK);
    if (geo)
      assert_int_equal(qk_geo_radius_list(geo, (qk_point_t){q.x * 360 - 180, q.y * 170 - 85}, 200e3,
                                          NULL, 0, &S.geo_n[i]),
                       QK_OK);
  }
  /* The first id lookup makes the tree's id map (once, see index.h); after it, read-only
   * calls leave memory and shape unchanged. */
  qk_node_t first_leaf;
  assert_int_equal(qk_tree_leaf_of(tree, 0, &first_leaf), QK_OK);
  qk_tree_stats(tree, &S.stats);
  assert_int_equal(qk_collider_pairs(col, count_pairs, &S.pairs), QK_OK);
  S.svg = write_mem(0, &S.svg_len);
  S.msh = write_mem(1, &S.msh_len);
  assert_non_null(S.svg);
  assert_non_null(S.msh);
  /* The single-threaded run agrees with itself (the oracle of the threaded run). */
  for (size_t i = 0; i < NQ; i++) assert_int_equal(run_query(i), 0);

  worker_t w[THREADS];
  for (unsigned t = 0; t < THREADS; t++) {
    w[t] = (worker_t){.id = t};
    assert_int_equal(pthread_create(&w[t].th, NULL, work, &w[t]), 0);
  }
  for (unsigned t = 0; t < THREADS; t++) assert_int_equal(pthread_join(w[t].th, NULL), 0);
  for (unsigned t = 0; t < THREADS; t++)
    if (w[t].bad)
      fail_msg("thread %u: query %zu gave a different answer (check %d)", t, w[t].where, w[t].bad);

  free(S.svg);
  free(S.msh);
  qk_mesh_free(mesh);
  qk_poly_free(poly);
  qk_geo_free(geo);
  qk_collider_free(col);
  qk_tree_free(tree);
}

/* Distinct trees are independent: each thread builds, changes and frees its own. */
static void *own_tree(void *arg) {
  unsigned seed = *(unsigned *)arg;
  qkt_rng_t r;
  qkt_rng_seed(&r, seed);
  qk_point_t p[500];
  qkt_points(&r, QKT_UNIFORM, p, 500);
  qk_tree_options_t o;
  qk_tree_options_init(&o);
  o.has_root = 1;
  o.root = (qk_square_t){0, 0, 1};
  qk_tree_t *t;
  if (qk_tree_build(p, 250, &o, &t) != QK_OK) return (void *)1;
  for (int i = 250; i < 500; i++)
    if (qk_tree_insert(t, p[i], NULL) != QK_OK) return (void *)1;
  for (qk_id_t i = 0; i < 500; i += 3)
    if (qk_tree_remove(t, i) != QK_OK) return (void *)1;
  if (qk_tree_balance(t) != QK_OK || qk_tree_check(t, NULL, 0) != QK_OK) return (void *)1;
  qk_tree_free(t);
  return NULL;
}

static void test_reliab_threads_independent_writers(void **state) {
  (void)state;
  pthread_t th[THREADS];
  unsigned seeds[THREADS];
  for (unsigned t = 0; t < THREADS; t++) {
    seeds[t] = 100 + t;
    assert_int_equal(pthread_create(&th[t], NULL, own_tree, &seeds[t]), 0);
  }
  for (unsigned t = 0; t < THREADS; t++) {
    void *rv;
    assert_int_equal(pthread_join(th[t], &rv), 0);
    assert_null(rv);
  }
}

/* Mesh generation only reads its input: several threads may mesh one qk_poly at once,
 * and each gets the same mesh. */
typedef struct gen_job {
  pthread_t th;
  const qk_poly_t *poly;
  size_t nt, nv;
  const qk_mesh_t *ref;
  const qk_mesh_options_t *opt;
  int bad;
} gen_job_t;

static void *gen_one(void *arg) {
  gen_job_t *j = arg;
  for (int round = 0; round < ROUNDS && !j->bad; round++) {
    qk_mesh_t *m;
    if (qk_mesh_generate(j->poly, j->opt, &m, NULL) != QK_OK) {
      j->bad = 1;
      return NULL;
    }
    size_t nt, nv, rt, rv;
    const uint32_t *tri = qk_mesh_triangles(m, &nt), *rtri = qk_mesh_triangles(j->ref, &rt);
    const double *xy = qk_mesh_vertices(m, &nv), *rxy = qk_mesh_vertices(j->ref, &rv);
    j->bad = nt != rt || nv != rv || memcmp(tri, rtri, 3 * nt * sizeof *tri) ||
             memcmp(xy, rxy, 2 * nv * sizeof *xy);
    qk_mesh_free(m);
    if (round == 1) qk_mesh_trim(); /* while the others take and give back chunks */
  }
  return NULL;
}

/* THREADS threads mesh poly ROUNDS times each with options o, each mesh compared with
 * one made first on this thread. */
static void generate_on_threads(const qk_poly_t *poly, const qk_mesh_options_t *o) {
  qk_mesh_t *ref;
  assert_int_equal(qk_mesh_generate(poly, o, &ref, NULL), QK_OK);
  gen_job_t jobs[THREADS];
  for (unsigned t = 0; t < THREADS; t++) {
    jobs[t] = (gen_job_t){.poly = poly, .ref = ref, .opt = o};
    assert_int_equal(pthread_create(&jobs[t].th, NULL, gen_one, &jobs[t]), 0);
  }
  for (unsigned t = 0; t < THREADS; t++) {
    assert_int_equal(pthread_join(jobs[t].th, NULL), 0);
    assert_int_equal(jobs[t].bad, 0);
  }
  qk_mesh_free(ref);
}

static void test_reliab_threads_generate_from_one_input(void **state) {
  (void)state;
  /* A square ring (with a hole point) and a diagonal strip on [0,32]^2. */
  const char *text = "12 2 0 0\n0 4 4\n1 20 4\n2 20 20\n3 4 20\n4 8 8\n5 16 8\n6 16 16\n"
                     "7 8 16\n8 22 2\n9 24 2\n10 30 8\n11 28 8\n12 0\n0 0 1\n1 1 2\n2 2 3\n"
                     "3 3 0\n4 4 5\n5 5 6\n6 6 7\n7 7 4\n8 8 9\n9 9 10\n10 10 11\n11 11 8\n"
                     "1\n0 12 12\n";
  FILE *f = fmemopen((void *)text, strlen(text), "rb");
  assert_non_null(f);
  qk_poly_t *poly;
  assert_int_equal(qk_poly_read(f, NULL, &poly, NULL), QK_OK);
  fclose(f);
  qk_mesh_options_t mo;
  qk_mesh_options_init(&mo);
  generate_on_threads(poly, &mo);
  qk_poly_free(poly);
  /* Large enough for the mesher's arena (blocks of 64 KB and more), whose chunks freed
   * meshes leave kept for the next: a 256-gon of radius 1 on the grid 2^-20 in the
   * general mode, edges at most 1/32 (some 20,000 triangles). */
  enum { K = 256 };
  double xy[2 * K];
  uint32_t seg[2 * K];
  for (uint32_t i = 0; i < K; i++) {
    double a = 2 * 3.14159265358979323846 * i / K;
    xy[2 * i] = nearbyint(ldexp(cos(a), 20)) * 0x1p-20;
    xy[2 * i + 1] = nearbyint(ldexp(sin(a), 20)) * 0x1p-20;
    seg[2 * i] = i, seg[2 * i + 1] = (i + 1) % K;
  }
  assert_int_equal(qk_poly_from_arrays(xy, K, seg, K, NULL, 0, NULL, &poly, NULL), QK_OK);
  mo.mode = QK_MESH_GENERAL;
  mo.max_size = 1.0 / 32;
  generate_on_threads(poly, &mo);
  qk_poly_free(poly);
}

/* Neighbour arrays equal field by field (their padding is unspecified). */
static void assert_same_nb(const qk_neighbor_t *a, const qk_neighbor_t *b, size_t n) {
  for (size_t i = 0; i < n; i++) {
    if (a[i].id != b[i].id || !(a[i].dist == b[i].dist || (isinf(a[i].dist) && isinf(b[i].dist))))
      fail_msg("entry %zu: (%u, %.17g) != (%u, %.17g)", i, a[i].id, a[i].dist, b[i].id, b[i].dist);
  }
}

/* Two trees over the same points hold the same leaves, points in the same slots. */
static void assert_same_tree(const qk_tree_t *a, const qk_tree_t *b) {
  size_t na, nb;
  assert_int_equal(qk_tree_leaves(a, NULL, 0, &na), QK_OK);
  assert_int_equal(qk_tree_leaves(b, NULL, 0, &nb), QK_OK);
  assert_int_equal(na, nb);
  qk_node_t *la = malloc(na * sizeof *la), *lb = malloc(nb * sizeof *lb);
  qk_tree_leaves(a, la, na, &na);
  qk_tree_leaves(b, lb, nb, &nb);
  for (size_t i = 0; i < na; i++) {
    assert_int_equal(la[i], lb[i]);
    const double *xa, *ya, *xb, *yb;
    const qk_id_t *ia, *ib;
    size_t ca, cb;
    qk_tree_leaf_points(a, la[i], &xa, &ya, &ia, &ca);
    qk_tree_leaf_points(b, lb[i], &xb, &yb, &ib, &cb);
    assert_int_equal(ca, cb);
    assert_memory_equal(ia, ib, ca * sizeof *ia);
  }
  free(la);
  free(lb);
}

static void test_reliab_threads_library_threads(void **state) {
  (void)state;
  qkt_rng_t r;
  qkt_rng_seed(&r, qkt_seed(11));
  enum { N = 140000, Q = 1200, K = 5 }; /* 2^16 points per build thread at least */
  qk_point_t *p = malloc(N * sizeof *p), *qs = malloc(Q * sizeof *qs);
  qkt_points(&r, QKT_CLUSTERED, p, N);
  for (int i = 0; i < Q; i++) qs[i] = (qk_point_t){qkt_rng_unit(&r), qkt_rng_unit(&r)};
  qs[Q - 5].x = NAN; /* a failed query in the last share */
  qk_tree_options_t o;
  qk_tree_options_init(&o);
  o.capacity = 16;
  qk_tree_t *t1, *t2;
  assert_int_equal(qk_tree_build(p, N, &o, &t1), QK_OK);
  o.threads = 2;
  assert_int_equal(qk_tree_build(p, N, &o, &t2), QK_OK);
  QKT_CHECK_TREE(t2);
  assert_same_tree(t1, t2);
  qk_neighbor_t *k1 = malloc(Q * K * sizeof *k1), *k2 = malloc(Q * K * sizeof *k2);
  size_t *c1 = malloc(Q * sizeof *c1), *c2 = malloc(Q * sizeof *c2);
  qk_node_t *l1 = malloc(Q * sizeof *l1), *l2 = malloc(Q * sizeof *l2);
  assert_int_equal(qk_query_knn_batch(t1, qs, Q, K, INFINITY, k1, c1), QK_ERR_NONFINITE);
  assert_int_equal(qk_query_locate_batch(t1, qs, Q, l1), QK_OK);
  size_t cap = 60 * Q, n1, n2;
  qk_neighbor_t *r1 = malloc(cap * sizeof *r1), *r2 = malloc(cap * sizeof *r2);
  assert_int_equal(qk_query_radius_list_batch(t1, qs, Q, 0.01, r1, cap, c1, &n1), QK_ERR_NONFINITE);
  for (uint32_t threads = 0; threads <= 2; threads++) {
    qk_tree_set_threads(t2, threads);
    assert_int_equal(qk_query_knn_batch(t2, qs, Q, K, INFINITY, k2, c2), QK_ERR_NONFINITE);
    assert_same_nb(k1, k2, Q * K);
    assert_int_equal(qk_query_locate_batch(t2, qs, Q, l2), QK_OK);
    assert_memory_equal(l1, l2, Q * sizeof *l1);
    size_t *rc = malloc(Q * sizeof *rc);
    assert_int_equal(qk_query_radius_list_batch(t1, qs, Q, 0.01, r1, cap, rc, &n1),
                     QK_ERR_NONFINITE);
    size_t full = n1 < cap ? n1 : cap; /* what the buffer holds */
    /* A buffer too small for the later shares: QK_OK-style short buffer, same prefix. */
    size_t small = full / 3;
    assert_int_equal(qk_query_radius_list_batch(t2, qs, Q, 0.01, r2, small, c2, &n2),
                     QK_ERR_NONFINITE);
    assert_int_equal(n1, n2);
    assert_memory_equal(rc, c2, Q * sizeof *rc);
    assert_same_nb(r1, r2, small);
    assert_int_equal(qk_query_radius_list_batch(t2, qs, Q, 0.01, r2, cap, c2, &n2),
                     QK_ERR_NONFINITE);
    assert_same_nb(r1, r2, full);
    free(rc);
  }
  qk_tree_free(t1);
  qk_tree_free(t2);
  free(p), free(qs), free(k1), free(k2), free(c1), free(c2), free(l1), free(l2), free(r1), free(r2);
}

int main(void) {
  const struct CMUnitTest tests[] = {
      cmocka_unit_test(test_reliab_threads_concurrent_readers),
      cmocka_unit_test(test_reliab_threads_independent_writers),
      cmocka_unit_test(test_reliab_threads_generate_from_one_input),
      cmocka_unit_test(test_reliab_threads_library_threads),
  };
  return cmocka_run_group_tests(tests, NULL, NULL);
}
