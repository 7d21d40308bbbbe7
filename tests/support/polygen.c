/* Random disjoint 45-degree polygons (see polygen.h). */
#include "polygen.h"

#include <stdlib.h>
#include <string.h>

static void *grow(void *p, size_t *cap, size_t need, size_t elem) {
  if (need <= *cap) return p;
  size_t nc = *cap ? 2 * *cap : 64;
  while (nc < need) nc *= 2;
  void *q = realloc(p, nc * elem);
  if (!q) abort(); /* test support: out of memory is fatal */
  *cap = nc;
  return q;
}

void pg_add_polygon(pg_input_t *p, const int64_t *xy, size_t n) {
  /* Drop repeated consecutive points (cuts of zero length). */
  int64_t *v = malloc(2 * n * sizeof *v);
  if (!v) abort();
  size_t k = 0;
  for (size_t i = 0; i < n; i++) {
    if (k && v[2 * k - 2] == xy[2 * i] && v[2 * k - 1] == xy[2 * i + 1]) continue;
    v[2 * k] = xy[2 * i], v[2 * k + 1] = xy[2 * i + 1], k++;
  }
  while (k > 1 && v[0] == v[2 * k - 2] && v[1] == v[2 * k - 1]) k--;
  if (k >= 3) {
    size_t base = p->nv;
    p->xy = grow(p->xy, &p->cap_v, 2 * (p->nv + k), sizeof *p->xy);
    p->seg = grow(p->seg, &p->cap_s, 2 * (p->ns + k), sizeof *p->seg);
    for (size_t i = 0; i < k; i++) {
      p->xy[2 * p->nv] = (double)v[2 * i], p->xy[2 * p->nv + 1] = (double)v[2 * i + 1];
      p->nv++;
      p->seg[2 * p->ns] = (uint32_t)(base + i);
      p->seg[2 * p->ns + 1] = (uint32_t)(base + (i + 1) % k);
      p->ns++;
    }
  }
  free(v);
}

static int64_t rnd(qkt_rng_t *r, int64_t lo, int64_t hi) { /* [lo, hi] */
  if (hi <= lo) return lo;
  return lo + (int64_t)qkt_rng_below(r, (uint32_t)(hi - lo + 1));
}

/* An octagon (or rectangle, diamond, triangle...) in the box, maybe holding another. */
static void shape(qkt_rng_t *r, pg_input_t *p, int64_t x0, int64_t y0, int64_t x1, int64_t y1) {
  int64_t w = x1 - x0, h = y1 - y0, mn = w < h ? w : h;
  if (w < 1 || h < 1) return;
  if (qkt_rng_below(r, 5) == 0 && w >= 2 && h >= 1) {
    /* A thin diagonal strip of width one. */
    int64_t k = (w - 1) < h ? (w - 1) : h;
    int64_t s[8] = {x0, y0, x0 + 1, y0, x0 + 1 + k, y0 + k, x0 + k, y0 + k};
    pg_add_polygon(p, s, 4);
    return;
  }
  int64_t a = rnd(r, 0, mn / 2), b = rnd(r, 0, mn / 2), c = rnd(r, 0, mn / 2),
          d = rnd(r, 0, mn / 2);
  if (qkt_rng_below(r, 4) == 0) a = b = c = d = mn / 2; /* diamond-like */
  int64_t o[16] = {x0 + a, y0, x1 - b, y0, x1, y0 + b, x1, y1 - c,
                   x1 - c, y1, x0 + d, y1, x0, y1 - d, x0, y0 + a};
  pg_add_polygon(p, o, 8);
  int64_t m = a > b ? a : b;
  m = m > c ? m : c;
  m = m > d ? m : d;
  /* A nested component strictly inside, clear of the boundary: the box shrunk by the
   * largest cut lies inside the octagon, and one more unit keeps them apart. */
  if (w >= 2 * m + 4 && h >= 2 * m + 4 && qkt_rng_below(r, 2) == 0)
    shape(r, p, x0 + m + 1 + rnd(r, 0, 1), y0 + m + 1 + rnd(r, 0, 1), x1 - m - 1, y1 - m - 1);
}

/* A cell [x0,x1) x [y0,y1) gets `budget` shapes by random cuts; shapes stop one unit
 * short of the cell's high sides (unless those are the domain's), so they never touch. */
static void cell(qkt_rng_t *r, pg_input_t *p, uint64_t U, int64_t x0, int64_t y0, int64_t x1,
                 int64_t y1, size_t budget) {
  int64_t w = x1 - x0, h = y1 - y0;
  if (budget <= 1 || (w < 6 && h < 6)) {
    int64_t hx = x1 == (int64_t)U ? x1 : x1 - 1, hy = y1 == (int64_t)U ? y1 : y1 - 1;
    int64_t bx0 = rnd(r, x0, x0 + (hx - x0) / 3), by0 = rnd(r, y0, y0 + (hy - y0) / 3);
    int64_t bx1 = rnd(r, hx - (hx - bx0) / 3, hx), by1 = rnd(r, hy - (hy - by0) / 3, hy);
    if (qkt_rng_below(r, 8) || budget == 0) shape(r, p, bx0, by0, bx1, by1);
    return;
  }
  size_t b1 = budget / 2, b2 = budget - b1;
  if (w >= h) {
    int64_t xm = rnd(r, x0 + w / 4, x1 - w / 4);
    cell(r, p, U, x0, y0, xm, y1, b1);
    cell(r, p, U, xm, y0, x1, y1, b2);
  } else {
    int64_t ym = rnd(r, y0 + h / 4, y1 - h / 4);
    cell(r, p, U, x0, y0, x1, ym, b1);
    cell(r, p, U, x0, ym, x1, y1, b2);
  }
}

void pg_generate(qkt_rng_t *r, uint64_t U, size_t target, pg_input_t *out) {
  memset(out, 0, sizeof *out);
  cell(r, out, U, 0, 0, (int64_t)U, (int64_t)U, target ? target : 1);
}

void pg_free(pg_input_t *p) {
  free(p->xy);
  free(p->seg);
  memset(p, 0, sizeof *p);
}
