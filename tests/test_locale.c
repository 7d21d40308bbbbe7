/*
 * Test plan for numbers as text under a locale whose decimal separator is a comma
 * (index/textloc.h): a program that called setlocale(LC_ALL, "de_DE.UTF-8"), or a thread
 * that called uselocale() with such a locale, gets from every reader and writer exactly
 * what the C locale gets:
 *  - the readers (points CSV, the values reader, `.poly`) accept "1.5" with the same
 *    values and refuse "1,5" with the same status, message, line and column; GeoJSON
 *    (json-c) reads "10.5" as 10.5;
 *  - error messages holding numbers (the mesher's, the region builder's) are the same;
 *  - the writers (tree and region SVG; mesh .node, .ele, .poly, .msh, .vtu, SVG) write the
 *    same bytes; the .node coordinates include 1.5e-7, which numfmt's fast path leaves to
 *    snprintf;
 *  - the caller's locale is in place again after each call.
 * The comma locale: an installed one (de_DE.UTF-8, fr_FR.UTF-8, ...), else one built at
 * test time with localedef (libc-bin, always there) from a definition written here (only
 * LC_NUMERIC; the `locales` package's sources are not needed) into a temporary directory
 * named by LOCPATH, about 5 ms. Without either the tests report themselves skipped.
 */
#define _POSIX_C_SOURCE 200809L
#include <locale.h>
#include <pthread.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "qk_test.h"

/* Loading a locale from LOCPATH, glibc keeps blocks that LeakSanitizer reports as leaked
 * (made by __argz_add_sep inside setlocale and newlocale; not the library's): under ASan
 * they are suppressed by name, through LeakSanitizer's hook for built-in suppressions. */
#if defined(__SANITIZE_ADDRESS__)
#define QKT_LSAN 1
#elif defined(__has_feature)
#if __has_feature(address_sanitizer)
#define QKT_LSAN 1
#endif
#endif
#if defined(QKT_LSAN)
const char *__lsan_default_suppressions(void);
const char *__lsan_default_suppressions(void) { return "leak:__argz_add_sep\n"; }
#endif

/* ---- the comma locale ------------------------------------------------------------- */

static char comma_name[64]; /* "" when there is none */
static char built_dir[256]; /* the temporary LOCPATH directory, "" when none was made */

static int is_comma(const char *name) {
  int ok = setlocale(LC_ALL, name) && strcmp(localeconv()->decimal_point, ",") == 0;
  setlocale(LC_ALL, "C");
  return ok;
}

static int write_file(const char *path, const char *text) {
  FILE *f = fopen(path, "w");
  if (!f) return 0;
  int ok = fputs(text, f) >= 0;
  return fclose(f) == 0 && ok;
}

/* A locale "qk_comma" built with localedef into a temporary directory (LOCPATH). */
static int build_comma_locale(void) {
  const char *tmp = getenv("TMPDIR");
  snprintf(built_dir, sizeof built_dir, "%s/qk-test-locale-XXXXXX", tmp && *tmp ? tmp : "/tmp");
  if (!mkdtemp(built_dir)) return built_dir[0] = '\0', 0;
  /* An ASCII character map: every code named <Uxxxx>, so LC_NUMERIC can name ',' and '.'. */
  char map[8192], *p = map;
  p += sprintf(p, "<code_set_name> ANSI_X3.4-1968\n<escape_char> /\n<comment_char> %%\n"
                  "<mb_cur_min> 1\n<mb_cur_max> 1\nCHARMAP\n");
  for (int c = 0; c < 128; c++) p += sprintf(p, "<U%04X> /x%02x\n", c, c);
  sprintf(p, "END CHARMAP\n");
  char path[512], cmd[2048];
  snprintf(path, sizeof path, "%s/charmap", built_dir);
  if (!write_file(path, map)) return 0;
  snprintf(path, sizeof path, "%s/comma.src", built_dir);
  if (!write_file(path, "LC_NUMERIC\ndecimal_point \"<U002C>\"\nthousands_sep \"<U002E>\"\n"
                        "grouping 3;3\nEND LC_NUMERIC\n"))
    return 0;
  /* -c: the categories not defined (all but LC_NUMERIC) take the POSIX values, with a
   * warning and exit status 1, so the result is judged by setlocale below. */
  snprintf(cmd, sizeof cmd,
           "localedef -c -f '%s/charmap' -i '%s/comma.src' '%s/qk_comma' >/dev/null 2>&1",
           built_dir, built_dir, built_dir);
  if (system(cmd) == -1) return 0;
  setenv("LOCPATH", built_dir, 1);
  return is_comma("qk_comma");
}

static int group_setup(void **state) {
  (void)state;
  static const char *names[] = {"de_DE.UTF-8", "de_DE.utf8", "de_DE",       "fr_FR.UTF-8",
                                "fr_FR.utf8",  "fr_FR",      "nl_NL.UTF-8", "it_IT.UTF-8",
                                "es_ES.UTF-8", "ru_RU.UTF-8"};
  for (size_t i = 0; i < sizeof names / sizeof *names; i++)
    if (is_comma(names[i])) {
      snprintf(comma_name, sizeof comma_name, "%s", names[i]);
      return 0;
    }
  if (build_comma_locale()) snprintf(comma_name, sizeof comma_name, "qk_comma");
  return 0;
}

static int group_teardown(void **state) {
  (void)state;
  setlocale(LC_ALL, "C");
  if (built_dir[0]) {
    char cmd[512];
    snprintf(cmd, sizeof cmd, "rm -rf '%s'", built_dir);
    if (system(cmd) != 0) fprintf(stderr, "could not remove %s\n", built_dir);
  }
  return 0;
}

/* ---- every reader and writer, their results as bytes ------------------------------ */

/* Named sections of bytes, compared one by one. No number is printed here with printf:
 * values go in as their bytes, so the record itself does not follow the locale. */
enum { MAX_SECTIONS = 40 };
typedef struct record {
  const char *name[MAX_SECTIONS];
  char *bytes[MAX_SECTIONS];
  size_t len[MAX_SECTIONS];
  size_t n;
} record_t;

static void add(record_t *r, const char *name, const void *bytes, size_t len) {
  assert_true(r->n < MAX_SECTIONS);
  r->name[r->n] = name;
  r->bytes[r->n] = malloc(len + 1);
  assert_non_null(r->bytes[r->n]);
  memcpy(r->bytes[r->n], bytes, len);
  r->bytes[r->n][len] = '\0';
  r->len[r->n++] = len;
}

static void add_status(record_t *r, const char *name, qk_status_t st, const char *message,
                       unsigned long line, unsigned long column) {
  char b[512]; /* the status, then the message (NUL-terminated), line and column */
  size_t n = 0, m = strlen(message) + 1;
  assert_true(sizeof st + m + sizeof line + sizeof column <= sizeof b);
  memcpy(b, &st, sizeof st), n += sizeof st;
  memcpy(b + n, message, m), n += m;
  memcpy(b + n, &line, sizeof line), n += sizeof line;
  memcpy(b + n, &column, sizeof column), n += sizeof column;
  add(r, name, b, n);
}

static void free_record(record_t *r) {
  for (size_t i = 0; i < r->n; i++) free(r->bytes[i]);
  r->n = 0;
}

typedef enum writer {
  W_TREE_SVG,
  W_REGION_SVG,
  W_NODE,
  W_ELE,
  W_POLY,
  W_MSH,
  W_VTU,
  W_MESH_SVG
} writer_t;

static void add_output(record_t *r, const char *name, writer_t w, const void *obj) {
  char *buf = NULL;
  size_t len = 0;
  FILE *f = open_memstream(&buf, &len);
  assert_non_null(f);
  qk_status_t st = QK_ERR_INVALID;
  switch (w) {
  case W_TREE_SVG:
    st = qk_tree_write_svg(obj, f, 800);
    break;
  case W_REGION_SVG:
    st = qk_region_write_svg(obj, f, 1000);
    break;
  case W_NODE:
    st = qk_mesh_write_node(obj, f, 0);
    break;
  case W_ELE:
    st = qk_mesh_write_ele(obj, f, 0);
    break;
  case W_POLY:
    st = qk_mesh_write_poly(obj, f, 0);
    break;
  case W_MSH:
    st = qk_mesh_write_msh(obj, f);
    break;
  case W_VTU:
    st = qk_mesh_write_vtu(obj, f);
    break;
  case W_MESH_SVG:
    st = qk_mesh_write_svg(obj, f, 800);
    break;
  }
  assert_int_equal(st, QK_OK);
  assert_int_equal(fclose(f), 0);
  add(r, name, buf, len);
  free(buf);
}

static FILE *text_stream(const char *text) {
  FILE *f = fmemopen((void *)text, strlen(text), "r");
  assert_non_null(f);
  return f;
}

static void read_csv(record_t *r, const char *name, const char *text) {
  FILE *f = text_stream(text);
  qk_point_t *pts = NULL;
  size_t n = 0;
  qk_error_t err = {0};
  qk_status_t st = qk_points_read_csv_file(f, NULL, NULL, &pts, &n, &err);
  fclose(f);
  add_status(r, name, st, err.message, err.line, err.column);
  add(r, name, pts ? (const void *)pts : "", n * sizeof *pts);
  free(pts);
}

static void read_poly(record_t *r, const char *name, const char *text) {
  FILE *f = text_stream(text);
  qk_poly_t *p = NULL;
  qk_mesh_error_t err = {0};
  qk_status_t st = qk_poly_read(f, NULL, &p, &err);
  fclose(f);
  add_status(r, name, st, err.message, err.line, err.column);
  double xy[8];
  size_t nv = 0;
  if (p) assert_int_equal(qk_poly_vertices(p, xy, 4, &nv), QK_OK);
  add(r, name, xy, 2 * nv * sizeof *xy);
  qk_poly_free(p);
}

/* Everything, in the calling thread's locale. */
static void run_all(record_t *r) {
  /* Readers: "1.5" is read, "1,5" refused, as in the C locale. */
  read_csv(r, "csv 1.5", "x,y\n1.5,2.25\n-0.125e1,.5\n");
  read_csv(r, "csv \"1,5\"", "x,y\n\"1,5\",2\n");
  read_csv(r, "csv 1.5 below the smallest double", "x,y\n1.5e-400,2\n");
  {
    FILE *f = text_stream("a,b,c\n1.5,,2e-3\n0.25,7.75,\n");
    double *v = NULL;
    size_t rows = 0;
    qk_error_t err = {0};
    qk_status_t st = qk_csv_read_values(f, NULL, 3, 1, NULL, &v, &rows, &err);
    fclose(f);
    add_status(r, "csv values", st, err.message, err.line, err.column);
    add(r, "csv values", v ? (const void *)v : "", rows * 3 * sizeof *v);
    free(v);
  }
  read_poly(r, "poly 1.5", "3 2 0 0\n0 0 0\n1 1.5 0\n2 0 1.5\n3 0\n0 0 1\n1 1 2\n2 2 0\n0\n");
  read_poly(r, "poly 1,5", "3 2 0 0\n0 0 0\n1 1,5 0\n2 0 1.5\n3 0\n0 0 1\n1 1 2\n2 2 0\n0\n");

  /* Error messages holding numbers. */
  const double xy[] = {0, 0, 1.5e-7, 0, 0, 1.5e-7};
  const uint32_t seg[] = {0, 1, 1, 2, 2, 0};
  qk_poly_t *poly = NULL;
  qk_mesh_error_t me = {0};
  assert_int_equal(qk_poly_from_arrays(xy, 3, seg, 3, NULL, 0, NULL, &poly, &me), QK_OK);
  qk_mesh_options_t mo;
  qk_mesh_options_init(&mo);
  mo.max_size = -1.5;
  qk_mesh_t *m = NULL;
  qk_status_t st = qk_mesh_generate(poly, &mo, &m, &me);
  add_status(r, "mesh max_size -1.5", st, me.message, me.line, 0);
  {
    const double xy[] = {0, 0, 200.5, 0, 200.5, 1.5, 0, 0};
    const size_t rs[] = {0, 4}, fs[] = {0, 1};
    qk_region_arrays_t in = {xy, rs, 1, fs, 1};
    qk_region_t *reg = NULL;
    qk_error_t err = {0};
    st = qk_region_from_arrays(&in, NULL, &reg, &err);
    add_status(r, "region lon 200.5", st, err.message, err.line, err.column);
    qk_region_free(reg);
  }

  /* Writers. */
  qk_point_t pts[3] = {{0, 0}, {1, 1}, {0.3, 0.7}};
  qk_tree_options_t to;
  qk_tree_options_init(&to);
  qk_tree_t *t = NULL;
  assert_int_equal(qk_tree_build(pts, 3, &to, &t), QK_OK);
  add_output(r, "tree svg", W_TREE_SVG, t);
  qk_tree_free(t);

  const double regions[] = {0.3e-7, 0.3e-7, 2.5};
  assert_int_equal(qk_poly_set_regions(poly, regions, 1, &me), QK_OK);
  qk_mesh_options_init(&mo);
  assert_int_equal(qk_mesh_generate(poly, &mo, &m, &me), QK_OK);
  add_output(r, "mesh .node", W_NODE, m);
  add_output(r, "mesh .ele", W_ELE, m);
  add_output(r, "mesh .poly", W_POLY, m);
  add_output(r, "mesh .msh", W_MSH, m);
  add_output(r, "mesh .vtu", W_VTU, m);
  add_output(r, "mesh svg", W_MESH_SVG, m);
  qk_mesh_free(m);
  qk_poly_free(poly);

  qk_region_options_t ro;
  qk_region_options_init(&ro);
  ro.planar = 1;
  {
    const double rxy[] = {0, 0, 10.5, 0, 10.5, 10.5, 0, 0};
    const size_t rs[] = {0, 4}, fs[] = {0, 1};
    qk_region_arrays_t in = {rxy, rs, 1, fs, 1};
    qk_region_t *reg = NULL;
    assert_int_equal(qk_region_from_arrays(&in, &ro, &reg, NULL), QK_OK);
    add_output(r, "region svg", W_REGION_SVG, reg);
    qk_region_free(reg);
  }
#ifdef QK_HAVE_JSONC
  {
    const char *gj = "{\"type\":\"Polygon\",\"coordinates\":[[[0,0],[10.5,0],[10.5,10.5],[0,0]]]}";
    qk_region_t *reg = NULL;
    qk_error_t err = {0};
    st = qk_region_read_geojson_text(gj, strlen(gj), &ro, &reg, &err);
    add_status(r, "geojson 10.5", st, err.message, err.line, err.column);
    uint32_t feat = 7;
    if (reg) {
      assert_int_equal(qk_region_locate(reg, (qk_point_t){8, 1}, QK_BOUNDARY_SEMI_OPEN, &feat),
                       QK_OK);
      assert_int_equal(feat, 0); /* inside only when 10.5 is read as 10.5 */
      add_output(r, "geojson svg", W_REGION_SVG, reg);
    }
    qk_region_free(reg);
  }
#endif
}

/* The C locale's record, checked against what it must hold. */
static void run_reference(record_t *ref) {
  setlocale(LC_ALL, "C");
  run_all(ref);
  qk_status_t st;
  memcpy(&st, ref->bytes[0], sizeof st);
  assert_int_equal(st, QK_OK); /* csv 1.5 */
  const double want[4] = {1.5, 2.25, -1.25, 0.5};
  assert_int_equal(ref->len[1], sizeof want);
  assert_memory_equal(ref->bytes[1], want, sizeof want);
  memcpy(&st, ref->bytes[2], sizeof st);
  assert_int_equal(st, QK_ERR_PARSE); /* csv "1,5" */
}

/* Every section that differs is listed (a status section shows its message). */
static void assert_same(const record_t *ref, const record_t *got, const char *where) {
  assert_int_equal(ref->n, got->n);
  size_t bad = 0;
  for (size_t i = 0; i < ref->n; i++) {
    assert_string_equal(ref->name[i], got->name[i]);
    if (ref->len[i] == got->len[i] && memcmp(ref->bytes[i], got->bytes[i], ref->len[i]) == 0)
      continue;
    size_t k = 0;
    while (k < ref->len[i] && k < got->len[i] && ref->bytes[i][k] == got->bytes[i][k]) k++;
    size_t from = k > 40 ? k - 40 : k < sizeof(qk_status_t) ? sizeof(qk_status_t) : 0;
    if (from > ref->len[i] || from > got->len[i]) from = 0;
    print_error("%s: '%s' differs from the C locale's at byte %zu:\n  C:     '%.80s'\n  comma: "
                "'%.80s'\n",
                where, ref->name[i], k, ref->bytes[i] + from, got->bytes[i] + from);
    bad++;
  }
  if (bad) fail_msg("%s: %zu of %zu results differ from the C locale's", where, bad, ref->n);
}

/* setlocale(LC_ALL, comma) in the program: every result as in the C locale, and the
 * program's locale still the comma one after each call. */
static void test_locale_global(void **state) {
  (void)state;
  QKT_ONE_THREAD_TEST();
  if (!comma_name[0]) skip(); /* no comma locale here, and localedef could not make one */
  record_t ref = {0}, got = {0};
  run_reference(&ref);
  assert_non_null(setlocale(LC_ALL, comma_name));
  assert_string_equal(localeconv()->decimal_point, ",");
  run_all(&got);
  assert_string_equal(localeconv()->decimal_point, ","); /* restored by every call */
  setlocale(LC_ALL, "C");
  assert_same(&ref, &got, "setlocale");
  free_record(&ref);
  free_record(&got);
}

typedef struct thread_arg {
  record_t rec;
  int restored;
} thread_arg_t;

static void *thread_main(void *ud) {
  thread_arg_t *a = ud;
  locale_t loc = newlocale(LC_ALL_MASK, comma_name, (locale_t)0);
  if (!loc) return NULL;
  locale_t old = uselocale(loc);
  run_all(&a->rec);
  a->restored = uselocale((locale_t)0) == loc && strcmp(localeconv()->decimal_point, ",") == 0;
  uselocale(old);
  freelocale(loc);
  return NULL;
}

/* A thread with uselocale(comma) while the program stays in the C locale: the same. */
static void test_locale_thread(void **state) {
  (void)state;
  if (!comma_name[0]) skip();
  record_t ref = {0};
  run_reference(&ref);
  thread_arg_t a;
  memset(&a, 0, sizeof a);
  pthread_t th;
  assert_int_equal(pthread_create(&th, NULL, thread_main, &a), 0);
  assert_int_equal(pthread_join(th, NULL), 0);
  assert_int_equal(a.rec.n, ref.n); /* (0: newlocale failed in the thread) */
  assert_true(a.restored);
  assert_same(&ref, &a.rec, "uselocale in a thread");
  free_record(&ref);
  free_record(&a.rec);
}

int main(void) {
  const struct CMUnitTest tests[] = {
      cmocka_unit_test(test_locale_global),
      cmocka_unit_test(test_locale_thread),
  };
  return cmocka_run_group_tests(tests, group_setup, group_teardown);
}
