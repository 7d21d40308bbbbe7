/*
 * Private helpers of the collide module (the static collider and the world): the
 * traversal stack bound and entries, and the allocation and tree accessors it reads
 * through index/index_access.h. Not API; collide/ depends on index/ only.
 */
#ifndef QUADKIT_COLLIDE_INTERNAL_H
#define QUADKIT_COLLIDE_INTERNAL_H

#include <math.h>

#include "index/index_access.h"
#include "quadkit/collide.h"

/*
 * Deepest possible traversal stack: a depth-first search pops one node and pushes at
 * most four children, so it never holds more than 3 per level plus 4.
 */
#define QK__CSTACK_MAX (3 * (QK_MAX_DEPTH_LIMIT + 2) + 8)

/* A stacked node with the lower bound that let it in (re-checked when popped, because
 * the pruning threshold may have shrunk meanwhile). */
typedef struct qk__centry {
  uint32_t node;
  double bound;
} qk__centry_t;

/* Sort up to four stacked entries by descending bound, so the nearest is popped first. */
static inline void qk__csort4_desc(qk__centry_t *e, int n) {
  for (int i = 1; i < n; i++) {
    qk__centry_t v = e[i];
    int j = i - 1;
    while (j >= 0 && e[j].bound < v.bound) {
      e[j + 1] = e[j];
      j--;
    }
    e[j + 1] = v;
  }
}

/* ---- the static collider's parts shared with collide/collider_batch.c --------------- */

/* The leaves whose boxes meet one internal node's (the parent of the leaves searched
 * next), kept by the caller of qk__collider_leaf_pairs between calls: parent QK_NONE
 * before the first (a search's own; the collider must not change meanwhile). */
#define QK__FAMILY_MAX 128
typedef struct qk__pairs_cache {
  uint32_t parent;
  uint32_t n; /* QK_NONE: the leaves of this parent search on their own */
  uint32_t leaf[QK__FAMILY_MAX];
} qk__pairs_cache_t;

/* Pairs of the items of one leaf with those of every leaf whose box meets its own, as
 * qk_collider_pairs() reports them; nonzero when fn asked to stop. */
int qk__collider_leaf_pairs(const qk_collider_t *c, uint32_t leaf, qk__pairs_cache_t *pc,
                            qk_pair_fn fn, void *ud);
/* fn on every non-empty leaf in the order qk_collider_pairs() visits them; nonzero when
 * fn asked to stop. */
int qk__collider_each_leaf(const qk_collider_t *c, int (*fn)(uint32_t leaf, void *ud), void *ud);
/* qk_collider_pairs() on the calling thread. */
void qk__collider_pairs_serial(const qk_collider_t *c, qk_pair_fn fn, void *ud);
/* qk_collider_pairs() on the collider's threads: QK_OK, or QK_ERR_NOMEM (nothing
 * reported yet: the caller then runs the serial search). */
qk_status_t qk__collider_pairs_threaded(const qk_collider_t *c, qk_pair_fn fn, void *ud);
/* The ray cast's structures for a cast on a const collider, made on first need
 * (qk_collider_prepare_rays): QK_OK or QK_ERR_NOMEM. The fast path is one acquire load. */
qk_status_t qk__collider_rays_ready(const qk_collider_t *c);
/* The threads option as set (0: every online core), and the allocator. */
uint32_t qk__collider_threads(const qk_collider_t *c);
const qk_allocator_t *qk__collider_alloc(const qk_collider_t *c);

/* ---- the world's shapes (collide/shape.c, collide/exact.c) ------------------------ */

/* Exact signs: orientation of c relative to a->b; (b-a).(c-a); (r1+r2)^2 - |a-b|^2;
 * r^2 |q-p|^2 - ((q-p) x (c-p))^2. Inputs must satisfy qk__value_ok. */
int qk__orient(double ax, double ay, double bx, double by, double cx, double cy);
int qk__dot_sign(double ax, double ay, double bx, double by, double cx, double cy);
int qk__within(double ax, double ay, double bx, double by, double r1, double r2);
int qk__line_within(double px, double py, double qx, double qy, double cx, double cy, double r);
/* The values of qk__orient's, qk__dot_sign's, qk__within's and qk__line_within's
 * polynomials, to within
 * 2^-54 of themselves (exactly summed where their terms cancel): for the distances and ray
 * parameters that order query answers. Same inputs. */
long double qk__orient_value(double ax, double ay, double bx, double by, double cx, double cy);
long double qk__dot_value(double ax, double ay, double bx, double by, double cx, double cy);
long double qk__within_value(double ax, double ay, double bx, double by, double r1, double r2);
long double qk__line_within_value(double px, double py, double qx, double qy, double cx, double cy,
                                  double r);

/* qk__orient with its floating-point filter inline (the same filter, 8 ulps of the two
 * products: the same answers), the call only for the signs the filter cannot decide. */
static inline int qk__orient_fast(double ax, double ay, double bx, double by, double cx,
                                  double cy) {
  double l = (bx - ax) * (cy - ay), r = (by - ay) * (cx - ax);
  double det = l - r, bound = 0x1p-50 * (fabs(l) + fabs(r));
  if (det > bound) return 1;
  if (-det > bound) return -1;
  return qk__orient(ax, ay, bx, by, cx, cy);
}

/* Zero, or magnitude in [2^-100, 2^100]: the range in which the predicates are exact. */
static inline int qk__value_ok(double v) {
  double a = fabs(v);
  return v == 0 || (a >= 0x1p-100 && a <= 0x1p100);
}

/* max and min of values known not to be NaN (cheaper than fmax / fmin calls). */
static inline double qk__max(double a, double b) { return a > b ? a : b; }
static inline double qk__min(double a, double b) { return a < b ? a : b; }
/* Check a shape and normalise it (box corners min then max, unused values zeroed). */
qk_status_t qk__shape_normalize(const qk_shape_t *in, qk_shape_t *out);
/* Bounding box, rounded outwards (contains the shape exactly). */
qk_box_t qk__shape_box(const qk_shape_t *s);
/* Exact closed overlap of two normalised shapes. */
int qk__shapes_overlap(const qk_shape_t *a, const qk_shape_t *b);
/* Distance from p to a shape (0 exactly when p is in it). */
double qk__shape_dist(const qk_shape_t *s, qk_point_t p);
/* Parameter in [0, 1] of the first contact of the segment o -> to with a shape it meets. */
double qk__ray_param(const qk_shape_t *s, qk_point_t o, qk_point_t to);

#endif /* QUADKIT_COLLIDE_INTERNAL_H */
