/*
 * An exact checker for quadtree meshes, independent of the generator: its own integer
 * arithmetic (coordinates doubled, 128-bit products where they could overflow) and its
 * own reading of the input's components.
 */
#ifndef QK_MESH_CHECK_H
#define QK_MESH_CHECK_H

#include <stddef.h>
#include <stdint.h>

/* The input as given to the generator: integer vertices, segments (0-based vertex
 * pairs), hole points (multiples of 1/2 in this checker), and the domain side U. */
typedef struct mc_input {
  const double *xy;
  size_t nv;
  const uint32_t *seg;
  size_t ns;
  const double *holes;
  size_t nh;
  uint64_t U;
} mc_input_t;

/* The mesh: vertices (2 per), triangles (3 per, 0-based) and per-triangle components. */
typedef struct mc_mesh {
  const double *xy;
  size_t nv;
  const uint32_t *tri;
  const uint32_t *comp;
  size_t nt;
} mc_mesh_t;

/*
 * Check: vertices distinct and on the half-integer lattice in [0,U]^2; triangles
 * counter-clockwise with every angle in [45, 90] degrees (exactly, by dot and cross
 * products); every interior edge shared by exactly two triangles on opposite sides and
 * every other edge on the domain boundary (or on a component next to a hole); triangle
 * areas summing to U^2 minus the holes; every input segment a union of mesh edges; every
 * triangle labelled with the innermost component containing it and none in a hole.
 * Returns 0 when the mesh passes, else 1 with a description in msg.
 */
int mc_check(const mc_input_t *in, const mc_mesh_t *m, char *msg, size_t msg_size);

#endif
