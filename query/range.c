/*
 * Range and radius queries: the book's range search on a quadtree (ch. 14), descending
 * only into nodes whose (slightly widened) square meets the query region and testing
 * each point of the leaves reached. The traversal uses a fixed stack, so it never
 * allocates.
 */
#include "query/query_internal.h"

/* A box test for the leaves, shared by the callback and the buffer form. */
typedef int (*qk__emit_fn)(void *ctx, qk_id_t id, double x, double y, double dist);

static qk_status_t range_walk(const qk_tree_t *t, qk_box_t b, qk__emit_fn emit, void *ctx) {
  if (isnan(b.xmin) || isnan(b.ymin) || isnan(b.xmax) || isnan(b.ymax)) return QK_ERR_NONFINITE;
  if (b.xmin > b.xmax || b.ymin > b.ymax || t->n_points == 0) return QK_OK;
  const double e = qk__margin(t);
  uint32_t stack[QK__STACK_MAX];
  int sp = 0;
  stack[sp++] = 0;
  while (sp > 0) {
    const qk__node_t *n = &t->nodes[stack[--sp]];
    if (n->count == 0) continue;
    if (qk__is_leaf(n)) {
      const double *px = t->px + n->start, *py = t->py + n->start;
      const qk_id_t *pid = t->pid + n->start;
      for (uint32_t i = 0; i < n->count; i++) {
        double x = px[i], y = py[i];
        if (x >= b.xmin && x <= b.xmax && y >= b.ymin && y <= b.ymax)
          if (emit(ctx, pid[i], x, y, 0.0)) return QK_OK;
      }
      continue;
    }
    /* Test the children's squares, derived from this node's, before pushing them, so
     * that a pruned child's node is never read. */
    const double hs = t->side[n->depth + 1];
    const double xlo[2] = {n->x0 - e, n->x0 + hs - e},
                 xhi[2] = {n->x0 + hs + e, n->x0 + 2 * hs + e};
    const double ylo[2] = {n->y0 - e, n->y0 + hs - e},
                 yhi[2] = {n->y0 + hs + e, n->y0 + 2 * hs + e};
    for (int c = 3; c >= 0; c--) {
      unsigned east = qk__q_east((unsigned)c), north = qk__q_north((unsigned)c);
      if (xlo[east] > b.xmax || xhi[east] < b.xmin || ylo[north] > b.ymax || yhi[north] < b.ymin)
        continue;
      stack[sp++] = n->child + (uint32_t)c;
    }
  }
  return QK_OK;
}

static qk_status_t radius_walk(const qk_tree_t *t, qk_point_t c, double r, qk__emit_fn emit,
                               void *ctx) {
  if (!isfinite(c.x) || !isfinite(c.y) || isnan(r)) return QK_ERR_NONFINITE;
  if (r < 0) return QK_ERR_INVALID;
  if (t->n_points == 0) return QK_OK;
  const double r2 = r * r, e = qk__margin(t);
  uint32_t stack[QK__STACK_MAX];
  int sp = 0;
  stack[sp++] = 0;
  if (qk__cell_d2(t, &t->nodes[0], c.x, c.y, e) > r2) return QK_OK;
  while (sp > 0) {
    const qk__node_t *n = &t->nodes[stack[--sp]];
    if (n->count == 0) continue;
    if (qk__is_leaf(n)) {
      const double *px = t->px + n->start, *py = t->py + n->start;
      const qk_id_t *pid = t->pid + n->start;
      for (uint32_t i = 0; i < n->count; i++) {
        double dx = px[i] - c.x, dy = py[i] - c.y;
        double d2 = dx * dx + dy * dy;
        if (d2 <= r2)
          if (emit(ctx, pid[i], px[i], py[i], sqrt(d2))) return QK_OK;
      }
      continue;
    }
    /* As for boxes: bound the children from this node's square before pushing them. */
    const double hs = t->side[n->depth + 1], x0 = n->x0, y0 = n->y0;
    const double cx[4] = {x0 + hs, x0, x0, x0 + hs}, cy[4] = {y0 + hs, y0 + hs, y0, y0};
    for (int k = 3; k >= 0; k--)
      if (qk__square_d2(cx[k], cy[k], hs, c.x, c.y, e) <= r2) stack[sp++] = n->child + (uint32_t)k;
  }
  return QK_OK;
}

/* Adapters from the internal emitter to the public callback and buffers. */
typedef struct cb_ctx {
  qk_found_fn fn;
  void *ud;
} cb_ctx_t;

static int emit_cb(void *ctx, qk_id_t id, double x, double y, double dist) {
  cb_ctx_t *c = ctx;
  qk_point_t p = {x, y};
  return c->fn(id, p, dist, c->ud);
}

typedef struct buf_ctx {
  qk_id_t *ids;
  qk_neighbor_t *nb;
  size_t cap, n;
} buf_ctx_t;

static int emit_ids(void *ctx, qk_id_t id, double x, double y, double dist) {
  buf_ctx_t *b = ctx;
  (void)x, (void)y, (void)dist;
  if (b->n < b->cap) b->ids[b->n] = id;
  b->n++;
  return 0;
}

static int emit_nb(void *ctx, qk_id_t id, double x, double y, double dist) {
  buf_ctx_t *b = ctx;
  (void)x, (void)y;
  if (b->n < b->cap) {
    b->nb[b->n].id = id;
    b->nb[b->n].dist = dist;
  }
  b->n++;
  return 0;
}

qk_status_t qk_query_range(const qk_tree_t *tree, qk_box_t box, qk_found_fn fn, void *ud) {
  if (!tree || !fn) return QK_ERR_INVALID;
  cb_ctx_t c = {fn, ud};
  return range_walk(tree, box, emit_cb, &c);
}

qk_status_t qk_query_range_ids(const qk_tree_t *tree, qk_box_t box, qk_id_t *ids, size_t cap,
                               size_t *n_out) {
  if (!tree || !n_out || (cap > 0 && !ids)) return QK_ERR_INVALID;
  buf_ctx_t b = {ids, NULL, cap, 0};
  qk_status_t st = range_walk(tree, box, emit_ids, &b);
  *n_out = b.n;
  return st;
}

qk_status_t qk_query_radius(const qk_tree_t *tree, qk_point_t c, double r, qk_found_fn fn,
                            void *ud) {
  if (!tree || !fn) return QK_ERR_INVALID;
  cb_ctx_t cc = {fn, ud};
  return radius_walk(tree, c, r, emit_cb, &cc);
}

qk_status_t qk_query_radius_list(const qk_tree_t *tree, qk_point_t c, double r, qk_neighbor_t *out,
                                 size_t cap, size_t *n_out) {
  if (!tree || !n_out || (cap > 0 && !out)) return QK_ERR_INVALID;
  buf_ctx_t b = {NULL, out, cap, 0};
  qk_status_t st = radius_walk(tree, c, r, emit_nb, &b);
  *n_out = b.n;
  return st;
}

qk_status_t qk_query_radius_batch(const qk_tree_t *tree, const qk_point_t *centres, size_t nq,
                                  double r, qk_neighbor_t *out, size_t cap, size_t *offsets) {
  if (!tree || !offsets || (nq > 0 && !centres) || (cap > 0 && !out)) return QK_ERR_INVALID;
  if (isnan(r)) return QK_ERR_NONFINITE;
  if (r < 0) return QK_ERR_INVALID;
  qk_status_t first = QK_OK;
  size_t total = 0;
  for (size_t i = 0; i < nq; i++) {
    offsets[i] = total;
    /* Each query writes straight after the previous one, into what is left of out. */
    buf_ctx_t b = {NULL, out ? out + (total < cap ? total : cap) : NULL,
                   total < cap ? cap - total : 0, 0};
    qk_status_t st = radius_walk(tree, centres[i], r, emit_nb, &b);
    if (st != QK_OK && first == QK_OK) first = st;
    total += b.n;
  }
  offsets[nq] = total;
  if (first == QK_OK && total > cap) first = QK_ERR_LIMIT;
  return first;
}
