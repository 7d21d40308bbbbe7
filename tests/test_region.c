/*
 * Test plan for region/ (polygon layers, point location). The oracle is a brute-force
 * crossing-parity test written here independently of the library: layers are built on
 * integer coordinates, the oracle decides with 128-bit integer orientations, and the
 * library sees the same geometry translated and scaled by exact powers of two (so its
 * floating-point filter meets non-trivial values near degeneracy).
 *  - random layers (self-intersecting rings, several rings per feature, many points on
 *    edges and vertices): locate, locate_all and the three boundary rules == oracle, with
 *    leaf capacities 1, 3 and the default; points on the build's one-pass grid lines and
 *    at its cells' centres == brute force;
 *  - coverages: grid cells and jittered quadrilateral cells sharing edges; points on
 *    shared edges and vertices belong to exactly one feature under semi-open;
 *  - closed and open rules on hand-made squares; reversed windings give the same answers;
 *  - holes and multipolygons; bow-tie rings (and the self-intersection count); the count
 *    on random layers, also with repeated positions and rings doubling back, == a brute
 *    force over each ring's pairs of edges of non-zero length; the review's hand-made rings;
 *  - lon/lat mode: an antimeridian-crossing square, a ring around the south pole,
 *    longitudes 180 / -180 / 540, latitudes beyond the poles, planar mode switching it off;
 *    slanted edges across the antimeridian, both ways == even-odd on the unwrapped rings;
 *    coverages across the antimeridian (two features sharing an edge, both ways round; a
 *    random triangulation, and the same away from it): every point in exactly one feature;
 *  - the SVG drawing: each ring one closed subpath, the even-odd area of each feature's
 *    path == its area, outlines without the pieces added along +-180 and the poles;
 *  - the refinement's decisions (answers cannot see them): on separated squares of 4
 *    edges with capacity 4, every leaf holds at most 4 edges;
 *  - batch == single, threaded batch == single; batches large enough for the Morton order
 *    (with vertices, far and non-finite points, failed scratch allocation) == single;
 *  - allocation failure at every N (arrays and GeoJSON): QK_ERR_NOMEM, nothing leaked;
 *    a build that succeeds despite a failure (a shrink) has the index of a clean build;
 *  - without keep_tree: the same index and answers as with the tree, allocation failures;
 *  - GeoJSON: Feature, bare geometry, skipped geometries, properties; errors with line
 *    and column, feature index and reason (lone surrogate escapes, coordinates nested at
 *    the wrong depth for their type);
 *  - real data (skipped when ../shared/data is absent): countries-50m with the
 *    Russia / Finland / Norway cities of issue 9 and famous cities.
 */
#define _XOPEN_SOURCE 700 /* mkstemp, fdopen */
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <unistd.h>

#include "qk_test.h"
/* test_region_grid_sides reads the descent's grid (internal) to aim at its cell sides. */
#include "region/region_internal.h"

#ifdef QK_HAVE_JSONC
/* The GeoJSON fuzz target, compiled in with its failures reported through cmocka; its
 * seed corpus is replayed below. */
#define QKF_REPLAY 1
#define QKF_FAIL(...) fail_msg(__VA_ARGS__)
#include "fuzz/fuzz_geojson.c"
#include <dirent.h>
#endif

/* ---- an integer layer and its oracle ------------------------------------------------ */

typedef struct tl {
  long *xy; /* integer coordinates */
  size_t nv, cap_v;
  size_t rs[512];
  size_t nr;
  size_t fs[256];
  size_t nf;
} tl_t;

static void tl_init(tl_t *t) {
  memset(t, 0, sizeof *t);
  t->cap_v = 4096;
  t->xy = malloc(2 * t->cap_v * sizeof(long));
}

static void tl_free(tl_t *t) { free(t->xy); }

static void tl_vertex(tl_t *t, long x, long y) {
  if (t->nv == t->cap_v) {
    t->cap_v *= 2;
    t->xy = realloc(t->xy, 2 * t->cap_v * sizeof(long));
  }
  t->xy[2 * t->nv] = x;
  t->xy[2 * t->nv + 1] = y;
  t->nv++;
}

/* Add a ring from n points (closed here). */
static void tl_ring(tl_t *t, const long *p, size_t n) {
  if (t->nr == 0) t->rs[0] = 0;
  for (size_t i = 0; i < n; i++) tl_vertex(t, p[2 * i], p[2 * i + 1]);
  tl_vertex(t, p[0], p[1]);
  t->rs[++t->nr] = t->nv;
}

static void tl_end_feature(tl_t *t) {
  if (t->nf == 0) t->fs[0] = 0;
  t->fs[++t->nf] = t->nr;
}

/* Exact: the tests' coordinates stay below 2^20, so the products fit in 64 bits. */
static int orient_i(long ax, long ay, long bx, long by, long cx, long cy) {
  long long d = (long long)(bx - ax) * (cy - ay) - (long long)(by - ay) * (cx - ax);
  return (d > 0) - (d < 0);
}

/* Independent oracle: half-open crossing parity (the point moved by (e, e^2)), plus an
 * exact on-edge test for the closed and open rules. */
static int oracle_in(const tl_t *t, size_t f, long px, long py, qk_boundary_t rule) {
  int par = 0, on = 0;
  for (size_t r = t->fs[f]; r < t->fs[f + 1]; r++)
    for (size_t v = t->rs[r]; v + 1 < t->rs[r + 1]; v++) {
      long ax = t->xy[2 * v], ay = t->xy[2 * v + 1], bx = t->xy[2 * v + 2], by = t->xy[2 * v + 3];
      if (ax == bx && ay == by) continue;
      int o = orient_i(ax, ay, bx, by, px, py);
      if ((ay > py) != (by > py) && ((by > ay) ? o > 0 : o < 0)) par ^= 1;
      if (o == 0 && px >= (ax < bx ? ax : bx) && px <= (ax < bx ? bx : ax) &&
          py >= (ay < by ? ay : by) && py <= (ay < by ? by : ay))
        on = 1;
    }
  if (rule == QK_BOUNDARY_SEMI_OPEN) return par;
  if (rule == QK_BOUNDARY_CLOSED) return par || on;
  return par && !on;
}

/* The library's view: x = OFF + ix * SCALE (exact for |ix| < 2^26). */
#define OFF 1048576.0
#define SCALE (1.0 / 128)

static int tl_keep_tree = 1; /* options.keep_tree for tl_build */

static qk_region_t *tl_build(const tl_t *t, uint32_t leaf_edges, const qk_allocator_t *alloc,
                             qk_status_t *st_out) {
  double *xy = malloc(2 * (t->nv + 1) * sizeof(double));
  for (size_t i = 0; i < 2 * t->nv; i++) xy[i] = OFF + (double)t->xy[i] * SCALE;
  qk_region_arrays_t a = {xy, t->rs, t->nr, t->fs, t->nf};
  qk_region_options_t o;
  qk_region_options_init(&o);
  o.planar = 1;
  o.leaf_edges = leaf_edges;
  o.allocator = alloc;
  o.keep_tree = tl_keep_tree;
  qk_region_t *r = NULL;
  qk_error_t err;
  qk_status_t st = qk_region_from_arrays(&a, &o, &r, &err);
  free(xy);
  if (st_out)
    *st_out = st;
  else if (st)
    fail_msg("build: %s: %s", qk_strerror(st), err.message);
  return r;
}

static qk_point_t tp(long x, long y) {
  return (qk_point_t){OFF + (double)x * SCALE, OFF + (double)y * SCALE};
}

/* Compare every query answer with the oracle at integer point (x, y). */
static void check_point(const qk_region_t *r, const tl_t *t, long x, long y, uint64_t seed) {
  for (int rule = 0; rule < 3; rule++) {
    uint32_t want = QK_NONE, got;
    uint32_t all[256];
    size_t nwant = 0, n;
    for (size_t f = 0; f < t->nf; f++)
      if (oracle_in(t, f, x, y, (qk_boundary_t)rule)) {
        if (want == QK_NONE) want = (uint32_t)f;
        all[nwant++] = (uint32_t)f;
      }
    assert_int_equal(qk_region_locate(r, tp(x, y), (qk_boundary_t)rule, &got), QK_OK);
    if (got != want)
      fail_msg("seed %llu rule %d point (%ld, %ld): locate %d, oracle %d", (unsigned long long)seed,
               rule, x, y, (int)got, (int)want);
    uint32_t buf[256];
    assert_int_equal(qk_region_locate_all(r, tp(x, y), (qk_boundary_t)rule, buf, 256, &n), QK_OK);
    if (n != nwant)
      fail_msg("seed %llu rule %d point (%ld, %ld): locate_all %zu features, oracle %zu",
               (unsigned long long)seed, rule, x, y, n, nwant);
    for (size_t i = 0; i < n; i++) assert_int_equal(buf[i], all[i]);
    /* counting only (no room): the same count */
    assert_int_equal(qk_region_locate_all(r, tp(x, y), (qk_boundary_t)rule, NULL, 0, &n), QK_OK);
    if (n != nwant)
      fail_msg("seed %llu rule %d point (%ld, %ld): locate_all without room %zu, oracle %zu",
               (unsigned long long)seed, rule, x, y, n, nwant);
  }
}

/* ---- random layers ------------------------------------------------------------------- */

static void random_layer(qkt_rng_t *g, tl_t *t, size_t nf, long span) {
  tl_init(t);
  for (size_t f = 0; f < nf; f++) {
    size_t rings = 1 + qkt_rng_below(g, 3);
    for (size_t k = 0; k < rings; k++) {
      long p[2 * 12];
      size_t n = 3 + qkt_rng_below(g, 8);
      long cx = (long)qkt_rng_below(g, (uint32_t)span), cy = (long)qkt_rng_below(g, (uint32_t)span);
      long rad = 1 + (long)qkt_rng_below(g, (uint32_t)(span / 3));
      for (size_t i = 0; i < n; i++) {
        p[2 * i] = cx - rad + (long)qkt_rng_below(g, (uint32_t)(2 * rad + 1));
        p[2 * i + 1] = cy - rad + (long)qkt_rng_below(g, (uint32_t)(2 * rad + 1));
      }
      tl_ring(t, p, n);
    }
    tl_end_feature(t);
  }
}

static void test_region_random_vs_oracle(void **state) {
  (void)state;
  uint64_t seed = qkt_seed(9001);
  qkt_rng_t g;
  qkt_rng_seed(&g, seed);
  const uint32_t caps[3] = {1, 3, 0};
  for (int round = 0; round < 12; round++) {
    tl_t t;
    long span = round % 2 ? 24 : 200;
    random_layer(&g, &t, 1 + qkt_rng_below(&g, 12), span);
    qk_region_t *r = tl_build(&t, caps[round % 3], NULL, NULL);
    QKT_CHECK_TREE(qk_region_tree(r));
    /* vertices (exactly on edges), random lattice points, points outside */
    for (size_t v = 0; v < t.nv; v++) check_point(r, &t, t.xy[2 * v], t.xy[2 * v + 1], seed);
    for (int i = 0; i < 600; i++) {
      long x = -3 + (long)qkt_rng_below(&g, (uint32_t)span + 6);
      long y = -3 + (long)qkt_rng_below(&g, (uint32_t)span + 6);
      check_point(r, &t, x, y, seed);
    }
    /* midpoints of edges: scale the layer by 2 */
    qk_region_free(r);
    tl_t t2 = t;
    t2.xy = malloc(2 * t.nv * sizeof(long));
    for (size_t i = 0; i < 2 * t.nv; i++) t2.xy[i] = 2 * t.xy[i];
    r = tl_build(&t2, caps[round % 3], NULL, NULL);
    for (size_t v = 0; v + 1 < t2.nv; v++)
      check_point(r, &t2, (t2.xy[2 * v] + t2.xy[2 * v + 2]) / 2,
                  (t2.xy[2 * v + 1] + t2.xy[2 * v + 3]) / 2, seed);
    qk_region_free(r);
    free(t2.xy);
    tl_free(&t);
  }
}

/* Points exactly on, and one ulp either side of, the grid cells' sides and the cell
 * centres of the top levels, against a brute force over the layer's pieces (the half-open
 * ray with the library's exact predicate: this checks the descent and the grid, which
 * must send every point to the leaf the build assigned it to). */
static uint32_t brute_pieces(const qk_region_t *r, double x, double y) {
  int par = 0;
  for (size_t i = 0; i < r->n_segs; i++) {
    const qk__seg_t *g = &r->segs[i];
    if ((g->ay > y) != (g->by > y)) {
      int s = qk__side(g->ax, g->ay, g->bx, g->by, x, y);
      if ((g->by > g->ay) ? s > 0 : s < 0) par ^= 1;
    }
    if (i + 1 == r->n_segs || r->seg_tag[i + 1] >> 2 != r->seg_tag[i] >> 2) {
      if (par) return r->seg_tag[i] >> 2;
      par = 0;
    }
  }
  return QK_NONE;
}

static void test_region_grid_sides(void **state) {
  (void)state;
  uint64_t seed = qkt_seed(31337);
  qkt_rng_t g;
  qkt_rng_seed(&g, seed);
  for (int round = 0; round < 3; round++) {
    tl_t t;
    random_layer(&g, &t, 40, 5000);
    qk_region_t *r = tl_build(&t, round + 1, NULL, NULL);
    assert_true(r->grid_level >= 2);
    size_t n = (size_t)1 << r->grid_level;
    for (size_t k = 0; k < 3000; k++) {
      size_t i = qkt_rng_below(&g, (uint32_t)n), j = qkt_rng_below(&g, (uint32_t)n);
      double xs[3] = {r->gx[i], nextafter(r->gx[i], -INFINITY), nextafter(r->gx[i], INFINITY)};
      double ys[3] = {r->gy[j], nextafter(r->gy[j], -INFINITY), nextafter(r->gy[j], INFINITY)};
      for (int a = 0; a < 3; a++)
        for (int b = 0; b < 3; b++) {
          uint32_t f, want = brute_pieces(r, xs[a], ys[b]);
          qk_region_locate(r, (qk_point_t){xs[a], ys[b]}, QK_BOUNDARY_SEMI_OPEN, &f);
          if (f != want)
            fail_msg("seed %llu: (%.17g, %.17g): locate %d, brute force %d",
                     (unsigned long long)seed, xs[a], ys[b], (int)f, (int)want);
        }
    }
    qk_region_free(r);
    tl_free(&t);
  }
}

/* Points on the lines and at the centres of the build's one-pass grid (the level-k cells,
 * 4^k about the number of pieces; region/build_top.c), computed here as the refinement
 * computes cell sides, and just beside them: the answers equal brute force. Leaf
 * capacities 1 to 3 make cells split far below the grid. */
static void test_region_build_grid_lines(void **state) {
  (void)state;
  uint64_t seed = qkt_seed(4242);
  qkt_rng_t g;
  qkt_rng_seed(&g, seed);
  for (int round = 0; round < 3; round++) {
    tl_t t;
    random_layer(&g, &t, 30 + 20 * (size_t)round, 3000);
    qk_region_t *r = tl_build(&t, (uint32_t)round + 1, NULL, NULL);
    unsigned k = 0;
    while (k < 10 && ((size_t)1 << (2 * (k + 1))) <= r->n_segs) k++;
    assert_true(k >= 3);
    size_t n = (size_t)1 << k;
    double hk = r->rside;
    for (unsigned l = 0; l <= k; l++) hk *= 0.5;
    for (size_t q = 0; q < 2000; q++) {
      size_t i = qkt_rng_below(&g, (uint32_t)n), j = qkt_rng_below(&g, (uint32_t)n);
      double lx = r->rx, ly = r->ry, h = r->rside;
      for (unsigned l = 0; l < k; l++) {
        h *= 0.5;
        if (i >> (k - 1 - l) & 1) lx = lx + h;
        if (j >> (k - 1 - l) & 1) ly = ly + h;
      }
      double xs[4] = {lx, nextafter(lx, -INFINITY), nextafter(lx, INFINITY), lx + hk};
      double ys[4] = {ly, nextafter(ly, -INFINITY), nextafter(ly, INFINITY), ly + hk};
      for (int a = 0; a < 4; a++)
        for (int b = 0; b < 4; b++) {
          uint32_t f, want = brute_pieces(r, xs[a], ys[b]);
          qk_region_locate(r, (qk_point_t){xs[a], ys[b]}, QK_BOUNDARY_SEMI_OPEN, &f);
          if (f != want)
            fail_msg("seed %llu: (%.17g, %.17g): locate %d, brute force %d",
                     (unsigned long long)seed, xs[a], ys[b], (int)f, (int)want);
        }
    }
    for (size_t q = 0; q < 300; q++)
      check_point(r, &t, (long)qkt_rng_below(&g, 3200) - 100, (long)qkt_rng_below(&g, 3200) - 100,
                  seed);
    qk_region_free(r);
    tl_free(&t);
  }
}

/* ---- coverages ------------------------------------------------------------------------- */

static void exactly_one(const qk_region_t *r, long x, long y, uint64_t seed) {
  size_t n;
  assert_int_equal(qk_region_locate_all(r, tp(x, y), QK_BOUNDARY_SEMI_OPEN, NULL, 0, &n), QK_OK);
  if (n != 1)
    fail_msg("seed %llu: point (%ld, %ld) in %zu features", (unsigned long long)seed, x, y, n);
}

static void test_region_coverage_grid(void **state) {
  (void)state;
  tl_t t;
  tl_init(&t);
  const long n = 8, s = 4;
  for (long i = 0; i < n; i++)
    for (long j = 0; j < n; j++) {
      long p[8] = {i * s, j * s, (i + 1) * s, j * s, (i + 1) * s, (j + 1) * s, i * s, (j + 1) * s};
      tl_ring(&t, p, 4);
      tl_end_feature(&t);
    }
  for (uint32_t cap = 1; cap <= 8; cap *= 8) {
    qk_region_t *r = tl_build(&t, cap, NULL, NULL);
    for (long x = 0; x < n * s; x++)
      for (long y = 0; y < n * s; y++) {
        exactly_one(r, x, y, 0);
        check_point(r, &t, x, y, 0);
      }
    /* the outer top and right sides are outside after the perturbation, the others in */
    uint32_t f;
    qk_region_locate(r, tp(n * s, 3), QK_BOUNDARY_SEMI_OPEN, &f);
    assert_int_equal(f, QK_NONE);
    qk_region_locate(r, tp(n * s, 3), QK_BOUNDARY_CLOSED, &f);
    assert_int_equal(f, (uint32_t)(n - 1) * n);
    qk_region_free(r);
  }
  tl_free(&t);
}

static void test_region_coverage_jittered(void **state) {
  (void)state;
  uint64_t seed = qkt_seed(77);
  qkt_rng_t g;
  qkt_rng_seed(&g, seed);
  for (int round = 0; round < 4; round++) {
    enum { N = 7 };
    long vx[N + 1][N + 1], vy[N + 1][N + 1];
    for (int i = 0; i <= N; i++)
      for (int j = 0; j <= N; j++) {
        int border = i == 0 || j == 0 || i == N || j == N;
        vx[i][j] = 20 * i + (border ? 0 : (long)qkt_rng_below(&g, 13) - 6);
        vy[i][j] = 20 * j + (border ? 0 : (long)qkt_rng_below(&g, 13) - 6);
      }
    tl_t t;
    tl_init(&t);
    for (int i = 0; i < N; i++)
      for (int j = 0; j < N; j++) {
        long p[8] = {vx[i][j],         vy[i][j],         vx[i + 1][j], vy[i + 1][j],
                     vx[i + 1][j + 1], vy[i + 1][j + 1], vx[i][j + 1], vy[i][j + 1]};
        if (qkt_rng_below(&g, 2)) { /* either winding */
          long q[8] = {p[6], p[7], p[4], p[5], p[2], p[3], p[0], p[1]};
          memcpy(p, q, sizeof p);
        }
        tl_ring(&t, p, 4);
        tl_end_feature(&t);
      }
    qk_region_t *r = tl_build(&t, round % 2 ? 2 : 0, NULL, NULL);
    for (int i = 1; i < N; i++)
      for (int j = 1; j < N; j++) {
        exactly_one(r, vx[i][j], vy[i][j], seed); /* an inner vertex */
        check_point(r, &t, vx[i][j], vy[i][j], seed);
      }
    /* points on shared edges: lattice points of the segments */
    for (int i = 1; i < N; i++)
      for (int j = 0; j < N; j++) {
        long ax = vx[i][j], ay = vy[i][j], bx = vx[i][j + 1], by = vy[i][j + 1];
        for (int k = 1; k < 8; k++) {
          /* only lattice points exactly on the edge */
          long num_x = ax * (8 - k) + bx * k, num_y = ay * (8 - k) + by * k;
          if (num_x % 8 || num_y % 8) continue;
          exactly_one(r, num_x / 8, num_y / 8, seed);
        }
      }
    for (int i = 0; i < 2000; i++) {
      long x = 1 + (long)qkt_rng_below(&g, 20 * N - 2), y = 1 + (long)qkt_rng_below(&g, 20 * N - 2);
      exactly_one(r, x, y, seed);
    }
    qk_region_free(r);
    tl_free(&t);
  }
}

/* ---- boundary rules, windings, holes, bow-ties ------------------------------------------ */

static void test_region_rules_and_windings(void **state) {
  (void)state;
  tl_t t, u;
  tl_init(&t);
  tl_init(&u);
  long sq[8] = {0, 0, 10, 0, 10, 10, 0, 10};
  long rev[8] = {0, 10, 10, 10, 10, 0, 0, 0};
  long hole[8] = {3, 3, 7, 3, 7, 7, 3, 7};
  long holer[8] = {3, 7, 7, 7, 7, 3, 3, 3};
  long far[8] = {20, 0, 30, 0, 30, 10, 20, 10};
  tl_ring(&t, sq, 4), tl_ring(&t, hole, 4), tl_ring(&t, far, 4), tl_end_feature(&t);
  tl_ring(&u, rev, 4), tl_ring(&u, hole, 4), tl_ring(&u, far, 4), tl_end_feature(&u);
  (void)holer;
  qk_region_t *a = tl_build(&t, 0, NULL, NULL), *b = tl_build(&u, 0, NULL, NULL);
  for (long x = -2; x <= 32; x++)
    for (long y = -2; y <= 12; y++) {
      check_point(a, &t, x, y, 0);
      for (int rule = 0; rule < 3; rule++) {
        uint32_t fa, fb;
        qk_region_locate(a, tp(x, y), (qk_boundary_t)rule, &fa);
        qk_region_locate(b, tp(x, y), (qk_boundary_t)rule, &fb);
        assert_int_equal(fa, fb);
      }
    }
  uint32_t f;
  /* hole: (5,5) out, (1,1) in, (25,5) in (second part) */
  qk_region_locate(a, tp(5, 5), QK_BOUNDARY_SEMI_OPEN, &f), assert_int_equal(f, QK_NONE);
  qk_region_locate(a, tp(1, 1), QK_BOUNDARY_SEMI_OPEN, &f), assert_int_equal(f, 0);
  qk_region_locate(a, tp(25, 5), QK_BOUNDARY_SEMI_OPEN, &f), assert_int_equal(f, 0);
  /* boundary: left side (0, 5) in under semi-open, right side (10, 5) out; closed both in,
   * open both out; a hole's edge (3, 5) is boundary too */
  qk_region_locate(a, tp(0, 5), QK_BOUNDARY_SEMI_OPEN, &f), assert_int_equal(f, 0);
  qk_region_locate(a, tp(10, 5), QK_BOUNDARY_SEMI_OPEN, &f), assert_int_equal(f, QK_NONE);
  qk_region_locate(a, tp(10, 5), QK_BOUNDARY_CLOSED, &f), assert_int_equal(f, 0);
  qk_region_locate(a, tp(0, 5), QK_BOUNDARY_OPEN, &f), assert_int_equal(f, QK_NONE);
  qk_region_locate(a, tp(3, 5), QK_BOUNDARY_CLOSED, &f), assert_int_equal(f, 0);
  qk_region_locate(a, tp(0, 0), QK_BOUNDARY_CLOSED, &f), assert_int_equal(f, 0);
  qk_region_locate(a, tp(0, 0), QK_BOUNDARY_OPEN, &f), assert_int_equal(f, QK_NONE);
  qk_region_stats_t s;
  qk_region_stats(a, &s);
  assert_int_equal(s.features, 1);
  assert_int_equal(s.rings, 3);
  assert_int_equal(s.holes, 2);
  assert_int_equal(s.self_intersecting, 0);
  qk_region_free(a);
  qk_region_free(b);
  tl_free(&t);
  tl_free(&u);
}

static void test_region_bowtie(void **state) {
  (void)state;
  tl_t t;
  tl_init(&t);
  long bow[8] = {0, 0, 10, 10, 10, 0, 0, 10};
  tl_ring(&t, bow, 4), tl_end_feature(&t);
  qk_region_t *r = tl_build(&t, 0, NULL, NULL);
  for (long x = -1; x <= 11; x++)
    for (long y = -1; y <= 11; y++) check_point(r, &t, x, y, 0);
  uint32_t f;
  qk_region_locate(r, tp(8, 5), QK_BOUNDARY_SEMI_OPEN, &f), assert_int_equal(f, 0);
  qk_region_locate(r, tp(5, 8), QK_BOUNDARY_SEMI_OPEN, &f), assert_int_equal(f, QK_NONE);
  qk_region_stats_t s;
  qk_region_stats(r, &s);
  assert_int_equal(s.self_intersecting, 1);
  qk_region_free(r);
  tl_free(&t);
}

/* Do the closed segments a-b and c-d meet (exactly)? */
static int meet_i(const long *a, const long *b, const long *c, const long *d) {
  int o1 = orient_i(a[0], a[1], b[0], b[1], c[0], c[1]);
  int o2 = orient_i(a[0], a[1], b[0], b[1], d[0], d[1]);
  int o3 = orient_i(c[0], c[1], d[0], d[1], a[0], a[1]);
  int o4 = orient_i(c[0], c[1], d[0], d[1], b[0], b[1]);
  if (o1 * o2 > 0 || o3 * o4 > 0) return 0;
  if (o1 || o2 || o3 || o4) return 1;
  for (int k = 0; k < 2; k++) { /* collinear: do the extents overlap on both axes? */
    long lo1 = a[k] < b[k] ? a[k] : b[k], hi1 = a[k] < b[k] ? b[k] : a[k];
    long lo2 = c[k] < d[k] ? c[k] : d[k], hi2 = c[k] < d[k] ? d[k] : c[k];
    if ((lo1 > lo2 ? lo1 : lo2) > (hi1 < hi2 ? hi1 : hi2)) return 0;
  }
  return 1;
}

/* Do the closed segments a-b and c-d (a != b) lie on one line and overlap in more than a
 * point? */
static int overlap_i(const long *a, const long *b, const long *c, const long *d) {
  if (orient_i(a[0], a[1], b[0], b[1], c[0], c[1]) || orient_i(a[0], a[1], b[0], b[1], d[0], d[1]))
    return 0;
  int k = a[0] != b[0] ? 0 : 1; /* an axis along which the line runs */
  long lo1 = a[k] < b[k] ? a[k] : b[k], hi1 = a[k] < b[k] ? b[k] : a[k];
  long lo2 = c[k] < d[k] ? c[k] : d[k], hi2 = c[k] < d[k] ? d[k] : c[k];
  return (lo1 > lo2 ? lo1 : lo2) < (hi1 < hi2 ? hi1 : hi2);
}

/* The self-intersection count by brute force, by the docs' definition: a ring counts when
 * two of its edges meet away from a vertex they share. An edge of zero length is no edge,
 * so those are dropped first and the edges on either side of a repeated position are
 * neighbours (consecutive ones, and the last and the first). Neighbours share a vertex and
 * meet elsewhere only by overlapping: the ring doubling back (a spike, or a ring of one
 * edge there and back). */
static size_t oracle_self_intersecting(const tl_t *t) {
  size_t bad = 0;
  for (size_t r = 0; r < t->nr; r++) {
    size_t rs = t->rs[r], re = t->rs[r + 1], n = 0;
    size_t *e = malloc((re - rs) * sizeof *e); /* the ring's edges of non-zero length */
    for (size_t v = rs; v + 1 < re; v++) {
      const long *a = t->xy + 2 * v;
      if (a[0] != a[2] || a[1] != a[3]) e[n++] = v;
    }
    int hit = 0;
    for (size_t i = 0; i < n && !hit; i++)
      for (size_t j = i + 1; j < n && !hit; j++) {
        const long *a = t->xy + 2 * e[i], *c = t->xy + 2 * e[j];
        bool neighbours = j == i + 1 || (i == 0 && j == n - 1);
        hit = neighbours ? overlap_i(a, a + 2, c, c + 2) : meet_i(a, a + 2, c, c + 2);
      }
    bad += (size_t)hit;
    free(e);
  }
  return bad;
}

/* A random layer whose rings repeat positions (consecutively, also the first and the
 * closing one) and double back (spikes out and back, and back along part of an edge). */
static void degenerate_layer(qkt_rng_t *g, tl_t *t, size_t nf, long span) {
  tl_init(t);
  for (size_t f = 0; f < nf; f++) {
    for (size_t k = 0, rings = 1 + qkt_rng_below(g, 2); k < rings; k++) {
      long p[2 * 64];
      size_t m = 0, n = 3 + qkt_rng_below(g, 6);
      long cx = (long)qkt_rng_below(g, (uint32_t)span), cy = (long)qkt_rng_below(g, (uint32_t)span);
      long rad = 1 + (long)qkt_rng_below(g, (uint32_t)(span / 3));
      for (size_t i = 0; i < n; i++) {
        long x = cx - rad + (long)qkt_rng_below(g, (uint32_t)(2 * rad + 1));
        long y = cy - rad + (long)qkt_rng_below(g, (uint32_t)(2 * rad + 1));
        p[2 * m] = x, p[2 * m + 1] = y, m++;
        for (uint32_t rep = qkt_rng_below(g, 4); rep >= 2; rep--) /* repeated */
          p[2 * m] = x, p[2 * m + 1] = y, m++;
        uint32_t what = qkt_rng_below(g, 10);
        long dx = (long)qkt_rng_below(g, 5) - 2, dy = (long)qkt_rng_below(g, 5) - 2;
        if (what == 0) { /* out and back to (x, y) */
          p[2 * m] = x + 2 * dx, p[2 * m + 1] = y + 2 * dy, m++;
          p[2 * m] = x, p[2 * m + 1] = y, m++;
        } else if (what == 1) { /* out, and back half way */
          p[2 * m] = x + 2 * dx, p[2 * m + 1] = y + 2 * dy, m++;
          p[2 * m] = x + dx, p[2 * m + 1] = y + dy, m++;
        }
      }
      if (qkt_rng_below(g, 4) == 0) p[2 * m] = p[0], p[2 * m + 1] = p[1], m++; /* closing twice */
      tl_ring(t, p, m);
    }
    tl_end_feature(t);
  }
}

static void test_region_self_intersecting_oracle(void **state) {
  (void)state;
  uint64_t seed = qkt_seed(9107);
  qkt_rng_t g;
  qkt_rng_seed(&g, seed);
  const uint32_t caps[3] = {1, 3, 0};
  for (int round = 0; round < 48; round++) {
    tl_t t;
    long span = round % 2 ? 16 : 300;
    /* (rounds 24 on: rings with repeated positions and doubling back) */
    if (round < 24)
      random_layer(&g, &t, 1 + qkt_rng_below(&g, 12), span);
    else
      degenerate_layer(&g, &t, 1 + qkt_rng_below(&g, 12), span / 2);
    qk_region_t *r = tl_build(&t, caps[round % 3], NULL, NULL);
    qk_region_stats_t s;
    qk_region_stats(r, &s);
    size_t want = oracle_self_intersecting(&t);
    if (s.self_intersecting != want)
      fail_msg("seed %llu round %d: %zu self-intersecting rings, oracle %zu",
               (unsigned long long)seed, round, s.self_intersecting, want);
    qk_region_free(r);
    tl_free(&t);
  }
}

static qk_region_t *lonlat(const double *xy, const size_t *rs, size_t nr, const size_t *fs,
                           size_t nf, int planar);

/* The count on hand-made rings (the review's cases): a repeated position is no edge, so a
 * square with (1, 0) or its closing position repeated is simple (both were counted, the
 * edges around the repeat taken for non-neighbours meeting at their shared vertex); a
 * ring doubling back touches itself away from the shared vertex, a spike as a ring of one
 * edge there and back (A, B, A, A: it was not counted). Planar, and in lon/lat mode
 * across the antimeridian. */
static void test_region_self_intersecting_repeats(void **state) {
  (void)state;
  static const struct {
    long p[16];
    size_t n, want;
  } cases[] = {
      {{0, 0, 1, 0, 1, 0, 1, 1, 0, 1}, 5, 0},
      {{0, 0, 1, 0, 1, 1, 0, 1, 0, 0}, 5, 0},
      {{0, 0, 0, 0, 4, 0, 4, 0, 4, 4, 4, 4, 0, 4, 0, 4}, 8, 0},
      {{5, 0, 5, 0, 10, 0, 10, 10, 0, 0}, 5, 0},          /* straight on through the repeat */
      {{0, 0, 10, 0, 15, 0, 10, 0, 10, 10, 0, 10}, 6, 1}, /* a spike */
      {{0, 0, 10, 0, 0, 0}, 3, 1},                        /* A, B, A, A */
      {{0, 0, 10, 0, 10, 0, 0, 0}, 4, 1},
      {{0, 0, 10, 0, 5, 0, 5, 5}, 4, 1},          /* back along half the edge */
      {{5, 0, 5, 0, 10, 0, 10, 10, 8, 0}, 5, 1},  /* back at the ring's start */
      {{0, 0, 10, 0, 10, 10, 0, 10, 5, 0}, 5, 1}, /* a vertex on an edge */
  };
  for (size_t i = 0; i < sizeof cases / sizeof cases[0]; i++) {
    tl_t t;
    tl_init(&t);
    tl_ring(&t, cases[i].p, cases[i].n);
    tl_end_feature(&t);
    assert_int_equal(oracle_self_intersecting(&t), cases[i].want); /* (the oracle agrees) */
    qk_region_t *r = tl_build(&t, 0, NULL, NULL);
    qk_region_stats_t s;
    qk_region_stats(r, &s);
    if (s.self_intersecting != cases[i].want)
      fail_msg("case %zu: %zu self-intersecting rings, want %zu", i, s.self_intersecting,
               cases[i].want);
    qk_region_free(r);
    tl_free(&t);
  }
  /* lon/lat: a square across the antimeridian with a repeated position (0), an edge
   * across it there and back (1), the square with a spike back over it (1) */
  double xy[] = {170, -10, -170, -10, -170, -10, -170, 10, 170, 10, 170,  -10, /* 0 */
                 170, 0,   -170, 0,   170,  0,   170,  0,                      /* 1 */
                 170, -10, -170, -10, -170, 10,  -175, 10, 175, 10, -175, 10,  170, 10, 170, -10};
  size_t rs[] = {0, 6, 10, 18}, fs[] = {0, 1, 2, 3};
  const size_t want[3] = {0, 1, 1};
  for (size_t k = 0; k < 3; k++) {
    qk_region_t *r = lonlat(xy + 2 * rs[k], (size_t[]){0, rs[k + 1] - rs[k]}, 1, fs, 1, 0);
    qk_region_stats_t s;
    qk_region_stats(r, &s);
    if (s.self_intersecting != want[k])
      fail_msg("lon/lat ring %zu: %zu self-intersecting, want %zu", k, s.self_intersecting,
               want[k]);
    qk_region_free(r);
  }
}

/* ---- lon/lat mode ------------------------------------------------------------------------ */

static qk_region_t *lonlat(const double *xy, const size_t *rs, size_t nr, const size_t *fs,
                           size_t nf, int planar) {
  qk_region_arrays_t a = {xy, rs, nr, fs, nf};
  qk_region_options_t o;
  qk_region_options_init(&o);
  o.planar = planar;
  qk_region_t *r;
  qk_error_t e;
  qk_status_t st = qk_region_from_arrays(&a, &o, &r, &e);
  if (st) fail_msg("%s", e.message);
  return r;
}

static uint32_t at(const qk_region_t *r, double x, double y, qk_boundary_t b) {
  uint32_t f;
  qk_region_locate(r, (qk_point_t){x, y}, b, &f);
  return f;
}

static void test_region_lonlat(void **state) {
  (void)state;
  /* feature 0: a square across the antimeridian; feature 1: a ring around the south pole
   * (westward, as Natural Earth's); feature 2: an Arctic ring, eastward, cut at +-180
   * with vertices on both sides */
  double xy[] = {170, -10, -170, -10, -170, 10, 170, 10, 170, -10, -180, -80, 90,  -80, 0,    -80,
                 -90, -80, -180, -80, -180, 80, -90, 80, 0,   80,  90,   80,  180, 80,  -180, 80};
  size_t rs[] = {0, 5, 10, 16}, fs[] = {0, 1, 2, 3};
  qk_region_t *r = lonlat(xy, rs, 3, fs, 3, 0);
  assert_int_equal(at(r, 175, 0, 0), 0);
  assert_int_equal(at(r, -175, 0, 0), 0);
  assert_int_equal(at(r, 180, 0, 0), 0);
  assert_int_equal(at(r, -180, 5, 0), 0);
  assert_int_equal(at(r, 540, 0, 0), 0);  /* = 180 */
  assert_int_equal(at(r, -545, 0, 0), 0); /* = 175 */
  assert_int_equal(at(r, 0, 0, 0), QK_NONE);
  assert_int_equal(at(r, 160, 0, 0), QK_NONE);
  assert_int_equal(at(r, 0, -85, 0), 1);
  assert_int_equal(at(r, 123, -90, 0), 1);
  assert_int_equal(at(r, 123, -90, QK_BOUNDARY_CLOSED), 1);
  assert_int_equal(at(r, -45, -79, 0), QK_NONE);
  assert_int_equal(at(r, 0, 85, 0), 2);
  assert_int_equal(at(r, 179.5, 89, 0), 2);
  assert_int_equal(at(r, 0, 75, 0), QK_NONE);
  /* the poles lie inside the rings around them, under every rule (before, the north pole
   * was in no feature: the map's top line is the closure's edge) */
  for (int rule = 0; rule < 3; rule++)
    for (double x = -180; x <= 180; x += 45) {
      assert_int_equal(at(r, x, 90, (qk_boundary_t)rule), 2);
      assert_int_equal(at(r, x, -90, (qk_boundary_t)rule), 1);
    }
  assert_int_equal(at(r, 0, 91, 0), QK_NONE);
  assert_int_equal(at(r, 0, -91, 0), QK_NONE);
  /* the seam inside the square is not a boundary */
  assert_int_equal(at(r, -180, 0, QK_BOUNDARY_OPEN), 0);
  uint32_t f;
  assert_int_equal(qk_region_locate(r, (qk_point_t){NAN, 0}, 0, &f), QK_ERR_NONFINITE);
  assert_int_equal(f, QK_NONE);
  qk_region_free(r);
  /* planar mode: the first square is the band between 170 and -170 */
  r = lonlat(xy, rs, 1, fs, 1, 1);
  assert_int_equal(at(r, 0, 0, 0), 0);
  assert_int_equal(at(r, 175, 0, 0), QK_NONE);
  qk_region_free(r);
  /* out-of-range coordinates in lon/lat mode name the mode */
  double bad[] = {0, 0, 200, 0, 200, 10, 0, 0};
  size_t brs[] = {0, 4}, bfs[] = {0, 1};
  qk_region_arrays_t a = {bad, brs, 1, bfs, 1};
  qk_error_t e;
  assert_int_equal(qk_region_from_arrays(&a, NULL, &r, &e), QK_ERR_GEOMETRY);
  assert_null(r);
  assert_non_null(strstr(e.message, "planar"));
}

/* Rings with an edge from (-180, y) to (180, y): across the whole map (at the poles, or
 * where a step would double back on the antimeridian) or a zero-length step (Fiji).
 * Each feature is a latitude range (the island also a longitude range, Antarctica below
 * its coast's straight lon/lat edges), so the oracle is a comparison; random points lie
 * on no edge. Before the rule the whole world, the cap and the band held nothing. */
static void test_region_across_map(void **state) {
  (void)state;
  double xy[] = {
      /* 0: the whole world, a hole [0, 10] x [30, 40] */
      -180, -90, 180, -90, 180, 90, -180, 90, -180, -90, 0, 30, 10, 30, 10, 40, 0, 40, 0, 30,
      /* 1: north of 60 */
      -180, 60, 180, 60, 180, 90, -180, 90, -180, 60,
      /* 2: a band between -10 and 10, one side with a vertex in the middle */
      -180, -10, 180, -10, 180, 0, 180, 10, -180, 10, -180, -10,
      /* 3: south of -60: a ring along -60 closed by a step */
      -180, -60, -90, -60, 0, -60, 90, -60, 180, -60, -180, -60,
      /* 4: an island across the antimeridian with two steps */
      179, -17, 180, -17, -180, -17, -179, -17, -179, -16, -180, -16, 180, -16, 179, -16, 179, -17,
      /* 5: Antarctica as Natural Earth 10m draws it, along -90 from 180 to -180 */
      -180, -80, -90, -75, 0, -70, 90, -75, 180, -80, 180, -90, -180, -90, -180, -80};
  size_t rs[] = {0, 5, 10, 15, 21, 27, 36, 44}, fs[] = {0, 2, 3, 4, 5, 6, 7};
  qk_region_t *r = lonlat(xy, rs, 7, fs, 6, 0);
  uint64_t seed = 12345;
  for (int i = 0; i < 20000; i++) {
    seed = seed * 6364136223846793005u + 1442695040888963407u;
    double x = -180 + 360 * (double)(seed >> 11) * 0x1p-53;
    seed = seed * 6364136223846793005u + 1442695040888963407u;
    double y = -90 + 180 * (double)(seed >> 11) * 0x1p-53;
    if (i < 8) x = i % 2 ? 179.5 : -179.5, y = -16.5 + (i / 2) * 0.01; /* the island */
    double coast = x < -90  ? -80 + (x + 180) / 90 * 5
                   : x < 0  ? -75 + (x + 90) / 90 * 5
                   : x < 90 ? -70 - x / 90 * 5
                            : -75 - (x - 90) / 90 * 5;
    bool want[6] = {
        !(x > 0 && x < 10 && y > 30 && y < 40),      y > 60,   y > -10 && y < 10, y < -60,
        (x > 179 || x < -179) && y > -17 && y < -16, y < coast};
    uint32_t all[8];
    size_t n;
    assert_int_equal(qk_region_locate_all(r, (qk_point_t){x, y}, QK_BOUNDARY_SEMI_OPEN, all, 8, &n),
                     QK_OK);
    bool got[6] = {0};
    for (size_t k = 0; k < n; k++) got[all[k]] = 1;
    for (int f = 0; f < 6; f++)
      if (got[f] != want[f])
        fail_msg("(%.17g, %.17g) feature %d: got %d, want %d", x, y, f, got[f], want[f]);
  }
  /* The poles, at any longitude and under every rule, by single, all and batch calls: the
   * north one in the world and the cap, the south one in the world, the south cap and
   * Antarctica (each holds the area around it; the map's top and bottom lines are edges
   * of those rings, and the semi-open shift took the north pole off the map). */
  const uint32_t north[] = {0, 1}, south[] = {0, 3, 5};
  qk_point_t poles[18];
  /* (off the antimeridian: under `open` the whole world's sides along +-180 are its ring) */
  for (int k = 0; k < 18; k++) poles[k] = (qk_point_t){-170 + 40 * (k / 2), k % 2 ? -90 : 90};
  for (int rule = 0; rule < 3; rule++) {
    uint32_t one[18];
    assert_int_equal(qk_region_locate_batch(r, poles, 18, (qk_boundary_t)rule, 1, one), QK_OK);
    for (int k = 0; k < 18; k++) {
      const uint32_t *want = k % 2 ? south : north;
      size_t nw = k % 2 ? 3 : 2, n;
      uint32_t all[8];
      assert_int_equal(qk_region_locate_all(r, poles[k], (qk_boundary_t)rule, all, 8, &n), QK_OK);
      assert_int_equal(n, nw);
      for (size_t j = 0; j < n; j++) assert_int_equal(all[j], want[j]);
      assert_int_equal(at(r, poles[k].x, poles[k].y, (qk_boundary_t)rule), want[0]);
      assert_int_equal(one[k], want[0]);
    }
  }
  qk_region_free(r);
}

/* A point on the antimeridian is on the ring of a feature that ends at longitude 180
 * (east side) as well as of one that starts at -180 (west side): under `closed` both hold
 * it, under `open` neither (the sphere's answer); `semi-open` gives the west one alone.
 * Queries map 180 to -180, and the east feature's edges at 180 are in other leaves: before
 * the fix `closed` gave only the west feature. Checked for single, all and batch calls
 * (a batch of 5000 takes the sorted path). */
static void test_region_antimeridian_boundary(void **state) {
  (void)state;
  /* feature 0: [170, 180] x [0, 10]; feature 1: [-180, -170] x [0, 10]; feature 2:
   * [175, 180] x [20, 30], which only touches the antimeridian */
  double xy[] = {170, 0,    180, 0,    180, 10,  170, 10,  170, 0,   -180, 0,   -170, 0,   -170,
                 10,  -180, 10,  -180, 0,   175, 20,  180, 20,  180, 30,   175, 30,   175, 20};
  size_t rs[] = {0, 5, 10, 15}, fs[] = {0, 1, 2, 3};
  qk_region_t *r = lonlat(xy, rs, 3, fs, 3, 0);
  /* {x, y, semi-open, closed, open}, first feature */
  const double cases[][5] = {{180, 5, 1, 0, -1},   {-180, 5, 1, 0, -1},   {540, 5, 1, 0, -1},
                             {180, 0, 1, 0, -1},   {180, 10, -1, 0, -1},  {175, 5, 0, 0, 0},
                             {-175, 5, 1, 1, 1},   {180, 25, -1, 2, -1},  {-180, 25, -1, 2, -1},
                             {180, 30, -1, 2, -1}, {180, 31, -1, -1, -1}, {180, 15, -1, -1, -1}};
  size_t nc = sizeof cases / sizeof cases[0];
  for (size_t i = 0; i < nc; i++)
    for (int rule = 0; rule < 3; rule++) {
      uint32_t want = cases[i][2 + rule] < 0 ? QK_NONE : (uint32_t)cases[i][2 + rule];
      if (at(r, cases[i][0], cases[i][1], (qk_boundary_t)rule) != want)
        fail_msg("(%g, %g) rule %d: got %u, want %u", cases[i][0], cases[i][1], rule,
                 (unsigned)at(r, cases[i][0], cases[i][1], (qk_boundary_t)rule), (unsigned)want);
    }
  uint32_t all[4];
  size_t n;
  assert_int_equal(qk_region_locate_all(r, (qk_point_t){180, 5}, QK_BOUNDARY_CLOSED, all, 4, &n),
                   QK_OK);
  assert_int_equal(n, 2);
  assert_int_equal(all[0], 0);
  assert_int_equal(all[1], 1);
  assert_int_equal(qk_region_locate_all(r, (qk_point_t){-180, 0}, QK_BOUNDARY_OPEN, all, 4, &n),
                   QK_OK);
  assert_int_equal(n, 0);
  assert_int_equal(qk_region_locate_all(r, (qk_point_t){180, 5}, QK_BOUNDARY_SEMI_OPEN, all, 4, &n),
                   QK_OK);
  assert_int_equal(n, 1);
  assert_int_equal(all[0], 1);
  /* batches: the same answers as single calls, in both batch paths */
  size_t m = 5000;
  qk_point_t *p = malloc(m * sizeof *p);
  uint32_t *a = malloc(m * sizeof *a), *b = malloc(m * sizeof *b);
  for (size_t i = 0; i < m; i++)
    p[i] = (qk_point_t){i % 3 ? 180.0 : 170.0 + (double)(i % 7), (double)(i % 35)};
  for (int rule = 0; rule < 3; rule++) {
    for (size_t i = 0; i < m; i++) a[i] = at(r, p[i].x, p[i].y, (qk_boundary_t)rule);
    assert_int_equal(qk_region_locate_batch(r, p, m, (qk_boundary_t)rule, 1, b), QK_OK);
    assert_memory_equal(a, b, m * sizeof *a);
    assert_int_equal(qk_region_locate_batch(r, p, 100, (qk_boundary_t)rule, 1, b), QK_OK);
    assert_memory_equal(a, b, 100 * sizeof *a);
  }
  assert_int_equal(a[0], QK_NONE); /* (170, 0), the last rule open: a corner, in none */
  free(p), free(a), free(b);
  qk_region_free(r);
}

/* The same for a layer that reaches the antimeridian from one side only, whose root square
 * therefore ends short of the other side (nineteenth session): [170, 180] x [0, 10] alone
 * held no point (180, y) under `closed` (the query, mapped to (-180, y), fell outside the
 * root and was answered "none" before the antimeridian was looked at), and a layer of
 * enough pieces for a query grid must not descend the missing side. Single, all and both
 * batch paths; the mirror layer on [-180, -170] too. */
static void test_region_antimeridian_one_side(void **state) {
  (void)state;
  for (int west = 0; west < 2; west++)
    for (int fine = 0; fine < 2; fine++) {
      /* a rectangle [170, 180] x [0, 10] (or its mirror), its side along the meridian
       * split into 4096 edges when `fine` (a query grid) */
      size_t nv = fine ? 4096 + 5 : 6, k = 0;
      double *xy = malloc(2 * nv * sizeof *xy);
      double sg = west ? -1 : 1;
      xy[k++] = sg * 170, xy[k++] = 0;
      xy[k++] = sg * 180, xy[k++] = 0;
      for (size_t i = 1; i + 5 < nv; i++) xy[k++] = sg * 180, xy[k++] = 10.0 * (double)i / 4096;
      xy[k++] = sg * 180, xy[k++] = 10;
      xy[k++] = sg * 170, xy[k++] = 10;
      xy[k++] = sg * 170, xy[k++] = 0;
      assert_int_equal(k, 2 * nv - 2);
      nv--;
      size_t rs[] = {0, nv}, fs[] = {0, 1};
      qk_region_t *r = lonlat(xy, rs, 1, fs, 1, 0);
      /* {x, y, semi-open, closed, open} */
      const double cases[][5] = {{180, 5, west ? 0 : -1, 0, -1}, {-180, 5, west ? 0 : -1, 0, -1},
                                 {540, 0, west ? 0 : -1, 0, -1}, {-540, 10, -1, 0, -1},
                                 {180, 10.5, -1, -1, -1},        {sg * 175, 5, 0, 0, 0}};
      for (size_t i = 0; i < sizeof cases / sizeof cases[0]; i++)
        for (int rule = 0; rule < 3; rule++) {
          uint32_t want = cases[i][2 + rule] < 0 ? QK_NONE : (uint32_t)cases[i][2 + rule];
          uint32_t got = at(r, cases[i][0], cases[i][1], (qk_boundary_t)rule);
          if (got != want)
            fail_msg("west %d fine %d (%g, %g) rule %d: got %u, want %u", west, fine, cases[i][0],
                     cases[i][1], rule, (unsigned)got, (unsigned)want);
          uint32_t all[2];
          size_t n;
          assert_int_equal(qk_region_locate_all(r, (qk_point_t){cases[i][0], cases[i][1]},
                                                (qk_boundary_t)rule, all, 2, &n),
                           QK_OK);
          assert_int_equal(n, want != QK_NONE);
        }
      size_t m = 5000;
      qk_point_t *p = malloc(m * sizeof *p);
      uint32_t *b = malloc(m * sizeof *b);
      for (size_t i = 0; i < m; i++)
        p[i] = (qk_point_t){i % 2 ? 180.0 : sg * 175, (double)(i % 11)};
      assert_int_equal(qk_region_locate_batch(r, p, m, QK_BOUNDARY_CLOSED, 1, b), QK_OK);
      for (size_t i = 0; i < m; i++) assert_int_equal(b[i], 0);
      free(p), free(b), free(xy);
      qk_region_free(r);
    }
}

/* `open`: a zero-width spike ring up the meridian and back, (180, 0) -> (180, 8) -> (180,
 * 0), in a feature that holds both sides there (a triangle across the antimeridian): the
 * spike's two edges along +180 were taken for a -180/+180 pair (an even number: one
 * meridian, no boundary), and (180, 4) was inside under `open`, where the same shape at
 * longitude 0 puts (0, 4) on a ring, outside. Each edge along +180 must be matched by one
 * along -180. */
static void test_region_antimeridian_spike_open(void **state) {
  (void)state;
  for (int at0 = 0; at0 < 2; at0++) {
    const double c = at0 ? 0 : 180, w = at0 ? -10 : 170, e = at0 ? 10 : -170;
    const double xy[] = {w, 0, e, 0, c, 10, w, 0, c, 0, c, 8, c, 0, c, 0};
    size_t rs[] = {0, 4, 8}, fs[] = {0, 2};
    qk_region_t *r = lonlat(xy, rs, 2, fs, 1, 0);
    for (int rule = 0; rule < 3; rule++) {
      /* closed: on a ring, inside; open: on the spike, outside; semi-open: the point
       * moved by (e, e^2) lies in the triangle */
      uint32_t want = rule == QK_BOUNDARY_OPEN ? QK_NONE : 0;
      uint32_t got = at(r, c, 4, (qk_boundary_t)rule);
      if (got != want)
        fail_msg("spike at longitude %g, (%g, 4), rule %d: got %u, want %u", c, c, rule,
                 (unsigned)got, (unsigned)want);
    }
    /* (guard: beside the spike, inside under every rule) */
    for (int rule = 0; rule < 3; rule++) assert_int_equal(at(r, c, 9, (qk_boundary_t)rule), 0);
    qk_region_free(r);
  }
}

/* `open` on the antimeridian against an oracle that reads the sphere (seventeenth
 * session). Features are lon/lat rectangles on an integer grid: the whole world (with a
 * hole touching one side of the map or not), a band [-180, 180] x [y0, y1], and sets of
 * rectangles [-180, -170] or [170, 180] or both (an island split by the antimeridian)
 * over disjoint latitude ranges. A point (+-180, y) is inside a feature on the sphere when
 * the feature holds both sides of the meridian around it: a rectangle or band reaching
 * -180 and one reaching 180 hold latitudes strictly between their bounds, and no hole
 * touching the meridian holds y on its closed range. Before, the given sides along -180
 * and 180 (one meridian on the sphere) counted as boundary: the whole world, a band and a
 * split island held no point of the antimeridian under `open`. */
static void test_region_antimeridian_open_oracle(void **state) {
  (void)state;
  uint64_t seed = 20261202;
  for (int round = 0; round < 40; round++) {
    enum { NF = 6, MAXR = 8 };
    double xy[NF * MAXR * 10];
    size_t rs[NF * MAXR + 1], fs[NF + 1], nr = 0, nv = 0;
    /* per feature: latitude ranges of the parts reaching west (-180) and east (180),
     * holes touching the meridian */
    double wy[NF][MAXR][2], ey[NF][MAXR][2], hy[NF][2];
    int nw[NF] = {0}, ne[NF] = {0}, nh[NF] = {0};
#define RNG() (seed = seed * 6364136223846793005u + 1442695040888963407u, (unsigned)(seed >> 33))
#define RING(...)                                                                                  \
  do {                                                                                             \
    const double v_[] = {__VA_ARGS__};                                                             \
    rs[nr++] = nv / 2;                                                                             \
    for (size_t k_ = 0; k_ < sizeof v_ / sizeof v_[0]; k_++) xy[nv++] = v_[k_];                    \
  } while (0)
    for (int f = 0; f < NF; f++) {
      fs[f] = nr;
      unsigned kind = RNG() % 4;
      if (kind == 0) { /* the whole world, a hole maybe touching a side */
        RING(-180, -90, 180, -90, 180, 90, -180, 90, -180, -90);
        wy[f][0][0] = ey[f][0][0] = -90, wy[f][0][1] = ey[f][0][1] = 90, nw[f] = ne[f] = 1;
        double h0 = -80 + (double)(RNG() % 150), h1 = h0 + 1 + (double)(RNG() % 8);
        unsigned side = RNG() % 3; /* 0: west, 1: east, 2: inside, touching neither */
        double x0 = side == 0 ? -180 : side == 1 ? 170 : 0, x1 = x0 + 10;
        RING(x0, h0, x1, h0, x1, h1, x0, h1, x0, h0);
        if (side < 2) hy[f][0] = h0, hy[f][1] = h1, nh[f] = 1;
      } else if (kind == 1) { /* a band */
        double y0 = -80 + (double)(RNG() % 150), y1 = y0 + 1 + (double)(RNG() % 9);
        RING(-180, y0, 180, y0, 180, y1, -180, y1, -180, y0);
        wy[f][0][0] = ey[f][0][0] = y0, wy[f][0][1] = ey[f][0][1] = y1, nw[f] = ne[f] = 1;
      } else { /* rectangles on one side or both, over disjoint latitude ranges */
        double y = -85 + (double)(RNG() % 20);
        int parts = 1 + (int)(RNG() % 3);
        for (int k = 0; k < parts; k++) {
          double y0 = y, y1 = y0 + 1 + (double)(RNG() % 6);
          unsigned side = RNG() % 3; /* 0: west, 1: east, 2: both */
          if (side != 1) {
            RING(-180, y0, -170, y0, -170, y1, -180, y1, -180, y0);
            wy[f][nw[f]][0] = y0, wy[f][nw[f]++][1] = y1;
          }
          if (side != 0) {
            RING(170, y0, 180, y0, 180, y1, 170, y1, 170, y0);
            ey[f][ne[f]][0] = y0, ey[f][ne[f]++][1] = y1;
          }
          /* next part: just above (touching: a shared corner latitude) or further up */
          y = y1 + (double)(RNG() % 3) * 5;
        }
      }
    }
#undef RING
#undef RNG
    fs[NF] = nr;
    rs[nr] = nv / 2;
    qk_region_t *r = lonlat(xy, rs, nr, fs, NF, 0);
    qk_point_t q[4 * 717];
    size_t nq = 0;
    for (int i = -179 * 2; i <= 179 * 2; i++) /* every quarter degree but near the poles */
      for (int s = 0; s < 4; s++)
        q[nq++] = (qk_point_t){s == 0 ? 180 : s == 1 ? -180 : s == 2 ? 540 : -900, i * 0.25};
    uint32_t *batch = malloc(nq * sizeof *batch);
    assert_int_equal(qk_region_locate_batch(r, q, nq, QK_BOUNDARY_OPEN, 1, batch), QK_OK);
    for (size_t i = 0; i < nq; i++) {
      double y = q[i].y;
      uint32_t want = QK_NONE;
      bool in[NF];
      for (int f = NF - 1; f >= 0; f--) {
        bool w = false, e = false, h = false;
        for (int k = 0; k < nw[f]; k++) w |= wy[f][k][0] < y && y < wy[f][k][1];
        for (int k = 0; k < ne[f]; k++) e |= ey[f][k][0] < y && y < ey[f][k][1];
        for (int k = 0; k < nh[f]; k++) h |= hy[f][0] <= y && y <= hy[f][1];
        in[f] = w && e && !h;
        if (in[f]) want = (uint32_t)f;
      }
      uint32_t got = at(r, q[i].x, y, QK_BOUNDARY_OPEN);
      if (got != want || batch[i] != want)
        fail_msg("round %d: (%g, %g) open: got %u (batch %u), want %u", round, q[i].x, y,
                 (unsigned)got, (unsigned)batch[i], (unsigned)want);
      uint32_t all[NF];
      size_t n;
      assert_int_equal(qk_region_locate_all(r, q[i], QK_BOUNDARY_OPEN, all, NF, &n), QK_OK);
      size_t k = 0;
      for (int f = 0; f < NF; f++)
        if (in[f]) {
          if (k >= n || all[k] != (uint32_t)f)
            fail_msg("round %d: (%g, %g) open, all: feature %d missing", round, q[i].x, y, f);
          k++;
        }
      assert_int_equal(n, k);
    }
    free(batch);
    qk_region_free(r);
  }
}

/* ---- batch and threads ------------------------------------------------------------------- */

static void test_region_batch_threads(void **state) {
  (void)state;
  uint64_t seed = qkt_seed(4242);
  qkt_rng_t g;
  qkt_rng_seed(&g, seed);
  tl_t t;
  random_layer(&g, &t, 30, 1000);
  qk_region_t *r = tl_build(&t, 0, NULL, NULL);
  size_t n = 50000;
  qk_point_t *p = malloc(n * sizeof *p);
  uint32_t *a = malloc(n * sizeof *a), *b = malloc(n * sizeof *b), *c = malloc(n * sizeof *c);
  for (size_t i = 0; i < n; i++)
    p[i] = tp(-10 + (long)qkt_rng_below(&g, 1020), -10 + (long)qkt_rng_below(&g, 1020));
  p[7].x = NAN;
  for (int rule = 0; rule < 3; rule++) {
    for (size_t i = 0; i < n; i++) {
      qk_status_t st = qk_region_locate(r, p[i], (qk_boundary_t)rule, &a[i]);
      assert_int_equal(st, i == 7 ? QK_ERR_NONFINITE : QK_OK);
    }
    assert_int_equal(qk_region_locate_batch(r, p, n, (qk_boundary_t)rule, 1, b), QK_ERR_NONFINITE);
    assert_int_equal(qk_region_locate_batch(r, p, n, (qk_boundary_t)rule, 3, c), QK_ERR_NONFINITE);
    assert_memory_equal(a, b, n * sizeof *a);
    assert_memory_equal(a, c, n * sizeof *a);
    assert_int_equal(qk_region_locate_batch(r, p, n, (qk_boundary_t)rule, 0, c), QK_ERR_NONFINITE);
    assert_memory_equal(a, c, n * sizeof *a);
  }
  free(p), free(a), free(b), free(c);
  qk_region_free(r);
  tl_free(&t);
}

/* Batches large enough to be answered in Morton order (chunks of 2^18 points, sorted from
 * 2^15 up): answers in input order equal to single calls, with points on vertices and
 * edges, outside the layer, non-finite, and all in one cell; with 1 and 2 threads; and
 * when the sort's scratch cannot be allocated (then the batch runs in input order). */
static void test_region_batch_morton(void **state) {
  (void)state;
  uint64_t seed = qkt_seed(977);
  qkt_rng_t g;
  qkt_rng_seed(&g, seed);
  tl_t t;
  random_layer(&g, &t, 20, 1000);
  qkt_alloc_t as;
  qk_allocator_t al = qkt_alloc_make(&as);
  qk_region_t *r = tl_build(&t, 0, &al, NULL);
  size_t n = 300000; /* one full chunk and a sorted remainder of 37856 */
  qk_point_t *p = malloc(n * sizeof *p);
  uint32_t *a = malloc(n * sizeof *a), *b = malloc(n * sizeof *b);
  for (size_t i = 0; i < n; i++) {
    unsigned kind = (unsigned)qkt_rng_below(&g, 8);
    if (kind == 0) { /* a vertex of the layer */
      size_t v = (size_t)qkt_rng_below(&g, t.nv);
      p[i] = tp(t.xy[2 * v], t.xy[2 * v + 1]);
    } else if (kind == 1 && i > n / 2) { /* many points in one cell */
      p[i] = tp(500 + (long)qkt_rng_below(&g, 3), 500 + (long)qkt_rng_below(&g, 3));
    } else {
      p[i] = tp(-50 + (long)qkt_rng_below(&g, 1100), -50 + (long)qkt_rng_below(&g, 1100));
    }
  }
  p[3].x = NAN, p[n - 1].y = INFINITY, p[n / 2].x = -INFINITY, p[1000].y = 1e300;
  for (int rule = 0; rule < 3; rule++) {
    for (size_t i = 0; i < n; i++) qk_region_locate(r, p[i], (qk_boundary_t)rule, &a[i]);
    for (unsigned th = 1; th <= 2; th++) {
      memset(b, 0xab, n * sizeof *b);
      assert_int_equal(qk_region_locate_batch(r, p, n, (qk_boundary_t)rule, th, b),
                       QK_ERR_NONFINITE);
      for (size_t i = 0; i < n; i++)
        if (a[i] != b[i])
          fail_msg("seed %llu rule %d threads %u point %zu (%.17g, %.17g): batch %u, single %u",
                   (unsigned long long)seed, rule, th, i, p[i].x, p[i].y, b[i], a[i]);
    }
  }
  /* The scratch allocation fails: the same answers, in input order, nothing leaked. */
  size_t live = as.live_blocks;
  as.calls = 0;
  as.fail_at = 1;
  memset(b, 0xab, n * sizeof *b);
  assert_int_equal(qk_region_locate_batch(r, p, n, QK_BOUNDARY_SEMI_OPEN, 1, b), QK_ERR_NONFINITE);
  assert_true(as.failed);
  assert_int_equal(as.live_blocks, live);
  for (size_t i = 0; i < n; i++) qk_region_locate(r, p[i], QK_BOUNDARY_SEMI_OPEN, &a[i]);
  assert_memory_equal(a, b, n * sizeof *a);
  as.fail_at = 0;
  qk_region_free(r);
  assert_int_equal(as.live_blocks, 0);
  free(p), free(a), free(b);
  tl_free(&t);
}

/* Under every boundary rule: batch calls on one and two threads give the single calls'
 * answers a (b is scratch for n answers), and every stride-th point the brute force's under
 * the default rule. */
static void check_batch_single_brute(const qk_region_t *r, const qk_point_t *pt, size_t n,
                                     uint32_t *a, uint32_t *b, uint64_t seed, size_t stride) {
  for (int rule = 0; rule < 3; rule++) {
    for (size_t i = 0; i < n; i++) qk_region_locate(r, pt[i], (qk_boundary_t)rule, &a[i]);
    for (unsigned th = 1; th <= 2; th++) {
      memset(b, 0xab, n * sizeof *b);
      assert_int_equal(qk_region_locate_batch(r, pt, n, (qk_boundary_t)rule, th, b), QK_OK);
      for (size_t i = 0; i < n; i++)
        if (a[i] != b[i])
          fail_msg("seed %llu rule %d threads %u point %zu (%.17g, %.17g): batch %u, single %u",
                   (unsigned long long)seed, rule, th, i, pt[i].x, pt[i].y, b[i], a[i]);
    }
    if (rule == QK_BOUNDARY_SEMI_OPEN)
      for (size_t i = 0; i < n; i += stride)
        if (a[i] != brute_pieces(r, pt[i].x, pt[i].y))
          fail_msg("seed %llu point %zu (%.17g, %.17g): %u, brute force %u",
                   (unsigned long long)seed, i, pt[i].x, pt[i].y, a[i],
                   brute_pieces(r, pt[i].x, pt[i].y));
  }
}

/* Batches aimed at the cells' sides: points exactly on the sides met along random descents
 * (every depth, the grid's included) and one double either side, clustered around each
 * descent's leaf, so that in Morton order most points fall in the leaf box of the point
 * before (which skips the descent: locate.c) and many lie on its bounds. Batches with 1 and
 * 2 threads equal single calls under the three rules, and the semi-open answers of a
 * sample equal brute force over the pieces. */
static void test_region_batch_cell_sides(void **state) {
  (void)state;
  uint64_t seed = qkt_seed(4711);
  qkt_rng_t g;
  qkt_rng_seed(&g, seed);
  tl_t t;
  random_layer(&g, &t, 40, 5000);
  qk_region_t *r = tl_build(&t, 1, NULL, NULL);
  enum { PATHS = 64, MAXS = 3 * 64 };
  static double xs[PATHS][MAXS], ys[PATHS][MAXS];
  size_t ns[PATHS];
  for (int p = 0; p < PATHS; p++) {
    uint32_t k = r->kid[0];
    double sx = r->rx, sy = r->ry, h = r->rside;
    ns[p] = 0;
    while (!(k & QK__LEAF) && ns[p] + 3 <= MAXS) {
      h *= 0.5;
      double mx = sx + h, my = sy + h;
      double cx[3] = {mx, nextafter(mx, -INFINITY), nextafter(mx, INFINITY)};
      double cy[3] = {my, nextafter(my, -INFINITY), nextafter(my, INFINITY)};
      for (int a = 0; a < 3; a++) xs[p][ns[p]] = cx[a], ys[p][ns[p]++] = cy[a];
      unsigned q = (unsigned)qkt_rng_below(&g, 4); /* NE 0, NW 1, SW 2, SE 3 */
      if (q == 0 || q == 3) sx = mx;
      if (q <= 1) sy = my;
      k = r->kid[k + q];
    }
  }
  size_t n = 150000; /* three chunks of the sort */
  qk_point_t *pt = malloc(n * sizeof *pt);
  uint32_t *a = malloc(n * sizeof *a), *b = malloc(n * sizeof *b);
  for (size_t i = 0; i < n; i++) {
    size_t p = qkt_rng_below(&g, PATHS);
    /* mostly the deepest sides of the path, where the leaves are small */
    size_t lo = ns[p] > 12 ? ns[p] - 12 : 0, span = ns[p] - lo;
    size_t u = qkt_rng_below(&g, 4) ? lo + qkt_rng_below(&g, (uint32_t)span)
                                    : qkt_rng_below(&g, (uint32_t)ns[p]);
    size_t v = qkt_rng_below(&g, 4) ? lo + qkt_rng_below(&g, (uint32_t)span)
                                    : qkt_rng_below(&g, (uint32_t)ns[p]);
    pt[i] = (qk_point_t){xs[p][u], ys[p][v]};
  }
  check_batch_single_brute(r, pt, n, a, b, seed, 97);
  free(pt), free(a), free(b);
  qk_region_free(r);
  tl_free(&t);
}

/* The pure cells (locate.c): a batch point surely inside a cell that lies in direct leaves
 * of one answer takes it while its chunk is sorted. Points exactly on the pure cells' sides
 * (as the descent computes them), one and a few doubles either side, and random points in
 * the cells: batches with 1 and 2 threads equal single calls under the three rules, a
 * sample equals brute force, and every pure cell's answer is the single call's at its
 * centre. The leaf records' edge boxes (a point beside them reads no edge) are checked on
 * the same points. */
static void test_region_batch_pure_cells(void **state) {
  (void)state;
  uint64_t seed = qkt_seed(2718);
  qkt_rng_t g;
  qkt_rng_seed(&g, seed);
  tl_t t;
  qk_region_t *r;
  unsigned P;
  size_t cells;
  /* Layers drawn until one has a sixteenth of its cells pure or more (a few seeds' first
   * layers have 4-7%: crossing rings leave fewer cells inside one answer). */
  for (int tries = 0;; tries++) {
    random_layer(&g, &t, 12, 5000);
    /* coordinates that make the root square's side and its cells' sides not dyadic, so that
     * a point's cell coordinate is rounded */
    double *xy = malloc(2 * t.nv * sizeof *xy);
    for (size_t i = 0; i < 2 * t.nv; i++) xy[i] = -3.7 + (double)t.xy[i] * 0.0371;
    qk_region_arrays_t in = {xy, t.rs, t.nr, t.fs, t.nf};
    qk_region_options_t o;
    qk_region_options_init(&o);
    o.planar = 1;
    qk_error_t err;
    assert_int_equal(qk_region_from_arrays(&in, &o, &r, &err), QK_OK);
    free(xy);
    P = r->pure_level;
    assert_true(P >= 3 && P <= 8);
    cells = (size_t)1 << P;
    size_t pure = 0;
    for (size_t i = 0; i < cells * cells; i++) pure += r->pure[i] != 0;
    if (pure >= cells * cells / 16) break;
    if (tries == 20)
      fail_msg("seed %llu: %zu pure cells of %zu", (unsigned long long)seed, pure, cells * cells);
    qk_region_free(r);
    tl_free(&t);
  }
  size_t n_pure = 0;
  double *sx = malloc((cells + 1) * sizeof *sx), *sy = malloc((cells + 1) * sizeof *sy);
  qk__region_grid_sides(r->rx, r->rside, P, sx);
  qk__region_grid_sides(r->ry, r->rside, P, sy);
  sx[cells] = r->rx + r->rside, sy[cells] = r->ry + r->rside;
  for (size_t j = 0; j < cells; j++)
    for (size_t i = 0; i < cells; i++) {
      uint8_t v = r->pure[j << P | i];
      if (!v) continue;
      n_pure++;
      uint32_t want;
      qk_point_t c = {0.5 * (sx[i] + sx[i + 1]), 0.5 * (sy[j] + sy[j + 1])};
      assert_int_equal(qk_region_locate(r, c, QK_BOUNDARY_CLOSED, &want), QK_OK);
      if (want != r->pure_ans[v - 1])
        fail_msg("seed %llu pure cell (%zu, %zu): %u, single call %u", (unsigned long long)seed, i,
                 j, r->pure_ans[v - 1], want);
    }
  assert_true(n_pure >= cells * cells / 16);
  size_t n = 150000; /* three chunks of the sort */
  qk_point_t *pt = malloc(n * sizeof *pt);
  uint32_t *a = malloc(n * sizeof *a), *b = malloc(n * sizeof *b);
  for (size_t k = 0; k < n; k++) {
    size_t i = qkt_rng_below(&g, (uint32_t)cells), j = qkt_rng_below(&g, (uint32_t)cells);
    double x = sx[i], y = sy[j];
    int steps = (int)qkt_rng_below(&g, 9) - 4; /* on the side, or up to 4 doubles off */
    for (; steps < 0; steps++) x = nextafter(x, -INFINITY);
    for (; steps > 0; steps--) x = nextafter(x, INFINITY);
    steps = (int)qkt_rng_below(&g, 9) - 4;
    for (; steps < 0; steps++) y = nextafter(y, -INFINITY);
    for (; steps > 0; steps--) y = nextafter(y, INFINITY);
    if (qkt_rng_below(&g, 3) == 0) /* anywhere in the cell */
      x = sx[i] + (sx[i + 1] - sx[i]) * qkt_rng_unit(&g),
      y = sy[j] + (sy[j + 1] - sy[j]) * qkt_rng_unit(&g);
    pt[k] = (qk_point_t){x, y};
  }
  check_batch_single_brute(r, pt, n, a, b, seed, 61);
  free(pt), free(a), free(b), free(sx), free(sy);
  qk_region_free(r);
  tl_free(&t);
}

/* Without keep_tree the cells go straight into the query arrays: the same index (stats)
 * and the same answers as the refinement on a quadkit tree, for leaf capacities 1 and 8;
 * with every allocation failing in turn, QK_ERR_NOMEM and nothing leaked. */
static void test_region_without_tree(void **state) {
  (void)state;
  uint64_t seed = qkt_seed(31);
  qkt_rng_t g;
  qkt_rng_seed(&g, seed);
  tl_t t;
  random_layer(&g, &t, 25, 1000);
  size_t n = 20000;
  qk_point_t *p = malloc(n * sizeof *p);
  uint32_t *a = malloc(n * sizeof *a), *b = malloc(n * sizeof *b);
  for (size_t i = 0; i < n; i++)
    p[i] = tp(-10 + (long)qkt_rng_below(&g, 1020), -10 + (long)qkt_rng_below(&g, 1020));
  for (uint32_t cap = 1; cap <= 8; cap += 7) {
    tl_keep_tree = 1;
    qk_region_t *r1 = tl_build(&t, cap, NULL, NULL);
    tl_keep_tree = 0;
    qk_region_t *r0 = tl_build(&t, cap, NULL, NULL);
    assert_non_null(qk_region_tree(r1));
    assert_null(qk_region_tree(r0));
    qk_region_stats_t s0, s1;
    qk_region_stats(r0, &s0);
    qk_region_stats(r1, &s1);
    assert_int_equal(s0.leaves, s1.leaves);
    assert_int_equal(s0.leaf_edges, s1.leaf_edges);
    assert_int_equal(s0.depth, s1.depth);
    assert_true(s0.bytes < s1.bytes);
    for (int rule = 0; rule < 3; rule++) {
      assert_int_equal(qk_region_locate_batch(r1, p, n, (qk_boundary_t)rule, 1, a), QK_OK);
      assert_int_equal(qk_region_locate_batch(r0, p, n, (qk_boundary_t)rule, 1, b), QK_OK);
      for (size_t i = 0; i < n; i++)
        if (a[i] != b[i])
          fail_msg("seed %llu cap %u rule %d point %zu: without tree %u, with %u",
                   (unsigned long long)seed, cap, rule, i, b[i], a[i]);
    }
    qk_region_free(r0);
    qk_region_free(r1);
  }
  /* A build that succeeds although an allocation failed (only a shrink may fail so: it
   * keeps the block) makes the same index as one without failures; the mutation sweep
   * found a failed split turned into a leaf (a coarser index, answers unchanged) accepted
   * here. */
  qk_region_t *ref = tl_build(&t, 2, NULL, NULL);
  qk_region_stats_t sref;
  qk_region_stats(ref, &sref);
  qk_region_free(ref);
  for (size_t k = 1;; k++) {
    qkt_alloc_t as;
    qk_allocator_t al = qkt_alloc_make(&as); /* (it clears the counts) */
    as.fail_at = k;
    qk_status_t st;
    qk_region_t *r = tl_build(&t, 2, &al, &st);
    if (st == QK_OK) {
      qk_region_stats_t sr;
      qk_region_stats(r, &sr);
      assert_int_equal(sr.leaves, sref.leaves);
      assert_int_equal(sr.leaf_edges, sref.leaf_edges);
      assert_int_equal(sr.depth, sref.depth);
      qk_region_free(r);
      assert_int_equal(as.live_blocks, 0);
      if (!as.failed) break;
      continue;
    }
    assert_int_equal(st, QK_ERR_NOMEM);
    assert_null(r);
    assert_int_equal(as.live_blocks, 0);
    assert_true(k < 100000);
  }
  tl_keep_tree = 1;
  free(p), free(a), free(b);
  tl_free(&t);
}

/* ---- allocation failure -------------------------------------------------------------------- */

static void test_region_alloc_failure(void **state) {
  (void)state;
  qkt_rng_t g;
  qkt_rng_seed(&g, 5);
  tl_t t;
  random_layer(&g, &t, 6, 100);
  for (size_t n = 1;; n++) {
    qkt_alloc_t as;
    qk_allocator_t al = qkt_alloc_make(&as); /* (it clears the counts) */
    as.fail_at = n;
    qk_status_t st;
    qk_region_t *r = tl_build(&t, 2, &al, &st);
    if (st == QK_OK) { /* all succeeded, or only a shrink failed (it keeps the block) */
      check_point(r, &t, 50, 50, 5);
      qk_region_free(r);
      assert_int_equal(as.live_blocks, 0);
      if (!as.failed) break;
      continue;
    }
    assert_int_equal(st, QK_ERR_NOMEM);
    assert_null(r);
    assert_int_equal(as.live_blocks, 0);
    assert_int_equal(as.live_bytes, 0);
    assert_true(n < 100000);
  }
  tl_free(&t);
  const char *js = "{\"type\":\"FeatureCollection\",\"features\":[{\"type\":\"Feature\","
                   "\"properties\":{\"name\":\"a\",\"n\":3},\"geometry\":{\"type\":\"Polygon\","
                   "\"coordinates\":[[[0,0],[1,0],[1,1],[0,0]],[[0.1,0.05],[0.2,0.05],"
                   "[0.2,0.1],[0.1,0.05]]]}},{\"type\":\"Feature\",\"properties\":null,"
                   "\"geometry\":{\"type\":\"Point\",\"coordinates\":[0,0]}}]}";
  for (size_t n = 1;; n++) {
    qkt_alloc_t as;
    qk_allocator_t al = qkt_alloc_make(&as); /* (it clears the counts) */
    as.fail_at = n;
    qk_region_options_t o;
    qk_region_options_init(&o);
    o.allocator = &al;
    qk_region_t *r;
    qk_error_t e;
    qk_status_t st = qk_region_read_geojson_text(js, strlen(js), &o, &r, &e);
    if (st == QK_OK) { /* all succeeded, or only a shrink failed (it keeps the block) */
      assert_string_equal(qk_region_property(r, 0, "name"), "a");
      qk_region_free(r);
      assert_int_equal(as.live_blocks, 0);
      if (!as.failed) break;
      continue;
    }
    assert_int_equal(st, QK_ERR_NOMEM);
    assert_null(r);
    assert_int_equal(as.live_blocks, 0);
    assert_true(n < 100000);
  }
}

/* ---- GeoJSON ----------------------------------------------------------------------------------
 */

static qk_status_t gj(const char *text, qk_region_t **r, qk_error_t *e) {
  return qk_region_read_geojson_text(text, strlen(text), NULL, r, e);
}

static void test_region_geojson(void **state) {
  (void)state;
  qk_region_t *r;
  qk_error_t e;
  const char *fc =
      "{\"type\":\"FeatureCollection\",\"features\":[\n"
      "{\"type\":\"Feature\",\"properties\":{\"name\":\"A\",\"pop\":12,\"ok\":true,\"z\":null},"
      "\"geometry\":{\"type\":\"MultiPolygon\",\"coordinates\":[[[[0,0],[1,0],[1,1],[0,1],[0,0]]],"
      "[[[5,5],[6,5],[6,6],[5,5]]]]}},\n"
      "{\"type\":\"Feature\",\"properties\":{\"name\":\"line\"},\"geometry\":{\"type\":"
      "\"LineString\",\"coordinates\":[[0,0],[1,1]]}},\n"
      "{\"type\":\"Feature\",\"properties\":{\"name\":\"B\"},\"geometry\":{\"type\":\"Polygon\","
      "\"coordinates\":[[[0,0],[0,1],[-1,1],[-1,0],[0,0]]]}},\n"
      "{\"type\":\"Feature\",\"properties\":{},\"geometry\":null}]}";
  assert_int_equal(gj(fc, &r, &e), QK_OK);
  qk_region_stats_t s;
  qk_region_stats(r, &s);
  assert_int_equal(s.features, 4);
  assert_int_equal(s.skipped, 2);
  assert_int_equal(s.rings, 3);
  assert_int_equal(s.holes, 0);
  assert_string_equal(qk_region_property(r, 0, "name"), "A");
  assert_string_equal(qk_region_property(r, 0, "pop"), "12");
  assert_string_equal(qk_region_property(r, 0, "ok"), "true");
  assert_string_equal(qk_region_property(r, 0, "z"), "");
  assert_null(qk_region_property(r, 0, "nope"));
  assert_string_equal(qk_region_property(r, 2, "name"), "B");
  assert_int_equal(at(r, 0.5, 0.5, 0), 0);
  assert_int_equal(at(r, 5.7, 5.2, 0), 0);
  assert_int_equal(at(r, -0.5, 0.5, 0), 2);
  assert_int_equal(at(r, 0, 0.5, 0), 0); /* shared edge x = 0: the feature to the right */
  assert_int_equal(at(r, 0, 0.5, QK_BOUNDARY_CLOSED), 0);
  size_t n;
  uint32_t fl[4];
  qk_region_locate_all(r, (qk_point_t){0, 0.5}, QK_BOUNDARY_CLOSED, fl, 4, &n);
  assert_int_equal(n, 2);
  assert_int_equal(fl[1], 2);
  qk_region_free(r);
  /* a bare geometry and a single feature */
  assert_int_equal(gj("{\"type\":\"Polygon\",\"coordinates\":[[[0,0],[2,0],[2,2],[0,0]]]}", &r, &e),
                   QK_OK);
  assert_int_equal(at(r, 1.5, 0.5, 0), 0);
  qk_region_free(r);
  assert_int_equal(gj("{\"type\":\"Feature\",\"geometry\":{\"type\":\"Polygon\",\"coordinates\":"
                      "[[[0,0],[2,0],[2,2],[0,0]]]},\"properties\":{\"k\":\"v\"}}",
                      &r, &e),
                   QK_OK);
  assert_string_equal(qk_region_property(r, 0, "k"), "v");
  qk_region_free(r);

  /* errors */
  struct {
    const char *text;
    qk_status_t st;
    unsigned long line;
    const char *msg;
  } bad[] = {
      {"{\"type\":\"FeatureCollection\",\n \"features\": [1,, 2]}", QK_ERR_PARSE, 2,
       "malformed JSON"},
      {"{\"type\":\"Polygon\",\"coordinates\":[[[0,0],[1,0],[1,1],[0,0]]]", QK_ERR_PARSE, 1,
       "end of input"},
      {"{\"type\":\"Polygon\",\"coordinates\":[[[0,0],[1,0],[1,1],[0,0]]]} x", QK_ERR_PARSE, 1,
       "after the JSON value"},
      {"[1,2]", QK_ERR_PARSE, 0, "GeoJSON object"},
      {"{\"type\":\"FeatureCollection\"}", QK_ERR_PARSE, 0, "features"},
      {"{\"type\":\"FeatureCollection\",\"features\":[{\"type\":\"Feature\",\"geometry\":{\"type\":"
       "\"Polygon\",\"coordinates\":[[[0,0],[1,0],[0,0]]]}}]}",
       QK_ERR_GEOMETRY, 0, "feature 0, polygon 0, ring 0: 3 positions"},
      {"{\"type\":\"FeatureCollection\",\"features\":[{\"type\":\"Feature\",\"geometry\":null},"
       "{\"type\":\"Feature\",\"geometry\":{\"type\":\"Polygon\",\"coordinates\":[[[0,0],[1,0],"
       "[1,1],[0,1]]]}}]}",
       QK_ERR_GEOMETRY, 0, "feature 1, polygon 0, ring 0: not closed"},
      {"{\"type\":\"Polygon\",\"coordinates\":[[[0,0],[1,\"a\"],[1,1],[0,0]]]}", QK_ERR_PARSE, 0,
       "position 1: expected"},
      {"{\"type\":\"Polygon\",\"coordinates\":[[[0,0],[1,0],[1,1e999],[0,0]]]}", QK_ERR_NONFINITE,
       0, "not finite"},
      {"{\"type\":\"Polygon\",\"coordinates\":[[[0,0],[1,0],[1,95],[0,0]]]}", QK_ERR_GEOMETRY, 0,
       "planar"},
      {"{\"type\":\"Polygon\",\"coordinates\":{}}", QK_ERR_PARSE, 0, "coordinates"},
      {"{\"type\":\"Feature\",\"geometry\":{\"type\":\"Polygon\",\"coordinates\":[]},"
       "\"properties\":5}",
       QK_ERR_PARSE, 0, "properties"},
  };
  for (size_t i = 0; i < sizeof bad / sizeof bad[0]; i++) {
    r = (qk_region_t *)1;
    qk_status_t st = gj(bad[i].text, &r, &e);
    if (st != bad[i].st || !strstr(e.message, bad[i].msg) || (bad[i].line && e.line != bad[i].line))
      fail_msg("case %zu: status %s line %lu message '%s'", i, qk_strerror(st), e.line, e.message);
    assert_null(r);
  }
  /* absurd planar coordinates */
  qk_region_options_t o;
  qk_region_options_init(&o);
  o.planar = 1;
  const char *huge = "{\"type\":\"Polygon\",\"coordinates\":[[[0,0],[1e200,0],[1,1],[0,0]]]}";
  assert_int_equal(qk_region_read_geojson_text(huge, strlen(huge), &o, &r, &e), QK_ERR_GEOMETRY);
  assert_non_null(strstr(e.message, "absurd"));
  assert_int_equal(qk_region_read_geojson("/nonexistent/x.geojson", NULL, &r, &e), QK_ERR_IO);
}

/* A lone surrogate escape (json-c reads it as U+FFFD; I-JSON forbids it, as the reader
 * refuses a surrogate's raw bytes) is an error at the escape, in a value, a name, a
 * FeatureCollection (read feature by feature) or a bare Feature; a surrogate pair, an
 * escaped backslash before "ud800" and other escapes are not. A Polygon's coordinates
 * given to a MultiPolygon, or the reverse, are named as nested at the wrong depth (they
 * were "ring 0: 2 positions (a ring needs at least 4)", or "1 positions"). */
static void test_region_geojson_surrogates_and_depth(void **state) {
  (void)state;
  const char *poly =
      "\"geometry\":{\"type\":\"Polygon\",\"coordinates\":[[[0,0],[1,0],[1,1],[0,0]]]}";
  char text[512];
  struct {
    const char *props;    /* the properties object, on line 2 */
    unsigned long column; /* of the escape (0: accepted) */
  } sur[] = {
      {"{\"name\":\"a\\ud800b\"}", 11},
      {"{\"name\":\"a\\udc00\"}", 11},
      {"{\"n\\ud83d\":1}", 4},
      {"{\"name\":\"\\ud83d\\u0041\"}", 10},
      {"{\"name\":\"\\ud83d\"}", 10},
      {"{\"name\":\"a\\ud83d\\ude00b\"}", 0},
      {"{\"name\":\"\\\\ud800 \\u00e9\\n\"}", 0},
  };
  for (size_t i = 0; i < sizeof sur / sizeof sur[0]; i++)
    for (int fc = 0; fc < 2; fc++) {
      snprintf(text, sizeof text, "%s{\"type\":\"Feature\",\n\"properties\":%s,%s}%s",
               fc ? "{\"type\":\"FeatureCollection\",\"features\":[" : "", sur[i].props, poly,
               fc ? "]}" : "");
      qk_region_t *r = (qk_region_t *)1;
      qk_error_t e;
      qk_status_t st = gj(text, &r, &e);
      if (!sur[i].column) {
        if (st != QK_OK) fail_msg("case %zu: %s", i, e.message);
        qk_region_free(r);
        continue;
      }
      if (st != QK_ERR_PARSE || e.line != 2 || e.column != 13 + sur[i].column ||
          !strstr(e.message, "half of a surrogate pair") || !strstr(e.message, "RFC 7493"))
        fail_msg("case %zu%s: status %s at %lu:%lu: %s", i, fc ? " (collection)" : "",
                 qk_strerror(st), e.line, e.column, e.message);
      assert_null(r);
    }
  struct {
    const char *geom, *msg;
  } depth[] = {
      {"{\"type\":\"MultiPolygon\",\"coordinates\":[[[0,0],[1,0],[1,1],[0,0]]]}",
       "polygon 0, ring 0: the coordinates array has the wrong depth for a MultiPolygon (nested "
       "too shallow): expected positions as arrays of numbers"},
      {"{\"type\":\"Polygon\",\"coordinates\":[[[[0,0],[1,0],[1,1],[0,0]]]]}",
       "polygon 0, ring 0: the coordinates array has the wrong depth for a Polygon (nested too "
       "deep): expected positions as arrays of numbers"},
      {"{\"type\":\"Polygon\",\"coordinates\":[[0,0],[1,0],[1,1],[0,0]]}",
       "wrong depth for a Polygon (nested too shallow)"},
      {"{\"type\":\"Polygon\",\"coordinates\":[0,0]}",
       "polygon 0: the coordinates array has the wrong depth for a Polygon (nested too shallow)"},
      {"{\"type\":\"MultiPolygon\",\"coordinates\":[[[[[0,0],[1,0],[1,1],[0,0]]]]]}",
       "wrong depth for a MultiPolygon (nested too deep)"},
      {"{\"type\":\"MultiPolygon\",\"coordinates\":[[[[0,0],[1,0],[1,1],[0,0]]],[[0,0],[2,0],"
       "[2,2],[0,0]]]}",
       "feature 0, polygon 1, ring 0: the coordinates array has the wrong depth"},
  };
  for (size_t i = 0; i < sizeof depth / sizeof depth[0]; i++) {
    qk_region_t *r = (qk_region_t *)1;
    qk_error_t e;
    qk_status_t st = gj(depth[i].geom, &r, &e);
    if (st != QK_ERR_PARSE || !strstr(e.message, depth[i].msg) || e.line != 1 || e.column < 30)
      fail_msg("depth case %zu: status %s at %lu:%lu: %s", i, qk_strerror(st), e.line, e.column,
               e.message);
    assert_null(r);
  }
}

/* ---- real data ----------------------------------------------------------------------------- */

static void test_region_countries(void **state) {
  (void)state;
  char path[1024];
  FILE *f = qkt_open_shared("countries-50m.geojson", path, sizeof path);
  if (!f) {
    print_message("no %s: skipped\n", path);
    skip();
  }
  fclose(f);
  qk_region_t *r;
  qk_error_t e;
  qk_region_options_t o;
  qk_region_options_init(&o);
  o.keep_tree = 1;
  qk_status_t st = qk_region_read_geojson(path, &o, &r, &e);
  if (st) fail_msg("%s: %s", path, e.message);
  struct {
    const char *city;
    double lon, lat;
    const char *country; /* NULL: must not be Russia */
  } c[] = {
      {"Rovaniemi", 25.7294, 66.5039, "Finland"},
      {"Tornio", 24.1470, 65.8481, "Finland"},
      {"Bodo", 14.4049, 67.2804, NULL},
      {"Kautokeino", 23.0413, 68.9995, "Norway"},
      {"Murmansk", 33.0856, 68.9585, "Russia"},
      {"Moscow", 37.6173, 55.7558, "Russia"},
      {"Chukotka west of 180", -175.0, 67.0, "Russia"},
      {"Chukotka east of 180", 175.0, 67.0, "Russia"},
      {"Viti Levu", 178.0, -17.8, "Fiji"},
      {"Paris", 2.3522, 48.8566, "France"},
      {"Berlin", 13.4050, 52.5200, "Germany"},
      {"Madrid", -3.7038, 40.4168, "Spain"},
      {"Tokyo", 139.6917, 35.6895, "Japan"},
      {"Cairo", 31.2357, 30.0444, "Egypt"},
      {"Sao Paulo", -46.6333, -23.5505, "Brazil"},
      {"Nairobi", 36.8219, -1.2921, "Kenya"},
      {"Delhi", 77.1025, 28.7041, "India"},
      {"Denver", -104.9903, 39.7392, "United States of America"},
      {"Sydney inland", 150.9, -33.8, "Australia"},
      {"Antarctic plateau", 0.0, -85.0, "Antarctica"},
      {"Ross ice", -160.0, -84.0, "Antarctica"},
  };
  for (size_t i = 0; i < sizeof c / sizeof c[0]; i++) {
    uint32_t ft = at(r, c[i].lon, c[i].lat, QK_BOUNDARY_SEMI_OPEN);
    const char *name = ft == QK_NONE ? "(none)" : qk_region_property(r, ft, "name");
    if (c[i].country ? strcmp(name, c[i].country) != 0 : strcmp(name, "Russia") == 0)
      fail_msg("%s (%g, %g): %s, want %s", c[i].city, c[i].lon, c[i].lat, name,
               c[i].country ? c[i].country : "not Russia");
  }
  assert_int_equal(at(r, -30, 0, 0), QK_NONE); /* Atlantic */
  qk_region_stats_t s;
  qk_region_stats(r, &s);
  assert_int_equal(s.features, 241);
  QKT_CHECK_TREE(qk_region_tree(r));
  qk_region_free(r);
}

/* The OGR reader (when built with GDAL) reads the same GeoJSON file to the same layer. */
static void test_region_ogr(void **state) {
  (void)state;
  char path[] = "/tmp/qk_region_ogr_XXXXXX";
  int fd = mkstemp(path);
  assert_true(fd >= 0);
  const char *js =
      "{\"type\":\"FeatureCollection\",\"features\":["
      "{\"type\":\"Feature\",\"properties\":{\"name\":\"A\"},\"geometry\":"
      "{\"type\":\"Polygon\",\"coordinates\":[[[0,0],[4,0],[4,4],[0,4],[0,0]],"
      "[[1,1],[1,2],[2,2],[2,1],[1,1]]]}},"
      "{\"type\":\"Feature\",\"properties\":{\"name\":\"B\"},\"geometry\":"
      "{\"type\":\"MultiPolygon\",\"coordinates\":[[[[4,0],[8,0],[8,4],[4,4],[4,0]]]]}}]}";
  FILE *f = fdopen(fd, "w");
  fputs(js, f);
  fclose(f);
  qk_region_t *a, *b;
  qk_error_t e;
  qk_status_t st = qk_region_read_ogr(path, NULL, &b, &e);
  if (st == QK_ERR_UNSUPPORTED) {
    assert_non_null(strstr(e.message, "libgdal-dev"));
    remove(path);
    skip();
  }
  if (st) fail_msg("ogr: %s", e.message);
  assert_int_equal(qk_region_read_geojson(path, NULL, &a, &e), QK_OK);
  remove(path);
  assert_int_equal(qk_region_feature_count(b), 2);
  assert_string_equal(qk_region_property(b, 1, "name"), "B");
  for (double y = -0.5; y <= 4.5; y += 0.25)
    for (double x = -0.5; x <= 8.5; x += 0.25)
      for (int rule = 0; rule < 3; rule++)
        assert_int_equal(at(a, x, y, (qk_boundary_t)rule), at(b, x, y, (qk_boundary_t)rule));
  qk_region_stats_t s;
  qk_region_stats(b, &s);
  assert_int_equal(s.holes, 1);
  qk_region_free(a);
  qk_region_free(b);
  assert_int_equal(qk_region_read_ogr("/nonexistent/none.shp", NULL, &b, &e), QK_ERR_IO);
}

/* Shapefile bytes written by hand (ESRI's specification: a 100-byte header, big-endian
 * record headers, little-endian contents): n unit squares [i, i+1] x [0, 1]. */
static void shp_be32(unsigned char *p, uint32_t v) {
  for (int i = 0; i < 4; i++) p[i] = (unsigned char)(v >> (24 - 8 * i));
}
static void shp_le32(unsigned char *p, uint32_t v) {
  for (int i = 0; i < 4; i++) p[i] = (unsigned char)(v >> (8 * i));
}
static void shp_le64(unsigned char *p, double d) {
  uint64_t v;
  memcpy(&v, &d, 8);
  for (int i = 0; i < 8; i++) p[i] = (unsigned char)(v >> (8 * i));
}
static void shp_header(unsigned char *h, size_t bytes, int n) {
  memset(h, 0, 100);
  shp_be32(h, 9994);
  shp_be32(h + 24, (uint32_t)(bytes / 2));
  shp_le32(h + 28, 1000);
  shp_le32(h + 32, 5); /* polygons */
  shp_le64(h + 36, 0), shp_le64(h + 44, 0), shp_le64(h + 52, n), shp_le64(h + 60, 1);
}
static void write_squares_shp(const char *base, int n, size_t shp_bytes_kept) {
  size_t rec = 8 + 128, shp = 100 + rec * (size_t)n, shx = 100 + 8 * (size_t)n;
  unsigned char *b = calloc(shp, 1), *x = calloc(shx, 1);
  shp_header(b, shp, n);
  shp_header(x, shx, n);
  for (int i = 0; i < n; i++) {
    unsigned char *r = b + 100 + rec * (size_t)i;
    shp_be32(r, (uint32_t)i + 1);
    shp_be32(r + 4, 64);
    shp_le32(r + 8, 5);
    shp_le64(r + 12, i), shp_le64(r + 20, 0), shp_le64(r + 28, i + 1), shp_le64(r + 36, 1);
    shp_le32(r + 44, 1); /* parts */
    shp_le32(r + 48, 5); /* points */
    shp_le32(r + 52, 0); /* the part starts at point 0 */
    const double sq[5][2] = {{i, 0}, {i, 1}, {i + 1, 1}, {i + 1, 0}, {i, 0}}; /* clockwise */
    for (int k = 0; k < 5; k++)
      shp_le64(r + 56 + 16 * k, sq[k][0]), shp_le64(r + 64 + 16 * k, sq[k][1]);
    shp_be32(x + 100 + 8 * (size_t)i, (uint32_t)((100 + rec * (size_t)i) / 2));
    shp_be32(x + 104 + 8 * (size_t)i, 64);
  }
  char path[256];
  snprintf(path, sizeof path, "%s.shp", base);
  FILE *f = fopen(path, "wb");
  assert_non_null(f);
  fwrite(b, 1, shp_bytes_kept < shp ? shp_bytes_kept : shp, f);
  fclose(f);
  snprintf(path, sizeof path, "%s.shx", base);
  f = fopen(path, "wb");
  assert_non_null(f);
  fwrite(x, 1, shx, f);
  fclose(f);
  free(b), free(x);
}

/* A damaged file through GDAL is an error naming the feature (nineteenth session): a
 * shapefile of 200 squares cut after 87 records was read as 87 squares and 113 empty
 * features (GDAL reported each short read by an error the reader did not look at, and
 * printed it on stderr), with status QK_OK. */
static void test_region_ogr_damaged(void **state) {
  (void)state;
  char dir[] = "/tmp/qk_region_shp_XXXXXX";
  assert_non_null(mkdtemp(dir));
  char base[128], path[160];
  snprintf(base, sizeof base, "%s/sq", dir);
  snprintf(path, sizeof path, "%s.shp", base);
  write_squares_shp(base, 200, SIZE_MAX);
  qk_region_t *r;
  qk_error_t e;
  qk_region_options_t o;
  qk_region_options_init(&o);
  o.planar = 1;
  qk_status_t st = qk_region_read_ogr(path, &o, &r, &e);
  if (st == QK_ERR_UNSUPPORTED) {
    remove(path), snprintf(path, sizeof path, "%s.shx", base), remove(path), rmdir(dir);
    skip();
  }
  if (st) fail_msg("intact file: %s", e.message);
  assert_int_equal(qk_region_feature_count(r), 200);
  assert_int_equal(at(r, 150.5, 0.5, QK_BOUNDARY_SEMI_OPEN), 150);
  qk_region_free(r);
  write_squares_shp(base, 200, 12000); /* 87 whole records and part of one */
  r = (qk_region_t *)1;
  assert_int_equal(qk_region_read_ogr(path, &o, &r, &e), QK_ERR_IO);
  assert_null(r);
  if (!strstr(e.message, "feature 87")) fail_msg("message: %s", e.message);
  remove(path);
  snprintf(path, sizeof path, "%s.shx", base);
  remove(path);
  rmdir(dir);
}

static void test_region_fuzz_corpus(void **state) {
  (void)state;
#ifdef QK_HAVE_JSONC
  const char *srcdir = getenv("QK_SOURCE_DIR");
  char dir[1024];
  snprintf(dir, sizeof dir, "%s/fuzz/corpus/geojson", srcdir ? srcdir : ".");
  DIR *d = opendir(dir);
  if (!d) {
    print_message("no %s: skipped\n", dir);
    skip();
  }
  size_t n = 0;
  struct dirent *e;
  while ((e = readdir(d))) {
    if (e->d_name[0] == '.') continue;
    char path[2048];
    snprintf(path, sizeof path, "%s/%s", dir, e->d_name);
    FILE *f = fopen(path, "rb");
    if (!f) continue;
    static uint8_t buf[1 << 16];
    size_t len = fread(buf, 1, sizeof buf, f);
    fclose(f);
    qkf_geojson(buf, len);
    n++;
  }
  closedir(d);
  assert_true(n > 0);
#else
  skip();
#endif
}

/* Even-odd test of (x, y) against the ring q[0..n) (closed by its first vertex), on the
 * unwrapped plane. Exact here: every coordinate is a multiple of 1/4 below 2^9, so each
 * product is exact in a double. */
static int unwrapped_inside(const double *q, size_t n, double x, double y) {
  int in = 0;
  for (size_t i = 0; i < n; i++) {
    double ax = q[2 * i], ay = q[2 * i + 1];
    double bx = q[2 * ((i + 1) % n)], by = q[2 * ((i + 1) % n) + 1];
    if ((ay > y) != (by > y)) {
      double side = (bx - ax) * (y - ay) - (by - ay) * (x - ax);
      if ((by > ay) ? side > 0 : side < 0) in = !in;
    }
  }
  return in;
}

/* Slanted edges across the antimeridian: the cut's latitude is interpolated (prepare.c's
 * cut_lat), in both directions. Feature 0 crosses eastward, from (170, 0) to (-170, 20)
 * (cut at latitude 10); feature 1 westward, from (-170, -40) to (170, -20) (cut at -30).
 * The oracle is the even-odd rule on the rings with their western longitudes moved by
 * 360 (an unwrapped plane where the rings do not cross anything), at points off every
 * edge. The mutation sweep found the eastward cut's latitude untested: with `ax <= m` for
 * `ax == m` every eastward cut took the start's latitude, and only edges along a
 * latitude crossed the antimeridian in the other tests. */
static void test_region_antimeridian_slanted(void **state) {
  (void)state;
  double xy[] = {170,  0,   -170, 20,  -170, 30,  170,  30,  170,  0,
                 -170, -40, 170,  -20, 170,  -10, -170, -10, -170, -40};
  const double u0[] = {170, 0, 190, 20, 190, 30, 170, 30};
  const double u1[] = {190, -40, 170, -20, 170, -10, 190, -10};
  size_t rs[] = {0, 5, 10}, fs[] = {0, 1, 2};
  qk_region_t *r = lonlat(xy, rs, 2, fs, 2, 0);
  size_t checked = 0;
  for (double lon = 165.5; lon < 195; lon += 1)
    for (double lat = -44.75; lat < 35; lat += 0.5) {
      uint32_t want = unwrapped_inside(u0, 4, lon, lat)   ? 0
                      : unwrapped_inside(u1, 4, lon, lat) ? 1
                                                          : QK_NONE;
      double x = lon > 180 ? lon - 360 : lon;
      for (int rule = 0; rule < 3; rule++) {
        uint32_t got = at(r, x, lat, (qk_boundary_t)rule);
        if (got != want)
          fail_msg("(%g, %g) rule %d: locate %d, unwrapped even-odd %d", x, lat, rule, (int)got,
                   (int)want);
      }
      checked += want != QK_NONE;
    }
  assert_true(checked > 200); /* (the grid does meet both features) */
  qk_region_free(r);
}

/* ---- coverages across the antimeridian ------------------------------------------------ */

/* The latitude of segment p-q at longitude m, interpolated from p (m between them). */
static double interp_from(double px, double py, double qx, double qy, double m) {
  return py + (m - px) / (qx - px) * (qy - py);
}

/* The coverage promise at (x, y): in exactly one feature under semi-open, at least one
 * under closed, at most one under open; locate gives the one of locate_all. Returns the
 * feature. */
static uint32_t cover_one(const qk_region_t *r, double x, double y, const char *what,
                          uint64_t seed) {
  size_t n[3];
  uint32_t all[8], one;
  for (int rule = 2; rule >= 0; rule--) /* (semi-open, 0, last: its list stays in all) */
    assert_int_equal(
        qk_region_locate_all(r, (qk_point_t){x, y}, (qk_boundary_t)rule, all, 8, &n[rule]), QK_OK);
  assert_int_equal(qk_region_locate(r, (qk_point_t){x, y}, QK_BOUNDARY_SEMI_OPEN, &one), QK_OK);
  if (n[0] != 1 || n[1] < 1 || n[2] > 1 || one != all[0])
    fail_msg("seed %llu, %s: (%.17g, %.17g) in %zu features under semi-open (%zu closed, %zu "
             "open), locate %d",
             (unsigned long long)seed, what, x, y, n[0], n[1], n[2], (int)one);
  return all[0];
}

/* Two features sharing an edge across the antimeridian, listed (175, 1.92) -> (-171, -8.68)
 * in one and the reverse in the other, and the same with both rings reversed (the review's
 * layers). The cut's latitude was interpolated from each edge's own start, a few ulps
 * apart in the two features: points on the antimeridian between the two cuts were in both
 * features (the first layer) or in neither (the second). Points within 8 ulps of either
 * interpolation, at 180 and -180, are each in exactly one feature; points off the edge in
 * the one on their side of it. */
static void test_region_antimeridian_shared_edge(void **state) {
  (void)state;
  double north[] = {175, 1.92, -171, -8.68, -171, 10, 175, 10, 175, 1.92};
  double south[] = {-171, -8.68, 175, 1.92, 175, -20, -171, -20, -171, -8.68};
  const double cuts[2] = {interp_from(175, 1.92, 189, -8.68, 180),
                          interp_from(-171, -8.68, -185, 1.92, -180)};
  for (int reversed = 0; reversed < 2; reversed++) {
    double xy[20];
    for (int k = 0; k < 5; k++) {
      int j = reversed ? 4 - k : k;
      xy[2 * k] = north[2 * j], xy[2 * k + 1] = north[2 * j + 1];
      xy[10 + 2 * k] = south[2 * j], xy[10 + 2 * k + 1] = south[2 * j + 1];
    }
    size_t rs[] = {0, 5, 10}, fs[] = {0, 1, 2};
    qk_region_t *r = lonlat(xy, rs, 2, fs, 2, 0);
    const char *what = reversed ? "reversed rings" : "rings as given";
    for (int c = 0; c < 2; c++) {
      double y = cuts[c];
      for (int k = 0; k < 8; k++) y = nextafter(y, -INFINITY);
      for (int k = 0; k <= 16; k++, y = nextafter(y, INFINITY)) {
        cover_one(r, 180, y, what, 0);
        cover_one(r, -180, y, what, 0);
      }
    }
    /* off the edge: the feature on the point's side (north above the edge) */
    const double xs[4] = {180, -180, 179.9, -179.9};
    for (int i = 0; i < 4; i++)
      for (double y = -19.75; y < 10; y += 0.5) {
        double u = xs[i] < 0 ? xs[i] + 360 : xs[i];
        double line = 1.92 + (u - 175) / 14 * (-8.68 - 1.92);
        uint32_t f = cover_one(r, xs[i], y, what, 0);
        if (f != (y > line ? 0u : 1u))
          fail_msg("%s: (%g, %g) in feature %u, the edge is at %g", what, xs[i], y, (unsigned)f,
                   line);
      }
    qk_region_free(r);
  }
}

/* A seeded random coverage across the antimeridian: triangles on a jittered 8 x 8 grid
 * over longitudes 160 to 200 (wrapped to -160) and latitudes -20 to 20, the longitudes
 * rounded to 3, 6 or 13 decimals (so the cuts are not exact). Queried at 180 and -180
 * within 8 ulps of both interpolations of every edge across the antimeridian, at random
 * latitudes there, and at random points of the interior (those clearly inside a triangle
 * in the unwrapped plane: in its feature, a brute force over the triangles). Every point
 * is in exactly one feature. The control is the same grid moved by -180 degrees, to
 * longitudes -20 to 20, queried along longitude 0 the same way (no cut there: it held
 * before the fix too). */
static void test_region_antimeridian_coverage(void **state) {
  (void)state;
  uint64_t seed = qkt_seed(6053);
  qkt_rng_t g;
  qkt_rng_seed(&g, seed);
  enum { N = 8, T = 2 * N * N };
  for (int rd = 0; rd < 4; rd++) {
    double vx[N + 1][N + 1], vy[N + 1][N + 1]; /* unwrapped longitudes */
    for (int i = 0; i <= N; i++)
      for (int j = 0; j <= N; j++) {
        bool inner = i > 0 && i < N && j > 0 && j < N;
        double x = 160 + 5 * i + (inner ? qkt_rng_range(&g, -1, 1) : 0);
        double p = pow(10, (double[]){3, 6, 13}[qkt_rng_below(&g, 3)]);
        vx[i][j] = round(x * p) / p;
        vy[i][j] = -20 + 5 * j + (inner ? qkt_rng_range(&g, -1, 1) : 0);
      }
    double tri[T][6]; /* unwrapped */
    for (int i = 0, t = 0; i < N; i++)
      for (int j = 0; j < N; j++) {
        const int c[4][2] = {{i, j}, {i + 1, j}, {i + 1, j + 1}, {i, j + 1}};
        for (int h = 0; h < 2; h++, t++)
          for (int k = 0; k < 3; k++) {
            int q = k == 0 ? 0 : k + h; /* (a, b, c) and (a, c, d) */
            tri[t][2 * k] = vx[c[q][0]][c[q][1]], tri[t][2 * k + 1] = vy[c[q][0]][c[q][1]];
          }
      }
    for (int control = 0; control < 2; control++) {
      /* the layer: longitudes wrapped, or moved by -180 (both exact) */
      double xy[T * 8];
      size_t rs[T + 1], fs[T + 1];
      for (int t = 0; t < T; t++) {
        for (int k = 0; k < 4; k++) {
          double x = tri[t][2 * (k % 3)];
          xy[8 * t + 2 * k] = control ? x - 180 : x > 180 ? x - 360 : x;
          xy[8 * t + 2 * k + 1] = tri[t][2 * (k % 3) + 1];
        }
        rs[t] = 4 * (size_t)t, fs[t] = (size_t)t;
      }
      rs[T] = 4 * T, fs[T] = T;
      qk_region_t *r = lonlat(xy, rs, T, fs, T, 0);
      const char *what = control ? "control at longitude 0" : "across the antimeridian";
      const double m = control ? 0 : 180; /* the meridian queried, in the layer's longitudes */
      const double mx[2] = {m, control ? 0 : -180};
      size_t crossing = 0;
      for (int t = 0; t < T; t++)
        for (int k = 0; k < 3; k++) {
          double ax = tri[t][2 * k], ay = tri[t][2 * k + 1];
          double bx = tri[t][2 * ((k + 1) % 3)], by = tri[t][2 * ((k + 1) % 3) + 1];
          if (!(qk__min(ax, bx) < 180 && qk__max(ax, bx) > 180)) continue;
          crossing++;
          if (control) ax -= 180, bx -= 180;
          /* both ends' interpolations, in the frames the layer gives (the western end
           * moved back by 360 across the antimeridian) */
          double w = control ? 0 : 360;
          double ea = ax > bx ? ax : bx, eay = ax > bx ? ay : by; /* the eastern end */
          double wa = ax > bx ? bx : ax, way = ax > bx ? by : ay;
          double cut[2] = {interp_from(wa, way, ea, eay, m),
                           interp_from(ea - w, eay, wa - w, way, m - w)};
          for (int c = 0; c < 2; c++) {
            double y = cut[c];
            for (int s = 0; s < 8; s++) y = nextafter(y, -INFINITY);
            for (int s = 0; s <= 16; s++, y = nextafter(y, INFINITY))
              for (int e = 0; e < 2 && fabs(y) < 17; e++) cover_one(r, mx[e], y, what, seed);
          }
        }
      assert_true(crossing >= 2 * N); /* (each row's triangles cross the meridian) */
      for (int k = 0; k < 500; k++) cover_one(r, mx[k % 2], qkt_rng_range(&g, -17, 17), what, seed);
      for (int k = 0; k < 1000; k++) {
        double u = qkt_rng_range(&g, 165, 195), y = qkt_rng_range(&g, -17, 17);
        double x = control ? u - 180 : u > 180 ? u - 360 : u;
        uint32_t f = cover_one(r, x, y, what, seed), want = QK_NONE;
        for (int t = 0; t < T && want == QK_NONE; t++) {
          int pos = 0, neg = 0;
          for (int e = 0; e < 3; e++) {
            double ax = tri[t][2 * e], ay = tri[t][2 * e + 1];
            double bx = tri[t][2 * ((e + 1) % 3)], by = tri[t][2 * ((e + 1) % 3) + 1];
            double o = (bx - ax) * (y - ay) - (by - ay) * (u - ax);
            pos += o > 1e-9, neg += o < -1e-9;
          }
          if (pos == 3 || neg == 3) want = (uint32_t)t;
        }
        if (want != QK_NONE && f != want)
          fail_msg("seed %llu, %s: (%.17g, %.17g) in feature %u, inside triangle %u",
                   (unsigned long long)seed, what, x, y, (unsigned)f, (unsigned)want);
      }
      qk_region_free(r);
    }
  }
}

/* ---- the SVG drawing ----------------------------------------------------------------- */

/* One <path> of a drawing: its fill and stroke attributes, and its d parsed into points
 * (x[i], y[i]), subpaths starting at start[k] (start[nsub] = n), closed[k] when ended
 * with Z. */
typedef struct svg_path {
  char fill[32], stroke[32];
  double x[256], y[256];
  size_t n, start[65], nsub;
  bool closed[64];
} svg_path_t;

/* The value of attribute name="..." in the element [p, end), or "" */
static void svg_attr(const char *p, const char *end, const char *name, char *out, size_t cap) {
  char key[40];
  snprintf(key, sizeof key, " %s=\"", name);
  const char *a = strstr(p, key);
  out[0] = '\0';
  if (!a || a > end) return;
  a += strlen(key);
  size_t n = (size_t)(strchr(a, '"') - a);
  snprintf(out, cap, "%.*s", (int)(n < cap ? n : cap - 1), a);
}

/* The paths of an SVG text, in order (at most cap). */
static size_t svg_paths(const char *text, svg_path_t *out, size_t cap) {
  size_t np = 0;
  for (const char *p = text; np < cap && (p = strstr(p, "<path ")); p++) {
    const char *end = strstr(p, "/>");
    svg_path_t *s = &out[np++];
    memset(s, 0, sizeof *s);
    svg_attr(p, end, "fill", s->fill, sizeof s->fill);
    svg_attr(p, end, "stroke", s->stroke, sizeof s->stroke);
    const char *d = strstr(p, " d=\"");
    assert_true(d && d < end);
    for (d += 4; *d != '"';) {
      char c = *d++;
      if (c == 'Z') {
        assert_true(s->nsub > 0);
        s->closed[s->nsub - 1] = true;
        continue;
      }
      assert_true(c == 'M' || c == 'L');
      if (c == 'M') assert_true(s->nsub < 64), s->start[s->nsub++] = s->n;
      char *e;
      assert_true(s->n < 256 && s->nsub > 0);
      s->x[s->n] = strtod(d, &e);
      s->y[s->n] = strtod(e, &e);
      s->n++;
      d = e;
    }
    s->start[s->nsub] = s->n;
  }
  return np;
}

/* The segments of a path's fill, subpaths closed: segment i from (x[i], y[i]) to the next
 * point of its subpath, or its first. */
static size_t svg_next(const svg_path_t *s, size_t i) {
  size_t k = 0;
  while (s->start[k + 1] <= i) k++;
  return i + 1 < s->start[k + 1] ? i + 1 : s->start[k];
}

/* The area the path's even-odd fill covers: the length inside at the middle of each band
 * between consecutive heights of vertices and of crossings of two segments (within a band
 * the length is linear in y, so the middle's is its mean). */
static double svg_evenodd_area(const svg_path_t *s) {
  double *ys = malloc((s->n + s->n * s->n) * sizeof *ys), area = 0;
  size_t ny = 0;
  for (size_t i = 0; i < s->n; i++) {
    ys[ny++] = s->y[i];
    size_t i1 = svg_next(s, i);
    for (size_t j = i + 1; j < s->n; j++) { /* where segments i and j cross */
      size_t j1 = svg_next(s, j);
      double ux = s->x[i1] - s->x[i], uy = s->y[i1] - s->y[i];
      double vx = s->x[j1] - s->x[j], vy = s->y[j1] - s->y[j];
      double den = ux * vy - uy * vx;
      if (den == 0) continue;
      double t = ((s->x[j] - s->x[i]) * vy - (s->y[j] - s->y[i]) * vx) / den;
      double u = ((s->x[j] - s->x[i]) * uy - (s->y[j] - s->y[i]) * ux) / den;
      if (t > 0 && t < 1 && u > 0 && u < 1) ys[ny++] = s->y[i] + t * uy;
    }
  }
  for (size_t i = 1; i < ny; i++) /* (insertion sort: few points) */
    for (size_t j = i; j > 0 && ys[j - 1] > ys[j]; j--) {
      double t = ys[j];
      ys[j] = ys[j - 1], ys[j - 1] = t;
    }
  for (size_t b = 0; b + 1 < ny; b++) {
    if (ys[b + 1] == ys[b]) continue;
    double ym = 0.5 * (ys[b] + ys[b + 1]), xs[256];
    size_t nx = 0;
    for (size_t i = 0; i < s->n; i++) {
      size_t j = svg_next(s, i);
      if ((s->y[i] > ym) != (s->y[j] > ym))
        xs[nx++] = s->x[i] + (ym - s->y[i]) / (s->y[j] - s->y[i]) * (s->x[j] - s->x[i]);
    }
    for (size_t i = 1; i < nx; i++)
      for (size_t j = i; j > 0 && xs[j - 1] > xs[j]; j--) {
        double t = xs[j];
        xs[j] = xs[j - 1], xs[j - 1] = t;
      }
    for (size_t i = 0; i + 1 < nx; i += 2) area += (xs[i + 1] - xs[i]) * (ys[b + 1] - ys[b]);
  }
  free(ys);
  return area;
}

/* The total length of the path's segments (subpaths open: its Z drawn by none here). */
static double svg_length(const svg_path_t *s, bool along_x, double x, size_t *along) {
  double len = 0;
  for (size_t k = 0; k < s->nsub; k++)
    for (size_t i = s->start[k]; i + 1 < s->start[k + 1]; i++) {
      len += hypot(s->x[i + 1] - s->x[i], s->y[i + 1] - s->y[i]);
      if (along_x && fabs(s->x[i] - x) < 0.02 && fabs(s->x[i + 1] - x) < 0.02) ++*along;
    }
  return len;
}

/* The drawing of a layer, parsed. */
static size_t svg_of(const qk_region_t *r, svg_path_t *p, size_t cap) {
  FILE *f = tmpfile();
  assert_non_null(f);
  assert_int_equal(qk_region_write_svg(r, f, 1000), QK_OK);
  long n = ftell(f);
  char *text = malloc((size_t)n + 1);
  rewind(f);
  assert_int_equal(fread(text, 1, (size_t)n, f), (size_t)n);
  text[n] = '\0';
  fclose(f);
  size_t np = svg_paths(text, p, cap);
  free(text);
  return np;
}

/* The drawing fills the features: each ring is one closed subpath through its vertices
 * (the pieces were drawn as separate two-point subpaths, M a L b M c L d, which an
 * even-odd fill leaves empty), and the even-odd area of each feature's path is the
 * feature's (a hole of the same winding as its shell, a repeated position, a bow-tie). In
 * lon/lat mode the pieces added along the antimeridian and the poles close the fill but
 * are not drawn as boundary: a square across the antimeridian and a ring around the south
 * pole are filled with their areas, and their outlines are their own edges only. */
static void test_region_svg_fill(void **state) {
  (void)state;
  svg_path_t *p = malloc(8 * sizeof *p);
  /* planar: feature 0 a square with a hole of the same winding, feature 1 a triangle with
   * a position repeated, feature 2 a bow-tie */
  double xy[] = {0,  0, 10, 0, 10, 10, 0,  10, 0,  0, 3,  3, 6,  3,  6,  6, 3,  6,  3,  3,
                 20, 0, 30, 0, 30, 0,  25, 8,  20, 0, 40, 0, 50, 10, 50, 0, 40, 10, 40, 0};
  size_t rs[] = {0, 5, 10, 15, 20}, fs[] = {0, 2, 3, 4};
  const double area[3] = {100 - 9, 40, 50};
  qk_region_t *r = lonlat(xy, rs, 4, fs, 3, 1);
  double k = 1000 / r->rside;
  assert_int_equal(svg_of(r, p, 8), 3);
  for (size_t f = 0; f < 3; f++) {
    assert_string_not_equal(p[f].fill, "none");
    assert_string_equal(p[f].stroke, "#555"); /* (no added pieces: the fill's own outline) */
    assert_int_equal(p[f].nsub, fs[f + 1] - fs[f]);
    for (size_t s = 0; s < p[f].nsub; s++) {
      assert_true(p[f].closed[s]);
      /* the ring's positions, the repeated one once, then the closing one */
      size_t ring = fs[f] + s, m = p[f].start[s];
      for (size_t v = rs[ring]; v < rs[ring + 1]; v++) {
        if (v > rs[ring] && xy[2 * v] == xy[2 * v - 2] && xy[2 * v + 1] == xy[2 * v - 1]) continue;
        assert_true(m < p[f].start[s + 1]);
        assert_float_equal(p[f].x[m], (xy[2 * v] - r->rx) * k, 0.006);
        assert_float_equal(p[f].y[m], (r->ry + r->rside - xy[2 * v + 1]) * k, 0.006);
        m++;
      }
      assert_int_equal(m, p[f].start[s + 1]);
    }
    double a = svg_evenodd_area(&p[f]), want = area[f] * k * k;
    if (fabs(a - want) > 1e-3 * want)
      fail_msg("planar feature %zu: filled area %g, want %g", f, a, want);
  }
  qk_region_free(r);

  /* lon/lat: feature 0 a square across the antimeridian, feature 1 a ring around the south
   * pole along latitude -60 (crossing eastward), feature 2 a square away from both */
  double ll[] = {170,  -10, -170, -10, -170, 10,  170, 10, 170, -10, 0,  -60, 90, -60, 179, -60,
                 -179, -60, -90,  -60, 0,    -60, 10,  10, 20,  10,  20, 20,  10, 20,  10,  10};
  size_t lrs[] = {0, 5, 11, 16}, lfs[] = {0, 1, 2, 3};
  const double larea[3] = {400, 360 * 30, 100}, outline[3] = {80, 360, 40};
  r = lonlat(ll, lrs, 3, lfs, 3, 0);
  k = 1000 / r->rside;
  assert_int_equal(svg_of(r, p, 8), 5); /* features 0 and 1: a fill and an outline each */
  const size_t fill[3] = {0, 2, 4};
  for (size_t f = 0; f < 3; f++) {
    const svg_path_t *s = &p[fill[f]];
    assert_string_not_equal(s->fill, "none");
    assert_int_equal(s->nsub, 1);
    assert_true(s->closed[0]);
    /* the ring's positions in order among the path's, the others on the antimeridian or
     * the pole line */
    size_t v = lrs[f];
    for (size_t i = 0; i < s->n; i++) {
      double X = s->x[i] / k + r->rx, Y = r->ry + r->rside - s->y[i] / k;
      if (v < lrs[f + 1] && fabs(X - ll[2 * v]) < 0.01 && fabs(Y - ll[2 * v + 1]) < 0.01)
        v++;
      else if (!(fabs(fabs(X) - 180) < 0.01 || fabs(fabs(Y) - 90) < 0.01))
        fail_msg("lon/lat feature %zu: (%g, %g) is no vertex of the ring", f, X, Y);
    }
    assert_int_equal(v, lrs[f + 1]);
    double a = svg_evenodd_area(s), want = larea[f] * k * k;
    if (fabs(a - want) > 1e-3 * want)
      fail_msg("lon/lat feature %zu: filled area %g, want %g", f, a, want);
    /* the outline: the ring's edges, none along the antimeridian or the pole line */
    const svg_path_t *o = f < 2 ? &p[fill[f] + 1] : s;
    if (f < 2) {
      assert_string_equal(o->fill, "none");
      assert_string_equal(o->stroke, "#555");
      assert_string_equal(s->stroke, "none");
    }
    size_t along = 0;
    double len = svg_length(o, true, (180 - r->rx) * k, &along);
    svg_length(o, true, (-180 - r->rx) * k, &along);
    if (f == 2) len += hypot(o->x[0] - o->x[o->n - 1], o->y[0] - o->y[o->n - 1]);
    if (along || fabs(len - outline[f] * k) > 0.05)
      fail_msg("lon/lat feature %zu: outline %g long (want %g), %zu segments along +-180", f,
               len / k, outline[f], along);
  }
  qk_region_free(r);
  free(p);
}

/* A planar layer of nf features of one ring each, ring f the len positions (closed)
 * from xy + 2 len f. */
static qk_region_t *one_ring_features(const double *xy, size_t nf, size_t len) {
  size_t *rs = malloc((nf + 1) * sizeof *rs), *fs = malloc((nf + 1) * sizeof *fs);
  assert_non_null(rs), assert_non_null(fs);
  for (size_t f = 0; f <= nf; f++) rs[f] = len * f, fs[f] = f;
  qk_region_arrays_t in = {xy, rs, nf, fs, nf};
  qk_region_options_t o;
  qk_region_options_init(&o);
  o.planar = 1;
  qk_region_t *r = NULL;
  assert_int_equal(qk_region_from_arrays(&in, &o, &r, NULL), QK_OK);
  free(fs), free(rs);
  return r;
}

/* Exact orientation of (a, b, p) in quarter units (every value a multiple of 1/4 below 2^21). */
static int orient_q(const double *a, const double *b, const double *p) {
  long long ax = (long long)(4 * a[0]), ay = (long long)(4 * a[1]);
  long long bx = (long long)(4 * b[0]) - ax, by = (long long)(4 * b[1]) - ay;
  long long px = (long long)(4 * p[0]) - ax, py = (long long)(4 * p[1]) - ay;
  long long d = bx * py - by * px;
  return (d > 0) - (d < 0);
}

/* The split budget (pieces + 4096) is shared among a cell's children in proportion to their
 * pieces (refine.c, qk__child_floor; build_top.c the same): spent depth first, a fan of
 * slices round one apex had its first quadrant (north-east) split finely and the others
 * left as a few leaves of a quarter of the edges each (a QA helper's fan of 20,000
 * slices: queries 50-200 times slower there). The fan here is symmetric, so each quadrant
 * must get about as many leaves as the others; the answers (closed rule) against brute
 * force over the triangles besides. */
static void test_region_budget_shared_by_quadrants(void **state) {
  (void)state;
  const double R = 1 << 20;
  enum { N = 1600 }; /* slices: 4,800 pieces; the fan wants far more splits than 8,896 */
  double *xy = malloc(8 * N * sizeof *xy);
  assert_non_null(xy);
  double prev[2] = {R, 0};
  for (int i = 0; i < N; i++) {
    double a = 6.283185307179586 * (i + 1) / N;
    double cur[2] = {i + 1 == N ? R : round(R * cos(a)), i + 1 == N ? 0 : round(R * sin(a))};
    double *v = xy + 8 * i; /* apex, prev, cur, apex: counter-clockwise */
    v[0] = v[1] = v[6] = v[7] = 0;
    v[2] = prev[0], v[3] = prev[1], v[4] = cur[0], v[5] = cur[1];
    prev[0] = cur[0], prev[1] = cur[1];
  }
  qk_region_t *r = one_ring_features(xy, N, 4);
  size_t per_q[4] = {0, 0, 0, 0}; /* leaves by the quadrant of their edges' box */
  for (size_t i = 0; i < r->n_leaves; i++) {
    const qk__leaf_t *l = &r->leaves[i];
    if (l->ne == 0) continue;
    double cx = (double)l->ex0 + (double)l->ex1, cy = (double)l->ey0 + (double)l->ey1;
    per_q[(cx < 0) + 2 * (cy < 0)]++;
  }
  size_t lo = per_q[0], hi = per_q[0];
  for (int q = 1; q < 4; q++)
    lo = per_q[q] < lo ? per_q[q] : lo, hi = per_q[q] > hi ? per_q[q] : hi;
  if (!(hi <= 2 * lo && lo >= 100))
    fail_msg("leaves by quadrant (NE, NW, SE, SW): %zu %zu %zu %zu", per_q[0], per_q[1], per_q[2],
             per_q[3]);
  uint64_t seed = qkt_seed(977);
  qkt_rng_t g;
  qkt_rng_seed(&g, seed);
  uint32_t got[8];
  for (int k = 0; k < 2000; k++) {
    /* quarter units, some near the apex */
    double span = k % 4 ? 2 * R : 64;
    double p[2] = {((double)qkt_rng_below(&g, (uint32_t)(4 * span)) - 2 * span) / 4 + 0.25,
                   ((double)qkt_rng_below(&g, (uint32_t)(4 * span)) - 2 * span) / 4 + 0.25};
    uint32_t want[8];
    size_t nw = 0, n = 0;
    for (uint32_t f = 0; f < N && nw < 8; f++) {
      const double *v = xy + 8 * f;
      if (orient_q(v, v + 2, p) >= 0 && orient_q(v + 2, v + 4, p) >= 0 &&
          orient_q(v + 4, v, p) >= 0)
        want[nw++] = f;
    }
    assert_int_equal(
        qk_region_locate_all(r, (qk_point_t){p[0], p[1]}, QK_BOUNDARY_CLOSED, got, 8, &n), QK_OK);
    if (n != nw || memcmp(got, want, nw * sizeof *got))
      fail_msg("point (%.17g, %.17g): %zu features (first %u), brute force %zu (first %u) (seed "
               "%llu)",
               p[0], p[1], n, n ? got[0] : 0, nw, nw ? want[0] : 0, (unsigned long long)seed);
  }
  qk_region_free(r);
  free(xy);
}

/* A compact cluster far from the rest of the layer (qk__split_progress): the cells close
 * in on it, one child at a time, until its pieces separate. Before, a split that left all
 * the pieces in one child counted as no progress, as for pieces through one point, and
 * after three such levels the cell stayed a leaf: a grid of 1,600 squares 1/100 wide with
 * another feature at distance 1 was one leaf of 6,400 edges (8.9 us a locate against 0.09).
 * Here 400 squares with a square 2^k away for k = -6 .. 10: every leaf holds at most 2 C
 * edges, and the answers (closed rule) agree with brute force. */
static void test_region_cluster_far_from_the_rest(void **state) {
  (void)state;
  enum { G = 20, NF = G * G + 1 };
  const double cell = 0.01 / G, w = cell * 0.75;
  double *xy = malloc(10 * NF * sizeof *xy);
  assert_non_null(xy);
  uint64_t seed = qkt_seed(31337);
  qkt_rng_t g;
  qkt_rng_seed(&g, seed);
  for (int k = -6; k <= 10; k += 2) { /* (much farther, depth 26 ends above the squares) */
    const double far = ldexp(1, k);
    for (size_t f = 0; f < NF; f++) {
      double x = f + 1 < NF ? (double)(f % G) * cell : far,
             y = f + 1 < NF ? (double)(f / G) * cell : far;
      double s = f + 1 < NF ? w : 0.01, *v = xy + 10 * f;
      v[0] = x, v[1] = y, v[2] = x + s, v[3] = y, v[4] = x + s, v[5] = y + s;
      v[6] = x, v[7] = y + s, v[8] = x, v[9] = y;
    }
    qk_region_t *r = one_ring_features(xy, NF, 5);
    size_t most = 0;
    for (size_t i = 0; i < r->n_leaves; i++) most = r->leaves[i].ne > most ? r->leaves[i].ne : most;
    if (most > 16) fail_msg("another square at 2^%d: a leaf holds %zu edges (C = 8)", k, most);
    for (int q = 0; q < 400; q++) {
      qk_point_t p = {qkt_rng_range(&g, -0.001, 0.011), qkt_rng_range(&g, -0.001, 0.011)};
      if (q % 4 == 0) p.x = (double)qkt_rng_below(&g, G) * cell + (q % 8 ? w : 0); /* on a side */
      uint32_t got[4], want = QK_NONE;
      size_t n = 0, nw = 0;
      for (size_t f = 0; f + 1 < NF; f++) {
        const double *v = xy + 10 * f;
        if (v[0] <= p.x && p.x <= v[2] && v[1] <= p.y && p.y <= v[5]) want = (uint32_t)f, nw++;
      }
      assert_int_equal(qk_region_locate_all(r, p, QK_BOUNDARY_CLOSED, got, 4, &n), QK_OK);
      if (n != nw || (n && got[0] != want))
        fail_msg("another square at 2^%d, point (%.17g, %.17g): %zu features (%u), brute force "
                 "%zu (%u) (seed %llu)",
                 k, p.x, p.y, n, n ? got[0] : 0, nw, want, (unsigned long long)seed);
    }
    qk_region_free(r);
  }
  free(xy);
}

/* Overlapping features: a leaf's list of the features holding its reference point that
 * equals the last leaf's is stored once (refine.c, qk__emit_leaf; on overlapping layers the
 * lists are most of the index). 40 concentric squares, each point in up to 40: fewer
 * entries stored than listed, and the answers (closed rule) against brute force. */
static void test_region_shared_lists(void **state) {
  (void)state;
  enum { NF = 40 };
  double xy[10 * NF];
  for (int f = 0; f < NF; f++) {
    const double a = f + 1, v[10] = {-a, -a, a, -a, a, a, -a, a, -a, -a};
    memcpy(xy + 10 * f, v, sizeof v);
  }
  qk_region_t *r = one_ring_features(xy, NF, 5);
  size_t listed = 0;
  for (size_t i = 0; i < r->n_leaves; i++) listed += r->leaves[i].ns;
  if (!(5 * r->n_sets < 4 * listed)) /* (a fifth saved at least) */
    fail_msg("%zu features listed, %zu stored", listed, r->n_sets);
  uint64_t seed = qkt_seed(4711);
  qkt_rng_t g;
  qkt_rng_seed(&g, seed);
  for (int k = 0; k < 3000; k++) {
    qk_point_t p = {((double)qkt_rng_below(&g, 360) - 180) / 4,
                    ((double)qkt_rng_below(&g, 360) - 180) / 4};
    uint32_t got[NF];
    size_t n = 0, nw = 0;
    assert_int_equal(qk_region_locate_all(r, p, QK_BOUNDARY_CLOSED, got, NF, &n), QK_OK);
    for (int f = 0; f < NF; f++) {
      const double a = f + 1;
      if (fabs(p.x) <= a && fabs(p.y) <= a) {
        if (nw >= n || got[nw] != (uint32_t)f)
          fail_msg("point (%g, %g): feature %d missing (seed %llu)", p.x, p.y, f,
                   (unsigned long long)seed);
        nw++;
      }
    }
    if (n != nw) fail_msg("point (%g, %g): %zu features, %zu wanted", p.x, p.y, n, nw);
  }
  qk_region_free(r);
}

/* Overlapping features (service zones, buffers): every leaf's reference point lies in
 * many of them. A leaf keeps the features with pieces in it and the lowest of the others,
 * and the rest (its cover) is stored as its change from the last checkpoint leaf's cover
 * (qk__cover_t): stored whole, the lists took leaves x overlap words (a QA helper's 1,000
 * circles round one point: 327 MB, against 42 MB so). The answers of every rule, locate
 * and locate_all, against the oracle at lattice points, vertices among them; then the
 * words stored against the lists' length. */
static void test_region_overlapping_zones(void **state) {
  (void)state;
  enum { NF = 200, SIDES = 16 };
  uint64_t seed = qkt_seed(6161);
  qkt_rng_t g;
  qkt_rng_seed(&g, seed);
  tl_t t;
  tl_init(&t);
  for (int f = 0; f < NF; f++) { /* star-shaped round points near (500, 500) */
    long p[2 * SIDES];
    long cx = 450 + (long)qkt_rng_below(&g, 101), cy = 450 + (long)qkt_rng_below(&g, 101);
    for (int k = 0; k < SIDES; k++) {
      double rad = 150 + (double)qkt_rng_below(&g, 250), a = 6.283185307179586 * k / SIDES;
      p[2 * k] = cx + lround(rad * cos(a));
      p[2 * k + 1] = cy + lround(rad * sin(a));
    }
    tl_ring(&t, p, SIDES);
    tl_end_feature(&t);
  }
  qk_region_t *r = tl_build(&t, 0, NULL, NULL);
  for (size_t v = 0; v < t.nv; v += 7) check_point(r, &t, t.xy[2 * v], t.xy[2 * v + 1], seed);
  for (int i = 0; i < 1500; i++) {
    long x = 40 + (long)qkt_rng_below(&g, 920), y = 40 + (long)qkt_rng_below(&g, 920);
    check_point(r, &t, x, y, seed);
  }
  /* The middle, inside most features: whole lists took 94 words a leaf here (2.03 million),
   * the short sets, the covers and their places take 23. */
  uint32_t all[NF];
  size_t n = 0;
  assert_int_equal(qk_region_locate_all(r, tp(500, 500), QK_BOUNDARY_SEMI_OPEN, all, NF, &n),
                   QK_OK);
  if (n < NF / 2)
    fail_msg("the middle is in %zu features only (seed %llu)", n, (unsigned long long)seed);
  size_t words = r->n_sets + r->n_cover + 2 * r->n_leaves;
  if (words > 32 * r->n_leaves)
    fail_msg("%zu words stored for %zu leaves (seed %llu)", words, r->n_leaves,
             (unsigned long long)seed);
  qk_region_free(r);
  tl_free(&t);
}

/* The refinement splits a cell while more than C edges meet it and the split makes
 * progress (refine.c, and build_top.c's one pass over the top levels, which must make the
 * same decisions). On a lattice of separated squares of 4 edges each, with C = 4, a cell
 * holding edges of two squares always separates them within the stall budget (two squares
 * 21+ units apart cannot share a quadrant for three halvings without the parent holding
 * others), so every leaf ends with at most C edges. The answers alone cannot see a cell
 * left unsplit: the mutation sweep found the leaf test of refine.c (d + 1 < maxd) and
 * build_top.c's progress test (the children's counts) free to change. */
static void test_region_leaves_split_to_capacity(void **state) {
  (void)state;
  uint64_t seed = qkt_seed(4242);
  qkt_rng_t g;
  qkt_rng_seed(&g, seed);
  for (int round = 0; round < 4; round++) {
    tl_t t;
    tl_init(&t);
    long G = 10 + 4 * round; /* G rows of G squares: one feature per row */
    for (long i = 0; i < G; i++) {
      for (long j = 0; j < G; j++) {
        long x = 100 * j + (long)qkt_rng_below(&g, 60), y = 100 * i + (long)qkt_rng_below(&g, 60);
        long sq[8] = {x, y, x + 20, y, x + 20, y + 20, x, y + 20};
        tl_ring(&t, sq, 4);
      }
      tl_end_feature(&t);
    }
    qk_region_t *r = tl_build(&t, 4, NULL, NULL);
    qk_region_stats_t st;
    qk_region_stats(r, &st);
    size_t sum = 0;
    for (size_t i = 0; i < r->n_leaves; i++) {
      if (r->leaves[i].ne > 4)
        fail_msg("seed %llu, %ld x %ld squares: leaf %zu holds %u edges (capacity 4)",
                 (unsigned long long)seed, G, G, i, (unsigned)r->leaves[i].ne);
      sum += r->leaves[i].ne;
    }
    assert_int_equal(sum, st.leaf_edges);
    /* Every square's four edges are in some leaf. */
    assert_true(st.leaf_edges >= 4 * (size_t)(G * G));
    qk_region_free(r);
    tl_free(&t);
  }
}

int main(void) {
  const struct CMUnitTest tests[] = {
      cmocka_unit_test(test_region_leaves_split_to_capacity),
      cmocka_unit_test(test_region_budget_shared_by_quadrants),
      cmocka_unit_test(test_region_cluster_far_from_the_rest),
      cmocka_unit_test(test_region_shared_lists),
      cmocka_unit_test(test_region_overlapping_zones),
      cmocka_unit_test(test_region_antimeridian_slanted),
      cmocka_unit_test(test_region_antimeridian_shared_edge),
      cmocka_unit_test(test_region_antimeridian_coverage),
      cmocka_unit_test(test_region_svg_fill),
      cmocka_unit_test(test_region_random_vs_oracle),
      cmocka_unit_test(test_region_grid_sides),
      cmocka_unit_test(test_region_build_grid_lines),
      cmocka_unit_test(test_region_coverage_grid),
      cmocka_unit_test(test_region_coverage_jittered),
      cmocka_unit_test(test_region_rules_and_windings),
      cmocka_unit_test(test_region_bowtie),
      cmocka_unit_test(test_region_self_intersecting_oracle),
      cmocka_unit_test(test_region_self_intersecting_repeats),
      cmocka_unit_test(test_region_lonlat),
      cmocka_unit_test(test_region_antimeridian_boundary),
      cmocka_unit_test(test_region_antimeridian_one_side),
      cmocka_unit_test(test_region_antimeridian_open_oracle),
      cmocka_unit_test(test_region_antimeridian_spike_open),
      cmocka_unit_test(test_region_across_map),
      cmocka_unit_test(test_region_batch_threads),
      cmocka_unit_test(test_region_batch_morton),
      cmocka_unit_test(test_region_batch_cell_sides),
      cmocka_unit_test(test_region_batch_pure_cells),
      cmocka_unit_test(test_region_without_tree),
      cmocka_unit_test(test_region_alloc_failure),
      cmocka_unit_test(test_region_geojson),
      cmocka_unit_test(test_region_geojson_surrogates_and_depth),
      cmocka_unit_test(test_region_countries),
      cmocka_unit_test(test_region_ogr),
      cmocka_unit_test(test_region_ogr_damaged),
      cmocka_unit_test(test_region_fuzz_corpus),
  };
  return cmocka_run_group_tests(tests, NULL, NULL);
}
