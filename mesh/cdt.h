/*
 * A constrained Delaunay triangulation on flat arrays, for the general mesh mode
 * (mesh/general*.c). Internal to mesh/.
 *
 * The triangulation covers a square given at creation (its four corners are vertices 0..3);
 * every later vertex must lie strictly inside it. Triangles are counter-clockwise vertex
 * triples; edge i of triangle t is the edge opposite vertex i, from v[(i+1)%3] to v[(i+2)%3],
 * and nbr[3t+i] is the triangle across it (QK__CDT_NONE on the square's boundary). An edge
 * may be constrained (a piece of an input segment): it then carries the segment's id in
 * seg[3t+i] on both sides, and no flip removes it. Triangles are never deleted: insertions
 * and flips reuse and append slots, so triangle ids stay valid (a flip changes the triangles'
 * contents, and on_change reports it).
 *
 * Exactness: every decision is an exact predicate on the stored doubles (orientation,
 * in-circle), so the structure stays a valid triangulation for any finite input inside the
 * square; Delaunay ties (four cocircular points) are broken consistently.
 */
#ifndef QK_MESH_CDT_H
#define QK_MESH_CDT_H

#include <stddef.h>
#include <stdint.h>

#include "quadkit/common.h"

#define QK__CDT_NONE UINT32_MAX

/* Where a point lies relative to a triangle (qk__cdt_locate). */
typedef enum qk__cdt_where {
  QK__CDT_IN = 0,   /* strictly inside triangle *tri */
  QK__CDT_EDGE = 1, /* in the relative interior of edge *k of *tri */
  QK__CDT_VERT = 2  /* equal to vertex *k of *tri */
} qk__cdt_where_t;

/* Called for every triangle that an insertion, split or flip creates or changes (the
 * refinement's quality queue listens here). May be NULL. */
typedef void (*qk__cdt_change_fn)(void *user, uint32_t tri);

typedef struct qk__cdt {
  const qk_allocator_t *alloc; /* NULL: libc */
  double *xy;                  /* 2 * nv coordinates */
  uint32_t *vtri;              /* per vertex: one triangle incident to it */
  size_t nv, cap_v;
  uint32_t *v;   /* 3 * nt vertex ids, counter-clockwise */
  uint32_t *nbr; /* 3 * nt: triangle across edge i, or QK__CDT_NONE */
  uint32_t *seg; /* 3 * nt: input segment id of a constrained edge i, else QK__CDT_NONE */
  size_t nt, cap_t;
  size_t cap_tv, cap_tn, cap_ts; /* private: each array's own room (cap_t is the least) */
  uint32_t hint;                 /* a triangle near the last change: default start of walks */
  qk__cdt_change_fn on_change;
  void *user;
  /* Optional, set by a caller that has tested the next point against triangles already
   * (the refinement's cavity search) and cleared after that one insertion: known[n] ==
   * 2 * known_gen + r says the point lies strictly inside slot n's circumcircle (r = 1) or
   * not (r = 0), and the flips reuse that instead of testing again. NULL: no such record. */
  const uint32_t *known;
  uint32_t known_gen;
  /* Optional, set by a caller for one insertion that splits a constrained edge and cleared
   * after it: which sides of the edge the flips restore (bit 0: the side of the triangle
   * the point was located in, bit 1: the other side, 4: neither; 0, the default: both). The
   * general mode leaves the side it never outputs, searches or refines (the outside, holes)
   * as it is: flips never cross the edge, so the other side's triangles come out the same. */
  int legal_sides;
  /* Optional, set by a caller for one insertion of a point strictly inside a triangle
   * (QK__CDT_IN) and cleared after it: a record of the insertion's changes, with which
   * qk__cdt_undo_insert takes the point out again (on_change must be NULL then). Two words,
   * then four a Lawson flip: room for 4 (nv + 1) + 2 words (a flip adds a triangle to the
   * point's star, so there are at most nv). nundo counts the words written. NULL: no
   * record. */
  uint32_t *undo;
  size_t nundo;
  /* With undo, also set by the caller: room for nv + 4 entries, where the flips list the
   * point's star triangles whose edge 0 (the side away from the point) is constrained,
   * nundo_seg of them (the flips meet each triangle of the final star once). */
  uint32_t *undo_seg;
  size_t nundo_seg;
  /* Private to mesh/cdt*.c: the flip stack (cap_v + 8 entries, in the vertex block) and the
   * segment insertion's scratch. */
  uint32_t *stk;
  uint32_t *scr;
  size_t cap_scr;
} qk__cdt_t;

/* Start a triangulation of the square [x0, x0 + side] x [y0, y0 + side] (two triangles,
 * vertices 0..3 its corners counter-clockwise from (x0, y0)), with room reserved for about
 * nv_hint vertices. QK_OK or QK_ERR_NOMEM (then nothing to free). */
qk_status_t qk__cdt_init(qk__cdt_t *c, const qk_allocator_t *alloc, double x0, double y0,
                         double side, size_t nv_hint);

/* Room for nv vertices and nt triangles in all (a caller that can estimate the final size
 * saves the copies of growing by steps). QK_OK or QK_ERR_NOMEM (then nothing changed but
 * the room of arrays already grown). */
qk_status_t qk__cdt_reserve(qk__cdt_t *c, size_t nv, size_t nt);

/* Grow block p of osize bytes to nsize, keeping its first `live` bytes (NULL when out of
 * memory; p is then unchanged). When those are under half of it (room reserved ahead), a
 * new block gets the live part only, where a realloc may copy the whole old block (the
 * mesher's arena does). */
void *qk__cdt_grow_live(const qk_allocator_t *a, void *p, size_t osize, size_t nsize, size_t live);

/* Give back the arrays' spare room (realloc to the current counts; a failed shrink changes
 * nothing). Later insertions grow them again. */
void qk__cdt_shrink(qk__cdt_t *c);

/* Free the arrays; the struct may be reused after qk__cdt_init. */
void qk__cdt_free(qk__cdt_t *c);

/* Find (x, y) by walking from triangle `start` (QK__CDT_NONE: c->hint). Returns the
 * triangle in *tri and, for EDGE and VERT, the edge or vertex slot in *k. The point must
 * lie in the square. */
qk__cdt_where_t qk__cdt_locate(const qk__cdt_t *c, double x, double y, uint32_t start,
                               uint32_t *tri, int *k);

/* qk__cdt_locate for a triangulation without constrained edges (a Delaunay one), starting at
 * vertex u (strictly inside the square): turn around u to the triangle whose angle at u
 * holds (x, y), then a deterministic visibility walk (two orientation tests a step at most,
 * no random choice). A walk longer than the triangle count (never seen; cocircular ties
 * could in principle make one cycle) goes on as qk__cdt_locate. The triangle reported for
 * a point on an edge may be either side of it (as for qk__cdt_locate from another start). */
qk__cdt_where_t qk__cdt_locate_delaunay(const qk__cdt_t *c, double x, double y, uint32_t u,
                                        uint32_t *tri, int *k);

/* Insert the point (x, y) and restore the constrained Delaunay property by flips.
 * *v_out is the new vertex, or the existing vertex at exactly that position (then *existed
 * is set to 1 and nothing changes). A point in the relative interior of a constrained edge
 * splits it: both halves keep the segment id (callers put only points that lie exactly on
 * the segment there; the refinement does, for segment split points). `start` as for
 * locate. QK_OK or QK_ERR_NOMEM (the triangulation is then unchanged); QK_ERR_OUTSIDE (and
 * nothing changes) when the point is not in the closed square or is NaN. A point on the
 * square's boundary is accepted (it splits a boundary edge) but breaks "the four corners
 * are the only boundary vertices": callers keep points strictly inside. */
qk_status_t qk__cdt_insert(qk__cdt_t *c, double x, double y, uint32_t start, uint32_t *v_out,
                           int *existed);

/* qk__cdt_insert for a point the caller has located already: (t, k, w) as qk__cdt_locate (or
 * qk__cdt_walk, when it returns 1) reports for (x, y), the triangulation unchanged since.
 * Saves the second walk and its orientation tests (exact ones for a point on an edge).
 * After a new vertex's insertion (also by qk__cdt_insert) it is in slot 0 of every
 * triangle around it: the split puts it there and each flip keeps it there in both
 * triangles (callers walking its star need not search for it). */
qk_status_t qk__cdt_insert_at(qk__cdt_t *c, double x, double y, uint32_t t, int k,
                              qk__cdt_where_t w, uint32_t *v_out, int *existed);

/* qk__cdt_insert_at for a point (x, y) strictly inside triangle t (QK__CDT_IN), with undo
 * set and known, legal_sides and on_change not: the same changes, without the checks and
 * the choice of legalisation that the general call makes, and one call fewer with
 * qk__gm_insert_in (the refinement's circumcentres: about 40 instructions of the 2,650 that
 * qk_mesh_generate spends a circumcentre on South Africa at extent/256). */
qk_status_t qk__cdt_insert_in_undo(qk__cdt_t *c, double x, double y, uint32_t t, uint32_t *v_out);

/* Take back the last insertion, made with c->undo set (and still set) into triangle t: every
 * triangle slot, link, vertex triangle, count and the hint as they were before it (slots
 * past the counts keep what the insertion wrote there). Nothing else may have changed. */
void qk__cdt_undo_insert(qk__cdt_t *c, uint32_t t);

/* Make the edge from vertex a to vertex b a constrained edge with segment id `seg`,
 * removing the edges it crosses and restoring the constrained Delaunay property.
 * Returns QK_OK; QK_ERR_GEOMETRY when a vertex lies in the relative interior of ab
 * (*block is that vertex, *block_seg QK__CDT_NONE) or a constrained edge crosses ab (*block
 * is one of its vertices, *block_seg its segment id); QK_ERR_NOMEM. On an error the
 * triangulation is a valid constrained Delaunay triangulation of what was inserted before
 * (in fact unchanged: every check and allocation comes before the first change). When ab is
 * already an edge it is marked (QK_OK); if it is already constrained with another id,
 * QK_ERR_GEOMETRY with *block = a and *block_seg that id. a == b: QK_ERR_GEOMETRY, *block
 * = a. Every triangle changed is reported to on_change (also the two sides of ab). */
qk_status_t qk__cdt_insert_segment(qk__cdt_t *c, uint32_t a, uint32_t b, uint32_t seg,
                                   uint32_t *block, uint32_t *block_seg);

/* Mark the existing edge of triangle t opposite slot k (qk__cdt_find_edge's answer) as
 * constrained with id seg, on both its sides, reporting both triangles to on_change: what
 * qk__cdt_insert_segment does for an edge already there, for a caller that found the edge
 * itself. */
void qk__cdt_mark_segment(qk__cdt_t *c, uint32_t t, int k, uint32_t seg);

/* The triangle and edge slot of the edge from vertex a to vertex b (oriented so that the
 * triangle lies on its left), or QK__CDT_NONE when ab is not an edge. */
uint32_t qk__cdt_find_edge(const qk__cdt_t *c, uint32_t a, uint32_t b, int *k);

/* Walk the straight segment from vertex w to the point (x, y) in the square, starting
 * among the triangles around w. Returns 1 when no constrained edge meets the closed segment
 * anywhere but at w: *tri, *k and *where then locate (x, y) as qk__cdt_locate does. Returns
 * 0 when one does (the refinement's visibility test: that constrained edge separates the
 * point from w), at the first such place from w on:
 *  - the segment crosses or ends on the relative interior of a constrained edge, or runs
 *    along one (overlaps it, from w or from a vertex it passed): *where is QK__CDT_EDGE,
 *    *tri the triangle on w's side of it (for an overlap, either side) and *k its slot;
 *  - the segment runs into (or ends at) a vertex other than w that is an end of a
 *    constrained edge: *where is QK__CDT_VERT and *k that vertex's slot in *tri.
 * A vertex with no constrained edge on the way is passed through. */
int qk__cdt_walk(const qk__cdt_t *c, uint32_t w, double x, double y, uint32_t *tri, int *k,
                 qk__cdt_where_t *where);

/* qk__cdt_walk starting the turn around w at triangle `start` (which holds w; QK__CDT_NONE:
 * wherever) instead of an arbitrary one: from a triangle's vertex w towards its
 * circumcentre, when w is opposite the longest edge, the ray runs inside that triangle's
 * angle at w, so the turn ends at once. */
int qk__cdt_walk_from(const qk__cdt_t *c, uint32_t w, uint32_t start, double x, double y,
                      uint32_t *tri, int *k, qk__cdt_where_t *where);

/* The triangles around vertex a: counter-clockwise from vtri[a] until back there, or, at
 * the square's boundary, until the boundary and then clockwise from vtri[a]. Start with
 * qk__cdt_ring_t r = {a, QK__CDT_NONE, QK__CDT_NONE, 1}; each qk__cdt_ring_next(c, &r)
 * returns the next triangle, QK__CDT_NONE at the end:
 *   for (uint32_t t = qk__cdt_ring_next(c, &r); t != QK__CDT_NONE; t = qk__cdt_ring_next(c, &r))
 * The triangulation must not change during the loop. */
typedef struct qk__cdt_ring {
  uint32_t a, first, t;
  int ccw;
} qk__cdt_ring_t;
uint32_t qk__cdt_ring_next(const qk__cdt_t *c, qk__cdt_ring_t *r);

/* Exact sign of (a - p) . (b - p): < 0 when p lies strictly inside the circle with diameter
 * ab, 0 on it, > 0 outside (p encroaches the segment ab when the sign is <= 0). */
int qk__cdt_encroach(const double a[2], const double b[2], const double p[2]);

/* Exact in-circle test: > 0 when d lies strictly inside the circle through a, b, c (a, b, c
 * counter-clockwise), < 0 outside, 0 on it. */
int qk__incircle(const double a[2], const double b[2], const double c[2], const double d[2]);

/* The same, without the floating-point filter (the fallback of callers that filter inline). */
int qk__incircle_exact(const double a[2], const double b[2], const double c[2], const double d[2]);

#endif
