/*
 * The exact distance test of the point-set queries (query/: radius and kNN) and of the
 * static collider's disc tests (collide/): whether two points lie within a distance of
 * each other, in exact arithmetic for any finite doubles, behind a floating-point filter.
 * It lives in index/, the one module the others build on, so that neither of them
 * depends on the other (it was in query/ until December 2026). Not API.
 */
#ifndef QUADKIT_INDEX_DIST_EXACT_H
#define QUADKIT_INDEX_DIST_EXACT_H

#include <math.h>
#include <stdint.h>
#include <string.h>

/*
 * Is (ax - bx)^2 + (ay - by)^2 <= (r1 + r2)^2, computed exactly (no rounding, no overflow,
 * no underflow) for any finite doubles with r1, r2 >= 0? 1 or 0. Slow (big integers):
 * for the cases the filter below cannot decide.
 */
int qk__within_exact(double ax, double ay, double bx, double by, double r1, double r2);

/*
 * The sign (-1, 0 or 1) of |a - q|^2 - |b - q|^2, computed exactly for any finite doubles:
 * the kNN searches' order when the filter below cannot tell two squares apart.
 */
int qk__dist_cmp_exact(double qx, double qy, double ax, double ay, double bx, double by);

/*
 * The squared distance from q to p in doubles when every operation of it is exact (then
 * *d2 is the exact value; returns 1), else 0: each difference's rounding error is 0
 * (Knuth's two-sum), each difference has at most 26 significant bits and lies above
 * 2^-480 or is 0 (so its square is exact and normal), and the sum's error is 0 (an
 * overflow makes the two-sum check NaN, which fails it). Points on grids of dyadic steps
 * (integers, halves) pass, so their ties cost no big integers.
 */
static inline int qk__sum_exact(double a, double b, double s) {
  const double bb = s - a;
  return (a - (s - bb)) + (b - bb) == 0;
}
static inline int qk__square_exact(double v) {
  uint64_t u;
  memcpy(&u, &v, sizeof u);
  return v == 0 || (fabs(v) >= 0x1p-480 && (u & ((UINT64_C(1) << 27) - 1)) == 0);
}
static inline int qk__d2_exact(double qx, double qy, double px, double py, double *d2) {
  const double dx = px - qx, dy = py - qy;
  if (!qk__sum_exact(px, -qx, dx) || !qk__sum_exact(py, -qy, dy)) return 0;
  if (!qk__square_exact(dx) || !qk__square_exact(dy)) return 0;
  const double a = dx * dx, b = dy * dy;
  *d2 = a + b;
  return qk__sum_exact(a, b, *d2);
}

/*
 * The filter: with d2 = dx*dx + dy*dy and r2 = rs*rs computed in doubles (dx, dy, rs each
 * one rounded operation on the inputs), d2 < qk__filter_lo(r2) means inside and
 * d2 > qk__filter_hi(r2) outside, exactly; in between, or when r2 >= 2^1000 (where squares
 * may have overflowed), only qk__within_exact() tells. The bounds: every rounding is within
 * a relative 2^-53, or an absolute 2^-1075 where a product underflows, so d2 and r2 are
 * within a relative 6 * 2^-53 plus an absolute 2^-1073 of the exact values; the margins
 * 2^-45 relative and 2^-1060 absolute exceed that. A pruning test that compares a lower
 * bound of d2 with qk__filter_hi(r2) keeps every point the exact test accepts.
 * Two squared distances da and db computed the same way compare the same way: da <
 * qk__filter_lo(db) means the first point is nearer, da > qk__filter_hi(db) farther,
 * exactly (both carry the errors above, which the margins cover twice over).
 */
#define QK__FILTER_REL 0x1p-45
#define QK__FILTER_ABS 0x1p-1060
#define QK__FILTER_MAX 0x1p1000
static inline double qk__filter_lo(double r2) {
  return r2 < QK__FILTER_MAX ? r2 * (1 - QK__FILTER_REL) - QK__FILTER_ABS : -1.0;
}
static inline double qk__filter_hi(double r2) {
  return r2 < QK__FILTER_MAX ? r2 * (1 + QK__FILTER_REL) + QK__FILTER_ABS : INFINITY;
}

/*
 * 2^-e for the exponent e of v > 0 (v = m 2^e, 0.5 <= m < 1), within [2^-1022, 2^1023]:
 * v times it lies in [0.5, 1) unless v is below 2^-1022 or above 2^1022. The radius
 * query, kNN and the collider's disc tests multiply their differences by it when the
 * filter's squares would leave its range, below about 2^-530 (where they underflow
 * under QK__FILTER_ABS) or from 2^500 (beyond QK__FILTER_MAX): a difference rounded once
 * and then scaled exactly by a power of two (or, below 1, with an absolute error under
 * 2^-1075 where it turns subnormal, as an underflowing product) keeps the bounds above,
 * and one that overflows, scaled or not, is farther than any finite radius.
 */
static inline double qk__scale_of(double v) {
  int ex;
  (void)frexp(v, &ex);
  ex = ex > 1022 ? 1022 : (ex < -1023 ? -1023 : ex);
  return ldexp(1.0, -ex);
}

/* The scale for a radius (or a sum of radii) rs >= 0: 1 within [2^-400, 2^400] or
 * infinite; 2^1023 for 0 (any nonzero difference then scales to at least 2^-51, far above
 * the filter's absolute margin, so only coincident points pass); else qk__scale_of(rs). */
static inline double qk__radius_scale(double rs) {
  if ((rs >= 0x1p-400 && rs <= 0x1p400) || isinf(rs)) return 1.0;
  return rs > 0 ? qk__scale_of(rs) : 0x1p1023;
}

#endif /* QUADKIT_INDEX_DIST_EXACT_H */
