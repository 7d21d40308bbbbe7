/*
 * Step 1 of the book's mesh generation (de Berg et al., ch. 14.3): split the domain
 * square while a square larger than unit size has a component boundary meeting its
 * closure. The unit squares reached also check the edges for crossings and touchings.
 */
#include "mesh/mesh_internal.h"

#include <math.h>
#include <stdlib.h>
#include <string.h>

static int sgn(int64_t v) { return (v > 0) - (v < 0); }

/* Orientation of c relative to the line a->b. */
static int orient(int64_t ax, int64_t ay, int64_t bx, int64_t by, int64_t cx, int64_t cy) {
  return sgn(qk__cross(bx - ax, by - ay, cx - ax, cy - ay));
}

/* Is c, collinear with a and b, within their bounding box? */
static int within(int64_t ax, int64_t ay, int64_t bx, int64_t by, int64_t cx, int64_t cy) {
  return cx >= (ax < bx ? ax : bx) && cx <= (ax > bx ? ax : bx) && cy >= (ay < by ? ay : by) &&
         cy <= (ay > by ? ay : by);
}

/* Do the closed segments of two edges meet? */
static int edges_meet(const qk__edge_t *p, const qk__edge_t *q) {
  int o1 = orient(p->ax, p->ay, p->bx, p->by, q->ax, q->ay);
  int o2 = orient(p->ax, p->ay, p->bx, p->by, q->bx, q->by);
  int o3 = orient(q->ax, q->ay, q->bx, q->by, p->ax, p->ay);
  int o4 = orient(q->ax, q->ay, q->bx, q->by, p->bx, p->by);
  if (o1 * o2 < 0 && o3 * o4 < 0) return 1;
  if (o1 == 0 && within(p->ax, p->ay, p->bx, p->by, q->ax, q->ay)) return 1;
  if (o2 == 0 && within(p->ax, p->ay, p->bx, p->by, q->bx, q->by)) return 1;
  if (o3 == 0 && within(q->ax, q->ay, q->bx, q->by, p->ax, p->ay)) return 1;
  if (o4 == 0 && within(q->ax, q->ay, q->bx, q->by, p->bx, p->by)) return 1;
  return 0;
}

/*
 * Are two edges a legal pair? They may meet only when consecutive on one component, at
 * their shared vertex, and without running back along each other.
 */
static int edges_legal(const qk__gen_t *g, const qk__edge_t *p, const qk__edge_t *q) {
  const uint32_t *sp = &g->poly->seg[2 * p->seg], *sq = &g->poly->seg[2 * q->seg];
  for (int i = 0; i < 2; i++)
    for (int j = 0; j < 2; j++)
      if (sp[i] == sq[j]) {
        /* Shared vertex v: they overlap iff the other ends lie in the same direction. */
        const double *vx = g->poly->vx, *vy = g->poly->vy;
        int64_t x = (int64_t)vx[sp[i]], y = (int64_t)vy[sp[i]];
        int64_t ux = (int64_t)vx[sp[1 - i]] - x, uy = (int64_t)vy[sp[1 - i]] - y;
        int64_t wx = (int64_t)vx[sq[1 - j]] - x, wy = (int64_t)vy[sq[1 - j]] - y;
        return !(qk__cross(ux, uy, wx, wy) == 0 && ux * wx + uy * wy > 0);
      }
  return !edges_meet(p, q);
}

/* Does an end of edge e lie on edge f (lattice coordinates, exact)? */
static int end_on(const qk__edge_t *e, const qk__edge_t *f) {
  const int64_t ex[2] = {e->ax, e->bx}, ey[2] = {e->ay, e->by};
  for (int i = 0; i < 2; i++)
    if (qk__cross(f->bx - f->ax, f->by - f->ay, ex[i] - f->ax, ey[i] - f->ay) == 0 &&
        ex[i] >= (f->ax < f->bx ? f->ax : f->bx) && ex[i] <= (f->ax < f->bx ? f->bx : f->ax) &&
        ey[i] >= (f->ay < f->by ? f->ay : f->by) && ey[i] <= (f->ay < f->by ? f->by : f->ay))
      return 1;
  return 0;
}

static qk_status_t pair_error(qk__gen_t *g, const qk__edge_t *p, const qk__edge_t *q) {
  const qk_poly_t *P = g->poly;
  unsigned long lp = P->sline[p->seg], lq = P->sline[q->seg];
  /* (a touch, an end of one on the other, which the general mode takes: 3; a crossing: 2) */
  g->meet = end_on(p, q) || end_on(q, p) ? QK__MEET_TOUCH : QK__MEET_CROSS;
  if (p->comp == q->comp)
    return qk__mesh_fail(g->err, QK_ERR_GEOMETRY, lq,
                         "component %u intersects itself: segments %lu (line %lu) and %lu (line "
                         "%lu) meet",
                         p->comp, qk__mesh_num(P, p->seg), lp, qk__mesh_num(P, q->seg), lq);
  return qk__mesh_fail(g->err, QK_ERR_GEOMETRY, lq,
                       "components %u and %u touch or cross: segments %lu (line %lu) and %lu "
                       "(line %lu) meet",
                       p->comp, q->comp, qk__mesh_num(P, p->seg), lp, qk__mesh_num(P, q->seg), lq);
}

/* Does edge e, with bounding box b, meet the closed square [x0, x0+s] x [y0, y0+s]? */
static int edge_meets_square(const qk__edge_t *e, const qk__ebox_t *b, int64_t x0, int64_t y0,
                             int64_t s) {
  int64_t x1 = x0 + s, y1 = y0 + s;
  int64_t minx = b->minx, maxx = b->maxx, miny = b->miny, maxy = b->maxy;
  if (maxx < x0 || minx > x1 || maxy < y0 || miny > y1) return 0;
  if (e->ax == e->bx || e->ay == e->by) return 1;
  /* A diagonal: the y-range it covers over the shared x-range must meet [y0, y1]. */
  int64_t lo = minx > x0 ? minx : x0, hi = maxx < x1 ? maxx : x1, ylo, yhi;
  if ((e->bx - e->ax) == (e->by - e->ay)) {
    int64_t c = e->ay - e->ax;
    ylo = lo + c, yhi = hi + c;
  } else {
    int64_t c = e->ax + e->ay;
    ylo = c - hi, yhi = c - lo;
  }
  return yhi >= y0 && ylo <= y1;
}

/*
 * A unit leaf of the subdivision: check the edges meeting it pairwise (every crossing or
 * touching of two edges happens in the closure of some unit leaf, since any square whose
 * closure holds a boundary point is split down to unit size), and record which of its
 * sides and diagonals are component edges.
 *
 * Every edge meeting a closed unit square contains one of its corners (edges lie on
 * lattice lines), and a legal corner lies on at most two edges, so at most 8 edges meet a
 * unit square in a valid input; checking the first 9 pairwise finds the fault otherwise.
 */
static qk_status_t unit_leaf(qk__gen_t *g, uint32_t node, int64_t x0, int64_t y0, size_t off,
                             size_t k) {
  const uint32_t *L = g->arena + off;
  size_t m = k < 9 ? k : 9;
  for (size_t i = 0; i < m; i++)
    for (size_t j = i + 1; j < m; j++)
      if (!edges_legal(g, &g->e[L[i]], &g->e[L[j]])) return pair_error(g, &g->e[L[i]], &g->e[L[j]]);
  if (k > 8)
    return qk__mesh_fail(g->err, QK_ERR_GEOMETRY, g->poly->sline[g->e[L[0]].seg],
                         "too many segments meet the unit square at (%lld, %lld)", (long long)x0,
                         (long long)y0);
  void *rp = g->rec;
  if (g->nrec >= g->rec_cap && qk__grow(g->a, &rp, &g->rec_cap, g->nrec + 1, sizeof *g->rec))
    return qk__mesh_fail(g->err, QK_ERR_NOMEM, 0, "out of memory");
  g->rec = rp;
  qk__unit_rec_t *r = &g->rec[g->nrec++];
  memset(r, 0, sizeof *r);
  r->node = node;
  r->nedge = (uint32_t)k;
  for (size_t i = 0; i < k; i++) r->edge[i] = L[i];
  for (size_t i = 0; i < k; i++) {
    const qk__edge_t *e = &g->e[L[i]];
    int64_t minx = e->ax < e->bx ? e->ax : e->bx, maxx = e->ax < e->bx ? e->bx : e->ax;
    int64_t miny = e->ay < e->by ? e->ay : e->by, maxy = e->ay < e->by ? e->by : e->ay;
    int32_t c = (int32_t)e->comp;
    if (e->ay == e->by) { /* horizontal: the south or north side, if it spans it */
      if (minx <= x0 && maxx >= x0 + 1) {
        int32_t v = e->bx > e->ax ? c : -c;
        if (e->ay == y0) r->piece[QK__P_S] = v;
        if (e->ay == y0 + 1) r->piece[QK__P_N] = v;
      }
    } else if (e->ax == e->bx) { /* vertical: the west or east side */
      if (miny <= y0 && maxy >= y0 + 1) {
        int32_t v = e->by > e->ay ? c : -c;
        if (e->ax == x0) r->piece[QK__P_W] = v;
        if (e->ax == x0 + 1) r->piece[QK__P_E] = v;
      }
    } else if (minx <= x0 && maxx >= x0 + 1) {
      if ((e->bx - e->ax) == (e->by - e->ay)) {
        if (e->ay - e->ax == y0 - x0) r->piece[QK__P_D0] = e->bx > e->ax ? c : -c;
      } else if (e->ax + e->ay == x0 + y0 + 1) {
        r->piece[QK__P_D1] = e->bx < e->ax ? c : -c;
      }
    }
  }
  return QK_OK;
}

/*
 * Step 1, subdivision: split a square while it is larger than unit size and its closure
 * meets the boundary of some component (touching at a single point counts). Each square
 * receives the list of edges meeting its closure, taken from its parent's list, so the
 * work is proportional to the output rather than to squares times edges.
 */
qk_status_t qk__mesh_subdivide(qk__gen_t *g, uint32_t node, int64_t x0, int64_t y0, int64_t s,
                               size_t off, size_t k) {
  if (k == 0) return QK_OK;
  if (s == 1) return unit_leaf(g, node, x0, y0, off, k);
  /* The tree's root square is (0, 0, U), U a power of two: the node's depth is the number
   * of halvings from U to s, and its corner is (x0, y0) exactly. */
  unsigned depth = (unsigned)(__builtin_ctzll(g->U) - __builtin_ctzll((uint64_t)s));
  qk_status_t st = qk__tree_split_leaf_at(g->tree, node, (double)x0, (double)y0, depth);
  if (st != QK_OK) return qk__mesh_fail(g->err, st, 0, "%s while subdividing", qk_strerror(st));
  g->nsplit++;
  uint32_t child = qk__node_child(g->tree, node);
  int64_t h = s / 2;
  for (unsigned q = 0; q < 4; q++) {
    int64_t cx = x0 + (qk__q_east(q) ? h : 0), cy = y0 + (qk__q_north(q) ? h : 0);
    void *ap = g->arena;
    if (g->arena_n + k > g->arena_cap &&
        qk__grow(g->a, &ap, &g->arena_cap, g->arena_n + k, sizeof *g->arena))
      return qk__mesh_fail(g->err, QK_ERR_NOMEM, 0, "out of memory");
    g->arena = ap;
    size_t base = g->arena_n, n = 0;
    for (size_t i = 0; i < k; i++) {
      uint32_t ei = g->arena[off + i];
      if (edge_meets_square(&g->e[ei], &g->box[ei], cx, cy, h)) g->arena[base + n++] = ei;
    }
    if (!n) continue; /* a child no edge meets stays a leaf: no call */
    g->arena_n = base + n;
    st = qk__mesh_subdivide(g, child + q, cx, cy, h, base, n);
    g->arena_n = base;
    if (st != QK_OK) return st;
  }
  return QK_OK;
}

int qk__mesh_rec_cmp(const void *a, const void *b) {
  uint32_t x = ((const qk__unit_rec_t *)a)->node, y = ((const qk__unit_rec_t *)b)->node;
  return (x > y) - (x < y);
}
