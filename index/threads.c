/*
 * Worker threads for the parallel parts of the library (bulk build, batch queries). A
 * parallel region runs share 0 on the calling thread and the others on POSIX threads
 * created for it; a share whose thread cannot be created runs on the calling thread
 * afterwards, so the result never depends on how many threads actually ran.
 *
 * A call of several parallel regions (the bulk build: four to six) can hold a team for
 * its length (qk__team_begin/qk__team_end): its workers are started once, run the shares
 * of every region the calling thread starts, and wait in between, first spinning (with the
 * processor's pause, not a yield), then parked on a condition variable. Starting a thread and
 * waking it on the other core cost 0.03-2 ms a region on the two vCPUs of the seventeenth session's
 * machine (more than the build's regions take on two threads); a team pays that once per call.
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

#if defined(QK_HAVE_PTHREADS)
/* How long a worker spins for the next region before it parks, and the calling thread for
 * the workers to finish one before it parks: the gaps between a build's regions (its
 * allocations and prefix sums) are well below this. A spinning thread does not yield: on a
 * loaded machine a yield hands its core to another process for a time slice, which made the
 * worker start a region 0.35-0.6 ms late at best (later than a thread created for it); a
 * parked one is woken with the scheduler's preference for a waking thread. */
#define TEAM_SPIN_NS 200000
#define TEAM_WAIT_NS 50000

/* A spinning loop's step. */
static inline void team_relax(void) {
#if defined(__x86_64__) || defined(__i386__)
  __builtin_ia32_pause();
#elif defined(__aarch64__)
  __asm__ __volatile__("yield");
#endif
}

typedef struct team team_t;
typedef struct tworker {
  team_t *p;
  unsigned idx; /* runs share idx + 1 */
} tworker_t;

struct team {
  pthread_mutex_t mu;
  pthread_cond_t go, done;
  atomic_uint gen;     /* regions posted (each worker runs each once) */
  atomic_uint pending; /* workers still in the current region */
  int quit;
  bool busy;      /* a region is running on the team (the calling thread's flag) */
  unsigned n_th;  /* workers started */
  unsigned depth; /* nested qk__team_begin calls on the calling thread */
  /* The current region (written before gen is advanced, read after it is seen). */
  qk__share_fn fn;
  void *ctx;
  unsigned nw;
  pthread_t th[QK__MAX_THREADS];
  tworker_t ww[QK__MAX_THREADS];
};

/* The calling thread's team, if it holds one; its storage. */
static _Thread_local team_t *cur_team;
static _Thread_local team_t team_store;

static long long now_ns(void) {
  struct timespec ts;
  clock_gettime(CLOCK_MONOTONIC, &ts);
  return (long long)ts.tv_sec * 1000000000LL + ts.tv_nsec;
}

static void *team_worker(void *arg) {
  tworker_t *me = arg;
  team_t *p = me->p;
  unsigned seen = 0;
  for (;;) {
    unsigned g = atomic_load_explicit(&p->gen, memory_order_acquire);
    if (g == seen) {
      long long t0 = now_ns();
      while ((g = atomic_load_explicit(&p->gen, memory_order_acquire)) == seen &&
             now_ns() - t0 < TEAM_SPIN_NS)
        team_relax();
      if (g == seen) {
        pthread_mutex_lock(&p->mu);
        while ((g = atomic_load_explicit(&p->gen, memory_order_acquire)) == seen)
          pthread_cond_wait(&p->go, &p->mu);
        pthread_mutex_unlock(&p->mu);
      }
    }
    seen = g;
    if (p->quit) return NULL;
    if (me->idx + 1 < p->nw) p->fn(p->ctx, me->idx + 1, p->nw);
    if (atomic_fetch_sub_explicit(&p->pending, 1u, memory_order_acq_rel) == 1u) {
      pthread_mutex_lock(&p->mu);
      pthread_cond_signal(&p->done);
      pthread_mutex_unlock(&p->mu);
    }
  }
}

/* Post a region to every worker (under the mutex, so that a parking worker's check and wait
 * are one step and no wake-up is lost). */
static void team_post(team_t *p, qk__share_fn fn, void *ctx, unsigned nw, int quit) {
  pthread_mutex_lock(&p->mu);
  p->fn = fn, p->ctx = ctx, p->nw = nw, p->quit = quit;
  atomic_store_explicit(&p->pending, p->n_th, memory_order_relaxed);
  atomic_fetch_add_explicit(&p->gen, 1u, memory_order_release);
  pthread_cond_broadcast(&p->go);
  pthread_mutex_unlock(&p->mu);
}

static void team_wait(team_t *p) {
  long long t0 = now_ns();
  while (atomic_load_explicit(&p->pending, memory_order_acquire) && now_ns() - t0 < TEAM_WAIT_NS)
    team_relax();
  pthread_mutex_lock(&p->mu);
  while (atomic_load_explicit(&p->pending, memory_order_acquire))
    pthread_cond_wait(&p->done, &p->mu);
  pthread_mutex_unlock(&p->mu);
}
#endif

void qk__team_begin(unsigned nw) {
#if defined(QK_HAVE_PTHREADS)
  if (cur_team) {
    cur_team->depth++;
    return;
  }
  if (nw <= 1) return;
  if (nw > QK__MAX_THREADS) nw = QK__MAX_THREADS;
  team_t *p = &team_store;
  p->n_th = 0;
  p->depth = 1;
  p->busy = false;
  if (pthread_mutex_init(&p->mu, NULL)) return;
  if (pthread_cond_init(&p->go, NULL)) goto fail_go;
  if (pthread_cond_init(&p->done, NULL)) goto fail_done;
  atomic_init(&p->gen, 0u);
  atomic_init(&p->pending, 0u);
  p->quit = 0;
  for (unsigned i = 0; i + 1 < nw; i++) {
    p->ww[i] = (tworker_t){p, i};
    if (pthread_create(&p->th[i], NULL, team_worker, &p->ww[i])) break;
    p->n_th++;
  }
  if (p->n_th) {
    cur_team = p;
    return;
  }
  pthread_cond_destroy(&p->done);
fail_done:
  pthread_cond_destroy(&p->go);
fail_go:
  pthread_mutex_destroy(&p->mu);
#else
  (void)nw;
#endif
}

void qk__team_end(void) {
#if defined(QK_HAVE_PTHREADS)
  team_t *p = cur_team;
  if (!p || --p->depth > 0) return;
  team_post(p, NULL, NULL, 0, 1);
  for (unsigned i = 0; i < p->n_th; i++) pthread_join(p->th[i], NULL);
  pthread_cond_destroy(&p->done);
  pthread_cond_destroy(&p->go);
  pthread_mutex_destroy(&p->mu);
  cur_team = NULL;
#endif
}

void qk__run_shares(unsigned nw, qk__share_fn fn, void *ctx) {
  if (nw <= 1) {
    fn(ctx, 0, 1);
    return;
  }
  if (nw > QK__MAX_THREADS) nw = QK__MAX_THREADS;
#if defined(QK_HAVE_PTHREADS)
  team_t *tp = cur_team;
  if (tp && !tp->busy && nw <= tp->n_th + 1) {
    /* On the calling thread's team: share 0 here, the others on its workers (a worker
     * whose share number is nw or more only reports back). */
    tp->busy = true;
    team_post(tp, fn, ctx, nw, 0);
    fn(ctx, 0, nw);
    team_wait(tp);
    tp->busy = false;
    return;
  }
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
