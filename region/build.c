/*
 * Building the index of a layer: the refinement and the per-leaf arrays (the design is
 * described at the top of region.c).
 */
#include <string.h>
#include <time.h>

#include "region/region_internal.h"

#define MAXD (QK_MAX_DEPTH_LIMIT + 1)

typedef struct bctx {
  qk_region_t *r;
  const qk__pieces_t *pc;
  const qk_region_arrays_t *in;
  uint32_t C, maxd;
  uint32_t *e[MAXD + 1]; /* per depth: the pieces meeting the current cell */
  size_t ne[MAXD + 1];
  uint32_t *store[MAXD + 1]; /* per depth: the four children's lists, one after another */
  size_t cap_store[MAXD + 1];
  size_t cnt[MAXD + 1][4];
  uint32_t *s[MAXD + 1]; /* per depth: features containing its reference point */
  size_t ns[MAXD + 1], cap_s[MAXD + 1];
  /* per depth: the features whose parity flips from the cell's reference point to each
   * child's, four lists of up to ne[d] + 1 (found while sorting the pieces) */
  uint32_t *odd[MAXD + 1];
  size_t cap_odd[MAXD + 1];
  size_t nodd[MAXD + 1][4];
  uint8_t *bad; /* per ring: self-intersecting */
  unsigned depth;
  size_t splits_left; /* a budget on splits: see build_node */
} bctx_t;

/* Do two closed segments meet (exactly)? */
static bool segs_meet(const qk__seg_t *p, const qk__seg_t *q) {
  if (qk__max(p->ax, p->bx) < qk__min(q->ax, q->bx) ||
      qk__max(q->ax, q->bx) < qk__min(p->ax, p->bx) ||
      qk__max(p->ay, p->by) < qk__min(q->ay, q->by) ||
      qk__max(q->ay, q->by) < qk__min(p->ay, p->by))
    return false; /* boxes apart: most pairs */
  int o1 = qk__orient(p->ax, p->ay, p->bx, p->by, q->ax, q->ay);
  int o2 = qk__orient(p->ax, p->ay, p->bx, p->by, q->bx, q->by);
  if (o1 * o2 > 0) return false;
  int o3 = qk__orient(q->ax, q->ay, q->bx, q->by, p->ax, p->ay);
  int o4 = qk__orient(q->ax, q->ay, q->bx, q->by, p->bx, p->by);
  if (o3 * o4 > 0) return false;
  if (o1 == 0 && o2 == 0)
    return qk__max(qk__min(p->ax, p->bx), qk__min(q->ax, q->bx)) <=
               qk__min(qk__max(p->ax, p->bx), qk__max(q->ax, q->bx)) &&
           qk__max(qk__min(p->ay, p->by), qk__min(q->ay, q->by)) <=
               qk__min(qk__max(p->ay, p->by), qk__max(q->ay, q->by));
  return true;
}

/* Flag the rings of a leaf's pieces that meet themselves away from a shared vertex. A
 * leaf's pieces come in increasing order (every list keeps the order of the pieces), and
 * a ring's pieces are consecutive, so the pieces of p's ring follow p. A
 * leaf holds few pieces except where pieces never separate (many through one point);
 * there the pairs are not checked, so that such input costs no quadratic time: the stat
 * is then a lower bound (documented). */
#define SELF_CHECK_MAX 256

static void self_meets(bctx_t *b, const uint32_t *E, size_t n) {
  const qk__pieces_t *pc = b->pc;
  if (n > SELF_CHECK_MAX) return;
  for (size_t i = 0; i < n; i++) {
    uint32_t p = E[i], rp = pc->ring[p], vp = pc->vtx[p];
    if (vp == UINT32_MAX || b->bad[rp]) continue;
    size_t rs = b->in->ring_start[rp], re = b->in->ring_start[rp + 1];
    for (size_t j = i + 1; j < n && pc->ring[E[j]] == rp; j++) {
      uint32_t q = E[j];
      if (pc->vtx[q] == UINT32_MAX) continue;
      uint32_t vq = pc->vtx[q];
      uint32_t lo = vp < vq ? vp : vq, hi = vp < vq ? vq : vp;
      if (hi - lo <= 1 || (lo == rs && hi == re - 2)) continue; /* same or neighbouring edges */
      if (segs_meet(&pc->seg[p], &pc->seg[q])) {
        b->bad[rp] = 1;
        break;
      }
    }
  }
}

static qk_status_t emit_leaf(bctx_t *b, qk_node_t v, double cx, double cy, unsigned d) {
  qk_region_t *r = b->r;
  const qk__pieces_t *pc = b->pc;
  size_t ne = b->ne[d], ns = b->ns[d];
  if (d > b->depth) b->depth = d;
  if (ne == 0 && ns <= 1) {
    r->kid[v] = QK__LEAF | QK__DIRECT | (ns ? b->s[d][0] + 1 : 0);
    r->n_direct++;
    return QK_OK;
  }
  if (r->n_leaves >= QK__DIRECT - 1) return QK_ERR_LIMIT;
  qk_status_t st = QK_OK;
  /* (qk__grow returns at once when there is room; the tests save the calls) */
  if ((r->n_leaves + 1 > r->cap_leaves &&
       (st = qk__grow(&r->alloc, (void **)&r->leaves, &r->cap_leaves, r->n_leaves + 1,
                      sizeof(qk__leaf_t)))) ||
      (r->n_le + ne > r->cap_le &&
       (st = qk__grow(&r->alloc, (void **)&r->le, &r->cap_le, r->n_le + ne, sizeof(uint32_t)))) ||
      (r->n_le + ne > r->cap_le_tag &&
       (st = qk__grow(&r->alloc, (void **)&r->le_tag, &r->cap_le_tag, r->n_le + ne,
                      sizeof(uint32_t)))) ||
      (r->n_sets + ns > r->cap_sets && (st = qk__grow(&r->alloc, (void **)&r->sets, &r->cap_sets,
                                                      r->n_sets + ns, sizeof(uint32_t)))))
    return st;
  if (r->n_le + ne > UINT32_MAX || r->n_sets + ns > UINT32_MAX) return QK_ERR_LIMIT;
  r->leaves[r->n_leaves] =
      (qk__leaf_t){(uint32_t)r->n_le, (uint32_t)ne, (uint32_t)r->n_sets, (uint32_t)ns};
  for (size_t i = 0; i < ne; i++) {
    uint32_t p = b->e[d][i];
    const qk__seg_t *g = &pc->seg[p];
    int side = qk__side(g->ax, g->ay, g->bx, g->by, cx, cy);
    r->le[r->n_le + i] = p;
    r->le_tag[r->n_le + i] =
        pc->feat[p] << 2 | (uint32_t)(pc->vtx[p] == UINT32_MAX) << 1 | (uint32_t)(side > 0);
  }
  if (ns) memcpy(r->sets + r->n_sets, b->s[d], ns * sizeof(uint32_t));
  r->n_le += ne;
  r->n_sets += ns;
  r->kid[v] = QK__LEAF | (uint32_t)r->n_leaves;
  r->n_leaves++;
  self_meets(b, b->e[d], ne);
  return QK_OK;
}

/* Sort the pieces of level d into the four children's lists (a piece may go to several).
 * A child keeps a piece whose box meets its square and, unless the box lies inside the
 * square, whose line has corners of the square on both sides or within a tolerance. That
 * is conservative: it may keep a piece that misses the closed square, never drops one that
 * meets it (an extra piece costs time, not correctness). The line's value at the children's corners
 * is its value at the centre plus multiples of dx h and dy h (h = half the side), so one evaluation
 * serves the four children; the tolerance covers the rounding of that sum and of the
 * corners themselves (x0 + h is not exactly the middle).
 * Returns whether the split makes progress: every child meets fewer pieces than the cell.
 * Pieces that all pass one point (a vertex of high degree) or overlap (shared edges)
 * never separate, and such cells would otherwise split down to the depth cap. */
/* The parities gathered while sorting a cell's pieces into its children: for child q,
 * the features crossed an odd number of times by the segment from the cell's reference
 * point to the child's (which lies in the child's closed square, so only the child's
 * pieces can cross it). A child's pieces come in feature order, so a feature is done when
 * the next one starts. */
typedef struct flips {
  const uint32_t *feat;
  uint32_t *odd; /* child q's list at odd + q * stride */
  size_t stride;
  double ox, oy, qx[4], qy[4]; /* the parent centre and the children's */
  uint32_t cur[4];
  bool par[4];
  size_t n[4];
  double lo_x[4], hi_x[4], lo_y[4], hi_y[4]; /* the box of each segment centre -> child's */
} flips_t;

static inline void flip(flips_t *fl, unsigned q, uint32_t p, const qk__seg_t *g, double lx,
                        double hx, double ly, double hy) {
  /* only pieces whose box meets the segment's can cross it */
  if (hx < fl->lo_x[q] || lx > fl->hi_x[q] || hy < fl->lo_y[q] || ly > fl->hi_y[q]) return;
  double qx = fl->qx[q], qy = fl->qy[q];
  uint32_t f = fl->feat[p];
  if (f != fl->cur[q]) {
    if (fl->par[q]) fl->odd[q * fl->stride + fl->n[q]++] = fl->cur[q];
    fl->cur[q] = f;
    fl->par[q] = false;
  }
  int sc = qk__side(g->ax, g->ay, g->bx, g->by, fl->ox, fl->oy);
  if (qk__crosses(fl->ox, fl->oy, qx, qy, g->ax, g->ay, g->bx, g->by, sc)) fl->par[q] = !fl->par[q];
}

static qk_status_t split_lists(bctx_t *b, unsigned d, double x0, double y0, double x1, double y1,
                               double cx, double cy, double half, bool *progress) {
  size_t n = b->ne[d];
  qk_status_t st = qk__grow(&b->r->alloc, (void **)&b->store[d + 1], &b->cap_store[d + 1],
                            4 * n + 1, sizeof(uint32_t));
  if (st) return st;
  if ((st = qk__grow(&b->r->alloc, (void **)&b->odd[d], &b->cap_odd[d], 4 * (n + 1),
                     sizeof(uint32_t))))
    return st;
  uint32_t *out = b->store[d + 1];
  size_t c0 = 0, c1 = 0, c2 = 0, c3 = 0;
  /* the children's reference points, exactly as build_node computes them */
  const double hh = half * 0.5;
  flips_t fl = {b->pc->feat,
                b->odd[d],
                n + 1,
                cx,
                cy,
                {cx + hh, x0 + hh, x0 + hh, cx + hh},
                {cy + hh, cy + hh, y0 + hh, y0 + hh},
                {UINT32_MAX, UINT32_MAX, UINT32_MAX, UINT32_MAX},
                {false, false, false, false},
                {0, 0, 0, 0},
                {0},
                {0},
                {0},
                {0}};
  for (unsigned q = 0; q < 4; q++) {
    fl.lo_x[q] = qk__min(cx, fl.qx[q]), fl.hi_x[q] = qk__max(cx, fl.qx[q]);
    fl.lo_y[q] = qk__min(cy, fl.qy[q]), fl.hi_y[q] = qk__max(cy, fl.qy[q]);
  }
  const double h = cx - x0;
  const qk__seg_t *seg = b->pc->seg;
  const uint32_t *E = b->e[d];
  for (size_t i = 0; i < n; i++) {
    uint32_t p = E[i];
    const qk__seg_t *g = &seg[p];
    double lx = qk__min(g->ax, g->bx), hx = qk__max(g->ax, g->bx);
    double ly = qk__min(g->ay, g->by), hy = qk__max(g->ay, g->by);
    /* Inside one child's square and off the centre lines (most pieces below the top
     * levels): that child only. NE 0, NW 1, SW 2, SE 3. */
    if ((lx > cx || hx < cx) && (ly > cy || hy < cy)) {
      bool east = lx > cx, north = ly > cy;
      if ((east ? hx <= x1 : lx >= x0) && (north ? hy <= y1 : ly >= y0)) {
        unsigned q = north ? (east ? 0u : 1u) : (east ? 3u : 2u);
        if (north)
          east ? (out[c0++] = p) : (out[n + c1++] = p);
        else
          east ? (out[3 * n + c3++] = p) : (out[2 * n + c2++] = p);
        flip(&fl, q, p, g, lx, hx, ly, hy);
        continue;
      }
    }
    bool e = hx >= cx, w = lx <= cx, no = hy >= cy, so = ly <= cy;
    double dx = g->bx - g->ax, dy = g->by - g->ay;
    double l = dx * (cy - g->ay), r = dy * (cx - g->ax);
    double v = l - r, a = dx * h, q = dy * h;
    double tol = 1e-12 * (fabs(l) + fabs(r) + fabs(a) + fabs(q) +
                          (fabs(dx) + fabs(dy)) * (fabs(cx) + fabs(cy)));
    /* the line's value over each child's corners: v + dx * [0 or +-h] - dy * [0 or +-h] */
    double ap = qk__max(a, 0), an = qk__min(a, 0), qp = qk__max(q, 0), qn = qk__min(q, 0);
    if (e && no && v + an - qp <= tol && v + ap - qn >= -tol)
      out[c0++] = p, flip(&fl, 0, p, g, lx, hx, ly, hy);
    if (w && no && v + an + qn <= tol && v + ap + qp >= -tol)
      out[n + c1++] = p, flip(&fl, 1, p, g, lx, hx, ly, hy);
    if (w && so && v - ap + qn <= tol && v - an + qp >= -tol)
      out[2 * n + c2++] = p, flip(&fl, 2, p, g, lx, hx, ly, hy);
    if (e && so && v - ap - qp <= tol && v - an - qn >= -tol)
      out[3 * n + c3++] = p, flip(&fl, 3, p, g, lx, hx, ly, hy);
  }
  for (unsigned q = 0; q < 4; q++) {
    if (fl.par[q]) fl.odd[q * fl.stride + fl.n[q]++] = fl.cur[q];
    b->nodd[d][q] = fl.n[q];
  }
  size_t *cnt = b->cnt[d + 1];
  cnt[0] = c0, cnt[1] = c1, cnt[2] = c2, cnt[3] = c3;
  *progress = c0 < n && c1 < n && c2 < n && c3 < n;
  return QK_OK;
}

/* The set of child q: the parent's set (level d) with the features of the child's flip
 * list toggled (a symmetric difference of two sorted lists), at level d + 1. */
static qk_status_t child_set(bctx_t *b, unsigned d, unsigned q) {
  const qk_allocator_t *a = &b->r->alloc;
  size_t ns = b->ns[d], nodd = b->nodd[d][q];
  const uint32_t *odd = b->odd[d] + q * (b->ne[d] + 1);
  qk_status_t st;
  if ((st = qk__grow(a, (void **)&b->s[d + 1], &b->cap_s[d + 1], ns + nodd + 1, sizeof(uint32_t))))
    return st;
  const uint32_t *S = b->s[d];
  uint32_t *T = b->s[d + 1];
  size_t i = 0, j = 0, k = 0;
  while (i < ns || j < nodd) {
    if (j == nodd || (i < ns && S[i] < odd[j]))
      T[k++] = S[i++];
    else if (i == ns || odd[j] < S[i])
      T[k++] = odd[j++];
    else
      i++, j++;
  }
  b->ns[d + 1] = k;
  return QK_OK;
}

/* Splits that make no progress are allowed this many levels in a row (a cluster in one
 * quadrant separates after a few). */
#define STALL_BUDGET 2

static qk_status_t build_node(bctx_t *b, qk_node_t v, double x0, double y0, double x1, double y1,
                              double side, unsigned d, unsigned stall) {
  qk_region_t *r = b->r;
  double h = side * 0.5, cx = x0 + h, cy = y0 + h;
  qk_status_t st;
  bool split = false;
  /* The budget bounds the work on adversarial input (thousands of long edges fanning out
   * of one point need a number of cells far beyond the edges to separate them); when it
   * runs out the remaining cells stay leaves with more pieces. Real layers stay far
   * below it. */
  if (b->ne[d] > b->C && d < b->maxd && b->splits_left > 0) {
    bool prog;
    if ((st = split_lists(b, d, x0, y0, x1, y1, cx, cy, h, &prog))) return st;
    stall = prog ? 0 : stall + 1;
    split = stall <= STALL_BUDGET;
  }
  if (split) {
    /* With the tree kept, its split names the children; without, they take the next four
     * slots of kid[] (the same cells, numbered without the tree's bookkeeping). */
    uint32_t first = 0;
    if (r->tree) {
      st = qk_tree_split_leaf(r->tree, v);
      if (st == QK_OK) first = qk__node_child(r->tree, v);
    } else {
      st = r->n_kid + 4 < QK__DIRECT ? QK_OK : QK_ERR_LIMIT;
      first = (uint32_t)r->n_kid;
    }
    if (st == QK_OK) {
      b->splits_left--;
      if ((st = qk__grow(&r->alloc, (void **)&r->kid, &r->cap_kid,
                         r->tree ? qk__tree_node_bound(r->tree) : r->n_kid + 4, sizeof(uint32_t))))
        return st;
      r->kid[v] = first;
      if (first + 4 > r->n_kid) r->n_kid = first + 4;
      size_t n = b->ne[d];
      for (unsigned q = 0; q < 4; q++) {
        int east = (int)qk__q_east(q), north = (int)qk__q_north(q);
        double qx0 = east ? cx : x0, qx1 = east ? x1 : cx;
        double qy0 = north ? cy : y0, qy1 = north ? y1 : cy;
        b->e[d + 1] = b->store[d + 1] + q * n;
        b->ne[d + 1] = b->cnt[d + 1][q];
        if ((st = child_set(b, d, q))) return st;
        if ((st = build_node(b, first + q, qx0, qy0, qx1, qy1, h, d + 1, stall))) return st;
      }
      return QK_OK;
    }
    if (st != QK_ERR_LIMIT) return st;
  }
  return emit_leaf(b, v, cx, cy, d);
}

/* The root's set: the half-open ray from its reference point, against every piece. */
static qk_status_t root_set(bctx_t *b, double cx, double cy) {
  const qk__pieces_t *pc = b->pc;
  size_t n = pc->n, k = 0;
  qk_status_t st = qk__grow(&b->r->alloc, (void **)&b->s[0], &b->cap_s[0], n + 1, sizeof(uint32_t));
  if (st) return st;
  bool par = false;
  for (size_t i = 0; i < n; i++) {
    const qk__seg_t *g = &pc->seg[i];
    if ((g->ay > cy) != (g->by > cy)) {
      int s = qk__side(g->ax, g->ay, g->bx, g->by, cx, cy);
      if ((g->by > g->ay) ? s > 0 : s < 0) par = !par;
    }
    if (i + 1 == n || pc->feat[i + 1] != pc->feat[i]) {
      if (par) b->s[0][k++] = pc->feat[i];
      par = false;
    }
  }
  b->ns[0] = k;
  return QK_OK;
}

static qk_status_t root_square(const qk__pieces_t *pc, qk_region_t *r, qk_error_t *err) {
  double x0 = INFINITY, y0 = INFINITY, x1 = -INFINITY, y1 = -INFINITY;
  for (size_t i = 0; i < pc->n; i++) {
    const qk__seg_t *g = &pc->seg[i];
    x0 = qk__min(x0, qk__min(g->ax, g->bx));
    x1 = qk__max(x1, qk__max(g->ax, g->bx));
    y0 = qk__min(y0, qk__min(g->ay, g->by));
    y1 = qk__max(y1, qk__max(g->ay, g->by));
  }
  if (!pc->n) {
    r->stats.box = (qk_box_t){0, 0, 0, 0};
    r->rx = r->ry = -0.5;
    r->rside = 1;
    return QK_OK;
  }
  r->stats.box = (qk_box_t){x0, y0, x1, y1};
  double w = x1 - x0, h = y1 - y0, ext = qk__max(w, h);
  if (ext < 1e-60)
    return qk__region_fail(err, QK_ERR_GEOMETRY, SIZE_MAX, "layer extent %g is too small", ext);
  /* The root strictly contains every piece, so a point outside it is outside all. */
  double side = ext * 1.125;
  for (;;) {
    double rx = x0 - (side - w) * 0.5, ry = y0 - (side - h) * 0.5;
    if (rx < x0 && ry < y0 && rx + side > x1 && ry + side > y1) {
      r->rx = rx;
      r->ry = ry;
      r->rside = side;
      return QK_OK;
    }
    side *= 1.0625;
  }
}

/* The query window (region_internal.h): inside the root square, and in lon/lat mode inside
 * [-180, 180) x [-90, 90], so that normalising such a point changes nothing. The bounds are
 * doubles a query compares with directly: x < rx + rside is x <= the double below it. */
static void query_window(qk_region_t *r) {
  double x0 = r->rx, x1 = nextafter(r->rx + r->rside, -INFINITY);
  double y0 = r->ry, y1 = nextafter(r->ry + r->rside, -INFINITY);
  if (!r->planar) {
    x0 = qk__max(x0, -180.0);
    x1 = qk__min(x1, nextafter(180.0, 0.0));
    y0 = qk__max(y0, -90.0);
    y1 = qk__min(y1, 90.0);
  }
  r->qx0 = x0, r->qx1 = x1, r->qy0 = y0, r->qy1 = y1;
}

static double now(void) {
  struct timespec ts;
  if (!timespec_get(&ts, TIME_UTC)) return 0;
  return (double)ts.tv_sec + 1e-9 * (double)ts.tv_nsec;
}

/* The cells' lower sides at depth G along one axis, as the descent computes them. */
static void grid_sides(double r0, double side, unsigned G, double *out) {
  size_t g = (size_t)1 << G;
  for (size_t i = 0; i < g; i++) {
    double s = r0, h = side;
    for (unsigned l = 0; l < G; l++) {
      h *= 0.5;
      if (i >> (G - 1 - l) & 1) s = s + h;
    }
    out[i] = s;
  }
  out[g] = INFINITY;
}

/* The grid shortcut (see region_internal.h): G grows while 4^G stays below twice the
 * leaves, up to 8 (256 KiB). */
static qk_status_t build_grid(qk_region_t *r, unsigned depth) {
  unsigned G = 0;
  while (G < 8 && G < depth && ((size_t)1 << (2 * (G + 1))) <= 2 * r->n_leaves) G++;
  if (G < 2) return QK_OK;
  size_t g = (size_t)1 << G;
  const qk_allocator_t *a = &r->alloc;
  uint32_t *grid = qk__realloc(a, NULL, 0, g * g * sizeof *grid);
  double *gx = qk__realloc(a, NULL, 0, (g + 1) * sizeof *gx);
  double *gy = qk__realloc(a, NULL, 0, (g + 1) * sizeof *gy);
  if (!grid || !gx || !gy) {
    qk__free(a, grid, g * g * sizeof *grid);
    qk__free(a, gx, (g + 1) * sizeof *gx);
    qk__free(a, gy, (g + 1) * sizeof *gy);
    return QK_ERR_NOMEM;
  }
  grid_sides(r->rx, r->rside, G, gx);
  grid_sides(r->ry, r->rside, G, gy);
  for (size_t j = 0; j < g; j++)
    for (size_t i = 0; i < g; i++) {
      uint32_t k = r->kid[0];
      unsigned l = 0;
      for (; l < G && !(k & QK__LEAF); l++) {
        unsigned east = i >> (G - 1 - l) & 1, north = j >> (G - 1 - l) & 1;
        unsigned q = north ? (east ? 0u : 1u) : (east ? 3u : 2u);
        k = r->kid[k + q];
      }
      /* A leaf above depth G with edges needs its own square (for its reference point),
       * not the grid cell's: such cells descend from the root. */
      if (l < G && !(k & QK__DIRECT)) k = QK__REDO;
      grid[j << G | i] = k;
    }
  r->grid = grid;
  r->gx = gx;
  r->gy = gy;
  r->grid_level = G;
  r->grid_scale = (double)g / r->rside;
  r->grid_side = r->rside;
  for (unsigned l = 0; l < G; l++) r->grid_side *= 0.5;
  return QK_OK;
}

/* Give back the room the doubling left (a failed shrink keeps the larger block). */
static void shrink(const qk_allocator_t *a, void **p, size_t *cap, size_t n, size_t elem) {
  if (!*p || n >= *cap) return;
  if (n == 0) n = 1;
  void *q = qk__realloc(a, *p, *cap * elem, n * elem);
  if (q) {
    *p = q;
    *cap = n;
  }
}

static void shrink_all(qk_region_t *r) {
  const qk_allocator_t *a = &r->alloc;
  shrink(a, (void **)&r->leaves, &r->cap_leaves, r->n_leaves, sizeof(qk__leaf_t));
  shrink(a, (void **)&r->le, &r->cap_le, r->n_le, sizeof(uint32_t));
  shrink(a, (void **)&r->le_tag, &r->cap_le_tag, r->n_le, sizeof(uint32_t));
  shrink(a, (void **)&r->sets, &r->cap_sets, r->n_sets, sizeof(uint32_t));
  shrink(a, (void **)&r->kid, &r->cap_kid, r->n_kid, sizeof(uint32_t));
  shrink(a, (void **)&r->segs, &r->cap_segs, r->n_segs, sizeof(qk__seg_t));
  shrink(a, (void **)&r->seg_feat, &r->cap_seg_feat, r->n_segs, sizeof(uint32_t));
}

static size_t layer_bytes(const qk_region_t *r) {
  return sizeof *r + r->cap_segs * sizeof(qk__seg_t) + r->cap_seg_feat * sizeof(uint32_t) +
         r->cap_kid * sizeof(uint32_t) + r->cap_leaves * sizeof(qk__leaf_t) +
         r->cap_le * sizeof(uint32_t) + r->cap_le_tag * sizeof(uint32_t) +
         r->cap_sets * sizeof(uint32_t) + qk_tree_memory(r->tree) + r->props.pool_cap +
         (r->grid_level ? ((size_t)4 << (2 * r->grid_level)) +
                              (((size_t)2 << r->grid_level) + 2) * sizeof(double)
                        : 0) +
         (r->props.cap_start + r->props.cap_key + r->props.cap_val) * sizeof(size_t);
}

qk_status_t qk__region_build(const qk_region_arrays_t *in, const qk_region_options_t *options,
                             qk__props_t *props, size_t skipped, size_t holes, qk_region_t **out,
                             qk_error_t *err) {
  qk_region_options_t o;
  qk_allocator_t alloc;
  qk__region_options(options, &o, &alloc);
  qk__props_t pr = {0};
  if (props) {
    pr = *props;
    memset(props, 0, sizeof *props);
  }
  if (err) {
    err->line = err->column = 0;
    err->item = SIZE_MAX;
    err->message[0] = '\0';
  }
  if (out) *out = NULL;
  qk_status_t st = QK_OK;
  if (!out) st = qk__region_fail(err, QK_ERR_INVALID, SIZE_MAX, "no output");
  if (o.leaf_edges == 0) o.leaf_edges = QK_REGION_DEFAULT_LEAF_EDGES;
  if (o.max_depth == 0) o.max_depth = QK_REGION_DEFAULT_MAX_DEPTH;
  if (!st && o.max_depth > QK_MAX_DEPTH_LIMIT)
    st = qk__region_fail(err, QK_ERR_INVALID, SIZE_MAX, "max_depth %u exceeds %d", o.max_depth,
                         QK_MAX_DEPTH_LIMIT);
  if (st) {
    qk__props_free(&alloc, &pr);
    return st;
  }
  double t0 = now();
  qk__pieces_t pc;
  if ((st = qk__region_prepare(&alloc, in, o.planar, &pc, err))) {
    qk__props_free(&alloc, &pr);
    return st;
  }
  bctx_t b;
  memset(&b, 0, sizeof b);
  qk_region_t *r = qk__realloc(&alloc, NULL, 0, sizeof *r);
  if (!r) {
    qk__pieces_free(&alloc, &pc);
    qk__props_free(&alloc, &pr);
    return qk__region_fail(err, QK_ERR_NOMEM, SIZE_MAX, "out of memory");
  }
  memset(r, 0, sizeof *r);
  r->alloc = alloc;
  r->planar = o.planar;
  r->n_features = (uint32_t)in->n_features;
  r->props = pr;
  b.r = r;
  b.pc = &pc;
  b.in = in;
  b.C = o.leaf_edges;
  b.maxd = o.max_depth;
  b.splits_left = pc.n + 4096;
  if ((st = root_square(&pc, r, err))) goto done;
  query_window(r);
  if (o.keep_tree) { /* the refinement is made on a quadkit tree, kept for qk_region_tree */
    qk_tree_options_t to;
    qk_tree_options_init(&to);
    to.has_root = 1;
    to.root = (qk_square_t){r->rx, r->ry, r->rside};
    to.max_depth = o.max_depth;
    to.allocator = &r->alloc;
    if ((st = qk_tree_build(NULL, 0, &to, &r->tree))) goto done;
  }
  /* The arrays at once at about their final size (measured on Natural Earth layers: the
   * nodes, the leaf pieces about 1.5 per piece, the leaves with pieces a third), so that
   * they are seldom copied while they grow; shrink_all gives back the rest. */
  {
    size_t pn = pc.n + 16;
    if ((st = qk__grow(&alloc, (void **)&r->kid, &r->cap_kid, pn, sizeof(uint32_t))) ||
        (st = qk__grow(&alloc, (void **)&r->le, &r->cap_le, pn + pn / 2, sizeof(uint32_t))) ||
        (st = qk__grow(&alloc, (void **)&r->le_tag, &r->cap_le_tag, pn + pn / 2,
                       sizeof(uint32_t))) ||
        (st = qk__grow(&alloc, (void **)&r->leaves, &r->cap_leaves, pn / 2, sizeof(qk__leaf_t))) ||
        (st = qk__grow(&alloc, (void **)&r->sets, &r->cap_sets, pn / 2, sizeof(uint32_t))))
      goto done;
  }
  r->n_kid = 1;
  b.bad = qk__realloc(&alloc, NULL, 0, in->n_rings + 1);
  if (!b.bad) {
    st = QK_ERR_NOMEM;
    goto done;
  }
  memset(b.bad, 0, in->n_rings + 1);
  if ((st = qk__grow(&alloc, (void **)&b.store[0], &b.cap_store[0], pc.n + 1, sizeof(uint32_t))))
    goto done;
  b.e[0] = b.store[0];
  for (size_t i = 0; i < pc.n; i++) b.e[0][i] = (uint32_t)i;
  b.ne[0] = pc.n;
  double h = r->rside * 0.5;
  if ((st = root_set(&b, r->rx + h, r->ry + h))) goto done;
  st = build_node(&b, 0, r->rx, r->ry, r->rx + r->rside, r->ry + r->rside, r->rside, 0, 0);
  if (!st) st = build_grid(r, b.depth);

done:
  for (int d = 0; d <= MAXD; d++) {
    qk__free(&alloc, b.store[d], b.cap_store[d] * sizeof(uint32_t));
    qk__free(&alloc, b.s[d], b.cap_s[d] * sizeof(uint32_t));
    qk__free(&alloc, b.odd[d], b.cap_odd[d] * sizeof(uint32_t));
  }
  size_t bad = 0;
  if (b.bad) {
    for (size_t i = 0; i < in->n_rings; i++) bad += b.bad[i];
    qk__free(&alloc, b.bad, in->n_rings + 1);
  }
  qk__free(&alloc, pc.ring, pc.cap * sizeof(uint32_t));
  qk__free(&alloc, pc.vtx, pc.cap * sizeof(uint32_t));
  r->segs = pc.seg;
  r->seg_feat = pc.feat;
  r->n_segs = pc.n;
  r->cap_segs = r->cap_seg_feat = pc.cap;
  if (st) {
    qk_region_free(r);
    if (err && !err->message[0])
      qk__region_fail(err, st, SIZE_MAX, "%s while building the index", qk_strerror(st));
    return st;
  }
  qk_region_stats_t *s = &r->stats;
  s->features = in->n_features;
  s->rings = in->n_rings;
  s->vertices = in->n_rings ? in->ring_start[in->n_rings] : 0;
  if (holes == SIZE_MAX) {
    holes = 0;
    for (size_t f = 0; f < in->n_features; f++) {
      size_t k = in->feature_start[f + 1] - in->feature_start[f];
      holes += k ? k - 1 : 0;
    }
  }
  s->holes = holes;
  s->self_intersecting = bad;
  s->skipped = skipped;
  s->edges = pc.n;
  s->leaves = r->n_leaves + r->n_direct;
  s->leaf_edges = r->n_le;
  s->depth = b.depth;
  s->planar = r->planar;
  shrink_all(r);
  s->build_seconds = now() - t0;
  s->bytes = layer_bytes(r);
  *out = r;
  return QK_OK;
}
