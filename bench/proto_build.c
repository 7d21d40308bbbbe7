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

typedef struct {
  uint64_t code;
  uint32_t id;
  uint32_t pad;
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

static void radix16(item_t *a, item_t *tmp, size_t n, int shift) {
  static uint32_t cnt[65536];
  memset(cnt, 0, sizeof cnt);
  for (size_t i = 0; i < n; i++) cnt[(a[i].code >> shift) & 0xFFFF]++;
  uint32_t sum = 0;
  for (int d = 0; d < 65536; d++) {
    uint32_t c = cnt[d];
    cnt[d] = sum;
    sum += c;
  }
  for (size_t i = 0; i < n; i++) tmp[cnt[(a[i].code >> shift) & 0xFFFF]++] = a[i];
}

static int cmp_item(const void *x, const void *y) {
  uint64_t a = ((const item_t *)x)->code, b = ((const item_t *)y)->code;
  return a < b ? -1 : a > b;
}

/* First index in [lo, hi) whose code is >= key. */
static size_t lower(const item_t *a, size_t lo, size_t hi, uint64_t key) {
  while (lo < hi) {
    size_t m = lo + (hi - lo) / 2;
    if (a[m].code < key)
      lo = m + 1;
    else
      hi = m;
  }
  return lo;
}

typedef struct {
  pnode_t *nodes;
  size_t n_nodes, cap_nodes;
  size_t leaves;
  const item_t *a;
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

/* Quadrant digit order in a Morton code with y in the odd bits: 0 SW, 1 SE, 2 NW, 3 NE. */
static void build_node(builder_t *b, uint32_t v, size_t lo, size_t hi, unsigned depth) {
  b->nodes[v].start = (uint32_t)lo;
  b->nodes[v].count = (uint32_t)(hi - lo);
  b->nodes[v].depth = depth;
  b->nodes[v].first_child = UINT32_MAX;
  if (hi - lo <= b->capacity || depth >= 32) {
    b->leaves++;
    return;
  }
  uint32_t c = new_nodes(b, 4);
  b->nodes[v].first_child = c;
  unsigned sh = 2 * (31 - depth);
  uint64_t base = b->a[lo].code & ~((sh + 2 >= 64 ? ~0ull : ((1ull << (sh + 2)) - 1)));
  size_t cut[5];
  cut[0] = lo;
  for (unsigned q = 1; q < 4; q++) cut[q] = lower(b->a, cut[q - 1], hi, base | ((uint64_t)q << sh));
  cut[4] = hi;
  for (unsigned q = 0; q < 4; q++) build_node(b, c + q, cut[q], cut[q + 1], depth + 1);
}

/*
 * Build over n points (xy interleaved) and free everything again; returns the seconds the
 * build took and reports the leaf count and the bytes the result held.
 */
double qkb_proto_build(const double *xy, size_t n, unsigned capacity, size_t *leaves,
                       size_t *bytes) {
  struct timespec t0, t1;
  clock_gettime(CLOCK_MONOTONIC, &t0);
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

  /* (2) codes. */
  item_t *a = malloc((n ? n : 1) * sizeof *a), *tmp = malloc((n ? n : 1) * sizeof *tmp);
  for (size_t i = 0; i < n; i++) {
    uint32_t cx = cell_of(xy[2 * i], xmin, scale), cy = cell_of(xy[2 * i + 1], ymin, scale);
    a[i].code = spread32(cx) | (spread32(cy) << 1);
    a[i].id = (uint32_t)i;
  }
  /* (3) radix sort on bits 32..63, then finish long runs on the low bits. */
  radix16(a, tmp, n, 32);
  radix16(tmp, a, n, 48);
  for (size_t i = 0; i < n;) {
    size_t j = i + 1;
    while (j < n && (a[j].code >> 32) == (a[i].code >> 32)) j++;
    if (j - i > capacity) qsort(a + i, j - i, sizeof *a, cmp_item);
    i = j;
  }
  /* (4) the tree. */
  builder_t b = {NULL, 0, 0, 0, a, capacity};
  new_nodes(&b, 1);
  build_node(&b, 0, 0, n, 0);
  /* (5) coordinates in leaf order. */
  double *px = malloc((n ? n : 1) * sizeof *px), *py = malloc((n ? n : 1) * sizeof *py);
  uint32_t *pid = malloc((n ? n : 1) * sizeof *pid);
  for (size_t i = 0; i < n; i++) {
    uint32_t id = a[i].id;
    px[i] = xy[2 * id];
    py[i] = xy[2 * id + 1];
    pid[i] = id;
  }
  clock_gettime(CLOCK_MONOTONIC, &t1);
  *leaves = b.leaves;
  *bytes = n * (2 * sizeof(double) + sizeof(uint32_t)) + b.n_nodes * sizeof(pnode_t);
  free(a);
  free(tmp);
  free(b.nodes);
  free(px);
  free(py);
  free(pid);
  return (double)(t1.tv_sec - t0.tv_sec) + 1e-9 * (double)(t1.tv_nsec - t0.tv_nsec);
}
