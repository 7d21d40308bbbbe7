/*
 * Private declarations of region/, shared by its files only. Not API.
 */
#ifndef QUADKIT_REGION_INTERNAL_H
#define QUADKIT_REGION_INTERNAL_H

#include <math.h>
#include <stdbool.h>
#include <stdint.h>

#include "quadkit/region.h"
#include "index/index_access.h"

/* ---- exact predicates (predicates.c) --------------------------------------------- */

/* Sign of the orientation of (a, b, c) computed exactly: +1 left turn, -1 right, 0. */
int qk__orient_exact(double ax, double ay, double bx, double by, double cx, double cy);

/* fmin / fmax without the NaN rules (the library calls are not inlined). */
static inline double qk__min(double a, double b) { return a < b ? a : b; }
static inline double qk__max(double a, double b) { return a > b ? a : b; }

/* Shewchuk's bound for the filter: (3 + 16 eps) eps, eps = 2^-53. */
#define QK__ORIENT_ERR (3.3306690738754716e-16)

/* Orientation sign, exact: a floating-point filter first, the exact sum when needed. */
static inline int qk__orient(double ax, double ay, double bx, double by, double cx, double cy) {
  double l = (bx - ax) * (cy - ay), r = (by - ay) * (cx - ax);
  double d = l - r, bound = QK__ORIENT_ERR * (fabs(l) + fabs(r));
  if (d > bound) return 1;
  if (-d > bound) return -1;
  return qk__orient_exact(ax, ay, bx, by, cx, cy);
}

/*
 * The symbolic perturbation behind the semi-open rule: every query point (and every
 * reference point of the index) is moved by (e, e^2) for an infinitesimal e > 0. Side of
 * p + (e, e^2) against the line a->b: never 0 for a non-degenerate edge.
 */
static inline int qk__side(double ax, double ay, double bx, double by, double px, double py) {
  int o = qk__orient(ax, ay, bx, by, px, py);
  if (o) return o;
  /* orient(a, b, p + d) = orient(a, b, p) + (bx - ax) e^2 - (by - ay) e */
  if (by != ay) return by > ay ? -1 : 1;
  return bx > ax ? 1 : -1;
}

/* Side of the vertex q - (e, e^2) against the line c->p (c != p): the same perturbation,
 * seen from the segment. orient(c, p, q - d) = orient(c, p, q) + (py - cy) e - (px - cx) e^2. */
static inline int qk__side_of_vertex(double cx, double cy, double px, double py, double qx,
                                     double qy) {
  int o = qk__orient(cx, cy, px, py, qx, qy);
  if (o) return o;
  if (py != cy) return py > cy ? 1 : -1;
  return px > cx ? -1 : 1;
}

/* Does the perturbed segment c->p cross the perturbed edge a->b? `sc` is
 * qk__side(a, b, c), kept per leaf edge; c != p. */
static inline bool qk__crosses(double cx, double cy, double px, double py, double ax, double ay,
                               double bx, double by, int sc) {
  if (qk__side(ax, ay, bx, by, px, py) == sc) return false;
  return qk__side_of_vertex(cx, cy, px, py, ax, ay) != qk__side_of_vertex(cx, cy, px, py, bx, by);
}

/* Is p on the closed segment a-b (exactly)? */
static inline bool qk__on_edge(double ax, double ay, double bx, double by, double px, double py) {
  if (px < qk__min(ax, bx) || px > qk__max(ax, bx) || py < qk__min(ay, by) || py > qk__max(ay, by))
    return false;
  return qk__orient(ax, ay, bx, by, px, py) == 0;
}

/* ---- layers ------------------------------------------------------------------------ */

/* One edge piece. */
typedef struct qk__seg {
  double ax, ay, bx, by;
} qk__seg_t;

/* One leaf of the index: its edges [e0, e0 + ne) and its *short set* [s0, s0 + ns) of
 * the set array, in increasing order: the features containing its reference point that
 * have pieces in the leaf, and the lowest of those that have none (which hold the whole
 * closed square: its *cover*), all that the lowest feature holding a point needs. The
 * rest of the cover is kept apart (qk__cover_t), for queries of every feature. The
 * reference point is the centre of its square, x0 + side / 2, which the descent
 * recomputes from the square it arrives with (the same operations as the build, so the
 * same doubles). */
typedef struct qk__leaf {
  uint32_t e0, ne;
  uint32_t s0, ns;
  /* The box of the leaf's edges, rounded outwards to floats (qk__emit_leaf, as the
   * leaf is made): a query whose segment reference point -> point lies strictly beside it
   * crosses and touches none of them, and reads none (region/locate.c). */
  float ex0, ey0, ex1, ey1;
} qk__leaf_t;

/*
 * Where leaf i's cover (the features holding its whole closed square, in increasing
 * order) is kept: cover[ck] = m and cover[ck + 1 .. ck + m] are the cover of the last
 * *checkpoint* leaf at or before i, and cover[start, end) the features in one of the two
 * covers only (the change, sorted), start being the larger of ck + 1 + m and leaf i - 1's
 * end (0 for leaf 0): a checkpoint's own change is empty. Leaves next to each other in
 * Z-order mostly share their covers, so on layers of overlapping features (zones,
 * buffers) this takes a few words a leaf, where whole lists took leaves x overlap. A leaf
 * becomes a checkpoint when its change would be longer than its cover or than
 * QK__COVER_CHANGES_MAX words, so that a cover is read in at most about twice its length
 * (and no change needs sorting). Measured on 1,000 overlapping circles: 16 words took 49
 * MB, 32 took 42, 64 took 49 and 128 took 68 (checkpoints kept longer, changes longer).
 */
typedef struct qk__cover {
  uint32_t ck, end;
} qk__cover_t;

#define QK__COVER_CHANGES_MAX 32

/* The flags of seg_tag (features number fewer than 2^29: two bits are free). */
#define QK__SEG_RING_START 1u
#define QK__SEG_ADDED 2u

/* Leaf tags in the node array: kid[v] is the first child of v, or QK__LEAF | leaf, or,
 * for a leaf without edges holding at most one feature at its reference point,
 * QK__LEAF | QK__DIRECT | (feature + 1) (0: none), answered without reading leaves[]. */
#define QK__LEAF 0x80000000u
#define QK__DIRECT 0x40000000u
/* In the grid: descend from the root instead. */
#define QK__REDO 0xffffffffu

/* Properties collected by a reader: moved into the layer on success. */
typedef struct qk__props {
  size_t *start; /* n_features + 1 */
  size_t cap_start;
  size_t *key, *val;
  size_t n, cap_key, cap_val;
  char *pool;
  size_t pool_len, pool_cap;
} qk__props_t;

/* What a reader (GeoJSON, OGR) gathers before qk__region_build: the rings' points (xy,
 * nv points), ring starts (rs, nr rings), feature starts in rings (fs, nf features), the
 * properties, and the counts of skipped features and of holes. */
typedef struct qk__rings {
  double *xy;
  size_t nv, cap_xy;
  size_t *rs;
  size_t nr, cap_rs;
  size_t *fs;
  size_t nf, cap_fs;
  qk__props_t props;
  size_t skipped, holes;
} qk__rings_t;

struct qk_region {
  qk_allocator_t alloc;
  int planar;
  uint32_t n_features;

  /* Properties: feature f owns pairs [props.start[f], props.start[f+1]) (no pairs at all
   * when props.start is NULL); pair i is the NUL-terminated strings props.pool +
   * props.key[i] and props.pool + props.val[i]. */
  qk__props_t props;

  /* Every edge piece, grouped by feature and within it by ring, in ring order (for
   * drawings): seg_tag[i] is piece i's feature << 2 | QK__SEG_RING_START when it is its
   * ring's first piece | QK__SEG_ADDED when lon/lat mode added it along the antimeridian
   * or a pole (qk__pieces_t's vtx UINT32_MAX). */
  qk__seg_t *segs;
  uint32_t *seg_tag;
  size_t n_segs, cap_segs, cap_seg_tag;

  /* The index: the tree (cells only), and flat arrays for the descent. */
  qk_tree_t *tree;
  double rx, ry, rside;
  uint32_t *kid;
  size_t n_kid, cap_kid; /* n_kid: nodes in use */
  qk__leaf_t *leaves;
  size_t n_leaves, cap_leaves;
  size_t n_direct;  /* leaves stored as QK__DIRECT answers */
  uint32_t *le;     /* leaf edges (indices into segs), each leaf's grouped by feature */
  uint32_t *le_tag; /* feature << 1 | (side of the leaf's reference point > 0) */
  size_t n_le, cap_le, cap_le_tag;
  uint32_t *sets;
  size_t n_sets, cap_sets;
  qk__cover_t *cover_at; /* per leaf (qk__cover_t) */
  size_t cap_cover_at;
  uint32_t *cover;
  size_t n_cover, cap_cover;
  /* A shortcut for the top of the descent: the 2^G x 2^G cells of depth G; grid[j << G
   * | i] is the kid[] value of the node the descent reaches at depth G in column i, row
   * j (or of the leaf it stops at before). gx[i] / gy[j] are the cells' lower sides
   * exactly as the descent computes them (gx[2^G] = +inf), so the column a point falls
   * in is found exactly from a rounded guess. G = 0: no grid. */
  unsigned grid_level;
  uint32_t *grid;
  double *gx, *gy;
  double grid_scale; /* 2^G / rside */
  double grid_side;  /* rside / 2^G */
  /* Pure cells, for batches (qk__region_pure_build, region/locate.c): the root square
   * cut in 2^P x 2^P cells (P = pure_level, 0: no table); pure[j << P | i] is 0, or v > 0
   * when the cell (i, j) lies in direct leaves that all answer pure_ans[v - 1]. A batch
   * point whose cell is pure, surely (its cell coordinates farther than pure_eps from an
   * integer), takes that answer without a descent. */
  unsigned pure_level;
  uint8_t *pure;
  double pure_eps;
  uint32_t pure_ans[255];
  /* The query window: a point with qx0 <= x <= qx1 and qy0 <= y <= qy1 lies in the root
   * and needs no longitude wrap (the fast path of the queries' normalisation; empty when
   * qx0 > qx1). */
  double qx0, qx1, qy0, qy1;

  qk_region_stats_t stats;
};

/* Edge pieces of a layer, in feature order (prepare.c). ring[i] is the ring of piece
 * i and vtx[i] the ring vertex it starts from, or UINT32_MAX for the pieces added in
 * lon/lat mode along the antimeridian and the poles. */
typedef struct qk__pieces {
  qk__seg_t *seg;
  uint32_t *feat, *ring, *vtx;
  size_t n, cap;
} qk__pieces_t;

qk_status_t qk__region_prepare(const qk_allocator_t *a, const qk_region_arrays_t *in, int planar,
                               qk__pieces_t *out, qk_error_t *err);
void qk__pieces_free(const qk_allocator_t *a, qk__pieces_t *p);

/* Build a layer from validated-or-not arrays; `props` may be NULL. Takes the props
 * (frees them on error). skipped/holes go to the stats (holes: SIZE_MAX = count rings
 * after each feature's first). */
/* The options in force (the defaults when options is NULL) and the allocator they name
 * (region/region.c). */
void qk__region_options(const qk_region_options_t *options, qk_region_options_t *o,
                        qk_allocator_t *alloc);

/* Room for a ring of n more points at xy + 2 * nv (region/rings.c). */
qk_status_t qk__rings_reserve(const qk_allocator_t *a, qk__rings_t *r, size_t n);
/* The n points written at xy + 2 * nv form the next ring; k > 0 for a hole. */
void qk__rings_close(qk__rings_t *r, size_t n, size_t k);
/* The rings since the last feature form the next feature (its properties are ended
 * separately, by qk__props_end_feature). */
qk_status_t qk__rings_end_feature(const qk_allocator_t *a, qk__rings_t *r);
/* Build the region from what was gathered (qk__region_build). */
qk_status_t qk__rings_build(qk__rings_t *r, const qk_region_options_t *o, qk_region_t **out,
                            qk_error_t *err);
void qk__rings_free(const qk_allocator_t *a, qk__rings_t *r);
/* The GeoJSON text (no byte order mark, no NUL byte) parsed whole by json-c and walked
 * into a layer: what qk_region_read_geojson_text does when a FeatureCollection cannot be
 * read one feature at a time (region/geojson.c), and the tests' oracle for that path. */
qk_status_t qk__geojson_read_whole(const char *text, size_t len, const qk_region_options_t *options,
                                   qk_region_t **out, qk_error_t *err);
/* The start of every reader: clear *err, check path and out, set *out to NULL. */
qk_status_t qk__read_begin(const char *path, qk_region_t **out, qk_error_t *err);

qk_status_t qk__region_build(const qk_region_arrays_t *in, const qk_region_options_t *options,
                             qk__props_t *props, size_t skipped, size_t holes, qk_region_t **out,
                             qk_error_t *err);

/* Fill err (may be NULL) with a message and return st. */
qk_status_t qk__region_fail(qk_error_t *err, qk_status_t st, size_t item, const char *fmt, ...)
#if defined(__GNUC__)
    __attribute__((format(printf, 4, 5)))
#endif
    ;

/* Check one coordinate pair for the mode; returns QK_OK or an error with message. */
qk_status_t qk__region_check_coord(int planar, double x, double y, size_t feature, qk_error_t *err);

/* Properties being collected. */
void qk__props_free(const qk_allocator_t *a, qk__props_t *p);
qk_status_t qk__props_add(const qk_allocator_t *a, qk__props_t *p, const char *key, const char *val,
                          size_t val_len);
qk_status_t qk__props_end_feature(const qk_allocator_t *a, qk__props_t *p, size_t feature);

/* ---- building (build.c, refine.c, build_top.c) ---------------------------------------- */

#define QK__MAXD (QK_MAX_DEPTH_LIMIT + 1)

/* Splits that make no progress are allowed this many levels in a row (a cluster in one
 * quadrant separates after a few). */
#define QK__STALL_BUDGET 2

/* The state of one build. Per depth d along the current path: the pieces meeting the
 * cell (e, ne: increasing piece order) and the features containing its reference point
 * (set, ns: increasing). */
typedef struct qk__bctx {
  qk_region_t *r;
  const qk__pieces_t *pc;
  const qk_region_arrays_t *in;
  uint32_t C, maxd;
  uint32_t *e[QK__MAXD + 1];
  size_t ne[QK__MAXD + 1];
  uint32_t *store[QK__MAXD + 1]; /* per depth: the four children's lists, one after another */
  size_t cap_store[QK__MAXD + 1];
  size_t cnt[QK__MAXD + 1][4];
  const uint32_t *set[QK__MAXD + 1]; /* depth d's set: s[d], or the same list as a parent's
                                        or a grid cell's when no feature flips */
  uint32_t *s[QK__MAXD + 1];
  size_t ns[QK__MAXD + 1], cap_s[QK__MAXD + 1];
  /* per depth: the features whose parity flips from the cell's reference point to each
   * child's, four lists of up to ne[d] + 1 (found while sorting the pieces) */
  uint32_t *odd[QK__MAXD + 1];
  size_t cap_odd[QK__MAXD + 1];
  size_t nodd[QK__MAXD + 1][4];
  uint8_t *bad; /* per ring: self-intersecting */
  unsigned depth;
  size_t splits_left;      /* a budget on splits: see qk__build_node */
  size_t splits_floor;     /* the cell being refined stops splitting at this many left */
  size_t prev_s0, prev_ns; /* the last leaf's short set, in r->sets (qk__emit_leaf) */
  /* qk__emit_leaf's scratch: a leaf's short set and cover, the last checkpoint's cover
   * (ck_cov: qk__cover_t), the change between the two covers; and where the last
   * checkpoint is (cover_ck = UINT32_MAX: none yet) */
  uint32_t *sh, *cov, *ck_cov, *chg;
  size_t cap_sh, cap_cov, cap_ck_cov, cap_chg, n_ck_cov;
  uint32_t cover_ck;
} qk__bctx_t;

/* Whether a split of a cell of n pieces into children of cnt[4] makes progress: every
 * child meets fewer pieces than the cell, or one child meets them all and the others none
 * (a cluster of pieces far from the rest, inside one child: the splits close in on it).
 * Pieces that all pass one point (a vertex of high degree) or overlap (shared edges) never
 * separate, and such cells would otherwise split down to the depth cap; without the
 * second case a compact cluster in a large cell stopped there too (a grid of 1,600 squares
 * 1/100 wide, with another feature at 1 from it, ended as one leaf of 6,400 edges: 8.9 us
 * a locate against 0.3). */
static inline bool qk__split_progress(const size_t cnt[4], size_t n) {
  return (cnt[0] < n && cnt[1] < n && cnt[2] < n && cnt[3] < n) ||
         (cnt[0] != 0) + (cnt[1] != 0) + (cnt[2] != 0) + (cnt[3] != 0) == 1;
}

/* The floor below which child q of a cell (counts cnt[4] of its pieces) stops splitting:
 * the budget left above the cell's own floor is shared among the children not yet
 * refined, q and those after it, in proportion to their pieces, so that the first ones
 * cannot take what the others need (refine.c). */
size_t qk__child_floor(const qk__bctx_t *b, size_t floor, const size_t cnt[4], unsigned q);

/* The lower sides of the 2^G cells at depth G along one axis of the root [r0, r0 + side],
 * halved the way the descent halves them (build.c). */
void qk__region_grid_sides(double r0, double side, unsigned G, double *out);

/*
 * Which children of a cell keep a piece (bit q for child q: NE 0, NW 1, SW 2, SE 3). The
 * cell is [x0, x1] x [y0, y1] with centre (cx, cy); l.. are the piece's box. A child keeps
 * a piece whose box meets its square and, unless the box lies inside the square, whose
 * line has corners of the square on both sides or within a tolerance. That is
 * conservative: it may keep a piece that misses the closed square, never drops one that
 * meets it (an extra piece costs time, not correctness). The line's value at the
 * children's corners is its value at the centre plus multiples of dx h and dy h (h = cx -
 * x0), so one evaluation serves the four children; the tolerance covers the rounding of
 * that sum and of the corners themselves (x0 + h is not exactly the middle). Every build
 * path sorts pieces with this one function, so they all make the same cells.
 */
static inline unsigned qk__clip4(const qk__seg_t *g, double lx, double hx, double ly, double hy,
                                 double x0, double y0, double x1, double y1, double cx, double cy) {
  /* Inside one child's square and off the centre lines (most pieces below the top
   * levels): that child only. */
  if ((lx > cx || hx < cx) && (ly > cy || hy < cy)) {
    bool east = lx > cx, north = ly > cy;
    if ((east ? hx <= x1 : lx >= x0) && (north ? hy <= y1 : ly >= y0))
      return 1u << (north ? (east ? 0u : 1u) : (east ? 3u : 2u));
  }
  bool e = hx >= cx, w = lx <= cx, no = hy >= cy, so = ly <= cy;
  /* Inside one half's strip (a piece across the cell's side, or across the centre line
   * within one half): the children its box reaches. The box meets the cell's square
   * (every cell keeps only such pieces), so within the strip the piece passes through
   * each of those children and the test below would keep it. */
  if (ly > cy && hy <= y1) return (e ? 1u : 0u) | (w ? 2u : 0u);
  if (hy < cy && ly >= y0) return (w ? 4u : 0u) | (e ? 8u : 0u);
  if (lx > cx && hx <= x1) return (no ? 1u : 0u) | (so ? 8u : 0u);
  if (hx < cx && lx >= x0) return (no ? 2u : 0u) | (so ? 4u : 0u);
  const double h = cx - x0;
  double dx = g->bx - g->ax, dy = g->by - g->ay;
  double l = dx * (cy - g->ay), r = dy * (cx - g->ax);
  double v = l - r, a = dx * h, q = dy * h;
  double tol = 1e-12 * (fabs(l) + fabs(r) + fabs(a) + fabs(q) +
                        (fabs(dx) + fabs(dy)) * (fabs(cx) + fabs(cy)));
  /* the line's value over each child's corners: v + dx * [0 or +-h] - dy * [0 or +-h] */
  double ap = qk__max(a, 0), an = qk__min(a, 0), qp = qk__max(q, 0), qn = qk__min(q, 0);
  unsigned m = 0;
  if (e && no && v + an - qp <= tol && v + ap - qn >= -tol) m |= 1u;
  if (w && no && v + an + qn <= tol && v + ap + qp >= -tol) m |= 2u;
  if (w && so && v - ap + qn <= tol && v - an + qp >= -tol) m |= 4u;
  if (e && so && v - ap - qp <= tol && v - an - qn >= -tol) m |= 8u;
  return m;
}

/* Does the segment o -> q between two reference points cross piece g (box lx..hy)? The
 * box test first (qk__ref_crosses): only pieces whose box meets the segment's can cross
 * it. */
static inline bool qk__ref_crosses_line(double ox, double oy, double qx, double qy,
                                        const qk__seg_t *g) {
  /* Both ends surely on one side of the segment's line (qk__orient's filter, without its
   * exact fallback: undecided cases take the full test): no crossing. Most pieces in the
   * segment's box are decided here, by two products each. */
  double ux = qx - ox, uy = qy - oy;
  double la = ux * (g->ay - oy), ra = uy * (g->ax - ox), lb = ux * (g->by - oy),
         rb = uy * (g->bx - ox);
  double da = la - ra, db = lb - rb;
  double ea = QK__ORIENT_ERR * (fabs(la) + fabs(ra)), eb = QK__ORIENT_ERR * (fabs(lb) + fabs(rb));
  if ((da > ea && db > eb) || (da < -ea && db < -eb)) return false;
  int sc = qk__side(g->ax, g->ay, g->bx, g->by, ox, oy);
  return qk__crosses(ox, oy, qx, qy, g->ax, g->ay, g->bx, g->by, sc);
}

static inline bool qk__ref_crosses(double ox, double oy, double qx, double qy, const qk__seg_t *g,
                                   double lx, double hx, double ly, double hy) {
  if (hx < qk__min(ox, qx) || lx > qk__max(ox, qx) || hy < qk__min(oy, qy) || ly > qk__max(oy, qy))
    return false;
  return qk__ref_crosses_line(ox, oy, qx, qy, g);
}

/* The refinement below a cell whose pieces are b->e[d] and set b->set[d] (refine.c): split
 * while more than C pieces meet the cell, else a leaf. */
qk_status_t qk__build_node(qk__bctx_t *b, qk_node_t v, double x0, double y0, double x1, double y1,
                           double side, unsigned d, unsigned stall);
/* Store cell v (at depth d, reference point (cx, cy)) as a leaf with b->e[d], b->set[d]. */
qk_status_t qk__emit_leaf(qk__bctx_t *b, qk_node_t v, double cx, double cy, unsigned d);
/* Give cell v four children, numbered from *first: QK_ERR_LIMIT when the index is full
 * (v stays a leaf). */
qk_status_t qk__split_cell(qk__bctx_t *b, qk_node_t v, uint32_t *first);
/* b->set[d + 1] = b->set[d] with the features of the sorted list odd[0, n) toggled. */
qk_status_t qk__child_set(qk__bctx_t *b, unsigned d, const uint32_t *odd, size_t n);
/* The whole refinement from the root (build_top.c). */
qk_status_t qk__build_top(qk__bctx_t *b);

/* Build the pure cells (after the grid; QK_ERR_NOMEM fails the build), their
 * bytes, and their release (region/locate.c). */
qk_status_t qk__region_pure_build(qk_region_t *r);
size_t qk__region_pure_bytes(const qk_region_t *r);
void qk__region_pure_free(qk_region_t *r);

/* Locate in one leaf; used by every query. */
uint32_t qk__region_locate1(const qk_region_t *r, double x, double y, qk_boundary_t b);

#endif /* QUADKIT_REGION_INTERNAL_H */
