/*
 * BalanceQuadTree (lecture notes, section V; de Berg et al., ch. 14.2): split leaves
 * until any two leaves whose squares share an edge differ by at most one in depth.
 *
 * The rule it enforces, on internal cells rather than on pairs of leaves: a tree is
 * balanced exactly when, for every internal cell c of depth k >= 2 and each of the two
 * sides of c that lie on its parent p's boundary, the cell of p's size beside p on that
 * side is internal (or outside the root). Necessary: c's children, of depth k + 1, touch
 * that side, so the cell of depth k beside c there must exist, and its parent is that
 * cell beside p. Sufficient: if leaves A (depth a) and B (depth >= a + 2) share an edge,
 * B's ancestor c of depth a + 1 is internal and touches A on a side of its parent, which
 * has A's size, so A is the cell beside the parent and is a leaf. The balanced tree is
 * then the least set of internal cells that holds the tree's own, is closed under
 * parents and obeys the rule (the notes' splits of the larger neighbour, in any order).
 *
 * 1. Check: one pre-order pass over the internal nodes carries every node's four
 *    NorthNeighbor answers (of its depth, or a larger leaf, or none) down from its
 *    parent's; the rule fails at a node exactly where its neighbour on a side is a leaf
 *    and one of its children on that side is internal. Leaves are never visited, so the
 *    pass reads about a quarter of the nodes, in the order the build laid them out, and
 *    allocates nothing: a balanced tree costs this pass alone.
 * 2. Closure: each failure names a cell that must become internal; it and its missing
 *    ancestors join a list of new cells (with a hash set for membership), and each new
 *    cell, taken from the list in turn, applies the rule to itself in its turn. A cell
 *    is internal when the tree's descent reaches it as an internal node or the set holds
 *    it. Real trees are nearly balanced, so the list is short.
 * 3. Splits: the new cells in the order they were made (every cell after its parent),
 *    each found by a descent and split, with all nodes reserved first so nothing fails.
 */
#include <string.h>

#include "index/index_internal.h"

/* A cell: depth and integer position at that depth. */
typedef struct cell {
  uint64_t x, y;
  uint32_t d;
  uint32_t used; /* in the hash set: slot taken */
} cell_t;

/* Open-addressing hash set of cells (the new internal ones). */
typedef struct cset {
  cell_t *slot;
  size_t cap, n;
} cset_t;

/*
 * A cell's home slot: cells that share their ancestor three levels up share a run of 64
 * slots, in Z-order inside it, and the runs are scattered by a mixing hash of that
 * ancestor: the new cells come in spatial clusters, so consecutive lookups mostly probe a
 * run already in the cache.
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
  if (!s->n) return false;
  for (size_t i = hash_cell(x, y, d, s->cap);; i = (i + 1) & (s->cap - 1)) {
    const cell_t *c = &s->slot[i];
    if (!c->used) return false;
    if (c->x == x && c->y == y && c->d == d) return true;
  }
}

/* Add a cell that is not in the set (room must have been made: load at most one half). */
static void cset_put(cset_t *s, uint64_t x, uint64_t y, uint32_t d) {
  size_t i = hash_cell(x, y, d, s->cap);
  while (s->slot[i].used) i = (i + 1) & (s->cap - 1);
  s->slot[i] = (cell_t){x, y, d, 1};
  s->n++;
}

/* Everything the balance works with. */
typedef struct work {
  qk_tree_t *t;
  cset_t fresh;    /* the new internal cells */
  cell_t *list;    /* the same, in the order they were made */
  size_t n, cap;   /* list length and capacity */
  bool check_only; /* qk_tree_is_balanced(): stop at the first failure */
  bool failed;     /* the rule failed somewhere (check_only) */
  /* The last descent's path (the tree does not change until step 3): the nodes and
   * geometries at depths 0..plen, toward the cell (px, py) of depth pe. A descent to a
   * nearby cell starts at the deepest node the two paths share. */
  uint32_t plen, pe;
  uint64_t px, py;
  uint32_t pv[QK_MAX_DEPTH_LIMIT + 2];
  qk__geom_t pg[QK_MAX_DEPTH_LIMIT + 2];
} work_t;

static void work_free(work_t *w) {
  const qk_allocator_t *a = &w->t->alloc;
  qk__free(a, w->fresh.slot, w->fresh.cap * sizeof(cell_t));
  qk__free(a, w->list, w->cap * sizeof(cell_t));
}

/* Room for one more new cell in the set (load <= 1/2) and in the list. */
static qk_status_t work_reserve(work_t *w) {
  const qk_allocator_t *a = &w->t->alloc;
  cset_t *s = &w->fresh;
  if (2 * (s->n + 1) > s->cap) {
    size_t cap = s->cap ? 2 * s->cap : 64;
    cell_t *nw = qk__realloc(a, NULL, 0, cap * sizeof *nw);
    if (!nw) return QK_ERR_NOMEM;
    memset(nw, 0, cap * sizeof *nw);
    cset_t ns = {nw, cap, 0};
    for (size_t i = 0; i < s->cap; i++)
      if (s->slot[i].used) cset_put(&ns, s->slot[i].x, s->slot[i].y, s->slot[i].d);
    qk__free(a, s->slot, s->cap * sizeof *s->slot);
    *s = ns;
  }
  if (w->n == w->cap) {
    size_t cap = w->cap ? 2 * w->cap : 64;
    cell_t *nl = qk__realloc(a, w->list, w->cap * sizeof *nl, cap * sizeof *nl);
    if (!nl) return QK_ERR_NOMEM;
    w->list = nl;
    w->cap = cap;
  }
  return QK_OK;
}

/* The quadrant of the child that holds the cell whose position bits there are (e, n). */
static inline unsigned quadrant_of_bits(unsigned e, unsigned n) {
  static const unsigned char q[2][2] = {{QK_SW, QK_NW}, {QK_SE, QK_NE}};
  return q[e][n];
}

/* Make the cell (x, y) of depth e internal, with its ancestors: those that are leaves in
 * the tree and not yet new cells join the new cells, top-down, as far as they can split
 * (a cell that cannot split stops the chain, as in a split of the tree itself). */
static qk_status_t make_internal(work_t *w, uint64_t x, uint64_t y, uint32_t e) {
  const qk_tree_t *t = w->t;
  /* The deepest depth at which this cell's ancestor is the last descent's. */
  uint32_t m = e < w->pe ? e : w->pe;
  uint64_t diff = (x >> (e - m) ^ w->px >> (w->pe - m)) | (y >> (e - m) ^ w->py >> (w->pe - m));
  while (diff) {
    diff >>= 1;
    m--;
  }
  if (m > w->plen) m = w->plen;
  uint32_t v = w->pv[m];
  qk__geom_t g = w->pg[m];
  while (g.depth < e && !qk__is_leaf(&t->nodes[v])) {
    unsigned sh = e - g.depth - 1;
    unsigned q = quadrant_of_bits((unsigned)(x >> sh) & 1u, (unsigned)(y >> sh) & 1u);
    v = t->nodes[v].child + q;
    g = qk__child_geom(t, g, q);
    w->pv[g.depth] = v;
    w->pg[g.depth] = g;
  }
  w->plen = g.depth;
  w->pe = e;
  w->px = x;
  w->py = y;
  if (!qk__is_leaf(&t->nodes[v])) return QK_OK; /* internal in the tree already */
  /* v is a leaf of depth g.depth <= e: the cells from there down to e on the way. */
  for (;;) {
    unsigned k = g.depth;
    uint64_t cx = x >> (e - k), cy = y >> (e - k);
    if (!cset_has(&w->fresh, cx, cy, k)) {
      if (!qk__can_split(t, g)) return QK_OK;
      qk_status_t st = work_reserve(w);
      if (st) return st;
      cset_put(&w->fresh, cx, cy, k);
      w->list[w->n++] = (cell_t){cx, cy, k, 1};
    }
    if (k == e) return QK_OK;
    unsigned sh = e - k - 1;
    g = qk__child_geom(t, g, quadrant_of_bits((unsigned)(x >> sh) & 1u, (unsigned)(y >> sh) & 1u));
  }
}

/* The rule for an internal cell (x, y) of depth k >= 2: the cells of its parent's size
 * beside its parent, on the two sides it shares with it, are made internal. */
static qk_status_t apply_rule(work_t *w, uint64_t x, uint64_t y, uint32_t k) {
  uint64_t px = x >> 1, py = y >> 1, lim = (uint64_t)1 << (k - 1);
  qk_status_t st = QK_OK;
  if (y & 1) {
    if (py + 1 < lim) st = make_internal(w, px, py + 1, k - 1);
  } else if (py > 0) {
    st = make_internal(w, px, py - 1, k - 1);
  }
  if (st) return st;
  if (x & 1) {
    if (px + 1 < lim) st = make_internal(w, px + 1, py, k - 1);
  } else if (px > 0) {
    st = make_internal(w, px - 1, py, k - 1);
  }
  return st;
}

/* The integer position and depth of node v, from its path. */
static cell_t node_cell(const qk_tree_t *t, uint32_t v) {
  cell_t c = {0, 0, 0, 0};
  for (uint32_t a = v; a != 0; a = qk__parent(t, a), c.d++) {
    unsigned q = qk__quadrant(a);
    c.x |= (uint64_t)qk__q_east(q) << c.d;
    c.y |= (uint64_t)qk__q_north(q) << c.d;
  }
  return c;
}

/* Step 1: the pass over the internal nodes. For every node p other than the root whose
 * neighbour on side `dir` is a leaf while a child of p on that side is internal, the cell
 * beside p there is made internal (or, check_only, the pass stops). */
static qk_status_t check_pass(work_t *w) {
  const qk_tree_t *t = w->t;
  typedef struct item {
    uint32_t v;
    uint32_t nb[4];
  } item_t;
  item_t stack[3 * (QK_MAX_DEPTH_LIMIT + 2) + 4];
  int sp = 0;
  if (qk__is_leaf(&t->nodes[0])) return QK_OK;
  stack[sp++] = (item_t){0, {QK_NONE, QK_NONE, QK_NONE, QK_NONE}};
  while (sp > 0) {
    item_t it = stack[--sp];
    uint32_t b = t->nodes[it.v].child;
    bool inner[4];
    for (unsigned q = 0; q < 4; q++) inner[q] = !qk__is_leaf(&t->nodes[b + q]);
    /* The neighbours' first children (QK_NONE for a leaf or for none). */
    uint32_t nbc[4];
    for (unsigned d = 0; d < 4; d++) {
      uint32_t u = it.nb[d];
      nbc[d] = u == QK_NONE ? QK_NONE : t->nodes[u].child;
      if (u != QK_NONE && nbc[d] == QK_NONE) {
        /* A leaf beside p on side d: the rule fails when a child of p there is internal. */
        unsigned f[2];
        qk__facing_children((qk_dir_t)((d + 2) & 3u), f); /* p's children facing side d */
        if (inner[f[0]] || inner[f[1]]) {
          if (w->check_only) {
            w->failed = true;
            return QK_OK;
          }
          cell_t c = node_cell(t, it.v);
          uint64_t lim = (uint64_t)1 << c.d;
          uint64_t nx = c.x + (d == QK_EAST) - (d == QK_WEST);
          uint64_t ny = c.y + (d == QK_NORTH) - (d == QK_SOUTH);
          if (nx < lim && ny < lim) {
            qk_status_t st = make_internal(w, nx, ny, c.d);
            if (st) return st;
          }
        }
      }
    }
    for (int q = 3; q >= 0; q--) {
      if (!inner[q]) continue;
      /* A node whose children are all leaves never fails the rule and has no internal
       * child to pass on: it is not visited. */
      const qk__node_t *gc = &t->nodes[t->nodes[b + (uint32_t)q].child];
      if ((gc[0].child & gc[1].child & gc[2].child & gc[3].child) == QK_NONE) continue;
      item_t ch = {b + (uint32_t)q, {0, 0, 0, 0}};
      for (unsigned d = 0; d < 4; d++) {
        unsigned m = qk__mirror((unsigned)q, d);
        if (!qk__on_side((unsigned)q, d))
          ch.nb[d] = b + m; /* the sibling across */
        else
          ch.nb[d] = nbc[d] == QK_NONE ? it.nb[d] : nbc[d] + m;
      }
      stack[sp++] = ch;
    }
  }
  return QK_OK;
}

/* Step 3: split the new cells, each after its parent. Nodes are reserved. */
static void split_cells(work_t *w) {
  qk_tree_t *t = w->t;
  /* Each descent starts where it leaves the last one's path, as in make_internal (a split
   * only turns a leaf internal, and the nodes were reserved: the path stays valid). */
  w->plen = w->pe = 0;
  w->px = w->py = 0;
  for (size_t i = 0; i < w->n; i++) {
    const cell_t c = w->list[i];
    uint32_t m = c.d < w->pe ? c.d : w->pe;
    uint64_t diff =
        (c.x >> (c.d - m) ^ w->px >> (w->pe - m)) | (c.y >> (c.d - m) ^ w->py >> (w->pe - m));
    while (diff) {
      diff >>= 1;
      m--;
    }
    uint32_t v = w->pv[m];
    qk__geom_t g = w->pg[m];
    while (g.depth < c.d) {
      unsigned sh = c.d - g.depth - 1;
      unsigned q = quadrant_of_bits((unsigned)(c.x >> sh) & 1u, (unsigned)(c.y >> sh) & 1u);
      v = t->nodes[v].child + q;
      g = qk__child_geom(t, g, q);
      w->pv[g.depth] = v;
      w->pg[g.depth] = g;
    }
    qk__split(t, v, g);
    w->pe = c.d;
    w->px = c.x;
    w->py = c.y;
  }
}

qk_status_t qk_tree_balance(qk_tree_t *t) {
  if (!t) return QK_ERR_INVALID;
  work_t w;
  memset(&w, 0, sizeof w);
  w.t = t;
  w.pg[0] = (qk__geom_t){t->root_x, t->root_y, 0}; /* the path: the root, cell (0, 0, 0) */
  qk_status_t st = check_pass(&w);
  /* Step 2: every new cell applies the rule in turn; the list grows as it goes. */
  for (size_t i = 0; i < w.n && st == QK_OK; i++)
    if (w.list[i].d >= 2) st = apply_rule(&w, w.list[i].x, w.list[i].y, w.list[i].d);
  if (st == QK_OK && w.n) {
    if (w.n > UINT32_MAX / 4)
      st = QK_ERR_LIMIT;
    else if ((st = qk__reserve_nodes(t, (uint32_t)(4 * w.n))) == QK_OK)
      split_cells(&w);
  }
  if (st == QK_OK) t->refined = true;
  work_free(&w);
  return st;
}

int qk_tree_is_balanced(const qk_tree_t *t) {
  if (!t) return 0;
  work_t w;
  memset(&w, 0, sizeof w);
  w.t = (qk_tree_t *)t; /* read only: check_only never makes a cell */
  w.check_only = true;
  (void)check_pass(&w);
  return !w.failed;
}
