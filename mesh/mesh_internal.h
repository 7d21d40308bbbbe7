/*
 * Private declarations shared by the mesh module's sources. Not API.
 */
#ifndef QUADKIT_MESH_INTERNAL_H
#define QUADKIT_MESH_INTERNAL_H

#include "quadkit/mesh.h"
#include "index/index_access.h"

#include <stdarg.h>
#include <stdint.h>

/* Allocated capacities (in elements) of a qk_poly's arrays. */
typedef struct qk__poly_caps {
  size_t v, vy, vl, s, sl, h, hy, hl;
} qk__poly_caps_t;

/* The parsed input, as read: validation happens in qk_mesh_generate(). Line numbers are
 * 0 for inputs made from arrays. */
struct qk_poly {
  qk_allocator_t alloc;
  qk__poly_caps_t cap;
  unsigned first_index;
  size_t nv, ns, nh;
  double *vx, *vy;
  unsigned long *vline;
  uint32_t *seg; /* 2 * ns, 0-based */
  unsigned long *sline;
  double *hx, *hy;
  unsigned long *hline;
};

struct qk_mesh {
  qk_allocator_t alloc;
  qk_tree_t *tree;
  uint64_t size;
  double *xy; /* 2 * nv */
  size_t nv;
  uint32_t *tri; /* 3 * nt */
  uint32_t *comp;
  size_t nt;
  /* The input components, kept for drawing: integer vertices and segments. */
  double *cxy;
  size_t ncv;
  uint32_t *cseg;
  size_t ncs;
  qk_mesh_stats_t stats;
};

/* Grow *p (holding *cap elements of size `elem`) to at least `need` elements. */
qk_status_t qk__mesh_grow(const qk_allocator_t *a, void **p, size_t *cap, size_t elem, size_t need);

/* Fill an error record (err may be NULL); returns `st` for convenience. */
qk_status_t qk__mesh_fail(qk_mesh_error_t *err, qk_status_t st, unsigned long line, const char *fmt,
                          ...)
#if defined(__GNUC__)
    __attribute__((format(printf, 4, 5)))
#endif
    ;

/* A component edge, directed so that the component's interior lies on its left. */
typedef struct qk__edge {
  int64_t ax, ay, bx, by; /* input (not doubled) coordinates */
  uint32_t comp;          /* 1-based component id */
  uint32_t seg;           /* input segment index */
} qk__edge_t;

/*
 * The pieces of a unit leaf's closure that component edges cover: its four sides and two
 * diagonals. Each holds +c when component c's edge runs along the piece's positive
 * direction (west to east, south to north, SW to NE, SE to NW), -c when against it.
 */
enum { QK__P_S, QK__P_E, QK__P_N, QK__P_W, QK__P_D0, QK__P_D1, QK__P_COUNT };
typedef struct qk__unit_rec {
  uint32_t node;
  int32_t piece[QK__P_COUNT];
  uint32_t edge[8]; /* the edges meeting the closed square (at most 8, see unit_leaf) */
  uint32_t nedge;
} qk__unit_rec_t;

/* Generation state; freed in one place. */
typedef struct qk__gen {
  const qk_allocator_t *a;
  const qk_poly_t *poly;
  qk_mesh_error_t *err;
  uint64_t U;
  qk__edge_t *e;
  size_t ne;
  uint32_t ncomp;
  /* The edge-list arena of the subdivision: lists of edge indices, a stack of them. */
  uint32_t *arena;
  size_t arena_n, arena_cap;
  qk__unit_rec_t *rec;
  size_t nrec, rec_cap;
  qk_tree_t *tree;
} qk__gen_t;

/* An open-addressing hash map from 64-bit keys to 32-bit values. */
typedef struct qk__hmap {
  uint64_t *k;
  uint32_t *v;
  size_t cap, n; /* cap is a power of two; key UINT64_MAX marks an empty slot */
} qk__hmap_t;

/* Triangulation state. Coordinates are doubled input coordinates. */
typedef struct qk__tri_state {
  const qk_allocator_t *a;
  qk__hmap_t vmap;
  int64_t *vx, *vy; /* doubled coordinates */
  uint8_t *steiner;
  size_t nv, vcap, vycap, scap;
  uint32_t *tri;    /* 3 per triangle */
  uint32_t *label;  /* per triangle: its cell while triangulating, then its component */
  uint32_t *region; /* per triangle: its region (connected part between boundaries) */
  size_t nt, tcap, lcap, rcap;
  uint32_t nregion;
} qk__tri_state_t;

/* Facts the triangulation hands to hole removal. */
typedef struct qk__leaf_tris {
  uint32_t *first; /* per node id: first triangle of the leaf, or QK__MESH_UNSET */
  size_t cap;
} qk__leaf_tris_t;

/* "Not set" for node, record, cell and label slots. */
#define QK__MESH_UNSET UINT32_MAX

/* User-facing vertex or segment number. */
static inline unsigned long qk__mesh_num(const qk_poly_t *p, size_t i) {
  return (unsigned long)(i + p->first_index);
}

static inline int64_t qk__cross(int64_t ax, int64_t ay, int64_t bx, int64_t by) {
  return ax * by - ay * bx;
}

/* Order unit-leaf records by node id (qsort/bsearch). */
int qk__mesh_rec_cmp(const void *a, const void *b);

/* Validate vertices and segments, find the components (cycles) and orient their edges
 * counter-clockwise (mesh/validate.c). Fills g->e, g->ne, g->ncomp and g->U. */
qk_status_t qk__mesh_validate(qk__gen_t *g, uint64_t size);

/* Step 1, the subdivision of the square (x0, y0, s) at `node`, whose closure the k edges
 * at g->arena[off..] meet (mesh/subdivide.c). */
qk_status_t qk__mesh_subdivide(qk__gen_t *g, uint32_t node, int64_t x0, int64_t y0, int64_t s,
                               size_t off, size_t k);

/* Step 3 and the component labels (mesh/triangulate.c); qk__mesh_tri_free frees T. */
qk_status_t qk__mesh_triangulate(qk__gen_t *g, qk__tri_state_t *T, qk__leaf_tris_t *lt);
void qk__mesh_tri_free(qk__tri_state_t *T);

/* Mark the regions holding hole points in drop[] (T->nregion entries; mesh/holes.c). */
qk_status_t qk__mesh_find_holes(qk__gen_t *g, qk__tri_state_t *T, const qk__leaf_tris_t *lt,
                                uint8_t *drop);

#endif /* QUADKIT_MESH_INTERNAL_H */
