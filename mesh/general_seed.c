/*
 * The general mode, steps 4 to 6 (docs/mesh.md, "The general mode"): a quadtree graded
 * by the input's features, its seeds, and the segments' pre-split points, inserted into
 * the CDT in Z-order so that every walk starts next to its target.
 *
 * The tree lives in lattice coordinates, the root square being [0, 1]^2: input point
 * (x, y) is (x - X0, y - Y0) 2^-e there. The feature tests convert the squares back to input
 * coordinates (the same conversion for a square's sides and its corners, so a seed lies in
 * the closed box it was tested with).
 */
#include "mesh/general_mesh.h"

#include <math.h>
#include <stdlib.h>
#include <string.h>

/* Deepest subdivision: beyond it, the refinement alone separates features. */
#define GM_DEPTH_CAP 50
/* Whether the free leaves' corners and centres are inserted as seeds. They are not: on
 * the coastlines (Iceland, Norway; docs/mesh.md, "Mesh size") the refinement alone makes
 * half the triangles (2.6 times fewer with a size bound) in 20-45% fewer instructions in
 * all, though more a triangle. The leaves still size the refinement's work cap. */
#define GM_SEED_LEAVES 0
/* Whether the grading splits leaves larger than the size bound. Only a size function needs
 * it (the tree samples it, which sizes the refinement's work cap); with seeds off, nothing
 * else reads those leaves: the pre-split and the refinement take the bound where they are.
 * A plain max_size is counted instead (size_cells): on Norway with a bound of 1/256 of its
 * extent the size-split leaves were 3.9 million, three times the triangles, a third of the
 * meshing instructions and most of its memory. */
#define GM_SIZE_SPLITS(g) (GM_SEED_LEAVES || (g)->opt->size_fn)
/* Most tree nodes the grading may make (a size bound asking for more is refused). */
#define GM_NODE_CAP ((uint32_t)1 << 27)
/* Splits separating features below 2^-GM_DEEP of the root square are counted: near-
 * coincident features legitimately need a few per level, but two features close along a
 * long stretch (nearly parallel segments, a vertex next to a long segment) would need
 * cells of their gap's size all along it. More than GM_DEEP_BUDGET plus 256 per feature
 * is refused, before seconds of work. */
#define GM_DEEP 36
#define GM_DEEP_BUDGET 4096
/* Splits separating features at any depth: the coastlines take one or two a feature
 * (Norway: 1,953 segments, 4,596 splits), so more than GM_SEP_BUDGET plus 256 per
 * feature means two features close along a stretch far longer than their gap, above the
 * 2^-36 that GM_DEEP watches (a 2^31 by 1 rectangle: 2^31 cells; before this cap it ran
 * into GM_NODE_CAP after 18 s and 2.5 GB). Refused at about 2^20 nodes instead. */
#define GM_SEP_BUDGET ((size_t)1 << 18)

/* Lattice to input coordinates; multiplying by S = 2^e is exact (and cheaper than ldexp). */
static double in_x(const qk__gm_t *g, double X) { return g->X0 + X * g->S; }
static double in_y(const qk__gm_t *g, double Y) { return g->Y0 + Y * g->S; }

/* The size bound near a point set: max_size, and size_fn at each sample (+inf: none). */
static double size_at(const qk__gm_t *g, const double *xy, int n) {
  double h = g->opt->max_size > 0 ? g->opt->max_size : INFINITY;
  if (g->opt->size_fn)
    for (int i = 0; i < n; i++) {
      double v = g->opt->size_fn(xy[2 * i], xy[2 * i + 1], g->opt->size_user);
      if (v > 0 && v < h) h = v;
    }
  return h;
}

static double dist2(const double a[2], const double b[2]) {
  return (a[0] - b[0]) * (a[0] - b[0]) + (a[1] - b[1]) * (a[1] - b[1]);
}

/* Feature f's part in the closed box [lo, hi] into e (a vertex: itself; a segment: its
 * clipping by the box, Liang-Barsky in doubles; the caller knows it meets the box). Its
 * ends are g->fbox's (the grading's). */
static void part_in_box(const qk__gm_t *g, uint32_t f, const double lo[2], const double hi[2],
                        double e[4]) {
  const double *end = &g->fbox[8 * (size_t)f + 4];
  const double a[2] = {end[0], end[1]}, d[2] = {end[2] - a[0], end[3] - a[1]};
  double t0 = 0, t1 = 1;
  for (int i = 0; i < 2; i++) {
    if (d[i] == 0) continue;
    double s0 = (lo[i] - a[i]) / d[i], s1 = (hi[i] - a[i]) / d[i];
    if (s0 > s1) {
      double x = s0;
      s0 = s1, s1 = x;
    }
    t0 = s0 > t0 ? s0 : t0, t1 = s1 < t1 ? s1 : t1;
  }
  if (!(t0 <= t1)) t0 = t1 = 0; /* (rounding: the box only grazes it) */
  e[0] = a[0] + t0 * d[0], e[1] = a[1] + t0 * d[1];
  e[2] = a[0] + t1 * d[0], e[3] = a[1] + t1 * d[1];
}

/* The point of segment (or point) e nearest p, into q. */
static void nearest_on(const double e[4], const double p[2], double q[2]) {
  const double dx = e[2] - e[0], dy = e[3] - e[1], l2 = dx * dx + dy * dy;
  double t = l2 > 0 ? ((p[0] - e[0]) * dx + (p[1] - e[1]) * dy) / l2 : 0;
  t = t < 0 ? 0 : t > 1 ? 1 : t;
  q[0] = e[0] + t * dx, q[1] = e[1] + t * dy;
}

/* Whether features f and h face each other in the box across the outside of the domain
 * only: the midpoint of the nearest points of their parts in the box lies strictly inside
 * a triangle of a dropped face (the outside, or a hole). The refinement never puts a point
 * there nor tests across it (the dropped side is neither refined nor searched), so such a
 * pair sets no size: a comb's teeth 2^-11 apart across its slots, each tooth 0.0045 wide,
 * were refused as two segments too close along a stretch, though with a size bound that
 * never bound they made 53,351 triangles (a QA helper's). A midpoint on an edge or in a
 * kept face keeps the pair. */
static int across_outside(const qk__gm_t *g, uint32_t f, uint32_t h, const double lo[2],
                          const double hi[2]) {
  double e[2][4];
  part_in_box(g, f, lo, hi, e[0]);
  part_in_box(g, h, lo, hi, e[1]);
  double best = INFINITY, m[2] = {0, 0};
  for (int i = 0; i < 2; i++)
    for (int j = 0; j < 2; j++) {
      const double *p = &e[i][2 * j];
      double q[2];
      nearest_on(e[1 - i], p, q);
      const double d = dist2(p, q);
      if (d < best) best = d, m[0] = p[0] + (q[0] - p[0]) / 2, m[1] = p[1] + (q[1] - p[1]) / 2;
    }
  if (!(best > 0)) return 0;
  const qk__cdt_t *c = &g->cdt;
  if (!(m[0] > c->xy[0] && m[0] < c->xy[4] && m[1] > c->xy[1] && m[1] < c->xy[5])) return 0;
  /* (walked from f's end nearer the midpoint: a walk from the last insertion crossed the
   * mesh, and the comb took seconds) */
  const qk_poly_t *P = g->P;
  const uint32_t nv = (uint32_t)P->nv;
  const uint32_t u = f < nv ? f : P->seg[2 * (f - nv)], w = f < nv ? f : P->seg[2 * (f - nv) + 1];
  const double *end = &g->fbox[8 * (size_t)f + 4]; /* (u's place, then w's) */
  const uint32_t v = g->cv[dist2(end + 2, m) < dist2(end, m) ? w : u];
  uint32_t t;
  int k;
  if (qk__cdt_locate(c, m[0], m[1], v == QK__CDT_NONE ? QK__CDT_NONE : c->vtri[v], &t, &k) !=
      QK__CDT_IN)
    return 0;
  return g->faces[g->face[t]].drop;
}

/* Do features f and h (vertex ids below nv, then nv + segment ids) need separating in the
 * closed box [lo, hi]? Two vertices always do; a vertex and a segment unless the vertex is
 * an endpoint; two segments unless they share an endpoint that lies in the box (near their
 * shared vertex the concentric shells of the refinement grade them instead); and none
 * that face each other across the outside only (across_outside). */
static int separate(const qk__gm_t *g, uint32_t f, uint32_t h, const double lo[2],
                    const double hi[2]) {
  const qk_poly_t *P = g->P;
  uint32_t nv = (uint32_t)P->nv;
  if (f < nv && h < nv) return !across_outside(g, f, h, lo, hi);
  if (f < nv || h < nv) {
    uint32_t v = f < nv ? f : h, s = (f < nv ? h : f) - nv;
    return P->seg[2 * s] != v && P->seg[2 * s + 1] != v && !across_outside(g, f, h, lo, hi);
  }
  const uint32_t *a = &P->seg[2 * (f - nv)], *b = &P->seg[2 * (h - nv)];
  for (int i = 0; i < 2; i++)
    for (int j = 0; j < 2; j++)
      if (a[i] == b[j]) {
        double x = P->vx[a[i]], y = P->vy[a[i]];
        return !(x >= lo[0] && x <= hi[0] && y >= lo[1] && y <= hi[1]);
      }
  return !across_outside(g, f, h, lo, hi);
}

/* Whether the closed segment ab meets the closed box, exactly: the bounding boxes overlap
 * and the segment's line does not leave every box corner strictly on one side. The
 * orientation det(c) = dx (c_y - a_y) - dy (c_x - a_x) is linear in the corner c, so its
 * largest and smallest values over the box are at the two corners the exact signs of dx
 * and dy pick (a rounded difference has the exact sign): two tests, not four. Each is the
 * floating-point estimate with the error bound of qk__orient2d, the exact predicate only
 * when the bound leaves its sign open. f holds the segment as {ax, ay, bx, by}; the
 * caller has checked the bounding boxes (g->fbox: per feature {x0, y0, x1, y1} its bounding
 * box, then {ax, ay, bx, by} its ends, one cache line). */
static int seg_box_line(const double *f, const double lo[2], const double hi[2]) {
  const double a[2] = {f[0], f[1]}, b[2] = {f[2], f[3]};
  double dx = b[0] - a[0], dy = b[1] - a[1];
  /* The corner maximising det: largest y when dx > 0, smallest x when dy > 0. */
  const double cmax[2] = {dy > 0 ? lo[0] : hi[0], dx > 0 ? hi[1] : lo[1]};
  const double cmin[2] = {dy > 0 ? hi[0] : lo[0], dx > 0 ? lo[1] : hi[1]};
  const double *c[2] = {cmax, cmin};
  int o[2];
  for (int k = 0; k < 2; k++) {
    double l = dx * (c[k][1] - a[1]), r = dy * (c[k][0] - a[0]), det = l - r;
    double bound = (fabs(l) + fabs(r)) * 0x1p-50;
    o[k] = det > bound ? 1 : -det > bound ? -1 : qk__orient2d(a, b, c[k]);
  }
  return o[0] >= 0 && o[1] <= 0;
}

/* seg_box: an end in the box settles it (most features of a small box end in it), inline;
 * the line's test otherwise. */
static inline int seg_box(const double *f, const double lo[2], const double hi[2]) {
  if ((f[0] >= lo[0] && f[0] <= hi[0] && f[1] >= lo[1] && f[1] <= hi[1]) ||
      (f[2] >= lo[0] && f[2] <= hi[0] && f[3] >= lo[1] && f[3] <= hi[1]))
    return 1;
  return seg_box_line(f, lo, hi);
}

/* A leaf of the grading whose grown square meets no feature: with seeds the node is marked
 * for seeds(); without them nothing is wanted (the work cap counts every leaf). */
static qk_status_t mark_free(qk__gm_t *g, uint32_t node) {
  if (!GM_SEED_LEAVES) return QK_OK;
  if (node >= g->free_cap) {
    size_t old = g->free_cap;
    void *p = g->free_node;
    if (qk__grow(g->a, &p, &g->free_cap, (size_t)node + 1, 1)) return QK_ERR_NOMEM;
    g->free_node = p;
    memset(g->free_node + old, 0, g->free_cap - old);
  }
  g->free_node[node] = 1;
  return QK_OK;
}

/* The grown square, the leaf grown by a quarter of its side all round, in input
 * coordinates. (Growing by a whole side, as BEG's neighbourhoods do, made three times the
 * leaves on coastlines and twice the triangles for the same angle bound, and 10% more
 * instructions per triangle: the refinement places the last points near features more
 * cheaply than a finer tree.) */
static void grown_box(const qk__gm_t *g, double X, double Y, double s, double lo[2], double hi[2]) {
  lo[0] = in_x(g, X - s / 4), lo[1] = in_y(g, Y - s / 4);
  hi[0] = in_x(g, X + 1.25 * s), hi[1] = in_y(g, Y + 1.25 * s);
}

/* The refusal of a grading that would go on too finely along two features. */
static qk_status_t too_close(const qk__gm_t *g, uint32_t f, uint32_t h, double s, int deep) {
  const qk_poly_t *P = g->P;
  uint32_t nv = (uint32_t)P->nv, id[2] = {f, h};
  char nm[2][96];
  for (int i = 0; i < 2; i++) {
    int v = id[i] < nv;
    size_t j = v ? id[i] : id[i] - nv;
    unsigned long line = v ? (P->vline ? P->vline[j] : 0) : (P->sline ? P->sline[j] : 0);
    qk__gm_named(v ? "vertex" : "segment", v ? qk__mesh_num(P, j) : qk__mesh_snum(P, j), line,
                 nm[i]);
  }
  double gap = 1.5 * s * g->S, ext = fmax(g->bx1 - g->bx0, g->by1 - g->by0);
  /* (Within the 255 characters of a message, names of 40 characters each included.) */
  if (!deep)
    return qk__mesh_fail(g->err, QK_ERR_LIMIT, 0,
                         "%s and %s stay within %.3g of each other along a stretch (extent "
                         "%.6g, ratio %.3g): grading the quadtree to that gap would take over "
                         "%zu cell splits (2^18 + 256 a feature)",
                         nm[0], nm[1], gap, ext, ext / gap, g->sep_cap);
  return qk__mesh_fail(g->err, QK_ERR_LIMIT, 0,
                       "%s and %s stay within %.3g of each other along a stretch (extent %.6g, "
                       "ratio %.3g): grading the quadtree to that gap would take over %zu "
                       "cells below 2^-%d of the extent",
                       nm[0], nm[1], gap, ext, ext / gap, g->deep_cap, GM_DEEP);
}

/* Whether feature f is vertex v or a segment with end v. */
static int on_hub(const qk__gm_t *g, uint32_t f, uint32_t v) {
  const uint32_t nv = (uint32_t)g->P->nv;
  if (f < nv) return f == v;
  const uint32_t *e = &g->P->seg[2 * (f - nv)];
  return e[0] == v || e[1] == v;
}

/* A hub of the k features L meeting the closed box [lo, hi]: a vertex in the box such that
 * at most 48 of them are neither the vertex nor a segment ending at it, or UINT32_MAX. Two
 * features on a hub in the box never need separating there (separate), so a box that many
 * segments of one vertex meet (a fan) is split only for the others. One of any 49 of the
 * features is on the hub (at most 48 are off it): the hub, or a segment ending at it, so
 * the first 49 features and their ends are tried. */
static uint32_t hub_of(const qk__gm_t *g, const uint32_t *L, size_t k, const double lo[2],
                       const double hi[2]) {
  const qk_poly_t *P = g->P;
  const uint32_t nv = (uint32_t)P->nv;
  for (size_t i = 0; i < k && i < 49; i++) {
    for (int e = 0; e < (L[i] < nv ? 1 : 2); e++) {
      const uint32_t v = L[i] < nv ? L[i] : P->seg[2 * (L[i] - nv) + (uint32_t)e];
      const double x = P->vx[v], y = P->vy[v];
      if (!(x >= lo[0] && x <= hi[0] && y >= lo[1] && y <= hi[1])) continue;
      size_t off = 0;
      for (size_t j = 0; j < k && off <= 48; j++) off += !on_hub(g, L[j], v);
      if (off <= 48) return v;
    }
  }
  return UINT32_MAX;
}

/* Step 4: split a leaf while its grown square ([lo, hi], from its parent) meets two features
 * that need separating, or while it is larger than the size bound there (inside the input's
 * bounding box). The k features at g->arena[off..] meet this node's grown square; children
 * filter them. */
static qk_status_t subdivide(qk__gm_t *g, uint32_t node, double X, double Y, double s,
                             const double lo[2], const double hi[2], unsigned depth, size_t off,
                             size_t k) {
  int split = 0;
  if (depth < GM_DEPTH_CAP) {
    const uint32_t *L = g->arena + off;
    /* Many features: split at once, unless most of them are one hub's (a fan of segments
     * from one vertex in the box), whose pairs need no separating: then only the pairs
     * with a feature off the hub are tested (the same answer as testing all). */
    const uint32_t hub = k > 48 ? hub_of(g, L, k, lo, hi) : UINT32_MAX;
    if (k > 48 && hub == UINT32_MAX) split = 1;
    for (size_t i = 0; i < k && !split; i++)
      for (size_t j = i + 1; j < k && !split; j++)
        if ((hub == UINT32_MAX || !on_hub(g, L[i], hub) || !on_hub(g, L[j], hub)) &&
            (split = separate(g, L[i], L[j], lo, hi))) {
          if (depth >= GM_DEEP && ++g->deep_splits > g->deep_cap)
            return too_close(g, L[i], L[j], s, 1);
          if (++g->sep_splits > g->sep_cap) return too_close(g, L[i], L[j], s, 0);
        }
    if (!split && GM_SIZE_SPLITS(g) && (g->opt->max_size > 0 || g->opt->size_fn)) {
      double x0 = in_x(g, X), y0 = in_y(g, Y), x1 = in_x(g, X + s), y1 = in_y(g, Y + s);
      if (x1 >= g->bx0 && x0 <= g->bx1 && y1 >= g->by0 && y0 <= g->by1) {
        const double smp[10] = {x0, y0, x1, y0, x1, y1, x0, y1, (x0 + x1) / 2, (y0 + y1) / 2};
        split = x1 - x0 > size_at(g, smp, 5);
      }
    }
  }
  if (!split) return k == 0 ? mark_free(g, node) : QK_OK;
  if (qk__tree_node_bound(g->tree) > GM_NODE_CAP)
    return qk__mesh_fail(g->err, QK_ERR_LIMIT, 0,
                         "the size bound asks for more than 2^27 quadtree cells");
  /* The tree's root is (0, 0, 1) and every square here came from it by halvings, X and Y
   * sums of the halved sides (dyadic, exact at depths to GM_DEPTH_CAP): the tree's own
   * corner and depth, given so that the split does not walk the path back to the root. */
  qk_status_t st = qk__tree_split_leaf_at(g->tree, node, X, Y, depth);
  if (st) return qk__mesh_fail(g->err, st, 0, "%s while grading the quadtree", qk_strerror(st));
  uint32_t child = qk__node_child(g->tree, node);
  double h = s / 2, cx[4], cy[4], clo[4][2], chi[4][2];
  /* The four children's lists at once, child q's at base + q k (in the parent's order):
   * each feature's box is read once and tested against the children's columns and rows. */
  if (g->arena_n + 4 * k + 1 > g->arena_cap) {
    void *ap = g->arena;
    if (qk__grow(g->a, &ap, &g->arena_cap, g->arena_n + 4 * k + 1, sizeof *g->arena))
      return qk__mesh_fail(g->err, QK_ERR_NOMEM, 0, "out of memory");
    g->arena = ap;
  }
  unsigned qwest = 0, qeast = 0, qsouth = 0, qnorth = 0;
  for (unsigned q = 0; q < 4; q++) {
    cx[q] = X + (qk__q_east(q) ? h : 0), cy[q] = Y + (qk__q_north(q) ? h : 0);
    grown_box(g, cx[q], cy[q], h, clo[q], chi[q]);
    *(qk__q_east(q) ? &qeast : &qwest) = q;
    *(qk__q_north(q) ? &qnorth : &qsouth) = q;
  }
  const double xw0 = clo[qwest][0], xw1 = chi[qwest][0], xe0 = clo[qeast][0], xe1 = chi[qeast][0];
  const double ys0 = clo[qsouth][1], ys1 = chi[qsouth][1], yn0 = clo[qnorth][1],
               yn1 = chi[qnorth][1];
  size_t base = g->arena_n, n[4] = {0, 0, 0, 0};
  uint32_t nv = (uint32_t)g->P->nv, *A = g->arena;
  for (size_t i = 0; i < k; i++) {
    uint32_t f = A[off + i];
    const double *b = &g->fbox[8 * (size_t)f];
    int w = !(b[2] < xw0 || b[0] > xw1), e = !(b[2] < xe0 || b[0] > xe1);
    int so = !(b[3] < ys0 || b[1] > ys1), no = !(b[3] < yn0 || b[1] > yn1);
    /* Quadrant by quadrant with constant numbers, so the tests unroll. */
#define GM_PUT(q, in)                                                                              \
  if ((in) && (f < nv || seg_box(b + 4, clo[q], chi[q]))) A[base + (q)*k + n[q]++] = f
    GM_PUT(QK_NE, e && no);
    GM_PUT(QK_NW, w && no);
    GM_PUT(QK_SW, w && so);
    GM_PUT(QK_SE, e && so);
#undef GM_PUT
  }
  g->arena_n = base + 4 * k;
  /* A child with no feature, or one, is a leaf unless the size bound splits leaves: settled
   * here without the call (most children of the grading are such leaves). So is a child with
   * two features that need no separating there (two consecutive segments of a ring whose
   * shared vertex lies in the child's grown square: a coastline's commonest leaf), by the
   * test the call would make first. */
  const int settle = !GM_SIZE_SPLITS(g) || !(g->opt->max_size > 0 || g->opt->size_fn);
  for (unsigned q = 0; q < 4; q++) {
    if (settle && n[q] <= 1) {
      if (!n[q] && (st = mark_free(g, child + q))) break;
      continue;
    }
    /* g->arena, not A: a sibling's subdivision may have moved it. */
    const uint32_t *Lq = g->arena + base + q * k;
    if (settle && n[q] == 2 && !separate(g, Lq[0], Lq[1], clo[q], chi[q])) continue;
    st = subdivide(g, child + q, cx[q], cy[q], h, clo[q], chi[q], depth + 1, base + q * k, n[q]);
    if (st) break;
  }
  g->arena_n = base;
  return st;
}

/* Spread the low 32 bits of v to the even bit positions. */
static uint64_t spread32(uint64_t v) {
  v &= 0xFFFFFFFFu;
  v = (v | (v << 16)) & 0x0000FFFF0000FFFFull;
  v = (v | (v << 8)) & 0x00FF00FF00FF00FFull;
  v = (v | (v << 4)) & 0x0F0F0F0F0F0F0F0Full;
  v = (v | (v << 2)) & 0x3333333333333333ull;
  v = (v | (v << 1)) & 0x5555555555555555ull;
  return v;
}

/* Morton key of lattice point (X, Y) in [0, 1]^2, 32 bits an axis. */
static uint64_t morton_lat(double X, double Y) {
  X *= 0x1p32, Y *= 0x1p32;
  uint64_t ix = X <= 0 ? 0 : X >= 4294967295.0 ? 4294967295u : (uint64_t)X;
  uint64_t iy = Y <= 0 ? 0 : Y >= 4294967295.0 ? 4294967295u : (uint64_t)Y;
  return spread32(ix) | spread32(iy) << 1;
}

uint64_t qk__gm_morton(const qk__gm_t *g, double x, double y) {
  return morton_lat((x - g->X0) * g->inv_S, (y - g->Y0) * g->inv_S);
}

static qk_status_t add_pt(qk__gm_t *g, uint64_t key, double x, double y, uint32_t seg, uint64_t k) {
  if (g->npts + 1 > g->pts_cap) {
    void *p = g->pts;
    if (qk__grow(g->a, &p, &g->pts_cap, g->npts + 1, sizeof *g->pts)) return QK_ERR_NOMEM;
    g->pts = p;
  }
  g->pts[g->npts] = (qk__gm_pt_t){key, x, y, k, seg, (uint32_t)g->npts};
  g->npts++;
  return QK_OK;
}

/* Step 5: the corners and centres of the free leaves (whose grown squares meet no
 * feature) that meet the input's bounding box, in the tree's order. */
static qk_status_t seeds(qk__gm_t *g, uint32_t node, double X, double Y, double s, int fr) {
  fr |= node < g->free_cap && g->free_node[node];
  uint32_t child = qk__node_child(g->tree, node);
  if (child == QK_NONE) {
    if (!fr) return QK_OK;
    double x0 = in_x(g, X), y0 = in_y(g, Y), x1 = in_x(g, X + s), y1 = in_y(g, Y + s);
    if (x1 < g->bx0 || x0 > g->bx1 || y1 < g->by0 || y0 > g->by1) return QK_OK;
    g->cap_leaves++;
    const double c[10] = {x0, y0, x1, y0, x0, y1, x1, y1, in_x(g, X + s / 2), in_y(g, Y + s / 2)};
    const double L[10] = {X, Y, X + s, Y, X, Y + s, X + s, Y + s, X + s / 2, Y + s / 2};
    /* The centre moves by a pattern of up to s/256 (any double is a valid seed): a grid's
     * points are cocircular and collinear everywhere, which sends in-circle and orientation
     * tests to their exact, slow path, and every Delaunay triangle here has a centre as a
     * corner. Corners stay put, so that leaves sharing one emit it alike. */
    for (int i = 0; i < 5; i++) {
      uint64_t key = morton_lat(L[2 * i], L[2 * i + 1]);
      double x = c[2 * i], y = c[2 * i + 1];
      if (i == 4) {
        uint64_t h = key * 0x9E3779B97F4A7C15ull;
        double j = (x1 - x0) / 128;
        x += j * ((double)(h >> 61) / 7 - 0.5), y += j * ((double)((h >> 58) & 7) / 7 - 0.5);
      }
      if (add_pt(g, key, x, y, QK__CDT_NONE, 0)) return QK_ERR_NOMEM;
    }
    return QK_OK;
  }
  double h = s / 2;
  for (unsigned q = 0; q < 4; q++) {
    qk_status_t st =
        seeds(g, child + q, X + (qk__q_east(q) ? h : 0), Y + (qk__q_north(q) ? h : 0), h, fr);
    if (st) return st;
  }
  return QK_OK;
}

/* The leaves a grading by max_size alone would make over the input's bounding box: squares
 * of the root's side halved until within the bound, in a grid over the box. They size the
 * work cap with the graded tree's leaves (which the plain bound does not split). */
static size_t size_cells(const qk__gm_t *g) {
  double h = g->opt->max_size;
  if (GM_SIZE_SPLITS(g) || !(h > 0)) return 0;
  double s = g->S;
  while (s > h) s /= 2;
  double n = (floor((g->bx1 - g->bx0) / s) + 2) * (floor((g->by1 - g->by0) / s) + 2);
  return n < 0x1p40 ? (size_t)n : (size_t)1 << 40; /* (a thin domain's box may hold far more) */
}

/* Choose an exact split parameter strictly inside (lo, hi) of segment s: concentric shells
 * next to an input vertex, the midpoint otherwise; and its point, given the piece's ends
 * (general_refine.c). */
int qk__gm_split_param(const qk__gm_t *g, uint32_t s, uint64_t lo, uint64_t hi, uint64_t *k);
int qk__gm_split_point(const qk__gm_t *g, uint32_t s, uint64_t k, const double e0[2],
                       const double e1[2], double p[2]);

/* Step 6: split segment s's piece (lo, hi) while it is longer than the size bound at its
 * middle. Not to the graded leaves' sides: the refinement splits what is encroached, and
 * pieces cut to the leaves made meshes up to 9.5 times larger than needed at coarse
 * bounds or none (docs/mesh.md, "Mesh size"). A piece with no exact split point is left to the
 * refinement, which refuses the input only if it must split it. */
static qk_status_t presplit(qk__gm_t *g, uint32_t s, const double *A, const double *B, double len,
                            uint64_t lo, uint64_t hi, const double *e0, const double *e1) {
  double t = (double)(lo / 2 + hi / 2) * 0x1p-62;
  double mid[2] = {A[0] + t * (B[0] - A[0]), A[1] + t * (B[1] - A[1])};
  if (!(len * ((double)(hi - lo) * 0x1p-62) > size_at(g, mid, 1))) return QK_OK;
  uint64_t k;
  double p[2];
  /* (e0, e1: the piece's ends, which a free segment's point must lie strictly between) */
  if (!qk__gm_split_param(g, s, lo, hi, &k) || !qk__gm_split_point(g, s, k, e0, e1, p))
    return QK_OK;
  qk_status_t st = presplit(g, s, A, B, len, lo, k, e0, p);
  if (!st) st = add_pt(g, qk__gm_morton(g, p[0], p[1]), p[0], p[1], s, k);
  if (!st) st = presplit(g, s, A, B, len, k, hi, p, e1);
  return st;
}

/* Sort the points by Morton key: least significant digit first, 8 or 11 bits a pass, passes
 * whose digit is the same for every key skipped; stable. */
qk_status_t qk__gm_sort_points(const qk__gm_t *g, qk__gm_pt_t *pts, size_t n) {
  qk__gm_pt_t *tmp = qk__realloc(g->a, NULL, 0, (n + 1) * sizeof *tmp), *src = pts, *dst = tmp;
  if (!tmp) return QK_ERR_NOMEM;
  size_t cnt[2048];
  /* Digits of 8 bits below 2048 points, where clearing and summing 2048 counters a pass
   * would cost more than the points; 11 bits above (4 passes of the 44 key bits, not 6: a
   * pass moves each 40-byte record, about 25 instructions a point). The same stable order. */
  const int bits = n < 2048 ? 8 : 11;
  const uint64_t mask = ((uint64_t)1 << bits) - 1;
  /* Bits below 20 order points within 2^-22 of the square's side: irrelevant to walks. */
  for (int shift = 20; shift < 64; shift += bits) {
    memset(cnt, 0, (mask + 1) * sizeof *cnt);
    for (size_t i = 0; i < n; i++) cnt[(src[i].key >> shift) & mask]++;
    if (cnt[(src[0].key >> shift) & mask] == n) continue;
    size_t sum = 0;
    for (size_t d = 0; d <= mask; d++) {
      size_t c = cnt[d];
      cnt[d] = sum, sum += c;
    }
    for (size_t i = 0; i < n; i++) dst[cnt[(src[i].key >> shift) & mask]++] = src[i];
    qk__gm_pt_t *t = src;
    src = dst, dst = t;
  }
  if (src != pts) memcpy(pts, src, n * sizeof *src);
  qk__free(g->a, tmp, (n + 1) * sizeof *tmp);
  return QK_OK;
}

/* The edge holding split point q (rank r among all split points, first[s] .. first[s + 1]
 * those of its segment s, in parameter order): between the nearest split points of s
 * inserted already on either side (rv: their CDT vertices, NONE while not inserted), or the
 * segment's ends. No point lies on that piece between them, so it is one constrained edge:
 * found by turning around one end, without a walk and without the orientation tests of a
 * walk's last step, which are exact ones for a point on its own segment's line. */
static uint32_t seg_edge(const qk__gm_t *g, const qk__gm_pt_t *q, const uint32_t *first,
                         const uint32_t *rv, int *k) {
  const qk_poly_t *P = g->P;
  uint32_t s = q->seg, r = q->rank, a = QK__CDT_NONE, b = QK__CDT_NONE;
  for (uint32_t i = r; i > first[s] && a == QK__CDT_NONE;) a = rv[--i];
  for (uint32_t i = r + 1; i < first[s + 1] && b == QK__CDT_NONE; i++) b = rv[i];
  if (a == QK__CDT_NONE) a = g->cv[P->seg[2 * s]];
  if (b == QK__CDT_NONE) b = g->cv[P->seg[2 * s + 1]];
  return qk__cdt_find_edge(&g->cdt, a, b, k);
}

/* Insert the seeds and split points in Z-order: a seed's walk starts at the last vertex, a
 * split point goes straight onto its edge (seg_edge). Seeds in dropped faces (outside,
 * holes) are skipped. first[s] is where segment s's split points start in rank order. */
static qk_status_t insert_points(qk__gm_t *g, const uint32_t *first) {
  qk__cdt_t *c = &g->cdt;
  uint32_t hint = QK__CDT_NONE;
  uint32_t *rv = qk__realloc(g->a, NULL, 0, (g->npts + 1) * sizeof *rv);
  if (!rv) return qk__mesh_fail(g->err, QK_ERR_NOMEM, 0, "out of memory");
  memset(rv, 0xff, (g->npts + 1) * sizeof *rv); /* QK__CDT_NONE */
  /* Room for the points and the refinement at once, while the arrays are small: the CDT
   * was sized for 8 points an input vertex, and inputs of short segments far apart make
   * more (random PSLGs: 18 a vertex, three growths by half, each copying the arrays). */
  qk_status_t st = QK_OK;
  if (qk__gm_reserve(g, g->npts)) st = qk__mesh_fail(g->err, QK_ERR_NOMEM, 0, "out of memory");
  for (size_t i = 0; i < g->npts && !st; i++) {
    const qk__gm_pt_t *q = &g->pts[i];
    uint32_t t, v;
    int k, existed;
    qk__cdt_where_t w;
    if (q->seg == QK__CDT_NONE) {
      /* Leaves share corners: a repeated seed follows its twin (equal keys stay in order). */
      if (i && q->key == q[-1].key && q->x == q[-1].x && q->y == q[-1].y) continue;
      w = qk__cdt_locate(c, q->x, q->y, hint, &t, &k);
      hint = t;
      if (w == QK__CDT_VERT || g->faces[g->face[t]].drop ||
          (w == QK__CDT_EDGE && c->seg[3 * t + k] != QK__CDT_NONE))
        continue;
      g->seeds++;
    } else {
      t = seg_edge(g, q, first, rv, &k);
      w = QK__CDT_EDGE;
      if (t == QK__CDT_NONE) /* cannot happen: the piece is an edge */
        w = qk__cdt_locate(c, q->x, q->y, hint, &t, &k);
    }
    st = qk__gm_insert(g, q->x, q->y, t, k, w, q->seg, q->k, &v, &existed);
    if (st) {
      st = qk__mesh_fail(g->err, st, 0, "out of memory");
    } else {
      if (q->seg != QK__CDT_NONE) rv[q->rank] = v;
      hint = c->vtri[v];
    }
  }
  qk__free(g->a, rv, (g->npts + 1) * sizeof *rv);
  return st;
}

/* Step 4, the grading, with its statistics (g->stats) and the leaves it adds to the work
 * cap's count. */
qk_status_t qk__gm_grade(qk__gm_t *g) {
  const qk_poly_t *P = g->P;
  qk_tree_options_t to;
  qk_tree_options_init(&to);
  to.has_root = 1;
  to.root = (qk_square_t){0, 0, 1};
  to.capacity = 1;
  to.allocator = g->a;
  to.max_depth = QK_MAX_DEPTH_LIMIT;
  qk_status_t st = qk_tree_build(NULL, 0, &to, &g->tree);
  if (st) return qk__mesh_fail(g->err, st, 0, "%s while building the tree", qk_strerror(st));
  size_t nf = P->nv + P->ns;
  /* Each feature's ends in one flat array: the subdivision tests every feature of a node
   * against each child's box, and reads them here without going through P->seg. */
  g->fbox = qk__realloc(g->a, NULL, 0, (nf + 1) * 8 * sizeof *g->fbox);
  if (!g->fbox) return qk__mesh_fail(g->err, QK_ERR_NOMEM, 0, "out of memory");
  for (size_t f = 0; f < nf; f++) {
    uint32_t u = f < P->nv ? (uint32_t)f : P->seg[2 * (f - P->nv)];
    uint32_t w = f < P->nv ? (uint32_t)f : P->seg[2 * (f - P->nv) + 1];
    double ax = P->vx[u], ay = P->vy[u], bx = P->vx[w], by = P->vy[w], *q = &g->fbox[8 * f];
    q[0] = ax < bx ? ax : bx, q[1] = ay < by ? ay : by;
    q[2] = ax < bx ? bx : ax, q[3] = ay < by ? by : ay;
    q[4] = ax, q[5] = ay, q[6] = bx, q[7] = by;
  }
  /* The grading makes about ten leaves a feature on coastlines: room for the nodes up
   * front, rather than the tree's growth by an eighth (53 copies on Iceland). */
  if (qk__tree_reserve(g->tree, (uint32_t)(nf < 0x8000000 ? 16 * nf + 64 : 0)))
    return qk__mesh_fail(g->err, QK_ERR_NOMEM, 0, "out of memory");
  void *ap = g->arena;
  if (qk__grow(g->a, &ap, &g->arena_cap, nf + 1, sizeof *g->arena))
    return qk__mesh_fail(g->err, QK_ERR_NOMEM, 0, "out of memory");
  g->arena = ap;
  /* Isolated vertices and segments are the features; a vertex on a segment is separated
   * from others through its segments (two segments that share no vertex, or share one
   * outside the box), except from the segments at its neighbours, which the refinement's
   * shells grade. */
  uint8_t *onseg = qk__realloc(g->a, NULL, 0, P->nv + 1);
  if (!onseg) return qk__mesh_fail(g->err, QK_ERR_NOMEM, 0, "out of memory");
  memset(onseg, 0, P->nv + 1);
  for (size_t j = 0; j < 2 * P->ns; j++) onseg[P->seg[j]] = 1;
  size_t k = 0;
  for (size_t i = 0; i < P->nv; i++)
    if (!onseg[i]) g->arena[k++] = (uint32_t)i;
  qk__free(g->a, onseg, P->nv + 1);
  for (size_t s = 0; s < P->ns; s++) g->arena[k++] = (uint32_t)(P->nv + s);
  nf = k;
  g->arena_n = nf;
  g->deep_cap = GM_DEEP_BUDGET + 256 * nf;
  g->sep_cap = GM_SEP_BUDGET + 256 * nf;
  double rlo[2], rhi[2];
  grown_box(g, 0, 0, 1, rlo, rhi);
  if ((st = subdivide(g, qk_tree_root(g->tree), 0, 0, 1, rlo, rhi, 0, 0, nf))) return st;
  /* The tree grew from its root by splits alone (four nodes each, three more leaves), so
   * its node count gives its leaves without a walk. */
  g->stats->leaves_before_balance = 1 + 3 * ((size_t)qk__tree_node_bound(g->tree) - 1) / 4;
  /* Balanced only for the seeds, whose corners must conform: without them nothing reads the
   * leaves (the pre-split and the refinement follow the size bound), and balancing was
   * 10-13% of the meshing on coastlines at extent/32, 7% on Norway at extent/256. */
  if (GM_SEED_LEAVES && (st = qk_tree_balance(g->tree)))
    return qk__mesh_fail(g->err, st, 0, "%s while balancing", qk_strerror(st));
  g->stats->leaves = 1 + 3 * ((size_t)qk__tree_node_bound(g->tree) - 1) / 4;
  /* Every leaf of the graded tree: the refinement's points near the features, which the
   * grading sized, and in the free leaves (with seeds, seeds() counts the seeds' leaves). */
  if (!GM_SEED_LEAVES) g->cap_leaves += g->stats->leaves;
  return QK_OK;
}

qk_status_t qk__gm_seed(qk__gm_t *g) {
  const qk_poly_t *P = g->P;
  g->inv_S = ldexp(1.0, -g->e);
  /* Each segment's precision budget, computed once when a split point first asks for it
   * (qk__gm_split_param): most of a coastline's segments are never split. */
  g->sbud = qk__realloc(g->a, NULL, 0, P->ns + 1);
  if (!g->sbud) return qk__mesh_fail(g->err, QK_ERR_NOMEM, 0, "out of memory");
  memset(g->sbud, QK__GM_SBUD_UNSET & 0xff, P->ns + 1);
  qk_status_t st = QK_OK;
  g->cap_leaves = size_cells(g);
  /* The grading waits for the refinement to need it (general_refine.c, at the work cap),
   * unless a size function splits its leaves (they size the cap then) or the seeds are on:
   * on coastlines most meshes end within the cap the input's size sets, and grading first
   * was a third of the meshing with no size bound on Norway (1,953 segments), a sixth at
   * 1/256 of its extent. */
  if (GM_SIZE_SPLITS(g) && (st = qk__gm_grade(g))) return st;
  if (GM_SEED_LEAVES && seeds(g, qk_tree_root(g->tree), 0, 0, 1, 0))
    return qk__mesh_fail(g->err, QK_ERR_NOMEM, 0, "out of memory");
  /* The split points of segment s get ranks first[s] .. first[s + 1] - 1 in parameter
   * order (presplit makes them in order; seeds, when enabled, come before them all). */
  uint32_t *first = qk__realloc(g->a, NULL, 0, (P->ns + 1) * sizeof *first);
  if (!first) return qk__mesh_fail(g->err, QK_ERR_NOMEM, 0, "out of memory");
  /* Without a size function a segment whose squared length is at most (1 - 2^-40) h^2 is
   * not split: hypot, within an ulp of a length below (1 - 2^-41) h, cannot exceed h, so
   * presplit's first test would say no (no bound, h infinite: none is split). The test
   * skips the hypot and the call for most of a coastline's segments. Beyond h^2 below
   * 2^-1000 the squares may underflow: the test is not made. */
  double skip2 = -1;
  if (!g->opt->size_fn) {
    double h = g->opt->max_size;
    skip2 = !(h > 0) ? INFINITY : h * h >= 0x1p-1000 ? h * h * (1 - 0x1p-40) : -1;
  }
  for (size_t s = 0; s < P->ns && !st; s++) {
    uint32_t u = P->seg[2 * s], w = P->seg[2 * s + 1];
    const double A[2] = {P->vx[u], P->vy[u]}, B[2] = {P->vx[w], P->vy[w]};
    const double dx = B[0] - A[0], dy = B[1] - A[1];
    first[s] = (uint32_t)g->npts;
    if (dx * dx + dy * dy <= skip2) continue;
    st = presplit(g, (uint32_t)s, A, B, hypot(dx, dy), 0, QK__GM_ONE, A, B);
  }
  if (!st) first[P->ns] = (uint32_t)g->npts;
  if (!st && g->npts) st = qk__gm_sort_points(g, g->pts, g->npts);
  if (st)
    st = qk__mesh_fail(g->err, QK_ERR_NOMEM, 0, "out of memory");
  else
    st = insert_points(g, first);
  qk__free(g->a, first, (P->ns + 1) * sizeof *first);
  return st;
}
