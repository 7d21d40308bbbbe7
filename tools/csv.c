/* CSV input and small helpers shared by the subcommands. */
#define _XOPEN_SOURCE 700
#include <errno.h>
#include <math.h>
#include <stdarg.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/stat.h>
#include <unistd.h>

#include "cli.h"

void cli_error(const char *cmd, const char *fmt, ...) {
  va_list ap;
  fprintf(stderr, "quadkit %s: ", cmd);
  va_start(ap, fmt);
  vfprintf(stderr, fmt, ap);
  va_end(ap);
  fputc('\n', stderr);
}

int cli_status(const char *cmd, const char *what, qk_status_t st) {
  if (st == QK_OK) return CLI_OK;
  cli_error(cmd, "%s: %s", what, qk_strerror(st));
  switch (st) {
  case QK_ERR_NOMEM:
  case QK_ERR_CORRUPT:
  case QK_ERR_IO:
  case QK_ERR_UNSUPPORTED:
    return CLI_INTERNAL;
  default:
    return CLI_BAD_INPUT;
  }
}

int cli_build_tree(const char *cmd, const char *path, const qk_point_t *pts, size_t n,
                   const qk_tree_options_t *opt, qk_tree_t **out) {
  qk_status_t st = qk_tree_build(pts, n, opt, out);
  if (st == QK_ERR_LIMIT && n > 0) {
    /* The likely cause: an extent no double can hold. Name the values. */
    double x0 = pts[0].x, x1 = pts[0].x, y0 = pts[0].y, y1 = pts[0].y;
    for (size_t i = 1; i < n; i++) {
      x0 = pts[i].x < x0 ? pts[i].x : x0;
      x1 = pts[i].x > x1 ? pts[i].x : x1;
      y0 = pts[i].y < y0 ? pts[i].y : y0;
      y1 = pts[i].y > y1 ? pts[i].y : y1;
    }
    if (!isfinite(x1 - x0) || !isfinite(y1 - y0)) {
      cli_error(cmd,
                "%s: the points span x from %.17g to %.17g and y from %.17g to %.17g, "
                "an extent too large for a double",
                path, x0, x1, y0, y1);
      return CLI_BAD_INPUT;
    }
  }
  return cli_status(cmd, path, st);
}

int cli_parse_u32(const char *cmd, const char *opt, const char *s, unsigned long min,
                  unsigned long max, unsigned long *out) {
  char *end;
  if (!s) {
    cli_error(cmd, "%s needs a value", opt);
    return 1;
  }
  errno = 0;
  unsigned long v = strtoul(s, &end, 10);
  if (errno || end == s || *end || s[0] == '-' || v < min || v > max) {
    cli_error(cmd, "%s must be a whole number from %lu to %lu, not '%s'", opt, min, max, s);
    return 1;
  }
  *out = v;
  return 0;
}

int cli_parse_double(const char *cmd, const char *opt, const char *s, double *out) {
  char *end;
  if (!s) {
    cli_error(cmd, "%s needs a value", opt);
    return 1;
  }
  errno = 0;
  double v = strtod(s, &end);
  if (end == s || *end || !isfinite(v)) {
    cli_error(cmd, "%s must be a finite number, not '%s'", opt, s);
    return 1;
  }
  *out = v;
  return 0;
}

/* Split off the next field of a CSV line (quotes allowed). Returns the field start (NUL
 * terminated in place) and advances *p past the comma, or sets *p NULL at line end. */
static char *next_field(char **p) {
  char *s = *p, *f;
  if (*s == '"') {
    char *w = ++s;
    f = s;
    for (;;) {
      if (*s == '"' && s[1] == '"') {
        *w++ = '"';
        s += 2;
      } else if (*s == '"') {
        s++;
        break;
      } else if (*s == '\0') {
        break;
      } else {
        *w++ = *s++;
      }
    }
    char *after = s;
    *w = '\0';
    s = after;
    while (*s && *s != ',') s++;
  } else {
    f = s;
    while (*s && *s != ',') s++;
  }
  if (*s == ',') {
    *s = '\0';
    *p = s + 1;
  } else {
    *s = '\0';
    *p = NULL;
  }
  return f;
}

/* Parse a whole field as a number (surrounding blanks allowed). */
static int parse_number(const char *f, double *v) {
  char *end;
  while (*f == ' ' || *f == '\t') f++;
  if (!*f) return 0;
  errno = 0;
  *v = strtod(f, &end);
  if (end == f) return 0;
  while (*end == ' ' || *end == '\t') end++;
  return *end == '\0';
}

void cli_table_free(cli_table_t *t) {
  free(t->v);
  free(t->nfields);
  memset(t, 0, sizeof *t);
}

int cli_read_csv(const char *path, int min_fields, int max_fields, cli_table_t *out) {
  memset(out, 0, sizeof *out);
  out->cols = max_fields;
  FILE *f = fopen(path, "rb");
  if (!f) {
    fprintf(stderr, "quadkit: %s: cannot open: %s\n", path, strerror(errno));
    return CLI_BAD_INPUT;
  }
  char *line = NULL;
  size_t line_cap = 0, cap_rows = 0;
  ssize_t len;
  long lineno = 0;
  int seen_first = 0, rc = CLI_OK;
  while ((len = getline(&line, &line_cap, f)) >= 0) {
    lineno++;
    if ((size_t)len != strlen(line)) {
      fprintf(stderr, "quadkit: %s:%ld: binary data (NUL byte) in a text file\n", path, lineno);
      rc = CLI_BAD_INPUT;
      break;
    }
    while (len > 0 && (line[len - 1] == '\n' || line[len - 1] == '\r')) line[--len] = '\0';
    if (lineno == 1 && (unsigned char)line[0] == 0xEF && (unsigned char)line[1] == 0xBB &&
        (unsigned char)line[2] == 0xBF)
      memmove(line, line + 3, (size_t)len - 2); /* UTF-8 byte order mark */
    const char *q = line;
    while (*q == ' ' || *q == '\t') q++;
    if (!*q) continue;
    char *p = line;
    double vals[16];
    int nf = 0, first = !seen_first;
    seen_first = 1;
    while (p && nf < max_fields) {
      char *field = next_field(&p);
      double v;
      if (!parse_number(field, &v)) {
        if (first && nf == 0) break; /* a header line */
        if (nf < min_fields || p || field[0]) {
          fprintf(stderr, "quadkit: %s:%ld: field %d is not a number: '%.40s'\n", path, lineno,
                  nf + 1, field);
          rc = CLI_BAD_INPUT;
          break;
        }
        break;
      }
      if (!isfinite(v)) {
        fprintf(stderr, "quadkit: %s:%ld: field %d is not finite: '%.40s'\n", path, lineno, nf + 1,
                field);
        rc = CLI_BAD_INPUT;
        break;
      }
      vals[nf++] = v;
    }
    if (rc != CLI_OK) break;
    if (first && nf == 0) continue; /* header */
    if (nf < min_fields) {
      fprintf(stderr, "quadkit: %s:%ld: expected at least %d numeric fields, found %d\n", path,
              lineno, min_fields, nf);
      rc = CLI_BAD_INPUT;
      break;
    }
    if (out->rows >= QK_MAX_POINTS) {
      fprintf(stderr, "quadkit: %s:%ld: too many rows (limit %lu)\n", path, lineno,
              (unsigned long)QK_MAX_POINTS);
      rc = CLI_BAD_INPUT;
      break;
    }
    if (out->rows == cap_rows) {
      size_t nc = cap_rows ? cap_rows * 2 : 1024;
      double *nv = realloc(out->v, nc * (size_t)max_fields * sizeof *nv);
      if (!nv) {
        rc = CLI_INTERNAL;
        break;
      }
      out->v = nv;
      unsigned char *nn = realloc(out->nfields, nc);
      if (!nn) {
        rc = CLI_INTERNAL;
        break;
      }
      out->nfields = nn;
      cap_rows = nc;
    }
    for (int i = 0; i < max_fields; i++)
      out->v[out->rows * (size_t)max_fields + (size_t)i] = i < nf ? vals[i] : NAN;
    out->nfields[out->rows] = (unsigned char)nf;
    out->rows++;
  }
  if (rc == CLI_OK && ferror(f)) {
    fprintf(stderr, "quadkit: %s: read error\n", path);
    rc = CLI_BAD_INPUT;
  }
  if (rc == CLI_INTERNAL) fprintf(stderr, "quadkit: %s: out of memory\n", path);
  free(line);
  fclose(f);
  if (rc != CLI_OK) cli_table_free(out);
  return rc;
}

int cli_read_points(const char *path, qk_point_t **pts, size_t *n) {
  cli_table_t t;
  *pts = NULL;
  *n = 0;
  int rc = cli_read_csv(path, 2, 2, &t);
  if (rc) return rc;
  if (t.rows == 0) {
    fprintf(stderr, "quadkit: %s: no data rows\n", path);
    cli_table_free(&t);
    return CLI_BAD_INPUT;
  }
  qk_point_t *p = malloc(t.rows * sizeof *p);
  if (!p) {
    cli_table_free(&t);
    fprintf(stderr, "quadkit: %s: out of memory\n", path);
    return CLI_INTERNAL;
  }
  for (size_t i = 0; i < t.rows; i++) {
    p[i].x = t.v[2 * i];
    p[i].y = t.v[2 * i + 1];
  }
  *pts = p;
  *n = t.rows;
  cli_table_free(&t);
  return CLI_OK;
}

int cli_out_open(const char *cmd, const char *path, cli_out_t *o) {
  memset(o, 0, sizeof *o);
  if (!strcmp(path, "-")) {
    o->f = stdout;
    return CLI_OK;
  }
  /* A symbolic link is written through: the temporary goes beside its target and is
   * renamed over the target, so the link stays. Something that is not a regular file (a
   * FIFO, a device such as /dev/stdout) cannot be replaced atomically and must not be
   * replaced at all: it is written directly. */
  char *target = NULL;
  struct stat st;
  if (lstat(path, &st) == 0 && S_ISLNK(st.st_mode)) target = realpath(path, NULL);
  const char *final = target ? target : path;
  if (stat(final, &st) == 0 && !S_ISREG(st.st_mode)) {
    o->f = fopen(final, "wb");
    free(target);
    if (!o->f) {
      cli_error(cmd, "cannot write %s: %s", path, strerror(errno));
      return CLI_BAD_INPUT;
    }
    o->direct = 1;
    return CLI_OK;
  }
  size_t n = strlen(final) + 32;
  o->path = strdup(final);
  o->tmp = malloc(n);
  free(target);
  if (!o->path || !o->tmp) {
    free(o->path);
    free(o->tmp);
    cli_error(cmd, "out of memory");
    return CLI_INTERNAL;
  }
  snprintf(o->tmp, n, "%s.tmp.%ld", o->path, (long)getpid());
  o->f = fopen(o->tmp, "wb");
  if (!o->f) {
    cli_error(cmd, "cannot write %s: %s", path, strerror(errno));
    free(o->path);
    free(o->tmp);
    memset(o, 0, sizeof *o);
    return CLI_BAD_INPUT;
  }
  return CLI_OK;
}

int cli_out_close(const char *cmd, cli_out_t *o, int ok) {
  int rc = CLI_OK;
  if (!o->f) return CLI_OK;
  if (o->f == stdout) {
    if (fflush(stdout) != 0) rc = CLI_INTERNAL;
    o->f = NULL;
    return rc;
  }
  if (o->direct) {
    if (ferror(o->f)) rc = CLI_INTERNAL;
    if (fclose(o->f) != 0) rc = CLI_INTERNAL;
    memset(o, 0, sizeof *o);
    return rc;
  }
  if (ferror(o->f)) ok = 0, rc = CLI_INTERNAL;
  if (fclose(o->f) != 0) ok = 0, rc = CLI_INTERNAL;
  if (ok && rename(o->tmp, o->path) != 0) {
    cli_error(cmd, "cannot rename %s to %s: %s", o->tmp, o->path, strerror(errno));
    ok = 0;
    rc = CLI_INTERNAL;
  }
  if (!ok) {
    remove(o->tmp);
    if (rc == CLI_INTERNAL) cli_error(cmd, "failed writing %s", o->path);
  }
  free(o->path);
  free(o->tmp);
  memset(o, 0, sizeof *o);
  return rc;
}
