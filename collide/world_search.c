/*
 * The world's pair search (see collide/world.c for the design): every overlapping pair of
 * the order packed by the update, as unsorted 64-bit keys.
 *
 * Each cell's objects meet (1) the objects of their own level in the same and the
 * neighbouring cells, found by walking the sorted cells, and (2) the objects of every
 * finer level, found from the coarser object's side: its box is walked over the finer
 * level's sorted cells row by row (a row index gives each row's cells at once), so the
 * candidates are the finer objects near the box, not the coarse cell's whole loose square;
 * and the finer cells whose loose squares lie inside a box object are recorded whole,
 * without a test (most of the pairs of a large object with small ones). The rest are
 * tested four at a time on float boxes, and decided exactly when the floats cannot.
 */
#include <stdatomic.h>
#include <stddef.h>
#include <stdlib.h>
#include <string.h>

#include "collide/world_internal.h"
#include "index/inline.h"

#if defined(__SSE2__)
#include <emmintrin.h>
#endif

/* An occupied level: its cells [first, end), rows cy0 .. cy1, the box around its objects,
 * and (when its rows are not too many for its cells) a row index: rf[y - cy0] is the first
 * cell of a row at or after y, for y in [cy0, cy1 + 1]. */
typedef struct lvinfo {
  int l;
  uint32_t first, end, n_obj;
  int32_t cy0, cy1;
  const uint32_t *rf;
  qk_box_t box;
  int other; /* its cells find pairs with other levels (descend or look up) */
} lvinfo_t;

/* One worker: the pairs it found. Workers take chunks of cells in turn (next). */
typedef struct share {
  const qk_world_t *w;
  const qk__wpack_t *pk;
  qk__kvec_t out;
  const qk_allocator_t *alloc;
  int nomem;
  const lvinfo_t *lv; /* the occupied levels, ascending */
  int n_levels;
  const uint32_t *chunk; /* chunk i: cells (or bands) [chunk[i], chunk[i + 1]) */
  unsigned n_chunks;
  atomic_uint *next;
  const struct bands *bd; /* the bands, when the search is by bands */
  int ax; /* every object's float box is exact: the runs need not check (run_keys) */
} share_t;

/* Room for `more` keys after the found ones; 0 when memory ran short. */
/* Beyond the room asked for, the keys' buffer always has QK__KSLACK places more: the
 * grid's runs write each group's four candidate keys whatever the lanes kept (run_keys),
 * one place past the kept ones at most. */
#define QK__KSLACK 4
static int kv_reserve(share_t *s, size_t more) {
  qk__kvec_t *p = &s->out;
  more += QK__KSLACK;
  if (p->cap >= p->n && p->cap - p->n >= more) return 1;
  size_t cap = p->cap ? p->cap * 2 : 256;
  if (cap < p->n + more) cap = p->n + more;
  uint64_t *v = qk__realloc(s->alloc, p->v, p->cap * sizeof *v, cap * sizeof *v);
  if (!v) return 0;
  p->v = v;
  p->cap = cap;
  return 1;
}

/* Where the keys go, in locals for the loops of the grid's search (the count stored in
 * s->out through the keys' own type would be reloaded after every key written): the next
 * key and the end of the room. s->out.v is never NULL here (run_share reserves first). */
typedef struct kc {
  uint64_t *v, *end;
} kc_t;
static inline kc_t kc_open(const share_t *s) {
  return (kc_t){s->out.v + s->out.n, s->out.v + s->out.cap - QK__KSLACK};
}
static inline void kc_close(share_t *s, const kc_t *k) { s->out.n = (size_t)(k->v - s->out.v); }
/* Room for `more` keys after k->v; 0 when memory ran short. */
static __attribute__((noinline)) int kc_grow(share_t *s, kc_t *k, size_t more) {
  kc_close(s, k);
  if (!kv_reserve(s, more)) return 0;
  *k = kc_open(s);
  return 1;
}

static inline int boxes_meet(const qk_box_t *a, const qk_box_t *b) {
  return a->xmin <= b->xmax && b->xmin <= a->xmax && a->ymin <= b->ymax && b->ymin <= a->ymax;
}

/* The objects of slots i and j overlap, exactly. (Not inlined: the rare path, and inlined
 * it takes the registers of the four-wide loop that calls it.) */
__attribute__((noinline)) int qk__world_objects_meet(const qk_world_t *w, uint32_t i, uint32_t j) {
  const qk__wobj_t *p = &w->obj[i], *q = &w->obj[j];
  if ((p->flags & QK__WKIND) == QK_SHAPE_BOX && (q->flags & QK__WKIND) == QK_SHAPE_BOX)
    return p->x <= q->a && q->x <= p->a && p->y <= q->b && q->y <= p->b;
  /* (a disc's box is rounded outward, which costs more than the box test saves: the
   * float boxes met, and the doubles' rarely do not) */
  if ((p->flags & QK__WKIND) != QK_SHAPE_DISC && (q->flags & QK__WKIND) != QK_SHAPE_DISC) {
    qk_box_t pb = qk__wbox(p), qb = qk__wbox(q);
    if (!boxes_meet(&pb, &qb)) return 0;
  }
  qk_shape_t ps = qk__wshape(p), qs = qk__wshape(q);
  return qk__shapes_overlap(&ps, &qs);
}

/* The key of the pair of slot a (whose key half is ha = a << 32) and slot b. */
static inline uint64_t pair_key(uint32_t a, uint64_t ha, uint32_t b) {
  /* The smaller of the two ways round, without a branch: objects within a cell are in
   * no slot order, so which slot is smaller is a coin toss the branch predictor lost
   * about half the time. */
  const uint64_t k1 = ha | b, k2 = (uint64_t)b << 32 | a;
  return k1 < k2 ? k1 : k2;
}

/*
 * The box prefilter. The boxes are copied as floats in the order, four objects to a
 * group (16 floats: 4 xmin, 4 ymin, 4 xmax, 4 ymax; lanes past the last object hold an
 * empty box), so one object is compared with four at once. Rounding to float is
 * monotone, so u <= v implies (float)u <= (float)v: every comparison of the box test
 * that holds in doubles holds in floats, and the prefilter never drops a pair whose
 * boxes meet. What it keeps is decided exactly (qk__world_objects_meet), unless both boxes are
 * boxes whose floats are their doubles (fexact): the float test is then the exact one.
 */
#if defined(__SSE2__)
typedef struct probe {
  __m128 x0, y0, x1, y1;
} probe_t;
static inline probe_t probe_of(const float *me) {
  return (probe_t){_mm_set1_ps(me[0]), _mm_set1_ps(me[4]), _mm_set1_ps(me[8]), _mm_set1_ps(me[12])};
}
/* Lanes of group g whose float boxes meet the probe's box: a 4-bit mask. */
static inline unsigned group_hits(const float *g, const probe_t *p) {
  __m128 m =
      _mm_and_ps(_mm_cmple_ps(_mm_loadu_ps(g), p->x1), _mm_cmple_ps(p->x0, _mm_loadu_ps(g + 8)));
  m = _mm_and_ps(m, _mm_and_ps(_mm_cmple_ps(_mm_loadu_ps(g + 4), p->y1),
                               _mm_cmple_ps(p->y0, _mm_loadu_ps(g + 12))));
  return (unsigned)_mm_movemask_ps(m);
}
#else
typedef struct probe {
  float x0, y0, x1, y1;
} probe_t;
static inline probe_t probe_of(const float *me) { return (probe_t){me[0], me[4], me[8], me[12]}; }
static inline unsigned group_hits(const float *g, const probe_t *p) {
  unsigned bits = 0;
  for (int k = 0; k < 4; k++)
    bits |=
        (unsigned)(g[k] <= p->x1 && p->x0 <= g[8 + k] && g[4 + k] <= p->y1 && p->y0 <= g[12 + k])
        << k;
  return bits;
}
#endif

/* Object k of the order (its lane in the float groups). */
static inline const float *lane_of(const float *f, uint32_t k) {
  return f + (size_t)(k >> 2) * 16 + (k & 3);
}

/* One object as the searches use it: its slot, its key half, its float box broadcast,
 * and whether its float box is exact. */
typedef struct me {
  probe_t p;
  uint64_t hs;
  uint32_t slot;
  uint8_t exact;
} me_t;

static inline me_t me_of(const share_t *s, uint32_t k) {
  uint32_t slot = s->w->order[k];
  return (me_t){probe_of(lane_of(s->pk->fgrp, k)), (uint64_t)slot << 32, slot, s->pk->fexact[k]};
}

/* test_run's rest from a lane whose pair the float boxes cannot decide: lanes `bits` of
 * group q (the first of them that lane), then groups up to qe (the last masked by
 * `last`), each pair decided exactly where it must be. Returns past the keys kept. */
#if defined(__SSE2__)
#define QK__PROBE_ARGS __m128 p0, __m128 p1, __m128 p2, __m128 p3
#define QK__PROBE_PASS(p) (p).x0, (p).y0, (p).x1, (p).y1
#else
#define QK__PROBE_ARGS float p0, float p1, float p2, float p3
#define QK__PROBE_PASS(p) (p).x0, (p).y0, (p).x1, (p).y1
#endif
static __attribute__((noinline)) uint64_t *test_run_exact(share_t *s, uint32_t slot, unsigned ek,
                                                          QK__PROBE_ARGS, uint32_t q, unsigned bits,
                                                          uint32_t qe, unsigned last, uint64_t *v) {
  const probe_t p = {p0, p1, p2, p3}; /* (the probe apart: passed in registers) */
  const uint64_t hs = (uint64_t)slot << 32;
  const float *fg = s->pk->fgrp;
  const uint32_t *ord = s->w->order;
  const uint8_t *fx = s->pk->fexact;
  for (;;) {
    while (bits) {
      uint32_t j = q * 4 + (uint32_t)__builtin_ctz(bits);
      bits &= bits - 1;
      uint32_t sj = ord[j];
      *v = pair_key(slot, hs, sj);
      v += (ek & fx[j]) ? 1 : qk__world_objects_meet(s->w, slot, sj);
    }
    if (q == qe) return v;
    q++;
    bits = group_hits(fg + (size_t)q * 16, &p);
    if (q == qe) bits &= last;
  }
}

/* The pairs of the object of slot `slot` (key half hs, float box exact when ek, broadcast
 * in p) with the objects at order positions [lo, hi) (lo < hi): the first and last groups
 * masked to the range. The keys are written at v, which has room for hi - lo of them, and
 * kept when the pair is decided; returns past the kept ones. The loop makes no call while
 * the float boxes decide (both exact: every box of the benchmark's scenes), so the probe
 * stays in registers (a call would clobber them all, every group reloading it from the
 * stack); the first pair they cannot decide hands the rest to test_run_exact. */
#if defined(__SSE2__)
/* Where a group's lanes 1, 2 and 3 are stored, and how far the keys move on, for each
 * mask of lanes kept: lane i goes after the kept lanes before it (lane 0 at the start).
 * Read from a table, the places cost a load each, where computed from the mask's bits
 * they cost some ten instructions a group (two in three of which keep nothing). */
static const uint8_t lane_place[16][4] = {{0, 0, 0, 0}, {1, 1, 1, 1}, {0, 1, 1, 1}, {1, 2, 2, 2},
                                          {0, 0, 1, 1}, {1, 1, 2, 2}, {0, 1, 2, 2}, {1, 2, 3, 3},
                                          {0, 0, 0, 1}, {1, 1, 1, 2}, {0, 1, 1, 2}, {1, 2, 2, 3},
                                          {0, 0, 1, 2}, {1, 1, 2, 3}, {0, 1, 2, 3}, {1, 2, 3, 4}};
/* A group's four keys (the probe's slot sv above the lanes' og) stored at v, those of
 * lanes `bits` kept; returns past them. */
static QK__ALWAYS_INLINE uint64_t *group_keys(uint64_t *v, const uint32_t *og, __m128i sv,
                                              unsigned bits) {
  const __m128i o = _mm_loadu_si128((const __m128i *)og);
  const __m128i k01 = _mm_unpacklo_epi32(o, sv), k23 = _mm_unpackhi_epi32(o, sv);
  const uint8_t *at = lane_place[bits];
  _mm_storel_epi64((__m128i *)v, k01);
  _mm_storeh_pd((double *)(v + at[0]), _mm_castsi128_pd(k01));
  _mm_storel_epi64((__m128i *)(v + at[1]), k23);
  _mm_storeh_pd((double *)(v + at[2]), _mm_castsi128_pd(k23));
  return v + at[3];
}
/* With SSE2 a group's four keys are made and stored whatever its lanes that met, each
 * store's place moved on by its lane's bit: no branch on which lanes met, which about
 * one group in three has, at random (perf: the run loop's branches on the lanes' bits
 * were the search's most mispredicted). Each lane's key is this probe's slot above the
 * lane's, either way round: run_share puts every key the right way round in one pass
 * once its cells are done (a key a pair costs fewer instructions there than the smaller
 * and larger slot of every lane of every group tested, two in three of which keep no
 * key). The four places written lie within the kept keys and one place past them
 * (QK__KSLACK). The order's
 * lanes past its end are read (the order and the exactness bytes have room for them, see
 * qk__world_reorder) and masked off. A lane whose pair the float boxes cannot decide
 * (this probe's or its float box not exact) hands the group on to test_run_exact. */
static QK__ALWAYS_INLINE uint64_t *run_keys(share_t *s, const float *fg, const uint32_t *ord,
                                            const uint8_t *fx, uint32_t slot, uint64_t hs,
                                            unsigned ek, probe_t p, uint32_t lo, uint32_t hi,
                                            uint64_t *v, const int ax) {
  (void)hs;
  /* (the groups and their lanes' slots walked by pointers, the last group known by its
   * place) */
  const float *g = fg + (size_t)(lo >> 2) * 16, *const ge = fg + (size_t)((hi - 1) >> 2) * 16;
  const uint32_t *og = ord + (size_t)(lo >> 2) * 4;
  unsigned bits = group_hits(g, &p) & ~((1u << (lo & 3)) - 1) & 15u;
  const unsigned last = (2u << ((hi - 1) & 3)) - 1, ekm = ek ? 15u : 0u;
  const __m128i sv = _mm_set1_epi32((int)slot);
  if (ax) {
    /* (the groups before the last, then the last one masked: no other group pays for the
     * mask) */
    for (; g != ge; g += 16, og += 4) {
      v = group_keys(v, og, sv, bits);
      bits = group_hits(g + 16, &p);
    }
    return group_keys(v, og, sv, bits & last);
  }
  for (;; g += 16, og += 4, bits = group_hits(g, &p)) {
    if (g == ge) bits &= last;
    const uint32_t q = (uint32_t)((size_t)(g - fg) / 16), qe = (uint32_t)((size_t)(ge - fg) / 16);
    uint32_t f4; /* the lanes' exactness bytes (0 or 1), gathered into four bits */
    memcpy(&f4, fx + (size_t)q * 4, sizeof f4);
    if (bits & ~((f4 * 0x01020408u) >> 24 & ekm))
      return test_run_exact(s, slot, ek, QK__PROBE_PASS(p), q, bits, qe, last, v);
    v = group_keys(v, og, sv, bits);
    if (g == ge) return v;
  }
}
#else
static QK__ALWAYS_INLINE uint64_t *run_keys(share_t *s, const float *fg, const uint32_t *ord,
                                            const uint8_t *fx, uint32_t slot, uint64_t hs,
                                            unsigned ek, probe_t p, uint32_t lo, uint32_t hi,
                                            uint64_t *v, const int ax) {
  uint32_t q = lo >> 2, qe = (hi - 1) >> 2;
  unsigned bits = group_hits(fg + (size_t)q * 16, &p) & ~((1u << (lo & 3)) - 1) & 15u;
  const unsigned last = (2u << ((hi - 1) & 3)) - 1;
  for (;;) {
    if (q == qe) bits &= last;
    while (bits) {
      uint32_t j = q * 4 + (uint32_t)__builtin_ctz(bits);
      if (!ax && !(ek & fx[j]))
        return test_run_exact(s, slot, ek, QK__PROBE_PASS(p), q, bits, qe, last, v);
      bits &= bits - 1;
      *v++ = pair_key(slot, hs, ord[j]);
    }
    if (q == qe) return v;
    q++;
    bits = group_hits(fg + (size_t)q * 16, &p);
  }
}
#endif

/* The pairs of object m with the objects at order positions [lo, hi) (lo < hi), the keys
 * at kc (room reserved here). */
static QK__ALWAYS_INLINE int test_run_k(share_t *s, kc_t *kc, const me_t *m, uint32_t lo,
                                        uint32_t hi, const int ax) {
  if ((size_t)(kc->end - kc->v) < hi - lo && !kc_grow(s, kc, hi - lo)) return 0;
  const probe_t p = m->p; /* (in registers: the keys' stores could alias m) */
  kc->v = run_keys(s, s->pk->fgrp, s->w->order, s->pk->fexact, m->slot, m->hs, m->exact, p, lo, hi,
                   kc->v, ax);
  return 1;
}

/* test_run_k with the keys' place read from and stored to s->out. */
static QK__ALWAYS_INLINE int test_run(share_t *s, const me_t *m, uint32_t lo, uint32_t hi) {
  kc_t k = kc_open(s);
  int ok = test_run_k(s, &k, m, lo, hi, 0);
  kc_close(s, &k);
  return ok;
}

/* Record the pairs of object m with the objects at order positions [lo, hi), all known
 * to overlap it. */
static int emit_run(share_t *s, const me_t *m, uint32_t lo, uint32_t hi) {
  if (!kv_reserve(s, hi - lo)) return 0;
  const uint32_t *ord = s->w->order;
  const uint32_t slot = m->slot;
  const uint64_t hs = m->hs;
  uint64_t *v = s->out.v + s->out.n;
  for (uint32_t k = lo; k < hi; k++) *v++ = pair_key(slot, hs, ord[k]);
  s->out.n += hi - lo;
  return 1;
}

/* ---- the same level ---------------------------------------------------------------- */

/* Every object of cell a against the objects at order positions [blo, bhi) (other
 * cells' objects), whose boxes lie in ub. */
static int cross_run(share_t *s, kc_t *kc, uint32_t a, uint32_t blo, uint32_t bhi,
                     const qk_box_t *ub) {
  const qk__wcell_t *cl = s->w->cells;
  const float *fg = s->pk->fgrp;
  /* ub as floats, for a one-lane check of each of a's objects first. */
  float bx0 = (float)ub->xmin, by0 = (float)ub->ymin, bx1 = (float)ub->xmax, by1 = (float)ub->ymax;
  for (uint32_t k = cl[a].start, ke = cl[a + 1].start; k < ke; k++) {
    const float *f = lane_of(fg, k);
    if (!(f[0] <= bx1 && bx0 <= f[8] && f[4] <= by1 && by0 <= f[12])) continue;
    me_t m = me_of(s, k);
    if (!test_run_k(s, kc, &m, blo, bhi, 0)) return 0;
  }
  return 1;
}

/* same_level's runs for the objects [lo, hi) of a cell: each against the objects after it
 * up to hi, or up to hi2 when its float xmax reaches nx (the next cell's least xmin); and,
 * with `up`, against the row above's cells whose float boxes (cg, one lane a cell) its
 * float box meets, from the first such cell to the last (ust: where their objects start,
 * `above` of them in all). */
static QK__ALWAYS_INLINE int level_runs(share_t *s, kc_t *kc, uint32_t lo, uint32_t hi,
                                        uint32_t hi2, float nx, const float *cg,
                                        const uint32_t *ust, uint32_t above, const int up,
                                        const int ax) {
  const float *fg = s->pk->fgrp;
  const uint32_t *ord = s->w->order;
  const uint8_t *fx = s->pk->fexact;
  uint64_t *v = kc->v;
  for (uint32_t k = lo; k < hi; k++) {
    const float *f = lane_of(fg, k);
    const uint32_t e = f[8] >= nx ? hi2 : hi;
    if (!up && k + 1 >= e) continue;
    if ((size_t)(kc->end - v) < (e - k) + above) {
      kc->v = v;
      if (!kc_grow(s, kc, (e - k) + above)) return 0;
      v = kc->v;
    }
    const probe_t p = probe_of(f);
    const uint32_t slot = ord[k];
    const uint64_t hs = (uint64_t)slot << 32;
    const unsigned ek = fx[k];
    if (k + 1 < e) v = run_keys(s, fg, ord, fx, slot, hs, ek, p, k + 1, e, v, ax);
    if (up) {
      const unsigned m = group_hits(cg, &p);
      if (m) {
        uint32_t i = (uint32_t)__builtin_ctz(m), j = 32u - (uint32_t)__builtin_clz(m);
        v = run_keys(s, fg, ord, fx, slot, hs, ek, p, ust[i], ust[j], v, ax);
      }
    }
  }
  kc->v = v;
  return 1;
}
/* The pairs of cell a with its own level: within it, with the next cell of its row when
 * adjacent, and with the cells of the row above whose loose squares meet its own (three
 * consecutive ones at most, found by *up, a cursor that only moves forward). Each of a's
 * objects is broadcast once and meets two runs: the objects after it in its cell and,
 * when its float box reaches the next cell's, that cell's (they follow in the order); and
 * the row above's cells whose float boxes its float box meets, found by one four-wide test
 * against those boxes (rounded from the cells' boxes: monotone, so a cell whose float box
 * misses the object's misses every object's float box in it), from the first such cell to
 * the last (consecutive in the order too). end: past the last cell of a's level. */
static QK__ALWAYS_INLINE int same_level(share_t *s, kc_t *kc, uint32_t a, uint32_t end, double side,
                                        uint32_t *up, const int ax) {
  const qk_world_t *w = s->w;
  const qk__wcell_t *c = &w->cells[a];
  const qk_box_t *hb = s->pk->hb, *ha = &hb[a];
  uint32_t lo = c->start, hi = c[1].start, hi2 = hi;
  float nx = INFINITY; /* the next cell's least xmin as a float */
  if (a + 1 < end && c[1].cy == c->cy && c[1].cx == c->cx + 1 && boxes_meet(ha, &hb[a + 1]))
    hi2 = c[2].start, nx = (float)hb[a + 1].xmin;
  /* The row above: up to three consecutive cells (without the end cells whose boxes miss
   * this one's). Their objects lie in their loose squares, at or above (cy + 1) side, so
   * a cell whose box ends below that meets none of them, and its search is skipped (the
   * cursor stays: the next cell moves it on). In a sparse world most cells are such
   * (measured on the huge scene at 10^4, 1.2 objects a cell: the search 0.89 -> 0.81 M a
   * frame; the uniform scene's cells pay about 10 instructions each for the test). */
  uint32_t u = a + 1, u1 = a + 1;
  if (ha->ymax >= ((double)c->cy + 1) * side) {
    u = *up > a + 1 ? *up : a + 1;
    int64_t ty = (int64_t)c->cy + 1, tx = (int64_t)c->cx - 1;
    while (u < end && (w->cells[u].cy < ty || (w->cells[u].cy == ty && w->cells[u].cx < tx))) u++;
    *up = u;
    u1 = u;
    while (u1 < end && w->cells[u1].cy == ty && w->cells[u1].cx <= tx + 2) u1++;
    while (u < u1 && !boxes_meet(ha, &hb[u])) u++;
    while (u1 > u && !boxes_meet(ha, &hb[u1 - 1])) u1--;
  }
  if (u == u1) { /* (the common cell of a sparse world: nothing above) */
    if (hi2 == hi) {
      for (uint32_t k = lo; k + 1 < hi; k++) {
        me_t m = me_of(s, k);
        if (!test_run_k(s, kc, &m, k + 1, hi, ax)) return 0;
      }
      return 1;
    }
    return level_runs(s, kc, lo, hi, hi2, nx, NULL, NULL, 0, 0, ax);
  }
  /* Their boxes as floats, one lane a cell (the lanes after them an empty box), and where
   * their objects start in the order (ust[i] for cell u + i, and its end). */
  float cg[16];
  uint32_t ust[4];
  const uint32_t nu = u1 - u;
  for (uint32_t i = 0; i < 4; i++) {
    if (i < nu) {
      const qk_box_t *h = &hb[u + i];
      cg[i] = (float)h->xmin, cg[4 + i] = (float)h->ymin;
      cg[8 + i] = (float)h->xmax, cg[12 + i] = (float)h->ymax;
    } else {
      cg[i] = cg[4 + i] = INFINITY, cg[8 + i] = cg[12 + i] = -INFINITY;
    }
  }
  for (uint32_t i = 0; i <= nu; i++) ust[i] = w->cells[u + i].start;
  return level_runs(s, kc, lo, hi, hi2, nx, cg, ust, ust[nu] - ust[0], 1, ax);
}

/* ---- finer levels: the coarser object's box walked over their sorted cells ---------- */

/* The first cell of level lv at or after `from` not before (y, x), by a galloping search
 * from `from` (the cells before it are before (y, x)). */
static uint32_t gallop(const lvinfo_t *lv, const qk__wcell_t *cl, uint32_t from, int64_t y,
                       int64_t x) {
  if (from >= lv->end || !qk__cell_before(&cl[from], y, x)) return from;
  uint32_t lo = from, step = 1; /* cl[lo] is before (y, x) */
  while (lo + step < lv->end && qk__cell_before(&cl[lo + step], y, x)) lo += step, step *= 2;
  return qk__cell_bisect(cl, lo + 1, lo + step < lv->end ? lo + step : lv->end, y, x);
}

/* Cell indices from a scaled coordinate, clamped to a little beyond the 32-bit range of
 * cell indices (a box far from a fine level's cells gives values beyond it). */
static inline int64_t cell_index(double v) {
  if (v < -0x1p31 - 4) return INT32_MIN - INT64_C(4);
  if (v > 0x1p31 + 4) return INT32_MAX + INT64_C(4);
  return (int64_t)v;
}

/* A box in a finer level's cells: the cells that can hold objects meeting it, x in
 * [xa, xb] and y in [ya, yb], and those whose loose squares lie inside it, x in
 * [ix0, ix1] and y in [iy0, iy1] (none when the box is not a box object). */
typedef struct span {
  int64_t xa, xb, ya, yb, ix0, ix1, iy0, iy1;
} span_t;

/* The cells [c, hi) of row y (hi: the row's end) from the first one with cx >= xa: those
 * up to xb tested, or recorded whole when inside; returns the first cell after them. A
 * row of a few objects is tested in one run (finding its inside cells would cost more). */
static QK__ALWAYS_INLINE uint32_t do_row(share_t *s, const me_t *m, const span_t *sp, uint32_t c,
                                         uint32_t hi, int64_t y, int *ok) {
  const qk__wcell_t *cl = s->w->cells;
  uint32_t c1 = c;
  while (c1 < hi && cl[c1].cx <= sp->xb) c1++;
  if (c1 == c) return c;
  if (cl[c1].start - cl[c].start <= 8 || y < sp->iy0 || y > sp->iy1) {
    if (!test_run(s, m, cl[c].start, cl[c1].start)) *ok = 0;
    return c1;
  }
  uint32_t ca = c, cb; /* [c, ca) tested, [ca, cb) inside, [cb, c1) tested */
  while (ca < c1 && cl[ca].cx < sp->ix0) ca++;
  for (cb = ca; cb < c1 && cl[cb].cx <= sp->ix1;) cb++;
  if (ca == cb) ca = cb = c1; /* nothing inside: one run to test */
  if ((c < ca && !test_run(s, m, cl[c].start, cl[ca].start)) ||
      (ca < cb && !emit_run(s, m, cl[ca].start, cl[cb].start)) ||
      (cb < c1 && !test_run(s, m, cl[cb].start, cl[c1].start)))
    *ok = 0;
  return c1;
}

/* The first cell of [lo, hi) (one row's) with cx >= x, or hi: a few steps, then bisection. */
static inline uint32_t row_seek(const qk__wcell_t *cl, uint32_t lo, uint32_t hi, int64_t x) {
  for (int i = 0; i < 4 && lo < hi; i++, lo++)
    if (cl[lo].cx >= x) return lo;
  while (lo < hi) {
    uint32_t mid = lo + (hi - lo) / 2;
    if (cl[mid].cx < x)
      lo = mid + 1;
    else
      hi = mid;
  }
  return lo;
}

/*
 * Object m (box b) against the objects of the finer level lv. An object of lv's cell c
 * lies in c's loose square [c 2^l, (c + 2) 2^l) per axis, so those that can meet b are in
 * the cells from floor(min / 2^l) - 1 to floor(max / 2^l), a run of consecutive cells in
 * each row; and when m is a box, every object of a cell whose loose square lies inside b
 * (c from ceil(min / 2^l) to floor(max / 2^l) - 2) meets it, whatever its shape. With the
 * row index each row costs a lookup (and a bisection of the row when it has cells in
 * range); without, a galloping search skips the rows without such cells.
 */
static int descend(share_t *s, const me_t *m, const qk_box_t *b, int whole, const lvinfo_t *lv) {
  const qk__wcell_t *cl = s->w->cells;
  const double inv = qk__pow2(-lv->l);
  double x0 = b->xmin * inv, x1 = b->xmax * inv, y0 = b->ymin * inv, y1 = b->ymax * inv;
  span_t sp;
  sp.xa = cell_index(floor(x0)) - 1, sp.xb = cell_index(floor(x1));
  sp.ya = cell_index(floor(y0)) - 1, sp.yb = cell_index(floor(y1));
  sp.ix0 = cell_index(ceil(x0)), sp.ix1 = sp.xb - 2;
  sp.iy0 = whole ? cell_index(ceil(y0)) : INT64_MAX, sp.iy1 = sp.yb - 2;
  int64_t ya = sp.ya > lv->cy0 ? sp.ya : lv->cy0, yb = sp.yb < lv->cy1 ? sp.yb : lv->cy1;
  int ok = 1;
  if (lv->rf) {
    for (int64_t y = ya; y <= yb && ok; y++) {
      uint32_t lo = lv->rf[y - lv->cy0], hi = lv->rf[y - lv->cy0 + 1];
      if (lo == hi || cl[hi - 1].cx < sp.xa || cl[lo].cx > sp.xb) continue;
      if (cl[lo].cx < sp.xa) lo = row_seek(cl, lo + 1, hi, sp.xa);
      do_row(s, m, &sp, lo, hi, y, &ok);
    }
    return ok;
  }
  if (ya > yb) return 1;
  uint32_t c = gallop(lv, cl, lv->first, ya, sp.xa);
  while (ok && c < lv->end && cl[c].cy <= yb) {
    int64_t y = cl[c].cy;
    if (cl[c].cx < sp.xa)
      c = gallop(lv, cl, c, y, sp.xa);
    else if (cl[c].cx > sp.xb)
      c = gallop(lv, cl, c, y + 1, sp.xa);
    else {
      uint32_t row_end = gallop(lv, cl, c, y, INT64_MAX);
      c = gallop(lv, cl, do_row(s, m, &sp, c, row_end, y, &ok), y + 1, sp.xa);
    }
  }
  return ok;
}

/* ---- coarser levels: a fine cell looking up the coarse cells near it ----------------- */

/*
 * Which side finds the pairs of a coarse level with a finer one. Walking each coarse
 * object's box over the finer cells (descend) costs a few rows a coarse object, and
 * tests only finer objects near the box; looking up, from each finer cell, the coarse
 * cells whose loose squares meet it (two rows, bisected) costs a few searches a finer
 * cell and tests the coarse objects of those cells, which are few when the coarse level
 * is sparse but many when it is not. So: looking up when the coarse level has many more
 * objects than the finer one has cells (sizes mostly of one level, a few smaller ones:
 * the uniform scenes), descending otherwise (sizes spread over many levels).
 */
static inline int look_up(const lvinfo_t *coarse, const lvinfo_t *fine) {
  return coarse->n_obj > 16 * (size_t)(fine->end - fine->first);
}

/* Cell a against the cells of the coarser level lv whose loose squares
 * [c 2^l, (c + 2) 2^l) meet the box around a's objects: c from floor(min / 2^l) - 1 to
 * floor(max / 2^l), each row's found by bisection. */
static int cell_vs_level(share_t *s, uint32_t a, const lvinfo_t *lv) {
  const qk__wcell_t *cl = s->w->cells;
  const qk_box_t *hb = s->pk->hb, *ha = &hb[a];
  const double inv = qk__pow2(-lv->l);
  int64_t x0 = cell_index(floor(ha->xmin * inv)) - 1, x1 = cell_index(floor(ha->xmax * inv));
  int64_t y0 = cell_index(floor(ha->ymin * inv)) - 1, y1 = cell_index(floor(ha->ymax * inv));
  for (int64_t y = y0 > lv->cy0 ? y0 : lv->cy0; y <= y1 && y <= lv->cy1; y++)
    for (uint32_t k = qk__cell_bisect(cl, lv->first, lv->end, y, x0);
         k < lv->end && cl[k].cy == y && cl[k].cx <= x1; k++)
      if (boxes_meet(ha, &hb[k])) {
        kc_t kc = kc_open(s);
        int ok = cross_run(s, &kc, a, cl[k].start, cl[k + 1].start, &hb[k]);
        kc_close(s, &kc);
        if (!ok) return 0;
      }
  return 1;
}

/* The pairs of cell a (of level s->lv[me]): with its own level; of each of its objects with the
 * objects of the finer levels it descends to; and with the cells of the coarser levels that look up
 * (look_up), in each case only where the levels' boxes meet a's. */
static __attribute__((noinline)) int cell_others(share_t *s, uint32_t a, int me) {
  const qk_world_t *w = s->w;
  const qk__wcell_t *c = &w->cells[a];
  const qk_box_t *ha = &s->pk->hb[a];
  for (int li = 0; li < s->n_levels; li++) {
    const lvinfo_t *lv = &s->lv[li];
    if (li == me || !boxes_meet(ha, &lv->box)) continue;
    if (li > me) {
      if (look_up(lv, &s->lv[me]) && !cell_vs_level(s, a, lv)) return 0;
      continue;
    }
    if (look_up(&s->lv[me], lv)) continue;
    for (uint32_t k = c->start; k < c[1].start; k++) {
      const qk__wobj_t *o = &w->obj[w->order[k]];
      qk_box_t b = qk__wbox(o);
      if (!boxes_meet(&b, &lv->box)) continue;
      me_t m = me_of(s, k);
      if (!descend(s, &m, &b, (o->flags & QK__WKIND) == QK_SHAPE_BOX, lv)) return 0;
    }
  }
  return 1;
}
/* The pairs of cells [a, a1) of level s->lv[me] (see cell_others). Where that level finds
 * no pairs with others (every cell of a one-level world), the keys' place stays in locals
 * from cell to cell: opened and closed around each cell, it cost about 20 instructions a
 * cell, most of a sparse world's cell of one object. */
static QK__ALWAYS_INLINE int level_cells(share_t *s, uint32_t a, uint32_t a1, uint32_t *up, int me,
                                         const int ax) {
  const double side = qk__pow2(s->lv[me].l); /* (the level's cell side) */
  if (s->lv[me].other) {
    for (; a < a1; a++) {
      kc_t kc = kc_open(s);
      int ok = same_level(s, &kc, a, s->lv[me].end, side, up, ax);
      kc_close(s, &kc);
      if (!ok || !cell_others(s, a, me)) return 0;
    }
    return 1;
  }
  kc_t kc = kc_open(s);
  const uint32_t end = s->lv[me].end;
  int ok = 1;
  for (; ok && a < a1; a++) ok = same_level(s, &kc, a, end, side, up, ax);
  kc_close(s, &kc);
  return ok;
}

/* Every key of keys[0 .. n) the right way round, the smaller slot above (run_keys writes
 * the probe's slot above, either way round; keys already right stay). A rotation and the
 * smaller of the two: no branch. */
static void keys_ordered(uint64_t *keys, size_t n) {
  QK__UNROLL4
  for (size_t i = 0; i < n; i++) {
    const uint64_t k = keys[i], r = k >> 32 | k << 32;
    keys[i] = r < k ? r : k;
  }
}

static void run_share(unsigned t, void *ud) {
  share_t *s = &((share_t *)ud)[t];
  if (!kv_reserve(s, 256)) { /* (the keys' place is never NULL, its slack there: kc_open) */
    s->nomem = 1;
    return;
  }
  for (;;) {
    unsigned i = atomic_fetch_add_explicit(s->next, 1u, memory_order_relaxed);
    if (i >= s->n_chunks) {
      keys_ordered(s->out.v, s->out.n);
      return;
    }
    uint32_t up = 0;
    /* The chunk's cells level by level (me: the level of cell a). (Two copies of the
     * cells' loop: with every float box exact, the runs check none.) */
    for (uint32_t a = s->chunk[i], ae = s->chunk[i + 1], me = 0; a < ae;) {
      while (s->lv[me].end <= a) me++;
      const uint32_t a1 = s->lv[me].end < ae ? s->lv[me].end : ae;
      if (!(s->ax ? level_cells(s, a, a1, &up, (int)me, 1)
                  : level_cells(s, a, a1, &up, (int)me, 0))) {
        s->nomem = 1;
        return;
      }
      a = a1;
    }
  }
}

/* Level i of lv gets a row index when coarser levels descend to it (look_up) with
 * enough objects to pay for it (a few rows each), and its rows do not far outnumber its
 * cells (an index costs a word a row). */
static int wants_index(const lvinfo_t *lv, int n, int i) {
  size_t rows = (size_t)((int64_t)lv[i].cy1 - lv[i].cy0 + 1), visits = 0;
  if (rows > 4 * (size_t)(lv[i].end - lv[i].first) + 1024) return 0;
  for (int j = i + 1; j < n; j++)
    if (!look_up(&lv[j], &lv[i])) visits += 16 * (size_t)lv[j].n_obj;
  return visits >= rows;
}

/* The occupied levels and their row indices (in one block, *rf, of *n_rf entries, NULL
 * when none is needed). 0 when memory ran short. */
static int level_info(const qk_world_t *w, const qk__wpack_t *pk, lvinfo_t *lv, int *n_lv,
                      uint32_t **rf, size_t *n_rf) {
  int n = 0;
  for (int i = 0; i < QK__NLEV; i++) {
    if (!w->lv_n[i]) continue;
    uint32_t f = w->lv_first[i], e = f + w->lv_n[i];
    lv[n++] = (lvinfo_t){i + QK__LMIN,
                         f,
                         e,
                         w->cells[e].start - w->cells[f].start,
                         w->cells[f].cy,
                         w->cells[e - 1].cy,
                         NULL,
                         pk->lv_box[i],
                         0};
  }
  *n_lv = n;
  for (int i = 0; i < n; i++)
    for (int j = 0; j < n; j++)
      if ((j < i && !look_up(&lv[i], &lv[j])) || (j > i && look_up(&lv[j], &lv[i])))
        lv[i].other = 1;
  size_t need = 0;
  for (int i = 0; i < n; i++)
    if (wants_index(lv, n, i)) need += (size_t)((int64_t)lv[i].cy1 - lv[i].cy0 + 2);
  *rf = NULL, *n_rf = need;
  if (!need) return 1;
  uint32_t *r = qk__realloc(&w->alloc, NULL, 0, need * sizeof *r);
  if (!r) return 0;
  *rf = r;
  for (int i = 0; i < n; i++) {
    if (!wants_index(lv, n, i)) continue;
    size_t rows = (size_t)((int64_t)lv[i].cy1 - lv[i].cy0 + 1), y = 0;
    lv[i].rf = r;
    for (uint32_t c = lv[i].first; c < lv[i].end; c++)
      for (size_t cy = (size_t)((int64_t)w->cells[c].cy - lv[i].cy0); y <= cy; y++) r[y] = c;
    r[rows] = lv[i].end;
    r += rows + 1;
  }
  return 1;
}

/*
 * The grid's chunks of cells of about equal work (see qk__world_search): chunk i ends at
 * the first cell where the work of the cells before it reaches i / n_chunks of the
 * total, an object of level l weighing 2^(l - finest). Within a level every object
 * weighs the same, so the work up to a cell is the level's objects up to it, times the
 * weight: each cut is a bisection of the cell starts in one level's run, not a pass
 * over every cell (two such passes were most of the serial part of the search in a
 * sparse world, where nearly every object has a cell of its own).
 */
static void grid_chunks(const qk_world_t *w, int finest, uint32_t *chunk, unsigned n_chunks) {
  double wt[QK__NLEV], total = 0;
  int ls[QK__NLEV], nl = 0; /* the occupied levels, ascending: their runs in cell order */
  for (int l = 0; l < QK__NLEV; l++) {
    if (!w->lv_n[l]) continue;
    int d = l + QK__LMIN - finest;
    uint32_t f = w->lv_first[l], e = f + w->lv_n[l];
    wt[nl] = qk__pow2(d < 60 ? d : 60);
    total += (double)(w->cells[e].start - w->cells[f].start) * wt[nl];
    ls[nl++] = l;
  }
  unsigned i = 1;
  double before = 0; /* the work of the levels before level k */
  chunk[0] = 0;
  for (int k = 0; k < nl && i < n_chunks; k++) {
    uint32_t f = w->lv_first[ls[k]], e = f + w->lv_n[ls[k]];
    double lw = (double)(w->cells[e].start - w->cells[f].start) * wt[k];
    for (; i < n_chunks && before + lw >= total * i / n_chunks; i++) {
      /* the objects of this level the chunk's cells must hold (at least one) */
      double need = ceil((total * i / n_chunks - before) / wt[k]);
      uint64_t m = (uint64_t)w->cells[f].start + (uint64_t)(need > 1 ? need : 1);
      uint32_t a = qk__wcell_from(w->cells, f + 1, e, m);
      chunk[i] = a > chunk[i - 1] ? a : chunk[i - 1];
    }
    before += lw;
  }
  while (i <= n_chunks) chunk[i++] = w->n_cells;
}

/* ---- bands: a sweep on x in horizontal bands ---------------------------------------- */

/*
 * The grid's search above finds the pairs of objects of one size cheaply (a cell, its
 * right neighbour and the row above), but across sizes each coarse object walks the rows
 * of every finer level its box covers: in a scene of sizes over three decades that walk
 * costs more than the pairs it finds. Such scenes are searched in bands instead: the
 * plane is cut into horizontal bands of one height (a few times the objects' mean
 * height); each object is entered in every band its float box meets, and each band's
 * entries are sorted by their float xmin. Within a band an entry is compared with the
 * entries after it up to the first whose xmin lies beyond its xmax (a sweep on x), four
 * at a time, and a pair is kept in one band only (see sweep).
 */

/* Four entries of a band: their float xmin, ymin, ymax and their objects' slots. 64
 * bytes: a line per four candidates. */
typedef struct egrp {
  float x0[4], y0[4], y1[4];
  uint32_t slot[4];
} egrp_t;

/* A group's four entries' objects' float boxes at the last update (xmin, ymin, xmax,
 * ymax), when the search keeps only the pairs that began. */
typedef struct pgrp {
  float x0[4], y0[4], x1[4], y1[4];
} pgrp_t;

/* The bands: entries band after band, each band's by xmin (ascending; ties in any order),
 * four to a group. Each band starts a group and ends with one to four stop lanes (xmin a
 * NaN, which no comparison passes: see sweep), so a sweep needs no test of its band's
 * end. */
typedef struct bands {
  egrp_t *g;
  pgrp_t *pg;      /* or NULL: every pair is kept */
  uint8_t *fm;     /* per group: bit l when lane l's band is the first of its object */
  float *x1;       /* per entry: xmax */
  uint8_t *exact;  /* per entry: the object's float box is its box (NULL: all are) */
  int near;        /* (with exact) the candidates whose objects do not meet are kept,
                      marked by QK__NEAR */
  uint32_t *start; /* band b's entries are [start[b], end[b]), then its stop lanes up to */
  uint32_t *end;   /* start[b + 1], a multiple of four */
  uint32_t nb;
  size_t ne;
} bands_t;

/*
 * The sweep of entry k over the entries after it in its band (at least one), up to the
 * band's stop lanes.
 * The float boxes are tested as in test_run (a prefilter that never drops a pair whose
 * boxes meet; exact when both float boxes are). The entries after k have xmin >= k's, so
 * a candidate meets k's box on x when its xmin <= k's xmax, and the first that does not
 * ends the sweep.
 *
 * Each pair is kept once: two objects whose float boxes meet have y ranges that share
 * m = the higher of their two ymin, whose band is entered by both and is the first band
 * of one of them; in any later band both are entered, but neither first. So a pair is
 * kept where one of the two is entered first (band_of is non-decreasing in y).
 */
#if defined(__SSE2__)
/* One group g of the sweep of an entry (its broadcast bounds below), lanes `mask` (the
 * first group: the lanes after the entry; else all): its keys written at v, returned
 * past the kept ones; *stop set when a lane's xmin lies beyond the entry's xmax (or is a
 * band's stop lane). y1 is compared by "not less than", which a NaN passes: only a stop
 * lane holds one, and its xmin fails first. */
typedef struct sw {
  const share_t *s;
  const bands_t *bd;
  const egrp_t *g0;  /* the groups */
  const uint8_t *e0; /* the exact bytes (when not all_exact) */
  ptrdiff_t pd;      /* from a group to its boxes at the last update, in bytes */
  __m128 x1, y0, y1, px0, py0, px1, py1;
  __m128i ks, kb;
  uint32_t slot;
  unsigned ek;
} sw_t;
static QK__ALWAYS_INLINE uint64_t *sweep_grp(const sw_t *w, const egrp_t *g, const uint8_t *fm,
                                             unsigned mask, uint64_t *v, int *stop, const int any,
                                             const int all_exact, const int began,
                                             const int near_) {
  const __m128 cx = _mm_cmple_ps(_mm_loadu_ps(g->x0), w->x1);
  const __m128 m = _mm_and_ps(_mm_cmple_ps(_mm_loadu_ps(g->y0), w->y1),
                              _mm_cmpnlt_ps(_mm_loadu_ps(g->y1), w->y0));
  const unsigned cxm = (unsigned)_mm_movemask_ps(cx);
  unsigned bits = (unsigned)_mm_movemask_ps(_mm_and_ps(cx, m)) & mask & (any ? 15u : *fm);
  *stop = cxm != 15u;
  if (began && (all_exact || bits)) {
    /* (with every box exact, for every group: whether one of its lanes met k's box is a
     * coin toss in a crowded scene, and the test costs less than the mispredictions) */
    const pgrp_t *pq = (const pgrp_t *)(const void *)((const char *)g + w->pd);
    __m128 met = _mm_and_ps(_mm_and_ps(_mm_cmple_ps(_mm_loadu_ps(pq->x0), w->px1),
                                       _mm_cmpnlt_ps(_mm_loadu_ps(pq->x1), w->px0)),
                            _mm_and_ps(_mm_cmple_ps(_mm_loadu_ps(pq->y0), w->py1),
                                       _mm_cmpnlt_ps(_mm_loadu_ps(pq->y1), w->py0)));
    bits &= ~(unsigned)_mm_movemask_ps(met);
  }
  if (!(began && all_exact) && !bits) return v;
  __m128i sj = _mm_loadu_si128((const __m128i *)g->slot);
  if (all_exact) {
    /* the four keys at once: the entry's slot above each lane's, either way round
     * (sweep_run puts the kept ones the right way round when the sweeps are done) */
    const __m128i k01 = _mm_unpacklo_epi32(sj, w->ks), k23 = _mm_unpackhi_epi32(sj, w->ks);
    /* all four written, the end moved past the kept ones (room for three more than
     * the candidates is reserved): each pair of keys stored whole, then its second
     * key again over the first when the first is not kept */
    static const uint8_t kept[16] = {0, 1, 1, 2, 1, 2, 2, 3, 1, 2, 2, 3, 2, 3, 3, 4};
    uint64_t *v2 = v + kept[bits & 3];
    _mm_storeu_si128((__m128i *)v, k01);
    _mm_storeh_pd((double *)(v + (bits & 1)), _mm_castsi128_pd(k01));
    _mm_storeu_si128((__m128i *)v2, k23);
    _mm_storeh_pd((double *)(v2 + (bits >> 2 & 1)), _mm_castsi128_pd(k23));
    return v + kept[bits];
  }
  /* the four keys at once: (min << 32 | max) of the entry's slot and each lane's */
  const __m128i bias = _mm_set1_epi32(INT32_MIN);
  __m128i x = _mm_xor_si128(sj, w->ks);
  __m128i gt = _mm_cmpgt_epi32(_mm_xor_si128(sj, bias), w->kb); /* lane's slot > k's */
  __m128i mn = _mm_xor_si128(sj, _mm_and_si128(x, gt)), mx = _mm_xor_si128(mn, x);
  __m128i k01 = _mm_unpacklo_epi32(mx, mn), k23 = _mm_unpackhi_epi32(mx, mn);
  uint64_t key[4];
  _mm_storeu_si128((__m128i *)key, k01);
  _mm_storeu_si128((__m128i *)(key + 2), k23);
  const uint8_t *ex = w->e0 + (size_t)(g - w->g0) * 4;
  do {
    unsigned l = (unsigned)__builtin_ctz(bits);
    bits &= bits - 1;
    *v = key[l];
    if (near_)
      *v++ |=
          (w->ek & ex[l]) || qk__world_objects_meet(w->s->w, w->slot, g->slot[l]) ? 0 : QK__NEAR;
    else
      v += (w->ek & ex[l]) ? 1 : qk__world_objects_meet(w->s->w, w->slot, g->slot[l]);
  } while (bits);
  return v;
}

static QK__ALWAYS_INLINE uint64_t *sweep(const share_t *s, const bands_t *bd, uint32_t k,
                                         uint64_t *v, const int all_exact, const int began,
                                         const int near_) {
  const egrp_t *gk = &bd->g[k >> 2];
  const unsigned lk = k & 3;
  sw_t w;
  w.s = s, w.bd = bd, w.g0 = bd->g, w.e0 = bd->exact;
  w.pd = began ? (const char *)bd->pg - (const char *)bd->g : 0;
  w.x1 = _mm_set1_ps(bd->x1[k]), w.y0 = _mm_set1_ps(gk->y0[lk]), w.y1 = _mm_set1_ps(gk->y1[lk]);
  w.slot = gk->slot[lk];
  /* (began: k's box at the last update; a lane whose box then met it is dropped) */
  w.px0 = w.py0 = w.px1 = w.py1 = _mm_setzero_ps();
  if (began) {
    const pgrp_t *pk = &bd->pg[k >> 2];
    w.px0 = _mm_set1_ps(pk->x0[lk]), w.py0 = _mm_set1_ps(pk->y0[lk]);
    w.px1 = _mm_set1_ps(pk->x1[lk]), w.py1 = _mm_set1_ps(pk->y1[lk]);
  }
  w.ks = _mm_set1_epi32((int32_t)w.slot), w.kb = _mm_set1_epi32((int32_t)(w.slot ^ 0x80000000u));
  w.ek = all_exact ? 1 : bd->exact[k];
  /* The groups from k + 1's: the first masked to the lanes after k (those before it, k's
   * band's, hold no xmin beyond k's xmax: sorted), then whole ones up to the first lane
   * whose xmin lies beyond k's xmax, at the latest the band's stop lane. */
  const uint32_t lo = k + 1;
  const egrp_t *g = &bd->g[lo >> 2];
  const uint8_t *fm = &bd->fm[lo >> 2];
  const unsigned first = ~((1u << (lo & 3)) - 1) & 15u;
  int stop;
  /* k first in its band: every candidate may pair with it; else only those first here.
   * The two branches differ only in the constant `any` they give sweep_grp, which is
   * always inlined: each loop is then compiled with its own test (none for the first,
   * the lane's first-in-band byte for the second), instead of one loop that reads the
   * bytes and masks by a flag it tests every group. Keep them alike. */
  if (bd->fm[k >> 2] >> lk & 1) {
    v = sweep_grp(&w, g, fm, first, v, &stop, 1, all_exact, began, near_);
    while (!stop) v = sweep_grp(&w, ++g, ++fm, ~0u, v, &stop, 1, all_exact, began, near_);
  } else {
    v = sweep_grp(&w, g, fm, first, v, &stop, 0, all_exact, began, near_);
    while (!stop) v = sweep_grp(&w, ++g, ++fm, ~0u, v, &stop, 0, all_exact, began, near_);
  }
  return v;
}
#else
static uint64_t *sweep(const share_t *s, const bands_t *bd, uint32_t k, uint64_t *v,
                       const int all_exact, const int began, const int near_) {
  const egrp_t *G = bd->g;
  const pgrp_t *P = bd->pg;
  const egrp_t *gk = &G[k >> 2];
  const float x1 = bd->x1[k], y0 = gk->y0[k & 3], y1 = gk->y1[k & 3];
  const int any = bd->fm[k >> 2] >> (k & 3) & 1;
  const uint32_t slot = gk->slot[k & 3];
  const uint64_t hs = (uint64_t)slot << 32;
  /* (the band's stop lane, xmin a NaN, ends the sweep at the latest) */
  for (uint32_t j = k + 1;; j++) {
    const egrp_t *g = &G[j >> 2];
    unsigned l = j & 3;
    if (!(g->x0[l] <= x1)) break;
    if (!(g->y0[l] <= y1 && y0 <= g->y1[l] && (any || (bd->fm[j >> 2] >> l & 1)))) continue;
    if (began) {
      const pgrp_t *pk = &P[k >> 2], *pj = &P[j >> 2];
      unsigned lk = k & 3;
      if (pj->x0[l] <= pk->x1[lk] && pk->x0[lk] <= pj->x1[l] && pj->y0[l] <= pk->y1[lk] &&
          pk->y0[lk] <= pj->y1[l])
        continue;
    }
    uint32_t sj = g->slot[l];
    *v = pair_key(slot, hs, sj);
    if (near_)
      *v++ |= (all_exact || (bd->exact[k] & bd->exact[j])) || qk__world_objects_meet(s->w, slot, sj)
                  ? 0
                  : QK__NEAR;
    else
      v +=
          (all_exact || (bd->exact[k] & bd->exact[j])) ? 1 : qk__world_objects_meet(s->w, slot, sj);
  }
  return v;
}
#endif

/* The sweeps of bands [b0, b1) with the keys' end and room in locals (the room for a
 * sweep's keys, its candidates and three more, checked before each); 0 when memory ran
 * short. */
static QK__ALWAYS_INLINE int sweep_run(share_t *s, uint32_t b0, uint32_t b1, const int all_exact,
                                       const int began, const int near_) {
  const bands_t *bd = s->bd;
  const uint32_t *st = bd->start, *en = bd->end;
  if (!s->out.v && !kv_reserve(s, 256)) return 0;
  const size_t n0 = s->out.n;
  uint64_t *v = s->out.v + s->out.n, *vend = s->out.v + s->out.cap;
  for (uint32_t b = b0; b < b1; b++)
    for (uint32_t k = st[b], e = en[b]; k + 1 < e; k++) {
      if ((size_t)(vend - v) < (size_t)(e - k) + 2) {
        s->out.n = (size_t)(v - s->out.v);
        if (!kv_reserve(s, (size_t)(e - k) + 2)) return 0;
        v = s->out.v + s->out.n, vend = s->out.v + s->out.cap;
      }
      v = sweep(s, bd, k, v, all_exact, began, near_);
    }
  s->out.n = (size_t)(v - s->out.v);
#if defined(__SSE2__)
  if (all_exact) keys_ordered(s->out.v + n0, s->out.n - n0);
#else
  (void)n0;
#endif
  return 1;
}

/* The sweeps' variants, each a function of its own (their code apart, as measured). */
#define QK__SWEEP_VARIANT(name, all_exact, began, near_)                                           \
  __attribute__((noinline)) static int name(share_t *s, uint32_t b0, uint32_t b1) {                \
    return sweep_run(s, b0, b1, all_exact, began, near_);                                          \
  }
QK__SWEEP_VARIANT(sweep_any, 0, 0, 0)
QK__SWEEP_VARIANT(sweep_any_near, 0, 0, 1)
QK__SWEEP_VARIANT(sweep_any_began, 0, 1, 1)
QK__SWEEP_VARIANT(sweep_exact, 1, 0, 0)
QK__SWEEP_VARIANT(sweep_exact_began, 1, 1, 0)

static int sweep_bands(share_t *s, uint32_t b0, uint32_t b1) {
  /* (the began candidates only: see build_bands; near ones kept marked: see bands_t) */
  if (s->bd->exact) {
    if (s->bd->pg) return sweep_any_began(s, b0, b1);
    return s->bd->near ? sweep_any_near(s, b0, b1) : sweep_any(s, b0, b1);
  }
  return s->bd->pg ? sweep_exact_began(s, b0, b1) : sweep_exact(s, b0, b1);
}

static void run_bands(unsigned t, void *ud) {
  share_t *s = &((share_t *)ud)[t];
  for (;;) {
    unsigned i = atomic_fetch_add_explicit(s->next, 1u, memory_order_relaxed);
    if (i >= s->n_chunks) return;
    if (!sweep_bands(s, s->chunk[i], s->chunk[i + 1])) {
      s->nomem = 1;
      return;
    }
  }
}

/* A float's bits as an unsigned key in the floats' order (-0 before +0). */
static inline uint32_t fkey(float f) {
  uint32_t u;
  memcpy(&u, &f, sizeof u);
  return u & 0x80000000u ? ~u : u | 0x80000000u;
}

/* The band of y: non-decreasing in y (a difference rounded to nearest, a product by a
 * positive constant, a minimum and a truncation are each non-decreasing), and below
 * top + 1. */
static inline uint32_t band_of(float y, double ylo, double inv, double top) {
  return (uint32_t)qk__min(((double)y - ylo) * inv, top);
}

#if defined(__SSE2__)
/* band_of of the low two lanes of y, in the low two lanes (the same operations: minpd
 * keeps its second operand when the first is not below it, as qk__min). */
static inline __m128i band_of2(__m128 y, __m128d ylo, __m128d inv, __m128d top) {
  return _mm_cvttpd_epi32(_mm_min_pd(_mm_mul_pd(_mm_sub_pd(_mm_cvtps_pd(y), ylo), inv), top));
}
#endif

/* The entries' scatter into the bands (build_bands), on nt threads: thread t writes the
 * entries [P_t, P_t+1) (P_t = ne t / nt rounded down to a group: no group, first-band
 * byte or float is written by two threads), reading every record in order, so each band's
 * entries come in the order of one thread. The bands strictly inside its range are its
 * own (their cursors in pos); the first and the last, which it may share with its
 * neighbours, are counted from their starts in locals. */
typedef struct scat {
  const qk_world_t *w;
  const qk__wpack_t *pk;
  const uint64_t *rec; /* the records by xmin (low 32 bits: the object's place k) */
  const uint32_t *b01;
  egrp_t *g;
  pgrp_t *pg;
  uint8_t *fm, *exact;
  float *x1;
  const float *prev;
  const float *cur; /* (with SSE2, the boxes by slot: see fill_groups) */
  const uint32_t *start;
  uint32_t *pos;
  uint32_t nb;
  size_t ne;
  unsigned nt;
} scat_t;

/* The band holding entry p < ne: the last b with start[b] <= p. */
static uint32_t band_at(const uint32_t *start, uint32_t nb, size_t p) {
  uint32_t lo = 0, hi = nb - 1;
  while (lo < hi) {
    uint32_t m = lo + (hi - lo + 1) / 2;
    if (start[m] <= p)
      lo = m;
    else
      hi = m - 1;
  }
  return lo;
}

/* With SSE2 the entries' boxes from the boxes by slot (this update's, when there are
 * some, and the last update's) are written after the scatter, a group at a time
 * (fill_groups). */
#if defined(__SSE2__)
#define QK__PG_GROUPS 1
#else
#define QK__PG_GROUPS 0
#endif

/* Entry p: the object's slot s, and its float box f and last update's box pf (or NULL)
 * unless fill_groups writes them. */
static QK__ALWAYS_INLINE void put_entry(const scat_t *sc, uint32_t p, const float *f, uint32_t s,
                                        const float *pf, uint8_t ex) {
  egrp_t *q = &sc->g[p >> 2];
  q->slot[p & 3] = s;
  if (sc->exact) sc->exact[p] = ex;
  if (QK__PG_GROUPS && sc->cur) return; /* (the boxes: fill_groups) */
  q->x0[p & 3] = f[0], q->y0[p & 3] = f[4], q->y1[p & 3] = f[12];
  sc->x1[p] = f[8];
  if (pf) {
    pgrp_t *r = &sc->pg[p >> 2];
    r->x0[p & 3] = pf[0], r->y0[p & 3] = pf[1], r->x1[p & 3] = -pf[2], r->y1[p & 3] = -pf[3];
  }
}

#if defined(__SSE2__)
/* What scatter_ left out, bands [b0, b1), a whole group at a time by a transpose of its
 * four objects' boxes by slot, the same values as put_entry's: the entries' boxes from this
 * update's (cur, when there is one: the maxima negated) and their last update's (prev,
 * with pg). (Each band starts a group: bands on threads write apart.) */
static void fill_groups(const bands_t *bd, const float *prev, const float *cur, uint32_t b0,
                        uint32_t b1) {
  const __m128 neg = _mm_setr_ps(0.0f, 0.0f, -0.0f, -0.0f), all = _mm_set1_ps(-0.0f);
  for (uint32_t b = b0; b < b1; b++) {
    uint32_t p = bd->start[b];
    const uint32_t e = bd->end[b];
    for (; p + 4 <= e; p += 4) {
      egrp_t *q = &bd->g[p >> 2];
      const uint32_t *sl = q->slot;
      if (cur) {
        __m128 c0 = _mm_loadu_ps(cur + 4 * (size_t)sl[0]),
               c1 = _mm_loadu_ps(cur + 4 * (size_t)sl[1]),
               c2 = _mm_loadu_ps(cur + 4 * (size_t)sl[2]),
               c3 = _mm_loadu_ps(cur + 4 * (size_t)sl[3]);
        _MM_TRANSPOSE4_PS(c0, c1, c2, c3);
        _mm_storeu_ps(q->x0, c0), _mm_storeu_ps(q->y0, c1);
        _mm_storeu_ps(bd->x1 + p, _mm_xor_ps(c2, all)), _mm_storeu_ps(q->y1, _mm_xor_ps(c3, all));
      }
      if (bd->pg) {
        __m128 r0 = _mm_xor_ps(_mm_loadu_ps(prev + 4 * (size_t)sl[0]), neg),
               r1 = _mm_xor_ps(_mm_loadu_ps(prev + 4 * (size_t)sl[1]), neg),
               r2 = _mm_xor_ps(_mm_loadu_ps(prev + 4 * (size_t)sl[2]), neg),
               r3 = _mm_xor_ps(_mm_loadu_ps(prev + 4 * (size_t)sl[3]), neg);
        _MM_TRANSPOSE4_PS(r0, r1, r2, r3);
        pgrp_t *r = &bd->pg[p >> 2];
        _mm_storeu_ps(r->x0, r0), _mm_storeu_ps(r->y0, r1);
        _mm_storeu_ps(r->x1, r2), _mm_storeu_ps(r->y1, r3);
      }
    }
    for (; p < e; p++) {
      egrp_t *q = &bd->g[p >> 2];
      const uint32_t s = q->slot[p & 3];
      if (cur) {
        const float *c = cur + 4 * (size_t)s;
        q->x0[p & 3] = c[0], q->y0[p & 3] = c[1], bd->x1[p] = -c[2], q->y1[p & 3] = -c[3];
      }
      if (bd->pg) {
        const float *pf = prev + 4 * (size_t)s;
        pgrp_t *r = &bd->pg[p >> 2];
        r->x0[p & 3] = pf[0], r->y0[p & 3] = pf[1], r->x1[p & 3] = -pf[2], r->y1[p & 3] = -pf[3];
      }
    }
  }
}
/* fill_groups on threads: thread t's bands hold about the t-th share of the entries. */
typedef struct fill {
  bands_t bd;
  const float *prev, *cur;
  unsigned nt;
} fill_t;

static void fill_run(unsigned t, void *ud) {
  const fill_t *f = ud;
  const uint32_t nb = f->bd.nb, *st = f->bd.start;
  const size_t ne = st[nb];
  const uint32_t b0 = t ? band_at(st, nb, ne * t / f->nt) : 0,
                 b1 = t + 1 < f->nt ? band_at(st, nb, ne * (t + 1) / f->nt) : nb;
  fill_groups(&f->bd, f->prev, f->cur, b0, b1);
}
#endif

/* Thread t's entries (whole: all of them, on one thread, without the range's tests). */
static QK__ALWAYS_INLINE void scatter_(const scat_t *sc, unsigned t, int whole) {
  const qk_world_t *w = sc->w;
  const uint32_t n = w->n_order;
  const float *fg = sc->pk->fgrp;
  const uint8_t *fx = sc->pk->fexact;
  const uint32_t *ord = w->order;
  const size_t p0 = whole ? 0 : sc->ne * t / sc->nt & ~(size_t)3,
               p1 = whole || t + 1 == sc->nt ? sc->ne : sc->ne * (t + 1) / sc->nt & ~(size_t)3;
  if (p0 >= p1) return;
  const uint32_t blo = whole ? 0 : band_at(sc->start, sc->nb, p0),
                 bhi = whole ? sc->nb - 1 : band_at(sc->start, sc->nb, p1 - 1);
  uint32_t clo = sc->start[blo], chi = sc->start[bhi];
  const scat_t d = *sc; /* (a copy: the byte stores cannot change it) */
  uint32_t *pos = sc->pos;
  /* (with SSE2 the last update's boxes are written after, a group at a time:
   * fill_groups) */
  const pgrp_t *pg = QK__PG_GROUPS ? NULL : sc->pg;
  uint8_t *fm = sc->fm;
  for (uint32_t i = 0; i < n; i++) {
    uint32_t k = (uint32_t)sc->rec[i];
    uint32_t b0 = sc->b01[2 * k], be = sc->b01[2 * k + 1];
    if (!whole && (be < blo || b0 > bhi)) continue;
    uint32_t s = ord[k], b = whole || b0 >= blo ? b0 : blo, bl = whole || be <= bhi ? be : bhi;
    const float *pf = pg ? sc->prev + 4 * (size_t)s : NULL;
    if (whole) { /* (the loop as it was on one thread: a cursor a band, the first marked) */
      uint32_t p = pos[b]++;
      fm[p >> 2] |= (uint8_t)(1u << (p & 3)); /* its first band */
      for (;;) {
        put_entry(&d, p, lane_of(fg, k), s, pf, fx[k]);
        if (++b > be) break;
        p = pos[b]++;
      }
      continue;
    }
    for (; b <= bl; b++) {
      uint32_t p = b == blo ? clo++ : b == bhi ? chi++ : pos[b]++;
      if (p < p0 || p >= p1) continue;
      if (b == b0) fm[p >> 2] |= (uint8_t)(1u << (p & 3)); /* its first band */
      put_entry(&d, p, lane_of(fg, k), s, pf, fx[k]);
    }
  }
}

static void scatter_run(unsigned t, void *ud) { scatter_(ud, t, 0); }

/*
 * The bands' build before the scatter (build_bands), on nt threads: the first pass over
 * the objects (the y range, the heights' sum, the float boxes by slot, the records by
 * xmin and their digits' counts), the bands' counts, and the records' radix sort by xmin.
 * Thread t takes the objects of blocks [nblk t / nt, nblk (t + 1) / nt) of BB_BLOCK
 * objects, the same in every step; the heights are summed by block, then the blocks in
 * order, so the bands are the same on any number of threads. The radix sort is the one
 * of one thread, each pass on the threads as a stable counting sort: thread t's records
 * of a digit go after those of threads before it (their counts, per thread, give every
 * thread its cursors), so each pass's order, and the sort, are one thread's. (One thread
 * ran it all: 13.9 M instructions of the calling thread a frame on the benchmark's
 * clustered scene at 10^5, two threads.)
 */
#define BB_BLOCK 1024u
typedef struct bbjob {
  const qk_world_t *w;
  const float *fg;
  const uint8_t *fx;
  float *cur;
  uint64_t *rec, *tmp; /* the records, and the sort's other half */
  uint32_t *b01;
  uint32_t *cnt0; /* thread 0's digit counts (3 x 2048), then its cursors */
  uint32_t *cnt;  /* threads 1 .. nt - 1: theirs, 3 x 2048 each */
  uint32_t *bc;   /* threads 1 .. nt - 1: their band counts, nb + 1 each (thread 0's: start) */
  size_t bc_n;    /* (the room of bc, in counts) */
  double *bsum;   /* per block: the heights' sum */
  uint32_t n, nblk;
  unsigned nt;
  int phase, sh; /* the step, and the radix pass's shift */
  const uint64_t *src;
  uint64_t *dst;
  /* the bands (phase 1) */
  float ylo0;
  double inv, top;
  uint32_t nb, *start;
  size_t ne_all;
  /* per thread */
  float ylo[QK__MAX_THREADS], yhi[QK__MAX_THREADS];
  unsigned exact[QK__MAX_THREADS];
  size_t ne[QK__MAX_THREADS];
} bbjob_t;

static inline uint32_t *bb_cnt(const bbjob_t *J, unsigned t) {
  return t ? J->cnt + (size_t)(t - 1) * 3 * 2048 : J->cnt0;
}

/* Thread t's objects: [k0, k1). */
static inline void bb_range(const bbjob_t *J, unsigned t, uint32_t *k0, uint32_t *k1) {
  uint32_t b0 = (uint32_t)((uint64_t)J->nblk * t / J->nt),
           b1 = (uint32_t)((uint64_t)J->nblk * (t + 1) / J->nt);
  *k0 = b0 * BB_BLOCK, *k1 = b1 * BB_BLOCK < J->n ? b1 * BB_BLOCK : J->n;
}

static void bb_job(unsigned t, void *ud) {
  bbjob_t *J = ud;
  const float *fg = J->fg;
  uint32_t k0, k1;
  bb_range(J, t, &k0, &k1);
  if (J->phase == 0) { /* the first pass */
    uint32_t *cnt = bb_cnt(J, t);
    const uint8_t *fx = J->fx;
    const uint32_t *ord = J->w->order;
    float *cur = J->cur;
    uint64_t *rec = J->rec;
    memset(cnt, 0, 3 * 2048 * sizeof *cnt);
    float ylo = INFINITY, yhi = -INFINITY;
    unsigned all_exact = 1;
#if defined(__SSE2__)
    __m128 vlo = _mm_set1_ps(INFINITY), vhi = _mm_set1_ps(-INFINITY);
    const __m128 neg = _mm_set1_ps(-0.0f);
    const __m128i top = _mm_set1_epi32((int32_t)0x80000000u);
#endif
    for (uint32_t k = k0; k < k1;) {
      const uint32_t e = k + BB_BLOCK < k1 ? k + BB_BLOCK : k1;
      double hs = 0;
#if defined(__SSE2__)
      /* Whole groups as vectors (k starts a block, so a group): the same values as the
       * loop below, the heights summed in the same order (the key, the float's bits with
       * the sign flipped, or all flipped when it is set: fkey). */
      for (; k + 4 <= e; k += 4) {
        const float *f = fg + 4 * (size_t)k;
        const __m128 x0 = _mm_loadu_ps(f), y0 = _mm_loadu_ps(f + 4), x1 = _mm_loadu_ps(f + 8),
                     y1 = _mm_loadu_ps(f + 12);
        vlo = _mm_min_ps(y0, vlo), vhi = _mm_max_ps(y1, vhi);
        const __m128d h01 = _mm_sub_pd(_mm_cvtps_pd(y1), _mm_cvtps_pd(y0)),
                      h23 = _mm_sub_pd(_mm_cvtps_pd(_mm_movehl_ps(y1, y1)),
                                       _mm_cvtps_pd(_mm_movehl_ps(y0, y0)));
        hs += _mm_cvtsd_f64(h01), hs += _mm_cvtsd_f64(_mm_unpackhi_pd(h01, h01));
        hs += _mm_cvtsd_f64(h23), hs += _mm_cvtsd_f64(_mm_unpackhi_pd(h23, h23));
        uint32_t ex;
        memcpy(&ex, fx + k, sizeof ex);
        all_exact &= (ex & 0x01010101u) == 0x01010101u;
        if (cur) {
          __m128 c0 = x0, c1 = y0, c2 = _mm_xor_ps(x1, neg), c3 = _mm_xor_ps(y1, neg);
          _MM_TRANSPOSE4_PS(c0, c1, c2, c3);
          _mm_storeu_ps(cur + 4 * (size_t)ord[k], c0);
          _mm_storeu_ps(cur + 4 * (size_t)ord[k + 1], c1);
          _mm_storeu_ps(cur + 4 * (size_t)ord[k + 2], c2);
          _mm_storeu_ps(cur + 4 * (size_t)ord[k + 3], c3);
        }
        const __m128i u = _mm_castps_si128(x0),
                      key = _mm_xor_si128(u, _mm_or_si128(_mm_srai_epi32(u, 31), top)),
                      kv = _mm_add_epi32(_mm_set1_epi32((int32_t)k), _mm_setr_epi32(0, 1, 2, 3));
        _mm_storeu_si128((__m128i *)(rec + k), _mm_unpacklo_epi32(kv, key));
        _mm_storeu_si128((__m128i *)(rec + k + 2), _mm_unpackhi_epi32(kv, key));
        uint32_t xs[4];
        _mm_storeu_si128((__m128i *)xs, key);
        for (int l = 0; l < 4; l++)
          cnt[xs[l] & 2047]++, cnt[2048 + (xs[l] >> 11 & 2047)]++, cnt[4096 + (xs[l] >> 22)]++;
      }
#endif
      for (; k < e; k++) {
        const float *f = lane_of(fg, k);
        ylo = f[4] < ylo ? f[4] : ylo;
        yhi = f[12] > yhi ? f[12] : yhi;
        hs += (double)f[12] - f[4];
        all_exact &= fx[k];
        if (cur) {
          float *c = cur + 4 * (size_t)ord[k]; /* (the maxima negated: see qk__world_search) */
          c[0] = f[0], c[1] = f[4], c[2] = -f[8], c[3] = -f[12];
        }
        uint32_t x = fkey(f[0]);
        rec[k] = (uint64_t)x << 32 | k;
        cnt[x & 2047]++, cnt[2048 + (x >> 11 & 2047)]++, cnt[4096 + (x >> 22)]++;
      }
      J->bsum[(e - 1) / BB_BLOCK] = hs;
    }
#if defined(__SSE2__)
    float lo[4], hi[4];
    _mm_storeu_ps(lo, vlo), _mm_storeu_ps(hi, vhi);
    for (int l = 0; l < 4; l++) {
      ylo = lo[l] < ylo ? lo[l] : ylo;
      yhi = hi[l] > yhi ? hi[l] : yhi;
    }
#endif
    J->ylo[t] = ylo, J->yhi[t] = yhi, J->exact[t] = all_exact;
  } else if (J->phase == 1) { /* each object's bands, counted */
    uint32_t *c = t ? J->bc + (size_t)(t - 1) * (J->nb + 1) : J->start, *b01 = J->b01;
    const float ylo = J->ylo0;
    const double inv = J->inv, top = J->top;
    memset(c, 0, ((size_t)J->nb + 1) * sizeof *c);
    size_t ne = 0;
    uint32_t k = k0;
#if defined(__SSE2__)
    /* Whole groups as vectors (k0 starts a block, so a group), while a band fits the
     * conversion to int32 (below 2^31 bands: always, short of 2^32 objects) */
    const __m128d vlo = _mm_set1_pd((double)ylo), vinv = _mm_set1_pd(inv), vtop = _mm_set1_pd(top);
    for (; top < 2147483648.0 && k + 4 <= k1; k += 4) {
      const float *f = fg + 4 * (size_t)k;
      const __m128 y0 = _mm_loadu_ps(f + 4), y1 = _mm_loadu_ps(f + 12);
      const __m128i a = _mm_unpacklo_epi64(band_of2(y0, vlo, vinv, vtop),
                                           band_of2(_mm_movehl_ps(y0, y0), vlo, vinv, vtop)),
                    b = _mm_unpacklo_epi64(band_of2(y1, vlo, vinv, vtop),
                                           band_of2(_mm_movehl_ps(y1, y1), vlo, vinv, vtop));
      _mm_storeu_si128((__m128i *)(b01 + 2 * (size_t)k), _mm_unpacklo_epi32(a, b));
      _mm_storeu_si128((__m128i *)(b01 + 2 * (size_t)k + 4), _mm_unpackhi_epi32(a, b));
      uint32_t as[4], bs[4];
      _mm_storeu_si128((__m128i *)as, a), _mm_storeu_si128((__m128i *)bs, b);
      for (int l = 0; l < 4; l++) {
        uint32_t x = as[l];
        ne += bs[l] - x + 1;
        do c[++x]++;
        while (x <= bs[l]);
      }
    }
#endif
    for (; k < k1; k++) {
      const float *f = lane_of(fg, k);
      uint32_t a = band_of(f[4], ylo, inv, top), b = band_of(f[12], ylo, inv, top);
      b01[2 * k] = a, b01[2 * k + 1] = b;
      ne += b - a + 1;
      do c[++a]++;
      while (a <= b);
    }
    J->ne[t] = ne;
  } else if (J->phase == 2) { /* a radix pass's digit counted */
    uint32_t *c = bb_cnt(J, t);
    const uint64_t *a = J->src;
    const int sh = J->sh;
    memset(c, 0, 2048 * sizeof *c);
    QK__UNROLL4
    for (uint32_t j = k0; j < k1; j++) c[a[j] >> sh & 2047]++;
  } else { /* a radix pass's scatter, from the thread's cursors */
    uint32_t *c = bb_cnt(J, t);
    const uint64_t *a = J->src;
    uint64_t *d = J->dst;
    const int sh = J->sh;
    QK__UNROLL4
    for (uint32_t j = k0; j < k1; j++) d[c[a[j] >> sh & 2047]++] = a[j];
  }
}

static void bb_run(bbjob_t *J, int phase) {
  J->phase = phase;
  if (J->nt > 1)
    qk__world_run_jobs(J->w, J->nt, J->nt, bb_job, J);
  else
    bb_job(0, J);
}

/* The job for n objects on nt threads (at most one a block); 0 when memory ran short. */
static int bb_init(bbjob_t *J, const qk_world_t *w, const float *fg, const uint8_t *fx, float *cur,
                   uint64_t *rec, uint32_t *b01, unsigned nt) {
  const uint32_t n = w->n_order;
  memset(J, 0, offsetof(bbjob_t, ylo));
  J->w = w, J->fg = fg, J->fx = fx, J->cur = cur, J->rec = rec, J->tmp = rec + n, J->b01 = b01;
  J->n = n, J->nblk = (uint32_t)((n + BB_BLOCK - 1) / BB_BLOCK);
  if (nt > QK__MAX_THREADS) nt = QK__MAX_THREADS;
  if (nt > J->nblk) nt = J->nblk ? J->nblk : 1;
  J->nt = nt;
  J->bsum = qk__realloc(&w->alloc, NULL, 0, (J->nblk + 1) * sizeof *J->bsum);
  if (!J->bsum) return 0;
  if (nt > 1 &&
      !(J->cnt = qk__realloc(&w->alloc, NULL, 0, (size_t)(nt - 1) * 3 * 2048 * sizeof *J->cnt))) {
    qk__free(&w->alloc, J->bsum, (J->nblk + 1) * sizeof *J->bsum);
    return 0;
  }
  return 1;
}

static void bb_free(bbjob_t *J) {
  const qk_allocator_t *al = &J->w->alloc;
  qk__free(al, J->bsum, (J->nblk + 1) * sizeof *J->bsum);
  if (J->cnt) qk__free(al, J->cnt, (size_t)(J->nt - 1) * 3 * 2048 * sizeof *J->cnt);
  if (J->bc) qk__free(al, J->bc, J->bc_n * sizeof *J->bc);
  J->bsum = NULL, J->cnt = NULL, J->bc = NULL;
}

/* The bands' counts (start[b + 1]: the objects that enter band b) and J->ne_all; 0 when
 * memory ran short. */
static int bb_bands(bbjob_t *J) {
  const size_t m = (size_t)J->nb + 1, need = (size_t)(J->nt - 1) * m;
  if (need > J->bc_n) {
    const qk_allocator_t *al = &J->w->alloc;
    uint32_t *bc = qk__realloc(al, J->bc, J->bc_n * sizeof *bc, need * sizeof *bc);
    if (!bc) return 0;
    J->bc = bc, J->bc_n = need;
  }
  bb_run(J, 1);
  size_t ne = J->ne[0];
  for (unsigned t = 1; t < J->nt; t++) {
    const uint32_t *c = J->bc + (size_t)(t - 1) * m;
    for (size_t b = 0; b < m; b++) J->start[b] += c[b];
    ne += J->ne[t];
  }
  J->ne_all = ne;
  return 1;
}

/* The records sorted by xmin (in rec or tmp: returned). */
static const uint64_t *bb_sort(bbjob_t *J) {
  const unsigned nt = J->nt;
  const uint32_t n = J->n;
  uint64_t *a = J->rec, *t = J->tmp;
  int moved = 0; /* a pass ran: the later digits' counts by thread are counted again */
  for (int d = 0; d < 3; d++) {
    const int sh = 32 + 11 * d;
    J->src = a, J->sh = sh;
    if (moved && nt > 1) bb_run(J, 2);
    /* the digit's counts in all, and each thread's cursors: a digit's records by thread */
    const size_t o = moved && nt > 1 ? 0 : 2048 * (size_t)d;
    int shared = 0;
    uint32_t acc = 0;
    if (nt == 1) {
      /* One thread: its cursors written where the scatter reads them in the same loop
       * (over the first digit's counts, used by then), without the copy below. */
      const uint32_t *c = J->cnt0 + o;
      uint32_t *cur = J->cnt0;
      for (int x = 0; x < 2048; x++) {
        const uint32_t v = c[x];
        cur[x] = acc;
        shared |= v == n;
        acc += v;
      }
    } else
      for (int x = 0; x < 2048; x++) {
        uint32_t v = 0;
        for (unsigned u = 0; u < nt; u++) {
          uint32_t *c = bb_cnt(J, u) + o + x, cu = *c;
          *c = acc + v, v += cu;
        }
        shared |= v == n;
        acc += v;
      }
    if (shared) continue;
    if (o && nt > 1) /* (the cursors where the scatter reads them) */
      for (unsigned u = 0; u < nt; u++)
        memcpy(bb_cnt(J, u), bb_cnt(J, u) + o, 2048 * sizeof(uint32_t));
    J->dst = t;
    bb_run(J, 3);
    uint64_t *x = a;
    a = t, t = x;
    moved = 1;
  }
  return a;
}

/* Build the bands for the n objects of the pack, of a height of three times the objects'
 * mean float height (measured: from 2 to 4 times the search costs within 5% on the
 * clustered scene and on sizes over one and two decades), or higher when that would make
 * more than about n / 2 bands or far too many entries. 0 when memory ran short. */
static int build_bands(const qk_world_t *w, const qk__wpack_t *pk, bands_t *bd, const float *prev,
                       float *cur, int near_ok, unsigned nt) {
  const qk_allocator_t *al = &w->alloc;
  const uint32_t n = w->n_order;
  const float *fg = pk->fgrp;
  const uint8_t *fx = pk->fexact;
  memset(bd, 0, sizeof *bd);
  /* per object its first and last bands (b01), and the sort's records (twice) */
  uint64_t *rec = qk__realloc(al, NULL, 0, 3 * (size_t)n * sizeof *rec);
  uint32_t *cnt = rec ? qk__realloc(al, NULL, 0, 3 * 2048 * sizeof *cnt) : NULL;
  if (!cnt) {
    qk__free(al, rec, 3 * (size_t)n * sizeof *rec);
    return 0;
  }
  uint32_t *b01 = (uint32_t *)(rec + 2 * (size_t)n);
  bbjob_t J;
  if (!bb_init(&J, w, fg, fx, cur, rec, b01, nt)) {
    qk__free(al, cnt, 3 * 2048 * sizeof *cnt);
    qk__free(al, rec, 3 * (size_t)n * sizeof *rec);
    return 0;
  }
  /* One pass: the y range, the mean height, the records by xmin and their digits'
   * counts (on the threads, each over its blocks; one thread's counts in cnt). */
  J.cnt0 = cnt;
  bb_run(&J, 0);
  float ylo = INFINITY, yhi = -INFINITY;
  double hs = 0;
  unsigned all_exact = 1;
  for (unsigned t = 0; t < J.nt; t++) {
    ylo = J.ylo[t] < ylo ? J.ylo[t] : ylo;
    yhi = J.yhi[t] > yhi ? J.yhi[t] : yhi;
    all_exact &= J.exact[t];
  }
  for (uint32_t b = 0; b < J.nblk; b++) hs += J.bsum[b]; /* (in block order: any threads) */
  const size_t cap = (size_t)n / 2 + 16;
  const double range = (double)yhi - (double)ylo, top = (double)(cap - 1);
  double h = 3 * hs / n;
  if (!(h >= range / top)) h = range / top;
  if (!(h > 0)) h = 1; /* (one band) */
  double inv;
  uint32_t nb;
  size_t ne;
  uint32_t *start = NULL;
  for (;;) {
    inv = 1 / h;
    nb = band_of(yhi, ylo, inv, top) + 1;
    start = qk__realloc(al, NULL, 0, 3 * ((size_t)nb + 1) * sizeof *start);
    if (!start) break;
    /* each object's bands, counted (by the threads apart: bb_bands) */
    J.ylo0 = ylo, J.inv = inv, J.top = top, J.nb = nb, J.start = start;
    if (!bb_bands(&J)) {
      qk__free(al, start, 3 * ((size_t)nb + 1) * sizeof *start);
      start = NULL;
      break;
    }
    ne = J.ne_all + 4 * (size_t)nb; /* (with the stop lanes, at most) */
    if (J.ne_all <= 16 * (size_t)n + 1024 && ne < UINT32_MAX / 2) break;
    qk__free(al, start, 3 * ((size_t)nb + 1) * sizeof *start);
    h *= 2;
  }
  size_t ng = start ? ne / 4 + 1 : 0, xbytes = ne * (sizeof(float) + (all_exact ? 0 : 1));
  egrp_t *g = start ? qk__realloc(al, NULL, 0, ng * (sizeof *g + 1)) : NULL;
  float *x1 = g ? qk__realloc(al, NULL, 0, xbytes) : NULL;
  if (!x1) {
    if (start) qk__free(al, start, 3 * ((size_t)nb + 1) * sizeof *start);
    qk__free(al, g, ng * (sizeof *g + 1));
    bb_free(&J);
    qk__free(al, cnt, 3 * 2048 * sizeof *cnt);
    qk__free(al, rec, 3 * (size_t)n * sizeof *rec);
    return 0;
  }
  pgrp_t *pg = NULL;
  if (prev && (all_exact || near_ok) && !(pg = qk__realloc(al, NULL, 0, ng * sizeof *pg))) {
    qk__free(al, x1, xbytes);
    qk__free(al, start, 3 * ((size_t)nb + 1) * sizeof *start);
    qk__free(al, g, ng * (sizeof *g + 1));
    bb_free(&J);
    qk__free(al, cnt, 3 * 2048 * sizeof *cnt);
    qk__free(al, rec, 3 * (size_t)n * sizeof *rec);
    return 0;
  }
  uint8_t *fm = (uint8_t *)(g + ng);
  uint8_t *exact = all_exact ? NULL : (uint8_t *)(x1 + ne);
  uint32_t *pos = start + nb + 1, *end = pos + nb + 1;
  /* (each band from a group, its entries followed by one to four stop lanes) */
  for (uint32_t b = 0; b < nb; b++)
    end[b] = start[b] + start[b + 1], start[b + 1] = (end[b] + 4) & ~UINT32_C(3);
  end[nb] = start[nb];
  memcpy(pos, start, ((size_t)nb + 1) * sizeof *pos);
  /* The records by xmin: an LSD radix sort of three digits, skipping those all share
   * (on the threads: bb_sort). */
  const uint64_t *a = bb_sort(&J);
  bb_free(&J);
  /* Then the entries, band by band, in that order: each band's come sorted; then the
   * bands' stop lanes. The last group's lanes hold boxes that meet nothing (no sweep
   * reaches it: each stops at its band's stop lane). */
  memset(fm, 0, ng);
  for (int l = 0; l < 4; l++)
    g[ng - 1].x0[l] = g[ng - 1].y0[l] = INFINITY, g[ng - 1].y1[l] = -INFINITY,
           g[ng - 1].slot[l] = 0;
  if (pg)
    for (int l = 0; l < 4; l++)
      pg[ng - 1].x0[l] = pg[ng - 1].y0[l] = INFINITY,
              pg[ng - 1].x1[l] = pg[ng - 1].y1[l] = -INFINITY;
  scat_t sc = {w,     pk,  a,  b01,       g, pg, fm, exact, x1, prev, QK__PG_GROUPS ? cur : NULL,
               start, pos, nb, start[nb], nt};
  if (nt > 1)
    qk__world_run_jobs(w, nt, nt, scatter_run, &sc);
  else
    scatter_(&sc, 0, 1);
#if defined(__SSE2__)
  if (pg || cur) {
    fill_t fj = {{.g = g, .pg = pg, .x1 = x1, .start = start, .end = end, .nb = nb}, prev, cur, nt};
    if (nt > 1)
      qk__world_run_jobs(w, nt, nt, fill_run, &fj);
    else
      fill_groups(&fj.bd, prev, cur, 0, nb);
  }
#endif
  for (uint32_t b = 0; b < nb; b++)
    for (uint32_t p = end[b]; p < start[b + 1]; p++) {
      egrp_t *q = &g[p >> 2];
      q->x0[p & 3] = q->y0[p & 3] = q->y1[p & 3] = NAN, q->slot[p & 3] = 0;
      x1[p] = NAN;
      if (exact) exact[p] = 0;
      if (pg) {
        pgrp_t *r = &pg[p >> 2];
        r->x0[p & 3] = r->y0[p & 3] = INFINITY, r->x1[p & 3] = r->y1[p & 3] = -INFINITY;
      }
    }
  qk__free(al, cnt, 3 * 2048 * sizeof *cnt);
  qk__free(al, rec, 3 * (size_t)n * sizeof *rec);
  *bd = (bands_t){g, pg, fm, x1, exact, !all_exact && near_ok, start, end, nb, ne};
  return 1;
}

static void free_bands(const qk_world_t *w, bands_t *bd) {
  const qk_allocator_t *al = &w->alloc;
  if (!bd->start) return;
  qk__free(al, bd->g, (bd->ne / 4 + 1) * (sizeof *bd->g + 1));
  if (bd->pg) qk__free(al, bd->pg, (bd->ne / 4 + 1) * sizeof *bd->pg);
  qk__free(al, bd->x1, bd->ne * (sizeof(float) + (bd->exact ? 1 : 0)));
  qk__free(al, bd->start, 3 * ((size_t)bd->nb + 1) * sizeof *bd->start);
  memset(bd, 0, sizeof *bd);
}

/*
 * Bands or the grid. The grid's cost beyond its pairs is the walk of each coarse object
 * over the rows of the finer levels: about 2^(L - l - 1) + 2 rows for an object of level
 * L over level l (or, where the coarse level is looked up from the fine one's cells, two
 * rows a fine cell). The bands cost a sort and a sweep an entry, whatever the sizes. So
 * the bands are taken unless those rows come to less than one for eight objects.
 * Measured (search instructions a frame, 10^4 boxes moving as in the benchmark, grid
 * against bands): one level (the benchmark's uniform scene: 3.46 M against 3.73 M; its
 * sparse huge scene: 1.29 M against 2.79 M) stays on the grid; 95% of sizes 0.5 to 2 and
 * 5% tiny ones (0.18 rows an object): 3.92 M against 3.67 M; 85% and 15% of sizes 2 to
 * 8 (0.6): 6.23 M against 4.54 M; sizes over one decade (2.3): 6.46 M against 3.27 M; two
 * decades (7.1): 16.3 M against 5.25 M; the benchmark's clustered scene (three decades,
 * 42): 30.8 M against 10.9 M; two decades in a sparse world (20000 x 20000): 7.54 M
 * against 2.92 M.
 */
static int use_bands(const qk_world_t *w) {
  if (w->n_order <= 1) return 0;
  double n_obj[QK__NLEV], rows = 0;
  int l[QK__NLEV], nl = 0;
  uint32_t n_cells[QK__NLEV];
  for (int i = 0; i < QK__NLEV; i++) {
    if (!w->lv_n[i]) continue;
    uint32_t f = w->lv_first[i], e = f + w->lv_n[i];
    n_obj[nl] = (double)(w->cells[e].start - w->cells[f].start);
    n_cells[nl] = w->lv_n[i], l[nl++] = i + QK__LMIN;
  }
  for (int c = 1; c < nl; c++)
    for (int f = 0; f < c; f++) /* (a coarse level looked up from the fine cells: two rows each) */
      rows += n_obj[c] > 16 * (double)n_cells[f] ? 2 * (double)n_cells[f]
                                                 : n_obj[c] * (qk__pow2(l[c] - l[f] - 1) + 2);
  return rows > (double)w->n_order / 8;
}

int qk__world_by_bands(const qk_world_t *w) { return use_bands(w); }

/* Free the given buffers (a failure before the search ran). */
static qk_status_t search_nomem(const qk_world_t *w, qk__kvec_t *found, qk__kvec_t *tk) {
  qk__free(&w->alloc, found->v, found->cap * sizeof *found->v);
  for (unsigned t = 0; t < QK__KEEP_THREADS; t++) {
    qk__free(&w->alloc, tk[t].v, tk[t].cap * sizeof *tk[t].v);
    tk[t] = (qk__kvec_t){0};
  }
  return QK_ERR_NOMEM;
}

qk_status_t qk__world_search(const qk_world_t *w, const qk__wpack_t *pk, qk__kvec_t *out,
                             qk__kvec_t *tk, int *split, const float *prev, float *cur, int *cur_ok,
                             int *only_new) {
  *split = 0;
  *cur_ok = *only_new = 0;
  qk__kvec_t found = *out;
  found.n = 0;
  *out = (qk__kvec_t){0};
  lvinfo_t lv[QK__NLEV];
  int n_levels = 0;
  uint32_t *rf = NULL;
  size_t n_rf = 0;
  bands_t bd = {0};
  const int by_bands = w->by_bands; /* (use_bands, asked by qk__world_reorder) */
  unsigned nt = qk__world_update_threads(w);
  if (w->n_live < 4096) nt = 1; /* not worth a thread */
  /* Near candidates kept (marked), with room for the mark. */
  const int near_ok = cur && w->n_obj <= INT32_MAX;
  if (by_bands ? !build_bands(w, pk, &bd, prev, cur, near_ok, nt)
               : !level_info(w, pk, lv, &n_levels, &rf, &n_rf))
    return search_nomem(w, &found, tk);
  *cur_ok = by_bands && cur ? (!bd.exact ? 1 : bd.near ? 2 : 0) : 0;
  *only_new = bd.pg != NULL;
  /* Chunks of about equal work, taken in turn by the workers (many more than the
   * workers). By the grid, chunks of cells: an object's work grows with its size (the
   * finer cells its box covers): it is taken as 2^(l - finest level), so the few coarse
   * cells at the end of the order (which find most of the pairs of a mixed-size scene)
   * are spread over many chunks. By bands, chunks of bands of about equal entries. */
  enum { PER_THREAD = 32 };
  uint32_t chunk_one[2] = {0, by_bands ? bd.nb : w->n_cells}, *chunk = chunk_one;
  unsigned n_chunks = 1;
  if (nt > 1) {
    n_chunks = nt * PER_THREAD;
    chunk = qk__realloc(&w->alloc, NULL, 0, (n_chunks + 1) * sizeof *chunk);
    if (!chunk) {
      qk__free(&w->alloc, rf, n_rf * sizeof *rf);
      free_bands(w, &bd);
      return search_nomem(w, &found, tk);
    }
    unsigned i = 0;
    chunk[i++] = 0;
    if (by_bands) {
      for (uint32_t b = 0; b < bd.nb && i < n_chunks; b++)
        if ((double)bd.start[b + 1] >= (double)bd.start[bd.nb] * i / n_chunks) chunk[i++] = b + 1;
      while (i <= n_chunks) chunk[i++] = bd.nb;
    } else {
      grid_chunks(w, lv[0].l, chunk, n_chunks);
    }
  }
  atomic_uint next;
  atomic_init(&next, 0u);
  /* Every float box exact (the benchmark's scenes: boxes whose doubles are floats), the
   * padding lanes too (the pack marks them exact): then no run of the grid needs the
   * exactness bytes (measured: about six instructions a group of four tested, some 3%
   * of the uniform 10^4 frame's). */
  const uint32_t n_ord = w->n_cells ? w->cells[w->n_cells].start : 0;
  const int ax = !by_bands && !memchr(pk->fexact, 0, ((size_t)n_ord + 3) / 4 * 4);
  share_t shares[256];
  for (unsigned t = 0; t < nt; t++)
    shares[t] = (share_t){w, pk, {0}, &w->alloc, 0, lv, n_levels, chunk, n_chunks, &next, &bd, ax};
  /* The other workers start in the buffers given (those of the last update). */
  for (unsigned t = 1; t <= QK__KEEP_THREADS; t++) {
    if (t < nt)
      shares[t].out = tk[t - 1], shares[t].out.n = 0;
    else
      qk__free(&w->alloc, tk[t - 1].v, tk[t - 1].cap * sizeof *tk[t - 1].v);
    tk[t - 1] = (qk__kvec_t){0};
  }
  /* The first worker's buffer is the one given, or one sized by the last search (it
   * grows if need be). */
  size_t guess = w->last_found + w->last_found / 8 + 64;
  if (found.cap < guess) {
    qk__free(&w->alloc, found.v, found.cap * sizeof *found.v);
    found = (qk__kvec_t){0};
    found.v = qk__realloc(&w->alloc, NULL, 0, guess * sizeof *found.v);
    if (found.v) found.cap = guess;
  }
  shares[0].out = found;
  qk__world_run_jobs(w, nt, nt, by_bands ? run_bands : run_share, shares);
  found = shares[0].out;
  if (chunk != chunk_one) qk__free(&w->alloc, chunk, (n_chunks + 1) * sizeof *chunk);
  qk__free(&w->alloc, rf, n_rf * sizeof *rf);
  free_bands(w, &bd);
  qk_status_t st = QK_OK;
  size_t total = 0;
  for (unsigned t = 0; t < nt; t++) {
    if (shares[t].nomem) st = QK_ERR_NOMEM;
    total += shares[t].out.n;
  }
  /* All pairs in one list. */
  if (st == QK_OK && total > found.cap) {
    uint64_t *v = qk__realloc(&w->alloc, found.v, found.cap * sizeof *v, total * sizeof *v);
    if (v) {
      found.v = v;
      found.cap = total;
    } else {
      st = QK_ERR_NOMEM;
    }
  }
  /* With threads for the rows too (qk_world_update), the threads' keys stay where they
   * are: the rows' first pass reads each thread's own (no serial copy here). So do the
   * began ones (their join was 2 M instructions of the calling thread a frame at 10^5
   * clustered boxes on two threads, 300 000 keys copied). */
  int keep_split = nt > 1 && nt <= 1 + QK__KEEP_THREADS;
  if (st == QK_OK && !keep_split) {
    for (unsigned t = 1; t < nt; t++) {
      if (shares[t].out.n)
        memcpy(found.v + found.n, shares[t].out.v, shares[t].out.n * sizeof(uint64_t));
      found.n += shares[t].out.n;
    }
  }
  for (unsigned t = 1; t < nt; t++) {
    if (t <= QK__KEEP_THREADS) { /* given back, for the caller to keep or free */
      tk[t - 1] = shares[t].out;
      continue;
    }
    qk__free(&w->alloc, shares[t].out.v, shares[t].out.cap * sizeof(uint64_t));
  }
  if (st != QK_OK) {
    qk__free(&w->alloc, found.v, found.cap * sizeof *found.v);
    found = (qk__kvec_t){0};
  }
  *split = st == QK_OK && keep_split;
  *out = found;
  return st;
}
