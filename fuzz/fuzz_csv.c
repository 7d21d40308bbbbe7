/*
 * Fuzz target: the CLI's CSV reader (tools/csv.c, compiled in).
 *
 * The first input byte picks how many fields are required and allowed (as the
 * subcommands do: points 2, discs 3, boxes and rays 4, up to 16); the rest is written to
 * a file and read back. The reader must either reject the file with "bad input" or
 * return rows that obey its contract: each row has between min and max fields, the
 * present ones finite, the missing ones NaN, and no more rows than the file has lines.
 * cli_read_points() must agree with it.
 */
#include "fuzz/fuzz_common.h"

#include <unistd.h>

#include "tools/cli.h"
/* The reader itself, so that the target needs no CLI binary (it is not in the library). */
#include "tools/csv.c"

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

int qkf_csv(const uint8_t *data, size_t size) {
  static const int shapes[][2] = {{2, 2}, {2, 3}, {3, 3}, {4, 4}, {2, 5}, {1, 16}, {16, 16}};
  int sel = size ? data[0] % 7 : 0;
  int minf = shapes[sel][0], maxf = shapes[sel][1];
  const uint8_t *body = size ? data + 1 : data;
  size_t n = size ? size - 1 : 0;
  const char *path = csv_scratch(body, n);

  size_t lines = 1;
  for (size_t i = 0; i < n; i++) lines += body[i] == '\n';

  cli_table_t t;
  int rc = cli_read_csv(path, minf, maxf, &t);
  QKF_ASSERT(rc == CLI_OK || rc == CLI_BAD_INPUT, "cli_read_csv returned %d", rc);
  if (rc != CLI_OK) {
    QKF_ASSERT(t.v == NULL && t.rows == 0 && t.nfields == NULL, "rejected table not emptied");
  } else {
    QKF_ASSERT(t.rows <= lines, "%zu rows from %zu lines", t.rows, lines);
    QKF_ASSERT(t.cols == maxf, "cols %d, want %d", t.cols, maxf);
    for (size_t r = 0; r < t.rows; r++) {
      int nf = t.nfields[r];
      QKF_ASSERT(nf >= minf && nf <= maxf, "row %zu has %d fields (allowed %d..%d)", r, nf, minf,
                 maxf);
      for (int c = 0; c < maxf; c++) {
        double v = t.v[r * (size_t)maxf + (size_t)c];
        if (c < nf)
          QKF_ASSERT(isfinite(v), "row %zu field %d not finite", r, c);
        else
          QKF_ASSERT(isnan(v), "row %zu missing field %d is not NaN", r, c);
      }
    }
  }
  /* The points reader is the 2..2 reader plus "at least one row". */
  if (minf == 2 && maxf == 2) {
    qk_point_t *pts = NULL;
    size_t np = 0;
    int prc = cli_read_points(path, &pts, &np);
    int want = rc != CLI_OK ? rc : t.rows == 0 ? CLI_BAD_INPUT : CLI_OK;
    QKF_ASSERT(prc == want, "cli_read_points = %d, want %d", prc, want);
    if (prc == CLI_OK) {
      QKF_ASSERT(np == t.rows, "cli_read_points read %zu points, table %zu rows", np, t.rows);
      for (size_t i = 0; i < np; i++)
        QKF_ASSERT(pts[i].x == t.v[2 * i] && pts[i].y == t.v[2 * i + 1], "point %zu differs", i);
    }
    free(pts);
  }
  if (rc == CLI_OK) cli_table_free(&t);
  return 0;
}

#ifndef QKF_REPLAY
int LLVMFuzzerTestOneInput(const uint8_t *data, size_t size);
int LLVMFuzzerTestOneInput(const uint8_t *data, size_t size) { return qkf_csv(data, size); }
#endif
