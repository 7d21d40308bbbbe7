/*
 * The general rational mesh checker (mcr_check_general, see mesh_check_real.h): any
 * angles, real coordinates. Every decision is exact: a floating-point estimate with a
 * generous error bound answers when it is clearly on one side, GMP rationals otherwise.
 * Work is kept near-linear (sorted keys, a bucket grid for vertices on segments) so that
 * meshes of 10^5 triangles are checked in a fraction of a second.
 */
#include "mesh_check_real.h"

#include <math.h>
#include <stdarg.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#ifndef QK_HAVE_GMP
int mcr_check_general(const mcr_input_t *in, const mcr_mesh_t *m, const mcr_opts_t *opts,
                      mcr_report_t *rep, char *msg, size_t n) {
  (void)in, (void)m, (void)opts, (void)rep;
  snprintf(msg, n, "built without GMP: nothing checked");
  return 2;
}
#else
#include <gmp.h>

#define PI 3.14159265358979323846

/* Scratch state of one check. */
typedef struct gc {
  const mcr_input_t *in;
  const mcr_mesh_t *m;
  const mcr_opts_t *o;
  char *msg;
  size_t n;
  mpq_t q[8];
  double cmin, cmax; /* strict-side cotangents of the bounds (NAN: none) */
  uint64_t *keys;    /* directed edges, sorted */
  size_t ne;
  uint32_t *in2m, *m2in; /* input vertex -> mesh vertex and back (UINT32_MAX: none) */
  size_t *inc0;          /* input vertex v's incident segments: inc[inc0[v] .. inc0[v+1]) */
  uint32_t *inc;
  size_t *on0; /* mesh vertex v lies on the segments on[on0[v] .. on0[v+1]) */
  uint32_t *on;
  double phi_ratio, phi_deg; /* the best angle / g(phi) of a corner below its bound */
} gc_t;

static int fail(gc_t *c, const char *fmt, ...) {
  va_list ap;
  va_start(ap, fmt);
  vsnprintf(c->msg, c->n, fmt, ap);
  va_end(ap);
  return 1;
}

static void *xmalloc(size_t n) {
  void *p = malloc(n ? n : 1);
  if (!p) abort(); /* test support: out of memory is fatal */
  return p;
}

/* q = (b - a) as rationals. */
static void qdiff(mpq_t q, double b, double a, mpq_t t) {
  mpq_set_d(q, b);
  mpq_set_d(t, a);
  mpq_sub(q, q, t);
}

/* Exact sign of (b - a) x (c - a). */
static int orient(gc_t *c, const double *a, const double *b, const double *d) {
  double l = (b[0] - a[0]) * (d[1] - a[1]), r = (b[1] - a[1]) * (d[0] - a[0]);
  double det = l - r, bound = 1e-15 * (fabs(l) + fabs(r));
  if (det > bound && bound > 1e-280) return 1;
  if (-det > bound && bound > 1e-280) return -1;
  mpq_t *q = c->q;
  qdiff(q[0], b[0], a[0], q[7]), qdiff(q[1], b[1], a[1], q[7]);
  qdiff(q[2], d[0], a[0], q[7]), qdiff(q[3], d[1], a[1], q[7]);
  mpq_mul(q[4], q[0], q[3]), mpq_mul(q[5], q[1], q[2]);
  return mpq_cmp(q[4], q[5]) > 0 ? 1 : mpq_cmp(q[4], q[5]) < 0 ? -1 : 0;
}

/* Sign of C (u x w) - (u . w) for u = b - a, w = d - a (the corner at a): >= 0 when the
 * angle's cotangent is at most C. */
static int cot_side(gc_t *c, double C, const double *a, const double *b, const double *d) {
  double ux = b[0] - a[0], uy = b[1] - a[1], wx = d[0] - a[0], wy = d[1] - a[1];
  double f = C * (ux * wy - uy * wx) - (ux * wx + uy * wy);
  double mag = fabs(C) * (fabs(ux * wy) + fabs(uy * wx)) + fabs(ux * wx) + fabs(uy * wy);
  if (mag > 1e-280 && fabs(f) > 1e-13 * mag) return f > 0 ? 1 : -1;
  mpq_t *q = c->q;
  qdiff(q[0], b[0], a[0], q[7]), qdiff(q[1], b[1], a[1], q[7]);
  qdiff(q[2], d[0], a[0], q[7]), qdiff(q[3], d[1], a[1], q[7]);
  mpq_mul(q[4], q[0], q[3]), mpq_mul(q[5], q[1], q[2]), mpq_sub(q[4], q[4], q[5]); /* cross */
  mpq_set_d(q[5], C), mpq_mul(q[4], q[4], q[5]);
  mpq_mul(q[5], q[0], q[2]), mpq_mul(q[6], q[1], q[3]), mpq_add(q[5], q[5], q[6]); /* dot */
  int s = mpq_cmp(q[4], q[5]);
  return s > 0 ? 1 : s < 0 ? -1 : 0;
}

/* The corner angle at a (floating point, for reports). */
static double angle_deg(const double *a, const double *b, const double *d) {
  double ux = b[0] - a[0], uy = b[1] - a[1], wx = d[0] - a[0], wy = d[1] - a[1];
  return atan2(fabs(ux * wy - uy * wx), ux * wx + uy * wy) * 180 / PI;
}

/* Is the angle from direction u to direction w (counter-clockwise, both from the same
 * vertex) positive and below 60 degrees? Exact: cross > 0, dot > 0, 4 dot^2 > |u|^2 |w|^2. */
static int below60(gc_t *c, const double *v, const double *pu, const double *pw) {
  if (orient(c, v, pu, pw) <= 0) return 0;
  mpq_t *q = c->q;
  qdiff(q[0], pu[0], v[0], q[7]), qdiff(q[1], pu[1], v[1], q[7]);
  qdiff(q[2], pw[0], v[0], q[7]), qdiff(q[3], pw[1], v[1], q[7]);
  mpq_mul(q[4], q[0], q[2]), mpq_mul(q[5], q[1], q[3]), mpq_add(q[4], q[4], q[5]); /* dot */
  if (mpq_sgn(q[4]) <= 0) return 0;
  mpq_mul(q[4], q[4], q[4]), mpq_add(q[4], q[4], q[4]), mpq_add(q[4], q[4], q[4]);
  mpq_mul(q[5], q[0], q[0]), mpq_mul(q[6], q[1], q[1]), mpq_add(q[5], q[5], q[6]);
  mpq_mul(q[6], q[2], q[2]), mpq_mul(q[0], q[3], q[3]), mpq_add(q[6], q[6], q[0]);
  mpq_mul(q[5], q[5], q[6]);
  return mpq_cmp(q[4], q[5]) > 0;
}

/* The bound inside an input angle phi < 60 degrees (docs/mesh.md, "Small input angles"):
 * is the corner angle alpha at pa, between pb and pd, at least
 * g(phi) = arctan(sin phi / (2.02 - cos phi)), phi the angle at pv from pu to pw? Exact.
 * With X = |cross| and Y = dot at the corner, C = |cross| and D = dot of the input angle
 * and N = |u| |w|: tan g = C / (2.02 N - D) (positive: D <= N), so alpha >= g iff Y <= 0,
 * or X (2.02 N - D) >= Y C, i.e. 2.02 X N >= Y C + X D: true when the right side is <= 0,
 * else compare squares, (101/50)^2 X^2 |u|^2 |w|^2 >= (Y C + X D)^2. */
static int above_phi_bound(gc_t *c, const double *pa, const double *pb, const double *pd,
                           const double *pv, const double *pu, const double *pw) {
  mpq_t *q = c->q;
  mpq_t X, Y, C, D, UW;
  mpq_inits(X, Y, C, D, UW, NULL);
  qdiff(q[0], pb[0], pa[0], q[7]), qdiff(q[1], pb[1], pa[1], q[7]);
  qdiff(q[2], pd[0], pa[0], q[7]), qdiff(q[3], pd[1], pa[1], q[7]);
  mpq_mul(X, q[0], q[3]), mpq_mul(q[4], q[1], q[2]), mpq_sub(X, X, q[4]), mpq_abs(X, X);
  mpq_mul(Y, q[0], q[2]), mpq_mul(q[4], q[1], q[3]), mpq_add(Y, Y, q[4]);
  int ok = 1;
  if (mpq_sgn(Y) > 0) {
    qdiff(q[0], pu[0], pv[0], q[7]), qdiff(q[1], pu[1], pv[1], q[7]);
    qdiff(q[2], pw[0], pv[0], q[7]), qdiff(q[3], pw[1], pv[1], q[7]);
    mpq_mul(C, q[0], q[3]), mpq_mul(q[4], q[1], q[2]), mpq_sub(C, C, q[4]), mpq_abs(C, C);
    mpq_mul(D, q[0], q[2]), mpq_mul(q[4], q[1], q[3]), mpq_add(D, D, q[4]);
    mpq_mul(q[4], q[0], q[0]), mpq_mul(q[5], q[1], q[1]), mpq_add(q[4], q[4], q[5]);
    mpq_mul(q[5], q[2], q[2]), mpq_mul(q[6], q[3], q[3]), mpq_add(q[5], q[5], q[6]);
    mpq_mul(UW, q[4], q[5]);
    mpq_mul(q[4], Y, C), mpq_mul(q[5], X, D), mpq_add(q[4], q[4], q[5]); /* Y C + X D */
    if (mpq_sgn(q[4]) > 0) {
      mpq_mul(q[4], q[4], q[4]);
      mpq_mul(q[5], X, X), mpq_mul(q[5], q[5], UW);
      mpq_set_ui(q[6], 10201, 2500), mpq_mul(q[5], q[5], q[6]);
      ok = mpq_cmp(q[5], q[4]) >= 0;
    }
  }
  if (!ok) {
    double phi = angle_deg(pv, pu, pw), al = angle_deg(pa, pb, pd);
    double f = atan(sin(phi * PI / 180) / (2.02 - cos(phi * PI / 180))) * 180 / PI;
    if (al / f > c->phi_ratio) c->phi_ratio = al / f, c->phi_deg = phi;
  }
  mpq_clears(X, Y, C, D, UW, NULL);
  return ok;
}

/* The small-angle rule for the corner at mesh vertex a of the counter-clockwise triangle
 * (a, b, d) whose angle is below the bound. The triangle faces an input angle when, for
 * two input segments s1, s2 meeting at an input vertex v at phi < 60 degrees, the whole
 * triangle lies in their closed wedge and two of its vertices lie one on s1 and one on s2
 * (v itself lies on both: a triangle with a corner at v faces the angle). Then the corner
 * must be at least g(phi) (above_phi_bound). Returns 1 when some faced input angle allows
 * the corner (*at_apex: the corner is v itself), -1 when the triangle faces one but the
 * corner is below g(phi) for every one it faces, 0 when it faces none. apex_only (rule 1
 * alone): only corners at v count. Uses the vertex-to-segment lists (on0 / on). */
static int small_angle_rule(gc_t *c, uint32_t a, uint32_t b, uint32_t d, int apex_only,
                            int *at_apex) {
  const mcr_input_t *in = c->in;
  const uint32_t tv[3] = {a, b, d};
  const double *p[3] = {&c->m->xy[2 * a], &c->m->xy[2 * b], &c->m->xy[2 * d]};
  int below = 0;
  for (int x = 0; x < 3; x++)
    for (int y = 0; y < 3; y++)
      for (size_t i = c->on0[tv[x]]; i < c->on0[tv[x] + 1]; i++)
        for (size_t j = c->on0[tv[y]]; j < c->on0[tv[y] + 1]; j++) {
          uint32_t s1 = c->on[i], s2 = c->on[j];
          if (s1 == s2) continue;
          for (int e1 = 0; e1 < 2; e1++)
            for (int e2 = 0; e2 < 2; e2++) {
              uint32_t v = in->seg[2 * s1 + e1];
              if (v != in->seg[2 * s2 + e2]) continue;
              int apex = c->in2m[v] == a;
              if (apex_only && !apex) continue;
              const double *pv = &in->xy[2 * v], *pu = &in->xy[2 * in->seg[2 * s1 + 1 - e1]],
                           *pw = &in->xy[2 * in->seg[2 * s2 + 1 - e2]];
              if (!below60(c, pv, pu, pw)) {
                const double *t = pu;
                pu = pw, pw = t;
                if (!below60(c, pv, pu, pw)) continue;
              }
              int inside = 1;
              for (int k = 0; k < 3 && inside; k++)
                inside = orient(c, pv, pu, p[k]) >= 0 && orient(c, pv, p[k], pw) >= 0;
              if (!inside) continue;
              if (above_phi_bound(c, p[0], p[1], p[2], pv, pu, pw)) {
                *at_apex = apex;
                return 1;
              }
              below = -1;
            }
        }
  return below;
}

static int check_triangles(gc_t *c, mcr_report_t *rep) {
  const mcr_mesh_t *m = c->m;
  rep->min_angle_deg = 180, rep->max_angle_deg = 0;
  for (size_t t = 0; t < m->nt; t++) {
    const uint32_t *tr = &m->tri[3 * t];
    for (int i = 0; i < 3; i++)
      if (tr[i] >= m->nv) return fail(c, "triangle %zu uses vertex %u of %zu", t, tr[i], m->nv);
    if (orient(c, &m->xy[2 * tr[0]], &m->xy[2 * tr[1]], &m->xy[2 * tr[2]]) <= 0)
      return fail(c, "triangle %zu (%u %u %u) is not counter-clockwise", t, tr[0], tr[1], tr[2]);
    int had_exempt = 0;
    for (int i = 0; i < 3; i++) {
      uint32_t a = tr[i], b = tr[(i + 1) % 3], d = tr[(i + 2) % 3];
      const double *pa = &m->xy[2 * a], *pb = &m->xy[2 * b], *pd = &m->xy[2 * d];
      double deg = angle_deg(pa, pb, pd);
      if (deg < rep->min_angle_deg) rep->min_angle_deg = deg;
      if (deg > rep->max_angle_deg) rep->max_angle_deg = deg;
      if (isnan(c->cmin) || cot_side(c, c->cmin, pa, pb, pd) >= 0) continue;
      c->phi_ratio = 0, c->phi_deg = 0;
      int at_apex = 0;
      int e =
          c->o->exempt_small ? small_angle_rule(c, a, b, d, c->o->exempt_small == 1, &at_apex) : 0;
      if (e > 0) {
        if (at_apex)
          rep->exempt++;
        else
          rep->exempt_wedge++;
        had_exempt = 1;
        continue;
      }
      if (e < 0)
        return fail(c,
                    "triangle %zu has an angle of %.9g degrees (below %g) at vertex %u "
                    "(%.17g, %.17g), inside an input angle of %.9g degrees but below the bound "
                    "arctan(sin phi / (2.02 - cos phi)) there (%.6f of it)",
                    t, deg, c->o->min_deg, a, pa[0], pa[1], c->phi_deg, c->phi_ratio);
      return fail(c,
                  "triangle %zu has an angle of %.9g degrees (below %g) at vertex %u "
                  "(%.17g, %.17g) that no input angle below 60 degrees exempts",
                  t, deg, c->o->min_deg, a, pa[0], pa[1]);
    }
    if (had_exempt || isnan(c->cmax)) continue;
    for (int i = 0; i < 3; i++) {
      const double *pa = &m->xy[2 * tr[i]], *pb = &m->xy[2 * tr[(i + 1) % 3]],
                   *pd = &m->xy[2 * tr[(i + 2) % 3]];
      if (cot_side(c, c->cmax, pa, pb, pd) > 0)
        return fail(c, "triangle %zu has an angle of %.9g degrees (above %g)", t,
                    angle_deg(pa, pb, pd), c->o->max_deg);
    }
  }
  return 0;
}

static int cmp_u64(const void *a, const void *b) {
  uint64_t x = *(const uint64_t *)a, y = *(const uint64_t *)b;
  return (x > y) - (x < y);
}

static int has_key(const gc_t *c, uint64_t k) {
  size_t lo = 0, hi = c->ne;
  while (lo < hi) {
    size_t mid = lo + (hi - lo) / 2;
    if (c->keys[mid] < k)
      lo = mid + 1;
    else
      hi = mid;
  }
  return lo < c->ne && c->keys[lo] == k;
}

static int has_edge(const gc_t *c, uint64_t a, uint64_t b) {
  return has_key(c, a << 32 | b) || has_key(c, b << 32 | a);
}

/* Vertex keys: the bits of (x, y), then the index, for exact lookups. */
typedef struct vkey {
  uint64_t x, y;
  uint32_t i;
} vkey_t;

static int cmp_vkey(const void *pa, const void *pb) {
  const vkey_t *a = pa, *b = pb;
  if (a->x != b->x) return a->x < b->x ? -1 : 1;
  if (a->y != b->y) return a->y < b->y ? -1 : 1;
  return (a->i > b->i) - (a->i < b->i);
}

static vkey_t vkey_of(const double *p, uint32_t i) {
  vkey_t k = {0, 0, i};
  memcpy(&k.x, &p[0], 8), memcpy(&k.y, &p[1], 8);
  return k;
}

/* Input vertices back bit-identical, mesh vertices distinct; fills in2m / m2in. */
static int check_vertices(gc_t *c) {
  const mcr_mesh_t *m = c->m;
  vkey_t *k = xmalloc(m->nv * sizeof *k);
  int r = 0;
  for (size_t i = 0; i < m->nv; i++) {
    if (!isfinite(m->xy[2 * i]) || !isfinite(m->xy[2 * i + 1])) {
      r = fail(c, "mesh vertex %zu is not finite", i);
      break;
    }
    k[i] = vkey_of(&m->xy[2 * i], (uint32_t)i);
  }
  if (!r) qsort(k, m->nv, sizeof *k, cmp_vkey);
  for (size_t i = 1; !r && i < m->nv; i++)
    if (k[i].x == k[i - 1].x && k[i].y == k[i - 1].y)
      r = fail(c, "mesh vertices %u and %u coincide", k[i - 1].i, k[i].i);
  for (size_t i = 0; i < m->nv; i++) c->m2in[i] = UINT32_MAX;
  for (size_t v = 0; !r && v < c->in->nv; v++) {
    vkey_t q = vkey_of(&c->in->xy[2 * v], 0);
    size_t lo = 0, hi = m->nv;
    while (lo < hi) {
      size_t mid = lo + (hi - lo) / 2;
      if (cmp_vkey(&k[mid], &q) < 0)
        lo = mid + 1;
      else
        hi = mid;
    }
    if (lo == m->nv || k[lo].x != q.x || k[lo].y != q.y)
      r = fail(c, "input vertex %zu (%.17g, %.17g) is not a mesh vertex (bit-identical)", v,
               c->in->xy[2 * v], c->in->xy[2 * v + 1]);
    else
      c->in2m[v] = k[lo].i, c->m2in[k[lo].i] = (uint32_t)v;
  }
  free(k);
  return r;
}

/* Is p on the closed segment a-b, exactly? */
static int on_segment(gc_t *c, const double *a, const double *b, const double *p) {
  if (p[0] < fmin(a[0], b[0]) || p[0] > fmax(a[0], b[0]) || p[1] < fmin(a[1], b[1]) ||
      p[1] > fmax(a[1], b[1]))
    return 0;
  return orient(c, a, b, p) == 0;
}

/* A bucket grid over the mesh vertices. */
typedef struct grid {
  double x0, y0, w, h;
  size_t nx, ny;
  size_t *start; /* nx * ny + 1 */
  uint32_t *v;
} grid_t;

static size_t cell_x(const grid_t *g, double x) {
  double f = (x - g->x0) / g->w * (double)g->nx;
  if (!(f > 0)) return 0;
  return f >= (double)g->nx ? g->nx - 1 : (size_t)f;
}
static size_t cell_y(const grid_t *g, double y) {
  double f = (y - g->y0) / g->h * (double)g->ny;
  if (!(f > 0)) return 0;
  return f >= (double)g->ny ? g->ny - 1 : (size_t)f;
}

static void grid_build(grid_t *g, const mcr_mesh_t *m) {
  double lo[2] = {m->xy[0], m->xy[1]}, hi[2] = {m->xy[0], m->xy[1]};
  for (size_t i = 0; i < m->nv; i++)
    for (int k = 0; k < 2; k++)
      lo[k] = fmin(lo[k], m->xy[2 * i + k]), hi[k] = fmax(hi[k], m->xy[2 * i + k]);
  g->x0 = lo[0], g->y0 = lo[1];
  g->w = hi[0] - lo[0] > 0 ? hi[0] - lo[0] : 1, g->h = hi[1] - lo[1] > 0 ? hi[1] - lo[1] : 1;
  size_t side = (size_t)sqrt((double)m->nv / 2) + 1;
  g->nx = g->ny = side;
  g->start = calloc(side * side + 1, sizeof *g->start);
  g->v = xmalloc(m->nv * sizeof *g->v);
  if (!g->start) abort();
  for (size_t i = 0; i < m->nv; i++)
    g->start[cell_y(g, m->xy[2 * i + 1]) * side + cell_x(g, m->xy[2 * i]) + 1]++;
  for (size_t i = 0; i < side * side; i++) g->start[i + 1] += g->start[i];
  size_t *fill = xmalloc((side * side + 1) * sizeof *fill);
  memcpy(fill, g->start, (side * side + 1) * sizeof *fill);
  for (size_t i = 0; i < m->nv; i++)
    g->v[fill[cell_y(g, m->xy[2 * i + 1]) * side + cell_x(g, m->xy[2 * i])]++] = (uint32_t)i;
  free(fill);
}

/* The mesh vertices exactly on segment a-b, into out (returns how many): the grid's
 * columns the segment spans, and in each the rows its part of the line can reach. A
 * vertex's column is cell_x of its x, which lies in [cx0, cx1]; the line's y range is
 * taken over the column widened by a column on each side, plus a row of slack, which
 * absorbs the rounding of these computations. Each cell is visited once. */
static size_t vertices_on(gc_t *c, const grid_t *g, const double *a, const double *b,
                          uint32_t *out) {
  size_t k = 0;
  double xmin = fmin(a[0], b[0]), xmax = fmax(a[0], b[0]), cw = g->w / (double)g->nx;
  size_t cx0 = cell_x(g, xmin), cx1 = cell_x(g, xmax);
  for (size_t cx = cx0; cx <= cx1; cx++) {
    double xl = g->x0 + cw * ((double)cx - 1), xh = g->x0 + cw * ((double)cx + 2);
    xl = fmax(xl, xmin), xh = fmin(xh, xmax);
    double ylo = fmin(a[1], b[1]), yhi = fmax(a[1], b[1]);
    if (a[0] != b[0] && xl <= xh) {
      double t0 = (xl - a[0]) / (b[0] - a[0]), t1 = (xh - a[0]) / (b[0] - a[0]);
      double y0 = a[1] + t0 * (b[1] - a[1]), y1 = a[1] + t1 * (b[1] - a[1]);
      ylo = fmax(ylo, fmin(y0, y1)), yhi = fmin(yhi, fmax(y0, y1));
    }
    size_t ry0 = cell_y(g, ylo), ry1 = cell_y(g, yhi);
    if (ry0 > ry1) ry0 = 0, ry1 = g->ny - 1; /* rounding gone wrong: the whole column */
    ry0 = ry0 ? ry0 - 1 : 0, ry1 = ry1 + 1 < g->ny ? ry1 + 1 : ry1;
    for (size_t ry = ry0; ry <= ry1; ry++) {
      size_t cell = ry * g->nx + cx;
      for (size_t i = g->start[cell]; i < g->start[cell + 1]; i++)
        if (on_segment(c, a, b, &c->m->xy[2 * g->v[i]])) out[k++] = g->v[i];
    }
  }
  return k;
}

/* Every input segment is the chain of mesh edges through the mesh vertices on it; fills
 * the vertex -> segments lists (on0 / on). */
static int check_segments(gc_t *c) {
  const mcr_input_t *in = c->in;
  const mcr_mesh_t *m = c->m;
  grid_t g;
  grid_build(&g, m);
  uint32_t *buf = xmalloc((m->nv + 1) * sizeof *buf);
  size_t cap = 4 * in->ns + 16, n_pairs = 0;
  uint64_t *pairs = xmalloc(cap * sizeof *pairs); /* vertex << 32 | segment */
  int r = 0;
  for (size_t s = 0; s < in->ns; s++) { /* all of them: the lists are used after a failure */
    const double *a = &in->xy[2 * in->seg[2 * s]], *b = &in->xy[2 * in->seg[2 * s + 1]];
    size_t k = vertices_on(c, &g, a, b, buf);
    /* Order along the segment: by x, or by y for a vertical one (insertion sort). */
    int ax = a[0] != b[0] ? 0 : 1, up = a[ax] < b[ax];
    for (size_t i = 1; i < k; i++)
      for (size_t j = i; j > 0; j--) {
        double p = m->xy[2 * buf[j] + ax], q = m->xy[2 * buf[j - 1] + ax];
        if (up ? p >= q : p <= q) break;
        uint32_t t = buf[j];
        buf[j] = buf[j - 1], buf[j - 1] = t;
      }
    if (!r &&
        (k < 2 || buf[0] != c->in2m[in->seg[2 * s]] || buf[k - 1] != c->in2m[in->seg[2 * s + 1]]))
      r = fail(c, "segment %zu: its endpoints are not the ends of the mesh vertices on it", s);
    for (size_t i = 1; !r && i < k; i++)
      if (!has_edge(c, buf[i - 1], buf[i]))
        r = fail(c,
                 "segment %zu is not covered: mesh vertices %u (%.17g, %.17g) and %u on it are "
                 "not joined by a mesh edge",
                 s, buf[i - 1], m->xy[2 * buf[i - 1]], m->xy[2 * buf[i - 1] + 1], buf[i]);
    for (size_t i = 0; i < k; i++) {
      if (n_pairs == cap) {
        cap *= 2;
        pairs = realloc(pairs, cap * sizeof *pairs);
        if (!pairs) abort();
      }
      pairs[n_pairs++] = (uint64_t)buf[i] << 32 | s;
    }
  }
  qsort(pairs, n_pairs, sizeof *pairs, cmp_u64);
  c->on0 = calloc(m->nv + 1, sizeof *c->on0);
  c->on = xmalloc((n_pairs + 1) * sizeof *c->on);
  if (!c->on0) abort();
  for (size_t i = 0; i < n_pairs; i++)
    c->on0[(pairs[i] >> 32) + 1]++, c->on[i] = (uint32_t)pairs[i];
  for (size_t v = 0; v < m->nv; v++) c->on0[v + 1] += c->on0[v];
  free(pairs);
  free(buf);
  free(g.start);
  free(g.v);
  return r;
}

/* Do mesh vertices a and b lie on a common input segment? */
static int common_segment(const gc_t *c, uint32_t a, uint32_t b) {
  for (size_t i = c->on0[a]; i < c->on0[a + 1]; i++)
    for (size_t j = c->on0[b]; j < c->on0[b + 1]; j++)
      if (c->on[i] == c->on[j]) return 1;
  return 0;
}

/* Twinless edges on segments; edge lengths; the kept area from the boundary edges. */
static int check_edges(gc_t *c, mcr_report_t *rep) {
  const mcr_mesh_t *m = c->m;
  double h2 = c->o->max_edge * c->o->max_edge;
  mpq_t area, h;
  mpq_inits(area, h, NULL);
  mpq_set_d(h, c->o->max_edge), mpq_mul(h, h, h);
  int r = 0;
  for (size_t i = 0; !r && i < c->ne; i++) {
    uint32_t a = (uint32_t)(c->keys[i] >> 32), b = (uint32_t)c->keys[i];
    const double *p = &m->xy[2 * a], *q = &m->xy[2 * b];
    int twin = has_key(c, (uint64_t)b << 32 | a);
    if (c->o->max_edge > 0 && (!twin || a < b)) {
      double dx = q[0] - p[0], dy = q[1] - p[1], l2 = dx * dx + dy * dy;
      if (!(l2 < h2 * (1 - 1e-12))) {
        mpq_t *t = c->q;
        qdiff(t[0], q[0], p[0], t[7]), qdiff(t[1], q[1], p[1], t[7]);
        mpq_mul(t[0], t[0], t[0]), mpq_mul(t[1], t[1], t[1]), mpq_add(t[0], t[0], t[1]);
        if (mpq_cmp(t[0], h) > 0)
          r = fail(c, "edge %u-%u is %.17g long, above the bound %g", a, b, sqrt(l2),
                   c->o->max_edge);
      }
    }
    if (twin || r) continue;
    rep->boundary_edges++;
    if (!common_segment(c, a, b))
      r = fail(c,
               "edge (%.17g, %.17g)-(%.17g, %.17g) has no twin and lies on no input segment "
               "(a gap or a hanging vertex)",
               p[0], p[1], q[0], q[1]);
    /* Twice the area: the sum of p x q over the boundary edges (interior edges cancel). */
    mpq_set_d(c->q[0], p[0]), mpq_set_d(c->q[1], q[1]), mpq_mul(c->q[0], c->q[0], c->q[1]);
    mpq_set_d(c->q[2], p[1]), mpq_set_d(c->q[3], q[0]), mpq_mul(c->q[2], c->q[2], c->q[3]);
    mpq_sub(c->q[0], c->q[0], c->q[2]), mpq_add(area, area, c->q[0]);
  }
  rep->area = mpq_get_d(area) / 2;
  if (!r && c->o->n_rings) {
    mpq_t want, ring;
    mpq_inits(want, ring, NULL);
    for (size_t k = 0; k < c->o->n_rings; k++) {
      mpq_set_ui(ring, 0, 1);
      size_t s0 = c->o->ring_start[k], s1 = c->o->ring_start[k + 1];
      for (size_t i = s0; i < s1; i++) {
        const double *p = &c->in->xy[2 * c->o->ring_v[i]];
        const double *q = &c->in->xy[2 * c->o->ring_v[i + 1 < s1 ? i + 1 : s0]];
        mpq_set_d(c->q[0], p[0]), mpq_set_d(c->q[1], q[1]), mpq_mul(c->q[0], c->q[0], c->q[1]);
        mpq_set_d(c->q[2], p[1]), mpq_set_d(c->q[3], q[0]), mpq_mul(c->q[2], c->q[2], c->q[3]);
        mpq_sub(c->q[0], c->q[0], c->q[2]), mpq_add(ring, ring, c->q[0]);
      }
      mpq_abs(ring, ring);
      if (c->o->ring_sign[k] < 0)
        mpq_sub(want, want, ring);
      else
        mpq_add(want, want, ring);
    }
    if (!mpq_equal(want, area))
      r = fail(c, "the triangles cover area %.17g, the rings enclose %.17g", mpq_get_d(area) / 2,
               mpq_get_d(want) / 2);
    mpq_clears(want, ring, NULL);
  }
  if (!r && !(mpq_sgn(area) > 0)) r = fail(c, "the mesh encloses no area");
  mpq_clears(area, h, NULL);
  return r;
}

/* Output segments: mesh edges exactly on their input segment. */
static int check_output_segments(gc_t *c) {
  const mcr_mesh_t *m = c->m;
  for (size_t k = 0; k < m->no; k++) {
    uint32_t s = m->oseg_of[k], a = m->oseg[2 * k], b = m->oseg[2 * k + 1];
    if (s >= c->in->ns || a >= m->nv || b >= m->nv)
      return fail(c, "output segment %zu names segment %u, vertices %u %u", k, s, a, b);
    const double *p = &c->in->xy[2 * c->in->seg[2 * s]], *q = &c->in->xy[2 * c->in->seg[2 * s + 1]];
    if (!on_segment(c, p, q, &m->xy[2 * a]) || !on_segment(c, p, q, &m->xy[2 * b]))
      return fail(c, "output segment %zu (%u-%u) is off input segment %u", k, a, b, s);
    if (!has_edge(c, a, b))
      return fail(c, "output segment %zu (%u-%u) is not a mesh edge", k, a, b);
  }
  return 0;
}

/* The smallest angle between two input segments at a vertex (floating point). */
static double smallest_input_angle(const gc_t *c) {
  double best = 180;
  for (size_t v = 0; v < c->in->nv; v++)
    for (size_t i = c->inc0[v]; i < c->inc0[v + 1]; i++)
      for (size_t j = i + 1; j < c->inc0[v + 1]; j++) {
        uint32_t si = c->inc[i], sj = c->inc[j];
        uint32_t oi = c->in->seg[2 * si] == v ? c->in->seg[2 * si + 1] : c->in->seg[2 * si];
        uint32_t oj = c->in->seg[2 * sj] == v ? c->in->seg[2 * sj + 1] : c->in->seg[2 * sj];
        double d = angle_deg(&c->in->xy[2 * v], &c->in->xy[2 * oi], &c->in->xy[2 * oj]);
        if (d < best) best = d;
      }
  return best;
}

int mcr_check_general(const mcr_input_t *in, const mcr_mesh_t *m, const mcr_opts_t *opts,
                      mcr_report_t *rep_out, char *msg, size_t n) {
  mcr_report_t rep;
  memset(&rep, 0, sizeof rep);
  gc_t c;
  memset(&c, 0, sizeof c);
  c.in = in, c.m = m, c.o = opts, c.msg = msg, c.n = n;
  msg[0] = 0;
  if (m->nv == 0 || m->nt == 0) return snprintf(msg, n, "empty mesh"), 1;
  for (int i = 0; i < 8; i++) mpq_init(c.q[i]);
  /* Strict-side cotangents: cmin <= cot(min_deg), cmax >= cot(max_deg). */
  c.cmin = c.cmax = NAN;
  if (opts->min_deg > 0) {
    double t = 1 / tan(opts->min_deg * PI / 180);
    c.cmin = opts->min_deg == 45 ? 1 : t - fabs(t) * 1e-12;
  }
  if (opts->max_deg > 0) {
    double t = 1 / tan(opts->max_deg * PI / 180);
    c.cmax = opts->max_deg == 90 ? 0 : t + fabs(t) * 1e-12;
  }
  c.in2m = xmalloc((in->nv + 1) * sizeof *c.in2m);
  c.m2in = xmalloc((m->nv + 1) * sizeof *c.m2in);
  c.inc0 = calloc(in->nv + 2, sizeof *c.inc0);
  c.inc = xmalloc((2 * in->ns + 1) * sizeof *c.inc);
  c.ne = 3 * m->nt;
  c.keys = xmalloc(c.ne * sizeof *c.keys);
  if (!c.inc0) abort();
  int r = 0;
  for (size_t s = 0; !r && s < in->ns; s++) {
    if (in->seg[2 * s] >= in->nv || in->seg[2 * s + 1] >= in->nv)
      r = fail(&c, "input segment %zu names a vertex that does not exist", s);
    else
      c.inc0[in->seg[2 * s] + 1]++, c.inc0[in->seg[2 * s + 1] + 1]++;
  }
  for (size_t v = 0; v < in->nv; v++) c.inc0[v + 1] += c.inc0[v];
  if (!r) {
    size_t *fill = xmalloc((in->nv + 1) * sizeof *fill);
    memcpy(fill, c.inc0, (in->nv + 1) * sizeof *fill);
    for (size_t s = 0; s < in->ns; s++)
      c.inc[fill[in->seg[2 * s]]++] = (uint32_t)s, c.inc[fill[in->seg[2 * s + 1]]++] = (uint32_t)s;
    free(fill);
    rep.smallest_input_angle_deg = smallest_input_angle(&c);
  }
  if (!r) r = check_vertices(&c);
  for (size_t t = 0; !r && t < m->nt; t++)
    for (int i = 0; !r && i < 3; i++)
      if (m->tri[3 * t + i] >= m->nv)
        r = fail(&c, "triangle %zu uses vertex %u of %zu", t, m->tri[3 * t + i], m->nv);
  /* Angles (check_triangles) come first in what is reported, but the wedge rule needs the
   * vertex-to-segment lists, so a failed segment check is only reported after them. */
  int rseg = 0;
  char segmsg[512] = "";
  if (!r) {
    for (size_t t = 0; t < m->nt; t++)
      for (int i = 0; i < 3; i++)
        c.keys[3 * t + i] = (uint64_t)m->tri[3 * t + i] << 32 | m->tri[3 * t + (i + 1) % 3];
    qsort(c.keys, c.ne, sizeof *c.keys, cmp_u64);
    c.msg = segmsg, c.n = sizeof segmsg;
    rseg = check_segments(&c);
    c.msg = msg, c.n = n;
  }
  if (!r) r = check_triangles(&c, &rep);
  for (size_t i = 1; !r && i < c.ne; i++)
    if (c.keys[i] == c.keys[i - 1])
      r = fail(&c, "directed edge %u->%u is used twice (overlapping triangles)",
               (unsigned)(c.keys[i] >> 32), (unsigned)c.keys[i]);
  if (!r && rseg) r = 1, snprintf(msg, n, "%s", segmsg);
  if (!r) r = check_edges(&c, &rep);
  if (!r) r = check_output_segments(&c);
  for (int i = 0; i < 8; i++) mpq_clear(c.q[i]);
  free(c.in2m), free(c.m2in), free(c.inc0), free(c.inc), free(c.keys), free(c.on0), free(c.on);
  if (rep_out) *rep_out = rep;
  return r;
}
#endif
