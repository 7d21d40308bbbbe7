/*
 * BalanceQuadTree (lecture notes, section V; de Berg et al., ch. 14.2): split leaves
 * until any two leaves whose squares share an edge differ by at most one in depth.
 *
 * Done on a linear representation, as p4est balances its linear octrees: cells are named
 * by depth and integer position (ix, iy at that depth, so a cell's ancestor at depth j is
 * (ix, iy) >> (depth - j)), the internal cells are a hash set, and the leaves wait in one
 * list per depth. A leaf L of depth d needs, across each edge it shares with its parent P's
 * boundary, the cell N of P's size beside P to exist, that is N's parent (depth d - 2) to
 * be internal; otherwise a leaf of depth <= d - 2 touches L. If it is not, the leaf that
 * covers N is split, and its descendants towards N, down to depth d - 1 (the notes' split
 * of the larger neighbour). New leaves are shallower than L, so taking the lists from the
 * deepest up meets every leaf after everything that could split it: one pass. Only then
 * are the node array and the points split, top-down, with every node reserved at once.
 */
#include <string.h>

#include "index/index_internal.h"

/* A cell: depth and integer position at that depth. */
typedef struct cell {
  uint64_t x, y;
  uint32_t d;
  uint32_t used; /* in the hash set: slot taken */
} cell_t;

/* Open-addressing hash set of cells (the internal ones). */
typedef struct cset {
  cell_t *slot;
  size_t cap, n;
} cset_t;

/*
 * A cell's home slot: cells that share their ancestor three levels up share a run of 64
 * slots, in Z-order inside it, and the runs are scattered by a mixing hash of that
 * ancestor. The leaves are listed in Z-order, so consecutive lookups mostly probe a run
 * already in the cache, where a plain mixing hash costs a DRAM miss per lookup; scattering
 * the runs keeps clustered trees from piling up in one part of the table.
 */
static size_t hash_cell(uint64_t x, uint64_t y, uint32_t d, size_t cap) {
  const unsigned k = d < 3 ? d : 3;
  uint64_t ax = x >> k, ay = y >> k, lx = x & ((1u << k) - 1), ly = y & ((1u << k) - 1);
  uint64_t h = ax * 0x9E3779B97F4A7C15ull ^ (ay + 0x632BE59BD9B4E019ull) * 0xC2B2AE3D27D4EB4Full;
  h ^= (uint64_t)d * 0x165667B19E3779F9ull;
  h ^= h >> 29;
  /* Z-order of the low bits: (lx, ly) < 8 each, six bits. */
  uint64_t z = 0;
  for (unsigned i = 0; i < k; i++)
    z |= ((lx >> i) & 1u) << (2 * i + 1) | ((ly >> i) & 1u) << (2 * i);
  return (size_t)(h << 6 | z) & (cap - 1);
}

static bool cset_has(const cset_t *s, uint64_t x, uint64_t y, uint32_t d) {
  for (size_t i = hash_cell(x, y, d, s->cap);; i = (i + 1) & (s->cap - 1)) {
    const cell_t *c = &s->slot[i];
    if (!c->used) return false;
    if (c->x == x && c->y == y && c->d == d) return true;
  }
}

/* Add a cell (room must have been made: load at most one half). */
static void cset_put(cset_t *s, uint64_t x, uint64_t y, uint32_t d) {
  size_t i = hash_cell(x, y, d, s->cap);
  while (s->slot[i].used) {
    if (s->slot[i].x == x && s->slot[i].y == y && s->slot[i].d == d) return;
    i = (i + 1) & (s->cap - 1);
  }
  s->slot[i] = (cell_t){x, y, d, 1};
  s->n++;
}

/* Make room for `extra` more cells at load <= 1/2. */
static qk_status_t cset_reserve(const qk_tree_t *t, cset_t *s, size_t extra) {
  if (2 * (s->n + extra) <= s->cap) return QK_OK;
  size_t cap = s->cap ? s->cap : 64;
  while (2 * (s->n + extra) > cap) cap *= 2;
  cell_t *nw = qk__realloc(&t->alloc, NULL, 0, cap * sizeof *nw);
  if (!nw) return QK_ERR_NOMEM;
  memset(nw, 0, cap * sizeof *nw);
  cset_t ns = {nw, cap, 0};
  for (size_t i = 0; i < s->cap; i++)
    if (s->slot[i].used) cset_put(&ns, s->slot[i].x, s->slot[i].y, s->slot[i].d);
  qk__free(&t->alloc, s->slot, s->cap * sizeof *s->slot);
  *s = ns;
  return QK_OK;
}

/* A growable list of cells. */
typedef struct clist {
  cell_t *v;
  size_t n, cap;
} clist_t;

static qk_status_t clist_push(const qk_tree_t *t, clist_t *l, cell_t c) {
  if (l->n == l->cap) {
    size_t cap = l->cap ? 2 * l->cap : 64;
    cell_t *nv = qk__realloc(&t->alloc, l->v, l->cap * sizeof *nv, cap * sizeof *nv);
    if (!nv) return QK_ERR_NOMEM;
    l->v = nv;
    l->cap = cap;
  }
  l->v[l->n++] = c;
  return QK_OK;
}

/* Everything the balance works with. */
typedef struct work {
  qk_tree_t *t;
  cset_t internal;
  clist_t leaves[QK_MAX_DEPTH_LIMIT + 1]; /* leaves waiting, by depth */
} work_t;

static void work_free(work_t *w) {
  const qk_allocator_t *a = &w->t->alloc;
  qk__free(a, w->internal.slot, w->internal.cap * sizeof(cell_t));
  for (int d = 0; d <= QK_MAX_DEPTH_LIMIT; d++)
    qk__free(a, w->leaves[d].v, w->leaves[d].cap * sizeof(cell_t));
}

/* The internal cells into the set and, when `lists` is set, the leaves into their lists:
 * one pre-order walk, positions computed along the path. */
static qk_status_t collect(work_t *w, bool lists) {
  const qk_tree_t *t = w->t;
  typedef struct item {
    uint32_t v;
    cell_t c;
  } item_t;
  item_t stack[3 * (QK_MAX_DEPTH_LIMIT + 2) + 4];
  int sp = 0;
  stack[sp++] = (item_t){0, {0, 0, 0, 0}};
  qk_status_t st = QK_OK;
  while (sp > 0 && st == QK_OK) {
    item_t it = stack[--sp];
    const qk__node_t *n = &t->nodes[it.v];
    if (qk__is_leaf(n)) {
      if (lists) st = clist_push(t, &w->leaves[it.c.d], it.c);
      continue;
    }
    if ((st = cset_reserve(t, &w->internal, 1))) break;
    cset_put(&w->internal, it.c.x, it.c.y, it.c.d);
    for (int q = 3; q >= 0; q--)
      stack[sp++] = (item_t){n->child + (uint32_t)q,
                             {2 * it.c.x + qk__q_east((unsigned)q),
                              2 * it.c.y + qk__q_north((unsigned)q), it.c.d + 1, 0}};
  }
  return st;
}

/* The geometry of a cell, by the same arithmetic as a descent. */
static qk__geom_t cell_geom(const qk_tree_t *t, cell_t c) {
  qk__geom_t g = {t->root_x, t->root_y, 0};
  for (uint32_t l = 1; l <= c.d; l++) {
    unsigned east = (unsigned)(c.x >> (c.d - l)) & 1u, north = (unsigned)(c.y >> (c.d - l)) & 1u;
    g = qk__child_geom(t, g, east ? (north ? QK_NE : QK_SE) : (north ? QK_NW : QK_SW));
  }
  return g;
}

/* Make the cell (nx, ny) of depth e exist: split the leaf that covers it and its
 * descendants towards it, as far as they can split. New leaves go to their lists. */
static qk_status_t make_exist(work_t *w, uint64_t nx, uint64_t ny, uint32_t e) {
  /* The deepest internal ancestor of the cell (the root at worst, which is internal when
   * there is a cell of depth >= 2 at all). */
  uint32_t j = e - 1;
  while (j > 0 && !cset_has(&w->internal, nx >> (e - j), ny >> (e - j), j)) j--;
  for (uint32_t k = j + 1; k < e; k++) {
    /* The leaf of depth k on the way: split it, if it can be. */
    cell_t c = {nx >> (e - k), ny >> (e - k), k, 0};
    if (!qk__can_split(w->t, cell_geom(w->t, c))) break;
    qk_status_t st = cset_reserve(w->t, &w->internal, 1);
    if (st) return st;
    cset_put(&w->internal, c.x, c.y, c.d);
    /* Its four children are leaves now, but the one towards N when it splits next. */
    for (unsigned q = 0; q < 4; q++) {
      cell_t ch = {2 * c.x + qk__q_east(q), 2 * c.y + qk__q_north(q), k + 1, 0};
      if ((st = clist_push(w->t, &w->leaves[k + 1], ch))) return st;
    }
  }
  return QK_OK;
}

/* Split, top-down, every leaf whose cell the set says is internal. Nodes are reserved. */
static void apply(qk_tree_t *t, const cset_t *internal) {
  typedef struct item {
    uint32_t v;
    qk__geom_t g;
    uint64_t x, y;
  } item_t;
  item_t stack[3 * (QK_MAX_DEPTH_LIMIT + 2) + 4];
  int sp = 0;
  stack[sp++] = (item_t){0, {t->root_x, t->root_y, 0}, 0, 0};
  while (sp > 0) {
    item_t it = stack[--sp];
    if (qk__is_leaf(&t->nodes[it.v])) {
      if (!cset_has(internal, it.x, it.y, it.g.depth)) continue;
      qk__split(t, it.v, it.g);
    }
    uint32_t child = t->nodes[it.v].child;
    for (int q = 3; q >= 0; q--)
      stack[sp++] =
          (item_t){child + (uint32_t)q, qk__child_geom(t, it.g, (unsigned)q),
                   2 * it.x + qk__q_east((unsigned)q), 2 * it.y + qk__q_north((unsigned)q)};
  }
}

/* The two directions in which a child in quadrant q lies on its parent's boundary, as
 * (dx, dy) steps. */
static void outer_steps(unsigned q, int dx[2], int dy[2]) {
  dx[0] = 0;
  dy[0] = qk__q_north(q) ? 1 : -1;
  dx[1] = qk__q_east(q) ? 1 : -1;
  dy[1] = 0;
}

/* The cell of depth d - 1 beside leaf c's parent across its outer side i, if inside the
 * root. */
static bool beside_parent(cell_t c, int i, uint64_t *nx, uint64_t *ny) {
  unsigned q = (c.x & 1) ? ((c.y & 1) ? QK_NE : QK_SE) : ((c.y & 1) ? QK_NW : QK_SW);
  int dx[2], dy[2];
  outer_steps(q, dx, dy);
  uint64_t px = c.x >> 1, py = c.y >> 1, lim = (uint64_t)1 << (c.d - 1);
  if ((dx[i] < 0 && px == 0) || (dy[i] < 0 && py == 0)) return false;
  *nx = px + (uint64_t)(int64_t)dx[i];
  *ny = py + (uint64_t)(int64_t)dy[i];
  return *nx < lim && *ny < lim;
}

qk_status_t qk_tree_balance(qk_tree_t *t) {
  if (!t) return QK_ERR_INVALID;
  work_t w;
  memset(&w, 0, sizeof w);
  w.t = t;
  size_t before = 0;
  /* Room for the internal cells and as many again for the splits, so that the set is
   * rarely rehashed (a quarter of the nodes are internal). */
  qk_status_t st = cset_reserve(t, &w.internal, t->n_nodes / 2 + 64);
  if (st == QK_OK) st = collect(&w, true);
  before = w.internal.n;
  /* Deepest lists first: a leaf of depth d can only make leaves of depth < d. */
  for (uint32_t d = QK_MAX_DEPTH_LIMIT; d >= 2 && st == QK_OK; d--) {
    for (size_t i = 0; i < w.leaves[d].n && st == QK_OK; i++) {
      cell_t c = w.leaves[d].v[i];
      if (cset_has(&w.internal, c.x, c.y, c.d)) continue; /* split since it was listed */
      for (int k = 0; k < 2 && st == QK_OK; k++) {
        uint64_t nx, ny;
        if (!beside_parent(c, k, &nx, &ny)) continue;
        if (d >= 3 && !cset_has(&w.internal, nx >> 1, ny >> 1, d - 2))
          st = make_exist(&w, nx, ny, d - 1);
        /* (d == 2: the cell beside the parent is a child of the root, always there.) */
      }
    }
  }
  /* The splits, into the node array at the end: all nodes at once, then nothing fails. */
  if (st == QK_OK) {
    size_t splits = w.internal.n - before;
    if (splits > UINT32_MAX / 4)
      st = QK_ERR_LIMIT;
    else if (splits && (st = qk__reserve_nodes(t, (uint32_t)(4 * splits))) == QK_OK)
      apply(t, &w.internal);
  }
  t->refined = true;
  work_free(&w);
  return st;
}

int qk_tree_is_balanced(const qk_tree_t *t) {
  if (!t) return 0;
  /* One pre-order pass that carries every node's four neighbours (NorthNeighbor's answers:
   * of its depth, or a larger leaf, or none) down from its parent's: a child's neighbour
   * across an inner side is its sibling, across an outer side the parent's neighbour's
   * mirrored child (or that neighbour itself, when it is a leaf). A leaf has a neighbour
   * less than half its size exactly when its neighbour of equal depth is internal and one
   * of that neighbour's two children facing it is internal too; checking every leaf so
   * covers every pair of adjacent leaves. No memory beyond a stack of O(depth). */
  typedef struct item {
    uint32_t v;
    uint32_t nb[4];
  } item_t;
  item_t stack[3 * (QK_MAX_DEPTH_LIMIT + 2) + 4];
  int sp = 0;
  stack[sp++] = (item_t){0, {QK_NONE, QK_NONE, QK_NONE, QK_NONE}};
  while (sp > 0) {
    item_t it = stack[--sp];
    const qk__node_t *n = &t->nodes[it.v];
    if (qk__is_leaf(n)) {
      for (unsigned d = 0; d < 4; d++) {
        uint32_t u = it.nb[d];
        if (u == QK_NONE || qk__is_leaf(&t->nodes[u])) continue;
        unsigned f[2];
        qk__facing_children((qk_dir_t)d, f);
        uint32_t c = t->nodes[u].child;
        if (!qk__is_leaf(&t->nodes[c + f[0]]) || !qk__is_leaf(&t->nodes[c + f[1]])) return 0;
      }
      continue;
    }
    for (int q = 3; q >= 0; q--) {
      item_t ch = {n->child + (uint32_t)q, {0, 0, 0, 0}};
      for (unsigned d = 0; d < 4; d++) {
        unsigned m = qk__mirror((unsigned)q, d);
        if (!qk__on_side((unsigned)q, d)) {
          ch.nb[d] = n->child + m; /* the sibling across */
        } else {
          uint32_t u = it.nb[d];
          ch.nb[d] = (u == QK_NONE || qk__is_leaf(&t->nodes[u])) ? u : t->nodes[u].child + m;
        }
      }
      stack[sp++] = ch;
    }
  }
  return 1;
}
