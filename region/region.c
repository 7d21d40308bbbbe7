/*
 * region/: which polygon of a layer holds a point.
 *
 * Design
 * ------
 * A layer is a list of features, each a set of closed rings; a point is inside a feature
 * when a ray from it crosses the feature's rings an odd number of times (even-odd over
 * all rings of the feature, so holes of either winding, overlapping parts and
 * self-intersecting rings need no repair). Rings become *edge pieces* (prepare.c): in
 * planar mode every non-degenerate ring edge; in lon/lat mode the edges are first cut at
 * the antimeridian and closed along it and along a pole (see prepare.c for the exact
 * rules), so that the pieces bound the right regions of the lon/lat rectangle.
 *
 * Semi-open boundaries by symbolic perturbation. Every point that is located (query
 * points and the index's reference points) is moved by (e, e^2), e > 0 infinitesimal.
 * The moved point lies on no edge line, so it is inside or outside each feature without
 * ambiguity, and in a coverage (features sharing edges) it is inside exactly one. The
 * perturbed orientation is the exact orientation with a fixed tie-break on the edge
 * direction (region_internal.h), so the whole rule costs nothing when no tie occurs.
 * The closed and open rules are the semi-open answer plus "is the point on one of the
 * feature's edges" (exact): closed adds those points, open removes them.
 *
 * Exactness. The orientation predicate is a floating-point filter with Shewchuk's error
 * bound and an exact fallback in expansion arithmetic (predicates.c). Every decision of
 * the build and of a query goes through it; the only floating-point computations whose
 * rounding matters are the cells' coordinates, which build and descent compute with the
 * same operations, and antimeridian cut points, which become vertices (both pieces of a
 * cut edge use the same rounded latitude).
 *
 * The index (build.c). The pieces are refined as a quadtree: a cell splits while more
 * than C = options.leaf_edges pieces meet its closed square, up to a depth cap. With
 * options.keep_tree the refinement runs on a quadkit tree (qk_tree_split_leaf, so it is a
 * plain quadkit tree that walks and checks understand, returned by qk_region_tree);
 * without it (the default) the same cells are numbered straight into the query array
 * kid[], which saves the tree's bookkeeping (about 8% of the build's instructions) and
 * its memory. Each cell has a reference point, the centre of its square as
 * computed by the descent. A leaf stores its reference point, the features containing
 * it (those with pieces in the leaf and the lowest of the others, which hold the whole
 * square; the rest as the change from the previous leaf's: qk__cover_t), and copies of
 * its pieces grouped by feature, each with the side of the reference point against it
 * (one bit).
 *
 * The build runs in two stages that make the same cells. The top k levels (4^k about the
 * number of pieces; build_top.c) are made in one pass over the pieces: each piece is
 * located in the 2^k x 2^k grid of level-k cells (its *home*: the deepest cell whose
 * open square holds its box; the few pieces across grid lines are clipped down from
 * there with the refinement's own test), the cells' piece counts and the grid cells'
 * lists (a counting sort) follow, and the split decisions above level k are taken from
 * the counts. The grid cells' reference points are classified by a walk along column 0
 * and then along each row, from centre to centre through the midpoint of the side
 * between them: each half step lies in one cell, so only that cell's pieces whose box
 * reaches the step's line are tested. Below level k (refine.c) a cell's pieces are sorted
 * into its children level by level, and a child's reference point is classified from
 * its parent's by counting the crossings of the segment parent reference -> child
 * reference (the parent's reference is a corner of the child's square, so only the
 * child's pieces can cross it). Every crossing count is exact (perturbed crossing
 * tests), and every list is made by the same conservative test (qk__clip4), so the index
 * does not depend on where the stages meet.
 *
 * Splits also stop when they do not separate the pieces (pieces through one point, or
 * overlapping shared edges) two levels in a row (a split that leaves them all in one
 * child, closing in on a cluster, is progress: qk__split_progress), and when a budget of
 * (pieces + 4096) splits is spent, shared among each cell's children in proportion to
 * their pieces (qk__child_floor), so adversarial input cannot make the index explode.
 *
 * Layout for queries (build.c). The cells form a flat array kid[] (node -> first child,
 * or a tagged leaf). A leaf without pieces whose reference point
 * lies in at most one feature is stored as its answer in kid[] itself (QK__DIRECT), so
 * most points away from boundaries never read a leaf record. A 2^G x 2^G grid over the
 * top G levels (G <= 8) holds the kid[] value reached at depth G; a query guesses its
 * grid cell by scaling and corrects the guess exactly against the cells' sides, which
 * are stored as the descent computes them.
 *
 * Query (locate.c): grid cell, then the rest of the descent (comparisons against cell
 * centres computed along the path exactly as the build computed them), then for each
 * feature with pieces in the leaf flip the reference point's membership once per piece
 * crossed by the segment reference -> point. Most pieces are rejected by one filtered
 * orientation (the point on the same side as the reference); the leaf walk runs first on
 * the floating-point filters alone, and again with the exact predicates when a filter
 * cannot decide. Batches are put in Morton order, chunk by chunk, so that consecutive
 * points share their descent and leaf: a point inside the previous point's leaf box (the
 * bounds its descent compared against) takes that leaf without descending; the points
 * that need a leaf's pieces are decided in blocks of 32, after a prefetch of each leaf
 * record (locate.c).
 */
#include <stdarg.h>
#include <stdio.h>
#include <string.h>
#include <time.h>

#include "region/region_internal.h"
#include "index/textloc.h"

qk_status_t qk__region_fail(qk_error_t *err, qk_status_t st, size_t item, const char *fmt, ...) {
  if (err) {
    err->item = item;
    va_list ap;
    va_start(ap, fmt);
    qk__vsnprintf(err->message, sizeof err->message, fmt, ap);
    va_end(ap);
  }
  return st;
}

void qk_region_options_init(qk_region_options_t *o) {
  if (!o) return;
  memset(o, 0, sizeof *o);
  o->leaf_edges = QK_REGION_DEFAULT_LEAF_EDGES;
  o->max_depth = QK_REGION_DEFAULT_MAX_DEPTH;
}

void qk__region_options(const qk_region_options_t *options, qk_region_options_t *o,
                        qk_allocator_t *alloc) {
  qk_region_options_init(o);
  if (options) *o = *options;
  *alloc = (qk_allocator_t){NULL, NULL};
  if (o->allocator) *alloc = *o->allocator;
}

void qk_region_free(qk_region_t *r) {
  if (!r) return;
  const qk_allocator_t *a = &r->alloc;
  qk__props_free(a, &r->props);
  qk__free(a, r->segs, r->cap_segs * sizeof(qk__seg_t));
  qk__free(a, r->seg_tag, r->cap_seg_tag * sizeof(uint32_t));
  qk_tree_free(r->tree);
  qk__free(a, r->kid, r->cap_kid * sizeof(uint32_t));
  qk__free(a, r->leaves, r->cap_leaves * sizeof(qk__leaf_t));
  qk__free(a, r->le, r->cap_le * sizeof(uint32_t));
  qk__free(a, r->le_tag, r->cap_le_tag * sizeof(uint32_t));
  qk__free(a, r->sets, r->cap_sets * sizeof(uint32_t));
  qk__free(a, r->cover_at, r->cap_cover_at * sizeof(qk__cover_t));
  qk__free(a, r->cover, r->cap_cover * sizeof(uint32_t));
  qk__region_pure_free(r);
  if (r->grid_level) {
    size_t g = (size_t)1 << r->grid_level;
    qk__free(a, r->grid, g * g * sizeof(uint32_t));
    qk__free(a, r->gx, (g + 1) * sizeof(double));
    qk__free(a, r->gy, (g + 1) * sizeof(double));
  }
  qk_allocator_t al = r->alloc;
  qk__free(&al, r, sizeof *r);
}

void qk_region_stats(const qk_region_t *r, qk_region_stats_t *s) {
  if (s) *s = r ? r->stats : (qk_region_stats_t){0};
}

size_t qk_region_feature_count(const qk_region_t *r) { return r ? r->n_features : 0; }

const qk_tree_t *qk_region_tree(const qk_region_t *r) { return r ? r->tree : NULL; }

const char *qk_region_property(const qk_region_t *r, uint32_t f, const char *name) {
  if (!r || !name || f >= r->n_features || !r->props.start) return NULL;
  const qk__props_t *p = &r->props;
  for (size_t i = p->start[f]; i < p->start[f + 1]; i++)
    if (!strcmp(p->pool + p->key[i], name)) return p->pool + p->val[i];
  return NULL;
}

/* ---- properties being collected by a reader ---------------------------------------- */

void qk__props_free(const qk_allocator_t *a, qk__props_t *p) {
  qk__free(a, p->start, p->cap_start * sizeof(size_t));
  qk__free(a, p->key, p->cap_key * sizeof(size_t));
  qk__free(a, p->val, p->cap_val * sizeof(size_t));
  qk__free(a, p->pool, p->pool_cap);
  memset(p, 0, sizeof *p);
}

static qk_status_t pool_add(const qk_allocator_t *a, qk__props_t *p, const char *s, size_t len,
                            size_t *at) {
  qk_status_t st = qk__grow(a, (void **)&p->pool, &p->pool_cap, p->pool_len + len + 1, 1);
  if (st) return st;
  *at = p->pool_len;
  memcpy(p->pool + p->pool_len, s, len);
  p->pool[p->pool_len + len] = '\0';
  p->pool_len += len + 1;
  return QK_OK;
}

qk_status_t qk__props_add(const qk_allocator_t *a, qk__props_t *p, const char *key, const char *val,
                          size_t val_len) {
  qk_status_t st = qk__grow(a, (void **)&p->key, &p->cap_key, p->n + 1, sizeof(size_t));
  if (st) return st;
  if ((st = qk__grow(a, (void **)&p->val, &p->cap_val, p->n + 1, sizeof(size_t)))) return st;
  size_t k, v;
  if ((st = pool_add(a, p, key, strlen(key), &k))) return st;
  if ((st = pool_add(a, p, val, val_len, &v))) return st;
  p->key[p->n] = k;
  p->val[p->n] = v;
  p->n++;
  return QK_OK;
}

qk_status_t qk__props_end_feature(const qk_allocator_t *a, qk__props_t *p, size_t feature) {
  /* start[f] is the first pair of feature f; start[feature + 1] closes it. */
  qk_status_t st = qk__grow(a, (void **)&p->start, &p->cap_start, feature + 2, sizeof(size_t));
  if (st) return st;
  if (feature == 0) p->start[0] = 0;
  p->start[feature + 1] = p->n;
  return QK_OK;
}
