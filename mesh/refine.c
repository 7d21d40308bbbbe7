/*
 * Size control: after the book's subdivision, split every leaf whose triangles could have
 * an edge longer than asked. The longest edge of a leaf of side s is its diagonal,
 * s sqrt 2 (the corner-to-corner split; the centre fan's edges are shorter), so a leaf is
 * split while s sqrt 2 exceeds the bound. Only leaves with no component edge are split
 * (those are larger than unit size), so the book's step 3 and its proof apply unchanged
 * to the refined, then balanced, tree; balancing only splits further, which keeps the
 * bound. The lattice is chosen fine enough (mesh/lattice.c) that unit leaves meet a
 * constant max_size; a size function is only sampled (corners and centre), and one that
 * asks for less than a unit leaf gives is refused (QK_MESH_AUTO meshes such input in the
 * general mode instead: generate.c); it was ignored there, without a word.
 */
#include "mesh/mesh_internal.h"

#include <math.h>

/* The longest edge wanted in the leaf square (X, Y, S) (lattice units), input units. */
static double wanted(const qk__gen_t *g, int64_t X, int64_t Y, int64_t S) {
  const qk_mesh_options_t *o = g->opt;
  double h = o->max_size > 0 ? o->max_size : INFINITY;
  if (o->size_fn) {
    static const int cx[5] = {0, 2, 0, 2, 1}, cy[5] = {0, 0, 2, 2, 1};
    for (int k = 0; k < 5; k++) {
      double x = qk__lat_out(&g->lat, 2 * X + cx[k] * S, g->lat.x0);
      double y = qk__lat_out(&g->lat, 2 * Y + cy[k] * S, g->lat.y0);
      double v = o->size_fn(x, y, o->size_user);
      if (v > 0 && v < h) h = v; /* (0, negative or NaN asks for nothing, as in general mode) */
    }
  }
  return h;
}

/* sc is qk__pow2(-f): a leaf's side in input units is S sc, exactly ldexp(S, -f), without
 * a call a leaf. */
static qk_status_t refine(qk__gen_t *g, double sc, qk_node_t v, int64_t X, int64_t Y, int64_t S) {
  /* With max_size alone the bound is the same everywhere and the test below is monotone
   * in S (products of positive numbers, rounded): when a square of side S needs no split,
   * neither does any square inside it, so its subtree is not visited. A size function is
   * sampled at every leaf. */
  if (!g->opt->size_fn &&
      !(qk__ldexp_by((double)S, sc, -g->lat.f) * 1.4142135623730951 > g->opt->max_size))
    return QK_OK;
  if (qk__node_leaf(g->tree, v)) {
    const double diag = qk__ldexp_by((double)S, sc, -g->lat.f) * 1.4142135623730951;
    const double want = wanted(g, X, Y, S);
    if (!(diag > want)) return QK_OK;
    if (S <= 1) {
      g->size_below_unit = 1;
      return qk__mesh_fail(g->err, QK_ERR_LIMIT, 0,
                           "the size function asks for %g near (%.17g, %.17g), less than the "
                           "lattice's unit square gives (diagonal %g): the general mode meshes "
                           "to it",
                           want, qk__lat_out(&g->lat, 2 * X + S, g->lat.x0),
                           qk__lat_out(&g->lat, 2 * Y + S, g->lat.y0), diag);
    }
    /* The root square is (0, 0, U), U a power of two (as in the subdivision). */
    unsigned depth = (unsigned)(__builtin_ctzll(g->U) - __builtin_ctzll((uint64_t)S));
    qk_status_t st = qk__tree_split_leaf_at(g->tree, v, (double)X, (double)Y, depth);
    if (st) return qk__mesh_fail(g->err, st, 0, "%s while refining to size", qk_strerror(st));
  }
  uint32_t c = qk__node_child(g->tree, v);
  int64_t h = S / 2;
  for (unsigned q = 0; q < 4; q++) {
    qk_status_t st =
        refine(g, sc, c + q, X + (qk__q_east(q) ? h : 0), Y + (qk__q_north(q) ? h : 0), h);
    if (st) return st;
  }
  return QK_OK;
}

/* refine() with max_size alone, for a node of side S >= smin, where smin is the least
 * side (a power of two) that the test splits: every side from smin up is split, none
 * below (the test is monotone in S), so the test is a comparison of integers, and the
 * children are visited only when they too need it. The same splits in the same order. */
static qk_status_t refine_uniform(qk__gen_t *g, qk_node_t v, int64_t X, int64_t Y, int64_t S,
                                  int64_t smin) {
  if (S <= 1) return QK_OK;
  if (qk__node_leaf(g->tree, v)) {
    unsigned depth = (unsigned)(__builtin_ctzll(g->U) - __builtin_ctzll((uint64_t)S));
    qk_status_t st = qk__tree_split_leaf_at(g->tree, v, (double)X, (double)Y, depth);
    if (st) return qk__mesh_fail(g->err, st, 0, "%s while refining to size", qk_strerror(st));
  }
  int64_t h = S / 2;
  if (h < smin) return QK_OK;
  uint32_t c = qk__node_child(g->tree, v);
  for (unsigned q = 0; q < 4; q++) {
    qk_status_t st = refine_uniform(g, c + q, X + (qk__q_east(q) ? h : 0),
                                    Y + (qk__q_north(q) ? h : 0), h, smin);
    if (st) return st;
  }
  return QK_OK;
}

qk_status_t qk__mesh_refine(qk__gen_t *g) {
  if (!(g->opt->max_size > 0) && !g->opt->size_fn) return QK_OK;
  double sc = qk__pow2(-g->lat.f);
  if (g->opt->size_fn) return refine(g, sc, qk_tree_root(g->tree), 0, 0, (int64_t)g->U);
  /* The least side refine() splits: its test, side by side from U down. */
  int64_t smin = (int64_t)g->U * 2;
  while (smin > 1 &&
         qk__ldexp_by((double)(smin / 2), sc, -g->lat.f) * 1.4142135623730951 > g->opt->max_size)
    smin /= 2;
  if (smin > (int64_t)g->U) return QK_OK; /* the root needs no split */
  return refine_uniform(g, qk_tree_root(g->tree), 0, 0, (int64_t)g->U, smin);
}
