/* Random planar straight-line graphs for the general mesh mode (see polygen.h). */
#include "polygen.h"

#include <math.h>
#include <stdlib.h>
#include <string.h>

#ifdef QK_HAVE_GMP
#include <gmp.h>
#endif

#define PI 3.14159265358979323846

static void *grow(void *p, size_t *cap, size_t need, size_t elem) {
  if (need <= *cap) return p;
  size_t nc = *cap ? 2 * *cap : 64;
  while (nc < need) nc *= 2;
  void *q = realloc(p, nc * elem);
  if (!q) abort(); /* test support: out of memory is fatal */
  *cap = nc;
  return q;
}

/* ---- exact predicates -------------------------------------------------------------- */

/* Sign of (b - a) x (c - a): a filter, then GMP; without GMP an uncertain answer is 2,
 * which every caller treats as "not valid" (so acceptance is always right). */
static int orient(const double *a, const double *b, const double *c) {
  double l = (b[0] - a[0]) * (c[1] - a[1]), r = (b[1] - a[1]) * (c[0] - a[0]);
  double det = l - r, bound = 1e-15 * (fabs(l) + fabs(r));
  if (det > bound && bound > 1e-280) return 1;
  if (-det > bound && bound > 1e-280) return -1;
#ifdef QK_HAVE_GMP
  mpq_t q[6];
  for (int i = 0; i < 6; i++) mpq_init(q[i]);
  mpq_set_d(q[0], b[0]), mpq_set_d(q[5], a[0]), mpq_sub(q[0], q[0], q[5]);
  mpq_set_d(q[1], c[1]), mpq_set_d(q[5], a[1]), mpq_sub(q[1], q[1], q[5]);
  mpq_set_d(q[2], b[1]), mpq_sub(q[2], q[2], q[5]);
  mpq_set_d(q[3], c[0]), mpq_set_d(q[5], a[0]), mpq_sub(q[3], q[3], q[5]);
  mpq_mul(q[4], q[0], q[1]), mpq_mul(q[5], q[2], q[3]);
  int s = mpq_cmp(q[4], q[5]);
  for (int i = 0; i < 6; i++) mpq_clear(q[i]);
  return s > 0 ? 1 : s < 0 ? -1 : 0;
#else
  return 2;
#endif
}

/* Is p inside the closed box of a, b? */
static int in_box(const double *a, const double *b, const double *p) {
  return p[0] >= fmin(a[0], b[0]) && p[0] <= fmax(a[0], b[0]) && p[1] >= fmin(a[1], b[1]) &&
         p[1] <= fmax(a[1], b[1]);
}

/* Do closed segments a-b and c-d meet? 2 when unsure (no GMP). */
static int meet(const double *a, const double *b, const double *c, const double *d) {
  int o1 = orient(a, b, c), o2 = orient(a, b, d), o3 = orient(c, d, a), o4 = orient(c, d, b);
  if (o1 == 2 || o2 == 2 || o3 == 2 || o4 == 2) return 2;
  if (o1 * o2 < 0 && o3 * o4 < 0) return 1;
  return (o1 == 0 && in_box(a, b, c)) || (o2 == 0 && in_box(a, b, d)) ||
         (o3 == 0 && in_box(c, d, a)) || (o4 == 0 && in_box(c, d, b));
}

/* Segments sharing endpoint a (a-b and a-d): do they overlap (collinear, same way)? */
static int fold(const double *a, const double *b, const double *d) {
  int o = orient(a, b, d);
  if (o == 2) return 2;
  if (o != 0) return 0;
  return (b[0] - a[0]) * (d[0] - a[0]) + (b[1] - a[1]) * (d[1] - a[1]) > 0;
}

/* Point p against ring r of p: 1 strictly inside, 0 outside, -1 on it (or unsure). */
static int in_ring(const pg_pslg_t *g, size_t r, const double *p) {
  size_t s0 = g->ring_start[r], s1 = g->ring_start[r + 1];
  int in = 0;
  for (size_t i = s0; i < s1; i++) {
    const double *a = &g->xy[2 * g->ring_v[i]], *b = &g->xy[2 * g->ring_v[i + 1 < s1 ? i + 1 : s0]];
    int o = orient(a, b, p);
    if (o == 2 || (o == 0 && in_box(a, b, p))) return -1;
    if ((a[1] > p[1]) != (b[1] > p[1])) {
      /* the edge crosses the horizontal through p: on which side of p? */
      int up = b[1] > a[1];
      if ((up && o > 0) || (!up && o < 0)) in = !in;
    }
  }
  return in;
}

/* Is p in the domain: strictly inside an outer ring and outside every hole (strictly)? */
static int in_domain(const pg_pslg_t *g, const double *p) {
  int inside = 0;
  for (size_t r = 0; r < g->nr; r++) {
    int k = in_ring(g, r, p);
    if (k < 0) return 0;
    if (k && g->ring_sign[r] < 0) return 0;
    if (k && g->ring_sign[r] > 0) inside = 1;
  }
  return inside;
}

/* ---- building ---------------------------------------------------------------------- */

static uint32_t add_v(pg_pslg_t *g, double x, double y) {
  g->xy = grow(g->xy, &g->cap_v, 2 * g->nv + 2, sizeof *g->xy);
  g->xy[2 * g->nv] = x, g->xy[2 * g->nv + 1] = y;
  return (uint32_t)g->nv++;
}

static void add_s(pg_pslg_t *g, uint32_t a, uint32_t b) {
  g->seg = grow(g->seg, &g->cap_s, 2 * g->ns + 2, sizeof *g->seg);
  g->seg[2 * g->ns] = a, g->seg[2 * g->ns + 1] = b;
  g->ns++;
}

/* Are the segments from s0 on, and the vertices from v0 on, compatible with the rest? */
static int valid_from(const pg_pslg_t *g, size_t v0, size_t s0) {
  for (size_t v = v0; v < g->nv; v++)
    for (size_t u = 0; u < v; u++)
      if (g->xy[2 * u] == g->xy[2 * v] && g->xy[2 * u + 1] == g->xy[2 * v + 1]) return 0;
  for (size_t s = s0; s < g->ns; s++)
    for (size_t t = 0; t < s; t++) {
      uint32_t a = g->seg[2 * s], b = g->seg[2 * s + 1], c = g->seg[2 * t], d = g->seg[2 * t + 1];
      const double *pa = &g->xy[2 * a], *pb = &g->xy[2 * b], *pc = &g->xy[2 * c],
                   *pd = &g->xy[2 * d];
      int shared = (a == c) + (a == d) + (b == c) + (b == d);
      if (shared >= 2) return 0; /* the same segment twice */
      if (shared == 1) {
        if (a == c && fold(pa, pb, pd)) return 0;
        if (a == d && fold(pa, pb, pc)) return 0;
        if (b == c && fold(pb, pa, pd)) return 0;
        if (b == d && fold(pb, pa, pc)) return 0;
        continue;
      }
      if (meet(pa, pb, pc, pd)) return 0;
    }
  return 1;
}

/* Undo everything after (nv, ns, nh, nr). */
static void rollback(pg_pslg_t *g, size_t nv, size_t ns, size_t nh, size_t nr) {
  g->nv = nv, g->ns = ns, g->nh = nh, g->nr = nr;
}

static double snap(double v, double grid) { return grid > 0 ? nearbyint(v / grid) * grid : v; }

static double unit(qkt_rng_t *r) { return qkt_rng_unit(r); }

/* A closed ring through k points as a ring record (vertices, segments). */
static void add_ring(pg_pslg_t *g, const double *pts, size_t k, int sign) {
  uint32_t base = (uint32_t)g->nv;
  for (size_t i = 0; i < k; i++) add_v(g, pts[2 * i], pts[2 * i + 1]);
  for (size_t i = 0; i < k; i++) add_s(g, base + (uint32_t)i, base + (uint32_t)((i + 1) % k));
  g->ring_start = grow(g->ring_start, &g->cap_r, g->nr + 2, sizeof *g->ring_start);
  g->ring_sign = realloc(g->ring_sign, g->cap_r * sizeof *g->ring_sign);
  if (!g->ring_sign) abort();
  if (g->nr == 0) g->ring_start[0] = 0;
  size_t at = g->ring_start[g->nr];
  g->ring_v = grow(g->ring_v, &g->cap_rv, at + k, sizeof *g->ring_v);
  for (size_t i = 0; i < k; i++) g->ring_v[at + i] = base + (uint32_t)i;
  g->ring_sign[g->nr] = sign;
  g->ring_start[++g->nr] = at + k;
}

/* Corners of a star-shaped ring around (cx, cy): k jittered angles, radii R..R/2. With
 * `collinear`, one edge gets a middle vertex one grid step (or one ulp) off its line. */
static size_t star(qkt_rng_t *r, double cx, double cy, double R, size_t k, double grid,
                   int collinear, double *pts) {
  size_t n = 0;
  for (size_t i = 0; i < k; i++) {
    double th = 2 * PI * ((double)i + 0.8 * unit(r)) / (double)k, rho = R * (0.5 + 0.5 * unit(r));
    pts[2 * n] = snap(cx + rho * cos(th), grid), pts[2 * n + 1] = snap(cy + rho * sin(th), grid);
    n++;
    if (collinear && i == k / 2) {
      /* the midpoint of this corner and the next one, pushed off the line */
      double th2 = 2 * PI * ((double)i + 1.5) / (double)k;
      double nx = snap(cx + rho * cos(th2), grid), ny = snap(cy + rho * sin(th2), grid);
      double mx = (pts[2 * n - 2] + nx) / 2, my = (pts[2 * n - 1] + ny) / 2;
      my = grid > 0 ? my + grid / 2 : nextafter(my, INFINITY);
      pts[2 * n] = mx, pts[2 * n + 1] = my;
      pts[2 * n + 2] = nx, pts[2 * n + 3] = ny;
      n += 2, i++;
    }
  }
  return n;
}

/* A hole: a small star (or, for small angles, a thin triangle) inside the domain, with
 * its hole point. Returns 1 when added. */
static int try_hole(qkt_rng_t *r, pg_pslg_t *g, double cx, double cy, double R, double grid,
                    int thin) {
  size_t nv = g->nv, ns = g->ns, nh = g->nh, nr = g->nr;
  double pts[2 * 24], hp[2];
  size_t k;
  if (thin) {
    double th = 2 * PI * unit(r), al = (0.5 + 58.5 * unit(r)) * PI / 180;
    pts[0] = snap(cx, grid), pts[1] = snap(cy, grid);
    pts[2] = snap(cx + R * cos(th), grid), pts[3] = snap(cy + R * sin(th), grid);
    pts[4] = snap(cx + R * cos(th + al), grid), pts[5] = snap(cy + R * sin(th + al), grid);
    k = 3;
    hp[0] = (pts[0] + pts[2] + pts[4]) / 3, hp[1] = (pts[1] + pts[3] + pts[5]) / 3;
  } else {
    k = star(r, cx, cy, R, 5 + qkt_rng_below(r, 8), grid, 0, pts);
    hp[0] = cx, hp[1] = cy;
  }
  if (!in_domain(g, hp)) return 0;
  add_ring(g, pts, k, -1);
  int ok = valid_from(g, nv, ns) && in_ring(g, g->nr - 1, hp) == 1;
  for (size_t i = 0; ok && i < nh; i++) ok = in_ring(g, g->nr - 1, &g->holes[2 * i]) == 0;
  if (!ok) return rollback(g, nv, ns, nh, nr), 0;
  g->holes = grow(g->holes, &g->cap_h, 2 * g->nh + 2, sizeof *g->holes);
  g->holes[2 * g->nh] = hp[0], g->holes[2 * g->nh + 1] = hp[1];
  g->nh++;
  return 1;
}

/* An open chain through k points (an internal constraint) if it fits in the domain. */
static int try_chain(pg_pslg_t *g, const double *pts, size_t k) {
  size_t nv = g->nv, ns = g->ns;
  for (size_t i = 0; i < k; i++)
    if (!in_domain(g, &pts[2 * i])) return 0;
  uint32_t base = (uint32_t)g->nv;
  for (size_t i = 0; i < k; i++) add_v(g, pts[2 * i], pts[2 * i + 1]);
  for (size_t i = 0; i + 1 < k; i++) add_s(g, base + (uint32_t)i, base + (uint32_t)i + 1);
  if (!valid_from(g, nv, ns)) return rollback(g, nv, ns, g->nh, g->nr), 0;
  return 1;
}

/* A fan: segments from one centre at small angles to each other. */
static int try_fan(qkt_rng_t *r, pg_pslg_t *g, double cx, double cy, double L, double grid) {
  size_t nv = g->nv, ns = g->ns;
  double c[2] = {snap(cx, grid), snap(cy, grid)};
  if (!in_domain(g, c)) return 0;
  uint32_t ic = add_v(g, c[0], c[1]);
  double th = 2 * PI * unit(r);
  size_t k = 2 + qkt_rng_below(r, 3);
  for (size_t i = 0; i < k; i++) {
    double p[2] = {snap(cx + L * cos(th), grid), snap(cy + L * sin(th), grid)};
    if (!in_domain(g, p)) return rollback(g, nv, ns, g->nh, g->nr), 0;
    add_s(g, ic, add_v(g, p[0], p[1]));
    th += (0.5 + 58.5 * unit(r)) * PI / 180;
  }
  if (!valid_from(g, nv, ns)) return rollback(g, nv, ns, g->nh, g->nr), 0;
  return 1;
}

void pg_pslg(qkt_rng_t *r, unsigned flags, size_t n, pg_pslg_t *g) {
  memset(g, 0, sizeof *g);
  g->flags = flags;
  int full = (flags & PG_FULL) != 0;
  /* Scale and position: a domain 2^e wide (2^20 with PG_SCALES) somewhere. */
  int e = flags & PG_SCALES ? 20 : (int)qkt_rng_below(r, 21) - 10;
  double R = ldexp(1, e - 1), grid = full ? 0 : ldexp(1, e - 14);
  double ox = snap((unit(r) - 0.5) * ldexp(1, e + (int)qkt_rng_below(r, 4)), grid),
         oy = snap((unit(r) - 0.5) * ldexp(1, e + (int)qkt_rng_below(r, 4)), grid);
  if (full) ox += unit(r) * R, oy += unit(r) * R;
  g->grid = flags & PG_NEAR_COLLINEAR ? grid / 2 : grid; /* midpoints: half a step */
  if (n < 3) n = 3;
  double *pts = malloc((2 * n + 8) * sizeof *pts);
  if (!pts) abort();
  for (int tries = 0;; tries++) {
    size_t k = star(r, ox, oy, R, n, grid, (flags & PG_NEAR_COLLINEAR) != 0, pts);
    add_ring(g, pts, k, 1);
    if (valid_from(g, 0, 0)) break;
    if (tries > 100) abort(); /* cannot happen for a star with k >= 3 */
    rollback(g, 0, 0, 0, 0);
  }
  free(pts);
  if (flags & PG_ISLAND) {
    double ipts[2 * 16];
    size_t k = star(r, ox + 3 * R, oy, R / 2, 8, grid, 0, ipts);
    add_ring(g, ipts, k, 1);
    if (!valid_from(g, g->nv - k, g->ns - k)) rollback(g, g->nv - k, g->ns - k, g->nh, g->nr - 1);
  }
  /* Features inside: holes first (so internal features can avoid them). */
  size_t want = 1 + n / 8;
  for (size_t i = 0, tries = 0; (flags & PG_HOLES) && i < want && tries < 40 * want; tries++) {
    double hr = R * (0.04 + 0.1 * unit(r)), rho = 0.4 * R * unit(r), th = 2 * PI * unit(r);
    i += (size_t)try_hole(r, g, ox + rho * cos(th), oy + rho * sin(th), hr, grid,
                          (flags & PG_SMALL_ANGLES) && qkt_rng_below(r, 2));
  }
  if (flags & PG_SCALES) {
    /* Tiny holes and chains, 2^-20 .. 2^-10 wide, on a grid 2^-8 of their size. */
    for (size_t i = 0, tries = 0; i < 3 && tries < 60; tries++) {
      double size = ldexp(1, -20 + (int)qkt_rng_below(r, 11)), tg = full ? 0 : size / 256;
      double rho = 0.4 * R * unit(r), th = 2 * PI * unit(r);
      double cx = snap(ox + rho * cos(th), tg), cy = snap(oy + rho * sin(th), tg);
      if (tries % 2) {
        i += (size_t)try_hole(r, g, cx, cy, size, tg, 0);
      } else {
        double c[4] = {cx, cy, snap(cx + size, tg), snap(cy + size / 3, tg)};
        i += (size_t)try_chain(g, c, 2);
      }
      if (tg > 0 && tg < g->grid) g->grid = tg;
    }
  }
  for (size_t i = 0, tries = 0; (flags & PG_INTERNAL) && i < want && tries < 40 * want; tries++) {
    double rho = 0.45 * R * unit(r), th = 2 * PI * unit(r), L = R * (0.05 + 0.2 * unit(r));
    double a = 2 * PI * unit(r), c[6];
    c[0] = snap(ox + rho * cos(th), grid), c[1] = snap(oy + rho * sin(th), grid);
    c[2] = snap(c[0] + L * cos(a), grid), c[3] = snap(c[1] + L * sin(a), grid);
    size_t k = 2;
    if (qkt_rng_below(r, 2)) {
      a += (unit(r) - 0.5) * 2;
      c[4] = snap(c[2] + L * cos(a), grid), c[5] = snap(c[3] + L * sin(a), grid), k = 3;
    }
    i += (size_t)try_chain(g, c, k);
  }
  for (size_t i = 0, tries = 0; (flags & PG_SMALL_ANGLES) && i < want && tries < 40 * want;
       tries++) {
    double rho = 0.45 * R * unit(r), th = 2 * PI * unit(r);
    i += (size_t)try_fan(r, g, ox + rho * cos(th), oy + rho * sin(th), R * (0.05 + 0.1 * unit(r)),
                         grid);
  }
  if (flags & PG_NEAR_COLLINEAR) {
    /* An internal chain a - m - b with m one grid step (one ulp) off the line a-b. */
    for (int tries = 0; tries < 40; tries++) {
      double rho = 0.4 * R * unit(r), th = 2 * PI * unit(r), L = R * 0.1;
      double c[6];
      c[0] = snap(ox + rho * cos(th), grid), c[1] = snap(oy + rho * sin(th), grid);
      c[4] = snap(c[0] + 2 * L, grid), c[5] = snap(c[1] + L, grid);
      c[2] = (c[0] + c[4]) / 2, c[3] = (c[1] + c[5]) / 2;
      c[3] = grid > 0 ? c[3] + grid : nextafter(c[3], INFINITY);
      if (try_chain(g, c, 3)) break;
    }
  }
  if (flags & PG_NEAR_COINCIDENT) {
    /* A segment starting one grid step (one ulp) from an existing vertex. */
    for (int tries = 0, done = 0; tries < 60 && done < 2; tries++) {
      size_t v = qkt_rng_below(r, (uint32_t)g->nv);
      /* Only from a vertex of the main grid: a long segment from a tiny feature's finely
       * placed vertex would exceed the precision budget (its split points need more bits
       * than the double has), which is a refusal, not what this feature tests. */
      if (grid > 0 && (g->xy[2 * v] != snap(g->xy[2 * v], grid) ||
                       g->xy[2 * v + 1] != snap(g->xy[2 * v + 1], grid)))
        continue;
      double dx = qkt_rng_below(r, 2) ? 1 : -1, dy = qkt_rng_below(r, 2) ? 1 : -1;
      double c[4];
      c[0] = grid > 0 ? g->xy[2 * v] + dx * grid : nextafter(g->xy[2 * v], dx * INFINITY);
      c[1] = grid > 0 ? g->xy[2 * v + 1] + dy * grid : nextafter(g->xy[2 * v + 1], dy * INFINITY);
      double a = 2 * PI * unit(r), L = R * 0.05;
      c[2] = snap(c[0] + L * cos(a), grid), c[3] = snap(c[1] + L * sin(a), grid);
      done += try_chain(g, c, 2);
    }
  }
}

int pg_pslg_check(const pg_pslg_t *g, char *msg, size_t n) {
  if (!valid_from(g, 0, 0))
    return snprintf(msg, n, "vertices coincide or segments meet (or, without GMP, unsure)"), 1;
  for (size_t h = 0; h < g->nh; h++) {
    int inside = 0;
    for (size_t r = 0; r < g->nr; r++) {
      int k = in_ring(g, r, &g->holes[2 * h]);
      if (k < 0) return snprintf(msg, n, "hole point %zu is on a ring", h), 1;
      if (k && g->ring_sign[r] < 0) inside++;
    }
    if (inside != 1) return snprintf(msg, n, "hole point %zu is in %d holes", h, inside), 1;
  }
  return 0;
}

void pg_pslg_write_poly(const pg_pslg_t *g, FILE *f) {
  fprintf(f, "%zu 2 0 0\n", g->nv);
  for (size_t i = 0; i < g->nv; i++)
    fprintf(f, "%zu %.17g %.17g\n", i, g->xy[2 * i], g->xy[2 * i + 1]);
  fprintf(f, "%zu 0\n", g->ns);
  for (size_t i = 0; i < g->ns; i++) fprintf(f, "%zu %u %u\n", i, g->seg[2 * i], g->seg[2 * i + 1]);
  fprintf(f, "%zu\n", g->nh);
  for (size_t i = 0; i < g->nh; i++)
    fprintf(f, "%zu %.17g %.17g\n", i, g->holes[2 * i], g->holes[2 * i + 1]);
}

void pg_pslg_free(pg_pslg_t *g) {
  free(g->xy), free(g->seg), free(g->holes), free(g->ring_v), free(g->ring_start),
      free(g->ring_sign);
  memset(g, 0, sizeof *g);
}
