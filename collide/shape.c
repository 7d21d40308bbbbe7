/*
 * The world's shapes: validation, bounding boxes rounded outwards, the exact closed
 * overlap test for every pair of kinds, and the distance and ray parameter used to order
 * query answers. Overlap is decided by exact signs (collide/exact.c), so touching counts
 * and no pair is gained or lost to rounding; distances and ray parameters are computed in
 * long double and only order the answers.
 */
#include <math.h>

#include "collide/collide_internal.h"

qk_status_t qk__shape_normalize(const qk_shape_t *in, qk_shape_t *out) {
  qk_shape_t s = *in;
  if (!isfinite(s.x) || !isfinite(s.y)) return QK_ERR_NONFINITE;
  switch (s.kind) {
  case QK_SHAPE_POINT:
    s.a = s.b = 0;
    break;
  case QK_SHAPE_DISC:
    if (!isfinite(s.a)) return QK_ERR_NONFINITE;
    if (s.a < 0) return QK_ERR_GEOMETRY;
    s.b = 0;
    break;
  case QK_SHAPE_BOX:
    if (!isfinite(s.a) || !isfinite(s.b)) return QK_ERR_NONFINITE;
    if (s.a < s.x) {
      double t = s.a;
      s.a = s.x;
      s.x = t;
    }
    if (s.b < s.y) {
      double t = s.b;
      s.b = s.y;
      s.y = t;
    }
    break;
  case QK_SHAPE_SEGMENT:
    if (!isfinite(s.a) || !isfinite(s.b)) return QK_ERR_NONFINITE;
    break;
  default:
    return QK_ERR_INVALID;
  }
  if (!qk__value_ok(s.x) || !qk__value_ok(s.y) || !qk__value_ok(s.a) || !qk__value_ok(s.b))
    return QK_ERR_LIMIT;
  *out = s;
  return QK_OK;
}

/* v - r rounded down (dir < 0) or v + r rounded up (dir > 0), exactly. */
static double offset_out(double v, double r, int dir) {
  double d = dir < 0 ? -r : r;
  double s = v + d, bv = s - v, err = (v - (s - bv)) + (d - bv);
  if (dir < 0 && err < 0) return nextafter(s, -INFINITY);
  if (dir > 0 && err > 0) return nextafter(s, INFINITY);
  return s;
}

qk_box_t qk__shape_box(const qk_shape_t *s) {
  switch (s->kind) {
  case QK_SHAPE_DISC:
    return (qk_box_t){offset_out(s->x, s->a, -1), offset_out(s->y, s->a, -1),
                      offset_out(s->x, s->a, 1), offset_out(s->y, s->a, 1)};
  case QK_SHAPE_BOX:
    return (qk_box_t){s->x, s->y, s->a, s->b};
  case QK_SHAPE_SEGMENT:
    return (qk_box_t){qk__min(s->x, s->a), qk__min(s->y, s->b), qk__max(s->x, s->a),
                      qk__max(s->y, s->b)};
  default:
    return (qk_box_t){s->x, s->y, s->x, s->y};
  }
}

/* ---- exact overlap -------------------------------------------------------------- */

static inline int in_box(double x, double y, double x0, double y0, double x1, double y1) {
  return x >= x0 && x <= x1 && y >= y0 && y <= y1;
}

/* A point on a closed segment. */
static int point_seg(double x, double y, const qk_shape_t *g) {
  if (!in_box(x, y, qk__min(g->x, g->a), qk__min(g->y, g->b), qk__max(g->x, g->a),
              qk__max(g->y, g->b)))
    return 0;
  return qk__orient(g->x, g->y, g->a, g->b, x, y) == 0;
}

/* A disc (centre cx, cy, radius r) and a closed segment: the nearest segment point is an
 * endpoint when the centre projects outside, else the foot of the perpendicular. */
static int disc_seg(double cx, double cy, double r, const qk_shape_t *g) {
  if (qk__dot_sign(g->x, g->y, g->a, g->b, cx, cy) <= 0)
    return qk__within(cx, cy, g->x, g->y, r, 0) >= 0;
  if (qk__dot_sign(g->a, g->b, g->x, g->y, cx, cy) <= 0)
    return qk__within(cx, cy, g->a, g->b, r, 0) >= 0;
  return qk__line_within(g->x, g->y, g->a, g->b, cx, cy, r) >= 0;
}

/* A box and a segment (separating axes: the box's two and the segment's normal). */
static int box_seg(const qk_shape_t *b, const qk_shape_t *g) {
  qk_box_t gb = qk__shape_box(g);
  if (gb.xmin > b->a || b->x > gb.xmax || gb.ymin > b->b || b->y > gb.ymax) return 0;
  /* With the boxes meeting, the segment misses the box exactly when the four corners lie
   * strictly on one side of its line: a corner on it, or two on either side, decide. */
  const double cx[4] = {b->x, b->a, b->a, b->x}, cy[4] = {b->y, b->y, b->b, b->b};
  int first = 0;
  for (int i = 0; i < 4; i++) {
    int o = qk__orient_fast(g->x, g->y, g->a, g->b, cx[i], cy[i]);
    if (o == 0 || (i > 0 && o != first)) return 1;
    first = o;
  }
  return 0;
}

static int seg_seg(const qk_shape_t *g, const qk_shape_t *h) {
  qk_box_t gb = qk__shape_box(g), hb = qk__shape_box(h);
  if (gb.xmin > hb.xmax || hb.xmin > gb.xmax || gb.ymin > hb.ymax || hb.ymin > gb.ymax) return 0;
  int o1 = qk__orient_fast(g->x, g->y, g->a, g->b, h->x, h->y);
  int o2 = qk__orient_fast(g->x, g->y, g->a, g->b, h->a, h->b);
  int o3 = qk__orient_fast(h->x, h->y, h->a, h->b, g->x, g->y);
  int o4 = qk__orient_fast(h->x, h->y, h->a, h->b, g->a, g->b);
  if (o1 * o2 < 0 && o3 * o4 < 0) return 1;
  if (o1 == 0 && in_box(h->x, h->y, gb.xmin, gb.ymin, gb.xmax, gb.ymax)) return 1;
  if (o2 == 0 && in_box(h->a, h->b, gb.xmin, gb.ymin, gb.xmax, gb.ymax)) return 1;
  if (o3 == 0 && in_box(g->x, g->y, hb.xmin, hb.ymin, hb.xmax, hb.ymax)) return 1;
  if (o4 == 0 && in_box(g->a, g->b, hb.xmin, hb.ymin, hb.xmax, hb.ymax)) return 1;
  return 0;
}

/* The box point nearest (x, y) is (x, y) clamped, exactly. */
static int disc_box(double cx, double cy, double r, const qk_shape_t *b) {
  double px = qk__min(qk__max(cx, b->x), b->a), py = qk__min(qk__max(cy, b->y), b->b);
  return qk__within(cx, cy, px, py, r, 0) >= 0;
}

/* Shapes ordered so that a's kind <= b's: point < disc < box < segment. */
static int rank(qk_shape_kind_t k) {
  switch (k) {
  case QK_SHAPE_POINT:
    return 0;
  case QK_SHAPE_DISC:
    return 1;
  case QK_SHAPE_BOX:
    return 2;
  default:
    return 3;
  }
}

int qk__shapes_overlap(const qk_shape_t *a, const qk_shape_t *b) {
  if (rank(a->kind) > rank(b->kind)) {
    const qk_shape_t *t = a;
    a = b;
    b = t;
  }
  switch (a->kind) {
  case QK_SHAPE_POINT:
    switch (b->kind) {
    case QK_SHAPE_POINT:
      return a->x == b->x && a->y == b->y;
    case QK_SHAPE_DISC:
      return qk__within(a->x, a->y, b->x, b->y, b->a, 0) >= 0;
    case QK_SHAPE_BOX:
      return in_box(a->x, a->y, b->x, b->y, b->a, b->b);
    default:
      return point_seg(a->x, a->y, b);
    }
  case QK_SHAPE_DISC:
    switch (b->kind) {
    case QK_SHAPE_DISC:
      return qk__within(a->x, a->y, b->x, b->y, a->a, b->a) >= 0;
    case QK_SHAPE_BOX:
      return disc_box(a->x, a->y, a->a, b);
    default:
      return disc_seg(a->x, a->y, a->a, b);
    }
  case QK_SHAPE_BOX:
    if (b->kind == QK_SHAPE_BOX)
      return a->x <= b->a && b->x <= a->a && a->y <= b->b && b->y <= a->b;
    return box_seg(a, b);
  default:
    return seg_seg(a, b);
  }
}

/* ---- distances and ray parameters (ordering only) ------------------------------- */

double qk__shape_dist(const qk_shape_t *s, qk_point_t p) {
  long double dx, dy;
  switch (s->kind) {
  case QK_SHAPE_DISC: {
    if (qk__within(p.x, p.y, s->x, s->y, s->a, 0) >= 0) return 0; /* inside, exactly */
    /* |f| - r as (|f|^2 - r^2) / (|f| + r), the numerator summed exactly where it cancels:
     * sqrt(|f|^2) - r lost everything near a large disc's edge (a point 7407 from a disc
     * of radius 5.8e24 came out 0). */
    dx = (long double)p.x - s->x;
    dy = (long double)p.y - s->y;
    long double d =
        -qk__within_value(p.x, p.y, s->x, s->y, s->a, 0) / (sqrtl(dx * dx + dy * dy) + s->a);
    return d > 0 ? (double)d : 0x1p-1074;
  }
  case QK_SHAPE_BOX:
    dx = p.x < s->x ? (long double)s->x - p.x : (p.x > s->a ? (long double)p.x - s->a : 0);
    dy = p.y < s->y ? (long double)s->y - p.y : (p.y > s->b ? (long double)p.y - s->b : 0);
    break;
  case QK_SHAPE_SEGMENT: {
    if (point_seg(p.x, p.y, s)) return 0;
    /* The nearest point: an end when p lies beyond it along the segment (exact signs),
     * else the foot of the perpendicular, at |(b - a) x (p - a)| / |b - a| with the cross
     * product summed exactly where it cancels (from the projection, a distance of 2.47 at
     * coordinates near 1e24 came out 0). */
    const double *e = NULL;
    if (qk__dot_sign(s->x, s->y, s->a, s->b, p.x, p.y) <= 0)
      e = &s->x;
    else if (qk__dot_sign(s->a, s->b, s->x, s->y, p.x, p.y) <= 0)
      e = &s->a;
    if (e) {
      dx = (long double)p.x - e[0];
      dy = (long double)p.y - e[1];
      break;
    }
    long double ux = (long double)s->a - s->x, uy = (long double)s->b - s->y;
    long double d =
        fabsl(qk__orient_value(s->x, s->y, s->a, s->b, p.x, p.y)) / sqrtl(ux * ux + uy * uy);
    return d > 0 ? (double)d : 0x1p-1074;
  }
  default:
    dx = (long double)p.x - s->x;
    dy = (long double)p.y - s->y;
  }
  return (double)sqrtl(dx * dx + dy * dy);
}

double qk__ray_param(const qk_shape_t *s, qk_point_t o, qk_point_t to) {
  qk_shape_t po = {QK_SHAPE_POINT, o.x, o.y, 0, 0};
  if (qk__shapes_overlap(&po, s)) return 0;
  long double vx = (long double)to.x - o.x, vy = (long double)to.y - o.y;
  long double vv = vx * vx + vy * vy, t = 0;
  if (vv == 0) return 0;
  switch (s->kind) {
  case QK_SHAPE_DISC: {
    /* The first root of vv t^2 + 2 b t + c = 0 (f = o - centre, b = f.v, c = |f|^2 - r^2
     * > 0: o is outside), as c / (-b + sqrt(D)) with D = b^2 - vv c = vv r^2 - (v x f)^2
     * (Lagrange's identity), b, c and D summed exactly where they cancel. For a ray grazing
     * a disc D as b^2 - vv c lost 1e-10 of t (a tangent disc came before a point that was
     * first), b rounded (f nearly across v) put a grazing disc after one behind it, and
     * -b - sqrt(D) cancels where c / (-b + sqrt(D)) does not. */
    long double b = -qk__dot_value(o.x, o.y, s->x, s->y, to.x, to.y); /* f.v */
    long double c = -qk__within_value(o.x, o.y, s->x, s->y, s->a, 0);
    long double disc = qk__line_within_value(o.x, o.y, to.x, to.y, s->x, s->y, s->a);
    long double root = sqrtl(disc > 0 ? disc : 0);
    t = b < 0 ? c / (root - b) : (-b - root) / vv;
    break;
  }
  case QK_SHAPE_BOX: {
    long double lo = 0, hi = 1;
    long double mn[2] = {s->x, s->y}, mx[2] = {s->a, s->b}, org[2] = {o.x, o.y}, v[2] = {vx, vy};
    for (int k = 0; k < 2; k++) {
      if (v[k] == 0) continue;
      long double t1 = (mn[k] - org[k]) / v[k], t2 = (mx[k] - org[k]) / v[k];
      if (t1 > t2) {
        long double w = t1;
        t1 = t2;
        t2 = w;
      }
      if (t1 > lo) lo = t1;
      if (t2 < hi) hi = t2;
    }
    t = lo;
    break;
  }
  case QK_SHAPE_SEGMENT: {
    /* With A and B the sides of the segment's ends p, q from the ray's line
     * ((to - o) x (p - o) and (to - o) x (q - o)), the line meets it at
     * t = ((p - o) x (q - o)) / (B - A); A and B differ in sign or one is 0 (the segment
     * meets the ray), so B - A does not cancel. Collinear exactly when both are 0: then
     * the nearer end. (Rounded long double differences took a segment lying on the ray's
     * line for a crossing, at t = 0.) */
    long double A = qk__orient_value(o.x, o.y, to.x, to.y, s->x, s->y);
    long double B = qk__orient_value(o.x, o.y, to.x, to.y, s->a, s->b);
    if (A != 0 || B != 0) {
      t = qk__orient_value(o.x, o.y, s->x, s->y, s->a, s->b) / (B - A);
    } else { /* collinear: the nearer endpoint */
      long double t1 = (((long double)s->x - o.x) * vx + ((long double)s->y - o.y) * vy) / vv;
      long double t2 = (((long double)s->a - o.x) * vx + ((long double)s->b - o.y) * vy) / vv;
      t = t1 < t2 ? t1 : t2;
    }
    break;
  }
  default:
    t = (((long double)s->x - o.x) * vx + ((long double)s->y - o.y) * vy) / vv;
  }
  if (!(t > 0)) t = 0; /* (+0: never -0) */
  if (t > 1) t = 1;
  return (double)t;
}
