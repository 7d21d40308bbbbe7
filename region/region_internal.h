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

/* One leaf of the index: its edges [e0, e0 + ne) and the features containing its
 * reference point [s0, s0 + ns) of the set array, in increasing order. The reference
 * point is the centre of its square, x0 + side / 2, which the descent recomputes from
 * the square it arrives with (the same operations as the build, so the same doubles). */
typedef struct qk__leaf {
  uint32_t e0, ne;
  uint32_t s0, ns;
} qk__leaf_t;

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

  /* Every edge piece, grouped by feature (for drawings). */
  qk__seg_t *segs;
  uint32_t *seg_feat;
  size_t n_segs, cap_segs, cap_seg_feat;

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

/* Locate in one leaf; used by every query. */
uint32_t qk__region_locate1(const qk_region_t *r, double x, double y, qk_boundary_t b);

#endif /* QUADKIT_REGION_INTERNAL_H */
