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

#include "index/index_internal.h"

/* Cell digit of one level from the east and north bits: NE=0, NW=1, SW=2, SE=3. */
static inline uint32_t digit(unsigned east, unsigned north) {
  return ((north ^ 1u) << 1) | (east ^ north);
}

/* The exact cell number of (x, y): the tree's own comparisons for L levels. */
static uint32_t exact_cell(const qk_tree_t *t, double x, double y, unsigned L) {
  double cx = t->nodes[0].x0, cy = t->nodes[0].y0;
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

/* Interleave: bit i of hi goes to bit 2i+1, bit i of lo to bit 2i. */
static inline uint32_t interleave(uint32_t hi, uint32_t lo) {
  uint64_t v = ((uint64_t)hi << 32) | lo;
  uint64_t h = v >> 32, l = v & 0xFFFFFFFFu;
  h = (h | (h << 8)) & 0x00FF00FFull;
  h = (h | (h << 4)) & 0x0F0F0F0Full;
  h = (h | (h << 2)) & 0x33333333ull;
  h = (h | (h << 1)) & 0x55555555ull;
  l = (l | (l << 8)) & 0x00FF00FFull;
  l = (l | (l << 4)) & 0x0F0F0F0Full;
  l = (l | (l << 2)) & 0x33333333ull;
  l = (l | (l << 1)) & 0x55555555ull;
  return (uint32_t)((h << 1) | l);
}

/* Make node v over slots [a, b) a leaf or split it along the bucket counts. `cum` holds
 * the prefix sums of the 4^L buckets; v covers buckets [lo, lo + 4^(L - depth)). */
static qk_status_t from_buckets(qk_tree_t *t, uint32_t v, const uint32_t *cum, uint32_t lo,
                                unsigned L) {
  qk__node_t *n = &t->nodes[v];
  unsigned depth = n->depth;
  if (n->count <= t->capacity || !qk__can_split(t, n)) return QK_OK;
  if (depth == L) return qk__build_subtree(t, v);
  qk_status_t st = qk__reserve_nodes(t, 4);
  if (st) return st;
  /* Splitting moves no point: the children's slot ranges are already in order. */
  uint32_t b = qk__split_sorted(t, v);
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
    if ((st = from_buckets(t, b + q, cum, lo + q * span, L))) return st;
  return QK_OK;
}

qk_status_t qk__build_bucketed(qk_tree_t *t, const qk_point_t *p, size_t n, bool *done) {
  *done = false;
  unsigned L = 0;
  while (L < 8 && L < t->max_depth && ((size_t)1 << (2 * (L + 1))) <= n / 4) L++;
  if (L < 2) return QK_OK;
  /* Margin in grid units: rounding of the corner arithmetic (at most one rounding per
   * level) and of the scaling, with a factor of four to spare. */
  double x0 = t->nodes[0].x0, y0 = t->nodes[0].y0, side = t->side[0];
  double M = fmax(fmax(fabs(x0), fabs(x0 + side)), fmax(fabs(y0), fabs(y0 + side)));
  double cells = (double)(1u << L), scale = cells / side;
  double ulpM = nextafter(M, INFINITY) - M;
  double delta = 4 * (((L + 2) * ulpM + 2 * ulpM) * scale + cells * 4 * DBL_EPSILON);
  if (!(delta < 0.25)) return QK_OK; /* badly conditioned: use the plain build */

  size_t nb = (size_t)1 << (2 * L);
  /* Sort (cell, index) pairs by cell with a two-pass LSD radix sort on bytes (cells have
   * at most 16 bits), then gather the points in that order: random reads of one cache line
   * per point instead of random writes to three arrays. */
  size_t pairs = n ? n : 1;
  uint32_t *cum = qk__realloc(&t->alloc, NULL, 0, (nb + 1) * sizeof *cum);
  uint64_t *a = qk__realloc(&t->alloc, NULL, 0, pairs * sizeof *a);
  uint64_t *b = qk__realloc(&t->alloc, NULL, 0, pairs * sizeof *b);
  if (!cum || !a || !b) {
    qk__free(&t->alloc, cum, (nb + 1) * sizeof *cum);
    qk__free(&t->alloc, a, pairs * sizeof *a);
    qk__free(&t->alloc, b, pairs * sizeof *b);
    return QK_ERR_NOMEM;
  }
  memset(cum, 0, (nb + 1) * sizeof *cum);
  uint32_t lo_count[257] = {0}, hi_count[257] = {0};
  uint32_t top = (uint32_t)cells - 1;
  for (size_t i = 0; i < n; i++) {
    double qx = (p[i].x - x0) * scale, qy = (p[i].y - y0) * scale;
    double fx = floor(qx), fy = floor(qy);
    uint32_t k;
    if (qx - fx < delta || fx + 1 - qx < delta || qy - fy < delta || fy + 1 - qy < delta ||
        fx > top || fy > top) {
      k = exact_cell(t, p[i].x, p[i].y, L); /* near a grid line: the tree's comparisons */
    } else {
      uint32_t ix = (uint32_t)fx, iy = (uint32_t)fy;
      k = interleave(~iy & top, ix ^ iy);
    }
    a[i] = ((uint64_t)k << 32) | i;
    cum[k + 1]++;
    lo_count[(k & 0xFF) + 1]++;
    hi_count[(k >> 8) + 1]++;
  }
  for (int d = 0; d < 256; d++) lo_count[d + 1] += lo_count[d], hi_count[d + 1] += hi_count[d];
  for (size_t i = 0; i < n; i++) b[lo_count[(a[i] >> 32) & 0xFF]++] = a[i];
  for (size_t i = 0; i < n; i++) a[hi_count[(b[i] >> 40) & 0xFF]++] = b[i];
  for (size_t s = 0; s < n; s++) {
    uint32_t i = (uint32_t)a[s];
#if defined(__GNUC__)
    /* The reads are random: ask for the point a few iterations ahead. */
    if (s + 16 < n) __builtin_prefetch(&p[(uint32_t)a[s + 16]]);
#endif
    t->px[s] = p[i].x;
    t->py[s] = p[i].y;
    t->pid[s] = i;
    t->where[i] = (uint32_t)s;
  }
  for (size_t k = 0; k < nb; k++) cum[k + 1] += cum[k];
  qk__free(&t->alloc, a, pairs * sizeof *a);
  qk__free(&t->alloc, b, pairs * sizeof *b);
  qk_status_t st = from_buckets(t, 0, cum, 0, L);
  qk__free(&t->alloc, cum, (nb + 1) * sizeof *cum);
  *done = st == QK_OK;
  return st;
}
