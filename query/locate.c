/*
 * Point location: the descent of qk_tree_find_leaf(), packaged with the leaf's square
 * and points so that callers need no second lookup.
 */
#include "query/query_internal.h"

qk_status_t qk_query_locate(const qk_tree_t *tree, qk_point_t p, qk_location_t *loc) {
  if (!tree || !loc) return QK_ERR_INVALID;
  qk_node_t leaf;
  qk_status_t st = qk_tree_find_leaf(tree, p, &leaf);
  if (st != QK_OK) return st;
  const qk__node_t *n = &tree->nodes[leaf];
  loc->leaf = leaf;
  loc->square.x = n->x0;
  loc->square.y = n->y0;
  loc->square.side = tree->side[n->depth];
  loc->depth = n->depth;
  loc->count = n->count;
  loc->x = tree->px + n->start;
  loc->y = tree->py + n->start;
  loc->ids = tree->pid + n->start;
  return QK_OK;
}

qk_status_t qk_query_locate_batch(const qk_tree_t *tree, const qk_point_t *ps, size_t n,
                                  qk_node_t *leaves) {
  if (!tree || (n > 0 && (!ps || !leaves))) return QK_ERR_INVALID;
  /* In Z-order of the locations when the batch is large, so that consecutive descents
   * share their path through the cache; in the given order otherwise. */
  uint32_t *order;
  void *block = qk__morton_order(tree, ps, n, &order);
  for (size_t j = 0; j < n; j++) {
    size_t i = order ? order[j] : j;
    if (qk_tree_find_leaf(tree, ps[i], &leaves[i]) != QK_OK) leaves[i] = QK_NONE;
  }
  if (block) qk__morton_free(tree, block, n);
  return QK_OK;
}
