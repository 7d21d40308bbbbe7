/**
 * \file region.h
 * \brief Polygon layers and point location: which feature (country, county, zone) holds
 *        each point. Readers for GeoJSON (json-c) and, when built with GDAL, every OGR
 *        format; an array API; exact point-in-polygon answers from an edge quadtree.
 *
 * A layer is a list of features; a feature is a set of closed rings. A point is inside a
 * feature when a ray from it crosses the feature's rings an odd number of times (even-odd
 * over all the feature's rings: holes of either winding, overlapping parts and
 * self-intersecting rings included). Three boundary rules (qk_boundary_t) decide the
 * points on the rings. Every predicate is exact for double input, so no answer depends on
 * rounding. In lon/lat mode (the default) edges are straight in lon/lat, an edge whose
 * longitudes differ by more than 180 degrees crosses the antimeridian the short way and a
 * ring that winds around the globe encloses a pole; see docs/region.md.
 *
 * Thread safety: a layer never changes once built, so any number of threads may query
 * one layer at once.
 *
 * Numbers as text (GeoJSON through json-c, the SVG writer, error messages) follow the C
 * locale whatever locale the program or the calling thread set (setlocale, uselocale).
 */
#ifndef QUADKIT_REGION_H
#define QUADKIT_REGION_H

#include <stdio.h>

#include "quadkit/common.h"
#include "quadkit/index.h"

#ifdef __cplusplus
extern "C" {
#endif

/** A polygon layer with its point-location index (opaque). */
typedef struct qk_region qk_region_t;

/** How points on a feature's rings are decided. */
typedef enum qk_boundary {
  /** Default. A boundary point belongs to the feature found just above and to the right
   *  of it (the point moved by (e, e^2) for an infinitesimal e): in a coverage of features
   *  sharing edges every point of the plane belongs to exactly one feature. */
  QK_BOUNDARY_SEMI_OPEN = 0,
  /** A point on any ring of a feature is inside it (GEOS covers / intersects). */
  QK_BOUNDARY_CLOSED = 1,
  /** A point on any ring of a feature is outside it (GEOS contains). */
  QK_BOUNDARY_OPEN = 2
} qk_boundary_t;

/** Options for building a layer; initialise with qk_region_options_init(). */
typedef struct qk_region_options {
  /** Zero (default): coordinates are longitude, latitude in degrees (RFC 7946), with
   *  antimeridian and pole handling. Nonzero: plain planar coordinates. */
  int planar;
  /** A cell of the index splits while more than this many edge pieces cross it; 0 means
   *  QK_REGION_DEFAULT_LEAF_EDGES. */
  uint32_t leaf_edges;
  /** Deepest cell; 0 means QK_REGION_DEFAULT_MAX_DEPTH; at most QK_MAX_DEPTH_LIMIT. */
  uint32_t max_depth;
  /** Allocator for everything the layer owns; NULL means libc. Copied. */
  const qk_allocator_t *allocator;
  /** Nonzero: refine the index on a quadkit tree and keep it (qk_region_tree()); zero
   *  (default): the same cells go straight into the query arrays, with no tree (a faster
   *  build and half the memory). The answers are the same either way. */
  int keep_tree;
} qk_region_options_t;

/** Default split threshold: edge pieces per leaf. */
#define QK_REGION_DEFAULT_LEAF_EDGES 8
/** Default depth cap of the index. */
#define QK_REGION_DEFAULT_MAX_DEPTH 26
/** Largest accepted coordinate magnitude (planar mode). */
#define QK_REGION_MAX_COORD 1e100
/** Smallest accepted nonzero coordinate magnitude (keeps the exact predicates exact). */
#define QK_REGION_MIN_COORD 1e-100

/**
 * Fill options with the defaults (lon/lat, default split threshold and depth cap, libc).
 * \param [out] options the options to initialise.
 */
void qk_region_options_init(qk_region_options_t *options);

/**
 * Polygons given as arrays. Vertex v is (xy[2v], xy[2v+1]); ring r is the vertices
 * [ring_start[r], ring_start[r+1]), closed (its last vertex equals its first) and of at
 * least 4 vertices; feature f is the rings [feature_start[f], feature_start[f+1]).
 */
typedef struct qk_region_arrays {
  const double *xy;            /**< 2 * ring_start[n_rings] coordinates */
  const size_t *ring_start;    /**< n_rings + 1 offsets into the vertices, ring_start[0] == 0 */
  size_t n_rings;              /**< number of rings */
  const size_t *feature_start; /**< n_features + 1 offsets into the rings */
  size_t n_features;           /**< number of features */
} qk_region_arrays_t;

/**
 * Build a layer from arrays.
 * \param [in] in the polygons; copied, the caller keeps ownership.
 * \param [in] options NULL for defaults.
 * \param [out] out the new layer, freed with qk_region_free(); NULL on error.
 * \param [out] err where and why the input was rejected (item = feature); may be NULL.
 * \return QK_OK, QK_ERR_INVALID (bad offsets or options), QK_ERR_NONFINITE,
 *         QK_ERR_GEOMETRY (short or unclosed ring, coordinate out of range, a layer whose
 *         extent is below 1e-60: docs/region.md), QK_ERR_LIMIT or QK_ERR_NOMEM. Nothing
 *         is built on error.
 */
qk_status_t qk_region_from_arrays(const qk_region_arrays_t *in, const qk_region_options_t *options,
                                  qk_region_t **out, qk_error_t *err);

/**
 * Read a GeoJSON file (RFC 7946): a FeatureCollection, a Feature or a bare geometry.
 * Feature i is the file's feature i. Polygon and MultiPolygon geometries (and the polygons
 * of a GeometryCollection) give its rings; a feature left without rings (a Point, null or
 * empty geometry) stays empty and is counted as skipped in the stats. Properties are kept
 * (qk_region_property()). The syntax is strict RFC 8259 (no trailing commas; a NUL byte is
 * an error). A path that is not a regular file (a pipe, a FIFO, a device: /dev/stdin) is
 * read to at most 2^31 - 1 bytes (QK_ERR_LIMIT past that, as soon as it is passed), and a
 * text whose first value is not an object is refused there, before more is read; a regular
 * file has no size limit.
 * \param [in] path the file.
 * \param [in] options NULL for defaults (lon/lat).
 * \param [out] out the new layer, freed with qk_region_free(); NULL on error.
 * \param [out] err line and column (of the JSON error, or of the offending value inside
 *        valid JSON), feature index and reason; may be NULL.
 * \return QK_OK, QK_ERR_IO, QK_ERR_PARSE, QK_ERR_GEOMETRY, QK_ERR_NONFINITE, QK_ERR_LIMIT,
 *         QK_ERR_NOMEM, or QK_ERR_UNSUPPORTED when built without json-c.
 */
qk_status_t qk_region_read_geojson(const char *path, const qk_region_options_t *options,
                                   qk_region_t **out, qk_error_t *err);

/**
 * As qk_region_read_geojson(), from a buffer.
 * \param [in] text the JSON text (need not be NUL-terminated).
 * \param [in] len its length in bytes.
 * \param [in] options NULL for defaults.
 * \param [out] out the new layer; NULL on error.
 * \param [out] err may be NULL.
 * \return as qk_region_read_geojson() (never QK_ERR_IO).
 */
qk_status_t qk_region_read_geojson_text(const char *text, size_t len,
                                        const qk_region_options_t *options, qk_region_t **out,
                                        qk_error_t *err);

/**
 * Where a value is in a GeoJSON text: the line and column (1-based, counted in bytes, after
 * a UTF-8 byte order mark, as the reader's errors count them) of the value a JSON Pointer
 * (RFC 6901) leads to, for messages about data read from the text (json-c's tree keeps no
 * positions). A token of digits is an array index, any other a member name ("~0" and "~1"
 * stand for '~' and '/'). When the pointer leads nowhere, the deepest value on its way.
 * \param [in] text a JSON text that qk_region_read_geojson_text() accepted.
 * \param [in] len its length in bytes.
 * \param [in] pointer e.g. "/features/3/geometry/coordinates/0/2" ("" is the root).
 * \param [out] line the line.
 * \param [out] column the column.
 * \return QK_OK, QK_ERR_INVALID (a NULL argument, or a pointer not starting with '/' or
 *         longer than 1023 bytes), or QK_ERR_UNSUPPORTED when built without json-c.
 */
qk_status_t qk_region_find_json_pointer(const char *text, size_t len, const char *pointer,
                                        unsigned long *line, unsigned long *column);

/**
 * Read the polygons of a vector file through GDAL/OGR (Shapefile, GeoPackage, FlatGeobuf,
 * GeoJSON, ...): every layer's Polygon and MultiPolygon features, with their attribute
 * fields as properties. Coordinates are used as stored (no reprojection).
 * \param [in] path the dataset.
 * \param [in] options NULL for defaults.
 * \param [out] out the new layer; NULL on error.
 * \param [out] err may be NULL.
 * \return as qk_region_read_geojson(), or QK_ERR_UNSUPPORTED when built without GDAL
 *         (the message says to install libgdal-dev).
 */
qk_status_t qk_region_read_ogr(const char *path, const qk_region_options_t *options,
                               qk_region_t **out, qk_error_t *err);

/**
 * Read a layer, choosing the reader by name: ".geojson" and ".json" go to the GeoJSON
 * reader, everything else to OGR, except a path that is not a regular file or directory (a
 * pipe, a FIFO, /dev/stdin from a pipe), which goes to the GeoJSON reader: GDAL cannot
 * read a stream.
 * \param [in] path the file.
 * \param [in] options NULL for defaults.
 * \param [out] out the new layer; NULL on error.
 * \param [out] err may be NULL.
 * \return as the reader chosen.
 */
qk_status_t qk_region_read(const char *path, const qk_region_options_t *options, qk_region_t **out,
                           qk_error_t *err);

/**
 * Free a layer. qk_region_free(NULL) does nothing.
 * \param [in] region the layer.
 */
void qk_region_free(qk_region_t *region);

/**
 * The feature holding a point: the lowest feature index among those that contain it.
 * In lon/lat mode the point is (longitude, latitude): longitudes are taken modulo 360
 * (180 is -180) and a latitude outside [-90, 90] is in no feature.
 * \param [in] region the layer.
 * \param [in] p the point.
 * \param [in] boundary the boundary rule.
 * \param [out] feature the feature index, or QK_NONE.
 * \return QK_OK, QK_ERR_NONFINITE (feature set to QK_NONE) or QK_ERR_INVALID.
 */
qk_status_t qk_region_locate(const qk_region_t *region, qk_point_t p, qk_boundary_t boundary,
                             uint32_t *feature);

/**
 * qk_region_locate() for many points, on several threads when asked. The answers do not
 * depend on the number of threads. Batches of at least 2^12 points are answered in Morton
 * order of the points, in chunks of up to 2^16 points that the threads share out (same
 * answers, far fewer cache misses); for that each thread borrows 8 bytes per point of a
 * chunk (at most 512 KiB) from the layer's allocator for the duration of the call, in one
 * block for all threads, so an allocator given to a layer that several threads query in
 * batches at once must be thread-safe. When that memory cannot be had, the points are
 * answered in input order. Batches of fewer than 2^14 points per thread use fewer
 * threads.
 * \param [in] region the layer.
 * \param [in] points n points.
 * \param [in] n how many.
 * \param [in] boundary the boundary rule.
 * \param [in] threads 1 for the calling thread only, 0 for every core, else that many.
 * \param [out] features n answers (QK_NONE for none).
 * \return QK_OK, QK_ERR_NONFINITE (some point not finite: its answer is QK_NONE, the
 *         others are answered) or QK_ERR_INVALID. When a thread cannot be started its
 *         share is answered on the calling thread.
 */
qk_status_t qk_region_locate_batch(const qk_region_t *region, const qk_point_t *points, size_t n,
                                   qk_boundary_t boundary, unsigned threads, uint32_t *features);

/**
 * Every feature that contains a point, in increasing order.
 * \param [in] region the layer.
 * \param [in] p the point.
 * \param [in] boundary the boundary rule.
 * \param [out] features up to cap feature indices (may be NULL when cap is 0).
 * \param [in] cap room in features.
 * \param [out] n_out the full count (may exceed cap; then only cap were written).
 * \return QK_OK, QK_ERR_NONFINITE (count 0) or QK_ERR_INVALID.
 */
qk_status_t qk_region_locate_all(const qk_region_t *region, qk_point_t p, qk_boundary_t boundary,
                                 uint32_t *features, size_t cap, size_t *n_out);

/** Layer and index statistics. */
typedef struct qk_region_stats {
  size_t features;          /**< features (polygons and multipolygons kept) */
  size_t rings;             /**< rings, outer and inner */
  size_t vertices;          /**< ring vertices as given (closing vertex included) */
  size_t holes;             /**< inner rings (GeoJSON / OGR) or rings after a feature's first */
  size_t self_intersecting; /**< rings whose edges cross or touch away from a shared vertex
                                 (zero-length edges skipped; neighbours count by overlapping) */
  size_t skipped;           /**< input geometries skipped (points, lines, empty, null) */
  size_t edges;             /**< edge pieces indexed (after antimeridian splits and closures) */
  size_t leaves;            /**< leaves of the index */
  size_t leaf_edges;        /**< edge entries over all leaves */
  unsigned depth;           /**< deepest leaf */
  size_t bytes;             /**< memory owned by the layer */
  double build_seconds;     /**< wall time to build the index */
  int planar;               /**< the mode the layer was built in */
  qk_box_t box;             /**< bounding box of the edges */
} qk_region_stats_t;

/**
 * Statistics of a layer.
 * \param [in] region the layer (NULL: every figure 0, as for qk_tree_stats()).
 * \param [out] stats filled (NULL: nothing is done).
 */
void qk_region_stats(const qk_region_t *region, qk_region_stats_t *stats);

/**
 * Number of features.
 * \param [in] region the layer.
 * \return the count.
 */
size_t qk_region_feature_count(const qk_region_t *region);

/**
 * A feature's property as text: strings as they are, numbers and booleans in JSON
 * notation, null as "", objects and arrays as JSON text.
 * \param [in] region the layer.
 * \param [in] feature the feature index.
 * \param [in] name the property name.
 * \return a string owned by the layer, or NULL when the feature has no such property.
 */
const char *qk_region_property(const qk_region_t *region, uint32_t feature, const char *name);

/**
 * The index's tree (its cells; it stores no points), for walks and checks; kept only
 * when the layer was built with options.keep_tree.
 * \param [in] region the layer.
 * \return borrowed, valid while the layer lives; NULL when not kept.
 */
const qk_tree_t *qk_region_tree(const qk_region_t *region);

/**
 * Draw the features (even-odd filled, each ring one closed subpath; in lon/lat mode the
 * pieces added along the antimeridian and the poles are filled but not stroked) and the
 * index cells as SVG.
 * \param [in] region the layer.
 * \param [in] f an open stream, owned by the caller.
 * \param [in] width picture width in pixels (0 means 1000).
 * \return QK_OK or QK_ERR_IO (the stream is flushed, so a write it refused is seen).
 */
qk_status_t qk_region_write_svg(const qk_region_t *region, FILE *f, unsigned width);

#ifdef __cplusplus
}
#endif

#endif /* QUADKIT_REGION_H */
