/*
 * Test plan for the CSV reader (include/quadkit/io.h):
 *  - good files: a header detected or not, blank lines, a byte order mark, CRLF, quoted
 *    fields with commas and doubled quotes, extra columns, blanks around numbers;
 *  - columns by header name and by 1-based number, in any order, and the header rules
 *    (auto, yes, no); optional columns read as NaN when absent or empty;
 *  - random points written with %.17g read back bit for bit, across the reader's chunk
 *    boundary (lines longer than its 64 KiB buffer) and its growth steps;
 *  - every error kind with its status, line, column, row and message;
 *  - the row callback: every data row and the header, with line numbers, and its status;
 *  - allocation failure at every N: QK_ERR_NOMEM, nothing allocated, no leak; the
 *    unfailed run gives the same points;
 *  - binary input (32 MiB of NUL bytes, after a header, inside an open quote): refused at
 *    the first NUL with its line and column, the reader's memory staying under 1 MiB
 *    (it took the whole "line" into memory first, as it would /dev/zero).
 */
#define _POSIX_C_SOURCE 200809L
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <unistd.h>

#include "qk_test.h"

/* A file holding `text` (len bytes; -1: strlen), removed by the caller. */
static char *write_tmp(const char *text, long len) {
  const char *dir = getenv("TMPDIR");
  char *path = malloc(4096);
  assert_non_null(path);
  snprintf(path, 4096, "%s/qk-test-io-XXXXXX", dir && *dir ? dir : "/tmp");
  int fd = mkstemp(path);
  assert_true(fd >= 0);
  size_t n = len < 0 ? strlen(text) : (size_t)len;
  assert_int_equal(write(fd, text, n), (ssize_t)n);
  close(fd);
  return path;
}

typedef struct read_result {
  qk_status_t st;
  qk_point_t *pts;
  size_t n;
  qk_error_t err;
} read_result_t;

static read_result_t read_text(const char *text, long len, const char *columns,
                               qk_csv_header_t header) {
  char *path = write_tmp(text, len);
  qk_csv_options_t o;
  qk_csv_options_init(&o);
  o.columns = columns;
  o.header = header;
  read_result_t r;
  r.st = qk_points_read_csv(path, &o, NULL, &r.pts, &r.n, &r.err);
  remove(path);
  free(path);
  return r;
}

static void expect_points(const char *text, const char *columns, qk_csv_header_t header,
                          const double *xy, size_t n) {
  read_result_t r = read_text(text, -1, columns, header);
  if (r.st != QK_OK)
    fail_msg("'%s': %s (line %lu column %lu: %s)", text, qk_strerror(r.st), r.err.line,
             r.err.column, r.err.message);
  if (r.n != n) fail_msg("'%s': %zu points, want %zu", text, r.n, n);
  for (size_t i = 0; i < n; i++)
    if (r.pts[i].x != xy[2 * i] || r.pts[i].y != xy[2 * i + 1])
      fail_msg("'%s': point %zu is (%g, %g), want (%g, %g)", text, i, r.pts[i].x, r.pts[i].y,
               xy[2 * i], xy[2 * i + 1]);
  assert_string_equal(r.err.message, "");
  free(r.pts);
}

static void test_io_good_files(void **state) {
  (void)state;
  const double a[] = {0, 0, 1, 2};
  expect_points("x,y\n0,0\n1,2\n", NULL, QK_CSV_HEADER_AUTO, a, 2);
  expect_points("0,0\n1,2\n", NULL, QK_CSV_HEADER_AUTO, a, 2);
  expect_points("\n  \n0,0\n\t\n1,2", NULL, QK_CSV_HEADER_AUTO, a, 2);
  expect_points("\xEF\xBB\xBFx,y\r\n0,0\r\n1,2\r\n", NULL, QK_CSV_HEADER_AUTO, a, 2);
  expect_points("x,y,name\n 0 , 0 ,a\n\"1\",2,\"b, \"\"c\"\"\"\n", NULL, QK_CSV_HEADER_AUTO, a, 2);
  /* Fields not read are not checked, but a quote left open there would take the rest of
   * the file into its field (a record may span lines): an error (seventeenth session). */
  expect_points("0,0,\"closed\"x\n1,2,x\n", NULL, QK_CSV_HEADER_AUTO, a, 2);
  expect_points("", NULL, QK_CSV_HEADER_AUTO, NULL, 0);
  expect_points("x,y\n", NULL, QK_CSV_HEADER_AUTO, NULL, 0);
  /* Header rules: YES skips a numeric first line, NO reads it. */
  expect_points("5,5\n0,0\n1,2\n", NULL, QK_CSV_HEADER_YES, a, 2);
  const double b[] = {5, 5, 0, 0, 1, 2};
  expect_points("5,5\n0,0\n1,2\n", NULL, QK_CSV_HEADER_NO, b, 3);
  /* decimal forms: a point without digits on one side, signs, exponents, -0 */
  const double c[] = {0.5, 5, 1, -0.2, 150, 0};
  expect_points(".5,5.\n+1,-2E-1\n1.5e+2, -0 \n", NULL, QK_CSV_HEADER_AUTO, c, 3);
}

static void test_io_columns(void **state) {
  (void)state;
  const char *t = "name,lat,lon\nParis,48.5,2.25\n\"Rome, Lazio\",41.75,12.5\n";
  const double want[] = {2.25, 48.5, 12.5, 41.75};
  expect_points(t, "lon,lat", QK_CSV_HEADER_AUTO, want, 2);
  expect_points(t, " lon , lat ", QK_CSV_HEADER_AUTO, want, 2);
  expect_points(t, "3,2", QK_CSV_HEADER_AUTO, want, 2);
  expect_points(t, "lon,2", QK_CSV_HEADER_AUTO, want, 2);
  /* A quoted header name with a doubled quote. */
  const double q[] = {1, 2};
  expect_points("\"a\"\"b\",c\n2,1\n", "c,a\"b", QK_CSV_HEADER_AUTO, q, 1);
  /* Auto detection by the first selected column: column 3 of the first line is 'lon'. */
  expect_points("1,2,lon,lat\n9,9,1,2\n", "3,4", QK_CSV_HEADER_AUTO, q, 1);
}

static void test_io_values(void **state) {
  (void)state;
  /* Rays: four required columns and an optional fifth. The quoted 2.5 above an empty
   * field checks that a field's quoting is not carried over to the same column of the
   * next row (the sweep: without `sp->quoted = 0` the empty field was refused). */
  const char *t = "ox,oy,dx,dy,tmax\n0,0,1,0\n1,1,0,1,\"2.5\"\n2,2,1,1,\n";
  char *path = write_tmp(t, -1);
  FILE *f = fopen(path, "rb");
  assert_non_null(f);
  double *v;
  size_t rows;
  qk_error_t err;
  assert_int_equal(qk_csv_read_values(f, NULL, 5, 4, NULL, &v, &rows, &err), QK_OK);
  fclose(f);
  assert_int_equal(rows, 3);
  assert_true(v[0] == 0 && v[2] == 1 && isnan(v[4]));
  assert_true(v[5] == 1 && v[9] == 2.5);
  assert_true(v[10] == 2 && isnan(v[14]));
  free(v);
  /* Bad arguments. */
  f = fopen(path, "rb");
  assert_int_equal(qk_csv_read_values(f, NULL, 0, 0, NULL, &v, &rows, &err), QK_ERR_INVALID);
  assert_int_equal(qk_csv_read_values(f, NULL, 2, 3, NULL, &v, &rows, &err), QK_ERR_INVALID);
  assert_int_equal(qk_csv_read_values(f, NULL, 65, 1, NULL, &v, &rows, &err), QK_ERR_INVALID);
  assert_int_equal(qk_csv_read_values(NULL, NULL, 2, 2, NULL, &v, &rows, &err), QK_ERR_INVALID);
  fclose(f);
  remove(path);
  free(path);
  /* Zeros written with any exponent, and subnormals, are numbers: only a nonzero number
   * that reads as 0 is refused (test_io_errors). */
  read_result_t r = read_text("0e-400,-0.000E-999\n4.9e-324,2.2250738585072009e-308\n", -1, NULL,
                              QK_CSV_HEADER_AUTO);
  assert_int_equal(r.st, QK_OK);
  assert_int_equal(r.n, 2);
  assert_true(r.pts[0].x == 0 && r.pts[0].y == 0 && signbit(r.pts[0].y));
  assert_true(r.pts[1].x == 0x1p-1074 && r.pts[1].y == 0x0.fffffffffffffp-1022);
  free(r.pts);
}

/* Random points written with %.17g come back bit for bit, with long lines crossing the
 * reader's 64 KiB chunks. */
static void test_io_round_trip(void **state) {
  (void)state;
  uint64_t seed = qkt_seed(1313);
  qkt_rng_t r;
  qkt_rng_seed(&r, seed);
  enum { N = 3000 };
  static qk_point_t p[N];
  size_t cap = (size_t)N * 80 + 200000;
  char *text = malloc(cap);
  assert_non_null(text);
  size_t len = (size_t)snprintf(text, cap, "x,y,pad\n");
  for (size_t i = 0; i < N; i++) {
    p[i].x = qkt_rng_range(&r, -1e6, 1e6);
    p[i].y = ldexp(qkt_rng_unit(&r), (int)qkt_rng_below(&r, 200) - 100);
    len += (size_t)snprintf(text + len, cap - len, "%.17g,%.17g,", p[i].x, p[i].y);
    /* Every 1000th row carries a 70,000-byte third field. */
    size_t pad = i % 1000 == 7 ? 70000 : i % 3;
    memset(text + len, 'z', pad);
    len += pad;
    if (i % 2) text[len++] = '\r'; /* CRLF and LF mixed */
    text[len++] = '\n';
  }
  read_result_t rr = read_text(text, (long)len, NULL, QK_CSV_HEADER_AUTO);
  free(text);
  if (rr.st != QK_OK) fail_msg("seed %llu: %s", (unsigned long long)seed, rr.err.message);
  assert_int_equal(rr.n, N);
  for (size_t i = 0; i < N; i++)
    if (memcmp(&rr.pts[i], &p[i], sizeof p[i]))
      fail_msg("seed %llu: point %zu differs", (unsigned long long)seed, i);
  free(rr.pts);
}

static void expect_error(const char *text, long len, const char *columns, qk_csv_header_t h,
                         qk_status_t st, unsigned long line, unsigned long column, size_t item,
                         const char *message) {
  read_result_t r = read_text(text, len, columns, h);
  if (r.st != st || r.err.line != line || r.err.column != column || r.err.item != item ||
      strcmp(r.err.message, message))
    fail_msg("'%.40s': got %s line %lu column %lu item %zu '%s'; want %s line %lu column %lu item "
             "%zu '%s'",
             text, qk_strerror(r.st), r.err.line, r.err.column, r.err.item, r.err.message,
             qk_strerror(st), line, column, item, message);
  assert_null(r.pts);
  assert_int_equal(r.n, 0);
}

static void test_io_errors(void **state) {
  (void)state;
  const qk_csv_header_t A = QK_CSV_HEADER_AUTO;
  expect_error("x,y\n0,0\n1,abc\n", -1, NULL, A, QK_ERR_PARSE, 3, 3, 1,
               "field 2 (y) is not a number: 'abc'");
  /* A first line with a number among its selected fields is data: a malformed first row
   * is an error, not a header dropped without a word (review). */
  /* Old Mac line ends (CR alone): the whole file was one line, and the error named a
   * value with a raw CR in it. */
  expect_error("x,y\r0,0\r1,2\r", -1, NULL, A, QK_ERR_PARSE, 1, 4, SIZE_MAX,
               "a carriage return inside the line (line ends must be LF or CRLF, not CR alone)");
  expect_error("0,0\n1,2\r\n3,4\r5,6\n", -1, NULL, A, QK_ERR_PARSE, 3, 4, SIZE_MAX,
               "a carriage return inside the line (line ends must be LF or CRLF, not CR alone)");
  expect_error("x1,2\n3,4\n", -1, NULL, A, QK_ERR_PARSE, 1, 1, 0, "field 1 is not a number: 'x1'");
  expect_error("name,lon,lat\nRome,1e,2\n0,1,2\n", -1, "2,3", A, QK_ERR_PARSE, 2, 6, 0,
               "field 2 (lon) is not a number: '1e'");
  expect_error("0,0\n1\n", -1, NULL, A, QK_ERR_PARSE, 2, 2, 1,
               "field 2 is missing: the line has 1 field");
  expect_error("0,0\n  nan ,1\n", -1, NULL, A, QK_ERR_NONFINITE, 2, 1, 1,
               "field 1 is not finite: '  nan '");
  expect_error("0,0\n1,1e400\n", -1, NULL, A, QK_ERR_NONFINITE, 2, 3, 1,
               "field 2 is not finite: '1e400'");
  /* Numbers are decimal: strtod's hexadecimal was read silently (third review). */
  expect_error("x,y\n0x10,1\n", -1, NULL, A, QK_ERR_PARSE, 2, 1, 0,
               "field 1 (x) is not a decimal number: '0x10'");
  expect_error("0,0\n1, -0X1p-3 \n", -1, NULL, A, QK_ERR_PARSE, 2, 3, 1,
               "field 2 is not a decimal number: ' -0X1p-3 '");
  expect_error("0x1,0x2\n0,0\n", -1, NULL, A, QK_ERR_PARSE, 1, 1, 0,
               "field 1 is not a decimal number: '0x1'"); /* data, not a header */
  expect_error("0,0\n1.5.1,0\n", -1, NULL, A, QK_ERR_PARSE, 2, 1, 1,
               "field 1 is not a number: '1.5.1'");
  /* A quoted field's value as it reads ("" is one quote: it showed '1""', neither the
   * field nor its value), and a value cut at 40 bytes not inside a character (39 ASCII
   * bytes, then U+00E9: the e-acute is left out whole). */
  expect_error("0,0\n\"1\"\"\",0\n", -1, NULL, A, QK_ERR_PARSE, 2, 1, 1,
               "field 1 is not a number: '1\"'");
  expect_error("0,0\naaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaa\xc3\xa9,0\n", -1, NULL, A,
               QK_ERR_PARSE, 2, 1, 1,
               "field 1 is not a number: 'aaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaa'");
  /* A nonzero number below the smallest double: strtod reads it as 0, and so did the reader
   * without a word (forty-ninth session's review). A header of such numbers is data. */
  expect_error("0,0\n1,1e-400\n", -1, NULL, A, QK_ERR_LIMIT, 2, 3, 1,
               "field 2 is below the smallest double (it would read as 0): '1e-400'");
  expect_error(
      "x,y\n -0.0000007e-999 ,1\n", -1, NULL, A, QK_ERR_LIMIT, 2, 1, 0,
      "field 1 (x) is below the smallest double (it would read as 0): ' -0.0000007e-999 '");
  expect_error("1e-400,2\n0,0\n", -1, NULL, A, QK_ERR_LIMIT, 1, 1, 0,
               "field 1 is below the smallest double (it would read as 0): '1e-400'");
  /* A header's name is named without the blanks around it (the sweep: a label keeping its
   * trailing blanks passed every test). */
  expect_error(" x ,\t y \t\n0,abc\n", -1, NULL, A, QK_ERR_PARSE, 2, 3, 0,
               "field 2 (y) is not a number: 'abc'");
  /* A long value is echoed cut to its first 40 bytes, for both messages that show one
   * (the mutation sweep of io/: a cut at 39 passed every test). */
  expect_error("0,0\n1,0123456789abcdefghij0123456789ABCDEFGHIJxyz\n", -1, NULL, A, QK_ERR_PARSE, 2,
               3, 1, "field 2 is not a number: '0123456789abcdefghij0123456789ABCDEFGHIJ'");
  expect_error("0,0\n1,                                     nan  \n", -1, NULL, A, QK_ERR_NONFINITE,
               2, 3, 1, "field 2 is not finite: '                                     nan'");
  expect_error("0,0\n-INFINITY,0\n", -1, NULL, A, QK_ERR_NONFINITE, 2, 1, 1,
               "field 1 is not finite: '-INFINITY'");
  expect_error("0,0\n1,\0\n", 8, NULL, A, QK_ERR_PARSE, 2, 3, SIZE_MAX,
               "binary data (NUL byte) in a text file");
  expect_error("0,0\n\"1,2\n", -1, NULL, A, QK_ERR_PARSE, 2, 1, 1,
               "field 1: unterminated quoted field");
  expect_error("0,0\n1,\"2\" x\n", -1, NULL, A, QK_ERR_PARSE, 2, 3, 1,
               "field 2: text after a closing quote");
  expect_error("a,b\n0,0\n", -1, "lon,lat", A, QK_ERR_PARSE, 1, 0, SIZE_MAX,
               "no column named 'lon' in the header (2 fields: 'a,b')");
  expect_error("x,x,y\n0,0,0\n", -1, "x,y", A, QK_ERR_PARSE, 1, 3, SIZE_MAX,
               "column name 'x' appears twice in the header (fields 1 and 2)");
  expect_error("\"x,y\n0,0\n", -1, "x,y", A, QK_ERR_PARSE, 1, 1, SIZE_MAX,
               "header: unterminated quoted field");
  /* One field selected twice read every point onto the diagonal (sixth review). */
  expect_error("x,y\n0,1\n", -1, "x,1", A, QK_ERR_PARSE, 1, 0, SIZE_MAX,
               "columns 'x' and 1 (1 and 2 of the selection) are both field 1");
  expect_error("a,lon,lat\n0,1,2\n", -1, "lat,3", A, QK_ERR_PARSE, 1, 0, SIZE_MAX,
               "columns 'lat' and 3 (1 and 2 of the selection) are both field 3");
  expect_error("0,1\n", -1, "2,2", A, QK_ERR_INVALID, 0, 0, SIZE_MAX,
               "columns 2 and 2 (1 and 2 of the selection) are both field 2");
  expect_error("0,0\n", -1, "x,y", QK_CSV_HEADER_NO, QK_ERR_INVALID, 0, 0, SIZE_MAX,
               "column 'x' is named, but the input has no header");
  expect_error("0,0\n", -1, "1", A, QK_ERR_INVALID, 0, 0, SIZE_MAX,
               "columns must be 2 comma-separated names or 1-based numbers, not '1'");
  expect_error("0,0\n", -1, "1,2,3", A, QK_ERR_INVALID, 0, 0, SIZE_MAX,
               "columns must be 2 comma-separated names or 1-based numbers, not '1,2,3'");
  expect_error("0,0\n", -1, "1,", A, QK_ERR_INVALID, 0, 0, SIZE_MAX,
               "columns must be 2 comma-separated names or 1-based numbers, not '1,'");
  expect_error("0,0\n", -1, "0,1", A, QK_ERR_INVALID, 0, 0, SIZE_MAX,
               "column number 0 is out of range (1 to 100000)");
  /* A header rule outside the enum was read as QK_CSV_HEADER_AUTO (the API review). */
  expect_error("0,0\n", -1, NULL, (qk_csv_header_t)7, QK_ERR_INVALID, 0, 0, SIZE_MAX,
               "header rule 7 is none of QK_CSV_HEADER_AUTO, _YES and _NO");
  expect_error("0,0\n", -1, NULL, (qk_csv_header_t)-1, QK_ERR_INVALID, 0, 0, SIZE_MAX,
               "header rule -1 is none of QK_CSV_HEADER_AUTO, _YES and _NO");
  /* The byte order mark counts in line 1's columns. */
  expect_error("\xEF\xBB\xBF"
               "1,x\n",
               -1, NULL, A, QK_ERR_PARSE, 1, 6, 0, "field 2 is not a number: 'x'");
  /* Missing file. */
  qk_point_t *p;
  size_t n;
  qk_error_t err;
  assert_int_equal(qk_points_read_csv("/nonexistent/qk.csv", NULL, NULL, &p, &n, &err), QK_ERR_IO);
  assert_non_null(strstr(err.message, "cannot open"));
  assert_int_equal(qk_points_read_csv(NULL, NULL, NULL, &p, &n, &err), QK_ERR_INVALID);
  assert_int_equal(qk_points_read_csv_file(stdin, NULL, NULL, NULL, &n, NULL), QK_ERR_INVALID);
}

typedef struct seen {
  size_t rows, headers;
  unsigned long last_line;
  char text[64];
  int stop_at;
} seen_t;

static qk_status_t on_row(void *ud, size_t row, unsigned long lineno, const char *line,
                          size_t len) {
  seen_t *s = ud;
  assert_int_equal(strlen(line), len);
  if (row == SIZE_MAX) {
    s->headers++;
    snprintf(s->text, sizeof s->text, "%s", line);
  } else {
    assert_int_equal(row, s->rows);
    s->rows++;
    if (s->stop_at && (int)s->rows == s->stop_at) return QK_ERR_INVALID;
  }
  assert_true(lineno > s->last_line);
  s->last_line = lineno;
  return QK_OK;
}

/* Reads path's points with on_row reporting into *s (cleared first). */
static qk_status_t read_seen(const char *path, seen_t *s, qk_point_t **p, size_t *n,
                             qk_error_t *err) {
  int stop_at = s->stop_at;
  memset(s, 0, sizeof *s);
  s->stop_at = stop_at;
  qk_csv_options_t o;
  qk_csv_options_init(&o);
  o.on_row = on_row;
  o.ud = s;
  return qk_points_read_csv(path, &o, NULL, p, n, err);
}

static void test_io_callback(void **state) {
  (void)state;
  char *path = write_tmp("\xEF\xBB\xBFx,y,name\r\n\n0,0,a\n1,1,\"b\"\n2,2,c\n", -1);
  seen_t s = {0};
  qk_point_t *p;
  size_t n;
  qk_error_t err;
  assert_int_equal(read_seen(path, &s, &p, &n, &err), QK_OK);
  assert_int_equal(n, 3);
  assert_int_equal(s.rows, 3);
  assert_int_equal(s.headers, 1);
  assert_string_equal(s.text, "x,y,name");
  assert_int_equal(s.last_line, 5);
  free(p);
  /* A callback's failure stops the reader with its status. */
  s.stop_at = 2;
  assert_int_equal(read_seen(path, &s, &p, &n, &err), QK_ERR_INVALID);
  assert_null(p);
  assert_int_equal(err.line, 4);
  assert_int_equal(err.item, 1);
  assert_string_equal(err.message, "stopped by the row callback: invalid argument");
  remove(path);
  free(path);
}

/* A quoted field may hold line breaks (RFC 4180): its record spans several lines of the
 * file, and every line number is still the file's physical line (seventeenth session: a
 * break inside quotes in a column not read ended the record there, so the rest of the
 * field was read as rows, e.g. a row (5, 6) that the file does not have). */
static void test_io_multiline_quotes(void **state) {
  (void)state;
  const qk_csv_header_t A = QK_CSV_HEADER_AUTO;
  const double xy[] = {1, 2, 3, 4, 7, 8};
  expect_points("x,y,note\n1,2,\"a\n5,6,\"\n3,4,ok\n7,8,\"\"\"q\"\"\n\n,\"\n", NULL, A, xy, 3);
  expect_points("x,y,note\r\n1,2,\"a\r\n5,6,\"\r\n3,4,ok\r\n7,8,\"\n\"\n", NULL, A, xy, 3);
  /* A quote inside an unquoted field is text and opens nothing. */
  expect_points("x,y,note\n1,2,5\" long\n3,4,ok\n7,8,x\n", NULL, A, xy, 3);
  /* Nor does a quote after text that follows a closing quote, in a column not read: the
   * record ends with its line (the sweep: a scanner that let that quote open a field
   * read the rest of the file into it, passing every test). */
  expect_points("x,y,note\n1,2,\"a\"b\"\n3,4,ok\n7,8,x\n", NULL, A, xy, 3);
  /* An error on a later row names the physical line where that row starts. */
  expect_error("x,y,note\n1,2,\"a\n5,6,\"\n3,4,ok\nnan,1,z\n", -1, NULL, A, QK_ERR_NONFINITE, 5, 1,
               2, "field 1 (x) is not finite: 'nan'");
  expect_error("x,y,note\n1,2,\"a\n\n\nb\"\n3,4,\"\n\"\n5\n", -1, NULL, A, QK_ERR_PARSE, 8, 2, 2,
               "field 2 (y) is missing: the line has 1 field");
  /* An error in a field names the line and column where that field starts. */
  expect_error("name,x,y\n\"A\nB\",1,zz\n", -1, "2,3", A, QK_ERR_PARSE, 3, 6, 0,
               "field 3 (y) is not a number: 'zz'");
  expect_error("\xEF\xBB\xBF\"a\nb\",x,y\n1,2,zz\n", -1, "x,y", A, QK_ERR_PARSE, 3, 5, 0,
               "field 3 (y) is not a number: 'zz'");
  /* A quote left open runs to the end of the file and is reported where its field starts,
   * in a field not read too (its rows would be lost without a word). */
  expect_error("x,y,n\n1,2,ok\n3,4,\"open\n5,6,7\n", -1, NULL, A, QK_ERR_PARSE, 3, 5, SIZE_MAX,
               "field 3: unterminated quoted field (it runs to the end of the file)");
  expect_error("0,0,\"unclosed\n1,2,x\n", -1, NULL, A, QK_ERR_PARSE, 1, 5, SIZE_MAX,
               "field 3: unterminated quoted field (it runs to the end of the file)");
  /* The row callback gets each record's first line and its whole text. */
  char *path = write_tmp("x,y,n\n0,0,\"a\nb\"\n1,1,c\n", -1);
  seen_t s = {0};
  qk_point_t *p;
  size_t n;
  qk_error_t err;
  assert_int_equal(read_seen(path, &s, &p, &n, &err), QK_OK);
  assert_int_equal(n, 2);
  assert_int_equal(s.last_line, 4);
  free(p);
  remove(path);
  free(path);
}

/* Allocation failure at every N, on a file that makes every buffer grow. */
/* An allocator that keeps the peak of the bytes live. */
typedef struct peak {
  size_t live, peak;
} peak_t;

static void *peak_fn(void *ud, void *ptr, size_t osize, size_t nsize) {
  peak_t *p = ud;
  p->live = p->live - (ptr ? osize : 0) + nsize;
  if (p->live > p->peak) p->peak = p->live;
  if (nsize == 0) {
    free(ptr);
    return NULL;
  }
  return realloc(ptr, nsize);
}

static void test_io_binary_stream(void **state) {
  (void)state;
  static const struct {
    const char *head;
    unsigned long line, column;
  } cases[] = {{"", 1, 1}, {"x,y\n1,2\n3,", 3, 3}, {"x,y\n\"1", 2, 3}};
  size_t big = (size_t)32 << 20;
  char *text = calloc(big, 1);
  assert_non_null(text);
  for (size_t c = 0; c < sizeof cases / sizeof *cases; c++) {
    size_t h = strlen(cases[c].head);
    memset(text, 0, 64); /* (the previous case's head) */
    memcpy(text, cases[c].head, h);
    FILE *f = fmemopen(text, big, "r");
    assert_non_null(f);
    peak_t pk = {0, 0};
    qk_allocator_t a = {peak_fn, &pk};
    double *v = NULL;
    size_t rows = 0;
    qk_error_t err;
    qk_status_t st = qk_csv_read_values(f, NULL, 2, 2, &a, &v, &rows, &err);
    fclose(f);
    if (st != QK_ERR_PARSE || !strstr(err.message, "binary data (NUL byte)"))
      fail_msg("case %zu: %s: %s", c, qk_strerror(st), err.message);
    assert_int_equal(err.line, cases[c].line);
    assert_int_equal(err.column, cases[c].column);
    if (pk.peak > (1u << 20)) fail_msg("case %zu: %zu bytes at the peak", c, pk.peak);
    assert_int_equal(pk.live, 0);
  }
  free(text);
}

static void test_io_alloc_failure(void **state) {
  (void)state;
  size_t cap = 2000 * 40 + 140000;
  char *text = malloc(cap);
  assert_non_null(text);
  size_t len = (size_t)snprintf(text, cap, "name,x,y\n");
  for (int i = 0; i < 2000; i++)
    len += (size_t)snprintf(text + len, cap - len, "p%d,%d,%d\n", i, i, -i);
  memset(text + len, 'w', 130000); /* one line longer than two chunks */
  len += 130000;
  len += (size_t)snprintf(text + len, cap - len, ",7,8\n");
  char *path = write_tmp(text, (long)len);
  free(text);
  qk_csv_options_t o;
  qk_csv_options_init(&o);
  o.columns = "y,x";
  qk_point_t *ref;
  size_t nref;
  assert_int_equal(qk_points_read_csv(path, &o, NULL, &ref, &nref, NULL), QK_OK);
  assert_int_equal(nref, 2001);
  assert_true(ref[1999].x == -1999 && ref[1999].y == 1999 && ref[2000].x == 8);
  size_t fail_at = 1;
  for (;; fail_at++) {
    qkt_alloc_t st;
    qk_allocator_t a = qkt_alloc_make(&st);
    st.fail_at = fail_at;
    qk_point_t *p = (qk_point_t *)1;
    size_t n = 99;
    qk_error_t err;
    qk_status_t s = qk_points_read_csv(path, &o, &a, &p, &n, &err);
    if (!st.failed) {
      assert_int_equal(s, QK_OK);
      assert_int_equal(n, nref);
      assert_memory_equal(p, ref, n * sizeof *p);
      assert_int_equal(st.live_blocks, 1);
      a.fn(a.ud, p, n * sizeof *p, 0);
      break;
    }
    if (s != QK_ERR_NOMEM) fail_msg("failing allocation %zu: %s", fail_at, qk_strerror(s));
    assert_string_equal(err.message, "out of memory");
    assert_null(p);
    assert_int_equal(n, 0);
    if (st.live_blocks || st.live_bytes)
      fail_msg("failing allocation %zu leaked %zu blocks", fail_at, st.live_blocks);
  }
  assert_true(fail_at > 10); /* the line buffer, the values and the spans all grew */
  free(ref);
  remove(path);
  free(path);
}

int main(void) {
  const struct CMUnitTest tests[] = {
      cmocka_unit_test(test_io_good_files),    cmocka_unit_test(test_io_columns),
      cmocka_unit_test(test_io_values),        cmocka_unit_test(test_io_round_trip),
      cmocka_unit_test(test_io_errors),        cmocka_unit_test(test_io_callback),
      cmocka_unit_test(test_io_alloc_failure), cmocka_unit_test(test_io_multiline_quotes),
      cmocka_unit_test(test_io_binary_stream),
  };
  return cmocka_run_group_tests(tests, NULL, NULL);
}
