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

/* The rows over n_obj slots from their lengths ca (n keys in all): row and start of
 * every slot that has pairs; with cursors, ca[a] becomes row a's first place. 0 when
 * memory ran short. */
static int rows_index(const qk_allocator_t *al, qk__prows_t *r, uint32_t *ca, uint32_t n_obj,
                      size_t n, int cursors) {
  size_t nz = 0;
  for (uint32_t a = 0; a < n_obj; a++) nz += ca[a] != 0;
  if (!rows_alloc(al, r, nz)) return 0;
  uint32_t sa = 0;
  nz = 0;
  for (uint32_t a = 0; a < n_obj; a++) {
    uint32_t c = ca[a];
    if (c) r->row[nz] = a, r->start[nz++] = sa;
    if (cursors) ca[a] = sa;
    sa += c;
  }
  r->start[nz] = (uint32_t)n;
  return 1;
}

/*
 * Many keys over many slots (from QK__BUCKET_MIN keys): the two counting sorts below
 * would each scatter through n_obj cursors over an array far larger than the caches.
 * Instead the keys are first put in buckets of 2^abits consecutive slots a (a few
 * hundred buckets: as many cursors as fit in cache), each key as 32 bits,
 * (a mod 2^abits) << bbits | b, in place in the rows' buffer: the buckets are ranges of
 * rows, so each lands where its rows will be. Each bucket (about 2^15 keys) is then
 * sorted alone, in cache, by an LSD radix sort of two digits on those 32 bits, into
 * the scratch and back, keeping only b. Used when abits + bbits fit 28 bits.
 */
#define QK__BUCKET_MIN ((size_t)1 << 20)

static int bucket_plan(size_t n, uint32_t n_obj, unsigned *abits, unsigned *bbits) {
  if (n < QK__BUCKET_MIN) return 0;
  unsigned bb = 1, ab = 0;
  while (bb < 32 && ((uint64_t)1 << bb) < n_obj) bb++;
  /* buckets of about 2^15 keys: 2^ab slots hold n 2^ab / n_obj keys */
  while (ab < 31 && ((uint64_t)n << (ab + 1)) <= ((uint64_t)n_obj << 15)) ab++;
  /* (the high digit, (ab + bb) / 2 bits, must hold a mod 2^ab whole) */
  if (ab < 4 || (ab + bb) / 2 < ab || ab + bb > 28) return 0;
  *abits = ab, *bbits = bb;
  return 1;
}

/* cnt: n_obj + 1 entries for the rows' counts, then the buckets' cursors and the two
 * digits' counts (see rows_cnt). */
static size_t rows_cnt(uint32_t n_obj, size_t n) {
  unsigned ab, bb;
  size_t c = 2 * ((size_t)n_obj + 1);
  if (!bucket_plan(n, n_obj, &ab, &bb)) return c;
  size_t more = ((size_t)n_obj >> ab) + 2 + ((size_t)2 << ((ab + bb + 1) / 2));
  return c > n_obj + 1 + more ? c : n_obj + 1 + more;
}

/* (Not inlined: inlined, its loops share the update's registers and spill.) */
__attribute__((noinline)) static int rows_buckets(const qk_allocator_t *al, const uint64_t *keys,
                                                  uint32_t *t32, size_t n, uint32_t *cnt,
                                                  uint32_t n_obj, unsigned ab, unsigned bb,
                                                  qk__prows_t *r) {
  const uint32_t W = (uint32_t)1 << ab, nbk = (uint32_t)(((uint64_t)n_obj + W - 1) >> ab);
  const unsigned d0 = (ab + bb + 1) / 2, d1 = ab + bb - d0; /* the two digits' bits */
  const uint32_t m0 = ((uint32_t)1 << d0) - 1, bmask = ((uint32_t)1 << bb) - 1;
  /* ca: the rows' counts (filled bucket by bucket); bc: the buckets' starts, then their
   * cursors; c0, c1: the digits' counts. */
  uint32_t *ca = cnt, *bc = ca + n_obj + 1, *c0 = bc + nbk + 1, *c1 = c0 + m0 + 1;
  uint32_t *rb = r->b;
  memset(bc, 0, ((size_t)nbk + 1) * sizeof *bc);
  for (size_t i = 0; i < n; i++) bc[(uint32_t)(keys[i] >> 32) >> ab]++;
  for (uint32_t k = 0, s = 0; k <= nbk; k++) {
    uint32_t c = bc[k];
    bc[k] = s, s += c;
  }
  /* The buckets, in place: bucket k's keys at rb[bc[k] ..), cursors in bc. */
  const uint32_t bmul = bmask + 1; /* (a mod W) << bb as a product: one shift by ab left */
  for (size_t i = 0; i < n; i++) {
    uint64_t k = keys[i];
    uint32_t a = (uint32_t)(k >> 32);
    rb[bc[a >> ab]++] = (a & (W - 1)) * bmul | (uint32_t)k;
  }
  /* bc[k] is now bucket k's end, where k + 1's starts. Each bucket sorted by its low
   * digit into t32, then by its high digit, (a mod W) and the top of b, back into rb.
   * The high digit's counts give the rows' lengths: slot a's are those of its
   * 2^(d1 - ab) digits. */
  const unsigned sh = d1 - ab;
  for (uint32_t k = 0, lo = 0; k < nbk; lo = bc[k], k++) {
    uint32_t m = bc[k] - lo, *src = rb + lo, a0 = k << ab;
    uint32_t na = n_obj - a0 < W ? n_obj - a0 : W;
    memset(c0, 0, (((size_t)1 << d0) + ((size_t)1 << d1)) * sizeof *c0);
    for (uint32_t i = 0; i < m; i++) {
      uint32_t v = src[i];
      c0[v & m0]++, c1[v >> d0]++;
    }
    for (uint32_t s0 = 0, j = 0; j <= m0; j++) {
      uint32_t x = c0[j];
      c0[j] = s0, s0 += x;
    }
    for (uint32_t s1 = 0, j = 0, a = 0; a < na; a++) {
      uint32_t from = s1;
      for (uint32_t je = (a + 1) << sh; j < je; j++) {
        uint32_t x = c1[j];
        c1[j] = s1, s1 += x;
      }
      ca[a0 + a] = s1 - from;
    }
    for (uint32_t i = 0; i < m; i++) {
      uint32_t v = src[i];
      t32[c0[v & m0]++] = v;
    }
    for (uint32_t i = 0; i < m; i++) {
      uint32_t v = t32[i];
      src[c1[v >> d0]++] = v & bmask;
    }
  }
  return rows_index(al, r, ca, n_obj, n, 0);
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
  uint32_t *t32 = (uint32_t *)tmp;
  unsigned abits, bbits;
  if (bucket_plan(n, n_obj, &abits, &bbits)) {
    return rows_buckets(al, keys, t32, n, cnt, n_obj, abits, bbits, r);
  }
  /* cb[b + 1] counts slot b, then cb[b] is the scatter's cursor; ca[a] counts a, then
   * is row a's cursor. The first scatter writes only slot a (4 bytes), at b's place:
   * b is known from the place in the second. */
  uint32_t *cb = cnt, *ca = cnt + n_obj + 1;
  memset(cnt, 0, 2 * ((size_t)n_obj + 1) * sizeof *cnt);
  for (size_t i = 0; i < n; i++) {
    uint64_t k = keys[i];
    cb[(uint32_t)k + 1]++;
    ca[k >> 32]++;
  }
  for (uint32_t a = 1; a <= n_obj; a++) cb[a] += cb[a - 1];
  if (!rows_index(al, r, ca, n_obj, n, 1)) return 0;
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

/*
 * The dense frame (many pairs) on the world's threads: the rows and began / ended in
 * one go. The keys are split into nt chunks, each counted by slot a (cnt: a count array
 * per chunk), the counts made into each chunk's cursors per row (by slot ranges), and
 * the chunks scattered (only b) into their rows, unsorted. Then each thread takes a
 * range of rows (about n / nt pairs) and builds every row from the last frame's, which
 * is sorted (row_build: stamps per slot, the new slots that began sorted and put in by
 * bisection). Each thread's began and ended lists are in key order and the ranges
 * ascend, so the lists are joined in range order: the result is the same on any number
 * of threads, and the same as the one-thread path's (make_rows and diff). On one thread
 * that path is used: measured, it costs fewer instructions (the SSE row merge makes the
 * pairs that stayed cheap there), so this one pays only when split.
 */
#define QK__RMAX 64 /* = QK__MAX_THREADS */
typedef struct rjob {
  const qk_world_t *w;
  const qk__prows_t *o; /* the last frame's rows */
  qk__prows_t *r;       /* the new rows (b filled by the scatter) */
  const uint64_t *keys;
  size_t n;
  uint32_t n_obj;
  unsigned nt;
  int dirty, phase, nomem[QK__RMAX];
  uint32_t *cnt;  /* nt (n_obj + 1): per chunk, counts then cursors */
  uint32_t *st;   /* n_obj + 1: row a's pairs at rb[st[a] .. st[a + 1]) */
  uint32_t *mark; /* nt n_obj stamps, zero at first */
  uint32_t stamp[QK__RMAX];
  uint32_t *scr;                         /* per thread 2 maxlen slots */
  size_t rs[QK__RMAX + 1];               /* pairs per slot range, then their prefix */
  uint32_t pr[QK__RMAX + 1];             /* the threads' row ranges */
  size_t nz[QK__RMAX + 1], mx[QK__RMAX]; /* rows with pairs (then prefix), longest */
  size_t scr_off[QK__RMAX + 1];
  qk__kvec_t bv[QK__RMAX], ev[QK__RMAX];
} rjob_t;

static int cmp_u32(const void *x, const void *y) {
  uint32_t a = *(const uint32_t *)x, b = *(const uint32_t *)y;
  return (a > b) - (a < b);
}

static void sort_small(uint32_t *g, size_t n) {
  if (n > 24) {
    qsort(g, n, sizeof *g, cmp_u32);
    return;
  }
  for (size_t i = 1; i < n; i++) {
    uint32_t v = g[i];
    size_t j = i;
    for (; j > 0 && g[j - 1] > v; j--) g[j] = g[j - 1];
    g[j] = v;
  }
}

/* Build row a (n new slots at nb, unsorted; the old row ob of m slots, sorted) in place,
 * adding its began and ended pairs; 0 when memory ran short. The old row's slots are
 * stamped v (a stamp used once), those found in the new row then v + 1 (stayed); the
 * others of the new row began, and the old ones still at v ended. */
static int row_build(rjob_t *J, unsigned t, uint32_t a, uint32_t *nb, size_t n, const uint32_t *ob,
                     size_t m) {
  const qk_world_t *w = J->w;
  const qk_allocator_t *al = &w->alloc;
  uint32_t *mk = J->mark + (size_t)t * J->n_obj;
  uint32_t *S = J->scr + J->scr_off[t], *G = S + J->mx[t];
  qk__kvec_t *bv = &J->bv[t], *ev = &J->ev[t];
  uint64_t ka = (uint64_t)a << 32;
  int dirty = J->dirty, ch_a = dirty && changed(w, a);
  if (J->stamp[t] >= UINT32_MAX - 2) { /* (the stamps wrapped: start again) */
    memset(mk, 0, (size_t)J->n_obj * sizeof *mk);
    J->stamp[t] = 0;
  }
  uint32_t v = J->stamp[t] + 1, v1 = v + 1;
  J->stamp[t] = v1;
  for (size_t j = 0; j < m; j++) mk[ob[j]] = v;
  size_t ns = 0, ng = 0;
  for (size_t i = 0; i < n; i++) {
    uint32_t x = nb[i];
    if (mk[x] == v)
      mk[x] = v1, ns++;
    else
      G[ng++] = x;
  }
  const uint32_t *base = m ? ob : S; /* (S: never NULL) */
  if (ns != m || dirty) {            /* some ended: the stayed ones, in order */
    ns = 0;
    for (size_t j = 0; j < m; j++) {
      uint32_t y = ob[j];
      if (mk[y] == v1) {
        S[ns++] = y;
        if (dirty && (ch_a || changed(w, y)) && !kv_add(al, ev, ka | y)) return 0;
      } else if (!kv_add(al, ev, ka | y)) {
        return 0;
      }
    }
    base = S;
  }
  sort_small(G, ng);
  if (!dirty) {
    /* The began slots go in between runs of the stayed ones, found by bisection. */
    size_t i = 0, k = 0;
    for (size_t j = 0; j < ng; j++) {
      uint32_t x = G[j];
      size_t lo = i, hi = ns;
      while (lo < hi) {
        size_t mid = lo + (hi - lo) / 2;
        if (base[mid] < x)
          lo = mid + 1;
        else
          hi = mid;
      }
      memcpy(nb + k, base + i, (lo - i) * sizeof *nb);
      k += lo - i, i = lo;
      nb[k++] = x;
      if (!kv_add(al, bv, ka | x)) return 0;
    }
    memcpy(nb + k, base + i, (ns - i) * sizeof *nb);
    return 1;
  }
  size_t i = 0, j = 0, k = 0;
  while (i < ns || j < ng) {
    if (j == ng || (i < ns && S[i] < G[j])) {
      uint32_t y = S[i++];
      nb[k++] = y;
      if ((ch_a || changed(w, y)) && !kv_add(al, bv, ka | y)) return 0;
    } else {
      uint32_t x = G[j++];
      nb[k++] = x;
      if (!kv_add(al, bv, ka | x)) return 0;
    }
  }
  return 1;
}

static void rjob_run(unsigned t, void *ud) {
  rjob_t *J = ud;
  uint32_t n_obj = J->n_obj, *c = J->cnt + (size_t)t * (n_obj + 1);
  size_t k0 = J->n * t / J->nt, k1 = J->n * (t + 1) / J->nt;
  uint32_t s0 = (uint32_t)((uint64_t)n_obj * t / J->nt);
  uint32_t s1 = (uint32_t)((uint64_t)n_obj * (t + 1) / J->nt);
  unsigned nt = J->nt;
  size_t stride = (size_t)n_obj + 1;
  switch (J->phase) {
  case 0: /* count the chunk's keys by slot a (and clear the thread's stamps) */
    memset(J->mark + (size_t)t * n_obj, 0, (size_t)n_obj * sizeof *J->mark);
    memset(c, 0, stride * sizeof *c);
    for (const uint64_t *k = J->keys + k0, *e = J->keys + k1; k < e; k++) c[*k >> 32]++;
    break;
  case 1: { /* the slot range's pairs */
    size_t s = 0;
    for (unsigned u = 0; u < nt; u++)
      for (uint32_t a = s0; a < s1; a++) s += J->cnt[u * stride + a];
    J->rs[t] = s;
    break;
  }
  case 2: { /* row starts and the chunks' cursors */
    uint32_t base = (uint32_t)J->rs[t];
    for (uint32_t a = s0; a < s1; a++) {
      J->st[a] = base;
      for (unsigned u = 0; u < nt; u++) {
        uint32_t *p = &J->cnt[u * stride + a], q = *p;
        *p = base, base += q;
      }
    }
    break;
  }
  case 3: { /* scatter the chunk's b into the rows; then the row range's rows with
             * pairs, and its longest */
    uint32_t *rb = J->r->b;
    for (const uint64_t *k = J->keys + k0, *e = J->keys + k1; k < e; k++)
      rb[c[*k >> 32]++] = (uint32_t)*k;
    size_t nz = 0, mx = 0;
    for (uint32_t a = J->pr[t]; a < J->pr[t + 1]; a++) {
      size_t l = J->st[a + 1] - J->st[a];
      nz += l != 0, mx = l > mx ? l : mx;
    }
    J->nz[t] = nz;
    J->mx[t] = mx;
    break;
  }
  default: { /* build the rows */
    const qk__prows_t *o = J->o;
    qk__prows_t *r = J->r;
    size_t q = 0, hi = o->n_nz, z = J->nz[t];
    while (q < hi) { /* the first old row at or after the range */
      size_t mid = q + (hi - q) / 2;
      if (o->row[mid] < J->pr[t])
        q = mid + 1;
      else
        hi = mid;
    }
    for (uint32_t a = J->pr[t]; a < J->pr[t + 1]; a++) {
      size_t n = J->st[a + 1] - J->st[a], m = 0;
      const uint32_t *ob = NULL;
      if (q < o->n_nz && o->row[q] == a)
        ob = o->b + o->start[q], m = o->start[q + 1] - o->start[q], q++;
      if (!n && !m) continue;
      if (n) r->row[z] = a, r->start[z++] = J->st[a];
      if (!row_build(J, t, a, r->b + J->st[a], n, ob, m)) {
        J->nomem[t] = 1;
        return;
      }
    }
  }
  }
}

static void rjob_phase(rjob_t *J, int ph) {
  J->phase = ph;
  qk__run_jobs(J->nt, J->nt, rjob_run, J);
}

/* Rows, began and ended for the dense case; QK_ERR_NOMEM leaves nothing allocated in
 * *r, *bv, *ev. */
static int rows_frame(const qk_world_t *w, const uint64_t *keys, size_t n, qk__prows_t *r,
                      int dirty, qk__kvec_t *bvo, qk__kvec_t *evo) {
  const qk_allocator_t *al = &w->alloc;
  uint32_t n_obj = w->n_obj;
  unsigned nt = qk__world_update_threads(w);
  if (nt < 1 || w->n_live < 4096) nt = 1;
  if (nt > QK__RMAX) nt = QK__RMAX;
  rjob_t *J = qk__realloc(al, NULL, 0, sizeof *J);
  if (!J) return 0;
  memset(J, 0, sizeof *J);
  J->w = w, J->o = &w->cur, J->r = r, J->keys = keys, J->n = n, J->n_obj = n_obj, J->nt = nt;
  J->dirty = dirty;
  size_t stride = (size_t)n_obj + 1, cbytes = nt * stride * sizeof *J->cnt;
  size_t mbytes = (size_t)nt * n_obj * sizeof *J->mark, sbytes = stride * sizeof *J->st, scn = 0;
  int ok = 0;
  J->cnt = qk__realloc(al, NULL, 0, cbytes);
  J->st = J->cnt ? qk__realloc(al, NULL, 0, sbytes) : NULL;
  J->mark = J->st ? qk__realloc(al, NULL, 0, mbytes ? mbytes : 1) : NULL;
  if (!J->mark) goto out;
  rjob_phase(J, 0);
  rjob_phase(J, 1);
  size_t acc = 0;
  for (unsigned t = 0; t < nt; t++) {
    size_t s = J->rs[t];
    J->rs[t] = acc, acc += s;
  }
  rjob_phase(J, 2);
  J->st[n_obj] = (uint32_t)n;
  /* Row ranges of about n / nt pairs each. */
  J->pr[0] = 0, J->pr[nt] = n_obj;
  for (unsigned t = 1; t < nt; t++) {
    size_t want = n * t / nt;
    uint32_t lo = J->pr[t - 1], hi = n_obj;
    while (lo < hi) {
      uint32_t mid = lo + (hi - lo) / 2;
      if (J->st[mid] < want)
        lo = mid + 1;
      else
        hi = mid;
    }
    J->pr[t] = lo;
  }
  rjob_phase(J, 3);
  size_t nz = 0;
  for (unsigned t = 0; t < nt; t++) {
    size_t c = J->nz[t];
    J->nz[t] = nz, nz += c;
    J->scr_off[t] = scn, scn += 2 * J->mx[t];
  }
  J->scr = qk__realloc(al, NULL, 0, (scn ? scn : 1) * sizeof *J->scr);
  if (!J->scr || !rows_alloc(al, r, nz)) goto out;
  r->n = n;
  r->start[nz] = (uint32_t)n;
  for (unsigned t = 0; t < nt; t++) {
    size_t bc = w->began.n / nt + 64, ec = w->ended.n / nt + 64;
    if (!(J->bv[t].v = qk__realloc(al, NULL, 0, bc * sizeof(uint64_t)))) goto out;
    J->bv[t].cap = bc;
    if (!(J->ev[t].v = qk__realloc(al, NULL, 0, ec * sizeof(uint64_t)))) goto out;
    J->ev[t].cap = ec;
  }
  rjob_phase(J, 4);
  for (unsigned t = 0; t < nt; t++)
    if (J->nomem[t]) goto out;
  /* Thread 0's lists take the others'. */
  for (int which = 0; which < 2; which++) {
    qk__kvec_t *v = which ? J->ev : J->bv;
    size_t tot = 0;
    for (unsigned t = 0; t < nt; t++) tot += v[t].n;
    if (tot > v[0].cap) {
      uint64_t *p = qk__realloc(al, v[0].v, v[0].cap * sizeof *p, tot * sizeof *p);
      if (!p) goto out;
      v[0].v = p, v[0].cap = tot;
    }
    for (unsigned t = 1; t < nt; t++) {
      if (v[t].n) memcpy(v[0].v + v[0].n, v[t].v, v[t].n * sizeof *v[t].v);
      v[0].n += v[t].n;
    }
  }
  *bvo = J->bv[0], *evo = J->ev[0];
  J->bv[0] = J->ev[0] = (qk__kvec_t){0};
  ok = 1;
out:
  for (unsigned t = 0; t < nt; t++) {
    qk__free(al, J->bv[t].v, J->bv[t].cap * sizeof(uint64_t));
    qk__free(al, J->ev[t].v, J->ev[t].cap * sizeof(uint64_t));
  }
  if (!ok && r->row) qk__free(al, r->row, 2 * (r->n_nz + 1) * sizeof *r->row), r->row = NULL;
  qk__free(al, J->scr, (scn ? scn : 1) * sizeof *J->scr);
  qk__free(al, J->mark, mbytes ? mbytes : 1);
  qk__free(al, J->st, sbytes);
  qk__free(al, J->cnt, cbytes);
  qk__free(al, J, sizeof *J);
  return ok;
}

/*
 * Scratch kept between updates. A dense frame's buffers are large (the search's keys, 8
 * bytes a pair, the sort's scratch, 4, the new rows, 4: 150 MB a frame for the 9.5 M
 * pairs of 10^5 clustered boxes), and an allocator hands out buffers that large as fresh
 * pages from the system (glibc: from 32 MB always), each page faulted in and zeroed every
 * frame: measured, a quarter of such a frame's time went to the kernel. So buffers from
 * QK__KEEP_BYTES on are kept for the next update: the keys' buffer (grown to hold the
 * sort's scratch after the keys), and the rows' buffer of the last frame once the new
 * rows replace it (the next rows are built in it). Smaller ones are freed, as the
 * allocator recycles them cheaply. A kept buffer more than twice what its frame used is
 * freed (the next frame allocates afresh).
 */
#define QK__KEEP_BYTES ((size_t)8 << 20)

/* The rule for every kept buffer: cap elements of elem bytes are kept for a frame that
 * uses `used` of them when they are at least QK__KEEP_BYTES and at most twice that. */
static inline int keep_buf(size_t cap, size_t used, size_t elem) {
  return cap * elem >= QK__KEEP_BYTES && cap <= 2 * used;
}

static void keep_keys(qk_world_t *w, qk__kvec_t *found, size_t total) {
  const qk_allocator_t *al = &w->alloc;
  size_t want = total + total / 2 + total / 8 + 64; /* keys, the sort's scratch, some room */
  if (keep_buf(found->cap > want ? found->cap : want, want, sizeof *found->v)) {
    if (found->cap < want) { /* (its keys are no longer needed: no copy) */
      qk__free(al, found->v, found->cap * sizeof *found->v);
      found->v = qk__realloc(al, NULL, 0, want * sizeof *found->v);
      found->cap = found->v ? want : 0;
    }
    w->scr_keys = (qk__kvec_t){found->v, 0, found->cap};
  } else {
    qk__free(al, found->v, found->cap * sizeof *found->v);
  }
  *found = (qk__kvec_t){0};
}

/* The current rows are replaced: their pair buffer is kept as the next rows' when large. */
static void keep_rows(qk_world_t *w) {
  const qk_allocator_t *al = &w->alloc;
  qk__free(al, w->spare_b, w->cap_spare_b * sizeof *w->spare_b);
  w->spare_b = NULL, w->cap_spare_b = 0;
  if (keep_buf(w->cur.cap, w->cur.n, sizeof *w->cur.b)) {
    w->spare_b = w->cur.b, w->cap_spare_b = w->cur.cap;
    w->cur.b = NULL, w->cur.cap = 0;
  }
  rows_free(al, &w->cur);
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
  /* The search starts in the kept keys buffer (the world holds none while it runs). */
  qk__kvec_t found = w->scr_keys, tk[QK__KEEP_THREADS];
  w->scr_keys = (qk__kvec_t){0};
  memcpy(tk, w->scr_tkeys, sizeof tk);
  memset(w->scr_tkeys, 0, sizeof w->scr_tkeys);
  qk_status_t st = qk__world_search(w, &pk, &found, tk);
  qk__world_pack_free(w, &pk);
  /* The other threads' buffers are kept when large (as the first's: see keep_keys). */
  for (unsigned t = 0; t < QK__KEEP_THREADS; t++) {
    if (keep_buf(tk[t].cap, tk[t].n + 32, sizeof *tk[t].v))
      w->scr_tkeys[t] = tk[t], w->scr_tkeys[t].n = 0;
    else
      qk__free(al, tk[t].v, tk[t].cap * sizeof *tk[t].v);
  }
  if (st != QK_OK) return st;
  if (found.n > UINT32_MAX) { /* (rows and counts hold 32-bit positions) */
    qk__free(al, found.v, found.cap * sizeof *found.v);
    return QK_ERR_LIMIT;
  }
  /* Everything else the update needs, before anything changes: the new rows and the
   * began and ended lists (sized by the last frame's, grown as needed): a failure keeps
   * the last frame's lists. */
  size_t total = found.n, n_obj = w->n_obj, tcap = total ? total : 1;
  int dirty = w->ident_dirty, ok = 0;
  qk__prows_t nr = {0};
  qk__kvec_t bv = {0}, ev = {0};
  /* The new rows go in the buffer of the frame before last when it is large enough
   * (and not much larger), else in a new one with some room (frames are alike). */
  if (w->spare_b && w->cap_spare_b >= tcap && keep_buf(w->cap_spare_b, tcap, sizeof *nr.b)) {
    nr.b = w->spare_b, nr.cap = w->cap_spare_b;
    w->spare_b = NULL, w->cap_spare_b = 0;
  } else {
    size_t c = tcap * sizeof *nr.b >= QK__KEEP_BYTES ? tcap + tcap / 8 + 64 : tcap;
    if ((nr.b = qk__realloc(al, NULL, 0, c * sizeof *nr.b))) nr.cap = c;
  }
  unsigned nt = w->n_live < 4096 ? 1 : qk__world_update_threads(w);
  unsigned bk_a, bk_b; /* (unused: whether the bucketed sort applies) */
  if (nr.b && total * 4 >= n_obj && nt > 1 && !bucket_plan(total, (uint32_t)n_obj, &bk_a, &bk_b)) {
    /* dense, on threads: rows and began / ended in one go. From 2^20 pairs the
     * one-thread bucketed sort below is faster than this path's scatter through one
     * cursor a slot (clustered 10^5: 369k objects/s on one thread against 341k on two
     * this way), so a threaded world takes it there too. */
    ok = rows_frame(w, found.v, total, &nr, dirty, &bv, &ev);
  } else if (nr.b) {
    /* one thread, or sparse: the keys sorted into rows, then merged with the last
     * frame's */
    size_t ccap = total * 4 < n_obj ? 257 : rows_cnt((uint32_t)n_obj, total);
    /* (the dense sort's scratch holds 32-bit slots, the sparse one's keys) */
    size_t tbytes = (total * 4 < n_obj ? sizeof(uint64_t) : sizeof(uint32_t)) * tcap;
    /* The dense sort's scratch goes after the keys when their buffer has the room (it is
     * given the room when it is kept: see keep_keys). */
    int in_keys = total * 4 >= n_obj && (found.cap - total) * sizeof *found.v >= tbytes;
    uint64_t *tmp = in_keys ? found.v + total : qk__realloc(al, NULL, 0, tbytes);
    uint32_t *cnt = tmp ? qk__realloc(al, NULL, 0, ccap * sizeof *cnt) : NULL;
    ok = cnt && make_rows(al, found.v, tmp, total, cnt, (uint32_t)n_obj, &nr);
    qk__free(al, cnt, ccap * sizeof *cnt);
    if (!in_keys) qk__free(al, tmp, tbytes);
    /* The lists start with room for the last frame's counts and some (frames are
     * alike), and grow if need be. */
    size_t bcap = w->began.n + w->began.n / 4 + 64, ecap = w->ended.n + w->ended.n / 4 + 64;
    if (ok && (bv.v = qk__realloc(al, NULL, 0, bcap * sizeof *bv.v))) bv.cap = bcap;
    if (bv.v && (ev.v = qk__realloc(al, NULL, 0, ecap * sizeof *ev.v))) ev.cap = ecap;
    ok = ev.v && diff(w, &w->cur, &nr, dirty, &bv, &ev);
  }
  if (ok) w->last_found = total;
  keep_keys(w, &found, total);
  size_t n_eg = 0;
  if (dirty)
    for (uint32_t i = 0; i < w->n_obj; i++) n_eg += w->obj[i].gen != w->ugen[i];
  uint64_t *eg = NULL;
  if (!ok || (n_eg && !(eg = qk__realloc(al, NULL, 0, n_eg * sizeof *eg)))) {
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
  keep_rows(w);
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
