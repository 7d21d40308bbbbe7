/*
 * Building blocks of the general mesh mode (docs/mesh-general.md), not yet wired into
 * qk_mesh_generate(): exact predicates on double coordinates.
 */
#ifndef QK_MESH_GENERAL_INTERNAL_H
#define QK_MESH_GENERAL_INTERNAL_H

/*
 * The exact sign of the orientation determinant (b - a) x (c - a): +1 when a, b, c turn
 * counter-clockwise, -1 clockwise, 0 collinear. Exact for all finite doubles whose
 * coordinate differences and their pairwise products neither overflow nor underflow
 * (magnitudes within 2^-450 .. 2^450 suffice, zero differences included): a floating-point
 * estimate with a proven error bound answers when it can, expansion arithmetic otherwise.
 */
int qk__orient2d(const double a[2], const double b[2], const double c[2]);

#endif
