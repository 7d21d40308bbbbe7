/*
 * Reading Triangle's `.poly` format (a planar straight-line graph): a vertex section, a
 * segment section, an optional hole section and optional regional attributes. Only the
 * syntax is checked here; qk_mesh_generate() checks the geometry, using the line
 * numbers recorded for every vertex, segment and hole.
 */
#include "mesh/mesh_internal.h"
#include "index/textloc.h"

#include <errno.h>
#include <limits.h>
#include <math.h>
#include <stdarg.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

/* Counts beyond this are rejected as absurd before anything is allocated for them. */
#define POLY_MAX_COUNT (1ul << 26)
/* Vertex attributes per line beyond this are rejected as absurd. */
#define POLY_MAX_ATTRIBUTES 1000ul
/* A line longer than this is refused (the command-line tool's limit for a line of text
 * input): a row holds at most a number, two coordinates, POLY_MAX_ATTRIBUTES attributes
 * and a marker, some 25 KB, and without a limit an endless line (a pipe from `yes | tr -d
 * '\n'`, a file without line breaks) was taken into memory until it ran out. */
#define POLY_MAX_LINE 1048576ul
/* The tokens of a line that are kept: the most a row may hold (a vertex's number,
 * coordinates, attributes and marker); a row with more is refused by its count. */
#define POLY_MAX_TOKENS (4 + POLY_MAX_ATTRIBUTES)

/* A line reader that strips `#` comments and splits on blanks, skipping empty lines. */
typedef struct reader {
  FILE *f;
  const qk_allocator_t *a;
  char *buf;
  size_t cap;
  unsigned long line;
  char *tok[POLY_MAX_TOKENS]; /* the first tokens of the current line */
  size_t ntok;                /* tokens on the line (may exceed those kept) */
  int io_error;
  /* The section whose rows are being read (or were read last): its name, declared row
   * count and header line, for the hint when the rows do not match the count. */
  const char *sec;
  unsigned long sec_n, sec_line;
  size_t sec_fields; /* the fewest fields a row of that section has */
  char hint[128];
  size_t comma_tok; /* next_line's -5 */
} reader_t;

/* Read the next line holding a token. Returns 1, 0 at end of input, -1 out of memory,
 * -2 for a NUL byte (binary data, which no text format holds), -3 for a carriage return
 * not followed by a line feed (CR-only line ends would read as one long line), -4 for a
 * line longer than POLY_MAX_LINE (reading stops there), -5 for a decimal comma (tokens
 * comma_tok - 1 and comma_tok). */
static int next_line(reader_t *r) {
  for (;;) {
    size_t n = 0;
    int c;
    int any = 0;
    while ((c = getc(r->f)) != EOF) {
      any = 1;
      if (c == '\n') break;
      if (c == '\0') {
        r->line++;
        return -2;
      }
      if (c == '\r') {
        int d = getc(r->f);
        if (d != '\n' && d != EOF) {
          r->line++;
          return -3;
        }
        break; /* CR LF (or a CR ending the input) ends the line; the CR is not counted */
      }
      if (n == POLY_MAX_LINE) {
        r->line++;
        return -4;
      }
      if (n + 2 > r->cap) {
        void *p = r->buf;
        if (qk__grow(r->a, &p, &r->cap, n + 2, 1)) return -1;
        r->buf = p;
      }
      r->buf[n++] = (char)c;
    }
    if (ferror(r->f)) r->io_error = 1;
    if (!any) return 0;
    r->line++;
    if (!r->buf) continue; /* an empty line before any buffer exists */
    r->buf[n] = '\0';
    char *hash = strchr(r->buf, '#');
    if (hash) *hash = '\0';
    r->ntok = 0;
    char *s = r->buf;
    /* A UTF-8 byte order mark opening the file (Windows editors write one) is not text. */
    if (r->line == 1 && !strncmp(s, "\xEF\xBB\xBF", 3)) s += 3;
    /* Fields are separated by blanks, commas or both. A comma alone between two digits in
     * a row whose other fields are separated by blanks is a decimal comma ("3 0,5 4" read
     * as x = 0, y = 5 and a boundary marker 4, meshed without a word): refused. */
    int blank_sep = 0;
    size_t tight = 0; /* the token after such a comma (0: none) */
    char cut = 0;     /* the separator overwritten by the last token's end */
    for (;;) {
      int commas = cut == ',', blanks = cut && cut != ',';
      for (; *s == ' ' || *s == '\t' || *s == '\r' || *s == ','; s++) {
        if (*s == ',')
          commas++;
        else
          blanks = 1;
      }
      if (!*s) break;
      if (r->ntok > 0 && !commas) blank_sep = 1;
      if (r->ntok > 0 && commas == 1 && !blanks && !tight && s[-2] >= '0' && s[-2] <= '9' &&
          *s >= '0' && *s <= '9')
        tight = r->ntok;
      if (r->ntok < POLY_MAX_TOKENS) r->tok[r->ntok] = s;
      r->ntok++;
      while (*s && *s != ' ' && *s != '\t' && *s != '\r' && *s != ',') s++;
      cut = *s;
      if (*s) *s++ = '\0';
    }
    if (tight && blank_sep && tight < POLY_MAX_TOKENS) {
      r->comma_tok = tight;
      return -5;
    }
    if (r->ntok > 0) return 1;
  }
}

/* Whether a number's text has a nonzero digit before its exponent (it is not zero). */
static int nonzero_digits(const char *s) {
  for (; *s && *s != 'e' && *s != 'E'; s++)
    if (*s >= '1' && *s <= '9') return 1;
  return 0;
}

/* Parse a whole token as a finite decimal number (strtod's hexadecimal forms, 0x10 or
 * 0x1p-3, are refused as the CSV readers refuse them). */
static int parse_num(const char *s, double *v) {
  char *end;
  const char *digits = s + (*s == '+' || *s == '-');
  if (digits[0] == '0' && (digits[1] | 0x20) == 'x') return 0;
  errno = 0;
  double d = qk__strtod(s, &end);
  if (end == s || *end || !isfinite(d) || (d == 0 && nonzero_digits(s))) return 0;
  *v = d;
  return 1;
}

/* Why parse_num refused S, for the message: "" when S is simply not a number. */
static const char *num_why(const char *s) {
  const char *digits = s + (*s == '+' || *s == '-');
  if (digits[0] == '0' && (digits[1] | 0x20) == 'x') return " (hexadecimal numbers are not read)";
  char *end;
  double d = qk__strtod(s, &end);
  if (end == s || *end) return "";
  if (isnan(d) || (isinf(d) && strpbrk(s, "iI"))) return " (not a finite number)";
  if (d == 0) return " (below the smallest double: it would read as 0)";
  return " (beyond the range of a double)";
}

/* Parse a whole token as a non-negative integer count (digits only). */
static int parse_count(const char *s, unsigned long *v) {
  if (!*s) return 0;
  unsigned long x = 0;
  for (const char *p = s; *p; p++) {
    if (*p < '0' || *p > '9') return 0;
    if (x > (ULONG_MAX - 9) / 10) return 0;
    x = 10 * x + (unsigned long)(*p - '0');
  }
  *v = x;
  return 1;
}

/* Parse a whole token as an integer index (a number with no fractional part). */
static int parse_index(const char *s, long long *v) {
  double d;
  if (!parse_num(s, &d) || d != floor(d) || fabs(d) > 9e15) return 0;
  *v = (long long)d;
  return 1;
}

/* Parse a whole token as a boundary marker (an integer that fits 32 bits). */
static int parse_marker(const char *s, int32_t *v) {
  double d;
  if (!parse_num(s, &d) || d != floor(d) || d < -2147483648.0 || d > 2147483647.0) return 0;
  *v = (int32_t)d;
  return 1;
}

/* Why a marker was refused: an integer beyond 32 bits is one (it was "not an integer"). */
static const char *marker_why(const char *s) {
  double d;
  if (parse_num(s, &d) && d == floor(d))
    return "is out of range (boundary markers are 32-bit integers, -2147483648 to 2147483647)";
  return "is not an integer";
}

/* Record marker v for item i (of the array *m, capacity *cap), growing it. */
static qk_status_t put_marker(const qk_allocator_t *a, int32_t **m, size_t *cap, size_t i,
                              int32_t v) {
  void *p = *m;
  size_t old = *cap;
  if (qk__grow(a, &p, cap, i + 1, sizeof **m)) return QK_ERR_NOMEM;
  *m = p;
  if (*cap > old) memset(*m + old, 0, (*cap - old) * sizeof **m);
  (*m)[i] = v;
  return QK_OK;
}

void qk_poly_free(qk_poly_t *p) {
  if (!p) return;
  qk_allocator_t a = p->alloc;
  qk__free(&a, p->vx, p->cap.v * sizeof *p->vx);
  qk__free(&a, p->vy, p->cap.vy * sizeof *p->vy);
  qk__free(&a, p->vline, p->cap.vl * sizeof *p->vline);
  qk__free(&a, p->seg, p->cap.s * 2 * sizeof *p->seg);
  qk__free(&a, p->sline, p->cap.sl * sizeof *p->sline);
  qk__free(&a, p->hx, p->cap.h * sizeof *p->hx);
  qk__free(&a, p->hy, p->cap.hy * sizeof *p->hy);
  qk__free(&a, p->hline, p->cap.hl * sizeof *p->hline);
  qk__free(&a, p->vmark, p->cap.vm * sizeof *p->vmark);
  qk__free(&a, p->vmoved, p->vmoved_cap * sizeof *p->vmoved);
  qk__free(&a, p->smark, p->cap.sm * sizeof *p->smark);
  qk__free(&a, p->reg, p->cap.r * sizeof *p->reg);
  qk__free(&a, p, sizeof *p);
}

static qk_poly_t *poly_new(const qk_allocator_t *allocator) {
  qk_allocator_t a = {NULL, NULL};
  if (allocator) a = *allocator;
  qk_poly_t *p = qk__realloc(&a, NULL, 0, sizeof *p);
  if (!p) return NULL;
  memset(p, 0, sizeof *p);
  p->alloc = a;
  return p;
}

unsigned qk_poly_first_index(const qk_poly_t *p) { return p ? p->first_index : 0; }

/* v rounded to a multiple of step (ties to even). Where v / step reaches 2^53 (or
 * overflows: 1e10 on 2^-1074), step is below an ulp of v, the multiple of step nearest v
 * is within half an ulp of it, and v stays: the quotient alone was refused as an overflow.
 * (From 2^52 a step that is no power of two can still be up to two ulps.) */
static double round_to(double v, double step) {
  const double q = v / step;
  return fabs(q) < 0x1p53 ? nearbyint(q) * step : v;
}

qk_status_t qk_poly_round(qk_poly_t *p, double step, size_t *rounded) {
  if (rounded) *rounded = 0;
  if (!p || !(step > 0) || !isfinite(step)) return QK_ERR_INVALID;
  for (size_t i = 0; i < p->nv; i++) /* all or nothing */
    if (!isfinite(round_to(p->vx[i], step)) || !isfinite(round_to(p->vy[i], step)))
      return QK_ERR_NONFINITE;
  if (!p->vmoved && p->nv) { /* (before anything changes: all or nothing) */
    p->vmoved = qk__realloc(&p->alloc, NULL, 0, p->nv * sizeof *p->vmoved);
    if (!p->vmoved) return QK_ERR_NOMEM;
    p->vmoved_cap = p->nv;
    memset(p->vmoved, 0, p->nv * sizeof *p->vmoved);
  }
  size_t n = 0;
  for (size_t i = 0; i < p->nv; i++) {
    double x = round_to(p->vx[i], step), y = round_to(p->vy[i], step);
    n += (x != p->vx[i]) + (y != p->vy[i]);
    if (x != p->vx[i] || y != p->vy[i]) p->vmoved[i] += hypot(x - p->vx[i], y - p->vy[i]);
    p->vx[i] = x, p->vy[i] = y;
  }
  if (rounded) *rounded = n;
  return QK_OK;
}

/* The point nearest (x, y) on segment k's line between its ends: its squared distance. */
static double seg_dist2(const qk_poly_t *p, size_t k, double x, double y) {
  const uint32_t a = p->seg[2 * k], b = p->seg[2 * k + 1];
  const double ax = p->vx[a], ay = p->vy[a], dx = p->vx[b] - ax, dy = p->vy[b] - ay;
  const double len2 = dx * dx + dy * dy;
  double t = len2 > 0 ? ((x - ax) * dx + (y - ay) * dy) / len2 : 0;
  t = t < 0 ? 0 : t > 1 ? 1 : t;
  const double ex = ax + t * dx - x, ey = ay + t * dy - y;
  return ex * ex + ey * ey;
}

/* A hole or regional attribute point: where it is, its number among all of them. */
typedef struct rpt {
  double x, y;
  size_t i;
} rpt_t;

static int rpt_cmp(const void *a, const void *b) {
  const rpt_t *u = a, *v = b;
  return u->x < v->x ? -1 : u->x > v->x ? 1 : u->i < v->i ? -1 : u->i > v->i;
}

qk_status_t qk__poly_check_rounded(const qk_poly_t *p, qk_mesh_error_t *err) {
  const size_t np = p->nh + p->nr;
  /* A point left as read and farther from each rounded segment than rounding moved that
   * segment's ends is on the side it was on. Closer, its face may have changed: a
   * hole point 1.5e-8 inside a hole's edge, with that edge rounded past it, dropped the
   * face around the hole and meshed the hole. The points sorted by x, each segment
   * looks at those within r of its x range: about linear (every point against every
   * segment took 5 s for 22,500 holes). */
  if (!p->vmoved || np == 0) return QK_OK;
  rpt_t *pt = qk__realloc(&p->alloc, NULL, 0, np * sizeof *pt);
  if (!pt) return qk__mesh_fail(err, QK_ERR_NOMEM, 0, "out of memory while checking the holes");
  for (size_t i = 0; i < np; i++)
    pt[i] = i < p->nh ? (rpt_t){p->hx[i], p->hy[i], i}
                      : (rpt_t){p->reg[i - p->nh].x, p->reg[i - p->nh].y, i};
  qsort(pt, np, sizeof *pt, rpt_cmp);
  size_t bad = SIZE_MAX, bad_seg = 0; /* the first point by number, its first segment */
  for (size_t k = 0; k < p->ns; k++) {
    const uint32_t a = p->seg[2 * k], b = p->seg[2 * k + 1];
    /* (a segment moved at most as far as its farther-moved end: points of it are
     * combinations of its ends) */
    const double r = fmax(p->vmoved[a], p->vmoved[b]) * (1 + 0x1p-20);
    if (!(r > 0)) continue;
    const double x0 = fmin(p->vx[a], p->vx[b]) - r, x1 = fmax(p->vx[a], p->vx[b]) + r;
    const double y0 = fmin(p->vy[a], p->vy[b]) - r, y1 = fmax(p->vy[a], p->vy[b]) + r;
    size_t lo = 0, hi = np; /* the first point with x >= x0 */
    while (lo < hi) {
      size_t mid = lo + (hi - lo) / 2;
      if (pt[mid].x < x0)
        lo = mid + 1;
      else
        hi = mid;
    }
    for (size_t j = lo; j < np && pt[j].x <= x1; j++)
      if (pt[j].y >= y0 && pt[j].y <= y1 && pt[j].i < bad &&
          seg_dist2(p, k, pt[j].x, pt[j].y) < r * r)
        bad = pt[j].i, bad_seg = k;
  }
  qk__free(&p->alloc, pt, np * sizeof *pt);
  if (bad == SIZE_MAX) return QK_OK;
  const int hole = bad < p->nh;
  const double x = hole ? p->hx[bad] : p->reg[bad - p->nh].x,
               y = hole ? p->hy[bad] : p->reg[bad - p->nh].y;
  const unsigned long line = hole ? (p->hline ? p->hline[bad] : 0) : p->reg[bad - p->nh].line;
  const size_t k = bad_seg;
  const uint32_t a = p->seg[2 * k], b = p->seg[2 * k + 1];
  return qk__mesh_fail(err, QK_ERR_GEOMETRY, line,
                       "%s %zu at (%.17g, %.17g) is within %.3g (as far as rounding moved an "
                       "end) of segment %zu (vertices %u to %u), which may have crossed it; "
                       "move it off",
                       hole ? "hole" : "region point", (hole ? bad : bad - p->nh) + p->first_index,
                       x, y, fmax(p->vmoved[a], p->vmoved[b]), k + p->first_index,
                       a + p->first_index, b + p->first_index);
}

void qk_poly_counts(const qk_poly_t *p, size_t *nv, size_t *ns, size_t *nh) {
  if (nv) *nv = p ? p->nv : 0;
  if (ns) *ns = p ? p->ns : 0;
  if (nh) *nh = p ? p->nh : 0;
}

static qk_status_t add_vertex(qk_poly_t *p, qk__poly_caps_t *c, double x, double y,
                              unsigned long line) {
  const qk_allocator_t *a = &p->alloc;
  size_t need = p->nv + 1;
  if (qk__grow(a, (void **)&p->vx, &c->v, need, sizeof *p->vx) ||
      qk__grow(a, (void **)&p->vy, &c->vy, need, sizeof *p->vy) ||
      qk__grow(a, (void **)&p->vline, &c->vl, need, sizeof *p->vline))
    return QK_ERR_NOMEM;
  p->vx[p->nv] = x;
  p->vy[p->nv] = y;
  p->vline[p->nv] = line;
  p->nv++;
  return QK_OK;
}

static qk_status_t add_segment(qk_poly_t *p, qk__poly_caps_t *c, uint32_t u, uint32_t v,
                               unsigned long line) {
  const qk_allocator_t *a = &p->alloc;
  size_t need = p->ns + 1;
  if (qk__grow(a, (void **)&p->seg, &c->s, need, 2 * sizeof *p->seg) ||
      qk__grow(a, (void **)&p->sline, &c->sl, need, sizeof *p->sline))
    return QK_ERR_NOMEM;
  p->seg[2 * p->ns] = u;
  p->seg[2 * p->ns + 1] = v;
  p->sline[p->ns] = line;
  p->ns++;
  return QK_OK;
}

static qk_status_t add_hole(qk_poly_t *p, qk__poly_caps_t *c, double x, double y,
                            unsigned long line) {
  const qk_allocator_t *a = &p->alloc;
  size_t need = p->nh + 1;
  if (qk__grow(a, (void **)&p->hx, &c->h, need, sizeof *p->hx) ||
      qk__grow(a, (void **)&p->hy, &c->hy, need, sizeof *p->hy) ||
      qk__grow(a, (void **)&p->hline, &c->hl, need, sizeof *p->hline))
    return QK_ERR_NOMEM;
  p->hx[p->nh] = x;
  p->hy[p->nh] = y;
  p->hline[p->nh] = line;
  p->nh++;
  return QK_OK;
}

/* Fill the error record with the reader's line; returns st. */
static qk_status_t rfail(const reader_t *r, qk_mesh_error_t *err, qk_status_t st, const char *fmt,
                         ...)
#if defined(__GNUC__)
    __attribute__((format(printf, 4, 5)))
#endif
    ;

static qk_status_t rfail(const reader_t *r, qk_mesh_error_t *err, qk_status_t st, const char *fmt,
                         ...) {
  if (err) {
    err->line = r->line;
    va_list ap;
    va_start(ap, fmt);
    qk__vsnprintf(err->message, sizeof err->message, fmt, ap);
    va_end(ap);
  }
  return st;
}

/* Start the rows of a section: name, declared count (its header is the current line),
 * the fewest fields of a row. */
static void section(reader_t *r, const char *what, unsigned long n, size_t fields) {
  r->sec = what, r->sec_n = n, r->sec_line = r->line, r->sec_fields = fields;
}

/* A hint for a row or header that does not fit where the count says it should: the rows
 * of the current section are fewer than declared (`fewer`), or the last section has
 * more (a line read as the next header, when it has the fields of such a row). "" when
 * there is no section yet. */
static const char *rows_hint(reader_t *r, int fewer) {
  r->hint[0] = '\0';
  if (r->sec && (fewer || r->ntok >= r->sec_fields))
    snprintf(r->hint, sizeof r->hint, " (%s %s rows than the %lu that line %lu declares?)",
             fewer ? "fewer" : "more", r->sec, r->sec_n, r->sec_line);
  return r->hint;
}

/* Read the next line holding a token, if any: *got is 1, or 0 at the end of input. */
static qk_status_t maybe_line(reader_t *r, qk_mesh_error_t *err, int *got) {
  int g = next_line(r);
  if (g == -2) return rfail(r, err, QK_ERR_PARSE, "binary data (a NUL byte)");
  if (g == -4)
    return rfail(r, err, QK_ERR_LIMIT, "line longer than %lu bytes (1 MiB), the limit for a line",
                 POLY_MAX_LINE);
  if (g == -3)
    return rfail(r, err, QK_ERR_PARSE,
                 "a carriage return inside the line (line ends must be LF or CRLF, not CR alone)");
  if (g == -5)
    return rfail(r, err, QK_ERR_PARSE,
                 "'%s,%s': a decimal comma? Numbers take a decimal point; fields are separated "
                 "by blanks or commas",
                 r->tok[r->comma_tok - 1], r->tok[r->comma_tok]);
  if (g < 0) return rfail(r, err, QK_ERR_NOMEM, "out of memory");
  if (g == 0 && r->io_error) return rfail(r, err, QK_ERR_IO, "read error");
  *got = g;
  return QK_OK;
}

/* Read the next line, failing with `what` (the expectation) at the end of input. */
static qk_status_t need_line(reader_t *r, qk_mesh_error_t *err, const char *what) {
  int got = 0;
  qk_status_t st = maybe_line(r, err, &got);
  if (st) return st;
  if (!got) return rfail(r, err, QK_ERR_PARSE, "%s", what);
  return QK_OK;
}

/* Read a section header's count (first token), rejecting absurd values. */
static qk_status_t read_count(reader_t *r, qk_mesh_error_t *err, const char *what,
                              unsigned long *n) {
  if (!parse_count(r->tok[0], n))
    return rfail(r, err, QK_ERR_PARSE, "expected the number of %s, found '%s'", what, r->tok[0]);
  if (*n > POLY_MAX_COUNT)
    return rfail(r, err, QK_ERR_LIMIT, "%lu %s is absurd (at most %lu accepted)", *n, what,
                 POLY_MAX_COUNT);
  return QK_OK;
}

/* Truncation message for the i-th of n items. */
static const char *truncated(char *buf, size_t cap, unsigned long n, unsigned long i,
                             const char *what) {
  snprintf(buf, cap, "truncated input: expected %lu %s, found %lu", n, what, i);
  return buf;
}

/* The vertex section: <#vertices> <dimension> <#attributes> <#boundary markers>, then
 * <#> <x> <y> [attributes] [marker]. */
static qk_status_t read_vertices(reader_t *r, qk_poly_t *p, qk_mesh_error_t *err) {
  unsigned long nv, dim = 2, nattr = 0, nmark = 0;
  char msg[96];
  qk_status_t st = need_line(r, err, "empty input: expected the vertex section header");
  if (st || (st = read_count(r, err, "vertices", &nv))) return st;
  if (r->ntok > 4)
    return rfail(r, err, QK_ERR_PARSE, "vertex section header has %zu fields, expected 4", r->ntok);
  if (r->ntok > 1 && (!parse_count(r->tok[1], &dim) || dim != 2))
    return rfail(r, err, QK_ERR_PARSE, "dimension must be 2, found '%s'", r->tok[1]);
  if (r->ntok > 2 && (!parse_count(r->tok[2], &nattr) || nattr > POLY_MAX_ATTRIBUTES))
    return rfail(r, err, QK_ERR_PARSE, "bad number of vertex attributes '%s'", r->tok[2]);
  if (r->ntok > 3 && (!parse_count(r->tok[3], &nmark) || nmark > 1))
    return rfail(r, err, QK_ERR_PARSE, "number of boundary markers must be 0 or 1, found '%s'",
                 r->tok[3]);
  if (nv == 0)
    return rfail(r, err, QK_ERR_PARSE,
                 "no vertices (vertices in a separate .node file are not supported)");
  section(r, "vertex", nv, 3);
  for (unsigned long i = 0; i < nv; i++) {
    if ((st = need_line(r, err, truncated(msg, sizeof msg, nv, i, "vertices")))) return st;
    long long idx;
    double x, y;
    if (!parse_index(r->tok[0], &idx))
      return rfail(r, err, QK_ERR_PARSE, "bad vertex number '%s'", r->tok[0]);
    if (i == 0) {
      if (idx != 0 && idx != 1)
        return rfail(r, err, QK_ERR_PARSE, "first vertex number must be 0 or 1, found %lld", idx);
      p->first_index = (unsigned)idx;
    } else if (idx != (long long)(i + p->first_index)) {
      return rfail(r, err, QK_ERR_PARSE, "vertex number %lu expected, found %lld",
                   i + p->first_index, idx);
    }
    if (r->ntok < 3)
      return rfail(r, err, QK_ERR_PARSE, "vertex %lld: expected x and y, found %zu field%s%s", idx,
                   r->ntok, r->ntok == 1 ? "" : "s", rows_hint(r, 1));
    if (!parse_num(r->tok[1], &x))
      return rfail(r, err, QK_ERR_PARSE, "vertex %lld: bad x coordinate '%s'%s", idx, r->tok[1],
                   num_why(r->tok[1]));
    if (!parse_num(r->tok[2], &y))
      return rfail(r, err, QK_ERR_PARSE, "vertex %lld: bad y coordinate '%s'%s", idx, r->tok[2],
                   num_why(r->tok[2]));
    if (r->ntok > 3 + nattr + nmark)
      return rfail(r, err, QK_ERR_PARSE, "vertex %lld: %zu fields, at most %lu expected", idx,
                   r->ntok, 3 + nattr + nmark);
    /* Every attribute the header declares (the marker may be left out): a row short of
     * one was read with what it had, the attributes after it missing without a word. */
    if (r->ntok < 3 + nattr)
      return rfail(r, err, QK_ERR_PARSE,
                   "vertex %lld: %zu fields, expected %lu (number, x, y and the %lu attribute%s "
                   "that line %lu declares%s)",
                   idx, r->ntok, 3 + nattr, nattr, nattr == 1 ? "" : "s", r->sec_line,
                   nmark ? ", then an optional boundary marker" : "");
    for (size_t k = 3; k < r->ntok; k++) { /* (at most 3 + nattr + nmark: all kept) */
      double v;
      if (!parse_num(r->tok[k], &v))
        return rfail(r, err, QK_ERR_PARSE, "vertex %lld: bad field '%s'%s", idx, r->tok[k],
                     num_why(r->tok[k]));
    }
    int32_t mark = 0;
    if (nmark && r->ntok == 4 + nattr && !parse_marker(r->tok[3 + nattr], &mark))
      return rfail(r, err, QK_ERR_PARSE, "vertex %lld: boundary marker '%s' %s", idx,
                   r->tok[3 + nattr], marker_why(r->tok[3 + nattr]));
    if (add_vertex(p, &p->cap, x, y, r->line) ||
        (nmark && put_marker(&p->alloc, &p->vmark, &p->cap.vm, p->nv - 1, mark)))
      return rfail(r, err, QK_ERR_NOMEM, "out of memory");
  }
  return QK_OK;
}

/* The segment section: <#segments> <#boundary markers>, then <#> <endpoint> <endpoint>
 * [marker]. */
static qk_status_t read_segments(reader_t *r, qk_poly_t *p, qk_mesh_error_t *err) {
  unsigned long ns, smark = 0, nv = p->nv;
  char msg[96];
  qk_status_t st = need_line(r, err, "truncated input: expected the segment section header");
  if (st || (st = read_count(r, err, "segments", &ns))) return st;
  if (r->ntok > 2)
    return rfail(r, err, QK_ERR_PARSE, "segment section header has %zu fields, expected 2%s",
                 r->ntok, rows_hint(r, 0));
  if (r->ntok > 1 && (!parse_count(r->tok[1], &smark) || smark > 1))
    return rfail(r, err, QK_ERR_PARSE,
                 "number of segment boundary markers must be 0 or 1, found '%s'", r->tok[1]);
  section(r, "segment", ns, 3);
  for (unsigned long i = 0; i < ns; i++) {
    if ((st = need_line(r, err, truncated(msg, sizeof msg, ns, i, "segments")))) return st;
    long long idx, e[2];
    if (!parse_index(r->tok[0], &idx))
      return rfail(r, err, QK_ERR_PARSE, "bad segment number '%s'", r->tok[0]);
    if (r->ntok < 3)
      return rfail(r, err, QK_ERR_PARSE,
                   "segment %lld: expected two endpoints, found %zu field%s%s", idx, r->ntok,
                   r->ntok == 1 ? "" : "s", rows_hint(r, 1));
    if (r->ntok > 3 + smark)
      return rfail(r, err, QK_ERR_PARSE, "segment %lld: %zu fields, at most %lu expected", idx,
                   r->ntok, 3 + smark);
    /* Numbered as the vertices are, from the vertices' first number on: a number out of
     * turn was taken as its row's position, and messages named that position. */
    if (idx != (long long)(i + p->first_index))
      return rfail(r, err, QK_ERR_PARSE, "segment number %lu expected, found %lld",
                   i + p->first_index, idx);
    for (int k = 0; k < 2; k++)
      if (!parse_index(r->tok[1 + k], &e[k]) || e[k] < (long long)p->first_index ||
          e[k] >= (long long)(nv + p->first_index))
        return rfail(r, err, QK_ERR_PARSE,
                     "segment %lld: endpoint '%s' is not a vertex number (%u..%lu)", idx,
                     r->tok[1 + k], p->first_index, nv - 1 + p->first_index);
    int32_t mark = 0;
    if (r->ntok > 3 && !parse_marker(r->tok[3], &mark))
      return rfail(r, err, QK_ERR_PARSE, "segment %lld: boundary marker '%s' %s", idx, r->tok[3],
                   marker_why(r->tok[3]));
    if (add_segment(p, &p->cap, (uint32_t)(e[0] - p->first_index),
                    (uint32_t)(e[1] - p->first_index), r->line) ||
        (smark && put_marker(&p->alloc, &p->smark, &p->cap.sm, p->ns - 1, mark)))
      return rfail(r, err, QK_ERR_NOMEM, "out of memory");
  }
  return QK_OK;
}

/* The hole section, its header already read: <#holes>, then <#> <x> <y>. */
static qk_status_t read_holes(reader_t *r, qk_poly_t *p, qk_mesh_error_t *err) {
  unsigned long nh;
  char msg[96];
  qk_status_t st = read_count(r, err, "holes", &nh);
  if (st) return st;
  if (r->ntok > 1)
    return rfail(r, err, QK_ERR_PARSE, "hole section header has %zu fields, expected 1%s", r->ntok,
                 rows_hint(r, 0));
  section(r, "hole", nh, 3);
  for (unsigned long i = 0; i < nh; i++) {
    if ((st = need_line(r, err, truncated(msg, sizeof msg, nh, i, "holes")))) return st;
    long long idx;
    double x, y;
    if (!parse_index(r->tok[0], &idx))
      return rfail(r, err, QK_ERR_PARSE, "bad hole number '%s'", r->tok[0]);
    if (r->ntok != 3)
      return rfail(r, err, QK_ERR_PARSE, "hole %lld: expected x and y only, found %zu field%s%s",
                   idx, r->ntok, r->ntok == 1 ? "" : "s", r->ntok < 3 ? rows_hint(r, 1) : "");
    if (idx != (long long)(i + p->first_index)) /* (as the segments) */
      return rfail(r, err, QK_ERR_PARSE, "hole number %lu expected, found %lld", i + p->first_index,
                   idx);
    if (!parse_num(r->tok[1], &x) || !parse_num(r->tok[2], &y))
      return rfail(r, err, QK_ERR_PARSE, "hole %lld: bad coordinates '%s' '%s'%s", idx, r->tok[1],
                   r->tok[2], num_why(r->tok[parse_num(r->tok[1], &x) ? 2 : 1]));
    if (add_hole(p, &p->cap, x, y, r->line)) return rfail(r, err, QK_ERR_NOMEM, "out of memory");
  }
  return QK_OK;
}

/* Append a regional attribute. */
static qk_status_t add_region(qk_poly_t *p, double x, double y, double attr, unsigned long line) {
  void *q = p->reg;
  if (qk__grow(&p->alloc, &q, &p->cap.r, p->nr + 1, sizeof *p->reg)) return QK_ERR_NOMEM;
  p->reg = q;
  p->reg[p->nr++] = (qk__region_pt_t){x, y, attr, line};
  return QK_OK;
}

/* Regional attributes, the header already read: <#regions>, then <#> <x> <y> <attribute>
 * [<area>]. The area constraint is checked for syntax and otherwise ignored (size
 * control is qk_mesh_options_t's max_size and size_fn). */
static qk_status_t read_regions(reader_t *r, qk_poly_t *p, qk_mesh_error_t *err) {
  unsigned long nr;
  char msg[96];
  qk_status_t st = read_count(r, err, "regional attributes", &nr);
  if (st) return st;
  if (r->ntok > 1)
    return rfail(r, err, QK_ERR_PARSE, "region section header has %zu fields, expected 1%s",
                 r->ntok, rows_hint(r, 0));
  section(r, "region", nr, 4);
  for (unsigned long i = 0; i < nr; i++) {
    if ((st = need_line(r, err, truncated(msg, sizeof msg, nr, i, "regional attributes"))))
      return st;
    if (r->ntok < 4 || r->ntok > 5)
      return rfail(r, err, QK_ERR_PARSE, "region %lu: expected 4 or 5 fields, found %zu%s",
                   i + p->first_index, r->ntok, r->ntok < 4 ? rows_hint(r, 1) : "");
    double v[5];
    for (size_t k = 0; k < r->ntok; k++)
      if (!parse_num(r->tok[k], &v[k]))
        return rfail(r, err, QK_ERR_PARSE, "region: bad field '%s'%s", r->tok[k],
                     num_why(r->tok[k]));
    if (add_region(p, v[1], v[2], v[3], r->line))
      return rfail(r, err, QK_ERR_NOMEM, "out of memory");
  }
  return QK_OK;
}

/* Everything after the segments: the hole section (required, as in Triangle, whose reader
 * stops at a file that ends before it: a lost hole section would mesh the holes as solid),
 * optional regions, then nothing. */
static qk_status_t read_tail(reader_t *r, qk_poly_t *p, qk_mesh_error_t *err) {
  int got = 0;
  qk_status_t st = need_line(r, err,
                             "truncated input: the file ends here, where the hole section was "
                             "expected (a line with the number of holes, 0 for none)");
  if (st) return st;
  if ((st = read_holes(r, p, err)) || (st = maybe_line(r, err, &got)) || !got) return st;
  if ((st = read_regions(r, p, err)) || (st = maybe_line(r, err, &got))) return st;
  if (got)
    return rfail(r, err, QK_ERR_PARSE, "unexpected content after the last section: '%s'%s",
                 r->tok[0], rows_hint(r, 0));
  return QK_OK;
}

qk_status_t qk_poly_read(FILE *f, const qk_allocator_t *allocator, qk_poly_t **out,
                         qk_mesh_error_t *err) {
  if (out) *out = NULL;
  qk__error_clear(err);
  if (!f || !out) return QK_ERR_INVALID;
  if (qk__c_locale_ready() != QK_OK) /* (numbers are read in the C locale: index/textloc.h) */
    return qk__mesh_fail(err, QK_ERR_NOMEM, 0, "out of memory");
  qk_poly_t *p = poly_new(allocator);
  if (!p) return qk__mesh_fail(err, QK_ERR_NOMEM, 0, "out of memory");
  reader_t r;
  memset(&r, 0, sizeof r);
  r.f = f, r.a = &p->alloc;
  qk_status_t st;
  if (!(st = read_vertices(&r, p, err)) && !(st = read_segments(&r, p, err)) &&
      !(st = read_tail(&r, p, err)) && r.io_error)
    st = rfail(&r, err, QK_ERR_IO, "read error");
  qk__free(&p->alloc, r.buf, r.cap);
  if (st != QK_OK) {
    qk_poly_free(p);
    return st;
  }
  *out = p;
  return QK_OK;
}

/* st, with the offending array item recorded. */
static qk_status_t item_fail(qk_mesh_error_t *err, size_t item, qk_status_t st) {
  if (err) err->item = item;
  return st;
}

qk_status_t qk_poly_from_arrays(const double *xy, size_t nv, const uint32_t *seg, size_t ns,
                                const double *holes, size_t nh, const qk_allocator_t *allocator,
                                qk_poly_t **out, qk_mesh_error_t *err) {
  qk__error_clear(err);
  if (!out) return qk__mesh_fail(err, QK_ERR_INVALID, 0, "no output pointer");
  *out = NULL;
  if (nv && !xy) return qk__mesh_fail(err, QK_ERR_INVALID, 0, "%zu vertices but no array", nv);
  if (ns && !seg) return qk__mesh_fail(err, QK_ERR_INVALID, 0, "%zu segments but no array", ns);
  if (nh && !holes) return qk__mesh_fail(err, QK_ERR_INVALID, 0, "%zu holes but no array", nh);
  if (nv > POLY_MAX_COUNT || ns > POLY_MAX_COUNT || nh > POLY_MAX_COUNT)
    return qk__mesh_fail(err, QK_ERR_LIMIT, 0,
                         "%zu vertices, %zu segments, %zu holes: at most %lu of each", nv, ns, nh,
                         POLY_MAX_COUNT);
  /* (err->item: the vertex, segment or hole, as the message says) */
  for (size_t i = 0; i < nv; i++)
    if (!isfinite(xy[2 * i]) || !isfinite(xy[2 * i + 1]))
      return item_fail(err, i,
                       qk__mesh_fail(err, QK_ERR_INVALID, 0,
                                     "vertex %zu: coordinates (%g, %g) not finite", i, xy[2 * i],
                                     xy[2 * i + 1]));
  for (size_t i = 0; i < 2 * ns; i++)
    if (seg[i] >= nv)
      return item_fail(err, i / 2,
                       qk__mesh_fail(err, QK_ERR_INVALID, 0,
                                     "segment %zu: endpoint %lu is not a vertex number (0..%zu)",
                                     i / 2, (unsigned long)seg[i], nv ? nv - 1 : 0));
  for (size_t i = 0; i < nh; i++)
    if (!isfinite(holes[2 * i]) || !isfinite(holes[2 * i + 1]))
      return item_fail(err, i,
                       qk__mesh_fail(err, QK_ERR_INVALID, 0,
                                     "hole %zu: coordinates (%g, %g) not finite", i, holes[2 * i],
                                     holes[2 * i + 1]));
  qk_poly_t *p = poly_new(allocator);
  if (!p) return qk__mesh_fail(err, QK_ERR_NOMEM, 0, "out of memory");
  qk__poly_caps_t *c = &p->cap;
  for (size_t i = 0; i < nv; i++)
    if (add_vertex(p, c, xy[2 * i], xy[2 * i + 1], 0)) goto nomem;
  for (size_t i = 0; i < ns; i++)
    if (add_segment(p, c, seg[2 * i], seg[2 * i + 1], 0)) goto nomem;
  for (size_t i = 0; i < nh; i++)
    if (add_hole(p, c, holes[2 * i], holes[2 * i + 1], 0)) goto nomem;
  *out = p;
  return QK_OK;
nomem:
  qk_poly_free(p);
  return qk__mesh_fail(err, QK_ERR_NOMEM, 0, "out of memory");
}

qk_status_t qk_poly_vertices(const qk_poly_t *p, double *xy, size_t cap, size_t *n_out) {
  if (!p || !n_out || (cap && !xy)) return QK_ERR_INVALID;
  *n_out = p->nv;
  for (size_t i = 0; i < p->nv && i < cap; i++) xy[2 * i] = p->vx[i], xy[2 * i + 1] = p->vy[i];
  return QK_OK;
}

qk_status_t qk_poly_segments(const qk_poly_t *p, uint32_t *seg, size_t cap, size_t *n_out) {
  if (!p || !n_out || (cap && !seg)) return QK_ERR_INVALID;
  *n_out = p->ns;
  size_t k = p->ns < cap ? p->ns : cap;
  if (k) memcpy(seg, p->seg, 2 * k * sizeof *seg);
  return QK_OK;
}

qk_status_t qk_poly_holes(const qk_poly_t *p, double *xy, size_t cap, size_t *n_out) {
  if (!p || !n_out || (cap && !xy)) return QK_ERR_INVALID;
  *n_out = p->nh;
  for (size_t i = 0; i < p->nh && i < cap; i++) xy[2 * i] = p->hx[i], xy[2 * i + 1] = p->hy[i];
  return QK_OK;
}

qk_status_t qk_poly_set_markers(qk_poly_t *p, const int32_t *vm, const int32_t *sm,
                                qk_mesh_error_t *err) {
  qk__error_clear(err);
  if (!p) return qk__mesh_fail(err, QK_ERR_INVALID, 0, "no input");
  int32_t *nv = NULL, *ns = NULL;
  size_t cv = 0, cs = 0;
  if (vm && p->nv && put_marker(&p->alloc, &nv, &cv, p->nv - 1, 0)) goto nomem;
  if (sm && p->ns && put_marker(&p->alloc, &ns, &cs, p->ns - 1, 0)) goto nomem;
  if (nv) memcpy(nv, vm, p->nv * sizeof *nv);
  if (ns) memcpy(ns, sm, p->ns * sizeof *ns);
  qk__free(&p->alloc, p->vmark, p->cap.vm * sizeof *p->vmark);
  qk__free(&p->alloc, p->smark, p->cap.sm * sizeof *p->smark);
  p->vmark = nv, p->cap.vm = cv, p->smark = ns, p->cap.sm = cs;
  return QK_OK;
nomem:
  qk__free(&p->alloc, nv, cv * sizeof *nv);
  return qk__mesh_fail(err, QK_ERR_NOMEM, 0, "out of memory");
}

qk_status_t qk_poly_set_regions(qk_poly_t *p, const double *xya, size_t nr, qk_mesh_error_t *err) {
  qk__error_clear(err);
  if (!p || (nr && !xya)) return qk__mesh_fail(err, QK_ERR_INVALID, 0, "no input or no array");
  if (nr > POLY_MAX_COUNT)
    return qk__mesh_fail(err, QK_ERR_LIMIT, 0, "%zu regional attributes: at most %lu", nr,
                         POLY_MAX_COUNT);
  for (size_t i = 0; i < 3 * nr; i++)
    if (!isfinite(xya[i]))
      return qk__mesh_fail(err, QK_ERR_INVALID, 0, "regional attribute %zu: %g is not finite",
                           i / 3, xya[i]);
  qk__region_pt_t *reg = NULL;
  size_t cap = 0;
  void *q = NULL;
  if (nr && qk__grow(&p->alloc, &q, &cap, nr, sizeof *reg))
    return qk__mesh_fail(err, QK_ERR_NOMEM, 0, "out of memory");
  reg = q;
  for (size_t i = 0; i < nr; i++)
    reg[i] = (qk__region_pt_t){xya[3 * i], xya[3 * i + 1], xya[3 * i + 2], 0};
  qk__free(&p->alloc, p->reg, p->cap.r * sizeof *p->reg);
  p->reg = reg, p->cap.r = cap, p->nr = nr;
  return QK_OK;
}
