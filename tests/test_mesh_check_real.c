/*
 * Test plan for the exact rational mesh checker itself (tests/support/mesh_check_real.h,
 * mcr_check_general): a checker that cannot fail checks nothing, so every rule is shown
 * to accept a good hand-made triangulation and to reject one with exactly that defect:
 *  - good meshes: a square fan (every angle 45 or 90), a thin wedge whose 14-degree
 *    input angle is exempt, an annulus (a square with a square hole) against its rings;
 *  - angles: a small angle at an input vertex whose input angle is 90 degrees, a small
 *    angle at a Steiner vertex, a triangle straddling an input segment at a small input
 *    angle, an input angle of 63 degrees (not below 60), the upper bound;
 *  - conformity: a missing triangle (an edge without a twin off every segment), a
 *    clockwise triangle, a directed edge used twice, two coincident mesh vertices;
 *  - exactness: an input vertex moved by one ulp, a vertex on a segment moved one ulp off
 *    it, an internal segment not made of mesh edges, an output segment off its segment;
 *  - areas: an annulus whose hole is filled (every edge paired, but the rings disagree);
 *  - size: an edge longer than max_edge.
 * Without GMP every test reports itself skipped.
 */
#include <math.h>
#include <stdio.h>
#include <string.h>

#include "mesh_check_real.h"
#include "qk_test.h"

/* Run the checker; expect pass (want == NULL) or a failure whose message has `want`. */
static void expect(const mcr_input_t *in, const mcr_mesh_t *m, const mcr_opts_t *o,
                   const char *want, mcr_report_t *rep) {
  if (!mcr_available()) skip();
  char msg[512];
  mcr_report_t r;
  int rc = mcr_check_general(in, m, o, &r, msg, sizeof msg);
  if (!want) {
    if (rc != 0) fail_msg("expected a pass, got: %s", msg);
  } else {
    if (rc != 1) fail_msg("expected a failure with '%s', the mesh passed", want);
    if (!strstr(msg, want)) fail_msg("expected '%s' in: %s", want, msg);
  }
  if (rep) *rep = r;
}

/* The square [0,4]^2 and its centre: four triangles with angles 45, 45, 90. */
static const double sq_xy[] = {0, 0, 4, 0, 4, 4, 0, 4, 2, 2};
static const uint32_t sq_seg[] = {0, 1, 1, 2, 2, 3, 3, 0};
static const uint32_t sq_tri[] = {0, 1, 4, 1, 2, 4, 2, 3, 4, 3, 0, 4};
static const uint32_t sq_ring[] = {0, 1, 2, 3};
static const size_t sq_rs[] = {0, 4};
static const int plus[] = {1, -1};

static mcr_opts_t opts20(void) {
  mcr_opts_t o = {20, 1, 140, 0, NULL, NULL, NULL, 0};
  return o;
}

static void test_check_good_square(void **state) {
  (void)state;
  mcr_input_t in = {sq_xy, 4, sq_seg, 4};
  uint32_t oseg[] = {0, 1, 1, 2, 2, 3, 3, 0}, of[] = {0, 1, 2, 3};
  mcr_mesh_t m = {sq_xy, 5, sq_tri, 4, oseg, of, 4};
  mcr_opts_t o = opts20();
  o.ring_v = sq_ring, o.ring_start = sq_rs, o.ring_sign = plus, o.n_rings = 1;
  mcr_report_t r;
  expect(&in, &m, &o, NULL, &r);
  assert_true(fabs(r.area - 16) < 1e-12);
  assert_int_equal(r.exempt, 0);
  assert_int_equal(r.boundary_edges, 4);
  assert_true(fabs(r.min_angle_deg - 45) < 1e-9 && fabs(r.max_angle_deg - 90) < 1e-9);
  assert_true(fabs(r.smallest_input_angle_deg - 90) < 1e-9);
  o.max_edge = 4; /* the sides are exactly 4 long: allowed */
  expect(&in, &m, &o, NULL, NULL);
}

/* The annulus [0,8]^2 minus [2,6]^2, as 8 triangles; `fill` adds the hole's two. */
static const double an_xy[] = {0, 0, 8, 0, 8, 8, 0, 8, 2, 2, 6, 2, 6, 6, 2, 6};
static const uint32_t an_seg[] = {0, 1, 1, 2, 2, 3, 3, 0, 4, 5, 5, 6, 6, 7, 7, 4};
static const uint32_t an_tri[] = {0, 1, 5, 0, 5, 4, 1, 2, 6, 1, 6, 5, 2, 3, 7,
                                  2, 7, 6, 3, 0, 4, 3, 4, 7, 4, 5, 6, 4, 6, 7};
static const uint32_t an_ring[] = {0, 1, 2, 3, 4, 5, 6, 7};
static const size_t an_rs[] = {0, 4, 8};

static void test_check_defects_conformity(void **state) {
  (void)state;
  mcr_input_t in = {sq_xy, 4, sq_seg, 4};
  mcr_opts_t o = opts20();
  /* A missing triangle: the filled annulus below (a valid mesh of the square [0,8]^2)
   * without triangle 4-5-6: edge 6-4 has no twin and lies on no segment, while every
   * segment is still covered. */
  mcr_input_t ain = {an_xy, 8, an_seg, 8};
  uint32_t gap[27];
  memcpy(gap, an_tri, 24 * sizeof *gap);
  memcpy(gap + 24, an_tri + 27, 3 * sizeof *gap);
  mcr_mesh_t am = {an_xy, 8, an_tri, 10, NULL, NULL, 0};
  mcr_opts_t o10 = {10, 1, 0, 0, NULL, NULL, NULL, 0};
  expect(&ain, &am, &o10, NULL, NULL);
  am.tri = gap, am.nt = 9;
  expect(&ain, &am, &o10, "no twin", NULL);
  mcr_mesh_t m = {sq_xy, 5, sq_tri, 4, NULL, NULL, 0};
  /* A clockwise triangle. */
  uint32_t cw[12];
  memcpy(cw, sq_tri, sizeof cw);
  cw[4] = 4, cw[5] = 2;
  m.tri = cw, m.nt = 4;
  expect(&in, &m, &o, "counter-clockwise", NULL);
  /* A triangle given twice. */
  uint32_t twice[15];
  memcpy(twice, sq_tri, sizeof sq_tri);
  memcpy(twice + 12, sq_tri, 3 * sizeof *twice);
  m.tri = twice, m.nt = 5;
  expect(&in, &m, &o, "used twice", NULL);
  /* Two mesh vertices at one place. */
  double dup[12];
  memcpy(dup, sq_xy, sizeof sq_xy);
  dup[10] = 2, dup[11] = 2;
  mcr_mesh_t md = {dup, 6, sq_tri, 4, NULL, NULL, 0};
  expect(&in, &md, &o, "coincide", NULL);
}

static void test_check_defects_exactness(void **state) {
  (void)state;
  mcr_input_t in = {sq_xy, 4, sq_seg, 4};
  mcr_opts_t o = opts20();
  /* An input vertex one ulp away in the mesh. */
  double moved[10];
  memcpy(moved, sq_xy, sizeof moved);
  moved[2] = nextafter(4, 5);
  mcr_mesh_t m = {moved, 5, sq_tri, 4, NULL, NULL, 0};
  expect(&in, &m, &o, "not a mesh vertex", NULL);
  /* A vertex meant to split the bottom side one ulp above it: the side is not covered
   * (its mesh vertices 0 and 1 are not joined). */
  const double xy[] = {0, 0, 4, 0, 4, 4, 0, 4, 2, 2, 2, 0x1p-60};
  const uint32_t tri[] = {0, 5, 4, 5, 1, 4, 1, 2, 4, 2, 3, 4, 3, 0, 4, 0, 1, 5};
  mcr_mesh_t mo = {xy, 6, tri, 5, NULL, NULL, 0};
  /* (Five triangles: 0-5-1 bulges below nothing, so first the side is uncovered.) */
  expect(&in, &mo, &o, "not covered", NULL);
  /* An internal segment 0-2 while the mesh uses the other diagonal. */
  const uint32_t seg5[] = {0, 1, 1, 2, 2, 3, 3, 0, 0, 2};
  mcr_input_t in5 = {sq_xy, 4, seg5, 5};
  const uint32_t diag[] = {0, 1, 3, 1, 2, 3};
  mcr_mesh_t mdg = {sq_xy, 4, diag, 2, NULL, NULL, 0};
  mcr_opts_t o45 = {45, 0, 90, 0, NULL, NULL, NULL, 0};
  expect(&in, &mdg, &o45, NULL, NULL); /* without the internal segment it is fine */
  expect(&in5, &mdg, &o45, "not covered", NULL);
  /* An output segment off its input segment, and one that is not a mesh edge. */
  uint32_t os[] = {0, 4}, of[] = {0};
  mcr_mesh_t ms = {sq_xy, 5, sq_tri, 4, os, of, 1};
  expect(&in, &ms, &o, "off input segment", NULL);
  uint32_t os2[] = {0, 2}, of2[] = {4};
  mcr_mesh_t ms2 = {sq_xy, 5, sq_tri, 4, os2, of2, 1};
  expect(&in5, &ms2, &o, "not a mesh edge", NULL); /* the fan covers the diagonal via the centre */
}

static void test_check_areas(void **state) {
  (void)state;
  mcr_input_t in = {an_xy, 8, an_seg, 8};
  mcr_opts_t o = {10, 1, 0, 0, an_ring, an_rs, plus, 2};
  mcr_mesh_t m = {an_xy, 8, an_tri, 8, NULL, NULL, 0};
  mcr_report_t r;
  expect(&in, &m, &o, NULL, &r);
  assert_true(fabs(r.area - 48) < 1e-12);
  assert_int_equal(r.boundary_edges, 8);
  m.nt = 10; /* the hole filled: every edge still paired or on a segment */
  expect(&in, &m, &o, "cover area", NULL);
  o.n_rings = 0; /* without rings the filled annulus is a valid mesh of the square */
  expect(&in, &m, &o, NULL, &r);
  assert_true(fabs(r.area - 64) < 1e-12);
}

static void test_check_angles(void **state) {
  (void)state;
  /* A thin wedge: its 14-degree corner at input vertex 0 lies in the input angle. */
  const double w_xy[] = {0, 0, 8, 0, 8, 2};
  const uint32_t w_seg[] = {0, 1, 1, 2, 2, 0}, w_tri[] = {0, 1, 2};
  mcr_input_t win = {w_xy, 3, w_seg, 3};
  mcr_mesh_t wm = {w_xy, 3, w_tri, 1, NULL, NULL, 0};
  mcr_opts_t o = opts20();
  mcr_report_t r;
  expect(&win, &wm, &o, NULL, &r);
  assert_int_equal(r.exempt, 1);
  assert_true(fabs(r.smallest_input_angle_deg - atan(0.25) * 180 / 3.14159265358979323846) < 1e-9);
  o.exempt_small = 0;
  expect(&win, &wm, &o, "below 20", NULL);
  o.exempt_small = 1;

  /* A 2.9-degree angle at the square's corner 2, whose input angle is 90. */
  const double s_xy[] = {0, 0, 4, 0, 4, 4, 0, 4, 2, 3.875};
  mcr_input_t in = {sq_xy, 4, sq_seg, 4};
  const uint32_t s_tri[] = {2, 3, 4, 0, 1, 4, 1, 2, 4, 3, 0, 4};
  mcr_mesh_t sm = {s_xy, 5, s_tri, 4, NULL, NULL, 0};
  expect(&in, &sm, &o, "at vertex 2 ", NULL);

  /* A 4-degree angle at Steiner vertex 6 (not an input vertex). */
  const double t_xy[] = {0, 0, 4, 0, 4, 4, 0, 4, 1, 0, 1.25, 0, 1, 3.5};
  const uint32_t t_tri[] = {4, 5, 6, 0, 4, 6, 0, 6, 3, 5, 1, 6, 1, 2, 6, 2, 3, 6};
  mcr_mesh_t tm = {t_xy, 7, t_tri, 6, NULL, NULL, 0};
  expect(&in, &tm, &o, "at vertex 6 ", NULL);
  mcr_opts_t loose = {1, 1, 0, 0, NULL, NULL, NULL, 0};
  expect(&in, &tm, &loose, NULL, NULL); /* and it is a valid mesh otherwise */

  /* Vertex 0 with segments towards (8,0), (8,1) (7.1 degrees apart) and (0,8). */
  const double v_xy[] = {0, 0, 8, 0, 8, 1, 0, 8, 8, -1, 8, 0.5, 8, 0.25, 4, 8};
  const uint32_t v_seg[] = {0, 1, 0, 2, 0, 3, 0, 7};
  mcr_input_t vin = {v_xy, 8, v_seg, 3};
  const uint32_t across[] = {0, 4, 5}; /* from -7 to 3.6 degrees: across segment 0-1 */
  mcr_mesh_t vm = {v_xy, 8, across, 1, NULL, NULL, 0};
  expect(&vin, &vm, &o, "at vertex 0 ", NULL);
  /* 1.8 to 3.6 degrees: inside the wedge, but 1.8 degrees is below the bound there,
   * g(7.1) = arctan(sin 7.1 / (2.02 - cos 7.1)) = 6.9 degrees. */
  const uint32_t inside[] = {0, 6, 5};
  vm.tri = inside;
  char msg[512];
  if (!mcr_available()) skip();
  assert_int_equal(mcr_check_general(&vin, &vm, &o, &r, msg, sizeof msg), 1);
  assert_non_null(strstr(msg, "below the bound arctan"));
  /* 0 to 7.1 degrees (the whole input angle, above the bound): exempt. */
  const uint32_t whole[] = {0, 1, 2};
  vm.tri = whole;
  assert_int_equal(mcr_check_general(&vin, &vm, &o, &r, msg, sizeof msg), 1);
  assert_null(strstr(msg, "degrees (below")); /* it fails later, on conformity */
  /* The same corner between segments towards (8,0) and (4,8), 63 degrees apart. */
  vin.ns = 4;
  const uint32_t v_seg2[] = {0, 1, 0, 7, 0, 3, 0, 3};
  vin.seg = v_seg2;
  expect(&vin, &vm, &o, "at vertex 0 ", NULL);

  /* A triangle spanning a 14-degree input angle, its 17-degree corner at a Steiner vertex
   * inside the wedge and its other two vertices on the two segments: refused by rule 1
   * (not at the input vertex), allowed by rule 2 (the wedge rule). */
  const double s2_xy[] = {0, 0, 16, 0, 16, 4, 1.5, 0.2, 8, 0, 8, 2, 2.5, 1.5};
  const uint32_t s2_seg[] = {0, 1, 0, 2, 1, 2}, span[] = {3, 4, 5}, off[] = {6, 4, 5};
  mcr_input_t s2in = {s2_xy, 7 - 4, s2_seg, 3};
  mcr_mesh_t s2m = {s2_xy, 7, span, 1, NULL, NULL, 0};
  expect(&s2in, &s2m, &o, "at vertex 3 ", NULL);
  mcr_opts_t ow = o;
  ow.exempt_small = 2;
  assert_int_equal(mcr_check_general(&s2in, &s2m, &ow, &r, msg, sizeof msg), 1);
  assert_null(strstr(msg, "degrees (below")); /* exempt; it fails later, on conformity */
  assert_int_equal(r.exempt_wedge, 1);
  /* The same shape with its corner outside the wedge (above segment 0-2): not exempt. */
  s2m.tri = off;
  ow.min_deg = 30;
  expect(&s2in, &s2m, &ow, "at vertex 6 ", NULL);

  /* The upper bound: the square fan has right angles. */
  mcr_mesh_t m = {sq_xy, 5, sq_tri, 4, NULL, NULL, 0};
  mcr_opts_t up = {20, 1, 80, 0, NULL, NULL, NULL, 0};
  expect(&in, &m, &up, "above 80", NULL);
  up.max_deg = 90;
  expect(&in, &m, &up, NULL, NULL);
}

static void test_check_size(void **state) {
  (void)state;
  mcr_input_t in = {sq_xy, 4, sq_seg, 4};
  mcr_mesh_t m = {sq_xy, 5, sq_tri, 4, NULL, NULL, 0};
  mcr_opts_t o = opts20();
  o.max_edge = nextafter(4, 0);
  expect(&in, &m, &o, "above the bound", NULL);
}

int main(void) {
  const struct CMUnitTest tests[] = {
      cmocka_unit_test(test_check_good_square),
      cmocka_unit_test(test_check_defects_conformity),
      cmocka_unit_test(test_check_defects_exactness),
      cmocka_unit_test(test_check_areas),
      cmocka_unit_test(test_check_angles),
      cmocka_unit_test(test_check_size),
  };
  return cmocka_run_group_tests(tests, NULL, NULL);
}
