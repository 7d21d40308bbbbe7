/*
 * quadkit-proto-cores: what two threads can gain on this machine, whatever the code. Not
 * a benchmark of quadkit: it measures the machine the two-thread rows run on.
 *
 *   - compute: six independent integer chains, then eight floating-point ones, on one
 *     thread and then on two (each pinned to its own processor): the throughput ratio
 *     two threads reach when nothing is shared;
 *   - memory: each thread reads its own 64 MB, a line a step, twenty times: the ratio
 *     when the memory system is shared;
 *   - transfer: one cache line passed back and forth between two pinned threads: how
 *     long a line one thread wrote takes to reach the other (one way).
 *
 * Usage: quadkit-proto-cores [cpu_a cpu_b]   (default 0 and 1)
 */
#define _GNU_SOURCE
#include <pthread.h>
#include <sched.h>
#include <stdatomic.h>
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <time.h>

static int cpu_a = 0, cpu_b = 1;
static double *buf;
static size_t nbuf;
static volatile uint64_t sink;

static double now(void) {
  struct timespec t;
  clock_gettime(CLOCK_MONOTONIC, &t);
  return (double)t.tv_sec + 1e-9 * (double)t.tv_nsec;
}

static void pin(int cpu) {
  cpu_set_t s;
  CPU_ZERO(&s);
  CPU_SET(cpu, &s);
  pthread_setaffinity_np(pthread_self(), sizeof s, &s);
}

typedef struct task {
  int kind, cpu, half;
} task_t;

static void *work(void *arg) {
  const task_t *t = arg;
  pin(t->cpu);
  uint64_t a = 1, b = 2, c = 3, d = 4, e = 5, f = 6;
  if (t->kind == 0) {
    for (long i = 0; i < 300000000L; i++) {
      a = a * 3 + 1, b = b * 5 + 1, c ^= c << 1;
      d += d >> 1, e = e * 7 + 3, f ^= f >> 3;
    }
  } else if (t->kind == 1) {
    double x[8] = {1, 2, 3, 4, 5, 6, 7, 8};
    for (long i = 0; i < 150000000L; i++)
      for (int k = 0; k < 8; k++) x[k] = x[k] * 1.0000001 + 1e-9;
    a = (uint64_t)x[3];
  } else {
    const double *p = buf + (size_t)t->half * (nbuf / 2);
    double s = 0;
    for (int r = 0; r < 20; r++)
      for (size_t i = 0; i < nbuf / 2; i += 8) s += p[i];
    a = (uint64_t)s;
  }
  sink = a + b + c + d + e + f;
  return NULL;
}

static void scaling(int kind, const char *what) {
  task_t one = {kind, cpu_a, 0}, two = {kind, cpu_b, 1};
  double t0 = now();
  work(&one);
  double t1 = now();
  pthread_t th;
  double t2 = now();
  if (pthread_create(&th, NULL, work, &two) != 0) {
    fprintf(stderr, "quadkit-proto-cores: cannot start a thread\n");
    exit(1);
  }
  work(&one);
  pthread_join(th, NULL);
  double t3 = now();
  printf("%-9s one thread %.3f s, two threads (twice the work) %.3f s: %.2fx\n", what, t1 - t0,
         t3 - t2, 2 * (t1 - t0) / (t3 - t2));
}

#define ROUNDS 2000000
static _Alignas(64) _Atomic int flag;

static void *bounce(void *arg) {
  (void)arg;
  pin(cpu_b);
  for (int i = 0; i < ROUNDS; i++) {
    while (atomic_load_explicit(&flag, memory_order_acquire) != 2 * i + 1) {
    }
    atomic_store_explicit(&flag, 2 * i + 2, memory_order_release);
  }
  return NULL;
}

int main(int argc, char **argv) {
  if (argc == 3) cpu_a = atoi(argv[1]), cpu_b = atoi(argv[2]);
  nbuf = (size_t)16 << 20; /* 128 MB: 64 MB a thread */
  buf = malloc(nbuf * sizeof *buf);
  if (!buf) {
    fprintf(stderr, "quadkit-proto-cores: out of memory\n");
    return 1;
  }
  for (size_t i = 0; i < nbuf; i++) buf[i] = (double)i;
  pin(cpu_a);
  printf("processors %d and %d\n", cpu_a, cpu_b);
  scaling(0, "integer");
  scaling(1, "float");
  scaling(2, "memory");
  pthread_t th;
  if (pthread_create(&th, NULL, bounce, NULL) != 0) return 1;
  double t0 = now();
  for (int i = 0; i < ROUNDS; i++) {
    atomic_store_explicit(&flag, 2 * i + 1, memory_order_release);
    while (atomic_load_explicit(&flag, memory_order_acquire) != 2 * i + 2) {
    }
  }
  double t1 = now();
  pthread_join(th, NULL);
  printf("transfer  a line between the two: %.0f ns one way (%.0f ns a round trip)\n",
         (t1 - t0) / ROUNDS / 2 * 1e9, (t1 - t0) / ROUNDS * 1e9);
  free(buf);
  return 0;
}
