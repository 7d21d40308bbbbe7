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
 * of two-products and two-sums.
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

/* a + b = *s + *e exactly (Knuth's two-sum: six operations, no branch). */
static inline void two_sum(double a, double b, double *s, double *e) {
  double x = a + b, bv = x - a, av = x - bv;
  *s = x;
  *e = (a - av) + (b - bv);
}

/* a * b = *p + *e exactly (barring underflow and overflow): with a fused multiply-add when
 * the hardware has one, else by Dekker's splitting into 26-bit halves. */
static inline void two_prod(double a, double b, double *p, double *e) {
  double x = a * b;
  *p = x;
#ifdef FP_FAST_FMA
  *e = fma(a, b, -x);
#else
  const double split = 134217729.0; /* 2^27 + 1 */
  double ca = split * a, ah = ca - (ca - a), al = a - ah;
  double cb = split * b, bh = cb - (cb - b), bl = b - bh;
  *e = al * bl - (((x - ah * bh) - al * bh) - ah * bl);
#endif
}

/* Add q to the expansion h[0..*n): the chain of two-sums from the smallest component up
 * keeps the result nonoverlapping and ordered; zero components are dropped. h must have
 * room for *n + 1 components. */
static void grow(double *h, int *n, double q) {
  int m = 0;
  for (int i = 0; i < *n; i++) {
    double s, e;
    two_sum(q, h[i], &s, &e);
    if (e != 0) h[m++] = e;
    q = s;
  }
  if (q != 0) h[m++] = q;
  *n = m;
}

/* h += f (f's components added one by one; h needs room for *nh + nf components). */
static void add_to(double *h, int *nh, const double *f, int nf) {
  for (int i = 0; i < nf; i++) grow(h, nh, f[i]);
}

/* h = b * e, for an expansion e of n components: each e[i] * b is split into its rounded
 * product and error, and both are carried up into the running high part, whose lower
 * parts are emitted in increasing order. h has room for 2n components; returns the count. */
static int scale(const double *e, int n, double b, double *h) {
  if (n == 0 || b == 0) return 0;
  int m = 0;
  double q, lo;
  two_prod(e[0], b, &q, &lo);
  if (lo != 0) h[m++] = lo;
  for (int i = 1; i < n; i++) {
    double p, pe, s, se, t, te;
    two_prod(e[i], b, &p, &pe);
    two_sum(q, pe, &s, &se);
    if (se != 0) h[m++] = se;
    two_sum(p, s, &t, &te);
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
  two_sum(a, -b, &s, &e);
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

int qk__incircle_exact(const double a[2], const double b[2], const double c[2], const double d[2]) {
  double dx[3][2], dy[3][2];
  int nx[3], ny[3];
  const double *pt[3] = {a, b, c};
  for (int i = 0; i < 3; i++) {
    nx[i] = diff(pt[i][0], d[0], dx[i]);
    ny[i] = diff(pt[i][1], d[1], dy[i]);
  }
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
 * its error is below ((1 + u)^11 - 1) times the sum of the monomials' magnitudes, which the
 * computed permanent (the same expression with absolute values) bounds within a factor
 * (1 - u)^-12: below 12u * permanent < 2^-49 * permanent.
 */
int qk__incircle(const double a[2], const double b[2], const double c[2], const double d[2]) {
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
