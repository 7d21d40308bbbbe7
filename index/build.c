/*
 * Bulk build by bucketing: the points sorted by their cell in a uniform 2^L x 2^L grid over
 * the root square (qk__cell_sort, index/cellsort.c), which lays them out in the tree's
 * pre-order (children NE, NW, SW, SE); then the top L levels of the tree read off the
 * bucket counts without touching a point; only buckets still over capacity are split
 * further, by the plain partition (qk__split), in cache. The subtrees below depth 3 are
 * built as jobs on the threads, each into node arrays of its own, and appended in
 * pre-order, so that the tree is the same node for node for any number of threads.
 */
#include <string.h>

#include "index/index_access.h"

/* A node of the top levels still over capacity, whose subtree is built on its own: the
 * node, its geometry and its first bucket. */
typedef struct subtree {
  uint32_t v;
  qk__geom_t g;
  uint32_t lo;
  uint32_t base; /* where its nodes go in the tree, once built on a thread */
} subtree_t;

/* The subtrees hang at this depth (at most 4^3 of them), when the grid is deeper. */
#define TOP_DEPTH 3u
/* The deepest grid the sort makes (cells of 16-bit numbers). */
#define GRID_MAX 8u
/* Fewest points in cells over the capacity for the subtrees to be built on threads. */
#define DEEP_MIN 65536u

/* Make node v over slots [a, b) a leaf or split it along the bucket counts. `cum` holds
 * the prefix sums of the 4^L buckets; v covers buckets [lo, lo + 4^(L - depth)). With a
 * list, a node of depth `top` that must split is appended to it instead, in pre-order.
 * Depth first with a stack of its own rather than by recursion (a call a node cost more
 * than the node's own work: 240 instructions a split node at 1M uniform points): a node's
 * children are pushed last to first, so that nodes are split, and their children's blocks
 * appended, in the recursion's pre-order. */
typedef struct fb_item {
  qk__geom_t g;
  uint32_t v, lo;
} fb_item_t;

static qk_status_t from_buckets(qk_tree_t *t, uint32_t v, const qk__geom_t *gp, const uint32_t *cum,
                                uint32_t lo, unsigned L, unsigned top, subtree_t *list,
                                size_t *n_list, qk__cell_wait_t *wait) {
  /* at most three siblings waiting on each of the L levels below the node, and four
   * children just pushed on the deepest */
  fb_item_t stack[3 * GRID_MAX + 1];
  size_t sp = 0;
  stack[sp++] = (fb_item_t){*gp, v, lo};
  const uint32_t cap = t->capacity;
  qk_status_t st;
  while (sp > 0) {
    const fb_item_t it = stack[--sp];
    const unsigned depth = it.g.depth;
    if (t->nodes[it.v].count <= cap || !qk__can_split(t, it.g)) continue;
    if (list && depth == top) {
      list[(*n_list)++] = (subtree_t){it.v, it.g, it.lo, 0};
      continue;
    }
    if (depth == L) {
      if (wait) qk__cell_wait(wait, it.lo); /* its points sorted */
      if ((st = qk__build_subtree(t, it.v, it.g))) return st;
      continue;
    }
    /* A fresh build has no free blocks: the children are appended, usually into nodes that
     * from_grid() reserved. Splitting moves no point: the children's slot ranges are
     * already in order. */
    if ((t->n_nodes + 4 > t->cap_nodes || (t->n_nodes + 3) / 4 > t->cap_blocks) &&
        (st = qk__reserve_nodes(t, 4)))
      return st;
    uint32_t b = t->n_nodes, span = 1u << (2 * (L - depth - 1));
    t->n_nodes += 4;
    qk__node_t *n = t->nodes;
    /* The five bounds of the four children's slot ranges, each read once. */
    const uint32_t *cb = cum + it.lo;
    uint32_t e[5] = {cb[0], cb[span], cb[2 * span], cb[3 * span], cb[4 * span]};
    for (uint32_t q = 0; q < 4; q++)
      n[b + q] = (qk__node_t){
          .child = QK_NONE, .start = e[q], .count = e[q + 1] - e[q], .room = e[q + 1] - e[q]};
    n[it.v].child = b;
    n[it.v].room = 0;
    t->blocks[(b - 1) >> 2] =
        (qk__block_t){.parent = it.v, .depth = (uint8_t)(depth + 1), .live = 1};
    /* Most children are leaves already: only those over capacity are pushed. */
    for (uint32_t q = 4; q-- > 0;)
      if (n[b + q].count > cap)
        stack[sp++] = (fb_item_t){qk__child_geom(t, it.g, q), b + q, it.lo + q * span};
  }
  return QK_OK;
}

/* Room for `extra` more nodes, allocated to size (qk__reserve_nodes() would round the
 * size up to its growth step, and qk_tree_build_ex() would then copy the nodes to give
 * the excess back). */
static qk_status_t reserve_exact(qk_tree_t *t, uint64_t extra) {
  uint64_t need = t->n_nodes + extra, blocks = (need + 2) / 4;
  if (need > UINT32_MAX / 2) return qk__reserve_nodes(t, (uint32_t)extra);
  if (need > t->cap_nodes) {
    qk__node_t *p = qk__realloc(&t->alloc, t->nodes, (size_t)t->cap_nodes * sizeof *p,
                                (size_t)need * sizeof *p);
    if (!p) return QK_ERR_NOMEM;
    t->nodes = p;
    t->cap_nodes = (uint32_t)need;
    qk__tree_advise_huge(t, p, (size_t)need * sizeof *p);
  }
  if (blocks > t->cap_blocks) {
    qk__block_t *p = qk__realloc(&t->alloc, t->blocks, (size_t)t->cap_blocks * sizeof *p,
                                 (size_t)blocks * sizeof *p);
    if (!p) return QK_ERR_NOMEM;
    t->blocks = p;
    t->cap_blocks = (uint32_t)blocks;
    qk__tree_advise_huge(t, p, (size_t)blocks * sizeof *p);
  }
  return QK_OK;
}

/* The subtrees built on threads: each into a tree of its own that shares the point arrays
 * (the subtrees' slot ranges are disjoint) and has its own node arrays, its root as node
 * 0; then appended to the tree in list order, which numbers every node as building them
 * one after another in the tree would. */
typedef struct sub_job {
  qk_tree_t *t;
  const uint32_t *cum;
  unsigned L;
  const subtree_t *list;
  qk_tree_t *own; /* one tree per subtree */
  qk_status_t *st;
} sub_job_t;

/* Set up the tree of its own for subtree i, with room for about as many nodes as it will
 * need (four per `capacity` points: more than a uniform or clustered set makes), so that
 * its arrays come from the calling thread and rarely grow on a worker. A worker's
 * allocations would come from a per-thread arena of the C library, returned to the
 * system when freed and faulted in again at the next build. */
static qk_status_t sub_init(const qk_tree_t *t, const subtree_t *s, qk_tree_t *o) {
  memset(o, 0, sizeof *o);
  o->alloc = t->alloc; /* the default allocator: thread-safe */
  o->capacity = t->capacity;
  o->max_depth = t->max_depth;
  o->root_x = t->root_x;
  o->root_y = t->root_y;
  memcpy(o->side, t->side, sizeof o->side);
  o->px = t->px;
  o->py = t->py;
  o->pid = t->pid;
  atomic_init(&o->where, NULL);
  o->free_block = QK_NONE;
  uint64_t count = t->nodes[s->v].count, est = 4 * (count / t->capacity) + 64;
  qk_status_t st = reserve_exact(o, est);
  if (st) return st;
  o->n_nodes = 1;
  o->nodes[0] = t->nodes[s->v];
  return QK_OK;
}

static void sub_build(unsigned i, unsigned w, void *ud) {
  (void)w;
  const sub_job_t *j = ud;
  j->st[i] =
      from_buckets(&j->own[i], 0, &j->list[i].g, j->cum, j->list[i].lo, j->L, 0, NULL, NULL, NULL);
}

/* Append subtree tree o, whose root stands for node v, to t at node `base` (nodes
 * reserved and counted): node u >= 1 of o becomes base + u - 1. */
static void sub_append(qk_tree_t *t, const qk_tree_t *o, uint32_t v, uint32_t base) {
  uint32_t extra = o->n_nodes - 1;
  for (uint32_t u = 1; u < o->n_nodes; u++) {
    qk__node_t n = o->nodes[u];
    if (n.child != QK_NONE) n.child += base - 1;
    t->nodes[base + u - 1] = n;
  }
  for (uint32_t k = 0; k < extra / 4; k++) {
    qk__block_t b = o->blocks[k];
    b.parent = b.parent == 0 ? v : b.parent + base - 1;
    t->blocks[(base - 1) / 4 + k] = b;
  }
  qk__node_t r = o->nodes[0];
  if (r.child != QK_NONE) r.child += base - 1;
  t->nodes[v] = r;
}

/* The appends write disjoint nodes and blocks: they run as jobs too. */
static void sub_append_job(unsigned i, unsigned w, void *ud) {
  (void)w;
  const sub_job_t *j = ud;
  sub_append(j->t, &j->own[i], j->list[i].v, j->list[i].base);
}

static void sub_free(const qk_tree_t *t, qk_tree_t *o) {
  qk__free(&t->alloc, o->nodes, (size_t)o->cap_nodes * sizeof(qk__node_t));
  qk__free(&t->alloc, o->blocks, (size_t)o->cap_blocks * sizeof(qk__block_t));
}

/* The tree below the grid's top levels: the top levels from the bucket counts, then
 * every subtree hanging below them, on nw threads when there are several of them and the
 * allocator is the default one (a caller's allocator is only ever called from one thread
 * at a time). */
static qk_status_t from_grid(qk_tree_t *t, qk__geom_t g, const uint32_t *cum, unsigned L,
                             size_t deep, unsigned nw, qk__cell_wait_t *wait) {
  subtree_t list[1u << (2 * TOP_DEPTH)];
  size_t n = 0;
  unsigned top = L > TOP_DEPTH ? TOP_DEPTH : L;
  /* Nodes for the grid's levels, reserved at once rather than grown step by step: at most
   * the complete tree of depth L, and about four per `capacity` points, with a sixteenth
   * to spare (within the slack that qk_tree_build_ex() leaves unreturned). */
  uint64_t full = (((uint64_t)1 << (2 * L + 2)) - 1) / 3,
           est = 4 * (cum[(size_t)1 << (2 * L)] / t->capacity) + 64;
  uint64_t want = full < est ? full : est;
  want += want / 16;
  /* And four per `capacity` points in the cells still over it, for the splits below the
   * grid (capacity 1, 1M uniform points: 2.8 nodes a point there). Grown an eighth at a
   * time by those splits instead, the array was copied about 30 times: that build took
   * 96 ms rather than 87 with every page already mapped, 390 rather than 230 in this
   * work's PVM guest, where a fresh page faults for 15-30 us (the reserve is large enough
   * for the tree's huge-page rule, qk__tree_advise_huge). The excess is given back at the
   * end (qk_tree_build_ex). */
  want += 4 * ((uint64_t)deep / t->capacity);
  qk_status_t st = reserve_exact(t, want);
  if (st) return st;
  st = from_buckets(t, 0, &g, cum, 0, L, top, list, &n, wait);
  if (st) return st;
  if (nw <= 1 || n < 2 || t->alloc.fn) {
    for (size_t i = 0; i < n && st == QK_OK; i++)
      st = from_buckets(t, list[i].v, &list[i].g, cum, list[i].lo, L, 0, NULL, NULL, wait);
    return st;
  }
  qk_tree_t *own = qk__realloc(&t->alloc, NULL, 0, n * sizeof *own);
  qk_status_t *sts = qk__realloc(&t->alloc, NULL, 0, n * sizeof *sts);
  if (!own || !sts) {
    qk__free(&t->alloc, own, n * sizeof *own);
    qk__free(&t->alloc, sts, n * sizeof *sts);
    return QK_ERR_NOMEM;
  }
  memset(own, 0, n * sizeof *own);
  for (size_t i = 0; i < n && st == QK_OK; i++) st = sub_init(t, &list[i], &own[i]);
  sub_job_t j = {t, cum, L, list, own, sts};
  if (st == QK_OK) qk__run_jobs_dynamic(nw, (unsigned)n, sub_build, &j);
  size_t extra = 0;
  for (size_t i = 0; i < n; i++) {
    if (st == QK_OK && sts[i]) st = sts[i];
    extra += own[i].n_nodes ? own[i].n_nodes - 1 : 0;
  }
  if (st == QK_OK && extra > UINT32_MAX) st = QK_ERR_LIMIT;
  if (st == QK_OK) st = reserve_exact(t, extra);
  if (st == QK_OK) {
    for (size_t i = 0; i < n; i++) {
      list[i].base = t->n_nodes;
      t->n_nodes += own[i].n_nodes - 1;
    }
    qk__run_jobs_dynamic(nw, (unsigned)n, sub_append_job, &j);
  }
  for (size_t i = 0; i < n; i++) sub_free(t, &own[i]);
  qk__free(&t->alloc, own, n * sizeof *own);
  qk__free(&t->alloc, sts, n * sizeof *sts);
  return st;
}

/* The tree made from the counts on the calling thread while the other threads sort the
 * points (qk__cell_hook_t). */
typedef struct grid_hook {
  qk_tree_t *t;
  unsigned L;
} grid_hook_t;

static qk_status_t grid_hook(void *ctx, const uint32_t *cum, size_t deep, qk__cell_wait_t *wait) {
  const grid_hook_t *h = ctx;
  qk_tree_t *t = h->t;
  return from_grid(t, (qk__geom_t){t->root_x, t->root_y, 0}, cum, h->L, deep, 1, wait);
}

qk_status_t qk__build_bucketed(qk_tree_t *t, const qk_point_t *p, size_t n, bool *done) {
  *done = false;
  unsigned L = 0;
  while (L < GRID_MAX && L < t->max_depth && ((size_t)1 << (2 * (L + 1))) <= n / 4) L++;
  if (L < 2) return QK_OK;
  /* Threads: a share of fewer than 2^16 points does not pay for its thread. */
  unsigned nw = qk__threads_resolve(t->threads);
  if (nw > n / 65536) nw = n / 65536 > 0 ? (unsigned)(n / 65536) : 1;
  uint32_t *cum;
  size_t deep;
  /* Below DEEP_MIN points in cells over the capacity, the tree is made on the calling
   * thread beside the sort's last pass (which had it wait 0.4 ms at 1M uniform points on
   * two threads: a twentieth of the build), waiting only for the buckets whose cells it
   * splits point by point. */
  grid_hook_t gh = {t, L};
  qk__cell_hook_t hook = {.deep_below = DEEP_MIN, .fn = grid_hook, .ctx = &gh};
  qk_status_t st = qk__cell_sort(t, p, n, L, nw, &hook, &cum, &deep);
  if (st || !cum) return st; /* !cum: badly conditioned, the plain build runs */
  if (hook.ran) {
    st = hook.st;
    qk__free(&t->alloc, cum, (((size_t)1 << (2 * L)) + 1) * sizeof *cum);
    *done = st == QK_OK;
    return st;
  }
  /* The tree on threads only when points are left to split below the grid: from the
   * counts alone (1M uniform points: 0.4 ms on one thread), the subtrees' own node arrays,
   * their appending and two more thread starts cost more than they save. */
  st = from_grid(t, (qk__geom_t){t->root_x, t->root_y, 0}, cum, L, deep, deep < DEEP_MIN ? 1 : nw,
                 NULL);
  qk__free(&t->alloc, cum, (((size_t)1 << (2 * L)) + 1) * sizeof *cum);
  *done = st == QK_OK;
  return st;
}
