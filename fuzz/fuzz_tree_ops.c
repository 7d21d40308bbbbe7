/*
 * Fuzz target: a random sequence of operations on one quadtree, every result checked
 * against a brute-force model of the point set.
 *
 * The input's first bytes choose the tree (capacity, depth cap, root square: dyadic,
 * non-dyadic, far from the origin, or so small it cannot be halved); the rest is a list
 * of operations: insert, remove, find the leaf of a location, split a leaf, balance,
 * range / radius / kNN / locate queries, a collider over the points, a rebuild from
 * scratch, and "fail the k-th allocation of the next change". After every change
 * qk_tree_check() must pass and the stored points must equal the model; after a failed
 * allocation the tree must be as it was (balance: still valid) and nothing may leak.
 */
#include "fuzz/fuzz_common.h"

#define TO_MAX_IDS 600
#define TO_MAX_OPS 400

typedef struct to_state {
  qkf_bytes_t in;
  qkt_alloc_t alloc_state;
  qk_allocator_t alloc;
  qk_tree_options_t opt;
  qk_tree_t *tree;
  int dyadic;   /* root corner and side are dyadic: squares are exact */
  int refined;  /* split beyond the capacity rule */
  size_t n_ids; /* ids handed out */
  double x[TO_MAX_IDS], y[TO_MAX_IDS];
  unsigned char alive[TO_MAX_IDS];
  qk_id_t freed[TO_MAX_IDS]; /* removed ids, reused last-in first-out by inserts */
  size_t n_freed;
} to_state_t;

static size_t to_live(const to_state_t *s) {
  size_t n = 0;
  for (size_t i = 0; i < s->n_ids; i++) n += s->alive[i];
  return n;
}

/* A location: on the grid of sixteenths of the root (edges and corners), anywhere in
 * it, a copy of a stored point, a neighbour of one in the last bit, just outside, or
 * raw bits (NaN, infinities, huge values). */
static qk_point_t to_point(to_state_t *s) {
  const qk_square_t r = s->opt.root;
  qk_point_t p;
  uint8_t kind = qkf_u8(&s->in) % 8;
  switch (kind) {
  case 0:
    p.x = r.x + r.side * (qkf_u8(&s->in) % 17) / 16.0;
    p.y = r.y + r.side * (qkf_u8(&s->in) % 17) / 16.0;
    return p;
  case 2:
  case 5:
    if (s->n_ids) {
      size_t i = qkf_u8(&s->in) % s->n_ids;
      p.x = s->x[i];
      p.y = s->y[i];
      if (kind == 5) {
        uint8_t d = qkf_u8(&s->in);
        if (d & 1) p.x = nextafter(p.x, d & 2 ? INFINITY : -INFINITY);
        if (d & 4) p.y = nextafter(p.y, d & 8 ? INFINITY : -INFINITY);
      }
      return p;
    }
    break;
  case 3:
    p.x = qkf_raw_double(&s->in);
    p.y = qkf_raw_double(&s->in);
    return p;
  case 4:
    p.x = nextafter(r.x, -INFINITY);
    p.y = r.y + r.side;
    if (qkf_u8(&s->in) & 1) p.x = r.x + r.side, p.y = nextafter(r.y + r.side, INFINITY);
    return p;
  default:
    break;
  }
  uint32_t a = qkf_u32(&s->in);
  p.x = r.x + r.side * ((a >> 16) / 65535.0);
  p.y = r.y + r.side * ((a & 0xffff) / 65535.0);
  return p;
}

static int to_inside(const to_state_t *s, qk_point_t p) {
  const qk_square_t r = s->opt.root;
  return p.x >= r.x && p.x <= r.x + r.side && p.y >= r.y && p.y <= r.y + r.side;
}

static int to_finite(qk_point_t p) { return isfinite(p.x) && isfinite(p.y); }

/* The tree against the model: invariants, counts, and every live point where it
 * belongs (its coordinates, its leaf, and that leaf found again by location). */
static void to_check(to_state_t *s, const char *after) {
  qkf_check_tree(s->tree, after);
  qk_tree_stats_t st;
  qk_tree_stats(s->tree, &st);
  QKF_ASSERT(st.points == to_live(s), "after %s: %zu points stored, model has %zu", after,
             st.points, to_live(s));
  for (size_t i = 0; i < s->n_ids; i++) {
    qk_point_t p;
    qk_status_t rc = qk_tree_point(s->tree, (qk_id_t)i, &p);
    if (!s->alive[i]) {
      QKF_ASSERT(rc == QK_ERR_NOT_FOUND, "after %s: removed id %zu still found", after, i);
      continue;
    }
    QKF_ASSERT(rc == QK_OK && p.x == s->x[i] && p.y == s->y[i], "after %s: id %zu wrong", after, i);
    qk_node_t a, b;
    QKF_ASSERT(qk_tree_leaf_of(s->tree, (qk_id_t)i, &a) == QK_OK, "leaf_of %zu", i);
    QKF_ASSERT(qk_tree_find_leaf(s->tree, p, &b) == QK_OK && a == b,
               "after %s: id %zu is in leaf %u but its location is in leaf %u", after, i, a, b);
  }
  qk_point_t none;
  QKF_ASSERT(qk_tree_point(s->tree, (qk_id_t)s->n_ids, &none) == QK_ERR_NOT_FOUND,
             "an id never handed out was found");
}

/* find_leaf against a descent that uses only the public node facts and the tie rules. */
static void to_find_leaf(to_state_t *s, qk_point_t p) {
  qk_node_t leaf = QK_NONE;
  qk_status_t rc = qk_tree_find_leaf(s->tree, p, &leaf);
  qk_status_t want = !to_finite(p) ? QK_ERR_NONFINITE : !to_inside(s, p) ? QK_ERR_OUTSIDE : QK_OK;
  QKF_ASSERT(rc == want, "find_leaf(%.17g, %.17g) = %d, want %d", p.x, p.y, rc, want);
  if (rc != QK_OK) return;
  qk_node_t v = qk_tree_root(s->tree);
  for (;;) {
    qk_node_info_t info;
    QKF_ASSERT(qk_tree_node_info(s->tree, v, &info) == QK_OK, "node_info(%u)", v);
    if (info.is_leaf) break;
    double half = info.square.side * 0.5;
    int east = p.x > info.square.x + half, north = p.y > info.square.y + half;
    v = info.children[east ? (north ? QK_NE : QK_SE) : (north ? QK_NW : QK_SW)];
  }
  QKF_ASSERT(v == leaf, "find_leaf(%.17g, %.17g) = %u, descent gives %u", p.x, p.y, leaf, v);
  const double *lx, *ly;
  const qk_id_t *lid;
  size_t ln;
  QKF_ASSERT(qk_tree_leaf_points(s->tree, leaf, &lx, &ly, &lid, &ln) == QK_OK, "leaf_points");
  for (size_t i = 0; i < ln; i++)
    QKF_ASSERT(lid[i] < s->n_ids && s->alive[lid[i]] && lx[i] == s->x[lid[i]] &&
                   ly[i] == s->y[lid[i]],
               "leaf %u holds a wrong point", leaf);
  qk_location_t loc;
  QKF_ASSERT(qk_query_locate(s->tree, p, &loc) == QK_OK && loc.leaf == leaf,
             "locate disagrees with find_leaf");
  qk_node_t batch = 0;
  QKF_ASSERT(qk_query_locate_batch(s->tree, &p, 1, &batch) == QK_OK && batch == leaf,
             "locate_batch disagrees with find_leaf");
}

static void to_insert(to_state_t *s, qk_point_t p, int armed) {
  qk_tree_stats_t before;
  qk_tree_stats(s->tree, &before);
  qk_id_t id = QK_NONE;
  qk_status_t rc = qk_tree_insert(s->tree, p, &id);
  qk_status_t want = !to_finite(p) ? QK_ERR_NONFINITE : !to_inside(s, p) ? QK_ERR_OUTSIDE : QK_OK;
  /* A failed allocation must fail the call cleanly, unless it was optional (a shrink). */
  if (armed && want == QK_OK && s->alloc_state.failed && rc == QK_ERR_NOMEM) want = rc;
  QKF_ASSERT(rc == want, "insert(%.17g, %.17g) = %d, want %d", p.x, p.y, rc, want);
  if (rc == QK_OK) {
    size_t want_id = s->n_freed ? s->freed[--s->n_freed] : s->n_ids++;
    QKF_ASSERT(id == want_id, "insert gave id %u, want %zu", id, want_id);
    s->x[id] = p.x;
    s->y[id] = p.y;
    s->alive[id] = 1;
  } else {
    qk_tree_stats_t after;
    qk_tree_stats(s->tree, &after);
    QKF_ASSERT(after.nodes == before.nodes && after.leaves == before.leaves,
               "failed insert changed the tree");
  }
  to_check(s, "insert");
}

static void to_remove(to_state_t *s, qk_id_t id, int armed) {
  qk_tree_stats_t before;
  qk_tree_stats(s->tree, &before);
  qk_status_t rc = qk_tree_remove(s->tree, id);
  int known = id < s->n_ids && s->alive[id];
  qk_status_t want = known ? QK_OK : QK_ERR_NOT_FOUND;
  if (armed && known && s->alloc_state.failed && rc == QK_ERR_NOMEM) want = rc;
  QKF_ASSERT(rc == want, "remove(%u) = %d, want %d", id, rc, want);
  if (rc == QK_OK) {
    s->alive[id] = 0;
    s->freed[s->n_freed++] = id;
  } else {
    qk_tree_stats_t after;
    qk_tree_stats(s->tree, &after);
    QKF_ASSERT(after.nodes == before.nodes && after.leaves == before.leaves,
               "failed remove changed the tree");
  }
  to_check(s, "remove");
}

static void to_move(to_state_t *s, qk_id_t id, qk_point_t p, int armed) {
  qk_tree_stats_t before;
  qk_tree_stats(s->tree, &before);
  qk_status_t rc = qk_tree_move(s->tree, id, p);
  int known = id < s->n_ids && s->alive[id];
  qk_status_t want = !to_finite(p)      ? QK_ERR_NONFINITE
                     : !to_inside(s, p) ? QK_ERR_OUTSIDE
                     : known            ? QK_OK
                                        : QK_ERR_NOT_FOUND;
  if (armed && want == QK_OK && s->alloc_state.failed && rc == QK_ERR_NOMEM) want = rc;
  QKF_ASSERT(rc == want, "move(%u, %.17g, %.17g) = %d, want %d", id, p.x, p.y, rc, want);
  if (rc == QK_OK) { /* the id stays */
    s->x[id] = p.x;
    s->y[id] = p.y;
  } else {
    qk_tree_stats_t after;
    qk_tree_stats(s->tree, &after);
    QKF_ASSERT(after.nodes == before.nodes && after.leaves == before.leaves,
               "failed move changed the tree");
  }
  to_check(s, "move");
}

/* Pick a leaf by the next input byte. */
static qk_node_t to_pick_leaf(to_state_t *s) {
  qk_node_t leaves[64];
  size_t n = 0;
  qk_tree_leaves(s->tree, leaves, 64, &n);
  if (n > 64) n = 64;
  return leaves[qkf_u8(&s->in) % n];
}

static void to_split(to_state_t *s, int armed) {
  qk_node_t leaf = to_pick_leaf(s);
  qk_node_info_t info;
  qk_tree_node_info(s->tree, leaf, &info);
  qk_tree_stats_t before, after;
  qk_tree_stats(s->tree, &before);
  qk_status_t rc = qk_tree_split_leaf(s->tree, leaf);
  double half = s->dyadic ? info.square.side * 0.5 : 0; /* exact only for dyadic roots */
  double xm = info.square.x + half, ym = info.square.y + half;
  int splittable = info.depth < before.max_depth && half > 0 && xm > info.square.x &&
                   xm < info.square.x + info.square.side && ym > info.square.y &&
                   ym < info.square.y + info.square.side;
  qk_tree_stats(s->tree, &after);
  if (rc == QK_OK) {
    QKF_ASSERT(info.depth < before.max_depth, "split a leaf at the depth cap");
    QKF_ASSERT(after.nodes == before.nodes + 4, "split added %zu nodes",
               after.nodes - before.nodes);
    s->refined = 1;
  } else {
    QKF_ASSERT(rc == QK_ERR_LIMIT || (armed && rc == QK_ERR_NOMEM && s->alloc_state.failed),
               "split_leaf = %d", rc);
    QKF_ASSERT(rc != QK_ERR_LIMIT || !s->dyadic || !splittable, "split refused a splittable leaf");
    QKF_ASSERT(after.nodes == before.nodes, "failed split changed the tree");
  }
  to_check(s, "split_leaf");
}

/* Brute-force balance: every two leaves sharing an edge of positive length differ by at
 * most one in depth. Only meaningful where squares are exact (dyadic roots). */
static int to_balanced_brute(to_state_t *s) {
  size_t n = 0;
  qk_tree_leaves(s->tree, NULL, 0, &n);
  if (n > 400) return -1;
  qk_node_t *lv = malloc(n * sizeof *lv);
  qk_node_info_t *in = malloc(n * sizeof *in);
  if (!lv || !in) abort();
  qk_tree_leaves(s->tree, lv, n, &n);
  for (size_t i = 0; i < n; i++) qk_tree_node_info(s->tree, lv[i], &in[i]);
  int ok = 1;
  for (size_t i = 0; i < n && ok; i++)
    for (size_t j = 0; j < n && ok; j++) {
      const qk_square_t a = in[i].square, b = in[j].square;
      if (in[i].depth + 1 >= in[j].depth) continue; /* only i much larger than j matters */
      int vert =
          (a.x + a.side == b.x || b.x + b.side == a.x) && b.y < a.y + a.side && a.y < b.y + b.side;
      int horz =
          (a.y + a.side == b.y || b.y + b.side == a.y) && b.x < a.x + a.side && a.x < b.x + b.side;
      if (vert || horz) ok = 0;
    }
  free(lv);
  free(in);
  return ok;
}

static void to_balance(to_state_t *s, int armed) {
  qk_status_t rc = qk_tree_balance(s->tree);
  s->refined = 1;
  QKF_ASSERT(rc == QK_OK || (armed && rc == QK_ERR_NOMEM && s->alloc_state.failed), "balance = %d",
             rc);
  to_check(s, "balance");
  int is = qk_tree_is_balanced(s->tree);
  if (rc == QK_OK && s->dyadic && s->opt.root.side >= 0x1p-900)
    QKF_ASSERT(is, "balance returned OK but the tree is not balanced");
  if (s->dyadic) {
    int brute = to_balanced_brute(s);
    QKF_ASSERT(brute < 0 || brute == is, "is_balanced = %d, brute force says %d", is, brute);
  }
}

/* ---- queries against brute force ------------------------------------------------------ */

static int to_cmp_id(const void *a, const void *b) {
  qk_id_t x = *(const qk_id_t *)a, y = *(const qk_id_t *)b;
  return (x > y) - (x < y);
}

typedef struct to_nb {
  long double d2;
  qk_id_t id;
} to_nb_t;

static int to_cmp_nb(const void *a, const void *b) {
  const to_nb_t *x = a, *y = b;
  if (x->d2 != y->d2) return x->d2 < y->d2 ? -1 : 1;
  return (x->id > y->id) - (x->id < y->id);
}

static void to_range(to_state_t *s) {
  qk_point_t a = to_point(s), b = to_point(s);
  qk_box_t box = {fmin(a.x, b.x), fmin(a.y, b.y), fmax(a.x, b.x), fmax(a.y, b.y)};
  uint8_t how = qkf_u8(&s->in);
  if (how & 1) box.xmin = -INFINITY;
  if (how & 2) box.ymax = INFINITY;
  if (how & 4) { /* inverted: holds nothing */
    double t = box.xmin;
    box.xmin = box.xmax, box.xmax = t;
  }
  static qk_id_t got[TO_MAX_IDS], want[TO_MAX_IDS];
  size_t nw = 0, ng = 0;
  int nan = isnan(box.xmin) || isnan(box.xmax) || isnan(box.ymin) || isnan(box.ymax);
  for (size_t i = 0; i < s->n_ids; i++)
    if (s->alive[i] && s->x[i] >= box.xmin && s->x[i] <= box.xmax && s->y[i] >= box.ymin &&
        s->y[i] <= box.ymax)
      want[nw++] = (qk_id_t)i;
  size_t cap = how & 8 ? nw / 2 : TO_MAX_IDS;
  qk_status_t rc = qk_query_range_ids(s->tree, box, got, cap, &ng);
  if (nan) {
    QKF_ASSERT(rc == QK_ERR_NONFINITE, "range with a NaN bound = %d", rc);
    return;
  }
  QKF_ASSERT(rc == QK_OK, "range = %d", rc);
  QKF_ASSERT(ng == nw, "range [%g,%g]x[%g,%g] found %zu, brute force %zu", box.xmin, box.xmax,
             box.ymin, box.ymax, ng, nw);
  if (cap < nw) return;
  qsort(got, ng, sizeof *got, to_cmp_id);
  QKF_ASSERT(!memcmp(got, want, nw * sizeof *got), "range returned the wrong ids");
}

static void to_radius(to_state_t *s) {
  qk_point_t c = to_point(s);
  uint8_t rb = qkf_u8(&s->in);
  double r = s->opt.root.side * (rb & 0x7f) / 64.0;
  if (rb == 0xff) r = -1;
  if (rb == 0xfe) r = NAN;
  if (rb == 0xfd) r = INFINITY;
  static qk_neighbor_t got[TO_MAX_IDS];
  static qk_id_t gid[TO_MAX_IDS], want[TO_MAX_IDS];
  size_t ng = 0, nw = 0;
  qk_status_t rc = qk_query_radius_list(s->tree, c, r, got, TO_MAX_IDS, &ng);
  if (!to_finite(c) || isnan(r)) {
    QKF_ASSERT(rc == QK_ERR_NONFINITE, "radius with NaN = %d", rc);
    return;
  }
  if (r < 0) {
    QKF_ASSERT(rc == QK_ERR_INVALID, "radius with r < 0 = %d", rc);
    return;
  }
  QKF_ASSERT(rc == QK_OK, "radius = %d", rc);
  /* The query is exact (query.h); the oracle's squares in long double decide only away
   * from the circle and from underflow: a point it cannot decide leaves this query to the
   * exact tests of tests/test_query.c (radius_exact, against rationals). */
  const long double s2 = (long double)r * r;
  for (size_t i = 0; i < s->n_ids; i++) {
    if (!s->alive[i]) continue;
    long double dx = (long double)s->x[i] - c.x, dy = (long double)s->y[i] - c.y;
    long double d2 = dx * dx + dy * dy;
    if (!(d2 > 1e-200L && d2 < 1e200L && s2 > 1e-200L && s2 < 1e200L) ||
        fabsl(d2 - s2) <= s2 * 1e-9L)
      return;
    if (d2 < s2) want[nw++] = (qk_id_t)i;
  }
  QKF_ASSERT(ng == nw, "radius %g around (%.17g, %.17g) found %zu, brute force %zu", r, c.x, c.y,
             ng, nw);
  for (size_t i = 0; i < ng; i++) gid[i] = got[i].id;
  qsort(gid, ng, sizeof *gid, to_cmp_id);
  QKF_ASSERT(!memcmp(gid, want, nw * sizeof *gid), "radius returned the wrong ids");
}

static void to_knn(to_state_t *s) {
  qk_point_t q = to_point(s);
  size_t k = qkf_u8(&s->in) % 12;
  uint8_t mb = qkf_u8(&s->in);
  double maxd = mb & 0x80 ? s->opt.root.side * (mb & 0x7f) / 64.0 : INFINITY;
  static to_nb_t all[TO_MAX_IDS];
  qk_neighbor_t got[12];
  size_t ng = 99, na = 0;
  qk_status_t rc = qk_query_knn(s->tree, q, k, maxd, got, &ng);
  if (!to_finite(q)) {
    QKF_ASSERT(rc == QK_ERR_NONFINITE, "knn at a NaN = %d", rc);
    return;
  }
  if (fmax(fabs(q.x), fabs(q.y)) > 0x1p510) { /* every root here lies within 2^510 */
    QKF_ASSERT(rc == QK_ERR_LIMIT, "knn beyond the distance range = %d", rc);
    return;
  }
  QKF_ASSERT(rc == QK_OK, "knn = %d", rc);
  /* The ranking and the cap are exact (query.h); the oracle's squares in long double
   * decide only away from ties (but between equal points), from the cap and from
   * underflow: a query they cannot decide is left to the exact tests of
   * tests/test_query.c (knn_exact, against rationals). */
  const long double m2 = (long double)maxd * maxd;
  for (size_t i = 0; i < s->n_ids; i++) {
    if (!s->alive[i]) continue;
    long double dx = (long double)s->x[i] - q.x, dy = (long double)s->y[i] - q.y;
    long double d2 = dx * dx + dy * dy;
    if (d2 != 0 && !(d2 > 1e-200L && d2 < 1e200L)) return;
    if (!isinf(maxd) && fabsl(d2 - m2) <= m2 * 1e-9L) return;
    if (isinf(maxd) || d2 < m2) all[na++] = (to_nb_t){d2, (qk_id_t)i};
  }
  qsort(all, na, sizeof *all, to_cmp_nb);
  size_t nw = na < k ? na : k;
  /* Every near tie of an answer with a point elsewhere, not only with the next in the
   * sorted list: copies of one point tie exactly and sit together, and a point apart from
   * them whose square rounds alike may come after the whole group. */
  for (size_t i = 0; i < nw; i++) {
    const qk_id_t a = all[i].id;
    for (size_t j = i + 1; j < na && all[j].d2 - all[i].d2 <= all[i].d2 * 1e-9L; j++) {
      const qk_id_t b = all[j].id;
      if (s->x[a] != s->x[b] || s->y[a] != s->y[b]) return;
    }
  }
  QKF_ASSERT(ng == nw, "knn k=%zu at (%.17g, %.17g) gave %zu, want %zu", k, q.x, q.y, ng, nw);
  for (size_t i = 0; i < nw; i++) {
    const qk_id_t a = all[i].id;
    const double dx = s->x[a] - q.x, dy = s->y[a] - q.y, d2 = dx * dx + dy * dy;
    const double want = d2 < 0x1p1000 ? sqrt(d2) : hypot(dx, dy); /* as the library reports */
    QKF_ASSERT(got[i].id == a && got[i].dist == want,
               "knn #%zu: id %u dist %.17g, want id %u dist %.17g", i, got[i].id, got[i].dist, a,
               want);
  }
}

/* A collider over (some of) the live points as discs of input-chosen radii: its pairs
 * and box queries against brute force with the documented overlap tests. */
/* Is (xa - xb)^2 + (ya - yb)^2 <= (ra + rb)^2, evaluated after scaling all six values
 * by one power of two so that nothing overflows and only negligible terms underflow?
 * Sets *unsure when the answer is within rounding of the boundary. */
static int to_scaled_le(double xa, double xb, double ya, double yb, double ra, double rb,
                        int *unsure) {
  double m =
      fmax(fmax(fmax(fabs(xa), fabs(xb)), fmax(fabs(ya), fabs(yb))), fmax(fabs(ra), fabs(rb)));
  *unsure = 0;
  if (m == 0) return 1;
  int e;
  frexp(m, &e);
  double dx = ldexp(xa, -e) - ldexp(xb, -e), dy = ldexp(ya, -e) - ldexp(yb, -e);
  double rs = ldexp(ra, -e) + ldexp(rb, -e);
  double big = fmax(fmax(fabs(dx), fabs(dy)), rs);
  if (big == 0) {
    /* Every scaled difference and the radii rounded to 0: touching only when the two
     * points are the same (a degenerate box 2^-1074 from a zero-radius disc's centre at
     * 2^60 is not; fuzz/regressions/tree_ops/collider-zero-radius-subnormal-gap). */
    if (xa == xb && ya == yb) return 1;
    *unsure = 1;
    return 0;
  }
  if (big < 0x1p-400) { /* all differences negligible against the coordinates */
    *unsure = 1;
    return 0;
  }
  double d2 = dx * dx + dy * dy, r2 = rs * rs, tol = 1e-12 * fmax(d2, r2);
  *unsure = fabs(d2 - r2) <= tol && !(d2 == 0 && r2 == 0);
  return d2 <= r2;
}

static int to_pair_cb(qk_id_t a, qk_id_t b, void *ud) {
  size_t *n = ud;
  (void)a, (void)b;
  ++*n;
  return 0;
}

static void to_collider(to_state_t *s) {
  enum { M = 48 };
  qk_disc_t d[M];
  qk_box_t bx[M];
  size_t nd = 0, nb = 0;
  for (size_t i = 0; i < s->n_ids && nd + nb < M; i++) {
    if (!s->alive[i]) continue;
    double r = s->opt.root.side * (qkf_u8(&s->in) % 16) / 64.0;
    if (qkf_u8(&s->in) & 1)
      d[nd++] = (qk_disc_t){s->x[i], s->y[i], r};
    else
      bx[nb++] = (qk_box_t){s->x[i] - r, s->y[i] - r / 2, s->x[i] + r, s->y[i] + r / 2};
  }
  qk_tree_options_t o = s->opt;
  o.allocator = NULL;
  qk_collider_t *c = NULL;
  qk_status_t rc = qk_collider_build(d, nd, bx, nb, &o, &c);
  if (rc == QK_ERR_OUTSIDE) return; /* a box centre rounded outside the root */
  QKF_ASSERT(rc == QK_OK, "collider_build = %d", rc);
  /* The documented tests, evaluated twice: literally in double (what the collider
   * promises) and after scaling every input by the same power of two so that squares of
   * tiny or huge differences neither underflow nor overflow (plain doubles, no long
   * double, so that the oracle means the same under valgrind). Where the two disagree,
   * or a pair is within rounding of touching, either answer is accepted: that is the
   * documented limit of the formulas (see docs/reliability.md, "Limits"). */
  size_t sure = 0, maybe = 0;
  for (size_t i = 0; i < nd + nb; i++)
    for (size_t j = i + 1; j < nd + nb; j++) {
      if (i >= nd) {
        const qk_box_t *p = &bx[i - nd], *q = &bx[j - nd];
        sure +=
            p->xmin <= q->xmax && q->xmin <= p->xmax && p->ymin <= q->ymax && q->ymin <= p->ymax;
        continue;
      }
      int lit, exact, unsure;
      if (j < nd) {
        double dx = d[i].x - d[j].x, dy = d[i].y - d[j].y, rs = d[i].r + d[j].r;
        lit = dx * dx + dy * dy <= rs * rs;
        exact = to_scaled_le(d[i].x, d[j].x, d[i].y, d[j].y, d[i].r, d[j].r, &unsure);
      } else {
        const qk_box_t *b = &bx[j - nd];
        double x = d[i].x, y = d[i].y;
        /* The nearest box point: its differences from the centre are exact. */
        double nx = x < b->xmin ? b->xmin : x > b->xmax ? b->xmax : x;
        double ny = y < b->ymin ? b->ymin : y > b->ymax ? b->ymax : y;
        double dx = nx - x, dy = ny - y;
        lit = dx * dx + dy * dy <= d[i].r * d[i].r;
        exact = to_scaled_le(nx, x, ny, y, d[i].r, 0, &unsure);
      }
      if (unsure || exact != lit)
        maybe++;
      else
        sure += exact;
    }
  size_t got = 0, listed = 0;
  if (getenv("QKF_DEBUG")) {
    for (size_t i = 0; i < nd; i++)
      fprintf(stderr, "disc %zu: %a %a %a\n", i, d[i].x, d[i].y, d[i].r);
    for (size_t i = 0; i < nb; i++)
      fprintf(stderr, "box %zu: %a %a %a %a\n", nd + i, bx[i].xmin, bx[i].ymin, bx[i].xmax,
              bx[i].ymax);
  }
  QKF_ASSERT(qk_collider_pairs(c, to_pair_cb, &got) == QK_OK, "collider_pairs failed");
  QKF_ASSERT(qk_collider_pairs_list(c, NULL, 0, &listed) == QK_OK, "pairs_list failed");
  QKF_ASSERT(got == listed && got >= sure && got <= sure + maybe,
             "collider: %zu pairs (list %zu), brute force %zu (+%zu within rounding)", got, listed,
             sure, maybe);
  /* A ray from a point: any hit lies within [0, tmax]. */
  qk_point_t o0 = to_point(s), dir = to_point(s);
  qk_hit_t hit;
  rc = qk_collider_raycast(c, o0, dir, 1.0, &hit);
  QKF_ASSERT(rc == QK_OK || rc == QK_ERR_NONFINITE || rc == QK_ERR_INVALID, "raycast = %d", rc);
  if (rc == QK_OK && hit.id != QK_NONE)
    QKF_ASSERT(hit.id < nd + nb && hit.t >= 0 && hit.t <= 1, "raycast hit %u at t=%g", hit.id,
               hit.t);
  qk_collider_free(c);
}

/* Batches (kNN, locate, radius) against the same queries asked one at a time. Batches
 * of 64 or more borrow a buffer from the tree's allocator, which may be armed to fail:
 * the answers must not change, and nothing may stay borrowed. */
static void to_batch(to_state_t *s) {
  enum { MAXQ = 130, K = 4 };
  static qk_point_t q[MAXQ];
  static qk_neighbor_t got[MAXQ * K], one[K];
  static size_t counts[MAXQ], offsets[MAXQ + 1];
  static qk_node_t leaves[MAXQ];
  static qk_neighbor_t rout[MAXQ * 8];
  size_t nq = 1 + qkf_u8(&s->in) % MAXQ;
  uint8_t fail = qkf_u8(&s->in);
  for (size_t i = 0; i < nq; i++) q[i] = to_point(s);
  double r = s->opt.root.side / 16;
  size_t blocks = s->alloc_state.live_blocks;
  qkt_alloc_arm(&s->alloc_state, fail & 1 ? 1 : 0);
  qk_status_t kb = qk_query_knn_batch(s->tree, q, nq, K, INFINITY, got, counts);
  qk_status_t lb = qk_query_locate_batch(s->tree, q, nq, leaves);
  qk_status_t rb = qk_query_radius_batch(s->tree, q, nq, r, rout, MAXQ * 8, offsets);
  qkt_alloc_arm(&s->alloc_state, 0);
  QKF_ASSERT(s->alloc_state.live_blocks == blocks, "a batch kept %zu borrowed blocks",
             s->alloc_state.live_blocks - blocks);
  QKF_ASSERT(lb == QK_OK, "locate_batch = %d", lb);
  int any_bad = 0;
  qk_status_t first_bad = QK_OK;
  for (size_t i = 0; i < nq; i++) {
    size_t n1 = 0;
    qk_status_t st = qk_query_knn(s->tree, q[i], K, INFINITY, one, &n1);
    if (st != QK_OK) {
      if (!any_bad) first_bad = st;
      any_bad = 1;
      QKF_ASSERT(counts[i] == 0, "knn_batch answered non-finite query %zu", i);
      QKF_ASSERT(leaves[i] == QK_NONE, "locate_batch placed non-finite query %zu", i);
      continue;
    }
    QKF_ASSERT(counts[i] == n1, "knn_batch query %zu: %zu neighbours, single query %zu", i,
               counts[i], n1);
    for (size_t j = 0; j < n1; j++)
      QKF_ASSERT(got[i * K + j].id == one[j].id && got[i * K + j].dist == one[j].dist,
                 "knn_batch query %zu neighbour %zu differs from the single query", i, j);
    for (size_t j = n1; j < K; j++)
      QKF_ASSERT(got[i * K + j].id == QK_NONE, "knn_batch: unused slot not QK_NONE");
    qk_node_t leaf = QK_NONE;
    qk_status_t fl = qk_tree_find_leaf(s->tree, q[i], &leaf);
    QKF_ASSERT(leaves[i] == (fl == QK_OK ? leaf : QK_NONE), "locate_batch query %zu", i);
    if (rb == QK_OK) {
      size_t nr = 0;
      qk_query_radius_list(s->tree, q[i], r, NULL, 0, &nr);
      QKF_ASSERT(offsets[i + 1] - offsets[i] == nr, "radius_batch query %zu: %zu, single %zu", i,
                 offsets[i + 1] - offsets[i], nr);
    }
  }
  QKF_ASSERT(kb == first_bad, "knn_batch = %d", kb);
  QKF_ASSERT(rb == QK_OK || rb == QK_ERR_LIMIT || (any_bad && rb == QK_ERR_NONFINITE),
             "radius_batch = %d", rb);
}

/* Refinement predicate: split a leaf that holds a point while above the chosen depth. */
static int to_refine_cb(const qk_tree_t *t, qk_node_t leaf, qk_square_t sq, uint32_t depth,
                        void *ud) {
  size_t n = 0;
  (void)sq;
  qk_tree_leaf_points(t, leaf, NULL, NULL, NULL, &n);
  return n > 0 && depth < *(const uint32_t *)ud;
}

/* Build a fresh tree of the live points: unless refined, it must have the same shape,
 * since the shape depends only on the point set. With an armed allocator the build
 * must fail cleanly. */
static void to_rebuild(to_state_t *s, size_t fail_at) {
  static qk_point_t pts[TO_MAX_IDS];
  size_t n = 0;
  for (size_t i = 0; i < s->n_ids; i++)
    if (s->alive[i]) pts[n++] = (qk_point_t){s->x[i], s->y[i]};
  qkt_alloc_t fa;
  qk_allocator_t al = qkt_alloc_make(&fa);
  qkt_alloc_arm(&fa, fail_at);
  qk_tree_options_t o = s->opt;
  o.allocator = &al;
  qk_tree_t *t = (qk_tree_t *)&fa;
  qk_status_t rc = qk_tree_build(pts, n, &o, &t);
  if (fa.failed && rc != QK_OK) { /* (an optional allocation, a shrink, may fail) */
    QKF_ASSERT(rc == QK_ERR_NOMEM && t == NULL, "build with a failed allocation = %d", rc);
    QKF_ASSERT(fa.live_blocks == 0, "failed build leaked %zu blocks", fa.live_blocks);
    return;
  }
  QKF_ASSERT(rc == QK_OK, "rebuild = %d", rc);
  qkf_check_tree(t, "rebuild");
  if (!s->refined) {
    qk_tree_stats_t a, b;
    qk_tree_stats(s->tree, &a);
    qk_tree_stats(t, &b);
    QKF_ASSERT(a.nodes == b.nodes && a.leaves == b.leaves && a.height == b.height,
               "incremental tree (%zu nodes, %zu leaves, height %u) differs from a fresh build "
               "(%zu, %zu, %u)",
               a.nodes, a.leaves, a.height, b.nodes, b.leaves, b.height);
  }
  qk_tree_free(t);
  QKF_ASSERT(fa.live_blocks == 0, "tree_free leaked %zu blocks", fa.live_blocks);
}

int qkf_tree_ops(const uint8_t *data, size_t size) {
  static to_state_t s;
  memset(&s, 0, sizeof s);
  s.in = (qkf_bytes_t){data, size, 0};
  s.alloc = qkt_alloc_make(&s.alloc_state);
  qk_tree_options_init(&s.opt);
  s.opt.allocator = &s.alloc;
  s.opt.capacity = 1 + qkf_u8(&s.in) % 8;
  uint8_t depth = qkf_u8(&s.in);
  s.opt.max_depth = depth % 4 == 0 ? 0 : 1 + depth % QK_MAX_DEPTH_LIMIT;
  s.opt.has_root = 1;
  static const qk_square_t roots[] = {
      {0, 0, 1},             /* the unit square */
      {-8, -8, 16},          /* dyadic, around the origin */
      {0.1, -0.3, 3},        /* not dyadic: far edges off by ulps */
      {1e15, -1e15, 1000},   /* far from the origin: few bits below the point */
      {0, 0, 0x1p-1070},     /* subnormal: cannot be halved far */
      {-0x1p60, 0, 0x1p61}}; /* huge, dyadic */
  uint8_t rk = qkf_u8(&s.in) % 6;
  s.opt.root = roots[rk];
  s.dyadic = rk != 2 && rk != 3;
  /* The initial points, built in bulk. */
  size_t n0 = qkf_u8(&s.in) % 40;
  qk_point_t init[40];
  for (size_t i = 0; i < n0; i++) {
    init[i] = to_point(&s);
    if (!to_finite(init[i]) || !to_inside(&s, init[i]))
      init[i] = (qk_point_t){s.opt.root.x, s.opt.root.y};
    s.x[i] = init[i].x, s.y[i] = init[i].y, s.alive[i] = 1;
  }
  s.n_ids = n0;
  qk_status_t rc = qk_tree_build(init, n0, &s.opt, &s.tree);
  QKF_ASSERT(rc == QK_OK, "initial build = %d", rc);
  to_check(&s, "build");

  for (int op = 0; op < TO_MAX_OPS && !qkf_done(&s.in); op++) {
    uint8_t code = qkf_u8(&s.in);
    int armed = 0;
    if (code >= 0xf0) { /* fail the k-th allocation of the change that follows */
      qkt_alloc_arm(&s.alloc_state, 1 + (code & 7));
      armed = 1;
      static const uint8_t changes[] = {0, 3, 4, 12};
      uint8_t pick = qkf_u8(&s.in);
      code = changes[pick % 4];
      if (code == 3 && (pick & 0x80)) code = 129; /* a move rather than a removal */
    }
    switch (code % 14) {
    case 0:
    case 1:
    case 2:
      if (s.n_ids < TO_MAX_IDS) to_insert(&s, to_point(&s), armed);
      break;
    case 3:
      if (code & 0x80) { /* codes 129, 143, ...: move a point, keeping its id */
        qk_id_t id = (qk_id_t)(qkf_u8(&s.in) % (s.n_ids + 2));
        to_move(&s, id, to_point(&s), armed);
      } else {
        to_remove(&s, (qk_id_t)(qkf_u8(&s.in) % (s.n_ids + 2)), armed);
      }
      break;
    case 4:
      if (qkf_u8(&s.in) & 1)
        to_split(&s, armed);
      else
        to_balance(&s, armed);
      break;
    case 5:
      to_find_leaf(&s, to_point(&s));
      break;
    case 6:
      to_range(&s);
      break;
    case 7:
      to_radius(&s);
      break;
    case 8:
      to_knn(&s);
      break;
    case 9:
      to_collider(&s);
      break;
    case 10:
      to_rebuild(&s, qkf_u8(&s.in) % 6);
      break;
    case 13:
      to_batch(&s);
      break;
    case 11: { /* neighbours of a leaf: each adjacent leaf lists the leaf back */
      qk_node_t leaf = to_pick_leaf(&s);
      for (int d = 0; d < 4; d++) {
        qk_node_t adj[64];
        size_t na = 0;
        QKF_ASSERT(qk_tree_adjacent_leaves(s.tree, leaf, (qk_dir_t)d, adj, 64, &na) == QK_OK,
                   "adjacent_leaves failed");
        qk_node_t nb = qk_tree_neighbor(s.tree, leaf, (qk_dir_t)d);
        QKF_ASSERT((na == 0) == (nb == QK_NONE), "neighbor and adjacent_leaves disagree");
        for (size_t i = 0; i < na && i < 64; i++) {
          qk_node_t back[64];
          size_t nback = 0, found = 0;
          qk_tree_adjacent_leaves(s.tree, adj[i], (qk_dir_t)((d + 2) % 4), back, 64, &nback);
          for (size_t j = 0; j < nback && j < 64; j++) found += back[j] == leaf;
          QKF_ASSERT(found == 1 || nback > 64, "leaf %u is not adjacent back to %u", adj[i], leaf);
        }
      }
      break;
    }
    default: { /* refine: split leaves holding points down to a chosen depth */
      uint32_t limit = qkf_u8(&s.in) % 5;
      qk_tree_stats_t before;
      qk_tree_stats(s.tree, &before);
      qk_status_t r2 = qk_tree_refine(s.tree, to_refine_cb, &limit);
      s.refined = 1;
      QKF_ASSERT(r2 == QK_OK || (armed && r2 == QK_ERR_NOMEM && s.alloc_state.failed),
                 "refine = %d", r2);
      to_check(&s, "refine");
      break;
    }
    }
    if (armed) {
      /* A failed change may keep arrays it grew (the tree owns them); anything else it
       * allocated would show up as a leak when the tree is freed below. */
      qkt_alloc_arm(&s.alloc_state, 0);
    }
  }
  qk_tree_free(s.tree);
  QKF_ASSERT(s.alloc_state.live_blocks == 0 && s.alloc_state.live_bytes == 0,
             "freeing the tree left %zu blocks", s.alloc_state.live_blocks);
  return 0;
}

#ifndef QKF_REPLAY
int LLVMFuzzerTestOneInput(const uint8_t *data, size_t size);
int LLVMFuzzerTestOneInput(const uint8_t *data, size_t size) { return qkf_tree_ops(data, size); }
#endif
