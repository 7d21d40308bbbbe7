/* The CSV scanner: lines of a stream through the caller's allocator, fields, numbers. */
#include <errno.h>
#include <stdlib.h>
#include <string.h>

#include "io/io_internal.h"

enum { CHUNK = 1 << 16 };

void *qk__io_realloc(const qk_allocator_t *a, void *p, size_t osize, size_t nsize) {
  if (a && a->fn) return a->fn(a->ud, p, osize, nsize);
  if (nsize == 0) {
    free(p);
    return NULL;
  }
  return realloc(p, nsize);
}

void qk__lines_init(qk__lines_t *r, FILE *f, const qk_allocator_t *alloc) {
  memset(r, 0, sizeof *r);
  r->f = f;
  r->alloc = alloc;
}

void qk__lines_free(qk__lines_t *r) {
  if (r->chunk) qk__io_realloc(r->alloc, r->chunk, CHUNK, 0);
  if (r->line) qk__io_realloc(r->alloc, r->line, r->cap, 0);
  r->chunk = r->line = NULL;
  r->cap = 0;
}

/* Room for `need` bytes in the line buffer. */
static int line_room(qk__lines_t *r, size_t need) {
  if (need <= r->cap) return 0;
  size_t nc = r->cap ? r->cap : 256;
  while (nc < need) nc *= 2;
  char *p = qk__io_realloc(r->alloc, r->line, r->cap, nc);
  if (!p) return -1;
  r->line = p;
  r->cap = nc;
  return 0;
}

/* Quote state of a CSV record at the end of a physical line: 0 at a field's start, 1 in
 * an unquoted field (or after a closing quote), 2 inside quotes, 3 just after a quote seen
 * inside quotes (a closing quote, or the first of ""). Only a quote at a field's start
 * (blanks before it allowed) opens a quoted field, as in qk__csv_field. */
static int quote_state(int q, const char *s, size_t n) {
  for (size_t i = 0; i < n; i++) {
    char c = s[i];
    switch (q) {
    case 0:
      if (c == '"')
        q = 2;
      else if (c != ',' && c != ' ' && c != '\t')
        q = 1;
      break;
    case 1:
      if (c == ',') q = 0;
      break;
    case 2:
      if (c == '"') q = 3;
      break;
    default: /* 3 */
      q = c == '"' ? 2 : c == ',' ? 0 : 1;
      break;
    }
  }
  return q;
}

int qk__lines_next(qk__lines_t *r, size_t *len) {
  if (!r->chunk) {
    r->chunk = qk__io_realloc(r->alloc, NULL, 0, CHUNK);
    if (!r->chunk) return -1;
  }
  size_t n = 0;        /* bytes of the record so far */
  size_t pl = 0;       /* where the current physical line starts in it */
  int q = 0, open = 0; /* open: a physical line has begun and is not yet complete */
  int nul = 0;         /* a NUL byte ended the line */
  r->open_quote = 0;
  for (;;) {
    if (r->cpos == r->clen && !r->eof) {
      r->clen = fread(r->chunk, 1, CHUNK, r->f);
      r->cpos = 0;
      if (r->clen < CHUNK) {
        r->eof = 1;
        r->ioerr = ferror(r->f) != 0;
      }
    }
    if (r->cpos == r->clen) { /* the input ends */
      if (!open) {
        if (pl == 0) return 0; /* no record */
        n--;                   /* a record inside quotes at the end: drop its added LF */
        r->open_quote = 1;
        break;
      }
    } else {
      const char *s = r->chunk + r->cpos;
      size_t avail = r->clen - r->cpos;
      const char *nl = memchr(s, '\n', avail);
      size_t take = nl ? (size_t)(nl - s) + 1 : avail;
      /* Text has no NUL byte: the line ends at one, which the caller refuses as binary
       * data. Without this stop a binary stream of no line break (/dev/zero) was taken
       * into memory whole before the line was checked. */
      const char *z = memchr(s, '\0', take);
      if (z) take = (size_t)(z - s) + 1, nul = 1;
      if (line_room(r, n + take + 2)) return -1;
      memcpy(r->line + n, s, take);
      n += take;
      r->cpos += take;
      open = 1;
      if (!nl && !nul) continue; /* the line goes on in the next chunk */
    }
    /* A physical line is complete: cut its ending. */
    open = 0;
    while (n > pl && (r->line[n - 1] == '\n' || r->line[n - 1] == '\r')) n--;
    if (pl == 0) r->first = r->lineno + 1;
    r->lineno++;
    size_t bom = r->lineno == 1 && n >= 3 && !memcmp(r->line, "\xEF\xBB\xBF", 3) ? 3 : 0;
    q = quote_state(q, r->line + pl + bom, n - pl - bom);
    /* Inside quotes at the line's end: the record goes on, with a line feed in the field
     * (RFC 4180); at the end of the input the reader reports the open quote. */
    if (q != 2 || nul) break;
    if (r->eof && r->cpos == r->clen) { /* the input ends inside quotes */
      r->open_quote = 1;
      break;
    }
    r->line[n++] = '\n';
    pl = n;
  }
  r->line[n] = '\0';
  *len = n;
  return 1;
}

static int blank(char c) { return c == ' ' || c == '\t'; }

const char *qk__csv_field(const char *line, size_t len, size_t *pos, qk__span_t *sp) {
  size_t i = *pos;
  sp->start = i;
  sp->quoted = 0;
  size_t j = i;
  while (j < len && blank(line[j])) j++;
  if (j < len && line[j] == '"') {
    /* A quoted field: "" inside is a quote; only blanks may follow the closing quote. */
    sp->quoted = 1;
    sp->b = ++j;
    for (;;) {
      if (j >= len) return "unterminated quoted field";
      if (line[j] == '"' && j + 1 < len && line[j + 1] == '"') {
        j += 2;
      } else if (line[j] == '"') {
        break;
      } else {
        j++;
      }
    }
    sp->e = j++;
    while (j < len && blank(line[j])) j++;
    if (j < len && line[j] != ',') return "text after a closing quote";
  } else {
    sp->b = i;
    while (j < len && line[j] != ',') j++;
    sp->e = j;
  }
  *pos = j + 1; /* past the comma, or len + 1 after the last field */
  return NULL;
}

int qk__decimal_syntax(const char *s, size_t n) {
  size_t i = 0;
  if (i < n && (s[i] == '+' || s[i] == '-')) i++;
  static const char *const words[] = {"infinity", "inf", "nan"};
  for (int w = 0; w < 3; w++) { /* (strtod's words; the caller rejects them as not finite) */
    size_t k = strlen(words[w]), j = 0;
    while (j < k && i + j < n && (s[i + j] | 0x20) == words[w][j]) j++;
    if (j == k && i + k == n) return 1;
  }
  size_t d = 0;
  while (i < n && s[i] >= '0' && s[i] <= '9') i++, d++;
  if (i < n && s[i] == '.') {
    i++;
    while (i < n && s[i] >= '0' && s[i] <= '9') i++, d++;
  }
  if (d == 0) return 0;
  if (i < n && (s[i] == 'e' || s[i] == 'E')) {
    i++;
    if (i < n && (s[i] == '+' || s[i] == '-')) i++;
    size_t x = 0;
    while (i < n && s[i] >= '0' && s[i] <= '9') i++, x++;
    if (x == 0) return 0;
  }
  return i == n;
}

int qk__csv_number(char *line, const qk__span_t *sp, double *v) {
  size_t b = sp->b, e = sp->e;
  while (b < e && blank(line[b])) b++;
  while (e > b && blank(line[e - 1])) e--;
  if (b == e) return 0;
  if (!qk__decimal_syntax(line + b, e - b)) { /* hexadecimal, "1e", "1.2.3", ... */
    size_t h = b + (line[b] == '+' || line[b] == '-');
    return e - h > 1 && line[h] == '0' && (line[h + 1] | 0x20) == 'x' ? -1 : 0;
  }
  /* strtod needs a terminated string: end the field in place for the call. */
  char saved = line[e];
  line[e] = '\0';
  char *end;
  errno = 0;
  *v = qk__strtod(line + b, &end);
  line[e] = saved;
  if (end != line + e) return 0;
  if (*v == 0) /* (a nonzero digit before the exponent: "1e-400" read as 0) */
    for (size_t i = b; i < e && (line[i] | 0x20) != 'e'; i++)
      if (line[i] >= '1' && line[i] <= '9') return -2;
  return 1;
}
