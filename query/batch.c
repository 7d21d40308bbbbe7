/*
 * Batch queries: many queries in one call, answered in Z-order of their locations (so
 * that consecutive searches reuse the cache and most of one another's descent; point
 * location also walks the descents of the next QK__LANES queries in lockstep, so that
 * their cache misses overlap), and the queries spread
 * over the tree's threads in contiguous runs of that order: kNN and point location in
 * chunks that each thread takes from a shared counter when it is done with the one before
 * (qk__chunks_t), radius in one run per thread (its packed results go in thread order).
 * Every query writes only its own outputs, so the results are those of one thread; a
 * failed query is reported by the lowest index, whatever thread met it.
 */
#include <string.h>

#include "query/query_internal.h"

/* How many places ahead in Z-order a kNN batch asks for a query and its answer slots. */
#define QK__BATCH_AHEAD 8

/*
 * QK__BATCH_TEAM: a batch on several threads holds a team (qk__team_begin) for its length,
 * so that its regions (the Z-order's six and the queries', radius's search and copy) run
 * on one set of workers, started once and away from the calling thread's processor,
 * instead of a thread started for each region. On this guest a thread took 0.1-3.5 ms from
 * its creation to its share in a busy session: paid seven times, that was most of a
 * 100,000-query kNN batch's 15 ms on two threads.
 */

/* ---- the Z-order on the batch's threads ------------------------------------------- */

/* Batches from this size on are ordered on their threads. */
#define QK__ORDER_PAR_MIN 65536
/* As query/order.c: 11 bits per axis, two LSD passes of 11 bits. */
#define QK__OBITS 11
#define QK__OCELLS (1u << QK__OBITS)

/*
 * qk__morton_order()'s sort with its loops shared: the keys cut into one contiguous range
 * per share; per pass every share counts its range's digits, the offsets follow from the
 * counts in (digit, share) order, and every share moves its range to them. That is the
 * serial stable pass exactly, so the order (and the block, released with
 * qk__morton_free) is the same as qk__morton_order's.
 */
typedef struct order_job {
  const qk_point_t *qs;
  uint64_t *key, *tmp;
  size_t nq;
  unsigned nw, shift;
  double x0, y0, scale;
  uint32_t *count; /* nw rows of QK__OCELLS */
} order_job_t;

static inline uint32_t ocell(double v, double lo, double scale) {
  double c = (v - lo) * scale;
  if (!(c > 0)) return 0;
  if (c >= QK__OCELLS - 1) return QK__OCELLS - 1;
  return (uint32_t)c;
}

static void order_keys(void *ctx, unsigned w, unsigned nw) {
  order_job_t *j = ctx;
  size_t lo, hi;
  qk__share_range(j->nq, w, nw, &lo, &hi);
  for (size_t i = lo; i < hi; i++) {
    const uint32_t code = qk__spread16(ocell(j->qs[i].x, j->x0, j->scale)) << 1 |
                          qk__spread16(ocell(j->qs[i].y, j->y0, j->scale));
    j->key[i] = (uint64_t)code << 32 | (uint64_t)i;
  }
}

static void order_count(void *ctx, unsigned w, unsigned nw) {
  order_job_t *j = ctx;
  size_t lo, hi;
  qk__share_range(j->nq, w, nw, &lo, &hi);
  uint32_t *count = j->count + (size_t)w * QK__OCELLS;
  memset(count, 0, QK__OCELLS * sizeof *count);
  for (size_t i = lo; i < hi; i++) count[j->key[i] >> j->shift & (QK__OCELLS - 1)]++;
}

static void order_move(void *ctx, unsigned w, unsigned nw) {
  order_job_t *j = ctx;
  size_t lo, hi;
  qk__share_range(j->nq, w, nw, &lo, &hi);
  uint32_t *at = j->count + (size_t)w * QK__OCELLS; /* by now: where the digits go */
  for (size_t i = lo; i < hi; i++)
    j->tmp[at[j->key[i] >> j->shift & (QK__OCELLS - 1)]++] = j->key[i];
}

static void order_index(void *ctx, unsigned w, unsigned nw) {
  order_job_t *j = ctx;
  size_t lo, hi;
  qk__share_range(j->nq, w, nw, &lo, &hi);
  uint32_t *o = (uint32_t *)j->tmp;
  for (size_t i = lo; i < hi; i++) o[i] = (uint32_t)(j->key[i] & 0xFFFFFFFFu);
}

/* The Z-order of the queries, as qk__morton_order() gives it, on nw threads. */
static void *morton_order_par(const qk_tree_t *t, const qk_point_t *qs, size_t nq, unsigned nw,
                              uint32_t **order) {
  if (nw <= 1 || nq < QK__ORDER_PAR_MIN || nq > UINT32_MAX)
    return qk__morton_order(t, qs, nq, order);
  *order = NULL;
  const qk_allocator_t *a = qk__tree_allocator(t);
  uint64_t *k = qk__realloc(a, NULL, 0, 2 * nq * sizeof *k);
  uint32_t *count = qk__realloc(a, NULL, 0, (size_t)nw * QK__OCELLS * sizeof *count);
  if (!k || !count) {
    qk__free(a, count, (size_t)nw * QK__OCELLS * sizeof *count);
    if (k) qk__morton_free(t, k, nq);
    return NULL;
  }
  const qk_square_t r = qk__tree_root_square(t);
  order_job_t j = {qs, k, k + nq, nq, nw, 0, r.x, r.y, (double)QK__OCELLS / r.side, count};
  qk__run_shares(nw, order_keys, &j);
  for (int pass = 0; pass < 2; pass++) {
    j.shift = 32 + QK__OBITS * (unsigned)pass;
    qk__run_shares(nw, order_count, &j);
    uint32_t sum = 0;
    for (uint32_t b = 0; b < QK__OCELLS; b++)
      for (unsigned w = 0; w < nw; w++) {
        const uint32_t c = count[(size_t)w * QK__OCELLS + b];
        count[(size_t)w * QK__OCELLS + b] = sum;
        sum += c;
      }
    qk__run_shares(nw, order_move, &j);
    uint64_t *s = j.key;
    j.key = j.tmp;
    j.tmp = s;
  }
  /* Two passes: the keys are back in the first half; the indices go to the second. */
  qk__run_shares(nw, order_index, &j);
  qk__free(a, count, (size_t)nw * QK__OCELLS * sizeof *count);
  *order = (uint32_t *)j.tmp;
  return k;
}

/* ---- kNN ------------------------------------------------------------------------- */

typedef struct knn_job {
  const qk_tree_t *t;
  const qk_point_t *qs;
  const uint32_t *order;
  size_t nq, k;
  double max_dist;
  qk_neighbor_t *out;
  size_t *counts;
  qk__chunks_t chunks; /* runs of the Z-order, taken by the threads as they go */
  qk__first_err_t err[QK__MAX_THREADS];
} knn_job_t;

/* Queries per chunk at least: a chunk's first search descends the whole path and its
 * first QK__BATCH_AHEAD queries are not asked for ahead. */
#define QK__BATCH_CHUNK_MIN 256

static void knn_share(void *ctx, unsigned w, unsigned nw) {
  (void)nw;
  knn_job_t *j = ctx;
  size_t lo, hi;
  qk__first_err_t e = {QK_OK, SIZE_MAX};
  /* One path, carried from query to query: in Z-order each shares most of it with the
   * one before (qk__path_reuse), so only the last levels are descended again. */
  qk__path_t path;
  qk__path_init(j->t, &path);
  while (qk__chunks_take(&j->chunks, &lo, &hi))
    for (size_t jj = lo; jj < hi; jj++) {
      size_t i = j->order ? j->order[jj] : jj;
      if (j->order && jj + QK__BATCH_AHEAD < hi) {
        /* In Z-order the queries and their answers are read and written at random: ask for
         * those of a query a few places ahead, so that their misses overlap the searches. */
        const size_t a = j->order[jj + QK__BATCH_AHEAD];
        QK__PREFETCH(&j->qs[a]);
        if (j->out && j->k) {
          const char *row = (const char *)&j->out[a * j->k];
          const size_t bytes = j->k * sizeof(qk_neighbor_t);
          for (size_t off = 0; off < bytes && off < 16 * 64; off += 64) QK__PREFETCH_W(row + off);
          QK__PREFETCH_W(row + bytes - 1);
        }
        if (j->counts) QK__PREFETCH_W(&j->counts[a]);
      }
      const qk_point_t q = j->qs[i];
      qk_neighbor_t *o = j->out ? j->out + i * j->k : NULL;
      size_t n = 0;
      qk_status_t st = qk__knn_check(j->t, q, j->max_dist);
      if (st == QK_OK) {
        const int inside = qk__tree_contains(j->t, q.x, q.y);
        if (inside) qk__path_reuse(j->t, &path, q.x, q.y);
        n = qk__knn_one(j->t, q, j->k, j->max_dist, o, inside ? &path : NULL);
      } else {
        qk__note_err(&e, st, i);
      }
      for (size_t m = n; m < j->k; m++) o[m] = (qk_neighbor_t){QK_NONE, INFINITY};
      if (j->counts) j->counts[i] = n;
    }
  j->err[w] = e;
}

qk_status_t qk_query_knn_batch(const qk_tree_t *tree, const qk_point_t *qs, size_t nq, size_t k,
                               double max_dist, qk_neighbor_t *out, size_t *counts) {
  if (!tree || (nq > 0 && !qs) || (nq > 0 && k > 0 && !out)) return QK_ERR_INVALID;
  if (isnan(max_dist) || max_dist < 0) return QK_ERR_INVALID;
  uint32_t *order;
  unsigned nw = qk__batch_threads(tree, nq);
  qk__team_begin(nw); /* (see QK__BATCH_TEAM) */
  void *block = morton_order_par(tree, qs, nq, nw, &order);
  knn_job_t j = {.t = tree,
                 .qs = qs,
                 .order = order,
                 .nq = nq,
                 .k = k,
                 .max_dist = max_dist,
                 .out = out,
                 .counts = counts};
  qk__chunks_init(&j.chunks, nq, nw, QK__BATCH_CHUNK_MIN);
  qk__run_shares(nw, knn_share, &j);
  qk__team_end();
  if (block) qk__morton_free(tree, block, nq);
  qk__first_err_t e = {QK_OK, SIZE_MAX};
  for (unsigned w = 0; w < nw; w++) qk__note_err(&e, j.err[w].st, j.err[w].i);
  return e.st;
}

/* ---- point location --------------------------------------------------------------- */

typedef struct locate_job {
  const qk_tree_t *t;
  const qk_point_t *ps;
  const uint32_t *order;
  size_t n;
  qk_node_t *leaves;
  qk__chunks_t chunks;
} locate_job_t;

static void locate_share(void *ctx, unsigned w, unsigned nw) {
  (void)w, (void)nw;
  locate_job_t *j = ctx;
  size_t lo, hi;
  qk__path_t paths[QK__LANES];
  while (qk__chunks_take(&j->chunks, &lo, &hi))
    for (size_t jj = lo; jj < hi; jj++) {
      if ((jj - lo) % QK__LANES == 0) qk__walk_lanes(j->t, j->ps, j->order, jj, hi, paths);
      const qk__path_t *path = &paths[(jj - lo) % QK__LANES];
      size_t i = j->order ? j->order[jj] : jj;
      j->leaves[i] = path->valid ? path->leaf.node : QK_NONE;
    }
}

qk_status_t qk_query_locate_batch(const qk_tree_t *tree, const qk_point_t *ps, size_t n,
                                  qk_node_t *leaves) {
  if (!tree || (n > 0 && (!ps || !leaves))) return QK_ERR_INVALID;
  uint32_t *order;
  const unsigned nw = qk__batch_threads(tree, n);
  qk__team_begin(nw); /* (see QK__BATCH_TEAM) */
  void *block = morton_order_par(tree, ps, n, nw, &order);
  locate_job_t j = {.t = tree, .ps = ps, .order = order, .n = n, .leaves = leaves};
  qk__chunks_init(&j.chunks, n, nw, QK__BATCH_CHUNK_MIN);
  qk__run_shares(nw, locate_share, &j);
  qk__team_end();
  if (block) qk__morton_free(tree, block, n);
  return QK_OK;
}

/* ---- radius ----------------------------------------------------------------------- */

/*
 * Radius results are packed, so a share does not know where its results go until the
 * shares before it are done. Share 0 writes straight into the caller's buffer; every
 * other share into a buffer of its own (from the tree's allocator), copied into place
 * after the join, by all the shares at once when there is much to copy (the copy is
 * memory-bound: on one thread it was the batch's serial part). A share whose buffer was
 * too small or could not be had is answered again after the join, on the calling thread,
 * straight into place.
 */
typedef struct radius_job {
  const qk_tree_t *t;
  const qk_point_t *centres;
  size_t nq;
  double r;
  qk_neighbor_t *out;
  size_t cap;
  size_t *counts;
  qk_neighbor_t *buf[QK__MAX_THREADS];
  size_t buf_cap[QK__MAX_THREADS], total[QK__MAX_THREADS];
  size_t at[QK__MAX_THREADS], copy[QK__MAX_THREADS]; /* where each buffer goes; how much */
  size_t copy_total;
  qk__first_err_t err[QK__MAX_THREADS];
} radius_job_t;

/* Results copied by all shares from this many on. */
#define QK__RADIUS_COPY_PAR_MIN 16384

static void radius_share(void *ctx, unsigned w, unsigned nw) {
  radius_job_t *j = ctx;
  size_t lo, hi, bad;
  qk__share_range(j->nq, w, nw, &lo, &hi);
  qk_neighbor_t *out = w == 0 ? j->out : j->buf[w];
  size_t cap = w == 0 ? j->cap : j->buf_cap[w];
  qk_status_t st =
      qk__radius_range(j->t, j->centres, lo, hi, j->r, out, cap, j->counts, &j->total[w], &bad);
  j->err[w] = (qk__first_err_t){st, st == QK_OK ? SIZE_MAX : bad};
}

/* Share w's part of the copy: the results [lo, hi) of the buffers laid end to end, in
 * share order. */
static void radius_copy(void *ctx, unsigned w, unsigned nw) {
  radius_job_t *j = ctx;
  size_t lo, hi, base = 0;
  qk__share_range(j->copy_total, w, nw, &lo, &hi);
  for (unsigned s = 1; s < QK__MAX_THREADS && lo < hi; s++) {
    const size_t end = base + j->copy[s];
    if (lo < end) {
      const size_t m = (hi < end ? hi : end) - lo;
      memcpy(j->out + j->at[s] + (lo - base), j->buf[s] + (lo - base), m * sizeof *j->out);
      lo += m;
    }
    base = end;
  }
}

qk_status_t qk__radius_batch(const qk_tree_t *t, const qk_point_t *centres, size_t nq, double r,
                             qk_neighbor_t *out, size_t cap, size_t *counts, size_t *n_out) {
  unsigned nw = qk__batch_threads(t, nq);
  radius_job_t job = {
      .t = t, .centres = centres, .nq = nq, .r = r, .out = out, .cap = cap, .counts = counts};
  radius_job_t *j = &job;
  /* A guess for the other shares' buffers: as many results per query as share 0 would
   * need if the caller's buffer were sized for the whole batch. */
  for (unsigned w = 1; w < nw; w++) {
    size_t lo, hi;
    qk__share_range(nq, w, nw, &lo, &hi);
    size_t want = cap / nq * (hi - lo) + 64;
    j->buf[w] = qk__realloc(qk__tree_allocator(t), NULL, 0, want * sizeof(qk_neighbor_t));
    j->buf_cap[w] = j->buf[w] ? want : 0;
  }
  qk__team_begin(nw); /* (see QK__BATCH_TEAM) */
  qk__run_shares(nw, radius_share, j);
  /* Where each share's results go (the totals are known now), and what fits there. */
  size_t sum = 0;
  for (unsigned w = 0; w < nw; w++) {
    j->at[w] = sum;
    if (w > 0 && j->total[w] <= j->buf_cap[w] && sum < cap) {
      j->copy[w] = j->total[w] < cap - sum ? j->total[w] : cap - sum;
      j->copy_total += j->copy[w];
    }
    sum += j->total[w];
  }
  if (j->copy_total >= QK__RADIUS_COPY_PAR_MIN)
    qk__run_shares(nw, radius_copy, j);
  else
    radius_copy(j, 0, 1);
  qk__team_end();
  qk__first_err_t e = {QK_OK, SIZE_MAX};
  for (unsigned w = 0; w < nw; w++) {
    size_t lo, hi, bad;
    qk__share_range(nq, w, nw, &lo, &hi);
    if (w > 0 && j->total[w] > j->buf_cap[w]) {
      /* Answer this share again straight into place (what fits in the caller's buffer). */
      size_t room = j->at[w] < cap ? cap - j->at[w] : 0;
      qk_status_t st = qk__radius_range(t, centres, lo, hi, r, out ? out + (cap - room) : NULL,
                                        room, counts, &j->total[w], &bad);
      j->err[w] = (qk__first_err_t){st, st == QK_OK ? SIZE_MAX : bad};
    }
    qk__note_err(&e, j->err[w].st, j->err[w].i);
    if (w > 0) qk__free(qk__tree_allocator(t), j->buf[w], j->buf_cap[w] * sizeof(qk_neighbor_t));
  }
  *n_out = sum;
  return e.st;
}
