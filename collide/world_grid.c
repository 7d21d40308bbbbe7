/*
 * The world's sorted loose grid (see collide/world.c for the design): at each update the
 * dirty objects are filed in their new cells, sorted by cell and merged into the order of
 * the last update, from which removed and dirty slots are dropped; the same pass rebuilds
 * the cell list and packs the boxes for the pair search.
 */
#include <stdlib.h>
#include <string.h>

#include "collide/world_internal.h"
#include "index/inline.h"

#if defined(__SSE2__)
#include <emmintrin.h>
#endif

/* A dirty object to merge in: its cell as a sortable key (level, then cy, then cx, each
 * biased to unsigned), and its slot (ties: by slot, so the order is deterministic). */
typedef struct drec {
  uint64_t ly; /* (level - QK__LMIN) << 32 | biased cy */
  uint32_t x;  /* biased cx */
  uint32_t slot;
} drec_t;

/* Dirty objects from which the threads file them (merge_threads). */
#define QK__REFILE_MIN 1024

static inline uint32_t bias(int32_t v) { return (uint32_t)v ^ 0x80000000u; }
static inline int32_t unbias(uint32_t u) {
  return u >= 0x80000000u ? (int32_t)(u - 0x80000000u) : (int32_t)((int64_t)u - 0x80000000);
}

static int drec_cmp(const void *p, const void *q) {
  const drec_t *a = p, *b = q;
  if (a->ly != b->ly) return a->ly < b->ly ? -1 : 1;
  if (a->x != b->x) return a->x < b->x ? -1 : 1;
  return (a->slot > b->slot) - (a->slot < b->slot);
}

/* Sort n records by key, stably, through tmp (n entries): an LSD radix sort on the key's
 * nine bytes, skipping the bytes all records share (most of them: nearby cells). For
 * cells too far apart for drec_sort's packed keys. */
static void drec_sort_bytes(drec_t *d, drec_t *tmp, size_t n) {
  /* Keys relative to their minima, so that only the low bytes differ (a cell index of -1
   * and one of 0 differ in every byte once biased). */
  uint64_t ly_min = d[0].ly;
  uint32_t x_min = d[0].x;
  for (size_t i = 1; i < n; i++) {
    ly_min = d[i].ly < ly_min ? d[i].ly : ly_min;
    x_min = d[i].x < x_min ? d[i].x : x_min;
  }
  uint64_t ly_or = 0, ly_and = ~(uint64_t)0;
  uint32_t x_or = 0, x_and = ~0u;
  for (size_t i = 0; i < n; i++) {
    d[i].ly -= ly_min, d[i].x -= x_min;
    ly_or |= d[i].ly, ly_and &= d[i].ly;
    x_or |= d[i].x, x_and &= d[i].x;
  }
  for (int byte = 0; byte < 9; byte++) {
    int in_x = byte < 4, sh = in_x ? 8 * byte : 8 * (byte - 4);
    uint64_t differ = in_x ? (uint64_t)(x_or ^ x_and) : (ly_or ^ ly_and);
    if (!((differ >> sh) & 0xff)) continue;
    size_t count[257] = {0};
    for (size_t i = 0; i < n; i++) count[((in_x ? d[i].x : d[i].ly) >> sh & 0xff) + 1]++;
    for (int k = 1; k < 257; k++) count[k] += count[k - 1];
    for (size_t i = 0; i < n; i++) tmp[count[(in_x ? d[i].x : d[i].ly) >> sh & 0xff]++] = d[i];
    memcpy(d, tmp, n * sizeof *d);
  }
  for (size_t i = 0; i < n; i++) d[i].ly += ly_min, d[i].x += x_min;
}

/* The bits of v (0 for 0). */
static inline unsigned bits_of(uint64_t v) {
  unsigned b = 0;
  while (b < 64 && v >> b) b++;
  return b;
}

/*
 * Sort n records by key, stably, through tmp (n entries). Each record's key relative to
 * the minima (level, cy and cx each minus its least value) is packed with the record's
 * index in one 64-bit word, ((level, cy, cx) << ib | i), when the fields' ranges fit;
 * the words are sorted by an LSD radix sort of digits of at most 11 bits on the key bits
 * only (the dirty objects of a frame lie in a few levels of nearby cells: some 30 bits,
 * three passes over 8-byte words where the 8-bit digits of the records took five passes
 * over 16-byte records), and the records rebuilt from them in that order. Otherwise (cells
 * far apart) the records are sorted on their bytes (drec_sort_bytes). Both are stable, so
 * the order is the same: by key, ties in the records' order.
 */
static void drec_sort(drec_t *d, drec_t *tmp, size_t n) {
  uint64_t l0 = d[0].ly >> 32, l1 = l0;
  uint32_t y0 = (uint32_t)d[0].ly, y1 = y0, x0 = d[0].x, x1 = x0;
  for (size_t i = 1; i < n; i++) {
    uint64_t l = d[i].ly >> 32;
    uint32_t y = (uint32_t)d[i].ly, x = d[i].x;
    l0 = l < l0 ? l : l0, l1 = l > l1 ? l : l1;
    y0 = y < y0 ? y : y0, y1 = y > y1 ? y : y1;
    x0 = x < x0 ? x : x0, x1 = x > x1 ? x : x1;
  }
  const unsigned ib = bits_of(n - 1), xb = bits_of(x1 - x0), yb = bits_of(y1 - y0),
                 kb = bits_of(l1 - l0) + yb + xb;
  if (ib + kb > 64 || n > UINT32_MAX) {
    drec_sort_bytes(d, tmp, n);
    return;
  }
  if (!kb) return; /* one cell: already in order */
  /* As few digits of at most 11 bits as the key needs, each as narrow as that allows
   * (the counts' prefix sums cost 2^DB a digit: few records take narrower digits). */
  const unsigned nd = (kb + 10) / 11, DB = (kb + nd - 1) / nd; /* nd <= 6: kb <= 64 */
  const uint32_t DN = (uint32_t)1 << DB;
  uint64_t *a = (uint64_t *)tmp, *t = a + n; /* tmp: 16 n bytes */
  uint32_t cnt[6][2048];
  for (unsigned g = 0; g < (nd > 3 ? nd : 3); g++) memset(cnt[g], 0, DN * sizeof cnt[g][0]);
  /* (up to three digits, the common case, counted without a loop over the digits; the
   * counts of digits past nd are not read) */
  for (size_t i = 0; i < n; i++) {
    uint64_t k = ((d[i].ly >> 32) - l0) << (yb + xb) | (uint64_t)((uint32_t)d[i].ly - y0) << xb |
                 (d[i].x - x0);
    a[i] = k << ib | i;
    if (nd <= 3) {
      cnt[0][k & (DN - 1)]++, cnt[1][k >> DB & (DN - 1)]++, cnt[2][k >> (2 * DB) & (DN - 1)]++;
    } else {
      for (unsigned g = 0; g < nd; g++) cnt[g][k >> (DB * g) & (DN - 1)]++;
    }
  }
  for (unsigned g = 0; g < nd; g++) {
    uint32_t *c = cnt[g], acc = 0;
    int shared = 0;
    for (uint32_t x = 0; x < DN; x++) {
      uint32_t v = c[x];
      shared |= v == n;
      c[x] = acc, acc += v;
    }
    if (shared) continue;
    const unsigned sh = ib + DB * g;
    QK__UNROLL4
    for (size_t i = 0; i < n; i++) t[c[a[i] >> sh & (DN - 1)]++] = a[i];
    uint64_t *x = a;
    a = t, t = x;
  }
  /* The slots in the sorted order (in the other buffer: 8 n bytes), then the records. */
  uint32_t *sl = (uint32_t *)t;
  const uint64_t im = ((uint64_t)1 << ib) - 1;
  for (size_t i = 0; i < n; i++) sl[i] = d[a[i] & im].slot;
  const uint64_t xm = ((uint64_t)1 << xb) - 1, ym = ((uint64_t)1 << yb) - 1;
  for (size_t i = 0; i < n; i++) {
    uint64_t k = a[i] >> ib;
    d[i] = (drec_t){((k >> (yb + xb)) + l0) << 32 | (uint32_t)((k >> xb & ym) + y0),
                    (uint32_t)(k & xm) + x0, sl[i]};
  }
}

static inline drec_t rec_of(const qk__wobj_t *o, uint32_t slot) {
  return (drec_t){(uint64_t)(uint32_t)(o->level - QK__LMIN) << 32 | bias(o->cy), bias(o->u.cx),
                  slot};
}

/* Whether the loose square of cell (level, cx, cy), [c 2^level, (c + 2) 2^level) per
 * axis, lies on one side of zero with every value's magnitude in [2^-100, 2^100]
 * (QK__WCLEAN). (The products are exact: |c| < 2^30.) */
static inline int square_clean(int level, int32_t cx, int32_t cy) {
  const double s = qk__pow2(level);
  const double lo[2] = {cx * s, cy * s}, hi[2] = {(cx + 2.0) * s, (cy + 2.0) * s};
  for (int k = 0; k < 2; k++)
    if (!((lo[k] >= 0x1p-100 && hi[k] <= 0x1p100) || (lo[k] >= -0x1p100 && hi[k] <= -0x1p-100)))
      return 0;
  return 1;
}

/* File live dirty object o (slot i) in its new cell; its record. */
static inline drec_t file_dirty(const qk_world_t *w, qk__wobj_t *o, uint32_t i, bool undirty) {
  double e;
  qk_box_t f = qk__world_fat_box(w, o, &e);
  int level, forced;
  int32_t cx, cy;
  qk__world_cell_of(&f, &level, &cx, &cy, &forced);
  o->level = (int8_t)level, o->u.cx = cx, o->cy = cy;
  /* Re-filed by a move that leaves the fat box (its extent e' widened by the margins, the
   * speed's as of now) small enough for a level two steps finer, 2^level / 16: when
   * e' (1 + 2 margin) + 2 min_margin and e' + 2 step margin are both at most that. (Not
   * when its coordinates set its level.) */
  double s = qk__pow2(level) / 16, t = (s - 2 * w->opt.min_margin) / (1 + 2 * w->opt.margin);
  double ts = s - 2 * qk__world_step_margin(o->k.step, e);
  if (ts < t) t = ts;
  o->k.shrink = forced || !(t >= 0) ? -1.0f : (float)t;
  o->flags = (uint8_t)((o->flags & ~(QK__WFORCED | QK__WCLEAN | (undirty ? QK__WDIRTY : 0))) |
                       (forced ? QK__WFORCED : 0) | (square_clean(level, cx, cy) ? QK__WCLEAN : 0));
  return rec_of(o, i);
}

static inline void box_join(qk_box_t *h, const qk_box_t *b) {
  h->xmin = qk__min(h->xmin, b->xmin), h->ymin = qk__min(h->ymin, b->ymin);
  h->xmax = qk__max(h->xmax, b->xmax), h->ymax = qk__max(h->ymax, b->ymax);
}

static const qk_box_t empty_box = {INFINITY, INFINITY, -INFINITY, -INFINITY};

/* Object o at position m of the order: its float box, whether that is exact, and (with
 * h) its box joined into h. */
static inline void pack_one(const qk__wobj_t *o, float *fg, uint8_t *fx, uint32_t m, qk_box_t *h) {
  qk_box_t b =
      (o->flags & QK__WKIND) == QK_SHAPE_BOX ? (qk_box_t){o->x, o->y, o->a, o->b} : qk__wbox(o);
  if (h) box_join(h, &b);
  float *g = fg + (size_t)(m >> 2) * 16 + (m & 3);
  g[0] = (float)b.xmin, g[4] = (float)b.ymin, g[8] = (float)b.xmax, g[12] = (float)b.ymax;
  /* A box whose floats are its doubles: the float box test is then the exact one. Its
   * values are zero or of magnitude in [2^-100, 2^100], inside the floats' normal
   * range, so they are floats exactly when their last 29 mantissa bits are zero. */
  uint64_t u[4];
  memcpy(u, &b, sizeof u);
  fx[m] = (o->flags & QK__WKIND) == QK_SHAPE_BOX &&
          !((u[0] | u[1] | u[2] | u[3]) & ((UINT64_C(1) << 29) - 1));
}

/* The boxes of cells [c0, c1) of a new order: per object its float box and whether that
 * is exact, and (with cell boxes, which only the search on the grid reads) per cell the
 * box around its objects; with cell_boxes 2 each object's cell noted in it too
 * (cells_noted). Without SSE2 (pack_run_ is the same with it). */
#if !defined(__SSE2__)
static QK__ALWAYS_INLINE void pack_cells_(const qk_world_t *w, qk__wpack_t *pk, const uint32_t *ord,
                                          const qk__wcell_t *cells, uint32_t c0, uint32_t c1,
                                          const int cell_boxes) {
  float *fg = pk->fgrp;
  uint8_t *fx = pk->fexact;
  for (uint32_t c = c0; c < c1; c++) {
    qk_box_t h = empty_box;
    for (uint32_t m = cells[c].start, me = cells[c + 1].start; m < me; m++) {
      qk__wobj_t *o = &w->obj[ord[m]];
      pack_one(o, fg, fx, m, cell_boxes ? &h : NULL);
      if (cell_boxes == 2) o->cell = c;
    }
    if (cell_boxes) pk->hb[c] = h;
  }
}
#endif

#if defined(__SSE2__)
/* How far ahead the pack fetches its objects: some 0.5 us of packing at 10^5 objects, the
 * time a line takes from memory on this guest and more (16, 0.13 us, packed the huge and
 * uniform scenes' objects 3.5% slower a frame, the huge one at 10^6 6%). */
#define QK__PACK_AHEAD 64

/* The same as pack_cells_, walking the objects of cells [c0, c1) in one run instead of
 * cell by cell (most cells of a sparse world hold one or two objects, and a cell's loop
 * cost as much as its objects): four boxes filling a group are converted and stored as
 * the group's four rows (a transpose), the others one at a time, and the cell box is
 * stored where the next cell starts. A group is written whole only when it lies inside
 * the range (ranges on threads share their end groups). */
static QK__ALWAYS_INLINE void pack_run_(const qk_world_t *w, qk__wpack_t *pk, const uint32_t *ord,
                                        const qk__wcell_t *cells, uint32_t c0, uint32_t c1,
                                        const int cell_boxes) {
  if (c0 >= c1) return;
  float *fg = pk->fgrp;
  uint8_t *fx = pk->fexact;
  const __m128d inf = _mm_set1_pd(INFINITY), ninf = _mm_set1_pd(-INFINITY);
  __m128d hlo = inf, hhi = ninf;
  /* (the next cell's start read past the last cell too: the cells have room, see
   * qk__world_reorder) */
  const qk__wcell_t *cn = &cells[c0 + 1];
  qk_box_t *hp = &pk->hb[c0];
  uint32_t m = cells[c0].start, next = cn->start, ci = c0; /* (ci: the cell, noted in obj) */
  const uint32_t me = cells[c1].start;
  qk__wobj_t *obj = w->obj;
  /* The objects lie in slot order, walked here in cell order: each a line from anywhere
   * in the array. Where the array outgrows the caches, each is asked for QK__PACK_AHEAD
   * objects ahead (pf: the next one to ask for). */
  const int far = qk__world_far(w);
  uint32_t pf = m;
  while (m < me) {
    if (far) {
      const uint32_t want = me - m > QK__PACK_AHEAD ? m + QK__PACK_AHEAD : me;
      for (; pf < want; pf++) {
        if (cell_boxes == 2) /* (its cell is noted in it: a write) */
          __builtin_prefetch(&obj[ord[pf]], 1);
        else
          __builtin_prefetch(&obj[ord[pf]], 0);
      }
    }
    if (!(m & 3) && m + 4 <= me) {
      qk__wobj_t *o0 = &obj[ord[m]], *o1 = &obj[ord[m + 1]], *o2 = &obj[ord[m + 2]],
                 *o3 = &obj[ord[m + 3]];
      if (((o0->flags & QK__WKIND) == QK_SHAPE_BOX) & ((o1->flags & QK__WKIND) == QK_SHAPE_BOX) &
          ((o2->flags & QK__WKIND) == QK_SHAPE_BOX) & ((o3->flags & QK__WKIND) == QK_SHAPE_BOX)) {
        const __m128d p[4] = {_mm_loadu_pd(&o0->x), _mm_loadu_pd(&o1->x), _mm_loadu_pd(&o2->x),
                              _mm_loadu_pd(&o3->x)};
        const __m128d q[4] = {_mm_loadu_pd(&o0->a), _mm_loadu_pd(&o1->a), _mm_loadu_pd(&o2->a),
                              _mm_loadu_pd(&o3->a)};
        __m128 f[4];
        /* (exact: the last 29 mantissa bits of its four values zero, as in pack_one; a
         * word per lane, its low half's, all ones when they are) */
        const __m128i lowm = _mm_set1_epi64x((INT64_C(1) << 29) - 1);
        __m128 z[4];
        for (int k = 0; k < 4; k++) {
          f[k] = _mm_movelh_ps(_mm_cvtpd_ps(p[k]), _mm_cvtpd_ps(q[k])); /* (x, y, a, b) */
          z[k] = _mm_castsi128_ps(_mm_cmpeq_epi32(
              _mm_and_si128(_mm_or_si128(_mm_castpd_si128(p[k]), _mm_castpd_si128(q[k])), lowm),
              _mm_setzero_si128()));
        }
        /* (each box's two words, lanes 0 and 2 of its z, anded: one word a box, then a
         * byte a box) */
        const __m128 z01 = _mm_shuffle_ps(z[0], z[1], _MM_SHUFFLE(2, 0, 2, 0)),
                     z23 = _mm_shuffle_ps(z[2], z[3], _MM_SHUFFLE(2, 0, 2, 0));
        __m128i e = _mm_castps_si128(_mm_and_ps(_mm_shuffle_ps(z01, z23, _MM_SHUFFLE(2, 0, 2, 0)),
                                                _mm_shuffle_ps(z01, z23, _MM_SHUFFLE(3, 1, 3, 1))));
        e = _mm_and_si128(e, _mm_set1_epi32(1));
        e = _mm_packs_epi32(e, e);
        const uint32_t ex = (uint32_t)_mm_cvtsi128_si32(_mm_packs_epi16(e, e));
        _MM_TRANSPOSE4_PS(f[0], f[1], f[2], f[3]);
        float *g = fg + (size_t)(m >> 2) * 16;
        _mm_storeu_ps(g, f[0]), _mm_storeu_ps(g + 4, f[1]);
        _mm_storeu_ps(g + 8, f[2]), _mm_storeu_ps(g + 12, f[3]);
        memcpy(fx + m, &ex, 4);
        qk__wobj_t *const o[4] = {o0, o1, o2, o3};
        if (cell_boxes)
          for (int k = 0; k < 4; k++) {
            if (cell_boxes == 2) o[k]->cell = ci;
            hlo = _mm_min_pd(hlo, p[k]), hhi = _mm_max_pd(hhi, q[k]);
            if (m + (uint32_t)k + 1 == next) {
              _mm_storeu_pd(&hp->xmin, hlo), _mm_storeu_pd(&hp->xmax, hhi);
              hlo = inf, hhi = ninf;
              hp++, next = (++cn)->start, ci++;
            }
          }
        m += 4;
        continue;
      }
    }
    qk__wobj_t *o = &obj[ord[m]];
    if (cell_boxes == 2) o->cell = ci;
    if ((o->flags & QK__WKIND) == QK_SHAPE_BOX) {
      const __m128d p = _mm_loadu_pd(&o->x), q = _mm_loadu_pd(&o->a);
      if (cell_boxes) hlo = _mm_min_pd(hlo, p), hhi = _mm_max_pd(hhi, q);
      const __m128 fp = _mm_cvtpd_ps(p), fq = _mm_cvtpd_ps(q);
      float *g = fg + (size_t)(m >> 2) * 16 + (m & 3);
      _mm_store_ss(g, fp);
      _mm_store_ss(g + 4, _mm_shuffle_ps(fp, fp, 1));
      _mm_store_ss(g + 8, fq);
      _mm_store_ss(g + 12, _mm_shuffle_ps(fq, fq, 1));
      fx[m] = !_mm_movemask_pd(
          _mm_or_pd(_mm_cmpneq_pd(_mm_cvtps_pd(fp), p), _mm_cmpneq_pd(_mm_cvtps_pd(fq), q)));
    } else {
      qk_box_t h = empty_box;
      pack_one(o, fg, fx, m, &h);
      if (cell_boxes)
        hlo = _mm_min_pd(_mm_loadu_pd(&h.xmin), hlo), hhi = _mm_max_pd(_mm_loadu_pd(&h.xmax), hhi);
    }
    if (cell_boxes && m + 1 == next) {
      _mm_storeu_pd(&hp->xmin, hlo), _mm_storeu_pd(&hp->xmax, hhi);
      hlo = inf, hhi = ninf;
      hp++, next = (++cn)->start, ci++;
    }
    m++;
  }
}
#endif

static void pack_cells(const qk_world_t *w, qk__wpack_t *pk, const uint32_t *ord,
                       const qk__wcell_t *cells, uint32_t c0, uint32_t c1, int cell_boxes) {
#if defined(__SSE2__)
#define QK__PACK pack_run_
#else
#define QK__PACK pack_cells_
#endif
  /* (each with its cell_boxes a constant) */
  if (cell_boxes == 2)
    QK__PACK(w, pk, ord, cells, c0, c1, 2);
  else if (cell_boxes)
    QK__PACK(w, pk, ord, cells, c0, c1, 1);
  else
    QK__PACK(w, pk, ord, cells, c0, c1, 0);
#undef QK__PACK
}

/* The packing's jobs a thread, taken in order by whichever thread is free: the objects
 * the caller moved last are in its cache, so it packs faster than a worker that must
 * fetch them from the caller's core (on the PVM guest of the twenty-ninth session the
 * worker's half took half as long again as the caller's). */
#define QK__PACK_JOBS 8

/* One job of the packing: a range of cells of about equal objects. */
typedef struct pack_job {
  const qk_world_t *w;
  qk__wpack_t *pk;
  const uint32_t *ord;
  const qk__wcell_t *cells;
  uint32_t nc;
  unsigned n_jobs;
  int cell_boxes;
} pack_job_t;

static void pack_run(unsigned t, unsigned s, void *ud) {
  (void)s;
  pack_job_t *p = ud;
  uint32_t n = p->cells[p->nc].start;
  uint32_t c0 = qk__wcell_from(p->cells, 0, p->nc, (uint32_t)((uint64_t)n * t / p->n_jobs));
  uint32_t c1 = qk__wcell_from(p->cells, 0, p->nc, (uint32_t)((uint64_t)n * (t + 1) / p->n_jobs));
  pack_cells(p->w, p->pk, p->ord, p->cells, c0, c1, p->cell_boxes);
}

void qk__world_pack(const qk_world_t *w, qk__wpack_t *pk, const uint32_t *ord,
                    const qk__wcell_t *cells, uint32_t nc, int note) {
  uint32_t n = cells[nc].start;
  unsigned nt = qk__world_update_threads(w);
  if (n < 4096) nt = 1; /* not worth a thread */
  /* (the cells' and levels' boxes are for the search on the grid) */
  const int cell_boxes = w->by_bands ? 0 : note ? 2 : 1;
  if (nt > 1) {
    pack_job_t p = {w, pk, ord, cells, nc, QK__PACK_JOBS * nt, cell_boxes};
    qk__world_run_jobs_shared(w, nt, p.n_jobs, pack_run, &p);
  } else {
    pack_cells(w, pk, ord, cells, 0, nc, cell_boxes);
  }
  for (uint32_t k = n; k & 3; k++) { /* empty lanes: a box that meets nothing */
    float *g = pk->fgrp + (size_t)(k >> 2) * 16 + (k & 3);
    g[0] = g[4] = INFINITY, g[8] = g[12] = -INFINITY;
    pk->fexact[k] = 1; /* (read four at a time by the search, masked off) */
  }
  /* Each level's box: its cells are one run (joined in registers). */
  for (int l = 0; l < QK__NLEV && cell_boxes; l++) {
    qk_box_t b = empty_box;
    for (uint32_t c = w->lv_first[l], ce = c + w->lv_n[l]; c < ce; c++) box_join(&b, &pk->hb[c]);
    pk->lv_box[l] = b;
  }
}

/* One merge of old cells [c0, c1) with the dirty records [j0, j1) (those that sort before
 * old cell c1, or all that are left when c1 is the last), written from ord[m] and
 * cells[nc] on, counting cells in lv_first / lv_n (positions in cells). */
typedef struct merge {
  const qk_world_t *w;
  const drec_t *d;
  uint32_t *ord;
  qk__wcell_t *cells;
  uint32_t *lv_first, *lv_n;
  uint32_t m, nc; /* in: where to write; out: past the last written */
  /* Or NULL: a bit a slot, set for the dirty ones, when every slot of the old order is
   * live (no add or remove since the last update). The old entries are then kept by this
   * bit alone, without reading their objects (64 bytes each, out of cache). */
  const uint64_t *skip;
  /* Or NULL (only with skip): a bit an old cell, set for those that lose a dirty object
   * and those before which (or in which) a dirty record goes. The cells between two set
   * bits keep every object and meet no record: copied as a run, without a key or a skip
   * bit read (cell_touched). */
  const uint64_t *touch;
} merge_t;

/* The cells a merge writes, counted into its level runs (lv_first / lv_n) a run at a
 * time: they come in (level, cy, cx) order, so each level's cells are one run, and its
 * count is kept in locals until the level changes (count_in for every cell reloaded the
 * counts, which the cells' stores may alias). */
typedef struct lvrun {
  int l;          /* the level of the run (biased), or -1 before the first cell */
  uint32_t first; /* its first cell */
} lvrun_t;

static inline void lvrun_flush(merge_t *g, const lvrun_t *r, uint32_t nc) {
  if (r->l < 0) return;
  if (!g->lv_n[r->l]) g->lv_first[r->l] = r->first;
  g->lv_n[r->l] += nc - r->first;
}

/* Cell nc, of biased level l, is written: a new run when l is not the run's. */
static inline void lvrun_add(merge_t *g, lvrun_t *r, int l, uint32_t nc) {
  if (l != r->l) {
    lvrun_flush(g, r, nc);
    r->l = l, r->first = nc;
  }
}

/* The objects of old cell c but the dirty and removed ones, written from ord[m]: by the
 * skip bits when there are (merge_t), else by their objects' flags. Returns past them. */
static QK__ALWAYS_INLINE uint32_t keep_old(const qk_world_t *w, const uint64_t *sk,
                                           const qk__wcell_t *oc, uint32_t c, uint32_t *ord,
                                           uint32_t m, const int skipping) {
  const uint32_t *old = w->order;
  for (uint32_t k = oc[c].start, ke = oc[c + 1].start; k < ke; k++) {
    const uint32_t i = old[k];
    if (skipping) {
      ord[m] = i; /* (kept unless dirty: written, then counted) */
      m += !(sk[i >> 6] >> (i & 63) & 1);
    } else {
      const qk__wobj_t *o = &w->obj[i];
      if (qk__wlive(o) && !(o->flags & QK__WDIRTY)) ord[m++] = i;
    }
  }
  return m;
}

/* The first touched cell (merge_t) in [c, c1), or c1. */
static inline uint32_t next_touched(const uint64_t *tb, uint32_t c, uint32_t c1) {
  size_t k = c >> 6;
  const size_t ke = ((size_t)c1 + 63) >> 6;
  uint64_t x = tb[k] & (~UINT64_C(0) << (c & 63));
  while (!x) {
    if (++k >= ke) return c1;
    x = tb[k];
  }
  const size_t e = k * 64 + (size_t)__builtin_ctzll(x);
  return e < c1 ? (uint32_t)e : c1;
}

/* Old cells [c, e), which keep every object, written from cells with their starts moved
 * by dm. */
static inline void copy_cells(qk__wcell_t *cells, const qk__wcell_t *oc, uint32_t c, uint32_t e,
                              uint32_t dm) {
#if defined(__SSE2__)
  const __m128i dv = _mm_set_epi32(0, (int)dm, 0, 0); /* (the start is the third word) */
  for (; c < e; c++, cells++)
    _mm_storeu_si128((__m128i *)cells, _mm_add_epi32(_mm_loadu_si128((const __m128i *)&oc[c]), dv));
#else
  for (; c < e; c++, cells++) *cells = oc[c], cells->start += dm;
#endif
}

static QK__ALWAYS_INLINE void merge_range_(merge_t *g, uint32_t c0, uint32_t c1, size_t j,
                                           size_t j1, const int skipping, const int touching) {
  const qk_world_t *w = g->w;
  const drec_t *d = g->d;
  const qk__wcell_t *oc = w->cells;
  const uint64_t *sk = g->skip;
  uint32_t *ord = g->ord, m = g->m, nc = g->nc;
  qk__wcell_t *cells = g->cells;
  lvrun_t run = {-1, nc};
  uint32_t c = c0;
  for (;;) {
    /* The next dirty record's cell in locals (the stores below may alias the records),
     * past every cell's key when none is left. */
    const uint64_t jly = j < j1 ? d[j].ly : UINT64_MAX;
    const uint32_t jx = j < j1 ? d[j].x : UINT32_MAX;
    /* The old cells before it (all that are left after the last record) keep their
     * objects but the dirty and removed ones: most cells of a frame where few objects
     * left their cells. */
    for (; c < c1; c++) {
      if (touching && !(g->touch[c >> 6] >> (c & 63) & 1)) {
        /* Cells c .. e - 1 keep their objects, and every record left sorts after them
         * (where a record goes is touched): copied, their starts moved. */
        const uint32_t e = next_touched(g->touch, c, c1);
        const uint32_t s0 = oc[c].start, se = oc[e].start, dm = m - s0;
        memcpy(ord + m, w->order + s0, (size_t)(se - s0) * sizeof *ord);
        if (oc[c].level == oc[e - 1].level) {
          lvrun_add(g, &run, oc[c].level - QK__LMIN, nc);
          copy_cells(cells + nc, oc, c, e, dm);
          nc += e - c;
        } else {
          for (uint32_t k = c; k < e; k++) {
            lvrun_add(g, &run, oc[k].level - QK__LMIN, nc);
            copy_cells(cells + nc++, oc, k, k + 1, dm);
          }
        }
        m = se + dm, c = e;
        if (c == c1) break;
      }
      const uint64_t cly = (uint64_t)(uint32_t)(oc[c].level - QK__LMIN) << 32 | bias(oc[c].cy);
      if (cly > jly || (cly == jly && bias(oc[c].cx) >= jx)) break;
      const uint32_t m0 = m;
      m = keep_old(w, sk, oc, c, ord, m, skipping);
      if (m > m0) { /* (one left empty is dropped) */
        lvrun_add(g, &run, (int)(cly >> 32), nc);
        cells[nc] = oc[c];
        cells[nc++].start = m0;
      }
    }
    if (j == j1) break;
    /* The records of the next dirty cell: a cell of their own, or (the same key) old cell
     * c's after its kept objects. */
    const uint32_t m0 = m;
    const int l = (int)(jly >> 32);
    if (c < c1 && bias(oc[c].cx) == jx &&
        ((uint64_t)(uint32_t)(oc[c].level - QK__LMIN) << 32 | bias(oc[c].cy)) == jly)
      m = keep_old(w, sk, oc, c++, ord, m, skipping);
    do ord[m++] = d[j++].slot;
    while (j < j1 && d[j].ly == jly && d[j].x == jx);
    lvrun_add(g, &run, l, nc);
    /* (the cell from the record's key, not from the object: see rec_of) */
    cells[nc++] = (qk__wcell_t){unbias(jx), unbias((uint32_t)jly), m0, l + QK__LMIN};
  }
  lvrun_flush(g, &run, nc);
  g->m = m, g->nc = nc;
}

static void merge_range(merge_t *g, uint32_t c0, uint32_t c1, size_t j, size_t j1) {
  if (g->touch)
    merge_range_(g, c0, c1, j, j1, 1, 1);
  else if (g->skip)
    merge_range_(g, c0, c1, j, j1, 1, 0);
  else
    merge_range_(g, c0, c1, j, j1, 0, 0);
}

/*
 * The merge on the world's threads: the old cells cut into ranges (QK__MERGE_JOBS a
 * thread, of about equal work, taken by whichever thread is free), each range with the
 * dirty records that sort from its first cell to the next range's first (the first range
 * also those before, the last those after). A range's output is the serial merge's for
 * those cells, and the ranges' outputs follow each other in the serial merge's order
 * (their keys ascend from range to range). A range is merged into scratch, then, once
 * the ranges' sizes are known, copied to its place (cell starts and level runs shifted
 * by the ranges before it).
 */
#define QK__MMAX 64
_Static_assert(QK__MMAX <= 256, "a range in a byte (mjob_t rg)");
typedef struct mjob {
  const qk_world_t *w;
  const drec_t *d;
  uint32_t *ord;       /* the new order */
  qk__wcell_t *cells;  /* the new cells */
  uint32_t *s_ord;     /* scratch: n_order + m_d */
  qk__wcell_t *s_cell; /* scratch: n_oc + m_d */
  int phase;
  const uint64_t *skip; /* or NULL (merge_t) */
  uint32_t c0[QK__MMAX + 1];
  size_t j0[QK__MMAX + 1];
  /* Filing on the threads (refile): the live dirty slots sl[0 .. m_d), cut into nt
   * chunks; their records (unsorted, in dd) go to the ranges by the ranges' first cells'
   * keys (bly, bx; none past n_oc), each range's in d[j0[r] .. j0[r + 1]), sorted there. */
  const uint32_t *sl;
  size_t m_d;
  drec_t *dd, *pd;
  uint8_t *rg;     /* each record's range, found in phase 2 for phase 3 */
  unsigned nt, nb; /* threads; ranges with a first cell (1 .. nb - 1 have bounds) */
  uint64_t bly[QK__MMAX + 1];
  uint32_t bx[QK__MMAX + 1];
  size_t cnt[QK__MMAX][QK__MMAX];              /* per chunk, records per range; then cursors */
  uint32_t om[QK__MMAX + 1], oc[QK__MMAX + 1]; /* the ranges' offsets in the result */
  merge_t g[QK__MMAX];
  uint32_t lv[QK__MMAX][2 * QK__NLEV]; /* per range: level runs (first, count) */
  uint32_t lvd[QK__MMAX][QK__NLEV];    /* phase 4: per chunk, dirty slots by level */
} mjob_t;

/* The range a record goes to: the last whose first cell's key is at most its key. */
static inline unsigned range_of(const mjob_t *J, const drec_t *r) {
  unsigned lo = 1, hi = J->nb; /* ranges 1 .. nb - 1 have bounds, ascending */
  while (lo < hi) {
    unsigned mid = (lo + hi) / 2;
    if (r->ly < J->bly[mid] || (r->ly == J->bly[mid] && r->x < J->bx[mid]))
      hi = mid;
    else
      lo = mid + 1;
  }
  return lo - 1;
}

/* Phase 2: file chunk t's dirty objects, count its records by range; phase 3: move them
 * to their ranges (chunk by chunk, so each range keeps the dirty list's order). */
static void refile_run(mjob_t *J, unsigned t) {
  size_t k0 = J->m_d * t / J->nt, k1 = J->m_d * (t + 1) / J->nt;
  size_t *c = J->cnt[t];
  if (J->phase == 2) {
    memset(c, 0, J->nt * sizeof *c);
    for (size_t k = k0; k < k1; k++) {
      uint32_t i = J->sl[k];
      J->dd[k] = file_dirty(J->w, &J->w->obj[i], i, J->skip != NULL);
      const unsigned r = range_of(J, &J->dd[k]);
      J->rg[k] = (uint8_t)r;
      c[r]++;
    }
  } else {
    /* (the range found in phase 2: its search cost as much again as the move, 12 ns a
     * record) */
    for (size_t k = k0; k < k1; k++) J->pd[c[J->rg[k]]++] = J->dd[k];
  }
}

static void merge_run(unsigned t, unsigned s, void *ud) {
  (void)s;
  mjob_t *J = ud;
  if (J->phase == 4) { /* chunk t's dirty slots counted by their level (at the last update) */
    size_t k0 = J->m_d * t / J->nt, k1 = J->m_d * (t + 1) / J->nt;
    uint32_t *c = J->lvd[t];
    memset(c, 0, sizeof J->lvd[t]);
    for (size_t k = k0; k < k1; k++) c[J->w->obj[J->sl[k]].level - QK__LMIN]++;
    return;
  }
  merge_t *g = &J->g[t];
  /* (a range writes its scratch from its first cell's and first record's positions: at
   * most that many entries come before it) */
  uint32_t sm = J->w->cells[J->c0[t]].start + (uint32_t)J->j0[t];
  uint32_t sc = J->c0[t] + (uint32_t)J->j0[t];
  if (J->phase >= 2) {
    refile_run(J, t);
    return;
  }
  if (J->phase == 0) {
    /* (filed on the threads: this range's records are sorted here, as the serial sort
     * would have them: the same stable radix sort, in the dirty list's order) */
    if (J->sl && J->j0[t + 1] - J->j0[t] > 1)
      drec_sort(J->pd + J->j0[t], J->dd + J->j0[t], J->j0[t + 1] - J->j0[t]);
    *g = (merge_t){J->w, J->d, J->s_ord, J->s_cell, J->lv[t], J->lv[t] + QK__NLEV,
                   sm,   sc,   J->skip,  NULL};
    memset(J->lv[t], 0, sizeof J->lv[t]);
    merge_range(g, J->c0[t], J->c0[t + 1], J->j0[t], J->j0[t + 1]);
  } else {
    uint32_t nm = g->m - sm, ncl = g->nc - sc, dm = J->om[t] - sm;
    if (nm) memcpy(J->ord + J->om[t], J->s_ord + sm, nm * sizeof *J->ord);
    qk__wcell_t *dst = J->cells + J->oc[t];
    const qk__wcell_t *src = J->s_cell + sc;
    for (uint32_t k = 0; k < ncl; k++) dst[k] = src[k], dst[k].start += dm;
  }
}

/*
 * The merge's cuts (positions in the old order) when its dirty objects are filed on the
 * threads: about equal work a range, counting a dirty object as QK__MDIRTY old ones (its
 * record's sort and its place in the merge, against an old object's test and copy). The
 * dirty objects are counted by level (phase 4; an object's level follows its size, so
 * it is mostly the one it is filed at now) and taken as spread evenly over their level's
 * run of the old order. Most of them are the small, fast objects of the finest levels,
 * at the start of the order: on the benchmark's clustered scene at 10^5, 35 361 of the
 * first 50 000 objects' range were dirty against 2 819 of the second's, and equal objects
 * a range gave the first range 9.5 M instructions of sorting and merging against 1.7 M.
 * Any cuts give the same result; these only balance the threads.
 */
#define QK__MDIRTY 8
static void merge_cuts(const qk_world_t *w, const mjob_t *J, uint32_t *cut) {
  const qk__wcell_t *oc = w->cells;
  uint64_t dl[QK__NLEV], total = 0;
  for (int l = 0; l < QK__NLEV; l++) {
    uint64_t d = 0;
    for (unsigned t = 0; t < J->nt; t++) d += J->lvd[t][l];
    dl[l] = d;
    total += d * QK__MDIRTY;
  }
  total += w->n_order;
  unsigned t = 1;
  uint64_t done = 0; /* the work of the levels before l */
  for (int l = 0; l < QK__NLEV && t < J->nt; l++) {
    if (!w->lv_n[l]) continue;
    uint32_t p0 = oc[w->lv_first[l]].start, p1 = oc[w->lv_first[l] + w->lv_n[l]].start;
    uint64_t d = dl[l] * QK__MDIRTY, lw = (uint64_t)(p1 - p0) + d;
    /* (a level's dirty objects are taken as spread over its run: done + lw at its end) */
    for (; t < J->nt && total * t / J->nt <= done + lw; t++) {
      double f = lw ? (double)(total * t / J->nt - done) / (double)lw : 0;
      uint32_t p = p0 + (uint32_t)(f * (p1 - p0));
      cut[t] = p < p1 ? p : p1;
    }
    done += lw;
  }
}

/* The merge's ranges a thread, taken in order by whichever thread is free: a range's
 * work is only estimated (merge_cuts), and a worker is slower on the lines the caller's
 * moves left in its cache. */
#define QK__MERGE_JOBS 4

/* The merge's ranges on nth threads. */
static unsigned merge_ranges(unsigned nth) {
  return nth > QK__MMAX / QK__MERGE_JOBS ? QK__MMAX : QK__MERGE_JOBS * nth;
}

/* Whether the merge runs on the threads (merge_threads), scratch permitting. */
static int merge_fits(const qk_world_t *w, uint32_t n_oc) {
  unsigned nth = qk__world_update_threads(w);
  return nth >= 2 && w->n_order >= 4096 && n_oc >= 4 * merge_ranges(nth);
}

/* The merge on threads (see mjob_t); 0 when it is not worth them or its scratch cannot
 * be had (the caller then merges here). With sl, the m_d live dirty slots sl[0 .. m_d)
 * are filed on the threads too and their records sorted there, in d (room for 2 m_d);
 * else d holds their records, sorted. */
static int merge_threads(qk_world_t *w, drec_t *d, size_t m_d, const uint32_t *sl,
                         const uint64_t *skip, uint32_t *ord, qk__wcell_t *cells, uint32_t n_oc,
                         uint32_t *m_out, uint32_t *nc_out) {
  const unsigned nth = qk__world_update_threads(w), nt = merge_ranges(nth);
  if (!merge_fits(w, n_oc)) return 0;
  const qk_allocator_t *a = &w->alloc;
  size_t so = (size_t)w->n_order + m_d, sc = (size_t)n_oc + m_d;
  /* (s_ord's block also holds the records' ranges when the threads file them) */
  const size_t sob = so * sizeof(uint32_t) + (sl ? m_d : 0);
  mjob_t *J = qk__realloc(a, NULL, 0, sizeof *J);
  uint32_t *s_ord = J ? qk__realloc(a, NULL, 0, sob) : NULL;
  qk__wcell_t *s_cell = s_ord ? qk__realloc(a, NULL, 0, sc * sizeof *s_cell) : NULL;
  if (!s_cell) {
    qk__free(a, s_ord, sob);
    qk__free(a, J, sizeof *J);
    return 0;
  }
  J->rg = sl ? (uint8_t *)(s_ord + so) : NULL;
  J->w = w, J->d = d, J->ord = ord, J->cells = cells, J->s_ord = s_ord, J->s_cell = s_cell;
  J->sl = NULL, J->nt = nt, J->skip = skip;
  /* Ranges of old cells of about equal objects; each range's dirty records from the
   * first that does not sort before its first cell. With the dirty slots at hand (sl),
   * of about equal work instead (merge_cuts). */
  const qk__wcell_t *oc = w->cells;
  uint32_t cut[QK__MMAX + 1];
  for (unsigned t = 0; t <= nt; t++) cut[t] = (uint32_t)((uint64_t)w->n_order * t / nt);
  if (sl) {
    J->sl = sl, J->m_d = m_d, J->phase = 4;
    qk__world_run_jobs_shared(w, nth, nt, merge_run, J);
    merge_cuts(w, J, cut);
  }
  J->c0[0] = 0, J->j0[0] = 0;
  for (unsigned t = 1; t < nt; t++) {
    uint32_t c = qk__wcell_from(oc, 0, n_oc, cut[t]);
    if (c < J->c0[t - 1]) c = J->c0[t - 1];
    J->c0[t] = c;
  }
  J->c0[nt] = n_oc;
  if (sl) {
    /* The dirty objects filed on the threads, their records sent to the ranges (as the
     * search below would cut the sorted records) and sorted there (merge_run). */
    J->nb = 1;
    while (J->nb < nt && J->c0[J->nb] < n_oc) {
      const qk__wcell_t *b = &oc[J->c0[J->nb]];
      J->bly[J->nb] = (uint64_t)(uint32_t)(b->level - QK__LMIN) << 32 | bias(b->cy);
      J->bx[J->nb] = bias(b->cx);
      J->nb++;
    }
    J->sl = sl, J->m_d = m_d, J->dd = d + m_d, J->pd = d;
    J->phase = 2;
    qk__world_run_jobs_shared(w, nth, nt, merge_run, J);
    size_t s = 0;
    for (unsigned r = 0; r < nt; r++) {
      J->j0[r] = s;
      for (unsigned t = 0; t < nt; t++) {
        size_t x = J->cnt[t][r];
        J->cnt[t][r] = s, s += x;
      }
    }
    J->j0[nt] = m_d;
    J->phase = 3;
    qk__world_run_jobs_shared(w, nth, nt, merge_run, J);
  }
  for (unsigned t = 1; t < nt && !sl; t++) {
    uint32_t c = J->c0[t];
    size_t lo = J->j0[t - 1], hi = m_d;
    if (c < n_oc) {
      uint64_t cly = (uint64_t)(uint32_t)(oc[c].level - QK__LMIN) << 32 | bias(oc[c].cy);
      uint32_t cxk = bias(oc[c].cx);
      while (lo < hi) {
        size_t mid = lo + (hi - lo) / 2;
        if (d[mid].ly < cly || (d[mid].ly == cly && d[mid].x < cxk))
          lo = mid + 1;
        else
          hi = mid;
      }
    } else {
      lo = m_d;
    }
    J->j0[t] = lo;
  }
  J->j0[nt] = m_d;
  J->phase = 0;
  qk__world_run_jobs_shared(w, nth, nt, merge_run, J);
  /* The ranges' places, and the level runs (a level's cells are one run across ranges). */
  uint32_t om = 0, ocn = 0;
  memset(w->lv_first, 0, sizeof w->lv_first);
  memset(w->lv_n, 0, sizeof w->lv_n);
  for (unsigned t = 0; t < nt; t++) {
    uint32_t sm = oc[J->c0[t]].start + (uint32_t)J->j0[t], scl = J->c0[t] + (uint32_t)J->j0[t];
    J->om[t] = om, J->oc[t] = ocn;
    const uint32_t *lf = J->lv[t], *ln = J->lv[t] + QK__NLEV;
    for (int l = 0; l < QK__NLEV; l++) {
      if (!ln[l]) continue;
      if (!w->lv_n[l]) w->lv_first[l] = lf[l] - scl + ocn;
      w->lv_n[l] += ln[l];
    }
    om += J->g[t].m - sm, ocn += J->g[t].nc - scl;
  }
  J->phase = 1;
  qk__world_run_jobs_shared(w, nth, nt, merge_run, J);
  *m_out = om, *nc_out = ocn;
  qk__free(a, s_cell, sc * sizeof *s_cell);
  qk__free(a, s_ord, sob);
  qk__free(a, J, sizeof *J);
  return 1;
}

/* Whether old cell c sorts before key (ly, x). */
static inline int cell_lt(const qk__wcell_t *c, uint64_t ly, uint32_t x) {
  const uint64_t cly = (uint64_t)(uint32_t)(c->level - QK__LMIN) << 32 | bias(c->cy);
  return cly < ly || (cly == ly && bias(c->cx) < x);
}

static inline void touch_set(uint64_t *tb, uint32_t c) { tb[c >> 6] |= UINT64_C(1) << (c & 63); }

/*
 * Touch (merge_t) the old cell [0, n) that dirty record r goes before or into: the first
 * cell not before it, searched from h, the cell its object left (noted by the last pack:
 * a moved object's new cell is mostly a neighbour of its old one, a few cells or a row away
 * in the order) by galloping, then bisection. Done as each object is filed, while its
 * line is at hand: after the sort, reading each record's object again for h missed the
 * caches in large worlds.
 */
static void cell_touched(const qk_world_t *w, uint64_t *tb, const drec_t *r, uint32_t h,
                         uint32_t n) {
  const qk__wcell_t *oc = w->cells;
  const uint64_t ly = r->ly;
  const uint32_t x = r->x;
  uint32_t lo, hi; /* the answer in [lo, hi] */
  if (cell_lt(&oc[h], ly, x)) {
    uint32_t s = 1;
    lo = h + 1;
    while (lo + s - 1 < n && cell_lt(&oc[lo + s - 1], ly, x)) lo += s, s *= 2;
    hi = lo + s - 1 < n ? lo + s - 1 : n;
  } else {
    uint32_t s = 1;
    hi = h;
    while (hi >= s && !cell_lt(&oc[hi - s], ly, x)) hi -= s, s *= 2;
    lo = hi >= s ? hi - s + 1 : 0;
  }
  while (lo < hi) {
    const uint32_t mid = lo + (hi - lo) / 2;
    if (cell_lt(&oc[mid], ly, x))
      lo = mid + 1;
    else
      hi = mid;
  }
  if (lo < n) touch_set(tb, lo);
}

void qk__world_pack_free(qk_world_t *w, qk__wpack_t *pk) {
  qk__free(&w->alloc, pk->fgrp, pk->cap_fgrp * (16 * sizeof *pk->fgrp + 4));
  qk__free(&w->alloc, pk->hb, pk->cap_hb * sizeof *pk->hb);
  pk->fgrp = NULL, pk->hb = NULL;
  pk->cap_fgrp = pk->cap_hb = 0;
}

/* How far ahead in the dirty list the filing asks for its objects. */
#define QK__DIRTY_AHEAD 8

/* The merge's touched cells (merge_t's touch) are found when the dirty objects are at
 * most this share of the old cells (1 / QK__TOUCH_SHARE), and the pack notes each
 * object's cell for them when they were so in the update before. */
#define QK__TOUCH_SHARE 16

qk_status_t qk__world_reorder(qk_world_t *w, qk__wpack_t *pk) {
  const qk_allocator_t *a = &w->alloc;
  pk->fgrp = NULL, pk->hb = NULL, pk->cap_fgrp = pk->cap_hb = 0;
  /* Everything the pass needs, before anything changes: the dirty records, the new
   * order, the new cells (at most the old ones plus one per dirty object, and the
   * sentinel) and the pack. */
  /* (and one past the sentinel, which the pack reads: pack_run_) */
  size_t nd = w->n_dirty, n = w->n_live, ncap = (size_t)w->n_cells + nd + 2;
  /* (one more: the one-thread merge writes an old entry before it knows whether to keep
   * it) */
  /* (and three more: the search reads the order four at a time, the last group's lanes
   * past the end too) */
  size_t ocap = n + 4, gcap = (n + 3) / 4 + 1;
  /* The dirty records and, for the radix sort, as many again; then, when every slot of
   * the old order is live, the dirty slots' bits (merge_t). */
  const size_t nsk = nd && !w->ident_dirty ? ((size_t)w->n_obj + 63) / 64 : 0;
  /* And, when the merge will be here and the last pack noted each object's cell, a bit an
   * old cell (merge_t's touch): when the dirty objects touch few of the cells (at most two
   * each: the one left and the one before which the new one goes), as in a sparse world
   * where few objects move. Finding a dirty object's cell costs a search of the old cells
   * from the one it left (some 50 ns an object at 10^5 cells, whose 1.4 MB miss the
   * caches) and saves about 2 ns a cell of an untouched run: in the benchmark's huge scene
   * at 10^5 objects (88,000 cells) the merge with its search took 1.33-1.56 ms with
   * 11,256 dirty objects (1 / 8 of the cells) against 1.00-1.08 without, and 0.40-0.43 ms
   * with 2,813 against 0.62-0.63 without; even at 1 / 14 the two were about even (in the
   * uniform scene, some eight objects a cell, most cells are touched). */
  const uint32_t n_oc0 = w->order ? w->n_cells : 0;
  const size_t ntw =
      nsk && w->cells_noted && n_oc0 >= 64 && nd < n_oc0 / QK__TOUCH_SHARE && !merge_fits(w, n_oc0)
          ? ((size_t)n_oc0 + 64) / 64
          : 0;
  const size_t dbytes = 2 * nd * sizeof(drec_t) + (nsk + ntw) * sizeof(uint64_t);
  drec_t *d = nd ? qk__realloc(a, NULL, 0, dbytes) : NULL;
  uint32_t *ord = (!nd || d) ? qk__realloc(a, NULL, 0, ocap * sizeof *ord) : NULL;
  qk__wcell_t *cells = ord ? qk__realloc(a, NULL, 0, ncap * sizeof *cells) : NULL;
  float *fg = cells ? qk__realloc(a, NULL, 0, gcap * (16 * sizeof *fg + 4)) : NULL;
  qk_box_t *hb = fg ? qk__realloc(a, NULL, 0, ncap * sizeof *hb) : NULL;
  if (!hb) {
    qk__free(a, d, dbytes);
    qk__free(a, ord, ocap * sizeof *ord);
    qk__free(a, cells, ncap * sizeof *cells);
    qk__free(a, fg, gcap * (16 * sizeof *fg + 4));
    return QK_ERR_NOMEM;
  }
  pk->fgrp = fg, pk->cap_fgrp = gcap, pk->hb = hb, pk->cap_hb = ncap;
  pk->fexact = (uint8_t *)(fg + gcap * 16);

  /* File the live dirty objects in their new cells and sort their records. With many
   * (and the merge on threads), the threads file them and sort them by the merge's
   * ranges, in the same stable order (merge_threads); the list is read here. */
  uint32_t m = 0, nc = 0, n_oc = w->order ? w->n_cells : 0;
  size_t m_d = 0;
  int merged = 0;
  uint64_t *skip = NULL, *touch = NULL; /* (merge_t) */
  if (nsk) {
    skip = (uint64_t *)(d + 2 * nd);
    memset(skip, 0, nsk * sizeof *skip);
  }
  if (ntw) {
    touch = skip + nsk;
    memset(touch, 0, ntw * sizeof *touch);
  }
  uint32_t *sl =
      nd >= QK__REFILE_MIN && merge_fits(w, n_oc) ? qk__realloc(a, NULL, 0, nd * sizeof *sl) : NULL;
  if (sl && skip) {
    /* Every dirty object is live (see nsk): marked in skip, and no longer dirty once filed
     * (file_dirty), so that neither this walk, the merge nor the end of the update reads
     * its object (at 10^5 objects on two threads they were the update's largest serial
     * cost: lines the threads had filed, read one after another). */
    for (uint32_t i = w->dirty_head; i != QK_NONE; i = w->dnext[i]) {
      sl[m_d++] = i;
      skip[i >> 6] |= (uint64_t)1 << (i & 63);
    }
  } else if (sl) {
    for (uint32_t i = w->dirty_head; i != QK_NONE; i = w->dnext[i])
      if (qk__wlive(&w->obj[i])) sl[m_d++] = i;
  }
  if (sl) {
    if (m_d > 64) merged = merge_threads(w, d, m_d, sl, skip, ord, cells, n_oc, &m, &nc);
    if (!merged)
      for (size_t k = 0; k < m_d; k++) d[k] = file_dirty(w, &w->obj[sl[k]], sl[k], skip != NULL);
    qk__free(a, sl, nd * sizeof *sl);
  } else if (nsk) {
    /* Every dirty object is live (see nsk), marked in skip, and no longer dirty once filed
     * (the merge reads skip, nothing else the flag): no second walk of the list. */
    /* (the list's objects lie anywhere in the array: where it outgrows the caches, each
     * asked for QK__DIRTY_AHEAD entries of the list ahead, by a second cursor) */
    /* (and, when the cells are searched, the cell that the object QK__DIRTY_AHEAD / 2 entries
     * ahead left: its object was asked for before) */
    uint32_t ahead = qk__world_far(w) ? w->dirty_head : QK_NONE, near = QK_NONE;
    for (int k = 0; k < QK__DIRTY_AHEAD && ahead != QK_NONE; k++) {
      if (touch && k == QK__DIRTY_AHEAD / 2) near = ahead;
      ahead = w->dnext[ahead];
    }
    for (uint32_t i = w->dirty_head; i != QK_NONE; i = w->dnext[i]) {
      if (ahead != QK_NONE) {
        __builtin_prefetch(&w->obj[ahead], 1);
        ahead = w->dnext[ahead];
      }
      if (near != QK_NONE) {
        __builtin_prefetch(&w->cells[w->obj[near].cell]);
        near = w->dnext[near];
      }
      const uint32_t h = w->obj[i].cell;
      d[m_d] = file_dirty(w, &w->obj[i], i, true);
      if (touch) {
        touch_set(touch, h); /* (its old cell, which loses it) */
        cell_touched(w, touch, &d[m_d], h, n_oc);
      }
      m_d++;
      skip[i >> 6] |= (uint64_t)1 << (i & 63);
    }
  } else {
    for (uint32_t i = w->dirty_head; i != QK_NONE; i = w->dnext[i])
      if (qk__wlive(&w->obj[i])) d[m_d++] = file_dirty(w, &w->obj[i], i, false);
  }
  if (!merged) {
    if (m_d > 64)
      drec_sort(d, d + nd, m_d);
    else if (m_d > 1)
      qsort(d, m_d, sizeof *d, drec_cmp);
  }

  /* Merge, cell by cell: the old cells in order (their kept entries stay sorted: their
   * cells did not change), each preceded by the dirty cells that sort before it and
   * followed by the dirty entries of the same cell. The keys are compared once a cell,
   * not once an object. On threads by ranges of old cells (merge_threads), else here. */
  if (!merged && !merge_threads(w, d, m_d, NULL, skip, ord, cells, n_oc, &m, &nc)) {
    merge_t mg = {w, d, ord, cells, w->lv_first, w->lv_n, 0, 0, skip, touch};
    memset(w->lv_first, 0, sizeof w->lv_first);
    memset(w->lv_n, 0, sizeof w->lv_n);
    merge_range(&mg, 0, n_oc, 0, m_d);
    m = mg.m, nc = mg.nc;
  }
  cells[nc] = (qk__wcell_t){0, 0, m, INT32_MAX};
  ord[m] = ord[m + 1] = ord[m + 2] = 0; /* (read, masked off: see ocap) */
  /* (the new order in place first: the pack asks whether the search will be by bands) */
  qk__free(a, w->order, (size_t)w->cap_order * sizeof *w->order);
  qk__free(a, w->cells, (size_t)w->cap_cells * sizeof *w->cells);
  w->order = ord, w->n_order = m, w->cap_order = (uint32_t)ocap;
  w->cells = cells, w->n_cells = nc, w->cap_cells = (uint32_t)ncap;
  qk__world_note_levels(w);
  qk__world_qtree_stale(w);
  w->by_bands = qk__world_by_bands(w);
  /* Each object's cell noted for the next update's merge when it is likely to use them:
   * when this one's dirty objects were few for the cells (frames are alike; see ntw), or
   * it filed every object (the first update: nothing to go by). */
  const int note = nd < nc / QK__TOUCH_SHARE || !n_oc;
  qk__world_pack(w, pk, ord, cells, nc, note);
  w->cells_noted = !w->by_bands && note;
  for (uint32_t k = w->dirty_head; k != QK_NONE && !skip; k = w->dnext[k])
    w->obj[k].flags &= (uint8_t)~QK__WDIRTY;
  w->dirty_head = QK_NONE;
  w->n_dirty = 0;
  qk__free(a, d, dbytes);
  /* Give back the cells' room for the dirty objects that joined existing cells (a
   * failed shrink is harmless). */
  /* And the object slots' slack after growth (a failed shrink is harmless). */
  if (w->cap_obj > w->n_obj + w->n_obj / 32 + 16) {
    (void)qk__world_obj_resize(w, w->n_obj + w->n_obj / 64 + 16);
  }
  /* (Not with no object slots at all: an add whose slot array could not be grown leaves
   * cap_obj 0 behind a grown ugen, and a realloc to 0 bytes frees it and returns NULL.) */
  if (w->cap_ugen > w->cap_obj && w->cap_obj > 0) {
    uint32_t *nu =
        qk__realloc(a, w->ugen, (size_t)w->cap_ugen * sizeof *nu, (size_t)w->cap_obj * sizeof *nu);
    if (nu) w->ugen = nu, w->cap_ugen = w->cap_obj;
  }
  if (w->cap_dnext > w->cap_obj && w->cap_obj > 0) {
    uint32_t *nd = qk__realloc(a, w->dnext, (size_t)w->cap_dnext * sizeof *nd,
                               (size_t)w->cap_obj * sizeof *nd);
    if (nd) w->dnext = nd, w->cap_dnext = w->cap_obj;
  }
  if (ncap > (size_t)nc + 1 + 16) {
    qk__wcell_t *c = qk__realloc(a, w->cells, ncap * sizeof *c, ((size_t)nc + 1) * sizeof *c);
    if (c) w->cells = c, w->cap_cells = nc + 1;
  }
  return QK_OK;
}
