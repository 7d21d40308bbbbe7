/*
 * Private declarations of the io module: a line reader and a CSV field scanner that
 * allocate through the caller's allocator. Not API. The module depends on no other but
 * index/textloc.h (numbers read in the C locale).
 */
#ifndef QUADKIT_IO_INTERNAL_H
#define QUADKIT_IO_INTERNAL_H

#include <stdio.h>

#include "quadkit/io.h"
#include "index/textloc.h" /* numbers in the C locale */

/* The allocator call (libc when a is NULL or has no function). */
void *qk__io_realloc(const qk_allocator_t *a, void *p, size_t osize, size_t nsize);

/* Lines of a stream, read in chunks; each line NUL-terminated, its ending removed. */
typedef struct qk__lines {
  FILE *f;
  const qk_allocator_t *alloc;
  char *chunk; /* read buffer */
  size_t clen, cpos;
  char *line; /* the current line */
  size_t cap;
  unsigned long lineno; /* physical lines read */
  unsigned long first;  /* the physical line where the current record starts */
  int eof, ioerr;
  int open_quote; /* the current record ends with the input inside a quoted field */
} qk__lines_t;

/* Start reading f. */
void qk__lines_init(qk__lines_t *r, FILE *f, const qk_allocator_t *alloc);
/* The next CSV record into r->line (*len bytes): one line, or several when a quoted field
 * holds line breaks (each kept as one LF, a CRLF inside quotes included); it starts on
 * physical line r->first; a NUL byte ends it (kept as its last byte, for the caller to
 * refuse). 1, or 0 at the end, or -1 out of memory. */
int qk__lines_next(qk__lines_t *r, size_t *len);
/* Free the buffers. */
void qk__lines_free(qk__lines_t *r);

/* One field of a line: its text is line[b, e) (inside the quotes when quoted); it starts
 * at byte `start` (0-based) of the line. */
typedef struct qk__span {
  size_t start, b, e;
  int quoted;
} qk__span_t;

/* Scan the field starting at *pos of line[0, len): fill *sp and move *pos past the comma
 * (to len + 1 after the last field). Returns 0, or an error message. */
const char *qk__csv_field(const char *line, size_t len, size_t *pos, qk__span_t *sp);

/* Is s[0, n) a decimal number: an optional sign, digits with an optional decimal point
 * (at least one digit), an optional exponent (e or E, optional sign, digits); or one of
 * strtod's words inf, infinity, nan (any case, optional sign)? 1 or 0. */
int qk__decimal_syntax(const char *s, size_t n);

/* Is the field a number (qk__decimal_syntax, blanks around allowed)? 1 and *v set; 0 when
 * not; -1 when it is hexadecimal (0x...), which strtod would take but CSV does not; -2 when
 * it is a nonzero number below the smallest double, which strtod reads as 0. */
int qk__csv_number(char *line, const qk__span_t *sp, double *v);

#endif /* QUADKIT_IO_INTERNAL_H */
