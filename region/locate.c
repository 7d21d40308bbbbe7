/*
 * Queries: descend to the leaf, then decide each candidate feature by the parity of the
 * crossings of the segment leaf reference -> point (see region.c). Batch calls put the
 * points in Morton order chunk by chunk and split the chunks over threads; each answer is
 * computed by the same code, so results depend neither on the order nor on the threads.
 */
#include <float.h>
#include <stdatomic.h>
#include <string.h>
#if defined(__SSE2__)
#include <emmintrin.h>
#endif

#include "region/region_internal.h"
#include "index/inline.h"

/* Map a query to the plane of the index; false when it is in no feature. Most points lie
 * in the query window, where the mapping changes nothing but the tiny coordinates. */
static QK__ALWAYS_INLINE bool in_root(const qk_region_t *r, double x, double y) {
  return x >= r->rx && x < r->rx + r->rside && y >= r->ry && y < r->ry + r->rside;
}

static QK__ALWAYS_INLINE bool normalise(const qk_region_t *r, double *x, double *y,
                                        qk_boundary_t b) {
  if (!(*x >= r->qx0 && *x <= r->qx1 && *y >= r->qy0 && *y <= r->qy1)) {
    if (!r->planar) {
      if (!(*y >= -90 && *y <= 90)) return false;
      /* A pole is one point of the sphere, inside whatever holds the area around it (the
       * whole world, a polar cap, a ring around it), yet on the map's top or bottom line,
       * which the semi-open rule's shift would take it off and which a feature reaching
       * the pole has as an edge: it is answered one step of the double toward the
       * equator, at its longitude. */
      if (*y == 90 || *y == -90) *y = nextafter(*y, 0.0);
      if (*x < -180 || *x >= 180) {
        /* Exactly x mod 360 in [-180, 180): fmod is exact, and so is the step by 360
         * (Sterbenz: t is within a factor 2 of 360). fmod(x + 180, 360) - 180 rounded
         * twice, so a vertex given 360 degrees away missed its own ring. */
        double t = fmod(*x, 360.0);
        if (t >= 180) t -= 360.0;
        if (t < -180) t += 360.0;
        *x = t;
      }
    }
    if (!in_root(r, *x, *y))
      /* A point on the antimeridian is also (180, y): under `closed` and `open` a layer
       * that reaches the meridian from the east only (its root square ends short of -180)
       * may have it on a ring (antimeridian_features). */
      return !r->planar && *x == -180.0 && b != QK_BOUNDARY_SEMI_OPEN && in_root(r, 180.0, *y);
  }
  /* Coordinates too small for the exact predicates are zero (the layer has none). */
  if (fabs(*x) < QK_REGION_MIN_COORD) *x = 0.0;
  if (fabs(*y) < QK_REGION_MIN_COORD) *y = 0.0;
  return true;
}

/*
 * The leaf a descent ended in, with the half-open box [lx, ux) x [ly, uy) of the points
 * that take the same path. lx is the leaf square's lower side: the descent only moves it
 * up, to a midpoint x0 + h that is never below x0 (rounding is monotone), so it is the
 * largest lower bound met on the way (the grid cell's side included). ux is the smallest
 * upper bound met (the grid cell's next side, then each midpoint the point fell below),
 * kept as a minimum so that no assumption on rounding is needed. A point inside the box
 * compares the same way as the one that made it at every level, so it reaches the same
 * leaf with the same reference point (cx, cy): a batch in Morton order asks this box
 * first and descends only when the point has left it. An empty box (lx = +inf) holds
 * nothing.
 */
typedef struct leaf_box {
  double lx, ly, ux, uy, cx, cy;
  uint32_t k; /* the kid[] value of the leaf */
} leaf_box_t;

static QK__ALWAYS_INLINE bool in_box(const leaf_box_t *c, double x, double y) {
  return x >= c->lx && x < c->ux && y >= c->ly && y < c->uy;
}

/* Descend to the leaf holding (x, y), which normalise() accepted. */
static QK__ALWAYS_INLINE void descend(const qk_region_t *r, double x, double y, leaf_box_t *c) {
  const uint32_t *kid = r->kid;
  uint32_t k = kid[0];
  double sx = r->rx, sy = r->ry, h = r->rside, ux = INFINITY, uy = INFINITY;
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
      ux = r->gx[i + 1];
      uy = r->gy[j + 1];
      h = r->grid_side;
    }
  }
  while (!(k & QK__LEAF)) {
    h *= 0.5;
    double mx = sx + h, my = sy + h;
    unsigned east = x >= mx, north = y >= my;
    /* NE 0, NW 1, SW 2, SE 3, without a branch */
    unsigned q = (north ^ 1u) << 1 | (north ^ east);
    sx = east ? mx : sx;
    sy = north ? my : sy;
    ux = east ? ux : qk__min(ux, mx);
    uy = north ? uy : qk__min(uy, my);
    k = kid[k + q];
  }
  c->lx = sx, c->ly = sy, c->ux = ux, c->uy = uy;
  c->cx = sx + h * 0.5;
  c->cy = sy + h * 0.5;
  c->k = k;
}

/* The answer of a direct leaf. */
static inline uint32_t direct(uint32_t k) { return (k & 0x3fffffffu) - 1u; }

/* Does the box of leaf L's edges lie strictly beside the box [lox, hix] x [loy, hiy]?
 * Then every edge does (beside()), and none is touched or crossed by a segment in it. */
static QK__ALWAYS_INLINE bool box_beside(const qk__leaf_t *L, double lox, double hix, double loy,
                                         double hiy) {
  return hix < L->ex0 || lox > L->ex1 || hiy < L->ey0 || loy > L->ey1;
}

/*
 * Every feature holding leaf L's reference point, in increasing order: the short set
 * merged with the cover, which is the checkpoint's cover with the features of the leaf's
 * change toggled (qk__cover_t). Between two features of the change or the short set the
 * checkpoint's features are taken as a run (merged one feature at a time, a feature took
 * four times the instructions).
 */
typedef struct full_set {
  const uint32_t *s, *se; /* the short set, what is left of it */
  const uint32_t *c, *ce; /* the checkpoint's cover, what is left of it */
  const uint32_t *d;
  unsigned di, dn; /* the change */
} full_set_t;

static void full_set_init(const qk_region_t *r, const qk__leaf_t *L, full_set_t *it) {
  static const uint32_t none[1] = {0};
  it->s = it->se = none; /* (no sets at all: r->sets may be NULL, and NULL + 0 is undefined) */
  if (L->ns) it->s = r->sets + L->s0, it->se = it->s + L->ns;
  size_t i = (size_t)(L - r->leaves);
  const qk__cover_t cv = r->cover_at[i];
  const uint32_t *ck = r->cover + cv.ck;
  it->c = ck + 1;
  it->ce = it->c + ck[0];
  uint32_t start = cv.ck + 1 + ck[0], prev_end = i ? r->cover_at[i - 1].end : 0;
  if (prev_end > start) start = prev_end;
  it->d = r->cover + start;
  it->di = 0, it->dn = cv.end - start;
}

/* The next change or short-set feature (QK_NONE: none). */
static QK__ALWAYS_INLINE uint32_t full_set_event(const full_set_t *it) {
  uint32_t x = it->di < it->dn ? it->d[it->di] : QK_NONE;
  uint32_t y = it->s < it->se ? *it->s : QK_NONE;
  return x < y ? x : y;
}

/* Whether f, the set's next candidate or above it, is in the set; taken if so. */
static QK__ALWAYS_INLINE bool full_set_take(full_set_t *it, uint32_t f) {
  bool in_s = it->s < it->se && *it->s == f;
  bool in_d = it->di < it->dn && it->d[it->di] == f;
  bool in_c = it->c < it->ce && *it->c == f;
  it->s += in_s, it->di += in_d, it->c += in_c;
  return in_s || in_c != in_d;
}

/* The set's next feature, not taken (QK_NONE after the last). */
static uint32_t full_set_peek(full_set_t *it) {
  for (;;) {
    uint32_t t = full_set_event(it), c = it->c < it->ce ? *it->c : QK_NONE;
    if (c < t) return c;
    if (t == QK_NONE) return QK_NONE;
    bool in_s = it->s < it->se && *it->s == t, in_d = it->di < it->dn && it->d[it->di] == t;
    if (in_s || (c == t) != in_d) return t;
    full_set_take(it, t); /* (in the checkpoint and changed: gone) */
  }
}

/* Take the set's features below f: written to out[n ..] while below cap; returns the
 * new count. */
static QK__ALWAYS_INLINE size_t full_set_take_below(full_set_t *it, uint32_t f, uint32_t *out,
                                                    size_t cap, size_t n) {
  for (;;) {
    uint32_t t = full_set_event(it), lim = t < f ? t : f;
    const uint32_t *c = it->c, *e = c;
    while (e < it->ce && *e < lim) e++;
    size_t k = (size_t)(e - c);
    if (n < cap) memcpy(out + n, c, (k < cap - n ? k : cap - n) * sizeof(uint32_t));
    n += k;
    it->c = e;
    if (lim == f) return n;
    if (full_set_take(it, t)) {
      if (n < cap) out[n] = t;
      n++;
    }
  }
}

/* Decide the features of one leaf in increasing order and hand each one that holds the
 * point to out[] (while below cap). Returns how many were found. Inlined per rule, so
 * the semi-open rule, which needs no on-edge test, gets a loop of its own. */
static QK__ALWAYS_INLINE size_t leaf_features(const qk_region_t *r, const qk__leaf_t *L, double cx,
                                              double cy, double x, double y, qk_boundary_t b,
                                              uint32_t *out, size_t cap) {
  /* (the arrays may be NULL when the whole layer has no sets or no edges) */
  uint32_t ne = L->ne, i = 0;
  full_set_t fs;
  full_set_init(r, L, &fs);
  const uint32_t *E = ne ? r->le + L->e0 : NULL; /* indices into r->segs */
  const uint32_t *tag = ne ? r->le_tag + L->e0 : NULL;
  const qk__seg_t *segs = r->segs;
  bool same = (x == cx && y == cy);
  size_t n = 0;
  /* every edge beside the segment c-p's box: the point is on none and crosses none */
  if (box_beside(L, qk__min(cx, x), qk__max(cx, x), qk__min(cy, y), qk__max(cy, y))) ne = 0;
  while (i < ne) {
    uint32_t f = tag[i] >> 2;
    n = full_set_take_below(&fs, f, out, cap, n);
    bool par = full_set_take(&fs, f);
    bool on = false;
    for (; i < ne && (tag[i] >> 2) == f; i++) {
      const qk__seg_t *g = &segs[E[i]];
      if (b != QK_BOUNDARY_SEMI_OPEN && !(tag[i] & 2) &&
          qk__on_edge(g->ax, g->ay, g->bx, g->by, x, y))
        on = true;
      if (same) continue;
      int sc = (tag[i] & 1) ? 1 : -1;
      par ^= qk__crosses(cx, cy, x, y, g->ax, g->ay, g->bx, g->by, sc);
    }
    bool in = b == QK_BOUNDARY_SEMI_OPEN ? par
              : b == QK_BOUNDARY_CLOSED  ? (par || on)
                                         : (par && !on);
    if (in) {
      if (n < cap) out[n] = f;
      n++;
    }
  }
  return full_set_take_below(&fs, QK_NONE, out, cap, n);
}

/* The lowest feature holding the point in leaf record L (QK_NONE for none): the same
 * walk as leaf_features() stopping at the first feature, written for that case (the
 * features that hold the reference point and have no pieces here come from the set,
 * held one ahead in `s`). Inlined per rule. */
static QK__ALWAYS_INLINE uint32_t leaf_first_exact(const qk_region_t *r, const qk__leaf_t *L,
                                                   double cx, double cy, double x, double y,
                                                   qk_boundary_t b) {
  uint32_t ne = L->ne, ns = L->ns, s0 = L->s0;
  /* features are below 2^29 (prepare.c), so QK_NONE follows every one */
  uint32_t s = ns ? r->sets[s0] : QK_NONE, si = 0;
  bool same = (x == cx && y == cy);
  if (ne == 0 || (same && b == QK_BOUNDARY_SEMI_OPEN)) return s; /* no crossings */
  const uint32_t *tag = r->le_tag + L->e0, *E = r->le + L->e0;   /* E: indices into segs */
  const qk__seg_t *segs = r->segs;
  uint32_t i = 0;
  do {
    uint32_t f = tag[i] >> 2;
    if (s < f) return s;
    bool par = s == f, on = false;
    if (par) s = ++si < ns ? r->sets[s0 + si] : QK_NONE;
    do {
      uint32_t tg = tag[i];
      const qk__seg_t *g = &segs[E[i]];
      if (b != QK_BOUNDARY_SEMI_OPEN) {
        if (!(tg & 2) && qk__on_edge(g->ax, g->ay, g->bx, g->by, x, y)) on = true;
        if (same) continue;
      }
      par ^= qk__crosses(cx, cy, x, y, g->ax, g->ay, g->bx, g->by, (tg & 1) ? 1 : -1);
    } while (++i < ne && (tag[i] >> 2) == f);
    bool in = b == QK_BOUNDARY_SEMI_OPEN ? par
              : b == QK_BOUNDARY_CLOSED  ? (par || on)
                                         : (par && !on);
    if (in) return f;
  } while (i < ne);
  return s;
}

/* Returned by leaf_first_filtered when a filter could not decide. */
#define UNSURE (QK_NONE - 1u)

/* Does edge g lie strictly beside the box [lox, hix] x [loy, hiy]? (Then it crosses no
 * segment in the box, whatever the perturbation, which is infinitesimal.) */
static QK__ALWAYS_INLINE bool beside(const qk__seg_t *g, double lox, double hix, double loy,
                                     double hiy) {
  return qk__max(g->ax, g->bx) < lox || qk__min(g->ax, g->bx) > hix ||
         qk__max(g->ay, g->by) < loy || qk__min(g->ay, g->by) > hiy;
}

/* leaf_first_exact() for the common case where every orientation it needs is decided by
 * the floating-point filter (qk__orient's, on the same expressions): then no orientation
 * is zero, so the perturbation never matters and the point is on no edge (the three rules
 * agree), and the loop makes no call (which would cost the registers holding the points).
 * Returns UNSURE when some filter cannot decide; the caller then runs the exact walk. */
static QK__ALWAYS_INLINE uint32_t leaf_first_filtered(const qk_region_t *r, const qk__leaf_t *L,
                                                      double cx, double cy, double x, double y) {
  static const double sign[2] = {-1.0, 1.0};
  uint32_t ne = L->ne, ns = L->ns, s0 = L->s0;
  uint32_t s = ns ? r->sets[s0] : QK_NONE, si = 0;
  /* the box of the segment c-p: an edge strictly beside it cannot cross it */
  const double lox = qk__min(cx, x), hix = qk__max(cx, x);
  const double loy = qk__min(cy, y), hiy = qk__max(cy, y);
  /* All of them beside it (often, in a leaf whose edges are a small cluster): no edge is
   * read. (Also when ne = 0: the box is empty.) */
  if (box_beside(L, lox, hix, loy, hiy)) return s;
  const uint32_t *tag = r->le_tag + L->e0, *E = r->le + L->e0;
  const qk__seg_t *segs = r->segs;
  const double px = x - cx, py = y - cy;
  /* Most often every edge is beside that box: then nothing crosses, the point is in the
   * features of the reference point, and a tight scan (no feature bookkeeping) says so. */
  uint32_t i = 0;
  while (i < ne && beside(&segs[E[i]], lox, hix, loy, hiy)) i++;
  if (i == ne) return s;
  i = 0;
  do {
    uint32_t f = tag[i] >> 2;
    if (s < f) return s;
    bool par = s == f;
    if (par) s = ++si < ns ? r->sets[s0 + si] : QK_NONE;
    do {
      const qk__seg_t *g = &segs[E[i]];
      if (beside(g, lox, hix, loy, hiy)) continue;
      /* orient(a, b, p), signed so that positive is the reference point's side */
      double l = (g->bx - g->ax) * (y - g->ay), rr = (g->by - g->ay) * (x - g->ax);
      double d = (l - rr) * sign[tag[i] & 1], bound = QK__ORIENT_ERR * (fabs(l) + fabs(rr));
      if (d > bound) continue; /* p on the reference point's side: no crossing */
      if (!(-d > bound)) return UNSURE;
      /* orient(c, p, a) and orient(c, p, b): does c-p cross the edge? */
      double la = px * (g->ay - cy), ra = py * (g->ax - cx);
      double lb = px * (g->by - cy), rb = py * (g->bx - cx);
      double da = la - ra, db = lb - rb;
      if (!(fabs(da) > QK__ORIENT_ERR * (fabs(la) + fabs(ra))) ||
          !(fabs(db) > QK__ORIENT_ERR * (fabs(lb) + fabs(rb))))
        return UNSURE;
      par ^= (da > 0) != (db > 0);
    } while (++i < ne && (tag[i] >> 2) == f);
    if (par) return f;
  } while (i < ne);
  return s;
}

/* leaf_first_exact() per rule, out of line (a point near an edge's line). */
#if defined(__GNUC__)
__attribute__((noinline))
#endif
static uint32_t
leaf_first_slow(const qk_region_t *r, const qk__leaf_t *L, double cx, double cy, double x, double y,
                qk_boundary_t b) {
  if (b == QK_BOUNDARY_SEMI_OPEN)
    return leaf_first_exact(r, L, cx, cy, x, y, QK_BOUNDARY_SEMI_OPEN);
  return leaf_first_exact(r, L, cx, cy, x, y, b);
}

/* The lowest feature holding the point in leaf record L (QK_NONE for none). */
static QK__ALWAYS_INLINE uint32_t leaf_first(const qk_region_t *r, const qk__leaf_t *L, double cx,
                                             double cy, double x, double y, qk_boundary_t b) {
  uint32_t f = leaf_first_filtered(r, L, cx, cy, x, y);
  return f != UNSURE ? f : leaf_first_slow(r, L, cx, cy, x, y, b);
}

/*
 * Lon/lat mode, the closed and open rules, a point on the antimeridian: queries map
 * longitude 180 to -180, but a ring edge at longitude 180 (a feature east of the
 * antimeridian, ending on it) is in the leaves of the map's east side, so the point
 * (-180, y) never meets it and a feature touching the antimeridian from the east would
 * not hold the point under `closed` (nor lose it under `open`). The point is both (-180,
 * y) and (180, y): its parity comes from the leaf at -180 as usual, and "on a ring" from
 * the given (not added) edges of both leaves. The features of the reference point's set
 * and of the two leaves' edges are merged in increasing order. Rare (a query exactly on
 * the antimeridian), so written for clarity. Hands features to out[] while below cap and
 * returns how many hold the point (the first only unless `all`).
 */
/* For an edge given along the antimeridian through (x, y), x = -180 or 180: count it in
 * *sides when it covers [y, y + e^2] (the semi-open side of the point); any other edge
 * through the point sets *across (the point is on a boundary that crosses the meridian). */
static void along_meridian(const qk__seg_t *g, double x, double y, unsigned *sides, bool *across) {
  if (g->ax != x || g->bx != x)
    *across = true;
  else if (qk__min(g->ay, g->by) <= y && y < qk__max(g->ay, g->by))
    ++*sides; /* (a zero-length piece on the meridian is neither) */
}

static size_t antimeridian_features(const qk_region_t *r, double y, qk_boundary_t b, bool all,
                                    uint32_t *out, size_t cap) {
  /* A side outside the root square has no leaf: nothing of the layer is there (the layer
   * reaches the antimeridian from one side only). */
  leaf_box_t w = {.k = QK__LEAF | QK__DIRECT}, e = {.k = QK__LEAF | QK__DIRECT};
  bool has_w = in_root(r, -180.0, y);
  if (has_w) descend(r, -180.0, y, &w);
  if (in_root(r, 180.0, y)) descend(r, 180.0, y, &e);
  const qk__leaf_t *LW = (w.k & QK__DIRECT) ? NULL : &r->leaves[w.k & ~QK__LEAF];
  const qk__leaf_t *LE = (e.k & QK__DIRECT) ? NULL : &r->leaves[e.k & ~QK__LEAF];
  /* the set of the west leaf's reference point: a direct leaf's answer, or the full set */
  full_set_t fs;
  uint32_t s = has_w && (w.k & QK__DIRECT) ? direct(w.k) : QK_NONE;
  if (LW) {
    full_set_init(r, LW, &fs);
    s = full_set_peek(&fs);
  }
  uint32_t nw = LW ? LW->ne : 0, ne = LE ? LE->ne : 0;
  const uint32_t *EW = nw ? r->le + LW->e0 : NULL, *TW = nw ? r->le_tag + LW->e0 : NULL;
  const uint32_t *EE = ne ? r->le + LE->e0 : NULL, *TE = ne ? r->le_tag + LE->e0 : NULL;
  bool same = (-180.0 == w.cx && y == w.cy);
  uint32_t iw = 0, ie = 0;
  size_t n = 0;
  for (;;) {
    uint32_t f = s;
    if (iw < nw && (TW[iw] >> 2) < f) f = TW[iw] >> 2;
    if (ie < ne && (TE[ie] >> 2) < f) f = TE[ie] >> 2;
    if (f == QK_NONE) return n;
    bool par = s == f, on = false, across = false;
    /* given edges along -180 and along +180 covering [y, y + e^2] */
    unsigned sides_w = 0, sides_e = 0;
    if (par) s = LW ? (full_set_take(&fs, f), full_set_peek(&fs)) : QK_NONE;
    for (; iw < nw && (TW[iw] >> 2) == f; iw++) {
      const qk__seg_t *g = &r->segs[EW[iw]];
      if (!(TW[iw] & 2) && qk__on_edge(g->ax, g->ay, g->bx, g->by, -180.0, y))
        on = true, along_meridian(g, -180.0, y, &sides_w, &across);
      if (!same)
        par ^=
            qk__crosses(w.cx, w.cy, -180.0, y, g->ax, g->ay, g->bx, g->by, (TW[iw] & 1) ? 1 : -1);
    }
    for (; ie < ne && (TE[ie] >> 2) == f; ie++) {
      const qk__seg_t *g = &r->segs[EE[ie]];
      if (!(TE[ie] & 2) && qk__on_edge(g->ax, g->ay, g->bx, g->by, 180.0, y))
        on = true, along_meridian(g, 180.0, y, &sides_e, &across);
    }
    /* `open`: the point is inside when the feature holds the map's west edge beside it
     * (par: the point moved by (e, e^2)) and the east edge too, and no given edge off the
     * meridian passes through it. Along the meridian the parity changes, from (180 - e, y)
     * to (-180 + e, y), with the given edges there (the added closures come in pairs, one
     * on each side over the same latitudes). As many on -180 as on +180 (a ring whose sides
     * on -180 and +180 are one meridian, the whole world, a band, an island split in two)
     * is no boundary on the sphere: each pair is one cut of the map. Otherwise a ring runs
     * along the meridian there (a feature on one side only; a zero-width spike up the
     * meridian and back, whose two edges on +180 were taken for such a pair). */
    if (b == QK_BOUNDARY_CLOSED ? (par || on) : (par && (!on || (!across && sides_w == sides_e)))) {
      if (n < cap) out[n] = f;
      n++;
      if (!all) return n;
    }
  }
}

/* Is (x, y), normalised, a point on the antimeridian under a rule that needs
 * antimeridian_features()? */
static inline bool on_antimeridian(const qk_region_t *r, double x, qk_boundary_t b) {
  return x == -180.0 && !r->planar && b != QK_BOUNDARY_SEMI_OPEN;
}

uint32_t qk__region_locate1(const qk_region_t *r, double x, double y, qk_boundary_t b) {
  if (!normalise(r, &x, &y, b)) return QK_NONE;
  if (on_antimeridian(r, x, b)) {
    uint32_t f = QK_NONE;
    antimeridian_features(r, y, b, false, &f, 1);
    return f;
  }
  leaf_box_t c;
  descend(r, x, y, &c);
  if (c.k & QK__DIRECT) return direct(c.k);
  return leaf_first(r, &r->leaves[c.k & ~QK__LEAF], c.cx, c.cy, x, y, b);
}

/* ---- pure cells ----------------------------------------------------------------------- */

/* A cell answer meaning "not one direct answer" (features are below 2^29, QK_NONE above). */
#define MIXED (QK_NONE - 1u)

/* The one answer of every leaf under node value k, or MIXED. */
static uint32_t subtree_answer(const qk_region_t *r, uint32_t k) {
  if (k & QK__LEAF) return (k & QK__DIRECT) ? direct(k) : MIXED;
  uint32_t a = subtree_answer(r, r->kid[k]);
  for (unsigned q = 1; q < 4 && a != MIXED; q++)
    if (subtree_answer(r, r->kid[k + q]) != a) a = MIXED;
  return a;
}

/* Fill the answers of the cells under node value k, the cell (i, j) of depth d. */
static void cell_answers(const qk_region_t *r, uint32_t k, unsigned d, size_t i, size_t j,
                         unsigned P, uint32_t *ans) {
  if (d == P || (k & QK__LEAF)) {
    uint32_t a = subtree_answer(r, k);
    size_t w = (size_t)1 << (P - d); /* a leaf above depth P covers w x w cells */
    for (size_t jj = j * w; jj < (j + 1) * w; jj++)
      for (size_t ii = i * w; ii < (i + 1) * w; ii++) ans[jj << P | ii] = a;
    return;
  }
  /* NE 0, NW 1, SW 2, SE 3 */
  cell_answers(r, r->kid[k + 0], d + 1, 2 * i + 1, 2 * j + 1, P, ans);
  cell_answers(r, r->kid[k + 1], d + 1, 2 * i, 2 * j + 1, P, ans);
  cell_answers(r, r->kid[k + 2], d + 1, 2 * i, 2 * j, P, ans);
  cell_answers(r, r->kid[k + 3], d + 1, 2 * i + 1, 2 * j, P, ans);
}

/*
 * The level: 2^8 cells a side (the batch's sort cells, 64 KiB) for a layer of at least a
 * megabyte, else one level finer than the grid (at most 2 bytes a leaf), so that the table
 * stays a small part of the layer. A cell is pure when it lies in direct leaves of one
 * answer: a point in it, whose descent passes through the cell's node (the cells' sides
 * are the descent's), ends in one of those leaves, and gets that answer whatever the
 * boundary rule (a direct leaf has no edges). `pure_eps` bounds the rounding of a point's
 * cell coordinate (x - rx) * 2^8 / rside against the cells' sides, as computed by the
 * descent: a point whose coordinate is farther than that from an integer is in the cell
 * its truncation names.
 */
qk_status_t qk__region_pure_build(qk_region_t *r) {
  unsigned P = r->grid_level + 1;
  if (r->n_le * sizeof(uint32_t) * 2 + r->n_segs * sizeof(qk__seg_t) >= ((size_t)1 << 20)) P = 8;
  if (P > 8) P = 8;
  if (P < 3 || r->n_kid == 0) return QK_OK;
  size_t g = (size_t)1 << P;
  const qk_allocator_t *a = &r->alloc;
  uint32_t *ans = qk__realloc(a, NULL, 0, g * g * sizeof *ans);
  uint8_t *pure = qk__realloc(a, NULL, 0, g * g);
  if (!ans || !pure) {
    qk__free(a, ans, g * g * sizeof *ans);
    qk__free(a, pure, g * g);
    return QK_ERR_NOMEM;
  }
  cell_answers(r, r->kid[0], 0, 0, 0, P, ans);
  /* the answers numbered in the order they first appear, row by row; runs of one answer
   * are common (oceans, large countries), so the last cell's number is tried first */
  unsigned n_ans = 0, last_t = 0;
  uint32_t last_v = MIXED;
  for (size_t c = 0; c < g * g; c++) {
    uint32_t v = ans[c];
    if (v != last_v) {
      unsigned t = 0;
      if (v != MIXED) {
        while (t < n_ans && r->pure_ans[t] != v) t++;
        if (t == n_ans && n_ans < 255) r->pure_ans[n_ans++] = v;
        t = t < n_ans ? t + 1 : 0; /* (no room left for another answer: not pure) */
      }
      last_v = v, last_t = t;
    }
    pure[c] = (uint8_t)last_t;
  }
  qk__free(a, ans, g * g * sizeof *ans);
  r->pure = pure;
  r->pure_level = P;
  /* The sides: 8 halvings and additions from rx (each off by half an ulp of at most |rx|
   * + rside); the coordinate: a subtraction and a product (relative errors of 2^-53).
   * 2^-40 of the magnitudes involved, in cells, is far above their sum. */
  r->pure_eps = (fabs(r->rx) + fabs(r->ry) + 2 * r->rside) * (256.0 / r->rside) * 0x1p-40;
  return QK_OK;
}

size_t qk__region_pure_bytes(const qk_region_t *r) {
  return r->pure_level ? (size_t)1 << (2 * r->pure_level) : 0;
}

void qk__region_pure_free(qk_region_t *r) {
  if (r->pure_level) qk__free(&r->alloc, r->pure, qk__region_pure_bytes(r));
  r->pure = NULL;
  r->pure_level = 0;
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
  if (!normalise(r, &x, &y, b)) return QK_OK;
  if (on_antimeridian(r, x, b)) {
    *n_out = antimeridian_features(r, y, b, true, features, cap);
    return QK_OK;
  }
  leaf_box_t c;
  descend(r, x, y, &c);
  if (c.k & QK__DIRECT) {
    if (direct(c.k) != QK_NONE) {
      if (cap) features[0] = direct(c.k);
      *n_out = 1;
    }
  } else {
    *n_out = leaf_features(r, &r->leaves[c.k & ~QK__LEAF], c.cx, c.cy, x, y, b, features, cap);
  }
  return QK_OK;
}

/* ---- batches -------------------------------------------------------------------------- */

/*
 * Morton order. Random points over a layer larger than the processor's caches miss the
 * cache at nearly every level of their descent and again at their leaf's edges. Answered
 * in Z-order of their cells instead, consecutive points walk the same top levels and
 * mostly the same leaves, which then stay in cache, and a point that lies in the leaf box
 * of the point before (leaf_box_t) skips its descent altogether (on countries-50m with
 * 10^6 uniform points, three points in four).
 *
 * The batch is cut into chunks of up to CHUNK points, which the threads take one at a
 * time from an atomic counter, so that a thread whose points are cheaper (ocean, or
 * outside the layer) takes more chunks and the threads end together. A chunk is ordered
 * without moving its points: one pass writes for each point of the query window an item,
 * its cell's 16-bit Morton code (256 x 256 cells of the root square) above its index in
 * the chunk (the few other points, outside the window, non-finite or with a tiny
 * coordinate, are answered by the single-point code after that pass); two passes of a
 * radix sort on the code's two bytes order the items (stable: within a cell the input
 * order stays); the answers are then computed in that order, reading each point (with a
 * prefetch a few items ahead) and writing each answer at its index. A chunk's items
 * (2 x 256 KiB), input (1 MiB) and output (256 KiB) stay near the processor's
 * second-level cache, and a thread's scratch is those two item arrays, borrowed once per
 * call, whatever the batch size. Only the order of the work changes: every answer is
 * computed alone by the same code and written to its own index, so the results are
 * those of single calls.
 */
#define IDX_BITS 16
#define CHUNK ((size_t)1 << IDX_BITS)
#define IDX_MASK ((uint32_t)CHUNK - 1u)
/* How far ahead of the point being answered the next point is prefetched; the item
 * arrays have room for that many items more than a chunk. */
#define PREFETCH 8
/* Chunks with fewer points are answered in input order (the sort would not pay). */
#define SORT_MIN ((size_t)1 << 12)
/* Batches of fewer points per thread run on fewer threads (a thread costs tens of
 * microseconds to start; this many points take about half a millisecond). */
#define MIN_PER_THREAD ((size_t)1 << 14)
/* A batch on several threads is cut into at least this many chunks per thread, so that
 * the threads end together. */
#define CHUNKS_PER_THREAD 16

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

/* One pass of the radix sort: the items of `from` to `to` by the byte at `shift`. */
static void radix_pass(const uint32_t *from, uint32_t *to, size_t m, unsigned shift,
                       uint32_t *cnt) {
  uint32_t sum = 0;
  for (unsigned d = 0; d < 256; d++) {
    uint32_t c = cnt[d];
    cnt[d] = sum;
    sum += c;
  }
  for (size_t i = 0; i < m; i++) {
    uint32_t v = from[i];
    to[cnt[(v >> shift) & 255u]++] = v;
  }
}

/* Order the points of a chunk: items[0..m) of the points that lie in the query window
 * with no tiny coordinate (so that normalising them changes nothing), in Morton order of
 * their cells; the other points are answered now. `tmp` has room for n items. Returns m. */
static size_t sort_chunk(const qk_region_t *r, const qk_point_t *pts, size_t n, qk_boundary_t b,
                         uint32_t *out, uint32_t *items, uint32_t *tmp, int *nonfinite) {
  const double scale = 256.0 / r->rside, rx = r->rx, ry = r->ry;
  const double qx0 = r->qx0, qx1 = r->qx1, qy0 = r->qy0, qy1 = r->qy1;
  /* a point in a pure cell is answered at once (P <= 8: the pure cells are sort cells or
   * groups of them) */
  const uint8_t *pure = r->pure;
  const unsigned P = r->pure_level, pshift = 8 - P;
  uint32_t cnt[2][256];
  memset(cnt, 0, sizeof cnt);
  size_t m = 0, k = 0;
#if defined(__SSE2__)
  /* The same tests and cells, on x and y at once (a third of this loop's instructions). */
  const __m128d lo = _mm_set_pd(qy0, qx0), hi = _mm_set_pd(qy1, qx1);
  const __m128d tiny = _mm_set1_pd(QK_REGION_MIN_COORD), org = _mm_set_pd(ry, rx);
  const __m128d sc = _mm_set1_pd(scale), abs_mask = _mm_castsi128_pd(_mm_set1_epi64x(INT64_MAX));
  const __m128d eps = _mm_set1_pd(r->pure_eps), eps1 = _mm_set1_pd(1.0 - r->pure_eps);
#endif
  for (size_t i = 0; i < n; i++) {
#if defined(__SSE2__)
    __m128d p = _mm_loadu_pd(&pts[i].x);
    __m128d ok = _mm_and_pd(_mm_and_pd(_mm_cmpge_pd(p, lo), _mm_cmple_pd(p, hi)),
                            _mm_cmpge_pd(_mm_and_pd(p, abs_mask), tiny));
    if (_mm_movemask_pd(ok) != 3) {
      tmp[n - ++k] = (uint32_t)i; /* answered below, out of this loop (which then makes no call) */
      continue;
    }
    /* A coordinate's cell of 256 along one axis of the root square: the point is in the
     * query window, so (v - lo) * scale is in [0, 256]. A rounded guess is enough: the
     * order only has to be good, not exact (the one value that can come out as 256 wraps
     * to cell 0), and the pure cells allow for one cell of error (256 is cell 255). */
    __m128d t = _mm_mul_pd(_mm_sub_pd(p, org), sc);
    __m128i cell = _mm_cvttpd_epi32(t);
    uint32_t ux = (uint32_t)_mm_cvtsi128_si32(cell);
    uint32_t uy = (uint32_t)_mm_cvtsi128_si32(_mm_srli_si128(cell, 4));
    if (pure) {
      /* the fractional parts of both coordinates, farther than eps from 0 and 1 */
      __m128d f = _mm_sub_pd(t, _mm_cvtepi32_pd(cell));
      if (_mm_movemask_pd(_mm_and_pd(_mm_cmpgt_pd(f, eps), _mm_cmplt_pd(f, eps1))) == 3) {
        uint8_t v = pure[(uy > 255 ? 255 : uy) >> pshift << P | (ux > 255 ? 255 : ux) >> pshift];
        if (v) {
          out[i] = r->pure_ans[v - 1];
          continue;
        }
      }
    }
    uint32_t c = spread8[ux & 255u] | (uint32_t)spread8[uy & 255u] << 1;
#else
    double x = pts[i].x, y = pts[i].y;
    if (!(x >= qx0 && x <= qx1 && y >= qy0 && y <= qy1 && fabs(x) >= QK_REGION_MIN_COORD &&
          fabs(y) >= QK_REGION_MIN_COORD)) {
      tmp[n - ++k] = (uint32_t)i; /* answered below, out of this loop (which then makes no call) */
      continue;
    }
    double tx = (x - rx) * scale, ty = (y - ry) * scale;
    uint32_t ux = (uint32_t)tx, uy = (uint32_t)ty;
    if (pure) {
      /* the fractional parts of both coordinates, farther than eps from 0 and 1 */
      double fx = tx - ux, fy = ty - uy, eps = r->pure_eps;
      if (fx > eps && fx < 1 - eps && fy > eps && fy < 1 - eps) {
        uint8_t v = pure[(uy > 255 ? 255 : uy) >> pshift << P | (ux > 255 ? 255 : ux) >> pshift];
        if (v) {
          out[i] = r->pure_ans[v - 1];
          continue;
        }
      }
    }
    uint32_t c = spread8[ux & 255u] | (uint32_t)spread8[uy & 255u] << 1;
#endif
    items[m++] = c << IDX_BITS | (uint32_t)i;
    cnt[0][c & 255u]++;
    cnt[1][c >> 8]++;
  }
  for (size_t j = n - k; j < n; j++) { /* (m + k = n: the radix sort writes tmp[0..m) only) */
    double x = pts[tmp[j]].x, y = pts[tmp[j]].y;
    if (!isfinite(x) || !isfinite(y)) *nonfinite = 1;
    out[tmp[j]] = qk__region_locate1(r, x, y, b); /* (NaN included: none) */
  }
  radix_pass(items, tmp, m, IDX_BITS, cnt[0]);
  radix_pass(tmp, items, m, IDX_BITS + 8, cnt[1]);
  for (unsigned k = 0; k < PREFETCH; k++) items[m + k] = 0; /* for run()'s look-ahead */
  return m;
}

/* Answer points of a chunk into out[] (indexed like pts): with items, the m points
 * items[t] & IDX_MASK, which need no normalising (sort_chunk); without, the m points in
 * input order. A point in the leaf box of the point before takes its leaf without a
 * descent. Points that need a leaf's edges are gathered in blocks of BLOCK and decided
 * together after a prefetch of their leaf records, so that those loads overlap. */
#define BLOCK 32

static QK__ALWAYS_INLINE void run_impl(const qk_region_t *r, qk_boundary_t b, const qk_point_t *pts,
                                       const uint32_t *items, size_t m, uint32_t *out,
                                       int *nonfinite, bool sorted) {
  leaf_box_t c = {INFINITY, INFINITY, -INFINITY, -INFINITY, 0, 0, 0};
  uint32_t bi[BLOCK], bk[BLOCK];
  double bx[BLOCK], by[BLOCK], bcx[BLOCK], bcy[BLOCK];
  unsigned nb = 0;
  for (size_t t = 0; t < m; t++) {
    uint32_t i = sorted ? items[t] & IDX_MASK : (uint32_t)t;
    double x = pts[i].x, y = pts[i].y;
    if (sorted) {
#if defined(__GNUC__)
      /* the points are read out of order: ask for one a few places ahead */
      __builtin_prefetch(&pts[items[t + PREFETCH] & IDX_MASK]); /* (items are padded) */
#endif
    } else {
      if (!isfinite(x) || !isfinite(y)) *nonfinite = 1;
      if (!normalise(r, &x, &y, b)) {
        out[i] = QK_NONE;
        continue;
      }
      if (on_antimeridian(r, x, b)) { /* (sorted items never are: see build.c's window) */
        out[i] = qk__region_locate1(r, x, y, b);
        continue;
      }
    }
    if (!in_box(&c, x, y)) {
      descend(r, x, y, &c);
#if defined(__GNUC__)
      if (!(c.k & QK__DIRECT)) __builtin_prefetch(&r->leaves[c.k & ~QK__LEAF]);
#endif
    }
    if (c.k & QK__DIRECT) {
      out[i] = direct(c.k);
      continue;
    }
    bi[nb] = i, bk[nb] = c.k, bx[nb] = x, by[nb] = y, bcx[nb] = c.cx, bcy[nb] = c.cy;
    if (++nb < BLOCK && t + 1 < m) continue;
    for (unsigned e = 0; e < nb; e++)
      out[bi[e]] = leaf_first(r, &r->leaves[bk[e] & ~QK__LEAF], bcx[e], bcy[e], bx[e], by[e], b);
    nb = 0;
  }
  for (unsigned e = 0; e < nb; e++)
    out[bi[e]] = leaf_first(r, &r->leaves[bk[e] & ~QK__LEAF], bcx[e], bcy[e], bx[e], by[e], b);
}

/* run_impl for sorted items (the loop then tests nothing about the order per point). */
static void run_sorted(const qk_region_t *r, qk_boundary_t b, const qk_point_t *pts,
                       const uint32_t *items, size_t m, uint32_t *out) {
  run_impl(r, b, pts, items, m, out, NULL, true);
}

/* run_impl in input order, normalising each point. */
static void run_plain(const qk_region_t *r, qk_boundary_t b, const qk_point_t *pts, size_t m,
                      uint32_t *out, int *nonfinite) {
  run_impl(r, b, pts, NULL, m, out, nonfinite, false);
}

typedef struct batch {
  const qk_region_t *r;
  const qk_point_t *pts;
  size_t n, chunk, n_chunks;
  qk_boundary_t b;
  uint32_t *out;
  /* the scratch (NULL: none): per share, two arrays of `chunk` items */
  uint32_t *scratch;
  atomic_size_t next; /* the next chunk to take */
  int nonfinite[QK__MAX_THREADS];
} batch_t;

static void locate_share(void *ctx, unsigned w, unsigned nw) {
  (void)nw;
  batch_t *bt = ctx;
  size_t room = bt->chunk + PREFETCH;
  uint32_t *items = bt->scratch ? bt->scratch + (size_t)w * 2 * room : NULL;
  int nonfinite = 0;
  for (;;) {
    size_t c = atomic_fetch_add_explicit(&bt->next, 1, memory_order_relaxed);
    if (c >= bt->n_chunks) break;
    size_t c0 = c * bt->chunk, n = bt->n - c0 < bt->chunk ? bt->n - c0 : bt->chunk;
    const qk_point_t *pts = bt->pts + c0;
    uint32_t *out = bt->out + c0;
    if (items && n >= SORT_MIN) {
      size_t m = sort_chunk(bt->r, pts, n, bt->b, out, items, items + room, &nonfinite);
      run_sorted(bt->r, bt->b, pts, items, m, out);
    } else {
      run_plain(bt->r, bt->b, pts, n, out, &nonfinite);
    }
  }
  if (nonfinite) bt->nonfinite[w] = 1;
}

qk_status_t qk_region_locate_batch(const qk_region_t *r, const qk_point_t *pts, size_t n,
                                   qk_boundary_t b, unsigned threads, uint32_t *out) {
  if (!r || bad_rule(b) || (n && (!pts || !out))) return QK_ERR_INVALID;
  if (n == 0) return QK_OK;
  unsigned nw = qk__threads_resolve(threads);
  size_t most = n / MIN_PER_THREAD ? n / MIN_PER_THREAD : 1;
  if (nw > most) nw = (unsigned)most;
  /* Chunks of CHUNK points, or smaller ones (multiples of 16, so that no two chunks write
   * the same cache line of a 64-byte aligned out[]) when the threads would have too few. */
  size_t chunk = CHUNK, per = CHUNKS_PER_THREAD * (size_t)nw;
  if (nw > 1 && n < CHUNK * per) chunk = ((n + per - 1) / per + 15) & ~(size_t)15;
  if (chunk > n) chunk = n;
  batch_t bt = {r, pts, n, chunk, (n + chunk - 1) / chunk, b, out, NULL, 0, {0}};
  atomic_init(&bt.next, 0);
  size_t bytes = (size_t)nw * 2 * (chunk + PREFETCH) * sizeof(uint32_t);
  if (n >= SORT_MIN) bt.scratch = qk__realloc(&r->alloc, NULL, 0, bytes);
  qk__run_shares(nw, locate_share, &bt);
  if (bt.scratch) qk__free(&r->alloc, bt.scratch, bytes);
  for (unsigned w = 0; w < nw; w++)
    if (bt.nonfinite[w]) return QK_ERR_NONFINITE;
  return QK_OK;
}
