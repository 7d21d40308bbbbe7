/*
 * Test plan for mesh/ (quadtree mesh generation), every mesh passed through the exact,
 * independent checker of tests/support/mesh_check.c (tiling by area and edge pairing,
 * angles in [45, 90], input respected, innermost component ids, holes dropped):
 *  - the notes' example (a 1x1 component at (1,1) in a 16x16 grid);
 *  - hand-made cases: a diamond, a thin diagonal strip, components on the domain's edge,
 *    a component covering the whole domain, a nested component (innermost id), a ring
 *    with a hole, a hole in the outer face, an empty input;
 *  - random valid inputs from the polygon generator at U = 8 ... 1024;
 *  - non-uniformity: for a fixed component, doubling U adds a bounded number of
 *    triangles;
 *  - the statistics' smallest and largest angle equal every triangle's angles' extremes,
 *    by brute force (to the last bit), with and without holes;
 *  - vertices are numbered in order of first use by the triangles, every one used (the
 *    triangulation numbers them as it makes the triangles; a scan says so);
 *  - the subdivision is a quadkit tree: qk_tree_check() passes and it is balanced;
 *  - allocation failure at every N: QK_ERR_NOMEM, no leak;
 *  - the writers: counts and headers of .node, .ele, .msh, .vtu, and an SVG.
 */
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "mesh_check.h"
#include "polygen.h"
#include "qk_test.h"

/*
 * The leaves the statistics report are the tree's (qk_tree_leaves), and, when every
 * triangle is kept (`all_kept`: no holes), the triangles come leaf by leaf in
 * qk_tree_leaves' order: the leaf holding each triangle's centroid (found by point
 * location, apart from the generator's own walk) never goes back in that order.
 */
static void check_leaf_order(const qk_mesh_t *m, const qk_mesh_stats_t *s, int all_kept,
                             const char *what) {
  const qk_tree_t *t = qk_mesh_tree(m);
  size_t nl = 0;
  assert_int_equal(qk_tree_leaves(t, NULL, 0, &nl), QK_OK);
  if (s->leaves != nl) fail_msg("%s: stats say %zu leaves, the tree has %zu", what, s->leaves, nl);
  if (!all_kept) return;
  qk_node_t *leaves = malloc((nl + 1) * sizeof *leaves);
  assert_non_null(leaves);
  assert_int_equal(qk_tree_leaves(t, leaves, nl, &nl), QK_OK);
  qk_node_t top = 0;
  for (size_t i = 0; i < nl; i++)
    if (leaves[i] > top) top = leaves[i];
  size_t *pos = malloc(((size_t)top + 1) * sizeof *pos);
  assert_non_null(pos);
  for (size_t i = 0; i < nl; i++) pos[leaves[i]] = i;
  size_t nv, nt;
  const double *xy = qk_mesh_vertices(m, &nv);
  const uint32_t *tri = qk_mesh_triangles(m, &nt);
  size_t last = 0;
  for (size_t k = 0; k < nt; k++) {
    const uint32_t *v = &tri[3 * k];
    qk_point_t c = {(xy[2 * v[0]] + xy[2 * v[1]] + xy[2 * v[2]]) / 3,
                    (xy[2 * v[0] + 1] + xy[2 * v[1] + 1] + xy[2 * v[2] + 1]) / 3};
    qk_node_t leaf;
    assert_int_equal(qk_tree_find_leaf(t, c, &leaf), QK_OK);
    assert_true(leaf <= top);
    if (pos[leaf] < last)
      fail_msg("%s: triangle %zu lies in leaf %zu of the tree's order, after leaf %zu", what, k,
               pos[leaf], last);
    last = pos[leaf];
  }
  free(pos);
  free(leaves);
}

/* Does some lattice point of a segment (integer endpoints, at 0, 45, 90 or 135 degrees)
 * lie in the closed square [x0, x0 + s]^2? Such a segment meets the square exactly then:
 * between two consecutive lattice points it runs along a unit side or inside a unit cell. */
static int seg_meets_square(const double *a, const double *b, int64_t x0, int64_t y0, int64_t s) {
  int64_t ax = (int64_t)a[0], ay = (int64_t)a[1], dx = (int64_t)b[0] - ax, dy = (int64_t)b[1] - ay;
  int64_t n = llabs(dx) > llabs(dy) ? llabs(dx) : llabs(dy);
  for (int64_t k = 0; k <= n; k++) {
    int64_t x = ax + (n ? k * dx / n : 0), y = ay + (n ? k * dy / n : 0);
    if (x >= x0 && x <= x0 + s && y >= y0 && y <= y0 + s) return 1;
  }
  return 0;
}

/* Leaves of the book's subdivision before balancing, by brute force: a square is split
 * while larger than unit size and some segment meets its closure. */
static size_t book_leaves(const double *xy, const uint32_t *seg, size_t ns, int64_t x0, int64_t y0,
                          int64_t s) {
  int meets = 0;
  for (size_t i = 0; i < ns && !meets && s > 1; i++)
    meets = seg_meets_square(&xy[2 * seg[2 * i]], &xy[2 * seg[2 * i + 1]], x0, y0, s);
  if (!meets) return 1;
  int64_t h = s / 2;
  return book_leaves(xy, seg, ns, x0, y0, h) + book_leaves(xy, seg, ns, x0 + h, y0, h) +
         book_leaves(xy, seg, ns, x0, y0 + h, h) + book_leaves(xy, seg, ns, x0 + h, y0 + h, h);
}

/* The statistics' smallest and largest angle against every triangle's three angles, by
 * brute force over the mesh as returned: on doubled coordinates, which are integers in the
 * book's mode, with atan2 of |cross| and dot as the statistics document, so the extremes
 * must agree to the last bit (the generator takes them from the few triangle shapes a
 * quadtree mesh has, not from every triangle). */
static void check_angle_extremes(const qk_mesh_t *m, const qk_mesh_stats_t *s, const char *what) {
  size_t nv, nt;
  const double *xy = qk_mesh_vertices(m, &nv);
  const uint32_t *tri = qk_mesh_triangles(m, &nt);
  double lo = 180, hi = 0;
  for (size_t k = 0; k < nt; k++)
    for (int i = 0; i < 3; i++) {
      const double *a = &xy[2 * tri[3 * k + (i + 2) % 3]], *b = &xy[2 * tri[3 * k + i]],
                   *c = &xy[2 * tri[3 * k + (i + 1) % 3]];
      int64_t ux = (int64_t)(2 * a[0]) - (int64_t)(2 * b[0]);
      int64_t uy = (int64_t)(2 * a[1]) - (int64_t)(2 * b[1]);
      int64_t wx = (int64_t)(2 * c[0]) - (int64_t)(2 * b[0]);
      int64_t wy = (int64_t)(2 * c[1]) - (int64_t)(2 * b[1]);
      double dux = (double)ux, duy = (double)uy, dwx = (double)wx, dwy = (double)wy;
      double ang = atan2(fabs(dux * dwy - duy * dwx), dux * dwx + duy * dwy) *
                   (180.0 / 3.14159265358979323846);
      if (ang < lo) lo = ang;
      if (ang > hi) hi = ang;
    }
  if (!nt) lo = hi = 0;
  if (s->min_angle_deg != lo || s->max_angle_deg != hi)
    fail_msg("%s: statistics say angles %.17g..%.17g, the triangles %.17g..%.17g", what,
             s->min_angle_deg, s->max_angle_deg, lo, hi);
}

/* The vertices are numbered in order of first use by the triangles, and all are used:
 * scanning the triangles, each vertex first met is the next number. */
static void check_first_use(const qk_mesh_t *m, const char *what) {
  size_t nv, nt;
  qk_mesh_vertices(m, &nv);
  const uint32_t *tri = qk_mesh_triangles(m, &nt);
  size_t next = 0;
  for (size_t i = 0; i < 3 * nt; i++) {
    if (tri[i] > next)
      fail_msg("%s: corner %zu is vertex %u before vertex %zu was used", what, i, tri[i], next);
    if (tri[i] == next) next++;
  }
  if (next != nv) fail_msg("%s: %zu vertices, %zu used", what, nv, next);
}

/* Mesh an input given as arrays and run the checker; returns the triangle count. */
static size_t mesh_and_check(const double *xy, size_t nv, const uint32_t *seg, size_t ns,
                             const double *holes, size_t nh, uint64_t U, const char *what) {
  qk_poly_t *p;
  assert_int_equal(qk_poly_from_arrays(xy, nv, seg, ns, holes, nh, NULL, &p, NULL), QK_OK);
  qk_mesh_options_t o;
  qk_mesh_options_init(&o);
  o.size = U;
  qk_mesh_t *m;
  qk_mesh_error_t err;
  qk_status_t st = qk_mesh_generate(p, &o, &m, &err);
  if (st != QK_OK) fail_msg("%s: %s: %s", what, qk_strerror(st), err.message);
  QKT_CHECK_TREE(qk_mesh_tree(m));
  assert_true(qk_tree_is_balanced(qk_mesh_tree(m)));
  mc_input_t in = {xy, nv, seg, ns, holes, nh, U};
  mc_mesh_t mm;
  mm.xy = qk_mesh_vertices(m, &mm.nv);
  mm.tri = qk_mesh_triangles(m, &mm.nt);
  mm.comp = qk_mesh_triangle_components(m, NULL);
  char msg[512];
  if (mc_check(&in, &mm, msg, sizeof msg))
    fail_msg("%s (U=%llu): %s", what, (unsigned long long)U, msg);
  qk_mesh_stats_t s;
  qk_mesh_stats(m, &s);
  assert_int_equal(s.triangles, mm.nt);
  if (mm.nt) assert_true(s.min_angle_deg > 44.999 && s.max_angle_deg < 90.001);
  check_angle_extremes(m, &s, what);
  check_first_use(m, what);
  check_leaf_order(m, &s, nh == 0, what);
  if (U <= 256 && ns <= 64) {
    size_t want = book_leaves(xy, seg, ns, 0, 0, (int64_t)U);
    if (s.leaves_before_balance != want)
      fail_msg("%s: %zu leaves before balancing, brute force says %zu", what,
               s.leaves_before_balance, want);
  }
  size_t nt = mm.nt;
  qk_mesh_free(m);
  qk_poly_free(p);
  return nt;
}

static void poly_close(uint32_t *seg, size_t *ns, uint32_t first, uint32_t n) {
  for (uint32_t i = 0; i < n; i++) {
    seg[2 * *ns] = first + i;
    seg[2 * *ns + 1] = first + (i + 1) % n;
    (*ns)++;
  }
}

static void test_mesh_notes_example(void **state) {
  (void)state;
  double xy[] = {1, 1, 2, 1, 2, 2, 1, 2};
  uint32_t seg[8];
  size_t ns = 0;
  poly_close(seg, &ns, 0, 4);
  size_t nt = mesh_and_check(xy, 4, seg, ns, NULL, 0, 16, "notes example");
  assert_true(nt < 512 / 4); /* far fewer than the 512 uniform triangles */
}

static void test_mesh_hand_made(void **state) {
  (void)state;
  /* A diamond. */
  double d[] = {8, 2, 14, 8, 8, 14, 2, 8};
  uint32_t seg[64];
  size_t ns = 0;
  poly_close(seg, &ns, 0, 4);
  mesh_and_check(d, 4, seg, ns, NULL, 0, 16, "diamond");
  mesh_and_check(d, 4, seg, ns, NULL, 0, 64, "diamond U=64");
  /* A thin diagonal strip of width one. */
  double s[] = {2, 1, 3, 1, 14, 12, 13, 12};
  mesh_and_check(s, 4, seg, ns, NULL, 0, 16, "thin strip");
  /* The anti-diagonal strip, touching the domain's edge at both ends. */
  double s2[] = {15, 0, 16, 0, 1, 15, 0, 15};
  mesh_and_check(s2, 4, seg, ns, NULL, 0, 16, "anti-diagonal strip");
  /* The whole domain as one component, and a triangle in a corner. */
  double w[] = {0, 0, 8, 0, 8, 8, 0, 8};
  mesh_and_check(w, 4, seg, ns, NULL, 0, 8, "whole domain");
  double tri[] = {0, 0, 4, 0, 0, 4};
  ns = 0;
  poly_close(seg, &ns, 0, 3);
  mesh_and_check(tri, 3, seg, ns, NULL, 0, 16, "corner triangle");
  /* A nested component not touching its parent: triangles take the innermost id. */
  double nest[] = {2, 2, 14, 2, 14, 14, 2, 14, 6, 6, 10, 6, 10, 10, 6, 10, 7, 8, 8, 7, 9, 8, 8, 9};
  ns = 0;
  poly_close(seg, &ns, 0, 4);
  poly_close(seg, &ns, 4, 4);
  poly_close(seg, &ns, 8, 4);
  mesh_and_check(nest, 12, seg, ns, NULL, 0, 16, "nested");
  /* A ring: the inner square's inside is a hole; then a hole in the outer face. */
  double ring[] = {2, 2, 14, 2, 14, 14, 2, 14, 5, 5, 11, 5, 11, 11, 5, 11};
  ns = 0;
  poly_close(seg, &ns, 0, 4);
  poly_close(seg, &ns, 4, 4);
  double h1[] = {8, 8};
  size_t with_hole = mesh_and_check(ring, 8, seg, ns, h1, 1, 16, "ring with hole");
  size_t without = mesh_and_check(ring, 8, seg, ns, NULL, 0, 16, "ring");
  assert_true(with_hole < without);
  double h2[] = {0.5, 0.5, 8, 8};
  mesh_and_check(ring, 8, seg, ns, h2, 2, 16, "outer face and inner holes");
  /* A band across the domain cuts the outside in two: a hole below it removes only the
   * lower part. */
  double band[] = {0, 6, 16, 6, 16, 8, 0, 8};
  ns = 0;
  poly_close(seg, &ns, 0, 4);
  double h3[] = {8, 2};
  size_t all = mesh_and_check(band, 4, seg, ns, NULL, 0, 16, "band");
  size_t part = mesh_and_check(band, 4, seg, ns, h3, 1, 16, "band, hole below");
  assert_true(part < all && part > all / 3);
  /* No components at all: two triangles. */
  assert_int_equal(mesh_and_check(NULL, 0, NULL, 0, NULL, 0, 4, "empty"), 2);
}

/* Exact brute-force oracle for the input rules: do segments i and j (0-based pairs into
 * xy) meet other than at a shared vertex of consecutive, non-overlapping segments? */
static int64_t orient3(const int64_t *a, const int64_t *b, const int64_t *c) {
  int64_t v = (b[0] - a[0]) * (c[1] - a[1]) - (b[1] - a[1]) * (c[0] - a[0]);
  return (v > 0) - (v < 0);
}
static int on_seg(const int64_t *a, const int64_t *b, const int64_t *c) {
  return orient3(a, b, c) == 0 && c[0] >= (a[0] < b[0] ? a[0] : b[0]) &&
         c[0] <= (a[0] > b[0] ? a[0] : b[0]) && c[1] >= (a[1] < b[1] ? a[1] : b[1]) &&
         c[1] <= (a[1] > b[1] ? a[1] : b[1]);
}
static void test_mesh_random(void **state) {
  (void)state;
  uint64_t seed = qkt_seed(424242);
  qkt_rng_t r;
  qkt_rng_seed(&r, seed);
  static const uint64_t sizes[] = {8, 16, 32, 64, 256, 1024};
  for (int round = 0; round < 96; round++) {
    uint64_t U = sizes[round % 6];
    pg_input_t in;
    pg_generate(&r, U, 1 + qkt_rng_below(&r, U >= 256 ? 24 : 8), &in);
    char what[96];
    snprintf(what, sizeof what, "random seed %llu round %d", (unsigned long long)seed, round);
    /* Every third round, up to two hole points on the half-integer lattice, away from
     * every segment. */
    double holes[4];
    size_t nh = 0;
    for (int tries = 0; round % 3 == 0 && nh < 2 && tries < 50; tries++) {
      int64_t h[2] = {qkt_rng_below(&r, (uint32_t)(2 * U + 1)),
                      qkt_rng_below(&r, (uint32_t)(2 * U + 1))};
      int on = 0;
      for (size_t i = 0; i < in.ns && !on; i++) {
        int64_t a[2] = {2 * (int64_t)in.xy[2 * in.seg[2 * i]],
                        2 * (int64_t)in.xy[2 * in.seg[2 * i] + 1]};
        int64_t b[2] = {2 * (int64_t)in.xy[2 * in.seg[2 * i + 1]],
                        2 * (int64_t)in.xy[2 * in.seg[2 * i + 1] + 1]};
        on = on_seg(a, b, h);
      }
      if (!on) holes[2 * nh] = (double)h[0] / 2, holes[2 * nh + 1] = (double)h[1] / 2, nh++;
    }
    mesh_and_check(in.xy, in.nv, in.seg, in.ns, nh ? holes : NULL, nh, U, what);
    pg_free(&in);
  }
}

/* Do segments i and j break the input rules? */
static int bad_pair(const int64_t *P, const uint32_t *seg, size_t i, size_t j) {
  const int64_t *a = &P[2 * seg[2 * i]], *b = &P[2 * seg[2 * i + 1]];
  const int64_t *c = &P[2 * seg[2 * j]], *d = &P[2 * seg[2 * j + 1]];
  for (int u = 0; u < 2; u++)
    for (int v = 0; v < 2; v++)
      if (seg[2 * i + u] == seg[2 * j + v]) {
        const int64_t *o = &P[2 * seg[2 * i + u]], *p = &P[2 * seg[2 * i + 1 - u]],
                      *q = &P[2 * seg[2 * j + 1 - v]];
        /* Overlap iff the far ends lie on one ray from the shared vertex. */
        return orient3(o, p, q) == 0 &&
               (p[0] - o[0]) * (q[0] - o[0]) + (p[1] - o[1]) * (q[1] - o[1]) > 0;
      }
  int64_t o1 = orient3(a, b, c), o2 = orient3(a, b, d), o3 = orient3(c, d, a),
          o4 = orient3(c, d, b);
  if (o1 * o2 < 0 && o3 * o4 < 0) return 1;
  return on_seg(a, b, c) || on_seg(a, b, d) || on_seg(c, d, a) || on_seg(c, d, b);
}

/* Random octagons placed without care: the generator must accept exactly the inputs
 * the brute-force oracle finds valid, and mesh those correctly. */
static void test_mesh_random_validity(void **state) {
  (void)state;
  uint64_t seed = qkt_seed(99);
  qkt_rng_t r;
  qkt_rng_seed(&r, seed);
  size_t valid = 0, invalid = 0;
  for (int round = 0; round < 300; round++) {
    pg_input_t in;
    memset(&in, 0, sizeof in);
    int k = 1 + (int)qkt_rng_below(&r, 4);
    for (int i = 0; i < k; i++) {
      int64_t x0 = qkt_rng_below(&r, 24), y0 = qkt_rng_below(&r, 24);
      int64_t w = 1 + qkt_rng_below(&r, 8), h = 1 + qkt_rng_below(&r, 8), mn = w < h ? w : h;
      int64_t c = qkt_rng_below(&r, (uint32_t)(mn / 2 + 1));
      int64_t o[16] = {x0 + c, y0,         x0 + w - c, y0,     x0 + w, y0 + c,
                       x0 + w, y0 + h - c, x0 + w - c, y0 + h, x0 + c, y0 + h,
                       x0,     y0 + h - c, x0,         y0 + c};
      pg_add_polygon(&in, o, 8);
    }
    int64_t *P = malloc((2 * in.nv + 2) * sizeof *P);
    assert_non_null(P);
    for (size_t i = 0; i < 2 * in.nv; i++) P[i] = (int64_t)in.xy[i];
    int ok = 1;
    for (size_t i = 0; i < in.ns && ok; i++)
      for (size_t j = i + 1; j < in.ns && ok; j++) ok = !bad_pair(P, in.seg, i, j);
    qk_poly_t *p;
    assert_int_equal(qk_poly_from_arrays(in.xy, in.nv, in.seg, in.ns, NULL, 0, NULL, &p, NULL),
                     QK_OK);
    qk_mesh_options_t o;
    qk_mesh_options_init(&o);
    o.size = 32;
    qk_mesh_t *m = NULL;
    qk_mesh_error_t err;
    qk_status_t st = qk_mesh_generate(p, &o, &m, &err);
    if (ok && st != QK_OK)
      fail_msg("seed %llu round %d: valid input rejected: %s", (unsigned long long)seed, round,
               err.message);
    if (!ok && st != QK_ERR_GEOMETRY)
      fail_msg("seed %llu round %d: invalid input gave %s", (unsigned long long)seed, round,
               qk_strerror(st));
    if (ok) {
      mc_input_t ci = {in.xy, in.nv, in.seg, in.ns, NULL, 0, 32};
      mc_mesh_t mm;
      mm.xy = qk_mesh_vertices(m, &mm.nv);
      mm.tri = qk_mesh_triangles(m, &mm.nt);
      mm.comp = qk_mesh_triangle_components(m, NULL);
      char msg[512];
      if (mc_check(&ci, &mm, msg, sizeof msg))
        fail_msg("seed %llu round %d: %s", (unsigned long long)seed, round, msg);
    }
    valid += ok, invalid += !ok;
    qk_mesh_free(m);
    qk_poly_free(p);
    free(P);
    pg_free(&in);
  }
  print_message("%zu valid, %zu invalid inputs\n", valid, invalid);
  assert_true(valid > 20 && invalid > 20);
}

/* Doubling U for a fixed component adds a bounded number of triangles: the mesh grows
 * with the logarithm of U, not with U^2. */
static void test_mesh_non_uniform(void **state) {
  (void)state;
  double xy[] = {1, 1, 3, 1, 4, 2, 4, 3, 2, 3, 1, 2};
  uint32_t seg[12];
  size_t ns = 0;
  poly_close(seg, &ns, 0, 6);
  size_t prev = 0, first_step = 0;
  for (uint64_t U = 8; U <= (1u << 14); U *= 2) {
    size_t nt = mesh_and_check(xy, 6, seg, ns, NULL, 0, U, "non-uniform");
    if (prev) {
      size_t step = nt - prev;
      if (!first_step) first_step = step;
      if (step > first_step + 16)
        fail_msg("U=%llu: %zu triangles added", (unsigned long long)U, step);
    }
    prev = nt;
  }
}

static void test_mesh_alloc_failure(void **state) {
  (void)state;
  double xy[] = {2, 2, 6, 2, 6, 6, 2, 6, 3, 4, 4, 3, 5, 4, 4, 5};
  uint32_t seg[16];
  size_t ns = 0;
  poly_close(seg, &ns, 0, 4);
  poly_close(seg, &ns, 4, 4);
  double hole[] = {4, 4};
  for (size_t fail_at = 1;; fail_at++) {
    qkt_alloc_t st;
    qk_allocator_t a = qkt_alloc_make(&st);
    st.fail_at = fail_at;
    qk_poly_t *p = NULL;
    qk_mesh_t *m = NULL;
    qk_status_t s = qk_poly_from_arrays(xy, 8, seg, ns, hole, 1, &a, &p, NULL);
    if (s == QK_OK) {
      qk_mesh_options_t o;
      qk_mesh_options_init(&o);
      o.size = 8;
      o.allocator = &a;
      qk_mesh_error_t err;
      s = qk_mesh_generate(p, &o, &m, &err);
      if (s == QK_OK) {
        FILE *f = tmpfile();
        assert_non_null(f);
        s = qk_mesh_write_msh(m, f);
        fclose(f);
      }
    }
    qk_mesh_free(m);
    qk_poly_free(p);
    assert_int_equal(st.live_bytes, 0);
    assert_int_equal(st.live_blocks, 0);
    if (!st.failed) {
      assert_int_equal(s, QK_OK);
      break;
    }
    /* A failed allocation that only gives back slack (the tree shrinks its arrays) may
     * leave the call successful. */
    if (s != QK_OK && s != QK_ERR_NOMEM)
      fail_msg("failing allocation %zu: status %s", fail_at, qk_strerror(s));
    assert_true(fail_at < 5000);
  }
}

/* Read a whole stream back into memory. */
static char *slurp(FILE *f) {
  long n = ftell(f);
  rewind(f);
  char *b = malloc((size_t)n + 1);
  assert_non_null(b);
  assert_int_equal(fread(b, 1, (size_t)n, f), (size_t)n);
  b[n] = '\0';
  return b;
}

static void test_mesh_writers(void **state) {
  (void)state;
  double xy[] = {1, 1, 2, 1, 2, 2, 1, 2};
  uint32_t seg[8];
  size_t ns = 0;
  poly_close(seg, &ns, 0, 4);
  qk_poly_t *p;
  assert_int_equal(qk_poly_from_arrays(xy, 4, seg, ns, NULL, 0, NULL, &p, NULL), QK_OK);
  qk_mesh_options_t o;
  qk_mesh_options_init(&o);
  o.size = 16;
  qk_mesh_t *m;
  assert_int_equal(qk_mesh_generate(p, &o, &m, NULL), QK_OK);
  size_t nv, nt;
  const double *v = qk_mesh_vertices(m, &nv);
  const uint32_t *t = qk_mesh_triangles(m, &nt);
  const uint32_t *c = qk_mesh_triangle_components(m, NULL);

  /* .node and .ele, first index 1: read back and compare. */
  FILE *f = tmpfile();
  assert_int_equal(qk_mesh_write_node(m, f, 1), QK_OK);
  rewind(f);
  size_t n;
  int d, a, b;
  assert_int_equal(fscanf(f, "%zu %d %d %d", &n, &d, &a, &b), 4);
  assert_int_equal(n, nv);
  for (size_t i = 0; i < nv; i++) {
    size_t id;
    double x, y;
    assert_int_equal(fscanf(f, "%zu %lf %lf", &id, &x, &y), 3);
    assert_int_equal(id, i + 1);
    assert_true(x == v[2 * i] && y == v[2 * i + 1]);
  }
  fclose(f);
  f = tmpfile();
  assert_int_equal(qk_mesh_write_ele(m, f, 1), QK_OK);
  rewind(f);
  assert_int_equal(fscanf(f, "%zu %d %d", &n, &d, &a), 3);
  assert_int_equal(n, nt);
  assert_int_equal(d, 3);
  assert_int_equal(a, 1);
  for (size_t i = 0; i < nt; i++) {
    unsigned long id, x, y, z, k;
    assert_int_equal(fscanf(f, "%lu %lu %lu %lu %lu", &id, &x, &y, &z, &k), 5);
    assert_true(x == t[3 * i] + 1 && y == t[3 * i + 1] + 1 && z == t[3 * i + 2] + 1);
    assert_true(k == c[i]);
  }
  fclose(f);

  /* gmsh and VTK: structure and counts. */
  f = tmpfile();
  assert_int_equal(qk_mesh_write_msh(m, f), QK_OK);
  char *s = slurp(f);
  fclose(f);
  assert_non_null(strstr(s, "$MeshFormat\n4.1 0 8\n"));
  assert_non_null(strstr(s, "\"component_1\""));
  assert_non_null(strstr(s, "\"outside\""));
  char want[64];
  snprintf(want, sizeof want, "$Elements\n2 %zu 1 %zu\n", nt, nt);
  assert_non_null(strstr(s, want));
  free(s);
  f = tmpfile();
  assert_int_equal(qk_mesh_write_vtu(m, f), QK_OK);
  s = slurp(f);
  fclose(f);
  snprintf(want, sizeof want, "NumberOfPoints=\"%zu\" NumberOfCells=\"%zu\"", nv, nt);
  assert_non_null(strstr(s, want));
  assert_non_null(strstr(s, "Name=\"component\""));
  free(s);
  f = tmpfile();
  assert_int_equal(qk_mesh_write_svg(m, f, 400), QK_OK);
  s = slurp(f);
  fclose(f);
  assert_non_null(strstr(s, "<svg"));
  assert_non_null(strstr(s, "</svg>"));
  free(s);
  qk_mesh_free(m);
  qk_poly_free(p);
}

/* The checker is not vacuous: damaged copies of a good mesh are rejected. */
static void test_mesh_checker_rejects(void **state) {
  (void)state;
  double xy[] = {2, 2, 6, 2, 6, 6, 2, 6, 3, 4, 4, 3, 5, 4, 4, 5};
  uint32_t seg[16];
  size_t ns = 0;
  poly_close(seg, &ns, 0, 4);
  poly_close(seg, &ns, 4, 4);
  qk_poly_t *p;
  assert_int_equal(qk_poly_from_arrays(xy, 8, seg, ns, NULL, 0, NULL, &p, NULL), QK_OK);
  qk_mesh_options_t o;
  qk_mesh_options_init(&o);
  o.size = 8;
  qk_mesh_t *m;
  assert_int_equal(qk_mesh_generate(p, &o, &m, NULL), QK_OK);
  size_t nv, nt;
  const double *v = qk_mesh_vertices(m, &nv);
  const uint32_t *t = qk_mesh_triangles(m, &nt);
  const uint32_t *c = qk_mesh_triangle_components(m, NULL);
  double *v2 = malloc(2 * nv * sizeof *v2);
  uint32_t *t2 = malloc(3 * nt * sizeof *t2), *c2 = malloc(nt * sizeof *c2);
  assert_non_null(v2);
  assert_non_null(t2);
  assert_non_null(c2);
  mc_input_t in = {xy, 8, seg, ns, NULL, 0, 8};
  char msg[256];
  for (int damage = 0; damage < 6; damage++) {
    memcpy(v2, v, 2 * nv * sizeof *v2);
    memcpy(t2, t, 3 * nt * sizeof *t2);
    memcpy(c2, c, nt * sizeof *c2);
    mc_mesh_t mm = {v2, nv, t2, c2, nt};
    switch (damage) {
    case 0:
      break; /* the undamaged mesh passes */
    case 1: {
      uint32_t x = t2[0];
      t2[0] = t2[1], t2[1] = x;
    } break; /* clockwise */
    case 2:
      mm.nt--;
      break; /* a gap */
    case 3:
      c2[nt / 2] = c2[nt / 2] == 2 ? 1 : 2;
      break; /* a wrong component */
    case 4:
      v2[0] += 0.5;
      break; /* a moved vertex */
    case 5:
      v2[1] += 0.25;
      break; /* off the lattice */
    }
    int bad = mc_check(&in, &mm, msg, sizeof msg);
    if (bad != (damage != 0)) fail_msg("damage %d: checker said %d (%s)", damage, bad, msg);
  }
  free(v2), free(t2), free(c2);
  qk_mesh_free(m);
  qk_poly_free(p);
}

int main(void) {
  const struct CMUnitTest tests[] = {
      cmocka_unit_test(test_mesh_notes_example), cmocka_unit_test(test_mesh_hand_made),
      cmocka_unit_test(test_mesh_random),        cmocka_unit_test(test_mesh_random_validity),
      cmocka_unit_test(test_mesh_non_uniform),   cmocka_unit_test(test_mesh_alloc_failure),
      cmocka_unit_test(test_mesh_writers),       cmocka_unit_test(test_mesh_checker_rejects),
  };
  return cmocka_run_group_tests(tests, NULL, NULL);
}
