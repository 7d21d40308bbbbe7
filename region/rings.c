/* What the region readers (GeoJSON, OGR) gather: rings, features, properties. */
#include <string.h>

#include "region/region_internal.h"

qk_status_t qk__rings_reserve(const qk_allocator_t *a, qk__rings_t *r, size_t n) {
  qk_status_t st;
  if ((st = qk__grow(a, (void **)&r->xy, &r->cap_xy, 2 * (r->nv + n), sizeof(double))) ||
      (st = qk__grow(a, (void **)&r->rs, &r->cap_rs, r->nr + 2, sizeof(size_t))))
    return st;
  return QK_OK;
}

void qk__rings_close(qk__rings_t *r, size_t n, size_t k) {
  if (r->nr == 0) r->rs[0] = 0;
  r->nv += n;
  r->rs[++r->nr] = r->nv;
  if (k > 0) r->holes++;
}

qk_status_t qk__rings_end_feature(const qk_allocator_t *a, qk__rings_t *r) {
  qk_status_t st = qk__grow(a, (void **)&r->fs, &r->cap_fs, r->nf + 2, sizeof(size_t));
  if (st) return st;
  if (r->nf == 0) r->fs[0] = 0;
  r->fs[++r->nf] = r->nr;
  return QK_OK;
}

qk_status_t qk__rings_build(qk__rings_t *r, const qk_region_options_t *o, qk_region_t **out,
                            qk_error_t *err) {
  size_t zero = 0;
  qk_region_arrays_t arr = {r->xy, r->nr ? r->rs : &zero, r->nr, r->fs, r->nf};
  return qk__region_build(&arr, o, &r->props, r->skipped, r->holes, out, err);
}

void qk__rings_free(const qk_allocator_t *a, qk__rings_t *r) {
  qk__free(a, r->xy, r->cap_xy * sizeof(double));
  qk__free(a, r->rs, r->cap_rs * sizeof(size_t));
  qk__free(a, r->fs, r->cap_fs * sizeof(size_t));
  qk__props_free(a, &r->props);
}

qk_status_t qk__read_begin(const char *path, qk_region_t **out, qk_error_t *err) {
  if (err) {
    memset(err, 0, sizeof *err);
    err->item = SIZE_MAX;
  }
  if (!path || !out) return qk__region_fail(err, QK_ERR_INVALID, SIZE_MAX, "no path");
  *out = NULL;
  return QK_OK;
}
