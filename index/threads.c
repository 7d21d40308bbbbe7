/*
 * Worker threads for the parallel parts of the library (bulk build, batch queries). A
 * parallel region runs share 0 on the calling thread and the others on POSIX threads
 * created for it; a share whose thread cannot be created runs on the calling thread
 * afterwards, so the result never depends on how many threads actually ran.
 */
#define _POSIX_C_SOURCE 200809L
#include <stdatomic.h>
#include <time.h>
#include <unistd.h>

#include "index/index_access.h"

#if defined(QK_HAVE_PTHREADS)
#include <pthread.h>
#include <sched.h>
#endif

unsigned qk__threads_resolve(uint32_t threads) {
  if (threads == 0) {
#if defined(_SC_NPROCESSORS_ONLN)
    long n = sysconf(_SC_NPROCESSORS_ONLN);
    threads = n > 0 ? (uint32_t)n : 1u;
#else
    threads = 1;
#endif
  }
  return threads > QK__MAX_THREADS ? QK__MAX_THREADS : threads;
}

void qk__thread_yield(void) {
#if defined(QK_HAVE_PTHREADS)
  sched_yield();
#endif
}

void qk__thread_nap(void) {
#if defined(QK_HAVE_PTHREADS)
  struct timespec ts = {0, 20000}; /* 20 us */
  nanosleep(&ts, NULL);
#endif
}

typedef struct share {
  qk__share_fn fn;
  void *ctx;
  unsigned w, nw;
} share_t;

#if defined(QK_HAVE_PTHREADS)
static void *run_share(void *arg) {
  share_t *s = arg;
  s->fn(s->ctx, s->w, s->nw);
  return NULL;
}
#endif

void qk__run_shares(unsigned nw, qk__share_fn fn, void *ctx) {
  if (nw <= 1) {
    fn(ctx, 0, 1);
    return;
  }
  if (nw > QK__MAX_THREADS) nw = QK__MAX_THREADS;
#if defined(QK_HAVE_PTHREADS)
  pthread_t th[QK__MAX_THREADS];
  share_t sh[QK__MAX_THREADS];
  bool started[QK__MAX_THREADS] = {false};
  for (unsigned w = 1; w < nw; w++) {
    sh[w] = (share_t){fn, ctx, w, nw};
    started[w] = pthread_create(&th[w], NULL, run_share, &sh[w]) == 0;
  }
  fn(ctx, 0, nw);
  for (unsigned w = 1; w < nw; w++) {
    if (started[w])
      pthread_join(th[w], NULL);
    else
      fn(ctx, w, nw);
  }
#else
  for (unsigned w = 0; w < nw; w++) fn(ctx, w, nw);
#endif
}

typedef struct jobs {
  unsigned n;
  void (*fn)(unsigned, void *);
  void *ud;
} jobs_t;

static void jobs_share(void *ctx, unsigned w, unsigned nw) {
  const jobs_t *j = ctx;
  for (unsigned i = w; i < j->n; i += nw) j->fn(i, j->ud);
}

void qk__run_jobs(unsigned threads, unsigned n, void (*fn)(unsigned i, void *ud), void *ud) {
  jobs_t j = {n, fn, ud};
  qk__run_shares(threads < n ? threads : n, jobs_share, &j);
}

/* Jobs handed out by a shared counter: a share takes the next job when it finishes one,
 * so shares of uneven jobs end together. */
typedef struct djobs {
  atomic_uint next;
  unsigned n;
  void (*fn)(unsigned, unsigned, void *);
  void *ud;
} djobs_t;

static void djobs_share(void *ctx, unsigned w, unsigned nw) {
  (void)nw;
  djobs_t *j = ctx;
  for (;;) {
    unsigned i = atomic_fetch_add_explicit(&j->next, 1u, memory_order_relaxed);
    if (i >= j->n) return;
    j->fn(i, w, j->ud);
  }
}

void qk__run_jobs_dynamic(unsigned threads, unsigned n,
                          void (*fn)(unsigned i, unsigned w, void *ud), void *ud) {
  djobs_t j;
  atomic_init(&j.next, 0u);
  j.n = n;
  j.fn = fn;
  j.ud = ud;
  qk__run_shares(threads < n ? threads : n, djobs_share, &j);
}
