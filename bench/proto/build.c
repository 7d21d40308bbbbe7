/*
 * Prototype, not library code: a bulk build of the same point-region quadtree as
 * qk_tree_build() (same root, same leaves) by sorting Morton codes with a radix sort and
 * cutting the sorted array into leaves. It exists to measure what the technique buys
 * before anyone moves it into index/; quadkit-bench times it next to the library
 * ("proto-morton") and checks that its leaf count equals the library's.
 *
 * Steps: (1) the root square, as qk_tree_build() derives it; (2) a 64-bit Morton code
 * per point (32 levels), computed so that a coordinate exactly on a split line goes to
 * the west/south half as the library's tie rule says; (3) an LSD radix sort of
 * (code, id) on the top 32 bits in two 16-bit passes; runs that still share those 32
 * bits and exceed the capacity are sorted further on the low bits; (4) a top-down pass
 * that splits a range while it holds more than `capacity` points, finding the four
 * children's sub-ranges by binary search on the code; (5) the coordinates gathered
 * into leaf order as x[] and y[] arrays.
 */
#define _POSIX_C_SOURCE 199309L
#include <math.h>
#include <stdint.h>
#include <stdlib.h>
#include <string.h>
#include <time.h>

/* The sort key is the top 32 bits of the Morton code (16 levels); the full 64-bit code
 * is recomputed only for the rare runs that share those 32 bits and exceed capacity. */
typedef struct {
  uint32_t key;
  uint32_t id;
} item_t;

typedef struct {
  uint32_t first_child; /* index of the first of four children, or UINT32_MAX */
  uint32_t start, count;
  uint32_t depth;
} pnode_t;

static uint64_t spread32(uint32_t v) {
  uint64_t x = v;
  x = (x | (x << 16)) & 0x0000FFFF0000FFFFull;
  x = (x | (x << 8)) & 0x00FF00FF00FF00FFull;
  x = (x | (x << 4)) & 0x0F0F0F0F0F0F0F0Full;
  x = (x | (x << 2)) & 0x3333333333333333ull;
  x = (x | (x << 1)) & 0x5555555555555555ull;
  return x;
}

/* The cell of coordinate v along one axis at 32 levels: the largest i with
 * x0 + i * cell < v, so that v on a boundary goes to the lower cell (the library's
 * "east when x > xmid"). */
static uint32_t cell_of(double v, double x0, double scale) {
  double f = (v - x0) * scale; /* scale = 2^32 / side */
  if (!(f > 0)) return 0;
  double c = ceil(f) - 1;
  if (c >= 4294967295.0) return 4294967295u;
  return (uint32_t)c;
}

/* One LSD radix pass on 11 bits of the key: 2048 buckets keep the scatter's write
 * streams few enough for the caches. */
static void radix11(const item_t *a, item_t *out, size_t n, int shift) {
  uint32_t cnt[2048];
  memset(cnt, 0, sizeof cnt);
  for (size_t i = 0; i < n; i++) cnt[(a[i].key >> shift) & 0x7FF]++;
  uint32_t sum = 0;
  for (int d = 0; d < 2048; d++) {
    uint32_t c = cnt[d];
    cnt[d] = sum;
    sum += c;
  }
  for (size_t i = 0; i < n; i++) out[cnt[(a[i].key >> shift) & 0x7FF]++] = a[i];
}

typedef struct {
  uint64_t code;
  uint32_t id;
} full_t;

static int cmp_full(const void *x, const void *y) {
  uint64_t a = ((const full_t *)x)->code, b = ((const full_t *)y)->code;
  return a < b ? -1 : a > b;
}

typedef struct {
  pnode_t *nodes;
  size_t n_nodes, cap_nodes;
  size_t leaves;
  const item_t *a;  /* sorted by the 32-bit key */
  uint64_t *code64; /* full codes, filled only inside runs that need them */
  double *px, *py;  /* coordinates in sorted order */
  uint32_t *pid;
  double x0, y0, scale;
  unsigned capacity;
} builder_t;

static uint32_t new_nodes(builder_t *b, unsigned k) {
  if (b->n_nodes + k > b->cap_nodes) {
    b->cap_nodes = 2 * b->cap_nodes + k + 64;
    b->nodes = realloc(b->nodes, b->cap_nodes * sizeof *b->nodes);
  }
  uint32_t r = (uint32_t)b->n_nodes;
  b->n_nodes += k;
  return r;
}

/* A run sharing its 32-bit key and holding more than `capacity` points: compute the full
 * codes and sort the run's coordinates by them (insertion-free: sort an index). */
static void deepen(builder_t *b, size_t lo, size_t hi) {
  size_t m = hi - lo;
  full_t *f = malloc(m * sizeof *f);
  for (size_t i = 0; i < m; i++) {
    uint32_t cx = cell_of(b->px[lo + i], b->x0, b->scale);
    uint32_t cy = cell_of(b->py[lo + i], b->y0, b->scale);
    f[i].code = spread32(cx) | (spread32(cy) << 1);
    f[i].id = (uint32_t)i;
  }
  qsort(f, m, sizeof *f, cmp_full);
  double *tx = malloc(m * sizeof *tx), *ty = malloc(m * sizeof *ty);
  uint32_t *ti = malloc(m * sizeof *ti);
  for (size_t i = 0; i < m; i++) {
    tx[i] = b->px[lo + f[i].id];
    ty[i] = b->py[lo + f[i].id];
    ti[i] = b->pid[lo + f[i].id];
    b->code64[lo + i] = f[i].code;
  }
  memcpy(b->px + lo, tx, m * sizeof *tx);
  memcpy(b->py + lo, ty, m * sizeof *ty);
  memcpy(b->pid + lo, ti, m * sizeof *ti);
  free(f);
  free(tx);
  free(ty);
  free(ti);
}

static inline uint64_t code_at(const builder_t *b, size_t i, unsigned depth) {
  return depth < 16 ? (uint64_t)b->a[i].key << 32 : b->code64[i];
}

/* First index in [lo, hi) whose code is >= key. */
static size_t lower(const builder_t *b, size_t lo, size_t hi, uint64_t key, unsigned depth) {
  while (lo < hi) {
    size_t m = lo + (hi - lo) / 2;
    if (code_at(b, m, depth) < key)
      lo = m + 1;
    else
      hi = m;
  }
  return lo;
}

/* Quadrant digit order in a Morton code with y in the odd bits: 0 SW, 1 SE, 2 NW, 3 NE
 * (the prototype's own order; only the leaf count is compared with the library). */
static void build_node(builder_t *b, uint32_t v, size_t lo, size_t hi, unsigned depth) {
  b->nodes[v].start = (uint32_t)lo;
  b->nodes[v].count = (uint32_t)(hi - lo);
  b->nodes[v].depth = depth;
  b->nodes[v].first_child = UINT32_MAX;
  if (hi - lo <= b->capacity || depth >= 32) {
    b->leaves++;
    return;
  }
  if (depth == 16) {
    if (!b->code64) b->code64 = malloc(b->n_nodes ? (size_t)b->nodes[0].count * 8 : 8);
    deepen(b, lo, hi);
  }
  uint32_t c = new_nodes(b, 4);
  b->nodes[v].first_child = c;
  unsigned sh = 2 * (31 - depth);
  uint64_t base = code_at(b, lo, depth) & ~((sh + 2 >= 64 ? ~0ull : ((1ull << (sh + 2)) - 1)));
  size_t cut[5];
  cut[0] = lo;
  for (unsigned q = 1; q < 4; q++)
    cut[q] = lower(b, cut[q - 1], hi, base | ((uint64_t)q << sh), depth);
  cut[4] = hi;
  for (unsigned q = 0; q < 4; q++) build_node(b, c + q, cut[q], cut[q + 1], depth + 1);
}

static double secs(struct timespec a, struct timespec b) {
  return (double)(b.tv_sec - a.tv_sec) + 1e-9 * (double)(b.tv_nsec - a.tv_nsec);
}

/* Phase times of the last build, for the report (codes, sort, gather, tree). */
double qkb_proto_phase[4];

/*
 * Build over n points (xy interleaved) and free everything again; returns the seconds the
 * build took and reports the leaf count and the bytes the result held.
 */
double qkb_proto_build(const double *xy, size_t n, unsigned capacity, size_t *leaves,
                       size_t *bytes) {
  struct timespec t0, t1, t2, t3, t4;
  clock_gettime(CLOCK_PROCESS_CPUTIME_ID, &t0);
  if (capacity == 0) capacity = 1;
  /* (1) the root square, exactly as the library's smallest enclosing square. */
  double xmin = n ? xy[0] : 0, xmax = xmin, ymin = n ? xy[1] : 0, ymax = ymin;
  for (size_t i = 1; i < n; i++) {
    double x = xy[2 * i], y = xy[2 * i + 1];
    xmin = x < xmin ? x : xmin;
    xmax = x > xmax ? x : xmax;
    ymin = y < ymin ? y : ymin;
    ymax = y > ymax ? y : ymax;
  }
  double side = fmax(xmax - xmin, ymax - ymin);
  if (!(side > 0)) side = 1;
  while (xmin + side < xmax || ymin + side < ymax) side = nextafter(side, INFINITY);
  double scale = 4294967296.0 / side;

  /* (2) 32-bit keys: the top 16 levels of the Morton code. */
  size_t nn = n ? n : 1;
  item_t *a = malloc(nn * sizeof *a), *tmp = malloc(nn * sizeof *tmp);
  if (!a || !tmp) {
    free(a);
    free(tmp);
    *leaves = *bytes = 0;
    return -1;
  }
  a[0].key = 0; /* n may be 0; keeps the first slot defined for the sort's reads */
  a[0].id = 0;
  for (size_t i = 0; i < n; i++) {
    uint32_t cx = cell_of(xy[2 * i], xmin, scale), cy = cell_of(xy[2 * i + 1], ymin, scale);
    a[i].key = (uint32_t)((spread32(cx >> 16) | (spread32(cy >> 16) << 1)));
    a[i].id = (uint32_t)i;
  }
  clock_gettime(CLOCK_PROCESS_CPUTIME_ID, &t1);
  /* (3) LSD radix sort, three 11-bit passes (33 >= 32 bits). */
  radix11(a, tmp, n, 0);
  radix11(tmp, a, n, 11);
  radix11(a, tmp, n, 22);
  item_t *sorted = tmp;
  clock_gettime(CLOCK_PROCESS_CPUTIME_ID, &t2);
  /* (4) coordinates in sorted order. */
  double *px = malloc(nn * sizeof *px), *py = malloc(nn * sizeof *py);
  uint32_t *pid = malloc(nn * sizeof *pid);
  for (size_t i = 0; i < n; i++) {
    uint32_t id = sorted[i].id;
    px[i] = xy[2 * id];
    py[i] = xy[2 * id + 1];
    pid[i] = id;
  }
  clock_gettime(CLOCK_PROCESS_CPUTIME_ID, &t3);
  /* (5) the tree, splitting while a range holds more than `capacity` points. */
  builder_t b = {NULL, 0, 0, 0, sorted, NULL, px, py, pid, xmin, ymin, scale, capacity};
  new_nodes(&b, 1);
  b.nodes[0].count = (uint32_t)n;
  build_node(&b, 0, 0, n, 0);
  clock_gettime(CLOCK_PROCESS_CPUTIME_ID, &t4);
  qkb_proto_phase[0] = secs(t0, t1);
  qkb_proto_phase[1] = secs(t1, t2);
  qkb_proto_phase[2] = secs(t2, t3);
  qkb_proto_phase[3] = secs(t3, t4);
  *leaves = b.leaves;
  *bytes = n * (2 * sizeof(double) + sizeof(uint32_t)) + b.n_nodes * sizeof(pnode_t);
  free(a);
  free(tmp);
  free(b.nodes);
  free(b.code64);
  free(px);
  free(py);
  free(pid);
  return secs(t0, t4);
}
