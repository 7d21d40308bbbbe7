/*
 * Test plan for the collider's ray cast at the edges of its float pruning
 * (collide/collider.c, "How the ray cast prunes in float"):
 *  - the oracle is brute force over every item with the library's own item tests (the
 *    same double operations, written out again here), so pruning that lost a node would
 *    show as a different id or t, and the answers must agree exactly, t to the last bit;
 *  - scenes of boxes sharing edges at coordinates that are not floats (multiples of 0.1),
 *    discs tangent to boxes and to each other, discs only and mixed, deep trees
 *    (capacity 1 and 3);
 *  - rays along box edges (axis-parallel, the general test, and tilted by 2^-60 and
 *    2^-101, on either side of the float test's range), through box corners, tangent to
 *    discs, from inside boxes and discs, axis-parallel from anywhere, and random;
 *  - the same scenes and rays scaled by 1e-30, 1e25, 1e35 (beyond the float test's
 *    range: the general test), 1e60, and moved by 1e7 and 1e5 (float boxes far coarser
 *    than the items), with directions scaled by 1e20 and 1e-20 (parameters that overflow
 *    and underflow a float) and 1e-35 (the general test), and tmax cut-offs;
 *  - the quantised node boxes at their edges: items stacked on one point (zero extent,
 *    leaves past the depth cap), boxes of zero width and height on one line, items whose
 *    sides fall exactly on and just off power-of-two grid values, far from the origin and
 *    near it; rays along those sides and through those points;
 *  - trees deeper than the 32 bits of the ray's descent (pairs of discs 2^-45 apart, depth
 *    cap 60) and a given root square whose halvings are not exact (corner -0.3, side
 *    1.7), with rays from inside and outside the root;
 *  - the climbs' stop (computed in the path's 32-bit fixed point): discs centred a
 *    fraction of 2^-32 beyond a square's side, hit from the other side with tmax at the
 *    hit, which only a climb past that square finds;
 *  - the batch call (which reorders its rays by origin) against single calls;
 *  - ties: every disc three times at shuffled ids, so that each hit is decided by the
 *    smallest id among equal t;
 *  - a scene as large as the benchmark's in its ray arrays' size (70,000 discs, over the
 *    2 MiB from which the cast asks for lines ahead), discs only, with boxes, and built
 *    on two threads (the entries' parents, which the climbs read, filled by subtrees),
 *    rays from anywhere, from disc centres and along the leaves' split lines: the paths that only
 *    large colliders take (the prefetches read the nodes above the start); and the batch
 *    call there (rays sorted by origin) against single calls.
 */
#include <math.h>
#include <stdio.h>
#include <stdlib.h>

#include "qk_test.h"
#include "query_oracle.h"

static uint64_t g_seed;

/* The library's box test (collider.c ray_box: the slab test by division). */
static int bf_axis(double mn, double mx, double o, double d, double *lo, double *hi) {
  if (d == 0) return !(o < mn || o > mx);
  double t1 = (mn - o) / d, t2 = (mx - o) / d;
  if (t1 > t2) {
    double s = t1;
    t1 = t2;
    t2 = s;
  }
  if (t1 > *lo) *lo = t1;
  if (t2 < *hi) *hi = t2;
  return 1;
}

static double bf_ray_box(qk_box_t b, qk_point_t o, qk_point_t v, double tmax) {
  double lo = 0.0, hi = tmax;
  if (!bf_axis(b.xmin, b.xmax, o.x, v.x, &lo, &hi) || !bf_axis(b.ymin, b.ymax, o.y, v.y, &lo, &hi))
    return -1.0;
  return lo > hi ? -1.0 : lo;
}

/* Smallest t, then smallest id, over all items (discs are ids 0 .. nd - 1). */
static qk_hit_t brute(const qk_disc_t *d, size_t nd, const qk_box_t *b, size_t nb, qk_point_t o,
                      qk_point_t v, double tmax) {
  qk_hit_t h = {QK_NONE, INFINITY};
  for (size_t i = 0; i < nd + nb; i++) {
    double t = i < nd ? qko_ray_disc_bits(d[i], o, v, tmax) : bf_ray_box(b[i - nd], o, v, tmax);
    if (t >= 0 && (t < h.t || (t == h.t && (qk_id_t)i < h.id))) {
      h.t = t;
      h.id = (qk_id_t)i;
    }
  }
  return h;
}

/* One cast against brute force; variant and ray number name it in a failure. */
static void expect_brute(const qk_collider_t *c, const qk_disc_t *d, size_t nd, const qk_box_t *b,
                         size_t nb, qk_point_t o, qk_point_t v, double tmax, int variant, int i) {
  qk_hit_t h, w = brute(d, nd, b, nb, o, v, tmax);
  assert_int_equal(qk_collider_raycast(c, o, v, tmax, &h), QK_OK);
  if (h.id != w.id || !(h.t == w.t || (isinf(h.t) && isinf(w.t))))
    fail_msg("variant %d ray %d (o %.17g %.17g, d %.17g %.17g, tmax %g): hit (%u, %.17g) vs "
             "brute force (%u, %.17g) (seed %llu)",
             variant, i, o.x, o.y, v.x, v.y, tmax, h.id, h.t, w.id, w.t,
             (unsigned long long)g_seed);
}

enum { NB_MAX = 200, ND_MAX = 300, N_RAYS = 700 };

/* Boxes on a 0.1 grid sharing edges (some cells left out), discs tangent to boxes'
 * right sides and to each other, and random discs. */
static void make_scene(qkt_rng_t *r, qk_disc_t *d, size_t *nd, qk_box_t *b, size_t *nb,
                       int with_boxes) {
  *nb = 0;
  if (with_boxes)
    for (int i = 0; i < 14 && *nb < NB_MAX; i++)
      for (int j = 0; j < 14 && *nb < NB_MAX; j++)
        if (qkt_rng_below(r, 3) != 0)
          b[(*nb)++] = (qk_box_t){0.1 * i, 0.1 * j, 0.1 * (i + 1), 0.1 * j + 0.1 * (1 + (i & 1))};
  *nd = 0;
  for (size_t k = 0; k < (with_boxes ? 60u : 150u) && *nb > 0; k++) {
    const qk_box_t *bx = &b[qkt_rng_below(r, (uint32_t)*nb)];
    double rad = qkt_rng_range(r, 0.001, 0.04);
    d[(*nd)++] = (qk_disc_t){bx->xmax + rad, 0.5 * (bx->ymin + bx->ymax), rad};
  }
  while (*nd < ND_MAX - 40) {
    double rad = qkt_rng_below(r, 10) == 0 ? 0.0 : qkt_rng_range(r, 0, 0.05);
    d[(*nd)++] = (qk_disc_t){qkt_rng_range(r, 0, 1.4), qkt_rng_range(r, 0, 1.4), rad};
    if (*nd % 7 == 0) { /* a tangent neighbour */
      qk_disc_t p = d[*nd - 1];
      d[(*nd)++] = (qk_disc_t){p.x + p.r + 0.03, p.y, 0.03};
    }
  }
}

/* Ray i of a scene in its own coordinates (before scaling). */
static void make_ray(qkt_rng_t *r, int i, const qk_disc_t *d, size_t nd, const qk_box_t *b,
                     size_t nb, qk_point_t *o, qk_point_t *v, double *tmax) {
  static const double tilt[3] = {0.0, 0x1p-60, 0x1p-101};
  const double e = tilt[qkt_rng_below(r, 3)] * (qkt_rng_below(r, 2) ? 1 : -1);
  const double sgn = qkt_rng_below(r, 2) ? 1.0 : -1.0;
  double ang = qkt_rng_range(r, 0, 6.283185307179586);
  *o = (qk_point_t){qkt_rng_range(r, -0.2, 1.6), qkt_rng_range(r, -0.2, 1.6)};
  *v = (qk_point_t){cos(ang), sin(ang)};
  const qk_box_t *bx = nb ? &b[qkt_rng_below(r, (uint32_t)nb)] : NULL;
  const qk_disc_t *dc = &d[qkt_rng_below(r, (uint32_t)nd)];
  switch (i % 8) {
  case 1: /* along a horizontal edge, from either end */
    if (!bx) break;
    *o = (qk_point_t){sgn > 0 ? bx->xmin - 0.3 : bx->xmax + 0.3, i & 8 ? bx->ymax : bx->ymin};
    *v = (qk_point_t){sgn, e};
    break;
  case 2: /* along a vertical edge */
    if (!bx) break;
    *o = (qk_point_t){i & 8 ? bx->xmax : bx->xmin, sgn > 0 ? bx->ymin - 0.3 : bx->ymax + 0.3};
    *v = (qk_point_t){e, sgn};
    break;
  case 3: /* diagonally through a corner */
    if (!bx) break;
    *o = (qk_point_t){bx->xmax + 0.25 * sgn, bx->ymax + 0.25 * sgn};
    *v = (qk_point_t){-sgn, -sgn + e};
    break;
  case 4: /* from inside a box */
    if (bx) *o = (qk_point_t){0.5 * (bx->xmin + bx->xmax), 0.5 * (bx->ymin + bx->ymax)};
    break;
  case 5: /* from inside a disc */
    *o = (qk_point_t){dc->x, dc->y};
    break;
  case 6: /* tangent to a disc's top or bottom */
    *o = (qk_point_t){dc->x - 0.5 * sgn, dc->y + (i & 8 ? dc->r : -dc->r)};
    *v = (qk_point_t){sgn, e};
    break;
  case 7: /* axis-parallel from anywhere */
    *v = i & 8 ? (qk_point_t){sgn, 0} : (qk_point_t){0, sgn};
    break;
  default:
    break;
  }
  *tmax = qkt_rng_below(r, 4) == 0 ? qkt_rng_range(r, 0, 1) : INFINITY;
}

static void test_collide_rays_float_edges(void **state) {
  (void)state;
  qkt_rng_t r;
  qkt_rng_seed(&r, g_seed);
  static const struct {
    double scale, offset;
  } frames[] = {{1, 0}, {1e-30, 0}, {1e25, 0}, {1e35, 0}, {1e60, 0}, {1, 1e7}, {1e-3, 1e5}};
  static const double dscale[] = {1, 1e20, 1e-20, 1e-35};
  qk_disc_t d0[ND_MAX], d[ND_MAX];
  qk_box_t b0[NB_MAX], b[NB_MAX];
  long checked = 0;
  for (int scene = 0; scene < 2; scene++) {
    size_t nd, nb;
    make_scene(&r, d0, &nd, b0, &nb, 1);
    if (scene == 1) nb = 0; /* discs only: the two-at-a-time leaf test */
    for (size_t f = 0; f < sizeof frames / sizeof frames[0]; f++) {
      const double s = frames[f].scale, off = frames[f].offset;
      for (size_t i = 0; i < nd; i++)
        d[i] = (qk_disc_t){d0[i].x * s + off, d0[i].y * s + off, d0[i].r * s};
      for (size_t i = 0; i < nb; i++)
        b[i] = (qk_box_t){b0[i].xmin * s + off, b0[i].ymin * s + off, b0[i].xmax * s + off,
                          b0[i].ymax * s + off};
      qk_tree_options_t opt;
      qk_tree_options_init(&opt);
      opt.capacity = f % 2 ? 1 : 3;
      qk_collider_t *c = NULL;
      assert_int_equal(qk_collider_build(d, nd, nb ? b : NULL, nb, &opt, &c), QK_OK);
      for (int i = 0; i < N_RAYS; i++) {
        qk_point_t o, v;
        double tmax;
        make_ray(&r, i, d0, nd, b0, nb, &o, &v, &tmax);
        const double ds = dscale[qkt_rng_below(&r, 4)];
        o = (qk_point_t){o.x * s + off, o.y * s + off};
        v = (qk_point_t){v.x * ds, v.y * ds};
        tmax = tmax * s / ds;
        qk_hit_t h, w = brute(d, nd, b, nb, o, v, tmax);
        assert_int_equal(qk_collider_raycast(c, o, v, tmax, &h), QK_OK);
        if (h.id != w.id || !(h.t == w.t || (isinf(h.t) && isinf(w.t))))
          fail_msg("scene %d frame %zu ray %d (o %.17g %.17g, d %.17g %.17g, tmax %g): "
                   "hit (%u, %.17g) vs brute force (%u, %.17g) (seed %llu)",
                   scene, f, i, o.x, o.y, v.x, v.y, tmax, h.id, h.t, w.id, w.t,
                   (unsigned long long)g_seed);
        checked++;
      }
      qk_collider_free(c);
    }
  }
  assert_true(checked == 2L * 7 * N_RAYS);
}

/* Degenerate scenes for the 8-bit grids of the ray nodes: many items at one point, flat
 * boxes on a line, sides on grid values (k / 2^j) and next to them. */
static void test_collide_rays_grid_edges(void **state) {
  (void)state;
  qkt_rng_t r;
  qkt_rng_seed(&r, g_seed + 1);
  static const double offs[] = {0.0, 1e7, -3.0, 0x1p-20};
  qk_disc_t d[120];
  qk_box_t b[60];
  long checked = 0;
  for (size_t f = 0; f < sizeof offs / sizeof offs[0]; f++) {
    const double off = offs[f];
    size_t nd = 0, nb = 0;
    for (int i = 0; i < 40; i++) /* stacked: one point, radius 0 or tiny */
      d[nd++] = (qk_disc_t){off + 0.5, off + 0.25, i % 3 ? 0.0 : 0x1p-30};
    while (nd < 120) {
      const double x = off + (double)qkt_rng_below(&r, 64) / 64,
                   y = off + (double)qkt_rng_below(&r, 64) / 64;
      const double e = qkt_rng_below(&r, 2) ? 0.0 : 0x1p-40 * (qkt_rng_below(&r, 2) ? 1 : -1);
      d[nd++] = (qk_disc_t){x + e, y - e, (double)qkt_rng_below(&r, 4) / 128};
    }
    for (int i = 0; i < 60; i++) { /* flat boxes on y = off + 0.75 and x = off + 0.125 */
      const double a = off + (double)qkt_rng_below(&r, 64) / 64,
                   w = (double)qkt_rng_below(&r, 3) / 64;
      b[nb++] = i % 2 ? (qk_box_t){a, off + 0.75, a + w, off + 0.75}
                      : (qk_box_t){off + 0.125, a, off + 0.125, a + w};
    }
    for (int cap = 1; cap <= 8; cap += 7) {
      qk_tree_options_t opt;
      qk_tree_options_init(&opt);
      opt.capacity = (uint32_t)cap;
      qk_collider_t *c = NULL;
      assert_int_equal(qk_collider_build(d, nd, b, nb, &opt, &c), QK_OK);
      for (int i = 0; i < 400; i++) {
        qk_point_t o = {off + qkt_rng_range(&r, -0.2, 1.2), off + qkt_rng_range(&r, -0.2, 1.2)}, v;
        const double ang = qkt_rng_range(&r, 0, 6.283185307179586);
        v = (qk_point_t){cos(ang), sin(ang)};
        if (i % 4 == 1)
          o.y = off + 0.75, v = (qk_point_t){i & 8 ? 1 : -1, i & 16 ? 0x1p-60 : 0x1p-20};
        if (i % 4 == 2)
          o.x = off + 0.125, v = (qk_point_t){i & 16 ? -0x1p-60 : 0x1p-20, i & 8 ? 1 : -1};
        if (i % 4 == 3) v = (qk_point_t){off + 0.5 - o.x, off + 0.25 - o.y}; /* at the stack */
        qk_hit_t h, w = brute(d, nd, b, nb, o, v, INFINITY);
        assert_int_equal(qk_collider_raycast(c, o, v, INFINITY, &h), QK_OK);
        if (h.id != w.id || !(h.t == w.t || (isinf(h.t) && isinf(w.t))))
          fail_msg("offset %g cap %d ray %d (o %.17g %.17g, d %.17g %.17g): hit (%u, %.17g) vs "
                   "brute force (%u, %.17g) (seed %llu)",
                   off, cap, i, o.x, o.y, v.x, v.y, h.id, h.t, w.id, w.t,
                   (unsigned long long)g_seed);
        checked++;
      }
      qk_collider_free(c);
    }
  }
  assert_true(checked == 4L * 2 * 400);
}

/* Deep trees and an inexact root square: the local start's descent stops at 32 levels,
 * and its squares differ from the tree's by roundings that the margin must cover. */
static void test_collide_rays_deep_and_rooted(void **state) {
  (void)state;
  qkt_rng_t r;
  qkt_rng_seed(&r, g_seed + 3);
  enum { ND = 240 };
  qk_disc_t d[ND];
  long checked = 0;
  for (int variant = 0; variant < 2; variant++) {
    for (int i = 0; i < ND; i += 2) { /* pairs 2^-45 apart, some in a tight cluster */
      const double x = i < 80 ? 0.4 + qkt_rng_range(&r, 0, 1e-9) : qkt_rng_range(&r, 0, 1.3);
      const double y = i < 80 ? 0.7 + qkt_rng_range(&r, 0, 1e-9) : qkt_rng_range(&r, 0, 1.3);
      const double rad =
          qkt_rng_below(&r, 3) ? qkt_rng_range(&r, 0, 1e-10) : qkt_rng_range(&r, 0, 0.02);
      d[i] = (qk_disc_t){x, y, rad};
      d[i + 1] = (qk_disc_t){x + 0x1p-45, y - 0x1p-45, rad};
    }
    qk_tree_options_t opt;
    qk_tree_options_init(&opt);
    opt.capacity = 1;
    opt.max_depth = QK_MAX_DEPTH_LIMIT;
    if (variant == 1) {
      opt.has_root = 1;
      opt.root = (qk_square_t){-0.3, -0.3, 1.7};
    }
    qk_collider_t *c = NULL;
    assert_int_equal(qk_collider_build(d, ND, NULL, 0, &opt, &c), QK_OK);
    for (int i = 0; i < 600; i++) {
      const qk_disc_t *t = &d[qkt_rng_below(&r, ND)];
      qk_point_t o = {qkt_rng_range(&r, -0.5, 1.8), qkt_rng_range(&r, -0.5, 1.8)};
      static const double near[3] = {0.0, 0x1p-47, 1e-9}; /* on, beside, off the pair */
      const double nr = near[qkt_rng_below(&r, 3)];
      if (i % 3 == 0) o = (qk_point_t){t->x + nr, t->y - nr};
      const double ang = qkt_rng_range(&r, 0, 6.283185307179586);
      qk_point_t v = {cos(ang), sin(ang)};
      if (i % 3 == 1) v = (qk_point_t){t->x - o.x, t->y - o.y};
      const double tmax = qkt_rng_below(&r, 4) == 0 ? qkt_rng_range(&r, 0, 0.3) : INFINITY;
      expect_brute(c, d, ND, NULL, 0, o, v, tmax, variant, i);
      checked++;
    }
    qk_collider_free(c);
  }
  assert_true(checked == 2L * 600);
}

/*
 * The climbs' stop at the edges of the path's fixed point (collider.c climb_stop): in the
 * root square [0, 1]^2, discs of the largest radius centred half a unit, one unit and a
 * unit and a half of 2^-32 beyond a square's side (the root's midlines, and a level-2
 * side), a ray from the other side along the centre's line with tmax at the disc's own
 * hit: the widened segment then ends a fraction of a unit past the side, so the search
 * must climb past the square (to the root for a midline) to find the disc. Small discs on
 * a grid make the tree deep (capacity 1); every direction, each axis.
 */
static void test_collide_rays_climb_edges(void **state) {
  (void)state;
  enum { NG = 16, NPROBE = 4 * 2 * 3 };
  qk_disc_t d[NG * NG + NPROBE];
  size_t nd = 0;
  for (int i = 0; i < NG; i++)
    for (int j = 0; j < NG; j++) d[nd++] = (qk_disc_t){(i + 0.5) / NG, (j + 0.5) / NG, 1e-5};
  static const double side[2] = {0.5, 0.25};                /* a midline, a level-2 side */
  static const double off[3] = {0x1p-33, 0x1p-32, 0x3p-33}; /* beyond it, in 2^-32 */
  qk_point_t org[NPROBE], dir[NPROBE];
  int np = 0;
  for (int s = 0; s < 2; s++)
    for (int k = 0; k < 3; k++)
      for (int q = 0; q < 4; q++) { /* +x, -x, +y, -y */
        const double r = 1e-3, e = q % 2 ? side[s] - off[k] : side[s] + off[k];
        const double along = 0.3 + 0.1 * q + 0.01 * k; /* clear of the grid's discs */
        const double from = q % 2 ? side[s] + 0.003 : side[s] - 0.003;
        const double sgn = q % 2 ? -1.0 : 1.0;
        if (q < 2) {
          d[nd++] = (qk_disc_t){e, along, r};
          org[np] = (qk_point_t){from, along}, dir[np] = (qk_point_t){sgn, 0x1p-90};
        } else {
          d[nd++] = (qk_disc_t){along, e, r};
          org[np] = (qk_point_t){along, from}, dir[np] = (qk_point_t){0x1p-90, sgn};
        }
        np++;
      }
  qk_tree_options_t opt;
  qk_tree_options_init(&opt);
  opt.capacity = 1;
  opt.has_root = 1;
  opt.root = (qk_square_t){0, 0, 1};
  qk_collider_t *c = NULL;
  assert_int_equal(qk_collider_build(d, nd, NULL, 0, &opt, &c), QK_OK);
  for (int i = 0; i < np; i++) {
    const qk_hit_t w = brute(d, nd, NULL, 0, org[i], dir[i], INFINITY);
    assert_int_equal(w.id, NG * NG + i); /* the probe's own disc, first */
    expect_brute(c, d, nd, NULL, 0, org[i], dir[i], w.t, 0, i);
    expect_brute(c, d, nd, NULL, 0, org[i], dir[i], nextafter(w.t, INFINITY), 1, i);
  }
  qk_collider_free(c);
}

/* The batch call, on one and two threads, answers each ray as a single call does. */
static void test_collide_rays_batch_matches_single(void **state) {
  (void)state;
  qkt_rng_t r;
  qkt_rng_seed(&r, g_seed + 2);
  enum { ND = 3000, NR = 5000 };
  qk_disc_t *d = malloc(ND * sizeof *d);
  qk_point_t *o = malloc(NR * sizeof *o), *v = malloc(NR * sizeof *v);
  qk_hit_t *h = malloc(NR * sizeof *h);
  assert_non_null(d && o && v && h);
  for (int i = 0; i < ND; i++)
    d[i] =
        (qk_disc_t){qkt_rng_range(&r, 0, 1), qkt_rng_range(&r, 0, 1), qkt_rng_range(&r, 0, 0.01)};
  for (int i = 0; i < NR; i++) {
    const double ang = qkt_rng_range(&r, 0, 6.283185307179586);
    o[i] = (qk_point_t){qkt_rng_range(&r, -0.5, 1.5), qkt_rng_range(&r, -0.5, 1.5)};
    v[i] = (qk_point_t){cos(ang), sin(ang)};
  }
  qk_collider_t *c = NULL;
  assert_int_equal(qk_collider_build(d, ND, NULL, 0, NULL, &c), QK_OK);
  for (uint32_t th = 1; th <= 2; th++) {
    qk_collider_set_threads(c, th);
    assert_int_equal(qk_collider_raycast_batch(c, o, v, NR, 0.5, h), QK_OK);
    for (int i = 0; i < NR; i++) {
      qk_hit_t s;
      assert_int_equal(qk_collider_raycast(c, o[i], v[i], 0.5, &s), QK_OK);
      if (s.id != h[i].id || !(s.t == h[i].t || (isinf(s.t) && isinf(h[i].t))))
        fail_msg("threads %u ray %d: batch (%u, %.17g) vs single (%u, %.17g) (seed %llu)", th, i,
                 h[i].id, h[i].t, s.id, s.t, (unsigned long long)g_seed);
    }
  }
  qk_collider_free(c);
  free(d), free(o), free(v), free(h);
}

/*
 * Ties between discs: every disc three times, the copies at shuffled ids, so that the
 * slots of equal discs are adjacent in the tree while their ids are not in slot order, and
 * every hit is a tie of three (t equal to the last bit) that only the smallest id decides.
 * The cast reads ids from the tree's id array only for the discs that may be the best hit,
 * two at a time or one at a time; both must pick the smallest id of a tie.
 */
static void test_collide_rays_tied_discs(void **state) {
  (void)state;
  qkt_rng_t r;
  qkt_rng_seed(&r, g_seed + 3);
  enum { NU = 1500, COPIES = 3, ND = NU * COPIES, NR = 3000 };
  qk_disc_t *u = malloc(NU * sizeof *u), *d = malloc(ND * sizeof *d);
  uint32_t *perm = malloc(ND * sizeof *perm);
  assert_non_null(u && d && perm);
  for (int i = 0; i < NU; i++)
    u[i] =
        (qk_disc_t){qkt_rng_range(&r, 0, 1), qkt_rng_range(&r, 0, 1), qkt_rng_range(&r, 0, 0.03)};
  for (uint32_t i = 0; i < ND; i++) perm[i] = i;
  for (uint32_t i = ND - 1; i > 0; i--) { /* Fisher-Yates */
    uint32_t j = qkt_rng_below(&r, i + 1), t = perm[i];
    perm[i] = perm[j], perm[j] = t;
  }
  for (uint32_t i = 0; i < ND; i++) d[perm[i]] = u[i % NU];
  long ties = 0;
  for (uint32_t cap = 1; cap <= 8; cap += 7) {
    qk_tree_options_t opt;
    qk_tree_options_init(&opt);
    opt.capacity = cap;
    qk_collider_t *c = NULL;
    assert_int_equal(qk_collider_build(d, ND, NULL, 0, &opt, &c), QK_OK);
    for (int i = 0; i < NR; i++) {
      const double ang = qkt_rng_range(&r, 0, 6.283185307179586);
      const qk_disc_t *dc = &u[qkt_rng_below(&r, NU)];
      const qk_point_t o =
          i % 3 == 0 ? (qk_point_t){dc->x, dc->y} /* inside: t = 0 */
                     : (qk_point_t){qkt_rng_range(&r, -0.2, 1.2), qkt_rng_range(&r, -0.2, 1.2)};
      const qk_point_t v = {cos(ang), sin(ang)};
      qk_hit_t h, w = brute(d, ND, NULL, 0, o, v, INFINITY);
      assert_int_equal(qk_collider_raycast(c, o, v, INFINITY, &h), QK_OK);
      if (h.id != w.id || !(h.t == w.t || (isinf(h.t) && isinf(w.t))))
        fail_msg("capacity %u ray %d: hit (%u, %.17g) vs brute force (%u, %.17g) (seed %llu)", cap,
                 i, h.id, h.t, w.id, w.t, (unsigned long long)g_seed);
      ties += w.id != QK_NONE;
    }
    qk_collider_free(c);
  }
  assert_true(ties > NR); /* most rays hit (and every hit is a tie of three) */
  free(u), free(d), free(perm);
}

/* The ray from o along v times 2^k, for each k of ks (those whose direction scales back to
 * v exactly), must hit what the ray along v hit (ref), at t times 2^-k, exactly. */
static void expect_scaled_hits(const qk_collider_t *c, qk_point_t o, qk_point_t v, qk_hit_t ref,
                               const int *ks, size_t nk, int ray) {
  for (size_t j = 0; j < nk; j++) {
    const int k = ks[j];
    const qk_point_t vk = {ldexp(v.x, k), ldexp(v.y, k)};
    if (ldexp(vk.x, -k) != v.x || ldexp(vk.y, -k) != v.y) continue; /* underflowed */
    qk_hit_t h;
    assert_int_equal(qk_collider_raycast(c, o, vk, INFINITY, &h), QK_OK);
    const double want = ref.id == QK_NONE ? INFINITY : ldexp(ref.t, -k);
    if (h.id != ref.id || !(h.t == want || (isinf(h.t) && isinf(want))))
      fail_msg("ray %d, direction times 2^%d: (%u, %.17g), want (%u, %.17g) (seed %llu)", ray, k,
               h.id, h.t, ref.id, want, (unsigned long long)g_seed);
  }
}

/*
 * Directions far beyond the arithmetic's range (components of 2^600 and more, or all
 * below 2^-600): the same ray with its direction multiplied by 2^k hits the same item at
 * t times 2^-k, exactly, since the cast scales such a direction back by a power of two.
 * The reference directions have their largest component in [1/2, 1), so that scaling
 * gives them back bit for bit; a cast that squared the raw components would overflow
 * (every ray "hits" at t = 0) or underflow.
 */
static void test_collide_rays_extreme_directions(void **state) {
  (void)state;
  qkt_rng_t r;
  qkt_rng_seed(&r, g_seed + 3);
  enum { ND = 2000, NR = 2000 };
  qk_disc_t *d = malloc(ND * sizeof *d);
  assert_non_null(d);
  for (int i = 0; i < ND; i++)
    d[i] =
        (qk_disc_t){qkt_rng_range(&r, 0, 1), qkt_rng_range(&r, 0, 1), qkt_rng_range(&r, 0, 0.01)};
  qk_collider_t *c = NULL;
  assert_int_equal(qk_collider_build(d, ND, NULL, 0, NULL, &c), QK_OK);
  const int ks[] = {600, -600, 1000, -1000, 1023, -1060};
  long hits = 0;
  for (int i = 0; i < NR; i++) {
    const double ang = qkt_rng_range(&r, 0, 6.283185307179586);
    const qk_point_t o = {qkt_rng_range(&r, -0.5, 1.5), qkt_rng_range(&r, -0.5, 1.5)};
    qk_point_t v = {cos(ang), sin(ang)};
    const double m = fmax(fabs(v.x), fabs(v.y)); /* in [0.707, 1]: 1 only on an axis */
    if (m == 1) continue;
    qk_hit_t ref;
    assert_int_equal(qk_collider_raycast(c, o, v, INFINITY, &ref), QK_OK);
    hits += ref.id != QK_NONE;
    expect_scaled_hits(c, o, v, ref, ks, sizeof ks / sizeof ks[0], i);
  }
  assert_true(hits > NR / 4); /* the rays do hit things */
  qk_collider_free(c);
  free(d);
}

/* Coordinates and radii far from 1: a scene scaled by 2^k (centres, radii and origins) with
 * its directions scaled by 2^j has the same hits at t scaled by 2^(k - j), to the bit
 * (every operation of the cast commutes with scaling by a power of two). Beyond 2^400
 * the squares of the plain disc test overflow (hits at t = inf, or t = 0), and a large
 * direction times a large radius did so below it (a miss); below 2^-511 they underflow
 * (fifty-fifth session: scaled by 2^-600, a disc the ray passes at nine radii was hit at
 * t = 0, and at 2^-530 t was off in its fifth digit); hand cases besides. */
static void test_collide_rays_far_coordinates(void **state) {
  (void)state;
  qkt_rng_t r;
  qkt_rng_seed(&r, g_seed + 4);
  enum { ND = 1500, NR = 600 };
  qk_disc_t *d = malloc(ND * sizeof *d), *dk = malloc(ND * sizeof *dk);
  assert_non_null(d), assert_non_null(dk);
  for (int i = 0; i < ND; i++)
    d[i] =
        (qk_disc_t){qkt_rng_range(&r, 0, 1), qkt_rng_range(&r, 0, 1), qkt_rng_range(&r, 0, 0.01)};
  qk_collider_t *c = NULL;
  assert_int_equal(qk_collider_build(d, ND, NULL, 0, NULL, &c), QK_OK);
  const int kj[][2] = {{420, 0},  {600, 0},  {1000, 0}, {600, 300}, {300, 400},   {390, 120},
                       {-420, 0}, {-530, 0}, {-600, 0}, {-900, 0},  {-600, -300}, {-700, 200}};
  qk_point_t o[NR], v[NR];
  qk_hit_t ref[NR];
  long hits = 0;
  for (int i = 0; i < NR; i++) {
    const double ang = qkt_rng_range(&r, 0, 6.283185307179586);
    o[i] = (qk_point_t){qkt_rng_range(&r, -0.5, 1.5), qkt_rng_range(&r, -0.5, 1.5)};
    v[i] = (qk_point_t){cos(ang), sin(ang)};
    assert_int_equal(qk_collider_raycast(c, o[i], v[i], INFINITY, &ref[i]), QK_OK);
    hits += ref[i].id != QK_NONE;
  }
  assert_true(hits > NR / 4); /* the rays do hit things */
  for (size_t s = 0; s < sizeof kj / sizeof kj[0]; s++) {
    const int k = kj[s][0], j = kj[s][1];
    for (int i = 0; i < ND; i++)
      dk[i] = (qk_disc_t){ldexp(d[i].x, k), ldexp(d[i].y, k), ldexp(d[i].r, k)};
    qk_collider_t *ck = NULL;
    assert_int_equal(qk_collider_build(dk, ND, NULL, 0, NULL, &ck), QK_OK);
    for (int i = 0; i < NR; i++) {
      const qk_point_t ok = {ldexp(o[i].x, k), ldexp(o[i].y, k)};
      const qk_point_t vj = {ldexp(v[i].x, j), ldexp(v[i].y, j)};
      qk_hit_t h;
      assert_int_equal(qk_collider_raycast(ck, ok, vj, INFINITY, &h), QK_OK);
      const double want = ref[i].id == QK_NONE ? INFINITY : ldexp(ref[i].t, k - j);
      if (h.id != ref[i].id || !(h.t == want || (isinf(h.t) && isinf(want))))
        fail_msg("ray %d, scene times 2^%d, direction times 2^%d: (%u, %.17g), want (%u, %.17g) "
                 "(seed %llu)",
                 i, k, j, h.id, h.t, ref[i].id, want, (unsigned long long)g_seed);
    }
    qk_collider_free(ck);
  }
  qk_collider_free(c);
  /* by hand: the first hit of a ray along an axis is the distance less the radius */
  const struct {
    qk_disc_t d;
    qk_point_t o, v;
    double t;
  } cases[] = {
      {{0, 0, 1e10}, {1e12, 0}, {-1e150, 0}, (1e12 - 1e10) / 1e150},
      {{0, 0, 1}, {1e200, 0}, {-1, 0}, 1e200},
      {{0, 0, 1}, {1e300, 1e300}, {-1e300, -1e300}, 1},
      {{1e300, -1e300, 1e299}, {-1e300, -1e300}, {1, 0}, 2e300 - 1e299},
  };
  for (size_t i = 0; i < sizeof cases / sizeof cases[0]; i++) {
    qk_collider_t *c1 = NULL;
    assert_int_equal(qk_collider_build(&cases[i].d, 1, NULL, 0, NULL, &c1), QK_OK);
    qk_hit_t h;
    assert_int_equal(qk_collider_raycast(c1, cases[i].o, cases[i].v, INFINITY, &h), QK_OK);
    if (h.id != 0 || !(fabs(h.t - cases[i].t) <= 1e-14 * cases[i].t))
      fail_msg("case %zu: (%u, %.17g), want (0, %.17g)", i, h.id, h.t, cases[i].t);
    qk_collider_free(c1);
  }
  free(dk);
  free(d);
}

/* Far coordinates with a short direction (twentieth session): t overflows along the
 * direction as given. From (-8e307, -8e307) along (1e-10, 1e-10) the box test reported a
 * zero-width box beside the ray (x = 8e307, y in [-8e307, -7e307]) as hit at t = inf,
 * and of two boxes on the ray, both beyond t = DBL_MAX, the farther one (smaller id) won
 * the tie of two infinities. Now: a miss, and the nearer box at t = inf; the same ray
 * along (1, 1) (t finite) agrees on every item. */
static void test_collide_rays_short_direction_far(void **state) {
  (void)state;
  const qk_box_t b[] = {{8e307, -8e307, 8e307, -7e307}, /* beside the ray */
                        {6e307, 6e307, 7e307, 7e307},
                        {1e307, 1e307, 2e307, 2e307}};
  const qk_point_t o = {-8e307, -8e307};
  const struct {
    size_t first, n;
    qk_id_t id;
  } cases[] = {{0, 1, QK_NONE}, {1, 2, 1}, {0, 3, 2}};
  for (size_t i = 0; i < sizeof cases / sizeof cases[0]; i++) {
    qk_collider_t *c = NULL;
    assert_int_equal(qk_collider_build(NULL, 0, b + cases[i].first, cases[i].n, NULL, &c), QK_OK);
    qk_hit_t h, unit;
    assert_int_equal(qk_collider_raycast(c, o, (qk_point_t){1e-10, 1e-10}, INFINITY, &h), QK_OK);
    assert_int_equal(qk_collider_raycast(c, o, (qk_point_t){1, 1}, INFINITY, &unit), QK_OK);
    if (h.id != cases[i].id || unit.id != cases[i].id)
      fail_msg("case %zu: short direction %u at %.17g, unit direction %u at %.17g, want %u", i,
               (unsigned)h.id, h.t, (unsigned)unit.id, unit.t, (unsigned)cases[i].id);
    assert_true(isinf(h.t)); /* beyond the largest double, or a miss */
    assert_true(cases[i].id == QK_NONE ? isinf(unit.t) : isfinite(unit.t));
    qk_collider_free(c);
  }
}

/* Scenes spanning nearly the whole double range (items from -2^1023 to 2^1023), cast
 * with directions beyond 2^100, which the cast scales by a power of two: t must stay
 * what it is, though t along a direction scaled to [1/2, 1) would exceed the largest
 * double there (such casts answered t = inf, and a farther item of smaller id won the
 * tie of two infinities). Hand cases whose every t is a dyadic number (exact); then
 * random scenes, where the ray with direction v 2^j must give the hit of the ray with
 * direction v (largest component in [2, 6]: not scaled) at t 2^-j, exactly. */
static void test_collide_rays_span_of_doubles(void **state) {
  (void)state;
  const double h = 0x1p1023, q = 0x1p1021;
  /* disc 0 farther than disc 1 on the ray up the y axis from -2^1023 */
  const qk_disc_t hd[] = {
      {0, 0x1.8p1022, 0x1p1020}, {0, q, 0x1p1020}, {0x1p1022, 0x1p1022, 0x1p1020}};
  const qk_box_t hb[] = {{-1, q, 1, 0x1p1022},
                         {0x1p1022 - q, -h, 0x1p1022 + q, -0x1p1022},
                         {-0x1p1022 - 1, q + 0x1p1020, -0x1p1022 + 1, 0x1p1022}};
  qk_collider_t *c = NULL;
  assert_int_equal(qk_collider_build(hd, 3, hb, 3, NULL, &c), QK_OK);
  const struct {
    qk_point_t o, v;
    double tmax;
    qk_id_t id;
    double t;
  } cases[] = {
      {{0, -h}, {0, h}, INFINITY, 1, 1.125},            /* (2^1023 + 2^1020) / 2^1023 */
      {{0, -h}, {0, 0x1p200}, INFINITY, 1, 0x1.2p823},  /* the same point along 2^200 */
      {{0, h}, {0, -h}, INFINITY, 0, 0.125},            /* from the top: disc 0 first */
      {{0, -h}, {0, h}, 1, QK_NONE, INFINITY},          /* tmax short of disc 1 */
      {{-0x1p1022, -h}, {0, h}, INFINITY, 5, 1.375},    /* box 5 from below */
      {{-q, -h}, {0x1p1022, 0x1p1022}, INFINITY, 4, 1}, /* box 4's corner (2^1021, -2^1022) */
      {{0x1p1022, -h}, {0, 0x1p1000}, INFINITY, 4, 0},  /* from inside box 4: t = 0 */
      {{0x1p1022, -0x1.8p1022}, {0, 0x1p900}, INFINITY, 4, 0},
      {{0x1p1022, -0x1p1022}, {0, 0x1p700}, INFINITY, 4, 0},
      {{0x1p1022, -0x1.fp1022}, {0, -0x1p101}, INFINITY, 4, 0},
      {{0x1p1022, h}, {0, -h}, INFINITY, 2, 0.375}, /* down onto disc 2's top */
  };
  for (size_t i = 0; i < sizeof cases / sizeof cases[0]; i++) {
    qk_hit_t hit;
    assert_int_equal(qk_collider_raycast(c, cases[i].o, cases[i].v, cases[i].tmax, &hit), QK_OK);
    if (hit.id != cases[i].id || !(hit.t == cases[i].t))
      fail_msg("case %zu: (%u, %.17g), want (%u, %.17g)", i, hit.id, hit.t, cases[i].id,
               cases[i].t);
  }
  qk_collider_free(c);

  qkt_rng_t r;
  qkt_rng_seed(&r, g_seed + 9);
  enum { ND = 60, NB = 15, NR = 600 };
  qk_disc_t *d = malloc(ND * sizeof *d);
  qk_box_t *b = malloc(NB * sizeof *b);
  assert_non_null(d), assert_non_null(b);
  const double span = 0x1.ep1022; /* 0.9375 of 2^1023 */
  for (int i = 0; i < ND; i++)
    d[i] = (qk_disc_t){qkt_rng_range(&r, -span, span), qkt_rng_range(&r, -span, span),
                       qkt_rng_range(&r, 0, 0x1p1017)};
  for (int i = 0; i < NB; i++) {
    const double x = qkt_rng_range(&r, -span, span), y = qkt_rng_range(&r, -span, span);
    b[i] = (qk_box_t){x, y, x + qkt_rng_range(&r, 0, 0x1p1017), y + qkt_rng_range(&r, 0, 0x1p1017)};
  }
  assert_int_equal(qk_collider_build(d, ND, b, NB, NULL, &c), QK_OK);
  const int js[] = {99, 100, 200, 600, 1019};
  long hits = 0, far_hits = 0;
  for (int i = 0; i < NR; i++) {
    const double ang = qkt_rng_range(&r, 0, 6.283185307179586);
    /* from the square's bottom edge, upwards; the largest component in [2, 6], so that t
     * stays below 2^1024 (1.33 times 2^1024 of distance at most, over 2) */
    const qk_point_t o = {qkt_rng_range(&r, -span, span), -span};
    const qk_point_t v = {2 * cos(ang), 4 * fabs(sin(ang)) + 2};
    qk_hit_t ref;
    assert_int_equal(qk_collider_raycast(c, o, v, INFINITY, &ref), QK_OK);
    hits += ref.id != QK_NONE;
    /* t along v scaled to [1/2, 1) beyond the largest double */
    far_hits += ref.id != QK_NONE && isinf(ldexp(ref.t, ilogb(fmax(fabs(v.x), v.y)) + 1));
    expect_scaled_hits(c, o, v, ref, js, sizeof js / sizeof js[0], i);
  }
  assert_true(hits > NR / 8); /* the rays do hit things, */
  assert_true(far_hits > 10); /* some beyond where [1/2, 1) overflowed */
  qk_collider_free(c);
  free(d);
  free(b);
}

/* A collider over 2 MiB of ray arrays (70,000 records of 32 bytes), bench-like discs
 * (radii up to 0.5 / sqrt(n), capacity 8), once of discs only and once with a tenth boxes:
 * every ray against brute force. */
static void test_collide_rays_large_scene(void **state) {
  (void)state;
  qkt_rng_t r;
  qkt_rng_seed(&r, g_seed + 7);
  enum { ND = 70000, NB = 7000, NR = 400 };
  qk_disc_t *d = malloc(ND * sizeof *d);
  qk_box_t *b = malloc(NB * sizeof *b);
  assert_non_null(d && b);
  const double rmax = 0.5 / sqrt((double)ND);
  for (int i = 0; i < ND; i++)
    d[i] =
        (qk_disc_t){qkt_rng_range(&r, 0, 1), qkt_rng_range(&r, 0, 1), qkt_rng_range(&r, 0, rmax)};
  for (int i = 0; i < NB; i++) {
    const double x = qkt_rng_range(&r, 0, 1), y = qkt_rng_range(&r, 0, 1);
    b[i] = (qk_box_t){x, y, x + qkt_rng_range(&r, 0, rmax), y + qkt_rng_range(&r, 0, rmax)};
  }
  qk_tree_options_t opt;
  qk_tree_options_init(&opt);
  opt.capacity = 8;
  long checked = 0;
  /* Variants: discs only, with boxes, and discs only built on two threads (the ray entries
   * below the top levels, and their parents, then filled by subtrees on their own). */
  for (int variant = 0; variant < 3; variant++) {
    const size_t nb = variant == 1 ? NB : 0;
    opt.threads = variant == 2 ? 2 : 1;
    qk_collider_t *c = NULL;
    assert_int_equal(qk_collider_build(d, ND, nb ? b : NULL, nb, &opt, &c), QK_OK);
    for (int i = 0; i < NR; i++) {
      qk_point_t o = {qkt_rng_range(&r, -0.1, 1.1), qkt_rng_range(&r, -0.1, 1.1)};
      if (i % 4 == 1) o = (qk_point_t){d[i].x, d[i].y};             /* inside a disc */
      if (i % 4 == 2) o.x = (double)qkt_rng_below(&r, 257) / 256.0; /* on a split line */
      const double ang = qkt_rng_range(&r, 0, 6.283185307179586);
      qk_point_t v = {cos(ang), sin(ang)};
      if (i % 8 == 2) v = (qk_point_t){0, ang < 3.14 ? 1 : -1}; /* along it */
      const double tmax = qkt_rng_below(&r, 4) == 0 ? qkt_rng_range(&r, 0, 0.02) : INFINITY;
      expect_brute(c, d, ND, b, nb, o, v, tmax, variant, i);
      checked++;
    }
    /* The batch call sorts these many rays by origin: the same answers as single calls. */
    enum { NBATCH = 2048 };
    qk_point_t *bo = malloc(NBATCH * sizeof *bo), *bv = malloc(NBATCH * sizeof *bv);
    qk_hit_t *bh = malloc(NBATCH * sizeof *bh);
    assert_non_null(bo && bv && bh);
    for (int i = 0; i < NBATCH; i++) {
      const double ang = qkt_rng_range(&r, 0, 6.283185307179586);
      bo[i] = (qk_point_t){qkt_rng_range(&r, -0.1, 1.1), qkt_rng_range(&r, -0.1, 1.1)};
      bv[i] = (qk_point_t){cos(ang), sin(ang)};
    }
    assert_int_equal(qk_collider_raycast_batch(c, bo, bv, NBATCH, INFINITY, bh), QK_OK);
    for (int i = 0; i < NBATCH; i++) {
      qk_hit_t h;
      assert_int_equal(qk_collider_raycast(c, bo[i], bv[i], INFINITY, &h), QK_OK);
      if (h.id != bh[i].id || !(h.t == bh[i].t || (isinf(h.t) && isinf(bh[i].t))))
        fail_msg("variant %d batch ray %d: batch (%u, %.17g) vs single (%u, %.17g) (seed %llu)",
                 variant, i, bh[i].id, bh[i].t, h.id, h.t, (unsigned long long)g_seed);
    }
    free(bo), free(bv), free(bh);
    qk_collider_free(c);
  }
  assert_true(checked == 3L * NR);
  free(d), free(b);
}

int main(void) {
  g_seed = qkt_seed(90211);
  const struct CMUnitTest tests[] = {
      cmocka_unit_test(test_collide_rays_float_edges),
      cmocka_unit_test(test_collide_rays_grid_edges),
      cmocka_unit_test(test_collide_rays_deep_and_rooted),
      cmocka_unit_test(test_collide_rays_climb_edges),
      cmocka_unit_test(test_collide_rays_batch_matches_single),
      cmocka_unit_test(test_collide_rays_tied_discs),
      cmocka_unit_test(test_collide_rays_extreme_directions),
      cmocka_unit_test(test_collide_rays_far_coordinates),
      cmocka_unit_test(test_collide_rays_span_of_doubles),
      cmocka_unit_test(test_collide_rays_short_direction_far),
      cmocka_unit_test(test_collide_rays_large_scene),
  };
  return cmocka_run_group_tests(tests, NULL, NULL);
}
