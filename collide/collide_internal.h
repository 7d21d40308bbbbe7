/*
 * Private helpers of the collide module (the static collider and the world): the
 * traversal stack bound and entries, and the allocation and tree accessors it reads
 * through index/index_access.h. Not API; collide/ depends on index/ only.
 */
#ifndef QUADKIT_COLLIDE_INTERNAL_H
#define QUADKIT_COLLIDE_INTERNAL_H

#include <math.h>

#include "index/index_access.h"
#include "quadkit/collide.h"

/*
 * Deepest possible traversal stack: a depth-first search pops one node and pushes at
 * most four children, so it never holds more than 3 per level plus 4.
 */
#define QK__CSTACK_MAX (3 * (QK_MAX_DEPTH_LIMIT + 2) + 8)

/* A stacked node with the lower bound that let it in (re-checked when popped, because
 * the pruning threshold may have shrunk meanwhile). */
typedef struct qk__centry {
  uint32_t node;
  double bound;
} qk__centry_t;

/* Sort up to four stacked entries by descending bound, so the nearest is popped first. */
static inline void qk__csort4_desc(qk__centry_t *e, int n) {
  for (int i = 1; i < n; i++) {
    qk__centry_t v = e[i];
    int j = i - 1;
    while (j >= 0 && e[j].bound < v.bound) {
      e[j + 1] = e[j];
      j--;
    }
    e[j + 1] = v;
  }
}

#endif /* QUADKIT_COLLIDE_INTERNAL_H */
