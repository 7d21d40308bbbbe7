/*
 * The world's worker threads. An update runs up to eight parallel steps (the re-filing's
 * merge, the packing, the search, the rows' four passes); starting and joining threads for
 * each (qk__run_shares) costs a thread creation, a wake-up on another core and a join per
 * step and thread, every frame. So a world with threads > 1 keeps its workers, a pool of
 * index/ (qk__pool_t in index/index_access.h; the bulk build's team is one too): they are
 * started by the first update that uses them, run the shares of every later step, and wait
 * in between by the pool's rule: spinning while an update holds the pool (its next step
 * follows within microseconds), then parked until the next step or qk_world_free. The
 * calling thread runs share 0 of every step, as before, so the shares and what each writes
 * are those of qk__run_shares: no answer depends on which of them ran the workers.
 *
 * The pool serves one step at a time. The update has the world to itself, but the batch
 * queries (const, maybe from several threads at once) also run steps: a step that finds
 * the pool taken runs on threads started for it instead (qk__run_shares).
 *
 * A detached job (qk__world_pool_detach: the scratch cache's blocks given back at the end
 * of an update) is a step of its own that only the first worker runs and nobody waits
 * for: the caller goes on, and the pool's next step, or its end, first waits for it.
 *
 * In a child forked after the workers started, they do not exist: the pool refuses every
 * step there (the steps start threads as before) until the next update frees its memory and
 * starts workers of the child's own.
 */
#include "collide/world_internal.h"

void qk__world_pool_start(qk_world_t *w, unsigned threads) {
  if (w->pool && !qk__pool_live(w->pool)) qk__pool_free(w->pool), w->pool = NULL;
  if (!w->pool && threads >= 2)
    w->pool = qk__pool_new(&w->alloc, threads); /* (NULL: the steps start their own threads) */
}

void qk__world_pool_free(qk_world_t *w) {
  qk__pool_free(w->pool);
  w->pool = NULL;
}

void qk__world_pool_hold(qk_world_t *w, int on) { qk__pool_hold(w->pool, on); }

int qk__world_pool_detach(qk_world_t *w, void (*fn)(void *), void *ctx) {
  return qk__pool_detach(w->pool, fn, ctx);
}

void qk__world_run_jobs(const qk_world_t *w, unsigned threads, unsigned n,
                        void (*fn)(unsigned i, void *ud), void *ud) {
  qk__pool_run_jobs(w->pool, threads, n, fn, ud);
}

void qk__world_run_jobs_shared(const qk_world_t *w, unsigned threads, unsigned n,
                               void (*fn)(unsigned i, unsigned s, void *ud), void *ud) {
  qk__pool_run_jobs_dynamic(w->pool, threads, n, fn, ud);
}
