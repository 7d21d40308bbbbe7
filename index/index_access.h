/*
 * The narrow interface through which the modules built on index/ (query/, collide/,
 * region/, mesh/) read a tree's structure. Not API, and not the layout: index/ may store
 * its nodes however it likes, and only this file and the sources in index/ know how. Outside
 * index/, code includes this header, never index_internal.h; CI (scripts/check-layout.sh)
 * rejects `->nodes[`, `->side[`, `->px`, `->py`, `->pid` and `qk__node_t` outside index/,
 * and, from clang's syntax tree, any use of a field of struct qk_tree, qk__node or qk__block
 * whose name is written outside index/ (this file's accessors are index/'s).
 *
 * Nodes are named by qk_node_t (0 is the root). The four children of an internal node are
 * consecutive ids, first + QK_NE .. first + QK_SE. A leaf's points occupy the slots
 * [start, start + count) of three parallel arrays (x, y, id), which stay valid until the
 * tree is next modified. Descents that need many squares should compute them from the
 * path (the root square halved, a corner moved per quadrant, as qk__child_square() does)
 * rather than ask for each node's: the path is in registers, a node's square may not be.
 * The first section declares the few helpers every module shares (growth, threads, the
 * short-buffer sink, clearing an error record, Morton spreading, the SVG preamble),
 * implemented in index/.
 */
#ifndef QUADKIT_INDEX_ACCESS_H
#define QUADKIT_INDEX_ACCESS_H

#include "index/index_internal.h"

#include <stdint.h>
#include <string.h>

/* ---- helpers every module shares (implemented in index/) ------------------------- */

/* Grow *p, an array of *cap items of `elem` bytes, to hold at least `need` items: from 16,
 * doubling. QK_ERR_LIMIT when the size would overflow, QK_ERR_NOMEM when the allocation
 * fails; either way *p and *cap are unchanged. */
qk_status_t qk__grow(const qk_allocator_t *a, void **p, size_t *cap, size_t need, size_t elem);

/* Threads: qk__run_shares() and qk__share_range() (index_internal.h) split a region into
 * shares; qk__run_jobs() runs fn(i, ud) for i in [0, n) on min(threads, n, QK__MAX_THREADS)
 * shares, job i in share i mod their number (0 or 1 thread: all on the caller). */
void qk__run_jobs(unsigned threads, unsigned n, void (*fn)(unsigned i, void *ud), void *ud);

/* A pool of worker threads kept between parallel regions (index/threads.c): the build's team
 * (qk__team_begin) and the world's workers (collide/world_threads.c) are pools. The calling
 * thread runs share 0 of a region, the workers shares 1..; between regions the workers wait
 * for the next one, spinning for a while when their owner holds the pool (regions follow
 * each other within microseconds), then parked.
 * qk__pool_new(a, nw) starts nw - 1 workers (memory from a, NULL: libc), or returns NULL
 * when it cannot start one; qk__pool_free (which accepts NULL) waits for a detached job,
 * joins them and frees the pool. qk__pool_threads: 1 + the workers (1 for NULL). */
typedef struct qk__pool qk__pool_t;
qk__pool_t *qk__pool_new(const qk_allocator_t *a, unsigned nw);
void qk__pool_free(qk__pool_t *p);
unsigned qk__pool_threads(const qk__pool_t *p);
/* How many times the calling thread parked waiting for the end of one of p's regions (it
 * spins first: 1 ms while it holds the pool, 50 us otherwise); 0 for NULL (tests). */
unsigned qk__pool_owner_parks(const qk__pool_t *p);
/* How long the calling thread spins for the end of p's region before it parks, in ns
 * (p not NULL). */
unsigned long qk__pool_wait_spin_ns(const qk__pool_t *p);
/* Where worker i first ran, and in *home where the thread that started it ran then, when
 * the workers were started away from that processor (Linux, with another processor to
 * start on); -1 in both otherwise. The worker writes its processor before it runs any
 * region: read it after a region has run. */
int qk__pool_start_cpu(const qk__pool_t *p, unsigned i, int *home);
/* The same for the calling thread when qk__run_shares started it for a region (away from
 * the starting thread's processor, as a pool's workers): where it first ran, and in *home
 * where the starting thread ran then; -1 in both otherwise (tests, from inside a share). */
int qk__share_start_cpu(int *home);
/* Whether p's workers run in this process (0 for NULL, and in a child forked after they
 * started: there qk__pool_free only frees its memory). */
int qk__pool_live(const qk__pool_t *p);
/* Shares 0 .. nw - 1 of fn, share 0 on the calling thread, the others on the workers (a
 * share its worker has not taken when share 0 ends runs on the calling thread next), and
 * return 1 when all are done; 0, nothing run, when there is no pool (NULL, or a child forked
 * after it started), another region holds it, nw is 0, or it has fewer than nw threads (the
 * caller then runs the region otherwise, e.g. qk__run_shares). One region at a time; calls from
 * several threads are safe (all but one get 0). */
int qk__pool_run(qk__pool_t *p, unsigned nw, qk__share_fn fn, void *ctx);
/* qk__run_jobs and qk__run_jobs_dynamic (index_internal.h) on p's workers when qk__pool_run
 * gives it the region, on threads started for it otherwise (p NULL: always). */
void qk__pool_run_jobs(qk__pool_t *p, unsigned threads, unsigned n,
                       void (*fn)(unsigned i, void *ud), void *ud);
void qk__pool_run_jobs_dynamic(qk__pool_t *p, unsigned threads, unsigned n,
                               void (*fn)(unsigned i, unsigned w, void *ud), void *ud);
/* While held (on nonzero) the workers spin between regions (200 us) before they park; when
 * released, they park at once. */
void qk__pool_hold(qk__pool_t *p, int on);
/* fn(ctx) on the first worker while the caller goes on (the pool's next region and its end
 * wait for it); 0, fn not run, when there is no pool here or it is taken. */
int qk__pool_detach(qk__pool_t *p, void (*fn)(void *), void *ctx);

/* An error record for a call that may succeed (err may be NULL): no line, column or item
 * (SIZE_MAX), message "". */
static inline void qk__error_clear(qk_error_t *err) {
  if (!err) return;
  memset(err, 0, sizeof *err);
  err->item = SIZE_MAX;
}

/* The short-buffer rule of the buffer-form calls: count every item in n, write it to out[n]
 * only while n < cap (value is evaluated only then). */
#define QK__SINK_PUT(out, cap, n, value)                                                           \
  do {                                                                                             \
    if ((n) < (cap)) (out)[(n)] = (value);                                                         \
    (n)++;                                                                                         \
  } while (0)

/* Spread the low 16 bits of v to the even bit positions (one axis of a Morton code). */
static inline uint32_t qk__spread16(uint32_t v) {
  v &= 0xFFFFu;
  v = (v | (v << 8)) & 0x00FF00FFu;
  v = (v | (v << 4)) & 0x0F0F0F0Fu;
  v = (v | (v << 2)) & 0x33333333u;
  v = (v | (v << 1)) & 0x55555555u;
  return v;
}

/* Start an SVG drawing of a width x width square: the <svg> element, with a 2-unit margin
 * all round, and a white background (index/svg.c; the caller closes it with </svg>). */
void qk__svg_open(FILE *f, unsigned width);

/* ---- the tree as a whole -------------------------------------------------------- */

/* The allocator every structure derived from the tree should use. */
static inline const qk_allocator_t *qk__tree_allocator(const qk_tree_t *t) { return &t->alloc; }

/* Threads the batch queries on this tree use (resolved: at least 1). */
static inline unsigned qk__tree_threads(const qk_tree_t *t) {
  return qk__threads_resolve(t->threads);
}

/* Points stored. */
static inline size_t qk__tree_count(const qk_tree_t *t) { return t->n_points; }

/* Node ids in use are below this bound (ids of free blocks included). */
static inline uint32_t qk__tree_node_bound(const qk_tree_t *t) { return t->n_nodes; }

/* Point slots in use are below this bound (slots owned by no leaf included). */
static inline uint32_t qk__tree_slot_bound(const qk_tree_t *t) { return t->n_slots; }

/* The point arrays, indexed by slot. */
static inline const double *qk__tree_xs(const qk_tree_t *t) { return t->px; }
static inline const double *qk__tree_ys(const qk_tree_t *t) { return t->py; }
static inline const qk_id_t *qk__tree_ids(const qk_tree_t *t) { return t->pid; }

/* Side length of the squares at a depth (exact halvings of the root's). */
static inline double qk__tree_side(const qk_tree_t *t, unsigned depth) { return t->side[depth]; }

/* The root's square. */
static inline qk_square_t qk__tree_root_square(const qk_tree_t *t) {
  return (qk_square_t){t->root_x, t->root_y, t->side[0]};
}

/* ---- one node ------------------------------------------------------------------- */

/* First of the four children, or QK_NONE for a leaf. */
static inline uint32_t qk__node_child(const qk_tree_t *t, qk_node_t v) { return t->nodes[v].child; }

static inline bool qk__node_leaf(const qk_tree_t *t, qk_node_t v) {
  return t->nodes[v].child == QK_NONE;
}

static inline unsigned qk__node_depth(const qk_tree_t *t, qk_node_t v) { return qk__depth(t, v); }

/* A node's parent (QK_NONE for the root) and which child of it the node is. */
static inline qk_node_t qk__node_parent(const qk_tree_t *t, qk_node_t v) {
  return qk__parent(t, v);
}
static inline qk_quadrant_t qk__node_quadrant(qk_node_t v) {
  return (qk_quadrant_t)qk__quadrant(v);
}

/* Is v a node in use? */
static inline bool qk__node_live(const qk_tree_t *t, qk_node_t v) { return qk__live(t, v); }

/* A node's square (a cold read, recomputed down its path in O(depth): prefer squares
 * computed along the descent). */
static inline qk_square_t qk__node_square(const qk_tree_t *t, qk_node_t v) {
  qk__geom_t g = qk__node_geom(t, v);
  return (qk_square_t){g.x0, g.y0, t->side[g.depth]};
}

/* First slot of a leaf's points. For an internal node, a hint to prefetch by, never to read
 * points from: after a bulk build, its subtree's points are the slots [start, start + count)
 * (index_internal.h); after inserts and removals they may lie elsewhere. */
static inline uint32_t qk__node_start(const qk_tree_t *t, qk_node_t v) { return t->nodes[v].start; }

/* Points in a node's subtree (for a leaf: its own). */
static inline uint32_t qk__node_count(const qk_tree_t *t, qk_node_t v) { return t->nodes[v].count; }

/* Slots a leaf owns from its first (at least its count; 0 for an internal node). */
static inline uint32_t qk__node_room(const qk_tree_t *t, qk_node_t v) { return t->nodes[v].room; }

/* A hint that node v will be read soon. */
static inline void qk__node_prefetch(const qk_tree_t *t, qk_node_t v) {
#if defined(__GNUC__)
  __builtin_prefetch(&t->nodes[v]);
#else
  (void)t;
  (void)v;
#endif
}

/* ---- squares along a path --------------------------------------------------------- */

/* The square of child q of a node of square s. */
static inline qk_square_t qk__child_square(qk_square_t s, unsigned q) {
  double h = s.side * 0.5;
  return (qk_square_t){s.x + (qk__q_east(q) ? h : 0.0), s.y + (qk__q_north(q) ? h : 0.0), h};
}

/* Is (x, y) inside the closed root square? */
static inline bool qk__tree_contains(const qk_tree_t *t, double x, double y) {
  qk_square_t r = qk__tree_root_square(t);
  return x >= r.x && x <= r.x + r.side && y >= r.y && y <= r.y + r.side;
}

/* The leaf whose square holds (x, y), which must lie in the root square, by the tie rules
 * (as qk_tree_find_leaf()); its square and depth go to *sq and *depth when not NULL. The
 * squares are computed along the path, with the same arithmetic as the tree's own. */
static inline qk_node_t qk__tree_descend(const qk_tree_t *t, double x, double y, qk_square_t *sq,
                                         unsigned *depth) {
  qk_square_t s = qk__tree_root_square(t);
  unsigned d = 0;
  qk_node_t v = 0;
  for (uint32_t c = qk__node_child(t, v); c != QK_NONE; c = qk__node_child(t, v)) {
    double h = qk__tree_side(t, d + 1);
    unsigned q = qk__quadrant_of(s.x, s.y, h, x, y);
    v = c + q;
    s = qk__child_square(s, q);
    s.side = h;
    d++;
  }
  if (sq) *sq = s;
  if (depth) *depth = d;
  return v;
}

/* qk_tree_split_leaf() for a caller that descended to the leaf and knows its square's
 * lower-left corner (x0, y0) and its depth, as the tree computes them (the root's corner
 * plus the halved sides of the path: dyadic values, exact): the same checks, statuses and
 * split, without walking the path back up to recompute them. Debug builds check them. */
qk_status_t qk__tree_split_leaf_at(qk_tree_t *t, qk_node_t leaf, double x0, double y0,
                                   unsigned depth);

/* Room for `extra` more nodes before the tree next grows its node arrays (a caller that
 * knows roughly how many splits it will make saves the growth's copies). */
static inline qk_status_t qk__tree_reserve(qk_tree_t *t, uint32_t extra) {
  return qk__reserve_nodes(t, extra);
}

#endif /* QUADKIT_INDEX_ACCESS_H */
