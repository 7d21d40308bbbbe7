/*
 * Queries on the world: objects overlapping a shape, hits along a segment (all, in
 * order, or the first) and the k nearest objects to a point. Each gathers candidates
 * from the cells of every occupied level whose loose squares meet the query's box (or
 * scans a level's cells when there are fewer of them than squares to look up), then
 * decides each candidate exactly (collide/shape.c).
 */
#include <stdlib.h>
#include <string.h>

#include "collide/world_internal.h"

static inline int boxes_meet(const qk_box_t *a, const qk_box_t *b) {
  return a->xmin <= b->xmax && b->xmin <= a->xmax && a->ymin <= b->ymax && b->ymin <= a->ymax;
}

/* v / 2^l floored, clamped far inside the int64 range. */
static int64_t scaled(double v, int l) {
  double s = floor(ldexp(v, -l));
  if (s > 0x1p60) s = 0x1p60;
  if (s < -0x1p60) s = -0x1p60;
  return (int64_t)s;
}

/* The objects of cell c that are where the order files them (live, not dirty) and whose
 * boxes meet qb. */
static int visit_cell(const qk_world_t *w, uint32_t c, qk_box_t qb, qk__wvisit_fn fn, void *ud) {
  for (uint32_t k = w->cells[c].start, e = w->cells[c + 1].start; k < e; k++) {
    uint32_t i = w->order[k];
    const qk__wobj_t *o = &w->obj[i];
    if (!qk__wlive(o) || (o->flags & QK__WDIRTY)) continue;
    qk_box_t b = qk__wbox(o);
    if (boxes_meet(&b, &qb) && fn(w, i, &b, ud)) return 1;
  }
  return 0;
}

/* A box's cell range at level l: an object of cell c lies in [c 2^l, (c + 2) 2^l), so it
 * can meet the box only when c <= max / 2^l and c > min / 2^l - 2. */
typedef struct crange {
  int64_t x0, x1, y0, y1;
} crange_t;

static crange_t range_of(qk_box_t b, int l) {
  return (crange_t){scaled(b.xmin, l) - 1, scaled(b.xmax, l), scaled(b.ymin, l) - 1,
                    scaled(b.ymax, l)};
}

static inline int in_range(const crange_t *r, int64_t x, int64_t y) {
  return x >= r->x0 && x <= r->x1 && y >= r->y0 && y <= r->y1;
}

/* The cells of level l in range r (row by row, each row found by binary search), but
 * those in *skip. */
static int visit_range(const qk_world_t *w, int l, crange_t r, const crange_t *skip, qk_box_t qb,
                       qk__wvisit_fn fn, void *ud) {
  uint32_t end = w->lv_first[l - QK__LMIN] + w->lv_n[l - QK__LMIN];
  for (int64_t y = r.y0; y <= r.y1; y++)
    for (uint32_t k = qk__cell_lower(w, l, y, r.x0);
         k < end && w->cells[k].cy == y && w->cells[k].cx <= r.x1; k++) {
      if (skip && in_range(skip, w->cells[k].cx, y)) continue;
      if (visit_cell(w, k, qb, fn, ud)) return 1;
    }
  return 0;
}

/* Every cell of level l in range r, by scanning the level's cells. */
static int scan_level(const qk_world_t *w, int l, crange_t r, qk_box_t qb, qk__wvisit_fn fn,
                      void *ud) {
  uint32_t k = w->lv_first[l - QK__LMIN], end = k + w->lv_n[l - QK__LMIN];
  for (; k < end; k++)
    if (in_range(&r, w->cells[k].cx, w->cells[k].cy) && visit_cell(w, k, qb, fn, ud)) return 1;
  return 0;
}

/*
 * A long segment at a fine level: the cells along it, piece by piece, instead of every
 * cell of its bounding box. Each piece is the box between two consecutive points
 * computed on the segment, widened by far more than their rounding, so the pieces cover
 * the true segment. Along a segment the pieces' cell ranges move monotonically, so a
 * cell in two ranges is in every range between them: skipping the cells of the
 * previous range visits each cell (and so each object) once.
 */
/* Piece k of n of the segment seg[0] -> seg[1] (k = 1 .. n, in order): the box from the
 * end of piece k - 1 (*p, updated to piece k's end) to the point at k / n, widened by
 * e = 2^-40 of the ends' magnitudes, far more than the points' rounding. */
typedef struct pieces {
  qk_point_t a, b, p;
  double e;
  size_t n;
} pieces_t;

static pieces_t pieces_of(const qk_point_t *seg, size_t n) {
  const qk_point_t a = seg[0], b = seg[1];
  return (pieces_t){a, b, a, (fabs(a.x) + fabs(a.y) + fabs(b.x) + fabs(b.y)) * 0x1p-40, n};
}

static qk_box_t next_piece(pieces_t *s, size_t k) {
  const double t = (double)k / (double)s->n;
  const qk_point_t a = s->a, b = s->b, p = s->p;
  const qk_point_t q = k == s->n ? b : (qk_point_t){a.x + t * (b.x - a.x), a.y + t * (b.y - a.y)};
  s->p = q;
  return (qk_box_t){fmin(p.x, q.x) - s->e, fmin(p.y, q.y) - s->e, fmax(p.x, q.x) + s->e,
                    fmax(p.y, q.y) + s->e};
}

static int visit_along(const qk_world_t *w, int l, const qk_point_t *seg, double pieces,
                       qk_box_t qb, qk__wvisit_fn fn, void *ud) {
  crange_t prev = {1, 0, 1, 0}; /* empty */
  pieces_t s = pieces_of(seg, (size_t)pieces);
  for (size_t k = 1; k <= s.n; k++) {
    crange_t r = range_of(next_piece(&s, k), l);
    if (visit_range(w, l, r, &prev, qb, fn, ud)) return 1;
    prev = r;
  }
  return 0;
}

/* The objects added or re-filed since the last update (not in the order's cells), one by
 * one. */
static int visit_dirty(const qk_world_t *w, qk_box_t qb, qk__wvisit_fn fn, void *ud) {
  for (uint32_t i = w->dirty_head; i != QK_NONE; i = w->dnext[i]) {
    const qk__wobj_t *o = &w->obj[i];
    if (!qk__wlive(o)) continue;
    qk_box_t b = qk__wbox(o);
    if (boxes_meet(&b, &qb) && fn(w, i, &b, ud)) return 1;
  }
  return 0;
}

void qk__world_visit_seg(const qk_world_t *w, qk_box_t qb, const qk_point_t *seg, qk__wvisit_fn fn,
                         void *ud) {
  if (w->n_live == 0) return;
  int levels[QK__NLEV];
  int n = qk__world_levels(w, levels);
  for (int li = 0; li < n; li++) {
    int l = levels[li];
    crange_t r = range_of(qb, l);
    double ncell = w->lv_n[l - QK__LMIN], lg = log2(ncell + 1) + 2;
    double rows = (double)r.y1 - (double)r.y0 + 1;
    if (rows * lg <= 2 * ncell + 8) { /* a binary search a row */
      if (visit_range(w, l, r, NULL, qb, fn, ud)) return;
      continue;
    }
    if (seg) {
      /* pieces about four cells long on the longer axis; each searches its rows */
      double s = qk__pow2(l);
      double major = fmax(qb.xmax - qb.xmin, qb.ymax - qb.ymin);
      double pieces = ceil(major / (4 * s));
      double prow = (qb.ymax - qb.ymin) / pieces / s + 3;
      if (pieces >= 1 && pieces < 1e7 && pieces * prow * lg <= 2 * ncell + 8) {
        if (visit_along(w, l, seg, pieces, qb, fn, ud)) return;
        continue;
      }
    }
    if (scan_level(w, l, r, qb, fn, ud)) return;
  }
  visit_dirty(w, qb, fn, ud);
}

void qk__world_visit(const qk_world_t *w, qk_box_t qb, qk__wvisit_fn fn, void *ud) {
  qk__world_visit_seg(w, qb, NULL, fn, ud);
}

/* ---- overlap with a shape --------------------------------------------------------- */

typedef struct qctx {
  const qk_shape_t *q;
  qk_handle_t *out;
  size_t cap, n;
} qctx_t;

static int q_visit(const qk_world_t *w, uint32_t i, const qk_box_t *b, void *ud) {
  (void)b;
  qctx_t *c = ud;
  qk_shape_t sh = qk__wshape(&w->obj[i]);
  if (!qk__shapes_overlap(c->q, &sh)) return 0;
  QK__SINK_PUT(c->out, c->cap, c->n, qk__handle(w, i));
  return 0;
}

static int handle_cmp(const void *x, const void *y) {
  uint32_t a = (uint32_t) * (const qk_handle_t *)x, b = (uint32_t) * (const qk_handle_t *)y;
  return (a > b) - (a < b);
}

qk_status_t qk_world_query(const qk_world_t *w, const qk_shape_t *shape, qk_handle_t *out,
                           size_t cap, size_t *n_out) {
  if (!w || !shape || !n_out || (cap && !out)) return QK_ERR_INVALID;
  *n_out = 0;
  qk_shape_t q;
  qk_status_t st = qk__shape_normalize(shape, &q);
  if (st != QK_OK) return st;
  qctx_t c = {&q, out, cap, 0};
  qk_point_t seg[2] = {{q.x, q.y}, {q.a, q.b}};
  qk__world_visit_seg(w, qk__shape_box(&q), q.kind == QK_SHAPE_SEGMENT ? seg : NULL, q_visit, &c);
  if (c.n <= cap && c.n > 1) qsort(out, c.n, sizeof *out, handle_cmp);
  *n_out = c.n;
  return QK_OK;
}

/* ---- rays ------------------------------------------------------------------------- */

typedef struct rctx {
  qk_shape_t seg;
  qk_point_t from, to;
  qk_world_hit_t *out;
  size_t cap, n;
  qk_world_hit_t best;
} rctx_t;

static inline int hit_less(double ta, uint32_t sa, double tb, uint32_t sb) {
  return ta < tb || (ta == tb && sa < sb);
}

static int r_visit_all(const qk_world_t *w, uint32_t i, const qk_box_t *b, void *ud) {
  (void)b;
  rctx_t *c = ud;
  qk_shape_t sh = qk__wshape(&w->obj[i]);
  if (!qk__shapes_overlap(&c->seg, &sh)) return 0;
  QK__SINK_PUT(c->out, c->cap, c->n,
               ((qk_world_hit_t){qk__handle(w, i), qk__ray_param(&sh, c->from, c->to)}));
  return 0;
}

/* Boxes and points, whose distance and ray parameter (qk__shape_dist, qk__ray_param)
 * are those of their boxes computed in long double, to within a few ulps of the real
 * values: a bound from the box in doubles then bounds the computed value too. (A disc's
 * or a segment's is computed with cancellations whose error can exceed any fixed
 * relative margin, so they are always computed, as before: the answers stay the same.) */
static inline int box_like(const qk__wobj_t *o) {
  const unsigned k = o->flags & QK__WKIND;
  return k == QK_SHAPE_BOX || k == QK_SHAPE_POINT;
}

/* A lower bound of where the segment from -> to (direction v, computed) enters box b, as
 * a parameter in [0, 1], or more than 1 when it misses the box's slabs: the slab entry in
 * doubles. Each quotient is within 3 ulps of its real value, so the bound is below the
 * real entry by far less than the 2^-40 the caller leaves. */
static double entry_bound(const rctx_t *c, const qk_box_t *b) {
  const double ox = c->from.x, oy = c->from.y, vx = c->to.x - ox, vy = c->to.y - oy;
  double lo = 0;
  if (vx != 0) {
    double t1 = (b->xmin - ox) / vx, t2 = (b->xmax - ox) / vx;
    lo = qk__max(lo, qk__min(t1, t2));
  } else if (ox < b->xmin || ox > b->xmax) {
    return 2;
  }
  if (vy != 0) {
    double t1 = (b->ymin - oy) / vy, t2 = (b->ymax - oy) / vy;
    lo = qk__max(lo, qk__min(t1, t2));
  } else if (oy < b->ymin || oy > b->ymax) {
    return 2;
  }
  return lo;
}

static int r_visit_first(const qk_world_t *w, uint32_t i, const qk_box_t *b, void *ud) {
  rctx_t *c = ud;
  /* An object the segment reaches (in its box) only after the best hit so far cannot be
   * the first: its parameter would be larger, so no exact test is needed. */
  if (c->best.h != QK_HANDLE_NONE && box_like(&w->obj[i]) &&
      entry_bound(c, b) > c->best.t + 0x1p-40)
    return 0;
  qk_shape_t sh = qk__wshape(&w->obj[i]);
  if (!qk__shapes_overlap(&c->seg, &sh)) return 0;
  double t = qk__ray_param(&sh, c->from, c->to);
  if (c->best.h == QK_HANDLE_NONE || hit_less(t, i, c->best.t, (uint32_t)c->best.h))
    c->best = (qk_world_hit_t){qk__handle(w, i), t};
  return 0;
}

static int hit_cmp(const void *x, const void *y) {
  const qk_world_hit_t *a = x, *b = y;
  if (a->t != b->t) return a->t < b->t ? -1 : 1;
  uint32_t sa = (uint32_t)a->h, sb = (uint32_t)b->h;
  return (sa > sb) - (sa < sb);
}

static qk_status_t ray_setup(qk_point_t from, qk_point_t to, rctx_t *c) {
  qk_shape_t s = {QK_SHAPE_SEGMENT, from.x, from.y, to.x, to.y};
  memset(c, 0, sizeof *c);
  c->from = from;
  c->to = to;
  c->best = (qk_world_hit_t){QK_HANDLE_NONE, INFINITY};
  return qk__shape_normalize(&s, &c->seg);
}

qk_status_t qk_world_raycast_all(const qk_world_t *w, qk_point_t from, qk_point_t to,
                                 qk_world_hit_t *out, size_t cap, size_t *n_out) {
  if (!w || !n_out || (cap && !out)) return QK_ERR_INVALID;
  *n_out = 0;
  rctx_t c;
  qk_status_t st = ray_setup(from, to, &c);
  if (st != QK_OK) return st;
  c.out = out;
  c.cap = cap;
  qk_point_t seg[2] = {from, to};
  qk__world_visit_seg(w, qk__shape_box(&c.seg), seg, r_visit_all, &c);
  if (c.n <= cap && c.n > 1) qsort(out, c.n, sizeof *out, hit_cmp);
  *n_out = c.n;
  return QK_OK;
}

/*
 * The first hit in a world of boxes and points only (!had_round), stopping early: the
 * segment in n pieces about a cell long at the level of the most cells, in order, each
 * piece's cells at every level at once (visit_along's pieces and covering argument).
 * After pieces 1 .. k every object the segment touches at a parameter up to t_k = k / n
 * has been tested: its box meets one of those pieces' boxes, so its cell is in their
 * ranges. An object not tested yet touches the segment only beyond t_k, and a box's or
 * a point's parameter is computed to within a few ulps of the real one, so once the
 * best hit lies before t_k by a margin no object left can come first, nor tie with it.
 * (A disc's or a segment's parameter can be off by more than any such margin: worlds
 * that had one visit every candidate.) The objects not filed yet and the levels that
 * have few cells for the rows the pieces would search are tested first, whole. Returns
 * 0, having tested nothing, when the pieces would be too many: the caller visits the
 * segment's cells as any query does.
 */
static int visit_first(const qk_world_t *w, qk_box_t qb, const qk_point_t *seg, rctx_t *c) {
  int levels[QK__NLEV], along[QK__NLEV];
  crange_t prev[QK__NLEV];
  const int nl = qk__world_levels(w, levels);
  if (nl == 0) return 0;
  /* pieces a cell long at the level of the most cells */
  int lm = levels[0];
  for (int li = 1; li < nl; li++)
    if (w->lv_n[levels[li] - QK__LMIN] > w->lv_n[lm - QK__LMIN]) lm = levels[li];
  const double pieces =
      ceil(fmax(fabs(seg[1].x - seg[0].x), fabs(seg[1].y - seg[0].y)) / qk__pow2(lm));
  if (!(pieces <= 0x1p20)) return 0;
  const size_t n = pieces < 1 ? 1 : (size_t)pieces;
  visit_dirty(w, qb, r_visit_first, c);
  int walk = 0;
  for (int li = 0; li < nl; li++) {
    const int l = levels[li];
    const double ncell = w->lv_n[l - QK__LMIN], lg = log2(ncell + 1) + 2;
    const double prow = (qb.ymax - qb.ymin) / (double)n / qk__pow2(l) + 3;
    along[li] = (double)n * prow * lg <= 2 * ncell + 8;
    walk |= along[li];
    prev[li] = (crange_t){1, 0, 1, 0}; /* empty */
    if (!along[li]) scan_level(w, l, range_of(qb, l), qb, r_visit_first, c);
  }
  if (!walk) return 1; /* (every level scanned whole) */
  pieces_t s = pieces_of(seg, n);
  for (size_t k = 1; k <= n; k++) {
    const qk_box_t pb = next_piece(&s, k);
    for (int li = 0; li < nl; li++) {
      if (!along[li]) continue;
      const crange_t r = range_of(pb, levels[li]);
      if (memcmp(&r, &prev[li], sizeof r))
        visit_range(w, levels[li], r, &prev[li], qb, r_visit_first, c);
      prev[li] = r;
    }
    if (c->best.h != QK_HANDLE_NONE && c->best.t < (double)k / (double)n - 0x1p-30) break;
  }
  return 1;
}

qk_status_t qk_world_raycast(const qk_world_t *w, qk_point_t from, qk_point_t to,
                             qk_world_hit_t *hit) {
  if (!w || !hit) return QK_ERR_INVALID;
  *hit = (qk_world_hit_t){QK_HANDLE_NONE, INFINITY};
  rctx_t c;
  qk_status_t st = ray_setup(from, to, &c);
  if (st != QK_OK) return st;
  qk_point_t seg[2] = {from, to};
  const qk_box_t qb = qk__shape_box(&c.seg);
  if (w->n_live && (w->had_round || !visit_first(w, qb, seg, &c)))
    qk__world_visit_seg(w, qb, seg, r_visit_first, &c);
  *hit = c.best;
  return QK_OK;
}

typedef struct batch {
  const qk_world_t *w;
  const qk_point_t *from, *to;
  size_t n, chunk;
  qk_world_hit_t *hits;
  qk_status_t st[64];
} batch_t;

static void batch_run(unsigned k, void *ud) {
  batch_t *b = ud;
  size_t lo = (size_t)k * b->chunk, hi = lo + b->chunk < b->n ? lo + b->chunk : b->n;
  for (size_t i = lo; i < hi; i++) {
    qk_status_t st = qk_world_raycast(b->w, b->from[i], b->to[i], &b->hits[i]);
    if (st != QK_OK) b->st[k % 64] = st;
  }
}

/* Jobs of a batch of n: chunks of 256 queries, or larger ones so that there are at most
 * 64 (the size of the batches' status arrays). Sets *chunk. */
static size_t batch_jobs(size_t n, size_t *chunk) {
  *chunk = 256;
  if ((n + 255) / 256 > 64) *chunk = (n + 63) / 64;
  return (n + *chunk - 1) / *chunk;
}

qk_status_t qk_world_raycast_batch(const qk_world_t *w, const qk_point_t *from,
                                   const qk_point_t *to, size_t n, qk_world_hit_t *hits) {
  if (!w || (n && (!from || !to || !hits))) return QK_ERR_INVALID;
  batch_t b = {w, from, to, n, 256, hits, {QK_OK}};
  size_t jobs = batch_jobs(n, &b.chunk);
  qk__world_run_jobs(w, w->opt.threads, (unsigned)jobs, batch_run, &b);
  for (int k = 0; k < 64; k++)
    if (b.st[k] != QK_OK) return b.st[k];
  return QK_OK;
}

/* ---- k nearest -------------------------------------------------------------------- */

typedef struct kctx {
  qk_point_t p;
  qk_world_hit_t *out; /* sorted ascending by (t, slot), n of k filled */
  size_t k, n, seen;
} kctx_t;

static int k_visit(const qk_world_t *w, uint32_t i, const qk_box_t *b, void *ud) {
  kctx_t *c = ud;
  c->seen++;
  if (c->n == c->k && box_like(&w->obj[i])) {
    /* Farther than the k-th so far by its box: not among the k.
     * The squared box distance in doubles is within a few ulps of its real value, far
     * inside the 2^-40 left here, and its sign parts are exact. */
    double dx = qk__max(qk__max(b->xmin - c->p.x, c->p.x - b->xmax), 0);
    double dy = qk__max(qk__max(b->ymin - c->p.y, c->p.y - b->ymax), 0);
    double kt = c->out[c->n - 1].t;
    if (dx * dx + dy * dy > kt * kt * (1 + 0x1p-40)) return 0;
  }
  qk_shape_t sh = qk__wshape(&w->obj[i]);
  double d = qk__shape_dist(&sh, c->p);
  if (c->n == c->k && !hit_less(d, i, c->out[c->n - 1].t, (uint32_t)c->out[c->n - 1].h)) return 0;
  size_t j = c->n < c->k ? c->n++ : c->n - 1;
  while (j > 0 && hit_less(d, i, c->out[j - 1].t, (uint32_t)c->out[j - 1].h)) {
    c->out[j] = c->out[j - 1];
    j--;
  }
  c->out[j] = (qk_world_hit_t){qk__handle(w, i), d};
  return 0;
}

qk_status_t qk_world_knn(const qk_world_t *w, qk_point_t p, size_t k, qk_world_hit_t *out,
                         size_t *n_out) {
  if (!w || !n_out || (k && !out)) return QK_ERR_INVALID;
  *n_out = 0;
  if (!isfinite(p.x) || !isfinite(p.y)) return QK_ERR_NONFINITE;
  if (!qk__value_ok(p.x) || !qk__value_ok(p.y)) return QK_ERR_LIMIT;
  if (k == 0 || w->n_live == 0) return QK_OK;
  int levels[QK__NLEV];
  int n_levels = qk__world_levels(w, levels);
  /*
   * Grow a square around p until it holds k objects no farther than its half side:
   * every object within distance r meets the square of half side r, so those k are the
   * nearest. Distances are rounded, so the bound is kept a little inside r.
   */
  double r = 1.0;
  if (n_levels) {
    /* The first square about holds 2k objects at the finest level's mean density: those
     * objects in its cells over the cells' area. */
    const int l0 = levels[0] - QK__LMIN;
    const uint32_t c0 = w->lv_first[l0], nc = w->lv_n[l0];
    const double objs = (double)(w->cells[c0 + nc].start - w->cells[c0].start);
    r = ldexp(sqrt((double)k * nc / (objs > 1 ? objs : 1)), levels[0] - 1);
  }
  for (;;) {
    kctx_t c = {p, out, k, 0, 0};
    qk_box_t qb = {p.x - r, p.y - r, p.x + r, p.y + r};
    qk__world_visit(w, qb, k_visit, &c);
    if (c.seen == w->n_live || (c.n == k && c.out[k - 1].t <= r * (1 - 0x1p-20))) {
      *n_out = c.n;
      return QK_OK;
    }
    r *= 2;
  }
}

typedef struct kbatch {
  const qk_world_t *w;
  const qk_point_t *ps;
  size_t n, k, chunk;
  qk_world_hit_t *out;
  size_t *counts;
  qk_status_t st[64];
} kbatch_t;

static void kbatch_run(unsigned j, void *ud) {
  kbatch_t *b = ud;
  size_t lo = (size_t)j * b->chunk, hi = lo + b->chunk < b->n ? lo + b->chunk : b->n;
  for (size_t i = lo; i < hi; i++) {
    qk_status_t st = qk_world_knn(b->w, b->ps[i], b->k, b->out + i * b->k, &b->counts[i]);
    if (st != QK_OK) b->st[j % 64] = st;
  }
}

qk_status_t qk_world_knn_batch(const qk_world_t *w, const qk_point_t *ps, size_t n, size_t k,
                               qk_world_hit_t *out, size_t *counts) {
  if (!w || (n && (!ps || !counts || (k && !out)))) return QK_ERR_INVALID;
  kbatch_t b = {w, ps, n, k, 256, out, counts, {QK_OK}};
  size_t jobs = batch_jobs(n, &b.chunk);
  qk__world_run_jobs(w, w->opt.threads, (unsigned)jobs, kbatch_run, &b);
  for (int j = 0; j < 64; j++)
    if (b.st[j] != QK_OK) return b.st[j];
  return QK_OK;
}
