/*
 * Exact points on input segments for the general mesh mode (docs/mesh-general.md,
 * section 3). A coordinate pair (a, b), both multiples of 2^e and below 2^E in magnitude,
 * has b - a a multiple of 2^e below 2^(E+1), a double when E + 1 - e <= 53; scaled by
 * 2^-m and multiplied by k <= 2^m it stays a multiple of 2^(e-m) below 2^(E+1), a double
 * when m <= 52 - (E - e); and a plus it lies between a and b, so below 2^E and a multiple
 * of 2^(e-m): a double too. Every operation's exact result is a double, so each is exact.
 */
#include <math.h>
#include <string.h>

#include "mesh/general_internal.h"

/* For finite x != 0: the exponent of its lowest set bit (x is an odd multiple of 2^*lsb)
 * and the q with 2^(q-1) <= |x| < 2^q, read off the bits (frexp's q, without the call). */
static void bit_exps(double x, int *lsb, int *q) {
  uint64_t u;
  memcpy(&u, &x, sizeof u);
  int be = (int)(u >> 52 & 0x7ff);
  uint64_t mant = u & (((uint64_t)1 << 52) - 1);
  int e0 = -1074; /* x = mant 2^e0 */
  if (be) mant |= (uint64_t)1 << 52, e0 = be - 1075;
  int tz = 0, top = 0;
#if defined(__GNUC__)
  tz = __builtin_ctzll(mant); /* mant != 0 */
  top = 63 - __builtin_clzll(mant);
#else
  while (!(mant >> tz & 1)) tz++;
  top = 63;
  while (!(mant >> top & 1)) top--;
#endif
  *lsb = e0 + tz;
  *q = e0 + top + 1;
}

/* Budget of one coordinate pair. */
static int pair_budget(double a, double b) {
  if (a == b) return QK__SEG_BUDGET_MAX;
  int e = INT32_MAX, big = INT32_MIN, q;
  double v[2] = {a, b};
  for (int i = 0; i < 2; i++) {
    if (v[i] == 0) continue;
    int l;
    bit_exps(v[i], &l, &q); /* |v| < 2^q */
    if (l < e) e = l;
    if (q > big) big = q;
  }
  int m = 52 - (big - e);
  /* Keep every intermediate a normal double: multiples of 2^(e-m) with e - m >= -1022. */
  if (m > e + 1022) m = e + 1022;
  return m;
}

int qk__seg_budget(const double a[2], const double b[2]) {
  int mx = pair_budget(a[0], b[0]), my = pair_budget(a[1], b[1]);
  return mx < my ? mx : my;
}

int qk__seg_point(const double a[2], const double b[2], uint64_t k, int m, double out[2]) {
  if (m < 0 || m > 62 || k > (uint64_t)1 << m) return -1;
  if (k == 0) return out[0] = a[0], out[1] = a[1], 0;
  if (k == (uint64_t)1 << m) return out[0] = b[0], out[1] = b[1], 0;
  if (m > qk__seg_budget(a, b)) return -1;
  qk__seg_point_in(a, b, k, m, out);
  return 0;
}
