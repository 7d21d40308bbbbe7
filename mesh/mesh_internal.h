/*
 * Private declarations shared by the mesh module's sources. Not API.
 */
#ifndef QUADKIT_MESH_INTERNAL_H
#define QUADKIT_MESH_INTERNAL_H

#include "quadkit/mesh.h"
#include "index/index_access.h"

#include <math.h>
#include <stdarg.h>
#include <stdint.h>

/* Allocated capacities (in elements) of a qk_poly's arrays. */
typedef struct qk__poly_caps {
  size_t v, vy, vl, s, sl, h, hy, hl, vm, sm, r;
} qk__poly_caps_t;

/* A regional attribute: a point, the attribute of the region holding it, its line. */
typedef struct qk__region_pt {
  double x, y, attr;
  unsigned long line;
} qk__region_pt_t;

/* The parsed input, as read: validation happens in qk_mesh_generate(). Line numbers are
 * 0 for inputs made from arrays. */
struct qk_poly {
  qk_allocator_t alloc;
  qk__poly_caps_t cap;
  unsigned first_index;
  size_t nv, ns, nh;
  double *vx, *vy;
  unsigned long *vline;
  uint32_t *seg; /* 2 * ns, 0-based */
  unsigned long *sline;
  double *hx, *hy;
  unsigned long *hline;
  int32_t *vmark, *smark; /* boundary markers, NULL when the input has none */
  qk__region_pt_t *reg;   /* regional attributes */
  size_t nr;
  double *vmoved; /* per vertex: how far qk_poly_round() calls moved it, summed (NULL: never
                     rounded; nv entries, allocated with vx's capacity) */
  size_t vmoved_cap;
  /* Only in the general mode's working copy of an input whose vertices lie inside its
   * segments or whose segments repeat (general_run.c): per segment of the copy, the input
   * segment it is a piece of, for messages and outputs. NULL in every qk_poly_t a caller
   * holds. */
  const uint32_t *sorig;
};

/* After qk_poly_round(): QK_ERR_GEOMETRY, naming it, when a hole or regional attribute
 * point (left as read) is nearer a segment than rounding moved either of its ends, which
 * may have moved it across. */
qk_status_t qk__poly_check_rounded(const qk_poly_t *p, qk_mesh_error_t *err);

/*
 * The lattice the mesher works on: lattice point (X, Y) is the input point
 * (x0 + X 2^-f, y0 + Y 2^-f). The book's mode uses f = 0 and origin (0, 0).
 */
typedef struct qk__lattice {
  int f;
  double x0, y0;
} qk__lattice_t;

/* An output segment: a mesh edge along an input segment, and that segment's marker. */
typedef struct qk__oseg {
  uint32_t a, b;
  int32_t mark;
  uint32_t seg;
} qk__oseg_t;

/* The mesher's arena for large blocks (all modes) when the caller gives no allocator
 * (mesh/arena.c): qk__mesh_arena_fn is a qk_alloc_fn over it. */
typedef struct qk__mesh_arena qk__mesh_arena_t;
int qk__mesh_arena_available(void);
qk__mesh_arena_t *qk__mesh_arena_new(void);
void *qk__mesh_arena_fn(void *ud, void *ptr, size_t osize, size_t nsize);
void qk__mesh_arena_seal(qk__mesh_arena_t *r);
void qk__mesh_arena_free(qk__mesh_arena_t *r);
/* Tests: the bytes of chunks kept for later meshes (qk_mesh_trim), and every kept
 * chunk filled with `byte`. */
size_t qk__mesh_arena_kept_bytes(void);
void qk__mesh_arena_poison_kept(unsigned char byte);

struct qk_mesh {
  qk_allocator_t alloc;
  qk__mesh_arena_t *arena; /* NULL, or the arena alloc runs on (the mesh is libc's) */
  qk_tree_t *tree;
  uint64_t size;
  double *xy; /* 2 * nv */
  size_t nv;
  uint32_t *tri; /* 3 * nt */
  uint32_t *comp;
  size_t nt;
  /* The input components, kept for drawing: integer vertices and segments. */
  double *cxy;
  size_t ncv;
  uint32_t *cseg;
  size_t ncs;
  qk_mesh_stats_t stats;
  qk__lattice_t lat;
  int32_t *vmark;   /* per vertex: boundary marker (nv + 1) */
  qk__oseg_t *oseg; /* mesh edges along input segments */
  size_t noseg, noseg_cap;
  int has_marks; /* the input carried boundary markers */
  double *attr;  /* per triangle: regional attribute (nt + 1), NULL without regions */
  /* General mode: the angle bound (degrees) its exempt angles are counted against. Its
   * smallest and largest angles and exempt count are computed by qk_mesh_stats, from the
   * triangles (qk__mesh_angles), not by the generation; 0 in the other modes, whose
   * generation fills them. */
  double angle_bound_deg;
  /* General mode: set when it refused two segments that cross (away from any vertex), so
   * that QK_MESH_AUTO's fallback keeps the lattice mode's message for them (generate.c). */
  int refused_crossing;
};

/* The smallest and largest angle of mesh m (degrees; 0 without triangles) and the count
 * of angles below bound_deg: one pass over the triangles. */
void qk__mesh_angles(const qk_mesh_t *m, double bound_deg, double *min_deg, double *max_deg,
                     size_t *below);

/* Fill an error record (err may be NULL; column 0, item SIZE_MAX: the message names the
 * item); returns `st` for convenience. */
qk_status_t qk__mesh_fail(qk_mesh_error_t *err, qk_status_t st, unsigned long line, const char *fmt,
                          ...)
#if defined(__GNUC__)
    __attribute__((format(printf, 4, 5)))
#endif
    ;

/* A component edge, directed so that the component's interior lies on its left. */
typedef struct qk__edge {
  int64_t ax, ay, bx, by; /* input (not doubled) coordinates */
  uint32_t comp;          /* 1-based component id */
  uint32_t seg;           /* input segment index */
} qk__edge_t;

/*
 * The pieces of a unit leaf's closure that component edges cover: its four sides and two
 * diagonals. Each holds +c when component c's edge runs along the piece's positive
 * direction (west to east, south to north, SW to NE, SE to NW), -c when against it.
 */
enum { QK__P_S, QK__P_E, QK__P_N, QK__P_W, QK__P_D0, QK__P_D1, QK__P_COUNT };
typedef struct qk__unit_rec {
  uint32_t node;
  int32_t piece[QK__P_COUNT];
  uint32_t edge[8]; /* the edges meeting the closed square (at most 8, see unit_leaf) */
  uint32_t nedge;
} qk__unit_rec_t;

/* An edge's bounding box, for the subdivision's tests. */
typedef struct qk__ebox {
  int64_t minx, maxx, miny, maxy;
} qk__ebox_t;

/* Generation state; freed in one place. */
/* What a lattice mode's refusal of segments that meet found (qk__gen_t's meet): the
 * general mode's own check refused them (the precheck), two segments crossing, or touching
 * or overlapping (an end of one on the other). */
enum { QK__MEET_CHECK = 1, QK__MEET_CROSS = 2, QK__MEET_TOUCH = 3 };

typedef struct qk__gen {
  const qk_allocator_t *a;
  const qk_poly_t *poly; /* the input on the lattice */
  const qk_poly_t *src;  /* the input as given (for messages) */
  qk__lattice_t lat;
  const qk_mesh_options_t *opt;
  qk_mesh_error_t *err;
  /* Set where the lattice modes refuse segments that meet (components touching or
   * crossing, repeated or overlapping segments): QK_MESH_AUTO then tries the general mode,
   * which takes touching input (generate.c): a QK__MEET_ value, 0 when none. */
  int meet;
  /* Set where a size function asks for less than a unit square of the lattice gives
   * (mesh/refine.c): QK_MESH_AUTO then meshes in the general mode. */
  int size_below_unit;
  uint64_t U;
  qk__edge_t *e;
  qk__ebox_t *box; /* per edge, made by the subdivision */
  size_t ne;
  uint32_t ncomp;
  /* The edge-list arena of the subdivision: lists of edge indices, a stack of them. */
  uint32_t *arena;
  size_t arena_n, arena_cap;
  qk__unit_rec_t *rec;
  size_t nrec, rec_cap;
  size_t nsplit; /* leaves split by the subdivision (each makes three more leaves) */
  qk_tree_t *tree;
} qk__gen_t;

/* An open-addressing hash map from 64-bit keys to 32-bit values. */
typedef struct qk__hmap {
  uint64_t *k;
  uint32_t *v;
  size_t cap, n; /* cap is a power of two; key UINT64_MAX marks an empty slot */
} qk__hmap_t;

/* The slot of a key in a map of cap slots (a power of two, at least 2): the top bits of
 * the key times 2^64 / phi (Fibonacci hashing), which spreads the lattice positions'
 * regular keys (x << 32 | y) well. */
static inline size_t qk__hmap_slot(uint64_t key, size_t cap) {
  return (size_t)((key * 0x9e3779b97f4a7c15ull) >> (64 - __builtin_ctzll((uint64_t)cap)));
}

/* The value of a key, or UINT32_MAX when absent. */
static inline uint32_t qk__hmap_find(const qk__hmap_t *h, uint64_t key) {
  size_t mask = h->cap - 1, j = qk__hmap_slot(key, h->cap);
  for (uint64_t k; (k = h->k[j]) != UINT64_MAX; j = (j + 1) & mask)
    if (k == key) return h->v[j];
  return UINT32_MAX;
}

/* Triangulation state. Coordinates are doubled input coordinates. */
typedef struct qk__tri_state {
  const qk_allocator_t *a;
  qk__hmap_t vmap;  /* vertex id by doubled lattice position (x << 32 | y): every leaf corner */
  int64_t *vx, *vy; /* doubled coordinates */
  uint8_t *steiner;
  size_t nv, vcap, vycap, scap;
  uint32_t *tri;    /* 3 per triangle */
  uint32_t *label;  /* per triangle: its cell while triangulating, then its component */
  uint32_t *region; /* per triangle: its region (connected part between boundaries); NULL
                     * when the input has no hole and no regional attribute point */
  size_t nt, tcap, lcap, rcap;
  uint32_t nregion;
  /* Per input segment in order, its lattice points from its first endpoint to its last
   * (n + 1 for n lattice steps): the vertex there, from the vertex map before it is freed
   * (every lattice point of a segment is a corner of its unit leaves). */
  uint32_t *segv;
  size_t nsegv;
  /* The triangle shapes made, by log2 of the doubled leaf side: bit 3s (s a side, south,
   * east, north, west) the centre fan's triangle (corner s, corner s+1, centre), bits
   * 3s+1 and 3s+2 (corner s, midpoint s, centre) and (midpoint s, corner s+1, centre),
   * bits 12-13 the split along SW-NE (SW, SE, NE), (SW, NE, NW) and bits 14-15 along
   * SE-NW (SW, SE, NW), (SE, NE, NW): every triangle is one of these, translated. */
  uint16_t shapes[64];
  /* Per vertex, its number in the order of first use by the triangles as they are made
   * (the numbering of the output when every triangle is kept), ocap entries. */
  uint32_t *ord;
  /* tri holds the output's numbering (ord's) rather than vertex ids: when no point is
   * located in the triangles (no hole, no regional attribute point), so that every
   * triangle is kept and no one reads the triangles' coordinates through tri. */
  int tri_ord;
  size_t ocap;
} qk__tri_state_t;

/* The doubled-coordinate vertices of shape bit k (see qk__tri_state_t.shapes) in the
 * leaf square [0, S]^2 (mesh/triangulate.c). */
void qk__mesh_shape(int k, int64_t S, int64_t x[3], int64_t y[3]);

/* Facts the triangulation hands to hole removal. */
typedef struct qk__leaf_tris {
  uint32_t *first; /* per leaf's node id: first triangle of the leaf (set at leaves only) */
  size_t cap;
  size_t nleaves; /* leaves of the balanced tree */
} qk__leaf_tris_t;

/* "Not set" for node, record, cell and label slots. */
#define QK__MESH_UNSET UINT32_MAX

/* User-facing vertex or segment number. */
static inline unsigned long qk__mesh_num(const qk_poly_t *p, size_t i) {
  return (unsigned long)(i + p->first_index);
}

/* User-facing number of segment s (of the input segment it is a piece of, in a copy). */
static inline unsigned long qk__mesh_snum(const qk_poly_t *p, size_t s) {
  return qk__mesh_num(p, p->sorig ? p->sorig[s] : s);
}

static inline int64_t qk__cross(int64_t ax, int64_t ay, int64_t bx, int64_t by) {
  return ax * by - ay * bx;
}

/* Order unit-leaf records by node id (qsort/bsearch). */
int qk__mesh_rec_cmp(const void *a, const void *b);

/* Validate vertices and segments, find the components (cycles) and orient their edges
 * counter-clockwise (mesh/validate.c). Fills g->e, g->ne, g->ncomp and g->U. */
qk_status_t qk__mesh_validate(qk__gen_t *g, uint64_t size);

/* Step 1, the subdivision of the square (x0, y0, s) at `node`, whose closure the k edges
 * at g->arena[off..] meet (mesh/subdivide.c). */
qk_status_t qk__mesh_subdivide(qk__gen_t *g, uint32_t node, int64_t x0, int64_t y0, int64_t s,
                               size_t off, size_t k);

/* Step 3 and the component labels (mesh/triangulate.c); qk__mesh_tri_free frees T. */
qk_status_t qk__mesh_triangulate(qk__gen_t *g, qk__tri_state_t *T, qk__leaf_tris_t *lt);
void qk__mesh_tri_free(qk__tri_state_t *T);

/* Mark the regions holding hole points in drop[] (T->nregion entries; mesh/holes.c). */
qk_status_t qk__mesh_find_holes(qk__gen_t *g, qk__tri_state_t *T, const qk__leaf_tris_t *lt,
                                uint8_t *drop);

/* The region (T->region id) holding each regional-attribute point of the input, or
 * QK__MESH_UNSET for one the tree does not hold (mesh/holes.c); `out` has P->nr slots. */
qk_status_t qk__mesh_find_regions(qk__gen_t *g, qk__tri_state_t *T, const qk__leaf_tris_t *lt,
                                  uint32_t *out);

/* Most lattice steps along the segments (and triangles asked for by a size bound) the
 * dyadic mode accepts: about 2^25 triangles, a few GB at most. */
#define QK__MESH_MAX_STEPS ((double)(1 << 24))

/* Lattice steps (of 2^-f) along the segments: the sum over segments of the larger of
 * |dx| and |dy| times 2^f; *longest (may be NULL) gets the segment with the most. */
double qk__mesh_lattice_steps(const qk_poly_t *P, int f, size_t *longest);

/* The book's mode on domain side U (0: the default, from the coordinates): QK_ERR_LIMIT (a message
 * in err, naming the longest segment, when err is not NULL) when it would take more than
 * QK__MESH_MAX_STEPS unit steps along the segments or about that many triangles for the size bound,
 * as the dyadic mode refuses (mesh/lattice.c). */
qk_status_t qk__mesh_book_limit(const qk_poly_t *P, const qk_mesh_options_t *opt, uint64_t U,
                                qk_mesh_error_t *err);

/* Choose the lattice for an input (mesh/lattice.c): the book's (f = 0, origin 0) when
 * `book`, else the coarsest dyadic lattice holding every vertex exactly and fine enough
 * for opt->max_size. Fails with QK_ERR_GEOMETRY naming the vertex when none fits. */
qk_status_t qk__mesh_lattice(const qk_poly_t *P, const qk_mesh_options_t *opt, int book,
                             qk__lattice_t *L, qk_mesh_error_t *err);

/* A copy of P with its coordinates on lattice L (vertices exactly), through allocator a. */
qk_status_t qk__mesh_lattice_poly(const qk_poly_t *P, const qk__lattice_t *L,
                                  const qk_allocator_t *a, qk_poly_t **out);

/* Free a copy made by qk__mesh_lattice_poly (NULL is a no-op). */
void qk__mesh_lattice_poly_free(qk_poly_t *q);

/* Input coordinate of a doubled lattice coordinate (exact, see mesh/lattice.c). */
static inline double qk__lat_out(const qk__lattice_t *L, int64_t v2, double origin) {
  return ldexp((double)v2, -(L->f + 1)) + origin;
}

/* 2^k when it is a double (-1074 <= k <= 1023), else 0. Then x * qk__pow2(k) is exactly
 * ldexp(x, k): both are the correctly rounded x 2^k. The long loops multiply instead of
 * calling ldexp (about 50 instructions a call). */
static inline double qk__pow2(int k) { return k >= -1074 && k <= 1023 ? ldexp(1.0, k) : 0; }

/* ldexp(x, k) given s = qk__pow2(k). */
static inline double qk__ldexp_by(double x, double s, int k) {
  return s != 0 ? x * s : ldexp(x, k);
}

/* Step 1b: split leaves larger than the size bound asks (mesh/refine.c). */
qk_status_t qk__mesh_refine(qk__gen_t *g);

/* The general mode (mesh/general_*.c, docs/mesh.md "The general mode"): mesh P into m
 * (allocated and zeroed, its allocator set); on an error m holds nothing to keep (the
 * caller frees it). */
qk_status_t qk__mesh_general(const qk_poly_t *P, const qk_mesh_options_t *opt, qk_mesh_t *m,
                             qk_mesh_error_t *err);

/* The general mode's check of the input alone (mesh/general_run.c): the CDT of P's
 * vertices and segments, refusing duplicate vertices, vertices on segments and crossing
 * or overlapping segments with QK_ERR_GEOMETRY (naming both), in expected O(n log n);
 * QK_ERR_LIMIT for an extent its predicates cannot take. Nothing is kept. */
qk_status_t qk__mesh_general_check(const qk_poly_t *P, const qk_mesh_options_t *opt,
                                   qk_allocator_t *a, qk_mesh_error_t *err);

/* Lattice steps along the segments above which the lattice modes check the input for
 * crossings with qk__mesh_general_check before subdividing: their own check happens during
 * the subdivision, whose work grows with the steps (2^24 steps: minutes and gigabytes
 * before a crossing was reported). */
#define QK__MESH_PRECHECK_STEPS ((double)(1 << 16))

/* After a lattice mode's validation: the book's limit (qk__mesh_book_limit, when book_U,
 * the book's domain side, is not 0), then that check for an input (lat: on its lattice,
 * src: as given) of more than QK__MESH_PRECHECK_STEPS steps; its QK_ERR_GEOMETRY and
 * QK_ERR_NOMEM are returned (with err filled), anything else is left to the lattice
 * mode's own checks (mesh/lattice.c). */
qk_status_t qk__mesh_precheck(const qk_poly_t *lat, const qk_poly_t *src,
                              const qk_mesh_options_t *opt, uint64_t book_U, qk_allocator_t *a,
                              qk_mesh_error_t *err);

/* The output segments and vertex markers of a finished mesh (mesh/markers.c): segv is the
 * triangulation's vertices along the segments (qk__tri_state_t.segv), newid their ids in m
 * (QK__MESH_UNSET for vertices not kept). */
qk_status_t qk__mesh_markers(qk__gen_t *g, qk_mesh_t *m, const uint32_t *segv,
                             const uint32_t *newid);

#endif /* QUADKIT_MESH_INTERNAL_H */
