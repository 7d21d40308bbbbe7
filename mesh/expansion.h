/*
 * Error-free transformations and expansion growth for the general mode's exact predicates
 * (mesh/general_predicates.c, mesh/cdt_exact.c, mesh/general_refine.c). An expansion is an
 * array of doubles, nonoverlapping and ordered by increasing magnitude, whose exact sum is
 * the value it stands for.
 */
#ifndef QK_MESH_EXPANSION_H
#define QK_MESH_EXPANSION_H

#include <math.h>

/* a + b = *s + *e exactly (Knuth's two-sum: six operations, no branch). */
static inline void qk__two_sum(double a, double b, double *s, double *e) {
  double x = a + b, bv = x - a, av = x - bv;
  *s = x;
  *e = (a - av) + (b - bv);
}

/* a * b = *p + *e exactly (barring underflow and overflow): with a fused multiply-add when
 * the hardware has one, else by Dekker's splitting into 26-bit halves. */
static inline void qk__two_prod(double a, double b, double *p, double *e) {
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
static inline void qk__exp_grow(double *h, int *n, double q) {
  int m = 0;
  for (int i = 0; i < *n; i++) {
    double s, e;
    qk__two_sum(q, h[i], &s, &e);
    if (e != 0) h[m++] = e;
    q = s;
  }
  if (q != 0) h[m++] = q;
  *n = m;
}

#endif
