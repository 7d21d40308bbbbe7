/*
 * Test plan for the lattice modes' block arena (mesh/arena.c):
 *  - the arena as an allocator, against a shadow of every block: a seeded random run of
 *    allocations, reallocations (growing and shrinking, across the 64 KB line between
 *    libc's blocks and the arena's, across chunks) and frees over 48 slots. Every live
 *    block is filled with its own byte; sampled bytes of every block are checked after
 *    each step (two live blocks that overlap overwrite each other's bytes), and a
 *    reallocated block must keep its first min(old, new) bytes. Then the arena is sealed
 *    and the run goes on (new blocks from libc, the arena's blocks still freed and
 *    moved). Under AddressSanitizer the chunks are malloc's, so leaks show;
 *  - the mesher with the arena (no allocator given) and without (a counting allocator):
 *    the bench's octagons at U = 256 in the book's mode and scaled by 2^-10 in the dyadic
 *    mode, every vertex bit, triangle, component, statistic but the seconds, and the
 *    .node/.ele/.poly text the same; the arena ran where it is available; writing the
 *    mesh from the arena's mesh works (its sealed arena passes new blocks to libc);
 *  - the same for the general mode, on the bench's kind of random polygon with holes (a
 *    star-shaped outer ring of 512 corners, star-shaped holes inside, on the grid 2^-20);
 *  - in each of those, the chunks a freed mesh leaves kept for the next (qk_mesh_trim):
 *    where the arena runs, freeing the arena's mesh keeps some, they are filled with
 *    garbage, and the same input meshed again takes kept chunks (fewer kept bytes after)
 *    and gives the same mesh, bit for bit: nothing may read a block before writing it;
 *    qk_mesh_trim() leaves none kept.
 */
#define _DEFAULT_SOURCE /* open_memstream */
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "mesh/mesh_internal.h"
#include "qk_test.h"

#define SLOTS 48

typedef struct slot {
  unsigned char *p;
  size_t n;
  unsigned char v;
} slot_t;

/* Sampled bytes of s: every 509th, and the last. */
static void check_slot(const slot_t *s, size_t upto, unsigned char v, int step) {
  for (size_t i = 0; i < upto; i += 509)
    if (s->p[i] != v)
      fail_msg("step %d: byte %zu of a %zu-byte block is %u, not %u", step, i, s->n, s->p[i], v);
  if (upto && s->p[upto - 1] != v) fail_msg("step %d: last byte of a block changed", step);
}

/* A size: mostly libc's (below 64 KB) or one chunk's, now and then several chunks. */
static size_t draw_size(qkt_rng_t *r) {
  uint32_t k = qkt_rng_below(r, 16);
  if (k < 5) return 1 + qkt_rng_below(r, 60000);
  if (k < 15) return 60000 + qkt_rng_below(r, 1200000);
  return 2000000 + qkt_rng_below(r, 3000000);
}

static void run_blocks(qk__mesh_arena_t *ar, slot_t *sl, qkt_rng_t *r, int steps, int *vgen) {
  for (int step = 0; step < steps; step++) {
    slot_t *s = &sl[qkt_rng_below(r, SLOTS)];
    if (!s->p) {
      s->n = draw_size(r);
      s->p = qk__mesh_arena_fn(ar, NULL, 0, s->n);
      assert_non_null(s->p);
    } else if (qkt_rng_below(r, 3) == 0) {
      qk__mesh_arena_fn(ar, s->p, s->n, 0);
      s->p = NULL;
      continue;
    } else {
      size_t n = qkt_rng_below(r, 2) ? draw_size(r) : s->n + 1 + qkt_rng_below(r, 100000);
      unsigned char *q = qk__mesh_arena_fn(ar, s->p, s->n, n);
      assert_non_null(q);
      s->p = q;
      check_slot(s, n < s->n ? n : s->n, s->v, step);
      s->n = n;
    }
    s->v = (unsigned char)(1 + (*vgen)++ % 251);
    memset(s->p, s->v, s->n);
    for (int j = 0; j < SLOTS; j++)
      if (sl[j].p) check_slot(&sl[j], sl[j].n, sl[j].v, step);
  }
}

static void test_mesh_arena_blocks(void **state) {
  (void)state;
  uint64_t seed = qkt_seed(17);
  for (int round = 0; round < 3; round++) {
    qkt_rng_t r;
    qkt_rng_seed(&r, seed + (uint64_t)round);
    qk__mesh_arena_t *ar = qk__mesh_arena_new();
    assert_non_null(ar);
    slot_t sl[SLOTS];
    memset(sl, 0, sizeof sl);
    int vgen = 0;
    run_blocks(ar, sl, &r, 600, &vgen);
    qk__mesh_arena_seal(ar);
    run_blocks(ar, sl, &r, 300, &vgen);
    for (int j = 0; j < SLOTS; j++)
      if (sl[j].p) qk__mesh_arena_fn(ar, sl[j].p, sl[j].n, 0);
    qk__mesh_arena_free(ar);
  }
}

/* The bench's octagons (bench/data.cpp's layout, own generator): g x g cells of U / g,
 * one octagon each, half-width a in [cell/4, cell/4 + cell/8], corners cut by a/2. */
static size_t octagons(unsigned U, unsigned g, qkt_rng_t *r, double *xy, uint32_t *seg) {
  size_t nv = 0;
  long cell = (long)(U / g);
  for (unsigned i = 0; i < g; i++)
    for (unsigned j = 0; j < g; j++) {
      long a = cell / 4 + (long)qkt_rng_below(r, (uint32_t)(cell / 8 + 1)), b = a / 2;
      long slack = cell / 2 - a - 2;
      long cx = (long)i * cell + cell / 2 +
                (slack > 0 ? (long)qkt_rng_below(r, (uint32_t)(2 * slack + 1)) - slack : 0);
      long cy = (long)j * cell + cell / 2 +
                (slack > 0 ? (long)qkt_rng_below(r, (uint32_t)(2 * slack + 1)) - slack : 0);
      long px[8] = {cx - a + b, cx + a - b, cx + a, cx + a, cx + a - b, cx - a + b, cx - a, cx - a};
      long py[8] = {cy - a, cy - a, cy - a + b, cy + a - b, cy + a, cy + a, cy + a - b, cy - a + b};
      for (int k = 0; k < 8; k++) {
        xy[2 * (nv + k)] = (double)px[k], xy[2 * (nv + k) + 1] = (double)py[k];
        seg[2 * (nv + k)] = (uint32_t)(nv + k),
                      seg[2 * (nv + k) + 1] = (uint32_t)(nv + (k + 1) % 8);
      }
      nv += 8;
    }
  return nv;
}

/* The mesh's text in .node, .ele and .poly, concatenated; freed by the caller. */
static char *mesh_text(const qk_mesh_t *m, size_t *len) {
  char *buf = NULL;
  FILE *f = open_memstream(&buf, len);
  assert_non_null(f);
  assert_int_equal(qk_mesh_write_node(m, f, 0), QK_OK);
  assert_int_equal(qk_mesh_write_ele(m, f, 0), QK_OK);
  assert_int_equal(qk_mesh_write_poly(m, f, 0), QK_OK);
  fclose(f);
  return buf;
}

/* Mesh a and mesh b equal: every vertex bit, triangle, component, statistic but the
 * seconds, and the .node/.ele/.poly text. */
static void assert_same(const qk_mesh_t *a, const qk_mesh_t *b) {
  size_t nva, nvb, nta, ntb;
  const double *va = qk_mesh_vertices(a, &nva), *vb = qk_mesh_vertices(b, &nvb);
  const uint32_t *ta = qk_mesh_triangles(a, &nta), *tb = qk_mesh_triangles(b, &ntb);
  assert_true(nta > 30000);
  assert_int_equal(nva, nvb);
  assert_int_equal(nta, ntb);
  assert_memory_equal(va, vb, 2 * nva * sizeof *va);
  assert_memory_equal(ta, tb, 3 * nta * sizeof *ta);
  assert_memory_equal(qk_mesh_triangle_components(a, NULL), qk_mesh_triangle_components(b, NULL),
                      nta * sizeof(uint32_t));
  qk_mesh_stats_t sa, sb;
  qk_mesh_stats(a, &sa), qk_mesh_stats(b, &sb);
  sa.seconds_validate = sa.seconds_subdivide = sa.seconds_balance = sa.seconds_triangulate = 0;
  sb.seconds_validate = sb.seconds_subdivide = sb.seconds_balance = sb.seconds_triangulate = 0;
  assert_memory_equal(&sa, &sb, sizeof sa);
  size_t la, lb;
  char *xa = mesh_text(a, &la), *xb = mesh_text(b, &lb);
  assert_int_equal(la, lb);
  assert_memory_equal(xa, xb, la);
  free(xa), free(xb);
}

static void same_mesh(const qk_poly_t *p, qk_mesh_options_t o) {
  qk_mesh_t *ma = NULL, *mb = NULL;
  qk_mesh_error_t err;
  o.allocator = NULL;
  if (qk_mesh_generate(p, &o, &ma, &err)) fail_msg("%s", err.message);
  qkt_alloc_t st;
  qk_allocator_t a = qkt_alloc_make(&st);
  o.allocator = &a;
  if (qk_mesh_generate(p, &o, &mb, &err)) fail_msg("%s", err.message);
  assert_true((ma->arena != NULL) == (qk__mesh_arena_available() != 0));
  assert_null(mb->arena);
  assert_same(ma, mb);
  qk_mesh_free(ma);
  /* Again with the arena, from the kept chunks filled with garbage. */
  const size_t kept = qk__mesh_arena_kept_bytes();
  assert_true((kept > 0) == (qk__mesh_arena_available() != 0));
  qk__mesh_arena_poison_kept(0xa5);
  o.allocator = NULL;
  if (qk_mesh_generate(p, &o, &ma, &err)) fail_msg("%s", err.message);
  if (kept) assert_true(qk__mesh_arena_kept_bytes() < kept);
  assert_same(ma, mb);
  qk_mesh_free(ma);
  qk_mesh_free(mb);
  assert_int_equal(st.live_blocks, 0);
  qk_mesh_trim();
  assert_int_equal(qk__mesh_arena_kept_bytes(), 0);
}

static void test_mesh_arena_same_mesh(void **state) {
  (void)state;
  enum { U = 256, G = 4, NV = 8 * G * G };
  double xy[2 * (NV + 4)];
  uint32_t seg[2 * (NV + 4)];
  qkt_rng_t r;
  qkt_rng_seed(&r, 259);
  size_t nv = octagons(U, G, &r, xy, seg);
  qk_poly_t *p = NULL;
  assert_int_equal(qk_poly_from_arrays(xy, nv, seg, nv, NULL, 0, NULL, &p, NULL), QK_OK);
  qk_mesh_options_t o;
  qk_mesh_options_init(&o);
  o.size = U;
  same_mesh(p, o);
  qk_poly_free(p);
  /* The dyadic mode: scaled by 2^-10, one lattice step in, inside the domain square. */
  const double s = ldexp(1, -10), side = (U + 2) * s;
  double sq[8] = {0, 0, side, 0, side, side, 0, side};
  for (size_t i = 0; i < 2 * nv; i++) xy[i] = (xy[i] + 1) * s;
  for (size_t i = 0; i < 8; i++) xy[2 * nv + i] = sq[i];
  for (uint32_t k = 0; k < 4; k++)
    seg[2 * (nv + k)] = (uint32_t)nv + k, seg[2 * (nv + k) + 1] = (uint32_t)nv + (k + 1) % 4;
  assert_int_equal(qk_poly_from_arrays(xy, nv + 4, seg, nv + 4, NULL, 0, NULL, &p, NULL), QK_OK);
  qk_mesh_options_init(&o);
  o.mode = QK_MESH_DYADIC;
  o.max_size = 8 * s;
  same_mesh(p, o);
  qk_poly_free(p);
}

/* A star-shaped ring of k corners at radius 0.8R to R around (cx, cy), on the grid 2^-20,
 * appended to xy / seg; returns the new vertex count. */
static size_t star(double cx, double cy, double R, size_t k, qkt_rng_t *r, double *xy,
                   uint32_t *seg, size_t nv) {
  for (size_t i = 0; i < k; i++) {
    double th = 2 * 3.14159265358979323846 * ((double)i + 0.8 * qkt_rng_unit(r)) / (double)k;
    double rho = R * (0.8 + 0.2 * qkt_rng_unit(r));
    xy[2 * (nv + i)] = nearbyint(ldexp(cx + rho * cos(th), 20)) * 0x1p-20;
    xy[2 * (nv + i) + 1] = nearbyint(ldexp(cy + rho * sin(th), 20)) * 0x1p-20;
    seg[2 * (nv + i)] = (uint32_t)(nv + i), seg[2 * (nv + i) + 1] = (uint32_t)(nv + (i + 1) % k);
  }
  return nv + k;
}

static void test_mesh_arena_general(void **state) {
  (void)state;
  enum { N = 512, CELLS = 6, CAP = N + CELLS * CELLS * 13 };
  double xy[2 * CAP], holes[2 * CELLS * CELLS];
  uint32_t seg[2 * CAP];
  qkt_rng_t r;
  qkt_rng_seed(&r, 7);
  size_t nv = star(0, 0, 1, N, &r, xy, seg, 0), nh = 0;
  const double w = 1.4 / CELLS;
  for (int i = 0; i < CELLS; i++)
    for (int j = 0; j < CELLS; j++) {
      double cx = -0.7 + (i + 0.5) * w, cy = -0.7 + (j + 0.5) * w;
      if (cx * cx + cy * cy > 0.6 * 0.6 || qkt_rng_unit(&r) < 0.5) continue;
      nv = star(cx, cy, 0.3 * w, 5 + qkt_rng_below(&r, 8), &r, xy, seg, nv);
      holes[2 * nh] = nearbyint(ldexp(cx, 20)) * 0x1p-20;
      holes[2 * nh + 1] = nearbyint(ldexp(cy, 20)) * 0x1p-20, nh++;
    }
  assert_true(nh > 0);
  qk_poly_t *p = NULL;
  assert_int_equal(qk_poly_from_arrays(xy, nv, seg, nv, holes, nh, NULL, &p, NULL), QK_OK);
  qk_mesh_options_t o;
  qk_mesh_options_init(&o);
  o.mode = QK_MESH_GENERAL;
  o.max_size = 2.0 / 128;
  same_mesh(p, o);
  qk_poly_free(p);
}

int main(void) {
  const struct CMUnitTest tests[] = {
      cmocka_unit_test(test_mesh_arena_blocks),
      cmocka_unit_test(test_mesh_arena_same_mesh),
      cmocka_unit_test(test_mesh_arena_general),
  };
  return cmocka_run_group_tests(tests, NULL, NULL);
}
