/*
 * Shared by the sources of the constrained Delaunay triangulation (mesh/cdt*.c): the
 * inline predicate filters, the walk around a vertex, the flip. The refinement
 * (mesh/general_refine.c) uses the inline in-circle filter for its cavity search too.
 */
#ifndef QK_MESH_CDT_INTERNAL_H
#define QK_MESH_CDT_INTERNAL_H

#include <math.h>

#include "mesh/cdt.h"
#include "mesh/general_internal.h"

/* The orientation of (a, b, p), exact: the floating-point estimate when its error bound
 * (mesh/general_predicates.c) allows, else qk__orient2d. */
static inline int qk__cdt_orient(const double *a, const double *b, const double *p) {
  double l = (b[0] - a[0]) * (p[1] - a[1]), r = (b[1] - a[1]) * (p[0] - a[0]);
  double det = l - r, bound = (fabs(l) + fabs(r)) * 0x1p-50;
  if (det > bound) return 1;
  if (-det > bound) return -1;
  return qk__orient2d(a, b, p);
}

/* qk__incircle with its filter inline (mesh/cdt_exact.c gives the bound's proof). */
static inline int qk__cdt_incircle(const double *a, const double *b, const double *c,
                                   const double *d) {
  double adx = a[0] - d[0], ady = a[1] - d[1];
  double bdx = b[0] - d[0], bdy = b[1] - d[1];
  double cdx = c[0] - d[0], cdy = c[1] - d[1];
  double bc1 = bdx * cdy, bc2 = cdx * bdy;
  double ca1 = cdx * ady, ca2 = adx * cdy;
  double ab1 = adx * bdy, ab2 = bdx * ady;
  double la = adx * adx + ady * ady, lb = bdx * bdx + bdy * bdy, lc = cdx * cdx + cdy * cdy;
  double det = la * (bc1 - bc2) + lb * (ca1 - ca2) + lc * (ab1 - ab2);
  double perm =
      la * (fabs(bc1) + fabs(bc2)) + lb * (fabs(ca1) + fabs(ca2)) + lc * (fabs(ab1) + fabs(ab2));
  double bound = perm * 0x1p-49;
  if (det > bound) return 1;
  if (-det > bound) return -1;
  return qk__incircle_exact(a, b, c, d);
}

/* The coordinates of vertex v. */
static inline const double *qk__cdt_pt(const qk__cdt_t *c, uint32_t v) {
  return c->xy + 2 * (size_t)v;
}

/* For p collinear with a and b (a != b): whether p lies on the ray from a through b beyond
 * a (p != a), and where along it: -1 before b, 0 at b, 1 beyond b. Exact comparisons of
 * coordinates along an axis on which a and b differ. */
static inline int qk__cdt_along(const double *a, const double *b, const double *p, int *pos) {
  int ax = a[0] != b[0] ? 0 : 1;
  double dir = b[ax] - a[ax];
  if (p[ax] == a[ax]) return 0;
  if ((p[ax] > a[ax]) != (dir > 0)) return 0;
  *pos = p[ax] == b[ax] ? 0 : ((p[ax] < b[ax]) == (dir > 0) ? -1 : 1);
  return 1;
}

/* The slot (0..2) of vertex a in triangle t, which holds it. */
static inline int qk__cdt_slot(const qk__cdt_t *c, uint32_t t, uint32_t a) {
  const uint32_t *v = c->v + 3 * (size_t)t;
  return v[0] == a ? 0 : v[1] == a ? 1 : 2;
}

/* Flip edge i of triangle t, whose other side is slot j of triangle n: with t = (p, q, r)
 * from slot i and s the vertex of n across, t becomes (p, q, s) and n (p, s, r). The quad
 * must be strictly convex. */
void qk__cdt_flip(qk__cdt_t *c, uint32_t t, int i, uint32_t n, int j);

/* Tests only: nonzero makes segment insertion take its flip fallback (mesh/cdt_segment.c),
 * which otherwise runs only when a cavity's triangulation cannot be planned. */
extern int qk__cdt_test_flips;

/* Room for `need` entries in c->scr. */
qk_status_t qk__cdt_reserve_scratch(qk__cdt_t *c, size_t need);

#endif
