/*
 * Checking the components before meshing: integer coordinates inside the domain, allowed
 * angles, every vertex of degree two, no coincident vertices; then the cycles, numbered
 * by their smallest segment and oriented counter-clockwise. Crossings and touchings are
 * found later, during the subdivision (mesh/subdivide.c), where they cost nothing extra.
 */
#include "mesh/mesh_internal.h"

#include <math.h>
#include <stdlib.h>
#include <string.h>

/* Sorting vertices by position to find coincident ones. */
typedef struct vkey {
  int64_t x, y;
  uint32_t i;
} vkey_t;

static int vkey_cmp(const void *a, const void *b) {
  const vkey_t *p = a, *q = b;
  if (p->x != q->x) return p->x < q->x ? -1 : 1;
  if (p->y != q->y) return p->y < q->y ? -1 : 1;
  return (p->i > q->i) - (p->i < q->i);
}

/* Integer coordinates inside the domain; sets g->U. */
static qk_status_t check_vertices(qk__gen_t *g, uint64_t size) {
  const qk_poly_t *P = g->poly;
  uint64_t maxc = 0;
  for (size_t i = 0; i < P->nv; i++) {
    double x = P->vx[i], y = P->vy[i];
    if (!(x == floor(x) && y == floor(y)) || !isfinite(x) || !isfinite(y))
      return qk__mesh_fail(g->err, QK_ERR_GEOMETRY, P->vline[i],
                           "vertex %lu: coordinates (%.17g, %.17g) are not integers",
                           qk__mesh_num(P, i), x, y);
    if (x < 0 || y < 0 || x > (double)QK_MESH_MAX_SIZE || y > (double)QK_MESH_MAX_SIZE ||
        (size && (x > (double)size || y > (double)size)))
      return qk__mesh_fail(g->err, QK_ERR_GEOMETRY, P->vline[i],
                           "vertex %lu: (%.17g, %.17g) lies outside the domain [0,%llu]^2",
                           qk__mesh_num(P, i), x, y,
                           (unsigned long long)(size ? size : QK_MESH_MAX_SIZE));
    if ((uint64_t)x > maxc) maxc = (uint64_t)x;
    if ((uint64_t)y > maxc) maxc = (uint64_t)y;
  }
  if (size) {
    g->U = size;
  } else {
    g->U = 1;
    while (g->U < maxc) g->U *= 2;
  }
  return QK_OK;
}

/* Coincident vertices would make two components touch or a polygon degenerate. keys has
 * P->nv slots. */
static qk_status_t check_coincident(qk__gen_t *g, vkey_t *keys) {
  const qk_poly_t *P = g->poly;
  for (size_t i = 0; i < P->nv; i++)
    keys[i] = (vkey_t){(int64_t)P->vx[i], (int64_t)P->vy[i], (uint32_t)i};
  qsort(keys, P->nv, sizeof *keys, vkey_cmp);
  for (size_t i = 1; i < P->nv; i++)
    if (keys[i].x == keys[i - 1].x && keys[i].y == keys[i - 1].y)
      return qk__mesh_fail(g->err, QK_ERR_GEOMETRY, P->vline[keys[i].i],
                           "vertices %lu and %lu coincide at (%.17g, %.17g)",
                           qk__mesh_num(P, keys[i - 1].i), qk__mesh_num(P, keys[i].i),
                           g->src->vx[keys[i].i] + 0.0, g->src->vy[keys[i].i] + 0.0);
  return QK_OK;
}

/* Segments: distinct endpoints, allowed angles, and every vertex of degree two; fills the
 * two segments of each vertex into adj (2 * P->nv slots; deg has P->nv). */
static qk_status_t check_segments(qk__gen_t *g, uint32_t *adj, uint8_t *deg) {
  const qk_poly_t *P = g->poly;
  memset(deg, 0, P->nv);
  for (size_t s = 0; s < P->ns; s++) {
    uint32_t u = P->seg[2 * s], v = P->seg[2 * s + 1];
    int64_t dx = (int64_t)P->vx[v] - (int64_t)P->vx[u], dy = (int64_t)P->vy[v] - (int64_t)P->vy[u];
    if (u == v)
      return qk__mesh_fail(g->err, QK_ERR_GEOMETRY, P->sline[s],
                           "segment %lu joins vertex %lu to itself", qk__mesh_num(P, s),
                           qk__mesh_num(P, u));
    /* The coordinates as given, for the message ("+ 0.0" prints -0 as 0, as the book's
     * integer messages did). */
    const qk_poly_t *S = g->src;
    if (!(dx == 0 || dy == 0 || dx == dy || dx == -dy))
      return qk__mesh_fail(g->err, QK_ERR_GEOMETRY, P->sline[s],
                           "segment %lu from (%.17g, %.17g) to (%.17g, %.17g) is not at 0, 45, 90 "
                           "or 135 degrees%s",
                           qk__mesh_num(P, s), S->vx[u] + 0.0, S->vy[u] + 0.0, S->vx[v] + 0.0,
                           S->vy[v] + 0.0,
                           S == P ? "" : " (the dyadic mode keeps the book's edge directions)");
    for (int k = 0; k < 2; k++) {
      uint32_t w = P->seg[2 * s + k];
      if (deg[w] >= 2)
        return qk__mesh_fail(g->err, QK_ERR_GEOMETRY, P->sline[s],
                             "vertex %lu has degree more than 2 (segment %lu is its third)",
                             qk__mesh_num(P, w), qk__mesh_num(P, s));
      adj[2 * w + deg[w]++] = (uint32_t)s;
    }
  }
  for (size_t i = 0; i < P->nv; i++)
    if (deg[i] != 2)
      return qk__mesh_fail(g->err, QK_ERR_GEOMETRY, P->vline[i],
                           deg[i] ? "vertex %lu has degree 1: it ends an open chain"
                                  : "vertex %lu is on no segment (degree 0)",
                           qk__mesh_num(P, i));
  return QK_OK;
}

/* Orient the edges e[first..g->ne) of component c counter-clockwise, from the turn at
 * the lowest (then leftmost) vertex, which is convex. */
static qk_status_t orient_component(qk__gen_t *g, uint32_t c, size_t first) {
  const qk_poly_t *P = g->poly;
  size_t lo = first;
  for (size_t i = first + 1; i < g->ne; i++)
    if (g->e[i].ay < g->e[lo].ay || (g->e[i].ay == g->e[lo].ay && g->e[i].ax < g->e[lo].ax)) lo = i;
  const qk__edge_t *in = &g->e[lo == first ? g->ne - 1 : lo - 1], *outg = &g->e[lo];
  int64_t turn =
      qk__cross(in->bx - in->ax, in->by - in->ay, outg->bx - outg->ax, outg->by - outg->ay);
  if (turn == 0) {
    g->meet = QK__MEET_TOUCH;
    return qk__mesh_fail(g->err, QK_ERR_GEOMETRY, P->sline[outg->seg],
                         "component %u is degenerate: segments %lu and %lu overlap", c,
                         qk__mesh_num(P, in->seg), qk__mesh_num(P, outg->seg));
  }
  if (turn < 0)
    for (size_t i = first; i < g->ne; i++) {
      qk__edge_t *e = &g->e[i];
      int64_t tx = e->ax, ty = e->ay;
      e->ax = e->bx, e->ay = e->by, e->bx = tx, e->by = ty;
    }
  return QK_OK;
}

/* Components: walk each cycle from its smallest segment, so that the cycle of segment 0
 * is component 1 and so on. comp_of has P->ns slots. */
static qk_status_t walk_components(qk__gen_t *g, const uint32_t *adj, uint32_t *comp_of) {
  const qk_poly_t *P = g->poly;
  g->e = qk__realloc(g->a, NULL, 0, (P->ns ? P->ns : 1) * sizeof *g->e);
  if (!g->e) return qk__mesh_fail(g->err, QK_ERR_NOMEM, 0, "out of memory");
  for (size_t s = 0; s < P->ns; s++) comp_of[s] = 0;
  for (size_t s0 = 0; s0 < P->ns; s0++) {
    if (comp_of[s0]) continue;
    uint32_t c = ++g->ncomp;
    size_t first = g->ne;
    /* Walk: from segment s entered at vertex `from`, leave through its other end. */
    uint32_t s = (uint32_t)s0, from = P->seg[2 * s0];
    size_t len = 0;
    do {
      comp_of[s] = c;
      uint32_t to = P->seg[2 * s] == from ? P->seg[2 * s + 1] : P->seg[2 * s];
      g->e[g->ne++] = (qk__edge_t){
          (int64_t)P->vx[from], (int64_t)P->vy[from], (int64_t)P->vx[to], (int64_t)P->vy[to], c, s};
      len++;
      s = adj[2 * to] == s ? adj[2 * to + 1] : adj[2 * to];
      from = to;
    } while (s != s0);
    if (len < 3) {
      g->meet = QK__MEET_TOUCH;
      return qk__mesh_fail(g->err, QK_ERR_GEOMETRY, P->sline[g->e[first + 1].seg],
                           "segments %lu and %lu coincide", qk__mesh_num(P, g->e[first].seg),
                           qk__mesh_num(P, g->e[first + 1].seg));
    }
    qk_status_t st = orient_component(g, c, first);
    if (st) return st;
  }
  return QK_OK;
}

/*
 * Validate vertices and segments, find the components (cycles) and orient their edges
 * counter-clockwise. Fills g->e, g->ne, g->ncomp and g->U.
 */
qk_status_t qk__mesh_validate(qk__gen_t *g, uint64_t size) {
  const qk_poly_t *P = g->poly;
  qk_status_t st = check_vertices(g, size);
  if (st) return st;
  vkey_t *keys = qk__realloc(g->a, NULL, 0, (P->nv ? P->nv : 1) * sizeof *keys);
  uint32_t *adj = qk__realloc(g->a, NULL, 0, (P->nv ? 2 * P->nv : 1) * sizeof *adj);
  uint8_t *deg = qk__realloc(g->a, NULL, 0, P->nv ? P->nv : 1);
  uint32_t *comp_of = qk__realloc(g->a, NULL, 0, (P->ns ? P->ns : 1) * sizeof *comp_of);
  if (!keys || !adj || !deg || !comp_of)
    st = qk__mesh_fail(g->err, QK_ERR_NOMEM, 0, "out of memory");
  else if (!(st = check_coincident(g, keys)) && !(st = check_segments(g, adj, deg)))
    st = walk_components(g, adj, comp_of);
  qk__free(g->a, keys, (P->nv ? P->nv : 1) * sizeof *keys);
  qk__free(g->a, adj, (P->nv ? 2 * P->nv : 1) * sizeof *adj);
  qk__free(g->a, deg, P->nv ? P->nv : 1);
  qk__free(g->a, comp_of, (P->ns ? P->ns : 1) * sizeof *comp_of);
  return st;
}
