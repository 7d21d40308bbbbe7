/*
 * The GeoJSON reader on unusual input found by a review with hostile files:
 *  - a UTF-8 byte order mark before the text is ignored (RFC 8259 allows it; it was a
 *    "malformed JSON" error);
 *  - a "type" that is not one of RFC 7946's (a typo: "FeatureColection", "polygon") is
 *    an error naming the feature, not a silently skipped, empty layer;
 *  - RFC 7946's other geometry types are still skipped and counted, but their
 *    coordinates are read as strictly as a polygon's: a malformed point or line is an
 *    error at its line and column (it was skipped without a word);
 *  - malformed JSON gives its line and column in qk_error_t, not repeated in the
 *    message (the CLI printed "f.geojson:1:61: line 1, column 61: ...");
 *  - a GeometryCollection's polygons (nested ones too) are the feature's (they were
 *    skipped as if it had no area);
 *  - a NUL byte, anywhere, and trailing commas are errors with their position (json-c
 *    took a NUL after the value for a blank and accepted "[0,0],]");
 *  - an error inside valid JSON (a short or open ring, a wrong type, a coordinate beyond
 *    the largest double, an unknown geometry type, lon/lat out of range) gives the line
 *    and column of the offending value, besides the feature index (it gave no line).
 *    Oracle: the offset of a marked substring of the text, counted into line and column.
 *  - a property value holding "\u0000" is refused at its position (a property is a C
 *    string: join wrote the value cut short there);
 *  - qk_region_find_json_pointer (the same path following, public for the mesher's
 *    messages): a JSON Pointer's value, escapes (~0, ~1) in names, an index past the end
 *    (the deepest value found), a byte order mark; malformed pointers refused;
 *  - a FeatureCollection is read one feature at a time (json-c's tree of a whole file
 *    took nine times its size): the layer is the one the whole-text reading gives, and
 *    JSON that reading refuses is refused the same way. Oracle: the whole-text reading
 *    (qk__geojson_read_whole): stats, properties and locate_all over a grid compared; on
 *    errors the status, message, item, line and column; the countries file too when
 *    present.
 */
#include "support/qk_test.h"

#include "region/region_internal.h"

#include <string.h>

#ifdef QK_HAVE_JSONC
static qk_status_t read_text(const char *text, qk_region_t **r, qk_error_t *err) {
  qk_region_options_t o;
  qk_region_options_init(&o);
  o.planar = 1;
  return qk_region_read_geojson_text(text, strlen(text), &o, r, err);
}

static qk_status_t read_text_with(const char *text, const qk_region_options_t *o, qk_region_t **r,
                                  qk_error_t *err) {
  return qk_region_read_geojson_text(text, strlen(text), o, r, err);
}

#define SQUARE "{\"type\":\"Polygon\",\"coordinates\":[[[0,0],[1,0],[1,1],[0,1],[0,0]]]}"
#endif

static void test_geojson_bom(void **state) {
  (void)state;
#ifndef QK_HAVE_JSONC
  skip();
#else
  qk_region_t *r = NULL;
  qk_error_t err;
  assert_int_equal(read_text("\xEF\xBB\xBF" SQUARE, &r, &err), QK_OK);
  uint32_t f = QK_NONE;
  assert_int_equal(qk_region_locate(r, (qk_point_t){0.5, 0.5}, QK_BOUNDARY_SEMI_OPEN, &f), QK_OK);
  assert_int_equal(f, 0);
  qk_region_free(r);
  /* A BOM alone is an empty document; a BOM in the middle is still an error. */
  assert_int_equal(read_text("\xEF\xBB\xBF", &r, &err), QK_ERR_PARSE);
  assert_null(r);
  /* ... reported as one, as an empty file is (the sweep: a BOM stripped only when text
   * followed it was refused as a bad character instead, passing every test). */
  assert_string_equal(err.message, "unexpected end of input");
  assert_int_equal(err.line, 1);
  assert_int_equal(err.column, 1);
  assert_int_equal(read_text(" \xEF\xBB\xBF" SQUARE, &r, &err), QK_ERR_PARSE);
  assert_null(r);
#endif
}

static void test_geojson_unknown_types(void **state) {
  (void)state;
#ifndef QK_HAVE_JSONC
  skip();
#else
  qk_region_t *r = NULL;
  qk_error_t err;
  assert_int_equal(read_text("{\"type\":\"FeatureColection\",\"features\":[]}", &r, &err),
                   QK_ERR_PARSE);
  assert_null(r);
  assert_non_null(strstr(err.message, "unknown GeoJSON type \"FeatureColection\""));
  const char *lower = "{\"type\":\"FeatureCollection\",\"features\":[{\"type\":\"Feature\","
                      "\"properties\":{},\"geometry\":" SQUARE "},{\"type\":\"Feature\","
                      "\"properties\":{},\"geometry\":{\"type\":\"polygon\","
                      "\"coordinates\":[]}}]}";
  assert_int_equal(read_text(lower, &r, &err), QK_ERR_PARSE);
  assert_null(r);
  assert_int_equal(err.item, 1);
  assert_non_null(strstr(err.message, "feature 1: unknown geometry type \"polygon\""));
  /* RFC 7946's other types: skipped and counted, indices kept. */
  const char *mixed = "{\"type\":\"FeatureCollection\",\"features\":["
                      "{\"type\":\"Feature\",\"properties\":{},\"geometry\":{\"type\":\"Point\","
                      "\"coordinates\":[0,0]}},"
                      "{\"type\":\"Feature\",\"properties\":{},\"geometry\":{\"type\":"
                      "\"GeometryCollection\",\"geometries\":[]}},"
                      "{\"type\":\"Feature\",\"properties\":{},\"geometry\":" SQUARE "}]}";
  assert_int_equal(read_text(mixed, &r, &err), QK_OK);
  qk_region_stats_t s;
  qk_region_stats(r, &s);
  assert_int_equal(s.skipped, 2);
  uint32_t f = QK_NONE;
  assert_int_equal(qk_region_locate(r, (qk_point_t){0.5, 0.5}, QK_BOUNDARY_SEMI_OPEN, &f), QK_OK);
  assert_int_equal(f, 2);
  qk_region_free(r);
  assert_int_equal(read_text("{\"type\":\"LineString\",\"coordinates\":[[0,0],[1,1]]}", &r, &err),
                   QK_OK);
  qk_region_free(r);
#endif
}

static void test_geojson_error_position(void **state) {
  (void)state;
#ifndef QK_HAVE_JSONC
  skip();
#else
  qk_region_t *r = NULL;
  qk_error_t err;
  assert_int_equal(read_text("{\n  \"type\": \"Polygon\",\n  \"coordinates\": [[[0,0],", &r, &err),
                   QK_ERR_PARSE);
  assert_int_equal(err.line, 3);
  assert_true(err.column > 1);
  assert_string_equal(err.message, "unexpected end of input");
  assert_int_equal(read_text("{\"type\": @}", &r, &err), QK_ERR_PARSE);
  assert_int_equal(err.line, 1);
  assert_non_null(strstr(err.message, "malformed JSON"));
  assert_null(strstr(err.message, "line"));
  assert_int_equal(read_text(SQUARE "\n x", &r, &err), QK_ERR_PARSE);
  assert_int_equal(err.line, 2);
  assert_int_equal(err.column, 2);
  assert_string_equal(err.message, "unexpected text after the JSON value");
#endif
}

static void test_geojson_collection_and_strict(void **state) {
  (void)state;
#ifndef QK_HAVE_JSONC
  skip();
#else
  qk_region_t *r = NULL;
  qk_error_t err;
  const char *gc = "{\"type\":\"GeometryCollection\",\"geometries\":[{\"type\":\"Point\","
                   "\"coordinates\":[5,5]}," SQUARE ",{\"type\":\"GeometryCollection\","
                   "\"geometries\":[{\"type\":\"MultiPolygon\",\"coordinates\":[[[[2,0],[3,0],"
                   "[3,1],[2,1],[2,0]]]]}]}]}";
  assert_int_equal(read_text(gc, &r, &err), QK_OK);
  const qk_point_t p[3] = {{0.5, 0.5}, {2.5, 0.5}, {1.5, 0.5}};
  const uint32_t want[3] = {0, 0, QK_NONE};
  for (int i = 0; i < 3; i++) {
    uint32_t f = 7;
    assert_int_equal(qk_region_locate(r, p[i], QK_BOUNDARY_SEMI_OPEN, &f), QK_OK);
    assert_int_equal(f, want[i]);
  }
  qk_region_stats_t st;
  qk_region_stats(r, &st);
  assert_int_equal(st.skipped, 0);
  qk_region_free(r);
  /* A collection without area is skipped and counted, like a Point. */
  assert_int_equal(read_text("{\"type\":\"GeometryCollection\",\"geometries\":[]}", &r, &err),
                   QK_OK);
  qk_region_stats(r, &st);
  assert_int_equal(st.skipped, 1);
  qk_region_free(r);
  assert_int_equal(read_text("{\"type\":\"GeometryCollection\"}", &r, &err), QK_ERR_PARSE);
  assert_non_null(strstr(err.message, "\"geometries\""));
  /* NUL bytes: after the value, and inside it. */
  static const char nul_after[] = SQUARE "\0\n";
  assert_int_equal(qk_region_read_geojson_text(nul_after, sizeof nul_after - 1, NULL, &r, &err),
                   QK_ERR_PARSE);
  assert_null(r);
  assert_int_equal(err.line, 1);
  assert_int_equal(err.column, sizeof SQUARE);
  assert_string_equal(err.message, "binary data (NUL byte) in a text file");
  static const char nul_in[] = "{\"type\":\n\"Poly\0gon\"}";
  assert_int_equal(qk_region_read_geojson_text(nul_in, sizeof nul_in - 1, NULL, &r, &err),
                   QK_ERR_PARSE);
  assert_int_equal(err.line, 2);
  assert_int_equal(err.column, 6);
  /* Trailing commas. */
  assert_int_equal(
      read_text("{\"type\":\"Polygon\",\"coordinates\":[[[0,0],[1,0],[1,1],[0,0],]]}", &r, &err),
      QK_ERR_PARSE);
  assert_null(r);
  assert_non_null(strstr(err.message, "malformed JSON"));
  assert_int_equal(read_text("{\"type\":\"Polygon\",\"coordinates\":[],}", &r, &err), QK_ERR_PARSE);
#endif
}

#ifdef QK_HAVE_JSONC
/* The 1-based line and column of the first occurrence of `mark` in `text`. */
static void mark_at(const char *text, const char *mark, unsigned long *line, unsigned long *col) {
  const char *p = strstr(text, mark);
  assert_non_null(p);
  *line = 1, *col = 1;
  for (const char *q = text; q < p; q++) {
    if (*q == '\n')
      ++*line, *col = 1;
    else
      ++*col;
  }
}

/* text is refused with status st, feature f, and a position at `mark`. */
static void refused_at(const char *text, int planar, qk_status_t st, size_t f, const char *mark,
                       const char *words) {
  qk_region_options_t o;
  qk_region_options_init(&o);
  o.planar = planar;
  qk_region_t *r = NULL;
  qk_error_t err;
  unsigned long line, col;
  mark_at(text, mark, &line, &col);
  qk_status_t got = qk_region_read_geojson_text(text, strlen(text), &o, &r, &err);
  if (got != st || err.item != f || err.line != line || err.column != col ||
      !strstr(err.message, words))
    fail_msg("got %s item %zu at %lu:%lu '%s'; want %s item %zu at %lu:%lu '%s'", qk_strerror(got),
             err.item, err.line, err.column, err.message, qk_strerror(st), f, line, col, words);
  assert_null(r);
}
#endif

static void test_geojson_semantic_position(void **state) {
  (void)state;
#ifndef QK_HAVE_JSONC
  skip();
#else
#define FC_HEAD                                                                                    \
  "{\"type\": \"FeatureCollection\",\n \"features\": [\n"                                          \
  "  {\"type\": \"Feature\", \"properties\": {\"name\": \"ok\"},\n   \"geometry\": " SQUARE "},\n"
  /* a ring of 3 positions, on its own line, in feature 1 */
  refused_at(FC_HEAD "  {\"type\": \"Feature\", \"properties\": {\"n\": 1},\n"
                     "   \"geometry\": {\"type\": \"Polygon\", \"coordinates\": [\n"
                     "     [[0,0],[1,0],[0,0]]\n   ]}}\n ]}\n",
             1, QK_ERR_GEOMETRY, 1, "[[0,0],[1,0],[0,0]]", "3 positions");
  /* a coordinate beyond the largest double: the number itself */
  refused_at(FC_HEAD "  {\"type\": \"Feature\", \"properties\": null, \"geometry\":\n"
                     "   {\"type\": \"Polygon\", \"coordinates\": [[[0,0],[1,0],\n"
                     "    [1, 2e308],[0,0]]]}}]}",
             1, QK_ERR_NONFINITE, 1, "2e308", "beyond the largest double");
  /* a nonzero coordinate below the smallest double, which json-c reads as 0 (it was
   * taken as 0; eighteenth session), in either place, also written without exponent */
  refused_at(FC_HEAD "  {\"type\": \"Feature\", \"properties\": null, \"geometry\":\n"
                     "   {\"type\": \"Polygon\", \"coordinates\": [[[0,0],[1,0],\n"
                     "    [1, 1e-400],[0,0]]]}}]}",
             1, QK_ERR_GEOMETRY, 1, "1e-400", "below the smallest double");
  refused_at(FC_HEAD "  {\"type\": \"Feature\", \"properties\": null, \"geometry\":\n"
                     "   {\"type\": \"Polygon\", \"coordinates\": [[[0,0],[1,0],\n"
                     "    [-2.5E-999, 1],[0,0]]]}}]}",
             1, QK_ERR_GEOMETRY, 1, "-2.5E-999", "below the smallest double");
  /* a position that is not two numbers */
  refused_at(FC_HEAD "  {\"type\": \"Feature\", \"properties\": {}, \"geometry\":\n"
                     "   {\"type\": \"Polygon\", \"coordinates\": [[[0,0],[1,0],\n"
                     "    [1,\"a\"],[0,0]]]}}]}",
             1, QK_ERR_PARSE, 1, "[1,\"a\"]", "expected [x, y] numbers");
  /* a third element that is not a number (the altitude is not used, but it is part of the
   * position; it was accepted without a word) */
  refused_at(FC_HEAD "  {\"type\": \"Feature\", \"properties\": {}, \"geometry\":\n"
                     "   {\"type\": \"Polygon\", \"coordinates\": [[[0,0],[1,0],\n"
                     "    [1,1,\"a\"],[0,0]]]}}]}",
             1, QK_ERR_PARSE, 1, "[1,1,\"a\"]", "expected [x, y] numbers");
  /* an unknown geometry type: the geometry object */
  refused_at(FC_HEAD "  {\"type\": \"Feature\", \"properties\": {},\n"
                     "   \"geometry\": {\"type\": \"Polgon\", \"coordinates\": []}}]}",
             1, QK_ERR_PARSE, 1, "{\"type\": \"Polgon\"", "unknown geometry type");
  /* a feature that is not a Feature: the element itself */
  refused_at(FC_HEAD "  {\"type\": \"Feat\", \"geometry\": null}]}", 1, QK_ERR_PARSE, 1,
             "{\"type\": \"Feat\"", "expected an object with \"type\": \"Feature\"");
  /* "coordinates" of the wrong type: its value */
  refused_at(FC_HEAD "  {\"type\": \"Feature\", \"properties\": {},\n"
                     "   \"geometry\": {\"type\": \"Polygon\", \"coordinates\": {\"a\": 1}}}]}",
             1, QK_ERR_PARSE, 1, "{\"a\": 1}", "\"coordinates\" must be an array, found object");
  /* a property value holding "\u0000" (a C string would end there): the value */
  refused_at(FC_HEAD "  {\"type\": \"Feature\", \"geometry\": null,\n"
                     "   \"properties\": {\"a\": 1, \"n\": \"x\\u0000y\"}}]}",
             1, QK_ERR_PARSE, 1, "\"x\\u0000y\"", "property \"n\" holds a NUL character");
  /* properties of the wrong type */
  refused_at(FC_HEAD "  {\"type\": \"Feature\", \"geometry\": null,\n   \"properties\": [1]}]}", 1,
             QK_ERR_PARSE, 1, "[1]}", "\"properties\" must be an object or null");
  /* a ring not closed, in the second polygon of a MultiPolygon inside a GeometryCollection
   * that is the document itself (feature 0), after a Point */
  refused_at("{\"type\": \"GeometryCollection\", \"geometries\": [\n"
             " {\"type\": \"Point\", \"coordinates\": [0, 0]},\n"
             " {\"type\": \"MultiPolygon\", \"coordinates\": [\n"
             "  [[[0,0],[1,0],[1,1],[0,0]]],\n"
             "  [[[0,0],[1,0],[1,1],[0,0]], [[5,5],[6,5],[6,6],[5,6]]]]}]}",
             1, QK_ERR_GEOMETRY, 0, "[[5,5]", "not closed");
  /* longitude/latitude out of range (not planar): the position */
  refused_at("{\"type\": \"Feature\", \"properties\": {}, \"geometry\": {\"type\": \"Polygon\",\n"
             "\"coordinates\": [[[0,0],[10,0],[10,10],[0,0]], [[1,1],[200,1],[2,2],[1,1]]]}}",
             0, QK_ERR_GEOMETRY, 0, "[200,1]", "is not a longitude/latitude");
  /* a name written with an escape is not matched in the text: the error points at the
   * deepest value found on the way (here the geometry), never at a wrong place */
  refused_at("{\"type\": \"Polygon\", \"coordin\\u0061tes\": [[[0,0],[1,0],[0,0]]]}", 1,
             QK_ERR_GEOMETRY, 0, "{\"type\"", "3 positions");
  /* blanks of every kind, a string holding brackets and escaped quotes before the value */
  refused_at("{\"type\": \"Feature\", \"properties\": {\"s\": \"]}[{\\\"\\\\\"},\r\n\t\"geometry\""
             " :\r\n {\"type\": \"Polygon\", \"coordinates\" :\t[ [[0,0],[1,0],[1,1],[0,1],[0,0]] ,"
             "\r\n [[0,0],[1,0]] ]}}",
             1, QK_ERR_GEOMETRY, 0, "[[0,0],[1,0]] ]", "2 positions");
#endif
}

/* Points and lines are skipped, but read as strictly as a polygon's positions: a malformed
 * one is refused at its place (they went through without a word, where the same inside a
 * Polygon was refused). Valid ones, and empty ones, are still skipped and counted. */
static void test_geojson_no_area_strict(void **state) {
  (void)state;
#ifndef QK_HAVE_JSONC
  skip();
#else
  refused_at(FC_HEAD "  {\"type\": \"Feature\", \"properties\": {},\n"
                     "   \"geometry\": {\"type\": \"Point\", \"coordinates\": \"x\"}}]}",
             1, QK_ERR_PARSE, 1, "\"x\"}", "Point \"coordinates\" must be an array, found string");
  refused_at(
      FC_HEAD "  {\"type\": \"Feature\", \"properties\": {},\n"
              "   \"geometry\": {\"type\": \"MultiPoint\", \"coordinates\": [[0, 0], [\"a\"]]}}]}",
      1, QK_ERR_PARSE, 1, "[\"a\"]", "feature 1, MultiPoint position 1: expected [x, y] numbers");
  refused_at(FC_HEAD
             "  {\"type\": \"Feature\", \"properties\": {},\n"
             "   \"geometry\": {\"type\": \"LineString\", \"coordinates\": [[1e400, 0]]}}]}",
             1, QK_ERR_NONFINITE, 1, "1e400",
             "coordinate 1e400 is beyond the largest double (not finite) at LineString position 0");
  refused_at(FC_HEAD "  {\"type\": \"Feature\", \"properties\": {},\n"
                     "   \"geometry\": {\"type\": \"MultiLineString\", \"coordinates\":\n"
                     "    [[[0, 0], [1, 1]], [[0, 0], [0, 2e-400]]]}}]}",
             1, QK_ERR_GEOMETRY, 1, "2e-400",
             "below the smallest double, it reads as 0; magnitude must be 0 or within [1e-100, "
             "1e100]) at MultiLineString line 1, position 1");
  refused_at(FC_HEAD "  {\"type\": \"Feature\", \"properties\": {},\n"
                     "   \"geometry\": {\"type\": \"MultiLineString\", \"coordinates\": [7]}}]}",
             1, QK_ERR_PARSE, 1, "7]",
             "feature 1, MultiLineString line 0: expected an array of positions, found int");
  refused_at(
      FC_HEAD
      "  {\"type\": \"Feature\", \"properties\": {},\n"
      "   \"geometry\": {\"type\": \"Point\", \"coordinates\": [100000000000000000000, 0]}}]}",
      1, QK_ERR_PARSE, 1, "100000000000000000000",
      "feature 1, Point: integer 100000000000000000000 is outside the 64-bit range");
  refused_at(FC_HEAD "  {\"type\": \"Feature\", \"properties\": {},\n"
                     "   \"geometry\": {\"type\": \"LineString\"}}]}",
             1, QK_ERR_PARSE, 1, "{\"type\": \"LineString\"",
             "LineString without a \"coordinates\" array");
  /* out of longitude/latitude range, not planar; inside a GeometryCollection (feature 0) */
  refused_at("{\"type\": \"GeometryCollection\", \"geometries\": [\n"
             " {\"type\": \"Point\", \"coordinates\": [200, 0]}, " SQUARE "]}",
             0, QK_ERR_GEOMETRY, 0, "[200, 0]", "is not a longitude/latitude");
  /* Valid points and lines, an empty Point, an empty line: skipped and counted. */
  qk_region_t *r = NULL;
  qk_error_t err;
  assert_int_equal(read_text(FC_HEAD
                             "  {\"type\": \"Feature\", \"properties\": {}, \"geometry\":\n"
                             "   {\"type\": \"Point\", \"coordinates\": [1, 2, 3]}},\n"
                             "  {\"type\": \"Feature\", \"properties\": {}, \"geometry\":\n"
                             "   {\"type\": \"Point\", \"coordinates\": []}},\n"
                             "  {\"type\": \"Feature\", \"properties\": {}, \"geometry\":\n"
                             "   {\"type\": \"MultiLineString\", \"coordinates\": [[[0, 0], [1, "
                             "1]], []]}},\n"
                             "  {\"type\": \"Feature\", \"properties\": {}, \"geometry\":\n"
                             "   {\"type\": \"MultiPoint\", \"coordinates\": [[5, 5]]}}]}",
                             &r, &err),
                   QK_OK);
  qk_region_stats_t s;
  qk_region_stats(r, &s);
  assert_int_equal(s.features, 5);
  assert_int_equal(s.skipped, 4);
  qk_region_free(r);
#undef FC_HEAD
#endif
}

/* ---- a FeatureCollection read one feature at a time ---- */

#ifdef QK_HAVE_JSONC
/* The layer read from text equals the one read whole: the same status and error, or the
 * same stats, properties (names[]) and features at every point of a grid over box. */
static void same_as_whole(const char *text, size_t len, int planar, const char *const *names,
                          const double box[4], unsigned grid) {
  qk_region_options_t o;
  qk_region_options_init(&o);
  o.planar = planar;
  qk_region_t *a = NULL, *b = NULL;
  qk_error_t ea, eb;
  qk_status_t sa = qk_region_read_geojson_text(text, len, &o, &a, &ea);
  qk_status_t sb = qk__geojson_read_whole(text, len, &o, &b, &eb);
  if (sa != sb)
    fail_msg("status %d (%s), whole %d (%s)", sa, sa ? ea.message : "", sb, sb ? eb.message : "");
  if (sa) {
    if (strcmp(ea.message, eb.message))
      fail_msg("%s\nread whole: %s\nin: %.300s", ea.message, eb.message, text);
    assert_true(ea.item == eb.item && ea.line == eb.line && ea.column == eb.column);
    return;
  }
  qk_region_stats_t ta, tb;
  qk_region_stats(a, &ta);
  qk_region_stats(b, &tb);
  assert_true(ta.features == tb.features && ta.rings == tb.rings && ta.vertices == tb.vertices &&
              ta.skipped == tb.skipped);
  assert_int_equal(qk_region_feature_count(a), qk_region_feature_count(b));
  for (uint32_t f = 0; f < qk_region_feature_count(a); f++)
    for (size_t k = 0; names && names[k]; k++) {
      const char *pa = qk_region_property(a, f, names[k]), *pb = qk_region_property(b, f, names[k]);
      if (!pa || !pb)
        assert_true(pa == pb);
      else
        assert_string_equal(pa, pb);
    }
  for (unsigned i = 0; i <= grid; i++)
    for (unsigned j = 0; j <= grid; j++) {
      qk_point_t p = {box[0] + (box[2] - box[0]) * i / grid, box[1] + (box[3] - box[1]) * j / grid};
      uint32_t fa[16], fb[16];
      size_t na = 0, nb = 0;
      assert_int_equal(qk_region_locate_all(a, p, QK_BOUNDARY_CLOSED, fa, 16, &na), QK_OK);
      assert_int_equal(qk_region_locate_all(b, p, QK_BOUNDARY_CLOSED, fb, 16, &nb), QK_OK);
      assert_int_equal(na, nb);
      assert_memory_equal(fa, fb, (na < 16 ? na : 16) * sizeof *fa);
    }
  qk_region_free(a);
  qk_region_free(b);
}

#define FA                                                                                         \
  "{\"type\":\"Feature\",\"properties\":{\"name\":\"a]},\\\"[{\",\"k\":\"\\\\\",\"n\":[1,{\"x\":"  \
  "null}],"                                                                                        \
  "\"z\":1.5e3},\"geometry\":{\"type\":\"Polygon\",\"coordinates\":[[[0,0],[2,0],[2,2],[0,2],[0,"  \
  "0]],"                                                                                           \
  "[[0.5,0.5],[1,0.5],[1,1],[0.5,0.5]]]}}"
#define FB                                                                                         \
  "{ \"geometry\" : {\"type\":\"GeometryCollection\",\"geometries\":[{\"type\":\"Point\","         \
  "\"coordinates\":[9,9]},{\"type\":\"GeometryCollection\",\"geometries\":[{\"type\":"             \
  "\"MultiPolygon\",\"coordinates\":[[[[1,1],[3,1],[3,3],[1,1]]],[[[2.5,0],[3,0],[3,0.5],"         \
  "[2.5,0]]]]}]}]},\n\t\"type\" : \"Feature\", \"properties\": {\"name\": \"b\"} }"
#define FC "{\"type\":\"Feature\",\"properties\":null,\"geometry\":null}"
#define FD                                                                                         \
  "{\"type\":\"Feature\",\"properties\":{\"name\":\"d\"},\"geometry\":{\"type\":\"Point\","        \
  "\"coordinates\":[1,1]}}"
#define SHORT                                                                                      \
  "{\"type\":\"Feature\",\"properties\":{},\"geometry\":{\"type\":\"Polygon\",\"coordinates\":"    \
  "[[[0,0],[1,0],[0,0]]]}}"
#endif

static void test_geojson_streamed(void **state) {
  (void)state;
#ifndef QK_HAVE_JSONC
  skip();
#else
  static const char *const names[] = {"name", "k", "n", "z", NULL};
  const double box[4] = {-0.25, -0.25, 3.25, 3.25};
  static const char *const valid[] = {
      /* members in any order, around the array too; strings holding brackets, commas,
       * escaped quotes and backslashes; nested collections; null and point geometries */
      "{\"features\":[" FA "," FB "," FC "," FD "],\"type\":\"FeatureCollection\",\"bbox\":[0,0,"
      "3,3],\"crs\":{\"a\":[1,{\"b\":\"]\"}]}}",
      " \r\n{ \"type\" :\"FeatureCollection\" ,\n \"features\"\t:\n[\n " FB " ,\r\n\t" FA
      "\n ]\n}\n ",
      "{\"type\":\"FeatureCollection\",\"features\":[]}",
      "{\"type\":\"FeatureCollection\",\"features\":[ \n ]}",
      "{\"type\":\"FeatureCollection\",\"features\":[" FA "]}",
      "{\"type\":\"FeatureCollection\",\"features\":[" FB "," FB "," FA "]}",
  };
  for (size_t i = 0; i < sizeof valid / sizeof *valid; i++) {
    qk_region_t *r = NULL;
    qk_error_t e;
    if (read_text(valid[i], &r, &e)) fail_msg("valid %zu: %s", i, e.message);
    qk_region_free(r);
    same_as_whole(valid[i], strlen(valid[i]), 1, names, box, 28);
  }
  {
    /* the same name written with an escape is the same name, refused as any duplicate
     * (json-c kept the later array: this was read as valid before the fiftieth session) */
    static const char esc[] =
        "{\"type\":\"FeatureCollection\",\"features\":[" FA "],\"feat\\u0075res\":[" FB "]}";
    qk_region_t *r = NULL;
    qk_error_t e;
    assert_int_equal(read_text(esc, &r, &e), QK_ERR_PARSE);
    assert_non_null(strstr(e.message, "duplicate name \"feat\\u0075res\""));
  }
  /* The streamed reading is the one taken (it allocates the emptied root and the spans
   * through the layer's allocator besides what the whole-text one does), and an
   * allocation failure at any of its calls is QK_ERR_NOMEM with nothing left allocated. */
  qkt_alloc_t ca;
  qk_region_options_t ao;
  qk_region_options_init(&ao);
  ao.planar = 1;
  qk_allocator_t al = qkt_alloc_make(&ca);
  ao.allocator = &al;
  qk_region_t *r = NULL;
  qk_error_t e;
  assert_int_equal(qk__geojson_read_whole(valid[0], strlen(valid[0]), &ao, &r, &e), QK_OK);
  qk_region_free(r);
  size_t whole_calls = ca.calls;
  qkt_alloc_arm(&ca, 0);
  assert_int_equal(read_text_with(valid[0], &ao, &r, &e), QK_OK);
  qk_region_free(r);
  size_t calls = ca.calls;
  if (calls < whole_calls + 2) fail_msg("%zu allocations, whole %zu", calls, whole_calls);
  for (size_t k = 1; k <= calls; k++) {
    qkt_alloc_arm(&ca, k);
    qk_status_t st = read_text_with(valid[0], &ao, &r, &e);
    /* (QK_OK: only a shrink failed, which keeps the block; the first call is the
     * spans' and fails the read, not sends it to the whole-text reading) */
    if (st != QK_OK || k == 1) {
      assert_int_equal(st, QK_ERR_NOMEM);
      assert_null(r);
      assert_non_null(strstr(e.message, "out of memory"));
    }
    qk_region_free(r);
    assert_int_equal(ca.live_blocks, 0);
  }
  /* JSON the whole-text reading refuses, and errors inside valid JSON */
  static const char *const invalid[] = {
      "{\"type\":\"FeatureCollection\",\"features\":[" FA ",]}",
      "{\"type\":\"FeatureCollection\",\"features\":[" FA " " FB "]}",
      "{\"type\":\"FeatureCollection\",\"features\":[" FA ",," FB "]}",
      "{\"type\":\"FeatureCollection\",\"features\":[," FA "]}",
      "{\"type\":\"FeatureCollection\",\"features\":[" FA "}]}",
      "{\"type\":\"FeatureCollection\",\"features\":[" FA "," FB "] ]}",
      "{\"type\":\"FeatureCollection\",\"features\":[" FA "," FB ",{\"type\":\"Feature\"]}",
      "{\"type\":\"FeatureCollection\",\"features\":[{\"type\":\"Feature\",\"properties\":"
      "{\"s\":\"x}]}\"}," FB "]}",
      "{\"type\":\"FeatureCollection\",\"features\":[null," FA "]}",
      "{\"type\":\"FeatureCollection\",\"features\":[" FA "," SHORT "]}",
      "{\"type\":\"FeatureCollection\",\"features\":[" FA "," FA "],\"features\":[]}",
      "{\"type\":\"FeatureColection\",\"features\":[" FA "]}",
      "{\"type\":\"FeatureCollection\",\"features\":[" FA "]} x}",
      "{\"type\":\"FeatureCollection\",\"features\":[" FA "],}",
      "{\"type\":\"FeatureCollection\",\"features\":[" FA "] \"bbox\":[]}",
      "{\"type\":\"FeatureCollection\",\"features\":[" FA "," FB "]",
      "{\"type\":\"FeatureCollection\",\"features\":[1e400]}",
      "{\"type\":\"FeatureCollection\",\"features\":[\"" FA "\"]}",
  };
  for (size_t i = 0; i < sizeof invalid / sizeof *invalid; i++) {
    if (read_text(invalid[i], &r, &e) == QK_OK) fail_msg("invalid %zu accepted", i);
    assert_null(r);
    same_as_whole(invalid[i], strlen(invalid[i]), 1, names, box, 4);
  }
  /* json-c's nesting limit holds as for the whole text: 31 levels in all, 32 refused */
  for (int d = 27; d <= 30; d++) {
    char t[1024];
    int n = snprintf(t, sizeof t,
                     "{\"type\":\"FeatureCollection\",\"features\":[{\"type\":\"Feature\","
                     "\"properties\":{\"n\":%.*s%.*s},\"geometry\":null}]}",
                     d, "[[[[[[[[[[[[[[[[[[[[[[[[[[[[[[[[[[[[[[[[", d,
                     "]]]]]]]]]]]]]]]]]]]]]]]]]]]]]]]]]]]]]]]]");
    qk_status_t st = read_text(t, &r, &e);
    qk_region_free(r);
    if ((st == QK_OK) != (d <= 28)) fail_msg("depth %d: status %d", d, st);
    same_as_whole(t, (size_t)n, 1, names, box, 2);
  }
  /* the countries, when present: every country's name and a 1-degree grid */
  char path[1024];
  FILE *f = qkt_open_shared("countries-50m.geojson", path, sizeof path);
  if (!f) {
    print_message("no %s: the countries part skipped\n", path);
    skip();
  }
  assert_int_equal(fseek(f, 0, SEEK_END), 0);
  long n = ftell(f);
  assert_true(n > 0);
  rewind(f);
  char *text = malloc((size_t)n);
  assert_non_null(text);
  assert_int_equal(fread(text, 1, (size_t)n, f), (size_t)n);
  fclose(f);
  static const char *const cnames[] = {"name", NULL};
  const double world[4] = {-180, -90, 180, 90};
  same_as_whole(text, (size_t)n, 0, cnames, world, 360);
  free(text);
#endif
}

static void test_geojson_locate(void **state) {
  (void)state;
#ifndef QK_HAVE_JSONC
  skip();
#else
  const char *t = "\xEF\xBB\xBF{\"type\": \"FeatureCollection\", \"a/b~c\": [7, 8],\n"
                  " \"features\": [\n  {\"geometry\": {\"coordinates\": [[[0, 0],\n"
                  "   [1, 0], [1, 1], [0, 0]]]}}]}";
  const char *body = t + 3; /* lines and columns count after the byte order mark */
  static const struct {
    const char *ptr, *mark;
  } cases[] = {
      {"", "{\"type\""},
      {"/features/0/geometry/coordinates/0/2", "[1, 1]"},
      {"/features/0/geometry/coordinates/0/1/1", "0], [1, 1]"},
      {"/a~1b~0c/1", "8]"},
      {"/features/0/geometry/coordinates/0/9", "[[0, 0],\n"}, /* past the end: the ring */
      {"/features/3", "[\n  {"},                              /* past the end: the array */
      {"/nothing/0", "{\"type\""},                            /* no such member: the root */
  };
  for (size_t i = 0; i < sizeof cases / sizeof *cases; i++) {
    unsigned long line, col, wl, wc;
    mark_at(body, cases[i].mark, &wl, &wc);
    assert_int_equal(qk_region_find_json_pointer(t, strlen(t), cases[i].ptr, &line, &col), QK_OK);
    if (line != wl || col != wc)
      fail_msg("%s: got %lu:%lu, want %lu:%lu", cases[i].ptr, line, col, wl, wc);
  }
  unsigned long line, col;
  assert_int_equal(qk_region_find_json_pointer(t, strlen(t), "features", &line, &col),
                   QK_ERR_INVALID);
  assert_int_equal(qk_region_find_json_pointer(NULL, 0, "", &line, &col), QK_ERR_INVALID);
  char longp[1100];
  memset(longp, 'a', sizeof longp - 1);
  longp[0] = '/', longp[sizeof longp - 1] = '\0';
  assert_int_equal(qk_region_find_json_pointer(t, strlen(t), longp, &line, &col), QK_ERR_INVALID);
#endif
}

/* Strings hold no raw control character and only well-formed UTF-8 (RFC 8259 sections 7
 * and 8.1): json-c's strict mode passed both into names and property values, and from
 * there into join's CSV. Each bad byte is named at its own line and column, in a
 * collection (the streamed reading) and in a lone feature (the whole-text one). */
static void test_geojson_string_bytes(void **state) {
  (void)state;
#ifndef QK_HAVE_JSONC
  skip();
#else
  static const struct {
    const char *s; /* the name property's value, as written in the file */
    size_t at;     /* the offending byte's position in s, or SIZE_MAX: valid */
    const char *words;
  } cases[] = {
      {"a\x01z", 1, "control character U+0001 inside a string"},
      {"tab\there", 3, "control character U+0009"},
      {"x\n", 1, "control character U+000A"},
      {"\x1f", 0, "control character U+001F"},
      {"ab\xff", 2, "byte 0xFF inside a string is not UTF-8"},
      {"\xc3", 0, "byte 0xC3"},             /* cut short by the quote */
      {"\xc0\xaf", 0, "byte 0xC0"},         /* overlong '/' */
      {"\xe0\x80\xaf", 1, "byte 0x80"},     /* overlong, three bytes */
      {"\xed\xa0\x80", 1, "byte 0xA0"},     /* a surrogate, U+D800 */
      {"\xf4\x90\x80\x80", 1, "byte 0x90"}, /* past U+10FFFF */
      {"\xe6\x97\x41", 0, "byte 0xE6"},     /* a continuation missing: the lead byte */
      {"\xc3"
       "a",
       0, "byte 0xC3"},         /* (the error blamed the a) */
      {"\x80", 0, "byte 0x80"}, /* a lone continuation */
      {"Z\xc3\xbcrich \xe6\x97\xa5 \xf0\x9f\x98\x80 \x7f", SIZE_MAX, NULL},
      {"\xf4\x8f\xbf\xbf \xef\xbf\xbf \xed\x9f\xbf \xee\x80\x80", SIZE_MAX, NULL},
      {"a\\u0001\\\"\\n", SIZE_MAX, NULL}, /* escaped, they are fine */
  };
  for (size_t i = 0; i < sizeof cases / sizeof *cases; i++)
    for (int lone = 0; lone < 2; lone++) {
      char text[512];
      const char *head = lone ? "{\"type\": \"Feature\",\n \"properties\": {\"name\": \""
                              : "{\"type\": \"FeatureCollection\", \"features\": [\n"
                                "{\"type\": \"Feature\", \"properties\": {\"name\": \"";
      snprintf(text, sizeof text, "%s%s\"},\n \"geometry\": " SQUARE "}%s", head, cases[i].s,
               lone ? "" : "]}");
      qk_region_t *r = NULL;
      qk_error_t e;
      qk_status_t st = read_text(text, &r, &e);
      if (cases[i].at == SIZE_MAX) {
        if (st) fail_msg("case %zu (lone %d): %s", i, lone, e.message);
        qk_region_free(r);
        continue;
      }
      unsigned long col =
          (unsigned long)(strchr(head, '\n') ? strlen(strrchr(head, '\n') + 1) : strlen(head)) + 1 +
          cases[i].at;
      if (st != QK_ERR_PARSE || e.line != 2 || e.column != col ||
          !strstr(e.message, cases[i].words))
        fail_msg("case %zu (lone %d): got %s at %lu:%lu '%s'; want 2:%lu '%s'", i, lone,
                 qk_strerror(st), e.line, e.column, e.message, col, cases[i].words);
      assert_null(r);
    }
  /* A duplicate name holding an escaped quote is quoted whole in the message (it was cut
   * at the escaped quote). */
  static const char dup[] =
      "{\"type\": \"Feature\", \"properties\": {\"a\\\"b\": 1, \"a\\\"b\": 2},"
      " \"geometry\": " SQUARE "}";
  qk_region_t *r = NULL;
  qk_error_t e;
  assert_int_equal(read_text(dup, &r, &e), QK_ERR_PARSE);
  if (!strstr(e.message, "duplicate name \"a\\\"b\" in one object")) fail_msg("%s", e.message);
  /* A long one is cut after 60 bytes, but not inside a character: 59 ASCII bytes and then
   * two-byte characters (U+00E9) come back with the whole first of them. */
  char longdup[512], name[80];
  memset(name, 'n', 59);
  strcpy(name + 59, "\xc3\xa9\xc3\xa9\xc3\xa9");
  snprintf(longdup, sizeof longdup,
           "{\"type\": \"Feature\", \"properties\": {\"%s\": 1, \"%s\": 2}, \"geometry\": " SQUARE
           "}",
           name, name);
  assert_int_equal(read_text(longdup, &r, &e), QK_ERR_PARSE);
  char want[128];
  snprintf(want, sizeof want, "duplicate name \"%.61s\" in one object", name);
  if (!strstr(e.message, want)) fail_msg("%s", e.message);
#endif
}

int main(void) {
  const struct CMUnitTest tests[] = {
      cmocka_unit_test(test_geojson_locate),
      cmocka_unit_test(test_geojson_bom),
      cmocka_unit_test(test_geojson_unknown_types),
      cmocka_unit_test(test_geojson_error_position),
      cmocka_unit_test(test_geojson_collection_and_strict),
      cmocka_unit_test(test_geojson_semantic_position),
      cmocka_unit_test(test_geojson_no_area_strict),
      cmocka_unit_test(test_geojson_streamed),
      cmocka_unit_test(test_geojson_string_bytes),
  };
  return cmocka_run_group_tests(tests, NULL, NULL);
}
