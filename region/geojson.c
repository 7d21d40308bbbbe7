/*
 * The GeoJSON reader (RFC 7946), on json-c. The text is parsed into json-c's tree, then
 * walked into the array form of a layer (rings, features, properties) and handed to the
 * builder; on any error nothing is built. A FeatureCollection's tree is made one
 * feature at a time (read_streamed), the whole text's only when that fails. A layer's
 * feature i is the file's feature i: features whose geometry is not a Polygon or
 * MultiPolygon stay as empty features (their properties kept) and are counted as
 * skipped, so indices match the file.
 *
 * json-c allocates with malloc, not through the layer's allocator; the allocation-failure
 * tests therefore cover the rest of the reader and the builder.
 */
#define _POSIX_C_SOURCE 200809L /* fileno, fstat */
#include <ctype.h>
#include <errno.h>
#include <limits.h>
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/stat.h>

#include "region/region_internal.h"

#ifdef QK_HAVE_JSONC
#include <json.h>

/* One step from a JSON value to a member of it (name) or an element of it (idx, name NULL). */
typedef struct gj_step {
  const char *name;
  size_t idx;
} gj_step_t;

enum { GJ_PATH_MAX = 24 };

typedef struct gj {
  const qk_allocator_t *a;
  int planar;
  qk__rings_t rg;
  qk_error_t *err;
  /* The way from the root to the value being read (json-c's tree keeps no positions):
   * each function steps in before it reads a member or element and steps out after it
   * read it well, so after an error the path leads to the offending value, and
   * locate() finds its line and column in the text. Deeper steps than
   * GJ_PATH_MAX are counted but not kept (the error then points at an ancestor). */
  gj_step_t path[GJ_PATH_MAX];
  size_t depth;
  char key[128]; /* a property name on the path (json-c's own is freed before locate()) */
  /* The text being walked (a whole document, or one feature of a collection read a
   * feature at a time) and how many steps of the path lead to it: where a value's own
   * digits are needed (raw()). */
  const char *text;
  size_t len, base;
} gj_t;

static size_t skip_value(const char *t, size_t n, size_t i);
static size_t locate(const char *t, size_t n, const gj_step_t *path, size_t depth);

/* json-c 0.16 reads an integer beyond 64 bits as INT64_MIN or UINT64_MAX without a word
 * (later versions refuse it in strict mode): 1e20 written as 100000000000000000000
 * became 1.8446744073709552e19. Such a value, or a container holding one, is read from
 * the text instead (raw()). */
static bool clamped(json_object *o) {
  return json_object_is_type(o, json_type_int) &&
         (json_object_get_int64(o) == INT64_MIN || json_object_get_uint64(o) == UINT64_MAX);
}

static bool clamped_text(const char *s) {
  return strstr(s, "18446744073709551615") || strstr(s, "-9223372036854775808");
}

/* The text of the value the path leads to: *off and *end in g->text; false when the path
 * is not kept whole or the value found is not what `number` asks (a number: '-'
 * or a digit; else any value). */
static bool raw(const gj_t *g, bool number, size_t *off, size_t *end) {
  if (!g->text || g->depth > GJ_PATH_MAX || g->depth < g->base) return false;
  *off = locate(g->text, g->len, g->path + g->base, g->depth - g->base);
  if (*off >= g->len) return false;
  char c = g->text[*off];
  if (number && c != '-' && (c < '0' || c > '9')) return false;
  *end = skip_value(g->text, g->len, *off);
  return true;
}

/* Is the integer written at text[off, end) beyond what json-c reads exactly (below -2^63,
 * above 2^64 - 1)? */
static bool beyond_64_bits(const char *t, size_t off, size_t end) {
  bool neg = t[off] == '-';
  size_t d0 = off + neg, z = 0;
  while (d0 + z + 1 < end && t[d0 + z] == '0') z++;
  const char *lim = neg ? "9223372036854775808" : "18446744073709551615";
  size_t m = end - d0 - z, ml = strlen(lim);
  return m > ml || (m == ml && memcmp(t + d0 + z, lim, ml) > 0);
}

static void step_in(gj_t *g, const char *name, size_t idx) {
  if (g->depth < GJ_PATH_MAX) g->path[g->depth] = (gj_step_t){name, idx};
  g->depth++;
}

static void step_out(gj_t *g) { g->depth--; }

static qk_status_t nomem(gj_t *g, qk_status_t st) {
  return qk__region_fail(g->err, st, SIZE_MAX, "%s while reading", qk_strerror(st));
}

static const char *type_name(json_object *o) {
  return o ? json_type_to_name(json_object_get_type(o)) : "null";
}

/* One ring: positions [lon, lat, ...]. */
/* A JSON value as text for an error message (json-c allocates it; "?" if that fails). */
static const char *shown(json_object *o) {
  const char *s = o ? json_object_to_json_string(o) : "null";
  return s ? s : "?";
}

/* Is o a number written with a nonzero digit before its exponent (json-c keeps a parsed
 * double's text)? Then reading it as 0 (an underflow, such as 1e-400) changed it. */
static bool nonzero_text(json_object *o) {
  if (!json_object_is_type(o, json_type_double)) return false;
  const char *s = json_object_to_json_string(o);
  for (; s && *s && *s != 'e' && *s != 'E'; s++)
    if (*s >= '1' && *s <= '9') return true;
  return false;
}

/* Where a position is in its feature, for messages: ty "polygon" (polygon a, ring b,
 * position c), "MultiLineString" (line a, position b), "Point", or another type (its
 * position a). Written out only for a message: a position of every polygon's ring goes
 * through here. */
typedef struct gj_at {
  const char *ty;
  size_t a, b, c;
} gj_at_t;

static const char *at_text(const gj_at_t *w, char *buf, size_t n) {
  if (!strcmp(w->ty, "polygon"))
    snprintf(buf, n, "polygon %zu, ring %zu, position %zu", w->a, w->b, w->c);
  else if (!strcmp(w->ty, "MultiLineString"))
    snprintf(buf, n, "MultiLineString line %zu, position %zu", w->a, w->b);
  else if (!strcmp(w->ty, "Point"))
    snprintf(buf, n, "Point");
  else
    snprintf(buf, n, "%s position %zu", w->ty, w->a);
  return buf;
}

static bool is_number(json_object *o) {
  return json_object_is_type(o, json_type_double) || json_object_is_type(o, json_type_int);
}

/* One position p ([x, y, ...], numbers only) into *vx, *vy, checked as every coordinate is:
 * `w` says where it is in feature f. The path leads to p; on an error, to p or the
 * number. */
static qk_status_t position(gj_t *g, json_object *p, size_t f, const gj_at_t *w, double *vx,
                            double *vy) {
  char at[96];
  json_object *x = NULL, *y = NULL;
  if (json_object_is_type(p, json_type_array) && json_object_array_length(p) >= 2) {
    x = json_object_array_get_idx(p, 0);
    y = json_object_array_get_idx(p, 1);
  }
  bool okx = x && is_number(x), oky = y && is_number(y);
  /* Elements after x and y (altitude, measure) are not used, but a position holds
   * numbers only (RFC 7946, 3.1.1): [0, 0, "a"] is not a position. */
  for (size_t j = 2; okx && oky && j < json_object_array_length(p); j++) {
    oky = is_number(json_object_array_get_idx(p, j));
  }
  if (!okx || !oky)
    return qk__region_fail(g->err, QK_ERR_PARSE, f,
                           "feature %zu, %s: expected [x, y] numbers, found %s", f,
                           at_text(w, at, sizeof at), shown(p));
  for (int c = 0; c < 2; c++) {
    size_t off, end;
    if (!clamped(c ? y : x)) continue;
    step_in(g, NULL, (size_t)c);
    if (!raw(g, true, &off, &end) || beyond_64_bits(g->text, off, end)) {
      bool shown_raw = raw(g, true, &off, &end);
      size_t nd = shown_raw ? end - off : 0;
      return qk__region_fail(g->err, QK_ERR_PARSE, f,
                             "feature %zu, %s: integer %.*s%s is outside the 64-bit range "
                             "json-c reads exactly (-2^63 to 2^64-1); write it with an exponent "
                             "(1e20, not 100000000000000000000)",
                             f, at_text(w, at, sizeof at), (int)(nd < 40 ? nd : 40),
                             shown_raw ? g->text + off : "", nd < 40 ? "" : "...");
    }
    step_out(g);
  }
  *vx = json_object_get_double(x), *vy = json_object_get_double(y);
  if (!isfinite(*vx) || !isfinite(*vy)) { /* (NaN and Infinity were refused: an overflow) */
    step_in(g, NULL, isfinite(*vx) ? 1 : 0);
    return qk__region_fail(g->err, QK_ERR_NONFINITE, f,
                           "feature %zu: coordinate %.60s is beyond the largest double (not "
                           "finite) at %s",
                           f, shown(isfinite(*vx) ? y : x), at_text(w, at, sizeof at));
  }
  const bool zx = *vx == 0 && nonzero_text(x);
  if (zx || (*vy == 0 && nonzero_text(y))) { /* (it read as 0, silently) */
    step_in(g, NULL, zx ? 0 : 1);
    return qk__region_fail(g->err, QK_ERR_GEOMETRY, f,
                           "feature %zu: absurd coordinate %.60s (below the smallest double, "
                           "it reads as 0; magnitude must be 0 or within [1e-100, 1e100]) at %s",
                           f, shown(zx ? x : y), at_text(w, at, sizeof at));
  }
  qk_status_t st = qk__region_check_coord(g->planar, *vx, *vy, f, g->err);
  if (st) {
    size_t len = strlen(g->err->message);
    snprintf(g->err->message + len, sizeof g->err->message - len, " at %s",
             at_text(w, at, sizeof at));
  }
  return st;
}

/* A coordinates array nested one level too shallow or too deep for its type (a Polygon's
 * coordinates given to a MultiPolygon, or the reverse) shows as a ring or a polygon of
 * numbers, or as a ring whose first position holds arrays; read on, it gave "ring 0: 2
 * positions (a ring needs at least 4)". `where` names the ring or polygon, e0 is its
 * first element, deep says which way. */
static qk_status_t wrong_depth(gj_t *g, size_t f, const char *where, const char *ty,
                               json_object *e0, bool deep) {
  const char *s = shown(e0);
  return qk__region_fail(
      g->err, QK_ERR_PARSE, f,
      "feature %zu, %s: the coordinates array has the wrong depth for a %s "
      "(nested too %s): expected positions as arrays of numbers, [x, y], "
      "found %s %.40s%s (a %s's coordinates are %s)",
      f, where, ty, deep ? "deep" : "shallow", deep ? "an array of arrays" : "a number", s,
      strlen(s) > 40 ? "..." : "", ty,
      strcmp(ty, "Polygon") ? "[[[[x, y], ...], ...], ...]" : "[[[x, y], ...], ...]");
}

static qk_status_t ring(gj_t *g, json_object *arr, const char *ty, size_t f, size_t poly,
                        size_t k) {
  if (!json_object_is_type(arr, json_type_array))
    return qk__region_fail(g->err, QK_ERR_PARSE, f,
                           "feature %zu, polygon %zu, ring %zu: expected an array of positions, "
                           "found %s",
                           f, poly, k, type_name(arr));
  size_t n = json_object_array_length(arr);
  json_object *e0 = n ? json_object_array_get_idx(arr, 0) : NULL;
  bool shallow = e0 && is_number(e0);
  if (shallow || (json_object_is_type(e0, json_type_array) && json_object_array_length(e0) &&
                  json_object_is_type(json_object_array_get_idx(e0, 0), json_type_array))) {
    char where[64];
    snprintf(where, sizeof where, "polygon %zu, ring %zu", poly, k);
    return wrong_depth(g, f, where, ty, e0, !shallow);
  }
  if (n < 4)
    return qk__region_fail(g->err, QK_ERR_GEOMETRY, f,
                           "feature %zu, polygon %zu, ring %zu: %zu positions (a ring needs at "
                           "least 4)",
                           f, poly, k, n);
  qk_status_t st;
  if ((st = qk__rings_reserve(g->a, &g->rg, n))) return nomem(g, st);
  for (size_t i = 0; i < n; i++) {
    const gj_at_t w = {"polygon", poly, k, i};
    step_in(g, NULL, i);
    double *v = g->rg.xy + 2 * (g->rg.nv + i);
    if ((st = position(g, json_object_array_get_idx(arr, i), f, &w, &v[0], &v[1]))) return st;
    step_out(g);
  }
  const double *s = g->rg.xy + 2 * g->rg.nv, *e = g->rg.xy + 2 * (g->rg.nv + n - 1);
  if (s[0] != e[0] || s[1] != e[1])
    return qk__region_fail(g->err, QK_ERR_GEOMETRY, f,
                           "feature %zu, polygon %zu, ring %zu: not closed (first position "
                           "[%.17g, %.17g], last [%.17g, %.17g])",
                           f, poly, k, s[0], s[1], e[0], e[1]);
  qk__rings_close(&g->rg, n, k);
  return QK_OK;
}

static qk_status_t polygon(gj_t *g, json_object *rings, const char *ty, size_t f, size_t poly) {
  if (!json_object_is_type(rings, json_type_array))
    return qk__region_fail(g->err, QK_ERR_PARSE, f,
                           "feature %zu, polygon %zu: expected an array of rings, found %s", f,
                           poly, type_name(rings));
  size_t n = json_object_array_length(rings);
  if (n && is_number(json_object_array_get_idx(rings, 0))) {
    char where[32];
    snprintf(where, sizeof where, "polygon %zu", poly);
    return wrong_depth(g, f, where, ty, json_object_array_get_idx(rings, 0), false);
  }
  for (size_t k = 0; k < n; k++) {
    step_in(g, NULL, k);
    qk_status_t st = ring(g, json_object_array_get_idx(rings, k), ty, f, poly, k);
    if (st) return st;
    step_out(g);
  }
  return QK_OK;
}

/* RFC 7946's geometry types without area: skipped and counted. Any other "type" (a typo
 * such as "polygon" or "Polgon") is an error, not a silent skip. */
static bool other_geometry(const char *ty) {
  static const char *const names[] = {"Point", "MultiPoint", "LineString", "MultiLineString"};
  for (size_t i = 0; i < sizeof names / sizeof *names; i++)
    if (!strcmp(ty, names[i])) return true;
  return false;
}

/* A geometry's "coordinates" array into *c, the path stepped into it; or the error. */
static qk_status_t coordinates_of(gj_t *g, json_object *geom, const char *ty, size_t f,
                                  json_object **c) {
  if (!json_object_object_get_ex(geom, "coordinates", c))
    return qk__region_fail(g->err, QK_ERR_PARSE, f,
                           "feature %zu: %s without a \"coordinates\" array", f, ty);
  step_in(g, "coordinates", 0);
  if (!json_object_is_type(*c, json_type_array))
    return qk__region_fail(g->err, QK_ERR_PARSE, f,
                           "feature %zu: %s \"coordinates\" must be an array, found %s", f, ty,
                           type_name(*c));
  return QK_OK;
}

/* A geometry without area (other_geometry): nothing of it is kept, but its coordinates are
 * read as a polygon's are, so that a malformed one is an error at its place, not a silent
 * skip ({"type": "Point", "coordinates": "x"}, a LineString at 1e400 went through where the
 * same in a Polygon was refused). An empty coordinates array is an empty geometry (RFC
 * 7946, 3.1). */
static qk_status_t no_area(gj_t *g, json_object *geom, const char *ty, size_t f) {
  json_object *c = NULL;
  qk_status_t cst = coordinates_of(g, geom, ty, f, &c);
  if (cst) return cst;
  const bool point = !strcmp(ty, "Point"), lines = !strcmp(ty, "MultiLineString");
  double x, y;
  qk_status_t st = QK_OK;
  if (point) {
    const gj_at_t w = {"Point", 0, 0, 0};
    if (json_object_array_length(c)) st = position(g, c, f, &w, &x, &y);
  } else {
    for (size_t l = 0, nl = json_object_array_length(c); l < nl && !st; l++) {
      json_object *e = json_object_array_get_idx(c, l);
      step_in(g, NULL, l);
      if (!lines) {
        const gj_at_t w = {ty, l, 0, 0};
        st = position(g, e, f, &w, &x, &y);
      } else if (!json_object_is_type(e, json_type_array)) {
        st = qk__region_fail(g->err, QK_ERR_PARSE, f,
                             "feature %zu, MultiLineString line %zu: expected an array of "
                             "positions, found %s",
                             f, l, type_name(e));
      }
      for (size_t i = 0, n = lines && !st ? json_object_array_length(e) : 0; i < n && !st; i++) {
        const gj_at_t w = {"MultiLineString", l, i, 0};
        step_in(g, NULL, i);
        st = position(g, json_object_array_get_idx(e, i), f, &w, &x, &y);
        if (!st) step_out(g);
      }
      if (!st) step_out(g);
    }
  }
  if (!st) step_out(g);
  return st;
}

/* The rings of one geometry into g->rg; *poly numbers its polygons within the feature.
 * A GeometryCollection gives the polygons of its members, in order (members without
 * area add nothing). */
static qk_status_t geometry_rings(gj_t *g, json_object *geom, size_t f, size_t *poly) {
  json_object *t = NULL, *c = NULL;
  if (!json_object_is_type(geom, json_type_object) ||
      !json_object_object_get_ex(geom, "type", &t) || !json_object_is_type(t, json_type_string))
    return qk__region_fail(g->err, QK_ERR_PARSE, f,
                           "feature %zu: geometry must be an object with a string \"type\"", f);
  const char *ty = json_object_get_string(t);
  if (!strcmp(ty, "GeometryCollection")) {
    if (!json_object_object_get_ex(geom, "geometries", &c) ||
        !json_object_is_type(c, json_type_array))
      return qk__region_fail(g->err, QK_ERR_PARSE, f,
                             "feature %zu: GeometryCollection without a \"geometries\" array", f);
    step_in(g, "geometries", 0);
    for (size_t i = 0, n = json_object_array_length(c); i < n; i++) {
      step_in(g, NULL, i);
      qk_status_t st = geometry_rings(g, json_object_array_get_idx(c, i), f, poly);
      if (st) return st;
      step_out(g);
    }
    step_out(g);
    return QK_OK;
  }
  bool one = !strcmp(ty, "Polygon"), multi = !strcmp(ty, "MultiPolygon");
  if (!one && !multi) {
    if (!other_geometry(ty))
      return qk__region_fail(g->err, QK_ERR_PARSE, f,
                             "feature %zu: unknown geometry type \"%.60s\" (RFC 7946: Polygon, "
                             "MultiPolygon, Point, ...; names are case-sensitive)",
                             f, ty);
    return no_area(g, geom, ty, f);
  }
  qk_status_t cst = coordinates_of(g, geom, ty, f, &c);
  if (cst) return cst;
  qk_status_t st = QK_OK;
  if (one) {
    st = polygon(g, c, ty, f, (*poly)++);
  } else {
    for (size_t i = 0, n = json_object_array_length(c); i < n && !st; i++) {
      step_in(g, NULL, i);
      st = polygon(g, json_object_array_get_idx(c, i), ty, f, (*poly)++);
      if (!st) step_out(g);
    }
  }
  if (!st) step_out(g);
  return st;
}

/* A feature's geometry (NULL: none); a feature left without rings counts as skipped. */
static qk_status_t geometry(gj_t *g, json_object *geom, size_t f) {
  size_t r0 = g->rg.nr, poly = 0;
  qk_status_t st = geom ? geometry_rings(g, geom, f, &poly) : QK_OK;
  if (!st && g->rg.nr == r0) g->rg.skipped++; /* no area: a Point, null, empty, ... */
  return st;
}

static qk_status_t properties(gj_t *g, json_object *props, size_t f) {
  if (props && json_object_is_type(props, json_type_object)) {
    struct json_object_iterator it = json_object_iter_begin(props);
    struct json_object_iterator end = json_object_iter_end(props);
    for (; !json_object_iter_equal(&it, &end); json_object_iter_next(&it)) {
      const char *k = json_object_iter_peek_name(&it);
      json_object *v = json_object_iter_peek_value(&it);
      const char *s = "";
      size_t len = 0;
      if (json_object_is_type(v, json_type_string)) {
        s = json_object_get_string(v);
        len = (size_t)json_object_get_string_len(v);
        /* "\u0000" in a value: a property is a C string, which would end there and drop
         * the rest without a word (join's output, qk_region_property). */
        if (memchr(s, '\0', len)) {
          snprintf(g->key, sizeof g->key, "%s", k); /* (a longer one: the properties) */
          step_in(g, "properties", 0);
          step_in(g, g->key, 0);
          return qk__region_fail(g->err, QK_ERR_PARSE, f,
                                 "feature %zu: property \"%.60s\" holds a NUL character "
                                 "(\\u0000), which a property value cannot keep",
                                 f, k);
        }
      } else if (v) {
        s = json_object_to_json_string_ext(v, JSON_C_TO_STRING_PLAIN);
        if (!s) return nomem(g, QK_ERR_NOMEM); /* json-c's malloc failed */
        len = strlen(s);
        if (clamped_text(s)) {
          /* An integer beyond 64 bits (an id such as 123456789012345678901234) as written,
           * not as json-c clamped it; it refused the whole file before. */
          size_t off, end;
          snprintf(g->key, sizeof g->key, "%s", k);
          step_in(g, "properties", 0);
          step_in(g, g->key, 0);
          if (strlen(k) >= sizeof g->key || !raw(g, false, &off, &end))
            return qk__region_fail(g->err, QK_ERR_PARSE, f,
                                   "feature %zu: property \"%.60s\" holds an integer beyond "
                                   "64 bits that cannot be read exactly here",
                                   f, k);
          step_out(g), step_out(g);
          s = g->text + off, len = end - off;
        }
      }
      qk_status_t st = qk__props_add(g->a, &g->rg.props, k, s, len);
      if (st) return nomem(g, st);
    }
  } else if (props) {
    step_in(g, "properties", 0);
    return qk__region_fail(g->err, QK_ERR_PARSE, f,
                           "feature %zu: \"properties\" must be an object or null, found %s", f,
                           type_name(props));
  }
  qk_status_t st = qk__props_end_feature(g->a, &g->rg.props, f);
  return st ? nomem(g, st) : QK_OK;
}

/* The next feature ends (its properties ended already). */
static qk_status_t end_feature(gj_t *g) {
  qk_status_t st = qk__rings_end_feature(g->a, &g->rg);
  return st ? nomem(g, st) : QK_OK;
}

static qk_status_t feature(gj_t *g, json_object *feat, size_t f) {
  json_object *t = NULL, *geom = NULL, *props = NULL;
  if (!json_object_is_type(feat, json_type_object) ||
      !json_object_object_get_ex(feat, "type", &t) || !json_object_is_type(t, json_type_string) ||
      strcmp(json_object_get_string(t), "Feature"))
    return qk__region_fail(g->err, QK_ERR_PARSE, f,
                           "feature %zu: expected an object with \"type\": \"Feature\"", f);
  if (!json_object_object_get_ex(feat, "geometry", &geom))
    return qk__region_fail(g->err, QK_ERR_PARSE, f, "feature %zu: no \"geometry\" member", f);
  json_object_object_get_ex(feat, "properties", &props);
  step_in(g, "geometry", 0);
  qk_status_t st = geometry(g, geom, f);
  if (st) return st;
  step_out(g);
  st = properties(g, props, f);
  if (!st) st = end_feature(g);
  return st;
}

static qk_status_t document(gj_t *g, json_object *root) {
  json_object *t = NULL, *feats = NULL;
  if (!json_object_is_type(root, json_type_object) ||
      !json_object_object_get_ex(root, "type", &t) || !json_object_is_type(t, json_type_string))
    return qk__region_fail(g->err, QK_ERR_PARSE, SIZE_MAX,
                           "expected a GeoJSON object with a string \"type\"");
  const char *ty = json_object_get_string(t);
  if (!strcmp(ty, "FeatureCollection")) {
    if (!json_object_object_get_ex(root, "features", &feats) ||
        !json_object_is_type(feats, json_type_array))
      return qk__region_fail(g->err, QK_ERR_PARSE, SIZE_MAX,
                             "FeatureCollection without a \"features\" array");
    size_t n = json_object_array_length(feats);
    step_in(g, "features", 0);
    for (size_t i = 0; i < n; i++) {
      step_in(g, NULL, i);
      qk_status_t st = feature(g, json_object_array_get_idx(feats, i), i);
      if (st) return st;
      step_out(g);
    }
    step_out(g);
    return QK_OK;
  }
  if (!strcmp(ty, "Feature")) return feature(g, root, 0);
  if (strcmp(ty, "Polygon") && strcmp(ty, "MultiPolygon") && strcmp(ty, "GeometryCollection") &&
      !other_geometry(ty))
    return qk__region_fail(g->err, QK_ERR_PARSE, SIZE_MAX,
                           "unknown GeoJSON type \"%.60s\" (expected FeatureCollection, Feature "
                           "or a geometry; names are case-sensitive)",
                           ty);
  qk_status_t st = geometry(g, root, 0);
  if (!st) st = qk__props_end_feature(g->a, &g->rg.props, 0);
  if (!st) st = end_feature(g);
  return st == QK_ERR_NOMEM ? nomem(g, st) : st;
}

/* Line and column (1-based) of a byte offset. */
static void where(const char *text, size_t off, qk_error_t *err) {
  unsigned long line = 1, col = 1;
  for (size_t i = 0; i < off; i++) {
    if (text[i] == '\n')
      line++, col = 1;
    else
      col++;
  }
  if (err) {
    err->line = line;
    err->column = col;
  }
}

/* ---- finding a value in the text by its path (the text is well-formed JSON: json-c
 * parsed it strictly and json_check() found no duplicate names) ---- */

static size_t skip_blanks(const char *t, size_t n, size_t i) {
  while (i < n && (t[i] == ' ' || t[i] == '\t' || t[i] == '\r' || t[i] == '\n')) i++;
  return i;
}

/* The whole text is JSON's null, between blanks. */
static bool is_json_null(const char *t, size_t n) {
  size_t i = skip_blanks(t, n, 0);
  return n - i >= 4 && !memcmp(t + i, "null", 4) && skip_blanks(t, n, i + 4) == n;
}

/* t[i] is a quote: the index after the closing quote (one not escaped by an odd run of
 * backslashes). */
static size_t skip_string(const char *t, size_t n, size_t i) {
  for (size_t b = ++i;;) {
    const char *q = i < n ? memchr(t + i, '"', n - i) : NULL;
    if (!q) return n;
    i = (size_t)(q - t);
    size_t bs = 0;
    while (bs < i - b && t[i - 1 - bs] == '\\') bs++;
    if (bs % 2 == 0) return i + 1;
    i++;
  }
}

/* The index after the value starting at t[i] (blanks skipped before it). Only quotes and
 * brackets matter inside an object or array: the bytes between are skipped by a table
 * (a coordinate array is mostly digits). */
static size_t skip_value(const char *t, size_t n, size_t i) {
  static const unsigned char mark[256] = {['"'] = 1, ['{'] = 1, ['['] = 1, ['}'] = 1, [']'] = 1};
  i = skip_blanks(t, n, i);
  if (i >= n) return n;
  if (t[i] == '"') return skip_string(t, n, i);
  if (t[i] != '{' && t[i] != '[') {
    while (i < n && !strchr(",]} \t\r\n", t[i])) i++;
    return i;
  }
  size_t depth = 0;
  while (i < n) {
    while (i < n && !mark[(unsigned char)t[i]]) i++;
    if (i == n) break;
    char c = t[i];
    if (c == '"') {
      i = skip_string(t, n, i);
      continue;
    }
    if (c == '{' || c == '[') depth++;
    if ((c == '}' || c == ']') && --depth == 0) return i + 1;
    i++;
  }
  return n;
}

/* The offset of the value the path leads to in t[0, n) (the root's when depth is 0), or
 * of the deepest value on the way that was found. A name is compared as written (the
 * reader's names hold no escapes). */
static size_t locate(const char *t, size_t n, const gj_step_t *path, size_t depth) {
  size_t at = skip_blanks(t, n, 0);
  for (size_t d = 0; d < depth && d < GJ_PATH_MAX; d++) {
    const gj_step_t *s = &path[d];
    if (at >= n || t[at] != (s->name ? '{' : '[')) return at;
    size_t i = at + 1, k = 0, found = SIZE_MAX;
    for (;;) {
      i = skip_blanks(t, n, i);
      if (i >= n || t[i] == '}' || t[i] == ']') break;
      size_t v = i;
      if (s->name) { /* "name" : value */
        size_t e = skip_string(t, n, i), len = strlen(s->name);
        int same = e - i == len + 2 && !memcmp(t + i + 1, s->name, len);
        v = skip_blanks(t, n, e);
        v = skip_blanks(t, n, v + (v < n && t[v] == ':'));
        if (same) found = v;
      } else if (k == s->idx) {
        found = v;
      }
      if (found != SIZE_MAX) break;
      i = skip_blanks(t, n, skip_value(t, n, v));
      if (i < n && t[i] == ',') i++;
      k++;
    }
    if (found == SIZE_MAX) return at;
    at = found;
  }
  return at;
}

/* Where a whole JSON value (json-c's lenient syntax) ends in text[0, n), or SIZE_MAX when
 * those bytes do not hold one: tells text after a value from a malformed value. */
static size_t value_end(const char *text, size_t n) {
  if (n > (size_t)INT_MAX) return SIZE_MAX;
  json_tokener *tok = json_tokener_new();
  if (!tok) return SIZE_MAX;
  json_object *v = json_tokener_parse_ex(tok, text, (int)n);
  size_t end = v && json_tokener_get_error(tok) == json_tokener_success
                   ? json_tokener_get_parse_end(tok)
                   : SIZE_MAX;
  json_object_put(v);
  json_tokener_free(tok);
  return end;
}

/* One object member's name: its text[off, off + len) inside the quotes, and a hash. */
typedef struct jkey {
  uint64_t h;
  size_t off, len; /* the name as written: text[off, off + raw); len: its decoded bytes */
  size_t raw;
} jkey_t;

/* The value of the four hexadecimal digits at t (json-c checked them). */
static unsigned long hex4(const char *t) {
  unsigned long u = 0;
  for (int d = 0; d < 4; d++)
    u = u * 16 +
        (unsigned long)(isdigit((unsigned char)t[d]) ? t[d] - '0' : (t[d] | 32) - 'a' + 10);
  return u;
}

/* The next character of the JSON string text[*i, e) (well-formed: json-c parsed it),
 * escapes decoded, as UTF-8 bytes into out; returns how many (0 at the end). */
static size_t jdecode(const char *text, size_t *i, size_t e, unsigned char out[4]) {
  if (*i >= e) return 0;
  unsigned char c = (unsigned char)text[(*i)++];
  if (c != '\\' || *i >= e) return out[0] = c, 1;
  c = (unsigned char)text[(*i)++];
  static const char from[] = "bfnrt", to[] = "\b\f\n\r\t";
  const char *k = c ? strchr(from, c) : NULL;
  if (c != 'u') return out[0] = k ? (unsigned char)to[k - from] : c, 1; /* \" \\ \/ */
  unsigned long u = *i + 4 <= e ? hex4(text + *i) : 0;
  *i = *i + 4 <= e ? *i + 4 : e;
  if (u >= 0xD800 && u < 0xDC00 && *i + 6 <= e && text[*i] == '\\' && text[*i + 1] == 'u') {
    unsigned long lo = hex4(text + *i + 2);
    if (lo >= 0xDC00 && lo < 0xE000) u = 0x10000 + ((u - 0xD800) << 10) + (lo - 0xDC00), *i += 6;
  }
  if (u >= 0xD800 && u < 0xE000) u = 0xFFFD; /* (lone: refused before names are decoded) */
  if (u < 0x80) return out[0] = (unsigned char)u, 1;
  if (u < 0x800)
    return out[0] = (unsigned char)(0xC0 | u >> 6), out[1] = (unsigned char)(0x80 | (u & 63)), 2;
  if (u < 0x10000)
    return out[0] = (unsigned char)(0xE0 | u >> 12), out[1] = (unsigned char)(0x80 | (u >> 6 & 63)),
           out[2] = (unsigned char)(0x80 | (u & 63)), 3;
  return out[0] = (unsigned char)(0xF0 | u >> 18), out[1] = (unsigned char)(0x80 | (u >> 12 & 63)),
         out[2] = (unsigned char)(0x80 | (u >> 6 & 63)), out[3] = (unsigned char)(0x80 | (u & 63)),
         4;
}

/* Whether the string text[b, e), decoded, is lit. */
static bool jname_is(const char *text, size_t b, size_t e, const char *lit) {
  unsigned char c[4];
  size_t m, k = 0;
  while ((m = jdecode(text, &b, e, c)))
    for (size_t q = 0; q < m; q++, k++)
      if (!lit[k] || (unsigned char)lit[k] != c[q]) return false;
  return !lit[k];
}

/* Whether two names, as written, are the same once decoded ("a\u0062" is "ab"). */
static bool jname_equal(const char *text, const jkey_t *a, const jkey_t *b) {
  if (a->len != b->len) return false;
  size_t i = a->off, j = b->off, ni = 0, nj = 0, pi = 0, pj = 0;
  unsigned char x[4], y[4];
  for (;;) {
    if (pi == ni) ni = jdecode(text, &i, a->off + a->raw, x), pi = 0;
    if (pj == nj) nj = jdecode(text, &j, b->off + b->raw, y), pj = 0;
    if (!ni || !nj) return !ni && !nj;
    if (x[pi++] != y[pj++]) return false;
  }
}

static int jkey_cmp(const void *x, const void *y) {
  const jkey_t *a = x, *b = y;
  if (a->h != b->h) return a->h < b->h ? -1 : 1;
  if (a->len != b->len) return a->len < b->len ? -1 : 1;
  return (a->off > b->off) - (a->off < b->off);
}

/* The object whose names are k[0, n) closed: the offset of the later of the first pair of
 * equal names (escapes decoded: "coordinate\u0073" is "coordinates", which json-c keeps
 * instead of the first), or SIZE_MAX; *first: the earlier one. */
static size_t duplicate(const char *text, jkey_t *k, size_t n, size_t *first) {
  size_t dup = SIZE_MAX;
  if (n < 2) return dup;
  qsort(k, n, sizeof *k, jkey_cmp);
  for (size_t i = 0; i < n; i++)
    for (size_t j = i + 1; j < n && k[j].h == k[i].h && k[j].len == k[i].len; j++)
      if (jname_equal(text, &k[i], &k[j])) {
        if (k[j].off < dup) dup = k[j].off, *first = k[i].off;
        break; /* (sorted by offset: later equal names come after k[j]) */
      }
  return dup;
}

/* The offset of the first byte of the string text[b, e) that RFC 8259 forbids there,
 * or SIZE_MAX: a control character (U+0000 to U+001F must be escaped), or a byte that
 * does not belong to well-formed UTF-8 (RFC 3629: no overlong forms, no surrogates,
 * nothing past U+10FFFF). json-c's strict mode passes both into names and values. */
static size_t string_bytes(const char *text, size_t b, size_t e) {
  const unsigned char *s = (const unsigned char *)text;
  for (size_t i = b; i < e;) {
    unsigned c = s[i];
    if (c >= 0x20 && c < 0x80) {
      i++;
      continue;
    }
    if (c < 0x20) return i;
    /* the sequence's length and the range of its second byte */
    size_t n;
    unsigned lo = 0x80, hi = 0xBF;
    if (c >= 0xC2 && c <= 0xDF)
      n = 2;
    else if (c >= 0xE0 && c <= 0xEF)
      n = 3, lo = c == 0xE0 ? 0xA0 : 0x80, hi = c == 0xED ? 0x9F : 0xBF;
    else if (c >= 0xF0 && c <= 0xF4)
      n = 4, lo = c == 0xF0 ? 0x90 : 0x80, hi = c == 0xF4 ? 0x8F : 0xBF;
    else
      return i;
    if (i + n > e) return i;
    /* a byte that continues no sequence: the sequence is cut short, at its lead byte;
     * a continuation byte out of range: an overlong form, a surrogate or past U+10FFFF */
    for (size_t k = 1; k < n; k++)
      if (s[i + k] < 0x80 || s[i + k] > 0xBF) return i;
    if (s[i + 1] < lo || s[i + 1] > hi) return i + 1;
    i += n;
  }
  return SIZE_MAX;
}

/* The offset of the first escape in the string text[b, e) (json-c parsed it: escapes are
 * well-formed) that writes half of a surrogate pair alone, or SIZE_MAX: \uD800 to \uDBFF
 * not followed by \uDC00 to \uDFFF, or one of the latter not after one of the former.
 * json-c reads it as U+FFFD without a word; RFC 8259 leaves such strings to the parser,
 * I-JSON (RFC 7493, 2.1) forbids them, as the raw bytes of a surrogate are refused. */
static size_t lone_surrogate(const char *text, size_t b, size_t e) {
  for (const char *q; b < e && (q = memchr(text + b, '\\', e - b));) {
    size_t i = (size_t)(q - text);
    if (i + 6 > e || text[i + 1] != 'u') { /* \" \\ \/ \b ... (two bytes) */
      b = i + 2;
      continue;
    }
    unsigned long u = hex4(text + i + 2);
    if (u >= 0xDC00 && u < 0xE000) return i;
    b = i + 6;
    if (u < 0xD800 || u >= 0xDC00) continue;
    if (i + 12 > e || text[i + 6] != '\\' || text[i + 7] != 'u') return i;
    unsigned long lo = hex4(text + i + 8);
    if (lo < 0xDC00 || lo >= 0xE000) return i;
    b = i + 12;
  }
  return SIZE_MAX;
}

/* What json-c's strict mode lets through but RFC 8259 does not, in a text it parsed: the
 * words NaN and Infinity, raw control characters and bytes that are not UTF-8 in strings, a decimal
 * point without digits after it ("1."), and a name twice in one object (RFC 8259 leaves the meaning
 * to the parser; json-c, like GDAL and Python, keeps the last, so a second "coordinates" silently
 * replaced the first). QK_OK, or a parse error at the offending byte. */
static qk_status_t json_check(const qk_allocator_t *a, const char *text, size_t len,
                              qk_error_t *err) {
  enum { MAX_DEPTH = 512 }; /* (json-c parses 32 levels at most by default) */
  size_t base[MAX_DEPTH];   /* per open object its first name in keys; SIZE_MAX: an array */
  size_t depth = 0, n = 0, cap = 0;
  jkey_t *keys = NULL;
  qk_status_t st = QK_OK;
  int after_type = 0; /* the last string was the name "type" */
  /* the bytes that matter (the rest, mostly commas, blanks and letters, are skipped) */
  static const unsigned char special[256] = {
      ['"'] = 1, ['{'] = 1, ['['] = 1, ['}'] = 1, [']'] = 1, ['N'] = 1, ['I'] = 1,
      ['.'] = 1, ['-'] = 1, ['0'] = 1, ['1'] = 1, ['2'] = 1, ['3'] = 1, ['4'] = 1,
      ['5'] = 1, ['6'] = 1, ['7'] = 1, ['8'] = 1, ['9'] = 1};
  for (size_t i = 0; i < len && !st; i++) {
    while (i < len && !special[(unsigned char)text[i]]) i++;
    if (i == len) break;
    char c = text[i];
    if (c == '"') {
      size_t b = ++i;
      for (;;) { /* the closing quote: one not escaped by an odd run of backslashes */
        const char *q = memchr(text + i, '"', len - i);
        i = q ? (size_t)(q - text) : len;
        size_t bs = 0;
        while (bs < i - b && text[i - 1 - bs] == '\\') bs++;
        if (!q || bs % 2 == 0) break;
        i++;
      }
      size_t e = i, j = i + 1;
      size_t bad = string_bytes(text, b, e);
      if (bad != SIZE_MAX) {
        unsigned char x = (unsigned char)text[bad];
        where(text, bad, err);
        st = x < 0x20 ? qk__region_fail(err, QK_ERR_PARSE, SIZE_MAX,
                                        "malformed JSON: control character U+%04X inside a string "
                                        "(RFC 8259: write it as an escape, \\u%04X)",
                                        x, x)
                      : qk__region_fail(err, QK_ERR_PARSE, SIZE_MAX,
                                        "malformed JSON: byte 0x%02X inside a string is not UTF-8 "
                                        "(RFC 8259 texts are UTF-8)",
                                        x);
        break;
      }
      if ((bad = lone_surrogate(text, b, e)) != SIZE_MAX) {
        where(text, bad, err);
        st = qk__region_fail(err, QK_ERR_PARSE, SIZE_MAX,
                             "malformed JSON: \\u%.4s inside a string is half of a surrogate "
                             "pair, alone (I-JSON, RFC 7493: strings hold Unicode characters; "
                             "write the pair, or the character itself)",
                             text + bad + 2);
        break;
      }
      while (j < len && (text[j] == ' ' || text[j] == '\n' || text[j] == '\r' || text[j] == '\t'))
        j++;
      int name = j < len && text[j] == ':';
      /* A name and a "type" value, decoded: a NUL in one (json-c keeps names as C strings,
       * so "coordinates\u0000" became a second "coordinates" past the duplicate test and
       * replaced the polygon; "Polygon\u0000z" read as "Polygon"; property values are
       * refused with their feature, below), the name "type" however written, and the
       * decoded name's hash and length for the duplicate test. */
      uint64_t h = 1469598103934665603u; /* (FNV-1a) */
      size_t dlen = 0, z = SIZE_MAX;
      if (name || after_type) {
        unsigned char out[4];
        for (size_t k = b, at = k, m; (m = jdecode(text, &k, e, out)); at = k)
          for (size_t q = 0; q < m; q++, dlen++) {
            h = (h ^ out[q]) * 1099511628211u;
            if (!out[q] && z == SIZE_MAX) z = at;
          }
      }
      if (z != SIZE_MAX) {
        where(text, z, err);
        st = qk__region_fail(err, QK_ERR_PARSE, SIZE_MAX,
                             "%s holds a NUL character (\\u0000), which the reader cannot keep",
                             name ? "a member name" : "a \"type\" value");
        break;
      }
      jkey_t key = {h, b, dlen, e - b};
      after_type = name && dlen == 4 && jname_is(text, b, e, "type");
      if (name && depth && base[depth - 1] != SIZE_MAX) {
        if (n == cap && (st = qk__grow(a, (void **)&keys, &cap, n + 1, sizeof *keys))) break;
        keys[n++] = key;
      }
    } else if (c == '{' || c == '[') {
      if (depth == MAX_DEPTH) break; /* (deeper than json-c parses: not checked) */
      base[depth++] = c == '{' ? n : SIZE_MAX;
    } else if ((c == '}' || c == ']') && depth) {
      size_t b = base[--depth], first = 0, dup;
      if (b == SIZE_MAX) continue;
      if (n - b >= 2 && (dup = duplicate(text, keys + b, n - b, &first)) != SIZE_MAX) {
        qk_error_t at;
        where(text, first - 1, &at);
        where(text, dup - 1, err);
        size_t nl = 0; /* (the name as written, its first 60 bytes; past escaped quotes) */
        while (dup + nl < len && text[dup + nl] != '"' && nl < 60)
          nl += text[dup + nl] == '\\' && dup + nl + 1 < len ? 2 : 1;
        /* (and the rest of a character cut there: names were checked as UTF-8) */
        while (dup + nl < len && ((unsigned char)text[dup + nl] & 0xC0) == 0x80) nl++;
        st = qk__region_fail(err, QK_ERR_PARSE, SIZE_MAX,
                             "duplicate name \"%.*s\" in one object (first at line %lu, column "
                             "%lu; JSON names must be unique here)",
                             (int)nl, text + dup, at.line, at.column);
      }
      n = b;
    } else if (c == '-' || (c >= '0' && c <= '9')) {
      /* A number, read whole: its decimal point needs digits after it. (An integer
       * beyond 64 bits is dealt with where its value is used: clamped().) */
      size_t j = i + (c == '-');
      while (j < len && text[j] >= '0' && text[j] <= '9') j++;
      if (j < len && text[j] == '.') {
        if (j + 1 >= len || text[j + 1] < '0' || text[j + 1] > '9') {
          where(text, j, err);
          st = qk__region_fail(err, QK_ERR_PARSE, SIZE_MAX,
                               "malformed JSON: a decimal point must be followed by digits");
          break;
        }
        for (j++; j < len && text[j] >= '0' && text[j] <= '9';) j++;
      }
      i = j - 1; /* (the loop steps past the number; an exponent is skipped as plain text) */
    } else if (c == 'N' || c == 'I') {
      where(text, i, err);
      st = qk__region_fail(err, QK_ERR_PARSE, SIZE_MAX,
                           "malformed JSON: %s is not a JSON number (RFC 8259)",
                           c == 'N' ? "NaN" : "Infinity");
    } else if (c == '.' && (i + 1 >= len || text[i + 1] < '0' || text[i + 1] > '9')) {
      where(text, i, err);
      st = qk__region_fail(err, QK_ERR_PARSE, SIZE_MAX,
                           "malformed JSON: a decimal point must be followed by digits");
    }
  }
  qk__free(a, keys, cap * sizeof *keys);
  return st == QK_ERR_NOMEM ? qk__region_fail(err, st, SIZE_MAX, "out of memory") : st;
}

/* text[0, n) parsed strictly by json-c, allowing `depth` levels of nesting: the value,
 * or NULL when those bytes are not exactly one value (blanks around it allowed). */
static json_object *parse_exact(const char *text, size_t n, int depth) {
  while (n && strchr(" \t\r\n", text[n - 1])) n--;
  if (n > (size_t)INT_MAX) return NULL;
  json_tokener *tok = json_tokener_new_ex(depth);
  if (!tok) return NULL;
  json_tokener_set_flags(tok, JSON_TOKENER_STRICT);
  json_object *v = json_tokener_parse_ex(tok, text, (int)n);
  if (v && (json_tokener_get_error(tok) != json_tokener_success ||
            json_tokener_get_parse_end(tok) != n)) {
    json_object_put(v);
    v = NULL;
  }
  json_tokener_free(tok);
  return v;
}

/* A FeatureCollection, one feature at a time. json-c's tree of a whole collection takes
 * some nine times the text (a 41 MB file, ten copies of the countries, took 350 MB of
 * tree besides its text), so the root object is parsed with its "features" array
 * emptied, then each element on its own, walked into the rings before the next is
 * parsed. The elements are found by skip_value(), which is exact on well-formed JSON;
 * each must be exactly one value to json-c (two levels less deep allowed, as it sits two
 * levels down), with one comma between two: then the whole text is JSON that json-c
 * parses into the same values.
 *
 * This path only ever succeeds: QK_OK with *out built, or QK_ERR_NOMEM. Anything else
 * (another layout, a root that is not a FeatureCollection, malformed JSON, an error in a
 * feature) gives QK_ERR_PARSE with nothing built, and the caller reads the text whole as
 * before, which finds and words the error as it always has. */
static qk_status_t read_streamed(const char *text, size_t len, const qk_region_options_t *o,
                                 const qk_allocator_t *a, qk_region_t **out, qk_error_t *err) {
  /* the root object's "features" member (names compared as written), and the spans of
   * its elements: [sp[2k], sp[2k + 1]) */
  size_t i = skip_blanks(text, len, 0), lb = SIZE_MAX, rb = SIZE_MAX, *sp = NULL, ns = 0, cap = 0;
  qk_status_t st = QK_OK;
  if (i >= len || text[i] != '{') return QK_ERR_PARSE;
  for (i = skip_blanks(text, len, i + 1); !st && i < len && text[i] == '"';) {
    size_t e = skip_string(text, len, i);
    if (memchr(text + i, '\\', e - i)) st = QK_ERR_PARSE; /* (json-c decodes escapes) */
    bool features = e - i == 10 && !memcmp(text + i, "\"features\"", 10);
    i = skip_blanks(text, len, e);
    if (i >= len || text[i] != ':') st = QK_ERR_PARSE;
    i = skip_blanks(text, len, i + 1);
    if (!st && features && i < len && text[i] == '[') {
      lb = i, ns = 0; /* (a second "features" is refused later, by json_check) */
      for (i = skip_blanks(text, len, i + 1); i < len && text[i] != ']';) {
        size_t v = i, e = skip_value(text, len, i);
        if ((st = qk__grow(a, (void **)&sp, &cap, ns + 2, sizeof *sp))) break;
        sp[ns++] = v, sp[ns++] = e;
        i = skip_blanks(text, len, e);
        if (i >= len || text[i] != ',') break;
        i = skip_blanks(text, len, i + 1);
      }
      if (!st && (i >= len || text[i] != ']')) st = QK_ERR_PARSE;
      rb = i++;
    } else {
      i = skip_value(text, len, i);
    }
    i = skip_blanks(text, len, i);
    if (i < len && text[i] == ',') i = skip_blanks(text, len, i + 1);
  }
  if (!st && (lb == SIZE_MAX || rb >= len)) st = QK_ERR_PARSE;

  /* the root with "features": [] */
  size_t sn = st ? 0 : len - (rb - lb - 1);
  char *sk = st ? NULL : qk__realloc(a, NULL, 0, sn);
  if (!st && !sk) st = QK_ERR_NOMEM;
  if (!st) {
    memcpy(sk, text, lb + 1);
    memcpy(sk + lb + 1, text + rb, len - rb);
    json_object *root = parse_exact(sk, sn, JSON_TOKENER_DEFAULT_DEPTH), *t = NULL;
    qk__free(a, sk, sn);
    bool collection = root && json_object_is_type(root, json_type_object) &&
                      json_object_object_get_ex(root, "type", &t) &&
                      json_object_is_type(t, json_type_string) &&
                      !strcmp(json_object_get_string(t), "FeatureCollection");
    json_object_put(root);
    if (!collection) st = QK_ERR_PARSE;
  }
  if (!st) st = json_check(a, text, len, err);

  qk_error_t scratch;
  gj_t g;
  memset(&g, 0, sizeof g);
  g.a = a;
  g.planar = o->planar;
  g.err = err ? err : &scratch;
  step_in(&g, "features", 0);
  for (size_t k = 0; !st && k < ns; k += 2) {
    /* (a comma follows every element but the last, which the bracket must follow) */
    size_t e = sp[k + 1];
    bool sep = k + 2 < ns || skip_blanks(text, len, e) == rb;
    json_object *feat =
        sep ? parse_exact(text + sp[k], e - sp[k], JSON_TOKENER_DEFAULT_DEPTH - 2) : NULL;
    if (!feat) {
      st = QK_ERR_PARSE;
      break;
    }
    step_in(&g, NULL, k / 2);
    g.text = text + sp[k], g.len = e - sp[k], g.base = 2; /* (the path's features/k) */
    st = feature(&g, feat, k / 2);
    json_object_put(feat);
    if (!st) step_out(&g);
  }
  qk__free(a, sp, cap * sizeof *sp);
  if (!st) st = qk__rings_build(&g.rg, o, out, err);
  qk__rings_free(g.a, &g.rg);
  if (st == QK_ERR_NOMEM && err && !err->message[0]) /* (the skeleton's or the spans') */
    qk__region_fail(err, st, SIZE_MAX, "out of memory");
  return !st || st == QK_ERR_NOMEM ? st : QK_ERR_PARSE;
}

qk_status_t qk_region_read_geojson_text(const char *text, size_t len,
                                        const qk_region_options_t *options, qk_region_t **out,
                                        qk_error_t *err) {
  if (err) {
    memset(err, 0, sizeof *err);
    err->item = SIZE_MAX;
  }
  if (!out || (!text && len)) return qk__region_fail(err, QK_ERR_INVALID, SIZE_MAX, "no input");
  *out = NULL;
  /* RFC 8259 lets a parser ignore a UTF-8 byte order mark; Windows editors write one. */
  if (len >= 3 && !memcmp(text, "\xEF\xBB\xBF", 3)) text += 3, len -= 3;
  /* A NUL byte is not JSON (json-c would stop there, or take it for a blank after the
   * value): binary data is refused where it is. */
  const char *nul = len ? memchr(text, '\0', len) : NULL;
  if (nul) {
    where(text, (size_t)(nul - text), err);
    return qk__region_fail(err, QK_ERR_PARSE, SIZE_MAX, "binary data (NUL byte) in a text file");
  }
  qk_region_options_t o;
  qk_allocator_t alloc;
  qk__region_options(options, &o, &alloc);
  qk_status_t st = read_streamed(text, len, &o, &alloc, out, err);
  return st != QK_ERR_PARSE ? st : qk__geojson_read_whole(text, len, options, out, err);
}

qk_status_t qk__geojson_read_whole(const char *text, size_t len, const qk_region_options_t *options,
                                   qk_region_t **out, qk_error_t *err) {
  if (err) {
    memset(err, 0, sizeof *err);
    err->item = SIZE_MAX;
  }
  *out = NULL;
  qk_region_options_t o;
  qk_allocator_t alloc;
  qk__region_options(options, &o, &alloc);
  json_tokener *tok = json_tokener_new();
  if (!tok) return qk__region_fail(err, QK_ERR_NOMEM, SIZE_MAX, "out of memory");
  /* RFC 8259 JSON: no trailing commas, no single quotes (json-c accepts both otherwise). */
  json_tokener_set_flags(tok, JSON_TOKENER_STRICT);
  json_object *root = NULL;
  size_t at = 0;
  enum json_tokener_error jerr = json_tokener_continue;
  /* json-c allocates with malloc (it has no allocator hook) and, in the versions Debian
   * ships, reports a failed allocation as a parse error; malloc's ENOMEM tells them
   * apart. */
  errno = 0;
  /* json-c takes an int length: feed large texts in pieces. */
  do {
    size_t chunk = len - at > (1u << 30) ? (1u << 30) : len - at;
    root = json_tokener_parse_ex(tok, text + at, (int)chunk);
    jerr = json_tokener_get_error(tok);
    if (jerr != json_tokener_continue || chunk == 0) {
      at += json_tokener_get_parse_end(tok);
      break;
    }
    at += chunk;
  } while (at < len);
  /* Only a failed parse consults errno: a successful call may leave ENOMEM behind (C allows
   * it, and json-c 0.16 under valgrind does on every document), and the failures json-c
   * absorbs were seen to leave the document whole (docs/region.md). */
  if (!root && jerr == json_tokener_continue && at == len) {
    /* A number or a word at the very end ("42", "null") leaves json-c waiting for more of
     * it: the NUL that ends a C string tells it the text ended. Any other wait is a
     * truncated text, reported below as before. */
    json_object *v = json_tokener_parse_ex(tok, "", 1);
    if (json_tokener_get_error(tok) == json_tokener_success)
      root = v, jerr = json_tokener_success;
    else
      json_object_put(v);
  }
  if (!root && jerr == json_tokener_success && is_json_null(text, len)) {
    /* The document is JSON's null, which json-c gives as no object at all: it was
     * reported as "unexpected end of input" or "malformed JSON: success". json-c gives
     * the same when an allocation fails, so the text itself says which it was. */
    json_tokener_free(tok);
    where(text, skip_blanks(text, len, 0), err);
    return qk__region_fail(err, QK_ERR_PARSE, SIZE_MAX,
                           "expected a GeoJSON object with a string \"type\", found null");
  }
  if (errno == ENOMEM && (!root || jerr != json_tokener_success)) {
    json_object_put(root);
    json_tokener_free(tok);
    return qk__region_fail(err, QK_ERR_NOMEM, SIZE_MAX, "out of memory parsing JSON (json-c)");
  }
  if (!root && jerr == json_tokener_continue) {
    /* the text ended inside a value */
    where(text, len, err);
    json_tokener_free(tok);
    return qk__region_fail(err, QK_ERR_PARSE, SIZE_MAX, "unexpected end of input");
  }
  size_t end = !root && jerr != json_tokener_continue ? value_end(text, at) : SIZE_MAX;
  if (end != SIZE_MAX) {
    /* strict mode stopped after a whole value: text follows it */
    while (end < len && strchr(" \t\r\n", text[end])) end++;
    where(text, end, err);
    json_tokener_free(tok);
    return qk__region_fail(err, QK_ERR_PARSE, SIZE_MAX, "unexpected text after the JSON value");
  }
  if (!root || jerr != json_tokener_success) {
    size_t off = at ? at - 1 : 0;
    /* json-c stops at a character that starts no token, not after it: "  x" and "[1, x]"
     * were placed one column early, at the blank before the x (other errors are placed
     * as before). The reader of a stream, which refuses such a first byte itself, places
     * it at that byte too. */
    if (jerr == json_tokener_error_parse_unexpected && at < len) off = at;
    where(text, off, err);
    qk_status_t st = qk__region_fail(err, QK_ERR_PARSE, SIZE_MAX, "malformed JSON: %s",
                                     json_tokener_error_desc(jerr));
    json_object_put(root);
    json_tokener_free(tok);
    return st;
  }
  json_tokener_free(tok);
  for (size_t i = at; i < len; i++)
    if (!text[i] || !strchr(" \t\r\n", text[i])) {
      where(text, i, err);
      json_object_put(root);
      return qk__region_fail(err, QK_ERR_PARSE, SIZE_MAX, "unexpected text after the JSON value");
    }
  qk_status_t st = json_check(&alloc, text, len, err);
  if (st) {
    json_object_put(root);
    return st;
  }
  qk_error_t scratch;
  gj_t g;
  memset(&g, 0, sizeof g);
  g.a = &alloc;
  g.planar = o.planar;
  g.err = err ? err : &scratch;
  g.text = text, g.len = len, g.base = 0;
  st = document(&g, root); /* json-c's allocations there are checked for NULL */
  json_object_put(root);
  /* An error inside valid JSON (a short ring, a wrong type, a huge coordinate): the line
   * and column of the value the walk stopped at. */
  if (st && st != QK_ERR_NOMEM && err) where(text, locate(text, len, g.path, g.depth), err);
  if (!st) st = qk__rings_build(&g.rg, &o, out, err);
  qk__rings_free(g.a, &g.rg);
  return st;
}

qk_status_t qk_region_find_json_pointer(const char *text, size_t len, const char *pointer,
                                        unsigned long *line, unsigned long *column) {
  char buf[1024];
  size_t n = pointer ? strlen(pointer) : 0;
  if (!text || !pointer || !line || !column || n >= sizeof buf || (n && pointer[0] != '/'))
    return QK_ERR_INVALID;
  if (len >= 3 && !memcmp(text, "\xEF\xBB\xBF", 3)) text += 3, len -= 3;
  /* The tokens, unescaped in place into buf, become the reader's path steps. */
  gj_step_t path[GJ_PATH_MAX];
  size_t depth = 0, w = 0;
  for (size_t i = 0; i < n && depth < GJ_PATH_MAX;) {
    char *tok = buf + w;
    int digits = 1;
    for (i++; i < n && pointer[i] != '/'; i++) {
      char c = pointer[i];
      if (c == '~' && i + 1 < n && (pointer[i + 1] == '0' || pointer[i + 1] == '1'))
        c = pointer[++i] == '0' ? '~' : '/';
      digits &= c >= '0' && c <= '9';
      buf[w++] = c;
    }
    buf[w++] = '\0';
    if (digits && *tok) {
      errno = 0;
      unsigned long long k = strtoull(tok, NULL, 10);
      path[depth++] = (gj_step_t){NULL, errno || k > SIZE_MAX ? SIZE_MAX : (size_t)k};
    } else {
      path[depth++] = (gj_step_t){tok, 0};
    }
  }
  qk_error_t at;
  where(text, locate(text, len, path, depth), &at);
  *line = at.line, *column = at.column;
  return QK_OK;
}

/* The most bytes of text read from a stream (a pipe, a FIFO, a socket, a device: anything
 * but a regular file). A file's size bounds what is read from it, and files of several
 * GiB read as before (a 2.47 GB FeatureCollection: 23 s, 3.5 GB resident); a stream gives
 * no size in advance and may never end (`yes ' ' | quadkit join /dev/stdin ...`), while
 * the reader keeps the whole text (for the positions of its errors). 2^31 - 1 bytes is
 * far beyond a layer sent through a pipe in practice and bounds the memory a runaway
 * writer takes to a few GiB. Not static: the tests lower it (tests/test_geojson_stream.c). */
size_t qk__geojson_stream_max = INT_MAX;

/* Where a GeoJSON text's first value starts in buf[0, len): the first byte after a
 * UTF-8 byte order mark and blanks (from *scan on, which is kept between calls so that
 * blanks are looked at once), or len when only blanks came so far. */
static size_t first_value(const char *buf, size_t len, size_t *scan) {
  if (*scan == 0 && len >= 3 && !memcmp(buf, "\xEF\xBB\xBF", 3)) *scan = 3;
  *scan = skip_blanks(buf, len, *scan);
  return *scan;
}

/* A text whose first value is not an object is refused at that value without reading
 * further: with the wording the whole text's reading gives it (a byte that starts no JSON
 * value is malformed JSON; a value that is not an object is not GeoJSON). */
static qk_status_t not_an_object(const char *buf, size_t at, qk_error_t *err) {
  size_t bom = at >= 3 && !memcmp(buf, "\xEF\xBB\xBF", 3) ? 3 : 0;
  where(buf + bom, at - bom, err);
  if (!strchr("[\"-0123456789tfn", buf[at]) || !buf[at])
    return qk__region_fail(err, QK_ERR_PARSE, SIZE_MAX, "malformed JSON: unexpected character");
  return qk__region_fail(err, QK_ERR_PARSE, SIZE_MAX,
                         "expected a GeoJSON object with a string \"type\"");
}

qk_status_t qk_region_read_geojson(const char *path, const qk_region_options_t *options,
                                   qk_region_t **out, qk_error_t *err) {
  qk_status_t st0 = qk__read_begin(path, out, err);
  if (st0) return st0;
  FILE *f = fopen(path, "rb");
  if (!f)
    return qk__region_fail(err, QK_ERR_IO, SIZE_MAX, "cannot open %s: %s", path, strerror(errno));
  struct stat sb;
  size_t max =
      fstat(fileno(f), &sb) == 0 && S_ISREG(sb.st_mode) ? SIZE_MAX - 1 : qk__geojson_stream_max;
  /* The whole file, through the caller's allocator like every other allocation. */
  qk_region_options_t o;
  qk_allocator_t a;
  qk__region_options(options, &o, &a);
  char *buf = NULL;
  size_t cap = 0, len = 0, scan = 0;
  qk_status_t st = QK_OK;
  bool checked = false, failed = false; /* (failed: err says why) */
  for (;;) {
    /* One byte beyond the limit is read, to tell a text of exactly max bytes from a
     * longer one, and the buffer never grows past that. */
    size_t want = len + (1 << 16) < max + 1 ? len + (1 << 16) : max + 1;
    if ((st = qk__grow(&a, (void **)&buf, &cap, want, 1))) break;
    size_t room = (cap < max + 1 ? cap : max + 1) - len;
    size_t got = fread(buf + len, 1, room, f);
    /* A NUL byte is refused where it is (qk_region_read_geojson_text): reading stops there,
     * so that an endless binary stream (/dev/zero, a pipe from one) fails at once instead
     * of filling memory. */
    const char *nul = got ? memchr(buf + len, '\0', got) : NULL;
    if (nul) {
      len = (size_t)(nul - buf) + 1;
      break;
    }
    len += got;
    if (len > max) {
      failed = true;
      st = qk__region_fail(err, QK_ERR_LIMIT, SIZE_MAX,
                           "GeoJSON text from a pipe or device longer than %zu bytes, the limit "
                           "for a stream (a regular file has none)",
                           max);
      break;
    }
    /* The first value must be an object: anything else is refused at once (an endless
     * `yes x` fails here), unless the text ended within this read: then the whole text's
     * reading words the error as it always has. */
    size_t at = checked ? 0 : first_value(buf, len, &scan);
    if (!checked && at < len) {
      checked = true;
      if (buf[at] != '{' && got == room) {
        failed = true;
        st = not_an_object(buf, at, err);
        break;
      }
    }
    if (got < room) break;
  }
  if (st && !failed)
    st = qk__region_fail(err, st, SIZE_MAX, "out of memory reading %s", path);
  else if (!st && ferror(f))
    st = qk__region_fail(err, QK_ERR_IO, SIZE_MAX, "cannot read %s: %s", path, strerror(errno));
  fclose(f);
  if (!st) st = qk_region_read_geojson_text(buf, len, options, out, err);
  qk__free(&a, buf, cap);
  return st;
}

#else /* no json-c */

qk_status_t qk_region_read_geojson_text(const char *text, size_t len,
                                        const qk_region_options_t *options, qk_region_t **out,
                                        qk_error_t *err) {
  (void)text, (void)len, (void)options;
  if (out) *out = NULL;
  if (err) memset(err, 0, sizeof *err);
  return qk__region_fail(err, QK_ERR_UNSUPPORTED, SIZE_MAX,
                         "built without json-c: install libjson-c-dev and rebuild");
}

qk_status_t qk_region_find_json_pointer(const char *text, size_t len, const char *pointer,
                                        unsigned long *line, unsigned long *column) {
  (void)text, (void)len, (void)pointer, (void)line, (void)column;
  return QK_ERR_UNSUPPORTED;
}

qk_status_t qk_region_read_geojson(const char *path, const qk_region_options_t *options,
                                   qk_region_t **out, qk_error_t *err) {
  (void)path;
  return qk_region_read_geojson_text(NULL, 0, options, out, err);
}

#endif

qk_status_t qk_region_from_arrays(const qk_region_arrays_t *in, const qk_region_options_t *options,
                                  qk_region_t **out, qk_error_t *err) {
  return qk__region_build(in, options, NULL, 0, SIZE_MAX, out, err);
}
