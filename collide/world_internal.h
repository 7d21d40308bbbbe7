/*
 * The world's private layout, shared by collide/world.c (objects), collide/world_grid.c
 * (the sorted loose grid), collide/world_search.c (the pair search), collide/world_pairs.c
 * (the frame's pair lists) and collide/world_query.c (queries). Not API.
 */
#ifndef QUADKIT_WORLD_INTERNAL_H
#define QUADKIT_WORLD_INTERNAL_H

#include "collide/collide_internal.h"

#include <stdatomic.h>

/* Before a short hot loop over many keys (counting and scattering sorts): unrolled four
 * times, its index update, compare and branch are paid once for four keys (measured on
 * the frame's sorts: a few instructions a key of about ten). */
#if defined(__GNUC__) && !defined(__clang__)
#define QK__UNROLL4 _Pragma("GCC unroll 4")
#elif defined(__clang__)
#define QK__UNROLL4 _Pragma("clang loop unroll_count(4)")
#else
#define QK__UNROLL4
#endif

/* Levels: cells of side 2^L for L in [QK__LMIN, QK__LMIN + QK__NLEV); the filing keeps
 * L in [QK__LFLOOR, 127] so that it fits an int8_t. */
#define QK__LMIN (-128)
#define QK__NLEV 256
#define QK__LFLOOR (-120)

/* Flags of an object: its kind in the low two bits, then: */
#define QK__WKIND 3u
#define QK__WDIRTY 4u  /* on the dirty list: not (or no longer) where the order files it */
#define QK__WFORCED 8u /* its level was raised by its coordinates' magnitude */
/* Its cell's loose square holds only values the world accepts (magnitudes in [2^-100,
 * 2^100], no zero), so that a box inside it needs no check of its values (qk_world_move). */
#define QK__WCLEAN 16u

/*
 * An object: 64 bytes. The shape is stored once (x, y, a, b as qk_shape_t, the kind in
 * flags); the box is derived from it. (cx, cy, level) is the cell it is filed in, as of
 * the last update: the object lies in that cell's loose square [cx 2^L, (cx + 2) 2^L)
 * per axis, unless it is DIRTY. The generation at the last update (the handles of the
 * stored pairs) is kept apart, in the world's ugen array: walking the pairs reads it
 * for every pair, and 4 bytes a slot stay in cache where 64 do not.
 */
typedef struct qk__wobj {
  double x, y, a, b;
  uint64_t tag;
  uint32_t gen; /* generation of the slot (odd: live) */
  union {
    int32_t cx;
    uint32_t free_next; /* while the slot is free: the next free slot */
  } u;
  int32_t cy;
  int8_t level;
  uint8_t flags;
  union {
    float step;   /* while DIRTY: how far the move that made it dirty took it (its speed) */
    float shrink; /* while filed: re-filed when its extent falls to this (a finer level) */
  } k;
  uint32_t cell; /* its cell's index in the cells of the last update when it was packed for
                    the grid (cells_noted; in the object's padding) */
} qk__wobj_t;

/* A cell of the sorted loose grid: the objects order[start .. next cell's start). */
typedef struct qk__wcell {
  int32_t cx, cy;
  uint32_t start;
  int32_t level;
} qk__wcell_t;

/* The first cell a in [lo, hi) with cells[a].start >= m, or hi if none (cells are sorted
 * by start). */
static inline uint32_t qk__wcell_from(const qk__wcell_t *cells, uint32_t lo, uint32_t hi,
                                      uint64_t m) {
  while (lo < hi) {
    uint32_t mid = lo + (hi - lo) / 2;
    if (cells[mid].start < m)
      lo = mid + 1;
    else
      hi = mid;
  }
  return lo;
}

/* Pairs as 64-bit keys: slot a in the high half, slot b (> a) in the low half, so the
 * keys' order is the (slot a, slot b) order. The search finds them so, and the began
 * and ended lists keep them so; the current pairs are stored by rows (qk__prows_t). */
typedef struct qk__kvec {
  uint64_t *v;
  size_t n, cap;
} qk__kvec_t;

/* The current pairs by rows, 4 bytes a pair and 8 a slot that has pairs: the k-th row
 * with pairs is slot row[k] (ascending), and holds the slots b > row[k] of its pairs,
 * ascending, at b[start[k] .. start[k + 1]). Rows without pairs take no room, so a
 * sparse world pays for its pairs only. */
typedef struct qk__prows {
  uint32_t *b;
  size_t n, cap;   /* pairs, and the room of b */
  size_t off;      /* b lies off places into its block (of off + cap; see rows_began) */
  uint32_t *row;   /* n_nz + 1 entries: the rows' slots, then (start) their starts */
  uint32_t *start; /* n_nz + 1 entries, start[n_nz] = n (in row's allocation) */
  size_t n_nz;     /* rows with pairs */
} qk__prows_t;

/* The block that holds r's pairs (or NULL), and its room in pairs. */
static inline uint32_t *qk__prows_block(const qk__prows_t *r) {
  return r->b ? r->b - r->off : NULL;
}
static inline size_t qk__prows_room(const qk__prows_t *r) { return r->off + r->cap; }

/* The search threads whose key buffers an update keeps (beyond the first). */
#define QK__KEEP_THREADS 7

/* The update's large scratch kept between updates (collide/world_scratch.c): freed
 * blocks of QK__WSCR_MIN bytes and more, up to QK__WSCR_BLOCKS, and the blocks taken from
 * them (lent), larger than their users asked, with their true sizes. */
#define QK__WSCR_MIN ((size_t)256 << 10)
#define QK__WSCR_BLOCKS 32
#define QK__WSCR_LENT 64
typedef struct qk__wscr_blk {
  void *p;
  size_t cap;
  size_t hi;      /* its largest use, less a sixteenth an update since */
  unsigned epoch; /* the update that kept it */
} qk__wscr_blk_t;
typedef struct qk__wscr_lent {
  void *p;
  size_t cap, size; /* its true size, and the size its user believes */
  size_t hi;        /* the block's hi when it was kept before (0: a new block) */
} qk__wscr_lent_t;
typedef struct qk__wscr {
  qk_allocator_t user; /* the allocator the world was given */
  atomic_flag lock;
  int active;                     /* in an update */
  unsigned epoch;                 /* updates begun */
  unsigned n_blk, n_lent, n_resv; /* (n_resv: lent entries held for blocks being allocated) */
  qk__wscr_blk_t blk[QK__WSCR_BLOCKS];
  qk__wscr_lent_t lent[QK__WSCR_LENT];
} qk__wscr_t;

struct qk_world {
  qk_allocator_t alloc; /* the cache below, in front of scr.user */
  qk__wscr_t scr;
  qk_world_options_t opt;
  /* The objects, one cache line each: obj is the block obj_raw (QK__WOBJ_SLACK bytes
   * more than the slots) moved up to a multiple of 64 bytes (qk__world_obj_resize). */
  qk__wobj_t *obj;
  void *obj_raw;
  uint32_t n_obj, cap_obj; /* slots used (high-water mark) and allocated */
  uint32_t *ugen;          /* per slot: its generation at the last update */
  uint32_t cap_ugen;
  /* Per slot: the next slot of the dirty list. Apart from the objects so that the update
   * reads the list without reading each dirty object's 64 bytes one after another (on
   * two threads the lines a worker had just filed, from the other core). */
  uint32_t *dnext;
  uint32_t cap_dnext;
  uint32_t free_head; /* first free slot, or QK_NONE */
  size_t n_live;
  uint32_t dirty_head; /* objects added or re-filed since the last update */
  uint32_t n_dirty;    /* entries of the dirty list (removed ones included) */
  uint32_t move_next;  /* the slot after the last qk_world_move's (a run in slot order) */
  /* The order: the slots of the last update sorted by cell (level, cy, cx), and its
   * cells, sorted the same way, with a sentinel (start = n_order). */
  uint32_t *order;
  uint32_t n_order, cap_order;
  qk__wcell_t *cells;
  uint32_t n_cells, cap_cells;
  uint32_t lv_first[QK__NLEV], lv_n[QK__NLEV]; /* each level's run of cells */
  /* The occupied levels (lv_n nonzero), ascending, noted when the order is made
   * (qk__world_note_levels): a query reads these few, not all QK__NLEV counts. */
  int16_t lv_occ[QK__NLEV];
  int n_lv_occ;
  qk__prows_t cur; /* this frame's pairs (handles: ugen) */
  /* The current pairs also as keys in order (8 bytes a pair), when the last update's
   * merge was the key merge of short rows (then ckeys.n == cur.n, else ckeys.n is 0):
   * the next merge reads the last frame's keys here instead of writing them out of the
   * rows again. */
  qk__kvec_t ckeys;
  qk__kvec_t began; /* pairs that began (handles: ugen) */
  qk__kvec_t ended; /* pairs that ended (handles: ugen, or egen for changed slots) */
  uint64_t *egen;   /* slot << 32 | generation before the last update, of the slots
                       that changed at it (sorted) */
  size_t n_egen;
  size_t last_found; /* keys found by the last search, which size the next one's buffer: a
                        frame's pairs, or after a began-only frame its began candidates
                        (what the next began-only search finds; a full search after it
                        grows the buffer as it goes) */
  /* Scratch kept from one update to the next, so that a dense frame's buffers (tens of
   * megabytes at 10^5 objects) are not fresh pages every frame: the search's keys (with
   * room for the row sort's 32-bit scratch after them), and the rows' buffer of the
   * frame before last (the next rows are built in it). Cut when much larger than used. */
  qk__kvec_t scr_keys;                    /* (n unused) */
  qk__kvec_t scr_tkeys[QK__KEEP_THREADS]; /* the other threads' keys (threads 1, 2, ...) */
  uint32_t *spare_b;
  size_t cap_spare_b;
  /* The objects' float boxes at the last update, by slot (xmin, ymin, -xmax, -ymax), when
   * that update's search was by bands and every float box was exact (else NULL): the
   * next search then finds only the pairs whose boxes did not meet then (see
   * qk__world_search). n_fbox slots. */
  float *fbox;
  uint32_t n_fbox;
  /* With fbox: the pairs whose float boxes met at the last update but whose objects did
   * not (the near candidates), as keys in no order. With the current pairs they are
   * every pair whose float boxes then met. */
  qk__kvec_t near;
  int ident_dirty;  /* an object was added or removed since the last update */
  int had_round;    /* a disc or a segment was ever added or moved to (never cleared): the
                       first-hit ray stops early only in worlds of boxes and points */
  int cells_noted;  /* each live object's `cell` is its index in the cells (the last pack) */
  int by_bands;     /* the order of the last update is searched by bands (qk__world_by_bands,
                       asked once by qk__world_reorder) */
  qk__pool_t *pool; /* the world's workers (collide/world_threads.c), or NULL */
  /* The query tree (collide/world_query.c): each level's cells again, in Morton order of
   * their (cx - qx0, cy - qy0) (qkey, and the cell in qcell), made by the first query
   * after an update that wants it. qstate: 0 not made for the order of the last update,
   * 1 being made (by one query; the others go without), 2 made. Its arrays are read only
   * after reading 2 (acquire), written only after taking 0 -> 1. */
  atomic_int qstate;
  atomic_size_t qbytes; /* what its arrays hold, in bytes (the bitmaps', tables' and
                           groups' below too) */
  uint64_t *qkey;
  uint32_t *qcell;
  uint32_t cap_q;
  int32_t qx0[QK__NLEV], qy0[QK__NLEV];
  /* Also made with it: per occupied level, a bitmap of where its cells are, their (cx -
   * qx0, cy - qy0) shifted right by qb_s (the least shift that needs at most 8 bits a
   * cell and 64), qb_w bits a row and qb_h rows, at qbits + qb_off (in words). */
  uint64_t *qbits;
  size_t cap_qbits; /* (in words) */
  uint32_t qb_off[QK__NLEV], qb_w[QK__NLEV], qb_h[QK__NLEV];
  uint8_t qb_s[QK__NLEV];
  /* And per level of 16 cells or more, where each square of its tree's top qt_d depths
   * (qt_d in [2, 5], else 0) begins: qtab[qt_off + j] is the first of the level's keys at
   * or above j << qt_sh, for j in [0, 4^qt_d]. */
  uint32_t *qtab;
  size_t cap_qtab;
  uint32_t qt_off[QK__NLEV];
  uint8_t qt_d[QK__NLEV], qt_sh[QK__NLEV];
  /* And made with it: the groups of the crowded cells (qk__wfine_t; the cells of
   * QK__FINE_MIN objects or more). The cells' entries in cell order, found by a hash of
   * (level, cx, cy) in fhash (fmask + 1 entries, UINT32_MAX empty); their objects' slots
   * (the live ones filed there) in fslot, four to a group, and the groups' float boxes
   * in fg4, the boxes of their runs of four groups in fg16, each (xmin, ymin, -xmax,
   * -ymax). */
  struct qk__wfine *fine;
  uint32_t n_fine, cap_fine;
  size_t fine_moves; /* moves that have looked up their cells since the groups were set out */
  uint32_t *fhash;
  uint32_t fmask;
  uint32_t *fslot;
  float *fg4, *fg16;
  size_t cap_fslot; /* fslot's room, and fg4's in floats (four a group of four slots); fg16
                       holds four floats a run of four groups (cap_fslot / 16 + cap_fine) */
};

/* A crowded cell's groups: its objects (in an order of their own, near ones together) at
 * fslot[4 g4 ..], n of them in groups of four from group g4 (the last group padded with
 * QK_NONE), and those groups four by four from g16, room for all the cell's objects set
 * out. state (collide/world_query.c): empty, being filled by a query, filled (n and the
 * groups may be read after reading it, acquire), or stale: an object of the cell has
 * moved since (qk__world_fine_touch), and its group's box may no longer hold it, so the
 * queries read the cell's objects one by one until the next update. */
typedef struct qk__wfine {
  uint32_t cell, g4, g16, n;
  atomic_int state;
} qk__wfine_t;

/* Cells with this many objects get groups. (scripts/fuzz.sh builds with 2, so that the
 * fuzzer's small worlds have them.) */
#ifndef QK__FINE_MIN
#define QK__FINE_MIN 16
#endif

/* A filed object o (not dirty) got a new shape in its cell: its cell's groups, if the query
 * tree has them, are stale. (Called by every move that leaves an object filed: a relaxed
 * load and a branch while no query has made the tree since the last update, else a
 * lookup in the groups' hash, for the first n / 16 + 64 such moves; after them every
 * group is dropped until the next update, as a frame that moves its objects after its
 * queries would otherwise pay the lookup for every move.) */
void qk__world_fine_stale(qk_world_t *w, const qk__wobj_t *o);
static inline void qk__world_fine_touch(qk_world_t *w, const qk__wobj_t *o) {
  if (atomic_load_explicit(&w->qstate, memory_order_relaxed) == 2 && w->n_fine)
    qk__world_fine_stale(w, o);
}

/* The scratch cache: qk__wscr_init makes it the world's allocator (w->alloc) in front
 * of user; between qk__wscr_begin and qk__wscr_end (an update) it keeps freed large
 * blocks and hands them out again, and at the end frees those kept before the update
 * began and not taken since. qk__wscr_flush frees every kept block (before the world is
 * freed); qk__wscr_bytes is what it holds beyond what the world's users asked for. */
void qk__wscr_init(qk_world_t *w, const qk_allocator_t *user);
void qk__wscr_begin(qk_world_t *w);
void qk__wscr_end(qk_world_t *w);
void qk__wscr_flush(qk_world_t *w);
size_t qk__wscr_bytes(const qk_world_t *w);

/* 2^e for e in [-1022, 1023], exactly (cheaper than ldexp in the inner loops; scaling
 * by it is exact for the world's values, which never come near the subnormals). */
static inline double qk__pow2(int e) {
  union {
    uint64_t u;
    double d;
  } v = {(uint64_t)(e + 1023) << 52};
  return v.d;
}

static inline int qk__wlive(const qk__wobj_t *o) { return o->gen & 1; }

/* The current pairs' keys in order when the last update kept them (ckeys), else NULL. */
static inline uint64_t *qk__world_kept_keys(const qk_world_t *w) {
  return w->cur.n && w->ckeys.n == w->cur.n ? w->ckeys.v : NULL;
}

/* The threads an update may use: one below the options' thread_min live objects. */
static inline unsigned qk__world_update_threads(const qk_world_t *w) {
  return w->n_live < w->opt.thread_min ? 1 : w->opt.threads;
}

/* The world's workers (collide/world_threads.c), a pool of index/ (qk__pool_t):
 * qk__world_pool_start(w, threads) starts threads - 1 of them, waiting between parallel
 * steps, unless it has or cannot (the steps then start threads of their own);
 * qk__world_pool_free joins them. qk__world_run_jobs is qk__run_jobs on them
 * (qk__pool_run_jobs): fn(i, ud) for i in [0, n), job i in share i mod min(threads, n),
 * share 0 on the calling thread. */
void qk__world_pool_start(qk_world_t *w, unsigned threads);
void qk__world_pool_free(qk_world_t *w);
/* While an update runs (on nonzero), the workers wait for its next step spinning for a
 * while before they park (qk__pool_hold). */
void qk__world_pool_hold(qk_world_t *w, int on);
/* fn(ctx) on the first worker while the caller goes on (the pool's next step and its end
 * wait for it); 0, fn not run, when there is no pool here or it is taken. */
int qk__world_pool_detach(qk_world_t *w, void (*fn)(void *), void *ctx);
void qk__world_run_jobs(const qk_world_t *w, unsigned threads, unsigned n,
                        void (*fn)(unsigned i, void *ud), void *ud);
/* The same jobs handed out in order to whichever thread is free (qk__run_jobs_dynamic: s is
 * the share running job i; results must not depend on it). */
void qk__world_run_jobs_shared(const qk_world_t *w, unsigned threads, unsigned n,
                               void (*fn)(unsigned i, unsigned s, void *ud), void *ud);

static inline qk_shape_t qk__wshape(const qk__wobj_t *o) {
  return (qk_shape_t){(qk_shape_kind_t)(o->flags & QK__WKIND), o->x, o->y, o->a, o->b};
}

/* The object's box (qk__shape_box of its shape). */
static inline qk_box_t qk__wbox(const qk__wobj_t *o) {
  if ((o->flags & QK__WKIND) == QK_SHAPE_BOX) return (qk_box_t){o->x, o->y, o->a, o->b};
  qk_shape_t s = qk__wshape(o);
  return qk__shape_box(&s);
}

/* (level, cy, cx) order of cells. */
static inline int qk__key_less(int l1, int32_t y1, int32_t x1, int l2, int32_t y2, int32_t x2) {
  return l1 != l2 ? l1 < l2 : y1 != y2 ? y1 < y2 : x1 < x2;
}

/* Cell c comes before (y, x) in (cy, cx) order. */
static inline int qk__cell_before(const qk__wcell_t *c, int64_t y, int64_t x) {
  return c->cy < y || (c->cy == y && c->cx < x);
}

/* The first cell in [lo, hi) not before (y, x), or hi (the cells before lo are before it). */
static inline uint32_t qk__cell_bisect(const qk__wcell_t *cl, uint32_t lo, uint32_t hi, int64_t y,
                                       int64_t x) {
  while (lo < hi) {
    uint32_t mid = lo + (hi - lo) / 2;
    if (qk__cell_before(&cl[mid], y, x))
      lo = mid + 1;
    else
      hi = mid;
  }
  return lo;
}

/* The order changed (an update): the query tree is no longer for it (its arrays are kept
 * for the next; qk__world_qtree_free frees them, before the world is freed). */
static inline void qk__world_qtree_stale(qk_world_t *w) {
  atomic_store_explicit(&w->qstate, 0, memory_order_relaxed);
}
void qk__world_qtree_free(qk_world_t *w);

/* Occupied levels of the order, ascending; returns how many. */
int qk__world_levels(const qk_world_t *w, int *levels);
/* Note the occupied levels from lv_n (after the order's cells are made). */
void qk__world_note_levels(qk_world_t *w);

/* Visit every live object whose box meets qb, giving fn its box: fn returns nonzero to stop. */
typedef int (*qk__wvisit_fn)(const qk_world_t *w, uint32_t slot, const qk_box_t *box, void *ud);
void qk__world_visit(const qk_world_t *w, qk_box_t qb, qk__wvisit_fn fn, void *ud);
/* The same for the box of a segment seg[0] -> seg[1], visiting only the cells along it
 * where the box would hold many more. */
void qk__world_visit_seg(const qk_world_t *w, qk_box_t qb, const qk_point_t *seg, qk__wvisit_fn fn,
                         void *ud);

/* The scratch of one update's search: the objects' boxes as floats in the order, four
 * to a group of 16 floats, and per cell the box around its objects. */
typedef struct qk__wpack {
  float *fgrp;
  size_t cap_fgrp; /* in groups */
  uint8_t *fexact; /* per object (in the order): a box whose float box is exact (in the
                      same allocation, after the groups) */
  qk_box_t *hb;
  size_t cap_hb;
  qk_box_t lv_box[QK__NLEV]; /* per level: the box around its cells' objects */
} qk__wpack_t;

/* The object array's room beyond its slots: enough to move the slots up to a line. */
#define QK__WOBJ_SLACK 64
/* Give the object array room for cap slots (cap > 0), the first min(cap, cap_obj) kept, on
 * a 64-byte boundary (malloc gives 16: every object then lay across two lines, and the
 * update's walks in cell order read both). 0 when memory ran short: nothing changed. */
int qk__world_obj_resize(qk_world_t *w, uint32_t cap);
/* The object array outgrows the caches (1 MB of L2 a core on this guest): the update's
 * walks in cell order ask for objects ahead from there on. Below it they took 1-10%
 * longer for it (the sparse huge scene at 10^4 objects). */
#define QK__WORLD_FAR_SLOTS 32768u
static inline int qk__world_far(const qk_world_t *w) { return w->n_obj >= QK__WORLD_FAR_SLOTS; }
/* How many pairs ahead a walk of the current pairs' keys asks for slot b's generation,
 * in a far world. */
#define QK__WALK_AHEAD 16

/* Bring the order up to date (file the dirty objects, drop removed ones) and fill the
 * pack. QK_ERR_NOMEM leaves the world unchanged; the caller frees the pack with
 * qk__world_pack_free either way. */
qk_status_t qk__world_reorder(qk_world_t *w, qk__wpack_t *pk);
void qk__world_pack_free(qk_world_t *w, qk__wpack_t *pk);
/* Fill the pack (sized for the order) for the order ord and its nc cells (with the
 * sentinel), which are the world's order, on the world's threads. The cells' and levels'
 * boxes only when the search will be on the grid (w->by_bands zero); then, with note,
 * each object's cell noted in the object too (cells_noted). */
void qk__world_pack(const qk_world_t *w, qk__wpack_t *pk, const uint32_t *ord,
                    const qk__wcell_t *cells, uint32_t nc, int note);

/* A key the search marks as a near candidate: the objects' float boxes meet, the objects
 * do not (see qk__world_search). */
#define QK__NEAR ((uint64_t)1 << 63)
/* The objects of slots i and j overlap, exactly. */
int qk__world_objects_meet(const qk_world_t *w, uint32_t i, uint32_t j);

/* Every overlapping pair of the packed order (collide/world_search.c), as unsorted keys
 * in *found (the caller frees it), on the world's threads. *found comes in empty or with
 * a buffer to start with (its room in cap, n = 0), which the search then owns; so do
 * tk[0 .. QK__KEEP_THREADS), buffers for threads 1, 2, ..., which come back (n: the
 * keys they held) for the caller to keep or free. QK_ERR_NOMEM (found empty) when memory
 * ran short. With *split nonzero on return, the keys were left where the threads found
 * them: the first thread's in found (whose room holds them all), thread t's in tk[t - 1]
 * (t < the threads of an update, which are then at most 1 + QK__KEEP_THREADS); else they
 * are all in found.
 * Began pairs only: prev (or NULL) holds the float boxes by slot of the last update, with
 * no object added or removed since; cur (or NULL) room for n_obj slots' float boxes, each
 * stored as (xmin, ymin, -xmax, -ymax): boxes a and b meet when b[i] <= -a[(i + 2) mod 4]
 * for every i, one four-wide comparison (negation is exact). When
 * the search is by bands and every float box is exact (*cur_ok = 1), or not (*cur_ok =
 * 2: the candidates whose objects do not meet are in *found (or tk) too, marked by
 * QK__NEAR), it fills cur and, given prev, keeps only the candidates whose float boxes at
 * the last update did not meet (*only_new): with the last update's pairs and near
 * candidates re-tested, those make this update's. */
/* Whether the search of the order as it is now goes by bands (else by the grid): only then
 * are the float boxes by slot (cur below) filled. */
int qk__world_by_bands(const qk_world_t *w);
qk_status_t qk__world_search(const qk_world_t *w, const qk__wpack_t *pk, qk__kvec_t *found,
                             qk__kvec_t *tk, int *split, const float *prev, float *cur, int *cur_ok,
                             int *only_new);

/* The cell (level, cx, cy) a fat box is filed in; *forced when the magnitude of its
 * coordinates raised the level. */
void qk__world_cell_of(const qk_box_t *f, int *level, int32_t *cx, int32_t *cy, int *forced);

/* The margin for a dirty object's speed: QK__WSTEP times the step of the move that made it
 * dirty, at most QK__WSTEP_CAP times its extent e. */
#define QK__WSTEP 2.0
#define QK__WSTEP_CAP 32.0
static inline double qk__world_step_margin(double step, double e) {
  double m = QK__WSTEP * step, cap = QK__WSTEP_CAP * e;
  return m < cap ? m : cap;
}

/* The fat box of dirty object o (its box widened by the margins: the larger of the size's and
 * the speed's), and in *e its extent. */
static inline qk_box_t qk__world_fat_box(const qk_world_t *w, const qk__wobj_t *o, double *e) {
  qk_box_t b = qk__wbox(o);
  *e = qk__max(b.xmax - b.xmin, b.ymax - b.ymin);
  double m = w->opt.margin * *e + w->opt.min_margin, ms = qk__world_step_margin(o->k.step, *e);
  if (ms > m) m = ms;
  if (!isfinite(m)) m = 0;
  return (qk_box_t){b.xmin - m, b.ymin - m, b.xmax + m, b.ymax + m};
}

static inline qk_handle_t qk__handle(const qk_world_t *w, uint32_t slot) {
  return ((uint64_t)w->obj[slot].gen << 32) | slot;
}

/* The handle of slot s as of the last update (the handles of the stored pairs). */
static inline qk_handle_t qk__uhandle(const qk_world_t *w, uint32_t s) {
  return ((uint64_t)w->ugen[s] << 32) | s;
}

/* The handles of a stored pair key (generations as of the last update). */
static inline qk_world_pair_t qk__key_pair(const qk_world_t *w, uint64_t k) {
  return (qk_world_pair_t){qk__uhandle(w, (uint32_t)(k >> 32)), qk__uhandle(w, (uint32_t)k)};
}

/* The generation slot s had at the update before the last: kept apart (egen, sorted by
 * slot) for the slots that changed at the last update, else its generation at the last. */
static inline uint32_t qk__ended_gen(const qk_world_t *w, uint32_t s) {
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

/* The handles of an ended pair's key: the generations its slots had at the update before
 * the last. */
static inline qk_world_pair_t qk__ended_pair(const qk_world_t *w, uint64_t k) {
  uint32_t a = (uint32_t)(k >> 32), b = (uint32_t)k;
  return (qk_world_pair_t){(uint64_t)qk__ended_gen(w, a) << 32 | a,
                           (uint64_t)qk__ended_gen(w, b) << 32 | b};
}

#endif /* QUADKIT_WORLD_INTERNAL_H */
