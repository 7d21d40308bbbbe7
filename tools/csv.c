/* CSV input of the command-line tool: the library's reader, its errors printed with
 * file, line and column, and the rows' text kept for --keep. */
#define _POSIX_C_SOURCE 200809L /* getline */
#include <errno.h>
#include <math.h>
#include <stdint.h>
#include <stdlib.h>
#include <string.h>

#include "cli.h"

void cli_rows_free(cli_rows_t *r) {
  if (!r) return;
  for (size_t i = 0; r->text && i < r->n; i++) free(r->text[i]);
  free(r->text);
  free(r->lineno);
  free(r->header);
  int keep = r->keep_text;
  memset(r, 0, sizeof *r);
  r->keep_text = keep;
}

/* The quote state of CSV text after s[0, n), from state q: 0 at a field's start, 1 in an
 * unquoted field or after a closing quote, 2 inside quotes, 3 just after a quote inside
 * quotes (a closing one, or the first of ""). Only a quote at a field's start (blanks
 * before it allowed) opens a quoted field, as the library's reader says. */
static int quote_state(int q, const char *s, size_t n, size_t *commas) {
  for (size_t i = 0; i < n; i++) {
    char c = s[i];
    if (q == 0)
      q = c == '"' ? 2 : c == ',' || c == ' ' || c == '\t' ? 0 : 1;
    else if (q == 1)
      q = c == ',' ? 0 : 1;
    else if (q == 2)
      q = c == '"' ? 3 : 2;
    else
      q = c == '"' ? 2 : c == ',' ? 0 : 1;
    if (q == 0 && c == ',' && commas) ++*commas;
  }
  return q;
}

/* Fields of a CSV record (quotes respected). */
static size_t count_fields(const char *s) {
  size_t n = 1;
  quote_state(0, s, strlen(s), &n);
  return n;
}

long cli_read_record(FILE *f, char **line, size_t *cap, unsigned long *phys, unsigned long *first,
                     const char **why) {
  size_t n = 0;
  int q = 0, part = 0;
  char *buf = NULL;
  *why = NULL;
  size_t bcap = 0;
  long rc;
  for (;; part++) {
    ssize_t got = getline(part ? &buf : line, part ? &bcap : cap, f);
    if (got < 0) {
      /* getline's -1 is the end of the input, a read error (ferror, which the caller
       * reports) or a line too long for memory (neither flag set; errno ENOMEM): that
       * one was taken for the end, so join wrote nothing and exited 0 on a binary
       * input of no line break (/dev/zero). */
      if (!feof(f) && !ferror(f)) {
        rc = -3;
        goto out;
      }
      if (!part) return -1;
      /* the input ends inside quotes: the record is returned, flagged (the rows after
       * the quote would be lost without a word) */
      *why = "unterminated quoted field (it runs to the end of the file)";
      n--; /* the added LF */
      break;
    }
    char *l = part ? buf : *line;
    ++*phys;
    if (!part) *first = *phys;
    if ((size_t)got != strlen(l)) {
      *why = "binary data (NUL byte) in a text file";
      rc = -2;
      goto out;
    }
    size_t c = (size_t)got;
    if (cli_cut_line_end(l, &c)) {
      *why = CLI_LONE_CR;
      rc = -2;
      goto out;
    }
    if (part) {
      if (n + c + 2 > *cap) {
        char *p = realloc(*line, n + c + 2);
        if (!p) {
          rc = -3;
          goto out;
        }
        *line = p, *cap = n + c + 2;
      }
      memcpy(*line + n, l, c);
    }
    size_t bom = *phys == 1 && c >= 3 && !memcmp(*line, "\xEF\xBB\xBF", 3) ? 3 : 0;
    q = quote_state(q, *line + n + bom, c - bom, NULL);
    n += c;
    if (q != 2) break;
    if (n + 2 > *cap) {
      char *p = realloc(*line, n + 2);
      if (!p) {
        rc = -3;
        goto out;
      }
      *line = p, *cap = n + 2;
    }
    (*line)[n++] = '\n';
  }
  (*line)[n] = '\0';
  rc = (long)n;
out:
  free(buf);
  return rc;
}

static char *dup_text(const char *s, size_t len) {
  char *p = malloc(len + 1);
  if (p) memcpy(p, s, len), p[len] = '\0';
  return p;
}

/* The reader's row callback: line numbers always, the text when kept. */
static qk_status_t on_row(void *ud, size_t row, unsigned long lineno, const char *line,
                          size_t len) {
  cli_rows_t *r = ud;
  size_t nf = r->keep_text ? count_fields(line) : 0;
  if (nf > r->width) r->width = nf;
  if (row == SIZE_MAX) {
    if (r->keep_text && !(r->header = dup_text(line, len))) return QK_ERR_NOMEM;
    return QK_OK;
  }
  if (r->n == r->cap) {
    size_t nc = r->cap ? 2 * r->cap : 1024;
    unsigned long *nl = realloc(r->lineno, nc * sizeof *nl);
    if (!nl) return QK_ERR_NOMEM;
    r->lineno = nl;
    if (r->keep_text) {
      char **nt = realloc(r->text, nc * sizeof *nt);
      if (!nt) return QK_ERR_NOMEM;
      r->text = nt;
    }
    r->cap = nc;
  }
  if (r->keep_text && !(r->text[r->n] = dup_text(line, len))) return QK_ERR_NOMEM;
  r->lineno[r->n++] = lineno;
  return QK_OK;
}

/* Print the reader's error and map it to an exit code. */
static int read_error(const char *path, qk_status_t st, const qk_error_t *e) {
  if (e->line && e->column)
    cli_msg("quadkit: %s:%lu:%lu: %s\n", path, e->line, e->column, e->message);
  else if (e->line)
    cli_msg("quadkit: %s:%lu: %s\n", path, e->line, e->message);
  else
    cli_msg("quadkit: %s: %s\n", path, e->message[0] ? e->message : qk_strerror(st));
  return st == QK_ERR_NOMEM ? CLI_INTERNAL : CLI_BAD_INPUT;
}

/* Read through the library with `columns` selected, rows collected into *rows. */
static int read_values(const char *path, const char *columns, int required, int cols,
                       cli_rows_t *rows, double **v, size_t *n) {
  cli_rows_t scratch = {0};
  if (!rows) rows = &scratch;
  qk_csv_options_t opt;
  qk_csv_options_init(&opt);
  opt.columns = columns;
  opt.on_row = on_row;
  opt.ud = rows;
  qk_error_t err;
  FILE *f = cli_open_input(NULL, path);
  if (!f) return CLI_BAD_INPUT;
  qk_status_t st = qk_csv_read_values(f, &opt, (size_t)cols, (size_t)required, NULL, v, n, &err);
  fclose(f);
  int rc = st == QK_OK ? CLI_OK : read_error(path, st, &err);
  if (rc || rows == &scratch) cli_rows_free(rows);
  return rc;
}

int cli_read_table(const char *path, int required, int cols, cli_rows_t *rows, cli_table_t *out) {
  memset(out, 0, sizeof *out);
  out->cols = cols;
  return read_values(path, NULL, required, cols, rows, &out->v, &out->rows);
}

void cli_table_free(cli_table_t *t) {
  free(t->v);
  memset(t, 0, sizeof *t);
}

static int read_points(const char *path, const char *xy, cli_rows_t *rows, qk_point_t **pts,
                       size_t *n, int need_rows) {
  double *v = NULL;
  *pts = NULL;
  *n = 0;
  int rc = read_values(path, xy, 2, 2, rows, &v, n);
  if (rc) return rc;
  if (*n == 0 && need_rows) {
    cli_msg("quadkit: %s: no data rows\n", path);
    cli_rows_free(rows);
    return CLI_BAD_INPUT;
  }
  *pts = (qk_point_t *)(void *)v; /* rows of two doubles: the points' layout */
  return CLI_OK;
}

int cli_read_points(const char *path, const char *xy, cli_rows_t *rows, qk_point_t **pts,
                    size_t *n) {
  return read_points(path, xy, rows, pts, n, 1);
}

int cli_read_queries(const char *path, const char *xy, cli_rows_t *rows, qk_point_t **pts,
                     size_t *n) {
  return read_points(path, xy, rows, pts, n, 0);
}

void cli_write_fields(FILE *f, const char *text, size_t width, const char *prefix) {
  size_t nf = 0;
  if (text && prefix) {
    /* The header's names, each prefixed (inside the quotes of a quoted name). */
    const char *s = text;
    for (;;) {
      while (*s == ' ' || *s == '\t') s++;
      fputc(',', f);
      int quoted = 0;
      if (*s == '"') {
        fputc(*s++, f);
        quoted = 1;
      }
      fputs(prefix, f);
      while (*s && (quoted || *s != ',')) {
        if (*s == '"') quoted = !quoted;
        fputc(*s++, f);
      }
      nf++;
      if (!*s) break;
      s++;
    }
  } else if (text) {
    fputc(',', f);
    fputs(text, f);
    nf = count_fields(text);
  }
  for (; nf < width; nf++) {
    if (prefix)
      fprintf(f, ",%s%zu", prefix, nf + 1);
    else
      fputc(',', f);
  }
}

int cli_cut_line_end(char *line, size_t *len) {
  size_t n = *len;
  while (n > 0 && (line[n - 1] == '\n' || line[n - 1] == '\r')) line[--n] = '\0';
  *len = n;
  return memchr(line, '\r', n) != NULL;
}
