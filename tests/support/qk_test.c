#include "qk_test.h"

#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

void qkt_rng_seed(qkt_rng_t *r, uint64_t seed) { r->s = seed ^ 0x9E3779B97F4A7C15ull; }

uint64_t qkt_rng_next(qkt_rng_t *r) {
  /* splitmix64 */
  uint64_t z = (r->s += 0x9E3779B97F4A7C15ull);
  z = (z ^ (z >> 30)) * 0xBF58476D1CE4E5B9ull;
  z = (z ^ (z >> 27)) * 0x94D049BB133111EBull;
  return z ^ (z >> 31);
}

double qkt_rng_unit(qkt_rng_t *r) { return (double)(qkt_rng_next(r) >> 11) * 0x1.0p-53; }

double qkt_rng_range(qkt_rng_t *r, double a, double b) { return a + (b - a) * qkt_rng_unit(r); }

uint32_t qkt_rng_below(qkt_rng_t *r, uint32_t n) { return (uint32_t)(qkt_rng_unit(r) * n); }

void qkt_points(qkt_rng_t *r, qkt_dist_t d, qk_point_t *out, size_t n) {
  double cx[8], cy[8];
  for (int i = 0; i < 8; i++) cx[i] = qkt_rng_unit(r), cy[i] = qkt_rng_unit(r);
  for (size_t i = 0; i < n; i++) {
    switch (d) {
    case QKT_UNIFORM:
      out[i].x = qkt_rng_unit(r);
      out[i].y = qkt_rng_unit(r);
      break;
    case QKT_CLUSTERED: {
      int c = (int)qkt_rng_below(r, 8);
      double s = 0.002 * (1 + c);
      /* sum of uniforms: a cheap bell shape, clamped into the unit square */
      double dx = (qkt_rng_unit(r) + qkt_rng_unit(r) + qkt_rng_unit(r) - 1.5) * s;
      double dy = (qkt_rng_unit(r) + qkt_rng_unit(r) + qkt_rng_unit(r) - 1.5) * s;
      out[i].x = fmin(fmax(cx[c] + dx, 0), 1);
      out[i].y = fmin(fmax(cy[c] + dy, 0), 1);
      break;
    }
    case QKT_DUPLICATES: {
      int c = (int)qkt_rng_below(r, 5);
      out[i].x = cx[c];
      out[i].y = cy[c];
      break;
    }
    case QKT_GRID_EDGES:
      out[i].x = qkt_rng_below(r, 17) / 16.0;
      out[i].y = qkt_rng_below(r, 17) / 16.0;
      break;
    }
  }
}

qk_tree_options_t qkt_unit_options(uint32_t capacity, const qk_allocator_t *a) {
  qk_tree_options_t o;
  qk_tree_options_init(&o);
  o.capacity = capacity;
  o.has_root = 1;
  o.root = (qk_square_t){0, 0, 1};
  o.allocator = a;
  return o;
}

void qkt_filters_from_env(void) {
  const char *only = getenv("QKT_TEST_FILTER"), *skip = getenv("QKT_SKIP_FILTER");
  if (only && *only) cmocka_set_test_filter(only);
  if (skip && *skip) cmocka_set_skip_filter(skip);
}

uint64_t qkt_seed(uint64_t def) {
  const char *s = getenv("QK_SEED");
  uint64_t seed = s ? strtoull(s, NULL, 0) : def;
  print_message("seed %llu (set QK_SEED to change)\n", (unsigned long long)seed);
  return seed;
}

static int cmp_id(const void *a, const void *b) {
  qk_id_t x = *(const qk_id_t *)a, y = *(const qk_id_t *)b;
  return (x > y) - (x < y);
}

static QKT_SERIAL qk_visit_t shape_visit(const qk_tree_t *t, qk_node_t v, void *ud) {
  qkt_shape_t *s = ud;
  qk_node_info_t info;
  assert_int_equal(qk_tree_node_info(t, v, &info), QK_OK);
  uint64_t h = s->hash * 1000003u ^ (info.depth * 31u + (unsigned)info.is_leaf * 7u + info.count);
  if (info.is_leaf) {
    const qk_id_t *ids;
    size_t n;
    assert_int_equal(qk_tree_leaf_points(t, v, NULL, NULL, &ids, &n), QK_OK);
    qk_id_t *c = malloc((n + 1) * sizeof *c);
    assert_non_null(c);
    memcpy(c, ids, n * sizeof *c);
    qsort(c, n, sizeof *c, cmp_id);
    for (size_t i = 0; i < n; i++) h = h * 1000003u ^ c[i];
    free(c);
  }
  s->hash = h;
  s->nodes++;
  return QK_VISIT_CONTINUE;
}

QKT_SERIAL qkt_shape_t qkt_tree_shape(const qk_tree_t *t) {
  qkt_shape_t s = {1469598103934665603ull, 0};
  qk_tree_visit(t, qk_tree_root(t), shape_visit, &s);
  return s;
}

QKT_SERIAL void qkt_assert_same_tree(const qk_tree_t *a, const qk_tree_t *b) {
  qk_tree_stats_t sa, sb;
  qk_tree_stats(a, &sa);
  qk_tree_stats(b, &sb);
  assert_int_equal(sa.nodes, sb.nodes);
  assert_int_equal(sa.leaves, sb.leaves);
  qk_node_t stack[4 * 64];
  int sp = 0;
  stack[sp++] = qk_tree_root(a);
  assert_int_equal(qk_tree_root(a), qk_tree_root(b));
  while (sp > 0) {
    qk_node_t v = stack[--sp];
    qk_node_info_t ia, ib;
    assert_int_equal(qk_tree_node_info(a, v, &ia), QK_OK);
    assert_int_equal(qk_tree_node_info(b, v, &ib), QK_OK);
    assert_true(ia.is_leaf == ib.is_leaf && ia.count == ib.count && ia.depth == ib.depth &&
                ia.parent == ib.parent && ia.square.x == ib.square.x &&
                ia.square.y == ib.square.y && ia.square.side == ib.square.side);
    assert_memory_equal(ia.children, ib.children, sizeof ia.children);
    if (!ia.is_leaf) {
      for (int q = 3; q >= 0; q--) stack[sp++] = ia.children[q];
      continue;
    }
    const double *xa, *ya, *xb, *yb;
    const qk_id_t *da, *db;
    size_t ca, cb;
    qk_tree_leaf_points(a, v, &xa, &ya, &da, &ca);
    qk_tree_leaf_points(b, v, &xb, &yb, &db, &cb);
    assert_int_equal(ca, cb);
    if (ca) {
      assert_memory_equal(da, db, ca * sizeof *da);
      assert_memory_equal(xa, xb, ca * sizeof *xa);
      assert_memory_equal(ya, yb, ca * sizeof *ya);
    }
  }
}

mcr_mesh_t qkt_mesh_view(const qk_mesh_t *m) {
  mcr_mesh_t v = {0};
  v.xy = qk_mesh_vertices(m, &v.nv);
  v.tri = qk_mesh_triangles(m, &v.nt);
  assert_int_equal(qk_mesh_segments(m, NULL, NULL, NULL, 0, &v.no), QK_OK);
  uint32_t *ab = malloc((2 * v.no + 2) * sizeof *ab), *sg = malloc((v.no + 1) * sizeof *sg);
  assert_true(ab && sg);
  assert_int_equal(qk_mesh_segments(m, ab, sg, NULL, v.no, &v.no), QK_OK);
  v.oseg = ab, v.oseg_of = sg;
  return v;
}

void qkt_mesh_view_free(mcr_mesh_t *v) {
  free((void *)v->oseg);
  free((void *)v->oseg_of);
  v->oseg = v->oseg_of = NULL;
}

FILE *qkt_open_shared(const char *name, char *path, size_t cap) {
  const char *dir = getenv("QK_SHARED_DIR");
  snprintf(path, cap, "%s/data/%s", dir ? dir : "../shared", name);
  return fopen(path, "rb");
}
