/*
 * The world's private layout, shared by collide/world.c (objects, filing, pairs) and
 * collide/world_query.c (queries). Not API.
 */
#ifndef QUADKIT_WORLD_INTERNAL_H
#define QUADKIT_WORLD_INTERNAL_H

#include "collide/collide_internal.h"

/* Levels: cells of side 2^L for L in [QK__LMIN, QK__LMIN + QK__NLEV). */
#define QK__LMIN (-200)
#define QK__NLEV 320

typedef struct qk__wobj {
  qk_shape_t s;   /* normalised */
  qk_box_t box;   /* the shape's box, rounded outwards */
  qk_box_t loose; /* its cell's loose square [cx 2^L, (cx + 2) 2^L) per axis: the object is
                     re-filed only when box leaves it (the far sides are open) */
  uint64_t tag;
  double fe;     /* extent of the fat box it was filed by (re-filed when it shrinks to 1/8) */
  uint32_t gen;  /* generation of the slot (odd: live) */
  uint32_t ugen; /* generation at the last update: the handles of the stored pairs */
  int16_t level;
  uint16_t live;
  uint32_t next, prev; /* the cell's list; next also links the free slots */
} qk__wobj_t;

/* A cell of the loose grid at one level; count == 0 marks an empty table entry. */
typedef struct qk__wcell {
  int64_t cx, cy;
  int32_t level;
  uint32_t head;
  uint32_t count;
  uint32_t start; /* during an update: the cell's header in the packed array (its
                     objects follow) */
} qk__wcell_t;

/* An object as the pair search reads it: its box and slot, packed cell by cell; each
 * cell's run starts with a header (slot QK_NONE) holding the box around its objects. */
typedef struct qk__wpack {
  qk_box_t box;
  uint32_t slot;
  uint32_t is_box; /* both boxes: the box test is the whole test (in a header: the cell's
                      first float group) */
} qk__wpack_t;

typedef struct qk__pvec {
  qk_world_pair_t *v;
  size_t n, cap;
} qk__pvec_t;

/* Pairs as 64-bit keys: slot a in the high half, slot b (> a) in the low half, so the
 * keys' order is the (slot a, slot b) order. */
typedef struct qk__kvec {
  uint64_t *v;
  size_t n, cap;
} qk__kvec_t;

struct qk_world {
  qk_allocator_t alloc;
  qk_world_options_t opt;
  qk__wobj_t *obj;
  uint32_t n_obj, cap_obj; /* slots used (high-water mark) and allocated */
  uint32_t free_head;      /* first free slot, or QK_NONE */
  size_t n_live;
  qk__wcell_t *cells; /* open addressing, linear probing; cap a power of two */
  size_t cap_cells, n_cells;
  uint32_t level_objs[QK__NLEV];
  uint32_t level_cells[QK__NLEV];
  qk__kvec_t cur, began; /* this frame's pairs and those that began (handles: ugen) */
  qk__pvec_t ended;      /* pairs that ended, as handles (their slots may be reused) */
  int ident_dirty;       /* an object was added or removed since the last update */
  /* Scratch of qk_world_update, kept between frames. */
  qk__wpack_t *pack;
  size_t cap_pack;
  uint32_t *occ; /* the occupied table entries, in table order */
  size_t cap_occ;
  float *fgrp;      /* the boxes as floats (a prefilter), 4 objects to 16 floats */
  size_t cap_fgrp;  /* in groups */
  qk__kvec_t found; /* the search's pairs, unsorted */
  uint32_t *count;  /* per slot: pairs whose first slot it is (cap_count entries) */
  size_t cap_count;
};

/* 2^e for e in [-1022, 1023], exactly (cheaper than ldexp in the inner loops; scaling
 * by it is exact for the world's values, which never come near the subnormals). */
static inline double qk__pow2(int e) {
  union {
    uint64_t u;
    double d;
  } v = {(uint64_t)(e + 1023) << 52};
  return v.d;
}

static inline size_t qk__cell_hash(int level, int64_t cx, int64_t cy) {
  uint64_t h = (uint64_t)cx * 0x9E3779B97F4A7C15ull;
  h ^= (uint64_t)cy * 0xC2B2AE3D27D4EB4Full + ((uint64_t)(uint32_t)level << 7);
  h ^= h >> 29;
  h *= 0xBF58476D1CE4E5B9ull;
  return (size_t)(h ^ (h >> 32));
}

/* The table entry of cell (level, cx, cy), or the empty entry where it would go. */
static inline size_t qk__cell_find(const qk_world_t *w, int level, int64_t cx, int64_t cy) {
  size_t mask = w->cap_cells - 1, i = qk__cell_hash(level, cx, cy) & mask;
  for (;;) {
    const qk__wcell_t *c = &w->cells[i];
    if (c->count == 0) return i;
    if (c->cx == cx && c->cy == cy && c->level == level) return i;
    i = (i + 1) & mask;
  }
}

/* The cell (level, cx, cy), or NULL (inline, for the pair search). */
static inline const qk__wcell_t *qk__cell_get(const qk_world_t *w, int level, int64_t cx,
                                              int64_t cy) {
  if (w->n_cells == 0) return NULL;
  const qk__wcell_t *c = &w->cells[qk__cell_find(w, level, cx, cy)];
  return c->count ? c : NULL;
}

/* The cell (level, cx, cy), or NULL. */
const qk__wcell_t *qk__world_cell(const qk_world_t *w, int level, int64_t cx, int64_t cy);

/* Occupied levels, ascending; returns how many. */
int qk__world_levels(const qk_world_t *w, int *levels);

/* Visit every live object whose box meets qb: fn returns nonzero to stop. */
typedef int (*qk__wvisit_fn)(const qk_world_t *w, uint32_t slot, void *ud);
void qk__world_visit(const qk_world_t *w, qk_box_t qb, qk__wvisit_fn fn, void *ud);
/* The same for the box of a segment seg[0] -> seg[1], visiting only the cells along it
 * where the box would hold many more. */
void qk__world_visit_seg(const qk_world_t *w, qk_box_t qb, const qk_point_t *seg, qk__wvisit_fn fn,
                         void *ud);

static inline qk_handle_t qk__handle(const qk_world_t *w, uint32_t slot) {
  return ((uint64_t)w->obj[slot].gen << 32) | slot;
}

/* The handles of a stored pair key (generations as of the last update). */
static inline qk_world_pair_t qk__key_pair(const qk_world_t *w, uint64_t k) {
  uint32_t a = (uint32_t)(k >> 32), b = (uint32_t)k;
  return (qk_world_pair_t){((uint64_t)w->obj[a].ugen << 32) | a,
                           ((uint64_t)w->obj[b].ugen << 32) | b};
}

#endif /* QUADKIT_WORLD_INTERNAL_H */
