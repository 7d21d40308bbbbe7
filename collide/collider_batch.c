/*
 * The static collider on several threads: all pairs and batches of rays. Work is cut into
 * more jobs than threads, in a fixed order (leaves in the order the one-thread search
 * visits them, rays by index); every job writes only its own outputs, and the pairs are
 * reported in job order, so neither the answers nor their order depend on the number of
 * threads or on which thread ran which job.
 */
#include <stdatomic.h>
#include <string.h>

#include "collide/collide_internal.h"

/* ---- all pairs ------------------------------------------------------------------ */

/*
 * The tree is cut into subtrees of at most a share of the items each, listed in the order
 * the one-thread search visits them (a depth-first descent that stops at such subtrees:
 * a few hundred nodes, not every leaf). Each subtree is a job, taken from a shared
 * counter (so the threads end together however unequal the jobs), whose leaves are
 * searched in that same order, keeping their pairs in a buffer of the job's own. The
 * calling thread, between its own jobs, reports every job finished so far in job order,
 * and the rest after the join: the pairs come in the one-thread order while most of the
 * reporting overlaps the other threads' searches, instead of all of it following them. A
 * job that could not keep its pairs (no memory) is searched again by the reporter,
 * straight into the callback, when its turn comes: the same pairs in the same place.
 */

/* Jobs per thread (about): a job's share of the pairs is what may be left to report after
 * the join, and what one thread may still search after the others ran out of jobs. */
#define PAIRS_JOBS_PER_THREAD 32

/* One job's pairs, in the order its leaves produced them. */
typedef struct pjob {
  qk_pair_t *buf;
  size_t n, cap;
  int nomem;
  const qk_allocator_t *alloc;
} pjob_t;

typedef struct pctx {
  const qk_collider_t *c;
  const qk_tree_t *t;
  const uint32_t *roots; /* per job: the root of its subtree */
  unsigned n_jobs;
  pjob_t *jobs;       /* written by a job's thread, read by the reporter once done */
  atomic_uchar *done; /* per job: set (release) when its pjob_t is final */
  atomic_int stop;    /* the callback asked to stop: jobs not begun are skipped */
  qk_pair_fn fn;      /* the reporter's (calling thread's) part from here on */
  void *ud;
  unsigned next; /* the next job to report */
} pctx_t;

static int keep_pair(qk_id_t a, qk_id_t b, void *ud) {
  pjob_t *j = ud;
  if (j->n == j->cap) {
    size_t cap = j->cap ? 2 * j->cap : 256;
    qk_pair_t *p = qk__realloc(j->alloc, j->buf, j->cap * sizeof *p, cap * sizeof *p);
    if (!p) {
      j->nomem = 1;
      return 1;
    }
    j->buf = p;
    j->cap = cap;
  }
  j->buf[j->n].a = a;
  j->buf[j->n++].b = b;
  return 0;
}

/* The pairs of the non-empty leaves below `root`, in the one-thread order (as
 * qk__collider_each_leaf visits them); nonzero when fn asked to stop. */
static int subtree_pairs(const pctx_t *p, uint32_t root, qk_pair_fn fn, void *ud) {
  uint32_t stack[QK__CSTACK_MAX];
  qk__pairs_cache_t pc;
  pc.parent = pc.n = QK_NONE;
  int sp = 0;
  stack[sp++] = root;
  while (sp > 0) {
    const uint32_t v = stack[--sp];
    const uint32_t child = qk__node_child(p->t, v);
    if (child != QK_NONE) {
      for (int k = 3; k >= 0; k--) stack[sp++] = child + (uint32_t)k;
      continue;
    }
    if (qk__node_count(p->t, v) > 0 && qk__collider_leaf_pairs(p->c, v, &pc, fn, ud)) return 1;
  }
  return 0;
}

/* Report job i's pairs (calling thread only), then release its buffer. */
static void report_job(pctx_t *p, unsigned i) {
  pjob_t *j = &p->jobs[i];
  int stop = 0;
  if (j->nomem)
    stop = subtree_pairs(p, p->roots[i], p->fn, p->ud);
  else
    for (size_t k = 0; k < j->n && !stop; k++) stop = p->fn(j->buf[k].a, j->buf[k].b, p->ud);
  qk__free(j->alloc, j->buf, j->cap * sizeof *j->buf);
  j->buf = NULL, j->n = j->cap = 0;
  if (stop) atomic_store_explicit(&p->stop, 1, memory_order_relaxed);
}

/* Report the finished jobs from p->next on, in order, up to the first unfinished one. */
static void report_done(pctx_t *p) {
  while (p->next < p->n_jobs && !atomic_load_explicit(&p->stop, memory_order_relaxed) &&
         atomic_load_explicit(&p->done[p->next], memory_order_acquire))
    report_job(p, p->next++);
}

static void pairs_job(unsigned i, unsigned w, void *ud) {
  pctx_t *p = ud;
  if (!atomic_load_explicit(&p->stop, memory_order_relaxed)) {
    /* The job's state on this thread's stack while it grows: the jobs' records lie side by
     * side, and every pair kept updates n (false sharing with the neighbouring job). */
    pjob_t j = p->jobs[i];
    subtree_pairs(p, p->roots[i], keep_pair, &j);
    p->jobs[i] = j;
  }
  atomic_store_explicit(&p->done[i], 1, memory_order_release);
  /* Share 0 runs on the calling thread, which alone may call the callback. */
  if (w == 0) report_done(p);
}

typedef struct lctx {
  const qk_tree_t *t;
  const qk_allocator_t *alloc;
  uint32_t limit; /* a subtree of at most this many items is one job */
  uint32_t *out;
  size_t n, cap;
  int nomem;
} lctx_t;

/* The job roots below v in depth-first order: v itself when small enough or a leaf,
 * else its children's. Empty subtrees have no pairs and make no job. Recursion depth is
 * bounded by the tree's depth cap. */
static void list_roots(lctx_t *l, uint32_t v) {
  const uint32_t count = qk__node_count(l->t, v), child = qk__node_child(l->t, v);
  if (count == 0 || l->nomem) return;
  if (child == QK_NONE || count <= l->limit) {
    if (l->n == l->cap && qk__grow(l->alloc, (void **)&l->out, &l->cap, l->n + 1, sizeof *l->out))
      l->nomem = 1;
    else
      l->out[l->n++] = v;
    return;
  }
  for (uint32_t k = 0; k < 4; k++) list_roots(l, child + k);
}

qk_status_t qk__collider_pairs_threaded(const qk_collider_t *c, qk_pair_fn fn, void *ud) {
  const qk_allocator_t *a = qk__collider_alloc(c);
  const qk_tree_t *t = qk_collider_tree(c);
  unsigned threads = qk__threads_resolve(qk__collider_threads(c));
  const size_t items = qk__node_count(t, 0);
  if (threads <= 1 || items < 2) return QK_ERR_NOMEM; /* nothing to share: the serial path */
  const size_t limit = items / ((size_t)PAIRS_JOBS_PER_THREAD * threads);
  lctx_t l = {t, a, limit > 0 ? (uint32_t)limit : 1u, NULL, 0, 0, 0};
  list_roots(&l, 0);
  const unsigned n_jobs = (unsigned)l.n;
  pjob_t *jobs = NULL;
  atomic_uchar *done = NULL;
  qk_status_t st = QK_ERR_NOMEM; /* nothing reported yet: the caller searches serially */
  if (!l.nomem && n_jobs >= 2) {
    jobs = qk__realloc(a, NULL, 0, n_jobs * sizeof *jobs);
    done = qk__realloc(a, NULL, 0, n_jobs * sizeof *done);
  }
  if (jobs && done) {
    pctx_t p = {.c = c,
                .t = t,
                .roots = l.out,
                .n_jobs = n_jobs,
                .jobs = jobs,
                .done = done,
                .fn = fn,
                .ud = ud,
                .next = 0};
    atomic_init(&p.stop, 0);
    for (unsigned i = 0; i < n_jobs; i++) {
      jobs[i] = (pjob_t){NULL, 0, 0, 0, a};
      atomic_init(&done[i], 0);
    }
    qk__run_jobs_dynamic(threads, n_jobs, pairs_job, &p);
    report_done(&p); /* every job is done now: the rest, unless stopped */
    for (unsigned i = p.next; i < n_jobs; i++)
      qk__free(a, jobs[i].buf, jobs[i].cap * sizeof *jobs[i].buf);
    st = QK_OK;
  }
  qk__free(a, l.out, l.cap * sizeof *l.out);
  qk__free(a, jobs, jobs ? n_jobs * sizeof *jobs : 0);
  qk__free(a, done, done ? n_jobs * sizeof *done : 0);
  return st;
}

/* ---- rays ----------------------------------------------------------------------- */

/* Rays per job: enough to amortise a hand-out, few enough to balance the threads. */
#define RAYS_PER_JOB 256
/* In Z order, a ray's origin, direction and hit lie anywhere in their arrays: those of the
 * ray this many places on are asked for ahead. */
#define RAYS_AHEAD 8
/* Batches from this size on are cast in the Z order of their origins. */
#define RAYS_SORT_MIN 1024

typedef struct rctx {
  const qk_collider_t *c;
  const qk_point_t *origins, *dirs;
  size_t n;
  double tmax;
  qk_hit_t *hits;
  const uint64_t *order; /* low 32 bits: the k-th ray to cast, or NULL: in input order */
  size_t *first_bad;     /* per job: its lowest-numbered ray that failed, or n */
  qk_status_t *bad_st;
} rctx_t;

static void rays_job(unsigned i, unsigned w, void *ud) {
  (void)w;
  rctx_t *r = ud;
  size_t lo = (size_t)i * RAYS_PER_JOB, hi = lo + RAYS_PER_JOB < r->n ? lo + RAYS_PER_JOB : r->n;
  for (size_t k = lo; k < hi; k++) {
    if (r->order && k + RAYS_AHEAD < hi) {
      const size_t a = (size_t)(uint32_t)r->order[k + RAYS_AHEAD];
      __builtin_prefetch(&r->origins[a]);
      __builtin_prefetch(&r->dirs[a]);
      __builtin_prefetch(&r->hits[a], 1);
    }
    const size_t j = r->order ? (size_t)(uint32_t)r->order[k] : k;
    qk_status_t st = qk_collider_raycast(r->c, r->origins[j], r->dirs[j], r->tmax, &r->hits[j]);
    if (st != QK_OK && j < r->first_bad[i]) {
      r->first_bad[i] = j;
      r->bad_st[i] = st;
    }
  }
}

/* Batches from this size on are sorted on the collider's threads. */
#define RAYS_SORT_PAR_MIN 65536

/*
 * The sort's parallel plan: the keys are cut into one contiguous range per share; in each
 * pass every share counts its range's digits, the offsets follow from the counts in
 * (digit, share) order, and every share moves its range to them. That is the serial
 * LSD pass exactly (stable, the same order), with its three loops shared.
 */
typedef struct sort_ctx {
  const qk_point_t *origins;
  uint64_t *key, *tmp;
  size_t n;
  unsigned nw, shift;
  double sx, sy, scale;
  size_t count[QK__MAX_THREADS][256];
} sort_ctx_t;

static void share_range(const sort_ctx_t *s, unsigned w, size_t *lo, size_t *hi) {
  *lo = s->n * w / s->nw;
  *hi = s->n * (w + 1) / s->nw;
}

/* Keys of rays [lo, hi): the origin's 16-bit Morton code over the root square (origins
 * outside it, or not finite, at its nearest side), then the ray's index. */
static void keys_job(unsigned w, void *ud) {
  sort_ctx_t *s = ud;
  size_t lo, hi;
  share_range(s, w, &lo, &hi);
  for (size_t i = lo; i < hi; i++) {
    double u = (s->origins[i].x - s->sx) * s->scale, v = (s->origins[i].y - s->sy) * s->scale;
    uint32_t ux = !(u > 0) ? 0 : u >= 65535 ? 65535 : (uint32_t)u;
    uint32_t uy = !(v > 0) ? 0 : v >= 65535 ? 65535 : (uint32_t)v;
    s->key[i] = (uint64_t)(qk__spread16(ux) | qk__spread16(uy) << 1) << 32 | i;
  }
}

static void count_job(unsigned w, void *ud) {
  sort_ctx_t *s = ud;
  size_t lo, hi, *count = s->count[w];
  share_range(s, w, &lo, &hi);
  memset(count, 0, 256 * sizeof *count);
  for (size_t i = lo; i < hi; i++) count[s->key[i] >> s->shift & 0xFF]++;
}

static void move_job(unsigned w, void *ud) {
  sort_ctx_t *s = ud;
  size_t lo, hi, *at = s->count[w]; /* by now: where this share's digits go */
  share_range(s, w, &lo, &hi);
  for (size_t i = lo; i < hi; i++) s->tmp[at[s->key[i] >> s->shift & 0xFF]++] = s->key[i];
}

/*
 * The rays in the Z (Morton) order of their origins over the tree's root square, so that
 * consecutive rays, which start near one another, find the nodes and items of their
 * neighbourhood still in cache: with random origins over a large set each ray otherwise
 * brings its own path from memory. An LSD radix sort of (key << 32 | index) in four byte
 * passes, stable, so the order is a function of the input alone, on the collider's
 * threads for large batches (the same order: see sort_ctx_t). NULL when the memory cannot
 * be had (the rays are then cast in input order: the same answers).
 */
static uint64_t *ray_order(const qk_collider_t *c, const qk_point_t *origins, size_t n,
                           unsigned threads, size_t *bytes) {
  const qk_allocator_t *a = qk__collider_alloc(c);
  *bytes = 2 * n * sizeof(uint64_t);
  uint64_t *buf = qk__realloc(a, NULL, 0, *bytes);
  sort_ctx_t *s = qk__realloc(a, NULL, 0, sizeof *s);
  if (!buf || !s) {
    qk__free(a, buf, *bytes);
    qk__free(a, s, sizeof *s);
    return NULL;
  }
  /* 16 MB at 10^6 rays, made anew by every batch: see alloc_arrays in collider.c. */
  qk__advise_huge(a, buf, *bytes);
  const qk_square_t sq = qk__tree_root_square(qk_collider_tree(c));
  s->origins = origins;
  s->key = buf, s->tmp = buf + n;
  s->n = n;
  s->nw = n < RAYS_SORT_PAR_MIN ? 1 : threads < QK__MAX_THREADS ? threads : QK__MAX_THREADS;
  s->sx = sq.x, s->sy = sq.y;
  s->scale = sq.side > 0 ? 65536.0 / sq.side : 0.0;
  qk__run_jobs(s->nw, s->nw, keys_job, s);
  for (s->shift = 32; s->shift < 64; s->shift += 8) {
    qk__run_jobs(s->nw, s->nw, count_job, s);
    size_t sum = 0;
    for (unsigned b = 0; b < 256; b++)
      for (unsigned w = 0; w < s->nw; w++) {
        const size_t k = s->count[w][b];
        s->count[w][b] = sum;
        sum += k;
      }
    qk__run_jobs(s->nw, s->nw, move_job, s);
    uint64_t *t = s->key;
    s->key = s->tmp;
    s->tmp = t;
  }
  qk__free(a, s, sizeof *s);
  return buf; /* four passes: the sorted keys are back in the first half */
}

qk_status_t qk_collider_raycast_batch(const qk_collider_t *c, const qk_point_t *origins,
                                      const qk_point_t *dirs, size_t n, double tmax,
                                      qk_hit_t *hits) {
  if (!c || (n > 0 && (!origins || !dirs || !hits))) return QK_ERR_INVALID;
  if (n == 0) return QK_OK;
  /* The ray structures first (made on first need), so that no ray fails for want of them. */
  qk_status_t pst = qk__collider_rays_ready(c);
  if (pst != QK_OK) return pst;
  size_t n_jobs = (n + RAYS_PER_JOB - 1) / RAYS_PER_JOB;
  if (n_jobs > UINT32_MAX) return QK_ERR_LIMIT;
  unsigned threads = qk__threads_resolve(qk__collider_threads(c));
  /* The per-job error records live on the stack when few, else are borrowed. */
  size_t bad_local[16];
  qk_status_t st_local[16];
  size_t *first_bad = bad_local;
  qk_status_t *bad_st = st_local;
  const qk_allocator_t *a = qk__collider_alloc(c);
  if (n_jobs > 16) {
    first_bad = qk__realloc(a, NULL, 0, n_jobs * sizeof *first_bad);
    bad_st = qk__realloc(a, NULL, 0, n_jobs * sizeof *bad_st);
    if (!first_bad || !bad_st) {
      qk__free(a, first_bad, n_jobs * sizeof *first_bad);
      qk__free(a, bad_st, n_jobs * sizeof *bad_st);
      return QK_ERR_NOMEM;
    }
  }
  size_t order_bytes = 0;
  uint64_t *order = NULL;
  /* The sort's nine regions and the rays' on one team of workers, started once (as a
   * tree's batches: QK__BATCH_TEAM in query/batch.c). */
  qk__team_begin(threads < n_jobs ? threads : (unsigned)n_jobs);
  if (n >= RAYS_SORT_MIN && n <= UINT32_MAX)
    order = ray_order(c, origins, n, threads, &order_bytes);
  for (size_t i = 0; i < n_jobs; i++) first_bad[i] = n;
  rctx_t r = {c, origins, dirs, n, tmax, hits, order, first_bad, bad_st};
  /* The jobs from a shared counter, not job i on thread i mod threads: a thread slowed
   * by another process on its processor, or started late, then casts fewer of them. */
  qk__run_jobs_dynamic(threads, (unsigned)n_jobs, rays_job, &r);
  qk__team_end();
  /* The error of the lowest-numbered failed ray. */
  qk_status_t st = QK_OK;
  size_t bad = n;
  for (size_t i = 0; i < n_jobs; i++)
    if (first_bad[i] < bad) bad = first_bad[i], st = bad_st[i];
  if (order) qk__free(a, order, order_bytes);
  if (n_jobs > 16) {
    qk__free(a, first_bad, n_jobs * sizeof *first_bad);
    qk__free(a, bad_st, n_jobs * sizeof *bad_st);
  }
  return st;
}
