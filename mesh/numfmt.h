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
 * returns the length. Correctly rounded (ties to even on the exact binary value, as glibc
 * does), so the digits read back as x; exponent forms and non-finite values go through
 * snprintf itself. */
size_t qk__fmt_g17(double x, char *buf);

/* Write v in decimal into buf (at least 21 bytes), not terminated; returns the length. */
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

#endif
