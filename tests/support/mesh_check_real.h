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

/*
 * The general checker (any angles, real coordinates, the general mode's rules).
 *
 * Angle bounds are turned into rational cotangents on the strict side: an angle passes
 * the lower bound when dot <= C cross with C a double no larger than cot(min_deg), so the
 * checker never accepts an angle below min_deg; likewise for the upper bound.
 */
typedef struct mcr_opts {
  double min_deg;   /* every angle >= this (0: no lower bound) ... */
  int exempt_small; /* ... except, when nonzero, angles inside input angles below 60 deg */
  double max_deg;   /* every angle <= this in triangles without exempt angles (0: none) */
  double max_edge;  /* every edge at most this long (0: no bound) */
  /* The input's rings (optional): ring r is the closed chain of input vertices
   * ring_v[ring_start[r] .. ring_start[r+1]), sign +1 for an outer ring, -1 for a hole.
   * With rings, the kept area (from the mesh's boundary edges) must equal
   * sum(sign |shoelace|) exactly. */
  const uint32_t *ring_v;
  const size_t *ring_start;
  const int *ring_sign;
  size_t n_rings;
} mcr_opts_t;

typedef struct mcr_report {
  double min_angle_deg, max_angle_deg; /* over every triangle (floating point) */
  size_t exempt;                       /* angles below min_deg at input vertices (rule 1) */
  size_t exempt_wedge;                 /* others allowed by the wedge rule (rule 2) */
  double smallest_input_angle_deg;     /* between two input segments at a vertex (180: none) */
  double area;                         /* the kept area (from the boundary edges) */
  size_t boundary_edges;               /* edges without a twin */
} mcr_report_t;

/*
 * Check, exactly: every input vertex is a mesh vertex with the same bits and no two mesh
 * vertices coincide; triangles are counter-clockwise; angle bounds as in opts (the
 * exemption: an angle below min_deg at an input vertex v, with both triangle edges at v
 * inside or along the wedge between two input segments meeting at v at phi < 60
 * degrees, or with exempt_small == 2 the wedge rule: the triangle lies in such a wedge
 * with two of its vertices on its two segments; either way the angle must still be at
 * least g(phi) = arctan(sin phi / (2.02 - cos phi)), exactly); no directed edge twice and every
 * edge without a twin lies on an input segment; every input segment is the chain of mesh edges
 * joining the mesh vertices exactly on it, in order; every output segment is a mesh edge exactly on
 * its input segment; edge lengths; the kept area against the rings. rep (may be NULL) receives the
 * figures. Returns 0 when the mesh passes, 1 with a description in msg, 2 without GMP.
 */
int mcr_check_general(const mcr_input_t *in, const mcr_mesh_t *m, const mcr_opts_t *opts,
                      mcr_report_t *rep, char *msg, size_t msg_size);

#endif
