/*
 * Cheap invariant checks shared by the mesh-mode fuzz targets (fuzz_mesh_dyadic.c,
 * fuzz_mesh_general.c), with no exact arithmetic library: counts agree with the
 * statistics, indices are in range, no directed edge is used twice, every input vertex
 * comes back bit-identical (dyadic mode, no holes), every triangle is counter-clockwise and every
 * output segment lies on its input segment (orientation decided by a floating-point filter with a
 * proven error bound; the rare uncertain case is not judged), and every writer succeeds. The exact
 * checker (tests/support/mesh_check_general.c, GMP) is the tests' business.
 */
#ifndef QKF_MESH_CHECK_H
#define QKF_MESH_CHECK_H

#include "fuzz/fuzz_common.h"

/* Sign of (b - a) x (c - a) when a filter is sure of it; 2 when it is not. */
static inline int qkfm_orient(const double *a, const double *b, const double *c) {
  double l = (b[0] - a[0]) * (c[1] - a[1]), r = (b[1] - a[1]) * (c[0] - a[0]);
  double det = l - r, bound = 1e-15 * (fabs(l) + fabs(r));
  if (!(bound > 1e-280) || !isfinite(det)) return l == 0 && r == 0 ? 0 : 2;
  if (det > bound) return 1;
  if (-det > bound) return -1;
  return 2;
}

static int qkfm_cmp_u64(const void *a, const void *b) {
  uint64_t x = *(const uint64_t *)a, y = *(const uint64_t *)b;
  return (x > y) - (x < y);
}

/* The input's arrays, through the public accessors. */
typedef struct qkfm_input {
  double *xy;
  uint32_t *seg;
  size_t nv, ns, nh;
} qkfm_input_t;

static inline void qkfm_input_get(const qk_poly_t *poly, qkfm_input_t *in) {
  qk_poly_counts(poly, &in->nv, &in->ns, &in->nh);
  in->xy = malloc((2 * in->nv + 2) * sizeof *in->xy);
  in->seg = malloc((2 * in->ns + 2) * sizeof *in->seg);
  if (!in->xy || !in->seg) abort();
  size_t n;
  QKF_ASSERT(qk_poly_vertices(poly, in->xy, in->nv, &n) == QK_OK && n == in->nv, "vertices");
  QKF_ASSERT(qk_poly_segments(poly, in->seg, in->ns, &n) == QK_OK && n == in->ns, "segments");
}

static inline void qkfm_input_free(qkfm_input_t *in) {
  free(in->xy);
  free(in->seg);
}

static inline void qkfm_check(const qkfm_input_t *in, const qk_mesh_t *m, qk_mesh_mode_t mode) {
  qk_mesh_stats_t st;
  qk_mesh_stats(m, &st);
  size_t nv = 0, nt = 0, no = 0;
  const double *xy = qk_mesh_vertices(m, &nv);
  const uint32_t *tri = qk_mesh_triangles(m, &nt);
  QKF_ASSERT(st.mode == mode, "mode %d, asked %d", (int)st.mode, (int)mode);
  QKF_ASSERT(st.triangles == nt && st.vertices <= nv, "stats disagree with the arrays");
  uint64_t *keys = malloc((3 * nt + 1) * sizeof *keys);
  if (!keys) abort();
  for (size_t t = 0; t < nt; t++) {
    for (int k = 0; k < 3; k++) {
      uint32_t v = tri[3 * t + k];
      QKF_ASSERT(v < nv, "triangle %zu uses vertex %u of %zu", t, v, nv);
      keys[3 * t + k] = (uint64_t)v << 32 | tri[3 * t + (k + 1) % 3];
    }
    int o = qkfm_orient(&xy[2 * tri[3 * t]], &xy[2 * tri[3 * t + 1]], &xy[2 * tri[3 * t + 2]]);
    QKF_ASSERT(o > 0, "triangle %zu is not counter-clockwise (%d)", t, o);
  }
  qsort(keys, 3 * nt, sizeof *keys, qkfm_cmp_u64);
  for (size_t i = 1; i < 3 * nt; i++)
    QKF_ASSERT(keys[i] != keys[i - 1], "directed edge %llu->%llu used twice",
               (unsigned long long)(keys[i] >> 32), (unsigned long long)(keys[i] & 0xffffffffu));
  free(keys);
  /* Input vertices bit-identical (quadratic: the inputs here are small). Only where every
   * input vertex must survive: the dyadic mode meshes its whole lattice square, so without
   * hole points none is dropped; the general mode drops the unbounded face (open chains
   * and isolated vertices outside every ring go with it). */
  for (size_t i = 0; mode == QK_MESH_DYADIC && in->nh == 0 && i < in->nv; i++) {
    int found = 0;
    for (size_t j = 0; j < nv && !found; j++)
      found = !memcmp(&xy[2 * j], &in->xy[2 * i], 2 * sizeof *xy);
    QKF_ASSERT(found, "input vertex %zu (%.17g, %.17g) is not a mesh vertex", i, in->xy[2 * i],
               in->xy[2 * i + 1]);
  }
  /* Output segments on their input segments. */
  QKF_ASSERT(qk_mesh_segments(m, NULL, NULL, NULL, 0, &no) == QK_OK, "qk_mesh_segments");
  uint32_t *ab = malloc((2 * no + 2) * sizeof *ab), *sg = malloc((no + 1) * sizeof *sg);
  if (!ab || !sg) abort();
  size_t no2 = 0;
  QKF_ASSERT(qk_mesh_segments(m, ab, sg, NULL, no, &no2) == QK_OK && no2 == no, "segments");
  for (size_t k = 0; k < no; k++) {
    QKF_ASSERT(ab[2 * k] < nv && ab[2 * k + 1] < nv && sg[k] < in->ns, "output segment %zu", k);
    const double *a = &in->xy[2 * in->seg[2 * sg[k]]], *b = &in->xy[2 * in->seg[2 * sg[k] + 1]];
    for (int e = 0; e < 2; e++)
      QKF_ASSERT(qkfm_orient(a, b, &xy[2 * ab[2 * k + e]]) != 1 &&
                     qkfm_orient(a, b, &xy[2 * ab[2 * k + e]]) != -1,
                 "output segment %zu is off input segment %u", k, sg[k]);
  }
  free(ab);
  free(sg);
  /* The angles the statistics promise. */
  if (nt && st.exempt_angles == 0 && st.proven_min_angle_deg > 0)
    QKF_ASSERT(st.min_angle_deg >= st.proven_min_angle_deg - 1e-6,
               "smallest angle %.9g below the proven %g with no exempt angle", st.min_angle_deg,
               st.proven_min_angle_deg);
  uint64_t bins[180], total = 0;
  QKF_ASSERT(qk_mesh_angle_histogram(m, bins) == QK_OK, "histogram");
  for (int k = 0; k < 180; k++) total += bins[k];
  QKF_ASSERT(total == 3 * (uint64_t)nt, "histogram counts %llu angles for %zu triangles",
             (unsigned long long)total, nt);
  FILE *null = fopen("/dev/null", "w");
  if (!null) abort();
  QKF_ASSERT(qk_mesh_write_node(m, null, 0) == QK_OK, "write_node");
  QKF_ASSERT(qk_mesh_write_ele(m, null, 0) == QK_OK, "write_ele");
  QKF_ASSERT(qk_mesh_write_poly(m, null, 0) == QK_OK, "write_poly");
  QKF_ASSERT(qk_mesh_write_msh(m, null) == QK_OK, "write_msh");
  QKF_ASSERT(qk_mesh_write_vtu(m, null) == QK_OK, "write_vtu");
  QKF_ASSERT(qk_mesh_write_svg(m, null, 0) == QK_OK, "write_svg");
  fclose(null);
}

/*
 * The common driver: byte 0 picks the size bound (0: none, else the input's extent /
 * 2^(b / 2 % 5) for odd b), byte 1 an allocation to fail (0..199: none); the rest is .poly text.
 * Inputs above max_nv vertices, or (max_perimeter > 0) whose perimeter in steps of the finest
 * binary digit of their coordinates exceeds max_perimeter, are only read: that bounds
 * the work per input, as does max_ratio (> 0): inputs whose extent exceeds max_ratio
 * times their shortest segment, or max_ratio^2 steps of their finest binary digit, are
 * only read. Returns 0.
 */
/* The exponent f of the finest binary digit of the coordinates relative to lo: every
 * coordinate is lo + an integer times 2^-f. */
static inline int qkfm_finest_digit(const qkfm_input_t *in, const double *lo) {
  int f = -1100;
  for (size_t i = 0; i < in->nv; i++)
    for (int k = 0; k < 2; k++) {
      double d = in->xy[2 * i + k] - lo[k];
      if (d == 0 || !isfinite(d)) continue;
      int e;
      double m = frexp(fabs(d), &e);
      uint64_t M = (uint64_t)ldexp(m, 53);
      int tz = 0;
      while (!(M & 1)) M >>= 1, tz++;
      if (53 - e - tz > f) f = 53 - e - tz;
    }
  return f;
}

/* The smallest angle, in radians, between two segments sharing an endpoint (pi if none).
 * The general mode grades its mesh into such an angle theta: about (1 / theta) triangles per
 * binary scale between the shortest feature and the extent, which is inherent (the angles
 * away from the apex stay above the bound), so a hair-thin wedge legitimately gives
 * 10^5..10^6 triangles, longer than a fuzzing run allows per input. */
static inline double qkfm_smallest_angle(const qkfm_input_t *in) {
  double best = 3.141592653589793;
  for (size_t s = 0; s < in->ns; s++)
    for (size_t t = s + 1; t < in->ns; t++)
      for (int i = 0; i < 2; i++)
        for (int j = 0; j < 2; j++) {
          uint32_t v = in->seg[2 * s + i];
          if (v != in->seg[2 * t + j]) continue;
          const double *o = &in->xy[2 * v], *a = &in->xy[2 * in->seg[2 * s + 1 - i]],
                       *b = &in->xy[2 * in->seg[2 * t + 1 - j]];
          double ax = a[0] - o[0], ay = a[1] - o[1], bx = b[0] - o[0], by = b[1] - o[1];
          double th = atan2(fabs(ax * by - ay * bx), ax * bx + ay * by);
          if (th < best) best = th;
        }
  return best;
}

static inline double qkfm_lattice_perimeter(const qkfm_input_t *in, const double *lo) {
  int f = qkfm_finest_digit(in, lo);
  double p = 0;
  for (size_t s = 0; s < in->ns; s++) {
    const double *a = &in->xy[2 * in->seg[2 * s]], *b = &in->xy[2 * in->seg[2 * s + 1]];
    p += fmax(fabs(a[0] - b[0]), fabs(a[1] - b[1]));
  }
  return ldexp(p, f < -1000 ? 0 : f);
}

/* mesh/general_run.c's test switch (mesh/general_mesh.h). */
extern int qk__gm_test_grade_late;

static inline int qkfm_run(const uint8_t *data, size_t size, qk_mesh_mode_t mode, size_t max_nv,
                           double max_perimeter, double max_ratio) {
  qkf_bytes_t in = {data, size, 0};
  uint8_t opt = qkf_u8(&in), fail = qkf_u8(&in);
  const uint8_t *text = data + in.at;
  size_t n = size - in.at;
  qkt_alloc_t as;
  qk_allocator_t al = qkt_alloc_make(&as);
  FILE *f = n ? fmemopen((void *)text, n, "rb") : fopen("/dev/null", "rb");
  if (!f) abort();
  qk_poly_t *poly = NULL;
  qk_mesh_error_t err;
  qk_status_t rc = qk_poly_read(f, &al, &poly, &err);
  fclose(f);
  if (rc != QK_OK) {
    QKF_ASSERT(poly == NULL && as.live_blocks == 0, "failed read left something");
    return 0;
  }
  qkfm_input_t pin;
  qkfm_input_get(poly, &pin);
  double lo[2] = {INFINITY, INFINITY}, hi[2] = {-INFINITY, -INFINITY};
  for (size_t i = 0; i < pin.nv; i++)
    for (int k = 0; k < 2; k++)
      lo[k] = fmin(lo[k], pin.xy[2 * i + k]), hi[k] = fmax(hi[k], pin.xy[2 * i + k]);
  /* The extent against the shortest segment: a needle 10^9 long and a few units wide
   * legitimately takes the general mode up to its work cap, longer than a fuzzing run
   * allows per input (tests/test_mesh_real.c meshes features 2^-20 to 2^20 apart). */
  double shortest = INFINITY, ext0 = fmax(hi[0] - lo[0], hi[1] - lo[1]);
  for (size_t s = 0; s < pin.ns; s++) {
    const double *a = &pin.xy[2 * pin.seg[2 * s]], *b = &pin.xy[2 * pin.seg[2 * s + 1]];
    double l = fmax(fabs(a[0] - b[0]), fabs(a[1] - b[1]));
    if (l > 0 && l < shortest) shortest = l;
  }
  /* Likewise the extent in steps of the finest binary digit: an isolated vertex 10^-14 from
   * a segment 10^10 long asks for 2^27 cells before the refusal, which takes seconds. */
  int fd = qkfm_finest_digit(&pin, lo);
  int too_spread = max_ratio > 0 && ((pin.ns && !(ext0 <= max_ratio * shortest)) ||
                                     !(ldexp(ext0, fd < -1000 ? 0 : fd) <= max_ratio * max_ratio));
  /* A hair-thin wedge (see qkfm_smallest_angle): at most ~2^14 triangles per scale. */
  if (max_ratio > 0 && pin.ns && isfinite(shortest)) {
    double th = qkfm_smallest_angle(&pin);
    too_spread |= !(log2(2 + ext0 / shortest) <= 16384 * th);
  }
  if (pin.nv <= max_nv && !too_spread &&
      !(max_perimeter > 0 && !(qkfm_lattice_perimeter(&pin, lo) <= max_perimeter))) {
    qk_mesh_options_t mo;
    qk_mesh_options_init(&mo);
    mo.allocator = &al;
    mo.mode = mode;
    double ext = fmax(hi[0] - lo[0], hi[1] - lo[1]);
    if (opt % 2 && pin.nv && isfinite(ext) && ext > 0) mo.max_size = ldexp(ext, -(opt / 2 % 5));
    qk_mesh_t *mesh = NULL;
    size_t blocks = as.live_blocks;
    qkt_alloc_arm(&as, fail >= 200 ? fail - 199u : 0);
    /* The general mode grades its tree only when the refinement outgrows an input-sized cap,
     * which these small inputs seldom do: opt >= 128 grades it at the refinement's start. */
    qk__gm_test_grade_late = opt >= 128;
    rc = qk_mesh_generate(poly, &mo, &mesh, &err);
    qk__gm_test_grade_late = 0;
    int failed = as.failed;
    qkt_alloc_arm(&as, 0);
    if (getenv("QKF_DEBUG")) fprintf(stderr, "generate: %d %s\n", rc, err.message);
    if (rc != QK_OK) {
      QKF_ASSERT(mesh == NULL, "failed generation left a mesh");
      QKF_ASSERT(as.live_blocks == blocks, "failed generation leaked %zu blocks",
                 as.live_blocks - blocks);
      QKF_ASSERT(rc == QK_ERR_GEOMETRY || rc == QK_ERR_LIMIT || rc == QK_ERR_INVALID ||
                     (rc == QK_ERR_NOMEM && failed),
                 "mesh_generate = %d (%s)", rc, err.message);
      QKF_ASSERT(err.message[0], "mesh_generate failed without a message");
    } else {
      qkfm_check(&pin, mesh, mode);
      qk_mesh_free(mesh);
    }
  }
  qk_poly_free(poly);
  qkfm_input_free(&pin);
  QKF_ASSERT(as.live_blocks == 0, "leaked %zu blocks", as.live_blocks);
  return 0;
}

#endif
