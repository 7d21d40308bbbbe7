/*
 * Bulk build by bucketing: one pass computes, for every point, the cell of the uniform
 * 2^L x 2^L grid over the root square that the tree's own tie rules send it to; a counting
 * sort by that cell number lays the points out in the tree's pre-order (children NE, NW,
 * SW, SE); the top L levels of the tree are then read off the bucket counts without
 * touching a point, and only buckets still over capacity are split further, by the plain
 * comparison-based partition (qk__split), in cache.
 *
 * The result is the same tree as the plain recursive build: the cell number of a point is
 * computed by scaling its coordinates, which can differ from the tree's comparisons only
 * for a point within rounding distance of a grid line; such points (rare) take the exact
 * route, the same comparisons the tree makes. When the root's coordinates are so badly
 * conditioned that no safe margin exists, the caller falls back to the plain build.
 */
#include <float.h>
#include <math.h>
#include <string.h>

#include "index/index_access.h"

/* Cell digit of one level from the east and north bits: NE=0, NW=1, SW=2, SE=3. */
static inline uint32_t digit(unsigned east, unsigned north) {
  return ((north ^ 1u) << 1) | (east ^ north);
}

/* The exact cell number of (x, y): the tree's own comparisons for L levels. */
static uint32_t exact_cell(const qk_tree_t *t, double x, double y, unsigned L) {
  double cx = t->root_x, cy = t->root_y;
  uint32_t key = 0;
  for (unsigned d = 0; d < L; d++) {
    double half = t->side[d + 1];
    unsigned e = x > cx + half, n = y > cy + half;
    if (e) cx += half;
    if (n) cy += half;
    key = (key << 2) | digit(e, n);
  }
  return key;
}

/* qk__spread16 of every byte, as a table: the cell pass computes two spreads per point,
 * and two loads from a 512-byte table cost a tenth of the shifts and masks. */
#define SPREAD2(n) n, n + 1, n + 4, n + 5
#define SPREAD4(n) SPREAD2(n), SPREAD2(n + 16), SPREAD2(n + 64), SPREAD2(n + 80)
#define SPREAD6(n) SPREAD4(n), SPREAD4(n + 256), SPREAD4(n + 1024), SPREAD4(n + 1280)
static const uint16_t spread8[256] = {SPREAD6(0), SPREAD6(4096), SPREAD6(16384), SPREAD6(20480)};

/* The cell of a point at (qx, qy) in grid units, by truncation, when the point is at least
 * `delta` away from every grid line (so truncation agrees with the tree's comparisons);
 * false otherwise. Truncation is floor here: negative values fail the range test. */
static inline bool scaled_cell(double qx, double qy, double cells, double delta, uint32_t *k) {
  if (!(qx >= delta && qy >= delta && qx < cells - delta && qy < cells - delta)) return false;
  uint32_t ix = (uint32_t)qx, iy = (uint32_t)qy;
  double fx = qx - ix, fy = qy - iy;
  if (!(fx >= delta && fx <= 1 - delta && fy >= delta && fy <= 1 - delta)) return false;
  uint32_t top = (uint32_t)cells - 1;
  *k = (uint32_t)(spread8[~iy & top] << 1) | spread8[ix ^ iy]; /* L <= 8 */
  return true;
}

/* A node of the top levels still over capacity, whose subtree is built on its own: the
 * node, its geometry and its first bucket. */
typedef struct subtree {
  uint32_t v;
  qk__geom_t g;
  uint32_t lo;
} subtree_t;

/* The subtrees hang at this depth (at most 4^3 of them), when the grid is deeper. */
#define TOP_DEPTH 3u

/* Make node v over slots [a, b) a leaf or split it along the bucket counts. `cum` holds
 * the prefix sums of the 4^L buckets; v covers buckets [lo, lo + 4^(L - depth)). With a
 * list, a node of depth `top` that must split is appended to it instead, in pre-order. */
static qk_status_t from_buckets(qk_tree_t *t, uint32_t v, qk__geom_t g, const uint32_t *cum,
                                uint32_t lo, unsigned L, unsigned top, subtree_t *list,
                                size_t *n_list) {
  unsigned depth = g.depth;
  if (t->nodes[v].count <= t->capacity || !qk__can_split(t, g)) return QK_OK;
  if (list && depth == top) {
    list[(*n_list)++] = (subtree_t){v, g, lo};
    return QK_OK;
  }
  if (depth == L) return qk__build_subtree(t, v, g);
  qk_status_t st = qk__reserve_nodes(t, 4);
  if (st) return st;
  /* Splitting moves no point: the children's slot ranges are already in order. */
  uint32_t b = qk__split_sorted(t, v, depth);
  t->nodes[v].start = 0;
  t->nodes[v].room = 0;
  uint32_t span = 1u << (2 * (L - depth - 1));
  for (uint32_t q = 0; q < 4; q++) {
    uint32_t first = lo + q * span;
    qk__node_t *c = &t->nodes[b + q];
    c->start = cum[first];
    c->count = cum[first + span] - cum[first];
    c->room = c->count;
  }
  for (uint32_t q = 0; q < 4; q++)
    if ((st = from_buckets(t, b + q, qk__child_geom(t, g, q), cum, lo + q * span, L, top, list,
                           n_list)))
      return st;
  return QK_OK;
}

/* The subtrees built on threads: each into a tree of its own that shares the point arrays
 * (the subtrees' slot ranges are disjoint) and has its own node arrays, its root as node
 * 0; then appended to the tree in list order, which numbers every node as building them
 * one after another in the tree would. */
typedef struct sub_job {
  const qk_tree_t *t;
  const uint32_t *cum;
  unsigned L;
  const subtree_t *list;
  qk_tree_t *own; /* one tree per subtree */
  qk_status_t *st;
} sub_job_t;

/* Set up the tree of its own for subtree i, with room for about as many nodes as it will
 * need (four per `capacity` points: more than a uniform or clustered set makes), so that
 * its arrays come from the calling thread and rarely grow on a worker. A worker's
 * allocations would come from a per-thread arena of the C library, returned to the
 * system when freed and faulted in again at the next build. */
static qk_status_t sub_init(const qk_tree_t *t, const subtree_t *s, qk_tree_t *o) {
  memset(o, 0, sizeof *o);
  o->alloc = t->alloc; /* the default allocator: thread-safe */
  o->capacity = t->capacity;
  o->max_depth = t->max_depth;
  o->root_x = t->root_x;
  o->root_y = t->root_y;
  memcpy(o->side, t->side, sizeof o->side);
  o->px = t->px;
  o->py = t->py;
  o->pid = t->pid;
  atomic_init(&o->where, NULL);
  o->free_block = QK_NONE;
  uint64_t count = t->nodes[s->v].count, est = 4 * (count / t->capacity) + 64;
  qk_status_t st = qk__reserve_nodes(o, est < UINT32_MAX / 2 ? (uint32_t)est : UINT32_MAX / 2);
  if (st) return st;
  o->n_nodes = 1;
  o->nodes[0] = t->nodes[s->v];
  return QK_OK;
}

static void sub_build(unsigned i, void *ud) {
  const sub_job_t *j = ud;
  j->st[i] = from_buckets(&j->own[i], 0, j->list[i].g, j->cum, j->list[i].lo, j->L, 0, NULL, NULL);
}

/* Append subtree tree o, whose root stands for node v, to t (nodes reserved). */
static void sub_append(qk_tree_t *t, const qk_tree_t *o, uint32_t v) {
  uint32_t base = t->n_nodes, extra = o->n_nodes - 1; /* node u >= 1 of o is base + u - 1 */
  for (uint32_t u = 1; u < o->n_nodes; u++) {
    qk__node_t n = o->nodes[u];
    if (n.child != QK_NONE) n.child += base - 1;
    t->nodes[base + u - 1] = n;
  }
  for (uint32_t k = 0; k < extra / 4; k++) {
    qk__block_t b = o->blocks[k];
    b.parent = b.parent == 0 ? v : b.parent + base - 1;
    t->blocks[(base - 1) / 4 + k] = b;
  }
  qk__node_t r = o->nodes[0];
  if (r.child != QK_NONE) r.child += base - 1;
  t->nodes[v] = r;
  t->n_nodes += extra;
}

static void sub_free(const qk_tree_t *t, qk_tree_t *o) {
  qk__free(&t->alloc, o->nodes, (size_t)o->cap_nodes * sizeof(qk__node_t));
  qk__free(&t->alloc, o->blocks, (size_t)o->cap_blocks * sizeof(qk__block_t));
}

/* The tree below the grid's top levels: the top levels from the bucket counts, then
 * every subtree hanging below them, on nw threads when there are several of them and the
 * allocator is the default one (a caller's allocator is only ever called from one thread
 * at a time). */
static qk_status_t from_grid(qk_tree_t *t, qk__geom_t g, const uint32_t *cum, unsigned L,
                             unsigned nw) {
  subtree_t list[1u << (2 * TOP_DEPTH)];
  size_t n = 0;
  unsigned top = L > TOP_DEPTH ? TOP_DEPTH : L;
  qk_status_t st = from_buckets(t, 0, g, cum, 0, L, top, list, &n);
  if (st) return st;
  if (nw <= 1 || n < 2 || t->alloc.fn) {
    for (size_t i = 0; i < n && st == QK_OK; i++)
      st = from_buckets(t, list[i].v, list[i].g, cum, list[i].lo, L, 0, NULL, NULL);
    return st;
  }
  qk_tree_t *own = qk__realloc(&t->alloc, NULL, 0, n * sizeof *own);
  qk_status_t *sts = qk__realloc(&t->alloc, NULL, 0, n * sizeof *sts);
  if (!own || !sts) {
    qk__free(&t->alloc, own, n * sizeof *own);
    qk__free(&t->alloc, sts, n * sizeof *sts);
    return QK_ERR_NOMEM;
  }
  memset(own, 0, n * sizeof *own);
  for (size_t i = 0; i < n && st == QK_OK; i++) st = sub_init(t, &list[i], &own[i]);
  sub_job_t j = {t, cum, L, list, own, sts};
  if (st == QK_OK) qk__run_jobs(nw, (unsigned)n, sub_build, &j);
  size_t extra = 0;
  for (size_t i = 0; i < n; i++) {
    if (st == QK_OK && sts[i]) st = sts[i];
    extra += own[i].n_nodes ? own[i].n_nodes - 1 : 0;
  }
  if (st == QK_OK && extra > UINT32_MAX) st = QK_ERR_LIMIT;
  if (st == QK_OK) st = qk__reserve_nodes(t, (uint32_t)extra);
  for (size_t i = 0; i < n; i++) {
    if (st == QK_OK) sub_append(t, &own[i], list[i].v);
    sub_free(t, &own[i]);
  }
  qk__free(&t->alloc, own, n * sizeof *own);
  qk__free(&t->alloc, sts, n * sizeof *sts);
  return st;
}

/* What the parallel phases of the bucketed build share. Share w of nw covers the points
 * [lo, hi) of qk__share_range(n, w, nw) in the first two phases and the slots of the same
 * range in the gather. */
typedef struct bucket_job {
  qk_tree_t *t;
  const qk_point_t *p;
  size_t n, nb;
  double x0, y0, scale, cells, delta;
  unsigned L;
  uint16_t *key;
  uint32_t *order;
  uint32_t *hist; /* nw rows of nb: counts, then each share's next slot per bucket */
} bucket_job_t;

/* Phase 1: every point's cell, and this share's count per cell. The job's fields are
 * copied to locals: the stores to key[] and h[] could otherwise alias them. */
static void cells_share(void *ctx, unsigned w, unsigned nw) {
  const bucket_job_t *j = ctx;
  size_t lo, hi;
  qk__share_range(j->n, w, nw, &lo, &hi);
  uint32_t *h = j->hist + (size_t)w * j->nb;
  const qk_point_t *p = j->p;
  uint16_t *key = j->key;
  const double x0 = j->x0, y0 = j->y0, scale = j->scale, cells = j->cells, delta = j->delta;
  for (size_t i = lo; i < hi; i++) {
    uint32_t k;
    if (!scaled_cell((p[i].x - x0) * scale, (p[i].y - y0) * scale, cells, delta, &k))
      k = exact_cell(j->t, p[i].x, p[i].y, j->L); /* near a grid line: the tree's tests */
    key[i] = (uint16_t)k;
    h[k]++;
  }
}

/* Phase 2: the counting sort's placement, stable (shares are in point order). */
static void place_share(void *ctx, unsigned w, unsigned nw) {
  bucket_job_t *j = ctx;
  size_t lo, hi;
  qk__share_range(j->n, w, nw, &lo, &hi);
  uint32_t *next = j->hist + (size_t)w * j->nb;
  for (size_t i = lo; i < hi; i++) j->order[next[j->key[i]]++] = (uint32_t)i;
}

/* Phase 3: the gather of the points in that order: random reads of one cache line per
 * point rather than random writes to three arrays. */
static void gather_share(void *ctx, unsigned w, unsigned nw) {
  bucket_job_t *j = ctx;
  size_t lo, hi;
  qk__share_range(j->n, w, nw, &lo, &hi);
  qk_tree_t *t = j->t;
  const qk_point_t *p = j->p;
  for (size_t s = lo; s < hi; s++) {
    uint32_t i = j->order[s];
#if defined(__GNUC__)
    /* The reads are random: ask for the point a few iterations ahead. */
    if (s + 16 < hi) __builtin_prefetch(&p[j->order[s + 16]]);
#endif
    t->px[s] = p[i].x;
    t->py[s] = p[i].y;
    t->pid[s] = i;
  }
}

qk_status_t qk__build_bucketed(qk_tree_t *t, const qk_point_t *p, size_t n, bool *done) {
  *done = false;
  unsigned L = 0;
  while (L < 8 && L < t->max_depth && ((size_t)1 << (2 * (L + 1))) <= n / 4) L++;
  if (L < 2) return QK_OK;
  /* Margin in grid units: rounding of the corner arithmetic (at most one rounding per
   * level) and of the scaling, with a factor of four to spare. */
  double x0 = t->root_x, y0 = t->root_y, side = t->side[0];
  double M = fmax(fmax(fabs(x0), fabs(x0 + side)), fmax(fabs(y0), fabs(y0 + side)));
  double cells = (double)(1u << L), scale = cells / side;
  double ulpM = nextafter(M, INFINITY) - M;
  double delta = 4 * (((L + 2) * ulpM + 2 * ulpM) * scale + cells * 4 * DBL_EPSILON);
  if (!(delta < 0.25)) return QK_OK; /* badly conditioned: use the plain build */

  size_t nb = (size_t)1 << (2 * L);
  /* Threads: a share of fewer than 2^16 points does not pay for its thread and its
   * histogram (one count per cell). */
  unsigned nw = qk__threads_resolve(t->threads);
  if (nw > n / 65536) nw = n / 65536 > 0 ? (unsigned)(n / 65536) : 1;
  /* Counting sort of the point indices by cell (cells have at most 16 bits, so the counts
   * stay in cache), then a gather of the points in that order. */
  size_t m = n ? n : 1;
  uint32_t *cum = qk__realloc(&t->alloc, NULL, 0, (nb + 1) * sizeof *cum);
  uint16_t *key = qk__realloc(&t->alloc, NULL, 0, m * sizeof *key);
  uint32_t *order = qk__realloc(&t->alloc, NULL, 0, m * sizeof *order);
  uint32_t *hist = qk__realloc(&t->alloc, NULL, 0, nw * nb * sizeof *hist);
  if (!hist && nw > 1) { /* one thread needs one histogram only */
    nw = 1;
    hist = qk__realloc(&t->alloc, NULL, 0, nb * sizeof *hist);
  }
  if (!cum || !key || !order || !hist) {
    qk__free(&t->alloc, cum, (nb + 1) * sizeof *cum);
    qk__free(&t->alloc, key, m * sizeof *key);
    qk__free(&t->alloc, order, m * sizeof *order);
    qk__free(&t->alloc, hist, nw * nb * sizeof *hist);
    return QK_ERR_NOMEM;
  }
  memset(hist, 0, nw * nb * sizeof *hist);
  bucket_job_t j = {t, p, n, nb, x0, y0, scale, cells, delta, L, key, order, hist};
  qk__run_shares(nw, cells_share, &j);
  /* Bucket starts, and each share's first slot in every bucket: the shares before it
   * come first, so the order is the one thread's. */
  uint32_t acc = 0;
  for (size_t k = 0; k < nb; k++) {
    cum[k] = acc;
    for (unsigned w = 0; w < nw; w++) {
      uint32_t c = hist[(size_t)w * nb + k];
      hist[(size_t)w * nb + k] = acc;
      acc += c;
    }
  }
  cum[nb] = acc;
  qk__run_shares(nw, place_share, &j);
  qk__run_shares(nw, gather_share, &j);
  qk__free(&t->alloc, hist, nw * nb * sizeof *hist);
  qk__free(&t->alloc, key, m * sizeof *key);
  qk__free(&t->alloc, order, m * sizeof *order);
  qk_status_t st = from_grid(t, (qk__geom_t){x0, y0, 0}, cum, L, nw);
  qk__free(&t->alloc, cum, (nb + 1) * sizeof *cum);
  *done = st == QK_OK;
  return st;
}
