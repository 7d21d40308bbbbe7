/*
 * Helpers every part of the mesh module uses: growing an array, filling an error record.
 */
#include "mesh/mesh_internal.h"

#include <stdio.h>

qk_status_t qk__mesh_grow(const qk_allocator_t *a, void **p, size_t *cap, size_t elem,
                          size_t need) {
  if (need <= *cap) return QK_OK;
  size_t nc = *cap ? *cap : 16;
  while (nc < need) {
    if (nc > SIZE_MAX / 2 / elem) return QK_ERR_NOMEM;
    nc *= 2;
  }
  void *np = qk__realloc(a, *p, *cap * elem, nc * elem);
  if (!np) return QK_ERR_NOMEM;
  *p = np;
  *cap = nc;
  return QK_OK;
}

qk_status_t qk__mesh_fail(qk_mesh_error_t *err, qk_status_t st, unsigned long line, const char *fmt,
                          ...) {
  if (err) {
    err->line = line;
    va_list ap;
    va_start(ap, fmt);
    vsnprintf(err->message, sizeof err->message, fmt, ap);
    va_end(ap);
  }
  return st;
}
