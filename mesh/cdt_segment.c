/*
 * Constrained edges and straight walks in the triangulation of mesh/cdt.h.
 *
 * Segment insertion (qk__cdt_insert_segment) first traces ab from a, triangle by triangle,
 * recording the triangles it crosses and refusing (before any change) a vertex on ab or a
 * constrained edge across it. The crossed triangles form a cavity that ab cuts into two
 * pseudo-polygons; each is retriangulated by its constrained Delaunay triangulation in the
 * cavity's triangle slots (same count: k crossed edges, k + 1 triangles either way), and
 * the result is the constrained Delaunay triangulation with ab (outside the cavity nothing
 * changes: Shewchuk and Brown, "Fast segment insertion and incremental construction of
 * constrained Delaunay triangulations", 2015, give the theorem). No flip order to prove
 * terminating, and the work is bounded by the cavity's size squared (linear in practice).
 */
#include "mesh/cdt_internal.h"
#ifdef CDT_DEBUG
#include <stdio.h>
#endif

#define NONE QK__CDT_NONE

static inline const double *pt(const qk__cdt_t *c, uint32_t v) { return c->xy + 2 * (size_t)v; }

/* For p collinear with a and b (a != b): whether p lies on the ray from a through b beyond
 * a (p != a), and where along it: -1 before b, 0 at b, 1 beyond b. Exact comparisons of
 * coordinates along an axis on which a and b differ. */
static int along(const double *a, const double *b, const double *p, int *pos) {
  int ax = a[0] != b[0] ? 0 : 1;
  double dir = b[ax] - a[ax];
  if (p[ax] == a[ax]) return 0;
  if ((p[ax] > a[ax]) != (dir > 0)) return 0;
  *pos = p[ax] == b[ax] ? 0 : ((p[ax] < b[ax]) == (dir > 0) ? -1 : 1);
  return 1;
}

/* Set the segment id of edge k of t on both its sides. */
static void mark(qk__cdt_t *c, uint32_t t, int k, uint32_t seg) {
  c->seg[3 * (size_t)t + k] = seg;
  if (c->on_change) c->on_change(c->user, t);
  uint32_t n = c->nbr[3 * (size_t)t + k];
  if (n == NONE) return;
  const uint32_t *nn = c->nbr + 3 * (size_t)n;
  int j = nn[0] == t ? 0 : nn[1] == t ? 1 : 2;
  c->seg[3 * (size_t)n + j] = seg;
  if (c->on_change) c->on_change(c->user, n);
}

/* Trace ab from a through the triangles it crosses, T_0 (at a) .. T_k (at b). Each gets a
 * record of REC words in c->scr: its id, the slot of its edge on the left chain (the
 * region's boundary left of a -> b; 3 if none), the same on the right, its vertex opposite
 * the edge it was entered by (NONE for T_0), and the left and right ends of the edge it is
 * left by (NONE for T_k). Returns k + 1, or -1 with *st set (NOMEM, or GEOMETRY with
 * *block and *block_seg). Changes nothing but the scratch. */
#define REC 6
static long trace(qk__cdt_t *c, uint32_t a, uint32_t b, qk_status_t *st, uint32_t *block,
                  uint32_t *block_seg) {
  const double *pa = pt(c, a), *pb = pt(c, b);
  qk__cdt_ring_t r = {a, NONE, NONE, 1};
  uint32_t t = NONE;
  int i = 0;
  for (uint32_t u = qk__cdt_ring_next(c, &r); u != NONE; u = qk__cdt_ring_next(c, &r)) {
    i = qk__cdt_slot(c, u, a);
    uint32_t x = c->v[3 * (size_t)u + (i + 1) % 3], y = c->v[3 * (size_t)u + (i + 2) % 3];
    int sx = qk__cdt_orient(pa, pb, pt(c, x)), pos;
    if (sx == 0 && along(pa, pb, pt(c, x), &pos)) {
      *block = x; /* x == b would be the edge ab, handled by the caller */
      *st = QK_ERR_GEOMETRY;
      return -1;
    }
    if (sx < 0 && qk__cdt_orient(pa, pb, pt(c, y)) > 0) {
      t = u;
      break;
    }
  }
  if (t == NONE) { /* cannot happen in a valid triangulation */
    *block = a;
    *st = QK_ERR_GEOMETRY;
    return -1;
  }
  /* T_0 = (a, x, y): the edge opposite a crosses ab, y is left and x right of a -> b. */
  long n = 0;
  uint32_t left = c->v[3 * (size_t)t + (i + 2) % 3], right = c->v[3 * (size_t)t + (i + 1) % 3];
  uint32_t ls = (uint32_t)(i + 1) % 3, rs = (uint32_t)(i + 2) % 3, apex = NONE;
  int k = i;
  for (;;) {
    if (qk__cdt_reserve_scratch(c, REC * ((size_t)n + 1)) != QK_OK) {
      *st = QK_ERR_NOMEM;
      return -1;
    }
    uint32_t *rec = c->scr + REC * n;
    rec[0] = t, rec[1] = ls, rec[2] = rs, rec[3] = apex, rec[4] = left, rec[5] = right;
    n++;
    if (k < 0) return n;
    uint32_t s = c->seg[3 * (size_t)t + k];
    if (s != NONE) {
      *block = left, *block_seg = s;
      *st = QK_ERR_GEOMETRY;
      return -1;
    }
    uint32_t nt = c->nbr[3 * (size_t)t + k];
    const uint32_t *nn = c->nbr + 3 * (size_t)nt;
    int j = nn[0] == t ? 0 : nn[1] == t ? 1 : 2;
    t = nt;
    /* t = (o, l, r) from slot j, entered through l -> r: its left chain edge is o-l (slot
     * j + 2), its right one r-o (slot j + 1) */
    uint32_t o = c->v[3 * (size_t)t + j];
    apex = o;
    if (o == b) {
      ls = (uint32_t)(j + 2) % 3, rs = (uint32_t)(j + 1) % 3;
      left = right = NONE, k = -1;
      continue;
    }
    int so = qk__cdt_orient(pa, pb, pt(c, o));
    if (so == 0) {
      *block = o;
      *st = QK_ERR_GEOMETRY;
      return -1;
    }
    if (so > 0) /* o is left: leave through r-o */
      left = o, k = (j + 1) % 3, ls = (uint32_t)(j + 2) % 3, rs = 3;
    else /* o is right: leave through o-l */
      right = o, k = (j + 2) % 3, ls = 3, rs = (uint32_t)(j + 1) % 3;
  }
}

/* Whether triangle t is among the sorted ids sp[0..n). */
static int in_pool(const uint32_t *sp, long n, uint32_t t) {
  long lo = 0, hi = n;
  while (lo < hi) {
    long mid = (lo + hi) / 2;
    if (sp[mid] < t)
      lo = mid + 1;
    else
      hi = mid;
  }
  return lo < n && sp[lo] == t;
}

static void sort_ids(uint32_t *x, long n) {
  for (long gap = n / 2; gap > 0; gap /= 2)
    for (long i = gap; i < n; i++) {
      uint32_t v = x[i];
      long j = i;
      for (; j >= gap && x[j - gap] > v; j -= gap) x[j] = x[j - gap];
      x[j] = v;
    }
}

/*
 * The fallback for cavities whose boundary touches itself (an edge inside the cavity with
 * both ends on one side of ab, so a vertex appears twice on a chain): remove the crossing
 * edges by flips (Sloan, "A fast algorithm for generating constrained Delaunay
 * triangulations", 1993: an edge whose quad is strictly convex is flipped, and its
 * replacement queued again while it still crosses ab), mark ab, then flip the cavity's
 * unconstrained edges by the in-circle test until none changes (Lawson). Flips keep the
 * cavity's triangle ids (sorted in sp), so both passes stay inside it.
 */
static void insert_by_flips(qk__cdt_t *c, uint32_t a, uint32_t b, uint32_t seg, const uint32_t *rec,
                            long nr, const uint32_t *sp, uint32_t *queue) {
  const double *pa = pt(c, a), *pb = pt(c, b);
  long nx = nr - 1, head = 0, count = nx;
  for (long m = 0; m < nx; m++)
    queue[2 * m] = rec[REC * m + 4], queue[2 * m + 1] = rec[REC * m + 5];
  while (count > 0) {
    uint32_t u = queue[2 * head], w = queue[2 * head + 1];
    head = head + 1 == nx ? 0 : head + 1;
    count--;
    int i;
    uint32_t e = qk__cdt_find_edge(c, u, w, &i);
    uint32_t n = c->nbr[3 * (size_t)e + i];
    const uint32_t *nn = c->nbr + 3 * (size_t)n;
    int j = nn[0] == e ? 0 : nn[1] == e ? 1 : 2;
    uint32_t p = c->v[3 * (size_t)e + i], s = c->v[3 * (size_t)n + j];
    long tail = (head + count) % nx;
    /* e = (p, u, w), n = (s, w, u): convex when u is right of p -> s and w left */
    if (qk__cdt_orient(pt(c, p), pt(c, s), pt(c, u)) < 0 &&
        qk__cdt_orient(pt(c, p), pt(c, s), pt(c, w)) > 0) {
      qk__cdt_flip(c, e, i, n, j);
      int op = qk__cdt_orient(pa, pb, pt(c, p)), os = qk__cdt_orient(pa, pb, pt(c, s));
      if (op * os < 0) queue[2 * tail] = p, queue[2 * tail + 1] = s, count++;
    } else {
      queue[2 * tail] = u, queue[2 * tail + 1] = w, count++;
    }
  }
  int k;
  uint32_t t = qk__cdt_find_edge(c, a, b, &k);
  mark(c, t, k, seg);
  for (int again = 1; again;) {
    again = 0;
    for (long m = 0; m < nr; m++)
      for (int i = 0; i < 3; i++) {
        uint32_t e = sp[m], n = c->nbr[3 * (size_t)e + i];
        if (n == NONE || c->seg[3 * (size_t)e + i] != NONE || !in_pool(sp, nr, n)) continue;
        const uint32_t *nn = c->nbr + 3 * (size_t)n;
        int j = nn[0] == e ? 0 : nn[1] == e ? 1 : 2;
        const uint32_t *ev = c->v + 3 * (size_t)e;
        if (qk__cdt_incircle(pt(c, ev[0]), pt(c, ev[1]), pt(c, ev[2]),
                             pt(c, c->v[3 * (size_t)n + j])) <= 0)
          continue;
        qk__cdt_flip(c, e, i, n, j);
        again = 1;
      }
  }
  c->hint = t;
}

/* Point the link of triangle x (outside the cavity) across its edge u-w at t. */
static void link_outside(qk__cdt_t *c, uint32_t x, uint32_t u, uint32_t w, uint32_t t) {
  if (x == NONE) return;
  int k = 3 - qk__cdt_slot(c, x, u) - qk__cdt_slot(c, x, w);
  c->nbr[3 * (size_t)x + k] = t;
}

/*
 * Triangulate the pseudo-polygon p[0..n) (the polygon lies left of p[0] -> p[n-1]; chain
 * edge m is p[m] -> p[m + 1], with the triangle nb[m] and segment id sg[m] outside it) by
 * its constrained Delaunay triangulation: on the base p[i] -> p[j], the apex is the vertex
 * between them whose circle with the base holds no other (one pass: the circles through
 * two points are nested on one side of them), then the same on p[i] -> p[c] and p[c] ->
 * p[j] (Anglada's algorithm, as in Shewchuk's notes on segment insertion). The triangles
 * reuse the ids in pool; the one on p[0] -> p[n-1] (slot 2) is returned, its link across
 * that edge left NONE. stk has room for 4n words.
 */
static uint32_t fill(qk__cdt_t *c, const uint32_t *p, const uint32_t *nb, const uint32_t *sg,
                     uint32_t n, const uint32_t *pool, uint32_t *used, uint32_t *stk) {
  uint32_t sp = 0, top = NONE;
  stk[0] = 0, stk[1] = n - 1, stk[2] = NONE, stk[3] = 0, sp = 1;
  while (sp > 0) {
    sp--;
    uint32_t i = stk[4 * sp], j = stk[4 * sp + 1], par = stk[4 * sp + 2], ps = stk[4 * sp + 3];
    uint32_t m = i + 1;
    for (uint32_t q = i + 2; q < j; q++)
      if (qk__cdt_incircle(pt(c, p[i]), pt(c, p[j]), pt(c, p[m]), pt(c, p[q])) > 0) m = q;
    uint32_t t = pool[(*used)++];
    uint32_t *tv = c->v + 3 * (size_t)t, *tn = c->nbr + 3 * (size_t)t, *ts = c->seg + 3 * (size_t)t;
    tv[0] = p[i], tv[1] = p[j], tv[2] = p[m];
    tn[2] = par, ts[2] = NONE;
    if (par != NONE)
      c->nbr[3 * (size_t)par + ps] = t;
    else
      top = t;
    if (m == i + 1) { /* edge p[m] -> p[i] is chain edge i */
      tn[1] = nb[i], ts[1] = sg[i];
      link_outside(c, nb[i], p[i], p[m], t);
    } else {
      tn[1] = NONE, ts[1] = NONE;
      stk[4 * sp] = i, stk[4 * sp + 1] = m, stk[4 * sp + 2] = t, stk[4 * sp + 3] = 1, sp++;
    }
    if (j == m + 1) { /* edge p[j] -> p[m] is chain edge m */
      tn[0] = nb[m], ts[0] = sg[m];
      link_outside(c, nb[m], p[m], p[j], t);
    } else {
      tn[0] = NONE, ts[0] = NONE;
      stk[4 * sp] = m, stk[4 * sp + 1] = j, stk[4 * sp + 2] = t, stk[4 * sp + 3] = 0, sp++;
    }
    c->vtri[p[i]] = t, c->vtri[p[j]] = t, c->vtri[p[m]] = t;
  }
  return top;
}

qk_status_t qk__cdt_insert_segment(qk__cdt_t *c, uint32_t a, uint32_t b, uint32_t seg,
                                   uint32_t *block, uint32_t *block_seg) {
  *block = NONE, *block_seg = NONE;
  if (a == b || a >= c->nv || b >= c->nv) {
    *block = a;
    return QK_ERR_GEOMETRY;
  }
  int k;
  uint32_t t = qk__cdt_find_edge(c, a, b, &k);
  if (t != NONE) {
    uint32_t old = c->seg[3 * (size_t)t + k];
    if (old != NONE && old != seg) {
      *block = a, *block_seg = old;
      return QK_ERR_GEOMETRY;
    }
    mark(c, t, k, seg);
    return QK_OK;
  }
  qk_status_t st = QK_OK;
  long nr = trace(c, a, b, &st, block, block_seg);
  if (nr < 0) return st;
  /* Both chains have at most nr + 1 vertices: room for the records, the pool of triangle
   * ids and its sorted copy, each chain's vertices, outside links and segment ids, and the
   * stack (or the fallback's queue). */
  size_t cap = (REC + 2) * (size_t)nr + 6 * ((size_t)nr + 2) + 4 * ((size_t)nr + 2);
  if (qk__cdt_reserve_scratch(c, cap) != QK_OK) return QK_ERR_NOMEM;
  uint32_t *rec = c->scr, *pool = rec + REC * nr, *sp = pool + nr;
  uint32_t *lv = sp + nr, *lnb = lv + nr + 2, *lsg = lnb + nr + 2;
  uint32_t *rv = lsg + nr + 2, *rnb = rv + nr + 2, *rsg = rnb + nr + 2, *stk = rsg + nr + 2;
  for (long m = 0; m < nr; m++) pool[m] = sp[m] = rec[REC * m];
  sort_ids(sp, nr);
  /* The chains from a to b: T_0 = (a, x, y) gives y (left) and x (right). */
  uint32_t nl = 0, nrr = 0;
  {
    const uint32_t *tv = c->v + 3 * (size_t)rec[0];
    int i = qk__cdt_slot(c, rec[0], a);
    lv[nl++] = a, lv[nl++] = tv[(i + 2) % 3];
    rv[nrr++] = a, rv[nrr++] = tv[(i + 1) % 3];
  }
  uint32_t el = 0, er = 0;
  int pinched = 0;
  for (long m = 0; m < nr; m++) {
    uint32_t tri = rec[REC * m], ls = rec[REC * m + 1], rs = rec[REC * m + 2];
    uint32_t o = rec[REC * m + 3];
    if (ls != 3) {
      if (m > 0) lv[nl++] = o;
      lnb[el] = c->nbr[3 * (size_t)tri + ls], lsg[el] = c->seg[3 * (size_t)tri + ls];
      pinched |= lnb[el] != NONE && in_pool(sp, nr, lnb[el]);
      el++;
    }
    if (rs != 3) {
      if (m > 0) rv[nrr++] = o;
      rnb[er] = c->nbr[3 * (size_t)tri + rs], rsg[er] = c->seg[3 * (size_t)tri + rs];
      pinched |= rnb[er] != NONE && in_pool(sp, nr, rnb[er]);
      er++;
    }
  }
  if (pinched) {
#ifdef CDT_DEBUG
    fprintf(stderr, "pinched cavity %ld\n", nr);
#endif
    insert_by_flips(c, a, b, seg, rec, nr, sp, stk);
    return QK_OK;
  }
  /* The right polygon lies left of b -> a: reverse its chain. */
  for (uint32_t m = 0; m < nrr / 2; m++) {
    uint32_t x = rv[m];
    rv[m] = rv[nrr - 1 - m], rv[nrr - 1 - m] = x;
  }
  for (uint32_t m = 0; m < er / 2; m++) {
    uint32_t x = rnb[m], y = rsg[m];
    rnb[m] = rnb[er - 1 - m], rsg[m] = rsg[er - 1 - m];
    rnb[er - 1 - m] = x, rsg[er - 1 - m] = y;
  }
  uint32_t used = 0;
  uint32_t tl = fill(c, lv, lnb, lsg, nl, pool, &used, stk);
  uint32_t tr = fill(c, rv, rnb, rsg, nrr, pool, &used, stk);
  c->nbr[3 * (size_t)tl + 2] = tr, c->seg[3 * (size_t)tl + 2] = seg;
  c->nbr[3 * (size_t)tr + 2] = tl, c->seg[3 * (size_t)tr + 2] = seg;
  if (c->on_change)
    for (uint32_t m = 0; m < used; m++) c->on_change(c->user, pool[m]);
  c->hint = tl;
  return QK_OK;
}

/* ---- the straight walk from a vertex -------------------------------------------------- */

/* Whether vertex o is an end of a constrained edge. */
static int on_constraint(const qk__cdt_t *c, uint32_t o) {
  qk__cdt_ring_t r = {o, NONE, NONE, 1};
  for (uint32_t t = qk__cdt_ring_next(c, &r); t != NONE; t = qk__cdt_ring_next(c, &r)) {
    int i = qk__cdt_slot(c, t, o);
    if (c->seg[3 * (size_t)t + (i + 1) % 3] != NONE || c->seg[3 * (size_t)t + (i + 2) % 3] != NONE)
      return 1;
  }
  return 0;
}

/* Stop at vertex slot k of t (the walk's end at a vertex, or a vertex that blocks it). */
static int at_vertex(const qk__cdt_t *c, uint32_t t, int k, int end, uint32_t *tri, int *kout,
                     qk__cdt_where_t *where) {
  *tri = t, *kout = k, *where = QK__CDT_VERT;
  if (on_constraint(c, c->v[3 * (size_t)t + k])) return 0;
  return end ? 1 : -1; /* -1: pass through and go on */
}

int qk__cdt_walk(const qk__cdt_t *c, uint32_t w, double x, double y, uint32_t *tri, int *k,
                 qk__cdt_where_t *where) {
  const double P[2] = {x, y}, *pw = pt(c, w);
  uint32_t u = w; /* the vertex the walk is at */
  for (;;) {
    const double *pu = pt(c, u);
    if (pu[0] == P[0] && pu[1] == P[1]) {
      uint32_t t = c->vtri[u];
      *tri = t, *k = qk__cdt_slot(c, t, u), *where = QK__CDT_VERT;
      if (u != w && on_constraint(c, u)) return 0;
      return 1;
    }
    /* Find the triangle (u, x, y) around u whose closed wedge holds P. */
    qk__cdt_ring_t r = {u, NONE, NONE, 1};
    uint32_t t = NONE, next_u = NONE;
    int i = 0;
    for (uint32_t s = qk__cdt_ring_next(c, &r); s != NONE; s = qk__cdt_ring_next(c, &r)) {
      i = qk__cdt_slot(c, s, u);
      int i1 = (i + 1) % 3, i2 = (i + 2) % 3;
      uint32_t vx = c->v[3 * (size_t)s + i1], vy = c->v[3 * (size_t)s + i2];
      int ox = qk__cdt_orient(pu, pt(c, vx), P), oy = qk__cdt_orient(pu, pt(c, vy), P), pos;
      if (ox == 0 && along(pu, P, pt(c, vx), &pos)) { /* P on the ray u -> vx */
        if (c->seg[3 * (size_t)s + i2] != NONE) {     /* along a constrained edge */
          *tri = s, *k = i2, *where = QK__CDT_EDGE;
          return 0;
        }
        if (pos > 0) { /* P before vx: on the edge */
          *tri = s, *k = i2, *where = QK__CDT_EDGE;
          return 1;
        }
        int res = at_vertex(c, s, i1, pos == 0, tri, k, where);
        if (res >= 0) return res;
        next_u = vx;
        break;
      }
      if (oy == 0 && along(pu, P, pt(c, vy), &pos)) { /* P on the ray u -> vy */
        if (c->seg[3 * (size_t)s + i1] != NONE) {
          *tri = s, *k = i1, *where = QK__CDT_EDGE;
          return 0;
        }
        if (pos > 0) {
          *tri = s, *k = i1, *where = QK__CDT_EDGE;
          return 1;
        }
        int res = at_vertex(c, s, i2, pos == 0, tri, k, where);
        if (res >= 0) return res;
        next_u = vy;
        break;
      }
      if (ox > 0 && oy < 0) {
        t = s;
        break;
      }
    }
    if (next_u != NONE) {
      u = next_u;
      continue;
    }
    if (t == NONE) { /* P outside the square: stay at u */
      *tri = c->vtri[u], *k = qk__cdt_slot(c, *tri, u), *where = QK__CDT_VERT;
      return 1;
    }
    /* The segment enters t = (u, x, y) between x (right of w -> P) and y (left). State:
     * (t, kk) with edge kk of t ahead of the segment, P strictly past the other two. */
    int kk = i;
    for (;;) {
      const uint32_t *tv = c->v + 3 * (size_t)t;
      int oe = qk__cdt_orient(pt(c, tv[(kk + 1) % 3]), pt(c, tv[(kk + 2) % 3]), P);
      if (oe > 0) {
        *tri = t, *k = 0, *where = QK__CDT_IN;
        return 1;
      }
      /* P on the edge ahead (in its relative interior: the line crosses it there), or
       * beyond it: either way a constrained edge stops the walk */
      if (oe == 0 || c->seg[3 * (size_t)t + kk] != NONE || c->nbr[3 * (size_t)t + kk] == NONE) {
        *tri = t, *k = kk, *where = QK__CDT_EDGE;
        return oe == 0 && c->seg[3 * (size_t)t + kk] == NONE;
      }
      uint32_t n = c->nbr[3 * (size_t)t + kk];
      const uint32_t *nn = c->nbr + 3 * (size_t)n;
      int j = nn[0] == t ? 0 : nn[1] == t ? 1 : 2;
      t = n;
      /* t = (o, l, r) from slot j, entered through l -> r, l left of w -> P, r right */
      const uint32_t *nv = c->v + 3 * (size_t)t;
      uint32_t o = nv[j];
      int so = qk__cdt_orient(pw, P, pt(c, o));
      if (so != 0) {
        kk = so > 0 ? (j + 1) % 3 : (j + 2) % 3; /* leave by r - o or by o - l */
        continue;
      }
      /* The line runs into o: P lies inside t before o, at o, or beyond o. */
      int or_ = qk__cdt_orient(pt(c, nv[(j + 2) % 3]), pt(c, o), P);
      int ol = qk__cdt_orient(pt(c, o), pt(c, nv[(j + 1) % 3]), P);
      if (or_ > 0 && ol > 0) {
        *tri = t, *k = 0, *where = QK__CDT_IN;
        return 1;
      }
      int res = at_vertex(c, t, j, or_ == 0 && ol == 0, tri, k, where);
      if (res >= 0) return res;
      next_u = o;
      break;
    }
    u = next_u;
  }
}
