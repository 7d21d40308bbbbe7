/*
 * Worker threads for the parallel parts of the library (bulk build, batch queries). A
 * parallel region runs share 0 on the calling thread and the others on POSIX threads
 * created for it; a share whose thread cannot be created runs on the calling thread
 * afterwards, so the result never depends on how many threads actually ran.
 *
 * Callers that run many parallel regions in a row keep a pool of workers (qk__pool_t): they
 * are started once, run the shares of every region the owner starts on the pool, and wait
 * in between, first spinning (with the processor's pause, not a yield) while the owner
 * holds the pool, then parked on a condition variable. When the owner has run share 0 it
 * runs the shares no worker has taken yet itself, so a region never waits for a worker
 * that is slow to start (3 ms on the PVM guest of the twenty-eighth session). Starting a
 * thread and waking it on the other core cost 0.03-2 ms a region on the two vCPUs of the
 * seventeenth session's machine (more than the build's regions take on two threads); a
 * pool pays that once. The bulk build holds one for its length (a team:
 * qk__team_begin/qk__team_end, four to six regions), and so do the kNN, locate, radius and
 * ray batches (their sorts' regions and the queries'); a world keeps one from its first
 * threaded update to qk_world_free (eight steps an update, collide/world_threads.c), with a
 * detached job for the end of an update. Threads created for a region, and a pool's
 * workers, start away from the creating thread's processor (start_away).
 */
#if defined(__linux__)
#define _GNU_SOURCE /* sched_getcpu, CPU_SET, pthread_attr_setaffinity_np */
#else
#define _POSIX_C_SOURCE 200809L
#endif
#include <stdatomic.h>
#include <stddef.h>
#include <string.h>
#include <time.h>
#include <unistd.h>

#include "index/index_access.h"

#if defined(QK_HAVE_PTHREADS)
#include <pthread.h>
#include <sched.h>
#endif
/* Workers started away from the starting thread's processor (see start_away()). */
#if defined(QK_HAVE_PTHREADS) && defined(__linux__) && defined(CPU_SET)
#define QK__POOL_AWAY 1
#else
#define QK__POOL_AWAY 0
#endif

int qk__shares_away_off;
int qk__pool_steal_off;
_Atomic int qk__pool_workers_idle;

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
#if QK__POOL_AWAY
  const cpu_set_t *home; /* started away: the starting thread's processors to take back */
  int home_cpu;          /* and the processor it ran on */
#endif
} share_t;

#if QK__POOL_AWAY
/* Thread attributes that start a thread on any of the calling thread's processors but the
 * one it runs on, with the caller's processor in *me and its whole set in *home; false
 * (start it as usual) where there is no other. This guest's scheduler placed a new thread
 * on its creator's processor, next to the running creator, and left it there: a pool's
 * worker for the whole of a build (one vCPU idle, the two shares of every region run one
 * after the other), and a region's thread for all of its share (see qk__run_shares). The
 * thread takes the creator's full set of processors back as soon as it runs. */
static bool start_away(pthread_attr_t *attr, cpu_set_t *home, int *me) {
  *me = sched_getcpu();
  if (*me < 0 || *me >= CPU_SETSIZE || pthread_getaffinity_np(pthread_self(), sizeof *home, home))
    return false;
  cpu_set_t away = *home;
  CPU_CLR(*me, &away);
  if (CPU_COUNT(&away) == 0 || pthread_attr_init(attr) != 0) return false;
  if (pthread_attr_setaffinity_np(attr, sizeof away, &away) != 0) {
    pthread_attr_destroy(attr);
    return false;
  }
  return true;
}
#endif

#if QK__POOL_AWAY
/* Where a region's thread first ran and where the thread that started it ran then, when it
 * was started away (tests: qk__share_start_cpu). */
static _Thread_local int share_start_cpu = -1, share_home_cpu = -1;
#endif

#if defined(QK_HAVE_PTHREADS)
static void *run_share(void *arg) {
  share_t *s = arg;
#if QK__POOL_AWAY
  /* Started on another processor: from here on the scheduler may place it anywhere the
   * starting thread may run. */
  if (s->home) {
    share_start_cpu = sched_getcpu();
    share_home_cpu = s->home_cpu;
    (void)pthread_setaffinity_np(pthread_self(), sizeof *s->home, s->home);
  }
#endif
  s->fn(s->ctx, s->w, s->nw);
  return NULL;
}
#endif

#if defined(QK_HAVE_PTHREADS)
/* How long a worker spins for the next region before it parks while its pool is held (the
 * gaps between a build's regions, its allocations and prefix sums, and between an update's
 * steps are well below this), and the calling thread for the workers to finish a region
 * before it parks when it does not hold the pool. A spinning thread does not yield: on a loaded
 * machine a yield hands its core to another process for a time slice, which made the worker start a
 * region 0.35-0.6 ms late at best (later than a thread created for it); a parked one is woken with
 * the scheduler's preference for a waking thread. */
#define POOL_SPIN_NS 200000
#define POOL_WAIT_NS 50000
/* How long the calling thread waits for the workers to finish a region by spinning while it
 * holds the pool, before it parks. A parked owner was woken 1-2.6 ms after the last worker
 * had finished in some regions of the two-thread build (load 9 from other helpers' sessions,
 * the driver's session at high weight): summed over a build's four regions, 0.88-0.92 ms in
 * the mean waiting with 50 us of spinning, 0.06-0.25 ms with this (1M uniform points, 40
 * builds). The shares of a region are unequal by up to half a millisecond (the scatter's). */
#define POOL_OWNER_SPIN_NS 1000000

/* A spinning loop's step. */
static inline void pool_relax(void) {
#if defined(__x86_64__) || defined(__i386__)
  __builtin_ia32_pause();
#elif defined(__aarch64__)
  __asm__ __volatile__("yield");
#endif
}

/* A worker's slot in its pool: which share it runs, and the last region (its gen) that share
 * was taken in, by the worker or by the owner; a share runs once, on whoever takes it
 * first. */
typedef struct pworker {
  _Atomic uint64_t taken;
  unsigned idx; /* runs share idx + 1 */
} pworker_t;

struct qk__pool {
  pthread_mutex_t mu;
  pthread_cond_t go, done;
  /* The region posted last: its number (from 1) times 2^8 plus its number of shares, in one
   * word, so that a worker that reads it knows how many shares that region has (none: the
   * workers end). */
  _Atomic uint64_t gen;
  atomic_uint running;  /* workers taking a share or running one */
  atomic_int busy;      /* a region (or the start of a detached job) is being run */
  atomic_int hold;      /* the owner runs regions back to back: the workers spin between them */
  unsigned n_th;        /* workers started */
  unsigned owner_parks; /* waits for a region's end that parked (tests) */
  pid_t proc;           /* the process that started them (a forked child has none of them) */
  qk_allocator_t alloc; /* the pool's memory came from here */
  /* The current region (written before gen is advanced, read by a worker once it has taken
   * a share of it). */
  qk__share_fn fn;
  void *ctx;
  /* A detached job: run by the first worker as a region of its own that nobody waits for
   * until the pool's next region or its end. */
  void (*dfn)(void *);
  void *dctx;
  pthread_t th[QK__MAX_THREADS];
  pworker_t ww[QK__MAX_THREADS];
#if QK__POOL_AWAY
  int away;       /* the workers were started away from processor `home_cpu` */
  int home_cpu;   /* the starting thread's processor when the workers were started */
  cpu_set_t home; /* the starting thread's processors, which each worker takes back */
  int start_cpu[QK__MAX_THREADS]; /* where each worker first ran (tests), -1 before */
  int owner_ok;                   /* owner_set holds the starting thread's processors */
  cpu_set_t owner_set;            /* (a kept team serves only threads allowed the same ones) */
#endif
};

static long long now_ns(void) {
  struct timespec ts;
  clock_gettime(CLOCK_MONOTONIC, &ts);
  return (long long)ts.tv_sec * 1000000000LL + ts.tv_nsec;
}

/* Whether a worker that began waiting at t0 still spins at time t: while the pool is held,
 * for POOL_SPIN_NS; otherwise it parks at once. */
static bool pool_spins(qk__pool_t *p, long long t0, long long t) {
  return atomic_load_explicit(&p->hold, memory_order_relaxed) && t - t0 < POOL_SPIN_NS;
}

#define GEN_SHARES(g) ((unsigned)((g)&0xffu))
_Static_assert(QK__MAX_THREADS < 256, "a region's share count fits the low byte of its gen");

/* Take share s (< the region's shares) of region g: true for the first taker only. A worker
 * late for region g (its owner has posted others since) finds its share taken: the owner
 * takes every share no worker has before it leaves a region. */
static bool take(qk__pool_t *p, unsigned s, uint64_t g) {
  _Atomic uint64_t *t = &p->ww[s - 1].taken;
  uint64_t v = atomic_load(t);
  while (v < g)
    if (atomic_compare_exchange_weak(t, &v, g)) return true;
  return false;
}

static void *pool_worker(void *arg) {
  pworker_t *me = arg;
  /* (the pool the slot lies in: a pointer in each slot made the pool 512 bytes larger, which
   * moved glibc's heap top in the benchmark's process so that it was trimmed and faulted
   * back in between one-thread calls: 3.4 times the page faults in `--op collide`) */
  qk__pool_t *p = (qk__pool_t *)(void *)((char *)(me - me->idx) - offsetof(qk__pool_t, ww));
  uint64_t seen = 0; /* (the pool posts nothing before its workers are started) */
#if QK__POOL_AWAY
  if (p->away) {
    /* Started on another processor: from here on the scheduler may place it anywhere the
     * starting thread may run. */
    p->start_cpu[me->idx] = sched_getcpu();
    (void)pthread_setaffinity_np(pthread_self(), sizeof p->home, &p->home);
  }
#endif
  for (;;) {
    /* The next region: spin a while, then park. */
    uint64_t g = atomic_load_explicit(&p->gen, memory_order_acquire);
    if (g == seen) {
      long long t0 = now_ns();
      while ((g = atomic_load_explicit(&p->gen, memory_order_acquire)) == seen &&
             pool_spins(p, t0, now_ns()))
        pool_relax();
      if (g == seen) {
        pthread_mutex_lock(&p->mu);
        while ((g = atomic_load_explicit(&p->gen, memory_order_acquire)) == seen)
          pthread_cond_wait(&p->go, &p->mu);
        pthread_mutex_unlock(&p->mu);
      }
    }
    seen = g;
    const unsigned s = me->idx + 1, nw = GEN_SHARES(g);
    if (nw == 0) return NULL;
    if (s >= nw || atomic_load_explicit(&qk__pool_workers_idle, memory_order_relaxed)) continue;
    /* Counted as running before the attempt, so that an owner who finds the share taken
     * also finds the count raised until its run ends. The region's fields are read only
     * once the share is ours: the owner waits for the count before it posts another. */
    atomic_fetch_add(&p->running, 1u);
    if (take(p, s, g)) p->fn(p->ctx, s, nw);
    if (atomic_fetch_sub(&p->running, 1u) == 1u) {
      pthread_mutex_lock(&p->mu);
      pthread_cond_signal(&p->done);
      pthread_mutex_unlock(&p->mu);
    }
  }
}

/* Post a region to every worker (under the mutex, so that a parking worker's check and wait
 * are one step and no wake-up is lost). */
static uint64_t pool_post(qk__pool_t *p, qk__share_fn fn, void *ctx, unsigned nw) {
  pthread_mutex_lock(&p->mu);
  p->fn = fn, p->ctx = ctx;
  uint64_t g0 = atomic_load_explicit(&p->gen, memory_order_relaxed);
  uint64_t g = ((g0 >> 8) + 1) << 8 | nw;
  atomic_store_explicit(&p->gen, g, memory_order_release);
  pthread_cond_broadcast(&p->go);
  pthread_mutex_unlock(&p->mu);
  return g;
}

unsigned long qk__pool_wait_spin_ns(const qk__pool_t *p) {
  return atomic_load_explicit(&p->hold, memory_order_relaxed) ? POOL_OWNER_SPIN_NS : POOL_WAIT_NS;
}

/* Whether the region posted last still runs: a share of it not yet taken, or a worker
 * taking or running one. */
static bool pool_busy(qk__pool_t *p) {
  uint64_t g = atomic_load_explicit(&p->gen, memory_order_relaxed);
  for (unsigned s = 1; s < GEN_SHARES(g); s++)
    if (atomic_load(&p->ww[s - 1].taken) < g) return true;
  return atomic_load(&p->running) != 0;
}

/* Wait for the workers to finish the region posted last. */
static void pool_wait(qk__pool_t *p) {
  if (!pool_busy(p)) return;
  long long t0 = now_ns(), spin = (long long)qk__pool_wait_spin_ns(p);
  while (pool_busy(p) && now_ns() - t0 < spin) pool_relax();
  pthread_mutex_lock(&p->mu);
  if (pool_busy(p)) p->owner_parks++;
  while (pool_busy(p)) pthread_cond_wait(&p->done, &p->mu);
  pthread_mutex_unlock(&p->mu);
}

static bool pool_forked(const qk__pool_t *p) { return p->proc != getpid(); }

#if QK__POOL_AWAY
/* The workers' start away from the starting thread's processor (start_away); a worker
 * started elsewhere stays there while it spins between regions. */
static bool pool_away(qk__pool_t *p, pthread_attr_t *attr) {
  p->away = 0;
  for (unsigned i = 0; i < QK__MAX_THREADS; i++) p->start_cpu[i] = -1;
  if (!start_away(attr, &p->home, &p->home_cpu)) return false;
  p->away = 1;
  return true;
}
#endif

qk__pool_t *qk__pool_new(const qk_allocator_t *a, unsigned nw) {
  if (nw <= 1) return NULL;
  if (nw > QK__MAX_THREADS) nw = QK__MAX_THREADS;
  qk__pool_t *p = qk__realloc(a, NULL, 0, sizeof *p);
  if (!p) return NULL;
  memset(p, 0, sizeof *p);
  p->alloc = a ? *a : (qk_allocator_t){NULL, NULL};
  if (pthread_mutex_init(&p->mu, NULL)) goto fail_mu;
  if (pthread_cond_init(&p->go, NULL)) goto fail_go;
  if (pthread_cond_init(&p->done, NULL)) goto fail_done;
  atomic_init(&p->gen, 0);
  atomic_init(&p->running, 0u);
  atomic_init(&p->busy, 0);
  atomic_init(&p->hold, 0);
  p->proc = getpid();
  pthread_attr_t attr, *ap = NULL;
#if QK__POOL_AWAY
  p->owner_ok = pthread_getaffinity_np(pthread_self(), sizeof p->owner_set, &p->owner_set) == 0;
  if (pool_away(p, &attr)) ap = &attr;
#else
  (void)attr;
#endif
  for (unsigned i = 0; i + 1 < nw; i++) {
    atomic_init(&p->ww[i].taken, 0);
    p->ww[i].idx = i;
    /* (where the system refuses the placement, a worker started as usual) */
    if (pthread_create(&p->th[i], ap, pool_worker, &p->ww[i]) &&
        (!ap || pthread_create(&p->th[i], NULL, pool_worker, &p->ww[i])))
      break;
    p->n_th++;
  }
  if (ap) pthread_attr_destroy(ap);
  if (p->n_th) return p;
  pthread_cond_destroy(&p->done);
fail_done:
  pthread_cond_destroy(&p->go);
fail_go:
  pthread_mutex_destroy(&p->mu);
fail_mu:
  qk__free(a, p, sizeof *p);
  return NULL;
}

void qk__pool_free(qk__pool_t *p) {
  if (!p) return;
  qk_allocator_t a = p->alloc;
  if (!pool_forked(p)) {
    pool_wait(p);                /* (a detached job) */
    pool_post(p, NULL, NULL, 0); /* (a region of no shares: the workers end) */
    for (unsigned i = 0; i < p->n_th; i++) pthread_join(p->th[i], NULL);
    pthread_cond_destroy(&p->done);
    pthread_cond_destroy(&p->go);
    pthread_mutex_destroy(&p->mu);
  } /* (else the workers and the locks are the parent's: only the memory is ours) */
  qk__free(&a, p, sizeof *p);
}

unsigned qk__pool_threads(const qk__pool_t *p) { return p ? p->n_th + 1 : 1; }

unsigned qk__pool_owner_parks(const qk__pool_t *p) { return p ? p->owner_parks : 0; }

int qk__pool_start_cpu(const qk__pool_t *p, unsigned i, int *home) {
  *home = -1;
#if QK__POOL_AWAY
  if (!p || !p->away || i >= p->n_th) return -1;
  *home = p->home_cpu;
  return p->start_cpu[i];
#else
  (void)p, (void)i;
  return -1;
#endif
}

int qk__pool_live(const qk__pool_t *p) { return p && !pool_forked(p); }

/* Whether the calling thread may run on the same processors as the thread that started
 * p's workers (which took that thread's set): a kept team's workers must not carry one
 * thread's pinning to another's builds. */
static int same_cpus(const qk__pool_t *p) {
#if QK__POOL_AWAY
  cpu_set_t mine;
  if (!p->owner_ok || pthread_getaffinity_np(pthread_self(), sizeof mine, &mine) != 0) return 0;
  return CPU_EQUAL(&mine, &p->owner_set);
#else
  (void)p;
  return 1;
#endif
}

void qk__pool_hold(qk__pool_t *p, int on) {
  if (p) atomic_store_explicit(&p->hold, on, memory_order_relaxed);
}

int qk__pool_run(qk__pool_t *p, unsigned nw, qk__share_fn fn, void *ctx) {
  int idle = 0;
  if (!p || nw == 0 || nw > p->n_th + 1 || pool_forked(p) ||
      !atomic_compare_exchange_strong_explicit(&p->busy, &idle, 1, memory_order_acquire,
                                               memory_order_relaxed))
    return 0;
  pool_wait(p); /* (a detached job: the workers are ours once it ends) */
  uint64_t g = pool_post(p, fn, ctx, nw);
  fn(ctx, 0, nw);
  /* The shares no worker has taken yet, here: a worker that is slow to start (on the two
   * vCPUs of this work, a new one ran its first region 3-5 ms after it was posted inside the
   * benchmark's process) does not hold the region up. Whoever runs a share, it is the same
   * share: the shares of a region must be correct run one after another on one thread
   * anyway (qk__run_shares does so when it cannot start a thread). */
  if (!qk__pool_steal_off)
    for (unsigned s = 1; s < nw; s++)
      if (take(p, s, g)) fn(ctx, s, nw);
  pool_wait(p);
  atomic_store_explicit(&p->busy, 0, memory_order_release);
  return 1;
}

static void detach_share(void *ctx, unsigned s, unsigned nw) {
  const qk__pool_t *p = ctx;
  (void)nw;
  if (s == 1) p->dfn(p->dctx);
}

int qk__pool_detach(qk__pool_t *p, void (*fn)(void *), void *ctx) {
  int idle = 0;
  if (!p || pool_forked(p) ||
      !atomic_compare_exchange_strong_explicit(&p->busy, &idle, 1, memory_order_acquire,
                                               memory_order_relaxed))
    return 0;
  pool_wait(p); /* (the one before) */
  p->dfn = fn, p->dctx = ctx;
  pool_post(p, detach_share, p, 2);
  atomic_store_explicit(&p->busy, 0, memory_order_release);
  return 1;
}
#else
static int same_cpus(const qk__pool_t *p) {
  (void)p;
  return 1;
}
qk__pool_t *qk__pool_new(const qk_allocator_t *a, unsigned nw) {
  (void)a, (void)nw;
  return NULL;
}
void qk__pool_free(qk__pool_t *p) { (void)p; }
unsigned qk__pool_threads(const qk__pool_t *p) {
  (void)p;
  return 1;
}
unsigned qk__pool_owner_parks(const qk__pool_t *p) {
  (void)p;
  return 0;
}
unsigned long qk__pool_wait_spin_ns(const qk__pool_t *p) {
  (void)p;
  return 0;
}
int qk__pool_start_cpu(const qk__pool_t *p, unsigned i, int *home) {
  (void)p, (void)i;
  *home = -1;
  return -1;
}
int qk__pool_live(const qk__pool_t *p) {
  (void)p;
  return 0;
}
void qk__pool_hold(qk__pool_t *p, int on) { (void)p, (void)on; }
int qk__pool_run(qk__pool_t *p, unsigned nw, qk__share_fn fn, void *ctx) {
  (void)p, (void)nw, (void)fn, (void)ctx;
  return 0;
}
int qk__pool_detach(qk__pool_t *p, void (*fn)(void *), void *ctx) {
  (void)p, (void)fn, (void)ctx;
  return 0;
}
#endif

/* The calling thread's team, if it holds one: a pool held for its length. */
static _Thread_local qk__pool_t *cur_team;
static _Thread_local unsigned team_depth; /* nested qk__team_begin calls */

/* The last team to end, its workers parked for the next team of the same size, on any
 * thread (one for the whole process: at most one team's workers wait unused). Starting a
 * worker and joining it were a twentieth of a two-thread build of 1M points (76 us before
 * its first region and 66 after its last, of 2.9 ms); waking a parked one takes 12 us. The
 * pool is ended when a team of another size takes it, by qk__team_release(), and when the
 * library is unloaded or the process exits (below). */
static _Atomic(qk__pool_t *) kept_team;

/* The kept pool when it has nw threads, this process started them (a forked child frees
 * the parent's memory only) and the calling thread may run where they may; NULL
 * otherwise, the kept one ended. */
static qk__pool_t *team_take(unsigned nw) {
  qk__pool_t *p = atomic_exchange(&kept_team, NULL);
  if (!p || (qk__pool_live(p) && qk__pool_threads(p) == nw && same_cpus(p))) return p;
  qk__pool_free(p);
  return NULL;
}

/* Keep p for the next team unless another is kept already. */
static void team_keep(qk__pool_t *p) {
  qk__pool_t *none = NULL;
  qk__pool_hold(p, 0); /* (its workers park now rather than spin) */
  if (!atomic_compare_exchange_strong(&kept_team, &none, p)) qk__pool_free(p);
}

void qk__team_release(void) { qk__pool_free(atomic_exchange(&kept_team, NULL)); }

#if defined(__GNUC__)
/* At dlclose() or exit: parked workers would otherwise outlive the code they run. */
__attribute__((destructor)) static void team_unload(void) { qk__team_release(); }
#endif

void qk__team_begin(unsigned nw) {
  if (cur_team) {
    team_depth++;
    return;
  }
  if (nw <= 1) return;
  cur_team = team_take(nw);
  if (!cur_team) cur_team = qk__pool_new(NULL, nw);
  if (!cur_team) return;
  team_depth = 1;
  qk__pool_hold(cur_team, 1);
}

void qk__team_end(void) {
  if (!cur_team || --team_depth > 0) return;
  team_keep(cur_team);
  cur_team = NULL;
}

void qk__run_shares(unsigned nw, qk__share_fn fn, void *ctx) {
  if (nw <= 1) {
    fn(ctx, 0, 1);
    return;
  }
  if (nw > QK__MAX_THREADS) nw = QK__MAX_THREADS;
  /* On the calling thread's team: share 0 here, the others on its workers (a worker whose
   * share number is nw or more only reports back). */
  if (qk__pool_run(cur_team, nw, fn, ctx)) return;
#if defined(QK_HAVE_PTHREADS)
  pthread_t th[QK__MAX_THREADS];
  share_t sh[QK__MAX_THREADS];
  bool started[QK__MAX_THREADS] = {false};
  pthread_attr_t attr, *ap = NULL;
#if QK__POOL_AWAY
  /* Each thread started away from this one's processor, as a pool's workers: started as
   * usual, this guest ran a region's new thread on the processor of the thread that
   * started it (which then runs share 0) until the end of its share, often the whole
   * region: 100,000 kNN queries on two threads took 31 ms, one thread 28 ms. */
  cpu_set_t home;
  int me;
  if (!qk__shares_away_off && start_away(&attr, &home, &me)) ap = &attr;
#else
  (void)attr;
#endif
  for (unsigned w = 1; w < nw; w++) {
    sh[w] = (share_t){.fn = fn, .ctx = ctx, .w = w, .nw = nw};
#if QK__POOL_AWAY
    sh[w].home = ap ? &home : NULL;
    sh[w].home_cpu = ap ? me : -1;
#endif
    started[w] = pthread_create(&th[w], ap, run_share, &sh[w]) == 0;
    if (!started[w] && ap) {
      /* (where the system refuses the placement, the thread is started as usual) */
#if QK__POOL_AWAY
      sh[w].home = NULL;
#endif
      started[w] = pthread_create(&th[w], NULL, run_share, &sh[w]) == 0;
    }
  }
  if (ap) pthread_attr_destroy(ap);
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

int qk__share_start_cpu(int *home) {
#if QK__POOL_AWAY
  *home = share_home_cpu;
  return share_start_cpu;
#else
  *home = -1;
  return -1;
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

/* The shares of n jobs on `threads` threads: at most one a job, at most QK__MAX_THREADS. */
static unsigned jobs_shares(unsigned threads, unsigned n) {
  unsigned nw = threads < n ? threads : n;
  return nw < QK__MAX_THREADS ? nw : QK__MAX_THREADS;
}

/* A region on p's workers when it takes it, on threads started for it otherwise. */
static void run_region(qk__pool_t *p, unsigned nw, qk__share_fn fn, void *ctx) {
  if (nw <= 1)
    fn(ctx, 0, 1);
  else if (!qk__pool_run(p, nw, fn, ctx))
    qk__run_shares(nw, fn, ctx);
}

void qk__pool_run_jobs(qk__pool_t *p, unsigned threads, unsigned n,
                       void (*fn)(unsigned i, void *ud), void *ud) {
  jobs_t j = {n, fn, ud};
  run_region(p, jobs_shares(threads, n), jobs_share, &j);
}

void qk__run_jobs(unsigned threads, unsigned n, void (*fn)(unsigned i, void *ud), void *ud) {
  qk__pool_run_jobs(NULL, threads, n, fn, ud);
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

void qk__pool_run_jobs_dynamic(qk__pool_t *p, unsigned threads, unsigned n,
                               void (*fn)(unsigned i, unsigned w, void *ud), void *ud) {
  djobs_t j;
  atomic_init(&j.next, 0u);
  j.n = n;
  j.fn = fn;
  j.ud = ud;
  run_region(p, jobs_shares(threads, n), djobs_share, &j);
}

void qk__run_jobs_dynamic(unsigned threads, unsigned n,
                          void (*fn)(unsigned i, unsigned w, void *ud), void *ud) {
  qk__pool_run_jobs_dynamic(NULL, threads, n, fn, ud);
}
