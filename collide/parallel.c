/*
 * A minimal fork-join for the world: n jobs on up to `threads` POSIX threads, the caller
 * running its share. Jobs are handed out statically (job i on thread i mod threads), so
 * which thread did what never changes an answer.
 */
#define _POSIX_C_SOURCE 200809L
#include <pthread.h>
#include <unistd.h>

#include "collide/world_internal.h"

typedef struct job {
  unsigned first, step, n;
  void (*fn)(unsigned, void *);
  void *ud;
} job_t;

static void *run(void *arg) {
  job_t *j = arg;
  for (unsigned i = j->first; i < j->n; i += j->step) j->fn(i, j->ud);
  return NULL;
}

int qk__parallel(unsigned threads, unsigned n, void (*fn)(unsigned i, void *ud), void *ud) {
  if (threads > n) threads = n;
  if (threads > 64) threads = 64;
  if (threads <= 1) {
    for (unsigned i = 0; i < n; i++) fn(i, ud);
    return 0;
  }
  pthread_t th[64];
  job_t jobs[64];
  unsigned started = 0;
  for (unsigned t = 1; t < threads; t++) {
    jobs[t] = (job_t){t, threads, n, fn, ud};
    if (pthread_create(&th[t], NULL, run, &jobs[t]) != 0) break;
    started = t;
  }
  /* Jobs of threads that could not start run here, after the caller's own. */
  jobs[0] = (job_t){0, threads, n, fn, ud};
  run(&jobs[0]);
  for (unsigned t = started + 1; t < threads; t++) {
    jobs[t] = (job_t){t, threads, n, fn, ud};
    run(&jobs[t]);
  }
  for (unsigned t = 1; t <= started; t++) pthread_join(th[t], NULL);
  return started + 1 < threads;
}

unsigned qk__threads_online(uint32_t threads) {
  if (threads == 0) {
#if defined(_SC_NPROCESSORS_ONLN)
    long n = sysconf(_SC_NPROCESSORS_ONLN);
    threads = n > 0 ? (uint32_t)n : 1u;
#else
    threads = 1;
#endif
  }
  return threads > 64 ? 64 : threads;
}
