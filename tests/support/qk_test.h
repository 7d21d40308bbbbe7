/* Helpers shared by every test: seeded random numbers, point generators and an
 * allocator that fails on the N-th call and counts what is still allocated. */
#ifndef QK_TEST_H
#define QK_TEST_H

#include <stdarg.h>
#include <stddef.h>
#include <stdint.h>
#include <setjmp.h>
#include <cmocka.h>

#include "quadkit/quadkit.h"
#include "mesh_check_real.h"

/* ThreadSanitizer builds (scripts/tsan.sh, run for the threaded tests): QKT_TSAN is 1 there
 * and 0 elsewhere, for tests that run their single-threaded parts shorter under it.
 * QKT_SERIAL marks a test's own oracle code (brute force, sorting, comparing lists) that
 * runs on one thread while no library call is under way: TSan does not instrument it,
 * since there is no race for it to find there, and instrumented such code was most of
 * test_world's time under TSan; nor does ASan (QKT_ASAN: 1 in AddressSanitizer builds),
 * for the same time (its dense scenes' sorts). The library's code stays instrumented. */
#if defined(__SANITIZE_THREAD__)
#define QKT_TSAN 1
#elif defined(__has_feature)
#if __has_feature(thread_sanitizer)
#define QKT_TSAN 1
#endif
#endif
#ifndef QKT_TSAN
#define QKT_TSAN 0
#endif
#if defined(__SANITIZE_ADDRESS__)
#define QKT_ASAN 1
#elif defined(__has_feature)
#if __has_feature(address_sanitizer)
#define QKT_ASAN 1
#endif
#endif
#ifndef QKT_ASAN
#define QKT_ASAN 0
#endif
#if QKT_TSAN
#define QKT_SERIAL __attribute__((no_sanitize("thread")))
#elif QKT_ASAN
#define QKT_SERIAL __attribute__((no_sanitize("address")))
#else
#define QKT_SERIAL
#endif

/* The first statement of a test that starts no thread: under ThreadSanitizer it is
 * skipped (reported so), since TSan finds nothing without a second thread and the other
 * builds run it. (A test is such when, run alone under `strace -f`, it makes no clone.) */
#define QKT_ONE_THREAD_TEST()                                                                      \
  do {                                                                                             \
    if (QKT_TSAN) skip();                                                                          \
  } while (0)

/* splitmix64-seeded xoshiro-style generator; deterministic across platforms. */
typedef struct qkt_rng {
  uint64_t s;
} qkt_rng_t;
void qkt_rng_seed(qkt_rng_t *r, uint64_t seed);
uint64_t qkt_rng_next(qkt_rng_t *r);
double qkt_rng_unit(qkt_rng_t *r);                      /* [0, 1) */
double qkt_rng_range(qkt_rng_t *r, double a, double b); /* [a, b) */
uint32_t qkt_rng_below(qkt_rng_t *r, uint32_t n);       /* [0, n) */

/* Point sets used throughout the tests. */
typedef enum qkt_dist {
  QKT_UNIFORM,    /* uniform in [0,1)^2 */
  QKT_CLUSTERED,  /* a few tight Gaussian-ish clusters */
  QKT_DUPLICATES, /* many exact duplicates of a few locations */
  QKT_GRID_EDGES  /* points on a dyadic grid: they fall on cell edges and corners */
} qkt_dist_t;
void qkt_points(qkt_rng_t *r, qkt_dist_t d, qk_point_t *out, size_t n);

/* Tree options over the unit square [0,1]^2 at `capacity`, allocations through `a` (NULL:
 * libc); the rest the defaults. */
qk_tree_options_t qkt_unit_options(uint32_t capacity, const qk_allocator_t *a);

/* cmocka's filters from the environment, for a main to call before running its tests:
 * QKT_TEST_FILTER (a pattern: run only the tests it matches) and QKT_SKIP_FILTER (skip
 * those it matches; scripts/memcheck.sh). */
void qkt_filters_from_env(void);

/* The seed for a test: QK_SEED from the environment, else `def`. Printed by the test. */
uint64_t qkt_seed(uint64_t def);

/* A file of the shared data, $QK_SHARED_DIR/data/NAME (../shared/data/NAME when that is
 * unset), opened for reading; its path in path[0, cap). NULL when it cannot be opened
 * (the caller skips, naming the path). */
FILE *qkt_open_shared(const char *name, char *path, size_t cap);

/* A canonical description of a tree's shape: every node's depth, leaf flag and count in
 * pre-order, and every leaf's ids sorted (inserts and the bulk build may order a leaf's
 * points apart), hashed. Two trees over the same points with the same rule agree. */
typedef struct qkt_shape {
  uint64_t hash;
  size_t nodes;
} qkt_shape_t;
qkt_shape_t qkt_tree_shape(const qk_tree_t *t);

/* Asserts that a and b are the same tree: the same node numbers, children, parents,
 * depths, counts and squares, and the same points (ids and coordinates) in the same order
 * in every leaf (what a threaded or differently-sorted build must reproduce exactly). */
void qkt_assert_same_tree(const qk_tree_t *a, const qk_tree_t *b);

/* A mesh as the exact checker reads it (mesh_check_real.h): vertices and triangles
 * borrowed from the mesh, its output segments copied out; free with qkt_mesh_view_free. */
mcr_mesh_t qkt_mesh_view(const qk_mesh_t *m);
void qkt_mesh_view_free(mcr_mesh_t *v);

/* The failing allocator (qkt_alloc_t, qkt_alloc_make, qkt_alloc_arm), shared with the
 * fuzz targets; a wrong osize from the library fails the test. */
#define QKT_ALLOC_FAIL(...) fail_msg(__VA_ARGS__)
#include "fail_alloc.h"

/* Assert qk_tree_check() passes, printing its message otherwise. */
#define QKT_CHECK_TREE(t)                                                                          \
  do {                                                                                             \
    char qkt_msg_[256];                                                                            \
    qk_status_t qkt_st_ = qk_tree_check((t), qkt_msg_, sizeof qkt_msg_);                           \
    /* its scratch allocation may be the one a failing allocator refuses (once) */                 \
    if (qkt_st_ == QK_ERR_NOMEM) qkt_st_ = qk_tree_check((t), qkt_msg_, sizeof qkt_msg_);          \
    if (qkt_st_ != QK_OK) fail_msg("qk_tree_check: %s", qkt_msg_);                                 \
  } while (0)

#endif
