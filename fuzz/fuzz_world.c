/*
 * Fuzz target: a random sequence of calls on the moving-objects world, checked against
 * a brute-force model of the live objects.
 *
 * The input's first bytes choose the world's options (threads 1 or 2, with the update's
 * thread threshold low enough that two threads really run, margins, and whether the
 * failing allocator of the tests is used); the rest is a list of operations: add an
 * object of any kind, move (one or a batch), remove, calls with stale or made-up handles,
 * update, pairs (all / began / ended, by callback and into short buffers), shape
 * queries, raycasts, kNN, "fail the k-th allocation of the next add or update", and
 * free-and-recreate. Shape values come from a small grid (multiples of 1/4 up to 16,
 * where every overlap test below is exact in double) or from extreme values: zero, -0,
 * the ends of the accepted range [2^-100, 2^100] and just beyond, 1e300, subnormals,
 * NaN, infinities, or raw input bits.
 *
 * Checked: a call's status against the documented shape rules; a refused call leaves
 * every object (qk_world_get) and the size as they were; after every update, for worlds
 * whose objects are all on the grid, the pairs equal brute force over the live objects
 * with exact overlap tests, and began / ended equal the differences from the previous
 * update's pairs; in every world, each object's pairs equal what qk_world_query() of its
 * shape finds; queries and raycasts on grid worlds equal brute force; short buffers
 * get the full count and a prefix of the full answer; nothing leaks.
 */
#include "fuzz/fuzz_common.h"

#define WO_MAX 48      /* objects in the model */
#define WO_MAX_OPS 300 /* operations per input */
#define WO_MAX_PAIRS (WO_MAX * (WO_MAX - 1) / 2)

typedef struct wo_obj {
  qk_handle_t h;
  qk_shape_t s; /* normalised as qk_world_get returns it */
  uint64_t tag;
  int grid; /* every used value on the grid */
} wo_obj_t;

typedef struct wo_state {
  qkf_bytes_t in;
  qkt_alloc_t alloc_state;
  qk_allocator_t alloc;
  int use_alloc;
  qk_world_options_t opt;
  qk_world_t *w;
  wo_obj_t obj[WO_MAX];
  size_t n;
  qk_handle_t stale[16]; /* handles of removed objects */
  size_t n_stale;
  /* The pairs of the last two updates, as handles (a's slot below b's). */
  qk_world_pair_t cur[WO_MAX_PAIRS], prev[WO_MAX_PAIRS];
  size_t n_cur, n_prev;
  int updated;   /* an update has succeeded since the world was made */
  int exact_cur; /* the model's pairs at the last update were known exactly */
} wo_state_t;

/* ---- values and shapes ---------------------------------------------------------------- */

static int wo_on_grid(double v) { return fabs(v) <= 16 && v * 4 == floor(v * 4); }

static double wo_value(wo_state_t *s) {
  uint8_t k = qkf_u8(&s->in);
  if (k < 200) return ((int)(k % 129) - 64) / 4.0; /* the grid: -16 .. 16 by 1/4 */
  static const double special[] = {0.0,
                                   -0.0,
                                   0x1p-100,
                                   -0x1p-100,
                                   0x1p100,
                                   -0x1p100,
                                   0x1.fffffffffffffp-101, /* just below the range */
                                   0x1.0000000000001p100,  /* just above */
                                   1e300,
                                   -1e300,
                                   1e-320,
                                   NAN,
                                   INFINITY,
                                   -INFINITY,
                                   0x1.8p99,
                                   1e30,
                                   -7.9e-31,
                                   0x1p-60,
                                   0x1p60 + 1024,
                                   3.0,
                                   0.1};
  enum { NS = sizeof special / sizeof special[0] };
  if (k < 200 + NS) return special[k - 200];
  return qkf_raw_double(&s->in);
}

static qk_shape_t wo_shape(wo_state_t *s) {
  qk_shape_t sh;
  memset(&sh, 0, sizeof sh);
  uint8_t k = qkf_u8(&s->in);
  sh.kind = (qk_shape_kind_t)(k % 4);
  sh.x = wo_value(s);
  sh.y = wo_value(s);
  if (sh.kind != QK_SHAPE_POINT) sh.a = wo_value(s);
  if (sh.kind == QK_SHAPE_BOX || sh.kind == QK_SHAPE_SEGMENT) sh.b = wo_value(s);
  /* Grid discs: mostly nonnegative radii so that they exist. */
  if (sh.kind == QK_SHAPE_DISC && (k & 0x40) && sh.a < 0) sh.a = -sh.a;
  return sh;
}

static int wo_nvals(qk_shape_kind_t k) {
  return k == QK_SHAPE_POINT ? 2 : k == QK_SHAPE_DISC ? 3 : 4;
}

static int wo_shape_grid(const qk_shape_t *sh) {
  const double v[4] = {sh->x, sh->y, sh->a, sh->b};
  for (int i = 0; i < wo_nvals(sh->kind); i++)
    if (!wo_on_grid(v[i])) return 0;
  return 1;
}

/* The statuses a shape may be refused with (a bit per status), 0 when it is valid. */
static unsigned wo_shape_errors(const qk_shape_t *sh) {
  if ((unsigned)sh->kind > QK_SHAPE_POINT) return 1u << QK_ERR_INVALID;
  const double v[4] = {sh->x, sh->y, sh->a, sh->b};
  unsigned e = 0;
  for (int i = 0; i < wo_nvals(sh->kind); i++) {
    if (!isfinite(v[i]))
      e |= 1u << QK_ERR_NONFINITE;
    else if (v[i] != 0 && (fabs(v[i]) < 0x1p-100 || fabs(v[i]) > 0x1p100))
      e |= 1u << QK_ERR_LIMIT;
  }
  if (sh->kind == QK_SHAPE_DISC && sh->a < 0) e |= 1u << QK_ERR_GEOMETRY;
  return e;
}

static qk_shape_t wo_normalise(qk_shape_t sh) {
  if (sh.kind == QK_SHAPE_BOX) {
    double x0 = fmin(sh.x, sh.a), x1 = fmax(sh.x, sh.a), y0 = fmin(sh.y, sh.b),
           y1 = fmax(sh.y, sh.b);
    sh.x = x0, sh.a = x1, sh.y = y0, sh.b = y1;
  }
  if (sh.kind == QK_SHAPE_POINT) sh.a = sh.b = 0;
  if (sh.kind == QK_SHAPE_DISC) sh.b = 0;
  return sh;
}

/* ---- exact overlap of grid shapes (every product below is exact in double) ------------ */

typedef struct wo_pt {
  double x, y;
} wo_pt_t;

static double wo_orient(wo_pt_t a, wo_pt_t b, wo_pt_t c) {
  return (b.x - a.x) * (c.y - a.y) - (b.y - a.y) * (c.x - a.x);
}

static int wo_sgn(double v) { return (v > 0) - (v < 0); }

static int wo_in_bbox(wo_pt_t a, wo_pt_t b, wo_pt_t p) {
  return p.x >= fmin(a.x, b.x) && p.x <= fmax(a.x, b.x) && p.y >= fmin(a.y, b.y) &&
         p.y <= fmax(a.y, b.y);
}

static int wo_seg_seg(wo_pt_t p1, wo_pt_t q1, wo_pt_t p2, wo_pt_t q2) {
  int o1 = wo_sgn(wo_orient(p1, q1, p2)), o2 = wo_sgn(wo_orient(p1, q1, q2));
  int o3 = wo_sgn(wo_orient(p2, q2, p1)), o4 = wo_sgn(wo_orient(p2, q2, q1));
  if (o1 * o2 < 0 && o3 * o4 < 0) return 1;
  if (o1 == 0 && wo_in_bbox(p1, q1, p2)) return 1;
  if (o2 == 0 && wo_in_bbox(p1, q1, q2)) return 1;
  if (o3 == 0 && wo_in_bbox(p2, q2, p1)) return 1;
  if (o4 == 0 && wo_in_bbox(p2, q2, q1)) return 1;
  return 0;
}

/* Squared distance from p to the segment ab <= r^2, exactly. */
static int wo_seg_disc(wo_pt_t a, wo_pt_t b, wo_pt_t p, double r) {
  double dx = b.x - a.x, dy = b.y - a.y, wx = p.x - a.x, wy = p.y - a.y;
  double wd = wx * dx + wy * dy, dd = dx * dx + dy * dy;
  if (wd <= 0) return wx * wx + wy * wy <= r * r;
  if (wd >= dd) {
    double ux = p.x - b.x, uy = p.y - b.y;
    return ux * ux + uy * uy <= r * r;
  }
  double cr = wx * dy - wy * dx;
  return cr * cr <= r * r * dd;
}

static int wo_box_pt(const qk_shape_t *b, wo_pt_t p) {
  return p.x >= b->x && p.x <= b->a && p.y >= b->y && p.y <= b->b;
}

/* a and b normalised grid shapes. */
static int wo_overlap(const qk_shape_t *a, const qk_shape_t *b) {
  if (a->kind > b->kind) {
    const qk_shape_t *t = a;
    a = b, b = t;
  }
  wo_pt_t a0 = {a->x, a->y}, a1 = {a->a, a->b}, b0 = {b->x, b->y}, b1 = {b->a, b->b};
  switch (a->kind) {
  case QK_SHAPE_DISC:
    switch (b->kind) {
    case QK_SHAPE_DISC: {
      double dx = a->x - b->x, dy = a->y - b->y, r = a->a + b->a;
      return dx * dx + dy * dy <= r * r;
    }
    case QK_SHAPE_BOX: {
      double nx = fmin(fmax(a->x, b->x), b->a), ny = fmin(fmax(a->y, b->y), b->b);
      double dx = nx - a->x, dy = ny - a->y;
      return dx * dx + dy * dy <= a->a * a->a;
    }
    case QK_SHAPE_SEGMENT:
      return wo_seg_disc(b0, b1, a0, a->a);
    default:
      return wo_seg_disc(b0, b0, a0, a->a);
    }
  case QK_SHAPE_BOX:
    switch (b->kind) {
    case QK_SHAPE_BOX:
      return a->x <= b->a && b->x <= a->a && a->y <= b->b && b->y <= a->b;
    case QK_SHAPE_SEGMENT: {
      if (wo_box_pt(a, b0) || wo_box_pt(a, b1)) return 1;
      wo_pt_t c[4] = {{a->x, a->y}, {a->a, a->y}, {a->a, a->b}, {a->x, a->b}};
      for (int i = 0; i < 4; i++)
        if (wo_seg_seg(c[i], c[(i + 1) % 4], b0, b1)) return 1;
      return 0;
    }
    default:
      return wo_box_pt(a, b0);
    }
  case QK_SHAPE_SEGMENT:
    if (b->kind == QK_SHAPE_SEGMENT) return wo_seg_seg(a0, a1, b0, b1);
    return wo_seg_seg(a0, a1, b0, b0);
  default:
    return a->x == b->x && a->y == b->y;
  }
}

/* ---- checks ----------------------------------------------------------------------------- */

static int wo_all_grid(const wo_state_t *s) {
  for (size_t i = 0; i < s->n; i++)
    if (!s->obj[i].grid) return 0;
  return 1;
}

static size_t wo_find(const wo_state_t *s, qk_handle_t h) {
  for (size_t i = 0; i < s->n; i++)
    if (s->obj[i].h == h) return i;
  return SIZE_MAX;
}

/* (Stored shapes are finite: == compares them, and lets a box's corners order 0 and -0
 * either way.) */
static int wo_same_shape(const qk_shape_t *a, const qk_shape_t *b) {
  return a->kind == b->kind && a->x == b->x && a->y == b->y &&
         (a->kind == QK_SHAPE_POINT || a->a == b->a) &&
         (a->kind == QK_SHAPE_POINT || a->kind == QK_SHAPE_DISC || a->b == b->b);
}

/* The world's objects against the model. */
static void wo_check_objects(wo_state_t *s, const char *after) {
  QKF_ASSERT(qk_world_size(s->w) == s->n, "after %s: size %zu, model %zu", after,
             qk_world_size(s->w), s->n);
  for (size_t i = 0; i < s->n; i++) {
    qk_shape_t sh;
    uint64_t tag = 0;
    qk_status_t rc = qk_world_get(s->w, s->obj[i].h, &sh, &tag);
    QKF_ASSERT(rc == QK_OK, "after %s: get(live object %zu) = %d", after, i, rc);
    QKF_ASSERT(wo_same_shape(&sh, &s->obj[i].s) && tag == s->obj[i].tag,
               "after %s: object %zu (kind %d) is (%d %a %a %a %a), model (%d %a %a %a %a)", after,
               i, s->obj[i].s.kind, sh.kind, sh.x, sh.y, sh.a, sh.b, s->obj[i].s.kind,
               s->obj[i].s.x, s->obj[i].s.y, s->obj[i].s.a, s->obj[i].s.b);
  }
  for (size_t i = 0; i < s->n_stale; i++)
    QKF_ASSERT(qk_world_get(s->w, s->stale[i], NULL, NULL) == QK_ERR_NOT_FOUND,
               "after %s: stale handle %llx found", after, (unsigned long long)s->stale[i]);
  QKF_ASSERT(qk_world_get(s->w, QK_HANDLE_NONE, NULL, NULL) == QK_ERR_NOT_FOUND,
             "QK_HANDLE_NONE found");
}

static int wo_pair_less(const qk_world_pair_t *p, const qk_world_pair_t *q) {
  uint32_t pa = QK_HANDLE_SLOT(p->a), qa = QK_HANDLE_SLOT(q->a);
  return pa != qa ? pa < qa : QK_HANDLE_SLOT(p->b) < QK_HANDLE_SLOT(q->b);
}

static int wo_has_pair(const qk_world_pair_t *v, size_t n, qk_world_pair_t p) {
  for (size_t i = 0; i < n; i++)
    if (v[i].a == p.a && v[i].b == p.b) return 1;
  return 0;
}

static qk_world_pair_t wo_pair_of(qk_handle_t a, qk_handle_t b) {
  if (QK_HANDLE_SLOT(a) > QK_HANDLE_SLOT(b)) {
    qk_handle_t t = a;
    a = b, b = t;
  }
  return (qk_world_pair_t){a, b};
}

static int wo_count_cb(qk_handle_t a, qk_handle_t b, void *ud) {
  size_t *c = ud;
  (void)a, (void)b;
  return ++c[0] == c[1];
}

/* Pairs of `which` into buf (full), checked for order and against a short buffer and
 * the callback form. */
static size_t wo_list(wo_state_t *s, qk_pairs_which_t which, qk_world_pair_t *buf, size_t cap) {
  size_t n = SIZE_MAX;
  qk_status_t rc = qk_world_pairs_list(s->w, which, buf, cap, &n);
  QKF_ASSERT(rc == QK_OK, "pairs_list(%d) = %d", which, rc);
  QKF_ASSERT(n <= cap, "pairs_list(%d): %zu pairs, at most %zu possible", which, n, cap);
  for (size_t i = 0; i + 1 < n; i++)
    QKF_ASSERT(wo_pair_less(&buf[i], &buf[i + 1]), "pairs_list(%d) not sorted at %zu", which, i);
  for (size_t i = 0; i < n; i++)
    QKF_ASSERT(QK_HANDLE_SLOT(buf[i].a) < QK_HANDLE_SLOT(buf[i].b),
               "pairs_list(%d): pair %zu not slot-ordered", which, i);
  /* A short buffer: the full count, and (documented: in order) a prefix. */
  size_t shortcap = (size_t)qkf_u8(&s->in) % 4, n2 = 0;
  qk_world_pair_t small[4];
  rc = qk_world_pairs_list(s->w, which, shortcap ? small : NULL, shortcap, &n2);
  QKF_ASSERT(rc == QK_OK && n2 == n, "short pairs_list(%d): %d, %zu pairs, want %zu", which, rc, n2,
             n);
  for (size_t i = 0; i < shortcap && i < n; i++)
    QKF_ASSERT(small[i].a == buf[i].a && small[i].b == buf[i].b,
               "short pairs_list(%d): pair %zu differs", which, i);
  size_t c[2] = {0, SIZE_MAX};
  QKF_ASSERT(qk_world_pairs(s->w, which, wo_count_cb, c) == QK_OK && c[0] == n,
             "pairs(%d) callback saw %zu pairs, list %zu", which, c[0], n);
  if (n > 0) {
    size_t stop[2] = {0, 1};
    qk_world_pairs(s->w, which, wo_count_cb, stop);
    QKF_ASSERT(stop[0] == 1, "pairs(%d) did not stop when asked", which);
  }
  return n;
}

/* After a successful update: the pairs against brute force (grid worlds) and against
 * the world's own shape queries (every world), began / ended against the previous
 * update's pairs. */
static void wo_after_update(wo_state_t *s) {
  static qk_world_pair_t got[WO_MAX_PAIRS], began[WO_MAX_PAIRS], ended[WO_MAX_PAIRS];
  size_t ng = wo_list(s, QK_PAIRS_ALL, got, WO_MAX_PAIRS);
  size_t nb = wo_list(s, QK_PAIRS_BEGAN, began, WO_MAX_PAIRS);
  size_t ne = wo_list(s, QK_PAIRS_ENDED, ended, WO_MAX_PAIRS);
  for (size_t i = 0; i < ng; i++)
    QKF_ASSERT(wo_find(s, got[i].a) != SIZE_MAX && wo_find(s, got[i].b) != SIZE_MAX,
               "a pair names a dead handle");
  if (wo_all_grid(s)) {
    size_t want = 0;
    for (size_t i = 0; i < s->n; i++)
      for (size_t j = i + 1; j < s->n; j++) {
        int ov = wo_overlap(&s->obj[i].s, &s->obj[j].s);
        want += ov;
        qk_world_pair_t p = wo_pair_of(s->obj[i].h, s->obj[j].h);
        QKF_ASSERT(ov == wo_has_pair(got, ng, p),
                   "update: objects %zu (kind %d) and %zu (kind %d) %s, the world %s", i,
                   s->obj[i].s.kind, j, s->obj[j].s.kind, ov ? "overlap" : "do not overlap",
                   ov ? "misses the pair" : "reports it");
      }
    QKF_ASSERT(want == ng, "update: %zu pairs, brute force %zu", ng, want);
  }
  /* Each object's pairs are what a query with its shape finds (less itself). */
  static qk_handle_t q[WO_MAX];
  for (size_t i = 0; i < s->n; i++) {
    size_t nq = 0;
    qk_status_t rc = qk_world_query(s->w, &s->obj[i].s, q, WO_MAX, &nq);
    QKF_ASSERT(rc == QK_OK, "query with live object %zu's shape = %d", i, rc);
    QKF_ASSERT(nq <= WO_MAX, "query found %zu objects", nq);
    size_t self = 0, paired = 0;
    for (size_t k = 0; k < nq; k++) {
      if (q[k] == s->obj[i].h) {
        self++;
        continue;
      }
      QKF_ASSERT(wo_has_pair(got, ng, wo_pair_of(s->obj[i].h, q[k])),
                 "object %zu's shape query finds %llx, which is not its pair", i,
                 (unsigned long long)q[k]);
    }
    for (size_t k = 0; k < ng; k++) paired += got[k].a == s->obj[i].h || got[k].b == s->obj[i].h;
    QKF_ASSERT(self == 1, "object %zu's shape query finds it %zu times", i, self);
    QKF_ASSERT(paired == nq - 1, "object %zu has %zu pairs, its shape query %zu others", i, paired,
               nq - 1);
  }
  /* began = cur \ prev, ended = prev \ cur (as handles: a reused slot is a new object). */
  const qk_world_pair_t *prev = s->cur; /* the previous update's, still in s->cur */
  size_t np = s->updated ? s->n_cur : 0;
  size_t wb = 0, we = 0;
  for (size_t i = 0; i < ng; i++)
    if (!wo_has_pair(prev, np, got[i])) {
      wb++;
      QKF_ASSERT(wo_has_pair(began, nb, got[i]), "a new pair is not in began");
    }
  for (size_t i = 0; i < np; i++)
    if (!wo_has_pair(got, ng, prev[i])) {
      we++;
      QKF_ASSERT(wo_has_pair(ended, ne, prev[i]), "a pair that ended is not in ended");
    }
  QKF_ASSERT(wb == nb && we == ne, "began %zu (want %zu), ended %zu (want %zu)", nb, wb, ne, we);
  memcpy(s->prev, s->cur, sizeof s->cur[0] * s->n_cur);
  s->n_prev = s->n_cur;
  memcpy(s->cur, got, sizeof got[0] * ng);
  s->n_cur = ng;
  s->updated = 1;
}

/* A refused or failed update keeps the last update's pairs. */
static void wo_pairs_kept(wo_state_t *s, const char *after) {
  static qk_world_pair_t got[WO_MAX_PAIRS];
  size_t n = 0;
  QKF_ASSERT(qk_world_pairs_list(s->w, QK_PAIRS_ALL, got, WO_MAX_PAIRS, &n) == QK_OK, "pairs_list");
  QKF_ASSERT(n == (s->updated ? s->n_cur : 0), "after %s: %zu pairs, had %zu", after, n, s->n_cur);
  for (size_t i = 0; i < n; i++)
    QKF_ASSERT(got[i].a == s->cur[i].a && got[i].b == s->cur[i].b, "after %s: pair %zu changed",
               after, i);
}

/* ---- operations ---------------------------------------------------------------------- */

static qk_handle_t wo_pick_handle(wo_state_t *s) {
  uint8_t k = qkf_u8(&s->in);
  if (k < 200 && s->n) return s->obj[k % s->n].h;
  if (k < 230 && s->n_stale) return s->stale[k % s->n_stale];
  if (k < 240) return QK_HANDLE_NONE;
  if (k < 250 && s->n) return s->obj[k % s->n].h + ((uint64_t)1 << 32); /* next generation */
  return (uint64_t)qkf_u32(&s->in) << 32 | qkf_u32(&s->in);
}

static void wo_add(wo_state_t *s, int armed) {
  qk_shape_t sh = wo_shape(s);
  uint64_t tag = qkf_u32(&s->in);
  unsigned errs = wo_shape_errors(&sh);
  qk_handle_t h = 12345;
  qk_status_t rc = qk_world_add(s->w, &sh, tag, &h);
  if (errs) {
    QKF_ASSERT(rc != QK_OK && (errs >> rc & 1),
               "add(kind %d, %a %a %a %a) = %d (%s), want one of %#x", sh.kind, sh.x, sh.y, sh.a,
               sh.b, rc, qk_strerror(rc), errs);
  } else if (armed && rc == QK_ERR_NOMEM && s->alloc_state.failed) {
    /* a clean failure */
  } else {
    QKF_ASSERT(rc == QK_OK, "add(kind %d, %a %a %a %a) = %d (%s)", sh.kind, sh.x, sh.y, sh.a, sh.b,
               rc, qk_strerror(rc));
  }
  if (rc != QK_OK) {
    QKF_ASSERT(*qk_strerror(rc) != '\0', "status %d has no message", rc);
    wo_check_objects(s, "a refused add");
    return;
  }
  QKF_ASSERT(h != QK_HANDLE_NONE && wo_find(s, h) == SIZE_MAX, "add gave a live handle");
  for (size_t i = 0; i < s->n_stale; i++)
    QKF_ASSERT(s->stale[i] != h, "add gave a removed object's handle again");
  s->obj[s->n++] = (wo_obj_t){h, wo_normalise(sh), tag, wo_shape_grid(&sh)};
}

static void wo_move(wo_state_t *s) {
  qk_handle_t h = wo_pick_handle(s);
  qk_shape_t sh = wo_shape(s);
  size_t i = wo_find(s, h);
  unsigned errs = i == SIZE_MAX ? 1u << QK_ERR_NOT_FOUND : wo_shape_errors(&sh);
  qk_status_t rc = qk_world_move(s->w, h, &sh);
  if (errs) {
    QKF_ASSERT(rc != QK_OK && (errs >> rc & 1), "move(%llx, kind %d, %a %a %a %a) = %d, want %#x",
               (unsigned long long)h, sh.kind, sh.x, sh.y, sh.a, sh.b, rc, errs);
    wo_check_objects(s, "a refused move");
    return;
  }
  QKF_ASSERT(rc == QK_OK, "move(kind %d, %a %a %a %a) = %d", sh.kind, sh.x, sh.y, sh.a, sh.b, rc);
  s->obj[i].s = wo_normalise(sh);
  s->obj[i].grid = wo_shape_grid(&sh);
}

static void wo_move_batch(wo_state_t *s) {
  enum { B = 4 };
  qk_handle_t h[B];
  qk_shape_t sh[B];
  size_t n = qkf_u8(&s->in) % (B + 1);
  for (size_t k = 0; k < n; k++) h[k] = wo_pick_handle(s), sh[k] = wo_shape(s);
  /* The first failing move, by the model. */
  size_t bad = n;
  unsigned errs = 0;
  for (size_t k = 0; k < n && bad == n; k++) {
    size_t i = wo_find(s, h[k]);
    errs = i == SIZE_MAX ? 1u << QK_ERR_NOT_FOUND : wo_shape_errors(&sh[k]);
    if (errs) bad = k;
  }
  qk_error_t err;
  memset(&err, 0x55, sizeof err);
  qk_status_t rc = qk_world_move_batch(s->w, h, sh, n, &err);
  if (bad < n) {
    QKF_ASSERT(rc != QK_OK && (errs >> rc & 1), "move_batch: move %zu should fail (%#x), got %d",
               bad, errs, rc);
    QKF_ASSERT(err.item == bad, "move_batch: err.item %zu, want %zu", err.item, bad);
    QKF_ASSERT(memchr(err.message, '\0', sizeof err.message) && err.message[0] != '\0',
               "move_batch: no message for a refused move");
  } else {
    QKF_ASSERT(rc == QK_OK, "move_batch of %zu valid moves = %d", n, rc);
  }
  for (size_t k = 0; k < bad; k++) {
    size_t i = wo_find(s, h[k]);
    s->obj[i].s = wo_normalise(sh[k]);
    s->obj[i].grid = wo_shape_grid(&sh[k]);
  }
  wo_check_objects(s, "move_batch");
}

static void wo_remove(wo_state_t *s) {
  qk_handle_t h = wo_pick_handle(s);
  size_t i = wo_find(s, h);
  qk_status_t rc = qk_world_remove(s->w, h);
  if (i == SIZE_MAX) {
    QKF_ASSERT(rc == QK_ERR_NOT_FOUND, "remove(unknown %llx) = %d", (unsigned long long)h, rc);
    wo_check_objects(s, "a refused remove");
    return;
  }
  QKF_ASSERT(rc == QK_OK, "remove(live) = %d", rc);
  if (s->n_stale < 16) s->stale[s->n_stale++] = h;
  s->obj[i] = s->obj[--s->n];
  QKF_ASSERT(qk_world_remove(s->w, h) == QK_ERR_NOT_FOUND, "removed twice");
}

static void wo_update(wo_state_t *s, int armed) {
  qk_status_t rc = qk_world_update(s->w);
  if (armed && rc == QK_ERR_NOMEM && s->alloc_state.failed) {
    wo_pairs_kept(s, "a failed update");
    wo_check_objects(s, "a failed update");
    return;
  }
  QKF_ASSERT(rc == QK_OK, "update = %d (%s)", rc, qk_strerror(rc));
  wo_check_objects(s, "update");
  wo_after_update(s);
}

static void wo_query(wo_state_t *s) {
  qk_shape_t sh = wo_shape(s);
  unsigned errs = wo_shape_errors(&sh);
  static qk_handle_t out[WO_MAX];
  size_t n = SIZE_MAX;
  qk_status_t rc = qk_world_query(s->w, &sh, out, WO_MAX, &n);
  if (errs) {
    QKF_ASSERT(rc != QK_OK && (errs >> rc & 1), "query(kind %d, %a %a %a %a) = %d, want %#x",
               sh.kind, sh.x, sh.y, sh.a, sh.b, rc, errs);
    return;
  }
  QKF_ASSERT(rc == QK_OK && n <= s->n, "query = %d, %zu of %zu objects", rc, n, s->n);
  for (size_t k = 0; k + 1 < n; k++)
    QKF_ASSERT(QK_HANDLE_SLOT(out[k]) < QK_HANDLE_SLOT(out[k + 1]), "query not by slot");
  if (wo_all_grid(s) && wo_shape_grid(&sh)) {
    qk_shape_t q = wo_normalise(sh);
    size_t want = 0;
    for (size_t i = 0; i < s->n; i++) {
      int ov = wo_overlap(&q, &s->obj[i].s), found = 0;
      want += ov;
      for (size_t k = 0; k < n; k++) found += out[k] == s->obj[i].h;
      QKF_ASSERT(found == ov,
                 "query (kind %d, %g %g %g %g) and object %zu (kind %d, %g %g %g %g): overlap %d, "
                 "found %d",
                 q.kind, q.x, q.y, q.a, q.b, i, s->obj[i].s.kind, s->obj[i].s.x, s->obj[i].s.y,
                 s->obj[i].s.a, s->obj[i].s.b, ov, found);
    }
    QKF_ASSERT(want == n, "query: %zu found, brute force %zu", n, want);
  }
  size_t cap = qkf_u8(&s->in) % 3, n2 = 0;
  qk_handle_t small[2];
  rc = qk_world_query(s->w, &sh, cap ? small : NULL, cap, &n2);
  QKF_ASSERT(rc == QK_OK && n2 == n, "short query: %d, %zu, want %zu", rc, n2, n);
  /* A short buffer holds some of the answer (sorted only when all fit). */
  for (size_t k = 0; k < cap && k < n; k++) {
    int found = 0;
    for (size_t j = 0; j < n; j++) found += out[j] == small[k];
    for (size_t j = 0; j < k; j++) found += small[j] == small[k] ? 2 : 0;
    QKF_ASSERT(found == 1, "short query: item %zu is not one of the answer's", k);
  }
}

static void wo_raycast(wo_state_t *s) {
  qk_point_t from = {wo_value(s), wo_value(s)}, to = {wo_value(s), wo_value(s)};
  static qk_world_hit_t out[WO_MAX];
  size_t n = SIZE_MAX;
  qk_status_t rc = qk_world_raycast_all(s->w, from, to, out, WO_MAX, &n);
  qk_shape_t seg = {QK_SHAPE_SEGMENT, from.x, from.y, to.x, to.y};
  unsigned errs = wo_shape_errors(&seg);
  if (errs) {
    QKF_ASSERT(rc != QK_OK, "raycast_all from (%a %a) to (%a %a) accepted", from.x, from.y, to.x,
               to.y);
    qk_world_hit_t one;
    QKF_ASSERT(qk_world_raycast(s->w, from, to, &one) != QK_OK, "raycast accepted a bad ray");
    return;
  }
  QKF_ASSERT(rc == QK_OK && n <= s->n, "raycast_all = %d, %zu hits", rc, n);
  for (size_t k = 0; k < n; k++) {
    QKF_ASSERT(out[k].t >= 0 && out[k].t <= 1, "raycast_all: t = %g", out[k].t);
    QKF_ASSERT(wo_find(s, out[k].h) != SIZE_MAX, "raycast_all: a dead handle");
    /* (ordered by t in long double: the doubles may tie in any slot order) */
    if (k) QKF_ASSERT(out[k - 1].t <= out[k].t, "raycast_all: hits out of order at %zu", k);
  }
  /* The hits are exactly the objects the segment touches: the same as a segment query. */
  static qk_handle_t q[WO_MAX];
  size_t nq = 0;
  QKF_ASSERT(qk_world_query(s->w, &seg, q, WO_MAX, &nq) == QK_OK && nq == n,
             "raycast_all: %zu hits, a segment query %zu objects", n, nq);
  for (size_t k = 0; k < nq; k++) {
    int found = 0;
    for (size_t j = 0; j < n; j++) found += out[j].h == q[k];
    QKF_ASSERT(found == 1, "raycast_all and the segment query disagree");
  }
  if (wo_all_grid(s) && wo_shape_grid(&seg)) {
    size_t want = 0;
    for (size_t i = 0; i < s->n; i++) want += wo_overlap(&seg, &s->obj[i].s);
    QKF_ASSERT(want == n, "raycast_all: %zu hits, brute force %zu", n, want);
  }
  qk_world_hit_t one, batch;
  QKF_ASSERT(qk_world_raycast(s->w, from, to, &one) == QK_OK, "raycast failed");
  if (n)
    QKF_ASSERT(one.h == out[0].h && one.t == out[0].t, "raycast differs from raycast_all's first");
  else
    QKF_ASSERT(one.h == QK_HANDLE_NONE && one.t == INFINITY, "raycast found a hit alone");
  QKF_ASSERT(qk_world_raycast_batch(s->w, &from, &to, 1, &batch) == QK_OK && batch.h == one.h &&
                 (batch.t == one.t),
             "raycast_batch differs from raycast");
  size_t cap = qkf_u8(&s->in) % 3, n2 = 0;
  qk_world_hit_t small[2];
  rc = qk_world_raycast_all(s->w, from, to, cap ? small : NULL, cap, &n2);
  QKF_ASSERT(rc == QK_OK && n2 == n, "short raycast_all: %d, %zu, want %zu", rc, n2, n);
  for (size_t k = 0; k < cap && k < n; k++) {
    int found = 0;
    for (size_t j = 0; j < n; j++) found += out[j].h == small[k].h && out[j].t == small[k].t;
    for (size_t j = 0; j < k; j++) found += small[j].h == small[k].h ? 2 : 0;
    QKF_ASSERT(found == 1, "short raycast_all: hit %zu is not one of the answer's", k);
  }
}

static void wo_knn(wo_state_t *s) {
  qk_point_t p = {wo_value(s), wo_value(s)};
  size_t k = qkf_u8(&s->in) % 6;
  static qk_world_hit_t out[8], batch[8];
  size_t n = SIZE_MAX, cnt = SIZE_MAX;
  qk_status_t rc = qk_world_knn(s->w, p, k, out, &n);
  qk_status_t rb = qk_world_knn_batch(s->w, &p, 1, k, batch, &cnt);
  if (!isfinite(p.x) || !isfinite(p.y)) {
    QKF_ASSERT(rc != QK_OK && rb != QK_OK, "knn accepted (%a %a)", p.x, p.y);
    return;
  }
  qk_shape_t pt = {QK_SHAPE_POINT, p.x, p.y, 0, 0};
  if (wo_shape_errors(&pt)) return; /* may be refused or answered */
  QKF_ASSERT(rc == QK_OK && rb == QK_OK, "knn = %d, knn_batch = %d", rc, rb);
  size_t want = k < s->n ? k : s->n;
  QKF_ASSERT(n == want && cnt == want, "knn: %zu (batch %zu), want %zu", n, cnt, want);
  for (size_t i = 0; i < n; i++) {
    QKF_ASSERT(out[i].t >= 0 && wo_find(s, out[i].h) != SIZE_MAX, "knn hit %zu", i);
    QKF_ASSERT(batch[i].h == out[i].h && batch[i].t == out[i].t, "knn_batch differs");
    if (i) QKF_ASSERT(out[i - 1].t <= out[i].t, "knn out of order");
  }
  /* On the grid, distance 0 exactly for the objects containing p: they come first. */
  if (!wo_all_grid(s) || !wo_shape_grid(&pt)) return;
  size_t nq = 0;
  qk_world_query(s->w, &pt, NULL, 0, &nq);
  for (size_t i = 0; i < n; i++)
    QKF_ASSERT((out[i].t == 0) == (i < nq), "knn: hit %zu at %g, %zu objects contain p", i,
               out[i].t, nq);
}

static void wo_make(wo_state_t *s) {
  qk_world_options_init(&s->opt);
  uint8_t o = qkf_u8(&s->in);
  s->opt.threads = o & 1 ? 2 : 1;
  s->opt.thread_min = o & 2 ? 0 : 4;
  static const double margins[] = {0.5, 0, 16, 0.01};
  s->opt.margin = margins[o >> 2 & 3];
  static const double mins[] = {0, 0.25, 0x1p-100, 1e20};
  s->opt.min_margin = mins[o >> 4 & 3];
  /* The counting allocator is not thread-safe: only with one thread. */
  s->use_alloc = s->opt.threads == 1;
  s->alloc = qkt_alloc_make(&s->alloc_state);
  s->opt.allocator = s->use_alloc ? &s->alloc : NULL;
  qk_status_t rc = qk_world_new(&s->opt, &s->w);
  QKF_ASSERT(rc == QK_OK, "world_new = %d", rc);
  s->n = s->n_stale = s->n_cur = s->n_prev = 0;
  s->updated = 0;
}

static void wo_free(wo_state_t *s) {
  qk_world_free(s->w);
  s->w = NULL;
  if (s->use_alloc)
    QKF_ASSERT(s->alloc_state.live_blocks == 0, "freeing the world left %zu blocks",
               s->alloc_state.live_blocks);
}

int qkf_world(const uint8_t *data, size_t size) {
  static wo_state_t s;
  memset(&s, 0, sizeof s);
  s.in = (qkf_bytes_t){data, size, 0};
  /* Refused options. */
  qk_world_options_t bad;
  qk_world_options_init(&bad);
  bad.threads = 257;
  qk_world_t *none = NULL;
  QKF_ASSERT(qk_world_new(&bad, &none) == QK_ERR_INVALID && none == NULL, "threads 257 accepted");
  bad.threads = 1;
  bad.margin = NAN;
  QKF_ASSERT(qk_world_new(&bad, &none) == QK_ERR_INVALID && none == NULL, "margin NaN accepted");
  wo_make(&s);
  for (int op = 0; op < WO_MAX_OPS && !qkf_done(&s.in); op++) {
    uint8_t code = qkf_u8(&s.in);
    int armed = 0;
    if (code >= 0xf0 && s.use_alloc) { /* fail the k-th allocation of an add or update */
      qkt_alloc_arm(&s.alloc_state, 1 + (code & 7));
      armed = 1;
      code = code & 8 ? 0 : 4;
    }
    switch (code % 11) {
    case 0:
    case 1:
      if (s.n < WO_MAX) wo_add(&s, armed);
      break;
    case 2:
      wo_move(&s);
      break;
    case 3:
      wo_remove(&s);
      break;
    case 4:
    case 5:
      wo_update(&s, armed);
      break;
    case 6:
      wo_query(&s);
      break;
    case 7:
      wo_raycast(&s);
      break;
    case 8:
      wo_knn(&s);
      break;
    case 9:
      wo_move_batch(&s);
      break;
    default:
      if (qkf_u8(&s.in) % 8 == 0) { /* free and start again */
        wo_free(&s);
        wo_make(&s);
      } else {
        QKF_ASSERT(qk_world_pairs_list(s.w, (qk_pairs_which_t)3, NULL, 0, &(size_t){0}) ==
                       QK_ERR_INVALID,
                   "pairs_list(which 3) accepted");
        wo_check_objects(&s, "a check");
      }
      break;
    }
    if (armed) qkt_alloc_arm(&s.alloc_state, 0);
  }
  wo_free(&s);
  return 0;
}

#ifndef QKF_REPLAY
int LLVMFuzzerTestOneInput(const uint8_t *data, size_t size);
int LLVMFuzzerTestOneInput(const uint8_t *data, size_t size) { return qkf_world(data, size); }
#endif
