/*
 * Test plan: the moving-objects world (qk_world_*) on scenes unlike the other tests',
 * against an exact brute force of our own: every pair of objects tested with GMP
 * rationals on the doubles as given (closed shapes: touching counts).
 *  - disc-disc |c1 - c2|^2 <= (r1 + r2)^2; disc-box and disc-segment by the squared
 *    distance from the centre to the nearest point (a clamp, a clamped projection);
 *    box-box by intervals; segment-segment by orientations (collinear overlaps and
 *    touching ends included); box-segment: an end inside, or a crossing of a side;
 *    a point is a disc of radius 0.
 *  - scenes: objects near 1e9 (and -1e9) with sizes from 1e-3 to 1e3 in one scene, all
 *    four kinds; exactly touching constructions (dyadic offsets, so the contact is exact);
 *    many coincident objects (identical discs, boxes, segments, points); degenerate
 *    shapes on a coarse grid (radius 0, zero-width boxes, zero-length segments); then half the
 *    objects moved, and the began / ended pairs checked as set differences.
 * QK_SEED=n replays a seed.
 */
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "qk_test.h"

#ifdef QK_HAVE_GMP
#include <gmp.h>

typedef struct ex {
  mpq_t t[8];
} ex_t;

static void q(mpq_t r, double d) { mpq_set_d(r, d); }

/* dist^2 from (cx, cy) to the closed box, compared with r^2: <= gives 1. */
static int disc_box(const qk_shape_t *d, const qk_shape_t *b) {
  double lo[2] = {fmin(b->x, b->a), fmin(b->y, b->b)}, hi[2] = {fmax(b->x, b->a), fmax(b->y, b->b)};
  double c[2] = {d->x, d->y};
  mpq_t s, t, u;
  mpq_inits(s, t, u, NULL);
  mpq_set_ui(s, 0, 1);
  for (int k = 0; k < 2; k++) {
    double n = c[k] < lo[k] ? lo[k] : c[k] > hi[k] ? hi[k] : c[k]; /* exact clamp */
    q(t, c[k]), q(u, n), mpq_sub(t, t, u), mpq_mul(t, t, t), mpq_add(s, s, t);
  }
  double r = d->kind == QK_SHAPE_POINT ? 0 : d->a;
  q(t, r), mpq_mul(t, t, t);
  int in = mpq_cmp(s, t) <= 0;
  mpq_clears(s, t, u, NULL);
  return in;
}

static int disc_disc(const qk_shape_t *a, const qk_shape_t *b) {
  double ra = a->kind == QK_SHAPE_POINT ? 0 : a->a, rb = b->kind == QK_SHAPE_POINT ? 0 : b->a;
  mpq_t s, t, u;
  mpq_inits(s, t, u, NULL);
  q(t, a->x), q(u, b->x), mpq_sub(t, t, u), mpq_mul(s, t, t);
  q(t, a->y), q(u, b->y), mpq_sub(t, t, u), mpq_mul(t, t, t), mpq_add(s, s, t);
  q(t, ra), q(u, rb), mpq_add(t, t, u), mpq_mul(t, t, t);
  int in = mpq_cmp(s, t) <= 0;
  mpq_clears(s, t, u, NULL);
  return in;
}

static int disc_seg(const qk_shape_t *d, const qk_shape_t *g) {
  double r = d->kind == QK_SHAPE_POINT ? 0 : d->a;
  mpq_t px, py, vx, vy, wx, wy, t, l, s, e;
  mpq_inits(px, py, vx, vy, wx, wy, t, l, s, e, NULL);
  q(px, g->x), q(py, g->y);
  q(vx, g->a), mpq_sub(vx, vx, px), q(vy, g->b), mpq_sub(vy, vy, py); /* q - p */
  q(wx, d->x), mpq_sub(wx, wx, px), q(wy, d->y), mpq_sub(wy, wy, py); /* c - p */
  mpq_mul(l, vx, vx), mpq_mul(e, vy, vy), mpq_add(l, l, e);           /* |v|^2 */
  mpq_mul(t, wx, vx), mpq_mul(e, wy, vy), mpq_add(t, t, e);           /* w.v */
  if (mpq_sgn(l) == 0 || mpq_sgn(t) <= 0)
    mpq_set_ui(t, 0, 1);
  else if (mpq_cmp(t, l) >= 0)
    mpq_set_ui(t, 1, 1);
  else
    mpq_div(t, t, l);
  /* w - t v */
  mpq_mul(e, t, vx), mpq_sub(wx, wx, e), mpq_mul(e, t, vy), mpq_sub(wy, wy, e);
  mpq_mul(s, wx, wx), mpq_mul(e, wy, wy), mpq_add(s, s, e);
  q(e, r), mpq_mul(e, e, e);
  int in = mpq_cmp(s, e) <= 0;
  mpq_clears(px, py, vx, vy, wx, wy, t, l, s, e, NULL);
  return in;
}

static int orient(double ax, double ay, double bx, double by, double cx, double cy) {
  mpq_t a, b, c, d;
  mpq_inits(a, b, c, d, NULL);
  q(a, bx), q(d, ax), mpq_sub(a, a, d);
  q(b, cy), q(d, ay), mpq_sub(b, b, d);
  mpq_mul(a, a, b);
  q(b, by), q(d, ay), mpq_sub(b, b, d);
  q(c, cx), q(d, ax), mpq_sub(c, c, d);
  mpq_mul(b, b, c);
  int s = mpq_cmp(a, b);
  mpq_clears(a, b, c, d, NULL);
  return (s > 0) - (s < 0);
}

static int on_seg(double ax, double ay, double bx, double by, double cx, double cy) {
  return cx >= fmin(ax, bx) && cx <= fmax(ax, bx) && cy >= fmin(ay, by) && cy <= fmax(ay, by);
}

static int seg_seg(double ax, double ay, double bx, double by, double cx, double cy, double dx,
                   double dy) {
  int o1 = orient(ax, ay, bx, by, cx, cy), o2 = orient(ax, ay, bx, by, dx, dy);
  int o3 = orient(cx, cy, dx, dy, ax, ay), o4 = orient(cx, cy, dx, dy, bx, by);
  if (o1 * o2 < 0 && o3 * o4 < 0) return 1;
  if (o1 == 0 && on_seg(ax, ay, bx, by, cx, cy)) return 1;
  if (o2 == 0 && on_seg(ax, ay, bx, by, dx, dy)) return 1;
  if (o3 == 0 && on_seg(cx, cy, dx, dy, ax, ay)) return 1;
  if (o4 == 0 && on_seg(cx, cy, dx, dy, bx, by)) return 1;
  return 0;
}

static int box_seg(const qk_shape_t *b, const qk_shape_t *g) {
  double x0 = fmin(b->x, b->a), y0 = fmin(b->y, b->b), x1 = fmax(b->x, b->a), y1 = fmax(b->y, b->b);
  if (g->x >= x0 && g->x <= x1 && g->y >= y0 && g->y <= y1) return 1;
  if (g->a >= x0 && g->a <= x1 && g->b >= y0 && g->b <= y1) return 1;
  return seg_seg(g->x, g->y, g->a, g->b, x0, y0, x1, y0) ||
         seg_seg(g->x, g->y, g->a, g->b, x1, y0, x1, y1) ||
         seg_seg(g->x, g->y, g->a, g->b, x1, y1, x0, y1) ||
         seg_seg(g->x, g->y, g->a, g->b, x0, y1, x0, y0);
}

static int overlap(const qk_shape_t *a, const qk_shape_t *b) {
  int ka = a->kind == QK_SHAPE_POINT ? QK_SHAPE_DISC : a->kind;
  int kb = b->kind == QK_SHAPE_POINT ? QK_SHAPE_DISC : b->kind;
  if (ka > kb) {
    const qk_shape_t *t = a;
    a = b, b = t;
    int k = ka;
    ka = kb, kb = k;
  }
  if (ka == QK_SHAPE_DISC && kb == QK_SHAPE_DISC) return disc_disc(a, b);
  if (ka == QK_SHAPE_DISC && kb == QK_SHAPE_BOX) return disc_box(a, b);
  if (ka == QK_SHAPE_DISC) return disc_seg(a, b);
  if (ka == QK_SHAPE_BOX && kb == QK_SHAPE_BOX)
    return fmax(fmin(a->x, a->a), fmin(b->x, b->a)) <= fmin(fmax(a->x, a->a), fmax(b->x, b->a)) &&
           fmax(fmin(a->y, a->b), fmin(b->y, b->b)) <= fmin(fmax(a->y, a->b), fmax(b->y, b->b));
  if (ka == QK_SHAPE_BOX) return box_seg(a, b);
  return seg_seg(a->x, a->y, a->a, a->b, b->x, b->y, b->a, b->b);
}

static int cmp_pair(const void *pa, const void *pb) {
  const uint64_t *a = pa, *b = pb;
  return (a[0] > b[0]) - (a[0] < b[0]) ? (a[0] > b[0]) - (a[0] < b[0])
                                       : (a[1] > b[1]) - (a[1] < b[1]);
}

/* The world's pairs (by object index) and the oracle's; both sorted. */
static size_t world_pairs(qk_world_t *w, qk_pairs_which_t which, const qk_handle_t *h, size_t n,
                          uint64_t *out, size_t cap) {
  size_t np = 0;
  assert_int_equal(qk_world_pairs_list(w, which, NULL, 0, &np), QK_OK);
  qk_world_pair_t *p = malloc((np + 1) * sizeof *p);
  assert_non_null(p);
  size_t got = 0;
  assert_int_equal(qk_world_pairs_list(w, which, p, np, &got), QK_OK);
  assert_int_equal(got, np);
  assert_true(np <= cap);
  for (size_t i = 0; i < np; i++) {
    uint64_t a = UINT64_MAX, b = UINT64_MAX;
    for (size_t k = 0; k < n; k++) { /* handles -> indices (slots: low 32 bits) */
      if (h[k] == p[i].a) a = k;
      if (h[k] == p[i].b) b = k;
    }
    assert_true(a != UINT64_MAX && b != UINT64_MAX && a != b);
    out[2 * i] = a < b ? a : b, out[2 * i + 1] = a < b ? b : a;
  }
  free(p);
  qsort(out, np, 2 * sizeof *out, cmp_pair);
  return np;
}

static size_t oracle_pairs(const qk_shape_t *s, size_t n, uint64_t *out) {
  size_t np = 0;
  for (size_t i = 0; i < n; i++)
    for (size_t j = i + 1; j < n; j++)
      if (overlap(&s[i], &s[j])) out[2 * np] = i, out[2 * np + 1] = j, np++;
  return np;
}

static void compare(const uint64_t *got, size_t ng, const uint64_t *want, size_t nw,
                    const qk_shape_t *s, const char *what, uint64_t seed) {
  size_t i = 0, j = 0, bad = 0;
  while (i < ng || j < nw) {
    int c = i == ng ? 1 : j == nw ? -1 : cmp_pair(&got[2 * i], &want[2 * j]);
    if (c == 0) {
      i++, j++;
      continue;
    }
    const uint64_t *p = c < 0 ? &got[2 * i++] : &want[2 * j++];
    if (bad++ < 10) {
      const qk_shape_t *a = &s[p[0]], *b = &s[p[1]];
      print_error("%s (seed %llu): pair %llu-%llu %s: kinds %d %d, (%.17g %.17g %.17g %.17g) "
                  "(%.17g %.17g %.17g %.17g)\n",
                  what, (unsigned long long)seed, (unsigned long long)p[0],
                  (unsigned long long)p[1], c < 0 ? "reported, not overlapping" : "missed", a->kind,
                  b->kind, a->x, a->y, a->a, a->b, b->x, b->y, b->a, b->b);
    }
  }
  if (bad) fail_msg("%s: %zu pairs differ (world %zu, oracle %zu)", what, bad, ng, nw);
}

/* A random shape near (ox, oy) with a size from 1e-3 to 1e3 (log-uniform), coordinates
 * rounded to multiples of 2^-20 so that dyadic touching offsets stay exact at 1e9. */
static double grid(double v) { return ldexp(nearbyint(ldexp(v, 20)), -20); }

static qk_shape_t random_shape(qkt_rng_t *r, double ox, double oy, double spread) {
  double size = pow(10, qkt_rng_range(r, -3, 3));
  double x = grid(ox + qkt_rng_range(r, 0, spread)), y = grid(oy + qkt_rng_range(r, 0, spread));
  qk_shape_t s = {(qk_shape_kind_t)qkt_rng_below(r, 4), x, y, 0, 0};
  switch (s.kind) {
  case QK_SHAPE_DISC:
    s.a = grid(size) > 0 ? grid(size) : 0x1p-20;
    break;
  case QK_SHAPE_BOX:
    s.a = grid(x + size), s.b = grid(y + size * qkt_rng_range(r, 0.1, 1));
    break;
  case QK_SHAPE_SEGMENT:
    s.a = grid(x + size * qkt_rng_range(r, -1, 1)), s.b = grid(y + size * qkt_rng_range(r, -1, 1));
    break;
  default:
    break;
  }
  return s;
}

/* A shape exactly touching s (sharing a boundary point): dyadic offsets. */
static qk_shape_t touching(qkt_rng_t *r, const qk_shape_t *s) {
  double d = ldexp(1, -(int)qkt_rng_below(r, 8)); /* 1 .. 2^-7 */
  switch (s->kind) {
  case QK_SHAPE_DISC: /* a point, a disc or a box's corner on the rightmost point */
    if (qkt_rng_below(r, 2)) return (qk_shape_t){QK_SHAPE_POINT, s->x + s->a, s->y, 0, 0};
    return (qk_shape_t){QK_SHAPE_DISC, s->x + s->a + d, s->y, d, 0};
  case QK_SHAPE_BOX: { /* a box sharing the right side, or a segment ending on it */
    double xr = fmax(s->x, s->a), yt = fmax(s->y, s->b);
    if (qkt_rng_below(r, 2)) return (qk_shape_t){QK_SHAPE_BOX, xr, yt, xr + d, yt + d};
    return (qk_shape_t){QK_SHAPE_SEGMENT, xr + d, yt + d, xr, yt};
  }
  case QK_SHAPE_SEGMENT: /* a segment from its end, or a point on it */
    if (qkt_rng_below(r, 2)) return (qk_shape_t){QK_SHAPE_SEGMENT, s->a, s->b, s->a + d, s->b - d};
    return (qk_shape_t){QK_SHAPE_POINT, s->x, s->y, 0, 0};
  default: /* a disc through the point */
    return (qk_shape_t){QK_SHAPE_DISC, s->x - d, s->y, d, 0};
  }
}

static void run_scene(qk_shape_t *s, size_t n, const char *what, qkt_rng_t *r, uint64_t seed) {
  qk_world_t *w = NULL;
  assert_int_equal(qk_world_new(NULL, &w), QK_OK);
  qk_handle_t *h = malloc(n * sizeof *h);
  size_t cap = n * (n - 1) / 2 + 1;
  /* (zeroed: gcc 12 at -O3 otherwise takes the oracle's writes for reads of nothing) */
  uint64_t *got = calloc(2 * cap, sizeof *got), *want = calloc(2 * cap, sizeof *want);
  uint64_t *prev = calloc(2 * cap, sizeof *prev), *diff = calloc(2 * cap, sizeof *diff);
  assert_true(h && got && want && prev && diff);
  for (size_t i = 0; i < n; i++) assert_int_equal(qk_world_add(w, &s[i], i, &h[i]), QK_OK);
  assert_int_equal(qk_world_update(w), QK_OK);
  size_t ng = world_pairs(w, QK_PAIRS_ALL, h, n, got, cap);
  size_t nw = oracle_pairs(s, n, want);
  compare(got, ng, want, nw, s, what, seed);
  memcpy(prev, want, 2 * nw * sizeof *want);
  size_t nprev = nw;
  /* Move half the objects (by a dyadic step, or onto another object's shape). */
  for (size_t i = 0; i < n; i += 2) {
    if (qkt_rng_below(r, 4) == 0)
      s[i] = s[qkt_rng_below(r, (uint32_t)n)];
    else {
      double d = ldexp(1, (int)qkt_rng_below(r, 12) - 8);
      s[i].x += d, s[i].y -= d;
      if (s[i].kind != QK_SHAPE_DISC) s[i].a += d, s[i].b -= d;
    }
    assert_int_equal(qk_world_move(w, h[i], &s[i]), QK_OK);
  }
  assert_int_equal(qk_world_update(w), QK_OK);
  ng = world_pairs(w, QK_PAIRS_ALL, h, n, got, cap);
  nw = oracle_pairs(s, n, want);
  char buf[160];
  snprintf(buf, sizeof buf, "%s, after moves", what);
  compare(got, ng, want, nw, s, buf, seed);
  /* began = now - before, ended = before - now */
  for (int which = 0; which < 2; which++) {
    const uint64_t *a = which ? prev : want, *b = which ? want : prev;
    size_t na = which ? nprev : nw, nb = which ? nw : nprev, nd = 0, j = 0;
    for (size_t i = 0; i < na; i++) {
      while (j < nb && cmp_pair(&b[2 * j], &a[2 * i]) < 0) j++;
      if (j == nb || cmp_pair(&b[2 * j], &a[2 * i]) != 0)
        diff[2 * nd] = a[2 * i], diff[2 * nd + 1] = a[2 * i + 1], nd++;
    }
    ng = world_pairs(w, which ? QK_PAIRS_ENDED : QK_PAIRS_BEGAN, h, n, got, cap);
    snprintf(buf, sizeof buf, "%s, %s pairs", what, which ? "ended" : "began");
    compare(got, ng, diff, nd, s, buf, seed);
  }
  print_message("%s: %zu objects, %zu pairs after the moves\n", what, n, nw);
  qk_world_free(w);
  free(h), free(got), free(want), free(prev), free(diff);
}

/* The oracle on hand-made cases, so that it can be trusted to fail. */
static void test_sweep_world_oracle(void **state) {
  (void)state;
  const double X = 1e9;
  qk_shape_t d = {QK_SHAPE_DISC, X, X, 0.5, 0};
  qk_shape_t p_on = {QK_SHAPE_POINT, X + 0.5, X, 0, 0};
  qk_shape_t p_off = {QK_SHAPE_POINT, nextafter(X + 0.5, INFINITY), X, 0, 0};
  assert_true(overlap(&d, &p_on) && !overlap(&d, &p_off));
  qk_shape_t b1 = {QK_SHAPE_BOX, X, X, X + 1, X + 1},
             b2 = {QK_SHAPE_BOX, X + 1, X + 1, X + 2, X + 2};
  qk_shape_t b3 = {QK_SHAPE_BOX, nextafter(X + 1, INFINITY), X, X + 2, X + 1};
  assert_true(overlap(&b1, &b2) && !overlap(&b1, &b3));
  qk_shape_t g_cross = {QK_SHAPE_SEGMENT, X - 1, X + 0.5, X + 2, X + 0.5}; /* through b1 */
  qk_shape_t g_miss = {QK_SHAPE_SEGMENT, X - 1, X + 0.5, X, X + 2};        /* by its corner */
  assert_true(overlap(&b1, &g_cross) && !overlap(&b1, &g_miss));
  qk_shape_t g_tan = {QK_SHAPE_SEGMENT, X - 1, X + 0.5, X + 1, X + 0.5}; /* tangent to d */
  qk_shape_t g_tan2 = {QK_SHAPE_SEGMENT, X - 1, nextafter(X + 0.5, INFINITY), X + 1,
                       nextafter(X + 0.5, INFINITY)};
  assert_true(overlap(&d, &g_tan) && !overlap(&d, &g_tan2));
  qk_shape_t g1 = {QK_SHAPE_SEGMENT, X, X, X + 2, X + 2},
             g2 = {QK_SHAPE_SEGMENT, X + 1, X + 1, X + 3, X + 3};
  qk_shape_t g3 = {QK_SHAPE_SEGMENT, X + 3, X + 3, X + 4, X + 4};
  assert_true(overlap(&g1, &g2) && !overlap(&g1, &g3));      /* collinear: overlapping, apart */
  qk_shape_t d2 = {QK_SHAPE_DISC, X + 1.5, X + 0.5, 0.5, 0}; /* touches b1's right side */
  qk_shape_t d3 = {QK_SHAPE_DISC, X + 1.5, X + 0.5, 0.4375, 0};
  assert_true(overlap(&b1, &d2) && !overlap(&b1, &d3));
}

static void test_sweep_world_scenes(void **state) {
  (void)state;
  uint64_t seed = qkt_seed(2027);
  qkt_rng_t r;
  qkt_rng_seed(&r, seed);
  enum { N = 600 };
  qk_shape_t *s = malloc(N * sizeof *s);
  assert_non_null(s);
  static const double origins[3] = {1e9, -1e9, 0};
  for (int o = 0; o < 3; o++) {
    /* Mixed sizes 1e-3..1e3 in a 3000-wide square at the origin, with touching partners
     * and a block of coincident copies. */
    size_t n = 0;
    while (n < N - 120) {
      s[n] = random_shape(&r, origins[o], origins[o], 3000);
      n++;
      if (qkt_rng_below(&r, 3) == 0) s[n] = touching(&r, &s[n - 1]), n++;
    }
    for (int k = 0; k < 4; k++) { /* 25 identical copies of one shape of each kind */
      qk_shape_t c = random_shape(&r, origins[o], origins[o], 3000);
      c.kind = (qk_shape_kind_t)k;
      if (k == QK_SHAPE_DISC) c.a = 0.5;
      if (k == QK_SHAPE_BOX || k == QK_SHAPE_SEGMENT) c.a = c.x + 0.25, c.b = c.y + 0.75;
      for (int m = 0; m < 25 && n < N; m++) s[n++] = c;
    }
    char what[64];
    snprintf(what, sizeof what, "scene at %g", origins[o]);
    run_scene(s, n, what, &r, seed);
  }
  /* Degenerate shapes on a coarse grid near 1e9, so many coincide or touch: discs of
   * radius 0, boxes of zero width or height, segments of zero length, points. */
  size_t n = 400;
  for (size_t i = 0; i < n; i++) {
    double x = 1e9 + 0.25 * qkt_rng_below(&r, 6), y = -1e9 + 0.25 * qkt_rng_below(&r, 6);
    double dx = 0.25 * qkt_rng_below(&r, 3), dy = 0.25 * qkt_rng_below(&r, 3);
    switch (qkt_rng_below(&r, 4)) {
    case 0:
      s[i] = (qk_shape_t){QK_SHAPE_DISC, x, y, qkt_rng_below(&r, 2) ? 0 : dx, 0};
      break;
    case 1:
      s[i] = (qk_shape_t){QK_SHAPE_BOX, x, y, x + dx, y};
      break;
    case 2:
      s[i] = (qk_shape_t){QK_SHAPE_SEGMENT, x, y, x + dx * qkt_rng_below(&r, 2), y - dy};
      break;
    default:
      s[i] = (qk_shape_t){QK_SHAPE_POINT, x, y, 0, 0};
      break;
    }
  }
  run_scene(s, n, "degenerate shapes on a grid", &r, seed);
  /* Discs all but tangent to segments at any angle, far from the origin: the radius is
   * the centre's distance to the segment's line (in long double), moved by up to two
   * ulps either way, so that the line-to-centre test is decided in doubles only when
   * its rounding allows and exactly otherwise. Each pair stands apart from the others. */
  n = 0;
  for (int i = 0; i < 150; i++) {
    double ox = 1e6 + 20.0 * i, oy = -3e5 + qkt_rng_range(&r, 0, 1);
    double ang = qkt_rng_range(&r, 0, 6.283185307179586), len = qkt_rng_range(&r, 1, 5);
    qk_shape_t g = {QK_SHAPE_SEGMENT, ox, oy, ox + len * cos(ang), oy + len * sin(ang)};
    double u = qkt_rng_range(&r, 0.3, 0.7), d = qkt_rng_range(&r, 0.2, 2);
    double cx = g.x + u * (g.a - g.x) - d * sin(ang), cy = g.y + u * (g.b - g.y) + d * cos(ang);
    long double vx = (long double)g.a - g.x, vy = (long double)g.b - g.y;
    long double cr = vx * ((long double)cy - g.y) - vy * ((long double)cx - g.x);
    double rad = (double)(fabsl(cr) / sqrtl(vx * vx + vy * vy));
    for (int k = (int)qkt_rng_below(&r, 5) - 2; k < 0; k++) rad = nextafter(rad, 0);
    for (int k = (int)qkt_rng_below(&r, 5) - 2; k > 0; k--) rad = nextafter(rad, INFINITY);
    s[n++] = g;
    s[n++] = (qk_shape_t){QK_SHAPE_DISC, cx, cy, rad, 0};
  }
  run_scene(s, n, "discs all but tangent to segments", &r, seed);
  free(s);
}
#else
static void test_sweep_world_oracle(void **state) {
  (void)state;
  skip();
}
static void test_sweep_world_scenes(void **state) {
  (void)state;
  skip(); /* the exact oracle needs GMP */
}
#endif

int main(void) {
  const struct CMUnitTest tests[] = {
      cmocka_unit_test(test_sweep_world_oracle),
      cmocka_unit_test(test_sweep_world_scenes),
  };
  return cmocka_run_group_tests(tests, NULL, NULL);
}
