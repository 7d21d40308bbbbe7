/*
 * Test plan for the moving-objects world (collide/world*.c):
 *  - every frame of seeded random scenes (uniform, clustered, mixed sizes over six
 *    decades, all four kinds, objects added and removed mid-run) against an O(n^2) loop
 *    over a mirror of the objects: pairs (also into a short buffer), began / ended sets
 *    (short rows and long rows take different merges; both occur), objects overlapping a
 *    random box / disc / point / segment, all hits of a segment (as a set, in order of t)
 *    and the first hit, k nearest (distances); queries also between moves and the update;
 *  - k nearest for k from 1 to beyond the number of objects, hit by hit in order against
 *    an exact oracle, among exact ties (integer points and boxes, slots reused);
 *  - a huge world: unit objects at coordinates near 1e9, and sizes 1e-3 .. 1e3 together;
 *  - the bench's clustered mixed-size scene, small (boxes of 0.03 .. 30 on a 1/64 grid in
 *    eight clusters, moving; also with discs, segments and points): large objects over
 *    many finer levels' cells, inside them and on their borders; and its frames in which
 *    only the pairs that began are searched for (boxes on the float grid, none added or
 *    removed; also frames without moves, with jumps, a box off the grid), on 1-3 threads;
 *    the began pairs' sort and the rows' join by ranges of slots on 1, 2, 3 and 8 threads
 *    where the began pairs fall unevenly (a box over every cluster: empty ranges; only
 *    the lowest or highest slots jumping; pairs past the last old row alone; none), and
 *    the re-filing's merge on ranges cut by work (only small, only large, all objects
 *    re-filed), every frame against brute force;
 *  - a dense world (about 2.4 M pairs) whose update keeps its large buffers for the next
 *    one: pairs, began and ended every frame, on one thread and two;
 *  - hand-made touching cases of every pair of kinds (integers: the oracle is exact);
 *    queries of every kind between the points of an integer grid against one object of
 *    each kind; near misses by one ulp at small coordinates, which the exact expansions
 *    decide (their value a tiny positive number);
 *  - objects moved just out of their cells' loose squares through each side (re-filed:
 *    queries beyond that side and the pairs there, before and after the update);
 *  - the batch of first hits against single casts, for counts around its chunks;
 *    segments ending on a circle along its tangent: every hit's t in [0, 1];
 *  - stale handles are rejected after removal and slot reuse;
 *  - churn: 10^5 frames of moves, adds and removes on a small world stay within 1.2x the
 *    memory of a fresh world holding the same objects;
 *  - allocation failure at every N in add and update leaves the world unchanged, no leak
 *    (also in a began-only update on two and three threads, and in a threaded update
 *    whose large scratch comes from the blocks the update before kept);
 *  - the update's kept scratch: a steady frame allocates (almost) no fresh large block,
 *    every block given back with the size it was allocated with and its canary intact,
 *    the kept bytes dropping when the world shrinks, every byte back after free;
 *  - two threads give the same pairs and batch ray hits as one (also on both sides of
 *    thread_min, live objects crossing it), and three reader threads
 *    querying one world at once get the single-threaded answers (run under TSan by
 *    scripts/tsan.sh); a child forked after the world's workers started (they are not in
 *    it) updates on threads of its own, with one thread's answers.
 * The oracle computes overlap in long double from the textbook formulas (distance from a
 * point to a segment, orientation signs), independently of the library's exact code.
 */
#define _POSIX_C_SOURCE 200809L /* fork, waitpid, alarm */
#include <math.h>
#include <pthread.h>
#include <sys/wait.h>
#include <unistd.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "collide/world_internal.h" /* (the re-filings: test_world_step_margin) */
#include "qk_test.h"
#ifdef QK_HAVE_GMP
#include <gmp.h>
#endif

static uint64_t g_seed;

/* Under ThreadSanitizer (QKT_TSAN: scripts/tsan.sh, which is here for the threaded tests)
 * a test that starts no thread is skipped (QKT_ONE_THREAD_TEST); tests of several thread
 * counts skip their one-thread runs there likewise, some threaded loops run shorter, and
 * the oracle's own code is not instrumented (QKT_SERIAL). */

/* ---- oracle --------------------------------------------------------------------------- */

typedef long double ld;

static QKT_SERIAL ld o_seg_d2(ld px, ld py, ld ax, ld ay, ld bx, ld by) {
  ld ux = bx - ax, uy = by - ay, uu = ux * ux + uy * uy;
  ld t = uu > 0 ? ((px - ax) * ux + (py - ay) * uy) / uu : 0;
  t = t < 0 ? 0 : t > 1 ? 1 : t;
  ld dx = px - (ax + t * ux), dy = py - (ay + t * uy);
  return dx * dx + dy * dy;
}
/* A disc (centre px, py, radius r) meets a segment: the squared distance to its nearest
 * endpoint against r^2 where that endpoint is nearest, else the squared cross product
 * against r^2 times the squared length (no division). In long double, and where a
 * comparison there is too close to call, exactly with GMP: the long double missed by 3e-30
 * in d^2 - r^2 a disc that misses a segment's endpoint (seed 25). */
static QKT_SERIAL int o_disc_seg_exact(double px, double py, double r, double ax, double ay,
                                       double bx, double by);
/* a - b too close to call in long double: within 10^-15 of mag, the size of the terms
 * that made a and b (their rounding errors are below 10^-18 of it). */
static QKT_SERIAL int o_close(ld a, ld b, ld mag) { return fabsl(a - b) <= 1e-15L * mag; }
static QKT_SERIAL int o_disc_seg(double px, double py, double r, double ax, double ay, double bx,
                                 double by) {
  ld ux = (ld)bx - ax, uy = (ld)by - ay, uu = ux * ux + uy * uy, wx = (ld)px - ax, wy = (ld)py - ay;
  ld dot = wx * ux + wy * uy, dmag = fabsl(wx * ux) + fabsl(wy * uy), r2 = (ld)r * r;
  if (o_close(dot, 0, dmag) || o_close(dot, uu, dmag + uu))
    return o_disc_seg_exact(px, py, r, ax, ay, bx, by);
  ld lhs, rhs, mag;
  if (uu == 0 || dot < 0) {
    lhs = wx * wx + wy * wy, rhs = r2, mag = lhs + rhs;
  } else if (dot > uu) {
    ld vx = (ld)px - bx, vy = (ld)py - by;
    lhs = vx * vx + vy * vy, rhs = r2, mag = lhs + rhs;
  } else {
    ld c1 = wx * uy, c2 = wy * ux, cmag = fabsl(c1) + fabsl(c2);
    lhs = (c1 - c2) * (c1 - c2), rhs = r2 * uu, mag = cmag * cmag + rhs;
  }
  if (o_close(lhs, rhs, mag)) return o_disc_seg_exact(px, py, r, ax, ay, bx, by);
  return lhs <= rhs;
}
/* Whether (px - cx)^2 + (py - cy)^2 <= (r1 + r2)^2: a point within a disc, two discs (radii
 * r1, r2), or a disc's centre and the nearest point of a box. Exactly with GMP (a double is
 * a rational), which `make test` installs: in long double, the 2^-60 or so by which a disc
 * misses a box at a corner it nearly touches vanishes beside r^2 (seed 3 found one). */
static QKT_SERIAL int o_within(double px, double cx, double py, double cy, double r1, double r2) {
#ifdef QK_HAVE_GMP
  mpq_t d, e, t;
  mpq_inits(d, e, t, NULL);
  mpq_set_d(d, px), mpq_set_d(t, cx), mpq_sub(d, d, t), mpq_mul(d, d, d); /* dx^2 */
  mpq_set_d(e, py), mpq_set_d(t, cy), mpq_sub(e, e, t), mpq_mul(e, e, e); /* dy^2 */
  mpq_add(d, d, e);
  mpq_set_d(e, r1), mpq_set_d(t, r2), mpq_add(e, e, t), mpq_mul(e, e, e); /* (r1 + r2)^2 */
  const int in = mpq_cmp(d, e) <= 0;
  mpq_clears(d, e, t, NULL);
  return in;
#else
  ld dx = (ld)px - cx, dy = (ld)py - cy, rs = (ld)r1 + r2;
  return dx * dx + dy * dy <= rs * rs;
#endif
}
static QKT_SERIAL int o_disc_seg_exact(double px, double py, double r, double ax, double ay,
                                       double bx, double by) {
#ifdef QK_HAVE_GMP
  mpq_t ux, uy, wx, wy, t, u;
  mpq_inits(ux, uy, wx, wy, t, u, NULL);
  mpq_set_d(ux, bx), mpq_set_d(t, ax), mpq_sub(ux, ux, t);
  mpq_set_d(uy, by), mpq_set_d(t, ay), mpq_sub(uy, uy, t);
  mpq_set_d(wx, px), mpq_set_d(t, ax), mpq_sub(wx, wx, t);
  mpq_set_d(wy, py), mpq_set_d(t, ay), mpq_sub(wy, wy, t);
  mpq_mul(t, wx, ux), mpq_mul(u, wy, uy), mpq_add(t, t, u); /* dot */
  mpq_t uu;
  mpq_init(uu);
  mpq_mul(u, ux, ux), mpq_mul(uu, uy, uy), mpq_add(uu, uu, u); /* |u|^2 */
  int in;
  if (mpq_sgn(uu) == 0 || mpq_sgn(t) <= 0)
    in = o_within(px, ax, py, ay, r, 0);
  else if (mpq_cmp(t, uu) >= 0)
    in = o_within(px, bx, py, by, r, 0);
  else { /* (wx uy - wy ux)^2 <= r^2 |u|^2 */
    mpq_mul(t, wx, uy), mpq_mul(u, wy, ux), mpq_sub(t, t, u), mpq_mul(t, t, t);
    mpq_set_d(u, r), mpq_mul(u, u, u), mpq_mul(u, u, uu);
    in = mpq_cmp(t, u) <= 0;
  }
  mpq_clears(ux, uy, wx, wy, t, u, uu, NULL);
  return in;
#else
  ld ux = (ld)bx - ax, uy = (ld)by - ay, uu = ux * ux + uy * uy, wx = (ld)px - ax, wy = (ld)py - ay;
  ld dot = wx * ux + wy * uy;
  if (uu == 0 || dot <= 0) return wx * wx + wy * wy <= (ld)r * r;
  if (dot >= uu) return ((ld)px - bx) * ((ld)px - bx) + ((ld)py - by) * ((ld)py - by) <= (ld)r * r;
  ld cr = wx * uy - wy * ux;
  return cr * cr <= (ld)r * r * uu;
#endif
}
/* The sign of (b - a) x (c - a): in long double, and exactly with GMP where that is too
 * close to call. */
static QKT_SERIAL int o_orient(double ax, double ay, double bx, double by, double cx, double cy) {
  ld l = ((ld)bx - ax) * ((ld)cy - ay), r = ((ld)by - ay) * ((ld)cx - ax);
#ifdef QK_HAVE_GMP
  if (o_close(l, r, fabsl(l) + fabsl(r))) {
    mpq_t p, q, t, u;
    mpq_inits(p, q, t, u, NULL);
    mpq_set_d(p, bx), mpq_set_d(t, ax), mpq_sub(p, p, t);                   /* bx - ax */
    mpq_set_d(u, cy), mpq_set_d(t, ay), mpq_sub(u, u, t), mpq_mul(p, p, u); /* (cy - ay) */
    mpq_set_d(q, by), mpq_sub(q, q, t);                                     /* by - ay */
    mpq_set_d(u, cx), mpq_set_d(t, ax), mpq_sub(u, u, t), mpq_mul(q, q, u); /* (cx - ax) */
    const int c = mpq_cmp(p, q);
    mpq_clears(p, q, t, u, NULL);
    return (c > 0) - (c < 0);
  }
#endif
  ld d = l - r;
  return (d > 0) - (d < 0);
}
static QKT_SERIAL int o_onseg(double px, double py, const qk_shape_t *s) {
  return o_orient(s->x, s->y, s->a, s->b, px, py) == 0 && px >= fminl(s->x, s->a) &&
         px <= fmaxl(s->x, s->a) && py >= fminl(s->y, s->b) && py <= fmaxl(s->y, s->b);
}
static QKT_SERIAL int o_segseg(const qk_shape_t *g, const qk_shape_t *h) {
  int o1 = o_orient(g->x, g->y, g->a, g->b, h->x, h->y),
      o2 = o_orient(g->x, g->y, g->a, g->b, h->a, h->b);
  int o3 = o_orient(h->x, h->y, h->a, h->b, g->x, g->y),
      o4 = o_orient(h->x, h->y, h->a, h->b, g->a, g->b);
  if (o1 * o2 < 0 && o3 * o4 < 0) return 1;
  return o_onseg(h->x, h->y, g) || o_onseg(h->a, h->b, g) || o_onseg(g->x, g->y, h) ||
         o_onseg(g->a, g->b, h);
}
/* Squared distance from a point to a shape (0 inside). */
static QKT_SERIAL ld o_d2(const qk_shape_t *s, ld px, ld py) {
  switch (s->kind) {
  case QK_SHAPE_DISC: {
    ld dx = px - s->x, dy = py - s->y, d = sqrtl(dx * dx + dy * dy) - s->a;
    return d <= 0 ? 0 : d * d;
  }
  case QK_SHAPE_BOX: {
    ld dx = px < s->x ? s->x - px : px > s->a ? px - s->a : 0;
    ld dy = py < s->y ? s->y - py : py > s->b ? py - s->b : 0;
    return dx * dx + dy * dy;
  }
  case QK_SHAPE_SEGMENT:
    return o_seg_d2(px, py, s->x, s->y, s->a, s->b);
  default:
    return (px - s->x) * (px - s->x) + (py - s->y) * (py - s->y);
  }
}
static QKT_SERIAL qk_shape_t o_norm(qk_shape_t s) {
  if (s.kind == QK_SHAPE_BOX) {
    double x0 = fmin(s.x, s.a), x1 = fmax(s.x, s.a), y0 = fmin(s.y, s.b), y1 = fmax(s.y, s.b);
    s.x = x0, s.a = x1, s.y = y0, s.b = y1;
  }
  return s;
}
static QKT_SERIAL int o_overlap(qk_shape_t a, qk_shape_t b) {
  a = o_norm(a), b = o_norm(b);
  if (a.kind > b.kind) {
    qk_shape_t t = a;
    a = b, b = t;
  }
  /* kinds: DISC 0, BOX 1, SEGMENT 2, POINT 3 */
  if (b.kind == QK_SHAPE_POINT) {
    if (a.kind == QK_SHAPE_SEGMENT) return o_onseg(b.x, b.y, &a);
    if (a.kind == QK_SHAPE_DISC) return o_within(b.x, a.x, b.y, a.y, a.a, 0);
    return o_d2(&a, b.x, b.y) == 0;
  }
  if (a.kind == QK_SHAPE_DISC && b.kind == QK_SHAPE_DISC)
    return o_within(b.x, a.x, b.y, a.y, a.a, b.a);
  if (a.kind == QK_SHAPE_DISC && b.kind == QK_SHAPE_BOX) /* (the box's point nearest the centre) */
    return o_within(fmin(fmax(a.x, b.x), b.a), a.x, fmin(fmax(a.y, b.y), b.b), a.y, a.a, 0);
  if (a.kind == QK_SHAPE_DISC) return o_disc_seg(a.x, a.y, a.a, b.x, b.y, b.a, b.b);
  if (a.kind == QK_SHAPE_BOX && b.kind == QK_SHAPE_BOX)
    return a.x <= b.a && b.x <= a.a && a.y <= b.b && b.y <= a.b;
  if (a.kind == QK_SHAPE_BOX) { /* segment: an endpoint inside, or it crosses an edge */
    if (o_d2(&a, b.x, b.y) == 0 || o_d2(&a, b.a, b.b) == 0) return 1;
    qk_shape_t e[4] = {{QK_SHAPE_SEGMENT, a.x, a.y, a.a, a.y},
                       {QK_SHAPE_SEGMENT, a.a, a.y, a.a, a.b},
                       {QK_SHAPE_SEGMENT, a.a, a.b, a.x, a.b},
                       {QK_SHAPE_SEGMENT, a.x, a.b, a.x, a.y}};
    for (int i = 0; i < 4; i++)
      if (o_segseg(&e[i], &b)) return 1;
    return 0;
  }
  return o_segseg(&a, &b);
}

/* ---- scenes ----------------------------------------------------------------------------- */

enum { SC_UNIFORM, SC_CLUSTERED, SC_MIXED, SC_HUGE };

static qk_shape_t rnd_shape(qkt_rng_t *r, int scene, int kinds) {
  double x = qkt_rng_unit(r) * 100, y = qkt_rng_unit(r) * 100, s = qkt_rng_range(r, 0.5, 3);
  if (scene == SC_CLUSTERED && qkt_rng_below(r, 4)) x = 40 + x * 0.05, y = 60 + y * 0.05;
  if (scene == SC_MIXED) s = pow(10, qkt_rng_range(r, -3, 3)) * (qkt_rng_below(r, 3) ? 0.01 : 1);
  if (scene == SC_HUGE) x = 1e9 + x, y = -1e9 + y;
  qk_shape_t sh = {QK_SHAPE_DISC, x, y, s / 2, 0};
  int k = kinds ? (int)qkt_rng_below(r, 4) : 0;
  if (k == 1)
    sh = (qk_shape_t){QK_SHAPE_BOX, x, y, x + s * qkt_rng_unit(r), y + s * qkt_rng_unit(r)};
  if (k == 2) {
    double a = qkt_rng_range(r, 0, 6.28);
    sh = (qk_shape_t){QK_SHAPE_SEGMENT, x, y, x + s * cos(a), y + s * sin(a)};
  }
  if (k == 3) sh = (qk_shape_t){QK_SHAPE_POINT, x, y, 0, 0};
  return sh;
}

static qk_shape_t moved(qkt_rng_t *r, qk_shape_t s) {
  double dx = qkt_rng_range(r, -0.7, 0.7), dy = qkt_rng_range(r, -0.7, 0.7);
  s.x += dx, s.y += dy;
  if (s.kind == QK_SHAPE_BOX || s.kind == QK_SHAPE_SEGMENT) s.a += dx, s.b += dy;
  return s;
}

typedef struct mirror {
  qk_handle_t *h;
  qk_shape_t *s;
  size_t n, cap;
} mirror_t;

static void m_add(qk_world_t *w, mirror_t *m, qk_shape_t s) {
  if (m->n == m->cap) {
    m->cap = m->cap ? 2 * m->cap : 64;
    m->h = realloc(m->h, m->cap * sizeof *m->h);
    m->s = realloc(m->s, m->cap * sizeof *m->s);
  }
  assert_int_equal(qk_world_add(w, &s, m->n, &m->h[m->n]), QK_OK);
  m->s[m->n++] = o_norm(s);
}

/* Move object i of the mirror to s, in the world and the mirror. */
static void m_move(qk_world_t *w, mirror_t *m, size_t i, qk_shape_t s) {
  assert_int_equal(qk_world_move(w, m->h[i], &s), QK_OK);
  m->s[i] = o_norm(s);
}

/* Remove a random object from the world and the mirror (the last one takes its place);
 * returns its index. */
static size_t m_remove_random(qk_world_t *w, mirror_t *m, qkt_rng_t *r) {
  size_t i = qkt_rng_below(r, (uint32_t)m->n);
  assert_int_equal(qk_world_remove(w, m->h[i]), QK_OK);
  m->n--;
  m->h[i] = m->h[m->n], m->s[i] = m->s[m->n];
  return i;
}

static QKT_SERIAL int wp_cmp(const void *x, const void *y) {
  const qk_world_pair_t *p = x, *q = y;
  uint32_t pa = (uint32_t)p->a, qa = (uint32_t)q->a, pb = (uint32_t)p->b, qb = (uint32_t)q->b;
  if (pa != qa) return pa < qa ? -1 : 1;
  return (pb > qb) - (pb < qb);
}

/* Blocks the oracle keeps from one call to the next (grown, never shrunk): the dense
 * scenes' lists are tens of MB, and a fresh block's pages faulted in at every frame were a
 * third of those tests' time (under ASan, whose large blocks are always fresh). Used on
 * the test's thread only; the blocks stay reachable until the process ends. Under ASan the
 * room past the bytes asked for is poisoned, so that the library writing a list past the
 * room it was given is caught as it was in a block of that size. */
#if QKT_ASAN
#include <sanitizer/asan_interface.h>
#else
#define ASAN_POISON_MEMORY_REGION(p, n) ((void)(p), (void)(n))
#define ASAN_UNPOISON_MEMORY_REGION(p, n) ((void)(p), (void)(n))
#endif
typedef struct kept {
  void *p;
  size_t cap;
} kept_t;
static QKT_SERIAL void *kept_get(kept_t *k, size_t bytes) {
  if (bytes > k->cap) {
    free(k->p);
    k->cap = bytes + bytes / 4;
    k->p = malloc(k->cap);
    assert_non_null(k->p);
  }
  ASAN_UNPOISON_MEMORY_REGION(k->p, bytes);
  ASAN_POISON_MEMORY_REGION((char *)k->p + bytes, k->cap - bytes);
  return k->p;
}
static kept_t g_kept_pairs, g_kept_sort, g_kept_boxes, g_kept_list, g_kept_began, g_kept_ended,
    g_kept_part;

/* Sorts v as wp_cmp orders it: by the slot of a, then of b. Many pairs go through an LSD
 * radix sort on the two 32-bit slots (four passes of 16 bits, a pass whose digit is the
 * same in every pair skipped: the high halves below 2^16 slots): qsort's comparisons of
 * the dense scenes' millions of pairs were half of this test's time. */
static QKT_SERIAL uint32_t pair_digit(const qk_world_pair_t *p, int pass) {
  uint64_t key = (uint64_t)(uint32_t)p->a << 32 | (uint32_t)p->b;
  return (uint32_t)(key >> (16 * pass)) & 0xFFFFu;
}
static QKT_SERIAL void sort_pairs(qk_world_pair_t *v, size_t n) {
  if (n < 4096) {
    if (n > 1) qsort(v, n, sizeof *v, wp_cmp);
    return;
  }
  static size_t at[65536];
  qk_world_pair_t *src = v, *dst = kept_get(&g_kept_sort, n * sizeof *dst);
  for (int pass = 0; pass < 4; pass++) {
    memset(at, 0, sizeof at);
    for (size_t i = 0; i < n; i++) at[pair_digit(&src[i], pass)]++;
    if (at[pair_digit(&src[0], pass)] == n) continue; /* (one digit: the order stays) */
    for (size_t d = 0, sum = 0; d < 65536; d++) {
      size_t c = at[d];
      at[d] = sum, sum += c;
    }
    for (size_t i = 0; i < n; i++) dst[at[pair_digit(&src[i], pass)]++] = src[i];
    qk_world_pair_t *t = src;
    src = dst, dst = t;
  }
  if (src != v) memcpy(v, src, n * sizeof *v);
}

/* All pairs by brute force, ordered as the library orders them. */
/* A box that holds shape s, widened by far more than the rounding of o_overlap's long
 * double tests, so that every pair o_overlap accepts has overlapping boxes. */
typedef struct obox {
  double x0, x1, y0, y1;
  size_t i;
} obox_t;
static QKT_SERIAL obox_t o_bounds(qk_shape_t s, size_t i) {
  s = o_norm(s);
  double r = s.kind == QK_SHAPE_DISC ? s.a : 0;
  double x1 = s.kind == QK_SHAPE_BOX || s.kind == QK_SHAPE_SEGMENT ? s.a : s.x;
  double y1 = s.kind == QK_SHAPE_BOX || s.kind == QK_SHAPE_SEGMENT ? s.b : s.y;
  obox_t b = {fmin(s.x, x1) - r, fmax(s.x, x1) + r, fmin(s.y, y1) - r, fmax(s.y, y1) + r, i};
  double e = (fabs(s.x) + fabs(s.y) + fabs(x1) + fabs(y1) + r) * 0x1p-40;
  b.x0 -= e, b.x1 += e, b.y0 -= e, b.y1 += e;
  return b;
}
static QKT_SERIAL int obox_cmp(const void *p, const void *q) {
  const obox_t *a = p, *b = q;
  return (a->x0 > b->x0) - (a->x0 < b->x0);
}

/* Every overlapping pair of the mirror, sorted. Brute force over all pairs, but pairs
 * whose bounding boxes are apart in x are skipped by a sweep over the boxes sorted by
 * their left edges (and those apart in y before the exact test), so that the scenes with
 * thousands of objects check quickly. */
static QKT_SERIAL size_t o_pairs(const mirror_t *m, qk_world_pair_t **out) {
  /* (gathered and sorted in a kept block, then copied to one of their size) */
  size_t n = 0, cap = g_kept_pairs.cap / sizeof(qk_world_pair_t);
  cap = cap > 64 ? cap : 64;
  qk_world_pair_t *v = kept_get(&g_kept_pairs, cap * sizeof *v);
  obox_t *bx = kept_get(&g_kept_boxes, (m->n ? m->n : 1) * sizeof *bx);
  for (size_t i = 0; i < m->n; i++) bx[i] = o_bounds(m->s[i], i);
  qsort(bx, m->n, sizeof *bx, obox_cmp);
  for (size_t p = 0; p < m->n; p++)
    for (size_t q = p + 1; q < m->n && bx[q].x0 <= bx[p].x1; q++) {
      if (bx[q].y0 > bx[p].y1 || bx[p].y0 > bx[q].y1) continue;
      size_t i = bx[p].i, j = bx[q].i;
      if (o_overlap(m->s[i], m->s[j])) {
        if (n == cap) {
          ASAN_UNPOISON_MEMORY_REGION(v, g_kept_pairs.cap);
          v = g_kept_pairs.p = realloc(v, (cap *= 2) * sizeof *v);
          assert_non_null(v);
          g_kept_pairs.cap = cap * sizeof *v;
        }
        qk_handle_t a = m->h[i], b = m->h[j];
        if ((uint32_t)a > (uint32_t)b) {
          qk_handle_t t = a;
          a = b, b = t;
        }
        v[n].a = a, v[n++].b = b;
      }
    }
  sort_pairs(v, n);
  *out = malloc((n ? n : 1) * sizeof *v);
  assert_non_null(*out);
  memcpy(*out, v, n * sizeof *v);
  return n;
}

/* p is in v[0 .. n), which is sorted as wp_cmp orders it and holds each pair of slots once:
 * the pair with p's slots, found by bisection, has p's handles. */
static QKT_SERIAL int in_list(const qk_world_pair_t *v, size_t n, qk_world_pair_t p) {
  const qk_world_pair_t *q = n ? bsearch(&p, v, n, sizeof *v, wp_cmp) : NULL;
  return q && q->a == p.a && q->b == p.b;
}

typedef struct cbctx {
  const qk_world_pair_t *want;
  size_t n, i;
  int ok;
} cbctx_t;

static int cb_pair(qk_handle_t a, qk_handle_t b, void *ud) {
  cbctx_t *c = ud;
  if (c->i >= c->n || c->want[c->i].a != a || c->want[c->i].b != b) c->ok = 0;
  c->i++;
  return 0;
}

/* cb_pair for the walk on the world's threads, with one worker (the pairs in order). */
static int cb_pair_worker(qk_handle_t a, qk_handle_t b, unsigned worker, void *ud) {
  if (worker != 0) ((cbctx_t *)ud)->ok = 0;
  return cb_pair(a, b, ud);
}

static int cb_stop(qk_handle_t a, qk_handle_t b, void *ud) {
  (void)a, (void)b;
  ++*(size_t *)ud;
  return 1;
}

static QKT_SERIAL void check_pairs(qk_world_t *w, const qk_world_pair_t *want, size_t nw,
                                   const qk_world_pair_t *prev, size_t np, const char *what,
                                   int frame) {
  size_t n;
  qk_world_pair_t *got = kept_get(&g_kept_list, (nw + np + 1) * sizeof *got);
  assert_int_equal(qk_world_pairs_list(w, QK_PAIRS_ALL, got, nw + np + 1, &n), QK_OK);
  if (n != nw)
    fail_msg("%s frame %d: %zu pairs, oracle %zu (seed %llu)", what, frame, n, nw,
             (unsigned long long)g_seed);
  for (size_t i = 0; i < n; i++)
    if (got[i].a != want[i].a || got[i].b != want[i].b)
      fail_msg("%s frame %d: pair %zu differs (seed %llu)", what, frame, i,
               (unsigned long long)g_seed);
  /* a short buffer: the full count, and the first cap pairs (rows cut in the middle) */
  if (nw > 1) {
    size_t cap = nw / 2 + (size_t)frame % 3, n2;
    qk_world_pair_t *part = kept_get(&g_kept_part, cap * sizeof *part);
    assert_int_equal(qk_world_pairs_list(w, QK_PAIRS_ALL, part, cap, &n2), QK_OK);
    assert_int_equal(n2, nw);
    for (size_t i = 0; i < cap && i < nw; i++)
      assert_true(part[i].a == want[i].a && part[i].b == want[i].b);
  }
  /* the callback form: the same pairs in the same order, and a nonzero return stops */
  cbctx_t cb = {want, nw, 0, 1};
  assert_int_equal(qk_world_pairs(w, QK_PAIRS_ALL, cb_pair, &cb), QK_OK);
  assert_true(cb.ok && cb.i == nw);
  size_t calls = 0;
  assert_int_equal(qk_world_pairs(w, QK_PAIRS_ALL, cb_stop, &calls), QK_OK);
  assert_int_equal(calls, nw ? 1 : 0);
  /* began: in want, not in prev; ended: in prev, not in want */
  size_t nb = 0, ne = 0;
  assert_int_equal(qk_world_pairs_list(w, QK_PAIRS_BEGAN, got, nw + np + 1, &nb), QK_OK);
  size_t exp_b = 0;
  for (size_t i = 0; i < nw; i++) exp_b += !in_list(prev, np, want[i]);
  assert_int_equal(nb, exp_b);
  for (size_t i = 0; i < nb; i++)
    assert_true(in_list(want, nw, got[i]) && !in_list(prev, np, got[i]));
  assert_int_equal(qk_world_pairs_list(w, QK_PAIRS_ENDED, got, nw + np + 1, &ne), QK_OK);
  size_t exp_e = 0;
  for (size_t i = 0; i < np; i++) exp_e += !in_list(want, nw, prev[i]);
  assert_int_equal(ne, exp_e);
  for (size_t i = 0; i < ne; i++)
    assert_true(in_list(prev, np, got[i]) && !in_list(want, nw, got[i]));
}

/* A frame's end: the update, then its pairs against the brute force over m and its began
 * and ended against *prev (check_pairs); *prev becomes this frame's pairs. */
static void update_and_check(qk_world_t *w, const mirror_t *m, qk_world_pair_t **prev, size_t *np,
                             const char *what, int frame) {
  assert_int_equal(qk_world_update(w), QK_OK);
  qk_world_pair_t *want;
  size_t nw = o_pairs(m, &want);
  check_pairs(w, want, nw, *prev, *np, what, frame);
  free(*prev);
  *prev = want, *np = nw;
}

/* qk_world_knn(p, k) against brute force: as many as there are up to k, in order, and
 * no more objects nearer than the i-th (by the oracle's distances, with a tolerance) than
 * i. `what` starts the failure message. */
static QKT_SERIAL void check_knn(qk_world_t *w, const mirror_t *m, qk_point_t p, size_t k,
                                 const char *what) {
  qk_world_hit_t nn[16];
  size_t nk;
  assert_true(k <= 16);
  assert_int_equal(qk_world_knn(w, p, k, nn, &nk), QK_OK);
  assert_int_equal(nk, m->n < k ? m->n : k);
  ld *d = malloc((m->n + 1) * sizeof *d);
  for (size_t i = 0; i < m->n; i++) d[i] = sqrtl(o_d2(&m->s[i], p.x, p.y));
  for (size_t i = 0; i < nk; i++) {
    size_t below = 0;
    for (size_t j = 0; j < m->n; j++) below += d[j] < nn[i].t - 1e-9 * (1 + nn[i].t + fabs(p.x));
    if (below > i)
      fail_msg("%sknn rank %zu: %zu objects nearer (seed %llu)", what, i, below,
               (unsigned long long)g_seed);
    if (i) assert_true(nn[i - 1].t <= nn[i].t);
  }
  free(d);
}

static QKT_SERIAL void check_queries(qkt_rng_t *r, qk_world_t *w, const mirror_t *m, int scene) {
  qk_handle_t *got = malloc((m->n + 1) * sizeof *got);
  for (int qi = 0; qi < 5; qi++) {
    /* kinds in turn; the fifth a long segment across the whole scene (walked cell by
     * cell at the fine levels rather than through its bounding box) */
    int q = qi == 4 ? 2 : qi;
    qk_shape_t qs = rnd_shape(r, scene, 1);
    qs.kind = (qk_shape_kind_t)q;
    if (q == 0) qs.a = qkt_rng_range(r, 0, 10);
    if (q == 1 || q == 2)
      qs.a = qs.x + qkt_rng_range(r, -10, 10), qs.b = qs.y + qkt_rng_range(r, -10, 10);
    if (qi == 4) {
      double off = scene == SC_HUGE ? 1e9 : 0;
      qs.x = off - 20, qs.a = off + 120;
      qs.y = qkt_rng_range(r, -20, 120) - off, qs.b = qkt_rng_range(r, -20, 120) - off;
      if (qkt_rng_below(r, 2)) { /* or mostly vertical */
        double t = qs.x;
        qs.x = qs.y + 2 * off, qs.y = t - 2 * off;
        t = qs.a;
        qs.a = qs.b + 2 * off, qs.b = t - 2 * off;
      }
    }
    size_t n, want = 0;
    assert_int_equal(qk_world_query(w, &qs, got, m->n + 1, &n), QK_OK);
    for (size_t i = 0; i < m->n; i++) want += o_overlap(qs, m->s[i]);
    if (n != want)
      fail_msg("query kind %d: %zu vs oracle %zu (seed %llu)", q, n, want,
               (unsigned long long)g_seed);
    for (size_t i = 0; i < n; i++) {
      size_t j = 0;
      while (j < m->n && m->h[j] != got[i]) j++;
      assert_true(j < m->n && o_overlap(qs, m->s[j]));
      if (i) assert_true((uint32_t)got[i - 1] < (uint32_t)got[i]);
    }
    /* a short buffer gets the first cap of the list (it got the first cap visited) */
    qk_handle_t *part = malloc((n + 1) * sizeof *part);
    for (size_t cap = 1; cap < n; cap = cap < 3 ? cap + 1 : cap * 2 + 1) {
      size_t np;
      assert_int_equal(qk_world_query(w, &qs, part, cap, &np), QK_OK);
      assert_int_equal(np, n);
      if (memcmp(part, got, cap * sizeof *part))
        fail_msg("query kind %d, %zu of %zu in the buffer: not the first by slot (seed %llu)", q,
                 cap, n, (unsigned long long)g_seed);
    }
    free(part);
    /* rays: the all-hits set is the segment query's; t nondecreasing; first = all[0] */
    if (q == 2) {
      qk_world_hit_t *hits = malloc((n + 1) * sizeof *hits), first;
      size_t nh;
      qk_point_t a = {qs.x, qs.y}, b = {qs.a, qs.b};
      assert_int_equal(qk_world_raycast_all(w, a, b, hits, n + 1, &nh), QK_OK);
      assert_int_equal(nh, n);
      for (size_t i = 0; i < nh; i++) {
        if (i) assert_true(hits[i - 1].t <= hits[i].t);
        assert_true(hits[i].t >= 0 && hits[i].t <= 1);
        /* the point at t is (nearly) on the shape */
        size_t j = 0;
        while (j < m->n && m->h[j] != hits[i].h) j++;
        assert_true(j < m->n);
        ld px = a.x + hits[i].t * ((ld)b.x - a.x), py = a.y + hits[i].t * ((ld)b.y - a.y);
        ld scale = 1 + fabsl(px) + fabsl(py);
        assert_true(sqrtl(o_d2(&m->s[j], px, py)) <= 1e-9 * scale);
      }
      qk_world_hit_t *hpart = malloc((nh + 1) * sizeof *hpart);
      for (size_t cap = 1; cap < nh; cap = cap < 3 ? cap + 1 : cap * 2 + 1) {
        size_t np;
        assert_int_equal(qk_world_raycast_all(w, a, b, hpart, cap, &np), QK_OK);
        assert_int_equal(np, nh);
        for (size_t i = 0; i < cap; i++)
          if (hpart[i].h != hits[i].h || hpart[i].t != hits[i].t)
            fail_msg("ray, %zu of %zu hits in the buffer: hit %zu is not the %zu-th in order "
                     "(seed %llu)",
                     cap, nh, i, i, (unsigned long long)g_seed);
      }
      free(hpart);
      assert_int_equal(qk_world_raycast(w, a, b, &first), QK_OK);
      if (nh)
        assert_true(first.h == hits[0].h && first.t == hits[0].t);
      else
        assert_true(first.h == QK_HANDLE_NONE);
      free(hits);
    }
  }
  check_knn(w, m,
            (qk_point_t){qkt_rng_unit(r) * 100 + (scene == SC_HUGE ? 1e9 : 0),
                         qkt_rng_unit(r) * 100 - (scene == SC_HUGE ? 1e9 : 0)},
            7, "");
  free(got);
}

/* A new world on that many threads, its threaded paths taken at any size (thread_min 0). */
static qk_world_t *threaded_world(unsigned threads) {
  qk_world_options_t o;
  qk_world_options_init(&o);
  o.threads = threads;
  o.thread_min = 0;
  qk_world_t *w;
  assert_int_equal(qk_world_new(&o, &w), QK_OK);
  return w;
}

static void run_scene(int scene, int kinds, size_t n, int frames, unsigned threads) {
  qkt_rng_t r;
  qkt_rng_seed(&r, g_seed + (uint64_t)scene * 7 + (uint64_t)kinds);
  qk_world_t *w = threaded_world(threads);
  mirror_t m = {0};
  for (size_t i = 0; i < n; i++) m_add(w, &m, rnd_shape(&r, scene, kinds));
  qk_world_pair_t *prev = NULL;
  size_t np = 0;
  qk_handle_t *bh = malloc((n + 1) * sizeof *bh);
  qk_shape_t *bs = malloc((n + 1) * sizeof *bs);
  for (int f = 0; f < frames; f++) {
    /* odd frames move by one qk_world_move_batch call, even ones object by object */
    size_t nb = 0;
    for (size_t i = 0; i < m.n; i++) {
      if (qkt_rng_below(&r, 3)) continue;
      qk_shape_t s = moved(&r, m.s[i]);
      if (f & 1) {
        if (nb < n)
          bh[nb] = m.h[i], bs[nb++] = s;
        else
          continue;
      } else {
        assert_int_equal(qk_world_move(w, m.h[i], &s), QK_OK);
      }
      m.s[i] = o_norm(s);
    }
    assert_int_equal(qk_world_move_batch(w, bh, bs, nb, NULL), QK_OK);
    if (f % 3 == 1) { /* remove a few, add a few */
      for (int k = 0; k < 5 && m.n > 0; k++) {
        (void)m_remove_random(w, &m, &r);
      }
      for (int k = 0; k < 4; k++) m_add(w, &m, rnd_shape(&r, scene, kinds));
    }
    /* Queries see moves at once: also between the moves and the update, when the moved-out,
     * added and removed objects are not yet filed (the dirty list). */
    if (f % 4 == 1) check_queries(&r, w, &m, scene);
    update_and_check(w, &m, &prev, &np, "scene", f);
    if (f % 4 == 0) check_queries(&r, w, &m, scene);
  }
  free(prev);
  free(bh), free(bs);
  free(m.h), free(m.s);
  qk_world_free(w);
}

static void test_world_uniform(void **s) {
  (void)s;
  QKT_ONE_THREAD_TEST();
  run_scene(SC_UNIFORM, 0, 400, 40, 1);
}
static void test_world_clustered(void **s) {
  (void)s;
  QKT_ONE_THREAD_TEST();
  run_scene(SC_CLUSTERED, 1, 300, 40, 1);
}
static void test_world_mixed_sizes(void **s) {
  (void)s;
  QKT_ONE_THREAD_TEST();
  run_scene(SC_MIXED, 1, 300, 30, 1);
}
static void test_world_all_kinds(void **s) {
  (void)s;
  QKT_ONE_THREAD_TEST();
  run_scene(SC_UNIFORM, 1, 400, 40, 1);
}
static void test_world_huge(void **s) {
  (void)s;
  QKT_ONE_THREAD_TEST();
  run_scene(SC_HUGE, 1, 300, 30, 1);
}
/* The library's list `which` equals v[0 .. n). */
static QKT_SERIAL void list_equals(qk_world_t *w, qk_pairs_which_t which, const qk_world_pair_t *v,
                                   size_t n, int frame) {
  size_t got;
  assert_int_equal(qk_world_pairs_list(w, which, NULL, 0, &got), QK_OK);
  if (got != n) fail_msg("dense frame %d list %d: %zu pairs, oracle %zu", frame, which, got, n);
  qk_world_pair_t *g = kept_get(&g_kept_list, (n ? n : 1) * sizeof *g);
  assert_int_equal(qk_world_pairs_list(w, which, g, n, &got), QK_OK);
  for (size_t i = 0; i < n; i++)
    if (g[i].a != v[i].a || g[i].b != v[i].b)
      fail_msg("dense frame %d list %d: pair %zu differs (seed %llu)", frame, which, i,
               (unsigned long long)g_seed);
}

/* update_and_check for many pairs: the pairs against brute force, began and ended
 * against a merge of the sorted last and new lists (a pair whose slots stay but whose
 * handles changed ended and began). */
static QKT_SERIAL void dense_check(qk_world_t *w, const mirror_t *m, qk_world_pair_t **prev,
                                   size_t *np, int frame) {
  assert_int_equal(qk_world_update(w), QK_OK);
  qk_world_pair_t *want;
  size_t nw = o_pairs(m, &want), i = 0, j = 0, nb = 0, ne = 0;
  list_equals(w, QK_PAIRS_ALL, want, nw, frame);
  qk_world_pair_t *b = kept_get(&g_kept_began, (nw + 1) * sizeof *b),
                  *e = kept_get(&g_kept_ended, (*np + 1) * sizeof *e);
  while (i < nw || j < *np) {
    int c = i == nw ? 1 : j == *np ? -1 : wp_cmp(&want[i], &(*prev)[j]);
    if (c == 0 && (want[i].a != (*prev)[j].a || want[i].b != (*prev)[j].b))
      b[nb++] = want[i++], e[ne++] = (*prev)[j++];
    else if (c == 0)
      i++, j++;
    else if (c < 0)
      b[nb++] = want[i++];
    else
      e[ne++] = (*prev)[j++];
  }
  list_equals(w, QK_PAIRS_BEGAN, b, nb, frame);
  list_equals(w, QK_PAIRS_ENDED, e, ne, frame);
  free(*prev);
  *prev = want, *np = nw;
}

/* A dense scene on w: n boxes of side 10 at corners uniform over [0, span]^2, then
 * `frames` frames of moves (frame 2 also removes one box and adds `add`, which reuses its
 * slot), each checked by dense_check and with more than min_pairs pairs. */
static void dense_scene(qk_world_t *w, qkt_rng_t *r, int n, double span, int frames, qk_shape_t add,
                        size_t min_pairs) {
  mirror_t m = {0};
  for (int i = 0; i < n; i++) {
    double x = qkt_rng_range(r, 0, span), y = qkt_rng_range(r, 0, span);
    m_add(w, &m, (qk_shape_t){QK_SHAPE_BOX, x, y, x + 10, y + 10});
  }
  qk_world_pair_t *prev = NULL;
  size_t np = 0;
  for (int f = 0; f < frames; f++) {
    for (size_t i = 0; i < m.n; i++) {
      qk_shape_t sh = moved(r, m.s[i]);
      m_move(w, &m, i, sh);
    }
    if (f == 2) {
      (void)m_remove_random(w, &m, r);
      m_add(w, &m, add);
    }
    dense_check(w, &m, &prev, &np, f);
    assert_true(np > min_pairs);
  }
  free(prev), free(m.h), free(m.s);
}

/* A dense world (2200 boxes of side 10 over an 11 x 11 square: about 2.4 M pairs) whose
 * buffers are large enough that the update keeps them for the next one (the keys with
 * the sort's scratch, the rows of the frame before last, the other threads' keys): frames
 * of moves, a remove and an add against brute force, on one thread and on two. */
static void test_world_dense_kept_scratch(void **s) {
  (void)s;
  /* (under TSan only the threaded world: one thread has nothing for it to check) */
  for (unsigned th = QKT_TSAN ? 2 : 1; th <= 2; th++) {
    qkt_rng_t r;
    qkt_rng_seed(&r, g_seed + 31 + th);
    qk_world_t *w = threaded_world(th);
    dense_scene(w, &r, 2200, 11, 4, (qk_shape_t){QK_SHAPE_BOX, 3, 3, 13, 13}, 2000000);
    qk_world_free(w);
  }
}

/* Over 2^20 pairs among 6000 boxes (of side 10 over a 60 x 60 square: about 1.5 M
 * pairs): the one-thread update sorts them into rows through buckets of slots (2^7 slots
 * a bucket here, the last one partial), each sorted alone; the frames (moves, then a
 * remove and an add reusing its slot) against brute force, in order. */
static void test_world_dense_buckets(void **s) {
  (void)s;
  QKT_ONE_THREAD_TEST();
  qkt_rng_t r;
  qkt_rng_seed(&r, g_seed + 57);
  qk_world_t *w;
  assert_int_equal(qk_world_new(NULL, &w), QK_OK);
  dense_scene(w, &r, 6000, 50, 3, (qk_shape_t){QK_SHAPE_BOX, 20, 20, 30, 30}, (size_t)1 << 20);
  qk_world_free(w);
}

/* From 4096 objects a threaded update sorts the pairs into rows and merges them with the
 * last frame's by ranges of slots, one range a thread: scenes with few pairs (the radix
 * sort of keys per range), with some pairs an object (the counting sorts per range; past
 * 2^16 slots, where a range's slots a and b no longer fit 32 bits together, with the keys
 * whole) and over 2^20 pairs (the buckets, split between the threads), on two and three
 * threads (ranges of uneven slot counts), each frame (moves, then a remove and an add
 * reusing its slot) against brute force; the merges read the last frame's keys as the
 * threads left them. */
static void test_world_threads_ranges(void **s) {
  (void)s;
  static const struct {
    int n;
    double span;
    size_t min_pairs;
  } sc[] = {
      {5000, 3000, 300}, {5000, 250, 20000}, {6000, 50, (size_t)1 << 20}, {70000, 3000, 50000}};
  for (unsigned th = 2; th <= 3; th++)
    for (size_t k = 0; k < sizeof sc / sizeof *sc; k++) {
      /* (under TSan the buckets' and the many slots' scenes on two threads only: the
       * longest by far there) */
      if (QKT_TSAN && th == 3 && k >= 2) continue;
      qkt_rng_t r;
      qkt_rng_seed(&r, g_seed + 61 + th * 8 + k);
      qk_world_t *w = threaded_world(th);
      double c = sc[k].span / 2;
      dense_scene(w, &r, sc[k].n, sc[k].span, 3, (qk_shape_t){QK_SHAPE_BOX, c, c, c + 10, c + 10},
                  sc[k].min_pairs);
      qk_world_free(w);
    }
}

/* Enough objects that the update packs the boxes on the threads and files the dirty
 * ones there (from 1024 of them, by the merge's ranges): frames of moves (by the batch
 * call), adds and removes give the same pairs, began and ended on two and three threads
 * as on one (checked against brute force by the scene tests). */
static void test_world_threads_frames(void **s) {
  (void)s;
  enum { N = 4500, W = 3 };
  qk_world_t *w[W];
  qk_handle_t *h[W];
  qk_shape_t *sh = malloc(N * sizeof *sh);
  qkt_rng_t r;
  qkt_rng_seed(&r, g_seed + 29);
  for (int i = 0; i < N; i++) sh[i] = rnd_shape(&r, SC_MIXED, 1);
  for (int t = 0; t < W; t++) {
    qk_world_options_t o;
    qk_world_options_init(&o);
    o.threads = (unsigned)t + 1;
    o.thread_min = 0; /* the threaded paths at this size too */
    assert_int_equal(qk_world_new(&o, &w[t]), QK_OK);
    h[t] = malloc(N * sizeof *h[t]);
    for (int i = 0; i < N; i++) assert_int_equal(qk_world_add(w[t], &sh[i], 0, &h[t][i]), QK_OK);
  }
  for (int f = 0; f < 6; f++) {
    for (int i = 0; i < N; i++) sh[i] = moved(&r, sh[i]);
    int gone = (int)qkt_rng_below(&r, N);
    for (int t = 0; t < W; t++) {
      assert_int_equal(qk_world_move_batch(w[t], h[t], sh, N, NULL), QK_OK);
      assert_int_equal(qk_world_remove(w[t], h[t][gone]), QK_OK);
      assert_int_equal(qk_world_add(w[t], &sh[gone], 0, &h[t][gone]), QK_OK);
      assert_int_equal(qk_world_update(w[t]), QK_OK);
    }
    for (int t = 1; t < W; t++)
      for (int which = 0; which < 3; which++) {
        size_t n0, n1;
        qk_world_pairs_list(w[0], (qk_pairs_which_t)which, NULL, 0, &n0);
        qk_world_pairs_list(w[t], (qk_pairs_which_t)which, NULL, 0, &n1);
        assert_int_equal(n0, n1);
        qk_world_pair_t *p0 = malloc((n0 + 1) * sizeof *p0), *p1 = malloc((n0 + 1) * sizeof *p1);
        qk_world_pairs_list(w[0], (qk_pairs_which_t)which, p0, n0, &n0);
        qk_world_pairs_list(w[t], (qk_pairs_which_t)which, p1, n1, &n1);
        assert_memory_equal(p0, p1, n0 * sizeof *p0);
        free(p0), free(p1);
      }
    /* the order and cells the threads filed answer queries (a misfiled cell breaks the
     * queries' binary searches, even where the bands search finds every pair) */
    for (int q = 0; q < 8; q++) {
      qk_shape_t qs = rnd_shape(&r, SC_MIXED, 1);
      qs.kind = QK_SHAPE_BOX;
      qs.a = qs.x + qkt_rng_range(&r, 0, 30), qs.b = qs.y + qkt_rng_range(&r, 0, 30);
      static qk_handle_t g0[N], g1[N];
      size_t n0, n1;
      assert_int_equal(qk_world_query(w[0], &qs, g0, N, &n0), QK_OK);
      for (int t = 1; t < W; t++) {
        assert_int_equal(qk_world_query(w[t], &qs, g1, N, &n1), QK_OK);
        assert_int_equal(n0, n1);
        assert_memory_equal(g0, g1, n0 * sizeof *g0);
      }
    }
  }
  for (int t = 0; t < W; t++) qk_world_free(w[t]), free(h[t]);
  free(sh);
}

/* The pairs, began and ended of two worlds are the same lists. */
static QKT_SERIAL void same_lists(qk_world_t *a, qk_world_t *b, int frame) {
  for (int which = 0; which < 3; which++) {
    size_t n0, n1;
    qk_world_pairs_list(a, (qk_pairs_which_t)which, NULL, 0, &n0);
    qk_world_pairs_list(b, (qk_pairs_which_t)which, NULL, 0, &n1);
    if (n0 != n1)
      fail_msg("frame %d list %d: %zu pairs against %zu (seed %llu)", frame, which, n0, n1,
               (unsigned long long)g_seed);
    qk_world_pair_t *p0 = malloc((n0 + 1) * sizeof *p0), *p1 = malloc((n0 + 1) * sizeof *p1);
    qk_world_pairs_list(a, (qk_pairs_which_t)which, p0, n0, &n0);
    qk_world_pairs_list(b, (qk_pairs_which_t)which, p1, n1, &n1);
    assert_memory_equal(p0, p1, n0 * sizeof *p0);
    free(p0), free(p1);
  }
}

/* The threads option's threshold (thread_min): a world whose live objects go from below
 * it to above and back, frame by frame (adds, removes and moves), gives on two threads
 * the same pairs, began and ended as on one, on both sides (below it the update stays on
 * the calling thread; above it the search, packing and rows run on the threads). */
static void test_world_thread_min_sides(void **s) {
  (void)s;
  enum { N = 5200, MIN = 4600 };
  qk_world_t *w[2];
  qk_handle_t h[2][N];
  static qk_shape_t sh[N];
  int live[N] = {0};
  qkt_rng_t r;
  qkt_rng_seed(&r, g_seed + 83);
  for (int i = 0; i < N; i++) sh[i] = rnd_shape(&r, SC_MIXED, 1);
  for (int t = 0; t < 2; t++) {
    qk_world_options_t o;
    qk_world_options_init(&o);
    o.threads = t ? 2 : 1;
    o.thread_min = MIN;
    assert_int_equal(qk_world_new(&o, &w[t]), QK_OK);
  }
  /* live counts per frame: below, across, above, back below */
  static const int want[] = {4300, 4500, 4700, 5100, 4650, 4550, 4200, 4800};
  int n_live = 0;
  for (int f = 0; f < (int)(sizeof want / sizeof *want); f++) {
    for (int i = 0; i < N; i++)
      if (live[i]) sh[i] = moved(&r, sh[i]);
    while (n_live != want[f]) {
      int i = (int)qkt_rng_below(&r, N);
      if (n_live < want[f] && !live[i]) {
        for (int t = 0; t < 2; t++)
          assert_int_equal(qk_world_add(w[t], &sh[i], 0, &h[t][i]), QK_OK);
        live[i] = 1, n_live++;
      } else if (n_live > want[f] && live[i]) {
        for (int t = 0; t < 2; t++) assert_int_equal(qk_world_remove(w[t], h[t][i]), QK_OK);
        live[i] = 0, n_live--;
      }
    }
    for (int t = 0; t < 2; t++) {
      for (int i = 0; i < N; i++)
        if (live[i]) assert_int_equal(qk_world_move(w[t], h[t][i], &sh[i]), QK_OK);
      assert_int_equal(qk_world_update(w[t]), QK_OK);
    }
    assert_int_equal(qk_world_size(w[1]), (size_t)n_live);
    same_lists(w[0], w[1], f);
    /* the order and cells the update filed (on threads above thread_min) answer queries */
    for (int q = 0; q < 4; q++) {
      qk_shape_t qs = rnd_shape(&r, SC_MIXED, 1);
      qs.kind = QK_SHAPE_BOX;
      qs.a = qs.x + qkt_rng_range(&r, 0, 30), qs.b = qs.y + qkt_rng_range(&r, 0, 30);
      static qk_handle_t g0[N], g1[N];
      size_t n0, n1;
      assert_int_equal(qk_world_query(w[0], &qs, g0, N, &n0), QK_OK);
      assert_int_equal(qk_world_query(w[1], &qs, g1, N, &n1), QK_OK);
      assert_int_equal(n0, n1);
      assert_memory_equal(g0, g1, n0 * sizeof *g0);
    }
  }
  for (int t = 0; t < 2; t++) qk_world_free(w[t]);
}

/* qk_world_move_batch: the moves before a failing one are done, it and the later ones
 * are not; err names the failing move. */
/* A box moved with each edge value in each coordinate (the common move's checks, two
 * lanes at a time: corners in order, magnitudes in [2^-100, 2^100]), by qk_world_move
 * and by qk_world_move_batch: the status and the stored shape are those the definitions
 * give (nonfinite, out of range, corners sorted), a failed move leaves the object as it
 * was, and after each move the pair with a fixed box and a query agree with comparisons. */
static int edge_ok(double v) {
  double a = fabs(v);
  return v == 0 || (a >= 0x1p-100 && a <= 0x1p100);
}
static void test_world_move_box_edges(void **s) {
  (void)s;
  QKT_ONE_THREAD_TEST();
  const double V[] = {1.5,
                      -2,
                      0,
                      -0.0,
                      0x1p100,
                      -0x1p100,
                      nextafter(0x1p100, INFINITY),
                      -nextafter(0x1p100, INFINITY),
                      0x1p-100,
                      -0x1p-100,
                      nextafter(0x1p-100, 0),
                      0x1p-101,
                      4e-320,
                      1e31,
                      -1e31,
                      7,
                      INFINITY,
                      -INFINITY,
                      NAN};
  const size_t nv = sizeof V / sizeof V[0];
  for (int batch = 0; batch < 2; batch++) {
    qk_world_t *w;
    assert_int_equal(qk_world_new(NULL, &w), QK_OK);
    qk_handle_t h, f;
    qk_shape_t cur = {QK_SHAPE_BOX, 1, 2, 3, 4}, fixed = {QK_SHAPE_BOX, 0.5, 0.5, 2.5, 2.5};
    assert_int_equal(qk_world_add(w, &cur, 1, &h), QK_OK);
    assert_int_equal(qk_world_add(w, &fixed, 2, &f), QK_OK);
    assert_int_equal(qk_world_update(w), QK_OK);
    for (size_t k = 0; k < 4 * nv; k++) {
      double c[4] = {1, 2, 3, 4};
      c[k % 4] = V[k / 4];
      qk_shape_t sh = {QK_SHAPE_BOX, c[0], c[1], c[2], c[3]};
      qk_status_t want = QK_OK;
      for (int i = 0; i < 4; i++)
        if (!isfinite(c[i])) want = QK_ERR_NONFINITE;
      for (int i = 0; i < 4 && want == QK_OK; i++)
        if (!edge_ok(c[i])) want = QK_ERR_LIMIT;
      qk_status_t got;
      if (batch) {
        qk_error_t err;
        got = qk_world_move_batch(w, &h, &sh, 1, &err);
      } else {
        got = qk_world_move(w, h, &sh);
      }
      assert_int_equal(got, want);
      if (want == QK_OK)
        cur = (qk_shape_t){QK_SHAPE_BOX, fmin(c[0], c[2]), fmin(c[1], c[3]), fmax(c[0], c[2]),
                           fmax(c[1], c[3])};
      qk_shape_t st;
      assert_int_equal(qk_world_get(w, h, &st, NULL), QK_OK);
      assert_true(st.kind == QK_SHAPE_BOX);
      assert_true(memcmp(&st.x, &cur.x, 4 * sizeof(double)) == 0); /* -0.0 kept as given */
      assert_int_equal(qk_world_update(w), QK_OK);
      size_t np;
      assert_int_equal(qk_world_pairs_list(w, QK_PAIRS_ALL, NULL, 0, &np), QK_OK);
      int meet = cur.x <= fixed.a && fixed.x <= cur.a && cur.y <= fixed.b && fixed.y <= cur.b;
      assert_int_equal(np, (size_t)meet);
      qk_handle_t out[2];
      assert_int_equal(qk_world_query(w, &cur, out, 2, &np), QK_OK);
      assert_int_equal(np, (size_t)(1 + meet));
    }
    qk_world_free(w);
  }
}

static void test_world_move_batch_errors(void **s) {
  (void)s;
  QKT_ONE_THREAD_TEST();
  qk_world_t *w;
  assert_int_equal(qk_world_new(NULL, &w), QK_OK);
  qk_handle_t h[4];
  for (int i = 0; i < 4; i++) {
    qk_shape_t sh = {QK_SHAPE_BOX, 10.0 * i, 0, 10.0 * i + 1, 1};
    assert_int_equal(qk_world_add(w, &sh, (uint64_t)i, &h[i]), QK_OK);
  }
  assert_int_equal(qk_world_update(w), QK_OK);
  qk_handle_t gone = h[2];
  assert_int_equal(qk_world_remove(w, gone), QK_OK);
  qk_handle_t bh[4] = {h[0], h[1], gone, h[3]};
  qk_shape_t bs[4];
  for (int i = 0; i < 4; i++) bs[i] = (qk_shape_t){QK_SHAPE_DISC, 100.0 + i, 5, 0.5, 0};
  qk_error_t err;
  assert_int_equal(qk_world_move_batch(w, bh, bs, 4, &err), QK_ERR_NOT_FOUND);
  assert_int_equal(err.item, 2);
  assert_non_null(strstr(err.message, "move 2"));
  qk_shape_t got;
  assert_int_equal(qk_world_get(w, h[0], &got, NULL), QK_OK);
  assert_true(got.kind == QK_SHAPE_DISC && got.x == 100);
  assert_int_equal(qk_world_get(w, h[1], &got, NULL), QK_OK);
  assert_true(got.kind == QK_SHAPE_DISC && got.x == 101);
  assert_int_equal(qk_world_get(w, h[3], &got, NULL), QK_OK);
  assert_true(got.kind == QK_SHAPE_BOX && got.x == 30); /* not moved */
  /* a bad shape: its status, the same partial rule; no err is fine */
  bh[2] = h[3];
  bs[0] = (qk_shape_t){QK_SHAPE_BOX, 0, 0, 1, 1};
  bs[1] = (qk_shape_t){QK_SHAPE_BOX, 0, 0, INFINITY, 1};
  assert_int_equal(qk_world_move_batch(w, bh, bs, 3, &err), QK_ERR_NONFINITE);
  assert_int_equal(err.item, 1);
  assert_int_equal(qk_world_move_batch(w, bh, bs, 3, NULL), QK_ERR_NONFINITE);
  assert_int_equal(qk_world_get(w, h[0], &got, NULL), QK_OK);
  assert_true(got.kind == QK_SHAPE_BOX && got.x == 0 && got.a == 1);
  assert_int_equal(qk_world_get(w, h[1], &got, NULL), QK_OK);
  assert_true(got.kind == QK_SHAPE_DISC && got.x == 101);
  /* unknown slots, nothing to do, bad arguments */
  qk_handle_t odd[1] = {(qk_handle_t)1 << 32 | 999};
  assert_int_equal(qk_world_move_batch(w, odd, bs, 1, NULL), QK_ERR_NOT_FOUND);
  odd[0] = QK_HANDLE_NONE;
  assert_int_equal(qk_world_move_batch(w, odd, bs, 1, NULL), QK_ERR_NOT_FOUND);
  assert_int_equal(qk_world_move_batch(w, NULL, NULL, 0, NULL), QK_OK);
  assert_int_equal(qk_world_move_batch(w, NULL, bs, 1, NULL), QK_ERR_INVALID);
  assert_int_equal(qk_world_move_batch(NULL, bh, bs, 1, NULL), QK_ERR_INVALID);
  /* the moved objects' pairs at the next update: 0 and 3 overlap now */
  bs[0] = (qk_shape_t){QK_SHAPE_BOX, 30.5, 0.5, 31.5, 1.5};
  assert_int_equal(qk_world_move_batch(w, h, bs, 1, NULL), QK_OK);
  assert_int_equal(qk_world_update(w), QK_OK);
  qk_world_pair_t p[2];
  size_t np;
  assert_int_equal(qk_world_pairs_list(w, QK_PAIRS_ALL, p, 2, &np), QK_OK);
  assert_int_equal(np, 1);
  assert_true(p[0].a == h[0] && p[0].b == h[3]);
  qk_world_free(w);
}

/* The float prefilter and the pair sort's long runs: boxes whose edges are doubles no
 * float can hold, touching exactly or missing by one ulp (the prefilter rounds monotonically,
 * the exact test decides), in cells of 1 to 9 objects (every lane pattern), plus one
 * large box in slot 0 meeting a hundred small ones (a run longer than insertion sort
 * takes), every frame against brute force. */
static void test_world_prefilter_and_sort(void **s) {
  (void)s;
  QKT_ONE_THREAD_TEST();
  qkt_rng_t r;
  qkt_rng_seed(&r, g_seed + 31);
  qk_world_t *w;
  assert_int_equal(qk_world_new(NULL, &w), QK_OK);
  mirror_t m = {0};
  m_add(w, &m,
        (qk_shape_t){
            QK_SHAPE_BOX,
            0,
            0,
            40,
            40,
        });
  const double eps = 0x1p-40;
  for (int g = 0; g < 60; g++) {
    double x = 1 + 3 * (g % 10) + eps * (g + 1), y = 1 + 5 * (g / 10) + eps;
    int k = 1 + g % 9;
    for (int i = 0; i < k; i++) {
      double w0 = 0.25 + 0.125 * i;
      qk_shape_t b = {QK_SHAPE_BOX, x, y, x + w0, y + w0};
      if (i % 3 == 1) b.x = b.a = x - w0; /* touching the first one's left edge exactly */
      if (i % 3 == 2) b.x = nextafter(x + 0.25, INFINITY), b.a = b.x + w0; /* one ulp off */
      if (i % 4 == 3) b = (qk_shape_t){QK_SHAPE_DISC, x + 0.25 + w0, y + 0.25, w0, 0};
      if (i == 0) b = (qk_shape_t){QK_SHAPE_BOX, x, y, x + 0.25, y + 0.25};
      m_add(w, &m, b);
    }
  }
  qk_world_pair_t *prev = NULL;
  size_t np = 0;
  for (int f = 0; f < 12; f++) {
    if (f) {
      for (size_t i = 1; i < m.n; i++) {
        if (qkt_rng_below(&r, 2)) continue;
        qk_shape_t sh = m.s[i];
        double d = (qkt_rng_below(&r, 2) ? 1 : -1) * eps * (double)qkt_rng_below(&r, 3);
        sh.x += d;
        if (sh.kind == QK_SHAPE_BOX) sh.a += d;
        m_move(w, &m, i, sh);
      }
    }
    update_and_check(w, &m, &prev, &np, "prefilter", f);
  }
  assert_true(np > 100);
  free(prev);
  free(m.h), free(m.s);
  qk_world_free(w);
}

/* The grid's runs with pairs the float boxes cannot decide among those they can
 * (collide/world_search.c, test_run: its loop hands the rest of a run to test_run_exact at
 * the first such lane): one level of dense cells (boxes of side 0.75 to 1, about 12 an
 * object's neighbourhood, so the search is on the grid and its runs span several groups of
 * four with several pairs each), most boxes on the float grid (multiples of 1/64) and
 * some off it by 2^-30 (their floats are not their doubles), a few of those touching or
 * missing an exact box by 2^-30 only (the float boxes meet, the doubles may not), and a
 * few discs; each frame every object moves by a multiple of 1/64 (the off-grid ones keep
 * their offset), every frame against brute force, on one thread and two. The off-grid
 * objects take several positions in a group (object i off when i mod 7 is 3 or 5), so that
 * the first undecided lane comes first, in the middle or last of a group with hits before
 * and after it. */
static void test_world_grid_undecided_runs(void **s) {
  (void)s;
  for (unsigned th = 1; th <= 2; th++) {
    qkt_rng_t r;
    qkt_rng_seed(&r, g_seed + 97);
    qk_world_t *w = threaded_world(th);
    mirror_t m = {0};
    const double off = 0x1p-30;
    for (int i = 0; i < 1200; i++) {
      double x = (double)qkt_rng_below(&r, 64 * 30) / 64,
             y = (double)qkt_rng_below(&r, 64 * 30) / 64;
      double e = (48 + (double)qkt_rng_below(&r, 17)) / 64;
      qk_shape_t b = {QK_SHAPE_BOX, x, y, x + e, y + e};
      if (i % 7 == 3 || i % 7 == 5) b.x += off, b.y += off, b.a += off, b.b += off;
      if (i % 31 == 7) b = (qk_shape_t){QK_SHAPE_DISC, x + e / 2, y + e / 2, e / 2, 0};
      m_add(w, &m, b);
    }
    /* Pairs that touch or miss by 2^-30: a box just right of an exact one. */
    for (int i = 0; i < 60; i++) {
      const qk_shape_t *a = &m.s[(size_t)i * 11];
      if (a->kind != QK_SHAPE_BOX) continue;
      double gap = i % 2 ? off : 0;
      m_add(w, &m, (qk_shape_t){QK_SHAPE_BOX, a->a + gap, a->y, a->a + gap + 0.75, a->y + 0.75});
    }
    qk_world_pair_t *prev = NULL;
    size_t np = 0;
    for (int f = 0; f < 8; f++) {
      for (size_t i = 0; f && i < m.n; i++) {
        if (qkt_rng_below(&r, 2)) continue;
        double dx = ((double)qkt_rng_below(&r, 9) - 4) / 64,
               dy = ((double)qkt_rng_below(&r, 9) - 4) / 64;
        qk_shape_t sh = m.s[i];
        sh.x += dx, sh.y += dy;
        if (sh.kind == QK_SHAPE_BOX) sh.a += dx, sh.b += dy;
        m_move(w, &m, i, sh);
      }
      update_and_check(w, &m, &prev, &np, "grid undecided runs", f);
      assert_false(qk__world_by_bands(w)); /* (the grid's search, not the bands') */
    }
    assert_true(np > 2000);
    free(prev), free(m.h), free(m.s);
    qk_world_free(w);
  }
}

/* The bench's clustered mixed-size scene, small: boxes in eight clusters with sizes over
 * three decades (0.03 .. 30, most small), on a grid of 1/64 so that edges touch exactly
 * and often, moving with constant velocities (bouncing off the scene's edges), a few
 * removed and added every third frame. Large boxes meet small objects several levels
 * finer, whose cells lie inside them (recorded without a test) or on their border
 * (tested); with kinds, a quarter of the objects are discs, segments and points (a large
 * disc or segment has no inside run: every finer object is tested). Every frame against
 * brute force. */
static double q64(double v) { return round(v * 64) / 64; }

static qk_shape_t cm_shape(qkt_rng_t *r, const double *cx, const double *cy, int kinds) {
  double w = q64(fmax(1.0 / 64, 0.03 * pow(1000.0, qkt_rng_unit(r) * qkt_rng_unit(r))));
  double h = q64(fmax(1.0 / 64, w * qkt_rng_range(r, 0.5, 1.5)));
  int c = (int)qkt_rng_below(r, 8);
  double spread = 2.5;
  double x = q64(cx[c] + (qkt_rng_unit(r) + qkt_rng_unit(r) + qkt_rng_unit(r) - 1.5) * spread);
  double y = q64(cy[c] + (qkt_rng_unit(r) + qkt_rng_unit(r) + qkt_rng_unit(r) - 1.5) * spread);
  qk_shape_t sh = {QK_SHAPE_BOX, x, y, x + w, y + h};
  switch (kinds ? qkt_rng_below(r, 8) : 7) {
  case 0:
    sh = (qk_shape_t){QK_SHAPE_DISC, x, y, w / 2, 0};
    break;
  case 1:
    sh = (qk_shape_t){QK_SHAPE_SEGMENT, x, y, x + w, y - h};
    break;
  case 2:
    sh = (qk_shape_t){QK_SHAPE_POINT, x, y, 0, 0};
    break;
  default:
    break;
  }
  return sh;
}

/* Eight cluster centres on the 1/64 grid in [5, 45]^2. */
static void cluster_centres(qkt_rng_t *r, double *cx, double *cy) {
  for (int c = 0; c < 8; c++)
    cx[c] = q64(qkt_rng_range(r, 5, 45)), cy[c] = q64(qkt_rng_range(r, 5, 45));
}

/* The shape moved by (dx, dy). */
static qk_shape_t shifted(qk_shape_t sh, double dx, double dy) {
  sh.x += dx, sh.y += dy;
  if (sh.kind == QK_SHAPE_BOX || sh.kind == QK_SHAPE_SEGMENT) sh.a += dx, sh.b += dy;
  return sh;
}

/* The shape's next step by (*vx, *vy), which turn back off the walls of [0, 50]^2. */
static qk_shape_t bounced(qk_shape_t sh, double *vx, double *vy) {
  if (sh.x + *vx < 0 || sh.x + *vx > 50) *vx = -*vx;
  if (sh.y + *vy < 0 || sh.y + *vy > 50) *vy = -*vy;
  return shifted(sh, *vx, *vy);
}

static void run_clustered_mixed(int kinds, size_t n, int frames) {
  qkt_rng_t r;
  qkt_rng_seed(&r, g_seed + 101 + (uint64_t)kinds);
  double cx[8], cy[8];
  cluster_centres(&r, cx, cy);
  qk_world_t *w;
  assert_int_equal(qk_world_new(NULL, &w), QK_OK);
  mirror_t m = {0};
  double *vx = NULL, *vy = NULL;
  size_t vcap = 0;
  qk_world_pair_t *prev = NULL;
  size_t np = 0;
  for (int f = 0; f < frames; f++) {
    if (f == 0 || f % 3 == 1) { /* the scene, then a few removed and added */
      for (int k = 0; f && k < 6 && m.n > 0; k++) {
        size_t i = m_remove_random(w, &m, &r);
        vx[i] = vx[m.n], vy[i] = vy[m.n];
      }
      for (size_t k = 0, add = f ? 5 : n; k < add; k++) {
        m_add(w, &m, cm_shape(&r, cx, cy, kinds));
        if (m.n > vcap) {
          vcap = m.cap;
          vx = realloc(vx, vcap * sizeof *vx), vy = realloc(vy, vcap * sizeof *vy);
        }
        double a = qkt_rng_range(&r, 0, 6.283185307179586);
        vx[m.n - 1] = q64(0.25 * cos(a)), vy[m.n - 1] = q64(0.25 * sin(a));
      }
    }
    for (size_t i = 0; f && i < m.n; i++) {
      qk_shape_t sh = bounced(m.s[i], &vx[i], &vy[i]);
      m_move(w, &m, i, sh);
    }
    update_and_check(w, &m, &prev, &np, "clustered mixed", f);
  }
  /* dense: large objects over many small ones (2.7 to 7.9 pairs an object at the end
   * with seeds 1 to 40; the check only that the scene is not sparse) */
  assert_true(np > n);
  free(prev), free(vx), free(vy);
  free(m.h), free(m.s);
  qk_world_free(w);
}

static void test_world_clustered_mixed_sizes(void **s) {
  (void)s;
  QKT_ONE_THREAD_TEST();
  run_clustered_mixed(0, 1200, 12);
  run_clustered_mixed(1, 1200, 12);
}

/*
 * Frames in which no object is added or removed and every box is on the float grid (the
 * bench's scene): the update then finds only the pairs that began (whose boxes did not
 * meet at the last update) and keeps the last frame's pairs whose boxes still meet
 * (collide/world_pairs.c, rows_began). The clustered boxes above, with frames where
 * nothing moves (every pair stays), where a tenth of the boxes jump anywhere (whole rows
 * begin and end), where one box leaves the float grid by 2^-30 (its float box is no longer
 * exact: every pair is found again, as is the frame after) and where one is removed and
 * one added; on one thread and, from 4096 objects, on two and three (rows_began by ranges
 * of slots). Every frame against brute force (dense_check).
 */
static void run_began_only_(unsigned threads, size_t n, int frames, int strip) {
  qkt_rng_t r;
  qkt_rng_seed(&r, g_seed + 131 + threads);
  double cx[8], cy[8];
  cluster_centres(&r, cx, cy);
  for (int c = 0; strip && c < 8; c++) cy[c] = 25;
  qk_world_t *w = threaded_world(threads);
  mirror_t m = {0};
  double *vx = malloc((n + 1) * sizeof *vx), *vy = malloc((n + 1) * sizeof *vy);
  for (size_t k = 0; k < n; k++) {
    m_add(w, &m, cm_shape(&r, cx, cy, 0));
    double a = qkt_rng_range(&r, 0, 6.283185307179586);
    vx[k] = q64(0.25 * cos(a)), vy[k] = q64(0.25 * sin(a));
  }
  qk_world_pair_t *prev = NULL;
  size_t np = 0;
  dense_check(w, &m, &prev, &np, 0);
  for (int f = 1; f < frames; f++) {
    int mode = f % 6; /* 0, 1: moves; 2: none; 3: jumps; 4: off the grid; 5: remove, add */
    if (mode == 5) {
      size_t i = m_remove_random(w, &m, &r);
      vx[i] = vx[m.n], vy[i] = vy[m.n];
      m_add(w, &m, cm_shape(&r, cx, cy, 0));
    }
    for (size_t i = 0; mode != 2 && i < m.n; i++) {
      qk_shape_t sh = m.s[i];
      if (mode == 3 && qkt_rng_below(&r, 10) == 0) {
        sh = cm_shape(&r, cx, cy, 0);
      } else {
        sh = bounced(sh, &vx[i], &vy[i]); /* (boxes) */
      }
      if (i == 0 && mode == 4) sh.x -= 0x1p-30; /* (still below sh.a) */
      if (i == 0 && mode == 5) sh.x = q64(sh.x);
      m_move(w, &m, i, sh);
    }
    dense_check(w, &m, &prev, &np, f);
  }
  assert_true(np > n); /* (dense: 2.9-31 pairs an object at seeds 1-40) */
  free(prev), free(vx), free(vy);
  free(m.h), free(m.s);
  qk_world_free(w);
}

static void run_began_only(unsigned threads, size_t n, int frames) {
  run_began_only_(threads, n, frames, 0);
}

/* The bands' entries scattered on the threads (collide/world_search.c, scatter_run: each
 * thread writes a range of entries, sharing its first and last bands with its
 * neighbours): the scene of run_began_only on 5 and 8 threads, and with every cluster on
 * one horizontal line (a strip a few bands high: several threads' ranges inside one
 * band). Every frame against brute force. */
/* Re-filing in place (collide/world_grid.c, merge_t's skip): frames with moves only keep
 * the old order's entries by a bit a dirty slot and take the dirty objects' cells from
 * their sort keys. Boxes on a 1/16 grid across 0 (cells of negative and positive indices),
 * sizes 1/16 .. 2 (six levels), moved by multiples of 1/16 so that many land exactly on
 * their loose squares' sides (kept: the far sides are open, the near ones closed) or just
 * past them; every fifth frame adds and removes some (the other path). Pairs, began and
 * ended and box queries against brute force every frame. */
static qk_shape_t grid_box(qkt_rng_t *r) {
  double x = (double)((int)qkt_rng_below(r, 257) - 128) / 16;
  double y = (double)((int)qkt_rng_below(r, 257) - 128) / 16;
  double w = ldexp(1, (int)qkt_rng_below(r, 6) - 4), h = ldexp(1, (int)qkt_rng_below(r, 6) - 4);
  return (qk_shape_t){QK_SHAPE_BOX, x, y, x + w, y + h};
}

static void test_world_refile_in_place(void **s) {
  (void)s;
  QKT_ONE_THREAD_TEST();
  qkt_rng_t r;
  qkt_rng_seed(&r, g_seed + 4242);
  qk_world_t *w;
  assert_int_equal(qk_world_new(NULL, &w), QK_OK);
  mirror_t m = {0};
  for (int i = 0; i < 400; i++) m_add(w, &m, grid_box(&r));
  qk_world_pair_t *prev = NULL;
  size_t np = 0;
  qk_handle_t *got = malloc(1024 * sizeof *got);
  for (int f = 0; f < 40; f++) {
    for (size_t i = 0; i < m.n; i++) {
      if (!qkt_rng_below(&r, 4)) continue;
      qk_shape_t b = m.s[i];
      double dx = (double)((int)qkt_rng_below(&r, 17) - 8) / 16;
      double dy = (double)((int)qkt_rng_below(&r, 17) - 8) / 16;
      if (fabs(b.x + dx) > 9 || fabs(b.y + dy) > 9) dx = -dx, dy = -dy;
      b.x += dx, b.a += dx, b.y += dy, b.b += dy;
      m_move(w, &m, i, b);
    }
    if (f % 5 == 4) {
      for (int k = 0; k < 3; k++) (void)m_remove_random(w, &m, &r);
      for (int k = 0; k < 3; k++) m_add(w, &m, grid_box(&r));
    }
    update_and_check(w, &m, &prev, &np, "refile", f);
    for (int q = 0; q < 4; q++) {
      qk_shape_t qb = grid_box(&r);
      qb.a += qkt_rng_range(&r, 0, 4), qb.b += qkt_rng_range(&r, 0, 4);
      size_t n = 0, want = 0;
      assert_int_equal(qk_world_query(w, &qb, got, 1024, &n), QK_OK);
      for (size_t i = 0; i < m.n; i++) {
        if (!o_overlap(qb, m.s[i])) continue;
        want++;
        int found = 0;
        for (size_t k = 0; k < n && k < 1024 && !found; k++) found = got[k] == m.h[i];
        if (!found)
          fail_msg("seed %llu frame %d: query misses object %zu", (unsigned long long)g_seed, f, i);
      }
      assert_int_equal(n, want);
    }
  }
  free(got);
  free(prev);
  free(m.h), free(m.s);
  qk_world_free(w);
}

static void test_world_bands_threads(void **s) {
  (void)s;
  for (unsigned th = 2; th <= 8; th += 3) {
    run_began_only_(th, 4200, 8, 1);
    if (th > 2) run_began_only_(th, 4200, 8, 0);
  }
}

/*
 * The bands' build on the threads (collide/world_search.c, bb_job: the first pass, the
 * bands' counts and the radix sort by xmin, each thread over its blocks of 1024 objects,
 * the sort's passes as stable counting sorts by thread). 5437 boxes (five whole blocks and
 * part of a sixth) of sizes 1/8 to 32 on 1 to 7 threads (6 and 7: one a block), their
 * xmin from 48 columns (ties across the blocks and the threads' ranges). First positive
 * multiples of 1/8 below 256, moving by 1/8 on x, so that the sort's lowest digit is the
 * same in every record (that pass skipped, the next taken from the first pass's counts);
 * then shifted across zero (float keys of both signs) and moving by 1/64 (every digit
 * sorted, the later passes counted again on the threads). Every frame against brute force
 * (dense_check).
 */
static void run_bands_build(unsigned threads) {
  enum { N = 5 * 1024 + 317, FRAMES = 6 };
  qkt_rng_t r;
  qkt_rng_seed(&r, g_seed + 211 + threads);
  qk_world_t *w = threaded_world(threads);
  mirror_t m = {0};
  for (size_t k = 0; k < N; k++) {
    double x = 4 + 4 * (double)qkt_rng_below(&r, 48), y = -80 + qkt_rng_below(&r, 1280) / 8.0;
    double e = qkt_rng_below(&r, 10) ? (1 + qkt_rng_below(&r, 8)) / 8.0 : 4 + qkt_rng_below(&r, 29);
    m_add(w, &m, (qk_shape_t){QK_SHAPE_BOX, x, y, x + e, y + e * (1 + qkt_rng_below(&r, 2))});
  }
  qk_world_pair_t *prev = NULL;
  size_t np = 0;
  dense_check(w, &m, &prev, &np, 0);
  assert_true(w->by_bands);
  for (int f = 1; f < FRAMES; f++) {
    const double step = f < 3 ? 1.0 / 8 : 1.0 / 64; /* (on the grid of 1/8, then off it) */
    for (size_t i = 0; i < m.n; i++)
      if (f == 3 || qkt_rng_below(&r, 2)) {
        qk_shape_t sh = m.s[i];
        double d = (f == 3 ? -100 : 0) + step * ((int)qkt_rng_below(&r, 3) - 1);
        sh.x += d, sh.a += d;
        m_move(w, &m, i, sh);
      }
    dense_check(w, &m, &prev, &np, f);
    assert_true(w->by_bands);
  }
  assert_true(np > N);
  free(prev), free(m.h), free(m.s);
  qk_world_free(w);
}

static void test_world_bands_build_threads(void **s) {
  (void)s;
  for (unsigned th = QKT_TSAN ? 2 : 1; th <= 7; th++) run_bands_build(th);
}

/*
 * The began pairs' rows sorted on the threads (collide/world_pairs.c, began_rows_threads:
 * the began keys cut by the ranges of slots that then merge them with the last frame's
 * rows, each range's keys sorted on its thread). Began-only frames (boxes on the float
 * grid, none added or removed) whose began pairs fall unevenly over the slots: with a
 * box over every cluster in slot 0 (its row holds a quarter of the old pairs, so on 8
 * threads ranges are empty); frames where only the lowest slots jump (the began pairs in
 * the first ranges), where only the highest of the clusters' slots jump, where nothing
 * moves but pairs of boxes in the last slots, far from the clusters, meet or part (began
 * rows past the last old row, and no other), and where nothing moves at all (no began
 * pair). On 1, 2, 3 and 8 threads, every frame against brute force (dense_check).
 */
/* A box of the clusters (cm_shape); with the giant, a sixteenth of its size (few pairs
 * among the clusters' boxes, so that the giant's row holds most). */
static qk_shape_t ranges_shape(qkt_rng_t *r, const double *cx, const double *cy, int giant) {
  qk_shape_t sh = cm_shape(r, cx, cy, 0);
  if (giant)
    sh.a = sh.x + fmax(1.0 / 64, q64((sh.a - sh.x) / 16)),
    sh.b = sh.y + fmax(1.0 / 64, q64((sh.b - sh.y) / 16));
  return sh;
}

static void run_began_ranges(unsigned threads, int giant) {
  enum { N = 4400, TAIL = 120, FRAMES = 13 };
  qkt_rng_t r;
  qkt_rng_seed(&r, g_seed + 191 + threads + 16 * (uint64_t)giant);
  double cx[8], cy[8];
  cluster_centres(&r, cx, cy);
  qk_world_t *w = threaded_world(threads);
  mirror_t m = {0};
  double vx[N], vy[N];
  for (size_t k = 0; k < N; k++) {
    qk_shape_t sh = ranges_shape(&r, cx, cy, giant);
    if (giant && k == 0) sh = (qk_shape_t){QK_SHAPE_BOX, -2, -2, 52, 52};
    if (k >= N - TAIL) { /* pairs of unit boxes at y = 100, apart (a gap of 0.5) */
      double x = 100 + 4 * (double)((k - (N - TAIL)) / 2) + 1.5 * (double)(k & 1);
      sh = (qk_shape_t){QK_SHAPE_BOX, x, 100, x + 1, 101};
    }
    m_add(w, &m, sh);
    double a = qkt_rng_range(&r, 0, 6.283185307179586);
    vx[k] = q64(0.25 * cos(a)), vy[k] = q64(0.25 * sin(a));
  }
  qk_world_pair_t *prev = NULL;
  size_t np = 0;
  dense_check(w, &m, &prev, &np, 0);
  for (int f = 1; f < FRAMES; f++) {
    int mode = f % 5; /* 0: all move; 1: the tail alone; 2: none; 3, 4: low, high slots jump */
    for (size_t i = giant ? 1 : 0; i < N - TAIL; i++) {
      if (mode == 0) m_move(w, &m, i, bounced(m.s[i], &vx[i], &vy[i]));
      if ((mode == 3 && i < N / 8) || (mode == 4 && i >= N - TAIL - N / 8))
        m_move(w, &m, i, ranges_shape(&r, cx, cy, giant));
    }
    /* the tail's odd boxes move against their even ones (from f = 1 on, in turns) or away */
    for (size_t i = N - TAIL + 1; (mode == 0 || mode == 1) && i < N; i += 2) {
      if ((i / 2 + (size_t)f) % 3 == 0) continue;
      qk_shape_t sh = m.s[i];
      double x = m.s[i - 1].x + (sh.x > m.s[i - 1].x + 1.25 ? 0.75 : 1.5);
      m_move(w, &m, i, (qk_shape_t){QK_SHAPE_BOX, x, 100, x + 1, 101});
    }
    dense_check(w, &m, &prev, &np, f);
  }
  assert_true(np > N);
  free(prev), free(m.h), free(m.s);
  qk_world_free(w);
}

static void test_world_began_ranges(void **s) {
  (void)s;
  static const unsigned th[] = {1, 2, 3, 8};
  for (int g = 0; g <= 1; g++)
    for (size_t k = QKT_TSAN ? 1 : 0; k < sizeof th / sizeof *th; k++) /* (TSan: threads) */
      run_began_ranges(th[k], g);
}

/*
 * The re-filing's merge on the threads, its ranges cut by work (collide/world_grid.c,
 * merge_cuts: the dirty objects counted by level on the threads, each weighing eight old
 * ones, spread over its level's run of the old order): small boxes over large ones, where
 * only the small ones jump (every dirty object in the finest level, the first of the
 * order: the cuts fall inside it), only the large ones (the last level: ranges without a
 * dirty object, one with them all), or all of them. Any cuts give the same order, so this
 * checks the counting pass and the merge on the ranges it gives, on 2, 3 and 8 threads,
 * every frame against brute force (dense_check).
 */
static void run_refile_split(unsigned threads, int which) {
  enum { N = 5800, BIG = 1600 }; /* (from 1024 dirty objects they are filed on the threads) */
  qkt_rng_t r;
  qkt_rng_seed(&r, g_seed + 211 + threads + 16 * (uint64_t)which);
  qk_world_t *w = threaded_world(threads);
  mirror_t m = {0};
  qk_world_pair_t *prev = NULL;
  size_t np = 0;
  /* (under TSan three frames of moves, not six: each is the same kind of re-filing) */
  for (int f = 0; f < (QKT_TSAN ? 4 : 7); f++) {
    for (size_t i = 0; i < N; i++) {
      int big = i >= N - BIG;
      if (f && !(which == 2 || (which == 1) == big)) continue;
      double e = big ? 4 : 0.25, x = q64(qkt_rng_range(&r, 0, 60)),
             y = q64(qkt_rng_range(&r, 0, 60));
      qk_shape_t sh = {QK_SHAPE_BOX, x, y, x + e, y + e};
      if (f)
        m_move(w, &m, i, sh);
      else
        m_add(w, &m, sh);
    }
    dense_check(w, &m, &prev, &np, f);
  }
  assert_true(np > N);
  free(prev), free(m.h), free(m.s);
  qk_world_free(w);
}

static void test_world_refile_split(void **s) {
  (void)s;
  static const unsigned th[] = {2, 3, 8};
  /* (under TSan 2 and 3 threads: eight on this test's two processors took a third of its
   * time there, for the same code) */
  for (int which = 0; which < 3; which++)
    for (size_t k = 0; k < sizeof th / sizeof *th - QKT_TSAN; k++) run_refile_split(th[k], which);
}

static void test_world_began_only(void **s) {
  (void)s;
  if (!QKT_TSAN) run_began_only(1, 1200, 13);
  for (unsigned th = QKT_TSAN ? 2 : 1; th <= 3; th++) run_began_only(th, 4200, 8);
}

/*
 * The began-only frame in general (rows_began with the near candidates: pairs whose float
 * boxes met at the last update but whose objects did not). The clustered scene of
 * run_began_only with, by variant: discs, segments and points among the boxes (kinds);
 * every coordinate off the float grid by a multiple of 0.1 and moves in steps of about
 * 0.1 (off); or both. Frames of moves, of none, of jumps, of tiny moves (a third of the
 * objects by +-2^-30, far below float precision here: their float boxes stay and the
 * objects of touching pairs part and meet again, which only the near candidates' exact
 * test sees), and of a remove and two adds (from 4095 objects this crosses the 4096 at
 * which the threads start). Every frame against brute force (dense_check).
 */
static qk_shape_t bg_shape(qkt_rng_t *r, const double *cx, const double *cy, int kinds, int off) {
  qk_shape_t sh = cm_shape(r, cx, cy, kinds);
  return off ? shifted(sh, 0.1 * qkt_rng_below(r, 10), 0.1 * qkt_rng_below(r, 10)) : sh;
}

static void run_began_general(unsigned threads, size_t n, int frames, int kinds, int off) {
  qkt_rng_t r;
  qkt_rng_seed(&r, g_seed + 151 + threads + 2 * (uint64_t)kinds + 4 * (uint64_t)off);
  double cx[8], cy[8];
  cluster_centres(&r, cx, cy);
  qk_world_t *w = threaded_world(threads);
  mirror_t m = {0};
  size_t vcap = n + 2 * (size_t)frames + 2;
  double *vx = malloc(vcap * sizeof *vx), *vy = malloc(vcap * sizeof *vy);
  for (size_t k = 0; k < vcap; k++) {
    double a = qkt_rng_range(&r, 0, 6.283185307179586);
    vx[k] = 0.25 * cos(a), vy[k] = 0.25 * sin(a);
    if (!off) vx[k] = q64(vx[k]), vy[k] = q64(vy[k]);
    if (off) vx[k] = 0.1 * round(vx[k] * 10), vy[k] = 0.1 * round(vy[k] * 10);
  }
  for (size_t k = 0; k < n; k++) m_add(w, &m, bg_shape(&r, cx, cy, kinds, off));
  qk_world_pair_t *prev = NULL;
  size_t np = 0;
  dense_check(w, &m, &prev, &np, 0);
  for (int f = 1; f < frames; f++) {
    int mode = f % 7; /* 0, 1: moves; 2: none; 3: jumps; 4, 5: tiny moves; 6: remove, adds */
    if (mode == 6) {
      size_t i = m_remove_random(w, &m, &r);
      vx[i] = vx[m.n], vy[i] = vy[m.n];
      m_add(w, &m, bg_shape(&r, cx, cy, kinds, off));
      m_add(w, &m, bg_shape(&r, cx, cy, kinds, off));
    }
    for (size_t i = 0; mode != 2 && i < m.n; i++) {
      qk_shape_t sh = m.s[i];
      if (mode == 3 && qkt_rng_below(&r, 10) == 0) {
        sh = bg_shape(&r, cx, cy, kinds, off);
      } else if (mode == 4 || mode == 5) {
        if (qkt_rng_below(&r, 3)) continue;
        double t = 0x1p-30;
        sh = shifted(sh, t * ((int)qkt_rng_below(&r, 3) - 1), t * ((int)qkt_rng_below(&r, 3) - 1));
      } else {
        sh = bounced(sh, &vx[i], &vy[i]);
      }
      m_move(w, &m, i, sh);
    }
    dense_check(w, &m, &prev, &np, f);
  }
  assert_true(np > n); /* (dense: 2.4-35 pairs an object at seeds 1-40) */
  free(prev), free(vx), free(vy);
  free(m.h), free(m.s);
  qk_world_free(w);
}

static void test_world_began_general(void **s) {
  (void)s;
  for (int v = 1; v <= 3 && !QKT_TSAN; v++) run_began_general(1, 1200, 16, v & 1, v >> 1);
  if (!QKT_TSAN) run_began_general(1, 1200, 16, 0, 0);
  for (unsigned th = QKT_TSAN ? 2 : 1; th <= 2; th++)
    for (int v = 1; v <= 3; v++) run_began_general(th, 4095, 13, v & 1, v >> 1);
}

/*
 * The search by bands (collide/world_search.c: sizes over several levels, here from 1/8
 * to 40), at its edges: on a lattice of 1/8 so that many xmin are equal and many boxes
 * touch; tall and wide boxes crossing many bands and one another in many of them (each
 * pair must come once: in the band of the higher ymin); and, in the second half of the
 * objects, corners moved by 2^-30 (below float precision there), so that the float boxes
 * touch where the exact ones may or may not and the exact test decides. Moves on the
 * lattice, removes and adds every third frame; every frame against brute force, on one
 * thread and on two.
 */
static qk_shape_t bands_shape(qkt_rng_t *r, int off) {
  double x = qkt_rng_below(r, 320) / 8.0, y = qkt_rng_below(r, 320) / 8.0, w, h;
  switch (qkt_rng_below(r, 10)) {
  case 0: /* tall */
    w = (1 + qkt_rng_below(r, 2)) / 8.0, h = 8 + qkt_rng_below(r, 25);
    break;
  case 1: /* wide */
    w = 8 + qkt_rng_below(r, 25), h = (1 + qkt_rng_below(r, 2)) / 8.0;
    break;
  case 2: /* large, or a point */
    w = h = qkt_rng_below(r, 4) ? 0 : 12 + qkt_rng_below(r, 8);
    break;
  default: /* small */
    w = (1 + qkt_rng_below(r, 3)) / 8.0, h = (1 + qkt_rng_below(r, 3)) / 8.0;
  }
  qk_shape_t s = {QK_SHAPE_BOX, x, y, x + w, y + h};
  if (off) { /* each corner moved by 2^-30 one way or the other, or not */
    double e = 0x1p-30;
    s.x += e * ((int)qkt_rng_below(r, 3) - 1), s.y += e * ((int)qkt_rng_below(r, 3) - 1);
    s.a += e * ((int)qkt_rng_below(r, 3) - 1), s.b += e * ((int)qkt_rng_below(r, 3) - 1);
    if (s.a < s.x) s.a = s.x;
    if (s.b < s.y) s.b = s.y;
  }
  return s;
}

static void test_world_bands_edges(void **s) {
  (void)s;
  for (unsigned th = 1; th <= 2; th++) {
    qkt_rng_t r;
    qkt_rng_seed(&r, g_seed + 71);
    qk_world_t *w = threaded_world(th);
    mirror_t m = {0};
    enum { N = 700 };
    for (int i = 0; i < N; i++) m_add(w, &m, bands_shape(&r, i >= N / 2));
    qk_world_pair_t *prev = NULL;
    size_t np = 0, most = 0;
    for (int f = 0; f < 12; f++) {
      for (size_t i = 0; f && i < m.n; i++) {
        if (qkt_rng_below(&r, 4) == 0) continue;
        double dx = ((int)qkt_rng_below(&r, 5) - 2) / 8.0,
               dy = ((int)qkt_rng_below(&r, 5) - 2) / 8.0;
        qk_shape_t sh = m.s[i];
        sh.x += dx, sh.a += dx, sh.y += dy, sh.b += dy;
        m_move(w, &m, i, sh);
      }
      if (f % 3 == 2) {
        for (int k = 0; k < 8; k++) {
          (void)m_remove_random(w, &m, &r);
        }
        for (int k = 0; k < 8; k++) m_add(w, &m, bands_shape(&r, k & 1));
      }
      update_and_check(w, &m, &prev, &np, "bands edges", f);
      most = np > most ? np : most;
    }
    /* tall and wide boxes over many small ones (2.8-5.5 pairs an object at seeds 1-40) */
    assert_true(most > 2 * N);
    free(prev), free(m.h), free(m.s);
    qk_world_free(w);
  }
}

/*
 * The bands' stop lanes (collide/world_search.c): each band starts a group of four and
 * ends with one to four lanes whose xmin is a NaN, which end every sweep that reaches
 * them, so a sweep tests no band end and masks only its first group (to the lanes after
 * its entry). Here the boxes lie in a narrow column (xmin in [0, 1/2], widths 1/64 to 1
 * over six levels: searched by bands), so the sweeps of the wide ones run to their band's
 * end, where the next band's entries meet them on x: a sweep that ran on (a band whose
 * entries fill its last group without a stop lane after it) or a first group left
 * unmasked (the entry itself and those before it) reports pairs twice, or an object with
 * itself. Bands of every count modulo four over the frames; moves, removes and adds;
 * every frame against brute force, on one thread and on two.
 */
static void test_world_bands_stop_lanes(void **s) {
  (void)s;
  for (unsigned th = 1; th <= 2; th++) {
    qkt_rng_t r;
    qkt_rng_seed(&r, g_seed + 173);
    qk_world_t *w = threaded_world(th);
    mirror_t m = {0};
    enum { N = 600 };
    for (int i = 0; i < N; i++) {
      double x = qkt_rng_below(&r, 33) / 64.0, y = qkt_rng_below(&r, 64 * 12) / 64.0;
      double wd = (double)(1u << qkt_rng_below(&r, 7)) / 64.0,
             h = (1 + qkt_rng_below(&r, 8)) / 64.0;
      m_add(w, &m, (qk_shape_t){QK_SHAPE_BOX, x, y, x + wd, y + h});
    }
    qk_world_pair_t *prev = NULL;
    size_t np = 0;
    for (int f = 0; f < 16; f++) {
      for (size_t i = 0; f && i < m.n; i++) {
        if (qkt_rng_below(&r, 3) == 0) continue;
        double dx = ((int)qkt_rng_below(&r, 3) - 1) / 64.0,
               dy = ((int)qkt_rng_below(&r, 9) - 4) / 64.0;
        m_move(w, &m, i, shifted(m.s[i], dx, dy));
      }
      if (f % 4 == 3) {
        for (int k = 0; k < 5; k++) (void)m_remove_random(w, &m, &r);
        for (int k = 0; k < 3 + f % 5; k++) {
          double x = qkt_rng_below(&r, 33) / 64.0, y = qkt_rng_below(&r, 64 * 12) / 64.0;
          m_add(w, &m, (qk_shape_t){QK_SHAPE_BOX, x, y, x + 1, y + 1.0 / 64});
        }
      }
      update_and_check(w, &m, &prev, &np, "bands stop lanes", f);
      assert_true(qk__world_by_bands(w));
    }
    assert_true(np > N);
    free(prev), free(m.h), free(m.s);
    qk_world_free(w);
  }
}

/*
 * The grid's search across levels (collide/world_search.c), which the update keeps for
 * scenes of mostly one size (few rows of finer levels for the coarse objects to walk;
 * otherwise it searches by bands): sizes 0.6 to 2 of all kinds with, in the first scene,
 * 0.5% of large boxes and discs (sides 10 to 30: levels up, walking the finer cells,
 * whole cells inside a box recorded without a test), and in the second, 3% of tiny
 * objects (levels down: the coarser cells looked up from theirs). Moves, removes and
 * adds; every frame against brute force, on one thread and on two.
 */
static qk_shape_t levels_shape(qkt_rng_t *r, int scene) {
  double x = qkt_rng_unit(r) * 60, y = qkt_rng_unit(r) * 60, s = qkt_rng_range(r, 0.6, 2);
  uint32_t u = qkt_rng_below(r, 1000);
  if (scene == 0 && u < 5) s = qkt_rng_range(r, 10, 30);
  if (scene == 1 && u < 30) s = qkt_rng_range(r, 0.04, 0.06);
  switch (qkt_rng_below(r, 4)) {
  case 0:
    return (qk_shape_t){QK_SHAPE_DISC, x, y, s / 2, 0};
  case 1:
    if (s < 10) return (qk_shape_t){QK_SHAPE_SEGMENT, x, y, x + s, y - s * 0.8};
    /* fall through */
  default:
    return (qk_shape_t){QK_SHAPE_BOX, x, y, x + s, y + s * qkt_rng_range(r, 0.7, 1)};
  }
}

static void test_world_grid_levels(void **s) {
  (void)s;
  for (int scene = 0; scene < 2; scene++)
    for (unsigned th = QKT_TSAN ? 2 : 1; th <= 2; th++) {
      qkt_rng_t r;
      qkt_rng_seed(&r, g_seed + 83 + (uint64_t)scene);
      qk_world_t *w = threaded_world(th);
      mirror_t m = {0};
      for (int i = 0; i < 1500; i++) m_add(w, &m, levels_shape(&r, scene));
      qk_world_pair_t *prev = NULL;
      size_t np = 0;
      for (int f = 0; f < 10; f++) {
        for (size_t i = 0; f && i < m.n; i++) {
          qk_shape_t sh = moved(&r, m.s[i]);
          m_move(w, &m, i, sh);
        }
        if (f % 3 == 2) {
          for (int k = 0; k < 6; k++) {
            (void)m_remove_random(w, &m, &r);
          }
          for (int k = 0; k < 6; k++) m_add(w, &m, levels_shape(&r, scene));
        }
        update_and_check(w, &m, &prev, &np, scene ? "grid levels (up)" : "grid levels (down)", f);
      }
      free(prev), free(m.h), free(m.s);
      qk_world_free(w);
    }
}

/* The one-thread merge's touched cells (collide/world_grid.c, merge_t's touch): a sparse
 * world on the grid (pairs of boxes of one level, most cells holding one or two objects),
 * each object drifting at its own velocity (steps of at most 0.6, so that no margin lifts
 * an object a level and the world stays on the grid), whose frames move every 16th to
 * 40th object (a few of the cells touched: the merge copies the runs of untouched cells
 * whole) or every object (once more than a sixteenth of the cells dirty: the cells are
 * not searched then, nor noted for the next frame), one frame removing and adding an
 * object (no search then either); every frame's pairs, began and ended against brute
 * force. */
static void test_world_few_movers(void **s) {
  (void)s;
  qkt_rng_t r;
  qkt_rng_seed(&r, g_seed + 89);
  qk_world_t *w = threaded_world(1);
  mirror_t m = {0};
  enum { GROUPS = 1200 };
  double v[2 * GROUPS][2];
  for (int g = 0; g < GROUPS; g++) {
    const double gx = qkt_rng_range(&r, 0, 3000), gy = qkt_rng_range(&r, 0, 3000);
    for (int k = 0; k < 2; k++) {
      const double x = gx + qkt_rng_range(&r, 0, 2), y = gy + qkt_rng_range(&r, 0, 2);
      v[m.n][0] = qkt_rng_range(&r, -0.3, 0.3), v[m.n][1] = qkt_rng_range(&r, -0.3, 0.3);
      m_add(w, &m,
            (qk_shape_t){QK_SHAPE_BOX, x, y, x + qkt_rng_range(&r, 0.55, 0.95),
                         y + qkt_rng_range(&r, 0.55, 0.95)});
    }
  }
  qk_world_pair_t *prev = NULL;
  size_t np = 0;
  static const int every[] = {16, 40, 16, 1, 16, 16, 25, 7, 16, 1, 25, 16, 16, 25};
  for (int f = 0; f <= 14; f++) {
    for (size_t i = 0; f && i < m.n; i += (size_t)every[f - 1]) {
      /* (two steps at a time: at most 0.6, so that no margin lifts an object a level) */
      qk_shape_t sh = m.s[i];
      const double dx = 2 * v[i][0], dy = 2 * v[i][1];
      sh.x += dx, sh.a += dx, sh.y += dy, sh.b += dy;
      m_move(w, &m, i, sh);
    }
    if (f == 6) {
      m.n--; /* (the last object: its velocity stays its slot's) */
      assert_int_equal(qk_world_remove(w, m.h[m.n]), QK_OK);
      m_add(w, &m, (qk_shape_t){QK_SHAPE_BOX, 10, 10, 10.7, 10.7});
    }
    update_and_check(w, &m, &prev, &np, "few movers", f);
  }
  free(prev), free(m.h), free(m.s);
  qk_world_free(w);
}

/* The re-filing's sort of the dirty objects by cell (collide/world_grid.c, drec_sort),
 * which packs each object's (level, cy, cx) relative to the frame's least ones with its
 * index into 64 bits when they fit: objects jumping every frame (all dirty, hundreds of
 * them) in groups of mixed sizes (1e-3 .. 10: five levels), over a span whose cells fit
 * (+-3000: about 23 bits a coordinate at the finest level, more than three of the sort's
 * 11-bit digits) and one whose cells do not (+-1e8: the level is raised by the
 * magnitude, and the cell indices still span about 2^31 each, so the records are sorted
 * on their bytes), every frame against brute force, on one thread and (the dirty ones
 * filed and sorted by the merge's ranges) two. */
static qk_shape_t refile_shape(qkt_rng_t *r, double gx, double gy) {
  double s = pow(10, qkt_rng_range(r, -3, 1)), x = gx + qkt_rng_range(r, 0, 12),
         y = gy + qkt_rng_range(r, 0, 12);
  return (qk_shape_t){QK_SHAPE_BOX, x, y, x + s, y + s * qkt_rng_range(r, 0.5, 1)};
}

static void test_world_refile_sort(void **s) {
  (void)s;
  for (int far = 0; far < 2; far++)
    for (unsigned th = 1; th <= 2; th++) {
      qkt_rng_t r;
      qkt_rng_seed(&r, g_seed + 97 + (uint64_t)far);
      const double span = far ? 1e8 : 3000;
      qk_world_t *w = threaded_world(th);
      mirror_t m = {0};
      enum { GROUPS = 24, PER = 25 };
      for (int g = 0; g < GROUPS; g++) {
        double gx = qkt_rng_range(&r, -span, span), gy = qkt_rng_range(&r, -span, span);
        for (int i = 0; i < PER; i++) m_add(w, &m, refile_shape(&r, gx, gy));
      }
      qk_world_pair_t *prev = NULL;
      size_t np = 0;
      for (int f = 0; f < 6; f++) {
        /* each group jumps somewhere else, its objects with new sizes */
        for (size_t g = 0; f && g < GROUPS; g++) {
          double gx = qkt_rng_range(&r, -span, span), gy = qkt_rng_range(&r, -span, span);
          for (size_t i = g * PER; i < (g + 1) * PER; i++) {
            qk_shape_t sh = refile_shape(&r, gx, gy);
            m_move(w, &m, i, sh);
          }
        }
        update_and_check(w, &m, &prev, &np, far ? "refile sort (far)" : "refile sort (near)", f);
        assert_true(np > 0);
      }
      free(prev), free(m.h), free(m.s);
      qk_world_free(w);
    }
}

/* The float boxes by slot (16 bytes a slot) are for the search by bands and the next
 * frame's began-only search: a frame searched on the grid (one level of sizes) allocates
 * none, a frame by bands (the clustered mixed sizes) one. An allocator counts the
 * allocations of exactly that size in the updates after the first, every frame checked
 * against brute force. */
typedef struct size_count {
  size_t size, n;
} size_count_t;

static void *counting_alloc(void *ud, void *p, size_t osize, size_t nsize) {
  (void)osize;
  size_count_t *c = ud;
  if (nsize == 0) {
    free(p);
    return NULL;
  }
  if (!p && nsize == c->size) c->n++;
  return realloc(p, nsize);
}

static void test_world_fbox_only_bands(void **s) {
  (void)s;
  QKT_ONE_THREAD_TEST();
  enum { N = 1001 };
  for (int bands = 0; bands < 2; bands++) {
    qkt_rng_t r;
    qkt_rng_seed(&r, g_seed + 151);
    size_count_t c = {16 * (size_t)N, 0};
    qk_allocator_t al = {counting_alloc, &c};
    qk_world_options_t o;
    qk_world_options_init(&o);
    o.allocator = &al;
    qk_world_t *w;
    assert_int_equal(qk_world_new(&o, &w), QK_OK);
    double cx[8], cy[8];
    cluster_centres(&r, cx, cy);
    mirror_t m = {0};
    for (int i = 0; i < N; i++) {
      double x = qkt_rng_unit(&r) * 30, y = qkt_rng_unit(&r) * 30;
      m_add(w, &m,
            bands ? cm_shape(&r, cx, cy, 0)
                  : (qk_shape_t){QK_SHAPE_BOX, x, y, x + 0.7, y + qkt_rng_range(&r, 0.6, 0.8)});
    }
    qk_world_pair_t *prev = NULL;
    size_t np = 0;
    update_and_check(w, &m, &prev, &np, "fbox", 0);
    c.n = 0;
    for (int f = 1; f < 5; f++) {
      for (size_t i = 0; i < m.n; i++) {
        qk_shape_t sh = shifted(m.s[i], 1.0 / 64, -1.0 / 64);
        m_move(w, &m, i, sh);
      }
      update_and_check(w, &m, &prev, &np, bands ? "fbox (bands)" : "fbox (grid)", f);
    }
    assert_true(np > N / 2);
    if (bands)
      assert_true(c.n >= 4);
    else
      assert_int_equal(c.n, 0);
    free(prev), free(m.h), free(m.s);
    qk_world_free(w);
  }
}

/* Moves that take an object just out of its cell's loose square (by 1/32 of the cell's
 * side, through each of its four sides) and nowhere else: the object must be re-filed,
 * since the cells searched for a box beyond that side do not include its old one (a
 * square's far sides are open). Discs, segments, points and boxes given with their
 * corners swapped take the general move (collide/world.c: move_general, in_loose), boxes
 * in order the inline one. The cell is read from the object (world_internal.h). The
 * part of the moved object's box beyond the side is queried before and after the update,
 * and the pairs with a box there are checked, all against the oracle. */
/* The box of a sorted shape whose values are on a fine dyadic grid (exact). */
static qk_box_t exact_box(qk_shape_t s) {
  double r = s.kind == QK_SHAPE_DISC ? s.a : 0;
  double x1 = s.kind == QK_SHAPE_BOX || s.kind == QK_SHAPE_SEGMENT ? s.a : s.x;
  double y1 = s.kind == QK_SHAPE_BOX || s.kind == QK_SHAPE_SEGMENT ? s.b : s.y;
  return (qk_box_t){fmin(s.x, x1) - r, fmin(s.y, y1) - r, fmax(s.x, x1) + r, fmax(s.y, y1) + r};
}
static void test_world_move_out_of_loose(void **s) {
  (void)s;
  QKT_ONE_THREAD_TEST();
  qkt_rng_t r;
  qkt_rng_seed(&r, g_seed + 401);
  for (int kind = 0; kind < 5; kind++)
    for (int side = 0; side < 4; side++)
      for (int trial = 0; trial < 6; trial++) {
        qk_world_t *w;
        assert_int_equal(qk_world_new(NULL, &w), QK_OK);
        mirror_t m = {0};
        double x = q64(qkt_rng_range(&r, 1, 60)), y = q64(qkt_rng_range(&r, 1, 60));
        double e = q64(qkt_rng_range(&r, 0.25, 4));
        qk_shape_t sh = {QK_SHAPE_POINT, x, y, 0, 0};
        if (kind == 0) sh = (qk_shape_t){QK_SHAPE_DISC, x, y, e / 2, 0};
        if (kind == 1 || kind == 2) sh = (qk_shape_t){QK_SHAPE_BOX, x, y, x + e, y + e / 2};
        if (kind == 3) sh = (qk_shape_t){QK_SHAPE_SEGMENT, x, y, x + e, y - e / 4};
        m_add(w, &m, sh);
        assert_int_equal(qk_world_update(w), QK_OK);
        const qk__wobj_t *o = &w->obj[(uint32_t)m.h[0]];
        double cs = ldexp(1, o->level), x0 = o->u.cx * cs, y0 = o->cy * cs, d = cs / 32;
        qk_box_t b = exact_box(m.s[0]);
        double dx = side == 0 ? x0 - d - b.xmin : side == 1 ? x0 + 2 * cs + d - b.xmax : 0;
        double dy = side == 2 ? y0 - d - b.ymin : side == 3 ? y0 + 2 * cs + d - b.ymax : 0;
        qk_shape_t mv = shifted(m.s[0], dx, dy);
        if (kind == 2) { /* corners swapped: the general move */
          double t = mv.x;
          mv.x = mv.a, mv.a = t;
        }
        m_move(w, &m, 0, mv);
        /* The part of the moved box beyond the side, the square's near sides excluded. */
        b = exact_box(m.s[0]);
        assert_true(side == 0   ? b.xmin == x0 - d
                    : side == 1 ? b.xmax == x0 + 2 * cs + d
                    : side == 2 ? b.ymin == y0 - d
                                : b.ymax == y0 + 2 * cs + d);
        qk_shape_t q = {QK_SHAPE_BOX, b.xmin, b.ymin, b.xmax, b.ymax};
        if (side == 0) q.a = x0 - d / 2;
        if (side == 1) q.x = x0 + 2 * cs;
        if (side == 2) q.b = y0 - d / 2;
        if (side == 3) q.y = y0 + 2 * cs;
        assert_true(q.x <= q.a && q.y <= q.b && o_overlap(q, m.s[0]));
        for (int pass = 0; pass < 2; pass++) {
          qk_handle_t got[2];
          size_t n;
          assert_int_equal(qk_world_query(w, &q, got, 2, &n), QK_OK);
          if (n != 1 || got[0] != m.h[0])
            fail_msg("kind %d side %d trial %d pass %d: %zu objects, not the moved one (seed "
                     "%llu)",
                     kind, side, trial, pass, n, (unsigned long long)g_seed);
          if (!pass) {
            m_add(w, &m, q);
            qk_world_pair_t *prev = NULL;
            size_t np = 0;
            update_and_check(w, &m, &prev, &np, "out of loose", side);
            assert_int_equal(np, 1);
            free(prev);
            assert_int_equal(qk_world_remove(w, m.h[1]), QK_OK);
            m.n = 1;
          }
        }
        free(m.h), free(m.s);
        qk_world_free(w);
      }
}

/* The world's batch of first hits (qk_world_raycast_batch) on one and two threads, for
 * counts around its chunks of 256 rays and past 64 chunks (where the chunks grow): every
 * ray's hit is that of qk_world_raycast (checked against the oracle in check_queries),
 * and no hit where no object meets the segment by brute force. The hits are filled with
 * a value no ray gives first, so that a ray the batch skips shows. */
static void test_world_raycast_batch(void **s) {
  (void)s;
  qkt_rng_t r;
  qkt_rng_seed(&r, g_seed + 409);
  enum { NOBJ = 300, NMAX = 64 * 256 + 300 };
  static const size_t counts[] = {0, 1, 2, 255, 256, 257, 511, 513, 64 * 256, 64 * 256 + 1, NMAX};
  qk_point_t *from = malloc(NMAX * sizeof *from), *to = malloc(NMAX * sizeof *to);
  qk_world_hit_t *got = malloc(NMAX * sizeof *got), *one = malloc(NMAX * sizeof *one);
  for (unsigned threads = 1; threads <= 2; threads++) {
    if (QKT_TSAN && threads == 1) continue;
    qk_world_t *w = threaded_world(threads);
    mirror_t m = {0};
    for (size_t i = 0; i < NOBJ; i++) m_add(w, &m, rnd_shape(&r, SC_UNIFORM, 1));
    assert_int_equal(qk_world_update(w), QK_OK);
    for (size_t i = 0; i < NMAX; i++) {
      from[i] = (qk_point_t){qkt_rng_range(&r, -10, 110), qkt_rng_range(&r, -10, 110)};
      to[i] =
          (qk_point_t){from[i].x + qkt_rng_range(&r, -8, 8), from[i].y + qkt_rng_range(&r, -8, 8)};
      assert_int_equal(qk_world_raycast(w, from[i], to[i], &one[i]), QK_OK);
    }
    for (size_t c = 0; c < sizeof counts / sizeof *counts; c++) {
      size_t n = counts[c];
      for (size_t i = 0; i < NMAX; i++) got[i] = (qk_world_hit_t){m.h[0], -1};
      assert_int_equal(qk_world_raycast_batch(w, from, to, n, got), QK_OK);
      size_t none = 0;
      for (size_t i = 0; i < n; i++) {
        if (got[i].h != one[i].h || !(got[i].t == one[i].t))
          fail_msg("threads %u, %zu rays: ray %zu hit %llx at %g, alone %llx at %g (seed %llu)",
                   threads, n, i, (unsigned long long)got[i].h, got[i].t,
                   (unsigned long long)one[i].h, one[i].t, (unsigned long long)g_seed);
        if (got[i].h != QK_HANDLE_NONE) continue;
        none++;
        qk_shape_t seg = {QK_SHAPE_SEGMENT, from[i].x, from[i].y, to[i].x, to[i].y};
        for (size_t j = 0; j < m.n; j++) assert_false(o_overlap(seg, m.s[j]));
      }
      for (size_t i = n; i < NMAX; i++) assert_true(got[i].h == m.h[0] && got[i].t == -1);
      if (n > 1000) assert_true(none > 0 && none < n); /* (both kinds of answer occur) */
    }
    free(m.h), free(m.s);
    qk_world_free(w);
  }
  free(from), free(to), free(got), free(one);
}

/* A random shape of the scene that is a box or a point. */
static qk_shape_t rnd_box_or_point(qkt_rng_t *r, int scene) {
  qk_shape_t sh;
  do sh = rnd_shape(r, scene, 1);
  while (sh.kind != QK_SHAPE_BOX && sh.kind != QK_SHAPE_POINT);
  return sh;
}

/* The first hit from a to b is the first of all the hits (qk_world_raycast_all, which
 * tests every candidate), and the hits are as many as brute force finds; all has room for
 * cap hits. `what` starts the failure message. */
static QKT_SERIAL void check_first_hit(qk_world_t *w, const mirror_t *m, qk_point_t a, qk_point_t b,
                                       qk_world_hit_t *all, size_t cap, const char *what) {
  qk_world_hit_t first;
  size_t n;
  assert_int_equal(qk_world_raycast(w, a, b, &first), QK_OK);
  assert_int_equal(qk_world_raycast_all(w, a, b, all, cap, &n), QK_OK);
  if (n ? first.h != all[0].h || !(first.t == all[0].t) : first.h != QK_HANDLE_NONE)
    fail_msg("%sfirst %llx at %.17g, of all %zu %llx at %.17g (seed %llu)", what,
             (unsigned long long)first.h, first.t, n, (unsigned long long)(n ? all[0].h : 0),
             n ? all[0].t : 0.0, (unsigned long long)g_seed);
  const qk_shape_t seg = {QK_SHAPE_SEGMENT, a.x, a.y, b.x, b.y};
  size_t want = 0;
  for (size_t j = 0; j < m->n; j++) want += o_overlap(seg, m->s[j]);
  if (n != want)
    fail_msg("%s%zu hits, brute force %zu (seed %llu)", what, n, want, (unsigned long long)g_seed);
}

/* A shape of the query-tree scenes: 0, 1 groups of four objects scattered over
 * [-4e5, 4e5]^2; 2 six clusters of sizes over three decades in [0, 1000]^2; 3 groups
 * scattered over 1e5 around (1e9, -1e9). Kinds: boxes and points (even scenes) or all. */
static qk_shape_t tree_shape(qkt_rng_t *r, int scene, double *g) {
  double x, y, s;
  if (scene == 2) {
    const int c = (int)qkt_rng_below(r, 6);
    x = 100 + 150 * c + qkt_rng_range(r, -30, 30) * qkt_rng_unit(r);
    y = 500 + 300 * (c % 2) + qkt_rng_range(r, -30, 30) * qkt_rng_unit(r);
    s = pow(10, qkt_rng_range(r, -2, 1));
  } else {
    if (qkt_rng_below(r, 4) == 0) {
      const double span = scene == 3 ? 5e4 : 4e5;
      g[0] = qkt_rng_range(r, -span, span), g[1] = qkt_rng_range(r, -span, span);
    }
    x = g[0] + qkt_rng_range(r, 0, 3), y = g[1] + qkt_rng_range(r, 0, 3);
    if (scene == 3) x += 1e9, y -= 1e9;
    s = qkt_rng_range(r, 0.5, 2);
  }
  qk_shape_t sh = {QK_SHAPE_BOX, x, y, x + s * qkt_rng_unit(r), y + s * qkt_rng_unit(r)};
  const int k = (int)qkt_rng_below(r, 4);
  if (k == 1) sh = (qk_shape_t){QK_SHAPE_POINT, x, y, 0, 0};
  if (scene % 2 && k == 2) sh = (qk_shape_t){QK_SHAPE_DISC, x, y, s / 2, 0};
  if (scene % 2 && k == 3) sh.kind = QK_SHAPE_SEGMENT;
  return sh;
}

/* The query tree (collide/world_query.c: each level's cells in Morton order, made by the
 * first query after an update, its memory kept for the next unless the cells shrink to
 * under half) in worlds where it matters: sparse ones with long
 * rays and points far from every object, and clustered ones over three decades of sizes, with
 * negative cell coordinates and far from the origin; boxes and points only (first hits
 * pruned by the tree) or all kinds. Every first hit is the first of all hits, the hits and
 * the box queries are brute force's, the k nearest are the nearest by brute force; after
 * an update (the tree made: the world's bytes grow), with objects moved, added and removed
 * since, and after most are removed. */
static void test_world_query_tree(void **s) {
  (void)s;
  QKT_ONE_THREAD_TEST();
  qkt_rng_t r;
  qkt_rng_seed(&r, g_seed + 977);
  enum { NOBJ = 2000, NRAY = 250 };
  qk_world_hit_t *all = malloc((NOBJ + 64) * sizeof *all);
  qk_handle_t *got = malloc((NOBJ + 64) * sizeof *got);
  for (int scene = 0; scene < 4; scene++) {
    qk_world_t *w = threaded_world(1);
    mirror_t m = {0};
    double g[2] = {0, 0};
    const double c0 = scene == 3 ? 1e9 : 0, span = scene == 2 ? 600 : scene == 3 ? 5e4 : 4e5;
    const double cx = scene == 2 ? 500 : c0, cy = scene == 2 ? 600 : -c0;
    for (int phase = 0; phase < 5; phase++) {
      if (phase == 0) {
        for (size_t i = 0; i < NOBJ; i++) m_add(w, &m, tree_shape(&r, scene, g));
      } else if (phase == 4) { /* most removed: the tree made again, smaller */
        while (m.n > 150) m_remove_random(w, &m, &r);
      } else if (phase == 2) {
        for (int j = 0; j < 60; j++) {
          const size_t i = qkt_rng_below(&r, (uint32_t)m.n);
          if (j % 6 == 0)
            m_remove_random(w, &m, &r);
          else if (j % 6 == 1)
            m_add(w, &m, tree_shape(&r, scene, g));
          else
            m_move(w, &m, i, moved(&r, m.s[i]));
        }
      }
      if (phase != 2) assert_int_equal(qk_world_update(w), QK_OK);
      const size_t before = qk_world_bytes(w);
      for (int q = 0; q < NRAY; q++) {
        /* from anywhere, or from an object; a quarter of the scene long or short */
        qk_point_t a = {cx + qkt_rng_range(&r, -span, span), cy + qkt_rng_range(&r, -span, span)};
        if (q % 3 == 0) a = (qk_point_t){m.s[q % m.n].x, m.s[q % m.n].y};
        const double len = q % 2 ? span / 2 : qkt_rng_range(&r, 1, 50);
        const double ang = qkt_rng_range(&r, 0, 6.283185307179586);
        qk_point_t b = {a.x + len * cos(ang), a.y + len * sin(ang)};
        if (q % 7 == 0) b.y = a.y;
        char what[64];
        snprintf(what, sizeof what, "tree scene %d phase %d ray %d: ", scene, phase, q);
        check_first_hit(w, &m, a, b, all, NOBJ + 64, what);
        if (q == 0 && phase == 0) assert_true(qk_world_bytes(w) > before); /* (made) */
        /* a box about the ray's start, of a side up to a fifth of the scene */
        const double h = q % 2 ? qkt_rng_range(&r, 0, span / 5) : qkt_rng_range(&r, 0, 5);
        const qk_shape_t box = {QK_SHAPE_BOX, a.x - h, a.y - h, a.x + h, a.y + h};
        size_t n, want = 0;
        assert_int_equal(qk_world_query(w, &box, got, NOBJ + 64, &n), QK_OK);
        for (size_t j = 0; j < m.n; j++) want += o_overlap(box, m.s[j]);
        if (n != want)
          fail_msg("tree scene %d phase %d box %d: %zu, brute force %zu (seed %llu)", scene, phase,
                   q, n, want, (unsigned long long)g_seed);
      }
      char what[48];
      snprintf(what, sizeof what, "tree scene %d phase %d: ", scene, phase);
      for (int q = 0; q < 60; q++) {
        const qk_point_t p = {cx + qkt_rng_range(&r, -span, span),
                              cy + qkt_rng_range(&r, -span, span)};
        check_knn(w, &m, p, q % 3 == 0 ? 1 : q % 3 == 1 ? 4 : 16, what);
      }
    }
    free(m.h), free(m.s);
    qk_world_free(w);
  }
  free(all), free(got);
}

/* A box of the crowded scenes: in [0, 6]^2, of sides 0.5-2 by up to as much (dozens to a
 * cell of side 4). */
static qk_shape_t crowded_box(qkt_rng_t *r) {
  const double x = qkt_rng_range(r, 0, 6), y = qkt_rng_range(r, 0, 6);
  const double sz = qkt_rng_range(r, 0.5, 2);
  return (qk_shape_t){QK_SHAPE_BOX, x, y, x + sz, y + sz * qkt_rng_unit(r)};
}

/* The objects overlapping qs are exactly brute force's, in slot order. */
static QKT_SERIAL void check_overlaps(qk_world_t *w, const mirror_t *m, qk_shape_t qs,
                                      qk_handle_t *got, const char *what) {
  size_t n, want = 0;
  assert_int_equal(qk_world_query(w, &qs, got, m->n + 1, &n), QK_OK);
  for (size_t j = 0; j < m->n; j++) want += o_overlap(qs, m->s[j]);
  if (n != want)
    fail_msg("%skind %d: %zu objects, brute force %zu (seed %llu)", what, (int)qs.kind, n, want,
             (unsigned long long)g_seed);
  for (size_t i = 0; i < n; i++) {
    size_t j = 0;
    while (j < m->n && m->h[j] != got[i]) j++;
    if (j == m->n || !o_overlap(qs, m->s[j]))
      fail_msg("%skind %d: %llx is not brute force's (seed %llu)", what, (int)qs.kind,
               (unsigned long long)got[i], (unsigned long long)g_seed);
    if (i) assert_true((uint32_t)got[i - 1] < (uint32_t)got[i]);
  }
}

/* Crowded cells (collide/world_query.c: their objects in groups of four with float boxes,
 * made with the query tree): 1,500 objects in a square of side 6, most of sizes 0.5-2
 * (dozens to a cell), a fifth 0.01-1, boxes and points or every kind, near the origin and far from
 * it. Box, disc, point and segment queries, first and all hits, and the k nearest against brute
 * force right after updates (the groups made: the world's bytes grow by more than a slot a crowded
 * object) and after moves that keep most objects in their cells (each group's box left behind: the
 * cell is read object by object until the next update; or, after many moves, every cell), adds,
 * removes, and moves out of the cluster. */
static void test_world_crowded_cells(void **s) {
  (void)s;
  QKT_ONE_THREAD_TEST();
  qkt_rng_t r;
  qkt_rng_seed(&r, g_seed + 991);
  enum { NOBJ = 1500, NQ = 60 };
  qk_world_hit_t *all = malloc((NOBJ + 256) * sizeof *all);
  qk_handle_t *got = malloc((NOBJ + 256) * sizeof *got);
  for (int scene = 0; scene < 4; scene++) {
    qk_world_t *w = threaded_world(1);
    mirror_t m = {0};
    const double ox = scene >= 2 ? 3e8 : -7.25, oy = scene >= 2 ? -5e8 : 3.5, side = 6;
    const int kinds = scene % 2; /* every kind, or boxes and points */
    for (int phase = 0; phase < 6; phase++) {
      if (phase == 0) {
        for (size_t i = 0; i < NOBJ; i++) {
          const double x = ox + qkt_rng_unit(&r) * side, y = oy + qkt_rng_unit(&r) * side;
          const double sz =
              pow(10, i % 5 ? qkt_rng_range(&r, -0.3, 0.3) : qkt_rng_range(&r, -2, 0));
          const int k = (int)qkt_rng_below(&r, kinds ? 4 : 2);
          qk_shape_t sh = {QK_SHAPE_BOX, x, y, x + sz * qkt_rng_unit(&r),
                           y + sz * qkt_rng_unit(&r)};
          if (k == 1) sh = (qk_shape_t){QK_SHAPE_POINT, x, y, 0, 0};
          if (k == 2) sh = (qk_shape_t){QK_SHAPE_DISC, x, y, sz / 2, 0};
          if (k == 3) sh.kind = QK_SHAPE_SEGMENT;
          m_add(w, &m, sh);
        }
        assert_int_equal(qk_world_update(w), QK_OK);
      } else if (phase % 2) { /* moves before the queries, no update: a third of the objects,
                                 from left to right (past the first few hundred every group is
                                 dropped, before the right-hand cells are marked stale), or 60
                                 at random (their cells marked stale) */
        /* (the objects in order of their x, by insertion) */
        size_t *byx = malloc(m.n * sizeof *byx);
        for (size_t i = 0; i < m.n; i++) {
          size_t k = i;
          for (; k > 0 && m.s[byx[k - 1]].x > m.s[i].x; k--) byx[k] = byx[k - 1];
          byx[k] = i;
        }
        const size_t nmove = phase == 1 ? m.n / 3 : 60;
        for (size_t j = 0; j < nmove; j++) {
          const size_t i = phase == 1 ? byx[3 * j] : qkt_rng_below(&r, (uint32_t)m.n);
          qk_shape_t sh = m.s[i];
          const double dx = qkt_rng_range(&r, -0.3, 0.3), dy = qkt_rng_range(&r, -0.3, 0.3);
          sh.x += dx, sh.y += dy;
          if (sh.kind == QK_SHAPE_BOX || sh.kind == QK_SHAPE_SEGMENT) sh.a += dx, sh.b += dy;
          if (j % 50 == 0) sh.x += 100, sh.a += sh.kind == QK_SHAPE_BOX ? 100 : 0; /* away */
          m_move(w, &m, i, sh);
        }
        free(byx);
        if (phase == 3)
          for (int j = 0; j < 40; j++) m_remove_random(w, &m, &r);
      } else {
        if (phase == 4) /* objects added into the cluster, then filed */
          for (int j = 0; j < 40; j++) {
            const double x = ox + qkt_rng_unit(&r) * side, y = oy + qkt_rng_unit(&r) * side;
            m_add(w, &m, (qk_shape_t){QK_SHAPE_BOX, x, y, x + 1, y + 0.5});
          }
        assert_int_equal(qk_world_update(w), QK_OK);
      }
      const size_t before = qk_world_bytes(w);
      for (int q = 0; q < NQ; q++) {
        char what[64];
        snprintf(what, sizeof what, "crowded scene %d phase %d query %d: ", scene, phase, q);
        const double x = ox - 1 + qkt_rng_unit(&r) * (side + 2);
        const double y = oy - 1 + qkt_rng_unit(&r) * (side + 2);
        const double h = q % 4 == 0 ? qkt_rng_range(&r, 0, 4) : qkt_rng_range(&r, 0, 0.5);
        check_overlaps(w, &m, (qk_shape_t){QK_SHAPE_BOX, x - h, y - h, x + h, y + h}, got, what);
        if (q == 0 && phase == 0) /* (the groups made: more than 4 bytes a crowded object) */
          assert_true(qk_world_bytes(w) > before + 4 * NOBJ);
        check_overlaps(w, &m, (qk_shape_t){QK_SHAPE_DISC, x, y, h, 0}, got, what);
        check_overlaps(w, &m, (qk_shape_t){QK_SHAPE_POINT, x, y, 0, 0}, got, what);
        const double ang = qkt_rng_range(&r, 0, 6.283185307179586), len = 4 * h + 0.1;
        const qk_point_t a = {x, y}, b = {x + len * cos(ang), y + len * sin(ang)};
        check_overlaps(w, &m, (qk_shape_t){QK_SHAPE_SEGMENT, a.x, a.y, b.x, b.y}, got, what);
        check_first_hit(w, &m, a, b, all, NOBJ + 256, what);
        if (q % 5 == 0) check_knn(w, &m, a, q % 3 == 0 ? 1 : q % 3 == 1 ? 5 : 16, what);
      }
    }
    free(m.h), free(m.s);
    qk_world_free(w);
  }
  free(all), free(got);
}

/* Levels whose cells span 2^30 columns and rows and more (unit boxes within 2.1e9 of the
 * origin, the corners among them): their trees' keys take 62 bits, and their bitmaps'
 * squares 2^25 cells a side (collide/world_query.c, tree_visit_along). First hits of long
 * rays between the objects, and all hits, against brute force. */
static void test_world_query_wide_span(void **s) {
  (void)s;
  QKT_ONE_THREAD_TEST();
  qkt_rng_t r;
  qkt_rng_seed(&r, g_seed + 997);
  enum { NOBJ = 200 };
  qk_world_hit_t *all = malloc((NOBJ + 8) * sizeof *all);
  qk_world_t *w = threaded_world(1);
  mirror_t m = {0};
  const double e = 2.1e9;
  for (size_t i = 0; i < NOBJ; i++) {
    /* the four corners and the edges, and some anywhere */
    double x = i % 4 < 2 ? -e : e - 1, y = i % 2 ? -e : e - 1;
    if (i >= 16) x = qkt_rng_range(&r, -e, e - 1), y = i % 3 ? y : qkt_rng_range(&r, -e, e - 1);
    m_add(w, &m, (qk_shape_t){QK_SHAPE_BOX, x, y, x + 1, y + 1});
  }
  assert_int_equal(qk_world_update(w), QK_OK);
  for (int q = 0; q < 400; q++) {
    const qk_shape_t *a = &m.s[qkt_rng_below(&r, (uint32_t)m.n)];
    const qk_shape_t *b = &m.s[q < 16 ? (uint32_t)(q + 5) % 16 : qkt_rng_below(&r, (uint32_t)m.n)];
    const qk_point_t p0 = {a->x + qkt_rng_unit(&r), a->y + qkt_rng_unit(&r)};
    const qk_point_t p1 = {b->x + qkt_rng_unit(&r), b->y + qkt_rng_unit(&r)};
    char what[48];
    snprintf(what, sizeof what, "wide span ray %d: ", q);
    check_first_hit(w, &m, q % 2 ? p0 : p1, q % 2 ? p1 : p0, all, NOBJ + 8, what);
  }
  free(m.h), free(m.s), free(all);
  qk_world_free(w);
}

/* Rays and segment queries far from every object, as points or short segments out at
 * 2^100 and beyond: their pieces' rounding margin (2^-40 of the ends' magnitudes, 2^61
 * there) once spanned 2^55 rows of the level, which the row walk stepped through one by one
 * (the fuzzer's world target hung in qk_world_raycast: fuzz/regressions/world/
 * ray-far-point-rows). Each call returns, with brute force's answer; near and at the
 * objects too, with a tree of several levels and with and without the query tree. */
static void test_world_query_far_out(void **s) {
  (void)s;
  QKT_ONE_THREAD_TEST();
  enum { NOBJ = 300 };
  qk_world_hit_t *all = malloc((NOBJ + 8) * sizeof *all);
  qk_handle_t *got = malloc((NOBJ + 8) * sizeof *got);
  qkt_rng_t r;
  qkt_rng_seed(&r, g_seed + 1013);
  qk_world_t *w = threaded_world(1);
  mirror_t m = {0};
  m_add(w, &m, (qk_shape_t){QK_SHAPE_BOX, -20, -20, 10, 10}); /* (level 6: the fuzzer's world) */
  assert_int_equal(qk_world_update(w), QK_OK);
  for (int pass = 0; pass < 2; pass++) {
    if (pass) { /* then many objects on several levels, and the query tree */
      for (size_t i = 1; i < NOBJ; i++) {
        double x = qkt_rng_range(&r, -100, 100), y = qkt_rng_range(&r, -100, 100);
        double e = ldexp(1, (int)qkt_rng_below(&r, 10) - 4);
        m_add(w, &m, (qk_shape_t){QK_SHAPE_BOX, x, y, x + e, y + e});
      }
      assert_int_equal(qk_world_update(w), QK_OK);
    }
    /* (the shapes' range ends at 2^100: a ray beyond it is refused) */
    qk_world_hit_t h;
    assert_int_equal(qk_world_raycast(w, (qk_point_t){0x1p101, 0}, (qk_point_t){0x1p101, 0}, &h),
                     QK_ERR_LIMIT);
    static const double far[] = {0x1p100, 0x1p99, 0x1p60, 1e30, 1e20};
    for (size_t f = 0; f < sizeof far / sizeof *far; f++)
      for (int q = 0; q < 8; q++) {
        const double x = q & 1 ? -far[f] : far[f], y = q & 2 ? -16 : q & 4 ? 5 : -far[f];
        /* (toward the origin: the ends stay within the range) */
        const double len = q & 4 ? 0 : ldexp(1, (int)qkt_rng_below(&r, 40) - 10);
        const qk_point_t p0 = {x, y}, p1 = {x - copysign(len, x), y - copysign(len / 2, y)};
        char what[64];
        snprintf(what, sizeof what, "far ray %g %d (pass %d): ", far[f], q, pass);
        check_first_hit(w, &m, p0, p1, all, NOBJ + 8, what);
        const qk_shape_t sg = {QK_SHAPE_SEGMENT, p0.x, p0.y, p1.x, p1.y};
        size_t n = 0;
        assert_int_equal(qk_world_query(w, &sg, got, NOBJ + 8, &n), QK_OK);
        assert_int_equal(n, 0);
      }
    /* and from far out to the objects (no piece walk: too many pieces) */
    for (int q = 0; q < 8; q++) {
      const qk_point_t p0 = {q & 1 ? -0x1p100 : 0x1p100, -16}, p1 = {0, q & 2 ? -16 : 0.5};
      check_first_hit(w, &m, p0, p1, all, NOBJ + 8, "far ray to the objects: ");
    }
  }
  free(m.h), free(m.s), free(all), free(got);
  qk_world_free(w);
}

/* Queries when the query tree's or a crowded cell's memory cannot be had: the k-th
 * allocation after an update fails (the tree's scratch, a large cell's sorting room), for
 * k = 1 .. 12, and box queries, first hits and the k nearest in a crowded world are still
 * brute force's (the queries go without the tree or the cell's groups, and a later query
 * makes them); nothing leaks. */
static void test_world_query_nomem(void **s) {
  (void)s;
  QKT_ONE_THREAD_TEST();
  qkt_rng_t r;
  qkt_rng_seed(&r, g_seed + 1009);
  enum { NOBJ = 1500 };
  qkt_alloc_t st;
  qk_allocator_t al = qkt_alloc_make(&st);
  qk_world_options_t o;
  qk_world_options_init(&o);
  o.allocator = &al;
  qk_world_t *w;
  assert_int_equal(qk_world_new(&o, &w), QK_OK);
  mirror_t m = {0};
  for (size_t i = 0; i < NOBJ; i++) { /* (cells of hundreds: sorted in allocated room) */
    const qk_shape_t b = crowded_box(&r);
    m_add(w, &m, i % 3 ? b : (qk_shape_t){QK_SHAPE_POINT, b.x, b.y, 0, 0});
  }
  qk_world_hit_t *all = malloc((NOBJ + 8) * sizeof *all);
  qk_handle_t *got = malloc((NOBJ + 8) * sizeof *got);
  size_t failed = 0;
  for (size_t k = 1; k <= 12; k++) {
    assert_int_equal(qk_world_update(w), QK_OK); /* (the tree made anew by the next query) */
    qkt_alloc_arm(&st, k);
    for (int q = 0; q < 8; q++) {
      char what[48];
      snprintf(what, sizeof what, "nomem %zu query %d: ", k, q);
      const double x = qkt_rng_range(&r, -1, 7), y = qkt_rng_range(&r, -1, 7), h = 0.5 + q % 3;
      check_overlaps(w, &m, (qk_shape_t){QK_SHAPE_BOX, x - h, y - h, x + h, y + h}, got, what);
      check_first_hit(w, &m, (qk_point_t){x, y}, (qk_point_t){x + 5, y - 3 + q}, all, NOBJ + 8,
                      what);
      check_knn(w, &m, (qk_point_t){x, y}, 1 + (size_t)q, what);
    }
    failed += st.failed;
    qkt_alloc_arm(&st, 0);
  }
  assert_true(failed >= 6); /* (the failures came where the queries allocate) */
  free(m.h), free(m.s), free(all), free(got);
  qk_world_free(w);
  assert_int_equal(st.live_blocks, 0);
  assert_int_equal(st.live_bytes, 0);
}

/* The query tree made by concurrent readers: right after each update, batches of first
 * hits and of nearest objects on two threads (whose queries race to make the tree and to
 * fill a crowded cell's groups: one makes it, the others search without meanwhile), then
 * the same queries one by one; the answers are the same (and TSan sees no race under make
 * tsan). */
static void test_world_query_tree_threads(void **s) {
  (void)s;
  qkt_rng_t r;
  qkt_rng_seed(&r, g_seed + 983);
  enum { NOBJ = 2000, NQ = 3000, K = 3 };
  qk_point_t *from = malloc(NQ * sizeof *from), *to = malloc(NQ * sizeof *to);
  qk_world_hit_t *hits = malloc(NQ * sizeof *hits), *nn = malloc(NQ * K * sizeof *nn);
  size_t *counts = malloc(NQ * sizeof *counts);
  /* scenes 0 and 1 sparse (tree_shape), 2 crowded: every query reads cells of dozens of
   * objects, whose groups the two threads race to fill */
  for (int scene = 0; scene < 3; scene++) {
    qk_world_t *w = threaded_world(2);
    mirror_t m = {0};
    double g[2] = {0, 0};
    const double span = scene == 2 ? 4 : 4e5;
    for (size_t i = 0; i < NOBJ; i++) {
      m_add(w, &m, scene == 2 ? crowded_box(&r) : tree_shape(&r, scene, g));
    }
    for (int round = 0; round < 4; round++) {
      for (int j = 0; j < 200; j++) {
        const size_t i = qkt_rng_below(&r, (uint32_t)m.n);
        m_move(w, &m, i, moved(&r, m.s[i]));
      }
      assert_int_equal(qk_world_update(w), QK_OK);
      for (size_t i = 0; i < NQ; i++) {
        const double c = scene == 2 ? 3 : 0;
        from[i] =
            (qk_point_t){c + qkt_rng_range(&r, -span, span), c + qkt_rng_range(&r, -span, span)};
        to[i] = (qk_point_t){from[i].x + qkt_rng_range(&r, -span / 2, span / 2),
                             from[i].y + qkt_rng_range(&r, -span / 2, span / 2)};
      }
      if (round % 2) {
        assert_int_equal(qk_world_knn_batch(w, from, NQ, K, nn, counts), QK_OK);
        assert_int_equal(qk_world_raycast_batch(w, from, to, NQ, hits), QK_OK);
      } else {
        assert_int_equal(qk_world_raycast_batch(w, from, to, NQ, hits), QK_OK);
        assert_int_equal(qk_world_knn_batch(w, from, NQ, K, nn, counts), QK_OK);
      }
      for (size_t i = 0; i < NQ; i++) {
        qk_world_hit_t one, k1[K];
        size_t n1;
        assert_int_equal(qk_world_raycast(w, from[i], to[i], &one), QK_OK);
        assert_true(one.h == hits[i].h && one.t == hits[i].t);
        assert_int_equal(qk_world_knn(w, from[i], K, k1, &n1), QK_OK);
        assert_int_equal(n1, counts[i]);
        for (size_t k = 0; k < n1; k++)
          assert_true(k1[k].h == nn[i * K + k].h && k1[k].t == nn[i * K + k].t);
      }
    }
    free(m.h), free(m.s);
    qk_world_free(w);
  }
  free(from), free(to), free(hits), free(nn), free(counts);
}

/* Queries in worlds of boxes and points only, where the first hit stops once no object
 * left can come first and both queries skip objects by their boxes (collide/world_query.c):
 * every first hit is the first of all the hits (qk_world_raycast_all, which tests every
 * candidate), no hit where brute force finds none, and the k nearest are the nearest by
 * brute force; in each scene, with objects moved, added and removed since the update (not
 * filed yet) and after it, for rays short and long, axis-parallel and of length zero. */
static void test_world_boxes_points_queries(void **s) {
  (void)s;
  QKT_ONE_THREAD_TEST();
  qkt_rng_t r;
  qkt_rng_seed(&r, g_seed + 433);
  enum { NOBJ = 400, NSMALL = 3000, NRAY = 300 };
  qk_world_hit_t *all = malloc((NSMALL + 64) * sizeof *all);
  /* the four scenes, then SC_HUGE + 1: 3000 small boxes and points (sides 0.05 to 0.3),
   * where rays cross many cells before their first hit and the pieces stop early */
  for (int scene = SC_UNIFORM; scene <= SC_HUGE + 1; scene++) {
    qk_world_t *w = threaded_world(1);
    mirror_t m = {0};
    for (int phase = 0; phase < 6; phase++) {
      if (phase == 0 && scene > SC_HUGE)
        for (size_t i = 0; i < NSMALL; i++) {
          double x = qkt_rng_unit(&r) * 100, y = qkt_rng_unit(&r) * 100;
          double sw = qkt_rng_range(&r, 0.05, 0.3), sh = qkt_rng_range(&r, 0.05, 0.3);
          m_add(w, &m,
                qkt_rng_below(&r, 4) ? (qk_shape_t){QK_SHAPE_BOX, x, y, x + sw, y + sh}
                                     : (qk_shape_t){QK_SHAPE_POINT, x, y, 0, 0});
        }
      else if (phase == 0)
        for (size_t i = 0; i < NOBJ; i++) m_add(w, &m, rnd_box_or_point(&r, scene));
      else if (phase % 2) /* moves, adds and removes, then queries before the update */
        for (int j = 0; j < 60; j++) {
          size_t i = qkt_rng_below(&r, (uint32_t)m.n);
          if (j % 6 == 0) {
            m_remove_random(w, &m, &r);
          } else if (j % 6 == 1) {
            m_add(w, &m, rnd_box_or_point(&r, scene));
          } else {
            m_move(w, &m, i, moved(&r, m.s[i]));
          }
        }
      else
        assert_int_equal(qk_world_update(w), QK_OK);
      const double off = scene == SC_HUGE ? 1e9 : 0;
      for (int q = 0; q < NRAY; q++) {
        qk_point_t a = {off + qkt_rng_range(&r, -10, 110), -off + qkt_rng_range(&r, -10, 110)};
        double len = q % 5 == 0   ? 150
                     : q % 5 == 1 ? qkt_rng_range(&r, 0.01, 3)
                                  : qkt_rng_range(&r, 3, 40);
        double ang = qkt_rng_range(&r, 0, 6.283185307179586);
        qk_point_t b = {a.x + len * cos(ang), a.y + len * sin(ang)};
        if (q % 7 == 0) b.y = a.y;  /* horizontal */
        if (q % 11 == 0) b.x = a.x; /* vertical */
        if (q % 13 == 0) b = a;     /* a point */
        if (q % 17 == 0 && m.n) {   /* from a corner or a point of an object */
          const qk_shape_t *o = &m.s[qkt_rng_below(&r, (uint32_t)m.n)];
          a = (qk_point_t){o->x, o->y};
        }
        char what[64];
        snprintf(what, sizeof what, "scene %d phase %d ray %d: ", scene, phase, q);
        check_first_hit(w, &m, a, b, all, NSMALL + 64, what);
      }
      char what[48];
      snprintf(what, sizeof what, "scene %d phase %d: ", scene, phase);
      for (int q = 0; q < 60; q++) {
        qk_point_t p = {off + qkt_rng_range(&r, -10, 110), -off + qkt_rng_range(&r, -10, 110)};
        check_knn(w, &m, p, q % 3 == 0 ? 1 : q % 3 == 1 ? 3 : 9, what);
      }
    }
    free(m.h), free(m.s);
    qk_world_free(w);
  }
  free(all);
}

/* Touching cases on integers (every formula is exact there). */
static void test_world_touching(void **s) {
  (void)s;
  QKT_ONE_THREAD_TEST();
  qk_shape_t sh[] = {
      {QK_SHAPE_DISC, 0, 0, 5, 0},
      {QK_SHAPE_DISC, 8, 6, 5, 0}, /* centres 10 apart */
      {QK_SHAPE_BOX, 5, -3, 9, 0},
      {QK_SHAPE_POINT, 9, 0, 0, 0}, /* box corner */
      {QK_SHAPE_SEGMENT, 9, 0, 20, 11},
      {QK_SHAPE_SEGMENT, 20, 11, 30, 0}, /* shared end */
      {QK_SHAPE_SEGMENT, -5, -8, 5, -8},
      {QK_SHAPE_DISC, 0, -13, 5, 0}, /* tangent line */
      {QK_SHAPE_POINT, 14, 5, 0, 0},
      {QK_SHAPE_SEGMENT, 3, 4, 3, 4}, /* point on seg; degenerate seg on disc */
  };
  size_t n = sizeof sh / sizeof *sh;
  qk_world_t *w;
  assert_int_equal(qk_world_new(NULL, &w), QK_OK);
  mirror_t m = {0};
  for (size_t i = 0; i < n; i++) m_add(w, &m, sh[i]);
  assert_int_equal(qk_world_update(w), QK_OK);
  qk_world_pair_t *want;
  size_t nw = o_pairs(&m, &want);
  check_pairs(w, want, nw, NULL, 0, "touching", 0);
  assert_true(nw >= 8);
  /* just apart: a disc of radius 5 at distance 10 + 2^-40 from another */
  qk_shape_t apart = {QK_SHAPE_DISC, 8 + 0x1p-40, 6, 5, 0};
  assert_int_equal(qk_world_move(w, m.h[1], &apart), QK_OK);
  qk_shape_t q = {QK_SHAPE_DISC, 0, 0, 5, 0};
  qk_handle_t got[16];
  size_t ng;
  assert_int_equal(qk_world_query(w, &q, got, 16, &ng), QK_OK);
  for (size_t i = 0; i < ng; i++) assert_true(got[i] != m.h[1]);
  free(want), free(m.h), free(m.s);
  qk_world_free(w);
}

/* Near misses by one unit in the last place at small coordinates, where the orientation
 * is decided by the exact expansions (its filter cannot) and the exact value is a tiny
 * positive number: a point, the end of a segment and the corner of a box one ulp off the
 * segment from (0, 0) to (1, 1) (scaled by 2^-k), on its left, and the same reflected in
 * the line x = y (on its right). None meets the segment; the oracle's long double products
 * are exact here. Pairs and queries of every object against the oracle. */
static qk_shape_t swap_xy(qk_shape_t s) {
  double t = s.x;
  s.x = s.y, s.y = t;
  t = s.a, s.a = s.b, s.b = t;
  return s;
}
static void test_world_one_ulp_off(void **s) {
  (void)s;
  QKT_ONE_THREAD_TEST();
  for (int k = 0; k < 4; k++)
    for (int mirror = 0; mirror < 2; mirror++) {
      double c = ldexp(1, -k), m = c / 2, u = nextafter(m, 1) - m;
      qk_shape_t sh[] = {
          {QK_SHAPE_SEGMENT, 0, 0, c, c},
          {QK_SHAPE_POINT, m, m + u, 0, 0},
          {QK_SHAPE_SEGMENT, m, m + u, m - c / 4, m + c / 4},
          {QK_SHAPE_BOX, m - c / 4, m + u, m, m + c / 4},
      };
      size_t n = sizeof sh / sizeof *sh;
      qk_world_t *w;
      assert_int_equal(qk_world_new(NULL, &w), QK_OK);
      mirror_t mi = {0};
      for (size_t i = 0; i < n; i++) m_add(w, &mi, mirror ? swap_xy(sh[i]) : sh[i]);
      for (size_t i = 1; i < n; i++) assert_false(o_overlap(mi.s[0], mi.s[i]));
      qk_world_pair_t *prev = NULL;
      size_t np = 0;
      update_and_check(w, &mi, &prev, &np, "one ulp off", k);
      for (size_t i = 0; i < n; i++) {
        qk_handle_t got[8];
        size_t ng, want = 0;
        assert_int_equal(qk_world_query(w, &mi.s[i], got, 8, &ng), QK_OK);
        for (size_t j = 0; j < n; j++) want += o_overlap(mi.s[i], mi.s[j]);
        if (ng != want)
          fail_msg("scale 2^-%d mirror %d object %zu: %zu objects met, oracle %zu", k, mirror, i,
                   ng, want);
      }
      free(prev), free(mi.h), free(mi.s);
      qk_world_free(w);
    }
}

/* Queries on the integer grid 0..6 against one object of each kind near its middle (a
 * box, a segment, a disc of radius 2, a point): every box and every segment between grid
 * points, every grid point, and discs of radius 1 and 2 at every grid point, so that
 * every side and corner is touched exactly (the oracle is exact on integers). The
 * world's queries reach the exact test only for candidates whose boxes meet the query's,
 * so touching is where that test alone decides. The nearest object to each grid point
 * too: at distance 0 exactly on the boundary (four grid points lie on the disc's circle). */
static void grid_query(qk_world_t *w, const qk_shape_t *obj, qk_shape_t q, size_t *met) {
  qk_handle_t got[2];
  size_t n, want = (size_t)o_overlap(q, *obj);
  assert_int_equal(qk_world_query(w, &q, got, 2, &n), QK_OK);
  if (n != want)
    fail_msg("object kind %d, query kind %d (%g %g %g %g): %zu met, oracle %zu", obj->kind, q.kind,
             q.x, q.y, q.a, q.b, n, want);
  *met += want;
}
/* The nearest object to p (the only one) is at the oracle's distance: 0 exactly where p
 * is on the shape (its boundary included), else within rounding. */
static void grid_knn(qk_world_t *w, const qk_shape_t *obj, qk_point_t p) {
  qk_world_hit_t hit;
  size_t n;
  assert_int_equal(qk_world_knn(w, p, 1, &hit, &n), QK_OK);
  assert_int_equal(n, 1);
  ld d = sqrtl(o_d2(obj, p.x, p.y));
  if ((d == 0) != (hit.t == 0) || fabsl(hit.t - d) > 1e-12L)
    fail_msg("object kind %d, point (%g %g): distance %a, oracle %La", obj->kind, p.x, p.y, hit.t,
             d);
}
static void test_world_query_grid_touching(void **s) {
  (void)s;
  QKT_ONE_THREAD_TEST();
  const qk_shape_t obj[] = {{QK_SHAPE_BOX, 2, 2, 4, 3},
                            {QK_SHAPE_SEGMENT, 2, 4, 4, 2},
                            {QK_SHAPE_DISC, 3, 3, 2, 0},
                            {QK_SHAPE_POINT, 3, 2, 0, 0}};
  for (size_t o = 0; o < sizeof obj / sizeof *obj; o++) {
    qk_world_t *w;
    assert_int_equal(qk_world_new(NULL, &w), QK_OK);
    qk_handle_t h;
    assert_int_equal(qk_world_add(w, &obj[o], 0, &h), QK_OK);
    assert_int_equal(qk_world_update(w), QK_OK);
    size_t met = 0;
    for (int x0 = 0; x0 <= 6; x0++)
      for (int y0 = 0; y0 <= 6; y0++) {
        grid_query(w, &obj[o], (qk_shape_t){QK_SHAPE_POINT, x0, y0, 0, 0}, &met);
        grid_knn(w, &obj[o], (qk_point_t){x0, y0});
        for (int r = 1; r <= 2; r++)
          grid_query(w, &obj[o], (qk_shape_t){QK_SHAPE_DISC, x0, y0, r, 0}, &met);
        for (int x1 = 0; x1 <= 6; x1++)
          for (int y1 = 0; y1 <= 6; y1++) {
            grid_query(w, &obj[o], (qk_shape_t){QK_SHAPE_SEGMENT, x0, y0, x1, y1}, &met);
            if (x0 <= x1 && y0 <= y1)
              grid_query(w, &obj[o], (qk_shape_t){QK_SHAPE_BOX, x0, y0, x1, y1}, &met);
          }
      }
    assert_true(met > 100);
    qk_world_free(w);
  }
}

/* qk_world_bytes is the bytes the world holds from its allocator (between updates):
 * exactly the live bytes of a counting allocator, after every update and every batch of
 * moves, adds and removes of a random scene of all kinds (the empty world first, and with
 * pairs and without). */
static void test_world_bytes_exact(void **s) {
  (void)s;
  QKT_ONE_THREAD_TEST();
  qkt_rng_t r;
  qkt_rng_seed(&r, g_seed + 419);
  qkt_alloc_t st;
  qk_allocator_t a = qkt_alloc_make(&st);
  qk_world_options_t o;
  qk_world_options_init(&o);
  o.allocator = &a;
  qk_world_t *w;
  assert_int_equal(qk_world_new(&o, &w), QK_OK);
  assert_int_equal(qk_world_bytes(w), st.live_bytes);
  assert_int_equal(qk_world_update(w), QK_OK);
  assert_int_equal(qk_world_bytes(w), st.live_bytes);
  mirror_t m = {0};
  for (int f = 0; f < 30; f++) {
    size_t add = f < 10 ? 40 : 5;
    for (size_t i = 0; i < add; i++) m_add(w, &m, rnd_shape(&r, SC_UNIFORM, 1));
    for (size_t i = 0; i < m.n; i++)
      if (qkt_rng_below(&r, 2)) m_move(w, &m, i, moved(&r, m.s[i]));
    for (int k = 0; k < 3 && m.n; k++) (void)m_remove_random(w, &m, &r);
    if (qk_world_bytes(w) != st.live_bytes)
      fail_msg("frame %d before the update: %zu bytes counted, %zu held", f, qk_world_bytes(w),
               st.live_bytes);
    assert_int_equal(qk_world_update(w), QK_OK);
    if (qk_world_bytes(w) != st.live_bytes)
      fail_msg("frame %d: %zu bytes counted, %zu held", f, qk_world_bytes(w), st.live_bytes);
  }
  qk_world_free(w);
  assert_int_equal(st.live_bytes, 0);
  free(m.h), free(m.s);
}

/* Frames in which most pairs end, or begin, at once while few stay, with no object added
 * or removed: 2000 pairs of touching boxes, of which all but the 60 of the lowest slots
 * part and then meet again, over and over. The merge of this frame's pairs with the last
 * frame's then has one list far longer than the other (few keys left in one when many are
 * left in the other, where its blocks of unchecked steps must stop at the shorter list's
 * end). Began and ended every frame against brute force. */
static void test_world_most_pairs_change(void **s) {
  (void)s;
  QKT_ONE_THREAD_TEST();
  enum { NP = 2000, KEEP = 60 };
  qk_world_t *w;
  assert_int_equal(qk_world_new(NULL, &w), QK_OK);
  mirror_t m = {0};
  for (int k = 0; k < NP; k++) {
    double x = (k % 50) * 4, y = (k / 50) * 4;
    m_add(w, &m, (qk_shape_t){QK_SHAPE_BOX, x, y, x + 1, y + 1});
    m_add(w, &m, (qk_shape_t){QK_SHAPE_BOX, x + 1, y, x + 2, y + 1}); /* touching */
  }
  qk_world_pair_t *prev = NULL;
  size_t np = 0;
  update_and_check(w, &m, &prev, &np, "most change", 0);
  assert_int_equal(np, NP);
  for (int f = 1; f <= 6; f++) {
    double dx = f & 1 ? 0.5 : -0.5; /* apart, then back */
    for (size_t i = 2 * KEEP + 1; i < m.n; i += 2) m_move(w, &m, i, shifted(m.s[i], dx, 0));
    update_and_check(w, &m, &prev, &np, "most change", f);
    assert_int_equal(np, f & 1 ? KEEP : NP);
  }
  free(prev), free(m.h), free(m.s);
  qk_world_free(w);
}

/* The dirty objects' radix sort (more than 64 of them) with about the widest keys it
 * packs: unit boxes (level 2) in three rows of 34 touching ones about 2^28 apart, cell
 * indices 2^26 from 0 either way: 28 bits a coordinate, 56 with the 7 of the index, six
 * digits (a wider range takes the byte sort). The pairs after adding them all, and after
 * moving them all, against brute force. */
static void test_world_sort_wide_keys(void **s) {
  (void)s;
  QKT_ONE_THREAD_TEST();
  qk_world_t *w;
  assert_int_equal(qk_world_new(NULL, &w), QK_OK);
  mirror_t m = {0};
  const double at[3] = {-0x1p28, 0, 0x1p28};
  for (int g = 0; g < 3; g++)
    for (int k = 0; k < 34; k++) {
      double x = at[g] + k, y = at[2 - g] + (k & 1);
      m_add(w, &m, (qk_shape_t){QK_SHAPE_BOX, x, y, x + 1, y + 1});
    }
  qk_world_pair_t *prev = NULL;
  size_t np = 0;
  update_and_check(w, &m, &prev, &np, "wide keys", 0);
  assert_true(np >= 99);
  for (int f = 1; f <= 2; f++) {
    for (size_t i = 0; i < m.n; i++) m_move(w, &m, i, shifted(m.s[i], 3, -3));
    update_and_check(w, &m, &prev, &np, "wide keys", f);
  }
  free(prev), free(m.h), free(m.s);
  qk_world_free(w);
}

/* Segments that end on a disc's circle at a Pythagorean point and run along its tangent
 * there, from a start rounded off the tangent: the hits that graze the disc are where
 * the long double root of the entry parameter lies farthest from its value (its
 * discriminant near zero), above 1 by up to about 1e-15. The documented parameter is in
 * [0, 1]: every hit's t, by qk_world_raycast and qk_world_raycast_all. */
static void test_world_ray_tangent_end(void **s) {
  (void)s;
  QKT_ONE_THREAD_TEST();
  static const int tri[][3] = {{3, 4, 5}, {5, 12, 13}, {8, 15, 17}, {7, 24, 25}, {20, 21, 29}};
  qkt_rng_t r;
  qkt_rng_seed(&r, g_seed + 433);
  qk_world_t *w;
  assert_int_equal(qk_world_new(NULL, &w), QK_OK);
  qk_handle_t h;
  qk_shape_t d = {QK_SHAPE_DISC, 0, 0, 1, 0};
  assert_int_equal(qk_world_add(w, &d, 0, &h), QK_OK);
  assert_int_equal(qk_world_update(w), QK_OK);
  int hits = 0;
  for (int it = 0; it < 20000; it++) {
    const int *p = tri[qkt_rng_below(&r, 5)];
    double k = ldexp(1, (int)qkt_rng_below(&r, 8) - 4);
    int sw = (int)qkt_rng_below(&r, 2);
    double ux = p[sw] * (qkt_rng_below(&r, 2) ? 1 : -1),
           uy = p[1 - sw] * (qkt_rng_below(&r, 2) ? 1 : -1);
    d.x = ((int)qkt_rng_below(&r, 2001) - 1000) * 0.125;
    d.y = ((int)qkt_rng_below(&r, 2001) - 1000) * 0.125;
    d.a = p[2] * k;
    assert_int_equal(qk_world_move(w, h, &d), QK_OK);
    qk_point_t to = {d.x + ux * k, d.y + uy * k};
    double m = (qkt_rng_below(&r, 1000) + 1) / 3.0 * k / p[2];
    qk_point_t from = {to.x - uy * m, to.y + ux * m};
    qk_world_hit_t first, all[2];
    size_t n;
    assert_int_equal(qk_world_raycast(w, from, to, &first), QK_OK);
    assert_int_equal(qk_world_raycast_all(w, from, to, all, 2, &n), QK_OK);
    assert_int_equal(n, first.h == h);
    if (first.h != h) continue;
    hits++;
    if (!(first.t >= 0 && first.t <= 1 && all[0].t == first.t))
      fail_msg("case %d: t %a outside [0, 1] (seed %llu)", it, first.t, (unsigned long long)g_seed);
  }
  assert_true(hits > 1000);
  qk_world_free(w);
}

/* qk_world_pair_bytes: at least what the pairs of the last update need (4 bytes a current
 * pair, 8 a began or ended pair), never more than qk_world_bytes. */
static void test_world_pair_bytes(void **s) {
  (void)s;
  QKT_ONE_THREAD_TEST();
  qk_world_t *w;
  assert_int_equal(qk_world_new(NULL, &w), QK_OK);
  assert_true(qk_world_pair_bytes(w) <= qk_world_bytes(w));
  enum { N = 200 };
  qk_handle_t h[N];
  for (int i = 0; i < N; i++) { /* a chain: each disc meets its two neighbours */
    qk_shape_t d = {QK_SHAPE_DISC, 1.5 * i, 0, 1, 0};
    assert_int_equal(qk_world_add(w, &d, (uint64_t)i, &h[i]), QK_OK);
  }
  for (int frame = 0; frame < 3; frame++) {
    if (frame == 2) /* every other disc leaves: all pairs end */
      for (int i = 0; i < N; i += 2) {
        qk_shape_t far = {QK_SHAPE_DISC, 1.5 * i, 1000, 1, 0};
        assert_int_equal(qk_world_move(w, h[i], &far), QK_OK);
      }
    assert_int_equal(qk_world_update(w), QK_OK);
    size_t all, began, ended;
    assert_int_equal(qk_world_pairs_list(w, QK_PAIRS_ALL, NULL, 0, &all), QK_OK);
    assert_int_equal(qk_world_pairs_list(w, QK_PAIRS_BEGAN, NULL, 0, &began), QK_OK);
    assert_int_equal(qk_world_pairs_list(w, QK_PAIRS_ENDED, NULL, 0, &ended), QK_OK);
    assert_int_equal(all, frame < 2 ? N - 1 : 0);
    assert_int_equal(began, frame == 0 ? N - 1 : 0);
    assert_int_equal(ended, frame == 2 ? N - 1 : 0);
    size_t pb = qk_world_pair_bytes(w);
    assert_true(pb >= 4 * all + 8 * (began + ended));
    assert_true(pb <= qk_world_bytes(w));
  }
  qk_world_free(w);
}

static void test_world_stale_handles(void **s) {
  (void)s;
  QKT_ONE_THREAD_TEST();
  qk_world_t *w;
  assert_int_equal(qk_world_new(NULL, &w), QK_OK);
  qk_shape_t a = {QK_SHAPE_DISC, 0, 0, 1, 0}, b = {QK_SHAPE_BOX, 5, 5, 6, 6};
  qk_handle_t ha, hb, hc;
  assert_int_equal(qk_world_add(w, &a, 11, &ha), QK_OK);
  assert_int_equal(qk_world_remove(w, ha), QK_OK);
  assert_int_equal(qk_world_remove(w, ha), QK_ERR_NOT_FOUND);
  assert_int_equal(qk_world_add(w, &b, 22, &hb), QK_OK);
  assert_int_equal(QK_HANDLE_SLOT(hb), QK_HANDLE_SLOT(ha)); /* slot reused */
  assert_true(hb != ha);
  uint64_t tag;
  qk_shape_t got;
  assert_int_equal(qk_world_get(w, ha, &got, &tag), QK_ERR_NOT_FOUND);
  assert_int_equal(qk_world_move(w, ha, &a), QK_ERR_NOT_FOUND);
  assert_int_equal(qk_world_get(w, hb, &got, &tag), QK_OK);
  assert_int_equal(tag, 22);
  assert_int_equal(qk_world_get(w, (qk_handle_t)77, &got, &tag), QK_ERR_NOT_FOUND);
  assert_int_equal(qk_world_get(w, QK_HANDLE_NONE, &got, &tag), QK_ERR_NOT_FOUND);
  /* bad shapes leave the object as it was */
  qk_shape_t bad = {QK_SHAPE_DISC, NAN, 0, 1, 0}, neg = {QK_SHAPE_DISC, 0, 0, -1, 0},
             big = {QK_SHAPE_POINT, 1e31, 0, 0, 0}, kind = {(qk_shape_kind_t)9, 0, 0, 0, 0};
  assert_int_equal(qk_world_move(w, hb, &bad), QK_ERR_NONFINITE);
  assert_int_equal(qk_world_move(w, hb, &neg), QK_ERR_GEOMETRY);
  assert_int_equal(qk_world_add(w, &big, 0, &hc), QK_ERR_LIMIT);
  assert_int_equal(qk_world_add(w, &kind, 0, &hc), QK_ERR_INVALID);
  assert_int_equal(qk_world_get(w, hb, &got, NULL), QK_OK);
  assert_true(got.kind == QK_SHAPE_BOX && got.x == 5 && got.b == 6);
  assert_int_equal(qk_world_size(w), 1);
  qk_world_free(w);
  /* options out of range */
  qk_world_options_t o;
  qk_world_options_init(&o);
  o.margin = 17;
  assert_int_equal(qk_world_new(&o, &w), QK_ERR_INVALID);
  o.margin = nextafter(16, 17);
  assert_int_equal(qk_world_new(&o, &w), QK_ERR_INVALID);
  qk_world_options_init(&o);
  o.min_margin = INFINITY;
  assert_int_equal(qk_world_new(&o, &w), QK_ERR_INVALID);
  o.min_margin = nextafter(0x1p100, INFINITY);
  assert_int_equal(qk_world_new(&o, &w), QK_ERR_INVALID);
  /* the bounds themselves are accepted (margin 0..16, min_margin 0..2^100) */
  o.margin = 16;
  o.min_margin = 0x1p100;
  assert_int_equal(qk_world_new(&o, &w), QK_OK);
  assert_int_equal(qk_world_add(w, &got, 0, &hc), QK_OK);
  assert_int_equal(qk_world_update(w), QK_OK);
  qk_world_free(w);
  qk_world_options_init(&o);
  o.threads = 257;
  assert_int_equal(qk_world_new(&o, &w), QK_ERR_INVALID);
  /* 0 threads: every online core, as the tree's and the collider's option (refused) */
  o.threads = 0;
  assert_int_equal(qk_world_new(&o, &w), QK_OK);
  assert_int_equal(qk_world_add(w, &got, 0, &hc), QK_OK);
  assert_int_equal(qk_world_update(w), QK_OK);
  qk_world_free(w);
  qk_world_free(NULL);
  /* the extremes of the accepted range: tiny and huge values, and a point at 2^100 */
  assert_int_equal(qk_world_new(NULL, &w), QK_OK);
  qk_shape_t lo = {QK_SHAPE_DISC, 0x1p-100, -0x1p-100, 0x1p-100, 0};
  qk_shape_t hi = {QK_SHAPE_BOX, -0x1p100, -0x1p100, 0x1p100, 0x1p100};
  qk_shape_t far = {QK_SHAPE_POINT, 0x1p100, 0x1p100, 0, 0};
  qk_handle_t h1, h2, h3;
  assert_int_equal(qk_world_add(w, &lo, 0, &h1), QK_OK);
  assert_int_equal(qk_world_add(w, &hi, 0, &h2), QK_OK);
  assert_int_equal(qk_world_add(w, &far, 0, &h3), QK_OK);
  assert_int_equal(qk_world_update(w), QK_OK);
  size_t np;
  assert_int_equal(qk_world_pairs_list(w, QK_PAIRS_ALL, NULL, 0, &np), QK_OK);
  assert_int_equal(np, 2); /* the big box holds both others; the disc is far from the point */
  qk_world_hit_t nn[3];
  assert_int_equal(qk_world_knn(w, (qk_point_t){0x1p99, 0x1p99}, 3, nn, &np), QK_OK);
  assert_int_equal(np, 3);
  assert_true(nn[0].h == h2 && nn[0].t == 0);
  qk_world_free(w);
}

/* 10^5 frames of a small world; memory stays within 1.2x a fresh world of the same. */
static void test_world_churn_memory(void **s) {
  (void)s;
  QKT_ONE_THREAD_TEST();
  qkt_rng_t r;
  qkt_rng_seed(&r, g_seed + 99);
  qk_world_t *w;
  assert_int_equal(qk_world_new(NULL, &w), QK_OK);
  mirror_t m = {0};
  for (int i = 0; i < 60; i++) m_add(w, &m, rnd_shape(&r, SC_UNIFORM, 1));
  size_t peak = 0;
  for (int f = 0; f < 100000; f++) {
    size_t i = qkt_rng_below(&r, (uint32_t)m.n);
    if (f % 10 == 0) { /* churn: remove one, add one */
      assert_int_equal(qk_world_remove(w, m.h[i]), QK_OK);
      m.h[i] = m.h[m.n - 1], m.s[i] = m.s[m.n - 1], m.n--;
      m_add(w, &m, rnd_shape(&r, SC_UNIFORM, 1));
    } else {
      qk_shape_t sh = moved(&r, m.s[i]);
      if (sh.x < 0 || sh.x > 100 || sh.y < 0 || sh.y > 100) sh = rnd_shape(&r, SC_UNIFORM, 1);
      m_move(w, &m, i, sh);
    }
    if (f % 20 == 0) assert_int_equal(qk_world_update(w), QK_OK);
    if (qk_world_bytes(w) > peak) peak = qk_world_bytes(w);
  }
  assert_int_equal(qk_world_update(w), QK_OK);
  qk_world_t *fresh;
  assert_int_equal(qk_world_new(NULL, &fresh), QK_OK);
  for (size_t i = 0; i < m.n; i++) {
    qk_handle_t h;
    assert_int_equal(qk_world_add(fresh, &m.s[i], 0, &h), QK_OK);
  }
  assert_int_equal(qk_world_update(fresh), QK_OK);
  size_t used = qk_world_bytes(w), base = qk_world_bytes(fresh);
  if (used * 10 > base * 12)
    fail_msg("churned %zu bytes vs fresh %zu (peak %zu)", used, base, peak);
  free(m.h), free(m.s);
  qk_world_free(w), qk_world_free(fresh);
}

/* The same at 10^5 objects of every kind, each moving every frame (|v| up to 0.65 on a
 * field of 475 units, as a bouncing scene): there the update's kept scratch is most of
 * the memory, and its blocks stayed up to twice what the updates asked for once the
 * first update's larger requests had passed (1.21x a fresh world after 20 frames, 1.24x
 * at the peak). The memory after the frames stays within 1.2x a fresh world of the same
 * objects (issue 10; about 1.10x now, while the peak in the first frames is 1.25x). */
static void test_world_churn_memory_large(void **s) {
  (void)s;
  QKT_ONE_THREAD_TEST();
  enum { N = 100000, FRAMES = 24 };
  const double span = 475;
  qkt_rng_t r;
  qkt_rng_seed(&r, g_seed + 1999);
  qk_shape_t *sh = malloc(N * sizeof *sh);
  double *v = malloc(2 * N * sizeof *v);
  qk_handle_t *h = malloc(N * sizeof *h);
  assert_non_null(sh), assert_non_null(v), assert_non_null(h);
  qk_world_t *w;
  assert_int_equal(qk_world_new(NULL, &w), QK_OK);
  for (size_t i = 0; i < N; i++) {
    double x = qkt_rng_unit(&r) * span, y = qkt_rng_unit(&r) * span;
    double z = qkt_rng_range(&r, 0.5, 2), a = qkt_rng_range(&r, 0, 6.28);
    static const qk_shape_kind_t kinds[4] = {QK_SHAPE_DISC, QK_SHAPE_BOX, QK_SHAPE_SEGMENT,
                                             QK_SHAPE_POINT};
    qk_shape_kind_t k = kinds[i % 4];
    sh[i] = k == QK_SHAPE_DISC      ? (qk_shape_t){k, x, y, z / 2, 0}
            : k == QK_SHAPE_BOX     ? (qk_shape_t){k, x, y, x + z, y + z * qkt_rng_unit(&r)}
            : k == QK_SHAPE_SEGMENT ? (qk_shape_t){k, x, y, x + z * cos(a), y + z * sin(a)}
                                    : (qk_shape_t){k, x, y, 0, 0};
    v[2 * i] = qkt_rng_range(&r, -0.65, 0.65), v[2 * i + 1] = qkt_rng_range(&r, -0.65, 0.65);
    assert_int_equal(qk_world_add(w, &sh[i], i, &h[i]), QK_OK);
  }
  assert_int_equal(qk_world_update(w), QK_OK);
  size_t peak = qk_world_bytes(w);
  for (int f = 0; f < FRAMES; f++) {
    for (size_t i = 0; i < N; i++) {
      double dx = v[2 * i], dy = v[2 * i + 1];
      sh[i].x += dx, sh[i].y += dy;
      if (sh[i].kind == QK_SHAPE_BOX || sh[i].kind == QK_SHAPE_SEGMENT)
        sh[i].a += dx, sh[i].b += dy;
      if (sh[i].x < 0 || sh[i].x > span) v[2 * i] = -dx;
      if (sh[i].y < 0 || sh[i].y > span) v[2 * i + 1] = -dy;
      assert_int_equal(qk_world_move(w, h[i], &sh[i]), QK_OK);
    }
    assert_int_equal(qk_world_update(w), QK_OK);
    if (qk_world_bytes(w) > peak) peak = qk_world_bytes(w);
  }
  qk_world_t *fresh;
  assert_int_equal(qk_world_new(NULL, &fresh), QK_OK);
  for (size_t i = 0; i < N; i++) {
    qk_handle_t g;
    assert_int_equal(qk_world_add(fresh, &sh[i], i, &g), QK_OK);
  }
  assert_int_equal(qk_world_update(fresh), QK_OK);
  size_t used = qk_world_bytes(w), base = qk_world_bytes(fresh);
  printf("# churned %zu bytes (peak %zu), fresh %zu: %.3fx (peak %.3fx)\n", used, peak, base,
         (double)used / (double)base, (double)peak / (double)base);
  if (used * 10 > base * 12)
    fail_msg("churned %zu bytes, peak %zu, vs fresh %zu", used, peak, base);
  free(sh), free(v), free(h);
  qk_world_free(w), qk_world_free(fresh);
}

/* Rays and nearest objects where rounding used to decide the order (a reviewer's exact
 * oracles): a segment lying on the ray's line was hit at t = 0; a ray grazing a disc got
 * a t 1e-10 early, so a tangent disc and a radius-0 disc came before a point that was
 * first, and a tie with a segment went by the wrong slot (and b = f.v, left rounded at
 * first, still misordered grazing discs); near a disc of radius 5.8e24 a
 * point 7407 from it was at distance 4.9e-324, and one 2.47 from a segment at 0. */
/* A world holding shapes sh[0, n) (tags 0..n-1, handles into h), updated. */
static qk_world_t *world_of(const qk_shape_t *sh, size_t n, qk_handle_t *h) {
  qk_world_t *w;
  assert_int_equal(qk_world_new(NULL, &w), QK_OK);
  for (size_t i = 0; i < n; i++) assert_int_equal(qk_world_add(w, &sh[i], i, &h[i]), QK_OK);
  assert_int_equal(qk_world_update(w), QK_OK);
  return w;
}

static void test_world_ray_knn_rounding(void **s) {
  (void)s;
  qk_world_t *w;
  qk_world_hit_t all[4], first, nb[2];
  qk_handle_t h[4];
  size_t n;
  /* the ray along y = 3x from (100 2^-40, 300 2^-40) to X = 2^29 + 2^-10: the point at
   * t = (2^27 - ox) / (X - ox) first, then the collinear segment at (2^28 - ox) / (X - ox) */
  const double ox = 100 * 0x1p-40, X = 0x1p29 + 0x1p-10, a = 0x1p28, b = 0x1p28 + 0x1p20;
  const qk_shape_t collinear[2] = {{QK_SHAPE_SEGMENT, a, 3 * a, b, 3 * b},
                                   {QK_SHAPE_POINT, 0x1p27, 3 * 0x1p27, 0, 0}};
  w = world_of(collinear, 2, h);
  assert_int_equal(
      qk_world_raycast_all(w, (qk_point_t){ox, 3 * ox}, (qk_point_t){X, 3 * X}, all, 3, &n), QK_OK);
  assert_int_equal(n, 2);
  assert_true(all[0].h == h[1] && all[1].h == h[0]);
  assert_true(fabs(all[0].t - (0x1p27 - ox) / (X - ox)) < 1e-15);
  assert_true(fabs(all[1].t - (0x1p28 - ox) / (X - ox)) < 1e-15);
  qk_world_free(w);
  /* the ray (-3, 4) -> (4, 4): a point at (-2^-40, 4), t = (3 - 2^-40) / 7, first; a disc
   * tangent to it and a radius-0 disc, and a segment from the latter's centre, all at
   * t = (3 + 2^-60) / 7 (in doubles the same as 3 / 7), in slot order */
  const qk_shape_t tangent[4] = {{QK_SHAPE_SEGMENT, 0x1p-60, 4, 8, 8},
                                 {QK_SHAPE_DISC, 0x1p-60, 5, 1, 0},
                                 {QK_SHAPE_DISC, 0x1p-60, 4, 0, 0},
                                 {QK_SHAPE_POINT, -0x1p-40, 4, 0, 0}};
  w = world_of(tangent, 4, h);
  assert_int_equal(qk_world_raycast_all(w, (qk_point_t){-3, 4}, (qk_point_t){4, 4}, all, 4, &n),
                   QK_OK);
  assert_int_equal(n, 4);
  assert_true(all[0].h == h[3] && all[1].h == h[0] && all[2].h == h[1] && all[3].h == h[2]);
  assert_true(all[0].t < all[1].t);
  assert_true(all[1].t == 3.0 / 7 && all[2].t == 3.0 / 7 && all[3].t == 3.0 / 7);
  assert_int_equal(qk_world_raycast(w, (qk_point_t){-3, 4}, (qk_point_t){4, 4}, &first), QK_OK);
  assert_true(first.h == h[3]);
  qk_world_free(w);
  /* a grazing ray, f nearly across v, so that b = f.v cancels too: the large disc (slot 0,
   * exact t 0.0608953374440831...) before the small one (slot 1, 0.0608953374442102...) */
  const qk_shape_t grazing[2] = {
      {QK_SHAPE_DISC, 0.04490772282310107, -0.31270444442065104, 0.3499419629730869, 0},
      {QK_SHAPE_DISC, -0.21129852201443586, -0.07433972900390695, 2.6990189333332616e-09, 0}};
  w = world_of(grazing, 2, h);
  assert_int_equal(qk_world_raycast_all(w, (qk_point_t){-0.21129851992102808, -0.07433972675380823},
                                        (qk_point_t){-0.21129852410784364, -0.07433973125400568},
                                        all, 3, &n),
                   QK_OK);
  assert_int_equal(n, 2);
  assert_true(all[0].h == h[0] && all[1].h == h[1]);
  assert_true(fabs(all[0].t - 0.060895337444083168) < 1e-16);
  qk_world_free(w);
  /* a ray tangent to a disc whose b rounds to 0: the disc at t = 2^-20, after the point at
   * the ray's origin (it came at t = 0, the tie going to the disc's slot) */
  const qk_point_t o = {2.7939677238464355e-09, 3.725290298461914e-09};
  const qk_shape_t at_origin[2] = {
      {QK_SHAPE_DISC, -3.1554436208840472e-30, 2.3665827156630354e-30, 4.6566128730773926e-09, 0},
      {QK_SHAPE_POINT, o.x, o.y, 0, 0}};
  w = world_of(at_origin, 2, h);
  assert_int_equal(
      qk_world_raycast_all(w, o, (qk_point_t){2.7939677238464322e-09, 3.7252902984619165e-09}, all,
                           3, &n),
      QK_OK);
  assert_int_equal(n, 2);
  assert_true(all[0].h == h[1] && all[0].t == 0 && all[1].h == h[0] && all[1].t == 0x1p-20);
  qk_world_free(w);
  /* kNN near a huge disc: the point (12345.678, 3.6267774588438875e24) is 7407.4068 from
   * the disc's edge (exact), after a point 1000 away */
  const double px = 12345.678, py = 3.6267774588438875e+24;
  const qk_shape_t huge_disc[2] = {{QK_SHAPE_DISC, -0x1.8p+81, -0x1p+80, 0x1.4p+82, 0},
                                   {QK_SHAPE_POINT, px + 1000, py, 0, 0}};
  w = world_of(huge_disc, 2, h);
  assert_int_equal(qk_world_knn(w, (qk_point_t){px, py}, 2, nb, &n), QK_OK);
  assert_int_equal(n, 2);
  assert_true(nb[0].h == h[1] && nb[1].h == h[0]);
  assert_true(fabs(nb[1].t - 7407.4068) < 1e-3);
  qk_world_free(w);
  /* kNN near a segment at 1e24: exact squared distance 6.125 (2.4748737341529163) */
  const qk_shape_t far_segment[2] = {{QK_SHAPE_SEGMENT, -7.0, 3.6267774588438875e+24,
                                      2.4178516392292583e+24, 6.044629098073146e+24},
                                     {QK_SHAPE_POINT, 0x1p80, 0x1p82, 0, 0}};
  w = world_of(far_segment, 2, h);
  assert_int_equal(qk_world_knn(w, (qk_point_t){0x1p80, 0x1p82}, 2, nb, &n), QK_OK);
  assert_int_equal(n, 2);
  assert_true(nb[0].h == h[1] && nb[0].t == 0 && nb[1].h == h[0]);
  assert_true(fabs(nb[1].t - sqrt(6.125)) < 1e-12);
  qk_world_free(w);
}

/* A slot's generation does not wrap: after 2^31 objects in one slot, a handle of its
 * first object matched again and named the new one (a reviewer's 2^31 removes and adds,
 * 25 s; here the generation is set near its end). The slot is retired instead. */
static void test_world_generation_wrap(void **s) {
  (void)s;
  qk_world_t *w;
  assert_int_equal(qk_world_new(NULL, &w), QK_OK);
  qk_shape_t p = {QK_SHAPE_POINT, 1, 2, 0, 0};
  qk_handle_t first, h;
  assert_int_equal(qk_world_add(w, &p, 7, &first), QK_OK);
  assert_int_equal(QK_HANDLE_SLOT(first), 0);
  w->obj[0].gen = UINT32_MAX; /* its last live generation */
  h = (qk_handle_t)UINT32_MAX << 32;
  assert_int_equal(qk_world_get(w, h, NULL, NULL), QK_OK);
  assert_int_equal(qk_world_remove(w, h), QK_OK);
  qk_handle_t again;
  p.x = 5;
  assert_int_equal(qk_world_add(w, &p, 8, &again), QK_OK);
  assert_int_not_equal(QK_HANDLE_SLOT(again), 0); /* not the spent slot */
  uint64_t tag = 0;
  assert_int_equal(qk_world_get(w, first, NULL, &tag), QK_ERR_NOT_FOUND);
  assert_int_equal(qk_world_get(w, h, NULL, &tag), QK_ERR_NOT_FOUND);
  assert_int_equal(qk_world_get(w, again, NULL, &tag), QK_OK);
  assert_int_equal(tag, 8);
  assert_int_equal(qk_world_size(w), 1);
  assert_int_equal(qk_world_update(w), QK_OK);
  size_t n = 0;
  assert_int_equal(qk_world_pairs_list(w, QK_PAIRS_ALL, NULL, 0, &n), QK_OK);
  assert_int_equal(n, 0);
  qk_world_free(w);
}

/* Allocation failure at every N: a failed add or update changes nothing. */
static void test_world_nomem(void **s) {
  (void)s;
  QKT_ONE_THREAD_TEST();
  qkt_rng_t r;
  qkt_rng_seed(&r, g_seed + 5);
  for (size_t fail = 1; fail < 400; fail++) {
    qkt_alloc_t st = {0};
    qk_allocator_t al = qkt_alloc_make(&st);
    qk_world_options_t o;
    qk_world_options_init(&o);
    o.allocator = &al;
    qk_world_t *w = NULL;
    st.fail_at = fail;
    if (qk_world_new(&o, &w) != QK_OK) {
      assert_int_equal(st.live_blocks, 0);
      continue;
    }
    size_t done = 0, before = 0;
    for (int i = 0; i < 300; i++) {
      qk_shape_t sh = rnd_shape(&r, SC_UNIFORM, 1);
      qk_handle_t h;
      size_t n0 = qk_world_size(w);
      qk_status_t rc = qk_world_add(w, &sh, 0, &h);
      if (rc == QK_ERR_NOMEM) {
        assert_int_equal(qk_world_size(w), n0);
        assert_true(h == QK_HANDLE_NONE);
        continue;
      }
      assert_int_equal(rc, QK_OK);
      if (i % 50 == 49) {
        qk_world_pairs_list(w, QK_PAIRS_ALL, NULL, 0, &before);
        rc = qk_world_update(w);
        size_t after;
        qk_world_pairs_list(w, QK_PAIRS_ALL, NULL, 0, &after);
        if (rc == QK_ERR_NOMEM)
          assert_int_equal(after, before);
        else
          assert_int_equal(rc, QK_OK), done++;
      }
    }
    qk_world_free(w);
    assert_int_equal(st.live_blocks, 0);
    assert_int_equal(st.live_bytes, 0);
  }
}

/* An allocation failing at each point of a began-only frame with near candidates (discs,
 * segments, points, boxes off the float grid): the update fails and leaves the last
 * frame, and the next (with memory) gives the pairs, began and ended against brute force
 * from that frame; an update that succeeds is checked too. */
static void test_world_nomem_began(void **s) {
  (void)s;
  QKT_ONE_THREAD_TEST();
  qkt_rng_t r;
  qkt_rng_seed(&r, g_seed + 171);
  double cx[8], cy[8];
  cluster_centres(&r, cx, cy);
  qkt_alloc_t st = {0};
  qk_allocator_t al = qkt_alloc_make(&st);
  qk_world_options_t o;
  qk_world_options_init(&o);
  o.allocator = &al;
  qk_world_t *w;
  assert_int_equal(qk_world_new(&o, &w), QK_OK);
  mirror_t m = {0};
  for (int k = 0; k < 600; k++) m_add(w, &m, bg_shape(&r, cx, cy, 1, 1));
  qk_world_pair_t *prev = NULL;
  size_t np = 0, failed = 0;
  dense_check(w, &m, &prev, &np, 0);
  for (size_t fail = 1; fail < 60; fail++) {
    for (size_t i = 0; i < m.n; i++) {
      qk_shape_t sh = shifted(m.s[i], 0.1 * ((int)qkt_rng_below(&r, 3) - 1), 0.1);
      m_move(w, &m, i, sh);
    }
    size_t before, after;
    qk_world_pairs_list(w, QK_PAIRS_ALL, NULL, 0, &before);
    qkt_alloc_arm(&st, fail);
    qk_status_t rc = qk_world_update(w);
    qkt_alloc_arm(&st, 0);
    if (rc == QK_OK) {
      qk_world_pair_t *want;
      size_t nw = o_pairs(&m, &want);
      list_equals(w, QK_PAIRS_ALL, want, nw, (int)fail);
      free(prev);
      prev = want, np = nw;
      continue;
    }
    assert_int_equal(rc, QK_ERR_NOMEM);
    qk_world_pairs_list(w, QK_PAIRS_ALL, NULL, 0, &after);
    assert_int_equal(after, before);
    failed++;
    dense_check(w, &m, &prev, &np, (int)fail);
  }
  assert_true(failed > 5);
  free(prev), free(m.h), free(m.s);
  qk_world_free(w);
  assert_int_equal(st.live_blocks, 0);
}

/* The world keeps its worker threads between updates; a child forked after they started
 * has none of them, so its threaded updates must not wait for them: the child's frames
 * (on two threads) give the pairs, began and ended of a one-thread world it builds itself.
 * A child that hangs is stopped by an alarm and fails the test. (Not under TSan, which
 * does not follow a multithreaded process into fork.) */
static void test_world_threads_fork(void **s) {
  (void)s;
#if QKT_TSAN
  skip();
#else
  enum { N = 4500 }; /* (the update runs on threads from 4096 objects) */
  qk_shape_t *sh = malloc(N * sizeof *sh);
  qk_handle_t *h[2] = {malloc(N * sizeof *h[0]), malloc(N * sizeof *h[1])};
  qkt_rng_t r;
  qkt_rng_seed(&r, g_seed + 41);
  for (int i = 0; i < N; i++) sh[i] = rnd_shape(&r, SC_UNIFORM, 1);
  qk_world_options_t o;
  qk_world_options_init(&o);
  o.threads = 2;
  o.thread_min = 0; /* the threaded paths at this size too */
  qk_world_t *w[2];
  assert_int_equal(qk_world_new(&o, &w[1]), QK_OK);
  for (int i = 0; i < N; i++) assert_int_equal(qk_world_add(w[1], &sh[i], 0, &h[1][i]), QK_OK);
  assert_int_equal(qk_world_update(w[1]), QK_OK); /* (the workers start) */
  fflush(NULL);
  pid_t pid = fork();
  assert_true(pid >= 0);
  if (pid == 0) {
    alarm(120);
    o.threads = 1;
    int bad = qk_world_new(&o, &w[0]) != QK_OK;
    for (int i = 0; i < N && !bad; i++) bad = qk_world_add(w[0], &sh[i], 0, &h[0][i]) != QK_OK;
    bad = bad || qk_world_update(w[0]) != QK_OK;
    for (int f = 0; f < 3 && !bad; f++) {
      for (int i = 0; i < N; i++) sh[i] = moved(&r, sh[i]);
      for (int t = 0; t < 2 && !bad; t++) {
        bad = qk_world_move_batch(w[t], h[t], sh, N, NULL) != QK_OK;
        bad = bad || qk_world_update(w[t]) != QK_OK;
      }
      for (int which = 0; which < 3 && !bad; which++) {
        size_t n0, n1;
        qk_world_pairs_list(w[0], (qk_pairs_which_t)which, NULL, 0, &n0);
        qk_world_pairs_list(w[1], (qk_pairs_which_t)which, NULL, 0, &n1);
        qk_world_pair_t *p0 = malloc((n0 + 1) * sizeof *p0), *p1 = malloc((n0 + 1) * sizeof *p1);
        bad = n0 != n1 || !p0 || !p1;
        if (!bad) {
          qk_world_pairs_list(w[0], (qk_pairs_which_t)which, p0, n0, &n0);
          qk_world_pairs_list(w[1], (qk_pairs_which_t)which, p1, n1, &n1);
          for (size_t k = 0; k < n0 && !bad; k++)
            bad = QK_HANDLE_SLOT(p0[k].a) != QK_HANDLE_SLOT(p1[k].a) ||
                  QK_HANDLE_SLOT(p0[k].b) != QK_HANDLE_SLOT(p1[k].b);
        }
        free(p0), free(p1);
      }
    }
    qk_world_free(w[0]);
    qk_world_free(w[1]);
    _exit(bad ? 1 : 0);
  }
  int status = 0;
  assert_int_equal(waitpid(pid, &status, 0), pid);
  if (!WIFEXITED(status) || WEXITSTATUS(status) != 0)
    fail_msg("forked child: %s %d (seed %llu)", WIFEXITED(status) ? "exit" : "signal",
             WIFEXITED(status) ? WEXITSTATUS(status) : WTERMSIG(status),
             (unsigned long long)g_seed);
  /* the parent's workers are still there */
  for (int i = 0; i < N; i++) sh[i] = moved(&r, sh[i]);
  assert_int_equal(qk_world_move_batch(w[1], h[1], sh, N, NULL), QK_OK);
  assert_int_equal(qk_world_update(w[1]), QK_OK);
  qk_world_free(w[1]);
  free(h[0]), free(h[1]), free(sh);
#endif
}

/*
 * The scratch cache's blocks given back on a worker (collide/world_scratch.c, drop, and
 * collide/world_threads.c, qk__world_pool_detach): the calling thread returns while the
 * worker frees them, and the pool's next step waits for it. An allocator whose free of a
 * block of 256 KB and more sleeps off the test's thread keeps that job running into the
 * next update; the scene swings between 4 500 boxes in a 20 x 20 square (some 100 000
 * pairs) and far apart (few), so that large blocks are given back every few frames. Every
 * frame against brute force (dense_check) on 1 to 7 threads, and the frees off the test's
 * thread counted: there are some from 2 threads on (none on one). A step posted while the
 * job runs would count the job's end as its own and go on before its worker's share (with
 * pool_run's wait removed this test did not end within 10 minutes; with no job detached it
 * fails on the count).
 */
typedef struct slow_alloc {
  pthread_t main;
  int off; /* large frees off the main thread (atomic) */
} slow_alloc_t;

static void *slow_fn(void *ud, void *p, size_t osize, size_t nsize) {
  slow_alloc_t *a = ud;
  if (nsize) return realloc(p, nsize);
  if (p && osize >= ((size_t)256 << 10) && !pthread_equal(pthread_self(), a->main)) {
    __atomic_fetch_add(&a->off, 1, __ATOMIC_RELAXED);
    struct timespec ts = {0, 20 * 1000 * 1000};
    nanosleep(&ts, NULL);
  }
  free(p);
  return NULL;
}

static void run_threads_detach(unsigned threads) {
  enum { N = 4500 }; /* (the update's steps run on the threads from 4096 objects) */
  slow_alloc_t sa = {pthread_self(), 0};
  qk_allocator_t al = {slow_fn, &sa};
  qk_world_options_t o;
  qk_world_options_init(&o);
  o.threads = threads;
  o.thread_min = 0;
  o.allocator = &al;
  qk_world_t *w;
  assert_int_equal(qk_world_new(&o, &w), QK_OK);
  qkt_rng_t r;
  qkt_rng_seed(&r, g_seed + 977 + threads);
  mirror_t m = {0};
  qk_world_pair_t *prev = NULL;
  size_t np = 0, most = 0;
  for (int f = 0; f < 8; f++) {
    double span = f % 3 == 0 ? 20 : 4000;
    for (size_t i = 0; i < N; i++) {
      double x = q64(qkt_rng_range(&r, 0, span)), y = q64(qkt_rng_range(&r, 0, span));
      qk_shape_t sh = {QK_SHAPE_BOX, x, y, x + 1, y + 1};
      if (f)
        m_move(w, &m, i, sh);
      else
        m_add(w, &m, sh);
    }
    dense_check(w, &m, &prev, &np, f);
    if (np > most) most = np;
  }
  qk_world_free(w); /* (with a job maybe still running: the pool's end waits for it) */
  assert_true(most > 40000);
  int off = __atomic_load_n(&sa.off, __ATOMIC_RELAXED);
  if (threads == 1)
    assert_int_equal(off, 0);
  else if (!off)
    fail_msg("%u threads: no block given back off the calling thread", threads);
  free(prev), free(m.h), free(m.s);
}

static void test_world_threads_detach(void **s) {
  (void)s;
  for (unsigned th = QKT_TSAN ? 2 : 1; th <= 7; th++) run_threads_detach(th);
}

/* Two threads give the same pairs and ray hits as one. */
static void test_world_threads(void **s) {
  (void)s;
  qk_world_t *w[2];
  for (int t = 0; t < 2; t++) {
    qk_world_options_t o;
    qk_world_options_init(&o);
    o.threads = t ? 2 : 1;
    o.thread_min = 0; /* the threaded paths at this size too */
    assert_int_equal(qk_world_new(&o, &w[t]), QK_OK);
    qkt_rng_t r;
    qkt_rng_seed(&r, g_seed + 17);
    for (int i = 0; i < 6000; i++) {
      qk_shape_t sh = rnd_shape(&r, SC_MIXED, 1);
      qk_handle_t h;
      assert_int_equal(qk_world_add(w[t], &sh, 0, &h), QK_OK);
    }
    assert_int_equal(qk_world_update(w[t]), QK_OK);
  }
  size_t n0, n1;
  qk_world_pairs_list(w[0], QK_PAIRS_ALL, NULL, 0, &n0);
  qk_world_pairs_list(w[1], QK_PAIRS_ALL, NULL, 0, &n1);
  assert_int_equal(n0, n1);
  qk_world_pair_t *p0 = malloc((n0 + 1) * sizeof *p0), *p1 = malloc((n0 + 1) * sizeof *p1);
  qk_world_pairs_list(w[0], QK_PAIRS_ALL, p0, n0, &n0);
  qk_world_pairs_list(w[1], QK_PAIRS_ALL, p1, n1, &n1);
  assert_memory_equal(p0, p1, n0 * sizeof *p0);
  enum { NR = 2000 };
  qk_point_t *a = malloc(NR * sizeof *a), *b = malloc(NR * sizeof *b);
  qk_world_hit_t *h0 = malloc(NR * sizeof *h0), *h1 = malloc(NR * sizeof *h1);
  qkt_rng_t r;
  qkt_rng_seed(&r, g_seed + 3);
  for (int i = 0; i < NR; i++) {
    a[i] = (qk_point_t){qkt_rng_unit(&r) * 100, qkt_rng_unit(&r) * 100};
    b[i] = (qk_point_t){a[i].x + qkt_rng_range(&r, -20, 20), a[i].y + qkt_rng_range(&r, -20, 20)};
  }
  assert_int_equal(qk_world_raycast_batch(w[0], a, b, NR, h0), QK_OK);
  assert_int_equal(qk_world_raycast_batch(w[1], a, b, NR, h1), QK_OK);
  assert_memory_equal(h0, h1, NR * sizeof *h0);
  /* batch kNN: identical on one and two threads, and equal to the single calls */
  enum { NK = 500, K = 4 };
  qk_world_hit_t *k0 = malloc(NK * K * sizeof *k0), *k1 = malloc(NK * K * sizeof *k1);
  size_t c0[NK], c1[NK];
  assert_int_equal(qk_world_knn_batch(w[0], a, NK, K, k0, c0), QK_OK);
  assert_int_equal(qk_world_knn_batch(w[1], a, NK, K, k1, c1), QK_OK);
  assert_memory_equal(c0, c1, sizeof c0);
  assert_memory_equal(k0, k1, NK * K * sizeof *k0);
  for (int i = 0; i < NK; i += 50) {
    qk_world_hit_t one[K];
    size_t n1;
    assert_int_equal(qk_world_knn(w[0], a[i], K, one, &n1), QK_OK);
    assert_int_equal(n1, c0[i]);
    assert_memory_equal(one, k0 + (size_t)i * K, n1 * sizeof *one);
  }
  free(k0), free(k1);
  for (int i = 0; i < NR; i += 97) {
    qk_world_hit_t one;
    assert_int_equal(qk_world_raycast(w[0], a[i], b[i], &one), QK_OK);
    assert_true(one.h == h0[i].h && (one.t == h0[i].t || one.h == QK_HANDLE_NONE));
  }
  free(a), free(b), free(h0), free(h1), free(p0), free(p1);
  qk_world_free(w[0]), qk_world_free(w[1]);
}

/* Readers: three threads query one world at once (read-only calls). */
typedef struct reader {
  const qk_world_t *w;
  const qk_point_t *a, *b;
  const qk_world_hit_t *want;
  int n, ok;
} reader_t;

static void *reader_main(void *arg) {
  reader_t *r = arg;
  r->ok = 1;
  for (int i = 0; i < r->n; i++) {
    qk_world_hit_t h, nn[3];
    size_t n;
    if (qk_world_raycast(r->w, r->a[i], r->b[i], &h) != QK_OK || h.h != r->want[i].h) r->ok = 0;
    if (qk_world_knn(r->w, r->a[i], 3, nn, &n) != QK_OK || n != 3) r->ok = 0;
    qk_shape_t q = {QK_SHAPE_DISC, r->a[i].x, r->a[i].y, 2, 0};
    if (qk_world_query(r->w, &q, NULL, 0, &n) != QK_OK) r->ok = 0;
  }
  size_t np;
  if (qk_world_pairs_list(r->w, QK_PAIRS_ALL, NULL, 0, &np) != QK_OK) r->ok = 0;
  return NULL;
}

static void test_world_concurrent_readers(void **s) {
  (void)s;
  qkt_rng_t r;
  qkt_rng_seed(&r, g_seed + 23);
  qk_world_t *w;
  assert_int_equal(qk_world_new(NULL, &w), QK_OK);
  for (int i = 0; i < 3000; i++) {
    qk_shape_t sh = rnd_shape(&r, SC_UNIFORM, 1);
    qk_handle_t h;
    assert_int_equal(qk_world_add(w, &sh, 0, &h), QK_OK);
  }
  assert_int_equal(qk_world_update(w), QK_OK);
  enum { NQ = 300 };
  qk_point_t a[NQ], b[NQ];
  qk_world_hit_t want[NQ];
  for (int i = 0; i < NQ; i++) {
    a[i] = (qk_point_t){qkt_rng_unit(&r) * 100, qkt_rng_unit(&r) * 100};
    b[i] = (qk_point_t){a[i].x + qkt_rng_range(&r, -30, 30), a[i].y + qkt_rng_range(&r, -30, 30)};
    assert_int_equal(qk_world_raycast(w, a[i], b[i], &want[i]), QK_OK);
  }
  pthread_t th[3];
  reader_t rd[3];
  for (int t = 0; t < 3; t++) {
    rd[t] = (reader_t){w, a, b, want, NQ, 0};
    assert_int_equal(pthread_create(&th[t], NULL, reader_main, &rd[t]), 0);
  }
  for (int t = 0; t < 3; t++) pthread_join(th[t], NULL);
  for (int t = 0; t < 3; t++) assert_true(rd[t].ok);
  qk_world_free(w);
}

/* Allocation failure at every allocating call of a threaded update (the rows and the
 * began / ended lists built on the world's threads): each failure leaves the pairs as
 * they were, and an update that succeeds agrees with a one-thread world. */
static qk_world_t *nomem_world(qk_allocator_t *al, unsigned threads, const qk_shape_t *sh,
                               const qk_shape_t *sh2, int n) {
  qk_world_options_t o;
  qk_world_options_init(&o);
  o.threads = threads;
  o.thread_min = 0; /* the threaded paths at this size too */
  o.allocator = al;
  qk_world_t *w;
  qk_handle_t *h = malloc(n * sizeof *h);
  assert_int_equal(qk_world_new(&o, &w), QK_OK);
  for (int i = 0; i < n; i++) assert_int_equal(qk_world_add(w, &sh[i], 0, &h[i]), QK_OK);
  assert_int_equal(qk_world_update(w), QK_OK);
  assert_int_equal(qk_world_move_batch(w, h, sh2, n, NULL), QK_OK);
  free(h);
  return w;
}

/* The counting allocator behind a lock: a threaded world allocates from its threads.
 * (Which call fails then varies with the threads' timing; every one must be handled.) */
static pthread_mutex_t g_alloc_mu = PTHREAD_MUTEX_INITIALIZER;
static void *locked_alloc(void *ud, void *p, size_t osize, size_t nsize) {
  pthread_mutex_lock(&g_alloc_mu);
  void *r = qkt_alloc_fn(ud, p, osize, nsize);
  pthread_mutex_unlock(&g_alloc_mu);
  return r;
}

/* After an update that returned rc: on QK_ERR_NOMEM, w's pairs, began and ended lists
 * have the lengths they had before it (before, read only then); else rc is QK_OK and the
 * three lists equal w0's (a world whose allocator never failed), in the same order. */
static void expect_update_outcome(qk_world_t *w0, qk_world_t *w, qk_status_t rc,
                                  const size_t before[3]) {
  for (int which = 0; which < 3; which++) {
    size_t n0, n1;
    qk_world_pairs_list(w0, (qk_pairs_which_t)which, NULL, 0, &n0);
    qk_world_pairs_list(w, (qk_pairs_which_t)which, NULL, 0, &n1);
    if (rc == QK_ERR_NOMEM) {
      assert_int_equal(n1, before[which]);
      continue;
    }
    assert_int_equal(rc, QK_OK);
    assert_int_equal(n0, n1);
    qk_world_pair_t *p0 = malloc((n0 + 1) * sizeof *p0), *p1 = malloc((n1 + 1) * sizeof *p1);
    qk_world_pairs_list(w0, (qk_pairs_which_t)which, p0, n0, &n0);
    qk_world_pairs_list(w, (qk_pairs_which_t)which, p1, n1, &n1);
    assert_memory_equal(p0, p1, n0 * sizeof *p0);
    free(p0), free(p1);
  }
}

/* (N 4 400: the update's blocks are below the scratch cache's 256 KB, so each failing
 * update allocates fresh; 20 000: the failing update is the second, its large scratch
 * taken from the blocks the first kept.) */
static void nomem_threads(int N) {
  qkt_rng_t r;
  qkt_rng_seed(&r, g_seed + 41);
  qk_shape_t *sh = malloc(2 * N * sizeof *sh);
  for (int i = 0; i < N; i++) sh[i] = rnd_shape(&r, SC_UNIFORM, 1), sh[N + i] = moved(&r, sh[i]);
  qk_world_t *w0 = nomem_world(NULL, 1, sh, sh + N, N);
  assert_int_equal(qk_world_update(w0), QK_OK);
  size_t calls = 0;
  for (size_t fail = 1; fail <= calls + 1; fail++) {
    qkt_alloc_t st = {0};
    qk_allocator_t al = qkt_alloc_make(&st);
    al = (qk_allocator_t){locked_alloc, &st};
    qk_world_t *w = nomem_world(&al, 2, sh, sh + N, N);
    size_t before[3];
    for (int which = 0; which < 3; which++)
      qk_world_pairs_list(w, (qk_pairs_which_t)which, NULL, 0, &before[which]);
    st.calls = 0, st.fail_at = calls ? fail : 0, st.failed = 0;
    qk_status_t rc = qk_world_update(w);
    if (!calls) calls = st.calls, fail = 0; /* the first round counts the calls */
    expect_update_outcome(w0, w, rc, before);
    qk_world_free(w);
    assert_int_equal(st.live_blocks, 0);
  }
  assert_true(calls >= 12); /* (the threaded rows allocate a dozen blocks and more) */
  qk_world_free(w0);
  free(sh);
}

static void test_world_nomem_threads(void **s) {
  (void)s;
  nomem_threads(4400);
}

static void test_world_nomem_threads_warm(void **s) {
  (void)s;
  nomem_threads(QKT_TSAN ? 4400 : 20000);
}

/* The update's large scratch kept between updates: an allocator that counts the fresh
 * blocks of 256 KB and more and puts a canary after every block (checked when it comes
 * back, so a kept block handed out smaller than its request fails here, as does a size
 * that does not match the block). After two frames of warm-up a steady frame allocates
 * (almost) no fresh large block, with pairs equal to a world on one thread; when most
 * objects are removed the kept bytes drop within three updates; after qk_world_free every
 * byte is back. */
typedef struct canary_alloc {
  pthread_mutex_t mu;
  size_t live, big_fresh;
} canary_alloc_t;

static const uint64_t g_canary = 0x5ca1ab1ec0ffee11u;
static void *canary_fn(void *ud, void *p, size_t osize, size_t nsize) {
  canary_alloc_t *a = ud;
  size_t *h = p ? (size_t *)p - 2 : NULL;
  pthread_mutex_lock(&a->mu);
  if (h) {
    uint64_t c;
    memcpy(&c, (char *)p + h[0], sizeof c);
    if (h[0] != osize || c != g_canary)
      fail_msg("block of %zu given back as %zu (canary %d)", h[0], osize, c == g_canary);
    a->live -= osize;
  }
  if (!p && nsize >= (256u << 10)) a->big_fresh++;
  a->live += nsize;
  pthread_mutex_unlock(&a->mu);
  if (nsize == 0) {
    free(h);
    return NULL;
  }
  size_t *n = realloc(h, 2 * sizeof *n + nsize + sizeof g_canary);
  if (!n) return NULL; /* (not reached in this test) */
  n[0] = nsize;
  memcpy((char *)(n + 2) + nsize, &g_canary, sizeof g_canary);
  return n + 2;
}

static void test_world_scratch_kept(void **s) {
  (void)s;
  enum { N = 30000 };
  qkt_rng_t r;
  qkt_rng_seed(&r, g_seed + 171);
  canary_alloc_t ca = {PTHREAD_MUTEX_INITIALIZER, 0, 0};
  qk_allocator_t al = {canary_fn, &ca};
  qk_shape_t *sh = malloc(N * sizeof *sh);
  qk_handle_t *h = malloc(N * sizeof *h), *h0 = malloc(N * sizeof *h0);
  for (int i = 0; i < N; i++) sh[i] = rnd_shape(&r, SC_UNIFORM, 1);
  qk_world_options_t o;
  qk_world_options_init(&o);
  o.threads = 2, o.thread_min = 0, o.allocator = &al;
  qk_world_t *w, *w0;
  assert_int_equal(qk_world_new(&o, &w), QK_OK);
  assert_int_equal(qk_world_new(NULL, &w0), QK_OK);
  for (int i = 0; i < N; i++) {
    assert_int_equal(qk_world_add(w, &sh[i], 0, &h[i]), QK_OK);
    assert_int_equal(qk_world_add(w0, &sh[i], 0, &h0[i]), QK_OK);
  }
  size_t fresh[5];
  for (int f = 0; f < 5; f++) {
    size_t b0 = ca.big_fresh;
    assert_int_equal(qk_world_update(w), QK_OK);
    assert_int_equal(qk_world_update(w0), QK_OK);
    fresh[f] = ca.big_fresh - b0;
    expect_update_outcome(w0, w, QK_OK, NULL);
    for (int i = 0; i < N; i++) {
      qk_shape_t m = moved(&r, sh[i]);
      sh[i] = m;
      assert_int_equal(qk_world_move(w, h[i], &m), QK_OK);
      assert_int_equal(qk_world_move(w0, h0[i], &m), QK_OK);
    }
  }
  if (fresh[0] < 5 || fresh[3] + fresh[4] > 2)
    fail_msg("fresh blocks of 256 KB and more by frame: %zu %zu %zu %zu %zu", fresh[0], fresh[1],
             fresh[2], fresh[3], fresh[4]);
  size_t big = qk_world_bytes(w);
  for (int i = 1000; i < N; i++) assert_int_equal(qk_world_remove(w, h[i]), QK_OK);
  /* (the first update after the removals still ends 30 000 objects' pairs; its blocks
   * are given back at the third) */
  for (int f = 0; f < 3; f++) assert_int_equal(qk_world_update(w), QK_OK);
  /* (what stays kept depends on the two threads' timing: 3.44 of 13.7 MB in a CI run that
   * failed a 4x bound; the cache keeping all it held would be no drop at all) */
  size_t small = qk_world_bytes(w);
  if (small * 2 > big) fail_msg("kept %zu bytes after shrinking from %zu", small, big);
  /* (under the mutex: a worker may still be giving the last update's blocks back) */
  pthread_mutex_lock(&ca.mu);
  size_t live = ca.live;
  pthread_mutex_unlock(&ca.mu);
  assert_true(live >= small);
  qk_world_free(w), qk_world_free(w0);
  assert_int_equal(ca.live, 0);
  free(sh), free(h), free(h0);
}

/* Allocation failure at every N in a began-only update on two and three threads (the
 * scene of run_began_ranges: the began keys sorted by ranges on the threads, the rows
 * merged by ranges): a failed update keeps the last frame's pairs, began and ended (their
 * contents), frees all it took, and the next update (the same moves, and more) gives the
 * pairs, began and ended against brute force. */
static void test_world_nomem_began_threads(void **s) {
  (void)s;
  enum { N = 4400 };
  for (unsigned th = 2; th <= 3; th++) {
    qkt_rng_t r;
    qkt_rng_seed(&r, g_seed + 181 + th);
    double cx[8], cy[8];
    cluster_centres(&r, cx, cy);
    qkt_alloc_t st = {0};
    (void)qkt_alloc_make(&st);
    qk_allocator_t al = {locked_alloc, &st};
    qk_world_options_t o;
    qk_world_options_init(&o);
    o.allocator = &al, o.threads = th, o.thread_min = 0;
    qk_world_t *w;
    assert_int_equal(qk_world_new(&o, &w), QK_OK);
    mirror_t m = {0};
    double vx[N], vy[N];
    for (size_t k = 0; k < N; k++) {
      m_add(w, &m, cm_shape(&r, cx, cy, 0));
      double a = qkt_rng_range(&r, 0, 6.283185307179586);
      vx[k] = q64(0.25 * cos(a)), vy[k] = q64(0.25 * sin(a));
    }
    qk_world_pair_t *prev = NULL;
    size_t np = 0, failed = 0;
    dense_check(w, &m, &prev, &np, 0);
    /* a began-only update, counting its allocating calls */
    for (size_t i = 0; i < m.n; i++) m_move(w, &m, i, bounced(m.s[i], &vx[i], &vy[i]));
    qkt_alloc_arm(&st, 0);
    dense_check(w, &m, &prev, &np, 1);
    size_t calls = st.calls;
    for (size_t fail = 1; fail <= calls; fail += QKT_TSAN ? 7 : 1) {
      for (size_t i = 0; i < m.n; i++) m_move(w, &m, i, bounced(m.s[i], &vx[i], &vy[i]));
      qk_world_pair_t *before[3];
      size_t nb[3];
      for (int which = 0; which < 3; which++) {
        qk_world_pairs_list(w, (qk_pairs_which_t)which, NULL, 0, &nb[which]);
        before[which] = malloc((nb[which] + 1) * sizeof *before[which]);
        qk_world_pairs_list(w, (qk_pairs_which_t)which, before[which], nb[which], &nb[which]);
      }
      qkt_alloc_arm(&st, fail);
      qk_status_t rc = qk_world_update(w);
      qkt_alloc_arm(&st, 0);
      if (rc == QK_ERR_NOMEM) {
        failed++;
        for (int which = 0; which < 3; which++)
          list_equals(w, (qk_pairs_which_t)which, before[which], nb[which], (int)fail);
        dense_check(w, &m, &prev, &np, (int)fail);
      } else {
        assert_int_equal(rc, QK_OK); /* (the failed call's result was not needed) */
        qk_world_pair_t *want;
        size_t nw = o_pairs(&m, &want);
        list_equals(w, QK_PAIRS_ALL, want, nw, (int)fail);
        free(prev);
        prev = want, np = nw;
      }
      for (int which = 0; which < 3; which++) free(before[which]);
    }
    assert_true(calls >= 12 && failed >= (QKT_TSAN ? 2 : 10));
    free(prev), free(m.h), free(m.s);
    qk_world_free(w);
    assert_int_equal(st.live_blocks, 0);
  }
}

/* ---- The rows' buffer kept while the pairs fall (issue 10, wt2) ---- */

/* A world whose pairs fall by about 2% a frame, searched by bands on their began
 * candidates only (3000 boxes of sides 1/4 to 4 on the 1/64 grid over a 24 x 24 square,
 * about 120 000 pairs, spreading out from its centre by 1% a frame), on one thread and
 * on two, through the canary allocator of test_world_scratch_kept: after two frames of
 * warm-up no update takes a fresh block of 256 KB or more from it, and every frame's
 * pairs, began and ended equal brute force. Before, the new rows' room was cut to their
 * size once it passed 1.25 times their pairs, though the scratch cache kept the block's
 * room; a frame or two later the rows (the last frame's and the began ones) outgrew that
 * room and a fresh block was taken for them, its pages faulted in (at 10^5 clustered
 * boxes, 40 MB every eighth update). */
static void test_world_rows_kept_falling(void **s) {
  (void)s;
  enum { N = 4400 };
  const int frames = QKT_TSAN ? 12 : 20;
  for (unsigned th = QKT_TSAN ? 2 : 1; th <= 2; th++) {
    qkt_rng_t r;
    qkt_rng_seed(&r, g_seed + 191 + th);
    canary_alloc_t ca = {PTHREAD_MUTEX_INITIALIZER, 0, 0};
    qk_allocator_t al = {canary_fn, &ca};
    qk_world_options_t o;
    qk_world_options_init(&o);
    o.threads = th, o.thread_min = 0, o.allocator = &al;
    qk_world_t *w;
    assert_int_equal(qk_world_new(&o, &w), QK_OK);
    mirror_t m = {0};
    for (int i = 0; i < N; i++) {
      double side = q64(0.25 * pow(16.0, qkt_rng_unit(&r)));
      double x = q64(qkt_rng_range(&r, 0, 23)), y = q64(qkt_rng_range(&r, 0, 23));
      m_add(w, &m, (qk_shape_t){QK_SHAPE_BOX, x, y, x + side, y + side});
    }
    qk_world_pair_t *prev = NULL;
    size_t np = 0, fresh = 0, first = 0;
    for (int f = 0; f < frames; f++) {
      if (f)
        for (size_t i = 0; i < m.n; i++) {
          const qk_shape_t *b = &m.s[i];
          double jx = qkt_rng_range(&r, -0.25, 0.25), jy = qkt_rng_range(&r, -0.25, 0.25);
          m_move(w, &m, i, shifted(*b, q64((b->x - 12) / 100 + jx), q64((b->y - 12) / 100 + jy)));
        }
      size_t b0 = ca.big_fresh;
      dense_check(w, &m, &prev, &np, f);
      if (f >= 2) fresh += ca.big_fresh - b0;
      if (f == 0) first = np;
    }
    /* (the scene: falling pairs, rows of 256 KB and more throughout) */
    assert_true(first > 100000 && np < first - first / 8 && np > 70000);
    if (fresh) fail_msg("%u threads: %zu fresh blocks of 256 KB and more", th, fresh);
    free(prev), free(m.h), free(m.s);
    qk_world_free(w);
    assert_int_equal(ca.live, 0);
  }
}

/* ---- the speed's margin (collide/world.c: a re-filed object's margin is at least twice
 * its last step, at most 32 times its size) ---------------------------------------------- */

/* Small boxes (1/64 .. 1/16, on the 1/64 grid) moving 1/4 or 3/16 an axis every frame,
 * bouncing in a 24 x 24 square: every frame against brute force, and the re-filings (the
 * dirty list after the moves) counted. With the size's margin alone such a box leaves its
 * cell's loose square (1/4 .. 1/2 wide) nearly every frame; with the speed's it takes a
 * few frames. Then one box jumps 1000 and stays: filed at a level no coarser than 65
 * times its size allows (the cap), and not re-filed while it stays (the shrink rule
 * keeps the margins it was filed with); a box shrinking from 4 to 1/64 in place is
 * re-filed at a fine level. */
/* The VmFlags of the mapping holding address a have flag (two letters), from
 * /proc/self/smaps: 1 yes, 0 no, -1 when it cannot tell. */
static int vma_has_flag(const void *a, const char *flag) {
  FILE *f = fopen("/proc/self/smaps", "r");
  if (!f) return -1;
  char line[512];
  int in = 0, got = -1;
  unsigned long x = (unsigned long)a;
  while (fgets(line, sizeof line, f)) {
    unsigned long lo, hi;
    if (sscanf(line, "%lx-%lx ", &lo, &hi) == 2 && strchr(line, '-') < strchr(line, ' ')) {
      in = x >= lo && x < hi;
    } else if (in && !strncmp(line, "VmFlags:", 8)) {
      got = 0;
      for (char *t = strtok(line + 8, " \n"); t; t = strtok(NULL, " \n"))
        if (!strcmp(t, flag)) got = 1;
      break;
    }
  }
  fclose(f);
  return got;
}

/* A large block the scratch cache takes fresh from the default allocator in an update
 * is marked for transparent huge pages (world_scratch.c: on this project's VM a 4 KB
 * page's first touch costs some 15 us, and a frame at 10^5 boxes faulted in thousands).
 * Fails (0 != 1) without the mark; skipped where smaps or THP are missing. */
static void test_world_scratch_huge_pages(void **s) {
  (void)s;
  QKT_ONE_THREAD_TEST();
  FILE *thp = fopen("/sys/kernel/mm/transparent_hugepage/enabled", "r");
  if (!thp) skip();
  fclose(thp);
  qk_world_options_t o;
  qk_world_options_init(&o);
  qk_world_t *w;
  assert_int_equal(qk_world_new(&o, &w), QK_OK);
  const size_t big = (size_t)16 << 20;
  char *out = qk__realloc(&w->alloc, NULL, 0, big);
  assert_non_null(out);
  int base = vma_has_flag(out + big / 2, "hg");
  if (base < 0) {
    qk__free(&w->alloc, out, big);
    qk_world_free(w);
    skip();
  }
  qk__wscr_begin(w);
  char *in = qk__realloc(&w->alloc, NULL, 0, big);
  assert_non_null(in);
  memset(in, 1, big);
  assert_int_equal(vma_has_flag(in + big / 2, "hg"), 1);
  qk__free(&w->alloc, in, big);
  qk__wscr_end(w);
  qk__free(&w->alloc, out, big);
  qk_world_free(w);
}

/*
 * A sparse frame's rows when the slots are many: the one-thread counting sort packs slot
 * a and slot b into 32 bits up to 2^16 slots, and beyond sorts the keys whole by slot b
 * (both then leave the keys in order for the began / ended merge); the pairs, began and
 * ended in order against the sweep oracle (o_pairs, dense_check) every frame, with slots
 * up to 65 535 and up to 65 540, moves, and in some frames objects removed and added back
 * in their slots (the same keys, new pairs: ended and began). Boxes of 0.5 to 2 at 0.48 an
 * area unit and moving up to 0.5, as in the benchmark's uniform scene: about 1.5 pairs an
 * object, a third of them changing every frame. And 140 000 slots, beyond QK__WIDE_SLOTS
 * (2^17), where the keys are sorted by buckets of slots (sort_wide: small buckets by
 * insertion, the others by digits of slot b and then a), with eight boxes of side 12 among
 * them: rows of over 32 pairs. The pairs walked by qk_world_pairs and by the walk's own
 * loop (one worker) in order too: past 32 768 slots both ask for generations ahead.
 */
static void test_world_rows_slot_bits(void **s) {
  (void)s;
  QKT_ONE_THREAD_TEST();
  for (int big = 0; big < 3; big++) {
    qkt_rng_t r;
    qkt_rng_seed(&r, g_seed + 5150 + (uint64_t)big);
    qk_world_t *w;
    assert_int_equal(qk_world_new(NULL, &w), QK_OK);
    mirror_t m = {0};
    const size_t n = big == 2 ? 140000 : big ? 65540 : 65536;
    const double side = big == 2 ? 540 : 370;
    for (size_t i = 0; i < n; i++) {
      double bw = 0.5 + 1.5 * qkt_rng_unit(&r), bh = 0.5 + 1.5 * qkt_rng_unit(&r);
      if (big == 2 && i % 17500 == 0) bw = bh = 12;
      double x = qkt_rng_unit(&r) * (side - bw), y = qkt_rng_unit(&r) * (side - bh);
      m_add(w, &m, (qk_shape_t){QK_SHAPE_BOX, x, y, x + bw, y + bh});
    }
    qk_world_pair_t *prev = NULL;
    size_t np = 0;
    for (int f = 0; f < 5; f++) {
      for (size_t i = 0; f && i < m.n; i++) {
        if (qkt_rng_below(&r, 4) == 0) continue;
        qk_shape_t b = m.s[i];
        double dx = qkt_rng_range(&r, -0.5, 0.5), dy = qkt_rng_range(&r, -0.5, 0.5);
        b.x += dx, b.a += dx, b.y += dy, b.b += dy;
        m_move(w, &m, i, b);
      }
      if (f == 2 || f == 4) {
        /* 40 objects removed and added back where they were, last removed first: each in
         * its own slot again (the most recently freed is reused first) with the same
         * pairs' keys, which end and begin (a new object) */
        qk_shape_t gone[40];
        for (int k = 0; k < 40; k++) {
          size_t i = qkt_rng_below(&r, (uint32_t)m.n);
          gone[k] = m.s[i];
          assert_int_equal(qk_world_remove(w, m.h[i]), QK_OK);
          m.n--;
          m.h[i] = m.h[m.n], m.s[i] = m.s[m.n];
        }
        for (int k = 39; k >= 0; k--) m_add(w, &m, gone[k]);
      }
      dense_check(w, &m, &prev, &np, f);      /* (pairs, began, ended in order) */
      assert_true(np * 4 >= n && np < 4 * n); /* (the counting sort, short rows) */
      cbctx_t cb = {prev, np, 0, 1};
      assert_int_equal(qk_world_pairs(w, QK_PAIRS_ALL, cb_pair, &cb), QK_OK);
      assert_true(cb.ok && cb.i == np);
      /* (the walk's own loop, one worker: the same pairs in the same order) */
      cbctx_t cw = {prev, np, 0, 1};
      assert_int_equal(qk_world_pairs_parallel(w, QK_PAIRS_ALL, cb_pair_worker, &cw), QK_OK);
      assert_true(cw.ok && cw.i == np);
    }
    free(prev);
    free(m.h), free(m.s);
    qk_world_free(w);
  }
}

static void test_world_step_margin(void **s) {
  (void)s;
  QKT_ONE_THREAD_TEST();
  qkt_rng_t r;
  qkt_rng_seed(&r, g_seed + 9191);
  qk_world_t *w;
  assert_int_equal(qk_world_new(NULL, &w), QK_OK);
  mirror_t m = {0};
  enum { N = 400, FRAMES = 30 };
  double vx[N], vy[N];
  for (int i = 0; i < N; i++) {
    double e = (double)(1 + qkt_rng_below(&r, 4)) / 64;
    double x = (double)qkt_rng_below(&r, 20 * 64) / 64, y = (double)qkt_rng_below(&r, 20 * 64) / 64;
    m_add(w, &m, (qk_shape_t){QK_SHAPE_BOX, x, y, x + e, y + e});
    vx[i] = (qkt_rng_below(&r, 2) ? 0.25 : 0.1875) * (qkt_rng_below(&r, 2) ? 1 : -1);
    vy[i] = (qkt_rng_below(&r, 2) ? 0.25 : 0.1875) * (qkt_rng_below(&r, 2) ? 1 : -1);
  }
  qk_world_pair_t *prev = NULL;
  size_t np = 0, refiled = 0;
  for (int f = 0; f < FRAMES; f++) {
    for (size_t i = 0; f && i < m.n; i++) {
      qk_shape_t b = m.s[i];
      if (b.x + vx[i] < 0 || b.a + vx[i] > 24) vx[i] = -vx[i];
      if (b.y + vy[i] < 0 || b.b + vy[i] > 24) vy[i] = -vy[i];
      b.x += vx[i], b.a += vx[i], b.y += vy[i], b.b += vy[i];
      m_move(w, &m, i, b);
    }
    if (f >= 5) refiled += w->n_dirty; /* (none added or removed) */
    update_and_check(w, &m, &prev, &np, "step margin", f);
  }
  /* (measured: 0.09 a box a frame; 0.90 with the size's margin alone) */
  double rate = (double)refiled / ((double)N * (FRAMES - 5));
  if (getenv("QKT_VERBOSE")) printf("step margin: %.3f re-filings a box a frame\n", rate);
  if (!(rate < 0.5))
    fail_msg("seed %llu: %.2f re-filings a box a frame", (unsigned long long)g_seed, rate);

  /* A jump of 1000, then still: the cap bounds the level (the fat box at most 65 times its
   * extent e, so the level's square under 4 times that; 2^12 without the cap). */
  qk_shape_t b = m.s[0];
  const double e0 = b.a - b.x;
  b.x += 1000, b.a += 1000;
  m_move(w, &m, 0, b);
  update_and_check(w, &m, &prev, &np, "step margin (jump)", FRAMES);
  const qk__wobj_t *o = &w->obj[(uint32_t)m.h[0]];
  assert_true(ldexp(1, o->level) < 4 * 65 * e0);
  for (int f = 0; f < 3; f++) {
    m_move(w, &m, 0, m.s[0]);
    assert_int_equal(w->n_dirty, 0);
    update_and_check(w, &m, &prev, &np, "step margin (still)", FRAMES + 1 + f);
  }
  /* Grown to 16 in place, then shrunk back to 1/64: re-filed, at level 4 or coarser, then at
   * -4 or finer. (A box at level 2 or finer: the moving boxes are filed at level 2 for their
   * speed's margin, whose loose square, 8 wide, cannot hold the grown box; one of side 4
   * fits some of them and would stay, not shrinking past that level's rule.) */
  size_t g = 1;
  while (g < m.n && w->obj[(uint32_t)m.h[g]].level > 2) g++;
  assert_true(g < m.n);
  b = m.s[g];
  b.a = b.x + 16, b.b = b.y + 16;
  m_move(w, &m, g, b);
  assert_int_equal(w->n_dirty, 1);
  update_and_check(w, &m, &prev, &np, "step margin (grown)", FRAMES + 4);
  assert_true(w->obj[(uint32_t)m.h[g]].level >= 4);
  b.a = b.x + 1.0 / 64, b.b = b.y + 1.0 / 64;
  m_move(w, &m, g, b);
  assert_int_equal(w->n_dirty, 1);
  update_and_check(w, &m, &prev, &np, "step margin (shrunk)", FRAMES + 5);
  assert_true(w->obj[(uint32_t)m.h[g]].level <= -4);
  free(prev), free(m.h), free(m.s);
  qk_world_free(w);
}

/*
 * Allocation failure at each call of a one-thread frame that only moves objects, in a
 * sparse world (rows of a pair or two): its began / ended come from the merge without
 * branches (collide/world_pairs.c, diff_flat_nobranch), whose scratch failing falls back
 * to the merge with branches and whose lists failing to grow fail the update. A failed
 * update leaves the pairs, began and ended as they were; one that succeeds gives the same
 * lists, in the same order, as a world whose allocator never fails. Fails with the
 * fallback's merge left out (began and ended empty).
 */
static void test_world_nomem_moves(void **s) {
  (void)s;
  enum { N = 3000 };
  qkt_rng_t r;
  qkt_rng_seed(&r, g_seed + 61);
  qk_shape_t *sh = malloc(2 * N * sizeof *sh);
  /* (boxes of one size class, as the bench's uniform scene: one level, searched on the
   * grid, about 1.5 pairs an object) */
  const double side = sqrt(N / 0.48);
  for (int i = 0; i < N; i++) {
    double x = qkt_rng_unit(&r) * side, y = qkt_rng_unit(&r) * side;
    sh[i] = (qk_shape_t){QK_SHAPE_BOX, x, y, x + qkt_rng_range(&r, 0.5, 2),
                         y + qkt_rng_range(&r, 0.5, 2)};
    sh[N + i] = moved(&r, sh[i]);
  }
  qk_world_t *w0 = nomem_world(NULL, 1, sh, sh + N, N);
  assert_int_equal(qk_world_update(w0), QK_OK);
  size_t calls = 0, ok_after_fail = 0;
  for (size_t fail = 1; fail <= calls + 1; fail++) {
    qkt_alloc_t st;
    qk_allocator_t al = qkt_alloc_make(&st);
    qk_world_t *w = nomem_world(&al, 1, sh, sh + N, N);
    size_t before[3];
    for (int which = 0; which < 3; which++)
      qk_world_pairs_list(w, (qk_pairs_which_t)which, NULL, 0, &before[which]);
    qkt_alloc_arm(&st, calls ? fail : 0);
    qk_status_t rc = qk_world_update(w);
    if (!calls) calls = st.calls, fail = 0; /* the first round counts the calls */
    ok_after_fail += rc == QK_OK && st.failed;
    expect_update_outcome(w0, w, rc, before);
    qk_world_free(w);
    assert_int_equal(st.live_blocks, 0);
  }
  /* (failures the update survives: the merge's scratch, a list's shrink) */
  assert_true(ok_after_fail >= 1);
  size_t nb, ne;
  qk_world_pairs_list(w0, QK_PAIRS_BEGAN, NULL, 0, &nb);
  qk_world_pairs_list(w0, QK_PAIRS_ENDED, NULL, 0, &ne);
  assert_true(nb > 0 && ne > 0);
  qk_world_free(w0);
  free(sh);
}

/* The kNN batch's layout is the tree's (query.h): counts may be NULL and the unused slots
 * of a point's block get {QK_HANDLE_NONE, INFINITY}; they kept what the caller had there,
 * and a NULL counts was refused. A point that fails (NaN) gets count 0 and an unused block. */
static void test_world_knn_batch_layout(void **s) {
  (void)s;
  enum { K = 5 };
  qk_world_t *w;
  assert_int_equal(qk_world_new(NULL, &w), QK_OK);
  qk_handle_t h[3];
  for (int i = 0; i < 3; i++)
    assert_int_equal(qk_world_add(w, &(qk_shape_t){QK_SHAPE_POINT, 10.0 * i, 0, 0, 0}, 0, &h[i]),
                     QK_OK);
  assert_int_equal(qk_world_update(w), QK_OK);
  const qk_point_t ps[3] = {{0, 0}, {NAN, 0}, {21, 0}};
  qk_world_hit_t out[3 * K];
  size_t counts[3];
  memset(out, 0x5a, sizeof out);
  assert_int_equal(qk_world_knn_batch(w, ps, 3, K, out, counts), QK_ERR_NONFINITE);
  assert_int_equal(counts[0], 3);
  assert_int_equal(counts[1], 0);
  assert_int_equal(counts[2], 3);
  const qk_handle_t want[3][3] = {{h[0], h[1], h[2]}, {0}, {h[2], h[1], h[0]}};
  for (int i = 0; i < 3; i++)
    for (size_t k = 0; k < K; k++) {
      const qk_world_hit_t *o = &out[i * K + k];
      if (k < counts[i])
        assert_true(o->h == want[i][k]);
      else
        assert_true(o->h == QK_HANDLE_NONE && o->t == INFINITY);
    }
  memset(out, 0x5a, sizeof out);
  assert_int_equal(qk_world_knn_batch(w, ps + 2, 1, K, out, NULL), QK_OK);
  assert_true(out[0].h == h[2] && out[0].t == 1 && out[3].h == QK_HANDLE_NONE);
  /* Batches report their first error, in the order of the points (issue 11), on one
   * thread and on several: a NaN then a point beyond 2^100, and the other way round, in
   * one chunk of 256 and in chunks of different threads; they reported the last. */
  enum { N = 2000 };
  qk_point_t *many = malloc(N * sizeof *many), *to = malloc(N * sizeof *to);
  qk_world_hit_t *hits = malloc(N * K * sizeof *hits);
  assert_non_null(many), assert_non_null(to), assert_non_null(hits);
  const size_t at[3][2] = {{1, 3}, {5, 1500}, {1700, 1999}};
  for (unsigned threads = 1; threads <= 2; threads++) {
    qk_world_options_t wo;
    qk_world_options_init(&wo);
    wo.threads = threads;
    qk_world_t *wt;
    assert_int_equal(qk_world_new(&wo, &wt), QK_OK);
    for (int i = 0; i < 3; i++)
      assert_int_equal(qk_world_add(wt, &(qk_shape_t){QK_SHAPE_POINT, 10.0 * i, 0, 0, 0}, 0, &h[i]),
                       QK_OK);
    assert_int_equal(qk_world_update(wt), QK_OK);
    for (int c = 0; c < 3; c++)
      for (int order = 0; order < 2; order++) {
        for (size_t i = 0; i < N; i++)
          many[i] = (qk_point_t){(double)i, 1}, to[i] = (qk_point_t){(double)i, -1};
        size_t a = at[c][order], b = at[c][1 - order];
        many[a].x = NAN, many[b].y = 1e200; /* NaN first when order is 0 */
        qk_status_t want_st = a < b ? QK_ERR_NONFINITE : QK_ERR_LIMIT;
        if (qk_world_knn_batch(wt, many, N, K, hits, NULL) != want_st ||
            qk_world_raycast_batch(wt, many, to, N, hits) != want_st)
          fail_msg("threads %u, errors at %zu (NaN) and %zu (1e200): not the first's status",
                   threads, a, b);
      }
    qk_world_free(wt);
  }
  free(many), free(to), free(hits);
  qk_world_free(w);
}

/* qk_world_knn for k from 1 to beyond the number of objects (the large k are kept in a
 * heap, the small ones sorted by insertion) against brute force, object by object in
 * order: points and boxes at small integer coordinates (their distances are then exact
 * square roots of exact sums, the oracle's too: ties are exact), many coincident or at
 * equal distances, boxes holding the query point (distance 0), slots reused after
 * removals so that slot order is not insertion order; ties go by slot. From the middle
 * (the tree's search), a corner, a point outside; after an update and with adds and
 * removals pending; and the batch against single queries. */
typedef struct {
  ld d2;
  uint32_t slot;
  qk_handle_t h;
} knn_ref_t;

static int knn_ref_cmp(const void *a, const void *b) {
  const knn_ref_t *x = a, *y = b;
  if (x->d2 != y->d2) return x->d2 < y->d2 ? -1 : 1;
  return x->slot < y->slot ? -1 : x->slot > y->slot;
}

static ld knn_axis(double v, double lo, double hi) {
  return v < lo ? (ld)lo - v : v > hi ? (ld)v - hi : 0;
}

static void knn_check_large(qk_world_t *w, const qk_shape_t *sh, const qk_handle_t *hs, size_t n,
                            qk_point_t p, size_t k) {
  knn_ref_t *ref = malloc((n + 1) * sizeof *ref);
  size_t live = 0;
  for (size_t i = 0; i < n; i++) {
    if (hs[i] == QK_HANDLE_NONE) continue;
    const qk_shape_t *s = &sh[i];
    const double x1 = s->kind == QK_SHAPE_BOX ? s->a : s->x;
    const double y1 = s->kind == QK_SHAPE_BOX ? s->b : s->y;
    const ld dx = knn_axis(p.x, s->x, x1), dy = knn_axis(p.y, s->y, y1);
    ref[live++] = (knn_ref_t){dx * dx + dy * dy, (uint32_t)hs[i], hs[i]};
  }
  qsort(ref, live, sizeof *ref, knn_ref_cmp);
  qk_world_hit_t *got = malloc((k + 1) * sizeof *got);
  size_t ng = 0;
  assert_int_equal(qk_world_knn(w, p, k, got, &ng), QK_OK);
  assert_int_equal(ng, k < live ? k : live);
  for (size_t i = 0; i < ng; i++)
    if (got[i].h != ref[i].h || got[i].t != (double)sqrtl(ref[i].d2))
      fail_msg("knn from (%g, %g), k %zu of %zu objects: hit %zu is slot %u at %.17g, not slot "
               "%u at %.17g (seed %llu)",
               p.x, p.y, k, live, i, (unsigned)(uint32_t)got[i].h, got[i].t, ref[i].slot,
               (double)sqrtl(ref[i].d2), (unsigned long long)g_seed);
  free(got);
  free(ref);
}

static void test_world_knn_large_k(void **s) {
  (void)s;
  enum { N = 2400, MORE = 300 };
  qkt_rng_t r;
  qkt_rng_seed(&r, g_seed + 5151);
  qk_world_t *w;
  assert_int_equal(qk_world_new(NULL, &w), QK_OK);
  qk_shape_t *sh = malloc((N + MORE) * sizeof *sh);
  qk_handle_t *hs = malloc((N + MORE) * sizeof *hs);
  size_t n = 0;
  /* about a third boxes of integer sides 0 .. 3, the rest points, on a 40 x 40 grid */
  for (; n < N; n++) {
    const double x = qkt_rng_below(&r, 40), y = qkt_rng_below(&r, 40);
    const double sx = qkt_rng_below(&r, 4), sy = qkt_rng_below(&r, 4);
    sh[n] = qkt_rng_below(&r, 3) ? (qk_shape_t){QK_SHAPE_POINT, x, y, 0, 0}
                                 : (qk_shape_t){QK_SHAPE_BOX, x, y, x + sx, y + sy};
    assert_int_equal(qk_world_add(w, &sh[n], n, &hs[n]), QK_OK);
  }
  /* a quarter removed, as many added again (into the freed slots, in another order) */
  for (size_t i = 0; i < N / 4; i++) {
    const size_t j = qkt_rng_below(&r, N);
    if (hs[j] == QK_HANDLE_NONE) continue;
    assert_int_equal(qk_world_remove(w, hs[j]), QK_OK);
    hs[j] = QK_HANDLE_NONE;
  }
  for (size_t i = 0; i < N; i++)
    if (hs[i] == QK_HANDLE_NONE && qkt_rng_below(&r, 2))
      assert_int_equal(qk_world_add(w, &sh[i], i, &hs[i]), QK_OK);
  assert_int_equal(qk_world_update(w), QK_OK);
  const qk_point_t ps[] = {{20, 20}, {0, 0}, {-50, 17}, {13.5, 27}, {39, 2.25}};
  const size_t ks[] = {1, 2, 8, 31, 32, 33, 64, 100, 257, 1000, N - 700, N, N + 100};
  for (int round = 0; round < 2; round++) {
    for (size_t pi = 0; pi < sizeof ps / sizeof *ps; pi++)
      for (size_t ki = 0; ki < sizeof ks / sizeof *ks; ki++)
        knn_check_large(w, sh, hs, n, ps[pi], ks[ki]);
    if (round) break;
    /* pending: some added (past the last update) and removed */
    for (; n < N + MORE; n++) {
      const double x = qkt_rng_below(&r, 44), y = qkt_rng_below(&r, 44);
      sh[n] = (qk_shape_t){QK_SHAPE_POINT, x, y, 0, 0};
      assert_int_equal(qk_world_add(w, &sh[n], n, &hs[n]), QK_OK);
    }
    for (size_t i = 0; i < MORE; i++) {
      const size_t j = qkt_rng_below(&r, N + MORE);
      if (hs[j] == QK_HANDLE_NONE) continue;
      assert_int_equal(qk_world_remove(w, hs[j]), QK_OK);
      hs[j] = QK_HANDLE_NONE;
    }
  }
  /* the batch, with k beyond the number of objects, as single queries */
  enum { K = N + MORE + 7, NP = sizeof ps / sizeof *ps };
  qk_world_hit_t *bat = malloc((size_t)NP * K * sizeof *bat), *one = malloc(K * sizeof *one);
  size_t counts[NP];
  assert_int_equal(qk_world_knn_batch(w, ps, NP, K, bat, counts), QK_OK);
  for (size_t i = 0; i < NP; i++) {
    size_t n1;
    assert_int_equal(qk_world_knn(w, ps[i], K, one, &n1), QK_OK);
    assert_int_equal(counts[i], n1);
    for (size_t j = 0; j < n1; j++)
      assert_true(bat[i * K + j].h == one[j].h && bat[i * K + j].t == one[j].t);
  }
  free(bat), free(one);
  free(sh), free(hs);
  qk_world_free(w);
}

int main(void) {
  g_seed = qkt_seed(20261130);
  qkt_filters_from_env();
  const struct CMUnitTest tests[] = {
      cmocka_unit_test(test_world_uniform),
      cmocka_unit_test(test_world_knn_batch_layout),
      cmocka_unit_test(test_world_knn_large_k),
      cmocka_unit_test(test_world_clustered),
      cmocka_unit_test(test_world_dense_kept_scratch),
      cmocka_unit_test(test_world_dense_buckets),
      cmocka_unit_test(test_world_threads_ranges),
      cmocka_unit_test(test_world_mixed_sizes),
      cmocka_unit_test(test_world_all_kinds),
      cmocka_unit_test(test_world_huge),
      cmocka_unit_test(test_world_clustered_mixed_sizes),
      cmocka_unit_test(test_world_began_only),
      cmocka_unit_test(test_world_refile_in_place),
      cmocka_unit_test(test_world_bands_threads),
      cmocka_unit_test(test_world_bands_build_threads),
      cmocka_unit_test(test_world_began_ranges),
      cmocka_unit_test(test_world_refile_split),
      cmocka_unit_test(test_world_began_general),
      cmocka_unit_test(test_world_bands_edges),
      cmocka_unit_test(test_world_bands_stop_lanes),
      cmocka_unit_test(test_world_grid_levels),
      cmocka_unit_test(test_world_few_movers),
      cmocka_unit_test(test_world_refile_sort),
      cmocka_unit_test(test_world_fbox_only_bands),
      cmocka_unit_test(test_world_prefilter_and_sort),
      cmocka_unit_test(test_world_grid_undecided_runs),
      cmocka_unit_test(test_world_touching),
      cmocka_unit_test(test_world_one_ulp_off),
      cmocka_unit_test(test_world_query_grid_touching),
      cmocka_unit_test(test_world_move_out_of_loose),
      cmocka_unit_test(test_world_raycast_batch),
      cmocka_unit_test(test_world_boxes_points_queries),
      cmocka_unit_test(test_world_query_tree),
      cmocka_unit_test(test_world_query_tree_threads),
      cmocka_unit_test(test_world_crowded_cells),
      cmocka_unit_test(test_world_query_wide_span),
      cmocka_unit_test(test_world_query_far_out),
      cmocka_unit_test(test_world_query_nomem),
      cmocka_unit_test(test_world_stale_handles),
      cmocka_unit_test(test_world_threads_frames),
      cmocka_unit_test(test_world_thread_min_sides),
      cmocka_unit_test(test_world_move_batch_errors),
      cmocka_unit_test(test_world_move_box_edges),
      cmocka_unit_test(test_world_pair_bytes),
      cmocka_unit_test(test_world_bytes_exact),
      cmocka_unit_test(test_world_most_pairs_change),
      cmocka_unit_test(test_world_sort_wide_keys),
      cmocka_unit_test(test_world_ray_tangent_end),
      cmocka_unit_test(test_world_churn_memory),
      cmocka_unit_test(test_world_churn_memory_large),
      cmocka_unit_test(test_world_generation_wrap),
      cmocka_unit_test(test_world_ray_knn_rounding),
      cmocka_unit_test(test_world_nomem),
      cmocka_unit_test(test_world_nomem_threads),
      cmocka_unit_test(test_world_nomem_threads_warm),
      cmocka_unit_test(test_world_scratch_kept),
      cmocka_unit_test(test_world_nomem_began_threads),
      cmocka_unit_test(test_world_nomem_began),
      cmocka_unit_test(test_world_threads),
      cmocka_unit_test(test_world_threads_detach),
      cmocka_unit_test(test_world_threads_fork),
      cmocka_unit_test(test_world_concurrent_readers),
      cmocka_unit_test(test_world_rows_kept_falling),
      cmocka_unit_test(test_world_step_margin),
      cmocka_unit_test(test_world_scratch_huge_pages),
      cmocka_unit_test(test_world_rows_slot_bits),
      cmocka_unit_test(test_world_nomem_moves),
  };
  return cmocka_run_group_tests(tests, NULL, NULL);
}
