/*
 * Exact orientation for double coordinates: a floating-point filter, and when the filter
 * cannot decide, an exact evaluation in expansion arithmetic (a value as a sum of
 * non-overlapping doubles, after Shewchuk, "Adaptive precision floating-point arithmetic
 * and fast robust geometric predicates", 1997). Written for quadkit; only the method is
 * borrowed.
 *
 * The exact path writes the determinant as a sum of six products of input coordinates,
 * turns each product into two doubles with a fused multiply-add (the rounded product
 * and its exact error), and adds the twelve doubles into an expansion with TwoSum. That
 * is exact as long as no product overflows and no product's error term underflows, which
 * the layer's coordinate bounds (QK_REGION_MIN_COORD..QK_REGION_MAX_COORD, or 0)
 * guarantee. This file must be compiled without floating-point contraction
 * (-ffp-contract=off; CMakeLists.txt sets it): a contracted TwoSum is not exact.
 */
#include <math.h>

#include "region/region_internal.h"

/* a + b = s + e exactly (Knuth's TwoSum, no ordering needed). */
static inline void two_sum(double a, double b, double *s, double *e) {
  double x = a + b;
  double bv = x - a;
  double av = x - bv;
  *s = x;
  *e = (a - av) + (b - bv);
}

/* Add q to the expansion h[0..n) (increasing magnitude, non-overlapping), dropping zero
 * components (Shewchuk's Grow-Expansion with zero elimination). Returns the new length. */
static int grow(double *h, int n, double q) {
  int m = 0;
  for (int i = 0; i < n; i++) {
    double s, e;
    two_sum(q, h[i], &s, &e);
    q = s;
    if (e != 0.0) h[m++] = e;
  }
  if (q != 0.0 || m == 0) h[m++] = q;
  return m;
}

int qk__orient_exact(double ax, double ay, double bx, double by, double cx, double cy) {
  /* (bx-ax)(cy-ay) - (by-ay)(cx-ax) = bx cy - bx ay - ax cy - by cx + by ax + ay cx */
  const double f[6][2] = {{bx, cy}, {-bx, ay}, {-ax, cy}, {-by, cx}, {by, ax}, {ay, cx}};
  double h[16];
  int n = 0;
  for (int i = 0; i < 6; i++) {
    double p = f[i][0] * f[i][1];
    double e = fma(f[i][0], f[i][1], -p);
    n = grow(h, n, e);
    n = grow(h, n, p);
  }
  /* The most significant nonzero component carries the sign. */
  for (int i = n - 1; i >= 0; i--)
    if (h[i] != 0.0) return h[i] > 0.0 ? 1 : -1;
  return 0;
}
