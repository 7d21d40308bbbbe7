/*
 * Quadtree mesh generation (de Berg et al., ch. 14.3; lecture notes, sections I and V):
 * validate the components, subdivide, balance (BalanceQuadTree, index/balance.c),
 * triangulate every leaf, then give every triangle its component and drop holes.
 *
 * Exactness: inputs are integers up to 2^30; internally every coordinate is doubled, so
 * square centres of unit squares (the only non-integer mesh vertices) are integers too,
 * and every test below is integer arithmetic in 64 bits.
 */
#include "mesh/mesh_internal.h"

#include <math.h>
#include <stdlib.h>
#include <string.h>
#include <time.h>

/* A component edge, directed so that the component's interior lies on its left. */
typedef struct edge {
  int64_t ax, ay, bx, by; /* input (not doubled) coordinates */
  uint32_t comp;          /* 1-based component id */
  uint32_t seg;           /* input segment index */
} edge_t;

/*
 * The pieces of a unit leaf's closure that component edges cover: its four sides and two
 * diagonals. Each holds +c when component c's edge runs along the piece's positive
 * direction (west to east, south to north, SW to NE, SE to NW), -c when against it.
 */
enum { P_S, P_E, P_N, P_W, P_D0, P_D1, P_COUNT };
typedef struct unit_rec {
  uint32_t node;
  int32_t piece[P_COUNT];
  uint32_t edge[8]; /* the edges meeting the closed square (at most 8, see unit_leaf) */
  uint32_t nedge;
} unit_rec_t;

static int rec_cmp(const void *a, const void *b) {
  uint32_t x = ((const unit_rec_t *)a)->node, y = ((const unit_rec_t *)b)->node;
  return (x > y) - (x < y);
}

/* Generation state; freed in one place. */
typedef struct gen {
  const qk_allocator_t *a;
  const qk_poly_t *poly;
  qk_mesh_error_t *err;
  uint64_t U;
  edge_t *e;
  size_t ne;
  uint32_t ncomp;
  /* The edge-list arena of the subdivision: lists of edge indices, a stack of them. */
  uint32_t *arena;
  size_t arena_n, arena_cap;
  unit_rec_t *rec;
  size_t nrec, rec_cap;
  qk_tree_t *tree;
} gen_t;

static double now(void) {
  struct timespec ts;
  if (timespec_get(&ts, TIME_UTC) != TIME_UTC) return 0;
  return (double)ts.tv_sec + 1e-9 * (double)ts.tv_nsec;
}

void qk_mesh_options_init(qk_mesh_options_t *o) {
  if (!o) return;
  o->size = 0;
  o->allocator = NULL;
}

/* User-facing vertex number. */
static unsigned long vnum(const qk_poly_t *p, size_t i) {
  return (unsigned long)(i + p->first_index);
}
static unsigned long snum(const qk_poly_t *p, size_t i) {
  return (unsigned long)(i + p->first_index);
}

static int64_t cross(int64_t ax, int64_t ay, int64_t bx, int64_t by) { return ax * by - ay * bx; }
static int sgn(int64_t v) { return (v > 0) - (v < 0); }

/* Orientation of c relative to the line a->b. */
static int orient(int64_t ax, int64_t ay, int64_t bx, int64_t by, int64_t cx, int64_t cy) {
  return sgn(cross(bx - ax, by - ay, cx - ax, cy - ay));
}

/* Is c, collinear with a and b, within their bounding box? */
static int within(int64_t ax, int64_t ay, int64_t bx, int64_t by, int64_t cx, int64_t cy) {
  return cx >= (ax < bx ? ax : bx) && cx <= (ax > bx ? ax : bx) && cy >= (ay < by ? ay : by) &&
         cy <= (ay > by ? ay : by);
}

/* Do the closed segments of two edges meet? */
static int edges_meet(const edge_t *p, const edge_t *q) {
  int o1 = orient(p->ax, p->ay, p->bx, p->by, q->ax, q->ay);
  int o2 = orient(p->ax, p->ay, p->bx, p->by, q->bx, q->by);
  int o3 = orient(q->ax, q->ay, q->bx, q->by, p->ax, p->ay);
  int o4 = orient(q->ax, q->ay, q->bx, q->by, p->bx, p->by);
  if (o1 * o2 < 0 && o3 * o4 < 0) return 1;
  if (o1 == 0 && within(p->ax, p->ay, p->bx, p->by, q->ax, q->ay)) return 1;
  if (o2 == 0 && within(p->ax, p->ay, p->bx, p->by, q->bx, q->by)) return 1;
  if (o3 == 0 && within(q->ax, q->ay, q->bx, q->by, p->ax, p->ay)) return 1;
  if (o4 == 0 && within(q->ax, q->ay, q->bx, q->by, p->bx, p->by)) return 1;
  return 0;
}

/*
 * Are two edges a legal pair? They may meet only when consecutive on one component, at
 * their shared vertex, and without running back along each other.
 */
static int edges_legal(const gen_t *g, const edge_t *p, const edge_t *q) {
  const uint32_t *sp = &g->poly->seg[2 * p->seg], *sq = &g->poly->seg[2 * q->seg];
  for (int i = 0; i < 2; i++)
    for (int j = 0; j < 2; j++)
      if (sp[i] == sq[j]) {
        /* Shared vertex v: they overlap iff the other ends lie in the same direction. */
        const double *vx = g->poly->vx, *vy = g->poly->vy;
        int64_t x = (int64_t)vx[sp[i]], y = (int64_t)vy[sp[i]];
        int64_t ux = (int64_t)vx[sp[1 - i]] - x, uy = (int64_t)vy[sp[1 - i]] - y;
        int64_t wx = (int64_t)vx[sq[1 - j]] - x, wy = (int64_t)vy[sq[1 - j]] - y;
        return !(cross(ux, uy, wx, wy) == 0 && ux * wx + uy * wy > 0);
      }
  return !edges_meet(p, q);
}

static qk_status_t pair_error(gen_t *g, const edge_t *p, const edge_t *q) {
  const qk_poly_t *P = g->poly;
  unsigned long lp = P->sline[p->seg], lq = P->sline[q->seg];
  if (p->comp == q->comp)
    return qk__mesh_fail(g->err, QK_ERR_GEOMETRY, lq,
                         "component %u intersects itself: segments %lu (line %lu) and %lu (line "
                         "%lu) meet",
                         p->comp, snum(P, p->seg), lp, snum(P, q->seg), lq);
  return qk__mesh_fail(g->err, QK_ERR_GEOMETRY, lq,
                       "components %u and %u touch or cross: segments %lu (line %lu) and %lu "
                       "(line %lu) meet",
                       p->comp, q->comp, snum(P, p->seg), lp, snum(P, q->seg), lq);
}

/* Does edge e meet the closed square [x0, x0+s] x [y0, y0+s]? */
static int edge_meets_square(const edge_t *e, int64_t x0, int64_t y0, int64_t s) {
  int64_t x1 = x0 + s, y1 = y0 + s;
  int64_t minx = e->ax < e->bx ? e->ax : e->bx, maxx = e->ax < e->bx ? e->bx : e->ax;
  int64_t miny = e->ay < e->by ? e->ay : e->by, maxy = e->ay < e->by ? e->by : e->ay;
  if (maxx < x0 || minx > x1 || maxy < y0 || miny > y1) return 0;
  if (e->ax == e->bx || e->ay == e->by) return 1;
  /* A diagonal: the y-range it covers over the shared x-range must meet [y0, y1]. */
  int64_t lo = minx > x0 ? minx : x0, hi = maxx < x1 ? maxx : x1, ylo, yhi;
  if ((e->bx - e->ax) == (e->by - e->ay)) {
    int64_t c = e->ay - e->ax;
    ylo = lo + c, yhi = hi + c;
  } else {
    int64_t c = e->ax + e->ay;
    ylo = c - hi, yhi = c - lo;
  }
  return yhi >= y0 && ylo <= y1;
}

/*
 * A unit leaf of the subdivision: check the edges meeting it pairwise (every crossing or
 * touching of two edges happens in the closure of some unit leaf, since any square whose
 * closure holds a boundary point is split down to unit size), and record which of its
 * sides and diagonals are component edges.
 *
 * Every edge meeting a closed unit square contains one of its corners (edges lie on
 * lattice lines), and a legal corner lies on at most two edges, so at most 8 edges meet a
 * unit square in a valid input; checking the first 9 pairwise finds the fault otherwise.
 */
static qk_status_t unit_leaf(gen_t *g, uint32_t node, int64_t x0, int64_t y0, size_t off,
                             size_t k) {
  const uint32_t *L = g->arena + off;
  size_t m = k < 9 ? k : 9;
  for (size_t i = 0; i < m; i++)
    for (size_t j = i + 1; j < m; j++)
      if (!edges_legal(g, &g->e[L[i]], &g->e[L[j]])) return pair_error(g, &g->e[L[i]], &g->e[L[j]]);
  if (k > 8)
    return qk__mesh_fail(g->err, QK_ERR_GEOMETRY, g->poly->sline[g->e[L[0]].seg],
                         "too many segments meet the unit square at (%lld, %lld)", (long long)x0,
                         (long long)y0);
  void *rp = g->rec;
  if (qk__mesh_grow(g->a, &rp, &g->rec_cap, sizeof *g->rec, g->nrec + 1))
    return qk__mesh_fail(g->err, QK_ERR_NOMEM, 0, "out of memory");
  g->rec = rp;
  unit_rec_t *r = &g->rec[g->nrec++];
  memset(r, 0, sizeof *r);
  r->node = node;
  r->nedge = (uint32_t)k;
  for (size_t i = 0; i < k; i++) r->edge[i] = L[i];
  for (size_t i = 0; i < k; i++) {
    const edge_t *e = &g->e[L[i]];
    int64_t minx = e->ax < e->bx ? e->ax : e->bx, maxx = e->ax < e->bx ? e->bx : e->ax;
    int64_t miny = e->ay < e->by ? e->ay : e->by, maxy = e->ay < e->by ? e->by : e->ay;
    int32_t c = (int32_t)e->comp;
    if (e->ay == e->by) { /* horizontal: the south or north side, if it spans it */
      if (minx <= x0 && maxx >= x0 + 1) {
        int32_t v = e->bx > e->ax ? c : -c;
        if (e->ay == y0) r->piece[P_S] = v;
        if (e->ay == y0 + 1) r->piece[P_N] = v;
      }
    } else if (e->ax == e->bx) { /* vertical: the west or east side */
      if (miny <= y0 && maxy >= y0 + 1) {
        int32_t v = e->by > e->ay ? c : -c;
        if (e->ax == x0) r->piece[P_W] = v;
        if (e->ax == x0 + 1) r->piece[P_E] = v;
      }
    } else if (minx <= x0 && maxx >= x0 + 1) {
      if ((e->bx - e->ax) == (e->by - e->ay)) {
        if (e->ay - e->ax == y0 - x0) r->piece[P_D0] = e->bx > e->ax ? c : -c;
      } else if (e->ax + e->ay == x0 + y0 + 1) {
        r->piece[P_D1] = e->bx < e->ax ? c : -c;
      }
    }
  }
  return QK_OK;
}

/*
 * Step 1, subdivision: split a square while it is larger than unit size and its closure
 * meets the boundary of some component (touching at a single point counts). Each square
 * receives the list of edges meeting its closure, taken from its parent's list, so the
 * work is proportional to the output rather than to squares times edges.
 */
static qk_status_t subdivide(gen_t *g, uint32_t node, int64_t x0, int64_t y0, int64_t s, size_t off,
                             size_t k) {
  if (k == 0) return QK_OK;
  if (s == 1) return unit_leaf(g, node, x0, y0, off, k);
  qk_status_t st = qk_tree_split_leaf(g->tree, node);
  if (st != QK_OK) return qk__mesh_fail(g->err, st, 0, "%s while subdividing", qk_strerror(st));
  uint32_t child = g->tree->nodes[node].child;
  int64_t h = s / 2;
  for (unsigned q = 0; q < 4; q++) {
    int64_t cx = x0 + (qk__q_east(q) ? h : 0), cy = y0 + (qk__q_north(q) ? h : 0);
    void *ap = g->arena;
    if (qk__mesh_grow(g->a, &ap, &g->arena_cap, sizeof *g->arena, g->arena_n + k))
      return qk__mesh_fail(g->err, QK_ERR_NOMEM, 0, "out of memory");
    g->arena = ap;
    size_t base = g->arena_n, n = 0;
    for (size_t i = 0; i < k; i++) {
      uint32_t ei = g->arena[off + i];
      if (edge_meets_square(&g->e[ei], cx, cy, h)) g->arena[base + n++] = ei;
    }
    g->arena_n = base + n;
    st = subdivide(g, child + q, cx, cy, h, base, n);
    g->arena_n = base;
    if (st != QK_OK) return st;
  }
  return QK_OK;
}

/* Sorting vertices by position to find coincident ones. */
typedef struct vkey {
  int64_t x, y;
  uint32_t i;
} vkey_t;

static int vkey_cmp(const void *a, const void *b) {
  const vkey_t *p = a, *q = b;
  if (p->x != q->x) return p->x < q->x ? -1 : 1;
  if (p->y != q->y) return p->y < q->y ? -1 : 1;
  return (p->i > q->i) - (p->i < q->i);
}

/*
 * Validate vertices and segments, find the components (cycles) and orient their edges
 * counter-clockwise. Fills g->e, g->ne, g->ncomp and g->U.
 */
static qk_status_t validate(gen_t *g, uint64_t size) {
  const qk_poly_t *P = g->poly;
  qk_mesh_error_t *err = g->err;
  qk_status_t st = QK_OK;
  uint64_t maxc = 0;
  for (size_t i = 0; i < P->nv; i++) {
    double x = P->vx[i], y = P->vy[i];
    if (!(x == floor(x) && y == floor(y)) || !isfinite(x) || !isfinite(y))
      return qk__mesh_fail(err, QK_ERR_GEOMETRY, P->vline[i],
                           "vertex %lu: coordinates (%.17g, %.17g) are not integers", vnum(P, i), x,
                           y);
    if (x < 0 || y < 0 || x > (double)QK_MESH_MAX_SIZE || y > (double)QK_MESH_MAX_SIZE ||
        (size && (x > (double)size || y > (double)size)))
      return qk__mesh_fail(err, QK_ERR_GEOMETRY, P->vline[i],
                           "vertex %lu: (%.17g, %.17g) lies outside the domain [0,%llu]^2",
                           vnum(P, i), x, y, (unsigned long long)(size ? size : QK_MESH_MAX_SIZE));
    if ((uint64_t)x > maxc) maxc = (uint64_t)x;
    if ((uint64_t)y > maxc) maxc = (uint64_t)y;
  }
  if (size) {
    g->U = size;
  } else {
    g->U = 1;
    while (g->U < maxc) g->U *= 2;
  }

  /* Coincident vertices would make two components touch or a polygon degenerate. */
  vkey_t *keys = qk__realloc(g->a, NULL, 0, (P->nv ? P->nv : 1) * sizeof *keys);
  uint32_t *adj = qk__realloc(g->a, NULL, 0, (P->nv ? 2 * P->nv : 1) * sizeof *adj);
  uint8_t *deg = qk__realloc(g->a, NULL, 0, P->nv ? P->nv : 1);
  uint32_t *comp_of = qk__realloc(g->a, NULL, 0, (P->ns ? P->ns : 1) * sizeof *comp_of);
  if (!keys || !adj || !deg || !comp_of) {
    st = qk__mesh_fail(err, QK_ERR_NOMEM, 0, "out of memory");
    goto out;
  }
  for (size_t i = 0; i < P->nv; i++)
    keys[i] = (vkey_t){(int64_t)P->vx[i], (int64_t)P->vy[i], (uint32_t)i};
  qsort(keys, P->nv, sizeof *keys, vkey_cmp);
  for (size_t i = 1; i < P->nv; i++)
    if (keys[i].x == keys[i - 1].x && keys[i].y == keys[i - 1].y) {
      st = qk__mesh_fail(err, QK_ERR_GEOMETRY, P->vline[keys[i].i],
                         "vertices %lu and %lu coincide at (%lld, %lld)", vnum(P, keys[i - 1].i),
                         vnum(P, keys[i].i), (long long)keys[i].x, (long long)keys[i].y);
      goto out;
    }

  /* Segments: distinct endpoints, allowed angles, and every vertex of degree two. */
  memset(deg, 0, P->nv);
  for (size_t s = 0; s < P->ns; s++) {
    uint32_t u = P->seg[2 * s], v = P->seg[2 * s + 1];
    int64_t dx = (int64_t)P->vx[v] - (int64_t)P->vx[u], dy = (int64_t)P->vy[v] - (int64_t)P->vy[u];
    if (u == v) {
      st = qk__mesh_fail(err, QK_ERR_GEOMETRY, P->sline[s],
                         "segment %lu joins vertex %lu to itself", snum(P, s), vnum(P, u));
      goto out;
    }
    if (!(dx == 0 || dy == 0 || dx == dy || dx == -dy)) {
      st = qk__mesh_fail(err, QK_ERR_GEOMETRY, P->sline[s],
                         "segment %lu from (%lld, %lld) to (%lld, %lld) is not at 0, 45, 90 or 135 "
                         "degrees",
                         snum(P, s), (long long)P->vx[u], (long long)P->vy[u], (long long)P->vx[v],
                         (long long)P->vy[v]);
      goto out;
    }
    for (int k = 0; k < 2; k++) {
      uint32_t w = P->seg[2 * s + k];
      if (deg[w] >= 2) {
        st = qk__mesh_fail(err, QK_ERR_GEOMETRY, P->sline[s],
                           "vertex %lu has degree more than 2 (segment %lu is its third)",
                           vnum(P, w), snum(P, s));
        goto out;
      }
      adj[2 * w + deg[w]++] = (uint32_t)s;
    }
  }
  for (size_t i = 0; i < P->nv; i++)
    if (deg[i] != 2) {
      st = qk__mesh_fail(err, QK_ERR_GEOMETRY, P->vline[i],
                         deg[i] ? "vertex %lu has degree 1: it ends an open chain"
                                : "vertex %lu is on no segment (degree 0)",
                         vnum(P, i));
      goto out;
    }

  /* Components: walk each cycle from its smallest segment, so that the cycle of segment
   * 0 is component 1 and so on. */
  g->e = qk__realloc(g->a, NULL, 0, (P->ns ? P->ns : 1) * sizeof *g->e);
  if (!g->e) {
    st = qk__mesh_fail(err, QK_ERR_NOMEM, 0, "out of memory");
    goto out;
  }
  for (size_t s = 0; s < P->ns; s++) comp_of[s] = 0;
  for (size_t s0 = 0; s0 < P->ns; s0++) {
    if (comp_of[s0]) continue;
    uint32_t c = ++g->ncomp;
    size_t first = g->ne;
    /* Walk: from segment s entered at vertex `from`, leave through its other end. */
    uint32_t s = (uint32_t)s0, from = P->seg[2 * s0];
    size_t len = 0;
    do {
      comp_of[s] = c;
      uint32_t to = P->seg[2 * s] == from ? P->seg[2 * s + 1] : P->seg[2 * s];
      g->e[g->ne++] = (edge_t){
          (int64_t)P->vx[from], (int64_t)P->vy[from], (int64_t)P->vx[to], (int64_t)P->vy[to], c, s};
      len++;
      s = adj[2 * to] == s ? adj[2 * to + 1] : adj[2 * to];
      from = to;
    } while (s != s0);
    if (len < 3) {
      st = qk__mesh_fail(err, QK_ERR_GEOMETRY, P->sline[g->e[first + 1].seg],
                         "segments %lu and %lu coincide", snum(P, g->e[first].seg),
                         snum(P, g->e[first + 1].seg));
      goto out;
    }
    /* Orientation from the turn at the lowest (then leftmost) vertex, which is convex. */
    size_t lo = first;
    for (size_t i = first + 1; i < g->ne; i++)
      if (g->e[i].ay < g->e[lo].ay || (g->e[i].ay == g->e[lo].ay && g->e[i].ax < g->e[lo].ax))
        lo = i;
    const edge_t *in = &g->e[lo == first ? g->ne - 1 : lo - 1], *outg = &g->e[lo];
    int64_t turn =
        cross(in->bx - in->ax, in->by - in->ay, outg->bx - outg->ax, outg->by - outg->ay);
    if (turn == 0) {
      st = qk__mesh_fail(err, QK_ERR_GEOMETRY, P->sline[outg->seg],
                         "component %u is degenerate: segments %lu and %lu overlap", c,
                         snum(P, in->seg), snum(P, outg->seg));
      goto out;
    }
    if (turn < 0)
      for (size_t i = first; i < g->ne; i++) {
        edge_t *e = &g->e[i];
        int64_t tx = e->ax, ty = e->ay;
        e->ax = e->bx, e->ay = e->by, e->bx = tx, e->by = ty;
      }
  }
out:
  qk__free(g->a, keys, (P->nv ? P->nv : 1) * sizeof *keys);
  qk__free(g->a, adj, (P->nv ? 2 * P->nv : 1) * sizeof *adj);
  qk__free(g->a, deg, P->nv ? P->nv : 1);
  qk__free(g->a, comp_of, (P->ns ? P->ns : 1) * sizeof *comp_of);
  return st;
}

/* ---- Step 3: triangulation ---------------------------------------------------------- */

/* An open-addressing hash map from 64-bit keys to 32-bit values. */
typedef struct hmap {
  uint64_t *k;
  uint32_t *v;
  size_t cap, n; /* cap is a power of two; key UINT64_MAX marks an empty slot */
} hmap_t;

static size_t hslot(uint64_t key, size_t cap) {
  key ^= key >> 31;
  key *= 0x9e3779b97f4a7c15ull;
  key ^= key >> 29;
  return (size_t)key & (cap - 1);
}

static void hmap_free(const qk_allocator_t *a, hmap_t *h) {
  qk__free(a, h->k, h->cap * sizeof *h->k);
  qk__free(a, h->v, h->cap * sizeof *h->v);
  h->k = NULL, h->v = NULL, h->cap = h->n = 0;
}

static qk_status_t hmap_init(const qk_allocator_t *a, hmap_t *h, size_t expect) {
  size_t cap = 64;
  while (cap < 2 * expect) cap *= 2;
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

/* Find key; if absent insert it with value *v. Returns 1 when found (*v set), 0 when
 * inserted, -1 out of memory. */
static int hmap_get_or_put(const qk_allocator_t *a, hmap_t *h, uint64_t key, uint32_t *v) {
  if (2 * (h->n + 1) > h->cap) {
    hmap_t nh;
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

/* Triangulation state. Coordinates are doubled input coordinates. */
typedef struct tri_state {
  const qk_allocator_t *a;
  hmap_t vmap;
  int64_t *vx, *vy; /* doubled coordinates */
  uint8_t *steiner;
  size_t nv, vcap, vycap, scap;
  uint32_t *tri;   /* 3 per triangle */
  uint32_t *label; /* per triangle: its cell while triangulating, then its component */
  size_t nt, tcap, lcap;
} tri_state_t;

static qk_status_t new_vertex(tri_state_t *T, int64_t x, int64_t y, int steiner, uint32_t *id) {
  void *p1 = T->vx, *p2 = T->vy, *p3 = T->steiner;
  if (qk__mesh_grow(T->a, &p1, &T->vcap, sizeof *T->vx, T->nv + 1)) return QK_ERR_NOMEM;
  T->vx = p1;
  if (qk__mesh_grow(T->a, &p2, &T->vycap, sizeof *T->vy, T->nv + 1)) return QK_ERR_NOMEM;
  T->vy = p2;
  if (qk__mesh_grow(T->a, &p3, &T->scap, 1, T->nv + 1)) return QK_ERR_NOMEM;
  T->steiner = p3;
  T->vx[T->nv] = x, T->vy[T->nv] = y, T->steiner[T->nv] = (uint8_t)steiner;
  *id = (uint32_t)T->nv++;
  return QK_OK;
}

/* The vertex at a lattice point, created on first use (corners are shared by leaves). */
static qk_status_t corner_vertex(tri_state_t *T, int64_t x, int64_t y, uint32_t *id) {
  uint64_t key = ((uint64_t)x << 32) | (uint64_t)y;
  uint32_t v = (uint32_t)T->nv;
  int r = hmap_get_or_put(T->a, &T->vmap, key, &v);
  if (r < 0) return QK_ERR_NOMEM;
  if (r == 1) {
    *id = v;
    return QK_OK;
  }
  return new_vertex(T, x, y, 0, id);
}

static qk_status_t add_tri(tri_state_t *T, uint32_t a, uint32_t b, uint32_t c, uint32_t cell) {
  void *p1 = T->tri, *p2 = T->label;
  if (qk__mesh_grow(T->a, &p1, &T->tcap, 3 * sizeof *T->tri, T->nt + 1)) return QK_ERR_NOMEM;
  T->tri = p1;
  if (qk__mesh_grow(T->a, &p2, &T->lcap, sizeof *T->label, T->nt + 1)) return QK_ERR_NOMEM;
  T->label = p2;
  uint32_t *t = &T->tri[3 * T->nt];
  t[0] = a, t[1] = b, t[2] = c;
  T->label[T->nt] = cell;
  T->nt++;
  return QK_OK;
}

#define UNKNOWN UINT32_MAX

/*
 * A triangle edge lying on a component piece seeds the label of the triangle's cell when
 * the triangle is on the piece's left as the component runs, i.e. inside that component:
 * `dir` is +1 when the triangle traverses the piece in its positive direction.
 */
static void seed(uint32_t *label, int32_t piece, int dir) {
  if (piece != 0 && (piece > 0) == (dir > 0)) *label = (uint32_t)(piece > 0 ? piece : -piece);
}

/*
 * Labelling works on cells: the parts of a leaf that no component edge separates. A leaf
 * is one cell, except a unit leaf cut by a component diagonal, which is two. cell_side
 * tells whether cell k of a leaf with diagonal kind `diag` (0 none, 1 SW-NE, 2 SE-NW)
 * touches side s (south, east, north, west).
 */
static int cell_touches(int diag, int k, int s) {
  static const unsigned char touch[3][2] = {{0xf, 0x0}, {0x3, 0xc}, {0x9, 0x6}};
  return (touch[diag][k] >> s) & 1;
}

/*
 * Step 3 for one unit leaf holding component pieces: a component diagonal splits it
 * along that diagonal; otherwise the SW-NE diagonal does (its vertices are only its
 * corners, since no leaf is smaller than unit size). Seeds the labels of its cells.
 */
static qk_status_t tri_unit(tri_state_t *T, const unit_rec_t *r, const uint32_t c[4],
                            uint32_t cell0, uint32_t *cell_label) {
  /* c: SW, SE, NE, NW. */
  const int32_t *p = r->piece;
  if (p[P_D1]) {
    /* Along SE-NW: (SW, SE, NW) and (SE, NE, NW). */
    seed(&cell_label[cell0], p[P_S], +1);
    seed(&cell_label[cell0], p[P_D1], +1); /* SE -> NW is the positive direction of D1 */
    seed(&cell_label[cell0], p[P_W], -1);  /* NW -> SW runs southwards */
    seed(&cell_label[cell0 + 1], p[P_E], +1);
    seed(&cell_label[cell0 + 1], p[P_N], -1);
    seed(&cell_label[cell0 + 1], p[P_D1], -1);
    qk_status_t st = add_tri(T, c[0], c[1], c[3], cell0);
    if (st) return st;
    return add_tri(T, c[1], c[2], c[3], cell0 + 1);
  }
  /* Along SW-NE: (SW, SE, NE) and (SW, NE, NW); one cell unless SW-NE is a component
   * edge. */
  uint32_t cell1 = p[P_D0] ? cell0 + 1 : cell0;
  seed(&cell_label[cell0], p[P_S], +1);
  seed(&cell_label[cell0], p[P_E], +1);
  seed(&cell_label[cell0], p[P_D0], -1); /* NE -> SW */
  seed(&cell_label[cell1], p[P_D0], +1);
  seed(&cell_label[cell1], p[P_N], -1);
  seed(&cell_label[cell1], p[P_W], -1);
  qk_status_t st = add_tri(T, c[0], c[1], c[2], cell0);
  if (st) return st;
  return add_tri(T, c[0], c[2], c[3], cell1);
}

/* Facts the triangulation hands to hole removal. */
typedef struct leaf_tris {
  uint32_t *first; /* per node id: first triangle of the leaf, or UNKNOWN */
  size_t cap;
} leaf_tris_t;

/*
 * Components: a cell beside a component edge, on its inner (left) side, lies in that
 * component's face and was seeded with its id. Every other cell takes the label of the
 * face it shares with the cells across leaf sides that are not component edges (found
 * with the tree's neighbour finding); a face reached from no seed is the outer face,
 * label 0.
 */
static qk_status_t label_cells(gen_t *g, const qk_node_t *leaves, size_t nleaves,
                               const uint32_t *leaf_of, const uint32_t *rec_of,
                               uint32_t *cell_label) {
  const qk_tree_t *t = g->tree;
  size_t ncell = 2 * nleaves;
  uint32_t *queue = qk__realloc(g->a, NULL, 0, (ncell + 1) * sizeof *queue);
  if (!queue) return QK_ERR_NOMEM;
  size_t qh = 0, qt = 0;
  for (size_t c = 0; c < ncell; c++)
    if (cell_label[c] != UNKNOWN) queue[qt++] = (uint32_t)c;
  static const qk_dir_t side_dir[4] = {QK_SOUTH, QK_EAST, QK_NORTH, QK_WEST};
  static const int piece_of_side[4] = {P_S, P_E, P_N, P_W};
  while (qh < qt) {
    uint32_t c = queue[qh++], li = c / 2, k = c % 2;
    uint32_t v = leaves[li];
    const unit_rec_t *r = rec_of[v] != UNKNOWN ? &g->rec[rec_of[v]] : NULL;
    int diag = r ? (r->piece[P_D0] ? 1 : r->piece[P_D1] ? 2 : 0) : 0;
    for (int s = 0; s < 4; s++) {
      if (!cell_touches(diag, (int)k, s)) continue;
      if (r && r->piece[piece_of_side[s]]) continue; /* a component edge: a face boundary */
      qk_node_t nb[8];
      size_t n = 0;
      qk_tree_adjacent_leaves(t, v, side_dir[s], nb, 8, &n);
      for (size_t i = 0; i < n && i < 8; i++) {
        uint32_t lw = leaf_of[nb[i]];
        const unit_rec_t *rw = rec_of[nb[i]] != UNKNOWN ? &g->rec[rec_of[nb[i]]] : NULL;
        int dw = rw ? (rw->piece[P_D0] ? 1 : rw->piece[P_D1] ? 2 : 0) : 0;
        int opp = (s + 2) % 4;
        uint32_t cw = 2 * lw + (cell_touches(dw, 0, opp) ? 0 : 1);
        if (cell_label[cw] == UNKNOWN) cell_label[cw] = cell_label[c], queue[qt++] = cw;
      }
    }
  }
  for (size_t c = 0; c < ncell; c++)
    if (cell_label[c] == UNKNOWN) cell_label[c] = 0;
  qk__free(g->a, queue, (ncell + 1) * sizeof *queue);
  return QK_OK;
}

static qk_status_t triangulate(gen_t *g, tri_state_t *T, leaf_tris_t *lt) {
  const qk_tree_t *t = g->tree;
  qk_status_t st = QK_OK;
  /* Which unit leaves carry component pieces, and each leaf's index, by node id. */
  size_t nn = t->n_nodes;
  uint32_t *rec_of = qk__realloc(g->a, NULL, 0, nn * sizeof *rec_of);
  uint32_t *leaf_of = qk__realloc(g->a, NULL, 0, nn * sizeof *leaf_of);
  lt->cap = nn;
  lt->first = qk__realloc(g->a, NULL, 0, lt->cap * sizeof *lt->first);
  size_t nleaves = 0;
  qk_tree_leaves(t, NULL, 0, &nleaves);
  qk_node_t *leaves = qk__realloc(g->a, NULL, 0, (nleaves + 1) * sizeof *leaves);
  uint32_t *cell_label = qk__realloc(g->a, NULL, 0, (2 * nleaves + 1) * sizeof *cell_label);
  if (!rec_of || !leaf_of || !lt->first || !leaves || !cell_label ||
      hmap_init(g->a, &T->vmap, 2 * nleaves + 16) != QK_OK) {
    st = QK_ERR_NOMEM;
    goto out;
  }
  memset(rec_of, 0xff, nn * sizeof *rec_of);
  memset(lt->first, 0xff, lt->cap * sizeof *lt->first);
  memset(cell_label, 0xff, (2 * nleaves + 1) * sizeof *cell_label);
  for (size_t i = 0; i < g->nrec; i++) rec_of[g->rec[i].node] = (uint32_t)i;
  qk_tree_leaves(t, leaves, nleaves, &nleaves);
  for (size_t li = 0; li < nleaves; li++) leaf_of[leaves[li]] = (uint32_t)li;

  for (size_t li = 0; li < nleaves; li++) {
    uint32_t v = leaves[li], cell = (uint32_t)(2 * li);
    const qk__node_t *n = &t->nodes[v];
    int64_t S = 2 * (int64_t)(t->side[n->depth]), X = 2 * (int64_t)n->x0, Y = 2 * (int64_t)n->y0;
    lt->first[v] = (uint32_t)T->nt;
    uint32_t c[4];
    if ((st = corner_vertex(T, X, Y, &c[0])) || (st = corner_vertex(T, X + S, Y, &c[1])) ||
        (st = corner_vertex(T, X + S, Y + S, &c[2])) || (st = corner_vertex(T, X, Y + S, &c[3])))
      goto out;
    if (rec_of[v] != UNKNOWN) {
      if ((st = tri_unit(T, &g->rec[rec_of[v]], c, cell, cell_label))) goto out;
      continue;
    }
    /* A side holds a midpoint vertex exactly when the neighbour across it (found by
     * NorthNeighbor, of at most this depth) is internal: then, the tree being balanced,
     * two leaves of half the size meet this side. Unit leaves have no smaller
     * neighbours. Sides in CCW order: south, east, north, west. */
    static const qk_dir_t side_dir[4] = {QK_SOUTH, QK_EAST, QK_NORTH, QK_WEST};
    int64_t mx[4] = {X + S / 2, X + S, X + S / 2, X}, my[4] = {Y, Y + S / 2, Y + S, Y + S / 2};
    uint32_t ring[8];
    size_t nr = 0;
    for (int s = 0; s < 4; s++) {
      ring[nr++] = c[s];
      if (S > 2) {
        qk_node_t u = qk_tree_neighbor(t, v, side_dir[s]);
        if (u != QK_NONE && !qk__is_leaf(&t->nodes[u]) &&
            (st = corner_vertex(T, mx[s], my[s], &ring[nr++])))
          goto out;
      }
    }
    if (nr == 4) {
      /* Vertices only at its corners: split along a diagonal (angles 45, 45, 90). */
      if ((st = add_tri(T, c[0], c[1], c[2], cell)) || (st = add_tri(T, c[0], c[2], c[3], cell)))
        goto out;
      continue;
    }
    /* A Steiner point at the centre, joined to every boundary vertex: each triangle has
     * a right angle at the centre (corner-corner) or at the midpoint (corner-midpoint). */
    uint32_t ctr;
    if ((st = new_vertex(T, X + S / 2, Y + S / 2, 1, &ctr))) goto out;
    for (size_t i = 0; i < nr; i++)
      if ((st = add_tri(T, ring[i], ring[(i + 1) % nr], ctr, cell))) goto out;
  }
  if ((st = label_cells(g, leaves, nleaves, leaf_of, rec_of, cell_label))) goto out;
  for (size_t i = 0; i < T->nt; i++) T->label[i] = cell_label[T->label[i]];
out:
  qk__free(g->a, rec_of, nn * sizeof *rec_of);
  qk__free(g->a, leaf_of, nn * sizeof *leaf_of);
  qk__free(g->a, leaves, (nleaves + 1) * sizeof *leaves);
  qk__free(g->a, cell_label, (2 * nleaves + 1) * sizeof *cell_label);
  if (st) qk__mesh_fail(g->err, st, 0, "%s while triangulating", qk_strerror(st));
  return st;
}

/*
 * Exact sign of s1 x + s2 y - c for doubles x, y >= 0, signs s1, s2 in {-1, 0, 1} and an
 * integer c: the lines of a quadtree mesh are axis-parallel or diagonal, so every
 * orientation test against a hole point has this form. Split x = ix + fx, y = iy + fy
 * with integer parts and fractions in [0, 1) (both exact); the integer part decides
 * unless it is within one of zero, and then only exact comparisons of fractions remain.
 */
static int lin_sign(int s1, int s2, double x, double y, int64_t c) {
  if (s1 == 0 || s2 == 0) {
    double v = s1 ? x : y;
    int s = s1 ? s1 : s2;
    if (s == 0) return (c < 0) - (c > 0);
    /* sign(s v - c) = s * sign(v - s c) */
    double t = (double)(s * c);
    return s * ((v > t) - (v < t));
  }
  if (s1 < 0) return -lin_sign(-s1, -s2, x, y, -c);
  double ix = floor(x), iy = floor(y), fx = x - ix, fy = y - iy;
  if (s2 > 0) { /* x + y - c = I + (fx + fy), fx + fy in [0, 2) */
    int64_t I = (int64_t)ix + (int64_t)iy - c;
    if (I >= 0) return (I > 0 || fx > 0 || fy > 0) ? 1 : 0;
    if (I <= -2) return -1;
    /* I = -1: sign(fx + fy - 1). 1 - f is exact for f >= 1/2; if both are below 1/2 the
     * sum is below 1. */
    if (fy >= 0.5) return (fx > 1 - fy) - (fx < 1 - fy);
    if (fx >= 0.5) return (fy > 1 - fx) - (fy < 1 - fx);
    return -1;
  }
  /* x - y - c = I + (fx - fy), fx - fy in (-1, 1). */
  int64_t I = (int64_t)ix - (int64_t)iy - c;
  if (I >= 1) return 1;
  if (I <= -1) return -1;
  return (fx > fy) - (fx < fy);
}

/* Exact turn from a->b (integer points, direction axis-parallel or diagonal) to h. */
static int orient_h(int64_t ax, int64_t ay, int64_t bx, int64_t by, double hx, double hy) {
  int sx = (bx > ax) - (bx < ax), sy = (by > ay) - (by < ay);
  /* cross((s), h - a) = sx (hy - ay) - sy (hx - ax) = -sy hx + sx hy - (sx ay - sy ax) */
  return lin_sign(-sy, sx, hx, hy, sx * ay - sy * ax);
}

/* Is h on the closed segment a-b? */
static int on_edge(const edge_t *e, double hx, double hy) {
  if (orient_h(e->ax, e->ay, e->bx, e->by, hx, hy) != 0) return 0;
  double x0 = (double)(e->ax < e->bx ? e->ax : e->bx), x1 = (double)(e->ax < e->bx ? e->bx : e->ax);
  double y0 = (double)(e->ay < e->by ? e->ay : e->by), y1 = (double)(e->ay < e->by ? e->by : e->ay);
  return hx >= x0 && hx <= x1 && hy >= y0 && hy <= y1;
}

/* Holes: find the face holding each hole point and mark its label to be dropped. */
static qk_status_t find_holes(gen_t *g, tri_state_t *T, const leaf_tris_t *lt, uint8_t *drop) {
  const qk_poly_t *P = g->poly;
  for (size_t h = 0; h < P->nh; h++) {
    double hx = P->hx[h], hy = P->hy[h];
    if (!(hx >= 0 && hy >= 0 && hx <= (double)g->U && hy <= (double)g->U))
      return qk__mesh_fail(g->err, QK_ERR_GEOMETRY, P->hline[h],
                           "hole %lu at (%.17g, %.17g) lies outside the domain [0,%llu]^2",
                           snum(P, h), hx, hy, (unsigned long long)g->U);
    qk_node_t leaf;
    if (qk_tree_find_leaf(g->tree, (qk_point_t){hx, hy}, &leaf) != QK_OK) continue;
    /* On a component edge the face is ambiguous. Such an edge meets the closure of the
     * leaf holding the point, so the leaf is a unit square and the edge in its list. */
    unit_rec_t key;
    key.node = leaf;
    const unit_rec_t *r = g->nrec ? bsearch(&key, g->rec, g->nrec, sizeof *g->rec, rec_cmp) : NULL;
    for (uint32_t i = 0; r && i < r->nedge; i++)
      if (on_edge(&g->e[r->edge[i]], hx, hy))
        return qk__mesh_fail(g->err, QK_ERR_GEOMETRY, P->hline[h],
                             "hole %lu at (%.17g, %.17g) lies on the boundary of component %u",
                             snum(P, h), hx, hy, g->e[r->edge[i]].comp);
    if (leaf >= lt->cap || lt->first[leaf] == UNKNOWN) continue;
    /* A leaf's triangles are consecutive and at most 8; scan them (a triangle of the next
     * leaf that also holds the point is in the same face, so overrunning is harmless). */
    for (uint32_t t = lt->first[leaf]; t < T->nt && t < lt->first[leaf] + 8; t++) {
      const uint32_t *tr = &T->tri[3 * t];
      int inside = 1;
      for (int i = 0; i < 3 && inside; i++) {
        uint32_t a = tr[i], b = tr[(i + 1) % 3];
        if (orient_h(T->vx[a], T->vy[a], T->vx[b], T->vy[b], 2 * hx, 2 * hy) < 0) inside = 0;
      }
      if (inside) {
        drop[T->label[t]] = 1;
        break;
      }
    }
  }
  return QK_OK;
}

static void gen_free(gen_t *g) {
  qk__free(g->a, g->e, (g->poly->ns ? g->poly->ns : 1) * sizeof *g->e);
  qk__free(g->a, g->arena, g->arena_cap * sizeof *g->arena);
  qk__free(g->a, g->rec, g->rec_cap * sizeof *g->rec);
}

static void tri_free(tri_state_t *T) {
  hmap_free(T->a, &T->vmap);
  qk__free(T->a, T->vx, T->vcap * sizeof *T->vx);
  qk__free(T->a, T->vy, T->vycap * sizeof *T->vy);
  qk__free(T->a, T->steiner, T->scap);
  qk__free(T->a, T->tri, T->tcap * 3 * sizeof *T->tri);
  qk__free(T->a, T->label, T->lcap * sizeof *T->label);
}

void qk_mesh_free(qk_mesh_t *m) {
  if (!m) return;
  qk_allocator_t a = m->alloc;
  qk_tree_free(m->tree);
  /* Every array was allocated one element longer than needed, so that none is empty. */
  qk__free(&a, m->xy, (2 * m->nv + 2) * sizeof *m->xy);
  qk__free(&a, m->tri, (3 * m->nt + 3) * sizeof *m->tri);
  qk__free(&a, m->comp, (m->nt + 1) * sizeof *m->comp);
  qk__free(&a, m->cxy, (2 * m->ncv + 2) * sizeof *m->cxy);
  qk__free(&a, m->cseg, (2 * m->ncs + 2) * sizeof *m->cseg);
  qk__free(&a, m, sizeof *m);
}

/* Angle at b of triangle a-b-c, in degrees. */
static double angle_deg(const int64_t *vx, const int64_t *vy, uint32_t a, uint32_t b, uint32_t c) {
  double ux = (double)(vx[a] - vx[b]), uy = (double)(vy[a] - vy[b]);
  double wx = (double)(vx[c] - vx[b]), wy = (double)(vy[c] - vy[b]);
  return atan2(fabs(ux * wy - uy * wx), ux * wx + uy * wy) * (180.0 / 3.14159265358979323846);
}

qk_status_t qk_mesh_generate(const qk_poly_t *poly, const qk_mesh_options_t *options,
                             qk_mesh_t **out, qk_mesh_error_t *err) {
  if (err) err->line = 0, err->message[0] = '\0';
  if (!out) return QK_ERR_INVALID;
  *out = NULL;
  if (!poly) return qk__mesh_fail(err, QK_ERR_INVALID, 0, "no input");
  qk_mesh_options_t opt;
  qk_mesh_options_init(&opt);
  if (options) opt = *options;
  if (opt.size && ((opt.size & (opt.size - 1)) || opt.size > QK_MESH_MAX_SIZE))
    return qk__mesh_fail(err, QK_ERR_INVALID, 0,
                         "domain size %llu is not a power of two between 1 and 2^30",
                         (unsigned long long)opt.size);
  qk_allocator_t alloc = {NULL, NULL};
  if (opt.allocator) alloc = *opt.allocator;

  qk_mesh_t *m = qk__realloc(&alloc, NULL, 0, sizeof *m);
  if (!m) return qk__mesh_fail(err, QK_ERR_NOMEM, 0, "out of memory");
  memset(m, 0, sizeof *m);
  m->alloc = alloc;
  gen_t g;
  memset(&g, 0, sizeof g);
  g.a = &m->alloc, g.poly = poly, g.err = err;
  tri_state_t T;
  memset(&T, 0, sizeof T);
  T.a = &m->alloc;
  leaf_tris_t lt = {NULL, 0};
  uint8_t *drop = NULL;
  uint32_t *newid = NULL;
  qk_status_t st;

  double t0 = now();
  if ((st = validate(&g, opt.size))) goto fail;
  m->size = g.U;
  m->stats.components = g.ncomp;

  /* The subdivision is a quadkit tree over the root square [0,U]^2 with no points. */
  double t1 = now();
  qk_tree_options_t to;
  qk_tree_options_init(&to);
  to.has_root = 1;
  to.root = (qk_square_t){0, 0, (double)g.U};
  to.capacity = 1;
  to.allocator = &m->alloc;
  {
    uint32_t lg = 0;
    while (((uint64_t)1 << lg) < g.U) lg++;
    to.max_depth = lg + 1;
  }
  if ((st = qk_tree_build(NULL, 0, &to, &m->tree))) {
    qk__mesh_fail(err, st, 0, "%s while building the tree", qk_strerror(st));
    goto fail;
  }
  g.tree = m->tree;
  {
    void *ap = g.arena;
    if (qk__mesh_grow(g.a, &ap, &g.arena_cap, sizeof *g.arena, g.ne + 1)) {
      st = qk__mesh_fail(err, QK_ERR_NOMEM, 0, "out of memory");
      goto fail;
    }
    g.arena = ap;
    for (size_t i = 0; i < g.ne; i++) g.arena[i] = (uint32_t)i;
    g.arena_n = g.ne;
  }
  if ((st = subdivide(&g, qk_tree_root(g.tree), 0, 0, (int64_t)g.U, 0, g.ne))) goto fail;
  qk_tree_leaves(g.tree, NULL, 0, &m->stats.leaves_before_balance);
  /* Records sorted by node id, for lookups by hole location. */
  if (g.nrec) qsort(g.rec, g.nrec, sizeof *g.rec, rec_cmp);

  /* Step 2: BalanceQuadTree. */
  double t2 = now();
  if ((st = qk_tree_balance(g.tree))) {
    qk__mesh_fail(err, st, 0, "%s while balancing", qk_strerror(st));
    goto fail;
  }
  qk_tree_leaves(g.tree, NULL, 0, &m->stats.leaves);

  /* Step 3: triangulate, label, drop holes, compact. */
  double t3 = now();
  if ((st = triangulate(&g, &T, &lt))) goto fail;
  drop = qk__realloc(g.a, NULL, 0, g.ncomp + 1);
  newid = qk__realloc(g.a, NULL, 0, (T.nv ? T.nv : 1) * sizeof *newid);
  if (!drop || !newid) {
    st = qk__mesh_fail(err, QK_ERR_NOMEM, 0, "out of memory");
    goto fail;
  }
  memset(drop, 0, g.ncomp + 1);
  if ((st = find_holes(&g, &T, &lt, drop))) goto fail;

  memset(newid, 0xff, (T.nv ? T.nv : 1) * sizeof *newid);
  size_t kt = 0, kv = 0;
  for (size_t t = 0; t < T.nt; t++) {
    if (drop[T.label[t]]) continue;
    kt++;
    for (int i = 0; i < 3; i++)
      if (newid[T.tri[3 * t + i]] == UNKNOWN) newid[T.tri[3 * t + i]] = (uint32_t)kv++;
  }
  m->nv = kv, m->nt = kt, m->ncv = poly->nv, m->ncs = poly->ns;
  m->xy = qk__realloc(g.a, NULL, 0, (2 * kv + 2) * sizeof *m->xy);
  m->tri = qk__realloc(g.a, NULL, 0, (3 * kt + 3) * sizeof *m->tri);
  m->comp = qk__realloc(g.a, NULL, 0, (kt + 1) * sizeof *m->comp);
  m->cxy = qk__realloc(g.a, NULL, 0, (2 * poly->nv + 2) * sizeof *m->cxy);
  m->cseg = qk__realloc(g.a, NULL, 0, (2 * poly->ns + 2) * sizeof *m->cseg);
  if (!m->xy || !m->tri || !m->comp || !m->cxy || !m->cseg) {
    st = qk__mesh_fail(err, QK_ERR_NOMEM, 0, "out of memory");
    goto fail;
  }
  double amin = 180, amax = 0;
  size_t steiner = 0;
  for (size_t i = 0; i < T.nv; i++)
    if (newid[i] != UNKNOWN) {
      m->xy[2 * newid[i]] = (double)T.vx[i] / 2;
      m->xy[2 * newid[i] + 1] = (double)T.vy[i] / 2;
      steiner += T.steiner[i];
    }
  size_t j = 0;
  for (size_t t = 0; t < T.nt; t++) {
    if (drop[T.label[t]]) continue;
    const uint32_t *tr = &T.tri[3 * t];
    for (int i = 0; i < 3; i++) {
      m->tri[3 * j + i] = newid[tr[i]];
      double ang = angle_deg(T.vx, T.vy, tr[(i + 2) % 3], tr[i], tr[(i + 1) % 3]);
      if (ang < amin) amin = ang;
      if (ang > amax) amax = ang;
    }
    m->comp[j++] = T.label[t];
  }
  for (size_t i = 0; i < poly->nv; i++)
    m->cxy[2 * i] = poly->vx[i], m->cxy[2 * i + 1] = poly->vy[i];
  if (poly->ns) memcpy(m->cseg, poly->seg, 2 * poly->ns * sizeof *m->cseg);
  double t4 = now();

  m->stats.size = g.U;
  m->stats.triangles = kt;
  m->stats.vertices = kv;
  m->stats.steiner = steiner;
  m->stats.min_angle_deg = kt ? amin : 0;
  m->stats.max_angle_deg = kt ? amax : 0;
  m->stats.uniform_triangles = 2.0 * (double)g.U * (double)g.U;
  m->stats.seconds_validate = t1 - t0;
  m->stats.seconds_subdivide = t2 - t1;
  m->stats.seconds_balance = t3 - t2;
  m->stats.seconds_triangulate = t4 - t3;
  st = QK_OK;
fail:
  qk__free(g.a, drop, g.ncomp + 1);
  qk__free(g.a, newid, (T.nv ? T.nv : 1) * sizeof *newid);
  qk__free(g.a, lt.first, lt.cap * sizeof *lt.first);
  tri_free(&T);
  gen_free(&g);
  if (st != QK_OK) {
    qk_mesh_free(m);
    return st;
  }
  *out = m;
  return QK_OK;
}

const double *qk_mesh_vertices(const qk_mesh_t *m, size_t *n) {
  if (n) *n = m ? m->nv : 0;
  return m ? m->xy : NULL;
}

const uint32_t *qk_mesh_triangles(const qk_mesh_t *m, size_t *n) {
  if (n) *n = m ? m->nt : 0;
  return m ? m->tri : NULL;
}

const uint32_t *qk_mesh_triangle_components(const qk_mesh_t *m) { return m ? m->comp : NULL; }

const qk_tree_t *qk_mesh_tree(const qk_mesh_t *m) { return m ? m->tree : NULL; }

void qk_mesh_stats(const qk_mesh_t *m, qk_mesh_stats_t *s) {
  if (!s) return;
  if (!m) {
    memset(s, 0, sizeof *s);
    return;
  }
  *s = m->stats;
}
