/*
 * Collision of items with extent. Discs and boxes are stored in a point-region quadtree
 * by their centres (ch. 14); since an item may stick out of the square of the leaf that
 * holds its centre, every node also keeps the bounding box of all items beneath it (the
 * quadtree analogue of an R-tree's node rectangle). A query then enters a node exactly
 * when that box meets the query, which widens each node's reach by just as much as its
 * largest item needs, and no more.
 */
#include <assert.h>
#include <float.h>
#include <stdatomic.h>
#include <stdlib.h>
#include <string.h>

#include "collide/collide_internal.h"
#include "index/inline.h"
#include "index/dist_exact.h"

#if defined(__SSE2__)
#include <emmintrin.h>
#endif

/*
 * The collider's own copy of each node: the bounding box of the items beneath it, in
 * floats rounded outwards (so still a bounding box), with the links the searches need.
 * 32 bytes, so the four children of a node fill two adjacent cache lines and a search
 * reads one place per level instead of the tree's node and a separate box array. An
 * empty node has a box at +infinity on every side, which every test rejects.
 */
typedef struct cnode {
  float xmin, ymin, xmax, ymax;
  uint32_t child; /* first of four children, or QK_NONE for a leaf */
  uint32_t start; /* a leaf's first slot */
  uint32_t count; /* a leaf's number of items */
  uint32_t quad;  /* an internal node's entry in quads (QK_NONE: none, or not prepared) */
} cnode_t;

/*
 * An internal node for the ray cast, as a compressed BVH4 stores it: the boxes of its four
 * children quantised to 8 bits per side against a grid of the node's own box, and where
 * each child leads, in one 64-byte line. A ray reads one line per node and nothing else
 * until the leaves (the cnode_t array is for the other searches and for the rays that the
 * float test does not take).
 *
 * The grid of an axis is lo + i * sc, i = 0 .. 255, with sc a power of two and lo a
 * multiple of sc whose quotient is below 2^23 in magnitude: every grid value is then a
 * float, and lo + i * sc computed in float is exact (the product scales by a power of two,
 * the sum is representable), whatever the rounding or contraction of the arithmetic. A
 * child's box is its cnode_t box rounded outwards to the grid (min down, max up), so it
 * still holds every item beneath, and the float test of fact (2) below applies to it as
 * to any float box. An empty child is a leaf of no items whose box is inverted (min at
 * the grid's top, max at its bottom), which rays all but always reject.
 *
 * sc is a normal float (grid_axis: 2^-126 at least) and a power of two, so its 23 bits of
 * mantissa are zero; they carry the entry's parent instead (qnode_parent: the high 23 bits
 * of its index in sc_x's, the low 9 in sc_y's; QK_NONE for the root), and the float test
 * masks them off (qnode_slab_float). A climb of the cast then reads its next node's index
 * from the line of the node it has just searched, instead of from a separate array of
 * parents (0.41 first-level and 0.24 second-level misses a ray at 10^6 discs, and a
 * mispredicted branch 0.35 times a ray, for the climbs above the start table's parent).
 */
typedef struct qnode {
  float h[4];    /* lo and sc per axis: lo_x, lo_y, sc_x, sc_y (sc's mantissas: the parent) */
  uint8_t q[16]; /* child k: xmin at QX0 + k, ymin at QY0 + k, xmax at QX1 + k, ymax at QY1 + k */
  uint32_t link[4];  /* child k: its entry in quads when internal, else its first slot */
  uint32_t count[4]; /* child k: QK_NONE when internal, else its number of items */
} qnode_t;

enum { QX0 = 0, QY0 = 4, QX1 = 8, QY1 = 12 };

/* The mantissa of a float, which sc leaves free (see qnode_t). */
#define QK__MANT 0x7FFFFFu

/* Stores p as the entry's parent in the mantissas of sc (set before, with no mantissa). */
static inline void qnode_set_parent(qnode_t *q, uint32_t p) {
  uint32_t bx, by;
  memcpy(&bx, &q->h[2], sizeof bx);
  memcpy(&by, &q->h[3], sizeof by);
  bx |= p >> 9, by |= p & 0x1FFu;
  memcpy(&q->h[2], &bx, sizeof bx);
  memcpy(&q->h[3], &by, sizeof by);
}

/* The entry's parent in quads (QK_NONE for the root's entry). */
static inline uint32_t qnode_parent(const qnode_t *q) {
  uint32_t bx, by;
  memcpy(&bx, &q->h[2], sizeof bx);
  memcpy(&by, &q->h[3], sizeof by);
  return (bx & QK__MANT) << 9 | (by & 0x1FFu);
}

/* The entries after the start table's node that the cast asks for with it (cast_float):
 * at 10^6 discs 6 lines beat 4 and 2 by the clock (the subtree holds about 5.5). The
 * array has as many spare entries at its end, so that no index needs a bound. */
#define QK__RAY_SUBTREE_LINES 6

/* The ray arrays' size (entries and item records) from which the cast asks for lines
 * ahead (prefetch_climbs, the start's subtree): below it they mostly sit in a
 * second-level cache, where the asking costs more than it saves (10^4 discs, 0.7 MB:
 * 4% slower by the clock; 10^5, 6.7 MB: 3% faster; 10^6: 15-20% faster). */
#define QK__RAY_PREFETCH_BYTES ((size_t)2 << 20)

/*
 * The children sit in a qnode_t's lanes in Z order, lane = 2 * north + east (SW, SE, NW,
 * NE), so that the order in which a ray meets the four squares is lane ^ s for a ray with
 * s = (dx < 0) + 2 (dy < 0): nearest first, as a BVH orders its children per octant.
 */
static const uint32_t lane_quadrant[4] = {QK_SW, QK_SE, QK_NW, QK_NE};

/*
 * A disc as the collider keeps it: with its id beside it, 32 bytes, two to a cache line, so
 * that a leaf's scan reads its discs' lines and nothing else (the tree's id array would
 * be one more miss per leaf).
 */
typedef struct sdisc {
  qk_disc_t d;
  qk_id_t id;
  uint32_t pad;
} sdisc_t;
_Static_assert(sizeof(sdisc_t) == 32 && sizeof(qk_box_t) == 32,
               "the ray cast's prefetch of a stacked leaf takes 32 bytes a slot");

/*
 * Item data is kept in the tree's slot order (parallel to the tree's point arrays), not by id, so
 * that scanning a leaf reads consecutive memory instead of jumping to each item's id: for large
 * sets that is what the scans cost.
 */
enum { RAYS_NONE = 0, RAYS_BUSY = 1, RAYS_READY = 2 };

struct qk_collider {
  qk_allocator_t alloc;
  qk_tree_t *tree;
  size_t n_discs, n;
  size_t n_slots;    /* slots in use (the tree's slot bound, at least 1) */
  size_t sbox_cap;   /* slots sbox has room for (qk_collider_rebuild keeps it) */
  qk_box_t *sbox;    /* per slot: the item's box, or a disc's (padded) bounding box */
  sdisc_t *sdisc;    /* per slot: the disc and its id (NULL without discs), 64-byte aligned */
  void *sdisc_block; /* the allocation holding sdisc (kept by a rebuild without discs) */
  size_t sdisc_bytes;
  qk_point_t *centres; /* kept by qk_collider_rebuild for the next one (NULL: none) */
  size_t centres_cap;
  cnode_t *cn;    /* per node id: see cnode_t */
  void *cn_block; /* the allocation holding cn (aligned inside it) */
  size_t cn_bytes;
  size_t n_nodes;
  /* The ray cast's structures, made on first need (qk_collider_prepare_rays): rays_state
   * RAYS_NONE, RAYS_BUSY while one thread makes them, RAYS_READY once they are made (the
   * other fields below are then set, and read only after an acquire load of it). */
  atomic_int rays_state;
  qnode_t *quads;    /* per internal node (cnode_t::quad), 64-byte aligned; NULL past 2^100 */
  void *quads_block; /* the allocation holding quads */
  size_t quads_bytes;
  uint32_t n_quads; /* entries filled */
  uint32_t *ztab;   /* the ray cast's start table, two words a cell (see fill_ztab); NULL: none */
  size_t ztab_bytes;
  unsigned zdepth;  /* its depth: 4^zdepth cells */
  int ray_prefetch; /* the cast asks for the lines of its likely next reads (see below) */
  uint32_t threads; /* for the pairs and batch calls (0: every online core) */
  double mag;       /* largest coordinate magnitude of any item box, for rounding margins */
  int tiny_discs;   /* some disc's box lies within NEAR_COORD of the origin (the ray cast) */
  double reach;     /* farthest any item box reaches from its centre on an axis (the ray cast) */
  /* The ray cast's start (cast_float), from the root square, computed once: its corner,
   * 2^32 / side (NaN when side <= 2^-900: no local start), and the fixed part of the
   * climb check's margin. */
  double rs_x, rs_y, rs_f, rs_k;
};

/* Exact overlap predicates (touching counts): the squares in doubles decide unless the
 * distance is within a relative 2^-45 of the radii's sum (index/dist_exact.h), where the
 * exact test does, for any finite values. A radius outside [2^-400, 2^400] scales the
 * differences by a power of two first (qk__radius_scale): unscaled, squares below about
 * 1e-154 underflowed and radii from 2^500 on left the filter's range, and every pair went
 * to the exact test (pairs_list of 32,000 discs 3.5 s at scales 1e-200 and 1e200 against
 * 2 ms at 1; fifty-sixth session). */
static inline int disc_disc(const qk_disc_t *a, const qk_disc_t *b) {
  double dx = a->x - b->x, dy = a->y - b->y, rs = a->r + b->r;
  if (!(rs >= 0x1p-400 && rs <= 0x1p400)) { /* the squares scaled (qk__radius_scale) */
    const double sc = qk__radius_scale(rs);
    dx *= sc, dy *= sc, rs *= sc;
  }
  double d2 = dx * dx + dy * dy, r2 = rs * rs;
  if (d2 > qk__filter_hi(r2)) return 0;
  return d2 <= qk__filter_lo(r2) || qk__within_exact(a->x, a->y, b->x, b->y, a->r, b->r);
}

static inline int box_box(const qk_box_t *a, const qk_box_t *b) {
  return a->xmin <= b->xmax && b->xmin <= a->xmax && a->ymin <= b->ymax && b->ymin <= a->ymax;
}

static inline int disc_box(const qk_disc_t *d, const qk_box_t *b) {
  double px = d->x < b->xmin ? b->xmin : (d->x > b->xmax ? b->xmax : d->x);
  double py = d->y < b->ymin ? b->ymin : (d->y > b->ymax ? b->ymax : d->y);
  double dx = d->x - px, dy = d->y - py, rs = d->r;
  if (!(rs >= 0x1p-400 && rs <= 0x1p400)) { /* as disc_disc */
    const double sc = qk__radius_scale(rs);
    dx *= sc, dy *= sc, rs *= sc;
  }
  double d2 = dx * dx + dy * dy, r2 = rs * rs;
  if (d2 > qk__filter_hi(r2)) return 0;
  return d2 <= qk__filter_lo(r2) || qk__within_exact(d->x, d->y, px, py, d->r, 0);
}

/* A query shape or an item: a disc or a box. */
typedef struct shape {
  int is_disc;
  qk_disc_t d;
  qk_box_t b;
} shape_t;

static inline shape_t slot_shape(const qk_collider_t *c, uint32_t slot) {
  shape_t s;
  s.is_disc = qk__tree_ids(c->tree)[slot] < c->n_discs;
  if (s.is_disc)
    s.d = c->sdisc[slot].d;
  else
    s.b = c->sbox[slot];
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

/* The next float above / below a finite f (what nextafterf does, without the call: the
 * ray cast rounds its constants with these once per ray). */
static inline float float_up(float f) {
  if (f == 0) return 0x1p-149f;
  uint32_t b;
  memcpy(&b, &f, sizeof b);
  b = f > 0 ? b + 1 : b - 1;
  memcpy(&f, &b, sizeof f);
  return f;
}

static inline float float_down(float f) { return -float_up(-f); }

/* Round outwards to float; out-of-range values go to the largest float or infinity
 * (converting them directly would be undefined). */
static inline float round_down(double v) {
  if (v > FLT_MAX) return FLT_MAX;
  if (v < -FLT_MAX) return -INFINITY;
  float f = (float)v;
  return (double)f > v ? float_down(f) : f;
}

static inline float round_up(double v) {
  if (v > FLT_MAX) return INFINITY;
  if (v < -FLT_MAX) return -FLT_MAX;
  float f = (float)v;
  return (double)f < v ? float_up(f) : f;
}

/* round_up for a parameter t >= 0 (or +infinity), without the branches for negative
 * values: the next float above is the next bit pattern. The step up is added as the
 * comparison's 0 or 1, not under a branch: whether the conversion rounded down is a coin
 * toss (0.44 mispredicted branches a ray at 10^6 discs, as the ray cast calls it). */
static inline float round_up_t(double t) {
  if (!(t <= FLT_MAX)) return INFINITY;
  float f = (float)t;
  uint32_t b;
  memcpy(&b, &f, sizeof b);
  b += (uint32_t)((double)f < t);
  memcpy(&f, &b, sizeof f);
  return f;
}

/* A node's float box: b rounded outwards, or an inverted box for an empty node. */
static void set_float_box(cnode_t *cn, uint32_t count, const qk_box_t *b) {
  if (count == 0) {
    cn->xmin = cn->ymin = cn->xmax = cn->ymax = INFINITY;
  } else {
    cn->xmin = round_down(b->xmin);
    cn->ymin = round_down(b->ymin);
    cn->xmax = round_up(b->xmax);
    cn->ymax = round_up(b->ymax);
  }
}

/* Post-order: a node's box is the union of its children's (or its items'). Recursion
 * depth is bounded by the tree's depth cap. */
static qk_box_t fill_node_boxes(qk_collider_t *c, uint32_t node) {
  const qk_tree_t *t = c->tree;
  cnode_t *cn = &c->cn[node];
  qk_box_t b = {INFINITY, INFINITY, -INFINITY, -INFINITY};
  const int leaf = qk__node_leaf(t, node);
  const uint32_t start = qk__node_start(t, node), count = qk__node_count(t, node);
  cn->child = qk__node_child(t, node);
  cn->start = start;
  cn->count = leaf ? count : 0;
  cn->quad = QK_NONE;
  if (leaf) {
    for (uint32_t i = 0; i < count; i++) box_union(&b, &c->sbox[start + i]);
  } else {
    for (uint32_t k = 0; k < 4; k++) {
      qk_box_t cb = fill_node_boxes(c, cn->child + k);
      box_union(&b, &cb);
    }
  }
  set_float_box(cn, count, &b);
  return b; /* for an empty node the inverted box, which leaves a union unchanged */
}

/* The grid of one axis for a node's box [pmin, pmax] (finite floats, below 2^102 in
 * magnitude): the least power of two sc at which the box spans at most 255 steps and
 * lo = floor(pmin / sc) sc has a quotient below 2^23 (see qnode_t). The divisions by sc
 * are exact. */
static void grid_axis(double pmin, double pmax, float *lo, float *sc) {
  /* From the power of two just below what either condition needs (no smaller step can
   * meet both), so that the loop runs once or twice. */
  const double need = qk__max((pmax - pmin) / 255, qk__max(fabs(pmin), fabs(pmax)) * 0x1p-23);
  int ex;
  (void)frexp(need, &ex);
  double s = qk__max(ldexp(1.0, ex - 1), 0x1p-126), a, b;
  for (;;) {
    a = floor(pmin / s), b = ceil(pmax / s);
    if (b - a <= 255 && fabs(a) <= 0x1p23 && fabs(b) <= 0x1p23) break;
    s *= 2;
  }
  *lo = (float)(a * s);
  *sc = (float)s;
}

/* The side v (a float) in grid steps from lo, rounded down or up: exact, as above. */
static uint8_t grid_step(double v, double lo, double sc, int up) {
  double i = (up ? ceil(v / sc) : floor(v / sc)) - lo / sc;
  return (uint8_t)(i < 0 ? 0 : i > 255 ? 255 : i);
}

/* Pre-order: an internal node's qnode_t, then those of its internal children, so that a
 * descent mostly moves forward in memory. Returns the node's entry in quads. */
/* The subtrees that a threaded build fills in parallel (see fill_boxes and fill_quads). */
#define SPLIT_DEPTH 3
#define SPLIT_MAX 64 /* 4^SPLIT_DEPTH */
typedef struct split {
  uint32_t node[SPLIT_MAX];  /* roots: the nodes at SPLIT_DEPTH and shallower leaves */
  uint32_t n_int[SPLIT_MAX]; /* their internal non-empty nodes (qnode_t entries: count_quads) */
  uint32_t base[SPLIT_MAX];  /* their first entry in quads */
  uint32_t up[SPLIT_MAX];    /* their parents' entries in quads */
  qk_box_t box[SPLIT_MAX];   /* their item boxes, unrounded */
  unsigned n, iter;
  qk_collider_t *c;
} split_t;

static uint32_t fill_qnodes(qk_collider_t *c, uint32_t node, uint32_t parent, uint32_t *next,
                            split_t *sp, unsigned depth) {
  cnode_t *cn = &c->cn[node];
  const uint32_t idx = (*next)++;
  qnode_t *q = &c->quads[idx];
  float lo[2], sc[2];
  grid_axis(cn->xmin, cn->xmax, &lo[0], &sc[0]);
  grid_axis(cn->ymin, cn->ymax, &lo[1], &sc[1]);
  q->h[0] = lo[0], q->h[1] = lo[1], q->h[2] = sc[0], q->h[3] = sc[1];
  qnode_set_parent(q, parent);
  cn->quad = idx;
  for (uint32_t k = 0; k < 4; k++) {
    const uint32_t child = cn->child + lane_quadrant[k];
    const cnode_t *ch = &c->cn[child];
    if (ch->xmin == INFINITY) { /* empty: inverted, no items */
      q->q[QX0 + k] = q->q[QY0 + k] = 255;
      q->q[QX1 + k] = q->q[QY1 + k] = 0;
      q->link[k] = 0;
      q->count[k] = 0;
      continue;
    }
    q->q[QX0 + k] = grid_step(ch->xmin, lo[0], sc[0], 0);
    q->q[QY0 + k] = grid_step(ch->ymin, lo[1], sc[1], 0);
    q->q[QX1 + k] = grid_step(ch->xmax, lo[0], sc[0], 1);
    q->q[QY1 + k] = grid_step(ch->ymax, lo[1], sc[1], 1);
    if (ch->child != QK_NONE) {
      q->count[k] = QK_NONE;
      if (sp && depth + 1 == SPLIT_DEPTH) { /* a subtree filled later, on its own thread */
        unsigned i = 0;
        while (sp->node[i] != child) i++;
        sp->base[i] = *next;
        sp->up[i] = idx;
        *next += sp->n_int[i];
        q->link[k] = sp->base[i];
      } else { /* q stays valid: quads is never moved */
        q->link[k] = fill_qnodes(c, child, idx, next, sp, depth + 1);
      }
    } else {
      q->link[k] = ch->start;
      q->count[k] = ch->count;
    }
  }
  return idx;
}

/* The roots of the parallel subtrees, in the order of the children (post-order top). */
static void split_roots(qk_collider_t *c, uint32_t node, unsigned depth, split_t *sp) {
  const qk_tree_t *t = c->tree;
  if (depth == SPLIT_DEPTH || qk__node_leaf(t, node)) {
    sp->node[sp->n] = node;
    sp->n_int[sp->n] = 0;
    sp->n++;
    return;
  }
  for (uint32_t k = 0; k < 4; k++) split_roots(c, qk__node_child(t, node) + k, depth + 1, sp);
}

/* fill_node_boxes above the roots, whose boxes are in sp (visited in split_roots' order). */
static qk_box_t fill_top_boxes(qk_collider_t *c, uint32_t node, unsigned depth, split_t *sp) {
  const qk_tree_t *t = c->tree;
  if (depth == SPLIT_DEPTH || qk__node_leaf(t, node)) return sp->box[sp->iter++];
  cnode_t *cn = &c->cn[node];
  qk_box_t b = {INFINITY, INFINITY, -INFINITY, -INFINITY};
  const uint32_t count = qk__node_count(t, node);
  cn->child = qk__node_child(t, node);
  cn->start = qk__node_start(t, node);
  cn->count = 0;
  cn->quad = QK_NONE;
  for (uint32_t k = 0; k < 4; k++) {
    qk_box_t cb = fill_top_boxes(c, cn->child + k, depth + 1, sp);
    box_union(&b, &cb);
  }
  set_float_box(cn, count, &b);
  return b;
}

static void boxes_job(unsigned i, void *ud) {
  split_t *sp = ud;
  sp->box[i] = fill_node_boxes(sp->c, sp->node[i]);
}

/*
 * The node boxes, on the build's threads: the subtrees below SPLIT_DEPTH are independent
 * (each writes its own nodes' boxes), so they are filled in parallel, the levels above
 * them by the calling thread. The arrays are the same whatever the threads.
 */
static void fill_boxes(qk_collider_t *c, unsigned threads) {
  split_t *sp = NULL;
  if (threads > 1) sp = qk__realloc(&c->alloc, NULL, 0, sizeof *sp);
  if (!sp) { /* one thread (or no memory for the plan: the same arrays, serially) */
    fill_node_boxes(c, 0);
    return;
  }
  sp->n = sp->iter = 0;
  sp->c = c;
  split_roots(c, 0, 0, sp);
  qk__run_jobs(threads, sp->n, boxes_job, sp);
  fill_top_boxes(c, 0, 0, sp);
  qk__free(&c->alloc, sp, sizeof *sp);
}

/* The internal non-empty nodes of a subtree: its qnode_t entries. Recursion depth is
 * bounded by the tree's depth cap. */
static uint32_t count_quads(const qk_collider_t *c, uint32_t node) {
  const cnode_t *cn = &c->cn[node];
  if (cn->child == QK_NONE || cn->xmin == INFINITY) return 0;
  uint32_t n = 1;
  for (uint32_t k = 0; k < 4; k++) n += count_quads(c, cn->child + k);
  return n;
}

static void count_job(unsigned i, void *ud) {
  split_t *sp = ud;
  sp->n_int[i] = count_quads(sp->c, sp->node[i]);
}

static void quads_job(unsigned i, void *ud) {
  split_t *sp = ud;
  const cnode_t *cn = &sp->c->cn[sp->node[i]];
  if (cn->child == QK_NONE || cn->xmin == INFINITY) return; /* no entries (nor a base) */
  uint32_t next = sp->base[i];
  fill_qnodes(sp->c, sp->node[i], sp->up[i], &next, NULL, SPLIT_DEPTH);
}

/*
 * The ray cast's nodes from the node boxes, on `threads` threads: as for the boxes, the
 * subtrees below SPLIT_DEPTH are filled in parallel and the levels above them by the
 * calling thread. The entries are numbered as the one-thread pre-order numbers them (each
 * subtree's count is taken first), so the array is the same whatever the threads.
 */
static void fill_quads(qk_collider_t *c, unsigned threads) {
  if (c->cn[0].child == QK_NONE || c->cn[0].xmin == INFINITY) return;
  split_t *sp = NULL;
  if (threads > 1) sp = qk__realloc(&c->alloc, NULL, 0, sizeof *sp);
  if (!sp) { /* one thread (or no memory for the plan: the same array, serially) */
    fill_qnodes(c, 0, QK_NONE, &c->n_quads, NULL, 0);
    return;
  }
  sp->n = sp->iter = 0;
  sp->c = c;
  split_roots(c, 0, 0, sp);
  if (sp->n == 1) { /* the root is the only subtree */
    fill_qnodes(c, 0, QK_NONE, &c->n_quads, NULL, 0);
  } else {
    qk__run_jobs(threads, sp->n, count_job, sp);
    fill_qnodes(c, 0, QK_NONE, &c->n_quads, sp, 0);
    qk__run_jobs(threads, sp->n, quads_job, sp);
  }
  qk__free(&c->alloc, sp, sizeof *sp);
}

/*
 * The ray cast's start table. A ray first descends from the root to the deepest internal
 * node on its origin's path, by the bits of the origin's position alone (cast_float); the
 * first zdepth levels of that descent depend only on the top 2 zdepth bits of the
 * origin's Morton code, so they are done once here for each of the 4^zdepth codes. Cell z
 * holds the descent's node after at most zdepth levels (word 2 z: the quads entry, times
 * 64, plus its depth) and that node's parent (word 2 z + 1; QK_NONE for the root). A ray
 * then starts at most a couple of levels above its leaf with one load from a small table
 * instead of zdepth dependent loads of nodes; the search starts at the deepest internal
 * node, at or below the cell's node, and the parent in the same line is the node of the
 * first climb when the search starts at the cell's node (asked for with the cell).
 */
#define ZTAB_DEPTH_MAX 9
#define ZTAB_DEPTH_BITS 6

static void fill_ztab(qk_collider_t *c, uint32_t q, unsigned depth, uint32_t prefix) {
  const unsigned zd = c->zdepth;
  const qnode_t *qn = &c->quads[q];
  for (uint32_t k = 0; k < 4; k++) {
    const uint32_t p = prefix << 2 | k; /* the lane is the Morton digit (2 north + east) */
    if (qn->count[k] == QK_NONE) {
      if (depth + 1 < zd) {
        fill_ztab(c, qn->link[k], depth + 1, p);
      } else { /* depth + 1 == zd: the child is the cell's node */
        c->ztab[2 * p] = qn->link[k] << ZTAB_DEPTH_BITS | (depth + 1);
        c->ztab[2 * p + 1] = q;
      }
    } else { /* a leaf or an empty child: the descent stops at q in all cells below p */
      const unsigned sh = 2 * (zd - depth - 1);
      const uint32_t up = qnode_parent(qn);
      for (uint32_t z = p << sh; z < (p + 1) << sh; z++) {
        c->ztab[2 * z] = q << ZTAB_DEPTH_BITS | depth;
        c->ztab[2 * z + 1] = up;
      }
    }
  }
}

/* The table's size: about one cell per sixteen internal nodes (4^(zdepth + 2) <= n_quads),
 * so that it costs 1/128 of the quads' memory or less (128 KiB at 10^6 discs) and stays
 * in a second-level cache: a table four times larger saves the rays one level of descent
 * through entries that are mostly cached, but misses that cache more often (under
 * callgrind with a 1 MiB second level, 0.7 more misses a ray at 10^6 discs, for 12 fewer
 * instructions). None for small trees (the descent is short) or when the entries would
 * not fit the packing. */
static qk_status_t build_ztab(qk_collider_t *c) {
  unsigned zd = 0;
  while (zd < ZTAB_DEPTH_MAX && (4ull << 2 * (zd + 1)) <= c->n_quads) zd++;
  if (zd < 2 || c->n_quads >= 1u << (32 - ZTAB_DEPTH_BITS)) return QK_OK;
  c->ztab_bytes = ((size_t)2 << 2 * zd) * sizeof *c->ztab;
  c->ztab = qk__realloc(&c->alloc, NULL, 0, c->ztab_bytes);
  if (!c->ztab) return QK_ERR_NOMEM; /* qk_collider_free releases what was made */
  c->zdepth = zd;
  fill_ztab(c, c->cn[0].quad, 0, 0);
  return QK_OK;
}

/* Does a node's box meet a closed box? */
static inline int cbox_box(const cnode_t *n, const qk_box_t *b) {
  return n->xmin <= b->xmax && b->xmin <= n->xmax && n->ymin <= b->ymax && b->ymin <= n->ymax;
}

/* Free the ray cast's structures (all, or what a failed preparation made) and forget them. */
static void free_rays(qk_collider_t *c) {
  qk__free(&c->alloc, c->quads_block, c->quads_bytes);
  qk__free(&c->alloc, c->ztab, c->ztab_bytes);
  c->quads_block = NULL, c->quads = NULL, c->quads_bytes = 0, c->n_quads = 0;
  c->ztab = NULL, c->ztab_bytes = 0, c->zdepth = 0;
}

void qk_collider_free(qk_collider_t *c) {
  if (!c) return;
  qk_allocator_t a = c->alloc;
  free_rays(c);
  qk__free(&a, c->sbox, c->sbox_cap * sizeof *c->sbox);
  qk__free(&a, c->sdisc_block, c->sdisc_bytes);
  qk__free(&a, c->cn_block, c->cn_bytes);
  qk__free(&a, c->centres, c->centres_cap * sizeof *c->centres);
  qk_tree_free(c->tree);
  qk__free(&a, c, sizeof *c);
}

/* Phase 1: the inputs are finite, radii non-negative and boxes not inverted. */
/* The check of one item: discs [0, n_discs), then boxes. */
static inline qk_status_t item_status(const qk_disc_t *discs, size_t n_discs, const qk_box_t *boxes,
                                      size_t i) {
  if (i < n_discs) {
    const qk_disc_t *d = &discs[i];
    if (!isfinite(d->x) || !isfinite(d->y) || !isfinite(d->r)) return QK_ERR_NONFINITE;
    return d->r < 0 ? QK_ERR_GEOMETRY : QK_OK;
  }
  const qk_box_t *b = &boxes[i - n_discs];
  if (!isfinite(b->xmin) || !isfinite(b->ymin) || !isfinite(b->xmax) || !isfinite(b->ymax))
    return QK_ERR_NONFINITE;
  return b->xmin > b->xmax || b->ymin > b->ymax ? QK_ERR_GEOMETRY : QK_OK;
}

#define CHECK_JOBS_PER_THREAD 4
#define CHECK_PAR_MIN 4096

typedef struct check_ctx {
  const qk_disc_t *discs;
  const qk_box_t *boxes;
  size_t n_discs, n, n_jobs;
  qk_status_t st[QK__MAX_THREADS * CHECK_JOBS_PER_THREAD]; /* per job: its first item's */
} check_ctx_t;

static void check_job(unsigned j, void *ud) {
  check_ctx_t *x = ud;
  const size_t lo = x->n * j / x->n_jobs, hi = x->n * (j + 1) / x->n_jobs;
  x->st[j] = QK_OK;
  for (size_t i = lo; i < hi && x->st[j] == QK_OK; i++)
    x->st[j] = item_status(x->discs, x->n_discs, x->boxes, i);
}

/* Phase 1: the inputs are finite, radii non-negative and boxes not inverted; the first
 * failing item's status, on `threads` threads for large sets (ranges in item order, so
 * the lowest failing range holds the first failing item). */
static qk_status_t check_items(const qk_disc_t *discs, size_t n_discs, const qk_box_t *boxes,
                               size_t n_boxes, uint32_t threads_opt) {
  if ((n_discs > 0 && !discs) || (n_boxes > 0 && !boxes)) return QK_ERR_INVALID;
  if (n_discs > QK_MAX_POINTS || n_boxes > QK_MAX_POINTS - n_discs) return QK_ERR_LIMIT;
  check_ctx_t x;
  x.discs = discs, x.boxes = boxes, x.n_discs = n_discs, x.n = n_discs + n_boxes;
  unsigned threads = qk__threads_resolve(threads_opt);
  if (threads > QK__MAX_THREADS) threads = QK__MAX_THREADS;
  if (x.n < CHECK_PAR_MIN) threads = 1;
  x.n_jobs = threads > 1 ? (size_t)threads * CHECK_JOBS_PER_THREAD : 1;
  qk__run_jobs(threads, (unsigned)x.n_jobs, check_job, &x);
  for (size_t j = 0; j < x.n_jobs; j++)
    if (x.st[j] != QK_OK) return x.st[j];
  return QK_OK;
}

/* Jobs per thread of the build's linear passes (static shares: a few per thread even out
 * their pages' first touches), and the smallest set worth threads. */
#define RANGE_JOBS_PER_THREAD 4
#define RANGE_PAR_MIN 4096

/* The ray cast's disc test in scaled coordinates (ray_disc_scaled): for an origin or a disc
 * beyond FAR_COORD in magnitude, whose squares could overflow, and for an origin and a disc
 * all within NEAR_COORD of the origin, whose squares could underflow. */
#define FAR_COORD 0x1p400
#define NEAR_COORD 0x1p-400

/* A linear pass of the build over [0, n) in n_jobs ranges; each returns a maximum. */
typedef struct range_ctx {
  qk_collider_t *c;
  const qk_disc_t *discs;
  const qk_box_t *boxes;
  size_t n_discs;        /* discs are items [0, n_discs) */
  qk_point_t *centres;   /* build_centre_tree's output */
  const uint32_t *where; /* fill_slots' id map (ids_range) */
  atomic_int tiny;       /* centres_range: a disc's box within NEAR_COORD of the origin */
  size_t n, n_jobs;
  double (*fn)(struct range_ctx *x, size_t lo, size_t hi);
  double max[QK__MAX_THREADS * RANGE_JOBS_PER_THREAD];
} range_ctx_t;

static void range_job(unsigned i, void *ud) {
  range_ctx_t *x = ud;
  x->max[i] = x->fn(x, x->n * i / x->n_jobs, x->n * (i + 1) / x->n_jobs);
}

/* fn over [0, n) on the collider's threads; the largest of its results (or 0). Each range
 * writes only its own entries, so the arrays are those of one thread. */
static double run_ranges(range_ctx_t *x, size_t n, double (*fn)(range_ctx_t *, size_t, size_t)) {
  unsigned threads = qk__threads_resolve(x->c->threads);
  if (threads > QK__MAX_THREADS) threads = QK__MAX_THREADS;
  if (n < RANGE_PAR_MIN) threads = 1;
  x->n = n;
  x->fn = fn;
  x->n_jobs = threads > 1 ? (size_t)threads * RANGE_JOBS_PER_THREAD : 1;
  qk__run_jobs(threads, (unsigned)x->n_jobs, range_job, x);
  double m = 0;
  for (size_t i = 0; i < x->n_jobs; i++) m = qk__max(m, x->max[i]);
  return m;
}

/* Items [lo, hi): their centres; the largest coordinate magnitude of their boxes (and
 * x->tiny set when a disc's box lies within NEAR_COORD of the origin). */
static double centres_range(range_ctx_t *x, size_t lo, size_t hi) {
  const size_t n_discs = x->n_discs;
  double mag = 0;
  int tiny = 0;
  for (size_t i = lo; i < hi; i++) {
    qk_box_t bb;
    if (i < n_discs) {
      bb = disc_bbox(&x->discs[i]);
      x->centres[i].x = x->discs[i].x;
      x->centres[i].y = x->discs[i].y;
    } else {
      bb = x->boxes[i - n_discs];
      /* Halves first, so that the sum cannot overflow. */
      x->centres[i].x = 0.5 * bb.xmin + 0.5 * bb.xmax;
      x->centres[i].y = 0.5 * bb.ymin + 0.5 * bb.ymax;
    }
    const double m =
        qk__max(qk__max(fabs(bb.xmin), fabs(bb.xmax)), qk__max(fabs(bb.ymin), fabs(bb.ymax)));
    mag = qk__max(mag, m);
    tiny |= i < n_discs && m < NEAR_COORD;
  }
  if (tiny) atomic_store_explicit(&x->tiny, 1, memory_order_relaxed);
  return mag;
}

/* A block of `need` bytes at *block, holding `*have` bytes: kept when large enough, else
 * replaced by a new one (the old contents are not needed). The new block is had before
 * the old one goes, so that on failure the old one stays. Returns whether it was newly
 * made, or -1 on failure. */
static int grow_block(const qk_allocator_t *a, void **block, size_t *have, size_t need) {
  if (*block && *have >= need) return 0;
  void *b = qk__realloc(a, NULL, 0, need);
  if (!b) return -1;
  qk__free(a, *block, *have);
  *block = b, *have = need;
  return 1;
}

/* Phase 2: the tree of the centres of n items, the first n_discs of them discs (ids in
 * input order, discs first): built afresh, or c's tree rebuilt when opt is NULL (the
 * centres then in a block the collider keeps for the next rebuild: a block borrowed per
 * call may be given back to the system by the C library and faulted in again); the
 * largest coordinate magnitude of any item box to *mag, and to *tiny whether some disc's
 * box lies within NEAR_COORD of the origin. On an error other than QK_ERR_NOMEM a rebuilt
 * tree is as it was. */
static qk_status_t build_centre_tree(qk_collider_t *c, const qk_disc_t *discs, size_t n_discs,
                                     const qk_box_t *boxes, size_t n, const qk_tree_options_t *opt,
                                     double *mag, int *tiny) {
  qk_point_t *centres = NULL;
  if (opt) {
    if (n) centres = qk__realloc(&c->alloc, NULL, 0, n * sizeof *centres);
    if (n && !centres) return QK_ERR_NOMEM;
    qk__advise_huge(&c->alloc, centres, n * sizeof *centres); /* see alloc_arrays */
  } else { /* a rebuild keeps them for the next one */
    void *block = c->centres;
    size_t bytes = c->centres_cap * sizeof *c->centres;
    if (grow_block(&c->alloc, &block, &bytes, (n ? n : 1) * sizeof *centres) < 0)
      return QK_ERR_NOMEM;
    c->centres = centres = block, c->centres_cap = bytes / sizeof *centres;
  }
  range_ctx_t x;
  x.c = c, x.discs = discs, x.boxes = boxes, x.n_discs = n_discs, x.centres = centres;
  x.where = NULL;
  atomic_init(&x.tiny, 0);
  *mag = run_ranges(&x, n, centres_range);
  *tiny = atomic_load_explicit(&x.tiny, memory_order_relaxed);
  qk_status_t st =
      opt ? qk_tree_build(centres, n, opt, &c->tree) : qk_tree_rebuild(c->tree, centres, n, NULL);
  if (opt) qk__free(&c->alloc, centres, n * sizeof *centres);
  return st;
}

/* Phase 3: the per-slot item arrays and the node array, sized from the tree; those of an
 * earlier build are kept when large enough (qk_collider_rebuild). On failure every array
 * the collider had is still there. */
static qk_status_t alloc_arrays(qk_collider_t *c) {
  const qk_allocator_t *a = &c->alloc;
  /* Sizes of at least one, so that every array exists even for an empty set. */
  uint32_t slots = qk__tree_slot_bound(c->tree), nodes = qk__tree_node_bound(c->tree);
  const size_t n_slots = slots ? slots : 1, n_nodes = nodes ? nodes : 1;
  /* Every large array is advised for transparent huge pages before its first touch, so
   * that its pages are huge from the start, whatever the options' hint (as Embree
   * advises its BVH on Linux): the collider's arrays are made anew by every build, and
   * glibc gives blocks of this size back to the system when they are freed, so that
   * each fresh build faulted them in 4 KiB at a time, at 15-20 us a fault on the machine
   * of this work (10^6 boxes: 19,100 faults and 290 ms a build, against 4,800 and 130-150
   * ms advised; 10^7: 3.3-3.9 s against 1.1-1.5 s; docs/collide.md). A ray jumps across
   * the disc records and the ray entries (prepare_rays), one or two lines per 4 KiB
   * page, and misses the TLB far less on huge pages (10^6 discs: some 14 % less CPU time
   * a ray). qk__advise_huge skips arrays below 4 MB and custom allocators. */
  void *sbox = c->sbox;
  size_t sbox_bytes = c->sbox_cap * sizeof *c->sbox;
  int made = grow_block(a, &sbox, &sbox_bytes, n_slots * sizeof *c->sbox);
  if (made < 0) return QK_ERR_NOMEM;
  c->sbox = sbox, c->sbox_cap = sbox_bytes / sizeof *c->sbox;
  if (made) qk__advise_huge(a, c->sbox, sbox_bytes);
  if (c->n_discs) {
    made = grow_block(a, &c->sdisc_block, &c->sdisc_bytes, n_slots * sizeof(sdisc_t) + 64);
    if (made < 0) return QK_ERR_NOMEM;
    if (made) qk__advise_huge(a, c->sdisc_block, c->sdisc_bytes);
  }
  /* Three spare entries in front put each block of four children (which start at ids
   * 1, 5, 9, ...) on a 128-byte boundary, with 64 bytes of slack for the alignment. */
  made = grow_block(a, &c->cn_block, &c->cn_bytes, (n_nodes + 3) * sizeof(cnode_t) + 64);
  if (made < 0) return QK_ERR_NOMEM;
  if (made) qk__advise_huge(a, c->cn_block, c->cn_bytes);
  c->n_slots = n_slots, c->n_nodes = n_nodes;
  c->sdisc = c->n_discs ? (sdisc_t *)(((uintptr_t)c->sdisc_block + 63) & ~(uintptr_t)63) : NULL;
  c->cn = (cnode_t *)(((uintptr_t)c->cn_block + 63) & ~(uintptr_t)63) + 3;
  return QK_OK;
}

/* The item of `id` into `slot`; how far its box reaches from the centre there. */
static inline double put_item(qk_collider_t *c, const range_ctx_t *x, size_t id, uint32_t slot,
                              const double *xs, const double *ys) {
  if (id < c->n_discs) {
    c->sdisc[slot] = (sdisc_t){x->discs[id], (qk_id_t)id, 0};
    c->sbox[slot] = disc_bbox(&x->discs[id]);
  } else {
    c->sbox[slot] = x->boxes[id - c->n_discs];
  }
  const qk_box_t *b = &c->sbox[slot];
  return qk__max(qk__max(xs[slot] - b->xmin, b->xmax - xs[slot]),
                 qk__max(ys[slot] - b->ymin, b->ymax - ys[slot]));
}

/* Slots [lo, hi) of a tree whose slots are all in use (each holds the item of its id). */
static double slots_range(range_ctx_t *x, size_t lo, size_t hi) {
  qk_collider_t *c = x->c;
  const double *xs = qk__tree_xs(c->tree), *ys = qk__tree_ys(c->tree);
  const qk_id_t *pid = qk__tree_ids(c->tree);
  double reach = 0;
  for (size_t slot = lo; slot < hi; slot++)
    reach = qk__max(reach, put_item(c, x, pid[slot], (uint32_t)slot, xs, ys));
  return reach;
}

/* Ids [lo, hi), each into the slot the tree's id map gives it. */
static double ids_range(range_ctx_t *x, size_t lo, size_t hi) {
  qk_collider_t *c = x->c;
  const double *xs = qk__tree_xs(c->tree), *ys = qk__tree_ys(c->tree);
  double reach = 0;
  for (size_t id = lo; id < hi; id++)
    reach = qk__max(reach, put_item(c, x, id, x->where[id], xs, ys));
  return reach;
}

/* Phase 4: each item into the slot the tree gave its centre, then the node boxes; on the
 * build's threads. When the tree uses exactly n slots (a bulk build), every slot holds
 * one item and the pass goes slot by slot (reading the items at random, writing in
 * order); otherwise id by id through the tree's id map. */
static qk_status_t fill_slots(qk_collider_t *c, const qk_disc_t *discs, const qk_box_t *boxes) {
  range_ctx_t x;
  x.c = c, x.discs = discs, x.boxes = boxes, x.n_discs = c->n_discs, x.centres = NULL;
  x.where = NULL;
  if (qk__tree_slot_bound(c->tree) == c->n) {
    c->reach = run_ranges(&x, c->n, slots_range);
  } else {
    qk_status_t st = qk__id_map(c->tree, &x.where);
    if (st != QK_OK) return st;
    c->reach = run_ranges(&x, c->n, ids_range);
  }
  unsigned threads = qk__threads_resolve(c->threads);
  fill_boxes(c, c->n < RANGE_PAR_MIN ? 1 : threads);
  /* (A root square below 2^-900 would make side / 2^32 subnormal: no local start.) */
  const qk_square_t rs = qk__tree_root_square(c->tree);
  c->rs_x = rs.x, c->rs_y = rs.y;
  c->rs_f = rs.side > 0x1p-900 ? 0x1p32 / rs.side : NAN;
  c->rs_k = (fabs(rs.x) + fabs(rs.y) + rs.side) * 0x1p-45;
  return QK_OK;
}

/*
 * Make the ray cast's structures from the node boxes: the 4-wide entries (quads), each
 * with its parent (qnode_t), then the start table (build_ztab). Every internal node has four
 * children, so there are at most n_nodes / 4 of them; each entry is one cache line.
 * Items beyond 2^100 take the general test only (fact 2's range), and their boxes need
 * not fit a float grid: no entries then. On failure nothing is kept.
 */
static qk_status_t prepare_rays(qk_collider_t *c) {
  if (c->mag > 0x1p100) return QK_OK;
  c->quads_bytes = (c->n_nodes / 4 + 1 + QK__RAY_SUBTREE_LINES) * sizeof(qnode_t) + 64;
  c->quads_block = qk__realloc(&c->alloc, NULL, 0, c->quads_bytes);
  if (!c->quads_block) {
    c->quads_bytes = 0;
    return QK_ERR_NOMEM;
  }
  c->quads = (qnode_t *)(((uintptr_t)c->quads_block + 63) & ~(uintptr_t)63);
  qk__advise_huge(&c->alloc, c->quads_block, c->quads_bytes); /* see alloc_arrays */
  fill_quads(c, c->n < RANGE_PAR_MIN ? 1 : qk__threads_resolve(c->threads));
  c->ray_prefetch =
      (size_t)c->n_quads * sizeof(qnode_t) + c->n_slots * sizeof(sdisc_t) >= QK__RAY_PREFETCH_BYTES;
  qk_status_t st = c->n_quads ? build_ztab(c) : QK_OK;
  if (st != QK_OK) free_rays(c);
  return st;
}

qk_status_t qk_collider_prepare_rays(qk_collider_t *c) {
  if (!c) return QK_ERR_INVALID;
  /* Once-only initialisation that may fail: the thread that moves the state from NONE to
   * BUSY prepares, the others wait (napping) until it is READY, or NONE again after a
   * failure, when the next of them tries in turn. */
  for (;;) {
    int s = atomic_load_explicit(&c->rays_state, memory_order_acquire);
    if (s == RAYS_READY) return QK_OK;
    if (s == RAYS_NONE &&
        atomic_compare_exchange_strong_explicit(&c->rays_state, &s, RAYS_BUSY, memory_order_acquire,
                                                memory_order_acquire)) {
      const qk_status_t st = prepare_rays(c);
      atomic_store_explicit(&c->rays_state, st == QK_OK ? RAYS_READY : RAYS_NONE,
                            memory_order_release);
      return st;
    }
    if (s == RAYS_BUSY) qk__thread_nap();
  }
}

qk_status_t qk__collider_rays_ready(const qk_collider_t *c) {
  if (atomic_load_explicit(&c->rays_state, memory_order_acquire) == RAYS_READY) return QK_OK;
  /* The collider was not made const (qk_collider_build allocates it); only the ray
   * fields change, under the state above. */
  return qk_collider_prepare_rays((qk_collider_t *)c);
}

qk_status_t qk_collider_build(const qk_disc_t *discs, size_t n_discs, const qk_box_t *boxes,
                              size_t n_boxes, const qk_tree_options_t *options,
                              qk_collider_t **out) {
  if (!out) return QK_ERR_INVALID;
  *out = NULL;
  qk_tree_options_t opt;
  if (options)
    opt = *options;
  else
    qk_tree_options_init(&opt);
  qk_status_t st = check_items(discs, n_discs, boxes, n_boxes, opt.threads);
  if (st != QK_OK) return st;
  qk_allocator_t a = {NULL, NULL};
  if (opt.allocator) a = *opt.allocator;
  qk_collider_t *c = qk__realloc(&a, NULL, 0, sizeof *c);
  if (!c) return QK_ERR_NOMEM;
  memset(c, 0, sizeof *c);
  c->alloc = a;
  c->threads = opt.threads;
  opt.huge_pages = 1; /* the centres' tree too (see alloc_arrays) */
  atomic_init(&c->rays_state, RAYS_NONE);
  c->n_discs = n_discs;
  c->n = n_discs + n_boxes;
  if ((st = build_centre_tree(c, discs, n_discs, boxes, c->n, &opt, &c->mag, &c->tiny_discs)) !=
          QK_OK ||
      (st = alloc_arrays(c)) != QK_OK || (st = fill_slots(c, discs, boxes)) != QK_OK) {
    qk_collider_free(c);
    return st;
  }
  *out = c;
  return QK_OK;
}

/* Forget the ray structures of the items before a rebuild. */
static void drop_rays(qk_collider_t *c) {
  free_rays(c);
  atomic_store_explicit(&c->rays_state, RAYS_NONE, memory_order_relaxed);
}

/* A collider without items after a rebuild ran out of memory: no ray structures, the tree
 * emptied and the arrays of the last build (every one at least one entry long) filled for
 * no items; nothing is allocated. */
static void make_empty(qk_collider_t *c) {
  drop_rays(c);
  qk__free(&c->alloc, c->centres, c->centres_cap * sizeof *c->centres);
  c->centres = NULL, c->centres_cap = 0;
  c->n_discs = c->n = 0;
  c->mag = 0, c->tiny_discs = 0;
  qk_status_t st = qk_tree_rebuild(c->tree, NULL, 0, NULL);
  if (st == QK_OK) st = alloc_arrays(c);
  if (st == QK_OK) st = fill_slots(c, NULL, NULL);
  assert(st == QK_OK); /* no points and arrays of one entry need no memory */
  (void)st;
}

qk_status_t qk_collider_rebuild(qk_collider_t *c, const qk_disc_t *discs, size_t n_discs,
                                const qk_box_t *boxes, size_t n_boxes) {
  if (!c) return QK_ERR_INVALID;
  qk_status_t st = check_items(discs, n_discs, boxes, n_boxes, c->threads);
  if (st != QK_OK) return st;
  /* The tree on the collider's threads, as the build's other phases. A centre outside a
   * given root is found by the tree's rebuild, which then leaves the tree as it was: so
   * is the collider, whose own arrays are not touched before. */
  qk_tree_set_threads(c->tree, c->threads);
  double mag;
  int tiny;
  st = build_centre_tree(c, discs, n_discs, boxes, n_discs + n_boxes, NULL, &mag, &tiny);
  if (st == QK_OK) {
    drop_rays(c); /* made for the old items; the next cast makes them again */
    c->n_discs = n_discs;
    c->n = n_discs + n_boxes;
    c->mag = mag, c->tiny_discs = tiny;
    if ((st = alloc_arrays(c)) == QK_OK) st = fill_slots(c, discs, boxes);
  }
  if (st == QK_ERR_NOMEM) make_empty(c);
  return st;
}

const qk_tree_t *qk_collider_tree(const qk_collider_t *c) { return c ? c->tree : NULL; }

size_t qk_collider_size(const qk_collider_t *c) { return c ? c->n : 0; }

/* Visit every item whose shape overlaps q (whose bounding box is qb), descending only
 * into nodes whose item box meets qb. Returns nonzero when fn asked to stop. */
typedef int (*item_fn)(qk_id_t id, void *ud);

static int overlap_walk(const qk_collider_t *c, const shape_t *q, const qk_box_t *qb, item_fn fn,
                        void *ud) {
  const qk_id_t *pid = qk__tree_ids(c->tree);
  uint32_t stack[QK__CSTACK_MAX];
  int sp = 0;
  stack[sp++] = 0;
  while (sp > 0) {
    const cnode_t *n = &c->cn[stack[--sp]];
    if (!cbox_box(n, qb)) continue;
    if (n->child == QK_NONE) {
      for (uint32_t s = n->start; s < n->start + n->count; s++) {
        if (!box_box(&c->sbox[s], qb)) continue;
        shape_t sh = slot_shape(c, s);
        if (shapes_overlap(q, &sh) && fn(pid[s], ud)) return 1;
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
  if (qk_tree_point(f->c->tree, id, &p) != QK_OK) return 1; /* (cannot be: the tree's own id) */
  return f->fn(id, p, 0.0, f->ud);
}

qk_status_t qk_collider_query_box(const qk_collider_t *c, qk_box_t box, qk_found_fn fn, void *ud) {
  if (!c || !fn) return QK_ERR_INVALID;
  if (isnan(box.xmin) || isnan(box.ymin) || isnan(box.xmax) || isnan(box.ymax))
    return QK_ERR_NONFINITE;
  if (box.xmin > box.xmax || box.ymin > box.ymax) return QK_ERR_GEOMETRY;
  shape_t q = {0, {0, 0, 0}, box};
  found_ctx_t f = {c, fn, ud};
  overlap_walk(c, &q, &box, found_adapter, &f);
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
  overlap_walk(c, &q, &qb, found_adapter, &f);
  return QK_OK;
}

/* The exact overlap of the items in two slots whose boxes meet, when one is a disc (two
 * boxes overlap exactly when their boxes meet). */
static int slots_overlap(const qk_collider_t *c, uint32_t si, uint32_t sj) {
  shape_t x = slot_shape(c, si), y = slot_shape(c, sj);
  return shapes_overlap(&x, &y);
}

#if defined(__SSE2__)
/* Does the box with corners lo, hi meet the one with corners qlo, qhi (each the x and y of
 * a corner)? The comparisons of box_box, two at a time. */
static inline int box_meets(__m128d lo, __m128d hi, __m128d qlo, __m128d qhi) {
  return _mm_movemask_pd(_mm_and_pd(_mm_cmple_pd(lo, qhi), _mm_cmple_pd(qlo, hi))) == 3;
}

/* A node's corners (float pairs xmin, ymin and xmax, ymax) widened to doubles. */
static inline __m128d cnode_lo(const cnode_t *n) {
  return _mm_cvtps_pd(_mm_castsi128_ps(_mm_loadl_epi64((const __m128i *)(const void *)&n->xmin)));
}
static inline __m128d cnode_hi(const cnode_t *n) {
  return _mm_cvtps_pd(_mm_castsi128_ps(_mm_loadl_epi64((const __m128i *)(const void *)&n->xmax)));
}
#endif

/*
 * All pairs between the items of leaf `a` and those of leaf `b`, each pair reported from
 * the side of its smaller id. Boxes against boxes need no test beyond the bounding
 * boxes, which are exact for them. The arrays are read through locals: the callback could
 * write anywhere as far as the compiler knows, which would make it load them again for
 * every item.
 */
static inline int leaf_pairs(const qk_collider_t *c, const cnode_t *la, const cnode_t *lb,
                             qk_pair_fn fn, void *ud) {
  const qk_id_t *pid = qk__tree_ids(c->tree);
  const qk_box_t *sbox = c->sbox;
  const size_t n_discs = c->n_discs;
  const uint32_t a0 = la->start, a1 = a0 + la->count, b0 = lb->start, b1 = b0 + lb->count;
#if defined(__SSE2__)
  const __m128d blo = cnode_lo(lb), bhi = cnode_hi(lb);
  for (uint32_t si = a0; si < a1; si++) {
    const __m128d lo = _mm_loadu_pd(&sbox[si].xmin), hi = _mm_loadu_pd(&sbox[si].xmax);
    if (!box_meets(lo, hi, blo, bhi)) continue;
    const qk_id_t ia = pid[si];
    const int a_disc = ia < n_discs;
    for (uint32_t sj = b0; sj < b1; sj++) {
      const qk_id_t ib = pid[sj];
      if (ib <= ia ||
          !box_meets(_mm_loadu_pd(&sbox[sj].xmin), _mm_loadu_pd(&sbox[sj].xmax), lo, hi))
        continue;
      if ((a_disc || ib < n_discs) && !slots_overlap(c, si, sj)) continue;
      if (fn(ia, ib, ud)) return 1;
    }
  }
#else
  for (uint32_t si = a0; si < a1; si++) {
    const qk_box_t *bi = &sbox[si];
    if (!cbox_box(lb, bi)) continue;
    const qk_id_t ia = pid[si];
    const int a_disc = ia < n_discs;
    for (uint32_t sj = b0; sj < b1; sj++) {
      const qk_id_t ib = pid[sj];
      if (ib <= ia || !box_box(bi, &sbox[sj])) continue;
      if ((a_disc || ib < n_discs) && !slots_overlap(c, si, sj)) continue;
      if (fn(ia, ib, ud)) return 1;
    }
  }
#endif
  return 0;
}

#if defined(__SSE2__)
/* leaf_pairs of a leaf with itself: its items all meet its own box, so they go to the
 * pairing without the test against it. */
static int self_pairs(const qk_collider_t *c, const cnode_t *la, qk_pair_fn fn, void *ud) {
  const qk_id_t *pid = qk__tree_ids(c->tree);
  const qk_box_t *sbox = c->sbox;
  const size_t n_discs = c->n_discs;
  const uint32_t a0 = la->start, a1 = a0 + la->count;
  for (uint32_t si = a0; si < a1; si++) {
    const __m128d lo = _mm_loadu_pd(&sbox[si].xmin), hi = _mm_loadu_pd(&sbox[si].xmax);
    const qk_id_t ia = pid[si];
    const int a_disc = ia < n_discs;
    for (uint32_t sj = a0; sj < a1; sj++) {
      const qk_id_t ib = pid[sj];
      if (ib <= ia ||
          !box_meets(_mm_loadu_pd(&sbox[sj].xmin), _mm_loadu_pd(&sbox[sj].xmax), lo, hi))
        continue;
      if ((a_disc || ib < n_discs) && !slots_overlap(c, si, sj)) continue;
      if (fn(ia, ib, ud)) return 1;
    }
  }
  return 0;
}

/*
 * Which of the four children (32-byte cnode_t records side by side from ch) have a box
 * that meets the box whose sides q holds as (xmax, ymax, -xmin, -ymin): bit k for child
 * k. A child meets it when xmin <= q.xmax, ymin <= q.ymax, -xmax <= -q.xmin and
 * -ymax <= -q.ymin, all four float comparisons at once (negation is exact, and an empty
 * child's box at +infinity fails the first): the comparisons of cbox_box, whose double
 * operands are these floats widened.
 */
static inline unsigned children_meet(const cnode_t *ch, __m128 q) {
  const __m128 neg = _mm_castsi128_ps(_mm_set_epi32((int)0x80000000u, (int)0x80000000u, 0, 0));
  const __m128i m0 = _mm_castps_si128(_mm_cmple_ps(_mm_xor_ps(_mm_loadu_ps(&ch[0].xmin), neg), q));
  const __m128i m1 = _mm_castps_si128(_mm_cmple_ps(_mm_xor_ps(_mm_loadu_ps(&ch[1].xmin), neg), q));
  const __m128i m2 = _mm_castps_si128(_mm_cmple_ps(_mm_xor_ps(_mm_loadu_ps(&ch[2].xmin), neg), q));
  const __m128i m3 = _mm_castps_si128(_mm_cmple_ps(_mm_xor_ps(_mm_loadu_ps(&ch[3].xmin), neg), q));
  /* Each comparison to a byte, child k's four in 32-bit lane k: all ones when all hold. */
  const __m128i all = _mm_packs_epi16(_mm_packs_epi32(m0, m1), _mm_packs_epi32(m2, m3));
  return (unsigned)_mm_movemask_ps(_mm_castsi128_ps(_mm_cmpeq_epi32(all, _mm_set1_epi32(-1))));
}

/* The lowest set bit of a nonzero 4-bit mask. */
static const uint8_t low_bit4[16] = {0, 0, 1, 0, 2, 0, 1, 0, 3, 0, 1, 0, 2, 0, 1, 0};

/*
 * The depth-first search for the leaves whose boxes meet the box q holds (as
 * children_meet takes it), from the root (internal), one leaf per leaf_next in
 * depth-first order. The four children of a node are tested at once, and the node's entry
 * on the stack holds its first child and the mask of those that met the box; the lowest
 * bit left is visited next (its subtree stacked above the entry), so the children go in
 * order.
 */
typedef struct leaf_iter {
  int sp;
  uint64_t stack[QK__CSTACK_MAX];
} leaf_iter_t;

static inline void leaf_first(leaf_iter_t *it, const cnode_t *cn, __m128 q) {
  const unsigned m = children_meet(&cn[cn[0].child], q);
  it->sp = 0;
  if (m) it->stack[it->sp++] = (uint64_t)cn[0].child << 4 | m;
}

/* The next leaf met, or QK_NONE. */
static inline uint32_t leaf_next(leaf_iter_t *it, const cnode_t *cn, __m128 q) {
  while (it->sp > 0) {
    const uint64_t e = it->stack[it->sp - 1], rest = e & (e - 1); /* the lowest bit cleared */
    it->stack[it->sp - 1] = rest;
    it->sp -= (rest & 15) == 0;
    const uint32_t v = (uint32_t)(e >> 4) + low_bit4[e & 15];
    const uint32_t child = cn[v].child;
    if (child == QK_NONE) return v;
    const unsigned m = children_meet(&cn[child], q);
    if (m) it->stack[it->sp++] = (uint64_t)child << 4 | m;
  }
  return QK_NONE;
}

/* A node's box as children_meet takes it. */
static inline __m128 meet_box(const cnode_t *n) {
  return _mm_set_ps(-n->ymin, -n->xmin, n->ymax, n->xmax);
}

/* Does node n's box meet the box q holds (as children_meet takes it)? */
static inline int node_meets(const cnode_t *n, __m128 q) {
  const __m128 neg = _mm_castsi128_ps(_mm_set_epi32((int)0x80000000u, (int)0x80000000u, 0, 0));
  return _mm_movemask_ps(_mm_cmple_ps(_mm_xor_ps(_mm_loadu_ps(&n->xmin), neg), q)) == 15;
}

/*
 * The family list of internal node p in pc: every leaf whose box meets p's, in depth-first
 * order, when p has two or more non-empty leaf children (n = QK_NONE otherwise, or when
 * they are more than the list holds). The leaves meeting one of those children's boxes are
 * among them (a child's float box lies in its parent's, both rounded outwards from nested
 * boxes), in the same order, so a child then filters the list instead of descending from
 * the root: one descent for the family instead of one per leaf.
 */
static void family_list(const qk_collider_t *c, uint32_t p, qk__pairs_cache_t *pc) {
  const cnode_t *cn = c->cn;
  const cnode_t *ch = &cn[cn[p].child];
  pc->parent = p;
  pc->n = QK_NONE;
  int leaves = 0;
  for (int k = 0; k < 4; k++) leaves += ch[k].child == QK_NONE && ch[k].count > 0;
  if (leaves < 2) return;
  const __m128 q = meet_box(&cn[p]);
  uint32_t n = 0, v;
  leaf_iter_t it;
  leaf_first(&it, cn, q); /* the root's box holds p's */
  while ((v = leaf_next(&it, cn, q)) != QK_NONE) {
    if (n == QK__FAMILY_MAX) return;
    pc->leaf[n++] = v;
  }
  pc->n = n;
}
#endif

/*
 * Leaf against leaf: for each leaf, one descent finds every leaf whose item box meets its
 * own, and the items of the two are paired directly. That shares one descent among all
 * the items of a leaf instead of making one per item. This is the part for one leaf.
 */
int qk__collider_leaf_pairs(const qk_collider_t *c, uint32_t leaf, qk__pairs_cache_t *pc,
                            qk_pair_fn fn, void *ud) {
  const cnode_t *cn = c->cn;
  const cnode_t *la = &cn[leaf];
  /* The leaf's box, widened back to doubles, is what the other leaves must meet. */
  const qk_box_t ba = {la->xmin, la->ymin, la->xmax, la->ymax};
  if (!cbox_box(&cn[0], &ba)) return 0;
  if (cn[0].child == QK_NONE) return leaf_pairs(c, la, &cn[0], fn, ud);
#if defined(__SSE2__)
  /* The same leaves in the same (depth-first) order as the plain search below, from the
   * family list of the leaf's parent when it has one, else by a descent of its own. */
  const __m128 q = meet_box(la);
  const uint32_t parent = qk__node_parent(c->tree, leaf);
  if (pc->parent != parent) family_list(c, parent, pc);
  if (pc->n != QK_NONE) {
    for (uint32_t i = 0; i < pc->n; i++) {
      const cnode_t *lb = &cn[pc->leaf[i]];
      if (lb == la) {
        if (self_pairs(c, la, fn, ud)) return 1;
      } else if (node_meets(lb, q) && leaf_pairs(c, la, lb, fn, ud)) {
        return 1;
      }
    }
    return 0;
  }
  uint32_t v;
  leaf_iter_t it;
  leaf_first(&it, cn, q);
  while ((v = leaf_next(&it, cn, q)) != QK_NONE)
    if (leaf_pairs(c, la, &cn[v], fn, ud)) return 1;
#else
  (void)pc;
  uint32_t inner[QK__CSTACK_MAX];
  int si = 0;
  for (int k = 3; k >= 0; k--) inner[si++] = cn[0].child + (uint32_t)k;
  while (si > 0) {
    const cnode_t *lb = &cn[inner[--si]];
    if (!cbox_box(lb, &ba)) continue;
    if (lb->child != QK_NONE) {
      for (int k = 3; k >= 0; k--) inner[si++] = lb->child + (uint32_t)k;
      continue;
    }
    if (leaf_pairs(c, la, lb, fn, ud)) return 1;
  }
#endif
  return 0;
}

int qk__collider_each_leaf(const qk_collider_t *c, int (*fn)(uint32_t leaf, void *ud), void *ud) {
  uint32_t outer[QK__CSTACK_MAX];
  int so = 0;
  outer[so++] = 0;
  while (so > 0) {
    uint32_t v = outer[--so];
    const cnode_t *la = &c->cn[v];
    if (la->child != QK_NONE) {
      for (int k = 3; k >= 0; k--) outer[so++] = la->child + (uint32_t)k;
      continue;
    }
    if (la->count > 0 && fn(v, ud)) return 1;
  }
  return 0;
}

typedef struct pairs_ctx {
  const qk_collider_t *c;
  qk_pair_fn fn;
  void *ud;
  qk__pairs_cache_t pc;
} pairs_ctx_t;

static int serial_leaf(uint32_t leaf, void *ud) {
  pairs_ctx_t *p = ud;
  return qk__collider_leaf_pairs(p->c, leaf, &p->pc, p->fn, p->ud);
}

void qk__collider_pairs_serial(const qk_collider_t *c, qk_pair_fn fn, void *ud) {
  pairs_ctx_t p = {c, fn, ud, {QK_NONE, QK_NONE, {0}}};
  qk__collider_each_leaf(c, serial_leaf, &p);
}

qk_status_t qk_collider_pairs(const qk_collider_t *c, qk_pair_fn fn, void *ud) {
  if (!c || !fn) return QK_ERR_INVALID;
  /* On several threads when asked and the memory for it can be had; the same pairs in
   * the same order either way. */
  if (c->threads == 1 || qk__collider_pairs_threaded(c, fn, ud) != QK_OK)
    qk__collider_pairs_serial(c, fn, ud);
  return QK_OK;
}

void qk_collider_set_threads(qk_collider_t *c, uint32_t threads) {
  if (c) c->threads = threads;
}

uint32_t qk__collider_threads(const qk_collider_t *c) { return c->threads; }

const qk_allocator_t *qk__collider_alloc(const qk_collider_t *c) { return &c->alloc; }

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
  qk_status_t st = qk_collider_pairs(c, list_pair, &l);
  if (st != QK_OK) return st;
  *n_out = l.n;
  /* Sorting only a prefix would mislead: sort what we wrote when it is all of them. */
  if (l.n <= cap && l.n > 1) qsort(out, l.n, sizeof *out, pair_cmp);
  return QK_OK;
}

/* ---------------------------------------------------------------------------------- */
/* Ray casting                                                                          */

/*
 * How the ray cast prunes in float and still never loses a hit (docs/collide.md, "The ray
 * path", has the same argument in prose; tests/test_collide.c checks it against brute
 * force on grazing, axis-parallel, inside, huge and tiny cases).
 *
 * Hits are decided by the items alone, in doubles (ray_disc, ray_box); node boxes only
 * prune, and a node must be entered whenever it holds an item that the search would
 * report. Two facts give that.
 *
 * (1) The item margin. Let w = (|ox| + |oy| + 2 mag) 2^-40, mag the largest coordinate
 *     magnitude of any item box. An item hit at a computed th has the exact point
 *     o + th d within w of its box on each axis: th comes from the same doubles with
 *     relative errors of a few 2^-53, which move that point by some 2^-50 (|o| + mag),
 *     and disc boxes carry a pad of 2^-40 of their own magnitude. (This is the margin
 *     the search has always relied on; w is 2^10 times the roundings it covers, short of
 *     underflow in the item tests themselves.) So the exact ray meets the node's box
 *     widened by w, B_w, at t* = th, and 0 <= th <= min(tmax, best) for an item that is
 *     to be reported (ties included).
 *
 * (2) The float test accepts every node whose B_w the exact ray meets at some real t* in
 *     [0, T], T = round_up(min(tmax, best)), and returns an entry bound L <= fl(t*), fl
 *     being rounding to the nearest float. Per axis, for dx > 0 (for dx < 0 the sides
 *     swap and so do the rounding directions below):
 *       near = fl(fl(xmin - Pn) * In),   far = fl(fl(xmax - Pf) * If),
 *     with floats Pn >= ox + w, Pf <= ox - w, 0 < In <= 1 / (dx (1 + u)) and
 *     If >= 1 / (dx (1 - u)), u = 2^-24 the float unit roundoff. From
 *     xmin - w <= ox + t* dx <= xmax + w: a = xmin - Pn <= t* dx. If a <= 0 then
 *     fl(a) In <= 0 <= t*; else fl(a) <= a (1 + u) (a float subtraction errs by at most
 *     u relatively, and not at all when the result is subnormal), so fl(a) In <= a / dx
 *     <= t*. Likewise b = xmax - Pf >= t* dx >= 0, fl(b) >= b (1 - u) and fl(b) If >= t*.
 *     Rounding to nearest is monotone, overflow and underflow included, so
 *     near <= fl(t*) <= far; with the same for y, fl(0) = 0 and fl(t*) <= fl(T) = T:
 *       L = max(near_x, near_y, 0) <= fl(t*) <= min(far_x, far_y, T) = U,
 *     and the test L <= U accepts. As th <= best gives fl(th) <= round_up(best), a
 *     stacked node with bound L is dropped only when L > round_up(best) says it holds
 *     nothing at t <= best.
 *     The constants meet the conditions: Pn and Pf are ox + w + m and ox - w - m,
 *     m = (|ox| + w) 2^-21 + 2^-140, computed in double and converted to float; m is
 *     above the roundings of the double sums (2^-52 relatively) and of the conversion
 *     (2^-24 relatively, or 2^-150 below the normal range), so Pn >= ox + w and
 *     Pf <= ox - w. In and If are 1/dx times 1 - 2^-21 and 1 + 2^-21 in double,
 *     converted to float: three roundings of at most 2^-24 + 2^-52 relatively in all,
 *     which the factor's 2^-21 exceeds by more than the u that fact (2) asks. No NaN can
 *     arise, and no difference can overflow, when |ox|, |oy|, mag <= 2^100 and
 *     2^-100 <= |dx|, |dy| <= 2^100: every ray constant is then a finite nonzero float,
 *     box sides (the exact grid values of qnode_t) are finite below 2^103, and no
 *     infinity meets a zero or another infinity. Other rays (a zero or extreme component,
 *     huge coordinates) and builds without SSE2 take the general test, in doubles, on the
 *     cnode_t boxes widened by w.
 */
typedef struct ray {
  double ox, oy, dx, dy;
  double w;   /* the item margin of fact (1) */
  double ts;  /* w over the direction's largest component: the general test's margin in t */
  int simd;   /* the float test's ranges hold (fact 2) */
  unsigned s; /* the lanes in the order the ray meets their squares: i ^ s */
#if defined(__SSE2__)
  __m128d vox, voy;     /* ox, oy in both lanes (the leaf test) */
  __m128d vdx, vdy, va; /* dx, dy and dx dx + dy dy in both lanes (the leaf test) */
  __m128i swap;         /* per 32-bit group of qnode_t::q: all ones where entry and exit swap */
  __m128 pnx, pny, pfx, pfy; /* Pn, Pf per axis */
  __m128 inx, iny, ifx, ify; /* In, If per axis */
#endif
} ray_t;

/* A stacked node of the ray cast: an entry of quads (count QK_NONE; in the general test a
 * node id) or a leaf's slot range, with a lower bound on the t of anything in it (float,
 * rounded down). */
typedef struct rentry {
  uint32_t link, count;
  float bound;
} rentry_t;

#if defined(__GNUC__)
#define QK__CPREFETCH(p) __builtin_prefetch(p)
#else
#define QK__CPREFETCH(p) ((void)(p))
#endif

/*
 * One axis of the slab test in doubles, by division: narrow [*lo, *hi] to where o + t d
 * lies in [min, max]; 0 when a zero component leaves the origin's coordinate outside.
 */
static inline int slab_axis(double min, double max, double o, double d, double *lo, double *hi) {
  if (d == 0) return !(o < min || o > max);
  double t1 = (min - o) / d, t2 = (max - o) / d;
  if (t1 > t2) {
    double s = t1;
    t1 = t2;
    t2 = s;
  }
  if (t1 > *lo) *lo = t1;
  if (t2 < *hi) *hi = t2;
  return 1;
}

/* The slab test of the ray against a closed box: the parameter interval [lo, hi] within
 * [0, tmax] in which the ray is inside the box (empty when lo > hi). */
static inline int slab(double xmin, double ymin, double xmax, double ymax, const ray_t *r,
                       double tmax, double *lo_out, double *hi_out) {
  double lo = 0.0, hi = tmax;
  if (!slab_axis(xmin, xmax, r->ox, r->dx, &lo, &hi) ||
      !slab_axis(ymin, ymax, r->oy, r->dy, &lo, &hi))
    return 0;
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

/*
 * ray_disc() in coordinates scaled by a power of two 2^-k, for an origin or a disc beyond
 * FAR_COORD, where its squares could overflow (a hit at t = inf, or a miss), or all within
 * NEAR_COORD of the origin, where they could underflow (below 2^-511 they did: a disc the ray
 * passes at nine radii, at 1e-170, was hit at t = 0). The origin, the disc and tmax are
 * scaled by the 2^-k that brings the largest of their magnitudes just below FAR_COORD, or
 * to [1/2, 1), and t is scaled back. |f + t d| = r is |2^-k f + (2^-k t) d| = 2^-k r, and
 * scaling by a power of two commutes with every rounding, so t is ray_disc()'s own but for
 * parts that fall below 2^-1022 (coordinates 2^1000 times smaller than the largest, which
 * then count as 0). With the direction's largest component in [2^-100, 2^100] (the cast's
 * scaling), no square or product of ray_disc() overflows below FAR_COORD. (A tiny disc
 * far from the origin, seen from far away, still squares its radius into the underflow:
 * the ray then passes it within far less than the rounding of its own coordinates.)
 */
static double ray_disc_scaled(const qk_disc_t *d, double ox, double oy, double dx, double dy,
                              double tmax) {
  const double m =
      qk__max(qk__max(fabs(ox), fabs(oy)), qk__max(qk__max(fabs(d->x), fabs(d->y)), d->r));
  if (!(m > FAR_COORD || (m < NEAR_COORD && m > 0))) return ray_disc(d, ox, oy, dx, dy, tmax);
  int e;
  (void)frexp(m, &e);
  const int k = m > FAR_COORD ? e - 400 : e; /* m 2^-k in [2^399, 2^400), or [1/2, 1) */
  const qk_disc_t s = {ldexp(d->x, -k), ldexp(d->y, -k), ldexp(d->r, -k)};
  const double t = ray_disc(&s, ldexp(ox, -k), ldexp(oy, -k), dx, dy, ldexp(tmax, -k));
  return t < 0 ? t : ldexp(t, k);
}

#if defined(__SSE2__)
/*
 * ray_disc() for the discs d[0] and d[1] at once, each lane the same sequence of IEEE
 * operations as the scalar code. Bit k of the result is set when disc k is hit at a t in
 * [0, best] (t into th[k], written only when some bit is set); the lanes that the scalar
 * code would leave early compute values (perhaps NaN) that the masks discard.
 */
static inline unsigned ray_disc2(const sdisc_t *d, const ray_t *r, double tmax, double best,
                                 double th[2]) {
  const __m128d a0 = _mm_load_pd(&d[0].d.x), a1 = _mm_load_pd(&d[1].d.x); /* x, y */
  const __m128d x = _mm_unpacklo_pd(a0, a1), y = _mm_unpackhi_pd(a0, a1);
  const __m128d rr = _mm_set_pd(d[1].d.r, d[0].d.r);
  const __m128d dx = r->vdx, dy = r->vdy;
  const __m128d fx = _mm_sub_pd(r->vox, x), fy = _mm_sub_pd(r->voy, y);
  const __m128d cc =
      _mm_sub_pd(_mm_add_pd(_mm_mul_pd(fx, fx), _mm_mul_pd(fy, fy)), _mm_mul_pd(rr, rr));
  const __m128d b = _mm_add_pd(_mm_mul_pd(fx, dx), _mm_mul_pd(fy, dy));
  const __m128d a = r->va;
  const __m128d cr = _mm_sub_pd(_mm_mul_pd(fx, dy), _mm_mul_pd(fy, dx));
  const __m128d disc = _mm_sub_pd(_mm_mul_pd(_mm_mul_pd(a, rr), rr), _mm_mul_pd(cr, cr));
  const __m128d zero = _mm_setzero_pd();
  const __m128d inside = _mm_cmple_pd(cc, zero);
  /* Outside: hit when b < 0, disc >= 0 and t <= tmax (then t > 0). Most pairs miss on
   * both lanes before t is needed: they skip the square root and the division. */
  const __m128d may = _mm_and_pd(_mm_cmplt_pd(b, zero), _mm_cmpge_pd(disc, zero));
  if (!_mm_movemask_pd(_mm_or_pd(inside, may))) return 0;
  const __m128d t = _mm_div_pd(cc, _mm_add_pd(_mm_sub_pd(zero, b), _mm_sqrt_pd(disc)));
  const __m128d hit = _mm_and_pd(may, _mm_cmple_pd(t, _mm_set1_pd(tmax)));
  const __m128d tv = _mm_andnot_pd(inside, t); /* 0 inside */
  const __m128d cand = _mm_and_pd(_mm_or_pd(inside, hit), _mm_cmple_pd(tv, _mm_set1_pd(best)));
  _mm_storeu_pd(th, tv);
  return (unsigned)_mm_movemask_pd(cand);
}
#endif

static inline double ray_box(const qk_box_t *b, const ray_t *r, double tmax) {
  double lo, hi;
  if (!slab(b->xmin, b->ymin, b->xmax, b->ymax, r, tmax, &lo, &hi) || lo > hi) return -1.0;
  return lo;
}

/* The best hit so far: smallest t, then smallest id. */
typedef struct best {
  double t;
  qk_id_t id;
} best_t;

/* The items of slots [slot, end) against the ray, into *b. Discs carry their ids; the
 * tree's id array is read only for hits on boxes and for the kind in mixed sets. */
static QK__ALWAYS_INLINE void scan_leaf(const qk_collider_t *c, const ray_t *ray, uint32_t slot,
                                        uint32_t end, double tmax, int scaled, best_t *b) {
  const qk_id_t *pid = qk__tree_ids(c->tree);
  const int all_discs = c->n_discs == c->n, no_discs = c->n_discs == 0;
#if defined(__SSE2__)
  /* Discs two at a time, with the same operations as ray_disc() lane by lane (so the same
   * t to the last bit); only lanes that could be a new best go on. An odd count's last
   * pair is the last two discs: the one before the last is tested twice, which gives the
   * same t and id again and so leaves the best as it is (cheaper than a scalar test). */
  if (all_discs && !scaled && end - slot >= 2) {
    const uint32_t last = end - 2;
    for (uint32_t s2 = slot;; s2 += 2) {
      if (s2 > last) s2 = last;
      double th[2];
      const unsigned cand = ray_disc2(&c->sdisc[s2], ray, tmax, b->t, th);
      if (cand) { /* rare: neither disc can be a new best in most pairs */
        /* The lane in cand, or the smaller (t, id) of both, by index (a loop over the two
         * lanes mispredicted 0.7 times a ray; one ? th[1] : th[0] compiles to a branch). Each
         * lane in cand has t <= b->t, so the chosen one replaces the best unless it ties
         * with a smaller id. Both lanes are candidates in few pairs. */
        unsigned k = cand >> 1;
        if (cand == 3)
          k = th[1] < th[0] || (th[1] == th[0] && c->sdisc[s2 + 1].id < c->sdisc[s2].id);
        const double tk = th[k];
        const qk_id_t id = c->sdisc[s2 + k].id;
        if (tk < b->t || id < b->id) *b = (best_t){tk, id};
      }
      if (s2 + 2 >= end) break;
    }
    return;
  }
#endif
  for (; slot < end; slot++) {
    int is_disc = all_discs || (!no_discs && pid[slot] < c->n_discs);
    double th = !is_disc ? ray_box(&c->sbox[slot], ray, tmax)
                : scaled
                    ? ray_disc_scaled(&c->sdisc[slot].d, ray->ox, ray->oy, ray->dx, ray->dy, tmax)
                    : ray_disc(&c->sdisc[slot].d, ray->ox, ray->oy, ray->dx, ray->dy, tmax);
    if (th < 0 || th > b->t) continue;
    qk_id_t id = all_discs ? c->sdisc[slot].id : pid[slot];
    if (th < b->t || id < b->id) *b = (best_t){th, id};
  }
}

/*
 * visit[s][keep]: the kept lanes of a node in the order a ray of signs s meets their
 * squares (lane ^ s), packed: bits 0-1 the nearest (taken at once), bits 2-3 how many
 * others, then the others two bits each, farthest first (the order they are stacked, so
 * that the nearest of them is popped first).
 */
static const uint16_t visit[4][16] = {
    {0x000, 0x000, 0x001, 0x014, 0x002, 0x024, 0x025, 0x068, 0x003, 0x034, 0x035, 0x078, 0x036,
     0x0b8, 0x0b9, 0x1bc},
    {0x000, 0x000, 0x001, 0x005, 0x002, 0x024, 0x025, 0x029, 0x003, 0x034, 0x035, 0x039, 0x027,
     0x0e8, 0x0e9, 0x0ed},
    {0x000, 0x000, 0x001, 0x014, 0x002, 0x006, 0x016, 0x01a, 0x003, 0x007, 0x017, 0x01b, 0x036,
     0x0ca, 0x0da, 0x31e},
    {0x000, 0x000, 0x001, 0x005, 0x002, 0x006, 0x016, 0x04a, 0x003, 0x007, 0x017, 0x04b, 0x027,
     0x08b, 0x09b, 0x24f},
};

/* Sets up what both tests read: the origin, the direction, w and the leaf test's
 * constants. */
static inline void ray_init_common(ray_t *r, const qk_collider_t *c, qk_point_t o, qk_point_t d) {
  r->ox = o.x, r->oy = o.y, r->dx = d.x, r->dy = d.y;
  r->w = (fabs(o.x) + fabs(o.y) + 2 * c->mag) * 0x1p-40;
#if defined(__SSE2__)
  const __m128d dneg = _mm_cmplt_pd(_mm_set_pd(d.y, d.x), _mm_setzero_pd());
  r->s = (unsigned)_mm_movemask_pd(dneg); /* (dx < 0) + 2 (dy < 0) */
  r->vox = _mm_set1_pd(o.x), r->voy = _mm_set1_pd(o.y);
  r->vdx = _mm_set1_pd(d.x), r->vdy = _mm_set1_pd(d.y);
  r->va = _mm_set1_pd(d.x * d.x + d.y * d.y); /* the same operations as ray_disc()'s a */
#else
  r->s = (unsigned)(d.x < 0) | (unsigned)(d.y < 0) << 1;
#endif
}

#if defined(__SSE2__)
/* Fills the float test's constants (fact (2)'s ranges hold; r->w set). */
static inline void ray_init_float(ray_t *r, qk_point_t o, qk_point_t d) {
  /* Pn, Pf: the origin moved by w (towards the exit for the entry side, back for the
   * exit side) and by m more, then converted to float: m exceeds the roundings of the
   * double sums and of the conversion, so Pn >= o + w and Pf <= o - w as fact (2) asks
   * (cheaper than rounding in a chosen direction). In, If: 1/d scaled by 1 -+ 2^-21,
   * then converted (an error of 2^-24 at most in this range). */
  /* Both axes at once (lane 0 x, lane 1 y), each lane the same IEEE operations as
   * mx = (|ox| + w) 2^-21 + 2^-140, xp = fl(ox + w + mx), xm = fl(ox - w - mx) and
   * fl(1/dx (1 -+ 2^-21)) written out per axis, so the same floats. */
  const __m128d d2 = _mm_set_pd(d.y, d.x), dneg = _mm_cmplt_pd(d2, _mm_setzero_pd());
  const __m128d o2 = _mm_set_pd(o.y, o.x), w2 = _mm_set1_pd(r->w);
  const __m128d m2 = _mm_add_pd(
      _mm_mul_pd(_mm_add_pd(_mm_andnot_pd(_mm_set1_pd(-0.0), o2), w2), _mm_set1_pd(0x1p-21)),
      _mm_set1_pd(0x1p-140));
  const __m128 p = _mm_cvtpd_ps(_mm_add_pd(_mm_add_pd(o2, w2), m2)); /* xp, yp */
  const __m128 m = _mm_cvtpd_ps(_mm_sub_pd(_mm_sub_pd(o2, w2), m2)); /* xm, ym */
  const __m128d q2 = _mm_div_pd(_mm_set1_pd(1.0), d2);
  const __m128 in = _mm_cvtpd_ps(_mm_mul_pd(q2, _mm_set1_pd(1 - 0x1p-21)));
  const __m128 fi = _mm_cvtpd_ps(_mm_mul_pd(q2, _mm_set1_pd(1 + 0x1p-21)));
  /* A negative component enters a box by its max side: swap min and max of that axis
   * (neg: all ones in 32-bit group 0 for dx < 0, group 1 for dy < 0, and again in 2, 3). */
  const __m128i neg = _mm_shuffle_epi32(_mm_castpd_si128(dneg), _MM_SHUFFLE(2, 0, 2, 0));
  const __m128 ng = _mm_castsi128_ps(neg);
  const __m128 pn = _mm_or_ps(_mm_and_ps(ng, m), _mm_andnot_ps(ng, p));
  const __m128 pf = _mm_or_ps(_mm_and_ps(ng, p), _mm_andnot_ps(ng, m));
  r->inx = _mm_shuffle_ps(in, in, 0x00), r->iny = _mm_shuffle_ps(in, in, 0x55);
  r->ifx = _mm_shuffle_ps(fi, fi, 0x00), r->ify = _mm_shuffle_ps(fi, fi, 0x55);
  r->pnx = _mm_shuffle_ps(pn, pn, 0x00), r->pny = _mm_shuffle_ps(pn, pn, 0x55);
  r->pfx = _mm_shuffle_ps(pf, pf, 0x00), r->pfy = _mm_shuffle_ps(pf, pf, 0x55);
  r->swap = neg;
}
#endif

/* Sets up the ray; fills the float test's constants when fact (2)'s ranges hold. */
static void ray_init(ray_t *r, const qk_collider_t *c, qk_point_t o, qk_point_t d) {
  const double ax = fabs(d.x), ay = fabs(d.y), dn = qk__max(ax, ay);
  ray_init_common(r, c, o, d);
  r->ts = 0.0;
  r->simd = 0;
#if defined(__SSE2__)
  const double big = 0x1p100, mo = qk__max(qk__max(fabs(o.x), fabs(o.y)), c->mag);
  r->simd = c->quads && mo <= big && qk__min(ax, ay) >= 0x1p-100 && dn <= big;
#endif
  if (!r->simd) {
    r->ts = dn > 0 ? r->w / dn : 0.0;
    return;
  }
#if defined(__SSE2__)
  ray_init_float(r, o, d);
#endif
}

/*
 * The general test of a node's four children, in doubles on their cnode_t boxes: bit k is
 * set when lane k's box, widened by w, meets the ray within [0, tmax + ts] at a parameter
 * not beyond best + ts, and bound[k] receives that entry parameter less ts, rounded down
 * to float. For the rays the float test does not take, and without SSE2.
 */
static unsigned node_slab_general(const qk_collider_t *c, const cnode_t *n, const ray_t *r,
                                  double tmax, double best, float bound[4]) {
  unsigned keep = 0;
  const double w = r->w, ts = r->ts;
  for (int k = 0; k < 4; k++) {
    const cnode_t *ch = &c->cn[n->child + lane_quadrant[k]];
    double x0 = ch->xmin, y0 = ch->ymin, x1 = ch->xmax, y1 = ch->ymax;
    double l, u;
    if (x0 == INFINITY || !slab(x0 - w, y0 - w, x1 + w, y1 + w, r, tmax, &l, &u) ||
        !(l <= u + ts && l - ts <= best))
      continue;
    bound[k] = round_down(l - ts);
    keep |= 1u << k;
  }
  return keep;
}

/* The cast with the general test, walking the cnode_t array (entries are node ids). */
static void cast_general(const qk_collider_t *c, const ray_t *ray, double tmax, int scaled,
                         qk_hit_t *hit) {
  best_t b = {INFINITY, QK_NONE};
  float tf = round_up(tmax);
  rentry_t stack[QK__CSTACK_MAX];
  int sp = 0;
  uint32_t cur = 0;
  for (;;) {
    const cnode_t *n = &c->cn[cur];
    if (n->child != QK_NONE) {
      float lo4[4];
      unsigned keep = node_slab_general(c, n, ray, tmax, b.t, lo4);
      if (keep) {
        const unsigned v = visit[ray->s][keep];
        for (unsigned j = v >> 2 & 3, o = v >> 4; j > 0; j--, o >>= 2)
          stack[sp++] = (rentry_t){n->child + lane_quadrant[o & 3], 0, lo4[o & 3]};
        cur = n->child + lane_quadrant[v & 3];
        continue;
      }
    } else {
      const double best0 = b.t;
      scan_leaf(c, ray, n->start, n->start + n->count, tmax, scaled, &b);
      if (b.t != best0) tf = round_up(b.t); /* b.t <= tmax: the items test t <= tmax */
    }
    while (sp > 0 && stack[sp - 1].bound > tf) sp--;
    if (sp == 0) break;
    cur = stack[--sp].link;
  }
  hit->id = b.id;
  hit->t = b.id == QK_NONE ? INFINITY : b.t;
}

#if defined(__SSE2__)
/*
 * The float test of fact (2) on the four children of a qnode_t at once: bit k is set when
 * child k is kept, and bound[k] receives L. The grid steps are put in entry / exit order
 * per axis (one swap of 32-bit groups), widened to floats and mapped exactly to the grid
 * values; then four subtractions, four multiplications, two maxima, two minima and a
 * comparison for the four children together.
 */
static inline unsigned qnode_slab_float(const qnode_t *q, const ray_t *r, __m128 tv,
                                        float bound[4]) {
  __m128i raw = _mm_load_si128((const __m128i *)(const void *)q->q);
  const __m128i sw = _mm_shuffle_epi32(raw, _MM_SHUFFLE(1, 0, 3, 2));
  raw = _mm_xor_si128(raw, _mm_and_si128(_mm_xor_si128(raw, sw), r->swap));
  const __m128i z = _mm_setzero_si128();
  const __m128i near16 = _mm_unpacklo_epi8(raw, z), far16 = _mm_unpackhi_epi8(raw, z);
  /* sc's mantissas hold the entry's parent (see qnode_t): masked off, sc exactly */
  const __m128 h = _mm_and_ps(
      _mm_load_ps(q->h), _mm_castsi128_ps(_mm_set_epi32((int)~QK__MANT, (int)~QK__MANT, -1, -1)));
  const __m128 lox = _mm_shuffle_ps(h, h, 0x00), loy = _mm_shuffle_ps(h, h, 0x55);
  const __m128 scx = _mm_shuffle_ps(h, h, 0xAA), scy = _mm_shuffle_ps(h, h, 0xFF);
  const __m128 nx =
      _mm_add_ps(lox, _mm_mul_ps(_mm_cvtepi32_ps(_mm_unpacklo_epi16(near16, z)), scx));
  const __m128 ny =
      _mm_add_ps(loy, _mm_mul_ps(_mm_cvtepi32_ps(_mm_unpackhi_epi16(near16, z)), scy));
  const __m128 fx = _mm_add_ps(lox, _mm_mul_ps(_mm_cvtepi32_ps(_mm_unpacklo_epi16(far16, z)), scx));
  const __m128 fy = _mm_add_ps(loy, _mm_mul_ps(_mm_cvtepi32_ps(_mm_unpackhi_epi16(far16, z)), scy));
  const __m128 tnx = _mm_mul_ps(_mm_sub_ps(nx, r->pnx), r->inx);
  const __m128 tfx = _mm_mul_ps(_mm_sub_ps(fx, r->pfx), r->ifx);
  const __m128 tny = _mm_mul_ps(_mm_sub_ps(ny, r->pny), r->iny);
  const __m128 tfy = _mm_mul_ps(_mm_sub_ps(fy, r->pfy), r->ify);
  const __m128 l = _mm_max_ps(_mm_max_ps(tnx, tny), _mm_setzero_ps());
  const __m128 u = _mm_min_ps(_mm_min_ps(tfx, tfy), tv);
  _mm_storeu_ps(bound, l);
  return (unsigned)_mm_movemask_ps(_mm_cmple_ps(l, u));
}

/*
 * The search with the float test over the subtree of quads entry `from` (its own box
 * untested), into *bp; entry `skip` (QK_NONE: none), a child of `from`, is passed over
 * with all beneath it: its lane is dropped from the first node's kept lanes, so that it
 * is neither stacked nor visited. A node that keeps no child jumps to the pop, which sits
 * in the loop over leaves.
 */
static QK__ALWAYS_INLINE void walk_float(const qk_collider_t *c, const ray_t *rp, double tmax,
                                         uint32_t from, uint32_t skip, best_t *bp, float *tfp) {
  const ray_t *const ray = rp;
  best_t b = *bp;
  /* T of fact (2): min(tmax, best) rounded up to float, kept by the caller from one search
   * to the next (it only shrinks, and only here). */
  float tf = *tfp;
  __m128 tv = _mm_set1_ps(tf);
  rentry_t stack[QK__CSTACK_MAX];
  int sp = 0;
  const unsigned s = ray->s;
  const qnode_t *quads = c->quads;
  const qnode_t *q = &quads[from];
  /* The leaves' item records: discs with ids, else boxes (32 bytes a slot either way). */
  const char *const leaf_base = c->sdisc ? (const char *)c->sdisc : (const char *)c->sbox;
  float lo4[4];
  unsigned keep = qnode_slab_float(q, ray, tv, lo4);
  if (skip != QK_NONE) { /* a constant at the first search's call: no code there */
    /* The children of `from` but `skip`, which the caller has searched (its lane found by
     * comparing the four links at once: only an internal child can match), so that it is
     * neither stacked nor visited. */
    const __m128i is_skip =
        _mm_and_si128(_mm_cmpeq_epi32(_mm_load_si128((const __m128i *)(const void *)q->link),
                                      _mm_set1_epi32((int)skip)),
                      _mm_cmpeq_epi32(_mm_load_si128((const __m128i *)(const void *)q->count),
                                      _mm_set1_epi32(-1)));
    keep &= ~(unsigned)_mm_movemask_ps(_mm_castsi128_ps(is_skip));
  }
  rentry_t cur;
  for (;;) {
    if (keep) {
      /* The kept children in the order the ray meets their squares (the item boxes
       * mostly follow it; the bounds keep the pruning exact whatever the order): the
       * nearest is taken at once, the others stacked far to near, each with its
       * memory asked for now so that the misses overlap the work on the nearest. */
      const unsigned v = visit[s][keep], k0 = v & 3;
      for (unsigned j = v >> 2 & 3, o = v >> 4; j > 0; j--, o >>= 2) {
        const unsigned k = o & 3;
        const uint32_t nx = q->link[k], cnt = q->count[k];
        stack[sp++] = (rentry_t){nx, cnt, lo4[k]};
        /* The address by a conditional move, not a branch (which mispredicted 0.4 times a
         * ray): two lines from the entry (the next is its first child's when internal) or
         * from the leaf's first item record (32 bytes a slot either way), as in
         * prefetch_climbs (the second line: 2% less CPU time in a same-process A/B). */
        const char *p = cnt == QK_NONE ? (const char *)quads + (size_t)nx * sizeof(qnode_t)
                                       : leaf_base + (size_t)nx * 32;
        QK__CPREFETCH(p);
        QK__CPREFETCH((const void *)((uintptr_t)p + 64)); /* may pass the end of sbox */
      }
      cur = (rentry_t){q->link[k0], q->count[k0], 0.0f};
    } else {
      goto pop;
    }
    /* Leaves are scanned, and the stack popped, until an entry comes up to be tested. */
    while (cur.count != QK_NONE) {
      const double best0 = b.t;
      scan_leaf(c, ray, cur.link, cur.link + cur.count, tmax, 0, &b);
      if (b.t != best0) {
        tf = round_up_t(b.t); /* b.t <= tmax: the items test t <= tmax */
        tv = _mm_set1_ps(tf);
      }
    pop:
      /* Next, the nearest stacked node that may still hold a hit no farther than best
       * (its bound re-checked: best may have come closer since it was stacked). */
      while (sp > 0 && stack[sp - 1].bound > tf) sp--;
      if (sp == 0) goto done;
      cur = stack[--sp];
    }
    q = &quads[cur.link];
    keep = qnode_slab_float(q, ray, tv, lo4);
  }
done:
  *bp = b;
  *tfp = tf;
}

/* The Morton code of (x, y): the bits of x at the even positions of a 64-bit word, those
 * of y at the odd ones; both axes spread at once in the two 64-bit lanes. */
static inline uint64_t morton32(uint32_t x, uint32_t y) {
#if !defined(__x86_64__) && !defined(_M_X64) /* no 64-bit move out of a vector register */
  uint64_t v[2] = {x, y};
  for (int k = 0; k < 2; k++) {
    v[k] = (v[k] | v[k] << 16) & 0x0000FFFF0000FFFFull;
    v[k] = (v[k] | v[k] << 8) & 0x00FF00FF00FF00FFull;
    v[k] = (v[k] | v[k] << 4) & 0x0F0F0F0F0F0F0F0Full;
    v[k] = (v[k] | v[k] << 2) & 0x3333333333333333ull;
    v[k] = (v[k] | v[k] << 1) & 0x5555555555555555ull;
  }
  return v[0] | v[1] << 1;
#else
  __m128i v = _mm_set_epi64x((long long)y, (long long)x);
  v = _mm_and_si128(_mm_or_si128(v, _mm_slli_epi64(v, 16)), _mm_set1_epi64x(0x0000FFFF0000FFFFll));
  v = _mm_and_si128(_mm_or_si128(v, _mm_slli_epi64(v, 8)), _mm_set1_epi64x(0x00FF00FF00FF00FFll));
  v = _mm_and_si128(_mm_or_si128(v, _mm_slli_epi64(v, 4)), _mm_set1_epi64x(0x0F0F0F0F0F0F0F0Fll));
  v = _mm_and_si128(_mm_or_si128(v, _mm_slli_epi64(v, 2)), _mm_set1_epi64x(0x3333333333333333ll));
  v = _mm_and_si128(_mm_or_si128(v, _mm_slli_epi64(v, 1)), _mm_set1_epi64x(0x5555555555555555ll));
  v = _mm_or_si128(v, _mm_slli_epi64(_mm_unpackhi_epi64(v, v), 1));
  return (uint64_t)_mm_cvtsi128_si64(v);
#endif
}

/*
 * Asks for what the first two climbs of cast_float read: the other children of the two
 * nodes above the start N (path[n - 1], path[n - 2]; those the descent has filled in, from
 * path[known] on), as their entries in quads or their leaves' disc records. A climb's reads
 * otherwise begin only when the search below has ended, one chain of misses after the
 * other, and most rays climb (at 10^6 discs 68% at least once, 42% twice, 23% three times);
 * asked for here, these misses overlap those of N's own leaves. Some lines are asked for
 * in vain (the children the ray passes by, the climbs not made). A prefetch changes no
 * result.
 */
/* Always inlined: gcc 12 counts __builtin_prefetch as free of side effects, finds a helper
 * made of nothing else "pure", and deletes a call to it, whose result (void) is unused.
 * Until the twelfth session the leaves' prefetch (prefetch_discs, called here and for the
 * origin's leaf) was such a call: the origin leaf's records and the climbs' leaves were
 * never asked for. -fdump-tree-optimized shows whether the prefetches remain. */
static QK__ALWAYS_INLINE void prefetch_climbs(const qk_collider_t *c, const uint32_t *path,
                                              unsigned n, unsigned known) {
  if (c->n_discs != c->n) return;
  const char *qb = (const char *)c->quads, *sb = (const char *)c->sdisc;
  for (unsigned a = n, up = 0; a > known && up < 2; a--, up++) {
    const qnode_t *q = &c->quads[path[a - 1]];
    for (unsigned k = 0; k < 4; k++) {
      /* Without branches (they mispredicted 1.9 times a ray): two lines from the child's
       * first, its entry and the next (in pre-order its first child's, when internal), or
       * a leaf's first two lines of records (4.4 discs on average; the hardware's
       * adjacent-line fetch mostly brings the rest). The child searched already (path[a])
       * and empty children (slot 0) are asked for in vain, at no cost but the asking. */
      const uint32_t l = q->link[k], cnt = q->count[k];
      const char *p =
          cnt == QK_NONE ? qb + (size_t)l * sizeof(qnode_t) : sb + (size_t)l * sizeof(sdisc_t);
      QK__CPREFETCH(p);
      QK__CPREFETCH((const void *)((uintptr_t)p + 64)); /* (may pass an array's end) */
    }
  }
}

/*
 * The climbs' stop: the deepest level a (0 .. 32) such that the box [lo, hi] (x in lane 0,
 * y in lane 1) lies strictly inside the origin's level-a square, the cells of the path's
 * 32-bit fixed point (ix, iy) that share their first a bits (f = 2^32 / side of the
 * root, rs = its corner). On each axis the ends are converted to fixed point,
 * ul = (lo - rs) f and uh = (hi - rs) f, each within 2^-19 of its exact value (three
 * roundings of 2^-53 relatively, below 2^32), and moved outwards: A = trunc(fl(ul - 2 -
 * 2^31)) + 2^31 < ul - 1 + 2^-21 and B = trunc(fl(uh + 2 - 2^31)) + 2^31 > uh + 1 - 2^-21
 * (the 2^31 shift makes the conversion's signed range the unsigned one; truncation
 * errs by less than 1, the subtraction by at most 2^-22). If A and B share their first a
 * bits with the path's, the exact ends lie strictly after the cell's start (at most A)
 * and before its end (beyond B): the side holds [lo, hi] with the exact corner
 * rs + (first a bits) side 2^-32, which the margin of cast_float relates to the tree's
 * square. The first level at which either end of either axis leaves the path's cells is
 * the count of leading zeros of the bits that differ, over all four at once. Ends within
 * two units of the root's edges, beyond them or infinite give 0 (the root).
 */
static inline unsigned climb_stop(__m128d lo, __m128d hi, __m128d rs, __m128d f, __m128i path) {
  const __m128d ul = _mm_mul_pd(_mm_sub_pd(lo, rs), f), uh = _mm_mul_pd(_mm_sub_pd(hi, rs), f);
  const __m128d ok =
      _mm_and_pd(_mm_cmpge_pd(ul, _mm_set1_pd(2.0)), _mm_cmplt_pd(uh, _mm_set1_pd(0x1p32 - 2)));
  const __m128i a = _mm_cvttpd_epi32(_mm_sub_pd(ul, _mm_set1_pd(0x1p31 + 2)));
  const __m128i b = _mm_cvttpd_epi32(_mm_add_pd(uh, _mm_set1_pd(2 - 0x1p31)));
  __m128i diff = _mm_or_si128(_mm_xor_si128(a, path), _mm_xor_si128(b, path));
  diff = _mm_or_si128(diff, _mm_shuffle_epi32(diff, _MM_SHUFFLE(1, 1, 1, 1)));
  const uint32_t v = (uint32_t)_mm_cvtsi128_si32(diff);
  if (_mm_movemask_pd(ok) != 3) return 0; /* (also for NaN, and a NaN f) */
#if defined(__GNUC__)
  return v ? (unsigned)__builtin_clz(v) : 32;
#else
  unsigned n = 0;
  while (n < 32 && !(v >> (31 - n) & 1)) n++;
  return n;
#endif
}

/* Levels above the origin's deepest internal node at which the local search starts: none
 * since a climb no longer visits the child it has searched (one level up cost 14 more
 * instructions a ray at 10^6 discs, 15 at 10^4, 21 at 10^5, and 0.1-0.7 more
 * mispredicted branches; the misses the same). */
#define QK__RAY_START_UP 0

/*
 * The cast with the float test, in two steps. Most rays end near their origin, and a
 * search from the root spends most of its work testing the boxes on the way down to it.
 * So the descent to the origin first goes by the bits of the origin's position alone
 * (no box tests), and the search proper starts at N, the deepest internal node
 * there, which yields the first hit t1 among N's items (or t1 = tmax). Any other item
 * that the ray meets at t <= t1 has its centre outside N's square (centres strictly
 * inside a node's square are all beneath it) and, by fact (1), the point o + t d of the
 * hit within reach + w of that centre on each axis. So when the segment from o to
 * o + t1 d stays farther than that from the edges of the square of an ancestor A of N,
 * every such item lies beneath A. So while the segment is not inside the square of the
 * node searched last (N first), the search goes on from that node's parent with the best
 * so far, passing over the node, which it has done; the best only comes closer, and the
 * root holds every item. Most rays stop at N. The margin adds w for the roundings
 * of reach, of the segment's end and of the comparisons (each below 2^-48 of the
 * magnitudes involved), and 2^-45 of the root square's for the corners: here they are
 * the root's corner plus the path's bits times side / 2^32 (exact: climb_stop compares
 * in fixed point, its conversions' errors inside its two units of slack), where the
 * tree adds halves level by level (one rounding each, 60 levels at most), so the two
 * differ by less than 2^-46 of it. The descent need not pick, near a midline, the child
 * the tree would pick for the origin: the nodes on the path are nodes of the tree
 * whatever the bits, and only the check above decides. The answer is the smallest
 * (t, id) over A's items, the same as a search from the root finds.
 */
static QK__ALWAYS_INLINE void cast_float(const qk_collider_t *c, const ray_t *ray, double tmax,
                                         qk_hit_t *hit) {
  best_t b = {INFINITY, QK_NONE};
  const cnode_t *root = &c->cn[0];
  if (root->child == QK_NONE) {
    scan_leaf(c, ray, root->start, root->start + root->count, tmax, 0, &b);
  } else {
    const qk_tree_t *t = c->tree;
    /* The path, by the bits of the origin's position in the root square in 32-bit fixed
     * point (a lane's two bits per level): entries in quads. */
    uint32_t path[33];
    const double ox = ray->ox, oy = ray->oy;
    const double f = c->rs_f, ux = (ox - c->rs_x) * f, uy = (oy - c->rs_y) * f;
    uint32_t e = root->quad, ix = 0, iy = 0;
    path[0] = e;
    unsigned d = 0, known = 0; /* path[known .. d] are filled */
    /* (f is NaN for a root square below 2^-900: no local start; see fill_slots) */
    if (ux >= 0 && ux < 0x1p32 && uy >= 0 && uy < 0x1p32) {
      const qnode_t *quads = c->quads;
      ix = (uint32_t)ux, iy = (uint32_t)uy;
      uint64_t z = morton32(ix, iy); /* the lanes, root first, from bit 63 */
      if (c->ztab) {                 /* the first levels from the start table (fill_ztab) */
        const uint32_t *cell = &c->ztab[2 * (z >> (64 - 2 * c->zdepth))];
        known = d = cell[0] & ((1u << ZTAB_DEPTH_BITS) - 1);
        path[d] = e = cell[0] >> ZTAB_DEPTH_BITS;
        if (d > 0) path[--known] = cell[1]; /* the start is at depth d - 1 or below */
        /* The descent reads the cell's node and then, mostly, one of its children: in
         * quads' pre-order the node's subtree follows it, 4-16 entries on average at the
         * table's depth (see build_ztab), its children among the first. Their lines are
         * asked for with the node's, so that the second read of the descent does not wait
         * for the first (the lines past the subtree are asked for in vain). So is the
         * parent's, which prefetch_climbs reads. */
        if (c->ray_prefetch) {
          for (uint32_t k = 1; k <= QK__RAY_SUBTREE_LINES; k++) QK__CPREFETCH(&quads[e + k]);
          if (d > 0) QK__CPREFETCH(&quads[cell[1]]);
        }
        z <<= 2 * d;
      }
      while (d < 32) {
        const unsigned lane = (unsigned)(z >> 62);
        const qnode_t *q = &quads[e];
        if (q->count[lane] != QK_NONE) {
          /* The origin's leaf, which the search below reaches after a few node tests:
           * its items and ids asked for now, so that those misses overlap the tests. */
          const uint32_t st = q->link[lane], cnt = q->count[lane];
          if (cnt > 0) {
            if (c->n_discs == c->n) {
              /* The leaf's first two lines (ids included; 4.4 discs on average); as in
               * prefetch_climbs, the hardware's adjacent-line fetch mostly brings the rest
               * (all five lines, as before, measured no faster). */
              QK__CPREFETCH(&c->sdisc[st]);
              QK__CPREFETCH((const void *)((uintptr_t)&c->sdisc[st] + 64));
            } else {
              QK__CPREFETCH(c->sdisc ? (const void *)&c->sdisc[st] : (const void *)&c->sbox[st]);
              QK__CPREFETCH(&qk__tree_ids(t)[st]);
            }
          }
          break;
        }
        path[++d] = e = q->link[lane];
        z <<= 2;
      }
    }
    const unsigned n = d > QK__RAY_START_UP ? d - QK__RAY_START_UP : 0;
    for (; known > n; known--) path[known - 1] = qnode_parent(&c->quads[path[known]]);
    if (c->ray_prefetch) prefetch_climbs(c, path, n, known);
    float tf = round_up_t(tmax); /* T of fact (2) for best = infinity (see walk_float) */
    walk_float(c, ray, tmax, path[n], QK_NONE, &b, &tf);
    /* Up from N one level at a time while the segment to the best hit so far (or to
     * tmax) is not inside the square of the node searched: each step searches the
     * parent's other children, which may bring the hit closer. The deepest level whose
     * square holds the widened segment is found from the path's bits (climb_stop), anew
     * only when the best has moved; the climbs stop at or below it. For t1 = infinity the
     * box is infinite (m is, and no NaN arises: |dx|, |dy| >= 2^-100), and the level 0. */
    const double mb = c->reach + 2 * ray->w + c->rs_k;
    const __m128d o2 = _mm_set_pd(oy, ox), d2 = _mm_set_pd(ray->dy, ray->dx);
    const __m128d oa2 = _mm_andnot_pd(_mm_set1_pd(-0.0), o2); /* |ox|, |oy| */
    const __m128d rs2 = _mm_set_pd(c->rs_y, c->rs_x), f2 = _mm_set1_pd(c->rs_f);
    /* the path's bits, shifted as climb_stop's conversions are (lanes 0 and 1) */
    const __m128i p2 =
        _mm_xor_si128(_mm_set_epi32(0, 0, (int)iy, (int)ix), _mm_set1_epi32((int)0x80000000u));
    double t1_seen = -1.0;
    unsigned stop = 0;
    for (unsigned a = n; a > 0; a--) {
      const double t1 = b.t < tmax ? b.t : tmax;
      if (t1 != t1_seen) {
        /* the segment's end, and m = mb + (|ox| + |ex| + |oy| + |ey| + reach) 2^-48 (the sum
         * in any order: its roundings are some 2^-52 of it, far inside the 2^-48) */
        const __m128d e2 = _mm_add_pd(o2, _mm_mul_pd(_mm_set1_pd(t1), d2));
        const __m128d s2 = _mm_add_pd(oa2, _mm_andnot_pd(_mm_set1_pd(-0.0), e2));
        const double m =
            mb + (_mm_cvtsd_f64(s2) + _mm_cvtsd_f64(_mm_unpackhi_pd(s2, s2)) + c->reach) * 0x1p-48;
        const __m128d m2 = _mm_set1_pd(m);
        stop = climb_stop(_mm_sub_pd(_mm_min_pd(o2, e2), m2), _mm_add_pd(_mm_max_pd(o2, e2), m2),
                          rs2, f2, p2);
        t1_seen = t1;
      }
      if (a <= stop) break;
      /* The parent from the line of the node just searched (see qnode_t), whether or not
       * the path holds it already: no branch, no miss. */
      path[a - 1] = qnode_parent(&c->quads[path[a]]);
      walk_float(c, ray, tmax, path[a - 1], path[a], &b, &tf);
    }
  }
  hit->id = b.id;
  hit->t = b.id == QK_NONE ? INFINITY : b.t;
}
#endif

/* The other rays (scaled, far or general test) and builds without SSE2: apart, so that
 * the common ray's call saves and spills nothing for them. */
#if defined(__GNUC__)
__attribute__((noinline))
#endif
static qk_status_t
raycast_rare(const qk_collider_t *c, qk_point_t o, qk_point_t d, double tmax, qk_hit_t *hit) {
  /* The cast's arithmetic squares and multiplies the direction's components with
   * coordinates and radii: a direction whose largest component is beyond 2^100 could
   * overflow there (a radius of 1e10 with a direction of 1e150 did: t = 0, or a miss) and
   * one below 2^-100 underflow. Such a direction is scaled by a power of two to a largest
   * component in [1/2, 1) (a small one) or [2^50, 2^51) (a large one), which is exact (but
   * for a component 2^1000 times smaller than the other, which then underflows: the ray's
   * direction moves by less than 2^-1000 of a radian), and t is scaled back: the same t, to
   * the bit, as the unscaled cast's wherever that one does not overflow. A large direction
   * stops at 2^50 so that t along it stays below 2^975 for any two doubles' distance: at
   * [1/2, 1) it overflowed beyond 2^1023 (from (0, -1e308) along (0, 1e308), a disc at the
   * origin, t = 1, came back at t = inf, and a farther item with a smaller id won the tie of
   * two infinities). Beyond FAR_COORD (coordinates, then ray_disc_scaled()) every direction
   * is scaled to [2^50, 2^51): from (-1e308, -1e308) along (1e-10, 1e-10) t overflowed in
   * the box test, which then reported a box the ray misses at t = inf. A hit whose t, scaled
   * back, is beyond the largest double still reports inf (its id now the nearest item's).
   * An origin within NEAR_COORD of the origin, with discs as near, also takes
   * ray_disc_scaled() (near). */
  const double m = qk__max(fabs(d.x), fabs(d.y)); /* finite: no call to fmax, no spills */
  const double mo = qk__max(fabs(o.x), fabs(o.y));
  const int far = qk__max(mo, c->mag) > FAR_COORD, near = c->tiny_discs && mo < NEAR_COORD;
  int e = 0;
  if (m > 0 && (far || m > 0x1p100 || m < 0x1p-100)) {
    (void)frexp(m, &e); /* m in [2^(e-1), 2^e) */
    if (far || m > 0x1p100) e -= 51;
    d.x = ldexp(d.x, -e);
    d.y = ldexp(d.y, -e);
    tmax = ldexp(tmax, e); /* t along d / 2^e is t along d times 2^e */
  }
  ray_t ray;
  ray_init(&ray, c, o, d);
#if defined(__SSE2__)
  if (ray.simd && !far && !near)
    cast_float(c, &ray, tmax, hit);
  else
#endif
    cast_general(c, &ray, tmax, far || near, hit);
  if (e != 0 && hit->id != QK_NONE) hit->t = ldexp(hit->t, -e);
  return QK_OK;
}

qk_status_t qk_collider_raycast(const qk_collider_t *c, qk_point_t o, qk_point_t d, double tmax,
                                qk_hit_t *hit) {
  if (!c || !hit) return QK_ERR_INVALID;
  hit->id = QK_NONE;
  hit->t = INFINITY;
  /* v - v is 0 for a finite v and NaN otherwise: one test for the four. */
  if ((o.x - o.x) + (o.y - o.y) + (d.x - d.x) + (d.y - d.y) != 0) return QK_ERR_NONFINITE;
  if (isnan(tmax) || tmax < 0) return QK_ERR_INVALID;
  if (c->n == 0) return QK_OK;
  if (atomic_load_explicit(&c->rays_state, memory_order_acquire) != RAYS_READY) {
    /* the first cast: no call (and no spills around it) on the others */
    const qk_status_t st = qk__collider_rays_ready(c);
    if (st != QK_OK) return st;
  }
#if defined(__SSE2__)
  /* The common ray, in one branch: components and coordinates within the float test's
   * ranges (ray_init's simd), which also leave the direction unscaled and the
   * coordinates below FAR_COORD, and no disc test to scale up (raycast_rare's near); the
   * same cast as below, with only what it reads set. */
  {
    const double ax = fabs(d.x), ay = fabs(d.y), oo = qk__max(fabs(o.x), fabs(o.y));
    const double mo = qk__max(oo, c->mag);
    if (c->quads &&
        ((int)(mo <= 0x1p100) & (int)(qk__min(ax, ay) >= 0x1p-100) &
         (int)(qk__max(ax, ay) <= 0x1p100) & (int)(oo >= NEAR_COORD || !c->tiny_discs))) {
      ray_t ray;
      ray_init_common(&ray, c, o, d);
      ray_init_float(&ray, o, d);
      cast_float(c, &ray, tmax, hit);
      return QK_OK;
    }
  }
#endif
  return raycast_rare(c, o, d, tmax, hit);
}
