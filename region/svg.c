/* The SVG drawing of a layer: features filled even-odd, index cells as outlines. */
#include "region/region_internal.h"
#include "index/textloc.h"

/* Features: one path per feature, each of its rings one closed subpath through its pieces
 * in order, filled even-odd. In lon/lat mode the pieces of a ring that crosses the
 * antimeridian do not join end to end: a cut's two closures meet the pole line at 180 and
 * at -180, and the pieces along the pole line come last. The subpath leaves those out and
 * runs straight along the pole line from one closure to the other. Both the subpath and
 * the ring's pieces are closed, so what one has and the other lacks is closed too, and
 * lies on the pole line: it covers no area, and the even-odd fill is the feature's. The
 * pieces added along the antimeridian and the poles are not the feature's boundary: they
 * are filled but not stroked, the outline being a second path of the ring's own pieces. */
/* A path command to the layer's point (x, y), in picture units (k a unit, y down). */
static void put(const qk_region_t *r, FILE *f, char cmd, double x, double y, double k) {
  fprintf(f, "%c%.2f %.2f", cmd, (x - r->rx) * k, (r->ry + r->rside - y) * k);
}

static void write_feature(const qk_region_t *r, FILE *f, size_t i0, size_t i1, double k) {
  bool added = false;
  for (size_t i = i0; i < i1; i++) added |= (r->seg_tag[i] & QK__SEG_ADDED) != 0;
  unsigned hue = (unsigned)(((r->seg_tag[i0] >> 2) * 2654435761u) % 360u);
  fprintf(f, "<path fill-rule=\"evenodd\" fill=\"hsl(%u,55%%,75%%)\" ", hue);
  if (added)
    fprintf(f, "stroke=\"none\" d=\"");
  else
    fprintf(f, "stroke=\"#555\" stroke-width=\"0.3\" d=\"");
  bool open = false; /* a subpath is under way; (px, py): where it stands */
  double px = 0, py = 0;
  for (size_t i = i0; i < i1; i++) {
    const qk__seg_t *g = &r->segs[i];
    if ((r->seg_tag[i] & QK__SEG_RING_START) && open) fputc('Z', f), open = false;
    if ((r->seg_tag[i] & QK__SEG_ADDED) && g->ay == g->by) continue; /* along a pole */
    if (!open || g->ax != px || g->ay != py) /* (not open: a ring's first; else a gap) */
      put(r, f, open ? 'L' : 'M', g->ax, g->ay, k);
    put(r, f, 'L', g->bx, g->by, k);
    open = true, px = g->bx, py = g->by;
  }
  if (open) fputc('Z', f);
  fprintf(f, "\"/>\n");
  if (!added) return;
  fprintf(f, "<path fill=\"none\" stroke=\"#555\" stroke-width=\"0.3\" d=\"");
  bool drawn = false; /* the last piece written was the previous one */
  for (size_t i = i0; i < i1; i++) {
    const qk__seg_t *g = &r->segs[i];
    if (r->seg_tag[i] & QK__SEG_ADDED) {
      drawn = false;
      continue;
    }
    if (!drawn || (r->seg_tag[i] & QK__SEG_RING_START) || g->ax != g[-1].bx || g->ay != g[-1].by)
      put(r, f, 'M', g->ax, g->ay, k);
    put(r, f, 'L', g->bx, g->by, k);
    drawn = true;
  }
  fprintf(f, "\"/>\n");
}

static qk_status_t write_svg(const qk_region_t *r, FILE *f, unsigned width) {
  if (!r || !f) return QK_ERR_INVALID;
  if (width == 0) width = 1000;
  double x0 = r->rx, y0 = r->ry, s = r->rside, k = width / s;
  fprintf(f,
          "<svg xmlns=\"http://www.w3.org/2000/svg\" width=\"%u\" height=\"%u\" "
          "viewBox=\"0 0 %u %u\">\n<rect width=\"100%%\" height=\"100%%\" fill=\"white\"/>\n",
          width, width, width, width);
  for (size_t i = 0, j; i < r->n_segs; i = j) {
    for (j = i + 1; j < r->n_segs && r->seg_tag[j] >> 2 == r->seg_tag[i] >> 2;) j++;
    write_feature(r, f, i, j, k);
  }
  /* Cells: a walk down the flat child array with the squares computed on the way. */
  fprintf(f, "<g fill=\"none\" stroke=\"#c33\" stroke-width=\"0.25\">\n");
  typedef struct cell {
    uint32_t k;
    double x, y, h;
  } cell_t;
  cell_t stack[4 * (QK_MAX_DEPTH_LIMIT + 2)];
  int top = 0;
  stack[top++] = (cell_t){r->kid[0], x0, y0, s};
  while (top) {
    cell_t c = stack[--top];
    if (c.k & QK__LEAF) {
      fprintf(f, "<rect x=\"%.2f\" y=\"%.2f\" width=\"%.2f\" height=\"%.2f\"/>\n", (c.x - x0) * k,
              (y0 + s - c.y - c.h) * k, c.h * k, c.h * k);
      continue;
    }
    double h = c.h * 0.5;
    for (unsigned q = 0; q < 4; q++) {
      double nx = qk__q_east(q) ? c.x + h : c.x, ny = qk__q_north(q) ? c.y + h : c.y;
      stack[top++] = (cell_t){r->kid[c.k + q], nx, ny, h};
    }
  }
  fprintf(f, "</g>\n</svg>\n");
  return fflush(f) != 0 || ferror(f) ? QK_ERR_IO : QK_OK; /* (flushed: see mesh/write.c) */
}

/* Runs in the C locale (index/textloc.h): the same bytes whatever locale the program or
 * the calling thread set ("400.000", never "400,000"). */
qk_status_t qk_region_write_svg(const qk_region_t *r, FILE *f, unsigned width) {
  QK__RETURN_IN_C_LOCALE(write_svg(r, f, width));
}
