/* Points from CSV: two required columns, x then y, through the values reader. */
#include <errno.h>
#include <string.h>

#include "io/io_internal.h"

/* The values reader's rows of two doubles are the points' layout. */
_Static_assert(sizeof(qk_point_t) == 2 * sizeof(double), "qk_point_t is two doubles");

qk_status_t qk_points_read_csv_file(FILE *f, const qk_csv_options_t *opt,
                                    const qk_allocator_t *alloc, qk_point_t **pts, size_t *n,
                                    qk_error_t *err) {
  if (pts) *pts = NULL;
  if (n) *n = 0;
  if (!pts || !n) {
    if (err) {
      memset(err, 0, sizeof *err);
      err->item = SIZE_MAX;
      snprintf(err->message, sizeof err->message, "invalid arguments");
    }
    return QK_ERR_INVALID;
  }
  double *v = NULL;
  size_t rows = 0;
  qk_status_t st = qk_csv_read_values(f, opt, 2, 2, alloc, &v, &rows, err);
  if (st != QK_OK) return st;
  *pts = (qk_point_t *)(void *)v;
  *n = rows;
  return QK_OK;
}

qk_status_t qk_points_read_csv(const char *path, const qk_csv_options_t *opt,
                               const qk_allocator_t *alloc, qk_point_t **pts, size_t *n,
                               qk_error_t *err) {
  if (pts) *pts = NULL;
  if (n) *n = 0;
  if (err) {
    memset(err, 0, sizeof *err);
    err->item = SIZE_MAX;
  }
  FILE *f = path ? fopen(path, "rb") : NULL;
  if (!f) {
    if (err)
      snprintf(err->message, sizeof err->message, "cannot open: %s",
               path ? strerror(errno) : "no file name");
    return path ? QK_ERR_IO : QK_ERR_INVALID;
  }
  qk_status_t st = qk_points_read_csv_file(f, opt, alloc, pts, n, err);
  fclose(f);
  return st;
}
