/*
 * The constrained Delaunay triangulation of mesh/cdt.h: storage, point location and point
 * insertion (Lawson's incremental algorithm: split the triangle 1 -> 3 or the edge 2 -> 4,
 * then flip the edges opposite the new vertex that fail the in-circle test, never a
 * constrained one). Segment insertion is in cdt_segment.c, the visibility walk in
 * cdt_walk.c, the exact predicates in cdt_exact.c.
 *
 * Memory: the per-vertex arrays (xy, vtri and the flip stack) live in one block, grown by
 * half again with realloc and vtri and the stack then moved up to their new offsets; the
 * per-triangle arrays (v, nbr, seg) are three blocks, each grown by half again with
 * realloc (a large block is remapped, not copied next to the old one: no transient peak of
 * old plus new, and nothing to move). A failed realloc leaves the block as it was. Every
 * operation reserves what it may need before it changes anything.
 */
#include <assert.h>
#include <string.h>

#include "index/index_access.h"
#include "index/inline.h"
#include "mesh/cdt_internal.h"

#define NONE QK__CDT_NONE

/* ---- storage ------------------------------------------------------------------------ */

static size_t vblock_bytes(size_t cap) {
  return cap * (2 * sizeof(double) + sizeof(uint32_t)) + (cap + 8) * sizeof(uint32_t);
}

/* The next capacity: half again, at least `need`. */
static size_t next_cap(size_t cap, size_t need) {
  cap = cap < 16 ? 16 : cap;
  while (cap < need) cap += cap / 2;
  return cap;
}

/* Room for `need` vertices: half again or more (exact: just `need`). */
static qk_status_t grow_vertices_slow(qk__cdt_t *c, size_t need, int exact) {
  size_t old = c->cap_v, cap = exact ? need : next_cap(old, need);
  if (cap > (size_t)UINT32_MAX - 16) cap = (size_t)UINT32_MAX - 16;
  if (cap < need) return QK_ERR_NOMEM;
  char *blk;
  if (c->xy && 2 * c->nv < old) {
    /* Mostly room (a reservation): a new block and the live part copied, where a realloc
     * may copy the whole old block (the mesher's arena does). */
    blk = qk__realloc(c->alloc, NULL, 0, vblock_bytes(cap));
    if (!blk) return QK_ERR_NOMEM;
    memcpy(blk, c->xy, c->nv * 2 * sizeof(double));
    memcpy(blk + cap * 2 * sizeof(double), c->vtri, c->nv * sizeof *c->vtri);
    qk__free(c->alloc, c->xy, vblock_bytes(old));
  } else {
    blk = qk__realloc(c->alloc, c->xy, c->xy ? vblock_bytes(old) : 0, vblock_bytes(cap));
    if (!blk) return QK_ERR_NOMEM;
    if (c->nv)
      memmove(blk + cap * 2 * sizeof(double), blk + old * 2 * sizeof(double),
              c->nv * sizeof(uint32_t));
  }
  double *xy = (double *)blk;
  uint32_t *vtri = (uint32_t *)(blk + cap * 2 * sizeof(double));
  c->xy = xy, c->vtri = vtri, c->stk = vtri + cap, c->cap_v = cap;
  return QK_OK;
}

static inline qk_status_t grow_vertices(qk__cdt_t *c, size_t need) {
  return need <= c->cap_v ? QK_OK : grow_vertices_slow(c, need, 0);
}

void *qk__cdt_grow_live(const qk_allocator_t *a, void *p, size_t osize, size_t nsize, size_t live) {
  if (!p || 2 * live >= osize) return qk__realloc(a, p, osize, nsize);
  void *q = qk__realloc(a, NULL, 0, nsize);
  if (!q) return NULL;
  memcpy(q, p, live);
  qk__free(a, p, osize);
  return q;
}

/* One per-triangle array (3 entries a triangle) to `cap` triangles; *have its capacity.
 * When less than half of it is in use (the mesher reserves ahead: on Norway at 1/256 of its
 * extent the seeding's reservation grew arrays of 35,065 triangles holding 3,908), a new
 * block gets the live part only, where a realloc may copy the whole old block (the mesher's
 * arena does: 1.26 MB of the 78 M instructions there, counted by byte). */
static int grow_array(qk__cdt_t *c, uint32_t **arr, size_t *have, size_t cap) {
  if (*have >= cap) return 1;
  const size_t e = 3 * sizeof **arr, live = c->nt < *have ? c->nt : *have;
  uint32_t *a = qk__cdt_grow_live(c->alloc, *arr, *arr ? *have * e : 0, cap * e, live * e);
  if (!a) return 0;
  *arr = a, *have = cap;
  return 1;
}

static qk_status_t grow_triangles_slow(qk__cdt_t *c, size_t need, int exact) {
  size_t cap = exact ? need : next_cap(c->cap_t, need);
  if (cap > (size_t)UINT32_MAX / 4) cap = (size_t)UINT32_MAX / 4;
  if (cap < need) return QK_ERR_NOMEM;
  /* Three arrays, each grown on its own (a large block is remapped, not copied); one that
   * grew before a failure keeps its room. */
  if (!grow_array(c, &c->v, &c->cap_tv, cap) || !grow_array(c, &c->nbr, &c->cap_tn, cap) ||
      !grow_array(c, &c->seg, &c->cap_ts, cap))
    return QK_ERR_NOMEM;
  c->cap_t = cap;
  return QK_OK;
}

static inline qk_status_t grow_triangles(qk__cdt_t *c, size_t need) {
  return need <= c->cap_t ? QK_OK : grow_triangles_slow(c, need, 0);
}

qk_status_t qk__cdt_reserve(qk__cdt_t *c, size_t nv, size_t nt) {
  if (nv > c->cap_v && grow_vertices_slow(c, nv, 1) != QK_OK) return QK_ERR_NOMEM;
  if (nt > c->cap_t && grow_triangles_slow(c, nt, 1) != QK_OK) return QK_ERR_NOMEM;
  return QK_OK;
}

/* Shrink one per-triangle array to `cap` triangles (a failed shrink keeps it as it was). */
static void shrink_array(qk__cdt_t *c, uint32_t **arr, size_t *have, size_t cap) {
  if (!*arr || *have <= cap) return;
  uint32_t *a = qk__realloc(c->alloc, *arr, *have * 3 * sizeof **arr, cap * 3 * sizeof **arr);
  if (a) *arr = a, *have = cap;
}

void qk__cdt_shrink(qk__cdt_t *c) {
  size_t nt = c->nt, cap = nt < 16 ? 16 : nt;
  if (cap < c->cap_t) {
    shrink_array(c, &c->v, &c->cap_tv, cap);
    shrink_array(c, &c->nbr, &c->cap_tn, cap);
    shrink_array(c, &c->seg, &c->cap_ts, cap);
    size_t m = c->cap_tv < c->cap_tn ? c->cap_tv : c->cap_tn;
    c->cap_t = m < c->cap_ts ? m : c->cap_ts;
  }
  size_t nv = c->nv, vcap = nv < 16 ? 16 : nv, vold = c->cap_v;
  if (c->xy && vcap < vold) {
    char *blk = (char *)c->xy;
    memmove(blk + vcap * 2 * sizeof(double), c->vtri, nv * sizeof *c->vtri);
    char *nb = qk__realloc(c->alloc, blk, vblock_bytes(vold), vblock_bytes(vcap));
    if (nb) {
      uint32_t *vtri = (uint32_t *)(nb + vcap * 2 * sizeof(double));
      c->xy = (double *)nb, c->vtri = vtri, c->stk = vtri + vcap, c->cap_v = vcap;
    } else {
      memmove(blk + vold * 2 * sizeof(double), blk + vcap * 2 * sizeof(double),
              nv * sizeof *c->vtri);
    }
  }
}

qk_status_t qk__cdt_reserve_scratch(qk__cdt_t *c, size_t need) {
  if (need <= c->cap_scr) return QK_OK;
  size_t cap = c->cap_scr < 64 ? 64 : c->cap_scr;
  while (cap < need) cap *= 2;
  uint32_t *s = qk__realloc(c->alloc, c->scr, c->cap_scr * sizeof *s, cap * sizeof *s);
  if (!s) return QK_ERR_NOMEM;
  c->scr = s, c->cap_scr = cap;
  return QK_OK;
}

qk_status_t qk__cdt_init(qk__cdt_t *c, const qk_allocator_t *alloc, double x0, double y0,
                         double side, size_t nv_hint) {
  memset(c, 0, sizeof *c);
  c->alloc = alloc;
  c->hint = 0;
  size_t nv = nv_hint + 4;
  if (nv < nv_hint || nv > (size_t)UINT32_MAX / 4) nv = 16;
  if (grow_vertices(c, nv) != QK_OK) return QK_ERR_NOMEM;
  if (grow_triangles(c, 2 * nv) != QK_OK) {
    qk__cdt_free(c);
    memset(c, 0, sizeof *c);
    return QK_ERR_NOMEM;
  }
  const double cx[4] = {x0, x0 + side, x0 + side, x0}, cy[4] = {y0, y0, y0 + side, y0 + side};
  for (int i = 0; i < 4; i++) c->xy[2 * i] = cx[i], c->xy[2 * i + 1] = cy[i];
  c->nv = 4;
  /* t0 = (0, 1, 2), t1 = (0, 2, 3), sharing the diagonal 0-2 */
  const uint32_t v[6] = {0, 1, 2, 0, 2, 3}, nb[6] = {NONE, 1, NONE, NONE, NONE, 0};
  for (int i = 0; i < 6; i++) c->v[i] = v[i], c->nbr[i] = nb[i], c->seg[i] = NONE;
  c->nt = 2;
  c->vtri[0] = 0, c->vtri[1] = 0, c->vtri[2] = 0, c->vtri[3] = 1;
  return QK_OK;
}

void qk__cdt_free(qk__cdt_t *c) {
  if (c->xy) qk__free(c->alloc, c->xy, vblock_bytes(c->cap_v));
  if (c->v) qk__free(c->alloc, c->v, c->cap_tv * 3 * sizeof *c->v);
  if (c->nbr) qk__free(c->alloc, c->nbr, c->cap_tn * 3 * sizeof *c->nbr);
  if (c->seg) qk__free(c->alloc, c->seg, c->cap_ts * 3 * sizeof *c->seg);
  if (c->scr) qk__free(c->alloc, c->scr, c->cap_scr * sizeof *c->scr);
  const qk_allocator_t *a = c->alloc;
  memset(c, 0, sizeof *c);
  c->alloc = a;
}

/* ---- point location ----------------------------------------------------------------- */

/* Where p lies in the closed triangle t, from the signs o[] of its edges (edge e's the
 * orientation of v[e + 1], v[e + 2], p): inside, on edge *k, or at the vertex *k between
 * the two zero edges. */
static qk__cdt_where_t where_in(const int o[3], uint32_t t, uint32_t *tri, int *k) {
  *tri = t;
  *k = 0;
  int nz = (o[0] == 0) + (o[1] == 0) + (o[2] == 0);
  if (nz == 0) return QK__CDT_IN;
  if (nz == 1) {
    *k = o[0] == 0 ? 0 : o[1] == 0 ? 1 : 2;
    return QK__CDT_EDGE;
  }
  *k = o[0] != 0 ? 0 : o[1] != 0 ? 1 : 2; /* the vertex between the two zero edges */
  return QK__CDT_VERT;
}

/*
 * The remembering stochastic walk (Devillers, Pion and Teillaud, "Walking in a
 * triangulation", 2002): from the current triangle, cross an edge that has p strictly on
 * its far side, testing the edges from a random one on and never the one just crossed.
 * It ends with probability 1 on any triangulation (a deterministic visibility walk may
 * cycle on a non-Delaunay one, and a constrained one is not Delaunay).
 */
qk__cdt_where_t qk__cdt_locate(const qk__cdt_t *c, double x, double y, uint32_t start,
                               uint32_t *tri, int *k) {
  const double p[2] = {x, y};
  uint32_t t = start != NONE ? start : c->hint;
  if (t >= c->nt) t = 0;
  uint32_t from = NONE, rnd = 0x9E3779B9u ^ t;
  int o[3];
  for (;;) {
    const uint32_t *tv = c->v + 3 * (size_t)t, *tn = c->nbr + 3 * (size_t)t;
    rnd ^= rnd << 13, rnd ^= rnd >> 17, rnd ^= rnd << 5;
    int i = (int)(((uint64_t)rnd * 3) >> 32);
    uint32_t next = NONE;
    for (int j = 0; j < 3; j++, i = i == 2 ? 0 : i + 1) {
      uint32_t n = tn[i];
      if (n == from) { /* p is strictly inside this edge's half-plane: we came across it */
        o[i] = 1;
        continue;
      }
      const double *a = c->xy + 2 * (size_t)tv[i == 2 ? 0 : i + 1];
      const double *b = c->xy + 2 * (size_t)tv[i == 0 ? 2 : i - 1];
      o[i] = qk__cdt_orient(a, b, p);
      if (o[i] < 0 && n != NONE) {
        next = n;
        break;
      }
    }
    if (next == NONE) break;
    from = t, t = next;
  }
  /* p is in the closed triangle t (outside the square only if it was asked for there) */
  return where_in(o, t, tri, k);
}

qk__cdt_where_t qk__cdt_locate_delaunay(const qk__cdt_t *c, double x, double y, uint32_t u,
                                        uint32_t *tri, int *k) {
  const double p[2] = {x, y}, *pu = c->xy + 2 * (size_t)u;
  uint32_t t = c->vtri[u];
  int i = qk__cdt_slot(c, t, u);
  const uint32_t *tv = c->v + 3 * (size_t)t;
  /* t = (u, a, b) counter-clockwise from u's slot i: p is in t's closed angle at u when it
   * is not right of u -> a (oa >= 0) and not left of u -> b (ob <= 0). Turn clockwise
   * (across u-a, edge i + 2) while p is right of u -> a, else counter-clockwise (across
   * u-b, edge i + 1) while it is left of u -> b; the spoke crossed keeps its sign. */
  int oa = qk__cdt_orient(pu, c->xy + 2 * (size_t)tv[i == 2 ? 0 : i + 1], p), ob = 0;
  if (oa < 0) {
    for (size_t guard = 0;; guard++) {
      uint32_t n = c->nbr[3 * (size_t)t + (i == 0 ? 2 : i - 1)];
      if (n == NONE || guard > c->nt) return qk__cdt_locate(c, x, y, t, tri, k);
      t = n, i = qk__cdt_slot(c, t, u), tv = c->v + 3 * (size_t)t;
      ob = -1;
      oa = qk__cdt_orient(pu, c->xy + 2 * (size_t)tv[i == 2 ? 0 : i + 1], p);
      if (oa >= 0) break;
    }
  } else {
    ob = qk__cdt_orient(pu, c->xy + 2 * (size_t)tv[i == 0 ? 2 : i - 1], p);
    for (size_t guard = 0; ob > 0; guard++) {
      uint32_t n = c->nbr[3 * (size_t)t + (i == 2 ? 0 : i + 1)];
      if (n == NONE || guard > c->nt) return qk__cdt_locate(c, x, y, t, tri, k);
      t = n, i = qk__cdt_slot(c, t, u), tv = c->v + 3 * (size_t)t;
      oa = 1;
      ob = qk__cdt_orient(pu, c->xy + 2 * (size_t)tv[i == 0 ? 2 : i - 1], p);
    }
  }
  /* In t's angle at u: inside t unless beyond the edge across from u (edge i). */
  const double *a = c->xy + 2 * (size_t)tv[i == 2 ? 0 : i + 1];
  const double *b = c->xy + 2 * (size_t)tv[i == 0 ? 2 : i - 1];
  int o[3];
  o[i] = qk__cdt_orient(a, b, p), o[i == 2 ? 0 : i + 1] = -ob, o[i == 0 ? 2 : i - 1] = oa;
  uint32_t from = t, n = c->nbr[3 * (size_t)t + i];
  if (o[i] < 0 && n != NONE) {
    /* The visibility walk: entered across edge j, p lies strictly inside that edge's
     * half-plane, so only the other two can lead on, tried in a random order (a fixed order
     * cost 6% more on Norway's coastline). On a Delaunay triangulation it cannot
     * cycle (Edelsbrunner's acyclicity theorem); the cap hands a walk that ran long to the
     * stochastic one. */
    const uint32_t *V = c->v, *N = c->nbr;
    const double *XY = c->xy;
    const size_t cap = c->nt;
    uint32_t rnd = 0x9E3779B9u ^ n;
    int j, e1, e2, o1, o2;
    t = n;
    for (size_t steps = 0;; steps++) {
      if (steps > cap) return qk__cdt_locate(c, x, y, t, tri, k);
      const uint32_t *wv = V + 3 * (size_t)t, *wn = N + 3 * (size_t)t;
      j = wn[0] == from ? 0 : wn[1] == from ? 1 : 2;
      e1 = j == 2 ? 0 : j + 1, e2 = j == 0 ? 2 : j - 1;
      /* Edge e runs from v[e + 1] to v[e + 2]: edge e1 from v[e2] to v[j], edge e2 from
       * v[j] to v[e1]. */
      const double *pj = XY + 2 * (size_t)wv[j], *p1 = XY + 2 * (size_t)wv[e1];
      const double *p2 = XY + 2 * (size_t)wv[e2];
      uint32_t n1 = wn[e1], n2 = wn[e2];
      rnd ^= rnd << 13, rnd ^= rnd >> 17, rnd ^= rnd << 5;
      if (rnd & 1) {
        o1 = qk__cdt_orient(p2, pj, p);
        if (o1 < 0 && n1 != NONE) {
          from = t, t = n1;
          continue;
        }
        o2 = qk__cdt_orient(pj, p1, p);
      } else {
        o2 = qk__cdt_orient(pj, p1, p);
        if (o2 < 0 && n2 != NONE) {
          from = t, t = n2;
          continue;
        }
        o1 = qk__cdt_orient(p2, pj, p);
      }
      if (o1 < 0 && n1 != NONE) {
        from = t, t = n1;
        continue;
      }
      if (o2 < 0 && n2 != NONE) {
        from = t, t = n2;
        continue;
      }
      break;
    }
    /* In the closed triangle t, strictly inside edge j's half-plane. */
    o[j] = 1, o[e1] = o1, o[e2] = o2;
  }
  return where_in(o, t, tri, k);
}

/* ---- the changes: split, flip -------------------------------------------------------- */

static inline void changed(qk__cdt_t *c, uint32_t t) {
  if (c->on_change) c->on_change(c->user, t);
}

/* In triangle x (if any), make the link that pointed to `from` point to `to`. */
static inline void relink(qk__cdt_t *c, uint32_t x, uint32_t from, uint32_t to) {
  if (x == NONE) return;
  uint32_t *n = c->nbr + 3 * (size_t)x;
  if (n[0] == from)
    n[0] = to;
  else if (n[1] == from)
    n[1] = to;
  else
    n[2] = to;
}

static inline void set_tri(qk__cdt_t *c, uint32_t t, uint32_t a, uint32_t b, uint32_t d,
                           uint32_t na, uint32_t nb, uint32_t nd, uint32_t sa, uint32_t sb,
                           uint32_t sd) {
  uint32_t *v = c->v + 3 * (size_t)t, *n = c->nbr + 3 * (size_t)t, *s = c->seg + 3 * (size_t)t;
  v[0] = a, v[1] = b, v[2] = d;
  n[0] = na, n[1] = nb, n[2] = nd;
  s[0] = sa, s[1] = sb, s[2] = sd;
}

static inline void flip(qk__cdt_t *c, uint32_t t, int i, uint32_t n, int j) {
  const int i1 = i == 2 ? 0 : i + 1, i2 = i == 0 ? 2 : i - 1;
  const int j1 = j == 2 ? 0 : j + 1, j2 = j == 0 ? 2 : j - 1;
  uint32_t *tv = c->v + 3 * (size_t)t, *tn = c->nbr + 3 * (size_t)t, *ts = c->seg + 3 * (size_t)t;
  uint32_t *nv = c->v + 3 * (size_t)n, *nn = c->nbr + 3 * (size_t)n, *ns = c->seg + 3 * (size_t)n;
  uint32_t p = tv[i], q = tv[i1], r = tv[i2], s = nv[j];
  uint32_t A = tn[i1], sA = ts[i1], B = tn[i2], sB = ts[i2];
  uint32_t C = nn[j1], sC = ns[j1], D = nn[j2], sD = ns[j2];
  set_tri(c, t, p, q, s, C, n, B, sC, NONE, sB);
  set_tri(c, n, p, s, r, D, A, t, sD, sA, NONE);
  relink(c, A, t, n);
  relink(c, C, n, t);
  c->vtri[q] = t, c->vtri[r] = n; /* q left n, r left t; p and s are in both */
  changed(c, t);
  changed(c, n);
}

/* flip() with i = 0, for the legalisation after a point insertion (always inlined there).
 * report: a constant, 0 in the copy that never has on_change set (the undo record's): with
 * no call through c->on_change the compiler keeps the arrays and the loop's state in
 * registers instead of reloading them from c after every flip. */
static QK__ALWAYS_INLINE void flip0(qk__cdt_t *c, uint32_t t, uint32_t n, int j, const int report) {
  const int j1 = j == 2 ? 0 : j + 1, j2 = j == 0 ? 2 : j - 1;
  uint32_t *tv = c->v + 3 * (size_t)t, *tn = c->nbr + 3 * (size_t)t, *ts = c->seg + 3 * (size_t)t;
  uint32_t *nv = c->v + 3 * (size_t)n, *nn = c->nbr + 3 * (size_t)n, *ns = c->seg + 3 * (size_t)n;
  uint32_t p = tv[0], q = tv[1], r = tv[2], s = nv[j];
  uint32_t A = tn[1], sA = ts[1];
  uint32_t C = nn[j1], sC = ns[j1], D = nn[j2], sD = ns[j2];
  tv[2] = s, tn[0] = C, tn[1] = n, ts[0] = sC, ts[1] = NONE; /* t = (p, q, s), B kept */
  nv[0] = p, nv[1] = s, nv[2] = r;
  nn[0] = D, nn[1] = A, nn[2] = t;
  ns[0] = sD, ns[1] = sA, ns[2] = NONE;
  /* A, across the spoke p-r, is in p's star too, with p in slot 0 (every triangle the
   * split and the flips make has it there), so that spoke is its edge 2 (p to r). */
  if (A != NONE) {
    assert(c->v[3 * (size_t)A] == p && c->nbr[3 * (size_t)A + 2] == t);
    c->nbr[3 * (size_t)A + 2] = n;
  }
  relink(c, C, n, t);
  c->vtri[q] = t, c->vtri[r] = n;
  if (report) changed(c, t), changed(c, n);
}

void qk__cdt_flip(qk__cdt_t *c, uint32_t t, int i, uint32_t n, int j) { flip(c, t, i, n, j); }

/* The slot of triangle n that faces triangle t. */
static inline int facing(const qk__cdt_t *c, uint32_t n, uint32_t t) {
  const uint32_t *nn = c->nbr + 3 * (size_t)n;
  return nn[0] == t ? 0 : nn[1] == t ? 1 : 2;
}

/* Split triangle t by the new vertex p inside it: t = (p, b, c), t1 = (p, c, a),
 * t2 = (p, a, b). Pushes the three on the flip stack. Always inlined: with its second
 * caller, qk__cdt_insert_in_undo, it was a call of 128 instructions where inlined it is
 * about 96 (0.9 M instructions of 69 M on South Africa at extent/256). */
static QK__ALWAYS_INLINE int split3(qk__cdt_t *c, uint32_t t, uint32_t p, const int report) {
  uint32_t *tv = c->v + 3 * (size_t)t, *tn = c->nbr + 3 * (size_t)t, *ts = c->seg + 3 * (size_t)t;
  uint32_t a = tv[0], b = tv[1], d = tv[2];
  uint32_t na = tn[0], nb = tn[1], nd = tn[2], sa = ts[0], sb = ts[1], sd = ts[2];
  uint32_t t1 = (uint32_t)c->nt, t2 = t1 + 1;
  c->nt += 2;
  set_tri(c, t, p, b, d, na, t1, t2, sa, NONE, NONE);
  set_tri(c, t1, p, d, a, nb, t2, t, sb, NONE, NONE);
  set_tri(c, t2, p, a, b, nd, t, t1, sd, NONE, NONE);
  relink(c, nb, t, t1);
  relink(c, nd, t, t2);
  c->vtri[p] = t, c->vtri[a] = t1;
  if (report) changed(c, t), changed(c, t1), changed(c, t2);
  c->stk[0] = t, c->stk[1] = t1, c->stk[2] = t2;
  return 3;
}

/* Split edge k of triangle t (and the triangle n across it, if any) by the new vertex p in
 * its relative interior. The halves keep the edge's segment id. Pushes the new triangles. */
static int split_edge(qk__cdt_t *c, uint32_t t, int k, uint32_t p) {
  const int k1 = k == 2 ? 0 : k + 1, k2 = k == 0 ? 2 : k - 1;
  uint32_t *tv = c->v + 3 * (size_t)t, *tn = c->nbr + 3 * (size_t)t, *ts = c->seg + 3 * (size_t)t;
  uint32_t a = tv[k], b = tv[k1], d = tv[k2]; /* the edge is b -> d */
  uint32_t n = tn[k], s = ts[k];
  uint32_t ntb = tn[k1], stb = ts[k1], ntd = tn[k2], std_ = ts[k2];
  uint32_t t1 = (uint32_t)c->nt++;
  if (n == NONE) {
    set_tri(c, t, p, d, a, ntb, t1, NONE, stb, NONE, s);
    set_tri(c, t1, p, a, b, ntd, NONE, t, std_, s, NONE);
    relink(c, ntd, t, t1);
    c->vtri[p] = t, c->vtri[b] = t1, c->vtri[d] = t;
    changed(c, t), changed(c, t1);
    c->stk[0] = t, c->stk[1] = t1;
    return 2;
  }
  int j = facing(c, n, t);
  const int j1 = j == 2 ? 0 : j + 1, j2 = j == 0 ? 2 : j - 1;
  uint32_t *nv = c->v + 3 * (size_t)n, *nn = c->nbr + 3 * (size_t)n, *ns = c->seg + 3 * (size_t)n;
  uint32_t e = nv[j]; /* n = (e, d, b) */
  uint32_t nnd = nn[j1], snd = ns[j1], nnb = nn[j2], snb = ns[j2];
  uint32_t n1 = (uint32_t)c->nt++;
  set_tri(c, t, p, d, a, ntb, t1, n1, stb, NONE, s);
  set_tri(c, t1, p, a, b, ntd, n, t, std_, s, NONE);
  set_tri(c, n, p, b, e, nnd, n1, t1, snd, NONE, s);
  set_tri(c, n1, p, e, d, nnb, t, n, snb, s, NONE);
  relink(c, ntd, t, t1);
  relink(c, nnb, n, n1);
  c->vtri[p] = t, c->vtri[b] = t1, c->vtri[d] = t, c->vtri[e] = n;
  changed(c, t), changed(c, t1), changed(c, n), changed(c, n1);
  c->stk[0] = t, c->stk[1] = t1, c->stk[2] = n, c->stk[3] = n1;
  return 4;
}

/* Is the vertex across edge 0 of t (slot j of n) strictly inside t's circumcircle? With
 * t = (p, q, r) holding the new point p and n = (r, q, s) an old triangle, that is p inside
 * n's (an even permutation of the in-circle determinant). */
static inline int across_in(const qk__cdt_t *c, uint32_t t, uint32_t n, int j) {
  const uint32_t *tv = c->v + 3 * (size_t)t;
  const double *pp = c->xy + 2 * (size_t)tv[0], *pq = c->xy + 2 * (size_t)tv[1];
  const double *pr = c->xy + 2 * (size_t)tv[2];
  const double *ps = c->xy + 2 * (size_t)c->v[3 * (size_t)n + j];
  return qk__cdt_incircle(pp, pq, pr, ps) > 0;
}

/* across_in out of line, for the loop below when the caller's record decides (almost)
 * every test: the test inline there cost registers (spills and reloads) on every pass. */
#if defined(__GNUC__)
__attribute__((noinline))
#endif
static int
across_in_call(const qk__cdt_t *c, uint32_t t, uint32_t n, int j) {
  return across_in(c, t, n, j);
}

/* Lawson's flips after inserting p: every stacked triangle has p in slot 0; its edge 0 is
 * flipped when the vertex across it lies strictly inside its circumcircle (ties keep the
 * edge, so flips end). Each flip adds one triangle to p's star, so the stack never holds
 * more than its initial four plus nv entries. With_known, with_undo and report (constants in
 * each of the three copies): c->known records the tests (the refinement's cavity search made
 * them all but past its cap), which the loop reads; without, it tests. The same flips
 * either way. With_undo it also writes c->undo's record of each flip (what undo_flip0
 * needs) and lists the star's constrained far edges in c->undo_seg. Report: each flip goes
 * to on_change; the undo copy has it 0 (on_change must be NULL there: the refinement, its
 * user, never sets it), which was 0.4% of the meshing's instructions with the arrays in
 * locals (a copy without reports for the plain insertions gained nothing). */
static QK__ALWAYS_INLINE void legalize_with(qk__cdt_t *c, int sp, const int with_known,
                                            const int with_undo, const int report) {
  assert(!with_undo || !c->on_change);
  /* The arrays in locals: nothing in the loop moves them, and with no call in the loop but
   * the exact in-circle test's (rare) the compiler keeps them in registers. */
  uint32_t *const stk = c->stk, *const undo = c->undo, *const useg = c->undo_seg;
  const uint32_t *const N = c->nbr, *const S = c->seg, *const V = c->v;
  const uint32_t *const vtri = c->vtri;
  size_t nu = c->nundo, nus = 0;
  const uint32_t *known = c->known, in = 2 * c->known_gen + 1;
  const double *xy = c->xy;
  const double *pv = c->xy + 2 * (c->nv - 1), pp[2] = {pv[0], pv[1]}; /* p, the last vertex */
  while (sp > 0) {
    uint32_t t = stk[--sp];
    uint32_t n = N[3 * (size_t)t];
    if (with_undo) {
      if (S[3 * (size_t)t] != NONE) { /* final: a star triangle flips only across edge 0 */
        useg[nus++] = t;
        continue;
      }
      if (n == NONE) continue;
    } else if (n == NONE || S[3 * (size_t)t] != NONE)
      continue;
    int j;
    if (with_known && (known[n] | 1) == in) { /* stamped 2 gen (outside) or 2 gen + 1 */
      if (known[n] != in) continue;
      j = facing(c, n, t);
    } else if (with_undo || !with_known) {
      /* The same test as across_in's, written as the cavity search writes it: p against
       * n's circumcircle, n's corners in its own order (an even permutation, so the same
       * exact sign), p's coordinates loaded once for the loop; n's slot facing t is looked
       * up only for a flip (most tests keep the edge). */
      const uint32_t *nv = V + 3 * (size_t)n;
      if (!(qk__cdt_incircle(xy + 2 * (size_t)nv[0], xy + 2 * (size_t)nv[1], xy + 2 * (size_t)nv[2],
                             pp) > 0))
        continue;
      j = facing(c, n, t);
    } else {
      j = facing(c, n, t);
      if (!across_in_call(c, t, n, j)) continue;
    }
    if (with_undo) { /* what undo_flip0 needs besides the flipped pair */
      const uint32_t *tv = V + 3 * (size_t)t;
      undo[nu] = t, undo[nu + 1] = (uint32_t)j;
      undo[nu + 2] = vtri[tv[1]], undo[nu + 3] = vtri[tv[2]];
      nu += 4;
    }
    flip0(c, t, n, j, report);
    stk[sp++] = t, stk[sp++] = n;
  }
  if (with_undo) c->nundo = nu, c->nundo_seg = nus;
}

static void legalize(qk__cdt_t *c, int sp) {
  if (c->known)
    legalize_with(c, sp, 1, 0, 1);
  else if (c->undo)
    legalize_with(c, sp, 0, 1, 0);
  else
    legalize_with(c, sp, 0, 0, 1);
}
/* flip0(c, t, n, j) taken back, n = t's edge-1 neighbour, q's and r's vertex triangles
 * restored to vq and vr. After the flip t = (p, q, s) with neighbours (C, n, B) and n =
 * (p, s, r) with (D, A, t); before it t was (p, q, r) with (n, A, B), its edge 0
 * unconstrained, and n held s in slot j, r and q after it, with t, C, D across. */
static void undo_flip0(qk__cdt_t *c, uint32_t t, int j, uint32_t vq, uint32_t vr) {
  const int j1 = j == 2 ? 0 : j + 1, j2 = j == 0 ? 2 : j - 1;
  uint32_t *tv = c->v + 3 * (size_t)t, *tn = c->nbr + 3 * (size_t)t, *ts = c->seg + 3 * (size_t)t;
  const uint32_t n = tn[1];
  uint32_t *nv = c->v + 3 * (size_t)n, *nn = c->nbr + 3 * (size_t)n, *ns = c->seg + 3 * (size_t)n;
  const uint32_t p = tv[0], q = tv[1], s = tv[2], r = nv[2];
  const uint32_t C = tn[0], sC = ts[0], B = tn[2], sB = ts[2];
  const uint32_t D = nn[0], sD = ns[0], A = nn[1], sA = ns[1];
  set_tri(c, t, p, q, r, n, A, B, NONE, sA, sB);
  nv[j] = s, nv[j1] = r, nv[j2] = q;
  nn[j] = t, nn[j1] = C, nn[j2] = D;
  ns[j] = NONE, ns[j1] = sC, ns[j2] = sD;
  if (A != NONE) c->nbr[3 * (size_t)A + 2] = t;
  relink(c, C, t, n);
  c->vtri[q] = vq, c->vtri[r] = vr;
}

void qk__cdt_undo_insert(qk__cdt_t *c, uint32_t t) {
  const uint32_t *u = c->undo;
  assert(u && c->nundo >= 2 && (c->nundo - 2) % 4 == 0);
  for (size_t i = c->nundo; i > 2; i -= 4)
    undo_flip0(c, u[i - 4], (int)u[i - 3], u[i - 2], u[i - 1]);
  /* split3 taken back: t = (p, b, d), t1 = (p, d, a), t2 = (p, a, b), the last two slots. */
  const uint32_t t1 = (uint32_t)c->nt - 2, t2 = t1 + 1;
  const uint32_t *tv = c->v + 3 * (size_t)t, *v1 = c->v + 3 * (size_t)t1;
  assert(c->nbr[3 * (size_t)t + 1] == t1 && c->nbr[3 * (size_t)t + 2] == t2);
  const uint32_t a = v1[2], b = tv[1], d = tv[2];
  const uint32_t na = c->nbr[3 * (size_t)t], nb = c->nbr[3 * (size_t)t1],
                 nd = c->nbr[3 * (size_t)t2];
  const uint32_t sa = c->seg[3 * (size_t)t], sb = c->seg[3 * (size_t)t1],
                 sd = c->seg[3 * (size_t)t2];
  set_tri(c, t, a, b, d, na, nb, nd, sa, sb, sd);
  relink(c, nb, t1, t);
  relink(c, nd, t2, t);
  c->vtri[a] = u[1];
  c->nt -= 2, c->nv -= 1;
  c->hint = u[0];
  c->nundo = 0;
}

qk_status_t qk__cdt_insert(qk__cdt_t *c, double x, double y, uint32_t start, uint32_t *v_out,
                           int *existed) {
  uint32_t t;
  int k;
  *existed = 0;
  /* corners 0 and 2 are the square's; NaN fails the comparisons too */
  if (!(x >= c->xy[0] && x <= c->xy[4] && y >= c->xy[1] && y <= c->xy[5])) return QK_ERR_OUTSIDE;
  qk__cdt_where_t w = qk__cdt_locate(c, x, y, start, &t, &k);
  return qk__cdt_insert_at(c, x, y, t, k, w, v_out, existed);
}

qk_status_t qk__cdt_insert_at(qk__cdt_t *c, double x, double y, uint32_t t, int k,
                              qk__cdt_where_t w, uint32_t *v_out, int *existed) {
  *existed = 0;
  if (!(x >= c->xy[0] && x <= c->xy[4] && y >= c->xy[1] && y <= c->xy[5])) return QK_ERR_OUTSIDE;
  if (w == QK__CDT_VERT) {
    *v_out = c->v[3 * (size_t)t + k];
    *existed = 1;
    return QK_OK;
  }
  if (grow_vertices(c, c->nv + 1) != QK_OK || grow_triangles(c, c->nt + 2) != QK_OK)
    return QK_ERR_NOMEM;
  uint32_t p = (uint32_t)c->nv++;
  c->xy[2 * (size_t)p] = x, c->xy[2 * (size_t)p + 1] = y;
  if (c->undo) { /* (a point inside t: split3's changes are known from t's three slots) */
    assert(w == QK__CDT_IN);
    c->undo[0] = c->hint, c->undo[1] = c->vtri[c->v[3 * (size_t)t]];
    c->nundo = 2;
  }
  int sp = w == QK__CDT_IN ? split3(c, t, p, 1) : split_edge(c, t, k, p);
  if (sp == 4 && c->legal_sides) { /* stacked: t's side (t, t1), then the other's */
    if (!(c->legal_sides & 1)) c->stk[0] = c->stk[2], c->stk[1] = c->stk[3];
    sp = (c->legal_sides & 1 ? 2 : 0) + (c->legal_sides & 2 ? 2 : 0);
  }
  legalize(c, sp);
  c->hint = c->vtri[p];
  *v_out = p;
  return QK_OK;
}

qk_status_t qk__cdt_insert_in_undo(qk__cdt_t *c, double x, double y, uint32_t t, uint32_t *v_out) {
  assert(c->undo && !c->known && !c->legal_sides && !c->on_change);
  if (grow_vertices(c, c->nv + 1) != QK_OK || grow_triangles(c, c->nt + 2) != QK_OK)
    return QK_ERR_NOMEM;
  uint32_t p = (uint32_t)c->nv++;
  c->xy[2 * (size_t)p] = x, c->xy[2 * (size_t)p + 1] = y;
  c->undo[0] = c->hint, c->undo[1] = c->vtri[c->v[3 * (size_t)t]];
  c->nundo = 2;
  legalize_with(c, split3(c, t, p, 0), 0, 1, 0);
  c->hint = c->vtri[p];
  *v_out = p;
  return QK_OK;
}

/* ---- around a vertex ---------------------------------------------------------------- */

uint32_t qk__cdt_ring_next(const qk__cdt_t *c, qk__cdt_ring_t *r) {
  if (r->t == NONE) {
    r->t = r->first = c->vtri[r->a];
    r->ccw = 1;
    return r->t;
  }
  if (r->ccw) {
    uint32_t n = c->nbr[3 * (size_t)r->t + (qk__cdt_slot(c, r->t, r->a) + 1) % 3];
    if (n == r->first) return NONE;
    if (n != NONE) return r->t = n;
    r->ccw = 0;
    r->t = r->first;
  }
  uint32_t n = c->nbr[3 * (size_t)r->t + (qk__cdt_slot(c, r->t, r->a) + 2) % 3];
  if (n == NONE) return NONE;
  return r->t = n;
}

uint32_t qk__cdt_find_edge(const qk__cdt_t *c, uint32_t a, uint32_t b, int *k) {
  /* The turn of qk__cdt_ring_next, written out: one slot lookup a triangle instead of a call
   * and two lookups (the segments' insertion, the pre-split and the splits call this once
   * for every input segment or piece; on Norway the calls were 2% of the meshing). A
   * triangle holding b after a clockwise (edge b -> a) has ab's triangle across its edge
   * b-a, so the turn ends there too: the answer is the one triangle with the edge a -> b
   * whatever turns reach it. */
  const uint32_t *V = c->v, *N = c->nbr;
  const uint32_t first = c->vtri[a];
  uint32_t t = first;
  int ccw = 1;
  for (;;) {
    const uint32_t *tv = V + 3 * (size_t)t;
    const int i = tv[0] == a ? 0 : tv[1] == a ? 1 : 2;
    const int i1 = i == 2 ? 0 : i + 1, i2 = i == 0 ? 2 : i - 1;
    if (tv[i1] == b) return *k = i2, t;
    if (tv[i2] == b) {
      uint32_t u = N[3 * (size_t)t + i1];
      if (u == NONE) return NONE;
      const uint32_t *uv = V + 3 * (size_t)u;
      const int j = uv[0] == a ? 0 : uv[1] == a ? 1 : 2;
      return *k = j == 0 ? 2 : j - 1, u;
    }
    /* Counter-clockwise around a until back at the first triangle; at the square's edge,
     * clockwise from the first. */
    uint32_t n = N[3 * (size_t)t + (ccw ? i1 : i2)];
    if (ccw && n == first) return NONE;
    if (n == NONE) {
      if (!ccw) return NONE;
      ccw = 0;
      const uint32_t *fv = V + 3 * (size_t)first;
      const int f = fv[0] == a ? 0 : fv[1] == a ? 1 : 2;
      n = N[3 * (size_t)first + (f == 0 ? 2 : f - 1)];
      if (n == NONE) return NONE;
    }
    t = n;
  }
}
