/*
 * The exact distance test behind the radius query's and the static collider's filters:
 * every finite double is an integer multiple of 2^-1074 below 2^1024, so after scaling by
 * a common power of two the five inputs are integers of at most 2100 bits, and the test
 * is one comparison of sums of squares of integers (at most 4200 bits). Schoolbook
 * arithmetic on 32-bit limbs: slow, and only reached when a point lies within a relative
 * 2^-45 of the boundary or the values are beyond 2^500. The kNN searches compare two
 * points' distances to a query the same way (qk__dist_cmp_exact) when their squares in
 * doubles lie within the filter's margin of each other. Both first try the doubles
 * themselves (qk__d2_exact): where every operation is exact, as on grids of dyadic steps,
 * whose ties are the common case, no big integer is made.
 */
#include <math.h>
#include <stdint.h>
#include <string.h>

#include "index/dist_exact.h"

enum { LIMBS = 68, WIDE = 2 * LIMBS + 2 };

typedef struct big {
  int n;            /* limbs in use: the value is w[0] .. w[n - 1] */
  uint32_t w[WIDE]; /* little-endian magnitude */
} big_t;

/* Limb k of a, 0 beyond its length. */
static inline uint32_t limb_at(const big_t *a, int k) { return k < a->n ? a->w[k] : 0; }
static inline int max_i(int a, int b) { return a > b ? a : b; }

/* |v| as an integer multiple of 2^e0 (e0 no larger than v's lowest digit's exponent). */
static void big_set(big_t *b, double v, int e0) {
  b->n = 0;
  if (v == 0) return;
  int e;
  double m = frexp(fabs(v), &e);        /* |v| = m 2^e, m in [0.5, 1) */
  uint64_t mi = (uint64_t)ldexp(m, 53); /* |v| = mi 2^(e - 53), exactly */
  int shift = e - 53 - e0;              /* >= 0, below 32 LIMBS - 86 */
  int limb = shift / 32, bit = shift % 32;
  uint64_t lo = mi << bit, hi = bit ? mi >> (64 - bit) : 0; /* mi 2^bit, below 2^86 */
  memset(b->w, 0, (size_t)limb * sizeof b->w[0]);
  b->w[limb] = (uint32_t)lo, b->w[limb + 1] = (uint32_t)(lo >> 32), b->w[limb + 2] = (uint32_t)hi;
  b->n = limb + 3;
}

static int big_cmp(const big_t *a, const big_t *b) {
  for (int k = max_i(a->n, b->n) - 1; k >= 0; k--) {
    const uint32_t x = limb_at(a, k), y = limb_at(b, k);
    if (x != y) return x < y ? -1 : 1;
  }
  return 0;
}

static void big_add(big_t *out, const big_t *a, const big_t *b) {
  const int n = max_i(a->n, b->n);
  uint64_t c = 0;
  for (int k = 0; k < n; k++) {
    c += (uint64_t)limb_at(a, k) + limb_at(b, k);
    out->w[k] = (uint32_t)c;
    c >>= 32;
  }
  out->w[n] = (uint32_t)c;
  out->n = n + 1;
}

/* out = a - b, a >= b. */
static void big_sub(big_t *out, const big_t *a, const big_t *b) {
  int64_t c = 0;
  for (int k = 0; k < a->n; k++) {
    c += (int64_t)a->w[k] - limb_at(b, k);
    out->w[k] = (uint32_t)c;
    c = c < 0 ? -1 : 0;
  }
  out->n = a->n;
}

/* |sa A - sb B| for magnitudes A, B with signs sa, sb (1 for negative). */
static void big_absdiff(big_t *out, const big_t *a, int sa, const big_t *b, int sb) {
  if (sa != sb)
    big_add(out, a, b);
  else if (big_cmp(a, b) >= 0)
    big_sub(out, a, b);
  else
    big_sub(out, b, a);
}

/* out = a^2 (a below 2^(32 LIMBS)): 2n limbs for a of n. */
static void big_sqr(big_t *out, const big_t *a) {
  int n = a->n;
  while (n > 0 && a->w[n - 1] == 0) n--;
  memset(out->w, 0, (size_t)(2 * n) * sizeof out->w[0]);
  out->n = 2 * n;
  for (int i = 0; i < n; i++) {
    uint64_t c = 0;
    for (int j = 0; j < n; j++) {
      c += (uint64_t)a->w[i] * a->w[j] + out->w[i + j];
      out->w[i + j] = (uint32_t)c;
      c >>= 32;
    }
    for (int k = i + n; c; k++) { /* below 2n: the partial sums stay below a^2 */
      c += out->w[k];
      out->w[k] = (uint32_t)c;
      c >>= 32;
    }
  }
}

/* A power of two that divides v: 2^(e - 53) for |v| = m 2^e (a large value for 0). */
static int low_exp(double v) {
  if (v == 0) return 1 << 20;
  int e;
  frexp(v, &e);
  return e - 53;
}

/* The squared distance from (qx, qy) to (px, py) into *out, all four inputs integers in
 * units of 2^e0. */
static void big_d2(big_t *out, double qx, double qy, double px, double py, int e0) {
  big_t a, b, dx, dy, s;
  big_set(&a, px, e0), big_set(&b, qx, e0);
  big_absdiff(&dx, &a, px < 0, &b, qx < 0);
  big_set(&a, py, e0), big_set(&b, qy, e0);
  big_absdiff(&dy, &a, py < 0, &b, qy < 0);
  big_sqr(&s, &dx);
  big_sqr(&a, &dy);
  big_add(out, &s, &a);
}

/* The lowest of the six values' low_exp: every one an integer in units of 2^that. */
static int low_exp6(double a, double b, double c, double d, double e, double f) {
  const double v[6] = {a, b, c, d, e, f};
  int e0 = 1 << 20;
  for (int k = 0; k < 6; k++) {
    int x = low_exp(v[k]);
    if (x < e0) e0 = x;
  }
  return e0;
}

int qk__within_exact(double ax, double ay, double bx, double by, double r1, double r2) {
  double dd, rr = r1 + r2;
  /* Exact in doubles (grids of dyadic steps): rs * rs is then exact too, or overflows to
   * inf where the exact square exceeds every double, d2 included. */
  if (qk__d2_exact(bx, by, ax, ay, &dd) && qk__sum_exact(r1, r2, rr) && qk__square_exact(rr))
    return dd <= rr * rr;
  const int e0 = low_exp6(ax, bx, ay, by, r1, r2);
  big_t a, b, d2, rs;
  big_d2(&d2, bx, by, ax, ay, e0);
  big_set(&a, r1, e0), big_set(&b, r2, e0);
  big_add(&rs, &a, &b); /* radii are >= 0 */
  big_sqr(&a, &rs);
  return big_cmp(&d2, &a) <= 0;
}

int qk__dist_cmp_exact(double qx, double qy, double ax, double ay, double bx, double by) {
  double da, db;
  if (qk__d2_exact(qx, qy, ax, ay, &da) && qk__d2_exact(qx, qy, bx, by, &db))
    return (da > db) - (da < db);
  const int e0 = low_exp6(qx, qy, ax, ay, bx, by);
  big_t ba, bb;
  big_d2(&ba, qx, qy, ax, ay, e0);
  big_d2(&bb, qx, qy, bx, by, e0);
  return big_cmp(&ba, &bb);
}
