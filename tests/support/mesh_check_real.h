/*
 * An exact checker for meshes with real (double) coordinates, independent of the
 * generator and of any lattice: every test is exact rational arithmetic (GMP's mpq) on
 * the doubles as given. Without GMP (QK_HAVE_GMP undefined) mcr_available() is 0 and
 * mcr_check() reports that it checked nothing.
 */
#ifndef QK_MESH_CHECK_REAL_H
#define QK_MESH_CHECK_REAL_H

#include <stddef.h>
#include <stdint.h>

/* The input: vertices, segments (0-based pairs); hole-free inputs only. */
typedef struct mcr_input {
  const double *xy;
  size_t nv;
  const uint32_t *seg;
  size_t ns;
} mcr_input_t;

/* The mesh: vertices (2 per), triangles (3 per, 0-based), output segments (2 per) with
 * the input segment of each. */
typedef struct mcr_mesh {
  const double *xy;
  size_t nv;
  const uint32_t *tri;
  size_t nt;
  const uint32_t *oseg, *oseg_of;
  size_t no;
} mcr_mesh_t;

/* 1 when built with GMP. */
int mcr_available(void);

/*
 * Check, exactly: every input vertex is a mesh vertex (bit-identical); triangles are
 * counter-clockwise with every angle at least `min_deg` degrees where min_deg is 45 (the
 * test dot <= cross) and at most 90 (dot >= 0); no directed edge twice, and every edge
 * without a twin on the boundary of the mesh vertices' bounding box; the triangle areas
 * sum to that box's area (so they tile it); every input segment is the union of the mesh
 * edges between the mesh vertices lying exactly on it, consecutive by parameter; every
 * output segment lies exactly on its input segment. Returns 0 when the mesh passes, else
 * 1 with a description in msg (and 2 without GMP).
 */
int mcr_check(const mcr_input_t *in, const mcr_mesh_t *m, char *msg, size_t msg_size);

#endif
