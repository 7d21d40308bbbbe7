/*
 * The world's frame (see collide/world.c for the design): the order brought up to date
 * (collide/world_grid.c), all overlapping pairs found (collide/world_search.c) and
 * sorted into rows (one per slot that has pairs), and the began / ended sets by merging
 * them with the previous frame's.
 */
#include <assert.h>
#include <stdlib.h>
#include <string.h>

#include "collide/world_internal.h"
#include "index/inline.h"

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

/* Append src's keys to v. 0 when memory ran short (v's keys as they were). */
static int kv_append(const qk_allocator_t *a, qk__kvec_t *v, const qk__kvec_t *src) {
  if (v->n + src->n > v->cap) {
    size_t cap = v->n + src->n > 2 * v->cap ? v->n + src->n : 2 * v->cap;
    uint64_t *p = qk__realloc(a, v->v, v->cap * sizeof *p, cap * sizeof *p);
    if (!p) return 0;
    v->v = p, v->cap = cap;
  }
  if (src->n) memcpy(v->v + v->n, src->v, src->n * sizeof *v->v);
  v->n += src->n;
  return 1;
}

/* Whether two float boxes by slot (xmin, ymin, -xmax, -ymax) meet (closed). */
static inline int fboxes_meet(const float *a, const float *b) {
  return b[0] <= -a[2] && b[1] <= -a[3] && b[2] <= -a[0] && b[3] <= -a[1];
}

static void rows_free(const qk_allocator_t *a, qk__prows_t *r) {
  qk__free(a, qk__prows_block(r), qk__prows_room(r) * sizeof *r->b);
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

/* The rows over n_obj slots from a0 on from their lengths ca (ca[a] for slot a0 + a; n
 * keys in all): row and start of every slot that has pairs; with cursors, ca[a] becomes
 * its row's first place. 0 when memory ran short. */
static QK__ALWAYS_INLINE int rows_fill(const qk_allocator_t *al, qk__prows_t *r, uint32_t *ca,
                                       uint32_t a0, uint32_t n_obj, size_t n, int cursors,
                                       size_t nz) {
  if (!rows_alloc(al, r, nz)) return 0;
  uint32_t sa = 0;
  nz = 0;
  /* Every slot writes its row and start at the next place, which only a slot with pairs
   * keeps (no branch: in the uniform scene a quarter of the slots, at random, have no
   * pairs, and the branch on it was mispredicted that often). The writes stay within
   * row[0 .. nz] and start[0 .. nz], and start[nz] is set after. */
  for (uint32_t a = 0; a < n_obj; a++) {
    uint32_t c = ca[a];
    r->row[nz] = a0 + a, r->start[nz] = sa;
    nz += c != 0;
    if (cursors) ca[a] = sa;
    sa += c;
  }
  r->start[nz] = (uint32_t)n;
  return 1;
}
static int rows_index(const qk_allocator_t *al, qk__prows_t *r, uint32_t *ca, uint32_t a0,
                      uint32_t n_obj, size_t n, int cursors) {
  size_t nz = 0;
  for (uint32_t a = 0; a < n_obj; a++) nz += ca[a] != 0;
  return rows_fill(al, r, ca, a0, n_obj, n, cursors, nz);
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

/*
 * Many keys over very many slots, where bucket_plan's 32-bit keys do not fit (10^6 slots:
 * b takes 20 bits): the two counting sorts would scatter through two arrays of a count a
 * slot (4 MB each) and the keys at random, several misses of the caches a key (a quarter
 * of the frame of the benchmark's uniform scene at 10^6 objects). Instead the keys are
 * sorted whole (sort_wide): put in buckets of 2^ab consecutive slots a (at most 1024
 * buckets: as many cursors as stay in cache), then each bucket, in cache, by an LSD radix
 * sort on b and then a mod 2^ab; the rows are then read off the sorted keys, as the
 * sparse sort's are. From QK__WIDE_SLOTS slots (two counts a slot no longer fit a
 * core's L2).
 */
#define QK__WIDE_SLOTS ((uint32_t)1 << 17)

static int rows_wide(size_t n, uint32_t n_b) {
  unsigned ab, bb;
  return n * 4 >= n_b && n_b >= QK__WIDE_SLOTS && !bucket_plan(n, n_b, &ab, &bb);
}

/* The bucket plan's digits: d0 and d1 bits, the low digit's mask, b's mask. */
typedef struct bdig {
  unsigned ab, bb, d0, d1, sh;
  uint32_t m0, bmask;
} bdig_t;

static bdig_t bucket_digits(unsigned ab, unsigned bb) {
  bdig_t g;
  g.ab = ab, g.bb = bb;
  g.d0 = (ab + bb + 1) / 2, g.d1 = ab + bb - g.d0;
  g.m0 = ((uint32_t)1 << g.d0) - 1, g.bmask = ((uint32_t)1 << bb) - 1;
  g.sh = g.d1 - ab;
  return g;
}

/* x, which the compiler may no longer take for a constant: 2^bb stays a multiplier (one
 * instruction, any register) instead of becoming a shift by a variable count, which on
 * x86 takes the cl register from the other shift of the loop (measured: 15 -> 12
 * instructions a key in the bucket scatter). */
static inline uint32_t opaque_u32(uint32_t x) {
#if defined(__GNUC__)
  __asm__("" : "+r"(x));
#endif
  return x;
}

/* The counts c[0 .. n) (n a multiple of 4) replaced by their exclusive prefix sums, four
 * at a time (the buckets' digits have about one count for two keys: a scalar scan was
 * 8 instructions a count, some 3 a key). */
static void excl_scan(uint32_t *c, size_t n) {
#if defined(__SSE2__)
  __m128i carry = _mm_setzero_si128();
  for (size_t j = 0; j < n; j += 4) {
    __m128i x = _mm_loadu_si128((const __m128i *)(c + j));
    x = _mm_add_epi32(x, _mm_slli_si128(x, 4));
    x = _mm_add_epi32(x, _mm_slli_si128(x, 8)); /* inclusive within the four */
    _mm_storeu_si128((__m128i *)(c + j), _mm_add_epi32(_mm_slli_si128(x, 4), carry));
    carry = _mm_shuffle_epi32(_mm_add_epi32(x, carry), 0xFF);
  }
#else
  for (uint32_t s = 0, j = 0; j < n; j++) {
    uint32_t x = c[j];
    c[j] = s, s += x;
  }
#endif
}

/* One stable counting pass of the m keys at src into dst by the digit (k >> sh) & mask
 * (k the key, sh < 64), through the counts c (mask + 1 entries, a multiple of four): a
 * pass of the sparse sort and of the wide one's buckets. */
static void key_pass(uint64_t *dst, const uint64_t *src, uint32_t m, unsigned sh, uint32_t mask,
                     uint32_t *c) {
  memset(c, 0, ((size_t)mask + 1) * sizeof *c);
  QK__UNROLL4
  for (uint32_t i = 0; i < m; i++) c[(src[i] >> sh) & mask]++;
  excl_scan(c, (size_t)mask + 1);
  QK__UNROLL4
  for (uint32_t i = 0; i < m; i++) dst[c[(src[i] >> sh) & mask]++] = src[i];
}

/* Buckets of fewer keys than this are sorted by insertion. */
#define QK__WIDE_SMALL 24

/* Sort the n keys (slots a and b below n_b) into key order, through tmp (n keys); cnt holds
 * the buckets' counts and one digit's (at most 1026 + max(2^11, 2^ab) entries, which
 * rows_cnt's 2 (n_b + 1) hold, n_b being at least QK__WIDE_SLOTS). The keys go into
 * buckets of 2^ab consecutive slots a (at most 1024 buckets: as many cursors as stay in
 * cache), then each bucket, in cache, by an LSD radix sort: slot b in digits of at most 11
 * bits, then a mod 2^ab. (Its rows were sorted by insertion after a counting sort on
 * a mod 2^ab before: rows of one or two keys in the uniform scene, whose lengths and order
 * the branches mispredicted.) Returns the number of rows (slots a with keys), counted
 * while each bucket is in cache. */
static size_t sort_wide(uint64_t *keys, uint64_t *tmp, size_t n, uint32_t n_b, uint32_t *cnt) {
  unsigned ab = 8, bb = 1;
  while (((uint64_t)n_b >> ab) > 1024) ab++;
  while (bb < 32 && ((uint64_t)1 << bb) < n_b) bb++;
  const unsigned np = (bb + 10) / 11, d = (bb + np - 1) / np; /* b's digits: np of d bits */
  const uint32_t nbk = (n_b >> ab) + 1, W = (uint32_t)1 << ab;
  uint32_t *bc = cnt, *c = cnt + nbk + 1;
  memset(bc, 0, ((size_t)nbk + 1) * sizeof *bc);
  QK__UNROLL4
  for (size_t i = 0; i < n; i++) bc[(keys[i] >> (32 + ab)) + 1]++;
  for (uint32_t k = 1; k <= nbk; k++) bc[k] += bc[k - 1];
  QK__UNROLL4
  for (size_t i = 0; i < n; i++) tmp[bc[keys[i] >> (32 + ab)]++] = keys[i];
  /* bc[k] is now bucket k's end, where k + 1's starts. */
  size_t nz = 0;
  for (uint32_t k = 0, lo = 0; k < nbk; lo = bc[k], k++) {
    const uint32_t m = bc[k] - lo;
    uint64_t *kb = keys + lo, *tb = tmp + lo;
    if (m < QK__WIDE_SMALL) {
      for (uint32_t j = 0; j < m; j++) {
        const uint64_t v = tb[j];
        uint32_t i = j;
        for (; i > 0 && kb[i - 1] > v; i--) kb[i] = kb[i - 1];
        kb[i] = v;
      }
    } else {
      /* b's digits, then a mod 2^ab: np + 1 passes between tb and kb, from tb */
      uint64_t *src = tb, *dst = kb;
      for (unsigned p = 0; p < np; p++) {
        key_pass(dst, src, m, p * d, ((uint32_t)1 << d) - 1, c);
        uint64_t *t = src;
        src = dst, dst = t;
      }
      key_pass(dst, src, m, 32, W - 1, c);
      if (dst != kb) memcpy(kb, dst, (size_t)m * sizeof *kb);
    }
    /* (a bucket's rows are its own: the first key starts one) */
    uint64_t last = m ? ~kb[0] : 0;
    for (uint32_t i = 0; i < m; i++) nz += kb[i] >> 32 != last >> 32, last = kb[i];
  }
  return nz;
}

/* One bucket (m keys at src, as (a mod W) << bb | b, for na slots from a0) sorted by its
 * low digit into t32, then by its high digit, (a mod W) and the top of b, back into src
 * keeping only b. The high digit's counts give the rows' lengths: slot a's are those of
 * its 2^(d1 - ab) digits, into ca[a - a0]. c0, c1: the digits' counts. */
static void bucket_sort(const bdig_t *g, uint32_t *src, uint32_t m, uint32_t na, uint32_t *t32,
                        uint32_t *c0, uint32_t *c1, uint32_t *ca) {
  const unsigned d0 = g->d0, sh = g->sh;
  const uint32_t m0 = g->m0, bmask = g->bmask;
  memset(c0, 0, (((size_t)1 << d0) + ((size_t)1 << g->d1)) * sizeof *c0);
  QK__UNROLL4
  for (uint32_t i = 0; i < m; i++) {
    uint32_t v = src[i];
    c0[v & m0]++, c1[v >> d0]++;
  }
  excl_scan(c0, (size_t)m0 + 1);
  /* (slots past na have no keys: their digits count 0) */
  const uint32_t n1 = (uint32_t)1 << g->d1;
  excl_scan(c1, n1);
  for (uint32_t a = 0; a < na; a++) {
    uint32_t j = a << sh, je = (a + 1) << sh;
    ca[a] = (je < n1 ? c1[je] : m) - c1[j];
  }
  QK__UNROLL4
  for (uint32_t i = 0; i < m; i++) {
    uint32_t v = src[i];
    t32[c0[v & m0]++] = v;
  }
  QK__UNROLL4
  for (uint32_t i = 0; i < m; i++) {
    uint32_t v = t32[i];
    src[c1[v >> d0]++] = v & bmask;
  }
}

/* (Not inlined: inlined, its loops share the update's registers and spill.) */
__attribute__((noinline)) static int rows_buckets(const qk_allocator_t *al, const uint64_t *keys,
                                                  uint32_t *t32, size_t n, uint32_t *cnt,
                                                  uint32_t n_obj, unsigned ab, unsigned bb,
                                                  qk__prows_t *r) {
  const bdig_t g = bucket_digits(ab, bb);
  const uint32_t W = (uint32_t)1 << ab, nbk = (uint32_t)(((uint64_t)n_obj + W - 1) >> ab);
  /* ca: the rows' counts (filled bucket by bucket); bc: the buckets' starts, then their
   * cursors; c0, c1: the digits' counts. */
  uint32_t *ca = cnt, *bc = ca + n_obj + 1, *c0 = bc + nbk + 1, *c1 = c0 + g.m0 + 1;
  uint32_t *rb = r->b;
  memset(bc, 0, ((size_t)nbk + 1) * sizeof *bc);
  QK__UNROLL4
  for (size_t i = 0; i < n; i++) bc[(uint32_t)(keys[i] >> 32) >> ab]++;
  for (uint32_t k = 0, s = 0; k <= nbk; k++) {
    uint32_t c = bc[k];
    bc[k] = s, s += c;
  }
  /* The buckets, in place: bucket k's keys at rb[bc[k] ..), cursors in bc. */
  /* (a mod W) << bb as a product: one shift by ab left */
  const uint32_t bmul = opaque_u32(g.bmask + 1);
  QK__UNROLL4
  for (size_t i = 0; i < n; i++) {
    uint64_t k = keys[i];
    uint32_t a = (uint32_t)(k >> 32);
    rb[bc[a >> ab]++] = (a & (W - 1)) * bmul | (uint32_t)k;
  }
  /* bc[k] is now bucket k's end, where k + 1's starts. */
  for (uint32_t k = 0, lo = 0; k < nbk; lo = bc[k], k++) {
    uint32_t a0 = k << ab, na = n_obj - a0 < W ? n_obj - a0 : W;
    bucket_sort(&g, rb + lo, bc[k] - lo, na, t32, c0, c1, ca + a0);
  }
  return rows_index(al, r, ca, 0, n_obj, n, 0);
}

/* The b counts' prefix over slots b (cb[b] becomes the first place of b's keys); with
 * `whole` (slots a and b the same range from 0, ca their counts), the count of rows in
 * the same pass over the slots, else 0. */
static QK__ALWAYS_INLINE size_t b_prefix(uint32_t *cb, const uint32_t *ca, uint32_t n_b,
                                         const int whole) {
  size_t nz = 0;
  for (uint32_t b = 1; b <= n_b; b++) {
    cb[b] += cb[b - 1];
    if (whole) nz += ca[b - 1] != 0;
  }
  return nz;
}

/*
 * The found keys (unsorted, n of them) as rows, each row ascending; 0 when memory ran
 * short. Slots a are in [a0, a0 + n_a), slots b below n_b; bucket: a0 = 0, n_a = n_b,
 * and cnt holds rows_cnt(n_b, n) entries, so that many keys may take rows_buckets. Many keys (at
 * least a quarter of the slots): two stable counting sorts, by slot b into tmp (as 32-bit slots a),
 * then by slot a, which writes only b into its row; both counts come from one read of the keys
 * (cnt: n_a + n_b + 2 entries). Few keys (a sparse world): an LSD radix sort of the keys on the
 * bytes that differ (cnt: 257 entries), so the passes cost the keys, not the slots, then the rows
 * from the sorted keys. tmp64: tmp holds n keys (else n 32-bit slots; the sparse sort's and the
 * wide one's callers give it n keys). With flat, the keys are left in key order in keys when the
 * sort makes them so at little cost (*flat = keys), as every sort but the buckets' does.
 */
static QK__ALWAYS_INLINE int make_rows(const qk_allocator_t *al, uint64_t *keys, uint64_t *tmp,
                                       size_t n, uint32_t *cnt, uint32_t a0, uint32_t n_a,
                                       uint32_t n_b, int bucket, const int whole, qk__prows_t *r,
                                       uint64_t **flat, const int tmp64) {
  uint32_t *rb = r->b;
  r->n = n;
  if (flat) *flat = NULL;
  /* (the wide sort with flat only, whose caller, update, sizes tmp for it; its slots are
   * every slot from 0) */
  const int wide = whole && flat && rows_wide(n, n_b);
  if (n * 4 < n_b || wide) {
    size_t nz = 0;
    if (wide) {
      nz = sort_wide(keys, tmp, n, n_b, cnt);
    } else {
      uint64_t all_or = 0, all_and = ~(uint64_t)0;
      for (size_t i = 0; i < n; i++) all_or |= keys[i], all_and &= keys[i];
      for (int sh = 0; n > 1 && sh < 64; sh += 8) {
        if (!(((all_or ^ all_and) >> sh) & 0xff)) continue;
        key_pass(tmp, keys, (uint32_t)n, (unsigned)sh, 0xff, cnt);
        memcpy(keys, tmp, n * sizeof *keys); /* the result stays in keys */
      }
      for (size_t i = 0; i < n; i++) nz += !i || keys[i] >> 32 != keys[i - 1] >> 32;
    }
    if (!rows_alloc(al, r, nz)) return 0;
    /* Every key writes a row and start at the next place, which only a row's first key
     * keeps (no branch: rows of one or two keys at random in the uniform scene; as
     * rows_fill). The writes stay within row[0 .. nz] and start[0 .. nz]. */
    nz = 0;
    uint64_t last = n ? ~keys[0] : 0; /* (the first key starts a row) */
    for (size_t i = 0; i < n; i++) {
      const uint64_t k = keys[i];
      r->row[nz] = (uint32_t)(k >> 32), r->start[nz] = (uint32_t)i;
      nz += k >> 32 != last >> 32;
      rb[i] = (uint32_t)k;
      last = k;
    }
    r->start[nz] = (uint32_t)n;
    if (flat) *flat = keys;
    return 1;
  }
  uint32_t *t32 = (uint32_t *)tmp;
  unsigned abits, bbits;
  if (bucket && bucket_plan(n, n_b, &abits, &bbits))
    return rows_buckets(al, keys, t32, n, cnt, n_b, abits, bbits, r);
  /* cb[b + 1] counts slot b, then cb[b] is the scatter's cursor; ca[a] counts a, then
   * is row a's cursor. The first scatter writes only slot a (4 bytes), at b's place:
   * b is known from the place in the second. */
  uint32_t *cb = cnt, *ca = cnt + n_b + 1;
  memset(cnt, 0, ((size_t)n_a + n_b + 2) * sizeof *cnt);
  QK__UNROLL4
  for (size_t i = 0; i < n; i++) {
    uint64_t k = keys[i];
    cb[(uint32_t)k + 1]++;
    ca[(k >> 32) - a0]++;
  }
  size_t nz = b_prefix(cb, ca, n_b, whole);
  if (!whole)
    for (uint32_t a = 0; a < n_a; a++) nz += ca[a] != 0;
  if (!rows_fill(al, r, ca, a0, n_a, n, 1, nz)) return 0;
  /* When a - a0 and b fit 32 bits together (up to 2^16 slots), the first scatter writes
   * both, (a - a0) << bb | b, and the second reads b there: one plain loop over the keys
   * (measured: 27.5 -> 10.8 instructions an object on the uniform scene at 10^4, whose
   * 1.5 keys a slot b made the loop over the slots b with a short inner loop each cost
   * more than its keys). */
  unsigned bb = 0;
  while (bb < 32 && ((uint64_t)1 << bb) < n_b) bb++;
  if (bb < 32 && ((uint64_t)(n_a - 1) >> (32 - bb)) == 0) {
    const uint32_t bm = (uint32_t)(((uint64_t)1 << bb) - 1);
    QK__UNROLL4
    for (size_t i = 0; i < n; i++) {
      uint64_t k = keys[i];
      t32[cb[(uint32_t)k]++] = ((uint32_t)(k >> 32) - a0) << bb | (uint32_t)k;
    }
    if (flat) {
      /* (the keys, read by the first scatter only, become the rows' keys in order) */
      QK__UNROLL4
      for (size_t i = 0; i < n; i++) {
        uint32_t x = t32[i], a = x >> bb, p = ca[a]++;
        rb[p] = x & bm;
        keys[p] = (uint64_t)(a + a0) << 32 | (x & bm);
      }
      *flat = keys;
      return 1;
    }
    QK__UNROLL4
    for (size_t i = 0; i < n; i++) {
      uint32_t x = t32[i];
      rb[ca[x >> bb]++] = x & bm;
    }
    return 1;
  }
  /* Else, with room for the keys in tmp, the keys themselves go there by slot b, and the
   * second sort reads each key's a and b in one plain loop. (The 32-bit form, a at b's
   * place, leaves b to be known from the place: a loop over the slots b with a short inner
   * loop each, whose exits were mispredicted at about every slot; measured on the uniform
   * scene at 10^5 objects, 1.5 keys a slot: the rows 1.89-2.01 -> 1.55-1.73 ms a frame.) */
  if (tmp64) {
    QK__UNROLL4
    for (size_t i = 0; i < n; i++) {
      const uint64_t k = keys[i];
      tmp[cb[(uint32_t)k]++] = k;
    }
    if (flat) {
      QK__UNROLL4
      for (size_t i = 0; i < n; i++) {
        const uint64_t k = tmp[i];
        const uint32_t p = ca[(uint32_t)(k >> 32) - a0]++;
        rb[p] = (uint32_t)k;
        keys[p] = k;
      }
      *flat = keys;
      return 1;
    }
    QK__UNROLL4
    for (size_t i = 0; i < n; i++) {
      const uint64_t k = tmp[i];
      rb[ca[(uint32_t)(k >> 32) - a0]++] = (uint32_t)k;
    }
    return 1;
  }
  QK__UNROLL4
  for (size_t i = 0; i < n; i++) t32[cb[(uint32_t)keys[i]]++] = (uint32_t)(keys[i] >> 32) - a0;
  /* cb[b] is now the end of b's run, where b + 1's starts. */
  size_t i = 0;
  if (flat) {
    /* (as above: the keys in order too, one store more a key; measured on the uniform
     * scene at 10^5, whose merge then takes the keys: 62.40 -> 59.89 M a frame) */
    for (uint32_t b = 0; b < n_b; b++) QK__UNROLL4
    for (size_t e = cb[b]; i < e; i++) {
      const uint32_t a = t32[i], p = ca[a]++;
      rb[p] = b;
      keys[p] = (uint64_t)(a + a0) << 32 | b;
    }
    *flat = keys;
    return 1;
  }
  for (uint32_t b = 0; b < n_b; b++) QK__UNROLL4
  for (size_t e = cb[b]; i < e; i++) rb[ca[t32[i]]++] = b;
  return 1;
}

/* Whether make_rows_flat's sort of n keys over n_obj slots wants 8 bytes of scratch a key
 * (the sparse and wide sorts, and the counting sort past 2^16 slots, whose keys' a and b no
 * longer fit 32 bits together), else 4 (the buckets', the counting sort's below). */
static int rows_tmp64(size_t n, uint32_t n_obj) {
  unsigned ab, bb;
  if (n * 4 < n_obj || rows_wide(n, n_obj)) return 1;
  return n_obj > ((uint32_t)1 << 16) && !bucket_plan(n, n_obj, &ab, &bb);
}

/* make_rows for the one-thread path: every slot, from 0, buckets allowed. With the
 * slots' offset a constant 0 the sorts' loops lose a subtraction a key (measured: 24.8
 * -> 22.2 instructions a pair on the clustered scene at 10^4). */
__attribute__((noinline)) static int make_rows_all(const qk_allocator_t *al, uint64_t *keys,
                                                   uint64_t *tmp, size_t n, uint32_t *cnt,
                                                   uint32_t n_obj, qk__prows_t *r) {
  return make_rows(al, keys, tmp, n, cnt, 0, n_obj, n_obj, 1, 1, r, NULL, 0);
}

/* make_rows_all that also leaves the rows' keys in order in a flat list, *flat (keys
 * itself), when its sort makes them at little cost (every sort but the buckets'), else
 * *flat NULL: the merge that follows then reads this frame's keys from the list rather
 * than through the rows (diff_merge given nk). */
__attribute__((noinline)) static int make_rows_flat(const qk_allocator_t *al, uint64_t *keys,
                                                    uint64_t *tmp, size_t n, uint32_t *cnt,
                                                    uint32_t n_obj, qk__prows_t *r, uint64_t **flat,
                                                    int tmp64) {
  return make_rows(al, keys, tmp, n, cnt, 0, n_obj, n_obj, 1, 1, r, flat, tmp64);
}

/* make_rows for a thread's range of slots (no buckets: rows_frame did those), tmp with
 * room for the n keys (the range's place in the found keys' buffer); with flat, the keys
 * left in order in keys as make_rows_flat leaves them. */
__attribute__((noinline)) static int make_rows_range(const qk_allocator_t *al, uint64_t *keys,
                                                     uint64_t *tmp, size_t n, uint32_t *cnt,
                                                     uint32_t a0, uint32_t n_a, uint32_t n_b,
                                                     qk__prows_t *r, uint64_t **flat) {
  return make_rows(al, keys, tmp, n, cnt, a0, n_a, n_b, 0, 0, r, flat, 1);
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
  *c = (rcur_t){r, 0, 0, 0, 0};
  if (!r->n_nz) return END;
  *c = (rcur_t){r, r->start[0], r->start[1], 0, (uint64_t)r->row[0] << 32};
  return c->ka | r->b[c->i];
}

static inline uint64_t rc_next(rcur_t *c) {
  if (++c->i == c->end) {
    if (++c->p == c->r->n_nz) return END;
    c->end = c->r->start[c->p + 1];
    c->ka = (uint64_t)c->r->row[c->p] << 32;
  }
  return c->ka | c->r->b[c->i];
}

/*
 * Began and ended: one merge of this frame's keys with the last frame's. A pair whose
 * slot now holds another object (or none) has ended, and a pair with such a slot has
 * begun (dirty: objects were added or removed since the last update). Both lists come
 * out in key order. This frame's keys come through the rows nw, or, given nk, from a flat
 * list in key order (nn of them). Returns 0 when memory ran short (the lists are then the
 * caller's to free).
 */
static QK__ALWAYS_INLINE int diff_merge(const qk_world_t *w, const qk__prows_t *o,
                                        const qk__prows_t *nw, const uint64_t *nk, size_t nn,
                                        int dirty, qk__kvec_t *bv, qk__kvec_t *ev) {
  const qk_allocator_t *al = &w->alloc;
  rcur_t cn = {0}, co; /* (cn unused when nk is given; set for the compilers that warn) */
  size_t i = 0;
  /* this frame's keys: through the rows (nk NULL), or from the flat list nk */
  uint64_t x = nk ? (nn ? nk[0] : END) : rc_first(&cn, nw), y = rc_first(&co, o);
#define DIFF_NEXT_X (nk ? (++i < nn ? nk[i] : END) : rc_next(&cn))
  while (x != END || y != END) {
    if (x < y) {
      if (!kv_add(al, bv, x)) return 0;
      x = DIFF_NEXT_X;
    } else if (x > y) {
      if (!kv_add(al, ev, y)) return 0;
      y = rc_next(&co);
    } else {
      if (dirty && (changed(w, (uint32_t)(x >> 32)) || changed(w, (uint32_t)x)) &&
          (!kv_add(al, bv, x) || !kv_add(al, ev, x)))
        return 0;
      x = DIFF_NEXT_X, y = rc_next(&co);
    }
  }
#undef DIFF_NEXT_X
  return 1;
}

/* The same merge row by row, for long rows (a dense world): a row's pairs are compared
 * as 32-bit slots in a tight loop, and a row's key is made once. */
static QK__ALWAYS_INLINE int diff_rows(const qk_world_t *w, const qk__prows_t *o,
                                       const qk__prows_t *nw, int dirty, qk__kvec_t *bv,
                                       qk__kvec_t *ev) {
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
      /* Runs of pairs that stayed (most of them), four at a time; at the first four that
       * differ, the equal ones before the difference are skipped at once. */
      if (!dirty) {
        while (i + 4 <= ie && j + 4 <= je) {
          unsigned eq = (unsigned)_mm_movemask_epi8(
              _mm_cmpeq_epi32(_mm_loadu_si128((const __m128i *)(nb + i)),
                              _mm_loadu_si128((const __m128i *)(ob + j))));
          if (eq != 0xFFFF) {
            unsigned same = (unsigned)__builtin_ctz(~eq) >> 2;
            i += same, j += same;
            break;
          }
          i += 4, j += 4;
        }
        if (i == ie || j == je) break;
      }
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

/* diff_merge from a flat list, with the lists in locals (see diff); apart from diff, whose
 * other merges GCC compiled worse beside it (measured: +1.8% in the row cursor's merge on
 * the uniform scene at 10^5). */
static __attribute__((noinline)) int diff_flat_lists(const qk_world_t *w, const qk__prows_t *o,
                                                     const uint64_t *nk, size_t nn, int dirty,
                                                     qk__kvec_t *bv, qk__kvec_t *ev) {
  qk__kvec_t lb = *bv, le = *ev;
  int ok = diff_merge(w, o, NULL, nk, nn, dirty, &lb, &le);
  *bv = lb, *ev = le;
  return ok;
}

/* Room for `more` keys after v's (the shared doubling growth); 0 when memory ran short. */
static int kv_more(const qk_allocator_t *a, qk__kvec_t *v, size_t more) {
  return qk__grow(a, (void **)&v->v, &v->cap, v->n + more, sizeof *v->v) == QK_OK;
}

/* The last frame's pairs o as keys in order, at k (room for o->n + 4; o may be a view of
 * some rows, rows_view, whose pairs start at o->start[0]). Each row writes its first four
 * places whatever its length (a row of one or two pairs, as in the uniform scene, then
 * takes no branch of its own; the next row overwrites the places beyond it), and only
 * longer rows loop. */
static void rows_keys(const qk__prows_t *o, uint64_t *k) {
  if (!o->n_nz) return;
  const size_t base = o->start[0];
  const uint32_t *b = o->b + base, *row = o->row, *st = o->start;
  size_t p = 0, nz = o->n_nz;
  for (; p < nz && (size_t)st[p] - base + 4 <= o->n; p++) {
    const uint64_t ka = (uint64_t)row[p] << 32;
    const size_t i = st[p] - base, e = st[p + 1] - base;
    k[i] = ka | b[i], k[i + 1] = ka | b[i + 1], k[i + 2] = ka | b[i + 2], k[i + 3] = ka | b[i + 3];
    for (size_t j = i + 4; j < e; j++) k[j] = ka | b[j];
  }
  for (; p < nz; p++) {
    const uint64_t ka = (uint64_t)row[p] << 32;
    for (size_t j = st[p] - base, e = st[p + 1] - base; j < e; j++) k[j] = ka | b[j];
  }
}

/*
 * diff_flat_lists without branches on the keys, when no slot changed (not dirty): the
 * last frame's pairs first as keys in order (rows_keys), then a merge whose every step
 * writes this frame's key to began and the last frame's to ended and keeps each only when
 * it is smaller, and moves on in the list (or both) whose key was not larger. In the
 * uniform scene a third of the pairs change every frame, so which of the three cases a
 * step takes is close to random, and the branches of the merge were mispredicted at
 * about every change (measured: the merge was 13% of the frame's time for 8.5% of its
 * instructions). The lists get room for a block of steps at a time (a step adds at most
 * one key to each). Same lists, in the same order, as diff_merge. Returns 0 when memory
 * ran short (the merge's scratch failing falls back to diff_merge).
 */
#define QK__DIFF_STEPS 256
/* One step of the merge of x = nk[*i] and y = ok[*j] (see diff_flat_nobranch). */
static QK__ALWAYS_INLINE void diff_step(const uint64_t *nk, const uint64_t *ok, size_t *i,
                                        size_t *j, uint64_t *B, size_t *nb, uint64_t *E,
                                        size_t *ne) {
  const uint64_t x = nk[*i], y = ok[*j];
  B[*nb] = x, E[*ne] = y;
  *nb += x < y, *ne += y < x;
  *i += x <= y, *j += y <= x;
}

/* The merge of nk[i .. nn) with ok[j .. no) onto the ends of lb and le (began and ended),
 * with room a block of steps at a time. 0 when memory ran short. */
static int diff_flat_run(const qk_allocator_t *al, const uint64_t *nk, size_t i, size_t nn,
                         const uint64_t *ok, size_t j, size_t no, qk__kvec_t *lb, qk__kvec_t *le) {
  while (i < nn && j < no) {
    /* (a block adds at most as many keys to each list as it has steps or keys left) */
    const size_t rb = nn - i < QK__DIFF_STEPS ? nn - i : QK__DIFF_STEPS;
    const size_t re = no - j < QK__DIFF_STEPS ? no - j : QK__DIFF_STEPS;
    if (!kv_more(al, lb, rb) || !kv_more(al, le, re)) return 0;
    uint64_t *B = lb->v, *E = le->v;
    size_t nb = lb->n, ne = le->n;
    /* A step moves on by one key at most in each list, so a block of no more steps than
     * either list has keys left needs no test of the lists' ends; the last steps, when
     * either list is nearly done, test them. */
    const size_t sb = rb < re ? rb : re;
    if (sb >= 16)
      for (size_t c = 0; c < sb; c++) diff_step(nk, ok, &i, &j, B, &nb, E, &ne);
    else
      for (int c = 0; c < QK__DIFF_STEPS && i < nn && j < no; c++)
        diff_step(nk, ok, &i, &j, B, &nb, E, &ne);
    lb->n = nb, le->n = ne;
  }
  if (!kv_more(al, lb, nn - i) || !kv_more(al, le, no - j)) return 0;
  if (nn > i) memcpy(lb->v + lb->n, nk + i, (nn - i) * sizeof *nk);
  if (no > j) memcpy(le->v + le->n, ok + j, (no - j) * sizeof *ok);
  lb->n += nn - i, le->n += no - j;
  return 1;
}

/* Keys a[0 .. n) (ascending) appended to v. 0 when memory ran short. */
static int kv_put(const qk_allocator_t *al, qk__kvec_t *v, const uint64_t *a, size_t n) {
  if (!kv_more(al, v, n)) return 0;
  if (n) memcpy(v->v + v->n, a, n * sizeof *a);
  v->n += n;
  return 1;
}

/*
 * diff_flat_lists without branches on the keys, when no slot changed (not dirty): the
 * last frame's pairs first as keys in order (rows_keys), then a merge whose every step
 * writes this frame's key to began and the last frame's to ended and keeps each only when
 * it is smaller, and moves on in the list (or both) whose key was not larger. In the
 * uniform scene a third of the pairs change every frame, so which of the three cases a
 * step takes is close to random, and the branches of the merge were mispredicted at
 * about every change (measured: the merge was 13% of the frame's time for 8.5% of its
 * instructions). Each step waits for the last (its keys are read where the last step
 * moved on to), so the lists are cut in two at this frame's middle key and the halves
 * merged in one loop, a step of each at a time: two chains of steps that do not wait for
 * each other. The first half's lists are written in place, the second's into scratch and
 * then after them. Same lists, in the same order, as diff_merge. Returns 0 when memory
 * ran short (the merge's scratch failing falls back to diff_merge).
 */
static __attribute__((noinline)) int diff_flat_nobranch(const qk_world_t *w, const qk__prows_t *o,
                                                        uint64_t *ck, uint64_t *nk, size_t nn,
                                                        uint64_t *b2, qk__kvec_t *bv,
                                                        qk__kvec_t *ev) {
  const qk_allocator_t *al = &w->alloc;
  const size_t no = o->n;
  /* The last frame's keys: those the last update kept (ck), else written out of its rows
   * into scratch. */
  const size_t n_ok = no && !ck ? no + 4 : 0;
  uint64_t *ok = ck ? ck : n_ok ? qk__realloc(al, NULL, 0, n_ok * sizeof *ok) : NULL;
  if (no && !ok) return diff_flat_lists(w, o, nk, nn, 0, bv, ev);
  if (n_ok) rows_keys(o, ok);
  qk__kvec_t lb = *bv, le = *ev;
  int res = 1;
  /* The halves: nk[0 .. h) with ok[0 .. h2) and nk[h .. nn) with ok[h2 .. no), where
   * ok[h2] is the first old key not below nk[h]: every key of the first is below every
   * key of the second. */
  size_t h = nn / 2, h2 = 0;
  if (no && h) {
    size_t lo = 0, hi = no;
    while (lo < hi) {
      const size_t mid = lo + (hi - lo) / 2;
      if (ok[mid] < nk[h])
        lo = mid + 1;
      else
        hi = mid;
    }
    h2 = lo;
  }
  /* The second half's ended list is written over the old keys it has read (it takes at
   * most one place a key read, so a key is written at or before the place read next):
   * the last frame's keys are not needed after the merge. Its began list goes to b2 when
   * given (room for nn - h keys: this frame's keys then stay, to be kept for the next
   * merge), else over this frame's keys in the same way. (In a block of their own, 123 KB
   * more at 10^4 objects, the C library's heap gave back and took again more pages:
   * 6 700 -> 10 800 page faults in 600 frames.) */
  uint64_t *B2 = b2 ? b2 : nk + h, *E2 = ok ? ok + h2 : NULL;
  size_t i = 0, j = 0, i2 = h, j2 = h2, nb2 = 0, ne2 = 0;
  while (no && h) {
    size_t sb = QK__DIFF_STEPS;
    if (h - i < sb) sb = h - i;
    if (h2 - j < sb) sb = h2 - j;
    if (nn - i2 < sb) sb = nn - i2;
    if (no - j2 < sb) sb = no - j2;
    if (sb < 16) break;
    if (!kv_more(al, &lb, sb) || !kv_more(al, &le, sb)) {
      res = 0;
      break;
    }
    uint64_t *B = lb.v, *E = le.v;
    size_t nb = lb.n, ne = le.n;
    for (size_t c = 0; c < sb; c++) {
      diff_step(nk, ok, &i, &j, B, &nb, E, &ne);
      diff_step(nk, ok, &i2, &j2, B2, &nb2, E2, &ne2);
    }
    lb.n = nb, le.n = ne;
  }
  /* The rest of the first half, the second half's lists so far, the rest of it. */
  if (res)
    res = diff_flat_run(al, nk, i, h, ok, j, h2, &lb, &le) && kv_put(al, &lb, B2, nb2) &&
          kv_put(al, &le, E2, ne2) && diff_flat_run(al, nk, i2, nn, ok, j2, no, &lb, &le);
  qk__free(al, n_ok ? ok : NULL, n_ok * sizeof *ok);
  *bv = lb, *ev = le;
  return res;
}

/* Began and ended, by whichever merge suits the rows' lengths (measured: the key merge
 * for rows of a pair or two, the row merge from about four); the key merge reads this
 * frame's keys from nk (in key order, nw->n of them) when given. */
static __attribute__((noinline)) int diff_lists(const qk_world_t *w, const qk__prows_t *o,
                                                const qk__prows_t *nw, int dirty, qk__kvec_t *bv,
                                                qk__kvec_t *ev) {
  /* The lists in locals (their ends and room stay in registers, where through the
   * pointers every key added wrote its count back), given back either way. */
  qk__kvec_t lb = *bv, le = *ev;
  int ok = nw->n + o->n >= 4 * (nw->n_nz + o->n_nz)
               ? diff_rows(w, o, nw, dirty, &lb, &le)
               : diff_merge(w, o, nw, NULL, 0, dirty, &lb, &le);
  *bv = lb, *ev = le;
  return ok;
}
/* Began and ended from the last frame's rows o (and its keys ck in order, when kept)
 * and this frame's nw (and its keys nk in order, when the sort left them so). *kept: this
 * frame's keys are still in nk, in order, after the merge (the next one may read them):
 * the key merge of short rows, which with b2 (room for half of nk) writes its scratch
 * there, not over nk. */
static int diff(const qk_world_t *w, const qk__prows_t *o, const qk__prows_t *nw, int dirty,
                uint64_t *ck, uint64_t *nk, uint64_t *b2, qk__kvec_t *bv, qk__kvec_t *ev,
                int *kept) {
  *kept = 0;
  if (nk && nw->n + o->n < 4 * (nw->n_nz + o->n_nz)) {
    *kept = dirty || b2;
    return dirty ? diff_flat_lists(w, o, nk, nw->n, dirty, bv, ev)
                 : diff_flat_nobranch(w, o, ck, nk, nw->n, b2, bv, ev);
  }
  return diff_lists(w, o, nw, dirty, bv, ev);
}

#define QK__RMAX 64 /* = QK__MAX_THREADS */

/*
 * Rows, began and ended when the search kept only the pairs that began (see
 * qk__world_search: no object added or removed since the last update, every float box
 * exact then and now). The last frame's pairs whose boxes still meet (a test on the
 * float boxes by slot, fb, exact here) stay and the others ended; the began keys (few
 * when objects move little) are sorted into rows and merged in. The rows, began and
 * ended are those of the sort-and-merge path, in the same order. With threads, by
 * ranges of slots a of about equal old pairs: range t writes its rows from the most
 * places its slots could take (the old pairs and began ones before it), its row index
 * and its lists apart; they are then joined in range order, each range's pairs moved
 * down to where its rows go.
 */
typedef struct bjob {
  const qk_world_t *w;
  const qk__prows_t *o, *nb; /* the last frame's rows, the began ones */
  const float *fb;
  uint32_t *out; /* the new rows' pairs */
  unsigned nt;
  int exact; /* the float boxes are exact: their test is the objects' */
  size_t q[QK__RMAX + 1], p[QK__RMAX + 1]; /* range t: old rows [q[t], q[t + 1]), began p */
  size_t d[QK__RMAX], z[QK__RMAX];         /* its pairs and rows */
  uint32_t *zr[QK__RMAX];                  /* its rows' slots, then (at zr + zc) starts */
  size_t zc[QK__RMAX];
  /* range t's began keys: on one thread the frame's list itself, on several its place in
   * that list (its began keys are known: those of its began rows); its ended keys, which
   * the tests decide, a list of its own, joined after */
  qk__kvec_t bv[QK__RMAX], ev[QK__RMAX];
  qk__kvec_t nv[QK__RMAX]; /* (not exact) the old pairs that became near candidates */
  int nomem[QK__RMAX];
  /* The join on threads (phase 1): range t's first row, pair and ended key in the result,
   * and where its pairs were written; the result. */
  int phase;
  size_t zo[QK__RMAX], dd[QK__RMAX], eo[QK__RMAX], base[QK__RMAX];
  qk__prows_t *r;
  uint64_t *je;
  /* Range 0 written downward (began_range_down): its pairs end at base[1], where range
   * 1's begin, and the joined pairs start off places into out. */
  int down;
  size_t off;
} bjob_t;

#if defined(__SSE2__)
/* The float box by slot of slot x (fb: (xmin, ymin, -xmax, -ymax)) meets the box whose
 * limits are lim (its halves swapped and negated): 1 or 0, one comparison on four floats. */
static QK__ALWAYS_INLINE int fb_meets(const float *fb, uint32_t x, __m128 lim) {
  return _mm_movemask_ps(_mm_cmple_ps(_mm_loadu_ps(fb + 4 * (size_t)x), lim)) == 15;
}
#endif

static QK__ALWAYS_INLINE int began_range_(bjob_t *J, unsigned t, const int exact) {
  const qk_allocator_t *al = &J->w->alloc;
  const qk__prows_t *o = J->o, *nb = J->nb;
  const float *fb = J->fb;
  const size_t q0 = J->q[t], q1 = J->q[t + 1], p0 = J->p[t], p1 = J->p[t + 1];
  const size_t zc = (q1 - q0) + (p1 - p0);
  uint32_t *zr = qk__realloc(al, NULL, 0, (2 * zc + 1) * sizeof *zr);
  if (!zr) return 0;
  J->zr[t] = zr, J->zc[t] = zc;
  qk__kvec_t lb = J->bv[t], le = J->ev[t], ln = J->nv[t];
  uint32_t *restrict out =
      J->out + (q0 < o->n_nz ? o->start[q0] : o->n) + (p0 < nb->n_nz ? nb->start[p0] : nb->n);
  const uint32_t *restrict ob = o->b, *restrict bb = nb->b;
  size_t p = p0, q = q0, z = 0, d = 0;
  int ok = 1;
  while (p < p1 || q < q1) {
    uint32_t an = p < p1 ? nb->row[p] : UINT32_MAX, ao = q < q1 ? o->row[q] : UINT32_MAX;
    uint32_t a = an < ao ? an : ao;
    size_t i = 0, ie = 0, j = 0, je = 0;
    if (an == a) i = nb->start[p], ie = nb->start[p + 1], p++;
    if (ao == a) j = o->start[q], je = o->start[q + 1], q++;
    const uint64_t ka = (uint64_t)a << 32;
    const size_t d0 = d;
    const float *fa = fb + 4 * (size_t)a;
#if defined(__SSE2__)
    /* b's box meets a's: (b.xmin, b.ymin, -b.xmax, -b.ymax) <= (a.xmax, a.ymax, -a.xmin,
     * -a.ymin), one comparison on the four floats (the boxes by slot hold the maxima
     * negated: lim is a's halves swapped and negated) */
    const __m128 av = _mm_loadu_ps(fa);
    const __m128 lim =
        _mm_xor_ps(_mm_shuffle_ps(av, av, _MM_SHUFFLE(1, 0, 3, 2)), _mm_set1_ps(-0.0f));
#endif
    /* The old row in order, each pair tested; the began slots (y, the next of them)
     * are put in before the first old slot above them. */
#if defined(__SSE2__)
    if (exact && i == ie) {
      /* A row without began pairs (most rows): its old pairs tested in a loop of their
       * own, without the began slot's comparison, and without a branch on the test:
       * each pair is written as kept and as ended, and the count of the list it
       * belongs to moves on (room for the whole row in the ended list first). */
      if (le.cap - le.n < je - j && !(ok = kv_more(al, &le, je - j))) goto out;
      uint64_t *ev = le.v + le.n;
      for (; j < je; j++) {
        const uint32_t x = ob[j];
        const int meet = fb_meets(fb, x, lim);
        out[d] = x, *ev = ka | x;
        d += (size_t)meet, ev += !meet;
      }
      le.n = (size_t)(ev - le.v);
      if (d > d0) zr[z] = a, zr[zc + z++] = (uint32_t)d0;
      continue;
    }
    if (exact) {
      /* A row with began pairs: the same without a branch on the test, the began slots
       * (y, the next of them) put in before the first old slot above them. */
      if ((le.cap - le.n < je - j && !(ok = kv_more(al, &le, je - j))) ||
          (lb.cap - lb.n < ie - i && !(ok = kv_more(al, &lb, ie - i))))
        goto out;
      uint64_t *ev = le.v + le.n, *bv = lb.v + lb.n;
      uint32_t y = bb[i]; /* (i < ie: the rows without are above) */
      for (; j < je; j++) {
        const uint32_t x = ob[j];
        while (y < x) {
          out[d++] = y, *bv++ = ka | y;
          y = ++i < ie ? bb[i] : UINT32_MAX;
        }
        const int meet = fb_meets(fb, x, lim);
        out[d] = x, *ev = ka | x;
        d += (size_t)meet, ev += !meet;
      }
      for (; i < ie; i++) out[d++] = bb[i], *bv++ = ka | bb[i];
      le.n = (size_t)(ev - le.v), lb.n = (size_t)(bv - lb.v);
      if (d > d0) zr[z] = a, zr[zc + z++] = (uint32_t)d0;
      continue;
    }
#endif
    uint32_t y = i < ie ? bb[i] : UINT32_MAX;
    for (; j < je; j++) {
      const uint32_t x = ob[j];
      if (__builtin_expect(y < x, 0)) {
        do {
          out[d++] = y;
          if (!(ok = kv_add(al, &lb, ka | y))) goto out;
          y = ++i < ie ? bb[i] : UINT32_MAX;
        } while (y < x);
      }
      const float *fx = fb + 4 * (size_t)x;
#if defined(__SSE2__)
      const int meet = _mm_movemask_ps(_mm_cmple_ps(_mm_loadu_ps(fx), lim));
      out[d] = x; /* (kept when it meets) */
      if (__builtin_expect(meet == 15, 1)) {
#else
      out[d] = x;
      if (fboxes_meet(fa, fx)) {
#endif
        if (exact || qk__world_objects_meet(J->w, a, x)) {
          d++;
          continue;
        }
        if (!(ok = kv_add(al, &ln, ka | x))) goto out; /* (and it ended) */
      }
      if (!(ok = kv_add(al, &le, ka | x))) goto out;
    }
    for (; i < ie; i++) {
      out[d++] = bb[i];
      if (!(ok = kv_add(al, &lb, ka | bb[i]))) goto out;
    }
    if (d > d0) zr[z] = a, zr[zc + z++] = (uint32_t)d0;
  }
  J->d[t] = d, J->z[t] = z;
out:
  J->bv[t] = lb, J->ev[t] = le, J->nv[t] = ln;
  return ok;
}

/* (apart: one function for both, the exact one's loop takes an instruction more a pair) */
__attribute__((noinline)) static int began_range_exact(bjob_t *J, unsigned t) {
  return began_range_(J, t, 1);
}

__attribute__((noinline)) static int began_range_near(bjob_t *J, unsigned t) {
  return began_range_(J, t, 0);
}

static int began_range(bjob_t *J, unsigned t) {
  return J->exact ? began_range_exact(J, t) : began_range_near(J, t);
}

#if defined(__SSE2__)
/*
 * Range 0 of several (every float box exact) as began_range_exact, from its last row
 * down to its first and each row from its last pair down, so that its pairs end at
 * base[1], the most places the range could take, where range 1's pairs begin: the two
 * are joined where they lie, not moved (bjob_join moved range 1 down over the places of
 * range 0's ended pairs: half of every pair on one thread, 0.9 ms of a 34 ms frame of
 * the benchmark's clustered scene at 10^5 on two threads). Its row index (each row's
 * start counted down from base[1]) and its ended list come out in descending order, and
 * bjob_join turns them round as it copies them; its began keys go in their place in the
 * joined list from its top down.
 */
static __attribute__((noinline)) int began_range_down(bjob_t *J) {
  const qk_allocator_t *al = &J->w->alloc;
  const qk__prows_t *o = J->o, *nb = J->nb;
  const float *fb = J->fb;
  const size_t q0 = J->q[0], q1 = J->q[1], p0 = J->p[0], p1 = J->p[1];
  const size_t zc = (q1 - q0) + (p1 - p0);
  uint32_t *zr = qk__realloc(al, NULL, 0, (2 * zc + 1) * sizeof *zr);
  if (!zr) return 0;
  J->zr[0] = zr, J->zc[0] = zc;
  qk__kvec_t lb = J->bv[0], le = J->ev[0];
  uint32_t *const top =
      J->out + (q1 < o->n_nz ? o->start[q1] : o->n) + (p1 < nb->n_nz ? nb->start[p1] : nb->n);
  uint32_t *restrict at = top; /* the pairs written so far: [at, top) */
  const uint32_t *restrict ob = o->b, *restrict bb = nb->b;
  size_t p = p1, q = q1, z = 0;
  int ok = 1;
  while (p > p0 || q > q0) {
    /* the larger of the two rows' slots (slot 0 may have a row: no sentinel) */
    const uint32_t an = p > p0 ? nb->row[p - 1] : 0, ao = q > q0 ? o->row[q - 1] : 0;
    const uint32_t a = p == p0 ? ao : q == q0 || an > ao ? an : ao;
    size_t i = 0, ie = 0, j = 0, je = 0;
    if (p > p0 && an == a) i = nb->start[p - 1], ie = nb->start[p], p--;
    if (q > q0 && ao == a) j = o->start[q - 1], je = o->start[q], q--;
    const uint64_t ka = (uint64_t)a << 32;
    uint32_t *const at0 = at;
    const __m128 av = _mm_loadu_ps(fb + 4 * (size_t)a);
    const __m128 lim =
        _mm_xor_ps(_mm_shuffle_ps(av, av, _MM_SHUFFLE(1, 0, 3, 2)), _mm_set1_ps(-0.0f));
    if (le.cap - le.n < je - j && !(ok = kv_more(al, &le, je - j))) goto out;
    uint64_t *ev = le.v + le.n;
    if (i == ie) {
      for (size_t k = je; k > j; k--) {
        const uint32_t x = ob[k - 1];
        const int meet = fb_meets(fb, x, lim);
        at[-1] = x, *ev = ka | x;
        at -= meet, ev += !meet;
      }
    } else {
      /* the began slots (y, the next of them down; every slot of a row is above its
       * row's, so above 0) put in after the first old slot below them; their keys from
       * the top of the range's place in the joined list down (bv[0]) */
      uint64_t *bv = lb.v + lb.cap - lb.n;
      size_t k = ie;
      uint32_t y = bb[k - 1];
      for (size_t m = je; m > j; m--) {
        const uint32_t x = ob[m - 1];
        while (y > x) {
          *--at = y, *--bv = ka | y;
          y = --k > i ? bb[k - 1] : 0;
        }
        const int meet = fb_meets(fb, x, lim);
        at[-1] = x, *ev = ka | x;
        at -= meet, ev += !meet;
      }
      for (; k > i; k--) *--at = bb[k - 1], *--bv = ka | bb[k - 1];
      lb.n = (size_t)(lb.v + lb.cap - bv);
    }
    le.n = (size_t)(ev - le.v);
    if (at < at0) zr[z] = a, zr[zc + z++] = (uint32_t)(top - at);
  }
  J->d[0] = (size_t)(top - at), J->z[0] = z;
out:
  J->bv[0] = lb, J->ev[0] = le;
  return ok;
}
#endif

/* Range t's rows (row index, and, the last range, every range's pairs moved down in
 * range order: a range's place may overlap the one before's) and ended list into the
 * result. */
static void bjob_join(bjob_t *J, unsigned t) {
  qk__prows_t *r = J->r;
  const uint32_t *zr = J->zr[t];
  const size_t zo = J->zo[t], zc = J->zc[t], d = J->dd[t], z = J->z[t];
  if (t == 0 && J->down) { /* (written downward: turned round; the began keys in place) */
    const size_t d0 = J->d[0], ne = J->ev[0].n;
    for (size_t k = 0; k < z; k++)
      r->row[z - 1 - k] = zr[k], r->start[z - 1 - k] = (uint32_t)(d0 - zr[zc + k]);
    for (size_t k = 0; k < ne; k++) J->je[J->eo[0] + k] = J->ev[0].v[ne - 1 - k];
  } else {
    for (size_t k = 0; k < z; k++)
      r->row[zo + k] = zr[k], r->start[zo + k] = (uint32_t)(d + zr[zc + k]);
    if (J->ev[t].n) memcpy(J->je + J->eo[t], J->ev[t].v, J->ev[t].n * sizeof *J->je);
  }
  if (t + 1 < J->nt) return;
  /* (range 1 follows a range 0 written downward where it lies: off + dd[1] = base[1]) */
  for (unsigned u = 1; u < J->nt; u++)
    if (J->d[u] && J->base[u] != J->off + J->dd[u])
      memmove(J->out + J->off + J->dd[u], J->out + J->base[u], J->d[u] * sizeof *J->out);
}

static void bjob_run(unsigned t, void *ud) {
  bjob_t *J = ud;
  if (J->phase) {
    bjob_join(J, t);
    return;
  }
#if defined(__SSE2__)
  const int ok = t == 0 && J->down ? began_range_down(J) : began_range(J, t);
#else
  const int ok = began_range(J, t);
#endif
  if (!ok) J->nomem[t] = 1;
}

/* Room for n keys in v (its keys kept). 0 when memory ran short (v as it was). */
static int kv_room(const qk_allocator_t *a, qk__kvec_t *v, size_t n) {
  if (n <= v->cap) return 1;
  uint64_t *p = qk__realloc(a, v->v, v->cap * sizeof *p, n * sizeof *p);
  if (!p) return 0;
  v->v = p, v->cap = n;
  return 1;
}

/* The first i in [lo, hi) with a[i] >= key (hi when none): a is ascending there. */
static size_t first_at_least(const uint32_t *a, size_t lo, size_t hi, size_t key) {
  while (lo < hi) {
    size_t mid = lo + (hi - lo) / 2;
    if (a[mid] < key)
      lo = mid + 1;
    else
      hi = mid;
  }
  return lo;
}

/*
 * The began keys sorted into rows on nt threads, by the ranges of slots a that then merge
 * them with the old rows (cut[t] .. cut[t + 1]): each thread counts its chunk of the keys
 * by range, scatters the chunk into the ranges (in room, n_room slots of scratch, when
 * it holds the n keys, else in a buffer of their own), then sorts one range's keys into
 * its rows (make_rows over its slots, the range's place in keys as its scratch) in nb->b
 * from the range's first key on. The ranges' row indexes are then joined in range order.
 * Rows are unique and ascending, so these are make_rows_all's rows, on any number of
 * threads. The ranges are those of the merge, so each thread sorts the began keys it will
 * merge. (One thread sorted them all before: 17.8 M instructions of the calling thread a
 * frame on the benchmark's clustered scene at 10^5, 610 000 began keys.) 0 when memory
 * ran short (nb->b is kept; nothing else allocated).
 */
typedef struct sjob {
  const qk_world_t *w;
  uint64_t *keys, *part;
  const qk__kvec_t *src; /* (or NULL) chunk t: the keys thread t of the search found */
  size_t n;
  unsigned nt;
  int phase;
  uint32_t cut[QK__RMAX + 1];
  size_t pc[QK__RMAX * QK__RMAX]; /* chunk t's counts by range u (t nt + u), then cursors */
  size_t ks[QK__RMAX + 1];        /* range u's keys: part[ks[u] .. ks[u + 1]) */
  qk__prows_t lr[QK__RMAX];       /* range u's rows (b in nb->b + ks[u]) */
  uint32_t *b;
  int nomem[QK__RMAX];
} sjob_t;

/* The range of slot a: the last u with cut[u] <= a (cut[0] = 0); two ranges (two
 * threads, the common case) by one comparison. */
static QK__ALWAYS_INLINE unsigned sjob_range(const sjob_t *J, uint32_t a, const int two) {
  if (two) return a >= J->cut[1];
  unsigned lo = 0, hi = J->nt;
  while (hi - lo > 1) {
    unsigned mid = (lo + hi) / 2;
    if (a >= J->cut[mid])
      lo = mid;
    else
      hi = mid;
  }
  return lo;
}

/* Chunk [k0, k1)'s keys counted by range (scatter zero) or scattered into the ranges from
 * the cursors c. */
static QK__ALWAYS_INLINE void sjob_pass(sjob_t *J, const uint64_t *keys, size_t k0, size_t k1,
                                        size_t *c, int scatter, const int two) {
  uint64_t *pt = J->part;
  if (!scatter) {
    QK__UNROLL4
    for (size_t i = k0; i < k1; i++) c[sjob_range(J, (uint32_t)(keys[i] >> 32), two)]++;
  } else {
    QK__UNROLL4
    for (size_t i = k0; i < k1; i++) {
      uint64_t k = keys[i];
      pt[c[sjob_range(J, (uint32_t)(k >> 32), two)]++] = k;
    }
  }
}

static void sjob_run(unsigned t, void *ud) {
  sjob_t *J = ud;
  const unsigned nt = J->nt;
  /* chunk t: a share of the keys, or the ones thread t of the search found */
  const uint64_t *keys = J->src ? J->src[t].v : J->keys;
  const size_t k0 = J->src ? 0 : J->n * t / nt, k1 = J->src ? J->src[t].n : J->n * (t + 1) / nt;
  /* (the counts and cursors in locals: the chunks' rows of pc share cache lines) */
  size_t c[QK__RMAX];
  if (J->phase <= 1) { /* count the chunk's keys by range, or scatter them */
    if (J->phase == 0)
      memset(c, 0, nt * sizeof *c);
    else
      memcpy(c, J->pc + (size_t)t * nt, nt * sizeof *c);
    if (nt == 2)
      sjob_pass(J, keys, k0, k1, c, J->phase, 1);
    else
      sjob_pass(J, keys, k0, k1, c, J->phase, 0);
    if (J->phase == 0) memcpy(J->pc + (size_t)t * nt, c, nt * sizeof *c);
  } else { /* range t's rows */
    const qk_allocator_t *al = &J->w->alloc;
    const uint32_t n_obj = J->w->n_obj, s0 = J->cut[t], s1 = J->cut[t + 1];
    const size_t m = J->ks[t + 1] - J->ks[t];
    size_t cn = m * 4 < n_obj ? 257 : (size_t)(s1 - s0) + n_obj + 2;
    uint32_t *cnt = qk__realloc(al, NULL, 0, cn * sizeof *cnt);
    J->lr[t].b = J->b + J->ks[t];
    if (!cnt || !make_rows_range(al, J->part + J->ks[t], J->keys + J->ks[t], m, cnt, s0, s1 - s0,
                                 n_obj, &J->lr[t], NULL))
      J->nomem[t] = 1;
    qk__free(al, cnt, cn * sizeof *cnt);
  }
}

static int began_rows_threads(const qk_world_t *w, uint64_t *keys, const qk__kvec_t *src,
                              uint32_t *room, size_t n_room, size_t n, const uint32_t *cut,
                              unsigned nt, qk__prows_t *nb) {
  const qk_allocator_t *al = &w->alloc;
  sjob_t *J = qk__realloc(al, NULL, 0, sizeof *J);
  if (!J) return 0;
  memset(J, 0, sizeof *J);
  /* (the keys by range go in the new rows' buffer, not written yet, when it has the room:
   * it is usually the kept buffer of the frame before last, whose pages are in memory) */
  int own = n_room / 2 < n, ok = 0;
  J->w = w, J->keys = keys, J->src = src, J->n = n, J->nt = nt, J->b = nb->b;
  J->part = own ? qk__realloc(al, NULL, 0, (n ? n : 1) * sizeof *keys) : (uint64_t *)room;
  if (!J->part) goto out;
  memcpy(J->cut, cut, (nt + 1) * sizeof *cut);
  qk__world_run_jobs(w, nt, nt, sjob_run, J);
  /* the ranges' starts and the chunks' cursors (a range's keys chunk by chunk) */
  size_t s = 0;
  for (unsigned u = 0; u < nt; u++) {
    J->ks[u] = s;
    for (unsigned t = 0; t < nt; t++) {
      size_t x = J->pc[(size_t)t * nt + u];
      J->pc[(size_t)t * nt + u] = s, s += x;
    }
  }
  J->ks[nt] = s;
  J->phase = 1;
  qk__world_run_jobs(w, nt, nt, sjob_run, J);
  J->phase = 2;
  qk__world_run_jobs(w, nt, nt, sjob_run, J);
  size_t nz = 0;
  for (unsigned u = 0; u < nt; u++) {
    if (J->nomem[u]) goto out;
    nz += J->lr[u].n_nz;
  }
  if (!rows_alloc(al, nb, nz)) goto out;
  nz = 0;
  for (unsigned u = 0; u < nt; u++) {
    const qk__prows_t *lr = &J->lr[u];
    for (size_t k = 0; k < lr->n_nz; k++)
      nb->row[nz + k] = lr->row[k], nb->start[nz + k] = (uint32_t)(J->ks[u] + lr->start[k]);
    nz += lr->n_nz;
  }
  nb->start[nz] = (uint32_t)n;
  nb->n = n;
  ok = 1;
out:
  for (unsigned u = 0; u < nt; u++)
    if (J->lr[u].row) qk__free(al, J->lr[u].row, 2 * (J->lr[u].n_nz + 1) * sizeof *J->lr[u].row);
  if (own) qk__free(al, J->part, (n ? n : 1) * sizeof *keys);
  qk__free(al, J, sizeof *J);
  return ok;
}

/* tmp and cnt: make_rows' scratch for the n began keys (one thread; on threads each range
 * takes its own, and the keys' room); r->b has room for the last frame's pairs and these. 0 when
 * memory ran short (the caller then frees *r, *bv, *ev and *nv). With src (nt threads, and
 * last frame's pairs), the keys are where the search's threads found them (src[t], nt of
 * them) and keys is only room for n. */
__attribute__((noinline)) static int rows_began(const qk_world_t *w, uint64_t *keys,
                                                const qk__kvec_t *src, uint64_t *tmp, size_t n,
                                                uint32_t *cnt, const float *fb, int exact,
                                                unsigned nt, qk__prows_t *r, qk__kvec_t *bv,
                                                qk__kvec_t *ev, qk__kvec_t *nv) {
  const qk_allocator_t *al = &w->alloc;
  const qk__prows_t *o = &w->cur;
  qk__prows_t nb = {0};
  if (!(nb.b = qk__realloc(al, NULL, 0, (n ? n : 1) * sizeof *nb.b))) return 0;
  nb.cap = n ? n : 1;
  bjob_t *J = qk__realloc(al, NULL, 0, sizeof *J);
  if (!J) {
    rows_free(al, &nb);
    return 0;
  }
  memset(J, 0, sizeof *J);
  if (nt > QK__RMAX) nt = QK__RMAX;
  if (!o->n_nz) nt = 1;
  J->w = w, J->o = o, J->nb = &nb, J->fb = fb, J->out = r->b, J->nt = nt, J->exact = exact;
  /* the ranges: about equal old pairs; range t takes the slots from cut[t] on */
  uint32_t cut[QK__RMAX + 1];
  J->q[0] = 0, J->q[nt] = o->n_nz, cut[0] = 0, cut[nt] = w->n_obj;
  for (unsigned t = 1; t < nt; t++) {
    size_t lo = first_at_least(o->start, J->q[t - 1], o->n_nz, o->n * t / nt);
    J->q[t] = lo, cut[t] = lo < o->n_nz ? o->row[lo] : w->n_obj;
  }
  /* the began keys' rows: sorted by the same ranges on the threads */
  if (!(nt == 1 ? make_rows_all(al, keys, tmp, n, cnt, w->n_obj, &nb)
                : began_rows_threads(w, keys, src, r->b, r->cap, n, cut, nt, &nb))) {
    qk__free(al, J, sizeof *J);
    rows_free(al, &nb);
    return 0;
  }
  J->p[0] = 0, J->p[nt] = nb.n_nz;
  for (unsigned t = 1; t < nt; t++) J->p[t] = first_at_least(nb.row, J->p[t - 1], nb.n_nz, cut[t]);
  int ok = 1;
  if (nt == 1) {
    J->bv[0] = *bv, J->ev[0] = *ev, J->nv[0] = *nv;
    ok = began_range(J, 0);
    *bv = J->bv[0], *ev = J->ev[0], *nv = J->nv[0];
    J->bv[0] = J->ev[0] = J->nv[0] = (qk__kvec_t){0};
  } else {
    /* Range t's began keys (those of its began rows, in key order) straight to their
     * place in bv; its ended ones to a list of its own, joined after. */
    ok = kv_room(al, bv, bv->n + nb.n);
    size_t at = 0; /* (range t's first began key: nb.start[p[t]]) */
    for (unsigned t = 0; ok && t < nt; t++) {
      const size_t b1 = J->p[t + 1] < nb.n_nz ? nb.start[J->p[t + 1]] : nb.n;
      J->bv[t] = (qk__kvec_t){bv->v + bv->n + at, 0, b1 - at};
      at = b1;
      size_t ec = w->ended.n / nt + 64;
      if (!(J->ev[t].v = qk__realloc(al, NULL, 0, ec * sizeof(uint64_t)))) ok = 0;
      J->ev[t].cap = J->ev[t].v ? ec : 0;
    }
#if defined(__SSE2__)
    J->down = exact;
#endif
    if (ok) qk__world_run_jobs(w, nt, nt, bjob_run, J);
    for (unsigned t = 0; ok && t < nt; t++) ok = !J->nomem[t];
    for (unsigned t = 0; ok && t < nt; t++) assert(J->bv[t].n == J->bv[t].cap);
  }
  /* The joined index, lists and pairs; on threads, each range joins its own (bjob_join:
   * the calling thread copied them all before, 10.8 MB of lists and 19 MB of pairs moved
   * a frame on the benchmark's clustered scene at 10^5), the near candidates here. */
  size_t z = 0, d = 0, bt = bv->n, et = ev->n;
  for (unsigned t = 0; ok && t < nt; t++) {
    J->zo[t] = z, J->dd[t] = d, J->eo[t] = et;
    J->base[t] = (J->q[t] < o->n_nz ? o->start[J->q[t]] : o->n) +
                 (J->p[t] < nb.n_nz ? nb.start[J->p[t]] : nb.n);
    z += J->z[t], d += J->d[t], bt += J->bv[t].n, et += J->ev[t].n;
  }
  if (ok && J->down) J->off = J->base[1] - J->d[0];
  if (ok && nt > 1) ok = kv_room(al, ev, et); /* (bv's: before the ranges) */
  for (unsigned t = 0; ok && nt > 1 && t < nt; t++) ok = kv_append(al, nv, &J->nv[t]);
  if (ok && (ok = rows_alloc(al, r, z))) {
    J->r = r, J->je = ev->v, J->phase = 1;
    if (nt > 1)
      qk__world_run_jobs(w, nt, nt, bjob_run, J);
    else
      bjob_join(J, 0); /* (the lists are bv and ev themselves) */
    if (nt > 1) bv->n = bt, ev->n = et;
    r->start[z] = (uint32_t)d;
    r->n = d;
    r->b += J->off, r->cap -= J->off, r->off = J->off;
  }
  for (unsigned t = 0; t < nt; t++) {
    qk__free(al, J->zr[t], J->zr[t] ? (2 * J->zc[t] + 1) * sizeof *J->zr[t] : 0);
    qk__free(al, J->ev[t].v, J->ev[t].cap * sizeof(uint64_t));
    qk__free(al, J->nv[t].v, J->nv[t].cap * sizeof(uint64_t));
  }
  qk__free(al, J, sizeof *J);
  rows_free(al, &nb);
  return ok;
}

/*
 * Rows, began and ended on the world's threads, by ranges of slots a. The keys are split
 * into nt chunks; each chunk is counted by partition (consecutive slots a: the buckets
 * of the bucketed sort, or 2^pb slots), the partitions are given to the threads in
 * ranges of about n / nt keys, and each chunk is scattered into its partitions (the
 * bucketed sort's 32-bit form straight into the rows' buffer, else the keys into
 * `part`). Each thread then sorts its range's keys into its rows (the bucket sort, or
 * make_rows over its slots: the one-thread path's sorts) and merges them with the last
 * frame's rows of its range (diff). A range's keys land where its rows go (rows ascend
 * by slot a), the rows are unique and sorted, and each range's began and ended lists
 * are in key order, joined in range order: the result is the one-thread path's, on any
 * number of threads. The found keys' buffer is the sort's scratch once scattered.
 */
typedef struct pjob {
  const qk_world_t *w;
  const qk__prows_t *o;  /* the last frame's rows */
  qk__prows_t *r;        /* the new rows */
  uint64_t *keys;        /* the found keys; scratch after the scatter */
  uint64_t *ck;          /* the last frame's keys in order, when kept and not dirty */
  const qk__kvec_t *src; /* or NULL: chunk t's keys (the search's thread t's), else keys' */
  uint64_t *part;        /* the keys by partition (not bucketed) */
  size_t n;
  uint32_t n_obj, np; /* slots, partitions */
  unsigned nt, pb;    /* threads, slots per partition (2^pb) */
  int dirty, phase, bucketed;
  bdig_t g;
  uint32_t *pc;              /* nt (np + 1): per chunk, counts by partition, then cursors */
  uint32_t *pst;             /* np + 1: the partitions' starts */
  uint32_t *ca;              /* bucketed: the rows' counts, n_obj + 1 */
  uint32_t rp[QK__RMAX + 1]; /* the threads' partition ranges */
  qk__prows_t lr[QK__RMAX];  /* each range's rows (starts from the range's first key) */
  size_t nzo[QK__RMAX + 1];  /* the ranges' first rows in the result */
  qk__kvec_t bj, ej;         /* the began and ended lists joined */
  /* each range's lists, in bj from its first pair's place (bbase) and in ej from its
   * first old pair's (ebase) */
  qk__kvec_t bv[QK__RMAX], ev[QK__RMAX];
  size_t bbase[QK__RMAX], ebase[QK__RMAX];
  int nomem[QK__RMAX];
  int kept[QK__RMAX]; /* the range's keys are in order in part after its merge */
} pjob_t;

/* The rows of o whose slot is in [s0, s1), as rows (sharing o's arrays). */
static qk__prows_t rows_view(const qk__prows_t *o, uint32_t s0, uint32_t s1) {
  qk__prows_t v = {0};
  if (!o->n_nz) return v;
  size_t q0 = first_at_least(o->row, 0, o->n_nz, s0);
  size_t lo = first_at_least(o->row, q0, o->n_nz, s1);
  v.b = o->b, v.row = o->row + q0, v.start = o->start + q0, v.n_nz = lo - q0;
  v.n = o->start[lo] - o->start[q0];
  return v;
}

/* Range t's rows: sorted, indexed (in J->lr[t]) and merged with the last frame's. */
static int range_rows(pjob_t *J, unsigned t) {
  const qk_allocator_t *al = &J->w->alloc;
  uint32_t p0 = J->rp[t], p1 = J->rp[t + 1];
  uint32_t s0 = (uint32_t)((uint64_t)p0 << J->pb), s1 = (uint32_t)((uint64_t)p1 << J->pb);
  if (s1 > J->n_obj) s1 = J->n_obj;
  if (s0 > s1) s0 = s1;
  size_t k0 = J->pst[p0], m = J->pst[p1] - k0;
  qk__prows_t *lr = &J->lr[t];
  lr->b = J->r->b + k0;
  uint64_t *scr = J->keys + k0; /* 8 m bytes of scratch */
  uint64_t *nk = NULL;          /* (not bucketed: the range's keys in order, in part) */
  if (J->bucketed) {
    const uint32_t W = (uint32_t)1 << J->g.ab;
    size_t cn = ((size_t)1 << J->g.d0) + ((size_t)1 << J->g.d1);
    uint32_t *c0 = qk__realloc(al, NULL, 0, cn * sizeof *c0);
    if (!c0) return 0;
    for (uint32_t k = p0; k < p1; k++) {
      uint32_t a0 = k << J->g.ab, na = J->n_obj - a0 < W ? J->n_obj - a0 : W;
      bucket_sort(&J->g, J->r->b + J->pst[k], J->pst[k + 1] - J->pst[k], na, (uint32_t *)scr, c0,
                  c0 + J->g.m0 + 1, J->ca + a0);
    }
    qk__free(al, c0, cn * sizeof *c0);
    lr->n = m;
    if (!rows_index(al, lr, J->ca + s0, s0, s1 - s0, m, 0)) return 0;
  } else {
    size_t cn = m * 4 < J->n_obj ? 257 : (size_t)(s1 - s0) + J->n_obj + 2;
    uint32_t *cnt = qk__realloc(al, NULL, 0, cn * sizeof *cnt);
    if (!cnt) return 0;
    int ok = make_rows_range(al, J->part + k0, scr, m, cnt, s0, s1 - s0, J->n_obj, lr, &nk);
    qk__free(al, cnt, cn * sizeof *cnt);
    if (!ok) return 0;
  }
  /* (the last range takes the old rows of slots past n_obj too) */
  qk__prows_t ov = rows_view(J->o, t ? s0 : 0, t + 1 < J->nt ? s1 : UINT32_MAX);
  /* The range's lists go straight into the joined ones (rows_frame moves them down): its
   * began keys from its first pair's place on, with room for its pairs (a pair began at
   * most once), its ended ones from its first old pair's, with room for those. So they
   * never grow, and are not copied into the joined lists' fresh pages (on the first frame
   * of 10^5 clustered boxes, 9.8 M began keys: 19 000 page faults more than one thread). */
  J->bbase[t] = k0, J->ebase[t] = ov.n_nz ? ov.start[0] : 0;
  J->bv[t] = (qk__kvec_t){J->bj.v + k0, 0, m};
  J->ev[t] = (qk__kvec_t){J->ej.v + J->ebase[t], 0, ov.n};
  /* The lists grow in locals: the ranges' list heads share cache lines in J, and every
   * key added writes its count (false sharing between the threads). */
  qk__kvec_t bv = J->bv[t], ev = J->ev[t];
  /* The merge as the one-thread path's: from the range's keys in order, and the last
   * frame's when kept (the range's old pairs are a run of them), its scratch in the sort's
   * (free after it), so that the range's keys stay in order for the next frame's. */
  uint64_t *ck = J->ck && ov.n ? J->ck + ov.start[0] : NULL;
  int kept;
  int ok = diff(J->w, &ov, lr, J->dirty, ck, nk, nk ? scr : NULL, &bv, &ev, &kept);
  J->kept[t] = kept && nk;
  J->bv[t] = bv, J->ev[t] = ev;
  return ok;
}

static void pjob_run(unsigned t, void *ud) {
  pjob_t *J = ud;
  size_t k0 = J->n * t / J->nt, k1 = J->n * (t + 1) / J->nt;
  const uint64_t *keys = J->keys;
  if (J->src) keys = J->src[t].v, k0 = 0, k1 = J->src[t].n;
  uint32_t *c = J->pc + (size_t)t * (J->np + 1);
  const unsigned pb = J->pb;
  switch (J->phase) {
  case 0: /* count the chunk's keys by partition */
    memset(c, 0, ((size_t)J->np + 1) * sizeof *c);
    QK__UNROLL4
    for (size_t i = k0; i < k1; i++) c[(uint32_t)(keys[i] >> 32) >> pb]++;
    break;
  case 1: /* scatter the chunk into the partitions */
    if (J->bucketed) {
      uint32_t *rb = J->r->b;
      const uint32_t W = (uint32_t)1 << pb, bmul = opaque_u32(J->g.bmask + 1);
      QK__UNROLL4
      for (size_t i = k0; i < k1; i++) {
        uint64_t k = keys[i];
        uint32_t a = (uint32_t)(k >> 32);
        rb[c[a >> pb]++] = (a & (W - 1)) * bmul | (uint32_t)k;
      }
    } else {
      uint64_t *pt = J->part;
      QK__UNROLL4
      for (size_t i = k0; i < k1; i++) {
        uint64_t k = keys[i];
        pt[c[(uint32_t)(k >> 32) >> pb]++] = k;
      }
    }
    break;
  case 2: /* the range's rows, began and ended */
    if (!range_rows(J, t)) J->nomem[t] = 1;
    break;
  default: { /* the range's rows into the result */
    const qk__prows_t *lr = &J->lr[t];
    qk__prows_t *r = J->r;
    uint32_t base = (uint32_t)J->pst[J->rp[t]];
    size_t z = J->nzo[t];
    if (lr->n_nz) memcpy(r->row + z, lr->row, lr->n_nz * sizeof *r->row);
    for (size_t k = 0; k < lr->n_nz; k++) r->start[z + k] = base + lr->start[k];
  }
  }
}

static void pjob_phase(pjob_t *J, int ph) {
  J->phase = ph;
  qk__world_run_jobs(J->w, J->nt, J->nt, pjob_run, J);
}

/* Rows, began and ended on nt threads (keys: the found keys, n of them, in a buffer of
 * at least n; used as scratch); QK_ERR_NOMEM leaves nothing allocated in *r (but b),
 * *bvo, *evo. *kept: this frame's n keys in order, in a block of n keys that the caller
 * then owns (as the one-thread path's make_rows_flat leaves them), or NULL. */
static int rows_frame(const qk_world_t *w, uint64_t *keys, const qk__kvec_t *src, size_t n,
                      qk__prows_t *r, int dirty, unsigned nt, qk__kvec_t *bvo, qk__kvec_t *evo,
                      uint64_t **kept) {
  *kept = NULL;
  const qk_allocator_t *al = &w->alloc;
  uint32_t n_obj = w->n_obj;
  if (nt > QK__RMAX) nt = QK__RMAX;
  pjob_t *J = qk__realloc(al, NULL, 0, sizeof *J);
  if (!J) return 0;
  memset(J, 0, sizeof *J);
  J->w = w, J->o = &w->cur, J->r = r, J->keys = keys, J->n = n, J->n_obj = n_obj, J->nt = nt;
  J->src = src;
  J->dirty = dirty;
  J->ck = dirty ? NULL : qk__world_kept_keys(w);
  unsigned ab, bb;
  if (n * 4 >= n_obj && bucket_plan(n, n_obj, &ab, &bb)) {
    J->bucketed = 1, J->g = bucket_digits(ab, bb), J->pb = ab;
  } else { /* about 256 partitions a thread */
    unsigned pb = 0;
    while (pb < 31 && ((uint64_t)n_obj >> pb) > 256u * nt) pb++;
    J->pb = pb;
  }
  J->np = (uint32_t)(((uint64_t)n_obj + ((uint64_t)1 << J->pb) - 1) >> J->pb);
  size_t pcn = (size_t)nt * (J->np + 1), psn = (size_t)J->np + 1;
  size_t can = J->bucketed ? (size_t)n_obj + 1 : 0, ptn = J->bucketed ? 0 : n;
  int ok = 0;
  J->pc = qk__realloc(al, NULL, 0, (pcn + psn + can) * sizeof *J->pc);
  if (!J->pc) goto out;
  J->pst = J->pc + pcn, J->ca = can ? J->pst + psn : NULL;
  if (ptn && !(J->part = qk__realloc(al, NULL, 0, ptn * sizeof *J->part))) goto out;
  pjob_phase(J, 0);
  /* The partitions' starts, the ranges and the chunks' cursors (a partition's keys chunk
   * by chunk). The ranges take about equal work, a key counted as two slots: a range's
   * sort and merge cost about 8 ns a key and its counts' passes over its slots about 5 ns
   * a slot (measured on the uniform scene at 10^5 objects, whose rows are longer at the
   * low slots: ranges of equal keys, 29,700 and 71,300 slots, took 0.78 and 1.07 ms). */
  const uint64_t work = (uint64_t)n + n_obj / 2;
  size_t s = 0;
  unsigned t = 1;
  J->rp[0] = 0;
  for (uint32_t p = 0; p < J->np; p++) {
    J->pst[p] = (uint32_t)s;
    const uint64_t done = s + (((uint64_t)p << J->pb) >> 1);
    for (; t < nt && done >= work * t / nt; t++) J->rp[t] = p;
    for (unsigned u = 0; u < nt; u++) {
      uint32_t *c = &J->pc[(size_t)u * (J->np + 1) + p], x = *c;
      *c = (uint32_t)s, s += x;
    }
  }
  J->pst[J->np] = (uint32_t)n;
  for (; t <= nt; t++) J->rp[t] = J->np;
  pjob_phase(J, 1);
  /* The joined began and ended lists, with room for every pair and every old pair: each
   * range writes its own in place (range_rows), at least one entry each. */
  size_t bcap = n ? n : 1, ecap = J->o->n ? J->o->n : 1;
  if (!(J->bj.v = qk__realloc(al, NULL, 0, bcap * sizeof *J->bj.v))) goto out;
  J->bj.cap = bcap;
  if (!(J->ej.v = qk__realloc(al, NULL, 0, ecap * sizeof *J->ej.v))) goto out;
  J->ej.cap = ecap;
  pjob_phase(J, 2);
  for (t = 0; t < nt; t++)
    if (J->nomem[t]) goto out;
  size_t nz = 0;
  for (t = 0; t < nt; t++) J->nzo[t] = nz, nz += J->lr[t].n_nz;
  if (!rows_alloc(al, r, nz)) goto out;
  r->n = n;
  r->start[nz] = (uint32_t)n;
  /* Each range's lists moved down to follow the ones before, in range order (a range's
   * new place may overlap the one before's old): none move on a frame where every pair
   * began or none ended, and a few where they are few. */
  size_t bt = 0, et = 0;
  for (t = 0; t < nt; t++) {
    if (J->bv[t].n && bt != J->bbase[t])
      memmove(J->bj.v + bt, J->bv[t].v, J->bv[t].n * sizeof *J->bj.v);
    if (J->ev[t].n && et != J->ebase[t])
      memmove(J->ej.v + et, J->ev[t].v, J->ev[t].n * sizeof *J->ej.v);
    bt += J->bv[t].n, et += J->ev[t].n;
  }
  J->bj.n = bt, J->ej.n = et;
  pjob_phase(J, 3);
  *bvo = J->bj, *evo = J->ej;
  J->bj = J->ej = (qk__kvec_t){0};
  ok = 1;
  /* (every range's keys in order: part holds the frame's, range after range) */
  int all = J->part != NULL;
  for (t = 0; t < nt; t++) all = all && J->kept[t];
  if (all) *kept = J->part, J->part = NULL;
out:
  qk__free(al, J->bj.v, J->bj.cap * sizeof(uint64_t));
  qk__free(al, J->ej.v, J->ej.cap * sizeof(uint64_t));
  for (t = 0; t < nt; t++) {
    if (J->lr[t].row) qk__free(al, J->lr[t].row, 2 * (J->lr[t].n_nz + 1) * sizeof *J->lr[t].row);
  }
  if (!ok && r->row) qk__free(al, r->row, 2 * (r->n_nz + 1) * sizeof *r->row), r->row = NULL;
  qk__free(al, J->part, ptn * sizeof *J->part);
  qk__free(al, J->pc, (pcn + psn + can) * sizeof *J->pc);
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
 * sort's scratch after the keys), the other search threads' keys, and the rows' buffer of
 * the last frame once the new rows replace it (the next rows are built in it). Smaller
 * ones are freed, as the allocator recycles them cheaply. A kept buffer more than twice
 * what its frame used is freed (the next frame allocates afresh).
 *
 * The bound is the scratch cache's (world_scratch.c), which keeps the update's freed
 * blocks from QK__WSCR_MIN on: a buffer of that size freed here would only be kept by the
 * cache, or given back and faulted in again. It was 8 MB: then a search thread's keys
 * (2 to 4 MB at 10^5 clustered boxes, 300 000 began candidates a thread) started each
 * update from nothing and grew by doubling past the cache (a realloc that grows is the
 * given allocator's), 3 MB of fresh pages an update on two threads.
 */
#define QK__KEEP_BYTES QK__WSCR_MIN

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
  if (keep_buf(qk__prows_room(&w->cur), w->cur.n, sizeof *w->cur.b)) {
    w->spare_b = qk__prows_block(&w->cur), w->cap_spare_b = qk__prows_room(&w->cur);
    w->cur.b = NULL, w->cur.cap = w->cur.off = 0;
  }
  rows_free(al, &w->cur);
}

/* The other search threads' buffers are kept when large (as the first's: see keep_keys). */
static void keep_tkeys(qk_world_t *w, qk__kvec_t *tk) {
  for (unsigned t = 0; t < QK__KEEP_THREADS; t++) {
    if (keep_buf(tk[t].cap, tk[t].n + 32, sizeof *tk[t].v))
      w->scr_tkeys[t] = tk[t], w->scr_tkeys[t].n = 0;
    else
      qk__free(&w->alloc, tk[t].v, tk[t].cap * sizeof *tk[t].v);
    tk[t] = (qk__kvec_t){0};
  }
}

static qk_status_t update(qk_world_t *w);

/* Move the keys of v marked near (QK__NEAR) to nn, unmarked; v keeps the others, in
 * order. */
static qk_status_t take_near(const qk_allocator_t *al, qk__kvec_t *v, qk__kvec_t *nn) {
  size_t m = 0;
  for (size_t i = 0; i < v->n; i++) {
    uint64_t k = v->v[i];
    if (!(k & QK__NEAR))
      v->v[m++] = k;
    else if (!kv_add(al, nn, k & ~QK__NEAR))
      return QK_ERR_NOMEM;
  }
  v->n = m;
  return QK_OK;
}

qk_status_t qk_world_update(qk_world_t *w) {
  if (!w) return QK_ERR_INVALID;
  qk__world_pool_start(w, qk__world_update_threads(w));
  qk__world_pool_hold(w, 1);
  qk__wscr_begin(w);
  qk_status_t st = update(w);
  qk__wscr_end(w);
  qk__world_pool_hold(w, 0);
  return st;
}

static qk_status_t update(qk_world_t *w) {
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
  int split;
  /* The float boxes by slot for the next update (with the near candidates when they are
   * not all exact), and the last update's, with which the search
   * keeps only the candidates that began when no object was added or removed since (a
   * failed allocation only loses that). */
  unsigned nt = w->n_live < 4096 ? 1 : qk__world_update_threads(w);
  if (nt > QK__RMAX) nt = QK__RMAX;
  /* (only a search by bands fills them: a frame on the grid allocates none) */
  const uint32_t nfb = w->by_bands ? w->n_obj : 0;
  float *fb = nfb ? qk__realloc(al, NULL, 0, (size_t)nfb * 4 * sizeof *fb) : NULL;
  const float *prev = fb && !w->ident_dirty && w->fbox && w->n_fbox == nfb ? w->fbox : NULL;
  int fb_ok, only_new;
  qk_status_t st = qk__world_search(w, &pk, &found, tk, &split, prev, fb, &fb_ok, &only_new);
  qk__world_pack_free(w, &pk);
  /* This update's near candidates (see qk__world_search): those the search marked, and
   * when it found only the new candidates, the last update's near ones whose float boxes
   * still meet and whose objects do not (those that do are pairs that began). */
  qk__kvec_t nn = {0};
  if (st == QK_OK && fb_ok == 2) {
    st = take_near(al, &found, &nn);
    for (unsigned t = 0; split && st == QK_OK && t < QK__KEEP_THREADS; t++)
      st = take_near(al, &tk[t], &nn);
  }
  if (st == QK_OK && only_new)
    for (size_t i = 0; st == QK_OK && i < w->near.n; i++) {
      uint64_t k = w->near.v[i];
      uint32_t a = (uint32_t)(k >> 32), b = (uint32_t)k;
      const float *fa = fb + 4 * (size_t)a, *fx = fb + 4 * (size_t)b;
      if (!fboxes_meet(fa, fx)) continue;
      if (fb_ok == 1 || qk__world_objects_meet(w, a, b)) {
        if (!kv_add(al, &found, k)) st = QK_ERR_NOMEM;
      } else if (!kv_add(al, &nn, k)) {
        st = QK_ERR_NOMEM;
      }
    }
  /* The keys of the search's threads: left where they were found when the rows run on
   * as many threads (each reads its own in the rows' first pass), else joined here. */
  qk__kvec_t src[1 + QK__KEEP_THREADS];
  size_t total = found.n;
  if (split) {
    for (unsigned t = 0; t < QK__KEEP_THREADS; t++) {
      total += tk[t].n;
      if (tk[t].n && t + 1 >= nt) split = 0; /* (not expected: the same threads) */
    }
    if (nt > 1 + QK__KEEP_THREADS) split = 0;
    /* (the began-only rows read them where they are, with found's room for all as the
     * scratch: see rows_began; with no last frame's pairs they run on one thread) */
    if (only_new && (nt < 2 || nt > QK__RMAX || !w->cur.n_nz)) split = 0;
    if (st == QK_OK && !kv_room(al, &found, total)) st = QK_ERR_NOMEM;
    if (st == QK_OK && !split) { /* (found's room holds them all) */
      for (unsigned t = 0; t < QK__KEEP_THREADS; t++) {
        if (tk[t].n) memcpy(found.v + found.n, tk[t].v, tk[t].n * sizeof *found.v);
        found.n += tk[t].n;
      }
    } else {
      src[0] = found;
      for (unsigned t = 1; t < nt; t++) src[t] = tk[t - 1];
    }
  }
  if (st != QK_OK || total + (only_new ? w->cur.n : 0) > UINT32_MAX) {
    /* (rows and counts hold 32-bit positions) */
    qk__free(al, fb, (size_t)nfb * 4 * sizeof *fb);
    qk__free(al, nn.v, nn.cap * sizeof *nn.v);
    if (st != QK_OK) {
      qk__free(al, found.v, found.cap * sizeof *found.v);
      found = (qk__kvec_t){0};
    }
    keep_tkeys(w, tk);
    if (st != QK_OK) return st;
    qk__free(al, found.v, found.cap * sizeof *found.v);
    return QK_ERR_LIMIT;
  }
  /* Everything else the update needs, before anything changes: the new rows and the
   * began and ended lists (sized by the last frame's, grown as needed): a failure keeps
   * the last frame's lists. */
  size_t n_obj = w->n_obj, tcap = total ? total : 1;
  /* (the began pairs only: the rows are the last frame's that stay and these) */
  size_t rcap = only_new ? total + w->cur.n + 1 : tcap;
  int dirty = w->ident_dirty, ok = 0, kept = 0;
  const uint64_t *keep = NULL; /* this frame's keys in order, to be kept (see ckeys) */
  uint64_t *tkeep = NULL;      /* the same from the threads' rows, in a block of their own */
  qk__prows_t nr = {0};
  qk__kvec_t bv = {0}, ev = {0};
  /* The new rows go in the buffer of the frame before last when it is large enough
   * (and not much larger), else in a new one with some room (frames are alike). */
  if (w->spare_b && w->cap_spare_b >= rcap && keep_buf(w->cap_spare_b, rcap, sizeof *nr.b)) {
    nr.b = w->spare_b, nr.cap = w->cap_spare_b;
    w->spare_b = NULL, w->cap_spare_b = 0;
  } else {
    size_t c = rcap * sizeof *nr.b >= QK__KEEP_BYTES ? rcap + rcap / 8 + 64 : rcap;
    if ((nr.b = qk__realloc(al, NULL, 0, c * sizeof *nr.b))) nr.cap = c;
  }
  if (nr.b && nt > 1 && !only_new) {
    /* on threads: the same sorts and merge, by ranges of slots */
    ok = rows_frame(w, found.v, split ? src : NULL, total, &nr, dirty, nt, &bv, &ev, &tkeep);
  } else if (nr.b) {
    /* one thread: the keys sorted into rows, then merged with the last frame's */
    size_t ccap = total * 4 < n_obj ? 257 : rows_cnt((uint32_t)n_obj, total);
    const int t64 = rows_tmp64(total, (uint32_t)n_obj);
    size_t tbytes = (t64 ? sizeof(uint64_t) : sizeof(uint32_t)) * tcap;
    /* (and the key merge's scratch after the sort, half of the keys: see diff) */
    if (tbytes < (tcap / 2 + 1) * sizeof(uint64_t)) tbytes = (tcap / 2 + 1) * sizeof(uint64_t);
    /* The dense sort's scratch goes after the keys when their buffer has the room (it is
     * given the room when it is kept: see keep_keys). */
    int in_keys = total * 4 >= n_obj && (found.cap - total) * sizeof *found.v >= tbytes;
    uint64_t *tmp = in_keys ? found.v + total : qk__realloc(al, NULL, 0, tbytes);
    uint32_t *cnt = tmp ? qk__realloc(al, NULL, 0, ccap * sizeof *cnt) : NULL;
    /* The lists start with room for the last frame's counts and some (frames are
     * alike), and grow if need be; began holds at most this frame's keys, ended the last
     * frame's pairs. (Frame 1 follows a frame where every pair began: 9.8 M at 10^5
     * clustered boxes, against some 600 000 now. Its room was then 98 MB, and the list cut
     * to size after the rows was copied to a fresh block on the calling thread alone:
     * 1 200 page faults, 17 ms of the update's CPU time on this machine.) */
    size_t bcap = w->began.n + w->began.n / 4 + 64, ecap = w->ended.n + w->ended.n / 4 + 64;
    if (bcap > total + 64) bcap = total + 64;
    if (ecap > w->cur.n + 64) ecap = w->cur.n + 64;
    if (cnt && (bv.v = qk__realloc(al, NULL, 0, bcap * sizeof *bv.v))) bv.cap = bcap;
    if (bv.v && (ev.v = qk__realloc(al, NULL, 0, ecap * sizeof *ev.v))) ev.cap = ecap;
    if (ev.v && only_new)
      ok = rows_began(w, found.v, split ? src : NULL, tmp, total, cnt, fb, fb_ok == 1, nt, &nr, &bv,
                      &ev, &nn);
    else if (ev.v) {
      uint64_t *nk = NULL; /* (this frame's keys in order, when the sort left them so) */
      /* The last frame's keys when kept; the merge's scratch in the sort's (free after
       * it), so that this frame's keys stay. */
      uint64_t *ck = dirty ? NULL : qk__world_kept_keys(w);
      ok = make_rows_flat(al, found.v, tmp, total, cnt, (uint32_t)n_obj, &nr, &nk, t64) &&
           diff(w, &w->cur, &nr, dirty, ck, nk, tmp, &bv, &ev, &kept);
      if (ok && kept && nk) keep = nk;
    }
    qk__free(al, cnt, ccap * sizeof *cnt);
    if (!in_keys) qk__free(al, tmp, tbytes);
  }
  if (ok) w->last_found = total;
  /* This frame's keys in order for the next merge, when the merge left them so: their
   * buffer (the search's) becomes ckeys, and the last frame's ckeys the buffer that
   * keep_keys keeps or frees (no copy). */
  if (keep) {
    assert(keep == found.v);
    const qk__kvec_t t = w->ckeys;
    w->ckeys = found, w->ckeys.n = total;
    found = t, found.n = 0;
  } else {
    qk__free(al, w->ckeys.v, w->ckeys.cap * sizeof *w->ckeys.v);
    w->ckeys = (qk__kvec_t){0};
    if (tkeep) w->ckeys = (qk__kvec_t){tkeep, total, total};
  }
  keep_tkeys(w, tk);
  keep_keys(w, &found, total);
  size_t n_eg = 0;
  if (dirty)
    for (uint32_t i = 0; i < w->n_obj; i++) n_eg += w->obj[i].gen != w->ugen[i];
  uint64_t *eg = NULL;
  if (!ok || (n_eg && !(eg = qk__realloc(al, NULL, 0, n_eg * sizeof *eg)))) {
    w->ckeys.n = 0; /* (they are this frame's, and the last frame's rows stay) */
    qk__free(al, fb, (size_t)nfb * 4 * sizeof *fb);
    qk__free(al, nn.v, nn.cap * sizeof *nn.v);
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
   * generations. A buffer the rule of kept buffers keeps is not cut: the scratch cache
   * keeps the room of a block cut to half or more in an update anyway, so the cut only
   * hid that room, and two frames on, the rows, grown past the cut, found the buffer too
   * small and took a fresh one (40 MB at 10^5 clustered boxes whose pairs fall by 1% a
   * frame: 10 000 page faults every eighth update). */
  keep_rows(w);
  if (nr.cap > nr.n + nr.n / 4 + 64 && !keep_buf(qk__prows_room(&nr), nr.n, sizeof *nr.b)) {
    size_t c = nr.n ? nr.n : 1;
    uint32_t *p = qk__realloc(al, qk__prows_block(&nr), qk__prows_room(&nr) * sizeof *p,
                              (nr.off + c) * sizeof *p);
    if (p) nr.b = p + nr.off, nr.cap = c;
  }
  w->cur = nr;
  /* This update's float boxes for the next one, when they are all exact. */
  qk__free(al, w->fbox, (size_t)w->n_fbox * 4 * sizeof *w->fbox);
  w->fbox = NULL, w->n_fbox = 0;
  qk__free(al, w->near.v, w->near.cap * sizeof *w->near.v);
  w->near = (qk__kvec_t){0};
  if (fb_ok) {
    w->fbox = fb, w->n_fbox = nfb;
    shrink(al, &nn);
    w->near = nn;
  } else {
    qk__free(al, fb, (size_t)nfb * 4 * sizeof *fb);
    qk__free(al, nn.v, nn.cap * sizeof *nn.v);
  }
  if (dirty) {
    for (uint32_t i = 0; i < w->n_obj; i++) {
      if (w->obj[i].gen != w->ugen[i]) w->egen[w->n_egen++] = (uint64_t)i << 32 | w->ugen[i];
      w->ugen[i] = w->obj[i].gen;
    }
    w->ident_dirty = 0;
  }
  return QK_OK;
}

qk_status_t qk_world_pairs(const qk_world_t *w, qk_pairs_which_t which, qk_world_pair_fn fn,
                           void *ud) {
  if (!w || !fn) return QK_ERR_INVALID;
  if (which == QK_PAIRS_ENDED) {
    for (size_t i = 0; i < w->ended.n; i++) {
      qk_world_pair_t q = qk__ended_pair(w, w->ended.v[i]);
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
  /* The arrays in locals: fn may write any memory the compiler knows of, so fields read
   * through w in the loop would be read again after every call. */
  const uint32_t *row = w->cur.row, *start = w->cur.start, *rb = w->cur.b, *ug = w->ugen;
  const size_t n_nz = w->cur.n_nz;
  const uint64_t *ck = qk__world_kept_keys(w);
  if (ck) {
    /* The pairs also as keys in order (see ckeys): each pair from its key. */
    const size_t n = w->cur.n;
    size_t i = 0;
    if (qk__world_far(w)) /* (slots b at random in a generation array beyond the caches) */
      for (; i + QK__WALK_AHEAD < n; i++) {
        __builtin_prefetch(&ug[(uint32_t)ck[i + QK__WALK_AHEAD]]);
        const uint32_t a = (uint32_t)(ck[i] >> 32), b = (uint32_t)ck[i];
        if (fn((uint64_t)ug[a] << 32 | a, (uint64_t)ug[b] << 32 | b, ud)) return QK_OK;
      }
    for (; i < n; i++) {
      const uint32_t a = (uint32_t)(ck[i] >> 32), b = (uint32_t)ck[i];
      if (fn((uint64_t)ug[a] << 32 | a, (uint64_t)ug[b] << 32 | b, ud)) return QK_OK;
    }
    return QK_OK;
  }
  if (w->cur.n < 4 * n_nz) {
    /* Short rows (a sparse world): a plain loop (the unrolled one's set-up costs more than
     * it saves in a row of a pair or two; measured on the uniform scene at 10^4: 36.5 ->
     * 30.1 instructions an object a frame, where the clustered scene's long rows take
     * 246.3 unrolled against 259.2 plain) */
    const size_t n = w->cur.n;
    size_t k = 0;
    for (size_t i = 0; i < n; i++) {
      /* One loop over the pairs, moving to the next row at its start (rows are not empty):
       * a loop a row ended at a pair or two, at random, and mispredicted about once a
       * row. */
      k += i == start[k + 1];
      const uint32_t a = row[k], b = rb[i];
      if (fn((uint64_t)ug[a] << 32 | a, (uint64_t)ug[b] << 32 | b, ud)) return QK_OK;
    }
    return QK_OK;
  }
  for (size_t k = 0; k < n_nz; k++) {
    uint32_t a = row[k];
    qk_handle_t ha = (uint64_t)ug[a] << 32 | a;
    QK__UNROLL4
    for (size_t i = start[k], e = start[k + 1]; i < e; i++) {
      uint32_t b = rb[i];
      if (fn(ha, (uint64_t)ug[b] << 32 | b, ud)) return QK_OK;
    }
  }
  return QK_OK;
}

qk_status_t qk_world_pairs_list(const qk_world_t *w, qk_pairs_which_t which, qk_world_pair_t *out,
                                size_t cap, size_t *n_out) {
  if (!w || !n_out || (cap && !out)) return QK_ERR_INVALID;
  if (which == QK_PAIRS_ENDED) {
    *n_out = w->ended.n;
    for (size_t i = 0; i < w->ended.n && i < cap; i++) out[i] = qk__ended_pair(w, w->ended.v[i]);
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
