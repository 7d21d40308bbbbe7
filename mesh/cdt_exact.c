/*
 * Exact predicates of the constrained Delaunay triangulation (mesh/cdt.h): the in-circle
 * determinant and the encroachment sign (a - p) . (b - p), each a floating-point estimate
 * with a proven error bound and an exact fallback in expansion arithmetic.
 *
 * Expansion arithmetic (the technique of Priest and of Shewchuk, "Adaptive precision
 * floating-point arithmetic and fast robust geometric predicates", 1997; our own code):
 * a real number is held as a sum of doubles ordered by increasing magnitude, no two of
 * which overlap (the lowest set bit of the larger lies above the highest set bit of the
 * smaller), zeros dropped. Then the largest component has the sign of the whole sum. Sums
 * and products of doubles are made exact by returning their rounding error as a second
 * double (two-sum, two-product); an expansion grows by one double through a chain of
 * two-sums (the result is again nonoverlapping), and is scaled by a double through a chain
 * of two-products and two-sums. Points on a shared grid (every difference exact and, scaled
 * by a power of two, an integer below 2^30) take a shortcut through 128-bit integers where
 * the compiler has them.
 *
 * Range of exactness: every coordinate is 0 or has magnitude in [2^-200, 2^200]. Then every
 * coordinate is a multiple of 2^-252, every component of a degree-k product of differences
 * is a multiple of 2^(-252k) >= 2^-1008 (so no product's rounding error underflows) and
 * below 2^(202k + 30) <= 2^838 (so nothing overflows, the splitting constant of the
 * two-product included). The filters' error bounds hold in the same range (no underflow
 * in a product; sums that underflow are exact).
 */
#include <math.h>

#include "mesh/cdt.h"
#include "mesh/cdt_internal.h"
#include "mesh/expansion.h"

/* h += f (f's components added one by one; h needs room for *nh + nf components). */
static void add_to(double *h, int *nh, const double *f, int nf) {
  for (int i = 0; i < nf; i++) qk__exp_grow(h, nh, f[i]);
}

/* h = b * e, for an expansion e of n components: each e[i] * b is split into its rounded
 * product and error, and both are carried up into the running high part, whose lower
 * parts are emitted in increasing order. h has room for 2n components; returns the count. */
static int scale(const double *e, int n, double b, double *h) {
  if (n == 0 || b == 0) return 0;
  int m = 0;
  double q, lo;
  qk__two_prod(e[0], b, &q, &lo);
  if (lo != 0) h[m++] = lo;
  for (int i = 1; i < n; i++) {
    double p, pe, s, se, t, te;
    qk__two_prod(e[i], b, &p, &pe);
    qk__two_sum(q, pe, &s, &se);
    if (se != 0) h[m++] = se;
    qk__two_sum(p, s, &t, &te);
    if (te != 0) h[m++] = te;
    q = t;
  }
  if (q != 0) h[m++] = q;
  return m;
}

/* h = e * f (h has room for 2 * ne * nf components, tmp for 2 * ne). */
static int mul(const double *e, int ne, const double *f, int nf, double *h, double *tmp) {
  int nh = 0;
  for (int j = 0; j < nf; j++) {
    int nt = scale(e, ne, f[j], tmp);
    add_to(h, &nh, tmp, nt);
  }
  return nh;
}

/* The exact difference a - b as an expansion of at most two components. */
static int diff(double a, double b, double *h) {
  double s, e;
  qk__two_sum(a, -b, &s, &e);
  int n = 0;
  if (e != 0) h[n++] = e;
  if (s != 0) h[n++] = s;
  return n;
}

static int sign_of(const double *h, int n) { return n == 0 ? 0 : (h[n - 1] > 0 ? 1 : -1); }

static void negate(double *h, int n) {
  for (int i = 0; i < n; i++) h[i] = -h[i];
}

/* h = x1 * y1 + sgn * x2 * y2 (sgn = +1 or -1) for expansions of at most two components
 * (at most 16 out). */
static int cross2(const double *x1, int n1, const double *y1, int m1, const double *x2, int n2,
                  const double *y2, int m2, int sgn, double *h) {
  double p[8], q[8], tmp[4];
  int np = mul(x1, n1, y1, m1, p, tmp), nq = mul(x2, n2, y2, m2, q, tmp);
  if (sgn < 0) negate(q, nq);
  for (int i = 0; i < np; i++) h[i] = p[i];
  int nh = np;
  add_to(h, &nh, q, nq);
  return nh;
}

#ifdef __SIZEOF_INT128__
__extension__ typedef __int128 qk__i128;

/*
 * The in-circle sign in integers, for the common hard case of points on a shared grid (the
 * quadtree's seeds: many exactly cocircular quadruples). The six differences x[0..6) (ax,
 * ay, bx, by, cx, cy, all exact) are scaled by a power of two so the largest is below 2^30;
 * when all are then integers, every product of two is below 2^60, each 2x2 determinant and
 * lift below 2^61, each term below 2^122 and the sum below 2^124: exact in 128 bits.
 * Returns 0 (and *sign untouched) when they are not integers at that scale.
 */
static int incircle_int(const double x[6], int *sign) {
  double m = 0;
  for (int i = 0; i < 6; i++) m = fabs(x[i]) > m ? fabs(x[i]) : m;
  if (m == 0) {
    *sign = 0;
    return 1;
  }
  int e;
  (void)frexp(m, &e);     /* m < 2^e */
  if (e < -900) return 0; /* the scale would overflow: leave it to the expansions */
  double scale = ldexp(1.0, 30 - e);
  int64_t q[6];
  for (int i = 0; i < 6; i++) {
    double v = x[i] * scale; /* exact: a power of two, no overflow (|v| < 2^30) */
    q[i] = (int64_t)v;
    if ((double)q[i] != v) return 0;
  }
  qk__i128 det = 0;
  for (int i = 0; i < 3; i++) {
    int j = (i + 1) % 3, k = (i + 2) % 3;
    qk__i128 lift = (qk__i128)(q[2 * i] * q[2 * i] + q[2 * i + 1] * q[2 * i + 1]);
    qk__i128 d2 = (qk__i128)(q[2 * j] * q[2 * k + 1]) - (qk__i128)(q[2 * j + 1] * q[2 * k]);
    det += lift * d2;
  }
  *sign = det > 0 ? 1 : det < 0 ? -1 : 0;
  return 1;
}
#endif

int qk__incircle_exact(const double a[2], const double b[2], const double c[2], const double d[2]) {
  double dx[3][2], dy[3][2];
  int nx[3], ny[3];
  const double *pt[3] = {a, b, c};
  for (int i = 0; i < 3; i++) {
    nx[i] = diff(pt[i][0], d[0], dx[i]);
    ny[i] = diff(pt[i][1], d[1], dy[i]);
  }
#ifdef __SIZEOF_INT128__
  if (nx[0] < 2 && ny[0] < 2 && nx[1] < 2 && ny[1] < 2 && nx[2] < 2 && ny[2] < 2) {
    /* every difference is one double (or zero): try the integer path */
    double x[6];
    for (int i = 0; i < 3; i++)
      x[2 * i] = nx[i] ? dx[i][0] : 0, x[2 * i + 1] = ny[i] ? dy[i][0] : 0;
    int sign;
    if (incircle_int(x, &sign)) return sign;
  }
#endif
  /* det = sum over i of lift_i * (x_j y_k - y_j x_k), (i, j, k) cyclic. */
  double total[1536];
  int ntot = 0;
  for (int i = 0; i < 3; i++) {
    int j = (i + 1) % 3, k = (i + 2) % 3;
    double lift[16], det2[16], term[512], tmp[32];
    int nl = cross2(dx[i], nx[i], dx[i], nx[i], dy[i], ny[i], dy[i], ny[i], 1, lift);
    int nd = cross2(dx[j], nx[j], dy[k], ny[k], dy[j], ny[j], dx[k], nx[k], -1, det2);
    int nterm = mul(lift, nl, det2, nd, term, tmp);
    add_to(total, &ntot, term, nterm);
  }
  return sign_of(total, ntot);
}

/*
 * The filter: with u = 2^-53, the computed determinant is the exact one with each of its
 * twelve degree-4 monomials perturbed by at most eleven relative roundings (one per
 * difference, square or product, subtraction, lift sum, scaling and the two final sums), so
 * its error is below ((1 + u)^11 - 1) times the sum of the monomials' magnitudes, which
 * mesh/cdt_internal.h bounds by a computed quantity S within a factor (1 - u)^-11: below
 * 12u S < 2^-49 S.
 */
int qk__incircle(const double a[2], const double b[2], const double c[2], const double d[2]) {
  return qk__cdt_incircle(a, b, c, d);
}

/* The sign of (a - p) . (b - p). The estimate's error is below (3u + 16u^2)(|l| + |r|)
 * for its two products l and r (the same expression shape as the orientation's), so an
 * estimate above 2^-50 (|l| + |r|) in magnitude has the right sign. */
int qk__cdt_encroach(const double a[2], const double b[2], const double p[2]) {
  double l = (a[0] - p[0]) * (b[0] - p[0]), r = (a[1] - p[1]) * (b[1] - p[1]);
  double dot = l + r, bound = (fabs(l) + fabs(r)) * 0x1p-50;
  if (dot > bound) return 1;
  if (-dot > bound) return -1;
  double ax[2], bx[2], ay[2], by[2], h[16];
  int nax = diff(a[0], p[0], ax), nbx = diff(b[0], p[0], bx);
  int nay = diff(a[1], p[1], ay), nby = diff(b[1], p[1], by);
  int n = cross2(ax, nax, bx, nbx, ay, nay, by, nby, 1, h);
  return sign_of(h, n);
}
