/*
 * Test plan: point location on the real layers against a brute force of our own.
 * countries-50m.geojson and us-states-10m.geojson (../shared/data) are read twice: by the
 * library (qk_region_read_geojson, lon/lat and planar modes) and here, independently,
 * with json-c. The oracle tests every feature by even-odd ray crossings over all its
 * rings, with exact orientation signs (a double filter, then GMP rationals), and the three
 * boundary rules of docs/region.md:
 *  - semi-open: the point moved by (e, e^2); for the ray towards +x that is the half-open
 *    crossing rule (an edge counts when lower.y <= p.y < upper.y) with a strictly positive
 *    orientation (lower, upper, p): a point on an edge that is not horizontal is right of
 *    it after the move;
 *  - closed / open: a point on an edge of a feature is in / out of it.
 * Lon/lat mode: an edge whose longitudes differ by more than 180 degrees goes the short
 * way, so each ring is unwrapped into one closed curve of the plane (longitudes may leave
 * [-180, 180]); a query longitude is taken modulo 360 into [-180, 180) (180 is -180: the
 * point moved east) and tested at its copies 360 k apart; parity adds up over the copies.
 * A point on edges along the antimeridian and no other is on the boundary (closed, open)
 * only where the feature holds one side of it: the parities of the point moved east and
 * moved west differ (Fiji's rings meet there).
 * A ring that does not close after unwrapping winds round a pole (Antarctica's): it is
 * closed along the pole's latitude (docs/region.md, rule 3), edges that are no boundary.
 * Points: the cities (cities.csv), uniform random points in each layer's box, every
 * vertex of every ring (vertices of shared borders in the US states) and the double
 * midpoint of every edge (often exactly on it), and a cross of points 1 ulp around
 * sampled vertices, and the same vertices 360 degrees east and west (lon/lat). locate() must give
 * the oracle's lowest feature and locate_all() its whole set; locate_batch() (one and two
 * threads) the same answers as locate(). Sampled in the default run
 * (QK_SWEEP_ALL=1: every point). Skipped without the data (QK_SHARED_DIR), json-c or GMP.
 */
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "qk_test.h"

#if defined(QK_HAVE_JSONC) && defined(QK_HAVE_GMP)
#include <gmp.h>
#include <json-c/json.h>
#define SW_ON 1
#else
#define SW_ON 0
#endif

#if SW_ON
/* One feature: its edges (x0, y0, x1, y1) in bands of y for speed. */
typedef struct sw_feature {
  double *e; /* 5 per edge: x0, y0, x1, y1, 1 (0 for a closure along a pole: no boundary) */
  size_t ne, cap;
  double box[4]; /* xmin, ymin, xmax, ymax */
  int skip;      /* a ring winding round a pole: not compared */
  size_t nb;     /* bands */
  size_t *band_start;
  uint32_t *band_edge;
} sw_feature_t;

typedef struct sw_layer {
  sw_feature_t *f;
  size_t nf;
  int lonlat;
} sw_layer_t;

static void add_edge(sw_feature_t *f, double x0, double y0, double x1, double y1, int real) {
  if (f->ne == f->cap) {
    f->cap = f->cap ? 2 * f->cap : 64;
    f->e = realloc(f->e, f->cap * 5 * sizeof *f->e);
    assert_non_null(f->e);
  }
  double *e = &f->e[5 * f->ne++];
  e[0] = x0, e[1] = y0, e[2] = x1, e[3] = y1, e[4] = real;
  f->box[0] = fmin(f->box[0], fmin(x0, x1)), f->box[1] = fmin(f->box[1], fmin(y0, y1));
  f->box[2] = fmax(f->box[2], fmax(x0, x1)), f->box[3] = fmax(f->box[3], fmax(y0, y1));
}

static void add_ring(sw_feature_t *f, json_object *ring, int lonlat) {
  size_t n = json_object_array_length(ring);
  if (n < 2) return;
  double px = 0, py = 0, fx = 0, fy = 0; /* previous (unwrapped), first (as given) */
  double ysum = 0;
  for (size_t i = 0; i < n; i++) {
    json_object *c = json_object_array_get_idx(ring, i);
    double x = json_object_get_double(json_object_array_get_idx(c, 0));
    double y = json_object_get_double(json_object_array_get_idx(c, 1));
    if (i == 0) {
      px = fx = x, py = fy = y;
      continue;
    }
    if (lonlat) { /* the short way: the copy of x nearest the previous longitude */
      double k = 0, d = x - px;
      while (d > 180) d -= 360, k -= 360;
      while (d < -180) d += 360, k += 360;
      x += k;
    }
    add_edge(f, px, py, x, y, 1);
    ysum += y;
    px = x, py = y;
  }
  /* GeoJSON rings repeat their first point. Unwrapped, a ring round a pole comes back to
   * it 360 k degrees away; as in docs/region.md (rule 3) it is closed along the pole's
   * latitude on its side (here: the side of its mean latitude), and those edges are no
   * boundary for the closed and open rules. */
  if (px != fx || py != fy) {
    if (lonlat && py == fy && fmod(px - fx, 360.0) == 0) {
      double pole = ysum < 0 ? -90 : 90;
      if (fabs(px - fx) != 360) f->skip = 1; /* winds more than once: not compared */
      add_edge(f, px, py, px, pole, 0);
      add_edge(f, px, pole, fx, pole, 0);
      add_edge(f, fx, pole, fx, fy, 0);
      return;
    }
    add_edge(f, px, py, fx, fy, 1); /* a ring left open: close it */
  }
}

static void build_bands(sw_feature_t *f) {
  if (!f->ne) return;
  f->nb = f->ne / 4 + 1;
  if (f->nb > 4096) f->nb = 4096;
  double y0 = f->box[1], h = (f->box[3] - f->box[1]) / (double)f->nb;
  if (!(h > 0)) f->nb = 1, h = 1;
  size_t *cnt = calloc(f->nb + 1, sizeof *cnt);
  assert_non_null(cnt);
  for (int pass = 0; pass < 2; pass++) {
    for (size_t i = 0; i < f->ne; i++) {
      double *e = &f->e[5 * i];
      double lo = fmin(e[1], e[3]), hi = fmax(e[1], e[3]);
      size_t b0 = (size_t)fmax(0, floor((lo - y0) / h) - 1);
      size_t b1 = (size_t)fmin((double)f->nb - 1, floor((hi - y0) / h) + 1);
      for (size_t b = b0; b <= b1 && b < f->nb; b++)
        if (pass == 0)
          cnt[b + 1]++;
        else
          f->band_edge[cnt[b]++] = (uint32_t)i;
    }
    if (pass == 0) {
      for (size_t b = 0; b < f->nb; b++) cnt[b + 1] += cnt[b];
      f->band_start = malloc((f->nb + 1) * sizeof *f->band_start);
      f->band_edge = malloc((cnt[f->nb] + 1) * sizeof *f->band_edge);
      assert_true(f->band_start && f->band_edge);
      memcpy(f->band_start, cnt, (f->nb + 1) * sizeof *cnt);
    }
  }
  free(cnt);
}

static int load_layer(const char *path, int lonlat, sw_layer_t *L) {
  json_object *root = json_object_from_file(path);
  if (!root) return 0;
  json_object *feats = json_object_object_get(root, "features");
  L->nf = json_object_array_length(feats);
  L->f = calloc(L->nf, sizeof *L->f);
  L->lonlat = lonlat;
  for (size_t i = 0; i < L->nf; i++) {
    sw_feature_t *f = &L->f[i];
    f->box[0] = f->box[1] = INFINITY, f->box[2] = f->box[3] = -INFINITY;
    json_object *g = json_object_object_get(json_object_array_get_idx(feats, i), "geometry");
    if (!g || json_object_get_type(g) != json_type_object) continue;
    const char *type = json_object_get_string(json_object_object_get(g, "type"));
    json_object *co = json_object_object_get(g, "coordinates");
    if (!strcmp(type, "Polygon")) {
      for (size_t r = 0; r < json_object_array_length(co); r++)
        add_ring(f, json_object_array_get_idx(co, r), lonlat);
    } else if (!strcmp(type, "MultiPolygon")) {
      for (size_t p = 0; p < json_object_array_length(co); p++) {
        json_object *poly = json_object_array_get_idx(co, p);
        for (size_t r = 0; r < json_object_array_length(poly); r++)
          add_ring(f, json_object_array_get_idx(poly, r), lonlat);
      }
    }
    build_bands(f);
  }
  json_object_put(root);
  return 1;
}

static void free_layer(sw_layer_t *L) {
  for (size_t i = 0; i < L->nf; i++)
    free(L->f[i].e), free(L->f[i].band_start), free(L->f[i].band_edge);
  free(L->f);
}

/* Exact sign of (b - a) x (p - a). */
static int orient(const double *a, const double *b, double px, double py) {
  double l = (b[0] - a[0]) * (py - a[1]), r = (b[1] - a[1]) * (px - a[0]);
  double det = l - r, bound = 1e-14 * (fabs(l) + fabs(r));
  if (det > bound) return 1;
  if (-det > bound) return -1;
  mpq_t q[6];
  for (int i = 0; i < 6; i++) mpq_init(q[i]);
  mpq_set_d(q[0], b[0]), mpq_set_d(q[1], a[0]), mpq_sub(q[0], q[0], q[1]); /* bx - ax */
  mpq_set_d(q[2], py), mpq_set_d(q[1], a[1]), mpq_sub(q[2], q[2], q[1]);   /* py - ay */
  mpq_mul(q[0], q[0], q[2]);
  mpq_set_d(q[3], b[1]), mpq_set_d(q[1], a[1]), mpq_sub(q[3], q[3], q[1]); /* by - ay */
  mpq_set_d(q[4], px), mpq_set_d(q[1], a[0]), mpq_sub(q[4], q[4], q[1]);   /* px - ax */
  mpq_mul(q[3], q[3], q[4]);
  int s = mpq_cmp(q[0], q[3]);
  for (int i = 0; i < 6; i++) mpq_clear(q[i]);
  return (s > 0) - (s < 0);
}

/* An edge along the antimeridian (lon/lat: longitude 180 + 360 k at both ends). */
static int on_meridian(const double *e) {
  return e[0] == e[2] && fabs(remainder(e[0], 360)) == 180;
}

/* Parity of crossings (semi-open rule: the point moved east) and of the point moved west
 * instead (an edge through it then counts), and whether (x, y) lies on an edge: *on_m for
 * an edge along the antimeridian (lon/lat), else *on. */
static void test_one(const sw_feature_t *f, int lonlat, double x, double y, int *parity,
                     int *parity_w, int *on, int *on_m) {
  if (x < f->box[0] || x > f->box[2] || y < f->box[1] || y > f->box[3] || !f->ne) {
    /* a point outside the box: no crossing to its right is possible only when it is right
     * of the box; left of it, crossings may still happen */
    if (!(y >= f->box[1] && y <= f->box[3] && x < f->box[0])) return;
  }
  double h = (f->box[3] - f->box[1]) / (double)f->nb;
  size_t b = h > 0 ? (size_t)fmin((double)f->nb - 1, fmax(0, floor((y - f->box[1]) / h))) : 0;
  for (size_t k = f->band_start[b]; k < f->band_start[b + 1]; k++) {
    const double *e = &f->e[5 * f->band_edge[k]];
    const double *lo = e, *hi = e + 2;
    if (lo[1] > hi[1]) lo = e + 2, hi = e;
    if (y < lo[1] || y > hi[1]) continue;
    if (x > fmax(lo[0], hi[0])) continue;
    int s = orient(lo, hi, x, y);
    if (s == 0 && x >= fmin(lo[0], hi[0]) && e[4] != 0) /* on the edge (closed segment) */
      *(lonlat && on_meridian(e) ? on_m : on) = 1;
    if (lo[1] <= y && y < hi[1] && s > 0) *parity ^= 1;
    if (lo[1] <= y && y < hi[1] && s >= 0) *parity_w ^= 1;
  }
}

/* The oracle: every feature holding (x, y) under rule, into out (count returned). */
static size_t oracle(const sw_layer_t *L, double x, double y, qk_boundary_t rule, uint32_t *out,
                     int *skipped) {
  size_t n = 0;
  *skipped = 0;
  if (L->lonlat) {
    if (y < -90 || y > 90) return 0;
    x = fmod(x, 360.0);
    if (x >= 180) x -= 360;
    if (x < -180) x += 360;
  }
  for (size_t i = 0; i < L->nf; i++) {
    const sw_feature_t *f = &L->f[i];
    if (!f->ne) continue;
    if (f->skip) { /* a polar ring: no point in its latitudes is compared */
      if (y >= f->box[1] && y <= f->box[3]) *skipped = 1;
      continue;
    }
    int parity = 0, parity_w = 0, on = 0, on_m = 0;
    for (int k = L->lonlat ? -2 : 0; k <= (L->lonlat ? 2 : 0); k++)
      test_one(f, L->lonlat, x + 360.0 * k, y, &parity, &parity_w, &on, &on_m);
    /* A point on the antimeridian that only edges along it pass through is on the sphere's
     * boundary when the feature holds one side of it only (docs/region.md, rule 5: an island
     * given as two rings meeting there holds it under open). */
    if (on_m && parity != parity_w) on = 1;
    int in = rule == QK_BOUNDARY_SEMI_OPEN ? parity
             : rule == QK_BOUNDARY_CLOSED  ? (on || parity)
                                           : (!on && parity);
    if (in) out[n++] = (uint32_t)i;
  }
  return n;
}

typedef struct sw_tally {
  size_t points, compared, skipped, mismatches;
  qk_point_t *pts;    /* every point checked, for the batch calls */
  uint32_t *first[3]; /* locate()'s answers, per rule */
  size_t cap;
} sw_tally_t;

static void check_point(const qk_region_t *R, const sw_layer_t *L, double x, double y,
                        const char *what, sw_tally_t *t) {
  static const qk_boundary_t rules[3] = {QK_BOUNDARY_SEMI_OPEN, QK_BOUNDARY_CLOSED,
                                         QK_BOUNDARY_OPEN};
  static const char *const names[3] = {"semi-open", "closed", "open"};
  if (t->points == t->cap) {
    t->cap = t->cap ? 2 * t->cap : 4096;
    t->pts = realloc(t->pts, t->cap * sizeof *t->pts);
    for (int r = 0; r < 3; r++) t->first[r] = realloc(t->first[r], t->cap * sizeof *t->first[r]);
    assert_true(t->pts && t->first[0] && t->first[1] && t->first[2]);
  }
  t->pts[t->points] = (qk_point_t){x, y};
  for (int r = 0; r < 3; r++)
    assert_int_equal(qk_region_locate(R, (qk_point_t){x, y}, rules[r], &t->first[r][t->points]),
                     QK_OK);
  t->points++;
  for (int r = 0; r < 3; r++) {
    uint32_t want[64], got[64];
    int skipped;
    size_t nw = oracle(L, x, y, rules[r], want, &skipped);
    if (skipped) {
      t->skipped++;
      continue;
    }
    size_t ng = 0;
    assert_int_equal(qk_region_locate_all(R, (qk_point_t){x, y}, rules[r], got, 64, &ng), QK_OK);
    uint32_t one;
    assert_int_equal(qk_region_locate(R, (qk_point_t){x, y}, rules[r], &one), QK_OK);
    t->compared++;
    int bad = ng != nw || (nw ? one != want[0] : one != QK_NONE);
    for (size_t i = 0; !bad && i < nw; i++) bad = got[i] != want[i];
    if (bad) {
      if (t->mismatches++ < 20)
        print_error(
            "%s (%.17g, %.17g) %s %s: library %zu feature(s) first %d, oracle %zu first %d\n", what,
            x, y, L->lonlat ? "lon/lat" : "planar", names[r], ng, ng ? (int)got[0] : -1, nw,
            nw ? (int)want[0] : -1);
    }
  }
}

static const char *data_path(const char *file) {
  static char path[3][1024];
  static int which;
  const char *dir = getenv("QK_SHARED_DIR");
  which = (which + 1) % 3;
  snprintf(path[which], sizeof path[0], "%s/data/%s", dir && *dir ? dir : "../shared", file);
  FILE *f = fopen(path[which], "rb");
  if (!f) return NULL;
  fclose(f);
  return path[which];
}

static void sweep_layer(const char *file, const char *cities, int planar) {
  const char *path = data_path(file);
  int all = getenv("QK_SWEEP_ALL") != NULL;
  sw_layer_t L;
  memset(&L, 0, sizeof L);
  assert_true(load_layer(path, !planar, &L));
  qk_region_options_t o;
  qk_region_options_init(&o);
  o.planar = planar;
  qk_region_t *R = NULL;
  qk_error_t err;
  assert_int_equal(qk_region_read_geojson(path, &o, &R, &err), QK_OK);
  assert_int_equal(qk_region_feature_count(R), L.nf);
  sw_tally_t t;
  memset(&t, 0, sizeof t);
  uint64_t seed = qkt_seed(77);
  qkt_rng_t rng;
  qkt_rng_seed(&rng, seed);
  /* The cities. */
  qk_csv_options_t co;
  qk_csv_options_init(&co);
  co.columns = "lon,lat";
  qk_point_t *pts = NULL;
  size_t n = 0;
  assert_int_equal(qk_points_read_csv(cities, &co, NULL, &pts, &n, &err), QK_OK);
  size_t step = all ? 1 : planar ? 97 : 13;
  for (size_t i = 0; i < n; i += step) check_point(R, &L, pts[i].x, pts[i].y, "city", &t);
  free(pts);
  /* Uniform points in the layer's box. */
  double box[4] = {INFINITY, INFINITY, -INFINITY, -INFINITY};
  for (size_t i = 0; i < L.nf; i++)
    if (L.f[i].ne)
      box[0] = fmin(box[0], L.f[i].box[0]), box[1] = fmin(box[1], L.f[i].box[1]),
      box[2] = fmax(box[2], L.f[i].box[2]), box[3] = fmax(box[3], L.f[i].box[3]);
  if (!planar) box[0] = fmax(box[0], -180), box[2] = fmin(box[2], 180);
  for (int i = 0; i < (all ? 200000 : 3000); i++)
    check_point(R, &L, qkt_rng_range(&rng, box[0], box[2]), qkt_rng_range(&rng, box[1], box[3]),
                "random", &t);
  /* Vertices, edge midpoints and points 1 ulp around vertices. */
  size_t vstep = all ? 1 : planar ? 211 : 37;
  for (size_t i = 0; i < L.nf; i++)
    for (size_t k = qkt_rng_below(&rng, (uint32_t)vstep); k < L.f[i].ne; k += vstep) {
      const double *e = &L.f[i].e[5 * k];
      if (e[4] == 0) continue; /* a closure along a pole */
      check_point(R, &L, e[0], e[1], "vertex", &t);
      check_point(R, &L, e[0] + 0.5 * (e[2] - e[0]), e[1] + 0.5 * (e[3] - e[1]), "midpoint", &t);
      if (k % 8 == 0) {
        check_point(R, &L, nextafter(e[0], INFINITY), e[1], "vertex+ulp x", &t);
        check_point(R, &L, nextafter(e[0], -INFINITY), e[1], "vertex-ulp x", &t);
        check_point(R, &L, e[0], nextafter(e[1], INFINITY), "vertex+ulp y", &t);
        check_point(R, &L, e[0], nextafter(e[1], -INFINITY), "vertex-ulp y", &t);
        if (!planar) { /* the same vertex a turn east and west: longitudes mod 360, exactly */
          check_point(R, &L, e[0] + 360, e[1], "vertex+360", &t);
          check_point(R, &L, e[0] - 360, e[1], "vertex-360", &t);
        }
      }
    }
  print_message("%s (%s): %zu points, %zu answers compared, %zu skipped (a ring winding twice), "
                "%zu mismatches (seed %llu)\n",
                file, planar ? "planar" : "lon/lat", t.points, t.compared, t.skipped, t.mismatches,
                (unsigned long long)seed);
  /* The batch calls (Morton order, chunks, two threads) give locate()'s answers. */
  uint32_t *batch = malloc((t.points + 1) * sizeof *batch);
  assert_non_null(batch);
  static const qk_boundary_t brules[3] = {QK_BOUNDARY_SEMI_OPEN, QK_BOUNDARY_CLOSED,
                                          QK_BOUNDARY_OPEN};
  for (int r = 0; r < 3; r++)
    for (unsigned th = 1; th <= 2; th++) {
      assert_int_equal(qk_region_locate_batch(R, t.pts, t.points, brules[r], th, batch), QK_OK);
      for (size_t i = 0; i < t.points; i++)
        if (batch[i] != t.first[r][i])
          fail_msg("%s: batch (%u threads, rule %d) point (%.17g, %.17g): %d, locate %d", file, th,
                   r, t.pts[i].x, t.pts[i].y, (int)batch[i], (int)t.first[r][i]);
    }
  free(batch), free(t.pts), free(t.first[0]), free(t.first[1]), free(t.first[2]);
  qk_region_free(R);
  free_layer(&L);
  assert_int_equal(t.mismatches, 0);
}
#endif

static void test_sweep_region_layers(void **state) {
  (void)state;
#if SW_ON
  const char *cities = data_path("cities.csv");
  if (!cities || !data_path("countries-50m.geojson") || !data_path("us-states-10m.geojson")) {
    print_message("no shared data under QK_SHARED_DIR: skipped\n");
    skip();
  }
  char cpath[1024];
  snprintf(cpath, sizeof cpath, "%s", cities);
  for (int planar = 0; planar < 2; planar++) {
    sweep_layer("us-states-10m.geojson", cpath, planar);
    sweep_layer("countries-50m.geojson", cpath, planar);
  }
#else
  skip();
#endif
}

/* No data needed: a triangle whose vertex v has many significant bits, queried at v and
 * at v + 360 (the same point on the sphere; v + 360 k for other k is not a double): every boundary
 * rule must answer the same (the reduction modulo 360 used to round: v + 360 missed its own vertex
 * under closed). */
static void test_sweep_region_lon_mod_360(void **state) {
  (void)state;
  const double v[2] = {-174.43074430744306, 67.038136425895516};
  const double xy[8] = {v[0], v[1], -176, 66, -172, 66.5, v[0], v[1]};
  const size_t rs[2] = {0, 4}, fs[2] = {0, 1};
  qk_region_arrays_t in = {xy, rs, 1, fs, 1};
  qk_region_t *R = NULL;
  assert_int_equal(qk_region_from_arrays(&in, NULL, &R, NULL), QK_OK);
  static const qk_boundary_t rules[3] = {QK_BOUNDARY_SEMI_OPEN, QK_BOUNDARY_CLOSED,
                                         QK_BOUNDARY_OPEN};
  for (int r = 0; r < 3; r++) {
    uint32_t want;
    assert_int_equal(qk_region_locate(R, (qk_point_t){v[0], v[1]}, rules[r], &want), QK_OK);
    if (rules[r] == QK_BOUNDARY_CLOSED) assert_int_equal(want, 0);
    if (rules[r] == QK_BOUNDARY_OPEN) assert_int_equal(want, QK_NONE);
    for (int k = -2; k <= 2; k++) {
      double x = v[0] + 360.0 * k;
      if (x - 360.0 * k != v[0]) continue; /* v + 360 k not a double: another point */
      uint32_t got;
      assert_int_equal(qk_region_locate(R, (qk_point_t){x, v[1]}, rules[r], &got), QK_OK);
      if (got != want)
        fail_msg("rule %d: lon %.17g answered %u, lon %.17g %u", r, x, got, v[0], want);
    }
  }
  qk_region_free(R);
}

int main(void) {
  const struct CMUnitTest tests[] = {
      cmocka_unit_test(test_sweep_region_lon_mod_360),
      cmocka_unit_test(test_sweep_region_layers),
  };
  return cmocka_run_group_tests(tests, NULL, NULL);
}
