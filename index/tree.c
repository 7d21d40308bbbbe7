/*
 * The point-region quadtree: construction, insertion, removal and lookups.
 *
 * Storage (see index_internal.h): nodes in one array, children in blocks of four; points
 * in three parallel arrays (x, y, id) where every leaf owns a contiguous block of slots.
 * A bulk build lays the blocks out in pre-order with no gaps. An insert into a full block
 * moves the leaf's points to a larger block at the end of the arrays; the abandoned slots
 * are counted as garbage and the arrays are compacted when garbage outweighs live points.
 *
 * Every mutating call first makes all the allocations it may need, and only then changes
 * the tree, so that a failed allocation leaves the tree exactly as it was.
 */
#include <assert.h>
#include <math.h>
#include <stdarg.h>
#include <stdio.h>
#include <string.h>

#include "index/index_internal.h"
#include "index/textloc.h"

#if defined(__SSE2__)
#include <emmintrin.h>
#endif
/* The bounding box two points per register where the compiler can target AVX2 in one
 * function and the processor has it (as index/cellsort.c's keys). */
#if defined(__GNUC__) && defined(__x86_64__) && (defined(__clang__) || __GNUC__ >= 8)
#define QK__TREE_AVX2 1
#include <immintrin.h>
#else
#define QK__TREE_AVX2 0
#endif

void qk_tree_options_init(qk_tree_options_t *o) {
  if (!o) return;
  memset(o, 0, sizeof *o);
  o->capacity = 1;
  o->max_depth = QK_DEFAULT_MAX_DEPTH;
  o->threads = 1;
}

void qk_tree_set_threads(qk_tree_t *t, uint32_t threads) {
  if (t) t->threads = threads;
}

/* Fill an error record (when there is one) and return the status. */
static qk_status_t say(qk_error_t *err, qk_status_t st, size_t item, const char *fmt, ...) {
  if (!err) return st;
  err->line = 0;
  err->column = 0;
  err->item = item;
  va_list ap;
  va_start(ap, fmt);
  qk__vsnprintf(err->message, sizeof err->message, fmt, ap);
  va_end(ap);
  return st;
}

/* ---- allocation helpers ---------------------------------------------------------- */

/* Grow an array of `elem`-byte items from *cap to at least `need` items. Growth is by an
 * eighth, not a doubling, so that a tree under churn stays near the size of a fresh build
 * (issue 10); the copies stay amortised O(1) per item. */
static qk_status_t grow(const qk_allocator_t *a, void **arr, uint32_t *cap, size_t need,
                        size_t elem) {
  if (need <= *cap) return QK_OK;
  if (need > UINT32_MAX) return QK_ERR_LIMIT;
  size_t ncap = *cap ? (size_t)*cap : 16;
  while (ncap < need) ncap += ncap / 8 + 16;
  if (ncap > UINT32_MAX) ncap = UINT32_MAX;
  if (ncap > SIZE_MAX / elem) return QK_ERR_LIMIT;
  void *p = qk__realloc(a, *arr, (size_t)*cap * elem, ncap * elem);
  if (!p) return QK_ERR_NOMEM;
  *arr = p;
  *cap = (uint32_t)ncap;
  return QK_OK;
}

qk_status_t qk__reserve_nodes(qk_tree_t *t, uint32_t extra) {
  /* Blocks on the free list can be reused; the rest must fit after n_nodes. The hot and
   * the cold arrays grow separately: if the second fails, the first is only larger. */
  size_t reusable = (size_t)t->n_free_blocks * 4;
  if (extra <= reusable) return QK_OK;
  size_t need = (size_t)t->n_nodes + (extra - reusable);
  qk_status_t st = grow(&t->alloc, (void **)&t->nodes, &t->cap_nodes, need, sizeof(qk__node_t));
  if (st) return st;
  return grow(&t->alloc, (void **)&t->blocks, &t->cap_blocks, (need - 1 + 3) / 4,
              sizeof(qk__block_t));
}

void qk__tree_advise_huge(const qk_tree_t *t, void *p, size_t size) {
  /* With the tree's option every array, else those over 32 MB (more than 4M points for
   * the coordinates, 8M for the ids, 2M nodes): glibc maps such a block afresh for every
   * call and unmaps it when freed, so that each build would fault it in 4 KB at a time
   * (15-31 us a fault in the PVM guest of this work; see qk__cell_sort()'s record block).
   * Smaller arrays come from the heap, faulted once and reused, and are left alone. */
  if (t->huge_pages || size > ((size_t)32 << 20)) qk__advise_huge(&t->alloc, p, size);
}

/* A set of the three parallel point arrays. */
typedef struct slots {
  double *x, *y;
  qk_id_t *id;
} slots_t;

static void slots_free(const qk_allocator_t *a, slots_t *s, size_t cap) {
  qk__free(a, s->x, cap * sizeof(double));
  qk__free(a, s->y, cap * sizeof(double));
  qk__free(a, s->id, cap * sizeof(qk_id_t));
}

static qk_status_t slots_alloc(const qk_tree_t *t, size_t cap, slots_t *s) {
  const qk_allocator_t *a = &t->alloc;
  s->x = qk__realloc(a, NULL, 0, cap * sizeof(double));
  s->y = qk__realloc(a, NULL, 0, cap * sizeof(double));
  s->id = qk__realloc(a, NULL, 0, cap * sizeof(qk_id_t));
  if (s->x && s->y && s->id) {
    qk__tree_advise_huge(t, s->x, cap * sizeof(double));
    qk__tree_advise_huge(t, s->y, cap * sizeof(double));
    qk__tree_advise_huge(t, s->id, cap * sizeof(qk_id_t));
    return QK_OK;
  }
  slots_free(a, s, cap);
  return QK_ERR_NOMEM;
}

/* Replace the tree's point arrays by `s` of `cap` slots, freeing the old ones. */
static void slots_install(qk_tree_t *t, slots_t s, size_t cap) {
  slots_t old = {t->px, t->py, t->pid};
  slots_free(&t->alloc, &old, t->cap_slots);
  t->px = s.x;
  t->py = s.y;
  t->pid = s.id;
  t->cap_slots = (uint32_t)cap;
}

/* The point arrays' next size when they grow: an eighth more (and 16). */
static size_t slots_step(size_t cap) { return cap + cap / 8 + 16; }

/* Grow the three point arrays together to at least `need` slots. */
static qk_status_t reserve_slots(qk_tree_t *t, size_t need) {
  if (need <= t->cap_slots) return QK_OK;
  if (need > UINT32_MAX) return QK_ERR_LIMIT;
  /* The first allocation (a bulk build) is exact; growth is by an eighth. */
  size_t ncap = t->cap_slots ? (size_t)t->cap_slots : need;
  while (ncap < need) ncap = slots_step(ncap);
  if (ncap > UINT32_MAX) ncap = UINT32_MAX;
  slots_t s;
  if (slots_alloc(t, ncap, &s)) return QK_ERR_NOMEM;
  if (t->n_slots) {
    memcpy(s.x, t->px, (size_t)t->n_slots * sizeof(double));
    memcpy(s.y, t->py, (size_t)t->n_slots * sizeof(double));
    memcpy(s.id, t->pid, (size_t)t->n_slots * sizeof(qk_id_t));
  }
  slots_install(t, s, ncap);
  return QK_OK;
}

/* The room a full leaf of `count` points gets when it moves to the tail. */
static uint32_t grown_room(uint32_t count) { return count + count / 4 + 2; }

/* The room a leaf of `count` points keeps through a compaction: an eighth more from 8
 * points on, a thirty-second below (so that a leaf of thousands of copies of one point at
 * the depth cap is not full either). A compaction that left every leaf full had the next
 * insert into each move it to the tail, abandoning its block: at capacity 32 the
 * abandoned blocks set off the next compaction after about n / 500 inserts, and 1M
 * inserts copied some 500 slots each (8.4 s). */
static uint32_t compact_room(uint32_t count) {
  return count + (count >= 8 ? count / 8 : count / 32);
}

/* Rewrite the point arrays with every leaf's block in pre-order, each with its
 * compact_room, leaving `headroom` free slots at the end; leaf `grow` (or QK_NONE), which
 * is about to take a point, gets its grown room, so that it does not move to the tail
 * right after. Allocates fresh arrays; on failure nothing changes. */
static qk_status_t compact(qk_tree_t *t, size_t headroom, uint32_t grow) {
  /* The arrays' size: every live leaf's room (the root, then the blocks in use). */
  size_t ncap = headroom;
  const qk__node_t *nd = t->nodes;
  if (qk__is_leaf(&nd[0])) ncap += compact_room(nd[0].count);
  for (uint32_t b = 1; b + 3 < t->n_nodes; b += 4)
    if (t->blocks[(b - 1) >> 2].live)
      for (uint32_t v = b; v < b + 4; v++)
        if (qk__is_leaf(&nd[v])) ncap += compact_room(nd[v].count);
  if (grow != QK_NONE) ncap += grown_room(nd[grow].count) - compact_room(nd[grow].count);
  if (ncap < 16) ncap = 16;
  if (ncap > UINT32_MAX) return QK_ERR_LIMIT;
  slots_t s;
  if (slots_alloc(t, ncap, &s)) return QK_ERR_NOMEM;
  double *nx = s.x, *ny = s.y;
  qk_id_t *ni = s.id;
  /* Pre-order walk with an explicit stack: at most 3 pending siblings per level. */
  uint32_t stack[4 * (QK_MAX_DEPTH_LIMIT + 2)], top = 0, pos = 0;
  uint32_t *w = qk__id_map_if_made(t);
  stack[top++] = 0;
  while (top) {
    uint32_t v = stack[--top];
    qk__node_t *n = &t->nodes[v];
    if (!qk__is_leaf(n)) {
      n->start = pos; /* its subtree's first slot (pre-order), the hint of index_internal.h */
      for (int c = 3; c >= 0; c--) stack[top++] = n->child + (uint32_t)c;
      continue;
    }
    const uint32_t from = n->start;
    if (n->count == 1) { /* (most leaves of a small capacity hold one point or none) */
      nx[pos] = t->px[from];
      ny[pos] = t->py[from];
      ni[pos] = t->pid[from];
    } else if (n->count > 1) {
      memcpy(nx + pos, t->px + from, (size_t)n->count * sizeof(double));
      memcpy(ny + pos, t->py + from, (size_t)n->count * sizeof(double));
      memcpy(ni + pos, t->pid + from, (size_t)n->count * sizeof(qk_id_t));
    }
    if (w)
      for (uint32_t i = 0; i < n->count; i++) w[ni[pos + i]] = pos + i;
    n->start = pos;
    n->room = v == grow ? grown_room(n->count) : compact_room(n->count);
    pos += n->room;
  }
  slots_install(t, s, ncap);
  t->spare = pos - (uint32_t)t->n_points;
  t->n_slots = pos;
  t->garbage = 0;
  return QK_OK;
}

/* Make sure `extra` slots are free at the end of the point arrays. The arrays are
 * compacted, with a sixteenth of headroom, rather than grown when that gives back at least
 * a thirty-second of the points (slots that are neither points nor the room the last
 * compaction left in leaves) and either more than a sixteenth is garbage (blocks that
 * leaves abandoned) or growing would take the arrays past a fifth over the points: so the
 * arrays of a tree under churn stay within about a fifth of its points (issue 10), and a
 * growing tree grows. A compaction costs O(n) plus a walk of the node array's blocks,
 * which removals do not shrink, so it leaves headroom for both, n / 16 + n_nodes / 64
 * slots: with n / 16 alone a tree being emptied compacted ever more often (removing all
 * 100,000 points at capacity 1: 69 compactions, half the instructions; now 6). Each
 * comes after Omega(n / 32) slots were abandoned or that headroom was used, so O(1)
 * amortised a slot. `grow` is the leaf that is to take a point next (or
 * QK_NONE): the compaction gives it room, else a big leaf would move to the tail right
 * after, abandon its block, and so set off the next compaction. */
static qk_status_t reserve_tail(qk_tree_t *t, size_t extra, uint32_t grow) {
  if ((size_t)t->n_slots + extra <= t->cap_slots) return QK_OK;
  size_t n = t->n_points, slack = t->n_slots - n;
  if (slack > t->spare + n / 32 && (t->garbage > n / 16 || slots_step(t->cap_slots) > n + n / 5))
    return compact(t, n / 16 + t->n_nodes / 64 + extra, grow);
  return reserve_slots(t, (size_t)t->n_slots + extra);
}

/* ---- giving memory back as the tree shrinks ------------------------------------------ */

/* Move the node block at src (its first node) to the free block at dst: its parent's link,
 * its children's blocks' parent links and its record follow. */
static void move_block(qk_tree_t *t, uint32_t src, uint32_t dst) {
  memcpy(&t->nodes[dst], &t->nodes[src], 4 * sizeof(qk__node_t));
  *qk__block_of(t, dst) = *qk__block_of(t, src);
  t->nodes[qk__block_of(t, dst)->parent].child = dst;
  for (uint32_t q = 0; q < 4; q++)
    if (!qk__is_leaf(&t->nodes[dst + q]))
      qk__block_of(t, t->nodes[dst + q].child)->parent = dst + q;
}

/* Give back the node blocks merges freed: the blocks in use beyond the first `live` are
 * moved into the free ones before them, in place, and both arrays shrink to `live` blocks.
 * Node numbers change (as every changing call allows; index.h). The work is a move per
 * block that lay beyond, so it is proportional to the blocks freed since the last time, and
 * the arrays shrink where they are (no new pages to fault in). */
static void defrag_nodes(qk_tree_t *t) {
  const uint32_t live = (t->n_nodes - 1) / 4 - t->n_free_blocks, end = 1 + 4 * live;
  uint32_t hi = t->n_nodes; /* the blocks from hi on are moved or free */
  for (uint32_t f = t->free_block; f != QK_NONE;) {
    const uint32_t next = qk__block_of(t, f)->parent;
    if (f < end) {
      do hi -= 4;
      while (!qk__block_of(t, hi)->live);
      move_block(t, hi, f);
    }
    f = next;
  }
  t->n_nodes = end;
  t->free_block = QK_NONE;
  t->n_free_blocks = 0;
  /* Shrunk where they lie; a refused shrink keeps the larger arrays, which are as good. */
  qk__node_t *nodes = qk__realloc(&t->alloc, t->nodes, (size_t)t->cap_nodes * sizeof *nodes,
                                  (size_t)end * sizeof *nodes);
  if (nodes) t->nodes = nodes, t->cap_nodes = end;
  if (!live) { /* (no block records left) */
    qk__free(&t->alloc, t->blocks, (size_t)t->cap_blocks * sizeof *t->blocks);
    t->blocks = NULL, t->cap_blocks = 0;
    return;
  }
  qk__block_t *blocks = qk__realloc(&t->alloc, t->blocks, (size_t)t->cap_blocks * sizeof *blocks,
                                    (size_t)live * sizeof *blocks);
  if (blocks) t->blocks = blocks, t->cap_blocks = live;
}

/* After a removal: when the node arrays hold more than 1.2 times the nodes in use (plus 64),
 * give back the blocks merges freed (defrag_nodes: work proportional to the blocks freed);
 * when the point arrays hold more than 1.5 times the points (plus 256 and a slot for every
 * 64 nodes: a compaction leaves about 1.2 times and those slots), compact them (O(n) after a third
 * of them was given up, so O(1) amortised a removal). So a tree that has shrunk holds about what a
 * fresh build of its points would (issue 10: 8.6 times that after 90% of 10^6 points were removed
 * at capacity 1, with nothing given back; and the node arrays' high-water mark took churn at
 * capacity 1 to 1.19 times a fresh build). Optional: when memory is short the tree stays as it is,
 * valid and larger. */
#if defined(__GNUC__)
__attribute__((noinline))
#endif
static void
give_back_now(qk_tree_t *t, bool nodes, bool slots) {
  if (nodes) defrag_nodes(t);
  if (slots) (void)compact(t, t->n_points / 16 + t->n_nodes / 64, QK_NONE);
}

/* (The trigger counts the headroom compact() leaves for the nodes, n_nodes / 64: without
 * it, pairs of coincident points at capacity 1, chains of nodes to the depth cap of some
 * 80 nodes a pair, left the compacted arrays above the trigger, and every removal
 * compacted them all again: 20,000 removals took 125 s.) */
static inline void give_back(qk_tree_t *t) {
  const size_t n = t->n_points, used = (size_t)t->n_nodes - 4 * (size_t)t->n_free_blocks;
  const bool nodes = t->cap_nodes > used + used / 5 + 64,
             slots = t->cap_slots > n + n / 2 + 256 + t->n_nodes / 64;
  if (nodes || slots) give_back_now(t, nodes, slots);
}

/* ---- the id map ------------------------------------------------------------------- */

qk_status_t qk__id_map(const qk_tree_t *ct, const uint32_t **map) {
  uint32_t *w = qk__id_map_if_made(ct);
  if (!w) {
    qk_tree_t *t = (qk_tree_t *)ct; /* only the atomic pointer is written */
    size_t cap = qk__id_map_capacity(t);
    w = qk__realloc(&t->alloc, NULL, 0, cap * sizeof *w);
    if (!w) return QK_ERR_NOMEM;
    for (size_t i = 0; i < cap; i++) w[i] = QK_NONE;
    for (uint32_t v = 0; v < t->n_nodes; v++) {
      const qk__node_t *n = &t->nodes[v];
      if (!qk__live(t, v) || !qk__is_leaf(n)) continue;
      for (uint32_t s = n->start; s < n->start + n->count; s++) w[t->pid[s]] = s;
    }
    /* Publish; if another reader got there first, use its map and drop this one. */
    uint32_t *expected = NULL;
    if (!atomic_compare_exchange_strong_explicit(&t->where, &expected, w, memory_order_acq_rel,
                                                 memory_order_acquire)) {
      qk__free(&t->alloc, w, cap * sizeof *w);
      w = expected;
    }
  }
  *map = w;
  return QK_OK;
}

/* In a call that changes the tree (so no reader runs): the id map, made first when `need`
 * is set, with its capacity recorded; *out is NULL when it is not made and not needed. */
static qk_status_t own_map(qk_tree_t *t, bool need, uint32_t **out) {
  const uint32_t *w = qk__id_map_if_made(t);
  if (!w && need) {
    qk_status_t st = qk__id_map(t, &w);
    if (st) return st;
  }
  if (w && !t->cap_ids) t->cap_ids = qk__id_map_capacity(t);
  *out = (uint32_t *)w;
  return QK_OK;
}

/* ---- nodes ---------------------------------------------------------------------------- */

/* Take a block of four node slots (reserved beforehand). */
static uint32_t take_block(qk_tree_t *t) {
  uint32_t b;
  if (t->free_block != QK_NONE) {
    b = t->free_block;
    t->free_block = qk__block_of(t, b)->parent;
    t->n_free_blocks--;
  } else {
    b = t->n_nodes;
    t->n_nodes += 4;
  }
  return b;
}

static void release_block(qk_tree_t *t, uint32_t b) {
  qk__block_t *k = qk__block_of(t, b);
  k->live = 0;
  k->parent = t->free_block;
  t->free_block = b;
  t->n_free_blocks++;
}

qk__geom_t qk__node_geom(const qk_tree_t *t, uint32_t v) {
  unsigned char path[QK_MAX_DEPTH_LIMIT + 2];
  unsigned len = 0;
  for (uint32_t a = v; a != 0; a = qk__parent(t, a)) path[len++] = (unsigned char)qk__quadrant(a);
  qk__geom_t g = {t->root_x, t->root_y, 0};
  while (len > 0) g = qk__child_geom(t, g, path[--len]);
  return g;
}

/* Attach a block of four children (reserved beforehand) to a leaf, with their links but
 * no points: the caller sets each child's slot range. */
uint32_t qk__split_sorted(qk_tree_t *t, uint32_t leaf, unsigned depth) {
  uint32_t b = take_block(t);
  qk__node_t *n = &t->nodes[leaf];
  for (uint32_t q = 0; q < 4; q++)
    t->nodes[b + q] = (qk__node_t){.child = QK_NONE, .start = n->start, .count = 0, .room = 0};
  *qk__block_of(t, b) = (qk__block_t){.parent = leaf, .depth = (uint8_t)(depth + 1), .live = 1};
  n->child = b;
  return b;
}

uint32_t qk__split(qk_tree_t *t, uint32_t leaf, qk__geom_t g) {
  qk__node_t *n = &t->nodes[leaf];
  double half = t->side[g.depth + 1];
  double x0 = g.x0, y0 = g.y0;
  uint32_t start = n->start, count = n->count, room = n->room;
  if (count == 0) {
    /* No points to partition (the meshers' trees, balancing's new cells): the children
     * start where the leaf did, empty, and the last one takes the leaf's room, as below. */
    uint32_t b = qk__split_sorted(t, leaf, g.depth);
    t->nodes[b + 3].room = room;
    n = &t->nodes[leaf];
    n->room = 0;
    return b;
  }

  /* Partition the leaf's slots into NE, NW, SW, SE order in place (American flag sort on
   * the quadrant). */
  uint32_t cnt[4] = {0, 0, 0, 0};
  for (uint32_t i = start; i < start + count; i++)
    cnt[qk__quadrant_of(x0, y0, half, t->px[i], t->py[i])]++;
  uint32_t first[4], next[4];
  first[0] = start;
  for (int q = 1; q < 4; q++) first[q] = first[q - 1] + cnt[q - 1];
  memcpy(next, first, sizeof next);
  for (int q = 0; q < 4; q++) {
    uint32_t end = first[q] + cnt[q];
    while (next[q] < end) {
      uint32_t i = next[q];
      unsigned r = qk__quadrant_of(x0, y0, half, t->px[i], t->py[i]);
      if ((int)r == q) {
        next[q]++;
        continue;
      }
      uint32_t j = next[r]++;
      double tx = t->px[i], ty = t->py[i];
      qk_id_t ti = t->pid[i];
      t->px[i] = t->px[j];
      t->py[i] = t->py[j];
      t->pid[i] = t->pid[j];
      t->px[j] = tx;
      t->py[j] = ty;
      t->pid[j] = ti;
    }
  }
  uint32_t *w = qk__id_map_if_made(t);
  if (w)
    for (uint32_t i = start; i < start + count; i++) w[t->pid[i]] = i;

  uint32_t b = qk__split_sorted(t, leaf, g.depth);
  for (uint32_t q = 0; q < 4; q++) {
    qk__node_t *c = &t->nodes[b + q];
    c->start = first[q];
    c->count = cnt[q];
    c->room = cnt[q];
  }
  /* The leaf's unused room goes to the last child so that no slot is lost. */
  t->nodes[b + 3].room += room - count;
  n = &t->nodes[leaf];
  n->room = 0;
  return b;
}

/* Split a leaf and then every child that is still over capacity. Nodes must be reserved
 * for the whole cascade (4 per level below the leaf). */
static void split_while_full(qk_tree_t *t, uint32_t leaf, qk__geom_t g) {
  while (t->nodes[leaf].count > t->capacity && qk__can_split(t, g)) {
    uint32_t b = qk__split(t, leaf, g);
    uint32_t next = QK_NONE;
    for (uint32_t q = 0; q < 4; q++)
      if (t->nodes[b + q].count > t->capacity) next = q;
    if (next == QK_NONE) break;
    leaf = b + next;
    g = qk__child_geom(t, g, next);
  }
}

/* ---- construction ------------------------------------------------------------------ */

static qk_status_t check_options(const qk_tree_options_t *o) {
  if (o->max_depth > QK_MAX_DEPTH_LIMIT) return QK_ERR_INVALID;
  if (o->has_root) {
    const qk_square_t *r = &o->root;
    if (!isfinite(r->x) || !isfinite(r->y) || !isfinite(r->side)) return QK_ERR_NONFINITE;
    if (!(r->side > 0) || !isfinite(r->x + r->side) || !isfinite(r->y + r->side))
      return QK_ERR_INVALID;
  }
  return QK_OK;
}

/* One pass over the input (or over share w of nw of it): the bounding box, and whether
 * every coordinate is finite. */
typedef struct bbox_job {
  const qk_point_t *p;
  size_t n;
  qk_box_t box[QK__MAX_THREADS];
  int finite[QK__MAX_THREADS];
} bbox_job_t;

/* The input read ahead by hand, 4 KB (256 points), one prefetch a line, as the bulk
 * build's key pass and scatter do (index/cellsort.c): the hardware's prefetch alone left
 * the pass about a twentieth of the whole build slower (process CPU time, A/B in one
 * process, 1M uniform points, one thread, medians 0.93-0.97 with it). An address past the
 * array's end is only a hint, computed outside C's pointer arithmetic. */
#if defined(__GNUC__)
#define QK__BBOX_PREFETCH(p) __builtin_prefetch((const void *)((uintptr_t)(p) + 4096))
#else
#define QK__BBOX_PREFETCH(p) ((void)0)
#endif

#if QK__TREE_AVX2
/* The same as the SSE2 loop below, two points per register: half the instructions. */
__attribute__((target("avx2"))) static void bbox_avx2(const qk_point_t *p, size_t lo, size_t hi,
                                                      qk_box_t *box, int *finite) {
  __m256d mn0 = _mm256_set1_pd(INFINITY), mn1 = mn0, mx0 = _mm256_set1_pd(-INFINITY), mx1 = mx0;
  __m256d nan = _mm256_setzero_pd();
  size_t i = lo;
  for (; i + 8 <= hi; i += 8) {
    QK__BBOX_PREFETCH(&p[i]); /* the step's two lines, 4 KB ahead */
    QK__BBOX_PREFETCH(&p[i + 4]);
    __m256d a = _mm256_loadu_pd(&p[i].x), b = _mm256_loadu_pd(&p[i + 2].x);
    __m256d c = _mm256_loadu_pd(&p[i + 4].x), d = _mm256_loadu_pd(&p[i + 6].x);
    mn0 = _mm256_min_pd(mn0, a);
    mx0 = _mm256_max_pd(mx0, a);
    mn1 = _mm256_min_pd(mn1, b);
    mx1 = _mm256_max_pd(mx1, b);
    mn0 = _mm256_min_pd(mn0, c);
    mx0 = _mm256_max_pd(mx0, c);
    mn1 = _mm256_min_pd(mn1, d);
    mx1 = _mm256_max_pd(mx1, d);
    nan = _mm256_or_pd(
        nan, _mm256_or_pd(_mm256_cmp_pd(a, b, _CMP_UNORD_Q), _mm256_cmp_pd(c, d, _CMP_UNORD_Q)));
  }
  mn0 = _mm256_min_pd(mn0, mn1);
  mx0 = _mm256_max_pd(mx0, mx1);
  __m128d mn = _mm_min_pd(_mm256_castpd256_pd128(mn0), _mm256_extractf128_pd(mn0, 1));
  __m128d mx = _mm_max_pd(_mm256_castpd256_pd128(mx0), _mm256_extractf128_pd(mx0, 1));
  __m128d un = _mm_or_pd(_mm256_castpd256_pd128(nan), _mm256_extractf128_pd(nan, 1));
  for (; i < hi; i++) {
    __m128d a = _mm_loadu_pd(&p[i].x);
    mn = _mm_min_pd(mn, a);
    mx = _mm_max_pd(mx, a);
    un = _mm_or_pd(un, _mm_cmpunord_pd(a, a));
  }
  double l[2], u[2];
  _mm_storeu_pd(l, mn);
  _mm_storeu_pd(u, mx);
  *box = (qk_box_t){l[0], l[1], u[0], u[1]};
  *finite =
      !_mm_movemask_pd(un) && isfinite(l[0]) && isfinite(l[1]) && isfinite(u[0]) && isfinite(u[1]);
  if (lo == hi) *finite = 1; /* an empty share: the box stays empty */
}
#endif

static void bbox_share(void *ctx, unsigned w, unsigned nw) {
  bbox_job_t *j = ctx;
  size_t lo, hi;
  qk__share_range(j->n, w, nw, &lo, &hi);
  const qk_point_t *p = j->p;
#if QK__TREE_AVX2
  if (qk__build_avx2()) {
    bbox_avx2(p, lo, hi, &j->box[w], &j->finite[w]);
    return;
  }
#endif
#if defined(__SSE2__)
  /* Two lanes (x, y) per point, four points per step, in four pairs of accumulators. An
   * unordered compare flags a NaN; an infinite coordinate shows in the box itself. The
   * accumulator is min/max's first operand, so the loop needs no register copies (a NaN
   * there may be dropped from the box, but the flag has it). */
  __m128d mn0 = _mm_set1_pd(INFINITY), mn1 = mn0, mn2 = mn0, mn3 = mn0;
  __m128d mx0 = _mm_set1_pd(-INFINITY), mx1 = mx0, mx2 = mx0, mx3 = mx0;
  __m128d nan = _mm_setzero_pd();
  size_t i = lo;
  for (; i + 4 <= hi; i += 4) {
    QK__BBOX_PREFETCH(&p[i]);
    __m128d a = _mm_loadu_pd(&p[i].x), b = _mm_loadu_pd(&p[i + 1].x);
    __m128d c = _mm_loadu_pd(&p[i + 2].x), d = _mm_loadu_pd(&p[i + 3].x);
    mn0 = _mm_min_pd(mn0, a);
    mx0 = _mm_max_pd(mx0, a);
    mn1 = _mm_min_pd(mn1, b);
    mx1 = _mm_max_pd(mx1, b);
    mn2 = _mm_min_pd(mn2, c);
    mx2 = _mm_max_pd(mx2, c);
    mn3 = _mm_min_pd(mn3, d);
    mx3 = _mm_max_pd(mx3, d);
    nan = _mm_or_pd(nan, _mm_or_pd(_mm_cmpunord_pd(a, b), _mm_cmpunord_pd(c, d)));
  }
  for (; i < hi; i++) {
    __m128d a = _mm_loadu_pd(&p[i].x);
    mn0 = _mm_min_pd(mn0, a);
    mx0 = _mm_max_pd(mx0, a);
    nan = _mm_or_pd(nan, _mm_cmpunord_pd(a, a));
  }
  mn0 = _mm_min_pd(_mm_min_pd(mn0, mn1), _mm_min_pd(mn2, mn3));
  mx0 = _mm_max_pd(_mm_max_pd(mx0, mx1), _mm_max_pd(mx2, mx3));
  double mn[2], mx[2];
  _mm_storeu_pd(mn, mn0);
  _mm_storeu_pd(mx, mx0);
  j->box[w] = (qk_box_t){mn[0], mn[1], mx[0], mx[1]};
  j->finite[w] = !_mm_movemask_pd(nan) && isfinite(mn[0]) && isfinite(mn[1]) && isfinite(mx[0]) &&
                 isfinite(mx[1]);
  if (lo == hi) j->finite[w] = 1; /* an empty share: the box stays empty */
#else
  double xmin = INFINITY, ymin = INFINITY, xmax = -INFINITY, ymax = -INFINITY;
  int finite = 1;
  for (size_t i = lo; i < hi; i++) {
    double x = p[i].x, y = p[i].y;
    finite &= isfinite(x) & isfinite(y);
    xmin = x < xmin ? x : xmin;
    xmax = x > xmax ? x : xmax;
    ymin = y < ymin ? y : ymin;
    ymax = y > ymax ? y : ymax;
  }
  j->box[w] = (qk_box_t){xmin, ymin, xmax, ymax};
  j->finite[w] = finite;
#endif
}

/* The bounding box over `threads` shares (a share of fewer than 2^17 points does not pay
 * for its thread). */
static qk_status_t bounding_box(const qk_point_t *p, size_t n, uint32_t threads, qk_box_t *b) {
  bbox_job_t j;
  j.p = p;
  j.n = n;
  unsigned nw = qk__threads_resolve(threads);
  if (nw > n / 131072) nw = n / 131072 > 0 ? (unsigned)(n / 131072) : 1;
  qk__run_shares(nw, bbox_share, &j);
  *b = j.box[0];
  int finite = j.finite[0];
  for (unsigned w = 1; w < nw; w++) {
    b->xmin = j.box[w].xmin < b->xmin ? j.box[w].xmin : b->xmin;
    b->ymin = j.box[w].ymin < b->ymin ? j.box[w].ymin : b->ymin;
    b->xmax = j.box[w].xmax > b->xmax ? j.box[w].xmax : b->xmax;
    b->ymax = j.box[w].ymax > b->ymax ? j.box[w].ymax : b->ymax;
    finite &= j.finite[w];
  }
  return finite ? QK_OK : QK_ERR_NONFINITE;
}

/* The lower end of a side-long interval holding [lo, hi]: lo, or when lo + side overflows,
 * hi - side stepped down to lo or below. */
static double axis_start(double lo, double hi, double side) {
  if (isfinite(lo + side)) return lo;
  double x = hi - side;
  while (x > lo) x = nextafter(x, -INFINITY);
  return x;
}

/* The smallest enclosing square of a bounding box (lower-left at the minima, or near
 * DBL_MAX reaching down past them). */
static qk_status_t enclosing_square(qk_box_t b, size_t n, qk_square_t *s) {
  *s = (qk_square_t){0, 0, 1};
  if (n == 0) return QK_OK;
  s->x = b.xmin;
  s->y = b.ymin;
  s->side = fmax(b.xmax - b.xmin, b.ymax - b.ymin);
  if (!(s->side > 0)) s->side = 1; /* one distinct location: any positive side will do */
  if (!isfinite(s->side)) return QK_ERR_LIMIT; /* the extent overflows a double */
  /* Each axis starts at its minimum or, near DBL_MAX where that overflows, ends at its
   * maximum, reaching down past the minimum (points at 1e308 and 1.5e308 had a finite
   * enclosing square, and were refused). Rounding may leave a maximum a hair outside:
   * widen by an ulp and place both axes again (a widening for x's sake pushed a y placed
   * at its maximum past DBL_MAX). */
  for (;;) {
    s->x = axis_start(b.xmin, b.xmax, s->side);
    s->y = axis_start(b.ymin, b.ymax, s->side);
    if (s->x + s->side >= b.xmax && s->y + s->side >= b.ymax) break;
    s->side = nextafter(s->side, INFINITY);
    if (!isfinite(s->side)) return QK_ERR_LIMIT;
  }
  if (!isfinite(s->x + s->side) || !isfinite(s->y + s->side)) return QK_ERR_LIMIT;
  return QK_OK;
}

static int inside_root(const qk_tree_t *t, double x, double y) {
  return x >= t->root_x && x <= t->root_x + t->side[0] && y >= t->root_y &&
         y <= t->root_y + t->side[0];
}

/* Recursive bulk build of the subtree of `node` over its slots, splitting while over
 * capacity. The recursion depth is bounded by max_depth. */
qk_status_t qk__build_subtree(qk_tree_t *t, uint32_t node, qk__geom_t g) {
  if (t->nodes[node].count <= t->capacity || !qk__can_split(t, g)) return QK_OK;
  qk_status_t st;
  if (t->free_block == QK_NONE &&
      (t->n_nodes + 4 > t->cap_nodes || (t->n_nodes + 3) / 4 > t->cap_blocks) &&
      (st = qk__reserve_nodes(t, 4)))
    return st;
  uint32_t b = qk__split(t, node, g);
  /* Only the children over capacity are visited (most are leaves at once: a call each
   * was a tenth of a capacity-1 build). */
  for (uint32_t q = 0; q < 4; q++)
    if (t->nodes[b + q].count > t->capacity &&
        (st = qk__build_subtree(t, b + q, qk__child_geom(t, g, q))))
      return st;
  return QK_OK;
}

/* Check the input and find the root square, saying what is wrong with it. */
static qk_status_t check_input(const qk_point_t *points, size_t n, const qk_tree_options_t *options,
                               qk_square_t *root, qk_error_t *err) {
  qk_status_t st;
  if (n && !points) return say(err, QK_ERR_INVALID, SIZE_MAX, "no point array for %zu points", n);
  if (n > QK_MAX_POINTS)
    return say(err, QK_ERR_LIMIT, SIZE_MAX, "%zu points: at most %u", n, (unsigned)QK_MAX_POINTS);
  if ((st = check_options(options))) {
    const qk_square_t *r = &options->root;
    if (options->max_depth > QK_MAX_DEPTH_LIMIT)
      return say(err, st, SIZE_MAX, "max_depth %u exceeds %d", options->max_depth,
                 QK_MAX_DEPTH_LIMIT);
    return say(err, st, SIZE_MAX, "root square (%g, %g, side %g): %s", r->x, r->y, r->side,
               st == QK_ERR_NONFINITE ? "not finite"
                                      : "the side must be positive and the square finite");
  }
  qk_box_t bbox;
  if ((st = bounding_box(points, n, options->threads, &bbox))) {
    for (size_t i = 0; i < n; i++)
      if (!isfinite(points[i].x) || !isfinite(points[i].y))
        return say(err, st, i, "point %zu (%g, %g) is not finite", i, points[i].x, points[i].y);
  }
  if (options->has_root) {
    *root = options->root;
    const qk_square_t r = *root;
    if (n && (bbox.xmin < r.x || bbox.xmax > r.x + r.side || bbox.ymin < r.y ||
              bbox.ymax > r.y + r.side))
      for (size_t i = 0; i < n; i++) {
        double x = points[i].x, y = points[i].y;
        if (x < r.x || x > r.x + r.side || y < r.y || y > r.y + r.side)
          return say(err, QK_ERR_OUTSIDE, i,
                     "point %zu (%.17g, %.17g) lies outside the root square (%.17g, %.17g, side "
                     "%.17g)",
                     i, x, y, r.x, r.y, r.side);
      }
  } else if ((st = enclosing_square(bbox, n, root))) {
    return say(err, st, SIZE_MAX, "the points' extent [%g, %g] x [%g, %g] overflows a double",
               bbox.xmin, bbox.xmax, bbox.ymin, bbox.ymax);
  }
  return say(err, QK_OK, SIZE_MAX, "%s", "");
}

qk_status_t qk_tree_build(const qk_point_t *points, size_t n, const qk_tree_options_t *options,
                          qk_tree_t **out) {
  return qk_tree_build_ex(points, n, options, out, NULL);
}

/* Make t the tree of n points over `root`, into its existing arrays (grown as needed):
 * everything but the allocator, the options and the arrays is reset. On failure the tree
 * is left valid and empty. */
static qk_status_t fill(qk_tree_t *t, const qk_point_t *points, size_t n, qk_square_t root) {
  qk_status_t st;
  t->root_x = root.x;
  t->root_y = root.y;
  t->side[0] = root.side;
  for (int d = 1; d < QK_MAX_DEPTH_LIMIT + 2; d++) t->side[d] = t->side[d - 1] * 0.5;
  qk__free(&t->alloc, qk__id_map_if_made(t), (size_t)qk__id_map_capacity(t) * sizeof(uint32_t));
  atomic_store_explicit(&t->where, NULL, memory_order_release);
  t->cap_ids = 0;
  t->n_free_ids = 0;
  t->free_block = QK_NONE;
  t->n_free_blocks = 0;
  t->refined = false;
  t->garbage = 0;
  t->spare = 0;
  t->n_slots = t->n_ids = 0;
  t->n_points = 0;
  t->n_nodes = 0;
  if ((st = grow(&t->alloc, (void **)&t->nodes, &t->cap_nodes, 1, sizeof(qk__node_t)))) return st;
  t->n_nodes = 1;
  t->nodes[0] = (qk__node_t){.child = QK_NONE, .start = 0, .count = 0, .room = 0};
  /* At least one slot even for an empty tree, so that a leaf's points are never a NULL
   * base plus an offset (undefined behaviour even for offset 0). */
  if ((st = reserve_slots(t, n ? n : 1))) return st;
  t->nodes[0].count = t->nodes[0].room = (uint32_t)n;
  t->n_slots = (uint32_t)n;
  t->n_ids = (uint32_t)n;
  t->n_points = n;
  bool done;
  st = qk__build_bucketed(t, points, n, &done);
  if (!st && !done) {
    /* The plain recursive build of the book: copy, then partition top-down. */
    for (size_t i = 0; i < n; i++) {
      t->px[i] = points[i].x;
      t->py[i] = points[i].y;
      t->pid[i] = (qk_id_t)i;
    }
    st = qk__build_subtree(t, 0, (qk__geom_t){root.x, root.y, 0});
  }
  if (st) { /* back to an empty tree: one leaf, no point */
    t->n_nodes = 1;
    t->nodes[0] = (qk__node_t){.child = QK_NONE, .start = 0, .count = 0, .room = 0};
    t->n_slots = t->n_ids = 0;
    t->n_points = 0;
  }
  return st;
}

/* The threads a build of n points runs its regions on: the bucketed build gives no thread a
 * share of fewer than 2^16 points (the bounding box none of fewer than 2^17). */
static unsigned build_team(uint32_t threads, size_t n) {
  unsigned nw = qk__threads_resolve(threads);
  return nw > n / 65536 ? (n / 65536 > 0 ? (unsigned)(n / 65536) : 1) : nw;
}

static qk_status_t build_ex(const qk_point_t *points, size_t n, const qk_tree_options_t *options,
                            qk_tree_t **out, qk_error_t *err) {
  qk_tree_options_t def;
  qk_status_t st;
  if (!out) return say(err, QK_ERR_INVALID, SIZE_MAX, "no place for the tree (out is NULL)");
  *out = NULL;
  if (!options) {
    qk_tree_options_init(&def);
    options = &def;
  }
  qk_square_t root = {0, 0, 1};
  if ((st = check_input(points, n, options, &root, err))) return st;

  qk_allocator_t alloc = {NULL, NULL};
  if (options->allocator) alloc = *options->allocator;
  qk_tree_t *t = qk__realloc(&alloc, NULL, 0, sizeof *t);
  if (!t) return say(err, QK_ERR_NOMEM, SIZE_MAX, "%s", qk_strerror(QK_ERR_NOMEM));
  memset(t, 0, sizeof *t);
  t->alloc = alloc;
  t->capacity = options->capacity ? options->capacity : 1;
  t->max_depth = options->max_depth ? options->max_depth : QK_DEFAULT_MAX_DEPTH;
  t->threads = options->threads;
  t->fixed_root = options->has_root != 0;
  t->huge_pages = options->huge_pages != 0;
  if ((st = fill(t, points, n, root))) goto fail;
  /* Give back the node arrays' growth slack; if the allocator will not shrink, keep it. */
  if (t->cap_nodes > t->n_nodes + t->n_nodes / 16) {
    qk__node_t *nn = qk__realloc(&t->alloc, t->nodes, (size_t)t->cap_nodes * sizeof *nn,
                                 (size_t)t->n_nodes * sizeof *nn);
    if (nn) {
      t->nodes = nn;
      t->cap_nodes = t->n_nodes;
    }
  }
  uint32_t nb = (t->n_nodes - 1) / 4;
  if (t->cap_blocks > nb + nb / 16 && nb > 0) {
    qk__block_t *nk = qk__realloc(&t->alloc, t->blocks, (size_t)t->cap_blocks * sizeof *nk,
                                  (size_t)nb * sizeof *nk);
    if (nk) {
      t->blocks = nk;
      t->cap_blocks = nb;
    }
  }
  *out = t;
  return QK_OK;
fail:
  qk_tree_free(t);
  return say(err, st, SIZE_MAX, "%s", qk_strerror(st));
}

/* The build's parallel regions (bounding box, keys, scatter, fine pass, subtrees) on one
 * team of workers, started once (index/threads.c). */
qk_status_t qk_tree_build_ex(const qk_point_t *points, size_t n, const qk_tree_options_t *options,
                             qk_tree_t **out, qk_error_t *err) {
  qk__team_begin(options && points ? build_team(options->threads, n) : 1);
  qk_status_t st = build_ex(points, n, options, out, err);
  qk__team_end();
  return st;
}

static qk_status_t rebuild(qk_tree_t *t, const qk_point_t *points, size_t n, qk_error_t *err);

qk_status_t qk_tree_rebuild(qk_tree_t *t, const qk_point_t *points, size_t n, qk_error_t *err) {
  qk__team_begin(t && points ? build_team(t->threads, n) : 1);
  qk_status_t st = rebuild(t, points, n, err);
  qk__team_end();
  return st;
}

static qk_status_t rebuild(qk_tree_t *t, const qk_point_t *points, size_t n, qk_error_t *err) {
  if (!t) return say(err, QK_ERR_INVALID, SIZE_MAX, "no tree to rebuild");
  qk_tree_options_t o;
  qk_tree_options_init(&o);
  o.capacity = t->capacity;
  o.max_depth = t->max_depth;
  o.threads = t->threads;
  o.has_root = t->fixed_root;
  o.root = (qk_square_t){t->root_x, t->root_y, t->side[0]};
  qk_square_t root = o.root;
  qk_status_t st = check_input(points, n, &o, &root, err);
  if (st) return st;
  /* Point arrays large enough, allocated before anything changes; their old contents
   * need no copy. */
  size_t need = n ? n : 1;
  if (need > t->cap_slots) {
    slots_t s;
    if (need > UINT32_MAX) return say(err, QK_ERR_LIMIT, SIZE_MAX, "%zu points", n);
    if (slots_alloc(t, need, &s)) {
      /* left empty, as after a later failure (the header's promise): the old points
       * stayed and the caller could not tell which had happened */
      (void)fill(t, points, 0, root); /* (no allocation: the tree has a node and a slot) */
      return say(err, QK_ERR_NOMEM, SIZE_MAX, "out of memory");
    }
    slots_install(t, s, need);
  }
  /* From now on the bulk build keeps its record block for the next one (a tree rebuilt
   * once is likely rebuilt every frame): it is the largest block a build borrows, which a
   * C library may give back to the system between builds and fault in again. */
  t->keep_rec = true;
  if ((st = fill(t, points, n, root))) return say(err, st, SIZE_MAX, "%s", qk_strerror(st));
  return QK_OK;
}

void qk_tree_free(qk_tree_t *t) {
  if (!t) return;
  qk_allocator_t a = t->alloc;
  qk__free(&a, t->nodes, (size_t)t->cap_nodes * sizeof(qk__node_t));
  qk__free(&a, t->blocks, (size_t)t->cap_blocks * sizeof(qk__block_t));
  qk__free(&a, t->free_ids, (size_t)t->cap_free_ids * sizeof(qk_id_t));
  slots_t pts = {t->px, t->py, t->pid};
  slots_free(&a, &pts, t->cap_slots);
  qk__free(&a, qk__id_map_if_made(t), (size_t)qk__id_map_capacity(t) * sizeof(uint32_t));
  qk__free(&a, t->kept_rec, t->kept_rec_bytes);
  qk__free(&a, t, sizeof *t);
}

/* ---- insert and remove --------------------------------------------------------------- */

/* Descend from the root to the leaf whose square holds (x, y); its geometry to *g. */
static uint32_t descend(const qk_tree_t *t, double x, double y, qk__geom_t *g) {
  uint32_t v = 0;
  qk__geom_t c = {t->root_x, t->root_y, 0};
  while (!qk__is_leaf(&t->nodes[v])) {
    unsigned q = qk__quadrant_of(c.x0, c.y0, t->side[c.depth + 1], x, y);
    v = t->nodes[v].child + q;
    c = qk__child_geom(t, c, q);
  }
  if (g) *g = c;
  return v;
}

/* Put point (p, id) into the tree: into the leaf that holds p, moved to the tail first
 * when its block is full, then split while over capacity. Everything must have been
 * reserved: nodes for a cascade to the depth cap, the tail for the move, the map entry. */
static void place(qk_tree_t *t, qk_point_t p, qk_id_t id) {
  uint32_t *w = qk__id_map_if_made(t);
  qk__geom_t g;
  uint32_t leaf = descend(t, p.x, p.y, &g);
  qk__node_t *n = &t->nodes[leaf];
  if (n->count == n->room) {
    uint32_t to = t->n_slots, newroom = grown_room(n->count);
    memcpy(t->px + to, t->px + n->start, (size_t)n->count * sizeof(double));
    memcpy(t->py + to, t->py + n->start, (size_t)n->count * sizeof(double));
    memcpy(t->pid + to, t->pid + n->start, (size_t)n->count * sizeof(qk_id_t));
    if (w)
      for (uint32_t i = 0; i < n->count; i++) w[t->pid[to + i]] = to + i;
    t->garbage += n->room;
    n->start = to;
    n->room = newroom;
    t->n_slots += newroom;
  }
  uint32_t s = n->start + n->count;
  t->px[s] = p.x;
  t->py[s] = p.y;
  t->pid[s] = id;
  if (w) w[id] = s;
  for (uint32_t v = leaf; v != QK_NONE; v = qk__parent(t, v)) t->nodes[v].count++;
  t->n_points++;
  split_while_full(t, leaf, g);
}

/* Tail slots a place() of p needs, when the leaf that holds p has `count` points in
 * `room` slots. */
static size_t place_need(uint32_t count, uint32_t room) {
  return count == room ? grown_room(count) : 0;
}

qk_status_t qk_tree_insert(qk_tree_t *t, qk_point_t p, qk_id_t *id_out) {
  qk_status_t st;
  if (!t) return QK_ERR_INVALID;
  if (!isfinite(p.x) || !isfinite(p.y)) return QK_ERR_NONFINITE;
  if (!inside_root(t, p.x, p.y)) return QK_ERR_OUTSIDE;
  bool reuse = t->n_free_ids > 0;
  if (!reuse && t->n_ids >= QK_MAX_POINTS) return QK_ERR_LIMIT;

  /* All allocation first: the id map (for a new id), nodes for a cascade of splits down
   * to the depth cap, and a larger block for the leaf if its block is full. */
  uint32_t *w;
  if ((st = own_map(t, false, &w))) return st;
  if (w && !reuse) {
    if ((st = grow(&t->alloc, (void **)&w, &t->cap_ids, (size_t)t->n_ids + 1, sizeof(uint32_t))))
      return st;
    atomic_store_explicit(&t->where, w, memory_order_release);
  }
  if ((st = qk__reserve_nodes(t, 4 * (t->max_depth + 1)))) return st;
  uint32_t leaf = descend(t, p.x, p.y, NULL);
  const qk__node_t *n = &t->nodes[leaf];
  if ((st = reserve_tail(t, place_need(n->count, n->room), leaf))) return st;

  /* From here on nothing can fail. Removed ids are handed out again, the most recently
   * removed first; a new id only when none is free. */
  qk_id_t id = reuse ? t->free_ids[--t->n_free_ids] : t->n_ids++;
  place(t, p, id);
  if (id_out) *id_out = id;
  if (t->cap_free_ids > 2 * (size_t)t->n_free_ids + 256) { /* (given back as it empties) */
    uint32_t cap = t->n_free_ids + t->n_free_ids / 8 + 16;
    qk_id_t *f = qk__realloc(&t->alloc, t->free_ids, (size_t)t->cap_free_ids * sizeof *f,
                             (size_t)cap * sizeof *f);
    if (f) t->free_ids = f, t->cap_free_ids = cap; /* (else kept as it is) */
  }
  return QK_OK;
}

/* Move every point of v's subtree into one block at the end of the point arrays, make v
 * a leaf over that block, and free the node blocks below it. The tail must have room. */
static void collapse(qk_tree_t *t, uint32_t v) {
  uint32_t to = t->n_slots, pos = to;
  uint32_t *w = qk__id_map_if_made(t);
  uint32_t stack[4 * (QK_MAX_DEPTH_LIMIT + 2)], top = 0;
  stack[top++] = t->nodes[v].child;
  while (top) {
    uint32_t b = stack[--top];
    for (uint32_t q = 0; q < 4; q++) {
      qk__node_t *c = &t->nodes[b + q];
      if (!qk__is_leaf(c)) {
        stack[top++] = c->child;
        continue;
      }
      memcpy(t->px + pos, t->px + c->start, (size_t)c->count * sizeof(double));
      memcpy(t->py + pos, t->py + c->start, (size_t)c->count * sizeof(double));
      memcpy(t->pid + pos, t->pid + c->start, (size_t)c->count * sizeof(qk_id_t));
      if (w)
        for (uint32_t i = 0; i < c->count; i++) w[t->pid[pos + i]] = pos + i;
      pos += c->count;
      t->garbage += c->room;
    }
    release_block(t, b);
  }
  qk__node_t *n = &t->nodes[v];
  n->child = QK_NONE;
  n->start = to;
  n->room = pos - to;
  t->n_slots = pos;
}

/* The highest ancestor of `leaf` that a removal from it merges (the highest one left
 * holding at most `capacity` points: counts only grow upwards, so those ancestors form a
 * chain above the leaf), or QK_NONE. */
static uint32_t merge_top(const qk_tree_t *t, uint32_t leaf) {
  uint32_t top = QK_NONE;
  if (!t->refined)
    for (uint32_t v = qk__parent(t, leaf); v != QK_NONE; v = qk__parent(t, v)) {
      if (t->nodes[v].count - 1 > t->capacity) break;
      top = v;
    }
  return top;
}

/* Take the point in slot w[id] out of `leaf` (filling the hole with the leaf's last point)
 * and merge `top` if it is not QK_NONE; the tail must have room for the merge. */
static void unplace(qk_tree_t *t, uint32_t *w, qk_id_t id, uint32_t leaf, uint32_t top) {
  uint32_t s = w[id];
  qk__node_t *n = &t->nodes[leaf];
  uint32_t last = n->start + n->count - 1;
  if (s != last) {
    t->px[s] = t->px[last];
    t->py[s] = t->py[last];
    t->pid[s] = t->pid[last];
    w[t->pid[s]] = s;
  }
  w[id] = QK_NONE;
  for (uint32_t v = leaf; v != QK_NONE; v = qk__parent(t, v)) t->nodes[v].count--;
  t->n_points--;
  if (top != QK_NONE) collapse(t, top);
}

qk_status_t qk_tree_remove(qk_tree_t *t, qk_id_t id) {
  if (!t) return QK_ERR_INVALID;
  if (id >= t->n_ids) return QK_ERR_NOT_FOUND;
  uint32_t *w;
  qk_status_t st = own_map(t, true, &w);
  if (st) return st;
  if (w[id] == QK_NONE) return QK_ERR_NOT_FOUND;
  uint32_t leaf = descend(t, t->px[w[id]], t->py[w[id]], NULL);
  uint32_t top = merge_top(t, leaf);
  /* Room to remember the id for reuse, and a tail for the merge. */
  if ((st = grow(&t->alloc, (void **)&t->free_ids, &t->cap_free_ids, (size_t)t->n_free_ids + 1,
                 sizeof(qk_id_t))))
    return st;
  if (top != QK_NONE && (st = reserve_tail(t, t->nodes[top].count, QK_NONE))) return st;

  /* Nothing can fail from here on (the reservation may have compacted the arrays, so
   * the slot is read only in unplace). */
  unplace(t, w, id, leaf, top);
  t->free_ids[t->n_free_ids++] = id;
  give_back(t);
  return QK_OK;
}

qk_status_t qk_tree_move(qk_tree_t *t, qk_id_t id, qk_point_t p) {
  if (!t) return QK_ERR_INVALID;
  if (!isfinite(p.x) || !isfinite(p.y)) return QK_ERR_NONFINITE;
  if (!inside_root(t, p.x, p.y)) return QK_ERR_OUTSIDE;
  if (id >= t->n_ids) return QK_ERR_NOT_FOUND;
  uint32_t *w;
  qk_status_t st = own_map(t, true, &w);
  if (st) return st;
  if (w[id] == QK_NONE) return QK_ERR_NOT_FOUND;
  uint32_t from = descend(t, t->px[w[id]], t->py[w[id]], NULL);
  uint32_t to = descend(t, p.x, p.y, NULL);
  if (from == to) {
    /* The same leaf: only the coordinates change, and with them no count or shape. */
    t->px[w[id]] = p.x;
    t->py[w[id]] = p.y;
    return QK_OK;
  }
  /* Another leaf: the removal's merge and the insertion's move and splits, all reserved
   * first. If the merge swallows the target leaf, the point goes into the merged leaf,
   * which then is full (its room is its count). */
  uint32_t top = merge_top(t, from);
  uint32_t count = t->nodes[to].count;
  if (top != QK_NONE)
    for (uint32_t v = to; v != QK_NONE; v = qk__parent(t, v))
      if (v == top) count = t->nodes[top].count - 1;
  /* Reserve as if the target leaf were full: the reservation may compact the arrays,
   * after which every leaf is, but the target when no merge swallows it. */
  size_t need = (top != QK_NONE ? t->nodes[top].count : 0) + grown_room(count);
  if ((st = qk__reserve_nodes(t, 4 * (t->max_depth + 1)))) return st;
  if ((st = reserve_tail(t, need, top == QK_NONE ? to : QK_NONE))) return st;

  /* Nothing can fail from here on. */
  unplace(t, w, id, from, top);
  place(t, p, id);
  return QK_OK;
}

/* ---- lookups ---------------------------------------------------------------------- */

/* The slot of a point id, or QK_NONE. Uses (making it if need be) the id map; if the map
 * cannot be allocated, a scan of the leaves gives the same answer in O(n). */
static uint32_t slot_of(const qk_tree_t *t, qk_id_t id) {
  if (id >= t->n_ids) return QK_NONE;
  const uint32_t *w;
  if (qk__id_map(t, &w) == QK_OK) return w[id];
  for (uint32_t v = 0; v < t->n_nodes; v++) {
    const qk__node_t *n = &t->nodes[v];
    if (!qk__live(t, v) || !qk__is_leaf(n)) continue;
    for (uint32_t s = n->start; s < n->start + n->count; s++)
      if (t->pid[s] == id) return s;
  }
  return QK_NONE;
}

qk_status_t qk_tree_point(const qk_tree_t *t, qk_id_t id, qk_point_t *p) {
  if (!t || !p) return QK_ERR_INVALID;
  uint32_t s = slot_of(t, id);
  if (s == QK_NONE) return QK_ERR_NOT_FOUND;
  p->x = t->px[s];
  p->y = t->py[s];
  return QK_OK;
}

qk_status_t qk_tree_leaf_of(const qk_tree_t *t, qk_id_t id, qk_node_t *leaf) {
  if (!t || !leaf) return QK_ERR_INVALID;
  uint32_t s = slot_of(t, id);
  if (s == QK_NONE) return QK_ERR_NOT_FOUND;
  *leaf = descend(t, t->px[s], t->py[s], NULL);
  return QK_OK;
}

qk_status_t qk_tree_find_leaf(const qk_tree_t *t, qk_point_t p, qk_node_t *leaf) {
  if (!t || !leaf) return QK_ERR_INVALID;
  if (!isfinite(p.x) || !isfinite(p.y)) return QK_ERR_NONFINITE;
  if (!inside_root(t, p.x, p.y)) return QK_ERR_OUTSIDE;
  *leaf = descend(t, p.x, p.y, NULL);
  return QK_OK;
}

qk_node_t qk_tree_root(const qk_tree_t *t) {
  (void)t;
  return 0;
}

static int is_live(const qk_tree_t *t, qk_node_t v) { return t && qk__live(t, v); }

int qk_tree_node_is_leaf(const qk_tree_t *t, qk_node_t v) {
  return is_live(t, v) && qk__is_leaf(&t->nodes[v]);
}

qk_status_t qk_tree_node_info(const qk_tree_t *t, qk_node_t v, qk_node_info_t *info) {
  if (!t || !info) return QK_ERR_INVALID;
  if (!is_live(t, v)) return QK_ERR_NOT_FOUND;
  const qk__node_t *n = &t->nodes[v];
  qk__geom_t g = qk__node_geom(t, v);
  info->square.x = g.x0;
  info->square.y = g.y0;
  info->square.side = t->side[g.depth];
  info->depth = g.depth;
  info->parent = qk__parent(t, v);
  for (uint32_t q = 0; q < 4; q++) info->children[q] = qk__is_leaf(n) ? QK_NONE : n->child + q;
  info->quadrant = (qk_quadrant_t)qk__quadrant(v);
  info->is_leaf = qk__is_leaf(n);
  info->count = n->count;
  return QK_OK;
}

qk_status_t qk_tree_leaf_points(const qk_tree_t *t, qk_node_t leaf, const double **x,
                                const double **y, const qk_id_t **ids, size_t *n) {
  if (!qk_tree_node_is_leaf(t, leaf)) return QK_ERR_INVALID;
  const qk__node_t *l = &t->nodes[leaf];
  if (x) *x = t->px + l->start;
  if (y) *y = t->py + l->start;
  if (ids) *ids = t->pid + l->start;
  if (n) *n = l->count;
  return QK_OK;
}

/* ---- refinement beyond the capacity rule ---------------------------------------------- */

/* The split of qk_tree_split_leaf and qk__tree_split_leaf_at, for a live leaf of geometry
 * g. The node arrays grow by half at least when full (qk__reserve_nodes would grow them by
 * an eighth: callers that split leaf by leaf, as the meshers do, copied them often). */
static qk_status_t split_leaf_at(qk_tree_t *t, qk_node_t leaf, qk__geom_t g) {
  if (!qk__can_split(t, g)) return QK_ERR_LIMIT;
  size_t need = (size_t)t->n_nodes + 4; /* as qk__reserve_nodes(t, 4) counts it */
  if (t->n_free_blocks == 0 && (need > t->cap_nodes || (need + 2) / 4 > t->cap_blocks)) {
    qk_status_t st = qk__reserve_nodes(t, t->n_nodes / 2 + 4);
    if (st) st = qk__reserve_nodes(t, 4); /* no room for the half: the four are enough */
    if (st) return st;
  }
  qk__split(t, leaf, g);
  t->refined = true;
  return QK_OK;
}

qk_status_t qk_tree_split_leaf(qk_tree_t *t, qk_node_t leaf) {
  if (!qk_tree_node_is_leaf(t, leaf)) return QK_ERR_INVALID;
  return split_leaf_at(t, leaf, qk__node_geom(t, leaf));
}

qk_status_t qk__tree_split_leaf_at(qk_tree_t *t, qk_node_t leaf, double x0, double y0,
                                   unsigned depth) {
  if (!t || !qk__live(t, leaf) || !qk__is_leaf(&t->nodes[leaf])) return QK_ERR_INVALID;
  qk__geom_t g = {x0, y0, depth};
#ifndef NDEBUG
  qk__geom_t w = qk__node_geom(t, leaf);
  assert(w.depth == depth && w.x0 == x0 && w.y0 == y0);
#endif
  return split_leaf_at(t, leaf, g);
}

qk_status_t qk_tree_refine(qk_tree_t *t, qk_refine_fn fn, void *ud) {
  if (!t || !fn) return QK_ERR_INVALID;
  t->refined = true;
  /* Depth-first over the leaves with an explicit stack; every split pushes its children,
   * so the stack never holds more than 3 per level plus the initial leaves. */
  size_t cap = 64, top = 0;
  qk_status_t st = QK_OK;
  uint32_t *stack = qk__realloc(&t->alloc, NULL, 0, cap * sizeof *stack);
  if (!stack) return QK_ERR_NOMEM;
  stack[top++] = 0;
  while (top) {
    uint32_t v = stack[--top];
    qk__node_t *n = &t->nodes[v];
    if (!qk__is_leaf(n)) {
      if (top + 4 > cap) {
        uint32_t *ns = qk__realloc(&t->alloc, stack, cap * sizeof *stack, 2 * cap * sizeof *stack);
        if (!ns) {
          st = QK_ERR_NOMEM;
          break;
        }
        stack = ns;
        cap *= 2;
      }
      for (int q = 3; q >= 0; q--) stack[top++] = n->child + (uint32_t)q;
      continue;
    }
    qk__geom_t g = qk__node_geom(t, v);
    qk_square_t sq = {g.x0, g.y0, t->side[g.depth]};
    if (!qk__can_split(t, g) || !fn(t, v, sq, g.depth, ud)) continue;
    if ((st = qk__reserve_nodes(t, 4))) break;
    qk__split(t, v, g);
    stack[top++] = v; /* revisit: now internal, pushes its children */
  }
  qk__free(&t->alloc, stack, cap * sizeof *stack);
  return st;
}
