/* Brute-force oracles for the query and collide modules: every answer computed by a plain
 * loop over all points or items (rays: exact rational arithmetic with GMP when built). */
#ifndef QK_QUERY_ORACLE_H
#define QK_QUERY_ORACLE_H

#include <stddef.h>

#include "quadkit/quadkit.h"

/* Is (ax - bx)^2 + (ay - by)^2 <= (r1 + r2)^2? And the sign of |a - q|^2 - |b - q|^2.
 * Exact (rationals) when built with GMP; else long doubles, then doubles. */
int qko_within(double ax, double ay, double bx, double by, double r1, double r2);
int qko_dist_cmp(qk_point_t q, qk_point_t a, qk_point_t b);

/* Ids of the points inside a closed box, ascending. Returns the count. */
size_t qko_range(const qk_point_t *pts, size_t n, qk_box_t box, qk_id_t *out);

/* Points within r of c, ascending by id, with distances. Returns the count. */
size_t qko_radius(const qk_point_t *pts, size_t n, qk_point_t c, double r, qk_neighbor_t *out);

/* The k nearest (ties by id) within max_dist; `alive` may be NULL (all alive). */
size_t qko_knn(const qk_point_t *pts, const unsigned char *alive, size_t n, qk_point_t q, size_t k,
               double max_dist, qk_neighbor_t *out);

/* Collision: all overlapping pairs sorted (a, b); items as qk_collider_build numbers them. */
size_t qko_pairs(const qk_disc_t *d, size_t nd, const qk_box_t *b, size_t nb, qk_pair_t **out);
/* Items overlapping a query box or disc (is_disc selects), ascending. */
size_t qko_overlap(const qk_disc_t *d, size_t nd, const qk_box_t *b, size_t nb, int is_disc,
                   qk_disc_t qd, qk_box_t qb, qk_id_t *out);
/* First hit of a ray, derived independently of the library (see query_oracle.c): with
 * GMP its t is the double at or just after the exact entry. */
qk_hit_t qko_raycast(const qk_disc_t *d, size_t nd, const qk_box_t *b, size_t nb, qk_point_t o,
                     qk_point_t dir, double tmax);

/* The oracle's entry parameter of item i (-1 for a miss). */
double qko_ray_item(const qk_disc_t *d, size_t nd, const qk_box_t *b, size_t i, qk_point_t o,
                    qk_point_t dir, double tmax);

/* The library's own disc test (collide/collider.c ray_disc), the same operations in the
 * same order, for the tests that require the cast to match a brute force over it to the
 * last bit of t: t of the entry, 0 from inside, -1 for a miss or t > tmax. */
double qko_ray_disc_bits(qk_disc_t d, qk_point_t o, qk_point_t v, double tmax);

/* Sort neighbours by (dist, id) / by id. */
void qko_sort_by_dist(qk_neighbor_t *v, size_t n);
void qko_sort_by_id(qk_neighbor_t *v, size_t n);
void qko_sort_ids(qk_id_t *v, size_t n);

/* The lon,lat columns of ../shared/data/cities.csv ($QK_SHARED_DIR/data/cities.csv), or
 * NULL (with *n = 0) when the file is absent. Caller frees. */
qk_point_t *qko_load_cities(size_t *n);
#endif
