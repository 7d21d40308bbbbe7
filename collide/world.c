/*
 * The moving-objects world: objects with stable handles, filed in a sorted loose
 * hierarchical grid, and the per-frame pairs.
 *
 * Design. Each object keeps a fattened box (its box widened by a margin, half its size
 * by default) and is filed by that box in one cell of a grid of squares of side 2^L: the
 * smallest even L whose cell holds the fattened box's lower-left corner and reaches two
 * cells up and right past it, so the fat box lies in the cell's "loose" square
 * [cx 2^L, (cx + 2) 2^L) (exact: powers of two and floors; the far side open). The
 * object keeps its cell (level, cx, cy); a move whose box stays inside the loose square
 * changes only the shape (four comparisons), so steady motion re-files only the objects
 * that drifted out, having moved at least the margin. Those go on a dirty list (linked
 * through the objects: moves never allocate) and are filed anew at the next update, with
 * the margin at least twice the step of the move that took them out (at most 32 times
 * their size): a small fast object is filed in a cell it takes a few frames to leave,
 * not one it leaves every frame (the bench's clustered scene at 10^4 re-filed 47% of its
 * objects a frame, 11% so). A move also re-files an object whose fat box (with the
 * margins it was filed with) shrank to fit a level two steps finer: the extent below which
 * that holds is kept in the object while it is filed (its step while it is dirty).
 *
 * There is no hash table: the grid is the world's slots sorted by cell, (level, cy, cx)
 * (collide/world_grid.c), and its cells, one entry per occupied cell, sorted the same
 * way. An update drops removed slots and the dirty ones from the order (the rest stay
 * sorted: their cells did not change), sorts the dirty ones and merges them in, in one
 * pass that also packs the boxes for the pair search. Neighbour cells of the same level
 * are then found by walking the sorted cells (the next cell; the row above by a cursor
 * that only moves forward); across levels, each coarser object walks its box over the
 * finer level's sorted cells row by row (collide/world_search.c). Queries search the
 * cells by binary search per row and check the dirty objects one by one.
 *
 * Levels adapt to the sizes (an object of size e sits at level ~log2 e, from 1e-3 to
 * 1e3 and beyond in one world; levels are a factor of 4 apart) and to the coordinates
 * (cell indices are kept below 2^30 so they fit 32 bits: a unit object at 1e9 is filed
 * at level 0, one at 1e20 at a coarser one).
 *
 * Memory (between updates): 68 bytes an object slot (the object and its generation at
 * the last update), 4 an entry of the order, 16 a cell; and the pair state: the current
 * pairs by rows (4 bytes a pair and 8 a slot with pairs) and the began and ended lists
 * (8 bytes a pair). The update's scratch (float boxes, cell boxes, the search's pairs and the
 * sort's buffers and counts) is allocated per update and freed before it returns, but for
 * the buffers of 8 MB and more, kept for the next update (collide/world_pairs.c).
 *
 * Handles: slot in the low 32 bits, generation in the high 32. A slot's generation is
 * odd while it is live and becomes even at removal; a freed slot is reused (last freed,
 * first reused) with the next odd generation, so stale handles never match. A slot whose
 * generation would wrap (after 2^31 objects) is retired instead of reused.
 *
 * Failure: add reserves the object slot before the world changes; move and remove never
 * allocate; update allocates the new order and its scratch before anything changes, and
 * builds its new pair lists aside, swapping them in only when all succeeded.
 */
#include <stddef.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "collide/world_internal.h"

#if defined(__SSE2__)
#include <emmintrin.h>
#endif

#if defined(__GNUC__)
#define QK__NOINLINE __attribute__((noinline))
#else
#define QK__NOINLINE
#endif

void qk_world_options_init(qk_world_options_t *o) {
  if (!o) return;
  memset(o, 0, sizeof *o);
  o->threads = 1;
  o->margin = 0.5;
  o->min_margin = 0;
  o->thread_min = 32768;
}

qk_status_t qk_world_new(const qk_world_options_t *options, qk_world_t **out) {
  if (!out) return QK_ERR_INVALID;
  *out = NULL;
  qk_world_options_t o;
  qk_world_options_init(&o);
  if (options) o = *options;
  /* 0 threads: every online core, as for the tree and the collider (it was refused) */
  if (o.threads == 0) o.threads = qk__threads_resolve(0);
  /* Bounded margins keep every fat box, and so every level, inside the level table. */
  if (!(o.margin >= 0 && o.margin <= 16) || !(o.min_margin >= 0 && o.min_margin <= 0x1p100) ||
      o.threads > 256)
    return QK_ERR_INVALID;
  qk_allocator_t a = {NULL, NULL};
  if (o.allocator) a = *o.allocator;
  qk_world_t *w = qk__realloc(&a, NULL, 0, sizeof *w);
  if (!w) return QK_ERR_NOMEM;
  memset(w, 0, sizeof *w);
  atomic_init(&w->qstate, 0);
  atomic_init(&w->qbytes, 0);
  qk__wscr_init(w, &a); /* w->alloc: the scratch cache in front of a */
  w->opt = o;
  w->opt.allocator = NULL;
  w->free_head = QK_NONE;
  w->dirty_head = QK_NONE;
  *out = w;
  return QK_OK;
}

/* The object array's block in bytes (its slots and QK__WOBJ_SLACK), 0 when there is none. */
static size_t obj_bytes(const qk_world_t *w) {
  return w->obj_raw ? (size_t)w->cap_obj * sizeof *w->obj + QK__WOBJ_SLACK : 0;
}

void qk_world_free(qk_world_t *w) {
  if (!w) return;
  qk__world_pool_free(w);
  qk_allocator_t a = w->alloc;
  qk__free(&a, w->obj_raw, obj_bytes(w));
  qk__free(&a, w->order, (size_t)w->cap_order * sizeof *w->order);
  qk__free(&a, w->cells, (size_t)w->cap_cells * sizeof *w->cells);
  qk__free(&a, w->ugen, (size_t)w->cap_ugen * sizeof *w->ugen);
  qk__free(&a, w->dnext, (size_t)w->cap_dnext * sizeof *w->dnext);
  qk__free(&a, qk__prows_block(&w->cur), qk__prows_room(&w->cur) * sizeof *w->cur.b);
  qk__free(&a, w->cur.row, w->cur.row ? 2 * (w->cur.n_nz + 1) * sizeof *w->cur.row : 0);
  qk__free(&a, w->ckeys.v, w->ckeys.cap * sizeof *w->ckeys.v);
  qk__free(&a, w->began.v, w->began.cap * sizeof *w->began.v);
  qk__free(&a, w->ended.v, w->ended.cap * sizeof *w->ended.v);
  qk__free(&a, w->egen, w->n_egen * sizeof *w->egen);
  qk__free(&a, w->scr_keys.v, w->scr_keys.cap * sizeof *w->scr_keys.v);
  qk__free(&a, w->spare_b, w->cap_spare_b * sizeof *w->spare_b);
  qk__free(&a, w->fbox, (size_t)w->n_fbox * 4 * sizeof *w->fbox);
  qk__free(&a, w->near.v, w->near.cap * sizeof *w->near.v);
  qk__world_qtree_free(w);
  for (unsigned t = 0; t < QK__KEEP_THREADS; t++)
    qk__free(&a, w->scr_tkeys[t].v, w->scr_tkeys[t].cap * sizeof *w->scr_tkeys[t].v);
  qk__wscr_flush(w);
  a = w->scr.user;
  qk__free(&a, w, sizeof *w);
}

size_t qk_world_size(const qk_world_t *w) { return w ? w->n_live : 0; }

/* The other search threads' kept key buffers, in bytes. */
static size_t kept_tkeys(const qk_world_t *w) {
  size_t b = 0;
  for (unsigned t = 0; t < QK__KEEP_THREADS; t++) b += w->scr_tkeys[t].cap * sizeof(uint64_t);
  return b;
}

size_t qk_world_pair_bytes(const qk_world_t *w) {
  if (!w) return 0;
  return qk__prows_room(&w->cur) * sizeof *w->cur.b +
         (w->cur.row ? 2 * (w->cur.n_nz + 1) * sizeof *w->cur.row : 0) +
         (w->ckeys.cap + w->began.cap + w->ended.cap + w->n_egen + w->scr_keys.cap) *
             sizeof(uint64_t) +
         w->cap_spare_b * sizeof *w->spare_b + kept_tkeys(w) +
         (size_t)w->n_fbox * 4 * sizeof *w->fbox + w->near.cap * sizeof *w->near.v +
         qk__wscr_bytes(w);
}

int qk__world_obj_resize(qk_world_t *w, uint32_t cap) {
  const size_t osize = obj_bytes(w);
  const size_t off0 = w->obj_raw ? (size_t)((char *)w->obj - (char *)w->obj_raw) : 0;
  char *raw =
      qk__realloc(&w->alloc, w->obj_raw, osize, (size_t)cap * sizeof *w->obj + QK__WOBJ_SLACK);
  if (!raw) return 0;
  /* The block may have moved to another offset from a line: the kept slots moved with it
   * (they lie within the first osize bytes, or the first cap slots past off0 < 64). */
  const size_t off = (size_t)(-(uintptr_t)raw & 63);
  const uint32_t keep = cap < w->cap_obj ? cap : w->cap_obj;
  if (off != off0 && keep) memmove(raw + off, raw + off0, (size_t)keep * sizeof *w->obj);
  w->obj_raw = raw;
  w->obj = (qk__wobj_t *)(void *)(raw + off);
  w->cap_obj = cap;
  return 1;
}

size_t qk_world_bytes(const qk_world_t *w) {
  if (!w) return 0;
  return sizeof *w + obj_bytes(w) + (size_t)w->cap_ugen * sizeof *w->ugen +
         (size_t)w->cap_dnext * sizeof *w->dnext + (size_t)w->cap_order * sizeof *w->order +
         (size_t)w->cap_cells * sizeof *w->cells + qk_world_pair_bytes(w) +
         atomic_load_explicit(&w->qbytes, memory_order_relaxed);
}

/* ---- filing ---------------------------------------------------------------------- */

/* The exponent of a positive normal double (floor(log2 v)), from its bits. */
static inline int exp_of(double v, uint64_t *mant) {
  uint64_t u;
  memcpy(&u, &v, sizeof u);
  *mant = u & ((UINT64_C(1) << 52) - 1);
  return (int)((u >> 52) & 0x7ff) - 1023;
}

/* Smallest L with 2^L >= e (e >= 0; QK__LFLOOR for anything below 2^QK__LFLOOR). */
static int ceil_log2(double e) {
  if (!(e > 0x1p-120)) return QK__LFLOOR;
  uint64_t m;
  int ex = exp_of(e, &m);
  return m ? ex + 1 : ex;
}

#if !defined(__SSE2__)
/* floor(v) for |v| < 2^30 (the cell indices below: no range check, no rounding mode),
 * exactly: truncated, then one less when that lies above v. (-0.0 gives +0.0, the same
 * cell index and square.) */
static inline double floor30(double v) {
  double t = (double)(int64_t)v;
  return t > v ? t - 1 : t;
}
#endif

void qk__world_cell_of(const qk_box_t *f, int *level, int32_t *cx, int32_t *cy, int *forced) {
#if defined(__SSE2__)
  /* (the extent and the magnitude from (xmin, ymin) and (xmax, ymax) as pairs: the same
   * values, up to the sign of a zero, which neither use below sees) */
  const __m128d lo = _mm_loadu_pd(&f->xmin), hi = _mm_loadu_pd(&f->xmax);
  const __m128d ext = _mm_sub_pd(hi, lo), sign = _mm_set1_pd(-0.0);
  const __m128d am = _mm_max_pd(_mm_andnot_pd(sign, lo), _mm_andnot_pd(sign, hi));
  double e = _mm_cvtsd_f64(_mm_max_sd(ext, _mm_unpackhi_pd(ext, ext)));
  double mag = _mm_cvtsd_f64(_mm_max_sd(am, _mm_unpackhi_pd(am, am)));
#else
  double e = qk__max(f->xmax - f->xmin, f->ymax - f->ymin);
  double mag =
      qk__max(qk__max(fabs(f->xmin), fabs(f->xmax)), qk__max(fabs(f->ymin), fabs(f->ymax)));
#endif
  int l = ceil_log2(e);
  l += l & 1; /* levels a factor of 4 apart: fewer levels to visit, a few more objects per cell */
  if (l < QK__LFLOOR) l = QK__LFLOOR;
  *forced = 0;
  /* |coordinate| < 2^(ilogb + 1) <= 2^(l + 30): cell indices (and cx + 2) fit 32 bits. */
  uint64_t mant;
  int lm = mag >= 0x1p-1000 ? exp_of(mag, &mant) - 29 : QK__LFLOOR; /* ilogb(mag) - 29 */
  if (lm > l) l = lm, *forced = 1;
#if defined(__SSE2__)
  /* Both axes at once: (xmin, ymin) scaled, truncated to int32 (exact: below 2^30 in
   * magnitude), one less where that lies above (floor30 on two lanes), the loose square's
   * far sides compared with (xmax, ymax). */
  for (;; l++) {
    const __m128d v = _mm_mul_pd(lo, _mm_set1_pd(qk__pow2(-l)));
    const __m128i ti = _mm_cvttpd_epi32(v);
    const __m128d t = _mm_cvtepi32_pd(ti);
    const __m128i above = _mm_castpd_si128(_mm_cmpgt_pd(t, v)); /* (all ones: -1 in int32) */
    const __m128i xi = _mm_add_epi32(ti, _mm_shuffle_epi32(above, _MM_SHUFFLE(3, 3, 2, 0)));
    const __m128d x = _mm_cvtepi32_pd(xi), s = _mm_set1_pd(qk__pow2(l));
    if (_mm_movemask_pd(_mm_cmplt_pd(hi, _mm_mul_pd(_mm_add_pd(x, _mm_set1_pd(2)), s))) == 3) {
      *level = l;
      *cx = _mm_cvtsi128_si32(xi);
      *cy = _mm_cvtsi128_si32(_mm_shuffle_epi32(xi, _MM_SHUFFLE(1, 1, 1, 1)));
      return;
    }
  }
#else
  for (;; l++) {
    double inv = qk__pow2(-l), s = qk__pow2(l);
    double x = floor30(f->xmin * inv), y = floor30(f->ymin * inv);
    if (f->xmax < (x + 2) * s && f->ymax < (y + 2) * s) {
      *level = l;
      *cx = (int32_t)x;
      *cy = (int32_t)y;
      return;
    }
  }
#endif
}

/* How far a move from box o to box b went: the larger move of a lower-left coordinate. */
static inline float step_of(const qk__wobj_t *o, const qk_box_t *b) {
  double d = qk__max(fabs(b->xmin - o->x), fabs(b->ymin - o->y));
  return d < 0x1p100 ? (float)d : 0x1p100f;
}

/* Put slot i on the dirty list (unless it is on it already). */
static inline void make_dirty(qk_world_t *w, uint32_t i) {
  qk__wobj_t *o = &w->obj[i];
  if (o->flags & QK__WDIRTY) return;
  o->flags |= QK__WDIRTY;
  w->dnext[i] = w->dirty_head;
  w->dirty_head = i;
  w->n_dirty++;
}

/* a inside the loose square of o's cell (its far sides open), exactly. */
static inline int in_loose(const qk__wobj_t *o, const qk_box_t *a) {
  double s = qk__pow2(o->level);
  double x0 = (double)o->u.cx * s, y0 = (double)o->cy * s;
  return a->xmin >= x0 && a->ymin >= y0 && a->xmax < x0 + 2 * s && a->ymax < y0 + 2 * s;
}

/* The live object of a handle, or NULL. */
static qk__wobj_t *lookup(const qk_world_t *w, qk_handle_t h) {
  uint32_t slot = (uint32_t)h, gen = (uint32_t)(h >> 32);
  if (slot >= w->n_obj) return NULL;
  qk__wobj_t *o = &w->obj[slot];
  return qk__wlive(o) && o->gen == gen ? o : NULL;
}

static void set_shape(qk_world_t *w, qk__wobj_t *o, const qk_shape_t *s) {
  o->x = s->x, o->y = s->y, o->a = s->a, o->b = s->b;
  o->flags = (uint8_t)((o->flags & ~QK__WKIND) | ((unsigned)s->kind & QK__WKIND));
  if (s->kind == QK_SHAPE_DISC || s->kind == QK_SHAPE_SEGMENT) w->had_round = 1;
}

qk_status_t qk_world_add(qk_world_t *w, const qk_shape_t *shape, uint64_t tag, qk_handle_t *h) {
  if (!w || !shape || !h) return QK_ERR_INVALID;
  *h = QK_HANDLE_NONE;
  qk_shape_t s;
  qk_status_t st = qk__shape_normalize(shape, &s);
  if (st != QK_OK) return st;
  if (w->free_head == QK_NONE && w->n_obj == w->cap_obj) {
    if (w->cap_obj >= UINT32_MAX / 2) return QK_ERR_LIMIT;
    uint32_t cap = w->cap_obj ? w->cap_obj + w->cap_obj / 2 : 16; /* 1.5x: less slack */
    if (w->cap_ugen < cap) { /* (grown first: a failure after it leaves only room) */
      uint32_t *nu = qk__realloc(&w->alloc, w->ugen, (size_t)w->cap_ugen * sizeof *nu,
                                 (size_t)cap * sizeof *nu);
      if (!nu) return QK_ERR_NOMEM;
      w->ugen = nu;
      w->cap_ugen = cap;
    }
    if (w->cap_dnext < cap) {
      uint32_t *nd = qk__realloc(&w->alloc, w->dnext, (size_t)w->cap_dnext * sizeof *nd,
                                 (size_t)cap * sizeof *nd);
      if (!nd) return QK_ERR_NOMEM;
      w->dnext = nd;
      w->cap_dnext = cap;
    }
    if (!qk__world_obj_resize(w, cap)) return QK_ERR_NOMEM;
  }
  uint32_t i;
  if (w->free_head != QK_NONE) {
    i = w->free_head;
    w->free_head = w->obj[i].u.free_next;
    w->obj[i].gen++;
  } else {
    i = w->n_obj++;
    memset(&w->obj[i], 0, sizeof w->obj[i]);
    w->obj[i].gen = 1;
    w->ugen[i] = 0;
  }
  qk__wobj_t *o = &w->obj[i];
  o->tag = tag;
  set_shape(w, o, &s);
  o->k.step = 0;
  o->flags &= (uint8_t)~QK__WFORCED;
  make_dirty(w, i); /* filed at the next update; until then queries check it directly */
  w->n_live++;
  w->ident_dirty = 1;
  *h = qk__handle(w, i);
  return QK_OK;
}

#if !defined(__SSE2__)
/* qk__shape_normalize for a box whose values need no change (the common move): corners
 * in order and every value of magnitude in [2^-100, 2^100] (zeros, NaN and the
 * infinities take the general path). (With SSE2 move_obj checks this itself.) */
static inline int box_ok(const qk_shape_t *s) {
  if (s->kind != QK_SHAPE_BOX || !(s->x <= s->a && s->y <= s->b)) return 0;
  return qk__value_ok(s->x) && qk__value_ok(s->y) && qk__value_ok(s->a) && qk__value_ok(s->b) &&
         s->x && s->y && s->a && s->b;
}
#endif

/* How far ahead a run of moves in slot order fetches its objects (64 objects: about 0.45
 * us of moves, more than a line's transfer between two cores). */
#define QK__MOVE_AHEAD 64

/* A write to come at p: the line fetched for writing (PREFETCHW; a no-op where the
 * processor lacks it), so that a line a worker thread read stays one fetch, not a
 * read and then an upgrade. */
static inline void qk__prefetch_write(const void *p) {
#if defined(__x86_64__) || defined(__i386__)
  __asm__ __volatile__("prefetchw %0" : : "m"(*(const char *)p));
#else
  __builtin_prefetch(p, 1);
#endif
}

/* (move_obj reads the cell as two adjacent int32: cx, then cy) */
_Static_assert(offsetof(qk__wobj_t, cy) == offsetof(qk__wobj_t, u) + 4, "cx, cy adjacent");
_Static_assert(sizeof(qk__wobj_t) == 64, "an object: 64 bytes");

/* The move of a live object o (slot i) to a shape: the common case (a box needing no
 * normalisation, staying in its loose square) is inline and branch-light, as the batch
 * call runs it once per object. */
/* Re-filed when it leaves its cell's loose square, or when it shrank so much that a level
 * two steps finer would hold its fat box (unless its coordinates set the level). */
static inline void refile_check(qk_world_t *w, qk__wobj_t *o, uint32_t i, const qk_box_t *nb,
                                float step) {
  if (o->flags & QK__WDIRTY) return; /* filed at the next update anyway */
  if (in_loose(o, nb) && !(qk__max(nb->xmax - nb->xmin, nb->ymax - nb->ymin) <= o->k.shrink)) {
    qk__world_fine_touch(w, o);
    return;
  }
  o->k.step = step;
  make_dirty(w, i);
}

/* The general move (any kind, any values): kept out of line so that the common one below
 * needs no stack frame. */
static QK__NOINLINE qk_status_t move_general(qk_world_t *w, qk__wobj_t *o, uint32_t i,
                                             const qk_shape_t *shape) {
  qk_shape_t s;
  qk_status_t st = qk__shape_normalize(shape, &s);
  if (st != QK_OK) return st;
  qk_box_t nb = qk__shape_box(&s);
  float step = step_of(o, &nb);
  set_shape(w, o, &s);
  refile_check(w, o, i, &nb, step);
  return QK_OK;
}

/* The move of a live object o (slot i) to a shape: the common case (a box needing no
 * normalisation, staying in its loose square) inline and branch-light, as the batch
 * call runs it once per object. With SSE2 the box's two corners are loaded once as
 * (x, y) and (a, b) and checked, stored and compared with the loose square two lanes at
 * a time: corners in order, every magnitude in [2^-100, 2^100] (for each axis the lesser
 * and the greater magnitude of its two values), then the square from (cx, cy) (adjacent
 * in the object) times 2^level. The same answers as box_ok and refile_check. */
static inline qk_status_t move_obj(qk_world_t *w, qk__wobj_t *o, uint32_t i,
                                   const qk_shape_t *shape) {
#if defined(__SSE2__)
  if (shape->kind != QK_SHAPE_BOX) return move_general(w, o, i, shape);
  const __m128d p = _mm_loadu_pd(&shape->x), q = _mm_loadu_pd(&shape->a);
  /* The most common move: a box that stays a box in its cell's loose square, which holds
   * only values the world accepts (QK__WCLEAN): corners in order and inside the square
   * (a NaN fails the comparisons) need no check of the values themselves. */
  if ((o->flags & (QK__WKIND | QK__WDIRTY | QK__WCLEAN)) == (QK_SHAPE_BOX | QK__WCLEAN)) {
    const __m128d s2 = _mm_set1_pd(qk__pow2(o->level));
    const __m128d lo = _mm_mul_pd(_mm_cvtepi32_pd(_mm_loadl_epi64((const __m128i *)&o->u.cx)), s2);
    const __m128d hi = _mm_add_pd(lo, _mm_add_pd(s2, s2));
    const __m128d in =
        _mm_and_pd(_mm_cmple_pd(p, q), _mm_and_pd(_mm_cmpge_pd(p, lo), _mm_cmplt_pd(q, hi)));
    if (_mm_movemask_pd(in) == 3) {
      const __m128d ext = _mm_sub_pd(q, p);
      if (!(_mm_cvtsd_f64(_mm_max_sd(ext, _mm_unpackhi_pd(ext, ext))) <= o->k.shrink)) {
        _mm_storeu_pd(&o->x, p);
        _mm_storeu_pd(&o->a, q);
        qk__world_fine_touch(w, o);
        return QK_OK;
      }
    }
  }
  {
    const __m128d sign = _mm_set1_pd(-0.0);
    const __m128d ap = _mm_andnot_pd(sign, p), aq = _mm_andnot_pd(sign, q);
    /* (NaN fails p <= q, so min / max never see one that matters) */
    const __m128d ok = _mm_and_pd(
        _mm_cmple_pd(p, q), _mm_and_pd(_mm_cmpge_pd(_mm_min_pd(ap, aq), _mm_set1_pd(0x1p-100)),
                                       _mm_cmple_pd(_mm_max_pd(ap, aq), _mm_set1_pd(0x1p100))));
    if (_mm_movemask_pd(ok) != 3) return move_general(w, o, i, shape);
  }
  const __m128d was = _mm_loadu_pd(&o->x);
  /* (stored as given: no copy through a normalised shape) */
  _mm_storeu_pd(&o->x, p);
  _mm_storeu_pd(&o->a, q);
  const unsigned fl = o->flags;
  o->flags = (uint8_t)((fl & ~QK__WKIND) | QK_SHAPE_BOX);
  if (fl & QK__WDIRTY) return QK_OK; /* filed at the next update anyway */
  const double s = qk__pow2(o->level);
  const __m128d s2 = _mm_set1_pd(s);
  const __m128d lo = _mm_mul_pd(_mm_cvtepi32_pd(_mm_loadl_epi64((const __m128i *)&o->u.cx)), s2);
  const __m128d hi = _mm_add_pd(lo, _mm_add_pd(s2, s2));
  if (_mm_movemask_pd(_mm_and_pd(_mm_cmpge_pd(p, lo), _mm_cmplt_pd(q, hi))) == 3) {
    const __m128d ext = _mm_sub_pd(q, p);
    if (!(_mm_cvtsd_f64(_mm_max_sd(ext, _mm_unpackhi_pd(ext, ext))) <= o->k.shrink)) {
      qk__world_fine_touch(w, o);
      return QK_OK;
    }
  }
  /* (its step: the larger move of (x, y); the same value as step_of) */
  const __m128d d = _mm_andnot_pd(_mm_set1_pd(-0.0), _mm_sub_pd(p, was));
  const double dm = _mm_cvtsd_f64(_mm_max_sd(d, _mm_unpackhi_pd(d, d)));
  o->k.step = dm < 0x1p100 ? (float)dm : 0x1p100f;
  make_dirty(w, i);
  return QK_OK;
#else
  if (!box_ok(shape)) return move_general(w, o, i, shape);
  /* (stored as given: no copy through a normalised shape) */
  qk_box_t nb = {shape->x, shape->y, shape->a, shape->b};
  float step = step_of(o, &nb);
  o->x = nb.xmin, o->y = nb.ymin, o->a = nb.xmax, o->b = nb.ymax;
  o->flags = (uint8_t)((o->flags & ~QK__WKIND) | QK_SHAPE_BOX);
  refile_check(w, o, i, &nb, step);
  return QK_OK;
#endif
}

qk_status_t qk_world_move(qk_world_t *w, qk_handle_t h, const qk_shape_t *shape) {
  if (!w || !shape) return QK_ERR_INVALID;
  qk__wobj_t *o = lookup(w, h);
  if (!o) return QK_ERR_NOT_FOUND;
  /* Moves in slot order (a caller's loop over its objects, added in that order): the
   * object QK__MOVE_AHEAD slots on, fetched for writing. On the two-vCPU guest of the
   * twenty-ninth session, where a line moved between the vCPUs' caches in 90-240 ns,
   * the moves after an update on two threads (whose worker had read half the objects)
   * took 1.7-1.9 ms for 10^5 boxes without it and 0.75-0.8 ms with it, as after one. */
  const uint32_t slot = (uint32_t)h;
  if (slot == w->move_next && slot + QK__MOVE_AHEAD < w->n_obj)
    qk__prefetch_write(o + QK__MOVE_AHEAD);
  w->move_next = slot + 1;
  return move_obj(w, o, (uint32_t)h, shape);
}

qk_status_t qk_world_move_batch(qk_world_t *w, const qk_handle_t *h, const qk_shape_t *shapes,
                                size_t n, qk_error_t *err) {
  qk__error_clear(err);
  if (!w || (n && (!h || !shapes))) {
    if (err) snprintf(err->message, sizeof err->message, "a NULL world, or NULL handles or shapes");
    return QK_ERR_INVALID;
  }
  const uint32_t n_obj = w->n_obj;
  for (size_t k = 0; k < n; k++) {
    /* The handle check: a live slot's generation is odd and a removed one's even, so an
     * odd generation equal to the slot's names its live object. */
    uint32_t slot = (uint32_t)h[k], gen = (uint32_t)(h[k] >> 32);
    /* (the object QK__MOVE_AHEAD moves on, fetched for writing: see qk_world_move) */
    if (k + QK__MOVE_AHEAD < n && (uint32_t)h[k + QK__MOVE_AHEAD] < n_obj)
      qk__prefetch_write(&w->obj[(uint32_t)h[k + QK__MOVE_AHEAD]]);
    qk_status_t st = QK_ERR_NOT_FOUND;
    if (slot < n_obj) {
      qk__wobj_t *o = &w->obj[slot];
      if (o->gen == gen && (gen & 1)) st = move_obj(w, o, slot, &shapes[k]);
    }
    if (st != QK_OK) {
      if (!err) return st;
      err->line = err->column = 0;
      err->item = k;
      snprintf(err->message, sizeof err->message, "move %zu (handle 0x%016llx): %s", k,
               (unsigned long long)h[k],
               st == QK_ERR_NOT_FOUND ? "no live object has this handle" : qk_strerror(st));
      return st;
    }
  }
  return QK_OK;
}

qk_status_t qk_world_remove(qk_world_t *w, qk_handle_t h) {
  if (!w) return QK_ERR_INVALID;
  qk__wobj_t *o = lookup(w, h);
  if (!o) return QK_ERR_NOT_FOUND;
  uint32_t i = (uint32_t)h;
  /* Its entry in the order (or the dirty list) stays until the next update, which drops
   * it: readers skip slots that are not live. */
  o->gen++;
  if (o->gen != 0) {
    o->u.free_next = w->free_head;
    w->free_head = i;
  } /* else its generations are spent (2^31 objects have held it): it is retired, never
     * reused, so that a handle of its first object is not taken for a new one */
  w->n_live--;
  w->ident_dirty = 1;
  return QK_OK;
}

qk_status_t qk_world_get(const qk_world_t *w, qk_handle_t h, qk_shape_t *shape, uint64_t *tag) {
  if (!w) return QK_ERR_INVALID;
  const qk__wobj_t *o = lookup(w, h);
  if (!o) return QK_ERR_NOT_FOUND;
  if (shape) *shape = qk__wshape(o);
  if (tag) *tag = o->tag;
  return QK_OK;
}

void qk__world_note_levels(qk_world_t *w) {
  int n = 0;
  for (int l = 0; l < QK__NLEV; l++)
    if (w->lv_n[l]) w->lv_occ[n++] = (int16_t)(l + QK__LMIN);
  w->n_lv_occ = n;
}

int qk__world_levels(const qk_world_t *w, int *levels) {
  for (int i = 0; i < w->n_lv_occ; i++) levels[i] = w->lv_occ[i];
  return w->n_lv_occ;
}
