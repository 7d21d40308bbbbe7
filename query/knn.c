/*
 * k nearest neighbours: a depth-first branch-and-bound search that visits the children
 * of a node nearest first and prunes every node whose square lies farther than the
 * current k-th best (the classic search of Friedman, Bentley and Finkel, run on the
 * quadtree's squares). The k best so far live in a bounded max-heap that is the
 * caller's output buffer, so a query allocates nothing.
 */
#include "query/query_internal.h"

static void sift_down(qk_neighbor_t *h, size_t n, size_t i) {
  qk_neighbor_t v = h[i];
  for (;;) {
    size_t l = 2 * i + 1, m = i;
    qk_neighbor_t best = v;
    if (l < n && qk__nb_less(best.dist, best.id, h[l].dist, h[l].id)) m = l, best = h[l];
    if (l + 1 < n && qk__nb_less(best.dist, best.id, h[l + 1].dist, h[l + 1].id)) m = l + 1;
    if (m == i) break;
    h[i] = h[m];
    i = m;
  }
  h[i] = v;
}

void qk__heap_push(qk_neighbor_t *h, size_t *n, qk_neighbor_t v) {
  size_t i = (*n)++;
  while (i > 0) {
    size_t p = (i - 1) / 2;
    if (!qk__nb_less(h[p].dist, h[p].id, v.dist, v.id)) break;
    h[i] = h[p];
    i = p;
  }
  h[i] = v;
}

void qk__heap_replace_top(qk_neighbor_t *h, size_t n, qk_neighbor_t v) {
  h[0] = v;
  sift_down(h, n, 0);
}

void qk__heap_sort(qk_neighbor_t *h, size_t n) {
  /* Standard in-place heapsort of a max-heap: move the worst to the end repeatedly. */
  while (n > 1) {
    qk_neighbor_t top = h[0];
    h[0] = h[--n];
    sift_down(h, n, 0);
    h[n] = top;
  }
}

/* Offer a leaf's points to the heap h (n entries, at most k), tightening *thr. */
static inline void scan_leaf(const qk_tree_t *t, qk_node_t leaf, double qx, double qy, size_t k,
                             qk_neighbor_t *h, size_t *n_io, double *thr_io) {
  const uint32_t start = qk__node_start(t, leaf), count = qk__node_count(t, leaf);
  const double *px = qk__tree_xs(t) + start, *py = qk__tree_ys(t) + start;
  const qk_id_t *pid = qk__tree_ids(t) + start;
  double thr = *thr_io;
  for (uint32_t i = 0; i < count; i++) {
    double dx = px[i] - qx, dy = py[i] - qy;
    double d2 = dx * dx + dy * dy;
    if (d2 <= thr) qk__heap_offer(h, n_io, k, pid[i], d2, &thr);
  }
  *thr_io = thr;
}

/*
 * The search proper, on squared distances. `limit2` is the squared cap; a point enters
 * when its squared distance is at most limit2 and it beats the heap's worst (or the heap
 * is not full). A node is pruned when its bound is strictly above the threshold: a node
 * at exactly the k-th distance may still hold a point with a smaller id.
 */
static size_t knn_search(const qk_tree_t *t, double qx, double qy, size_t k, double limit2,
                         qk_neighbor_t *h) {
  const double e = qk__margin(t);
  size_t n = 0;
  double thr = limit2; /* prune above this: the cap, then the k-th best once full */
  /*
   * First go straight down to the leaf whose square holds q (when q is in the root) and
   * take its points: that usually sets the threshold close to its final value before
   * the search proper starts, so that the search pushes few nodes it later discards.
   * The search then skips that leaf.
   */
  qk_node_t first = QK_NONE;
  if (qk__tree_contains(t, qx, qy)) {
    first = qk__tree_descend(t, qx, qy, NULL, NULL);
    scan_leaf(t, first, qx, qy, k, h, &n, &thr);
  }
  qk__cell_entry_t stack[QK__STACK_MAX];
  int sp = 0;
  const qk_square_t r = qk__tree_root_square(t);
  stack[sp].c = qk__root_cell(t);
  stack[sp++].bound = qk__square_d2(r.x, r.y, r.side, qx, qy, e);
  while (sp > 0) {
    qk__cell_entry_t top = stack[--sp];
    if (top.bound > thr) continue;
    const uint32_t child = qk__node_child(t, top.c.node);
    if (child == QK_NONE) {
      if (top.c.node != first) scan_leaf(t, top.c.node, qx, qy, k, h, &n, &thr);
      continue;
    }
    /* Bound the children from this node's square (NE, NW, SW, SE), not from their
     * nodes; a child is read only if it is visited (empty ones are dropped then). The
     * children share their edges, so two distances per axis give all four bounds. */
    qk__cell_t kc[4];
    qk__cell_children(t, top.c, child, kc);
    const double hs = qk__tree_side(t, top.c.depth + 1), x0 = top.c.x, y0 = top.c.y;
    const double xm = x0 + hs, ym = y0 + hs;
    const double dxw = qk__gap(qx, x0 - e, xm + e), dxe = qk__gap(qx, xm - e, xm + hs + e);
    const double dys = qk__gap(qy, y0 - e, ym + e), dyn = qk__gap(qy, ym - e, ym + hs + e);
    const double xw = dxw * dxw, xe = dxe * dxe, ys = dys * dys, yn = dyn * dyn;
    const double b[4] = {xe + yn, xw + yn, xw + ys, xe + ys}; /* NE, NW, SW, SE */
    qk__cell_entry_t kids[4];
    int m = 0;
    for (uint32_t c = 0; c < 4; c++) {
      if (b[c] > thr) continue;
      kids[m].c = kc[c];
      kids[m++].bound = b[c];
    }
    qk__sort_cells_desc(kids, m);
    for (int i = 0; i < m; i++) stack[sp++] = kids[i];
  }
  return n;
}

/*
 * Walk the paths from the root to the leaves holding the next QK__LANES queries in
 * lockstep, one level at a time, prefetching each next node: the lanes' cache misses
 * then overlap instead of following one another, and the searches that come next find
 * their paths in the cache. Only a hint: it changes no result.
 */
void qk__prefetch_paths(const qk_tree_t *t, const qk_point_t *qs, const uint32_t *order, size_t j0,
                        size_t nq) {
  qk_node_t v[QK__LANES];
  unsigned d[QK__LANES];
  int lanes = 0;
  double qx[QK__LANES], qy[QK__LANES], cx[QK__LANES], cy[QK__LANES];
  const qk_square_t r = qk__tree_root_square(t);
  for (size_t j = j0; j < nq && j < j0 + QK__LANES; j++) {
    qk_point_t q = qs[order ? order[j] : j];
    if (!qk__tree_contains(t, q.x, q.y)) continue;
    qx[lanes] = q.x;
    qy[lanes] = q.y;
    cx[lanes] = r.x;
    cy[lanes] = r.y;
    d[lanes] = 0;
    v[lanes++] = 0;
  }
  const double *xs = qk__tree_xs(t), *ys = qk__tree_ys(t);
  while (lanes > 0) {
    for (int l = 0; l < lanes;) {
      const uint32_t child = qk__node_child(t, v[l]);
      if (child == QK_NONE) {
        uint32_t s = qk__node_start(t, v[l]);
        QK__PREFETCH(xs + s);
        QK__PREFETCH(ys + s);
        lanes--; /* this lane is done: move the last one here */
        v[l] = v[lanes];
        d[l] = d[lanes];
        qx[l] = qx[lanes];
        qy[l] = qy[lanes];
        cx[l] = cx[lanes];
        cy[l] = cy[lanes];
        continue;
      }
      const double h = qk__tree_side(t, d[l] + 1);
      const unsigned q = qk__quadrant_of(cx[l], cy[l], h, qx[l], qy[l]);
      if (qk__q_east(q)) cx[l] += h;
      if (qk__q_north(q)) cy[l] += h;
      d[l]++;
      v[l] = child + q;
      qk__node_prefetch(t, v[l]);
      l++;
    }
  }
}

static qk_status_t check_args(qk_point_t q, double max_dist) {
  if (!isfinite(q.x) || !isfinite(q.y)) return QK_ERR_NONFINITE;
  if (isnan(max_dist) || max_dist < 0) return QK_ERR_INVALID;
  return QK_OK;
}

/* One query into out (k entries, k >= 1); returns the count. */
static size_t knn_one(const qk_tree_t *t, qk_point_t q, size_t k, double max_dist,
                      qk_neighbor_t *out) {
  const size_t np = qk__tree_count(t);
  if (np == 0 || k == 0) return 0;
  if (k > np) k = np;
  double limit2 = max_dist * max_dist;
  size_t n = knn_search(t, q.x, q.y, k, limit2, out);
  qk__heap_sort(out, n);
  for (size_t i = 0; i < n; i++) out[i].dist = sqrt(out[i].dist);
  return n;
}

qk_status_t qk_query_knn(const qk_tree_t *tree, qk_point_t q, size_t k, double max_dist,
                         qk_neighbor_t *out, size_t *n_out) {
  if (!tree || !n_out || (k > 0 && !out)) return QK_ERR_INVALID;
  *n_out = 0;
  qk_status_t st = check_args(q, max_dist);
  if (st != QK_OK) return st;
  *n_out = knn_one(tree, q, k, max_dist, out);
  return QK_OK;
}

qk_status_t qk_query_knn_batch(const qk_tree_t *tree, const qk_point_t *qs, size_t nq, size_t k,
                               double max_dist, qk_neighbor_t *out, size_t *counts) {
  if (!tree || (nq > 0 && !qs) || (nq > 0 && k > 0 && !out)) return QK_ERR_INVALID;
  if (isnan(max_dist) || max_dist < 0) return QK_ERR_INVALID;
  qk_status_t first = QK_OK;
  size_t first_i = SIZE_MAX;
  uint32_t *order;
  void *block = qk__morton_order(tree, qs, nq, &order);
  for (size_t j = 0; j < nq; j++) {
    if (j % QK__LANES == 0) qk__prefetch_paths(tree, qs, order, j, nq);
    size_t i = order ? order[j] : j;
    qk_neighbor_t *o = out ? out + i * k : NULL;
    size_t n = 0;
    qk_status_t st = check_args(qs[i], max_dist);
    if (st == QK_OK)
      n = knn_one(tree, qs[i], k, max_dist, o);
    else if (i < first_i) {
      first = st; /* the error of the lowest-numbered query, whatever the answer order */
      first_i = i;
    }
    for (size_t m = n; m < k; m++) {
      o[m].id = QK_NONE;
      o[m].dist = INFINITY;
    }
    if (counts) counts[i] = n;
  }
  if (block) qk__morton_free(tree, block, nq);
  return first;
}
