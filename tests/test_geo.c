/*
 * Test plan for the geodesic queries (query/geo.c):
 *  - kNN and radius by geodesic distance on WGS84 against geod_inverse on every point,
 *    for points spread over the globe, clustered at the antimeridian and at both poles,
 *    with queries there too (lon +-180, lat +-90), at several capacities and k;
 *  - longitudes outside [-180, 180] are normalised; lat outside [-90, 90] and NaN fail;
 *  - the real cities set when present (kNN and a 50 km radius);
 *  - without geodesic support every call returns QK_ERR_UNSUPPORTED.
 */
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "qk_test.h"
#include "query_oracle.h"

static uint64_t g_seed;

#if defined(QK_HAVE_GEODESIC)
#include <geodesic.h>

/* Every geod_inverse of this program, the library's included, goes through here (linked
 * with -Wl,--wrap=geod_inverse: tests/CMakeLists.txt), so a test can count the geodesics
 * a query measures. */
void __real_geod_inverse(const struct geod_geodesic *g, double lat1, double lon1, double lat2,
                         double lon2, double *ps12, double *pazi1, double *pazi2);
void __wrap_geod_inverse(const struct geod_geodesic *g, double lat1, double lon1, double lat2,
                         double lon2, double *ps12, double *pazi1, double *pazi2);
static _Atomic size_t g_inverses; /* (atomic: the batch tests run threads) */
void __wrap_geod_inverse(const struct geod_geodesic *g, double lat1, double lon1, double lat2,
                         double lon2, double *ps12, double *pazi1, double *pazi2) {
  g_inverses++;
  __real_geod_inverse(g, lat1, lon1, lat2, lon2, ps12, pazi1, pazi2);
}

/* The oracle: geod_inverse on every point, sorted by (metres, id). */
static size_t geo_brute(const qk_point_t *p, size_t n, qk_point_t q, double lim, size_t k,
                        qk_neighbor_t *out) {
  struct geod_geodesic g;
  geod_init(&g, 6378137, 1 / 298.257223563);
  qk_neighbor_t *all = malloc((n ? n : 1) * sizeof *all);
  size_t m = 0;
  for (size_t i = 0; i < n; i++) {
    double s12;
    geod_inverse(&g, q.y, remainder(q.x, 360.0), p[i].y, remainder(p[i].x, 360.0), &s12, NULL,
                 NULL);
    if (s12 <= lim) {
      all[m].id = (qk_id_t)i;
      all[m++].dist = s12;
    }
  }
  qko_sort_by_dist(all, m);
  if (m > k) m = k;
  memcpy(out, all, m * sizeof *out);
  free(all);
  return m;
}

static void assert_same(const qk_neighbor_t *a, size_t na, const qk_neighbor_t *b, size_t nb,
                        const char *what, size_t qi, qk_point_t q) {
  if (na != nb)
    fail_msg("%s query %zu (%.17g, %.17g): %zu results, oracle %zu (seed %llu)", what, qi, q.x, q.y,
             na, nb, (unsigned long long)g_seed);
  for (size_t i = 0; i < na; i++)
    if (a[i].id != b[i].id || a[i].dist != b[i].dist)
      fail_msg("%s query %zu rank %zu: (%u, %.17g) vs oracle (%u, %.17g) (seed %llu)", what, qi, i,
               a[i].id, a[i].dist, b[i].id, b[i].dist, (unsigned long long)g_seed);
}

/* A location: uniform on the sphere, or near the antimeridian, or near a pole. */
static qk_point_t geo_loc(qkt_rng_t *r, int kind) {
  qk_point_t p;
  switch (kind) {
  case 0:
    p.x = qkt_rng_range(r, -180, 180);
    p.y = asin(qkt_rng_range(r, -1, 1)) * 57.29577951308232;
    break;
  case 1: /* within a degree of the antimeridian, on either side */
    p.x = qkt_rng_below(r, 2) ? qkt_rng_range(r, 179, 180) : qkt_rng_range(r, -180, -179);
    p.y = qkt_rng_range(r, -60, 60);
    break;
  case 2: /* within two degrees of a pole */
    p.x = qkt_rng_range(r, -180, 180);
    p.y = qkt_rng_below(r, 2) ? qkt_rng_range(r, 88, 90) : qkt_rng_range(r, -90, -88);
    break;
  default: /* exact special values */
  {
    static const double lons[] = {-180, 180, 0, 90, -90};
    static const double lats[] = {90, -90, 0, 45, -45};
    p.x = lons[qkt_rng_below(r, 5)];
    p.y = lats[qkt_rng_below(r, 5)];
  }
  }
  return p;
}

static void test_geo_knn_radius(void **state) {
  (void)state;
  qkt_rng_t r;
  qkt_rng_seed(&r, g_seed);
  const size_t n = 2000;
  const uint32_t caps[] = {1, 8, 64};
  const size_t ks[] = {1, 5, 40};
  qk_point_t *p = malloc(n * sizeof *p);
  qk_neighbor_t *got = malloc(n * sizeof *got), *want = malloc(n * sizeof *want);
  for (int set = 0; set < 3; set++)
    for (int ci = 0; ci < 3; ci++) {
      for (size_t i = 0; i < n; i++) p[i] = geo_loc(&r, set == 0 ? 0 : (int)(i % 4));
      qk_tree_options_t o;
      qk_tree_options_init(&o);
      o.capacity = caps[ci];
      qk_geo_t *g = NULL;
      assert_int_equal(qk_geo_build(p, n, &o, &g), QK_OK);
      QKT_CHECK_TREE(qk_geo_tree(g));
      for (size_t qi = 0; qi < 60; qi++) {
        qk_point_t q = qi % 7 == 0 ? p[qkt_rng_below(&r, (uint32_t)n)] : geo_loc(&r, (int)(qi % 4));
        size_t k = ks[qi % 3], ng;
        double cap = qi % 5 == 0 ? 500e3 : INFINITY;
        assert_int_equal(qk_geo_knn(g, q, k, cap, got, &ng), QK_OK);
        size_t nw = geo_brute(p, n, q, cap, k, want);
        assert_same(got, ng, want, nw, "geo-knn", qi, q);

        double metres = qi % 4 == 0 ? 0 : qkt_rng_range(&r, 0, 3e6);
        assert_int_equal(qk_geo_radius_list(g, q, metres, got, n, &ng), QK_OK);
        nw = geo_brute(p, n, q, metres, n, want);
        assert_same(got, ng, want, nw, "geo-radius", qi, q);
      }
      /* Half the globe and the whole globe. */
      size_t ng;
      qk_point_t q = {-179.5, 89.9};
      assert_int_equal(qk_geo_radius_list(g, q, 2.1e7, got, n, &ng), QK_OK);
      assert_same(got, ng, want, geo_brute(p, n, q, 2.1e7, n, want), "geo-radius-big", 0, q);
      assert_int_equal(qk_geo_knn(g, q, n, INFINITY, got, &ng), QK_OK);
      assert_int_equal(ng, n);
      assert_same(got, ng, want, geo_brute(p, n, q, INFINITY, n, want), "geo-knn-all", 0, q);
      qk_geo_free(g);
    }
  free(p), free(got), free(want);
}

/* Places at one position (a city's centre standing for the addresses geocoded to it):
 * they share a leaf and a distance, and ties are kept by id, so none can be pruned; each
 * was measured, and 100,000 of them made a query 130 ms (a QA helper's). The answers
 * against the oracle, and the geodesics a query measures: one for the run, a few hundred
 * for the rest, where there were at least as many as the places at the point. */
static void test_geo_places_at_one_point(void **state) {
  (void)state;
  qkt_rng_t r;
  qkt_rng_seed(&r, g_seed);
  const size_t n = 6000, at_one = 5000;
  qk_point_t *p = malloc(n * sizeof *p);
  qk_neighbor_t *got = malloc(n * sizeof *got), *want = malloc(n * sizeof *want);
  const qk_point_t paris = {2.3522, 48.8566};
  for (size_t i = 0; i < n; i++) /* the point's places spread among the others' ids */
    p[i] = i % 6 ? paris : (qk_point_t){qkt_rng_range(&r, -2, 7), qkt_rng_range(&r, 45, 52)};
  qk_geo_t *g = NULL;
  assert_int_equal(qk_geo_build(p, n, NULL, &g), QK_OK);
  assert_int_equal(at_one, n - (n + 5) / 6);
  for (size_t qi = 0; qi < 12; qi++) {
    qk_point_t q = {paris.x + qkt_rng_range(&r, -0.5, 0.5), paris.y + qkt_rng_range(&r, -0.5, 0.5)};
    if (qi == 0) q = paris;
    size_t k = qi % 3 == 0 ? 1 : 10, ng;
    g_inverses = 0;
    assert_int_equal(qk_geo_knn(g, q, k, INFINITY, got, &ng), QK_OK);
    size_t used = g_inverses;
    assert_same(got, ng, want, geo_brute(p, n, q, INFINITY, k, want), "geo-knn-dups", qi, q);
    if (used > 400)
      fail_msg("query %zu: %zu geodesics measured for k = %zu (seed %llu)", qi, used, k,
               (unsigned long long)g_seed);
    double metres = qkt_rng_range(&r, 1e3, 60e3);
    g_inverses = 0;
    assert_int_equal(qk_geo_radius_list(g, q, metres, got, n, &ng), QK_OK);
    used = g_inverses;
    assert_same(got, ng, want, geo_brute(p, n, q, metres, n, want), "geo-radius-dups", qi, q);
    if (used > 400)
      fail_msg("query %zu: %zu geodesics measured within %g m (seed %llu)", qi, used, metres,
               (unsigned long long)g_seed);
  }
  qk_geo_free(g);
  free(p), free(got), free(want);
}

static void test_geo_normalise_and_errors(void **state) {
  (void)state;
  qk_point_t p[3] = {{190, 10}, {-170, 10.5}, {540, 0}};
  qk_geo_t *g = NULL;
  assert_int_equal(qk_geo_build(p, 3, NULL, &g), QK_OK);
  qk_neighbor_t nb[3];
  size_t n;
  /* 190 is -170; 540 is 180 (the same meridian as -180). */
  assert_int_equal(qk_geo_knn(g, (qk_point_t){-170, 10}, 3, INFINITY, nb, &n), QK_OK);
  assert_int_equal(n, 3);
  assert_int_equal(nb[0].id, 0);
  assert_true(nb[0].dist == 0.0);
  assert_int_equal(nb[1].id, 1);
  double d;
  assert_int_equal(qk_geo_distance((qk_point_t){180, 0}, (qk_point_t){-180, 0}, &d), QK_OK);
  assert_true(d == 0.0);
  /* One degree of longitude across the antimeridian on the equator: a * pi / 180. */
  assert_int_equal(qk_geo_distance((qk_point_t){179.5, 0}, (qk_point_t){-179.5, 0}, &d), QK_OK);
  assert_true(fabs(d - 6378137.0 * 3.14159265358979323846 / 180) < 1e-6);
  assert_int_equal(qk_geo_knn(g, (qk_point_t){0, 91}, 1, INFINITY, nb, &n), QK_ERR_OUTSIDE);
  assert_int_equal(qk_geo_knn(g, (qk_point_t){NAN, 0}, 1, INFINITY, nb, &n), QK_ERR_NONFINITE);
  assert_int_equal(qk_geo_knn(g, (qk_point_t){0, 0}, 1, -5, nb, &n), QK_ERR_INVALID);
  assert_int_equal(qk_geo_radius_list(g, (qk_point_t){0, 0}, -1, nb, 3, &n), QK_ERR_INVALID);
  qk_geo_free(g);
  qk_point_t bad = {0, -90.5};
  assert_int_equal(qk_geo_build(&bad, 1, NULL, &g), QK_ERR_OUTSIDE);
  assert_null(g);
  bad.y = INFINITY;
  assert_int_equal(qk_geo_build(&bad, 1, NULL, &g), QK_ERR_NONFINITE);
  /* Batch form equals single queries. */
  qk_point_t qs[2] = {{0, 0}, {NAN, 0}};
  qk_neighbor_t out[4];
  size_t counts[2];
  assert_int_equal(qk_geo_build(p, 3, NULL, &g), QK_OK);
  assert_int_equal(qk_geo_knn_batch(g, qs, 2, 2, INFINITY, out, counts), QK_ERR_NONFINITE);
  assert_int_equal(counts[0], 2);
  assert_int_equal(counts[1], 0);
  assert_int_equal(out[2].id, QK_NONE);
  assert_int_equal(qk_geo_knn(g, qs[0], 2, INFINITY, nb, &n), QK_OK);
  assert_int_equal(nb[0].id, out[0].id);
  assert_int_equal(nb[1].id, out[1].id);
  qk_geo_free(g);
  qk_geo_free(NULL);
  /* An empty index answers with nothing. */
  assert_int_equal(qk_geo_build(NULL, 0, NULL, &g), QK_OK);
  assert_int_equal(qk_geo_knn(g, (qk_point_t){0, 0}, 3, INFINITY, nb, &n), QK_OK);
  assert_int_equal(n, 0);
  assert_int_equal(qk_geo_radius_list(g, (qk_point_t){0, 0}, 1e7, nb, 3, &n), QK_OK);
  assert_int_equal(n, 0);
  qk_geo_free(g);
}

/* The batch form (large enough to be reordered) equals single queries. */
static void test_geo_batch(void **state) {
  (void)state;
  qkt_rng_t r;
  qkt_rng_seed(&r, g_seed + 3);
  const size_t n = 3000, nq = 150, k = 4;
  qk_point_t *p = malloc(n * sizeof *p), *qs = malloc(nq * sizeof *qs);
  for (size_t i = 0; i < n; i++) p[i] = geo_loc(&r, (int)(i % 3));
  for (size_t i = 0; i < nq; i++) qs[i] = geo_loc(&r, (int)(i % 4));
  qs[5].x = 400; /* longitudes outside [-180, 180] are normalised */
  qs[9].y = NAN;
  qk_geo_t *g = NULL;
  assert_int_equal(qk_geo_build(p, n, NULL, &g), QK_OK);
  qk_neighbor_t *out = malloc(nq * k * sizeof *out), one[4];
  size_t counts[150];
  assert_int_equal(qk_geo_knn_batch(g, qs, nq, k, INFINITY, out, counts), QK_ERR_NONFINITE);
  for (size_t i = 0; i < nq; i++) {
    size_t m = 0;
    if (i == 9) {
      assert_int_equal(counts[i], 0);
      continue;
    }
    assert_int_equal(qk_geo_knn(g, qs[i], k, INFINITY, one, &m), QK_OK);
    assert_same(out + i * k, counts[i], one, m, "geo-batch", i, qs[i]);
  }
  qk_geo_free(g);
  free(p), free(qs), free(out);
}

static void test_geo_nomem(void **state) {
  (void)state;
  qkt_rng_t r;
  qkt_rng_seed(&r, g_seed + 2);
  qk_point_t p[500];
  for (size_t i = 0; i < 500; i++) p[i] = geo_loc(&r, (int)(i % 4));
  for (size_t fail_at = 1;; fail_at++) {
    qkt_alloc_t st;
    qk_allocator_t a = qkt_alloc_make(&st);
    st.fail_at = fail_at;
    qk_tree_options_t o;
    qk_tree_options_init(&o);
    o.capacity = 4;
    o.allocator = &a;
    qk_geo_t *g = NULL;
    qk_status_t s = qk_geo_build(p, 500, &o, &g);
    if (s == QK_OK) {
      qk_neighbor_t nb[3];
      size_t n;
      assert_int_equal(qk_geo_knn(g, p[0], 3, INFINITY, nb, &n), QK_OK);
      assert_int_equal(n, 3);
      qk_geo_free(g);
      assert_int_equal(st.live_blocks, 0);
      assert_true(fail_at > 3);
      break;
    }
    assert_int_equal(s, QK_ERR_NOMEM);
    assert_null(g);
    assert_int_equal(st.live_blocks, 0);
    assert_true(fail_at < 1000);
  }
}

static void test_geo_cities(void **state) {
  (void)state;
  size_t n;
  qk_point_t *p = qko_load_cities(&n);
  if (!p) {
    print_message("cities.csv not found: skipping the real-data test\n");
    skip();
  }
  qkt_rng_t r;
  qkt_rng_seed(&r, g_seed + 1);
  qk_geo_t *g = NULL;
  assert_int_equal(qk_geo_build(p, n, NULL, &g), QK_OK);
  qk_neighbor_t got[10], want[10];
  qk_neighbor_t *gr = malloc(n * sizeof *gr), *wr = malloc(n * sizeof *wr);
  for (size_t qi = 0; qi < 12; qi++) {
    qk_point_t q = qi % 2 ? p[qkt_rng_below(&r, (uint32_t)n)] : geo_loc(&r, (int)(qi % 4));
    size_t ng, nw = geo_brute(p, n, q, INFINITY, 10, want);
    assert_int_equal(qk_geo_knn(g, q, 10, INFINITY, got, &ng), QK_OK);
    assert_same(got, ng, want, nw, "cities-geo-knn", qi, q);
    nw = geo_brute(p, n, q, 50e3, n, wr);
    assert_int_equal(qk_geo_radius_list(g, q, 50e3, gr, n, &ng), QK_OK);
    assert_same(gr, ng, wr, nw, "cities-geo-radius", qi, q);
  }
  qk_geo_free(g);
  free(p), free(gr), free(wr);
}

#else

static void test_geo_unsupported(void **state) {
  (void)state;
  qk_point_t p = {0, 0};
  qk_geo_t *g = (qk_geo_t *)&p;
  assert_int_equal(qk_geo_build(&p, 1, NULL, &g), QK_ERR_UNSUPPORTED);
  assert_null(g);
  double d;
  assert_int_equal(qk_geo_distance(p, p, &d), QK_ERR_UNSUPPORTED);
}

#endif

int main(void) {
  g_seed = qkt_seed(4242);
  const struct CMUnitTest tests[] = {
#if defined(QK_HAVE_GEODESIC)
    cmocka_unit_test(test_geo_knn_radius),
    cmocka_unit_test(test_geo_normalise_and_errors),
    cmocka_unit_test(test_geo_places_at_one_point),
    cmocka_unit_test(test_geo_nomem),
    cmocka_unit_test(test_geo_batch),
    cmocka_unit_test(test_geo_cities),
#else
    cmocka_unit_test(test_geo_unsupported),
#endif
  };
  return cmocka_run_group_tests(tests, NULL, NULL);
}
