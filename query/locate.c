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
