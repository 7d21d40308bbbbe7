/* Traversal, leaf listing and statistics. */
#include "index/index_internal.h"

qk_status_t qk_tree_visit(const qk_tree_t *t, qk_node_t start, qk_visit_fn fn, void *ud) {
  if (!t || !fn) return QK_ERR_INVALID;
  if (!qk__live(t, start)) return QK_ERR_NOT_FOUND;
  /* Pre-order with an explicit stack: each level leaves at most three siblings pending. */
  uint32_t stack[4 * (QK_MAX_DEPTH_LIMIT + 2)], top = 0;
  stack[top++] = start;
  while (top) {
    uint32_t v = stack[--top];
    qk_visit_t r = fn(t, v, ud);
    if (r == QK_VISIT_STOP) break;
    const qk__node_t *n = &t->nodes[v];
    if (r == QK_VISIT_SKIP || qk__is_leaf(n)) continue;
    for (int q = 3; q >= 0; q--) stack[top++] = n->child + (uint32_t)q;
  }
  return QK_OK;
}

typedef struct leaf_list {
  qk_node_t *out;
  size_t cap, n;
} leaf_list_t;

static qk_visit_t collect_leaf(const qk_tree_t *t, qk_node_t v, void *ud) {
  leaf_list_t *l = ud;
  if (qk__is_leaf(&t->nodes[v])) {
    if (l->n < l->cap) l->out[l->n] = v;
    l->n++;
  }
  return QK_VISIT_CONTINUE;
}

qk_status_t qk_tree_leaves(const qk_tree_t *t, qk_node_t *leaves, size_t cap, size_t *n_out) {
  if (!t || !n_out || (cap && !leaves)) return QK_ERR_INVALID;
  leaf_list_t l = {leaves, cap, 0};
  qk_status_t st = qk_tree_visit(t, 0, collect_leaf, &l);
  *n_out = l.n;
  return st;
}

size_t qk_tree_memory(const qk_tree_t *t) {
  if (!t) return 0;
  return sizeof *t + (size_t)t->cap_nodes * sizeof(qk__node_t) +
         (size_t)t->cap_blocks * sizeof(qk__block_t) + (size_t)t->cap_free_ids * sizeof(qk_id_t) +
         (size_t)t->cap_slots * (2 * sizeof(double) + sizeof(qk_id_t)) +
         (qk__id_map_if_made(t) ? (size_t)qk__id_map_capacity(t) * sizeof(uint32_t) : 0) +
         t->kept_rec_bytes;
}

static qk_visit_t count_node(const qk_tree_t *t, qk_node_t v, void *ud) {
  qk_tree_stats_t *s = ud;
  const qk__node_t *n = &t->nodes[v];
  s->nodes++;
  if (qk__depth(t, v) > s->height) s->height = qk__depth(t, v);
  if (qk__is_leaf(n)) {
    s->leaves++;
    if (n->count > s->max_leaf_points) s->max_leaf_points = n->count;
    if (n->count > t->capacity) s->capped_leaves++;
  }
  return QK_VISIT_CONTINUE;
}

void qk_tree_stats(const qk_tree_t *t, qk_tree_stats_t *s) {
  if (!s) return;
  *s = (qk_tree_stats_t){0};
  if (!t) return;
  if (qk_tree_visit(t, 0, count_node, s) != QK_OK) return; /* (cannot fail: t, its root) */
  s->points = t->n_points;
  s->memory_bytes = qk_tree_memory(t);
  s->capacity = t->capacity;
  s->max_depth = t->max_depth;
  s->root.x = t->root_x;
  s->root.y = t->root_y;
  s->root.side = t->side[0];
}
