/*
 * Range and radius queries: the book's range search on a quadtree (ch. 14), descending
 * only into nodes whose (slightly widened) square meets the query region and testing
 * each point of the leaves reached. The traversal uses a fixed stack, so it never
 * allocates.
 */
#include "index/dist_exact.h"
#include "query/query_internal.h"
#include "index/inline.h"

/* A box test for the leaves, shared by the callback and the buffer form. */
typedef int (*qk__emit_fn)(void *ctx, qk_id_t id, double x, double y, double dist);

static qk_status_t range_walk(const qk_tree_t *t, qk_box_t b, qk__emit_fn emit, void *ctx) {
  if (isnan(b.xmin) || isnan(b.ymin) || isnan(b.xmax) || isnan(b.ymax)) return QK_ERR_NONFINITE;
  if (b.xmin > b.xmax || b.ymin > b.ymax || qk__tree_count(t) == 0) return QK_OK;
  const double e = qk__margin(t);
  const double *xs = qk__tree_xs(t), *ys = qk__tree_ys(t);
  const qk_id_t *ids = qk__tree_ids(t);
  qk__cell_t stack[QK__STACK_MAX];
  int sp = 0;
  uint32_t pf_lo = 0, pf_hi = 0;
  stack[sp++] = qk__root_cell(t);
  while (sp > 0) {
    const qk__cell_t c = stack[--sp];
    const uint32_t child = qk__node_child(t, c.node);
    if (child == QK_NONE) {
      const uint32_t start = qk__node_start(t, c.node), count = qk__node_count(t, c.node);
      const double *px = xs + start, *py = ys + start;
      const qk_id_t *pid = ids + start;
      for (uint32_t i = 0; i < count; i++) {
        double x = px[i], y = py[i];
        if (x >= b.xmin && x <= b.xmax && y >= b.ymin && y <= b.ymax)
          if (emit(ctx, pid[i], x, y, 0.0)) return QK_OK;
      }
      continue;
    }
    /* A small subtree's points, ahead of its leaves (docs/query.md, eleventh round). */
    qk__ask_subtree(t, c.node, &pf_lo, &pf_hi);
    /* Test the children's squares, derived from this node's, before pushing them, so
     * that a pruned child's node is never read. */
    const double hs = qk__tree_side(t, c.depth + 1);
    qk__cell_t kids[4];
    qk__cell_children(t, c, child, kids);
    for (int q = 3; q >= 0; q--) {
      const qk__cell_t k = kids[q];
      if (k.x - e > b.xmax || k.x + hs + e < b.xmin || k.y - e > b.ymax || k.y + hs + e < b.ymin)
        continue;
      stack[sp++] = k;
    }
  }
  return QK_OK;
}

/* The radius query's rare case, out of line: a point within a relative 2^-45 of the
 * circle, or r beyond 2^500 (or infinite). Its distance, as rounded (without the overflow
 * of the squares), when it lies within r of c exactly; -1 when not. */
static __attribute__((noinline, cold)) double near_circle(double x, double y, qk_point_t c,
                                                          double r) {
  if (!isinf(r) && !qk__within_exact(x, y, c.x, c.y, r, 0)) return -1;
  double dx = x - c.x, dy = y - c.y, d2 = dx * dx + dy * dy;
  return d2 < 0x1p1000 ? sqrt(d2) : hypot(dx, dy);
}

/* The reported distance of a point within r: sqrt of the square in doubles, or beyond
 * 2^1000 hypot of the differences (as near_circle, and whatever the walk's scale). */
static double plain_dist(double x, double y, qk_point_t c) {
  double dx = x - c.x, dy = y - c.y, d2 = dx * dx + dy * dy;
  return d2 < 0x1p1000 ? sqrt(d2) : hypot(dx, dy);
}

/*
 * The walk, with the differences multiplied by sc (a power of two; 1, a constant, for
 * the common case, whose code is then the unscaled one). Below about 2^-530 every square
 * underflows under the filter's absolute margin, and from 2^500 on r^2 is beyond the
 * filter's range (qk__filter_hi is infinite there): either way no square was pruned and
 * every point went to the exact test, n big-integer tests per query (for r below 2^-400
 * or above 2^400 alone; fifty-sixth session). Scaled by the exponent of r, r sc lies in
 * [0.5, 1) and the filter decides again: dx sc is the difference rounded once, then
 * scaled exactly (or, for sc < 1, with an absolute error below 2^-1075 where it
 * underflows, which the filter's absolute margin covers, as for an underflowing
 * product); a difference that overflows, scaled or not, is farther than any finite r.
 */
static QK__ALWAYS_INLINE qk_status_t radius_walk_sc(const qk_tree_t *t, qk_point_t c, double r,
                                                    double sc, qk__emit_fn emit, void *ctx) {
  /* Exact: d2 at most lo is inside, above hi outside, and between them (a point within a
   * relative 2^-45 of the circle, or r beyond 2^500 unscaled) the exact test decides
   * (index/dist_exact.h). Squares are pruned against hi, which keeps every square holding
   * a point the exact test accepts. */
  const double rs = r * sc;
  const double r2 = rs * rs, lo = qk__filter_lo(r2), hi = qk__filter_hi(r2), e = qk__margin(t);
  const qk_square_t root = qk__tree_root_square(t);
  if (qk__square_d2_scaled(root.x, root.y, root.side, c.x, c.y, e, sc) > hi) return QK_OK;
  const double *xs = qk__tree_xs(t), *ys = qk__tree_ys(t);
  const qk_id_t *ids = qk__tree_ids(t);
  qk__cell_t stack[QK__STACK_MAX];
  int sp = 0;
  uint32_t pf_lo = 0, pf_hi = 0;
  stack[sp++] = qk__root_cell(t);
  while (sp > 0) {
    const qk__cell_t n = stack[--sp];
    const uint32_t child = qk__node_child(t, n.node);
    if (child == QK_NONE) {
      const uint32_t start = qk__node_start(t, n.node), count = qk__node_count(t, n.node);
      const double *px = xs + start, *py = ys + start;
      const qk_id_t *pid = ids + start;
      for (uint32_t i = 0; i < count; i++) {
        double dx = (px[i] - c.x) * sc, dy = (py[i] - c.y) * sc;
        double d2 = dx * dx + dy * dy;
        if (d2 <= hi) {
          double dist;
          if (sc == 1.0)
            dist = d2 <= lo ? sqrt(d2) : near_circle(px[i], py[i], c, r);
          else
            dist = d2 <= lo ? plain_dist(px[i], py[i], c) : near_circle(px[i], py[i], c, r);
          if (dist < 0) continue;
          if (emit(ctx, pid[i], px[i], py[i], dist)) return QK_OK;
        }
      }
      continue;
    }
    qk__ask_subtree(t, n.node, &pf_lo, &pf_hi);
    /* As for boxes: bound the children from this node's square before pushing them. */
    const double hs = qk__tree_side(t, n.depth + 1);
    qk__cell_t kids[4];
    qk__cell_children(t, n, child, kids);
    for (int q = 3; q >= 0; q--)
      if (qk__square_d2_scaled(kids[q].x, kids[q].y, hs, c.x, c.y, e, sc) <= hi)
        stack[sp++] = kids[q];
  }
  return QK_OK;
}

static qk_status_t radius_walk(const qk_tree_t *t, qk_point_t c, double r, qk__emit_fn emit,
                               void *ctx) {
  if (!isfinite(c.x) || !isfinite(c.y) || isnan(r)) return QK_ERR_NONFINITE;
  if (r < 0) return QK_ERR_INVALID;
  if (qk__tree_count(t) == 0) return QK_OK;
  /* The common case's walk has the constant 1 for its scale, and no multiplications. */
  const double sc = qk__radius_scale(r);
  if (sc == 1.0) return radius_walk_sc(t, c, r, 1.0, emit, ctx);
  return radius_walk_sc(t, c, r, sc, emit, ctx);
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
  QK__SINK_PUT(b->ids, b->cap, b->n, id);
  return 0;
}

static int emit_nb(void *ctx, qk_id_t id, double x, double y, double dist) {
  buf_ctx_t *b = ctx;
  (void)x, (void)y;
  QK__SINK_PUT(b->nb, b->cap, b->n, ((qk_neighbor_t){id, dist}));
  return 0;
}

qk_status_t qk_query_range(const qk_tree_t *tree, qk_box_t box, qk_found_fn fn, void *ud) {
  if (!tree || !fn) return QK_ERR_INVALID;
  cb_ctx_t c = {fn, ud};
  return range_walk(tree, box, emit_cb, &c);
}

qk_status_t qk_query_range_list(const qk_tree_t *tree, qk_box_t box, qk_id_t *ids, size_t cap,
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

qk_status_t qk_query_radius_list_batch(const qk_tree_t *tree, const qk_point_t *centres, size_t nq,
                                       double r, qk_neighbor_t *out, size_t cap, size_t *counts,
                                       size_t *n_out) {
  if (!tree || !n_out || (nq > 0 && (!centres || !counts)) || (cap > 0 && !out))
    return QK_ERR_INVALID;
  *n_out = 0;
  if (isnan(r)) return QK_ERR_NONFINITE;
  if (r < 0) return QK_ERR_INVALID;
  return qk__radius_batch(tree, centres, nq, r, out, cap, counts, n_out);
}

/* One thread's share of a radius batch: queries [lo, hi) into out (cap entries), which is
 * the caller's buffer for the first share and the share's own otherwise. */
qk_status_t qk__radius_range(const qk_tree_t *t, const qk_point_t *centres, size_t lo, size_t hi,
                             double r, qk_neighbor_t *out, size_t cap, size_t *counts,
                             size_t *total, size_t *first_bad) {
  qk_status_t first = QK_OK;
  size_t sum = 0;
  *first_bad = SIZE_MAX;
  for (size_t i = lo; i < hi; i++) {
    /* Each query writes straight after the previous one, into what is left of out. */
    buf_ctx_t b = {NULL, out ? out + (sum < cap ? sum : cap) : NULL, sum < cap ? cap - sum : 0, 0};
    qk_status_t st = radius_walk(t, centres[i], r, emit_nb, &b);
    if (st != QK_OK) {
      b.n = 0;
      if (first == QK_OK) {
        first = st;
        *first_bad = i;
      }
    }
    counts[i] = b.n;
    sum += b.n;
  }
  *total = sum;
  return first;
}
