/*
 * The world's worker threads. An update runs up to eight parallel steps (the re-filing's
 * merge, the packing, the search, the rows' four passes); starting and joining threads for
 * each (qk__run_shares) costs a thread creation, a wake-up on another core and a join per
 * step and thread, every frame. So a world with threads > 1 keeps its workers: they are
 * started by the first update that uses them, run the shares of every later step, and in
 * between wait: first by yielding (qk__thread_yield) for a short while, since the next step
 * of an update follows within microseconds, then parked on a condition variable until the
 * next step or qk_world_free. The calling thread runs share 0 of every step, as before, so
 * the shares and what each writes are those of qk__run_shares: no answer depends on which
 * of them ran the workers.
 *
 * The pool serves one step at a time. The update has the world to itself, but the batch
 * queries (const, maybe from several threads at once) also run steps: a step that finds
 * the pool taken runs on threads started for it instead (qk__run_shares).
 *
 * A detached job (qk__world_pool_detach: the scratch cache's blocks given back at the end
 * of an update) is a step of its own that only the first worker runs and nobody waits
 * for: the caller goes on, and the pool's next step, or its end, first waits for it.
 */
#define _POSIX_C_SOURCE 200809L
#include <stdatomic.h>
#include <string.h>
#include <time.h>
#include <unistd.h>

#include "collide/world_internal.h"

#if defined(QK_HAVE_PTHREADS)
#include <pthread.h>

/* How long a waiting thread yields before it parks: a worker while an update holds the
 * pool (the gaps between its steps are mostly well below this), the calling thread for
 * the workers to finish a step. Otherwise (between frames, after a batch query) the
 * workers park at once. */
#define QK__WPOOL_SPIN_NS 200000
#define QK__WPOOL_WAIT_NS 50000

struct qk__wpool;
typedef struct wworker {
  struct qk__wpool *p;
  unsigned idx; /* runs share idx + 1 */
} wworker_t;

struct qk__wpool {
  pthread_mutex_t mu;
  pthread_cond_t go, done;
  atomic_uint gen;     /* steps posted (the workers run each one once) */
  atomic_uint pending; /* workers still in the current step */
  atomic_int busy;     /* a step is running */
  atomic_int hold;     /* an update runs: the workers yield between its steps */
  int quit;
  unsigned n_th; /* workers started */
  pid_t proc;    /* the process that started them (a forked child has none of them) */
  /* The current step (written before gen is advanced, read after it is seen). */
  qk__share_fn fn;
  void *ctx;
  unsigned nw;
  /* A detached job (qk__world_pool_detach): run by the first worker as a step of its own
   * that nobody waits for until the pool's next step or its end. */
  void (*dfn)(void *);
  void *dctx;
  pthread_t th[QK__MAX_THREADS];
  wworker_t ww[QK__MAX_THREADS];
};

static long long now_ns(void) {
  struct timespec ts;
  clock_gettime(CLOCK_MONOTONIC, &ts);
  return (long long)ts.tv_sec * 1000000000LL + ts.tv_nsec;
}

static void *worker(void *arg) {
  wworker_t *me = arg;
  struct qk__wpool *p = me->p;
  unsigned seen = 0; /* (the pool posts nothing before its workers are started) */
  for (;;) {
    /* The next step: yield a while, then park. */
    unsigned g = atomic_load_explicit(&p->gen, memory_order_acquire);
    if (g == seen) {
      long long t0 = now_ns();
      while ((g = atomic_load_explicit(&p->gen, memory_order_acquire)) == seen &&
             atomic_load_explicit(&p->hold, memory_order_relaxed) &&
             now_ns() - t0 < QK__WPOOL_SPIN_NS)
        qk__thread_yield();
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

/* Post a step to every worker (the pool's mutex makes a parked worker's check and wait
 * one step, so no wake-up is lost). */
static void post(struct qk__wpool *p, qk__share_fn fn, void *ctx, unsigned nw, int quit) {
  pthread_mutex_lock(&p->mu);
  p->fn = fn, p->ctx = ctx, p->nw = nw, p->quit = quit;
  atomic_store_explicit(&p->pending, p->n_th, memory_order_relaxed);
  atomic_fetch_add_explicit(&p->gen, 1u, memory_order_release);
  pthread_cond_broadcast(&p->go);
  pthread_mutex_unlock(&p->mu);
}

static void wait_done(struct qk__wpool *p) {
  if (!atomic_load_explicit(&p->pending, memory_order_acquire)) return;
  long long t0 = now_ns();
  while (atomic_load_explicit(&p->pending, memory_order_acquire) &&
         now_ns() - t0 < QK__WPOOL_WAIT_NS)
    qk__thread_yield();
  pthread_mutex_lock(&p->mu);
  while (atomic_load_explicit(&p->pending, memory_order_acquire))
    pthread_cond_wait(&p->done, &p->mu);
  pthread_mutex_unlock(&p->mu);
}

/* In a child forked after the workers started, they do not exist: the pool is left
 * unused (its memory freed, its locks not touched) and the steps start threads as
 * before, until the next update starts workers of the child's own. */
static int forked(const struct qk__wpool *p) { return p->proc != getpid(); }

void qk__world_pool_start(qk_world_t *w, unsigned threads) {
  if (w->pool && forked(w->pool)) qk__free(&w->alloc, w->pool, sizeof *w->pool), w->pool = NULL;
  if (w->pool || threads < 2) return;
  if (threads > QK__MAX_THREADS) threads = QK__MAX_THREADS;
  struct qk__wpool *p = qk__realloc(&w->alloc, NULL, 0, sizeof *p);
  if (!p) return; /* (the steps start their own threads) */
  memset(p, 0, sizeof *p);
  if (pthread_mutex_init(&p->mu, NULL)) goto fail_mu;
  if (pthread_cond_init(&p->go, NULL)) goto fail_go;
  if (pthread_cond_init(&p->done, NULL)) goto fail_done;
  atomic_init(&p->gen, 0u);
  atomic_init(&p->pending, 0u);
  atomic_init(&p->busy, 0);
  atomic_init(&p->hold, 0);
  p->proc = getpid();
  for (unsigned i = 0; i + 1 < threads; i++) {
    p->ww[i] = (wworker_t){p, i};
    if (pthread_create(&p->th[i], NULL, worker, &p->ww[i])) break;
    p->n_th++;
  }
  if (!p->n_th) {
    pthread_cond_destroy(&p->done);
  fail_done:
    pthread_cond_destroy(&p->go);
  fail_go:
    pthread_mutex_destroy(&p->mu);
  fail_mu:
    qk__free(&w->alloc, p, sizeof *p);
    return;
  }
  w->pool = p;
}

void qk__world_pool_free(qk_world_t *w) {
  struct qk__wpool *p = w->pool;
  if (!p) return;
  if (forked(p)) {
    qk__free(&w->alloc, p, sizeof *p);
    w->pool = NULL;
    return;
  }
  wait_done(p); /* (a detached job) */
  post(p, NULL, NULL, 0, 1);
  for (unsigned i = 0; i < p->n_th; i++) pthread_join(p->th[i], NULL);
  pthread_cond_destroy(&p->done);
  pthread_cond_destroy(&p->go);
  pthread_mutex_destroy(&p->mu);
  qk__free(&w->alloc, p, sizeof *p);
  w->pool = NULL;
}

void qk__world_pool_hold(qk_world_t *w, int on) {
  if (w->pool) atomic_store_explicit(&w->pool->hold, on, memory_order_relaxed);
}

/* Shares 0 .. nw - 1 of fn on the pool (share 0 here), or 0 when it is taken. */
static int pool_run(struct qk__wpool *p, unsigned nw, qk__share_fn fn, void *ctx) {
  int idle = 0;
  if (!atomic_compare_exchange_strong_explicit(&p->busy, &idle, 1, memory_order_acquire,
                                               memory_order_relaxed))
    return 0;
  wait_done(p); /* (a detached job: the workers are ours once it ends) */
  post(p, fn, ctx, nw, 0);
  fn(ctx, 0, nw);
  /* Shares beyond the workers started (a creation failed) run here. */
  for (unsigned s = p->n_th + 1; s < nw; s++) fn(ctx, s, nw);
  wait_done(p);
  atomic_store_explicit(&p->busy, 0, memory_order_release);
  return 1;
}

static void detach_share(void *ctx, unsigned s, unsigned nw) {
  const struct qk__wpool *p = ctx;
  (void)nw;
  if (s == 1) p->dfn(p->dctx);
}

int qk__world_pool_detach(qk_world_t *w, void (*fn)(void *), void *ctx) {
  struct qk__wpool *p = w->pool;
  int idle = 0;
  if (!p || forked(p) ||
      !atomic_compare_exchange_strong_explicit(&p->busy, &idle, 1, memory_order_acquire,
                                               memory_order_relaxed))
    return 0;
  wait_done(p); /* (the one before) */
  p->dfn = fn, p->dctx = ctx;
  post(p, detach_share, p, 2, 0);
  atomic_store_explicit(&p->busy, 0, memory_order_release);
  return 1;
}
#else
int qk__world_pool_detach(qk_world_t *w, void (*fn)(void *), void *ctx) {
  (void)w, (void)fn, (void)ctx;
  return 0;
}
void qk__world_pool_start(qk_world_t *w, unsigned threads) { (void)w, (void)threads; }
void qk__world_pool_free(qk_world_t *w) { (void)w; }
void qk__world_pool_hold(qk_world_t *w, int on) { (void)w, (void)on; }
#endif

/* Jobs i = share, share + nw, ... of a qk__world_run_jobs call (qk__run_jobs' split). */
typedef struct wjobs {
  unsigned n;
  void (*fn)(unsigned, void *);
  void *ud;
} wjobs_t;

static void wjobs_share(void *ctx, unsigned s, unsigned nw) {
  const wjobs_t *j = ctx;
  for (unsigned i = s; i < j->n; i += nw) j->fn(i, j->ud);
}

void qk__world_run_jobs(const qk_world_t *w, unsigned threads, unsigned n,
                        void (*fn)(unsigned i, void *ud), void *ud) {
  wjobs_t j = {n, fn, ud};
  unsigned nw = threads < n ? threads : n;
  if (nw > QK__MAX_THREADS) nw = QK__MAX_THREADS;
  if (nw <= 1) {
    wjobs_share(&j, 0, 1);
    return;
  }
#if defined(QK_HAVE_PTHREADS)
  if (w->pool && !forked(w->pool) && pool_run(w->pool, nw, wjobs_share, &j)) return;
#else
  (void)w;
#endif
  qk__run_shares(nw, wjobs_share, &j);
}
