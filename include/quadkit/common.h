/**
 * \file common.h
 * \brief Status codes, allocator hook and small geometry types shared by every
 *        quadkit module.
 */
#ifndef QUADKIT_COMMON_H
#define QUADKIT_COMMON_H

#include <stddef.h>
#include <stdint.h>

#ifdef __cplusplus
extern "C" {
#endif

/**
 * The status codes, defined once. Each entry is (name, value, message); the enum
 * and qk_strerror() are both generated from this list.
 */
#define QK_STATUS_MAP(X)                                                                           \
  X(QK_OK, 0, "success")                                                                           \
  X(QK_ERR_NOMEM, 1, "out of memory")                                                              \
  X(QK_ERR_INVALID, 2, "invalid argument")                                                         \
  X(QK_ERR_NONFINITE, 3, "coordinate is NaN or infinite")                                          \
  X(QK_ERR_OUTSIDE, 4, "point lies outside the root square")                                       \
  X(QK_ERR_NOT_FOUND, 5, "no such point or node")                                                  \
  X(QK_ERR_LIMIT, 6, "size limit exceeded")                                                        \
  X(QK_ERR_CORRUPT, 7, "data structure invariant violated")                                        \
  X(QK_ERR_PARSE, 8, "malformed input")                                                            \
  X(QK_ERR_IO, 9, "input/output error")                                                            \
  X(QK_ERR_GEOMETRY, 10, "invalid geometry")                                                       \
  X(QK_ERR_UNSUPPORTED, 11, "operation not supported by this build or tree")

/** Status returned by every fallible quadkit call; QK_OK is 0. */
typedef enum qk_status {
#define QK__STATUS_ENUM(name, value, msg) name = value,
  QK_STATUS_MAP(QK__STATUS_ENUM)
#undef QK__STATUS_ENUM
} qk_status_t;

/**
 * A static, human-readable message for a status code.
 * \param [in] status any value; unknown codes get a generic message.
 * \return a NUL-terminated string that is never freed.
 */
const char *qk_strerror(qk_status_t status);

/**
 * Where and why an input was rejected: filled by every call that reads a file or a
 * caller's arrays, next to the status it returns. Zeroes mean "not known / not from text".
 */
typedef struct qk_error {
  unsigned long line;   /**< 1-based input line, or 0 when the input came from arrays */
  unsigned long column; /**< 1-based column on that line, or 0 when not known */
  size_t item;       /**< 0-based index of the offending item (point, feature, ...), or SIZE_MAX */
  char message[256]; /**< the reason, naming the offending item and value; "" on success */
} qk_error_t;

/**
 * Realloc-style allocation function (as Lua's lua_Alloc): with nsize == 0 it frees
 * ptr and returns NULL; otherwise it returns a block of nsize bytes holding the first
 * min(osize, nsize) bytes of ptr (ptr may be NULL, osize then 0), or NULL on failure,
 * in which case ptr is left untouched.
 */
typedef void *(*qk_alloc_fn)(void *ud, void *ptr, size_t osize, size_t nsize);

/** An allocator: a function and its user data. A NULL allocator means libc. */
typedef struct qk_allocator {
  qk_alloc_fn fn; /**< the allocation function */
  void *ud;       /**< passed to fn unchanged */
} qk_allocator_t;

/** A point in the plane. */
typedef struct qk_point {
  double x, y;
} qk_point_t;

/** An axis-aligned square: lower-left corner (x, y) and side length. */
typedef struct qk_square {
  double x, y, side;
} qk_square_t;

/** A closed axis-aligned box [xmin, xmax] x [ymin, ymax]. */
typedef struct qk_box {
  double xmin, ymin, xmax, ymax;
} qk_box_t;

/** Point identifier: the index of the point in the input, or as returned by insert. */
typedef uint32_t qk_id_t;

/** Node identifier inside one tree. */
typedef uint32_t qk_node_t;

/**
 * Called once per item found (a point of a tree, an item of a collider).
 * \param [in] id the point's id.
 * \param [in] p its coordinates (for geodesic queries: lon, lat in degrees).
 * \param [in] dist distance from the query (0 for box queries; metres for geodesic).
 * \param [in] ud the caller's pointer.
 * \return zero to go on, nonzero to stop the query.
 */
typedef int (*qk_found_fn)(qk_id_t id, qk_point_t p, double dist, void *ud);

/** "No node" / "no point". */
#define QK_NONE UINT32_MAX

#ifdef __cplusplus
}
#endif

#endif /* QUADKIT_COMMON_H */
