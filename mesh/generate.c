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

static double now(void) {
  struct timespec ts;
  if (timespec_get(&ts, TIME_UTC) != TIME_UTC) return 0;
  return (double)ts.tv_sec + 1e-9 * (double)ts.tv_nsec;
}

void qk_mesh_options_init(qk_mesh_options_t *o) {
  if (!o) return;
  o->size = 0;
  o->allocator = NULL;
  o->mode = QK_MESH_AUTO;
  o->max_size = 0;
  o->size_fn = NULL;
  o->size_user = NULL;
  o->min_angle_deg = 0;
}

static void gen_free(qk__gen_t *g) {
  qk__free(g->a, g->e, (g->poly->ns ? g->poly->ns : 1) * sizeof *g->e);
  qk__free(g->a, g->arena, g->arena_cap * sizeof *g->arena);
  qk__free(g->a, g->box, (g->ne ? g->ne : 1) * sizeof *g->box);
  qk__free(g->a, g->rec, g->rec_cap * sizeof *g->rec);
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
  qk__free(&a, m->vmark, (m->nv + 1) * sizeof *m->vmark);
  qk__free(&a, m->oseg, m->noseg_cap * sizeof *m->oseg);
  qk__free(&a, m->attr, (m->nt + 1) * sizeof *m->attr);
  if (m->arena) {
    qk__mesh_arena_free(m->arena);
    free(m);
  } else
    qk__free(&a, m, sizeof *m);
}

/* Angle at b of triangle a-b-c, in degrees. */
static double angle_deg(const int64_t *vx, const int64_t *vy, uint32_t a, uint32_t b, uint32_t c) {
  double ux = (double)(vx[a] - vx[b]), uy = (double)(vy[a] - vy[b]);
  double wx = (double)(vx[c] - vx[b]), wy = (double)(vy[c] - vy[b]);
  return atan2(fabs(ux * wy - uy * wx), ux * wx + uy * wy) * (180.0 / 3.14159265358979323846);
}

/*
 * A quadtree mesh has few triangle shapes: right isosceles ones in a few orientations, at
 * one size per tree level. Its three angles are a function of the triangle's two edge
 * vectors from its first vertex (every difference angle_deg takes is an exact integer
 * combination of them), so a small direct-mapped table keyed on those vectors gives the
 * smallest and largest angle as the three atan2 calls would, at a fraction of their cost.
 */
#define SHAPE_MEMO 256
typedef struct shape_memo {
  int64_t key[SHAPE_MEMO][4];
  double lo[SHAPE_MEMO], hi[SHAPE_MEMO];
} shape_memo_t;

static void shape_memo_init(shape_memo_t *sm) {
  /* Differences of lattice coordinates are far from INT64_MIN: no triangle has this key. */
  for (size_t j = 0; j < SHAPE_MEMO; j++)
    for (int i = 0; i < 4; i++) sm->key[j][i] = INT64_MIN;
}

/* The smallest and largest angle of triangle tr (degrees) into *lo and *hi. */
static void shape_angles(shape_memo_t *sm, const int64_t *vx, const int64_t *vy, const uint32_t *tr,
                         double *lo, double *hi) {
  int64_t k[4] = {vx[tr[1]] - vx[tr[0]], vy[tr[1]] - vy[tr[0]], vx[tr[2]] - vx[tr[0]],
                  vy[tr[2]] - vy[tr[0]]};
  uint64_t h = (uint64_t)k[0] * 0x9e3779b97f4a7c15ull ^ (uint64_t)k[1] * 0xc2b2ae3d27d4eb4full ^
               (uint64_t)k[2] * 0x165667b19e3779f9ull ^ (uint64_t)k[3] * 0x27d4eb2f165667c5ull;
  size_t j = (size_t)(h >> 56) & (SHAPE_MEMO - 1);
  int64_t *e = sm->key[j];
  if (e[0] != k[0] || e[1] != k[1] || e[2] != k[2] || e[3] != k[3]) {
    double amin = 180, amax = 0;
    for (int i = 0; i < 3; i++) {
      double ang = angle_deg(vx, vy, tr[(i + 2) % 3], tr[i], tr[(i + 1) % 3]);
      if (ang < amin) amin = ang;
      if (ang > amax) amax = ang;
    }
    memcpy(e, k, sizeof k), sm->lo[j] = amin, sm->hi[j] = amax;
  }
  *lo = sm->lo[j], *hi = sm->hi[j];
}

/* Check the options and fill *opt with them (defaults for NULL). */
static qk_status_t read_options(const qk_mesh_options_t *options, qk_mesh_options_t *opt,
                                qk_mesh_error_t *err) {
  qk_mesh_options_init(opt);
  if (options) *opt = *options;
  if (opt->size && ((opt->size & (opt->size - 1)) || opt->size > QK_MESH_MAX_SIZE))
    return qk__mesh_fail(err, QK_ERR_INVALID, 0,
                         "domain size %llu is not a power of two between 1 and 2^30",
                         (unsigned long long)opt->size);
  if (opt->mode != QK_MESH_AUTO && opt->mode != QK_MESH_BOOK && opt->mode != QK_MESH_DYADIC &&
      opt->mode != QK_MESH_GENERAL)
    return qk__mesh_fail(err, QK_ERR_INVALID, 0, "unknown mode %d", (int)opt->mode);
  if (!(opt->max_size >= 0) || isinf(opt->max_size))
    return qk__mesh_fail(err, QK_ERR_INVALID, 0, "max_size %g is not a finite length >= 0",
                         opt->max_size);
  if (!(opt->min_angle_deg >= 0 && opt->min_angle_deg <= 45))
    return qk__mesh_fail(err, QK_ERR_INVALID, 0, "min_angle_deg %g is not between 0 and 45",
                         opt->min_angle_deg);
  if (opt->mode == QK_MESH_GENERAL && opt->size)
    return qk__mesh_fail(err, QK_ERR_INVALID, 0,
                         "a domain size applies to the book's mode only (the general mode's "
                         "domain is the input's bounded faces)");
  if (opt->mode == QK_MESH_DYADIC && opt->size)
    return qk__mesh_fail(err, QK_ERR_INVALID, 0,
                         "a domain size applies to the book's mode only (the dyadic mode's "
                         "domain is the input's bounding square)");
  return QK_OK;
}

/* The book's mode: asked for, or (automatically) for integer inputs with no size bound,
 * and whenever a domain size is given. */
static int use_book(const qk_poly_t *P, const qk_mesh_options_t *o) {
  if (o->mode != QK_MESH_AUTO) return o->mode == QK_MESH_BOOK;
  if (o->size) return 1;
  if (o->max_size > 0 || o->size_fn) return 0;
  for (size_t i = 0; i < P->nv; i++)
    if (P->vx[i] != floor(P->vx[i]) || P->vy[i] != floor(P->vy[i])) return 0;
  return 1;
}

/*
 * Whether the book's or the dyadic mode (the one use_book() picks, in *book) can mesh the
 * input: its vertices on a lattice the mode accepts, every segment at 0, 45, 90 or 135
 * degrees and every vertex of degree two. Integer input the book's mode cannot take (a
 * vertex outside [0, 2^30]^2, or a mesh too large) goes to the dyadic mode, whose lattice
 * has an origin of its own (*book is cleared): a translated input keeps its proven angles.
 * QK_MESH_AUTO runs the general mode otherwise. The remaining conditions (no crossings,
 * hole points inside) are errors in every mode, so the classic mode reports them. *ok is
 * set; QK_ERR_NOMEM is the only failure.
 */
static qk_status_t classic_ok(const qk_poly_t *P, const qk_mesh_options_t *o, int *book,
                              const qk_allocator_t *a, int *ok) {
  *ok = 0;
  if (*book) {
    for (size_t i = 0; i < P->nv && *book; i++)
      if (!(P->vx[i] >= 0 && P->vy[i] >= 0 && P->vx[i] <= (double)QK_MESH_MAX_SIZE &&
            P->vy[i] <= (double)QK_MESH_MAX_SIZE))
        *book = 0;
    if (*book && qk__mesh_book_limit(P, o, 0, NULL)) *book = 0;
  }
  if (!*book) {
    /* What the dyadic mode refuses (through qk__mesh_lattice) goes to the general mode. */
    qk__lattice_t L;
    qk_mesh_error_t e;
    if (qk__mesh_lattice(P, o, 0, &L, &e)) return QK_OK;
  }
  /* On a lattice the mode accepts, coordinate differences are exact. */
  for (size_t s = 0; s < P->ns; s++) {
    uint32_t u = P->seg[2 * s], v = P->seg[2 * s + 1];
    double dx = P->vx[v] - P->vx[u], dy = P->vy[v] - P->vy[u];
    if (!(dx == 0 || dy == 0 || fabs(dx) == fabs(dy))) return QK_OK;
  }
  uint8_t *deg = qk__realloc(a, NULL, 0, P->nv + 1);
  if (!deg) return QK_ERR_NOMEM;
  memset(deg, 0, P->nv + 1);
  for (size_t s = 0; s < 2 * P->ns; s++)
    if (deg[P->seg[s]] < 3) deg[P->seg[s]]++;
  int all2 = 1;
  for (size_t i = 0; i < P->nv; i++) all2 &= deg[i] == 2;
  qk__free(a, deg, P->nv + 1);
  *ok = all2;
  return QK_OK;
}

/* Are the unit-leaf records in increasing node order? They are as made: a unit leaf is a
 * child of a square of side 2, whose four children get consecutive new ids when it is
 * split, and the depth-first subdivision splits those squares, and records their
 * children, in the order it meets them. Checked, so that the sort stays as the fallback
 * (node ids are the tree's business). */
static int recs_sorted(const qk__gen_t *g) {
  for (size_t i = 1; i < g->nrec; i++)
    if (g->rec[i - 1].node >= g->rec[i].node) return 0;
  return 1;
}

/* Step 1: the subdivision is a quadkit tree over the root square [0,U]^2 with no points,
 * split by qk__mesh_subdivide() from the list of every edge. */
static qk_status_t subdivide(qk__gen_t *g, qk_mesh_t *m) {
  qk_tree_options_t to;
  qk_tree_options_init(&to);
  to.has_root = 1;
  to.root = (qk_square_t){0, 0, (double)g->U};
  to.capacity = 1;
  to.allocator = &m->alloc;
  uint32_t lg = 0;
  while (((uint64_t)1 << lg) < g->U) lg++;
  to.max_depth = lg + 1;
  qk_status_t st = qk_tree_build(NULL, 0, &to, &m->tree);
  if (st) return qk__mesh_fail(g->err, st, 0, "%s while building the tree", qk_strerror(st));
  g->tree = m->tree;
  void *ap = g->arena;
  if (qk__grow(g->a, &ap, &g->arena_cap, g->ne + 1, sizeof *g->arena))
    return qk__mesh_fail(g->err, QK_ERR_NOMEM, 0, "out of memory");
  g->arena = ap;
  for (size_t i = 0; i < g->ne; i++) g->arena[i] = (uint32_t)i;
  g->box = qk__realloc(g->a, NULL, 0, (g->ne ? g->ne : 1) * sizeof *g->box);
  if (!g->box) return qk__mesh_fail(g->err, QK_ERR_NOMEM, 0, "out of memory");
  for (size_t i = 0; i < g->ne; i++) {
    const qk__edge_t *e = &g->e[i];
    g->box[i] = (qk__ebox_t){e->ax < e->bx ? e->ax : e->bx, e->ax < e->bx ? e->bx : e->ax,
                             e->ay < e->by ? e->ay : e->by, e->ay < e->by ? e->by : e->ay};
  }
  g->arena_n = g->ne;
  if ((st = qk__mesh_subdivide(g, qk_tree_root(g->tree), 0, 0, (int64_t)g->U, 0, g->ne))) return st;
  /* The tree starts as one leaf and every split turns a leaf into four. */
  m->stats.leaves_before_balance = 1 + 3 * g->nsplit;
  /* Records sorted by node id, for lookups by hole location. */
  if (g->nrec && !recs_sorted(g)) qsort(g->rec, g->nrec, sizeof *g->rec, qk__mesh_rec_cmp);
  return QK_OK;
}

/* Step 2: BalanceQuadTree. The leaves it leaves are counted by the triangulation. */
static qk_status_t balance(qk__gen_t *g) {
  qk_status_t st = qk_tree_balance(g->tree);
  if (st) return qk__mesh_fail(g->err, st, 0, "%s while balancing", qk_strerror(st));
  return QK_OK;
}

/* Copy the triangles of the kept regions (drop[region] == 0) and their vertices into the
 * mesh, renumbered densely, with the angle extremes and the input for drawing. newid has
 * T->nv slots. */
/* Input points with a negative zero coordinate, ordered by value (-0 == 0). */
typedef struct signed_pt {
  double x, y;
} signed_pt_t;

static int signed_pt_cmp(const void *a, const void *b) {
  const signed_pt_t *p = a, *q = b;
  if (p->x != q->x) return p->x < q->x ? -1 : 1;
  return (p->y > q->y) - (p->y < q->y);
}

/*
 * The lattice map back (qk__lat_out) is exact in value but adds the origin, so an input
 * coordinate of -0 comes back as +0. Input vertices come back bit-identical: every mesh
 * vertex equal in value to an input vertex with a -0 coordinate takes the input's bits.
 * Rare input, so the common case costs one pass over the input.
 */
static qk_status_t restore_signed_zeros(const qk__gen_t *g, qk_mesh_t *m) {
  const qk_poly_t *S = g->src;
  size_t k = 0;
  for (size_t i = 0; i < S->nv; i++)
    k += signbit(S->vx[i]) && S->vx[i] == 0 ? 1 : signbit(S->vy[i]) && S->vy[i] == 0;
  if (!k) return QK_OK;
  signed_pt_t *z = qk__realloc(g->a, NULL, 0, k * sizeof *z);
  if (!z) return qk__mesh_fail(g->err, QK_ERR_NOMEM, 0, "out of memory");
  size_t j = 0;
  for (size_t i = 0; i < S->nv; i++)
    if ((signbit(S->vx[i]) && S->vx[i] == 0) || (signbit(S->vy[i]) && S->vy[i] == 0))
      z[j].x = S->vx[i], z[j].y = S->vy[i], j++;
  qsort(z, k, sizeof *z, signed_pt_cmp);
  for (size_t v = 0; v < m->nv; v++) {
    signed_pt_t key = {m->xy[2 * v], m->xy[2 * v + 1]};
    if (key.x != 0 && key.y != 0) continue;
    const signed_pt_t *hit = bsearch(&key, z, k, sizeof *z, signed_pt_cmp);
    if (hit) m->xy[2 * v] = hit->x, m->xy[2 * v + 1] = hit->y;
  }
  qk__free(g->a, z, k * sizeof *z);
  return QK_OK;
}

static qk_status_t compact(qk__gen_t *g, qk__tri_state_t *T, const uint8_t *drop, uint32_t *newid,
                           qk_mesh_t *m, const uint32_t **ids) {
  const qk_poly_t *poly = g->poly;
  /* Vertices are numbered in order of first use by a kept triangle. With regions dropped,
   * a first pass counts and numbers into newid; without (the usual case), every triangle
   * and vertex is kept and the triangulation numbered them so as it made the triangles
   * (T->ord). *ids gets the numbering used. */
  int dropped = 0;
  for (size_t r = 0; r < T->nregion; r++) dropped |= drop[r];
  size_t kt = T->nt, kv = T->nv;
  *ids = T->ord;
  if (dropped) {
    memset(newid, 0xff, (T->nv ? T->nv : 1) * sizeof *newid);
    *ids = newid;
    kv = 0;
    kt = 0;
    for (size_t t = 0; t < T->nt; t++) {
      if (drop[T->region[t]]) continue;
      kt++;
      for (int i = 0; i < 3; i++)
        if (newid[T->tri[3 * t + i]] == QK__MESH_UNSET) newid[T->tri[3 * t + i]] = (uint32_t)kv++;
    }
  }
  m->nt = kt, m->ncv = poly->nv, m->ncs = poly->ns;
  if (T->tri_ord) {
    /* Every triangle kept and written in the output's numbering: the array is cut to the
     * mesh's size and handed over. */
    m->tri = qk__realloc(g->a, T->tri, 3 * T->tcap * sizeof *T->tri, (3 * kt + 3) * sizeof *m->tri);
    if (m->tri) T->tri = NULL, T->tcap = 0;
  } else {
    m->tri = qk__realloc(g->a, NULL, 0, (3 * kt + 3) * sizeof *m->tri);
  }
  if (!dropped && T->lcap >= kt + 1) {
    /* Every triangle kept: the labels are the components, in place; the array is cut to
     * the mesh's size and handed over instead of copied. */
    m->comp = qk__realloc(g->a, T->label, T->lcap * sizeof *T->label, (kt + 1) * sizeof *m->comp);
    if (m->comp) T->label = NULL, T->lcap = 0;
  } else {
    m->comp = qk__realloc(g->a, NULL, 0, (kt + 1) * sizeof *m->comp);
  }
  m->cxy = qk__realloc(g->a, NULL, 0, (2 * poly->nv + 2) * sizeof *m->cxy);
  m->cseg = qk__realloc(g->a, NULL, 0, (2 * poly->ns + 2) * sizeof *m->cseg);
  if (!m->tri || !m->comp || !m->cxy || !m->cseg)
    return qk__mesh_fail(g->err, QK_ERR_NOMEM, 0, "out of memory");
  double amin = 180, amax = 0;
  size_t j = 0;
  if (dropped) {
    /* The angle extremes of the kept triangles: the shapes the triangulation made need
     * not all be kept. */
    shape_memo_t *sm = qk__realloc(g->a, NULL, 0, sizeof *sm);
    if (!sm) return qk__mesh_fail(g->err, QK_ERR_NOMEM, 0, "out of memory");
    shape_memo_init(sm);
    for (size_t t = 0; t < T->nt; t++) {
      if (drop[T->region[t]]) continue;
      const uint32_t *tr = &T->tri[3 * t];
      for (int i = 0; i < 3; i++) m->tri[3 * j + i] = newid[tr[i]];
      double lo, hi;
      shape_angles(sm, T->vx, T->vy, tr, &lo, &hi);
      if (lo < amin) amin = lo;
      if (hi > amax) amax = hi;
      m->comp[j++] = T->label[t];
    }
    qk__free(g->a, sm, sizeof *sm);
  } else {
    /* The triangles renumbered in one pass, unless handed over above; the labels, unless
     * handed over above. */
    if (!T->tri_ord) {
      const uint32_t *in = T->tri, *ord = T->ord;
      uint32_t *to = m->tri;
      for (size_t t = 0; t < T->nt; t++, in += 3, to += 3) /* by triangle: a third of the loop */
        to[0] = ord[in[0]], to[1] = ord[in[1]], to[2] = ord[in[2]];
    }
    if (T->label && T->nt) memcpy(m->comp, T->label, T->nt * sizeof *m->comp);
    /* Every triangle is kept: the extremes over the shapes the triangulation made, each
     * measured once on its own copy at the origin (angle_deg sees the same coordinate
     * differences, so the same numbers as on every triangle of that shape). */
    for (int l = 0; l < 64; l++)
      for (unsigned bits = T->shapes[l]; bits; bits &= bits - 1) {
        int64_t x[3], y[3];
        qk__mesh_shape(__builtin_ctz(bits), (int64_t)1 << l, x, y);
        for (int i = 0; i < 3; i++) {
          double ang = angle_deg(x, y, (uint32_t)(i + 2) % 3, (uint32_t)i, (uint32_t)(i + 1) % 3);
          if (ang < amin) amin = ang;
          if (ang > amax) amax = ang;
        }
      }
  }
  m->nv = kv;
  m->xy = qk__realloc(g->a, NULL, 0, (2 * kv + 2) * sizeof *m->xy);
  if (!m->xy) return qk__mesh_fail(g->err, QK_ERR_NOMEM, 0, "out of memory");
  size_t steiner = 0;
  /* Back from the (doubled) lattice to input coordinates: exact, see mesh/lattice.c
   * (qk__lat_out, with the power of two computed once). */
  int k = -(g->lat.f + 1);
  double sc = qk__pow2(k);
  const uint32_t *id = *ids;
  const double x0 = g->lat.x0, y0 = g->lat.y0; /* locals: the stores to m->xy may alias */
  if (sc != 0 && id == T->ord) {
    /* The usual case: every vertex kept (numbered by T->ord) and the scale a double. */
    const int64_t *vx = T->vx, *vy = T->vy;
    double *xy = m->xy;
    for (size_t i = 0; i < T->nv; i++) {
      xy[2 * id[i]] = (double)vx[i] * sc + x0, xy[2 * id[i] + 1] = (double)vy[i] * sc + y0;
      steiner += T->steiner[i];
    }
  } else {
    for (size_t i = 0; i < T->nv; i++)
      if (id[i] != QK__MESH_UNSET) {
        m->xy[2 * id[i]] = qk__ldexp_by((double)T->vx[i], sc, k) + x0;
        m->xy[2 * id[i] + 1] = qk__ldexp_by((double)T->vy[i], sc, k) + y0;
        steiner += T->steiner[i];
      }
  }
  qk_status_t st = restore_signed_zeros(g, m);
  if (st) return st;
  for (size_t i = 0; i < poly->nv; i++)
    m->cxy[2 * i] = g->src->vx[i], m->cxy[2 * i + 1] = g->src->vy[i];
  if (poly->ns) memcpy(m->cseg, poly->seg, 2 * poly->ns * sizeof *m->cseg);
  m->stats.triangles = kt;
  m->stats.vertices = kv;
  m->stats.steiner = steiner;
  m->stats.min_angle_deg = kt ? amin : 0;
  m->stats.max_angle_deg = kt ? amax : 0;
  return QK_OK;
}

/* The regional attribute of every kept triangle (m->attr), when the input has any. */
static qk_status_t region_attributes(qk__gen_t *g, qk__tri_state_t *T, const qk__leaf_tris_t *lt,
                                     const uint8_t *drop, qk_mesh_t *m) {
  const qk_poly_t *S = g->src;
  if (!S->nr) return QK_OK;
  uint32_t *at = qk__realloc(g->a, NULL, 0, S->nr * sizeof *at);
  double *ra = qk__realloc(g->a, NULL, 0, ((size_t)T->nregion + 1) * sizeof *ra);
  m->attr = qk__realloc(g->a, NULL, 0, (m->nt + 1) * sizeof *m->attr);
  qk_status_t st = QK_OK;
  if (!at || !ra || !m->attr) {
    st = qk__mesh_fail(g->err, QK_ERR_NOMEM, 0, "out of memory");
  } else if (!(st = qk__mesh_find_regions(g, T, lt, at))) {
    for (size_t r = 0; r <= T->nregion; r++) ra[r] = 0;
    for (size_t i = 0; i < S->nr; i++)
      if (at[i] != QK__MESH_UNSET) ra[at[i]] = S->reg[i].attr;
    size_t j = 0;
    for (size_t t = 0; t < T->nt; t++)
      if (!drop[T->region[t]]) m->attr[j++] = ra[T->region[t]];
  }
  qk__free(g->a, at, S->nr * sizeof *at);
  qk__free(g->a, ra, ((size_t)T->nregion + 1) * sizeof *ra);
  return st;
}

/* Step 3: triangulate, label, drop holes, compact; the boundary markers. */
static qk_status_t triangulate(qk__gen_t *g, qk_mesh_t *m) {
  qk__tri_state_t T;
  memset(&T, 0, sizeof T);
  T.a = g->a;
  qk__leaf_tris_t lt = {NULL, 0, 0};
  uint8_t *drop = NULL;
  uint32_t *newid = NULL;
  qk_status_t st = qk__mesh_triangulate(g, &T, &lt);
  if (st) goto out;
  m->stats.leaves = lt.nleaves; /* counted by the triangulation's walk */
  drop = qk__realloc(g->a, NULL, 0, (size_t)T.nregion + 1);
  newid = qk__realloc(g->a, NULL, 0, (T.nv ? T.nv : 1) * sizeof *newid);
  if (!drop || !newid) {
    st = qk__mesh_fail(g->err, QK_ERR_NOMEM, 0, "out of memory");
    goto out;
  }
  memset(drop, 0, (size_t)T.nregion + 1);
  if ((st = qk__mesh_find_holes(g, &T, &lt, drop))) goto out;
  const uint32_t *ids = NULL;
  if ((st = compact(g, &T, drop, newid, m, &ids))) goto out;
  if ((st = region_attributes(g, &T, &lt, drop, m))) goto out;
  st = qk__mesh_markers(g, m, T.segv, ids);
out:
  qk__free(g->a, drop, (size_t)T.nregion + 1);
  qk__free(g->a, newid, (T.nv ? T.nv : 1) * sizeof *newid);
  qk__free(g->a, lt.first, lt.cap * sizeof *lt.first);
  qk__mesh_tri_free(&T);
  return st;
}

/* An empty mesh for the options' allocator; large blocks from huge-page chunks when the
 * caller gives none (mesh/arena.c): malloc's fresh 4 KB pages cost one fault each on
 * every call (all three modes). NULL when memory ran short. */
static qk_mesh_t *new_mesh(const qk_mesh_options_t *opt) {
  qk_allocator_t alloc = {NULL, NULL};
  if (opt->allocator) alloc = *opt->allocator;
  qk_mesh_t *m = qk__realloc(&alloc, NULL, 0, sizeof *m);
  if (!m) return NULL;
  memset(m, 0, sizeof *m);
  m->alloc = alloc;
  if (!opt->allocator && qk__mesh_arena_available() && (m->arena = qk__mesh_arena_new()))
    m->alloc = (qk_allocator_t){qk__mesh_arena_fn, m->arena};
  return m;
}

/* The general mode into m (freed on failure). */
static qk_status_t general(const qk_poly_t *poly, const qk_mesh_options_t *opt, qk_mesh_t *m,
                           qk_mesh_t **out, qk_mesh_error_t *err) {
  qk_status_t st = qk__mesh_general(poly, opt, m, err);
  if (st) {
    qk_mesh_free(m);
    return st;
  }
  qk__mesh_arena_seal(m->arena);
  *out = m;
  return QK_OK;
}

/* QK_MESH_AUTO, after the lattice mode it chose refused segments that meet (its message in
 * err, QK_ERR_GEOMETRY; g->meet says what it found): the general mode, which takes
 * touching input. On success err is cleared, as for any success. Where the general mode
 * refuses a crossing and the lattice mode had named a crossing too (or what its general
 * check found), or refuses options that are the lattice modes' only (QK_ERR_INVALID), the
 * lattice mode's message stands; any other refusal (a crossing behind a touch the lattice
 * mode named, a hole point on a segment, memory running short) is the general mode's,
 * which names what it found. */
static qk_status_t fallback(const qk_poly_t *poly, const qk_mesh_options_t *opt, qk_mesh_t **out,
                            qk_mesh_error_t *err, const qk__gen_t *g) {
  qk_mesh_error_t first;
  if (err) first = *err;
  qk_mesh_t *m = new_mesh(opt);
  if (!m) return qk__mesh_fail(err, QK_ERR_NOMEM, 0, "out of memory while allocating the mesh");
  qk__error_clear(err);
  qk_status_t st = qk__mesh_general(poly, opt, m, err);
  if (st == QK_OK) {
    qk__mesh_arena_seal(m->arena);
    *out = m;
    return QK_OK;
  }
  /* (a crossing, or options the general mode does not take, say min_angle_deg 40: the
   * lattice mode's refusal is the one that applies) */
  const int keep = (m->refused_crossing && g->meet != QK__MEET_TOUCH) || st == QK_ERR_INVALID;
  if (keep && err) *err = first;
  if (keep) st = QK_ERR_GEOMETRY;
  qk_mesh_free(m);
  return st;
}

qk_status_t qk_mesh_generate(const qk_poly_t *poly, const qk_mesh_options_t *options,
                             qk_mesh_t **out, qk_mesh_error_t *err) {
  qk__error_clear(err);
  if (!out) return QK_ERR_INVALID;
  *out = NULL;
  if (!poly) return qk__mesh_fail(err, QK_ERR_INVALID, 0, "no input");
  qk_mesh_options_t opt;
  qk_status_t st = read_options(options, &opt, err);
  if (st || (st = qk__poly_check_rounded(poly, err))) return st;
  qk_mesh_t *m = new_mesh(&opt);
  if (!m) return qk__mesh_fail(err, QK_ERR_NOMEM, 0, "out of memory while allocating the mesh");
  qk__gen_t g;
  memset(&g, 0, sizeof g);
  g.a = &m->alloc, g.poly = poly, g.src = poly, g.err = err, g.opt = &opt;
  int book = use_book(poly, &opt), classic = opt.mode == QK_MESH_BOOK || opt.mode == QK_MESH_DYADIC;
  if (opt.mode == QK_MESH_AUTO && opt.size)
    classic = 1;
  else if (opt.mode == QK_MESH_AUTO && (st = classic_ok(poly, &opt, &book, &m->alloc, &classic))) {
    qk_mesh_free(m);
    return qk__mesh_fail(err, st, 0, "out of memory while choosing the mode");
  }
  if (!classic) return general(poly, &opt, m, out, err);
  qk_poly_t *onlat = NULL;

  double t0 = now(), t1 = t0, t2 = t0, t3 = t0;
  if (book && opt.max_size > 0 && opt.max_size < 1.4142135623730951)
    st = qk__mesh_fail(err, QK_ERR_INVALID, 0,
                       "max_size %.17g is below sqrt(2), the book's unit square diagonal (the "
                       "dyadic mode refines the lattice instead)",
                       opt.max_size);
  else if (!(st = qk__mesh_lattice(poly, &opt, book, &g.lat, err)) && !book &&
           (st = qk__mesh_lattice_poly(poly, &g.lat, g.a, &onlat)))
    st = qk__mesh_fail(err, st, 0, "out of memory");
  if (onlat) g.poly = onlat;
  m->lat = g.lat;
  if (!st && !(st = qk__mesh_validate(&g, book ? opt.size : 0)) &&
      (st = qk__mesh_precheck(g.poly, g.src, &opt, book ? g.U : 0, &m->alloc, err)))
    g.meet = st == QK_ERR_GEOMETRY ? QK__MEET_CHECK : 0; /* (crossings or touches) */
  if (!st) {
    m->size = g.U;
    m->stats.components = g.ncomp;
    t1 = now();
    if (!(st = subdivide(&g, m)) && !(st = qk__mesh_refine(&g))) {
      t2 = now();
      if (!(st = balance(&g))) {
        t3 = now();
        st = triangulate(&g, m);
      }
    }
  }
  gen_free(&g);
  qk__mesh_lattice_poly_free(onlat);
  if (st != QK_OK) {
    qk_mesh_free(m);
    /* Chosen automatically, the lattice mode refused segments that meet: the general mode
     * takes touching input (a corner of one component on another's side, a shared side);
     * see fallback for whose message a refusal there returns. So too for a size function
     * asking for less than a unit square of the lattice gives. */
    if (((st == QK_ERR_GEOMETRY && g.meet) || (st == QK_ERR_LIMIT && g.size_below_unit)) &&
        opt.mode == QK_MESH_AUTO && !opt.size)
      return fallback(poly, &opt, out, err, &g);
    return st;
  }
  m->stats.size = g.U;
  m->stats.uniform_triangles = 2.0 * (double)g.U * (double)g.U;
  m->stats.seconds_validate = t1 - t0;
  m->stats.seconds_subdivide = t2 - t1;
  m->stats.seconds_balance = t3 - t2;
  m->stats.seconds_triangulate = now() - t3;
  m->stats.mode = book ? QK_MESH_BOOK : QK_MESH_DYADIC;
  m->stats.lattice_exponent = g.lat.f;
  m->stats.origin_x = g.lat.x0;
  m->stats.origin_y = g.lat.y0;
  m->stats.proven_min_angle_deg = 45;
  m->stats.proven_max_angle_deg = 90;
  qk__mesh_arena_seal(m->arena);
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

const uint32_t *qk_mesh_triangle_components(const qk_mesh_t *m, size_t *n) {
  if (n) *n = m ? m->nt : 0;
  return m ? m->comp : NULL;
}

const int32_t *qk_mesh_vertex_markers(const qk_mesh_t *m, size_t *n) {
  if (n) *n = m ? m->nv : 0;
  return m ? m->vmark : NULL;
}

const double *qk_mesh_triangle_attributes(const qk_mesh_t *m, size_t *n) {
  if (n) *n = m && m->attr ? m->nt : 0;
  return m ? m->attr : NULL;
}

qk_status_t qk_mesh_segments(const qk_mesh_t *m, uint32_t *ab, uint32_t *seg, int32_t *marker,
                             size_t cap, size_t *n_out) {
  if (!m || !n_out || (cap && !ab)) return QK_ERR_INVALID;
  *n_out = m->noseg;
  for (size_t i = 0; i < m->noseg && i < cap; i++) {
    ab[2 * i] = m->oseg[i].a, ab[2 * i + 1] = m->oseg[i].b;
    if (seg) seg[i] = m->oseg[i].seg;
    if (marker) marker[i] = m->oseg[i].mark;
  }
  return QK_OK;
}

qk_status_t qk_mesh_angle_histogram(const qk_mesh_t *m, uint64_t bins[180]) {
  if (!m || !bins) return QK_ERR_INVALID;
  memset(bins, 0, 180 * sizeof *bins);
  for (size_t t = 0; t < m->nt; t++) {
    const uint32_t *tr = &m->tri[3 * t];
    for (int i = 0; i < 3; i++) {
      const double *a = &m->xy[2 * tr[(i + 2) % 3]], *b = &m->xy[2 * tr[i]],
                   *c = &m->xy[2 * tr[(i + 1) % 3]];
      double ux = a[0] - b[0], uy = a[1] - b[1], wx = c[0] - b[0], wy = c[1] - b[1];
      double ang =
          atan2(fabs(ux * wy - uy * wx), ux * wx + uy * wy) * (180.0 / 3.14159265358979323846);
      int k = (int)floor(ang);
      bins[k < 0 ? 0 : k > 179 ? 179 : k]++;
    }
  }
  return QK_OK;
}

const qk_tree_t *qk_mesh_tree(const qk_mesh_t *m) { return m ? m->tree : NULL; }

void qk_mesh_stats(const qk_mesh_t *m, qk_mesh_stats_t *s) {
  if (!s) return;
  if (!m) {
    memset(s, 0, sizeof *s);
    return;
  }
  *s = m->stats;
  if (m->stats.mode == QK_MESH_GENERAL)
    qk__mesh_angles(m, m->angle_bound_deg, &s->min_angle_deg, &s->max_angle_deg, &s->exempt_angles);
}
