/*
 * Private layout of the quadtree, shared by index/ and, read-only, by the modules built
 * on it (query/, mesh/). Not API: it may change with any release.
 */
#ifndef QUADKIT_INDEX_INTERNAL_H
#define QUADKIT_INDEX_INTERNAL_H

#include "quadkit/index.h"

#include <stdatomic.h>
#include <stdbool.h>

/*
 * One node: the hot part, 16 bytes, all that a descent reads. `child` is the first of four
 * consecutive children (NE, NW, SW, SE) or QK_NONE for a leaf. For a leaf, its points
 * occupy slots [start, start + count) of the point arrays, with `room` slots reserved
 * there so that inserts usually need no move. `count` is the number of points in the
 * subtree for every node. An internal node keeps the `start` it had as a leaf (a split
 * leaves its points in its slot range, ordered by quadrant, and a bulk build's nodes begin
 * as leaves over their cells' runs; a compaction of the point arrays, which lays the
 * leaves out in pre-order, sets it to the subtree's first slot): after a bulk build its
 * subtree's points are the slots [start, start + count), which the searches use to ask for
 * them early; once inserts move a leaf or merges gather one, it is only a hint. A node's
 * square is not stored: descents compute it from the root's along their path
 * (qk__node_geom() recomputes it, in O(depth), for the cold callers).
 */
typedef struct qk__node {
  uint32_t child;
  uint32_t start;
  uint32_t count;
  uint32_t room;
} qk__node_t;

/*
 * The cold part, one record per block of four siblings (nodes 1 + 4b .. 4 + 4b form block
 * b; the root is in no block): their parent, their depth, and whether the block is in
 * use. A free block is on a list linked through `parent` (the next free block's first
 * node, or QK_NONE). A node's quadrant is its place in its block, (v - 1) % 4.
 */
typedef struct qk__block {
  uint32_t parent;
  uint8_t depth;
  uint8_t live;
  uint16_t pad_;
} qk__block_t;

struct qk_tree {
  qk_allocator_t alloc;
  uint32_t capacity;
  uint32_t max_depth;
  uint32_t threads;      /* threads for the build and batch queries; 0 = every core */
  bool fixed_root;       /* the root square was given (has_root), not fitted to the points */
  bool huge_pages;       /* advise huge pages for the point arrays */
  bool refined;          /* split beyond the capacity rule: removals no longer merge */
  double root_x, root_y; /* the root square's lower-left corner */
  double side[QK_MAX_DEPTH_LIMIT + 2]; /* side length at each depth, exact halvings */

  /* Nodes: node 0 is the root; children come in blocks of four. */
  qk__node_t *nodes;
  qk__block_t *blocks; /* cold records of the blocks, cap_nodes / 4 of them */
  uint32_t n_nodes;    /* slots used (high-water mark, including free blocks) */
  uint32_t cap_nodes;  /* node slots allocated (1 + 4 * cap_blocks once grown) */
  uint32_t cap_blocks; /* block records allocated */
  uint32_t free_block; /* first node of the first free block, or QK_NONE */
  uint32_t n_free_blocks;

  /* Points in leaf order: slot s holds (px[s], py[s]) with id pid[s]. */
  double *px, *py;
  qk_id_t *pid;
  uint32_t n_slots;   /* slots used (high-water mark) */
  uint32_t cap_slots; /* slots allocated */
  uint32_t garbage;   /* slots inside [0, n_slots) owned by no leaf */
  uint32_t spare;     /* room the last compaction left in leaves beyond their points */

  /* Id map: where[id] is the slot of point id, or QK_NONE once removed. A bulk build
   * does not make it (it costs a random write per point and 4 bytes per point): it is
   * made on first need, by a removal or an id lookup, and kept up to date from then on.
   * Id lookups are read-only calls that may run in many threads at once, so the pointer
   * is published atomically (qk__id_map). NULL: not made yet. */
  uint32_t *_Atomic where;
  uint32_t n_ids;   /* ids handed out */
  uint32_t cap_ids; /* entries allocated in where; 0 while the map is not made or was made
                       lazily, in which case it has max(n_ids, 1) entries */
  size_t n_points;  /* points stored */

  /* Removed ids, handed out again by inserts, the most recently removed first. */
  qk_id_t *free_ids;
  uint32_t n_free_ids, cap_free_ids;

  /* The bulk build's record block, kept between builds once the tree has been rebuilt
   * (qk_tree_rebuild sets keep_rec): a tree rebuilt every frame then asks for its largest
   * scratch block once (index/cellsort.c). NULL: none kept. */
  void *kept_rec;
  size_t kept_rec_bytes;
  bool keep_rec;
};

/* Allocation goes through here and only here. */
void *qk__realloc(const qk_allocator_t *a, void *ptr, size_t osize, size_t nsize);
void qk__free(const qk_allocator_t *a, void *ptr, size_t size);

/* Ask for transparent huge pages over a large block from the default allocator (a hint;
 * index/hugepages.c). */
void qk__advise_huge(const qk_allocator_t *a, void *p, size_t size);
/* qk__advise_huge() by the tree's rule: every array with its huge_pages option, else
 * arrays over 32 MB (index/tree.c). */
void qk__tree_advise_huge(const qk_tree_t *t, void *p, size_t size);

static inline bool qk__is_leaf(const qk__node_t *n) { return n->child == QK_NONE; }

/* The block record of a node other than the root. */
static inline qk__block_t *qk__block_of(const qk_tree_t *t, uint32_t v) {
  return &t->blocks[(v - 1) >> 2];
}

/* A node's depth, parent (QK_NONE for the root) and quadrant (QK_NE for the root). */
static inline unsigned qk__depth(const qk_tree_t *t, uint32_t v) {
  return v ? qk__block_of(t, v)->depth : 0u;
}
static inline uint32_t qk__parent(const qk_tree_t *t, uint32_t v) {
  return v ? qk__block_of(t, v)->parent : QK_NONE;
}
static inline unsigned qk__quadrant(uint32_t v) { return v ? (v - 1) & 3u : 0u; }

/* Is v a node in use (not beyond the array, not in a free block)? */
static inline bool qk__live(const qk_tree_t *t, uint32_t v) {
  return v < t->n_nodes && (v == 0 || qk__block_of(t, v)->live);
}

/* Which child of a node of square (x0, y0, side) a location belongs to, by the tie rules:
 * east when x > xmid, north when y > ymid. */
static inline unsigned qk__quadrant_of(double x0, double y0, double half, double x, double y) {
  unsigned east = x > x0 + half;
  unsigned north = y > y0 + half;
  /* NE=0 (1,1), NW=1 (0,1), SW=2 (0,0), SE=3 (1,0) */
  static const unsigned char q[2][2] = {{2, 1}, {3, 0}};
  return q[east][north];
}

/* East and north bits of a quadrant. */
static inline unsigned qk__q_east(unsigned q) { return q == QK_NE || q == QK_SE; }
static inline unsigned qk__q_north(unsigned q) { return q == QK_NE || q == QK_NW; }

/* Is quadrant q on the `dir` side of its parent's square? */
static inline bool qk__on_side(unsigned q, unsigned dir) {
  switch (dir) {
  case QK_NORTH:
    return qk__q_north(q);
  case QK_SOUTH:
    return !qk__q_north(q);
  case QK_EAST:
    return qk__q_east(q);
  default:
    return !qk__q_east(q);
  }
}

/* The quadrant mirrored across the axis perpendicular to dir: for north/south swap
 * north and south halves (SW <-> NW, SE <-> NE); for east/west swap east and west. */
static inline unsigned qk__mirror(unsigned q, unsigned dir) {
  static const unsigned char ns[4] = {QK_SE, QK_SW, QK_NW, QK_NE};
  static const unsigned char ew[4] = {QK_NW, QK_NE, QK_SE, QK_SW};
  return (dir == QK_NORTH || dir == QK_SOUTH) ? ns[q] : ew[q];
}

/* The two children of a node on the side that faces a neighbour lying in direction `dir`
 * of it (for a north neighbour: its SW and SE children), in west-to-east or south-to-north
 * order. */
static inline void qk__facing_children(qk_dir_t dir, unsigned q[2]) {
  static const unsigned char f[4][2] = {
      {QK_SW, QK_SE}, /* neighbour to the north: its south children */
      {QK_SW, QK_NW}, /* to the east: its west children */
      {QK_NW, QK_NE}, /* to the south: its north children */
      {QK_SE, QK_NE}, /* to the west: its east children */
  };
  q[0] = f[dir][0];
  q[1] = f[dir][1];
}

/* A node's square and depth: where a descent knows them, it passes them on. */
typedef struct qk__geom {
  double x0, y0;
  unsigned depth;
} qk__geom_t;

/* The geometry of a child q of a node of geometry g. */
static inline qk__geom_t qk__child_geom(const qk_tree_t *t, qk__geom_t g, unsigned q) {
  double h = t->side[g.depth + 1];
  return (qk__geom_t){g.x0 + (qk__q_east(q) ? h : 0.0), g.y0 + (qk__q_north(q) ? h : 0.0),
                      g.depth + 1};
}

/* A node's geometry recomputed from the root down its path (the same arithmetic as every
 * descent, so the same square): O(depth), for callers that did not descend to it. */
qk__geom_t qk__node_geom(const qk_tree_t *t, uint32_t v);

/* Can a node of this geometry be split (not at the depth cap, and its side still halves
 * exactly into distinct midpoints)? */
static inline bool qk__can_split(const qk_tree_t *t, qk__geom_t g) {
  if (g.depth >= t->max_depth) return false;
  double half = t->side[g.depth + 1];
  if (!(half > 0)) return false;
  double xm = g.x0 + half, ym = g.y0 + half;
  double side = t->side[g.depth];
  /* The midpoint must fall strictly inside the square, or the halves are not distinct
   * in double precision. */
  return xm > g.x0 && xm < g.x0 + side && ym > g.y0 && ym < g.y0 + side;
}

/* Split a leaf of geometry g into four children and distribute its points. Nodes must
 * have been reserved (qk__reserve_nodes) beforehand; cannot fail then. Returns the first
 * child. */
uint32_t qk__split(qk_tree_t *t, uint32_t leaf, qk__geom_t g);

/* Attach four children to a leaf of depth `depth` without moving its points (they are
 * already in quadrant order); the caller sets the children's slot ranges. Nodes must be
 * reserved. */
uint32_t qk__split_sorted(qk_tree_t *t, uint32_t leaf, unsigned depth);

/* Split `node` (of geometry g) and its descendants while over capacity (the plain
 * recursive build). */
qk_status_t qk__build_subtree(qk_tree_t *t, uint32_t node, qk__geom_t g);

/* Work that qk__cell_sort() runs on the calling thread beside its last pass (the points
 * sorted bucket by bucket on the other threads), when it runs on several threads with the
 * default allocator and fewer than deep_below points lie in cells over the capacity: fn
 * gets the 4^L + 1 bucket starts and the points in cells over the capacity (`deep`, as
 * qk__cell_sort returns it), and must call qk__cell_wait() before it reads or moves
 * the points of a cell. `ran` and `st` say whether it ran and what it returned. */
typedef struct qk__cell_wait qk__cell_wait_t;
typedef struct qk__cell_hook {
  size_t deep_below;
  qk_status_t (*fn)(void *ctx, const uint32_t *cum, size_t deep, qk__cell_wait_t *wait);
  void *ctx;
  bool ran;
  qk_status_t st;
} qk__cell_hook_t;

/* Return once the points of grid cell `cell` are in their sorted places (sorting them on
 * the calling thread when no thread has started to). */
void qk__cell_wait(qk__cell_wait_t *w, uint32_t cell);

/* Sort the n points into the tree's point arrays (already sized) by their cell in the
 * 2^L x 2^L grid over the root square, in the tree's pre-order, on nw threads (a caller's
 * allocator is only called from the calling thread). *cum gets the 4^L + 1 bucket starts
 * (the caller frees them), or NULL, with QK_OK and nothing written, when the root is too
 * badly conditioned for exact cells by scaling (index/cellsort.c). *deep gets the number
 * of points in cells holding more than the capacity (those the tree splits point by
 * point below the grid). */
qk_status_t qk__cell_sort(qk_tree_t *t, const qk_point_t *p, size_t n, unsigned L, unsigned nw,
                          qk__cell_hook_t *hook, uint32_t **cum, size_t *deep);

/* Nonzero: the build's passes take their SSE2 or plain paths even where the processor
 * has AVX2 (index/cellsort.c), so tests cover both on one machine. 0 by default. */
extern int qk__build_avx2_off;

/* Whether the build may use its AVX2 paths: the processor has them and they are not
 * turned off. */
int qk__build_avx2(void);

/* Bulk build by bucketing into a uniform grid (index/build.c). Sets *done when it built
 * the tree; leaves it false (and the tree untouched) when the plain build should run. */
qk_status_t qk__build_bucketed(qk_tree_t *t, const qk_point_t *p, size_t n, bool *done);

/* The id map if it has been made, else NULL. */
static inline uint32_t *qk__id_map_if_made(const qk_tree_t *t) {
  return atomic_load_explicit(&((qk_tree_t *)t)->where, memory_order_acquire);
}

/* Entries allocated in the id map when it has been made (see cap_ids). */
static inline uint32_t qk__id_map_capacity(const qk_tree_t *t) {
  if (t->cap_ids) return t->cap_ids;
  return t->n_ids ? t->n_ids : 1;
}

/* The id map, made now if it was not. Safe from concurrent readers: each may build a
 * candidate and the first to publish wins. QK_ERR_NOMEM when it cannot be made. */
qk_status_t qk__id_map(const qk_tree_t *t, const uint32_t **map);

/* ---- threads (index/threads.c) ---- */

/* Most threads a parallel region uses. */
#define QK__MAX_THREADS 64

/* The number of threads a `threads` option asks for: 0 means every online core. */
unsigned qk__threads_resolve(uint32_t threads);

/* Let another thread run (a waiting loop's step). */
void qk__thread_yield(void);

/* A longer waiting loop's step: sleep for a few microseconds. (A bare yield let a waiter spin
 * ahead of the thread it waited for where threads are run one at a time, as under
 * valgrind: minutes for a wait of milliseconds.) */
void qk__thread_nap(void);

/* One share of a parallel region: share w of nw. */
typedef void (*qk__share_fn)(void *ctx, unsigned w, unsigned nw);

/* Run fn for shares 0 .. nw-1, share 0 on the calling thread, and return when all are
 * done. Shares must write disjoint memory. */
void qk__run_shares(unsigned nw, qk__share_fn fn, void *ctx);
/* Nonzero: qk__run_shares starts its threads as usual, not away from the calling thread's
 * processor (for paired measurements in one process; not thread-safe to change while
 * regions run). */
extern int qk__shares_away_off;
/* Tests (not thread-safe to change while regions run): nonzero qk__pool_steal_off keeps the
 * owner of a pool from running the shares its workers have not taken yet, so that each share
 * runs on its worker; nonzero qk__pool_workers_idle has the workers take no share at all,
 * so that the owner runs every share of every region (never with a detached job; atomic,
 * as a worker may still be reading it when a region has ended without it). */
extern int qk__pool_steal_off;
extern _Atomic int qk__pool_workers_idle;

/* Hold a team of nw - 1 workers on the calling thread until qk__team_end(): the regions it
 * starts meanwhile (qk__run_shares, the jobs) run on them instead of on threads started for
 * each. Calls nest (the outermost's team serves); a region started inside another region's
 * share, or asking for more shares than the team has, starts threads of its own; without
 * workers (none could be started) every region does. */
void qk__team_begin(unsigned nw);
void qk__team_end(void);
/* A team's workers are kept, parked, for the next team of the same size on any thread;
 * qk__team_release() ends them (tests; the library's unloading does it too). */
void qk__team_release(void);

/* The half-open range of [0, n) that share w of nw covers. */
static inline void qk__share_range(size_t n, unsigned w, unsigned nw, size_t *lo, size_t *hi) {
  *lo = n / nw * w + (w < n % nw ? w : n % nw);
  *hi = *lo + n / nw + (w < n % nw);
}

/* A range [0, n) handed out in chunks from a shared counter (dynamic shares): a share takes
 * the next chunk when it finishes one, so that shares end together when one thread is
 * slowed (another process on its processor, a late start) or the work is uneven. Which
 * share runs a chunk varies from run to run: every index must write only its own outputs.
 * qk__chunks_init cuts about QK__CHUNKS_PER_SHARE chunks per share, of at least `least`. */
#define QK__CHUNKS_PER_SHARE 16
typedef struct qk__chunks {
  atomic_size_t next;
  size_t n, size;
} qk__chunks_t;

static inline void qk__chunks_init(qk__chunks_t *c, size_t n, unsigned nw, size_t least) {
  size_t size = n / ((size_t)QK__CHUNKS_PER_SHARE * (nw ? nw : 1));
  atomic_init(&c->next, 0);
  c->n = n;
  c->size = size > least ? size : least > 0 ? least : 1;
}

/* The next chunk [*lo, *hi), or false when none is left. */
static inline bool qk__chunks_take(qk__chunks_t *c, size_t *lo, size_t *hi) {
  size_t at = atomic_fetch_add_explicit(&c->next, c->size, memory_order_relaxed);
  if (at >= c->n) return false;
  *lo = at;
  *hi = c->n - at < c->size ? c->n : at + c->size;
  return true;
}

/* Run fn(i, w, ud) for i in [0, n) on min(threads, n) shares, each share taking the next
 * job from a shared counter; w is the share running the job (for scratch memory of its
 * own). Which share runs a job varies from run to run: jobs must write disjoint memory
 * and their results must not depend on w. */
void qk__run_jobs_dynamic(unsigned threads, unsigned n,
                          void (*fn)(unsigned i, unsigned w, void *ud), void *ud);

/* Make room for at least `extra` more node slots. */
qk_status_t qk__reserve_nodes(qk_tree_t *t, uint32_t extra);

#endif /* QUADKIT_INDEX_INTERNAL_H */
