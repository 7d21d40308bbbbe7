/*
 * The world's frame: all overlapping pairs from the loose grid (see collide/world.c for
 * the design), sorted, and the began / ended sets by merging with the previous frame.
 */
#include <stdlib.h>
#include <string.h>

#include "collide/world_internal.h"

/* One thread's share: a range of table entries and the pairs found there. */
typedef struct share {
  const qk_world_t *w;
  size_t lo, hi;
  qk__pvec_t out;
  int nomem;
  const int *levels;
  int n_levels;
} share_t;

static int pv_push(const qk_allocator_t *a, qk__pvec_t *p, qk_handle_t x, qk_handle_t y) {
  if (p->n == p->cap) {
    size_t cap = p->cap ? p->cap * 2 : 256;
    qk_world_pair_t *v = qk__realloc(a, p->v, p->cap * sizeof *v, cap * sizeof *v);
    if (!v) return 0;
    p->v = v;
    p->cap = cap;
  }
  p->v[p->n].a = x;
  p->v[p->n++].b = y;
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
  if (i > j) {
    uint32_t t = i;
    i = j;
    j = t;
  }
  return pv_push(&w->alloc, &s->out, qk__handle(w, i), qk__handle(w, j));
}

/* Every object of cell A against every object of cell B (A != B). */
static int cross_cells(share_t *s, const qk__wcell_t *a, const qk__wcell_t *b) {
  const qk__wpack_t *pk = s->w->pack;
  const qk_box_t *hb = &pk[b->start].box; /* the box around all of B's objects */
  if (!boxes_meet(&pk[a->start].box, hb)) return 1;
  for (uint32_t i = a->start + 1; i <= a->start + a->count; i++) {
    if (!boxes_meet(&pk[i].box, hb)) continue;
    for (uint32_t j = b->start + 1; j <= b->start + b->count; j++)
      if (!try_pair(s, &pk[i], &pk[j])) return 0;
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
      const qk__wcell_t *b = qk__world_cell(w, l, x, y);
      if (b && !cross_cells(s, a, b)) return 0;
    }
  return 1;
}

static int cell_pairs(share_t *s, const qk__wcell_t *a) {
  const qk_world_t *w = s->w;
  const qk__wpack_t *pk = w->pack;
  /* Within the cell. */
  for (uint32_t i = a->start + 1; i <= a->start + a->count; i++)
    for (uint32_t j = i + 1; j <= a->start + a->count; j++)
      if (!try_pair(s, &pk[i], &pk[j])) return 0;
  /* The same level: loose squares [c, c + 2) meet when the indices differ by <= 1; each
   * neighbour pair is taken once, from the cell that comes first in (x, y) order. */
  for (int dx = 0; dx <= 1; dx++)
    for (int dy = -1; dy <= 1; dy++) {
      if (dx == 0 && dy <= 0) continue;
      const qk__wcell_t *b = qk__world_cell(w, a->level, a->cx + dx, a->cy + dy);
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
    const qk__wcell_t *c = &s->w->cells[i];
    if (c->count && !cell_pairs(s, c)) {
      s->nomem = 1;
      return;
    }
  }
}

static int pair_cmp(const void *x, const void *y) {
  const qk_world_pair_t *p = x, *q = y;
  uint32_t pa = (uint32_t)p->a, qa = (uint32_t)q->a, pb = (uint32_t)p->b, qb = (uint32_t)q->b;
  if (pa != qa) return pa < qa ? -1 : 1;
  return (pb > qb) - (pb < qb);
}

/* The total order of a merge: slots, then generations (a slot reused within one frame
 * makes a different pair). */
static int pair_cmp_gen(const qk_world_pair_t *p, const qk_world_pair_t *q) {
  int c = pair_cmp(p, q);
  if (c) return c;
  if (p->a != q->a) return p->a < q->a ? -1 : 1;
  return (p->b > q->b) - (p->b < q->b);
}

static int pv_reserve(const qk_allocator_t *a, qk__pvec_t *p, size_t n) {
  /* Exact-ish sizing, so the lists follow the pair count down as well as up. */
  size_t cap = n + n / 8 + 16;
  qk_world_pair_t *v = qk__realloc(a, NULL, 0, cap * sizeof *v);
  if (!v) return 0;
  p->v = v;
  p->cap = cap;
  return 1;
}

/* Copy every object's box into the packed array, cell by cell, each cell's objects after
 * a header holding the box around them, and note where each cell starts. The searches
 * then read consecutive memory, not the objects' lists, and skip a neighbour cell whole
 * when its box misses (or, for one object, misses that object). */
static qk_status_t pack_cells(qk_world_t *w) {
  /* One header entry per cell (the box around its objects), then its objects. */
  size_t need = w->n_live + w->n_cells + 1;
  if (w->cap_pack < need || w->cap_pack > 2 * need + 64) {
    size_t cap = need + need / 4;
    qk__wpack_t *p = qk__realloc(&w->alloc, NULL, 0, cap * sizeof *p);
    if (!p) return QK_ERR_NOMEM;
    qk__free(&w->alloc, w->pack, w->cap_pack * sizeof *w->pack);
    w->pack = p;
    w->cap_pack = cap;
  }
  uint32_t k = 0;
  for (size_t c = 0; c < w->cap_cells; c++) {
    qk__wcell_t *cell = &w->cells[c];
    if (!cell->count) continue;
    uint32_t h = k++;
    qk_box_t hb = {INFINITY, INFINITY, -INFINITY, -INFINITY};
    for (uint32_t i = cell->head; i != QK_NONE; i = w->obj[i].next) {
      const qk_box_t *b = &w->obj[i].box;
      w->pack[k++] = (qk__wpack_t){*b, i, w->obj[i].s.kind == QK_SHAPE_BOX};
      hb.xmin = qk__min(hb.xmin, b->xmin), hb.ymin = qk__min(hb.ymin, b->ymin);
      hb.xmax = qk__max(hb.xmax, b->xmax), hb.ymax = qk__max(hb.ymax, b->ymax);
    }
    w->pack[h] = (qk__wpack_t){hb, QK_NONE, 0};
    cell->start = h;
  }
  return QK_OK;
}

/* Sort pairs by (slot a, slot b): LSD radix sort on 11-bit digits of b, then of a,
 * skipping digits that are zero everywhere; tmp holds as many pairs. */
static void sort_pairs(qk_world_pair_t *v, qk_world_pair_t *tmp, size_t n) {
  uint32_t hi_a = 0, hi_b = 0;
  int swaps = 0;
  for (size_t i = 0; i < n; i++) {
    hi_a |= (uint32_t)v[i].a;
    hi_b |= (uint32_t)v[i].b;
  }
  for (int pass = 0; pass < 6; pass++) {
    int shift = (pass % 3) * 11, on_a = pass >= 3;
    if ((((on_a ? hi_a : hi_b) >> shift) & 0x7ff) == 0) continue;
    size_t count[2049];
    memset(count, 0, sizeof count);
    for (size_t i = 0; i < n; i++) {
      uint32_t key = (uint32_t)(on_a ? v[i].a : v[i].b);
      count[((key >> shift) & 0x7ff) + 1]++;
    }
    for (size_t d = 1; d <= 2048; d++) count[d] += count[d - 1];
    for (size_t i = 0; i < n; i++) {
      uint32_t key = (uint32_t)(on_a ? v[i].a : v[i].b);
      tmp[count[(key >> shift) & 0x7ff]++] = v[i];
    }
    qk_world_pair_t *t = v; /* the sorted run is in tmp now: swap roles */
    v = tmp;
    tmp = t;
    swaps++;
  }
  if (swaps & 1) memcpy(tmp, v, n * sizeof *v); /* back into the caller's array */
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
    shares[t] =
        (share_t){w, w->cap_cells * t / nt, w->cap_cells * (t + 1) / nt, {0}, 0, levels, n_levels};
  }
  qk__run_jobs(nt, nt, run_share, shares);
  qk_status_t st = QK_OK;
  size_t total = 0;
  for (unsigned t = 0; t < nt; t++) {
    if (shares[t].nomem) st = QK_ERR_NOMEM;
    total += shares[t].out.n;
  }
  /* New lists aside: the frame's pairs and the two differences. */
  qk__pvec_t cur = {0}, began = {0}, ended = {0};
  if (st == QK_OK) {
    if (!pv_reserve(&w->alloc, &cur, total)) st = QK_ERR_NOMEM;
  }
  if (st == QK_OK) {
    size_t k = 0;
    for (unsigned t = 0; t < nt; t++) {
      if (shares[t].out.n) memcpy(cur.v + k, shares[t].out.v, shares[t].out.n * sizeof *cur.v);
      k += shares[t].out.n;
    }
    cur.n = total;
    /* began <= cur, ended <= previous; began is the sort's scratch before it is filled. */
    if (!pv_reserve(&w->alloc, &began, total) || !pv_reserve(&w->alloc, &ended, w->cur.n))
      st = QK_ERR_NOMEM;
    else if (total > 1)
      sort_pairs(cur.v, began.v, total);
  }
  for (unsigned t = 0; t < nt; t++)
    qk__free(&w->alloc, shares[t].out.v, shares[t].out.cap * sizeof *shares[t].out.v);
  if (st != QK_OK) {
    qk__free(&w->alloc, cur.v, cur.cap * sizeof *cur.v);
    qk__free(&w->alloc, began.v, began.cap * sizeof *began.v);
    qk__free(&w->alloc, ended.v, ended.cap * sizeof *ended.v);
    return st;
  }
  size_t i = 0, j = 0;
  const qk__pvec_t *old = &w->cur;
  while (i < cur.n || j < old->n) {
    int c = i == cur.n ? 1 : j == old->n ? -1 : pair_cmp_gen(&cur.v[i], &old->v[j]);
    if (c < 0)
      began.v[began.n++] = cur.v[i++];
    else if (c > 0)
      ended.v[ended.n++] = old->v[j++];
    else
      i++, j++;
  }
  qk__free(&w->alloc, w->cur.v, w->cur.cap * sizeof *w->cur.v);
  qk__free(&w->alloc, w->began.v, w->began.cap * sizeof *w->began.v);
  qk__free(&w->alloc, w->ended.v, w->ended.cap * sizeof *w->ended.v);
  w->cur = cur;
  w->began = began;
  w->ended = ended;
  return QK_OK;
}

static const qk__pvec_t *which_list(const qk_world_t *w, qk_pairs_which_t which) {
  switch (which) {
  case QK_PAIRS_ALL:
    return &w->cur;
  case QK_PAIRS_BEGAN:
    return &w->began;
  case QK_PAIRS_ENDED:
    return &w->ended;
  default:
    return NULL;
  }
}

qk_status_t qk_world_pairs(const qk_world_t *w, qk_pairs_which_t which, qk_world_pair_fn fn,
                           void *ud) {
  if (!w || !fn) return QK_ERR_INVALID;
  const qk__pvec_t *p = which_list(w, which);
  if (!p) return QK_ERR_INVALID;
  for (size_t i = 0; i < p->n; i++)
    if (fn(p->v[i].a, p->v[i].b, ud)) break;
  return QK_OK;
}

qk_status_t qk_world_pairs_list(const qk_world_t *w, qk_pairs_which_t which, qk_world_pair_t *out,
                                size_t cap, size_t *n_out) {
  if (!w || !n_out || (cap && !out)) return QK_ERR_INVALID;
  const qk__pvec_t *p = which_list(w, which);
  if (!p) return QK_ERR_INVALID;
  *n_out = p->n;
  if (p->n && cap) memcpy(out, p->v, (p->n < cap ? p->n : cap) * sizeof *out);
  return QK_OK;
}
