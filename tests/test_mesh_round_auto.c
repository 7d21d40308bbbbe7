/*
 * Test plan for `quadkit mesh --round auto` (tools/cmd_mesh.c, tools/mesh_geojson.c): the
 * command-line tool run as a program (QK_CLI, set by ctest) and the mesh it writes read
 * back from its .node and .ele files and passed through the independent exact rational
 * checker (tests/support/mesh_check_general.c), against the input rounded here:
 *  - the grid (mg_auto_grid) on seeded random point sets of magnitudes 2^-40 .. 2^40 and
 *    extents down to 2^-30 of them: M and W bound the coordinates and the extent tightly;
 *    2^k is the finest grid with 2k >= M + W - 52; and on that grid every segment between
 *    two rounded points has exact split points at steps of 2^-(W-k) of it, pieces no
 *    longer than the grid step in either coordinate (the library's own precision budget,
 *    qk__seg_budget, is at least W - k);
 *  - t2.poly (decimal coordinates, which the general mode refuses without rounding):
 *    with --round auto --max-size 5 the stats report the grid 2^-20 and 8 moved
 *    coordinates; the .node file's first vertices are the input rounded to 2^-20 here,
 *    bit for bit, each moved at most 2^-21; the mesh passes the checker (every angle at
 *    least 20 degrees, every edge at most 5, conforming, the segments covered exactly,
 *    the ring's area);
 *  - Norway (countries-50m.geojson, when present) with --project equirect --round auto:
 *    the .node file starts with the input mg_read() prepares with MG_ROUND_AUTO, every
 *    coordinate on its grid, and the mesh passes the checker with the rings' area.
 * Without GMP or without the tool (QK_CLI unset) the tests report themselves skipped.
 */
#define _XOPEN_SOURCE 700 /* mkdtemp */
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/wait.h>

#include "mesh/general_internal.h"
#include "mesh_check_real.h"
#include "qk_test.h"
#include "tools/mesh_geojson.c"

/* A scratch directory for the tool's files (removed by the caller's rm -rf). */
static char tmpdir[256];

static const char *cli_path(void) {
  const char *c = getenv("QK_CLI");
  if (!c || !c[0]) {
    print_message("QK_CLI unset: skipped\n");
    skip();
  }
  return c;
}

static void make_tmpdir(void) {
  const char *t = getenv("TMPDIR");
  snprintf(tmpdir, sizeof tmpdir, "%s/qk-round-auto-XXXXXX", t && t[0] ? t : "/tmp");
  assert_non_null(mkdtemp(tmpdir));
}

static void remove_tmpdir(void) {
  char cmd[300];
  snprintf(cmd, sizeof cmd, "rm -rf '%s'", tmpdir);
  assert_int_equal(system(cmd), 0);
}

/* The mesh as the tool wrote it: PREFIX.node (vertices numbered from `base`) and
 * PREFIX.ele. */
typedef struct cli_mesh {
  double *xy;
  size_t nv;
  uint32_t *tri;
  size_t nt;
} cli_mesh_t;

static void read_mesh(const char *prefix, unsigned base, cli_mesh_t *m) {
  char path[512], line[512];
  snprintf(path, sizeof path, "%s.node", prefix);
  FILE *f = fopen(path, "r");
  assert_non_null(f);
  assert_true(fgets(line, sizeof line, f) != NULL);
  m->nv = strtoul(line, NULL, 10);
  m->xy = malloc(2 * m->nv * sizeof *m->xy);
  assert_non_null(m->xy);
  for (size_t i = 0; i < m->nv; i++) {
    unsigned long id;
    assert_true(fgets(line, sizeof line, f) != NULL);
    assert_int_equal(sscanf(line, "%lu %lf %lf", &id, &m->xy[2 * i], &m->xy[2 * i + 1]), 3);
    assert_int_equal(id, i + base);
  }
  fclose(f);
  snprintf(path, sizeof path, "%s.ele", prefix);
  f = fopen(path, "r");
  assert_non_null(f);
  assert_true(fgets(line, sizeof line, f) != NULL);
  m->nt = strtoul(line, NULL, 10);
  m->tri = malloc(3 * m->nt * sizeof *m->tri);
  assert_non_null(m->tri);
  for (size_t t = 0; t < m->nt; t++) {
    unsigned long id, a, b, c;
    assert_true(fgets(line, sizeof line, f) != NULL);
    assert_int_equal(sscanf(line, "%lu %lu %lu %lu", &id, &a, &b, &c), 4);
    assert_true(a >= base && b >= base && c >= base);
    m->tri[3 * t] = (uint32_t)(a - base), m->tri[3 * t + 1] = (uint32_t)(b - base);
    m->tri[3 * t + 2] = (uint32_t)(c - base);
    assert_true(m->tri[3 * t] < m->nv && m->tri[3 * t + 1] < m->nv && m->tri[3 * t + 2] < m->nv);
  }
  fclose(f);
}

static void free_mesh(cli_mesh_t *m) { free(m->xy), free(m->tri); }

/* Check the tool's mesh exactly against the input (in), its rings and the bounds. */
static void check_mesh(const char *what, const mcr_input_t *in, const cli_mesh_t *cm,
                       const uint32_t *ring_v, const size_t *ring_start, const int *ring_sign,
                       size_t nr, double max_edge) {
  mcr_mesh_t m = {cm->xy, cm->nv, cm->tri, cm->nt, NULL, NULL, 0};
  mcr_opts_t o;
  memset(&o, 0, sizeof o);
  o.min_deg = 20, o.exempt_small = 2, o.max_deg = 140, o.max_edge = max_edge;
  o.ring_v = ring_v, o.ring_start = ring_start, o.ring_sign = ring_sign, o.n_rings = nr;
  mcr_report_t rep;
  char msg[512];
  int rc = mcr_check_general(in, &m, &o, &rep, msg, sizeof msg);
  if (rc != 0) fail_msg("%s: the exact checker: %s", what, msg);
  print_message("%s: %zu triangles checked exactly, smallest angle %.4g\n", what, cm->nt,
                rep.min_angle_deg);
}

/* Run a shell command; returns its exit status. */
static int run(const char *cmd) {
  int st = system(cmd);
  return st >= 0 && WIFEXITED(st) ? WEXITSTATUS(st) : -1;
}

/* The "round" field of a --stats line in file path. */
static double stats_round(const char *path) {
  FILE *f = fopen(path, "r");
  assert_non_null(f);
  static char buf[1 << 16];
  size_t n = fread(buf, 1, sizeof buf - 1, f);
  fclose(f);
  buf[n] = '\0';
  const char *p = strstr(buf, "\"round\": ");
  assert_non_null(p);
  return strtod(p + 9, NULL);
}

static void test_round_auto_grid(void **state) {
  (void)state;
  uint64_t seed = qkt_seed(2027);
  qkt_rng_t r;
  qkt_rng_seed(&r, seed);
  for (int c = 0; c < 300; c++) {
    /* Points about a centre of magnitude 2^a, spread over 2^b below it. */
    int a = (int)qkt_rng_below(&r, 81) - 40, b = a - (int)qkt_rng_below(&r, 31);
    double cx = ldexp(qkt_rng_unit(&r) * 2 - 1, a), cy = ldexp(qkt_rng_unit(&r) * 2 - 1, a);
    size_t n = 2 + qkt_rng_below(&r, 20);
    double xy[44];
    for (size_t i = 0; i < n; i++) {
      xy[2 * i] = cx + ldexp(qkt_rng_unit(&r) * 2 - 1, b);
      xy[2 * i + 1] = cy + ldexp(qkt_rng_unit(&r) * 2 - 1, b);
    }
    int M, W, k = mg_auto_grid(xy, n, &M, &W);
    double big = 0, lo[2] = {xy[0], xy[1]}, hi[2] = {xy[0], xy[1]};
    for (size_t i = 0; i < n; i++)
      for (int d = 0; d < 2; d++) {
        big = fmax(big, fabs(xy[2 * i + d]));
        lo[d] = fmin(lo[d], xy[2 * i + d]), hi[d] = fmax(hi[d], xy[2 * i + d]);
      }
    double side = fmax(hi[0] - lo[0], hi[1] - lo[1]);
    if (!(big < ldexp(1, M) && big >= ldexp(1, M - 1) && side < ldexp(1, W) &&
          side >= ldexp(1, W - 1)))
      fail_msg("seed %llu case %d: M %d W %d for magnitude %g, extent %g", (unsigned long long)seed,
               c, M, W, big, side);
    if (!(2 * k >= M + W - 52 && 2 * (k - 1) < M + W - 52))
      fail_msg("seed %llu case %d: k %d is not the finest with 2k >= M + W - 52 (M %d, W %d)",
               (unsigned long long)seed, c, k, M, W);
    /* On the grid, splits at steps of the grid step are exact on every segment. The
     * rounding may carry a coordinate up to 2^M itself (one bit less of budget): the
     * budget is asked of W - k on points whose magnitude stayed below 2^M. */
    double g = ldexp(1, k);
    for (size_t i = 0; i < 2 * n; i++) xy[i] = nearbyint(xy[i] / g) * g;
    for (size_t i = 0; i < n; i++)
      for (size_t j = i + 1; j < n; j++) {
        const double *p = &xy[2 * i], *q = &xy[2 * j];
        if ((p[0] == q[0] && p[1] == q[1]) ||
            fmax(fmax(fabs(p[0]), fabs(p[1])), fmax(fabs(q[0]), fabs(q[1]))) >= ldexp(1, M))
          continue;
        int bud = qk__seg_budget(p, q);
        if (bud < W - k)
          fail_msg("seed %llu case %d: budget %d below W - k = %d on the grid 2^%d",
                   (unsigned long long)seed, c, bud, W - k, k);
      }
  }
}

static void test_round_auto_t2(void **state) {
  (void)state;
  if (!mcr_available()) skip();
  const char *cli = cli_path();
  make_tmpdir();
  char path[400], cmd[2048];
  snprintf(path, sizeof path, "%s/t2.poly", tmpdir);
  FILE *f = fopen(path, "w");
  assert_non_null(f);
  fputs("4 2 0 0\n1 0.1 0.1\n2 37.7 0.2\n3 21.3 22.9\n4 3.3 19.1\n4 0\n1 1 2\n2 2 3\n3 3 4\n"
        "4 4 1\n0\n",
        f);
  fclose(f);
  snprintf(cmd, sizeof cmd,
           "'%s' mesh '%s/t2.poly' -o '%s/m' --max-size 5 --round auto --stats >'%s/stats' "
           "2>'%s/err'",
           cli, tmpdir, tmpdir, tmpdir, tmpdir);
  assert_int_equal(run(cmd), 0);
  snprintf(path, sizeof path, "%s/stats", tmpdir);
  double g = stats_round(path);
  /* Coordinates below 2^6, extent 37.6 below 2^6: k = ceil((6 + 6 - 52) / 2) = -20. */
  assert_true(g == ldexp(1, -20));
  const double in_dec[8] = {0.1, 0.1, 37.7, 0.2, 21.3, 22.9, 3.3, 19.1};
  double in_xy[8];
  for (int i = 0; i < 8; i++) {
    in_xy[i] = nearbyint(in_dec[i] / g) * g;
    assert_true(fabs(in_xy[i] - in_dec[i]) <= g / 2);
  }
  cli_mesh_t cm;
  snprintf(path, sizeof path, "%s/m", tmpdir);
  read_mesh(path, 1, &cm);
  assert_true(cm.nv > 4 && cm.nt > 0);
  for (int i = 0; i < 8; i++)
    if (cm.xy[i] != in_xy[i])
      fail_msg("vertex %d: %.17g in the .node file, rounded %.17g", i / 2 + 1, cm.xy[i], in_xy[i]);
  static const uint32_t seg[] = {0, 1, 1, 2, 2, 3, 3, 0}, ring[] = {0, 1, 2, 3};
  static const size_t rs[] = {0, 4};
  static const int sign[] = {1};
  mcr_input_t in = {in_xy, 4, seg, 4};
  check_mesh("t2.poly --round auto --max-size 5", &in, &cm, ring, rs, sign, 1, 5);
  free_mesh(&cm);
  remove_tmpdir();
}

static void test_round_auto_norway(void **state) {
  (void)state;
#ifndef QK_HAVE_JSONC
  skip();
#endif
  if (!mcr_available()) skip();
#if defined(__SANITIZE_ADDRESS__) || defined(__SANITIZE_THREAD__)
  skip(); /* the sanitizers make the mesh and its exact check slow; Release runs it */
#endif
  const char *cli = cli_path();
  char data[1024];
  FILE *df = qkt_open_shared("countries-50m.geojson", data, sizeof data);
  if (!df) {
    print_message("no countries-50m.geojson under QK_SHARED_DIR: SKIPPED\n");
    skip();
  }
  fclose(df);
  mg_options_t o = {-1, "name", "Norway", 1, MG_ROUND_AUTO};
  mg_input_t gj;
  char msg[1024];
  if (mg_read(data, &o, &gj, msg, sizeof msg)) fail_msg("Norway: %s", msg);
  assert_true(gj.round == ldexp(1, gj.round_exp) && gj.nv > 1000);
  for (size_t i = 0; i < 2 * gj.nv; i++)
    assert_true(gj.xy[i] == nearbyint(gj.xy[i] / gj.round) * gj.round);
  make_tmpdir();
  char cmd[3000], path[400];
  snprintf(cmd, sizeof cmd,
           "'%s' mesh '%s' --field name=Norway --project equirect --round auto -o '%s/n' "
           "--stats >'%s/stats' 2>'%s/err'",
           cli, data, tmpdir, tmpdir, tmpdir);
  assert_int_equal(run(cmd), 0);
  snprintf(path, sizeof path, "%s/stats", tmpdir);
  assert_true(stats_round(path) == gj.round);
  cli_mesh_t cm;
  snprintf(path, sizeof path, "%s/n", tmpdir);
  read_mesh(path, 0, &cm);
  assert_true(cm.nv >= gj.nv);
  for (size_t i = 0; i < 2 * gj.nv; i++)
    if (cm.xy[i] != gj.xy[i])
      fail_msg("Norway: vertex %zu is %.17g in the .node file, %.17g prepared", i / 2, cm.xy[i],
               gj.xy[i]);
  mcr_input_t in = {gj.xy, gj.nv, gj.seg, gj.ns};
  check_mesh("Norway --project equirect --round auto", &in, &cm, gj.ring_v, gj.ring_start,
             gj.ring_sign, gj.nr, 0);
  free_mesh(&cm);
  mg_free(&gj);
  remove_tmpdir();
}

int main(void) {
  const struct CMUnitTest tests[] = {
      cmocka_unit_test(test_round_auto_grid),
      cmocka_unit_test(test_round_auto_t2),
      cmocka_unit_test(test_round_auto_norway),
  };
  return cmocka_run_group_tests(tests, NULL, NULL);
}
