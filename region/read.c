/*
 * qk_region_read: the reader chosen by the path. By name, GeoJSON for ".geojson" and
 * ".json" (in any case), OGR for everything else; but a pipe or socket (`quadkit join <(curl ...)
 * pts.csv`, /dev/stdin from a pipe, a FIFO) goes to the GeoJSON reader whatever its name:
 * GDAL seeks in its input and cannot read a pipe (it said "Failed to read GeoJSON data"
 * for a GeoJSON text), while the GeoJSON reader reads its input to the end, and GeoJSON is
 * the one format of the usual ones that streams. Character devices (/dev/zero, a
 * terminal) still go to GDAL, which refuses them at once.
 */
#define _POSIX_C_SOURCE 200809L
#include <string.h>
#include <sys/stat.h>

#include "region/region_internal.h"

/* Whether path ends in suffix (lower case), in any case: "x.GeoJSON" went to GDAL's
 * GeoJSON driver, past this reader's checks (a duplicate "coordinates" kept silently). */
static int ends_in(const char *path, size_t n, const char *suffix) {
  size_t k = strlen(suffix);
  if (n < k) return 0;
  for (size_t i = 0; i < k; i++) {
    char c = path[n - k + i];
    if ((c >= 'A' && c <= 'Z' ? c - 'A' + 'a' : c) != suffix[i]) return 0;
  }
  return 1;
}

qk_status_t qk_region_read(const char *path, const qk_region_options_t *options, qk_region_t **out,
                           qk_error_t *err) {
  size_t n = path ? strlen(path) : 0;
  if (ends_in(path, n, ".geojson") || ends_in(path, n, ".json"))
    return qk_region_read_geojson(path, options, out, err);
  struct stat sb;
  if (path && stat(path, &sb) == 0 && (S_ISFIFO(sb.st_mode) || S_ISSOCK(sb.st_mode)))
    return qk_region_read_geojson(path, options, out, err);
  return qk_region_read_ogr(path, options, out, err);
}
