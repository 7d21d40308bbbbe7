/*
 * The CSV reader: numeric columns selected by name or number, per the rules in
 * include/quadkit/io.h. Phases: parse the column list, read lines, resolve names against
 * the header, then convert each data row's selected fields.
 */
#include <math.h>
#include <stdarg.h>
#include <stdint.h>
#include <stdlib.h>
#include <string.h>

#include "io/io_internal.h"

enum { MAX_COLS = 64, MAX_COLUMN = 100000, NAME_LEN = 48 };
#define MAX_ROWS ((size_t)UINT32_MAX - 1u) /* the ids a tree holds (QK_MAX_POINTS) */

typedef struct reader {
  const qk_csv_options_t *opt;
  const qk_allocator_t *alloc;
  qk_error_t *err;
  size_t ncols, nreq;
  size_t col[MAX_COLS];           /* 1-based column numbers, 0 = by name (unresolved) */
  const char *want[MAX_COLS];     /* the names asked for (into opt->columns) */
  size_t want_len[MAX_COLS];      /* their lengths */
  char label[MAX_COLS][NAME_LEN]; /* the header's name of each selected column, or "" */
  size_t maxcol;                  /* the largest selected column number */
  qk__span_t *spans;              /* fields of the current line (nspans >= maxcol) */
  size_t nspans;
  size_t bom;             /* 3 when line 1 started with a byte order mark */
  const char *rec;        /* the current record (several lines when a quoted field holds breaks) */
  unsigned long rec_line; /* the physical line where it starts */
  double *v;              /* rows * ncols values */
  size_t rows, cap;
} reader_t;

void qk_csv_options_init(qk_csv_options_t *opt) {
  if (opt) memset(opt, 0, sizeof *opt);
}

static qk_status_t fail(reader_t *r, qk_status_t st, unsigned long line, size_t column, size_t item,
                        const char *fmt, ...) {
  if (r->err) {
    /* A column of a record that spans lines: name the physical line and column. */
    if (line && column && r->rec && line == r->rec_line) {
      size_t lb = 0; /* where column's physical line starts in the record */
      for (size_t i = 0; i + 1 < column && r->rec[i]; i++)
        if (r->rec[i] == '\n') line++, lb = i + 1;
      column -= lb;
    }
    r->err->line = line;
    r->err->column = line && column ? (unsigned long)(column + (line == 1 ? r->bom : 0)) : 0;
    r->err->item = item;
    va_list ap;
    va_start(ap, fmt);
    qk__vsnprintf(r->err->message, sizeof r->err->message, fmt, ap);
    va_end(ap);
  }
  return st;
}

static int is_blank(char c) { return c == ' ' || c == '\t'; }

/* Parse opt->columns ("lon,lat", "3,2") into r->col / r->want. */
static qk_status_t parse_columns(reader_t *r) {
  const char *s = r->opt && r->opt->columns ? r->opt->columns : NULL;
  if (!s) {
    for (size_t k = 0; k < r->ncols; k++) r->col[k] = k + 1;
    r->maxcol = r->ncols;
    return QK_OK;
  }
  size_t k = 0;
  for (const char *p = s;; k++) {
    const char *e = strchr(p, ',');
    if (!e) e = p + strlen(p);
    const char *b = p, *t = e;
    while (b < t && is_blank(*b)) b++;
    while (t > b && is_blank(t[-1])) t--;
    if (k >= r->ncols || b == t)
      return fail(r, QK_ERR_INVALID, 0, 0, SIZE_MAX,
                  "columns must be %zu comma-separated names or 1-based numbers, not '%.80s'",
                  r->ncols, s);
    size_t num = 0, digits = 1;
    for (const char *q = b; q < t; q++) {
      if (*q < '0' || *q > '9')
        digits = 0;
      else if (num <= MAX_COLUMN)
        num = num * 10 + (size_t)(*q - '0');
    }
    if (digits && (num == 0 || num > MAX_COLUMN))
      return fail(r, QK_ERR_INVALID, 0, 0, SIZE_MAX, "column number %.*s is out of range (1 to %d)",
                  (int)(t - b), b, MAX_COLUMN);
    r->col[k] = digits ? num : 0;
    r->want[k] = digits ? NULL : b;
    r->want_len[k] = (size_t)(t - b);
    if (*e == '\0') break;
    p = e + 1;
  }
  if (k + 1 != r->ncols)
    return fail(r, QK_ERR_INVALID, 0, 0, SIZE_MAX,
                "columns must be %zu comma-separated names or 1-based numbers, not '%.80s'",
                r->ncols, s);
  return QK_OK;
}

/* The length of out[0, n) without a UTF-8 character cut at its end: the lead byte and the
 * continuation bytes after it go when fewer than the lead byte announces. */
static size_t utf8_whole(const char *out, size_t n) {
  size_t k = n;
  while (k > 0 && n - k < 4 && ((unsigned char)out[k - 1] & 0xC0) == 0x80) k--;
  if (k > 0) {
    const unsigned char lead = (unsigned char)out[k - 1];
    const size_t want = lead >= 0xF0 ? 4 : lead >= 0xE0 ? 3 : lead >= 0xC0 ? 2 : 1;
    if (want > 1 && n - (k - 1) < want) return k - 1;
  }
  return n;
}

/* A field's value for a message: its first 40 bytes as the value reads (a quoted field's
 * "" as one quote: the text between the quotes of "1""" is shown as 1", not 1""), not cut
 * inside a UTF-8 character. */
static void field_value(const char *line, const qk__span_t *sp, char *out, size_t cap) {
  size_t n = 0, j = sp->b;
  for (; j < sp->e && n + 1 < cap && n < 40; j++) {
    if (sp->quoted && line[j] == '"' && j + 1 < sp->e && line[j + 1] == '"') j++;
    out[n++] = line[j];
  }
  if (j >= sp->e) { /* whole: as it stands (bytes that are no UTF-8 too) */
    out[n] = '\0';
    return;
  }
  out[utf8_whole(out, n)] = '\0';
}

/* Does the (possibly quoted, blank-padded) field spell `name`? */
static int field_is(const char *line, const qk__span_t *sp, const char *name, size_t len) {
  size_t b = sp->b, e = sp->e, i = 0;
  if (!sp->quoted) {
    while (b < e && is_blank(line[b])) b++;
    while (e > b && is_blank(line[e - 1])) e--;
  }
  for (size_t j = b; j < e; j++, i++) {
    if (sp->quoted && line[j] == '"') j++; /* "" is one quote */
    if (i >= len || line[j] != name[i]) return 0;
  }
  return i == len;
}

/* Copy a field's text (quotes undone) into a label; a longer one is cut, not inside a
 * UTF-8 character, and ends in "..." (it was cut at 47 bytes, mid-word or mid-character). */
static void field_label(const char *line, const qk__span_t *sp, char *out) {
  size_t i = 0, b = sp->b, e = sp->e, j = b;
  while (b < e && is_blank(line[b])) b++;
  while (e > b && is_blank(line[e - 1])) e--;
  for (j = b; j < e && i + 1 < NAME_LEN; j++) {
    if (sp->quoted && line[j] == '"') j++;
    out[i++] = line[j];
  }
  if (j < e) { /* cut */
    i = utf8_whole(out, i < NAME_LEN - 4 ? i : NAME_LEN - 4);
    memcpy(out + i, "...", 3);
    i += 3;
  }
  out[i] = '\0';
}

/* Room in r->spans for the widest selection. */
static qk_status_t spans_room(reader_t *r) {
  if (r->maxcol <= r->nspans) return QK_OK;
  qk__span_t *p = qk__io_realloc(r->alloc, r->spans, r->nspans * sizeof *p, r->maxcol * sizeof *p);
  if (!p) return fail(r, QK_ERR_NOMEM, 0, 0, SIZE_MAX, "out of memory");
  r->spans = p;
  r->nspans = r->maxcol;
  return QK_OK;
}

/* Split the first `max` fields of a line into r->spans; *nf = how many there are (up to
 * max). Returns QK_OK or a parse error at the field that is malformed. */
static qk_status_t split(reader_t *r, const char *line, size_t len, size_t max, size_t *nf,
                         unsigned long lineno, size_t item) {
  size_t pos = 0, k = 0;
  while (k < max && pos <= len) {
    const char *msg = qk__csv_field(line, len, &pos, &r->spans[k]);
    if (msg)
      return fail(r, QK_ERR_PARSE, lineno, r->spans[k].start + 1, item, "field %zu: %s", k + 1,
                  msg);
    k++;
  }
  *nf = k;
  return QK_OK;
}

/* How selection i was asked for: its quoted name, or its field number. */
static void selection_label(const reader_t *r, size_t i, char *out, size_t size) {
  if (r->want[i])
    snprintf(out, size, "'%.*s'", (int)(r->want_len[i] < NAME_LEN ? r->want_len[i] : NAME_LEN),
             r->want[i]);
  else
    snprintf(out, size, "%zu", r->col[i]);
}

/* Two selections of one field (x and y both from column 1, "x,1" when x is the first
 * field) would read every point onto the diagonal: refused. Columns still unresolved (0)
 * are skipped; line is the header's, or 0 before any line is read. */
static qk_status_t distinct_columns(reader_t *r, unsigned long line) {
  for (size_t c = 0; c < r->ncols; c++)
    for (size_t d = c + 1; d < r->ncols; d++) {
      if (r->col[c] == 0 || r->col[c] != r->col[d]) continue;
      char a[NAME_LEN + 8], b[NAME_LEN + 8];
      selection_label(r, c, a, sizeof a);
      selection_label(r, d, b, sizeof b);
      return fail(r, line ? QK_ERR_PARSE : QK_ERR_INVALID, line, 0, SIZE_MAX,
                  "columns %s and %s (%zu and %zu of the selection) are both field %zu", a, b,
                  c + 1, d + 1, r->col[c]);
    }
  return QK_OK;
}

/* The header: resolve the names asked for and remember every selected column's label. */
static qk_status_t read_header(reader_t *r, const char *line, size_t len, unsigned long lineno) {
  size_t pos = 0, k = 0;
  qk__span_t sp;
  while (pos <= len) {
    const char *msg = qk__csv_field(line, len, &pos, &sp);
    if (msg) return fail(r, QK_ERR_PARSE, lineno, sp.start + 1, SIZE_MAX, "header: %s", msg);
    k++;
    for (size_t c = 0; c < r->ncols; c++) {
      if (r->col[c] == k) field_label(line, &sp, r->label[c]);
      if (!r->want[c] || !field_is(line, &sp, r->want[c], r->want_len[c])) continue;
      if (r->col[c] != 0)
        return fail(r, QK_ERR_PARSE, lineno, sp.start + 1, SIZE_MAX,
                    "column name '%.*s' appears twice in the header (fields %zu and %zu)",
                    (int)r->want_len[c], r->want[c], r->col[c], k);
      r->col[c] = k;
      field_label(line, &sp, r->label[c]);
    }
  }
  for (size_t c = 0; c < r->ncols; c++) {
    if (r->col[c] == 0)
      return fail(
          r, QK_ERR_PARSE, lineno, 0, SIZE_MAX,
          "no column named '%.*s%s' in the header (%zu fields: '%.*s%s')",
          (int)utf8_whole(r->want[c], r->want_len[c] < NAME_LEN ? r->want_len[c] : NAME_LEN),
          r->want[c], r->want_len[c] > NAME_LEN ? "..." : "", k,
          (int)utf8_whole(line, len < 100 ? len : 100), line, len > 100 ? "..." : "");
    if (r->col[c] > r->maxcol) r->maxcol = r->col[c];
  }
  qk_status_t st = distinct_columns(r, lineno);
  return st ? st : spans_room(r);
}

/* Room for one more row of values. */
static qk_status_t grow(reader_t *r) {
  if (r->rows < r->cap) return QK_OK;
  size_t nc = r->cap ? r->cap * 2 : 256;
  if (nc > SIZE_MAX / sizeof(double) / r->ncols) return QK_ERR_NOMEM;
  double *p =
      qk__io_realloc(r->alloc, r->v, r->cap * r->ncols * sizeof *p, nc * r->ncols * sizeof *p);
  if (!p) return QK_ERR_NOMEM;
  r->v = p;
  r->cap = nc;
  return QK_OK;
}

/* Convert one data row's selected fields into r->v. */
static qk_status_t read_row(reader_t *r, char *line, size_t len, unsigned long lineno) {
  size_t nf = 0, row = r->rows;
  qk_status_t st = split(r, line, len, r->maxcol, &nf, lineno, row);
  if (st) return st;
  if (row >= MAX_ROWS)
    return fail(r, QK_ERR_LIMIT, lineno, 0, row, "too many rows (at most %zu)", MAX_ROWS);
  if ((st = grow(r))) return fail(r, st, lineno, 0, row, "out of memory");
  double *out = r->v + row * r->ncols;
  for (size_t c = 0; c < r->ncols; c++) {
    size_t f = r->col[c];
    const char *lab = r->label[c];
    char named[NAME_LEN + 4] = "";
    if (lab[0]) snprintf(named, sizeof named, " (%s)", lab);
    if (f > nf) {
      if (c >= r->nreq) {
        out[c] = NAN;
        continue;
      }
      return fail(r, QK_ERR_PARSE, lineno, len + 1, row,
                  "field %zu%s is missing: the line has %zu field%s", f, named, nf,
                  nf == 1 ? "" : "s");
    }
    const qk__span_t *sp = &r->spans[f - 1];
    size_t b = sp->b;
    while (b < sp->e && is_blank(line[b])) b++;
    if (b == sp->e && c >= r->nreq && !sp->quoted) {
      out[c] = NAN; /* an empty optional field */
      continue;
    }
    double v;
    int num = qk__csv_number(line, sp, &v);
    char val[48];
    if (num <= 0 || !isfinite(v)) field_value(line, sp, val, sizeof val);
    if (num == -2)
      return fail(r, QK_ERR_LIMIT, lineno, sp->start + 1, row,
                  "field %zu%s is below the smallest double (it would read as 0): '%s'", f, named,
                  val);
    if (num <= 0)
      return fail(r, QK_ERR_PARSE, lineno, sp->start + 1, row,
                  "field %zu%s is not a %snumber: '%s'", f, named, num < 0 ? "decimal " : "", val);
    if (!isfinite(v))
      return fail(r, QK_ERR_NONFINITE, lineno, sp->start + 1, row,
                  "field %zu%s is not finite: '%s'", f, named, val);
    out[c] = v;
  }
  if (r->opt && r->opt->on_row) {
    st = r->opt->on_row(r->opt->ud, row, lineno, line, len);
    if (st) return fail(r, st, lineno, 0, row, "stopped by the row callback: %s", qk_strerror(st));
  }
  r->rows++;
  return QK_OK;
}

/* Is the first non-blank line a header? */
static int header_line(reader_t *r, char *line, size_t len) {
  qk_csv_header_t h = r->opt ? r->opt->header : QK_CSV_HEADER_AUTO;
  if (h == QK_CSV_HEADER_YES) return 1;
  if (h == QK_CSV_HEADER_NO) return 0;
  for (size_t c = 0; c < r->ncols; c++)
    if (r->col[c] == 0) return 1; /* names need a header */
  /* A header names the columns: none of the selected fields is a number. A line with a
   * number among them is data, so that a malformed first row is reported, not skipped
   * as a header ("x1,2" was dropped without a word). */
  size_t nf = 0;
  qk_error_t *keep = r->err;
  r->err = NULL; /* a malformed line is judged as data, with its own message */
  qk_status_t st = split(r, line, len, r->maxcol, &nf, 0, 0);
  r->err = keep;
  if (st != QK_OK) return 0;
  double v;
  for (size_t c = 0; c < r->ncols; c++)
    if (nf >= r->col[c] && qk__csv_number(line, &r->spans[r->col[c] - 1], &v)) return 0;
  return 1;
}

static qk_status_t read_lines(reader_t *r, qk__lines_t *in) {
  size_t len;
  int first = 1, got;
  while ((got = qk__lines_next(in, &len)) > 0) {
    char *line = in->line;
    unsigned long lineno = in->first; /* a record names the line where it starts */
    r->rec = line, r->rec_line = lineno;
    if (memchr(line, '\0', len))
      return fail(r, QK_ERR_PARSE, lineno, (size_t)((char *)memchr(line, '\0', len) - line) + 1,
                  SIZE_MAX, "binary data (NUL byte) in a text file");
    const char *cr = memchr(line, '\r', len);
    if (cr)
      return fail(r, QK_ERR_PARSE, lineno, (size_t)(cr - line) + 1, SIZE_MAX,
                  "a carriage return inside the line (line ends must be LF or CRLF, not CR "
                  "alone)");
    if (lineno == 1 && len >= 3 && !memcmp(line, "\xEF\xBB\xBF", 3)) {
      memmove(line, line + 3, len - 2); /* the byte order mark, and the NUL */
      len -= 3;
      r->bom = 3;
    }
    size_t i = 0;
    while (i < len && is_blank(line[i])) i++;
    if (i == len) continue;
    qk_status_t st;
    if (first && header_line(r, line, len)) {
      if ((st = read_header(r, line, len, lineno))) return st;
      if (r->opt && r->opt->on_row &&
          (st = r->opt->on_row(r->opt->ud, SIZE_MAX, lineno, line, len)))
        return fail(r, st, lineno, 0, SIZE_MAX, "stopped by the row callback: %s", qk_strerror(st));
      first = 0;
      continue;
    }
    first = 0;
    if (in->open_quote) { /* (a header reports it: all its fields are read) */
      /* A quote left open takes the rest of the input into its field, in a column not
       * read too: name it, as the rows after it would be lost. */
      size_t pos = 0, k = 0;
      qk__span_t sp;
      const char *msg = NULL;
      while (pos <= len && !(msg = qk__csv_field(line, len, &pos, &sp))) k++;
      if (k >= r->maxcol) /* (in a selected field the row reports it, as any bad quote) */
        return fail(r, QK_ERR_PARSE, lineno, msg ? sp.start + 1 : 0, SIZE_MAX,
                    "field %zu: unterminated quoted field (it runs to the end of the file)", k + 1);
    }
    if ((st = read_row(r, line, len, lineno))) return st;
  }
  r->rec = NULL;
  if (got < 0) return fail(r, QK_ERR_NOMEM, in->lineno + 1, 0, SIZE_MAX, "out of memory");
  if (in->ioerr) return fail(r, QK_ERR_IO, 0, 0, SIZE_MAX, "read error");
  return QK_OK;
}

qk_status_t qk_csv_read_values(FILE *f, const qk_csv_options_t *opt, size_t ncols, size_t nrequired,
                               const qk_allocator_t *alloc, double **values, size_t *rows,
                               qk_error_t *err) {
  if (values) *values = NULL;
  if (rows) *rows = 0;
  if (err) {
    memset(err, 0, sizeof *err);
    err->item = SIZE_MAX;
  }
  reader_t r;
  memset(&r, 0, sizeof r);
  r.opt = opt, r.alloc = alloc, r.err = err, r.ncols = ncols, r.nreq = nrequired;
  if (!f || !values || !rows || ncols == 0 || ncols > MAX_COLS || nrequired == 0 ||
      nrequired > ncols)
    return fail(&r, QK_ERR_INVALID, 0, 0, SIZE_MAX, "invalid arguments");
  if (opt && (unsigned)opt->header > (unsigned)QK_CSV_HEADER_NO)
    return fail(&r, QK_ERR_INVALID, 0, 0, SIZE_MAX,
                "header rule %d is none of QK_CSV_HEADER_AUTO, _YES and _NO", (int)opt->header);
  if (qk__c_locale_ready() != QK_OK) /* (numbers are read in the C locale: index/textloc.h) */
    return fail(&r, QK_ERR_NOMEM, 0, 0, SIZE_MAX, "out of memory");
  qk_status_t st = parse_columns(&r);
  if (!st) st = distinct_columns(&r, 0);
  if (st) return st;
  for (size_t c = 0; c < ncols; c++) {
    if (r.col[c] > r.maxcol) r.maxcol = r.col[c];
    if (r.col[c] == 0 && opt && opt->header == QK_CSV_HEADER_NO)
      return fail(&r, QK_ERR_INVALID, 0, 0, SIZE_MAX,
                  "column '%.*s' is named, but the input has no header", (int)r.want_len[c],
                  r.want[c]);
  }
  qk__lines_t in;
  qk__lines_init(&in, f, alloc);
  st = spans_room(&r);
  if (st == QK_OK) st = read_lines(&r, &in);
  qk__lines_free(&in);
  if (r.spans) qk__io_realloc(alloc, r.spans, r.nspans * sizeof *r.spans, 0);
  if (st == QK_OK && r.rows == 0 && r.v) {
    qk__io_realloc(alloc, r.v, r.cap * ncols * sizeof *r.v, 0);
    r.v = NULL;
  } else if (st == QK_OK && r.rows < r.cap) {
    /* Give back the slack, so that the caller frees exactly rows * ncols doubles. */
    double *p = qk__io_realloc(alloc, r.v, r.cap * ncols * sizeof *p, r.rows * ncols * sizeof *p);
    if (!p)
      st = fail(&r, QK_ERR_NOMEM, 0, 0, SIZE_MAX, "out of memory");
    else
      r.v = p;
  }
  if (st != QK_OK) {
    if (r.v) qk__io_realloc(alloc, r.v, r.cap * ncols * sizeof *r.v, 0);
    return st;
  }
  *values = r.v;
  *rows = r.rows;
  return QK_OK;
}
