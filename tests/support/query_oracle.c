/* Brute-force oracles for the query module (see query_oracle.h). */
#include "query_oracle.h"

#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#if defined(QK_HAVE_GMP)
#include <gmp.h>
#endif

/* Is (ax - bx)^2 + (ay - by)^2 <= (r1 + r2)^2 exactly? Rationals (GMP converts doubles
 * exactly) wherever a long double filter with a wide margin cannot tell; without GMP, the
 * double formula (the exact cases of the tests then fail rather than pass). */
int qko_within(double ax, double ay, double bx, double by, double r1, double r2) {
  long double dx = (long double)ax - bx, dy = (long double)ay - by, rs = (long double)r1 + r2;
  long double d2 = dx * dx + dy * dy, s2 = rs * rs;
  if (d2 > 1e-200L && d2 < 1e200L && s2 > 1e-200L && s2 < 1e200L) {
    if (d2 < s2 * (1 - 1e-9L)) return 1;
    if (d2 > s2 * (1 + 1e-9L)) return 0;
  }
#if defined(QK_HAVE_GMP)
  mpq_t a, b, x, y, r;
  mpq_inits(a, b, x, y, r, NULL);
  mpq_set_d(a, ax), mpq_set_d(b, bx), mpq_sub(x, a, b), mpq_mul(x, x, x);
  mpq_set_d(a, ay), mpq_set_d(b, by), mpq_sub(y, a, b), mpq_mul(y, y, y);
  mpq_add(x, x, y);
  mpq_set_d(a, r1), mpq_set_d(b, r2), mpq_add(r, a, b), mpq_mul(r, r, r);
  int in = mpq_cmp(x, r) <= 0;
  mpq_clears(a, b, x, y, r, NULL);
  return in;
#else
  double ex = ax - bx, ey = ay - by, er = r1 + r2;
  return ex * ex + ey * ey <= er * er;
#endif
}

static int cmp_dist(const void *x, const void *y) {
  const qk_neighbor_t *a = x, *b = y;
  if (a->dist != b->dist) return a->dist < b->dist ? -1 : 1;
  return (a->id > b->id) - (a->id < b->id);
}
static int cmp_nid(const void *x, const void *y) {
  const qk_neighbor_t *a = x, *b = y;
  return (a->id > b->id) - (a->id < b->id);
}
static int cmp_id(const void *x, const void *y) {
  qk_id_t a = *(const qk_id_t *)x, b = *(const qk_id_t *)y;
  return (a > b) - (a < b);
}
void qko_sort_by_dist(qk_neighbor_t *v, size_t n) {
  if (n > 1) qsort(v, n, sizeof *v, cmp_dist);
}
void qko_sort_by_id(qk_neighbor_t *v, size_t n) {
  if (n > 1) qsort(v, n, sizeof *v, cmp_nid);
}
void qko_sort_ids(qk_id_t *v, size_t n) {
  if (n > 1) qsort(v, n, sizeof *v, cmp_id);
}

size_t qko_range(const qk_point_t *pts, size_t n, qk_box_t b, qk_id_t *out) {
  size_t m = 0;
  for (size_t i = 0; i < n; i++)
    if (pts[i].x >= b.xmin && pts[i].x <= b.xmax && pts[i].y >= b.ymin && pts[i].y <= b.ymax)
      out[m++] = (qk_id_t)i;
  return m;
}

size_t qko_radius(const qk_point_t *pts, size_t n, qk_point_t c, double r, qk_neighbor_t *out) {
  size_t m = 0;
  for (size_t i = 0; i < n; i++) {
    double dx = pts[i].x - c.x, dy = pts[i].y - c.y, d2 = dx * dx + dy * dy;
    if (isinf(r) || qko_within(pts[i].x, pts[i].y, c.x, c.y, r, 0)) {
      out[m].id = (qk_id_t)i;
      out[m++].dist = d2 < 0x1p1000 ? sqrt(d2) : hypot(dx, dy); /* (as the library rounds it) */
    }
  }
  return m;
}

/* Is point a nearer to q than point b, or as near with a smaller id, exactly? Squares in
 * long double (no overflow or underflow for doubles' squares; a relative error of a few
 * 2^-64) decide away from a tie, rationals (GMP) near one; without GMP, long double. */
int qko_dist_cmp(qk_point_t q, qk_point_t a, qk_point_t b) {
  long double ax = (long double)a.x - q.x, ay = (long double)a.y - q.y;
  long double bx = (long double)b.x - q.x, by = (long double)b.y - q.y;
  long double da = ax * ax + ay * ay, db = bx * bx + by * by;
  if (da < db * (1 - 1e-15L)) return -1;
  if (da > db * (1 + 1e-15L)) return 1;
#if defined(QK_HAVE_GMP)
  mpq_t u, v, w;
  mpq_inits(u, v, w, NULL);
  mpq_set_d(u, a.x), mpq_set_d(v, q.x), mpq_sub(u, u, v), mpq_mul(w, u, u);
  mpq_set_d(u, a.y), mpq_set_d(v, q.y), mpq_sub(u, u, v), mpq_mul(u, u, u);
  mpq_add(w, w, u);
  mpq_set_d(u, b.x), mpq_set_d(v, q.x), mpq_sub(u, u, v), mpq_mul(v, u, u);
  mpq_set_d(u, b.y), mpq_sub(w, w, v), mpq_set_d(v, q.y), mpq_sub(u, u, v), mpq_mul(u, u, u);
  mpq_sub(w, w, u);
  const int c = mpq_sgn(w);
  mpq_clears(u, v, w, NULL);
  return c;
#else
  return (da > db) - (da < db);
#endif
}

static int o_nearer(const qk_point_t *pts, qk_point_t q, size_t a, size_t b) {
  /* the same place: the same distance (the duplicates' ties, without the rationals) */
  if (pts[a].x == pts[b].x && pts[a].y == pts[b].y) return a < b;
  const int c = qko_dist_cmp(q, pts[a], pts[b]);
  return c ? c < 0 : a < b;
}

size_t qko_knn(const qk_point_t *pts, const unsigned char *alive, size_t n, qk_point_t q, size_t k,
               double max_dist, qk_neighbor_t *out) {
  /* Every point is looked at; the k best so far stay sorted in out by the exact (distance,
   * id) order the library documents (ids in out until the end), and a better one is
   * inserted in place. Within max_dist exactly. A full sort of all n per query made the
   * tests that check thousands of queries slow. */
  size_t m = 0;
  for (size_t i = 0; i < n && k > 0; i++) {
    if (alive && !alive[i]) continue;
    if (!isinf(max_dist) && !qko_within(pts[i].x, pts[i].y, q.x, q.y, max_dist, 0)) continue;
    if (m == k && !o_nearer(pts, q, i, out[m - 1].id)) continue;
    size_t j = m < k ? m++ : m - 1;
    for (; j > 0 && o_nearer(pts, q, i, out[j - 1].id); j--) out[j] = out[j - 1];
    out[j].id = (qk_id_t)i;
  }
  for (size_t i = 0; i < m; i++) {
    const double dx = pts[out[i].id].x - q.x, dy = pts[out[i].id].y - q.y, d2 = dx * dx + dy * dy;
    out[i].dist = d2 < 0x1p1000 ? sqrt(d2) : hypot(dx, dy); /* (as the library rounds it) */
  }
  return m;
}

/* Item predicates, exact (as documented in query.h). */
static int o_disc_disc(qk_disc_t a, qk_disc_t b) {
  return qko_within(a.x, a.y, b.x, b.y, a.r, b.r);
}
static int o_box_box(qk_box_t a, qk_box_t b) {
  return a.xmin <= b.xmax && b.xmin <= a.xmax && a.ymin <= b.ymax && b.ymin <= a.ymax;
}
static int o_disc_box(qk_disc_t d, qk_box_t b) {
  double px = fmin(fmax(d.x, b.xmin), b.xmax), py = fmin(fmax(d.y, b.ymin), b.ymax);
  return qko_within(d.x, d.y, px, py, d.r, 0);
}
static int o_items(const qk_disc_t *d, size_t nd, const qk_box_t *b, size_t i, size_t j) {
  if (i < nd && j < nd) return o_disc_disc(d[i], d[j]);
  if (i < nd) return o_disc_box(d[i], b[j - nd]);
  if (j < nd) return o_disc_box(d[j], b[i - nd]);
  return o_box_box(b[i - nd], b[j - nd]);
}

size_t qko_pairs(const qk_disc_t *d, size_t nd, const qk_box_t *b, size_t nb, qk_pair_t **out) {
  size_t n = nd + nb, m = 0, cap = 16;
  qk_pair_t *v = malloc(cap * sizeof *v);
  for (size_t i = 0; i < n; i++)
    for (size_t j = i + 1; j < n; j++)
      if (o_items(d, nd, b, i, j)) {
        if (m == cap) v = realloc(v, (cap *= 2) * sizeof *v);
        v[m].a = (qk_id_t)i;
        v[m++].b = (qk_id_t)j;
      }
  *out = v;
  return m;
}

size_t qko_overlap(const qk_disc_t *d, size_t nd, const qk_box_t *b, size_t nb, int is_disc,
                   qk_disc_t qd, qk_box_t qb, qk_id_t *out) {
  size_t m = 0;
  for (size_t i = 0; i < nd + nb; i++) {
    int hit;
    if (i < nd)
      hit = is_disc ? o_disc_disc(d[i], qd) : o_disc_box(d[i], qb);
    else
      hit = is_disc ? o_disc_box(qd, b[i - nd]) : o_box_box(b[i - nd], qb);
    if (hit) out[m++] = (qk_id_t)i;
  }
  return m;
}

/*
 * Rays, derived independently of the library's formulas. A disc is first tried in long
 * double with the textbook root t = (-b - sqrt(b^2 - a c)) / a of |f + t v|^2 = r^2
 * (the library uses c / (-b + sqrt(...)) in double); the items whose long-double t is
 * near the best are then decided exactly: with GMP, whether the ray meets the item at
 * all (the nearest ray point to the centre, a rational, within r) and where it enters
 * (a box: the exact rational slab entry; a disc: bisection over doubles on the exact
 * predicate "o + t v lies in the closed disc"), so the oracle's t is the double just at
 * or after the true entry. Without GMP the long-double answers stand.
 */

#ifdef QK_HAVE_GMP
#include <gmp.h>

/* |o + t v - c|^2 <= r^2, exactly. */
static int x_in_disc(qk_disc_t d, qk_point_t o, qk_point_t v, double t) {
  mpq_t q[6];
  for (int i = 0; i < 6; i++) mpq_init(q[i]);
  mpq_set_d(q[0], t);
  /* px - cx */
  mpq_set_d(q[1], v.x);
  mpq_mul(q[1], q[1], q[0]);
  mpq_set_d(q[2], o.x - 0.0);
  mpq_add(q[1], q[1], q[2]);
  mpq_set_d(q[2], d.x);
  mpq_sub(q[1], q[1], q[2]);
  /* py - cy */
  mpq_set_d(q[3], v.y);
  mpq_mul(q[3], q[3], q[0]);
  mpq_set_d(q[2], o.y);
  mpq_add(q[3], q[3], q[2]);
  mpq_set_d(q[2], d.y);
  mpq_sub(q[3], q[3], q[2]);
  mpq_mul(q[1], q[1], q[1]);
  mpq_mul(q[3], q[3], q[3]);
  mpq_add(q[1], q[1], q[3]);
  mpq_set_d(q[4], d.r);
  mpq_mul(q[4], q[4], q[4]);
  int in = mpq_cmp(q[1], q[4]) <= 0;
  for (int i = 0; i < 6; i++) mpq_clear(q[i]);
  return in;
}

/* Exact first contact of a ray with a disc: -1 for none, else the smallest double t in
 * [0, tmax] with o + t v in the disc. */
static double x_ray_disc(qk_disc_t d, qk_point_t o, qk_point_t v, double tmax) {
  if (x_in_disc(d, o, v, 0)) return 0;
  /* the ray point nearest the centre: t* = (c - o).v / v.v, clamped */
  mpq_t num, den, t;
  mpq_inits(num, den, t, NULL);
  mpq_set_d(num, d.x);
  mpq_set_d(t, o.x);
  mpq_sub(num, num, t);
  mpq_set_d(t, v.x);
  mpq_mul(num, num, t);
  mpq_set_d(den, d.y);
  mpq_set_d(t, o.y);
  mpq_sub(den, den, t);
  mpq_set_d(t, v.y);
  mpq_mul(den, den, t);
  mpq_add(num, num, den);
  double vv = 0;
  mpq_set_d(den, v.x);
  mpq_mul(den, den, den);
  mpq_set_d(t, v.y);
  mpq_mul(t, t, t);
  mpq_add(den, den, t);
  vv = mpq_get_d(den);
  double hi = 0;
  if (vv > 0 && mpq_sgn(num) > 0) {
    mpq_div(t, num, den);
    hi = mpq_get_d(t); /* truncated: at or before t* */
    if (hi > tmax) hi = tmax;
  }
  mpq_clears(num, den, t, NULL);
  /* the nearest double at or after t* may be the only inside one */
  if (!x_in_disc(d, o, v, hi)) {
    double h2 = nextafter(hi, INFINITY);
    if (h2 <= tmax && x_in_disc(d, o, v, h2))
      hi = h2;
    else
      return -1;
  }
  double lo = 0; /* outside */
  while (nextafter(lo, INFINITY) < hi) {
    double mid = lo + (hi - lo) / 2;
    if (mid <= lo || mid >= hi) mid = nextafter(lo, INFINITY);
    if (x_in_disc(d, o, v, mid))
      hi = mid;
    else
      lo = mid;
  }
  return hi;
}

/* Exact slab entry of a ray with a box, rounded up to a double; -1 for none. */
static double x_ray_box(qk_box_t bx, qk_point_t o, qk_point_t v, double tmax) {
  mpq_t lo, hi, t1, t2, w;
  mpq_inits(lo, hi, t1, t2, w, NULL);
  mpq_set_ui(lo, 0, 1);
  int bounded = isfinite(tmax), ok = 1;
  if (bounded) mpq_set_d(hi, tmax);
  double mins[2] = {bx.xmin, bx.ymin}, maxs[2] = {bx.xmax, bx.ymax}, os[2] = {o.x, o.y},
         vs[2] = {v.x, v.y};
  for (int a = 0; a < 2 && ok; a++) {
    if (vs[a] == 0) {
      ok = !(os[a] < mins[a] || os[a] > maxs[a]);
      continue;
    }
    mpq_set_d(w, vs[a]);
    mpq_set_d(t1, mins[a]);
    mpq_set_d(t2, os[a]);
    mpq_sub(t1, t1, t2);
    mpq_div(t1, t1, w);
    mpq_set_d(t2, maxs[a]);
    mpq_set_d(w, os[a]);
    mpq_sub(t2, t2, w);
    mpq_set_d(w, vs[a]);
    mpq_div(t2, t2, w);
    if (mpq_cmp(t1, t2) > 0) mpq_swap(t1, t2);
    if (mpq_cmp(t1, lo) > 0) mpq_set(lo, t1);
    if (!bounded || mpq_cmp(t2, hi) < 0) mpq_set(hi, t2), bounded = 1;
  }
  double r = -1;
  if (ok && (!bounded || mpq_cmp(lo, hi) <= 0)) {
    r = mpq_get_d(lo);
    mpq_set_d(w, r);
    if (mpq_cmp(w, lo) < 0) r = nextafter(r, INFINITY);
  }
  mpq_clears(lo, hi, t1, t2, w, NULL);
  return r;
}
#endif

/* Long-double first contact: -1 for a miss. */
static long double l_ray_disc(qk_disc_t d, qk_point_t o, qk_point_t v, double tmax) {
  long double fx = (long double)o.x - d.x, fy = (long double)o.y - d.y;
  long double a = (long double)v.x * v.x + (long double)v.y * v.y;
  long double b = fx * v.x + fy * v.y, c = fx * fx + fy * fy - (long double)d.r * d.r;
  if (c <= 0) return 0;
  long double disc = b * b - a * c;
  if (disc < 0 || a == 0) return -1;
  long double t = (-b - sqrtl(disc)) / a;
  return t >= 0 && t <= tmax ? t : -1;
}
static long double l_ray_box(qk_box_t bx, qk_point_t o, qk_point_t v, double tmax) {
  long double lo = 0, hi = tmax;
  long double mins[2] = {bx.xmin, bx.ymin}, maxs[2] = {bx.xmax, bx.ymax}, os[2] = {o.x, o.y},
              vs[2] = {v.x, v.y};
  for (int a = 0; a < 2; a++) {
    if (vs[a] == 0) {
      if (os[a] < mins[a] || os[a] > maxs[a]) return -1;
      continue;
    }
    /* entering through the near plane, leaving through the far one */
    long double tn = ((vs[a] > 0 ? mins[a] : maxs[a]) - os[a]) / vs[a];
    long double tf = ((vs[a] > 0 ? maxs[a] : mins[a]) - os[a]) / vs[a];
    lo = fmaxl(lo, tn);
    hi = fminl(hi, tf);
  }
  return lo <= hi ? lo : -1;
}

qk_hit_t qko_raycast(const qk_disc_t *d, size_t nd, const qk_box_t *b, size_t nb, qk_point_t o,
                     qk_point_t dir, double tmax) {
  size_t n = nd + nb;
  long double *t = malloc((n ? n : 1) * sizeof *t), best = INFINITY;
  for (size_t i = 0; i < n; i++) {
    t[i] = i < nd ? l_ray_disc(d[i], o, dir, tmax) : l_ray_box(b[i - nd], o, dir, tmax);
    if (t[i] >= 0 && t[i] < best) best = t[i];
  }
  qk_hit_t h = {QK_NONE, INFINITY};
  /* the candidates: near the best in long double, or near-misses (decided exactly) */
  long double slack = 1e-6L * (1 + (isfinite(best) ? best : 0));
  for (size_t i = 0; i < n; i++) {
    double ti;
#ifdef QK_HAVE_GMP
    int near = t[i] >= 0 ? t[i] <= best + slack : 0;
    if (!near && t[i] < 0 && i < nd) {
      /* a miss in long double that is close to tangent gets the exact test too */
      long double fx = (long double)o.x - d[i].x, fy = (long double)o.y - d[i].y;
      long double cr = fx * dir.y - fy * dir.x,
                  a = (long double)dir.x * dir.x + (long double)dir.y * dir.y;
      near = fabsl(a * d[i].r * d[i].r - cr * cr) <= 1e-9L * (a * d[i].r * d[i].r + cr * cr);
    }
    if (!near) continue;
    ti = i < nd ? x_ray_disc(d[i], o, dir, tmax) : x_ray_box(b[i - nd], o, dir, tmax);
#else
    if (!(t[i] >= 0)) continue;
    ti = (double)t[i];
#endif
    if (ti >= 0 && ti <= tmax && (ti < h.t || (ti == h.t && (qk_id_t)i < h.id))) {
      h.t = ti;
      h.id = (qk_id_t)i;
    }
  }
  free(t);
  return h;
}

double qko_ray_item(const qk_disc_t *d, size_t nd, const qk_box_t *b, size_t i, qk_point_t o,
                    qk_point_t dir, double tmax) {
#ifdef QK_HAVE_GMP
  return i < nd ? x_ray_disc(d[i], o, dir, tmax) : x_ray_box(b[i - nd], o, dir, tmax);
#else
  return (double)(i < nd ? l_ray_disc(d[i], o, dir, tmax) : l_ray_box(b[i - nd], o, dir, tmax));
#endif
}

qk_point_t *qko_load_cities(size_t *n) {
  *n = 0;
  const char *dir = getenv("QK_SHARED_DIR");
  char path[4096];
  snprintf(path, sizeof path, "%s/data/cities.csv", dir ? dir : "../shared");
  FILE *f = fopen(path, "rb");
  if (!f) return NULL;
  size_t cap = 1 << 17, m = 0;
  qk_point_t *v = malloc(cap * sizeof *v);
  char line[1024];
  int first = 1;
  while (v && fgets(line, sizeof line, f)) {
    char *end;
    double lon = strtod(line, &end);
    if (end == line || *end != ',') {
      if (first) {
        first = 0;
        continue;
      }
      break;
    }
    first = 0;
    double lat = strtod(end + 1, NULL);
    if (m == cap) v = realloc(v, (cap *= 2) * sizeof *v);
    if (!v) break;
    v[m].x = lon;
    v[m++].y = lat;
  }
  fclose(f);
  *n = m;
  return v;
}

/* The library's disc test, operation for operation (collide/collider.c ray_disc). */
double qko_ray_disc_bits(qk_disc_t d, qk_point_t o, qk_point_t v, double tmax) {
  double fx = o.x - d.x, fy = o.y - d.y;
  double c = fx * fx + fy * fy - d.r * d.r;
  if (c <= 0) return 0.0;
  double b = fx * v.x + fy * v.y;
  if (b >= 0) return -1.0;
  double a = v.x * v.x + v.y * v.y, cr = fx * v.y - fy * v.x;
  double disc = a * d.r * d.r - cr * cr;
  if (disc < 0) return -1.0;
  double t = c / (-b + sqrt(disc));
  return t <= tmax ? t : -1.0;
}
