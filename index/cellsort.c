/*
 * The bulk build's sort of the points by cell (index/build.c makes the tree from it): every
 * point's cell in the uniform 2^L x 2^L grid over the root square, exactly the cell the
 * tree's own comparisons send it to, and a two-digit MSD radix sort of the points by cell
 * number into the tree's point arrays. The cell number's base-4 digits are the quadrants
 * (NE=0, NW=1, SW=2, SE=3), so cell order is the tree's pre-order.
 *
 * Three passes over the points, each split over threads (shares of the input, or jobs
 * taken from a counter):
 *  1. keys: the cell number of every point (2L bits), counted per cell and share;
 *  2. scatter: the point with its place and low digit as a 20-byte record into its coarse
 *     bucket (high digit, at most 8 bits: 256 buckets), through a write-combining buffer
 *     per bucket (whole cache lines, non-temporal for large inputs) into the segment of
 *     its bucket and share, placed by the counts of pass 1;
 *  3. per coarse bucket (a job each): the fine buckets' slot ranges from the counts, and
 *     the records' coordinates and ids sorted by the low digit into staging arrays in
 *     cache, then copied out in order to the tree's point arrays.
 * Both digits are counting sorts that keep input order, so the points of a cell keep
 * their input order and the result is the same for any number of threads.
 *
 * The cell of a point is its truncated scaled coordinate, corrected by one step against
 * the grid lines as the tree computes them (the corner arithmetic of every descent, one
 * addition per level), so that it is exactly the cell of the tree's comparisons: the
 * tree's descent is a binary search over those lines, and the cell is the number of lines
 * a coordinate lies east (north) of. The correction step suffices when the scaling errs by
 * less than a cell; when the root's coordinates are so badly conditioned that this is not
 * certain, the sort declines and the caller uses the plain build.
 */
#include <float.h>
#include <stdatomic.h>
#include <math.h>
#include <string.h>

#include "index/index_access.h"
#include "index/inline.h"

#if defined(__SSE2__)
#include <emmintrin.h>
#endif
/* The keys four at a time, and the streaming copy 32 bytes a store, where the compiler can
 * target AVX2 in one function and the processor has it (checked when the build runs). */
#if defined(__GNUC__) && defined(__x86_64__) && (defined(__clang__) || __GNUC__ >= 8)
#define QK__CELL_AVX2 1
#include <immintrin.h>
#else
#define QK__CELL_AVX2 0
#endif

int qk__build_avx2_off;

int qk__build_avx2(void) {
#if QK__CELL_AVX2
  return !qk__build_avx2_off && __builtin_cpu_supports("avx2");
#else
  return 0;
#endif
}

/* Reading ahead, where the compiler offers it. */
#if defined(__GNUC__)
#define QK__PREFETCH(p) __builtin_prefetch(p)
#define QK__UNLIKELY(c) __builtin_expect(!!(c), 0)
#else
#define QK__PREFETCH(p) ((void)0)
#define QK__UNLIKELY(c) (c)
#endif
/* How far ahead the fine pass reads its records (3.8 KB). On the Zen 5 machine 192
 * records took the fine pass from 2.26 to 2.10 ms (minima; medians 2.71 to 2.53) at 1M
 * uniform points on one thread, against 96; 48 was slower, 384 and 768 alike. */
#define PREFETCH_RECS 192
/* Read ahead of point p by PREFETCH_PTS points (an address past the array's end is only
 * a hint to the processor, computed outside C's pointer arithmetic). */
#define QK__PREFETCH_PTS(p)                                                                        \
  QK__PREFETCH((const void *)((uintptr_t)(p) + PREFETCH_PTS * sizeof(qk_point_t)))
/* How far ahead the key pass and the scatter read the input by hand, in points (4 KB,
 * a block of the key pass). The hardware's prefetch alone left the key pass reading the
 * input at half the rate of the bounding box: 3.2 against 1.8-1.9 ms at 1M points on one
 * thread, and the scatter 4.0 against 3.2-3.6 ms. */
#define PREFETCH_PTS 256

/* fine_staged() is made three times: for tags of the input's index with the 8-bit fine
 * digit of the deepest grid, and of any digit, with and without the index. */

/* The grid lines along one axis as the tree computes them: line k (0 < k < 2^L) splits
 * the node of depth d = L - 1 - ctz(k) whose lower corner is the origin plus the sides of
 * the levels where k's top d bits are set, added in order from the top; it lies at that
 * corner plus the side of depth d + 1. g[0] is -inf, g[2^L] and g[2^L + 1] are +inf. False
 * when the lines are not in order (rounding in a badly conditioned root). */
static bool grid_lines(const qk_tree_t *t, double origin, unsigned L, double *g) {
  uint32_t cells = 1u << L;
  g[0] = -INFINITY;
  g[cells] = g[cells + 1] = INFINITY;
  for (uint32_t k = 1; k < cells; k++) {
    unsigned tz = 0;
    while (!((k >> tz) & 1u)) tz++;
    unsigned d = L - 1 - tz;
    double c = origin;
    for (unsigned j = 0; j < d; j++)
      if ((k >> (L - 1 - j)) & 1u) c += t->side[j + 1];
    g[k] = c + t->side[d + 1];
  }
  for (uint32_t k = 2; k < cells; k++)
    if (g[k] < g[k - 1]) return false;
  return true;
}

/*
 * One axis's tables for the key pass. A coordinate v scaled to grid units and truncated
 * gives a first guess c in [0, 2^L], off by at most one cell; the lines on either side of
 * guess c, line[c] = (g[c], g[c + 1]), settle it: with m the two bits (v > g[c],
 * v > g[c + 1]), the cell is c - 1 + popcount(m). dig[4c + m] holds that cell's key bits
 * along this axis: a cell's key is dig_x ^ dig_y, two bits per level, the digit NE=0, NW=1,
 * SW=2, SE=3 from the east bit e and north bit n as ((n ^ 1) << 1) | (e ^ n).
 */
typedef struct axis_tab {
  double line[257][2];
  uint16_t dig[257 * 4];
} axis_tab_t;

static void axis_tables(const double *g, unsigned L, bool north, axis_tab_t *a) {
  uint32_t cells = 1u << L, top = cells - 1;
  uint32_t mask = (uint32_t)qk__spread16(top); /* the even bits of the key */
  for (uint32_t c = 0; c <= cells; c++) {
    a->line[c][0] = g[c];
    a->line[c][1] = g[c + 1];
    for (uint32_t m = 0; m < 4; m++) {
      int cell = (int)c - 1 + (int)(m & 1u) + (int)(m >> 1);
      uint32_t i = cell < 0 ? 0u : cell > (int)top ? top : (uint32_t)cell;
      uint32_t s = (uint32_t)qk__spread16(i);
      /* east bits go to the low bit of every digit; north bits to both, the high one
       * inverted */
      a->dig[4 * c + m] = (uint16_t)(north ? (((s ^ mask) << 1) ^ s) : s);
    }
  }
}

/* What the parallel phases of the bucketed build share. Passes 1 and 2 run on shares of
 * the input, qk__share_range(n, w, ns); pass 3 runs one job per coarse bucket. The records
 * of coarse bucket c written by share w form a segment of the record array; segments go in
 * the order (c, w), each starting at a multiple of WC records, so that a bucket's records
 * are one run of memory that the fine pass reads front to back.
 *
 * A record is 20 bytes: the point's coordinates, and a tag with its low digit in the low
 * fbits bits and above them its index in the input when the input has at most
 * 2^(32 - fbits) points (gid), else its place in its share (shares hold at most that many
 * points, so it fits). Byte arrays, read and written with memcpy (one move each). */
typedef struct rec {
  unsigned char b[20];
} rec_t;
_Static_assert(sizeof(rec_t) == 20, "records of 20 bytes");

/* Records per write-combining buffer: 64 of 20 bytes are twenty cache lines, streamed to
 * memory as one run. The scatter is bounded by its non-temporal stores' drain (their
 * stores took a third of its samples); runs of twenty lines instead of five cut it from
 * 2.40 to 1.93 ms (minima; medians 3.05 to 2.48) at 1M uniform points on one thread, 32
 * records 2.11, 128 records 2.04 (AMD EPYC, Zen 5, 1 MB L2). */
#define WC 64u
/* Most coarse buckets: their write-combining buffers take 320 KB a thread (in the
 * second-level cache, allocated with the scratch arrays, not on a worker's stack). At the deepest
 * grid the two digits are then 8 bits each: the fine pass writes 256 streams of pairs and 256 of
 * ids, whose current lines fit the first-level cache, where 7 and 9 bits left it 1024 lines and a
 * miss a point (callgrind, D1 48 KB, 1M uniform points: fine pass 1.01 -> 0.45 M write misses,
 * scatter 0.22 -> 0.44 M). */
#define MAX_COARSE_BITS 8u
/* Most points a thread stages in pass 3: 320 KB, within a core's second-level cache. */
#define STAGE_MAX 16384u
/* Points per block of the key computation: their keys stay in the first-level cache
 * between the loop that computes them and the one that scatters them. */
#define BLOCK 256u

typedef struct bucket_job {
  qk_tree_t *t;
  const qk_point_t *p;
  size_t n;
  double x0, y0, scale;
  const axis_tab_t *ax, *ay; /* the key tables of the two axes */
  unsigned fbits;            /* bits of the low digit */
  size_t nc;                 /* coarse buckets */
  bool stream;               /* write records and points around the caches */
  uint16_t *key;             /* every point's cell */
  rec_t *rec;                /* 64-byte aligned */
  unsigned char *wcb;        /* the scatter's write-combining buffers, nc * WC records a
                                thread, 64-byte aligned */
  uint32_t *seg;             /* ns rows of nc: where the records of (w, c) start */
  uint32_t *cnt;             /* ns rows of nc: records of bucket c from share w */
  uint32_t *hist;            /* ns rows of 4^L: the points of every cell by share */
  size_t nb;                 /* cells, 4^L */
  uint32_t *cbase;           /* nc + 1 coarse bucket starts in the point arrays */
  uint32_t *cum;             /* 4^L + 1 fine bucket starts */
  uint32_t *deep;            /* nc: points of bucket c in cells over the capacity */
  unsigned nw;               /* threads */
  unsigned ns;               /* shares of pass 1, at least nw */
  uint32_t stage_cap;        /* points per thread in the staging arrays (0: none) */
  double *sxy;               /* the staging arrays, stage_cap per thread: coordinate pairs */
  qk_id_t *sid;
  double near;   /* the scaling's error bound, in grid units */
  uint32_t even; /* the even bits of a key */
  bool avx2;     /* keys four at a time, copies 32 bytes a store */
  bool gid;      /* tags hold the point's index in the input, not in its share */
} bucket_job_t;

/* The cell of one point by the tables: the truncated scaled coordinate, corrected by the
 * lines on either side of it. */
static inline uint32_t key_by_lines(const bucket_job_t *j, double x, double y) {
  uint32_t cx = (uint32_t)((x - j->x0) * j->scale), cy = (uint32_t)((y - j->y0) * j->scale);
  const axis_tab_t *ax = j->ax, *ay = j->ay;
  uint32_t mx = (uint32_t)(x > ax->line[cx][0]) | (uint32_t)(x > ax->line[cx][1]) << 1;
  uint32_t my = (uint32_t)(y > ay->line[cy][0]) | (uint32_t)(y > ay->line[cy][1]) << 1;
  return (uint32_t)(ax->dig[4 * cx + mx] ^ ay->dig[4 * cy + my]);
}

#if QK__CELL_AVX2
/* The keys of m points, four at a time. A scaled coordinate whose fraction lies at least
 * `near` (the error bound of the scaling and of the grid lines, in grid units) from a
 * whole number is strictly between the lines of its truncation: its cell is that, and its
 * key the interleaved bits of the two cells (east bits low, north bits high and inverted:
 * the same bits as the tables'). The four points of a group with a coordinate nearer
 * than that to a line go by the tables. */
__attribute__((target("avx2"))) static void keys_avx2(const bucket_job_t *j, const qk_point_t *p,
                                                      size_t m, uint16_t *key) {
  const __m256d o = _mm256_setr_pd(j->x0, j->y0, j->x0, j->y0), sc = _mm256_set1_pd(j->scale);
  const __m256d lo = _mm256_set1_pd(j->near), hi = _mm256_set1_pd(1.0 - j->near);
  const __m256i m4 = _mm256_set1_epi32(0x0f0f), m2 = _mm256_set1_epi32(0x3333),
                m1 = _mm256_set1_epi32(0x5555), even = _mm256_set1_epi32((int)j->even);
  const __m256i pick = _mm256_setr_epi32(0, 2, 4, 6, 1, 3, 5, 7);
  size_t i = 0;
  /* Eight points a step: their 16 cell numbers packed to 16 bits in one register are spread
   * at once; each 32-bit lane then holds a point's east bits (low half) and north bits
   * (high half). */
  const __m256i w4 = _mm256_set1_epi16(0x0f0f), w2 = _mm256_set1_epi16(0x3333),
                w1 = _mm256_set1_epi16(0x5555), low = _mm256_set1_epi32(0xffff);
  const __m256i order = _mm256_setr_epi32(0, 1, 4, 5, 2, 3, 6, 7);
  for (; i + 8 <= m; i += 8) {
    QK__PREFETCH_PTS(&p[i]); /* two lines a step */
    QK__PREFETCH_PTS(&p[i + 4]);
    __m256d t0 = _mm256_mul_pd(_mm256_sub_pd(_mm256_loadu_pd(&p[i].x), o), sc);
    __m256d t1 = _mm256_mul_pd(_mm256_sub_pd(_mm256_loadu_pd(&p[i + 2].x), o), sc);
    __m256d t2 = _mm256_mul_pd(_mm256_sub_pd(_mm256_loadu_pd(&p[i + 4].x), o), sc);
    __m256d t3 = _mm256_mul_pd(_mm256_sub_pd(_mm256_loadu_pd(&p[i + 6].x), o), sc);
    __m128i i0 = _mm256_cvttpd_epi32(t0), i1 = _mm256_cvttpd_epi32(t1);
    __m128i i2 = _mm256_cvttpd_epi32(t2), i3 = _mm256_cvttpd_epi32(t3);
    __m256d f0 = _mm256_sub_pd(t0, _mm256_cvtepi32_pd(i0));
    __m256d f1 = _mm256_sub_pd(t1, _mm256_cvtepi32_pd(i1));
    __m256d f2 = _mm256_sub_pd(t2, _mm256_cvtepi32_pd(i2));
    __m256d f3 = _mm256_sub_pd(t3, _mm256_cvtepi32_pd(i3));
    __m256d bad = _mm256_or_pd(
        _mm256_or_pd(
            _mm256_or_pd(_mm256_cmp_pd(f0, lo, _CMP_LT_OQ), _mm256_cmp_pd(f0, hi, _CMP_GT_OQ)),
            _mm256_or_pd(_mm256_cmp_pd(f1, lo, _CMP_LT_OQ), _mm256_cmp_pd(f1, hi, _CMP_GT_OQ))),
        _mm256_or_pd(
            _mm256_or_pd(_mm256_cmp_pd(f2, lo, _CMP_LT_OQ), _mm256_cmp_pd(f2, hi, _CMP_GT_OQ)),
            _mm256_or_pd(_mm256_cmp_pd(f3, lo, _CMP_LT_OQ), _mm256_cmp_pd(f3, hi, _CMP_GT_OQ))));
    /* 32-bit lanes: points 0 1 2 3 (x, y each) and 4 5 6 7; packed to 16 bits: points
     * 0 1 4 5 in the low 128 bits, 2 3 6 7 in the high */
    __m256i a = _mm256_inserti128_si256(_mm256_castsi128_si256(i0), i1, 1);
    __m256i c = _mm256_inserti128_si256(_mm256_castsi128_si256(i2), i3, 1);
    __m256i v = _mm256_packus_epi32(a, c);
    v = _mm256_and_si256(_mm256_or_si256(v, _mm256_slli_epi16(v, 4)), w4);
    v = _mm256_and_si256(_mm256_or_si256(v, _mm256_slli_epi16(v, 2)), w2);
    v = _mm256_and_si256(_mm256_or_si256(v, _mm256_slli_epi16(v, 1)), w1);
    __m256i n = _mm256_srli_epi32(v, 16);
    __m256i k = _mm256_and_si256(
        _mm256_xor_si256(_mm256_xor_si256(v, n), _mm256_slli_epi32(_mm256_xor_si256(n, even), 1)),
        low);
    k = _mm256_permutevar8x32_epi32(k, order);
    __m128i k16 = _mm_packus_epi32(_mm256_castsi256_si128(k), _mm256_extracti128_si256(k, 1));
    _mm_storeu_si128((__m128i *)(void *)&key[i], k16);
    if (_mm256_movemask_pd(bad))
      for (size_t q = i; q < i + 8; q++) key[q] = (uint16_t)key_by_lines(j, p[q].x, p[q].y);
  }
  for (; i + 4 <= m; i += 4) {
    __m256d a = _mm256_loadu_pd(&p[i].x), b = _mm256_loadu_pd(&p[i + 2].x);
    __m256d ta = _mm256_mul_pd(_mm256_sub_pd(a, o), sc),
            tb = _mm256_mul_pd(_mm256_sub_pd(b, o), sc);
    __m128i ia = _mm256_cvttpd_epi32(ta), ib = _mm256_cvttpd_epi32(tb);
    __m256d fa = _mm256_sub_pd(ta, _mm256_cvtepi32_pd(ia));
    __m256d fb = _mm256_sub_pd(tb, _mm256_cvtepi32_pd(ib));
    __m256d bad = _mm256_or_pd(
        _mm256_or_pd(_mm256_cmp_pd(fa, lo, _CMP_LT_OQ), _mm256_cmp_pd(fa, hi, _CMP_GT_OQ)),
        _mm256_or_pd(_mm256_cmp_pd(fb, lo, _CMP_LT_OQ), _mm256_cmp_pd(fb, hi, _CMP_GT_OQ)));
    /* cx0 cy0 cx1 cy1 cx2 cy2 cx3 cy3, each spread to the even bits */
    __m256i v = _mm256_inserti128_si256(_mm256_castsi128_si256(ia), ib, 1);
    v = _mm256_and_si256(_mm256_or_si256(v, _mm256_slli_epi32(v, 4)), m4);
    v = _mm256_and_si256(_mm256_or_si256(v, _mm256_slli_epi32(v, 2)), m2);
    v = _mm256_and_si256(_mm256_or_si256(v, _mm256_slli_epi32(v, 1)), m1);
    __m256i n = _mm256_srli_epi64(v, 32); /* each point's north bits under its east bits */
    __m256i k =
        _mm256_xor_si256(_mm256_xor_si256(v, n), _mm256_slli_epi32(_mm256_xor_si256(n, even), 1));
    k = _mm256_permutevar8x32_epi32(k, pick);
    __m128i k16 = _mm_packus_epi32(_mm256_castsi256_si128(k), _mm256_castsi256_si128(k));
    _mm_storel_epi64((__m128i *)(void *)&key[i], k16);
    if (_mm256_movemask_pd(bad))
      for (size_t q = i; q < i + 4; q++) key[q] = (uint16_t)key_by_lines(j, p[q].x, p[q].y);
  }
  for (; i < m; i++) key[i] = (uint16_t)key_by_lines(j, p[i].x, p[i].y);
}
#endif

/* The keys of m points (m <= BLOCK). */
static void keys_block(const bucket_job_t *j, const qk_point_t *p, size_t m, uint16_t *key) {
#if QK__CELL_AVX2
  if (j->avx2) {
    keys_avx2(j, p, m, key);
    return;
  }
#endif
#if defined(__SSE2__)
  /* Both axes at once: scale, truncate, and compare with the two lines of each guess. */
  const __m128d o = _mm_setr_pd(j->x0, j->y0), sc = _mm_set1_pd(j->scale);
  const axis_tab_t *ax = j->ax, *ay = j->ay;
  for (size_t i = 0; i < m; i++) {
    QK__PREFETCH_PTS(&p[i]);
    __m128d v = _mm_loadu_pd(&p[i].x);
    __m128i c = _mm_cvttpd_epi32(_mm_mul_pd(_mm_sub_pd(v, o), sc));
    uint32_t cx = (uint32_t)_mm_cvtsi128_si32(c), cy = (uint32_t)_mm_extract_epi16(c, 2);
    int mx = _mm_movemask_pd(_mm_cmpgt_pd(_mm_unpacklo_pd(v, v), _mm_loadu_pd(ax->line[cx])));
    int my = _mm_movemask_pd(_mm_cmpgt_pd(_mm_unpackhi_pd(v, v), _mm_loadu_pd(ay->line[cy])));
    key[i] = (uint16_t)(ax->dig[4 * cx + (uint32_t)mx] ^ ay->dig[4 * cy + (uint32_t)my]);
  }
#else
  for (size_t i = 0; i < m; i++) key[i] = (uint16_t)key_by_lines(j, p[i].x, p[i].y);
#endif
}

/* Write one write-combining buffer's worth (WC records, whole cache lines at a 64-byte
 * aligned place) around the caches, or through them. */
static void flush_wc(rec_t *d, const rec_t *s, bool stream) {
#if defined(__SSE2__)
  if (stream) {
    __m128i *o = (__m128i *)(void *)d;
    const __m128i *i = (const __m128i *)(const void *)s;
    /* a line of four stores a step, unrolled by hand */
    for (unsigned q = 0; q < WC * sizeof(rec_t) / 16; q += 4) {
      __m128i a = i[q], b = i[q + 1], c = i[q + 2], e = i[q + 3];
      _mm_stream_si128(o + q, a);
      _mm_stream_si128(o + q + 1, b);
      _mm_stream_si128(o + q + 2, c);
      _mm_stream_si128(o + q + 3, e);
    }
    return;
  }
#else
  (void)stream;
#endif
  memcpy(d, s, WC * sizeof *d);
}

#if QK__CELL_AVX2
/* flush_wc()'s streaming path 32 bytes a store: two loads and two stores a line instead
 * of four each (both places are 64-byte aligned). */
__attribute__((target("avx"))) static void flush_wc_avx(rec_t *d, const rec_t *s) {
  __m256i *o = (__m256i *)(void *)d;
  const __m256i *i = (const __m256i *)(const void *)s;
  for (unsigned q = 0; q < WC * sizeof(rec_t) / 32; q += 2) {
    __m256i a = _mm256_load_si256(i + q), b = _mm256_load_si256(i + q + 1);
    _mm256_stream_si256(o + q, a);
    _mm256_stream_si256(o + q + 1, b);
  }
}
#endif

/* Pass 1 for share w: every point's cell, and the share's count of every cell and of
 * every coarse bucket. */
static void keys_job(unsigned w, unsigned thread, void *ctx) {
  (void)thread;
  const bucket_job_t *j = ctx;
  size_t lo, hi;
  qk__share_range(j->n, w, j->ns, &lo, &hi);
  uint32_t *h = j->hist + (size_t)w * j->nb;
  const qk_point_t *p = j->p;
  uint16_t *key = j->key;
  memset(h, 0, j->nb * sizeof *h);
  for (size_t i0 = lo; i0 < hi; i0 += BLOCK) {
    size_t m = hi - i0 < BLOCK ? hi - i0 : BLOCK;
    const uint16_t *k = key + i0;
    keys_block(j, p + i0, m, key + i0);
    size_t q = 0;
    for (; q + 4 <= m; q += 4) {
      h[k[q]]++;
      h[k[q + 1]]++;
      h[k[q + 2]]++;
      h[k[q + 3]]++;
    }
    for (; q < m; q++) h[k[q]]++;
  }
  const size_t nc = j->nc, nf = (size_t)1 << j->fbits;
  for (size_t c = 0; c < nc; c++) {
    uint32_t k = 0;
    for (size_t f = 0; f < nf; f++) k += h[c * nf + f];
    j->cnt[(size_t)w * nc + c] = k;
  }
}

/* Coarse bucket c's fine buckets' starts from the shares' counts of pass 1, and the points
 * of its cells over the capacity. */
static void bucket_starts(const bucket_job_t *j, size_t c) {
  const uint32_t nf = 1u << j->fbits;
  uint32_t next[1u << (16 - MAX_COARSE_BITS)];
  memcpy(next, j->hist + c * nf, nf * sizeof *next);
  for (unsigned v = 1; v < j->ns; v++) {
    const uint32_t *h = j->hist + (size_t)v * j->nb + c * nf;
    for (uint32_t f = 0; f < nf; f++) next[f] += h[f];
  }
  uint32_t *cum = j->cum + c * nf, acc = j->cbase[c], deep = 0, cap = j->t->capacity;
  for (uint32_t f = 0; f < nf; f++) {
    uint32_t k = next[f];
    cum[f] = acc;
    acc += k;
    deep += k > cap ? k : 0;
  }
  j->deep[c] = deep;
}

#if QK__CELL_AVX2
/* The scatter's buckets and tags of a block, sixteen keys a step (the compiler's SSE2 loop
 * took 3.8 instructions a point): cb[q] = k[q] >> fbits, tag[q] = tq + (q << fbits) +
 * (k[q] & mask). Returns how many were done (a multiple of 16). */
__attribute__((target("avx2"))) static size_t
tags_avx2(const uint16_t *k, size_t m, uint32_t tq, unsigned fbits, uint16_t *cb, uint32_t *tag) {
  const __m128i sh = _mm_cvtsi32_si128((int)fbits);
  const __m256i mask = _mm256_set1_epi32((int)((1u << fbits) - 1));
  const __m256i lane =
      _mm256_sllv_epi32(_mm256_setr_epi32(0, 1, 2, 3, 4, 5, 6, 7), _mm256_set1_epi32((int)fbits));
  const __m256i eight = _mm256_set1_epi32((int)(8u << fbits));
  __m256i t = _mm256_add_epi32(_mm256_set1_epi32((int)tq), lane);
  size_t q = 0;
  for (; q + 16 <= m; q += 16) {
    __m256i v = _mm256_loadu_si256((const __m256i *)(const void *)&k[q]);
    __m256i c = _mm256_srl_epi16(v, sh);
    _mm256_storeu_si256((__m256i *)(void *)&cb[q], c);
    __m256i lo = _mm256_cvtepu16_epi32(_mm256_castsi256_si128(v));
    __m256i hi = _mm256_cvtepu16_epi32(_mm256_extracti128_si256(v, 1));
    _mm256_storeu_si256((__m256i *)(void *)&tag[q], _mm256_or_si256(t, _mm256_and_si256(lo, mask)));
    t = _mm256_add_epi32(t, eight);
    _mm256_storeu_si256((__m256i *)(void *)&tag[q + 8],
                        _mm256_or_si256(t, _mm256_and_si256(hi, mask)));
    t = _mm256_add_epi32(t, eight);
  }
  return q;
}
#endif

/* Where the next record of a bucket goes in the write-combining buffers, in bytes, and
 * where its buffer ends: side by side, so that a point's bucket number indexes both with
 * one address (two arrays took a shift and an address computation a point more). */
typedef struct wc_at {
  uint32_t off, end;
} wc_at_t;

/* One point into its bucket's write-combining buffer as a record (its coordinates and
 * tag); a full buffer goes to the bucket's next WC records of the record array, through
 * the caches (mode 0) or around them (1: SSE2, 2: AVX). */
static QK__ALWAYS_INLINE void put_rec(unsigned char *bytes, wc_at_t *at, uint32_t *next, rec_t *rec,
                                      const qk_point_t *pt, uint32_t c, uint32_t tag,
                                      unsigned mode) {
  uint32_t o = at[c].off;
  memcpy(bytes + o, pt, 16);
  memcpy(bytes + o + 16, &tag, 4);
  o += (uint32_t)sizeof(rec_t);
  if (QK__UNLIKELY(o == at[c].end)) {
    /* next[c] is a multiple of WC and the array 64-byte aligned: whole lines */
    o -= WC * (uint32_t)sizeof(rec_t);
    const rec_t *src = (const rec_t *)(const void *)(bytes + o);
#if QK__CELL_AVX2
    if (mode == 2)
      flush_wc_avx(&rec[next[c]], src);
    else
#endif
      flush_wc(&rec[next[c]], src, mode != 0);
    next[c] += WC;
  }
  at[c].off = o;
}

/* Pass 2 for share w: the points as records into their coarse buckets' segments, stable.
 * Each bucket's records gather in a buffer of WC (twenty cache lines) that goes to memory
 * whole, with non-temporal stores for large inputs: no line of the record array is read
 * before it is written, and 2^8 buffers, unlike 2^8 scattered write streams, stay in
 * cache. */
static void scatter_job(unsigned w, unsigned thread, void *ctx) {
  const bucket_job_t *j = ctx;
  size_t lo, hi;
  qk__share_range(j->n, w, j->ns, &lo, &hi);
  const size_t nc = j->nc;
  const qk_point_t *p = j->p;
  const uint16_t *key = j->key;
  rec_t *rec = j->rec;
  const unsigned fbits = j->fbits;
  const uint32_t mask = (1u << fbits) - 1;
  const bool stream = j->stream;
  const unsigned mode = !stream ? 0u : j->avx2 ? 2u : 1u;
  uint32_t next[1u << MAX_COARSE_BITS]; /* where bucket c's next buffer goes */
  wc_at_t at[1u << MAX_COARSE_BITS];    /* bucket c's place in buf */
  rec_t *buf = (rec_t *)(void *)(j->wcb + (size_t)thread * nc * WC * sizeof(rec_t));
  _Alignas(16) uint32_t tag[BLOCK];
  _Alignas(32) uint16_t cb[BLOCK];
  for (size_t c = 0; c < nc; c++) {
    next[c] = j->seg[(size_t)w * nc + c];
    at[c].off = (uint32_t)(c * WC * sizeof(rec_t));
    at[c].end = (uint32_t)((c + 1) * WC * sizeof(rec_t));
  }
  unsigned char *bytes = buf[0].b;
  for (size_t i0 = lo; i0 < hi; i0 += BLOCK) {
    size_t m = hi - i0 < BLOCK ? hi - i0 : BLOCK;
    const uint16_t *k = key + i0;
    /* The block's buckets and tags in a loop of their own (vectorised: by hand with AVX2),
     * so that the scatter loop does little more than copy. */
    uint32_t tq = (uint32_t)(j->gid ? i0 : i0 - lo) << fbits;
    const uint32_t step = 1u << fbits;
    size_t q0 = 0;
#if QK__CELL_AVX2
    if (j->avx2) q0 = tags_avx2(k, m, tq, fbits, cb, tag);
    tq += (uint32_t)q0 << fbits;
#endif
    for (size_t q = q0; q < m; q++, tq += step) {
      cb[q] = (uint16_t)(k[q] >> fbits);
      tag[q] = tq | (k[q] & mask);
    }
    const qk_point_t *pp = p + i0;
    size_t q = 0;
    /* Four points a step, with one prefetch for their line of the input. */
    for (; q + 4 <= m; q += 4) {
      QK__PREFETCH_PTS(&pp[q]);
      put_rec(bytes, at, next, rec, &pp[q], cb[q], tag[q], mode);
      put_rec(bytes, at, next, rec, &pp[q + 1], cb[q + 1], tag[q + 1], mode);
      put_rec(bytes, at, next, rec, &pp[q + 2], cb[q + 2], tag[q + 2], mode);
      put_rec(bytes, at, next, rec, &pp[q + 3], cb[q + 3], tag[q + 3], mode);
    }
    for (; q < m; q++) put_rec(bytes, at, next, rec, &pp[q], cb[q], tag[q], mode);
  }
  for (size_t c = 0; c < nc; c++) {
    uint32_t fill = (uint32_t)(at[c].off - c * WC * sizeof(rec_t)) / (uint32_t)sizeof(rec_t);
    memcpy(&rec[next[c]], &buf[c * WC], fill * sizeof *rec);
  }
#if defined(__SSE2__)
  if (stream) _mm_sfence(); /* the streamed lines before anything the caller does next */
#endif
  /* The bucket starts, a share of the buckets each, so that the whole tree can be read off
   * them before (or while) the fine pass runs. */
  for (size_t c = w; c < nc; c += j->ns) bucket_starts(j, c);
}

static void keys_share(void *ctx, unsigned w, unsigned nw) {
  (void)nw;
  keys_job(w, w, ctx);
}

static void scatter_share(void *ctx, unsigned w, unsigned nw) {
  (void)nw;
  scatter_job(w, w, ctx);
}

/* Run a pass over the shares: share w on thread w when there are as many, else as jobs. */
static void run_pass(const bucket_job_t *j, qk__share_fn share,
                     void (*job)(unsigned, unsigned, void *)) {
  if (j->ns == j->nw) /* not two shares on a thread that happened to start first */
    qk__run_shares(j->nw, share, (void *)j);
  else
    qk__run_jobs_dynamic(j->nw, j->ns, job, (void *)j);
}

#if QK__CELL_AVX2
/* copy_out()'s streaming copy, 32 bytes per store. */
__attribute__((target("avx2"))) static void stream_avx2(unsigned char *d, const unsigned char *s,
                                                        size_t bytes) {
  size_t head = (size_t)(-(uintptr_t)d & 31u);
  if (head > bytes) head = bytes;
  memcpy(d, s, head);
  d += head, s += head, bytes -= head;
  for (; bytes >= 64; d += 64, s += 64, bytes -= 64) {
    __m256i a = _mm256_loadu_si256((const __m256i *)(const void *)s);
    __m256i b = _mm256_loadu_si256((const __m256i *)(const void *)(s + 32));
    _mm256_stream_si256((__m256i *)(void *)d, a);
    _mm256_stream_si256((__m256i *)(void *)(d + 32), b);
  }
  memcpy(d, s, bytes);
}
#endif

/* Copy `bytes` from src to dst, with non-temporal stores where `stream` asks. */
static void copy_out(void *dst, const void *src, size_t bytes, bool stream, bool avx2) {
#if QK__CELL_AVX2
  if (stream && avx2) {
    stream_avx2(dst, src, bytes);
    return;
  }
#else
  (void)avx2;
#endif
#if defined(__SSE2__)
  if (stream) {
    unsigned char *d = dst;
    const unsigned char *s = src;
    size_t head = (size_t)(-(uintptr_t)d & 15u);
    if (head > bytes) head = bytes;
    memcpy(d, s, head);
    d += head, s += head, bytes -= head;
    for (; bytes >= 64; d += 64, s += 64, bytes -= 64) {
      __m128i a = _mm_loadu_si128((const __m128i *)(const void *)s);
      __m128i b = _mm_loadu_si128((const __m128i *)(const void *)(s + 16));
      __m128i c = _mm_loadu_si128((const __m128i *)(const void *)(s + 32));
      __m128i e = _mm_loadu_si128((const __m128i *)(const void *)(s + 48));
      _mm_stream_si128((__m128i *)(void *)d, a);
      _mm_stream_si128((__m128i *)(void *)(d + 16), b);
      _mm_stream_si128((__m128i *)(void *)(d + 32), c);
      _mm_stream_si128((__m128i *)(void *)(d + 48), e);
    }
    memcpy(d, s, bytes);
    return;
  }
#else
  (void)stream;
#endif
  memcpy(dst, src, bytes);
}

/* Record r to slot d: its coordinates at px[d] and py[d], its id at pid[d]. */
static QK__ALWAYS_INLINE void put_record(const rec_t *r, uint32_t d, qk_id_t id, double *px,
                                         double *py, qk_id_t *pid) {
  memcpy(&px[d], r->b, 8);
  memcpy(&py[d], r->b + 8, 8);
  pid[d] = id;
}

/* Share v's segment of coarse bucket c: its records [*r, *e), and the id of its share's
 * first point (0 when the records carry global ids). */
static QK__ALWAYS_INLINE uint32_t share_segment(const bucket_job_t *j, unsigned c, unsigned v,
                                                bool gid, const rec_t **r, const rec_t **e) {
  size_t lo, hi, k = (size_t)v * j->nc + c;
  qk__share_range(j->n, v, j->ns, &lo, &hi);
  *r = j->rec + j->seg[k], *e = *r + j->cnt[k];
  return gid ? 0u : (uint32_t)lo;
}

/* Record r (its digits g) staged: to slot at[f] / 4 of fine digit f, at[f] += 4. */
static QK__ALWAYS_INLINE void stage_record(const rec_t *r, uint32_t g, uint32_t *at,
                                           unsigned char *sxy, unsigned char *sid, uint32_t id0,
                                           uint32_t mask, unsigned fbits) {
  uint32_t d = at[g & mask];
  at[g & mask] = d + 4;
  uint32_t i = id0 + (g >> fbits);
  memcpy(sxy + 4 * (size_t)d, r->b, 16);
  memcpy(sid + d, &i, 4);
}

/* Where fine_bucket() puts a record: staged (at, sxy, sid), or straight to the point
 * arrays (the slots next, px, py, pid). */
typedef struct fine_dst {
  uint32_t *slot; /* next[f], or at[f] in bytes of ids */
  double *px, *py;
  qk_id_t *pid;
  unsigned char *sxy, *sid;
} fine_dst_t;

/* The records of coarse bucket c, every share's segment in turn, each to the place of
 * its fine digit f (the low fbits of its tag) in d: staged (a constant here), or slot
 * next[f]++ of the point arrays. Two records a step: the second's slot is taken after the
 * first's, as one at a time would (they may share a fine bucket). The records come from
 * memory (written around the caches) and are read ahead by hand, about 4 KB: the
 * hardware's prefetch alone left the pass a fifth slower on one thread (4.4-4.6 against
 * 3.5-3.7 ms at 1M). */
static QK__ALWAYS_INLINE void fine_bucket(const bucket_job_t *j, unsigned c, bool gid,
                                          unsigned fbits, bool staged, const fine_dst_t *d) {
  const uint32_t mask = (1u << fbits) - 1;
  for (unsigned v = 0; v < j->ns; v++) {
    const rec_t *r, *e;
    const uint32_t id0 = share_segment(j, c, v, gid, &r, &e);
#define QK__PLACE(rp, g)                                                                           \
  (staged ? stage_record((rp), (g), d->slot, d->sxy, d->sid, id0, mask, fbits)                     \
          : put_record((rp), d->slot[(g)&mask]++, id0 + ((g) >> fbits), d->px, d->py, d->pid))
    for (; r + 2 <= e; r += 2) {
      QK__PREFETCH((const void *)((uintptr_t)r + PREFETCH_RECS * sizeof *r));
      uint32_t g0, g1;
      memcpy(&g0, r[0].b + 16, 4);
      memcpy(&g1, r[1].b + 16, 4);
      QK__PLACE(&r[0], g0);
      QK__PLACE(&r[1], g1);
    }
    if (r < e) {
      uint32_t g;
      memcpy(&g, r->b + 16, 4);
      QK__PLACE(r, g);
    }
#undef QK__PLACE
  }
}

/* fine_bucket() to the point arrays (a bucket too large for the staging arrays). */
static QK__ALWAYS_INLINE void fine_records(const bucket_job_t *j, unsigned c, uint32_t *next,
                                           double *px, double *py, qk_id_t *pid, bool gid) {
  const fine_dst_t d = {.slot = next, .px = px, .py = py, .pid = pid};
  fine_bucket(j, c, gid, j->fbits, false, &d);
}

/* fine_bucket() into the staging arrays: the record of fine digit f to staged slot
 * at[f] / 4 (at[f] += 4), its pair at byte 16 d of sxy and its id at byte 4 d of sid. The
 * slots counted in bytes of ids, which the pair's place scales by four in its address: a
 * slot number took a copy and a shift more a record. The digit's bits as a constant where
 * they are the deepest grid's eight (a byte: one move for the mask). */
static QK__ALWAYS_INLINE void fine_staged(const bucket_job_t *j, unsigned c, uint32_t *at,
                                          unsigned char *sxy, unsigned char *sid, bool gid,
                                          unsigned fbits) {
  const fine_dst_t d = {.slot = at, .sxy = sxy, .sid = sid};
  fine_bucket(j, c, gid, fbits, true, &d);
}

#if QK__CELL_AVX2
/* copy_pairs()'s streaming path eight points a step, 32 bytes a store for x on a 32-byte
 * boundary (2.4 instructions a point instead of 5), and for y too when it falls on one
 * with x; else (y_half: y 16 bytes off, the usual case for two blocks from malloc) y
 * takes two 16-byte stores. */
__attribute__((target("avx2"))) static QK__ALWAYS_INLINE void
pairs_avx2_body(double *x, double *y, const double *xy, size_t m, bool y_half) {
  size_t i = 0;
  for (; i < m && ((uintptr_t)(x + i) & 31u); i++) {
    x[i] = xy[2 * i];
    y[i] = xy[2 * i + 1];
  }
  for (; i + 8 <= m; i += 8) {
    /* a = x0 y0 x1 y1, b = x2 y2 x3 y3: unpacked within the halves, x0 x2 x1 x3 and
     * y0 y2 y1 y3, then the middle two swapped */
    __m256d a = _mm256_loadu_pd(xy + 2 * i), b = _mm256_loadu_pd(xy + 2 * i + 4);
    __m256d c = _mm256_loadu_pd(xy + 2 * i + 8), d = _mm256_loadu_pd(xy + 2 * i + 12);
    __m256d y0 = _mm256_permute4x64_pd(_mm256_unpackhi_pd(a, b), 0xd8);
    __m256d y1 = _mm256_permute4x64_pd(_mm256_unpackhi_pd(c, d), 0xd8);
    _mm256_stream_pd(x + i, _mm256_permute4x64_pd(_mm256_unpacklo_pd(a, b), 0xd8));
    _mm256_stream_pd(x + i + 4, _mm256_permute4x64_pd(_mm256_unpacklo_pd(c, d), 0xd8));
    if (y_half) {
      _mm_stream_pd(y + i, _mm256_castpd256_pd128(y0));
      _mm_stream_pd(y + i + 2, _mm256_extractf128_pd(y0, 1));
      _mm_stream_pd(y + i + 4, _mm256_castpd256_pd128(y1));
      _mm_stream_pd(y + i + 6, _mm256_extractf128_pd(y1, 1));
    } else {
      _mm256_stream_pd(y + i, y0);
      _mm256_stream_pd(y + i + 4, y1);
    }
  }
  for (; i < m; i++) {
    x[i] = xy[2 * i];
    y[i] = xy[2 * i + 1];
  }
}

__attribute__((target("avx2"))) static void pairs_avx2(double *x, double *y, const double *xy,
                                                       size_t m) {
  if (((uintptr_t)x ^ (uintptr_t)y) & 31u)
    pairs_avx2_body(x, y, xy, m, true);
  else
    pairs_avx2_body(x, y, xy, m, false);
}
#endif

/* Copy m staged coordinate pairs out to x[] and y[], with non-temporal stores where
 * `stream` asks and both destinations fall on 16-byte boundaries together (with AVX2 where
 * the processor has it: x 32 bytes a store, and y too when it is 32-byte aligned with x). */
static void copy_pairs(double *x, double *y, const double *xy, size_t m, bool stream, bool avx2) {
  size_t i = 0;
#if QK__CELL_AVX2
  if (stream && avx2 && (((uintptr_t)x ^ (uintptr_t)y) & 15u) == 0 && ((uintptr_t)x & 7u) == 0) {
    pairs_avx2(x, y, xy, m);
    return;
  }
#else
  (void)avx2;
#endif
#if defined(__SSE2__)
  if (m && (((uintptr_t)x ^ (uintptr_t)y) & 15u) == 0 && ((uintptr_t)x & 7u) == 0) {
    if ((uintptr_t)x & 15u) {
      x[0] = xy[0];
      y[0] = xy[1];
      i = 1;
    }
    if (stream) {
      for (; i + 4 <= m; i += 4) {
        __m128d a = _mm_loadu_pd(xy + 2 * i), b = _mm_loadu_pd(xy + 2 * i + 2);
        __m128d c = _mm_loadu_pd(xy + 2 * i + 4), d = _mm_loadu_pd(xy + 2 * i + 6);
        _mm_stream_pd(x + i, _mm_unpacklo_pd(a, b));
        _mm_stream_pd(y + i, _mm_unpackhi_pd(a, b));
        _mm_stream_pd(x + i + 2, _mm_unpacklo_pd(c, d));
        _mm_stream_pd(y + i + 2, _mm_unpackhi_pd(c, d));
      }
    } else {
      for (; i + 2 <= m; i += 2) {
        __m128d a = _mm_loadu_pd(xy + 2 * i), b = _mm_loadu_pd(xy + 2 * i + 2);
        _mm_store_pd(x + i, _mm_unpacklo_pd(a, b));
        _mm_store_pd(y + i, _mm_unpackhi_pd(a, b));
      }
    }
  }
#else
  (void)stream;
#endif
  for (; i < m; i++) {
    x[i] = xy[2 * i];
    y[i] = xy[2 * i + 1];
  }
}

/* Pass 3: coarse bucket c sorted by its low digit into the point arrays, stable, and its
 * fine buckets' starts from the shares' counts of pass 1. The sort writes all over the bucket's
 * slot range; when the range fits the share's staging arrays, it writes there (in cache, reused
 * from bucket to bucket) and the range is then copied out in order, so that the point arrays are
 * written front to back rather than line by line at random. */
static void fine_job(unsigned c, unsigned w, void *ud) {
  const bucket_job_t *j = ud;
  uint32_t a = j->cbase[c], b = j->cbase[c + 1];
  const uint32_t nf = 1u << j->fbits;
  uint32_t next[1u << (16 - MAX_COARSE_BITS)];
  const uint32_t *cum = j->cum + (size_t)c * nf;
  if (b - a <= j->stage_cap) {
    /* Staged: coordinates as pairs (one line written a point, not two) and ids. */
    for (uint32_t f = 0; f < nf; f++) next[f] = 4 * (cum[f] - a);
    double *sxy = j->sxy + (size_t)w * 2 * j->stage_cap;
    qk_id_t *sid = j->sid + (size_t)w * j->stage_cap;
    unsigned char *bxy = (unsigned char *)sxy, *bid = (unsigned char *)sid;
    /* The tags' ids without an addition a record where they are the input's indices. */
    if (j->gid && j->fbits == 8)
      fine_staged(j, c, next, bxy, bid, true, 8);
    else if (j->gid)
      fine_staged(j, c, next, bxy, bid, true, j->fbits);
    else
      fine_staged(j, c, next, bxy, bid, false, j->fbits);
    copy_pairs(j->t->px + a, j->t->py + a, sxy, b - a, j->stream, j->avx2);
    copy_out(j->t->pid + a, sid, (size_t)(b - a) * sizeof *sid, j->stream, j->avx2);
#if defined(__SSE2__)
    if (j->stream) _mm_sfence();
#endif
  } else {
    for (uint32_t f = 0; f < nf; f++) next[f] = cum[f];
    fine_records(j, c, next, j->t->px, j->t->py, j->t->pid, j->gid);
  }
}

/* The fine pass beside a hook (qk__cell_hook_t): share 0 runs the hook first, then every
 * share takes buckets in order from a counter. A bucket is claimed once (0 free, 1
 * claimed, 2 sorted); the hook, waiting for a cell, sorts the cell's bucket itself when no
 * share has claimed it, so it never waits for a share that has not started (a thread that
 * could not be created runs its share after share 0), and sorts other buckets while a
 * running share sorts the one it waits for. */
struct qk__cell_wait {
  const bucket_job_t *j;
  qk__cell_hook_t *hook;
  size_t deep; /* the points in cells over the capacity, for the hook */
  atomic_uint next;
  atomic_uchar state[1u << MAX_COARSE_BITS];
};

static bool claim(qk__cell_wait_t *s, unsigned c) {
  unsigned char free = 0;
  return atomic_compare_exchange_strong_explicit(&s->state[c], &free, 1, memory_order_relaxed,
                                                 memory_order_relaxed);
}

static void sort_claimed(qk__cell_wait_t *s, unsigned c, unsigned w) {
  fine_job(c, w, (void *)s->j);
  atomic_store_explicit(&s->state[c], 2, memory_order_release);
}

void qk__cell_wait(qk__cell_wait_t *s, uint32_t cell) {
  unsigned c = cell >> s->j->fbits;
  if (atomic_load_explicit(&s->state[c], memory_order_acquire) == 2) return;
  if (claim(s, c)) {
    sort_claimed(s, c, 0); /* the hook runs in share 0 */
    return;
  }
  /* Claimed by a running share: meanwhile sort the buckets no share has taken yet, then,
   * when none is left, wait for the rest of that one (a bucket's sort: tens of
   * microseconds). */
  for (unsigned spins = 0; atomic_load_explicit(&s->state[c], memory_order_acquire) != 2;) {
    if (atomic_load_explicit(&s->next, memory_order_relaxed) < s->j->nc) {
      unsigned k = atomic_fetch_add_explicit(&s->next, 1u, memory_order_relaxed);
      if (k < s->j->nc && claim(s, k)) sort_claimed(s, k, 0);
    } else if (++spins >= 64) {
      qk__thread_yield();
    }
  }
}

static void hook_share(void *ctx, unsigned w, unsigned nw) {
  (void)nw;
  qk__cell_wait_t *s = ctx;
  if (w == 0) s->hook->st = s->hook->fn(s->hook->ctx, s->j->cum, s->deep, s);
  for (;;) {
    unsigned c = atomic_fetch_add_explicit(&s->next, 1u, memory_order_relaxed);
    if (c >= s->j->nc) return;
    if (claim(s, c)) sort_claimed(s, c, w);
  }
}

/* The temporary arrays of the bucketed build. */
typedef struct scratch {
  uint32_t *cum, *cbase, *cnt, *seg, *hist, *deep;
  uint16_t *key;
  void *rec_block; /* rec, before alignment */
  void *wc_block;  /* the write-combining buffers, before alignment */
  double *sxy;
  qk_id_t *sid;
  size_t nb, nc, n, ns, n_rec, rec_bytes, n_stage, wc_bytes;
} scratch_t;

/* Free the scratch; the record block goes to the tree instead when it keeps one. */
static void scratch_free(qk_tree_t *t, scratch_t *s) {
  if (t->keep_rec && s->rec_block && !t->kept_rec) {
    t->kept_rec = s->rec_block, t->kept_rec_bytes = s->rec_bytes;
    s->rec_block = NULL;
  }
  qk__free(&t->alloc, s->cum, (s->nb + 1) * sizeof *s->cum);
  qk__free(&t->alloc, s->cbase, (s->nc + 1) * sizeof *s->cbase);
  qk__free(&t->alloc, s->deep, s->nc * sizeof *s->deep);
  qk__free(&t->alloc, s->cnt, s->ns * s->nc * sizeof *s->cnt);
  qk__free(&t->alloc, s->seg, s->ns * s->nc * sizeof *s->seg);
  qk__free(&t->alloc, s->hist, s->ns * s->nb * sizeof *s->hist);
  qk__free(&t->alloc, s->key, s->n * sizeof *s->key);
  qk__free(&t->alloc, s->rec_block, s->rec_bytes);
  qk__free(&t->alloc, s->wc_block, s->wc_bytes);
  qk__free(&t->alloc, s->sxy, 2 * s->n_stage * sizeof *s->sxy);
  qk__free(&t->alloc, s->sid, s->n_stage * sizeof *s->sid);
  memset(s, 0, sizeof *s);
}

qk_status_t qk__cell_sort(qk_tree_t *t, const qk_point_t *p, size_t n, unsigned L, unsigned nw,
                          qk__cell_hook_t *hook, uint32_t **cum, size_t *deep) {
  *cum = NULL;
  *deep = 0;
  /* Margin in grid units: rounding of the corner arithmetic (at most one rounding per
   * level) and of the scaling, with a factor of four to spare. Below a quarter cell, a
   * truncated coordinate is off by at most one cell, which the key pass corrects. */
  double x0 = t->root_x, y0 = t->root_y, side = t->side[0];
  double M = fmax(fmax(fabs(x0), fabs(x0 + side)), fmax(fabs(y0), fabs(y0 + side)));
  double cells = (double)(1u << L), scale = cells / side;
  double ulpM = nextafter(M, INFINITY) - M;
  double delta = 4 * (((L + 2) * ulpM + 2 * ulpM) * scale + cells * 4 * DBL_EPSILON);
  if (!(delta < 0.25)) return QK_OK; /* badly conditioned: the plain build */
  double g[258];
  axis_tab_t tabs[2];
  if (!grid_lines(t, x0, L, g)) return QK_OK;
  axis_tables(g, L, false, &tabs[0]);
  if (!grid_lines(t, y0, L, g)) return QK_OK;
  axis_tables(g, L, true, &tabs[1]);

  /* The high digit: half the key's bits, rounded up, and at most MAX_COARSE_BITS. */
  unsigned kbits = 2 * L, cbits = (kbits + 1) / 2;
  if (cbits > MAX_COARSE_BITS) cbits = MAX_COARSE_BITS;
  unsigned fbits = kbits - cbits;
  size_t nb = (size_t)1 << kbits, nc = (size_t)1 << cbits;
  /* Shares: one per thread, and more where a share would have more than 2^19 points. A tag
   * numbers 2^(32 - fbits) >= 2^24 points; the lower bound also has every input of more than
   * 2^19 points (the tests' too) sorted in several shares, on any number of threads. */
  size_t per = (size_t)1 << 19, ns = (n + per - 1) / per;
  if (ns < nw) ns = nw;
  scratch_t s = {0};
  s.nb = nb, s.nc = nc, s.n = n, s.ns = ns;
  s.cum = qk__realloc(&t->alloc, NULL, 0, (nb + 1) * sizeof *s.cum);
  s.cbase = qk__realloc(&t->alloc, NULL, 0, (nc + 1) * sizeof *s.cbase);
  s.deep = qk__realloc(&t->alloc, NULL, 0, nc * sizeof *s.deep);
  s.cnt = qk__realloc(&t->alloc, NULL, 0, ns * nc * sizeof *s.cnt);
  s.seg = qk__realloc(&t->alloc, NULL, 0, ns * nc * sizeof *s.seg);
  s.hist = qk__realloc(&t->alloc, NULL, 0, ns * nb * sizeof *s.hist);
  s.key = qk__realloc(&t->alloc, NULL, 0, n * sizeof *s.key);
  if (!s.cum || !s.cbase || !s.deep || !s.cnt || !s.seg || !s.hist || !s.key) {
    scratch_free(t, &s);
    return QK_ERR_NOMEM;
  }
  /* Large inputs go around the caches: their records and points would not stay there. */
  bool stream = n >= ((size_t)1 << 19);
  bucket_job_t j = {0};
  j.t = t, j.p = p, j.n = n, j.x0 = x0, j.y0 = y0, j.scale = scale;
  j.ax = &tabs[0], j.ay = &tabs[1], j.fbits = fbits, j.nc = nc, j.stream = stream;
  j.key = s.key, j.hist = s.hist, j.nb = nb, j.seg = s.seg;
  j.cnt = s.cnt, j.cbase = s.cbase, j.cum = s.cum, j.deep = s.deep, j.nw = nw, j.ns = (unsigned)ns;
  j.near = delta;
  j.even = (uint32_t)qk__spread16((1u << L) - 1);
  /* Up to 2^(32 - fbits) points (2^24 at the deepest grid), a tag holds the index itself. */
  j.gid = ((uint64_t)n << fbits) <= ((uint64_t)1 << 32);
#if QK__CELL_AVX2
  j.avx2 = qk__build_avx2();
#endif
  run_pass(&j, keys_share, keys_job);
  /* The buckets' starts, and each share's segment of every bucket: the shares before it
   * come first, so the order is the one thread's. Segments start at multiples of WC. */
  uint32_t acc = 0, most = 0;
  size_t at = 0;
  for (size_t c = 0; c < nc; c++) {
    s.cbase[c] = acc;
    for (size_t w = 0; w < ns; w++) {
      uint32_t k = s.cnt[w * nc + c];
      s.seg[w * nc + c] = (uint32_t)at;
      at += (k + WC - 1) / WC * WC;
      acc += k;
    }
    if (acc - s.cbase[c] > most) most = acc - s.cbase[c];
  }
  s.cbase[nc] = acc;
  s.cum[nb] = acc;
  s.n_rec = at ? at : 1;
  /* From the default allocator, the record block is asked for at least as large as the
   * rest of what a build holds (the tree's point arrays and nodes by estimate, the keys,
   * the counts) and a megabyte. glibc's malloc gives the top of its heap back to the
   * system when a free leaves more there than twice the largest block it recently had to
   * map: freeing a tree after a build whose largest block were less than half of it all
   * would hand back every page, and the next build would fault them all in again (10,000
   * faults for 1M points). The excess is never touched: address space, not memory. Blocks
   * of 32 MB and more are mapped afresh whatever their size (glibc's largest mapping
   * threshold), so a rest over that asks for just under 32 MB: the heap's top then goes
   * back only past 64 MB. At small capacities, whose nodes take the rest past 32 MB at 1M
   * points, a build of capacity 4 took 175 ms rather than 37 (every page faulted in again),
   * capacity 1 226 rather than 85 (thirtieth session). */
  s.rec_bytes = s.n_rec * sizeof(rec_t) + 64;
  if (!t->alloc.fn) {
    const size_t most = ((size_t)32 << 20) - ((size_t)64 << 10);
    size_t rest = n * (2 * sizeof(double) + sizeof(qk_id_t) + sizeof *s.key) + ns * nb * 4 +
                  (4 * (n / t->capacity) + 64) * sizeof(qk__node_t) + ((size_t)1 << 20);
    size_t want = rest < most ? rest : most;
    if (s.rec_bytes < want) s.rec_bytes = want;
  }
  /* A record block kept from the last build when large enough and not four times too
   * large (a rebuilt tree: see scratch_free; a tree rebuilt smaller keeps no more than four
   * times what it needs); another goes first. */
  bool kept = false;
  if (t->kept_rec && t->kept_rec_bytes >= s.rec_bytes && t->kept_rec_bytes / 4 <= s.rec_bytes) {
    s.rec_block = t->kept_rec, s.rec_bytes = t->kept_rec_bytes, kept = true;
  } else {
    qk__free(&t->alloc, t->kept_rec, t->kept_rec_bytes);
    s.rec_block = qk__realloc(&t->alloc, NULL, 0, s.rec_bytes);
  }
  t->kept_rec = NULL, t->kept_rec_bytes = 0;
  if (!s.rec_block) {
    scratch_free(t, &s);
    return QK_ERR_NOMEM;
  }
  /* The scatter writes 2^8 streams at once: on huge pages, they need fewer TLB entries.
   * Asked for also without the tree's option when the block is over 32 MB (more than 1.6M
   * points), which glibc maps afresh for every build and unmaps when freed: each build
   * would fault in the whole block 4 KB at a time (about 20 us a fault on the machine of
   * this work). 10M uniform points on one thread: 3.03-3.06 -> 1.61-1.77 s a build. Smaller
   * blocks come from the heap, faulted once and reused: advising them too made the bench's
   * one-thread build at 1M two to three times slower on that machine (other libraries'
   * blocks come and go in the same heap between its builds), though a loop of builds alone
   * gained 3-10%. */
  if (!kept && (t->huge_pages || s.rec_bytes > ((size_t)32 << 20)))
    qk__advise_huge(&t->alloc, s.rec_block, s.n_rec * sizeof(rec_t) + 64);
  j.rec = (rec_t *)(void *)((unsigned char *)s.rec_block + (-(uintptr_t)s.rec_block & 63u));
  s.wc_bytes = (size_t)nw * nc * WC * sizeof(rec_t) + 64;
  s.wc_block = qk__realloc(&t->alloc, NULL, 0, s.wc_bytes);
  if (!s.wc_block) {
    scratch_free(t, &s);
    return QK_ERR_NOMEM;
  }
  j.wcb = (unsigned char *)s.wc_block + (-(uintptr_t)s.wc_block & 63u);
  run_pass(&j, scatter_share, scatter_job);
  qk__free(&t->alloc, s.key, n * sizeof *s.key);
  s.key = NULL;
  qk__free(&t->alloc, s.wc_block, s.wc_bytes);
  s.wc_block = NULL;
  /* Staging arrays for pass 3, each thread's as large as the largest coarse bucket up to
   * STAGE_MAX points. */
  size_t cap = most < STAGE_MAX ? most : STAGE_MAX;
  s.n_stage = nw * cap;
  s.sxy = qk__realloc(&t->alloc, NULL, 0, 2 * s.n_stage * sizeof *s.sxy);
  s.sid = qk__realloc(&t->alloc, NULL, 0, s.n_stage * sizeof *s.sid);
  if (!s.sxy || !s.sid) {
    scratch_free(t, &s);
    return QK_ERR_NOMEM;
  }
  j.stage_cap = (uint32_t)cap;
  j.sxy = s.sxy, j.sid = s.sid;
  for (size_t c = 0; c < nc; c++) *deep += s.deep[c];
  if (hook && nw > 1 && nc > 1 && !t->alloc.fn && *deep < hook->deep_below) {
    /* The hook on the calling thread beside the sort (the other threads' allocations would
     * come from arenas of their own). */
    qk__cell_wait_t wt;
    wt.j = &j;
    wt.hook = hook;
    atomic_init(&wt.next, 0u);
    for (size_t c = 0; c < nc; c++) atomic_init(&wt.state[c], 0);
    wt.deep = *deep;
    hook->ran = true;
    qk__run_shares(nw < nc ? nw : (unsigned)nc, hook_share, &wt);
  } else {
    qk__run_jobs_dynamic(nw, (unsigned)nc, fine_job, &j);
  }
  *cum = s.cum;
  s.cum = NULL;
  scratch_free(t, &s);
  return QK_OK;
}
