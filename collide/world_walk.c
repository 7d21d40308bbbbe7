/*
 * The pairs of the last update walked on the world's threads (qk_world_pairs_parallel)
 * and read from any index on (qk_world_pairs_range). Both read the lists the update left
 * (collide/world_pairs.c): the current pairs by rows, the began and ended keys, and the
 * generations of the slots that changed. They change nothing, so any number of them may
 * run at once while the world is not changed.
 *
 * Pair k of the current pairs is in the row whose start is the largest at or below k:
 * one bisection over the rows' starts finds where a range begins, and from there the
 * rows are walked as qk_world_pairs() walks them. The began and ended lists are flat.
 */
#include "collide/world_internal.h"

/* How many pairs `which` names, or SIZE_MAX when it names none of the lists. */
static size_t pairs_count(const qk_world_t *w, qk_pairs_which_t which) {
  switch (which) {
  case QK_PAIRS_ALL:
    return w->cur.n;
  case QK_PAIRS_BEGAN:
    return w->began.n;
  case QK_PAIRS_ENDED:
    return w->ended.n;
  }
  return SIZE_MAX;
}

/* The row of the current pairs that holds pair i < cur.n: the largest k < n_nz with
 * start[k] <= i (rows are never empty, so their starts strictly increase). */
static size_t row_of(const qk__prows_t *r, size_t i) {
  size_t lo = 0, hi = r->n_nz; /* start[lo] <= i < start[hi] */
  while (hi - lo > 1) {
    size_t mid = lo + (hi - lo) / 2;
    if (r->start[mid] <= i)
      lo = mid;
    else
      hi = mid;
  }
  return lo;
}

qk_status_t qk_world_pairs_range(const qk_world_t *w, qk_pairs_which_t which, size_t first,
                                 qk_world_pair_t *out, size_t cap, size_t *n_out) {
  if (!w || !n_out || (cap && !out)) return QK_ERR_INVALID;
  size_t n = pairs_count(w, which);
  if (n == SIZE_MAX) return QK_ERR_INVALID;
  *n_out = n;
  if (first >= n || cap == 0) return QK_OK;
  size_t end = n - first < cap ? n : first + cap;
  if (which == QK_PAIRS_ENDED) {
    for (size_t i = first; i < end; i++) out[i - first] = qk__ended_pair(w, w->ended.v[i]);
  } else if (which == QK_PAIRS_BEGAN) {
    for (size_t i = first; i < end; i++) out[i - first] = qk__key_pair(w, w->began.v[i]);
  } else {
    const qk__prows_t *r = &w->cur;
    for (size_t k = row_of(r, first), i = first; i < end; k++) {
      qk_handle_t ha = qk__uhandle(w, r->row[k]);
      for (size_t e = r->start[k + 1] < end ? r->start[k + 1] : end; i < e; i++)
        out[i - first] = (qk_world_pair_t){ha, qk__uhandle(w, r->b[i])};
    }
  }
  return QK_OK;
}

/* One walk on the world's threads: worker t takes range t of nw of the n pairs. stop is
 * set by the first worker whose callback asks to stop; the others read it before each
 * block of WALK_BLOCK pairs (a relaxed load of a line nobody writes until then, which
 * stays in every core's cache). By callgrind on the benchmark's clustered scene at
 * 3 10^4 (1.46 M pairs), instructions a pair in the library, the callback's not counted:
 * qk_world_pairs() 11.4; one worker (no flag) 11.8; several, the flag read before each
 * pair 15.6 (the flag and the worker are two more values live across the call, and
 * spill), before each block 14.1. */
#define WALK_BLOCK 64
typedef struct walk {
  const qk_world_t *w;
  qk_pairs_which_t which;
  qk_world_pair_worker_fn fn;
  void *ud;
  size_t n;
  unsigned nw;
  atomic_int stop;
} walk_t;

/* In the loops below fn, ud and stop are locals: fn may write any memory the compiler
 * knows of (the walk's own struct among it), so fields read through J would be read again
 * after every call. With one worker (shared 0) nobody else can ask to stop: no check, and
 * no blocks. */
#define WALK_STOPPED() (shared && atomic_load_explicit(stop, memory_order_relaxed))
#define WALK_CALL(a, b, t)                                                                         \
  do {                                                                                             \
    if (fn((a), (b), (t), ud)) {                                                                   \
      atomic_store_explicit(stop, 1, memory_order_relaxed);                                        \
      return;                                                                                      \
    }                                                                                              \
  } while (0)
/* The end of the block that starts at i, of a run that ends at e. */
#define WALK_BLOCK_END(i, e) (shared && (e) - (i) > WALK_BLOCK ? (i) + WALK_BLOCK : (e))

/* The current pairs [lo, hi) of the only worker: the loops of qk_world_pairs(), with the
 * arrays in locals too. */
static __attribute__((noinline)) void walk_rows1(walk_t *J, size_t lo, size_t hi) {
  const qk_world_t *w = J->w;
  const uint32_t *row = w->cur.row, *start = w->cur.start, *rb = w->cur.b, *ug = w->ugen;
  const qk_world_pair_worker_fn fn = J->fn;
  void *const ud = J->ud;
  atomic_int *const stop = &J->stop;
  const uint64_t *ck = qk__world_kept_keys(w);
  if (ck) {
    /* The pairs also as keys in order (kept for the next update's merge: short rows):
     * each pair from its key, with no row to follow. */
    size_t i = lo;
    if (qk__world_far(w)) /* (as qk_world_pairs(): slot b's generation asked for ahead) */
      for (; i + QK__WALK_AHEAD < hi; i++) {
        __builtin_prefetch(&ug[(uint32_t)ck[i + QK__WALK_AHEAD]]);
        const uint64_t key = ck[i];
        const uint32_t a = (uint32_t)(key >> 32), b = (uint32_t)key;
        WALK_CALL((uint64_t)ug[a] << 32 | a, (uint64_t)ug[b] << 32 | b, 0);
      }
    for (; i < hi; i++) {
      const uint64_t key = ck[i];
      const uint32_t a = (uint32_t)(key >> 32), b = (uint32_t)key;
      WALK_CALL((uint64_t)ug[a] << 32 | a, (uint64_t)ug[b] << 32 | b, 0);
    }
    return;
  }
  size_t k = row_of(&w->cur, lo);
  if (w->cur.n < 4 * w->cur.n_nz) {
    /* Short rows (a sparse world): one loop over the pairs, moving to the next row at
     * its start, as qk_world_pairs() does (a loop a row would end at a pair or two). */
    for (size_t i = lo; i < hi; i++) {
      k += i == start[k + 1];
      const uint32_t a = row[k], b = rb[i];
      WALK_CALL((uint64_t)ug[a] << 32 | a, (uint64_t)ug[b] << 32 | b, 0);
    }
    return;
  }
  for (size_t i = lo; i < hi; k++) {
    const uint32_t a = row[k];
    const qk_handle_t ha = (uint64_t)ug[a] << 32 | a;
    QK__UNROLL4
    for (size_t e = start[k + 1] < hi ? start[k + 1] : hi; i < e; i++) {
      const uint32_t b = rb[i];
      WALK_CALL(ha, (uint64_t)ug[b] << 32 | b, 0);
    }
  }
}

/* The same for worker t of several, in blocks of WALK_BLOCK pairs, each after a look at
 * the stop flag. (Two functions, not one inlined twice: gcc 12 then kept fewer of the
 * one-worker loop's values in registers, 13.4 instructions a pair against 11.8.) */
static __attribute__((noinline)) void walk_rows(walk_t *J, unsigned t, size_t lo, size_t hi) {
  const qk_world_t *w = J->w;
  const uint32_t *row = w->cur.row, *start = w->cur.start, *rb = w->cur.b, *ug = w->ugen;
  const qk_world_pair_worker_fn fn = J->fn;
  void *const ud = J->ud;
  atomic_int *const stop = &J->stop;
  const int shared = 1;
  const uint64_t *ck = qk__world_kept_keys(w);
  if (ck) {
    /* The pairs as keys in order (walk_rows1): each pair from its key, no row to follow.
     * (Through the rows instead, two workers took 3.7-4.4 ns a pair each on the uniform
     * scene at 10^5, 1.5 pairs an object, against 2.5 for one worker from the keys: the
     * walk on two threads 281-286 us a frame, 223-228 from the keys, 370 on one.) */
    for (size_t i = lo; i < hi;) {
      if (WALK_STOPPED()) return;
      for (const size_t be = WALK_BLOCK_END(i, hi); i < be; i++) {
        const uint64_t key = ck[i];
        const uint32_t a = (uint32_t)(key >> 32), b = (uint32_t)key;
        WALK_CALL((uint64_t)ug[a] << 32 | a, (uint64_t)ug[b] << 32 | b, t);
      }
    }
    return;
  }
  size_t k = row_of(&w->cur, lo);
  if (w->cur.n < 4 * w->cur.n_nz) {
    for (size_t i = lo; i < hi;) {
      if (WALK_STOPPED()) return;
      for (const size_t be = WALK_BLOCK_END(i, hi); i < be; i++) {
        k += i == start[k + 1];
        const uint32_t a = row[k], b = rb[i];
        WALK_CALL((uint64_t)ug[a] << 32 | a, (uint64_t)ug[b] << 32 | b, t);
      }
    }
    return;
  }
  for (size_t i = lo; i < hi; k++) {
    const uint32_t a = row[k];
    const qk_handle_t ha = (uint64_t)ug[a] << 32 | a;
    const size_t e = start[k + 1] < hi ? start[k + 1] : hi;
    while (i < e) {
      if (WALK_STOPPED()) return;
      const size_t be = WALK_BLOCK_END(i, e);
      QK__UNROLL4
      for (; i < be; i++) {
        const uint32_t b = rb[i];
        WALK_CALL(ha, (uint64_t)ug[b] << 32 | b, t);
      }
    }
  }
}

static void walk_run(unsigned t, void *arg) {
  walk_t *J = arg;
  const qk_world_t *w = J->w;
  const qk_world_pair_worker_fn fn = J->fn;
  void *const ud = J->ud;
  atomic_int *const stop = &J->stop;
  const int shared = J->nw > 1; /* (the began and ended lists: one loop for both cases) */
  size_t lo, hi;
  qk__share_range(J->n, t, J->nw, &lo, &hi);
  if (lo >= hi) return;
  if (J->which == QK_PAIRS_ALL) {
    if (J->nw > 1)
      walk_rows(J, t, lo, hi);
    else
      walk_rows1(J, lo, hi);
  } else if (J->which == QK_PAIRS_BEGAN) {
    for (size_t i = lo; i < hi && !WALK_STOPPED();)
      for (const size_t be = WALK_BLOCK_END(i, hi); i < be; i++) {
        qk_world_pair_t q = qk__key_pair(w, w->began.v[i]);
        WALK_CALL(q.a, q.b, t);
      }
  } else {
    for (size_t i = lo; i < hi && !WALK_STOPPED();)
      for (const size_t be = WALK_BLOCK_END(i, hi); i < be; i++) {
        qk_world_pair_t q = qk__ended_pair(w, w->ended.v[i]);
        WALK_CALL(q.a, q.b, t);
      }
  }
}

qk_status_t qk_world_pairs_parallel(const qk_world_t *w, qk_pairs_which_t which,
                                    qk_world_pair_worker_fn fn, void *ud) {
  if (!w || !fn) return QK_ERR_INVALID;
  size_t n = pairs_count(w, which);
  if (n == SIZE_MAX) return QK_ERR_INVALID;
  if (n == 0) return QK_OK;
  /* The threads of an update (one below thread_min live objects: a world that small
   * walks its pairs in less time than waking a worker takes), at most one a pair. */
  unsigned nw = qk__world_update_threads(w);
  if (nw > QK__MAX_THREADS) nw = QK__MAX_THREADS;
  if (nw > n) nw = (unsigned)n;
  walk_t J = {w, which, fn, ud, n, nw, 0};
  /* One job a worker, job t in share t: worker t is the thread that runs share t. */
  qk__world_run_jobs(w, nw, nw, walk_run, &J);
  return QK_OK;
}
