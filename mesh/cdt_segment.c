/*
 * Constrained edges and straight walks in the triangulation of mesh/cdt.h.
 *
 * Segment insertion (qk__cdt_insert_segment) first traces ab from a, triangle by triangle,
 * recording the edges it crosses and refusing (before any change) a vertex on ab or a
 * constrained edge across it. It then removes the crossing edges by flips (Sloan, "A fast
 * algorithm for generating constrained Delaunay triangulations", 1993): an edge whose quad
 * is strictly convex is flipped, and its replacement goes back in the queue while it still
 * crosses ab; one that is not waits its turn again. When ab is an edge it is marked, and
 * the new edges are flipped by the in-circle test until none changes (Lawson's algorithm
 * inside the two polygons on either side of ab, which yields their constrained Delaunay
 * triangulations; outside them nothing changed).
 */
#include "mesh/cdt_internal.h"

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

/* Trace ab from a: the crossed edges go to c->scr as (left, right) vertex pairs (left of
 * a -> b first); returns their count, or -1 with *st set (NOMEM, or GEOMETRY with *block and
 * *block_seg). Changes nothing but the scratch array. */
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
  /* The edge opposite a in t crosses ab: its ends are y (left) and x (right). */
  long n = 0;
  uint32_t left = c->v[3 * (size_t)t + (i + 2) % 3], right = c->v[3 * (size_t)t + (i + 1) % 3];
  int k = i;
  for (;;) {
    uint32_t s = c->seg[3 * (size_t)t + k];
    if (s != NONE) {
      *block = left, *block_seg = s;
      *st = QK_ERR_GEOMETRY;
      return -1;
    }
    if (qk__cdt_reserve_scratch(c, 2 * (size_t)n + 2) != QK_OK) {
      *st = QK_ERR_NOMEM;
      return -1;
    }
    c->scr[2 * n] = left, c->scr[2 * n + 1] = right, n++;
    uint32_t nt = c->nbr[3 * (size_t)t + k];
    const uint32_t *nn = c->nbr + 3 * (size_t)nt;
    int j = nn[0] == t ? 0 : nn[1] == t ? 1 : 2;
    t = nt;
    uint32_t o = c->v[3 * (size_t)t + j];
    if (o == b) return n;
    int so = qk__cdt_orient(pa, pb, pt(c, o));
    if (so == 0) {
      *block = o;
      *st = QK_ERR_GEOMETRY;
      return -1;
    }
    /* t = (o, left, right) from slot j: leave by o-right (slot of left) or left-o */
    if (so > 0)
      left = o, k = (j + 1) % 3;
    else
      right = o, k = (j + 2) % 3;
  }
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
  long nx = trace(c, a, b, &st, block, block_seg);
  if (nx < 0) return st;
  /* Room for the queue (2 nx) and the list of new edges (2 nx). */
  if (qk__cdt_reserve_scratch(c, 4 * (size_t)nx) != QK_OK) return QK_ERR_NOMEM;
  uint32_t *queue = c->scr, *made = c->scr + 2 * nx;
  long head = 0, count = nx, nmade = 0;
  const double *pa = pt(c, a), *pb = pt(c, b);
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
    /* e = (p, u, w), n = (s, w, u): convex when u is right of p -> s and w left */
    if (qk__cdt_orient(pt(c, p), pt(c, s), pt(c, u)) < 0 &&
        qk__cdt_orient(pt(c, p), pt(c, s), pt(c, w)) > 0) {
      qk__cdt_flip(c, e, i, n, j);
      int sp = qk__cdt_orient(pa, pb, pt(c, p)), ss = qk__cdt_orient(pa, pb, pt(c, s));
      if ((sp > 0 && ss < 0) || (sp < 0 && ss > 0)) {
        long tail = (head + count) % nx;
        queue[2 * tail] = p, queue[2 * tail + 1] = s;
        count++;
      } else {
        made[2 * nmade] = p, made[2 * nmade + 1] = s;
        nmade++;
      }
    } else {
      long tail = (head + count) % nx;
      queue[2 * tail] = u, queue[2 * tail + 1] = w;
      count++;
    }
  }
  t = qk__cdt_find_edge(c, a, b, &k);
  mark(c, t, k, seg);
  /* Lawson's flips over the new edges until all are locally Delaunay. */
  for (int again = 1; again;) {
    again = 0;
    for (long m = 0; m < nmade; m++) {
      uint32_t u = made[2 * m], w = made[2 * m + 1];
      int i;
      uint32_t e = qk__cdt_find_edge(c, u, w, &i);
      if (c->seg[3 * (size_t)e + i] != NONE) continue; /* ab itself */
      uint32_t n = c->nbr[3 * (size_t)e + i];
      const uint32_t *nn = c->nbr + 3 * (size_t)n;
      int j = nn[0] == e ? 0 : nn[1] == e ? 1 : 2;
      uint32_t p = c->v[3 * (size_t)e + i], s = c->v[3 * (size_t)n + j];
      if (qk__cdt_incircle(pt(c, p), pt(c, u), pt(c, w), pt(c, s)) <= 0) continue;
      qk__cdt_flip(c, e, i, n, j);
      made[2 * m] = p, made[2 * m + 1] = s;
      again = 1;
    }
  }
  c->hint = t;
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
