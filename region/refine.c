/*
 * The refinement below a cell, level by level: sorting a cell's pieces into its children,
 * the children's sets, and the leaves' records (the design is described at the top of
 * region.c; the top levels are made in one pass by build_top.c).
 */
#include <float.h>
#include <math.h>
#include <string.h>
#if defined(__SSE2__)
#include <emmintrin.h>
#endif

#include "region/region_internal.h"

/* Do two closed segments meet (exactly)? */
static bool segs_meet(const qk__seg_t *p, const qk__seg_t *q) {
  if (qk__max(p->ax, p->bx) < qk__min(q->ax, q->bx) ||
      qk__max(q->ax, q->bx) < qk__min(p->ax, p->bx) ||
      qk__max(p->ay, p->by) < qk__min(q->ay, q->by) ||
      qk__max(q->ay, q->by) < qk__min(p->ay, p->by))
    return false; /* boxes apart: most pairs */
  int o1 = qk__orient(p->ax, p->ay, p->bx, p->by, q->ax, q->ay);
  int o2 = qk__orient(p->ax, p->ay, p->bx, p->by, q->bx, q->by);
  if (o1 * o2 > 0) return false;
  int o3 = qk__orient(q->ax, q->ay, q->bx, q->by, p->ax, p->ay);
  int o4 = qk__orient(q->ax, q->ay, q->bx, q->by, p->bx, p->by);
  if (o3 * o4 > 0) return false;
  if (o1 == 0 && o2 == 0)
    return qk__max(qk__min(p->ax, p->bx), qk__min(q->ax, q->bx)) <=
               qk__min(qk__max(p->ax, p->bx), qk__max(q->ax, q->bx)) &&
           qk__max(qk__min(p->ay, p->by), qk__min(q->ay, q->by)) <=
               qk__min(qk__max(p->ay, p->by), qk__max(q->ay, q->by));
  return true;
}

/* Does the ring turn back on itself at s, from p -> s to s -> q (p, q != s): do p and q lie
 * on one ray from s? Then the two edges overlap beyond their shared vertex. (Same signs of
 * p - s and q - s on both axes, compared exactly, and collinear.) */
static bool doubles_back(double px, double py, double sx, double sy, double qx, double qy) {
  if ((px > sx) != (qx > sx) || (px < sx) != (qx < sx) || (py > sy) != (qy > sy) ||
      (py < sy) != (qy < sy))
    return false;
  return qk__orient(px, py, sx, sy, qx, qy) == 0;
}

/* Is ring edge k (from position k to k + 1 of xy) of zero length? */
static inline bool zero_edge(const double *xy, uint32_t k) {
  return xy[2 * k] == xy[2 * k + 2] && xy[2 * k + 1] == xy[2 * k + 3];
}

/* Do pieces g of ring edge vp and h of ring edge vq (vp < vq, edges rs .. last of one
 * ring) meet away from a vertex they share? Edges are neighbours when only edges of zero
 * length lie between them (the docs: "an edge of zero length is no edge"), one way round
 * the ring (vq follows vp) or the other (vp follows vq); neighbours share a vertex and
 * count only when they overlap beyond it, the ring doubling back. Pieces that do not
 * share the vertex as an end (an edge cut at the antimeridian) count wherever they meet. */
static bool pieces_meet(const double *xy, uint32_t rs, uint32_t last, uint32_t vp, uint32_t vq,
                        const qk__seg_t *g, const qk__seg_t *h) {
  uint32_t k = vp + 1;
  while (k < vq && zero_edge(xy, k)) k++;
  if (k == vq && g->bx == h->ax && g->by == h->ay)
    return doubles_back(g->ax, g->ay, g->bx, g->by, h->bx, h->by);
  for (k = vq + 1; k <= last && zero_edge(xy, k);) k++;
  if (k > last) {
    for (k = rs; k < vp && zero_edge(xy, k);) k++;
    if (k == vp && h->bx == g->ax && h->by == g->ay)
      return doubles_back(h->ax, h->ay, h->bx, h->by, g->bx, g->by);
  }
  return segs_meet(g, h);
}

/* Flag the rings of a leaf's pieces that meet themselves away from a shared vertex. A
 * leaf's pieces come in increasing order (every list keeps the order of the pieces), and
 * a ring's pieces are consecutive, so the pieces of p's ring follow p. A
 * leaf holds few pieces except where pieces never separate (many through one point);
 * there the pairs are not checked, so that such input costs no quadratic time: the stat
 * is then a lower bound (documented). */
#define SELF_CHECK_MAX 256

static void self_meets(qk__bctx_t *b, const uint32_t *E, size_t n) {
  const qk__pieces_t *pc = b->pc;
  if (n > SELF_CHECK_MAX) return;
  const uint32_t *ring = pc->ring, *vtx = pc->vtx;
  const qk__seg_t *seg = pc->seg;
  const double *xy = b->in->xy;
  size_t ge;
  for (size_t i = 0; i + 1 < n; i = ge) {
    uint32_t rp = ring[E[i]];
    for (ge = i + 1; ge < n && ring[E[ge]] == rp;) ge++;
    if (ge - i < 2 || b->bad[rp]) continue;
    if (ge - i == 2) { /* two pieces (often one edge's, cut in two): skipped as below */
      uint32_t v0 = vtx[E[i]], v1 = vtx[E[i + 1]];
      if (v0 == UINT32_MAX || v1 == UINT32_MAX || v1 == v0) continue;
    }
    /* One ring's pieces, in the order of its vertices (vq >= vp below). */
    uint32_t rs = (uint32_t)b->in->ring_start[rp], last = (uint32_t)b->in->ring_start[rp + 1] - 2;
    bool hit = false;
    for (size_t a = i; a + 1 < ge && !hit; a++) {
      uint32_t p = E[a], vp = vtx[p];
      if (vp == UINT32_MAX) continue; /* the added pieces: not the ring's */
      const qk__seg_t *g = &seg[p];
      double lx = qk__min(g->ax, g->bx), hx = qk__max(g->ax, g->bx);
      double ly = qk__min(g->ay, g->by), hy = qk__max(g->ay, g->by);
      for (size_t c = a + 1; c < ge; c++) {
        uint32_t q = E[c], vq = vtx[q];
        if (vq == UINT32_MAX || vq == vp) continue; /* (vq == vp: pieces of one edge) */
        const qk__seg_t *h = &seg[q];
        if (qk__max(h->ax, h->bx) < lx || qk__min(h->ax, h->bx) > hx ||
            qk__max(h->ay, h->by) < ly || qk__min(h->ay, h->by) > hy)
          continue; /* boxes apart: most pairs */
        if (pieces_meet(xy, rs, last, vp, vq, g, h)) {
          b->bad[rp] = 1;
          hit = true;
          break;
        }
      }
    }
  }
}

#if defined(__SSE2__)
/* The leaf box (lo = (x0, y0), hi = (x1, y1)) rounded outwards to floats, four at once:
 * each converted to the nearest float, and those on the wrong side of their double moved
 * one float outwards by their bits (towards zero or away from it by the float's sign; a
 * zero becomes the smallest subnormal of the outward sign). This gives what a directed
 * rounding would, overflow included (a float beyond FLT_MAX: FLT_MAX, or an infinity). */
static void set_box(qk__leaf_t *L, __m128d lo, __m128d hi) {
  __m128 f = _mm_movelh_ps(_mm_cvtpd_ps(lo), _mm_cvtpd_ps(hi)); /* fx0 fy0 fx1 fy1 */
  __m128d mlo = _mm_cmpgt_pd(_mm_cvtps_pd(f), lo);
  __m128d mhi = _mm_cmplt_pd(_mm_cvtps_pd(_mm_movehl_ps(f, f)), hi);
  __m128i m = _mm_castps_si128(
      _mm_shuffle_ps(_mm_castpd_ps(mlo), _mm_castpd_ps(mhi), _MM_SHUFFLE(2, 0, 2, 0)));
  __m128i u = _mm_castps_si128(f);
  __m128i d = _mm_set_epi32(1, 1, -1, -1); /* the outward step of a positive float */
  __m128i sign = _mm_srai_epi32(u, 31);
  __m128i step = _mm_sub_epi32(_mm_xor_si128(d, sign), sign); /* negated for a negative */
  __m128i moved = _mm_add_epi32(u, _mm_and_si128(step, m));
  __m128i zero = _mm_and_si128(
      m, _mm_cmpeq_epi32(_mm_and_si128(u, _mm_set1_epi32(0x7fffffff)), _mm_setzero_si128()));
  __m128i tiny = _mm_set_epi32(1, 1, (int)0x80000001u, (int)0x80000001u);
  moved = _mm_or_si128(_mm_andnot_si128(zero, moved), _mm_and_si128(zero, tiny));
  float out[4];
  _mm_storeu_ps(out, _mm_castsi128_ps(moved));
  L->ex0 = out[0], L->ey0 = out[1], L->ex1 = out[2], L->ey1 = out[3];
}
#else
/* A float at most v (lo) or at least v (!lo): v rounded outwards. */
static float outward(double v, bool lo) {
  if (v > FLT_MAX) return lo ? FLT_MAX : INFINITY;
  if (v < -FLT_MAX) return lo ? -INFINITY : -FLT_MAX;
  float f = (float)v;
  if (lo ? !((double)f > v) : !((double)f < v)) return f;
  /* one float down (lo) or up, by its bits (nextafterf is a call, and most conversions
   * need it on one side) */
  if (f == 0) return lo ? -FLT_TRUE_MIN : FLT_TRUE_MIN;
  uint32_t u;
  memcpy(&u, &f, sizeof u);
  if ((f > 0) == lo)
    u--; /* towards zero */
  else
    u++; /* away from zero */
  memcpy(&f, &u, sizeof f);
  return f;
}
#endif

/* Split the set of depth d (the features holding the leaf's reference point) into the
 * leaf's short set, b->sh (*nsh), and its cover, b->cov (*nc): a feature of the set
 * without pieces among the leaf's E[0, ne) holds the whole closed square (a piece meeting
 * the square would be in the list: qk__clip4 keeps every such piece). The leaf's pieces
 * come in piece order, which is feature order, so one merge does it. */
static qk_status_t split_set(qk__bctx_t *b, unsigned d, size_t *nsh, size_t *nc) {
  const qk_allocator_t *a = &b->r->alloc;
  size_t ns = b->ns[d], ne = b->ne[d];
  qk_status_t st;
  if ((ns + 1 > b->cap_sh &&
       (st = qk__grow(a, (void **)&b->sh, &b->cap_sh, ns + 1, sizeof(uint32_t)))) ||
      (ns + 1 > b->cap_cov &&
       (st = qk__grow(a, (void **)&b->cov, &b->cap_cov, ns + 1, sizeof(uint32_t)))))
    return st;
  const uint32_t *S = b->set[d], *E = b->e[d], *feat = b->pc->feat;
  size_t j = 0, h = 0, c = 0;
  for (size_t i = 0; i < ns; i++) {
    uint32_t f = S[i];
    while (j < ne && feat[E[j]] < f) j++;
    if (j < ne && feat[E[j]] == f) {
      b->sh[h++] = f;
    } else {
      if (c == 0) b->sh[h++] = f; /* the cover's lowest */
      b->cov[c++] = f;
    }
  }
  *nsh = h, *nc = c;
  return QK_OK;
}

/* Store the cover of the leaf being made (b->cov, nc features) as its change from the
 * last checkpoint's cover, or make it a checkpoint (qk__cover_t). */
static qk_status_t store_cover(qk__bctx_t *b, size_t nc) {
  qk_region_t *r = b->r;
  const qk_allocator_t *a = &r->alloc;
  qk_status_t st;
  size_t nk = b->n_ck_cov;
  if (nc + nk > b->cap_chg &&
      (st = qk__grow(a, (void **)&b->chg, &b->cap_chg, nc + nk, sizeof(uint32_t))))
    return st;
  /* the change: the features in one of the two covers only */
  const uint32_t *A = b->cov, *B = b->ck_cov;
  size_t i = 0, j = 0, k = 0;
  while (i < nc || j < nk) {
    if (j == nk || (i < nc && A[i] < B[j]))
      b->chg[k++] = A[i++];
    else if (i == nc || B[j] < A[i])
      b->chg[k++] = B[j++];
    else
      i++, j++;
  }
  bool check = b->cover_ck == UINT32_MAX || k > nc || k > QK__COVER_CHANGES_MAX;
  size_t words = check ? nc + 1 : k;
  if (r->n_cover + words > UINT32_MAX) return QK_ERR_LIMIT;
  if ((r->n_leaves + 1 > r->cap_cover_at &&
       (st = qk__grow(a, (void **)&r->cover_at, &r->cap_cover_at, r->n_leaves + 1,
                      sizeof(qk__cover_t)))) ||
      (r->n_cover + words > r->cap_cover &&
       (st = qk__grow(a, (void **)&r->cover, &r->cap_cover, r->n_cover + words, sizeof(uint32_t)))))
    return st;
  if (check) {
    b->cover_ck = (uint32_t)r->n_cover;
    r->cover[r->n_cover] = (uint32_t)nc;
    if (nc) memcpy(r->cover + r->n_cover + 1, b->cov, nc * sizeof(uint32_t));
    /* the next leaves' changes are from this cover */
    uint32_t *t = b->ck_cov;
    size_t tc = b->cap_ck_cov;
    b->ck_cov = b->cov, b->cap_ck_cov = b->cap_cov;
    b->cov = t, b->cap_cov = tc;
    b->n_ck_cov = nc;
  } else if (k) {
    memcpy(r->cover + r->n_cover, b->chg, k * sizeof(uint32_t));
  }
  r->n_cover += words;
  r->cover_at[r->n_leaves] = (qk__cover_t){b->cover_ck, (uint32_t)r->n_cover};
  return QK_OK;
}

qk_status_t qk__emit_leaf(qk__bctx_t *b, qk_node_t v, double cx, double cy, unsigned d) {
  qk_region_t *r = b->r;
  const qk__pieces_t *pc = b->pc;
  size_t ne = b->ne[d], ns = b->ns[d];
  if (d > b->depth) b->depth = d;
  if (ne == 0 && ns <= 1) {
    r->kid[v] = QK__LEAF | QK__DIRECT | (ns ? b->set[d][0] + 1 : 0);
    r->n_direct++;
    return QK_OK;
  }
  if (r->n_leaves >= QK__DIRECT - 1) return QK_ERR_LIMIT;
  qk_status_t st = QK_OK;
  size_t nc;
  if ((st = split_set(b, d, &ns, &nc)) || (st = store_cover(b, nc))) return st;
  /* (qk__grow returns at once when there is room; the tests save the calls) */
  if ((r->n_leaves + 1 > r->cap_leaves &&
       (st = qk__grow(&r->alloc, (void **)&r->leaves, &r->cap_leaves, r->n_leaves + 1,
                      sizeof(qk__leaf_t)))) ||
      (r->n_le + ne > r->cap_le &&
       (st = qk__grow(&r->alloc, (void **)&r->le, &r->cap_le, r->n_le + ne, sizeof(uint32_t)))) ||
      (r->n_le + ne > r->cap_le_tag &&
       (st = qk__grow(&r->alloc, (void **)&r->le_tag, &r->cap_le_tag, r->n_le + ne,
                      sizeof(uint32_t)))) ||
      (r->n_sets + ns > r->cap_sets && (st = qk__grow(&r->alloc, (void **)&r->sets, &r->cap_sets,
                                                      r->n_sets + ns, sizeof(uint32_t)))))
    return st;
  if (r->n_le + ne > UINT32_MAX || r->n_sets + ns > UINT32_MAX) return QK_ERR_LIMIT;
  /* A short set equal to the last leaf's is shared (a leaf next to the last one in
   * Z-order with no boundary between their reference points). */
  const int same =
      ns && ns == b->prev_ns && !memcmp(r->sets + b->prev_s0, b->sh, ns * sizeof(uint32_t));
  r->leaves[r->n_leaves] = (qk__leaf_t){.e0 = (uint32_t)r->n_le,
                                        .ne = (uint32_t)ne,
                                        .s0 = (uint32_t)(same ? b->prev_s0 : r->n_sets),
                                        .ns = (uint32_t)ns};
  const uint32_t *E = b->e[d], *feat = pc->feat, *vtx = pc->vtx;
  const qk__seg_t *seg = pc->seg;
  uint32_t *le = r->le + r->n_le, *tag = r->le_tag + r->n_le;
  /* the box of the leaf's edges, rounded outwards to floats (see qk__leaf_t; ne > 0 here,
   * as a leaf without edges is direct unless several features hold its reference point) */
#if defined(__SSE2__) /* (min_pd and max_pd are qk__min and qk__max on two lanes) */
  __m128d lo = _mm_set1_pd(INFINITY), hi = _mm_set1_pd(-INFINITY);
#else
  double x0 = INFINITY, y0 = INFINITY, x1 = -INFINITY, y1 = -INFINITY;
#endif
  for (size_t i = 0; i < ne; i++) {
    uint32_t p = E[i];
    const qk__seg_t *g = &seg[p];
#if defined(__SSE2__)
    __m128d ga = _mm_loadu_pd(&g->ax), gb = _mm_loadu_pd(&g->bx);
    lo = _mm_min_pd(lo, _mm_min_pd(ga, gb));
    hi = _mm_max_pd(hi, _mm_max_pd(ga, gb));
#else
    x0 = qk__min(x0, qk__min(g->ax, g->bx)), x1 = qk__max(x1, qk__max(g->ax, g->bx));
    y0 = qk__min(y0, qk__min(g->ay, g->by)), y1 = qk__max(y1, qk__max(g->ay, g->by));
#endif
    int side = qk__side(g->ax, g->ay, g->bx, g->by, cx, cy);
    le[i] = p;
    tag[i] = feat[p] << 2 | (uint32_t)(vtx[p] == UINT32_MAX) << 1 | (uint32_t)(side > 0);
  }
  qk__leaf_t *L = &r->leaves[r->n_leaves];
  if (ne == 0) { /* an empty box: beside everything */
    L->ex0 = L->ey0 = INFINITY;
    L->ex1 = L->ey1 = -INFINITY;
  } else {
#if defined(__SSE2__)
    set_box(L, lo, hi);
#else
    L->ex0 = outward(x0, true), L->ey0 = outward(y0, true);
    L->ex1 = outward(x1, false), L->ey1 = outward(y1, false);
#endif
  }
  if (ns && !same) {
    memcpy(r->sets + r->n_sets, b->sh, ns * sizeof(uint32_t));
    b->prev_s0 = r->n_sets, b->prev_ns = ns;
    r->n_sets += ns;
  }
  r->n_le += ne;
  r->kid[v] = QK__LEAF | (uint32_t)r->n_leaves;
  r->n_leaves++;
  self_meets(b, b->e[d], ne);
  return QK_OK;
}

/* The parities gathered while sorting a cell's pieces into its children: for child q,
 * the features crossed an odd number of times by the segment from the cell's reference
 * point to the child's (which lies in the child's closed square, so only the child's
 * pieces can cross it). A child's pieces come in feature order, so a feature is done when
 * the next one starts. */
typedef struct flips {
  const uint32_t *feat;
  uint32_t *odd; /* child q's list at odd + q * stride */
  size_t stride;
  double ox, oy, qx[4], qy[4];       /* the parent centre and the children's */
  double lx[4], hx[4], ly[4], hy[4]; /* the box of each segment parent centre -> child's */
  uint32_t cur[4];
  bool par[4];
  size_t n[4];
} flips_t;

static inline void flip(flips_t *fl, unsigned q, uint32_t p, const qk__seg_t *g, double lx,
                        double hx, double ly, double hy) {
  /* (qk__ref_crosses, with the segment's box made once per cell) */
  if (hx < fl->lx[q] || lx > fl->hx[q] || hy < fl->ly[q] || ly > fl->hy[q]) return;
  if (!qk__ref_crosses_line(fl->ox, fl->oy, fl->qx[q], fl->qy[q], g)) return;
  uint32_t f = fl->feat[p];
  if (f != fl->cur[q]) {
    if (fl->par[q]) fl->odd[q * fl->stride + fl->n[q]++] = fl->cur[q];
    fl->cur[q] = f;
    fl->par[q] = false;
  }
  fl->par[q] = !fl->par[q];
}

/* Sort the pieces of level d into the four children's lists (a piece may go to several;
 * qk__clip4 decides) and gather the children's flips. Returns whether the split makes
 * progress (qk__split_progress). */
static qk_status_t split_lists(qk__bctx_t *b, unsigned d, double x0, double y0, double x1,
                               double y1, double cx, double cy, double half, bool *progress) {
  size_t n = b->ne[d];
  qk_status_t st;
  if ((4 * n + 1 > b->cap_store[d + 1] &&
       (st = qk__grow(&b->r->alloc, (void **)&b->store[d + 1], &b->cap_store[d + 1], 4 * n + 1,
                      sizeof(uint32_t)))) ||
      (4 * (n + 1) > b->cap_odd[d] &&
       (st = qk__grow(&b->r->alloc, (void **)&b->odd[d], &b->cap_odd[d], 4 * (n + 1),
                      sizeof(uint32_t)))))
    return st;
  uint32_t *out = b->store[d + 1];
  size_t c0 = 0, c1 = 0, c2 = 0, c3 = 0;
  /* the children's reference points, exactly as build_node computes them */
  const double hh = half * 0.5;
  flips_t fl = {b->pc->feat,
                b->odd[d],
                n + 1,
                cx,
                cy,
                {cx + hh, x0 + hh, x0 + hh, cx + hh},
                {cy + hh, cy + hh, y0 + hh, y0 + hh},
                {0, 0, 0, 0},
                {0, 0, 0, 0},
                {0, 0, 0, 0},
                {0, 0, 0, 0},
                {UINT32_MAX, UINT32_MAX, UINT32_MAX, UINT32_MAX},
                {false, false, false, false},
                {0, 0, 0, 0}};
  for (unsigned q = 0; q < 4; q++) {
    fl.lx[q] = qk__min(cx, fl.qx[q]), fl.hx[q] = qk__max(cx, fl.qx[q]);
    fl.ly[q] = qk__min(cy, fl.qy[q]), fl.hy[q] = qk__max(cy, fl.qy[q]);
  }
  const qk__seg_t *seg = b->pc->seg;
  const uint32_t *E = b->e[d];
  for (size_t i = 0; i < n; i++) {
    uint32_t p = E[i];
    const qk__seg_t *g = &seg[p];
    double lx = qk__min(g->ax, g->bx), hx = qk__max(g->ax, g->bx);
    double ly = qk__min(g->ay, g->by), hy = qk__max(g->ay, g->by);
    unsigned m = qk__clip4(g, lx, hx, ly, hy, x0, y0, x1, y1, cx, cy);
    if (m & 1u) out[c0++] = p, flip(&fl, 0, p, g, lx, hx, ly, hy);
    if (m & 2u) out[n + c1++] = p, flip(&fl, 1, p, g, lx, hx, ly, hy);
    if (m & 4u) out[2 * n + c2++] = p, flip(&fl, 2, p, g, lx, hx, ly, hy);
    if (m & 8u) out[3 * n + c3++] = p, flip(&fl, 3, p, g, lx, hx, ly, hy);
  }
  for (unsigned q = 0; q < 4; q++) {
    if (fl.par[q]) fl.odd[q * fl.stride + fl.n[q]++] = fl.cur[q];
    b->nodd[d][q] = fl.n[q];
  }
  size_t *cnt = b->cnt[d + 1];
  cnt[0] = c0, cnt[1] = c1, cnt[2] = c2, cnt[3] = c3;
  *progress = qk__split_progress(cnt, n);
  return QK_OK;
}

qk_status_t qk__child_set(qk__bctx_t *b, unsigned d, const uint32_t *odd, size_t nodd) {
  const qk_allocator_t *a = &b->r->alloc;
  size_t ns = b->ns[d];
  if (nodd == 0) { /* the parent's list, not copied (a depth's list stays while below it) */
    b->set[d + 1] = b->set[d];
    b->ns[d + 1] = ns;
    return QK_OK;
  }
  qk_status_t st;
  if (ns + nodd + 1 > b->cap_s[d + 1] &&
      (st = qk__grow(a, (void **)&b->s[d + 1], &b->cap_s[d + 1], ns + nodd + 1, sizeof(uint32_t))))
    return st;
  const uint32_t *S = b->set[d];
  uint32_t *T = b->s[d + 1];
  b->set[d + 1] = T;
  size_t i = 0, j = 0, k = 0;
  while (i < ns || j < nodd) {
    if (j == nodd || (i < ns && S[i] < odd[j]))
      T[k++] = S[i++];
    else if (i == ns || odd[j] < S[i])
      T[k++] = odd[j++];
    else
      i++, j++;
  }
  b->ns[d + 1] = k;
  return QK_OK;
}

size_t qk__child_floor(const qk__bctx_t *b, size_t floor, const size_t cnt[4], unsigned q) {
  double rest = 0;
  for (unsigned k = q + 1; k < 4; k++) rest += (double)cnt[k];
  const double all = rest + (double)cnt[q];
  if (!(b->splits_left > floor) || all == 0) return floor;
  return floor + (size_t)((double)(b->splits_left - floor) * (rest / all));
}

qk_status_t qk__split_cell(qk__bctx_t *b, qk_node_t v, uint32_t *first) {
  qk_region_t *r = b->r;
  qk_status_t st;
  /* With the tree kept, its split names the children; without, they take the next four
   * slots of kid[] (the same cells, numbered without the tree's bookkeeping). */
  if (r->tree) {
    if ((st = qk_tree_split_leaf(r->tree, v))) return st;
    *first = qk__node_child(r->tree, v);
  } else {
    if (r->n_kid + 4 >= QK__DIRECT) return QK_ERR_LIMIT;
    *first = (uint32_t)r->n_kid;
  }
  b->splits_left--;
  if ((st = qk__grow(&r->alloc, (void **)&r->kid, &r->cap_kid,
                     r->tree ? qk__tree_node_bound(r->tree) : r->n_kid + 4, sizeof(uint32_t))))
    return st;
  r->kid[v] = *first;
  if (*first + 4 > r->n_kid) r->n_kid = *first + 4;
  return QK_OK;
}

qk_status_t qk__build_node(qk__bctx_t *b, qk_node_t v, double x0, double y0, double x1, double y1,
                           double side, unsigned d, unsigned stall) {
  double h = side * 0.5, cx = x0 + h, cy = y0 + h;
  qk_status_t st;
  bool split = false;
  /* The budget bounds the work on adversarial input (thousands of long edges fanning out
   * of one point need a number of cells far beyond the edges to separate them); when it
   * runs out the remaining cells stay leaves with more pieces. Real layers stay far
   * below it. Each cell's children share what is left of it in proportion to their
   * pieces (qk__child_floor): spent depth first, the first quadrant of a fan took it all,
   * and cells far from the fan's apex kept up to 200 times the pieces a query scans. */
  if (b->ne[d] > b->C && d < b->maxd && b->splits_left > b->splits_floor) {
    bool prog;
    if ((st = split_lists(b, d, x0, y0, x1, y1, cx, cy, h, &prog))) return st;
    stall = prog ? 0 : stall + 1;
    split = stall <= QK__STALL_BUDGET;
  }
  if (split) {
    uint32_t first = 0;
    if ((st = qk__split_cell(b, v, &first)) == QK_OK) {
      size_t n = b->ne[d];
      const size_t floor = b->splits_floor;
      for (unsigned q = 0; q < 4; q++) {
        int east = (int)qk__q_east(q), north = (int)qk__q_north(q);
        double qx0 = east ? cx : x0, qx1 = east ? x1 : cx;
        double qy0 = north ? cy : y0, qy1 = north ? y1 : cy;
        size_t cn = b->cnt[d + 1][q];
        b->e[d + 1] = b->store[d + 1] + q * n;
        b->ne[d + 1] = cn;
        if (b->nodd[d][q] == 0) { /* (qk__child_set's first case, without the call) */
          b->set[d + 1] = b->set[d];
          b->ns[d + 1] = b->ns[d];
        } else if ((st = qk__child_set(b, d, b->odd[d] + q * (n + 1), b->nodd[d][q]))) {
          return st;
        }
        /* A child that will not split is a leaf at once (qk__build_node's test and
         * reference point, without the call). */
        b->splits_floor = qk__child_floor(b, floor, b->cnt[d + 1], q);
        if (!(cn > b->C && d + 1 < b->maxd && b->splits_left > b->splits_floor)) {
          double hq = h * 0.5;
          st = qk__emit_leaf(b, first + q, qx0 + hq, qy0 + hq, d + 1);
        } else {
          st = qk__build_node(b, first + q, qx0, qy0, qx1, qy1, h, d + 1, stall);
        }
        b->splits_floor = floor;
        if (st) return st;
      }
      return QK_OK;
    }
    if (st != QK_ERR_LIMIT) return st;
  }
  return qk__emit_leaf(b, v, cx, cy, d);
}
