/*
 * Building blocks of the general mesh mode (docs/mesh-general.md), not yet wired into
 * qk_mesh_generate(): exact predicates on double coordinates.
 */
#ifndef QK_MESH_GENERAL_INTERNAL_H
#define QK_MESH_GENERAL_INTERNAL_H

#include <stdint.h>

/*
 * The exact sign of the orientation determinant (b - a) x (c - a): +1 when a, b, c turn
 * counter-clockwise, -1 clockwise, 0 collinear. Exact for all finite doubles whose
 * coordinate differences and their pairwise products neither overflow nor underflow
 * (magnitudes within 2^-450 .. 2^450 suffice, zero differences included): a floating-point
 * estimate with a proven error bound answers when it can, expansion arithmetic otherwise.
 */
int qk__orient2d(const double a[2], const double b[2], const double c[2]);

/*
 * Whether the closed segment from a to b meets the closed box [lo[0], hi[0]] x [lo[1],
 * hi[1]] (lo <= hi), exactly (the refinement rules' test: a box against a feature). The
 * separating-axis test: the bounding boxes overlap and the segment's line does not leave
 * all four box corners strictly on one side. a == b is a point test.
 */
int qk__seg_meets_box(const double a[2], const double b[2], const double lo[2], const double hi[2]);

/*
 * The precision budget of the segment from a to b (docs/mesh-general.md, section 3): the
 * largest m such that qk__seg_point() computes every point a + (k / 2^m)(b - a),
 * 0 <= k <= 2^m, exactly; at most QK__SEG_BUDGET_MAX (a coordinate shared by both
 * endpoints limits nothing). Negative when only the endpoints themselves are exact.
 * a != b, finite.
 */
#define QK__SEG_BUDGET_MAX 1000
int qk__seg_budget(const double a[2], const double b[2]);

/*
 * out = a + (k / 2^m)(b - a), exactly, for 0 <= m <= qk__seg_budget(a, b) (or any m when k
 * is 0 or 2^m: the endpoints) and 0 <= k <= 2^m, m <= 62. Returns 0, or -1 (out untouched)
 * when m exceeds the budget or k exceeds 2^m.
 */
int qk__seg_point(const double a[2], const double b[2], uint64_t k, int m, double out[2]);

/*
 * qk__seg_point for a caller that has checked 0 < k < 2^m and m <= qk__seg_budget(a, b)
 * (the mesher caches each segment's budget): no checks, no call. The budget keeps every
 * intermediate a normal double, so scaling by 2^-m is an exact multiplication (what ldexp
 * computes, without the library call).
 */
static inline void qk__seg_point_in(const double a[2], const double b[2], uint64_t k, int m,
                                    double out[2]) {
  union {
    uint64_t u;
    double d;
  } sc = {(uint64_t)(1023 - m) << 52}; /* 2^-m, m in [0, 62] */
  out[0] = a[0] + (double)k * ((b[0] - a[0]) * sc.d);
  out[1] = a[1] + (double)k * ((b[1] - a[1]) * sc.d);
}

#endif
