/*
 * Exact mesh checker (see mesh_check.h). Written apart from mesh/: it recomputes the
 * components from the segments and decides containment by exact ray crossing.
 */
#include "mesh_check.h"

#include <math.h>
#include <stdarg.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

__extension__ typedef __int128 i128;

static int fail(char *msg, size_t n, const char *fmt, ...) {
  va_list ap;
  va_start(ap, fmt);
  if (msg && n) vsnprintf(msg, n, fmt, ap);
  va_end(ap);
  return 1;
}

/* Doubled vertex coordinates, sorted for lookup. */
typedef struct pt {
  int64_t x, y;
  uint32_t i;
} pt_t;

static int pt_cmp(const void *a, const void *b) {
  const pt_t *p = a, *q = b;
  if (p->x != q->x) return p->x < q->x ? -1 : 1;
  if (p->y != q->y) return p->y < q->y ? -1 : 1;
  return 0;
}

static int u64_cmp(const void *a, const void *b) {
  uint64_t x = *(const uint64_t *)a, y = *(const uint64_t *)b;
  return (x > y) - (x < y);
}

static long find_pt(const pt_t *s, size_t n, int64_t x, int64_t y) {
  pt_t k = {x, y, 0};
  const pt_t *r = bsearch(&k, s, n, sizeof *s, pt_cmp);
  return r ? (long)r->i : -1;
}

static int has_edge(const uint64_t *e, size_t n, uint32_t a, uint32_t b) {
  uint64_t k = (uint64_t)a << 32 | b;
  return bsearch(&k, e, n, sizeof *e, u64_cmp) != NULL;
}

/* A component as the checker sees it: its cycle of vertices, its area and bounding box
 * (doubled coordinates). */
typedef struct cyc {
  int64_t *x, *y;
  size_t n;
  i128 area2; /* twice the area, doubled coordinates: 8 * real area */
  int64_t xmin, xmax, ymin, ymax;
  int parent; /* component id of the innermost enclosing one, 0 for none */
} cyc_t;

/* Is (px, py) (in coordinates scaled by `k` relative to the cycle's) strictly inside? The
 * point is never on the boundary where this is used. Crossing-number test, exact. */
static int inside(const cyc_t *c, int64_t px, int64_t py, int64_t k) {
  if (px < c->xmin * k || px > c->xmax * k || py < c->ymin * k || py > c->ymax * k) return 0;
  int in = 0;
  for (size_t i = 0, j = c->n - 1; i < c->n; j = i++) {
    int64_t xi = c->x[i] * k, yi = c->y[i] * k, xj = c->x[j] * k, yj = c->y[j] * k;
    if ((yi > py) != (yj > py)) {
      /* x of the crossing > px  <=>  (xj - xi)(py - yi) / (yj - yi) + xi > px */
      i128 lhs = (i128)(xj - xi) * (py - yi), rhs = (i128)(px - xi) * (yj - yi);
      if (yj - yi > 0 ? lhs > rhs : lhs < rhs) in = !in;
    }
  }
  return in;
}

/* Innermost component holding a point: the smallest of those containing it. */
static int innermost(const cyc_t *c, size_t nc, int64_t px, int64_t py, int64_t k) {
  int best = 0;
  for (size_t i = 0; i < nc; i++)
    if (inside(&c[i], px, py, k) && (!best || c[i].area2 < c[best - 1].area2)) best = (int)i + 1;
  return best;
}

/*
 * Regions for holes, found on a fine grid independent of the mesh: every unit cell is
 * cut by both diagonals into four quarters (S, E, N, W), and every segment is a union of
 * unit cell sides and unit cell diagonals, so the connected parts of the domain minus
 * the segments are unions of quarters. A flood over quarters finds them.
 */
typedef struct regions {
  uint64_t U;
  uint8_t *h, *v, *d0, *d1; /* blocked unit edges: horizontal, vertical, two diagonals */
  uint32_t *id;             /* region of each quarter */
} regions_t;

static size_t qidx(uint64_t U, int64_t x, int64_t y, int q) {
  return ((size_t)y * U + (size_t)x) * 4 + (size_t)q;
}

static int regions_build(regions_t *R, const mc_input_t *in) {
  uint64_t U = in->U;
  R->U = U;
  R->h = calloc((U + 1) * U, 1), R->v = calloc((U + 1) * U, 1);
  R->d0 = calloc(U * U, 1), R->d1 = calloc(U * U, 1);
  R->id = malloc(4 * U * U * sizeof *R->id);
  uint32_t *queue = malloc(4 * U * U * sizeof *queue);
  if (!R->h || !R->v || !R->d0 || !R->d1 || !R->id || !queue) {
    free(queue);
    return 1;
  }
  for (size_t s = 0; s < in->ns; s++) {
    int64_t x = (int64_t)in->xy[2 * in->seg[2 * s]], y = (int64_t)in->xy[2 * in->seg[2 * s] + 1];
    int64_t qx = (int64_t)in->xy[2 * in->seg[2 * s + 1]],
            qy = (int64_t)in->xy[2 * in->seg[2 * s + 1] + 1];
    int64_t sx = (qx > x) - (qx < x), sy = (qy > y) - (qy < y);
    while (x != qx || y != qy) {
      int64_t nx = x + sx, ny = y + sy, lx = x < nx ? x : nx, ly = y < ny ? y : ny;
      if (sy == 0)
        R->h[(size_t)y * U + (size_t)lx] = 1;
      else if (sx == 0)
        R->v[(size_t)x * U + (size_t)ly] = 1;
      else if (sx == sy)
        R->d0[(size_t)ly * U + (size_t)lx] = 1;
      else
        R->d1[(size_t)ly * U + (size_t)lx] = 1;
      x = nx, y = ny;
    }
  }
  memset(R->id, 0xff, 4 * U * U * sizeof *R->id);
  uint32_t next = 0;
  for (size_t start = 0; start < 4 * U * U; start++) {
    if (R->id[start] != UINT32_MAX) continue;
    size_t qh = 0, qt = 0;
    R->id[start] = next, queue[qt++] = (uint32_t)start;
    while (qh < qt) {
      size_t c = queue[qh++];
      int q = (int)(c % 4);
      int64_t x = (int64_t)((c / 4) % U), y = (int64_t)((c / 4) / U);
      size_t nb[3];
      int n = 0;
      /* Inside the cell: S-E and N-W meet on diagonal d1, S-W and N-E on d0. */
      int d0 = R->d0[(size_t)y * U + (size_t)x], d1 = R->d1[(size_t)y * U + (size_t)x];
      static const int cw[4] = {1, 2, 3, 0}, ccw[4] = {3, 0, 1, 2};
      /* q and q+1 (S-E, E-N, N-W, W-S) are separated by d1, d0, d1, d0 respectively. */
      if (!((q % 2 == 0) ? d1 : d0)) nb[n++] = qidx(U, x, y, cw[q]);
      if (!((q % 2 == 0) ? d0 : d1)) nb[n++] = qidx(U, x, y, ccw[q]);
      /* Across the cell's side. */
      if (q == 0 && y > 0 && !R->h[(size_t)y * U + (size_t)x]) nb[n++] = qidx(U, x, y - 1, 2);
      if (q == 2 && y + 1 < (int64_t)U && !R->h[(size_t)(y + 1) * U + (size_t)x])
        nb[n++] = qidx(U, x, y + 1, 0);
      if (q == 1 && x + 1 < (int64_t)U && !R->v[(size_t)(x + 1) * U + (size_t)y])
        nb[n++] = qidx(U, x + 1, y, 3);
      if (q == 3 && x > 0 && !R->v[(size_t)x * U + (size_t)y]) nb[n++] = qidx(U, x - 1, y, 1);
      for (int i = 0; i < n; i++)
        if (R->id[nb[i]] == UINT32_MAX) R->id[nb[i]] = next, queue[qt++] = (uint32_t)nb[i];
    }
    next++;
  }
  free(queue);
  return 0;
}

static void regions_free(regions_t *R) {
  free(R->h), free(R->v), free(R->d0), free(R->d1), free(R->id);
}

/* The region of a point given in coordinates scaled by k (k even or 6 here). */
static uint32_t region_of(const regions_t *R, int64_t px, int64_t py, int64_t k) {
  int64_t U = (int64_t)R->U;
  int64_t x = px / k, y = py / k;
  if (x >= U) x = U - 1;
  if (y >= U) y = U - 1;
  int64_t fx = px - x * k, fy = py - y * k; /* in [0, k] */
  int q;
  if (fy <= fx && fy <= k - fx)
    q = 0; /* S */
  else if (fy >= fx && fy >= k - fx)
    q = 2; /* N */
  else if (fx > fy)
    q = 1; /* E */
  else
    q = 3; /* W */
  return R->id[qidx(R->U, x, y, q)];
}

/* The sign of fx + fy - 1 for doubles fx, fy in [0, 1], exactly: the rounded sum decides
 * unless it is 1 (rounding is monotone and 1 is a double), then the sum's rounding error
 * (Knuth's two-sum). */
static int sum_vs_one(double fx, double fy) {
  double s = fx + fy;
  if (s != 1) return s < 1 ? -1 : 1;
  double bv = s - fx, av = s - bv, err = (fx - av) + (fy - bv);
  return (err > 0) - (err < 0);
}

/* The region of a point at any double coordinates in the domain (a hole point), exactly:
 * its unit square, and its quarter there from its offsets in the square (exact: the
 * floor's difference). */
static uint32_t region_of_point(const regions_t *R, double px, double py) {
  const double top = (double)R->U - 1;
  double x = floor(px), y = floor(py);
  if (x > top) x = top;
  if (y > top) y = top;
  const double fx = px - x, fy = py - y;
  const int c = sum_vs_one(fx, fy);
  int q;
  if (fy <= fx && c <= 0)
    q = 0; /* S */
  else if (fy >= fx && c >= 0)
    q = 2; /* N */
  else if (fx > fy)
    q = 1; /* E */
  else
    q = 3; /* W */
  return R->id[qidx(R->U, (int64_t)x, (int64_t)y, q)];
}

int mc_check(const mc_input_t *in, const mc_mesh_t *m, char *msg, size_t msz) {
  int bad = 0;
  int64_t U2 = 2 * (int64_t)in->U;
  pt_t *pts = calloc(m->nv + 1, sizeof *pts);
  uint64_t *edges = calloc(3 * m->nt + 1, sizeof *edges);
  cyc_t *cyc = calloc(in->ns + 1, sizeof *cyc);
  int *comp_of_seg = calloc(in->ns + 1, sizeof *comp_of_seg);
  regions_t R;
  memset(&R, 0, sizeof R);
  int have_regions = 0;
  uint8_t *hole_region = NULL;
  size_t nc = 0;
  if (!pts || !edges || !cyc || !comp_of_seg) {
    bad = fail(msg, msz, "checker out of memory");
    goto out;
  }

  /* Vertices: half-integers in the domain, pairwise distinct. */
  for (size_t i = 0; i < m->nv; i++) {
    double x = 2 * m->xy[2 * i], y = 2 * m->xy[2 * i + 1];
    if (x != floor(x) || y != floor(y) || x < 0 || y < 0 || x > (double)U2 || y > (double)U2) {
      bad = fail(msg, msz, "vertex %zu (%g, %g) is not a half-integer point of the domain", i,
                 m->xy[2 * i], m->xy[2 * i + 1]);
      goto out;
    }
    pts[i] = (pt_t){(int64_t)x, (int64_t)y, (uint32_t)i};
  }
  qsort(pts, m->nv, sizeof *pts, pt_cmp);
  for (size_t i = 1; i < m->nv; i++)
    if (!pt_cmp(&pts[i], &pts[i - 1])) {
      bad = fail(msg, msz, "vertices %u and %u coincide", pts[i - 1].i, pts[i].i);
      goto out;
    }

  /* Components, recomputed from the segments: follow each cycle. */
  {
    uint32_t *inc = malloc((2 * in->nv + 1) * sizeof *inc);
    uint8_t *deg = calloc(in->nv + 1, 1);
    if (!inc || !deg) {
      free(inc), free(deg);
      bad = fail(msg, msz, "checker out of memory");
      goto out;
    }
    for (size_t s = 0; s < in->ns; s++)
      for (int k = 0; k < 2; k++) {
        uint32_t v = in->seg[2 * s + k];
        if (deg[v] < 2) inc[2 * v + deg[v]] = (uint32_t)s;
        deg[v]++;
      }
    for (size_t s0 = 0; s0 < in->ns && !bad; s0++) {
      if (comp_of_seg[s0]) continue;
      cyc_t *c = &cyc[nc++];
      c->x = malloc((in->ns + 1) * sizeof *c->x);
      c->y = malloc((in->ns + 1) * sizeof *c->y);
      if (!c->x || !c->y) {
        bad = fail(msg, msz, "checker out of memory");
        break;
      }
      uint32_t s = (uint32_t)s0, v = in->seg[2 * s0];
      c->xmin = c->ymin = INT64_MAX, c->xmax = c->ymax = INT64_MIN;
      do {
        comp_of_seg[s] = (int)nc;
        int64_t x = 2 * (int64_t)in->xy[2 * v], y = 2 * (int64_t)in->xy[2 * v + 1];
        c->x[c->n] = x, c->y[c->n] = y, c->n++;
        if (x < c->xmin) c->xmin = x;
        if (x > c->xmax) c->xmax = x;
        if (y < c->ymin) c->ymin = y;
        if (y > c->ymax) c->ymax = y;
        uint32_t w = in->seg[2 * s] == v ? in->seg[2 * s + 1] : in->seg[2 * s];
        s = inc[2 * w] == s ? inc[2 * w + 1] : inc[2 * w];
        v = w;
      } while (s != s0);
      i128 a = 0;
      for (size_t i = 0, j = c->n - 1; i < c->n; j = i++)
        a += (i128)c->x[j] * c->y[i] - (i128)c->x[i] * c->y[j];
      c->area2 = a < 0 ? -a : a;
    }
    free(inc);
    free(deg);
    if (bad) goto out;
  }
  for (size_t i = 0; i < nc; i++) {
    /* The parent: the smallest other component containing this one's first vertex. */
    int best = 0;
    for (size_t j = 0; j < nc; j++)
      if (j != i && inside(&cyc[j], cyc[i].x[0], cyc[i].y[0], 1) &&
          (!best || cyc[j].area2 < cyc[best - 1].area2))
        best = (int)j + 1;
    cyc[i].parent = best;
  }
  /* Holes remove whole regions (connected parts between boundaries). */
  i128 expect = (i128)U2 * U2 * 2;
  if (in->nh) {
    if (in->U > 4096) {
      bad = fail(msg, msz, "checker: holes on a domain larger than 4096 are not supported");
      goto out;
    }
    have_regions = 1; /* freed at the end even when building fails half-way */
    if (regions_build(&R, in)) {
      bad = fail(msg, msz, "checker out of memory");
      goto out;
    }
    hole_region = calloc(4 * in->U * in->U + 1, 1);
    if (!hole_region) {
      bad = fail(msg, msz, "checker out of memory");
      goto out;
    }
    for (size_t h = 0; h < in->nh; h++) {
      double hx = in->holes[2 * h], hy = in->holes[2 * h + 1];
      if (!(hx >= 0 && hx <= (double)in->U && hy >= 0 && hy <= (double)in->U)) {
        bad = fail(msg, msz, "checker: hole %zu (%g, %g) is outside the domain", h, hx, hy);
        goto out;
      }
      hole_region[region_of_point(&R, hx, hy)] = 1;
    }
    /* Each quarter has area 1/4: 2 in units of 8 * area. */
    for (size_t q = 0; q < 4 * in->U * in->U; q++)
      if (hole_region[R.id[q]]) expect -= 2;
  }

  /* Triangles: orientation, angles, labels; collect directed edges. */
  i128 area = 0;
  for (size_t t = 0; t < m->nt; t++) {
    const uint32_t *tr = &m->tri[3 * t];
    int64_t X[3], Y[3];
    for (int i = 0; i < 3; i++) {
      if (tr[i] >= m->nv) {
        bad = fail(msg, msz, "triangle %zu: vertex index %u out of range", t, tr[i]);
        goto out;
      }
      X[i] = (int64_t)(2 * m->xy[2 * tr[i]]);
      Y[i] = (int64_t)(2 * m->xy[2 * tr[i] + 1]);
      edges[3 * t + i] = (uint64_t)tr[i] << 32 | tr[(i + 1) % 3];
    }
    i128 cr = (i128)(X[1] - X[0]) * (Y[2] - Y[0]) - (i128)(Y[1] - Y[0]) * (X[2] - X[0]);
    if (cr <= 0) {
      bad = fail(msg, msz, "triangle %zu is not counter-clockwise (or is degenerate)", t);
      goto out;
    }
    area += cr;
    for (int i = 0; i < 3; i++) {
      int j = (i + 1) % 3, k = (i + 2) % 3;
      i128 ux = X[j] - X[i], uy = Y[j] - Y[i], vx = X[k] - X[i], vy = Y[k] - Y[i];
      i128 dot = ux * vx + uy * vy, uu = ux * ux + uy * uy, vv = vx * vx + vy * vy;
      /* angle <= 90 iff dot >= 0; angle >= 45 iff cos <= 1/sqrt 2 iff 2 dot^2 <= uu vv. */
      if (dot < 0 || 2 * dot * dot > uu * vv) {
        bad = fail(msg, msz, "triangle %zu: angle at vertex %u outside [45, 90] degrees", t, tr[i]);
        goto out;
      }
    }
    /* The centroid in coordinates scaled by 3 relative to doubled ones. */
    int64_t cx = X[0] + X[1] + X[2], cy = Y[0] + Y[1] + Y[2];
    int want = innermost(cyc, nc, cx, cy, 3);
    if (have_regions && hole_region[region_of(&R, cx, cy, 6)]) {
      bad = fail(msg, msz, "triangle %zu lies in a hole region", t);
      goto out;
    }
    if ((int)m->comp[t] != want) {
      bad = fail(msg, msz, "triangle %zu has component %u, expected %d", t, m->comp[t], want);
      goto out;
    }
  }
  if (area != expect) {
    bad = fail(msg, msz, "triangle areas sum to %.17g, expected %.17g (x8)", (double)area,
               (double)expect);
    goto out;
  }

  /* Edges: each directed edge once; its reverse present, or it lies on the domain's
   * boundary, or (with holes) on an input segment. */
  qsort(edges, 3 * m->nt, sizeof *edges, u64_cmp);
  for (size_t i = 1; i < 3 * m->nt; i++)
    if (edges[i] == edges[i - 1]) {
      bad = fail(msg, msz, "edge %u-%u is used twice in the same direction",
                 (unsigned)(edges[i] >> 32), (unsigned)edges[i]);
      goto out;
    }
  for (size_t i = 0; i < 3 * m->nt; i++) {
    uint32_t a = (uint32_t)(edges[i] >> 32), b = (uint32_t)edges[i];
    if (has_edge(edges, 3 * m->nt, b, a)) continue;
    int64_t ax = (int64_t)(2 * m->xy[2 * a]), ay = (int64_t)(2 * m->xy[2 * a + 1]);
    int64_t bx = (int64_t)(2 * m->xy[2 * b]), by = (int64_t)(2 * m->xy[2 * b + 1]);
    int on_domain = (ax == bx && (ax == 0 || ax == U2)) || (ay == by && (ay == 0 || ay == U2));
    int on_seg = 0;
    if (!on_domain && in->nh)
      for (size_t s = 0; s < in->ns && !on_seg; s++) {
        int64_t px = 2 * (int64_t)in->xy[2 * in->seg[2 * s]],
                py = 2 * (int64_t)in->xy[2 * in->seg[2 * s] + 1];
        int64_t qx = 2 * (int64_t)in->xy[2 * in->seg[2 * s + 1]],
                qy = 2 * (int64_t)in->xy[2 * in->seg[2 * s + 1] + 1];
        int64_t dx = qx - px, dy = qy - py;
        if ((ax - px) * dy != (ay - py) * dx || (bx - px) * dy != (by - py) * dx) continue;
        int64_t lo = 0, hi = dx * dx + dy * dy;
        int64_t ta = (ax - px) * dx + (ay - py) * dy, tb = (bx - px) * dx + (by - py) * dy;
        on_seg = ta >= lo && ta <= hi && tb >= lo && tb <= hi;
      }
    if (!on_domain && !on_seg) {
      bad = fail(msg, msz, "edge (%g,%g)-(%g,%g) has one triangle but is not on the boundary",
                 ax / 2.0, ay / 2.0, bx / 2.0, by / 2.0);
      goto out;
    }
  }

  /* Input respected: along each segment, the mesh vertices on it are joined by edges. */
  for (size_t s = 0; s < in->ns; s++) {
    int c = comp_of_seg[s];
    int64_t px = 2 * (int64_t)in->xy[2 * in->seg[2 * s]],
            py = 2 * (int64_t)in->xy[2 * in->seg[2 * s] + 1];
    int64_t qx = 2 * (int64_t)in->xy[2 * in->seg[2 * s + 1]],
            qy = 2 * (int64_t)in->xy[2 * in->seg[2 * s + 1] + 1];
    /* No triangle on either side: the regions beside the segment's first unit step are
     * holes (or outside the domain). */
    if (have_regions) {
      int64_t x = px / 2, y = py / 2, ux = (qx > px) - (qx < px), uy = (qy > py) - (qy < py);
      int64_t lx = ux < 0 ? x - 1 : x, ly = uy < 0 ? y - 1 : y, Ui = (int64_t)in->U;
      int all_holes = 1;
      if (uy == 0) { /* horizontal: the cells above (S quarter) and below (N quarter) */
        if (y < Ui && !hole_region[R.id[qidx(in->U, lx, y, 0)]]) all_holes = 0;
        if (y > 0 && !hole_region[R.id[qidx(in->U, lx, y - 1, 2)]]) all_holes = 0;
      } else if (ux == 0) { /* vertical: right (W quarter) and left (E quarter) */
        if (x < Ui && !hole_region[R.id[qidx(in->U, x, ly, 3)]]) all_holes = 0;
        if (x > 0 && !hole_region[R.id[qidx(in->U, x - 1, ly, 1)]]) all_holes = 0;
      } else if (!hole_region[R.id[qidx(in->U, lx, ly, 0)]] ||
                 !hole_region[R.id[qidx(in->U, lx, ly, 2)]]) {
        all_holes = 0; /* a diagonal: its S and N quarters lie on its two sides */
      }
      if (all_holes) continue;
    }
    (void)c;
    int64_t sx = (qx > px) - (qx < px), sy = (qy > py) - (qy < py);
    int64_t len = llabs(qx - px) > llabs(qy - py) ? llabs(qx - px) : llabs(qy - py);
    long prev = find_pt(pts, m->nv, px, py);
    if (prev < 0) {
      bad = fail(msg, msz, "segment %zu: its endpoint is not a mesh vertex", s);
      goto out;
    }
    for (int64_t k = 1; k <= len; k++) {
      long v = find_pt(pts, m->nv, px + k * sx, py + k * sy);
      if (v < 0) {
        if (k == len) {
          bad = fail(msg, msz, "segment %zu: its endpoint is not a mesh vertex", s);
          goto out;
        }
        continue;
      }
      if (!has_edge(edges, 3 * m->nt, (uint32_t)prev, (uint32_t)v) &&
          !has_edge(edges, 3 * m->nt, (uint32_t)v, (uint32_t)prev)) {
        bad = fail(msg, msz, "segment %zu is not a union of mesh edges (near (%g, %g))", s,
                   (px + k * sx) / 2.0, (py + k * sy) / 2.0);
        goto out;
      }
      prev = v;
    }
  }

out:
  for (size_t i = 0; i < nc; i++) free(cyc[i].x), free(cyc[i].y);
  free(cyc);
  free(pts);
  free(edges);
  free(comp_of_seg);
  free(hole_region);
  if (have_regions) regions_free(&R);
  return bad;
}
