/*
 * Exact orientation for the general mesh mode (docs/mesh-general.md, section 5).
 *
 * The determinant (bx - ax)(cy - ay) - (by - ay)(cx - ax) is first estimated in doubles;
 * its rounding error is at most (3u + 16u^2)(|l| + |r|) for the unit roundoff u = 2^-53
 * and the two products l, r (the standard bound for this expression), so an estimate
 * larger than 2^-50 (|l| + |r|) in magnitude has the right sign. Otherwise every
 * difference is split exactly into a rounded value and its error (two-sum), every product
 * of those parts exactly into a rounded product and its error (fma), and the sixteen
 * resulting doubles are summed exactly into a nonoverlapping expansion (each term added
 * by a chain of two-sums, smallest components first); the sign of an expansion is the
 * sign of its largest nonzero component. Points on a shared grid (exact differences that
 * are integers once scaled below 2^30) take a shortcut through 64-bit integers.
 */
#include <math.h>

#include "mesh/general_internal.h"
#include "mesh/expansion.h"

/* When the four differences are exact and, scaled by one power of two so that the largest
 * is below 2^30, integers (points on a shared grid: the common case of a tie), the
 * determinant is d0 d1 - d2 d3 in 64-bit integers (each product below 2^60). Returns 0 when
 * that does not apply. */
static int sign_int(const double d[4][2], int *sign) {
  double m = 0;
  for (int i = 0; i < 4; i++) {
    if (d[i][1] != 0) return 0;
    m = fabs(d[i][0]) > m ? fabs(d[i][0]) : m;
  }
  if (m == 0) {
    *sign = 0;
    return 1;
  }
  int e;
  (void)frexp(m, &e); /* m < 2^e */
  if (e < -900) return 0;
  double scale = ldexp(1.0, 30 - e);
  int64_t q[4];
  for (int i = 0; i < 4; i++) {
    double v = d[i][0] * scale; /* exact: a power of two, |v| < 2^30 */
    q[i] = (int64_t)v;
    if ((double)q[i] != v) return 0;
  }
  int64_t det = q[0] * q[1] - q[2] * q[3];
  *sign = det > 0 ? 1 : det < 0 ? -1 : 0;
  return 1;
}

static int sign_exact(const double *a, const double *b, const double *c) {
  double d[4][2]; /* bx - ax, cy - ay, by - ay, cx - ax as (value, error) */
  qk__two_sum(b[0], -a[0], &d[0][0], &d[0][1]);
  qk__two_sum(c[1], -a[1], &d[1][0], &d[1][1]);
  qk__two_sum(b[1], -a[1], &d[2][0], &d[2][1]);
  qk__two_sum(c[0], -a[0], &d[3][0], &d[3][1]);
  int sign;
  if (sign_int((const double(*)[2])d, &sign)) return sign;
  double h[17];
  int n = 0;
  for (int pair = 0; pair < 2; pair++) {
    const double *u = d[2 * pair], *v = d[2 * pair + 1];
    double sgn = pair == 0 ? 1.0 : -1.0;
    for (int i = 0; i < 2; i++)
      for (int j = 0; j < 2; j++) {
        double p, e;
        qk__two_prod(sgn * u[i], v[j], &p, &e);
        qk__exp_grow(h, &n, e);
        qk__exp_grow(h, &n, p);
      }
  }
  if (n == 0) return 0;
  return h[n - 1] > 0 ? 1 : -1;
}

int qk__orient2d(const double a[2], const double b[2], const double c[2]) {
  double l = (b[0] - a[0]) * (c[1] - a[1]), r = (b[1] - a[1]) * (c[0] - a[0]);
  double det = l - r, bound = (fabs(l) + fabs(r)) * 0x1p-50; /* as ldexp(., -50), no call */
  if (det > bound) return 1;
  if (-det > bound) return -1;
  return sign_exact(a, b, c);
}

int qk__seg_meets_box(const double a[2], const double b[2], const double lo[2],
                      const double hi[2]) {
  for (int i = 0; i < 2; i++) {
    double smin = a[i] < b[i] ? a[i] : b[i], smax = a[i] < b[i] ? b[i] : a[i];
    if (smax < lo[i] || smin > hi[i]) return 0;
  }
  /* Separating axes of a box and a segment: the two axes (done) and the segment's normal. */
  const double corner[4][2] = {{lo[0], lo[1]}, {hi[0], lo[1]}, {hi[0], hi[1]}, {lo[0], hi[1]}};
  int pos = 0, neg = 0;
  for (int k = 0; k < 4; k++) {
    int o = qk__orient2d(a, b, corner[k]);
    pos += o > 0, neg += o < 0;
  }
  return pos < 4 && neg < 4;
}
