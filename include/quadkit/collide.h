/**
 * \file collide.h
 * \brief Collision of items with extent: the static collider (discs and boxes built once)
 *        and the moving-objects world.
 */
#ifndef QUADKIT_COLLIDE_H
#define QUADKIT_COLLIDE_H

#include "quadkit/common.h"
#include "quadkit/index.h"
#include "quadkit/query.h"

#ifdef __cplusplus
extern "C" {
#endif

/* ---------------------------------------------------------------------------------- */
/* Collision of items with extent                                                       */

/** A closed disc: centre (x, y) and radius r >= 0. */
typedef struct qk_disc {
  double x, y, r;
} qk_disc_t;

/** A pair of item ids, a < b. */
typedef struct qk_pair {
  qk_id_t a, b;
} qk_pair_t;

/** The first item hit by a ray: its id (QK_NONE for none) and parameter t (INFINITY). */
typedef struct qk_hit {
  qk_id_t id; /**< the item, or QK_NONE */
  double t;   /**< where: origin + t * direction */
} qk_hit_t;

/**
 * A set of items with extent (discs and axis-aligned boxes) stored in a quadtree by
 * their centres. Every node also records the bounding box of the items stored beneath
 * it, so a query reaches exactly as far beyond a node's square as its largest item.
 */
typedef struct qk_collider qk_collider_t;

/**
 * Build a collider. Discs get ids 0 .. n_discs-1, boxes n_discs .. n_discs+n_boxes-1.
 * Items overlap when they share at least one point (touching counts): discs when
 * dx^2 + dy^2 <= (r1 + r2)^2, boxes when their closed intervals meet on both axes, a
 * disc and a box when the box point nearest the centre is within r.
 * \param [in] discs n_discs discs (copied; may be NULL when n_discs is 0).
 * \param [in] n_discs how many.
 * \param [in] boxes n_boxes closed boxes (copied; may be NULL when n_boxes is 0).
 * \param [in] n_boxes how many.
 * \param [in] options tree options for the centres (capacity, allocator, root); NULL
 *             for defaults (capacity 8).
 * \param [out] out the collider, freed with qk_collider_free(); NULL on error.
 * \return QK_OK, QK_ERR_NONFINITE, QK_ERR_GEOMETRY (negative radius or inverted box),
 *         QK_ERR_OUTSIDE (a centre outside a given root), QK_ERR_LIMIT or QK_ERR_NOMEM.
 */
qk_status_t qk_collider_build(const qk_disc_t *discs, size_t n_discs, const qk_box_t *boxes,
                              size_t n_boxes, const qk_tree_options_t *options,
                              qk_collider_t **out);

/** Free a collider; NULL does nothing. */
void qk_collider_free(qk_collider_t *c);

/** The collider's tree of item centres (borrowed; valid while the collider lives). */
const qk_tree_t *qk_collider_tree(const qk_collider_t *c);

/** Number of items. */
size_t qk_collider_size(const qk_collider_t *c);

/**
 * Report the items overlapping a closed box (touching counts), in no particular order.
 * \param [in] c the collider.
 * \param [in] box the query box (xmin <= xmax, ymin <= ymax).
 * \param [in] fn called per item with its centre and dist 0.
 * \param [in] ud passed to fn.
 * \return QK_OK, QK_ERR_NONFINITE or QK_ERR_GEOMETRY.
 */
qk_status_t qk_collider_query_box(const qk_collider_t *c, qk_box_t box, qk_found_fn fn, void *ud);

/**
 * Report the items overlapping a closed disc (touching counts), in no particular order.
 * \param [in] c the collider.
 * \param [in] disc the query disc (r >= 0).
 * \param [in] fn called per item with its centre and dist 0.
 * \param [in] ud passed to fn.
 * \return QK_OK, QK_ERR_NONFINITE or QK_ERR_GEOMETRY.
 */
qk_status_t qk_collider_query_disc(const qk_collider_t *c, qk_disc_t disc, qk_found_fn fn,
                                   void *ud);

/** Called once per overlapping pair (a < b); return nonzero to stop. */
typedef int (*qk_pair_fn)(qk_id_t a, qk_id_t b, void *ud);

/**
 * Broad phase: report every overlapping pair of items once, with a < b, in no particular
 * order.
 * \param [in] c the collider.
 * \param [in] fn the callback.
 * \param [in] ud passed to fn.
 * \return QK_OK.
 */
qk_status_t qk_collider_pairs(const qk_collider_t *c, qk_pair_fn fn, void *ud);

/**
 * Every overlapping pair into a buffer, sorted by a then b.
 * \param [in] c the collider.
 * \param [out] out buffer for up to cap pairs (may be NULL when cap is 0).
 * \param [in] cap its size.
 * \param [out] n_out the number of pairs (may exceed cap; the buffer then holds an
 *              unspecified subset, unsorted: call again with a buffer of n_out).
 * \return QK_OK.
 */
qk_status_t qk_collider_pairs_list(const qk_collider_t *c, qk_pair_t *out, size_t cap,
                                   size_t *n_out);

/**
 * First hit along a ray origin + t * dir, 0 <= t <= tmax: the item with the smallest t
 * at which the ray touches it (ties by smaller id); t = 0 when the origin lies inside an
 * item. For a segment from a to b pass dir = b - a and tmax = 1.
 * \param [in] c the collider.
 * \param [in] origin the ray's origin.
 * \param [in] dir its direction (any length; not normalised).
 * \param [in] tmax the largest t considered (INFINITY for a ray).
 * \param [out] hit the hit, or {QK_NONE, INFINITY}.
 * \return QK_OK, QK_ERR_NONFINITE or QK_ERR_INVALID (tmax < 0 or NaN).
 */
qk_status_t qk_collider_raycast(const qk_collider_t *c, qk_point_t origin, qk_point_t dir,
                                double tmax, qk_hit_t *hit);

#ifdef __cplusplus
}
#endif

#endif /* QUADKIT_COLLIDE_H */
