/*
 * The general mode, step 11: the kept triangles (those of faces that are neither the
 * unbounded face nor a hole) and the vertices they use, renumbered densely (the input
 * vertices first, in input order, then the others in CDT order); per triangle its face number and
 * regional attribute; the mesh edges along input segments with their markers. One pass
 * over the triangles counts, the next writes every array in its final form.
 */
#include "mesh/general_mesh.h"

#include <math.h>
#include <string.h>

static int kept(const qk__gm_t *g, uint32_t t) { return !g->faces[g->face[t]].drop; }

/* Is the edge of kept triangle t opposite corner k a mesh edge along an input segment
 * that t reports (each such edge once: by the kept triangle of smaller number)? Its
 * segment, or NONE. */
static uint32_t own_seg(const qk__gm_t *g, uint32_t t, int k) {
  const qk__cdt_t *c = &g->cdt;
  uint32_t s = c->seg[3 * t + k], u = c->nbr[3 * t + k];
  if (s == QK__CDT_NONE || (u != QK__CDT_NONE && u < t && kept(g, u))) return QK__CDT_NONE;
  return s;
}

/* The output segment of the edge of t opposite corner k, on segment s: directed along s. */
static qk__oseg_t out_seg(const qk__gm_t *g, uint32_t t, int k, uint32_t s, const uint32_t *newid) {
  const qk__cdt_t *c = &g->cdt;
  uint32_t a = c->v[3 * t + (k + 1) % 3], b = c->v[3 * t + (k + 2) % 3];
  if (qk__gm_param(g, a, s) > qk__gm_param(g, b, s)) {
    uint32_t x = a;
    a = b, b = x;
  }
  return (qk__oseg_t){newid[a], newid[b], g->P->smark ? g->P->smark[s] : 0,
                      g->P->sorig ? g->P->sorig[s] : s};
}

/* Vertex markers: an input vertex's own nonzero marker, else the first segment (in input
 * order) through it with a nonzero marker; a split point takes its segment's. */
static void vertex_markers(qk__gm_t *g, qk_mesh_t *m, const uint32_t *newid) {
  const qk__cdt_t *c = &g->cdt;
  const qk_poly_t *P = g->P;
  memset(m->vmark, 0, (m->nv + 1) * sizeof *m->vmark);
  if (!P->vmark && !P->smark) return; /* (no markers: the pass over the vertices sets none) */
  for (size_t v = 0; v < c->nv; v++) {
    uint32_t id = newid[v];
    if (id == QK__CDT_NONE) continue;
    if (g->vi[v].in != QK__CDT_NONE && P->vmark) m->vmark[id] = P->vmark[g->vi[v].in];
    if (g->vi[v].seg != QK__CDT_NONE && P->smark) m->vmark[id] = P->smark[g->vi[v].seg];
  }
  for (size_t s = 0; P->smark && s < P->ns; s++)
    for (int j = 0; j < 2; j++) {
      uint32_t id = newid[g->cv[P->seg[2 * s + j]]];
      if (id != QK__CDT_NONE && !m->vmark[id]) m->vmark[id] = P->smark[s];
    }
}

qk_status_t qk__gm_output(qk__gm_t *g, qk_mesh_t *m) {
  const qk__cdt_t *c = &g->cdt;
  const qk_poly_t *P = g->P;
  uint32_t *newid = qk__realloc(g->a, NULL, 0, (c->nv + 1) * sizeof *newid);
  if (!newid) return qk__mesh_fail(g->err, QK_ERR_NOMEM, 0, "out of memory");
  memset(newid, 0xff, (c->nv + 1) * sizeof *newid);
  size_t kt = 0, kv = 0, steiner = 0;
  uint32_t nf = 0;
  for (uint32_t f = 0; f < g->nface; f++) g->faces[f].id = g->faces[f].drop ? 0 : ++nf;
  size_t ns = 0;
  /* The arrays in locals in both passes over the triangles: the compiler reloaded them
   * from g, c and m on every triangle. */
  const uint32_t *const V = c->v, *const S = c->seg, *const face = g->face;
  const qk__gm_face_t *const faces = g->faces;
  for (uint32_t t = 0; t < c->nt; t++)
    if (!faces[face[t]].drop) {
      kt++;
      const uint32_t *ts = &S[3 * t];
      for (int i = 0; i < 3; i++) newid[V[3 * t + i]] = 0;
      if ((ts[0] & ts[1] & ts[2]) != QK__CDT_NONE)
        for (int i = 0; i < 3; i++) ns += own_seg(g, t, i) != QK__CDT_NONE;
    }
  /* The input vertices first, in input order, then the others in CDT order. */
  for (size_t i = 0; i < P->nv; i++)
    if (newid[g->cv[i]] == 0) newid[g->cv[i]] = (uint32_t)kv++;
  for (size_t v = 0; v < c->nv; v++)
    if (newid[v] == 0 && g->vi[v].in == QK__CDT_NONE) newid[v] = (uint32_t)kv++, steiner++;
  m->nv = kv, m->nt = kt, m->ncv = P->nv, m->ncs = P->ns;
  m->xy = qk__realloc(g->a, NULL, 0, (2 * kv + 2) * sizeof *m->xy);
  m->tri = qk__realloc(g->a, NULL, 0, (3 * kt + 3) * sizeof *m->tri);
  m->comp = qk__realloc(g->a, NULL, 0, (kt + 1) * sizeof *m->comp);
  m->cxy = qk__realloc(g->a, NULL, 0, (2 * P->nv + 2) * sizeof *m->cxy);
  m->cseg = qk__realloc(g->a, NULL, 0, (2 * P->ns + 2) * sizeof *m->cseg);
  m->vmark = qk__realloc(g->a, NULL, 0, (kv + 1) * sizeof *m->vmark);
  if (P->nr) m->attr = qk__realloc(g->a, NULL, 0, (kt + 1) * sizeof *m->attr);
  m->oseg = qk__realloc(g->a, NULL, 0, (ns + 1) * sizeof *m->oseg);
  if (m->oseg) m->noseg_cap = ns + 1;
  qk_status_t st = QK_OK;
  if (!m->xy || !m->tri || !m->comp || !m->cxy || !m->cseg || !m->vmark || (P->nr && !m->attr) ||
      !m->oseg) {
    st = qk__mesh_fail(g->err, QK_ERR_NOMEM, 0, "out of memory");
    goto out;
  }
  for (size_t v = 0; v < c->nv; v++)
    if (newid[v] != QK__CDT_NONE)
      m->xy[2 * newid[v]] = c->xy[2 * v], m->xy[2 * newid[v] + 1] = c->xy[2 * v + 1];
  size_t j = 0;
  uint32_t *const tri = m->tri, *const comp = m->comp;
  double *const attr = m->attr;
  for (uint32_t t = 0; t < c->nt; t++) {
    if (faces[face[t]].drop) continue;
    const uint32_t *tv = &V[3 * t];
    for (int i = 0; i < 3; i++) tri[3 * j + i] = newid[tv[i]];
    /* NONE has every bit set: the AND of the three is NONE only when no side is on a
     * segment, as in most triangles. */
    const uint32_t *ts = &S[3 * t];
    if ((ts[0] & ts[1] & ts[2]) != QK__CDT_NONE)
      for (int i = 0; i < 3; i++) {
        uint32_t sg = own_seg(g, t, i);
        if (sg != QK__CDT_NONE) m->oseg[m->noseg++] = out_seg(g, t, i, sg, newid);
      }
    const qk__gm_face_t *f = &faces[face[t]];
    comp[j] = f->id;
    if (attr) attr[j] = f->attr;
    j++;
  }
  for (size_t i = 0; i < P->nv; i++) m->cxy[2 * i] = P->vx[i], m->cxy[2 * i + 1] = P->vy[i];
  if (P->ns) memcpy(m->cseg, P->seg, 2 * P->ns * sizeof *m->cseg);
  vertex_markers(g, m, newid);
  m->has_marks = P->vmark || P->smark;
  m->stats.components = nf;
  m->stats.triangles = kt;
  m->stats.vertices = kv;
  m->stats.steiner = steiner;
  m->angle_bound_deg = g->bound_deg; /* (the angles: qk_mesh_stats) */
out:
  qk__free(g->a, newid, (c->nv + 1) * sizeof *newid);
  return st;
}

/* The general mode's angle figures, for qk_mesh_stats (the generation leaves them: a
 * caller that writes the mesh and never asks does not pay for a pass over every corner).
 * Angles through their cosines (one square root each); the extremes back to degrees at the
 * end. */
void qk__mesh_angles(const qk_mesh_t *m, double bound_deg, double *min_deg, double *max_deg,
                     size_t *below) {
  double cmax = -1, cmin = 1, cb = cos(bound_deg * (3.14159265358979323846 / 180));
  /* Most corners change none of the three (cmax, cmin, the count above cb): a corner whose
   * cosine lies strictly between cmin and min(cmax, cb) with a margin of 1e-9, far above
   * the roundings of a few operations, is passed over on squares (no division, no square
   * root). thr_hi (for positive cosines) and thr_lo (negative ones) are those squared
   * limits, with the margin; 0 (never a pass) until cmax > 0 > cmin. Any doubt (zero, NaN)
   * takes the full computation, so the results are those of computing every corner. */
  double thr_hi = 0, thr_lo = 0, nthr_hi = -0.0;
  double amin = INFINITY, amax = -INFINITY; /* (radians, the corners measured by atan2) */
  size_t exempt = 0;
  const double *const XY = m->xy;
  for (size_t t = 0; t < m->nt; t++) {
    const uint32_t *tv = &m->tri[3 * t];
    /* e[i] runs from corner i + 1 to corner i + 2, so the sides at corner i are e[i+2] and
     * -e[i+1]: the same roundings as differences from the corner (a - b is exactly
     * -(b - a)), with each squared length computed once. */
    double e[3][2], l[3];
    for (int i = 0; i < 3; i++) {
      const double *a = &XY[2 * (size_t)tv[(i + 1) % 3]], *b = &XY[2 * (size_t)tv[(i + 2) % 3]];
      e[i][0] = b[0] - a[0], e[i][1] = b[1] - a[1];
      l[i] = e[i][0] * e[i][0] + e[i][1] * e[i][1];
    }
    for (int i = 0; i < 3; i++) {
      const double *u = e[(i + 2) % 3], *w = e[(i + 1) % 3];
      double dot = u[0] * w[0] + u[1] * w[1], ll = l[(i + 2) % 3] * l[(i + 1) % 3];
      /* cosine -dot / sqrt(ll): skipped when dot^2 < thr_hi ll for dot < 0 or dot^2 < thr_lo ll
       * for dot > 0, both as comparisons of dot |dot| (the same products, signed): choosing
       * the threshold by dot's sign took eight instructions a corner. (A zero dot may be
       * computed where it was passed over: the full computation is what the pass stands for.) */
      double sq = dot * fabs(dot);
      if (sq > nthr_hi * ll && sq < thr_lo * ll) continue;
      double cs = -dot / sqrt(ll);
      if (cs > 1 - 1e-6 || cs < -1 + 1e-6) {
        /* Within 0.08 degrees of 0 or 180 the cosine tells angles apart poorly (below
         * 1e-6 degrees it is 1, and the smallest angle read 0): such corners are measured
         * by atan2 as well. One passed over above is beyond another by the margin. */
        double a = atan2(fabs(u[0] * w[1] - u[1] * w[0]), -dot);
        amin = a < amin ? a : amin, amax = a > amax ? a : amax;
      }
      if (cs > cmax || cs < cmin) {
        cmax = cs > cmax ? cs : cmax, cmin = cs < cmin ? cs : cmin; /* NaN: neither, as fmax */
        double hi = (cmax < cb ? cmax : cb) * (1 - 1e-9), lo = cmin * (1 - 1e-9);
        thr_hi = hi > 0 && cmin < 0 ? hi * hi : 0, thr_lo = lo < 0 && cmax > 0 ? lo * lo : 0;
        nthr_hi = -thr_hi;
      }
      exempt += cs > cb;
    }
  }
  const double deg = 180 / 3.14159265358979323846;
  /* (the extreme corner was measured by atan2 when its cosine is that close to 1 or -1) */
  *min_deg = m->nt ? (cmax > 1 - 1e-6 ? amin : acos(cmax)) * deg : 0;
  *max_deg = m->nt ? (cmin < -1 + 1e-6 ? amax : acos(cmin)) * deg : 0;
  *below = exempt;
}
