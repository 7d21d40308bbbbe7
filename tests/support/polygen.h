/*
 * Random valid mesh inputs: disjoint, non-touching polygons with integer vertices and
 * edges at multiples of 45 degrees (octagons with random corner cuts, which include
 * rectangles, diamonds and triangles), some touching the domain's edge and some nested
 * inside others.
 */
#ifndef QK_POLYGEN_H
#define QK_POLYGEN_H

#include <stddef.h>
#include <stdint.h>
#include <stdio.h>

#include "qk_test.h"

typedef struct pg_input {
  double *xy; /* 2 * nv integer coordinates */
  size_t nv, cap_v;
  uint32_t *seg; /* 2 * ns, 0-based */
  size_t ns, cap_s;
} pg_input_t;

/* Generate about `target` polygons in [0,U]^2 (U >= 4). Free with pg_free(). */
void pg_generate(qkt_rng_t *r, uint64_t U, size_t target, pg_input_t *out);

/* Append a closed polygon through n points. */
void pg_add_polygon(pg_input_t *p, const int64_t *xy, size_t n);

void pg_free(pg_input_t *p);

/*
 * Random planar straight-line graphs for the general mode (polygen_pslg.c): an outer
 * ring (a star-shaped polygon with jittered corners), and by flags holes (with their hole
 * points), an island (a second outer ring), internal constraint segments and open
 * chains, fans of segments at small angles (0.5 to 59 degrees), near-collinear triples
 * (a chain's middle vertex one grid step off the line), near-coincident vertices (one
 * grid step apart), tiny features (2^-20 to 2^-10 wide) in a domain 2^20 wide, and full
 * precision doubles. Every coordinate is a multiple of a power of two (the grid) unless
 * PG_FULL is given, so the general mode's precision budget usually holds; with PG_FULL it
 * may not, nor with PG_SCALES (tiny features on a 2^-28 grid up to 2^22 from the origin
 * leave only a few binary digits for split points), and a refusal (QK_ERR_GEOMETRY) is an
 * acceptable answer there. The result is checked
 * exactly (GMP when available, else a filter that only accepts certain answers): no
 * two vertices coincide, no two segments meet except at a shared endpoint, no vertex lies
 * inside a segment, hole points lie strictly inside their hole, nothing lies in a hole.
 */
enum {
  PG_HOLES = 1,
  PG_ISLAND = 2,
  PG_INTERNAL = 4,
  PG_SMALL_ANGLES = 8,
  PG_NEAR_COLLINEAR = 16,
  PG_NEAR_COINCIDENT = 32,
  PG_SCALES = 64,
  PG_FULL = 128,
  PG_ALL = 255
};

typedef struct pg_pslg {
  double *xy; /* 2 * nv */
  size_t nv, cap_v;
  uint32_t *seg; /* 2 * ns, 0-based */
  size_t ns, cap_s;
  double *holes; /* 2 * nh hole points */
  size_t nh, cap_h;
  /* Rings for the area check: ring r is ring_v[ring_start[r] .. ring_start[r+1]), sign
   * +1 (outer) or -1 (hole). */
  uint32_t *ring_v;
  size_t *ring_start; /* nr + 1 */
  int *ring_sign;
  size_t nr, cap_rv, cap_r;
  unsigned flags; /* what was asked for */
  double grid;    /* the finest grid step used (0 with PG_FULL) */
} pg_pslg_t;

/* A random PSLG with about n outer corners (n >= 3) and the features in flags. */
void pg_pslg(qkt_rng_t *r, unsigned flags, size_t n, pg_pslg_t *out);

/* Check a PSLG exactly as described above; 0 when valid, else 1 with msg. */
int pg_pslg_check(const pg_pslg_t *p, char *msg, size_t msg_size);

/* Write it as a .poly file (vertices, segments, holes). */
void pg_pslg_write_poly(const pg_pslg_t *p, FILE *f);

void pg_pslg_free(pg_pslg_t *p);

#endif
