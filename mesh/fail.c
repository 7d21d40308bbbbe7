/*
 * Helpers every part of the mesh module uses: filling an error record (arrays grow with
 * qk__grow from index/index_access.h).
 */
#include "mesh/mesh_internal.h"
#include "index/textloc.h"

#include <stdio.h>

qk_status_t qk__mesh_fail(qk_mesh_error_t *err, qk_status_t st, unsigned long line, const char *fmt,
                          ...) {
  if (err) {
    err->line = line;
    err->column = 0;
    err->item = SIZE_MAX;
    va_list ap;
    va_start(ap, fmt);
    qk__vsnprintf(err->message, sizeof err->message, fmt, ap);
    va_end(ap);
  }
  return st;
}
