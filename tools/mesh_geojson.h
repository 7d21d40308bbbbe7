/*
 * GeoJSON polygons as a mesh input (tools/mesh_geojson.c), shared by `quadkit mesh`, the
 * mesh tests and the benchmark. The file is read and checked by the region reader
 * (include/quadkit/region.h: line and column for malformed JSON, feature numbers, the
 * properties used to pick a feature); the chosen features' rings become closed chains
 * of segments for qk_poly_from_arrays(). Coordinates may be projected (equirectangular
 * at the mean latitude, in metres) and rounded to a grid; vertices that coincide after
 * that become one vertex, repeated segments one segment, and rings that collapse are
 * dropped — all counted, never silent. Every hole ring gets a hole point strictly inside
 * it and outside every other ring, checked exactly with the region layer's point
 * location.
 */
#ifndef QUADKIT_TOOLS_MESH_GEOJSON_H
#define QUADKIT_TOOLS_MESH_GEOJSON_H

#include <stddef.h>
#include <stdint.h>
#include "quadkit/region.h"

/* What to read. */
typedef struct mg_options {
  long feature;           /* the feature number (0-based, in file order), or -1 */
  const char *field_name; /* with field_value: the first feature whose property matches */
  const char *field_value;
  int project;  /* nonzero: equirectangular projection at the mean latitude, metres */
  double round; /* grid step to round every coordinate to (0: none; MG_ROUND_AUTO: the
                   grid mg_auto_grid() chooses from the coordinates after projection) */
} mg_options_t;

/* mg_options_t.round for `--round auto` (a sentinel, so that the positional initialisers
 * of the tests and the benchmark keep their meaning). */
#define MG_ROUND_AUTO (-1.0)

/* The input for qk_poly_from_arrays, and what happened on the way. */
typedef struct mg_input {
  double *xy;
  size_t nv;
  uint32_t *seg;
  size_t ns;
  double *holes;
  size_t nh;
  /* Rings as vertex chains (for exact area checks): ring r is ring_v[ring_start[r] ..
   * ring_start[r+1]), sign +1 for an outer ring, -1 for a hole. */
  uint32_t *ring_v;
  size_t *ring_start;
  int *ring_sign;
  size_t nr;
  /* Per segment: the feature, the input ring (below) and the position in it that the
   * segment starts from (or lies on, for a segment split at a T-junction). */
  uint32_t *seg_feature, *seg_ring, *seg_point;
  uint32_t *ring_src; /* per ring above: its input ring */
  qk_region_t *rings; /* each ring a feature (planar), when a ring has a hole or two touch */
  /* Input rings (the chosen features', in file order): feature, polygon within the
   * feature and ring within the polygon as the region reader numbers them, and where the
   * ring is in the text: a JSON Pointer at paths + in_path[q]. */
  size_t nin;
  uint32_t *in_feature, *in_poly, *in_ring;
  size_t *in_path;
  char *paths;
  size_t pole_ring; /* an input ring that goes round a pole as lon/lat, or SIZE_MAX */
  int pole_south;
  size_t features;          /* features that gave rings */
  size_t points;            /* ring points read (closing points not counted) */
  size_t rounded;           /* coordinates changed by rounding */
  double round;             /* the grid rounded to (0: none): o->round, or the auto grid */
  int round_exp;            /* MG_ROUND_AUTO: the grid is 2^round_exp ... */
  int round_mag, round_ext; /* ... chosen from these (mg_auto_grid) */
  size_t merged;            /* ring points that became an existing vertex */
  size_t dropped_rings;     /* rings with fewer than 3 distinct points left */
  size_t unused_points;     /* vertices left only by dropped rings (removed) */
  size_t dup_segments;      /* segments given twice */
  size_t split_points;      /* vertices inserted into axis-parallel ring edges they lay on */
  size_t filled_holes;      /* hole rings another ring fills exactly (no hole point) */
  double lat0;              /* the projection's latitude (degrees) */
  char name[128];           /* the feature's name (NAME / name / ADMIN), or "" */
  size_t field_matches;     /* --field: how many features match (the first is meshed) */
  long field_pick;          /* --field: the feature meshed */
} mg_input_t;

/*
 * `--round auto`: the exponent k of the grid 2^k for the n points xy (x, y pairs, finite).
 * *mag and *ext receive M and W with every |coordinate| < 2^M and the larger side of the
 * bounding box < 2^W; k = ceil((M + W - 52) / 2), kept in [-996, 1000] (the range
 * --round takes).
 *
 * Why: the general mode splits a segment only at a + (j / 2^m)(b - a) computed exactly
 * (mesh/general_points.c, qk__seg_budget): with both ends multiples of 2^k and below 2^M,
 * every such point is an exact double for m <= 52 - (M - k). A segment's coordinate
 * differences are below 2^W, so splits at steps of the grid itself (pieces down to 2^k,
 * m = W - k) are exact when 52 - M + k >= W - k, i.e. 2k >= M + W - 52; k is the finest
 * grid with that property. Rounding moves a vertex by at most 2^(k-1), at most
 * 2^(k-W) of the extent: 2^-26 of it when the input lies about the origin (M = W), a
 * factor 2 more for each factor 4 that the coordinates' magnitude exceeds the extent
 * (Norway in metres: 2^-24). The input's own detail after rounding (distances between
 * distinct vertices) is at least the grid step, so splits down to the grid step are what
 * its features need; deeper splits (a vertex nearer than 2^k to a segment, the descent
 * into a small input angle) may still be refused, naming the segment, as without --round.
 * No points (n = 0) or only zeros: k = 0.
 */
int mg_auto_grid(const double *xy, size_t n, int *mag, int *ext);

/*
 * Read path. Returns 0, or 1 (bad input) / 3 (out of memory, internal) with a message
 * naming the file, line or feature in msg.
 */
int mg_read(const char *path, const mg_options_t *o, mg_input_t *out, char *msg, size_t msg_size);

void mg_free(mg_input_t *in);

/* Whether two rings (or a ring and itself) share a vertex. */
int mg_rings_touch(const mg_input_t *in);

/*
 * Which of the n points pts (x, y pairs) lie inside none of in's rings, boundaries
 * included: out[i] = 1 for those (all 0 when no ring has a hole or touches another: then
 * there is no such face). A bounded face of the mesh there (a gap that features touching
 * all round it enclose) is outside the area. Located in the layer mg_read kept (rings).
 * Returns 0.
 */
int mg_outside_rings(const mg_input_t *in, const double *pts, size_t n, unsigned char *out);

/* Describe input segment s as "feature F, polygon P, ring R, position I" into buf, and
 * where that position is in the file path: *line and *col (0 when unknown). */
void mg_describe_segment(const mg_input_t *in, const char *path, size_t s, char *buf, size_t n,
                         unsigned long *line, unsigned long *col);
/* Describe input ring q ("feature F, polygon P, ring R", with ", position I" unless pos
 * is SIZE_MAX) into buf, and its JSON Pointer into ptr. */
void mg_describe_ring(const mg_input_t *in, size_t q, size_t pos, char *buf, size_t n, char *ptr,
                      size_t np);
/* The line and column of the value at a JSON Pointer in the GeoJSON file path (the file
 * read again; 0 and 0 when that fails). */
void mg_locate(const char *path, const char *pointer, unsigned long *line, unsigned long *col);
/* "path:line:col" of the value at a JSON Pointer, or "path" when unknown, into buf. */
void mg_place(const char *path, const char *pointer, char *buf, size_t n);
/* A parenthesised note naming the input ring that goes round a pole, with what to do
 * (in buf), or "" when there is none. */
const char *mg_pole_note(const mg_input_t *in, char *buf, size_t n);

#endif
