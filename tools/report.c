/* Messages of the command-line tool, and library statuses mapped to exit codes. */
#include <math.h>
#include <stdarg.h>
#include <stdio.h>

#include "cli.h"

void cli_error(const char *cmd, const char *fmt, ...) {
  va_list ap;
  fprintf(stderr, "quadkit %s: ", cmd);
  va_start(ap, fmt);
  vfprintf(stderr, fmt, ap);
  va_end(ap);
  fputc('\n', stderr);
}

int cli_status(const char *cmd, const char *what, qk_status_t st) {
  if (st == QK_OK) return CLI_OK;
  cli_error(cmd, "%s: %s", what, qk_strerror(st));
  switch (st) {
  case QK_ERR_NOMEM:
  case QK_ERR_CORRUPT:
  case QK_ERR_IO:
  case QK_ERR_UNSUPPORTED:
    return CLI_INTERNAL;
  default:
    return CLI_BAD_INPUT;
  }
}

int cli_build_tree(const char *cmd, const char *path, const qk_point_t *pts, size_t n,
                   const qk_tree_options_t *opt, qk_tree_t **out) {
  qk_status_t st = qk_tree_build(pts, n, opt, out);
  if (st == QK_ERR_LIMIT && n > 0) {
    /* The likely cause: an extent no double can hold. Name the values. */
    double x0 = pts[0].x, x1 = pts[0].x, y0 = pts[0].y, y1 = pts[0].y;
    for (size_t i = 1; i < n; i++) {
      x0 = pts[i].x < x0 ? pts[i].x : x0;
      x1 = pts[i].x > x1 ? pts[i].x : x1;
      y0 = pts[i].y < y0 ? pts[i].y : y0;
      y1 = pts[i].y > y1 ? pts[i].y : y1;
    }
    if (!isfinite(x1 - x0) || !isfinite(y1 - y0)) {
      cli_error(cmd,
                "%s: the points span x from %.17g to %.17g and y from %.17g to %.17g, "
                "an extent too large for a double",
                path, x0, x1, y0, y1);
      return CLI_BAD_INPUT;
    }
  }
  return cli_status(cmd, path, st);
}
