/*
 * The bounded max-heap of neighbours keyed by (dist, id) that the kNN searches use for
 * large k (the worst at h[0]), and its final in-place sort.
 */
#include "query/query_internal.h"

static void sift_down(qk_neighbor_t *h, size_t n, size_t i) {
  qk_neighbor_t v = h[i];
  for (;;) {
    size_t l = 2 * i + 1, m = i;
    qk_neighbor_t best = v;
    if (l < n && qk__nb_less(best.dist, best.id, h[l].dist, h[l].id)) m = l, best = h[l];
    if (l + 1 < n && qk__nb_less(best.dist, best.id, h[l + 1].dist, h[l + 1].id)) m = l + 1;
    if (m == i) break;
    h[i] = h[m];
    i = m;
  }
  h[i] = v;
}

void qk__heap_push(qk_neighbor_t *h, size_t *n, qk_neighbor_t v) {
  size_t i = (*n)++;
  while (i > 0) {
    size_t p = (i - 1) / 2;
    if (!qk__nb_less(h[p].dist, h[p].id, v.dist, v.id)) break;
    h[i] = h[p];
    i = p;
  }
  h[i] = v;
}

void qk__heap_replace_top(qk_neighbor_t *h, size_t n, qk_neighbor_t v) {
  h[0] = v;
  sift_down(h, n, 0);
}

void qk__heap_sort(qk_neighbor_t *h, size_t n) {
  /* Standard in-place heapsort of a max-heap: move the worst to the end repeatedly. */
  while (n > 1) {
    qk_neighbor_t top = h[0];
    h[0] = h[--n];
    sift_down(h, n, 0);
    h[n] = top;
  }
}
