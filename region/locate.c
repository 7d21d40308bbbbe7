/*
 * Queries: descend to the leaf, then decide each candidate feature by the parity of the
 * crossings of the segment leaf reference -> point (see region.c). Batch calls split the
 * points over threads; each answer is computed by the same code, so results do not depend
 * on the thread count.
 */
#include <string.h>

#include "region/region_internal.h"

/* Map a query to the plane of the index; false when it is in no feature. */
static inline bool normalise(const qk_region_t *r, double *x, double *y) {
  if (!r->planar) {
    if (!(*y >= -90 && *y <= 90)) return false;
    if (*x < -180 || *x >= 180) {
      double t = fmod(*x + 180.0, 360.0);
      if (t < 0) t += 360.0;
      *x = t - 180.0;
      if (*x >= 180) *x -= 360;
    }
  }
  if (!(*x >= r->rx && *x < r->rx + r->rside && *y >= r->ry && *y < r->ry + r->rside)) return false;
  /* Coordinates too small for the exact predicates are zero (the layer has none). */
  if (fabs(*x) < QK_REGION_MIN_COORD) *x = 0.0;
  if (fabs(*y) < QK_REGION_MIN_COORD) *y = 0.0;
  return true;
}

/* The kid[] value of the leaf holding (x, y); *cx, *cy: the leaf's reference point. */
static inline uint32_t descend(const qk_region_t *r, double x, double y, double *cx, double *cy) {
  const uint32_t *kid = r->kid;
  uint32_t k = kid[0];
  double sx = r->rx, sy = r->ry, h = r->rside;
  if (r->grid_level) {
    /* Guess the grid cell, then correct it exactly against the cells' sides. */
    unsigned G = r->grid_level;
    long last = (1L << G) - 1;
    long i = (long)((x - r->rx) * r->grid_scale), j = (long)((y - r->ry) * r->grid_scale);
    i = i < 0 ? 0 : i > last ? last : i;
    j = j < 0 ? 0 : j > last ? last : j;
    while (i > 0 && x < r->gx[i]) i--;
    while (x >= r->gx[i + 1]) i++;
    while (j > 0 && y < r->gy[j]) j--;
    while (y >= r->gy[j + 1]) j++;
    uint32_t g = r->grid[(size_t)j << G | (size_t)i];
    if (g != QK__REDO) {
      k = g;
      sx = r->gx[i];
      sy = r->gy[j];
      h = r->grid_side;
    }
  }
  while (!(k & QK__LEAF)) {
    h *= 0.5;
    double mx = sx + h, my = sy + h;
    unsigned east = x >= mx, north = y >= my;
    /* NE 0, NW 1, SW 2, SE 3 */
    unsigned q = north ? (east ? 0u : 1u) : (east ? 3u : 2u);
    sx = east ? mx : sx;
    sy = north ? my : sy;
    k = kid[k + q];
  }
  *cx = sx + h * 0.5;
  *cy = sy + h * 0.5;
  return k;
}

/* The answer of a direct leaf. */
static inline uint32_t direct(uint32_t k) { return (k & 0x3fffffffu) - 1u; }

/* Decide the features of one leaf in increasing order; call `take` for each feature that
 * holds the point, stop when it returns true. Returns the last feature taken or QK_NONE. */
typedef struct taker {
  uint32_t *out;
  size_t cap, n;
  bool all;
} taker_t;

static inline bool take(taker_t *t, uint32_t f) {
  if (t->n < t->cap) t->out[t->n] = f;
  t->n++;
  return !t->all;
}

static void leaf_features(const qk_region_t *r, const qk__leaf_t *L, double cx, double cy, double x,
                          double y, qk_boundary_t b, taker_t *t) {
  /* (the arrays may be NULL when the whole layer has no sets or no edges) */
  uint32_t ns = L->ns, si = 0, ne = L->ne, i = 0;
  const uint32_t *S = ns ? r->sets + L->s0 : NULL;
  const uint32_t *E = ne ? r->le + L->e0 : NULL; /* indices into r->segs */
  const uint32_t *tag = ne ? r->le_tag + L->e0 : NULL;
  bool same = (x == cx && y == cy);
  while (i < ne) {
    uint32_t f = tag[i] >> 2;
    while (si < ns && S[si] < f)
      if (take(t, S[si++])) return;
    bool par = si < ns && S[si] == f;
    if (par) si++;
    bool on = false;
    for (; i < ne && (tag[i] >> 2) == f; i++) {
      const qk__seg_t *g = &r->segs[E[i]];
      if (b != QK_BOUNDARY_SEMI_OPEN && !(tag[i] & 2) &&
          qk__on_edge(g->ax, g->ay, g->bx, g->by, x, y))
        on = true;
      if (same) continue;
      int sc = (tag[i] & 1) ? 1 : -1;
      if (qk__crosses(cx, cy, x, y, g->ax, g->ay, g->bx, g->by, sc)) par = !par;
    }
    bool in = b == QK_BOUNDARY_SEMI_OPEN ? par
              : b == QK_BOUNDARY_CLOSED  ? (par || on)
                                         : (par && !on);
    if (in && take(t, f)) return;
  }
  while (si < ns)
    if (take(t, S[si++])) return;
}

uint32_t qk__region_locate1(const qk_region_t *r, double x, double y, qk_boundary_t b) {
  if (!normalise(r, &x, &y)) return QK_NONE;
  double cx, cy;
  uint32_t k = descend(r, x, y, &cx, &cy);
  if (k & QK__DIRECT) return direct(k);
  const qk__leaf_t *L = &r->leaves[k & ~QK__LEAF];
  if (L->ne == 0) return L->ns ? r->sets[L->s0] : QK_NONE;
  uint32_t f = QK_NONE;
  taker_t t = {&f, 1, 0, false};
  leaf_features(r, L, cx, cy, x, y, b, &t);
  return t.n ? f : QK_NONE;
}

static bool bad_rule(qk_boundary_t b) {
  return b != QK_BOUNDARY_SEMI_OPEN && b != QK_BOUNDARY_CLOSED && b != QK_BOUNDARY_OPEN;
}

qk_status_t qk_region_locate(const qk_region_t *r, qk_point_t p, qk_boundary_t b,
                             uint32_t *feature) {
  if (!r || !feature || bad_rule(b)) return QK_ERR_INVALID;
  if (!isfinite(p.x) || !isfinite(p.y)) {
    *feature = QK_NONE;
    return QK_ERR_NONFINITE;
  }
  *feature = qk__region_locate1(r, p.x, p.y, b);
  return QK_OK;
}

qk_status_t qk_region_locate_all(const qk_region_t *r, qk_point_t p, qk_boundary_t b,
                                 uint32_t *features, size_t cap, size_t *n_out) {
  if (!r || !n_out || bad_rule(b) || (cap && !features)) return QK_ERR_INVALID;
  *n_out = 0;
  if (!isfinite(p.x) || !isfinite(p.y)) return QK_ERR_NONFINITE;
  double x = p.x, y = p.y;
  if (!normalise(r, &x, &y)) return QK_OK;
  taker_t t = {features, cap, 0, true};
  double cx, cy;
  uint32_t k = descend(r, x, y, &cx, &cy);
  if (k & QK__DIRECT) {
    if (direct(k) != QK_NONE) take(&t, direct(k));
  } else {
    leaf_features(r, &r->leaves[k & ~QK__LEAF], cx, cy, x, y, b, &t);
  }
  *n_out = t.n;
  return QK_OK;
}

typedef struct job {
  const qk_region_t *r;
  const qk_point_t *pts;
  size_t n;
  qk_boundary_t b;
  uint32_t *out;
  int nonfinite;
} job_t;

/* A batch runs in blocks: first every point's descent (independent chains of loads the
 * processor overlaps) with a prefetch of its leaf, then the leaf tests. With an order,
 * the job's points are taken from sorted[] (its points in that order) and the answer of
 * sorted[i] goes to out[order[i]]. Each answer is what qk__region_locate1 gives. */
#define BLOCK 32

static void run(job_t *j, const qk_point_t *sorted, const uint32_t *order) {
  const qk_region_t *r = j->r;
  const qk_point_t *pts = order ? sorted : j->pts;
  for (size_t i0 = 0; i0 < j->n; i0 += BLOCK) {
    size_t m = j->n - i0 < BLOCK ? j->n - i0 : BLOCK;
    uint32_t k[BLOCK];
    double x[BLOCK], y[BLOCK], cx[BLOCK], cy[BLOCK];
    for (size_t i = 0; i < m; i++) {
      x[i] = pts[i0 + i].x, y[i] = pts[i0 + i].y;
      k[i] = QK__LEAF | QK__DIRECT; /* none */
      if (!isfinite(x[i]) || !isfinite(y[i])) {
        j->nonfinite = 1;
        continue;
      }
      if (!normalise(r, &x[i], &y[i])) continue;
      k[i] = descend(r, x[i], y[i], &cx[i], &cy[i]);
#if defined(__GNUC__)
      if (!(k[i] & QK__DIRECT)) __builtin_prefetch(&r->leaves[k[i] & ~QK__LEAF]);
#endif
    }
    for (size_t i = 0; i < m; i++) {
      uint32_t f = QK_NONE;
      if (k[i] & QK__DIRECT) {
        f = direct(k[i]);
      } else {
        const qk__leaf_t *L = &r->leaves[k[i] & ~QK__LEAF];
        if (L->ne == 0) {
          f = L->ns ? r->sets[L->s0] : QK_NONE;
        } else {
          taker_t t = {&f, 1, 0, false};
          leaf_features(r, L, cx[i], cy[i], x[i], y[i], j->b, &t);
          if (!t.n) f = QK_NONE;
        }
      }
      j->out[order ? order[i0 + i] : i0 + i] = f;
    }
  }
}

/*
 * Morton buckets. Random points over a layer larger than the processor's caches miss
 * the cache at nearly every level of their descent and again at their leaf's edges.
 * Answering the points in Z-order of their cells instead makes consecutive points walk
 * the same top levels and mostly the same leaves, which then stay in cache. A share is
 * taken in chunks of up to CHUNK points; each chunk is ordered by one counting pass over
 * 2^SORT_BITS x 2^SORT_BITS cells of the root square (the cells' Morton codes are the
 * bucket numbers; within a bucket the input order is kept), copying each point to its
 * place so that the queries read them in sequence, and the answers, scattered back to
 * the chunk's own part of out[], stay within a few hundred kilobytes. Only the order of
 * the work changes: every answer is computed alone by the same code and written to its
 * own index, so the results are those of single calls. Measured on countries-50m with
 * 10^6 uniform points (docs/region.md): callgrind counts more instructions (the sort)
 * but the time per point falls by about a quarter (process CPU time on a loaded machine;
 * the benchmark run on an idle one has the final word).
 * Each thread borrows 22 bytes per chunk point and 4 << (2 SORT_BITS) bytes from the
 * layer's allocator for the call; when that fails the batch runs in input order.
 */
#define SORT_BITS 8
#define SORT_BUCKETS (1u << (2 * SORT_BITS))
#define CHUNK ((size_t)1 << 18)
/* Chunks with fewer points are answered in input order (the sort would not pay). */
#define SORT_MIN ((size_t)1 << 15)

/* Bits 0..7 of v at the even positions 0..14. */
static const uint16_t spread8[256] = {
#define S1(v) (((v)&1) | ((v)&2) << 1 | ((v)&4) << 2 | ((v)&8) << 3)
#define S2(v) (S1(v) | S1((v) >> 4) << 8)
#define R4(v) S2(v), S2(v + 1), S2(v + 2), S2(v + 3)
#define R16(v) R4(v), R4(v + 4), R4(v + 8), R4(v + 12)
    R16(0),   R16(16),  R16(32),  R16(48),  R16(64),  R16(80),  R16(96),  R16(112),
    R16(128), R16(144), R16(160), R16(176), R16(192), R16(208), R16(224), R16(240)};
#undef S1
#undef S2
#undef R4
#undef R16

/* A coordinate's cell along one axis of the root square, clamped (points outside the
 * root, even NaN, go to some cell; they are answered like any other). */
static inline uint32_t sort_cell(double v, double lo, double scale) {
  double c = (v - lo) * scale;
  if (!(c > 0)) return 0;
  if (c >= (double)((1u << SORT_BITS) - 1)) return (1u << SORT_BITS) - 1;
  return (uint32_t)c;
}

/* sorted[] = pts[0..n) by bucket and order[i] = the index of sorted[i] in pts; cnt has
 * SORT_BUCKETS entries, key n (n <= CHUNK). */
static void sort_chunk(const qk_region_t *r, const qk_point_t *pts, size_t n, uint32_t *cnt,
                       uint16_t *key, qk_point_t *sorted, uint32_t *order) {
  const double scale = (double)(1u << SORT_BITS) / r->rside;
  memset(cnt, 0, SORT_BUCKETS * sizeof *cnt);
  for (size_t i = 0; i < n; i++) {
    uint32_t c = spread8[sort_cell(pts[i].x, r->rx, scale)] |
                 (uint32_t)spread8[sort_cell(pts[i].y, r->ry, scale)] << 1;
    key[i] = (uint16_t)c;
    cnt[c]++;
  }
  uint32_t sum = 0;
  for (uint32_t b = 0; b < SORT_BUCKETS; b++) {
    uint32_t c = cnt[b];
    cnt[b] = sum;
    sum += c;
  }
  for (size_t i = 0; i < n; i++) {
    uint32_t at = cnt[key[i]]++;
    sorted[at] = pts[i];
    order[at] = (uint32_t)i;
  }
}

typedef struct batch {
  job_t all;
  /* The scratch of the Morton order (cnt NULL: none): per share, SORT_BUCKETS counters
   * and `chunk` places in each of sorted[], order[] and key[]. */
  size_t chunk;
  uint32_t *cnt, *order;
  qk_point_t *sorted;
  uint16_t *key;
  int nonfinite[QK__MAX_THREADS];
} batch_t;

static void locate_share(void *ctx, unsigned w, unsigned nw) {
  batch_t *bt = ctx;
  size_t lo, hi;
  qk__share_range(bt->all.n, w, nw, &lo, &hi);
  for (size_t c0 = lo; c0 < hi; c0 += CHUNK) {
    size_t c1 = hi - c0 < CHUNK ? hi : c0 + CHUNK;
    job_t j = {bt->all.r, bt->all.pts + c0, c1 - c0, bt->all.b, bt->all.out + c0, 0};
    size_t at = (size_t)w * bt->chunk;
    bool sort = bt->cnt && j.n >= SORT_MIN;
    if (sort)
      sort_chunk(j.r, j.pts, j.n, bt->cnt + (size_t)w * SORT_BUCKETS, bt->key + at, bt->sorted + at,
                 bt->order + at);
    run(&j, sort ? bt->sorted + at : NULL, sort ? bt->order + at : NULL);
    if (j.nonfinite) bt->nonfinite[w] = 1;
  }
}

/* The scratch of nw shares of chunks of up to `chunk` points. */
static size_t scratch_bytes(size_t chunk, unsigned nw) {
  return (size_t)nw * (chunk * (sizeof(qk_point_t) + sizeof(uint32_t) + sizeof(uint16_t)) +
                       SORT_BUCKETS * sizeof(uint32_t));
}

qk_status_t qk_region_locate_batch(const qk_region_t *r, const qk_point_t *pts, size_t n,
                                   qk_boundary_t b, unsigned threads, uint32_t *out) {
  if (!r || bad_rule(b) || (n && (!pts || !out))) return QK_ERR_INVALID;
  threads = qk__threads_resolve(threads);
  size_t min_per = 4096; /* below this a thread costs more than it saves */
  if ((size_t)threads > n / min_per) threads = (unsigned)(n / min_per);
  unsigned nw = threads ? threads : 1;
  if (nw > QK__MAX_THREADS) nw = QK__MAX_THREADS;
  batch_t bt = {{r, pts, n, b, out, 0}, 0, NULL, NULL, NULL, NULL, {0}};
  /* Sort only when a share is large enough to pay. */
  size_t per = (n + nw - 1) / nw;
  bt.chunk = per < CHUNK ? per : CHUNK;
  void *scratch = NULL;
  if (bt.chunk >= SORT_MIN) scratch = qk__realloc(&r->alloc, NULL, 0, scratch_bytes(bt.chunk, nw));
  if (scratch) {
    bt.sorted = scratch;
    bt.cnt = (uint32_t *)(bt.sorted + (size_t)nw * bt.chunk);
    bt.order = bt.cnt + (size_t)nw * SORT_BUCKETS;
    bt.key = (uint16_t *)(bt.order + (size_t)nw * bt.chunk);
  }
  qk__run_shares(threads, locate_share, &bt);
  if (scratch) qk__free(&r->alloc, scratch, scratch_bytes(bt.chunk, nw));
  for (unsigned w = 0; w < QK__MAX_THREADS; w++)
    if (bt.nonfinite[w]) return QK_ERR_NONFINITE;
  return QK_OK;
}
