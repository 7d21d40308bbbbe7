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
#include "index/inline.h"

static inline int boxes_meet(const qk_box_t *a, const qk_box_t *b) {
  return a->xmin <= b->xmax && b->xmin <= a->xmax && a->ymin <= b->ymax && b->ymin <= a->ymax;
}

/* The steps of a binary search among n cells, and two: the cost of a row's search that
 * the choices between searching rows, walking and scanning weigh (floor(log2(n + 1)) + 2,
 * from the bits: log2 was a call of some 50 instructions a level and query). */
static inline double lg_cells(uint32_t n) {
  return (double)(63 - __builtin_clzll((uint64_t)n + 1)) + 2;
}

/* v / 2^l floored, clamped far inside the int64 range. (The product by 2^-l is
 * ldexp(v, -l) bit for bit, an exact scaling rounded as ldexp rounds, without its call:
 * it was a tenth of a query in the clustered world.) */
static int64_t scaled(double v, int l) {
  double s = v * qk__pow2(-l);
  s = s < 0x1p60 ? s : 0x1p60;
  s = s > -0x1p60 ? s : -0x1p60;
  const int64_t i = (int64_t)s; /* (toward zero, exactly; then down: floor without its call) */
  return i - ((double)i > s);
}

/* Object i if it is where the order files it (live, not dirty) and its box meets qb. */
static inline int visit_obj(const qk_world_t *w, uint32_t i, const qk_box_t *qb, qk__wvisit_fn fn,
                            void *ud) {
  const qk__wobj_t *o = &w->obj[i];
  if (!qk__wlive(o) || (o->flags & QK__WDIRTY)) return 0;
  qk_box_t b = qk__wbox(o);
  return boxes_meet(&b, qb) && fn(w, i, &b, ud);
}

static const qk__wfine_t *fine_of(const qk_world_t *w, uint32_t c);
static int visit_groups(const qk_world_t *w, const qk__wfine_t *f, const qk_box_t *qb,
                        const qk_point_t *seg, qk__wvisit_fn fn, void *ud);

/* The objects of cell c that are where the order files them (live, not dirty) and whose
 * boxes meet qb: in a crowded cell, those of its groups whose boxes meet qb. */
static int visit_cell(const qk_world_t *w, uint32_t c, qk_box_t qb, const qk_point_t *seg,
                      qk__wvisit_fn fn, void *ud) {
  const uint32_t s = w->cells[c].start, e = w->cells[c + 1].start;
  if (e - s >= QK__FINE_MIN) {
    const qk__wfine_t *f = fine_of(w, c);
    if (f) return visit_groups(w, f, &qb, seg, fn, ud);
  }
  for (uint32_t k = s; k < e; k++)
    if (visit_obj(w, w->order[k], &qb, fn, ud)) return 1;
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

/* ---- where a level's cells are ------------------------------------------------------ */

/* Level li's bitmap (qb_*, after the tree's qx0 and qy0 are set): the shift that keeps it
 * within 8 bits a cell and 64, its rows' width and its rows; 0 words when it has none. */
static size_t bits_shape(qk_world_t *w, int li) {
  const uint32_t f = w->lv_first[li], m = w->lv_n[li];
  const qk__wcell_t *c = w->cells + f;
  int64_t x1 = c[0].cx;
  for (uint32_t k = 1; k < m; k++) x1 = c[k].cx > x1 ? c[k].cx : x1;
  const uint64_t wd = (uint64_t)(x1 - w->qx0[li]),
                 ht = (uint64_t)((int64_t)c[m - 1].cy - w->qy0[li]);
  const uint64_t room = 8 * (uint64_t)m + 64;
  int sh = 0;
  while ((wd >> sh) + 1 > room / ((ht >> sh) + 1)) sh++; /* (the product, without overflow) */
  w->qb_s[li] = (uint8_t)sh, w->qb_w[li] = (uint32_t)(wd >> sh) + 1;
  w->qb_h[li] = (uint32_t)(ht >> sh) + 1;
  return ((size_t)w->qb_w[li] * w->qb_h[li] + 63) / 64;
}

/* The bitmaps of the occupied levels; none (qb_w 0) when out of memory. */
static void bits_make(qk_world_t *w) {
  size_t words = 0;
  for (int i = 0; i < w->n_lv_occ; i++) {
    const int li = w->lv_occ[i] - QK__LMIN;
    w->qb_off[li] = (uint32_t)words;
    words += bits_shape(w, li);
  }
  if (words > w->cap_qbits || w->cap_qbits > 2 * words + 64) {
    qk__free(&w->alloc, w->qbits, w->cap_qbits * sizeof *w->qbits);
    w->qbits = qk__realloc(&w->alloc, NULL, 0, words * sizeof *w->qbits);
    w->cap_qbits = w->qbits ? words : 0;
  }
  if (!w->qbits) {
    for (int i = 0; i < w->n_lv_occ; i++) w->qb_w[w->lv_occ[i] - QK__LMIN] = 0;
    return;
  }
  memset(w->qbits, 0, words * sizeof *w->qbits);
  for (int i = 0; i < w->n_lv_occ; i++) {
    const int li = w->lv_occ[i] - QK__LMIN, sh = w->qb_s[li];
    const uint32_t f = w->lv_first[li], m = w->lv_n[li];
    uint64_t *b = w->qbits + w->qb_off[li];
    uint64_t set = 0;
    for (uint32_t k = 0; k < m; k++) {
      const qk__wcell_t *c = &w->cells[f + k];
      const uint64_t x = (uint64_t)((int64_t)c->cx - w->qx0[li]) >> sh;
      const uint64_t y = (uint64_t)((int64_t)c->cy - w->qy0[li]) >> sh;
      const uint64_t bit = y * w->qb_w[li] + x, word = b[bit / 64];
      set += !(word >> (bit % 64) & 1);
      b[bit / 64] = word | UINT64_C(1) << (bit % 64);
    }
    /* (a level whose bits are mostly set, as a uniform world's, is searched without: its
     * rows have cells, and the test would only add to their search) */
    if (2 * set > (uint64_t)w->qb_w[li] * w->qb_h[li]) w->qb_w[li] = 0;
  }
}

/* Level li's bitmap over the columns [x0, x1] of its cells, row by row (level_rows, then
 * row_has): none when it has no bitmap or the columns are too many to look at. */
typedef struct lvrows {
  const uint64_t *b; /* NULL: every row may have cells */
  uint64_t bw, bh, bx0, bx1;
  int64_t y0;
  int sh;
} lvrows_t;

/* The bitmap's columns (or rows) [*b0, *b1] that cells [lo, hi] fall in, along an axis
 * whose bitmap starts at cell `origin` and has n of them, shifted by sh; 0 when none. */
static inline int bit_span(int64_t lo, int64_t hi, int64_t origin, int sh, uint64_t n, uint64_t *b0,
                           uint64_t *b1) {
  lo -= origin, hi -= origin;
  if (hi < 0 || lo > hi) return 0;
  *b0 = lo < 0 ? 0 : (uint64_t)lo >> sh;
  *b1 = (uint64_t)hi >> sh;
  if (*b0 >= n) return 0;
  if (*b1 >= n) *b1 = n - 1;
  return 1;
}

/* 0 when level li surely has no cell in columns [x0, x1]. */
static int level_rows(const qk_world_t *w, int li, int64_t x0, int64_t x1, lvrows_t *v) {
  v->b = NULL;
  const uint64_t bw = w->qb_w[li];
  if (!bw) return 1;
  uint64_t bx0, bx1;
  if (!bit_span(x0, x1, w->qx0[li], w->qb_s[li], bw, &bx0, &bx1)) return 0;
  if (bx1 - bx0 >= 128) return 1; /* (too many to look at) */
  *v = (lvrows_t){w->qbits + w->qb_off[li], bw, w->qb_h[li], bx0, bx1, w->qy0[li], w->qb_s[li]};
  return 1;
}

/* Whether the bitmap's row by (below bh) has bits in the columns of v. */
static inline int bitrow_has(const lvrows_t *v, uint64_t by) {
  const uint64_t lo = by * v->bw + v->bx0, hi = lo + (v->bx1 - v->bx0);
  const uint64_t *b = v->b + lo / 64, mlo = ~UINT64_C(0) << (lo % 64);
  const uint64_t mhi = ~UINT64_C(0) >> (63 - hi % 64);
  if (lo / 64 == hi / 64) return (b[0] & mlo & mhi) != 0;
  if (b[0] & mlo) return 1;
  for (uint64_t k = 1; k < hi / 64 - lo / 64; k++)
    if (b[k]) return 1;
  return (b[hi / 64 - lo / 64] & mhi) != 0;
}

/* Whether level li may have cells in range r: 0 only when its bitmap shows none. */
static int level_has(const qk_world_t *w, int li, const crange_t *r) {
  lvrows_t v;
  if (!w->qb_w[li]) return 1;
  if (!level_rows(w, li, r->x0, r->x1, &v)) return 0;
  if (!v.b) return 1;
  uint64_t by0, by1;
  if (!bit_span(r->y0, r->y1, v.y0, v.sh, v.bh, &by0, &by1)) return 0;
  if (by1 - by0 >= 64) return 1; /* (too many to look at) */
  for (uint64_t by = by0; by <= by1; by++)
    if (bitrow_has(&v, by)) return 1;
  return 0;
}

/* The cells of level l in range r (row by row, each row found by binary search), but
 * those in *skip. With bits (the query tree is made), rows where the level's bitmap has
 * none of r's cells are not searched. The rows without cells are stepped over, not walked
 * through: a row whose search finds the next cell in a later row goes on from that row,
 * and a bitmap row without bits from the next one, so the walk takes at most a step a
 * bitmap row and two a row with cells, however many rows r spans (a range of 2^55 rows,
 * from a point ray at 2^100 widened by its rounding margin, hung the walk that stepped
 * row by row: fuzz/regressions/world/ray-far-point-rows). */
static QK__ALWAYS_INLINE int visit_range(const qk_world_t *w, int l, crange_t r,
                                         const crange_t *skip, qk_box_t qb, const qk_point_t *seg,
                                         qk__wvisit_fn fn, void *ud, int bits) {
  const uint32_t end = w->lv_first[l - QK__LMIN] + w->lv_n[l - QK__LMIN];
  const qk__wcell_t *cl = w->cells;
  lvrows_t v;
  v.b = NULL;
  if (bits && w->qb_w[l - QK__LMIN] && !level_rows(w, l - QK__LMIN, r.x0, r.x1, &v)) return 0;
  int64_t y = r.y0;
  uint32_t lo = w->lv_first[l - QK__LMIN]; /* (the searches go forward: from the last cell found) */
  while (y <= r.y1) {
    if (v.b) { /* (the bitmap's row of y: none before its first or past its last) */
      if (y < v.y0) {
        y = v.y0;
        continue;
      }
      const uint64_t by = (uint64_t)(y - v.y0) >> v.sh;
      if (by >= v.bh) return 0;
      if (!bitrow_has(&v, by)) {
        y = v.y0 + (int64_t)((by + 1) << v.sh);
        continue;
      }
    }
    uint32_t k = qk__cell_bisect(cl, lo, end, y, r.x0);
    lo = k;
    if (k >= end || cl[k].cy > r.y1) return 0;
    if (cl[k].cy != y) { /* (no cell in rows y .. cy - 1 at or after column x0) */
      y = cl[k].cy;
      continue;
    }
    for (; k < end && cl[k].cy == y && cl[k].cx <= r.x1; k++) {
      if (skip && in_range(skip, cl[k].cx, y)) continue;
      if (visit_cell(w, k, qb, seg, fn, ud)) return 1;
    }
    y++;
  }
  return 0;
}

/* Every cell of level l in range r, by scanning the level's cells. */
static int scan_level(const qk_world_t *w, int l, crange_t r, qk_box_t qb, const qk_point_t *seg,
                      qk__wvisit_fn fn, void *ud) {
  uint32_t k = w->lv_first[l - QK__LMIN], end = k + w->lv_n[l - QK__LMIN];
  for (; k < end; k++)
    if (in_range(&r, w->cells[k].cx, w->cells[k].cy) && visit_cell(w, k, qb, seg, fn, ud)) return 1;
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
/* The margin of a segment's pieces: 2^-40 of its ends' magnitudes. */
static inline double piece_margin(const qk_point_t *seg) {
  return (fabs(seg[0].x) + fabs(seg[0].y) + fabs(seg[1].x) + fabs(seg[1].y)) * 0x1p-40;
}

/* Piece k of n of the segment seg[0] -> seg[1] (k = 1 .. n, in order): the box from the
 * end of piece k - 1 (*p, updated to piece k's end) to the point at k / n, widened by
 * e = 2^-40 of the ends' magnitudes, far more than the points' rounding. */
typedef struct pieces {
  qk_point_t a, b, p;
  double e;
  size_t n;
  qk_box_t box; /* the segment's box */
} pieces_t;

static pieces_t pieces_of(const qk_point_t *seg, size_t n) {
  const qk_point_t a = seg[0], b = seg[1];
  const qk_box_t box = {qk__min(a.x, b.x), qk__min(a.y, b.y), qk__max(a.x, b.x), qk__max(a.y, b.y)};
  return (pieces_t){a, b, a, piece_margin(seg), n, box};
}

/* (clipped to the segment's box, which holds the whole segment: the margin, 2^-40 of
 * the ends' magnitudes, can be far wider than the segment, as for a short one far out) */
static qk_box_t next_piece(pieces_t *s, size_t k) {
  const double t = (double)k / (double)s->n;
  const qk_point_t a = s->a, b = s->b, p = s->p;
  const qk_point_t q = k == s->n ? b : (qk_point_t){a.x + t * (b.x - a.x), a.y + t * (b.y - a.y)};
  s->p = q;
  return (qk_box_t){qk__max(qk__min(p.x, q.x) - s->e, s->box.xmin),
                    qk__max(qk__min(p.y, q.y) - s->e, s->box.ymin),
                    qk__min(qk__max(p.x, q.x) + s->e, s->box.xmax),
                    qk__min(qk__max(p.y, q.y) + s->e, s->box.ymax)};
}

/* The rows of level l a piece of n of segment seg (box qb) spans at most: its share of
 * the box's height and its margin on both sides, within the box's height, and a row or
 * two of each end's cell. */
static double piece_rows(const qk_box_t *qb, const qk_point_t *seg, double n, int l) {
  const double h = qb->ymax - qb->ymin;
  return qk__min(h, h / n + 2 * piece_margin(seg)) / qk__pow2(l) + 3;
}

static int visit_along(const qk_world_t *w, int l, const qk_point_t *seg, double pieces,
                       qk_box_t qb, qk__wvisit_fn fn, void *ud, int bits) {
  crange_t prev = {1, 0, 1, 0}; /* empty */
  pieces_t s = pieces_of(seg, (size_t)pieces);
  for (size_t k = 1; k <= s.n; k++) {
    crange_t r = range_of(next_piece(&s, k), l);
    if (visit_range(w, l, r, &prev, qb, seg, fn, ud, bits)) return 1;
    prev = r;
  }
  return 0;
}

/* The state of a ray query (collide/world_query.c's rays, and the query tree's pruning). */
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

/* Boxes and points, whose distance and ray parameter (qk__shape_dist, qk__ray_param)
 * are those of their boxes computed in long double, to within a few ulps of the real
 * values: a bound from the box in doubles then bounds the computed value too. (A disc's
 * or a segment's is computed with cancellations whose error can exceed any fixed
 * relative margin, so they are always computed, as before: the answers stay the same.) */
static inline int box_like(const qk__wobj_t *o) {
  const unsigned k = o->flags & QK__WKIND;
  return k == QK_SHAPE_BOX || k == QK_SHAPE_POINT;
}

/* The segment's slabs over box b, as parameters: returns a lower bound of where the
 * segment from -> to (direction v, computed) enters b, in [0, 1], or more than 1 when it
 * misses the slabs (2 for an axis it does not move along, outside b): the slab entry in
 * doubles; and sets *exit to min(1, each axis's exit) computed as closely (not all axes'
 * when the entry is 2: any exit is below it then). Each quotient
 * is within 3 ulps of its real value, so both are off the real ones by far less than the
 * 2^-40 the callers leave. */
static inline double slab_entry(const rctx_t *c, const qk_box_t *b, double *exit) {
  const double ox = c->from.x, oy = c->from.y, vx = c->to.x - ox, vy = c->to.y - oy;
  double lo = 0;
  *exit = 1;
  if (vx != 0) {
    const double t1 = (b->xmin - ox) / vx, t2 = (b->xmax - ox) / vx;
    lo = qk__max(lo, qk__min(t1, t2)), *exit = qk__min(*exit, qk__max(t1, t2));
  } else if (ox < b->xmin || ox > b->xmax) {
    return 2;
  }
  if (vy != 0) {
    const double t1 = (b->ymin - oy) / vy, t2 = (b->ymax - oy) / vy;
    lo = qk__max(lo, qk__min(t1, t2)), *exit = qk__min(*exit, qk__max(t1, t2));
  } else if (oy < b->ymin || oy > b->ymax) {
    return 2;
  }
  return lo;
}

/* The entry alone (slab_entry). */
static inline double entry_bound(const rctx_t *c, const qk_box_t *b) {
  double exit;
  return slab_entry(c, b, &exit);
}

/* ---- the query tree -------------------------------------------------------------- */

/*
 * Each level's cells again in Morton order of (cx - qx0, cy - qy0): the quadtree over the
 * level's cells, implicit in that order. A run of two or more cells of it lies in one
 * square of the tree, the least whose key prefix its first and last keys share, and
 * that square's four quarters are the runs between the keys that begin them (binary
 * searches). A query descends from the level's whole run into the squares its region
 * meets, and so skips the empty space a row-by-row search steps through: a long ray
 * across a sparse world, a box over many rows of a fine level. Made by the first query
 * after an update that finds enough cells for it (the frames of a world nobody queries
 * pay nothing); until it is made, or if it cannot be (no memory), the queries search by
 * rows as before, with the same answers: every path decides the same candidates exactly.
 */
/* Fewer cells: rows and scans are as quick. (scripts/fuzz.sh builds with 2, so that the
 * fuzzer's worlds of a few dozen objects take the tree too.) */
#ifndef QK__TREE_MIN
#define QK__TREE_MIN 64
#endif
#define QK__TREE_LEAF 4 /* runs of this many cells are tested cell by cell */
/* With the tree there, a first hit walks its segment in pieces (visit_first) for at most
 * this many pieces: a dense world's first hit is often found by then; past them (sparse
 * or clustered worlds, long rays) the tree goes on, pruned by the best hit so far
 * (instructions a first hit, the benchmark's scenes at 10^4 objects, for 0 / 2 / 8 / 32
 * pieces: uniform 13.7 / 7.6 / 7.5 / 7.5 k, clustered 20.6 / 23.0 / 28.6 / 30.2 k, huge
 * 14.8 k for all). */
#define QK__FIRST_PIECES 2

/* The bits of v at the even bit positions of the result. */
static uint64_t spread(uint32_t v) {
  uint64_t x = v;
  x = (x | x << 16) & UINT64_C(0x0000ffff0000ffff);
  x = (x | x << 8) & UINT64_C(0x00ff00ff00ff00ff);
  x = (x | x << 4) & UINT64_C(0x0f0f0f0f0f0f0f0f);
  x = (x | x << 2) & UINT64_C(0x3333333333333333);
  return (x | x << 1) & UINT64_C(0x5555555555555555);
}

/* ---- groups in crowded cells ------------------------------------------------------ */

/*
 * A cell of many objects (a cluster's: at 10^4 objects of the benchmark's clustered scene a
 * cell of side 4 holds some 50 of sides 1-4, and a box query read 30 objects for each one
 * it found) is given bounds finer than its square: its live objects in the Morton order of
 * their boxes' centres within the cell's loose square (6 bits an axis), four to a group,
 * each group with the float box around its objects' boxes, and each run of four groups
 * with the box around theirs. A query reads the objects of the groups whose boxes meet
 * its box (in floats: see group_meets). The tree's making only sets out room for each
 * crowded cell; the first query that reads the cell fills it (one query, under the cell's
 * state: the others read the cell object by object meanwhile), so that a few queries
 * after an update pay for the cells they read. Objects removed since are skipped as
 * before; objects added or re-filed since are dirty, visited apart. A move that leaves
 * an object in its cell would leave its group's box behind: it marks the cell stale
 * (qk__world_fine_stale), whose objects the queries then read one by one until the next
 * update makes the tree anew.
 */
enum { FINE_EMPTY, FINE_FILLING, FINE_FILLED, FINE_STALE };

static size_t fine_groups16(size_t cap_fslot, size_t cap_fine) { return cap_fslot / 16 + cap_fine; }

static size_t fine_bytes(const qk_world_t *w) {
  if (!w->cap_fine) return 0;
  return (size_t)w->cap_fine * sizeof *w->fine + ((size_t)w->fmask + 1) * sizeof *w->fhash +
         w->cap_fslot * (sizeof *w->fslot + sizeof *w->fg4) +
         fine_groups16(w->cap_fslot, w->cap_fine) * 4 * sizeof *w->fg16;
}

static void fine_free(qk_world_t *w) {
  const qk_allocator_t *a = &w->alloc;
  if (w->cap_fine) {
    qk__free(a, w->fine, (size_t)w->cap_fine * sizeof *w->fine);
    qk__free(a, w->fhash, ((size_t)w->fmask + 1) * sizeof *w->fhash);
    qk__free(a, w->fslot, w->cap_fslot * sizeof *w->fslot);
    qk__free(a, w->fg4, w->cap_fslot * sizeof *w->fg4);
    qk__free(a, w->fg16, fine_groups16(w->cap_fslot, w->cap_fine) * 4 * sizeof *w->fg16);
  }
  w->fine = NULL, w->fhash = NULL, w->fslot = NULL, w->fg4 = NULL, w->fg16 = NULL;
  w->cap_fine = 0, w->fmask = 0, w->cap_fslot = 0, w->n_fine = 0;
}

void qk__world_qtree_free(qk_world_t *w) {
  qk__free(&w->alloc, w->qkey, (size_t)w->cap_q * sizeof *w->qkey);
  qk__free(&w->alloc, w->qcell, (size_t)w->cap_q * sizeof *w->qcell);
  w->qkey = NULL, w->qcell = NULL, w->cap_q = 0;
  qk__free(&w->alloc, w->qtab, w->cap_qtab * sizeof *w->qtab);
  w->qtab = NULL, w->cap_qtab = 0;
  qk__free(&w->alloc, w->qbits, w->cap_qbits * sizeof *w->qbits);
  w->qbits = NULL, w->cap_qbits = 0;
  fine_free(w);
  atomic_store_explicit(&w->qbytes, 0, memory_order_relaxed);
}

static inline uint32_t fine_hash(int level, int32_t cx, int32_t cy) {
  const uint32_t h =
      (uint32_t)cx * 0x9E3779B1u ^ (uint32_t)cy * 0x85EBCA77u ^ (uint32_t)level * 0xC2B2AE3Du;
  return h ^ h >> 16;
}

void qk__world_fine_stale(qk_world_t *w, const qk__wobj_t *o) {
  if (++w->fine_moves > w->n_live / 16 + 64) { /* (many moves: every group dropped) */
    w->n_fine = 0;
    return;
  }
  for (uint32_t h = fine_hash(o->level, o->u.cx, o->cy) & w->fmask;; h = (h + 1) & w->fmask) {
    const uint32_t i = w->fhash[h];
    if (i == UINT32_MAX) return;
    const qk__wcell_t *cl = &w->cells[w->fine[i].cell];
    if (cl->cx == o->u.cx && cl->cy == o->cy && cl->level == o->level) {
      atomic_store_explicit(&w->fine[i].state, FINE_STALE, memory_order_relaxed);
      return;
    }
  }
}

/* A group's box g (xmin, ymin, -xmax, -ymax) meets the query's q (xmax, ymax, -xmin, -ymin).
 * Both are rounded to floats to nearest, which keeps the order of any two values (a <= b
 * gives (float)a <= (float)b) and commutes with negation: boxes that meet still meet. */
static inline int group_meets(const float *g, const float *q) {
  return g[0] <= q[0] && g[1] <= q[1] && g[2] <= q[2] && g[3] <= q[3];
}

static inline int seg_may_meet(const qk_point_t *seg, const qk_box_t *b);

/* Whether the segment may meet group box g: its box widened by more than the rounding to
 * floats (2^-24 of a value, 2^-149 near zero), then seg_may_meet. */
static inline int group_seg_may_meet(const float *g, const qk_point_t *seg) {
  const double x0 = g[0], y0 = g[1], x1 = -(double)g[2], y1 = -(double)g[3];
  const qk_box_t b = {x0 - (fabs(x0) * 0x1p-23 + 0x1p-140), y0 - (fabs(y0) * 0x1p-23 + 0x1p-140),
                      x1 + (fabs(x1) * 0x1p-23 + 0x1p-140), y1 + (fabs(y1) * 0x1p-23 + 0x1p-140)};
  return seg_may_meet(seg, &b);
}

static int visit_groups(const qk_world_t *w, const qk__wfine_t *f, const qk_box_t *qb,
                        const qk_point_t *seg, qk__wvisit_fn fn, void *ud) {
  const float q[4] = {(float)qb->xmax, (float)qb->ymax, (float)-qb->xmin, (float)-qb->ymin};
  const uint32_t n4 = (f->n + 3) / 4;
  const float *g4 = w->fg4 + 4 * (size_t)f->g4, *g16 = w->fg16 + 4 * (size_t)f->g16;
  const uint32_t *slot = w->fslot + 4 * (size_t)f->g4;
  for (uint32_t j16 = 0; 4 * j16 < n4; j16++) {
    if (!group_meets(g16 + 4 * j16, q) || (seg && !group_seg_may_meet(g16 + 4 * j16, seg)))
      continue;
    const uint32_t e4 = 4 * j16 + 4 < n4 ? 4 * j16 + 4 : n4;
    for (uint32_t j = 4 * j16; j < e4; j++) {
      if (!group_meets(g4 + 4 * j, q) || (seg && !group_seg_may_meet(g4 + 4 * j, seg))) continue;
      for (uint32_t k = 4 * j; k < 4 * j + 4 && slot[k] != QK_NONE; k++)
        if (visit_obj(w, slot[k], qb, fn, ud)) return 1;
    }
  }
  return 0;
}

/* Where in its cell's loose square a box's centre lies: 6 bits an axis, interleaved. */
static uint32_t fine_key(const qk_box_t *b, const qk__wcell_t *c) {
  const double s = qk__pow2(5 - c->level); /* 64 steps over the square's side 2^(l + 1) */
  const double fx = (b->xmin + b->xmax) * 0.5 * s - (double)c->cx * 32;
  const double fy = (b->ymin + b->ymax) * 0.5 * s - (double)c->cy * 32;
  const uint32_t ix = !(fx > 0) ? 0 : fx >= 63 ? 63 : (uint32_t)fx;
  const uint32_t iy = !(fy > 0) ? 0 : fy >= 63 ? 63 : (uint32_t)fy;
  return (uint32_t)(spread(ix) | spread(iy) << 1);
}

/* Sorts keys[0, m) by their 12-bit key (in the high half); tmp: room for m. */
static void fine_sort(uint64_t *keys, uint64_t *tmp, uint32_t m) {
  if (m <= 48) {
    for (uint32_t i = 1; i < m; i++) {
      const uint64_t v = keys[i];
      uint32_t j = i;
      for (; j > 0 && keys[j - 1] > v; j--) keys[j] = keys[j - 1];
      keys[j] = v;
    }
    return;
  }
  /* two passes of six bits, through tmp and back */
  uint64_t *src = keys, *dst = tmp;
  for (int sh = 32; sh < 44; sh += 6) {
    uint32_t count[65] = {0};
    for (uint32_t i = 0; i < m; i++) count[((src[i] >> sh) & 63) + 1]++;
    for (int d = 0; d < 64; d++) count[d + 1] += count[d];
    for (uint32_t i = 0; i < m; i++) dst[count[(src[i] >> sh) & 63]++] = src[i];
    uint64_t *t = src;
    src = dst, dst = t;
  }
}

/* The box around boxes[0, n) as floats (xmin, ymin, -xmax, -ymax). */
static void group_box(float *g, const qk_box_t *b, uint32_t n) {
  qk_box_t u = b[0];
  for (uint32_t k = 1; k < n; k++) {
    u.xmin = qk__min(u.xmin, b[k].xmin), u.ymin = qk__min(u.ymin, b[k].ymin);
    u.xmax = qk__max(u.xmax, b[k].xmax), u.ymax = qk__max(u.ymax, b[k].ymax);
  }
  g[0] = (float)u.xmin, g[1] = (float)u.ymin, g[2] = (float)-u.xmax, g[3] = (float)-u.ymax;
}

/* Fills f's groups from its cell's live objects that are filed there; 0 when out of memory. */
#define QK__FINE_STACK 128
typedef struct fobj {
  qk_box_t b;
  uint32_t slot;
} fobj_t;
static int fine_fill(const qk_world_t *w, qk__wfine_t *f) {
  const qk__wcell_t *cl = &w->cells[f->cell];
  const uint32_t s = cl->start, e = cl[1].start, cap = e - s;
  uint64_t stack_keys[2 * QK__FINE_STACK];
  fobj_t stack_obj[QK__FINE_STACK];
  uint64_t *keys = stack_keys;
  fobj_t *ob = stack_obj;
  if (cap > QK__FINE_STACK) {
    keys = qk__realloc(&w->alloc, NULL, 0, 2 * (size_t)cap * sizeof *keys);
    ob = qk__realloc(&w->alloc, NULL, 0, (size_t)cap * sizeof *ob);
    if (!keys || !ob) {
      qk__free(&w->alloc, keys, keys ? 2 * (size_t)cap * sizeof *keys : 0);
      qk__free(&w->alloc, ob, ob ? (size_t)cap * sizeof *ob : 0);
      return 0;
    }
  }
  /* the objects (box and slot), and their keys with their places among them */
  uint32_t m = 0;
  for (uint32_t k = s; k < e; k++) {
    const uint32_t i = w->order[k];
    const qk__wobj_t *o = &w->obj[i];
    if (!qk__wlive(o) || (o->flags & QK__WDIRTY)) continue;
    ob[m] = (fobj_t){qk__wbox(o), i};
    keys[m] = (uint64_t)fine_key(&ob[m].b, cl) << 32 | m;
    m++;
  }
  fine_sort(keys, keys + cap, m);
  const uint32_t n4 = (m + 3) / 4, n16 = (n4 + 3) / 4;
  uint32_t *slot = w->fslot + 4 * (size_t)f->g4;
  float *g4 = w->fg4 + 4 * (size_t)f->g4;
  for (uint32_t j = 0; j < n4; j++) {
    const uint32_t n = 4 * j + 4 <= m ? 4 : m - 4 * j;
    qk_box_t gb[4];
    for (uint32_t k = 0; k < n; k++) {
      const fobj_t *x = &ob[(uint32_t)keys[4 * j + k]];
      slot[4 * j + k] = x->slot, gb[k] = x->b;
    }
    for (uint32_t k = n; k < 4; k++) slot[4 * j + k] = QK_NONE;
    group_box(g4 + 4 * j, gb, n);
  }
  for (uint32_t j = 0; j < n16; j++) {
    const float *gj = g4 + 16 * (size_t)j;
    float *u = w->fg16 + 4 * ((size_t)f->g16 + j);
    const uint32_t n = 4 * j + 4 <= n4 ? 4 : n4 - 4 * j;
    for (int d = 0; d < 4; d++) {
      u[d] = gj[d];
      for (uint32_t k = 1; k < n; k++) u[d] = gj[4 * k + d] < u[d] ? gj[4 * k + d] : u[d];
    }
  }
  f->n = m;
  if (keys != stack_keys) {
    qk__free(&w->alloc, keys, 2 * (size_t)cap * sizeof *keys);
    qk__free(&w->alloc, ob, (size_t)cap * sizeof *ob);
  }
  return 1;
}

/* The groups of cell c, filled by this query if no other has begun to, or NULL when there
 * are none to read (no tree made for this order, another query filling them, stale, or
 * no memory to sort the cell's objects). */
static const qk__wfine_t *fine_of(const qk_world_t *w, uint32_t c) {
  if (atomic_load_explicit(&((qk_world_t *)w)->qstate, memory_order_acquire) != 2 || !w->n_fine)
    return NULL;
  const qk__wcell_t *cl = &w->cells[c];
  for (uint32_t h = fine_hash(cl->level, cl->cx, cl->cy) & w->fmask;; h = (h + 1) & w->fmask) {
    const uint32_t i = w->fhash[h];
    if (i == UINT32_MAX) return NULL;
    qk__wfine_t *f = &w->fine[i];
    if (f->cell != c) continue;
    int st = atomic_load_explicit(&f->state, memory_order_acquire);
    if (st == FINE_FILLED) return f;
    if (st != FINE_EMPTY ||
        !atomic_compare_exchange_strong_explicit(&f->state, &st, FINE_FILLING, memory_order_acquire,
                                                 memory_order_relaxed))
      return NULL;
    const int ok = fine_fill(w, f);
    atomic_store_explicit(&f->state, ok ? FINE_FILLED : FINE_EMPTY, memory_order_release);
    return ok ? f : NULL;
  }
}

/* Sets out room for the groups of the order's crowded cells, none filled; 0 (and none)
 * when out of memory. */
static int fine_make(qk_world_t *w) {
  const qk_allocator_t *a = &w->alloc;
  uint32_t nf = 0;
  size_t ns = 0;
  for (uint32_t c = 0; c < w->n_cells; c++) {
    const uint32_t m = w->cells[c + 1].start - w->cells[c].start;
    if (m >= QK__FINE_MIN) nf++, ns += (m + 3) & ~(size_t)3;
  }
  w->n_fine = 0, w->fine_moves = 0;
  if (!nf) return 1;
  /* (made anew when outgrown, or when the crowded cells have shrunk to under half) */
  if (nf > w->cap_fine || ns > w->cap_fslot || w->cap_fine > 2 * (size_t)nf + 64 ||
      w->cap_fslot > 2 * ns + 1024) {
    fine_free(w);
    uint32_t hsize = 64;
    while (hsize < 2 * nf) hsize *= 2;
    w->fine = qk__realloc(a, NULL, 0, (size_t)nf * sizeof *w->fine);
    w->fhash = qk__realloc(a, NULL, 0, (size_t)hsize * sizeof *w->fhash);
    w->fslot = qk__realloc(a, NULL, 0, ns * sizeof *w->fslot);
    w->fg4 = qk__realloc(a, NULL, 0, ns * sizeof *w->fg4);
    w->fg16 = qk__realloc(a, NULL, 0, fine_groups16(ns, nf) * 4 * sizeof *w->fg16);
    w->cap_fine = nf, w->fmask = hsize - 1, w->cap_fslot = ns;
    if (!w->fine || !w->fhash || !w->fslot || !w->fg4 || !w->fg16) {
      fine_free(w);
      return 0;
    }
  }
  for (uint32_t h = 0; h <= w->fmask; h++) w->fhash[h] = UINT32_MAX;
  uint32_t g4 = 0, g16 = 0;
  for (uint32_t c = 0; c < w->n_cells; c++) {
    const qk__wcell_t *cl = &w->cells[c];
    const uint32_t m = cl[1].start - cl->start, n4 = (m + 3) / 4;
    if (m < QK__FINE_MIN) continue;
    qk__wfine_t *f = &w->fine[w->n_fine];
    f->cell = c, f->g4 = g4, f->g16 = g16, f->n = 0;
    atomic_init(&f->state, FINE_EMPTY);
    uint32_t h = fine_hash(cl->level, cl->cx, cl->cy) & w->fmask;
    while (w->fhash[h] != UINT32_MAX) h = (h + 1) & w->fmask;
    w->fhash[h] = w->n_fine++;
    g4 += n4, g16 += (n4 + 3) / 4;
  }
  return 1;
}

/* Sorts the keys and cells of [0, m) by key, least significant byte first, over the
 * bytes below `bytes`, through the scratch tk, tc. */
static void radix_sort(uint64_t *key, uint32_t *cell, uint64_t *tk, uint32_t *tc, uint32_t m,
                       int bytes) {
  uint64_t *sk = key, *dk = tk;
  uint32_t *sc = cell, *dc = tc;
  for (int b = 0; b < bytes; b++) {
    uint32_t count[257] = {0};
    const int sh = 8 * b;
    for (uint32_t i = 0; i < m; i++) count[((sk[i] >> sh) & 255) + 1]++;
    for (int d = 0; d < 256; d++) count[d + 1] += count[d];
    for (uint32_t i = 0; i < m; i++) {
      const uint32_t j = count[(sk[i] >> sh) & 255]++;
      dk[j] = sk[i], dc[j] = sc[i];
    }
    uint64_t *k = sk;
    sk = dk, dk = k;
    uint32_t *c = sc;
    sc = dc, dc = c;
  }
  if (sk != key) {
    memcpy(key, sk, (size_t)m * sizeof *key);
    memcpy(cell, sc, (size_t)m * sizeof *cell);
  }
}

/* The tables of the levels' top depths (qt_d and qt_sh set, keys sorted); none (qt_d 0)
 * when out of memory. */
static void tabs_make(qk_world_t *w) {
  size_t n = 0;
  for (int i = 0; i < w->n_lv_occ; i++) {
    const int li = w->lv_occ[i] - QK__LMIN;
    w->qt_off[li] = (uint32_t)n;
    if (w->qt_d[li]) n += ((size_t)1 << 2 * w->qt_d[li]) + 1;
  }
  if (n > w->cap_qtab || w->cap_qtab > 2 * n + 64) {
    qk__free(&w->alloc, w->qtab, w->cap_qtab * sizeof *w->qtab);
    w->qtab = n ? qk__realloc(&w->alloc, NULL, 0, n * sizeof *w->qtab) : NULL;
    w->cap_qtab = w->qtab ? n : 0;
  }
  for (int i = 0; i < w->n_lv_occ; i++) {
    const int li = w->lv_occ[i] - QK__LMIN, sh = w->qt_sh[li];
    if (!w->qt_d[li]) continue;
    if (!w->qtab) {
      w->qt_d[li] = 0;
      continue;
    }
    const uint64_t *key = w->qkey + w->lv_first[li];
    const uint32_t m = w->lv_n[li], last = (uint32_t)1 << 2 * w->qt_d[li];
    uint32_t *t = w->qtab + w->qt_off[li], j = 0;
    for (uint32_t k = 0; k < m; k++)
      for (const uint64_t b = key[k] >> sh; j <= b;) t[j++] = k;
    while (j <= last) t[j++] = m;
  }
}

/* Makes the tree for the order of the last update; 0 when out of memory. */
static int qtree_make(qk_world_t *w) {
  const qk_allocator_t *a = &w->alloc;
  const uint32_t nc = w->n_cells;
  /* (made anew when the cells outgrow it, or have shrunk to under half of it) */
  if (nc > w->cap_q || w->cap_q > 2 * (size_t)nc + 64) {
    qk__world_qtree_free(w);
    w->qkey = qk__realloc(a, NULL, 0, (size_t)nc * sizeof *w->qkey);
    w->qcell = qk__realloc(a, NULL, 0, (size_t)nc * sizeof *w->qcell);
    w->cap_q = nc;
    if (!w->qkey || !w->qcell) {
      qk__world_qtree_free(w);
      return 0;
    }
  }
  uint64_t *tk = qk__realloc(a, NULL, 0, (size_t)nc * sizeof *tk);
  uint32_t *tc = qk__realloc(a, NULL, 0, (size_t)nc * sizeof *tc);
  int ok = tk && tc;
  for (int i = 0; ok && i < w->n_lv_occ; i++) {
    const int l = w->lv_occ[i] - QK__LMIN;
    const uint32_t f = w->lv_first[l], m = w->lv_n[l];
    const qk__wcell_t *c = w->cells + f;
    int32_t x0 = c[0].cx; /* (rows by cy: the least cy is the first's) */
    for (uint32_t k = 1; k < m; k++) x0 = c[k].cx < x0 ? c[k].cx : x0;
    w->qx0[l] = x0, w->qy0[l] = c[0].cy;
    uint64_t all = 0;
    for (uint32_t k = 0; k < m; k++) {
      const uint64_t key = spread((uint32_t)((int64_t)c[k].cx - x0)) |
                           spread((uint32_t)((int64_t)c[k].cy - c[0].cy)) << 1;
      w->qkey[f + k] = key, w->qcell[f + k] = f + k;
      all |= key;
    }
    int bytes = 0;
    while (bytes < 8 && all >> (8 * bytes)) bytes++;
    radix_sort(w->qkey + f, w->qcell + f, tk, tc, m, bytes);
    /* the table of its top depths: at most an entry a cell */
    const int kb = all ? (64 - __builtin_clzll(all) + 1) & ~1 : 0;
    int d = 0;
    while (d < 5 && 2 * (d + 1) <= kb && (UINT64_C(4) << 2 * d) <= m) d++;
    w->qt_d[l] = (uint8_t)(d >= 2 ? d : 0), w->qt_sh[l] = (uint8_t)(kb - 2 * d);
  }
  if (ok) tabs_make(w);
  qk__free(a, tk, tk ? (size_t)nc * sizeof *tk : 0);
  qk__free(a, tc, tc ? (size_t)nc * sizeof *tc : 0);
  if (ok) bits_make(w); /* (without bitmaps or groups when they cannot be had) */
  if (ok && !fine_make(w)) w->n_fine = 0;
  atomic_store_explicit(&w->qbytes,
                        (size_t)w->cap_q * (sizeof *w->qkey + sizeof *w->qcell) +
                            (w->cap_qbits * sizeof *w->qbits + w->cap_qtab * sizeof *w->qtab) +
                            fine_bytes(w),
                        memory_order_relaxed);
  return ok;
}

/* Whether the query tree of the last update's order (and its crowded cells' groups) is
 * there to read, making it if no other query is (a query of a world shared by many
 * readers: the tree and qstate are the only state it writes, under qstate's protocol).
 * Made for the groups alone in a world of a few cells; tree_ready says whether to
 * descend the tree. */
static int qtree_ready(const qk_world_t *cw) {
  qk_world_t *w = (qk_world_t *)cw;
  const int s = atomic_load_explicit(&w->qstate, memory_order_acquire);
  if (s == 2) return 1;
  if (s != 0 || (w->n_cells < QK__TREE_MIN && w->n_order < QK__FINE_MIN)) return 0;
  int expect = 0;
  if (!atomic_compare_exchange_strong_explicit(&w->qstate, &expect, 1, memory_order_acquire,
                                               memory_order_relaxed))
    return 0;
  const int ok = qtree_make(w);
  atomic_store_explicit(&w->qstate, ok ? 2 : 0, memory_order_release);
  return ok;
}

static int tree_ready(const qk_world_t *w) { return qtree_ready(w) && w->n_cells >= QK__TREE_MIN; }

/* The first of keys [lo, hi) at or above k, or hi. */
static uint32_t key_lower(const uint64_t *keys, uint32_t lo, uint32_t hi, uint64_t k) {
  while (lo < hi) {
    const uint32_t mid = lo + (hi - lo) / 2;
    if (keys[mid] < k)
      lo = mid + 1;
    else
      hi = mid;
  }
  return lo;
}

/* Where the objects of cells [x, x + s) x [y, y + s) of level l lie (loose squares). */
static qk_box_t loose_box(int64_t x, int64_t y, int64_t s, int l) {
  const double u = qk__pow2(l);
  return (qk_box_t){(double)x * u, (double)y * u, (double)(x + s + 1) * u, (double)(y + s + 1) * u};
}

/* Whether the segment seg[0] -> seg[1] may meet box b: 0 only when it surely does not.
 * Apart from the exact test of the boxes, it misses b when b's corners all lie on one
 * side of its line: when the corner of the largest orientation (dx (y - py) - dy (x - px),
 * linear in the corner) is below zero, or the corner of the least above it. Each is
 * computed within 4 ulps of its two terms' magnitudes, and only a side beyond 2^-48 of
 * them counts. */
static inline int seg_may_meet(const qk_point_t *seg, const qk_box_t *b) {
  const qk_point_t p = seg[0], q = seg[1];
  if (qk__max(p.x, q.x) < b->xmin || qk__min(p.x, q.x) > b->xmax || qk__max(p.y, q.y) < b->ymin ||
      qk__min(p.y, q.y) > b->ymax)
    return 0;
  const double dx = q.x - p.x, dy = q.y - p.y;
  /* the corner of the largest orientation, then of the least */
  const double u1 = (dx > 0 ? b->ymax : b->ymin) - p.y, v1 = (dy > 0 ? b->xmin : b->xmax) - p.x;
  const double u0 = (dx > 0 ? b->ymin : b->ymax) - p.y, v0 = (dy > 0 ? b->xmax : b->xmin) - p.x;
  const double o1 = dx * u1 - dy * v1, t1 = (fabs(dx * u1) + fabs(dy * v1)) * 0x1p-48;
  const double o0 = dx * u0 - dy * v0, t0 = (fabs(dx * u0) + fabs(dy * v0)) * 0x1p-48;
  return !(o1 < -t1) && !(o0 > t0);
}

typedef struct tquery {
  int l;
  crange_t r;            /* level l's cells whose loose squares meet qb */
  const qk_point_t *seg; /* the segment whose box qb is, or NULL */
  const rctx_t *first;   /* a first hit among boxes and points (prunes by its t), or NULL */
  qk_box_t qb;
  qk__wvisit_fn fn;
  void *ud;
} tquery_t;

/* The square of a run of two or more cells of level li (keys from `key`): its least cell
 * (x, y) and side in cells, and its first key; its quarter k (x half k & 1, y half k >> 1)
 * holds the run's cells tree_quarters puts in [run[k], run[k + 1]). */
typedef struct tsquare {
  int64_t x, y, side;
  uint64_t org;
} tsquare_t;

static inline tsquare_t tree_square(const qk_world_t *w, int li, const uint64_t *key, uint32_t lo,
                                    uint32_t hi) {
  /* the least square whose key prefix the first and last keys share: side 2^s */
  const int s = (63 - __builtin_clzll(key[lo] ^ key[hi - 1])) / 2 + 1;
  const uint64_t org = s == 32 ? 0 : key[lo] & ~((UINT64_C(1) << 2 * s) - 1);
  /* (its corner: the first cell's coordinates, relative to the level's least, rounded down
   * to the side; the same as squeezing org's bits, for fewer instructions) */
  const qk__wcell_t *c = &w->cells[w->qcell[w->lv_first[li] + lo]];
  const int64_t side = INT64_C(1) << s, x0 = w->qx0[li], y0 = w->qy0[li];
  return (tsquare_t){x0 + (((int64_t)c->cx - x0) & ~(side - 1)),
                     y0 + (((int64_t)c->cy - y0) & ~(side - 1)), side, org};
}

static inline void tree_quarters(const qk_world_t *w, int li, const uint64_t *key,
                                 const tsquare_t *sq, uint32_t lo, uint32_t hi, uint32_t run[5]) {
  const uint64_t q = (uint64_t)(sq->side / 2) * (uint64_t)(sq->side / 2); /* a quarter's keys */
  run[0] = lo, run[4] = hi;
  if (w->qt_d[li] && q >= (UINT64_C(1) << w->qt_sh[li])) { /* (a square of the top depths) */
    const uint32_t *t = w->qtab + w->qt_off[li];
    const int sh = w->qt_sh[li];
    for (int k = 1; k < 4; k++) run[k] = t[(sq->org + (uint64_t)k * q) >> sh];
    return;
  }
  for (int k = 1; k < 4; k++) run[k] = key_lower(key, run[k - 1], hi, sq->org + (uint64_t)k * q);
}

/* Whether the cells [x, x + s) x [y, y + s) of the query's level may hold what it seeks. */
static int tree_meets(const tquery_t *t, int64_t x, int64_t y, int64_t s) {
  if (x > t->r.x1 || x + s - 1 < t->r.x0 || y > t->r.y1 || y + s - 1 < t->r.y0) return 0;
  if (!t->seg) return 1;
  const qk_box_t b = loose_box(x, y, s, t->l);
  if (!seg_may_meet(t->seg, &b)) return 0;
  /* every object there is reached after the best hit so far (see r_visit_first) */
  const rctx_t *c = t->first;
  return !c || c->best.h == QK_HANDLE_NONE || !(entry_bound(c, &b) > c->best.t + 0x1p-40);
}

/* The cells of the query's level that tree_meets, by the level's query tree: the
 * quarters nearest the segment's start first. */
static int tree_visit_run(const qk_world_t *w, const tquery_t *t, uint32_t lo0, uint32_t hi0) {
  const int li = t->l - QK__LMIN;
  const uint32_t base = w->lv_first[li];
  const uint64_t *key = w->qkey + base;
  const uint32_t *cell = w->qcell + base;
  const int near = !t->seg ? 0 : (t->seg[1].x < t->seg[0].x) | (t->seg[1].y < t->seg[0].y) << 1;
  uint32_t stack[2 * 136]; /* runs waiting: at most 3 a square of the descent, 32 deep */
  int sp = 0;
  stack[sp++] = lo0, stack[sp++] = hi0;
  while (sp) {
    const uint32_t hi = stack[--sp], lo = stack[--sp];
    if (hi - lo <= QK__TREE_LEAF) {
      for (uint32_t k = lo; k < hi; k++) {
        const qk__wcell_t *c = &w->cells[cell[k]];
        if (tree_meets(t, c->cx, c->cy, 1) && visit_cell(w, cell[k], t->qb, t->seg, t->fn, t->ud))
          return 1;
      }
      continue;
    }
    const tsquare_t sq = tree_square(w, li, key, lo, hi);
    if (!tree_meets(t, sq.x, sq.y, sq.side)) continue;
    uint32_t run[5];
    tree_quarters(w, li, key, &sq, lo, hi, run);
    /* pushed so that the quarter `near` comes off first */
    for (int j = 3; j >= 0; j--) {
      const int k = near ^ j;
      if (run[k] < run[k + 1]) stack[sp++] = run[k], stack[sp++] = run[k + 1];
    }
  }
  return 0;
}

/*
 * A segment at a level with a bitmap (collide/world_query.c, "where a level's cells are"):
 * in pieces two bitmap squares long, in order along it, the squares of the bitmap whose bits
 * are set and that the pieces' cell ranges reach, each descended as a run of the tree
 * (the square's keys: its Morton prefix, as the bitmap's squares and the tree's share
 * their origin (qx0, qy0) and sides of a power of two). The cell ranges of the pieces move
 * monotonically along the segment, and so do their squares: skipping the squares of the
 * previous piece's range visits each once. Every object the segment meets lies in a cell
 * of some piece's range (visit_along), so in one of those squares; a long ray across a
 * sparse level reads a few bits a piece instead of descending from the level's top.
 */
static int tree_visit_along(const qk_world_t *w, const tquery_t *t) {
  const int li = t->l - QK__LMIN, sh = w->qb_s[li];
  const uint64_t bw = w->qb_w[li], bh = w->qb_h[li];
  const int64_t x0 = w->qx0[li], y0 = w->qy0[li];
  const uint64_t *bits = w->qbits + w->qb_off[li], *key = w->qkey + w->lv_first[li];
  const uint32_t m = w->lv_n[li];
  const double major = qk__max(fabs(t->seg[1].x - t->seg[0].x), fabs(t->seg[1].y - t->seg[0].y));
  const double n = ceil(major / qk__pow2(t->l + sh + 1));
  if (!(n <= 0x1p16)) return tree_visit_run(w, t, 0, m);
  pieces_t p = pieces_of(t->seg, n < 1 ? 1 : (size_t)n);
  uint64_t pb[4] = {1, 0, 1, 0}; /* the last piece's squares (bx0, bx1, by0, by1): none */
  for (size_t k = 1; k <= p.n; k++) {
    /* a first hit before the pieces so far by a margin: no object left comes first (see
     * visit_first) */
    const rctx_t *c = t->first;
    if (c && c->best.h != QK_HANDLE_NONE && c->best.t < (double)(k - 1) / (double)p.n - 0x1p-30)
      break;
    const crange_t r = range_of(next_piece(&p, k), t->l);
    uint64_t b[4]; /* (its squares, clipped to the bitmap) */
    if (!bit_span(r.x0, r.x1, x0, sh, bw, &b[0], &b[1]) ||
        !bit_span(r.y0, r.y1, y0, sh, bh, &b[2], &b[3])) {
      pb[0] = 1, pb[1] = 0; /* (none) */
      continue;
    }
    for (uint64_t by = b[2]; by <= b[3]; by++)
      for (uint64_t bx = b[0]; bx <= b[1]; bx++) {
        if (bx >= pb[0] && bx <= pb[1] && by >= pb[2] && by <= pb[3]) continue;
        const uint64_t bit = by * bw + bx;
        if (!(bits[bit / 64] >> (bit % 64) & 1)) continue;
        /* (its keys [k0, k1): cell indices are below 2^30 in magnitude (qk__world_cell_of),
         * so a level spans under 2^31 of them, its keys are below 2^62 and k1 does not
         * wrap) */
        const uint64_t k0 = (spread((uint32_t)bx) | spread((uint32_t)by) << 1) << 2 * sh;
        const uint64_t k1 = k0 + (UINT64_C(1) << 2 * sh);
        const uint32_t lo = key_lower(key, 0, m, k0), hi = key_lower(key, lo, m, k1);
        if (lo < hi && tree_visit_run(w, t, lo, hi)) return 1;
      }
    memcpy(pb, b, sizeof pb);
  }
  return 0;
}

/* The cells of the query's level that tree_meets: by the bitmap for a segment where the
 * level has one, else from the top of the level's tree. */
static int tree_visit(const qk_world_t *w, const tquery_t *t) {
  const int li = t->l - QK__LMIN;
  if (t->seg && w->qb_w[li]) return tree_visit_along(w, t);
  return tree_visit_run(w, t, 0, w->lv_n[li]);
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

/* Level by level, the cells whose objects may meet qb (and the segment, when given):
 * by a binary search a row when the rows are few, else by the query tree when it is
 * there, else along the segment in pieces or by a scan of the level's cells, whichever
 * reads fewer. With `first` (a first hit in a world of boxes and points), the tree skips
 * squares that the best hit so far rules out. Returns 1 when fn stopped the visit. */
static int visit_levels(const qk_world_t *w, qk_box_t qb, const qk_point_t *seg,
                        const rctx_t *first, qk__wvisit_fn fn, void *ud) {
  const int made = qtree_ready(w), tree = made && w->n_cells >= QK__TREE_MIN;
  int levels[QK__NLEV];
  int n = qk__world_levels(w, levels);
  for (int li = 0; li < n; li++) {
    int l = levels[li];
    crange_t r = range_of(qb, l);
    double ncell = w->lv_n[l - QK__LMIN], lg = lg_cells(w->lv_n[l - QK__LMIN]);
    double rows = (double)r.y1 - (double)r.y0 + 1;
    if (rows * lg <= 2 * ncell + 8 && (!tree || rows <= 4)) { /* a binary search a row */
      if (visit_range(w, l, r, NULL, qb, seg, fn, ud, made)) return 1;
      continue;
    }
    if (made && !level_has(w, l - QK__LMIN, &r)) continue; /* (none there) */
    if (tree) {
      const tquery_t t = {l, r, seg, first, qb, fn, ud};
      if (tree_visit(w, &t)) return 1;
      continue;
    }
    if (seg) {
      /* pieces about four cells long on the longer axis; each searches its rows */
      double major = qk__max(qb.xmax - qb.xmin, qb.ymax - qb.ymin);
      double pieces = ceil(major / (4 * qk__pow2(l)));
      double prow = piece_rows(&qb, seg, pieces, l);
      if (pieces >= 1 && pieces < 1e7 && pieces * prow * lg <= 2 * ncell + 8) {
        if (visit_along(w, l, seg, pieces, qb, fn, ud, made)) return 1;
        continue;
      }
    }
    if (scan_level(w, l, r, qb, seg, fn, ud)) return 1;
  }
  return 0;
}

void qk__world_visit_seg(const qk_world_t *w, qk_box_t qb, const qk_point_t *seg, qk__wvisit_fn fn,
                         void *ud) {
  if (w->n_live == 0 || visit_levels(w, qb, seg, NULL, fn, ud)) return;
  visit_dirty(w, qb, fn, ud);
}

void qk__world_visit(const qk_world_t *w, qk_box_t qb, qk__wvisit_fn fn, void *ud) {
  qk__world_visit_seg(w, qb, NULL, fn, ud);
}

/* ---- overlap with a shape --------------------------------------------------------- */

/*
 * The first cap of a list in an order, kept while it is found: the first cap entries go
 * into the buffer, which becomes a max-heap when full; a later entry that comes before
 * the heap's top replaces it. (Writing the first cap found gave a short buffer the first
 * cap visited, not the first cap of the order the header promises.) The caller sorts the
 * min(n, cap) entries at the end.
 */
#define QK__KEEP_FIRST(name, type, less)                                                           \
  static void name##_sift(type *a, size_t n, size_t i) {                                           \
    for (;;) {                                                                                     \
      size_t l = 2 * i + 1, m = i;                                                                 \
      if (l < n && less(a[m], a[l])) m = l;                                                        \
      if (l + 1 < n && less(a[m], a[l + 1])) m = l + 1;                                            \
      if (m == i) return;                                                                          \
      const type t = a[i];                                                                         \
      a[i] = a[m], a[m] = t, i = m;                                                                \
    }                                                                                              \
  }                                                                                                \
  /* put v as the n-th entry found (n counts those before it) */                                   \
  static void name(type *a, size_t cap, size_t n, type v) {                                        \
    if (n < cap) {                                                                                 \
      a[n] = v;                                                                                    \
      if (n + 1 == cap)                                                                            \
        for (size_t i = cap / 2; i-- > 0;) name##_sift(a, cap, i);                                 \
    } else if (cap && less(v, a[0])) {                                                             \
      a[0] = v;                                                                                    \
      name##_sift(a, cap, 0);                                                                      \
    }                                                                                              \
  }

#define SLOT_LESS(x, y) ((uint32_t)(x) < (uint32_t)(y))
#define HIT_LESS(x, y) hit_less((x).t, (uint32_t)(x).h, (y).t, (uint32_t)(y).h)
QK__KEEP_FIRST(keep_handle, qk_handle_t, SLOT_LESS)
QK__KEEP_FIRST(keep_hit, qk_world_hit_t, HIT_LESS)

typedef struct qctx {
  const qk_shape_t *q;
  int q_box_like; /* the query is a box or a point */
  qk_handle_t *out;
  size_t cap, n;
} qctx_t;

static int q_visit(const qk_world_t *w, uint32_t i, const qk_box_t *b, void *ud) {
  (void)b;
  qctx_t *c = ud;
  /* A box or a point is its box, exactly (qk__shape_box): between two of them the box
   * test that brought the object here decided the overlap. */
  if (!c->q_box_like || !box_like(&w->obj[i])) {
    qk_shape_t sh = qk__wshape(&w->obj[i]);
    if (!qk__shapes_overlap(c->q, &sh)) return 0;
  }
  keep_handle(c->out, c->cap, c->n++, qk__handle(w, i));
  return 0;
}

/* Sorts handles by slot (the low half; no two the same): quicksort on the median of
 * three, the smaller part first, by insertion below 16 (qsort's calls of its comparison
 * were a tenth of a box query in the clustered world). */
static void sort_by_slot(qk_handle_t *a, size_t n) {
  while (n > 16) {
    const uint32_t x = (uint32_t)a[0], y = (uint32_t)a[n / 2], z = (uint32_t)a[n - 1];
    const uint32_t p = x < y ? (y < z ? y : x < z ? z : x) : (x < z ? x : y < z ? z : y);
    /* Hoare's partition: p is neither the least nor the greatest slot, so both parts
     * [0, j] and (j, n) are non-empty */
    size_t i = 0, j = n - 1;
    for (;;) {
      while ((uint32_t)a[i] < p) i++;
      while ((uint32_t)a[j] > p) j--;
      if (i >= j) break;
      const qk_handle_t t = a[i];
      a[i++] = a[j], a[j--] = t;
    }
    if (j + 1 < n - j - 1) {
      sort_by_slot(a, j + 1);
      a += j + 1, n -= j + 1;
    } else {
      sort_by_slot(a + j + 1, n - j - 1);
      n = j + 1;
    }
  }
  for (size_t i = 1; i < n; i++) {
    const qk_handle_t h = a[i];
    size_t j = i;
    for (; j > 0 && (uint32_t)a[j - 1] > (uint32_t)h; j--) a[j] = a[j - 1];
    a[j] = h;
  }
}

qk_status_t qk_world_query(const qk_world_t *w, const qk_shape_t *shape, qk_handle_t *out,
                           size_t cap, size_t *n_out) {
  if (!w || !shape || !n_out || (cap && !out)) return QK_ERR_INVALID;
  *n_out = 0;
  qk_shape_t q;
  qk_status_t st = qk__shape_normalize(shape, &q);
  if (st != QK_OK) return st;
  qctx_t c = {&q, q.kind == QK_SHAPE_BOX || q.kind == QK_SHAPE_POINT, out, cap, 0};
  qk_point_t seg[2] = {{q.x, q.y}, {q.a, q.b}};
  qk__world_visit_seg(w, qk__shape_box(&q), q.kind == QK_SHAPE_SEGMENT ? seg : NULL, q_visit, &c);
  sort_by_slot(out, c.n < cap ? c.n : cap);
  *n_out = c.n;
  return QK_OK;
}

/* ---- rays ------------------------------------------------------------------------- */

static int r_visit_all(const qk_world_t *w, uint32_t i, const qk_box_t *b, void *ud) {
  (void)b;
  rctx_t *c = ud;
  qk_shape_t sh = qk__wshape(&w->obj[i]);
  if (!qk__shapes_overlap(&c->seg, &sh)) return 0;
  keep_hit(c->out, c->cap, c->n++,
           (qk_world_hit_t){qk__handle(w, i), qk__ray_param(&sh, c->from, c->to)});
  return 0;
}

static int r_visit_first(const qk_world_t *w, uint32_t i, const qk_box_t *b, void *ud) {
  rctx_t *c = ud;
  /* No exact test for a box or point that the segment surely misses (its slabs' entry
   * beyond their exit), or reaches only after the best hit so far: its parameter would be
   * larger, so it cannot be the first. */
  if (box_like(&w->obj[i])) {
    double exit;
    const double entry = slab_entry(c, b, &exit);
    if (entry > exit + 0x1p-40) return 0;
    if (c->best.h != QK_HANDLE_NONE && entry > c->best.t + 0x1p-40) return 0;
  }
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
  if ((c.n < cap ? c.n : cap) > 1) qsort(out, c.n < cap ? c.n : cap, sizeof *out, hit_cmp);
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
static int visit_first(const qk_world_t *w, qk_box_t qb, const qk_point_t *seg, rctx_t *c,
                       int tree) {
  int levels[QK__NLEV], along[QK__NLEV];
  crange_t prev[QK__NLEV];
  const int nl = qk__world_levels(w, levels);
  if (nl == 0) return 0;
  /* pieces a cell long at the level of the most cells */
  int lm = levels[0];
  for (int li = 1; li < nl; li++)
    if (w->lv_n[levels[li] - QK__LMIN] > w->lv_n[lm - QK__LMIN]) lm = levels[li];
  const double pieces =
      ceil(qk__max(fabs(seg[1].x - seg[0].x), fabs(seg[1].y - seg[0].y)) / qk__pow2(lm));
  if (!(pieces <= 0x1p20)) return 0;
  const size_t n = pieces < 1 ? 1 : (size_t)pieces;
  /* with the tree, the walk hands over to it after this many pieces */
  const size_t stop = tree ? QK__FIRST_PIECES : n;
  visit_dirty(w, qb, r_visit_first, c);
  int walk = 0;
  for (int li = 0; li < nl; li++) {
    const int l = levels[li];
    const double ncell = w->lv_n[l - QK__LMIN], lg = lg_cells(w->lv_n[l - QK__LMIN]);
    const double prow = piece_rows(&qb, seg, (double)n, l);
    along[li] = (double)n * prow * lg <= 2 * ncell + 8;
    walk |= along[li];
    prev[li] = (crange_t){1, 0, 1, 0}; /* empty */
    if (!along[li] && !tree) scan_level(w, l, range_of(qb, l), qb, seg, r_visit_first, c);
  }
  pieces_t s = pieces_of(seg, n);
  for (size_t k = 1; walk && k <= n; k++) {
    /* (the tree then visits every level, those walked so far again: the same objects
     * give the same best hit) */
    if (k > stop) return 0;
    const qk_box_t pb = next_piece(&s, k);
    for (int li = 0; li < nl; li++) {
      if (!along[li]) continue;
      const crange_t r = range_of(pb, levels[li]);
      if (memcmp(&r, &prev[li], sizeof r))
        visit_range(w, levels[li], r, &prev[li], qb, seg, r_visit_first, c, tree);
      prev[li] = r;
    }
    if (c->best.h != QK_HANDLE_NONE && c->best.t < (double)k / (double)n - 0x1p-30) break;
  }
  /* the levels not walked, after the walk's hits: they prune the tree's squares */
  for (int li = 0; tree && li < nl; li++) {
    if (along[li]) continue;
    const tquery_t t = {levels[li], range_of(qb, levels[li]), seg, c, qb, r_visit_first, c};
    if (!level_has(w, levels[li] - QK__LMIN, &t.r)) continue; /* (none there) */
    tree_visit(w, &t);
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
  if (w->n_live && w->had_round) {
    qk__world_visit_seg(w, qb, seg, r_visit_first, &c); /* every candidate (visit_first) */
  } else if (w->n_live) {
    const int tree = tree_ready(w);
    if (!visit_first(w, qb, seg, &c, tree)) { /* (the walk handed over, or could not start) */
      if (tree) {
        /* the objects not filed first: their hits prune the tree's squares */
        visit_dirty(w, qb, r_visit_first, &c);
        visit_levels(w, qb, seg, &c, r_visit_first, &c);
      } else {
        qk__world_visit_seg(w, qb, seg, r_visit_first, &c);
      }
    }
  }
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

static void batch_run(unsigned k, unsigned share, void *ud) {
  (void)share;
  batch_t *b = ud;
  size_t lo = (size_t)k * b->chunk, hi = lo + b->chunk < b->n ? lo + b->chunk : b->n;
  for (size_t i = lo; i < hi; i++) {
    qk_status_t st = qk_world_raycast(b->w, b->from[i], b->to[i], &b->hits[i]);
    if (st != QK_OK && b->st[k % 64] == QK_OK) b->st[k % 64] = st; /* its first */
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
  qk__world_run_jobs_shared(w, w->opt.threads, (unsigned)jobs, batch_run, &b);
  for (int k = 0; k < 64; k++)
    if (b.st[k] != QK_OK) return b.st[k];
  return QK_OK;
}

/* ---- k nearest -------------------------------------------------------------------- */

/* At most this many nearest are kept sorted by insertion (cheaper for small k); beyond,
 * in a bounded max-heap (the worst at out[0]) sorted once at the end: the insertion sort's
 * shifts made k = n from the middle of a world quadratic (k = n = 200 000: 6.7 s). */
#ifndef QK__KSORT_MAX
#define QK__KSORT_MAX 32
#endif

typedef struct kctx {
  qk_point_t p;
  qk_world_hit_t *out; /* n of k filled: sorted ascending by (t, slot), or (k beyond
                          QK__KSORT_MAX) a max-heap by (t, slot) until k_finish */
  size_t k, n, seen;
} kctx_t;

static inline int khit_less(const qk_world_hit_t *a, const qk_world_hit_t *b) {
  return hit_less(a->t, (uint32_t)a->h, b->t, (uint32_t)b->h);
}

/* The worst of the k kept (n == k): the distance beyond which nothing enters. */
static inline const qk_world_hit_t *k_worst(const kctx_t *c) {
  return &c->out[c->k > QK__KSORT_MAX ? 0 : c->n - 1];
}

static void khp_sift_down(qk_world_hit_t *h, size_t n, size_t i) {
  const qk_world_hit_t v = h[i];
  for (;;) {
    size_t l = 2 * i + 1, m = i;
    const qk_world_hit_t *best = &v;
    if (l < n && khit_less(best, &h[l])) m = l, best = &h[l];
    if (l + 1 < n && khit_less(best, &h[l + 1])) m = l + 1;
    if (m == i) break;
    h[i] = h[m];
    i = m;
  }
  h[i] = v;
}

/* The hits in order (best first), the heap's in place. */
static void k_finish(kctx_t *c) {
  if (c->k <= QK__KSORT_MAX) return;
  for (size_t n = c->n; n > 1;) {
    const qk_world_hit_t top = c->out[0];
    c->out[0] = c->out[--n];
    khp_sift_down(c->out, n, 0);
    c->out[n] = top;
  }
}

static int k_visit(const qk_world_t *w, uint32_t i, const qk_box_t *b, void *ud) {
  kctx_t *c = ud;
  c->seen++;
  const int full = c->n == c->k;
  if (full && box_like(&w->obj[i])) {
    /* Farther than the k-th so far by its box: not among the k.
     * The squared box distance in doubles is within a few ulps of its real value, far
     * inside the 2^-40 left here, and its sign parts are exact. */
    double dx = qk__max(qk__max(b->xmin - c->p.x, c->p.x - b->xmax), 0);
    double dy = qk__max(qk__max(b->ymin - c->p.y, c->p.y - b->ymax), 0);
    double kt = k_worst(c)->t;
    if (dx * dx + dy * dy > kt * kt * (1 + 0x1p-40)) return 0;
  }
  qk_shape_t sh = qk__wshape(&w->obj[i]);
  const qk_world_hit_t v = {qk__handle(w, i), qk__shape_dist(&sh, c->p)};
  if (full && !khit_less(&v, k_worst(c))) return 0;
  if (c->k > QK__KSORT_MAX) {
    if (full) {
      c->out[0] = v;
      khp_sift_down(c->out, c->n, 0);
      return 0;
    }
    size_t j = c->n++;
    while (j > 0 && khit_less(&c->out[(j - 1) / 2], &v)) {
      c->out[j] = c->out[(j - 1) / 2];
      j = (j - 1) / 2;
    }
    c->out[j] = v;
    return 0;
  }
  size_t j = full ? c->n - 1 : c->n++;
  while (j > 0 && khit_less(&v, &c->out[j - 1])) {
    c->out[j] = c->out[j - 1];
    j--;
  }
  c->out[j] = v;
  return 0;
}

/*
 * The k nearest by the query tree, best first: runs of cells waiting in a heap by the
 * squared distance from p to their squares (lb, computed in doubles within a few ulps),
 * all levels at once. Each popped run is split into its quarters, or its cells' objects
 * are visited (k_visit), until the nearest waiting square is farther than the k-th so far
 * by the same relative margin the growing square of qk_world_knn leaves (2^-20): every
 * object not visited lies in a waiting square, so its distance, computed as closely, is
 * beyond the k-th, neither nearer nor tied. Returns 0, having found nothing, when the
 * heap would overflow (many squares tie: the caller grows its square instead).
 */
#ifndef QK__KHEAP /* (scripts/fuzz.sh builds with 6, so that the fuzzer overflows it) */
#define QK__KHEAP 512
#endif
typedef struct kitem {
  double lb;
  uint32_t lo, hi;
  int l;
} kitem_t;

static int kheap_push(kitem_t *h, int *n, kitem_t it) {
  if (*n == QK__KHEAP) return 0;
  int i = (*n)++;
  while (i > 0 && h[(i - 1) / 2].lb > it.lb) {
    h[i] = h[(i - 1) / 2];
    i = (i - 1) / 2;
  }
  h[i] = it;
  return 1;
}

static kitem_t kheap_pop(kitem_t *h, int *n) {
  const kitem_t top = h[0], last = h[--*n];
  int i = 0;
  for (;;) {
    int j = 2 * i + 1;
    if (j >= *n) break;
    if (j + 1 < *n && h[j + 1].lb < h[j].lb) j++;
    if (!(h[j].lb < last.lb)) break;
    h[i] = h[j];
    i = j;
  }
  if (*n) h[i] = last;
  return top;
}

static double box_lb2(qk_point_t p, const qk_box_t *b) {
  const double dx = qk__max(qk__max(b->xmin - p.x, p.x - b->xmax), 0);
  const double dy = qk__max(qk__max(b->ymin - p.y, p.y - b->ymax), 0);
  return dx * dx + dy * dy;
}

/* Whether every object at squared distance lb or more lies beyond the k-th so far by the
 * margin knn_tree's comment gives. */
static inline int knn_beyond(const kctx_t *c, double lb) {
  if (c->n < c->k) return 0;
  const double kt = k_worst(c)->t;
  return lb * (1 - 0x1p-18) > kt * kt;
}

/* The box beyond which objects are farther than the k-th so far by the tree's margin (see
 * knn_tree; its sides also above the rounding of p's coordinates), or the whole plane
 * while fewer than k are found: a crowded cell's groups outside it are not read. */
static qk_box_t knn_box(const kctx_t *c) {
  if (c->n < c->k) return (qk_box_t){-INFINITY, -INFINITY, INFINITY, INFINITY};
  const double h = k_worst(c)->t * (1 + 0x1p-17) + (fabs(c->p.x) + fabs(c->p.y)) * 0x1p-50;
  return (qk_box_t){c->p.x - h, c->p.y - h, c->p.x + h, c->p.y + h};
}

static int knn_tree(const qk_world_t *w, kctx_t *c) {
  kitem_t heap[QK__KHEAP];
  int nh = 0;
  const qk_box_t all = {-INFINITY, -INFINITY, INFINITY, INFINITY};
  for (int i = 0; i < w->n_lv_occ; i++)
    if (!kheap_push(heap, &nh, (kitem_t){0, 0, w->lv_n[w->lv_occ[i] - QK__LMIN], w->lv_occ[i]}))
      return 0;
  visit_dirty(w, all, k_visit, c);
  while (nh) {
    const kitem_t it = kheap_pop(heap, &nh);
    if (knn_beyond(c, it.lb)) break;
    const int li = it.l - QK__LMIN;
    const uint32_t base = w->lv_first[li];
    const uint64_t *key = w->qkey + base;
    if (it.hi - it.lo <= QK__TREE_LEAF) {
      for (uint32_t j = it.lo; j < it.hi; j++) {
        const uint32_t cell = w->qcell[base + j];
        const qk__wcell_t *cl = &w->cells[cell];
        const qk_box_t b = loose_box(cl->cx, cl->cy, 1, it.l);
        if (!knn_beyond(c, box_lb2(c->p, &b))) visit_cell(w, cell, knn_box(c), NULL, k_visit, c);
      }
      continue;
    }
    const tsquare_t sq = tree_square(w, li, key, it.lo, it.hi);
    const int64_t half = sq.side / 2;
    uint32_t run[5];
    tree_quarters(w, li, key, &sq, it.lo, it.hi, run);
    for (int j = 0; j < 4; j++) {
      if (run[j] == run[j + 1]) continue;
      const qk_box_t b = loose_box(sq.x + (j & 1) * half, sq.y + (j >> 1) * half, half, it.l);
      const double lb = box_lb2(c->p, &b);
      if (knn_beyond(c, lb)) continue; /* (it would stop the search when popped) */
      if (!kheap_push(heap, &nh, (kitem_t){lb, run[j], run[j + 1], it.l})) return 0;
    }
  }
  return 1;
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
  for (int grown = 0, tree_next = 0;; grown++) {
    kctx_t c = {p, out, k, 0, 0};
    /* Where the squares fell short (sparse or clustered worlds: the first held fewer than
     * k objects, or the second still missed), the tree goes straight to the nearest
     * squares instead of growing the square again. */
    if (tree_next > 0) {
      tree_next = -1; /* (once: a heap that overflowed would overflow again) */
      if (tree_ready(w) && knn_tree(w, &c)) {
        k_finish(&c);
        *n_out = c.n;
        return QK_OK;
      }
    }
    c = (kctx_t){p, out, k, 0, 0};
    qk_box_t qb = {p.x - r, p.y - r, p.x + r, p.y + r};
    qk__world_visit(w, qb, k_visit, &c);
    if (c.seen == w->n_live || (c.n == k && k_worst(&c)->t <= r * (1 - 0x1p-20))) {
      k_finish(&c);
      *n_out = c.n;
      return QK_OK;
    }
    if (tree_next == 0) tree_next = c.n < k || grown >= 1;
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

static void kbatch_run(unsigned j, unsigned share, void *ud) {
  (void)share;
  kbatch_t *b = ud;
  size_t lo = (size_t)j * b->chunk, hi = lo + b->chunk < b->n ? lo + b->chunk : b->n;
  for (size_t i = lo; i < hi; i++) {
    size_t c = 0;
    qk_world_hit_t *o = b->out + i * b->k;
    qk_status_t st = qk_world_knn(b->w, b->ps[i], b->k, o, &c);
    if (st != QK_OK) c = 0, b->st[j % 64] = b->st[j % 64] ? b->st[j % 64] : st;
    /* the block's unused slots, as qk_query_knn_batch fills them */
    for (size_t s = c; s < b->k; s++) o[s] = (qk_world_hit_t){QK_HANDLE_NONE, INFINITY};
    if (b->counts) b->counts[i] = c;
  }
}

qk_status_t qk_world_knn_batch(const qk_world_t *w, const qk_point_t *ps, size_t n, size_t k,
                               qk_world_hit_t *out, size_t *counts) {
  if (!w || (n && (!ps || (k && !out)))) return QK_ERR_INVALID;
  kbatch_t b = {w, ps, n, k, 256, out, counts, {QK_OK}};
  size_t jobs = batch_jobs(n, &b.chunk);
  qk__world_run_jobs_shared(w, w->opt.threads, (unsigned)jobs, kbatch_run, &b);
  for (int j = 0; j < 64; j++)
    if (b.st[j] != QK_OK) return b.st[j];
  return QK_OK;
}
