/*
 * The world's frame (see collide/world.c for the design): the order brought up to date
 * (collide/world_grid.c), all overlapping pairs found (collide/world_search.c) and
 * sorted, and the began / ended sets by merging with the previous frame.
 */
#include <stdlib.h>
#include <string.h>

#include "collide/world_internal.h"

/* Sort n keys in src: two stable counting sorts, by the second slot then by the first
 * (count has n_obj + 1 entries), through dst, which ends as scratch. Each pass is a count
 * and a scatter, whatever the lengths of the runs. */
static void sort_keys(uint64_t *src, uint64_t *dst, size_t n, uint32_t *count, uint32_t n_obj) {
  if (n == 0) return; /* src may be NULL then */
  memset(count, 0, ((size_t)n_obj + 1) * sizeof *count);
  for (size_t i = 0; i < n; i++) count[(uint32_t)src[i] + 1]++;
  for (uint32_t a = 1; a <= n_obj; a++) count[a] += count[a - 1];
  for (size_t i = 0; i < n; i++) dst[count[(uint32_t)src[i]]++] = src[i];
  memset(count, 0, ((size_t)n_obj + 1) * sizeof *count);
  for (size_t i = 0; i < n; i++) count[(dst[i] >> 32) + 1]++;
  for (uint32_t a = 1; a <= n_obj; a++) count[a] += count[a - 1];
  for (size_t i = 0; i < n; i++) src[count[dst[i] >> 32]++] = dst[i];
}

/* The same for few keys (fewer than a quarter of the slots, as in a sparse world): an LSD
 * radix sort on the keys' bytes that differ, so the passes cost the keys, not the slots
 * (count has at least 256 entries). */
static void sort_few_keys(uint64_t *src, uint64_t *dst, size_t n, uint32_t *count) {
  if (n < 2) return;
  uint64_t all_or = 0, all_and = ~(uint64_t)0;
  for (size_t i = 0; i < n; i++) all_or |= src[i], all_and &= src[i];
  for (int sh = 0; sh < 64; sh += 8) {
    if (!(((all_or ^ all_and) >> sh) & 0xff)) continue;
    memset(count, 0, 257 * sizeof *count);
    for (size_t i = 0; i < n; i++) count[(src[i] >> sh & 0xff) + 1]++;
    for (int k = 1; k < 257; k++) count[k] += count[k - 1];
    for (size_t i = 0; i < n; i++) dst[count[src[i] >> sh & 0xff]++] = src[i];
    memcpy(src, dst, n * sizeof *src); /* the result stays in src */
  }
}

/* Cut a list's room to its length (a failed shrink keeps the larger buffer). */
static void shrink(const qk_allocator_t *a, qk__kvec_t *v) {
  if (v->cap == v->n) return;
  if (v->n == 0) {
    qk__free(a, v->v, v->cap * sizeof *v->v);
    *v = (qk__kvec_t){0};
    return;
  }
  uint64_t *p = qk__realloc(a, v->v, v->cap * sizeof *p, v->n * sizeof *p);
  if (p) v->v = p, v->cap = v->n;
}

/* A slot's object is not the one it held at the last update (removed, or a new one). */
static inline int changed(const qk_world_t *w, uint32_t s) {
  return s >= w->n_obj || w->obj[s].gen != w->obj[s].ugen;
}

qk_status_t qk_world_update(qk_world_t *w) {
  if (!w) return QK_ERR_INVALID;
  qk__wpack_t pk;
  qk_status_t pst = qk__world_reorder(w, &pk);
  if (pst != QK_OK) {
    qk__world_pack_free(w, &pk);
    return pst;
  }
  qk__kvec_t found;
  qk_status_t st = qk__world_search(w, &pk, &found);
  qk__world_pack_free(w, &pk);
  size_t total = found.n;
  /* The sort's scratch and counts; the sorted search buffer becomes the new list (the
   * old one is freed once merged). */
  size_t tcap = total ? total : 1;
  uint64_t *tmp = NULL;
  if (st == QK_OK && !(tmp = qk__realloc(&w->alloc, NULL, 0, tcap * sizeof *tmp)))
    st = QK_ERR_NOMEM;
  size_t n_count = (size_t)w->n_obj + 1 > 257 ? (size_t)w->n_obj + 1 : 257;
  uint32_t *count = NULL;
  if (st == QK_OK && !(count = qk__realloc(&w->alloc, NULL, 0, n_count * sizeof *count)))
    st = QK_ERR_NOMEM;
  if (st == QK_OK) {
    if (total * 4 < w->n_obj)
      sort_few_keys(found.v, tmp, total, count);
    else
      sort_keys(found.v, tmp, total, count, w->n_obj);
    w->last_found = total;
  }
  qk__free(&w->alloc, count, n_count * sizeof *count);
  qk__free(&w->alloc, tmp, tcap * sizeof *tmp);
  if (st != QK_OK) {
    qk__free(&w->alloc, found.v, found.cap * sizeof *found.v);
    return st;
  }
  uint64_t *nv = found.v;
  size_t ncap = found.cap;
  /* Began and ended: a merge of this frame's keys with the last frame's. A pair whose slot
   * now holds another object (or none) has ended, and a pair with such a slot has begun.
   * Their lists are allocated at their largest (all new pairs began, all old ones
   * ended) and, when objects were added or removed, the slots that changed with their
   * generations at the last update (the ended pairs' handles), all before anything
   * changes: a failure keeps the last frame's lists. After the merge the two lists are
   * cut to size (a failed shrink is harmless). */
  const uint64_t *ov = w->cur.v;
  size_t nn = total, on = w->cur.n;
  int dirty = w->ident_dirty;
  size_t n_eg = 0;
  if (dirty)
    for (uint32_t i = 0; i < w->n_obj; i++) n_eg += w->obj[i].gen != w->obj[i].ugen;
  uint64_t *bv = nn ? qk__realloc(&w->alloc, NULL, 0, nn * sizeof *bv) : NULL;
  uint64_t *ev = on ? qk__realloc(&w->alloc, NULL, 0, on * sizeof *ev) : NULL;
  uint64_t *eg = n_eg ? qk__realloc(&w->alloc, NULL, 0, n_eg * sizeof *eg) : NULL;
  if ((nn && !bv) || (on && !ev) || (n_eg && !eg)) {
    qk__free(&w->alloc, bv, nn * sizeof *bv);
    qk__free(&w->alloc, ev, on * sizeof *ev);
    qk__free(&w->alloc, eg, n_eg * sizeof *eg);
    qk__free(&w->alloc, nv, ncap * sizeof *nv);
    return QK_ERR_NOMEM;
  }
  qk__free(&w->alloc, w->began.v, w->began.cap * sizeof *bv);
  qk__free(&w->alloc, w->ended.v, w->ended.cap * sizeof *ev);
  qk__free(&w->alloc, w->egen, w->n_egen * sizeof *w->egen);
  w->began = (qk__kvec_t){bv, 0, nn};
  w->ended = (qk__kvec_t){ev, 0, on};
  w->egen = eg, w->n_egen = 0;
  size_t i = 0, j = 0;
  if (!dirty) { /* the common frame: the same objects, so equal keys are the same pair */
    while (i < nn && j < on) {
      uint64_t x = nv[i], y = ov[j];
      if (x < y)
        bv[w->began.n++] = x, i++;
      else if (x > y)
        ev[w->ended.n++] = y, j++;
      else
        i++, j++;
    }
  }
  for (; i < nn || j < on;) {
    if (j == on || (i < nn && nv[i] < ov[j]))
      bv[w->began.n++] = nv[i++];
    else if (i == nn || nv[i] > ov[j])
      ev[w->ended.n++] = ov[j++];
    else {
      if (dirty && (changed(w, (uint32_t)(nv[i] >> 32)) || changed(w, (uint32_t)nv[i]))) {
        bv[w->began.n++] = nv[i];
        ev[w->ended.n++] = ov[j];
      }
      i++, j++;
    }
  }
  shrink(&w->alloc, &w->began);
  shrink(&w->alloc, &w->ended);
  /* This frame's keys become the current list, and the handles they stand for are the
   * present generations. */
  qk__free(&w->alloc, w->cur.v, w->cur.cap * sizeof *w->cur.v);
  w->cur = (qk__kvec_t){nv, total, ncap};
  shrink(&w->alloc, &w->cur);
  if (dirty) {
    for (uint32_t i = 0; i < w->n_obj; i++) {
      qk__wobj_t *o = &w->obj[i];
      if (o->gen != o->ugen) w->egen[w->n_egen++] = (uint64_t)i << 32 | o->ugen;
      o->ugen = o->gen;
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
  return w->obj[s].ugen;
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
  if (which != QK_PAIRS_ALL && which != QK_PAIRS_BEGAN) return QK_ERR_INVALID;
  const qk__kvec_t *p = which == QK_PAIRS_ALL ? &w->cur : &w->began;
  for (size_t i = 0; i < p->n; i++) {
    qk_world_pair_t q = qk__key_pair(w, p->v[i]);
    if (fn(q.a, q.b, ud)) break;
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
  if (which != QK_PAIRS_ALL && which != QK_PAIRS_BEGAN) return QK_ERR_INVALID;
  const qk__kvec_t *p = which == QK_PAIRS_ALL ? &w->cur : &w->began;
  *n_out = p->n;
  size_t m = p->n < cap ? p->n : cap;
  for (size_t i = 0; i < m; i++) out[i] = qk__key_pair(w, p->v[i]);
  return QK_OK;
}
