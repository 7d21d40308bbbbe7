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

#endif
