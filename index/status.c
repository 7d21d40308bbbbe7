/* Status messages and the one allocation entry point of the library. */
#include <stdlib.h>

#include "index/index_access.h"

const char *qk_strerror(qk_status_t status) {
  switch (status) {
#define QK__STATUS_CASE(name, value, msg)                                                          \
  case name:                                                                                       \
    return msg;
    QK_STATUS_MAP(QK__STATUS_CASE)
#undef QK__STATUS_CASE
  }
  return "unknown status code";
}

void *qk__realloc(const qk_allocator_t *a, void *ptr, size_t osize, size_t nsize) {
  if (a && a->fn) return a->fn(a->ud, ptr, osize, nsize);
  if (nsize == 0) {
    free(ptr);
    return NULL;
  }
  return realloc(ptr, nsize);
}

void qk__free(const qk_allocator_t *a, void *ptr, size_t size) {
  if (ptr) qk__realloc(a, ptr, size, 0);
}

qk_status_t qk__grow(const qk_allocator_t *a, void **p, size_t *cap, size_t need, size_t elem) {
  if (need <= *cap) return QK_OK;
  size_t nc = *cap ? *cap : 16;
  while (nc < need) {
    if (nc > SIZE_MAX / 2 / elem) return QK_ERR_LIMIT;
    nc *= 2;
  }
  void *q = qk__realloc(a, *p, *cap * elem, nc * elem);
  if (!q) return QK_ERR_NOMEM;
  *p = q;
  *cap = nc;
  return QK_OK;
}
