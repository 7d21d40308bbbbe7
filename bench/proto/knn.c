/*
 * Prototype, not library code: 1-NN search variants on the library's own tree layout
 * (index/index_internal.h, read only), to measure what each technique buys before it is
 * proposed for query/. Run as `quadkit-proto [n] [queries]`; prints the rate of
 * qk_query_knn() and of each variant on the same tree and queries, and checks that every
 * variant returns the same distances.
 *
 *   library    qk_query_knn(k = 1), the committed search;
 *   locate     descend straight to the leaf holding q (no stack, no bounds), scan it,
 *              then run the pruned depth-first search with that distance as the bound;
 *   batch8     `locate` for 8 queries in lockstep: the 8 descents advance one level at
 *              a time with the next node prefetched, so their cache misses overlap;
 *              the pruned search then runs per query.
 */
#define _POSIX_C_SOURCE 199309L
#include <math.h>
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <time.h>

#include "index/index_internal.h"
#include "quadkit/query.h"

static double now(void) {
  struct timespec t;
  clock_gettime(CLOCK_MONOTONIC, &t);
  return (double)t.tv_sec + 1e-9 * (double)t.tv_nsec;
}

static uint64_t rng_state = 88172645463325252ull;
static double urand(void) {
  rng_state ^= rng_state << 13;
  rng_state ^= rng_state >> 7;
  rng_state ^= rng_state << 17;
  return (double)(rng_state >> 11) * 0x1p-53;
}

/* Squared distance from q to a node's square (no margin: the prototype's points are
 * uniform doubles in [0, 1), where the dyadic root makes every square exact). */
/* Since issue 11 nodes store no square: this prototype, written for the 40-byte nodes,
 * recomputes each from the path (O(depth)), so its rates no longer mean what they did;
 * it still checks that the techniques give the library's answers. */
static inline qk__geom_t geom_of(const qk_tree_t *t, const qk__node_t *n) {
  return qk__node_geom(t, (uint32_t)(n - t->nodes));
}

static inline double cell_d2(const qk_tree_t *t, const qk__node_t *n, double qx, double qy) {
  qk__geom_t g = geom_of(t, n);
  double s = t->side[g.depth];
  double dx = qx < g.x0 ? g.x0 - qx : (qx > g.x0 + s ? qx - g.x0 - s : 0.0);
  double dy = qy < g.y0 ? g.y0 - qy : (qy > g.y0 + s ? qy - g.y0 - s : 0.0);
  return dx * dx + dy * dy;
}

static inline uint32_t child_toward(const qk_tree_t *t, const qk__node_t *n, double qx, double qy) {
  qk__geom_t g = geom_of(t, n);
  double half = t->side[g.depth + 1];
  return n->child + qk__quadrant_of(g.x0, g.y0, half, qx, qy);
}

static inline void scan_leaf(const qk_tree_t *t, const qk__node_t *n, double qx, double qy,
                             double *best, uint32_t *bid) {
  const double *px = t->px + n->start, *py = t->py + n->start;
  for (uint32_t i = 0; i < n->count; i++) {
    double dx = px[i] - qx, dy = py[i] - qy, d2 = dx * dx + dy * dy;
    if (d2 < *best || (d2 == *best && t->pid[n->start + i] < *bid)) {
      *best = d2;
      *bid = t->pid[n->start + i];
    }
  }
}

/* The leaf scan with GCC/Clang vector extensions, four doubles at a time: a pass that
 * only computes the smallest squared distance (no branches, no ids), then an exact
 * scalar pass with the id tie rule only when that minimum can change the answer. */
typedef double v4d __attribute__((vector_size(32)));
typedef long long v4l __attribute__((vector_size(32)));
static inline void scan_leaf_vec(const qk_tree_t *t, const qk__node_t *n, double qx, double qy,
                                 double *best, uint32_t *bid) {
  const double *px = t->px + n->start, *py = t->py + n->start;
  uint32_t cnt = n->count, i = 0;
  double m = INFINITY;
  if (cnt >= 4) {
    v4d vm = {INFINITY, INFINITY, INFINITY, INFINITY};
    v4d vqx = {qx, qx, qx, qx}, vqy = {qy, qy, qy, qy};
    for (; i + 4 <= cnt; i += 4) {
      v4d x, y;
      memcpy(&x, px + i, sizeof x);
      memcpy(&y, py + i, sizeof y);
      v4d dx = x - vqx, dy = y - vqy, d2 = dx * dx + dy * dy;
      v4l lt = d2 < vm; /* all ones where d2 is smaller */
      vm = (v4d)(((v4l)d2 & lt) | ((v4l)vm & ~lt));
    }
    for (int j = 0; j < 4; j++) m = vm[j] < m ? vm[j] : m;
  }
  for (; i < cnt; i++) {
    double dx = px[i] - qx, dy = py[i] - qy, d2 = dx * dx + dy * dy;
    m = d2 < m ? d2 : m;
  }
  if (m > *best) return;
  scan_leaf(t, n, qx, qy, best, bid);
}

/* The pruned depth-first search, nearest child first, from the root, with an initial
 * bound; skips the leaf already scanned. */
static int use_vec = 0;
static void dfs(const qk_tree_t *t, double qx, double qy, uint32_t skip, double *best,
                uint32_t *bid) {
  uint32_t stack[256];
  int sp = 0;
  stack[sp++] = 0;
  while (sp) {
    const qk__node_t *n = &t->nodes[stack[--sp]];
    if (cell_d2(t, n, qx, qy) > *best) continue;
    if (n->child == QK_NONE) {
      if ((uint32_t)(n - t->nodes) != skip) {
        if (use_vec)
          scan_leaf_vec(t, n, qx, qy, best, bid);
        else
          scan_leaf(t, n, qx, qy, best, bid);
      }
      continue;
    }
    double b[4];
    uint32_t c[4];
    int m = 0;
    for (uint32_t q = 0; q < 4; q++) {
      const qk__node_t *ch = &t->nodes[n->child + q];
      if (!ch->count) continue;
      double d = cell_d2(t, ch, qx, qy);
      if (d > *best) continue;
      int j = m++;
      while (j > 0 && b[j - 1] < d) {
        b[j] = b[j - 1];
        c[j] = c[j - 1];
        j--;
      }
      b[j] = d;
      c[j] = n->child + q;
    }
    for (int j = 0; j < m; j++) stack[sp++] = c[j];
  }
}

static uint32_t locate(const qk_tree_t *t, double qx, double qy) {
  uint32_t v = 0;
  while (t->nodes[v].child != QK_NONE) v = child_toward(t, &t->nodes[v], qx, qy);
  return v;
}

static double nn_locate(const qk_tree_t *t, double qx, double qy, uint32_t *id) {
  double best = INFINITY;
  uint32_t leaf = locate(t, qx, qy);
  scan_leaf(t, &t->nodes[leaf], qx, qy, &best, id);
  dfs(t, qx, qy, leaf, &best, id);
  return best;
}

static void nn_batch8(const qk_tree_t *t, const double *q, size_t nq, double *out) {
  for (size_t b = 0; b < nq; b += 8) {
    size_t m = nq - b < 8 ? nq - b : 8;
    uint32_t v[8] = {0};
    int live = 1;
    while (live) {
      live = 0;
      for (size_t i = 0; i < m; i++) {
        const qk__node_t *n = &t->nodes[v[i]];
        if (n->child == QK_NONE) continue;
        v[i] = child_toward(t, n, q[2 * (b + i)], q[2 * (b + i) + 1]);
        __builtin_prefetch(&t->nodes[v[i]]);
        live = 1;
      }
    }
    for (size_t i = 0; i < m; i++) {
      const qk__node_t *n = &t->nodes[v[i]];
      __builtin_prefetch(t->px + n->start);
      __builtin_prefetch(t->py + n->start);
    }
    for (size_t i = 0; i < m; i++) {
      double qx = q[2 * (b + i)], qy = q[2 * (b + i) + 1], best = INFINITY;
      uint32_t id = QK_NONE;
      scan_leaf(t, &t->nodes[v[i]], qx, qy, &best, &id);
      dfs(t, qx, qy, v[i], &best, &id);
      out[b + i] = best;
    }
  }
}

int main(int argc, char **argv) {
  size_t n = argc > 1 ? (size_t)atof(argv[1]) : 1000000;
  size_t nq = argc > 2 ? (size_t)atof(argv[2]) : 200000;
  qk_point_t *p = malloc(n * sizeof *p);
  for (size_t i = 0; i < n; i++) p[i] = (qk_point_t){urand(), urand()};
  double *q = malloc(2 * nq * sizeof *q), *ref = malloc(nq * sizeof *ref),
         *got = malloc(nq * sizeof *got);
  for (size_t i = 0; i < 2 * nq; i++) q[i] = urand();
  qk_tree_options_t o;
  qk_tree_options_init(&o);
  o.capacity = 32;
  o.has_root = 1;
  o.root = (qk_square_t){0, 0, 1};
  qk_tree_t *t;
  if (qk_tree_build(p, n, &o, &t)) return 3;
  int reps = argc > 3 ? atoi(argv[3]) : 3;
  for (int rep = 0; rep < reps; rep++) {
    double t0 = now();
    for (size_t i = 0; i < nq; i++) {
      qk_neighbor_t nb;
      size_t c;
      qk_query_knn(t, (qk_point_t){q[2 * i], q[2 * i + 1]}, 1, INFINITY, &nb, &c);
      ref[i] = nb.dist * nb.dist;
    }
    double t1 = now();
    for (size_t i = 0; i < nq; i++) {
      uint32_t id = QK_NONE;
      got[i] = nn_locate(t, q[2 * i], q[2 * i + 1], &id);
    }
    double t2 = now();
    int ok1 = 1;
    for (size_t i = 0; i < nq; i++) ok1 &= fabs(got[i] - ref[i]) <= 1e-12 * ref[i] + 1e-300;
    double t3 = now();
    nn_batch8(t, q, nq, got);
    double t4 = now();
    int ok2 = 1;
    for (size_t i = 0; i < nq; i++) ok2 &= fabs(got[i] - ref[i]) <= 1e-12 * ref[i] + 1e-300;
    use_vec = 1;
    double t5 = now();
    for (size_t i = 0; i < nq; i++) {
      uint32_t id = QK_NONE;
      double best = INFINITY;
      uint32_t leaf = locate(t, q[2 * i], q[2 * i + 1]);
      scan_leaf_vec(t, &t->nodes[leaf], q[2 * i], q[2 * i + 1], &best, &id);
      dfs(t, q[2 * i], q[2 * i + 1], leaf, &best, &id);
      got[i] = best;
    }
    double t6 = now();
    use_vec = 0;
    int ok3 = 1;
    for (size_t i = 0; i < nq; i++) ok3 &= fabs(got[i] - ref[i]) <= 1e-12 * ref[i] + 1e-300;
    printf("n=%zu queries=%zu  library %.2f M/s  locate %.2f M/s (%s)  batch8 %.2f M/s (%s)  "
           "locate+vec %.2f M/s (%s)\n",
           n, nq, nq / (t1 - t0) / 1e6, nq / (t2 - t1) / 1e6, ok1 ? "same" : "DIFFERENT",
           nq / (t4 - t3) / 1e6, ok2 ? "same" : "DIFFERENT", nq / (t6 - t5) / 1e6,
           ok3 ? "same" : "DIFFERENT");
  }
  qk_tree_free(t);
  free(p);
  free(q);
  free(ref);
  free(got);
  return 0;
}
