/*
 * Collision of items with extent. Discs and boxes are stored in a point-region quadtree
 * by their centres (ch. 14); since an item may stick out of the square of the leaf that
 * holds its centre, every node also keeps the bounding box of all items beneath it (the
 * quadtree analogue of an R-tree's node rectangle). A query then enters a node exactly
 * when that box meets the query, which widens each node's reach by just as much as its
 * largest item needs, and no more.
 */
#include <stdlib.h>
#include <string.h>

#include "query/query_internal.h"

struct qk_collider {
  qk_allocator_t alloc;
  qk_tree_t *tree;
  size_t n_discs, n;
  qk_disc_t *discs;
  qk_box_t *boxes;
  qk_box_t *ibox; /* per item id: a box containing everything the item's tests can touch */
  qk_box_t *nbox; /* per node id: union of ibox over the items beneath */
  size_t n_nodes;
  double mag; /* largest coordinate magnitude of any item box, for rounding margins */
};

/* Exact overlap predicates (touching counts). */
static inline int disc_disc(const qk_disc_t *a, const qk_disc_t *b) {
  double dx = a->x - b->x, dy = a->y - b->y, rs = a->r + b->r;
  return dx * dx + dy * dy <= rs * rs;
}

static inline int box_box(const qk_box_t *a, const qk_box_t *b) {
  return a->xmin <= b->xmax && b->xmin <= a->xmax && a->ymin <= b->ymax && b->ymin <= a->ymax;
}

static inline int disc_box(const qk_disc_t *d, const qk_box_t *b) {
  double px = d->x < b->xmin ? b->xmin : (d->x > b->xmax ? b->xmax : d->x);
  double py = d->y < b->ymin ? b->ymin : (d->y > b->ymax ? b->ymax : d->y);
  double dx = d->x - px, dy = d->y - py;
  return dx * dx + dy * dy <= d->r * d->r;
}

/* A query shape or an item: a disc or a box. */
typedef struct shape {
  int is_disc;
  qk_disc_t d;
  qk_box_t b;
} shape_t;

static inline shape_t item_shape(const qk_collider_t *c, qk_id_t id) {
  shape_t s;
  s.is_disc = id < c->n_discs;
  if (s.is_disc)
    s.d = c->discs[id];
  else
    s.b = c->boxes[id - c->n_discs];
  return s;
}

static inline int shapes_overlap(const shape_t *a, const shape_t *b) {
  if (a->is_disc) return b->is_disc ? disc_disc(&a->d, &b->d) : disc_box(&a->d, &b->b);
  return b->is_disc ? disc_box(&b->d, &a->b) : box_box(&a->b, &b->b);
}

/*
 * The box around a disc, widened by 2^-40 of its magnitude: the disc tests round, so a
 * pair they accept may be apart by a few units in the last place more than r1 + r2; the
 * margin keeps such pairs inside the boxes used for pruning.
 */
static qk_box_t disc_bbox(const qk_disc_t *d) {
  double pad = (fabs(d->x) + fabs(d->y) + d->r) * 0x1p-40;
  qk_box_t b = {d->x - d->r - pad, d->y - d->r - pad, d->x + d->r + pad, d->y + d->r + pad};
  return b;
}

static inline void box_union(qk_box_t *a, const qk_box_t *b) {
  if (b->xmin < a->xmin) a->xmin = b->xmin;
  if (b->ymin < a->ymin) a->ymin = b->ymin;
  if (b->xmax > a->xmax) a->xmax = b->xmax;
  if (b->ymax > a->ymax) a->ymax = b->ymax;
}

/* Post-order: a node's box is the union of its children's (or its items'). Recursion
 * depth is bounded by the tree's depth cap. */
static qk_box_t fill_node_boxes(qk_collider_t *c, uint32_t node) {
  const qk_tree_t *t = c->tree;
  const qk__node_t *n = &t->nodes[node];
  qk_box_t b = {INFINITY, INFINITY, -INFINITY, -INFINITY};
  if (qk__is_leaf(n)) {
    for (uint32_t i = 0; i < n->count; i++) box_union(&b, &c->ibox[t->pid[n->start + i]]);
  } else {
    for (uint32_t k = 0; k < 4; k++) {
      qk_box_t cb = fill_node_boxes(c, n->child + k);
      box_union(&b, &cb);
    }
  }
  c->nbox[node] = b;
  return b;
}

void qk_collider_free(qk_collider_t *c) {
  if (!c) return;
  qk_allocator_t a = c->alloc;
  qk__free(&a, c->discs, c->n_discs * sizeof *c->discs);
  qk__free(&a, c->boxes, (c->n - c->n_discs) * sizeof *c->boxes);
  qk__free(&a, c->ibox, c->n * sizeof *c->ibox);
  qk__free(&a, c->nbox, c->n_nodes * sizeof *c->nbox);
  qk_tree_free(c->tree);
  qk__free(&a, c, sizeof *c);
}

qk_status_t qk_collider_build(const qk_disc_t *discs, size_t n_discs, const qk_box_t *boxes,
                              size_t n_boxes, const qk_tree_options_t *options,
                              qk_collider_t **out) {
  if (!out) return QK_ERR_INVALID;
  *out = NULL;
  if ((n_discs > 0 && !discs) || (n_boxes > 0 && !boxes)) return QK_ERR_INVALID;
  if (n_discs > QK_MAX_POINTS || n_boxes > QK_MAX_POINTS - n_discs) return QK_ERR_LIMIT;
  for (size_t i = 0; i < n_discs; i++) {
    if (!isfinite(discs[i].x) || !isfinite(discs[i].y) || !isfinite(discs[i].r))
      return QK_ERR_NONFINITE;
    if (discs[i].r < 0) return QK_ERR_GEOMETRY;
  }
  for (size_t i = 0; i < n_boxes; i++) {
    const qk_box_t *b = &boxes[i];
    if (!isfinite(b->xmin) || !isfinite(b->ymin) || !isfinite(b->xmax) || !isfinite(b->ymax))
      return QK_ERR_NONFINITE;
    if (b->xmin > b->xmax || b->ymin > b->ymax) return QK_ERR_GEOMETRY;
  }
  qk_tree_options_t opt;
  if (options) {
    opt = *options;
  } else {
    qk_tree_options_init(&opt);
    opt.capacity = 8;
  }
  qk_allocator_t a = {NULL, NULL};
  if (opt.allocator) a = *opt.allocator;
  size_t n = n_discs + n_boxes;

  qk_collider_t *c = qk__realloc(&a, NULL, 0, sizeof *c);
  if (!c) return QK_ERR_NOMEM;
  memset(c, 0, sizeof *c);
  c->alloc = a;
  c->n_discs = n_discs;
  c->n = n;
  qk_status_t st = QK_OK;
  qk_point_t *centres = NULL;
  if (n_discs) c->discs = qk__realloc(&a, NULL, 0, n_discs * sizeof *c->discs);
  if (n_boxes) c->boxes = qk__realloc(&a, NULL, 0, n_boxes * sizeof *c->boxes);
  if (n) c->ibox = qk__realloc(&a, NULL, 0, n * sizeof *c->ibox);
  if (n) centres = qk__realloc(&a, NULL, 0, n * sizeof *centres);
  if ((n_discs && !c->discs) || (n_boxes && !c->boxes) || (n && (!c->ibox || !centres))) {
    st = QK_ERR_NOMEM;
    goto fail;
  }
  if (n_discs) memcpy(c->discs, discs, n_discs * sizeof *discs);
  if (n_boxes) memcpy(c->boxes, boxes, n_boxes * sizeof *boxes);
  c->mag = 0;
  for (size_t i = 0; i < n; i++) {
    qk_box_t bb;
    if (i < n_discs) {
      bb = disc_bbox(&discs[i]);
      centres[i].x = discs[i].x;
      centres[i].y = discs[i].y;
    } else {
      bb = boxes[i - n_discs];
      /* Halves first, so that the sum cannot overflow. */
      centres[i].x = 0.5 * bb.xmin + 0.5 * bb.xmax;
      centres[i].y = 0.5 * bb.ymin + 0.5 * bb.ymax;
    }
    c->ibox[i] = bb;
    double m = fmax(fmax(fabs(bb.xmin), fabs(bb.xmax)), fmax(fabs(bb.ymin), fabs(bb.ymax)));
    if (m > c->mag) c->mag = m;
  }
  st = qk_tree_build(centres, n, &opt, &c->tree);
  if (st != QK_OK) goto fail;
  qk__free(&a, centres, n * sizeof *centres);
  centres = NULL;
  c->n_nodes = c->tree->n_nodes;
  c->nbox = qk__realloc(&a, NULL, 0, c->n_nodes * sizeof *c->nbox);
  if (!c->nbox) {
    c->n_nodes = 0;
    st = QK_ERR_NOMEM;
    goto fail;
  }
  fill_node_boxes(c, 0);
  *out = c;
  return QK_OK;
fail:
  qk__free(&a, centres, n * sizeof *centres);
  qk_collider_free(c);
  return st;
}

const qk_tree_t *qk_collider_tree(const qk_collider_t *c) { return c ? c->tree : NULL; }

size_t qk_collider_size(const qk_collider_t *c) { return c ? c->n : 0; }

/*
 * Visit every item whose shape overlaps q (whose bounding box is qb), descending only
 * into nodes whose item box meets qb. Items with id <= skip_upto are not reported (the
 * pair search uses it to report each pair once); pass -1 (as SIZE_MAX) for none.
 */
typedef int (*item_fn)(qk_id_t id, void *ud);

static int overlap_walk(const qk_collider_t *c, const shape_t *q, const qk_box_t *qb, size_t min_id,
                        item_fn fn, void *ud) {
  const qk_tree_t *t = c->tree;
  uint32_t stack[QK__STACK_MAX];
  int sp = 0;
  stack[sp++] = 0;
  while (sp > 0) {
    uint32_t node = stack[--sp];
    const qk__node_t *n = &t->nodes[node];
    if (n->count == 0 || !box_box(&c->nbox[node], qb)) continue;
    if (qk__is_leaf(n)) {
      const qk_id_t *pid = t->pid + n->start;
      for (uint32_t i = 0; i < n->count; i++) {
        qk_id_t id = pid[i];
        if (id < min_id || !box_box(&c->ibox[id], qb)) continue;
        shape_t s = item_shape(c, id);
        if (shapes_overlap(q, &s) && fn(id, ud)) return 1;
      }
    } else {
      for (int k = 3; k >= 0; k--) stack[sp++] = n->child + (uint32_t)k;
    }
  }
  return 0;
}

typedef struct found_ctx {
  const qk_collider_t *c;
  qk_found_fn fn;
  void *ud;
} found_ctx_t;

static int found_adapter(qk_id_t id, void *ud) {
  found_ctx_t *f = ud;
  qk_point_t p;
  qk_tree_point(f->c->tree, id, &p);
  return f->fn(id, p, 0.0, f->ud);
}

qk_status_t qk_collider_query_box(const qk_collider_t *c, qk_box_t box, qk_found_fn fn, void *ud) {
  if (!c || !fn) return QK_ERR_INVALID;
  if (isnan(box.xmin) || isnan(box.ymin) || isnan(box.xmax) || isnan(box.ymax))
    return QK_ERR_NONFINITE;
  if (box.xmin > box.xmax || box.ymin > box.ymax) return QK_ERR_GEOMETRY;
  shape_t q = {0, {0, 0, 0}, box};
  found_ctx_t f = {c, fn, ud};
  overlap_walk(c, &q, &box, 0, found_adapter, &f);
  return QK_OK;
}

qk_status_t qk_collider_query_disc(const qk_collider_t *c, qk_disc_t disc, qk_found_fn fn,
                                   void *ud) {
  if (!c || !fn) return QK_ERR_INVALID;
  if (!isfinite(disc.x) || !isfinite(disc.y) || !isfinite(disc.r)) return QK_ERR_NONFINITE;
  if (disc.r < 0) return QK_ERR_GEOMETRY;
  shape_t q = {1, disc, {0, 0, 0, 0}};
  qk_box_t qb = disc_bbox(&disc);
  found_ctx_t f = {c, fn, ud};
  overlap_walk(c, &q, &qb, 0, found_adapter, &f);
  return QK_OK;
}

typedef struct pair_ctx {
  qk_id_t a;
  qk_pair_fn fn;
  void *ud;
} pair_ctx_t;

static int pair_adapter(qk_id_t id, void *ud) {
  pair_ctx_t *p = ud;
  return p->fn(p->a, id, p->ud);
}

qk_status_t qk_collider_pairs(const qk_collider_t *c, qk_pair_fn fn, void *ud) {
  if (!c || !fn) return QK_ERR_INVALID;
  const qk_tree_t *t = c->tree;
  /* Take the items leaf by leaf, so that consecutive searches touch the same nodes. */
  uint32_t stack[QK__STACK_MAX];
  int sp = 0;
  stack[sp++] = 0;
  while (sp > 0) {
    const qk__node_t *n = &t->nodes[stack[--sp]];
    if (n->count == 0) continue;
    if (!qk__is_leaf(n)) {
      for (int k = 3; k >= 0; k--) stack[sp++] = n->child + (uint32_t)k;
      continue;
    }
    for (uint32_t i = 0; i < n->count; i++) {
      qk_id_t a = t->pid[n->start + i];
      shape_t s = item_shape(c, a);
      pair_ctx_t p = {a, fn, ud};
      if (overlap_walk(c, &s, &c->ibox[a], (size_t)a + 1, pair_adapter, &p)) return QK_OK;
    }
  }
  return QK_OK;
}

typedef struct list_ctx {
  qk_pair_t *out;
  size_t cap, n;
} list_ctx_t;

static int list_pair(qk_id_t a, qk_id_t b, void *ud) {
  list_ctx_t *l = ud;
  if (l->n < l->cap) {
    l->out[l->n].a = a;
    l->out[l->n].b = b;
  }
  l->n++;
  return 0;
}

static int pair_cmp(const void *x, const void *y) {
  const qk_pair_t *p = x, *q = y;
  if (p->a != q->a) return p->a < q->a ? -1 : 1;
  return (p->b > q->b) - (p->b < q->b);
}

qk_status_t qk_collider_pairs_list(const qk_collider_t *c, qk_pair_t *out, size_t cap,
                                   size_t *n_out) {
  if (!c || !n_out || (cap > 0 && !out)) return QK_ERR_INVALID;
  list_ctx_t l = {out, cap, 0};
  qk_collider_pairs(c, list_pair, &l);
  *n_out = l.n;
  /* Sorting only a prefix would mislead: sort what we wrote when it is all of them. */
  if (l.n <= cap && l.n > 1) qsort(out, l.n, sizeof *out, pair_cmp);
  return QK_OK;
}

/* ---------------------------------------------------------------------------------- */
/* Ray casting                                                                          */

/*
 * Slab test of the ray against a closed box: the parameter interval [lo, hi] within
 * [0, tmax] in which the ray is inside the box. Division (not a reciprocal) keeps a
 * zero numerator from turning into NaN for tiny direction components.
 */
static inline int slab(const qk_box_t *b, double ox, double oy, double dx, double dy, double tmax,
                       double *lo_out, double *hi_out) {
  double lo = 0.0, hi = tmax;
  if (dx != 0) {
    double t1 = (b->xmin - ox) / dx, t2 = (b->xmax - ox) / dx;
    if (t1 > t2) {
      double s = t1;
      t1 = t2;
      t2 = s;
    }
    if (t1 > lo) lo = t1;
    if (t2 < hi) hi = t2;
  } else if (ox < b->xmin || ox > b->xmax) {
    return 0;
  }
  if (dy != 0) {
    double t1 = (b->ymin - oy) / dy, t2 = (b->ymax - oy) / dy;
    if (t1 > t2) {
      double s = t1;
      t1 = t2;
      t2 = s;
    }
    if (t1 > lo) lo = t1;
    if (t2 < hi) hi = t2;
  } else if (oy < b->ymin || oy > b->ymax) {
    return 0;
  }
  *lo_out = lo;
  *hi_out = hi;
  return 1;
}

/*
 * First parameter t in [0, tmax] at which the ray meets a disc, or -1. The discriminant
 * is written as a r^2 - (f x d)^2 (Lagrange's identity) to avoid cancelling two large
 * squares, and the root as c / (-b + sqrt(disc)) to avoid cancelling -b and sqrt(disc).
 */
static inline double ray_disc(const qk_disc_t *d, double ox, double oy, double dx, double dy,
                              double tmax) {
  double fx = ox - d->x, fy = oy - d->y;
  double c = fx * fx + fy * fy - d->r * d->r;
  if (c <= 0) return 0.0;
  double b = fx * dx + fy * dy;
  if (b >= 0) return -1.0;
  double a = dx * dx + dy * dy, cr = fx * dy - fy * dx;
  double disc = a * d->r * d->r - cr * cr;
  if (disc < 0) return -1.0;
  double t = c / (-b + sqrt(disc));
  return t <= tmax ? t : -1.0;
}

static inline double ray_box(const qk_box_t *b, double ox, double oy, double dx, double dy,
                             double tmax) {
  double lo, hi;
  if (!slab(b, ox, oy, dx, dy, tmax, &lo, &hi) || lo > hi) return -1.0;
  return lo;
}

qk_status_t qk_collider_raycast(const qk_collider_t *c, qk_point_t o, qk_point_t d, double tmax,
                                qk_hit_t *hit) {
  if (!c || !hit) return QK_ERR_INVALID;
  hit->id = QK_NONE;
  hit->t = INFINITY;
  if (!isfinite(o.x) || !isfinite(o.y) || !isfinite(d.x) || !isfinite(d.y)) return QK_ERR_NONFINITE;
  if (isnan(tmax) || tmax < 0) return QK_ERR_INVALID;
  if (c->n == 0) return QK_OK;
  const qk_tree_t *t = c->tree;
  /*
   * Node boxes bound the items in space, but the parameters computed for a box and for
   * a disc round differently; widen each node's interval by a margin far above those
   * roundings (which scale with the coordinates over the direction's length).
   */
  double dn = fmax(fabs(d.x), fabs(d.y));
  double ts = dn > 0 ? (fabs(o.x) + fabs(o.y) + 2 * c->mag) * 0x1p-40 / dn : 0.0;
  double best = INFINITY;
  qk_id_t best_id = QK_NONE;
  qk__entry_t stack[QK__STACK_MAX];
  int sp = 0;
  double lo, hi;
  if (!slab(&c->nbox[0], o.x, o.y, d.x, d.y, tmax, &lo, &hi) || lo > hi + ts) return QK_OK;
  stack[sp].node = 0;
  stack[sp++].bound = lo - ts;
  while (sp > 0) {
    qk__entry_t e = stack[--sp];
    if (e.bound > best) continue;
    const qk__node_t *n = &t->nodes[e.node];
    if (qk__is_leaf(n)) {
      const qk_id_t *pid = t->pid + n->start;
      for (uint32_t i = 0; i < n->count; i++) {
        qk_id_t id = pid[i];
        double th = id < c->n_discs ? ray_disc(&c->discs[id], o.x, o.y, d.x, d.y, tmax)
                                    : ray_box(&c->boxes[id - c->n_discs], o.x, o.y, d.x, d.y, tmax);
        if (th >= 0 && (th < best || (th == best && id < best_id))) {
          best = th;
          best_id = id;
        }
      }
      continue;
    }
    qk__entry_t kids[4];
    int m = 0;
    for (uint32_t k = 0; k < 4; k++) {
      uint32_t ch = n->child + k;
      if (t->nodes[ch].count == 0) continue;
      if (!slab(&c->nbox[ch], o.x, o.y, d.x, d.y, tmax, &lo, &hi) || lo > hi + ts) continue;
      if (lo - ts > best) continue;
      kids[m].node = ch;
      kids[m++].bound = lo - ts;
    }
    qk__sort4_desc(kids, m);
    for (int i = 0; i < m; i++) stack[sp++] = kids[i];
  }
  hit->id = best_id;
  hit->t = best_id == QK_NONE ? INFINITY : best;
  return QK_OK;
}
