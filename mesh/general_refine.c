/*
 * The general mode, step 9: Delaunay refinement (Ruppert 1995; Shewchuk 2002) on the CDT
 * the seeds and split points made. Encroached subsegments are split first, at exact dyadic
 * points of their input segment (concentric shells next to an input vertex); then a bad
 * triangle (smallest angle below the bound, or an edge above the size bound) gets its
 * circumcentre, unless that point is hidden behind a subsegment or would encroach one, in
 * which case those subsegments are split instead. Next to an input angle phi below 60
 * degrees (docs/mesh.md, "Small input angles", which has the proofs): a skinny triangle
 * whose shortest edge joins two points at equal distance on its two segments, lying in
 * their wedge, is left alone (exempt) when its smallest angle is at least
 * g(phi) = arctan(sin phi / (2.02 - cos phi)), and split otherwise; a piece touching the
 * apex is never split below the floor (2^-48 of its segment), a triangle that would need it
 * is rejected, and a mesh still holding a bad triangle at the end is refused.
 */
#include "mesh/cdt_internal.h"
#include "index/inline.h"
#include "mesh/expansion.h"
#include "mesh/general_mesh.h"

#include <assert.h>
#include <math.h>
#include <string.h>

int qk__gm_split_param(const qk__gm_t *g, uint32_t s, uint64_t lo, uint64_t hi, uint64_t *k);
static int protected_piece(const qk__gm_t *g, uint32_t s, uint64_t lo, uint64_t hi);

/* The exact budget of a segment, clamped to [-1, 62]. */
static int exact_budget(const double A[2], const double B[2]) {
  int bud = qk__seg_budget(A, B);
  return bud > 62 ? 62 : bud < -1 ? -1 : bud;
}

int qk__gm_split_param(const qk__gm_t *g, uint32_t s, uint64_t lo, uint64_t hi, uint64_t *k) {
  const qk_poly_t *P = g->P;
  uint32_t u = P->seg[2 * s], w = P->seg[2 * s + 1];
  const double A[2] = {P->vx[u], P->vy[u]}, B[2] = {P->vx[w], P->vy[w]};
  int bud = g->sbud[s];
  if (bud == QK__GM_SBUD_UNSET) {
    bud = exact_budget(A, B);
    if (bud < 62 && (A[0] == B[0] || A[1] == B[1])) bud = QK__GM_SBUD_FREE;
    g->sbud[s] = (int8_t)bud;
  }
  int shell = lo == 0 ? g->vsmall[u] : hi == QK__GM_ONE ? g->vsmall[w] : 0;
  const int apex = (lo == 0) != (hi == QK__GM_ONE) && shell;
  /* A free segment splits anywhere (to an ulp) but at the apex of a small input angle,
   * whose shells the termination proof needs at exact radii: there its exact budget. */
  if (bud == QK__GM_SBUD_FREE) bud = apex ? exact_budget(A, B) : 62;
  if (bud < 1 || hi - lo < 2 || protected_piece(g, s, lo, hi)) return 0;
  uint64_t q = (uint64_t)1 << (62 - bud), target = lo + (hi - lo) / 2;
  if (apex) {
    /* Concentric shells at the apex of a small input angle: the split point's distance
     * from the apex is the power of two nearest half the piece's length, so that pieces of
     * segments meeting there split at equal radii (Shewchuk 2002). Elsewhere, the exact
     * midpoint in parameter. */
    double len = hypot(B[0] - A[0], B[1] - A[1]), L = len * ldexp((double)(hi - lo), -62);
    int ex;
    double f = frexp(L / 2, &ex), d = ldexp(1.0, f < 0.70710678118654752 ? ex - 1 : ex);
    double dk = ldexp(d / len, 62);
    if (dk > 0 && dk < (double)(hi - lo)) {
      uint64_t D = (uint64_t)dk;
      target = lo == 0 ? lo + D : hi - D;
    }
  }
  uint64_t K = (target + q / 2) / q * q;
  if (K <= lo || K >= hi) K = (lo + (hi - lo) / 2 + q / 2) / q * q;
  if (K <= lo || K >= hi) K = lo / q * q + q;
  if (K <= lo || K >= hi) return 0;
  *k = K;
  return 1;
}

int qk__gm_split_point(const qk__gm_t *g, uint32_t s, uint64_t k, const double e0[2],
                       const double e1[2], double p[2]) {
  const qk_poly_t *P = g->P;
  uint32_t u = P->seg[2 * s], w = P->seg[2 * s + 1];
  const double A[2] = {P->vx[u], P->vy[u]}, B[2] = {P->vx[w], P->vy[w]};
  /* The trailing zero bits of k (0 < k < 2^62): the pre-split's midpoints have dozens. */
#if defined(__GNUC__) || defined(__clang__)
  int tz = __builtin_ctzll(k);
#else
  int tz = 0;
  while (!((k >> tz) & 1)) tz++;
#endif
  qk__seg_point_in(A, B, k >> tz, 62 - tz, p);  /* 0 < k < 2^62 on the budget's grid */
  if (g->sbud[s] != QK__GM_SBUD_FREE) return 1; /* exact */
  /* Free: the constant coordinate is A's (copied: A + k 0 would turn -0 into 0), the other
   * rounded (a few roundings, each monotone in k); strictly between the piece's ends, it
   * keeps their order. */
  const int i = A[0] == B[0]; /* the coordinate that varies along the segment */
  p[1 - i] = A[1 - i];
  return p[i] > fmin(e0[i], e1[i]) && p[i] < fmax(e0[i], e1[i]);
}

/* The floor next to a small input angle (docs/mesh.md, "The refinement" and "Small input
 * angles"): a
 * piece of segment s that touches the apex of an input angle below 60 degrees and spans
 * less than 2^-48 of s (2^14 parameter steps of 2^-62) is never split, so every vertex on
 * such a segment stays at least 2^-50 of its length from the apex: the descent towards an
 * apex stops after at most 48 halvings, and the termination proof (docs/mesh.md, "Small
 * input angles") uses that distance. */
#define GM_FLOOR_STEPS ((uint64_t)1 << 14)

static int protected_piece(const qk__gm_t *g, uint32_t s, uint64_t lo, uint64_t hi) {
  const qk_poly_t *P = g->P;
  int at_u = lo == 0 && g->vsmall[P->seg[2 * s]],
      at_w = hi == QK__GM_ONE && g->vsmall[P->seg[2 * s + 1]];
  return (at_u || at_w) && hi - lo < GM_FLOOR_STEPS;
}

/* qk__gm_split, telling whether it split: *done is 0 when the piece a-b is protected by the
 * floor (nothing inserted), 1 otherwise. */
static qk_status_t split_piece(qk__gm_t *g, uint32_t a, uint32_t b, uint32_t s, int *done) {
  const qk_poly_t *P = g->P;
  uint64_t lo = qk__gm_param(g, a, s), hi = qk__gm_param(g, b, s), k;
  if (lo > hi) {
    uint64_t t = lo;
    lo = hi, hi = t;
  }
  *done = !protected_piece(g, s, lo, hi);
  if (!*done) return QK_OK;
  uint32_t u = P->seg[2 * s], w = P->seg[2 * s + 1];
  const double A[2] = {P->vx[u], P->vy[u]}, B[2] = {P->vx[w], P->vy[w]};
  int kk = 0;
  uint32_t t = QK__CDT_NONE, v;
  double p[2];
  int ok = qk__gm_split_param(g, s, lo, hi, &k);
  if (ok) {
    t = qk__cdt_find_edge(&g->cdt, a, b, &kk);
    if (t == QK__CDT_NONE) return QK_OK; /* split already */
    ok = qk__gm_split_point(g, s, k, qk__gm_vxy(g, a), qk__gm_vxy(g, b), p);
  }
  if (!ok) {
    /* The step the split needs: the piece spans (hi - lo) 2^-62 of the segment. */
    int need = 62 - (int)floor(log2((double)(hi - lo))) + 1, bud = qk__seg_budget(A, B);
    unsigned long line = P->sline ? P->sline[s] : 0;
    char nm[80], has[112];
    const int apex = (lo == 0 && g->vsmall[u]) || (hi == QK__GM_ONE && g->vsmall[w]);
    if (g->sbud[s] == QK__GM_SBUD_FREE && !apex) /* (axis-parallel: any double on it) */
      snprintf(has, sizeof has, "any double on it, but none strictly inside this piece");
    else if (g->sbud[s] == QK__GM_SBUD_FREE && bud < 1) /* (the shells need exact points) */
      snprintf(has, sizeof has, "none, and at the apex of a small input angle it must be exact");
    else if (g->sbud[s] == QK__GM_SBUD_FREE)
      snprintf(has, sizeof has, "2^-%d, and at the apex of a small input angle it must be exact",
               bud < 62 ? bud : 62);
    else if (bud < 1)
      snprintf(has, sizeof has, "none guaranteed");
    else
      snprintf(has, sizeof has, "2^-%d", bud < 62 ? bud : 62);
    return qk__mesh_fail(g->err, QK_ERR_GEOMETRY, line,
                         "%s from (%.17g, %.17g) to (%.17g, %.17g) needs a split point at steps "
                         "of 2^-%d of its length; exact ones: %s. Round the input to a grid "
                         "(a coarser one if it was rounded already)",
                         qk__gm_sname(P, "segment", s, line, nm), A[0], A[1], B[0], B[1], need,
                         has);
  }
  int existed;
  qk_status_t st = qk__gm_insert(g, p[0], p[1], t, kk, QK__CDT_EDGE, s, k, &v, &existed);
  if (st) return qk__mesh_fail(g->err, st, 0, "out of memory");
  return QK_OK;
}

qk_status_t qk__gm_split(qk__gm_t *g, uint32_t a, uint32_t b, uint32_t s) {
  int done;
  return split_piece(g, a, b, s, &done);
}

static double d2(const double *p, const double *q) {
  double x = p[0] - q[0], y = p[1] - q[1];
  return x * x + y * y;
}

static int exempt_at(const qk__gm_t *g, const uint32_t *tv, int i);

int qk__gm_exempt(const qk__gm_t *g, const uint32_t *tv) {
  const qk__cdt_t *c = &g->cdt;
  double l[3];
  for (int i = 0; i < 3; i++) l[i] = d2(&c->xy[2 * tv[(i + 1) % 3]], &c->xy[2 * tv[(i + 2) % 3]]);
  return exempt_at(g, tv, l[0] <= l[1] && l[0] <= l[2] ? 0 : l[1] <= l[2] ? 1 : 2);
}

/* qk__gm_exempt with i, the slot opposite the triangle's shortest edge (the first of the
 * shortest), known. */
static int exempt_at(const qk__gm_t *g, const uint32_t *tv, int i) {
  const qk__cdt_t *c = &g->cdt;
  const qk_poly_t *P = g->P;
  uint32_t p = tv[(i + 1) % 3], q = tv[(i + 2) % 3];
  uint32_t s1 = g->vi[p].seg, s2 = g->vi[q].seg;
  if (s1 == QK__CDT_NONE || s2 == QK__CDT_NONE || s1 == s2) return 0;
  for (int x = 0; x < 2; x++)
    for (int y = 0; y < 2; y++) {
      uint32_t apex = P->seg[2 * s1 + x];
      if (apex != P->seg[2 * s2 + y]) continue;
      uint32_t o1 = P->seg[2 * s1 + 1 - x], o2 = P->seg[2 * s2 + 1 - y];
      double ux = P->vx[o1] - P->vx[apex], uy = P->vy[o1] - P->vy[apex];
      double wx = P->vx[o2] - P->vx[apex], wy = P->vy[o2] - P->vy[apex];
      double C = fabs(ux * wy - uy * wx), D = ux * wx + uy * wy;
      if (!(atan2(C, D) < 1.0471975511965976)) return 0; /* 60 degrees */
      const double ap[2] = {P->vx[apex], P->vy[apex]};
      double r1 = sqrt(d2(&c->xy[2 * p], ap)), r2 = sqrt(d2(&c->xy[2 * q], ap));
      if (!(fabs(r1 - r2) <= 1e-3 * fmax(r1, r2))) return 0;
      /* The triangle faces the input angle: its third corner lies in the closed wedge
       * (exact orientations; p and q lie on its sides). */
      const double *Z = &c->xy[2 * tv[i]], U[2] = {P->vx[o1], P->vy[o1]},
                   W[2] = {P->vx[o2], P->vy[o2]};
      int turn = qk__orient2d(ap, U, W);
      if (qk__orient2d(ap, U, Z) * turn < 0 || qk__orient2d(ap, Z, W) * turn < 0) return 0;
      /* The smallest angle, at z opposite the shortest edge, must be at least
       * g(phi) = arctan(sin phi / (2.02 - cos phi)) (docs/mesh.md, "Small input angles"):
       * tan = X / Y at z against C / (2.02 N - D), N = |u| |w|, with a relative margin of
       * 1e-6 for the rounding of both (the tests check the bound exactly). */
      const double *Pp = &c->xy[2 * p], *Pq = &c->xy[2 * q];
      double ax = Pp[0] - Z[0], ay = Pp[1] - Z[1], bx = Pq[0] - Z[0], by = Pq[1] - Z[1];
      double X = fabs(ax * by - ay * bx), Y = ax * bx + ay * by;
      if (Y <= 0) return 1;
      double N = sqrt((ux * ux + uy * uy) * (wx * wx + wy * wy));
      return X * (2.02 * N - D) >= Y * C * (1 + 1e-6);
    }
  return 0;
}

/* Is |pq|^2 > h^2, exactly? Each difference splits into a rounded part and its error, each
 * square and the cross term into products and their errors; the sum is an exact expansion
 * whose sign is its largest component's. */
static int len2_exceeds(const double *p, const double *q, double h) {
  double x[16];
  int n = 0;
  for (int i = 0; i < 2; i++) {
    double dh, dl;
    qk__two_sum(p[i], -q[i], &dh, &dl);
    const double f[3][2] = {{dh, dh}, {2 * dh, dl}, {dl, dl}};
    for (int k = 0; k < 3; k++) {
      double pr = f[k][0] * f[k][1];
      qk__exp_grow(x, &n, fma(f[k][0], f[k][1], -pr));
      qk__exp_grow(x, &n, pr);
    }
  }
  double hh = h * h;
  qk__exp_grow(x, &n, -fma(h, h, -hh));
  qk__exp_grow(x, &n, -hh);
  return n > 0 && x[n - 1] > 0;
}

/* qk__gm_is_bad for a triangle of a kept face (inlined in the refinement's checks, which
 * have looked at the face already). */
static inline int bad_kept(const qk__gm_t *g, uint32_t t) {
  const qk__cdt_t *c = &g->cdt;
  const uint32_t *tv = &c->v[3 * t];
  const double *p0 = &c->xy[2 * tv[0]], *p1 = &c->xy[2 * tv[1]], *p2 = &c->xy[2 * tv[2]];
  /* l_i: the squared length of the edge opposite vertex i. Written out (no arrays indexed
   * by i modulo 3) so that it all stays in registers; the arithmetic is the same. */
  double l0 = d2(p1, p2), l1 = d2(p2, p0), l2 = d2(p0, p1);
  double lmax = l0 > l1 ? l0 : l1;
  lmax = l2 > lmax ? l2 : lmax;
  const qk_mesh_options_t *opt = g->opt;
  if (g->size_plain) { /* the same tests as below, on the bound's squares kept in g */
    if (lmax > g->h2_hi) return 1;
    if (lmax >= g->h2_lo && (len2_exceeds(p1, p2, g->h_plain) || len2_exceeds(p2, p0, g->h_plain) ||
                             len2_exceeds(p0, p1, g->h_plain)))
      return 1;
  } else if (opt->max_size > 0 || opt->size_fn) {
    double h = opt->max_size > 0 ? opt->max_size : INFINITY;
    if (opt->size_fn) {
      double cx = (p0[0] + p1[0] + p2[0]) / 3, cy = (p0[1] + p1[1] + p2[1]) / 3;
      double v = opt->size_fn(cx, cy, opt->size_user);
      if (v > 0 && v < h) h = v;
    }
    double h2 = h * h;
    if (lmax > h2 * (1 + 0x1p-48)) return 1;
    /* Within rounding of h: decide exactly, so that an edge of exactly h (a leaf's side) is
     * good and one a hair longer is not. */
    if (lmax >= h2 * (1 - 0x1p-48) &&
        (len2_exceeds(p1, p2, h) || len2_exceeds(p2, p0, h) || len2_exceeds(p0, p1, h)))
      return 1;
  }
  /* The smallest angle is at vertex o opposite the shortest edge (u, w the next two
   * counter-clockwise, lu and lw the squared lengths of the edges opposite them); below 90
   * degrees, so comparing squared sines is comparing angles. */
  const double *o, *u, *w;
  double lu, lw;
  int io;
  if (l0 <= l1 && l0 <= l2)
    o = p0, u = p1, w = p2, lu = l1, lw = l2, io = 0;
  else if (l1 <= l2)
    o = p1, u = p2, w = p0, lu = l2, lw = l0, io = 1;
  else
    o = p2, u = p0, w = p1, lu = l0, lw = l1, io = 2;
  double ux = u[0] - o[0], uy = u[1] - o[1], wx = w[0] - o[0], wy = w[1] - o[1];
  double cr = ux * wy - uy * wx;
  if (cr * cr >= g->sin2_bound * lw * lu) return 0;
  /* Exemption needs two segments meeting below 60 degrees (the smallest input angle, from
   * atan2 of directions, is far more exact than this 1-degree margin). */
  if (g->smallest_input_angle > 61) return 1;
  return !exempt_at(g, tv, io);
}

int qk__gm_is_bad(const qk__gm_t *g, uint32_t t) {
  return g->faces[g->face[t]].drop ? 0 : bad_kept(g, t);
}

/* The bad-triangle queue is a ring: g->bad_head and g->nbad count pops and pushes since the
 * start, the entry of count i is g->bad[i & (g->bad_cap - 1)], and bad_cap is a power of two
 * (qk__grow doubles from 16). It holds only the waiting triangles, and a push never moves
 * them, except when the ring is full and grows. */
#define BAD_AT(g, i) ((g)->bad[(i) & ((g)->bad_cap - 1)])

static qk_status_t push_bad_slow(qk__gm_t *g, uint32_t t) {
  size_t old = g->bad_cap, live = g->nbad - g->bad_head;
  void *p = g->bad;
  if (qk__grow(g->a, &p, &g->bad_cap, live + 1, sizeof *g->bad)) return QK_ERR_NOMEM;
  g->bad = p;
  /* Unwrap: the entries from the head's slot to the old end stay; those that had wrapped
   * to the front follow them. */
  size_t h = old ? g->bad_head & (old - 1) : 0;
  if (live && h + live > old) memcpy(g->bad + old, g->bad, (h + live - old) * sizeof *g->bad);
  g->nbad = h + live, g->bad_head = h; /* counts restart at the head's slot */
  const uint32_t *tv = &g->cdt.v[3 * t];
  BAD_AT(g, g->nbad) = (qk__gm_tq_t){t, tv[0], tv[1], tv[2]};
  g->nbad++;
  return QK_OK;
}

/* Queue triangle t as bad (inline while the ring has room). */
static inline qk_status_t push_bad(qk__gm_t *g, uint32_t t) {
  if (g->nbad - g->bad_head < g->bad_cap) {
    const uint32_t *tv = &g->cdt.v[3 * t];
    BAD_AT(g, g->nbad) = (qk__gm_tq_t){t, tv[0], tv[1], tv[2]};
    g->nbad++;
    return QK_OK;
  }
  return push_bad_slow(g, t);
}

static qk_status_t push_enc(qk__gm_t *g, uint32_t a, uint32_t b, uint32_t s) {
  if (3 * (g->nenc + 1) > g->enc_cap) {
    void *p = g->enc;
    if (qk__grow(g->a, &p, &g->enc_cap, 3 * (g->nenc + 1), sizeof *g->enc)) return QK_ERR_NOMEM;
    g->enc = p;
  }
  g->enc[3 * g->nenc] = a, g->enc[3 * g->nenc + 1] = b, g->enc[3 * g->nenc + 2] = s;
  g->nenc++;
  return QK_OK;
}

/* Is the constrained edge k of kept triangle t encroached by its apex there? */
static int apex_encroaches(const qk__gm_t *g, uint32_t t, int k) {
  const qk__cdt_t *c = &g->cdt;
  const uint32_t *tv = &c->v[3 * t];
  return qk__cdt_encroach(&c->xy[2 * tv[(k + 1) % 3]], &c->xy[2 * tv[(k + 2) % 3]],
                          &c->xy[2 * tv[k]]) < 0;
}

/* Queue what triangle t (changed or new), in a kept face, asks for: its encroached
 * subsegments (seen from a kept side) and itself when bad. */
static inline qk_status_t check_kept(qk__gm_t *g, uint32_t t) {
  const qk__cdt_t *c = &g->cdt;
  const uint32_t *ts = &c->seg[3 * t];
  if ((ts[0] & ts[1] & ts[2]) != QK__CDT_NONE) /* some edge constrained (NONE is all ones) */
    for (int k = 0; k < 3; k++)
      if (ts[k] != QK__CDT_NONE && apex_encroaches(g, t, k) &&
          push_enc(g, c->v[3 * t + (k + 1) % 3], c->v[3 * t + (k + 2) % 3], c->seg[3 * t + k]))
        return QK_ERR_NOMEM;
  return bad_kept(g, t) ? push_bad(g, t) : QK_OK;
}

/* check_kept for any triangle. */
static qk_status_t check(qk__gm_t *g, uint32_t t) {
  if (g->faces[g->face[t]].drop) return QK_OK;
  return check_kept(g, t);
}

/* The star of the last insertion's vertex v = g->dirty_v, all in face f = g->dirty_face
 * (g->star_pending): label its triangles f and, when f is kept, check_kept them, each
 * spoke's length computed once; one walk around v for both (the insertion leaves them to
 * this walk: a separate listing walk cost about 1.5% of the instructions). The ring is
 * counter-clockwise from vtri[v] across edge 1 of each triangle, as star() in
 * general_build.c lists it, v in slot 0 of each (mesh/cdt.h): the same triangles in the
 * same order, so the same queue. One copy for each of clear (below) and plain (g->size_plain),
 * constants there, with the arrays and the bounds in locals: the loop read them from g and
 * tested both flags on every triangle (about 5 of its 100 instructions a triangle: 14.1 M
 * against 13.3 M in all on South Africa at extent/256). */
static QK__ALWAYS_INLINE qk_status_t check_star_with(qk__gm_t *g, const int clear,
                                                     const int plain) {
  const qk__cdt_t *c = &g->cdt;
  const uint32_t v = g->dirty_v, f = g->dirty_face, first = c->vtri[v];
  const uint32_t *V = c->v, *N = c->nbr, *S = c->seg;
  const double *XY = c->xy;
  uint32_t *face = g->face;
  uint32_t t = first;
  if (g->faces[f].drop) {
    do {
      face[t] = f;
      t = N[3 * (size_t)t + 1];
    } while (t != first && t != QK__CDT_NONE);
    return QK_OK;
  }
  const double h2_hi = g->h2_hi, h2_lo = g->h2_lo, h = g->h_plain, sin2 = g->sin2_bound;
  const int exempt_possible = !(g->smallest_input_angle > 61);
  const double *pv = &XY[2 * (size_t)v];
  uint32_t prev = QK__CDT_NONE;
  double lx = 0;
  /* The ring's state in locals (nbad written back at the end and around a growth), not
   * read from g at every push (0.07% of the instructions on South Africa at extent/256). */
  qk__gm_tq_t *ring = g->bad;
  size_t nbad = g->nbad, mask = g->bad_cap - 1, room = g->bad_head + g->bad_cap;
  do {
    face[t] = f;
    const uint32_t *tv = &V[3 * (size_t)t], *ts = &S[3 * (size_t)t];
    assert(tv[0] == v);
    const uint32_t x = tv[1], y = tv[2];
    const double *px = &XY[2 * (size_t)x], *py = &XY[2 * (size_t)y];
    if (x != prev) lx = d2(pv, px); /* the first triangle (the ring is closed: x follows y) */
    const double ly = d2(pv, py);
    /* After a clear cavity (clear), v is a circumcentre inside a kept face, so no spoke is
     * constrained, and each far edge x-y was an edge of a cavity triangle (Lawson's flips
     * from p's triangle remove exactly the triangles the search found: those whose
     * circumcircles hold p, reached without crossing a constraint), whose constrained
     * edges the search tested against p with the same exact test and found none
     * encroached: nothing to test here. */
    assert(!clear || (ts[1] == QK__CDT_NONE && ts[2] == QK__CDT_NONE &&
                      (ts[0] == QK__CDT_NONE || !apex_encroaches(g, t, 0))));
    if (!clear && (ts[0] & ts[1] & ts[2]) != QK__CDT_NONE)
      for (int k = 0; k < 3; k++)
        if (ts[k] != QK__CDT_NONE && apex_encroaches(g, t, k) &&
            push_enc(g, V[3 * t + (k + 1) % 3], V[3 * t + (k + 2) % 3], S[3 * t + k]))
          return QK_ERR_NOMEM;
    /* bad_star's tests, written out here with the bounds in locals; a spoke longer than the
     * bound (most triangles bad by size have one) decides before the far edge's length is
     * computed. */
    int bad;
    double lo = 0;
    if (plain && (lx > h2_hi || ly > h2_hi)) {
      bad = 1;
    } else if (lo = d2(px, py), plain && lo > h2_hi) {
      bad = 1;
    } else if (plain && (lo > ly ? (lo > lx ? lo : lx) : (ly > lx ? ly : lx)) >= h2_lo &&
               (len2_exceeds(px, py, h) || len2_exceeds(py, pv, h) || len2_exceeds(pv, px, h))) {
      bad = 1;
    } else {
      const double *o, *u, *w;
      double lu, lw;
      int r;
      if (lo < ly && lo < lx)
        o = pv, u = px, w = py, lu = ly, lw = lx, r = 0;
      else if (ly < lo && ly < lx)
        o = px, u = py, w = pv, lu = lx, lw = lo, r = 1;
      else if (lx < lo && lx < ly)
        o = py, u = pv, w = px, lu = lo, lw = ly, r = 2;
      else
        o = NULL, u = w = NULL, lu = lw = 0, r = -1;
      if (r < 0) {
        bad = bad_kept(g, t);
      } else {
        double ux = u[0] - o[0], uy = u[1] - o[1], wx = w[0] - o[0], wy = w[1] - o[1];
        double cr = ux * wy - uy * wx;
        bad = cr * cr >= sin2 * lw * lu ? 0 : !exempt_possible ? 1 : !exempt_at(g, tv, r);
      }
    }
    if (bad) {
      if (nbad < room) {
        qk__gm_tq_t *e = &ring[nbad++ & mask];
        e->t = t, e->a = v, e->b = x, e->c = y;
      } else {
        g->nbad = nbad;
        if (push_bad_slow(g, t)) return QK_ERR_NOMEM;
        ring = g->bad, nbad = g->nbad, mask = g->bad_cap - 1, room = g->bad_head + g->bad_cap;
      }
    }
    lx = ly, prev = y;
    t = N[3 * (size_t)t + 1];
  } while (t != first && t != QK__CDT_NONE);
  g->nbad = nbad;
  return QK_OK;
}

static qk_status_t check_star(qk__gm_t *g, int clear) {
  if (g->size_plain) return clear ? check_star_with(g, 1, 1) : check_star_with(g, 0, 1);
  return clear ? check_star_with(g, 1, 0) : check_star_with(g, 0, 0);
}

/* Check the triangles the last insertion made (its star): when they share one face, its
 * label is looked at once. clear: the insertion was a circumcentre whose cavity search
 * was complete and found no encroached subsegment (CAVITY_CLEAR). */
static qk_status_t check_dirty_after(qk__gm_t *g, int clear) {
  size_t n = g->ndirty;
  g->ndirty = 0;
  if (g->star_pending) {
    g->star_pending = 0;
    return check_star(g, clear);
  }
  if (g->dirty_face != QK__CDT_NONE) {
    if (g->faces[g->dirty_face].drop) return QK_OK;
    for (size_t i = 0; i < n; i++)
      if (check_kept(g, g->dirty[i])) return QK_ERR_NOMEM;
    return QK_OK;
  }
  for (size_t i = 0; i < n; i++)
    if (check(g, g->dirty[i])) return QK_ERR_NOMEM;
  return QK_OK;
}

static qk_status_t check_dirty(qk__gm_t *g) { return check_dirty_after(g, 0); }

/* Is subsegment a-b still an edge, encroached from a kept side? */
static int still_encroached(const qk__gm_t *g, uint32_t a, uint32_t b) {
  const qk__cdt_t *c = &g->cdt;
  int k;
  uint32_t t = qk__cdt_find_edge(c, a, b, &k);
  if (t == QK__CDT_NONE) return 0;
  if (!g->faces[g->face[t]].drop && apex_encroaches(g, t, k)) return 1;
  uint32_t n = c->nbr[3 * t + k];
  if (n == QK__CDT_NONE || g->faces[g->face[n]].drop) return 0;
  for (int j = 0; j < 3; j++)
    if (c->nbr[3 * n + j] == t) return apex_encroaches(g, n, j);
  return 0;
}

static qk_status_t grow_stack(qk__gm_t *g, size_t need) {
  if (need <= g->stack_cap) return QK_OK;
  void *p = g->stack;
  if (qk__grow(g->a, &p, &g->stack_cap, need, sizeof *g->stack)) return QK_ERR_NOMEM;
  g->stack = p;
  return QK_OK;
}

/* The cavity stamps cover every triangle slot; new slots and a wrapped generation start
 * from 0 (no stamp). */
static qk_status_t grow_marks_to(qk__gm_t *g, size_t nt) {
  size_t c = g->mark_cap;
  if (nt > c) {
    void *p = g->mark;
    if (qk__grow(g->a, &p, &c, nt, sizeof *g->mark)) return QK_ERR_NOMEM;
    g->mark = p;
    memset(g->mark + g->mark_cap, 0, (c - g->mark_cap) * sizeof *g->mark);
    g->mark_cap = c;
  }
  if (g->mark_gen >= UINT32_MAX / 2) {
    memset(g->mark, 0, g->mark_cap * sizeof *g->mark);
    g->mark_gen = 0;
  }
  return QK_OK;
}

/* The cavity search's call: nothing to do once the refinement has reserved (tested inline,
 * the call per cavity was 0.16% of the instructions on Norway at 1/256). */
static inline qk_status_t grow_marks(qk__gm_t *g) {
  if (g->cdt.nt <= g->mark_cap && g->mark_gen < UINT32_MAX / 2) return QK_OK;
  return grow_marks_to(g, g->cdt.nt);
}

/* What the cavity search found (cavity_encroach). */
enum {
  CAVITY_NOMEM = -1,
  CAVITY_CLEAR = 0,     /* the whole cavity searched, no subsegment encroached */
  CAVITY_CAPPED = 1,    /* none encroached in the part searched, but the search stopped at
                         * its cap: the rest of the cavity's edges were not tested */
  CAVITY_ENCROACHED = 2 /* some encroached subsegments queued in g->enc */
};

/* The subsegments on the boundary of the insertion cavity of p (the triangles whose
 * circumcircles hold p, reached from t0 and t1 without crossing a constrained edge) that p
 * would encroach: queued (as triples) in g->enc. Returns a CAVITY_ value: CAVITY_CLEAR says
 * the new vertex's star will have no encroached edge (check_star). Every slot tested gets a stamp,
 * g->mark[t] = 2 g->mark_gen + (1 inside the circle, 0 not): membership without a scan, and the
 * insertion of p that follows reuses the results for its flips (qk__cdt_t's known) instead of
 * testing the same circles again. */
static int cavity_encroach(qk__gm_t *g, uint32_t t0, uint32_t t1, const double p[2]) {
  const qk__cdt_t *c = &g->cdt;
  size_t n = 0, seen = 0;
  int found = 0, capped = 0;
  /* Room for the whole search at once: it stops growing past 4096 triangles. */
  if (grow_stack(g, 4096 + 8) || grow_marks(g)) return CAVITY_NOMEM;
  /* The arrays in locals: nothing in the loop moves them (push_enc grows g->enc only), and
   * the compiler cannot tell that across push_enc's call. A stamp of this search is
   * 2 gen or 2 gen + 1, i.e. stamp | 1 == in. */
  const uint32_t *V = c->v, *N = c->nbr, *S = c->seg;
  const double *XY = c->xy;
  uint32_t *mark = g->mark, *stack = g->stack;
  const uint32_t in = 2 * ++g->mark_gen + 1;
  stack[n++] = t0, mark[t0] = in;
  if (t1 != QK__CDT_NONE) stack[n++] = t1, mark[t1] = in;
  /* stack[0..seen) are done, [seen, n) to do. */
  while (seen < n) {
    const size_t t = stack[seen++];
    for (int k = 0; k < 3; k++) {
      if (S[3 * t + k] != QK__CDT_NONE) {
        uint32_t a = V[3 * t + (k + 1) % 3], b = V[3 * t + (k + 2) % 3];
        if (qk__cdt_encroach_in(&XY[2 * (size_t)a], &XY[2 * (size_t)b], p) < 0) {
          if (push_enc(g, a, b, S[3 * t + k])) return CAVITY_NOMEM;
          found = 1;
        }
        continue;
      }
      uint32_t u = N[3 * t + k];
      if (u == QK__CDT_NONE || (mark[u] | 1) == in) continue;
      if (n > 4096) {
        capped = 1;
        continue;
      }
      const uint32_t *uv = &V[3 * (size_t)u];
      int r = qk__cdt_incircle(&XY[2 * (size_t)uv[0]], &XY[2 * (size_t)uv[1]],
                               &XY[2 * (size_t)uv[2]], p) > 0;
      mark[u] = in - 1 + (uint32_t)r; /* tested once */
      if (r) stack[n++] = u;
    }
  }
  return found ? CAVITY_ENCROACHED : capped ? CAVITY_CAPPED : CAVITY_CLEAR;
}

/* Does the new vertex v encroach a constrained edge of its star? v lies strictly inside a
 * kept face, so its spokes are not constrained: the edges to test are the constrained far
 * edges (edge 0, v in slot 0), which the insertion's flips listed in c->undo_seg; the
 * cavity search's exact test. */
static int star_encroached(const qk__gm_t *g, uint32_t v) {
  const qk__cdt_t *c = &g->cdt;
  const double *pv = &c->xy[2 * (size_t)v];
  for (size_t i = 0; i < c->nundo_seg; i++) {
    const uint32_t *tv = &c->v[3 * (size_t)c->undo_seg[i]];
    assert(tv[0] == v && c->seg[3 * (size_t)c->undo_seg[i]] != QK__CDT_NONE);
    if (qk__cdt_encroach_in(&c->xy[2 * (size_t)tv[1]], &c->xy[2 * (size_t)tv[2]], pv) < 0) return 1;
  }
  return 0;
}

/* Insert circumcentre p, strictly inside kept triangle t, before asking whether it encroaches a
 * subsegment: returns 0 when it does not (then it stays, its star not yet checked), 1 when it does
 * (then it has been taken back: the CDT, the vertex's record and the insertion count are as they
 * were, and the caller does what the cavity search says), -1 on NOMEM. Lawson's flips from t
 * replace exactly the insertion cavity (the triangles whose circumcircles hold p, reached without
 * crossing a constraint), so the star's far edges are the cavity's boundary: the edges the cavity
 * search would have tested, with the same exact test, and one of them is encroached exactly when
 * the search would have found one; the point is taken back for about 0.4% of the circumcentres (46
 * of 11,018 on Norway at extent/256, 144 of 63,367 on Iceland), where the search then runs as it
 * always did, so the mesh is the same. The search itself, a walk over the cavity and its neighbours
 * whose in-circle results the flips reused, is saved for the others: the flips make the same tests
 * themselves. */
static int insert_circumcentre(qk__gm_t *g, const double p[2], uint32_t t) {
  qk__cdt_t *c = &g->cdt;
  /* Room for the record: two words and four a flip, at most one flip a vertex; then the
   * list of constrained far edges, at most one a vertex. */
  size_t need = 5 * (c->nv + 4) + 2;
  if (need > g->undo_cap) {
    /* Sized for the CDT's room for vertices (the refinement reserved its estimate), and a
     * new block, not a grown one: a record lives for one insertion, so nothing is copied.
     * Grown by doubling with copies it was six growths and 0.9 M instructions of 73 M on
     * South Africa at extent/256. */
    size_t cap = 5 * (c->cap_v + 4) + 2;
    cap = cap < need ? need : cap;
    qk__free(g->a, g->undo, g->undo_cap * sizeof *g->undo);
    g->undo = qk__realloc(g->a, NULL, 0, cap * sizeof *g->undo);
    g->undo_cap = g->undo ? cap : 0;
    if (!g->undo) return -1;
  }
  uint32_t v;
  c->undo = g->undo, c->undo_seg = g->undo + 4 * (c->nv + 2) + 2;
  qk_status_t st = qk__gm_insert_in(g, p[0], p[1], t, &v);
  if (st) return c->undo = NULL, -1;
  assert(g->dirty_v == v && g->dirty_face == g->face[t]);
  if (!star_encroached(g, v)) return c->undo = NULL, 0;
  qk__cdt_undo_insert(c, t);
  c->undo = NULL;
  /* (g->vi[v] holds the values of a vertex never used, as before: no input vertex, no
   * segment, parameter 0. Without star_later the insertion listed its star and labelled it
   * with the face its old triangles had, the cavity's one face; the two new slots are past
   * the count now and get their face when they are made again.) */
  g->star_pending = 0, g->ndirty = 0, g->insertions--;
  return 1;
}

/* A constrained edge at vertex x (found by turning around it from triangle t): the
 * subsegment to split when a circumcentre's walk runs into x. */
static int constrained_at(const qk__gm_t *g, uint32_t t, uint32_t x, uint32_t *a, uint32_t *b,
                          uint32_t *s) {
  const qk__cdt_t *c = &g->cdt;
  uint32_t u = t;
  for (int guard = 0; guard < 1 << 16 && u != QK__CDT_NONE; guard++) {
    int i = c->v[3 * u] == x ? 0 : c->v[3 * u + 1] == x ? 1 : 2;
    for (int d = 1; d <= 2; d++) {
      int k = (i + d) % 3;
      if (c->seg[3 * u + k] != QK__CDT_NONE) {
        *a = c->v[3 * u + (k + 1) % 3], *b = c->v[3 * u + (k + 2) % 3], *s = c->seg[3 * u + k];
        return 1;
      }
    }
    u = c->nbr[3 * u + (i + 1) % 3];
    if (u == t) break;
  }
  return 0;
}

/* The corner of triangle tv opposite its longest edge (the first of the longest). */
static uint32_t far_corner(const qk__cdt_t *c, const uint32_t *tv) {
  double l[3];
  for (int i = 0; i < 3; i++) l[i] = d2(&c->xy[2 * tv[(i + 1) % 3]], &c->xy[2 * tv[(i + 2) % 3]]);
  return tv[l[0] >= l[1] && l[0] >= l[2] ? 0 : l[1] >= l[2] ? 1 : 2];
}

/* The queue's entry for triangle t as it is now. Taken only where a split replaces t's
 * circumcentre (t is queued again after it): built up front for every triangle, it cost
 * about three instructions a circumcentre (0.13% on South Africa at extent/256). */
static qk__gm_tq_t queued(const qk__cdt_t *c, uint32_t t) {
  const uint32_t *tv = &c->v[3 * (size_t)t];
  return (qk__gm_tq_t){t, tv[0], tv[1], tv[2]};
}

/* A bad triangle only a few ulps across, whose circumcentre does not exist in doubles or
 * rounds onto a vertex: no double near it could improve it (two vertices 1 ulp apart in x,
 * where y's ulp is eight times coarser, leave only points on its circumcircle). Refused,
 * saying so and how small it is (the message once said only "precision exhausted"). */
static qk_status_t exhausted(const qk__gm_t *g, const uint32_t *tv, const double *W,
                             const char *what) {
  const qk__cdt_t *c = &g->cdt;
  double e = INFINITY;
  for (int i = 0; i < 3; i++) e = fmin(e, sqrt(d2(&c->xy[2 * tv[i]], &c->xy[2 * tv[(i + 1) % 3]])));
  return qk__mesh_fail(g->err, QK_ERR_LIMIT, 0,
                       "%s the triangle at (%.17g, %.17g), %.3g across: no double near it "
                       "improves it (features a few ulps apart, such as vertices 1 ulp "
                       "apart); round the input to a grid (--round)",
                       what, W[0], W[1], e);
}

/* Split a bad triangle: its circumcentre, or the subsegments hiding or encroached by it.
 * *rejected counts the triangles left because only protected pieces stood in the way. */
static qk_status_t split_triangle(qk__gm_t *g, uint32_t t, const double lo[2], const double hi[2],
                                  size_t *rejected) {
  qk__cdt_t *c = &g->cdt;
  const uint32_t *tv = &c->v[3 * t];
  const double *A = &c->xy[2 * tv[0]], *B = &c->xy[2 * tv[1]], *C = &c->xy[2 * tv[2]];
  double bx = B[0] - A[0], by = B[1] - A[1], cx = C[0] - A[0], cy = C[1] - A[1];
  double D = 2 * (bx * cy - by * cx), b2 = bx * bx + by * by, c2 = cx * cx + cy * cy;
  double p[2] = {A[0] + (cy * b2 - by * c2) / D, A[1] + (bx * c2 - cx * b2) / D};
  /* A circumcentre beyond the input's bounding box grown by an eighth (lo, hi: refine()
   * computes them once) lies in the unbounded face: walk towards the box's edge instead,
   * which is as hidden. */
  if (!isfinite(p[0]) || !isfinite(p[1])) {
    const double *W = &c->xy[2 * far_corner(c, tv)];
    return exhausted(g, tv, W, "no circumcentre for");
  }
  const int clamped = p[0] > hi[0] || p[0] < lo[0] || p[1] > hi[1] || p[1] < lo[1];
  uint32_t tri;
  int k;
  qk__cdt_where_t where;
  /* A circumcentre strictly inside t itself (t acute), as the filters decide it: where the
   * walk would end at once (from w below, its first triangle t holds p strictly inside),
   * without the walk or w; any doubt walks. */
  int inside = !clamped;
  for (int i = 0; i < 3 && inside; i++) {
    const double *a = &c->xy[2 * tv[i]], *b = &c->xy[2 * tv[i == 2 ? 0 : i + 1]];
    double l = (b[0] - a[0]) * (p[1] - a[1]), r = (b[1] - a[1]) * (p[0] - a[0]);
    inside = l - r > (fabs(l) + fabs(r)) * 0x1p-50;
  }
  /* Else walk from the vertex opposite the longest edge (the circumcentre lies beyond it
   * when it lies outside the triangle). */
  const uint32_t w = inside ? tv[0] : far_corner(c, tv);
  const double *W = &c->xy[2 * w];
  if (clamped) {
    double lam = 1;
    for (int j = 0; j < 2; j++) {
      double dj = p[j] - W[j];
      if (p[j] > hi[j]) lam = fmin(lam, (hi[j] - W[j]) / dj);
      if (p[j] < lo[j]) lam = fmin(lam, (lo[j] - W[j]) / dj);
    }
    p[0] = W[0] + lam * (p[0] - W[0]), p[1] = W[1] + lam * (p[1] - W[1]);
  }
  if (inside) {
    tri = t, k = 0, where = QK__CDT_IN;
  } else if (!qk__cdt_walk_from(c, w, t, p[0], p[1], &tri, &k, &where)) {
    uint32_t a, b, s;
    if (where == QK__CDT_EDGE) {
      a = c->v[3 * tri + (k + 1) % 3], b = c->v[3 * tri + (k + 2) % 3], s = c->seg[3 * tri + k];
    } else if (!constrained_at(g, tri, c->v[3 * tri + k], &a, &b, &s)) {
      return qk__mesh_fail(g->err, QK_ERR_LIMIT, 0, "cannot split the triangle at (%.17g, %.17g)",
                           W[0], W[1]);
    }
    int done;
    const qk__gm_tq_t self = queued(c, t); /* t as it is now, to queue again after the split */
    qk_status_t st = split_piece(g, a, b, s, &done);
    if (!st) st = check_dirty(g);
    /* Behind a protected piece: the triangle is rejected (left as it is; the final check
     * refuses the mesh if it is still below the bound). */
    if (!st && done && push_bad(g, t)) st = QK_ERR_NOMEM;
    if (!st && done) BAD_AT(g, g->nbad - 1) = self;
    if (!done) ++*rejected;
    return st;
  }
  if (clamped || where == QK__CDT_VERT) return exhausted(g, tv, W, "precision exhausted refining");
  uint32_t v;
  int existed;
  if (where == QK__CDT_IN) {
    int enc = insert_circumcentre(g, p, tri);
    if (enc < 0) return qk__mesh_fail(g->err, QK_ERR_NOMEM, 0, "out of memory");
    if (!enc) return check_dirty_after(g, 1);
  }
  uint32_t t1 = where == QK__CDT_EDGE ? c->nbr[3 * tri + k] : QK__CDT_NONE;
  size_t before = g->nenc;
  const int f = cavity_encroach(g, tri, t1, p);
  if (f == CAVITY_NOMEM) return QK_ERR_NOMEM;
  if (f == CAVITY_ENCROACHED) {
    /* Split those instead (the queue's front part is still empty here: the refinement
     * handles encroached subsegments before triangles), then retry the triangle. */
    int any = 0;
    const qk__gm_tq_t self = queued(c, t); /* (an insertion taken back left t as it was) */
    while (g->nenc > before) {
      g->nenc--;
      uint32_t a = g->enc[3 * g->nenc], b = g->enc[3 * g->nenc + 1], s = g->enc[3 * g->nenc + 2];
      int done;
      qk_status_t st = split_piece(g, a, b, s, &done);
      if (!st) st = check_dirty(g);
      if (st) return st;
      any |= done;
    }
    /* Every encroached piece protected: the triangle is rejected (as above). */
    if (!any) return ++*rejected, QK_OK;
    if (push_bad(g, t)) return QK_ERR_NOMEM;
    BAD_AT(g, g->nbad - 1) = self;
    return QK_OK;
  }
  /* The cavity's tests stand for this one insertion (slots untested, beyond the search's
   * cap, are tested by the flips as usual). */
  c->known = g->mark, c->known_gen = g->mark_gen;
  qk_status_t st = qk__gm_insert(g, p[0], p[1], tri, k, where, QK__CDT_NONE, 0, &v, &existed);
  c->known = NULL;
  if (st) return qk__mesh_fail(g->err, st, 0, "out of memory");
  return check_dirty_after(g, f == CAVITY_CLEAR);
}

/* With a plain size bound h, the refined mesh holds about 5.1 triangles per h^2 of kept
 * area (5.05 to 5.2 on the coastlines at 1/128 and 1/256 of their extent), plus a layer
 * along the boundary that the area misses where the boundary is long against the area
 * (Norway at 1/256: 22,044 triangles made against 20,500 by area; Iceland at 1/64: 8,702
 * against 8,438): one more a segment piece covers it (6,517 and 1,412 there). Room for
 * that is reserved up front in the CDT's arrays and the cavity stamps, which saves the
 * copies of growing them by steps (the last growth alone copies two thirds of them; on
 * Norway at 1/256 the one growth cost 1.3 M instructions of 93 M). Beyond 2^27
 * triangles, steps. The seeding reserves it before it inserts its points, with room for
 * them (every point inserted adds two triangles): the arrays are still small then, so the
 * growth copies little (reserved after the seeds' insertion instead, on the random PSLG at
 * 1/256 the growths copied the seeded CDT's arrays: 0.7% of the instructions); the call
 * before the refinement then has nothing to do (the estimate counted the same points). */
static qk_status_t reserve(qk__gm_t *g, size_t more) {
  qk__cdt_t *c = &g->cdt;
  double h = g->opt->max_size, est = 0;
  if (!more && g->reserved) return QK_OK;
  if (h > 0 && !g->opt->size_fn) {
    est = 5.3 * qk__gm_area(g) / (h * h) + (double)(g->P->ns + g->npts);
    if (!(est < (double)((size_t)1 << 27))) est = 0;
  }
  if (!more && !est) return QK_OK;
  size_t nt = c->nt + 2 * more + (size_t)est;
  size_t nv = c->nv + more + (size_t)est / 2 + 4;
  if (qk__cdt_reserve(c, nv, nt) || grow_marks_to(g, nt) || qk__gm_fit_to(g, nv, nt, 1))
    return QK_ERR_NOMEM;
  g->reserved = est > 0;
  return QK_OK;
}

/* The seeding's call (the refinement's stays inlined: making it a call changed the
 * refinement loop's code, 0.04% more instructions on Iceland). */
qk_status_t qk__gm_reserve(qk__gm_t *g, size_t more) { return reserve(g, more); }

static qk_status_t refine(qk__gm_t *g) {
  qk__cdt_t *c = &g->cdt;
  g->ndirty = 0;
  g->size_plain = g->opt->max_size > 0 && !g->opt->size_fn;
  if (g->size_plain) {
    double h = g->opt->max_size, h2 = h * h;
    g->h_plain = h, g->h2_hi = h2 * (1 + 0x1p-48), g->h2_lo = h2 * (1 - 0x1p-48);
  }
  if (reserve(g, 0)) return qk__mesh_fail(g->err, QK_ERR_NOMEM, 0, "out of memory");
  /* Room in the bad-triangle ring for every triangle the first pass may queue, taken while
   * the ring is empty (nothing to unwrap; qk__grow keeps the power of two): it grew from
   * 16 by doubling with copies before, 0.27% of the instructions on Norway at 1/256. */
  if (g->nbad == g->bad_head && c->nt > g->bad_cap) {
    void *p = g->bad;
    if (qk__grow(g->a, &p, &g->bad_cap, c->nt, sizeof *g->bad))
      return qk__mesh_fail(g->err, QK_ERR_NOMEM, 0, "out of memory");
    g->bad = p;
    g->nbad = g->bad_head = 0;
  }
  for (uint32_t t = 0; t < c->nt; t++)
    if (check(g, t)) return qk__mesh_fail(g->err, QK_ERR_NOMEM, 0, "out of memory");
  qk_status_t st = QK_OK;
  size_t rejected = 0;
  const double ew = g->bx1 - g->bx0, eh = g->by1 - g->by0, m = (ew > eh ? ew : eh) / 8; /* finite */
  const double clip_lo[2] = {g->bx0 - m, g->by0 - m}, clip_hi[2] = {g->bx1 + m, g->by1 + m};
  for (;;) {
    if (!g->tree && g->insertions >= g->work_cap) {
      /* The input's size did not cap the work: the graded tree's leaves do (general_run.c),
       * or its grading refuses an input whose features stay close along a stretch. */
      const char *stage = g->stage;
      g->stage = "grading the quadtree";
      if ((st = qk__gm_grade(g))) return st;
      g->stage = stage;
      g->work_cap = qk__gm_work_cap(g);
    }
    if (g->insertions > g->work_cap) {
      double x = 0, y = 0;
      if (g->bad_head < g->nbad) {
        const double *q = &c->xy[2 * BAD_AT(g, g->bad_head).a];
        x = q[0], y = q[1];
      }
      return qk__mesh_fail(g->err, QK_ERR_LIMIT, 0,
                           "the refinement did not settle after %zu insertions (still working "
                           "near (%.17g, %.17g))%s",
                           g->insertions, x, y,
                           g->bound_deg > 20.7
                               ? "; a minimum angle above 20.7 degrees has no termination proof"
                               : "");
    }
    if (g->nenc) {
      g->nenc--;
      uint32_t a = g->enc[3 * g->nenc], b = g->enc[3 * g->nenc + 1], s = g->enc[3 * g->nenc + 2];
      if (!still_encroached(g, a, b)) continue;
      int done;
      if ((st = split_piece(g, a, b, s, &done)) || (st = check_dirty(g))) break;
      continue;
    }
    if (g->bad_head == g->nbad) break;
    /* A triangle was queued when found bad; the slot holding the same three vertices in
     * the same order is the same triangle (its face, and so its quality, unchanged), so it
     * is still bad and is not tested again. A changed slot is skipped: its new triangle was
     * checked (and queued if bad) when the CDT changed it. Most entries are stale (about
     * 70% with a size bound, which queues nearly every new triangle): they are skipped in
     * a loop of their own, as nothing else changes while they are popped. */
    const qk__gm_tq_t *ring = g->bad;
    const size_t mask = g->bad_cap - 1, end = g->nbad;
    size_t head = g->bad_head;
    qk__gm_tq_t q;
    int same;
    do {
      q = ring[head++ & mask];
      const uint32_t *tv = &c->v[3 * (size_t)q.t];
      same = tv[0] == q.a && tv[1] == q.b && tv[2] == q.c;
    } while (!same && head != end);
    g->bad_head = head;
    if (same && (st = split_triangle(g, q.t, clip_lo, clip_hi, &rejected))) break;
  }
  if (st == QK_ERR_NOMEM) return qk__mesh_fail(g->err, st, 0, "out of memory");
  if (st) return st;
  /* A triangle rejected at the floor and still bad: refuse rather than return a mesh that
   * breaks the bound (docs/mesh.md, "The refinement": the floor). */
  for (uint32_t t = 0; rejected && t < c->nt; t++) {
    if (!qk__gm_is_bad(g, t)) continue;
    const double *q = &c->xy[2 * c->v[3 * t]];
    return qk__mesh_fail(g->err, QK_ERR_LIMIT, 0,
                         "the triangle at (%.17g, %.17g) stays below the angle bound: improving "
                         "it would split a segment closer than 2^-50 of its length to the apex "
                         "of a small input angle (the floor)",
                         q[0], q[1]);
  }
  return QK_OK;
}

qk_status_t qk__gm_refine(qk__gm_t *g) {
  /* Stars whole (check_star) with a plain size bound or none, i.e. without a size
   * function; with one, triangle by triangle from the insertion's list. */
  g->star_later = !g->opt->size_fn;
  g->star_pending = 0;
  qk_status_t st = refine(g);
  g->star_later = g->star_pending = 0;
  return st;
}
