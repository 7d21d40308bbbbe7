/*
 * The update's large scratch kept between updates (issue 10).
 *
 * An update at 10^5 objects allocates some forty blocks of 1 to 8 MB (float boxes, cell
 * boxes, the bands' entries, the re-filing's order and cells, sort scratch, the threads'
 * buffers) and frees them before it returns; the C library gives such blocks back to the
 * kernel and the next frame faults them in again (3 400 page faults an update on one
 * thread, 6 000 on two). So the world's allocator is this cache in front of the one the
 * world was given: during an update a freed block of QK__WSCR_MIN bytes or more is kept
 * (up to QK__WSCR_BLOCKS of them), and a fresh request of that size takes the smallest
 * kept block that holds it and is at most twice its size. A block kept at the start of
 * an update and not taken by its end is freed then, so a world that shrinks gives its
 * memory back within a few updates. Outside an update the cache keeps nothing and takes
 * nothing. Allocation sites need no change: they call the world's allocator as before.
 *
 * A block taken from the cache may be larger than its user believes (its request); such
 * blocks are listed (lent) with their true size, so that their later free or realloc
 * hands the given allocator the size it allocated. The update's worker threads allocate
 * too, so the lists are behind a spin lock (held for a few list operations, never across
 * a call of the given allocator).
 *
 * A fresh block of 4 MB or more from the default allocator is marked for transparent huge
 * pages (qk__advise_huge): where a first touch of a 4 KB page is dear (15 us of CPU time on
 * a paravirtualised guest), the blocks the cache has not kept yet, in the first frames
 * after a build or when the counts change, fault in by 2 MB (the bench's clustered 10^5
 * scene, frames 1-5 on one thread: 3 900 page faults an update -> 1 000-1 150).
 */
#include "collide/world_internal.h"

#include <string.h>

static void lock(qk__wscr_t *c) {
  while (atomic_flag_test_and_set_explicit(&c->lock, memory_order_acquire)) {
  }
}
static void unlock(qk__wscr_t *c) { atomic_flag_clear_explicit(&c->lock, memory_order_release); }

/* The lent entry of p, or -1. */
static int lent_of(const qk__wscr_t *c, const void *p) {
  for (unsigned i = 0; i < c->n_lent; i++)
    if (c->lent[i].p == p) return (int)i;
  return -1;
}

static void *cache_fn(void *ud, void *p, size_t osize, size_t nsize) {
  qk__wscr_t *c = ud;
  /* Small blocks (never lent: a lent block's size is at least QK__WSCR_MIN) pass. */
  if (osize < QK__WSCR_MIN && (p || nsize < QK__WSCR_MIN))
    return qk__realloc(&c->user, p, osize, nsize);
  if (!p) {
    /* A fresh block: the smallest kept one that holds it and is at most twice it. */
    lock(c);
    int best = -1;
    if (c->active && c->n_lent < QK__WSCR_LENT)
      for (unsigned i = 0; i < c->n_blk; i++)
        if (c->blk[i].cap >= nsize && c->blk[i].cap / 2 <= nsize &&
            (best < 0 || c->blk[i].cap < c->blk[best].cap))
          best = (int)i;
    if (best >= 0) {
      void *q = c->blk[best].p;
      c->lent[c->n_lent++] = (qk__wscr_lent_t){q, c->blk[best].cap, nsize, c->blk[best].hi};
      c->blk[best] = c->blk[--c->n_blk];
      unlock(c);
      return q;
    }
    /* A miss: in an update, a block an eighth larger (lent), so that the next frame's
     * request, much the same, fits it too. */
    int roomy = c->active && c->n_lent + c->n_resv < QK__WSCR_LENT;
    c->n_resv += roomy;
    unlock(c);
    if (!roomy) {
      void *q = qk__realloc(&c->user, NULL, 0, nsize);
      qk__advise_huge(&c->user, q, nsize);
      return q;
    }
    size_t cap = nsize + nsize / 8;
    void *q = qk__realloc(&c->user, NULL, 0, cap);
    qk__advise_huge(&c->user, q, cap);
    lock(c);
    c->n_resv--;
    if (q) c->lent[c->n_lent++] = (qk__wscr_lent_t){q, cap, nsize, 0};
    unlock(c);
    return q;
  }
  lock(c);
  int k = lent_of(c, p);
  size_t cap = k >= 0 ? c->lent[k].cap : osize, hi = osize;
  if (k >= 0) hi = c->lent[k].size > c->lent[k].hi ? c->lent[k].size : c->lent[k].hi;
  if (nsize == 0) {
    if (k >= 0) c->lent[k] = c->lent[--c->n_lent];
    if (c->active && c->n_blk < QK__WSCR_BLOCKS) {
      c->blk[c->n_blk++] = (qk__wscr_blk_t){p, cap, hi, c->epoch};
      unlock(c);
      return NULL;
    }
    unlock(c);
    return qk__realloc(&c->user, p, cap, 0);
  }
  if (nsize <= cap && nsize >= cap / 2 && nsize >= QK__WSCR_MIN &&
      (k >= 0 || (c->active && c->n_lent + c->n_resv < QK__WSCR_LENT))) {
    /* Still fits its block: nothing to move (a block cut in an update keeps its room, as
     * the next frame's will want it again). */
    if (k < 0) k = (int)c->n_lent++, c->lent[k] = (qk__wscr_lent_t){p, cap, 0, 0};
    c->lent[k].size = nsize;
    unlock(c);
    return p;
  }
  int active = c->active;
  unlock(c);
  if (active && nsize < osize) {
    /* Cut to less than half in an update: moved to a block of its new size, and its old
     * block kept for a request of about its size (the next frame's, or this one's). */
    void *q = cache_fn(c, NULL, 0, nsize);
    if (q) {
      memcpy(q, p, nsize);
      cache_fn(c, p, osize, 0);
      return q;
    }
  }
  void *q = qk__realloc(&c->user, p, cap, nsize);
  if (q && k >= 0) {
    lock(c);
    int j = lent_of(c, p); /* (other threads may have moved the entries) */
    c->lent[j] = c->lent[--c->n_lent];
    unlock(c);
  }
  return q;
}

void qk__wscr_init(qk_world_t *w, const qk_allocator_t *user) {
  qk__wscr_t *c = &w->scr;
  memset(c, 0, sizeof *c);
  atomic_flag_clear(&c->lock);
  c->user = *user;
  w->alloc = (qk_allocator_t){cache_fn, c};
}

void qk__wscr_begin(qk_world_t *w) {
  qk__wscr_t *c = &w->scr;
  lock(c);
  c->epoch++;
  c->active = 1;
  unlock(c);
}

/* Blocks given back (gone.b[0 .. n)) with the allocator that gave them. */
typedef struct gone {
  qk_allocator_t user;
  unsigned n;
  qk__wscr_blk_t b[QK__WSCR_BLOCKS];
} gone_t;

static void gone_free(void *ctx) {
  gone_t *g = ctx;
  for (unsigned i = 0; i < g->n; i++) qk__realloc(&g->user, g->b[i].p, g->b[i].cap, 0);
}

static void gone_free_job(void *ctx) {
  gone_t *g = ctx;
  qk_allocator_t a = g->user;
  gone_free(g);
  qk__free(&a, g, sizeof *g);
}

/* Frees the kept blocks of an epoch other than keep (all of them when keep is 0, which
 * no update has). With w, on a worker of the world's pool when it has one: the caller
 * goes on (giving back the blocks of a frame where the pairs were many, 480 MB at 10^5
 * clustered boxes, took it 14 ms on the benchmark's second frame). */
static void drop(qk__wscr_t *c, unsigned keep, qk_world_t *w) {
  gone_t g0, *g = &g0;
  g0.n = 0;
  lock(c);
  for (unsigned i = 0; i < c->n_blk;)
    if (!keep || c->blk[i].epoch != keep)
      g0.b[g0.n++] = c->blk[i], c->blk[i] = c->blk[--c->n_blk];
    else
      i++;
  unlock(c);
  g0.user = c->user;
  if (g0.n && w && w->pool && (g = qk__realloc(&c->user, NULL, 0, sizeof *g))) {
    *g = g0;
    if (qk__world_pool_detach(w, gone_free_job, g)) return;
    qk__free(&c->user, g, sizeof *g);
  }
  gone_free(&g0);
}

void qk__wscr_end(qk_world_t *w) {
  qk__wscr_t *c = &w->scr;
  lock(c);
  c->active = 0;
  unsigned e = c->epoch;
  unlock(c);
  drop(c, e, w);
  /* A kept block serves a request of half its size and up, so over frames whose requests
   * shrink (a world's first update files everything at once, later ones only what moved)
   * the kept blocks stayed up to twice what the updates used: 19 MB kept for 16.6 MB of
   * requests at 10^5 moving objects, a churned world 1.21x the memory of a fresh one.
   * Each block's hi is its largest use, less a sixteenth for every update since: a block
   * a quarter larger than that is cut to an eighth more (realloc cuts in place: the pages
   * past the cut are given back, none is touched). A block that serves a large request
   * now and then keeps its room; one that serves smaller requests for some updates in a
   * row shrinks. (The update's workers have stopped: nothing else uses the lists now.) */
  for (unsigned i = 0; i < c->n_blk; i++) {
    qk__wscr_blk_t *b = &c->blk[i];
    size_t want = b->hi + b->hi / 8;
    if (b->cap > b->hi + b->hi / 4 && want >= QK__WSCR_MIN) {
      void *q = qk__realloc(&c->user, b->p, b->cap, want);
      if (q) b->p = q, b->cap = want;
    }
    b->hi -= b->hi / 16;
  }
}

void qk__wscr_flush(qk_world_t *w) { drop(&w->scr, 0, NULL); }

size_t qk__wscr_bytes(const qk_world_t *w) {
  qk__wscr_t *c = (qk__wscr_t *)&w->scr; /* (the lock only) */
  size_t b = 0;
  lock(c);
  for (unsigned i = 0; i < c->n_blk; i++) b += c->blk[i].cap;
  for (unsigned i = 0; i < c->n_lent; i++) b += c->lent[i].cap - c->lent[i].size;
  unlock(c);
  return b;
}
