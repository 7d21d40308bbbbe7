/*
 * The world's pair search (see collide/world.c for the design): every overlapping pair of
 * the order packed by the update, cell by cell, as unsorted 64-bit keys.
 */
#include <stdlib.h>
#include <string.h>

#include "collide/world_internal.h"

#if defined(__SSE2__)
#include <emmintrin.h>
#endif

/* One thread's share: a range of cells and the pairs found there. */
typedef struct share {
  const qk_world_t *w;
  const qk__wpack_t *pk;
  size_t lo, hi;
  qk__kvec_t out;
  const qk_allocator_t *alloc;
  int nomem;
  const int *levels;
  int n_levels;
} share_t;

static int kv_grow(const qk_allocator_t *a, qk__kvec_t *p) {
  size_t cap = p->cap ? p->cap * 2 : 256;
  uint64_t *v = qk__realloc(a, p->v, p->cap * sizeof *v, cap * sizeof *v);
  if (!v) return 0;
  p->v = v;
  p->cap = cap;
  return 1;
}

static inline int kv_push(share_t *s, uint32_t i, uint32_t j) {
  if (s->out.n == s->out.cap && !kv_grow(s->alloc, &s->out)) return 0;
  s->out.v[s->out.n++] = i < j ? (uint64_t)i << 32 | j : (uint64_t)j << 32 | i;
  return 1;
}

static inline int boxes_meet(const qk_box_t *a, const qk_box_t *b) {
  return a->xmin <= b->xmax && b->xmin <= a->xmax && a->ymin <= b->ymax && b->ymin <= a->ymax;
}

/* Test the objects of two slots exactly; record the pair when they overlap. */
static inline int try_pair(share_t *s, uint32_t i, uint32_t j) {
  const qk__wobj_t *p = &s->w->obj[i], *q = &s->w->obj[j];
  if ((p->flags & QK__WKIND) == QK_SHAPE_BOX && (q->flags & QK__WKIND) == QK_SHAPE_BOX) {
    /* Two boxes need nothing beyond their boxes. */
    if (!(p->x <= q->a && q->x <= p->a && p->y <= q->b && q->y <= p->b)) return 1;
  } else {
    qk_box_t pb = qk__wbox(p), qb = qk__wbox(q);
    if (!boxes_meet(&pb, &qb)) return 1;
    qk_shape_t ps = qk__wshape(p), qs = qk__wshape(q);
    if (!qk__shapes_overlap(&ps, &qs)) return 1;
  }
  return kv_push(s, i, j);
}

/*
 * The box prefilter. The boxes are copied as floats in the order, four objects to a
 * group (16 floats: 4 xmin, 4 ymin, 4 xmax, 4 ymax; lanes past the last object hold an
 * empty box), so one object is compared with four at once. Rounding to float is
 * monotone, so u <= v implies (float)u <= (float)v: every comparison of the box test
 * that holds in doubles holds in floats, and the prefilter never drops a pair whose
 * boxes meet. What it keeps is decided in doubles by try_pair.
 */

/* One object's float box, broadcast for the four-wide test. */
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

/* The pairs of lanes `bits` of group q with object k of the order. Two boxes whose
 * floats are exact have passed the exact box test already (the floats' comparisons are
 * the doubles'); the others are decided by try_pair. */
static inline int group_pairs(share_t *s, uint32_t k, uint32_t q, unsigned bits) {
  const uint32_t *ord = s->w->order;
  const uint8_t *fx = s->pk->fexact;
  uint32_t slot = ord[k];
  while (bits) {
    unsigned lane = (unsigned)__builtin_ctz(bits);
    bits &= bits - 1;
    uint32_t j = q * 4 + lane;
    if (fx[k] & fx[j]) {
      if (!kv_push(s, slot, ord[j])) return 0;
    } else if (!try_pair(s, slot, ord[j])) {
      return 0;
    }
  }
  return 1;
}

/* Object k of the order against the objects at order positions [lo, hi) (lo < hi): the
 * first and last groups masked to the range, the ones between whole. */
static inline int obj_vs_range(share_t *s, uint32_t k, uint32_t lo, uint32_t hi) {
  const float *fg = s->pk->fgrp;
  probe_t p = probe_of(lane_of(fg, k));
  uint32_t q = lo >> 2, qe = (hi - 1) >> 2;
  unsigned first = ~((1u << (lo & 3)) - 1) & 15u, last = (2u << ((hi - 1) & 3)) - 1;
  if (q == qe) return group_pairs(s, k, q, group_hits(fg + (size_t)q * 16, &p) & first & last);
  if (!group_pairs(s, k, q, group_hits(fg + (size_t)q * 16, &p) & first)) return 0;
  for (q++; q < qe; q++) {
    unsigned bits = group_hits(fg + (size_t)q * 16, &p);
    if (bits && !group_pairs(s, k, q, bits)) return 0;
  }
  return group_pairs(s, k, qe, group_hits(fg + (size_t)qe * 16, &p) & last);
}

/* Every object of cell a against the objects at order positions [blo, bhi) (other
 * cells' objects), whose boxes lie in ub. */
static int cross_run(share_t *s, uint32_t a, uint32_t blo, uint32_t bhi, const qk_box_t *ub) {
  const qk__wcell_t *cl = s->w->cells;
  const float *fg = s->pk->fgrp;
  /* ub as floats, for a one-lane check of each of a's objects first. */
  float bx0 = (float)ub->xmin, by0 = (float)ub->ymin, bx1 = (float)ub->xmax, by1 = (float)ub->ymax;
  for (uint32_t k = cl[a].start, ke = cl[a + 1].start; k < ke; k++) {
    const float *me = lane_of(fg, k);
    if (!(me[0] <= bx1 && bx0 <= me[8] && me[4] <= by1 && by0 <= me[12])) continue;
    if (!obj_vs_range(s, k, blo, bhi)) return 0;
  }
  return 1;
}

/* Every object of cell a against every object of cell b (a != b). */
static inline int cross_cells(share_t *s, uint32_t a, uint32_t b) {
  const qk_box_t *hb = &s->pk->hb[b];
  if (!boxes_meet(&s->pk->hb[a], hb)) return 1;
  return cross_run(s, a, s->w->cells[b].start, s->w->cells[b + 1].start, hb);
}

/* Cell a against the cells of the coarser level l whose loose squares
 * [c 2^l, (c + 2) 2^l) meet the box around a's objects: c from floor(min / 2^l) - 1 to
 * floor(max / 2^l), each row found by binary search. */
static int cell_vs_level(share_t *s, uint32_t a, int l) {
  const qk_world_t *w = s->w;
  const qk_box_t *hb = &s->pk->hb[a];
  const double inv = qk__pow2(-l);
  int64_t x0 = (int64_t)floor(hb->xmin * inv) - 1, x1 = (int64_t)floor(hb->xmax * inv);
  int64_t y0 = (int64_t)floor(hb->ymin * inv) - 1, y1 = (int64_t)floor(hb->ymax * inv);
  uint32_t end = w->lv_first[l - QK__LMIN] + w->lv_n[l - QK__LMIN];
  for (int64_t y = y0; y <= y1; y++)
    for (uint32_t k = qk__cell_lower(w, l, y, x0);
         k < end && w->cells[k].cy == y && w->cells[k].cx <= x1; k++)
      if (!cross_cells(s, a, k)) return 0;
  return 1;
}

/* The pairs of cell a: within it, with the cells of its level after it whose loose
 * squares meet its own (indices differing by at most one: the next cell of its row and
 * three of the row above, found by *up, a cursor that only moves forward), and with the
 * cells of every coarser level that its objects can meet. */
static int cell_pairs(share_t *s, uint32_t a, uint32_t *up) {
  const qk_world_t *w = s->w;
  const qk__wcell_t *c = &w->cells[a];
  const qk_box_t *hb = s->pk->hb, *ha = &hb[a];
  int l = c->level;
  /* Within the cell, and with the next cell of its row when adjacent: its objects follow
   * in the order, so each object meets one run of the ones after it. */
  uint32_t lo = c->start, hi = c[1].start, hi2 = hi;
  if (c[1].level == l && c[1].cy == c->cy && c[1].cx == c->cx + 1 && boxes_meet(ha, &hb[a + 1]))
    hi2 = c[2].start;
  for (uint32_t k = lo; k < hi && k + 1 < hi2; k++)
    if (!obj_vs_range(s, k, k + 1, hi2)) return 0;
  /* The row above: up to three consecutive cells, so one run too (without the end cells
   * whose boxes miss this one's). */
  uint32_t end = w->lv_first[l - QK__LMIN] + w->lv_n[l - QK__LMIN];
  uint32_t u = *up > a + 1 ? *up : a + 1;
  int64_t ty = (int64_t)c->cy + 1, tx = (int64_t)c->cx - 1;
  while (u < end && (w->cells[u].cy < ty || (w->cells[u].cy == ty && w->cells[u].cx < tx))) u++;
  *up = u;
  uint32_t u1 = u;
  while (u1 < end && w->cells[u1].cy == ty && w->cells[u1].cx <= tx + 2) u1++;
  while (u < u1 && !boxes_meet(ha, &hb[u])) u++;
  while (u1 > u && !boxes_meet(ha, &hb[u1 - 1])) u1--;
  if (u < u1) {
    qk_box_t ub = hb[u];
    for (uint32_t k = u + 1; k < u1; k++) {
      ub.xmin = qk__min(ub.xmin, hb[k].xmin), ub.ymin = qk__min(ub.ymin, hb[k].ymin);
      ub.xmax = qk__max(ub.xmax, hb[k].xmax), ub.ymax = qk__max(ub.ymax, hb[k].ymax);
    }
    if (!cross_run(s, a, w->cells[u].start, w->cells[u1].start, &ub)) return 0;
  }
  /* Coarser levels whose objects' box meets this cell's. */
  for (int li = 0; li < s->n_levels; li++) {
    int lb = s->levels[li];
    if (lb <= l || !boxes_meet(&s->pk->hb[a], &s->pk->lv_box[lb - QK__LMIN])) continue;
    if (!cell_vs_level(s, a, lb)) return 0;
  }
  return 1;
}

static void run_share(unsigned t, void *ud) {
  share_t *s = &((share_t *)ud)[t];
  uint32_t up = 0;
  for (size_t i = s->lo; i < s->hi; i++) {
    if (!cell_pairs(s, (uint32_t)i, &up)) {
      s->nomem = 1;
      return;
    }
  }
}

qk_status_t qk__world_search(const qk_world_t *w, const qk__wpack_t *pk, qk__kvec_t *out) {
  int levels[QK__NLEV];
  int n_levels = qk__world_levels(w, levels);
  unsigned nt = w->opt.threads;
  if (w->n_live < 4096) nt = 1; /* not worth a thread */
  share_t shares[256];
  for (unsigned t = 0; t < nt; t++)
    shares[t] = (share_t){w,
                          pk,
                          (size_t)w->n_cells * t / nt,
                          (size_t)w->n_cells * (t + 1) / nt,
                          {0},
                          &w->alloc,
                          0,
                          levels,
                          n_levels};
  /* The first share's buffer is sized by the last search (it grows if need be). */
  qk__kvec_t found = {0};
  size_t guess = w->last_found + w->last_found / 8 + 64;
  found.v = qk__realloc(&w->alloc, NULL, 0, guess * sizeof *found.v);
  if (found.v) found.cap = guess;
  shares[0].out = found;
  qk__run_jobs(nt, nt, run_share, shares);
  found = shares[0].out;
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
  if (st == QK_OK) {
    for (unsigned t = 1; t < nt; t++) {
      if (shares[t].out.n)
        memcpy(found.v + found.n, shares[t].out.v, shares[t].out.n * sizeof(uint64_t));
      found.n += shares[t].out.n;
    }
  }
  for (unsigned t = 1; t < nt; t++)
    qk__free(&w->alloc, shares[t].out.v, shares[t].out.cap * sizeof(uint64_t));
  if (st != QK_OK) {
    qk__free(&w->alloc, found.v, found.cap * sizeof *found.v);
    found = (qk__kvec_t){0};
  }
  *out = found;
  return st;
}
