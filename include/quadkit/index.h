/**
 * \file index.h
 * \brief The point-region quadtree (de Berg et al., Computational Geometry, ch. 14).
 *
 * A node's square is split at its centre (xmid, ymid) into four quadrants:
 *   NE: x >  xmid and y >  ymid      NW: x <= xmid and y >  ymid
 *   SW: x <= xmid and y <= ymid      SE: x >  xmid and y <= ymid
 * A square is split while it holds more than `capacity` points, unless it is at the
 * maximum depth (default QK_DEFAULT_MAX_DEPTH) or its side can no longer be halved in
 * double precision; such a leaf may hold more points. This cap is what keeps coincident
 * points from recursing forever.
 *
 * For a tree that was only built, inserted into and removed from, the shape depends
 * only on the set of points: a node is internal exactly when it holds more than
 * `capacity` points and can be split. Removing points merges four sibling leaves back
 * into their parent as soon as they fit. qk_tree_split_leaf(), qk_tree_refine() and
 * qk_tree_balance() split beyond that rule; afterwards the tree is "refined": removals
 * no longer merge and qk_tree_check() checks the weaker invariants (see there).
 *
 * Squares: a child's corner is computed as its parent's corner plus half the parent's
 * side. With a dyadic root (corner and side multiples of a power of two, e.g. [0, 2^k]^2)
 * every square is exact; with another root the far edges of a square may be off by a few
 * ulps, while which leaf a point belongs to always follows the tie rules exactly.
 *
 * Thread safety: any number of threads may call the read-only functions (those taking
 * `const qk_tree_t *`) on one tree at once; a call that changes the tree must not run
 * concurrently with any other call on the same tree. Distinct trees are independent.
 *
 * Node and point storage: nodes live in one flat array, the four children of a node
 * stored together in NE, NW, SW, SE order; a leaf's points are a contiguous range of
 * the coordinate arrays. Pointers, ranges and node numbers obtained from a tree stay valid
 * until the next call that changes it (a removal that gives memory back renumbers the
 * nodes).
 */
#ifndef QUADKIT_INDEX_H
#define QUADKIT_INDEX_H

#include <stdio.h>

#include "quadkit/common.h"

#ifdef __cplusplus
extern "C" {
#endif

/** Opaque quadtree handle. */
typedef struct qk_tree qk_tree_t;

/** Default maximum depth of a node (the root has depth 0). */
#define QK_DEFAULT_MAX_DEPTH 40
/** Largest accepted max_depth. */
#define QK_MAX_DEPTH_LIMIT 60
/** Largest number of point ids a tree can hand out (ids are 32-bit). */
#define QK_MAX_POINTS (UINT32_MAX - 1u)

/** Quadrants, in the order in which a node's four children are stored. */
typedef enum qk_quadrant { QK_NE = 0, QK_NW = 1, QK_SW = 2, QK_SE = 3 } qk_quadrant_t;

/** Directions for neighbour finding. */
typedef enum qk_dir { QK_NORTH = 0, QK_EAST = 1, QK_SOUTH = 2, QK_WEST = 3 } qk_dir_t;

/** Options for building a tree; initialise with qk_tree_options_init(). */
typedef struct qk_tree_options {
  /** Most points a leaf holds before it splits; 0 means 1 (the textbook tree). */
  uint32_t capacity;
  /** Deepest node depth; 0 means QK_DEFAULT_MAX_DEPTH; at most QK_MAX_DEPTH_LIMIT. */
  uint32_t max_depth;
  /** Nonzero: use `root` as the root square; zero: the smallest enclosing square of
   *  the points (the unit square [0,1]^2 when there are none). */
  int has_root;
  /** The root square when has_root is nonzero; its side must be positive. */
  qk_square_t root;
  /** Allocator for everything the tree owns; NULL means libc. The pointed-to struct is
   *  copied. With more than one thread it must be thread-safe (libc's is). */
  const qk_allocator_t *allocator;
  /** Threads for the bulk build and, kept by the tree, for its batch queries
   *  (qk_query_*_batch); 0 means every online core. Default 1. Results do not depend on
   *  it. A call on several threads leaves its worker threads parked (waiting, using no
   *  processor) for the next such call with as many threads, from any thread of the
   *  process; they end when the library is unloaded or the process exits. */
  uint32_t threads;
  /** Nonzero: ask the kernel for transparent huge pages (madvise MADV_HUGEPAGE) over the
   *  point arrays when they come from the default allocator and exceed 4 MB; a hint, on
   *  Linux only. Default 0. */
  int huge_pages;
} qk_tree_options_t;

/**
 * Fill options with the defaults (capacity 1, default depth cap, smallest enclosing
 * square, libc allocator, one thread).
 * \param [out] options the options to initialise.
 */
void qk_tree_options_init(qk_tree_options_t *options);

/**
 * Build a tree over an array of points. Point i gets id i.
 * \param [in] points n points; copied, the caller keeps ownership.
 * \param [in] n number of points (at most QK_MAX_POINTS).
 * \param [in] options NULL for defaults.
 * \param [out] out the new tree, freed by the caller with qk_tree_free(); set to NULL on
 *              error.
 * \return QK_OK, QK_ERR_NONFINITE (a NaN/infinite coordinate), QK_ERR_OUTSIDE (a point
 *         outside the given root), QK_ERR_INVALID (bad options), QK_ERR_LIMIT or
 *         QK_ERR_NOMEM.
 */
qk_status_t qk_tree_build(const qk_point_t *points, size_t n, const qk_tree_options_t *options,
                          qk_tree_t **out);

/**
 * qk_tree_build(), saying what was wrong with the input: on QK_ERR_NONFINITE or
 * QK_ERR_OUTSIDE, err->item is the index of the first offending point and err->message
 * names it with its coordinates (and the root, for a point outside it); on QK_ERR_INVALID
 * or QK_ERR_LIMIT the message names the option or count. On success err->item is SIZE_MAX
 * and the message empty. err->line and err->column are 0 (the input is an array).
 * \param [in] points,n,options as qk_tree_build().
 * \param [out] out the new tree, or NULL on error.
 * \param [out] err where and why the input was rejected (may be NULL).
 * \return as qk_tree_build().
 */
qk_status_t qk_tree_build_ex(const qk_point_t *points, size_t n, const qk_tree_options_t *options,
                             qk_tree_t **out, qk_error_t *err);

/**
 * Build the tree again over a new array of points, reusing its memory: the node and point
 * arrays are kept and grown only when too small, so a tree rebuilt every frame stops
 * growing once it has reached its largest size. From the first rebuild on, the tree also
 * keeps the bulk build's record block (20 to 32 bytes a point, counted by
 * qk_tree_memory()) for the next build: the largest block a build asks for, which a C
 * library may give back to the system between builds and fault in again; the rest of the
 * scratch (some 6 bytes a point and the bucket counts) is borrowed for the call. The
 * options it was built with stay (capacity, depth cap, threads, allocator; a given root
 * stays, a fitted root is fitted to the new points). Point i gets id i; the id map and the
 * removed ids are dropped.
 * \param [in,out] tree the tree; unchanged when the input is rejected, and left valid but
 *                  empty on QK_ERR_NOMEM.
 * \param [in] points n points; copied.
 * \param [in] n how many.
 * \param [out] err where and why the input was rejected, as qk_tree_build_ex() (may be
 *              NULL).
 * \return as qk_tree_build_ex().
 */
qk_status_t qk_tree_rebuild(qk_tree_t *tree, const qk_point_t *points, size_t n, qk_error_t *err);

/**
 * Set the number of threads the tree's batch queries use (0: every online core). Must
 * not run concurrently with any other call on the tree.
 * \param [in,out] tree the tree.
 * \param [in] threads the count.
 */
void qk_tree_set_threads(qk_tree_t *tree, uint32_t threads);

/**
 * Free a tree and everything it owns. qk_tree_free(NULL) does nothing.
 * \param [in] tree the tree.
 */
void qk_tree_free(qk_tree_t *tree);

/**
 * Insert a point. It gets the most recently removed id that has not been handed out again
 * (removed ids are kept on a stack and reused last-in first-out), or, when there is none,
 * the next unused id; so the ids of a tree stay below the largest number of points it has
 * held.
 * \param [in,out] tree the tree; unchanged on error.
 * \param [in] p the point; must lie in the closed root square.
 * \param [out] id_out the new id (may be NULL).
 * \return QK_OK, QK_ERR_NONFINITE, QK_ERR_OUTSIDE, QK_ERR_LIMIT or QK_ERR_NOMEM.
 */
qk_status_t qk_tree_insert(qk_tree_t *tree, qk_point_t p, qk_id_t *id_out);

/**
 * Remove a point by id; sibling leaves that now fit in one merge into their parent. The id
 * goes on the stack of ids the next inserts reuse (see qk_tree_insert()). When the tree has
 * shrunk well below what its node or point arrays hold, they are rewritten at its size
 * (nodes renumbered), so that memory follows the points: O(1) amortised a removal.
 * \param [in,out] tree the tree; unchanged on error.
 * \param [in] id the point's id.
 * \return QK_OK, QK_ERR_NOT_FOUND (unknown or already removed id) or QK_ERR_NOMEM.
 */
qk_status_t qk_tree_remove(qk_tree_t *tree, qk_id_t id);

/**
 * Move a stored point to a new location, keeping its id: the same tree as removing it and
 * inserting it there, all or nothing. A move within its leaf only rewrites the
 * coordinates.
 * \param [in,out] tree the tree; unchanged on error.
 * \param [in] id the point's id.
 * \param [in] p the new location; must lie in the closed root square.
 * \return QK_OK, QK_ERR_NONFINITE, QK_ERR_OUTSIDE, QK_ERR_NOT_FOUND or QK_ERR_NOMEM.
 */
qk_status_t qk_tree_move(qk_tree_t *tree, qk_id_t id, qk_point_t p);

/*
 * Id lookups (qk_tree_point, qk_tree_leaf_of) use a map from id to storage slot, 4 bytes
 * per id, which a bulk build does not make: the first lookup or removal makes it, with
 * the tree's allocator, and it is kept up to date from then on. The first lookups may run
 * in several threads at once (then the allocator must be thread-safe, as libc's is); if
 * the map cannot be allocated, a lookup still answers, by a scan of the points.
 */

/**
 * The coordinates of a stored point.
 * \param [in] tree the tree.
 * \param [in] id the point's id.
 * \param [out] p its coordinates.
 * \return QK_OK or QK_ERR_NOT_FOUND.
 */
qk_status_t qk_tree_point(const qk_tree_t *tree, qk_id_t id, qk_point_t *p);

/**
 * The leaf that holds a stored point.
 * \param [in] tree the tree.
 * \param [in] id the point's id.
 * \param [out] leaf the leaf.
 * \return QK_OK or QK_ERR_NOT_FOUND.
 */
qk_status_t qk_tree_leaf_of(const qk_tree_t *tree, qk_id_t id, qk_node_t *leaf);

/**
 * The leaf whose square holds a location, following the quadrant tie rules (so squares
 * are half-open on their west and south sides, the root's outer edges included).
 * \param [in] tree the tree.
 * \param [in] p any location.
 * \param [out] leaf the leaf.
 * \return QK_OK, QK_ERR_NONFINITE or QK_ERR_OUTSIDE.
 */
qk_status_t qk_tree_find_leaf(const qk_tree_t *tree, qk_point_t p, qk_node_t *leaf);

/** Facts about one node. */
typedef struct qk_node_info {
  qk_square_t square;     /**< the node's square */
  uint32_t depth;         /**< 0 for the root */
  qk_node_t parent;       /**< QK_NONE for the root */
  qk_node_t children[4];  /**< NE, NW, SW, SE; all QK_NONE for a leaf */
  qk_quadrant_t quadrant; /**< which child of its parent it is (QK_NE for the root) */
  int is_leaf;            /**< nonzero for a leaf */
  size_t count;           /**< points in the node's subtree */
} qk_node_info_t;

/** The root node (always valid). */
qk_node_t qk_tree_root(const qk_tree_t *tree);

/**
 * Facts about a node.
 * \param [in] tree the tree.
 * \param [in] node a node of the tree.
 * \param [out] info the facts.
 * \return QK_OK, QK_ERR_NOT_FOUND for an id that is not a live node, or QK_ERR_INVALID
 *         (a NULL argument).
 */
qk_status_t qk_tree_node_info(const qk_tree_t *tree, qk_node_t node, qk_node_info_t *info);

/** Nonzero when node is a live leaf of the tree. */
int qk_tree_node_is_leaf(const qk_tree_t *tree, qk_node_t node);

/**
 * The points of a leaf, as borrowed arrays valid until the tree next changes.
 * \param [in] tree the tree.
 * \param [in] leaf a leaf.
 * \param [out] x,y,ids the coordinates and ids of its points (any may be NULL).
 * \param [out] n how many.
 * \return QK_OK, or QK_ERR_INVALID when leaf is not a leaf.
 */
qk_status_t qk_tree_leaf_points(const qk_tree_t *tree, qk_node_t leaf, const double **x,
                                const double **y, const qk_id_t **ids, size_t *n);

/** What a visitor tells the walk to do next. */
typedef enum qk_visit {
  QK_VISIT_CONTINUE = 0, /**< go on, descending into this node's children */
  QK_VISIT_SKIP = 1,     /**< go on, but not below this node */
  QK_VISIT_STOP = 2      /**< end the walk */
} qk_visit_t;

/** Called once per node in pre-order (a node before its children, NE, NW, SW, SE). */
typedef qk_visit_t (*qk_visit_fn)(const qk_tree_t *tree, qk_node_t node, void *ud);

/**
 * Walk the subtree of a node in pre-order.
 * \param [in] tree the tree.
 * \param [in] start where to start (qk_tree_root() for the whole tree).
 * \param [in] fn the visitor.
 * \param [in] ud passed to fn.
 * \return QK_OK (also when the visitor stopped the walk) or QK_ERR_NOT_FOUND.
 */
qk_status_t qk_tree_visit(const qk_tree_t *tree, qk_node_t start, qk_visit_fn fn, void *ud);

/**
 * List the leaves in pre-order (Z-order: NE, NW, SW, SE at each level).
 * \param [in] tree the tree.
 * \param [out] leaves buffer for up to cap leaves (may be NULL when cap is 0).
 * \param [in] cap its size.
 * \param [out] n_out the total number of leaves (may exceed cap; then only cap written).
 * \return QK_OK.
 */
qk_status_t qk_tree_leaves(const qk_tree_t *tree, qk_node_t *leaves, size_t cap, size_t *n_out);

/** Tree statistics. */
typedef struct qk_tree_stats {
  uint32_t height;        /**< greatest node depth (0 for a single leaf) */
  size_t nodes;           /**< live nodes */
  size_t leaves;          /**< live leaves */
  size_t points;          /**< points stored */
  size_t max_leaf_points; /**< most points in one leaf */
  size_t capped_leaves;   /**< leaves over capacity because they cannot split */
  size_t memory_bytes;    /**< bytes held by the tree */
  uint32_t capacity;      /**< the tree's capacity */
  uint32_t max_depth;     /**< the tree's depth cap */
  qk_square_t root;       /**< the root square */
} qk_tree_stats_t;

/**
 * Compute statistics.
 * \param [in] tree the tree.
 * \param [out] stats the figures.
 */
void qk_tree_stats(const qk_tree_t *tree, qk_tree_stats_t *stats);

/** Bytes held by the tree (all arrays at their allocated size). */
size_t qk_tree_memory(const qk_tree_t *tree);

/**
 * Verify every invariant: links between parents and children, depths and squares,
 * subtree counts, each point inside its leaf by the quadrant rules of every ancestor,
 * leaf ranges disjoint, the id map, and the shape rule (a leaf over capacity only where
 * it cannot split; for an unrefined tree also every internal node over capacity).
 * \param [in] tree the tree.
 * \param [out] msg buffer for a description of the first violation (may be NULL).
 * \param [in] msg_size its size.
 * \return QK_OK, QK_ERR_CORRUPT, QK_ERR_INVALID (no tree), or QK_ERR_NOMEM when its
 *         scratch memory (a byte per slot and per id, from the tree's allocator) cannot
 *         be had.
 */
qk_status_t qk_tree_check(const qk_tree_t *tree, char *msg, size_t msg_size);

/**
 * The book's NorthNeighbor, generalised to four directions: the deepest node of depth
 * at most depth(node) whose square is adjacent to node's square across side `dir`, or
 * QK_NONE when node's side lies on the root square's boundary. O(depth + 1) time.
 * \param [in] tree the tree.
 * \param [in] node any live node.
 * \param [in] dir the side.
 * \return the neighbour, or QK_NONE (on the root's boundary, and for a node that is not
 *         live or a direction that is none of the four).
 */
qk_node_t qk_tree_neighbor(const qk_tree_t *tree, qk_node_t node, qk_dir_t dir);

/**
 * Every leaf adjacent to node across side `dir` (sharing a segment of positive length),
 * ordered west to east (north/south sides) or south to north (east/west sides).
 * \param [in] tree the tree.
 * \param [in] node any live node.
 * \param [in] dir the side.
 * \param [out] out buffer for up to cap leaves (may be NULL when cap is 0).
 * \param [in] cap its size.
 * \param [out] n_out total number of such leaves (only min(cap, total) are written).
 * \return QK_OK, QK_ERR_NOT_FOUND (not a live node) or QK_ERR_INVALID (a NULL tree or
 *         n_out, a NULL out with cap > 0, or dir not a side).
 */
qk_status_t qk_tree_adjacent_leaves(const qk_tree_t *tree, qk_node_t node, qk_dir_t dir,
                                    qk_node_t *out, size_t cap, size_t *n_out);

/**
 * Split one leaf into four children, moving its points into them, regardless of the
 * capacity rule (but never beyond the depth cap). Marks the tree refined.
 * \param [in,out] tree the tree; unchanged on error.
 * \param [in] leaf the leaf to split.
 * \return QK_OK, QK_ERR_INVALID (not a leaf), QK_ERR_LIMIT (at the depth cap or too
 *         small to halve) or QK_ERR_NOMEM.
 */
qk_status_t qk_tree_split_leaf(qk_tree_t *tree, qk_node_t leaf);

/** Decides whether a leaf of a refinement should be split (nonzero: split). */
typedef int (*qk_refine_fn)(const qk_tree_t *tree, qk_node_t leaf, qk_square_t square,
                            uint32_t depth, void *ud);

/**
 * Split leaves, top-down, while `fn` asks for it (as CGAL Orthtree's refine); stops at
 * the depth cap. Marks the tree refined.
 * \param [in,out] tree the tree.
 * \param [in] fn the split predicate.
 * \param [in] ud passed to fn.
 * \return QK_OK or QK_ERR_NOMEM (the splits made so far stay; the tree is valid).
 */
qk_status_t qk_tree_refine(qk_tree_t *tree, qk_refine_fn fn, void *ud);

/**
 * BalanceQuadTree: split leaves until any two leaves whose squares share an edge
 * differ by at most a factor 2 in side length; points move into the new leaves.
 * O((d+1) m) time for m nodes and depth d. Marks the tree refined. A leaf that cannot
 * split (depth cap, or too small to halve in double precision) stays as it is; then
 * qk_tree_is_balanced() may still return 0.
 * \param [in,out] tree the tree.
 * \return QK_OK or QK_ERR_NOMEM (the tree stays valid, possibly partly balanced).
 */
qk_status_t qk_tree_balance(qk_tree_t *tree);

/** Nonzero when every two edge-adjacent leaves differ by at most one in depth. */
int qk_tree_is_balanced(const qk_tree_t *tree);

/**
 * Draw the tree as SVG: the cells, and the points as dots. Numbers are written in the C
 * locale ("400.000") whatever locale the program or the calling thread set.
 * \param [in] tree the tree.
 * \param [in] f an open stream, owned by the caller.
 * \param [in] width picture width in pixels (0 means 800).
 * \return QK_OK or QK_ERR_IO (the stream is flushed, so a write it refused is seen).
 */
qk_status_t qk_tree_write_svg(const qk_tree_t *tree, FILE *f, unsigned width);

#ifdef __cplusplus
}
#endif

#endif /* QUADKIT_INDEX_H */
