/*
 * Private declarations shared by the mesh module's sources. Not API.
 */
#ifndef QUADKIT_MESH_INTERNAL_H
#define QUADKIT_MESH_INTERNAL_H

#include "quadkit/mesh.h"
#include "index/index_internal.h"

#include <stdarg.h>

/* The parsed input, as read: validation happens in qk_mesh_generate(). Line numbers are
 * 0 for inputs made from arrays. */
/* Allocated capacities (in elements) of a qk_poly's arrays. */
typedef struct qk__poly_caps {
  size_t v, vy, vl, s, sl, h, hy, hl;
} qk__poly_caps_t;

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

#endif /* QUADKIT_MESH_INTERNAL_H */
