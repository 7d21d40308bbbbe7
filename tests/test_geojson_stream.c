/*
 * qk_region_read_geojson on a stream (a pipe) that may never end. The reader keeps the
 * whole text, so an endless text grew until the machine ran out of memory; now:
 *  - a stream is read to at most qk__geojson_stream_max bytes (2^31 - 1; lowered here to
 *    1 MiB): past it the read stops, QK_ERR_LIMIT with a message naming the limit;
 *    endless blanks and an endless FeatureCollection (the same feature again and again)
 *    both stop there, and the writer is refused (EPIPE) after at most the limit, what a
 *    pipe buffers and one write more;
 *  - a text of exactly the limit is read (a valid collection padded to that many bytes),
 *    and a regular file is not limited (one of 4 MiB reads with the limit at 1 MiB);
 *  - a text whose first value (after a byte order mark and blanks) is not an object is
 *    refused at that value after one read: `yes x` as malformed JSON at 1:1, endless
 *    "[1,2]" lines and an endless "null" as not a GeoJSON object, the position counted
 *    after the mark and across blank lines. The wording is the whole text's reading's:
 *    the same input, cut short to a buffer, gives the same message (the oracle).
 * Oracles: the bytes the writer thread got into the pipe before EPIPE; the messages of
 * qk_region_read_geojson_text on the same text read whole.
 */
#define _POSIX_C_SOURCE 200809L
#include "support/qk_test.h"

#include <errno.h>
#include <pthread.h>
#include <signal.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <unistd.h>

#ifdef QK_HAVE_JSONC
/* The reader's limit for a stream (region/geojson.c), lowered by the tests. */
extern size_t qk__geojson_stream_max;

enum { LIMIT = 1 << 20, SAFETY = 64 << 20 };

/* A writer thread: `head` once, then `body` again and again until the reader closes the
 * pipe (EPIPE) or, bounded, `total` bytes are written (SIZE_MAX: until EPIPE, at most
 * SAFETY bytes so that a reader without a limit still ends). */
typedef struct writer {
  int fd;
  const char *head, *body;
  size_t total; /* bytes to write in all (a bounded text), or SIZE_MAX */
  size_t written;
  int epipe;
} writer_t;

/* Write n bytes of s (fewer when w's bound comes first); 0 when the reader went away. */
static int put(writer_t *w, const char *s, size_t n, size_t limit) {
  while (n && w->written < limit) {
    size_t m = n < limit - w->written ? n : limit - w->written;
    ssize_t k = write(w->fd, s, m);
    if (k < 0) {
      w->epipe = errno == EPIPE;
      return 0;
    }
    w->written += (size_t)k, s += k, n -= (size_t)k;
  }
  return 1;
}

static void *write_all(void *p) {
  writer_t *w = p;
  char buf[4096];
  size_t bn = strlen(w->body), fill = 0, limit = w->total != SIZE_MAX ? w->total : SAFETY;
  while (fill + bn <= sizeof buf) memcpy(buf + fill, w->body, bn), fill += bn;
  if (put(w, w->head, strlen(w->head), limit))
    while (w->written < limit && put(w, buf, fill, limit)) {
    }
  close(w->fd);
  return NULL;
}

/* Read the pipe's other end as a path (/dev/fd/N) while w writes; the status. */
static qk_status_t read_pipe(writer_t *w, qk_region_t **r, qk_error_t *err) {
  int fds[2];
  assert_int_equal(pipe(fds), 0);
  w->fd = fds[1], w->written = 0, w->epipe = 0;
  pthread_t t;
  assert_int_equal(pthread_create(&t, NULL, write_all, w), 0);
  char path[64];
  snprintf(path, sizeof path, "/dev/fd/%d", fds[0]);
  qk_region_options_t o;
  qk_region_options_init(&o);
  o.planar = 1;
  qk_status_t st = qk_region_read_geojson(path, &o, r, err);
  close(fds[0]); /* (the reader's own descriptor is closed: now the writer gets EPIPE) */
  pthread_join(t, NULL);
  return st;
}

static void limit_message(char *buf, size_t n, size_t limit) {
  snprintf(buf, n,
           "GeoJSON text from a pipe or device longer than %zu bytes, the limit for a stream "
           "(a regular file has none)",
           limit);
}

#define FEATURE                                                                                    \
  "{\"type\":\"Feature\",\"properties\":{\"k\":1},\"geometry\":{\"type\":\"Polygon\","             \
  "\"coordinates\":[[[0,0],[1,0],[1,1],[0,1],[0,0]]]}}"
#define HEAD "{\"type\":\"FeatureCollection\",\"features\":["
#endif

static void test_geojson_stream_endless(void **state) {
  (void)state;
#ifndef QK_HAVE_JSONC
  skip();
#else
  signal(SIGPIPE, SIG_IGN);
  size_t saved = qk__geojson_stream_max;
  qk__geojson_stream_max = LIMIT;
  char want[256];
  limit_message(want, sizeof want, LIMIT);
  const char *heads[] = {"", HEAD, "\xEF\xBB\xBF{\"type\":"};
  const char *bodies[] = {" \n\t", FEATURE ",\n", " "};
  for (int c = 0; c < 3; c++) {
    writer_t w = {.head = heads[c], .body = bodies[c], .total = SIZE_MAX};
    qk_region_t *r = (qk_region_t *)1;
    qk_error_t err;
    assert_int_equal(read_pipe(&w, &r, &err), QK_ERR_LIMIT);
    assert_null(r);
    assert_string_equal(err.message, want);
    assert_int_equal(err.line, 0);
    /* Reading stopped at the limit: the writer was refused after the limit, the pipe's
     * buffer (64 KiB on Linux; 1 MiB allowed) and one write. */
    assert_true(w.epipe);
    assert_true(w.written > LIMIT);
    assert_true(w.written < 2 * LIMIT + 4096);
  }
  qk__geojson_stream_max = saved;
#endif
}

#ifdef QK_HAVE_JSONC
/* A valid collection of exactly n bytes: three features, blanks to pad, the closing
 * brackets. */
static char *collection_of(size_t n, size_t *features) {
  char *t = malloc(n + 1);
  assert_non_null(t);
  size_t len = strlen(HEAD), fl = strlen(FEATURE);
  memcpy(t, HEAD, len);
  *features = 0;
  while (*features < 3 && len + fl + 1 + 2 <= n) { /* (overlapping squares: few) */
    if (*features) t[len++] = ',';
    memcpy(t + len, FEATURE, fl), len += fl;
    ++*features;
  }
  while (len + 2 < n) t[len++] = ' ';
  memcpy(t + len, "]}", 2), len += 2;
  t[len] = '\0';
  assert_int_equal(len, n);
  return t;
}
#endif

static void test_geojson_stream_bounded(void **state) {
  (void)state;
#ifndef QK_HAVE_JSONC
  skip();
#else
  signal(SIGPIPE, SIG_IGN);
  size_t saved = qk__geojson_stream_max;
  qk__geojson_stream_max = LIMIT;
  /* Exactly the limit: read whole. One byte more (a blank before the end): refused. */
  size_t nf = 0;
  char *text = collection_of(LIMIT, &nf);
  writer_t w = {.head = text, .body = " ", .total = LIMIT};
  qk_region_t *r = NULL;
  qk_error_t err;
  assert_int_equal(read_pipe(&w, &r, &err), QK_OK);
  assert_int_equal(w.written, LIMIT);
  assert_int_equal(qk_region_feature_count(r), nf);
  qk_region_free(r);
  free(text);
  text = collection_of(LIMIT + 1, &nf);
  writer_t w1 = {.head = text, .body = " ", .total = LIMIT + 1};
  assert_int_equal(read_pipe(&w1, &r, &err), QK_ERR_LIMIT);
  assert_null(r);
  free(text);

  /* A regular file four times the limit: not limited. */
  text = collection_of(4 * LIMIT, &nf);
  char path[] = "/tmp/qk_geojson_stream_XXXXXX";
  int fd = mkstemp(path);
  assert_true(fd >= 0);
  assert_int_equal(write(fd, text, 4 * LIMIT), 4 * LIMIT);
  close(fd);
  qk_region_options_t o;
  qk_region_options_init(&o);
  o.planar = 1;
  assert_int_equal(qk_region_read_geojson(path, &o, &r, &err), QK_OK);
  assert_int_equal(qk_region_feature_count(r), nf);
  qk_region_free(r);
  unlink(path);
  free(text);
  qk__geojson_stream_max = saved;
#endif
}

static void test_geojson_stream_not_object(void **state) {
  (void)state;
#ifndef QK_HAVE_JSONC
  skip();
#else
  signal(SIGPIPE, SIG_IGN);
  /* (the default limit: a reader that waited for the end would take seconds and 2 GiB) */
  static const struct {
    const char *head, *body;
    unsigned long line, column;
  } cases[] = {
      {"", "x\n", 1, 1},                         /* yes x */
      {"", "[1,2]\n", 1, 1},                     /* yes '[1,2]' */
      {"  \n\n", "null", 3, 1},                  /* blank lines, then nulls */
      {"\xEF\xBB\xBF \t", "\"s\",", 1, 3},       /* a mark, blanks, then strings */
      {"\r\n ", "}", 2, 2},                      /* a byte that starts no value */
      {"\xEF\xBB\xBF\xEF\xBB\xBF", "{} ", 1, 1}, /* a second mark is no blank */
  };
  for (size_t c = 0; c < sizeof cases / sizeof *cases; c++) {
    writer_t w = {.head = cases[c].head, .body = cases[c].body, .total = SIZE_MAX};
    qk_region_t *r = (qk_region_t *)1;
    qk_error_t err;
    assert_int_equal(read_pipe(&w, &r, &err), QK_ERR_PARSE);
    assert_null(r);
    assert_int_equal(err.line, cases[c].line);
    assert_int_equal(err.column, cases[c].column);
    /* One read of 64 KiB, plus the pipe's buffer and one write. */
    assert_true(w.epipe);
    assert_true(w.written < (256 << 10));
    /* The oracle: the whole text's reading of a short text of the same kind, whose value
     * after the first is cut off (so that it is the first value's message). */
    char shorttext[64];
    snprintf(shorttext, sizeof shorttext, "%s%s", cases[c].head, cases[c].body);
    size_t n = strlen(shorttext);
    while (n && strchr(",\n", shorttext[n - 1])) n--;
    qk_error_t whole;
    qk_region_t *r2 = NULL;
    assert_int_equal(qk_region_read_geojson_text(shorttext, n, NULL, &r2, &whole), QK_ERR_PARSE);
    /* (a document that is null alone is said to be null; here more follows it) */
    if (!strcmp(cases[c].body, "null"))
      assert_string_equal(err.message, "expected a GeoJSON object with a string \"type\"");
    else
      assert_string_equal(err.message, whole.message);
    assert_int_equal(err.line, whole.line);
    assert_int_equal(err.column, whole.column);
  }
#endif
}

int main(void) {
  qkt_filters_from_env();
  const struct CMUnitTest tests[] = {
      cmocka_unit_test(test_geojson_stream_endless),
      cmocka_unit_test(test_geojson_stream_bounded),
      cmocka_unit_test(test_geojson_stream_not_object),
  };
  return cmocka_run_group_tests(tests, NULL, NULL);
}
