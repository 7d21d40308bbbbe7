/*
 * Test plan: the general mesher on real borders it was not tuned on. Features of
 * ../shared/data/countries-50m.geojson and us-states-10m.geojson are read the way
 * `quadkit mesh FILE --project equirect --round 2^-4` reads them (tools/mesh_geojson.c:
 * equirectangular at the mean latitude, 1/16 m grid) and meshed in the general mode with
 * the bench's size bounds, extent/64 and extent/256 (extent: the larger side of the
 * projected bounding box). Every mesh goes through the exact rational checker
 * (tests/support/mesh_check_general.c): conforming, input vertices bit-identical, every
 * segment covered exactly, edges within the bound, the kept area equal to the rings'
 * (outer minus holes), every angle >= the proven bound except inside input angles below
 * 60 degrees. A refusal fails the test (these are valid inputs), except Antarctica,
 * whose polar ring has no equirectangular picture (docs/mesh.md, "Meshing lon/lat data").
 *  - test_sweep_mesh_sample: a fixed sample (antimeridian features Fiji and Russia, tiny
 *    islands, many-ring features, states with holes and shared borders) plus every 47th
 *    country and every 11th state, so the run stays short in Release;
 *  - QK_SWEEP_ALL=1: every feature of both files (the full sweep; minutes);
 *    QK_SWEEP_FILE=F.geojson QK_SWEEP_FROM=a QK_SWEEP_TO=b: features a..b-1 of any file
 *    (one line per mesh on stdout: file, feature, name, k, vertices, triangles, seconds).
 * Skipped when the data files are absent (QK_SHARED_DIR) or without GMP / json-c.
 */
#define _POSIX_C_SOURCE 200809L
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <time.h>

#include "mesh_check_real.h"
#include "qk_test.h"
#include "tools/mesh_geojson.c"

/* Sanitizers make the large meshes slow: a smaller sample there (Release runs it all). */
#if defined(__SANITIZE_ADDRESS__) || defined(__SANITIZE_THREAD__)
#define SW_SANITIZED 1
#elif defined(__has_feature)
#if __has_feature(address_sanitizer) || __has_feature(thread_sanitizer)
#define SW_SANITIZED 1
#endif
#endif
#ifndef SW_SANITIZED
#define SW_SANITIZED 0
#endif

static const char *data_path(const char *file) {
  static char path[2][1024];
  static int which;
  const char *dir = getenv("QK_SHARED_DIR");
  char *p = path[which ^= 1];
  snprintf(p, sizeof path[0], "%s/data/%s", dir && *dir ? dir : "../shared", file);
  FILE *f = fopen(p, "rb");
  if (!f) return NULL;
  fclose(f);
  return p;
}

static double now(void) {
  struct timespec ts;
  clock_gettime(CLOCK_MONOTONIC, &ts);
  return (double)ts.tv_sec + 1e-9 * (double)ts.tv_nsec;
}

/*
 * Real rings have zero-width spikes (Oregon's ring goes a -> b -> a on its border with
 * California): the reader merges the repeated segment, leaving a dangling chain. Pointing
 * out of the polygon it lies in the unbounded face, which the general mode drops, tip
 * included (docs/mesh.md: the domain is the bounded faces). For the checker, copy the
 * input without the dangling chains whose vertices the mesh does not have, and the rings
 * without their spikes (zero area). Returns how many vertices were left out.
 */
typedef struct sw_pruned {
  double *xy;
  uint32_t *seg, *ring_v, *smap; /* smap: old segment number -> new (UINT32_MAX: gone) */
  size_t nv, ns, *ring_start;
} sw_pruned_t;

static size_t removed_before(const unsigned char *gone, size_t s) {
  size_t n = 0;
  for (size_t i = 0; i < s; i++) n += gone[i];
  return n;
}

static size_t prune_dangling(const mg_input_t *g, const mcr_mesh_t *m, sw_pruned_t *out) {
  size_t *deg = calloc(g->nv, sizeof *deg);
  unsigned char *gone = calloc(g->nv, 1), *sgone = calloc(g->ns + 1, 1);
  uint32_t *map = malloc((g->nv + 1) * sizeof *map);
  assert_true(deg && gone && sgone && map);
  for (size_t i = 0; i < 2 * g->ns; i++) deg[g->seg[i]]++;
  size_t removed = 0;
  for (int changed = 1; changed;) {
    changed = 0;
    for (size_t v = 0; v < g->nv; v++) {
      if (gone[v] || deg[v] != 1) continue;
      int in_mesh = 0; /* bit-identical vertex in the mesh? */
      for (size_t w = 0; w < m->nv && !in_mesh; w++)
        in_mesh = m->xy[2 * w] == g->xy[2 * v] && m->xy[2 * w + 1] == g->xy[2 * v + 1];
      if (in_mesh) continue;
      for (size_t s = 0; s < g->ns; s++)
        if (!sgone[s] && (g->seg[2 * s] == v || g->seg[2 * s + 1] == v)) {
          sgone[s] = 1, deg[g->seg[2 * s]]--, deg[g->seg[2 * s + 1]]--;
          break;
        }
      gone[v] = 1, removed++, changed = 1;
    }
  }
  out->xy = malloc(2 * g->nv * sizeof *out->xy);
  out->seg = malloc(2 * g->ns * sizeof *out->seg + 1);
  out->ring_v = malloc(g->ring_start[g->nr] * sizeof *out->ring_v + 1);
  out->ring_start = malloc((g->nr + 1) * sizeof *out->ring_start);
  assert_true(out->xy && out->seg && out->ring_v && out->ring_start);
  out->nv = 0;
  for (size_t v = 0; v < g->nv; v++) {
    map[v] = (uint32_t)out->nv;
    if (!gone[v])
      out->xy[2 * out->nv] = g->xy[2 * v], out->xy[2 * out->nv + 1] = g->xy[2 * v + 1], out->nv++;
  }
  out->ns = 0;
  out->smap = malloc((g->ns + 1) * sizeof *out->smap);
  assert_non_null(out->smap);
  for (size_t s = 0; s < g->ns; s++)
    out->smap[s] = sgone[s] ? UINT32_MAX : (uint32_t)(s - removed_before(sgone, s));
  for (size_t s = 0; s < g->ns; s++)
    if (!sgone[s])
      out->seg[2 * out->ns] = map[g->seg[2 * s]],
                   out->seg[2 * out->ns + 1] = map[g->seg[2 * s + 1]], out->ns++;
  size_t k = 0;
  for (size_t r = 0; r < g->nr; r++) {
    size_t start = k;
    out->ring_start[r] = k;
    for (size_t i = g->ring_start[r]; i < g->ring_start[r + 1]; i++) {
      uint32_t v = g->ring_v[i];
      if (gone[v]) continue;
      if (k > start && out->ring_v[k - 1] == map[v]) continue; /* a -> (spike) -> a */
      out->ring_v[k++] = map[v];
    }
    if (k > start + 1 && out->ring_v[k - 1] == out->ring_v[start]) k--;
  }
  out->ring_start[g->nr] = k;
  free(deg), free(gone), free(sgone), free(map);
  return removed;
}

/* Mesh feature f of path at extent/k for each k; check exactly. Returns failures. */
static int sweep_feature(const char *path, long f, const char *name, const int *ks, size_t nk,
                         int verbose) {
  mg_input_t g;
  char msg[1024];
  mg_options_t mo = {name ? -1 : f, name ? "name" : NULL, name, 1, 1.0 / 16};
  int rc = mg_read(path, &mo, &g, msg, sizeof msg);
  if (rc) {
    /* Antarctica's polar ring is refused when it is read (projected), naming it. */
    int known = rc == 1 && strstr(msg, "goes round the south pole");
    if (verbose || !known)
      print_error("%s feature %ld: reading: %s%s\n", path, f, known ? "(known) " : "", msg);
    return !known;
  }
  int failures = 0;
  double lo[2] = {INFINITY, INFINITY}, hi[2] = {-INFINITY, -INFINITY};
  for (size_t i = 0; i < g.nv; i++)
    for (int c = 0; c < 2; c++)
      lo[c] = fmin(lo[c], g.xy[2 * i + c]), hi[c] = fmax(hi[c], g.xy[2 * i + c]);
  double extent = fmax(hi[0] - lo[0], hi[1] - lo[1]);
  for (size_t ki = 0; ki < nk; ki++) {
    double max_size = extent / ks[ki];
    qk_poly_t *poly = NULL;
    qk_mesh_error_t err;
    qk_status_t st = qk_poly_from_arrays(g.xy, g.nv, g.seg, g.ns, g.holes, g.nh, NULL, &poly, &err);
    if (st != QK_OK) {
      print_error("%s feature %ld (%s): qk_poly_from_arrays: %s\n", path, f, g.name, err.message);
      failures++;
      break;
    }
    qk_mesh_options_t o;
    qk_mesh_options_init(&o);
    o.mode = QK_MESH_GENERAL;
    o.max_size = max_size;
    qk_mesh_t *m = NULL;
    double t0 = now();
    st = qk_mesh_generate(poly, &o, &m, &err);
    double secs = now() - t0;
    qk_poly_free(poly);
    if (st != QK_OK) {
      int known = !strcmp(g.name, "Antarctica"); /* the polar ring: docs/mesh.md */
      if (verbose || !known)
        print_error("%s feature %ld (%s) k=%d: %s%s: %s\n", path, f, g.name, ks[ki],
                    known ? "(known) " : "", qk_strerror(st), err.message);
      failures += !known;
      continue;
    }
    qk_mesh_stats_t s;
    qk_mesh_stats(m, &s);
    mcr_input_t ci = {g.xy, g.nv, g.seg, g.ns};
    mcr_mesh_t cm = qkt_mesh_view(m);
    mcr_opts_t co;
    memset(&co, 0, sizeof co);
    co.min_deg = s.proven_min_angle_deg, co.exempt_small = 2, co.max_edge = max_size;
    co.ring_v = g.ring_v, co.ring_start = g.ring_start, co.ring_sign = g.ring_sign;
    sw_pruned_t pr = {0};
    size_t dangling = g.dup_segments ? prune_dangling(&g, &cm, &pr) : 0;
    if (dangling) {
      ci = (mcr_input_t){pr.xy, pr.nv, pr.seg, pr.ns};
      co.ring_v = pr.ring_v, co.ring_start = pr.ring_start;
      uint32_t *of = (uint32_t *)cm.oseg_of; /* the view's own copy */
      for (size_t i = 0; i < cm.no; i++) of[i] = pr.smap[of[i]];
      if (verbose)
        print_message("%s feature %ld (%s): %zu dangling vertices outside the domain left out "
                      "of the check\n",
                      path, f, g.name, dangling);
    }
    co.n_rings = g.nr;
    if (s.proven_max_angle_deg > 0 && s.proven_max_angle_deg < 180)
      co.max_deg = s.proven_max_angle_deg;
    mcr_report_t rep;
    int crc = mcr_check_general(&ci, &cm, &co, &rep, msg, sizeof msg);
    if (crc == 1) {
      print_error("%s feature %ld (%s) k=%d: the exact checker: %s\n", path, f, g.name, ks[ki],
                  msg);
      failures++;
    }
    if (verbose)
      printf("%s\t%ld\t%s\t%d\t%zu\t%zu\t%.3f\t%.2f\t%zu\n", path, f, g.name, ks[ki], g.nv, cm.nt,
             secs, s.min_angle_deg, s.exempt_angles);
    qkt_mesh_view_free(&cm);
    qk_mesh_free(m);
    free(pr.xy), free(pr.seg), free(pr.ring_v), free(pr.ring_start), free(pr.smap);
  }
  mg_free(&g);
  return failures;
}

static long feature_count(const char *path) {
  /* Count the "Feature" strings (not "FeatureCollection"), across buffer seams. */
  long n = 0;
  FILE *f = fopen(path, "rb");
  if (!f) return 0;
  char buf[1 << 16];
  size_t got;
  const char *key = "\"Feature\"";
  size_t kl = strlen(key), keep = 0;
  char tail[16] = {0};
  while ((got = fread(buf, 1, sizeof buf, f)) > 0) {
    char joined[sizeof buf + 16];
    memcpy(joined, tail, keep);
    memcpy(joined + keep, buf, got);
    size_t len = keep + got;
    for (size_t i = 0; i + kl <= len; i++)
      if (!memcmp(joined + i, key, kl)) n++;
    keep = len < kl - 1 ? len : kl - 1;
    memcpy(tail, joined + len - keep, keep);
  }
  fclose(f);
  return n;
}

static void test_sweep_mesh_sample(void **state) {
  (void)state;
  if (!mcr_available()) skip();
#ifndef QK_HAVE_JSONC
  skip();
#endif
  const char *countries = data_path("countries-50m.geojson");
  const char *states = data_path("us-states-10m.geojson");
  if (!countries || !states) {
    print_message("no countries-50m.geojson / us-states-10m.geojson under QK_SHARED_DIR: "
                  "skipped\n");
    skip();
  }
  int verbose = getenv("QK_VERBOSE") != NULL;
  static const int ks[] = {64, 256};
  int failures = 0;
  const char *file = getenv("QK_SWEEP_FILE");
  if (file) {
    long from = getenv("QK_SWEEP_FROM") ? atol(getenv("QK_SWEEP_FROM")) : 0;
    long to = getenv("QK_SWEEP_TO") ? atol(getenv("QK_SWEEP_TO")) : feature_count(file);
    for (long f = from; f < to; f++) failures += sweep_feature(file, f, NULL, ks, 2, 1);
    assert_int_equal(failures, 0);
    return;
  }
  int all = getenv("QK_SWEEP_ALL") != NULL;
  const char *paths[2] = {countries, states};
  long steps[2] = {SW_SANITIZED ? 1000 : 47, SW_SANITIZED ? 1000 : 11};
  for (int p = 0; p < 2; p++) {
    long n = feature_count(paths[p]);
    assert_true(n > 50);
    for (long f = 0; f < n; f++)
      if (all || f % steps[p] == 0)
        failures += sweep_feature(paths[p], f, NULL, ks, 2, verbose || all);
  }
  /* Features picked by name: both sides of the antimeridian, tiny islands, many rings. */
  static const char *const named[] = {"Fiji",         "Russia",   "Kiribati",  "Nauru",
                                      "Pitcairn Is.", "Maldives", "Indonesia", "Canada",
                                      "Vatican",      "Monaco"};
  for (size_t i = 0; i < (SW_SANITIZED ? 4 : sizeof named / sizeof *named) && !all; i++)
    failures += sweep_feature(countries, -1, named[i], ks, 2, verbose);
  failures += sweep_feature(states, -1, "Oregon", ks, 2, verbose); /* a spike: a -> b -> a */
  assert_int_equal(failures, 0);
}

int main(void) {
  const struct CMUnitTest tests[] = {
      cmocka_unit_test(test_sweep_mesh_sample),
  };
  return cmocka_run_group_tests(tests, NULL, NULL);
}
