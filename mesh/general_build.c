/*
 * The general mode, steps 2, 3, 7 and 8 (docs/mesh.md, "The general mode"): the root
 * square, the constrained Delaunay triangulation of the input vertices and segments (which
 * is also the validation: the CDT's exact predicates find duplicate vertices, vertices on
 * segments and crossing segments), and the faces: the unbounded one, holes and regions.
 */
#include "mesh/general_mesh.h"

#include <assert.h>
#include <math.h>
#include <stdlib.h>
#include <string.h>

/* The next room for `need` entries from `cap`: just `need` for a reservation (no slack),
 * else double, or `need` when that is more. */
static size_t fit_cap(size_t cap, size_t need, int exact) {
  return exact || need > 2 * cap ? need : 2 * cap;
}

qk_status_t qk__gm_fit_to(qk__gm_t *g, size_t nv, size_t nt, int exact) {
  /* Entries past the CDT's vertices and triangles hold their initial values (no vertex
   * or triangle has used them yet), so when those are fewer than half the room (a
   * reservation ahead), a new block takes the live entries only and initializes the rest:
   * a realloc may copy the whole old block (the mesher's arena does). */
  if (nv > g->vcap) {
    size_t c = fit_cap(g->vcap, nv, exact), live = g->cdt.nv < g->vcap ? g->cdt.nv : g->vcap;
    qk__gm_vert_t *p =
        qk__cdt_grow_live(g->a, g->vi, g->vcap * sizeof *p, c * sizeof *p, live * sizeof *p);
    if (!p) return QK_ERR_NOMEM;
    g->vi = p;
    const size_t from = 2 * live < g->vcap ? live : g->vcap; /* (a realloc kept the rest) */
    for (size_t i = from; i < c; i++) g->vi[i] = (qk__gm_vert_t){QK__CDT_NONE, QK__CDT_NONE, 0};
    g->vcap = c;
  }
  if (nt > g->fcap) {
    size_t c = fit_cap(g->fcap, nt, exact), live = g->cdt.nt < g->fcap ? g->cdt.nt : g->fcap;
    uint32_t *p =
        qk__cdt_grow_live(g->a, g->face, g->fcap * sizeof *p, c * sizeof *p, live * sizeof *p);
    if (!p) return QK_ERR_NOMEM;
    g->face = p;
    const size_t from = 2 * live < g->fcap ? live : g->fcap;    /* (a realloc kept the rest) */
    memset(g->face + from, 0xff, (c - from) * sizeof *g->face); /* QK__CDT_NONE */
    g->fcap = c;
  }
  return QK_OK;
}

uint64_t qk__gm_param(const qk__gm_t *g, uint32_t v, uint32_t s) {
  if (g->vi[v].seg == s) return g->vi[v].par;
  return g->vi[v].in == g->P->seg[2 * s] ? 0 : QK__GM_ONE;
}

/* The triangles around vertex v into g->dirty: after a point insertion, exactly those it
 * made or changed (the split makes triangles at v, and every Lawson flip replaces two
 * triangles at v by two others at v). The CDT's change hook reported the same set with
 * repeats (a triangle flipped twice came twice: a third more quality checks) and cost a
 * call a change. */
/* Room for one more triangle in g->dirty (out of line: rarely taken). */
#if defined(__GNUC__)
__attribute__((noinline, cold))
#endif
static qk_status_t
grow_dirty(qk__gm_t *g) {
  void *p = g->dirty;
  if (qk__grow(g->a, &p, &g->dirty_cap, g->ndirty + 16, sizeof *g->dirty)) return QK_ERR_NOMEM;
  g->dirty = p;
  return QK_OK;
}

static qk_status_t star(qk__gm_t *g, uint32_t v, uint32_t f) {
  const qk__cdt_t *c = &g->cdt;
  /* v lies strictly inside the square, so its star is a closed ring: counter-clockwise
   * across the edge after v in each triangle (edge 1: v is in slot 0 of each, mesh/cdt.h)
   * until back at the first. With f != NONE (one face all round) each triangle is labelled
   * on the way. */
  uint32_t first = c->vtri[v], t = first;
  size_t n = 0; /* the count in a register (g->ndirty is written back at the end) */
  do {
    if (n == g->dirty_cap) {
      g->ndirty = n;
      if (grow_dirty(g)) return QK_ERR_NOMEM;
    }
    g->dirty[n++] = t;
    if (f != QK__CDT_NONE) g->face[t] = f;
    assert(c->v[3 * (size_t)t] == v);
    t = c->nbr[3 * (size_t)t + 1];
  } while (t != first && t != QK__CDT_NONE);
  g->ndirty = n;
  g->dirty_v = v;
  return QK_OK;
}

qk_status_t qk__gm_insert(qk__gm_t *g, double x, double y, uint32_t t0, int k0, qk__cdt_where_t w,
                          uint32_t seg, uint64_t k, uint32_t *v_out, int *existed) {
  qk__cdt_t *c = &g->cdt;
  /* The faces on both sides of where the point goes: one face unless it splits a
   * constrained edge, whose line then tells the sides apart (every triangle the insertion
   * makes has the new vertex as a corner, so its other corners are on one side). */
  uint32_t f0 = g->face[t0], f1 = f0, ea = 0, eb = 0;
  g->ndirty = 0, g->star_pending = 0;
  if (w == QK__CDT_EDGE && c->seg[3 * t0 + k0] != QK__CDT_NONE) {
    uint32_t n = c->nbr[3 * t0 + k0];
    if (n != QK__CDT_NONE) f1 = g->face[n];
    ea = c->v[3 * t0 + (k0 + 1) % 3], eb = c->v[3 * t0 + (k0 + 2) % 3];
    /* A split segment between a kept and a dropped face (the coastline against the
     * outside), or inside dropped faces: the flips restore the kept side only. The dropped
     * side is never output, searched or refined, and flips never cross the segment, so
     * the kept side comes out the same; about half of such a split's in-circle tests. */
    int sides = (g->faces[f0].drop ? 0 : 1) | (g->faces[f1].drop ? 0 : 2);
    c->legal_sides = sides == 3 ? 0 : sides ? sides : 4; /* 4: neither side */
  }
  qk_status_t st = qk__cdt_insert_at(c, x, y, t0, k0, w, v_out, existed);
  c->legal_sides = 0; /* (both sides for every other insertion) */
  if (st) return st;
  if (qk__gm_fit(g)) return QK_ERR_NOMEM;
  if (*existed) return QK_OK;
  uint32_t v = *v_out;
  if (f0 == f1 && g->star_later)
    g->star_pending = 1, g->dirty_v = v; /* listed and labelled by the refinement's check */
  else if (star(g, v, f0 == f1 ? f0 : QK__CDT_NONE))
    return QK_ERR_NOMEM;
  g->vi[v] = (qk__gm_vert_t){QK__CDT_NONE, seg, k};
  g->dirty_face = f0 == f1 ? f0 : QK__CDT_NONE;
  if (f0 != f1) {
    /* The first triangle's side by the segment's line; then around the ring of triangles
     * at v (star() lists them in order), the side changes exactly where the ring crosses
     * one of the two halves of the split segment, the only constrained edges at v. */
    uint32_t t = g->dirty[0], f = f0;
    for (int j = 0; j < 3; j++) {
      uint32_t u = c->v[3 * t + j];
      if (u == v || u == ea || u == eb) continue; /* on the line: no side (and a slow zero) */
      int o = qk__orient2d(qk__gm_vxy(g, ea), qk__gm_vxy(g, eb), qk__gm_vxy(g, u));
      if (o) {
        f = o > 0 ? f0 : f1;
        break;
      }
    }
    g->face[t] = f;
    for (size_t i = 1; i < g->ndirty; i++) {
      /* edge 1, the one star() crossed from t (v is in slot 0) */
      if (c->seg[3 * (size_t)t + 1] != QK__CDT_NONE) f = f == f0 ? f1 : f0;
      t = g->dirty[i];
      g->face[t] = f;
    }
  }
  g->insertions++;
  return QK_OK;
}

qk_status_t qk__gm_star(qk__gm_t *g, uint32_t v, uint32_t f) { return star(g, v, f); }

/* Step 2: the root square, a power of two S = 2^e with corners at multiples of S / 4 (an
 * aligned square could not straddle zero), holding the input's bounding box grown by a
 * quarter of its extent on every side. */
static void root_square(qk__gm_t *g) {
  const qk_poly_t *P = g->P;
  double x0 = P->nv ? P->vx[0] : 0, x1 = x0, y0 = P->nv ? P->vy[0] : 0, y1 = y0;
  for (size_t i = 1; i < P->nv; i++) {
    x0 = fmin(x0, P->vx[i]), x1 = fmax(x1, P->vx[i]);
    y0 = fmin(y0, P->vy[i]), y1 = fmax(y1, P->vy[i]);
  }
  g->bx0 = x0, g->bx1 = x1, g->by0 = y0, g->by1 = y1;
  double w = fmax(x1 - x0, y1 - y0);
  if (!(w > 0)) w = fmax(fmax(fabs(x0), fabs(y0)), 1.0) * 0x1p-20;
  double lx = x0 - w / 4, hx = x1 + w / 4, ly = y0 - w / 4, hy = y1 + w / 4;
  int e;
  frexp(1.5 * w, &e);
  for (;; e++) {
    double S = ldexp(1.0, e), Q = S / 4, X0 = floor(lx / Q) * Q, Y0 = floor(ly / Q) * Q;
    if ((X0 + S > hx && Y0 + S > hy) || e > 1000) {
      g->S = S, g->e = e, g->X0 = X0, g->Y0 = Y0;
      return;
    }
  }
}

static unsigned long sline(const qk_poly_t *P, size_t s) { return P->sline ? P->sline[s] : 0; }
static unsigned long vline(const qk_poly_t *P, size_t v) { return P->vline ? P->vline[v] : 0; }

/* How far along the input's order walk_start looks for an inserted vertex near the next. */
#define GM_RING_REACH 8

/* Where the walk to input vertex i starts: at the last insertion (the CDT's hint), or at
 * input vertex i - 1 or i + 1 when one is inserted and nearer. Rings list their vertices
 * in order, so an index neighbour is usually a segment away, where the last insertion of
 * a round in Z-order may be a jump away (long walks across the thin triangles between
 * coastline vertices: 2,200 instructions a vertex on Norway). Returns that start's
 * triangle (the hint, or the neighbour's vtri), which the stochastic walk of a point on an
 * edge starts from, and in *u the vertex the walk starts from: the nearest of those and of
 * the inserted vertices i - GM_RING_REACH .. i + GM_RING_REACH. In the early rounds of the
 * randomized order i - 1 and i + 1 are seldom in yet, and a vertex a few places along the
 * ring is still far nearer than the last insertion (Norway: 1.48 M fewer instructions of
 * 54.3 M at extent/64 with a reach of 8; 6 and 10 gave 1.39 M and 1.46 M, the first
 * inserted vertex each way up to 16 places only 0.48 M). The walk's start changes only the
 * path: a point strictly inside a triangle ends in that triangle from any start, and a
 * point on an edge is located again from the returned triangle, as before, so the
 * triangulation and the mesh are the same. */
static uint32_t walk_start(const qk__gm_t *g, size_t i, uint32_t *u) {
  const qk_poly_t *P = g->P;
  const qk__cdt_t *c = &g->cdt;
  double x = P->vx[i], y = P->vy[i];
  uint32_t best = c->hint < c->nt ? c->hint : 0;
  *u = c->v[3 * (size_t)best];
  const double *h = &c->xy[2 * *u];
  double bd = (h[0] - x) * (h[0] - x) + (h[1] - y) * (h[1] - y);
  for (int d = -1; d <= 1; d += 2) {
    if ((d < 0 && i == 0) || (d > 0 && i + 1 >= P->nv)) continue;
    uint32_t w = g->cv[(size_t)((ptrdiff_t)i + d)];
    if (w == QK__CDT_NONE) continue;
    const double *q = &c->xy[2 * (size_t)w];
    double dd = (q[0] - x) * (q[0] - x) + (q[1] - y) * (q[1] - y);
    if (dd < bd) bd = dd, best = c->vtri[w], *u = w;
  }
  for (ptrdiff_t d = 2; d <= GM_RING_REACH; d++)
    for (int sg = -1; sg <= 1; sg += 2) {
      ptrdiff_t j = (ptrdiff_t)i + sg * d;
      if (j < 0 || j >= (ptrdiff_t)P->nv) continue;
      uint32_t w = g->cv[j];
      if (w == QK__CDT_NONE) continue;
      const double *q = &c->xy[2 * (size_t)w];
      double dd = (q[0] - x) * (q[0] - x) + (q[1] - y) * (q[1] - y);
      if (dd < bd) bd = dd, *u = w;
    }
  return best;
}

/* The input vertices in a biased randomized insertion order (Amenta, Choi and Rote): rounds
 * of geometrically growing size, drawn by a hash of the index, each in Z-order. In input
 * (or plain Z-) order, points along a coastline each flip a long fan of nearly cocircular
 * triangles: work grows like n^1.5 (12k instructions a vertex at 30,000); random rounds
 * keep the expected flips per insertion constant and Z-order keeps the walks short. */
static qk_status_t insert_vertices(qk__gm_t *g) {
  const qk_poly_t *P = g->P;
  qk__gm_pt_t *o = qk__realloc(g->a, NULL, 0, (P->nv + 1) * sizeof *o);
  if (!o) return qk__mesh_fail(g->err, QK_ERR_NOMEM, 0, "out of memory");
  for (size_t i = 0; i < P->nv; i++) {
    uint64_t h = ((uint64_t)i + 1) * 0x9E3779B97F4A7C15ull;
    h ^= h >> 31, h *= 0xBF58476D1CE4E5B9ull, h ^= h >> 29;
    int r = 0;
    while (r < 30 && !((h >> r) & 1)) r++; /* round r holds about n / 2^(r+1) points */
    uint64_t key = (uint64_t)(31 - r) << 59 | qk__gm_morton(g, P->vx[i], P->vy[i]) >> 5;
    o[i] = (qk__gm_pt_t){key, P->vx[i], P->vy[i], i, 0, 0};
  }
  qk_status_t st = P->nv ? qk__gm_sort_points(g, o, P->nv) : QK_OK;
  for (size_t j = 0; j < P->nv && !st; j++) {
    size_t i = (size_t)o[j].k;
    uint32_t v;
    int existed;
    double x = P->vx[i], y = P->vy[i];
    /* Located from the start vertex (the nearest of the last insertion and the ring
     * neighbours; no segment is inserted yet, so the triangulation is Delaunay). A point on
     * an edge is located again by the stochastic walk from the start's triangle, which
     * picks the side of the edge the insertion splits from (and so the triangles'
     * numbering) as before. */
    uint32_t u, t0 = walk_start(g, i, &u), t;
    int k;
    qk__cdt_where_t w = qk__cdt_locate_delaunay(&g->cdt, x, y, u, &t, &k);
    if (w == QK__CDT_EDGE) w = qk__cdt_locate(&g->cdt, x, y, t0, &t, &k);
    if ((st = qk__cdt_insert_at(&g->cdt, x, y, t, k, w, &v, &existed)) || (st = qk__gm_fit(g))) {
      st = qk__mesh_fail(g->err, QK_ERR_NOMEM, 0, "out of memory");
    } else if (existed) {
      /* Name the pair in input order. */
      size_t a = g->vi[v].in < i ? g->vi[v].in : i, b = g->vi[v].in < i ? i : g->vi[v].in;
      st = qk__mesh_fail(g->err, QK_ERR_GEOMETRY, vline(P, b),
                         "vertices %lu and %lu coincide at (%.17g, %.17g)", qk__mesh_num(P, a),
                         qk__mesh_num(P, b), x + 0.0, y + 0.0);
    } else {
      g->vi[v].in = (uint32_t)i;
      g->cv[i] = v;
    }
  }
  qk__free(g->a, o, (P->nv + 1) * sizeof *o);
  return st;
}

/* Touching input: segment s changed (split or merged; see qk__gm_t's touch). */
static qk_status_t note_change(qk__gm_t *g, size_t s) {
  if (!g->schg) {
    g->schg = qk__realloc(g->a, NULL, 0, g->P->ns + 1);
    if (!g->schg) return QK_ERR_NOMEM;
    memset(g->schg, 0, g->P->ns + 1);
  }
  g->schg[s] = 1;
  return QK_OK;
}

/* Room for `need` entries in g->stack. */
static qk_status_t stack_room(qk__gm_t *g, size_t need) {
  void *p = g->stack;
  if (qk__grow(g->a, &p, &g->stack_cap, need, sizeof *g->stack)) return QK_ERR_NOMEM;
  g->stack = p;
  return QK_OK;
}

/* Touching input: a piece a-b (input vertices) of changed segment s kept. */
static qk_status_t add_piece(qk__gm_t *g, size_t s, uint32_t a, uint32_t b) {
  if (3 * (g->npieces + 1) > g->pieces_cap) {
    void *p = g->pieces;
    if (qk__grow(g->a, &p, &g->pieces_cap, 3 * (g->npieces + 1), sizeof *g->pieces))
      return QK_ERR_NOMEM;
    g->pieces = p;
  }
  uint32_t *e = &g->pieces[3 * g->npieces++];
  e[0] = (uint32_t)s, e[1] = a, e[2] = b;
  return QK_OK;
}

/* What insert_piece did with a piece of a segment. */
enum { PIECE_IN, PIECE_MERGED, PIECE_SPLIT, PIECE_FAILED };

/* Touching input: the most splits (times a vertex lies inside a segment or piece) the
 * validation makes before refusing. Each costs a walk, and an input can ask for one a
 * (vertex, segment) pair: N segments along a line through N vertices, N^2 / 2 (8.6 s at N =
 * 16,000); real touching input (shared borders, T-junctions) needs a few an item. */
static size_t touch_cap(const qk_poly_t *P) { return ((size_t)1 << 16) + 16 * (P->nv + P->ns); }

/* insert_piece's cases other than a piece inserted (out of line: the loop over a
 * coastline's segments met none of them and paid for their registers and messages). t and
 * k: the edge a-b if there is one (constrained); else st, block and bseg are what
 * qk__cdt_insert_segment returned. */
#if defined(__GNUC__)
__attribute__((noinline, cold))
#endif
static int
piece_trouble(qk__gm_t *g, size_t s, uint32_t a, uint32_t b, uint32_t t, int k, qk_status_t st,
              uint32_t block, uint32_t bseg, uint32_t *vi, qk_status_t *out) {
  const qk_poly_t *P = g->P;
  const unsigned long ls = sline(P, s);
  char n1[80], n2[80];
  if (t != QK__CDT_NONE) { /* a-b is a constrained edge already: a repeat */
    if (g->touch) {
      if (note_change(g, s)) goto nomem;
      g->nmerged++;
      return PIECE_MERGED;
    }
    uint32_t o = g->cdt.seg[3 * t + k];
    *out =
        qk__mesh_fail(g->err, QK_ERR_GEOMETRY, ls, "%s and %s both join vertices %lu and %lu",
                      qk__gm_sname(P, "segments", o, sline(P, o), n1),
                      qk__gm_sname(P, "", s, ls, n2) + 1, qk__mesh_num(P, a), qk__mesh_num(P, b));
    return PIECE_FAILED;
  }
  if (st == QK_ERR_NOMEM) goto nomem;
  if (bseg != QK__CDT_NONE) {
    g->crossing = 1;
    *out = qk__mesh_fail(g->err, QK_ERR_GEOMETRY, ls, "%s and %s cross or overlap",
                         qk__gm_sname(P, "segments", bseg, sline(P, bseg), n1),
                         qk__gm_sname(P, "", s, ls, n2) + 1);
    return PIECE_FAILED;
  }
  *vi = block < g->vcap ? g->vi[block].in : QK__CDT_NONE;
  if (*vi == QK__CDT_NONE) {
    *out = qk__mesh_fail(g->err, QK_ERR_GEOMETRY, ls, "%s is blocked",
                         qk__gm_sname(P, "segment", s, ls, n2));
    return PIECE_FAILED;
  }
  /* A touch that rounding may have made (qk_poly_round moved the vertex or the segment's
   * ends) changed the input's shape: refused as without touch. */
  const uint32_t u = P->seg[2 * s], w = P->seg[2 * s + 1];
  const int moved = P->vmoved && (P->vmoved[*vi] > 0 || P->vmoved[u] > 0 || P->vmoved[w] > 0);
  if (!g->touch || moved) {
    *out = qk__mesh_fail(g->err, QK_ERR_GEOMETRY, ls, "%s at (%.17g, %.17g) lies on %s",
                         qk__gm_name(P, "vertex", *vi, vline(P, *vi), n1), P->vx[*vi] + 0.0,
                         P->vy[*vi] + 0.0, qk__gm_sname(P, "segment", s, ls, n2));
    return PIECE_FAILED;
  }
  if (note_change(g, s)) goto nomem;
  if (++g->nsplit > touch_cap(P)) {
    *out = qk__mesh_fail(g->err, QK_ERR_LIMIT, ls,
                         "%zu times a vertex lies inside a segment (%s and others): more than "
                         "%zu (2^16 + 16 an input vertex and segment), which many segments "
                         "overlapping along a line with many vertices on it would need; merge "
                         "such segments before meshing",
                         g->nsplit, qk__gm_sname(P, "segment", s, ls, n2), touch_cap(P));
    return PIECE_FAILED;
  }
  return PIECE_SPLIT;
nomem:
  *out = qk__mesh_fail(g->err, QK_ERR_NOMEM, 0, "out of memory");
  return PIECE_FAILED;
}

/* Piece a-b (input vertices) of segment s as a constrained edge: PIECE_IN; with g->touch,
 * PIECE_MERGED when an earlier segment or piece joins a and b, PIECE_SPLIT with *vi when
 * input vertex *vi lies inside it (nothing inserted then); PIECE_FAILED with *st and the
 * message otherwise (a repeat or a vertex inside without touch, a crossing). */
static inline int insert_piece(qk__gm_t *g, size_t s, uint32_t a, uint32_t b, uint32_t *vi,
                               qk_status_t *st) {
  qk__cdt_t *c = &g->cdt;
  int k;
  uint32_t t = qk__cdt_find_edge(c, g->cv[a], g->cv[b], &k);
  if (t != QK__CDT_NONE) {
    if (c->seg[3 * t + k] != QK__CDT_NONE)
      return piece_trouble(g, s, a, b, t, k, QK_OK, QK__CDT_NONE, QK__CDT_NONE, vi, st);
    /* Already an edge (most of a coastline's segments): marked here, rather than found a
     * second time by qk__cdt_insert_segment. */
    qk__cdt_mark_segment(c, t, k, (uint32_t)s);
    return PIECE_IN;
  }
  uint32_t block = QK__CDT_NONE, bseg = QK__CDT_NONE;
  qk_status_t r = qk__cdt_insert_segment(c, g->cv[a], g->cv[b], (uint32_t)s, &block, &bseg);
  if (!r) return PIECE_IN;
  return piece_trouble(g, s, a, b, QK__CDT_NONE, 0, r, block, bseg, vi, st);
}

/* Touching input: segment s, split at input vertex vi, inserted piece by piece from its
 * first vertex u to w (a stack of pieces in g->stack), each piece kept (add_piece) or
 * merged, or split again. */
static qk_status_t split_segment(qk__gm_t *g, size_t s, uint32_t u, uint32_t w, uint32_t vi) {
  size_t sp = 0;
  if (stack_room(g, 4)) return qk__mesh_fail(g->err, QK_ERR_NOMEM, 0, "out of memory");
  g->stack[sp++] = vi, g->stack[sp++] = w, g->stack[sp++] = u, g->stack[sp++] = vi;
  while (sp) {
    const uint32_t b = g->stack[--sp], a = g->stack[--sp];
    uint32_t v;
    qk_status_t st = QK_OK;
    switch (insert_piece(g, s, a, b, &v, &st)) {
    case PIECE_IN:
      if (add_piece(g, s, a, b)) return qk__mesh_fail(g->err, QK_ERR_NOMEM, 0, "out of memory");
      break;
    case PIECE_SPLIT: /* a-v first, then v-b */
      if (stack_room(g, sp + 4)) return qk__mesh_fail(g->err, QK_ERR_NOMEM, 0, "out of memory");
      g->stack[sp++] = v, g->stack[sp++] = b, g->stack[sp++] = a, g->stack[sp++] = v;
      break;
    case PIECE_FAILED:
      return st;
    default: /* PIECE_MERGED */
      break;
    }
  }
  return QK_OK;
}

/* The input segments as constrained edges. A segment joining the vertices of an earlier
 * one is a repeat; a vertex blocking its way lies inside it; a constrained edge blocking
 * its way crosses (or overlaps) it. Without g->touch each is refused, naming both. With
 * it, a repeat is merged into the earlier segment and a vertex inside splits the segment
 * there, its pieces then inserted in order from its first vertex (split_segment), and
 * only crossings are refused: two segments that overlap along a stretch always have a
 * vertex of one inside the other (the vertices are all in before any segment), so they
 * become shared pieces, merged. */
static qk_status_t insert_segments(qk__gm_t *g) {
  const qk_poly_t *P = g->P;
  for (size_t s = 0; s < P->ns; s++) {
    uint32_t u = P->seg[2 * s], w = P->seg[2 * s + 1], vi;
    if (u == w)
      return qk__mesh_fail(g->err, QK_ERR_GEOMETRY, sline(P, s),
                           "segment %lu joins vertex %lu to itself", qk__mesh_snum(P, s),
                           qk__mesh_num(P, u));
    qk_status_t st = QK_OK;
    const int r = insert_piece(g, s, u, w, &vi, &st);
    if (r == PIECE_FAILED) return st;
    if (r == PIECE_SPLIT && (st = split_segment(g, s, u, w, vi))) return st;
  }
  return QK_OK;
}

static qk_status_t new_face(qk__gm_t *g, uint32_t *f) {
  void *p = g->faces;
  if (qk__grow(g->a, &p, &g->nface_cap, g->nface + 1, sizeof *g->faces)) return QK_ERR_NOMEM;
  g->faces = p;
  *f = g->nface++;
  g->faces[*f] = (qk__gm_face_t){0, 0, 0};
  return QK_OK;
}

/* Step 8: the faces are the parts of the square between constrained edges, found by
 * flooding over unconstrained edges; face 0, the one holding the square's corners, is the
 * unbounded face. */
static qk_status_t label_faces(qk__gm_t *g) {
  qk__cdt_t *c = &g->cdt;
  void *p = g->stack;
  if (qk__grow(g->a, &p, &g->stack_cap, c->nt + 1, sizeof *g->stack)) return QK_ERR_NOMEM;
  g->stack = p;
  for (size_t i = 0; i <= c->nt; i++) {
    uint32_t t0 = i == 0 ? c->vtri[0] : (uint32_t)(i - 1);
    if (g->face[t0] != QK__CDT_NONE) continue;
    uint32_t f;
    if (new_face(g, &f)) return QK_ERR_NOMEM;
    size_t n = 0;
    g->stack[n++] = t0;
    g->face[t0] = f;
    while (n) {
      uint32_t t = g->stack[--n];
      for (int k = 0; k < 3; k++) {
        uint32_t u = c->nbr[3 * t + k];
        if (u == QK__CDT_NONE || c->seg[3 * t + k] != QK__CDT_NONE || g->face[u] != QK__CDT_NONE)
          continue;
        g->face[u] = f;
        g->stack[n++] = u;
      }
    }
  }
  g->faces[0].drop = 1;
  return QK_OK;
}

/* The face holding a hole or region point, or NONE outside the square; a point on a
 * segment or a vertex is refused (its face is ambiguous). */
static qk_status_t point_face(qk__gm_t *g, double x, double y, const char *what, unsigned long num,
                              unsigned long line, uint32_t *f) {
  qk__cdt_t *c = &g->cdt;
  *f = QK__CDT_NONE;
  if (!(x > g->X0 && x < g->X0 + g->S && y > g->Y0 && y < g->Y0 + g->S)) return QK_OK;
  uint32_t t;
  int k;
  qk__cdt_where_t w = qk__cdt_locate(c, x, y, QK__CDT_NONE, &t, &k);
  if (w == QK__CDT_EDGE && c->seg[3 * t + k] != QK__CDT_NONE)
    return qk__mesh_fail(g->err, QK_ERR_GEOMETRY, line,
                         "%s %lu at (%.17g, %.17g) lies on segment %lu", what, num, x, y,
                         qk__mesh_snum(g->P, c->seg[3 * t + k]));
  if (w == QK__CDT_VERT) {
    uint32_t vi = g->vi[c->v[3 * t + k]].in;
    return qk__mesh_fail(g->err, QK_ERR_GEOMETRY, line, "%s %lu at (%.17g, %.17g) is vertex %lu",
                         what, num, x, y, qk__mesh_num(g->P, vi == QK__CDT_NONE ? 0 : vi));
  }
  *f = g->face[t];
  return QK_OK;
}

static qk_status_t holes_and_regions(qk__gm_t *g) {
  const qk_poly_t *P = g->P;
  uint32_t f;
  for (size_t h = 0; h < P->nh; h++) {
    unsigned long line = P->hline ? P->hline[h] : 0;
    qk_status_t st = point_face(g, P->hx[h], P->hy[h], "hole", qk__mesh_num(P, h), line, &f);
    if (st) return st;
    if (f != QK__CDT_NONE) g->faces[f].drop = 1;
  }
  for (size_t r = 0; r < P->nr; r++) {
    const qk__region_pt_t *q = &P->reg[r];
    qk_status_t st =
        point_face(g, q->x, q->y, "regional attribute", qk__mesh_num(P, r), q->line, &f);
    if (st) return st;
    if (f != QK__CDT_NONE) g->faces[f].attr = q->attr;
  }
  return QK_OK;
}

/* The smallest angle between two segments at a vertex, in degrees (180 when none). The
 * segments' directions are bucketed by vertex (a counting pass, no comparison sort: most
 * vertices have two) and each vertex's few sorted by insertion once all are in. */
static qk_status_t input_angles(qk__gm_t *g) {
  const qk_poly_t *P = g->P;
  g->smallest_input_angle = 180;
  g->vsmall = qk__realloc(g->a, NULL, 0, P->nv + 1);
  if (!g->vsmall) return QK_ERR_NOMEM;
  memset(g->vsmall, 0, P->nv + 1);
  if (P->ns < 2) return QK_OK;
  uint32_t *start = qk__realloc(g->a, NULL, 0, (P->nv + 2) * sizeof *start);
  uint32_t *nb = qk__realloc(g->a, NULL, 0, 2 * P->ns * sizeof *nb);
  double *d = qk__realloc(g->a, NULL, 0, 2 * P->ns * sizeof *d);
  if (!start || !nb || !d) {
    qk__free(g->a, start, (P->nv + 2) * sizeof *start);
    qk__free(g->a, nb, 2 * P->ns * sizeof *nb);
    qk__free(g->a, d, 2 * P->ns * sizeof *d);
    return QK_ERR_NOMEM;
  }
  memset(start, 0, (P->nv + 2) * sizeof *start);
  for (size_t j = 0; j < 2 * P->ns; j++) start[P->seg[j] + 2]++;
  for (size_t v = 0; v < P->nv; v++) start[v + 2] += start[v + 1];
  /* start[v + 1] is now where vertex v's neighbours go; filling moves it to their end. */
  for (size_t s = 0; s < P->ns; s++)
    for (int j = 0; j < 2; j++) nb[start[P->seg[2 * s + j] + 1]++] = P->seg[2 * s + 1 - j];
  const double pi = 3.14159265358979323846;
  for (size_t v = 0; v < P->nv; v++) {
    size_t i = start[v], e = start[v + 1];
    if (i == e) continue;
    const double vx = P->vx[v], vy = P->vy[v];
    if (e - i == 2) {
      /* Two segments (every vertex of a ring): the smaller of the two angles between them,
       * one atan2 instead of one a direction (0.55 M instructions of 55 M on Norway at
       * extent/64 went to atan2 here). The same angle as the gaps between the sorted
       * directions below, to rounding far below the 0.001 degree margin of vsmall. */
      double ux = P->vx[nb[i]] - vx, uy = P->vy[nb[i]] - vy;
      double wx = P->vx[nb[i + 1]] - vx, wy = P->vy[nb[i + 1]] - vy;
      double dot = ux * wx + uy * wy;
      /* A negative dot gives atan2 at least pi/2 (less a rounding), so an angle of 90
       * degrees to 1e-14: neither small nor below a smallest angle already under 89.99,
       * which fmin would keep. Most vertices of a coastline are such (Norway: atan2 was
       * 0.8% of the meshing at extent/256); the values are those of computing every one. */
      if (dot < 0 && g->smallest_input_angle < 89.99) continue; /* (vsmall[v] stays 0) */
      double amin = atan2(fabs(ux * wy - uy * wx), dot) * 180 / pi;
      g->smallest_input_angle = fmin(g->smallest_input_angle, amin);
      g->vsmall[v] = amin < 60.001;
      continue;
    }
    for (size_t j = i; j < e; j++) d[j] = atan2(P->vy[nb[j]] - vy, P->vx[nb[j]] - vx);
    for (size_t j = i + 1; j < e; j++) {
      double a = d[j];
      size_t k = j;
      for (; k > i && d[k - 1] > a; k--) d[k] = d[k - 1];
      d[k] = a;
    }
    double amin = 360;
    for (size_t j = i + 1; j < e; j++) amin = fmin(amin, (d[j] - d[j - 1]) * 180 / pi);
    if (e - i >= 2) amin = fmin(amin, (d[i] + 2 * pi - d[e - 1]) * 180 / pi);
    g->smallest_input_angle = fmin(g->smallest_input_angle, amin);
    /* Concentric shells at the apexes of small angles only: elsewhere every split is an
     * exact midpoint, as in the proof for angles of 60 degrees and more. The estimate
     * errs by far less than the margin the proof has (a vertex at 59.999 degrees gets
     * shells, harmlessly). */
    g->vsmall[v] = amin < 60.001;
  }
  qk__free(g->a, start, (P->nv + 2) * sizeof *start);
  qk__free(g->a, nb, 2 * P->ns * sizeof *nb);
  qk__free(g->a, d, 2 * P->ns * sizeof *d);
  return QK_OK;
}

qk_status_t qk__gm_check_input(qk__gm_t *g) {
  const qk_poly_t *P = g->P;
  root_square(g);
  /* The in-circle test squares squared distances: beyond 2^250 they overflow (its filter
   * and its exact fallback alike), and a triangulation built on wrong answers can make
   * the point location walk forever; far below 2^-200 they underflow. */
  if (!(g->e <= 250 && g->e >= -200))
    return qk__mesh_fail(g->err, QK_ERR_LIMIT, 0,
                         "the input's extent %.17g x %.17g is %s: the exact predicates would "
                         "%s (scale the coordinates)",
                         g->bx1 - g->bx0, g->by1 - g->by0,
                         g->e > 250 ? "above 2^250 (about 1.8e75)" : "below 2^-200",
                         g->e > 250 ? "overflow" : "underflow");
  qk_status_t st = qk__cdt_init(&g->cdt, g->a, g->X0, g->Y0, g->S, 8 * P->nv + 16);
  if (st) return qk__mesh_fail(g->err, st, 0, "out of memory");
  g->cdt_live = 1;
  g->cv = qk__realloc(g->a, NULL, 0, (P->nv + 1) * sizeof *g->cv);
  if (!g->cv || qk__gm_fit_to(g, g->cdt.cap_v, g->cdt.cap_t, 1))
    return qk__mesh_fail(g->err, QK_ERR_NOMEM, 0, "out of memory");
  memset(g->cv, 0xff, (P->nv + 1) * sizeof *g->cv); /* QK__CDT_NONE: not inserted yet */
  if ((st = insert_vertices(g))) return st;
  return insert_segments(g);
}

double qk__gm_area(qk__gm_t *g) {
  if (g->area_known) return g->area;
  const qk__cdt_t *c = &g->cdt;
  double area = 0;
  for (size_t t = 0; t < c->nt; t++) {
    if (g->faces[g->face[t]].drop) continue;
    const uint32_t *tv = &c->v[3 * t];
    const double *A = &c->xy[2 * tv[0]], *B = &c->xy[2 * tv[1]], *C = &c->xy[2 * tv[2]];
    area += (B[0] - A[0]) * (C[1] - A[1]) - (B[1] - A[1]) * (C[0] - A[0]); /* (CCW: > 0) */
  }
  g->area = area / 2, g->area_known = 1;
  return g->area;
}

qk_status_t qk__gm_build(qk__gm_t *g) {
  qk_status_t st = qk__gm_check_input(g);
  if (st) return st;
  if (qk__gm_fit(g) || label_faces(g) || input_angles(g))
    return qk__mesh_fail(g->err, QK_ERR_NOMEM, 0, "out of memory");
  if ((st = holes_and_regions(g))) return st;
  /* From here on every insertion goes through qk__gm_insert, which lists the triangles it
   * changed (the new vertex's star) for labelling and the quality checks. */
  return QK_OK;
}
