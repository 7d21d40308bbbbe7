/*
 * The world's frame: all overlapping pairs from the loose grid (see collide/world.c for
 * the design), sorted, and the began / ended sets by merging with the previous frame.
 */
#include <stdlib.h>
#include <string.h>

#include "collide/world_internal.h"

#if defined(__SSE2__)
#include <emmintrin.h>
#endif

/* One thread's share: a range of table entries and the pairs found there. */
typedef struct share {
  const qk_world_t *w;
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

/* Test two packed objects; record the pair when they overlap. */
static inline int try_pair(share_t *s, const qk__wpack_t *p, const qk__wpack_t *q) {
  if (!boxes_meet(&p->box, &q->box)) return 1;
  const qk_world_t *w = s->w;
  uint32_t i = p->slot, j = q->slot;
  /* Two boxes need nothing beyond their boxes, which are exact for them. */
  if (!(p->is_box && q->is_box) && !qk__shapes_overlap(&w->obj[i].s, &w->obj[j].s)) return 1;
  return kv_push(s, i, j);
}

/*
 * The box prefilter. Besides the packed doubles, each cell's boxes are copied as floats,
 * four objects to a group (16 floats: 4 xmin, 4 ymin, 4 xmax, 4 ymax; missing lanes hold
 * an empty box), so one object is compared with four at once. Rounding to float is
 * monotone, so u <= v implies (float)u <= (float)v: every comparison of the box test
 * that holds in doubles holds in floats, and the prefilter never drops a pair whose
 * boxes meet. What it keeps is decided in doubles by try_pair.
 */

/* Lanes of group g whose float boxes meet the box (x0, y0, x1, y1): a 4-bit mask. */
static inline unsigned group_hits(const float *g, const float *me) {
#if defined(__SSE2__)
  __m128 m = _mm_and_ps(_mm_cmple_ps(_mm_loadu_ps(g), _mm_set1_ps(me[8])),
                        _mm_cmple_ps(_mm_set1_ps(me[0]), _mm_loadu_ps(g + 8)));
  m = _mm_and_ps(m, _mm_and_ps(_mm_cmple_ps(_mm_loadu_ps(g + 4), _mm_set1_ps(me[12])),
                               _mm_cmple_ps(_mm_set1_ps(me[4]), _mm_loadu_ps(g + 12))));
  return (unsigned)_mm_movemask_ps(m);
#else
  unsigned bits = 0;
  for (int k = 0; k < 4; k++)
    bits |=
        (unsigned)(g[k] <= me[8] && me[0] <= g[8 + k] && g[4 + k] <= me[12] && me[4] <= g[12 + k])
        << k;
  return bits;
#endif
}

/* Object k of a cell (its lane in the float groups starting at f). */
static inline const float *lane_of(const float *f, uint32_t k) {
  return f + (k >> 2) * 16 + (k & 3);
}

/* Object i of cell A (pack entry pi, float lane me) against the objects of cell B from
 * its group q0 on, lanes below `from` of that first group excluded. */
static inline int obj_vs_groups(share_t *s, const qk__wpack_t *pi, const float *me,
                                const qk__wcell_t *b, uint32_t q0, unsigned from) {
  const qk_world_t *w = s->w;
  const qk__wpack_t *pk = w->pack;
  const float *fb = w->fgrp + (size_t)pk[b->start].is_box * 16;
  uint32_t ng = (b->count + 3) >> 2;
  for (uint32_t q = q0; q < ng; q++) {
    unsigned bits = group_hits(fb + (size_t)q * 16, me);
    if (q == q0) bits &= ~((1u << from) - 1);
    while (bits) {
      unsigned lane = (unsigned)__builtin_ctz(bits);
      bits &= bits - 1;
      if (!try_pair(s, pi, &pk[b->start + 1 + q * 4 + lane])) return 0;
    }
  }
  return 1;
}

/* Every object of cell A against every object of cell B (A != B). */
static int cross_cells(share_t *s, const qk__wcell_t *a, const qk__wcell_t *b) {
  const qk__wpack_t *pk = s->w->pack;
  const qk_box_t *hb = &pk[b->start].box; /* the box around all of B's objects */
  if (!boxes_meet(&pk[a->start].box, hb)) return 1;
  const float *fa = s->w->fgrp + (size_t)pk[a->start].is_box * 16;
  for (uint32_t k = 0; k < a->count; k++) {
    const qk__wpack_t *pi = &pk[a->start + 1 + k];
    if (!boxes_meet(&pi->box, hb)) continue;
    if (!obj_vs_groups(s, pi, lane_of(fa, k), b, 0, 0)) return 0;
  }
  return 1;
}

/* Cell A against the cells of level l whose loose squares [c 2^l, (c + 2) 2^l) meet the
 * box around A's objects: c from floor(min / 2^l) - 1 to floor(max / 2^l). */
static int cell_vs_level(share_t *s, const qk__wcell_t *a, int l) {
  const qk_world_t *w = s->w;
  const qk_box_t *hb = &w->pack[a->start].box;
  const double inv = qk__pow2(-l);
  int64_t x0 = (int64_t)floor(hb->xmin * inv) - 1, x1 = (int64_t)floor(hb->xmax * inv);
  int64_t y0 = (int64_t)floor(hb->ymin * inv) - 1, y1 = (int64_t)floor(hb->ymax * inv);
  for (int64_t x = x0; x <= x1; x++)
    for (int64_t y = y0; y <= y1; y++) {
      const qk__wcell_t *b = qk__cell_get(w, l, x, y);
      if (b && !cross_cells(s, a, b)) return 0;
    }
  return 1;
}

static int cell_pairs(share_t *s, const qk__wcell_t *a) {
  const qk_world_t *w = s->w;
  const qk__wpack_t *pk = w->pack;
  /* Within the cell: each object with those after it. */
  const float *fa = w->fgrp + (size_t)pk[a->start].is_box * 16;
  for (uint32_t k = 0; k + 1 < a->count; k++)
    if (!obj_vs_groups(s, &pk[a->start + 1 + k], lane_of(fa, k), a, (k + 1) >> 2, (k + 1) & 3))
      return 0;
  /* The same level: loose squares [c, c + 2) meet when the indices differ by <= 1; each
   * neighbour pair is taken once, from the cell that comes first in (x, y) order. */
  for (int dx = 0; dx <= 1; dx++)
    for (int dy = -1; dy <= 1; dy++) {
      if (dx == 0 && dy <= 0) continue;
      const qk__wcell_t *b = qk__cell_get(w, a->level, a->cx + dx, a->cy + dy);
      if (b && !cross_cells(s, a, b)) return 0;
    }
  /* Coarser levels: the cells whose loose squares meet the box around this cell's
   * objects (about four per level: that box is much smaller than the cell's loose
   * square, and one set of lookups serves all of the cell's objects). */
  for (int li = 0; li < s->n_levels; li++) {
    int lb = s->levels[li];
    if (lb > a->level && !cell_vs_level(s, a, lb)) return 0;
  }
  return 1;
}

static void run_share(unsigned t, void *ud) {
  share_t *s = &((share_t *)ud)[t];
  for (size_t i = s->lo; i < s->hi; i++) {
    const qk__wcell_t *c = &s->w->cells[s->w->occ[i]];
    if (!cell_pairs(s, c)) {
      s->nomem = 1;
      return;
    }
  }
}

/* Copy every object's box into the packed array, cell by cell, each cell's objects after
 * a header holding the box around them, and note where each cell starts. The searches
 * then read consecutive memory, not the objects' lists, and skip a neighbour cell whole
 * when its box misses (or, for one object, misses that object). */
static qk_status_t pack_cells(qk_world_t *w) {
  /* One header entry per cell (the box around its objects), then its objects; float
   * groups: a quarter of the objects plus one per cell at most. */
  size_t need = w->n_live + w->n_cells + 1, gneed = w->n_live / 4 + w->n_cells + 1;
  size_t oneed = w->n_cells + 1;
  if (w->cap_pack < need || w->cap_pack > 2 * need + 64 || w->cap_fgrp < gneed ||
      w->cap_fgrp > 2 * gneed + 64 || w->cap_occ < oneed || w->cap_occ > 2 * oneed + 64) {
    size_t cap = need + need / 4, gcap = gneed + gneed / 4, ocap = oneed + oneed / 4;
    qk__wpack_t *p = qk__realloc(&w->alloc, NULL, 0, cap * sizeof *p);
    float *g = p ? qk__realloc(&w->alloc, NULL, 0, gcap * 16 * sizeof *g) : NULL;
    uint32_t *o = g ? qk__realloc(&w->alloc, NULL, 0, ocap * sizeof *o) : NULL;
    if (!o) {
      qk__free(&w->alloc, p, cap * sizeof *p);
      qk__free(&w->alloc, g, gcap * 16 * sizeof *g);
      return QK_ERR_NOMEM;
    }
    qk__free(&w->alloc, w->pack, w->cap_pack * sizeof *w->pack);
    qk__free(&w->alloc, w->fgrp, w->cap_fgrp * 16 * sizeof *w->fgrp);
    qk__free(&w->alloc, w->occ, w->cap_occ * sizeof *w->occ);
    w->pack = p;
    w->cap_pack = cap;
    w->fgrp = g;
    w->cap_fgrp = gcap;
    w->occ = o;
    w->cap_occ = ocap;
  }
  uint32_t k = 0, gk = 0, nocc = 0;
  for (size_t c = 0; c < w->cap_cells; c++) {
    qk__wcell_t *cell = &w->cells[c];
    if (!cell->count) continue;
    w->occ[nocc++] = (uint32_t)c;
    uint32_t h = k++, lane = 0;
    float *g = w->fgrp + (size_t)gk * 16;
    qk_box_t hb = {INFINITY, INFINITY, -INFINITY, -INFINITY};
    for (uint32_t i = cell->head; i != QK_NONE; i = w->obj[i].next) {
      const qk_box_t *b = &w->obj[i].box;
      w->pack[k++] = (qk__wpack_t){*b, i, w->obj[i].s.kind == QK_SHAPE_BOX};
      hb.xmin = qk__min(hb.xmin, b->xmin), hb.ymin = qk__min(hb.ymin, b->ymin);
      hb.xmax = qk__max(hb.xmax, b->xmax), hb.ymax = qk__max(hb.ymax, b->ymax);
      g[lane] = (float)b->xmin, g[4 + lane] = (float)b->ymin;
      g[8 + lane] = (float)b->xmax, g[12 + lane] = (float)b->ymax;
      if (++lane == 4) lane = 0, g += 16;
    }
    for (; lane && lane < 4; lane++) /* empty lanes: a box that meets nothing */
      g[lane] = g[4 + lane] = INFINITY, g[8 + lane] = g[12 + lane] = -INFINITY;
    /* the header's is_box holds the cell's first float group */
    w->pack[h] = (qk__wpack_t){hb, QK_NONE, gk};
    gk += (cell->count + 3) >> 2;
    cell->start = h;
  }
  return QK_OK;
}

/* Room for n entries of `size` bytes in a list of capacity *cap: NULL when the present
 * buffer will do (it holds n and is not far too large), else a new buffer (its capacity
 * in *ncap), or NULL with *fail set when memory is short and the present one is too
 * small. A shrink that fails is harmless: the present buffer is kept. */
static void *list_room(const qk_allocator_t *a, size_t cap, size_t n, size_t size, size_t slack,
                       size_t *ncap, int *fail) {
  size_t want = n + n / 4 + slack;
  if (cap >= n && cap <= 2 * want) return NULL;
  void *p = qk__realloc(a, NULL, 0, want * size);
  if (!p && cap < n) *fail = 1;
  *ncap = want;
  return p;
}

/* Make v hold at least n keys (contents not kept); 0 when memory is short. */
static int kv_size(const qk_allocator_t *a, qk__kvec_t *v, size_t n) {
  size_t ncap;
  int fail = 0;
  uint64_t *p = list_room(a, v->cap, n, sizeof *p, 16, &ncap, &fail);
  if (fail) return 0;
  if (p) {
    qk__free(a, v->v, v->cap * sizeof *v->v);
    v->v = p;
    v->cap = ncap;
  }
  return 1;
}

/* Sort n keys into dst: two stable counting sorts, by the second slot then by the first
 * (count has n_obj + 1 entries), through src, which ends as scratch. Each pass is a count
 * and a scatter, whatever the lengths of the runs. */
static void sort_keys(uint64_t *src, uint64_t *dst, size_t n, uint32_t *count, uint32_t n_obj) {
  if (n == 0) return; /* src may be NULL then */
  memset(count, 0, ((size_t)n_obj + 1) * sizeof *count);
  for (size_t i = 0; i < n; i++) count[(uint32_t)src[i] + 1]++;
  for (uint32_t a = 1; a <= n_obj; a++) count[a] += count[a - 1];
  for (size_t i = 0; i < n; i++) dst[count[(uint32_t)src[i]]++] = src[i];
  memset(count, 0, ((size_t)n_obj + 1) * sizeof *count);
  for (size_t i = 0; i < n; i++) count[(dst[i] >> 32) + 1]++;
  for (uint32_t a = 1; a <= n_obj; a++) count[a] += count[a - 1];
  for (size_t i = 0; i < n; i++) src[count[dst[i] >> 32]++] = dst[i];
  memcpy(dst, src, n * sizeof *dst);
}

/* A slot's object is not the one it held at the last update (removed, or a new one). */
static inline int changed(const qk_world_t *w, uint32_t s) {
  return s >= w->n_obj || w->obj[s].gen != w->obj[s].ugen;
}

static inline qk_world_pair_t old_pair(const qk_world_t *w, uint64_t k) {
  return qk__key_pair(w, k);
}

qk_status_t qk_world_update(qk_world_t *w) {
  if (!w) return QK_ERR_INVALID;
  qk_status_t pst = pack_cells(w);
  if (pst != QK_OK) return pst;
  int levels[QK__NLEV];
  int n_levels = qk__world_levels(w, levels);
  unsigned nt = w->opt.threads;
  if (w->n_live < 4096) nt = 1; /* not worth a thread */
  share_t shares[256];
  for (unsigned t = 0; t < nt; t++) {
    shares[t] = (share_t){
        w, w->n_cells * t / nt, w->n_cells * (t + 1) / nt, {0}, &w->alloc, 0, levels, n_levels};
  }
  shares[0].out = w->found; /* the first share fills the kept buffer */
  shares[0].out.n = 0;
  qk__run_jobs(nt, nt, run_share, shares);
  w->found = shares[0].out;
  qk_status_t st = QK_OK;
  size_t total = 0;
  for (unsigned t = 0; t < nt; t++) {
    if (shares[t].nomem) st = QK_ERR_NOMEM;
    total += shares[t].out.n;
  }
  /* Scratch sized before anything changes: all pairs in one list, the sort's target and
   * its counts. */
  if (st == QK_OK && total > w->found.cap) {
    uint64_t *v = qk__realloc(&w->alloc, w->found.v, w->found.cap * sizeof *v, total * sizeof *v);
    if (v) {
      w->found.v = v;
      w->found.cap = total;
    } else {
      st = QK_ERR_NOMEM;
    }
  }
  if (st == QK_OK) {
    for (unsigned t = 1; t < nt; t++) {
      if (shares[t].out.n)
        memcpy(w->found.v + w->found.n, shares[t].out.v, shares[t].out.n * sizeof(uint64_t));
      w->found.n += shares[t].out.n;
    }
  }
  for (unsigned t = 1; t < nt; t++)
    qk__free(&w->alloc, shares[t].out.v, shares[t].out.cap * sizeof(uint64_t));
  /* The new list (the old one is freed once merged). */
  size_t ncap = total + total / 8 + 16;
  uint64_t *nv = NULL;
  if (st == QK_OK && !(nv = qk__realloc(&w->alloc, NULL, 0, ncap * sizeof *nv))) st = QK_ERR_NOMEM;
  size_t need_count = (size_t)w->n_obj + 1;
  if (st == QK_OK && (w->cap_count < need_count || w->cap_count > 2 * need_count + 64)) {
    uint32_t *c = qk__realloc(&w->alloc, NULL, 0, need_count * sizeof *c);
    if (c) {
      qk__free(&w->alloc, w->count, w->cap_count * sizeof *w->count);
      w->count = c;
      w->cap_count = need_count;
    } else if (w->cap_count < need_count) {
      st = QK_ERR_NOMEM;
    }
  }
  if (st != QK_OK) {
    qk__free(&w->alloc, nv, ncap * sizeof *nv);
    return st;
  }
  sort_keys(w->found.v, nv, total, w->count, w->n_obj);
  /* Began and ended: a merge of this frame's keys with the last frame's, counted first so
   * the lists can be sized before either changes. A pair whose slot now holds another
   * object (or none) has ended, and a pair with such a slot has begun. */
  const uint64_t *ov = w->cur.v;
  size_t nn = total, on = w->cur.n;
  int dirty = w->ident_dirty;
  size_t n_began = 0, n_ended = 0;
  for (size_t i = 0, j = 0; i < nn || j < on;) {
    if (j == on || (i < nn && nv[i] < ov[j]))
      n_began++, i++;
    else if (i == nn || nv[i] > ov[j])
      n_ended++, j++;
    else {
      if (dirty && (changed(w, (uint32_t)(nv[i] >> 32)) || changed(w, (uint32_t)nv[i])))
        n_began++, n_ended++;
      i++, j++;
    }
  }
  /* Both lists' room before either changes: a failure keeps the last frame's lists. */
  size_t bcap = 0, ecap = 0;
  int fail = 0;
  uint64_t *bv = list_room(&w->alloc, w->began.cap, n_began, sizeof *bv, 16, &bcap, &fail);
  qk_world_pair_t *ev =
      fail ? NULL : list_room(&w->alloc, w->ended.cap, n_ended, sizeof *ev, 16, &ecap, &fail);
  if (fail) {
    qk__free(&w->alloc, bv, bcap * sizeof *bv);
    qk__free(&w->alloc, nv, ncap * sizeof *nv);
    return QK_ERR_NOMEM;
  }
  if (bv) {
    qk__free(&w->alloc, w->began.v, w->began.cap * sizeof *bv);
    w->began.v = bv, w->began.cap = bcap;
  }
  if (ev) {
    qk__free(&w->alloc, w->ended.v, w->ended.cap * sizeof *ev);
    w->ended.v = ev, w->ended.cap = ecap;
  }
  w->began.n = w->ended.n = 0;
  for (size_t i = 0, j = 0; i < nn || j < on;) {
    if (j == on || (i < nn && nv[i] < ov[j]))
      w->began.v[w->began.n++] = nv[i++];
    else if (i == nn || nv[i] > ov[j])
      w->ended.v[w->ended.n++] = old_pair(w, ov[j++]);
    else {
      if (dirty && (changed(w, (uint32_t)(nv[i] >> 32)) || changed(w, (uint32_t)nv[i]))) {
        w->began.v[w->began.n++] = nv[i];
        w->ended.v[w->ended.n++] = old_pair(w, ov[j]);
      }
      i++, j++;
    }
  }
  /* This frame's keys become the current list, and the handles they stand for are the
   * present generations. */
  qk__free(&w->alloc, w->cur.v, w->cur.cap * sizeof *w->cur.v);
  w->cur = (qk__kvec_t){nv, total, ncap};
  if (dirty) {
    for (uint32_t i = 0; i < w->n_obj; i++) w->obj[i].ugen = w->obj[i].gen;
    w->ident_dirty = 0;
  }
  /* Give back what a peak left in the scratch (failure is harmless). */
  (void)kv_size(&w->alloc, &w->found, total);
  return QK_OK;
}

qk_status_t qk_world_pairs(const qk_world_t *w, qk_pairs_which_t which, qk_world_pair_fn fn,
                           void *ud) {
  if (!w || !fn) return QK_ERR_INVALID;
  if (which == QK_PAIRS_ENDED) {
    for (size_t i = 0; i < w->ended.n; i++)
      if (fn(w->ended.v[i].a, w->ended.v[i].b, ud)) break;
    return QK_OK;
  }
  if (which != QK_PAIRS_ALL && which != QK_PAIRS_BEGAN) return QK_ERR_INVALID;
  const qk__kvec_t *p = which == QK_PAIRS_ALL ? &w->cur : &w->began;
  for (size_t i = 0; i < p->n; i++) {
    qk_world_pair_t q = qk__key_pair(w, p->v[i]);
    if (fn(q.a, q.b, ud)) break;
  }
  return QK_OK;
}

qk_status_t qk_world_pairs_list(const qk_world_t *w, qk_pairs_which_t which, qk_world_pair_t *out,
                                size_t cap, size_t *n_out) {
  if (!w || !n_out || (cap && !out)) return QK_ERR_INVALID;
  if (which == QK_PAIRS_ENDED) {
    *n_out = w->ended.n;
    if (w->ended.n && cap)
      memcpy(out, w->ended.v, (w->ended.n < cap ? w->ended.n : cap) * sizeof *out);
    return QK_OK;
  }
  if (which != QK_PAIRS_ALL && which != QK_PAIRS_BEGAN) return QK_ERR_INVALID;
  const qk__kvec_t *p = which == QK_PAIRS_ALL ? &w->cur : &w->began;
  *n_out = p->n;
  size_t m = p->n < cap ? p->n : cap;
  for (size_t i = 0; i < m; i++) out[i] = qk__key_pair(w, p->v[i]);
  return QK_OK;
}
