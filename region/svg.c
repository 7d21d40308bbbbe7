/* The SVG drawing of a layer: features filled even-odd, index cells as outlines. */
#include "region/region_internal.h"

qk_status_t qk_region_write_svg(const qk_region_t *r, FILE *f, unsigned width) {
  if (!r || !f) return QK_ERR_INVALID;
  if (width == 0) width = 1000;
  double x0 = r->rx, y0 = r->ry, s = r->rside, k = width / s;
  fprintf(f,
          "<svg xmlns=\"http://www.w3.org/2000/svg\" width=\"%u\" height=\"%u\" "
          "viewBox=\"0 0 %u %u\">\n<rect width=\"100%%\" height=\"100%%\" fill=\"white\"/>\n",
          width, width, width, width);
  /* Features: one path per feature (its pieces in order), even-odd fill. */
  for (size_t i = 0; i < r->n_segs;) {
    uint32_t ft = r->seg_feat[i];
    unsigned hue = (unsigned)((ft * 2654435761u) % 360u);
    fprintf(f,
            "<path fill-rule=\"evenodd\" fill=\"hsl(%u,55%%,75%%)\" stroke=\"#555\" "
            "stroke-width=\"0.3\" d=\"",
            hue);
    for (; i < r->n_segs && r->seg_feat[i] == ft; i++) {
      const qk__seg_t *g = &r->segs[i];
      fprintf(f, "M%.2f %.2fL%.2f %.2f", (g->ax - x0) * k, (y0 + s - g->ay) * k, (g->bx - x0) * k,
              (y0 + s - g->by) * k);
    }
    fprintf(f, "\"/>\n");
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
