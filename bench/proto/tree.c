/*
 * quadkit-proto-tree: the point tree's bulk build and one-by-one inserts at any capacity,
 * on uniform points in [0,1)^2, through the public API alone. The benchmark builds at
 * capacity 32 only; this times what a caller with other options gets.
 *
 *   quadkit-proto-tree build N CAPACITY [REPS [THREADS [HUGE]]]
 *       free the last tree and build N points REPS times (default 10; threads 1; HUGE 1
 *       sets the tree's huge_pages option); prints the median and best wall time, the
 *       nodes, and the page faults of the first build
 *   quadkit-proto-tree insert N CAPACITY
 *       insert N points one by one into an empty tree with the root [0,1]^2; prints the
 *       time and the tree's memory
 *
 * Wall clock: run it on an idle machine.
 */
#define _POSIX_C_SOURCE 200809L
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/resource.h>
#include <time.h>

#include "quadkit/quadkit.h"

static double now(void) {
  struct timespec t;
  clock_gettime(CLOCK_MONOTONIC, &t);
  return (double)t.tv_sec + 1e-9 * (double)t.tv_nsec;
}

static long faults(void) {
  struct rusage u;
  getrusage(RUSAGE_SELF, &u);
  return u.ru_minflt;
}

static int by_value(const void *a, const void *b) {
  double x = *(const double *)a, y = *(const double *)b;
  return (x > y) - (x < y);
}

static qk_point_t *uniform(size_t n) {
  qk_point_t *p = malloc(n * sizeof *p);
  uint64_t s = 42;
  for (size_t i = 0; p && i < n; i++) {
    s ^= s << 13, s ^= s >> 7, s ^= s << 17;
    p[i].x = (double)(s >> 11) * 0x1p-53;
    s ^= s << 13, s ^= s >> 7, s ^= s << 17;
    p[i].y = (double)(s >> 11) * 0x1p-53;
  }
  return p;
}

static int build(size_t n, unsigned cap, int reps, unsigned threads, int huge) {
  qk_point_t *p = uniform(n);
  double *t = malloc((size_t)reps * sizeof *t);
  if (!p || !t) return 3;
  qk_tree_options_t o;
  qk_tree_options_init(&o);
  o.capacity = cap;
  o.threads = threads;
  o.huge_pages = huge;
  qk_tree_t *tree = NULL;
  long first = 0;
  for (int r = 0; r < reps; r++) {
    long f0 = faults();
    double t0 = now();
    qk_tree_free(tree);
    tree = NULL;
    qk_status_t st = qk_tree_build(p, n, &o, &tree);
    t[r] = now() - t0;
    if (st) {
      fprintf(stderr, "quadkit-proto-tree: build: %s\n", qk_strerror(st));
      return 3;
    }
    if (r == 0) first = faults() - f0;
  }
  qk_tree_stats_t s;
  qk_tree_stats(tree, &s);
  qsort(t, (size_t)reps, sizeof *t, by_value);
  printf("build n=%zu capacity=%u threads=%u: median %.2f ms, best %.2f ms; %zu nodes; first "
         "build %ld page faults\n",
         n, cap, threads, 1e3 * t[reps / 2], 1e3 * t[0], s.nodes, first);
  qk_tree_free(tree);
  free(t);
  free(p);
  return 0;
}

static int insert(size_t n, unsigned cap) {
  qk_point_t *p = uniform(n);
  if (!p) return 3;
  qk_tree_options_t o;
  qk_tree_options_init(&o);
  o.capacity = cap;
  o.has_root = 1;
  o.root = (qk_square_t){0, 0, 1};
  qk_tree_t *tree;
  if (qk_tree_build(NULL, 0, &o, &tree)) return 3;
  double t0 = now();
  for (size_t i = 0; i < n; i++) {
    qk_status_t st = qk_tree_insert(tree, p[i], NULL);
    if (st) {
      fprintf(stderr, "quadkit-proto-tree: insert %zu: %s\n", i, qk_strerror(st));
      return 3;
    }
  }
  double dt = now() - t0;
  printf("insert n=%zu capacity=%u: %.0f ms (%.2f us each), tree %.1f MB\n", n, cap, 1e3 * dt,
         1e6 * dt / (double)n, (double)qk_tree_memory(tree) / 1e6);
  qk_tree_free(tree);
  free(p);
  return 0;
}

int main(int argc, char **argv) {
  if (argc < 4 || (strcmp(argv[1], "build") && strcmp(argv[1], "insert"))) {
    fprintf(stderr, "usage: quadkit-proto-tree build N CAPACITY [REPS [THREADS [HUGE]]]\n"
                    "       quadkit-proto-tree insert N CAPACITY\n");
    return 2;
  }
  size_t n = strtoull(argv[2], NULL, 10);
  unsigned cap = (unsigned)strtoul(argv[3], NULL, 10);
  if (n == 0 || cap == 0) {
    fprintf(stderr, "quadkit-proto-tree: N and CAPACITY must be positive\n");
    return 2;
  }
  if (!strcmp(argv[1], "insert")) return insert(n, cap);
  int reps = argc > 4 ? atoi(argv[4]) : 10;
  if (reps < 1) reps = 1;
  return build(n, cap, reps, argc > 5 ? (unsigned)atoi(argv[5]) : 1, argc > 6 && atoi(argv[6]));
}
