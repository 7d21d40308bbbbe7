/*
 * The general mode, step 6b (docs/mesh.md, "The interior lattice"). With a plain size bound
 * h (max_size, no size function) the part of the domain farther than about h from every
 * feature gets an equilateral triangular lattice of side s just below h, made directly
 * instead of point by point by the refinement (which would make about 2.3 times the
 * triangles there, at the cost of an insertion each):
 *
 * 1. A grid of cells of side c = s/3 over the input's bounding box marks every cell that a
 *    segment or an isolated vertex may meet; a cell is clear when no marked cell lies
 *    within two cells of it, so a point in a clear cell is at least 2c = 2s/3 from every
 *    feature and every vertex of the CDT (those lie on features: the step declines when
 *    seeds, GM_SEED_LEAVES in general_seed.c, were inserted).
 * 2. A lattice point is taken when it lies in a kept triangle of the CDT (so in a kept
 *    face) and in a clear cell; a lattice triangle when its three corners are. The taken
 *    triangles' union is bounded by outline edges.
 * 3. The outline's points are inserted into the CDT as free points. A taken triangle's
 *    circumcircle (radius s / sqrt 3 < 0.578 s) holds no vertex of the CDT: each of its
 *    points is within s / sqrt 3 of a corner, every vertex at least 2s/3 from every corner,
 *    and the lattice's own points lie outside it. So each outline edge, having an empty circle
 *    through its ends, is an edge of the CDT, and the CDT's triangles inside the outline
 *    have outline points as their only corners. They are replaced by the lattice's
 *    triangles.
 * 4. Nothing needs flipping afterwards: an edge between two lattice triangles is locally
 *    Delaunay (the lattice), one between two old triangles was, and across an outline edge
 *    ab the old triangle abe and the lattice triangle abc pass the test together (e outside
 *    abc's circumcircle, which is empty, is c outside abe's). Every edge locally Delaunay,
 *    the triangulation is the constrained Delaunay one (test_mesh_general_mode_lattice
 *    checks the meshes so, exactly).
 *
 * A check that fails (a point on a vertex or a constrained edge, an outline edge missing,
 * a triangle inside the outline with another corner) only stops the step before anything
 * is replaced: the points inserted so far stay as free points, and the refinement, which
 * guarantees the mesh's bounds by itself, meshes the rest. For the proof of termination
 * the lattice points are isolated input vertices, at least 2s/3 from every feature and s
 * from each other (docs/mesh.md, "The angle bound", step 1).
 */
#include <math.h>
#include <stdlib.h>
#include <string.h>

#include "mesh/cdt_internal.h"
#include "mesh/general_mesh.h"

#define NONE QK__CDT_NONE
#define MIN(a, b) ((a) < (b) ? (a) : (b))
#define MAX(a, b) ((a) > (b) ? (a) : (b))

/* Tests only: 0 turns the lattice off (the refinement alone meshes the interior), 2 stops
 * the step after the outline's insertion, as a failed check does. */
int qk__gm_test_lattice = 1;

typedef struct lat {
  qk__gm_t *g;
  double gx0, gy0, c, inv_c; /* the grid's origin, its cells' side and 1 / c */
  double s, hs, dy;          /* the lattice's side, half of it, its row step */
  size_t nx, ny, nrow;       /* cells a row and rows; lattice rows */
  size_t nu;                 /* lattice half steps a row (u from 0 to nu - 1) */
  size_t nh;                 /* lattice points a row in the dense index: nu/2 + 1 */
  uint8_t *hit;              /* per cell: 1 when a feature may meet it */
  uint8_t *vf;               /* per lattice point: the flags below */
  uint32_t *vface;           /* per taken lattice point: its face */
  uint32_t *vid;             /* per lattice point: its CDT vertex */
  size_t *lo, *hi; /* per lattice row: the first and last u of its taken points (lo > hi: none) */
  uint32_t *ts;    /* per lattice triangle: 0 taken (its CDT slot once built), else NONE */
  uint32_t *tl;    /* the taken triangles in index order, as 2 t + 1 for up, 2 t for down */
  uint32_t *tc;    /* their corners' point indices, three a triangle in slot order */
  size_t ntl;
} lat_t;

/* Taken-point flags. */
enum { V_TAKEN = 1, V_USED = 2, V_OUT = 4, V_SEEN = 8 };

static size_t cell_of(double v, double v0, double inv_c, size_t n) {
  double f = floor((v - v0) * inv_c);
  return f < 0 ? 0 : f >= (double)n ? n - 1 : (size_t)f;
}

/* Mark the cells the closed segment ab may meet, column by column, each range padded by
 * a sixteenth of a cell (far above the rounding of the interpolation: see qk__gm_lattice's
 * precision test). */
static void mark_segment(lat_t *L, const double a[2], const double b[2]) {
  const double c = L->c, pad = c / 16;
  double xlo = a[0] < b[0] ? a[0] : b[0], xhi = a[0] < b[0] ? b[0] : a[0];
  double ylo = a[1] < b[1] ? a[1] : b[1], yhi = a[1] < b[1] ? b[1] : a[1];
  size_t i0 = cell_of(xlo - pad, L->gx0, L->inv_c, L->nx);
  size_t i1 = cell_of(xhi + pad, L->gx0, L->inv_c, L->nx);
  const double dx = b[0] - a[0], dy = b[1] - a[1];
  for (size_t i = i0; i <= i1; i++) {
    double x0 = L->gx0 + (double)i * c - pad, x1 = L->gx0 + (double)(i + 1) * c + pad;
    x0 = x0 > xlo ? x0 : xlo, x1 = x1 < xhi ? x1 : xhi;
    double y0 = ylo, y1 = yhi;
    if (dx != 0 && x0 <= x1) {
      double ya = a[1] + (x0 - a[0]) * (dy / dx), yb = a[1] + (x1 - a[0]) * (dy / dx);
      y0 = ya < yb ? ya : yb, y1 = ya < yb ? yb : ya;
      y0 = y0 > ylo ? y0 : ylo, y1 = y1 < yhi ? y1 : yhi;
    }
    size_t j0 = cell_of(y0 - pad, L->gy0, L->inv_c, L->ny);
    size_t j1 = cell_of(y1 + pad, L->gy0, L->inv_c, L->ny);
    for (size_t j = j0; j <= j1; j++) L->hit[j * L->nx + i] = 1;
  }
}

/* Lattice point (u, j), u = j mod 2 (half steps of s along a row): its place and index. */
static double lx(const lat_t *L, size_t u) { return L->gx0 + (double)u * L->hs; }
static double ly(const lat_t *L, size_t j) { return L->gy0 + (double)j * L->dy; }
static size_t vindex(const lat_t *L, size_t u, size_t j) { return j * L->nh + (u >> 1); }

/* Lattice triangle (m, j) of the band between rows j and j + 1 (m from 1 to nu - 2): "up"
 * when m + j is odd, with corners (m - 1, j), (m + 1, j), (m, j + 1); "down" otherwise,
 * with (m, j), (m + 1, j + 1), (m - 1, j + 1); both counter-clockwise. Its corners' indices
 * in slot order. */
static void corners(const lat_t *L, size_t m, size_t j, size_t out[3]) {
  if ((m + j) & 1)
    out[0] = vindex(L, m - 1, j), out[1] = vindex(L, m + 1, j), out[2] = vindex(L, m, j + 1);
  else
    out[0] = vindex(L, m, j), out[1] = vindex(L, m + 1, j + 1), out[2] = vindex(L, m - 1, j + 1);
}

/* The lattice triangles across the slots of taken triangle tl[i]. Up: slot 0 (its right
 * side) borders down (m + 1, j), slot 1 (left) down (m - 1, j), slot 2 (bottom) down
 * (m, j - 1); down: slot 0 (top) up (m, j + 1), slot 1 (left) up (m - 1, j), slot 2
 * (right) up (m + 1, j). All on the lattice: taken triangles lie in bands 1 to nrow - 2
 * and at m from 1 to nu - 2, so their neighbours in bands 0 to nrow - 1. */
static void across(const lat_t *L, size_t i, uint32_t nb[3]) {
  const uint32_t t = L->tl[i] >> 1, nu = (uint32_t)L->nu;
  if (L->tl[i] & 1)
    nb[0] = t + 1, nb[1] = t - 1, nb[2] = t - nu;
  else
    nb[0] = t + nu, nb[1] = t - 1, nb[2] = t + 1;
}

/* Step 1's marks: every cell a segment or an isolated vertex may meet. */
static qk_status_t mark(lat_t *L) {
  const qk_poly_t *P = L->g->P;
  uint8_t *onseg = qk__realloc(L->g->a, NULL, 0, P->nv + 1);
  if (!onseg) return QK_ERR_NOMEM;
  memset(onseg, 0, P->nv + 1);
  for (size_t s = 0; s < P->ns; s++) {
    uint32_t u = P->seg[2 * s], w = P->seg[2 * s + 1];
    const double a[2] = {P->vx[u], P->vy[u]}, b[2] = {P->vx[w], P->vy[w]};
    mark_segment(L, a, b);
    onseg[u] = onseg[w] = 1;
  }
  for (size_t v = 0; v < P->nv; v++) {
    const double a[2] = {P->vx[v], P->vy[v]};
    if (!onseg[v]) mark_segment(L, a, a);
  }
  qk__free(L->g->a, onseg, P->nv + 1);
  return QK_OK;
}

/* Whether lattice point (x, y) is in a clear cell: no mark within two cells of its own.
 * (The grid's two outer columns and rows hold no clear cell.) */
static int clear_at(const lat_t *L, double x, double y) {
  size_t i = cell_of(x, L->gx0, L->inv_c, L->nx), j = cell_of(y, L->gy0, L->inv_c, L->ny);
  if (i < 2 || j < 2 || i + 2 >= L->nx || j + 2 >= L->ny) return 0;
  const uint8_t *h = &L->hit[(j - 2) * L->nx + i - 2];
  for (int r = 0; r < 5; r++, h += L->nx)
    if (h[0] | h[1] | h[2] | h[3] | h[4]) return 0;
  return 1;
}

/* The lattice rows the kept triangles of the CDT span (take_points' work), counted until
 * past limit. */
static size_t rows_spanned(const lat_t *L, size_t limit) {
  const qk__gm_t *g = L->g;
  const qk__cdt_t *c = &g->cdt;
  size_t n = 0;
  for (size_t t = 0; t < c->nt && n <= limit; t++) {
    if (g->faces[g->face[t]].drop) continue;
    const uint32_t *tv = &c->v[3 * t];
    double y0 = c->xy[2 * (size_t)tv[0] + 1], y1 = y0;
    for (int k = 1; k < 3; k++) {
      double y = c->xy[2 * (size_t)tv[k] + 1];
      y0 = MIN(y0, y), y1 = MAX(y1, y);
    }
    n += (size_t)((y1 - y0) / L->dy) + 2;
  }
  return n;
}

/* Step 2's points: those of the lattice in a kept triangle of the CDT (closed, with a
 * margin: a point near a triangle's side may be listed by both) and in a clear cell, so
 * in that triangle's face (rounding can misplace only points next to a side, and those
 * next to a constrained one are not clear). */
static void take_points(lat_t *L) {
  const qk__gm_t *g = L->g;
  const qk__cdt_t *c = &g->cdt;
  const double eps = L->c * 0x1p-20;
  for (size_t t = 0; t < c->nt; t++) {
    uint32_t f = g->face[t];
    if (g->faces[f].drop) continue;
    const uint32_t *tv = &c->v[3 * t];
    const double *p[3] = {qk__cdt_pt(c, tv[0]), qk__cdt_pt(c, tv[1]), qk__cdt_pt(c, tv[2])};
    double y0 = MIN(p[0][1], MIN(p[1][1], p[2][1])), y1 = MAX(p[0][1], MAX(p[1][1], p[2][1]));
    double r0 = ceil((y0 - eps - L->gy0) / L->dy), r1 = floor((y1 + eps - L->gy0) / L->dy);
    if (r0 < 0) r0 = 0;
    if (r1 > (double)L->nrow - 1) r1 = (double)L->nrow - 1;
    for (double r = r0; r <= r1; r++) {
      size_t j = (size_t)r;
      double y = ly(L, j), xa = INFINITY, xb = -INFINITY;
      for (int e = 0; e < 3; e++) {
        const double *a = p[e], *b = p[e == 2 ? 0 : e + 1];
        double lo = MIN(a[1], b[1]), hi = MAX(a[1], b[1]);
        if (y < lo - eps || y > hi + eps) continue;
        double x;
        if (hi - lo <= eps) { /* (a side along the row: both its ends) */
          xa = MIN(xa, MIN(a[0], b[0])), xb = MAX(xb, MAX(a[0], b[0]));
          continue;
        }
        double yy = y < lo ? lo : y > hi ? hi : y;
        x = a[0] + (yy - a[1]) * ((b[0] - a[0]) / (b[1] - a[1]));
        xa = MIN(xa, x), xb = MAX(xb, x);
      }
      if (!(xa <= xb)) continue;
      double u0 = ceil((xa - eps - L->gx0) / L->hs), u1 = floor((xb + eps - L->gx0) / L->hs);
      if (u0 < 0) u0 = 0;
      if (u1 > (double)L->nu - 1) u1 = (double)L->nu - 1;
      size_t u = (size_t)u0;
      if ((u ^ j) & 1) u++;
      for (; (double)u <= u1; u += 2) {
        size_t v = vindex(L, u, j);
        if (L->vf[v]) continue;
        if (!clear_at(L, lx(L, u), y)) {
          L->vf[v] = V_SEEN;
          continue;
        }
        L->vf[v] = V_TAKEN, L->vface[v] = f;
        L->lo[j] = u < L->lo[j] ? u : L->lo[j], L->hi[j] = u > L->hi[j] ? u : L->hi[j];
      }
    }
  }
}

/* An outline edge: taken triangle tl[lt]'s slot k, the CDT triangle inside (tin, slot kin)
 * and the one outside (tout, slot kout). */
typedef struct oedge {
  uint32_t lt, tin, tout;
  uint8_t k, kin, kout;
} oedge_t;

/* The CDT's triangles inside the outline (oe[0 .. ne), the inside slots flagged in seen's
 * bits 0-2), flooded across every other edge into inner (at most cap; bit 3 of seen marks
 * them), which is also the flood's queue. 0 when a check fails: a triangle with a corner
 * that is not an outline point (ids from nv0 on), a constrained edge or the square's side
 * inside, or more triangles than the lattice's. */
static int flood(const lat_t *L, const oedge_t *oe, size_t ne, uint8_t *seen, uint32_t nv0,
                 uint32_t *inner, size_t cap, size_t *ninner) {
  const qk__cdt_t *c = &L->g->cdt;
  size_t n = 0, q = 0;
  for (size_t e = 0; e < ne; e++) {
    uint32_t t0 = oe[e].tin;
    if (seen[t0] & 8) continue;
    if (n == cap) return 0;
    seen[t0] |= 8, inner[n++] = t0;
    while (q < n) {
      uint32_t t = inner[q++];
      const uint32_t *tv = &c->v[3 * (size_t)t];
      if (tv[0] < nv0 || tv[1] < nv0 || tv[2] < nv0) return 0;
      for (int k = 0; k < 3; k++) {
        if (seen[t] >> k & 1) continue;
        uint32_t u = c->nbr[3 * (size_t)t + k];
        if (u == NONE || c->seg[3 * (size_t)t + k] != NONE) return 0;
        if (seen[u] & 8) continue;
        if (n == cap) return 0;
        seen[u] |= 8, inner[n++] = u;
      }
    }
  }
  *ninner = n;
  return 1;
}

/* Steps 3 and 4, for the taken triangles (ts[t] == 0; ntaken of them). */
static qk_status_t build(lat_t *L) {
  qk__gm_t *g = L->g;
  qk__cdt_t *c = &g->cdt;
  const size_t ntaken = L->ntl;
  size_t nout = 0, nused = 0, ne = 0;
  /* The outline: the taken triangles' sides whose other side is not taken. */
  for (size_t i = 0; i < L->ntl; i++) {
    uint32_t nb[3];
    across(L, i, nb);
    const uint32_t *cv = &L->tc[3 * i];
    for (int k = 0; k < 3; k++) {
      if (L->ts[nb[k]] != NONE) continue;
      ne++;
      L->vf[cv[(k + 1) % 3]] |= V_OUT, L->vf[cv[(k + 2) % 3]] |= V_OUT;
    }
  }
  for (size_t j = 0; j < L->nrow; j++)
    for (size_t u = L->lo[j]; u <= L->hi[j] && u < L->nu; u += 2) {
      uint8_t f = L->vf[vindex(L, u, j)];
      nused += (f & V_USED) != 0, nout += (f & V_OUT) != 0;
    }
  /* Worth it only with at least four taken triangles an outline point: each outline point
   * costs an insertion, and a lattice cut into small pieces by features a few s apart
   * (isolated vertices or small holes at a pitch of 2.6 to 3.5 s: 0.5 to 2.9 triangles an
   * outline point) made up to 30% more triangles than the refinement alone, more slowly.
   * The coastlines have 4 to 150 (Norway at 1/256 of its extent 4.7, Iceland 36). */
  if (ntaken < 4 * nout) return QK_OK;
  /* Room for everything at once: an insertion makes two triangles. */
  size_t nv_all = c->nv + nused + 4, nt_all = c->nt + 2 * nout + ntaken + 4;
  if (qk__cdt_reserve(c, nv_all, nt_all) || qk__gm_fit_to(g, nv_all, nt_all, 1))
    return QK_ERR_NOMEM;
  qk__gm_pt_t *pts = qk__realloc(g->a, NULL, 0, (nout + 1) * sizeof *pts);
  oedge_t *oe = qk__realloc(g->a, NULL, 0, (ne + 1) * sizeof *oe);
  uint32_t *inner = qk__realloc(g->a, NULL, 0, (ntaken + 1) * sizeof *inner);
  uint8_t *seen = NULL;
  size_t seen_n = 0, np = 0, ninner = 0;
  qk_status_t st = !pts || !oe || !inner ? QK_ERR_NOMEM : QK_OK;
  int ok = !st;
  /* The outline's points, in Z-order, inserted as free points. */
  for (size_t j = 0; j < L->nrow && ok; j++)
    for (size_t u = L->lo[j]; u <= L->hi[j] && u < L->nu; u += 2) {
      size_t v = vindex(L, u, j);
      if (!(L->vf[v] & V_OUT)) continue;
      double x = lx(L, u), y = ly(L, j);
      pts[np++] = (qk__gm_pt_t){qk__gm_morton(g, x, y), x, y, v, NONE, 0};
    }
  if (ok && np && (st = qk__gm_sort_points(g, pts, np))) ok = 0;
  const uint32_t nv0 = (uint32_t)c->nv;
  uint32_t hint = NONE;
  for (size_t i = 0; i < np && ok; i++) {
    uint32_t t, v;
    int k, existed;
    qk__cdt_where_t w = qk__cdt_locate(c, pts[i].x, pts[i].y, hint, &t, &k);
    /* (Cannot happen: the point is 2s/3 from every feature, in a kept face.) */
    if (w == QK__CDT_VERT || (w == QK__CDT_EDGE && c->seg[3 * t + k] != NONE) ||
        g->faces[g->face[t]].drop) {
      ok = 0;
      break;
    }
    if ((st = qk__gm_insert(g, pts[i].x, pts[i].y, t, k, w, NONE, 0, &v, &existed))) {
      ok = 0;
      break;
    }
    L->vid[pts[i].k] = v;
    hint = c->vtri[v];
  }
  if (ok && qk__gm_test_lattice == 2) ok = 0;
  if (ok) {
    seen_n = c->nt + 1;
    seen = qk__realloc(g->a, NULL, 0, seen_n);
    if (!seen)
      st = QK_ERR_NOMEM, ok = 0;
    else
      memset(seen, 0, seen_n);
  }
  /* Every outline edge an edge of the CDT, with the lattice triangle's side inside. */
  size_t e = 0;
  for (size_t i = 0; i < L->ntl && ok; i++) {
    uint32_t nb[3];
    across(L, i, nb);
    const uint32_t *cv = &L->tc[3 * i];
    for (int k = 0; k < 3 && ok; k++) {
      if (L->ts[nb[k]] != NONE) continue;
      int kin;
      uint32_t tin = qk__cdt_find_edge(c, L->vid[cv[(k + 1) % 3]], L->vid[cv[(k + 2) % 3]], &kin);
      if (tin == NONE) {
        ok = 0;
        break;
      }
      seen[tin] |= (uint8_t)(1 << kin);
      oe[e++] = (oedge_t){(uint32_t)i, tin, NONE, (uint8_t)k, (uint8_t)kin, 0};
    }
  }
  if (ok) ok = flood(L, oe, ne, seen, nv0, inner, ntaken, &ninner);
  /* The triangle outside each outline edge (not one inside: the edge separates them). */
  for (size_t i = 0; i < ne && ok; i++) {
    const uint32_t *tv = &c->v[3 * (size_t)oe[i].tin];
    uint32_t a = tv[(oe[i].kin + 1) % 3], b = tv[(oe[i].kin + 2) % 3];
    uint32_t u = c->nbr[3 * (size_t)oe[i].tin + oe[i].kin];
    if (u == NONE || (seen[u] & 8)) {
      ok = 0;
      break;
    }
    const uint32_t *uv = &c->v[3 * (size_t)u];
    oe[i].tout = u, oe[i].kout = (uint8_t)(uv[0] != a && uv[0] != b   ? 0
                                           : uv[1] != a && uv[1] != b ? 1
                                                                      : 2);
  }
  if (ok) {
    /* The lattice's points inside the outline, then its triangles: the inside triangles'
     * slots first, then new ones. */
    for (size_t j = 0; j < L->nrow; j++)
      for (size_t u = L->lo[j]; u <= L->hi[j] && u < L->nu; u += 2) {
        size_t v = vindex(L, u, j);
        if ((L->vf[v] & (V_USED | V_OUT)) != V_USED) continue;
        uint32_t id = (uint32_t)c->nv++;
        c->xy[2 * (size_t)id] = lx(L, u), c->xy[2 * (size_t)id + 1] = ly(L, j);
        g->vi[id] = (qk__gm_vert_t){NONE, NONE, 0};
        L->vid[v] = id;
      }
    size_t d = 0;
    for (size_t i = 0; i < L->ntl; i++)
      L->ts[L->tl[i] >> 1] = d < ninner ? inner[d++] : (uint32_t)c->nt++;
    for (size_t i = 0; i < L->ntl; i++) {
      uint32_t nb[3], slot = L->ts[L->tl[i] >> 1];
      across(L, i, nb);
      const uint32_t *cv = &L->tc[3 * i];
      for (int k = 0; k < 3; k++) {
        uint32_t id = L->vid[cv[k]];
        c->v[3 * (size_t)slot + k] = id;
        c->nbr[3 * (size_t)slot + k] = L->ts[nb[k]]; /* (NONE across the outline) */
        c->seg[3 * (size_t)slot + k] = NONE;
        c->vtri[id] = slot;
      }
      g->face[slot] = L->vface[cv[0]];
    }
    for (size_t i = 0; i < ne; i++) {
      uint32_t slot = L->ts[L->tl[oe[i].lt] >> 1];
      c->nbr[3 * (size_t)slot + oe[i].k] = oe[i].tout;
      c->nbr[3 * (size_t)oe[i].tout + oe[i].kout] = slot;
    }
    c->hint = L->ts[L->tl[oe[0].lt] >> 1];
  }
  /* (Freed in the reverse order of their allocation: the mesher's arena takes back a freed
   * block only at the top of its chunk, and a hole left below keeps the triangulation's
   * arrays from growing in place later.) */
  qk__free(g->a, seen, seen_n);
  qk__free(g->a, inner, (ntaken + 1) * sizeof *inner);
  qk__free(g->a, oe, (ne + 1) * sizeof *oe);
  qk__free(g->a, pts, (nout + 1) * sizeof *pts);
  return st;
}

qk_status_t qk__gm_lattice(qk__gm_t *g) {
  const qk_mesh_options_t *opt = g->opt;
  const double h = opt->max_size;
  /* Not for a bound of 29 degrees or more: a point the refinement puts inside the lattice
   * (a circumcentre from the band) makes angles of 30 degrees there, bad for such a bound,
   * and the splits then run through the whole lattice (a unit square at 1/100, 30
   * degrees: 67,965 triangles where the refinement alone makes 50,201). */
  if (!qk__gm_test_lattice || opt->size_fn || !(h > 0) || g->bound_deg >= 29) return QK_OK;
  /* (With seeds, GM_SEED_LEAVES in general_seed.c, the CDT would have vertices off the
   * features, which the margins below do not see.) */
  if (g->seeds) return QK_OK;
  lat_t L;
  memset(&L, 0, sizeof L);
  L.g = g;
  L.s = h * (1 - 0x1p-20); /* every side below h, rounding included */
  L.c = L.s / 3, L.inv_c = 1 / L.c, L.hs = L.s / 2;
  L.dy = L.s * 0.86602540378443864676; /* sqrt 3 / 2 */
  /* Coordinates below 2^24 s: their rounding (2^-28 s) is far below the marks' pad and
   * the 2^-20 margin of the sides. */
  double M = MAX(MAX(fabs(g->bx0), fabs(g->bx1)), MAX(fabs(g->by0), fabs(g->by1)));
  if (!(L.s > M * 0x1p-24)) return QK_OK;
  /* Not for a domain smaller than 256 s^2: its lattice would be a few triangles. (Where
   * a long coast leaves little interior, as Norway's fjords at 1/256 of its extent, 3,868
   * s^2 of area along 1,597 s of coast, the lattice takes what there is at about the
   * refinement's cost: 16,526 triangles in the time the refinement makes 20,060.) */
  const double area = qk__gm_area(g);
  if (!(area >= 256 * L.s * L.s)) return QK_OK;
  L.gx0 = g->bx0 - 3 * L.c, L.gy0 = g->by0 - 3 * L.c;
  double fx = floor((g->bx1 - L.gx0) / L.c) + 4, fy = floor((g->by1 - L.gy0) / L.c) + 4;
  /* The scratch arrays take about 3.2 bytes a cell of the grid over the bounding box, the
   * mesh about 60 bytes a triangle and at least 2.3 triangles an s^2 of area: a grid of at
   * most 64 cells an s^2 of the domain (plus 4 M, 13 MB) keeps the scratch within about 1.5
   * times the mesh's size (205 bytes an s^2 against 138), and 2^28 cells (860 MB) bound it
   * outright. A thin diagonal strip's box, far larger than the strip, is not worth it (the
   * strip from (0, 0) to (1, 1), 0.047 wide, at h = 0.0002: 225 M cells, 720 MB). */
  if (!(fx * fy <= 64 * (area / L.s / L.s) + 0x1p22 && fx * fy <= 0x1p28)) return QK_OK;
  L.nx = (size_t)fx, L.ny = (size_t)fy;
  L.nrow = (size_t)floor(fy * L.c / L.dy) + 1;
  L.nu = (size_t)floor(fx * L.c / L.hs) + 1;
  L.nh = L.nu / 2 + 1;
  const size_t ncell = L.nx * L.ny, nvl = L.nrow * L.nh, ntri = L.nrow * L.nu;
  /* The rows the CDT's triangles span: at most 32 an s^2 of the domain (a row costs about
   * 30 instructions, a lattice triangle saves the refinement about 2,000, and there are
   * about 2.3 an s^2). A boundary of many vertices closer than s makes slivers across the
   * domain that each span every row (a 400 by 200 rectangle at s = 1 with 2^18 vertices
   * along each long side: 120 million rows, a second, more than the lattice saves; with
   * 4,096 a side, 1.9 million, well spent); past that the refinement alone meshes it. */
  const size_t budget = (size_t)(32 * (area / L.s / L.s)) + 4 * g->cdt.nt + 65536;
  if (rows_spanned(&L, budget) > budget) return QK_OK;
  qk_status_t st = QK_OK;
  L.hit = qk__realloc(g->a, NULL, 0, ncell);
  L.vf = qk__realloc(g->a, NULL, 0, nvl);
  L.vface = qk__realloc(g->a, NULL, 0, nvl * sizeof *L.vface);
  L.vid = qk__realloc(g->a, NULL, 0, nvl * sizeof *L.vid);
  L.ts = qk__realloc(g->a, NULL, 0, ntri * sizeof *L.ts);
  L.lo = qk__realloc(g->a, NULL, 0, 2 * L.nrow * sizeof *L.lo);
  L.hi = L.lo ? L.lo + L.nrow : NULL;
  if (!L.hit || !L.vf || !L.vface || !L.vid || !L.ts || !L.lo) st = QK_ERR_NOMEM;
  if (!st) {
    memset(L.hit, 0, ncell);
    memset(L.vf, 0, nvl);
    memset(L.ts, 0xff, ntri * sizeof *L.ts);
    for (size_t j = 0; j < L.nrow; j++) L.lo[j] = SIZE_MAX, L.hi[j] = 0;
    st = mark(&L);
  }

  if (!st) take_points(&L);
  /* The taken triangles: in band j, those with a corner in row j's or row j + 1's span;
   * counted, then listed (arrays of their exact size: see the frees below). */
  size_t ntaken = 0;
  for (int pass = 0; pass < 2 && !st; pass++) {
    if (pass) {
      L.tl = qk__realloc(g->a, NULL, 0, (ntaken + 1) * sizeof *L.tl);
      L.tc = qk__realloc(g->a, NULL, 0, 3 * (ntaken + 1) * sizeof *L.tc);
      if (!L.tl || !L.tc) {
        st = QK_ERR_NOMEM;
        break;
      }
    }
    for (size_t j = 1; j + 1 < L.nrow; j++) { /* (row 0 is two cells from the box) */
      size_t a = L.lo[j] < L.lo[j + 1] ? L.lo[j] : L.lo[j + 1];
      size_t b = L.hi[j] > L.hi[j + 1] ? L.hi[j] : L.hi[j + 1];
      if (a > b) continue;
      a = a > 1 ? a - 1 : 1, b = b + 2 < L.nu ? b + 1 : L.nu - 2;
      for (size_t m = a; m <= b; m++) {
        size_t cv[3];
        corners(&L, m, j, cv);
        if (!(L.vf[cv[0]] & L.vf[cv[1]] & L.vf[cv[2]] & V_TAKEN)) continue;
        if (!pass) {
          ntaken++;
          continue;
        }
        const size_t t = j * L.nu + m;
        L.ts[t] = 0, L.tl[L.ntl] = (uint32_t)(2 * t + ((m + j) & 1));
        for (int k = 0; k < 3; k++) L.tc[3 * L.ntl + k] = (uint32_t)cv[k], L.vf[cv[k]] |= V_USED;
        L.ntl++;
      }
    }
  }
  if (!st && L.ntl >= 16) st = build(&L);
  /* (In the reverse order of their allocation, as in build().) */
  qk__free(g->a, L.tc, L.tc ? 3 * (ntaken + 1) * sizeof *L.tc : 0);
  qk__free(g->a, L.tl, L.tl ? (ntaken + 1) * sizeof *L.tl : 0);
  qk__free(g->a, L.lo, L.lo ? 2 * L.nrow * sizeof *L.lo : 0);
  qk__free(g->a, L.ts, L.ts ? ntri * sizeof *L.ts : 0);
  qk__free(g->a, L.vid, L.vid ? nvl * sizeof *L.vid : 0);
  qk__free(g->a, L.vface, L.vface ? nvl * sizeof *L.vface : 0);
  qk__free(g->a, L.vf, L.vf ? nvl : 0);
  qk__free(g->a, L.hit, L.hit ? ncell : 0);
  return st ? qk__mesh_fail(g->err, st, 0, "out of memory") : QK_OK;
}
