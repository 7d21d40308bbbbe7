/*
 * Step 3 of the book's mesh generation: triangulate every leaf of the balanced
 * subdivision, then label every triangle with the innermost component containing it.
 * Coordinates here are doubled, so Steiner points at unit-square centres are integers.
 */
#include "mesh/mesh_internal.h"
#include "index/inline.h"

#include <assert.h>
#include <math.h>
#include <stdlib.h>
#include <string.h>

static size_t hslot(uint64_t key, size_t cap) { return qk__hmap_slot(key, cap); }

static void hmap_free(const qk_allocator_t *a, qk__hmap_t *h) {
  qk__free(a, h->k, h->cap * sizeof *h->k);
  qk__free(a, h->v, h->cap * sizeof *h->v);
  h->k = NULL, h->v = NULL, h->cap = h->n = 0;
}

/* The map holds at most 3/4 of its slots (hmap_room): with linear probing and the
 * Fibonacci hash a probe still takes under two slots on average, and the slots cleared
 * at start (a mesh's corner map: 8 bytes a slot) are half those of a half-full bound. */
static inline int hmap_room(const qk__hmap_t *h) { return 4 * (h->n + 1) <= 3 * h->cap; }

static qk_status_t hmap_init(const qk_allocator_t *a, qk__hmap_t *h, size_t expect) {
  size_t cap = 64;
  while (3 * cap < 4 * expect) cap *= 2;
  h->k = qk__realloc(a, NULL, 0, cap * sizeof *h->k);
  h->v = qk__realloc(a, NULL, 0, cap * sizeof *h->v);
  h->cap = cap, h->n = 0;
  if (!h->k || !h->v) {
    hmap_free(a, h);
    return QK_ERR_NOMEM;
  }
  memset(h->k, 0xff, cap * sizeof *h->k);
  return QK_OK;
}

/* The value of key into *v: 1 when present, 0 when not. */
static int hmap_get(const qk__hmap_t *h, uint64_t key, uint32_t *v) {
  uint32_t r = qk__hmap_find(h, key);
  if (r == QK__MESH_UNSET) return 0;
  *v = r;
  return 1;
}

/* Find key; if absent insert it with value *v. Returns 1 when found (*v set), 0 when
 * inserted, -1 out of memory. */
static int hmap_get_or_put(const qk_allocator_t *a, qk__hmap_t *h, uint64_t key, uint32_t *v) {
  if (!hmap_room(h)) {
    qk__hmap_t nh;
    if (hmap_init(a, &nh, h->cap)) return -1;
    for (size_t i = 0; i < h->cap; i++)
      if (h->k[i] != UINT64_MAX) {
        size_t j = hslot(h->k[i], nh.cap);
        while (nh.k[j] != UINT64_MAX) j = (j + 1) & (nh.cap - 1);
        nh.k[j] = h->k[i], nh.v[j] = h->v[i];
      }
    nh.n = h->n;
    hmap_free(a, h);
    *h = nh;
  }
  size_t j = hslot(key, h->cap);
  while (h->k[j] != UINT64_MAX) {
    if (h->k[j] == key) {
      *v = h->v[j];
      return 1;
    }
    j = (j + 1) & (h->cap - 1);
  }
  h->k[j] = key, h->v[j] = *v, h->n++;
  return 0;
}

/* new_vertex when an array must grow (kept out of line: the arrays are sized for the
 * usual counts before the leaves are triangulated, so this is seldom called). */
static qk_status_t new_vertex_grow(qk__tri_state_t *T, int64_t x, int64_t y, int steiner,
                                   uint32_t *id) {
  void *p1 = T->vx, *p2 = T->vy, *p3 = T->steiner;
  if (qk__grow(T->a, &p1, &T->vcap, T->nv + 1, sizeof *T->vx)) return QK_ERR_NOMEM;
  T->vx = p1;
  if (qk__grow(T->a, &p2, &T->vycap, T->nv + 1, sizeof *T->vy)) return QK_ERR_NOMEM;
  T->vy = p2;
  if (qk__grow(T->a, &p3, &T->scap, T->nv + 1, 1)) return QK_ERR_NOMEM;
  T->steiner = p3;
  T->vx[T->nv] = x, T->vy[T->nv] = y, T->steiner[T->nv] = (uint8_t)steiner;
  *id = (uint32_t)T->nv++;
  return QK_OK;
}

static inline qk_status_t new_vertex(qk__tri_state_t *T, int64_t x, int64_t y, int steiner,
                                     uint32_t *id) {
  if (T->nv < T->vcap && T->nv < T->vycap && T->nv < T->scap) { /* room: no calls */
    T->vx[T->nv] = x, T->vy[T->nv] = y, T->steiner[T->nv] = (uint8_t)steiner;
    *id = (uint32_t)T->nv++;
    return QK_OK;
  }
  return new_vertex_grow(T, x, y, steiner, id);
}

/* The vertex at a lattice point, created on first use (corners are shared by leaves).
 * Four calls a leaf: the probe is inlined, and a new key is stored in the slot the probe
 * ended at while the map has room (hmap_get_or_put, which grows it, otherwise). */
/* (Always inlined: GCC leaves it out of line where it is called nine times in a row.) */
static QK__ALWAYS_INLINE qk_status_t corner_vertex(qk__tri_state_t *T, int64_t x, int64_t y,
                                                   uint32_t *id) {
  uint64_t key = ((uint64_t)x << 32) | (uint64_t)y;
  qk__hmap_t *h = &T->vmap;
  size_t mask = h->cap - 1, j = hslot(key, h->cap);
  for (uint64_t k; (k = h->k[j]) != UINT64_MAX; j = (j + 1) & mask)
    if (k == key) {
      *id = h->v[j];
      return QK_OK;
    }
  uint32_t v = (uint32_t)T->nv;
  if (hmap_room(h))
    h->k[j] = key, h->v[j] = v, h->n++;
  else if (hmap_get_or_put(T->a, h, key, &v) < 0)
    return QK_ERR_NOMEM;
  return new_vertex(T, x, y, 0, id);
}

/* add_tri when the arrays must grow (seldom: they are sized for the usual counts). */
static qk_status_t add_tri_grow(qk__tri_state_t *T, uint32_t a, uint32_t b, uint32_t c,
                                uint32_t cell) {
  void *p1 = T->tri, *p2 = T->label;
  if (qk__grow(T->a, &p1, &T->tcap, T->nt + 1, 3 * sizeof *T->tri)) return QK_ERR_NOMEM;
  T->tri = p1;
  if (qk__grow(T->a, &p2, &T->lcap, T->nt + 1, sizeof *T->label)) return QK_ERR_NOMEM;
  T->label = p2;
  uint32_t *t = &T->tri[3 * T->nt];
  t[0] = a, t[1] = b, t[2] = c;
  T->label[T->nt] = cell;
  T->nt++;
  return QK_OK;
}

static inline qk_status_t add_tri(qk__tri_state_t *T, uint32_t a, uint32_t b, uint32_t c,
                                  uint32_t cell) {
  if (T->nt >= T->tcap || T->nt >= T->lcap) return add_tri_grow(T, a, b, c, cell);
  uint32_t *t = &T->tri[3 * T->nt];
  t[0] = a, t[1] = b, t[2] = c;
  T->label[T->nt] = cell;
  T->nt++;
  return QK_OK;
}

/*
 * A triangle edge lying on a component piece seeds the label of the triangle's cell when
 * the triangle is on the piece's left as the component runs, i.e. inside that component:
 * `dir` is +1 when the triangle traverses the piece in its positive direction.
 */
static void seed(uint32_t *label, int32_t piece, int dir) {
  if (piece != 0 && (piece > 0) == (dir > 0)) *label = (uint32_t)(piece > 0 ? piece : -piece);
}

/*
 * Step 3 for one unit leaf holding component pieces: a component diagonal splits it
 * along that diagonal; otherwise the SW-NE diagonal does (its vertices are only its
 * corners, since no leaf is smaller than unit size). Seeds the labels of its cells.
 */
static qk_status_t tri_unit(qk__tri_state_t *T, const qk__unit_rec_t *r, const uint32_t *c,
                            uint32_t cell0, uint32_t *cell_label) {
  /* c: SW, SE, NE, NW. */
  const int32_t *p = r->piece;
  if (p[QK__P_D1]) {
    /* Along SE-NW: (SW, SE, NW) and (SE, NE, NW). */
    seed(&cell_label[cell0], p[QK__P_S], +1);
    seed(&cell_label[cell0], p[QK__P_D1], +1); /* SE -> NW is the positive direction of D1 */
    seed(&cell_label[cell0], p[QK__P_W], -1);  /* NW -> SW runs southwards */
    seed(&cell_label[cell0 + 1], p[QK__P_E], +1);
    seed(&cell_label[cell0 + 1], p[QK__P_N], -1);
    seed(&cell_label[cell0 + 1], p[QK__P_D1], -1);
    qk_status_t st = add_tri(T, c[0], c[1], c[3], cell0);
    if (st) return st;
    return add_tri(T, c[1], c[2], c[3], cell0 + 1);
  }
  /* Along SW-NE: (SW, SE, NE) and (SW, NE, NW); one cell unless SW-NE is a component
   * edge. */
  uint32_t cell1 = p[QK__P_D0] ? cell0 + 1 : cell0;
  seed(&cell_label[cell0], p[QK__P_S], +1);
  seed(&cell_label[cell0], p[QK__P_E], +1);
  seed(&cell_label[cell0], p[QK__P_D0], -1); /* NE -> SW */
  seed(&cell_label[cell1], p[QK__P_D0], +1);
  seed(&cell_label[cell1], p[QK__P_N], -1);
  seed(&cell_label[cell1], p[QK__P_W], -1);
  qk_status_t st = add_tri(T, c[0], c[1], c[2], cell0);
  if (st) return st;
  return add_tri(T, c[0], c[2], c[3], cell1);
}

/*
 * Regions and components. Regions are the connected parts of the domain minus the
 * component boundaries: flood the cells across leaf sides that are not component edges
 * (the neighbours across a side come from the tree's neighbour finding). A cell beside a
 * component edge, on its inner (left) side, lies in that component's face and was seeded
 * with its id, which becomes its region's label; a region holding no seed lies outside
 * every component, label 0. (A face of a component is one region; the outside may be
 * several when components touching the domain's edge cut it apart.)
 */
/*
 * The leaves by their corners: by[k][c] is the leaf (index in the leaf list) whose corner
 * k (SW, SE, NE, NW) is corner vertex c, or QK__MESH_UNSET. Leaves do not overlap, so a
 * vertex is corner k of at most one leaf. Every neighbour across a side of a leaf in a
 * balanced tree has a corner at one of that side's ends, so the neighbours come from two
 * array reads with the leaf's own corner vertices, no coordinates and no hashing.
 */
/* A leaf's square on the lattice: corner (x, y), side s (the tree's root is (0, 0, U) with
 * U a power of two at most 2^30, so its squares are these integers exactly). */
typedef struct lat_sq {
  uint32_t x, y, s;
} lat_sq_t;

/* Whether the four squares from q are a node's four children in the leaf list's order
 * (NE, NW, SW, SE: quadrants 0-3): four leaves of one parent, side by side. Most leaves
 * come so (92% at the bench's octagons). */
static inline int sibling_leaves(const lat_sq_t *q) {
  uint32_t h = q[0].s;
  return q[1].s == h && q[2].s == h && q[3].s == h && q[1].x + h == q[0].x && q[1].y == q[0].y &&
         q[2].x == q[1].x && q[2].y + h == q[0].y && q[3].x == q[0].x && q[3].y == q[2].y;
}

/* corner_vertex for corner_vertices4 when the map and the arrays have room for nine more:
 * the same slot (qk__hmap_slot by a shift computed once) and the same vertex made. */
typedef struct grid_probe {
  uint64_t *k;
  uint32_t *v;
  size_t mask;
  unsigned shift;
  int64_t *vx, *vy;
  uint8_t *steiner;
  size_t nv;
} grid_probe_t;

static QK__ALWAYS_INLINE void grid_point(grid_probe_t *G, int64_t x, int64_t y, uint32_t *id) {
  const uint64_t key = ((uint64_t)x << 32) | (uint64_t)y;
  size_t j = (size_t)((key * 0x9e3779b97f4a7c15ull) >> G->shift);
  for (uint64_t k; (k = G->k[j]) != UINT64_MAX; j = (j + 1) & G->mask)
    if (k == key) {
      *id = G->v[j];
      return;
    }
  G->k[j] = key, G->v[j] = (uint32_t)G->nv;
  G->vx[G->nv] = x, G->vy[G->nv] = y, G->steiner[G->nv] = 0;
  *id = (uint32_t)G->nv++;
}

/* The corner vertices (into c, 4 a leaf: SW, SE, NE, NW) of four sibling leaves at q
 * (sibling_leaves): the nine lattice points of their 3 x 3 grid are looked up once each,
 * in the order the leaves' own corner_vertex calls would first meet them (NE's corners,
 * then NW's, SW's and SE's new ones), so that the vertices are made in the same order;
 * the sixteen look-ups leaf by leaf would find seven of them a second time. Out of line
 * (called once a group): inlined, it changes what GCC inlines into the leaf loop. */
__attribute__((noinline)) static qk_status_t corner_vertices4(qk__tri_state_t *T, const lat_sq_t *q,
                                                              uint32_t *c) {
  const int64_t S = 2 * (int64_t)q[0].s, X = 2 * (int64_t)q[2].x, Y = 2 * (int64_t)q[2].y;
  uint32_t p00, p01, p02, p10, p11, p12, p20, p21, p22; /* pji: the point (X + i S, Y + j S) */
  qk__hmap_t *h = &T->vmap;
  if (T->nv + 9 <= T->vcap && T->nv + 9 <= T->vycap && T->nv + 9 <= T->scap &&
      4 * (h->n + 9) <= 3 * h->cap) {
    /* Room for nine new vertices in the arrays and the map: no checks a point, and the
     * map's fields in registers. */
    grid_probe_t G = {h->k,  h->v,  h->cap - 1, 64u - (unsigned)__builtin_ctzll((uint64_t)h->cap),
                      T->vx, T->vy, T->steiner, T->nv};
    grid_point(&G, X + S, Y + S, &p11), grid_point(&G, X + 2 * S, Y + S, &p12);
    grid_point(&G, X + 2 * S, Y + 2 * S, &p22), grid_point(&G, X + S, Y + 2 * S, &p21);
    grid_point(&G, X, Y + S, &p10), grid_point(&G, X, Y + 2 * S, &p20);
    grid_point(&G, X, Y, &p00), grid_point(&G, X + S, Y, &p01);
    grid_point(&G, X + 2 * S, Y, &p02);
    h->n += G.nv - T->nv, T->nv = G.nv;
  } else {
    qk_status_t st;
    if ((st = corner_vertex(T, X + S, Y + S, &p11)) ||
        (st = corner_vertex(T, X + 2 * S, Y + S, &p12)) ||
        (st = corner_vertex(T, X + 2 * S, Y + 2 * S, &p22)) ||
        (st = corner_vertex(T, X + S, Y + 2 * S, &p21)) ||
        (st = corner_vertex(T, X, Y + S, &p10)) || (st = corner_vertex(T, X, Y + 2 * S, &p20)) ||
        (st = corner_vertex(T, X, Y, &p00)) || (st = corner_vertex(T, X + S, Y, &p01)) ||
        (st = corner_vertex(T, X + 2 * S, Y, &p02)))
      return st;
  }
  c[0] = p11, c[1] = p12, c[2] = p22, c[3] = p21;     /* NE */
  c[4] = p10, c[5] = p11, c[6] = p21, c[7] = p20;     /* NW */
  c[8] = p00, c[9] = p01, c[10] = p11, c[11] = p10;   /* SW */
  c[12] = p01, c[13] = p02, c[14] = p12, c[15] = p11; /* SE */
  return QK_OK;
}

typedef struct leaf_map {
  uint32_t *by[4];        /* by corner kind, indexed by corner vertex id */
  const uint32_t *corner; /* 4 per leaf: SW, SE, NE, NW vertex ids */
  const qk_node_t *leaves;
  const uint32_t *leaf_of; /* by node id */
  const uint32_t *side;    /* by leaf index: the leaf's side */
  const lat_sq_t *sq;      /* by leaf index: the leaf's square */
  uint32_t U;              /* the root square's side */
  const uint8_t *sib;      /* by leaf index: its sides facing a sibling leaf (sib_mask) */
} leaf_map_t;

/* The sides (bits south, east, north, west) of a parent's four leaf children (quadrants
 * NE, NW, SW, SE, as corner_vertices4 finds them) that face one of the others, of the
 * same size, and, per such side, the step from its leaf index to that sibling's. Other
 * leaves have none (0). */
static const uint8_t sib_mask[4] = {0x9, 0x3, 0x6, 0xc};
static const signed char sib_step[16][4] = {
    [0x9] = {3, 0, 0, 1}, [0x3] = {1, -1, 0, 0}, [0x6] = {0, 1, -1, 0}, [0xc] = {0, 0, -3, -1}};

/*
 * The leaves across side sd (south, east, north, west) of leaf li, as
 * qk_tree_adjacent_leaves gives them, same order, into nb (room for 8) as leaf indices,
 * for a side that is not on the root square's boundary: in a balanced tree one leaf of
 * the same size, two of half the size (the one lower along the side first, as the tree
 * lists them), or one of twice the size; the tree's own search otherwise (never, for a
 * balanced tree, but it costs nothing to be sure). Side sd runs from corner vertex p to
 * q; the same-size neighbour, the first half-size one and the double-size one when
 * aligned with p have their corner kp at p, the second half-size one and the double-size
 * one otherwise their corner kq at q. The same-size neighbour is the one leaf with both
 * (a == b); a double-size one leaves the other end without such a corner (it is the
 * middle of the large leaf's side).
 */
static const unsigned char pk[4][4] = {/* p's corner index, kp, q's index, kq */
                                       {0, 3, 1, 2},
                                       {1, 0, 2, 3},
                                       {3, 0, 2, 1},
                                       {0, 1, 3, 2}};

static size_t side_leaves(const qk_tree_t *t, const leaf_map_t *L, uint32_t li, int sd,
                          uint32_t *nb) {
  if ((L->sib[li] >> sd) & 1) { /* a sibling leaf of the same size */
    nb[0] = (uint32_t)((int64_t)li + sib_step[L->sib[li]][sd]);
    return 1;
  }
  const uint32_t *c = &L->corner[4 * li];
  const unsigned char *e = pk[sd];
  uint32_t a = L->by[e[1]][c[e[0]]], b = L->by[e[3]][c[e[2]]];
  if (a == b) {
    if (a != QK__MESH_UNSET) {
      nb[0] = a;
      return 1;
    }
  } else {
    uint64_t S = L->side[li];
    uint64_t sa = a != QK__MESH_UNSET ? L->side[a] : 0, sb = b != QK__MESH_UNSET ? L->side[b] : 0;
    if (sa == 2 * S && !sb) {
      nb[0] = a;
      return 1;
    }
    if (sb == 2 * S && !sa) {
      nb[0] = b;
      return 1;
    }
    if (sa && 2 * sa == S && 2 * sb == S) {
      nb[0] = a, nb[1] = b;
      return 2;
    }
  }
  if (a == QK__MESH_UNSET && b == QK__MESH_UNSET) {
    /* No leaf has a corner at either end across the side: the root square's boundary
     * (nothing across) in a balanced tree. */
    const lat_sq_t *q = &L->sq[li];
    if (sd == 0   ? q->y == 0
        : sd == 1 ? q->x + q->s == L->U
        : sd == 2 ? q->y + q->s == L->U
                  : q->x == 0)
      return 0;
  }
  static const qk_dir_t side_dir[4] = {QK_SOUTH, QK_EAST, QK_NORTH, QK_WEST};
  qk_node_t nn[8];
  size_t n = 0;
  if (qk_tree_adjacent_leaves(t, L->leaves[li], side_dir[sd], nn, 8, &n) != QK_OK)
    return 0; /* (cannot fail: a leaf of t, a direction, room) */
  if (n > 8) n = 8;
  for (size_t i = 0; i < n; i++) nb[i] = L->leaf_of[nn[i]];
  return n;
}

/* What the flood of one region works with. */
typedef struct flood {
  const qk_tree_t *t;
  const leaf_map_t *L;
  const uint8_t *kind; /* per leaf: diagonal kind (bits 0-1), component sides (bits 2-5) */
  uint32_t *region, *queue;
  uint8_t *back;
  uint32_t rid;
} flood_t;

/* The flood from leaf li's cell touching side sd across it: the cells facing it that no
 * region holds yet join region f->rid and the queue (from qt); returns the queue's length.
 * A neighbour no larger than li has only li's cell across its side opposite sd, so that
 * side is not looked up from it (f->back). */
static inline size_t flood_side(const flood_t *f, uint32_t li, int sd, size_t qt) {
  /* other[diag]: the sides of a leaf with diagonal kind diag that its cell 1 touches. */
  static const unsigned char other[4] = {0x0, 0xc, 0x6, 0x0};
  uint32_t nb[8];
  size_t n = side_leaves(f->t, f->L, li, sd, nb);
  const unsigned opp = (unsigned)(sd + 2) & 3;
  const uint32_t sl = f->L->side[li];
  for (size_t i = 0; i < n; i++) {
    uint32_t lw = nb[i];
    uint32_t cw = 2 * lw, d = f->kind[lw] & 3u;
    if (d) cw += (other[d] >> opp) & 1; /* a diagonal: which half faces this side */
    if (f->region[cw] != QK__MESH_UNSET) continue;
    f->region[cw] = f->rid, f->queue[qt++] = cw;
    f->back[cw] = f->L->side[lw] <= sl ? (uint8_t)(1u << opp) : 0;
  }
  return qt;
}

/* Per leaf, what the flood asks of it, in one byte: its diagonal kind (bits 0-1: 0 none,
 * 1 SW-NE, 2 SE-NW) and which sides are component edges, which the flood does not cross
 * (bit 2 + side, sides south, east, north, west), from the node's unit record r (a leaf
 * without one has 0). (Across the root square's boundary side_leaves finds nothing.) */
static inline uint8_t flood_kind(const qk__unit_rec_t *r) {
  static const int piece_of_side[4] = {QK__P_S, QK__P_E, QK__P_N, QK__P_W};
  uint8_t f = r->piece[QK__P_D0] ? 1 : r->piece[QK__P_D1] ? 2 : 0;
  for (int sd = 0; sd < 4; sd++)
    if (r->piece[piece_of_side[sd]]) f |= (uint8_t)(4 << sd);
  return f;
}

/* The regions and labels from the leaves' flood_kind bytes (made as the leaves are
 * triangulated) and the seeded cell labels. */
static qk_status_t label_cells(qk__gen_t *g, qk__tri_state_t *T, size_t nleaves,
                               const uint8_t *kind, const uint32_t *cell_label,
                               const leaf_map_t *L) {
  const qk_tree_t *t = g->tree;
  size_t ncell = 2 * nleaves;
  uint32_t *queue = qk__realloc(g->a, NULL, 0, (ncell + 1) * sizeof *queue);
  uint32_t *region = qk__realloc(g->a, NULL, 0, (ncell + 1) * sizeof *region);
  uint32_t *rlabel = qk__realloc(g->a, NULL, 0, (ncell + 1) * sizeof *rlabel);
  /* Per cell, the side it was reached across when that side holds nothing else new. */
  uint8_t *back = qk__realloc(g->a, NULL, 0, ncell + 1);
  qk_status_t st = QK_OK;
  /* The triangles' regions (T->region) are read only to find the regions of hole points
   * (g->poly's) and of regional attribute points (g->src's); without any, they are not
   * kept. */
  const int keep_regions = g->poly->nh || g->src->nr;
  void *rp = T->region;
  if (!queue || !region || !rlabel || !back ||
      (keep_regions && qk__grow(T->a, &rp, &T->rcap, T->nt + 1, sizeof *T->region))) {
    st = QK_ERR_NOMEM;
    goto out;
  }
  T->region = rp;
  memset(region, 0xff, (ncell + 1) * sizeof *region);
  /* Labelling works on cells: the parts of a leaf that no component edge separates. A
   * leaf is one cell, except a unit leaf cut by a component diagonal, which is two.
   * touch[diag][k] is the set of sides (south, east, north, west) that cell k of a leaf
   * with diagonal kind diag touches (flood_side tells which cell faces a side). */
  static const unsigned char touch[4][2] = {{0xf, 0x0}, {0x3, 0xc}, {0x9, 0x6}, {0, 0}};
  uint32_t nreg = 0;
  /* Start a flood from every cell not reached yet that holds triangles, in the order of
   * the triangles (leaf by leaf, cell 0 first): the region ids are as a flood started at
   * every triangle in turn would number them. */
  for (size_t c0 = 0; c0 < ncell; c0++) {
    if (region[c0] != QK__MESH_UNSET || ((c0 & 1) && !(kind[c0 / 2] & 3))) continue;
    uint32_t rid = nreg++;
    rlabel[rid] = 0;
    size_t qh = 0, qt = 0;
    region[c0] = rid, queue[qt++] = (uint32_t)c0, back[c0] = 0;
    while (qh < qt) {
      uint32_t c = queue[qh++], li = c / 2, k = c % 2;
      if (cell_label[c] != QK__MESH_UNSET) rlabel[rid] = cell_label[c];
      unsigned kl = kind[li];
      unsigned sides = touch[kl & 3][k] & ~(kl >> 2) & ~(unsigned)back[c] & 0xf;
      /* Side by side written out, so that each look-up's table entries fold. */
      flood_t f = {t, L, kind, region, queue, back, rid};
      if (sides & 1) qt = flood_side(&f, li, 0, qt);
      if (sides & 2) qt = flood_side(&f, li, 1, qt);
      if (sides & 4) qt = flood_side(&f, li, 2, qt);
      if (sides & 8) qt = flood_side(&f, li, 3, qt);
    }
  }
  if (keep_regions) {
    for (size_t tr = 0; tr < T->nt; tr++) {
      uint32_t rid = region[T->label[tr]];
      T->region[tr] = rid;
      T->label[tr] = rlabel[rid];
    }
  } else {
    for (size_t tr = 0; tr < T->nt; tr++) T->label[tr] = rlabel[region[T->label[tr]]];
  }
  T->nregion = nreg;
out:
  qk__free(g->a, queue, (ncell + 1) * sizeof *queue);
  qk__free(g->a, region, (ncell + 1) * sizeof *region);
  qk__free(g->a, rlabel, (ncell + 1) * sizeof *rlabel);
  qk__free(g->a, back, ncell + 1);
  return st;
}

/* Side s (south, east, north, west) of a leaf of doubled square (X, Y, S), S > 2, with
 * corner vertices c, onto its ring from ring[nr]: corner s, then the side's midpoint when
 * a vertex lies there (bit s of *mids); returns the new length. A side holds a midpoint
 * exactly when the neighbour across it (of at most this depth) is internal: then, the tree
 * being balanced, two leaves of half the size meet this side, and share a corner at its
 * midpoint. Otherwise no leaf has a corner there (a leaf across the side is as large as
 * this one or larger, with corners on a coarser grid). The leaf across the side with its
 * corner kp at the side's start p (side_leaves) is then of half the size, and the midpoint
 * is its corner kq. */
static inline size_t ring_side(const qk__tri_state_t *T, const leaf_map_t *L, const uint32_t *c,
                               unsigned sib, int s, int64_t X, int64_t Y, int64_t S, uint32_t *ring,
                               size_t nr, unsigned *mids) {
  ring[nr++] = c[s];
  if ((sib >> s) & 1) return nr; /* a sibling leaf of the same size across: no midpoint */
  uint32_t a = L->by[pk[s][1]][c[pk[s][0]]];
  if (a == QK__MESH_UNSET || 4 * (int64_t)L->side[a] > S) return nr;
  if (4 * (int64_t)L->side[a] == S) {
    ring[nr++] = L->corner[4 * a + pk[s][3]], *mids |= 1u << s;
    return nr;
  }
  /* A smaller neighbour: never in a balanced tree; the vertex map answers. */
  int64_t mx[4] = {X + S / 2, X + S, X + S / 2, X}, my[4] = {Y, Y + S / 2, Y + S, Y + S / 2};
  if (hmap_get(&T->vmap, ((uint64_t)mx[s] << 32) | (uint64_t)my[s], &ring[nr]))
    nr++, *mids |= 1u << s;
  return nr;
}

/* The leaves into `leaves` (room for the tree's node bound) in qk_tree_leaves' order,
 * pre-order with the children first to last, with their squares by leaf index into
 * `leaf_sq` (same room); returns their number. The squares are computed top-down, each
 * node's from its parent's as the walk goes (qk__node_square recomputes a node's whole
 * path at each call); in integers on the lattice, from the root (0, 0, U), the tree's own
 * squares (dyadic, halving exact). One walk instead of a count, a list and the squares. */
static size_t node_squares(const qk_tree_t *t, uint32_t U, qk_node_t *leaves, lat_sq_t *leaf_sq) {
  struct {
    qk_node_t v;
    lat_sq_t sq;
  } stack[3 * (QK_MAX_DEPTH_LIMIT + 2) + 4]; /* 3 siblings a level wait */
  size_t n = 0, nl = 0;
  stack[n].v = qk_tree_root(t), stack[n++].sq = (lat_sq_t){0, 0, U};
  while (n) {
    qk_node_t v = stack[--n].v;
    lat_sq_t sq = stack[n].sq;
    uint32_t c = qk__node_child(t, v);
    if (c == QK_NONE) {
      leaf_sq[nl] = sq;
      leaves[nl++] = v;
      continue;
    }
    uint32_t h = sq.s / 2;
    for (unsigned q = 4; q-- > 0;)
      stack[n].v = c + q, stack[n++].sq = (lat_sq_t){sq.x + (qk__q_east(q) ? h : 0),
                                                     sq.y + (qk__q_north(q) ? h : 0), h};
  }
  return nl;
}

/* T->segv: the vertex at every lattice point of every segment, in order. */
static qk_status_t segment_vertices(const qk__gen_t *g, qk__tri_state_t *T) {
  const qk_poly_t *P = g->poly;
  size_t total = 0;
  for (size_t s = 0; s < P->ns; s++) {
    uint32_t u = P->seg[2 * s], w = P->seg[2 * s + 1];
    int64_t dx = llabs((int64_t)P->vx[w] - (int64_t)P->vx[u]);
    int64_t dy = llabs((int64_t)P->vy[w] - (int64_t)P->vy[u]);
    total += (size_t)(dx > dy ? dx : dy) + 1;
  }
  T->segv = qk__realloc(T->a, NULL, 0, (total + 1) * sizeof *T->segv);
  if (!T->segv) return QK_ERR_NOMEM;
  T->nsegv = total;
  size_t j = 0;
  for (size_t s = 0; s < P->ns; s++) {
    uint32_t u = P->seg[2 * s], w = P->seg[2 * s + 1];
    int64_t ax = (int64_t)P->vx[u], ay = (int64_t)P->vy[u];
    int64_t dx = (int64_t)P->vx[w] - ax, dy = (int64_t)P->vy[w] - ay;
    int64_t n = llabs(dx) > llabs(dy) ? llabs(dx) : llabs(dy);
    int64_t sx = n ? dx / n : 0, sy = n ? dy / n : 0;
    for (int64_t k = 0; k <= n; k++)
      T->segv[j++] = qk__hmap_find(&T->vmap, (uint64_t)(2 * (ax + k * sx)) << 32 |
                                                 (uint64_t)(2 * (ay + k * sy)));
  }
  return QK_OK;
}

/* The shapes (qk__tri_state_t.shapes) of a leaf that is not a unit record, by which
 * sides hold a midpoint: none, the SW-NE split; else per side two fan triangles with a
 * midpoint, one without. */
#define FAN(m, s) (((m) >> (s)) & 1 ? 6u << 3 * (s) : 1u << 3 * (s))
#define FAN4(m) (m ? FAN(m, 0) | FAN(m, 1) | FAN(m, 2) | FAN(m, 3) : 0x3000u)
static const uint16_t fan_shapes[16] = {FAN4(0),  FAN4(1),  FAN4(2),  FAN4(3), FAN4(4),  FAN4(5),
                                        FAN4(6),  FAN4(7),  FAN4(8),  FAN4(9), FAN4(10), FAN4(11),
                                        FAN4(12), FAN4(13), FAN4(14), FAN4(15)};
#undef FAN4
#undef FAN

/* Number vertex u at its first use: the next number, returned advanced, when it has none. */
static inline uint32_t ord_use(uint32_t *ord, uint32_t next, uint32_t u) {
  if (ord[u] != QK__MESH_UNSET) return next;
  ord[u] = next;
  return next + 1;
}

void qk__mesh_shape(int k, int64_t S, int64_t x[3], int64_t y[3]) {
  /* Corners SW, SE, NE, NW (0-3), side midpoints south, east, north, west (4-7), centre. */
  const int64_t h = S / 2;
  const int64_t px[9] = {0, S, S, 0, h, S, h, 0, h}, py[9] = {0, 0, S, S, 0, h, S, h, h};
  static const unsigned char split[4][3] = {{0, 1, 2}, {0, 2, 3}, {0, 1, 3}, {1, 2, 3}};
  int s = k / 3, v[3];
  if (k >= 12) {
    for (int i = 0; i < 3; i++) v[i] = split[k - 12][i];
  } else if (k % 3 == 0) {
    v[0] = s, v[1] = (s + 1) % 4, v[2] = 8;
  } else if (k % 3 == 1) {
    v[0] = s, v[1] = 4 + s, v[2] = 8;
  } else {
    v[0] = 4 + s, v[1] = (s + 1) % 4, v[2] = 8;
  }
  for (int i = 0; i < 3; i++) x[i] = px[v[i]], y[i] = py[v[i]];
}

qk_status_t qk__mesh_triangulate(qk__gen_t *g, qk__tri_state_t *T, qk__leaf_tris_t *lt) {
  const qk_tree_t *t = g->tree;
  qk_status_t st = QK_OK;
  /* Which unit leaves carry component pieces, and each leaf's index, by node id. */
  size_t nn = qk__tree_node_bound(t);
  uint32_t *rec_of = qk__realloc(g->a, NULL, 0, nn * sizeof *rec_of);
  uint32_t *leaf_of = qk__realloc(g->a, NULL, 0, nn * sizeof *leaf_of);
  lt->cap = nn;
  lt->first = qk__realloc(g->a, NULL, 0, lt->cap * sizeof *lt->first);
  /* The leaves and their squares in one walk; a tree has fewer leaves than nodes. */
  size_t nleaves = 0;
  qk_node_t *leaves = qk__realloc(g->a, NULL, 0, (nn + 1) * sizeof *leaves);
  lat_sq_t *lsq = qk__realloc(g->a, NULL, 0, (nn + 1) * sizeof *lsq);
  uint32_t *cell_label = NULL;
  if (leaves && lsq) {
    nleaves = node_squares(t, (uint32_t)g->U, leaves, lsq);
    cell_label = qk__realloc(g->a, NULL, 0, (2 * nleaves + 1) * sizeof *cell_label);
  }
  lt->nleaves = nleaves;
  if (!rec_of || !leaf_of || !lt->first || !leaves || !lsq || !cell_label ||
      hmap_init(g->a, &T->vmap, nleaves + nleaves / 4 + 16) != QK_OK) {
    st = QK_ERR_NOMEM;
    goto out;
  }
  /* The per-node maps are read at leaves only, so only the leaves' entries are set, not
   * the whole node bound's: here rec_of's and leaf_of's, lt->first's as each leaf is
   * triangulated. */
  memset(cell_label, 0xff, (2 * nleaves + 1) * sizeof *cell_label);
  for (size_t li = 0; li < nleaves; li++)
    leaf_of[leaves[li]] = (uint32_t)li, rec_of[leaves[li]] = QK__MESH_UNSET;
  for (size_t i = 0; i < g->nrec; i++) rec_of[g->rec[i].node] = (uint32_t)i;

  /* Room for the usual counts (about 3 triangles and 1.5 vertices a leaf), so that the
   * arrays seldom grow while filled. */
  {
    void *p1 = T->tri, *p2 = T->label, *p3 = T->vx, *p4 = T->vy, *p5 = T->steiner;
    size_t nt = 3 * nleaves + 16, nv = nleaves + nleaves / 2 + 16;
    if (qk__grow(T->a, &p1, &T->tcap, nt, 3 * sizeof *T->tri) ||
        (T->tri = p1, qk__grow(T->a, &p2, &T->lcap, nt, sizeof *T->label)) ||
        (T->label = p2, qk__grow(T->a, &p3, &T->vcap, nv, sizeof *T->vx)) ||
        (T->vx = p3, qk__grow(T->a, &p4, &T->vycap, nv, sizeof *T->vy)) ||
        (T->vy = p4, qk__grow(T->a, &p5, &T->scap, nv, 1))) {
      st = QK_ERR_NOMEM;
      goto out;
    }
    T->steiner = p5;
  }
  /* First every leaf's corners, so that the vertex map holds every lattice point a leaf
   * has as a corner. */
  uint32_t *corner = qk__realloc(g->a, NULL, 0, (4 * nleaves + 4) * sizeof *corner);
  uint32_t *lside = qk__realloc(g->a, NULL, 0, (nleaves + 1) * sizeof *lside);
  uint8_t *sib = qk__realloc(g->a, NULL, 0, nleaves + 1);
  uint8_t *kind = qk__realloc(g->a, NULL, 0, nleaves + 1); /* flood_kind by leaf */
  if (!corner || !lside || !sib || !kind) {
    qk__free(g->a, corner, (4 * nleaves + 4) * sizeof *corner);
    qk__free(g->a, lside, (nleaves + 1) * sizeof *lside);
    qk__free(g->a, sib, nleaves + 1);
    qk__free(g->a, kind, nleaves + 1);
    st = QK_ERR_NOMEM;
    goto out;
  }
  for (size_t li = 0; li < nleaves;) {
    if (li + 3 < nleaves && sibling_leaves(&lsq[li])) {
      if ((st = corner_vertices4(T, &lsq[li], &corner[4 * li]))) break;
      for (int q = 0; q < 4; q++) lside[li + q] = lsq[li].s, sib[li + q] = sib_mask[q];
      li += 4;
      continue;
    }
    lat_sq_t sq = lsq[li];
    int64_t S = 2 * (int64_t)sq.s, X = 2 * (int64_t)sq.x, Y = 2 * (int64_t)sq.y;
    uint32_t *c = &corner[4 * li];
    lside[li] = sq.s, sib[li] = 0;
    /* SW, SE, NE, NW; the probe is inlined at each. */
    if ((st = corner_vertex(T, X, Y, &c[0])) || (st = corner_vertex(T, X + S, Y, &c[1])) ||
        (st = corner_vertex(T, X + S, Y + S, &c[2])) || (st = corner_vertex(T, X, Y + S, &c[3])))
      break;
    li++;
  }
  size_t ncorner = T->nv; /* the corner vertices are the first ids */
  leaf_map_t L = {{NULL, NULL, NULL, NULL}, corner, leaves, leaf_of, lside, lsq,
                  (uint32_t)g->U,           sib};
  for (int k = 0; k < 4 && !st; k++) {
    L.by[k] = qk__realloc(g->a, NULL, 0, (ncorner + 1) * sizeof *L.by[k]);
    if (!L.by[k])
      st = QK_ERR_NOMEM;
    else
      memset(L.by[k], 0xff, (ncorner + 1) * sizeof *L.by[k]);
  }
  for (size_t li = 0; li < nleaves && !st; li++)
    for (int k = 0; k < 4; k++) L.by[k][corner[4 * li + k]] = (uint32_t)li;
  /* The output's numbering (T->ord) as the triangles are made: a leaf's vertices in the
   * order its triangles first use them, each numbered at its first use overall. */
  uint32_t onext = 0;
  if (!st) {
    T->ocap = T->vcap;
    T->ord = qk__realloc(g->a, NULL, 0, T->ocap * sizeof *T->ord);
    if (!T->ord)
      T->ocap = 0, st = QK_ERR_NOMEM;
    else
      memset(T->ord, 0xff, ncorner * sizeof *T->ord);
  }
  uint32_t *ord = T->ord;
  /* With no point to locate, the triangles are written in the output's numbering (each
   * vertex is numbered before its first triangle is written). */
  const int tri_ord = T->tri_ord = !g->poly->nh && !g->src->nr;
  for (size_t li = 0; li < nleaves && !st; li++) {
    uint32_t v = leaves[li], cell = (uint32_t)(2 * li);
    lat_sq_t sq = lsq[li];
    int64_t S = 2 * (int64_t)sq.s, X = 2 * (int64_t)sq.x, Y = 2 * (int64_t)sq.y;
    lt->first[v] = (uint32_t)T->nt;
    const uint32_t *c = &corner[4 * li];
    kind[li] = 0;
    if (rec_of[v] != QK__MESH_UNSET) {
      const qk__unit_rec_t *r = &g->rec[rec_of[v]];
      kind[li] = flood_kind(r);
      T->shapes[1] |= r->piece[QK__P_D1] ? 0xc000 : 0x3000; /* S = 2 */
      /* (SW, SE, NW), (SE, NE, NW) along SE-NW; (SW, SE, NE), (SW, NE, NW) otherwise. */
      onext = ord_use(ord, onext, c[0]);
      onext = ord_use(ord, onext, c[1]);
      int d1 = r->piece[QK__P_D1] != 0;
      onext = ord_use(ord, onext, c[d1 ? 3 : 2]);
      onext = ord_use(ord, onext, c[d1 ? 2 : 3]);
      uint32_t oc[4];
      if (tri_ord) oc[0] = ord[c[0]], oc[1] = ord[c[1]], oc[2] = ord[c[2]], oc[3] = ord[c[3]];
      st = tri_unit(T, r, tri_ord ? oc : c, cell, cell_label);
      continue;
    }
    /* The boundary ring: the corners and the sides' midpoints that are vertices
     * (ring_side), in CCW order, sides south, east, north, west. Unit leaves have no
     * smaller neighbours. */
    uint32_t ring[9];
    size_t nr = 0;
    unsigned mids = 0;
    if (S <= 2) {
      ring[0] = c[0], ring[1] = c[1], ring[2] = c[2], ring[3] = c[3], nr = 4;
    } else { /* each side written out, its table entries folded */
      const unsigned sibm = sib[li];
      nr = ring_side(T, &L, c, sibm, 0, X, Y, S, ring, nr, &mids);
      nr = ring_side(T, &L, c, sibm, 1, X, Y, S, ring, nr, &mids);
      nr = ring_side(T, &L, c, sibm, 2, X, Y, S, ring, nr, &mids);
      nr = ring_side(T, &L, c, sibm, 3, X, Y, S, ring, nr, &mids);
    }
    T->shapes[__builtin_ctzll((uint64_t)S)] |= fan_shapes[mids];
    if (nr == 4) {
      /* Vertices only at its corners: split along a diagonal (angles 45, 45, 90). */
      for (int q = 0; q < 4; q++) onext = ord_use(ord, onext, c[q]);
      uint32_t oc[4];
      const uint32_t *tc = c;
      if (tri_ord)
        oc[0] = ord[c[0]], oc[1] = ord[c[1]], oc[2] = ord[c[2]], oc[3] = ord[c[3]], tc = oc;
      if (!(st = add_tri(T, tc[0], tc[1], tc[2], cell))) st = add_tri(T, tc[0], tc[2], tc[3], cell);
      continue;
    }
    /* A Steiner point at the centre, joined to every boundary vertex: each triangle has
     * a right angle at the centre (corner-corner) or at the midpoint (corner-midpoint). */
    uint32_t ctr;
    if ((st = new_vertex(T, X + S / 2, Y + S / 2, 1, &ctr))) break;
    if (ctr >= T->ocap) {
      void *p = T->ord;
      if ((st = qk__grow(T->a, &p, &T->ocap, (size_t)ctr + 1, sizeof *T->ord))) break;
      T->ord = ord = p;
    }
    /* The fan (ring[i], ring[i + 1], centre) first uses ring[0], ring[1], the centre, then
     * the rest of the ring in turn. */
    onext = ord_use(ord, onext, ring[0]);
    onext = ord_use(ord, onext, ring[1]);
    ord[ctr] = onext++;
    for (size_t i = 2; i < nr; i++) onext = ord_use(ord, onext, ring[i]);
    if (tri_ord) {
      for (size_t i = 0; i < nr; i++) ring[i] = ord[ring[i]];
      ctr = ord[ctr];
    }
    ring[nr] = ring[0];
    if (T->nt + nr > T->tcap || T->nt + nr > T->lcap) {
      for (size_t i = 0; i < nr && !st; i++) st = add_tri(T, ring[i], ring[i + 1], ctr, cell);
      continue;
    }
    /* The usual case: room for the whole fan, written without a check a triangle. */
    uint32_t *tt = &T->tri[3 * T->nt], *tl = &T->label[T->nt];
    for (size_t i = 0; i < nr; i++)
      tt[3 * i] = ring[i], tt[3 * i + 1] = ring[i + 1], tt[3 * i + 2] = ctr, tl[i] = cell;
    T->nt += nr;
  }
  assert(st || onext == T->nv); /* every vertex is a corner or a centre of some leaf */
  /* The boundary markers' vertices: every lattice point of a segment is a corner of its
   * unit leaves, so the vertex map holds it; then the map's memory goes back before
   * labelling. */
  if (!st) st = segment_vertices(g, T);
  hmap_free(T->a, &T->vmap);
  if (!st) st = label_cells(g, T, nleaves, kind, cell_label, &L);
  for (int k = 0; k < 4; k++) qk__free(g->a, L.by[k], (ncorner + 1) * sizeof *L.by[k]);
  qk__free(g->a, corner, (4 * nleaves + 4) * sizeof *corner);
  qk__free(g->a, lside, (nleaves + 1) * sizeof *lside);
  qk__free(g->a, sib, nleaves + 1);
  qk__free(g->a, kind, nleaves + 1);
out:
  qk__free(g->a, lsq, (nn + 1) * sizeof *lsq);
  qk__free(g->a, rec_of, nn * sizeof *rec_of);
  qk__free(g->a, leaf_of, nn * sizeof *leaf_of);
  qk__free(g->a, leaves, (nn + 1) * sizeof *leaves);
  qk__free(g->a, cell_label, (2 * nleaves + 1) * sizeof *cell_label);
  if (st) qk__mesh_fail(g->err, st, 0, "%s while triangulating", qk_strerror(st));
  return st;
}

void qk__mesh_tri_free(qk__tri_state_t *T) {
  hmap_free(T->a, &T->vmap);
  qk__free(T->a, T->segv, (T->nsegv + 1) * sizeof *T->segv);
  qk__free(T->a, T->vx, T->vcap * sizeof *T->vx);
  qk__free(T->a, T->vy, T->vycap * sizeof *T->vy);
  qk__free(T->a, T->steiner, T->scap);
  qk__free(T->a, T->tri, T->tcap * 3 * sizeof *T->tri);
  qk__free(T->a, T->label, T->lcap * sizeof *T->label);
  qk__free(T->a, T->region, T->rcap * sizeof *T->region);
  qk__free(T->a, T->ord, T->ocap * sizeof *T->ord);
}
