/*
 * The straight walk of mesh/cdt.h (qk__cdt_walk): from a vertex towards a point, triangle by
 * triangle along the segment, stopping where a constrained edge meets it (the refinement's
 * visibility test). Exact orientations decide which edge the segment leaves by and when it
 * runs through a vertex, so the walk is monotone along the segment and always ends.
 */
#include "mesh/cdt_internal.h"

#define NONE QK__CDT_NONE
#define pt qk__cdt_pt
#define along qk__cdt_along

/* The next and the previous slot, (i + 1) % 3 and (i + 2) % 3 without the division's
 * multiply-and-shift (a few instructions each, four of them a step of the walk). */
static inline int next3(int i) { return i == 2 ? 0 : i + 1; }
static inline int prev3(int i) { return i == 0 ? 2 : i - 1; }

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
  return qk__cdt_walk_from(c, w, NONE, x, y, tri, k, where);
}

int qk__cdt_walk_from(const qk__cdt_t *c, uint32_t w, uint32_t start, double x, double y,
                      uint32_t *tri, int *k, qk__cdt_where_t *where) {
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
    uint32_t t = NONE, next_u = NONE, s0;
    int i = 0;
    if (u == w && start < c->nt)
      s0 = r.first = r.t = start; /* the ring from there on, as from vtri[w] */
    else
      s0 = qk__cdt_ring_next(c, &r);
    for (uint32_t s = s0; s != NONE; s = qk__cdt_ring_next(c, &r)) {
      i = qk__cdt_slot(c, s, u);
      int i1 = next3(i), i2 = prev3(i);
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
      int oe = qk__cdt_orient(pt(c, tv[next3(kk)]), pt(c, tv[prev3(kk)]), P);
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
        kk = so > 0 ? next3(j) : prev3(j); /* leave by r - o or by o - l */
        continue;
      }
      /* The line runs into o: P lies inside t before o, at o, or beyond o. */
      int or_ = qk__cdt_orient(pt(c, nv[prev3(j)]), pt(c, o), P);
      int ol = qk__cdt_orient(pt(c, o), pt(c, nv[next3(j)]), P);
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
