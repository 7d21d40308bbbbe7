/*
 * Neighbour finding (lecture notes, section IV): the book's NorthNeighbor, written once
 * for all four directions by naming, for a direction, the coordinate bit it flips.
 */
#include "index/index_internal.h"

/*
 * NorthNeighbor(v) generalised. If v is not on the `dir` side of its parent, the
 * neighbour is its mirrored sibling (notes, lines 4-7). Otherwise find the parent's
 * neighbour u (line 8); if u is nil or a leaf it is the answer (lines 9-10), else the
 * answer is u's child mirrored from v's quadrant (lines 11-13). Written as a loop: first
 * climb to the lowest ancestor that is not on the `dir` side, then come back down.
 */
qk_node_t qk_tree_neighbor(const qk_tree_t *t, qk_node_t v, qk_dir_t dir) {
  if (!t || !qk__live(t, v) || (unsigned)dir > QK_WEST) return QK_NONE;
  unsigned char path[QK_MAX_DEPTH_LIMIT + 2];
  unsigned len = 0;
  uint32_t a = v;
  while (a != 0 && qk__on_side(qk__quadrant(a), dir)) {
    path[len++] = (unsigned char)qk__quadrant(a);
    a = qk__parent(t, a);
  }
  if (a == 0) return QK_NONE; /* the side lies on the root square's boundary */
  /* a's sibling across the side: same block, so a - quadrant(a) is the block's first. */
  uint32_t u = a - qk__quadrant(a) + qk__mirror(qk__quadrant(a), dir);
  while (len > 0 && !qk__is_leaf(&t->nodes[u]))
    u = t->nodes[u].child + qk__mirror(path[--len], dir);
  return u;
}

typedef struct adj {
  qk_node_t *out;
  size_t cap, n;
} adj_t;

static void push(adj_t *a, qk_node_t v) {
  if (a->n < a->cap) a->out[a->n] = v;
  a->n++;
}

static void collect(const qk_tree_t *t, uint32_t u, qk_dir_t dir, adj_t *a) {
  const qk__node_t *n = &t->nodes[u];
  if (qk__is_leaf(n)) {
    push(a, u);
    return;
  }
  unsigned q[2];
  qk__facing_children(dir, q);
  collect(t, n->child + q[0], dir, a);
  collect(t, n->child + q[1], dir, a);
}

qk_status_t qk_tree_adjacent_leaves(const qk_tree_t *t, qk_node_t v, qk_dir_t dir, qk_node_t *out,
                                    size_t cap, size_t *n_out) {
  if (!t || !n_out || (cap && !out) || (unsigned)dir > QK_WEST) return QK_ERR_INVALID;
  if (!qk__live(t, v)) return QK_ERR_NOT_FOUND;
  adj_t a = {out, cap, 0};
  qk_node_t u = qk_tree_neighbor(t, v, dir);
  if (u != QK_NONE) collect(t, u, dir, &a);
  *n_out = a.n;
  return QK_OK;
}
