/*
 * Prototype, not library code: the 2:1 check of BalanceQuadTree in O(1) per leaf. The
 * library's check (has_small_neighbor in index/balance.c, also behind
 * qk_tree_is_balanced) calls qk_tree_neighbor four times per leaf, each a walk up and
 * down the parent links, O(depth). Here one top-down pass gives every node its four
 * neighbours of equal or larger size (the result of NorthNeighbor and its three
 * siblings) from its parent's in O(1):
 *   - the neighbour across an edge inside the parent is a sibling;
 *   - otherwise take the parent's neighbour u: none stays none, a leaf u is the answer
 *     (it is larger), and an internal u gives its child mirrored across the edge.
 * The check of a leaf is then: a neighbour of the same depth that is internal and has a
 * non-leaf child facing the leaf. Run as `quadkit-proto-balance [n]` on a `gauss`-like
 * tree (capacity 8): prints the time of qk_tree_is_balanced() and of the table-based
 * check over the same tree, and checks that both say the same for every leaf.
 */
#define _POSIX_C_SOURCE 199309L
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <time.h>

#include "index/index_internal.h"

static double cpu(void) {
  struct timespec t;
  clock_gettime(CLOCK_PROCESS_CPUTIME_ID, &t);
  return (double)t.tv_sec + 1e-9 * (double)t.tv_nsec;
}

static unsigned long long rs = 88172645463325252ull;
static double urand(void) {
  rs ^= rs << 13;
  rs ^= rs >> 7;
  rs ^= rs << 17;
  return (double)(rs >> 11) * 0x1p-53;
}

/* Directions N, E, S, W (qk_dir_t); quadrants NE, NW, SW, SE (qk_quadrant_t). The
 * quadrant mirrored across an edge in direction d, and whether that mirror lies in the
 * same parent. */
static const unsigned char mirror[4][4] = {
    /* N */ {QK_SE, QK_SW, QK_NW, QK_NE},
    /* E */ {QK_NW, QK_NE, QK_SE, QK_SW},
    /* S */ {QK_SE, QK_SW, QK_NW, QK_NE},
    /* W */ {QK_NW, QK_NE, QK_SE, QK_SW}};
static const unsigned char inside[4][4] = {
    /* N: the south children have their north neighbour inside */ {0, 0, 1, 1},
    /* E: west children */ {0, 1, 1, 0},
    /* S: north children */ {1, 1, 0, 0},
    /* W: east children */ {1, 0, 0, 1}};
/* The two children of a neighbour lying in direction d that face the node. */
static const unsigned char facing[4][2] = {
    {QK_SW, QK_SE}, {QK_SW, QK_NW}, {QK_NW, QK_NE}, {QK_SE, QK_NE}};

/* nb[4 * v + d]: neighbour of node v in direction d of equal or larger size. Nodes are
 * visited from the root through an explicit stack of blocks so that a parent is always
 * done before its children. */
static void neighbours(const qk_tree_t *t, uint32_t *nb) {
  for (int d = 0; d < 4; d++) nb[d] = QK_NONE;
  uint32_t *stack = malloc(((size_t)t->n_nodes + 1) * sizeof *stack);
  size_t sp = 0;
  stack[sp++] = 0;
  while (sp) {
    uint32_t p = stack[--sp];
    uint32_t c = t->nodes[p].child;
    if (c == QK_NONE) continue;
    for (unsigned q = 0; q < 4; q++) {
      uint32_t v = c + q;
      for (unsigned d = 0; d < 4; d++) {
        uint32_t r;
        if (inside[d][q]) {
          r = c + mirror[d][q];
        } else {
          uint32_t u = nb[4 * p + d];
          if (u == QK_NONE || t->nodes[u].child == QK_NONE)
            r = u;
          else
            r = t->nodes[u].child + mirror[d][q];
        }
        nb[4 * v + d] = r;
      }
      stack[sp++] = v;
    }
  }
  free(stack);
}

static int small_neighbor(const qk_tree_t *t, const uint32_t *nb, uint32_t v) {
  for (unsigned d = 0; d < 4; d++) {
    uint32_t u = nb[4 * v + d];
    if (u == QK_NONE || t->nodes[u].child == QK_NONE) continue;
    uint32_t c = t->nodes[u].child;
    if (t->nodes[c + facing[d][0]].child != QK_NONE || t->nodes[c + facing[d][1]].child != QK_NONE)
      return 1;
  }
  return 0;
}

int main(int argc, char **argv) {
  size_t n = argc > 1 ? (size_t)atof(argv[1]) : 1000000;
  qk_point_t *p = malloc(n * sizeof *p);
  double cx[64], cy[64], sd[64], cum[64], tot = 0;
  for (int i = 0; i < 64; i++) {
    cx[i] = 0.05 + 0.9 * urand();
    cy[i] = 0.05 + 0.9 * urand();
    sd[i] = 0.002 + 0.04 * urand();
    tot += 1.0 / (i + 1);
    cum[i] = tot;
  }
  for (size_t i = 0; i < n; i++) {
    double w = urand() * tot;
    int k = 0;
    while (k < 63 && cum[k] < w) k++;
    double r = sqrt(-2 * log(urand() + 1e-300)), a = 6.283185307179586 * urand();
    double x = cx[k] + sd[k] * r * cos(a), y = cy[k] + sd[k] * r * sin(a);
    p[i].x = x < 0 ? 0 : x > 1 ? 1 : x;
    p[i].y = y < 0 ? 0 : y > 1 ? 1 : y;
  }
  qk_tree_options_t o;
  qk_tree_options_init(&o);
  o.capacity = 8;
  o.max_depth = 28;
  o.has_root = 1;
  o.root = (qk_square_t){0, 0, 1};
  qk_tree_t *t;
  if (qk_tree_build(p, n, &o, &t)) return 3;
  /* Time the check on the balanced tree, where both must look at every leaf (on an
   * unbalanced tree qk_tree_is_balanced stops at the first violation). */
  double tb0 = cpu();
  qk_tree_balance(t);
  double tb1 = cpu();
  printf("qk_tree_balance %.2f ms\n", (tb1 - tb0) * 1e3);
  uint32_t *nb = malloc(4 * (size_t)t->n_nodes * sizeof *nb);
  for (int rep = 0; rep < 3; rep++) {
    double t0 = cpu();
    int lib = qk_tree_is_balanced(t);
    double t1 = cpu();
    neighbours(t, nb);
    double t2 = cpu();
    size_t bad = 0, leaves = 0;
    for (uint32_t v = 0; v < t->n_nodes; v++)
      if (qk__live(t, v) && t->nodes[v].child == QK_NONE) {
        leaves++;
        bad += (size_t)small_neighbor(t, nb, v);
      }
    double t3 = cpu();
    printf("balanced tree, %zu leaves: qk_tree_is_balanced %.2f ms (%s); neighbour table %.2f ms "
           "+ check %.2f ms (%zu leaves with a small neighbour, %s)\n",
           leaves, (t1 - t0) * 1e3, lib ? "balanced" : "not balanced", (t2 - t1) * 1e3,
           (t3 - t2) * 1e3, bad, (bad == 0) == (lib != 0) ? "agrees" : "DISAGREES");
  }
  free(nb);
  qk_tree_free(t);
  free(p);
  return 0;
}
