/*
 * k nearest neighbours: a depth-first branch-and-bound search that goes into the nearest
 * child of a node at once and stacks the others, nearest on top, pruning every node whose
 * square lies farther than the current k-th best (the classic search of Friedman, Bentley
 * and Finkel, run on the quadtree's squares). Squares and their bounds come from the path:
 * the four children's bounds are two distances per axis from the parent's square, so a
 * child's node is read only when it is visited. The first descent goes straight to the
 * leaf nearest the query and leaves its siblings, level by level, on the stack, so the
 * search never walks that path twice.
 *
 * A query allocates nothing: for k = 1 the best so far is a single (distance, slot) pair
 * in registers, its id read once at the end; for k up to QK__KNN_SORTED an array of
 * (distance, slot) on the stack, its first k sorted at once by a sorting network and kept
 * sorted by insertion after that (few candidates enter then), its ids read at the end;
 * beyond that a bounded max-heap in the caller's buffer (query/heap.c).
 */
#include "query/query_internal.h"
#include "index/inline.h"

#include <string.h>

#include "index/dist_exact.h"

#if defined(__SSE2__)
#include <emmintrin.h>
#endif
/* The k = 1 leaf scan four points at a time, where the compiler can target AVX2 in one
 * function and the processor has it (checked at each scan: a load and a test). */
#if defined(__SSE2__) && defined(__GNUC__) && defined(__x86_64__) &&                               \
    (defined(__clang__) || __GNUC__ >= 8)
#define QK__KNN_AVX2 1
#include <immintrin.h>
#else
#define QK__KNN_AVX2 0
#endif

int qk__knn_avx2_off;

/* Largest k kept as a sorted array rather than a heap. */
#define QK__KNN_SORTED 32

/*
 * The best-so-far set of one search. Its order is exact (docs/query.md, "Exactness"):
 * candidates are ranked by their squared distances in doubles wherever those are farther
 * apart than the filter's margin (index/dist_exact.h), and by qk__dist_cmp_exact()
 * otherwise, then by id. Pruning compares lower bounds with `lim`, the filter's upper
 * bound of the k-th's square (qk__filter_hi), so that no point the exact order puts
 * before the k-th is pruned.
 */
typedef struct best {
  qk_neighbor_t *out; /* sorted array or heap of (slot, squared distance) */
  size_t k, n;
  double thr;    /* full: the k-th's squared distance */
  double lim;    /* prune strictly above this: lim0 until full, then min(hi(thr), lim0) */
  double lim0;   /* the limit's upper bound: hi(max_dist^2), or a guessed limit as is */
  double cap_lo; /* a candidate below this is within max_dist; at or above, the exact test */
  double cap;    /* max_dist, for that test */
  uint32_t slot; /* k = 1: the best point's slot (its squared distance is thr), or QK_NONE */
  /* The sorted search's first k candidates, in the order they came (fill_sort). */
  qk_neighbor_t *fill; /* (slot, squared distance) */
  double *keys;        /* their sort keys, 16-byte aligned, room for a power of two >= k */
  double sc; /* the differences' scale, a power of two: 1 except for KIND_SCALED (knn_scale) */
} best_t;

/*
 * The filter's bounds (index/dist_exact.h) without its overflow clause, which kNN does
 * not need: its queries keep the query and the tree within 2^510 (qk__knn_check), so a
 * difference is below 2^511 and a square below 2^1023 (2^1023 (1 + 2^-45) + 2^-1060 too):
 * nothing overflows. Two squares computed the same way: da < kx_lo(db) means a is
 * nearer, da > kx_hi(db) farther, exactly (dist_exact.h's argument); a lower bound above
 * kx_hi(db) means every point it bounds is farther than b. kx_hi(inf) and kx_lo(inf) are
 * inf (a cap whose square overflows holds every point).
 */
static inline double kx_lo(double v) { return v * (1 - QK__FILTER_REL) - QK__FILTER_ABS; }
static inline double kx_hi(double v) { return v * (1 + QK__FILTER_REL) + QK__FILTER_ABS; }

/* A search's limits: the caller's max_dist (guess2 < 0), or a guessed squared limit. */
static inline void best_limits(best_t *b, double max_dist, double guess2) {
  if (guess2 >= 0) {
    b->lim0 = guess2;
    b->cap_lo = INFINITY;
  } else {
    const double cs = max_dist * b->sc, cap2 = cs * cs;
    b->lim0 = kx_hi(cap2);
    b->cap_lo = kx_lo(cap2);
  }
  b->cap = max_dist;
  b->lim = b->thr = b->lim0;
}

/* After the k-th changed (its square now thr): the pruning limit. */
static inline void best_tighten(best_t *b) { b->lim = qk__min_d(kx_hi(b->thr), b->lim0); }

/* Slots a and b in the exact (distance, id) order, their squares too close to tell. */
#if defined(__GNUC__)
__attribute__((noinline, cold))
#endif
static int
before_exact(const qk_tree_t *t, double qx, double qy, uint32_t a, uint32_t b) {
  const double *xs = qk__tree_xs(t), *ys = qk__tree_ys(t);
  int c;
  if (xs[a] == xs[b] && ys[a] == ys[b]) /* one place twice (duplicates): the same distance */
    c = 0;
  else
    c = qk__dist_cmp_exact(qx, qy, xs[a], ys[a], xs[b], ys[b]);
  if (c) return c < 0;
  return qk__tree_ids(t)[a] < qk__tree_ids(t)[b];
}

/* Is slot a (squared distance da) before slot b (db) in the exact (distance, id) order? */
static inline int before(const qk_tree_t *t, double qx, double qy, double da, uint32_t a, double db,
                         uint32_t b) {
  if (da < kx_lo(db)) return 1;
  if (da > kx_hi(db)) return 0;
  return before_exact(t, qx, qy, a, b);
}

/* May slot s (squared distance v) enter while the set is not full: within max_dist? */
static inline int in_cap(const qk_tree_t *t, double qx, double qy, const best_t *b, double v,
                         uint32_t s) {
  return v < b->cap_lo || qk__within_exact(qk__tree_xs(t)[s], qk__tree_ys(t)[s], qx, qy, b->cap, 0);
}

/* The reported distance of a squared distance d2 (that of slot s): sqrt, or beyond
 * 2^1000, where the square may have overflowed, hypot of the differences (as the radius
 * query reports it). d2 infinite (a scaled search's square, which is not the one
 * reported): from the differences, the same value. */
static inline double report_dist(const qk_tree_t *t, double qx, double qy, double d2, uint32_t s) {
  if (d2 < QK__FILTER_MAX) return sqrt(d2);
  const double dx = qk__tree_xs(t)[s] - qx, dy = qk__tree_ys(t)[s] - qy, u2 = dx * dx + dy * dy;
  return u2 < QK__FILTER_MAX ? sqrt(u2) : hypot(dx, dy);
}

/* The max-heap of (slot, squared distance) of the search for k > QK__KNN_SORTED, the
 * exact last at h[0]. */
static void xheap_down(const qk_tree_t *t, double qx, double qy, qk_neighbor_t *h, size_t n,
                       size_t i) {
  const qk_neighbor_t v = h[i];
  for (;;) {
    size_t l = 2 * i + 1, m = i;
    qk_neighbor_t w = v;
    if (l < n && before(t, qx, qy, w.dist, w.id, h[l].dist, h[l].id)) m = l, w = h[l];
    if (l + 1 < n && before(t, qx, qy, w.dist, w.id, h[l + 1].dist, h[l + 1].id)) m = l + 1;
    if (m == i) break;
    h[i] = h[m];
    i = m;
  }
  h[i] = v;
}

/* Offer a leaf's points to a heap of at most k. */
static inline void scan_heap(const qk_tree_t *t, qk_node_t leaf, double qx, double qy, best_t *b,
                             int scaled) {
  const uint32_t start = qk__node_start(t, leaf), count = qk__node_count(t, leaf);
  const double *px = qk__tree_xs(t) + start, *py = qk__tree_ys(t) + start;
  qk_neighbor_t *h = b->out;
  const double sc = scaled ? b->sc : 1.0;
  for (uint32_t i = 0; i < count; i++) {
    const double dx = (px[i] - qx) * sc, dy = (py[i] - qy) * sc;
    const double d2 = dx * dx + dy * dy;
    if (!(d2 <= b->lim)) continue;
    const uint32_t s = start + i;
    if (b->n < b->k) {
      if (!in_cap(t, qx, qy, b, d2, s)) continue;
      size_t j = b->n++;
      for (; j > 0 && before(t, qx, qy, h[(j - 1) / 2].dist, h[(j - 1) / 2].id, d2, s);
           j = (j - 1) / 2)
        h[j] = h[(j - 1) / 2];
      h[j] = (qk_neighbor_t){s, d2};
      if (b->n < b->k) continue;
    } else {
      if (!before(t, qx, qy, d2, s, h[0].dist, h[0].id)) continue;
      h[0] = (qk_neighbor_t){s, d2};
      xheap_down(t, qx, qy, h, b->n, 0);
    }
    b->thr = h[0].dist;
    best_tighten(b);
  }
}

/* Sort the heap ascending in place, then slots to ids and squares to distances. */
static void xheap_finish(const qk_tree_t *t, double qx, double qy, qk_neighbor_t *h, size_t n,
                         int scaled) {
  for (size_t m = n; m > 1;) {
    const qk_neighbor_t top = h[0];
    h[0] = h[--m];
    xheap_down(t, qx, qy, h, m, 0);
    h[m] = top;
  }
  const qk_id_t *pid = qk__tree_ids(t);
  for (size_t i = 0; i < n; i++)
    h[i] = (qk_neighbor_t){pid[h[i].id],
                           report_dist(t, qx, qy, scaled ? INFINITY : h[i].dist, h[i].id)};
}

/*
 * Expand an internal cell: of its children with bound <= thr, the nearest becomes *cur
 * (returns 1) and the others are stacked with the nearest on top; returns 0 when every
 * child is pruned. The children share their edges, so two distances per axis give the
 * four bounds, and their order needs no sort: with the nearer and farther distance per
 * axis (Xn <= Xf, Yn <= Yf), the child on the query's side of both midlines comes first
 * (Xn + Yn), the diagonal one last (Xf + Yf), and one comparison orders the other two.
 */
static inline int expand(const qk_tree_t *t, qk__cell_entry_t *cur, uint32_t child, double qx,
                         double qy, double e, double sc, double thr, qk__cell_entry_t *stack,
                         int *sp) {
  static const unsigned char quad[2][2] = {{QK_SW, QK_NW}, {QK_SE, QK_NE}}; /* [east][north] */
  const qk__cell_t c = cur->c;
  const double hs = qk__tree_side(t, c.depth + 1);
  const double xm = c.x + hs, ym = c.y + hs;
#if defined(__SSE2__)
  /* Both axes in one register: the gaps to the west/south halves (ga) and to the east/north
   * halves (gb), qk__gap's operations lane by lane, so the same values as below. */
  const __m128d vq = _mm_set_pd(qy, qx), vc = _mm_set_pd(c.y, c.x), vm = _mm_set_pd(ym, xm);
  const __m128d vh = _mm_set1_pd(hs), ve = _mm_set1_pd(e), zero = _mm_setzero_pd();
  __m128d ga = _mm_add_pd(_mm_max_pd(_mm_sub_pd(_mm_sub_pd(vc, ve), vq), zero),
                          _mm_max_pd(_mm_sub_pd(vq, _mm_add_pd(vm, ve)), zero));
  __m128d gb = _mm_add_pd(_mm_max_pd(_mm_sub_pd(_mm_sub_pd(vm, ve), vq), zero),
                          _mm_max_pd(_mm_sub_pd(vq, _mm_add_pd(_mm_add_pd(vm, vh), ve)), zero));
  if (sc != 1.0) { /* a scaled search (a constant 1 otherwise, and no code) */
    ga = _mm_mul_pd(ga, _mm_set1_pd(sc));
    gb = _mm_mul_pd(gb, _mm_set1_pd(sc));
  }
  const int nearer = _mm_movemask_pd(_mm_cmplt_pd(gb, ga));
  const unsigned en = (unsigned)nearer & 1u, nn = (unsigned)nearer >> 1;
  const __m128d vn = _mm_min_pd(gb, ga), vf = _mm_max_pd(gb, ga);
  const __m128d n2 = _mm_mul_pd(vn, vn), f2 = _mm_mul_pd(vf, vf);
  const __m128d s1 = _mm_add_pd(_mm_unpacklo_pd(n2, f2), _mm_unpackhi_pd(n2, f2)); /* nn, ff */
  const double bnn = _mm_cvtsd_f64(s1);
  if (bnn > thr) return 0;
  const __m128d s2 = _mm_add_pd(_mm_unpacklo_pd(f2, n2), _mm_unpackhi_pd(n2, f2)); /* fn, nf */
  const double bff = _mm_cvtsd_f64(_mm_unpackhi_pd(s1, s1));
  const double bfn = _mm_cvtsd_f64(s2), bnf = _mm_cvtsd_f64(_mm_unpackhi_pd(s2, s2));
#else
  const double dxw = qk__gap(qx, c.x - e, xm + e) * sc, dxe = qk__gap(qx, xm - e, xm + hs + e) * sc;
  const double dys = qk__gap(qy, c.y - e, ym + e) * sc, dyn = qk__gap(qy, ym - e, ym + hs + e) * sc;
  const unsigned en = dxe < dxw, nn = dyn < dys; /* is the east / north half the nearer? */
  /* The nearer and farther per axis: the same values as choosing by en and nn. */
  const double xn = qk__min_d(dxe, dxw), xf = qk__max_d(dxe, dxw);
  const double yn = qk__min_d(dyn, dys), yf = qk__max_d(dyn, dys);
  const double bnn = xn * xn + yn * yn;
  if (bnn > thr) return 0;
  const double bff = xf * xf + yf * yf, bfn = xf * xf + yn * yn, bnf = xn * xn + yf * yf;
#endif
  const uint32_t d = c.depth + 1;
  const double xs[2] = {c.x, xm}, ys[2] = {c.y, ym};
#define QK__PUSH(east, north, bound)                                                               \
  stack[(*sp)++] = (qk__cell_entry_t) {                                                            \
    {child + quad[east][north], d, xs[east], ys[north]}, (bound)                                   \
  }
  if (bff <= thr) QK__PUSH(!en, !nn, bff);
  if (bfn > bnf) {
    if (bfn <= thr) QK__PUSH(!en, nn, bfn);
    if (bnf <= thr) QK__PUSH(en, !nn, bnf);
  } else {
    if (bnf <= thr) QK__PUSH(en, !nn, bnf);
    if (bfn <= thr) QK__PUSH(!en, nn, bfn);
  }
#undef QK__PUSH
  *cur = (qk__cell_entry_t){{child + quad[en][nn], d, xs[en], ys[nn]}, bnn};
  return 1;
}

/*
 * Stack the children of the path cell p other than its child `skip` (which the first
 * descent entered, and which holds the query), those with bound <= thr, nearest on top.
 * The query lies in skip's half on each axis, so the sibling across the x midline is
 * bounded by the x gap alone (dx^2), the one across the y midline by dy^2 and the diagonal
 * one by dx^2 + dy^2, at least either: the order needs one comparison, and the kept ones
 * are always the nearest m (kept diagonal => both kept; kept farther => nearer kept). So the
 * three are written in pushing order, farthest first, each over the last unless kept
 * (the stack pointer advanced by its flag), with no branch on the bounds, which go either
 * way at random. (Dropping the gap on the query's own side, 0 up to roundings inside the
 * margin, only lowers a bound, which stays a lower bound.)
 */
static QK__ALWAYS_INLINE void push_siblings(const qk_tree_t *t, qk__cell_t p, uint32_t child,
                                            unsigned skip, double qx, double qy, double e,
                                            double sc, double thr, qk__cell_entry_t *stack,
                                            int *sp) {
  static const unsigned char quad[2][2] = {{QK_SW, QK_NW}, {QK_SE, QK_NE}}; /* [east][north] */
  const unsigned ex = (0x9u >> skip) & 1u,
                 no = (0x3u >> skip) & 1u; /* skip is NE or SE; NE or NW */
  const double hs = qk__tree_side(t, p.depth + 1);
  const double xm = p.x + hs, ym = p.y + hs;
  const double xs[2] = {p.x, xm}, ys[2] = {p.y, ym};
  /* The gaps to the other half on each axis, whose corner is chosen by index, not by a
   * branch (the same intervals and values as expand's: x0 + hs is xm). */
  const double ox = xs[!ex], oy = ys[!no];
  const double dx = qk__gap(qx, ox - e, ox + hs + e) * sc,
               dy = qk__gap(qy, oy - e, oy + hs + e) * sc;
  const double bx = dx * dx, by = dy * dy;
  const double bd = bx + by, bn = qk__min_d(bx, by), bf = qk__max_d(bx, by);
  const unsigned xn = bx < by; /* the sibling across the x midline is the nearer */
  const uint32_t d = p.depth + 1;
  int s = *sp;
  stack[s] = (qk__cell_entry_t){{child + quad[!ex][!no], d, xs[!ex], ys[!no]}, bd};
  s += bd <= thr;
  const unsigned fe = ex ^ !xn, fn = no ^ xn; /* the farther: across y when x is nearer */
  stack[s] = (qk__cell_entry_t){{child + quad[fe][fn], d, xs[fe], ys[fn]}, bf};
  s += bf <= thr;
  const unsigned ne = ex ^ xn, nn = no ^ !xn;
  stack[s] = (qk__cell_entry_t){{child + quad[ne][nn], d, xs[ne], ys[nn]}, bn};
  s += bn <= thr;
  *sp = s;
}

/*
 * Is every point outside the square (x0, y0, side) farther from q than thr (squared)?
 * Such a point lies beyond one of the square's edges widened by e, so its computed
 * distance is at least the gap from q to that widened edge (subtraction and squaring are
 * monotone in floating point). q lies in the square.
 */
static inline bool ball_inside(double qx, double qy, double x0, double y0, double side, double e,
                               double sc, double thr) {
#if defined(__SSE2__)
  /* Both axes at once: the same differences, lane by lane. */
  const __m128d q = _mm_set_pd(qy, qx), c = _mm_set_pd(y0, x0), ve = _mm_set1_pd(e);
  const __m128d lo = _mm_sub_pd(q, _mm_add_pd(c, ve));
  const __m128d hi = _mm_sub_pd(_mm_sub_pd(_mm_add_pd(c, _mm_set1_pd(side)), ve), q);
  const __m128d m = _mm_min_pd(lo, hi);
  const double g = _mm_cvtsd_f64(_mm_min_sd(m, _mm_unpackhi_pd(m, m))) * sc;
#else
  const double g = qk__min_d(qk__min_d(qx - (x0 + e), (x0 + side - e) - qx),
                             qk__min_d(qy - (y0 + e), (y0 + side - e) - qy)) *
                   sc;
#endif
  return (g > 0) & (g * g > thr);
}

/* Which of the three leaf scans a search runs (a constant in each caller, so that the
 * compiler makes one specialised search per kind). */
enum { KIND_ONE, KIND_SORTED, KIND_HEAP, KIND_SCALED };

/* The differences' scale of a search (b->sc for KIND_SCALED, a constant 1 otherwise). */
#define QK__SC(kind, b) ((kind) == KIND_SCALED ? (b)->sc : 1.0)

/* Points whose squared distances one pass of the leaf scans computes into a buffer. */
#define QK__SCAN_CHUNK 64

#if defined(__SSE2__)
/* Squared distances to the points i and i + 1, into d2[i] and d2[i + 1]. */
static inline __m128d pair_d2(const double *xs, const double *ys, uint32_t i, __m128d vx,
                              __m128d vy, double *d2) {
  const __m128d dx = _mm_sub_pd(_mm_loadu_pd(xs + i), vx);
  const __m128d dy = _mm_sub_pd(_mm_loadu_pd(ys + i), vy);
  const __m128d d = _mm_add_pd(_mm_mul_pd(dx, dx), _mm_mul_pd(dy, dy));
  _mm_storeu_pd(d2 + i, d);
  return d;
}
#endif

/*
 * Squared distances from (qx, qy) to the m points (xs[i], ys[i]) into d2[], two at a
 * time where SSE2 is there (the same IEEE operations lane by lane as the scalar code, so
 * the same values), and the smallest of them. No branch depends on the data, so the loads
 * of a leaf's lines all go out at once and the loop costs a few instructions per point.
 * The last pair is done first, at m - 2, and the loop stops before it: for an odd count
 * the two overlap at m - 2, whose value is written twice, the same. That is a fixed step
 * instead of a scalar tail whose "one more?" branch goes either way from leaf to leaf
 * (the same in equal_mask and within).
 */
static inline double leaf_d2(const double *xs, const double *ys, uint32_t m, double qx, double qy,
                             double *d2) {
#if defined(__SSE2__)
  if (m >= 2) {
    const __m128d vx = _mm_set1_pd(qx), vy = _mm_set1_pd(qy);
    __m128d vlo = pair_d2(xs, ys, m - 2, vx, vy, d2); /* the last pair, first */
    for (uint32_t i = 0; i + 2 < m; i += 2) vlo = _mm_min_pd(vlo, pair_d2(xs, ys, i, vx, vy, d2));
    return _mm_cvtsd_f64(_mm_min_sd(vlo, _mm_unpackhi_pd(vlo, vlo)));
  }
#endif
  double lo = INFINITY;
  for (uint32_t i = 0; i < m; i++) {
    const double dx = xs[i] - qx, dy = ys[i] - qy;
    d2[i] = dx * dx + dy * dy;
    lo = qk__min_d(lo, d2[i]);
  }
  return lo;
}

/* Index of the lowest set bit of a nonzero v. */
static inline uint32_t ctz64(uint64_t v) {
#if defined(__GNUC__)
  return (uint32_t)__builtin_ctzll(v);
#else
  uint32_t i = 0;
  while (!(v >> i & 1)) i++;
  return i;
#endif
}

/* Bit i set when d2[i] <= v, for the m <= 64 values of d2[] (usually one bit: v is the
 * filter's upper bound of their minimum). */
static inline uint64_t le_mask(const double *d2, uint32_t m, double v) {
  uint64_t mask = 0;
#if defined(__SSE2__)
  if (m >= 2) {
    const __m128d vv = _mm_set1_pd(v);
    mask = (uint64_t)_mm_movemask_pd(_mm_cmple_pd(_mm_loadu_pd(d2 + m - 2), vv)) << (m - 2);
    for (uint32_t i = 0; i + 2 < m; i += 2)
      mask |= (uint64_t)_mm_movemask_pd(_mm_cmple_pd(_mm_loadu_pd(d2 + i), vv)) << i;
    return mask;
  }
#endif
  for (uint32_t i = 0; i < m; i++) mask |= (uint64_t)(d2[i] <= v) << i;
  return mask;
}

#if QK__KNN_AVX2
/* Squared distances to the points i .. i + 3 into d2[i ..], the same IEEE operations lane by
 * lane as pair_d2 (AVX2 without FMA: nothing is contracted), so the same values. */
__attribute__((target("avx2"))) static inline __m256d
quad_d2(const double *xs, const double *ys, uint32_t i, __m256d vx, __m256d vy, double *d2) {
  const __m256d dx = _mm256_sub_pd(_mm256_loadu_pd(xs + i), vx);
  const __m256d dy = _mm256_sub_pd(_mm256_loadu_pd(ys + i), vy);
  const __m256d d = _mm256_add_pd(_mm256_mul_pd(dx, dx), _mm256_mul_pd(dy, dy));
  _mm256_storeu_pd(d2 + i, d);
  return d;
}

/* leaf_d2 and, when the smallest value is at most lim, le_mask(d2, m, kx_hi(lo)), four
 * points at a time, for 4 <= m <= 64; *lo gets the smallest value. 0 when it is above lim
 * (the mask is never 0 otherwise: it holds the smallest). */
__attribute__((target("avx2"), noinline)) static uint64_t
one_chunk_avx2(const double *xs, const double *ys, uint32_t m, double qx, double qy, double lim,
               double *d2, double *lo) {
  const __m256d vx = _mm256_set1_pd(qx), vy = _mm256_set1_pd(qy);
  __m256d vlo = quad_d2(xs, ys, m - 4, vx, vy, d2); /* the last four, first (as leaf_d2) */
  for (uint32_t i = 0; i + 4 < m; i += 4) vlo = _mm256_min_pd(vlo, quad_d2(xs, ys, i, vx, vy, d2));
  const __m128d h = _mm_min_pd(_mm256_castpd256_pd128(vlo), _mm256_extractf128_pd(vlo, 1));
  const double v = _mm_cvtsd_f64(_mm_min_sd(h, _mm_unpackhi_pd(h, h)));
  *lo = v;
  if (!(v <= lim)) return 0;
  const __m256d vv = _mm256_set1_pd(kx_hi(v));
  uint64_t mask =
      (uint64_t)_mm256_movemask_pd(_mm256_cmp_pd(_mm256_loadu_pd(d2 + m - 4), vv, _CMP_LE_OQ))
      << (m - 4);
  for (uint32_t i = 0; i + 4 < m; i += 4)
    mask |= (uint64_t)_mm256_movemask_pd(_mm256_cmp_pd(_mm256_loadu_pd(d2 + i), vv, _CMP_LE_OQ))
            << i;
  return mask;
}
#endif

/*
 * The k = 1 leaf scan, in two steps per chunk: the smallest squared distance (leaf_d2),
 * and only when it can beat or tie the best so far, which point has it. The best is kept
 * as a slot, and ids are read only to break a tie (several points whose squares lie
 * within the filter's margin of the minimum, ranked exactly: before()), which is what
 * offering every point in turn with the exact (distance, id) order gives. The
 * point's id is read once, at the end (knn1): in a tree larger than the cache an id is a
 * miss of its own, and reading it here would put that miss between the scan and every
 * decision after it.
 */
static inline void scan_one(const qk_tree_t *t, qk_node_t leaf, double qx, double qy, best_t *b) {
  const uint32_t start = qk__node_start(t, leaf), count = qk__node_count(t, leaf);
  const double *xs = qk__tree_xs(t) + start, *ys = qk__tree_ys(t) + start;
  double d2[QK__SCAN_CHUNK];
  for (uint32_t base = 0; base < count; base += QK__SCAN_CHUNK) {
    const uint32_t m = count - base < QK__SCAN_CHUNK ? count - base : QK__SCAN_CHUNK;
    uint64_t at;
#if QK__KNN_AVX2
    if (m >= 4 && !qk__knn_avx2_off && __builtin_cpu_supports("avx2")) {
      double lo;
      at = one_chunk_avx2(xs + base, ys + base, m, qx, qy, b->lim, d2, &lo);
      if (!at) continue;
    } else
#endif
    {
      const double lo = leaf_d2(xs + base, ys + base, m, qx, qy, d2);
      if (!(lo <= b->lim)) continue;
      at = le_mask(d2, m, kx_hi(lo));
    }
    uint32_t i = ctz64(at), s = start + base + i;
    double ds = d2[i];
    if (at & (at - 1)) { /* several points near that distance: the exact order decides */
      for (uint64_t r = at & (at - 1); r; r &= r - 1) {
        const uint32_t i2 = ctz64(r), s2 = start + base + i2;
        if (before(t, qx, qy, d2[i2], s2, ds, s)) s = s2, ds = d2[i2];
      }
    }
    if (b->slot == QK_NONE ? in_cap(t, qx, qy, b, ds, s)
                           : before(t, qx, qy, ds, s, b->thr, b->slot)) {
      b->thr = ds;
      b->slot = s;
      best_tighten(b);
    }
  }
}

/*
 * Squared distances from (qx, qy) to the m <= 64 points (xs[i], ys[i]) into d2[], and a
 * mask of those within thr (bit i: d2[i] <= thr), in one pass, two points at a time where
 * SSE2 is there (the same IEEE operations as the scalar tail, so the same values). The
 * points' side of the threshold is then data, not a branch per point, which mispredicts
 * about as often as a point passes.
 */
static inline uint64_t within(const double *xs, const double *ys, uint32_t m, double qx, double qy,
                              double thr, double *d2) {
  uint64_t mask = 0;
#if defined(__SSE2__)
  if (m >= 2) {
    const __m128d vx = _mm_set1_pd(qx), vy = _mm_set1_pd(qy), vt = _mm_set1_pd(thr);
    mask = (uint64_t)_mm_movemask_pd(_mm_cmple_pd(pair_d2(xs, ys, m - 2, vx, vy, d2), vt))
           << (m - 2);
    for (uint32_t i = 0; i + 2 < m; i += 2)
      mask |= (uint64_t)_mm_movemask_pd(_mm_cmple_pd(pair_d2(xs, ys, i, vx, vy, d2), vt)) << i;
    return mask;
  }
#endif
  for (uint32_t i = 0; i < m; i++) {
    const double dx = xs[i] - qx, dy = ys[i] - qy;
    d2[i] = dx * dx + dy * dy;
    mask |= (uint64_t)(d2[i] <= thr) << i;
  }
  return mask;
}

/*
 * The sorted search's first k candidates are not inserted one by one: they are appended
 * as they come (the threshold is the caller's limit until k are there, so nothing else
 * depends on their order), and sorted once, when the k-th arrives or the search ends.
 * Inserting them kept the array sorted at the cost of the inversions in their order of
 * arrival, a shift of an entry each, and of one mispredicted branch per insertion, where
 * the shift stopped (about a third of the instructions and half of the mispredictions of
 * a k = 32 search). The sort is a network of minima and maxima with no branch on the data:
 * each candidate gets a key, the bits of its squared distance (a nonnegative double, whose
 * bits as an integer have the same order) shifted right by one, with the six low bits
 * replaced by its place in the fill order, and one binade added: a positive, normal double
 * (never subnormal, which a processor set to treat subnormal inputs as zero, as programs
 * linked with -ffast-math are, would read as 0, losing the place) whose order is that of
 * the distances wherever those differ above their seven low bits. Keys are distinct, so
 * the network sorts them without ties, and the candidates follow their keys. Two keys
 * whose distances agree above the low bits (equal distances, which the (distance, id)
 * order breaks by id, or nearly equal ones) are found in one pass over neighbours, and
 * only then are the candidates sorted again by comparisons, exactly.
 */
#define QK__FILL_LOW 63u /* the low bits of a key that hold the candidate's place */

/* Unroll the loop that follows (the sorting network's, whose bounds are constants once it
 * is inlined; not under the sanitizers, which inline nothing by force: index/inline.h). */
#if defined(QK__SANITIZED)
#define QK__UNROLL
#elif defined(__GNUC__) && !defined(__clang__)
#define QK__UNROLL _Pragma("GCC unroll 32")
#elif defined(__clang__)
#define QK__UNROLL _Pragma("unroll")
#else
#define QK__UNROLL
#endif

static inline uint64_t key_bits(double v) {
  uint64_t b;
  memcpy(&b, &v, sizeof b);
  return b;
}

static inline double make_key(double d2, uint32_t place) {
  const uint64_t b = ((key_bits(d2) >> 1 & ~(uint64_t)QK__FILL_LOW) | place) + ((uint64_t)1 << 52);
  double v;
  memcpy(&v, &b, sizeof v);
  return v;
}

#if defined(__SSE2__)
/* Compare-exchange of the pairs (i, i + 1) and (i + 2, i + 3). */
static inline void cx_adjacent(double *a, unsigned i) {
  const __m128d x = _mm_load_pd(a + i), y = _mm_load_pd(a + i + 2);
  const __m128d lo = _mm_unpacklo_pd(x, y), hi = _mm_unpackhi_pd(x, y);
  const __m128d mn = _mm_min_pd(lo, hi), mx = _mm_max_pd(lo, hi);
  _mm_store_pd(a + i, _mm_unpacklo_pd(mn, mx));
  _mm_store_pd(a + i + 2, _mm_unpackhi_pd(mn, mx));
}

/* The m keys' pairs (i, i + 1), i even, smaller first. */
static QK__ALWAYS_INLINE void cx_pairs(double *a, unsigned m) {
  QK__UNROLL
  for (unsigned i = 0; i < m; i += 4) cx_adjacent(a, i);
}

/* In each block of sz, entry t against entry sz - 1 - t, smaller first. */
static QK__ALWAYS_INLINE void cx_mirror(double *a, unsigned m, unsigned sz) {
  QK__UNROLL
  for (unsigned i = 0; i < m / 2; i += 2) {
    const unsigned b = i / (sz / 2) * sz, t = i % (sz / 2);
    const __m128d x = _mm_load_pd(a + b + t), z = _mm_load_pd(a + b + sz - 2 - t);
    const __m128d y = _mm_shuffle_pd(z, z, 1), mx = _mm_max_pd(x, y);
    _mm_store_pd(a + b + t, _mm_min_pd(x, y));
    _mm_store_pd(a + b + sz - 2 - t, _mm_shuffle_pd(mx, mx, 1));
  }
}

/* Entry i against entry i + j (j >= 2) where i & j is 0, smaller first. */
static QK__ALWAYS_INLINE void cx_apart(double *a, unsigned m, unsigned j) {
  QK__UNROLL
  for (unsigned h = 0; h < m / 2; h += 2) {
    const unsigned i = h / j * 2 * j + h % j;
    const __m128d x = _mm_load_pd(a + i), y = _mm_load_pd(a + i + j);
    _mm_store_pd(a + i, _mm_min_pd(x, y));
    _mm_store_pd(a + i + j, _mm_max_pd(x, y));
  }
}

/*
 * Sort the m (a power of two, 4 to 32) keys a[] ascending: Batcher's bitonic sorter in
 * the form whose comparators all put the smaller first (each merge of two sorted halves
 * of a block compares them mirror-wise, then cleans each half). Two comparators per
 * instruction, no branch.
 */
static QK__ALWAYS_INLINE void bitonic(double *a, unsigned m) {
  cx_pairs(a, m);
  cx_mirror(a, m, 4);
  cx_pairs(a, m);
  if (m == 4) return;
  cx_mirror(a, m, 8);
  cx_apart(a, m, 2);
  cx_pairs(a, m);
  if (m == 8) return;
  cx_mirror(a, m, 16);
  cx_apart(a, m, 4);
  cx_apart(a, m, 2);
  cx_pairs(a, m);
  if (m == 16) return;
  cx_mirror(a, m, 32);
  cx_apart(a, m, 8);
  cx_apart(a, m, 4);
  cx_apart(a, m, 2);
  cx_pairs(a, m);
}
#endif

/* Sort the n <= 32 keys a[], padded with +infinity up to a power of two (room for it). */
static inline void sort_keys(double *a, unsigned n) {
  unsigned m = 2;
  while (m < n) m <<= 1;
  for (unsigned i = n; i < m; i++) a[i] = INFINITY;
#if defined(__SSE2__)
  /* One specialised network per width, which the compiler unrolls. */
  switch (m) {
  case 2:
    break;
  case 4:
    bitonic(a, 4);
    return;
  case 8:
    bitonic(a, 8);
    return;
  case 16:
    bitonic(a, 16);
    return;
  default:
    bitonic(a, 32);
    return;
  }
#endif
  /* Insertion sort (no SSE2, or two keys). */
  for (unsigned i = 1; i < m; i++) {
    const double v = a[i];
    unsigned j = i;
    for (; j > 0 && a[j - 1] > v; j--) a[j] = a[j - 1];
    a[j] = v;
  }
}

/*
 * The n first candidates fill[] of a sorted search, sorted by (distance, id) into o[],
 * through their keys[] (fill_sort's comment above).
 */
static void fill_sort(const qk_tree_t *t, double qx, double qy, const qk_neighbor_t *fill,
                      double *keys, size_t n, qk_neighbor_t *o) {
  sort_keys(keys, (unsigned)n);
  /* In key order the squares are increasing unless two agree above the low bits, and the
   * exact order is theirs when each is beyond the filter's margin of the one before. */
  int clash = 0;
  o[0] = fill[key_bits(keys[0]) & QK__FILL_LOW];
  for (size_t i = 1; i < n; i++) {
    o[i] = fill[key_bits(keys[i]) & QK__FILL_LOW];
    clash |= !(o[i].dist > kx_hi(o[i - 1].dist));
  }
  if (!clash) return;
  /* Equal (or nearly equal) distances: by exact comparisons, ties by id. */
  for (size_t i = 0; i < n; i++) {
    const qk_neighbor_t v = fill[i];
    size_t j = i;
    for (; j > 0 && before(t, qx, qy, v.dist, v.id, o[j - 1].dist, o[j - 1].id); j--)
      o[j] = o[j - 1];
    o[j] = v;
  }
}

/*
 * Offer a leaf's points to a sorted array of at most k (squared distance, slot) pairs.
 * The array keeps slots, not ids, as the k = 1 search does: an id is read
 * only when two distances tie (the (distance, id) order), and the k ids at the end, all
 * at once (knn_search). In a tree larger than the cache the ids are lines of their own,
 * and most candidates are pushed out again before the end. The insertion compares
 * distances alone while they differ (one comparison per entry moved).
 */
static inline void scan_sorted(const qk_tree_t *t, qk_node_t leaf, double qx, double qy,
                               best_t *b) {
  const uint32_t start = qk__node_start(t, leaf), count = qk__node_count(t, leaf);
  const double *xs = qk__tree_xs(t) + start, *ys = qk__tree_ys(t) + start;
  qk_neighbor_t *o = b->out;
  const size_t k = b->k;
  /* In locals: the stores into o could alias them. */
  size_t n = b->n;
  double lim = b->lim;
  double d2[QK__SCAN_CHUNK];
  for (uint32_t base = 0; base < count; base += QK__SCAN_CHUNK) {
    const uint32_t m = count - base < QK__SCAN_CHUNK ? count - base : QK__SCAN_CHUNK;
    for (uint64_t r = within(xs + base, ys + base, m, qx, qy, lim, d2); r; r &= r - 1) {
      const uint32_t i = ctz64(r), s = start + base + i;
      const double v = d2[i];
      qk_neighbor_t *at;
      if (n < k) {
        /* Within the cap, appended; sorted once the k-th is there (fill_sort), the
         * threshold then its distance. */
        if (!in_cap(t, qx, qy, b, v, s)) continue;
        b->fill[n] = (qk_neighbor_t){s, v};
        b->keys[n] = make_key(v, (uint32_t)n);
        if (++n == k) {
          fill_sort(t, qx, qy, b->fill, b->keys, k, o);
          b->thr = o[k - 1].dist;
          best_tighten(b);
          lim = b->lim;
        }
        continue;
      }
      {
        /* The threshold is the last entry's distance, which may have shrunk since. */
        const qk_neighbor_t w = o[k - 1];
        if (!before(t, qx, qy, v, s, w.dist, w.id)) continue;
        at = o + k - 1;
      }
      /* o[-1] is a sentinel at distance -infinity (knn_search), so no bound check, and
       * the exact loop never reads its slot. Entries whose squares are beyond the filter's
       * margin above v's come after it; within the margin the exact order decides. */
      const double vhi = kx_hi(v), vlo = kx_lo(v);
      for (; at[-1].dist > vhi; at--) *at = at[-1];
      for (; at[-1].dist >= vlo && before_exact(t, qx, qy, s, at[-1].id); at--) *at = at[-1];
      *at = (qk_neighbor_t){s, v};
      b->thr = o[k - 1].dist;
      best_tighten(b);
      lim = b->lim;
    }
  }
  b->n = n;
}

/* Ask for the x and y lines of a leaf's first points (at most 64). */
static QK__ALWAYS_INLINE void prefetch_points(const qk_tree_t *t, qk_node_t leaf) {
  const uint32_t start = qk__node_start(t, leaf), count = qk__node_count(t, leaf);
  const uint32_t m = count < 64 ? count : 64;
  if (m == 0) return;
  const double *xs = qk__tree_xs(t) + start, *ys = qk__tree_ys(t) + start;
  /* A line every 8 doubles, and the last point's, which the steps miss when the leaf does
   * not start on a line. */
  for (uint32_t i = 0; i < m; i += 8) {
    QK__PREFETCH(xs + i);
    QK__PREFETCH(ys + i);
  }
  QK__PREFETCH(xs + m - 1);
  QK__PREFETCH(ys + m - 1);
}

/*
 * Ask for the ids of a leaf's points (those of its first 32). The k = 1 and sorted searches
 * read ids only at the end, and the answer lies most often in the leaf that holds the
 * query: asked for with that leaf's coordinates, the line is there by then instead of
 * being a miss of its own after the whole search. The first, middle and last of up to 32
 * ids (128 bytes) touch every line they span, with no test on the count.
 */
static QK__ALWAYS_INLINE void prefetch_ids(const qk_tree_t *t, qk_node_t leaf) {
  const uint32_t start = qk__node_start(t, leaf), count = qk__node_count(t, leaf);
  if (count == 0) return;
  const uint32_t m = count < 32 ? count : 32;
  const qk_id_t *pid = qk__tree_ids(t) + start;
  QK__PREFETCH(pid);
  QK__PREFETCH(pid + (m - 1) / 2);
  QK__PREFETCH(pid + m - 1);
}

/* Ask for what the climb reads first at uncle u: its children's block, or its points
 * when it is a leaf. */
static QK__ALWAYS_INLINE void prefetch_uncle(const qk_tree_t *t, uint32_t u) {
  const uint32_t c = qk__node_child(t, u);
  if (c == QK_NONE) {
    prefetch_points(t, u);
  } else {
    qk__node_prefetch(t, c); /* the block of four children spans one or two lines */
    qk__node_prefetch(t, c + 3);
  }
}

/*
 * Before a 1-NN search scans the leaf at the end of path p, ask for what its climb most
 * often reads at a cache miss of its own: the nodes below the leaf's parent's siblings
 * (the "uncles"), or their points when they are leaves. When the nearest point lies
 * across the parent's edge, the climb reaches an uncle, and without this it would read
 * the uncle's children and then their points one miss after the other, each after the
 * scan that admitted them. The uncles' own nodes share a block with the parent, which the
 * descent just read, so choosing costs no miss. Only the uncles across the parent's edges
 * that the leaf touches are asked for: the one across the parent's midline-side edge in x
 * when the leaf lies on that side of the parent, likewise in y, and the diagonal one when
 * the leaf touches both (1.25 uncles a query on average instead of 3). An uncle across an
 * edge the leaf does not touch is at least the leaf's side away, and the climb reaches it
 * only when no point of the leaf or its siblings lies that near: at 1M uniform points
 * (capacity 32, where every uncle is internal and asking for it means its children's
 * block, two lines) the climb expanded 0.115 uncles a query, every one of them among
 * those asked for, so the lines asked for go from 6 to 2.5 a query (0.23 of them read
 * later, by either choice). The leaf's siblings are
 * not asked for: their points lie next to the leaf's in memory (leaves are stored in
 * Z-order), and in an A/B at 1M uniform points asking for them cost more than it saved,
 * as did this for k = 8 and 32, whose searches are bound by their insertions rather than
 * by misses. Only hints: the search is the same.
 */
static QK__ALWAYS_INLINE void prefetch_uncles(const qk_tree_t *t, const qk__path_t *p) {
  if (p->len < 2) return;
  const unsigned g = p->len - 2; /* the grandparent's level */
  const uint32_t first = qk__node_child(t, p->cell[g].node);
  const unsigned pq = p->q[g], lq = p->q[g + 1]; /* the parent's and the leaf's quadrants */
  /* The leaf touches the parent's edge on the grandparent's midline in x (y) when its
   * east (north) side differs from the parent's. Flipping east is ^1 on the quadrant
   * numbers (NE, NW, SW, SE = 0..3), north ^3, both ^2. An uncle not wanted is replaced by
   * the parent, whose children's block the descent has just read (asked for again at no
   * cost): a test to skip it would go either way from query to query. */
  const unsigned in_x = qk__q_east(pq) != qk__q_east(lq);
  const unsigned in_y = qk__q_north(pq) != qk__q_north(lq);
  prefetch_uncle(t, first + (pq ^ in_x));
  prefetch_uncle(t, first + (pq ^ (3u * in_y)));
  prefetch_uncle(t, first + (pq ^ (2u * (in_x & in_y))));
}

/*
 * Before a 1-NN or sorted (k <= 32) search scans the leaf at the end of path p, ask for
 * the lines of the leaf's nearest sibling, the one across the parent's midline nearer the
 * query: its points (the first, middle and last of up to 32, every line of up to 16), or
 * its children's block when it is internal. At 1M uniform points 38% of the 1-NN searches
 * go on after the query leaf (0.5 more leaves a query), most often into that sibling,
 * whose points were then a miss after the scan that admitted it. Its node shares the
 * leaf's block, whose two lines the descent asked for. The other two siblings are not
 * asked for: they are reached less often; asking for all three gave nothing measurable in
 * an earlier round, and for both edge siblings was no steadier than for the nearest alone
 * (docs/query.md). A k = 8 search scans 3 leaves a query, nearly all within its final
 * k-th distance, the sibling most often among them: asking for it made k = 8 0.86-0.90
 * and k = 32 0.95 of the time (in-process A/B, fifteenth session). Only hints: the search
 * is the same.
 */
static QK__ALWAYS_INLINE void prefetch_sibling(const qk_tree_t *t, const qk__path_t *p, double qx,
                                               double qy) {
  if (p->len < 1) return;
  const qk__cell_t par = p->cell[p->len - 1];
  const double h = qk__tree_side(t, par.depth + 1);
  /* Across x (east flipped, ^1 on the quadrant numbers) when the x midline is the nearer,
   * else across y (north flipped, ^3); chosen without a branch, which would go either way
   * from query to query. */
  const unsigned xn = fabs(qx - (par.x + h)) < fabs(qy - (par.y + h));
  const unsigned flip = 3u - 2u * xn;
  const uint32_t s = qk__node_child(t, par.node) + (p->q[p->len - 1] ^ flip);
  const uint32_t c = qk__node_child(t, s);
  if (c != QK_NONE) {
    qk__node_prefetch(t, c);
    qk__node_prefetch(t, c + 3);
    return;
  }
  const uint32_t start = qk__node_start(t, s), count = qk__node_count(t, s);
  if (count == 0) return;
  const uint32_t m = count < 32 ? count : 32;
  const double *xs = qk__tree_xs(t) + start, *ys = qk__tree_ys(t) + start;
  QK__PREFETCH(xs);
  QK__PREFETCH(ys);
  QK__PREFETCH(xs + (m - 1) / 2);
  QK__PREFETCH(ys + (m - 1) / 2);
  QK__PREFETCH(xs + m - 1);
  QK__PREFETCH(ys + m - 1);
}

/* Scan a leaf into the best-so-far set. For KIND_ONE, the best is (b->thr, b->slot). */
static QK__ALWAYS_INLINE void scan(const qk_tree_t *t, qk_node_t leaf, double qx, double qy,
                                   best_t *b, int kind) {
  if (kind == KIND_SORTED)
    scan_sorted(t, leaf, qx, qy, b);
  else if (kind == KIND_HEAP)
    scan_heap(t, leaf, qx, qy, b, 0);
  else if (kind == KIND_SCALED)
    scan_heap(t, leaf, qx, qy, b, 1);
  else
    scan_one(t, leaf, qx, qy, b);
}

/*
 * Before a leaf's scan in a search for k > 1, ask for what the search reads next: the top
 * of the stack, its points when it is a leaf, else its children's block. Its node shares
 * a block with the leaf or with one of the path's cells, read already. The scan then
 * overlaps that miss instead of being followed by it. Whatever its bound: a test of it
 * against the threshold would go either way at random (with the test, 24.1 mispredicted
 * branches a k = 8 query and 52.4 for k = 32 under callgrind, without it 23.2 and 50.8,
 * and no slower in the A/B). Only a hint: the search is the same.
 * In-process A/B at 1M uniform points (fifteenth session), with the sibling asked for
 * (prefetch_sibling) in both: k = 32 0.86-0.89 of the time against 0.95 without this,
 * k = 8 about 0.01-0.02 better, k = 64 0.95-0.98 (the same driver against itself 1.03);
 * for k = 1, whose climb rarely goes past the sibling, nothing measurable (1.005-1.01
 * against 1.007-1.02), so it is not asked for there.
 */
static QK__ALWAYS_INLINE void prefetch_next(const qk_tree_t *t, const qk__cell_entry_t *stack,
                                            int sp) {
  if (sp == 0) return;
  const qk__cell_entry_t *n = &stack[sp - 1];
  const uint32_t c = qk__node_child(t, n->c.node);
  if (c == QK_NONE) {
    prefetch_points(t, n->c.node);
  } else {
    qk__node_prefetch(t, c);
    qk__node_prefetch(t, c + 3);
  }
}

/* Depth-first search of everything on the stack: pop, descend nearest-first, scan. */
static QK__ALWAYS_INLINE void drain(const qk_tree_t *t, double qx, double qy, double e, best_t *b,
                                    qk__cell_entry_t *stack, int *sp, int kind) {
  while (*sp > 0) {
    qk__cell_entry_t cur = stack[--*sp];
    if (cur.bound > b->lim) continue;
    for (;;) {
      const uint32_t child = qk__node_child(t, cur.c.node);
      if (child == QK_NONE) {
        /* The sorted search reads the ids of its answers at the end: this leaf's are then
         * in cache if it holds any, instead of a miss after the whole search. */
        if (kind == KIND_SORTED) prefetch_ids(t, cur.c.node);
        if (kind != KIND_ONE) prefetch_next(t, stack, *sp);
        scan(t, cur.c.node, qx, qy, b, kind);
        /* The 1-NN search reads its answer's id at the end: the query leaf's ids were
         * asked for with its points, but a best found on the climb (13.9% of the answers
         * at 1M uniform points) would be a miss after the whole search; asked for now, it
         * overlaps the rest of the climb. */
        if (kind == KIND_ONE && b->slot != QK_NONE) QK__PREFETCH(qk__tree_ids(t) + b->slot);
        break;
      }
      if (!expand(t, &cur, child, qx, qy, e, QK__SC(kind, b), b->lim, stack, sp)) break;
    }
  }
}

/* Scan the leaf at the end of a path, then climb it: each level's other children are
 * bounded from the path's square and searched, nearest first, before the level above. */
static QK__ALWAYS_INLINE void climb(const qk_tree_t *t, double qx, double qy, best_t *b, int kind,
                                    const qk__path_t *p) {
  const double e = qk__margin(t);
  qk__cell_entry_t stack[QK__STACK_MAX];
  int sp = 0;
  qk__cell_t c = p->leaf;
  unsigned len = p->len;
  if (kind == KIND_ONE) prefetch_uncles(t, p);
  if (kind != KIND_HEAP && kind != KIND_SCALED) prefetch_ids(t, c.node);
  if (kind != KIND_HEAP && kind != KIND_SCALED) prefetch_sibling(t, p, qx, qy);
  scan(t, c.node, qx, qy, b, kind);
  while (len > 0) {
    /* Everything inside c is done. When the threshold's ball lies inside c's square
     * (narrowed by the margin), nothing outside can come within it: stop climbing. */
    if (ball_inside(qx, qy, c.x, c.y, qk__tree_side(t, c.depth), e, QK__SC(kind, b), b->lim)) break;
    len--;
    push_siblings(t, p->cell[len], qk__node_child(t, p->cell[len].node), p->q[len], qx, qy, e,
                  QK__SC(kind, b), b->lim, stack, &sp);
    drain(t, qx, qy, e, b, stack, &sp, kind);
    c = p->cell[len];
  }
}

/*
 * The search. For a query inside the root, first straight down to the leaf that holds it
 * (by the tie rules, no bounds; or the path a batch walked already), which usually sets
 * the threshold near its final value; then back up that path. A query outside the root
 * starts with the root on the stack.
 */
static QK__ALWAYS_INLINE void search(const qk_tree_t *t, double qx, double qy, best_t *b, int kind,
                                     const qk__path_t *given) {
  if (given) { /* a path is walked only for a query inside the root */
    climb(t, qx, qy, b, kind, given);
    return;
  }
  if (!qk__tree_contains(t, qx, qy)) {
    const double e = qk__margin(t);
    const qk_square_t r = qk__tree_root_square(t);
    qk__cell_entry_t stack[QK__STACK_MAX];
    int sp = 0;
    stack[sp++] = (qk__cell_entry_t){
        qk__root_cell(t), qk__square_d2_scaled(r.x, r.y, r.side, qx, qy, e, QK__SC(kind, b))};
    drain(t, qx, qy, e, b, stack, &sp, kind);
    return;
  }
  qk__path_t p;
  qk__path_init(t, &p);
  qk__path_descend(t, &p, qx, qy, 0);
  climb(t, qx, qy, b, kind, &p);
}

/* k = 1: the best pair in registers. Returns 0 or 1. */
static size_t knn1(const qk_tree_t *t, double qx, double qy, double max_dist, qk_neighbor_t *out,
                   const qk__path_t *path) {
  best_t b = {.out = out, .k = 1, .slot = QK_NONE, .sc = 1.0};
  best_limits(&b, max_dist, -1);
  search(t, qx, qy, &b, KIND_ONE, path);
  if (b.slot == QK_NONE) return 0;
  out[0] = (qk_neighbor_t){qk__tree_ids(t)[b.slot], report_dist(t, qx, qy, b.thr, b.slot)};
  return 1;
}

#ifdef QK_KNN_STATS
size_t qk__knn_guess_runs, qk__knn_guess_misses;
#endif

/*
 * A first limit for a search of k > 1 (squared): the radius of the disc that holds about
 * k + 2 sqrt(k) + 4 points at the density of the smallest cell on the query's path that
 * holds at least 4k (its count over its area), or infinity when no cell does. A search
 * within it that finds k points has found the k nearest: every point beyond it ranks after
 * the k it found. Without it, until the best-so-far set is full, a search prunes nothing
 * and every point it meets enters the set, most to be pushed out again by nearer ones;
 * with it a point enters only when it lies within the disc. For uniform points the count
 * in the disc is about Poisson: at 1M uniform points the disc holds fewer than k in 0.1%
 * of the searches for k = 8 and 0.6% for k = 32, and those run again with the caller's
 * limit (the cost of a poor guess, as for clustered points, is one cheap extra search).
 * The size was chosen with callgrind at 1M uniform points (k = 8 and 32, instructions and
 * simulated mispredictions per query, the extra searches included): 2k + 8 points gave
 * 2479 and 7208 instructions, k + 2 sqrt(k) + 4 gave 2396 and 6558, k + 1.5 sqrt(k) + 4
 * 2374 and 6466 with twice the extra searches (1.4% for k = 32), which clustered points
 * would make dearer.
 */
static double guess_limit(const qk_tree_t *t, const qk__path_t *p, size_t k, double sc) {
  const size_t want = 4 * k;
  qk__cell_t c = p->leaf;
  size_t cnt = qk__node_count(t, c.node);
  for (unsigned i = p->len; cnt < want && i > 0;) {
    c = p->cell[--i];
    cnt = qk__node_count(t, c.node);
  }
  if (cnt < want) return INFINITY;
  const double side = qk__tree_side(t, c.depth) * sc;
  return ((double)k + 2.0 * sqrt((double)k) + 4.0) * side * side / (3.14159 * (double)cnt);
}

/* Any k > 1 within max_dist, or within the guessed squared limit guess2 (>= 0): how many
 * of out hold neighbours, sorted, with their distances; the ids of a sorted search's slots
 * are read at the end. A guessed search returns 0 unless it found k and every point it
 * did not look at lies beyond the filter's margin of the k-th (so after it, exactly). */
static size_t knn_limited(const qk_tree_t *t, double qx, double qy, size_t k, double max_dist,
                          double guess2, qk_neighbor_t *out, const qk__path_t *path, double sc) {
  best_t b = {.out = out, .k = k, .slot = QK_NONE, .sc = sc};
  best_limits(&b, max_dist, guess2);
  if (sc != 1.0) { /* knn_scale */
    search(t, qx, qy, &b, KIND_SCALED, path);
    if (guess2 >= 0 && (b.n < k || kx_hi(b.thr) > guess2)) return 0;
    xheap_finish(t, qx, qy, out, b.n, 1);
  } else if (k <= QK__KNN_SORTED) {
    /* The sorted array lives here, after a sentinel that ends every insertion's shift
     * without a bound check. */
    qk_neighbor_t sorted[QK__KNN_SORTED + 1], fill[QK__KNN_SORTED];
    _Alignas(16) double keys[QK__KNN_SORTED];
    sorted[0] = (qk_neighbor_t){QK_NONE, -INFINITY};
    b.out = sorted + 1;
    b.fill = fill;
    b.keys = keys;
    search(t, qx, qy, &b, KIND_SORTED, path);
    if (guess2 >= 0 && (b.n < k || kx_hi(b.thr) > guess2)) return 0;
    if (b.n < k && b.n > 0) /* fewer than k within the limit */
      fill_sort(t, qx, qy, b.fill, b.keys, b.n, b.out);
    /* The entries hold slots: their ids now, whose reads do not wait for one another. */
    const qk_id_t *pid = qk__tree_ids(t);
    size_t i = 0;
#if defined(__SSE2__)
    /* Two square roots per sqrtpd (correctly rounded, as sqrt(); no errno test on these
     * nonnegative values). */
    for (; i + 2 <= b.n; i += 2) {
      const __m128d d =
          _mm_sqrt_pd(_mm_loadh_pd(_mm_load_sd(&sorted[i + 1].dist), &sorted[i + 2].dist));
      out[i].id = pid[sorted[i + 1].id];
      out[i + 1].id = pid[sorted[i + 2].id];
      _mm_storel_pd(&out[i].dist, d);
      _mm_storeh_pd(&out[i + 1].dist, d);
    }
#endif
    for (; i < b.n; i++) out[i] = (qk_neighbor_t){pid[sorted[i + 1].id], sqrt(sorted[i + 1].dist)};
    /* Squares from 2^1000 on: hypot of the differences (report_dist). The last entry's
     * square is within the filter's margin of the largest (the exact order), so at least
     * half of 2^1000 when any is that large. */
    if (b.n > 0 && sorted[b.n].dist >= 0.5 * QK__FILTER_MAX)
      for (i = 0; i < b.n; i++)
        out[i].dist = report_dist(t, qx, qy, sorted[i + 1].dist, sorted[i + 1].id);
  } else {
    search(t, qx, qy, &b, KIND_HEAP, path);
    if (guess2 >= 0 && (b.n < k || kx_hi(b.thr) > guess2)) return 0;
    xheap_finish(t, qx, qy, out, b.n, 0);
  }
  return b.n;
}

/* Any k > 1: returns how many of out hold neighbours (distances), sorted. A query inside
 * the root is searched first within the guessed limit (guess_limit), from its path. */
static size_t knn_search(const qk_tree_t *t, double qx, double qy, size_t k, double max_dist,
                         qk_neighbor_t *out, const qk__path_t *path, double sc) {
  if (!qk__tree_contains(t, qx, qy)) return knn_limited(t, qx, qy, k, max_dist, -1, out, NULL, sc);
  qk__path_t own;
  if (!path) {
    qk__path_init(t, &own);
    qk__path_descend(t, &own, qx, qy, 0);
    path = &own;
  }
  /* Guessed only where every square within it is surely within max_dist. */
  const double guess2 = guess_limit(t, path, k, sc);
  best_t c;
  c.sc = sc;
  best_limits(&c, max_dist, -1);
  if (guess2 < c.cap_lo) {
#ifdef QK_KNN_STATS
    qk__knn_guess_runs++;
#endif
    if (knn_limited(t, qx, qy, k, max_dist, guess2, out, path, sc) == k) return k;
#ifdef QK_KNN_STATS
    qk__knn_guess_misses++;
#endif
  }
  return knn_limited(t, qx, qy, k, max_dist, -1, out, path, sc);
}

/*
 * The scale of a query's differences: 1, unless the tree's root and the query's gap to
 * it are both below 2^-400; then 2^-e for the exponent e of the larger (qk__scale_of).
 * There every square underflowed under the filter's absolute margin (2^-1060): every
 * distance read 0 (or nearly), no square was pruned, and every pair of points was
 * ranked by the exact comparison, n big-integer tests per query (35-80 ms at 10^5
 * points at scale 1e-160 to 1e-310 where 0.7 us at 1; fifty-sixth session). Scaled,
 * every difference is below 4 (with its gap to the root) and at least 2^-51 when not
 * 0, so nothing overflows and the filter decides as at scale 1; the scaled search keeps
 * its set in the heap (KIND_SCALED), and reports the unscaled distances.
 * (Large coordinates need nothing: kNN keeps them within 2^510, qk__knn_check.)
 */
static inline double knn_scale(const qk_tree_t *t, qk_point_t q) {
  const qk_square_t r = qk__tree_root_square(t);
  if (r.side >= 0x1p-400) return 1.0;
  const double m = qk__max_d(
      r.side, qk__max_d(qk__gap(q.x, r.x, r.x + r.side), qk__gap(q.y, r.y, r.y + r.side)));
  return m >= 0x1p-400 || !(m > 0) ? 1.0 : qk__scale_of(m);
}

/*
 * Walk the paths from the root to the leaves holding up to QK__LANES queries in lockstep,
 * one level at a time, prefetching each next node: the lanes' cache misses then overlap
 * instead of following one another. The paths are kept, so the searches that follow
 * start from them instead of descending again. A query outside the root (or not finite)
 * gets no path (`valid` 0).
 */
void qk__walk_lanes(const qk_tree_t *t, const qk_point_t *qs, const uint32_t *order, size_t j0,
                    size_t j1, qk__path_t *paths) {
  unsigned idx[QK__LANES];
  unsigned lanes = 0;
  for (size_t j = j0; j < j1 && j < j0 + QK__LANES; j++) {
    qk_point_t q = qs[order ? order[j] : j];
    qk__path_t *p = &paths[j - j0];
    p->valid = isfinite(q.x) && isfinite(q.y) && qk__tree_contains(t, q.x, q.y);
    if (!p->valid) continue;
    qk__path_init(t, p);
    idx[lanes++] = (unsigned)(j - j0);
  }
  const double *xs = qk__tree_xs(t), *ys = qk__tree_ys(t);
  while (lanes > 0) {
    for (unsigned l = 0; l < lanes;) {
      qk__path_t *p = &paths[idx[l]];
      qk_point_t q = qs[order ? order[j0 + idx[l]] : j0 + idx[l]];
      if (!qk__path_step(t, p, q.x, q.y)) {
        uint32_t s = qk__node_start(t, p->leaf.node);
        QK__PREFETCH(xs + s);
        QK__PREFETCH(ys + s);
        idx[l] = idx[--lanes]; /* this lane is done: move the last one here */
        continue;
      }
      qk__node_prefetch(t, p->leaf.node);
      l++;
    }
  }
}

/* One query into out (k entries); returns the count. */
size_t qk__knn_one(const qk_tree_t *t, qk_point_t q, size_t k, double max_dist, qk_neighbor_t *out,
                   const qk__path_t *path) {
  const size_t np = qk__tree_count(t);
  if (np == 0 || k == 0) return 0;
  if (k > np) k = np;
  const double sc = knn_scale(t, q);
  if (k > 1 || sc != 1.0) return knn_search(t, q.x, q.y, k, max_dist, out, path, sc);
  return knn1(t, q.x, q.y, max_dist, out, path);
}

qk_status_t qk_query_knn(const qk_tree_t *tree, qk_point_t q, size_t k, double max_dist,
                         qk_neighbor_t *out, size_t *n_out) {
  if (!tree || !n_out || (k > 0 && !out)) return QK_ERR_INVALID;
  *n_out = 0;
  qk_status_t st = qk__knn_check(tree, q, max_dist);
  if (st != QK_OK) return st;
  if (k == 1 && qk__tree_count(tree) > 0 && knn_scale(tree, q) == 1.0) {
    /* The common case straight to its search. */
    *n_out = knn1(tree, q.x, q.y, max_dist, out, NULL);
    return QK_OK;
  }
  *n_out = qk__knn_one(tree, q, k, max_dist, out, NULL);
  return QK_OK;
}
