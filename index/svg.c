/* SVG drawing of a tree: leaf cells as squares, points as dots. */
#include <math.h>

#include "index/index_access.h"
#include "index/textloc.h"

/* Positions are the offset from the root's corner over the root's side, times the width:
 * the offset is at most the side, so neither step overflows, where width / side did for
 * sides below about 4.5e-306 (every position inf or NaN). */
typedef struct svg {
  FILE *f;
  double x0, y0, side, w;
  int points; /* 0: draw cells; 1: draw points */
} svg_t;

static double along(const svg_t *s, double v, double from) { return (v - from) / s->side * s->w; }

/* A position as written (%.3f): one that rounds to zero is written 0.000, not -0.000 (the
 * top row's y, w - (w - side) - side, came out a few ulps below zero). */
static double shown(double v) { return fabs(v) < 0.0005 ? 0.0 : v; }

static qk_visit_t draw(const qk_tree_t *t, qk_node_t v, void *ud) {
  svg_t *s = ud;
  const qk__node_t *n = &t->nodes[v];
  if (!qk__is_leaf(n)) return QK_VISIT_CONTINUE;
  qk__geom_t g = qk__node_geom(t, v);
  double side = ldexp(s->w, -(int)g.depth);
  double x = along(s, g.x0, s->x0), y = s->w - along(s, g.y0, s->y0) - side;
  if (!s->points) {
    fprintf(s->f, "<rect x=\"%.3f\" y=\"%.3f\" width=\"%.3f\" height=\"%.3f\"/>\n", shown(x),
            shown(y), side, side);
    return QK_VISIT_CONTINUE;
  }
  for (uint32_t i = n->start; i < n->start + n->count; i++)
    fprintf(s->f, "<circle cx=\"%.3f\" cy=\"%.3f\" r=\"1.6\"/>\n", shown(along(s, t->px[i], s->x0)),
            shown(s->w - along(s, t->py[i], s->y0)));
  return QK_VISIT_CONTINUE;
}

void qk__svg_open(FILE *f, unsigned width) {
  unsigned w = width + 4;
  fprintf(f,
          "<svg xmlns=\"http://www.w3.org/2000/svg\" width=\"%u\" height=\"%u\" "
          "viewBox=\"-2 -2 %u %u\">\n<rect x=\"-2\" y=\"-2\" width=\"%u\" height=\"%u\" "
          "fill=\"white\"/>\n",
          w, w, w, w, w, w);
}

static qk_status_t write_svg(const qk_tree_t *t, FILE *f, unsigned width) {
  if (!t || !f) return QK_ERR_INVALID;
  if (width == 0) width = 800;
  svg_t s = {f, t->root_x, t->root_y, t->side[0], (double)width, 0};
  qk__svg_open(f, width);
  fprintf(f, "<g fill=\"none\" stroke=\"#4a6fa5\" stroke-width=\"0.6\">\n");
  /* Cells first, then the points on top, in two passes over the leaves. */
  qk_status_t st = qk_tree_visit(t, 0, draw, &s);
  fprintf(f, "</g>\n<g fill=\"#c0392b\">\n");
  s.points = 1;
  if (st == QK_OK) st = qk_tree_visit(t, 0, draw, &s);
  fprintf(f, "</g>\n</svg>\n");
  if (st != QK_OK) return st;
  return fflush(f) != 0 || ferror(f) ? QK_ERR_IO : QK_OK; /* (flushed: see mesh/write.c) */
}

/* Runs in the C locale (index/textloc.h): the same bytes whatever locale the program or
 * the calling thread set ("400.000", never "400,000"). */
qk_status_t qk_tree_write_svg(const qk_tree_t *t, FILE *f, unsigned width) {
  QK__RETURN_IN_C_LOCALE(write_svg(t, f, width));
}
