/*
 * The world's frame (see collide/world.c for the design): the order brought up to date
 * (collide/world_grid.c), all overlapping pairs found (collide/world_search.c) and
 * sorted into rows (one per slot that has pairs), and the began / ended sets by merging
 * them with the previous frame's.
 */
#include <stdlib.h>
#include <string.h>

#include "collide/world_internal.h"

#if defined(__SSE2__)
#include <emmintrin.h>
#endif

/* Cut a list's room to its length when it holds much more (a failed shrink keeps the
 * larger buffer). */
static void shrink(const qk_allocator_t *a, qk__kvec_t *v) {
  if (v->cap <= v->n + v->n / 4 + 64) return;
  if (v->n == 0) {
    qk__free(a, v->v, v->cap * sizeof *v->v);
    *v = (qk__kvec_t){0};
    return;
  }
  uint64_t *p = qk__realloc(a, v->v, v->cap * sizeof *p, v->n * sizeof *p);
  if (p) v->v = p, v->cap = v->n;
}

static inline int kv_add(const qk_allocator_t *a, qk__kvec_t *v, uint64_t k) {
  if (v->n == v->cap) {
    size_t cap = v->cap ? v->cap * 2 : 64;
    uint64_t *p = qk__realloc(a, v->v, v->cap * sizeof *p, cap * sizeof *p);
    if (!p) return 0;
    v->v = p, v->cap = cap;
  }
  v->v[v->n++] = k;
  return 1;
}

static void rows_free(const qk_allocator_t *a, qk__prows_t *r) {
  qk__free(a, r->b, r->cap * sizeof *r->b);
  qk__free(a, r->row, r->row ? 2 * (r->n_nz + 1) * sizeof *r->row : 0);
  *r = (qk__prows_t){0};
}

/* Room for n_nz rows (row and start in one block); 0 when memory ran short. */
static int rows_alloc(const qk_allocator_t *a, qk__prows_t *r, size_t n_nz) {
  r->row = qk__realloc(a, NULL, 0, 2 * (n_nz + 1) * sizeof *r->row);
  if (!r->row) return 0;
  r->start = r->row + n_nz + 1;
  r->n_nz = n_nz;
  return 1;
}

/*
 * The found keys (unsorted, n of them) as rows over n_obj slots, each row ascending;
 * 0 when memory ran short. Many keys (at least a quarter of the slots): two stable
 * counting sorts, by slot b into tmp (as 32-bit slots a), then by slot a, which writes
 * only b into its row; both counts come from one read of the keys (cnt: 2 (n_obj + 1)
 * entries). Few keys (a sparse world): an LSD radix sort of the keys on the bytes that
 * differ (cnt: 257 entries), so the passes cost the keys, not the slots, then the rows
 * from the sorted keys.
 */
static int make_rows(const qk_allocator_t *al, uint64_t *keys, uint64_t *tmp, size_t n,
                     uint32_t *cnt, uint32_t n_obj, qk__prows_t *r) {
  uint32_t *rb = r->b;
  r->n = n;
  if (n * 4 < n_obj) {
    uint64_t all_or = 0, all_and = ~(uint64_t)0;
    for (size_t i = 0; i < n; i++) all_or |= keys[i], all_and &= keys[i];
    for (int sh = 0; n > 1 && sh < 64; sh += 8) {
      if (!(((all_or ^ all_and) >> sh) & 0xff)) continue;
      memset(cnt, 0, 257 * sizeof *cnt);
      for (size_t i = 0; i < n; i++) cnt[(keys[i] >> sh & 0xff) + 1]++;
      for (int k = 1; k < 257; k++) cnt[k] += cnt[k - 1];
      for (size_t i = 0; i < n; i++) tmp[cnt[keys[i] >> sh & 0xff]++] = keys[i];
      memcpy(keys, tmp, n * sizeof *keys); /* the result stays in keys */
    }
    size_t nz = 0;
    for (size_t i = 0; i < n; i++) nz += !i || keys[i] >> 32 != keys[i - 1] >> 32;
    if (!rows_alloc(al, r, nz)) return 0;
    nz = 0;
    for (size_t i = 0; i < n; i++) {
      if (!i || keys[i] >> 32 != keys[i - 1] >> 32)
        r->row[nz] = (uint32_t)(keys[i] >> 32), r->start[nz++] = (uint32_t)i;
      rb[i] = (uint32_t)keys[i];
    }
    r->start[nz] = (uint32_t)n;
    return 1;
  }
  /* cb[b + 1] counts slot b, then cb[b] is the scatter's cursor; ca[a] counts a, then
   * is row a's cursor. The first scatter writes only slot a (4 bytes), at b's place:
   * b is known from the place in the second. */
  uint32_t *cb = cnt, *ca = cnt + n_obj + 1, *t32 = (uint32_t *)tmp;
  memset(cnt, 0, 2 * ((size_t)n_obj + 1) * sizeof *cnt);
  for (size_t i = 0; i < n; i++) {
    uint64_t k = keys[i];
    cb[(uint32_t)k + 1]++;
    ca[k >> 32]++;
  }
  for (uint32_t a = 1; a <= n_obj; a++) cb[a] += cb[a - 1];
  size_t nz = 0;
  for (uint32_t a = 0; a < n_obj; a++) nz += ca[a] != 0;
  if (!rows_alloc(al, r, nz)) return 0;
  uint32_t sa = 0;
  nz = 0;
  for (uint32_t a = 0; a < n_obj; a++) {
    uint32_t c = ca[a];
    if (c) r->row[nz] = a, r->start[nz++] = sa;
    ca[a] = sa, sa += c;
  }
  r->start[nz] = (uint32_t)n;
  for (size_t i = 0; i < n; i++) t32[cb[(uint32_t)keys[i]]++] = (uint32_t)(keys[i] >> 32);
  /* cb[b] is now the end of b's run, where b + 1's starts. */
  size_t i = 0;
  for (uint32_t b = 0; b < n_obj; b++)
    for (size_t e = cb[b]; i < e; i++) rb[ca[t32[i]]++] = b;
  return 1;
}

/* A slot's object is not the one it held at the last update (removed, or a new one). */
static inline int changed(const qk_world_t *w, uint32_t s) {
  return s >= w->n_obj || w->obj[s].gen != w->ugen[s];
}

/* A cursor over rows in key order: pair i, in a row that ends at end and whose key
 * part is ka. Rows with pairs are not empty, so the next row starts where one ends.
 * Slots are below 2^32 - 1, so no key is END. */
#define END UINT64_MAX
typedef struct rcur {
  const qk__prows_t *r;
  size_t i, end, p;
  uint64_t ka;
} rcur_t;

static inline uint64_t rc_first(rcur_t *c, const qk__prows_t *r) {
  *c = (rcur_t){r, 0, r->n ? r->start[1] : 0, 0, r->n ? (uint64_t)r->row[0] << 32 : 0};
  return r->n ? c->ka | r->b[0] : END;
}

static inline uint64_t rc_next(rcur_t *c) {
  if (++c->i == c->end) {
    if (c->i == c->r->n) return END;
    c->p++;
    c->end = c->r->start[c->p + 1];
    c->ka = (uint64_t)c->r->row[c->p] << 32;
  }
  return c->ka | c->r->b[c->i];
}

/*
 * Began and ended: one merge of this frame's keys with the last frame's. A pair whose
 * slot now holds another object (or none) has ended, and a pair with such a slot has
 * begun (dirty: objects were added or removed since the last update). Both lists come
 * out in key order. Returns 0 when memory ran short (the lists are then the caller's to
 * free).
 */
static int diff_keys(const qk_world_t *w, const qk__prows_t *o, const qk__prows_t *nw, int dirty,
                     qk__kvec_t *bv, qk__kvec_t *ev) {
  const qk_allocator_t *al = &w->alloc;
  rcur_t cn, co;
  uint64_t x = rc_first(&cn, nw), y = rc_first(&co, o);
  while (x != END || y != END) {
    if (x < y) {
      if (!kv_add(al, bv, x)) return 0;
      x = rc_next(&cn);
    } else if (x > y) {
      if (!kv_add(al, ev, y)) return 0;
      y = rc_next(&co);
    } else {
      if (dirty && (changed(w, (uint32_t)(x >> 32)) || changed(w, (uint32_t)x)) &&
          (!kv_add(al, bv, x) || !kv_add(al, ev, x)))
        return 0;
      x = rc_next(&cn), y = rc_next(&co);
    }
  }
  return 1;
}

/* The same merge row by row, for long rows (a dense world): a row's pairs are compared
 * as 32-bit slots in a tight loop, and a row's key is made once. */
static int diff_rows(const qk_world_t *w, const qk__prows_t *o, const qk__prows_t *nw, int dirty,
                     qk__kvec_t *bv, qk__kvec_t *ev) {
  const qk_allocator_t *al = &w->alloc;
  const uint32_t *nb = nw->b, *ob = o->b;
  size_t p = 0, q = 0; /* the next row with pairs, new and old */
  while (p < nw->n_nz || q < o->n_nz) {
    uint32_t an = p < nw->n_nz ? nw->row[p] : UINT32_MAX, ao = q < o->n_nz ? o->row[q] : UINT32_MAX;
    uint32_t a = an < ao ? an : ao;
    size_t i = 0, ie = 0, j = 0, je = 0;
    if (an == a) i = nw->start[p], ie = nw->start[p + 1], p++;
    if (ao == a) j = o->start[q], je = o->start[q + 1], q++;
    uint64_t ka = (uint64_t)a << 32;
    if (dirty && changed(w, a)) { /* every old pair ended, every new one began */
      for (; i < ie; i++)
        if (!kv_add(al, bv, ka | nb[i])) return 0;
      for (; j < je; j++)
        if (!kv_add(al, ev, ka | ob[j])) return 0;
      continue;
    }
    while (i < ie && j < je) {
#if defined(__SSE2__)
      /* Runs of pairs that stayed (most of them), four at a time. */
      if (!dirty)
        while (i + 4 <= ie && j + 4 <= je &&
               _mm_movemask_epi8(_mm_cmpeq_epi32(_mm_loadu_si128((const __m128i *)(nb + i)),
                                                 _mm_loadu_si128((const __m128i *)(ob + j)))) ==
                   0xFFFF)
          i += 4, j += 4;
      if (i == ie || j == je) break;
#endif
      uint32_t x = nb[i], y = ob[j];
      if (x == y) {
        if (dirty && changed(w, x) && (!kv_add(al, bv, ka | x) || !kv_add(al, ev, ka | x)))
          return 0;
        i++, j++;
      } else if (x < y) {
        if (!kv_add(al, bv, ka | x)) return 0;
        i++;
      } else {
        if (!kv_add(al, ev, ka | y)) return 0;
        j++;
      }
    }
    for (; i < ie; i++)
      if (!kv_add(al, bv, ka | nb[i])) return 0;
    for (; j < je; j++)
      if (!kv_add(al, ev, ka | ob[j])) return 0;
  }
  return 1;
}

/* Began and ended, by whichever merge suits the rows' lengths (measured: the key merge
 * for rows of a pair or two, the row merge from about four). */
static int diff(const qk_world_t *w, const qk__prows_t *o, const qk__prows_t *nw, int dirty,
                qk__kvec_t *bv, qk__kvec_t *ev) {
  if (nw->n + o->n >= 4 * (nw->n_nz + o->n_nz)) return diff_rows(w, o, nw, dirty, bv, ev);
  return diff_keys(w, o, nw, dirty, bv, ev);
}

qk_status_t qk_world_update(qk_world_t *w) {
  if (!w) return QK_ERR_INVALID;
  const qk_allocator_t *al = &w->alloc;
  qk__wpack_t pk;
  qk_status_t pst = qk__world_reorder(w, &pk);
  if (pst != QK_OK) {
    qk__world_pack_free(w, &pk);
    return pst;
  }
  qk__kvec_t found;
  qk_status_t st = qk__world_search(w, &pk, &found);
  qk__world_pack_free(w, &pk);
  if (st != QK_OK) return st;
  if (found.n > UINT32_MAX) { /* (rows and counts hold 32-bit positions) */
    qk__free(al, found.v, found.cap * sizeof *found.v);
    return QK_ERR_LIMIT;
  }
  /* Everything else the update needs, before anything changes: the sort's buffer and
   * counts, the new rows, and the began and ended lists (sized by the last frame's,
   * grown as needed): a failure keeps the last frame's lists. */
  size_t total = found.n, n_obj = w->n_obj;
  size_t tcap = total ? total : 1, ccap = total * 4 < n_obj ? 257 : 2 * (n_obj + 1);
  qk__prows_t nr = {0};
  /* (the dense sort's scratch holds 32-bit slots, the sparse one's keys) */
  size_t tbytes = (total * 4 < n_obj ? sizeof(uint64_t) : sizeof(uint32_t)) * tcap;
  uint64_t *tmp = qk__realloc(al, NULL, 0, tbytes);
  uint32_t *cnt = tmp ? qk__realloc(al, NULL, 0, ccap * sizeof *cnt) : NULL;
  nr.b = cnt ? qk__realloc(al, NULL, 0, tcap * sizeof *nr.b) : NULL;
  if (nr.b) nr.cap = tcap;
  qk__kvec_t bv = {0}, ev = {0};
  if (nr.b && make_rows(al, found.v, tmp, total, cnt, (uint32_t)n_obj, &nr)) w->last_found = total;
  qk__free(al, cnt, ccap * sizeof *cnt);
  qk__free(al, tmp, tbytes);
  qk__free(al, found.v, found.cap * sizeof *found.v);
  int dirty = w->ident_dirty;
  size_t n_eg = 0;
  if (dirty)
    for (uint32_t i = 0; i < w->n_obj; i++) n_eg += w->obj[i].gen != w->ugen[i];
  uint64_t *eg = NULL;
  /* The lists start with room for the last frame's counts and some (frames are alike),
   * and grow if need be. */
  size_t bcap = w->began.n + w->began.n / 4 + 64, ecap = w->ended.n + w->ended.n / 4 + 64;
  if (nr.row && (bv.v = qk__realloc(al, NULL, 0, bcap * sizeof *bv.v))) bv.cap = bcap;
  if (bv.v && (ev.v = qk__realloc(al, NULL, 0, ecap * sizeof *ev.v))) ev.cap = ecap;
  if (!ev.v || (n_eg && !(eg = qk__realloc(al, NULL, 0, n_eg * sizeof *eg))) ||
      !diff(w, &w->cur, &nr, dirty, &bv, &ev)) {
    qk__free(al, eg, n_eg * sizeof *eg);
    qk__free(al, bv.v, bv.cap * sizeof *bv.v);
    qk__free(al, ev.v, ev.cap * sizeof *ev.v);
    rows_free(al, &nr);
    return QK_ERR_NOMEM;
  }
  shrink(al, &bv);
  shrink(al, &ev);
  qk__free(al, w->began.v, w->began.cap * sizeof *w->began.v);
  qk__free(al, w->ended.v, w->ended.cap * sizeof *w->ended.v);
  qk__free(al, w->egen, w->n_egen * sizeof *w->egen);
  w->began = bv, w->ended = ev;
  w->egen = eg, w->n_egen = 0;
  /* This frame's rows become the current pairs (their room cut to size when it is much
   * larger: a failed shrink is harmless), and the handles they stand for are the present
   * generations. */
  rows_free(al, &w->cur);
  if (nr.cap > nr.n + nr.n / 4 + 64) {
    size_t c = nr.n ? nr.n : 1;
    uint32_t *p = qk__realloc(al, nr.b, nr.cap * sizeof *p, c * sizeof *p);
    if (p) nr.b = p, nr.cap = c;
  }
  w->cur = nr;
  if (dirty) {
    for (uint32_t i = 0; i < w->n_obj; i++) {
      if (w->obj[i].gen != w->ugen[i]) w->egen[w->n_egen++] = (uint64_t)i << 32 | w->ugen[i];
      w->ugen[i] = w->obj[i].gen;
    }
    w->ident_dirty = 0;
  }
  return QK_OK;
}

/* The handles of an ended pair: the generations its slots had at the update before the
 * last (those of the slots that changed at the last one are kept aside). */
static uint32_t ended_gen(const qk_world_t *w, uint32_t s) {
  size_t lo = 0, hi = w->n_egen;
  while (lo < hi) {
    size_t mid = lo + (hi - lo) / 2;
    uint32_t ms = (uint32_t)(w->egen[mid] >> 32);
    if (ms == s) return (uint32_t)w->egen[mid];
    if (ms < s)
      lo = mid + 1;
    else
      hi = mid;
  }
  return w->ugen[s];
}

static inline qk_world_pair_t ended_pair(const qk_world_t *w, uint64_t k) {
  uint32_t a = (uint32_t)(k >> 32), b = (uint32_t)k;
  return (qk_world_pair_t){(uint64_t)ended_gen(w, a) << 32 | a,
                           (uint64_t)ended_gen(w, b) << 32 | b};
}

qk_status_t qk_world_pairs(const qk_world_t *w, qk_pairs_which_t which, qk_world_pair_fn fn,
                           void *ud) {
  if (!w || !fn) return QK_ERR_INVALID;
  if (which == QK_PAIRS_ENDED) {
    for (size_t i = 0; i < w->ended.n; i++) {
      qk_world_pair_t q = ended_pair(w, w->ended.v[i]);
      if (fn(q.a, q.b, ud)) break;
    }
    return QK_OK;
  }
  if (which == QK_PAIRS_BEGAN) {
    for (size_t i = 0; i < w->began.n; i++) {
      qk_world_pair_t q = qk__key_pair(w, w->began.v[i]);
      if (fn(q.a, q.b, ud)) break;
    }
    return QK_OK;
  }
  if (which != QK_PAIRS_ALL) return QK_ERR_INVALID;
  const qk__prows_t *r = &w->cur;
  for (size_t k = 0; k < r->n_nz; k++) {
    qk_handle_t ha = qk__uhandle(w, r->row[k]);
    for (size_t i = r->start[k], e = r->start[k + 1]; i < e; i++)
      if (fn(ha, qk__uhandle(w, r->b[i]), ud)) return QK_OK;
  }
  return QK_OK;
}

qk_status_t qk_world_pairs_list(const qk_world_t *w, qk_pairs_which_t which, qk_world_pair_t *out,
                                size_t cap, size_t *n_out) {
  if (!w || !n_out || (cap && !out)) return QK_ERR_INVALID;
  if (which == QK_PAIRS_ENDED) {
    *n_out = w->ended.n;
    for (size_t i = 0; i < w->ended.n && i < cap; i++) out[i] = ended_pair(w, w->ended.v[i]);
    return QK_OK;
  }
  if (which == QK_PAIRS_BEGAN) {
    *n_out = w->began.n;
    for (size_t i = 0; i < w->began.n && i < cap; i++) out[i] = qk__key_pair(w, w->began.v[i]);
    return QK_OK;
  }
  if (which != QK_PAIRS_ALL) return QK_ERR_INVALID;
  const qk__prows_t *r = &w->cur;
  *n_out = r->n;
  size_t m = r->n < cap ? r->n : cap;
  for (size_t k = 0; k < r->n_nz && r->start[k] < m; k++) {
    qk_handle_t ha = qk__uhandle(w, r->row[k]);
    for (size_t i = r->start[k], e = r->start[k + 1] < m ? r->start[k + 1] : m; i < e; i++)
      out[i] = (qk_world_pair_t){ha, qk__uhandle(w, r->b[i])};
  }
  return QK_OK;
}
