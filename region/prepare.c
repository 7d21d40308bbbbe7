/*
 * From rings to edge pieces: validation of the arrays, then, per ring, the pieces that
 * bound the feature in the plane of the index.
 *
 * Planar mode: every ring edge a->b with a != b is a piece.
 *
 * Lon/lat mode (coordinates are longitude in [-180, 180], latitude in [-90, 90]):
 *  1. An edge whose longitudes differ by at most 180 degrees is a piece as it is.
 *  2. An edge whose longitudes differ by more than 180 crosses the antimeridian the
 *     short way. Its crossing latitude phi is interpolated linearly in lon/lat (rounded
 *     once; both halves use the same value, so it is simply a new vertex) and the edge
 *     becomes a -> (+-180, phi) and (-+180, phi) -> b. phi depends on the two ends only,
 *     not on which comes first, so that an edge shared by two features (a -> b in one,
 *     b -> a in the other) is cut at the same point in both. An edge from lon 180 to lon
 *     -180 (or back) runs along the antimeridian; it is cut at its vertex on 180 (so that
 *     it lies along -180 whichever way it runs). Except an
 *     edge from (-+180, y) to (+-180, y) that runs across the whole map along latitude y
 *     (across_map): at the poles (y = +-90, the map's top and bottom lines), and where
 *     read as a zero-length step the ring would double back on the antimeridian (its
 *     neighbouring edges both run along it on one side of y: the whole-map rectangle
 *     [-180, 60] .. [180, 90], the whole world). Such an edge is a piece as it is.
 *  3. Each cut leaves the two sides of the rectangle open. Both are closed along the
 *     antimeridian through the pole latitude P of the ring: eastward (lon increasing
 *     through 180) a cut adds (180, phi) -> (180, P) and (-180, P) -> (-180, phi);
 *     westward the reverse. For a ring crossing as often eastward as westward these
 *     closures cancel pairwise on [phi1, phi2] (even-odd), whatever P is.
 *  4. A ring with k more eastward than westward crossings winds k times around the
 *     globe; |k| pieces along the pole latitude, (180, P) -> (-180, P) (or the reverse
 *     for westward winding), close it. P is the pole on the side of the smaller enclosed
 *     lon/lat area: a ring around Antarctica encloses the south pole, an Arctic ring the
 *     north pole.
 * The added pieces (cuts' closures and pole pieces) are marked synthetic: they bound the
 * feature but are not its boundary on the sphere, so the closed and open rules ignore
 * them. Ring vertices at longitude 180 and -180 are different points of the rectangle;
 * queries map longitude 180 to -180.
 */
#include <stdlib.h>
#include <string.h>

#include "region/region_internal.h"

qk_status_t qk__region_check_coord(int planar, double x, double y, size_t f, qk_error_t *err) {
  if (!isfinite(x) || !isfinite(y))
    return qk__region_fail(err, QK_ERR_NONFINITE, f,
                           "feature %zu: coordinate (%g, %g) is not finite", f, x, y);
  if (!planar && (x < -180 || x > 180 || y < -90 || y > 90))
    return qk__region_fail(err, QK_ERR_GEOMETRY, f,
                           "feature %zu: (%.17g, %.17g) is not a longitude/latitude in [-180, 180] "
                           "x [-90, 90] (projected data needs planar mode)",
                           f, x, y);
  double v[2] = {x, y};
  for (int i = 0; i < 2; i++) {
    double m = fabs(v[i]);
    if (m > QK_REGION_MAX_COORD || (m != 0 && m < QK_REGION_MIN_COORD))
      return qk__region_fail(err, QK_ERR_GEOMETRY, f,
                             "feature %zu: absurd coordinate %.17g (magnitude must be 0 or within "
                             "[1e-100, 1e100])",
                             f, v[i]);
  }
  return QK_OK;
}

void qk__pieces_free(const qk_allocator_t *a, qk__pieces_t *p) {
  qk__free(a, p->seg, p->cap * sizeof(qk__seg_t));
  qk__free(a, p->feat, p->cap * sizeof(uint32_t));
  qk__free(a, p->ring, p->cap * sizeof(uint32_t));
  qk__free(a, p->vtx, p->cap * sizeof(uint32_t));
  memset(p, 0, sizeof *p);
}

static qk_status_t reserve(const qk_allocator_t *a, qk__pieces_t *p, size_t need) {
  if (need <= p->cap) return QK_OK;
  size_t nc = p->cap ? p->cap : (need > 64 ? need : 64); /* the first time: the bound asked */
  while (nc < need) nc *= 2;
  if (nc > UINT32_MAX) return QK_ERR_LIMIT;
  /* Fresh arrays, copied, then the old ones freed: on failure the old ones stay whole
   * and share one capacity. */
  qk__pieces_t n = {0};
  n.seg = qk__realloc(a, NULL, 0, nc * sizeof *n.seg);
  n.feat = qk__realloc(a, NULL, 0, nc * sizeof(uint32_t));
  n.ring = qk__realloc(a, NULL, 0, nc * sizeof(uint32_t));
  n.vtx = qk__realloc(a, NULL, 0, nc * sizeof(uint32_t));
  n.cap = nc;
  if (!n.seg || !n.feat || !n.ring || !n.vtx) {
    qk__free(a, n.seg, nc * sizeof *n.seg);
    qk__free(a, n.feat, nc * sizeof(uint32_t));
    qk__free(a, n.ring, nc * sizeof(uint32_t));
    qk__free(a, n.vtx, nc * sizeof(uint32_t));
    return QK_ERR_NOMEM;
  }
  if (p->n) {
    memcpy(n.seg, p->seg, p->n * sizeof *n.seg);
    memcpy(n.feat, p->feat, p->n * sizeof(uint32_t));
    memcpy(n.ring, p->ring, p->n * sizeof(uint32_t));
    memcpy(n.vtx, p->vtx, p->n * sizeof(uint32_t));
  }
  n.n = p->n;
  qk__pieces_free(a, p);
  *p = n;
  return QK_OK;
}

/* The ring being turned into pieces: either counted (out == NULL: winding and area) or
 * emitted. */
typedef struct ring_ctx {
  const qk_allocator_t *a;
  qk__pieces_t *out;
  uint32_t f, r;
  double area2; /* twice the signed area of the pieces (counted only) */
} ring_ctx_t;

static qk_status_t piece(ring_ctx_t *c, double ax, double ay, double bx, double by, uint32_t v) {
  if (ax == bx && ay == by) return QK_OK;
  qk__pieces_t *p = c->out;
  if (!p) { /* counting: only the area is wanted */
    c->area2 += ax * by - bx * ay;
    return QK_OK;
  }
  qk_status_t st = p->n < p->cap ? QK_OK : reserve(c->a, p, p->n + 1); /* (sized at once) */
  if (st) return st;
  p->seg[p->n] = (qk__seg_t){ax, ay, bx, by};
  p->feat[p->n] = c->f;
  p->ring[p->n] = c->r;
  p->vtx[p->n] = v;
  p->n++;
  return QK_OK;
}

/* Latitude where the edge between a and b, whose longitudes differ by more than 180, meets
 * the antimeridian. Computed from the unordered pair: always from the end e east of
 * longitude 0 towards the other end w moved by 360, whichever of them comes first in the
 * ring. An edge shared by two features is listed a -> b in one and b -> a in the other,
 * and an interpolation from each edge's own start rounds differently: the two cuts would
 * lie a few ulps apart, and points on the antimeridian between them would fall in both
 * features or in neither. */
static double cut_lat(double ax, double ay, double bx, double by) {
  bool a_east = ax > 0; /* (the ends' longitudes have opposite signs) */
  double ex = a_east ? ax : bx, ey = a_east ? ay : by;
  double wx = a_east ? bx : ax, wy = a_east ? by : ay;
  if (ex == 180) return ey;
  if (wx == -180) return wy;
  double t = (180 - ex) / ((wx + 360) - ex);
  double phi = ey + t * (wy - ey);
  double lo = qk__min(ey, wy), hi = qk__max(ey, wy);
  phi = qk__min(qk__max(phi, lo), hi);
  if (fabs(phi) < QK_REGION_MIN_COORD) phi = 0.0;
  return phi;
}

/* The ring's nearest edge of non-zero length before (dir -1) or after (dir +1) edge i of
 * a closed ring of len positions: its far end (the end away from edge i) in *x, *y. */
static void neighbour_end(const double *q, size_t len, size_t i, int dir, double *x, double *y) {
  size_t m = len - 1; /* edges 0 .. m-1; edge j runs from position j to j + 1 */
  size_t j = i;
  for (size_t step = 1; step < m; step++) {
    j = dir < 0 ? (j + m - 1) % m : (j + 1) % m;
    const double *a = q + 2 * j, *b = a + 2;
    if (a[0] == b[0] && a[1] == b[1]) continue;
    *x = dir < 0 ? a[0] : b[0];
    *y = dir < 0 ? a[1] : b[1];
    return;
  }
  *x = q[2 * i], *y = q[2 * i + 1]; /* (no other edge: the edge's own end) */
}

/* Does edge i of the ring, from (ax, y) to (bx, y) with {ax, bx} = {-180, 180}, run across
 * the whole map along latitude y (rather than being a zero-length step on the
 * antimeridian)? It does at the poles (the map's top and bottom lines), and where, read
 * as a step, the ring would double back on the antimeridian: its neighbouring edges both
 * run along the antimeridian on one side of y, as the sides of a band or of the whole-map
 * rectangle [-180, 60] .. [180, 90] do. */
static bool across_map(const double *q, size_t len, size_t i, double y) {
  if (y == 90 || y == -90) return true;
  double px, py, nx, ny;
  neighbour_end(q, len, i, -1, &px, &py);
  neighbour_end(q, len, i, +1, &nx, &ny);
  return fabs(px) == 180 && fabs(nx) == 180 && ((py > y && ny > y) || (py < y && ny < y));
}

/* Pieces of one ring in lon/lat mode; k_out: net eastward windings. */
static qk_status_t ring_lonlat(ring_ctx_t *c, const double *xy, size_t start, size_t len, double P,
                               long *k_out) {
  long k = 0;
  qk_status_t st = QK_OK;
  qk__pieces_t *out = c->out;
  const double *q = xy + 2 * start;
  for (size_t i = 0; i + 1 < len && !st; i++, q += 2) {
    uint32_t v = (uint32_t)(start + i);
    double ax = q[0], ay = q[1], bx = q[2], by = q[3];
    double d = bx - ax;
    if (d >= -180 && d <= 180) { /* the common case: the edge as it is */
      if (out && out->n < out->cap) {
        /* piece() inline, for the run of such edges (in locals: the stores cannot move
         * them) */
        qk__seg_t *seg = out->seg;
        uint32_t *feat = out->feat, *ring = out->ring, *vx = out->vtx, f = c->f, r = c->r;
        size_t n = out->n, cap = out->cap;
        bool full = false;
        for (;;) {
          if (ax != bx || ay != by) {
            if (n == cap) {
              full = true;
              break;
            }
            seg[n] = (qk__seg_t){ax, ay, bx, by};
            feat[n] = f, ring[n] = r, vx[n] = v;
            n++;
          }
          if (i + 2 >= len) break;
          double nx = q[4], ny = q[5];
          if (!(nx - bx >= -180 && nx - bx <= 180)) break;
          i++, q += 2, v++;
          ax = bx, ay = by, bx = nx, by = ny;
        }
        out->n = n;
        if (full) st = piece(c, ax, ay, bx, by, v); /* (sized at once: never) */
      } else if (ax != bx || ay != by) {
        st = piece(c, ax, ay, bx, by, v);
      }
    } else if (ay == by && fabs(d) == 360 && across_map(xy + 2 * start, len, i, ay)) {
      st = piece(c, ax, ay, bx, by, v); /* along latitude ay from one side to the other */
    } else if (d < -180) {              /* eastward through 180 */
      double phi = cut_lat(ax, ay, bx, by);
      if (!(st = piece(c, ax, ay, 180, phi, v)) && !(st = piece(c, 180, phi, 180, P, UINT32_MAX)) &&
          !(st = piece(c, -180, P, -180, phi, UINT32_MAX)))
        st = piece(c, -180, phi, bx, by, v);
      k++;
    } else { /* westward through -180 (or NaN, which validation rejects first) */
      double phi = cut_lat(ax, ay, bx, by);
      if (!(st = piece(c, ax, ay, -180, phi, v)) &&
          !(st = piece(c, -180, phi, -180, P, UINT32_MAX)) &&
          !(st = piece(c, 180, P, 180, phi, UINT32_MAX)))
        st = piece(c, 180, phi, bx, by, v);
      k--;
    }
  }
  for (long j = 0; j < labs(k) && !st; j++)
    st = k > 0 ? piece(c, 180, P, -180, P, UINT32_MAX) : piece(c, -180, P, 180, P, UINT32_MAX);
  *k_out = k;
  return st;
}

/* Does qk__region_check_coord accept (x, y)? (NaN fails every comparison.) */
static inline bool coord_ok(int planar, double x, double y) {
  double ax = fabs(x), ay = fabs(y);
  bool tiny_ok = (ax >= QK_REGION_MIN_COORD || ax == 0) && (ay >= QK_REGION_MIN_COORD || ay == 0);
  if (!planar) /* (within [-180, 180] x [-90, 90], far below the largest magnitude) */
    return ax <= 180 && ay <= 90 && tiny_ok;
  return ax <= QK_REGION_MAX_COORD && ay <= QK_REGION_MAX_COORD && tiny_ok;
}

/* Check the arrays; *bound: the pieces they make at most (see qk__region_prepare), counted
 * in the same pass over the coordinates. */
static qk_status_t check_arrays(const qk_region_arrays_t *in, int planar, size_t *bound,
                                qk_error_t *err) {
  *bound = 0;
  if (!in) return qk__region_fail(err, QK_ERR_INVALID, SIZE_MAX, "no input");
  if (in->n_features && !in->feature_start)
    return qk__region_fail(err, QK_ERR_INVALID, SIZE_MAX, "feature_start is NULL");
  if (in->n_rings && (!in->ring_start || !in->xy))
    return qk__region_fail(err, QK_ERR_INVALID, SIZE_MAX, "ring_start or xy is NULL");
  if (in->n_features >= (1u << 29))
    return qk__region_fail(err, QK_ERR_LIMIT, SIZE_MAX, "too many features (%zu)", in->n_features);
  size_t nr = in->feature_start ? in->feature_start[in->n_features] : 0;
  if ((in->feature_start && in->feature_start[0] != 0) || nr != in->n_rings)
    return qk__region_fail(err, QK_ERR_INVALID, SIZE_MAX,
                           "feature_start must run from 0 to n_rings (%zu)", in->n_rings);
  if (in->n_rings && in->ring_start[0] != 0)
    return qk__region_fail(err, QK_ERR_INVALID, SIZE_MAX, "ring_start[0] must be 0");
  if (in->n_rings && in->ring_start[in->n_rings] >= UINT32_MAX)
    return qk__region_fail(err, QK_ERR_LIMIT, SIZE_MAX, "too many vertices");
  for (size_t f = 0; f < in->n_features; f++) {
    if (in->feature_start[f + 1] < in->feature_start[f])
      return qk__region_fail(err, QK_ERR_INVALID, f, "feature %zu: ring offsets decrease", f);
    for (size_t r = in->feature_start[f]; r < in->feature_start[f + 1]; r++) {
      size_t s = in->ring_start[r], e = in->ring_start[r + 1];
      size_t k = r - in->feature_start[f];
      if (e < s)
        return qk__region_fail(err, QK_ERR_INVALID, f,
                               "feature %zu, ring %zu: vertex offsets "
                               "decrease",
                               f, k);
      if (e - s < 4)
        return qk__region_fail(err, QK_ERR_GEOMETRY, f,
                               "feature %zu, ring %zu: %zu positions (a ring needs at least 4)", f,
                               k, e - s);
      /* a ring edge gives one piece, or four when it crosses the antimeridian, and a ring
       * winding w times round the globe |w| more */
      long w = 0;
      size_t cuts = 0;
      double px = in->xy[2 * s];
      for (size_t v = s; v < e; v++) {
        double x = in->xy[2 * v], y = in->xy[2 * v + 1], d = x - px;
        px = x;
        if (d < -180 || d > 180) cuts++, w += d < -180 ? 1 : -1;
        if (coord_ok(planar, x, y)) continue; /* (the common case, without a call) */
        qk_status_t st = qk__region_check_coord(planar, x, y, f, err);
        if (st) return st;
      }
      *bound += e - s - 1;
      if (!planar) *bound += 3 * cuts + (size_t)labs(w);
      const double *p = in->xy + 2 * s, *q = in->xy + 2 * (e - 1);
      if (p[0] != q[0] || p[1] != q[1])
        return qk__region_fail(err, QK_ERR_GEOMETRY, f,
                               "feature %zu, ring %zu: not closed (first position (%.17g, %.17g), "
                               "last (%.17g, %.17g))",
                               f, k, p[0], p[1], q[0], q[1]);
    }
  }
  return QK_OK;
}

qk_status_t qk__region_prepare(const qk_allocator_t *a, const qk_region_arrays_t *in, int planar,
                               qk__pieces_t *out, qk_error_t *err) {
  memset(out, 0, sizeof *out);
  size_t bound;
  qk_status_t st = check_arrays(in, planar, &bound, err);
  if (st) return st;
  /* Room for every piece at once. */
  if (bound && (st = reserve(a, out, bound))) {
    qk__pieces_free(a, out);
    return qk__region_fail(err, st, SIZE_MAX,
                           st == QK_ERR_NOMEM ? "out of memory" : "too many edges");
  }
  for (size_t f = 0; f < in->n_features && !st; f++) {
    for (size_t r = in->feature_start[f]; r < in->feature_start[f + 1] && !st; r++) {
      size_t s = in->ring_start[r], len = in->ring_start[r + 1] - s;
      ring_ctx_t c = {a, out, (uint32_t)f, (uint32_t)r, 0};
      if (planar) {
        for (size_t i = 0; i + 1 < len && !st; i++) {
          const double *p = in->xy + 2 * (s + i);
          st = piece(&c, p[0], p[1], p[2], p[3], (uint32_t)(s + i));
        }
        continue;
      }
      /* Made as if the ring held the north pole; a ring around the globe holds the pole
       * towards which it encloses the smaller area, and one around the south pole is made
       * again (rare: each layer has a few such rings at most). */
      long k = 0;
      size_t first = out->n;
      if ((st = ring_lonlat(&c, in->xy, s, len, 90, &k)) || k == 0) continue;
      ring_ctx_t probe = {a, NULL, 0, 0, 0};
      ring_lonlat(&probe, in->xy, s, len, 90, &k);
      if (fabs(probe.area2) * 0.5 > 0.5 * 360 * 180) {
        out->n = first;
        st = ring_lonlat(&c, in->xy, s, len, -90, &k);
      }
    }
  }
  if (st) {
    qk__pieces_free(a, out);
    if (st == QK_ERR_NOMEM)
      qk__region_fail(err, st, SIZE_MAX, "out of memory");
    else
      qk__region_fail(err, st, SIZE_MAX, "too many edges");
  }
  return st;
}
