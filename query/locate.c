/*
 * Point location: the descent of qk_tree_find_leaf(), packaged with the leaf's square
 * and points so that callers need no second lookup. The square comes from the path.
 */
#include "query/query_internal.h"

qk_status_t qk_query_locate(const qk_tree_t *tree, qk_point_t p, qk_location_t *loc) {
  if (!tree || !loc) return QK_ERR_INVALID;
  if (!isfinite(p.x) || !isfinite(p.y)) return QK_ERR_NONFINITE;
  if (!qk__tree_contains(tree, p.x, p.y)) return QK_ERR_OUTSIDE;
  unsigned depth;
  qk_node_t leaf = qk__tree_descend(tree, p.x, p.y, &loc->square, &depth);
  uint32_t start = qk__node_start(tree, leaf);
  loc->leaf = leaf;
  loc->depth = depth;
  loc->count = qk__node_count(tree, leaf);
  loc->x = qk__tree_xs(tree) + start;
  loc->y = qk__tree_ys(tree) + start;
  loc->ids = qk__tree_ids(tree) + start;
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
    if (j % QK__LANES == 0) qk__prefetch_paths(tree, ps, order, j, n);
    qk_point_t p = ps[i];
    int ok = isfinite(p.x) && isfinite(p.y) && qk__tree_contains(tree, p.x, p.y);
    leaves[i] = ok ? qk__tree_descend(tree, p.x, p.y, NULL, NULL) : QK_NONE;
  }
  if (block) qk__morton_free(tree, block, n);
  return QK_OK;
}
