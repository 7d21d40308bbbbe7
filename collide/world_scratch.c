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
 * Where a first touch of a 4 KB page is dear (15 us of CPU time on a paravirtualised
 * guest), the blocks the cache has not kept yet, in the first frames after a build or
 * when the counts change, are what a frame waits for. With the default allocator, blocks
 * from 1.6 MB on are mapped apart on 2 MB boundaries and marked for transparent huge
 * pages (sys_fn), so that they fault in by 2 MB (4 MB and more were marked from the
 * seventeenth session, in place: 3 900 page faults an update -> 1 000-1 150 on frames 1-5
 * of the bench's clustered 10^5 scene, one thread). A block that grows in an update is
 * moved to one from the cache (twenty-fifth session: see docs/collide.md, "Memory").
 */
#define _DEFAULT_SOURCE /* (mmap's MAP_ANONYMOUS, madvise, sysconf) */
#include "collide/world_internal.h"

#include <stdint.h>
#include <stdlib.h>
#include <string.h>

#if defined(__linux__)
#include <sys/mman.h>
#include <unistd.h>
#endif

/* A transparent huge page's size (x86-64, arm64 with 4 KB pages). */
#define QK__WSCR_HUGE ((size_t)2 << 20)

#if defined(__linux__) && defined(MADV_HUGEPAGE) && defined(MAP_ANONYMOUS)
/*
 * The cache's allocator when the world was given the default one: blocks of 2 MB and more
 * are mapped apart, on 2 MB boundaries, and marked MADV_HUGEPAGE; smaller ones are the C
 * library's. The kernel backs a 2 MB range with a huge page only when the range lies
 * wholly in the mapping and has never had small pages: a block from malloc starts 16
 * bytes past a page (its first and last 2 MB, up to 1 024 pages, faulted by 4 KB), and
 * below glibc's mmap threshold (raised up to 32 MB by the first large free) it is cut
 * from the heap, whose ranges given back and taken again keep small pages (a 2.4 MB
 * block there faulted all its 590 pages by 4 KB). A block's mapping is its size in whole
 * huge pages when that adds a quarter at most, else in whole pages; the size given back
 * is the size asked for (the allocator contract), which gives the same mapping.
 */
static size_t sys_len(size_t size) {
  const size_t round = (size + QK__WSCR_HUGE - 1) & ~(QK__WSCR_HUGE - 1);
  if (round - size <= size / 4) return round;
  return (size + 4095) & ~(size_t)4095;
}

static void *sys_map(size_t size) {
  const size_t len = sys_len(size);
  char *m =
      mmap(NULL, len + QK__WSCR_HUGE, PROT_READ | PROT_WRITE, MAP_PRIVATE | MAP_ANONYMOUS, -1, 0);
  if (m == MAP_FAILED) return NULL;
  char *q = (char *)(((uintptr_t)m + QK__WSCR_HUGE - 1) & ~(uintptr_t)(QK__WSCR_HUGE - 1));
  if (q > m) munmap(m, (size_t)(q - m));
  if (m + QK__WSCR_HUGE > q) munmap(q + len, (size_t)(m + QK__WSCR_HUGE - q));
  (void)madvise(q, len & ~(QK__WSCR_HUGE - 1), MADV_HUGEPAGE);
  return q;
}

/* Whether a block of size bytes is mapped apart: from 2 MB, or when one huge page holds it
 * with a quarter to spare at most (from 1.6 MB). */
static int sys_mapped(size_t size) {
  return size >= QK__WSCR_HUGE || sys_len(size) == QK__WSCR_HUGE;
}

static void *sys_fn(void *ud, void *p, size_t osize, size_t nsize) {
  (void)ud;
  const int mo = p && sys_mapped(osize), mn = sys_mapped(nsize);
  if (!mo && !mn) {
    if (nsize) return realloc(p, nsize);
    free(p);
    return NULL;
  }
  if (mo && mn && sys_len(nsize) <= sys_len(osize)) {
    /* (the same mapping, or its tail given back) */
    if (sys_len(nsize) < sys_len(osize))
      munmap((char *)p + sys_len(nsize), sys_len(osize) - sys_len(nsize));
    return p;
  }
  void *q = NULL;
  if (nsize && !(q = mn ? sys_map(nsize) : malloc(nsize))) return NULL;
  if (q && p) memcpy(q, p, osize < nsize ? osize : nsize);
  if (mo)
    munmap(p, sys_len(osize));
  else
    free(p);
  return q;
}
#define QK__WSCR_SYS 1
#endif

/* A fresh block of at least size bytes from the given allocator; *cap its true size (a
 * mapped block's whole huge pages). */
static void *fresh(qk__wscr_t *c, size_t size, size_t *cap) {
  void *q = qk__realloc(&c->user, NULL, 0, size);
  *cap = size;
#if defined(QK__WSCR_SYS)
  if (c->user.fn == sys_fn && sys_mapped(size) && sys_len(size) % QK__WSCR_HUGE == 0)
    *cap = sys_len(size);
#endif
  return q;
}

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
  /* Small blocks (never lent: a lent block's size is at least QK__WSCR_MIN) pass, unless
   * one grows large (below). */
  if (osize < QK__WSCR_MIN && nsize < QK__WSCR_MIN) return qk__realloc(&c->user, p, osize, nsize);
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
      c->lent[c->n_lent++] = (qk__wscr_lent_t){q, c->blk[best].cap, nsize};
      c->blk[best] = c->blk[--c->n_blk];
      unlock(c);
      return q;
    }
    /* A miss: in an update, a block an eighth larger (lent), so that the next frame's
     * request, much the same, fits it too. */
    int roomy = c->active && c->n_lent + c->n_resv < QK__WSCR_LENT;
    c->n_resv += roomy;
    unlock(c);
    size_t cap;
    if (!roomy) return fresh(c, nsize, &cap);
    void *q = fresh(c, nsize + nsize / 8, &cap);
    lock(c);
    c->n_resv--;
    if (q) c->lent[c->n_lent++] = (qk__wscr_lent_t){q, cap, nsize};
    unlock(c);
    return q;
  }
  lock(c);
  int k = lent_of(c, p);
  size_t cap = k >= 0 ? c->lent[k].cap : osize;
  if (nsize == 0) {
    if (k >= 0) c->lent[k] = c->lent[--c->n_lent];
    if (c->active && c->n_blk < QK__WSCR_BLOCKS) {
      c->blk[c->n_blk++] = (qk__wscr_blk_t){p, cap, c->epoch};
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
    if (k < 0) k = (int)c->n_lent++, c->lent[k] = (qk__wscr_lent_t){p, cap, 0};
    c->lent[k].size = nsize;
    unlock(c);
    return p;
  }
  int active = c->active;
  unlock(c);
  if (active && nsize > osize) {
    /* Grown in an update (a list doubling, or a short list joined into a long one): a
     * block from the cache, or a fresh one with room on huge pages, and the old block
     * given back. (The given allocator's realloc faulted the new pages in by 4 KB, and a
     * block it gave was never the cache's, so the next frame's list, asked for at about
     * its final size, missed too. The old block is not kept: the steps of a list that
     * doubled, kept, were taken by the next frames' requests of up to half their size,
     * and held on to: 40 MB more between updates at 10^5 clustered boxes.) */
    void *q = cache_fn(c, NULL, 0, nsize);
    if (q) {
      memcpy(q, p, osize);
      lock(c);
      int j = lent_of(c, p);
      if (j >= 0) c->lent[j] = c->lent[--c->n_lent];
      unlock(c);
      qk__realloc(&c->user, p, cap, 0);
      return q;
    }
  }
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
#if defined(QK__WSCR_SYS)
  /* (4 KB pages only: sys_len rounds to them) */
  if (!user->fn && sysconf(_SC_PAGESIZE) == 4096) c->user = (qk_allocator_t){sys_fn, NULL};
#endif
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
