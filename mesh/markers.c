/*
 * Boundary markers and output segments. Every input segment lies in unit leaves only
 * (step 1 splits every larger square its closure meets), along their sides or
 * diagonals, so the mesh vertices on it are exactly the lattice points it passes
 * through, one lattice step apart, and the mesh edges along it join consecutive ones.
 * They are found by lattice position: no geometry is recomputed.
 */
#include "mesh/mesh_internal.h"

#include <stdlib.h>
#include <string.h>

static qk_status_t add_oseg(const qk_allocator_t *a, qk_mesh_t *m, size_t *cap, qk__oseg_t e) {
  void *p = m->oseg;
  if (qk__grow(a, &p, cap, m->noseg + 2, sizeof *m->oseg)) return QK_ERR_NOMEM;
  m->oseg = p;
  m->oseg[m->noseg++] = e;
  return QK_OK;
}

/* The lattice steps of input segment s. */
static int64_t seg_steps(const qk_poly_t *P, size_t s) {
  uint32_t u = P->seg[2 * s], w = P->seg[2 * s + 1];
  int64_t dx = llabs((int64_t)P->vx[w] - (int64_t)P->vx[u]);
  int64_t dy = llabs((int64_t)P->vy[w] - (int64_t)P->vy[u]);
  return dx > dy ? dx : dy;
}

/* The mesh vertex of a triangulation vertex (QK__MESH_UNSET: none, or not kept). */
static uint32_t mesh_id(const uint32_t *newid, uint32_t t) {
  return t == QK__MESH_UNSET ? t : newid[t];
}

/* The output segments of input segment s, whose lattice points' triangulation vertices
 * are v[0..n], and the markers of their vertices. */
static qk_status_t walk_segment(qk__gen_t *g, qk_mesh_t *m, const uint32_t *v,
                                const uint32_t *newid, size_t *cap, size_t s) {
  int64_t n = seg_steps(g->poly, s);
  int32_t mark = g->src->smark ? g->src->smark[s] : 0;
  if (n == 0) return QK_OK;
  uint32_t prev = QK__MESH_UNSET;
  for (int64_t k = 0; k <= n; k++) {
    uint32_t id = mesh_id(newid, v[k]);
    /* A vertex is missing only where holes dropped both sides of the segment. */
    if (id != QK__MESH_UNSET && mark && !m->vmark[id]) m->vmark[id] = mark;
    if (id != QK__MESH_UNSET && prev != QK__MESH_UNSET &&
        add_oseg(g->a, m, cap, (qk__oseg_t){prev, id, mark, (uint32_t)s}))
      return QK_ERR_NOMEM;
    prev = id;
  }
  return QK_OK;
}

qk_status_t qk__mesh_markers(qk__gen_t *g, qk_mesh_t *m, const uint32_t *segv,
                             const uint32_t *newid) {
  const qk_poly_t *P = g->poly, *S = g->src;
  qk_status_t st = QK_OK;
  m->has_marks = S->vmark || S->smark;
  m->vmark = qk__realloc(g->a, NULL, 0, (m->nv + 1) * sizeof *m->vmark);
  size_t cap = 0;
  if (!m->vmark) {
    st = QK_ERR_NOMEM;
    goto out;
  }
  memset(m->vmark, 0, (m->nv + 1) * sizeof *m->vmark);
  /* Input vertices' own markers first: they win over their segments'. Every input vertex
   * ends a segment (its degree is two), at lattice point 0 or n of it. */
  for (size_t s = 0, j = 0; S->vmark && s < P->ns; s++) {
    int64_t n = seg_steps(P, s);
    for (int e = 0; e < 2; e++) {
      uint32_t id = mesh_id(newid, segv[j + (e ? (size_t)n : 0)]);
      if (id != QK__MESH_UNSET) m->vmark[id] = S->vmark[P->seg[2 * s + (size_t)e]];
    }
    j += (size_t)n + 1;
  }
  for (size_t s = 0, j = 0; s < P->ns && !st; s++) {
    st = walk_segment(g, m, &segv[j], newid, &cap, s);
    j += (size_t)seg_steps(P, s) + 1;
  }
  if (!st && !m->oseg) {
    void *p = NULL;
    if (qk__grow(g->a, &p, &cap, 1, sizeof *m->oseg)) st = QK_ERR_NOMEM;
    m->oseg = p;
  }
out:
  m->noseg_cap = cap;
  if (st) return qk__mesh_fail(g->err, st, 0, "out of memory");
  return QK_OK;
}
