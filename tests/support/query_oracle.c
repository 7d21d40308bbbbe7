/* Brute-force oracles for the query module (see query_oracle.h). */
#include "query_oracle.h"

#include <math.h>
#include <stdio.h>
#include <stdlib.h>

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
  double r2 = r * r;
  for (size_t i = 0; i < n; i++) {
    double dx = pts[i].x - c.x, dy = pts[i].y - c.y, d2 = dx * dx + dy * dy;
    if (d2 <= r2) {
      out[m].id = (qk_id_t)i;
      out[m++].dist = sqrt(d2);
    }
  }
  return m;
}

size_t qko_knn(const qk_point_t *pts, const unsigned char *alive, size_t n, qk_point_t q, size_t k,
               double max_dist, qk_neighbor_t *out) {
  qk_neighbor_t *all = malloc((n ? n : 1) * sizeof *all);
  size_t m = 0;
  double lim = max_dist * max_dist;
  for (size_t i = 0; i < n; i++) {
    if (alive && !alive[i]) continue;
    double dx = pts[i].x - q.x, dy = pts[i].y - q.y, d2 = dx * dx + dy * dy;
    if (d2 > lim) continue;
    all[m].id = (qk_id_t)i;
    all[m++].dist = d2; /* sort on the squared distance, as the library does */
  }
  qko_sort_by_dist(all, m);
  if (m > k) m = k;
  for (size_t i = 0; i < m; i++) {
    out[i].id = all[i].id;
    out[i].dist = sqrt(all[i].dist);
  }
  free(all);
  return m;
}

/* Item predicates, written out again (same formulas as documented in query.h). */
static int o_disc_disc(qk_disc_t a, qk_disc_t b) {
  double dx = a.x - b.x, dy = a.y - b.y, rs = a.r + b.r;
  return dx * dx + dy * dy <= rs * rs;
}
static int o_box_box(qk_box_t a, qk_box_t b) {
  return a.xmin <= b.xmax && b.xmin <= a.xmax && a.ymin <= b.ymax && b.ymin <= a.ymax;
}
static int o_disc_box(qk_disc_t d, qk_box_t b) {
  double px = fmin(fmax(d.x, b.xmin), b.xmax), py = fmin(fmax(d.y, b.ymin), b.ymax);
  double dx = d.x - px, dy = d.y - py;
  return dx * dx + dy * dy <= d.r * d.r;
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

/* Ray against one item: smallest t in [0, tmax] or -1. The disc formula is the stable
 * one documented in collide.c; the box one is the slab method. */
static double o_ray_disc(qk_disc_t d, qk_point_t o, qk_point_t v, double tmax) {
  double fx = o.x - d.x, fy = o.y - d.y;
  double c = fx * fx + fy * fy - d.r * d.r;
  if (c <= 0) return 0;
  double b = fx * v.x + fy * v.y;
  if (b >= 0) return -1;
  double a = v.x * v.x + v.y * v.y, cr = fx * v.y - fy * v.x;
  double disc = a * d.r * d.r - cr * cr;
  if (disc < 0) return -1;
  double t = c / (-b + sqrt(disc));
  return t <= tmax ? t : -1;
}
static double o_ray_box(qk_box_t bx, qk_point_t o, qk_point_t v, double tmax) {
  double lo = 0, hi = tmax;
  double mins[2] = {bx.xmin, bx.ymin}, maxs[2] = {bx.xmax, bx.ymax}, os[2] = {o.x, o.y},
         vs[2] = {v.x, v.y};
  for (int a = 0; a < 2; a++) {
    if (vs[a] == 0) {
      if (os[a] < mins[a] || os[a] > maxs[a]) return -1;
      continue;
    }
    double t1 = (mins[a] - os[a]) / vs[a], t2 = (maxs[a] - os[a]) / vs[a];
    if (t1 > t2) {
      double s = t1;
      t1 = t2;
      t2 = s;
    }
    lo = fmax(lo, t1);
    hi = fmin(hi, t2);
  }
  return lo <= hi ? lo : -1;
}

qk_hit_t qko_raycast(const qk_disc_t *d, size_t nd, const qk_box_t *b, size_t nb, qk_point_t o,
                     qk_point_t dir, double tmax) {
  qk_hit_t h = {QK_NONE, INFINITY};
  for (size_t i = 0; i < nd + nb; i++) {
    double t = i < nd ? o_ray_disc(d[i], o, dir, tmax) : o_ray_box(b[i - nd], o, dir, tmax);
    if (t >= 0 && t < h.t) {
      h.t = t;
      h.id = (qk_id_t)i;
    }
  }
  return h;
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
