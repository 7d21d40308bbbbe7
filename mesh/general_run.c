/*
 * The general mode (QK_MESH_GENERAL; docs/mesh.md, "The general mode"): quality Delaunay
 * refinement seeded from a graded quadtree. This file runs the steps in order and frees
 * the working state in one place.
 */
#include "mesh/general_mesh.h"

#include <math.h>
#include <string.h>
#include <time.h>

static double now(void) {
  struct timespec ts;
  if (timespec_get(&ts, TIME_UTC) != TIME_UTC) return 0;
  return (double)ts.tv_sec + 1e-9 * (double)ts.tv_nsec;
}

/* The refinement's queues and scratch, freed before the output is allocated: the queue of
 * bad triangles holds every triangle ever queued (about three a triangle), so keeping it
 * to the end raised the peak memory by a quarter. */
static void free_refinement(qk__gm_t *g) {
  const qk_allocator_t *a = g->a;
  qk__free(a, g->bad, g->bad_cap * sizeof *g->bad);
  qk__free(a, g->enc, g->enc_cap * sizeof *g->enc);
  qk__free(a, g->stack, g->stack_cap * sizeof *g->stack);
  qk__free(a, g->dirty, g->dirty_cap * sizeof *g->dirty);
  qk__free(a, g->mark, g->mark_cap * sizeof *g->mark);
  qk__free(a, g->undo, g->undo_cap * sizeof *g->undo);
  g->undo = NULL, g->undo_cap = 0;
  qk__free(a, g->arena, g->arena_cap * sizeof *g->arena);
  qk__free(a, g->pts, g->pts_cap * sizeof *g->pts);
  qk__free(a, g->fbox, (g->P->nv + g->P->ns + 1) * 8 * sizeof *g->fbox);
  g->fbox = NULL;
  g->bad = NULL, g->enc = NULL, g->stack = NULL, g->dirty = NULL, g->arena = NULL, g->pts = NULL;
  g->mark = NULL, g->mark_cap = 0, g->mark_gen = 0;
  g->bad_cap = g->enc_cap = g->stack_cap = g->dirty_cap = g->arena_cap = g->pts_cap = 0;
  g->nbad = g->bad_head = g->nenc = g->ndirty = g->arena_n = g->npts = 0;
}

static void gm_free(qk__gm_t *g) {
  const qk_allocator_t *a = g->a;
  if (g->cdt_live) qk__cdt_free(&g->cdt);
  qk__free(a, g->cv, (g->P->nv + 1) * sizeof *g->cv);
  qk__free(a, g->vsmall, g->P->nv + 1);
  qk__free(a, g->sbud, g->P->ns + 1);
  qk__free(a, g->vi, g->vcap * sizeof *g->vi);
  qk__free(a, g->face, g->fcap * sizeof *g->face);
  qk__free(a, g->faces, g->nface_cap * sizeof *g->faces);
  qk_tree_free(g->tree);
  qk__free(a, g->free_node, g->free_cap);
  qk__free(a, g->pieces, g->pieces_cap * sizeof *g->pieces);
  qk__free(a, g->schg, g->schg ? g->P->ns + 1 : 0);
  free_refinement(g);
}

/*
 * Touching input (qk__gm_t's touch): a working copy of g->P in which every segment that
 * the validation split or merged is replaced by its pieces (none for a repeat), in segment
 * order, each piece keeping its segment's line and marker and naming it (sorig). Its
 * segment arrays are blocks of its own (free_copy), everything else is g->P's. QK_ERR_NOMEM
 * leaves a copy that free_copy still frees.
 */
typedef struct touched {
  qk_poly_t p;
  uint32_t *seg, *sorig;
  unsigned long *sline;
  int32_t *smark;
} touched_t;

/* Segment j of the copy: ab, a piece of P's segment s, with its line and marker. */
static void copy_piece(touched_t *tc, const qk_poly_t *P, size_t j, size_t s, const uint32_t *ab) {
  tc->seg[2 * j] = ab[0], tc->seg[2 * j + 1] = ab[1];
  tc->sorig[j] = (uint32_t)(P->sorig ? P->sorig[s] : s);
  if (tc->sline) tc->sline[j] = P->sline[s];
  if (tc->smark) tc->smark[j] = P->smark[s];
}

static qk_status_t touched_copy(const qk__gm_t *g, touched_t *tc) {
  const qk_poly_t *P = g->P;
  size_t n = g->npieces;
  for (size_t s = 0; s < P->ns; s++) n += !g->schg[s];
  memset(tc, 0, sizeof *tc);
  tc->p = *P;
  tc->p.ns = n;
  tc->seg = qk__realloc(g->a, NULL, 0, (2 * n + 2) * sizeof *tc->seg);
  tc->sorig = qk__realloc(g->a, NULL, 0, (n + 1) * sizeof *tc->sorig);
  if (P->sline) tc->sline = qk__realloc(g->a, NULL, 0, (n + 1) * sizeof *tc->sline);
  if (P->smark) tc->smark = qk__realloc(g->a, NULL, 0, (n + 1) * sizeof *tc->smark);
  tc->p.seg = tc->seg, tc->p.sorig = tc->sorig, tc->p.sline = tc->sline, tc->p.smark = tc->smark;
  if (!tc->seg || !tc->sorig || (P->sline && !tc->sline) || (P->smark && !tc->smark))
    return QK_ERR_NOMEM;
  size_t j = 0, k = 0;
  for (size_t s = 0; s < P->ns; s++) {
    if (!g->schg[s])
      copy_piece(tc, P, j++, s, &P->seg[2 * s]);
    else /* its pieces, in order (none for a repeat) */
      for (; k < g->npieces && g->pieces[3 * k] == s; k++)
        copy_piece(tc, P, j++, s, &g->pieces[3 * k + 1]);
  }
  return QK_OK;
}

static void free_copy(const qk_allocator_t *a, touched_t *tc) {
  size_t n = tc->p.ns;
  qk__free(a, tc->seg, tc->seg ? (2 * n + 2) * sizeof *tc->seg : 0);
  qk__free(a, tc->sorig, tc->sorig ? (n + 1) * sizeof *tc->sorig : 0);
  qk__free(a, tc->sline, tc->sline ? (n + 1) * sizeof *tc->sline : 0);
  qk__free(a, tc->smark, tc->smark ? (n + 1) * sizeof *tc->smark : 0);
}

/* A size bound asking for more triangles than memory could hold is refused up front,
 * counted over the domain (the kept faces' area and the segments' length: a mesh of edges
 * up to h has about two triangles an h-by-h square of area and a few an h along its
 * boundary), not over the input's bounding box, which for a thin diagonal strip is
 * thousands of times the domain (a 2^-10 by 1 strip at 45 degrees with h = 1e-4 was refused
 * as 2e8 triangles; it makes about 0.4 million). Divided by h twice rather than by h^2, so
 * that tiny extents with tiny bounds do not underflow. */
static qk_status_t check_size(qk__gm_t *g) {
  double h = g->opt->max_size;
  if (!(h > 0)) return QK_OK;
  double area = qk__gm_area(g), length = 0;
  const qk_poly_t *P = g->P;
  for (size_t k = 0; k < P->ns; k++) {
    const uint32_t a = P->seg[2 * k], b = P->seg[2 * k + 1];
    length += hypot(P->vx[b] - P->vx[a], P->vy[b] - P->vy[a]);
  }
  /* Triangles an h^2 of area, as measured (a trapezoid of area 0.625 at h = 0.01 and
   * 0.003): 3.3-3.6 where the interior lattice fills the domain (qk__gm_lattice: a bound
   * below 29 degrees, no size function, a grid of cells h / 3 over the bounding box of at
   * most 2^28), 7.1 where the refinement alone does. Counted as two an h^2, a QA helper's
   * trapezoid at h = 1.5e-4 passed as 7.8e7 triangles and made 1.97e8 in 17.5 GB (its grid
   * too large for the lattice). */
  const double gx = (g->bx1 - g->bx0) / (h / 3) + 8, gy = (g->by1 - g->by0) / (h / 3) + 8;
  const int lattice = g->bound_deg < 29 && !g->opt->size_fn && gx * gy <= 0x1p28;
  const double per = lattice ? 3.6 : 7.5;
  double tris = per * (area / h / h) + 4 * (length / h) + 8;
  if (tris > (double)(1 << 27))
    return qk__mesh_fail(g->err, QK_ERR_LIMIT, 0,
                         "max_size %.17g asks for about %.3g triangles over the domain (area "
                         "%.6g, boundary and segments %.6g long; at most 2^27)",
                         h, tris, area, length);
  return QK_OK;
}

/* Every refusal carries a message: an allocation failure says so with the step that ran
 * out ("out of memory while refining the triangulation"), whichever helper it came from. */
static qk_status_t name_failure(const qk__gm_t *g, qk_status_t st) {
  qk_mesh_error_t *err = g->err;
  if (!st || !err) return st;
  if (st == QK_ERR_NOMEM && !strstr(err->message, " while "))
    return qk__mesh_fail(err, st, 0, "out of memory while %s", g->stage);
  if (!err->message[0]) return qk__mesh_fail(err, st, 0, "%s while %s", qk_strerror(st), g->stage);
  return st;
}

static void gm_init(qk__gm_t *g, const qk_poly_t *P, const qk_mesh_options_t *opt, qk_mesh_t *m,
                    qk_mesh_error_t *err) {
  memset(g, 0, sizeof *g);
  g->a = &m->alloc, g->P = P, g->opt = opt, g->err = err, g->stats = &m->stats;
  g->bound_deg = opt->min_angle_deg > 0 ? opt->min_angle_deg : 20;
  /* A triangle is good only with a margin above the bound, so that the floating-point
   * angle test never passes an angle below it. */
  double s = sin((g->bound_deg + 1e-7) * (3.14159265358979323846 / 180));
  g->sin2_bound = s * s;
  g->stage = "checking the input";
}

int qk__gm_test_grade_late = 0;

qk_status_t qk__mesh_general_check(const qk_poly_t *P, const qk_mesh_options_t *opt,
                                   qk_allocator_t *a, qk_mesh_error_t *err) {
  qk__gm_t g;
  memset(&g, 0, sizeof g);
  g.a = a, g.P = P, g.opt = opt, g.err = err;
  g.stage = "checking the input";
  qk_status_t st = name_failure(&g, qk__gm_check_input(&g));
  gm_free(&g);
  return st;
}

qk_status_t qk__mesh_general(const qk_poly_t *P, const qk_mesh_options_t *opt, qk_mesh_t *m,
                             qk_mesh_error_t *err) {
  if (!(opt->min_angle_deg >= 0 && opt->min_angle_deg <= 34))
    return qk__mesh_fail(err, QK_ERR_INVALID, 0,
                         "min_angle_deg %g is not between 0 and 34 (the general mode's range)",
                         opt->min_angle_deg);
  qk__gm_t g;
  gm_init(&g, P, opt, m, err);
  double t0 = now(), t1 = t0, t2 = t0;
  /* Touching input is validated as it is, with its splits and repeats noted; the mesh is
   * then made from the working copy that has them resolved (touched_copy). */
  g.touch = 1;
  qk_status_t st = qk__gm_build(&g);
  touched_t tc = {.seg = NULL};
  const int touched = !st && (g.nsplit || g.nmerged);
  if (touched) {
    const size_t nsplit = g.nsplit, nmerged = g.nmerged;
    st = touched_copy(&g, &tc);
    gm_free(&g);
    gm_init(&g, &tc.p, opt, m, err);
    if (!st) st = qk__gm_build(&g); /* (nothing left to split or merge: no touch) */
    m->stats.split_vertices = nsplit, m->stats.merged_segments = nmerged;
  }
  if (!st) st = check_size(&g);
  if (!st) {
    t1 = now();
    g.stage = "splitting the segments to the size bound";
    st = qk__gm_seed(&g);
    g.stage = "filling the interior with the lattice";
    if (!st) st = qk__gm_lattice(&g);
    t2 = now();
  }
  if (!st) {
    /* The work cap: the refinement inserts fewer points than five a leaf of the graded
     * tree (its corners and centre: about what the seeds and the pre-split to the leaves'
     * sides once placed) and the pre-split points; ten times that means it does not settle.
     * Until the tree is graded (at this cap, general_refine.c) its leaves count none. */
    g.work_cap = qk__gm_test_grade_late && !g.tree ? 0 : qk__gm_work_cap(&g);
    g.stage = "refining the triangulation";
    st = qk__gm_refine(&g);
  }
  if (!st) {
    free_refinement(&g);
    qk__cdt_shrink(&g.cdt); /* room for the output's arrays */
    g.stage = "writing the mesh";
    st = qk__gm_output(&g, m);
  }
  st = name_failure(&g, st);
  if (!st) {
    m->tree = g.tree, g.tree = NULL;
    m->size = 1;
    m->lat = (qk__lattice_t){-g.e, g.X0, g.Y0};
    m->stats.size = 1;
    m->stats.mode = QK_MESH_GENERAL;
    m->stats.lattice_exponent = -g.e;
    m->stats.origin_x = g.X0, m->stats.origin_y = g.Y0;
    m->stats.uniform_triangles = 0;
    m->stats.proven_min_angle_deg = g.bound_deg <= 20.7 ? g.bound_deg : 0;
    m->stats.proven_max_angle_deg = g.bound_deg <= 20.7 ? 180 - 2 * g.bound_deg : 180;
    m->stats.smallest_input_angle_deg = g.smallest_input_angle;
    m->stats.seconds_validate = t1 - t0;
    m->stats.seconds_subdivide = t2 - t1;
    m->stats.seconds_balance = 0;
    m->stats.seconds_triangulate = now() - t2;
  }
  m->refused_crossing = st && g.crossing;
  gm_free(&g);
  if (touched) free_copy(&m->alloc, &tc);
  return st;
}
