/*
 * "%.17g" and "%lu" without printf (mesh/numfmt.h).
 *
 * A finite double is |x| = m 2^e with m < 2^53. printf's "%.17g" prints the 17 significant
 * digits of x correctly rounded: the integer T = round(|x| 10^s), s = 16 - X, where X is
 * the decimal exponent (10^16 <= T < 10^17 after rounding), in fixed notation when
 * -4 <= X < 17 with trailing zeros dropped. For those X, s lies in 0..21 and 5^s < 2^49, so
 * |x| 10^s = m 5^s 2^(e + s) is a 128-bit product shifted: exact integer arithmetic, rounding
 * ties to even on the exact remainder (glibc's rule in the default rounding mode). Other
 * exponents (and compilers without a 128-bit integer) use snprintf itself; the test
 * test_mesh_numfmt compares both on millions of values.
 */
#include "mesh/numfmt.h"

#include <math.h>
#include <string.h>

static const char digit_pairs[201] = "00010203040506070809"
                                     "10111213141516171819"
                                     "20212223242526272829"
                                     "30313233343536373839"
                                     "40414243444546474849"
                                     "50515253545556575859"
                                     "60616263646566676869"
                                     "70717273747576777879"
                                     "80818283848586878889"
                                     "90919293949596979899";

size_t qk__fmt_u64(uint64_t v, char *buf) {
  char t[24];
  size_t n = sizeof t;
  while (v >= 100) {
    unsigned d = (unsigned)(v % 100);
    v /= 100;
    t[--n] = digit_pairs[2 * d + 1], t[--n] = digit_pairs[2 * d];
  }
  if (v >= 10)
    t[--n] = digit_pairs[2 * v + 1], t[--n] = digit_pairs[2 * v];
  else
    t[--n] = (char)('0' + v);
  memcpy(buf, t + n, sizeof t - n);
  return sizeof t - n;
}

#if defined(__SIZEOF_INT128__)
__extension__ typedef unsigned __int128 qk__u128;

static const uint64_t POW5[22] = {1ull,
                                  5ull,
                                  25ull,
                                  125ull,
                                  625ull,
                                  3125ull,
                                  15625ull,
                                  78125ull,
                                  390625ull,
                                  1953125ull,
                                  9765625ull,
                                  48828125ull,
                                  244140625ull,
                                  1220703125ull,
                                  6103515625ull,
                                  30517578125ull,
                                  152587890625ull,
                                  762939453125ull,
                                  3814697265625ull,
                                  19073486328125ull,
                                  95367431640625ull,
                                  476837158203125ull};

#define E16 10000000000000000ull
#define E17 100000000000000000ull

/* The fixed-notation "%.17g" of finite nonzero x, or 0 when x needs the exponent form. */
static size_t g17_fixed(double x, char *buf) {
  uint64_t bits;
  memcpy(&bits, &x, sizeof bits);
  int be = (int)((bits >> 52) & 0x7FF);
  if (be == 0) return 0; /* subnormal: far outside the fixed range */
  uint64_t m = (bits & (((uint64_t)1 << 52) - 1)) | (uint64_t)1 << 52;
  int q = be - 1022, e = q - 53; /* |x| = m 2^e = f 2^q, f in [1/2, 1) */
  /* 2^(q-1) <= |x|, so 10^X0 <= |x| with X0 below: X is X0 or X0 + 1 (k log10(2) is never
   * within rounding of an integer for k != 0 in range). */
  int X = (int)floor((double)(q - 1) * 0.30102999566398120), tries = 0;
  uint64_t T;
  for (;;) {
    if (X < -5 || X > 16 || ++tries > 2) return 0;
    int s = 16 - X, sh = e + s;
    qk__u128 p = (qk__u128)m * POW5[s];
    if (sh >= 0) {
      if (sh >= 64 || (p << sh) >> 64) return 0;
      T = (uint64_t)(p << sh);
    } else {
      int r = -sh;
      if (r >= 127) return 0;
      qk__u128 hi = p >> r, rem = p - (hi << r), half = (qk__u128)1 << (r - 1);
      if (hi >> 64) return 0;
      T = (uint64_t)hi;
      if (T >= E17) { /* X was one too small */
        X++;
        continue;
      }
      T += rem > half || (rem == half && (T & 1));
    }
    if (T >= E17 && sh >= 0) {
      X++;
      continue;
    }
    break;
  }
  if (T == E17) T = E16, X++;
  if (T < E16 || X < -4 || X > 16) return 0;
  char d[18];
  for (int i = 15; i >= 1; i -= 2) {
    unsigned r = (unsigned)(T % 100);
    T /= 100;
    d[i] = digit_pairs[2 * r], d[i + 1] = digit_pairs[2 * r + 1];
  }
  d[0] = (char)('0' + T);
  int nd = 17;
  while (nd > 1 && d[nd - 1] == '0') nd--;
  size_t n = 0;
  if (x < 0) buf[n++] = '-';
  if (X >= 0) {
    memcpy(buf + n, d, (size_t)X + 1), n += (size_t)X + 1;
    if (nd > X + 1) {
      buf[n++] = '.';
      memcpy(buf + n, d + X + 1, (size_t)(nd - X - 1)), n += (size_t)(nd - X - 1);
    }
  } else {
    buf[n++] = '0', buf[n++] = '.';
    for (int i = -1; i > X; i--) buf[n++] = '0';
    memcpy(buf + n, d, (size_t)nd), n += (size_t)nd;
  }
  buf[n] = 0;
  return n;
}
#endif

size_t qk__fmt_g17(double x, char *buf) {
#if defined(__SIZEOF_INT128__)
  if (isfinite(x) && x != 0) {
    size_t n = g17_fixed(x, buf);
    if (n) return n;
  }
#endif
  int n = snprintf(buf, QK__NUMFMT_MAX, "%.17g", x);
  return n < 0 ? 0 : (size_t)n;
}

void qk__wbuf_flush(qk__wbuf_t *w) {
  if (w->n) fwrite(w->b, 1, w->n, w->f);
  w->n = 0;
}
