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

/* Two digits of d < 100 at p. */
static inline void put2(char *p, unsigned d) { memcpy(p, digit_pairs + 2 * d, 2); }

static const uint64_t P10[20] = {1ull,
                                 10ull,
                                 100ull,
                                 1000ull,
                                 10000ull,
                                 100000ull,
                                 1000000ull,
                                 10000000ull,
                                 100000000ull,
                                 1000000000ull,
                                 10000000000ull,
                                 100000000000ull,
                                 1000000000000ull,
                                 10000000000000ull,
                                 100000000000000ull,
                                 1000000000000000ull,
                                 10000000000000000ull,
                                 100000000000000000ull,
                                 1000000000000000000ull,
                                 10000000000000000000ull};

#if defined(__BYTE_ORDER__) && __BYTE_ORDER__ == __ORDER_LITTLE_ENDIAN__
#define QK__SWAR8 1
/*
 * The 8 decimal digits of v < 10^8 as the bytes of a word, first digit lowest (its memory
 * order on a little-endian machine), '0' not added: split into two 4-digit halves, each
 * into 2-digit and then 1-digit lanes with multiply-shift divisions (x / 100 is
 * x 10486 >> 20 for x < 10^4, x / 10 is x 103 >> 10 for x < 100), every lane at once.
 */
static inline uint64_t digits8(uint32_t v) {
  uint64_t y = (uint64_t)(v / 10000) | (uint64_t)(v % 10000) << 32;
  uint64_t z = ((y * 10486) >> 20) & 0x0000007F0000007Full;
  y = z | (y - 100 * z) << 16;
  z = ((y * 103) >> 10) & 0x000F000F000F000Full;
  return z | (y - 10 * z) << 8;
}
#endif

/* The 8 digits of v < 10^8 at p. */
static inline void put8(char *p, uint32_t v) {
#if defined(QK__SWAR8)
  uint64_t y = digits8(v) + 0x3030303030303030ull;
  memcpy(p, &y, 8);
#else
  uint32_t a = v / 10000, b = v % 10000;
  put2(p, a / 100), put2(p + 2, a % 100), put2(p + 4, b / 100), put2(p + 6, b % 100);
#endif
}

/* Decimal digits of v (1 for 0). */
static inline size_t n_digits(uint64_t v) {
#if defined(__GNUC__)
  /* floor(bits log10(2)) is the count or one less (1233 / 4096 is just above log10(2)). */
  size_t n = (size_t)((64 - __builtin_clzll(v | 1)) * 1233) >> 12;
  return n + ((v | 1) >= P10[n]);
#else
  size_t n = 1;
  while (n < 20 && v >= P10[n]) n++;
  return n;
#endif
}

/* The digits are written from the end, two at a time, straight into buf; values that fit
 * 32 bits (vertex and triangle numbers) divide in 32 bits. */
size_t qk__fmt_u64(uint64_t v, char *buf) {
#if defined(QK__SWAR8) && defined(__GNUC__)
  if (v < 100000000u) {
    /* The leading zero digits are the word's low zero bytes; the last n of the 8 digits
     * move to the word's first bytes. */
    uint64_t y = digits8((uint32_t)v);
    size_t n = y ? 8 - (size_t)__builtin_ctzll(y) / 8 : 1;
    y = (y + 0x3030303030303030ull) >> (8 * (8 - n));
    memcpy(buf, &y, 8);
    return n;
  }
#endif
  size_t n = n_digits(v);
  char *p = buf + n;
  while (v > UINT32_MAX) {
    unsigned d = (unsigned)(v % 100);
    v /= 100;
    put2(p -= 2, d);
  }
  uint32_t w = (uint32_t)v;
  while (w >= 100) {
    unsigned d = w % 100;
    w /= 100;
    put2(p -= 2, d);
  }
  if (w >= 10)
    put2(p - 2, w);
  else
    p[-1] = (char)('0' + w);
  return n;
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
  /* 2^(q-1) <= |x|, so 10^X0 <= |x| with X0 = floor((q - 1) log10(2)), here as
   * floor((q - 1) 78913 / 2^18) (exact for |q - 1| < 1650; 78913 / 2^18 is just below
   * log10(2); offset by 16 so that the shifted value is not negative):
   * X is X0 or X0 + 1 (k log10(2) is never within rounding of an integer for k != 0 in
   * range). Only the fixed range matters; beyond it the estimate is not used. */
  if (q < -30 || q > 70) return 0;
  int X = (int)(((uint32_t)((q - 1) * 78913 + (16 << 18))) >> 18) - 16, tries = 0;
  uint64_t T;
  for (;;) {
    if (X < -5 || X > 16 || ++tries > 2) return 0;
    int s = 16 - X, sh = e + s;
    qk__u128 p = (qk__u128)m * POW5[s];
    if (sh >= 0) {
      if (sh >= 64 || (p << sh) >> 64) return 0;
      T = (uint64_t)(p << sh);
    } else if (sh > -64) {
      /* The common case: the quotient and remainder of a shift by r < 64, in 64 bits. */
      int r = -sh;
      uint64_t lo = (uint64_t)p, hi = (uint64_t)(p >> 64);
      if (hi >> r) return 0;
      T = (lo >> r) | (r ? hi << (64 - r) : 0);
      uint64_t rem = lo & (((uint64_t)1 << r) - 1), half = (uint64_t)1 << (r - 1);
      if (T >= E17) { /* X was one too small */
        X++;
        continue;
      }
      T += rem > half || (rem == half && (T & 1));
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
  /* The 17 digits: T = d0 10^16 + hi 10^8 + lo. */
  char d[33]; /* 17 digits, then zeros for the fixed-size copy below */
  memset(d + 17, '0', 16);
  uint64_t top = T / 100000000u;
  uint32_t lo = (uint32_t)(T - top * 100000000u);
  d[0] = (char)('0' + top / 100000000u);
  put8(d + 1, (uint32_t)(top % 100000000u)), put8(d + 9, lo);
  int nd = 17;
  while (nd > 1 && d[nd - 1] == '0') nd--;
  size_t n = 0;
  if (x < 0) buf[n++] = '-';
  /* Fixed-size copies (a few moves each); buf has QK__NUMFMT_MAX bytes, and at most
   * 1 + 2 + 4 + 17 or 1 + 17 + 1 + 16 of them are touched. */
  if (X >= 0) {
    memcpy(buf + n, d, 17);
    if (nd > X + 1) {
      memcpy(buf + n + X + 2, d + X + 1, 16);
      buf[n + (size_t)X + 1] = '.';
      n += (size_t)nd + 1;
    } else {
      n += (size_t)X + 1;
    }
  } else {
    memcpy(buf + n, "0.0000", 6);
    memcpy(buf + n + 1 - X, d, 17);
    n += (size_t)(1 - X) + (size_t)nd;
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
  int n = snprintf(buf, QK__NUMFMT_MAX, "%.17g", x + 0.0); /* (-0 + 0 is +0) */
  return n < 0 ? 0 : (size_t)n;
}

void qk__wbuf_flush(qk__wbuf_t *w) {
  if (w->n) fwrite(w->b, 1, w->n, w->f);
  w->n = 0;
}
