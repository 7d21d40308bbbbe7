/*
 * Query ordering for the batch calls. Answering queries in Z-order (Morton order) of
 * their locations makes consecutive searches walk nearly the same nodes and leaves, so
 * most of what one query brings into the cache the next one reuses; for random queries
 * over a large tree that is where the time goes. The order comes from a least-
 * significant-digit radix sort of 22-bit Morton codes (11 bits per axis, relative to the
 * root square), two passes of 11 bits, linear in the number of queries.
 */
#include "query/query_internal.h"

/* Bits per axis of the Morton codes: a 2048 x 2048 grid over the root, finer than the
 * leaves of any tree whose queries are worth reordering, and two radix passes of 11 bits
 * whose 2048 counters stay in the first-level cache. */
#define QK__ORDER_BITS 11
#define QK__ORDER_CELLS (1u << QK__ORDER_BITS)

/* A coordinate's cell index along one axis of the root, clamped (queries may lie outside
 * the root, or be NaN, which any cell serves). */
static inline uint32_t cell_of(double v, double lo, double scale) {
  double c = (v - lo) * scale;
  if (!(c > 0)) return 0;
  if (c >= QK__ORDER_CELLS - 1) return QK__ORDER_CELLS - 1;
  return (uint32_t)c;
}

void *qk__morton_order(const qk_tree_t *t, const qk_point_t *qs, size_t nq, uint32_t **order) {
  *order = NULL;
  if (nq < 64 || nq > UINT32_MAX) return NULL; /* too few to pay, or ids do not fit */
  const qk_allocator_t *a = qk__tree_allocator(t);
  uint64_t *k = qk__realloc(a, NULL, 0, 2 * nq * sizeof *k);
  if (!k) return NULL;
  uint64_t *tmp = k + nq;
  const qk_square_t r = qk__tree_root_square(t);
  const double x0 = r.x, y0 = r.y, scale = (double)QK__ORDER_CELLS / r.side;
  for (size_t i = 0; i < nq; i++) {
    uint32_t code =
        qk__spread16(cell_of(qs[i].x, x0, scale)) << 1 | qk__spread16(cell_of(qs[i].y, y0, scale));
    k[i] = (uint64_t)code << 32 | (uint64_t)i;
  }
  for (int pass = 0; pass < 2; pass++) {
    uint32_t count[QK__ORDER_CELLS + 1] = {0};
    const int shift = 32 + QK__ORDER_BITS * pass;
    const uint64_t mask = QK__ORDER_CELLS - 1;
    for (size_t i = 0; i < nq; i++) count[((k[i] >> shift) & mask) + 1]++;
    for (uint32_t b = 0; b < QK__ORDER_CELLS; b++) count[b + 1] += count[b];
    for (size_t i = 0; i < nq; i++) tmp[count[(k[i] >> shift) & mask]++] = k[i];
    uint64_t *s = k;
    k = tmp;
    tmp = s;
  }
  /* After an even number of passes the sorted keys are back in the first half; the
   * second half, now unused, receives the query indices. */
  uint32_t *o = (uint32_t *)tmp;
  for (size_t i = 0; i < nq; i++) o[i] = (uint32_t)(k[i] & 0xFFFFFFFFu);
  *order = o;
  return k;
}

void qk__morton_free(const qk_tree_t *t, void *block, size_t nq) {
  qk__free(qk__tree_allocator(t), block, 2 * nq * sizeof(uint64_t));
}
