/*
 * The narrow interface through which the modules built on index/ (query/, collide/,
 * region/, mesh/) read a tree's structure. Not API, and not the layout: index/ may store
 * its nodes however it likes, and only this file and the index/ sources know how. Outside index/,
 * code includes this header, never index_internal.h; CI rejects `->nodes[`, `->side[`,
 * `->px`, `->py` and `->pid` outside index/.
 *
 * Nodes are named by qk_node_t (0 is the root). The four children of an internal node are
 * consecutive ids, first + QK_NE .. first + QK_SE. A leaf's points occupy the slots
 * [start, start + count) of three parallel arrays (x, y, id), which stay valid until the
 * tree is next modified. Descents that need many squares should compute them from the
 * path (the root square halved, a corner moved per quadrant, as qk__child_square() does)
 * rather than ask for each node's: the path is in registers, a node's square may not be.
 */
#ifndef QUADKIT_INDEX_ACCESS_H
#define QUADKIT_INDEX_ACCESS_H

#include "index/index_internal.h"

/* ---- the tree as a whole -------------------------------------------------------- */

/* The allocator every structure derived from the tree should use. */
static inline const qk_allocator_t *qk__tree_allocator(const qk_tree_t *t) { return &t->alloc; }

/* Points stored. */
static inline size_t qk__tree_count(const qk_tree_t *t) { return t->n_points; }

/* Node ids in use are below this bound (ids of free blocks included). */
static inline uint32_t qk__tree_node_bound(const qk_tree_t *t) { return t->n_nodes; }

/* Point slots in use are below this bound (slots owned by no leaf included). */
static inline uint32_t qk__tree_slot_bound(const qk_tree_t *t) { return t->n_slots; }

/* The point arrays, indexed by slot. */
static inline const double *qk__tree_xs(const qk_tree_t *t) { return t->px; }
static inline const double *qk__tree_ys(const qk_tree_t *t) { return t->py; }
static inline const qk_id_t *qk__tree_ids(const qk_tree_t *t) { return t->pid; }

/* Side length of the squares at a depth (exact halvings of the root's). */
static inline double qk__tree_side(const qk_tree_t *t, unsigned depth) { return t->side[depth]; }

/* The root's square. */
static inline qk_square_t qk__tree_root_square(const qk_tree_t *t) {
  return (qk_square_t){t->nodes[0].x0, t->nodes[0].y0, t->side[0]};
}

/* ---- one node ------------------------------------------------------------------- */

/* First of the four children, or QK_NONE for a leaf. */
static inline uint32_t qk__node_child(const qk_tree_t *t, qk_node_t v) { return t->nodes[v].child; }

static inline bool qk__node_leaf(const qk_tree_t *t, qk_node_t v) {
  return t->nodes[v].child == QK_NONE;
}

static inline unsigned qk__node_depth(const qk_tree_t *t, qk_node_t v) { return t->nodes[v].depth; }

/* A node's square (a cold read: prefer squares computed along the path). */
static inline qk_square_t qk__node_square(const qk_tree_t *t, qk_node_t v) {
  const qk__node_t *n = &t->nodes[v];
  return (qk_square_t){n->x0, n->y0, t->side[n->depth]};
}

/* First slot of a leaf's points. */
static inline uint32_t qk__node_start(const qk_tree_t *t, qk_node_t v) { return t->nodes[v].start; }

/* Points in a node's subtree (for a leaf: its own). */
static inline uint32_t qk__node_count(const qk_tree_t *t, qk_node_t v) { return t->nodes[v].count; }

/* A hint that node v will be read soon. */
static inline void qk__node_prefetch(const qk_tree_t *t, qk_node_t v) {
#if defined(__GNUC__)
  __builtin_prefetch(&t->nodes[v]);
#else
  (void)t;
  (void)v;
#endif
}

/* ---- squares along a path --------------------------------------------------------- */

/* The square of child q of a node of square s. */
static inline qk_square_t qk__child_square(qk_square_t s, unsigned q) {
  double h = s.side * 0.5;
  return (qk_square_t){s.x + (qk__q_east(q) ? h : 0.0), s.y + (qk__q_north(q) ? h : 0.0), h};
}

#endif /* QUADKIT_INDEX_ACCESS_H */
