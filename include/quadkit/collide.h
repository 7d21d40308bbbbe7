/**
 * \file collide.h
 * \brief Collision of items with extent: the static collider (discs and boxes built once)
 *        and the moving-objects world.
 */
#ifndef QUADKIT_COLLIDE_H
#define QUADKIT_COLLIDE_H

#include "quadkit/common.h"
#include "quadkit/index.h"

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
 * disc and a box when the box point nearest the centre is within r; decided exactly for
 * any finite values (the disc tests in double unless within a relative 2^-45 of touching
 * or beyond 2^500, then by an exact test; before December 2026 the double formula,
 * whose squares overflow beyond 1e154 and underflow below 1e-154).
 * \param [in] discs n_discs discs (copied; may be NULL when n_discs is 0).
 * \param [in] n_discs how many.
 * \param [in] boxes n_boxes closed boxes (copied; may be NULL when n_boxes is 0).
 * \param [in] n_boxes how many.
 * \param [in] options tree options for the centres (capacity, allocator, root, threads
 *             for the pairs and batch calls); NULL means qk_tree_options_init()'s defaults,
 *             as for every quadkit object (capacity 1; 8 to 16 is faster for large sets).
 *             Its huge_pages hint is not needed: on Linux the collider asks for
 *             transparent huge pages over each of its arrays of 4 MB and more that come
 *             from the default allocator (as Embree does for its BVH), since every build
 *             makes them anew.
 * \param [out] out the collider, freed with qk_collider_free(); NULL on error.
 * \return QK_OK, QK_ERR_NONFINITE, QK_ERR_GEOMETRY (negative radius or inverted box),
 *         QK_ERR_OUTSIDE (a centre outside a given root), QK_ERR_LIMIT or QK_ERR_NOMEM.
 */
qk_status_t qk_collider_build(const qk_disc_t *discs, size_t n_discs, const qk_box_t *boxes,
                              size_t n_boxes, const qk_tree_options_t *options,
                              qk_collider_t **out);

/**
 * Build the collider again over new items, reusing its memory: the item and node arrays
 * are kept and grown only when too small, so a collider rebuilt every frame stops asking
 * for large blocks once it has reached its largest size: it keeps as well the item centres
 * (16 bytes an item) and its tree the build's record block (see qk_tree_rebuild()) for
 * the next rebuild. A fresh build asks for every array anew, and a C library may give
 * large freed blocks back to the system, so that each build touches fresh pages: at 10^6
 * boxes a rebuild can take a third of the time of a build and free. The options the
 * collider was built with stay (capacity, depth cap, a given root, allocator); the build
 * runs on the collider's threads (qk_collider_set_threads()). Ids as for
 * qk_collider_build(). Ray structures made for the old items are dropped; the next cast
 * (or qk_collider_prepare_rays()) makes them again. Must not run concurrently with any
 * other call on the collider.
 * \param [in,out] c the collider.
 * \param [in] discs,n_discs,boxes,n_boxes the items, as qk_collider_build() (copied).
 * \return as qk_collider_build(), or QK_ERR_INVALID (c NULL). The collider is unchanged
 *         when the input is rejected; on QK_ERR_NOMEM it is left valid and empty.
 */
qk_status_t qk_collider_rebuild(qk_collider_t *c, const qk_disc_t *discs, size_t n_discs,
                                const qk_box_t *boxes, size_t n_boxes);

/** Free a collider (and its ray structures, if they were made); NULL does nothing. */
void qk_collider_free(qk_collider_t *c);

/**
 * Make the structures only the ray cast uses (its 4-wide quantised nodes and start table)
 * now. Optional: qk_collider_build() does not make them, so a collider used for pairs and
 * overlap queries alone never pays for them; the first qk_collider_raycast() or
 * qk_collider_raycast_batch() makes them otherwise (safely when several threads cast at
 * once: one makes them, from the collider's allocator, and the others wait). Call it
 * after the build so that the first cast does not pay for them. Idempotent; uses the
 * collider's threads (qk_collider_set_threads()) and must not run concurrently with that
 * call.
 * \param [in,out] c the collider.
 * \return QK_OK, QK_ERR_INVALID (c NULL) or QK_ERR_NOMEM (nothing kept: the collider is
 *         as before and a later call, or cast, tries again).
 */
qk_status_t qk_collider_prepare_rays(qk_collider_t *c);

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
 * order (but the same order for every threads setting: see qk_collider_set_threads()).
 * \param [in] c the collider.
 * \param [in] fn the callback.
 * \param [in] ud passed to fn.
 * \return QK_OK.
 */
qk_status_t qk_collider_pairs(const qk_collider_t *c, qk_pair_fn fn, void *ud);

/**
 * Set the number of threads qk_collider_pairs(), qk_collider_pairs_list() and
 * qk_collider_raycast_batch() use: 0 means every online core, the default is 1. The
 * answers, and the order in which qk_collider_pairs() reports them, do not depend on it;
 * fn is always called on the calling thread. With more than one thread, the pairs calls
 * collect the pairs in memory from the collider's allocator (which must then be
 * thread-safe) before reporting them; when that memory cannot be had they run on the
 * calling thread instead. Worker threads are kept between calls as the tree's are
 * (qk_tree_options_t.threads). Must not run concurrently with any other call on the
 * collider.
 * \param [in,out] c the collider (NULL does nothing).
 * \param [in] threads the count.
 */
void qk_collider_set_threads(qk_collider_t *c, uint32_t threads);

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
 * item. For a segment from a to b pass dir = b - a and tmax = 1. Hits are decided in
 * doubles (docs/collide.md), not exactly as the overlap queries are: a ray from within a
 * few ulps of a disc's circle may hit it at t = 0 even moving away from it (the world's
 * rays, qk_world_raycast(), are exact).
 * \param [in] c the collider.
 * \param [in] origin the ray's origin.
 * \param [in] dir its direction (any length, not normalised: one far from 1 is scaled
 *             internally by a power of two, which leaves t exact).
 * \param [in] tmax the largest t considered (INFINITY for a ray).
 * \param [out] hit the hit, or {QK_NONE, INFINITY}.
 * \return QK_OK, QK_ERR_NONFINITE, QK_ERR_INVALID (tmax < 0 or NaN) or QK_ERR_NOMEM (the
 *         ray structures could not be made: see qk_collider_prepare_rays()).
 */
qk_status_t qk_collider_raycast(const qk_collider_t *c, qk_point_t origin, qk_point_t dir,
                                double tmax, qk_hit_t *hit);

/**
 * qk_collider_raycast() for n rays in one call, on the collider's threads
 * (qk_collider_set_threads()), with the same hits as n single calls. A ray that fails
 * gets {QK_NONE, INFINITY} and the others are still answered. Batches of more than 4096
 * rays borrow 12 bytes per 256 rays from the collider's allocator for the duration of
 * the call.
 * \param [in] c the collider.
 * \param [in] origins n origins.
 * \param [in] dirs n directions.
 * \param [in] n how many rays.
 * \param [in] tmax the largest t considered, for every ray (INFINITY for rays).
 * \param [out] hits n hits, hits[i] for ray i.
 * \return QK_OK, QK_ERR_INVALID (NULL arrays, or tmax < 0 or NaN), QK_ERR_NOMEM (nothing
 *         cast; as for qk_collider_prepare_rays() when the ray structures could not be
 *         made), or the error of the lowest-numbered failed ray (QK_ERR_NONFINITE).
 */
qk_status_t qk_collider_raycast_batch(const qk_collider_t *c, const qk_point_t *origins,
                                      const qk_point_t *dirs, size_t n, double tmax,
                                      qk_hit_t *hits);

/* ---------------------------------------------------------------------------------- */
/* The world: moving objects with stable handles                                        */

/** Kind of a world object's shape. */
typedef enum qk_shape_kind {
  QK_SHAPE_DISC = 0,    /**< centre (x, y), radius a >= 0 */
  QK_SHAPE_BOX = 1,     /**< closed box with corners (x, y) and (a, b) */
  QK_SHAPE_SEGMENT = 2, /**< closed segment from (x, y) to (a, b) */
  QK_SHAPE_POINT = 3    /**< the point (x, y) */
} qk_shape_kind_t;

/**
 * A closed shape. Every value must be zero or of magnitude in [2^-100, 2^100] (about
 * 7.9e-31 to 1.3e30), which is what lets every overlap test be decided exactly.
 */
typedef struct qk_shape {
  qk_shape_kind_t kind; /**< which shape */
  double x, y, a, b;    /**< see qk_shape_kind_t; unused values are ignored */
} qk_shape_t;

/**
 * A handle to a world object: slot in the low 32 bits, generation in the high 32. A slot
 * is reused after its object is removed, with the next generation, so a stale handle is
 * rejected (QK_ERR_NOT_FOUND) rather than naming the new object; after 2^31 objects a
 * slot's generations are spent and it is retired (72 bytes of memory, never reused).
 */
typedef uint64_t qk_handle_t;

/** "No object". */
#define QK_HANDLE_NONE UINT64_MAX

/** The slot of a handle (stable while the object lives; dense, reused after removal). */
#define QK_HANDLE_SLOT(h) ((uint32_t)((h)&0xffffffffu))

/** A pair of overlapping objects, slot of a below slot of b. */
typedef struct qk_world_pair {
  qk_handle_t a, b;
} qk_world_pair_t;

/** An object found by a ray (t in [0, 1] along the segment) or a kNN query (t = distance). */
typedef struct qk_world_hit {
  qk_handle_t h; /**< the object, or QK_HANDLE_NONE */
  double t;      /**< ray parameter or distance */
} qk_world_hit_t;

/** Which pairs qk_world_pairs_list() reports. */
typedef enum qk_pairs_which {
  QK_PAIRS_ALL = 0,   /**< every pair overlapping at the last update */
  QK_PAIRS_BEGAN = 1, /**< overlapping at the last update, not at the one before */
  QK_PAIRS_ENDED = 2  /**< overlapping at the update before, not at the last (or removed) */
} qk_pairs_which_t;

/** World options; initialise with qk_world_options_init(). */
typedef struct qk_world_options {
  const qk_allocator_t *allocator; /**< NULL: libc. Must be thread-safe when threads > 1,
                                        or when queries run on other threads than the
                                        world's changes (they may make its query tree) */
  unsigned threads;                /**< threads for update, batch queries and
                                        qk_world_pairs_parallel (1: none; 0: every online
                                        core, as for the tree and the collider) */
  double margin;                   /**< fattening of each object's box, as a fraction of its
                                        size, 0..16 (default 0.5); larger: fewer re-filings */
  double min_margin;               /**< absolute fattening added, 0..2^100 (default 0) */
  size_t thread_min;               /**< an update (and qk_world_pairs_parallel) uses the
                                        threads only from this many live objects (default
                                        32768: below it, starting threads costs more than
                                        they save) */
} qk_world_options_t;

/** A moving-objects world; see docs/collide.md. */
typedef struct qk_world qk_world_t;

/** Defaults: libc allocator, one thread, margin 0.5, min_margin 0, thread_min 32768. */
void qk_world_options_init(qk_world_options_t *o);

/**
 * Make an empty world.
 * \param [in] options NULL for defaults (copied; the allocator struct is copied too).
 * \param [out] out the world, freed with qk_world_free().
 * \return QK_OK, QK_ERR_INVALID (threads above 256, a margin out of range) or
 *         QK_ERR_NOMEM.
 */
qk_status_t qk_world_new(const qk_world_options_t *options, qk_world_t **out);

/** Free a world; NULL does nothing. */
void qk_world_free(qk_world_t *w);

/**
 * Add an object. It takes part in pairs from the next qk_world_update().
 * \param [in] w the world.
 * \param [in] shape its shape (copied; a box's corners may come in any order).
 * \param [in] tag any value, returned by qk_world_get().
 * \param [out] h its handle.
 * \return QK_OK, QK_ERR_NONFINITE, QK_ERR_GEOMETRY (negative radius), QK_ERR_LIMIT (a
 *         value outside the accepted range, or 2^32 - 1 objects), QK_ERR_INVALID or
 *         QK_ERR_NOMEM (the world unchanged).
 */
qk_status_t qk_world_add(qk_world_t *w, const qk_shape_t *shape, uint64_t tag, qk_handle_t *h);

/**
 * Give an object a new shape (of any kind). It is re-filed (at the next update) only
 * when it leaves its cell's loose square. Never allocates.
 * \return QK_OK, QK_ERR_NOT_FOUND (stale or unknown handle) or a shape error as
 *         qk_world_add (the object unchanged).
 */
qk_status_t qk_world_move(qk_world_t *w, qk_handle_t h, const qk_shape_t *shape);

/**
 * qk_world_move() for n objects: object h[i] gets shapes[i], in order. Cheaper per object
 * than n calls (one loop, the handle check and the loose-square test inline). Never
 * allocates.
 * \param [in] w the world.
 * \param [in] h n handles (a handle may repeat: its last shape wins).
 * \param [in] shapes n shapes (copied).
 * \param [in] n how many.
 * \param [out] err may be NULL; on failure, item is the index of the offending move and
 *        message names it, its handle and the reason.
 * \return QK_OK, QK_ERR_INVALID, or the first failing move's status as qk_world_move()
 *         (QK_ERR_NOT_FOUND for a stale or unknown handle, or a shape error): the moves
 *         before it are done, it and the ones after it are not.
 */
qk_status_t qk_world_move_batch(qk_world_t *w, const qk_handle_t *h, const qk_shape_t *shapes,
                                size_t n, qk_error_t *err);

/**
 * Remove an object; its slot is reused by a later add with a new generation. Its pairs
 * are reported as ended at the next update.
 * \return QK_OK or QK_ERR_NOT_FOUND.
 */
qk_status_t qk_world_remove(qk_world_t *w, qk_handle_t h);

/**
 * An object's shape (normalised: a box's corners as min then max) and tag.
 * \param [out] shape may be NULL. \param [out] tag may be NULL.
 * \return QK_OK or QK_ERR_NOT_FOUND.
 */
qk_status_t qk_world_get(const qk_world_t *w, qk_handle_t h, qk_shape_t *shape, uint64_t *tag);

/** Number of live objects. */
size_t qk_world_size(const qk_world_t *w);

/** Bytes the world holds from its allocator (between updates: an update's scratch is
 * freed before it returns, except its large blocks kept for the next update, counted
 * in qk_world_pair_bytes()). */
size_t qk_world_bytes(const qk_world_t *w);

/** The part of qk_world_bytes() that holds the pair state: the current pairs (4 bytes a
 * pair and 4 a slot), the began and ended lists (8 bytes a pair) and, after an update
 * that searched by bands, the float boxes by slot (16 bytes a slot) and the pairs whose
 * float boxes met but whose shapes did not (8 bytes each), and the update's scratch kept
 * for the next one (blocks of 256 KB and more, and the keys and rows of 8 MB and more);
 * the rest is the index
 * (objects, order, cells). */
size_t qk_world_pair_bytes(const qk_world_t *w);

/**
 * End a frame: find every overlapping pair (exactly; touching counts) and the pairs that
 * began and ended since the last update. Uses the threads option.
 * \return QK_OK or QK_ERR_NOMEM, in which case the pairs of the previous update are kept
 *         and the call may be retried (QK_ERR_LIMIT, the same, past 2^32 - 1 pairs).
 */
qk_status_t qk_world_update(qk_world_t *w);

/** Called per pair in the order of qk_world_pairs_list(); return nonzero to stop. */
typedef int (*qk_world_pair_fn)(qk_handle_t a, qk_handle_t b, void *ud);

/**
 * The pairs of the last update, in order (by slot of a, then slot of b).
 * \param [in] which all, began or ended.
 * \return QK_OK or QK_ERR_INVALID.
 */
qk_status_t qk_world_pairs(const qk_world_t *w, qk_pairs_which_t which, qk_world_pair_fn fn,
                           void *ud);

/**
 * The pairs of the last update into a buffer, in order (by slot of a, then slot of b).
 * \param [out] out up to cap pairs. \param [out] n_out the full count (may exceed cap).
 * \return QK_OK or QK_ERR_INVALID.
 */
qk_status_t qk_world_pairs_list(const qk_world_t *w, qk_pairs_which_t which, qk_world_pair_t *out,
                                size_t cap, size_t *n_out);

/**
 * The pairs of the last update from index first on, in the order of qk_world_pairs_list():
 * pairs first, first + 1, ... into a buffer, so that threads of the caller's own can each
 * take a slice of the pairs (first = 0 is qk_world_pairs_list()). Finding pair first costs
 * a bisection over the rows of the pairs, not a walk of the pairs before it. Like every
 * read-only call it may run from many threads at once while the world is not changed.
 * \param [in] w the world.
 * \param [in] which all, began or ended.
 * \param [in] first the index of the first pair wanted (any value: from the count on,
 *             there are none).
 * \param [out] out up to cap pairs: pairs first .. first + cap - 1 of the order, those of
 *              them below the count (may be NULL when cap is 0).
 * \param [in] cap the buffer's size.
 * \param [out] n_out the full count of the list, as qk_world_pairs_list() gives it, whatever
 *              first and cap: min(cap, n_out - first) pairs were written when first <
 *              n_out, none otherwise.
 * \return QK_OK or QK_ERR_INVALID (w or n_out NULL, out NULL with cap > 0, which not a
 *         qk_pairs_which_t).
 */
qk_status_t qk_world_pairs_range(const qk_world_t *w, qk_pairs_which_t which, size_t first,
                                 qk_world_pair_t *out, size_t cap, size_t *n_out);

/** Called per pair by qk_world_pairs_parallel() on worker `worker`; nonzero stops the walk. */
typedef int (*qk_world_pair_worker_fn)(qk_handle_t a, qk_handle_t b, unsigned worker, void *ud);

/**
 * qk_world_pairs() on the world's threads. The pairs of the last update, in the order of
 * qk_world_pairs_list(), are cut into nw contiguous ranges of nearly equal counts (nw: the
 * threads an update uses, that is the threads option, or 1 below thread_min live
 * objects; at most 64, and at most the count); worker t in [0, nw) gets range t, in
 * order, on one thread (worker 0 on the calling thread). So the workers' pairs
 * concatenated in worker order are qk_world_pairs_list()'s, and accumulators indexed by
 * worker need no lock (keep them on cache lines of their own: workers writing one line
 * slow each other). fn runs on several threads at once: it must be safe so, and may call
 * the world's read-only functions, but the world must not be changed until this call
 * returns. The threads are the world's workers (those of qk_world_update(), started by
 * the first update that used them) when they are free, else threads started for the
 * call; it allocates nothing. A nonzero return from fn stops the walk: that worker calls
 * fn no more, and each other worker stops within 64 pairs after it sees the request (it
 * looks before each block of 64 of its pairs); each worker's pairs are a prefix of its
 * range.
 * \param [in] w the world.
 * \param [in] which all, began or ended.
 * \param [in] fn called once per pair (unless stopped) with the pair's handles, a's slot
 *             below b's, and the worker.
 * \param [in] ud passed to fn.
 * \return QK_OK (also when fn stopped the walk) or QK_ERR_INVALID (w or fn NULL, which
 *         not a qk_pairs_which_t).
 */
qk_status_t qk_world_pairs_parallel(const qk_world_t *w, qk_pairs_which_t which,
                                    qk_world_pair_worker_fn fn, void *ud);

/*
 * The queries below are read-only calls: many threads may query a world at once while
 * it is not changed. The first of them after an update that finds 64 cells or more, or
 * 16 objects or more, makes the world's query tree (for the order of that update; its
 * memory is kept for the next one and counted by qk_world_bytes()) through the world's
 * allocator, on the querying thread, and the first query to read a cell of 16 objects or
 * more sorts them into groups there; the others go without meanwhile, and a query whose
 * tree or groups cannot be allocated goes without them, with the same answers either way.
 */

/**
 * Objects overlapping a shape (a box, disc, point or segment; touching counts), exactly,
 * as they are now (moves need no update first), by slot.
 * \param [out] out up to cap handles: the first cap by slot when there are more.
 * \param [out] n_out the full count.
 * \return QK_OK, a shape error as qk_world_add() (QK_ERR_NONFINITE, QK_ERR_GEOMETRY,
 *         QK_ERR_LIMIT for a nonzero magnitude below 2^-100 or beyond 2^100), or
 *         QK_ERR_INVALID.
 */
qk_status_t qk_world_query(const qk_world_t *w, const qk_shape_t *shape, qk_handle_t *out,
                           size_t cap, size_t *n_out);

/**
 * Every object the segment from -> to touches (decided exactly), in order of the
 * parameter t in [0, 1] of the first contact (computed in long double; ties by slot).
 * For a ray, pass a far endpoint.
 * \param [out] out up to cap hits: the first cap in that order when there are more.
 * \param [out] n_out the full count.
 * \return QK_OK, QK_ERR_NONFINITE, QK_ERR_LIMIT (an endpoint coordinate beyond 2^100, or
 *         nonzero below 2^-100: pass a far endpoint within range) or QK_ERR_INVALID.
 */
qk_status_t qk_world_raycast_all(const qk_world_t *w, qk_point_t from, qk_point_t to,
                                 qk_world_hit_t *out, size_t cap, size_t *n_out);

/** The first of qk_world_raycast_all()'s hits, or {QK_HANDLE_NONE, INFINITY}. */
qk_status_t qk_world_raycast(const qk_world_t *w, qk_point_t from, qk_point_t to,
                             qk_world_hit_t *hit);

/**
 * First hits of n segments, on the world's threads. \param [out] hits n hits.
 * \return QK_OK, QK_ERR_INVALID (a NULL array), or the first error of a segment, in
 *         order (its hit is then {QK_HANDLE_NONE, INFINITY}; the others are cast).
 */
qk_status_t qk_world_raycast_batch(const qk_world_t *w, const qk_point_t *from,
                                   const qk_point_t *to, size_t n, qk_world_hit_t *hits);

/**
 * The k objects nearest to p (distance to the shape: 0 inside), by distance then slot.
 * \param [out] out k hits (t = distance). \param [out] n_out min(k, size).
 * \return QK_OK, QK_ERR_NONFINITE, QK_ERR_LIMIT (a coordinate of p beyond 2^100, or nonzero
 *         below 2^-100) or QK_ERR_INVALID.
 */
qk_status_t qk_world_knn(const qk_world_t *w, qk_point_t p, size_t k, qk_world_hit_t *out,
                         size_t *n_out);

/**
 * qk_world_knn() for n points, on the world's threads.
 * \param [out] out n * k hits, point i's in out[i k ..]; the unused slots of a point's
 *             block get {QK_HANDLE_NONE, INFINITY} (as in qk_query_knn_batch()).
 * \param [out] counts n counts (may be NULL).
 * \return QK_OK, QK_ERR_INVALID, or the first error of a point (its count is then 0).
 */
qk_status_t qk_world_knn_batch(const qk_world_t *w, const qk_point_t *ps, size_t n, size_t k,
                               qk_world_hit_t *out, size_t *counts);

#ifdef __cplusplus
}
#endif

#endif /* QUADKIT_COLLIDE_H */
