/*
 * Building the index of a layer: the root square, the root's set, the query grid and the
 * final arrays (the design is described at the top of region.c; the refinement is in
 * build_top.c and refine.c).
 */
#include <string.h>
#include <time.h>

#include "region/region_internal.h"

static qk_status_t root_square(const qk__pieces_t *pc, qk_region_t *r, qk_error_t *err) {
  double x0 = INFINITY, y0 = INFINITY, x1 = -INFINITY, y1 = -INFINITY;
  for (size_t i = 0; i < pc->n; i++) {
    const qk__seg_t *g = &pc->seg[i];
    x0 = qk__min(x0, qk__min(g->ax, g->bx));
    x1 = qk__max(x1, qk__max(g->ax, g->bx));
    y0 = qk__min(y0, qk__min(g->ay, g->by));
    y1 = qk__max(y1, qk__max(g->ay, g->by));
  }
  if (!pc->n) {
    r->stats.box = (qk_box_t){0, 0, 0, 0};
    r->rx = r->ry = -0.5;
    r->rside = 1;
    return QK_OK;
  }
  r->stats.box = (qk_box_t){x0, y0, x1, y1};
  double w = x1 - x0, h = y1 - y0, ext = qk__max(w, h);
  if (ext < 1e-60)
    return qk__region_fail(err, QK_ERR_GEOMETRY, SIZE_MAX, "layer extent %g is too small", ext);
  /* The root strictly contains every piece, so a point outside it is outside all. */
  double side = ext * 1.125;
  for (;;) {
    double rx = x0 - (side - w) * 0.5, ry = y0 - (side - h) * 0.5;
    if (rx < x0 && ry < y0 && rx + side > x1 && ry + side > y1) {
      r->rx = rx;
      r->ry = ry;
      r->rside = side;
      return QK_OK;
    }
    side *= 1.0625;
  }
}

/* The query window (region_internal.h): inside the root square, and in lon/lat mode inside
 * (-180, 180) x (-90, 90), so that normalising such a point changes nothing (the poles and
 * the antimeridian take the single-point path). The bounds are
 * doubles a query compares with directly: x < rx + rside is x <= the double below it. */
static void query_window(qk_region_t *r) {
  double x0 = r->rx, x1 = nextafter(r->rx + r->rside, -INFINITY);
  double y0 = r->ry, y1 = nextafter(r->ry + r->rside, -INFINITY);
  if (!r->planar) {
    /* (above -180: a point on the antimeridian takes the single-point path, which
     * handles it for the closed and open rules; see locate.c) */
    x0 = qk__max(x0, nextafter(-180.0, 0.0));
    x1 = qk__min(x1, nextafter(180.0, 0.0));
    y0 = qk__max(y0, nextafter(-90.0, 0.0));
    y1 = qk__min(y1, nextafter(90.0, 0.0));
  }
  r->qx0 = x0, r->qx1 = x1, r->qy0 = y0, r->qy1 = y1;
}

static double now(void) {
  struct timespec ts;
  if (!timespec_get(&ts, TIME_UTC)) return 0;
  return (double)ts.tv_sec + 1e-9 * (double)ts.tv_nsec;
}

/* The cells' lower sides at depth G along one axis, as the descent computes them (a
 * cell's upper child starts at its centre s + h / 2): out[0 .. 2^G - 1]. */
void qk__region_grid_sides(double r0, double side, unsigned G, double *out) {
  size_t g = (size_t)1 << G;
  for (size_t i = 0; i < g; i++) {
    double s = r0, h = side;
    for (unsigned l = 0; l < G; l++) {
      h *= 0.5;
      if (i >> (G - 1 - l) & 1) s = s + h;
    }
    out[i] = s;
  }
}

/* The grid cells under the node whose kid[] value is k, at depth l, column i, row j: the
 * value the descent reaches at depth G in each, or the leaf it stops at before. A leaf
 * above depth G with edges needs its own square (for its reference point), not the grid
 * cell's: such cells descend from the root. */
static void fill_grid(const qk_region_t *r, uint32_t *grid, unsigned G, uint32_t k, unsigned l,
                      size_t i, size_t j) {
  if (l < G && !(k & QK__LEAF)) {
    for (unsigned q = 0; q < 4; q++)
      fill_grid(r, grid, G, r->kid[k + q], l + 1, 2 * i + qk__q_east(q), 2 * j + qk__q_north(q));
    return;
  }
  if (l < G && !(k & QK__DIRECT)) k = QK__REDO;
  size_t w = (size_t)1 << (G - l);
  for (size_t jj = j * w; jj < (j + 1) * w; jj++)
    for (size_t ii = i * w; ii < (i + 1) * w; ii++) grid[jj << G | ii] = k;
}

/* The grid shortcut (see region_internal.h): G grows while 4^G stays below twice the
 * leaves, up to 8 (256 KiB). */
static qk_status_t build_grid(qk_region_t *r, unsigned depth) {
  unsigned G = 0;
  while (G < 8 && G < depth && ((size_t)1 << (2 * (G + 1))) <= 2 * r->n_leaves) G++;
  if (G < 2) return QK_OK;
  size_t g = (size_t)1 << G;
  const qk_allocator_t *a = &r->alloc;
  uint32_t *grid = qk__realloc(a, NULL, 0, g * g * sizeof *grid);
  double *gx = qk__realloc(a, NULL, 0, (g + 1) * sizeof *gx);
  double *gy = qk__realloc(a, NULL, 0, (g + 1) * sizeof *gy);
  if (!grid || !gx || !gy) {
    qk__free(a, grid, g * g * sizeof *grid);
    qk__free(a, gx, (g + 1) * sizeof *gx);
    qk__free(a, gy, (g + 1) * sizeof *gy);
    return QK_ERR_NOMEM;
  }
  qk__region_grid_sides(r->rx, r->rside, G, gx);
  qk__region_grid_sides(r->ry, r->rside, G, gy);
  gx[g] = gy[g] = INFINITY;
  fill_grid(r, grid, G, r->kid[0], 0, 0, 0);
  r->grid = grid;
  r->gx = gx;
  r->gy = gy;
  r->grid_level = G;
  r->grid_scale = (double)g / r->rside;
  r->grid_side = r->rside;
  for (unsigned l = 0; l < G; l++) r->grid_side *= 0.5;
  return QK_OK;
}

/* Give back the room the doubling left (a failed shrink keeps the larger block). */
static void shrink(const qk_allocator_t *a, void **p, size_t *cap, size_t n, size_t elem) {
  if (!*p || n >= *cap) return;
  if (n == 0) n = 1;
  void *q = qk__realloc(a, *p, *cap * elem, n * elem);
  if (q) {
    *p = q;
    *cap = n;
  }
}

static void shrink_all(qk_region_t *r) {
  const qk_allocator_t *a = &r->alloc;
  shrink(a, (void **)&r->leaves, &r->cap_leaves, r->n_leaves, sizeof(qk__leaf_t));
  shrink(a, (void **)&r->le, &r->cap_le, r->n_le, sizeof(uint32_t));
  shrink(a, (void **)&r->le_tag, &r->cap_le_tag, r->n_le, sizeof(uint32_t));
  shrink(a, (void **)&r->sets, &r->cap_sets, r->n_sets, sizeof(uint32_t));
  shrink(a, (void **)&r->cover_at, &r->cap_cover_at, r->n_leaves, sizeof(qk__cover_t));
  shrink(a, (void **)&r->cover, &r->cap_cover, r->n_cover, sizeof(uint32_t));
  shrink(a, (void **)&r->kid, &r->cap_kid, r->n_kid, sizeof(uint32_t));
  shrink(a, (void **)&r->segs, &r->cap_segs, r->n_segs, sizeof(qk__seg_t));
  shrink(a, (void **)&r->seg_tag, &r->cap_seg_tag, r->n_segs, sizeof(uint32_t));
}

static size_t layer_bytes(const qk_region_t *r) {
  return sizeof *r + r->cap_segs * sizeof(qk__seg_t) + r->cap_seg_tag * sizeof(uint32_t) +
         r->cap_kid * sizeof(uint32_t) + r->cap_leaves * sizeof(qk__leaf_t) +
         r->cap_le * sizeof(uint32_t) + r->cap_le_tag * sizeof(uint32_t) +
         r->cap_sets * sizeof(uint32_t) + r->cap_cover_at * sizeof(qk__cover_t) +
         r->cap_cover * sizeof(uint32_t) + qk_tree_memory(r->tree) + r->props.pool_cap +
         (r->grid_level ? ((size_t)4 << (2 * r->grid_level)) +
                              (((size_t)2 << r->grid_level) + 2) * sizeof(double)
                        : 0) +
         (r->props.cap_start + r->props.cap_key + r->props.cap_val) * sizeof(size_t) +
         qk__region_pure_bytes(r);
}

qk_status_t qk__region_build(const qk_region_arrays_t *in, const qk_region_options_t *options,
                             qk__props_t *props, size_t skipped, size_t holes, qk_region_t **out,
                             qk_error_t *err) {
  qk_region_options_t o;
  qk_allocator_t alloc;
  qk__region_options(options, &o, &alloc);
  qk__props_t pr = {0};
  if (props) {
    pr = *props;
    memset(props, 0, sizeof *props);
  }
  if (err) {
    err->line = err->column = 0;
    err->item = SIZE_MAX;
    err->message[0] = '\0';
  }
  if (out) *out = NULL;
  qk_status_t st = QK_OK;
  if (!out) st = qk__region_fail(err, QK_ERR_INVALID, SIZE_MAX, "no output");
  if (o.leaf_edges == 0) o.leaf_edges = QK_REGION_DEFAULT_LEAF_EDGES;
  if (o.max_depth == 0) o.max_depth = QK_REGION_DEFAULT_MAX_DEPTH;
  if (!st && o.max_depth > QK_MAX_DEPTH_LIMIT)
    st = qk__region_fail(err, QK_ERR_INVALID, SIZE_MAX, "max_depth %u exceeds %d", o.max_depth,
                         QK_MAX_DEPTH_LIMIT);
  if (st) {
    qk__props_free(&alloc, &pr);
    return st;
  }
  double t0 = now();
  qk__pieces_t pc;
  if ((st = qk__region_prepare(&alloc, in, o.planar, &pc, err))) {
    qk__props_free(&alloc, &pr);
    return st;
  }
  qk__bctx_t b;
  memset(&b, 0, sizeof b);
  qk_region_t *r = qk__realloc(&alloc, NULL, 0, sizeof *r);
  if (!r) {
    qk__pieces_free(&alloc, &pc);
    qk__props_free(&alloc, &pr);
    return qk__region_fail(err, QK_ERR_NOMEM, SIZE_MAX, "out of memory");
  }
  memset(r, 0, sizeof *r);
  r->alloc = alloc;
  r->planar = o.planar;
  r->n_features = (uint32_t)in->n_features;
  r->props = pr;
  b.r = r;
  b.pc = &pc;
  b.in = in;
  b.C = o.leaf_edges;
  b.maxd = o.max_depth;
  b.splits_left = pc.n + 4096;
  b.cover_ck = UINT32_MAX;
  if ((st = root_square(&pc, r, err))) goto done;
  query_window(r);
  if (o.keep_tree) { /* the refinement is made on a quadkit tree, kept for qk_region_tree */
    qk_tree_options_t to;
    qk_tree_options_init(&to);
    to.has_root = 1;
    to.root = (qk_square_t){r->rx, r->ry, r->rside};
    to.max_depth = o.max_depth;
    to.allocator = &r->alloc;
    if ((st = qk_tree_build(NULL, 0, &to, &r->tree))) goto done;
  }
  /* The arrays at once at about their final size (measured on Natural Earth layers: the
   * nodes, the leaf pieces about 1.5 per piece, the leaves with pieces a third), so that
   * they are seldom copied while they grow; shrink_all gives back the rest. */
  {
    size_t pn = pc.n + 16;
    if ((st = qk__grow(&alloc, (void **)&r->kid, &r->cap_kid, pn, sizeof(uint32_t))) ||
        (st = qk__grow(&alloc, (void **)&r->le, &r->cap_le, pn + pn / 2, sizeof(uint32_t))) ||
        (st = qk__grow(&alloc, (void **)&r->le_tag, &r->cap_le_tag, pn + pn / 2,
                       sizeof(uint32_t))) ||
        (st = qk__grow(&alloc, (void **)&r->leaves, &r->cap_leaves, pn / 2, sizeof(qk__leaf_t))) ||
        (st = qk__grow(&alloc, (void **)&r->sets, &r->cap_sets, pn / 2, sizeof(uint32_t))))
      goto done;
  }
  r->n_kid = 1;
  b.bad = qk__realloc(&alloc, NULL, 0, in->n_rings + 1);
  if (!b.bad) {
    st = QK_ERR_NOMEM;
    goto done;
  }
  memset(b.bad, 0, in->n_rings + 1);
  st = qk__build_top(&b);
  if (!st) st = build_grid(r, b.depth);
  if (!st) st = qk__region_pure_build(r);

done:
  for (int d = 0; d <= QK__MAXD; d++) {
    qk__free(&alloc, b.store[d], b.cap_store[d] * sizeof(uint32_t));
    qk__free(&alloc, b.s[d], b.cap_s[d] * sizeof(uint32_t));
    qk__free(&alloc, b.odd[d], b.cap_odd[d] * sizeof(uint32_t));
  }
  qk__free(&alloc, b.sh, b.cap_sh * sizeof(uint32_t));
  qk__free(&alloc, b.cov, b.cap_cov * sizeof(uint32_t));
  qk__free(&alloc, b.ck_cov, b.cap_ck_cov * sizeof(uint32_t));
  qk__free(&alloc, b.chg, b.cap_chg * sizeof(uint32_t));
  size_t bad = 0;
  if (b.bad) {
    for (size_t i = 0; i < in->n_rings; i++) bad += b.bad[i];
    qk__free(&alloc, b.bad, in->n_rings + 1);
  }
  /* The drawing's tags, in place of the features the build read (see seg_tag). */
  for (size_t i = 0; i < pc.n; i++)
    pc.feat[i] = pc.feat[i] << 2 |
                 (i == 0 || pc.ring[i] != pc.ring[i - 1] ? QK__SEG_RING_START : 0u) |
                 (pc.vtx[i] == UINT32_MAX ? QK__SEG_ADDED : 0u);
  qk__free(&alloc, pc.ring, pc.cap * sizeof(uint32_t));
  qk__free(&alloc, pc.vtx, pc.cap * sizeof(uint32_t));
  r->segs = pc.seg;
  r->seg_tag = pc.feat;
  r->n_segs = pc.n;
  r->cap_segs = r->cap_seg_tag = pc.cap;
  if (st) {
    qk_region_free(r);
    if (err && !err->message[0])
      qk__region_fail(err, st, SIZE_MAX, "%s while building the index", qk_strerror(st));
    return st;
  }
  qk_region_stats_t *s = &r->stats;
  s->features = in->n_features;
  s->rings = in->n_rings;
  s->vertices = in->n_rings ? in->ring_start[in->n_rings] : 0;
  if (holes == SIZE_MAX) {
    holes = 0;
    for (size_t f = 0; f < in->n_features; f++) {
      size_t k = in->feature_start[f + 1] - in->feature_start[f];
      holes += k ? k - 1 : 0;
    }
  }
  s->holes = holes;
  s->self_intersecting = bad;
  s->skipped = skipped;
  s->edges = pc.n;
  s->leaves = r->n_leaves + r->n_direct;
  s->leaf_edges = r->n_le;
  s->depth = b.depth;
  s->planar = r->planar;
  shrink_all(r);
  s->build_seconds = now() - t0;
  s->bytes = layer_bytes(r);
  *out = r;
  return QK_OK;
}
