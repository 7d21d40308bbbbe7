/* GeoJSON polygons as a mesh input; see mesh_geojson.h. */
#include "mesh_geojson.h"

#include <errno.h>
#include <limits.h>
#include <math.h>
#include <stdarg.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/stat.h>

#include "cli.h"
#include "quadkit/quadkit.h"

#ifdef QK_HAVE_JSONC
#include <json-c/json.h>
#endif

#define MG_PI 3.14159265358979323846
#define MG_EARTH_M 6371008.8 /* mean Earth radius (IUGG), metres */

static int mg_fail(char *msg, size_t n, int rc, const char *fmt, ...)
#if defined(__GNUC__)
    __attribute__((format(printf, 4, 5)))
#endif
    ;
static int mg_fail(char *msg, size_t n, int rc, const char *fmt, ...) {
  va_list ap;
  va_start(ap, fmt);
  vsnprintf(msg, n, fmt, ap);
  va_end(ap);
  return rc;
}

/* The text of an input read from a stream (a FIFO named .geojson), kept for mg_locate:
 * a stream cannot be read again, and opening a FIFO again waited for a writer forever
 * (`quadkit mesh f.geojson` hung on its way to a "segments cross" message). */
static struct {
  char *path, *text;
  size_t len;
} mg_kept;

void mg_free(mg_input_t *in) {
  qk_region_free(in->rings);
  free(in->xy), free(in->seg), free(in->holes), free(in->ring_v), free(in->ring_start);
  free(in->ring_sign), free(in->seg_feature), free(in->seg_ring), free(in->seg_point);
  free(in->ring_src), free(in->in_feature), free(in->in_poly), free(in->in_ring), free(in->in_path),
      free(in->paths);
  memset(in, 0, sizeof *in);
  free(mg_kept.path), free(mg_kept.text);
  memset(&mg_kept, 0, sizeof mg_kept);
}

static int slurp(const char *path, char **text, size_t *len, int *stream, char *msg, size_t n);

void mg_locate(const char *path, const char *pointer, unsigned long *line, unsigned long *col) {
  *line = *col = 0;
#ifdef QK_HAVE_JSONC
  /* Read again: only on the way to an error, so a read costs nothing when all is well. */
  if (mg_kept.text && !strcmp(mg_kept.path, path)) {
    if (qk_region_find_json_pointer(mg_kept.text, mg_kept.len, pointer, line, col) != QK_OK)
      *line = *col = 0;
    return;
  }
  struct stat sb;
  if (stat(path, &sb) != 0 || !S_ISREG(sb.st_mode)) return; /* (not to be read again) */
  char *text, msg[8];
  size_t len;
  int stream;
  if (slurp(path, &text, &len, &stream, msg, sizeof msg)) return;
  if (qk_region_find_json_pointer(text, len, pointer, line, col) != QK_OK) *line = *col = 0;
  free(text);
#else
  (void)path, (void)pointer;
#endif
}

void mg_describe_ring(const mg_input_t *in, size_t q, size_t pos, char *buf, size_t n, char *ptr,
                      size_t np) {
  if (!in->in_path || q >= in->nin) {
    snprintf(buf, n, "ring %zu", q), snprintf(ptr, np, "%s", "");
    return;
  }
  snprintf(buf, n, "feature %u, polygon %u, ring %u", in->in_feature[q], in->in_poly[q],
           in->in_ring[q]);
  if (pos != SIZE_MAX) {
    size_t k = strlen(buf);
    snprintf(buf + k, n - k, ", position %zu", pos);
    snprintf(ptr, np, "%s/%zu", in->paths + in->in_path[q], pos);
  } else {
    snprintf(ptr, np, "%s", in->paths + in->in_path[q]);
  }
}

void mg_place(const char *path, const char *pointer, char *buf, size_t n) {
  unsigned long line, col;
  mg_locate(path, pointer, &line, &col);
  if (line)
    snprintf(buf, n, "%s:%lu:%lu", path, line, col);
  else
    snprintf(buf, n, "%s", path);
}

const char *mg_pole_note(const mg_input_t *in, char *buf, size_t n) {
  char what[128], ptr[512];
  if (!in->in_path || in->pole_ring >= in->nin) return "";
  mg_describe_ring(in, in->pole_ring, SIZE_MAX, what, sizeof what, ptr, sizeof ptr);
  snprintf(buf, n,
           " (%s goes round the %s pole: its longitudes wind once round the globe, across "
           "the antimeridian, which no planar map of lon/lat closes; cut it along the "
           "antimeridian into rings that close in longitude, or project it with a polar "
           "projection (PROJ: +proj=stere +lat_0=%s90), or mesh other features with "
           "--feature N or --field NAME=VALUE)",
           what, in->pole_south ? "south" : "north", in->pole_south ? "-" : "");
  return buf;
}

void mg_describe_segment(const mg_input_t *in, const char *path, size_t s, char *buf, size_t n,
                         unsigned long *line, unsigned long *col) {
  *line = *col = 0;
  if (s >= in->ns || !in->seg_feature) {
    snprintf(buf, n, "segment %zu", s);
    return;
  }
  char ptr[512];
  mg_describe_ring(in, in->seg_ring[s], in->seg_point[s], buf, n, ptr, sizeof ptr);
  if (ptr[0]) mg_locate(path, ptr, line, col);
}

int mg_auto_grid(const double *xy, size_t n, int *mag, int *ext) {
  double big = 0, lo[2] = {0, 0}, hi[2] = {0, 0};
  for (size_t i = 0; i < n; i++)
    for (int c = 0; c < 2; c++) {
      double v = xy[2 * i + c];
      big = fmax(big, fabs(v));
      lo[c] = i ? fmin(lo[c], v) : v, hi[c] = i ? fmax(hi[c], v) : v;
    }
  /* The extent's subtraction rounds, but monotonically: a side of at least 2^W (a
   * double) never comes out below it, so W is never too small. */
  double side = fmax(hi[0] - lo[0], hi[1] - lo[1]);
  int m = 0, w = 0;
  if (big > 0) (void)frexp(big, &m); /* 2^(m-1) <= big < 2^m */
  if (side > 0)
    (void)frexp(side, &w);
  else
    w = m; /* one point: nothing to split; the grid from the magnitude alone */
  *mag = m, *ext = w;
  if (big == 0) return 0;
  int s = m + w - 52, k = s >= 0 ? (s + 1) / 2 : -(-s / 2); /* ceil(s / 2) */
  return k < -996 ? -996 : k > 1000 ? 1000 : k;
}

int mg_rings_touch(const mg_input_t *in) { return in->ring_start[in->nr] != in->nv; }

int mg_outside_rings(const mg_input_t *in, const double *pts, size_t n, unsigned char *out) {
  memset(out, 0, n);
  if (!in->rings) return 0; /* (rings that neither touch nor have holes: no such face) */
  for (size_t i = 0; i < n; i++) {
    uint32_t f = 0;
    out[i] = qk_region_locate(in->rings, (qk_point_t){pts[2 * i], pts[2 * i + 1]},
                              QK_BOUNDARY_CLOSED, &f) == QK_OK &&
             f == QK_NONE;
  }
  return 0;
}

#ifndef QK_HAVE_JSONC
int mg_read(const char *path, const mg_options_t *o, mg_input_t *out, char *msg, size_t n) {
  (void)o;
  memset(out, 0, sizeof *out);
  return mg_fail(msg, n, 1, "%s: GeoJSON input needs json-c (install libjson-c-dev)", path);
}
#else

/* A growing array of rings in input coordinates: points, ring starts, the feature and
 * ring number of each ring, and whether it is a hole. */
typedef struct rings {
  double *xy;
  size_t np, cap_p;
  size_t *start;               /* nr + 1 */
  uint32_t *feat, *poly, *num; /* the feature, its polygon (as the region reader numbers
                                  them) and the ring in the polygon */
  size_t *path;                /* where the ring is in the text: a JSON Pointer in paths */
  char *paths;
  size_t paths_len, cap_paths;
  int *hole;
  size_t nr, cap_r;
  int kind; /* the root: 0 a geometry, 1 a Feature, 2 a FeatureCollection */
} rings_t;

static int grow(void **p, size_t *cap, size_t need, size_t elem) {
  if (need <= *cap) return 0;
  size_t nc = *cap ? *cap : 16;
  while (nc < need) nc *= 2;
  void *q = realloc(*p, nc * elem);
  if (!q) return 1;
  *p = q;
  *cap = nc;
  return 0;
}

/* Append the rings of one GeoJSON polygon (an array of rings at JSON Pointer at) of
 * feature f, its polygon number pno. */
static int add_polygon(rings_t *r, json_object *poly, uint32_t f, uint32_t pno, const char *at) {
  size_t nring = json_object_array_length(poly);
  for (size_t k = 0; k < nring; k++) {
    json_object *ring = json_object_array_get_idx(poly, k);
    size_t np = json_object_array_length(ring);
    if (np > 1) np--; /* the closing point (the region reader checked it) */
    if (grow((void **)&r->xy, &r->cap_p, 2 * (r->np + np), sizeof *r->xy)) return 3;
    if (r->nr + 2 > r->cap_r) {
      size_t nc = r->cap_r ? 2 * r->cap_r : 16;
      void *a = realloc(r->start, nc * sizeof *r->start), *b, *c, *d, *e, *g;
      if (!a) return 3;
      r->start = a;
      if (!(b = realloc(r->feat, nc * sizeof *r->feat))) return 3;
      r->feat = b;
      if (!(c = realloc(r->num, nc * sizeof *r->num))) return 3;
      r->num = c;
      if (!(d = realloc(r->hole, nc * sizeof *r->hole))) return 3;
      r->hole = d;
      if (!(e = realloc(r->poly, nc * sizeof *r->poly))) return 3;
      r->poly = e;
      if (!(g = realloc(r->path, nc * sizeof *r->path))) return 3;
      r->path = g;
      if (!r->cap_r) r->start[0] = 0;
      r->cap_r = nc;
    }
    size_t pl = strlen(at) + 24;
    if (grow((void **)&r->paths, &r->cap_paths, r->paths_len + pl, 1)) return 3;
    r->path[r->nr] = r->paths_len;
    r->paths_len += (size_t)snprintf(r->paths + r->paths_len, pl, "%s/%zu", at, k) + 1;
    for (size_t i = 0; i < np; i++) {
      json_object *pt = json_object_array_get_idx(ring, i);
      r->xy[2 * r->np] = json_object_get_double(json_object_array_get_idx(pt, 0));
      r->xy[2 * r->np + 1] = json_object_get_double(json_object_array_get_idx(pt, 1));
      r->np++;
    }
    r->feat[r->nr] = f, r->poly[r->nr] = pno, r->num[r->nr] = (uint32_t)k, r->hole[r->nr] = k > 0;
    r->start[++r->nr] = r->np;
  }
  return 0;
}

/* The rings of one geometry (Polygon, MultiPolygon, or the polygons of a
 * GeometryCollection, as the region reader takes them) of feature f; anything else adds
 * nothing. */
static int add_geometry(rings_t *r, json_object *geom, uint32_t f, uint32_t *pno, const char *at) {
  json_object *t = NULL, *c = NULL;
  if (!geom || !json_object_object_get_ex(geom, "type", &t)) return 0;
  const char *ty = json_object_get_string(t);
  size_t al = strlen(at) + 40;
  char *sub = malloc(al); /* at, one or two steps deeper */
  if (!sub) return 3;
  int rc = 0;
  if (!strcmp(ty, "GeometryCollection")) {
    if (json_object_object_get_ex(geom, "geometries", &c))
      for (size_t k = 0, m = json_object_array_length(c); k < m && !rc; k++) {
        snprintf(sub, al, "%s/geometries/%zu", at, k);
        rc = add_geometry(r, json_object_array_get_idx(c, k), f, pno, sub);
      }
    free(sub);
    return rc;
  }
  int multi = !strcmp(ty, "MultiPolygon");
  if ((!multi && strcmp(ty, "Polygon")) || !json_object_object_get_ex(geom, "coordinates", &c)) {
    free(sub);
    return 0;
  }
  if (!multi) {
    snprintf(sub, al, "%s/coordinates", at);
    rc = add_polygon(r, c, f, (*pno)++, sub);
  }
  for (size_t k = 0, m = multi ? json_object_array_length(c) : 0; k < m && !rc; k++) {
    snprintf(sub, al, "%s/coordinates/%zu", at, k);
    rc = add_polygon(r, json_object_array_get_idx(c, k), f, (*pno)++, sub);
  }
  free(sub);
  return rc;
}

/* The rings of feature f (obj, a Feature or, at the root, a bare geometry) when wanted. */
static int gather_one(json_object *obj, int collection, size_t f, const unsigned char *want,
                      size_t nf, rings_t *r) {
  json_object *t = NULL, *geom = obj;
  char at[64] = "";
  if (collection) snprintf(at, sizeof at, "/features/%zu", f);
  if (json_object_object_get_ex(obj, "type", &t) && !strcmp(json_object_get_string(t), "Feature")) {
    if (!json_object_object_get_ex(obj, "geometry", &geom)) geom = NULL;
    strcat(at, "/geometry");
    if (!collection) r->kind = 1;
  }
  uint32_t pno = 0;
  if (f < nf && want[f] && add_geometry(r, geom, (uint32_t)f, &pno, at)) return 3;
  return 0;
}

/* Gather the rings of the features wanted (want[f] nonzero), numbering features as the
 * region reader does: feature f is the file's feature f, whatever its geometry (a bare
 * geometry is feature 0). */
static int gather(json_object *root, const unsigned char *want, size_t nf, rings_t *r,
                  size_t *seen) {
  json_object *t = NULL, *feats = NULL;
  size_t n = 1;
  int collection = json_object_object_get_ex(root, "type", &t) &&
                   !strcmp(json_object_get_string(t), "FeatureCollection") &&
                   json_object_object_get_ex(root, "features", &feats);
  if (collection) n = json_object_array_length(feats);
  r->kind = collection ? 2 : 0;
  for (size_t f = 0; f < n; f++)
    if (gather_one(collection ? json_object_array_get_idx(feats, f) : root, collection, f, want, nf,
                   r))
      return 3;
  *seen = n;
  return 0;
}

/* ---- a FeatureCollection one feature at a time: json-c's tree of a whole collection
 * takes several times its text (a 41 MB file: 399 MB for mesh against 258 MB for
 * regions, which reads a feature at a time), so when the root is written as
 * {"type": "FeatureCollection", ..., "features": [...]} each element is parsed on its
 * own. The text was accepted by the region reader: it is strict JSON without duplicate
 * names, so a scan of quotes and brackets finds the elements exactly. ---- */

static size_t j_blanks(const char *t, size_t n, size_t i) {
  while (i < n && (t[i] == ' ' || t[i] == '\t' || t[i] == '\r' || t[i] == '\n')) i++;
  return i;
}

/* t[i] is a quote: the index after its closing quote. */
static size_t j_string(const char *t, size_t n, size_t i) {
  for (i++; i < n; i++) {
    if (t[i] == '\\')
      i++;
    else if (t[i] == '"')
      return i + 1;
  }
  return n;
}

/* The index after the value at t[i]. */
static size_t j_value(const char *t, size_t n, size_t i) {
  if (i < n && t[i] == '"') return j_string(t, n, i);
  if (i < n && t[i] != '{' && t[i] != '[') {
    while (i < n && !strchr(",]} \t\r\n", t[i])) i++;
    return i;
  }
  size_t depth = 0;
  while (i < n) {
    char c = t[i];
    if (c == '"') {
      i = j_string(t, n, i);
      continue;
    }
    if (c == '{' || c == '[') depth++;
    if ((c == '}' || c == ']') && --depth == 0) return i + 1;
    i++;
  }
  return n;
}

/* The spans [sp[2k], sp[2k + 1]) of the root's "features" elements when the root's
 * "type" is written "FeatureCollection": 0, or 1 (another layout: read it whole), or 3
 * (out of memory). */
static int feature_spans(const char *t, size_t n, size_t **sp, size_t *ns) {
  size_t cap = 0, i = j_blanks(t, n, 0);
  int is_fc = 0, found = 0;
  *sp = NULL, *ns = 0;
  if (n >= 3 && !memcmp(t, "\xEF\xBB\xBF", 3)) i = j_blanks(t, n, 3);
  if (i >= n || t[i] != '{') return 1;
  for (i = j_blanks(t, n, i + 1); i < n && t[i] == '"';) {
    size_t e = j_string(t, n, i);
    int type = e - i == 6 && !memcmp(t + i, "\"type\"", 6);
    int feats = e - i == 10 && !memcmp(t + i, "\"features\"", 10);
    i = j_blanks(t, n, e);
    if (i >= n || t[i] != ':') break;
    i = j_blanks(t, n, i + 1);
    size_t v = i;
    if (feats && i < n && t[i] == '[') {
      found = 1;
      for (i = j_blanks(t, n, i + 1); i < n && t[i] != ']';) {
        size_t b = i;
        i = j_value(t, n, i);
        if (*ns + 2 > cap) {
          size_t nc = cap ? 2 * cap : 64;
          size_t *q = realloc(*sp, nc * sizeof *q);
          if (!q) return 3;
          *sp = q, cap = nc;
        }
        (*sp)[(*ns)++] = b, (*sp)[(*ns)++] = i;
        i = j_blanks(t, n, i);
        if (i < n && t[i] == ',') i = j_blanks(t, n, i + 1);
      }
      i++;
    } else {
      i = j_value(t, n, i);
      if (type && i - v == 19 && !memcmp(t + v, "\"FeatureCollection\"", 19)) is_fc = 1;
    }
    i = j_blanks(t, n, i);
    if (i < n && t[i] == ',') i = j_blanks(t, n, i + 1);
  }
  return is_fc && found ? 0 : 1;
}

/* gather() over the spans, each element parsed alone: 0, or 3 (out of memory, or an
 * element json-c does not read alone, which the region reader's check rules out). */
static int gather_spans(const char *t, const size_t *sp, size_t ns, const unsigned char *want,
                        size_t nf, rings_t *r, size_t *seen) {
  r->kind = 2;
  for (size_t k = 0; k < ns; k += 2) {
    size_t f = k / 2, len = sp[k + 1] - sp[k];
    json_object *obj = NULL;
    if (f < nf && want[f]) { /* (a feature not wanted is not parsed) */
      json_tokener *tok = len <= INT_MAX ? json_tokener_new() : NULL;
      if (!tok) return 3;
      obj = json_tokener_parse_ex(tok, t + sp[k], (int)len);
      json_tokener_free(tok);
      if (!obj) return 3;
    }
    int rc = obj ? gather_one(obj, 1, f, want, nf, r) : 0;
    json_object_put(obj);
    if (rc) return rc;
  }
  *seen = ns / 2;
  return 0;
}

/* Vertex keys for merging coincident points: the bits of x and y, then the point. */
typedef struct vkey {
  double x, y;
  size_t i;
} vkey_t;

static int cmp_vkey(const void *pa, const void *pb) {
  const vkey_t *a = pa, *b = pb;
  if (a->x != b->x) return a->x < b->x ? -1 : 1;
  if (a->y != b->y) return a->y < b->y ? -1 : 1;
  return (a->i > b->i) - (a->i < b->i);
}

typedef struct skey {
  uint64_t key;
  size_t i;
} skey_t;

static int cmp_skey(const void *pa, const void *pb) {
  const skey_t *a = pa, *b = pb;
  if (a->key != b->key) return a->key < b->key ? -1 : 1;
  return (a->i > b->i) - (a->i < b->i);
}

/* The first ring that goes round a pole (SIZE_MAX: none), *south for the south pole: as
 * lon/lat (every coordinate in range), it has an edge that crosses the antimeridian (its
 * longitudes more than 180 degrees apart, so the short way round is across), and its
 * longitude steps, each taken the short way round, add up to +-360 degrees rather than
 * 0. A ring cut along the antimeridian (an edge from 180 to -180, on one meridian) and
 * closed along it is not one: as planar lon/lat it is closed. */
static size_t pole_ring(const rings_t *r, int *south) {
  for (size_t q = 0; q < r->nr; q++) {
    size_t s0 = r->start[q], s1 = r->start[q + 1];
    double turn = 0, lat = 0;
    int lonlat = 1, across = 0;
    for (size_t i = s0; i < s1 && lonlat; i++) {
      const double *a = &r->xy[2 * i], *b = &r->xy[2 * (i + 1 < s1 ? i + 1 : s0)];
      lonlat = fabs(a[0]) <= 180 && fabs(a[1]) <= 90;
      double d = b[0] - a[0];
      across |= fabs(d) > 180 && fabs(d) < 360;
      turn += d > 180 ? d - 360 : d < -180 ? d + 360 : d;
      lat += a[1];
    }
    if (lonlat && across && fabs(turn) > 180) {
      *south = lat < 0;
      return q;
    }
  }
  return SIZE_MAX;
}

/* The far end of ring q's nearest edge of non-zero length before (dir -1) or after (dir
 * +1) its edge i (from point i to the next; the ring is stored without its closing point). */
static const double *neighbour_end(const rings_t *r, size_t q, size_t i, int dir) {
  size_t s = r->start[q], m = r->start[q + 1] - s, j = i - s;
  for (size_t step = 1; step < m; step++) {
    j = dir < 0 ? (j + m - 1) % m : (j + 1) % m;
    const double *a = r->xy + 2 * (s + j), *b = r->xy + 2 * (s + (j + 1) % m);
    if (a[0] != b[0] || a[1] != b[1]) return dir < 0 ? a : b;
  }
  return r->xy + 2 * i;
}

/* Does edge i of ring q, from (-180, y) to (180, y) or back, run across the whole map
 * along latitude y, as the region reader takes it (docs/region.md, rule 6), rather than
 * being a zero-length step on the antimeridian (Fiji)? At the poles, and where the ring
 * read as a step would double back on the antimeridian (a band, the whole world). */
static int across_map(const rings_t *r, size_t q, size_t i, double y) {
  if (y == 90 || y == -90) return 1;
  const double *p = neighbour_end(r, q, i, -1), *n = neighbour_end(r, q, i, +1);
  return fabs(p[0]) == 180 && fabs(n[0]) == 180 &&
         ((p[1] > y && n[1] > y) || (p[1] < y && n[1] < y));
}

/* A point before and after rounding, for --round auto's check that no two distinct points
 * become one. */
typedef struct moved {
  double x, y, ox, oy;
  size_t i;
} moved_t;

static int moved_cmp(const void *pa, const void *pb) {
  const moved_t *a = pa, *b = pb;
  const double ka[4] = {a->x, a->y, a->ox, a->oy}, kb[4] = {b->x, b->y, b->ox, b->oy};
  for (int k = 0; k < 4; k++)
    if (ka[k] != kb[k]) return ka[k] < kb[k] ? -1 : 1;
  return a->i < b->i ? -1 : a->i > b->i;
}

/* Project and round in place; counts rounded coordinates. With --round auto, *p1 < *p2
 * receive two points that were distinct and coincide after rounding (SIZE_MAX: none):
 * merging them, as points that coincide in the input are merged, would change the
 * input's shape on a grid the user did not choose. Returns 0, or 3 out of memory. */
static int transform(rings_t *r, const mg_options_t *o, mg_input_t *out, size_t *p1, size_t *p2) {
  *p1 = *p2 = SIZE_MAX;
  if (o->project && r->np) {
    double lo = r->xy[0], hi = r->xy[0], lat = 0;
    for (size_t i = 0; i < r->np; i++) {
      lo = fmin(lo, r->xy[2 * i]), hi = fmax(hi, r->xy[2 * i]);
      lat += r->xy[2 * i + 1];
    }
    out->lat0 = lat / (double)r->np;
    /* Across the antimeridian (Fiji, Russia, Alaska: parts at both ends of the map), the
     * negative longitudes move up by 360 so that the parts meet at 180. Not when an edge
     * runs across the prime meridian (a ring cut at the antimeridian that goes round the
     * globe, or the whole world): moving one of its ends would tear it across the map.
     * Nor when an edge from -180 to 180 runs across the map (the whole world
     * [-180, -90] .. [180, 90], a band): moved, all its points went to longitude 180 and
     * the world was "no ring with 3 distinct points". */
    int tear = 0;
    for (size_t q = 0; q < r->nr && !tear; q++)
      for (size_t i = r->start[q]; i < r->start[q + 1] && !tear; i++) {
        size_t j = i + 1 < r->start[q + 1] ? i + 1 : r->start[q];
        double a = r->xy[2 * i], b = r->xy[2 * j], y = r->xy[2 * i + 1];
        tear = (a < 0) != (b < 0) && fabs(b - a) < 180;
        if (fabs(b - a) == 360 && y == r->xy[2 * j + 1]) tear = across_map(r, q, i, y);
      }
    double k = cos(out->lat0 * MG_PI / 180) * MG_EARTH_M * MG_PI / 180;
    for (size_t i = 0; i < r->np; i++) {
      double lon = r->xy[2 * i];
      if (hi - lo > 180 && !tear && lon < 0) lon += 360;
      r->xy[2 * i] = lon * k;
      r->xy[2 * i + 1] = r->xy[2 * i + 1] * MG_EARTH_M * MG_PI / 180;
    }
  }
  double g = o->round;
  int autog = g == MG_ROUND_AUTO;
  if (autog) { /* after the projection: the grid is for the coordinates meshed */
    out->round_exp = mg_auto_grid(r->xy, r->np, &out->round_mag, &out->round_ext);
    g = ldexp(1, out->round_exp);
  }
  out->round = g > 0 ? g : 0;
  moved_t *mv = NULL;
  if (autog && r->np && !(mv = malloc(r->np * sizeof *mv))) return 3;
  for (size_t i = 0; mv && i < r->np; i++)
    mv[i].ox = r->xy[2 * i], mv[i].oy = r->xy[2 * i + 1], mv[i].i = i;
  if (g > 0)
    for (size_t i = 0; i < 2 * r->np; i++) {
      /* (from 2^53 steps on, the coordinate is a multiple of g to within half an ulp and
       * stays: the quotient may overflow, as qk_poly_round says) */
      double q = r->xy[i] / g, v = fabs(q) < 0x1p53 ? nearbyint(q) * g : r->xy[i];
      out->rounded += v != r->xy[i];
      r->xy[i] = v;
    }
  if (!mv) return 0;
  for (size_t i = 0; i < r->np; i++) mv[i].x = r->xy[2 * i], mv[i].y = r->xy[2 * i + 1];
  qsort(mv, r->np, sizeof *mv, moved_cmp);
  for (size_t i = 1; i < r->np; i++)
    if (mv[i].x == mv[i - 1].x && mv[i].y == mv[i - 1].y &&
        (mv[i].ox != mv[i - 1].ox || mv[i].oy != mv[i - 1].oy)) {
      size_t a = mv[i - 1].i, b = mv[i].i;
      if (*p1 == SIZE_MAX || (a < b ? a : b) < *p1) /* the first in file order */
        *p1 = a < b ? a : b, *p2 = a < b ? b : a;
    }
  free(mv);
  return 0;
}

/* Vertices lying exactly inside an axis-parallel ring edge (a T-junction: parts of a
 * feature cut along a meridian and kept whole across the antimeridian, Fiji's islands,
 * meet there with their cut points at different latitudes). Such an edge is split at
 * them, so that the cut edges become shared segments. Exact: equal coordinates only.
 * by_x: vertex numbers sorted by (x, y) (the merged vertices are in that order already);
 * by_y: sorted by (y, x). */
typedef struct tj {
  const double *xy;
  size_t nv;
  const uint32_t *by_y;
} tj_t;

/* First position in [0, n) whose key (c0 major, c1 minor) is >= (u, w); in by_x order
 * (idx NULL: vertex i itself) or by_y order. */
static size_t tj_lower(const tj_t *t, const uint32_t *idx, int c0, double u, double w) {
  size_t lo = 0, hi = t->nv;
  while (lo < hi) {
    size_t mid = lo + (hi - lo) / 2;
    const double *p = &t->xy[2 * (idx ? idx[mid] : mid)];
    if (p[c0] < u || (p[c0] == u && p[1 - c0] < w))
      lo = mid + 1;
    else
      hi = mid;
  }
  return lo;
}

/* The vertices strictly inside edge a-b when it is axis-parallel, in order from a to b,
 * into list (NULL: count only); returns how many. */
static size_t tj_inside(const tj_t *t, uint32_t a, uint32_t b, uint32_t *list) {
  const double *pa = &t->xy[2 * a], *pb = &t->xy[2 * b];
  int c0; /* the coordinate the edge keeps */
  if (pa[0] == pb[0])
    c0 = 0;
  else if (pa[1] == pb[1])
    c0 = 1;
  else
    return 0;
  const uint32_t *idx = c0 == 0 ? NULL : t->by_y;
  double lo = fmin(pa[1 - c0], pb[1 - c0]), hi = fmax(pa[1 - c0], pb[1 - c0]);
  size_t i0 = tj_lower(t, idx, c0, pa[c0], lo) + 1; /* past the endpoint at lo */
  size_t n = 0;
  for (size_t i = i0; i < t->nv; i++) {
    uint32_t v = idx ? idx[i] : (uint32_t)i;
    const double *p = &t->xy[2 * v];
    if (p[c0] != pa[c0] || p[1 - c0] >= hi) break;
    n++;
  }
  if (list) {
    int up = pa[1 - c0] < pb[1 - c0];
    for (size_t j = 0; j < n; j++) {
      size_t i = up ? i0 + j : i0 + n - 1 - j;
      list[j] = idx ? idx[i] : (uint32_t)i;
    }
  }
  return n;
}

static const double *g_cmp_xy; /* for qsort by (y, x) */
static int cmp_yx(const void *pa, const void *pb) {
  const double *a = &g_cmp_xy[2 * *(const uint32_t *)pa], *b = &g_cmp_xy[2 * *(const uint32_t *)pb];
  if (a[1] != b[1]) return a[1] < b[1] ? -1 : 1;
  return (a[0] > b[0]) - (a[0] < b[0]);
}

/* Merge coincident points into vertices, make the segments and the ring records. */
static int build(const rings_t *r, mg_input_t *out) {
  vkey_t *k = malloc((r->np + 1) * sizeof *k);
  size_t *vid = malloc((r->np + 1) * sizeof *vid);
  out->xy = malloc((2 * r->np + 2) * sizeof *out->xy);
  out->seg = malloc((2 * r->np + 2) * sizeof *out->seg);
  out->seg_feature = malloc((r->np + 1) * sizeof *out->seg_feature);
  out->seg_ring = malloc((r->np + 1) * sizeof *out->seg_ring);
  out->seg_point = malloc((r->np + 1) * sizeof *out->seg_point);
  out->ring_v = malloc((r->np + 1) * sizeof *out->ring_v);
  out->ring_start = malloc((r->nr + 1) * sizeof *out->ring_start);
  out->ring_sign = malloc((r->nr + 1) * sizeof *out->ring_sign);
  out->ring_src = malloc((r->nr + 1) * sizeof *out->ring_src);
  uint32_t *rpos = NULL; /* beside ring_v: the position in the input ring it comes from */
  int rc = 0;
  if (!k || !vid || !out->xy || !out->seg || !out->seg_feature || !out->seg_ring ||
      !out->seg_point || !out->ring_v || !out->ring_start || !out->ring_sign || !out->ring_src)
    rc = 3;
  if (!rc) {
    for (size_t i = 0; i < r->np; i++) k[i] = (vkey_t){r->xy[2 * i], r->xy[2 * i + 1], i};
    qsort(k, r->np, sizeof *k, cmp_vkey);
    for (size_t i = 0; i < r->np; i++) {
      if (i && k[i].x == k[i - 1].x && k[i].y == k[i - 1].y) {
        vid[k[i].i] = out->nv - 1, out->merged++;
        continue;
      }
      out->xy[2 * out->nv] = k[i].x, out->xy[2 * out->nv + 1] = k[i].y;
      vid[k[i].i] = out->nv++;
    }
    /* Vertex numbers in input order of first appearance make messages easier to follow,
     * but sorted order is what was built; keep it (the .node output numbers them). */
    out->ring_start[0] = 0;
    /* T-junctions: count the vertices to insert, and make room for them. */
    uint32_t *by_y = malloc((out->nv + 1) * sizeof *by_y);
    if (!by_y) rc = 3;
    tj_t tj = {out->xy, out->nv, by_y};
    size_t extra = 0;
    if (!rc) {
      for (size_t i = 0; i < out->nv; i++) by_y[i] = (uint32_t)i;
      g_cmp_xy = out->xy;
      qsort(by_y, out->nv, sizeof *by_y, cmp_yx);
      for (size_t q = 0; q < r->nr; q++)
        for (size_t i = r->start[q]; i < r->start[q + 1]; i++) {
          size_t j = i + 1 < r->start[q + 1] ? i + 1 : r->start[q];
          if (vid[i] != vid[j]) extra += tj_inside(&tj, (uint32_t)vid[i], (uint32_t)vid[j], NULL);
        }
    }
    if (!rc && extra) {
      size_t n = r->np + extra + 1;
      uint32_t *rv = realloc(out->ring_v, n * sizeof *rv);
      if (rv) out->ring_v = rv;
      uint32_t *sg = realloc(out->seg, 2 * n * sizeof *sg);
      if (sg) out->seg = sg;
      uint32_t *sf = realloc(out->seg_feature, n * sizeof *sf);
      if (sf) out->seg_feature = sf;
      uint32_t *sr = realloc(out->seg_ring, n * sizeof *sr);
      if (sr) out->seg_ring = sr;
      uint32_t *sp = realloc(out->seg_point, n * sizeof *sp);
      if (sp) out->seg_point = sp;
      if (!rv || !sg || !sf || !sr || !sp) rc = 3;
    }
    out->split_points = extra;
    if (!rc && !(rpos = malloc((r->np + extra + 1) * sizeof *rpos))) rc = 3;
    for (size_t q = 0; !rc && q < r->nr; q++) {
      size_t s0 = r->start[q], s1 = r->start[q + 1], at = out->ring_start[out->nr], m = 0;
      /* The ring's distinct consecutive vertices, with T-junction vertices inserted (an
       * inserted vertex is named by the position its edge starts from). */
      for (size_t i = s0; i < s1; i++) {
        uint32_t v = (uint32_t)vid[i];
        if (!(m && out->ring_v[at + m - 1] == v))
          rpos[at + m] = (uint32_t)(i - s0), out->ring_v[at + m++] = v;
        uint32_t w = (uint32_t)vid[i + 1 < s1 ? i + 1 : s0];
        size_t add = extra && v != w ? tj_inside(&tj, v, w, out->ring_v + at + m) : 0;
        for (size_t j = 0; j < add; j++) rpos[at + m + j] = (uint32_t)(i - s0);
        m += add;
      }
      while (m > 1 && out->ring_v[at] == out->ring_v[at + m - 1]) m--;
      if (m < 3) {
        out->dropped_rings++;
        continue;
      }
      for (size_t i = 0; i < m; i++) {
        uint32_t a = out->ring_v[at + i], b = out->ring_v[at + (i + 1) % m];
        out->seg[2 * out->ns] = a, out->seg[2 * out->ns + 1] = b;
        out->seg_feature[out->ns] = r->feat[q], out->seg_ring[out->ns] = (uint32_t)q;
        out->seg_point[out->ns] = rpos[at + i];
        out->ns++;
      }
      out->ring_sign[out->nr] = r->hole[q] ? -1 : 1;
      out->ring_src[out->nr] = (uint32_t)q;
      out->ring_start[++out->nr] = at + m;
    }
    free(by_y), free(rpos);
    /* A segment given twice (rings sharing an edge) is kept once: the first copy. */
    skey_t *sk = NULL;
    unsigned char *dup = NULL;
    if (!rc) {
      sk = malloc((out->ns + 1) * sizeof *sk);
      dup = calloc(out->ns + 1, 1);
      if (!sk || !dup) {
        free(sk), free(dup);
        rc = 3;
      }
    }
    size_t w = 0;
    if (!rc) {
      for (size_t s = 0; s < out->ns; s++) {
        uint32_t a = out->seg[2 * s], b = out->seg[2 * s + 1];
        sk[s].key = a < b ? (uint64_t)a << 32 | b : (uint64_t)b << 32 | a, sk[s].i = s;
      }
      qsort(sk, out->ns, sizeof *sk, cmp_skey);
      for (size_t s = 1; s < out->ns; s++)
        if (sk[s].key == sk[s - 1].key) dup[sk[s].i] = 1;
      for (size_t s = 0; s < out->ns; s++) {
        if (dup[s]) {
          out->dup_segments++;
          continue;
        }
        out->seg[2 * w] = out->seg[2 * s], out->seg[2 * w + 1] = out->seg[2 * s + 1];
        out->seg_feature[w] = out->seg_feature[s], out->seg_ring[w] = out->seg_ring[s];
        out->seg_point[w] = out->seg_point[s];
        w++;
      }
      free(sk), free(dup);
    }
    if (!rc) out->ns = w;
    /* The points of dropped rings would stay behind as isolated vertices, which the
     * mesher keeps as input (refining round them inside the domain): keep only the
     * vertices some segment uses. */
    uint32_t *renum = rc ? NULL : malloc((out->nv + 1) * sizeof *renum);
    if (!rc && !renum) rc = 3;
    if (!rc && out->dropped_rings) {
      for (size_t v = 0; v < out->nv; v++) renum[v] = UINT32_MAX;
      for (size_t i = 0; i < 2 * out->ns; i++) renum[out->seg[i]] = 0;
      size_t nv = 0;
      for (size_t v = 0; v < out->nv; v++)
        if (renum[v] == 0) {
          out->xy[2 * nv] = out->xy[2 * v], out->xy[2 * nv + 1] = out->xy[2 * v + 1];
          renum[v] = (uint32_t)nv++;
        }
      for (size_t i = 0; i < 2 * out->ns; i++) out->seg[i] = renum[out->seg[i]];
      for (size_t i = 0; i < out->ring_start[out->nr]; i++) out->ring_v[i] = renum[out->ring_v[i]];
      out->unused_points = out->nv - nv;
      out->nv = nv;
    }
    free(renum);
  }
  free(k), free(vid);
  return rc;
}

/* Every ring of in closed, as region layers want: *xy the points, (*rs)[q] ring q's first
 * (nr + 1 entries). 0, or 3 (out of memory: nothing left allocated). */
static int closed_rings(const mg_input_t *in, double **xy, size_t **rs) {
  *xy = malloc(2 * (in->ring_start[in->nr] + in->nr + 1) * sizeof **xy);
  *rs = malloc((in->nr + 1) * sizeof **rs);
  if (!*xy || !*rs) {
    free(*xy), free(*rs);
    *xy = NULL, *rs = NULL;
    return 3;
  }
  size_t at = 0;
  for (size_t q = 0; q < in->nr; q++) {
    (*rs)[q] = at;
    for (size_t i = in->ring_start[q]; i <= in->ring_start[q + 1]; i++) {
      uint32_t v = in->ring_v[i < in->ring_start[q + 1] ? i : in->ring_start[q]];
      (*xy)[2 * at] = in->xy[2 * v], (*xy)[2 * at + 1] = in->xy[2 * v + 1], at++;
    }
  }
  (*rs)[in->nr] = at;
  return 0;
}

/* What the search for hole points works with: the rings closed (xy, rs), the layer of
 * every ring as one even-odd feature (all) and of each ring as a feature of its own
 * (each, kept in mg_input_t as `rings`), and lists of rings, nr + 1 entries each. */
typedef struct hp {
  mg_input_t *in;
  const double *xy;
  const size_t *rs;
  const qk_region_t *all, *each;
  uint32_t *held, *at_p, *at_v;
  size_t nheld;
} hp_t;

/* The rings other than q holding every vertex of q, boundaries included, into h->held
 * (both lists in increasing order). */
static void rings_holding(hp_t *h, size_t q) {
  size_t m = h->in->ring_start[q + 1] - h->in->ring_start[q], cnt = 0;
  h->nheld = 0;
  for (size_t e = 0; e < m && (!e || h->nheld); e++) {
    qk_point_t v = {h->xy[2 * (h->rs[q] + e)], h->xy[2 * (h->rs[q] + e) + 1]};
    if (qk_region_locate_all(h->each, v, QK_BOUNDARY_CLOSED, h->at_v, h->in->nr, &cnt))
      cnt = 0; /* (cannot fail: a finite vertex, room for every ring) */
    size_t k = 0;
    for (size_t i = 0, j = 0; i < (e ? h->nheld : cnt); i++) {
      uint32_t r = e ? h->held[i] : h->at_v[i];
      while (j < cnt && h->at_v[j] < r) j++;
      if (j < cnt && h->at_v[j] == r && r != q) h->held[k++] = r;
    }
    h->nheld = k;
  }
}

/* A hole filled by another polygon, ring on ring (Lesotho in South Africa's hole, both
 * meshed): a ring holding every vertex of q whose every vertex q holds bounds the same
 * region, the rings crossing nowhere (the mesher refuses crossings); inside it the area
 * goes on (even-odd), and the hole needs no point. It was refused as a hole "covered by
 * another polygon". Only when the rings around q's inside, q and those holding it, are
 * odd in number (even-odd, as the domain): a hole equal to its own shell (two rings, no
 * area) counted as filled, and a polygon of no area was meshed as a square. */
static int filled(hp_t *h, size_t q) {
  if (h->nheld % 2) return 0; /* (q and an odd number holding it: even) */
  for (size_t i = 0; i < h->nheld; i++) {
    size_t r = h->held[i], np = 0;
    int all = 1;
    for (size_t v = h->rs[r]; v + 1 < h->rs[r + 1] && all; v++) {
      if (qk_region_locate_all(h->each, (qk_point_t){h->xy[2 * v], h->xy[2 * v + 1]},
                               QK_BOUNDARY_CLOSED, h->at_p, h->in->nr, &np))
        np = 0; /* (cannot fail, as above) */
      all = 0;
      for (size_t j = 0; j < np && !all; j++) all = h->at_p[j] == q;
    }
    if (all) return 1;
  }
  return 0;
}

/* Whether the rings holding p, under the boundary rule b, are exactly the rings holding
 * q (h->held), and q when `hole` (p on its inner side). */
static int in_face(hp_t *h, size_t q, int hole, qk_point_t p, qk_boundary_t b) {
  size_t np = 0;
  if (qk_region_locate_all(h->each, p, b, h->at_p, h->in->nr, &np))
    return 0; /* (a probe not finite) */
  if (np != h->nheld + (size_t)hole) return 0;
  for (size_t i = 0, j = 0; i < np; i++) {
    if (h->at_p[i] == q) continue;
    while (j < h->nheld && h->held[j] < h->at_p[i]) j++;
    if (j == h->nheld || h->held[j] != h->at_p[i]) return 0;
  }
  return 1;
}

/* The arc of ring q from edge a0, len edges: probes near the middle of an edge on either
 * side, from 2^-52 of the edge's length (a hole 5.8e-11 thin across edges of 256 lay
 * below 2^-41, where the probes once began, and was refused) out to 0.3 of it. The
 * nearest that lies in the face beside the edge (in exactly the rings holding q, and q for a hole)
 * tells whether that face is outside the area: then it is the hole point (returns 1). Nearest
 * first, so that a probe does not jump over a ring lying close to the edge into another face (a
 * sand bar along a lake's shore left a sliver of lake as land). Up to 4096 edges an arc
 * are tried. *loose: the first probe strictly inside the hole ring and outside the area,
 * to fall back on. */
static int arc_point(hp_t *h, size_t q, int hole, size_t a0, size_t len, int *loose,
                     qk_point_t *loose_p) {
  static const double coarse[] = {1e-3, 1e-2, 0.1, 0.3};
  mg_input_t *in = h->in;
  size_t m = in->ring_start[q + 1] - in->ring_start[q];
  for (size_t t = 0; t<len; t += len> 4096 ? (len + 4095) / 4096 : 1) {
    size_t e = (a0 + t) % m;
    const double *a = &h->xy[2 * (h->rs[q] + e)], *b = &h->xy[2 * (h->rs[q] + e + 1)];
    double mx = a[0] + (b[0] - a[0]) / 2, my = a[1] + (b[1] - a[1]) / 2;
    double nx = -(b[1] - a[1]), ny = b[0] - a[0];
    for (int k = 0; k < 2 * (42 + 4); k++) {
      double mag = k / 2 < 42 ? ldexp(1.0, -52 + k / 2) : coarse[k / 2 - 42];
      double step = k % 2 ? -mag : mag;
      qk_point_t p = {mx + step * nx, my + step * ny};
      size_t np = 0;
      if (qk_region_locate_all(h->each, p, QK_BOUNDARY_OPEN, h->at_p, in->nr, &np))
        continue; /* (a probe not finite: overflowed) */
      int in_q = 0;
      for (size_t i = 0; i < np && !in_q; i++) in_q = h->at_p[i] == q;
      if (in_q != hole) continue; /* the other side of the edge */
      uint32_t f_all = 0;
      int outside =
          qk_region_locate(h->all, p, QK_BOUNDARY_CLOSED, &f_all) == QK_OK && f_all == QK_NONE;
      if (hole && outside && !*loose) *loose = 1, *loose_p = p;
      /* in exactly the rings holding q (and q), strictly and boundaries included */
      if (!in_face(h, q, hole, p, QK_BOUNDARY_OPEN) || !in_face(h, q, hole, p, QK_BOUNDARY_CLOSED))
        continue;
      if (outside) in->holes[2 * in->nh] = p.x, in->holes[2 * in->nh + 1] = p.y, in->nh++;
      return outside; /* the face beside the arc: a point if it is not area */
    }
  }
  return 0;
}

/* A hole point for every face a hole ring bounds from inside, found exactly with planar
 * region layers: inside the ring and the rings that hold the whole of it (its shell, and
 * what holds that), on no ring's boundary, inside no other ring (an island in the lake, a
 * pond on the island: a point in the pond lay inside the hole ring and outside the area,
 * and the lake was meshed), and outside the domain (even-odd over every ring, boundaries
 * included). The ring bounds several faces when other rings touch it at two vertices or
 * more (an island touching the lake's shore at two points cuts the lake in two): a point
 * is looked for along each arc of the ring between vertices other rings share. Outer
 * rings that other rings touch and some ring holds are looked at on their outer side (a
 * pocket two islands in a lake enclose: a face no hole ring bounds, which was meshed as
 * area). The layer of each ring stays in in->rings for mg_outside_rings. */
static int hole_points(mg_input_t *in, const char *path, char *msg, size_t n) {
  size_t nh = 0;
  for (size_t q = 0; q < in->nr; q++) nh += in->ring_sign[q] < 0;
  if (!nh && !mg_rings_touch(in)) return 0;
  /* (at most a point an edge) */
  in->holes = malloc(2 * (in->ring_start[in->nr] + 1) * sizeof *in->holes);
  double *xy = NULL;
  size_t *rs = NULL, fs_all[2] = {0, in->nr};
  size_t *fs_each = malloc((in->nr + 1) * sizeof *fs_each);
  uint32_t *lists = malloc(3 * (in->nr + 1) * sizeof *lists);
  unsigned char *uses = calloc(in->nv + 1, 1);
  if (!in->holes || !fs_each || !lists || !uses || closed_rings(in, &xy, &rs)) {
    free(xy), free(rs), free(fs_each), free(lists), free(uses);
    return mg_fail(msg, n, 3, "out of memory");
  }
  qk_region_options_t ro;
  qk_region_options_init(&ro);
  ro.planar = 1;
  qk_region_arrays_t all = {xy, rs, in->nr, fs_all, 1};
  for (size_t q = 0; q <= in->nr; q++) fs_each[q] = q; /* one feature per ring */
  qk_region_arrays_t each = {xy, rs, in->nr, fs_each, in->nr};
  qk_region_t *l_all = NULL;
  qk_error_t err;
  int rc = 0;
  if (qk_region_from_arrays(&all, &ro, &l_all, &err) != QK_OK ||
      qk_region_from_arrays(&each, &ro, &in->rings, &err) != QK_OK)
    rc = mg_fail(msg, n, 1, "%s: the rings do not make a polygon layer: %s", path, err.message);
  hp_t h = {in, xy, rs, l_all, in->rings, lists, lists + in->nr + 1, lists + 2 * (in->nr + 1), 0};
  for (size_t i = 0; i < in->ring_start[in->nr]; i++)
    if (uses[in->ring_v[i]] < 2) uses[in->ring_v[i]]++;
  for (size_t q = 0; !rc && q < in->nr; q++) {
    int hole = in->ring_sign[q] < 0, found = 0;
    size_t m = in->ring_start[q + 1] - in->ring_start[q], first = 0;
    while (first < m && uses[in->ring_v[in->ring_start[q] + first]] < 2) first++;
    if (!hole && first == m) continue;
    if (first == m) first = 0;
    rings_holding(&h, q);
    if (hole && filled(&h, q)) {
      in->filled_holes++;
      continue;
    }
    /* (an outer ring held by no other ring has the outside of every ring beside it, or a
     * face that the lattice modes mesh as their outside: no point goes there) */
    if (!hole && !h.nheld) continue;
    int loose = 0;
    qk_point_t loose_p = {0, 0};
    /* The arcs: from each vertex another ring (or the ring again) shares to the next; one
     * arc, the whole ring, when none is shared. */
    for (size_t a0 = first, done = 0; done < m;) {
      size_t len = 1; /* edges in this arc: a0 .. a0 + len - 1 (mod m) */
      while (done + len < m && uses[in->ring_v[in->ring_start[q] + (a0 + len) % m]] < 2) len++;
      found |= arc_point(&h, q, hole, a0, len, &loose, &loose_p);
      done += len, a0 = (a0 + len) % m;
    }
    if (!hole) continue;
    /* No such point: rings that cross (the mesher names the crossing) or a gap below 2^-52
     * of every edge tried. A point strictly inside the ring and outside the area, as
     * before, lets the mesher say which. */
    if (!found && loose)
      found = 1, in->holes[2 * in->nh] = loose_p.x, in->holes[2 * in->nh + 1] = loose_p.y, in->nh++;
    if (!found) {
      size_t v = in->ring_v[in->ring_start[q]];
      char what[128], ptr[512], place[1024], note[512];
      mg_describe_ring(in, in->ring_src[q], SIZE_MAX, what, sizeof what, ptr, sizeof ptr);
      mg_place(path, ptr, place, sizeof place);
      rc = mg_fail(msg, n, 1,
                   "%s: %s: no point found strictly inside this hole ring (through (%.17g, "
                   "%.17g)) and outside the area (even-odd over every ring): a hole must "
                   "lie inside its shell, not outside it or covered by another polygon%s",
                   place, what, in->xy[2 * v], in->xy[2 * v + 1],
                   mg_pole_note(in, note, sizeof note));
    }
  }
  qk_region_free(l_all);
  free(xy), free(rs), free(fs_each), free(lists), free(uses);
  return rc;
}

/* A text whose first value (after a byte order mark and blanks) is not an object is
 * refused at that value, in the library reader's words, without reading further; *scan
 * keeps how far only blanks were seen. 0 while the text may still be GeoJSON. */
static int not_an_object(const char *path, const char *t, size_t len, size_t *scan, char *msg,
                         size_t n) {
  size_t bom = len >= 3 && !memcmp(t, "\xEF\xBB\xBF", 3) ? 3 : 0, i = *scan ? *scan : bom;
  while (i < len && strchr(" \t\r\n", t[i]) && t[i]) i++;
  *scan = i;
  if (i >= len || t[i] == '{') return 0;
  unsigned long line = 1, col = 1;
  for (size_t k = bom; k < i; k++) t[k] == '\n' ? (line++, col = 1) : col++;
  const char *why = t[i] && strchr("[\"-0123456789tfn", t[i])
                        ? "expected a GeoJSON object with a string \"type\""
                        : "malformed JSON: unexpected character";
  return mg_fail(msg, n, 1, "%s:%lu:%lu: %s", path, line, col, why);
}

/* The whole file into a malloc'd buffer (NUL-terminated); 0, or an exit code with msg. */
static int slurp(const char *path, char **text, size_t *len, int *stream, char *msg, size_t n) {
  *text = NULL, *len = 0, *stream = 0;
  FILE *f = fopen(path, "rb");
  if (!f) return mg_fail(msg, n, 1, "%s: cannot open: %s", path, strerror(errno));
  /* (stat, not fstat of fileno: this file is also compiled into tests as strict C11) */
  struct stat sb;
  *stream = !(stat(path, &sb) == 0 && S_ISREG(sb.st_mode));
  size_t max = *stream ? (size_t)CLI_STREAM_MAX : SIZE_MAX - 2; /* (tools/cli.h) */
  size_t cap = 0, scan = 0;
  int rc = 0, checked = 0;
  for (;;) {
    if (*len + 1 >= cap) {
      /* (one byte past the limit is read, to tell a text of that length from a longer one,
       * and the buffer never grows past it and the NUL) */
      size_t nc = cap ? 2 * cap : 1 << 16;
      if (nc > max + 2) nc = max + 2;
      char *p = realloc(*text, nc);
      if (!p) {
        rc = mg_fail(msg, n, 3, "%s: out of memory reading it", path);
        break;
      }
      *text = p, cap = nc;
    }
    size_t room = cap - 1 - *len;
    size_t got = fread(*text + *len, 1, room, f);
    /* Reading stops at a NUL byte, which the GeoJSON reader refuses where it is: an
     * endless binary stream (a .geojson name for /dev/zero) filled memory before. */
    const char *nul = got ? memchr(*text + *len, '\0', got) : NULL;
    if (nul) {
      *len = (size_t)(nul - *text) + 1;
      break;
    }
    *len += got;
    if (*len > max) {
      rc = mg_fail(msg, n, 1,
                   "%s: GeoJSON text from a pipe or device longer than %zu bytes, the limit for "
                   "a stream (a regular file has none)",
                   path, max);
      break;
    }
    /* (when the text ended within this read, the reader words its error as it always has) */
    if (!checked && got == room && (rc = not_an_object(path, *text, *len, &scan, msg, n))) break;
    checked = scan < *len;
    if (got == 0) break;
  }
  if (!rc && ferror(f)) rc = mg_fail(msg, n, 1, "%s: cannot read: %s", path, strerror(errno));
  fclose(f);
  if (rc) {
    free(*text);
    *text = NULL;
    return rc;
  }
  (*text)[*len] = '\0';
  return 0;
}

/* The JSON tree of a text the region reader accepted (a byte order mark skipped). */
static json_object *parse_again(const char *text, size_t len) {
  if (len >= 3 && !memcmp(text, "\xEF\xBB\xBF", 3)) text += 3, len -= 3;
  json_tokener *tok = json_tokener_new();
  if (!tok) return NULL;
  json_object *root = NULL;
  size_t at = 0;
  do { /* json-c takes an int length: large texts in pieces */
    size_t chunk = len - at > (1u << 30) ? (1u << 30) : len - at;
    root = json_tokener_parse_ex(tok, text + at, (int)chunk);
    if (json_tokener_get_error(tok) != json_tokener_continue) break;
    at += chunk;
  } while (at < len);
  if (json_tokener_get_error(tok) != json_tokener_success) {
    json_object_put(root);
    root = NULL;
  }
  json_tokener_free(tok);
  return root;
}

int mg_read(const char *path, const mg_options_t *o, mg_input_t *out, char *msg, size_t n) {
  memset(out, 0, sizeof *out);
  qk_region_t *layer = NULL;
  qk_error_t err;
  qk_region_options_t ro;
  qk_region_options_init(&ro);
  ro.planar = !o->project; /* lon/lat is checked as such only when it is projected here */
  /* One read of the file: the region reader checks the text, then the same text is
   * walked for the rings. */
  char *text = NULL;
  size_t len = 0;
  int stream = 0;
  int rc0 = slurp(path, &text, &len, &stream, msg, n);
  if (rc0) return rc0;
  qk_status_t st = qk_region_read_geojson_text(text, len, &ro, &layer, &err);
  if (st != QK_OK) {
    free(text);
    int rc = st == QK_ERR_NOMEM ? 3 : 1;
    if (err.line)
      return mg_fail(msg, n, rc, "%s:%lu:%lu: %s", path, err.line, err.column, err.message);
    return mg_fail(msg, n, rc, "%s: %s", path, err.message[0] ? err.message : qk_strerror(st));
  }
  size_t nf = qk_region_feature_count(layer);
  unsigned char *want = calloc(nf + 1, 1);
  int rc = want ? 0 : 3;
  if (rc) mg_fail(msg, n, 3, "out of memory");
  long pick = o->feature;
  if (!rc && o->field_name) {
    /* Every match counted: the first is meshed, and the caller says when there were
     * others (they would be left out without a word). A property's text is what join
     * prints: JSON null reads as "", so --field NAME= matches null and "" alike. */
    pick = -1;
    for (size_t f = 0; f < nf; f++) {
      const char *v = qk_region_property(layer, (uint32_t)f, o->field_name);
      if (v && !strcmp(v, o->field_value) && !out->field_matches++) pick = (long)f;
    }
    out->field_pick = pick;
    if (pick < 0)
      rc = mg_fail(msg, n, 1, "%s: no feature has %s=%s (of %zu features)", path, o->field_name,
                   o->field_value, nf);
  }
  if (!rc && pick >= (long)nf)
    rc = mg_fail(msg, n, 1, "%s: feature %ld does not exist (%zu features)", path, pick, nf);
  if (!rc) {
    for (size_t f = 0; f < nf; f++) want[f] = pick < 0 || (long)f == pick;
    const char *nm = NULL;
    if (pick >= 0) {
      static const char *names[] = {"NAME", "name", "ADMIN", "admin"};
      for (int i = 0; i < 4 && !nm; i++) nm = qk_region_property(layer, (uint32_t)pick, names[i]);
    }
    snprintf(out->name, sizeof out->name, "%s", nm ? nm : "");
  }
  qk_region_free(layer);
  rings_t r;
  memset(&r, 0, sizeof r);
  json_object *root = NULL;
  size_t *sp = NULL, ns = 0, seen = 0;
  int spans = rc ? 1 : feature_spans(text, len, &sp, &ns);
  if (!rc && spans == 3) rc = mg_fail(msg, n, 3, "out of memory");
  if (!rc && spans == 0 && gather_spans(text, sp, ns, want, nf, &r, &seen))
    rc = mg_fail(msg, n, 3, "%s: out of memory parsing its features again", path);
  free(sp);
  if (!rc && spans == 1) {
    root = parse_again(text, len);
    if (!root) rc = mg_fail(msg, n, 3, "%s: out of memory parsing it again", path);
  }
  char *kept_path = stream ? malloc(strlen(path) + 1) : NULL;
  if (kept_path) {
    strcpy(kept_path, path);
    free(mg_kept.path), free(mg_kept.text);
    mg_kept.path = kept_path, mg_kept.text = text, mg_kept.len = len;
  } else {
    free(text); /* (a stream's text without memory for its name: positions are left out) */
  }
  if (!rc && root && gather(root, want, nf, &r, &seen)) rc = mg_fail(msg, n, 3, "out of memory");
  if (!rc && seen != nf)
    rc = mg_fail(msg, n, 3, "%s: %zu features here, %zu for the region reader", path, seen, nf);
  if (!rc) { /* the features that gave rings */
    out->features = 0;
    for (size_t q = 0; q < r.nr; q++) out->features += q == 0 || r.feat[q] != r.feat[q - 1];
  }
  if (!rc && r.nr == 0) {
    if (pick >= 0) {
      char ptr[64] = "", place[1024];
      if (r.kind == 2) snprintf(ptr, sizeof ptr, "/features/%ld", pick);
      if (r.kind) strcat(ptr, "/geometry");
      mg_place(path, ptr, place, sizeof place);
      rc = mg_fail(msg, n, 1, "%s: feature %ld has no Polygon or MultiPolygon geometry", place,
                   pick);
    } else
      rc = mg_fail(msg, n, 1, "%s: no Polygon or MultiPolygon features", path);
  }
  json_object_put(root);
  free(want);
  int south = 0;
  size_t pole = rc ? SIZE_MAX : pole_ring(&r, &south);
  size_t c1 = SIZE_MAX, c2 = SIZE_MAX;
  if (!rc) {
    out->points = r.np;
    if (transform(&r, o, out, &c1, &c2)) rc = mg_fail(msg, n, 3, "out of memory");
  }
  if (!rc && c1 != SIZE_MAX) {
    /* Said before anything is merged: the rings' table names the two positions. */
    size_t q1 = 0, q2 = 0;
    while (r.start[q1 + 1] <= c1) q1++;
    while (r.start[q2 + 1] <= c2) q2++;
    out->nin = r.nr, out->in_feature = r.feat, out->in_poly = r.poly, out->in_ring = r.num;
    out->in_path = r.path, out->paths = r.paths;
    char w1[128], w2[128], ptr1[512], ptr2[512], place1[1024];
    unsigned long l2, col2;
    mg_describe_ring(out, q1, c1 - r.start[q1], w1, sizeof w1, ptr1, sizeof ptr1);
    mg_describe_ring(out, q2, c2 - r.start[q2], w2, sizeof w2, ptr2, sizeof ptr2);
    mg_place(path, ptr1, place1, sizeof place1);
    mg_locate(path, ptr2, &l2, &col2);
    out->nin = 0, out->in_feature = out->in_poly = out->in_ring = NULL;
    out->in_path = NULL, out->paths = NULL;
    rc =
        mg_fail(msg, n, 1,
                "%s: %s and %s (at %lu:%lu) are distinct points that both round to (%.17g, "
                "%.17g) on the grid 2^%d that --round auto chose (coordinates%s below 2^%d, "
                "extent below 2^%d): merged, they would change the input's shape. Give a "
                "finer grid (--round 2^%d, say) or remove one of the points",
                place1, w1, w2, l2, col2, r.xy[2 * c1], r.xy[2 * c1 + 1], out->round_exp,
                o->project ? " in metres" : "", out->round_mag, out->round_ext, out->round_exp - 8);
  }
  if (!rc && build(&r, out)) rc = mg_fail(msg, n, 3, "out of memory");
  /* The rings' table, for messages that name a ring or a position. */
  out->nin = r.nr, out->in_feature = r.feat, out->in_poly = r.poly, out->in_ring = r.num;
  out->in_path = r.path, out->paths = r.paths;
  r.feat = r.poly = r.num = NULL, r.path = NULL, r.paths = NULL;
  out->pole_ring = pole, out->pole_south = south;
  if (!rc && pole != SIZE_MAX && o->project) {
    /* Projected, such a ring is not closed (it runs from one side of the map to the
     * other), and what follows would fail on it with a message about its symptoms. */
    char what[128], ptr[512], place[1024];
    mg_describe_ring(out, pole, SIZE_MAX, what, sizeof what, ptr, sizeof ptr);
    mg_place(path, ptr, place, sizeof place);
    rc = mg_fail(msg, n, 1,
                 "%s: %s goes round the %s pole (its longitudes wind once round the globe, "
                 "across the antimeridian): --project equirect cannot map it to a closed "
                 "ring; cut it along the antimeridian into rings that close in longitude, or "
                 "project it with a polar projection (PROJ: +proj=stere +lat_0=%s90) and "
                 "mesh the planar result without --project, or mesh other features with "
                 "--feature N or --field NAME=VALUE",
                 place, what, south ? "south" : "north", south ? "-" : "");
  }
  if (!rc && out->ns == 0) rc = mg_fail(msg, n, 1, "%s: no ring with 3 distinct points", path);
  if (!rc) rc = hole_points(out, path, msg, n);
  free(r.xy), free(r.start), free(r.hole);
  if (rc) mg_free(out);
  return rc;
}
#endif
