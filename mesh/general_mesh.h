/*
 * The general mesh mode's state, shared by mesh/general_*.c (docs/mesh.md, "The general
 * mode"). Not API. The pipeline: general_build.c validates the input while building its
 * constrained Delaunay triangulation (mesh/cdt.h) and labels the faces; general_seed.c
 * grades a quadtree on the input's features and inserts its seeds and the segments'
 * pre-split points; general_lattice.c fills the interior with a lattice (a plain size bound);
 * general_refine.c runs the quality refinement; general_out.c fills struct qk_mesh;
 * general_run.c drives them.
 */
#ifndef QK_MESH_GENERAL_MESH_H
#define QK_MESH_GENERAL_MESH_H

#include <stdio.h>

#include "mesh/cdt.h"
#include "mesh/general_internal.h"
#include "mesh/mesh_internal.h"

/* Parameters on a segment are K / 2^62, K in [0, 2^62]. */
#define QK__GM_ONE ((uint64_t)1 << 62)
/* g->sbud[s] not computed yet (budgets lie in -1 .. 62). */
#define QK__GM_SBUD_UNSET (-128)
/* The budget of an axis-parallel segment whose exact budget is below 62: any parameter on
 * the 2^-62 grid, its point the double nearest (exact within the budget), exactly on the
 * segment (general_refine.c, qk__gm_split_point); ends sharing no fine grid (0.1 and 1.3)
 * no longer stop its splits. */
#define QK__GM_SBUD_FREE 63

/* A point to insert before the refinement: a seed (seg == QK__CDT_NONE) or a segment's
 * pre-split point (at parameter k on input segment seg). */
typedef struct qk__gm_pt {
  uint64_t key; /* Morton key of the point in the root square: the insertion order */
  double x, y;
  uint64_t k;
  uint32_t seg;
  uint32_t rank; /* a split point's place among all split points, by segment then parameter */
} qk__gm_pt_t;

/* A CDT vertex: its input vertex (or NONE), the segment of a split point (or NONE) and
 * its parameter there. */
typedef struct qk__gm_vert {
  uint32_t in, seg;
  uint64_t par;
} qk__gm_vert_t;

/* A face: dropped (the unbounded face, holes) or kept, and its regional attribute. */
typedef struct qk__gm_face {
  double attr;
  uint32_t drop, id;
} qk__gm_face_t;

/* A queued triangle, with its vertices to recognise a slot the CDT has reused since. */
typedef struct qk__gm_tq {
  uint32_t t, a, b, c;
} qk__gm_tq_t;

typedef struct qk__gm {
  const qk_allocator_t *a;
  const qk_poly_t *P;
  const qk_mesh_options_t *opt;
  qk_mesh_error_t *err;
  /* The root square [X0, X0 + S] x [Y0, Y0 + S], S = 2^e, and the input's bounding box. */
  double X0, Y0, S, inv_S; /* inv_S = 2^-e */
  int e;
  double bx0, by0, bx1, by1;
  qk__cdt_t cdt;
  int cdt_live;
  /* Touching input (general_build.c, insert_segments): with `touch` set, a vertex inside a
   * segment splits it and a segment (or piece) that repeats another is merged into it,
   * instead of refusals. The pieces of the segments so changed, as (segment, from, to)
   * vertex triples in segment order and, within one, from its first vertex on; schg marks
   * those segments (allocated at the first change); nsplit and nmerged count the splits
   * and the merged segments or pieces. */
  int touch;
  int crossing; /* a crossing was refused (qk_mesh_t's refused_crossing) */
  uint32_t *pieces;
  size_t npieces, pieces_cap;
  uint8_t *schg;
  size_t nsplit, nmerged;
  /* Per input vertex: its CDT vertex, and whether two of its segments meet at an angle
   * below 60 degrees there (the concentric shells' apexes). */
  uint32_t *cv;
  uint8_t *vsmall;
  /* Per input segment: its precision budget (qk__seg_budget, -1 to 62), computed once
   * when first asked for; QK__GM_SBUD_UNSET until then. */
  int8_t *sbud;
  /* Per CDT vertex. */
  qk__gm_vert_t *vi;
  size_t vcap;
  /* Per triangle slot: its face. Faces: 0 is the unbounded one; fdrop marks dropped faces
   * (the unbounded one and holes), fattr their regional attribute. */
  uint32_t *face;
  size_t fcap;
  qk__gm_face_t *faces;
  uint32_t nface;
  size_t nface_cap;
  /* Triangles the last insertion created or changed (the triangles around the new vertex,
   * general_build.c). */
  uint32_t *dirty;
  size_t ndirty, dirty_cap;
  uint32_t dirty_face; /* their face when they all have one (NONE: a split segment's two) */
  uint32_t dirty_v;    /* the vertex they surround, counter-clockwise in g->dirty */
  /* Set by the refinement when it checks stars whole (general_refine.c): an insertion
   * whose star lies in one face then neither lists nor labels it (star_pending says so,
   * g->dirty stays empty) and the refinement's check walks the ring once for both. */
  int star_later, star_pending;
  /* The graded quadtree (lattice coordinates: the root square is [0, 1]^2), NULL until
   * graded (qk__gm_grade), and the statistics its leaves go to. */
  qk_tree_t *tree;
  qk_mesh_stats_t *stats;
  uint8_t *free_node; /* per node id: its grown square meets no feature */
  size_t free_cap;
  uint32_t *arena; /* feature lists of the subdivision */
  double *fbox;    /* per feature (vertices, then segments): its box, then its ends */
  size_t arena_n, arena_cap;
  qk__gm_pt_t *pts;
  size_t npts, pts_cap;
  /* The refinement. */
  double bound_deg, sin2_bound;
  /* A plain size bound h (max_size, no size function): h and h^2 (1 +- 2^-48), the
   * quality test's thresholds, computed once. */
  int size_plain;
  double h_plain, h2_hi, h2_lo;
  int reserved; /* the refinement's room was reserved before the seeding's points */
  double area;  /* the kept faces' area once qk__gm_area() measured it (insertions keep it) */
  int area_known;
  int refining;
  qk__gm_tq_t *bad;
  size_t nbad, bad_head, bad_cap;
  uint32_t *enc; /* encroached subsegments: pairs of vertices, and their segment */
  size_t nenc, enc_cap;
  uint32_t *stack;
  size_t stack_cap;
  uint32_t *mark; /* per triangle slot: the cavity search's stamp (general_refine.c) */
  size_t mark_cap;
  uint32_t mark_gen;
  /* The CDT's record of a circumcentre's insertion, to take it back (general_refine.c,
   * insert_circumcentre; mesh/cdt.h, undo). */
  uint32_t *undo;
  size_t undo_cap;
  size_t insertions, work_cap;
  size_t seeds;      /* seeds inserted */
  size_t cap_leaves; /* leaves that size the work cap (general_run.c) */
  double smallest_input_angle;
  size_t deep_splits, deep_cap; /* the grading's splits below 2^-36 of the root square */
  size_t sep_splits, sep_cap;   /* the grading's splits that separate features, at any depth */
  const char *stage;            /* the step running, for messages: "grading the quadtree", ... */
} qk__gm_t;

/* "vertex 3" or, when the input has line numbers, "vertex 3 (line 12)", into buf; the
 * number is num's (qk__mesh_num or qk__mesh_snum). */
static inline const char *qk__gm_named(const char *what, unsigned long num, unsigned long line,
                                       char buf[80]) {
  if (line)
    snprintf(buf, 80, "%s %lu (line %lu)", what, num, line);
  else
    snprintf(buf, 80, "%s %lu", what, num);
  return buf;
}

/* Vertex i (or hole i, ...) so named. */
static inline const char *qk__gm_name(const qk_poly_t *P, const char *what, size_t i,
                                      unsigned long line, char buf[80]) {
  return qk__gm_named(what, qk__mesh_num(P, i), line, buf);
}

/* Segment s so named: the input segment's number where s is a piece of one. */
static inline const char *qk__gm_sname(const qk_poly_t *P, const char *what, size_t s,
                                       unsigned long line, char buf[80]) {
  return qk__gm_named(what, qk__mesh_snum(P, s), line, buf);
}

/* CDT vertex v's coordinates. */
static inline const double *qk__gm_vxy(const qk__gm_t *g, uint32_t v) { return &g->cdt.xy[2 * v]; }

/* general_build.c: root square, the CDT of the input (validation), faces, holes, regions. */
qk_status_t qk__gm_build(qk__gm_t *g);
/* The kept faces' area (the sum of their triangles'), measured once: insertions only
 * divide triangles. */
double qk__gm_area(qk__gm_t *g);
/* Its first part: the root square and the CDT of the input's vertices and segments, which
 * refuses duplicates, vertices on segments and crossings (expected O(n log n)). */
qk_status_t qk__gm_check_input(qk__gm_t *g);
/* Grow the per-vertex and per-triangle arrays to nv vertices and nt triangles: exactly
 * (a reservation for the final size) or by doubling. */
qk_status_t qk__gm_fit_to(qk__gm_t *g, size_t nv, size_t nt, int exact);
/* Grow them to the CDT's size (inline: a compare and a branch while there is room). */
static inline qk_status_t qk__gm_fit(qk__gm_t *g) {
  if (g->cdt.nv <= g->vcap && g->cdt.nt <= g->fcap) return QK_OK;
  return qk__gm_fit_to(g, g->cdt.nv, g->cdt.nt, 0);
}
/* The parameter of CDT vertex v on input segment s (an endpoint or a split point of s). */
uint64_t qk__gm_param(const qk__gm_t *g, uint32_t v, uint32_t s);
/* Insert (x, y), located at (t0, k0, w) as qk__cdt_locate reports it, label the new
 * triangles' faces and record the vertex as a split point of segment seg at parameter k
 * (seg NONE for a free point). *v_out is the vertex; *existed as qk__cdt_insert. */
qk_status_t qk__gm_insert(qk__gm_t *g, double x, double y, uint32_t t0, int k0, qk__cdt_where_t w,
                          uint32_t seg, uint64_t k, uint32_t *v_out, int *existed);
/* List the triangles around the new vertex v into g->dirty, labelling them with face f
 * unless f is NONE (general_build.c). */
qk_status_t qk__gm_star(qk__gm_t *g, uint32_t v, uint32_t f);
/* qk__gm_insert of a free point strictly inside triangle t0 (QK__CDT_IN, seg NONE), the
 * CDT's undo record set: by qk__cdt_insert_in_undo, with the same bookkeeping (inline in
 * the refinement, its one caller: a call of its own was 20 instructions of the 2,600 a
 * circumcentre costs on South Africa at extent/256). */
static inline qk_status_t qk__gm_insert_in(qk__gm_t *g, double x, double y, uint32_t t0,
                                           uint32_t *v_out) {
  const uint32_t f0 = g->face[t0];
  g->ndirty = 0, g->star_pending = 0;
  qk_status_t st = qk__cdt_insert_in_undo(&g->cdt, x, y, t0, v_out);
  if (st) return st;
  if (qk__gm_fit(g)) return QK_ERR_NOMEM;
  const uint32_t v = *v_out;
  if (g->star_later)
    g->star_pending = 1, g->dirty_v = v; /* as qk__gm_insert */
  else if (qk__gm_star(g, v, f0))
    return QK_ERR_NOMEM;
  g->vi[v] = (qk__gm_vert_t){QK__CDT_NONE, QK__CDT_NONE, 0};
  g->dirty_face = f0;
  g->insertions++;
  return QK_OK;
}
/* The Morton key of input point (x, y) in the root square, and a stable sort of points
 * by key (general_seed.c). */
uint64_t qk__gm_morton(const qk__gm_t *g, double x, double y);
qk_status_t qk__gm_sort_points(const qk__gm_t *g, qk__gm_pt_t *pts, size_t n);
/* general_seed.c: the pre-split points (and the seeds, when compiled in), inserted; the
 * graded quadtree first only with a size function or seeds. */
qk_status_t qk__gm_seed(qk__gm_t *g);
/* general_lattice.c: with a plain size bound, the interior lattice (its outline's points
 * inserted, its triangles made directly); a check that fails only stops it. Tests: 0 in
 * qk__gm_test_lattice turns it off, 2 stops it after the outline. */
qk_status_t qk__gm_lattice(qk__gm_t *g);
extern int qk__gm_test_lattice;
/* general_seed.c: the graded quadtree (g->tree, g->stats' leaves; its leaves added to
 * g->cap_leaves), or the refusal of an input whose grading would not end soon. */
qk_status_t qk__gm_grade(qk__gm_t *g);
/* The refinement's work cap (general_run.c): ten times five insertions a leaf that counts
 * (size cells, and the graded tree's leaves once graded), the pre-split points and the
 * input's vertices and segments, plus 10^5; plus 10^4 while the tree is not graded, so that
 * an input whose features stay close along a stretch reaches the grading's refusal soon. */
static inline size_t qk__gm_work_cap(const qk__gm_t *g) {
  return 10 * (g->npts + 5 * g->cap_leaves + g->P->nv + g->P->ns) + (g->tree ? 100000 : 10000);
}
/* Tests only: nonzero has the refinement grade the tree at its start (general_run.c), not
 * at the input-sized work cap, so that small inputs take the late grading's path. */
extern int qk__gm_test_grade_late;
/* general_refine.c: split the subsegment a-b of segment s at an exact point (concentric
 * shells next to an input vertex); QK_ERR_GEOMETRY naming s when no exact point exists. */
qk_status_t qk__gm_split(qk__gm_t *g, uint32_t a, uint32_t b, uint32_t s);
/* Room in the CDT and its per-triangle arrays for `more` points about to be inserted and,
 * with a plain size bound, for the refinement's estimated triangles. */
qk_status_t qk__gm_reserve(qk__gm_t *g, size_t more);
/* Quality refinement until no subsegment is encroached and no triangle is bad. */
qk_status_t qk__gm_refine(qk__gm_t *g);
/* Is triangle t bad (to be split)? 0 good or exempt, 1 bad. */
int qk__gm_is_bad(const qk__gm_t *g, uint32_t t);
/* Is triangle t's smallest angle below the bound, but exempt (inside a small input angle)? */
int qk__gm_exempt(const qk__gm_t *g, const uint32_t *tv);
/* general_out.c: fill the mesh. */
qk_status_t qk__gm_output(qk__gm_t *g, qk_mesh_t *m);

#endif
