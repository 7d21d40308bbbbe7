/*
 * Hole points: locate each in the mesh and mark the face holding it, with exact
 * predicates for points given as arbitrary doubles.
 */
#include "mesh/mesh_internal.h"

#include <math.h>
#include <stdlib.h>
#include <string.h>

/*
 * Exact sign of s1 x + s2 y - c for doubles x, y >= 0, signs s1, s2 in {-1, 0, 1} and an
 * integer c: the lines of a quadtree mesh are axis-parallel or diagonal, so every
 * orientation test against a hole point has this form. Split x = ix + fx, y = iy + fy
 * with integer parts and fractions in [0, 1) (both exact); the integer part decides
 * unless it is within one of zero, and then only exact comparisons of fractions remain.
 */
static int lin_sign(int s1, int s2, double x, double y, int64_t c) {
  if (s1 == 0 || s2 == 0) {
    double v = s1 ? x : y;
    int s = s1 ? s1 : s2;
    if (s == 0) return (c < 0) - (c > 0);
    /* sign(s v - c) = s * sign(v - s c) */
    double t = (double)(s * c);
    return s * ((v > t) - (v < t));
  }
  if (s1 < 0) return -lin_sign(-s1, -s2, x, y, -c);
  double ix = floor(x), iy = floor(y), fx = x - ix, fy = y - iy;
  if (s2 > 0) { /* x + y - c = I + (fx + fy), fx + fy in [0, 2) */
    int64_t I = (int64_t)ix + (int64_t)iy - c;
    if (I >= 0) return (I > 0 || fx > 0 || fy > 0) ? 1 : 0;
    if (I <= -2) return -1;
    /* I = -1: sign(fx + fy - 1). 1 - f is exact for f >= 1/2; if both are below 1/2 the
     * sum is below 1. */
    if (fy >= 0.5) return (fx > 1 - fy) - (fx < 1 - fy);
    if (fx >= 0.5) return (fy > 1 - fx) - (fy < 1 - fx);
    return -1;
  }
  /* x - y - c = I + (fx - fy), fx - fy in (-1, 1). */
  int64_t I = (int64_t)ix - (int64_t)iy - c;
  if (I >= 1) return 1;
  if (I <= -1) return -1;
  return (fx > fy) - (fx < fy);
}

/* Exact turn from a->b (integer points, direction axis-parallel or diagonal) to h. */
static int orient_h(int64_t ax, int64_t ay, int64_t bx, int64_t by, double hx, double hy) {
  int sx = (bx > ax) - (bx < ax), sy = (by > ay) - (by < ay);
  /* qk__cross((s), h - a) = sx (hy - ay) - sy (hx - ax) = -sy hx + sx hy - (sx ay - sy ax) */
  return lin_sign(-sy, sx, hx, hy, sx * ay - sy * ax);
}

/* Is h on the closed segment a-b? */
static int on_edge(const qk__edge_t *e, double hx, double hy) {
  if (orient_h(e->ax, e->ay, e->bx, e->by, hx, hy) != 0) return 0;
  double x0 = (double)(e->ax < e->bx ? e->ax : e->bx), x1 = (double)(e->ax < e->bx ? e->bx : e->ax);
  double y0 = (double)(e->ay < e->by ? e->ay : e->by), y1 = (double)(e->ay < e->by ? e->by : e->ay);
  return hx >= x0 && hx <= x1 && hy >= y0 && hy <= y1;
}

/*
 * The region holding point (hx, hy) (lattice coordinates), or QK__MESH_UNSET when no
 * triangle was found; `what`, `num`, (x, y) and `line` name the point in messages.
 */
static qk_status_t locate(qk__gen_t *g, const qk__tri_state_t *T, const qk__leaf_tris_t *lt,
                          double hx, double hy, const char *what, unsigned long num, double x,
                          double y, unsigned long line, uint32_t *region) {
  *region = QK__MESH_UNSET;
  int inside_domain = hx >= 0 && hy >= 0 && hx <= (double)g->U && hy <= (double)g->U;
  /* A regional attribute outside the domain names no region (Triangle's rule too). */
  if (!inside_domain && what[0] == 'r') return QK_OK;
  if (!inside_domain)
    return qk__mesh_fail(g->err, QK_ERR_GEOMETRY, line,
                         "%s %lu at (%.17g, %.17g) lies outside the domain", what, num, x, y);
  qk_node_t leaf;
  if (qk_tree_find_leaf(g->tree, (qk_point_t){hx, hy}, &leaf) != QK_OK) return QK_OK;
  /* On a component edge the face is ambiguous. Such an edge meets the closure of the
   * leaf holding the point, so the leaf is a unit square and the edge in its list. */
  qk__unit_rec_t key;
  key.node = leaf;
  const qk__unit_rec_t *r =
      g->nrec ? bsearch(&key, g->rec, g->nrec, sizeof *g->rec, qk__mesh_rec_cmp) : NULL;
  for (uint32_t i = 0; r && i < r->nedge; i++)
    if (on_edge(&g->e[r->edge[i]], hx, hy))
      return qk__mesh_fail(g->err, QK_ERR_GEOMETRY, line,
                           "%s %lu at (%.17g, %.17g) lies on the boundary of component %u", what,
                           num, x, y, g->e[r->edge[i]].comp);
  if (leaf >= lt->cap || lt->first[leaf] == QK__MESH_UNSET) return QK_OK;
  /* A leaf's triangles are consecutive and at most 8; scan them (a triangle of the next
   * leaf that also holds the point is in the same face, so overrunning is harmless). */
  for (uint32_t t = lt->first[leaf]; t < T->nt && t < lt->first[leaf] + 8; t++) {
    const uint32_t *tr = &T->tri[3 * t];
    int inside = 1;
    for (int i = 0; i < 3 && inside; i++) {
      uint32_t a = tr[i], b = tr[(i + 1) % 3];
      if (orient_h(T->vx[a], T->vy[a], T->vx[b], T->vy[b], 2 * hx, 2 * hy) < 0) inside = 0;
    }
    if (inside) {
      *region = T->region[t];
      return QK_OK;
    }
  }
  return QK_OK;
}

/* Holes: find the region holding each hole point and mark it to be dropped. */
qk_status_t qk__mesh_find_holes(qk__gen_t *g, qk__tri_state_t *T, const qk__leaf_tris_t *lt,
                                uint8_t *drop) {
  const qk_poly_t *P = g->poly;
  for (size_t h = 0; h < P->nh; h++) {
    uint32_t reg;
    qk_status_t st = locate(g, T, lt, P->hx[h], P->hy[h], "hole", qk__mesh_num(P, h), g->src->hx[h],
                            g->src->hy[h], P->hline[h], &reg);
    if (st) return st;
    if (reg != QK__MESH_UNSET) drop[reg] = 1;
  }
  return QK_OK;
}

qk_status_t qk__mesh_find_regions(qk__gen_t *g, qk__tri_state_t *T, const qk__leaf_tris_t *lt,
                                  uint32_t *out) {
  const qk_poly_t *S = g->src;
  for (size_t i = 0; i < S->nr; i++) {
    const qk__region_pt_t *q = &S->reg[i];
    double hx = ldexp(q->x - g->lat.x0, g->lat.f), hy = ldexp(q->y - g->lat.y0, g->lat.f);
    qk_status_t st = locate(g, T, lt, hx, hy, "regional attribute", qk__mesh_num(S, i), q->x, q->y,
                            q->line, &out[i]);
    if (st) return st;
  }
  return QK_OK;
}
