/*
 * Constrained edges and straight walks in the triangulation of mesh/cdt.h.
 *
 * Segment insertion (qk__cdt_insert_segment) first traces ab from a, triangle by triangle,
 * recording the triangles it crosses and refusing (before any change) a vertex on ab or a
 * constrained edge across it. The crossed triangles form a cavity that ab cuts into two
 * pseudo-polygons; each is retriangulated by its constrained Delaunay triangulation in the
 * cavity's triangle slots (same count: k crossed edges, k + 1 triangles either way), and
 * the result is the constrained Delaunay triangulation with ab (outside the cavity nothing
 * changes: Shewchuk and Brown, "Fast segment insertion and incremental construction of
 * constrained Delaunay triangulations", 2015, give the theorem). No flip order to prove
 * terminating, and the work is bounded by the cavity's size squared (linear in practice).
 *
 * A cavity's boundary may touch itself: an edge inside the cavity with both ends on one side
 * of ab (both triangles on it are crossed) appears on the chain twice, once each way (a
 * slit). Such an edge is kept through the retriangulation (its two sides linked to each
 * other) and the cavity's edges are then flipped by the in-circle test until all are
 * locally Delaunay. Should the plan of a cavity fail its checks (an apex not strictly left
 * of its base; never seen), segment insertion falls back to flips (insert_by_flips).
 */
#include "mesh/cdt_internal.h"

#define NONE QK__CDT_NONE
#define pt qk__cdt_pt
#define along qk__cdt_along

/* Set the segment id of edge k of t on both its sides. */
static void mark(qk__cdt_t *c, uint32_t t, int k, uint32_t seg) {
  c->seg[3 * (size_t)t + k] = seg;
  if (c->on_change) c->on_change(c->user, t);
  uint32_t n = c->nbr[3 * (size_t)t + k];
  if (n == NONE) return;
  const uint32_t *nn = c->nbr + 3 * (size_t)n;
  int j = nn[0] == t ? 0 : nn[1] == t ? 1 : 2;
  c->seg[3 * (size_t)n + j] = seg;
  if (c->on_change) c->on_change(c->user, n);
}

void qk__cdt_mark_segment(qk__cdt_t *c, uint32_t t, int k, uint32_t seg) { mark(c, t, k, seg); }

/* Trace ab from a through the triangles it crosses, T_0 (at a) .. T_k (at b). Each gets a
 * record of REC words in c->scr: its id, the slot of its edge on the left chain (the
 * region's boundary left of a -> b; 3 if none), the same on the right, its vertex opposite
 * the edge it was entered by (NONE for T_0), and the left and right ends of the edge it is
 * left by (NONE for T_k). Returns k + 1, or -1 with *st set (NOMEM, or GEOMETRY with
 * *block and *block_seg). Changes nothing but the scratch. */
#define REC 6

int qk__cdt_test_flips = 0;
static long trace(qk__cdt_t *c, uint32_t a, uint32_t b, qk_status_t *st, uint32_t *block,
                  uint32_t *block_seg) {
  const double *pa = pt(c, a), *pb = pt(c, b);
  qk__cdt_ring_t r = {a, NONE, NONE, 1};
  uint32_t t = NONE;
  int i = 0;
  for (uint32_t u = qk__cdt_ring_next(c, &r); u != NONE; u = qk__cdt_ring_next(c, &r)) {
    i = qk__cdt_slot(c, u, a);
    uint32_t x = c->v[3 * (size_t)u + (i + 1) % 3], y = c->v[3 * (size_t)u + (i + 2) % 3];
    int sx = qk__cdt_orient(pa, pb, pt(c, x)), pos;
    if (sx == 0 && along(pa, pb, pt(c, x), &pos)) {
      *block = x; /* x == b would be the edge ab, handled by the caller */
      *st = QK_ERR_GEOMETRY;
      return -1;
    }
    if (sx < 0 && qk__cdt_orient(pa, pb, pt(c, y)) > 0) {
      t = u;
      break;
    }
  }
  if (t == NONE) { /* cannot happen in a valid triangulation */
    *block = a;
    *st = QK_ERR_GEOMETRY;
    return -1;
  }
  /* T_0 = (a, x, y): the edge opposite a crosses ab, y is left and x right of a -> b. */
  long n = 0;
  uint32_t left = c->v[3 * (size_t)t + (i + 2) % 3], right = c->v[3 * (size_t)t + (i + 1) % 3];
  uint32_t ls = (uint32_t)(i + 1) % 3, rs = (uint32_t)(i + 2) % 3, apex = NONE;
  int k = i;
  for (;;) {
    if (qk__cdt_reserve_scratch(c, REC * ((size_t)n + 1)) != QK_OK) {
      *st = QK_ERR_NOMEM;
      return -1;
    }
    uint32_t *rec = c->scr + REC * n;
    rec[0] = t, rec[1] = ls, rec[2] = rs, rec[3] = apex, rec[4] = left, rec[5] = right;
    n++;
    if (k < 0) return n;
    uint32_t s = c->seg[3 * (size_t)t + k];
    if (s != NONE) {
      *block = left, *block_seg = s;
      *st = QK_ERR_GEOMETRY;
      return -1;
    }
    uint32_t nt = c->nbr[3 * (size_t)t + k];
    const uint32_t *nn = c->nbr + 3 * (size_t)nt;
    int j = nn[0] == t ? 0 : nn[1] == t ? 1 : 2;
    t = nt;
    /* t = (o, l, r) from slot j, entered through l -> r: its left chain edge is o-l (slot
     * j + 2), its right one r-o (slot j + 1) */
    uint32_t o = c->v[3 * (size_t)t + j];
    apex = o;
    if (o == b) {
      ls = (uint32_t)(j + 2) % 3, rs = (uint32_t)(j + 1) % 3;
      left = right = NONE, k = -1;
      continue;
    }
    int so = qk__cdt_orient(pa, pb, pt(c, o));
    if (so == 0) {
      *block = o;
      *st = QK_ERR_GEOMETRY;
      return -1;
    }
    if (so > 0) /* o is left: leave through r-o */
      left = o, k = (j + 1) % 3, ls = (uint32_t)(j + 2) % 3, rs = 3;
    else /* o is right: leave through o-l */
      right = o, k = (j + 2) % 3, ls = 3, rs = (uint32_t)(j + 1) % 3;
  }
}

/* Whether triangle t is among the sorted ids sp[0..n). */
static int in_pool(const uint32_t *sp, long n, uint32_t t) {
  long lo = 0, hi = n;
  while (lo < hi) {
    long mid = (lo + hi) / 2;
    if (sp[mid] < t)
      lo = mid + 1;
    else
      hi = mid;
  }
  return lo < n && sp[lo] == t;
}

static void sort_ids(uint32_t *x, long n) {
  for (long gap = n / 2; gap > 0; gap /= 2)
    for (long i = gap; i < n; i++) {
      uint32_t v = x[i];
      long j = i;
      for (; j >= gap && x[j - gap] > v; j -= gap) x[j] = x[j - gap];
      x[j] = v;
    }
}

/* Flip the unconstrained edges between triangles of the cavity (ids sorted in sp[0..nr))
 * by the in-circle test until none changes (Lawson): flips keep both triangles' ids, so the
 * pass stays in the cavity. */
static void lawson_pool(qk__cdt_t *c, const uint32_t *sp, long nr) {
  for (int again = 1; again;) {
    again = 0;
    for (long m = 0; m < nr; m++)
      for (int i = 0; i < 3; i++) {
        uint32_t e = sp[m], n = c->nbr[3 * (size_t)e + i];
        if (n == NONE || c->seg[3 * (size_t)e + i] != NONE || !in_pool(sp, nr, n)) continue;
        const uint32_t *nn = c->nbr + 3 * (size_t)n;
        int j = nn[0] == e ? 0 : nn[1] == e ? 1 : 2;
        const uint32_t *ev = c->v + 3 * (size_t)e;
        if (qk__cdt_incircle(pt(c, ev[0]), pt(c, ev[1]), pt(c, ev[2]),
                             pt(c, c->v[3 * (size_t)n + j])) <= 0)
          continue;
        qk__cdt_flip(c, e, i, n, j);
        again = 1;
      }
  }
}

/* For the crossing edge u-w: its triangle e (edge slot *i), the one across (n, slot *j), the
 * two apexes, and whether the quad is strictly convex (then it can be flipped). */
static int quad(const qk__cdt_t *c, uint32_t u, uint32_t w, uint32_t *e, int *i, uint32_t *n,
                int *j, uint32_t *p, uint32_t *s) {
  *e = qk__cdt_find_edge(c, u, w, i);
  *n = c->nbr[3 * (size_t)*e + *i];
  const uint32_t *nn = c->nbr + 3 * (size_t)*n;
  *j = nn[0] == *e ? 0 : nn[1] == *e ? 1 : 2;
  *p = c->v[3 * (size_t)*e + *i], *s = c->v[3 * (size_t)*n + *j];
  /* e = (p, u, w), n = (s, w, u): convex when u is right of p -> s and w left */
  return qk__cdt_orient(pt(c, *p), pt(c, *s), pt(c, u)) < 0 &&
         qk__cdt_orient(pt(c, *p), pt(c, *s), pt(c, w)) > 0;
}

/*
 * The fallback for cavities whose boundary touches itself (an edge inside the cavity with
 * both ends on one side of ab, so a vertex appears twice on a chain): remove the crossing
 * edges by flips, each time one whose quad is strictly convex and whose new diagonal does
 * not cross ab (Hanke, Ottmann and Schuierer, "The edge-flipping distance of
 * triangulations", 1996: such a flip always exists, so k crossing edges go in exactly k
 * flips; found by a scan, O(k^2) in all, and this path is rare). Should the scan find none,
 * any convex one is flipped (Sloan's rule) so that nothing stalls. Then ab is marked and
 * the cavity's unconstrained edges are flipped by the in-circle test until none changes
 * (Lawson). Flips keep the cavity's triangle ids (sorted in sp), so both passes stay in it.
 */
static qk_status_t insert_by_flips(qk__cdt_t *c, uint32_t a, uint32_t b, uint32_t seg,
                                   const uint32_t *rec, long nr, const uint32_t *sp,
                                   uint32_t *queue) {
  const double *pa = pt(c, a), *pb = pt(c, b);
  long count = nr - 1;
  for (long m = 0; m < count; m++)
    queue[2 * m] = rec[REC * m + 4], queue[2 * m + 1] = rec[REC * m + 5];
  long rot = 0; /* where the last scan for a convex quad began (Sloan's queue order) */
  while (count > 0) {
    long any = -1;
    int done = 0;
    for (long m = 0; m < count && !done; m++) {
      uint32_t e, n, p, s;
      int i, j;
      if (!quad(c, queue[2 * m], queue[2 * m + 1], &e, &i, &n, &j, &p, &s)) continue;
      if (any < 0 || (any < rot && m >= rot)) any = m;
      if (qk__cdt_orient(pa, pb, pt(c, p)) * qk__cdt_orient(pa, pb, pt(c, s)) >= 0) {
        qk__cdt_flip(c, e, i, n, j); /* one crossing fewer */
        count--;
        queue[2 * m] = queue[2 * count], queue[2 * m + 1] = queue[2 * count + 1];
        done = 1;
      }
    }
    if (done) continue;
    if (any < 0) return QK_ERR_CORRUPT; /* no convex quad: not a valid triangulation */
    rot = any + 1 < count ? any + 1 : 0;
    uint32_t e, n, p, s;
    int i, j;
    quad(c, queue[2 * any], queue[2 * any + 1], &e, &i, &n, &j, &p, &s);
    qk__cdt_flip(c, e, i, n, j); /* Sloan's rule: the new diagonal still crosses ab */
    queue[2 * any] = p, queue[2 * any + 1] = s;
  }
  int k;
  uint32_t t = qk__cdt_find_edge(c, a, b, &k);
  mark(c, t, k, seg);
  lawson_pool(c, sp, nr);
  c->hint = t;
  return QK_OK;
}

/* Point the link of triangle x (outside the cavity) across its edge u-w at t. */
static void link_outside(qk__cdt_t *c, uint32_t x, uint32_t u, uint32_t w, uint32_t t) {
  if (x == NONE) return;
  int k = 3 - qk__cdt_slot(c, x, u) - qk__cdt_slot(c, x, w);
  c->nbr[3 * (size_t)x + k] = t;
}

/* One chain of the cavity's boundary, from a to b or reversed: n vertices p, and for each
 * edge m (p[m] -> p[m + 1]) the triangle nb outside it, its segment id sg, the cavity
 * triangle own it belonged to, its partner (the same edge the other way round when it lies
 * inside the cavity: a slit; NONE otherwise), and the new triangle and slot on it. */
typedef struct chain {
  uint32_t n, *p, *nb, *sg, *own, *partner, *newt, *news;
} chain_t;

/*
 * Plan the constrained Delaunay triangulation of the pseudo-polygon of chain h (the polygon
 * lies left of p[0] -> p[n-1]): on the base p[i] -> p[j], the apex is the vertex between
 * them whose circle with the base holds no other (one pass: the circles through two points
 * are nested on one side of them), then the same on p[i] -> p[m] and p[m] -> p[j]
 * (Anglada's algorithm, as in Shewchuk's notes on segment insertion). A vertex that appears
 * twice on the chain (a slit's end) is never the apex of a base it ends. Triangles go to
 * out as (i, j, m, parent, slot in parent), parents first; returns their count, or -1 when
 * a base has no apex or an apex is not strictly left of its base (never for a cavity whose
 * boundary is simple; then the caller falls back to flips). stk has room for 4n words.
 */
static long plan(const qk__cdt_t *c, const chain_t *h, uint32_t *out, uint32_t *stk) {
  const uint32_t *p = h->p;
  long nt = 0;
  uint32_t sp = 1;
  stk[0] = 0, stk[1] = h->n - 1, stk[2] = NONE, stk[3] = 0;
  while (sp > 0) {
    sp--;
    uint32_t i = stk[4 * sp], j = stk[4 * sp + 1], par = stk[4 * sp + 2], ps = stk[4 * sp + 3];
    uint32_t m = NONE;
    for (uint32_t q = i + 1; q < j; q++) {
      if (p[q] == p[i] || p[q] == p[j]) continue;
      if (m == NONE || qk__cdt_incircle(pt(c, p[i]), pt(c, p[j]), pt(c, p[m]), pt(c, p[q])) > 0)
        m = q;
    }
    if (m == NONE || qk__cdt_orient(pt(c, p[i]), pt(c, p[j]), pt(c, p[m])) <= 0) return -1;
    uint32_t *o = out + 5 * nt;
    o[0] = i, o[1] = j, o[2] = m, o[3] = par, o[4] = ps;
    if (m > i + 1)
      stk[4 * sp] = i, stk[4 * sp + 1] = m, stk[4 * sp + 2] = (uint32_t)nt, stk[4 * sp + 3] = 1,
              sp++;
    if (j > m + 1)
      stk[4 * sp] = m, stk[4 * sp + 1] = j, stk[4 * sp + 2] = (uint32_t)nt, stk[4 * sp + 3] = 0,
              sp++;
    nt++;
  }
  return nt;
}

/* Give chain edge e of h the new triangle t (slot k): link it to the triangle outside, or,
 * for a slit, to the new triangle on the other side once both exist. */
static void chain_link(qk__cdt_t *c, chain_t *h, uint32_t e, uint32_t t, int k) {
  c->nbr[3 * (size_t)t + k] = NONE, c->seg[3 * (size_t)t + k] = h->sg[e];
  if (h->partner[e] == NONE) {
    c->nbr[3 * (size_t)t + k] = h->nb[e];
    link_outside(c, h->nb[e], h->p[e], h->p[e + 1], t);
    return;
  }
  h->newt[e] = t, h->news[e] = (uint32_t)k;
  uint32_t f = h->partner[e];
  if (h->newt[f] != NONE) {
    c->nbr[3 * (size_t)t + k] = h->newt[f];
    c->nbr[3 * (size_t)h->newt[f] + h->news[f]] = t;
  }
}

/* Write the planned triangles into the ids pool[*used ..]; returns the one on the base
 * p[0] -> p[n-1] (slot 2, its link across left NONE). */
static uint32_t write_plan(qk__cdt_t *c, chain_t *h, const uint32_t *plan, long nt,
                           const uint32_t *pool, uint32_t *used) {
  const uint32_t *p = h->p, *ids = pool + *used;
  for (long k = 0; k < nt; k++) {
    const uint32_t *o = plan + 5 * k;
    uint32_t i = o[0], j = o[1], m = o[2], t = ids[k];
    uint32_t *tv = c->v + 3 * (size_t)t, *tn = c->nbr + 3 * (size_t)t, *ts = c->seg + 3 * (size_t)t;
    tv[0] = p[i], tv[1] = p[j], tv[2] = p[m];
    tn[0] = tn[1] = tn[2] = NONE, ts[0] = ts[1] = ts[2] = NONE;
    if (o[3] != NONE) {
      uint32_t par = ids[o[3]];
      tn[2] = par, c->nbr[3 * (size_t)par + o[4]] = t;
    }
    if (m == i + 1) chain_link(c, h, i, t, 1); /* edge p[m] -> p[i] */
    if (j == m + 1) chain_link(c, h, m, t, 0); /* edge p[j] -> p[m] */
    c->vtri[p[i]] = t, c->vtri[p[j]] = t, c->vtri[p[m]] = t;
  }
  *used += (uint32_t)nt;
  return ids[0];
}

qk_status_t qk__cdt_insert_segment(qk__cdt_t *c, uint32_t a, uint32_t b, uint32_t seg,
                                   uint32_t *block, uint32_t *block_seg) {
  *block = NONE, *block_seg = NONE;
  if (a == b || a >= c->nv || b >= c->nv) {
    *block = a;
    return QK_ERR_GEOMETRY;
  }
  int k;
  uint32_t t = qk__cdt_find_edge(c, a, b, &k);
  if (t != NONE) {
    uint32_t old = c->seg[3 * (size_t)t + k];
    if (old != NONE && old != seg) {
      *block = a, *block_seg = old;
      return QK_ERR_GEOMETRY;
    }
    mark(c, t, k, seg);
    return QK_OK;
  }
  qk_status_t st = QK_OK;
  long nr = trace(c, a, b, &st, block, block_seg);
  if (nr < 0) return st;
  /* Room for the records, the pool of triangle ids and its sorted copy, both chains (at
   * most nr + 1 vertices each, eight arrays), the plans (five words a triangle) and the
   * stack (or the fallback's queue). */
  size_t w = (size_t)nr + 2;
  if (qk__cdt_reserve_scratch(c, (REC + 2 + 5) * (size_t)nr + 16 * w + 4 * w) != QK_OK)
    return QK_ERR_NOMEM;
  uint32_t *rec = c->scr, *pool = rec + REC * nr, *sp = pool + nr, *q = sp + nr;
  chain_t ch[2];
  for (int h = 0; h < 2; h++) {
    ch[h].n = 0;
    ch[h].p = q, ch[h].nb = q + w, ch[h].sg = q + 2 * w, ch[h].own = q + 3 * w;
    ch[h].partner = q + 4 * w, ch[h].newt = q + 5 * w, ch[h].news = q + 6 * w;
    q += 8 * w;
  }
  uint32_t *plans = q, *stk = plans + 5 * nr;
  for (long m = 0; m < nr; m++) pool[m] = sp[m] = rec[REC * m];
  sort_ids(sp, nr);
  /* The chains from a to b: T_0 = (a, x, y) gives y (left, chain 0) and x (right, 1). */
  {
    const uint32_t *tv = c->v + 3 * (size_t)rec[0];
    int i = qk__cdt_slot(c, rec[0], a);
    ch[0].p[0] = a, ch[0].p[1] = tv[(i + 2) % 3];
    ch[1].p[0] = a, ch[1].p[1] = tv[(i + 1) % 3];
    ch[0].n = ch[1].n = 2;
  }
  int slits = 0;
  for (long m = 0; m < nr; m++) {
    uint32_t tri = rec[REC * m], o = rec[REC * m + 3];
    for (int h = 0; h < 2; h++) {
      uint32_t slot = rec[REC * m + 1 + h];
      if (slot == 3) continue;
      chain_t *H = &ch[h];
      uint32_t e = m > 0 ? H->n - 1 : 0;
      if (m > 0) H->p[H->n++] = o;
      H->nb[e] = c->nbr[3 * (size_t)tri + slot], H->sg[e] = c->seg[3 * (size_t)tri + slot];
      H->own[e] = tri, H->partner[e] = NONE, H->newt[e] = NONE;
      slits |= H->nb[e] != NONE && in_pool(sp, nr, H->nb[e]);
    }
  }
  /* The right polygon lies left of b -> a: reverse its chain. */
  {
    chain_t *H = &ch[1];
    uint32_t n = H->n, ne = n - 1;
    for (uint32_t m = 0; m < n / 2; m++) {
      uint32_t x = H->p[m];
      H->p[m] = H->p[n - 1 - m], H->p[n - 1 - m] = x;
    }
    for (uint32_t m = 0; m < ne / 2; m++) {
      uint32_t *arr[3] = {H->nb, H->sg, H->own};
      for (int z = 0; z < 3; z++) {
        uint32_t x = arr[z][m];
        arr[z][m] = arr[z][ne - 1 - m], arr[z][ne - 1 - m] = x;
      }
    }
  }
  /* Slits: a chain edge whose outside is a cavity triangle pairs with the same edge the
   * other way round, owned by that triangle (rare: a linear search). */
  if (slits)
    for (int h = 0; h < 2; h++)
      for (uint32_t e = 0; e + 1 < ch[h].n; e++) {
        if (ch[h].nb[e] == NONE || !in_pool(sp, nr, ch[h].nb[e])) continue;
        for (uint32_t f = 0; f + 1 < ch[h].n; f++)
          if (ch[h].own[f] == ch[h].nb[e] && ch[h].p[f] == ch[h].p[e + 1] &&
              ch[h].p[f + 1] == ch[h].p[e])
            ch[h].partner[e] = f;
        if (ch[h].partner[e] == NONE) return insert_by_flips(c, a, b, seg, rec, nr, sp, stk);
      }
  if (qk__cdt_test_flips) return insert_by_flips(c, a, b, seg, rec, nr, sp, stk);
  long n0 = plan(c, &ch[0], plans, stk);
  long n1 = n0 < 0 ? -1 : plan(c, &ch[1], plans + 5 * n0, stk);
  if (n1 < 0 || n0 + n1 != nr) return insert_by_flips(c, a, b, seg, rec, nr, sp, stk);
  uint32_t used = 0;
  uint32_t tl = write_plan(c, &ch[0], plans, n0, pool, &used);
  uint32_t tr = write_plan(c, &ch[1], plans + 5 * n0, n1, pool, &used);
  c->nbr[3 * (size_t)tl + 2] = tr, c->seg[3 * (size_t)tl + 2] = seg;
  c->nbr[3 * (size_t)tr + 2] = tl, c->seg[3 * (size_t)tr + 2] = seg;
  if (slits) lawson_pool(c, sp, nr); /* the slits were kept as edges: flip them if need be */
  if (c->on_change)
    for (uint32_t m = 0; m < used; m++) c->on_change(c->user, pool[m]);
  c->hint = tl;
  return QK_OK;
}
