/*
 * Geodesic queries on WGS84. Points are stored in a quadtree over (longitude, latitude)
 * and searched by branch and bound, as the planar queries, with a lower bound on the
 * geodesic distance from the query to anything inside a node's lon/lat rectangle. Exact
 * distances come from GeographicLib's inverse solution (geod_inverse, through PROJ's
 * geodesic.h), computed only for points that survive two bounds:
 *
 * - Radial projection onto the sphere of radius b (the semi-minor axis) is the nearest-
 *   point map onto a convex ball that contains the ellipsoid, hence 1-Lipschitz; a curve
 *   on the ellipsoid therefore is at least as long as its image on that sphere, and a
 *   geodesic between two points is at least b times the angle between their geocentric
 *   directions. That angle is at least the chord between the unit direction vectors.
 * - For a node, the least angle from the query direction to any direction in the
 *   rectangle of geocentric latitudes and longitudes, computed exactly on the sphere
 *   (meridian edges by maximising the cosine along them), minus a margin that covers
 *   the rounding of acos.
 *
 * Both are true lower bounds, so the search is exact; longitudes differences are wrapped,
 * which handles the antimeridian, and a pole needs nothing special because a rectangle
 * touching it is bounded through its meridian edges.
 */
#include <stdlib.h>
#include <string.h>

#include "query/query_internal.h"

#if defined(QK_HAVE_GEODESIC)
#include <geodesic.h>

#define WGS84_A 6378137.0
#define WGS84_F (1 / 298.257223563)
/* Semi-minor axis b = a (1 - f). */
#define WGS84_B (WGS84_A * (1 - WGS84_F))
#define DEG (3.14159265358979323846 / 180.0)
/* Angle margin (radians) for the node bound: acos near 0 and 1 loses up to ~3e-8. */
#define ANGLE_MARGIN 1e-7

struct qk_geo {
  qk_allocator_t alloc;
  qk_tree_t *tree;
  struct geod_geodesic g;
  double *u; /* per id: unit geocentric direction (3 doubles) */
  size_t n;
};

/* Geocentric latitude (radians) of a geodetic latitude (degrees): tan psi = (1-e^2) tan
 * phi, monotone in phi. */
static double geocentric_lat(double lat_deg) {
  const double e2 = WGS84_F * (2 - WGS84_F);
  double phi = lat_deg * DEG;
  return atan2((1 - e2) * sin(phi), cos(phi));
}

static void unit_vector(double lon, double lat, double *u) {
  double psi = geocentric_lat(lat), lam = lon * DEG;
  u[0] = cos(psi) * cos(lam);
  u[1] = cos(psi) * sin(lam);
  u[2] = sin(psi);
}

/* Longitude into [-180, 180]. */
static double norm_lon(double lon) { return remainder(lon, 360.0); }

static qk_status_t check_lonlat(qk_point_t p) {
  if (!isfinite(p.x) || !isfinite(p.y)) return QK_ERR_NONFINITE;
  if (p.y < -90 || p.y > 90) return QK_ERR_OUTSIDE;
  return QK_OK;
}

/* The query, prepared once. */
typedef struct gq {
  double lon, lat;   /* normalised, degrees */
  double psi, lam;   /* geocentric latitude, longitude (radians) */
  double spsi, cpsi; /* their sine and cosine */
  double u[3];
} gq_t;

static void prepare(gq_t *q, qk_point_t p) {
  q->lon = norm_lon(p.x);
  q->lat = p.y;
  q->psi = geocentric_lat(q->lat);
  q->lam = q->lon * DEG;
  q->spsi = sin(q->psi);
  q->cpsi = cos(q->psi);
  unit_vector(q->lon, q->lat, q->u);
}

/* Least angle (radians) from the query to a meridian segment at longitude difference dl
 * (radians, in [0, pi]) spanning geocentric latitudes [p0, p1]. */
static double meridian_angle(const gq_t *q, double dl, double p0, double p1) {
  double A = q->spsi, B = q->cpsi * cos(dl);
  /* cos(angle) along the meridian is A sin(psi) + B cos(psi) = R cos(psi - psi*). */
  double ps = atan2(A, B);
  double best;
  if (ps >= p0 && ps <= p1) {
    best = sqrt(A * A + B * B);
  } else {
    double c0 = A * sin(p0) + B * cos(p0), c1 = A * sin(p1) + B * cos(p1);
    best = c0 > c1 ? c0 : c1;
  }
  if (best > 1) best = 1;
  if (best < -1) best = -1;
  return acos(best);
}

/* Lower bound in metres on the geodesic distance from q to any point of a node. */
static double node_bound(const gq_t *q, const qk_tree_t *t, qk__cell_t c) {
  double s = qk__tree_side(t, c.depth);
  /* Widen by a hair so that rounded cell edges never exclude a stored point. */
  double lon0 = c.x - 1e-9, lon1 = c.x + s + 1e-9;
  double lat0 = c.y - 1e-9, lat1 = c.y + s + 1e-9;
  if (lat0 < -90) lat0 = -90;
  if (lat1 > 90) lat1 = 90;
  if (lat0 > lat1) return INFINITY; /* the part of the root square beyond the pole */
  double p0 = geocentric_lat(lat0), p1 = geocentric_lat(lat1);
  double ang;
  int in_lon = (q->lon >= lon0 && q->lon <= lon1) ||
               (q->lon + 360 >= lon0 && q->lon + 360 <= lon1) ||
               (q->lon - 360 >= lon0 && q->lon - 360 <= lon1) || lon1 - lon0 >= 360;
  if (in_lon) {
    ang = q->psi < p0 ? p0 - q->psi : (q->psi > p1 ? q->psi - p1 : 0.0);
  } else {
    double d0 = fabs(remainder(q->lon - lon0, 360.0)) * DEG;
    double d1 = fabs(remainder(q->lon - lon1, 360.0)) * DEG;
    double a0 = meridian_angle(q, d0, p0, p1), a1 = meridian_angle(q, d1, p0, p1);
    ang = a0 < a1 ? a0 : a1;
  }
  ang -= ANGLE_MARGIN;
  return ang > 0 ? WGS84_B * ang : 0.0;
}

/* Lower bound in metres for one point from its unit vector: b * chord <= b * angle. */
static inline double point_bound(const gq_t *q, const double *u) {
  double dx = u[0] - q->u[0], dy = u[1] - q->u[1], dz = u[2] - q->u[2];
  double lb = WGS84_B * sqrt(dx * dx + dy * dy + dz * dz) * (1 - 1e-12) - 1e-6;
  return lb > 0 ? lb : 0.0;
}

static double geodesic(const struct geod_geodesic *g, const gq_t *q, double lon, double lat) {
  double s12 = 0;
  geod_inverse(g, q->lat, q->lon, lat, lon, &s12, NULL, NULL);
  return s12;
}

qk_status_t qk_geo_build(const qk_point_t *lonlat, size_t n, const qk_tree_options_t *options,
                         qk_geo_t **out) {
  if (!out) return QK_ERR_INVALID;
  *out = NULL;
  if (n > 0 && !lonlat) return QK_ERR_INVALID;
  if (n > QK_MAX_POINTS) return QK_ERR_LIMIT;
  for (size_t i = 0; i < n; i++) {
    qk_status_t st = check_lonlat(lonlat[i]);
    if (st != QK_OK) return st;
  }
  qk_tree_options_t opt;
  qk_tree_options_init(&opt); /* NULL options: the same defaults as everywhere */
  if (options) {
    opt.capacity = options->capacity;
    opt.max_depth = options->max_depth;
    opt.allocator = options->allocator;
    opt.threads = options->threads;
  }
  /* Longitudes in [-180, 180] and latitudes in [-90, 90] fit one square of side 360. */
  opt.has_root = 1;
  opt.root.x = -180;
  opt.root.y = -90;
  opt.root.side = 360;
  qk_allocator_t a = {NULL, NULL};
  if (opt.allocator) a = *opt.allocator;
  qk_geo_t *g = qk__realloc(&a, NULL, 0, sizeof *g);
  if (!g) return QK_ERR_NOMEM;
  memset(g, 0, sizeof *g);
  g->alloc = a;
  g->n = n;
  geod_init(&g->g, WGS84_A, WGS84_F);
  qk_point_t *pts = n ? qk__realloc(&a, NULL, 0, n * sizeof *pts) : NULL;
  g->u = n ? qk__realloc(&a, NULL, 0, 3 * n * sizeof *g->u) : NULL;
  qk_status_t st = QK_OK;
  if (n && (!pts || !g->u)) {
    st = QK_ERR_NOMEM;
    goto done;
  }
  for (size_t i = 0; i < n; i++) {
    pts[i].x = norm_lon(lonlat[i].x);
    pts[i].y = lonlat[i].y;
    unit_vector(pts[i].x, pts[i].y, g->u + 3 * i);
  }
  st = qk_tree_build(pts, n, &opt, &g->tree);
done:
  qk__free(&a, pts, n * sizeof *pts);
  if (st != QK_OK) {
    qk_geo_free(g);
    return st;
  }
  *out = g;
  return QK_OK;
}

void qk_geo_free(qk_geo_t *g) {
  if (!g) return;
  qk_allocator_t a = g->alloc;
  qk_tree_free(g->tree);
  qk__free(&a, g->u, 3 * g->n * sizeof *g->u);
  qk__free(&a, g, sizeof *g);
}

const qk_tree_t *qk_geo_tree(const qk_geo_t *g) { return g ? g->tree : NULL; }

qk_status_t qk_geo_distance(qk_point_t a, qk_point_t b, double *metres) {
  if (!metres) return QK_ERR_INVALID;
  qk_status_t st = check_lonlat(a);
  if (st == QK_OK) st = check_lonlat(b);
  if (st != QK_OK) return st;
  struct geod_geodesic g;
  geod_init(&g, WGS84_A, WGS84_F);
  double s12 = 0;
  geod_inverse(&g, a.y, norm_lon(a.x), b.y, norm_lon(b.x), &s12, NULL, NULL);
  *metres = s12;
  return QK_OK;
}

qk_status_t qk_geo_radius(const qk_geo_t *g, qk_point_t qp, double metres, qk_found_fn fn,
                          void *ud) {
  if (!g || !fn) return QK_ERR_INVALID;
  qk_status_t st = check_lonlat(qp);
  if (st != QK_OK) return st;
  if (isnan(metres) || metres < 0) return QK_ERR_INVALID;
  const qk_tree_t *t = g->tree;
  if (qk__tree_count(t) == 0) return QK_OK;
  const double *xs = qk__tree_xs(t), *ys = qk__tree_ys(t);
  const qk_id_t *ids = qk__tree_ids(t);
  gq_t q;
  prepare(&q, qp);
  qk__cell_t stack[QK__STACK_MAX];
  int sp = 0;
  stack[sp++] = qk__root_cell(t);
  while (sp > 0) {
    const qk__cell_t c = stack[--sp];
    const uint32_t count = qk__node_count(t, c.node);
    if (count == 0 || node_bound(&q, t, c) > metres) continue;
    const uint32_t child = qk__node_child(t, c.node);
    if (child != QK_NONE) {
      qk__cell_t kids[4];
      qk__cell_children(t, c, child, kids);
      for (int k = 3; k >= 0; k--) stack[sp++] = kids[k];
      continue;
    }
    const uint32_t start = qk__node_start(t, c.node);
    double lx = NAN, ly = NAN, d = 0; /* the last point measured (see geo_knn_one) */
    for (uint32_t i = 0; i < count; i++) {
      uint32_t s = start + i;
      qk_id_t id = ids[s];
      if (point_bound(&q, g->u + 3 * (size_t)id) > metres) continue;
      if (xs[s] != lx || ys[s] != ly) d = geodesic(&g->g, &q, lx = xs[s], ly = ys[s]);
      if (d <= metres) {
        qk_point_t p = {xs[s], ys[s]};
        if (fn(id, p, d, ud)) return QK_OK;
      }
    }
  }
  return QK_OK;
}

typedef struct nb_buf {
  qk_neighbor_t *out;
  size_t cap, n;
} nb_buf_t;

static int collect(qk_id_t id, qk_point_t p, double dist, void *ud) {
  nb_buf_t *b = ud;
  (void)p;
  QK__SINK_PUT(b->out, b->cap, b->n, ((qk_neighbor_t){id, dist}));
  return 0;
}

static int nb_cmp(const void *x, const void *y) {
  const qk_neighbor_t *a = x, *b = y;
  if (a->dist != b->dist) return a->dist < b->dist ? -1 : 1;
  return (a->id > b->id) - (a->id < b->id);
}

qk_status_t qk_geo_radius_list(const qk_geo_t *g, qk_point_t q, double metres, qk_neighbor_t *out,
                               size_t cap, size_t *n_out) {
  if (!g || !n_out || (cap > 0 && !out)) return QK_ERR_INVALID;
  nb_buf_t b = {out, cap, 0};
  qk_status_t st = qk_geo_radius(g, q, metres, collect, &b);
  *n_out = b.n;
  if (st == QK_OK && b.n <= cap && b.n > 1) qsort(out, b.n, sizeof *out, nb_cmp);
  return st;
}

/* Geodesic kNN: the planar search of knn.c with metres for squared distances. */
static size_t geo_knn_one(const qk_geo_t *g, const gq_t *q, size_t k, double limit,
                          qk_neighbor_t *h) {
  const qk_tree_t *t = g->tree;
  const size_t np = qk__tree_count(t);
  if (np == 0 || k == 0) return 0;
  if (k > np) k = np;
  const double *xs = qk__tree_xs(t), *ys = qk__tree_ys(t);
  const qk_id_t *ids = qk__tree_ids(t);
  size_t n = 0;
  double thr = limit;
  qk__cell_entry_t stack[QK__STACK_MAX];
  int sp = 0;
  stack[sp].c = qk__root_cell(t);
  stack[sp++].bound = 0;
  while (sp > 0) {
    qk__cell_entry_t top = stack[--sp];
    if (top.bound > thr) continue;
    const uint32_t child = qk__node_child(t, top.c.node);
    if (child == QK_NONE) {
      const uint32_t start = qk__node_start(t, top.c.node);
      const uint32_t count = qk__node_count(t, top.c.node);
      /* Places at one position (a city's centre standing for its addresses) share a leaf
       * and a distance, and ties are kept by id, so none is pruned: the geodesic, the
       * costly part, is measured once for a run of them (100,000 places at one point made
       * a query 130 ms). */
      double lx = NAN, ly = NAN, d = 0;
      for (uint32_t i = 0; i < count; i++) {
        uint32_t s = start + i;
        qk_id_t id = ids[s];
        if (point_bound(q, g->u + 3 * (size_t)id) > thr) continue;
        if (xs[s] != lx || ys[s] != ly) d = geodesic(&g->g, q, lx = xs[s], ly = ys[s]);
        if (d <= thr) qk__heap_offer(h, &n, k, id, d, &thr);
      }
      continue;
    }
    qk__cell_t kc[4];
    qk__cell_children(t, top.c, child, kc);
    qk__cell_entry_t kids[4];
    int m = 0;
    for (uint32_t c = 0; c < 4; c++) {
      if (qk__node_count(t, kc[c].node) == 0) continue;
      double b = node_bound(q, t, kc[c]);
      if (b > thr) continue;
      kids[m].c = kc[c];
      kids[m++].bound = b;
    }
    qk__sort_cells_desc(kids, m);
    for (int i = 0; i < m; i++) stack[sp++] = kids[i];
  }
  qk__heap_sort(h, n);
  return n;
}

qk_status_t qk_geo_knn(const qk_geo_t *g, qk_point_t qp, size_t k, double max_metres,
                       qk_neighbor_t *out, size_t *n_out) {
  if (!g || !n_out || (k > 0 && !out)) return QK_ERR_INVALID;
  *n_out = 0;
  qk_status_t st = check_lonlat(qp);
  if (st != QK_OK) return st;
  if (isnan(max_metres) || max_metres < 0) return QK_ERR_INVALID;
  gq_t q;
  prepare(&q, qp);
  *n_out = geo_knn_one(g, &q, k, max_metres, out);
  return QK_OK;
}

/* One thread's share of a geodesic kNN batch (as the planar one in query/batch.c). */
typedef struct geo_job {
  const qk_geo_t *g;
  const qk_point_t *qs;
  const uint32_t *order;
  size_t nq, k;
  double max_metres;
  qk_neighbor_t *out;
  size_t *counts;
  qk__chunks_t chunks; /* runs of the Z-order, taken by the threads as they go */
  qk__first_err_t err[QK__MAX_THREADS];
} geo_job_t;

static void geo_share(void *ctx, unsigned w, unsigned nw) {
  (void)nw;
  geo_job_t *j = ctx;
  size_t lo, hi;
  qk__first_err_t e = {QK_OK, SIZE_MAX};
  while (qk__chunks_take(&j->chunks, &lo, &hi))
    for (size_t jj = lo; jj < hi; jj++) {
      size_t i = j->order ? j->order[jj] : jj;
      qk_neighbor_t *o = j->out ? j->out + i * j->k : NULL;
      size_t n = 0;
      qk_status_t st = qk_geo_knn(j->g, j->qs[i], j->k, j->max_metres, o, &n);
      qk__note_err(&e, st, i);
      for (size_t m = n; m < j->k; m++) o[m] = (qk_neighbor_t){QK_NONE, INFINITY};
      if (j->counts) j->counts[i] = n;
    }
  j->err[w] = e;
}

qk_status_t qk_geo_knn_batch(const qk_geo_t *g, const qk_point_t *qs, size_t nq, size_t k,
                             double max_metres, qk_neighbor_t *out, size_t *counts) {
  if (!g || (nq > 0 && !qs) || (nq > 0 && k > 0 && !out)) return QK_ERR_INVALID;
  if (isnan(max_metres) || max_metres < 0) return QK_ERR_INVALID;
  /* Z-order of the queries' (raw) lon/lat: consecutive searches then share nodes. */
  uint32_t *order;
  void *block = qk__morton_order(g->tree, qs, nq, &order);
  unsigned nw = qk__batch_threads(g->tree, nq);
  geo_job_t j = {.g = g,
                 .qs = qs,
                 .order = order,
                 .nq = nq,
                 .k = k,
                 .max_metres = max_metres,
                 .out = out,
                 .counts = counts};
  qk__chunks_init(&j.chunks, nq, nw, 64);
  qk__run_shares(nw, geo_share, &j);
  if (block) qk__morton_free(g->tree, block, nq);
  qk__first_err_t e = {QK_OK, SIZE_MAX};
  for (unsigned w = 0; w < nw; w++) qk__note_err(&e, j.err[w].st, j.err[w].i);
  return e.st;
}

#else /* !QK_HAVE_GEODESIC */

qk_status_t qk_geo_build(const qk_point_t *lonlat, size_t n, const qk_tree_options_t *options,
                         qk_geo_t **out) {
  (void)lonlat, (void)n, (void)options;
  if (out) *out = NULL;
  return QK_ERR_UNSUPPORTED;
}
void qk_geo_free(qk_geo_t *g) { (void)g; }
const qk_tree_t *qk_geo_tree(const qk_geo_t *g) {
  (void)g;
  return NULL;
}
qk_status_t qk_geo_distance(qk_point_t a, qk_point_t b, double *metres) {
  (void)a, (void)b, (void)metres;
  return QK_ERR_UNSUPPORTED;
}
qk_status_t qk_geo_radius(const qk_geo_t *g, qk_point_t q, double metres, qk_found_fn fn,
                          void *ud) {
  (void)g, (void)q, (void)metres, (void)fn, (void)ud;
  return QK_ERR_UNSUPPORTED;
}
qk_status_t qk_geo_radius_list(const qk_geo_t *g, qk_point_t q, double metres, qk_neighbor_t *out,
                               size_t cap, size_t *n_out) {
  (void)g, (void)q, (void)metres, (void)out, (void)cap;
  if (n_out) *n_out = 0;
  return QK_ERR_UNSUPPORTED;
}
qk_status_t qk_geo_knn(const qk_geo_t *g, qk_point_t q, size_t k, double max_metres,
                       qk_neighbor_t *out, size_t *n_out) {
  (void)g, (void)q, (void)k, (void)max_metres, (void)out;
  if (n_out) *n_out = 0;
  return QK_ERR_UNSUPPORTED;
}
qk_status_t qk_geo_knn_batch(const qk_geo_t *g, const qk_point_t *qs, size_t nq, size_t k,
                             double max_metres, qk_neighbor_t *out, size_t *counts) {
  (void)g, (void)qs, (void)nq, (void)k, (void)max_metres, (void)out, (void)counts;
  return QK_ERR_UNSUPPORTED;
}

#endif /* QK_HAVE_GEODESIC */
