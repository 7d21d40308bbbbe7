/*
 * Number formatting for the mesh writers (mesh/write.c): the same characters as printf's
 * "%.17g" and "%lu", without printf's format parsing and its arbitrary-precision
 * conversion (which took most of the time of writing a million-triangle mesh). Internal to
 * mesh/.
 */
#ifndef QK_MESH_NUMFMT_H
#define QK_MESH_NUMFMT_H

#include <stddef.h>
#include <stdint.h>
#include <stdio.h>
#include <string.h>

/* Room a formatted number needs (with its terminating NUL). */
#define QK__NUMFMT_MAX 40

/* Write x as printf("%.17g", x) does into buf (QK__NUMFMT_MAX bytes), NUL-terminated;
 * returns the length; except that -0 is written "0", as the CLI prints it everywhere
 * (an input "-0" is the same point as "0"). Correctly rounded (ties to even on the exact
 * binary value, as glibc does), so the digits read back as x; exponent forms and
 * non-finite values go through snprintf itself. */
size_t qk__fmt_g17(double x, char *buf);

/* Write v in decimal into buf (at least 21 bytes, which bytes past the digits may be
 * scribbled over), not terminated; returns the length. */
size_t qk__fmt_u64(uint64_t v, char *buf);

/* A line buffer for the writers: text is appended, then written with one fwrite a few
 * kilobytes at a time. */
typedef struct qk__wbuf {
  FILE *f;
  size_t n;
  char b[1 << 14];
} qk__wbuf_t;

/* Write out what is buffered (keep going after an error: ferror(f) reports it). */
void qk__wbuf_flush(qk__wbuf_t *w);

/* Make room for `need` <= 256 more bytes. */
static inline char *qk__wbuf_room(qk__wbuf_t *w, size_t need) {
  if (w->n + need > sizeof w->b) qk__wbuf_flush(w);
  return w->b + w->n;
}

/* Append x as "%.17g", v as "%lu" (or "%ld"), a short string (<= 256 bytes), a
 * character. */
static inline void qk__wbuf_g17(qk__wbuf_t *w, double x) {
  w->n += qk__fmt_g17(x, qk__wbuf_room(w, QK__NUMFMT_MAX));
}
static inline void qk__wbuf_u(qk__wbuf_t *w, uint64_t v) {
  w->n += qk__fmt_u64(v, qk__wbuf_room(w, 24));
}
static inline void qk__wbuf_i(qk__wbuf_t *w, int64_t v) {
  char *p = qk__wbuf_room(w, 24);
  if (v < 0) *p++ = '-', w->n++;
  w->n += qk__fmt_u64(v < 0 ? 0 - (uint64_t)v : (uint64_t)v, p);
}
static inline void qk__wbuf_s(qk__wbuf_t *w, const char *s) {
  size_t n = strlen(s);
  memcpy(qk__wbuf_room(w, n), s, n), w->n += n;
}
static inline void qk__wbuf_c(qk__wbuf_t *w, char c) { *qk__wbuf_room(w, 1) = c, w->n++; }

/* A line number kept in decimal: the writers number their lines 0, 1, 2... (or from 1),
 * and adding one to the digits costs less than formatting the number anew. */
typedef struct qk__dcount {
  char d[24]; /* the digits, then zeros: copied 24 bytes at a time */
  size_t n;
} qk__dcount_t;

/* Start a counter at v. */
static inline void qk__dcount_init(qk__dcount_t *c, uint64_t v) {
  memset(c->d, '0', sizeof c->d);
  c->n = qk__fmt_u64(v, c->d);
  memset(c->d + c->n, '0', sizeof c->d - c->n);
}

/* Write the counter's digits at p (24 bytes of room), return how many; then add one. */
static inline size_t qk__dcount_put(qk__dcount_t *c, char *p) {
  size_t n = c->n, i = n;
  memcpy(p, c->d, sizeof c->d);
  while (i > 0 && c->d[i - 1] == '9') c->d[--i] = '0';
  if (i > 0) {
    c->d[i - 1]++;
  } else { /* 99...9 + 1: a one, then n zeros */
    c->d[0] = '1', c->d[n] = '0', c->n = n + 1;
  }
  return n;
}

#endif
