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

/*
 * Vertex ids by doubled lattice position: the triangulation's map of leaf corners, then
 * the ids the kept vertices have in the mesh. Every lattice point of a segment is a corner
 * of the unit leaves around it, so the map holds it.
 */
typedef struct vpos {
  const qk__hmap_t *vmap;
  const uint32_t *newid;
} vpos_t;

static uint64_t pos_key(int64_t X2, int64_t Y2) { return (uint64_t)X2 << 32 | (uint64_t)Y2; }

static uint32_t find(const vpos_t *v, uint64_t key) {
  uint32_t t = qk__hmap_find(v->vmap, key);
  return t == QK__MESH_UNSET ? t : v->newid[t];
}

static qk_status_t add_oseg(const qk_allocator_t *a, qk_mesh_t *m, size_t *cap, qk__oseg_t e) {
  void *p = m->oseg;
  if (qk__grow(a, &p, cap, m->noseg + 2, sizeof *m->oseg)) return QK_ERR_NOMEM;
  m->oseg = p;
  m->oseg[m->noseg++] = e;
  return QK_OK;
}

/* The output segments of input segment s, and the markers of their vertices. */
static qk_status_t walk_segment(qk__gen_t *g, qk_mesh_t *m, const vpos_t *pos, size_t *cap,
                                size_t s) {
  const qk_poly_t *P = g->poly;
  uint32_t u = P->seg[2 * s], w = P->seg[2 * s + 1];
  int64_t ax = (int64_t)P->vx[u], ay = (int64_t)P->vy[u];
  int64_t dx = (int64_t)P->vx[w] - ax, dy = (int64_t)P->vy[w] - ay;
  int64_t n = llabs(dx) > llabs(dy) ? llabs(dx) : llabs(dy);
  int32_t mark = g->src->smark ? g->src->smark[s] : 0;
  if (n == 0) return QK_OK;
  int64_t sx = dx / n, sy = dy / n;
  uint32_t prev = QK__MESH_UNSET;
  for (int64_t k = 0; k <= n; k++) {
    uint32_t id = find(pos, pos_key(2 * (ax + k * sx), 2 * (ay + k * sy)));
    /* A vertex is missing only where holes dropped both sides of the segment. */
    if (id != QK__MESH_UNSET && mark && !m->vmark[id]) m->vmark[id] = mark;
    if (id != QK__MESH_UNSET && prev != QK__MESH_UNSET &&
        add_oseg(g->a, m, cap, (qk__oseg_t){prev, id, mark, (uint32_t)s}))
      return QK_ERR_NOMEM;
    prev = id;
  }
  return QK_OK;
}

qk_status_t qk__mesh_markers(qk__gen_t *g, qk_mesh_t *m, const qk__hmap_t *vmap,
                             const uint32_t *newid) {
  const qk_poly_t *P = g->poly, *S = g->src;
  qk_status_t st = QK_OK;
  m->has_marks = S->vmark || S->smark;
  m->vmark = qk__realloc(g->a, NULL, 0, (m->nv + 1) * sizeof *m->vmark);
  vpos_t pos = {vmap, newid};
  size_t cap = 0;
  if (!m->vmark) {
    st = QK_ERR_NOMEM;
    goto out;
  }
  memset(m->vmark, 0, (m->nv + 1) * sizeof *m->vmark);
  /* Input vertices' own markers first: they win over their segments'. */
  for (size_t i = 0; S->vmark && i < P->nv; i++) {
    uint32_t id = find(&pos, pos_key(2 * (int64_t)P->vx[i], 2 * (int64_t)P->vy[i]));
    if (id != QK__MESH_UNSET) m->vmark[id] = S->vmark[i];
  }
  for (size_t s = 0; s < P->ns && !st; s++) st = walk_segment(g, m, &pos, &cap, s);
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
