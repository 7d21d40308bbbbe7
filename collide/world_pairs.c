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

/* Test objects i and j; record the pair when they overlap. */
static inline int try_pair(share_t *s, uint32_t i, uint32_t j) {
  const qk_world_t *w = s->w;
  const qk__wobj_t *a = &w->obj[i], *b = &w->obj[j];
  if (!boxes_meet(&a->box, &b->box)) return 1;
  /* Two boxes need nothing beyond their boxes, which are exact for them. */
  if (!(a->s.kind == QK_SHAPE_BOX && b->s.kind == QK_SHAPE_BOX) &&
      !qk__shapes_overlap(&a->s, &b->s))
    return 1;
  if (i > j) {
    uint32_t t = i;
    i = j;
    j = t;
  }
  return pv_push(&w->alloc, &s->out, qk__handle(w, i), qk__handle(w, j));
}

/* Every object of cell A against every object of cell B (A != B). */
static int cross_cells(share_t *s, const qk__wcell_t *a, const qk__wcell_t *b) {
  const qk__wobj_t *obj = s->w->obj;
  for (uint32_t i = a->head; i != QK_NONE; i = obj[i].next)
    for (uint32_t j = b->head; j != QK_NONE; j = obj[j].next)
      if (!try_pair(s, i, j)) return 0;
  return 1;
}

/* floor(v / 2^k) and ceil(v / 2^k) for k >= 0, on values below 2^52. */
static inline int64_t shr_floor(int64_t v, int k) {
  if (k > 60) return v < 0 ? -1 : 0;
  int64_t d = (int64_t)1 << k;
  return v >= 0 ? v / d : -((-v + d - 1) / d);
}
static inline int64_t shr_ceil(int64_t v, int k) { return -shr_floor(-v, k); }

static int cell_pairs(share_t *s, const qk__wcell_t *a) {
  const qk_world_t *w = s->w;
  const qk__wobj_t *obj = w->obj;
  /* Within the cell. */
  for (uint32_t i = a->head; i != QK_NONE; i = obj[i].next)
    for (uint32_t j = obj[i].next; j != QK_NONE; j = obj[j].next)
      if (!try_pair(s, i, j)) return 0;
  /* The same level: loose squares [c, c + 2) meet when the indices differ by <= 1; each
   * neighbour pair is taken once, from the cell that comes first in (x, y) order. */
  for (int dx = 0; dx <= 1; dx++)
    for (int dy = -1; dy <= 1; dy++) {
      if (dx == 0 && dy <= 0) continue;
      const qk__wcell_t *b = qk__world_cell(w, a->level, a->cx + dx, a->cy + dy);
      if (b && !cross_cells(s, a, b)) return 0;
    }
  /* Coarser levels: the cells whose loose squares [b 2^lb, (b + 2) 2^lb) meet this one's
   * [a 2^la, (a + 2) 2^la): b 2^k < a + 2 and (b + 2) 2^k > a, with k = lb - la. */
  for (int li = 0; li < s->n_levels; li++) {
    int lb = s->levels[li];
    if (lb <= a->level) continue;
    int k = lb - a->level;
    int64_t x0 = shr_floor(a->cx, k) - 1, x1 = shr_ceil(a->cx + 2, k) - 1;
    int64_t y0 = shr_floor(a->cy, k) - 1, y1 = shr_ceil(a->cy + 2, k) - 1;
    for (int64_t x = x0; x <= x1; x++)
      for (int64_t y = y0; y <= y1; y++) {
        const qk__wcell_t *b = qk__world_cell(w, lb, x, y);
        if (b && !cross_cells(s, a, b)) return 0;
      }
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

qk_status_t qk_world_update(qk_world_t *w) {
  if (!w) return QK_ERR_INVALID;
  int levels[QK__NLEV];
  int n_levels = qk__world_levels(w, levels);
  unsigned nt = w->opt.threads;
  if (w->n_live < 4096) nt = 1; /* not worth a thread */
  share_t shares[256];
  for (unsigned t = 0; t < nt; t++) {
    shares[t] =
        (share_t){w, w->cap_cells * t / nt, w->cap_cells * (t + 1) / nt, {0}, 0, levels, n_levels};
  }
  qk__parallel(nt, nt, run_share, shares);
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
      memcpy(cur.v + k, shares[t].out.v, shares[t].out.n * sizeof *cur.v);
      k += shares[t].out.n;
    }
    cur.n = total;
    if (total > 1) qsort(cur.v, total, sizeof *cur.v, pair_cmp);
    /* began <= cur, ended <= previous. */
    if (!pv_reserve(&w->alloc, &began, total) || !pv_reserve(&w->alloc, &ended, w->cur.n))
      st = QK_ERR_NOMEM;
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
