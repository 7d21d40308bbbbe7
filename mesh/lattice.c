/*
 * The lattice the mesher works on. The book's algorithm needs integer vertices; an input
 * whose coordinates are dyadic rationals (k / 2^f, as every double is, though f may be
 * large) lies on the lattice of spacing 2^-f, and the algorithm runs unchanged on the
 * lattice coordinates X = (x - x0) 2^f. Nothing is rounded anywhere:
 *  - x - x0 is a multiple of 2^-f below 2^30 2^-f, so it is a double and the subtraction
 *    exact; multiplying by 2^f is exact;
 *  - back, a mesh vertex is a multiple of 2^-(f+1) (a half-lattice point) of magnitude
 *    below 2^52 2^-(f+1) (checked here), so X 2^-f + x0 is a double and the sum exact;
 *    input vertices come back bit-identical.
 * When no lattice with at most 2^30 points per side holds every vertex (coordinates such
 * as 0.1, whose nearest double needs 2^-56 spacing, next to a range of 1), the input is
 * rejected naming the vertex that needs the finest spacing: there is no exact placement
 * to offer, and rounding would break the promise that input vertices come back as given.
 */
#include "mesh/mesh_internal.h"

#include <limits.h>
#include <math.h>
#include <string.h>

/* Fractional binary digits of a finite double (0 for integers). */
/* The binary fraction digits of c: the least f with c 2^f an integer, negative for
 * multiples of 2^1 and above (INT_MIN for 0, a multiple of every power of two). */
static int lattice_bits(double c) {
  if (c == 0) return INT_MIN;
  int e;
  double m = frexp(c, &e);                   /* c = m 2^e, 0.5 <= |m| < 1 */
  uint64_t M = (uint64_t)fabs(ldexp(m, 53)); /* c = +-M 2^(e-53), M an integer */
  int tz = 0;
  while (!(M & 1)) M >>= 1, tz++;
  return 53 - e - tz;
}

static int frac_bits(double c) {
  int bits = lattice_bits(c);
  return bits > 0 ? bits : 0;
}

double qk__mesh_lattice_steps(const qk_poly_t *P, int f, size_t *longest) {
  double steps = 0, most = -1;
  for (size_t s = 0; s < P->ns; s++) {
    uint32_t a = P->seg[2 * s], b = P->seg[2 * s + 1];
    double n = ldexp(fmax(fabs(P->vx[a] - P->vx[b]), fabs(P->vy[a] - P->vy[b])), f);
    steps += n;
    if (longest && n > most) most = n, *longest = s;
  }
  return steps;
}

qk_status_t qk__mesh_book_limit(const qk_poly_t *P, const qk_mesh_options_t *opt, uint64_t U,
                                qk_mesh_error_t *err) {
  if (!U) { /* the default domain: the smallest power of two >= every coordinate */
    double most = 1;
    for (size_t i = 0; i < P->nv; i++) most = fmax(most, fmax(P->vx[i], P->vy[i]));
    for (U = 1; (double)U < most;) U *= 2;
  }
  size_t k = 0;
  double steps = qk__mesh_lattice_steps(P, 0, &k), u = (double)U;
  double by_size = opt->max_size > 0 ? 4 * (u / opt->max_size) * (u / opt->max_size) : 0;
  if (!(steps > QK__MESH_MAX_STEPS || by_size > QK__MESH_MAX_STEPS)) return QK_OK;
  if (!(steps > QK__MESH_MAX_STEPS) || !P->ns)
    return qk__mesh_fail(err, QK_ERR_LIMIT, 0,
                         "max_size %.17g asks the book's mode for about %.3g triangles in the "
                         "domain of side %llu (at most %.3g): use a larger size bound or the "
                         "general mode (--general, QK_MESH_GENERAL)",
                         opt->max_size, by_size, (unsigned long long)U, (double)QK__MESH_MAX_STEPS);
  uint32_t a = P->seg[2 * k], b = P->seg[2 * k + 1];
  /* (Within the 255 characters of a message: the line names the segment.) */
  return qk__mesh_fail(err, QK_ERR_LIMIT, P->sline ? P->sline[k] : 0,
                       "the book's mode would need %.3g unit steps along the segments (at most "
                       "%.3g; segment %lu alone %.3g): it splits every cell along a segment to "
                       "unit size. Use the general mode (--general, QK_MESH_GENERAL) or scale "
                       "the input down",
                       steps, (double)QK__MESH_MAX_STEPS, qk__mesh_num(P, k),
                       fmax(fabs(P->vx[a] - P->vx[b]), fabs(P->vy[a] - P->vy[b])));
}

qk_status_t qk__mesh_lattice(const qk_poly_t *P, const qk_mesh_options_t *opt, int book,
                             qk__lattice_t *L, qk_mesh_error_t *err) {
  memset(L, 0, sizeof *L);
  if (book) return QK_OK;
  if (P->nv == 0) return QK_OK;
  int f = 0, coarse = INT_MIN; /* coarse: the coarsest lattice holding every vertex */
  size_t finest = 0;
  double minx = P->vx[0], miny = P->vy[0], maxx = minx, maxy = miny;
  for (size_t i = 0; i < P->nv; i++) {
    int b = frac_bits(P->vx[i]), c = frac_bits(P->vy[i]);
    if (b > f || c > f) f = b > c ? b : c, finest = i;
    int lb = lattice_bits(P->vx[i]), lc = lattice_bits(P->vy[i]);
    coarse = lb > coarse ? lb : coarse, coarse = lc > coarse ? lc : coarse;
    minx = fmin(minx, P->vx[i]), maxx = fmax(maxx, P->vx[i]);
    miny = fmin(miny, P->vy[i]), maxy = fmax(maxy, P->vy[i]);
  }
  double range = fmax(maxx - minx, maxy - miny);
  /* Integer input too wide for the unit lattice, on a coarser one (multiples of 2^k,
   * k > 0): that lattice (f = -k), so that it is meshed with its proven angles rather
   * than refused (or sent to the general mode). Where the unit lattice fits, f stays 0:
   * meshes made before are unchanged. */
  if (f == 0 && coarse < 0 && !(range <= (double)QK_MESH_MAX_SIZE))
    f = coarse > -1000 ? coarse : -1000;
  /* A unit square's diagonal, sqrt(2) 2^-f, is its longest possible edge. */
  int fv = f;
  if (opt->max_size > 0)
    while (f < 1100 && ldexp(1.0, -f) * 1.4142135623730951 > opt->max_size) f++;
  if (f > fv && !(ldexp(range, f) <= (double)QK_MESH_MAX_SIZE))
    return qk__mesh_fail(err, QK_ERR_LIMIT, 0,
                         "max_size %.17g needs a lattice of spacing 2^%d, and the input's extent "
                         "%.17g would span more than 2^30 such steps",
                         opt->max_size, -f, range);
  if (!(ldexp(range, f) <= (double)QK_MESH_MAX_SIZE))
    return qk__mesh_fail(err, QK_ERR_GEOMETRY, P->vline[finest],
                         "vertex %lu: (%.17g, %.17g) needs a lattice of spacing 2^%d, and the "
                         "input's extent %.17g would span more than 2^30 such steps (no exact "
                         "placement exists; see docs/mesh.md)",
                         qk__mesh_num(P, finest), P->vx[finest], P->vy[finest], -f, range);
  uint64_t U = 1;
  while ((double)U < ldexp(range, f)) U *= 2;
  double ext = ldexp((double)U, -f);
  double big = fmax(fmax(fabs(minx), fabs(minx + ext)), fmax(fabs(miny), fabs(miny + ext)));
  if (!(ldexp(big, f + 1) < 0x1p52))
    return qk__mesh_fail(err, QK_ERR_GEOMETRY, P->vline[finest],
                         "vertex %lu: (%.17g, %.17g) needs a lattice of spacing 2^%d, too fine "
                         "for a double at magnitude %.17g (no exact placement exists; see "
                         "docs/mesh.md)",
                         qk__mesh_num(P, finest), P->vx[finest], P->vy[finest], -f, big);
  /* The book's step 1 splits every square along the segments down to unit size, so the
   * mesh has a few triangles per lattice step of boundary; a size bound gives about
   * 4 (extent / H)^2. Refuse what could not fit in memory rather than try. */
  double steps = qk__mesh_lattice_steps(P, f, NULL);
  double by_size = opt->max_size > 0 ? 4 * (range / opt->max_size) * (range / opt->max_size) : 0;
  if (steps > QK__MESH_MAX_STEPS || by_size > QK__MESH_MAX_STEPS)
    return qk__mesh_fail(err, QK_ERR_LIMIT, P->vline[finest],
                         "the dyadic mode would need %.3g lattice steps of 2^%d along the "
                         "segments and about %.3g triangles for the size bound (at most %.3g): "
                         "vertex %lu (%.17g, %.17g) needs the finest spacing; round the input "
                         "to fewer binary digits (see docs/mesh.md)",
                         steps, -f, by_size, (double)QK__MESH_MAX_STEPS, qk__mesh_num(P, finest),
                         P->vx[finest], P->vy[finest]);
  L->f = f, L->x0 = minx, L->y0 = miny;
  return QK_OK;
}

qk_status_t qk__mesh_lattice_poly(const qk_poly_t *P, const qk__lattice_t *L,
                                  const qk_allocator_t *a, qk_poly_t **out) {
  qk_poly_t *q = qk__realloc(a, NULL, 0, sizeof *q);
  if (!q) return QK_ERR_NOMEM;
  memset(q, 0, sizeof *q);
  q->alloc = *a;
  q->first_index = P->first_index;
  size_t nv = P->nv ? P->nv : 1, ns = P->ns ? P->ns : 1, nh = P->nh ? P->nh : 1;
  q->vx = qk__realloc(a, NULL, 0, nv * sizeof *q->vx), q->cap.v = nv;
  q->vy = qk__realloc(a, NULL, 0, nv * sizeof *q->vy), q->cap.vy = nv;
  q->seg = qk__realloc(a, NULL, 0, 2 * ns * sizeof *q->seg), q->cap.s = ns;
  q->hx = qk__realloc(a, NULL, 0, nh * sizeof *q->hx), q->cap.h = nh;
  q->hy = qk__realloc(a, NULL, 0, nh * sizeof *q->hy), q->cap.hy = nh;
  if (!q->vx || !q->vy || !q->seg || !q->hx || !q->hy) {
    qk__mesh_lattice_poly_free(q);
    return QK_ERR_NOMEM;
  }
  q->nv = P->nv, q->ns = P->ns, q->nh = P->nh;
  for (size_t i = 0; i < P->nv; i++)
    q->vx[i] = ldexp(P->vx[i] - L->x0, L->f), q->vy[i] = ldexp(P->vy[i] - L->y0, L->f);
  /* Hole and region points need no exactness beyond their side of the segments; a point
   * within rounding distance of a segment may be placed on it (and is then rejected). */
  for (size_t i = 0; i < P->nh; i++)
    q->hx[i] = ldexp(P->hx[i] - L->x0, L->f), q->hy[i] = ldexp(P->hy[i] - L->y0, L->f);
  if (P->ns) memcpy(q->seg, P->seg, 2 * P->ns * sizeof *q->seg);
  /* Line numbers, markers and regions are read from the original (g->src). */
  q->vline = P->vline, q->sline = P->sline, q->hline = P->hline;
  q->cap.vl = q->cap.sl = q->cap.hl = 0;
  *out = q;
  return QK_OK;
}

void qk__mesh_lattice_poly_free(qk_poly_t *q) {
  if (!q) return;
  q->vline = q->sline = q->hline = NULL; /* borrowed from the original */
  qk_poly_free(q);
}

/* A large input is checked for crossings, vertices on segments and duplicates exactly
 * and in O(n log n) (the general mode's CDT of the input) before the subdivision, which
 * would find them only after work proportional to the lattice steps. Only its geometric
 * refusals count: an input the CDT's predicates cannot take (an extent below 2^-200, on
 * a fine dyadic lattice) is left to the subdivision, as before. Smaller inputs are not
 * checked twice, so their messages are the subdivision's, unchanged. */
qk_status_t qk__mesh_precheck(const qk_poly_t *lat, const qk_poly_t *src,
                              const qk_mesh_options_t *opt, uint64_t book_U, qk_allocator_t *a,
                              qk_mesh_error_t *err) {
  qk_status_t st;
  if (book_U && (st = qk__mesh_book_limit(src, opt, book_U, err))) return st;
  if (!(qk__mesh_lattice_steps(lat, 0, NULL) > QK__MESH_PRECHECK_STEPS)) return QK_OK;
  qk_mesh_error_t e;
  st = qk__mesh_general_check(src, opt, a, &e);
  if (st == QK_ERR_GEOMETRY || st == QK_ERR_NOMEM) {
    if (err) *err = e;
    return st;
  }
  return QK_OK;
}
