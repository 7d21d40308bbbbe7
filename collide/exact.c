/*
 * Exact signs of the small polynomials the world's overlap tests need, by floating-point
 * expansion arithmetic: a number is held as a sum of doubles whose binary digits do not
 * overlap, and sums and products of such sums are formed without rounding (Dekker's
 * two-sum and two-product, here with fma; the grow / scale / compress steps are those of
 * Shewchuk's "Adaptive precision floating-point arithmetic", 1997). Each predicate first
 * evaluates in plain doubles with a bound on the rounding error and falls back to the
 * exact evaluation only when the sign is in doubt.
 *
 * Exactness needs every product to be representable as a sum of doubles: no overflow and
 * no underflow. The world guarantees it by accepting only coordinates and sizes that are
 * zero or of magnitude in [2^-100, 2^100] (qk__value_ok): then every input is an integer
 * multiple of 2^-152 below 2^101, every polynomial here (degree at most 4) has terms that
 * are multiples of 2^-608 below 2^410, and all of that is inside the double range.
 */
#include <math.h>
#include <string.h>

#include "collide/collide_internal.h"

/*
 * Components of an expansion. A compressed expansion of values that are multiples of
 * 2^-608 below 2^410 has at most 1018 components (one per binary digit at worst); sums
 * and scalings of two such are below twice that. Real inputs produce a handful.
 */
#define XCAP 2048

typedef struct xp {
  int n;
  double v[XCAP];
} xp_t;

static inline void two_sum(double a, double b, double *s, double *e) {
  double x = a + b, bv = x - a, av = x - bv;
  *s = x;
  *e = (a - av) + (b - bv);
}

static inline void fast_two_sum(double a, double b, double *s, double *e) {
  double x = a + b;
  *s = x;
  *e = b - (x - a);
}

static inline void two_prod(double a, double b, double *p, double *e) {
  double x = a * b;
  *p = x;
  *e = fma(a, b, -x);
}

/* h = e + b (h may not alias e). */
static void x_grow(const xp_t *e, double b, xp_t *h) {
  double q = b, hh;
  int k = 0;
  for (int i = 0; i < e->n; i++) {
    two_sum(q, e->v[i], &q, &hh);
    if (hh != 0) h->v[k++] = hh;
  }
  if (q != 0 || k == 0) h->v[k++] = q;
  h->n = k;
}

/* Shewchuk's Compress: the same value in fewer, non-adjacent components (in place). */
static void x_compress(xp_t *e) {
  int m = e->n;
  if (m < 2) return;
  double g[XCAP];
  int bottom = m - 1;
  double q = e->v[bottom], qn, s;
  for (int i = m - 2; i >= 0; i--) {
    fast_two_sum(q, e->v[i], &qn, &s);
    if (s != 0) {
      g[bottom--] = qn;
      q = s;
    } else {
      q = qn;
    }
  }
  g[bottom] = q;
  int top = 0;
  for (int i = bottom + 1; i < m; i++) {
    fast_two_sum(g[i], q, &qn, &s);
    if (s != 0) e->v[top++] = s;
    q = qn;
  }
  e->v[top++] = q;
  e->n = top;
}

/* a += b (componentwise growth, then compressed). */
static void x_add(xp_t *a, const xp_t *b, xp_t *tmp) {
  for (int i = 0; i < b->n; i++) {
    x_grow(a, b->v[i], tmp);
    memcpy(a->v, tmp->v, (size_t)tmp->n * sizeof(double));
    a->n = tmp->n;
  }
  x_compress(a);
}

/* h = e * b (Shewchuk's Scale-Expansion with zero elimination). */
static void x_scale(const xp_t *e, double b, xp_t *h) {
  double q, hh, t, tt, q2;
  int k = 0;
  two_prod(e->v[0], b, &q, &hh);
  if (hh != 0) h->v[k++] = hh;
  for (int i = 1; i < e->n; i++) {
    two_prod(e->v[i], b, &t, &tt);
    two_sum(q, tt, &q2, &hh);
    if (hh != 0) h->v[k++] = hh;
    fast_two_sum(t, q2, &q, &hh);
    if (hh != 0) h->v[k++] = hh;
  }
  if (q != 0 || k == 0) h->v[k++] = q;
  h->n = k;
}

/* h = e * f, with scratch s and t. */
static void x_mul(const xp_t *e, const xp_t *f, xp_t *h, xp_t *s, xp_t *t) {
  h->n = 1;
  h->v[0] = 0;
  for (int i = 0; i < f->n; i++) {
    x_scale(e, f->v[i], s);
    x_compress(s); /* so that h and s together stay within XCAP */
    x_add(h, s, t);
  }
}

static inline void x_set_diff(xp_t *e, double a, double b) {
  double s, r;
  two_sum(a, -b, &s, &r);
  e->n = 0;
  if (r != 0) e->v[e->n++] = r;
  e->v[e->n++] = s;
}

static inline void x_set_sum(xp_t *e, double a, double b) { x_set_diff(e, a, -b); }

static inline void x_neg(xp_t *e) {
  for (int i = 0; i < e->n; i++) e->v[i] = -e->v[i];
}

static inline int x_sign(const xp_t *e) {
  double top = e->v[e->n - 1];
  return (top > 0) - (top < 0);
}

/* Scratch for one predicate: kept off the caller's stack frame by being one block. */
typedef struct xs {
  xp_t a, b, c, d, e, f, s, t;
} xs_t;

/* ---- predicates ------------------------------------------------------------------ */

#define EPS 0x1p-53

/* (b - a) x (c - a), exactly, into x (returned). */
static const xp_t *orient_x(xs_t *x, double ax, double ay, double bx, double by, double cx,
                            double cy) {
  x_set_diff(&x->a, bx, ax);
  x_set_diff(&x->b, cy, ay);
  x_mul(&x->a, &x->b, &x->c, &x->s, &x->t); /* (bx-ax)(cy-ay) */
  x_set_diff(&x->a, by, ay);
  x_set_diff(&x->b, cx, ax);
  x_mul(&x->a, &x->b, &x->d, &x->s, &x->t); /* (by-ay)(cx-ax) */
  x_neg(&x->d);
  x_add(&x->c, &x->d, &x->t);
  return &x->c;
}

int qk__orient(double ax, double ay, double bx, double by, double cx, double cy) {
  double l = (bx - ax) * (cy - ay), r = (by - ay) * (cx - ax);
  double det = l - r, bound = 8 * EPS * (fabs(l) + fabs(r));
  if (det > bound) return 1;
  if (-det > bound) return -1;
  xs_t xs; /* not zeroed: every part is written before it is read */
  return x_sign(orient_x(&xs, ax, ay, bx, by, cx, cy));
}

/* The value of an expansion, summed from its smallest component up in long double: its
 * components do not overlap, so the sum is within a few units of long double's last place
 * of the value. */
static long double x_value(const xp_t *e) {
  long double v = 0;
  for (int i = 0; i < e->n; i++) v += e->v[i];
  return v;
}

/* The value functions below evaluate in long double (differences of doubles rounded by at
 * most 2^-64 relative, products and sums by as much again: an error below 2^-60 of the
 * terms' magnitudes) and keep that value when it is at least 2^-6 of them (so within
 * 2^-54 of itself: below a double's rounding); otherwise, where the terms cancel, they
 * sum the exact expansion. */
#define VALUE_KEEP 0x1p-6L

long double qk__orient_value(double ax, double ay, double bx, double by, double cx, double cy) {
  long double l = ((long double)bx - ax) * ((long double)cy - ay);
  long double r = ((long double)by - ay) * ((long double)cx - ax), d = l - r;
  if (fabsl(d) >= VALUE_KEEP * (fabsl(l) + fabsl(r))) return d;
  xs_t xs;
  return x_value(orient_x(&xs, ax, ay, bx, by, cx, cy));
}

/* (b - a).(c - a), exactly, into x (returned). */
static const xp_t *dot_x(xs_t *x, double ax, double ay, double bx, double by, double cx,
                         double cy) {
  x_set_diff(&x->a, bx, ax);
  x_set_diff(&x->b, cx, ax);
  x_mul(&x->a, &x->b, &x->c, &x->s, &x->t);
  x_set_diff(&x->a, by, ay);
  x_set_diff(&x->b, cy, ay);
  x_mul(&x->a, &x->b, &x->d, &x->s, &x->t);
  x_add(&x->c, &x->d, &x->t);
  return &x->c;
}

/* sign of u.v with u = b - a, v = c - a. */
int qk__dot_sign(double ax, double ay, double bx, double by, double cx, double cy) {
  double l = (bx - ax) * (cx - ax), r = (by - ay) * (cy - ay);
  double dot = l + r, bound = 8 * EPS * (fabs(l) + fabs(r));
  if (dot > bound) return 1;
  if (-dot > bound) return -1;
  xs_t xs; /* not zeroed: every part is written before it is read */
  return x_sign(dot_x(&xs, ax, ay, bx, by, cx, cy));
}

long double qk__dot_value(double ax, double ay, double bx, double by, double cx, double cy) {
  long double l = ((long double)bx - ax) * ((long double)cx - ax);
  long double r = ((long double)by - ay) * ((long double)cy - ay), d = l + r;
  if (fabsl(d) >= VALUE_KEEP * (fabsl(l) + fabsl(r))) return d;
  xs_t xs;
  return x_value(dot_x(&xs, ax, ay, bx, by, cx, cy));
}

/* r^2 - (ax-bx)^2 - (ay-by)^2 with r = r1 + r2, exactly, into x (returned). */
static const xp_t *within_x(xs_t *x, double ax, double ay, double bx, double by, double r1,
                            double r2) {
  x_set_sum(&x->a, r1, r2);
  x_mul(&x->a, &x->a, &x->c, &x->s, &x->t); /* rs^2 */
  x_set_diff(&x->a, ax, bx);
  x_mul(&x->a, &x->a, &x->d, &x->s, &x->t);
  x_neg(&x->d);
  x_add(&x->c, &x->d, &x->t);
  x_set_diff(&x->a, ay, by);
  x_mul(&x->a, &x->a, &x->d, &x->s, &x->t);
  x_neg(&x->d);
  x_add(&x->c, &x->d, &x->t);
  return &x->c;
}

/* sign of r^2 - (ax-bx)^2 - (ay-by)^2, with r = r1 + r2 (exact sum). */
int qk__within(double ax, double ay, double bx, double by, double r1, double r2) {
  double dx = ax - bx, dy = ay - by, rs = r1 + r2;
  double p = rs * rs, q = dx * dx + dy * dy;
  double d = p - q, bound = 16 * EPS * (p + q);
  if (d > bound) return 1;
  if (-d > bound) return -1;
  xs_t xs; /* not zeroed: every part is written before it is read */
  return x_sign(within_x(&xs, ax, ay, bx, by, r1, r2));
}

long double qk__within_value(double ax, double ay, double bx, double by, double r1, double r2) {
  long double dx = (long double)ax - bx, dy = (long double)ay - by, rs = (long double)r1 + r2;
  long double p = rs * rs, q = dx * dx + dy * dy, d = p - q;
  if (fabsl(d) >= VALUE_KEEP * (p + q)) return d;
  xs_t xs;
  return x_value(within_x(&xs, ax, ay, bx, by, r1, r2));
}

/*
 * sign of r^2 |q - p|^2 - ((q - p) x (c - p))^2: nonnegative exactly when the line
 * through p and q passes within r of c. First in doubles: with the four differences
 * rounded (a relative error of at most eps = 2^-53 each), the cross product is within
 * about 4 eps C of its value (C = |dx ey| + |dy ex|), its square within 11 eps C^2, and
 * A = r^2 |q - p|^2 (all terms positive) within 6 eps A; with the last subtraction the
 * computed value is within 7 eps A + 12 eps C^2 of the real one, well inside the bound of
 * 32 eps (A + C^2) taken here (no term under- or overflows for values the world
 * accepts). Exactly when the value lies within that bound (a ray or segment grazing a
 * disc: the world's ray queries reach this for most discs they meet, which made the
 * exact path three quarters of a ray query's work in a world of discs).
 */
/* r^2 |q - p|^2 - ((q - p) x (c - p))^2, exactly, into x (returned). */
static const xp_t *line_within_x(xs_t *x, double px, double py, double qx, double qy, double cx,
                                 double cy, double r) {
  /* cross = (qx-px)(cy-py) - (qy-py)(cx-px) */
  x_set_diff(&x->a, qx, px);
  x_set_diff(&x->b, cy, py);
  x_mul(&x->a, &x->b, &x->c, &x->s, &x->t);
  x_set_diff(&x->a, qy, py);
  x_set_diff(&x->b, cx, px);
  x_mul(&x->a, &x->b, &x->d, &x->s, &x->t);
  x_neg(&x->d);
  x_add(&x->c, &x->d, &x->t); /* c = cross */
  x_mul(&x->c, &x->c, &x->e, &x->s, &x->t);
  x_neg(&x->e); /* e = -cross^2 */
  /* |q-p|^2 r^2 */
  x_set_diff(&x->a, qx, px);
  x_mul(&x->a, &x->a, &x->c, &x->s, &x->t);
  x_set_diff(&x->a, qy, py);
  x_mul(&x->a, &x->a, &x->d, &x->s, &x->t);
  x_add(&x->c, &x->d, &x->t); /* c = |q-p|^2 */
  x->a.n = 1;
  x->a.v[0] = r;
  x_mul(&x->c, &x->a, &x->d, &x->s, &x->t);
  x_mul(&x->d, &x->a, &x->f, &x->s, &x->t); /* f = |q-p|^2 r^2 */
  x_add(&x->f, &x->e, &x->t);
  return &x->f;
}

int qk__line_within(double px, double py, double qx, double qy, double cx, double cy, double r) {
  {
    const double dx = qx - px, dy = qy - py, ex = cx - px, ey = cy - py;
    const double l = dx * ey, m = dy * ex, cross = l - m, cabs = fabs(l) + fabs(m);
    const double a = r * r * (dx * dx + dy * dy), v = a - cross * cross;
    const double bound = 32 * EPS * (a + cabs * cabs);
    if (v > bound) return 1;
    if (-v > bound) return -1;
  }
  xs_t xs; /* not zeroed: every part is written before it is read */
  return x_sign(line_within_x(&xs, px, py, qx, qy, cx, cy, r));
}

long double qk__line_within_value(double px, double py, double qx, double qy, double cx, double cy,
                                  double r) {
  long double dx = (long double)qx - px, dy = (long double)qy - py;
  long double ex = (long double)cx - px, ey = (long double)cy - py;
  long double l = dx * ey, m = dy * ex, cross = l - m, cabs = fabsl(l) + fabsl(m);
  long double a = (long double)r * r * (dx * dx + dy * dy), v = a - cross * cross;
  if (fabsl(v) >= VALUE_KEEP * (a + cabs * cabs)) return v;
  xs_t xs;
  return x_value(line_within_x(&xs, px, py, qx, qy, cx, cy, r));
}
