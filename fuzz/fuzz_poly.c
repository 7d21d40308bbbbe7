/*
 * Fuzz target: the `.poly` reader and the whole mesh pipeline behind it.
 *
 * The first input byte chooses the domain option (automatic, or U = 1 .. 64) and
 * whether, and where, an allocation fails; the rest is the `.poly` text. A rejected
 * input must come with a message (and a line for parse errors); an accepted one must
 * give a mesh that an exact checker accepts: vertices on the half-integer lattice of
 * [0,U]^2, counter-clockwise triangles with every angle in [45, 90] degrees, no edge
 * used twice in one direction, every edge without a twin on the domain boundary
 * (conforming: no hanging vertices), total area U^2 (when there are no holes), every
 * input segment a union of mesh edges, and every writer succeeding. A failed
 * allocation must give QK_ERR_NOMEM and leak nothing.
 *
 * Automatic domain sizes above 64 are not meshed (only read and validated with U
 * forced to 64), which keeps each run short.
 */
#include "fuzz/fuzz_common.h"

/* The input's arrays (vertex coordinates, segments), copied out through the public
 * accessors, bound the work and check that the mesh respects the segments. */
typedef struct pf_input {
  double *xy, *holes;
  uint32_t *seg;
  size_t nv, ns, nh;
} pf_input_t;

static void pf_input_get(const qk_poly_t *poly, pf_input_t *in) {
  QKF_ASSERT(qk_poly_vertices(poly, NULL, 0, &in->nv) == QK_OK &&
                 qk_poly_segments(poly, NULL, 0, &in->ns) == QK_OK &&
                 qk_poly_holes(poly, NULL, 0, &in->nh) == QK_OK,
             "poly accessors");
  in->xy = malloc((2 * in->nv + 2) * sizeof *in->xy);
  in->seg = malloc((2 * in->ns + 2) * sizeof *in->seg);
  in->holes = malloc((2 * in->nh + 2) * sizeof *in->holes);
  if (!in->xy || !in->seg || !in->holes) abort();
  size_t n;
  QKF_ASSERT(qk_poly_vertices(poly, in->xy, in->nv, &n) == QK_OK && n == in->nv, "vertices");
  QKF_ASSERT(qk_poly_segments(poly, in->seg, in->ns, &n) == QK_OK && n == in->ns, "segments");
  QKF_ASSERT(qk_poly_holes(poly, in->holes, in->nh, &n) == QK_OK && n == in->nh, "holes");
}

static void pf_input_free(pf_input_t *in) {
  free(in->xy);
  free(in->seg);
  free(in->holes);
}

#define PF_MAX_U 64
/* Large domains (up to 2^28) are meshed when the components are short: the work grows
 * with the perimeter times log U, not with U. */
#define PF_BIG_U_LOG 28
#define PF_BIG_PERIMETER 64.0

static int pf_cmp_u64(const void *a, const void *b) {
  uint64_t x = *(const uint64_t *)a, y = *(const uint64_t *)b;
  return (x > y) - (x < y);
}

static int pf_has(const uint64_t *keys, size_t n, uint64_t k) {
  size_t lo = 0, hi = n;
  while (lo < hi) {
    size_t mid = lo + (hi - lo) / 2;
    if (keys[mid] < k)
      lo = mid + 1;
    else
      hi = mid;
  }
  return lo < n && keys[lo] == k;
}

/* Angle checks in exact integer arithmetic on doubled coordinates (at most 2^29 here,
 * so every product below is at most 2^58 and every sum of two at most 2^59). With the
 * triangle counter-clockwise, the cross product at each corner is the same positive
 * twice-area A, and an angle lies in [45, 90] degrees exactly when 0 <= dot <= A
 * (cos >= 0, and tan >= 1). */
static void pf_check_angles(int64_t p[3][2], size_t t) {
  int64_t area2 =
      (p[1][0] - p[0][0]) * (p[2][1] - p[0][1]) - (p[1][1] - p[0][1]) * (p[2][0] - p[0][0]);
  QKF_ASSERT(area2 > 0, "triangle %zu is not counter-clockwise (twice area %lld)", t,
             (long long)area2);
  for (int i = 0; i < 3; i++) {
    const int64_t *a = p[i], *b = p[(i + 1) % 3], *c = p[(i + 2) % 3];
    int64_t ux = b[0] - a[0], uy = b[1] - a[1], vx = c[0] - a[0], vy = c[1] - a[1];
    int64_t dot = ux * vx + uy * vy;
    QKF_ASSERT(dot >= 0, "triangle %zu has an obtuse angle", t);
    QKF_ASSERT(dot <= area2, "triangle %zu has an angle below 45 degrees", t);
  }
}

static void pf_check_mesh(const pf_input_t *poly, const qk_mesh_t *m) {
  qk_mesh_stats_t st;
  qk_mesh_stats(m, &st);
  const int64_t U2 = 2 * (int64_t)st.size; /* the domain side, in half units */
  size_t nv = 0, nt = 0;
  const double *xy = qk_mesh_vertices(m, &nv);
  const uint32_t *tri = qk_mesh_triangles(m, &nt);
  const uint32_t *comp = qk_mesh_triangle_components(m, NULL);
  QKF_ASSERT(st.triangles == nt && st.vertices == nv, "stats disagree with the arrays");
  if (nt > 0)
    QKF_ASSERT(st.min_angle_deg >= 45 - 1e-9 && st.max_angle_deg <= 90 + 1e-9,
               "stats: angles %g..%g", st.min_angle_deg, st.max_angle_deg);
  int64_t *v2 = malloc((nv + 1) * 2 * sizeof *v2);
  uint64_t *keys = malloc((3 * nt + 1) * sizeof *keys);
  if (!v2 || !keys) abort();
  for (size_t i = 0; i < nv; i++) {
    double x = 2 * xy[2 * i], y = 2 * xy[2 * i + 1];
    QKF_ASSERT(x == floor(x) && y == floor(y) && x >= 0 && y >= 0 && x <= U2 && y <= U2,
               "vertex %zu (%g, %g) is off the half-integer lattice of the domain", i, x / 2,
               y / 2);
    v2[2 * i] = (int64_t)x, v2[2 * i + 1] = (int64_t)y;
  }
  uint64_t area2 = 0; /* in quarter units, times 2 (at most 2^59) */
  for (size_t t = 0; t < nt; t++) {
    int64_t p[3][2];
    for (int k = 0; k < 3; k++) {
      uint32_t v = tri[3 * t + k];
      QKF_ASSERT(v < nv, "triangle %zu uses vertex %u of %zu", t, v, nv);
      p[k][0] = v2[2 * v], p[k][1] = v2[2 * v + 1];
      keys[3 * t + k] = (uint64_t)v << 32 | tri[3 * t + (k + 1) % 3];
    }
    pf_check_angles(p, t);
    area2 += (uint64_t)((p[1][0] - p[0][0]) * (p[2][1] - p[0][1]) -
                        (p[1][1] - p[0][1]) * (p[2][0] - p[0][0]));
    QKF_ASSERT(comp[t] <= st.components, "triangle %zu has component %u of %zu", t, comp[t],
               st.components);
  }
  size_t ne = 3 * nt;
  qsort(keys, ne, sizeof *keys, pf_cmp_u64);
  for (size_t i = 1; i < ne; i++)
    QKF_ASSERT(keys[i] != keys[i - 1], "edge %llu->%llu used twice in one direction",
               (unsigned long long)(keys[i] >> 32), (unsigned long long)(keys[i] & 0xffffffffu));
  if (poly->nh == 0) {
    QKF_ASSERT(area2 == (uint64_t)(2 * U2 * U2), "triangles cover twice-area %llu, domain %lld",
               (unsigned long long)area2, (long long)(2 * U2 * U2));
    /* Conforming: an edge with no twin lies on the domain boundary. */
    for (size_t i = 0; i < ne; i++) {
      uint32_t a = (uint32_t)(keys[i] >> 32), b = (uint32_t)keys[i];
      if (pf_has(keys, ne, (uint64_t)b << 32 | a)) continue;
      int64_t ax = v2[2 * a], ay = v2[2 * a + 1], bx = v2[2 * b], by = v2[2 * b + 1];
      int on = (ax == bx && (ax == 0 || ax == U2)) || (ay == by && (ay == 0 || ay == U2));
      QKF_ASSERT(on,
                 "edge (%g,%g)-(%g,%g) has no twin and is not on the boundary (hanging "
                 "vertex)",
                 ax / 2.0, ay / 2.0, bx / 2.0, by / 2.0);
    }
    /* Every input segment is a chain of mesh edges. */
    for (size_t s = 0; s < poly->ns; s++) {
      uint32_t i0 = poly->seg[2 * s], i1 = poly->seg[2 * s + 1];
      int64_t ax = (int64_t)(2 * poly->xy[2 * i0]), ay = (int64_t)(2 * poly->xy[2 * i0 + 1]);
      int64_t bx = (int64_t)(2 * poly->xy[2 * i1]), by = (int64_t)(2 * poly->xy[2 * i1 + 1]);
      int64_t dx = bx - ax, dy = by - ay, len2 = dx * dx + dy * dy;
      /* Mesh vertices on the segment, by their parameter along it. */
      uint64_t *on = malloc((nv + 1) * sizeof *on);
      if (!on) abort();
      size_t k = 0;
      for (size_t v = 0; v < nv; v++) {
        int64_t px = v2[2 * v] - ax, py = v2[2 * v + 1] - ay;
        if (px * dy - py * dx != 0) continue;
        int64_t dot = px * dx + py * dy;
        if (dot < 0 || dot > len2) continue;
        on[k++] = (uint64_t)dot << 32 | v;
      }
      qsort(on, k, sizeof *on, pf_cmp_u64);
      QKF_ASSERT(k >= 2, "segment %zu has %zu mesh vertices on it", s, k);
      for (size_t j = 1; j < k; j++) {
        uint64_t a = on[j - 1] & 0xffffffffu, b = on[j] & 0xffffffffu;
        QKF_ASSERT(pf_has(keys, ne, a << 32 | b) || pf_has(keys, ne, b << 32 | a),
                   "input segment %zu is not covered by mesh edges", s);
      }
      free(on);
    }
  }
  free(v2);
  free(keys);
  /* Every writer succeeds on a good stream. */
  FILE *null = fopen("/dev/null", "w");
  if (!null) abort();
  QKF_ASSERT(qk_mesh_write_node(m, null, 1) == QK_OK, "write_node");
  QKF_ASSERT(qk_mesh_write_ele(m, null, 1) == QK_OK, "write_ele");
  QKF_ASSERT(qk_mesh_write_msh(m, null) == QK_OK, "write_msh");
  QKF_ASSERT(qk_mesh_write_vtu(m, null) == QK_OK, "write_vtu");
  QKF_ASSERT(qk_mesh_write_svg(m, null, 0) == QK_OK, "write_svg");
  fclose(null);
  qkf_check_tree(qk_mesh_tree(m), "mesh generation");
  QKF_ASSERT(qk_tree_is_balanced(qk_mesh_tree(m)), "the mesh's tree is not balanced");
}

int qkf_poly(const uint8_t *data, size_t size) {
  qkf_bytes_t in = {data, size, 0};
  uint8_t opt = qkf_u8(&in), fail = qkf_u8(&in);
  const uint8_t *text = data + in.at;
  size_t n = size - in.at;
  qkt_alloc_t as;
  qk_allocator_t al = qkt_alloc_make(&as);
  /* fail: 0..199 never; 200..227 in the reader at call 1..28; 228..255 in generation. */
  size_t read_fail = fail >= 200 && fail < 228 ? fail - 199u : 0;
  size_t gen_fail = fail >= 228 ? fail - 227u : 0;

  /* fmemopen cannot open an empty buffer everywhere; an empty file stands in. */
  FILE *f = n ? fmemopen((void *)text, n, "rb") : fopen("/dev/null", "rb");
  if (!f) abort();
  qk_poly_t *poly = (qk_poly_t *)&as;
  qk_mesh_error_t err;
  qkt_alloc_arm(&as, read_fail);
  qk_status_t rc = qk_poly_read(f, &al, &poly, &err);
  fclose(f);
  if (getenv("QKF_DEBUG")) fprintf(stderr, "read: %d line %lu %s\n", rc, err.line, err.message);
  if (rc != QK_OK) {
    QKF_ASSERT(poly == NULL, "failed read left an input");
    QKF_ASSERT(as.live_blocks == 0, "failed read leaked %zu blocks", as.live_blocks);
    QKF_ASSERT(rc == QK_ERR_PARSE || rc == QK_ERR_LIMIT || (rc == QK_ERR_NOMEM && as.failed),
               "poly_read = %d", rc);
    QKF_ASSERT(err.message[0], "poly_read failed without a message");
    if (rc == QK_ERR_PARSE) QKF_ASSERT(err.line > 0 || n == 0, "parse error without a line");
    return 0;
  }
  QKF_ASSERT(!as.failed, "poly_read succeeded although an allocation failed");
  /* A failure armed for a call the reader never made must not carry over. */
  qkt_alloc_arm(&as, 0);
  size_t nv, ns, nh;
  qk_poly_counts(poly, &nv, &ns, &nh);
  pf_input_t pin;
  pf_input_get(poly, &pin);
  QKF_ASSERT(nv == pin.nv && ns == pin.ns && nh == pin.nh, "qk_poly_counts");
  for (size_t i = 0; i < ns; i++)
    QKF_ASSERT(pin.seg[2 * i] < nv && pin.seg[2 * i + 1] < nv,
               "segment %zu refers to a vertex that does not exist", i);

  /* The domain: U = 2^(opt % 7) or automatic when the input is small enough. */
  qk_mesh_options_t mo;
  qk_mesh_options_init(&mo);
  mo.allocator = &al;
  mo.mode = QK_MESH_BOOK; /* the checks below are the book's (half-integer lattice) */
  double big = 0;
  for (size_t i = 0; i < nv; i++)
    big = fmax(big, fmax(fabs(pin.xy[2 * i]), fabs(pin.xy[2 * i + 1])));
  double perimeter = 0;
  for (size_t i = 0; i < ns; i++) {
    uint32_t a = pin.seg[2 * i], b = pin.seg[2 * i + 1];
    perimeter +=
        fmax(fabs(pin.xy[2 * a] - pin.xy[2 * b]), fabs(pin.xy[2 * a + 1] - pin.xy[2 * b + 1]));
  }
  if (opt & 0x40 && perimeter <= PF_BIG_PERIMETER && nh == 0) {
    /* A large domain, from 2^7 to 2^28; the input is moved far from the origin. */
    mo.size = 1ull << (7 + opt % (PF_BIG_U_LOG - 6));
    if (big <= PF_MAX_U && (opt & 0x80)) {
      double shift = (double)(mo.size - 2 * PF_MAX_U);
      for (size_t i = 0; i < nv; i++) pin.xy[2 * i] += shift, pin.xy[2 * i + 1] += shift / 2;
      /* The shifted input replaces the one read (same allocator, disarmed above). */
      qk_poly_t *moved = NULL;
      QKF_ASSERT(qk_poly_from_arrays(pin.xy, nv, pin.seg, ns, pin.holes, nh, &al, &moved, NULL) ==
                     QK_OK,
                 "qk_poly_from_arrays on a read input");
      qk_poly_free(poly);
      poly = moved;
    }
  } else {
    mo.size = opt & 0x80 && big <= PF_MAX_U ? 0 : 1u << (opt % 7);
  }
  qk_mesh_t *mesh = (qk_mesh_t *)&as;
  size_t blocks = as.live_blocks;
  qkt_alloc_arm(&as, gen_fail);
  rc = qk_mesh_generate(poly, &mo, &mesh, &err);
  if (getenv("QKF_DEBUG"))
    fprintf(stderr, "generate (U option %llu): %d line %lu %s\n", (unsigned long long)mo.size, rc,
            err.line, err.message);
  if (rc != QK_OK) {
    QKF_ASSERT(mesh == NULL, "failed generation left a mesh");
    QKF_ASSERT(as.live_blocks == blocks, "failed generation leaked %zu blocks",
               as.live_blocks - blocks);
    QKF_ASSERT(rc == QK_ERR_GEOMETRY || rc == QK_ERR_LIMIT || (rc == QK_ERR_NOMEM && as.failed),
               "mesh_generate = %d (%s)", rc, err.message);
    QKF_ASSERT(err.message[0], "mesh_generate failed without a message");
  } else {
    /* (An optional allocation, such as the tree giving back slack, may fail quietly.) */
    pf_check_mesh(&pin, mesh);
    qk_mesh_free(mesh);
  }
  qk_poly_free(poly);
  pf_input_free(&pin);
  QKF_ASSERT(as.live_blocks == 0, "leaked %zu blocks", as.live_blocks);
  return 0;
}

#ifndef QKF_REPLAY
int LLVMFuzzerTestOneInput(const uint8_t *data, size_t size);
int LLVMFuzzerTestOneInput(const uint8_t *data, size_t size) { return qkf_poly(data, size); }
#endif
