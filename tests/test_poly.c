/*
 * Test plan for the mesh input (Triangle's .poly reader and qk_mesh_generate's checks):
 *  - good files: comments, blank lines, first index 0 and 1, attributes and markers
 *    (the marker may be left out), optional holes and regional attributes, all read
 *    with the right counts;
 *  - every kind of bad input gets its status, the line it is on and a message naming
 *    the problem: malformed numbers, wrong dimension, bad first index, non-consecutive
 *    vertex, segment or hole numbers, a vertex row short of its declared attributes,
 *    segment endpoints that are not vertices, truncated files, absurd
 *    counts, trailing garbage; non-integer and out-of-domain coordinates, edges at
 *    other angles, open chains, vertices of degree 0 or 3, coincident vertices,
 *    duplicate segments, self-intersecting polygons, touching and crossing components,
 *    holes outside the domain or on a boundary, a domain size that is not a power of
 *    two;
 *  - hole points a hair off a boundary, decided exactly;
 *  - 3000 random mutations of a valid file: success or a clean error with a message;
 *  - allocation failure at every N while reading: QK_ERR_NOMEM, no leak;
 *  - a line without end is refused at 1 MiB with little memory taken.
 */
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "mesh_check.h"
#include "qk_test.h"

static FILE *from_string(const char *s) {
  FILE *f = tmpfile();
  assert_non_null(f);
  fputs(s, f);
  rewind(f);
  return f;
}

/* Read and mesh `text`; return the status and fill err. */
static qk_status_t run(const char *text, uint64_t size, qk_mesh_error_t *err) {
  FILE *f = from_string(text);
  qk_poly_t *p = NULL;
  qk_status_t st = qk_poly_read(f, NULL, &p, err);
  fclose(f);
  if (st != QK_OK) {
    assert_null(p);
    return st;
  }
  qk_mesh_options_t o;
  qk_mesh_options_init(&o);
  o.size = size;
  o.mode = QK_MESH_BOOK; /* this file tests the book's mode (test_mesh_dyadic the other) */
  qk_mesh_t *m = NULL;
  st = qk_mesh_generate(p, &o, &m, err);
  if (st != QK_OK) assert_null(m);
  qk_mesh_free(m);
  qk_poly_free(p);
  return st;
}

/* Read and mesh (book's mode, domain `size`) and, when that succeeds, pass the mesh through
 * the exact checker of tests/support/mesh_check.c; a failure there fails the test. */
static qk_status_t run_checked(const char *text, uint64_t size, qk_mesh_error_t *err,
                               const char *what) {
  FILE *f = from_string(text);
  qk_poly_t *p = NULL;
  qk_status_t st = qk_poly_read(f, NULL, &p, err);
  fclose(f);
  if (st != QK_OK) return st;
  qk_mesh_options_t o;
  qk_mesh_options_init(&o);
  o.size = size;
  o.mode = QK_MESH_BOOK;
  qk_mesh_t *m = NULL;
  st = qk_mesh_generate(p, &o, &m, err);
  if (st == QK_OK) {
    size_t nv, ns, nh, k;
    qk_poly_counts(p, &nv, &ns, &nh);
    double *xy = malloc((2 * nv + 2) * sizeof *xy), *holes = malloc((2 * nh + 2) * sizeof *holes);
    uint32_t *seg = malloc((2 * ns + 2) * sizeof *seg);
    assert_true(xy && holes && seg);
    assert_int_equal(qk_poly_vertices(p, xy, nv, &k), QK_OK);
    assert_int_equal(qk_poly_segments(p, seg, ns, &k), QK_OK);
    assert_int_equal(qk_poly_holes(p, holes, nh, &k), QK_OK);
    qk_mesh_stats_t s;
    qk_mesh_stats(m, &s);
    mc_input_t in = {xy, nv, seg, ns, holes, nh, s.size};
    mc_mesh_t mm;
    mm.xy = qk_mesh_vertices(m, &mm.nv);
    mm.tri = qk_mesh_triangles(m, &mm.nt);
    mm.comp = qk_mesh_triangle_components(m, NULL);
    char msg[512];
    if (mc_check(&in, &mm, msg, sizeof msg))
      fail_msg("%s: the checker rejects the mesh: %s", what, msg);
    free(xy), free(holes), free(seg);
  }
  qk_mesh_free(m);
  qk_poly_free(p);
  return st;
}

#define SQUARE_SEGS "4 0\n0 0 1\n1 1 2\n2 2 3\n3 3 0\n"

static void test_poly_good(void **state) {
  (void)state;
  const char *text = "# a comment line\n"
                     "\n"
                     "4 2 1 1   # vertices with one attribute and a marker\n"
                     "1 1 1 0.5 1\n"
                     "2 3 1 0.5 1\n"
                     "3 3 3 0.5 1\n"
                     "4 1 3 0.5 1\n"
                     "4 1\n"
                     "1 1 2 1\n"
                     "2 2 3 1\n"
                     "3 3 4 1\n"
                     "4 4 1 1\n"
                     "1\n"
                     "1 2 2\n"
                     "1\n"
                     "1 5 5 7 0.1\n";
  FILE *f = from_string(text);
  qk_poly_t *p;
  qk_mesh_error_t err;
  assert_int_equal(qk_poly_read(f, NULL, &p, &err), QK_OK);
  fclose(f);
  size_t nv, ns, nh;
  qk_poly_counts(p, &nv, &ns, &nh);
  assert_int_equal(nv, 4);
  assert_int_equal(ns, 4);
  assert_int_equal(nh, 1);
  assert_int_equal(qk_poly_first_index(p), 1);
  qk_mesh_t *m;
  assert_int_equal(qk_mesh_generate(p, NULL, &m, &err), QK_OK);
  qk_mesh_stats_t s;
  qk_mesh_stats(m, &s);
  assert_int_equal(s.size, 4); /* the smallest power of two >= 3 */
  assert_int_equal(s.components, 1);
  /* The hole at (2,2) removes the square's inside: what is left has area 16 - 4. */
  size_t nt;
  const uint32_t *t = qk_mesh_triangles(m, &nt);
  const double *v = qk_mesh_vertices(m, NULL);
  double area = 0;
  for (size_t i = 0; i < nt; i++) {
    const double *a = &v[2 * t[3 * i]], *b = &v[2 * t[3 * i + 1]], *c = &v[2 * t[3 * i + 2]];
    area += ((b[0] - a[0]) * (c[1] - a[1]) - (b[1] - a[1]) * (c[0] - a[0])) / 2;
  }
  assert_true(area == 12);
  qk_mesh_free(m);
  qk_poly_free(p);
  /* Hole points a hair off a boundary are decided exactly: 1 + (1 + 2^-52) rounds to 2
   * in doubles, yet the point lies strictly inside the diamond x + y > 2. */
#define DIAMOND "4 2 0 0\n0 2 0\n1 4 2\n2 2 4\n3 0 2\n" SQUARE_SEGS
  assert_int_equal(run(DIAMOND "1\n0 1 1.0000000000000002\n", 0, &err), QK_OK);
  assert_int_equal(run(DIAMOND "1\n0 1 1\n", 0, &err), QK_ERR_GEOMETRY);
  /* On the same side with x's fraction at least 1/2 and y's below (the other exact branch). */
  assert_int_equal(run(DIAMOND "1\n0 0.75 1.25\n", 0, &err), QK_ERR_GEOMETRY);
  assert_int_equal(run(DIAMOND "1\n0 3 0.9999999999999999\n", 0, &err), QK_OK);
  assert_int_equal(run(DIAMOND "1\n0 3 1\n", 0, &err), QK_ERR_GEOMETRY);
  assert_int_equal(run(DIAMOND "1\n0 1e-300 2\n", 0, &err), QK_OK);
  assert_int_equal(run(DIAMOND "1\n0 2 4\n", 0, &err), QK_ERR_GEOMETRY);
  /* First index 0, no holes ("0"), no regional attributes (optional, as in Triangle). */
  assert_int_equal(run("4 2 0 0\n0 0 0\n1 2 0\n2 2 2\n3 0 2\n" SQUARE_SEGS "0\n", 0, &err), QK_OK);
  /* A declared boundary marker may be left out of a row (its attributes may not). */
  assert_int_equal(
      run("4 2 1 1\n0 0 0 5\n1 2 0 5 3\n2 2 2 5\n3 0 2 5 3\n" SQUARE_SEGS "0\n", 0, &err), QK_OK);
  /* Regional attributes are read from the columns after their number (numbered 7 and 8, so
   * that reading the number as x would put both outside the square): the diagonal splits
   * the square into a part below it (10) and one above (20). */
  f = from_string("4 2 0 0\n0 0 0\n1 4 0\n2 4 4\n3 0 4\n5 0\n0 0 1\n1 1 2\n2 2 3\n3 3 0\n"
                  "4 0 2\n0\n2\n7 3 1 10\n8 1 3 20 0.5\n");
  assert_int_equal(qk_poly_read(f, NULL, &p, &err), QK_OK);
  fclose(f);
  assert_int_equal(qk_mesh_generate(p, NULL, &m, &err), QK_OK);
  t = qk_mesh_triangles(m, &nt);
  v = qk_mesh_vertices(m, NULL);
  size_t na;
  const double *attr = qk_mesh_triangle_attributes(m, &na);
  assert_non_null(attr);
  assert_int_equal(na, nt);
  for (size_t i = 0; i < nt; i++) {
    double cx = 0, cy = 0;
    for (int k = 0; k < 3; k++) cx += v[2 * t[3 * i + k]], cy += v[2 * t[3 * i + k] + 1];
    assert_true(attr[i] == (cy < cx ? 10 : 20));
  }
  qk_mesh_free(m);
  qk_poly_free(p);
  /* Input vertices keep their own markers (5 to 8 round the square), the vertices inside
   * the unmarked segments none. */
  f = from_string("4 2 0 1\n0 0 0 5\n1 4 0 6\n2 4 4 7\n3 0 4 8\n" SQUARE_SEGS "0\n");
  assert_int_equal(qk_poly_read(f, NULL, &p, &err), QK_OK);
  fclose(f);
  assert_int_equal(qk_mesh_generate(p, NULL, &m, &err), QK_OK);
  size_t nmv;
  v = qk_mesh_vertices(m, &nmv);
  const int32_t *mk = qk_mesh_vertex_markers(m, &nmv);
  assert_non_null(mk);
  for (size_t i = 0; i < nmv; i++) {
    double x = v[2 * i], y = v[2 * i + 1];
    int32_t want = x == 0 && y == 0   ? 5
                   : x == 4 && y == 0 ? 6
                   : x == 4 && y == 4 ? 7
                   : x == 0 && y == 4 ? 8
                                      : 0;
    if (mk[i] != want) fail_msg("vertex (%g, %g): marker %d, not %d", x, y, mk[i], want);
  }
  qk_mesh_free(m);
  qk_poly_free(p);
}

typedef struct bad_case {
  const char *text;
  uint64_t size;
  qk_status_t status;
  unsigned long line;
  const char *words; /* must appear in the message */
} bad_case_t;

static void test_poly_bad(void **state) {
  (void)state;
  static const bad_case_t cases[] = {
      /* Syntax. */
      {"", 0, QK_ERR_PARSE, 0, "empty"},
      {"four 2 0 0\n", 0, QK_ERR_PARSE, 1, "number of vertices"},
      {"4 3 0 0\n", 0, QK_ERR_PARSE, 1, "dimension"},
      {"4 2 0 2\n", 0, QK_ERR_PARSE, 1, "boundary markers"},
      {"0 2 0 0\n", 0, QK_ERR_PARSE, 1, ".node"},
      {"99999999999 2 0 0\n", 0, QK_ERR_LIMIT, 1, "absurd"},
      {"4 2 0 0\n2 0 0\n", 0, QK_ERR_PARSE, 2, "first vertex number"},
      {"4 2 0 0\n0 0 0\n2 2 0\n", 0, QK_ERR_PARSE, 3, "vertex number 1 expected"},
      {"4 2 0 0\n0 0 0\n1 2 x\n", 0, QK_ERR_PARSE, 3, "bad y"},
      {"4 2 0 0\n0 0 0\n1 2 0 7\n", 0, QK_ERR_PARSE, 3, "fields"},
      {"4 2 0 0\n0 0 0\n1 2 0\n", 0, QK_ERR_PARSE, 3, "truncated"},
      {"4 2 0 0\n0 0 0\n1 2 0\n2 2 2\n3 0 2\n", 0, QK_ERR_PARSE, 5, "segment section"},
      {"4 2 0 0\n0 0 0\n1 2 0\n2 2 2\n3 0 2\n4 0\n0 0 1\n1 1 9\n", 0, QK_ERR_PARSE, 8,
       "not a vertex number"},
      /* A vertex number with a fraction is not rounded to a vertex. */
      {"4 2 0 0\n0 0 0\n1 2 0\n2 2 2\n3 0 2\n4 0\n0 0 1\n1 1.5 2\n2 2 3\n3 3 0\n0\n", 0,
       QK_ERR_PARSE, 8, "1.5"},
      {"4 2 0 0\n0 0 0\n1 2 0\n2 2 2\n3 0 2\n4 0\n0 0 1\n", 0, QK_ERR_PARSE, 7, "truncated"},
      {"4 2 0 0\n0 0 0\n1 2 0\n2 2 2\n3 0 2\n" SQUARE_SEGS "1\n", 0, QK_ERR_PARSE, 11, "truncated"},
      /* The hole section is required, as in Triangle: a file cut after the segments would
       * mesh its holes as solid. Named at the file's last line, comments included. */
      {"4 2 0 0\n0 0 0\n1 2 0\n2 2 2\n3 0 2\n" SQUARE_SEGS, 0, QK_ERR_PARSE, 10,
       "the file ends here, where the hole section was expected"},
      {"4 2 0 0\n0 0 0\n1 2 0\n2 2 2\n3 0 2\n" SQUARE_SEGS "# end\n\n", 0, QK_ERR_PARSE, 12,
       "hole section was expected"},
      /* Rows that do not match their section's count: the hint names the count's line. */
      {"5 2 0 0\n0 0 0\n1 2 0\n2 2 2\n3 0 2\n" SQUARE_SEGS "0\n", 0, QK_ERR_PARSE, 6,
       "(fewer vertex rows than the 5 that line 1 declares?)"},
      {"3 2 0 0\n0 0 0\n1 2 0\n2 2 2\n3 0 2\n" SQUARE_SEGS "0\n", 0, QK_ERR_PARSE, 5,
       "(more vertex rows than the 3 that line 1 declares?)"},
      {"4 2 0 0\n0 0 0\n1 2 0\n2 2 2\n3 0 2\n5 0\n0 0 1\n1 1 2\n2 2 3\n3 3 0\n0\n", 0, QK_ERR_PARSE,
       11, "(fewer segment rows than the 5 that line 6 declares?)"},
      {"4 2 0 0\n0 0 0\n1 2 0\n2 2 2\n3 0 2\n3 0\n0 0 1\n1 1 2\n2 2 3\n3 3 0\n0\n", 0, QK_ERR_PARSE,
       10, "(more segment rows than the 3 that line 6 declares?)"},
      {"4 2 0 0\n0 0 0\n1 2 0\n2 2 2\n3 0 2\n" SQUARE_SEGS "0\n0 1 1\n", 0, QK_ERR_PARSE, 12,
       "(more hole rows than the 0 that line 11 declares?)"},
      {"4 2 0 0\n0 0 0\n1 2 0\n2 2 2\n3 0 2\n" SQUARE_SEGS "2\n0 1 1\n0\n", 0, QK_ERR_PARSE, 13,
       "(fewer hole rows than the 2 that line 11 declares?)"},
      {"4 2 0 0\n0 0 0\n1 2 0\n2 2 2\n3 0 2\n" SQUARE_SEGS "0\n1\n0 1 1 5\n1 1 1 5\n", 0,
       QK_ERR_PARSE, 14, "(more region rows than the 1 that line 12 declares?)"},
      /* A malformed header that cannot be a row of the section before: no hint. */
      {"4 2 0 0\n0 0 0\n1 2 0\n2 2 2\n3 0 2\n" SQUARE_SEGS "0 junk\n", 0, QK_ERR_PARSE, 11,
       "hole section header has 2 fields, expected 1"},
      {"4 2 0 0\n0 0 0\n1 2 0\n2 2 2\n3 0 2\n" SQUARE_SEGS "0\n0\nextra\n", 0, QK_ERR_PARSE, 13,
       "unexpected"},
      {"4 2 0 0\n0 0 0\n1 2 0\n2 2 2\n3 0 2\n" SQUARE_SEGS "1\n0 nan 1\n", 0, QK_ERR_PARSE, 12,
       "hole"},
      /* Segment and hole numbers follow the vertices' (they were never checked: a row's
       * position stood for its number, in messages too). */
      {"4 2 0 0\n1 0 0\n2 2 0\n3 2 2\n4 0 2\n4 0\n1 1 2\n1 2 3\n3 3 4\n4 4 1\n0\n", 0, QK_ERR_PARSE,
       8, "segment number 2 expected, found 1"},
      {"4 2 0 0\n0 0 0\n1 2 0\n2 2 2\n3 0 2\n4 0\n0 0 1\n1 1 2\n2 2 3\n-5 3 0\n0\n", 0,
       QK_ERR_PARSE, 10, "segment number 3 expected, found -5"},
      {"4 2 0 0\n1 0 0\n2 2 0\n3 2 2\n4 0 2\n4 0\n0 1 2\n1 2 3\n2 3 4\n3 4 1\n0\n", 0, QK_ERR_PARSE,
       7, "segment number 1 expected, found 0"},
      {"4 2 0 0\n0 0 0\n1 2 0\n2 2 2\n3 0 2\n" SQUARE_SEGS "2\n0 1 1\n0 1 1\n", 0, QK_ERR_PARSE, 13,
       "hole number 1 expected, found 0"},
      /* Every declared vertex attribute, the marker optional (a row short of one was read). */
      {"4 2 2 0\n0 0 0 5 6\n1 2 0 5\n2 2 2 5 6\n3 0 2 5 6\n" SQUARE_SEGS "0\n", 0, QK_ERR_PARSE, 3,
       "vertex 1: 4 fields, expected 5 (number, x, y and the 2 attributes that line 1 declares)"},
      {"4 2 1 1\n0 0 0\n1 2 0 5\n2 2 2 5\n3 0 2 5\n" SQUARE_SEGS "0\n", 0, QK_ERR_PARSE, 2,
       "vertex 0: 3 fields, expected 4 (number, x, y and the 1 attribute that line 1 declares, "
       "then an optional boundary marker)"},
      /* Geometry. */
      {"4 2 0 0\n0 0 0\n1 2.5 0\n2 2 2\n3 0 2\n" SQUARE_SEGS "0\n", 0, QK_ERR_GEOMETRY, 3,
       "not integers"},
      {"4 2 0 0\n0 0 0\n1 20 0\n2 20 2\n3 0 2\n" SQUARE_SEGS "0\n", 16, QK_ERR_GEOMETRY, 3,
       "outside the domain"},
      {"4 2 0 0\n0 0 0\n1 -2 0\n2 2 2\n3 0 2\n" SQUARE_SEGS "0\n", 0, QK_ERR_GEOMETRY, 3,
       "outside the domain"},
      {"4 2 0 0\n0 0 0\n1 3 0\n2 2 2\n3 0 2\n" SQUARE_SEGS "0\n", 0, QK_ERR_GEOMETRY, 8, "degrees"},
      {"4 2 0 0\n0 0 0\n1 2 0\n2 2 2\n3 0 2\n3 0\n0 0 1\n1 1 2\n2 2 3\n0\n", 0, QK_ERR_GEOMETRY, 2,
       "open chain"},
      {"5 2 0 0\n0 0 0\n1 2 0\n2 2 2\n3 0 2\n4 3 3\n" SQUARE_SEGS "0\n", 0, QK_ERR_GEOMETRY, 6,
       "degree 0"},
      {"5 2 0 0\n0 0 0\n1 2 0\n2 2 2\n3 0 2\n4 4 4\n5 0\n0 0 1\n1 1 2\n2 2 3\n3 3 0\n4 2 4\n0\n", 0,
       QK_ERR_GEOMETRY, 12, "degree more than 2"},
      {"4 2 0 0\n0 0 0\n1 2 0\n2 2 2\n3 0 0\n" SQUARE_SEGS "0\n", 0, QK_ERR_GEOMETRY, 5,
       "coincide"},
      {"2 2 0 0\n0 0 0\n1 2 2\n2 0\n0 0 1\n1 1 0\n0\n", 0, QK_ERR_GEOMETRY, 6, "coincide"},
      /* A bow tie: the diagonals cross at (1,1). */
      {"4 2 0 0\n0 0 0\n1 2 0\n2 0 2\n3 2 2\n" SQUARE_SEGS "0\n", 0, QK_ERR_GEOMETRY, 0,
       "intersects itself"},
      /* Two squares sharing a corner point. */
      {"8 2 0 0\n0 0 0\n1 2 0\n2 2 2\n3 0 2\n4 2 2\n5 4 2\n6 4 4\n7 2 4\n8 0\n0 0 1\n1 1 2\n"
       "2 2 3\n3 3 0\n4 4 5\n5 5 6\n6 6 7\n7 7 4\n0\n",
       0, QK_ERR_GEOMETRY, 0, "coincide"},
      /* A corner of one square on the other's edge. */
      {"8 2 0 0\n0 0 0\n1 4 0\n2 4 4\n3 0 4\n4 4 2\n5 5 1\n6 6 2\n7 5 3\n8 0\n0 0 1\n1 1 2\n"
       "2 2 3\n3 3 0\n4 4 5\n5 5 6\n6 6 7\n7 7 4\n0\n",
       0, QK_ERR_GEOMETRY, 0, "touch or cross"},
      /* Two crossing rectangles. */
      {"8 2 0 0\n0 1 0\n1 3 0\n2 3 6\n3 1 6\n4 0 2\n5 6 2\n6 6 4\n7 0 4\n8 0\n0 0 1\n1 1 2\n"
       "2 2 3\n3 3 0\n4 4 5\n5 5 6\n6 6 7\n7 7 4\n0\n",
       0, QK_ERR_GEOMETRY, 0, "touch or cross"},
      /* A polygon doubling back along itself. */
      {"4 2 0 0\n0 0 0\n1 4 0\n2 2 0\n3 2 2\n" SQUARE_SEGS "0\n", 0, QK_ERR_GEOMETRY, 0, "itself"},
      {"4 2 0 0\n0 0 0\n1 2 0\n2 2 2\n3 0 2\n" SQUARE_SEGS "1\n0 9 1\n", 4, QK_ERR_GEOMETRY, 12,
       "outside the domain"},
      {"4 2 0 0\n0 0 0\n1 2 0\n2 2 2\n3 0 2\n" SQUARE_SEGS "1\n0 1 2\n", 4, QK_ERR_GEOMETRY, 12,
       "boundary"},
      {"4 2 0 0\n0 0 0\n1 2 0\n2 2 2\n3 0 2\n" SQUARE_SEGS "0\n", 12, QK_ERR_INVALID, 0,
       "power of two"},
  };
  /* A NUL byte: binary data, named with its line. */
  {
    FILE *f = tmpfile();
    assert_non_null(f);
    fwrite("4 2 0 0\n0 0\0 0\n", 1, 16, f);
    rewind(f);
    qk_poly_t *p = NULL;
    qk_mesh_error_t err;
    assert_int_equal(qk_poly_read(f, NULL, &p, &err), QK_ERR_PARSE);
    fclose(f);
    assert_int_equal(err.line, 2);
    assert_non_null(strstr(err.message, "binary"));
  }
  for (size_t i = 0; i < sizeof cases / sizeof *cases; i++) {
    qk_mesh_error_t err;
    qk_status_t st = run(cases[i].text, cases[i].size, &err);
    if (st != cases[i].status || (cases[i].line && err.line != cases[i].line) ||
        !strstr(err.message, cases[i].words))
      fail_msg("case %zu: status %s line %lu '%s'; expected %s line %lu '%s'", i, qk_strerror(st),
               err.line, err.message, qk_strerror(cases[i].status), cases[i].line, cases[i].words);
  }
  /* The rows hint only where the line could be a row of the section before. */
  {
    qk_mesh_error_t err;
    assert_int_equal(run("4 2 0 0\n0 0 0\n1 2 0\n2 2 2\n3 0 2\n" SQUARE_SEGS "0 junk\n", 0, &err),
                     QK_ERR_PARSE);
    assert_string_equal(err.message, "hole section header has 2 fields, expected 1");
  }
}

/* Random mutations of a valid file: every outcome is success or a clean error with a
 * message (run under ASan/UBSan in CI, this is a small fuzzer). */
static void test_poly_mutations(void **state) {
  (void)state;
  static const char base[] = "# two squares and a diamond inside one\n"
                             "12 2 0 0\n0 0 0\n1 6 0\n2 6 6\n3 0 6\n4 8 8\n5 12 8\n"
                             "6 12 12\n7 8 12\n8 3 1\n9 5 3\n10 3 5\n11 1 3\n"
                             "12 0\n0 0 1\n1 1 2\n2 2 3\n3 3 0\n4 4 5\n5 5 6\n6 6 7\n"
                             "7 7 4\n8 8 9\n9 9 10\n10 10 11\n11 11 8\n1\n0 10 10\n";
  static const char alphabet[] = "0123456789 -.\n#e+x";
  uint64_t seed = qkt_seed(31337);
  qkt_rng_t r;
  qkt_rng_seed(&r, seed);
  char buf[sizeof base + 64];
  size_t ok = 0;
  for (int round = 0; round < 3000; round++) {
    size_t n = sizeof base - 1;
    memcpy(buf, base, n);
    int edits = 1 + (int)qkt_rng_below(&r, 3);
    for (int e = 0; e < edits; e++) {
      size_t at = qkt_rng_below(&r, (uint32_t)n);
      char c = alphabet[qkt_rng_below(&r, sizeof alphabet - 1)];
      switch (qkt_rng_below(&r, 3)) {
      case 0:
        buf[at] = c;
        break;
      case 1:
        if (n + 1 < sizeof buf) memmove(buf + at + 1, buf + at, n - at), buf[at] = c, n++;
        break;
      default:
        memmove(buf + at, buf + at + 1, n - at - 1), n--;
        break;
      }
    }
    buf[n] = '\0';
    qk_mesh_error_t err;
    /* A fixed small domain, so that a mutated coordinate cannot ask for a huge mesh. */
    char what[64];
    snprintf(what, sizeof what, "seed %llu round %d", (unsigned long long)seed, round);
    qk_status_t st = run_checked(buf, 64, &err, what);
    if (st == QK_OK) {
      ok++;
      continue;
    }
    if ((st != QK_ERR_PARSE && st != QK_ERR_GEOMETRY && st != QK_ERR_LIMIT) || !err.message[0])
      fail_msg("seed %llu round %d: status %s, message '%s'", (unsigned long long)seed, round,
               qk_strerror(st), err.message);
  }
  print_message("%zu of 3000 mutated files were valid\n", ok);
  /* Most single-character edits break the file; but a run where (almost) none survive
   * would check nothing. About 10% do at this seed; demand a floor well below that. */
  if (ok < 100)
    fail_msg("seed %llu: only %zu of 3000 mutants meshed", (unsigned long long)seed, ok);
}

static void test_poly_alloc_failure(void **state) {
  (void)state;
  const char *text = "4 2 0 0\n0 0 0\n1 2 0\n2 2 2\n3 0 2\n" SQUARE_SEGS "1\n0 1 1\n";
  for (size_t fail_at = 1;; fail_at++) {
    qkt_alloc_t st;
    qk_allocator_t a = qkt_alloc_make(&st);
    st.fail_at = fail_at;
    FILE *f = from_string(text);
    qk_poly_t *p = NULL;
    qk_mesh_error_t err;
    qk_status_t s = qk_poly_read(f, &a, &p, &err);
    fclose(f);
    qk_poly_free(p);
    assert_int_equal(st.live_bytes, 0);
    if (!st.failed) {
      assert_int_equal(s, QK_OK);
      break;
    }
    assert_int_equal(s, QK_ERR_NOMEM);
    assert_true(fail_at < 1000);
  }
}

/* The allocator of test_poly_endless_line: qkt_alloc_fn, with the peak of live bytes. */
typedef struct peak_alloc {
  qkt_alloc_t a;
  size_t peak;
} peak_alloc_t;

static void *peak_fn(void *ud, void *ptr, size_t osize, size_t nsize) {
  peak_alloc_t *p = ud;
  void *q = qkt_alloc_fn(&p->a, ptr, osize, nsize);
  if (p->a.live_bytes > p->peak) p->peak = p->a.live_bytes;
  return q;
}

/* A line without end (32 MiB of digits, no line break; an endless pipe through the
 * library API, which the command line's screen does not guard) is refused at 1 MiB on
 * its line, with the reader's memory under 4 MiB (its buffer doubles to 2 MiB); the same after a
 * good first line. */
static void test_poly_endless_line(void **state) {
  (void)state;
  const size_t big = (size_t)32 << 20;
  for (int lead = 0; lead < 2; lead++) {
    FILE *f = tmpfile();
    assert_non_null(f);
    if (lead) fputs("4 2 0 0\n", f);
    char chunk[4096];
    memset(chunk, '7', sizeof chunk);
    for (size_t w = 0; w < big; w += sizeof chunk) fwrite(chunk, 1, sizeof chunk, f);
    rewind(f);
    peak_alloc_t pa = {.peak = 0};
    memset(&pa.a, 0, sizeof pa.a);
    qk_allocator_t a = {peak_fn, &pa};
    qk_poly_t *p = NULL;
    qk_mesh_error_t err;
    qk_status_t st = qk_poly_read(f, &a, &p, &err);
    fclose(f);
    assert_int_equal(st, QK_ERR_LIMIT);
    assert_null(p);
    assert_int_equal(err.line, 1 + lead);
    assert_non_null(strstr(err.message, "line longer than 1048576 bytes"));
    assert_int_equal(pa.a.live_bytes, 0);
    if (pa.peak > ((size_t)4 << 20)) fail_msg("lead %d: peak %zu bytes", lead, pa.peak);
  }
}

/* qk_poly_round: vertices rounded in place (ties to even), numbers, lines and holes kept;
 * a coordinate that would round past the largest double leaves everything unchanged. */
static void test_poly_round(void **state) {
  (void)state;
  FILE *f = from_string("3 2 0 1\n1 0.5 1.5 3\n2 4.25 -0.75 3\n3 -2.5 4 4\n3 1\n1 1 2 9\n"
                        "2 2 3 9\n3 3 1 9\n1\n1 0.3 0.3\n");
  qk_poly_t *p;
  qk_mesh_error_t err;
  assert_int_equal(qk_poly_read(f, NULL, &p, &err), QK_OK);
  fclose(f);
  size_t changed = 99;
  assert_int_equal(qk_poly_round(p, 0, &changed), QK_ERR_INVALID);
  assert_int_equal(qk_poly_round(p, NAN, &changed), QK_ERR_INVALID);
  assert_int_equal(qk_poly_round(NULL, 1, &changed), QK_ERR_INVALID);
  assert_int_equal(qk_poly_round(p, 1, &changed), QK_OK);
  assert_int_equal(changed, 5); /* 0.5, 1.5, 4.25, -0.75, -2.5 move; 4 does not */
  double xy[6], h[2];
  size_t n;
  qk_poly_vertices(p, xy, 3, &n);
  const double want[6] = {0, 2, 4, -1, -2, 4}; /* nearest, ties to even */
  for (int i = 0; i < 6; i++) assert_true(xy[i] == want[i]);
  qk_poly_holes(p, h, 1, &n);
  assert_true(h[0] == 0.3 && h[1] == 0.3);
  assert_int_equal(qk_poly_first_index(p), 1);
  qk_poly_free(p);
  f = from_string("2 2 0 0\n1 1.7976931348623157e308 0\n2 0 1\n0 0\n0\n");
  assert_int_equal(qk_poly_read(f, NULL, &p, &err), QK_OK);
  fclose(f);
  assert_int_equal(qk_poly_round(p, 0x1p1000, &changed), QK_ERR_NONFINITE);
  assert_int_equal(changed, 0);
  qk_poly_vertices(p, xy, 2, &n);
  assert_true(xy[0] == 1.7976931348623157e308 && xy[3] == 1);
  qk_poly_free(p);
  /* A fine step under a large coordinate: the quotient overflows (1e10 / 1e-300) or
   * passes 2^53, but the coordinate is a multiple to within half an ulp and stays (it was
   * refused as QK_ERR_NONFINITE); 2^-1074 changes nothing anywhere. */
  f = from_string("2 2 0 0\n1 1e10 0.1\n2 -3e200 4503599627370497\n0 0\n0\n");
  assert_int_equal(qk_poly_read(f, NULL, &p, &err), QK_OK);
  fclose(f);
  const double steps[] = {1e-300, 0x1p-1074, 0x1p-20};
  for (int k = 0; k < 3; k++) {
    assert_int_equal(qk_poly_round(p, steps[k], &changed), QK_OK);
    qk_poly_vertices(p, xy, 2, &n);
    assert_true(xy[0] == 1e10 && xy[2] == -3e200 && xy[3] == 4503599627370497.0);
    assert_true(xy[1] == (k < 2 ? 0.1 : nearbyint(0.1 * 0x1p20) * 0x1p-20));
    assert_int_equal(changed, k < 2 ? 0 : 1);
  }
  qk_poly_free(p);
  /* A step that is no power of two can be up to two ulps from 2^52 steps on: there the
   * coordinate still moves to the multiple (it was kept, 1.5 from it, for a while) */
  f = from_string("2 2 0 0\n1 15762598695796738 0\n2 0 1\n0 0\n0\n");
  assert_int_equal(qk_poly_read(f, NULL, &p, &err), QK_OK);
  fclose(f);
  assert_int_equal(qk_poly_round(p, 3.5, &changed), QK_OK);
  qk_poly_vertices(p, xy, 2, &n);
  assert_true(xy[0] == nearbyint(15762598695796738.0 / 3.5) * 3.5 && xy[0] != 15762598695796738.0);
  qk_poly_free(p);
}

/* The .poly text read, rounded to step (0: not rounded; *changed as qk_poly_round says,
 * when not NULL) and meshed in the general mode: qk_mesh_generate's status, the mesh in
 * *m. */
static qk_status_t rounded_general(const char *text, double step, size_t *changed, qk_mesh_t **m,
                                   qk_mesh_error_t *err) {
  FILE *f = from_string(text);
  qk_poly_t *p;
  assert_int_equal(qk_poly_read(f, NULL, &p, err), QK_OK);
  fclose(f);
  if (step > 0) assert_int_equal(qk_poly_round(p, step, changed), QK_OK);
  qk_mesh_options_t o;
  qk_mesh_options_init(&o);
  o.mode = QK_MESH_GENERAL;
  qk_status_t st = qk_mesh_generate(p, &o, m, err);
  qk_poly_free(p);
  return st;
}

/*
 * A hole point (or a regional attribute point) left as read, close to a hole's edge that
 * qk_poly_round moved across it: the square's face was dropped and the hole meshed (16
 * triangles, area 0.3 instead of 99.7). qk_mesh_generate refuses it, naming the point's
 * line and the segment; one farther from the segments than the grid meshes the square.
 */
static void test_poly_round_holes(void **state) {
  (void)state;
  static const char *square = "8 2 0 0\n0 0 0\n1 10 0\n2 10 10\n3 0 10\n4 4 4.0500001\n"
                              "5 6 4.0500001\n6 6 4.2\n7 4 4.2\n8 0\n0 0 1\n1 1 2\n2 2 3\n"
                              "3 3 0\n4 4 5\n5 5 6\n6 6 7\n7 7 4\n";
  const char *tails[] = {"1\n0 5 4.05000015\n", "0\n1\n0 5 4.05000015 7\n", "1\n0 5 4.1\n"};
  for (int k = 0; k < 3; k++) {
    char text[512];
    snprintf(text, sizeof text, "%s%s", square, tails[k]);
    for (int rounded = 0; rounded < 2; rounded++) {
      qk_mesh_t *m = NULL;
      qk_mesh_error_t err;
      qk_status_t st = rounded_general(text, rounded ? 0x1p-22 : 0, NULL, &m, &err);
      if (rounded && k < 2) {
        assert_int_equal(st, QK_ERR_GEOMETRY);
        assert_int_equal(err.line, k == 0 ? 20 : 21);
        if (!strstr(err.message, k == 0 ? "hole 0 at (5, 4.05" : "region point 0") ||
            !strstr(err.message, "segment 4 (vertices 4 to 5)"))
          fail_msg("%s", err.message);
        assert_null(m);
      } else {
        if (st != QK_OK) fail_msg("case %d, rounded %d: %s", k, rounded, err.message);
        qk_mesh_stats_t ms;
        qk_mesh_stats(m, &ms);
        /* the square less the hole (k != 1), or all of it with the inner square a region */
        assert_true(ms.triangles > 40);
        qk_mesh_free(m);
      }
    }
  }
  /* Rounding that moves nothing near the hole refuses it not: a hole point 0.5 from an
   * edge of integers (refused in the first version, which measured against the grid's
   * step) and 0.3 from one, while a vertex far off, (10, 5.45), moves 0.45 (refused in the
   * second, which measured against the largest move of any vertex). */
  size_t changed = 9;
  qk_mesh_t *m = NULL;
  qk_mesh_error_t err;
  if (rounded_general("9 2 0 0\n1 0 0\n2 10 0\n3 10 10\n4 0 10\n5 4 4\n6 6 4\n7 6 6\n8 4 6\n"
                      "9 10 5.45\n9 0\n1 1 2\n2 2 9\n3 9 3\n4 3 4\n5 4 1\n6 5 6\n7 6 7\n"
                      "8 7 8\n9 8 5\n2\n1 4.5 5\n2 5 4.3\n",
                      1, &changed, &m, &err) != QK_OK)
    fail_msg("%s", err.message);
  assert_int_equal(changed, 1);
  qk_mesh_free(m);
}

int main(void) {
  const struct CMUnitTest tests[] = {
      cmocka_unit_test(test_poly_round_holes),   cmocka_unit_test(test_poly_good),
      cmocka_unit_test(test_poly_bad),           cmocka_unit_test(test_poly_mutations),
      cmocka_unit_test(test_poly_alloc_failure), cmocka_unit_test(test_poly_round),
      cmocka_unit_test(test_poly_endless_line),
  };
  return cmocka_run_group_tests(tests, NULL, NULL);
}
