/*
 * The top levels of the refinement in one pass over the pieces.
 *
 * Sorting the pieces level by level from the root (refine.c) handles every piece once
 * per level above its leaf, and on real layers most of that work is in the top levels,
 * which every piece crosses. Here the cells of the first k levels (the complete quadtree
 * down to a 2^k x 2^k grid, about one grid cell per piece) are made in one pass:
 *
 *  - Lists. A piece's box is located in the grid by scaling and an exact correction
 *    against the grid lines, which are the cells' sides exactly as the refinement
 *    computes them. Its *home* is the deepest top cell whose open square holds the box.
 *    Above its home the level-by-level sort would send the piece to one child at each
 *    level (its box is off every centre line there, since those are grid lines outside
 *    the box), so it is only counted at its home. From a home above level k (a piece
 *    across grid lines: few) it is clipped down with the refinement's own test
 *    (qk__clip4). A cell's piece count is then the homes in its subtree plus the clipped
 *    pieces that reach it, and each grid cell's list, in piece order, comes from a
 *    counting sort.
 *  - Sets. The features containing each grid cell's centre are found by a walk: along
 *    column 0, then along every row, from centre to centre through the midpoint of the
 *    side between them. Each half of a step lies in one cell's closed square, so only
 *    that cell's pieces can cross it, and only those whose box reaches the step's line:
 *    few. The first centre is classified by a half-open ray to the west, which only its
 *    cell's pieces can cross. A leaf above
 *    level k has its centre at the corner of a grid cell: its set is that cell's with
 *    the crossings of the half diagonal between them.
 *
 * Then the cells are visited depth first from the root making the decisions of the
 * refinement (split while more than C pieces meet the cell, the stall rule, the budget of
 * splits) from the counts alone; a grid cell hands its list and set to qk__build_node,
 * and a leaf above level k gathers its pieces from its grid cells (and the clipped pieces
 * that stopped inside it). Every decision and list is the one the sort from the root
 * would make, and the sets are exact, so the index is the same, cell for cell.
 */
#include <stdlib.h>
#include <string.h>

#include "region/region_internal.h"

#define TOP_MAX 10 /* deepest one-pass level: 4^10 cells */
#define CLIPPED UINT32_MAX

typedef struct top {
  qk__bctx_t *b;
  const qk_allocator_t *a;
  unsigned k;
  size_t g;                  /* 2^k */
  double *gx, *gy;           /* g + 1 grid lines each: the cells' sides */
  double scale;              /* g / root side */
  double lside[TOP_MAX + 1]; /* a cell's side at each level */
  double hk;                 /* half a grid cell's side: a centre is gx[i] + hk */
  size_t off[TOP_MAX + 2];   /* cell (l, i, j) is number off[l] + (j << l | i) */
  uint32_t *home;            /* per cell: pieces at home in it, then summed over its subtree */
  uint32_t *reach;           /* per cell: clipped pieces reaching it from above */
  uint32_t *pcell;           /* per piece: its home's grid cell, or CLIPPED */
  uint32_t *pair;            /* (grid cell, piece) of clipped pieces, in piece order */
  size_t n_pair, cap_pair;
  uint32_t *stub; /* (cell number, piece): clipped pieces that reach no child */
  size_t n_stub, cap_stub;
  uint32_t *cstart; /* grid cell c's pieces: list[cstart[c], cstart[c + 1]) */
  uint32_t *list;
  uint32_t *cset; /* grid cell c's set: pool[cset[c]] features at pool + cset[c] + 1 */
  uint32_t *pool;
  size_t n_pool, cap_pool;
  uint32_t *s, *u, *oa, *ob, *oe; /* the walk's set, scratch, crossing lists */
  size_t cap_s, cap_u, cap_oa, cap_ob, cap_oe;
  uint32_t *gather; /* a leaf above level k: its pieces */
  size_t cap_gather;
} top_t;

static qk_status_t push2(const qk_allocator_t *a, uint32_t **v, size_t *n, size_t *cap, uint32_t x,
                         uint32_t y) {
  qk_status_t st;
  if (2 * *n + 2 > *cap && (st = qk__grow(a, (void **)v, cap, 2 * *n + 2, sizeof(uint32_t))))
    return st;
  (*v)[2 * *n] = x;
  (*v)[2 * *n + 1] = y;
  ++*n;
  return QK_OK;
}

/* ---- lists ------------------------------------------------------------------------- */

/* Column i with gx[i] < x <= gx[i + 1] (gx[0] < x <= gx[g]). */
static inline size_t col_lo(const double *gx, size_t g, double r0, double scale, double x) {
  /* (x > r0 and x < the root's end: 0 <= guess <= g, converted through int64_t, one
   * instruction, where a size_t conversion takes a branch and several) */
  size_t i = (size_t)(int64_t)((x - r0) * scale);
  if (i >= g) i = g - 1;
  while (i > 0 && gx[i] >= x) i--;
  while (i + 1 < g && gx[i + 1] < x) i++;
  return i;
}

/* Column i with gx[i] <= x < gx[i + 1] (gx[0] < x < gx[g]). */
static inline size_t col_hi(const double *gx, size_t g, double r0, double scale, double x) {
  size_t i = (size_t)(int64_t)((x - r0) * scale); /* (as col_lo) */
  if (i >= g) i = g - 1;
  while (i > 0 && gx[i] > x) i--;
  while (i + 1 < g && gx[i + 1] <= x) i++;
  return i;
}

/* Clip piece p, which meets cell (l, i, j), into the cells below it. */
static qk_status_t clip(top_t *t, uint32_t p, const qk__seg_t *g, double lx, double hx, double ly,
                        double hy, unsigned l, size_t i, size_t j) {
  if (l == t->k) return push2(t->a, &t->pair, &t->n_pair, &t->cap_pair, (uint32_t)(j << l | i), p);
  unsigned sh = t->k - l;
  double x0 = t->gx[i << sh], x1 = t->gx[(i + 1) << sh];
  double y0 = t->gy[j << sh], y1 = t->gy[(j + 1) << sh];
  double h = t->lside[l] * 0.5, cx = x0 + h, cy = y0 + h;
  unsigned m = qk__clip4(g, lx, hx, ly, hy, x0, y0, x1, y1, cx, cy);
  if (!m)
    return push2(t->a, &t->stub, &t->n_stub, &t->cap_stub, (uint32_t)(t->off[l] + (j << l | i)), p);
  qk_status_t st;
  for (unsigned q = 0; q < 4; q++) {
    if (!(m >> q & 1)) continue;
    size_t ci = 2 * i + qk__q_east(q), cj = 2 * j + qk__q_north(q);
    t->reach[t->off[l + 1] + (cj << (l + 1) | ci)]++;
    if ((st = clip(t, p, g, lx, hx, ly, hy, l + 1, ci, cj))) return st;
  }
  return QK_OK;
}

/* Every piece's home; the pieces across grid lines clipped from there. */
static qk_status_t place_pieces(top_t *t) {
  const qk__pieces_t *pc = t->b->pc;
  const qk_region_t *r = t->b->r;
  const unsigned k = t->k;
  const size_t g = t->g;
  qk_status_t st;
  for (size_t p = 0; p < pc->n; p++) {
    const qk__seg_t *s = &pc->seg[p];
    double lx = qk__min(s->ax, s->bx), hx = qk__max(s->ax, s->bx);
    double ly = qk__min(s->ay, s->by), hy = qk__max(s->ay, s->by);
    size_t i0 = col_lo(t->gx, g, r->rx, t->scale, lx);
    size_t j0 = col_lo(t->gy, g, r->ry, t->scale, ly);
    if (hx < t->gx[i0 + 1] && hy < t->gy[j0 + 1]) { /* inside one grid cell: most pieces */
      t->home[t->off[k] + (j0 << k | i0)]++;
      t->pcell[p] = (uint32_t)(j0 << k | i0);
      continue;
    }
    size_t i1 = col_hi(t->gx, g, r->rx, t->scale, hx);
    size_t j1 = col_hi(t->gy, g, r->ry, t->scale, hy);
    unsigned l = k;
    for (size_t diff = (i0 ^ i1) | (j0 ^ j1); diff; diff >>= 1) l--;
    size_t i = i0 >> (k - l), j = j0 >> (k - l);
    t->home[t->off[l] + (j << l | i)]++;
    t->pcell[p] = CLIPPED;
    if ((st = clip(t, (uint32_t)p, s, lx, hx, ly, hy, l, i, j))) return st;
  }
  return QK_OK;
}

/* The grid cells' lists (a counting sort, in piece order) and the subtree sums of the
 * home counts. */
static void sort_lists(top_t *t) {
  const unsigned k = t->k;
  const size_t nc = t->g * t->g, n = t->b->pc->n;
  const uint32_t *hk = t->home + t->off[k], *rk = t->reach + t->off[k];
  uint32_t *cs = t->cstart;
  size_t sum = 0;
  for (size_t c = 0; c < nc; c++) sum += hk[c] + rk[c], cs[c] = (uint32_t)sum;
  cs[nc] = (uint32_t)sum;
  /* backwards, so that each list comes out in piece order and cs[c] ends at its start */
  size_t q = t->n_pair;
  for (size_t p = n; p-- > 0;) {
    if (t->pcell[p] != CLIPPED) {
      t->list[--cs[t->pcell[p]]] = (uint32_t)p;
      continue;
    }
    while (q > 0 && t->pair[2 * q - 1] == p) q--, t->list[--cs[t->pair[2 * q]]] = (uint32_t)p;
  }
  for (unsigned l = k; l-- > 0;) {
    uint32_t *up = t->home + t->off[l], *dn = t->home + t->off[l + 1];
    size_t w = (size_t)1 << l;
    for (size_t j = 0; j < w; j++)
      for (size_t i = 0; i < w; i++) {
        const uint32_t *d0 = dn + ((2 * j) << (l + 1)) + 2 * i, *d1 = d0 + ((size_t)2 << l);
        up[j << l | i] += d0[0] + d0[1] + d1[0] + d1[1];
      }
  }
}

/* ---- sets -------------------------------------------------------------------------- */

/* Features crossed an odd number of times by the segment o -> q inside grid cell c (its
 * pieces come in feature order), into *out (grown to the cell's count). */
static qk_status_t cell_odd(top_t *t, size_t c, double ox, double oy, double qx, double qy,
                            uint32_t **out, size_t *cap, size_t *n_out) {
  const qk__pieces_t *pc = t->b->pc;
  const uint32_t *E = t->list + t->cstart[c];
  size_t n = t->cstart[c + 1] - t->cstart[c], k = 0;
  *n_out = 0;
  if (!n) return QK_OK;
  qk_status_t st;
  if ((st = qk__grow(t->a, (void **)out, cap, n, sizeof(uint32_t)))) return st;
  uint32_t *o = *out;
  for (size_t i = 0; i < n; i++) {
    const qk__seg_t *g = &pc->seg[E[i]];
    double lx = qk__min(g->ax, g->bx), hx = qk__max(g->ax, g->bx);
    double ly = qk__min(g->ay, g->by), hy = qk__max(g->ay, g->by);
    if (!qk__ref_crosses(ox, oy, qx, qy, g, lx, hx, ly, hy)) continue;
    uint32_t f = pc->feat[E[i]];
    if (k && o[k - 1] == f)
      k--; /* crossed twice so far: even */
    else
      o[k++] = f;
  }
  *n_out = k;
  return QK_OK;
}

/* t->s = t->s with the sorted features odd[0, n) toggled (through t->u). */
static qk_status_t toggle(top_t *t, size_t *ns, const uint32_t *odd, size_t n) {
  if (!n) return QK_OK;
  qk_status_t st;
  if ((st = qk__grow(t->a, (void **)&t->u, &t->cap_u, *ns + n + 1, sizeof(uint32_t)))) return st;
  const uint32_t *S = t->s;
  uint32_t *T = t->u;
  size_t i = 0, j = 0, k = 0;
  while (i < *ns || j < n) {
    if (j == n || (i < *ns && S[i] < odd[j]))
      T[k++] = S[i++];
    else if (i == *ns || odd[j] < S[i])
      T[k++] = odd[j++];
    else
      i++, j++;
  }
  uint32_t *w = t->s;
  size_t cw = t->cap_s;
  t->s = t->u, t->cap_s = t->cap_u;
  t->u = w, t->cap_u = cw;
  *ns = k;
  return QK_OK;
}

/* Record the walk's set as grid cell c's. */
static qk_status_t keep_set(top_t *t, size_t c, size_t ns) {
  qk_status_t st;
  if ((st = qk__grow(t->a, (void **)&t->pool, &t->cap_pool, t->n_pool + ns + 1, sizeof(uint32_t))))
    return st;
  if (t->n_pool + ns + 1 >= UINT32_MAX) return QK_ERR_LIMIT;
  t->cset[c] = (uint32_t)t->n_pool;
  t->pool[t->n_pool] = (uint32_t)ns;
  memcpy(t->pool + t->n_pool + 1, t->s, ns * sizeof(uint32_t));
  t->n_pool += ns + 1;
  return QK_OK;
}

/* The features containing the centre (cx, cy) of grid cell 0, from the half-open ray to
 * the west: inside the root it runs in cell 0's closed square, and no piece lies outside
 * the root, so only cell 0's pieces can cross it. (The perturbed point is above a vertex
 * exactly when the vertex is not above cy; an edge across its line is crossed on the
 * west side when the point is on the other side than for the ray to the east.) */
static qk_status_t first_set(top_t *t, double cx, double cy, size_t *ns) {
  const qk__pieces_t *pc = t->b->pc;
  const uint32_t *E = t->list + t->cstart[0];
  size_t n = t->cstart[1] - t->cstart[0], k = 0;
  qk_status_t st = qk__grow(t->a, (void **)&t->s, &t->cap_s, n + 1, sizeof(uint32_t));
  if (st) return st;
  for (size_t i = 0; i < n; i++) {
    const qk__seg_t *g = &pc->seg[E[i]];
    if ((g->ay > cy) == (g->by > cy)) continue;
    int sd = qk__side(g->ax, g->ay, g->bx, g->by, cx, cy);
    if ((g->by > g->ay) ? sd > 0 : sd < 0) continue; /* crossed to the east */
    uint32_t f = pc->feat[E[i]];
    if (k && t->s[k - 1] == f)
      k--;
    else
      t->s[k++] = f;
  }
  *ns = k;
  return QK_OK;
}

/* The features crossed an odd number of times by the two halves of grid cell c's
 * horizontal line through its centre, (x0, y) -> (xm, y) into t->oa and (xm, y) -> (x1, y)
 * into t->ob: one pass over its pieces, of which only those across the line are tested. */
static qk_status_t row_odds(top_t *t, size_t c, double x0, double xm, double x1, double y,
                            size_t *na, size_t *nb) {
  const qk__pieces_t *pc = t->b->pc;
  const uint32_t *E = t->list + t->cstart[c];
  size_t n = t->cstart[c + 1] - t->cstart[c], ka = 0, kb = 0;
  qk_status_t st;
  if ((st = qk__grow(t->a, (void **)&t->oa, &t->cap_oa, n, sizeof(uint32_t))) ||
      (st = qk__grow(t->a, (void **)&t->ob, &t->cap_ob, n, sizeof(uint32_t))))
    return st;
  uint32_t *oa = t->oa, *ob = t->ob;
  for (size_t i = 0; i < n; i++) {
    const qk__seg_t *g = &pc->seg[E[i]];
    double ly = qk__min(g->ay, g->by), hy = qk__max(g->ay, g->by);
    if (hy < y || ly > y) continue;
    double lx = qk__min(g->ax, g->bx), hx = qk__max(g->ax, g->bx);
    uint32_t f = pc->feat[E[i]];
    if (qk__ref_crosses(x0, y, xm, y, g, lx, hx, ly, hy)) {
      if (ka && oa[ka - 1] == f)
        ka--; /* crossed twice so far: even */
      else
        oa[ka++] = f;
    }
    if (qk__ref_crosses(xm, y, x1, y, g, lx, hx, ly, hy)) {
      if (kb && ob[kb - 1] == f)
        kb--;
      else
        ob[kb++] = f;
    }
  }
  *na = ka;
  *nb = kb;
  return QK_OK;
}

/* Every grid cell's set: column 0 upwards, then each row eastwards, from centre to
 * centre through the midpoint of the side between them. */
static qk_status_t walk(top_t *t) {
  const unsigned k = t->k;
  const size_t g = t->g;
  const double hk = t->hk;
  size_t ns, na, nb;
  qk_status_t st = first_set(t, t->gx[0] + hk, t->gy[0] + hk, &ns);
  for (size_t j = 0; j < g && !st; j++) {
    double cy = t->gy[j] + hk, cx = t->gx[0] + hk;
    if (j) { /* from row j - 1's first centre, which the pool holds */
      const uint32_t *prev = t->pool + t->cset[(j - 1) << k];
      ns = prev[0];
      if ((st = qk__grow(t->a, (void **)&t->s, &t->cap_s, ns + 1, sizeof(uint32_t)))) break;
      memcpy(t->s, prev + 1, ns * sizeof(uint32_t));
      if ((st = cell_odd(t, (j - 1) << k, cx, t->gy[j - 1] + hk, cx, t->gy[j], &t->oa, &t->cap_oa,
                         &na)) ||
          (st = toggle(t, &ns, t->oa, na)) ||
          (st = cell_odd(t, j << k, cx, t->gy[j], cx, cy, &t->oa, &t->cap_oa, &na)) ||
          (st = toggle(t, &ns, t->oa, na)))
        break;
    }
    if ((st = keep_set(t, j << k, ns))) break;
    /* e: the crossings of the east half of the previous cell's line, kept in t->oe */
    size_t ne = 0;
    for (size_t i = 0; i < g && !st; i++) {
      size_t c = j << k | i;
      bool moved = ne > 0;
      if (ne && (st = toggle(t, &ns, t->oe, ne))) break;
      ne = 0;
      if (t->cstart[c + 1] > t->cstart[c]) {
        double xm = t->gx[i] + hk;
        if ((st = row_odds(t, c, t->gx[i], xm, t->gx[i + 1], cy, &na, &nb))) break;
        if (i && na) {
          if ((st = toggle(t, &ns, t->oa, na))) break;
          moved = true;
        }
        if (nb) { /* keep the east half's for the next cell */
          uint32_t *w = t->oe;
          size_t cw = t->cap_oe;
          t->oe = t->ob, t->cap_oe = t->cap_ob;
          t->ob = w, t->cap_ob = cw;
          ne = nb;
        }
      }
      if (!i) continue;
      if (moved)
        st = keep_set(t, c, ns);
      else
        t->cset[c] = t->cset[c - 1]; /* the same set */
    }
  }
  return st;
}

/* ---- the visit --------------------------------------------------------------------- */

/* Pieces meeting cell (l, i, j). */
static inline size_t count(const top_t *t, unsigned l, size_t i, size_t j) {
  size_t w = t->off[l] + (j << l | i);
  return (size_t)t->home[w] + t->reach[w];
}

static int cmp_u32(const void *x, const void *y) {
  uint32_t a = *(const uint32_t *)x, b = *(const uint32_t *)y;
  return a < b ? -1 : a > b;
}

/* The pieces of cell (l, i, j), l < k, into t->gather: its grid cells' and the clipped
 * pieces that stopped inside it, in piece order, each once. */
static qk_status_t gather_cell(top_t *t, unsigned l, size_t i, size_t j, size_t *n_out) {
  unsigned sh = t->k - l, k = t->k;
  size_t n = t->n_stub;
  for (size_t jj = j << sh; jj < (j + 1) << sh; jj++)
    n += t->cstart[(jj << k) + ((i + 1) << sh)] - t->cstart[(jj << k) + (i << sh)];
  qk_status_t st;
  if ((st = qk__grow(t->a, (void **)&t->gather, &t->cap_gather, n + 1, sizeof(uint32_t))))
    return st;
  n = 0;
  for (size_t jj = j << sh; jj < (j + 1) << sh; jj++) {
    size_t c0 = t->cstart[(jj << k) + (i << sh)], c1 = t->cstart[(jj << k) + ((i + 1) << sh)];
    memcpy(t->gather + n, t->list + c0, (c1 - c0) * sizeof(uint32_t));
    n += c1 - c0;
  }
  for (size_t s = 0; s < t->n_stub; s++) {
    unsigned sl = 0;
    while (sl < k && t->stub[2 * s] >= t->off[sl + 1]) sl++;
    if (sl < l) continue; /* above the cell */
    size_t idx = t->stub[2 * s] - t->off[sl];
    size_t si = idx & (((size_t)1 << sl) - 1), sj = idx >> sl;
    if (si >> (sl - l) == i && sj >> (sl - l) == j) t->gather[n++] = t->stub[2 * s + 1];
  }
  qsort(t->gather, n, sizeof(uint32_t), cmp_u32);
  size_t u = 0;
  for (size_t s = 0; s < n; s++)
    if (!u || t->gather[u - 1] != t->gather[s]) t->gather[u++] = t->gather[s];
  *n_out = u;
  return QK_OK;
}

/* b->set[d] = the set of grid cell c, with the features toggled that cross the segment
 * from (ox, oy) to its centre (none when ox is NAN: then the pool's list itself, which
 * stays until the end of the build). */
static qk_status_t set_from_cell(top_t *t, unsigned d, size_t c, double ox, double oy) {
  qk__bctx_t *b = t->b;
  const uint32_t *cs = t->pool + t->cset[c];
  size_t ns = cs[0];
  if (ox != ox) {
    b->set[d] = cs + 1;
    b->ns[d] = ns;
    return QK_OK;
  }
  qk_status_t st;
  if ((st = qk__grow(t->a, (void **)&t->s, &t->cap_s, ns + 1, sizeof(uint32_t)))) return st;
  memcpy(t->s, cs + 1, ns * sizeof(uint32_t));
  size_t k = t->k, i = c & (t->g - 1), j = c >> k, na;
  if ((st = cell_odd(t, c, ox, oy, t->gx[i] + t->hk, t->gy[j] + t->hk, &t->oa, &t->cap_oa, &na)) ||
      (st = toggle(t, &ns, t->oa, na)))
    return st;
  if ((st = qk__grow(t->a, (void **)&b->s[d], &b->cap_s[d], ns + 1, sizeof(uint32_t)))) return st;
  memcpy(b->s[d], t->s, ns * sizeof(uint32_t));
  b->set[d] = b->s[d];
  b->ns[d] = ns;
  return QK_OK;
}

/* Cell (l, i, j), kid[] node v: qk__build_node's decisions from the counts. */
static qk_status_t top_cell(top_t *t, qk_node_t v, unsigned l, size_t i, size_t j, unsigned stall) {
  qk__bctx_t *b = t->b;
  unsigned sh = t->k - l;
  double x0 = t->gx[i << sh], x1 = t->gx[(i + 1) << sh];
  double y0 = t->gy[j << sh], y1 = t->gy[(j + 1) << sh];
  qk_status_t st;
  if (l == t->k) {
    size_t c = j << l | i;
    b->e[l] = t->list + t->cstart[c];
    b->ne[l] = t->cstart[c + 1] - t->cstart[c];
    if ((st = set_from_cell(t, l, c, NAN, NAN))) return st;
    double s = t->lside[l];
    if (!(b->ne[l] > b->C && l < b->maxd && b->splits_left > b->splits_floor)) /* a leaf */
      return qk__emit_leaf(b, v, x0 + s * 0.5, y0 + s * 0.5, l);
    return qk__build_node(b, v, x0, y0, x1, y1, s, l, stall);
  }
  size_t ne = count(t, l, i, j);
  double h = t->lside[l] * 0.5, cx = x0 + h, cy = y0 + h;
  bool split = false;
  size_t cnt[4] = {0, 0, 0, 0};
  if (ne > b->C && l < b->maxd && b->splits_left > b->splits_floor) {
    for (unsigned q = 0; q < 4; q++)
      cnt[q] = count(t, l + 1, 2 * i + qk__q_east(q), 2 * j + qk__q_north(q));
    const bool prog = qk__split_progress(cnt, ne);
    stall = prog ? 0 : stall + 1;
    split = stall <= QK__STALL_BUDGET;
  }
  if (split) {
    uint32_t first = 0;
    if ((st = qk__split_cell(b, v, &first)) == QK_OK) {
      const size_t floor = b->splits_floor; /* (each child's share: as qk__build_node's) */
      for (unsigned q = 0; q < 4; q++) {
        b->splits_floor = qk__child_floor(b, floor, cnt, q);
        st = top_cell(t, first + q, l + 1, 2 * i + qk__q_east(q), 2 * j + qk__q_north(q), stall);
        b->splits_floor = floor;
        if (st) return st;
      }
      return QK_OK;
    }
    if (st != QK_ERR_LIMIT) return st;
  }
  /* The centre is the south-west corner of a grid cell. */
  size_t n = 0, gi = (2 * i + 1) << (sh - 1), gj = (2 * j + 1) << (sh - 1);
  if ((st = set_from_cell(t, l, gj << t->k | gi, cx, cy))) return st;
  if (ne && (st = gather_cell(t, l, i, j, &n))) return st;
  b->e[l] = t->gather;
  b->ne[l] = n;
  return qk__emit_leaf(b, v, cx, cy, l);
}

/* ---- the pass ---------------------------------------------------------------------- */

/* The cells' sides at level k along one axis, as the refinement computes them (a cell's
 * east child starts at its centre x0 + side / 2); false when rounding leaves a grid
 * cell without a centre strictly inside (absurd extents: then k = 0). */
static bool grid_lines(double r0, double r1, double side, unsigned k, double hk, double *out) {
  size_t g = (size_t)1 << k;
  qk__region_grid_sides(r0, side, k, out);
  out[g] = r1;
  for (size_t i = 0; i < g; i++)
    if (!(out[i] < out[i] + hk && out[i] + hk < out[i + 1])) return false;
  return true;
}

qk_status_t qk__build_top(qk__bctx_t *b) {
  qk_region_t *r = b->r;
  const qk_allocator_t *a = &r->alloc;
  const size_t n = b->pc->n;
  top_t t;
  memset(&t, 0, sizeof t);
  t.b = b;
  t.a = a;
  /* k: about one grid cell per piece (measured on Natural Earth layers: fewer leave work
   * to the level-by-level sort, more cost more to sum and walk). */
  unsigned k = 0;
  while (k < TOP_MAX && k < b->maxd && ((size_t)1 << (2 * (k + 1))) <= n) k++;
  /* One block for the arrays of fixed size: the grid lines, then the per-cell counts,
   * lists and sets, and the per-piece homes. */
  size_t nw, nc, bytes;
  char *blk;
  for (;;) {
    t.k = k;
    t.g = (size_t)1 << k;
    t.off[0] = 0;
    for (unsigned l = 0; l <= k; l++) t.off[l + 1] = t.off[l] + ((size_t)1 << (2 * l));
    t.lside[0] = r->rside;
    for (unsigned l = 0; l < k; l++) t.lside[l + 1] = t.lside[l] * 0.5;
    t.hk = t.lside[k] * 0.5;
    nw = t.off[k + 1];
    nc = t.g * t.g;
    bytes = 2 * (t.g + 1) * sizeof(double) + (2 * nw + 2 * nc + n + 2) * sizeof(uint32_t);
    if (!(blk = qk__realloc(a, NULL, 0, bytes))) return QK_ERR_NOMEM;
    t.gx = (double *)blk;
    t.gy = t.gx + t.g + 1;
    if (grid_lines(r->rx, r->rx + r->rside, r->rside, k, t.hk, t.gx) &&
        grid_lines(r->ry, r->ry + r->rside, r->rside, k, t.hk, t.gy))
      break;
    qk__free(a, blk, bytes);
    if (k == 0) return QK_ERR_GEOMETRY; /* (root_square makes a root with a centre) */
    k = 0;
  }
  t.home = (uint32_t *)(t.gy + t.g + 1);
  t.reach = t.home + nw;
  t.cset = t.reach + nw;
  t.cstart = t.cset + nc;
  t.pcell = t.cstart + nc + 1;
  memset(t.home, 0, 2 * nw * sizeof(uint32_t));
  t.scale = (double)t.g / r->rside;
  qk_status_t st = place_pieces(&t);
  size_t total = 0;
  if (!st) {
    for (size_t c = 0; c < nc; c++) total += (size_t)t.home[t.off[k] + c] + t.reach[t.off[k] + c];
    if (total >= UINT32_MAX) st = QK_ERR_LIMIT;
  }
  if (!st && !(t.list = qk__realloc(a, NULL, 0, (total + 1) * sizeof(uint32_t)))) st = QK_ERR_NOMEM;
  if (!st) {
    sort_lists(&t);
    st = walk(&t);
  }
  if (!st) st = top_cell(&t, 0, 0, 0, 0, 0);
  qk__free(a, t.list, t.list ? (total + 1) * sizeof(uint32_t) : 0);
  qk__free(a, t.pair, t.cap_pair * sizeof(uint32_t));
  qk__free(a, t.stub, t.cap_stub * sizeof(uint32_t));
  qk__free(a, t.pool, t.cap_pool * sizeof(uint32_t));
  qk__free(a, t.s, t.cap_s * sizeof(uint32_t));
  qk__free(a, t.u, t.cap_u * sizeof(uint32_t));
  qk__free(a, t.oa, t.cap_oa * sizeof(uint32_t));
  qk__free(a, t.ob, t.cap_ob * sizeof(uint32_t));
  qk__free(a, t.oe, t.cap_oe * sizeof(uint32_t));
  qk__free(a, t.gather, t.cap_gather * sizeof(uint32_t));
  qk__free(a, blk, bytes);
  return st;
}
