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

/* qk__incircle with its filter inline. mesh/cdt_exact.c bounds the estimate's error by
 * ((1 + u)^11 - 1) M, u = 2^-53, M the sum of the magnitudes of the determinant's twelve
 * monomials (exact differences). M is bounded by la lb + lb lc + lc la (exact lifts):
 * |bdx cdy| + |cdx bdy| <= (lb + lc) / 2 as 2|xy| <= x^2 + y^2, and so for the other two
 * pairs. That in turn is at most s^2 / 3, s = la + lb + lc (s^2 is the sum of the three
 * squares and twice the three products, and the squares sum to at least the products).
 * The computed s is at most six roundings below its exact value (four in each lift: the
 * two differences, the squares, their sum; two in the sums), so the computed s^2 at most
 * thirteen (twice six, and the square's own), and the error is below 11u (1 - u)^-13 / 3
 * < 4u = 2^-51 times it. Two products fewer a test than the sum of the products (the
 * bound before, 2^-49 times it; 0.4% of the meshing's instructions on the coastlines at
 * extent/256). Equal to it when the point is near a corner, tighter when the three lifts
 * are alike, looser only when one lift dominates (the point far from two close corners);
 * the exact fallback ran 15 times instead of 18 on South Africa at extent/256. The sum of
 * the products replaced the computed permanent (det's expression with absolute values, M
 * within rounding), which cost six absolute values and four more operations a test; the
 * refinement makes about eight tests a point it inserts. */
static inline int qk__cdt_incircle(const double *a, const double *b, const double *c,
                                   const double *d) {
  double adx = a[0] - d[0], ady = a[1] - d[1];
  double bdx = b[0] - d[0], bdy = b[1] - d[1];
  double cdx = c[0] - d[0], cdy = c[1] - d[1];
  double la = adx * adx + ady * ady, lb = bdx * bdx + bdy * bdy, lc = cdx * cdx + cdy * cdy;
  double det =
      la * (bdx * cdy - cdx * bdy) + lb * (cdx * ady - adx * cdy) + lc * (adx * bdy - bdx * ady);
  double s = la + lb + lc, bound = s * s * 0x1p-51;
  if (det > bound) return 1;
  if (-det > bound) return -1;
  return qk__incircle_exact(a, b, c, d);
}

/* qk__cdt_encroach with its filter inline (the same estimate and bound as its first lines
 * in mesh/cdt_exact.c, so the same sign), for the refinement's cavity search, which tests
 * each constrained edge it meets; the filter decides all but ties. */
static inline int qk__cdt_encroach_in(const double *a, const double *b, const double *p) {
  double l = (a[0] - p[0]) * (b[0] - p[0]), r = (a[1] - p[1]) * (b[1] - p[1]);
  double dot = l + r, bound = (fabs(l) + fabs(r)) * 0x1p-50;
  if (dot > bound) return 1;
  if (-dot > bound) return -1;
  return qk__cdt_encroach(a, b, p);
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
