/**
 * \file query.h
 * \brief Queries on a quadkit tree: range, radius, k nearest neighbours, point
 *        location, collision of items with extent, and geodesic queries on WGS84.
 *
 * Every query here is exact: it returns what a brute-force loop over all points would,
 * evaluated with the same double-precision formulas stated in each function's comment.
 * The searches prune by the squares of the tree's nodes and never allocate per node.
 *
 * Thread safety: every function taking a `const` handle only reads it, so any number of
 * threads may query one tree, collider or geodesic index at the same time, as long as no
 * thread changes the tree meanwhile (see index.h).
 *
 * Result buffers follow one convention: the caller passes a buffer of `cap` entries and
 * gets back through `n_out` the total number of results; when that exceeds `cap` only
 * the first `cap` are written and the call still returns QK_OK (call again with a larger
 * buffer). Functions that fill such a buffer end in `_list`. Callbacks return zero to go
 * on and nonzero to stop the query early (which still returns QK_OK).
 *
 * Batch calls (`_batch`) answer many queries in one call, in parallel on the tree's
 * threads (qk_tree_options_t::threads, qk_tree_set_threads()), with the same results as
 * one thread. They share one layout: `counts[i]` receives the number of results of query
 * i; kNN results sit at a stride of k per query, other results are packed in query order.
 * A query that fails gets count 0 and the others are still answered; the call returns
 * the error of the lowest-numbered failed query.
 *
 * NULL options mean the defaults of qk_tree_options_init() everywhere.
 */
#ifndef QUADKIT_QUERY_H
#define QUADKIT_QUERY_H

#include "quadkit/index.h"

#ifdef __cplusplus
extern "C" {
#endif

/** A neighbour found by a query: the point's id and its distance from the query. */
typedef struct qk_neighbor {
  qk_id_t id;  /**< the point's id */
  double dist; /**< Euclidean distance (metres for the geodesic queries) */
} qk_neighbor_t;

/* ---------------------------------------------------------------------------------- */
/* Range and radius                                                                    */

/**
 * Report every point inside a closed box (xmin <= x <= xmax and ymin <= y <= ymax), in
 * no particular order. An inverted box (xmin > xmax) holds no point; infinite bounds are
 * allowed.
 * \param [in] tree the tree.
 * \param [in] box the box.
 * \param [in] fn called for each point with dist 0.
 * \param [in] ud passed to fn.
 * \return QK_OK or QK_ERR_NONFINITE (a NaN bound).
 */
qk_status_t qk_query_range(const qk_tree_t *tree, qk_box_t box, qk_found_fn fn, void *ud);

/**
 * The ids of the points inside a closed box, into a buffer, in no particular order.
 * \param [in] tree the tree.
 * \param [in] box the box.
 * \param [out] ids buffer for up to cap ids (may be NULL when cap is 0).
 * \param [in] cap its size.
 * \param [out] n_out how many points the box holds (may exceed cap).
 * \return QK_OK or QK_ERR_NONFINITE.
 */
qk_status_t qk_query_range_list(const qk_tree_t *tree, qk_box_t box, qk_id_t *ids, size_t cap,
                                size_t *n_out);

/** \deprecated The former name of qk_query_range_list(). */
static inline qk_status_t qk_query_range_ids(const qk_tree_t *tree, qk_box_t box, qk_id_t *ids,
                                             size_t cap, size_t *n_out) {
  return qk_query_range_list(tree, box, ids, cap, n_out);
}

/**
 * Report every point p within distance r of c, that is with
 * (p.x - c.x)^2 + (p.y - c.y)^2 <= r^2 in exact arithmetic, in no particular order: exact
 * for any finite values (no rounding, no overflow of the squares beyond 1e154, no
 * underflow below 1e-154). The squares in double decide all but the points within a
 * relative 2^-45 of the circle, and every point when r is beyond 2^500, which an exact
 * test (big integers, microseconds) decides. The distance passed is the rounded one
 * (sqrt of the double squares, or hypot of the differences where their sum reaches 2^1000,
 * near overflow), so a point exactly on the circle may be reported at a distance an ulp
 * above r. (Before December 2026 the double formula was the definition, overflow
 * included.)
 * \param [in] tree the tree.
 * \param [in] c the centre; may lie outside the root square.
 * \param [in] r the radius, >= 0 (INFINITY reports every point).
 * \param [in] fn called for each point with its distance.
 * \param [in] ud passed to fn.
 * \return QK_OK, QK_ERR_NONFINITE (c not finite, or r NaN) or QK_ERR_INVALID (r < 0).
 */
qk_status_t qk_query_radius(const qk_tree_t *tree, qk_point_t c, double r, qk_found_fn fn,
                            void *ud);

/**
 * The points within distance r of c, into a buffer, in no particular order.
 * \param [in] tree the tree.
 * \param [in] c the centre.
 * \param [in] r the radius, >= 0.
 * \param [out] out buffer for up to cap neighbours (may be NULL when cap is 0).
 * \param [in] cap its size.
 * \param [out] n_out how many points lie within r (may exceed cap).
 * \return as qk_query_radius().
 */
qk_status_t qk_query_radius_list(const qk_tree_t *tree, qk_point_t c, double r, qk_neighbor_t *out,
                                 size_t cap, size_t *n_out);

/**
 * Radius queries for many centres in one call, into one buffer. The results are packed
 * in query order: query i's are the counts[i] entries after those of queries 0 .. i-1.
 * When the total exceeds cap, only the first cap entries are written and the call still
 * returns QK_OK (the counts and *n_out tell the size needed).
 * \param [in] tree the tree.
 * \param [in] centres nq centres.
 * \param [in] nq how many.
 * \param [in] r the radius, >= 0.
 * \param [out] out buffer for up to cap neighbours (may be NULL when cap is 0).
 * \param [in] cap its size.
 * \param [out] counts nq entries: the number of points within r of each centre.
 * \param [out] n_out the total (may exceed cap).
 * \return QK_OK, QK_ERR_INVALID (r < 0 or a NULL argument), QK_ERR_NONFINITE (r NaN, or
 *         the lowest-numbered centre that is not finite; its count is 0).
 */
qk_status_t qk_query_radius_list_batch(const qk_tree_t *tree, const qk_point_t *centres, size_t nq,
                                       double r, qk_neighbor_t *out, size_t cap, size_t *counts,
                                       size_t *n_out);

/**
 * \deprecated The former layout of qk_query_radius_list_batch(): query i's results are
 * out[offsets[i] .. offsets[i+1]) (offsets has nq + 1 entries, offsets[nq] the total).
 * Returns QK_OK with the full offsets when the total exceeds cap, as every buffer does.
 */
static inline qk_status_t qk_query_radius_batch(const qk_tree_t *tree, const qk_point_t *centres,
                                                size_t nq, double r, qk_neighbor_t *out, size_t cap,
                                                size_t *offsets) {
  size_t total = 0;
  if (!offsets) return QK_ERR_INVALID;
  qk_status_t st = qk_query_radius_list_batch(tree, centres, nq, r, out, cap, offsets, &total);
  if (st == QK_ERR_INVALID) return st;
  size_t acc = 0;
  for (size_t i = 0; i < nq; i++) {
    size_t c = offsets[i];
    offsets[i] = acc;
    acc += c;
  }
  offsets[nq] = acc;
  return st;
}

/* ---------------------------------------------------------------------------------- */
/* k nearest neighbours                                                                */

/**
 * The k nearest points to q, exact, sorted by distance and ties by smaller id. With a
 * finite max_dist only points with squared distance <= max_dist^2 count (a capped kNN),
 * so fewer than k may be returned. Uses no heap memory: out is the search's priority
 * queue.
 * \param [in] tree the tree.
 * \param [in] q the query; may lie outside the root square.
 * \param [in] k how many neighbours (any k; at most the number of points come back).
 * \param [in] max_dist the cap, >= 0, or INFINITY.
 * \param [out] out buffer of k entries (may be NULL when k is 0).
 * \param [out] n_out how many were written: min(k, points within max_dist).
 * \return QK_OK, QK_ERR_NONFINITE, QK_ERR_INVALID (max_dist < 0 or NaN) or QK_ERR_LIMIT
 *         (q or the root square reaches beyond 2^510 ~ 3.4e153 on an axis, where squared
 *         distances could overflow). The ranking and the cap are exact (the exact
 *         squared distances, compared behind a floating-point filter), also below
 *         2^-537, where squares in double underflow; the distances reported are
 *         sqrt(dx*dx + dy*dy) in double (hypot(dx, dy) where that sum reaches 2^1000), as
 *         qk_query_radius() reports them, so two neighbours whose distances differ by
 *         less than rounding may report them equal or even in reverse.
 */
qk_status_t qk_query_knn(const qk_tree_t *tree, qk_point_t q, size_t k, double max_dist,
                         qk_neighbor_t *out, size_t *n_out);

/**
 * kNN for many queries in one call. Query i's neighbours are out[i*k .. i*k + counts[i]);
 * unused slots of its block get id QK_NONE and distance INFINITY. The queries are
 * answered in Z-order of their locations, so that consecutive searches reuse the cache;
 * for that a batch of 64 or more borrows 16 bytes per query from the tree's allocator
 * for the duration of the call (when that fails, the given order is used instead). A
 * custom allocator must therefore be thread-safe if batches run on several threads.
 * \param [in] tree the tree.
 * \param [in] qs nq queries.
 * \param [in] nq how many.
 * \param [in] k neighbours per query.
 * \param [in] max_dist the cap, or INFINITY.
 * \param [out] out nq * k entries.
 * \param [out] counts nq counts (may be NULL).
 * \return QK_OK, QK_ERR_NONFINITE or QK_ERR_LIMIT (as qk_query_knn(), for the
 *         lowest-numbered query that failed; the others are still answered, that one gets
 *         count 0) or QK_ERR_INVALID.
 */
qk_status_t qk_query_knn_batch(const qk_tree_t *tree, const qk_point_t *qs, size_t nq, size_t k,
                               double max_dist, qk_neighbor_t *out, size_t *counts);

/* ---------------------------------------------------------------------------------- */
/* Point location                                                                      */

/** The leaf holding a location, with its square and its points (borrowed). */
typedef struct qk_location {
  qk_node_t leaf;     /**< the leaf */
  qk_square_t square; /**< its square */
  uint32_t depth;     /**< its depth */
  size_t count;       /**< points in it */
  const double *x;    /**< their x coordinates (valid until the tree changes) */
  const double *y;    /**< their y coordinates */
  const qk_id_t *ids; /**< their ids */
} qk_location_t;

/**
 * Point location: the leaf whose square contains p (squares are half-open on their west
 * and south sides, the root's outer edges included, as qk_tree_find_leaf()).
 * \param [in] tree the tree.
 * \param [in] p the location.
 * \param [out] loc the leaf and its points.
 * \return QK_OK, QK_ERR_NONFINITE or QK_ERR_OUTSIDE.
 */
qk_status_t qk_query_locate(const qk_tree_t *tree, qk_point_t p, qk_location_t *loc);

/**
 * Point location for many points (answered in Z-order of the locations, with the same
 * temporary allocation as qk_query_knn_batch()).
 * \param [in] tree the tree.
 * \param [in] ps n locations.
 * \param [in] n how many.
 * \param [out] leaves n leaves; QK_NONE for a location outside the root or not finite.
 * \return QK_OK.
 */
qk_status_t qk_query_locate_batch(const qk_tree_t *tree, const qk_point_t *ps, size_t n,
                                  qk_node_t *leaves);

/* ---------------------------------------------------------------------------------- */
/* Geodesic queries (WGS84)                                                             */

/**
 * Points given as (lon, lat) in degrees on the WGS84 ellipsoid, indexed for queries by
 * geodesic distance in metres (GeographicLib's algorithms through PROJ's geodesic.h).
 * Longitudes are normalised into [-180, 180]; the antimeridian and the poles need no
 * special care from the caller. Without geodesic support in the build every geodesic
 * call returns QK_ERR_UNSUPPORTED.
 */
typedef struct qk_geo qk_geo_t;

/**
 * Build a geodesic index. Point i (x = lon, y = lat in degrees) gets id i.
 * \param [in] lonlat n points (copied).
 * \param [in] n how many.
 * \param [in] options tree options (only capacity, max_depth, threads and allocator are
 *             used; the root is fixed); NULL for the defaults of qk_tree_options_init()
 *             (capacity 1: a capacity of 16 or so answers faster).
 * \param [out] out the index, freed with qk_geo_free(); NULL on error.
 * \return QK_OK, QK_ERR_NONFINITE, QK_ERR_OUTSIDE (latitude outside [-90, 90]),
 *         QK_ERR_LIMIT, QK_ERR_NOMEM or QK_ERR_UNSUPPORTED.
 */
qk_status_t qk_geo_build(const qk_point_t *lonlat, size_t n, const qk_tree_options_t *options,
                         qk_geo_t **out);

/** Free a geodesic index; NULL does nothing. */
void qk_geo_free(qk_geo_t *g);

/** The underlying tree over (normalised lon, lat) (borrowed). */
const qk_tree_t *qk_geo_tree(const qk_geo_t *g);

/**
 * Geodesic distance in metres between two (lon, lat) points on WGS84.
 * \param [in] a,b the points.
 * \param [out] metres the distance.
 * \return QK_OK, QK_ERR_NONFINITE, QK_ERR_OUTSIDE (|lat| > 90) or QK_ERR_UNSUPPORTED.
 */
qk_status_t qk_geo_distance(qk_point_t a, qk_point_t b, double *metres);

/**
 * Report every point within `metres` (geodesic, inclusive) of q, in no particular
 * order, each with its distance.
 * \param [in] g the index.
 * \param [in] q the query (lon, lat).
 * \param [in] metres the radius, >= 0.
 * \param [in] fn called per point with its (lon, lat) and distance in metres.
 * \param [in] ud passed to fn.
 * \return QK_OK, QK_ERR_NONFINITE, QK_ERR_OUTSIDE, QK_ERR_INVALID or QK_ERR_UNSUPPORTED.
 */
qk_status_t qk_geo_radius(const qk_geo_t *g, qk_point_t q, double metres, qk_found_fn fn, void *ud);

/**
 * The points within `metres` of q into a buffer, sorted by distance then id.
 * \param [in] g the index.
 * \param [in] q the query (lon, lat).
 * \param [in] metres the radius, >= 0.
 * \param [out] out buffer for up to cap neighbours (may be NULL when cap is 0).
 * \param [in] cap its size.
 * \param [out] n_out the number of such points (may exceed cap; the buffer then holds
 *              an unspecified subset).
 * \return as qk_geo_radius().
 */
qk_status_t qk_geo_radius_list(const qk_geo_t *g, qk_point_t q, double metres, qk_neighbor_t *out,
                               size_t cap, size_t *n_out);

/**
 * The k nearest points to q by geodesic distance, sorted by distance then id; with a
 * finite max_metres only points within it count.
 * \param [in] g the index.
 * \param [in] q the query (lon, lat).
 * \param [in] k how many.
 * \param [in] max_metres the cap, or INFINITY.
 * \param [out] out k entries (distances in metres).
 * \param [out] n_out how many were written.
 * \return QK_OK, QK_ERR_NONFINITE, QK_ERR_OUTSIDE, QK_ERR_INVALID or QK_ERR_UNSUPPORTED.
 */
qk_status_t qk_geo_knn(const qk_geo_t *g, qk_point_t q, size_t k, double max_metres,
                       qk_neighbor_t *out, size_t *n_out);

/**
 * Geodesic kNN for many queries; layout and ordering as qk_query_knn_batch().
 * \param [in] g the index.
 * \param [in] qs nq queries (lon, lat).
 * \param [in] nq how many.
 * \param [in] k neighbours per query.
 * \param [in] max_metres the cap, or INFINITY.
 * \param [out] out nq * k entries.
 * \param [out] counts nq counts (may be NULL).
 * \return QK_OK, the error of the lowest-numbered failed query (the other queries are
 *         still answered), or QK_ERR_UNSUPPORTED.
 */
qk_status_t qk_geo_knn_batch(const qk_geo_t *g, const qk_point_t *qs, size_t nq, size_t k,
                             double max_metres, qk_neighbor_t *out, size_t *counts);

#ifdef __cplusplus
}
#endif

#endif /* QUADKIT_QUERY_H */
