/*
 * quadkit-proto-cores: what two threads can gain on this machine, whatever the code. Not
 * a benchmark of quadkit: it measures the machine the two-thread rows run on.
 *
 *   - compute: six independent integer chains, then eight floating-point ones, on one
 *     thread and then on two (each pinned to its own processor): the throughput ratio
 *     two threads reach when nothing is shared;
 *   - memory: each thread reads its own 64 MB, a line a step, twenty times: the ratio
 *     when the memory system is shared;
 *   - latency: a chain of dependent loads at random through 64 MB (each load's address is
 *     the one before's value), on each processor alone and on both at once: whether the
 *     two processors wait as long for memory (on this guest they need not; a search that
 *     misses the caches, one nearest-neighbour query a call, ran up to a third slower on
 *     the slower one), and the loads a second of both at once against one thread on the
 *     faster processor alone: what a two-thread row bound by latency can gain at most;
 *   - transfer: one cache line passed back and forth between two pinned threads: how
 *     long a line one thread wrote takes to reach the other (one way);
 *   - start: how long a thread started on the other processor takes to run, as it is, and
 *     right after this process faulted in 40 MB of new pages (4 KB ones, then huge pages):
 *     on a guest whose hypervisor must catch up with a process's new page mappings before
 *     another vCPU runs it, the first run there waits for that (docs/design.md, "Threads").
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
#include <string.h>
#include <sys/mman.h>
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
  double ns; /* latency: nanoseconds a load */
} task_t;

static uint64_t *chain; /* latency: two random cycles of CHAIN words, one a thread */
#define CHAIN ((size_t)8 << 20)
#define CHASE 4000000L

static void *work(void *arg) {
  task_t *t = arg;
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
  } else if (t->kind == 3) {
    const uint64_t *c = chain + (size_t)t->half * CHAIN;
    uint64_t at = 0;
    double t0 = now();
    for (long i = 0; i < CHASE; i++) at = c[at];
    t->ns = (now() - t0) / CHASE * 1e9;
    a = at;
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

/* Two random cycles through CHAIN words each (Sattolo's shuffle: one cycle), so every load
 * depends on the one before and lands on a line the caches do not hold. */
static void make_chains(void) {
  chain = malloc(2 * CHAIN * sizeof *chain);
  if (!chain) {
    fprintf(stderr, "quadkit-proto-cores: out of memory\n");
    exit(1);
  }
  uint64_t z = 88172645463325252ull;
  for (int h = 0; h < 2; h++) {
    uint64_t *c = chain + (size_t)h * CHAIN;
    for (size_t i = 0; i < CHAIN; i++) c[i] = i;
    for (size_t i = CHAIN - 1; i > 0; i--) {
      z ^= z << 13, z ^= z >> 7, z ^= z << 17;
      size_t j = z % i;
      uint64_t v = c[i];
      c[i] = c[j], c[j] = v;
    }
  }
}

/* Dependent loads on cpu_a alone, on cpu_b alone (the calling thread moved there), then on
 * both at once (each its own cycle). */
static void latency(void) {
  make_chains();
  task_t a = {3, cpu_a, 0, 0}, b = {3, cpu_b, 1, 0};
  work(&a);
  double alone_a = a.ns;
  work(&b);
  double alone_b = b.ns;
  pin(cpu_a);
  pthread_t th;
  if (pthread_create(&th, NULL, work, &b) != 0) {
    fprintf(stderr, "quadkit-proto-cores: cannot start a thread\n");
    exit(1);
  }
  work(&a);
  pthread_join(th, NULL);
  double fast = alone_a < alone_b ? alone_a : alone_b;
  printf("latency   a load at random in 64 MB: %.0f ns on %d alone, %.0f ns on %d alone; "
         "both at once %.0f and %.0f ns\n",
         alone_a, cpu_a, alone_b, cpu_b, a.ns, b.ns);
  printf("          two threads at once made %.2fx the loads a second of one thread on the faster "
         "processor alone: what a latency-bound two-thread row can gain at most\n",
         fast / a.ns + fast / b.ns);
  free(chain);
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

static _Atomic double started_at;

static void *note_start(void *arg) {
  (void)arg;
  atomic_store(&started_at, now());
  return NULL;
}

static int by_value(const void *a, const void *b) {
  double x = *(const double *)a, y = *(const double *)b;
  return (x > y) - (x < y);
}

/* The median time from pthread_create to the thread's first instruction, a thread pinned to
 * cpu_b started from cpu_a after a pause, over 9 starts; before each, with `mb` > 0, this
 * process maps and writes `mb` MB of new pages (huge pages asked for with `huge`), which
 * stay mapped until the thread has run. */
static void start(size_t mb, int huge, const char *what) {
  double d[9];
  for (int r = 0; r < 9; r++) {
    size_t bytes = mb << 20;
    char *m = NULL;
    if (bytes) {
      m = mmap(NULL, bytes, PROT_READ | PROT_WRITE, MAP_PRIVATE | MAP_ANONYMOUS, -1, 0);
      if (m == MAP_FAILED) {
        fprintf(stderr, "quadkit-proto-cores: cannot map %zu MB\n", mb);
        exit(1);
      }
#if defined(MADV_HUGEPAGE)
      if (huge) madvise(m, bytes, MADV_HUGEPAGE);
#endif
      memset(m, r + 1, bytes);
    }
    struct timespec pause = {0, 20000000}; /* 20 ms: the other vCPU idles */
    nanosleep(&pause, NULL);
    pthread_attr_t at;
    cpu_set_t s;
    CPU_ZERO(&s);
    CPU_SET(cpu_b, &s);
    pthread_t th;
    if (pthread_attr_init(&at) || pthread_attr_setaffinity_np(&at, sizeof s, &s)) exit(1);
    atomic_store(&started_at, 0.0);
    double t0 = now();
    if (pthread_create(&th, &at, note_start, NULL) != 0) {
      fprintf(stderr, "quadkit-proto-cores: cannot start a thread\n");
      exit(1);
    }
    pthread_join(th, NULL);
    pthread_attr_destroy(&at);
    d[r] = (atomic_load(&started_at) - t0) * 1e3;
    if (m) munmap(m, bytes);
  }
  qsort(d, 9, sizeof *d, by_value);
  printf("start     a thread on the other processor %s: median %.2f ms (%.2f-%.2f)\n", what, d[4],
         d[0], d[8]);
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
  latency();
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
  start(0, 0, "as it is");
  start(40, 0, "after 40 MB of new 4 KB pages");
  start(40, 1, "after 40 MB of new huge pages");
  return 0;
}
