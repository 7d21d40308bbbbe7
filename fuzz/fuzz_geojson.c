/*
 * Fuzz target: the GeoJSON reader and point location behind it.
 *
 * The first input byte chooses planar or lon/lat mode, the split threshold and whether,
 * and where, an allocation fails; the rest is GeoJSON text. A rejected input must come
 * with a message and no layer; a failed allocation must give QK_ERR_NOMEM and leak
 * nothing. An accepted layer is queried at every vertex, at the midpoints of edges and at
 * lattice points: locate, locate_all and the batch call must agree with each other, and,
 * in planar mode when every coordinate is a small integer, with a brute-force crossing
 * parity on the rings as json-c parsed them here (integer arithmetic, exact). Without a
 * failing allocation, the reader's answer (a FeatureCollection is read one feature at a
 * time) must be the whole-text reading's: the same status and error, or the same stats.
 */
#include "fuzz/fuzz_common.h"
#include "region/region_internal.h"

#include <json.h>

#define GF_MAX_V 4096

typedef struct gf_rings {
  long xy[2 * GF_MAX_V];
  size_t rs[GF_MAX_V + 1], nr, nv;
  size_t fs[GF_MAX_V + 1], nf;
  int integral;
} gf_rings_t;

/* Re-read the rings (only when the layer was accepted, so the shape is valid). */
static void gf_polygon(json_object *rings, gf_rings_t *g) {
  for (size_t k = 0; k < json_object_array_length(rings); k++) {
    json_object *r = json_object_array_get_idx(rings, k);
    for (size_t i = 0; i < json_object_array_length(r); i++) {
      json_object *p = json_object_array_get_idx(r, i);
      double x = json_object_get_double(json_object_array_get_idx(p, 0));
      double y = json_object_get_double(json_object_array_get_idx(p, 1));
      if (g->nv >= GF_MAX_V || x != floor(x) || y != floor(y) || fabs(x) > 1e6 || fabs(y) > 1e6) {
        g->integral = 0;
        return;
      }
      g->xy[2 * g->nv] = (long)x;
      g->xy[2 * g->nv + 1] = (long)y;
      g->nv++;
    }
    g->rs[++g->nr] = g->nv;
  }
}

static void gf_geometry(json_object *geom, gf_rings_t *g) {
  json_object *t, *c;
  if (geom && json_object_object_get_ex(geom, "type", &t) &&
      json_object_object_get_ex(geom, "coordinates", &c)) {
    const char *ty = json_object_get_string(t);
    if (!strcmp(ty, "Polygon")) gf_polygon(c, g);
    if (!strcmp(ty, "MultiPolygon"))
      for (size_t i = 0; i < json_object_array_length(c) && g->integral; i++)
        gf_polygon(json_object_array_get_idx(c, i), g);
  }
  g->fs[++g->nf] = g->nr;
}

static int gf_read(const char *text, size_t len, gf_rings_t *g) {
  memset(g, 0, sizeof *g);
  g->integral = 1;
  json_tokener *tok = json_tokener_new();
  json_object *root = json_tokener_parse_ex(tok, text, (int)len);
  json_tokener_free(tok);
  if (!root) return 0;
  json_object *t, *f;
  json_object_object_get_ex(root, "type", &t);
  const char *ty = json_object_get_string(t);
  if (!strcmp(ty, "FeatureCollection") && json_object_object_get_ex(root, "features", &f)) {
    if (json_object_array_length(f) >= GF_MAX_V) g->integral = 0;
    for (size_t i = 0; i < json_object_array_length(f) && g->integral; i++) {
      json_object *geom = NULL;
      json_object_object_get_ex(json_object_array_get_idx(f, i), "geometry", &geom);
      gf_geometry(geom, g);
    }
  } else if (!strcmp(ty, "Feature")) {
    json_object *geom = NULL;
    json_object_object_get_ex(root, "geometry", &geom);
    gf_geometry(geom, g);
  } else {
    gf_geometry(root, g);
  }
  json_object_put(root);
  return g->integral;
}

static int gf_orient(long ax, long ay, long bx, long by, long cx, long cy) {
  long long d = (long long)(bx - ax) * (cy - ay) - (long long)(by - ay) * (cx - ax);
  return (d > 0) - (d < 0);
}

/* Semi-open membership of the point moved by (e, e^2): half-open crossing parity. */
static uint32_t gf_oracle(const gf_rings_t *g, long px, long py) {
  for (size_t f = 0; f < g->nf; f++) {
    int par = 0;
    for (size_t r = g->fs[f]; r < g->fs[f + 1]; r++)
      for (size_t v = g->rs[r]; v + 1 < g->rs[r + 1]; v++) {
        long ax = g->xy[2 * v], ay = g->xy[2 * v + 1], bx = g->xy[2 * v + 2], by = g->xy[2 * v + 3];
        if ((ay > py) != (by > py)) {
          int o = gf_orient(ax, ay, bx, by, px, py);
          if ((by > ay) ? o > 0 : o < 0) par ^= 1;
        }
      }
    if (par) return (uint32_t)f;
  }
  return QK_NONE;
}

static void gf_check(const qk_region_t *r, const gf_rings_t *g, int oracle, double x, double y) {
  qk_point_t p = {x, y};
  for (int b = 0; b < 3; b++) {
    uint32_t f, fb, all[8];
    size_t n;
    QKF_ASSERT(qk_region_locate(r, p, (qk_boundary_t)b, &f) == QK_OK, "locate failed");
    QKF_ASSERT(qk_region_locate_all(r, p, (qk_boundary_t)b, all, 8, &n) == QK_OK, "locate_all");
    QKF_ASSERT((n == 0 && f == QK_NONE) || (n > 0 && all[0] == f), "locate %d vs locate_all %d",
               (int)f, n ? (int)all[0] : -1);
    QKF_ASSERT(qk_region_locate_batch(r, &p, 1, (qk_boundary_t)b, 1, &fb) == QK_OK, "batch");
    QKF_ASSERT(fb == f, "batch %d vs single %d", (int)fb, (int)f);
    if (b == 0 && oracle) {
      uint32_t want = gf_oracle(g, (long)x, (long)y);
      QKF_ASSERT(f == want, "point (%g, %g): locate %d, oracle %d", x, y, (int)f, (int)want);
    }
  }
}

int qkf_geojson(const uint8_t *data, size_t size) {
  qkf_bytes_t b = {data, size, 0};
  uint8_t mode = qkf_u8(&b);
  const char *text = (const char *)data + b.at;
  size_t len = size - b.at;
  qkt_alloc_t fa;
  qk_allocator_t al = qkt_alloc_make(&fa);
  qkt_alloc_arm(&fa, (mode & 0x80) ? (size_t)(mode & 0x1f) + 1 : 0);
  qk_region_options_t o;
  qk_region_options_init(&o);
  o.planar = mode & 1;
  o.leaf_edges = 1 + ((mode >> 1) & 7);
  o.allocator = &al;
  qk_region_t *r = (qk_region_t *)&o;
  qk_error_t err;
  qk_status_t st = qk_region_read_geojson_text(text, len, &o, &r, &err);
  qk_region_t *w = NULL;
  qk_error_t werr;
  qk_status_t wst = QK_OK;
  const char *wt = len >= 3 && !memcmp(text, "\xEF\xBB\xBF", 3) ? text + 3 : text;
  size_t wn = len - (size_t)(wt - text);
  int compare = !(mode & 0x80) && !memchr(wt, '\0', wn);
  if (compare) {
    qk_region_options_t wo = o;
    wo.allocator = NULL;
    wst = qk__geojson_read_whole(wt, wn, &wo, &w, &werr);
    QKF_ASSERT(wst == st, "status %s, whole-text reading %s (%s)", qk_strerror(st),
               qk_strerror(wst), wst ? werr.message : "");
    if (st)
      QKF_ASSERT(!strcmp(err.message, werr.message) && err.line == werr.line &&
                     err.column == werr.column && err.item == werr.item,
                 "error \"%s\" at %lu:%lu, whole-text reading \"%s\" at %lu:%lu", err.message,
                 err.line, err.column, werr.message, werr.line, werr.column);
  }
  if (st != QK_OK) {
    QKF_ASSERT(r == NULL, "failed read left a layer");
    QKF_ASSERT(err.message[0] != '\0', "status %s without a message", qk_strerror(st));
    if (st == QK_ERR_PARSE && !strncmp(err.message, "line ", 5))
      QKF_ASSERT(err.line > 0, "malformed JSON without a line: %s", err.message);
    QKF_ASSERT(fa.live_blocks == 0, "%zu blocks leaked after %s", fa.live_blocks, qk_strerror(st));
    return 0;
  }
  static gf_rings_t g;
  int oracle = o.planar && gf_read(text, len, &g);
  qk_region_stats_t s;
  qk_region_stats(r, &s);
  if (compare) {
    qk_region_stats_t ws;
    qk_region_stats(w, &ws);
    QKF_ASSERT(s.features == ws.features && s.rings == ws.rings && s.vertices == ws.vertices &&
                   s.skipped == ws.skipped,
               "layer %zu features %zu rings %zu vertices, whole-text reading %zu %zu %zu",
               s.features, s.rings, s.vertices, ws.features, ws.rings, ws.vertices);
    qk_region_free(w);
  }
  if (oracle) {
    for (size_t v = 0; v < g.nv; v++)
      gf_check(r, &g, 1, (double)g.xy[2 * v], (double)g.xy[2 * v + 1]);
    for (long y = -2; y <= 12; y += 1)
      for (long x = -2; x <= 12; x += 1) gf_check(r, &g, 1, (double)x, (double)y);
  } else {
    for (int i = 0; i < 64; i++) gf_check(r, &g, 0, -180 + 6.0 * i, -90 + 2.9 * i);
  }
  qk_region_free(r);
  QKF_ASSERT(fa.live_blocks == 0, "%zu blocks leaked", fa.live_blocks);
  return 0;
}

#ifndef QKF_REPLAY
int LLVMFuzzerTestOneInput(const uint8_t *data, size_t size) { return qkf_geojson(data, size); }
#endif
