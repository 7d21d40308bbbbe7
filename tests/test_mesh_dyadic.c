/*
 * Test plan for the dyadic-lattice mode of mesh/ (real coordinates), every mesh mapped
 * back to its lattice exactly (X = (x - x0) 2^f, checked to be an integer or half-integer)
 * and passed through the independent exact checker of tests/support/mesh_check.c:
 *  - random valid inputs from the polygon generator, scaled by 2^-k and moved to dyadic
 *    offsets (negative, large, tiny): the mesh passes the checker, every input vertex
 *    comes back bit-identical, every output segment lies exactly on its input segment
 *    and the output segments of each input segment chain from one end to the other;
 *  - features 2^-20 wide at 10^6 from the origin, and the rejection (with the vertex
 *    named) of inputs that need more than 2^30 lattice steps or more than a double's bits;
 *  - size control: with max_size H every edge is at most H (exactly, in lattice units);
 *    a size function gives a mesh between those of its extreme constant sizes;
 *  - boundary markers and regional attributes from a .poly file: vertex markers, output
 *    segments and their markers, per-triangle attributes; the writers (.node column,
 *    .poly, gmsh marker groups, VTU data);
 *  - the automatic choice (integer input: the book's mode; real input: dyadic) and the
 *    options' errors;
 *  - allocation failure at every N: QK_ERR_NOMEM, nothing leaked.
 */
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "mesh_check.h"
#include "mesh_check_real.h"
#include "polygen.h"
#include "qk_test.h"

/* An input as arrays, kept for checking. */
typedef struct arr {
  double *xy, *holes;
  uint32_t *seg;
  size_t nv, ns, nh;
} arr_t;

/* Map x to the lattice of mesh statistics s, failing unless it lands on a multiple of
 * 1/2 (mesh vertices) exactly. */
static double to_lat(double x, double origin, int f) {
  double X = ldexp(x - origin, f);
  assert_true(ldexp(X, 1) == floor(ldexp(X, 1)));
  /* The inverse map gives x back: the subtraction was exact. */
  assert_true(ldexp(X, -f) + origin == x);
  return X;
}

/* Check a dyadic mesh of input `in` (made with options o): lattice exactness, the exact
 * checker, bit-identical input vertices, output segments exactly on the input segments
 * and chaining along each. Returns the triangle count. */
static size_t check_dyadic(const arr_t *in, const qk_mesh_t *m, const char *what) {
  qk_mesh_stats_t s;
  qk_mesh_stats(m, &s);
  assert_int_equal(s.mode, QK_MESH_DYADIC);
  size_t nv, nt;
  const double *xy = qk_mesh_vertices(m, &nv);
  const uint32_t *tri = qk_mesh_triangles(m, &nt);
  double *lxy = malloc((2 * nv + 2) * sizeof *lxy), *lin = malloc((2 * in->nv + 2) * sizeof *lin);
  double *lh = malloc((2 * in->nh + 2) * sizeof *lh);
  assert_true(lxy && lin && lh);
  for (size_t i = 0; i < nv; i++) {
    lxy[2 * i] = to_lat(xy[2 * i], s.origin_x, s.lattice_exponent);
    lxy[2 * i + 1] = to_lat(xy[2 * i + 1], s.origin_y, s.lattice_exponent);
  }
  for (size_t i = 0; i < in->nv; i++) {
    lin[2 * i] = to_lat(in->xy[2 * i], s.origin_x, s.lattice_exponent);
    lin[2 * i + 1] = to_lat(in->xy[2 * i + 1], s.origin_y, s.lattice_exponent);
  }
  for (size_t i = 0; i < in->nh; i++) {
    lh[2 * i] = ldexp(in->holes[2 * i] - s.origin_x, s.lattice_exponent);
    lh[2 * i + 1] = ldexp(in->holes[2 * i + 1] - s.origin_y, s.lattice_exponent);
  }
  mc_input_t mi = {lin, in->nv, in->seg, in->ns, lh, in->nh, s.size};
  mc_mesh_t mm = {lxy, nv, tri, qk_mesh_triangle_components(m, NULL), nt};
  char msg[512];
  if (mc_check(&mi, &mm, msg, sizeof msg)) fail_msg("%s: checker: %s", what, msg);
  /* Input vertices bit-identical: each equals some output vertex exactly. */
  for (size_t i = 0; i < in->nv; i++) {
    int found = 0;
    for (size_t j = 0; j < nv && !found; j++)
      found = xy[2 * j] == in->xy[2 * i] && xy[2 * j + 1] == in->xy[2 * i + 1];
    if (!found)
      fail_msg("%s: input vertex %zu (%.17g, %.17g) not in the output", what, i, in->xy[2 * i],
               in->xy[2 * i + 1]);
  }
  /* Output segments: exactly on their input segment (integer cross products of doubled
   * lattice coordinates), and their lattice lengths add up to the segment's. */
  size_t no;
  assert_int_equal(qk_mesh_segments(m, NULL, NULL, NULL, 0, &no), QK_OK);
  uint32_t *ab = malloc((2 * no + 2) * sizeof *ab), *sg = malloc((no + 1) * sizeof *sg);
  double *len = calloc(in->ns + 1, sizeof *len);
  assert_true(ab && sg && len);
  size_t no2;
  assert_int_equal(qk_mesh_segments(m, ab, sg, NULL, no, &no2), QK_OK);
  assert_int_equal(no, no2);
  for (size_t k = 0; k < no; k++) {
    uint32_t s0 = sg[k];
    assert_true(s0 < in->ns);
    const double *A = &lin[2 * in->seg[2 * s0]], *B = &lin[2 * in->seg[2 * s0 + 1]];
    for (int e = 0; e < 2; e++) {
      const double *P = &lxy[2 * ab[2 * k + e]];
      int64_t ux = (int64_t)(2 * (B[0] - A[0])), uy = (int64_t)(2 * (B[1] - A[1]));
      int64_t px = (int64_t)(2 * (P[0] - A[0])), py = (int64_t)(2 * (P[1] - A[1]));
      if (ux * py - uy * px != 0)
        fail_msg("%s: output segment %zu leaves input segment %u", what, k, s0);
      int64_t dot = ux * px + uy * py;
      assert_true(dot >= 0 && dot <= ux * ux + uy * uy);
    }
    const double *P = &lxy[2 * ab[2 * k]], *Q = &lxy[2 * ab[2 * k + 1]];
    len[s0] += fmax(fabs(P[0] - Q[0]), fabs(P[1] - Q[1]));
  }
  if (in->nh == 0)
    for (size_t s0 = 0; s0 < in->ns; s0++) {
      const double *A = &lin[2 * in->seg[2 * s0]], *B = &lin[2 * in->seg[2 * s0 + 1]];
      if (len[s0] != fmax(fabs(A[0] - B[0]), fabs(A[1] - B[1])))
        fail_msg("%s: output segments cover %g of input segment %zu's %g lattice steps", what,
                 len[s0], s0, fmax(fabs(A[0] - B[0]), fabs(A[1] - B[1])));
    }
  /* The rational checker, on the doubles as given (no lattice); its quadratic segment
   * scan is kept to the smaller meshes so the test stays fast. */
  if (mcr_available() && in->nh == 0 && nt <= 1500) {
    mcr_input_t ri = {in->xy, in->nv, in->seg, in->ns};
    mcr_mesh_t rm = {xy, nv, tri, nt, ab, sg, no};
    if (mcr_check(&ri, &rm, msg, sizeof msg)) fail_msg("%s: rational checker: %s", what, msg);
  }
  free(ab), free(sg), free(len), free(lxy), free(lin), free(lh);
  return nt;
}

static qk_mesh_t *generate(const arr_t *in, const qk_mesh_options_t *o, const char *what) {
  qk_poly_t *p = NULL;
  qk_mesh_error_t err;
  if (qk_poly_from_arrays(in->xy, in->nv, in->seg, in->ns, in->holes, in->nh, NULL, &p, &err))
    fail_msg("%s: from_arrays: %s", what, err.message);
  qk_mesh_t *m = NULL;
  qk_status_t st = qk_mesh_generate(p, o, &m, &err);
  if (st != QK_OK) fail_msg("%s: %s: %s", what, qk_strerror(st), err.message);
  qk_poly_free(p);
  QKT_CHECK_TREE(qk_mesh_tree(m));
  assert_true(qk_tree_is_balanced(qk_mesh_tree(m)));
  return m;
}

static void test_mesh_dyadic_random(void **state) {
  (void)state;
  uint64_t seed = qkt_seed(4242);
  qkt_rng_t r;
  qkt_rng_seed(&r, seed);
  static const double offsets[] = {0, -1234.5625, 1e6, -3.0517578125e-05, 0x1p30 + 0.5};
  for (int round = 0; round < 100; round++) {
    uint64_t U = 8u << (round % 5);
    pg_input_t pg;
    pg_generate(&r, U, 1 + qkt_rng_below(&r, 6), &pg);
    int k = (int)qkt_rng_below(&r, 12);
    /* Offsets on the input's own grid (2^-k), so that the lattice stays 2^-k: a finer
     * offset would multiply the boundary's lattice steps. */
    double ox = ldexp(floor(ldexp(offsets[round % 5], k)), -k);
    double oy = ldexp(floor(ldexp(offsets[(round + 2) % 5], k)), -k);
    arr_t in = {malloc((2 * pg.nv + 2) * sizeof(double)), NULL, pg.seg, pg.nv, pg.ns, 0};
    assert_non_null(in.xy);
    for (size_t i = 0; i < pg.nv; i++)
      in.xy[2 * i] = ldexp(pg.xy[2 * i], -k) + ox,
                in.xy[2 * i + 1] = ldexp(pg.xy[2 * i + 1], -k) + oy;
    qk_mesh_options_t o;
    qk_mesh_options_init(&o);
    o.mode = QK_MESH_DYADIC;
    char what[96];
    snprintf(what, sizeof what, "seed %llu round %d (U %llu, 2^-%d, offset %g)",
             (unsigned long long)seed, round, (unsigned long long)U, k, ox);
    qk_mesh_t *m = generate(&in, &o, what);
    check_dyadic(&in, m, what);
    qk_mesh_free(m);
    free(in.xy);
    pg_free(&pg);
  }
}

/* The rational checker itself: it must see this run (GMP present) or report a skip, and
 * it must reject a mesh with a vertex moved off its segment by one ulp. */
static void test_mesh_dyadic_rational_checker(void **state) {
  (void)state;
  if (!mcr_available()) skip();
  double xy[8] = {1e6 + 0.25, 3.5, 1e6 + 2.25, 3.5, 1e6 + 2.25, 5.5, 1e6 + 0.25, 5.5};
  uint32_t seg[8] = {0, 1, 1, 2, 2, 3, 3, 0};
  arr_t in = {xy, NULL, seg, 4, 4, 0};
  qk_mesh_options_t o;
  qk_mesh_options_init(&o);
  o.max_size = 0.5;
  qk_mesh_t *m = generate(&in, &o, "rational");
  check_dyadic(&in, m, "rational");
  size_t nv, nt, no;
  const double *v = qk_mesh_vertices(m, &nv);
  const uint32_t *t = qk_mesh_triangles(m, &nt);
  assert_int_equal(qk_mesh_segments(m, NULL, NULL, NULL, 0, &no), QK_OK);
  uint32_t *ab = malloc(2 * no * sizeof *ab), *sg = malloc(no * sizeof *sg);
  double *moved = malloc(2 * nv * sizeof *moved);
  assert_true(ab && sg && moved);
  assert_int_equal(qk_mesh_segments(m, ab, sg, NULL, no, &no), QK_OK);
  memcpy(moved, v, 2 * nv * sizeof *moved);
  /* An output-segment vertex strictly inside segment 0 (y = 3.5), nudged by one ulp. */
  for (size_t k = 0; k < no; k++)
    if (sg[k] == 0 && moved[2 * ab[2 * k] + 1] == 3.5 && moved[2 * ab[2 * k]] > xy[0] &&
        moved[2 * ab[2 * k]] < xy[2]) {
      moved[2 * ab[2 * k] + 1] = nextafter(3.5, 4);
      break;
    }
  mcr_input_t ri = {xy, 4, seg, 4};
  mcr_mesh_t rm = {moved, nv, t, nt, ab, sg, no};
  char msg[256];
  assert_int_equal(mcr_check(&ri, &rm, msg, sizeof msg), 1);
  free(ab), free(sg), free(moved);
  qk_mesh_free(m);
}

/* Two squares of side 2^-20 a million units from the origin, 2^-16 apart: a lattice of
 * 2^-20, meshed exactly. A unit square beside them would need 2^22 lattice steps of
 * boundary (the book's subdivision reaches unit size all along the segments): refused
 * as a limit. 10^6 next to 2^-20: more than 2^30 steps, rejected naming the vertex. And
 * 0.1 (needing 2^-56 steps) next to 1: rejected. */
static void test_mesh_dyadic_scales(void **state) {
  (void)state;
  double e = 0x1p-20, X = 1e6, d = 0x1p-16;
  double xy[16] = {X,     X, X + e,     X, X + e,     X + e, X,     X + e,
                   X + d, X, X + d + e, X, X + d + e, X + e, X + d, X + e};
  uint32_t seg[16] = {0, 1, 1, 2, 2, 3, 3, 0, 4, 5, 5, 6, 6, 7, 7, 4};
  arr_t in = {xy, NULL, seg, 8, 8, 0};
  qk_mesh_options_t o;
  qk_mesh_options_init(&o);
  qk_mesh_t *m = generate(&in, &o, "tiny squares at 1e6");
  qk_mesh_stats_t s;
  qk_mesh_stats(m, &s);
  assert_int_equal(s.mode, QK_MESH_DYADIC); /* chosen automatically: real coordinates */
  assert_int_equal(s.lattice_exponent, 20);
  check_dyadic(&in, m, "tiny squares at 1e6");
  qk_mesh_free(m);

  /* Integer input too wide for the unit lattice (2^k apart, k up to 500) is meshed on the
   * coarsest lattice holding it, spacing 2^k (f = -k): with its proven angles, where the
   * dyadic mode refused it ("no exact placement exists", which was not so) and
   * QK_MESH_AUTO sent it to the general mode (20 degrees). */
  const int ks[3] = {40, 249, 500};
  for (int i = 0; i < 3; i++) {
    const double u = ldexp(1, ks[i]);
    double pent[10] = {u, u, 2 * u, u, 3 * u, 2 * u, 2 * u, 3 * u, u, 2 * u};
    uint32_t ps[10] = {0, 1, 1, 2, 2, 3, 3, 4, 4, 0};
    arr_t pin = {pent, NULL, ps, 5, 5, 0};
    m = generate(&pin, &o, "a pentagon on the lattice 2^k");
    qk_mesh_stats(m, &s);
    assert_int_equal(s.lattice_exponent, -ks[i]);
    assert_true(s.min_angle_deg >= 45 && s.max_angle_deg <= 90);
    check_dyadic(&pin, m, "a pentagon on the lattice 2^k");
    qk_mesh_free(m);
  }
  /* Where the unit lattice fits, it stays (meshes made before are unchanged): even
   * coordinates with a size bound (the dyadic mode). */
  double even[8] = {0, 0, 64, 0, 64, 64, 0, 64};
  arr_t ein = {even, NULL, seg, 4, 4, 0};
  o.max_size = 40;
  m = generate(&ein, &o, "even square");
  qk_mesh_stats(m, &s);
  assert_int_equal(s.mode, QK_MESH_DYADIC);
  assert_int_equal(s.lattice_exponent, 0);
  check_dyadic(&ein, m, "even square");
  qk_mesh_free(m);
  o.max_size = 0;

  qk_poly_t *p;
  qk_mesh_error_t err;
  /* QK_MESH_AUTO hands what the dyadic mode refuses to the general mode; insisting on the
   * dyadic mode keeps its refusals tested. */
  o.mode = QK_MESH_DYADIC;
  double big[8] = {X + e, X, X + 16 + e, X, X + 16 + e, X + 16, X + e, X + 16};
  assert_int_equal(qk_poly_from_arrays(big, 4, seg, 4, NULL, 0, NULL, &p, NULL), QK_OK);
  assert_int_equal(qk_mesh_generate(p, &o, &m, &err), QK_ERR_LIMIT);
  assert_non_null(strstr(err.message, "lattice steps"));
  qk_poly_free(p);
  xy[8] = xy[14] = -1e6;
  xy[10] = xy[12] = -1e6 + e;
  assert_int_equal(qk_poly_from_arrays(xy, 8, seg, 8, NULL, 0, NULL, &p, NULL), QK_OK);
  assert_int_equal(qk_mesh_generate(p, &o, &m, &err), QK_ERR_GEOMETRY);
  assert_non_null(strstr(err.message, "2^30"));
  assert_non_null(strstr(err.message, "no exact placement"));
  qk_poly_free(p);

  double t[8] = {0, 0, 1, 0, 1, 0.1, 0, 0.1};
  assert_int_equal(qk_poly_from_arrays(t, 4, seg, 4, NULL, 0, NULL, &p, NULL), QK_OK);
  assert_int_equal(qk_mesh_generate(p, &o, &m, &err), QK_ERR_GEOMETRY);
  assert_non_null(strstr(err.message, "vertex 2"));
  assert_null(m);
  qk_poly_free(p);

  /* Any angle is still the book's restriction: (0,0)-(1,0)-(0.5,0.75) is refused. */
  double tri[6] = {0, 0, 1, 0, 0.5, 0.75};
  uint32_t ts[6] = {0, 1, 1, 2, 2, 0};
  assert_int_equal(qk_poly_from_arrays(tri, 3, ts, 3, NULL, 0, NULL, &p, NULL), QK_OK);
  assert_int_equal(qk_mesh_generate(p, &o, &m, &err), QK_ERR_GEOMETRY);
  assert_non_null(strstr(err.message, "45"));
  qk_poly_free(p);
}

static double graded(double x, double y, void *u) {
  (void)y;
  return *(double *)u + 0.25 * fabs(x);
}

static void test_mesh_dyadic_size(void **state) {
  (void)state;
  double xy[12] = {-1.5, -1, 2.25, -1, 2.25, 0.5, 0.75, 0.5, 0.75, 2, -1.5, 2};
  uint32_t seg[12] = {0, 1, 1, 2, 2, 3, 3, 4, 4, 5, 5, 0};
  arr_t in = {xy, NULL, seg, 6, 6, 0};
  size_t counts[3];
  static const double H[3] = {1.0, 0.3, 0.07};
  for (int k = 0; k < 3; k++) {
    qk_mesh_options_t o;
    qk_mesh_options_init(&o);
    o.max_size = H[k];
    qk_mesh_t *m = generate(&in, &o, "max_size");
    counts[k] = check_dyadic(&in, m, "max_size");
    size_t nv, nt;
    const double *v = qk_mesh_vertices(m, &nv);
    const uint32_t *t = qk_mesh_triangles(m, &nt);
    qk_mesh_stats_t s;
    qk_mesh_stats(m, &s);
    /* Exactly: squared edge length in lattice units (integers) against (H 2^f)^2. */
    double Hl = ldexp(H[k], s.lattice_exponent);
    for (size_t i = 0; i < nt; i++)
      for (int j = 0; j < 3; j++) {
        const double *a = &v[2 * t[3 * i + j]], *b = &v[2 * t[3 * i + (j + 1) % 3]];
        double dx = ldexp(a[0] - b[0], s.lattice_exponent + 1);
        double dy = ldexp(a[1] - b[1], s.lattice_exponent + 1);
        long double L2 = (long double)dx * dx + (long double)dy * dy; /* 4 |e|^2 exactly */
        if (L2 > 4.0L * (long double)Hl * Hl)
          fail_msg("H %g: edge of length %g", H[k],
                   sqrt((double)L2) / 2 / ldexp(1, s.lattice_exponent));
      }
    qk_mesh_free(m);
  }
  assert_true(counts[0] < counts[1] && counts[1] < counts[2]);
  /* A graded size function, 0.36 to 0.92 here: between the constant sizes 1 and 0.3, and
   * met (every edge within the function at its triangle's centroid). It stays above the
   * lattice's unit square (side 0.25, diagonal 0.354): one asking for less is meshed in the
   * general mode (test_mesh_general_mode_size_fn_below_unit); with 0.07 here it was
   * returned as the lattice allowed, 0.35 where 0.07 was asked. */
  double h0 = 0.36;
  qk_mesh_options_t o;
  qk_mesh_options_init(&o);
  o.size_fn = graded;
  o.size_user = &h0;
  qk_mesh_t *m = generate(&in, &o, "size_fn");
  qk_mesh_stats_t ms;
  qk_mesh_stats(m, &ms);
  assert_int_equal(ms.mode, QK_MESH_DYADIC);
  assert_int_equal(ms.lattice_exponent, 2);
  size_t n = check_dyadic(&in, m, "size_fn");
  if (!(counts[0] < n && n < counts[1]))
    fail_msg("%zu triangles, not between %zu (size 1) and %zu (size 0.3)", n, counts[0], counts[1]);
  {
    size_t nv, nt;
    const double *v = qk_mesh_vertices(m, &nv);
    const uint32_t *t = qk_mesh_triangles(m, &nt);
    for (size_t i = 0; i < nt; i++) {
      const double *a = &v[2 * t[3 * i]], *b = &v[2 * t[3 * i + 1]], *c = &v[2 * t[3 * i + 2]];
      double l = fmax(hypot(a[0] - b[0], a[1] - b[1]),
                      fmax(hypot(b[0] - c[0], b[1] - c[1]), hypot(c[0] - a[0], c[1] - a[1])));
      double want = graded((a[0] + b[0] + c[0]) / 3, 0, &h0);
      if (l > want) fail_msg("triangle %zu: longest edge %g, size function %g", i, l, want);
    }
  }
  qk_mesh_free(m);
  /* The book's mode cannot go below its unit square's diagonal. */
  qk_poly_t *p;
  qk_mesh_error_t err;
  double ixy[8] = {0, 0, 2, 0, 2, 2, 0, 2};
  assert_int_equal(qk_poly_from_arrays(ixy, 4, seg, 0, NULL, 0, NULL, &p, NULL), QK_OK);
  o.size_fn = NULL, o.mode = QK_MESH_BOOK, o.max_size = 1;
  assert_int_equal(qk_mesh_generate(p, &o, &m, &err), QK_ERR_INVALID);
  o.max_size = -1, o.mode = QK_MESH_AUTO;
  assert_int_equal(qk_mesh_generate(p, &o, &m, &err), QK_ERR_INVALID);
  o.max_size = 0, o.mode = QK_MESH_DYADIC, o.size = 4;
  assert_int_equal(qk_mesh_generate(p, &o, &m, &err), QK_ERR_INVALID);
  qk_poly_free(p);
}

/* Two nested squares with markers 5 (outer) and 9 (inner), vertex 0 marked 3, regional
 * attributes 1.5 (between) and 2.5 (inside). */
static const char marked_poly[] = "8 2 0 1\n"
                                  "0 -1 -1 3\n1 3 -1 0\n2 3 3 0\n3 -1 3 0\n"
                                  "4 0.5 0.5 0\n5 1.5 0.5 0\n6 1.5 1.5 0\n7 0.5 1.5 0\n"
                                  "8 1\n0 0 1 5\n1 1 2 5\n2 2 3 5\n3 3 0 5\n"
                                  "4 4 5 9\n5 5 6 9\n6 6 7 9\n7 7 4 9\n"
                                  "0\n2\n0 0 0 1.5\n1 1 1 2.5\n";

static qk_poly_t *read_text(const char *text, const qk_allocator_t *a, qk_status_t *st) {
  FILE *f = tmpfile();
  assert_non_null(f);
  fputs(text, f);
  rewind(f);
  qk_poly_t *p = NULL;
  qk_mesh_error_t err;
  *st = qk_poly_read(f, a, &p, &err);
  fclose(f);
  return p;
}

/* A stream whose contents close_read() returns as a NUL-terminated string. */
static char *close_read(FILE *f) {
  long n = ftell(f);
  assert_true(n >= 0);
  char *buf = malloc((size_t)n + 1);
  assert_non_null(buf);
  rewind(f);
  assert_int_equal(fread(buf, 1, (size_t)n, f), (size_t)n);
  buf[n] = '\0';
  fclose(f);
  return buf;
}

static void test_mesh_dyadic_markers(void **state) {
  (void)state;
  qk_status_t st;
  qk_poly_t *p = read_text(marked_poly, NULL, &st);
  assert_int_equal(st, QK_OK);
  qk_mesh_t *m;
  qk_mesh_error_t err;
  assert_int_equal(qk_mesh_generate(p, NULL, &m, &err), QK_OK);
  size_t nv, nt, na, nm;
  const double *v = qk_mesh_vertices(m, &nv);
  const uint32_t *t = qk_mesh_triangles(m, &nt);
  const int32_t *mk = qk_mesh_vertex_markers(m, &nm);
  const double *at = qk_mesh_triangle_attributes(m, &na);
  const uint32_t *comp = qk_mesh_triangle_components(m, NULL);
  assert_int_equal(nm, nv);
  assert_int_equal(na, nt);
  for (size_t i = 0; i < nv; i++) {
    double x = v[2 * i], y = v[2 * i + 1];
    int outer = (x == -1 || x == 3 || y == -1 || y == 3);
    int inner = (x >= 0.5 && x <= 1.5 && y >= 0.5 && y <= 1.5) &&
                (x == 0.5 || x == 1.5 || y == 0.5 || y == 1.5);
    int32_t want = (x == -1 && y == -1) ? 3 : outer ? 5 : inner ? 9 : 0;
    if (mk[i] != want) fail_msg("vertex (%g, %g): marker %d, want %d", x, y, mk[i], want);
  }
  for (size_t i = 0; i < nt; i++) {
    double want = comp[i] == 2 ? 2.5 : comp[i] == 1 ? 1.5 : 0;
    if (at[i] != want) fail_msg("triangle %zu (component %u): attribute %g", i, comp[i], at[i]);
  }
  (void)t;
  size_t no;
  assert_int_equal(qk_mesh_segments(m, NULL, NULL, NULL, 0, &no), QK_OK);
  uint32_t *ab = malloc(2 * no * sizeof *ab), *sg = malloc(no * sizeof *sg);
  int32_t *mm = malloc(no * sizeof *mm);
  assert_true(ab && sg && mm);
  assert_int_equal(qk_mesh_segments(m, ab, sg, mm, no, &no), QK_OK);
  for (size_t k = 0; k < no; k++) assert_int_equal(mm[k], sg[k] < 4 ? 5 : 9);
  free(ab), free(sg), free(mm);

  /* Writers: the .node marker column, the .poly, gmsh's groups, VTU's data. */
  char *buf;
  FILE *f = tmpfile();
  assert_int_equal(qk_mesh_write_node(m, f, 0), QK_OK);
  buf = close_read(f);
  char head[64];
  snprintf(head, sizeof head, "%zu 2 0 1\n", nv);
  assert_memory_equal(buf, head, strlen(head));
  free(buf);
  f = tmpfile();
  assert_int_equal(qk_mesh_write_poly(m, f, 0), QK_OK);
  buf = close_read(f);
  snprintf(head, sizeof head, "0 2 0 1\n%zu 1\n", no);
  assert_non_null(strstr(buf, head));
  free(buf);
  f = tmpfile();
  assert_int_equal(qk_mesh_write_msh(m, f), QK_OK);
  buf = close_read(f);
  assert_non_null(strstr(buf, "1 1 \"marker_5\""));
  assert_non_null(strstr(buf, "1 2 \"marker_9\""));
  snprintf(head, sizeof head, "$Elements\n4 %zu 1 %zu\n", nt + no, nt + no);
  assert_non_null(strstr(buf, head));
  free(buf);
  f = tmpfile();
  assert_int_equal(qk_mesh_write_vtu(m, f), QK_OK);
  buf = close_read(f);
  assert_non_null(strstr(buf, "Name=\"marker\""));
  assert_non_null(strstr(buf, "Name=\"region\""));
  assert_non_null(strstr(buf, "Name=\"attribute\""));
  free(buf);
  f = tmpfile();
  assert_int_equal(qk_mesh_write_ele(m, f, 0), QK_OK);
  buf = close_read(f);
  snprintf(head, sizeof head, "%zu 3 2\n", nt);
  assert_memory_equal(buf, head, strlen(head));
  free(buf);
  uint64_t bins[180], total = 0;
  assert_int_equal(qk_mesh_angle_histogram(m, bins), QK_OK);
  for (int k = 0; k < 180; k++) {
    total += bins[k];
    if (bins[k]) assert_true(k >= 44 && k <= 90);
  }
  assert_int_equal(total, 3 * nt);
  qk_mesh_free(m);
  qk_poly_free(p);

  /* Markers and regions through the arrays API. */
  double xy[8] = {0.5, 0.5, 1, 0.5, 1, 1, 0.5, 1};
  uint32_t seg[8] = {0, 1, 1, 2, 2, 3, 3, 0};
  int32_t sm[4] = {1, 2, 3, 4}, vm[4] = {0, 0, 0, 0};
  double reg[3] = {0.75, 0.75, 4};
  assert_int_equal(qk_poly_from_arrays(xy, 4, seg, 4, NULL, 0, NULL, &p, NULL), QK_OK);
  assert_int_equal(qk_poly_set_markers(p, vm, sm, &err), QK_OK);
  assert_int_equal(qk_poly_set_regions(p, reg, 1, &err), QK_OK);
  double bad[3] = {NAN, 0, 0};
  assert_int_equal(qk_poly_set_regions(p, bad, 1, &err), QK_ERR_INVALID);
  assert_non_null(strstr(err.message, "regional attribute 0"));
  assert_int_equal(qk_mesh_generate(p, NULL, &m, &err), QK_OK);
  at = qk_mesh_triangle_attributes(m, &na);
  comp = qk_mesh_triangle_components(m, NULL);
  for (size_t i = 0; i < na; i++) assert_true(at[i] == (comp[i] ? 4 : 0));
  qk_mesh_free(m);
  qk_poly_free(p);
}

/* The automatic choice: integers give the book's mode, exactly as before. */
static void test_mesh_dyadic_auto(void **state) {
  (void)state;
  double xy[8] = {1, 1, 3, 1, 3, 3, 1, 3};
  uint32_t seg[8] = {0, 1, 1, 2, 2, 3, 3, 0};
  qk_poly_t *p;
  qk_mesh_t *m;
  qk_mesh_error_t err;
  assert_int_equal(qk_poly_from_arrays(xy, 4, seg, 4, NULL, 0, NULL, &p, &err), QK_OK);
  assert_int_equal(qk_mesh_generate(p, NULL, &m, &err), QK_OK);
  qk_mesh_stats_t s;
  qk_mesh_stats(m, &s);
  assert_int_equal(s.mode, QK_MESH_BOOK);
  assert_int_equal(s.size, 4);
  assert_true(s.proven_min_angle_deg == 45 && s.proven_max_angle_deg == 90);
  qk_mesh_free(m);
  qk_poly_free(p);
  /* Arrays API errors name the item. */
  uint32_t badseg[2] = {0, 7};
  assert_int_equal(qk_poly_from_arrays(xy, 4, badseg, 1, NULL, 0, NULL, &p, &err), QK_ERR_INVALID);
  assert_non_null(strstr(err.message, "segment 0: endpoint 7"));
  double nan_xy[2] = {NAN, 0};
  assert_int_equal(qk_poly_from_arrays(nan_xy, 1, NULL, 0, NULL, 0, NULL, &p, &err),
                   QK_ERR_INVALID);
  assert_non_null(strstr(err.message, "vertex 0"));
}

static void test_mesh_dyadic_alloc_failure(void **state) {
  (void)state;
  size_t fail_at;
  for (fail_at = 1;; fail_at++) {
    qkt_alloc_t as;
    qk_allocator_t a = qkt_alloc_make(&as);
    qk_status_t st;
    qk_poly_t *p = read_text(marked_poly, &a, &st);
    if (st != QK_OK) {
      qk_poly_free(p);
      continue;
    }
    as.fail_at = as.calls + fail_at;
    qk_mesh_options_t o;
    qk_mesh_options_init(&o);
    o.allocator = &a;
    o.max_size = 0.5;
    qk_mesh_t *m = (qk_mesh_t *)&as;
    qk_mesh_error_t err;
    st = qk_mesh_generate(p, &o, &m, &err);
    if (st == QK_OK) {
      qk_mesh_free(m);
      qk_poly_free(p);
      assert_int_equal(as.live_bytes, 0);
      break;
    }
    assert_int_equal(st, QK_ERR_NOMEM);
    assert_null(m);
    qk_poly_free(p);
    assert_int_equal(as.live_bytes, 0);
  }
  assert_true(fail_at > 10);
  /* Attaching markers and regions: a failed call leaves the input as it was. */
  double xy[8] = {0, 0, 1, 0, 1, 1, 0, 1}, reg[3] = {0.5, 0.5, 2};
  uint32_t seg[8] = {0, 1, 1, 2, 2, 3, 3, 0};
  int32_t vm[4] = {1, 2, 3, 4}, sm[4] = {5, 6, 7, 8};
  for (fail_at = 1; fail_at < 8; fail_at++) {
    qkt_alloc_t as;
    qk_allocator_t a = qkt_alloc_make(&as);
    qk_poly_t *p;
    assert_int_equal(qk_poly_from_arrays(xy, 4, seg, 4, NULL, 0, &a, &p, NULL), QK_OK);
    as.fail_at = as.calls + fail_at;
    qk_mesh_error_t err;
    qk_status_t s1 = qk_poly_set_markers(p, vm, sm, &err);
    qk_status_t s2 = qk_poly_set_regions(p, reg, 1, &err);
    assert_true(s1 == QK_OK || s1 == QK_ERR_NOMEM);
    assert_true(s2 == QK_OK || s2 == QK_ERR_NOMEM);
    qk_mesh_t *m;
    assert_int_equal(qk_mesh_generate(p, NULL, &m, &err), QK_OK);
    size_t n;
    const int32_t *mk = qk_mesh_vertex_markers(m, &n);
    int any = 0;
    for (size_t i = 0; i < n; i++) any |= mk[i] != 0;
    assert_int_equal(any, s1 == QK_OK); /* all markers attached, or none */
    assert_true((qk_mesh_triangle_attributes(m, NULL) != NULL) == (s2 == QK_OK));
    qk_mesh_free(m);
    qk_poly_free(p);
    assert_int_equal(as.live_bytes, 0);
  }
}

/* The book's mode with a size bound (at least its unit diagonal): still the book's
 * checker, every edge at most H. */
static void test_mesh_dyadic_book_size(void **state) {
  (void)state;
  double xy[8] = {3, 3, 5, 3, 5, 5, 3, 5};
  uint32_t seg[8] = {0, 1, 1, 2, 2, 3, 3, 0};
  qk_poly_t *p;
  qk_mesh_t *m;
  qk_mesh_error_t err;
  assert_int_equal(qk_poly_from_arrays(xy, 4, seg, 4, NULL, 0, NULL, &p, &err), QK_OK);
  qk_mesh_options_t o;
  qk_mesh_options_init(&o);
  o.mode = QK_MESH_BOOK;
  o.size = 16;
  o.max_size = 3;
  assert_int_equal(qk_mesh_generate(p, &o, &m, &err), QK_OK);
  mc_input_t in = {xy, 4, seg, 4, NULL, 0, 16};
  mc_mesh_t mm;
  mm.xy = qk_mesh_vertices(m, &mm.nv);
  mm.tri = qk_mesh_triangles(m, &mm.nt);
  mm.comp = qk_mesh_triangle_components(m, NULL);
  char msg[512];
  if (mc_check(&in, &mm, msg, sizeof msg)) fail_msg("book + max_size: %s", msg);
  for (size_t i = 0; i < mm.nt; i++)
    for (int j = 0; j < 3; j++) {
      const double *a = &mm.xy[2 * mm.tri[3 * i + j]], *b = &mm.xy[2 * mm.tri[3 * i + (j + 1) % 3]];
      assert_true((a[0] - b[0]) * (a[0] - b[0]) + (a[1] - b[1]) * (a[1] - b[1]) <= 9);
    }
  qk_mesh_free(m);
  qk_poly_free(p);
}

int main(void) {
  const struct CMUnitTest tests[] = {
      cmocka_unit_test(test_mesh_dyadic_random),
      cmocka_unit_test(test_mesh_dyadic_rational_checker),
      cmocka_unit_test(test_mesh_dyadic_scales),
      cmocka_unit_test(test_mesh_dyadic_size),
      cmocka_unit_test(test_mesh_dyadic_markers),
      cmocka_unit_test(test_mesh_dyadic_auto),
      cmocka_unit_test(test_mesh_dyadic_alloc_failure),
      cmocka_unit_test(test_mesh_dyadic_book_size),
  };
  return cmocka_run_group_tests(tests, NULL, NULL);
}
