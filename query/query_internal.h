/*
 * Private helpers of the query module: cell bounds with a rounding margin, the explicit
 * traversal stack and the bounded max-heap used by the kNN searches. Not API. Trees are
 * read only through index/index_access.h: squares are computed along each descent.
 */
#ifndef QUADKIT_QUERY_INTERNAL_H
#define QUADKIT_QUERY_INTERNAL_H

#include <math.h>

#if defined(__SSE2__)
#include <emmintrin.h>
#endif

#include "index/index_access.h"
#include "quadkit/query.h"

/*
 * Deepest possible traversal stack: a depth-first search pops one node and pushes at
 * most four children, so it never holds more than 3 per level plus 4.
 */
#define QK__STACK_MAX (3 * (QK_MAX_DEPTH_LIMIT + 2) + 8)

/* A stacked node with the lower bound that let it in (re-checked when popped, because
 * the pruning threshold may have shrunk meanwhile). */
typedef struct qk__entry {
  uint32_t node;
  double bound;
} qk__entry_t;

/* A stacked node with its square's corner and depth (the side is qk__tree_side(depth)),
 * carried down the descent so that no node's square is ever read back from the tree. */
typedef struct qk__cell {
  uint32_t node;
  uint32_t depth;
  double x, y;
} qk__cell_t;

/* A stacked node with its square and the lower bound that let it in. */
typedef struct qk__cell_entry {
  qk__cell_t c;
  double bound;
} qk__cell_entry_t;

/* The four children of a cell (NE, NW, SW, SE), their squares derived from its own. */
static inline void qk__cell_children(const qk_tree_t *t, qk__cell_t c, uint32_t first,
                                     qk__cell_t kids[4]) {
  const double h = qk__tree_side(t, c.depth + 1);
  const uint32_t d = c.depth + 1;
  kids[0] = (qk__cell_t){first + QK_NE, d, c.x + h, c.y + h};
  kids[1] = (qk__cell_t){first + QK_NW, d, c.x, c.y + h};
  kids[2] = (qk__cell_t){first + QK_SW, d, c.x, c.y};
  kids[3] = (qk__cell_t){first + QK_SE, d, c.x + h, c.y};
}

/* The root as a cell. */
static inline qk__cell_t qk__root_cell(const qk_tree_t *t) {
  qk_square_t r = qk__tree_root_square(t);
  return (qk__cell_t){0, 0, r.x, r.y};
}

/*
 * The margin by which node squares are widened before pruning. A node's square is
 * (x0, y0, side) as stored, but its points are only guaranteed to satisfy the split
 * tests of its ancestors, whose midpoints were rounded where they were computed; x0 +
 * side may differ from them by a few units in the last place of the coordinates. A
 * margin of 2^-40 of the root's magnitude covers hundreds of such roundings and costs
 * nothing measurable in pruning, while keeping every bound a true lower bound. Below
 * 2^-1000 that product underflows towards 0 while a rounding still costs up to 2^-1074
 * (a subnormal's unit, whatever the magnitude): the margin is never less than 2^-1060,
 * some 2^14 such units, far more than a descent of QK_MAX_DEPTH levels can round (a
 * subnormal root's leaf held its points one unit above its square's top and the range
 * query pruned it: forty-ninth session's review).
 */
static inline double qk__margin(const qk_tree_t *t) {
  qk_square_t r = qk__tree_root_square(t);
  const double m = (fabs(r.x) + fabs(r.y) + 2.0 * r.side) * 0x1p-40;
  return m > 0x1p-1060 ? m : 0x1p-1060;
}

/*
 * Squared distance from (qx, qy) to the square (x0, y0, side) widened by e. Floating-point
 * subtraction is monotone, so the result never exceeds the computed squared distance to
 * any point stored in the square's node. Squares are derived along the descent, from the
 * parent's, which lets a search bound the four children without reading their nodes (a
 * cache miss each for the ones it then prunes).
 */
static inline double qk__square_d2(double x0, double y0, double side, double qx, double qy,
                                   double e) {
  double xlo = x0 - e, xhi = x0 + side + e;
  double ylo = y0 - e, yhi = y0 + side + e;
  double dx = qx < xlo ? xlo - qx : (qx > xhi ? qx - xhi : 0.0);
  double dy = qy < ylo ? ylo - qy : (qy > yhi ? qy - yhi : 0.0);
  return dx * dx + dy * dy;
}

/*
 * qk__square_d2 with each gap multiplied by sc, an exact power of two, before it is
 * squared: the bound of the searches that scale their differences so that their squares
 * neither underflow nor overflow (docs/query.md, "Exactness"). Rounding is monotone, so a
 * scaled gap never exceeds the scaled difference of any point beyond it.
 */
static inline double qk__square_d2_scaled(double x0, double y0, double side, double qx, double qy,
                                          double e, double sc) {
  double xlo = x0 - e, xhi = x0 + side + e;
  double ylo = y0 - e, yhi = y0 + side + e;
  double dx = (qx < xlo ? xlo - qx : (qx > xhi ? qx - xhi : 0.0)) * sc;
  double dy = (qy < ylo ? ylo - qy : (qy > yhi ? qy - yhi : 0.0)) * sc;
  return dx * dx + dy * dy;
}

/* The smaller and the larger of two values known not to be NaN: one instruction (minsd,
 * maxsd, whose rule is exactly a < b ? a : b) where fmin() is a library call and compilers
 * may keep the ternary's branch, which the searches' bounds would take at random. */
static inline double qk__min_d(double a, double b) {
#if defined(__SSE2__)
  return _mm_cvtsd_f64(_mm_min_sd(_mm_set_sd(a), _mm_set_sd(b)));
#else
  return a < b ? a : b;
#endif
}
static inline double qk__max_d(double a, double b) {
#if defined(__SSE2__)
  return _mm_cvtsd_f64(_mm_max_sd(_mm_set_sd(a), _mm_set_sd(b)));
#else
  return a > b ? a : b;
#endif
}

/* Distance from v to the interval [lo, hi] (0 inside), lo <= hi: at most one of the two
 * terms is nonzero, and adding +0 changes nothing, so the value is that of the test "below,
 * above or inside", without its branches, which the searches' bounds take at random. */
static inline double qk__gap(double v, double lo, double hi) {
  return qk__max_d(lo - v, 0.0) + qk__max_d(v - hi, 0.0);
}

/* (d, id) ordering of neighbours: by distance, ties by smaller id. */
static inline int qk__nb_less(double da, qk_id_t ia, double db, qk_id_t ib) {
  return da < db || (da == db && ia < ib);
}

/* Bounded max-heap of neighbours keyed by (dist, id), the worst at h[0]. */
void qk__heap_push(qk_neighbor_t *h, size_t *n, qk_neighbor_t v);
void qk__heap_replace_top(qk_neighbor_t *h, size_t n, qk_neighbor_t v);
/* Sort the heap's contents ascending by (dist, id) in place. */
void qk__heap_sort(qk_neighbor_t *h, size_t n);

/*
 * Offer a candidate (id, d) to the bounded heap h of *n entries, at most k, whose
 * pruning threshold is *thr (anything farther than *thr is out): it enters while the
 * heap is not full, or when it beats the worst entry by (dist, id); *thr then becomes
 * the worst entry's distance once the heap is full. The kNN searches, planar (squared
 * distances) and geodesic (metres), share it.
 */
static inline void qk__heap_offer(qk_neighbor_t *h, size_t *n, size_t k, qk_id_t id, double d,
                                  double *thr) {
  qk_neighbor_t v = {id, d};
  if (*n < k) {
    qk__heap_push(h, n, v);
    if (*n == k && h[0].dist < *thr) *thr = h[0].dist;
  } else if (qk__nb_less(d, id, h[0].dist, h[0].id)) {
    qk__heap_replace_top(h, *n, v);
    *thr = h[0].dist;
  }
}

/*
 * Z-order of nq query locations, for the batch calls: returns a block to release with
 * qk__morton_free() and sets *order to the query indices in Morton order; returns NULL
 * (order NULL) when the batch is too small to gain or memory is short, in which case
 * the caller answers the queries in their given order.
 */
void *qk__morton_order(const qk_tree_t *t, const qk_point_t *qs, size_t nq, uint32_t **order);
void qk__morton_free(const qk_tree_t *t, void *block, size_t nq);

/* Queries whose paths are walked in lockstep by the batch calls, and the prefetch hint
 * (a no-op where the compiler has none). */
#define QK__LANES 8
#if defined(__GNUC__)
#define QK__PREFETCH(p) __builtin_prefetch(p)
#define QK__PREFETCH_W(p) __builtin_prefetch((p), 1)
#else
#define QK__PREFETCH(p) ((void)(p))
#define QK__PREFETCH_W(p) ((void)(p))
#endif

/*
 * A descent's path by the tie rules: the cells from the root to the leaf's parent, the
 * quadrant taken at each, and the cell reached (the leaf when the walk is over).
 */
typedef struct qk__path {
  qk__cell_t cell[QK_MAX_DEPTH_LIMIT + 1];
  unsigned char q[QK_MAX_DEPTH_LIMIT + 1];
#if defined(__SSE2__)
  __m128d mid[QK_MAX_DEPTH_LIMIT + 1];      /* each level's midlines (x, y), for qk__path_reuse */
  unsigned char go[QK_MAX_DEPTH_LIMIT + 1]; /* east (bit 0) and north (bit 1) taken there */
#endif
  unsigned len;
  qk__cell_t leaf;
  int valid; /* for a batch: the query was finite and inside the root */
} qk__path_t;

static inline void qk__path_init(const qk_tree_t *t, qk__path_t *p) {
  p->len = 0;
  p->leaf = qk__root_cell(t);
}

/* One level down towards (qx, qy); 0 when the cell reached is a leaf. */
static inline int qk__path_step(const qk_tree_t *t, qk__path_t *p, double qx, double qy) {
  const qk__cell_t c = p->leaf;
  const uint32_t child = qk__node_child(t, c.node);
  if (child == QK_NONE) return 0;
  const double h = qk__tree_side(t, c.depth + 1);
  const unsigned q = qk__quadrant_of(c.x, c.y, h, qx, qy);
  p->cell[p->len] = c;
  p->q[p->len++] = (unsigned char)q;
  p->leaf = (qk__cell_t){child + q, c.depth + 1, qk__q_east(q) ? c.x + h : c.x,
                         qk__q_north(q) ? c.y + h : c.y};
  return 1;
}

/*
 * A single query's descent asks for the points below the first node on its path whose
 * subtree holds at most this many (up to 16 lines of each coordinate array); see
 * qk__path_descend.
 */
#define QK__SUBTREE_PREFETCH 128

/* Ask for the x and y lines of the slots [start, start + count), 1 <= count <= 128, when
 * they lie within the point arrays (a node's start is only a hint: index_access.h). */
static inline void qk__prefetch_slots(const qk_tree_t *t, uint32_t start, uint32_t count) {
  const uint32_t bound = qk__tree_slot_bound(t);
  if (start > bound || count > bound - start) return;
  const double *xs = qk__tree_xs(t) + start, *ys = qk__tree_ys(t) + start;
  for (uint32_t i = 0; i < count; i += 8) {
    QK__PREFETCH(xs + i);
    QK__PREFETCH(ys + i);
  }
  QK__PREFETCH(xs + count - 1); /* the last line, which the steps miss when unaligned */
  QK__PREFETCH(ys + count - 1);
}

/*
 * Ask for the points of internal node `node` when it holds at most QK__SUBTREE_PREFETCH of
 * them, unless its start lies within [*lo, *hi), the slots asked for last (0, 0 before the
 * first): a walk reaches a node's descendants after it, and after a bulk build their
 * points lie within its run, so each run is asked for once. The descents and the box and
 * radius walks share it.
 */
static inline void qk__ask_subtree(const qk_tree_t *t, uint32_t node, uint32_t *lo, uint32_t *hi) {
  const uint32_t count = qk__node_count(t, node), start = qk__node_start(t, node);
  if (count - 1 >= QK__SUBTREE_PREFETCH || (start >= *lo && start < *hi)) return;
  qk__prefetch_slots(t, start, count);
  *lo = start, *hi = start + count;
}

/*
 * The rest of a descent towards (qx, qy) from p->leaf down to the leaf, in one loop that
 * keeps the cell in registers: the same decisions and squares as qk__path_step() (east
 * when qx > x + h, the child's corner moved by h), so the same path. A single query's descent
 * (keep_mids 0) asks at each level for both lines of the children's block (four 16-byte
 * nodes over two lines), not only the one holding the child it reads next: the kNN search
 * then reads the path's other children (the climb's siblings and uncles) without a miss of
 * their own, the other line having come in while the descent waited for its child. A
 * batch's queries, in Z-order, share their paths' blocks, which are in cache. Only hints.
 *
 * It also asks (qk__ask_subtree) for the points below the first node on the path whose
 * subtree holds at most QK__SUBTREE_PREFETCH points (from the node's start, a hint of
 * index/: after a bulk build a subtree's points are one run of slots). Without it the
 * leaf's points are asked for only once the leaf's node has been read, itself a miss after
 * its parent's: two misses one after the other at the end of every descent. Asked for from
 * the leaf's parent (at capacity 32) or higher up (smaller capacities, whose last levels
 * are more misses in a row), they come in while the descent reads its last nodes, and they
 * cover the siblings that a search goes on to scan. In-process A/B at 10^6 uniform points,
 * 16 rounds of 10^5 random queries, one per call (twenty-seventh session; both libraries
 * in one driver, alternating), new time over old, median of the rounds: k = 1 0.83-0.87 at
 * capacity 32, 0.78-0.90 at capacity 8, 0.84-0.85 at capacity 1; k = 8 0.85-0.88; k = 32
 * 0.93-0.98 (identical answers; docs/query.md, eleventh round). Thresholds of 96 and 192
 * did about as well; 256 (the grandparent's 240 points at capacity 32, 60 lines at once)
 * was slower than none in separate processes.
 */
static inline void qk__path_descend(const qk_tree_t *t, qk__path_t *p, double qx, double qy,
                                    int keep_mids) {
  uint32_t node = p->leaf.node, depth = p->leaf.depth;
  unsigned len = p->len;
#if defined(__SSE2__)
  /* The corner (x, y) in one register: both midlines, both decisions and both moves at
   * once; bit 0 of the mask is east, bit 1 north. */
  static const unsigned char quad[4] = {QK_SW, QK_SE, QK_NW, QK_NE};
  const __m128d vq = _mm_set_pd(qy, qx);
  __m128d v = _mm_set_pd(p->leaf.y, p->leaf.x);
  uint32_t pf_lo = 0, pf_hi = 0; /* the slots asked for (qk__ask_subtree) */
  for (uint32_t child = qk__node_child(t, node); child != QK_NONE;
       child = qk__node_child(t, node)) {
    const __m128d vm = _mm_add_pd(v, _mm_set1_pd(qk__tree_side(t, depth + 1)));
    const __m128d go = _mm_cmplt_pd(vm, vq); /* qx > xm, qy > ym */
    const int bits = _mm_movemask_pd(go);
    if (keep_mids) { /* a constant in each caller */
      p->mid[len] = vm;
      p->go[len] = (unsigned char)bits;
    }
    const unsigned q = quad[bits];
    if (!keep_mids) {
      qk__node_prefetch(t, child);
      qk__node_prefetch(t, child + 3);
      qk__ask_subtree(t, node, &pf_lo, &pf_hi);
    }
    qk__cell_t *c = &p->cell[len];
    c->node = node;
    c->depth = depth;
    _mm_storel_pd(&c->x, v);
    _mm_storeh_pd(&c->y, v);
    p->q[len++] = (unsigned char)q;
    node = child + q;
    depth++;
    v = _mm_or_pd(_mm_and_pd(go, vm), _mm_andnot_pd(go, v));
  }
  p->leaf.node = node;
  p->leaf.depth = depth;
  _mm_storel_pd(&p->leaf.x, v);
  _mm_storeh_pd(&p->leaf.y, v);
#else
  static const unsigned char quad[2][2] = {{QK_SW, QK_NW}, {QK_SE, QK_NE}}; /* [east][north] */
  double x = p->leaf.x, y = p->leaf.y;
  uint32_t pf_lo = 0, pf_hi = 0; /* the slots asked for (qk__ask_subtree) */
  for (uint32_t child = qk__node_child(t, node); child != QK_NONE;
       child = qk__node_child(t, node)) {
    const double h = qk__tree_side(t, depth + 1);
    const double xm = x + h, ym = y + h;
    const unsigned east = qx > xm, north = qy > ym;
    const unsigned q = quad[east][north];
    if (!keep_mids) {
      qk__node_prefetch(t, child);
      qk__node_prefetch(t, child + 3);
      qk__ask_subtree(t, node, &pf_lo, &pf_hi);
    }
    p->cell[len] = (qk__cell_t){node, depth, x, y};
    p->q[len++] = (unsigned char)q;
    node = child + q;
    depth++;
    x = east ? xm : x;
    y = north ? ym : y;
  }
  p->leaf = (qk__cell_t){node, depth, x, y};
#endif
  p->len = len;
}

/* qk__path_descend keeping each level's midlines and moves, for qk__path_reuse (a single
 * query's path, never reused, need not store them). */
static inline void qk__path_finish(const qk_tree_t *t, qk__path_t *p, double qx, double qy) {
  qk__path_descend(t, p, qx, qy, 1);
}

/*
 * Make p, the path of an earlier query in the same unchanged tree, the path of (qx, qy):
 * keep its levels from the root for as long as the new query takes the same quadrants
 * (decided with the same arithmetic as a descent), then descend afresh from there. For
 * queries in Z-order most of the path is shared, and its nodes need not be read again.
 */
static inline void qk__path_reuse(const qk_tree_t *t, qk__path_t *p, double qx, double qy) {
#if defined(__SSE2__)
  /* The midlines kept by the descent: one comparison of both per level. */
  const __m128d vq = _mm_set_pd(qy, qx);
  for (unsigned i = 0; i < p->len; i++) {
    if (_mm_movemask_pd(_mm_cmplt_pd(p->mid[i], vq)) != p->go[i]) {
      p->len = i;
      p->leaf = p->cell[i];
      break;
    }
  }
#else
  static const unsigned char quad[2][2] = {{QK_SW, QK_NW}, {QK_SE, QK_NE}};
  for (unsigned i = 0; i < p->len; i++) {
    const qk__cell_t c = p->cell[i];
    const double h = qk__tree_side(t, c.depth + 1);
    if (quad[qx > c.x + h][qy > c.y + h] != p->q[i]) {
      p->len = i;
      p->leaf = c;
      break;
    }
  }
#endif
  qk__path_finish(t, p, qx, qy);
}

/* Walk the paths of the queries order[j0 .. min(j1, j0 + QK__LANES)) in lockstep into
 * paths[0 ..) (query/knn.c). */
void qk__walk_lanes(const qk_tree_t *t, const qk_point_t *qs, const uint32_t *order, size_t j0,
                    size_t j1, qk__path_t *paths);

/* One kNN query into out (k entries), arguments checked; returns the count. `path`, when
 * not NULL, is the query's path, already walked. */
size_t qk__knn_one(const qk_tree_t *t, qk_point_t q, size_t k, double max_dist, qk_neighbor_t *out,
                   const qk__path_t *path);
/*
 * Distances are compared by their squares in double, (dx)^2 + (dy)^2: beyond 2^510 a
 * coordinate's difference could square past DBL_MAX, and every distance would read
 * infinite. kNN queries therefore need the query and the root square within
 * [-2^510, 2^510] on both axes (QK_ERR_LIMIT otherwise); one test per query. (The
 * radius query is defined by that double formula itself, overflow included.)
 */
#define QK__DIST_RANGE 0x1p510
static inline bool qk__dist_in_range(const qk_tree_t *t, qk_point_t q) {
  const qk_square_t r = qk__tree_root_square(t);
  /* maxsd rather than fmax(), a library call (no NaN here: q is finite, checked first, and
   * so is the root square). */
  const double m = qk__max_d(qk__max_d(fabs(q.x), fabs(q.y)),
                             qk__max_d(qk__max_d(fabs(r.x), fabs(r.y)),
                                       qk__max_d(fabs(r.x + r.side), fabs(r.y + r.side))));
  return m <= QK__DIST_RANGE;
}

/* Nonzero: the k = 1 leaf scan takes its SSE2 path even where the processor has AVX2
 * (query/knn.c), so that tests check both on one machine. 0 by default. */
extern int qk__knn_avx2_off;

/* QK_OK, or why a kNN query cannot be answered. */
static inline qk_status_t qk__knn_check(const qk_tree_t *t, qk_point_t q, double max_dist) {
#if defined(__SSE2__)
  {
    /* The common case first, both axes at once: |q| and the root square's corners within
     * the range (a NaN or an infinity fails the comparison) and a limit >= 0 (NaN fails it)
     * mean all three tests below pass. Otherwise they say which fails first. */
    const qk_square_t r = qk__tree_root_square(t);
    const __m128d lim = _mm_set1_pd(QK__DIST_RANGE);
    const __m128d mag = _mm_castsi128_pd(_mm_set1_epi64x(0x7fffffffffffffffLL));
    const __m128d r0 = _mm_set_pd(r.y, r.x), r1 = _mm_add_pd(r0, _mm_set1_pd(r.side));
    const __m128d aq = _mm_and_pd(_mm_unpacklo_pd(_mm_set_sd(q.x), _mm_set_sd(q.y)), mag);
    const __m128d ar = _mm_max_pd(_mm_and_pd(r0, mag), _mm_and_pd(r1, mag));
    const __m128d ok = _mm_and_pd(_mm_cmple_pd(aq, lim), _mm_cmple_pd(ar, lim));
    if (_mm_movemask_pd(ok) == 3 && max_dist >= 0) return QK_OK;
  }
#endif
  if (!isfinite(q.x) || !isfinite(q.y)) return QK_ERR_NONFINITE;
  if (isnan(max_dist) || max_dist < 0) return QK_ERR_INVALID;
  if (!qk__dist_in_range(t, q)) return QK_ERR_LIMIT;
  return QK_OK;
}

/* Radius batches (query/range.c does one share, query/batch.c spreads the shares). */
qk_status_t qk__radius_range(const qk_tree_t *t, const qk_point_t *centres, size_t lo, size_t hi,
                             double r, qk_neighbor_t *out, size_t cap, size_t *counts,
                             size_t *total, size_t *first_bad);
qk_status_t qk__radius_batch(const qk_tree_t *t, const qk_point_t *centres, size_t nq, double r,
                             qk_neighbor_t *out, size_t cap, size_t *counts, size_t *n_out);

/* Threads for a batch of nq queries on t: the tree's setting, but no thread for fewer
 * than QK__BATCH_SHARE queries. */
#define QK__BATCH_SHARE 64
static inline unsigned qk__batch_threads(const qk_tree_t *t, size_t nq) {
  unsigned nw = qk__tree_threads(t);
  size_t most = nq / QK__BATCH_SHARE;
  if (most < 1) most = 1;
  return nw > most ? (unsigned)most : nw;
}

/* Sort up to four stacked entries by descending bound, so the nearest is popped first. */
static inline void qk__sort4_desc(qk__entry_t *e, int n) {
  for (int i = 1; i < n; i++) {
    qk__entry_t v = e[i];
    int j = i - 1;
    while (j >= 0 && e[j].bound < v.bound) {
      e[j + 1] = e[j];
      j--;
    }
    e[j + 1] = v;
  }
}

/* The same for stacked cells. */
static inline void qk__sort_cells_desc(qk__cell_entry_t *e, int n) {
  for (int i = 1; i < n; i++) {
    qk__cell_entry_t v = e[i];
    int j = i - 1;
    while (j >= 0 && e[j].bound < v.bound) {
      e[j + 1] = e[j];
      j--;
    }
    e[j + 1] = v;
  }
}

/* The lowest-numbered failure of a batch, merged from its threads' shares. */
typedef struct qk__first_err {
  qk_status_t st;
  size_t i;
} qk__first_err_t;

static inline void qk__note_err(qk__first_err_t *e, qk_status_t st, size_t i) {
  if (st != QK_OK && i < e->i) {
    e->st = st;
    e->i = i;
  }
}

#endif /* QUADKIT_QUERY_INTERNAL_H */
