/*
 * Queries: descend to the leaf, then decide each candidate feature by the parity of the
 * crossings of the segment leaf reference -> point (see region.c). Batch calls split the
 * points over threads; each answer is computed by the same code, so results do not depend
 * on the thread count.
 */
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
 * processor overlaps) with a prefetch of its leaf, then the leaf tests. Each answer is
 * what qk__region_locate1 gives. */
#define BLOCK 32

static void run(job_t *j) {
  const qk_region_t *r = j->r;
  for (size_t i0 = 0; i0 < j->n; i0 += BLOCK) {
    size_t m = j->n - i0 < BLOCK ? j->n - i0 : BLOCK;
    uint32_t k[BLOCK];
    double x[BLOCK], y[BLOCK], cx[BLOCK], cy[BLOCK];
    for (size_t i = 0; i < m; i++) {
      x[i] = j->pts[i0 + i].x, y[i] = j->pts[i0 + i].y;
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
      j->out[i0 + i] = f;
    }
  }
}

typedef struct batch {
  job_t all;
  int nonfinite[QK__MAX_THREADS];
} batch_t;

static void locate_share(void *ctx, unsigned w, unsigned nw) {
  batch_t *bt = ctx;
  size_t lo, hi;
  qk__share_range(bt->all.n, w, nw, &lo, &hi);
  job_t j = {bt->all.r, bt->all.pts + lo, hi - lo, bt->all.b, bt->all.out + lo, 0};
  run(&j);
  bt->nonfinite[w] = j.nonfinite;
}

qk_status_t qk_region_locate_batch(const qk_region_t *r, const qk_point_t *pts, size_t n,
                                   qk_boundary_t b, unsigned threads, uint32_t *out) {
  if (!r || bad_rule(b) || (n && (!pts || !out))) return QK_ERR_INVALID;
  threads = qk__threads_resolve(threads);
  size_t min_per = 4096; /* below this a thread costs more than it saves */
  if ((size_t)threads > n / min_per) threads = (unsigned)(n / min_per);
  batch_t bt = {{r, pts, n, b, out, 0}, {0}};
  qk__run_shares(threads, locate_share, &bt);
  for (unsigned w = 0; w < QK__MAX_THREADS; w++)
    if (bt.nonfinite[w]) return QK_ERR_NONFINITE;
  return QK_OK;
}
