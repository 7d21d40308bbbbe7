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
  double s = floor(v * qk__pow2(-l));
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

/* The bits of v at the even bit positions of the result, and back. */
static uint64_t spread(uint32_t v) {
  uint64_t x = v;
  x = (x | x << 16) & UINT64_C(0x0000ffff0000ffff);
  x = (x | x << 8) & UINT64_C(0x00ff00ff00ff00ff);
  x = (x | x << 4) & UINT64_C(0x0f0f0f0f0f0f0f0f);
  x = (x | x << 2) & UINT64_C(0x3333333333333333);
  return (x | x << 1) & UINT64_C(0x5555555555555555);
}

static uint32_t squeeze(uint64_t x) {
  x &= UINT64_C(0x5555555555555555);
  x = (x | x >> 1) & UINT64_C(0x3333333333333333);
  x = (x | x >> 2) & UINT64_C(0x0f0f0f0f0f0f0f0f);
  x = (x | x >> 4) & UINT64_C(0x00ff00ff00ff00ff);
  x = (x | x >> 8) & UINT64_C(0x0000ffff0000ffff);
  return (uint32_t)(x | x >> 16);
}

void qk__world_qtree_free(qk_world_t *w) {
  qk__free(&w->alloc, w->qkey, (size_t)w->cap_q * sizeof *w->qkey);
  qk__free(&w->alloc, w->qcell, (size_t)w->cap_q * sizeof *w->qcell);
  w->qkey = NULL, w->qcell = NULL, w->cap_q = 0;
  atomic_store_explicit(&w->qbytes, 0, memory_order_relaxed);
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
    atomic_store_explicit(&w->qbytes, (size_t)nc * (sizeof *w->qkey + sizeof *w->qcell),
                          memory_order_relaxed);
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
  }
  qk__free(a, tk, tk ? (size_t)nc * sizeof *tk : 0);
  qk__free(a, tc, tc ? (size_t)nc * sizeof *tc : 0);
  return ok;
}

/* Whether the query tree of the last update's order is there to read, making it if no
 * other query is (a query of a world shared by many readers: the tree and qstate are
 * the only state it writes, under qstate's protocol). */
static int qtree_ready(const qk_world_t *cw) {
  qk_world_t *w = (qk_world_t *)cw;
  const int s = atomic_load_explicit(&w->qstate, memory_order_acquire);
  if (s == 2) return 1;
  if (s != 0 || w->n_cells < QK__TREE_MIN) return 0;
  int expect = 0;
  if (!atomic_compare_exchange_strong_explicit(&w->qstate, &expect, 1, memory_order_acquire,
                                               memory_order_relaxed))
    return 0;
  const int ok = qtree_make(w);
  atomic_store_explicit(&w->qstate, ok ? 2 : 0, memory_order_release);
  return ok;
}

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
static int seg_may_meet(const qk_point_t *seg, const qk_box_t *b) {
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
  return (tsquare_t){(int64_t)w->qx0[li] + squeeze(org), (int64_t)w->qy0[li] + squeeze(org >> 1),
                     INT64_C(1) << s, org};
}

static inline void tree_quarters(const uint64_t *key, const tsquare_t *sq, uint32_t lo, uint32_t hi,
                                 uint32_t run[5]) {
  const uint64_t q = (uint64_t)(sq->side / 2) * (uint64_t)(sq->side / 2); /* a quarter's keys */
  run[0] = lo, run[4] = hi;
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
static int tree_visit(const qk_world_t *w, const tquery_t *t) {
  const int li = t->l - QK__LMIN;
  const uint32_t base = w->lv_first[li];
  const uint64_t *key = w->qkey + base;
  const uint32_t *cell = w->qcell + base;
  const int near = !t->seg ? 0 : (t->seg[1].x < t->seg[0].x) | (t->seg[1].y < t->seg[0].y) << 1;
  uint32_t stack[2 * 136]; /* runs waiting: at most 3 a square of the descent, 32 deep */
  int sp = 0;
  stack[sp++] = 0, stack[sp++] = w->lv_n[li];
  while (sp) {
    const uint32_t hi = stack[--sp], lo = stack[--sp];
    if (hi - lo <= QK__TREE_LEAF) {
      for (uint32_t k = lo; k < hi; k++) {
        const qk__wcell_t *c = &w->cells[cell[k]];
        if (tree_meets(t, c->cx, c->cy, 1) && visit_cell(w, cell[k], t->qb, t->fn, t->ud)) return 1;
      }
      continue;
    }
    const tsquare_t sq = tree_square(w, li, key, lo, hi);
    if (!tree_meets(t, sq.x, sq.y, sq.side)) continue;
    uint32_t run[5];
    tree_quarters(key, &sq, lo, hi, run);
    /* pushed so that the quarter `near` comes off first */
    for (int j = 3; j >= 0; j--) {
      const int k = near ^ j;
      if (run[k] < run[k + 1]) stack[sp++] = run[k], stack[sp++] = run[k + 1];
    }
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

/* Level by level, the cells whose objects may meet qb (and the segment, when given):
 * by a binary search a row when the rows are few, else by the query tree when it is
 * there, else along the segment in pieces or by a scan of the level's cells, whichever
 * reads fewer. With `first` (a first hit in a world of boxes and points), the tree skips
 * squares that the best hit so far rules out. Returns 1 when fn stopped the visit. */
static int visit_levels(const qk_world_t *w, qk_box_t qb, const qk_point_t *seg,
                        const rctx_t *first, qk__wvisit_fn fn, void *ud) {
  const int tree = qtree_ready(w);
  int levels[QK__NLEV];
  int n = qk__world_levels(w, levels);
  for (int li = 0; li < n; li++) {
    int l = levels[li];
    crange_t r = range_of(qb, l);
    double ncell = w->lv_n[l - QK__LMIN], lg = lg_cells(w->lv_n[l - QK__LMIN]);
    double rows = (double)r.y1 - (double)r.y0 + 1;
    if (rows * lg <= 2 * ncell + 8 && (!tree || rows <= 4)) { /* a binary search a row */
      if (visit_range(w, l, r, NULL, qb, fn, ud)) return 1;
      continue;
    }
    if (tree) {
      const tquery_t t = {l, r, seg, first, qb, fn, ud};
      if (tree_visit(w, &t)) return 1;
      continue;
    }
    if (seg) {
      /* pieces about four cells long on the longer axis; each searches its rows */
      double s = qk__pow2(l);
      double major = fmax(qb.xmax - qb.xmin, qb.ymax - qb.ymin);
      double pieces = ceil(major / (4 * s));
      double prow = (qb.ymax - qb.ymin) / pieces / s + 3;
      if (pieces >= 1 && pieces < 1e7 && pieces * prow * lg <= 2 * ncell + 8) {
        if (visit_along(w, l, seg, pieces, qb, fn, ud)) return 1;
        continue;
      }
    }
    if (scan_level(w, l, r, qb, fn, ud)) return 1;
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
  if (c.n <= cap && c.n > 32) {
    qsort(out, c.n, sizeof *out, handle_cmp);
  } else if (c.n <= cap) { /* a few: by insertion (qsort's calls were 6% of a box query) */
    for (size_t i = 1; i < c.n; i++) {
      const qk_handle_t h = out[i];
      size_t j = i;
      for (; j > 0 && (uint32_t)out[j - 1] > (uint32_t)h; j--) out[j] = out[j - 1];
      out[j] = h;
    }
  }
  *n_out = c.n;
  return QK_OK;
}

/* ---- rays ------------------------------------------------------------------------- */

static int r_visit_all(const qk_world_t *w, uint32_t i, const qk_box_t *b, void *ud) {
  (void)b;
  rctx_t *c = ud;
  qk_shape_t sh = qk__wshape(&w->obj[i]);
  if (!qk__shapes_overlap(&c->seg, &sh)) return 0;
  QK__SINK_PUT(c->out, c->cap, c->n,
               ((qk_world_hit_t){qk__handle(w, i), qk__ray_param(&sh, c->from, c->to)}));
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
      ceil(fmax(fabs(seg[1].x - seg[0].x), fabs(seg[1].y - seg[0].y)) / qk__pow2(lm));
  if (!(pieces <= 0x1p20)) return 0;
  const size_t n = pieces < 1 ? 1 : (size_t)pieces;
  /* with the tree, the walk hands over to it after this many pieces */
  const size_t stop = tree ? QK__FIRST_PIECES : n;
  visit_dirty(w, qb, r_visit_first, c);
  int walk = 0;
  for (int li = 0; li < nl; li++) {
    const int l = levels[li];
    const double ncell = w->lv_n[l - QK__LMIN], lg = lg_cells(w->lv_n[l - QK__LMIN]);
    const double prow = (qb.ymax - qb.ymin) / (double)n / qk__pow2(l) + 3;
    along[li] = (double)n * prow * lg <= 2 * ncell + 8;
    walk |= along[li];
    prev[li] = (crange_t){1, 0, 1, 0}; /* empty */
    if (!along[li] && !tree) scan_level(w, l, range_of(qb, l), qb, r_visit_first, c);
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
        visit_range(w, levels[li], r, &prev[li], qb, r_visit_first, c);
      prev[li] = r;
    }
    if (c->best.h != QK_HANDLE_NONE && c->best.t < (double)k / (double)n - 0x1p-30) break;
  }
  /* the levels not walked, after the walk's hits: they prune the tree's squares */
  for (int li = 0; tree && li < nl; li++) {
    if (along[li]) continue;
    const tquery_t t = {levels[li], range_of(qb, levels[li]), seg, c, qb, r_visit_first, c};
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
    const int tree = qtree_ready(w);
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
  qk__world_run_jobs_shared(w, w->opt.threads, (unsigned)jobs, batch_run, &b);
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
  const double kt = c->out[c->k - 1].t;
  return lb * (1 - 0x1p-18) > kt * kt;
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
        if (!knn_beyond(c, box_lb2(c->p, &b))) visit_cell(w, cell, all, k_visit, c);
      }
      continue;
    }
    const tsquare_t sq = tree_square(w, li, key, it.lo, it.hi);
    const int64_t half = sq.side / 2;
    uint32_t run[5];
    tree_quarters(key, &sq, it.lo, it.hi, run);
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
      if (qtree_ready(w) && knn_tree(w, &c)) {
        *n_out = c.n;
        return QK_OK;
      }
    }
    c = (kctx_t){p, out, k, 0, 0};
    qk_box_t qb = {p.x - r, p.y - r, p.x + r, p.y + r};
    qk__world_visit(w, qb, k_visit, &c);
    if (c.seen == w->n_live || (c.n == k && c.out[k - 1].t <= r * (1 - 0x1p-20))) {
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
    qk_status_t st = qk_world_knn(b->w, b->ps[i], b->k, b->out + i * b->k, &b->counts[i]);
    if (st != QK_OK) b->st[j % 64] = st;
  }
}

qk_status_t qk_world_knn_batch(const qk_world_t *w, const qk_point_t *ps, size_t n, size_t k,
                               qk_world_hit_t *out, size_t *counts) {
  if (!w || (n && (!ps || !counts || (k && !out)))) return QK_ERR_INVALID;
  kbatch_t b = {w, ps, n, k, 256, out, counts, {QK_OK}};
  size_t jobs = batch_jobs(n, &b.chunk);
  qk__world_run_jobs_shared(w, w->opt.threads, (unsigned)jobs, kbatch_run, &b);
  for (int j = 0; j < 64; j++)
    if (b.st[j] != QK_OK) return b.st[j];
  return QK_OK;
}
