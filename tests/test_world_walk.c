/*
 * Test plan for the world's pairs walked on threads and read by ranges
 * (collide/world_walk.c: qk_world_pairs_parallel, qk_world_pairs_range):
 *  - seeded scenes of boxes on an integer grid (the oracle's closed-box test is exact),
 *    sparse (short rows: a pair or two a slot) and dense (long rows), moving, with objects
 *    added and removed every frame (slots reused: a pair that ended and one that began on
 *    the same slots), replayed on worlds of 1, 2, 3 and 4 threads with thread_min 0.
 *    Every frame: the pairs, began and ended lists from qk_world_pairs_list against a
 *    brute force over a mirror of the boxes and the previous frame's pairs; then the
 *    parallel walk (each worker's pairs kept apart, concatenated in worker order), and
 *    ranges at random cut points (and the whole list in one range, and ranges that run
 *    past the end), equal that list exactly; each worker's share is the documented split
 *    (nearly equal contiguous ranges, one a worker, min(threads, count) workers), runs on
 *    one thread, and worker 0 on the caller;
 *  - the state the calls read is the last update's: after moves, adds and removes with no
 *    update, the walk and the ranges still give the list taken right after the update;
 *  - a callback that asks to stop: each worker's pairs are a prefix of its range, the one
 *    that asked reports no pair after it, and the call returns QK_OK;
 *  - thread_min: below it the walk runs on the calling thread alone;
 *  - threads of the caller's own, each taking slices of the pairs by ranges at once, get
 *    the list;
 *  - bad arguments give QK_ERR_INVALID; an empty world and a count of zero call nothing
 *    and write nothing; a range from the count on writes nothing and gives the count.
 */
#define _POSIX_C_SOURCE 200809L
#include <pthread.h>
#include <stdatomic.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <time.h>

#include "collide/world_internal.h" /* (which walk loop a frame takes: its rows) */
#include "qk_test.h"

#define MAX_WORKERS 8

/* ---- oracle ---------------------------------------------------------------------------- */

/* A mirror of the objects by slot: live, handle, box (integers, so the closed-box test
 * below is exact). */
typedef struct mirror {
  int live[4096];
  qk_handle_t h[4096];
  double x0[4096], y0[4096], x1[4096], y1[4096];
  uint32_t n_slots;
} mirror_t;

/* A list of pairs, sorted by slot of a then slot of b when made by the oracle. */
typedef struct plist {
  qk_world_pair_t *p;
  size_t n, cap;
} plist_t;

static void pl_push(plist_t *l, qk_world_pair_t q) {
  if (l->n == l->cap) {
    l->cap = l->cap ? 2 * l->cap : 256;
    l->p = realloc(l->p, l->cap * sizeof *l->p);
    assert_non_null(l->p);
  }
  l->p[l->n++] = q;
}

static int pair_cmp(const void *x, const void *y) {
  const qk_world_pair_t *p = x, *q = y;
  uint32_t pa = QK_HANDLE_SLOT(p->a), qa = QK_HANDLE_SLOT(q->a);
  uint32_t pb = QK_HANDLE_SLOT(p->b), qb = QK_HANDLE_SLOT(q->b);
  return pa != qa ? (pa > qa) - (pa < qa) : (pb > qb) - (pb < qb);
}

/* Every overlapping pair of live boxes, slot a below slot b, in (slot a, slot b) order. */
static QKT_SERIAL void oracle_pairs(const mirror_t *m, plist_t *out) {
  out->n = 0;
  for (uint32_t i = 0; i < m->n_slots; i++) {
    if (!m->live[i]) continue;
    for (uint32_t j = i + 1; j < m->n_slots; j++)
      if (m->live[j] && m->x0[i] <= m->x1[j] && m->x0[j] <= m->x1[i] && m->y0[i] <= m->y1[j] &&
          m->y0[j] <= m->y1[i])
        pl_push(out, (qk_world_pair_t){m->h[i], m->h[j]});
  }
}

/* The pairs of a (sorted) not in b (sorted), by handles: a pair whose slots were reused
 * has other handles, so it is in one list and not the other. */
static QKT_SERIAL void oracle_minus(const plist_t *a, const plist_t *b, plist_t *out) {
  out->n = 0;
  size_t j = 0;
  for (size_t i = 0; i < a->n; i++) {
    while (j < b->n && pair_cmp(&b->p[j], &a->p[i]) < 0) j++;
    if (j < b->n && b->p[j].a == a->p[i].a && b->p[j].b == a->p[i].b) continue;
    pl_push(out, a->p[i]);
  }
}

static void assert_same(const qk_world_pair_t *got, size_t n_got, const qk_world_pair_t *want,
                        size_t n_want, const char *what, uint64_t seed) {
  if (n_got != n_want)
    fail_msg("%s: %zu pairs, want %zu (seed %llu)", what, n_got, n_want, (unsigned long long)seed);
  for (size_t i = 0; i < n_got; i++)
    if (got[i].a != want[i].a || got[i].b != want[i].b)
      fail_msg("%s: pair %zu is (%llx, %llx), want (%llx, %llx) (seed %llu)", what, i,
               (unsigned long long)got[i].a, (unsigned long long)got[i].b,
               (unsigned long long)want[i].a, (unsigned long long)want[i].b,
               (unsigned long long)seed);
}

/* The list through qk_world_pairs_list. */
static void list_of(const qk_world_t *w, qk_pairs_which_t which, plist_t *out) {
  size_t n = 0;
  assert_int_equal(qk_world_pairs_list(w, which, NULL, 0, &n), QK_OK);
  out->n = 0;
  if (out->cap < n + 1) {
    out->cap = n + 1;
    out->p = realloc(out->p, out->cap * sizeof *out->p);
    assert_non_null(out->p);
  }
  size_t n2 = 0;
  assert_int_equal(qk_world_pairs_list(w, which, out->p, n, &n2), QK_OK);
  assert_int_equal(n2, n);
  out->n = n;
}

/* ---- the parallel walk, recorded ------------------------------------------------------- */

typedef struct rec {
  plist_t per[MAX_WORKERS];
  pthread_t thread[MAX_WORKERS];
  int seen[MAX_WORKERS];
  unsigned max_worker; /* the largest worker seen, +1 */
  int bad_thread;      /* a worker seen on two threads */
  size_t stop_at;      /* stop after this many pairs of worker stop_worker (SIZE_MAX: never) */
  unsigned stop_worker;
} rec_t;

static int rec_fn(qk_handle_t a, qk_handle_t b, unsigned worker, void *ud) {
  rec_t *r = ud;
  if (worker >= MAX_WORKERS) {
    r->bad_thread = 2; /* (checked by the caller: a worker number out of range) */
    return 1;
  }
  if (!r->seen[worker]) {
    r->seen[worker] = 1, r->thread[worker] = pthread_self();
  } else if (!pthread_equal(r->thread[worker], pthread_self())) {
    r->bad_thread = 1;
  }
  pl_push(&r->per[worker], (qk_world_pair_t){a, b});
  return worker == r->stop_worker && r->per[worker].n == r->stop_at;
}

static void rec_reset(rec_t *r) {
  for (int t = 0; t < MAX_WORKERS; t++) r->per[t].n = 0, r->seen[t] = 0;
  r->bad_thread = 0;
  r->stop_at = SIZE_MAX;
  r->stop_worker = 0;
}

static void rec_free(rec_t *r) {
  for (int t = 0; t < MAX_WORKERS; t++) free(r->per[t].p);
}

/* The documented split: nw = min(threads, n) workers, worker t the t-th of nw nearly equal
 * contiguous ranges (the first n mod nw one longer). */
static void split(size_t n, unsigned nw, unsigned t, size_t *lo, size_t *hi) {
  size_t q = n / nw, r = n % nw;
  *lo = q * t + (t < r ? t : r);
  *hi = *lo + q + (t < r);
}

/* The walk of `which` on w (expected workers: min(threads, count)) against the list. */
static void check_walk(const qk_world_t *w, qk_pairs_which_t which, unsigned threads,
                       const plist_t *want, rec_t *r, uint64_t seed) {
  rec_reset(r);
  assert_int_equal(qk_world_pairs_parallel(w, which, rec_fn, r), QK_OK);
  if (r->bad_thread)
    fail_msg("a worker ran on two threads or out of range (seed %llu)", (unsigned long long)seed);
  unsigned nw = want->n < threads ? (unsigned)want->n : threads;
  plist_t all = {0};
  for (unsigned t = 0; t < MAX_WORKERS; t++) {
    size_t lo = 0, hi = 0;
    if (t < nw) split(want->n, nw, t, &lo, &hi);
    if (r->per[t].n != hi - lo)
      fail_msg("which %d, %u threads: worker %u got %zu pairs, its range %zu (seed %llu)",
               (int)which, threads, t, r->per[t].n, hi - lo, (unsigned long long)seed);
    for (size_t i = 0; i < r->per[t].n; i++) pl_push(&all, r->per[t].p[i]);
  }
  if (nw > 0 && !pthread_equal(r->thread[0], pthread_self()))
    fail_msg("worker 0 not on the calling thread (seed %llu)", (unsigned long long)seed);
  assert_same(all.p, all.n, want->p, want->n, "parallel walk", seed);
  free(all.p);
}

/* Ranges at random cut points, then one range of everything and one past the end. */
static void check_ranges(const qk_world_t *w, qk_pairs_which_t which, const plist_t *want,
                         qkt_rng_t *rng, uint64_t seed) {
  size_t n = want->n;
  qk_world_pair_t *buf = malloc((n + 8) * sizeof *buf);
  assert_non_null(buf);
  for (int round = 0; round < 3; round++) {
    size_t first = 0;
    while (first <= n) {
      size_t cap = 1 + qkt_rng_below(rng, (uint32_t)(round == 0 ? 4 : n / 3 + 2));
      size_t n_out = 12345;
      /* A sentinel after what the call may write: it must stay. */
      size_t k = first < n ? (n - first < cap ? n - first : cap) : 0;
      buf[first + k] = (qk_world_pair_t){7, 7};
      assert_int_equal(qk_world_pairs_range(w, which, first, buf + first, cap, &n_out), QK_OK);
      assert_int_equal(n_out, n);
      if (buf[first + k].a != 7 || buf[first + k].b != 7)
        fail_msg("range at %zu cap %zu wrote past its %zu pairs (seed %llu)", first, cap, k,
                 (unsigned long long)seed);
      if (first == n) break;
      first += k;
    }
    assert_same(buf, n, want->p, n, "ranges", seed);
  }
  size_t n_out = 0;
  assert_int_equal(qk_world_pairs_range(w, which, 0, buf, n + 8, &n_out), QK_OK);
  assert_int_equal(n_out, n);
  assert_same(buf, n, want->p, n, "one range", seed);
  buf[0] = (qk_world_pair_t){7, 7};
  assert_int_equal(qk_world_pairs_range(w, which, n + 5, buf, 4, &n_out), QK_OK);
  assert_int_equal(n_out, n);
  assert_true(buf[0].a == 7 && buf[0].b == 7);
  assert_int_equal(qk_world_pairs_range(w, which, SIZE_MAX, buf, 4, &n_out), QK_OK);
  assert_true(buf[0].a == 7 && buf[0].b == 7);
  free(buf);
}

/* ---- scenes ---------------------------------------------------------------------------- */

static qk_shape_t box_of(const mirror_t *m, uint32_t s) {
  return (qk_shape_t){QK_SHAPE_BOX, m->x0[s], m->y0[s], m->x1[s], m->y1[s]};
}

static void rnd_box(qkt_rng_t *r, mirror_t *m, uint32_t s, double side, int dense) {
  double x = qkt_rng_below(r, (uint32_t)side), y = qkt_rng_below(r, (uint32_t)side);
  double wx = 1 + qkt_rng_below(r, dense ? 12 : 3), wy = 1 + qkt_rng_below(r, dense ? 12 : 3);
  m->x0[s] = x, m->y0[s] = y, m->x1[s] = x + wx, m->y1[s] = y + wy;
}

/* One scene replayed on worlds of 1..4 threads (thread_min 0), every frame checked. */
static void run_scene(uint64_t seed, uint32_t n0, double side, int dense, int frames) {
  qkt_rng_t rng;
  qkt_rng_seed(&rng, seed);
  enum { NT = 4 };
  qk_world_t *w[NT];
  for (unsigned t = 0; t < NT; t++) {
    qk_world_options_t o;
    qk_world_options_init(&o);
    o.threads = t + 1;
    o.thread_min = 0;
    assert_int_equal(qk_world_new(&o, &w[t]), QK_OK);
  }
  static mirror_t m;
  memset(&m, 0, sizeof m);
  for (uint32_t i = 0; i < n0; i++) {
    rnd_box(&rng, &m, i, side, dense);
    qk_shape_t s = box_of(&m, i);
    for (unsigned t = 0; t < NT; t++) {
      qk_handle_t h;
      assert_int_equal(qk_world_add(w[t], &s, i, &h), QK_OK);
      assert_int_equal(QK_HANDLE_SLOT(h), i);
      m.h[i] = h;
    }
    m.live[i] = 1;
  }
  m.n_slots = n0;
  plist_t prev = {0}, cur = {0}, want = {0};
  rec_t rec;
  memset(&rec, 0, sizeof rec);
  int saw_reuse = 0, saw_long = 0, saw_short = 0;
  for (int f = 0; f < frames; f++) {
    /* Moves (a few jumps), removes and adds; the worlds get the same calls, so their slots
     * and handles agree. */
    for (uint32_t s = 0; s < m.n_slots; s++) {
      if (!m.live[s]) continue;
      int k = (int)qkt_rng_below(&rng, 20);
      if (k == 0) { /* remove */
        for (unsigned t = 0; t < NT; t++) assert_int_equal(qk_world_remove(w[t], m.h[s]), QK_OK);
        m.live[s] = 0;
        continue;
      }
      double dx = (double)qkt_rng_below(&rng, 3) - 1, dy = (double)qkt_rng_below(&rng, 3) - 1;
      if (k == 1) dx *= side / 4, dy *= side / 4;
      m.x0[s] += dx, m.x1[s] += dx, m.y0[s] += dy, m.y1[s] += dy;
      qk_shape_t sh = box_of(&m, s);
      for (unsigned t = 0; t < NT; t++) assert_int_equal(qk_world_move(w[t], m.h[s], &sh), QK_OK);
    }
    uint32_t adds = n0 / 20 + qkt_rng_below(&rng, 4);
    for (uint32_t i = 0; i < adds; i++) {
      qk_handle_t h = QK_HANDLE_NONE;
      uint32_t s = 0;
      for (unsigned t = 0; t < NT; t++) {
        qk_shape_t sh;
        if (t == 0) { /* the slot the world picks (a free one first), then the box there */
          qk_shape_t probe = {QK_SHAPE_BOX, 0, 0, 1, 1};
          assert_int_equal(qk_world_add(w[0], &probe, 0, &h), QK_OK);
          s = QK_HANDLE_SLOT(h);
          assert_true(s < 4096);
          if (s < m.n_slots) saw_reuse = 1;
          rnd_box(&rng, &m, s, side, dense);
          sh = box_of(&m, s);
          assert_int_equal(qk_world_move(w[0], h, &sh), QK_OK);
        } else {
          sh = box_of(&m, s);
          qk_handle_t h2;
          assert_int_equal(qk_world_add(w[t], &sh, 0, &h2), QK_OK);
          assert_true(h2 == h);
        }
      }
      m.h[s] = h, m.live[s] = 1;
      if (s >= m.n_slots) m.n_slots = s + 1;
    }
    for (unsigned t = 0; t < NT; t++) assert_int_equal(qk_world_update(w[t]), QK_OK);
    /* The oracle's lists. */
    oracle_pairs(&m, &cur);
    /* Which of the walk's two loops ran (long rows: 4 pairs a row and more). */
    saw_long |= w[0]->cur.n >= 4 * w[0]->cur.n_nz, saw_short |= w[0]->cur.n < 4 * w[0]->cur.n_nz;
    plist_t o_began = {0}, o_ended = {0};
    oracle_minus(&cur, &prev, &o_began);
    oracle_minus(&prev, &cur, &o_ended);
    const plist_t *oracle[3] = {&cur, &o_began, &o_ended};
    for (unsigned t = 0; t < NT; t++)
      for (int which = 0; which < 3; which++) {
        list_of(w[t], (qk_pairs_which_t)which, &want);
        assert_same(want.p, want.n, oracle[which]->p, oracle[which]->n, "list vs oracle", seed);
        check_walk(w[t], (qk_pairs_which_t)which, t + 1, &want, &rec, seed);
        check_ranges(w[t], (qk_pairs_which_t)which, &want, &rng, seed);
      }
    free(o_began.p), free(o_ended.p);
    plist_t tmp = prev;
    prev = cur, cur = tmp;
  }
  assert_true(saw_reuse);
  assert_true(dense ? saw_long : saw_short);
  for (unsigned t = 0; t < NT; t++) qk_world_free(w[t]);
  free(prev.p), free(cur.p), free(want.p);
  rec_free(&rec);
}

static void test_world_walk_sparse(void **state) {
  (void)state;
  uint64_t seed = qkt_seed(2401);
  run_scene(seed, 600, 120, 0, 12);
}

static void test_world_walk_dense(void **state) {
  (void)state;
  uint64_t seed = qkt_seed(2402);
  run_scene(seed, 500, 60, 1, 8);
}

/* ---- the last update's state ----------------------------------------------------------- */

static qk_world_t *dense_world(unsigned threads, size_t thread_min, uint32_t n, qk_handle_t *h,
                               uint64_t seed) {
  qkt_rng_t rng;
  qkt_rng_seed(&rng, seed);
  qk_world_options_t o;
  qk_world_options_init(&o);
  o.threads = threads;
  o.thread_min = thread_min;
  qk_world_t *w;
  assert_int_equal(qk_world_new(&o, &w), QK_OK);
  for (uint32_t i = 0; i < n; i++) {
    double x = qkt_rng_below(&rng, 40), y = qkt_rng_below(&rng, 40);
    qk_shape_t s = {QK_SHAPE_BOX, x, y, x + 1 + qkt_rng_below(&rng, 6),
                    y + 1 + qkt_rng_below(&rng, 6)};
    assert_int_equal(qk_world_add(w, &s, i, &h[i]), QK_OK);
  }
  assert_int_equal(qk_world_update(w), QK_OK);
  return w;
}

static void test_world_walk_last_update(void **state) {
  (void)state;
  uint64_t seed = qkt_seed(2403);
  qkt_rng_t rng;
  qkt_rng_seed(&rng, seed + 1);
  static qk_handle_t h[400];
  for (unsigned th = 1; th <= 3; th++) {
    qk_world_t *w = dense_world(th, 0, 400, h, seed);
    /* A second frame, so that began and ended are not empty. */
    for (uint32_t i = 0; i < 400; i += 3) {
      qk_shape_t s = {QK_SHAPE_BOX, i % 37, i % 41, i % 37 + 2, i % 41 + 2};
      assert_int_equal(qk_world_move(w, h[i], &s), QK_OK);
    }
    for (uint32_t i = 1; i < 400; i += 50) assert_int_equal(qk_world_remove(w, h[i]), QK_OK);
    assert_int_equal(qk_world_update(w), QK_OK);
    plist_t want[3] = {{0}};
    for (int which = 0; which < 3; which++) {
      list_of(w, (qk_pairs_which_t)which, &want[which]);
      assert_true(want[which].n > (size_t)(which == 0 ? 1000 : 10));
    }
    /* Changes with no update: moves everywhere, removes, adds into the freed slots. */
    for (uint32_t i = 0; i < 400; i += 2) {
      if (i % 50 == 1) continue;
      qk_shape_t s = {QK_SHAPE_BOX, 100 + i, 100, 100.5 + i, 100.5};
      assert_int_equal(qk_world_move(w, h[i], &s), QK_OK);
    }
    for (uint32_t i = 5; i < 400; i += 40) assert_int_equal(qk_world_remove(w, h[i]), QK_OK);
    for (int i = 0; i < 20; i++) {
      qk_shape_t s = {QK_SHAPE_BOX, 3, 3, 30, 30};
      qk_handle_t nh;
      assert_int_equal(qk_world_add(w, &s, 0, &nh), QK_OK);
    }
    rec_t rec;
    memset(&rec, 0, sizeof rec);
    for (int which = 0; which < 3; which++) {
      plist_t now = {0};
      list_of(w, (qk_pairs_which_t)which, &now);
      assert_same(now.p, now.n, want[which].p, want[which].n, "list after changes", seed);
      check_walk(w, (qk_pairs_which_t)which, th, &want[which], &rec, seed);
      check_ranges(w, (qk_pairs_which_t)which, &want[which], &rng, seed);
      free(now.p), free(want[which].p);
    }
    rec_free(&rec);
    qk_world_free(w);
  }
}

/* ---- stopping ------------------------------------------------------------------------- */

static void test_world_walk_stop(void **state) {
  (void)state;
  uint64_t seed = qkt_seed(2404);
  qkt_rng_t rng;
  qkt_rng_seed(&rng, seed);
  static qk_handle_t h[400];
  for (unsigned th = 1; th <= 4; th++) {
    qk_world_t *w = dense_world(th, 0, 400, h, seed + th);
    plist_t want = {0};
    list_of(w, QK_PAIRS_ALL, &want);
    assert_true(want.n > 1000);
    rec_t rec;
    memset(&rec, 0, sizeof rec);
    for (int round = 0; round < 20; round++) {
      rec_reset(&rec);
      rec.stop_worker = qkt_rng_below(&rng, th);
      size_t lo, hi;
      split(want.n, th, rec.stop_worker, &lo, &hi);
      rec.stop_at = 1 + qkt_rng_below(&rng, (uint32_t)(hi - lo));
      assert_int_equal(qk_world_pairs_parallel(w, QK_PAIRS_ALL, rec_fn, &rec), QK_OK);
      assert_false(rec.bad_thread);
      assert_int_equal(rec.per[rec.stop_worker].n, rec.stop_at);
      for (unsigned t = 0; t < th; t++) {
        split(want.n, th, t, &lo, &hi);
        assert_true(rec.per[t].n <= hi - lo);
        assert_same(rec.per[t].p, rec.per[t].n, want.p + lo, rec.per[t].n, "stopped prefix", seed);
      }
      /* One thread: the walk is qk_world_pairs's, stopped at the same pair. */
      if (th == 1) assert_int_equal(rec.per[0].n, rec.stop_at);
    }
    rec_free(&rec);
    free(want.p);
    qk_world_free(w);
  }
}

/* Worker 0 asks to stop at its first pair once worker 1 is in its first; worker 1 waits
 * there until then (and 50 ms more, for the request to reach it) before it returns 0.
 * Then it must report at most 63 more pairs (the rest of its block of 64), of a range of
 * about 3000. (Workers run on threads at once: the world's workers or threads started
 * for the call.) */
typedef struct stopper {
  atomic_int in1, asked;
  size_t calls[2];
  int timed_out;
} stopper_t;

/* Wait until *flag is set, at most 10 s (then *timed_out). */
static void wait_flag(atomic_int *flag, int *timed_out) {
  struct timespec t0, t;
  clock_gettime(CLOCK_MONOTONIC, &t0);
  while (!atomic_load(flag)) {
    clock_gettime(CLOCK_MONOTONIC, &t);
    if ((double)(t.tv_sec - t0.tv_sec) + 1e-9 * (double)(t.tv_nsec - t0.tv_nsec) > 10) {
      *timed_out = 1;
      return;
    }
  }
}

static int stopper_fn(qk_handle_t a, qk_handle_t b, unsigned worker, void *ud) {
  (void)a, (void)b;
  stopper_t *s = ud;
  s->calls[worker]++;
  if (worker == 0) {
    wait_flag(&s->in1, &s->timed_out);
    atomic_store(&s->asked, 1);
    return 1;
  }
  if (s->calls[1] == 1) {
    atomic_store(&s->in1, 1);
    int late = 0;
    wait_flag(&s->asked, &late);
    if (late) s->timed_out = 2;
    nanosleep(&(struct timespec){0, 50 * 1000 * 1000}, NULL);
  }
  return 0;
}

static void test_world_walk_stop_others(void **state) {
  (void)state;
  static qk_handle_t h[400];
  qk_world_t *w = dense_world(2, 0, 400, h, 2408);
  size_t n = 0;
  assert_int_equal(qk_world_pairs_list(w, QK_PAIRS_ALL, NULL, 0, &n), QK_OK);
  assert_true(n > 1000);
  for (int round = 0; round < 3; round++) {
    stopper_t s = {0};
    assert_int_equal(qk_world_pairs_parallel(w, QK_PAIRS_ALL, stopper_fn, &s), QK_OK);
    assert_false(s.timed_out);
    assert_int_equal(s.calls[0], 1);
    assert_in_range(s.calls[1], 1, 64);
  }
  qk_world_free(w);
}

/* ---- thread_min ------------------------------------------------------------------------ */

static void test_world_walk_thread_min(void **state) {
  (void)state;
  static qk_handle_t h[400];
  /* Fewer pairs than threads: one worker a pair. */
  qk_world_options_t o;
  qk_world_options_init(&o);
  o.threads = 4, o.thread_min = 0;
  qk_world_t *few;
  assert_int_equal(qk_world_new(&o, &few), QK_OK);
  for (int i = 0; i < 3; i++) {
    qk_shape_t s = {QK_SHAPE_BOX, 10.0 * (i / 2), 0, 10.0 * (i / 2) + 1, 1};
    assert_int_equal(qk_world_add(few, &s, 0, &h[i]), QK_OK);
  }
  qk_shape_t far = {QK_SHAPE_BOX, 5, 5, 6, 6};
  assert_int_equal(qk_world_add(few, &far, 0, &h[3]), QK_OK);
  assert_int_equal(qk_world_update(few), QK_OK);
  plist_t two = {0};
  list_of(few, QK_PAIRS_ALL, &two);
  assert_int_equal(two.n, 1);
  rec_t rec1;
  memset(&rec1, 0, sizeof rec1);
  check_walk(few, QK_PAIRS_ALL, 4, &two, &rec1, 2405);
  /* Two pairs (a box over two others): two workers of four. */
  qk_shape_t wide = {QK_SHAPE_BOX, 0, 0, 9, 1};
  assert_int_equal(qk_world_move(few, h[3], &wide), QK_OK);
  assert_int_equal(qk_world_update(few), QK_OK);
  list_of(few, QK_PAIRS_ALL, &two);
  assert_int_equal(two.n, 3);
  check_walk(few, QK_PAIRS_ALL, 4, &two, &rec1, 2405);
  list_of(few, QK_PAIRS_BEGAN, &two);
  assert_int_equal(two.n, 2);
  check_walk(few, QK_PAIRS_BEGAN, 4, &two, &rec1, 2405);
  rec_free(&rec1);
  free(two.p);
  qk_world_free(few);
  /* 400 live objects: below thread_min 401 the walk has one worker, from 400 four. */
  for (int side = 0; side < 2; side++) {
    qk_world_t *w = dense_world(4, side ? 400 : 401, 400, h, 2405);
    plist_t want = {0};
    list_of(w, QK_PAIRS_ALL, &want);
    rec_t rec;
    memset(&rec, 0, sizeof rec);
    check_walk(w, QK_PAIRS_ALL, side ? 4 : 1, &want, &rec, 2405);
    rec_free(&rec);
    free(want.p);
    qk_world_free(w);
  }
}

/* ---- the caller's own threads ---------------------------------------------------------- */

typedef struct slicer {
  const qk_world_t *w;
  qk_world_pair_t *out;
  size_t n, slice;
  unsigned id, nthreads;
  int bad;
} slicer_t;

/* Thread id takes slices id, id + nthreads, ... of the pairs. */
static void *slicer_run(void *arg) {
  slicer_t *s = arg;
  for (size_t first = s->id * s->slice; first < s->n; first += s->nthreads * s->slice) {
    size_t n_out = 0;
    if (qk_world_pairs_range(s->w, QK_PAIRS_ALL, first, s->out + first, s->slice, &n_out) !=
            QK_OK ||
        n_out != s->n)
      s->bad = 1;
  }
  return NULL;
}

/* A whole parallel walk on a thread of the caller's. */
typedef struct walker {
  const qk_world_t *w;
  const plist_t *want;
  unsigned threads;
  rec_t rec;
} walker_t;

static void *walker_run(void *arg) {
  walker_t *k = arg;
  rec_reset(&k->rec);
  if (qk_world_pairs_parallel(k->w, QK_PAIRS_ALL, rec_fn, &k->rec) != QK_OK) k->rec.bad_thread = 3;
  return NULL;
}

static void test_world_walk_own_threads(void **state) {
  (void)state;
  static qk_handle_t h[400];
  qk_world_t *w = dense_world(1, 0, 400, h, 2406);
  plist_t want = {0};
  list_of(w, QK_PAIRS_ALL, &want);
  qk_world_pair_t *out = calloc(want.n, sizeof *out);
  assert_non_null(out);
  enum { NTH = 3 };
  pthread_t th[NTH];
  slicer_t sl[NTH];
  for (unsigned i = 0; i < NTH; i++) {
    sl[i] = (slicer_t){w, out, want.n, 97, i, NTH, 0};
    assert_int_equal(pthread_create(&th[i], NULL, slicer_run, &sl[i]), 0);
  }
  for (unsigned i = 0; i < NTH; i++) {
    pthread_join(th[i], NULL);
    assert_false(sl[i].bad);
  }
  assert_same(out, want.n, want.p, want.n, "slices on the caller's threads", 2406);
  free(out), free(want.p);
  qk_world_free(w);
  /* Two parallel walks of a two-thread world at once, from two threads: one may have the
   * world's workers, the other starts threads of its own; both get the list. */
  w = dense_world(2, 0, 400, h, 2407);
  want = (plist_t){0};
  list_of(w, QK_PAIRS_ALL, &want);
  static walker_t wk[2];
  for (int round = 0; round < 20; round++) {
    for (unsigned i = 0; i < 2; i++) {
      wk[i].w = w, wk[i].want = &want, wk[i].threads = 2;
      assert_int_equal(pthread_create(&th[i], NULL, walker_run, &wk[i]), 0);
    }
    for (unsigned i = 0; i < 2; i++) {
      pthread_join(th[i], NULL);
      assert_false(wk[i].rec.bad_thread);
      assert_int_equal(wk[i].rec.per[0].n + wk[i].rec.per[1].n, want.n);
      assert_same(wk[i].rec.per[0].p, wk[i].rec.per[0].n, want.p, wk[i].rec.per[0].n, "walk 0",
                  2407);
      assert_same(wk[i].rec.per[1].p, wk[i].rec.per[1].n, want.p + wk[i].rec.per[0].n,
                  wk[i].rec.per[1].n, "walk 1", 2407);
      assert_int_equal(wk[i].rec.per[0].n, (want.n + 1) / 2);
    }
  }
  for (unsigned i = 0; i < 2; i++) rec_free(&wk[i].rec);
  free(want.p);
  qk_world_free(w);
}

/* ---- arguments ------------------------------------------------------------------------- */

static int count_fn(qk_handle_t a, qk_handle_t b, unsigned worker, void *ud) {
  (void)a, (void)b, (void)worker;
  (*(size_t *)ud)++;
  return 0;
}

static void test_world_walk_arguments(void **state) {
  (void)state;
  qk_world_t *w;
  assert_int_equal(qk_world_new(NULL, &w), QK_OK);
  size_t calls = 0, n_out = 99;
  qk_world_pair_t buf[2] = {{7, 7}, {7, 7}};
  /* Empty: nothing called, nothing written, count 0. */
  for (int which = 0; which < 3; which++) {
    assert_int_equal(qk_world_pairs_parallel(w, (qk_pairs_which_t)which, count_fn, &calls), QK_OK);
    assert_int_equal(qk_world_pairs_range(w, (qk_pairs_which_t)which, 0, buf, 2, &n_out), QK_OK);
    assert_int_equal(n_out, 0);
  }
  assert_int_equal(calls, 0);
  assert_true(buf[0].a == 7);
  /* Bad arguments. */
  assert_int_equal(qk_world_pairs_parallel(NULL, QK_PAIRS_ALL, count_fn, &calls), QK_ERR_INVALID);
  assert_int_equal(qk_world_pairs_parallel(w, QK_PAIRS_ALL, NULL, &calls), QK_ERR_INVALID);
  assert_int_equal(qk_world_pairs_parallel(w, (qk_pairs_which_t)3, count_fn, &calls),
                   QK_ERR_INVALID);
  assert_int_equal(qk_world_pairs_parallel(w, (qk_pairs_which_t)-1, count_fn, &calls),
                   QK_ERR_INVALID);
  assert_int_equal(qk_world_pairs_range(NULL, QK_PAIRS_ALL, 0, buf, 2, &n_out), QK_ERR_INVALID);
  assert_int_equal(qk_world_pairs_range(w, QK_PAIRS_ALL, 0, buf, 2, NULL), QK_ERR_INVALID);
  assert_int_equal(qk_world_pairs_range(w, QK_PAIRS_ALL, 0, NULL, 2, &n_out), QK_ERR_INVALID);
  assert_int_equal(qk_world_pairs_range(w, (qk_pairs_which_t)3, 0, buf, 2, &n_out), QK_ERR_INVALID);
  assert_int_equal(qk_world_pairs_range(w, (qk_pairs_which_t)-1, 0, buf, 2, &n_out),
                   QK_ERR_INVALID);
  /* A count with no buffer: out NULL and cap 0. */
  qk_handle_t a, b;
  qk_shape_t s = {QK_SHAPE_BOX, 0, 0, 1, 1};
  assert_int_equal(qk_world_add(w, &s, 0, &a), QK_OK);
  assert_int_equal(qk_world_add(w, &s, 1, &b), QK_OK);
  assert_int_equal(qk_world_update(w), QK_OK);
  assert_int_equal(qk_world_pairs_range(w, QK_PAIRS_ALL, 0, NULL, 0, &n_out), QK_OK);
  assert_int_equal(n_out, 1);
  assert_int_equal(qk_world_pairs_range(w, QK_PAIRS_ALL, 0, buf, 2, &n_out), QK_OK);
  assert_true(buf[0].a == a && buf[0].b == b && buf[1].a == 7);
  assert_int_equal(qk_world_pairs_parallel(w, QK_PAIRS_ALL, count_fn, &calls), QK_OK);
  assert_int_equal(calls, 1);
  qk_world_free(w);
}

int main(void) {
  const struct CMUnitTest tests[] = {
      cmocka_unit_test(test_world_walk_sparse),      cmocka_unit_test(test_world_walk_dense),
      cmocka_unit_test(test_world_walk_last_update), cmocka_unit_test(test_world_walk_stop),
      cmocka_unit_test(test_world_walk_stop_others), cmocka_unit_test(test_world_walk_thread_min),
      cmocka_unit_test(test_world_walk_own_threads), cmocka_unit_test(test_world_walk_arguments),
  };
  return cmocka_run_group_tests(tests, NULL, NULL);
}
