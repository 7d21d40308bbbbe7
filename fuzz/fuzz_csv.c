/*
 * Fuzz target: the library's CSV reader (io/, include/quadkit/io.h), which the CLI reads
 * every input through.
 *
 * The first input byte picks how many columns are read and required (as the
 * subcommands do: points 2, discs 3, boxes 4, rays 4 of 5, up to 16) and the header rule;
 * the rest is written to a file and read back. The reader must either reject the file
 * (a parse, non-finite or limit status, with a message and nothing allocated) or return
 * rows that obey its contract: required values finite, optional ones finite or NaN, no
 * more rows than the file has lines. qk_points_read_csv_file() must agree with it. The
 * read is repeated with the allocator failing at each call in turn: QK_ERR_NOMEM and
 * nothing leaked, or the same answer.
 */
#include "fuzz/fuzz_common.h"

#include <unistd.h>

/* One scratch file per process, rewritten for each input and removed at exit. */
static char csv_path[64];

static void csv_cleanup(void) { remove(csv_path); }

static const char *csv_scratch(const uint8_t *data, size_t size) {
  const char *path = csv_path;
  if (!csv_path[0]) {
    const char *dir = getenv("TMPDIR");
    snprintf(csv_path, sizeof csv_path, "%s/qkf-csv-%ld.csv",
             dir && strlen(dir) < 32 ? dir : "/tmp", (long)getpid());
    atexit(csv_cleanup);
  }
  FILE *f = fopen(path, "wb");
  if (!f || (size && fwrite(data, 1, size, f) != size) || fclose(f) != 0) {
    fprintf(stderr, "fuzz_csv: cannot write %s\n", path);
    abort();
  }
  return path;
}

/* Read the scratch file with the given shape through allocator a. */
static qk_status_t csv_read(const char *path, const qk_csv_options_t *o, size_t cols, size_t req,
                            const qk_allocator_t *a, double **v, size_t *rows, qk_error_t *err) {
  FILE *f = fopen(path, "rb");
  QKF_ASSERT(f, "cannot reopen %s", path);
  qk_status_t st = qk_csv_read_values(f, o, cols, req, a, v, rows, err);
  fclose(f);
  return st;
}

int qkf_csv(const uint8_t *data, size_t size) {
  static const int shapes[][2] = {{2, 2}, {3, 2}, {3, 3}, {4, 4}, {5, 4}, {16, 1}, {16, 16}};
  int sel = size ? data[0] % 7 : 0;
  size_t cols = (size_t)shapes[sel][0], req = (size_t)shapes[sel][1];
  qk_csv_options_t o;
  qk_csv_options_init(&o);
  o.header = (qk_csv_header_t)(size ? (data[0] / 7) % 3 : 0);
  const uint8_t *body = size ? data + 1 : data;
  size_t n = size ? size - 1 : 0;
  const char *path = csv_scratch(body, n);

  size_t lines = 1;
  for (size_t i = 0; i < n; i++) lines += body[i] == '\n';

  qkt_alloc_t as;
  qk_allocator_t al = qkt_alloc_make(&as);
  double *v = NULL;
  size_t rows = 0;
  qk_error_t err;
  qk_status_t st = csv_read(path, &o, cols, req, &al, &v, &rows, &err);
  QKF_ASSERT(st == QK_OK || st == QK_ERR_PARSE || st == QK_ERR_NONFINITE || st == QK_ERR_LIMIT,
             "qk_csv_read_values returned %s", qk_strerror(st));
  if (st != QK_OK) {
    QKF_ASSERT(v == NULL && rows == 0, "rejected input left rows");
    QKF_ASSERT(err.message[0] && err.line > 0, "rejection without a line and message");
    QKF_ASSERT(as.live_blocks == 0, "rejected input leaked %zu blocks", as.live_blocks);
  } else {
    QKF_ASSERT(rows <= lines, "%zu rows from %zu lines", rows, lines);
    QKF_ASSERT(as.live_blocks == (rows ? 1u : 0u), "%zu blocks live", as.live_blocks);
    for (size_t r = 0; r < rows; r++)
      for (size_t c = 0; c < cols; c++) {
        double x = v[r * cols + c];
        QKF_ASSERT(isfinite(x) || (c >= req && isnan(x)), "row %zu field %zu: %g", r, c, x);
      }
  }
  /* The points reader is the 2-of-2 reader. */
  if (cols == 2 && req == 2) {
    FILE *f = fopen(path, "rb");
    QKF_ASSERT(f, "cannot reopen %s", path);
    qk_point_t *pts = NULL;
    size_t np = 0;
    qk_status_t ps = qk_points_read_csv_file(f, &o, NULL, &pts, &np, NULL);
    fclose(f);
    QKF_ASSERT(ps == st, "points reader %s, values reader %s", qk_strerror(ps), qk_strerror(st));
    QKF_ASSERT(np == rows, "points reader read %zu points, values reader %zu rows", np, rows);
    for (size_t i = 0; i < np; i++)
      QKF_ASSERT(pts[i].x == v[2 * i] && pts[i].y == v[2 * i + 1], "point %zu differs", i);
    free(pts);
  }
  /* Allocation failure at each call (a few, to bound the work). */
  for (size_t k = 1; k <= 6; k++) {
    double *w = NULL;
    size_t wr = 0;
    qkt_alloc_arm(&as, k);
    qk_status_t ws = csv_read(path, &o, cols, req, &al, &w, &wr, &err);
    if (ws == QK_ERR_NOMEM) {
      QKF_ASSERT(w == NULL && wr == 0, "failed read left rows");
    } else {
      QKF_ASSERT(ws == st && wr == rows, "with call %zu failing: %s, %zu rows", k, qk_strerror(ws),
                 wr);
      for (size_t i = 0; i < wr * cols; i++)
        QKF_ASSERT(memcmp(&w[i], &v[i], sizeof *w) == 0, "value %zu differs", i);
    }
    if (w) al.fn(al.ud, w, wr * cols * sizeof *w, 0);
    QKF_ASSERT(as.live_blocks == (rows ? 1u : 0u), "call %zu failing leaked", k);
    if (!as.failed) break;
  }
  if (v) al.fn(al.ud, v, rows * cols * sizeof *v, 0);
  return 0;
}

#ifndef QKF_REPLAY
int LLVMFuzzerTestOneInput(const uint8_t *data, size_t size);
int LLVMFuzzerTestOneInput(const uint8_t *data, size_t size) { return qkf_csv(data, size); }
#endif
