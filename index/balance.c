/*
 * BalanceQuadTree (lecture notes, section V; de Berg et al., ch. 14.2): split leaves
 * until any two leaves whose squares share an edge differ by at most one in depth.
 */
#include "index/index_internal.h"

/*
 * The notes' first issue (line 4): a leaf must be split exactly when a neighbouring
 * square is less than half its size. Such a neighbour exists towards `dir` iff the
 * neighbour u found by NorthNeighbor is internal (then of the leaf's own depth) and one
 * of its two children facing the leaf is not a leaf.
 */
static bool has_small_neighbor(const qk_tree_t *t, uint32_t leaf) {
  for (int d = 0; d < 4; d++) {
    qk_node_t u = qk_tree_neighbor(t, leaf, (qk_dir_t)d);
    if (u == QK_NONE || qk__is_leaf(&t->nodes[u])) continue;
    unsigned q[2];
    qk__facing_children((qk_dir_t)d, q);
    if (!qk__is_leaf(&t->nodes[t->nodes[u].child + q[0]]) ||
        !qk__is_leaf(&t->nodes[t->nodes[u].child + q[1]]))
      return true;
  }
  return false;
}

/* A growable stack of node ids: the notes' linear list L. */
typedef struct stack {
  uint32_t *v;
  size_t n, cap;
} stack_t_;

/* Make room for `extra` more entries. */
static qk_status_t reserve(const qk_tree_t *t, stack_t_ *s, size_t extra) {
  if (s->cap - s->n >= extra) return QK_OK;
  size_t nc = 2 * s->cap + extra + 64;
  uint32_t *nv = qk__realloc(&t->alloc, s->v, s->cap * sizeof *nv, nc * sizeof *nv);
  if (!nv) return QK_ERR_NOMEM;
  s->v = nv;
  s->cap = nc;
  return QK_OK;
}

qk_status_t qk_tree_balance(qk_tree_t *t) {
  if (!t) return QK_ERR_INVALID;
  t->refined = true;
  stack_t_ s = {NULL, 0, 0};
  qk_status_t st = QK_OK;

  /* Line 1: every leaf goes into the list. */
  for (uint32_t i = 0; i < t->n_nodes && st == QK_OK; i++)
    if (qk__live(t, i) && qk__is_leaf(&t->nodes[i]) && (st = reserve(t, &s, 1)) == QK_OK)
      s.v[s.n++] = i;

  /* Lines 2-10. A node may sit in the list more than once or have been split since it
   * was pushed; such entries are skipped, which keeps the work O((d+1) m). */
  while (st == QK_OK && s.n > 0) {
    uint32_t v = s.v[--s.n];
    if (!qk__live(t, v) || !qk__is_leaf(&t->nodes[v])) continue;
    if (!has_small_neighbor(t, v)) continue;
    qk__geom_t g = qk__node_geom(t, v);
    if (!qk__can_split(t, g)) continue;
    /* Reserve (and grow the list) before splitting so that a failure leaves the tree
     * valid and every leaf that still needs attention is known. */
    if ((st = qk__reserve_nodes(t, 4)) != QK_OK) break;
    if ((st = reserve(t, &s, 8)) != QK_OK) break;
    /* Lines 5-7: qk__split moves the leaf's points into the correct new leaves. */
    uint32_t b = qk__split(t, v, g);
    /* Line 8: the new leaves may themselves need splitting. */
    for (uint32_t q = 0; q < 4; q++) s.v[s.n++] = b + q;
    /* Lines 9-10, the notes' second issue: a neighbour of v that is larger than v (found
     * by NorthNeighbor as a leaf of smaller depth) is now more than twice the size of the
     * new leaves beside it and must be split. */
    for (int d = 0; d < 4; d++) {
      qk_node_t u = qk_tree_neighbor(t, v, (qk_dir_t)d);
      if (u != QK_NONE && qk__is_leaf(&t->nodes[u]) && qk__depth(t, u) < g.depth) s.v[s.n++] = u;
    }
  }
  qk__free(&t->alloc, s.v, s.cap * sizeof *s.v);
  return st;
}

int qk_tree_is_balanced(const qk_tree_t *t) {
  if (!t) return 0;
  /* Checking every leaf for a neighbour less than half its size covers every pair of
   * adjacent leaves, since of two leaves differing by two or more levels the larger one
   * sees the smaller. */
  for (uint32_t i = 0; i < t->n_nodes; i++)
    if (qk__live(t, i) && qk__is_leaf(&t->nodes[i]) && has_small_neighbor(t, i)) return 0;
  return 1;
}
