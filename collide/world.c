/*
 * The moving-objects world: objects with stable handles, filed in a loose hierarchical
 * grid, and the per-frame pairs.
 *
 * Design. Each object keeps a fattened box (its box widened by a margin, half its size
 * by default) and is filed by that box in one cell of a grid of squares of side 2^L: the
 * smallest even L whose cell holds the fattened box's lower-left corner and reaches two
 * cells up and right past it, so the fat box lies in the cell's "loose" square
 * [cx 2^L, (cx + 2) 2^L) (exact: powers of two and floors; the far side open). The
 * object keeps that square; a move whose box stays inside it changes nothing else (four
 * comparisons), so steady motion re-files only the objects that drifted out of their
 * cell's loose square, having moved at least the margin. The cells of all levels live in one hash
 * table keyed by (level, cx, cy), each with an intrusive list of its objects; the table never holds
 * more cells than objects, so the world's memory is proportional to the live objects
 * whatever the churn.
 *
 * Levels adapt to the sizes (an object of size e sits at level ~log2 e, from 1e-3 to
 * 1e3 and beyond in one world; levels are a factor of 4 apart, which measured fewer
 * instructions than a factor of 2: fewer levels to visit, a few more objects per cell)
 * and to the coordinates (the cell index is kept below 2^51, so a unit object at 1e9 is
 * filed at level 0 and one at 1e30 at a coarser one).
 *
 * Pairs (collide/world_pairs.c): each update first copies the boxes into a packed array,
 * cell by cell, each cell headed by the box around its objects (and as floats, four
 * objects to a group, for a four-wide prefilter); every cell then meets the 5 cells
 * of its own level at or after it (itself and the neighbours whose loose squares reach it: indices
 * differing by at most 1), and each of its objects the cells of every coarser occupied level whose
 * loose squares meet the object's box (about four). Candidate pairs pass the exact box test, then
 * the exact shape test (collide/shape.c). Pairs are 64-bit keys counting-sorted by (slot a,
 * slot b), which makes
 * the order deterministic, the began / ended sets a merge of two sorted lists, and the
 * answer independent of the number of threads (each thread takes a range of the table).
 *
 * Handles: slot in the low 32 bits, generation in the high 32. A slot's generation is
 * odd while it is live and becomes even at removal; a freed slot is reused (last freed,
 * first reused) with the next odd generation, so stale handles never match.
 *
 * Failure: every allocation an operation needs is made before the world changes; add
 * reserves the object slot and the table room (the table keeps at least 4/3 as many
 * entries as objects, so filing never allocates), move and remove never allocate, and
 * update builds its new pair lists aside and swaps them in only when all succeeded.
 */
#include <stdlib.h>
#include <string.h>

#include "collide/world_internal.h"

void qk_world_options_init(qk_world_options_t *o) {
  if (!o) return;
  memset(o, 0, sizeof *o);
  o->threads = 1;
  o->margin = 0.5;
  o->min_margin = 0;
}

qk_status_t qk_world_new(const qk_world_options_t *options, qk_world_t **out) {
  if (!out) return QK_ERR_INVALID;
  *out = NULL;
  qk_world_options_t o;
  qk_world_options_init(&o);
  if (options) o = *options;
  /* Bounded margins keep every fat box, and so every level, inside the level table. */
  if (!(o.margin >= 0 && o.margin <= 16) || !(o.min_margin >= 0 && o.min_margin <= 0x1p100) ||
      o.threads == 0 || o.threads > 256)
    return QK_ERR_INVALID;
  qk_allocator_t a = {NULL, NULL};
  if (o.allocator) a = *o.allocator;
  qk_world_t *w = qk__realloc(&a, NULL, 0, sizeof *w);
  if (!w) return QK_ERR_NOMEM;
  memset(w, 0, sizeof *w);
  w->alloc = a;
  w->opt = o;
  w->opt.allocator = NULL;
  w->free_head = QK_NONE;
  *out = w;
  return QK_OK;
}

static void pvec_free(const qk_allocator_t *a, qk__pvec_t *p) {
  qk__free(a, p->v, p->cap * sizeof *p->v);
  p->v = NULL;
  p->n = p->cap = 0;
}

void qk_world_free(qk_world_t *w) {
  if (!w) return;
  qk_allocator_t a = w->alloc;
  qk__free(&a, w->obj, (size_t)w->cap_obj * sizeof *w->obj);
  qk__free(&a, w->cells, w->cap_cells * sizeof *w->cells);
  qk__free(&a, w->cur.v, w->cur.cap * sizeof *w->cur.v);
  qk__free(&a, w->began.v, w->began.cap * sizeof *w->began.v);
  pvec_free(&a, &w->ended);
  qk__free(&a, w->pack, w->cap_pack * sizeof *w->pack);
  qk__free(&a, w->fgrp, w->cap_fgrp * 16 * sizeof *w->fgrp);
  qk__free(&a, w->occ, w->cap_occ * sizeof *w->occ);
  qk__free(&a, w->found.v, w->found.cap * sizeof *w->found.v);
  qk__free(&a, w->count, w->cap_count * sizeof *w->count);
  qk__free(&a, w, sizeof *w);
}

size_t qk_world_size(const qk_world_t *w) { return w ? w->n_live : 0; }

size_t qk_world_bytes(const qk_world_t *w) {
  if (!w) return 0;
  return sizeof *w + (size_t)w->cap_obj * sizeof *w->obj + w->cap_cells * sizeof *w->cells +
         (w->cur.cap + w->began.cap + w->found.cap) * sizeof(uint64_t) +
         w->ended.cap * sizeof(qk_world_pair_t) + w->cap_pack * sizeof *w->pack +
         w->cap_count * sizeof *w->count + w->cap_fgrp * 16 * sizeof *w->fgrp +
         w->cap_occ * sizeof *w->occ;
}

/* ---- the cell table -------------------------------------------------------------- */

static size_t cell_find(const qk_world_t *w, int level, int64_t cx, int64_t cy) {
  return qk__cell_find(w, level, cx, cy);
}

const qk__wcell_t *qk__world_cell(const qk_world_t *w, int level, int64_t cx, int64_t cy) {
  return qk__cell_get(w, level, cx, cy);
}

/* Remove entry i, shifting later entries of its probe run back (no tombstones). */
static void cell_delete(qk_world_t *w, size_t i) {
  size_t mask = w->cap_cells - 1, j = i;
  w->cells[i].count = 0;
  for (;;) {
    j = (j + 1) & mask;
    qk__wcell_t *c = &w->cells[j];
    if (c->count == 0) return;
    size_t home = qk__cell_hash(c->level, c->cx, c->cy) & mask;
    /* c may move to i when i lies cyclically in [home, j). */
    int move = i <= j ? (home <= i || home > j) : (home <= i && home > j);
    if (move) {
      w->cells[i] = *c;
      c->count = 0;
      i = j;
    }
  }
}

/* Rebuild the table with `cap` entries (a power of two); the world is unchanged when
 * memory is short. */
static qk_status_t cells_resize(qk_world_t *w, size_t cap) {
  qk__wcell_t *nc = qk__realloc(&w->alloc, NULL, 0, cap * sizeof *nc);
  if (!nc) return QK_ERR_NOMEM;
  memset(nc, 0, cap * sizeof *nc);
  qk__wcell_t *old = w->cells;
  size_t old_cap = w->cap_cells;
  w->cells = nc;
  w->cap_cells = cap;
  for (size_t i = 0; i < old_cap; i++) {
    if (old[i].count == 0) continue;
    nc[cell_find(w, old[i].level, old[i].cx, old[i].cy)] = old[i];
  }
  qk__free(&w->alloc, old, old_cap * sizeof *old);
  return QK_OK;
}

/* ---- filing ---------------------------------------------------------------------- */

/* Smallest L with 2^L >= e (e >= 0). */
static int ceil_log2(double e) {
  if (e <= 0) return QK__LMIN;
  int ex;
  double m = frexp(e, &ex); /* e = m 2^ex, m in [0.5, 1) */
  return m == 0.5 ? ex - 1 : ex;
}

/* The level and cell of a fat box (see the file comment). */
static void cell_of(const qk_box_t *f, int *level, int64_t *cx, int64_t *cy) {
  double e = qk__max(f->xmax - f->xmin, f->ymax - f->ymin);
  double mag =
      qk__max(qk__max(fabs(f->xmin), fabs(f->xmax)), qk__max(fabs(f->ymin), fabs(f->ymax)));
  int l = ceil_log2(e);
  l += l & 1; /* levels a factor of 4 apart: fewer levels to visit, a few more objects per cell */
  if (mag > 0 && ilogb(mag) - 50 > l) l = ilogb(mag) - 50;
  if (l < QK__LMIN) l = QK__LMIN;
  for (;; l++) {
    double inv = qk__pow2(-l), s = qk__pow2(l);
    double x = floor(f->xmin * inv), y = floor(f->ymin * inv);
    if (f->xmax < (x + 2) * s && f->ymax < (y + 2) * s) {
      *level = l;
      *cx = (int64_t)x;
      *cy = (int64_t)y;
      return;
    }
  }
}

/* The cell of a filed object: its loose square's corner over the cell side (exact). */
static inline void obj_cell(const qk__wobj_t *o, int64_t *cx, int64_t *cy) {
  double inv = qk__pow2(-o->level);
  *cx = (int64_t)(o->loose.xmin * inv);
  *cy = (int64_t)(o->loose.ymin * inv);
}

/* File object i in cell (level, cx, cy); the table has room (see reserve). */
static void file_obj(qk_world_t *w, uint32_t i, int level, int64_t cx, int64_t cy) {
  qk__wobj_t *o = &w->obj[i];
  o->level = (int16_t)level;
  double s = qk__pow2(level);
  o->loose = (qk_box_t){(double)cx * s, (double)cy * s, (double)(cx + 2) * s, (double)(cy + 2) * s};
  size_t k = cell_find(w, level, cx, cy);
  qk__wcell_t *c = &w->cells[k];
  if (c->count == 0) {
    *c = (qk__wcell_t){cx, cy, level, QK_NONE, 0, 0};
    w->n_cells++;
    w->level_cells[level - QK__LMIN]++;
  }
  o->prev = QK_NONE;
  o->next = c->head;
  if (c->head != QK_NONE) w->obj[c->head].prev = i;
  c->head = i;
  c->count++;
  w->level_objs[level - QK__LMIN]++;
}

static void unfile_obj(qk_world_t *w, uint32_t i) {
  qk__wobj_t *o = &w->obj[i];
  int64_t cx, cy;
  obj_cell(o, &cx, &cy);
  size_t k = cell_find(w, o->level, cx, cy);
  qk__wcell_t *c = &w->cells[k];
  if (o->prev != QK_NONE)
    w->obj[o->prev].next = o->next;
  else
    c->head = o->next;
  if (o->next != QK_NONE) w->obj[o->next].prev = o->prev;
  w->level_objs[o->level - QK__LMIN]--;
  if (--c->count == 0) {
    w->n_cells--;
    w->level_cells[o->level - QK__LMIN]--;
    cell_delete(w, k);
  }
}

/* Set the shape and compute the cell its fat box (box widened by the margin) files it
 * in. */
static void set_shape(const qk_world_t *w, qk__wobj_t *o, const qk_shape_t *s, const qk_box_t *b,
                      int *level, int64_t *cx, int64_t *cy) {
  o->s = *s;
  o->box = *b;
  double e = qk__max(b->xmax - b->xmin, b->ymax - b->ymin);
  double m = w->opt.margin * e + w->opt.min_margin;
  if (!isfinite(m)) m = 0;
  qk_box_t fat = {b->xmin - m, b->ymin - m, b->xmax + m, b->ymax + m};
  o->fe = qk__max(fat.xmax - fat.xmin, fat.ymax - fat.ymin);
  cell_of(&fat, level, cx, cy);
}

/* a inside the loose square b (its far sides open). */
static inline int box_in_loose(const qk_box_t *a, const qk_box_t *b) {
  return a->xmin >= b->xmin && a->ymin >= b->ymin && a->xmax < b->xmax && a->ymax < b->ymax;
}

/* The live object of a handle, or NULL. */
static qk__wobj_t *lookup(const qk_world_t *w, qk_handle_t h) {
  uint32_t slot = (uint32_t)h, gen = (uint32_t)(h >> 32);
  if (slot >= w->n_obj) return NULL;
  qk__wobj_t *o = &w->obj[slot];
  return o->live && o->gen == gen ? o : NULL;
}

/* Room for one more object: a slot and table entries (at most one cell per object). */
static qk_status_t reserve(qk_world_t *w) {
  if (w->free_head == QK_NONE && w->n_obj == w->cap_obj) {
    if (w->cap_obj >= UINT32_MAX / 2) return QK_ERR_LIMIT;
    uint32_t cap = w->cap_obj ? w->cap_obj + w->cap_obj / 2 : 16; /* 1.5x: less slack */
    qk__wobj_t *no =
        qk__realloc(&w->alloc, w->obj, (size_t)w->cap_obj * sizeof *no, (size_t)cap * sizeof *no);
    if (!no) return QK_ERR_NOMEM;
    w->obj = no;
    w->cap_obj = cap;
  }
  /* Filing makes at most one cell an object: a load of at most 3/4 then. */
  size_t need = (w->n_live + 1) + (w->n_live + 1) / 3 + 1;
  if (w->cap_cells < need) {
    size_t cap = w->cap_cells ? w->cap_cells : 32;
    while (cap < need) cap *= 2;
    return cells_resize(w, cap);
  }
  return QK_OK;
}

qk_status_t qk_world_add(qk_world_t *w, const qk_shape_t *shape, uint64_t tag, qk_handle_t *h) {
  if (!w || !shape || !h) return QK_ERR_INVALID;
  *h = QK_HANDLE_NONE;
  qk_shape_t s;
  qk_status_t st = qk__shape_normalize(shape, &s);
  if (st != QK_OK) return st;
  if ((st = reserve(w)) != QK_OK) return st;
  uint32_t i;
  if (w->free_head != QK_NONE) {
    i = w->free_head;
    w->free_head = w->obj[i].next;
    w->obj[i].gen++;
  } else {
    i = w->n_obj++;
    w->obj[i].gen = 1;
    w->obj[i].ugen = 0;
  }
  qk__wobj_t *o = &w->obj[i];
  o->live = 1;
  o->tag = tag;
  qk_box_t b = qk__shape_box(&s);
  int level;
  int64_t cx, cy;
  set_shape(w, o, &s, &b, &level, &cx, &cy);
  file_obj(w, i, level, cx, cy);
  w->n_live++;
  w->ident_dirty = 1;
  *h = qk__handle(w, i);
  return QK_OK;
}

/* qk__shape_normalize for a box whose values need no change (the common move). */
static inline int box_ok(const qk_shape_t *s) {
  return s->kind == QK_SHAPE_BOX && s->x <= s->a && s->y <= s->b && qk__value_ok(s->x) &&
         qk__value_ok(s->y) && qk__value_ok(s->a) && qk__value_ok(s->b);
}

qk_status_t qk_world_move(qk_world_t *w, qk_handle_t h, const qk_shape_t *shape) {
  if (!w || !shape) return QK_ERR_INVALID;
  qk__wobj_t *o = lookup(w, h);
  if (!o) return QK_ERR_NOT_FOUND;
  qk_shape_t s;
  qk_box_t nb;
  if (box_ok(shape)) { /* value_ok excludes NaN and infinities */
    s = *shape;
    nb = (qk_box_t){s.x, s.y, s.a, s.b};
  } else {
    qk_status_t st = qk__shape_normalize(shape, &s);
    if (st != QK_OK) return st;
    nb = qk__shape_box(&s);
  }
  if (box_in_loose(&nb, &o->loose)) {
    /* Still inside its cell's loose square: only the shape changes (unless it shrank so
     * much that a finer level would serve it better, which re-files it below). */
    double e = qk__max(nb.xmax - nb.xmin, nb.ymax - nb.ymin);
    if (!(e * 8 < o->fe)) {
      o->s = s;
      o->box = nb;
      return QK_OK;
    }
  }
  uint32_t i = (uint32_t)h;
  int level;
  int64_t cx, cy, ox, oy;
  set_shape(w, o, &s, &nb, &level, &cx, &cy);
  obj_cell(o, &ox, &oy);
  if (level == o->level && cx == ox && cy == oy) return QK_OK;
  unfile_obj(w, i);
  file_obj(w, i, level, cx, cy);
  return QK_OK;
}

qk_status_t qk_world_remove(qk_world_t *w, qk_handle_t h) {
  if (!w) return QK_ERR_INVALID;
  qk__wobj_t *o = lookup(w, h);
  if (!o) return QK_ERR_NOT_FOUND;
  uint32_t i = (uint32_t)h;
  unfile_obj(w, i);
  o->live = 0;
  o->gen++;
  o->next = w->free_head;
  w->free_head = i;
  w->n_live--;
  w->ident_dirty = 1;
  /* Give table memory back after mass removal; failure to shrink is harmless. */
  if (w->cap_cells > 64 && w->n_live * 8 < w->cap_cells) (void)cells_resize(w, w->cap_cells / 2);
  return QK_OK;
}

qk_status_t qk_world_get(const qk_world_t *w, qk_handle_t h, qk_shape_t *shape, uint64_t *tag) {
  if (!w) return QK_ERR_INVALID;
  const qk__wobj_t *o = lookup(w, h);
  if (!o) return QK_ERR_NOT_FOUND;
  if (shape) *shape = o->s;
  if (tag) *tag = o->tag;
  return QK_OK;
}

int qk__world_levels(const qk_world_t *w, int *levels) {
  int n = 0;
  for (int l = 0; l < QK__NLEV; l++)
    if (w->level_cells[l]) levels[n++] = l + QK__LMIN;
  return n;
}
